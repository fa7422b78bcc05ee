"""The values passed between the steps of the hybrid model's predictive path.

Each step of :func:`hybridev.learning.pipeline.predictive_path` takes and returns one of
these (or :class:`~hybridev.learning.predictive.EnergyDistribution`); see
``docs/architecture.md``. They hold arrays and tables only: no step calls back into
another.

==========================  ======================================  =====================
value                       made by                                 read by
==========================  ======================================  =====================
:class:`PhysicsDraws`       physics stage                           domain, residual
:class:`DomainAssessment`   training domain                         physics fade, OOD
:class:`RawPrediction`      residual learner + distribution builder calibrator, OOD
:class:`CalibratedInterval` calibrator                              OOD, output
==========================  ======================================  =====================
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field, replace

import numpy as np
import pandas as pd

from hybridev.physics.trips import _physics_columns, append_columns

__all__ = ["ARRAY_COLUMNS", "CalibratedInterval", "DomainAssessment", "PhysicsDraws",
           "RawPrediction", "table_columns"]

ARRAY_COLUMNS = ("distance_km", "avg_speed_kmh", "temperature_c", "soc_initial", "hour",
                 "grade_pct", "max_speed_kmh", "energy_kwh_physics", "kwh_per_km_physics",
                 "elevation_gain_m", "elevation_loss_m")
"""Float columns of a physics table that the point prediction reads."""


def table_columns(table: pd.DataFrame) -> dict[str, np.ndarray]:
    """The :data:`ARRAY_COLUMNS` of ``table`` present (float) and ``mode`` (object)."""
    present = set(table.columns)
    cols = {c: table[c].to_numpy(float) for c in ARRAY_COLUMNS if c in present}
    if "mode" in present:
        cols["mode"] = table["mode"].to_numpy(object)
    return cols


@dataclass
class PhysicsDraws:
    """The physics of a batch of trips (output of :meth:`PhysicsStage.transform`).

    Attributes
    ----------
    table : pandas.DataFrame, (n_trips, ...)
        The validated trips (``mode`` ``None`` where unknown); with the physics columns
        from the start without a posterior, unless :attr:`append` holds them.
    columns : dict of str to numpy.ndarray
        The table's columns the prediction reads (:data:`ARRAY_COLUMNS` and ``mode``),
        as arrays, each looked up once; with the physics columns of the model's
        physics once :meth:`faded` (posterior physics).
    append : dict of str to numpy.ndarray
        Physics columns still to append to ``table``: the fast path without a
        posterior, and the model's physics once :meth:`faded`.
    physics : list of dict of str to numpy.ndarray
        Per physics, after :meth:`faded` (posterior physics): its four physics
        columns (:func:`hybridev.physics.trips.with_physics_columns`).
    energies : list of numpy.ndarray, each (1 + n_draws, n_trips), kWh
        Per physics (the model's, then each CV+ fold's): the posterior median, then the
        draws, with the discrepancy at full weight; the nominal physics (one row)
        without a posterior.
    plain : list of callable or None
        Per physics: the same energies without the discrepancy (``None`` without one),
        for :meth:`faded`.
    n_draws : int
    max_speed_kmh : numpy.ndarray or None
        Per trip, for the table's ``max_speed_kmh`` (posterior physics).
    capacity_kwh : float
    modes : dict of str to PhysicsDraws
        For trips lacking the mode every training trip had: their physics under each
        mode (by name); empty otherwise.
    tables : list of pandas.DataFrame
        Per physics, its table (after :meth:`faded`; built on first use: the predictive
        path reads :meth:`entry_columns` and builds its output table once).
    """

    table: pd.DataFrame
    columns: dict = field(default_factory=dict)
    append: dict = field(default_factory=dict)
    energies: list = field(default_factory=list)
    plain: list = field(default_factory=list)
    n_draws: int = 0
    max_speed_kmh: np.ndarray | None = None
    capacity_kwh: float = 0.0
    modes: dict = field(default_factory=dict)
    physics: list = field(default_factory=list)
    built: list | None = field(default=None, repr=False)

    @property
    def tables(self) -> list[pd.DataFrame]:
        """Per physics, the validated trips with its physics columns (after :meth:`faded`)."""
        if self.built is None:
            self.built = [append_columns(self.table, p) for p in self.physics]
        return self.built

    def entry_columns(self, entry: int = 0) -> dict[str, np.ndarray]:
        """:attr:`columns` of the table of ``entry`` (after :meth:`faded`)."""
        if self.physics:
            return {**self.columns, **self.physics[entry]}
        return self.columns or table_columns(self.tables[entry])

    def output_parts(self) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
        """``(table, physics)``: the model's physics table is ``table`` with the columns
        ``physics`` appended (after :meth:`faded`)."""
        return (self.table, self.physics[0]) if self.physics else (self.tables[0], {})

    @property
    def posterior(self) -> bool:
        """Whether the energies come from a posterior (their table waits for the fade)."""
        return self.max_speed_kmh is not None

    def faded(self, fade: np.ndarray | None, mode_fade: np.ndarray | None = None
              ) -> PhysicsDraws:
        """The physics with each trip's discrepancy weighted by ``fade`` (n_trips,).

        ``E = E_plain + fade (E - E_plain)``; ``None``: weight 1 for every trip.
        ``mode_fade``: the same for the trips of :attr:`modes`. Builds :attr:`tables`.
        """
        modes = {m: d.faded(mode_fade) for m, d in self.modes.items()}
        if not self.posterior:
            full = append_columns(self.table, self.append) if self.append else self.table
            return replace(self, built=[full] * len(self.energies), modes=modes)
        cols, energies, physics = self.columns or table_columns(self.table), [], []
        for energy, plain in zip(self.energies, self.plain, strict=True):
            if fade is not None and plain is not None:
                p = plain()
                blend = energy - p  # p + fade (energy - p), bit for bit, with one temporary
                blend *= fade  # (n_draws x n_trips arrays: each fresh one is page faults)
                blend += p
                energy = blend
            energies.append(energy[1:] if self.n_draws else energy[:1])
            physics.append(_physics_columns(energy[0], self.max_speed_kmh, self.capacity_kwh,
                                            cols["soc_initial"], cols["distance_km"]))
        return replace(self, energies=energies, physics=physics, built=None, modes=modes,
                       columns={**cols, **physics[0]}, append=physics[0])

    def point_columns(self) -> dict[str, np.ndarray]:
        """The columns the point prediction reads, as arrays (after :meth:`faded`)."""
        return self.columns or table_columns(self.table)

    def draws(self, entry: int = 0) -> np.ndarray:
        """Physics energies of posterior draws of ``entry`` (after :meth:`faded`), kWh."""
        if self.posterior:
            return self.energies[entry]
        return self.tables[entry]["energy_kwh_physics"].to_numpy(float)[None, :]


@dataclass
class DomainAssessment:
    """How far each trip lies from the training domain (:meth:`TrainingDomain.assess`).

    Attributes
    ----------
    score : numpy.ndarray, shape (n_trips,)
        ``domain_score``: the largest gap, at least 2 for a missing trained-with input.
    in_domain : numpy.ndarray of bool, shape (n_trips,)
    gap : numpy.ndarray, shape (n_trips,)
        Largest gap over the intensive domain quantities (in tolerances), missing inputs
        aside.
    no_trace, no_mode : numpy.ndarray of bool, shape (n_trips,)
        Trips lacking a logged trace / a mode the model was trained with.
    interp_gap : numpy.ndarray, shape (n_trips,), or None
        Largest interpolation gap between training values of the intensive
        quantities (:meth:`TrainingDomain.interior_gap`; in the domain, widened at a
        learned rate).
    has_trace : numpy.ndarray of bool, shape (n_trips,), or None
        Trips with a logged trace (whatever the model was trained with): the others
        are planned trips of a model with a planned-trip calibrator
        (:mod:`hybridev.learning.planned`).
    reasons : dict of str to int
        Trips out of the domain per reason (:meth:`TrainingDomain.reasons`).
    fade, mode_fade : numpy.ndarray or None
        The discrepancy's weight per trip (and per trip lacking a trained-with mode),
        None where it is 1 for every trip.
    ood_gap, inflation : numpy.ndarray, shape (n_trips,), or None
        The gap of the out-of-domain spread (a missing trained-with trace counts as
        2) and its inflation (:meth:`TrainingDomain.inflation`); None when every trip
        is in the domain.
    """

    score: np.ndarray
    in_domain: np.ndarray
    gap: np.ndarray
    no_trace: np.ndarray
    no_mode: np.ndarray
    reasons: dict
    fade: np.ndarray | None = None
    mode_fade: np.ndarray | None = None
    ood_gap: np.ndarray | None = None
    inflation: np.ndarray | None = None
    has_trace: np.ndarray | None = None
    interp_gap: np.ndarray | None = None


@dataclass(init=False)
class RawPrediction:
    """The uncalibrated prediction of a batch of trips.

    Attributes
    ----------
    base : pandas.DataFrame, (n_trips, ...)
        Validated trips; with the physics columns unless :attr:`physics` holds them.
    table : pandas.DataFrame, (n_trips, ...)
        Validated trips with the physics columns (``base`` and ``physics``, built on
        first use).
    dist : EnergyDistribution
        The raw predictive distribution of the fitted model (spread factor 1).
    folds : list of EnergyDistribution
        The same from each CV+ fold model (empty without CV+).
    mode_means : numpy.ndarray, shape (3, n_no_mode), kWh, or None
        Point energies of the trips lacking a trained-with mode under each of the three
        modes (see :mod:`hybridev.learning.ood`).
    mean, std : numpy.ndarray, shape (n_trips,), kWh
        Mean and spread of ``dist``.
    fold_means, fold_stds : numpy.ndarray, shape (n_folds, n_trips), kWh, or None
        The same of each fold distribution (spreads at least 1e-12); None without CV+.
    var_draws : numpy.ndarray, shape (n_trips,), kWh^2
        Variance of the physics draws.
    excess_var : numpy.ndarray, shape (n_trips,), kWh^2
        ``dist``'s variance beyond the draws' (:meth:`EnergyDistribution.excess_var`).
    physics : dict of str to numpy.ndarray
        Physics columns still to append to ``base`` (empty: ``base`` has them).
    columns : dict of str to numpy.ndarray or None
        The physics table's columns as arrays (:meth:`PhysicsDraws.entry_columns`;
        None: read from :attr:`table`).
    """

    base: pd.DataFrame
    dist: EnergyDistribution  # noqa: F821 (hybridev.learning.predictive)
    folds: list = field(default_factory=list)
    mode_means: np.ndarray | None = None
    mean: np.ndarray | None = None
    std: np.ndarray | None = None
    fold_means: np.ndarray | None = None
    fold_stds: np.ndarray | None = None
    var_draws: np.ndarray | None = None
    excess_var: np.ndarray | None = None
    physics: dict = field(default_factory=dict)
    columns: dict | None = None

    def __init__(self, table=None, dist=None, folds=None, mode_means=None, mean=None,
                 std=None, fold_means=None, fold_stds=None, var_draws=None, excess_var=None,
                 physics=None, columns=None, *, base=None) -> None:
        # ``table`` (the physics table, as before) or ``base`` with ``physics`` to append
        self.base = table if base is None else base
        self.dist, self.folds, self.mode_means = dist, list(folds or []), mode_means
        self.mean, self.std, self.fold_means, self.fold_stds = mean, std, fold_means, fold_stds
        self.var_draws, self.excess_var = var_draws, excess_var
        self.physics, self.columns = dict(physics or {}), columns

    @functools.cached_property
    def table(self) -> pd.DataFrame:
        """Validated trips with the physics columns (built on first use)."""
        return append_columns(self.base, self.physics) if self.physics else self.base


@dataclass
class CalibratedInterval:
    """Conformally calibrated energy interval per trip, kWh (before the out-of-domain step).

    Attributes
    ----------
    mean, std : numpy.ndarray, shape (n_trips,)
        Mean and spread of the raw distribution.
    lo, hi : numpy.ndarray, shape (n_trips,)
        Two-sided interval at the level, holding ``mean``.
    lo_one : numpy.ndarray, shape (n_trips,)
        One-sided lower bound at the level (for trips that may empty the battery).
    spread_factor : float
        The calibrator's multiplier on the raw spread (1 when uncalibrated).
    quantile : float, numpy.ndarray (n_trips,) or None
        The conformal quantile ``q`` of the level (None when uncalibrated; per trip when
        planned trips have their own, :mod:`hybridev.learning.planned`).
    quantile_one : float, numpy.ndarray (n_trips,) or None
        The one-sided factor ``q'`` of the normalised lower bound ``mean - q' std``.
    """

    mean: np.ndarray
    std: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    lo_one: np.ndarray
    spread_factor: float = 1.0
    quantile: float | np.ndarray | None = None
    quantile_one: float | np.ndarray | None = None
