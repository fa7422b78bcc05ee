"""How much wider intervals must be outside the training conditions: a learned rate.

A trip whose intensive conditions (temperature, speed, grade;
:mod:`hybridev.learning.domain`) lie a gap ``g > 1`` tolerances away from
every training trip gets its interval widened by the factor

``inflation(g) = clip(1 + rate * (g - 1), 1, 3)``.

The rate used to be a fixed 0.25 (:data:`~hybridev.learning.domain.OOD_INFLATION_PER_UNIT`).
:class:`GapRate` learns it from the fit's own out-of-sample scores instead:
the conformal step already scores every trip (CV+) or a held-out share (split)
with a model that did not see its day. Trips whose day brought conditions the
other days lack lie *outside their fold's training domain* (the domain is
re-recorded from each fold's training trips): they are natural shift
experiments. Each such trip's normalised score ``a_i = |y - mu| / s``,
over the in-domain conformal quantile ``q`` at the fit level (0.9), says
how much wider its interval needed to be; ``k_i = (a_i / q - 1) / (g_i - 1)``
is the rate that would just have covered it. The learned rate is the linear
quantile regression (at the same level) of ``a_i / q - 1`` on ``g_i - 1``
through the origin: the smallest rate that covers about 90 % of the shifted
trips, each weighted by its gap ``g_i - 1`` (the minimiser of the pinball loss
is the weighted quantile of the ``k_i``). The weights make it robust: a trip
just outside its fold's domain with an ordinary large score (one in ten has
one inside the domain too) has a huge ``k_i`` but almost no weight. It is
floored at :data:`GAP_RATE_FLOOR` (a width that does not grow at all away from
the data is not credible however few trips say so) and capped at
:data:`GAP_RATE_CAP`. With fewer than :data:`MIN_SHIFTED_TRIPS` shifted trips
the rate is the larger of that estimate and the fixed 0.25 (conservative).
The in-domain quantile ``q`` needs at least 9 in-domain trips; with fewer, all
the trips' scores give it.

**Between training values.** A condition between two training values (a
temperature between two logged ones) is interpolated, not new: it stays in the
domain (:meth:`~hybridev.learning.domain.TrainingDomain.interior_gap`). Its
interval is widened by ``clip(1 + interp_rate * (h - 1), 1, 3)`` with ``h`` the
distance to the nearest training value in tolerances, so 1 (no widening) for a
condition within a tolerance of the data. ``interp_rate`` is learned as the
rate above (without its floor: interpolating may need no widening at all), from the scored trips that lie between their fold's training values
(``h > 1``) and not beyond them; with fewer than :data:`MIN_SHIFTED_TRIPS` such
trips it is :data:`~hybridev.learning.domain.OOD_INFLATION_PER_UNIT` (a logged
history whose days bracket each other closely has no such trips, and needs no
widening: its ``h`` stays below 1). A model saved before this rate has none
(interpolation not widened, its predictions unchanged).

**Held-out bands.** Split conformal scores a random share of the trips, whose
conditions are those of the training trips: it has no trip between its fold's
values, and a design of a few fixed conditions (speeds 40, 60, ... km/h; -5, 20
and 32 °C) left the interpolation rate at the fixed 0.25 although its own data
can measure it. :func:`held_out_bands` makes such experiments: for each intensive
quantity, its training values are grouped into clusters (consecutive values within
a tolerance), and per quantity the interior cluster (neither the lowest nor the
highest) farthest from its neighbours is held out (at most half the trips; one
refit per quantity bounds the fit time). The residual ensemble is refitted without
the band's trips (:func:`hybridev.learning.fitting.held_band_scores`), and the
band's *calibration* trips, which neither the physics posterior nor any network saw,
are scored by it: their interpolation gap to the remaining values (``h > 1`` by
construction) and their score say how the error grows between the training values.
Their scores join the interpolation rate's (the in-domain quantile stays that of
the ordinary calibration trips), **paired** with the final model's scores of the same
trips (which the final model, trained with the band, scores out of sample too): each
band's scores are scaled by the in-domain quantile over the band's own quantile under
the final model, so that the rate measures how much *more* the refit errs there than a
model that had the band, not how hard the band's conditions are anyway. Unpaired, a
band's own difficulty was read as the gap's: on the structured benchmark the final model
errs on the held-out 20 °C and 60 km/h calibration trips about as much as the refits
that never saw them, and the unpaired rate widened the range bands at 7.5 °C well past
their nominal 80 % (``evaluation/range_bands``). One rate serves every quantity, so the bands are
used only when every quantity with room to interpolate has one (otherwise the
fallback rate stays). Documented shortcut: the refit shares the physics posterior
(a few global parameters, fitted on the band's training trips but never on the
scored ones) and the input and target standardisation of the final model (as CV+
fold ensembles share the standardisation).

The rate *beyond* the conditions is not learned this way. Holding out an edge band
needs the physics posterior refitted without it too (a posterior that saw the cold
trips knows their heater), and one rate would then speak for every quantity: a model
trained at 20 and 32 °C only can hold out a speed edge (where extrapolating is
benign) but no temperature edge, and a rate learned there left its trips at -5 °C
with 90 % intervals far too narrow (the learned rate also drops the physics posterior
predictive floor). Beyond the data the fixed rate and that floor
(:mod:`hybridev.learning.ood`) stay.

Why not weighted conformal prediction (Tibshirani et al. 2019)? It re-weights
the calibration scores by the likelihood ratio of the new trip's conditions;
for a trip outside the training conditions that ratio is unbounded and the
weighted quantile is infinite, so it helps only for moderate shifts inside the
data's support, where :mod:`hybridev.learning.domain` already finds a trip in
the domain. With 20-100 trips from a handful of days the density ratio itself
would be the least reliable part. The rate above answers the question that
matters beyond the support, with the data's own shifted trips.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.learning.domain import (
    DOMAIN_TOLERANCES,
    INTENSIVE,
    OOD_INFLATION_PER_UNIT,
    TrainingDomain,
    domain_quantities,
)

__all__ = ["FIT_LEVEL", "GAP_RATE_CAP", "GAP_RATE_FLOOR", "MAX_HELD_BANDS", "MAX_INFLATION",
           "MIN_SHIFTED_TRIPS", "GapRate", "band_scores", "fold_gaps", "held_out_bands"]

FIT_LEVEL = 0.9
"""Confidence level at which the rate is learned (and the in-domain quantile taken)."""

GAP_RATE_FLOOR = 0.1
"""Smallest learned rate: the width grows at least 10 % per tolerance beyond the data."""

GAP_RATE_CAP = 2.0
"""Largest learned rate: the inflation then reaches its cap (3) at a gap of 2."""

MIN_SHIFTED_TRIPS = 9
"""Shifted trips needed for the 0.9 quantile of their rates (``ceil(10 * 0.9) <= 9``)."""

MAX_INFLATION = 3.0
"""Cap of the inflation factor (as before the learned rate)."""

MAX_HELD_BANDS = 3
"""Interior bands held out at most (one refit of the residual ensemble each): one per
intensive quantity."""


@dataclass
class GapRate:
    """Learned widening rate per unit of intensive domain gap.

    Attributes (after :meth:`fit`)
    ------------------------------
    rate_ : float
        Inflation per unit gap beyond 1, dimensionless.
    n_shifted_ : int
        Scored trips outside their fold's training domain that it was learned from.
    learned_ : bool
        Whether the quantile was defined (``n_shifted_ >= MIN_SHIFTED_TRIPS``).
    interp_rate_ : float
        Inflation per unit interpolation gap beyond 1 (0: a model saved before it).
    n_interp_ : int
        Scored trips between their fold's training values (gap ``> 1``) it was
        learned from.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> gap = np.r_[np.zeros(200), rng.uniform(1.0, 5.0, 60)]
    >>> scores = rng.normal(size=260) * (1.0 + 0.5 * np.maximum(gap - 1.0, 0.0))
    >>> r = GapRate().fit(scores, gap)
    >>> 0.3 < r.rate_ < 1.0, r.n_shifted_
    (True, 60)
    """

    interp_rate_ = 0.0  # class defaults: a model saved before the interpolation rate
    n_interp_ = 0

    def fit(self, scores, gaps, *, interp=None, level: float = FIT_LEVEL) -> GapRate:
        """Learn the rate from normalised scores and their gaps.

        Parameters
        ----------
        scores : array_like, shape (n,) or a sequence of such arrays
            Signed normalised out-of-sample scores ``(y - mu) / s``. Several
            arrays (e.g. the scores with and without logged traces) are pooled,
            each against its own in-domain quantile.
        gaps : array_like, shape (n,) or a sequence of such arrays
            Each trip's largest intensive gap to its fold's training domain.
        interp : array_like or a sequence of such arrays, optional
            Each trip's largest interpolation gap between its fold's training values
            (:meth:`~hybridev.learning.domain.TrainingDomain.interior_gap`); None:
            no such trips (the fallback rate).
        level : float
            Level of the in-domain quantile and of the rate's quantile.
        """
        if isinstance(scores, np.ndarray) or np.ndim(scores[0]) == 0:
            scores, gaps = [scores], [gaps]
            interp = None if interp is None else [interp]
        if interp is None:
            interp = [np.zeros(np.shape(g)) for g in gaps]
        self.rate_, self.n_shifted_, self.learned_ = self._learn(scores, gaps, None, level,
                                                                 GAP_RATE_FLOOR)
        self.interp_rate_, self.n_interp_, _ = self._learn(scores, interp, gaps, level, 0.0)
        return self

    @staticmethod
    def _learn(scores, gaps, beyond, level: float, floor: float
               ) -> tuple[float, int, bool]:
        """``(rate, n_shifted, learned)`` from the trips with ``gap > 1`` (and, with
        ``beyond`` given, not beyond the range: ``beyond <= 1``); at least ``floor``."""
        if beyond is None:
            beyond = [np.zeros(np.shape(g)) for g in gaps]
        k, w = [], []
        for s, g, b in zip(scores, gaps, beyond, strict=True):
            a, g = np.abs(np.asarray(s, float)), np.asarray(g, float)
            if a.shape != g.shape or a.shape != np.shape(b):
                raise ValueError(f"scores and gaps must have one value per trip; got "
                                 f"{a.shape}, {g.shape}")
            out = g > 1.0
            plain = ~out & (np.asarray(b, float) <= 1.0)  # neither gap: the in-domain trips
            out &= np.asarray(b, float) <= 1.0
            if not out.any() or a.size < 9:
                continue
            inside = a[plain] if plain.sum() >= 9 else a
            q = max(_conformal_quantile(inside, level), 1e-12)
            k.append((a[out] / q - 1.0) / (g[out] - 1.0))
            w.append(g[out] - 1.0)
        k = np.concatenate(k) if k else np.zeros(0)
        learned = bool(k.size >= MIN_SHIFTED_TRIPS)
        rate = _weighted_quantile(k, np.concatenate(w), level) if k.size else 0.0
        if not learned:
            rate = max(rate, OOD_INFLATION_PER_UNIT)
        return float(np.clip(rate, floor, GAP_RATE_CAP)), int(k.size), learned

    def inflation(self, gap) -> np.ndarray:
        """Width multiplier ``clip(1 + rate_ (gap - 1), 1, 3)``, shape of ``gap``."""
        g = np.asarray(gap, float)
        return np.clip(1.0 + self.rate_ * (g - 1.0), 1.0, MAX_INFLATION)

    def interp_inflation(self, gap) -> np.ndarray:
        """Width multiplier between training values ``clip(1 + interp_rate_ (gap - 1),
        1, 3)``, shape of ``gap`` (None: 1)."""
        if gap is None:
            return np.float64(1.0)
        g = np.asarray(gap, float)
        return np.clip(1.0 + self.interp_rate_ * (g - 1.0), 1.0, MAX_INFLATION)

    def to_arrays(self) -> dict[str, np.ndarray]:
        """State for the saved model: ``{"state": [rate_, n_shifted_, learned_,
        interp_rate_, n_interp_]}``."""
        return {"state": np.array([self.rate_, self.n_shifted_, float(self.learned_),
                                   self.interp_rate_, self.n_interp_])}

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> GapRate:
        """Inverse of :meth:`to_arrays` (ValueError on a bad array); a state of 3 values
        (saved before the interpolation rate) gets ``interp_rate_ = 0``."""
        s = np.asarray(a.get("state", []), float)
        if s.shape not in ((3,), (5,)) or not np.all(np.isfinite(s)) or s[0] < 0 or (
                s.size == 5 and s[3] < 0):
            raise ValueError(f"gap rate: array 'state' must hold 3 or 5 finite values; "
                             f"got {s!r}")
        out = cls()
        out.rate_, out.n_shifted_, out.learned_ = float(s[0]), int(s[1]), bool(s[2])
        if s.size == 5:
            out.interp_rate_, out.n_interp_ = float(s[3]), int(s[4])
        return out


def _conformal_quantile(values: np.ndarray, level: float) -> float:
    """The ``ceil((n + 1) level)``-th smallest value (the largest when that exceeds n)."""
    v = np.sort(np.asarray(values, float))
    return float(v[min(math.ceil((v.size + 1) * level), v.size) - 1])


def _weighted_quantile(values: np.ndarray, weights: np.ndarray, level: float) -> float:
    """Smallest value whose cumulative weight share reaches ``level``."""
    order = np.argsort(values)
    cum = np.cumsum(weights[order]) / max(float(weights.sum()), 1e-300)
    return float(values[order][min(int(np.searchsorted(cum, level)), values.size - 1)])


def fold_gaps(trips: pd.DataFrame, fold: np.ndarray, traces=None, *,
              score_traces=None, interior: bool = False):
    """Each scored trip's largest intensive gap to its fold's training domain, (n,).

    With ``interior=True`` a pair: the gaps and the interpolation gaps
    (:meth:`~hybridev.learning.domain.TrainingDomain.interior_gap`), (n,) each.

    Parameters
    ----------
    trips : pandas.DataFrame, (n, ...)
        Validated trips (domain columns, ``trip_id``).
    fold : numpy.ndarray of int, shape (n,)
        Fold of each trip (-1: never scored; its gap is 0). The training domain
        of fold ``f`` is recorded from the trips with ``fold != f`` (and ``fold
        >= 0`` unless every scored trip is in one fold: then from ``fold == -1``,
        the split-conformal case).
    traces : LoggedTraces, optional
        Traces of the training trips (their grade).
    score_traces : LoggedTraces, optional
        Traces with which the scored trips are scored (None: summary only).
    """
    fold = np.asarray(fold, int)
    out, inner = np.zeros(len(trips)), np.zeros(len(trips))
    folds = np.unique(fold[fold >= 0])
    for f in folds:
        train = (fold != f) & ((fold >= 0) | (len(folds) == 1))
        if not train.any():
            continue
        dom = TrainingDomain.fit(trips.iloc[np.flatnonzero(train)], np.zeros((train.sum(), 1)),
                                 traces=traces)
        held = np.flatnonzero(fold == f)
        q = domain_quantities(trips.iloc[held], score_traces)[0]
        out[held] = dom.gap(trips.iloc[held], score_traces)
        inner[held] = dom.interior_gap(q)
    return (out, inner) if interior else out


def held_out_bands(q: np.ndarray, max_bands: int = MAX_HELD_BANDS
                   ) -> list[tuple[int, float, float]]:
    """Interior bands of the training conditions to hold out: ``(quantity, low, high)``.

    Parameters
    ----------
    q : numpy.ndarray, shape (n_trips, 5)
        :func:`~hybridev.learning.domain.domain_quantities` of the training trips.
    max_bands : int
        At most this many bands, the widest-gap ones first.

    Returns
    -------
    list of (int, float, float)
        Column of ``q`` and the band's lowest and highest training value. The values
        of each intensive quantity are grouped into clusters (consecutive values
        within a tolerance); per quantity the interior cluster (neither the lowest nor
        the highest) farthest (in tolerances) from its nearest neighbour (the first on
        a tie), of at most half the trips. Empty when a quantity with room to
        interpolate (two clusters or more) has no such band (two clusters, or a band
        over half the trips): one rate serves every quantity, so a rate measured on the
        others would speak for it unmeasured.

    Examples
    --------
    >>> t = np.zeros((6, 5))
    >>> t[:, 0] = [-5.0, -5.0, 20.0, 21.0, 32.0, 32.0]  # temperature, °C
    >>> held_out_bands(t)  # 20-21 °C: interior, its values within 3 °C
    [(0, 20.0, 21.0)]
    >>> held_out_bands(t[[0, 1, 4, 5]])  # -5 and 32 °C: nothing to hold out between
    []
    """
    q = np.asarray(q, float)
    found = []
    for j in np.flatnonzero(INTENSIVE):
        v, tol = np.unique(q[:, j]), DOMAIN_TOLERANCES[j]
        cut = np.flatnonzero(np.diff(v) > tol)  # a cluster ends where the next value is far
        first, last = np.r_[0, cut + 1], np.r_[cut, v.size - 1]
        best = None
        for a, b in zip(first[1:-1], last[1:-1], strict=True):
            n_in = int(((q[:, j] >= v[a]) & (q[:, j] <= v[b])).sum())
            gap = min(v[a] - v[a - 1], v[b + 1] - v[b]) / tol
            if n_in <= len(q) / 2 and (best is None or gap > best[0]):
                best = (gap, (int(j), float(v[a]), float(v[b])))
        if best is None and len(first) >= 2:
            return []  # room to interpolate, but no band to measure it on
        if best is not None:
            found.append(best)
    found.sort(key=lambda x: -x[0])  # stable: ties keep the quantity order
    return [band for _, band in found[:max(int(max_bands), 0)]]


def band_scores(q: np.ndarray, rest: np.ndarray, scored: np.ndarray, refit, score,
                reference=None, level: float = FIT_LEVEL) -> tuple[np.ndarray, np.ndarray]:
    """Scores of the calibration trips of held-out interior bands, and their gaps.

    Parameters
    ----------
    q : numpy.ndarray, shape (n_trips, 5)
        Domain quantities of every trip.
    rest : numpy.ndarray of int
        The trips the model was trained on (its training domain).
    scored : numpy.ndarray of int
        Trips no part of the model saw (split conformal's calibration trips).
    refit : callable
        ``refit(keep, band) -> refitted``: the residual ensemble refitted on the trips
        ``keep`` (int rows, a subset of ``rest``); ``band`` its index (a seed).
    score : callable
        ``score(rows, refitted) -> scores``: signed normalised scores ``(y - mu) / s``
        of the trips ``rows`` (int) under the refitted model, (len(rows),).
    reference : array_like, shape (len(scored),), optional
        Signed normalised scores of the ``scored`` trips under the final model, which
        saw the band (split conformal's calibration scores). With it each band's scores
        are *paired*: multiplied by ``q_all / q_band``, the conformal quantiles (at
        ``level``) of ``|reference|`` over all the scored trips and over the band's,
        so that against the in-domain quantile ``q_all`` (:meth:`GapRate.fit`) they
        measure how much wider the band's intervals must be than the final model's
        intervals *for the same trips*: the gap's own share of the error, not how hard
        the band's conditions are anyway (module docstring). None: unpaired.
    level : float
        Level of those quantiles.

    Returns
    -------
    scores, interp : numpy.ndarray, shape (m,) each
        The scored trips of each band (:func:`held_out_bands` of ``q[rest]``; none, and
        no refit, when they hold fewer than :data:`MIN_SHIFTED_TRIPS` scored trips),
        concatenated, and their interpolation gap to the training values left.
    """
    q, rest, scored = np.asarray(q, float), np.asarray(rest, int), np.asarray(scored, int)
    if reference is not None:
        ref = np.abs(np.asarray(reference, float))
        if ref.shape != scored.shape or not np.all(np.isfinite(ref)):
            raise ValueError(f"reference must hold one finite score per scored trip "
                             f"({scored.shape}); got {ref.shape}")
        q_all = _conformal_quantile(ref, level) if ref.size else 1.0
    out_s, out_h = [np.zeros(0)], [np.zeros(0)]
    bands = held_out_bands(q[rest])
    in_band = [(q[scored, j] >= lo) & (q[scored, j] <= hi) for j, lo, hi in bands]
    held_of = [scored[m] for m in in_band]
    if sum(len(h) for h in held_of) < MIN_SHIFTED_TRIPS:  # too few to learn from: no refit
        bands = []
    for k, ((j, lo, hi), held) in enumerate(zip(bands, held_of, strict=False)):
        keep = rest[(q[rest, j] < lo) | (q[rest, j] > hi)]
        if not len(held):
            continue
        dom = TrainingDomain(values=tuple(np.unique(q[keep, c]) for c in range(q.shape[1])),
                             feature_lo=np.zeros(1), feature_hi=np.zeros(1))
        out_h.append(dom.interior_gap(q[held]))
        s_band = np.asarray(score(held, refit(keep, k)), float)
        if reference is not None:  # paired: against the final model on the same trips
            s_band = s_band * q_all / max(_conformal_quantile(ref[in_band[k]], level), 1e-12)
        out_s.append(s_band)
    return np.concatenate(out_s), np.concatenate(out_h)
