"""The training domain of a fitted model: where its intervals can be trusted.

At :meth:`hybridev.HybridModel.fit` the model records, for a few trip
quantities, every value it was trained on (:class:`TrainingDomain`):

========================  ===========================  =====================
quantity                  from                          tolerance ``tol_f``
========================  ===========================  =====================
``temperature_c``         trip column                   3 °C
``avg_speed_kmh``         trip column                   8 km/h
``log_distance``          ``ln(distance_km)``           ``ln 1.5``
``log_duration``          ``ln(distance / speed)``      ``ln 1.5``
``grade_pct``             column, else logged trace,    1 %
                          else 0
========================  ===========================  =====================

A new trip's gap in each quantity is the distance to the *nearest* training
value over the tolerance; beyond the training range it counts against a third
of it (:data:`EDGE_FRACTION`: extrapolation is riskier). Between two training
values of an intensive quantity the gap is 0: the condition is interpolated
between familiar ones, not new (a trip at 3 °C between the paper design's -5
and 20 °C); its distance to the nearest value is the *interpolation gap*
(:meth:`TrainingDomain.interior_gap`), which widens at a learned rate
(:class:`hybridev.learning.shift.GapRate`). A trip's ``domain_score`` is the
largest gap over the intensive quantities (:data:`INTENSIVE_QUANTITIES`); it is
``in_domain`` when at most 1. The tolerances are physical scales, the same for every car.

Intensive and extensive conditions. Energy adds up over distance: a longer trip
under familiar speed, temperature and grade is a sum of familiar stretches, carried
by the physics (the residual is held at the training distances,
:mod:`hybridev.learning.physical`). So only the intensive quantities score the
domain; the gaps of the extensive ones (distance, duration) are recorded
(:meth:`TrainingDomain.gaps`) but neither flag a trip nor widen it.

Inputs the model was trained with but a trip lacks also leave the domain
(score at least :data:`MISSING_INPUT_SCORE`): a driving ``mode`` when every
training trip had one, a logged trace when most training trips had one, unless the model
calibrated trips predicted without their trace (:mod:`hybridev.learning.planned`,
:func:`hybridev.learning.fitting.fit_planned`: the domain is then recorded with
``needs_trace=False``, and a planned trip is in the domain when its conditions are).

Out-of-domain trips get intervals from the physics posterior predictive plus an
inflation growing with the score (:mod:`hybridev.learning.ood`; rate learned at fit,
:class:`hybridev.learning.shift.GapRate`, else :data:`OOD_INFLATION_PER_UNIT`); every
trip's network inputs are clipped to their training range
(:meth:`TrainingDomain.clip_features`): the residual does not extrapolate.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.core.errors import OutOfDomainWarning

__all__ = [
    "DOMAIN_QUANTITIES",
    "DOMAIN_TOLERANCES",
    "EDGE_FRACTION",
    "INTENSIVE",
    "INTENSIVE_QUANTITIES",
    "MISSING_INPUT_SCORE",
    "OOD_INFLATION_PER_UNIT",
    "TrainingDomain",
    "domain_quantities",
    "warn_out_of_domain",
]

DOMAIN_QUANTITIES = ("temperature_c", "avg_speed_kmh", "log_distance", "log_duration",
                     "grade_pct")
"""Trip quantities whose training values define the domain."""

DOMAIN_TOLERANCES = (3.0, 8.0, float(np.log(1.5)), float(np.log(1.5)), 1.0)
"""Gap (in the quantity's unit) that makes a trip leave the domain, per quantity."""

_REASON_NAMES = ("temperature", "speed", "distance", "duration", "grade")

INTENSIVE_QUANTITIES = ("temperature_c", "avg_speed_kmh", "grade_pct")
"""The quantities that score the domain: conditions, not amounts (see the module
docstring); ``log_distance`` and ``log_duration`` are extensive."""

INTENSIVE = np.array([q in INTENSIVE_QUANTITIES for q in DOMAIN_QUANTITIES])
"""Mask over :data:`DOMAIN_QUANTITIES` of the intensive quantities, shape (5,)."""

EDGE_FRACTION = 1.0 / 3.0
"""Beyond the training range a gap counts against ``EDGE_FRACTION * tol`` (1 °C, ...):
extrapolating is riskier than interpolating between training values."""

MISSING_INPUT_SCORE = 2.0
"""Domain score of a trip lacking an input the model was trained with."""

OOD_INFLATION_PER_UNIT = 0.25
"""Out-of-domain spread multiplier ``1 + 0.25 (score - 1)``, capped at 3 (score 9), on
every part of the spread but the physics posterior draws (:mod:`hybridev.learning.ood`)."""

_MAX_INFLATION = 3.0


def domain_quantities(table: pd.DataFrame, traces=None) -> tuple[np.ndarray, np.ndarray]:
    """Domain quantities (n_trips, 5) and whether each trip has a logged trace.

    Parameters
    ----------
    table : pandas.DataFrame
        Validated trips (``distance_km``, ``avg_speed_kmh``, ``temperature_c``,
        optional ``grade_pct``, ``trip_id``).
    traces : LoggedTraces, optional

    Returns
    -------
    q : numpy.ndarray, shape (n_trips, 5)
        In the order of :data:`DOMAIN_QUANTITIES`.
    has_trace : numpy.ndarray of bool, shape (n_trips,)

    Examples
    --------
    >>> t = pd.DataFrame({"distance_km": [10.0], "avg_speed_kmh": [40.0],
    ...                   "temperature_c": [5.0]})
    >>> q, tr = domain_quantities(t)
    >>> q.round(2).tolist(), tr.tolist()
    ([[5.0, 40.0, 2.3, -1.39, 0.0]], [False])
    """
    n = len(table)
    d = table["distance_km"].to_numpy(float)
    v = table["avg_speed_kmh"].to_numpy(float)
    grade = (table["grade_pct"].to_numpy(float) if "grade_pct" in table.columns
             else np.zeros(n))
    has_trace = np.zeros(n, dtype=bool)
    if traces is not None and len(traces) and "trip_id" in table.columns:
        pos = pd.Index(traces.trip_id).get_indexer(table["trip_id"].to_numpy(object))
        has_trace = pos >= 0
        if has_trace.any() and "grade_pct" not in table.columns:
            g = 100.0 * np.tan(traces.per_trip_mean(traces.grade_rad))
            grade[has_trace] = g[pos[has_trace]]
    return _quantities(table["temperature_c"].to_numpy(float), v, d, grade), has_trace


def _quantities(temperature_c: np.ndarray, avg_speed_kmh: np.ndarray, distance_km: np.ndarray,
                grade_pct: np.ndarray) -> np.ndarray:
    """:func:`domain_quantities`' matrix (n_trips, 5) from the trips' arrays."""
    d, v = distance_km, avg_speed_kmh
    return np.column_stack([temperature_c, v, np.log(np.maximum(d, 1e-3)),
                            np.log(np.maximum(d, 1e-3) / np.maximum(v, 1e-3)),
                            np.nan_to_num(grade_pct)])


@dataclass(frozen=True)
class TrainingDomain:
    """Values a model was trained on, to score how far new trips lie from them.

    Parameters
    ----------
    values : tuple of numpy.ndarray
        Sorted unique training values of each of :data:`DOMAIN_QUANTITIES`.
    feature_lo, feature_hi : numpy.ndarray, shape (n_features,)
        Range of the standardised network inputs over the training trips.
    needs_mode : bool
        Every training trip had a driving ``mode``.
    needs_trace : bool
        Most (> 50 %) training trips had a logged speed trace.

    Examples
    --------
    >>> t = pd.DataFrame({"distance_km": [10.0, 12.0] * 3, "avg_speed_kmh": [40.0] * 6,
    ...                   "temperature_c": [-5.0, -5.0, 20.0, 20.0, 32.0, 32.0]})
    >>> dom = TrainingDomain.fit(t, np.zeros((6, 2)))
    >>> new = t.iloc[:3].assign(temperature_c=[-4.0, 3.0, 45.0])
    >>> score, ok = dom.score(new)
    >>> score.round(2).tolist(), ok.tolist()  # 3 °C lies between -5 and 20 °C
    ([0.0, 0.0, 13.0], [True, True, False])
    """

    values: tuple
    feature_lo: np.ndarray
    feature_hi: np.ndarray
    needs_mode: bool = False
    needs_trace: bool = False

    @classmethod
    def fit(cls, table: pd.DataFrame, features: np.ndarray, traces=None) -> TrainingDomain:
        """Record the domain of the training ``table`` and standardised ``features``."""
        q, has_trace = domain_quantities(table, traces)
        x = np.asarray(features, float)
        mode = table["mode"] if "mode" in table.columns else pd.Series([None] * len(table))
        return cls(values=tuple(np.unique(q[:, j]) for j in range(q.shape[1])),
                   feature_lo=x.min(axis=0), feature_hi=x.max(axis=0),
                   needs_mode=bool(len(mode) and mode.notna().all()),
                   needs_trace=bool(has_trace.mean() > 0.5) if len(has_trace) else False)

    def gaps(self, table: pd.DataFrame, traces=None) -> np.ndarray:
        """Distance to the nearest training value over the tolerance, (n_trips, 5)."""
        return self._gaps(domain_quantities(table, traces)[0])

    def gap(self, table: pd.DataFrame, traces=None) -> np.ndarray:
        """Largest gap over the intensive quantities, shape (n_trips,) (0 with no trips).

        Examples
        --------
        >>> d = TrainingDomain.fit(pd.DataFrame({"distance_km": [10.0, 20.0],
        ...     "avg_speed_kmh": [50.0, 60.0], "temperature_c": [20.0, 22.0]}), np.zeros((2, 1)))
        >>> d.gap(pd.DataFrame({"distance_km": [400.0, 15.0], "avg_speed_kmh": [55.0, 55.0],
        ...     "temperature_c": [21.0, 14.0]})).round(2).tolist()
        [0.0, 6.0]
        """
        return _intensive_max(self.gaps(table, traces))

    def _gaps(self, q: np.ndarray, *, interior: bool = False, both: bool = False):
        """:meth:`gaps` of the domain quantities ``q`` (n_trips, 5); ``interior``:
        :meth:`interior_gap` instead; ``both``: ``(gaps, interior_gap)``, in one pass."""
        out, inner = np.empty_like(q), np.zeros(len(q))
        for j, (vals, tol) in enumerate(zip(self.values, DOMAIN_TOLERANCES, strict=True)):
            i = np.searchsorted(vals, q[:, j])
            below = vals[np.clip(i - 1, 0, len(vals) - 1)]
            above = vals[np.clip(i, 0, len(vals) - 1)]
            near = np.minimum(np.abs(q[:, j] - below), np.abs(q[:, j] - above)) / tol
            outside = np.maximum(vals[0] - q[:, j], q[:, j] - vals[-1])  # > 0 beyond the range
            if INTENSIVE[j]:  # between two training values: interpolated, not new
                inner = np.maximum(inner, np.where(outside > 0, 0.0, near))
                near = 0.0
            out[:, j] = np.where(outside > 0, outside / (EDGE_FRACTION * tol), near)
        return (out, inner) if both else inner if interior else out

    def interior_gap(self, q: np.ndarray) -> np.ndarray:
        """Largest interpolation gap over the intensive quantities, (n_trips,), of the
        :func:`domain_quantities` ``q`` (n_trips, 5): 0 beyond the training range."""
        return self._gaps(q, interior=True)

    def missing_inputs(self, table: pd.DataFrame, traces=None) -> np.ndarray:
        """Whether each trip lacks an input the model was trained with, (n_trips,) bool."""
        miss = np.zeros(len(table), dtype=bool)
        for lacking in self._missing(table, traces).values():
            miss |= lacking
        return miss

    def _missing(self, table: pd.DataFrame, traces=None) -> dict[str, np.ndarray]:
        """Per trained-with input (``"mode"``, ``"logged trace"``): trips lacking it."""
        n = len(table)
        out = {}
        if self.needs_mode:  # on the cells: Series operations are slow on a single trip
            out["mode"] = (pd.isna(table["mode"].to_numpy(dtype=object))
                           if "mode" in table.columns else np.ones(n, dtype=bool))
        if self.needs_trace:
            out["logged trace"] = ~domain_quantities(table, traces)[1]
        return out

    def reasons(self, table: pd.DataFrame, traces=None) -> dict[str, int]:
        """Trips outside the domain per reason (a trip may count under several).

        Examples
        --------
        >>> d = TrainingDomain.fit(pd.DataFrame({"distance_km": [10.0, 20.0],
        ...     "avg_speed_kmh": [50.0, 60.0], "temperature_c": [20.0, 22.0]}), np.zeros((2, 1)))
        >>> d.reasons(pd.DataFrame({"distance_km": [15.0, 15.0], "avg_speed_kmh": [55.0, 55.0],
        ...     "temperature_c": [-10.0, 21.0]}))
        {'temperature': 1}
        """
        out = {}
        if len(table):
            g = self.gaps(table, traces) > 1.0
            for j, name in enumerate(_REASON_NAMES):
                if INTENSIVE[j] and g[:, j].any():
                    out[name] = int(g[:, j].sum())
        for name, lacking in self._missing(table, traces).items():
            if lacking.any():
                out[f"missing {name}"] = int(lacking.sum())
        return out

    def score(self, table: pd.DataFrame, traces=None) -> tuple[np.ndarray, np.ndarray]:
        """``(domain_score, in_domain)`` per trip, shapes (n_trips,).

        ``domain_score`` is the largest gap over the intensive quantities (0 on a
        training value, 1 at the tolerance), at least :data:`MISSING_INPUT_SCORE` for a
        trip lacking a trained-with input; ``in_domain`` is ``score <= 1``.
        """
        s = self.gap(table, traces)
        s = np.where(self.missing_inputs(table, traces), np.maximum(s, MISSING_INPUT_SCORE), s)
        return s, s <= 1.0

    def assess(self, table: pd.DataFrame, traces=None, *, columns=None, fade: bool = False,
               warn: bool = False, stacklevel: int = 4):
        """:class:`~hybridev.learning.steps.DomainAssessment` of the trips of ``table``.

        ``columns``: the table's columns as arrays (:meth:`_score_columns`; only without
        ``traces``). ``fade``: add the discrepancy's weight per trip (``fade``, and
        ``mode_fade`` for the trips lacking a trained-with mode; None where it is 1 for
        every trip, :meth:`discrepancy_fade`). ``warn``: warn once when some trips are
        out (:func:`warn_out_of_domain`, with the reasons).
        """
        from hybridev.learning.steps import DomainAssessment

        n = len(table)
        if columns is not None and traces is None:
            grade = columns["grade_pct"] if "grade_pct" in columns else np.zeros(n)
            q = _quantities(columns["temperature_c"], columns["avg_speed_kmh"],
                            columns["distance_km"], grade)
            has_trace = np.zeros(n, dtype=bool)
            mode = columns.get("mode")
        else:
            q, has_trace = domain_quantities(table, traces)
            mode = table["mode"].to_numpy(dtype=object) if "mode" in table.columns else None
        g, inner = self._gaps(q, both=True)  # and the interior gap, in the same pass
        gap = _intensive_max(g)  # intensive conditions only (the module docstring)
        no_mode = ((pd.isna(mode) if mode is not None else np.ones(n, dtype=bool))
                   if self.needs_mode else np.zeros(n, dtype=bool))
        no_trace = ~has_trace if self.needs_trace else np.zeros(n, dtype=bool)
        score = np.where(no_mode | no_trace, np.maximum(gap, MISSING_INPUT_SCORE), gap)
        ok = score <= 1.0
        reasons = {}
        if not ok.all():
            for j, name in enumerate(_REASON_NAMES):
                if INTENSIVE[j] and (g[:, j] > 1.0).any():
                    reasons[name] = int((g[:, j] > 1.0).sum())
            for name, lacking in (("mode", no_mode), ("logged trace", no_trace)):
                if lacking.any():
                    reasons[f"missing {name}"] = int(lacking.sum())
            if warn:
                warn_out_of_domain(int((~ok).sum()), n, reasons=reasons, stacklevel=stacklevel)
        out = DomainAssessment(score=score, in_domain=ok, gap=gap, no_trace=no_trace,
                               no_mode=no_mode, reasons=reasons, has_trace=has_trace,
                               interp_gap=inner)
        if reasons:  # some trip is out: the gap and inflation of its out-of-domain spread
            out.ood_gap = np.where(no_trace, np.maximum(gap, MISSING_INPUT_SCORE), gap)
            out.inflation = self.inflation(out.ood_gap)
        if fade and n:
            out.fade = None if np.all(gap <= 1.0) else self.discrepancy_fade(gap)
            sub = gap[no_mode]
            out.mode_fade = None if np.all(sub <= 1.0) else self.discrepancy_fade(sub)
        return out

    def _score_columns(self, columns, n_trips: int) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`score` without logged traces, of a table given as arrays by column name.

        ``columns`` holds ``distance_km``, ``avg_speed_kmh``, ``temperature_c``
        (float), optionally ``grade_pct`` (float) and ``mode`` (object, ``None``
        where unknown), for ``n_trips`` trips.
        """
        n = int(n_trips)
        grade = columns["grade_pct"] if "grade_pct" in columns else np.zeros(n)
        q = _quantities(columns["temperature_c"], columns["avg_speed_kmh"],
                        columns["distance_km"], grade)
        s = _intensive_max(self._gaps(q))
        miss = np.zeros(n, dtype=bool)
        if self.needs_mode:
            miss |= pd.isna(columns["mode"]) if "mode" in columns else np.ones(n, dtype=bool)
        if self.needs_trace:  # no trip has a logged trace
            miss |= np.ones(n, dtype=bool)
        s = np.where(miss, np.maximum(s, MISSING_INPUT_SCORE), s)
        return s, s <= 1.0

    def clip_features(self, x: np.ndarray) -> np.ndarray:
        """Standardised network inputs held inside their training range (same shape)."""
        return np.clip(x, self.feature_lo, self.feature_hi).astype(np.asarray(x).dtype)

    @staticmethod
    def inflation(score) -> np.ndarray:
        """Spread multiplier of out-of-domain trips: ``1 + 0.25 (score - 1)``, in [1, 3]."""
        s = np.asarray(score, float)
        return np.clip(1.0 + OOD_INFLATION_PER_UNIT * (s - 1.0), 1.0, _MAX_INFLATION)

    @staticmethod
    def discrepancy_fade(score) -> np.ndarray:
        """Weight of the model-discrepancy stage at a gap ``score``: 1 down to 0, in [0, 1].

        ``1 - (inflation(score) - 1) / 2``: 1 inside the domain (``score <= 1``),
        falling linearly to 0 where the inflation saturates (``score >= 9``).
        Kennedy and O'Hagan's discrepancy reverts to its prior (none) away from
        the data; :mod:`hybridev.bayes.discrepancy`'s term weights are fitted
        where the trips were, and a trade between collinear terms there (the
        heating against the auxiliary load in a winter log) does not hold where
        one of them vanishes (``evaluation/seasonal_car``).

        Examples
        --------
        >>> TrainingDomain.discrepancy_fade([0.5, 1.0, 5.0, 9.0, 20.0]).tolist()
        [1.0, 1.0, 0.5, 0.0, 0.0]
        """
        return 1.0 - (TrainingDomain.inflation(score) - 1.0) / (_MAX_INFLATION - 1.0)

    # -- persistence -------------------------------------------------------------------
    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays for the saved model (see :mod:`hybridev.learning.persist`)."""
        out = {f"q{j}": v for j, v in enumerate(self.values)}
        out.update(feature_lo=self.feature_lo, feature_hi=self.feature_hi,
                   flags=np.array([self.needs_mode, self.needs_trace], dtype=np.int8))
        return out

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> TrainingDomain:
        """Inverse of :meth:`to_arrays` (ValueError on a missing array)."""
        try:
            values = tuple(np.asarray(a[f"q{j}"], float) for j in range(len(DOMAIN_QUANTITIES)))
            flags = np.asarray(a["flags"]).astype(bool)
            return cls(values, np.asarray(a["feature_lo"], float),
                       np.asarray(a["feature_hi"], float), bool(flags[0]), bool(flags[1]))
        except KeyError as exc:
            raise ValueError(f"training domain: array {exc} is missing") from exc


def _intensive_max(gaps: np.ndarray) -> np.ndarray:
    """Row-wise largest gap over the intensive columns of ``gaps`` (n_trips, 5)."""
    return gaps[:, INTENSIVE].max(axis=1) if len(gaps) else np.zeros(0)


def warn_out_of_domain(n_out: int, n_trips: int, *, stacklevel: int = 3,
                       reasons: dict[str, int] | None = None, what: str = "trip(s)") -> None:
    """Warn (:class:`~hybridev.core.errors.OutOfDomainWarning`) when ``n_out > 0``;
    ``reasons`` (:meth:`TrainingDomain.reasons`) says which conditions, with counts;
    ``what`` names the rows (``"condition(s)"`` for range conditions)."""
    if n_out:
        why = (f" (here: {', '.join(f'{k} {v}' for k, v in reasons.items())})"
               if reasons else "")
        warnings.warn(
            f"{n_out} of {n_trips} {what} lie outside the conditions the model was trained "
            "on (temperature, speed or grade beyond the training values, or a missing "
            f"input it was trained with){why}: see the in_domain and domain_score "
            "columns; their intervals widen with the distance to the data",
            OutOfDomainWarning, stacklevel=stacklevel)
