"""The hybrid physics + residual model (paper, Secs. III-IV) as a pipeline of components.

``E_h = E_p + dE``: the physics gives ``E_p``; an ensemble of small networks trained on
measured trips predicts the residual ``dE = E* - E_p`` from the trip features; the
final SoC is ``max(0, s0 - E_h / C)``. :class:`HybridModel` *has* one component per
job (the physics stage, residual learner, training domain and calibrator;
``docs/architecture.md``); ``fit`` makes them in that order
(:mod:`~hybridev.learning.fitting`) and every prediction runs
:func:`~hybridev.learning.pipeline.predictive_path`.

Conventions beyond the paper: trips without a ``mode`` use a uniform one-hot and the
``"normal"`` profile, without an ``hour`` noon (:mod:`~hybridev.learning.features`);
the residual never turns a consuming trip into a generating one (``max(E_p + dE,
min(E_p, 0))``); a share ``val_fraction`` (default 0.15 / 0.85, the paper's 225 of
1,275) is held out for early stopping, whole groups with ``groups=``; CV+ below
:data:`CV_PLUS_MAX_TRIPS` trips, split conformal above; an unfitted model predicts the
physics and warns (:class:`PhysicsFallbackWarning`), the paper's "defaults to the
validated physics model".
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Callable

import numpy as np
import pandas as pd

from hybridev.core.checks import check_seed
from hybridev.core.errors import PhysicsFallbackWarning
from hybridev.core.plugins import entry_point, lazy_backend
from hybridev.data.logs import MeasuredTrips
from hybridev.learning import components as comp
from hybridev.learning import fit_notes, fitting
from hybridev.learning.features import FEATURE_NAMES
from hybridev.learning.inputs import _check_range, unpack_trips
from hybridev.learning.ood import trace_gap
from hybridev.learning.params import (
    CONFORMAL_MODES,
    CV_PLUS_MAX_TRIPS,
    PAPER_CONFIG,
    PARAMETERS_DOC,
    VAL_FRACTION,
    HybridParams,
    check_params,
)
from hybridev.learning.persist import load_model, save_model
from hybridev.learning.physics_stage import PhysicsStage
from hybridev.learning.pipeline import predictive_path
from hybridev.learning.predictive import EnergyDistribution
from hybridev.learning.refit import RefitGuardMixin
from hybridev.physics.params import VehicleParams

__all__ = ["CONFORMAL_MODES", "CV_PLUS_MAX_TRIPS", "PAPER_CONFIG", "VAL_FRACTION", "HybridModel"]


class HybridModel(RefitGuardMixin, HybridParams):
    __doc__ = ("""Hybrid physics + residual-network predictor of trip energy and final SoC.

"""
               + PARAMETERS_DOC + """    Attributes
    ----------
    physics_ : PhysicsStage
        Vehicle, physics posterior and discrepancy stage
        (:class:`~hybridev.learning.physics_stage.PhysicsStage`); its state is also
        ``posterior_`` (None without ``calibrate_physics``), ``discrepancy_`` and
        ``heater_kind_`` (learned when ``vehicle`` has ``heater_kind="auto"``, the
        default of ``VehicleParams.from_coastdown``; else None).
    learner_ : ResidualLearner
        The residual ensemble (:class:`~hybridev.learning.residual.ResidualLearner`);
        its state is also ``net_``, ``history_``, ``feature_names_``,
        ``n_features_in_``, ``feature_mean_``, ``feature_std_``, ``target_mean_``,
        ``target_std_`` and ``n_parameters_`` (3,393 per member for the paper's
        network on the 11 listed inputs).
    domain_ : TrainingDomain
        Where the model was trained (:mod:`hybridev.learning.domain`).
    calibrator_ : Calibrator
        The conformal step (:class:`~hybridev.learning.calibrate.Calibrator`); its
        state is also ``conformal_`` (None when ``conformal_fraction=0``),
        ``cv_nets_``, ``cv_physics_``, ``mondrian_cut_km_`` and ``conformal_bins_``.
    gate_ : ResidualGate
        The stacking gate (:mod:`hybridev.learning.gate`; also ``learner_.gate_``).
    planned_ : PlannedTripCalibrator or None
        Planned trips' calibration (:mod:`hybridev.learning.planned`; fitted on traces).
    gap_rate_ : GapRate or None
        Learned out-of-domain widening rate (:mod:`hybridev.learning.shift`).
    fit_info_ : dict
        Trip counts, seed, fit time, validation-set errors, ``distance_km_range`` (shortest
        and longest fitting trip, km; past them the residual is held,
        :mod:`hybridev.learning.residual`), ``heater`` when the heater kind was learned
        (:mod:`hybridev.bayes.heater`), ``trace_gap_rel`` when fitted on logged traces
        (:mod:`hybridev.learning.ood`), ``residual_gate`` (its evidence), ``outliers`` and
        ``data_quality`` (:mod:`hybridev.learning.fit_notes`).

    Examples
    --------
    >>> from hybridev import make_trips, simulate
    >>> t = simulate(make_trips(40, seed=0), n_steps=100)
    >>> t["energy_kwh"] = t["energy_kwh_physics"] * 1.1
    >>> m = HybridModel(**PAPER_CONFIG, max_epochs=3, n_steps=100).fit(t, seed=0)
    >>> out = m.predict(t.drop(columns=["energy_kwh"]))
    >>> bool((out.energy_kwh_pred >= 0).all()), m.n_parameters_
    (True, 3393)

    The default (probabilistic) model also gives intervals, see
    :meth:`predict_interval`.
    """)

    _residual = True  # target E* - E_p; PureML sets False (target E*)
    _fallback_to_physics = True
    _default_features = FEATURE_NAMES

    # the components' learned state under the model's documented names
    (net_, history_, feature_mean_, feature_std_, target_mean_, target_std_,
     n_parameters_) = (comp.Part("learner_") for _ in range(7))
    posterior_, discrepancy_, heater_kind_ = (comp.Part("physics_") for _ in range(3))
    conformal_, cv_nets_, cv_physics_, mondrian_cut_km_, conformal_bins_ = (
        comp.Part("calibrator_", a) for a in (None, "fold_nets_", "fold_physics_", "cut_km_", "bins_"))

    # -- components ----------------------------------------------------------------------
    @property
    def feature_names_(self) -> tuple[str, ...]:
        return self.learner_.feature_names

    @property
    def n_features_in_(self) -> int:
        return len(self.feature_names_)

    def fitted(self) -> bool:
        """Whether the residual learner is fitted (else ``predict`` falls back to the physics)."""
        return hasattr(self.__dict__.get("learner_"), "net_")

    def components(self) -> dict:
        """The fitted components by name: ``physics``, ``learner``, ``domain``, ``calibrator``."""
        return {k: self.__dict__[f"{k}_"] for k in comp.NAMES
                if self.__dict__.get(f"{k}_") is not None}

    def physics_stage(self) -> PhysicsStage:
        """The fitted physics stage (with the current ``vehicle``), or an unfitted one."""
        return comp.physics_of(self)

    def _vehicle(self) -> VehicleParams:
        return self.physics_stage().vehicle()

    @property
    def capacity_kwh(self) -> float:
        """Battery capacity of the model's vehicle, kWh."""
        return float(self._vehicle().battery_capacity_kwh)

    def _check_params(self) -> None:
        check_params(self)

    def __sklearn_is_fitted__(self) -> bool:
        return self.fitted()

    def _require_fitted(self) -> None:
        comp.require_fitted(self)

    def _require_probabilistic(self, what: str) -> None:
        comp.require_probabilistic(self, what)

    def _check_level(self, level) -> None:
        comp.check_level(self, level)

    def fit(self, measured_trips: pd.DataFrame | MeasuredTrips, *, seed: int = 0,
            timeseries=None, groups="auto",
            progress: Callable[[int], None] | None = None) -> HybridModel:
        """Fit the residual network on measured trips.

        Parameters
        ----------
        measured_trips : pandas.DataFrame
            A measured-trip table (:func:`hybridev.data.measured.validate_measured_trips`):
            trip columns plus ``energy_kwh`` (kWh) and/or ``soc_final``. With a
            ``start_time`` column and no ``parked_min``, the minutes parked before each
            trip are derived from the table (:mod:`hybridev.data.parked`): a trip after
            a short stop starts with a warm cabin.
        seed : int
            Seeds the validation split, initialisation, data order and dropout.
        timeseries : LoggedTraces or pandas.DataFrame, optional
            Logged speed traces by ``trip_id``: the physics of those trips (calibration,
            features, residuals) runs on the real trace. A
            :class:`~hybridev.data.logs.MeasuredTrips` brings its own traces.
        groups : "auto", str, array_like (n_trips,) or None
            Groups of correlated trips (a column name such as ``"date"`` or
            ``"session_group"``, or one label per trip): every split (early stopping,
            split-conformal calibration, CV+ folds) keeps whole groups together
            (:mod:`hybridev.learning.splits`). ``"auto"`` (default): the trips' ``date``
            column, else ``session_group``, else the calendar day of ``start_time``,
            else none, as the physics calibration does; ``None``: every trip its own
            group.
        progress : callable, optional
            Called with the number of finished epochs.

        Returns
        -------
        self

        Raises
        ------
        ValueError
            On an invalid parameter or row (naming field, value and range).

        Warns
        -----
        CalibrationWarning
            When the data cannot calibrate 90 % intervals (too few calibration
            trips or groups), or when a physics parameter's posterior median
            leaves its prior's 99 % range (often an input in the wrong unit;
            :func:`hybridev.bayes.checks.warn_unphysical`).
        """
        self._check_params()
        _check_range("seed", seed, 0, 2**63 - 1, integer=True)  # of fit
        t0 = time.perf_counter()
        good, traces, table = fitting.fit_inputs(self, measured_trips, timeseries)
        split = fitting.split_trips(self, good, table, groups, seed)
        for name in comp.NAMES:
            self.__dict__.pop(f"{name}_", None)
        # 1. physics: heater kind, posterior and discrepancy (calibration trips held out)
        self.physics_, heater = fitting.fit_physics(self, good, split, traces, seed)
        # 2. residual learner and training domain on the physics of every trip
        self.learner_, self.domain_, (xs, ys, e_meas, e_phys, scale) = fitting.fit_learner(
            self, good, self.physics_.table(good, traces), split, traces, progress)
        d_fit = good["distance_km"].to_numpy(float)[split.rest]  # what the networks learn from
        self.fit_info_ = {"distance_km_range": [float(d_fit.min()), float(d_fit.max())]}
        # 3. calibrator: split conformal on the held-out trips, or CV+ folds
        self.calibrator_ = fitting.fit_calibrator(self, good, traces, split, xs, ys, e_meas,
                                                  seed)
        info = self.fit_info_ = fitting.fit_summary(self, good, split, heater, seed,
                                                    (xs, e_meas, e_phys, scale))
        # 5. planned trips (no logged trace) and the out-of-domain widening rate
        self.planned_, self.gap_rate_, self.domain_ = fitting.fit_planned(
            self, good, traces, split, e_meas, seed)
        if traces is not None and self.domain_.needs_trace:
            info["trace_gap_rel"] = trace_gap(self, good, e_meas, traces)  # learning.ood
        info.update(fit_notes.fit_notes(measured_trips, self.physics_.posterior_))
        info["fit_seconds"] = fitting.elapsed(t0)
        return self

    def predict(self, trips: pd.DataFrame, *, timeseries=None) -> pd.DataFrame:
        """Predict trip energy and final SoC.

        Parameters
        ----------
        trips : pandas.DataFrame, MeasuredTrips or dask.dataframe.DataFrame
            A trip table; ``mode`` may be missing or ``None`` and ``hour``
            missing (see the module docstring). A ``start_time`` column without
            ``parked_min`` derives it from the table's rows, as ``fit`` does. A
            :class:`~hybridev.data.logs.MeasuredTrips` brings its traces. A dask
            DataFrame gives a lazy dask DataFrame with the same rows
            (:mod:`hybridev.fleet.scoring`, needs ``pip install hybridev[dask]``).
        timeseries : LoggedTraces or pandas.DataFrame, optional
            Logged speed traces by ``trip_id`` (see :meth:`fit`).

        Returns
        -------
        pandas.DataFrame
            A copy of ``trips`` with :func:`hybridev.simulate`'s columns
            (``energy_kwh_physics``, ``soc_final_physics``, ``max_speed_kmh``,
            ``kwh_per_km_physics``; with a posterior, at its median) plus
            ``energy_kwh_pred`` (kWh, the mean over members, never below the physical
            floor, :mod:`hybridev.learning.physical`) and ``soc_final_pred`` (``s0 -
            E/C`` clipped to [0, 1]); a fitted model adds ``domain_score`` and
            ``in_domain`` (:mod:`hybridev.learning.domain`).

        Warns
        -----
        PhysicsFallbackWarning
            When the model is not fitted: ``energy_kwh_pred`` is the physics.
        OutOfDomainWarning
            Once, with the count, when some trips lie outside the training domain.
        """
        if (backend := lazy_backend(trips)) is not None:  # dask: hybridev.fleet.scoring
            return entry_point(f"{backend}.predict")(self, trips, timeseries=timeseries)
        if not self.fitted() and not self._fallback_to_physics:
            self._require_fitted()
        self._check_params()
        trips, traces = unpack_trips(trips, timeseries)
        if not self.fitted():
            warnings.warn(f"{type(self).__name__} is not fitted: energy_kwh_pred is the physics "
                          "prediction only (energy_kwh_physics); fit it on measured trips to "
                          "add the learned residual", PhysicsFallbackWarning, stacklevel=2)
        return predictive_path(self, trips, traces, kind="point")

    def predict_distribution(self, trips: pd.DataFrame, *, level: float = 0.9,
                             seed: int = 0, timeseries=None) -> EnergyDistribution:
        """Predictive distribution of the trips' energies (joint across trips).

        Parameters
        ----------
        trips, seed, timeseries
            As :meth:`predict_interval` (a pandas table or MeasuredTrips).
        level : float
            Confidence level in (0, 1) whose conformal correction sets the spread
            factor (:meth:`hybridev.learning.conformal.NormalizedConformal.spread_factor`);
            out-of-domain trips get the larger of that and their out-of-domain spread.

        Returns
        -------
        EnergyDistribution
            With ``n_trips`` in the row order of ``trips``.

        Raises
        ------
        sklearn.exceptions.NotFittedError, ValueError
            As :meth:`predict_interval` (which also warns the same).
        """
        self._require_probabilistic("predict_distribution")
        check_seed(seed)
        self._check_level(level)  # before any work
        trips, traces = unpack_trips(trips, timeseries)
        return predictive_path(self, trips, traces, kind="distribution", level=level, seed=seed)

    def predict_interval(self, trips: pd.DataFrame, level: float = 0.9, *,
                         seed: int = 0, timeseries=None) -> pd.DataFrame:
        """Predict energy and final SoC with intervals at confidence ``level``.

        Parameters
        ----------
        trips : pandas.DataFrame, MeasuredTrips or dask.dataframe.DataFrame
            Trip table (``mode`` may be missing); a
            :class:`~hybridev.data.logs.MeasuredTrips` brings its traces; a dask
            DataFrame gives a lazy dask DataFrame with the same rows
            (:mod:`hybridev.fleet.scoring`).
        level : float
            Confidence level in (0, 1), e.g. 0.9 for a 90 % interval.
        seed : int
            Seeds the choice of posterior draws.
        timeseries : LoggedTraces or pandas.DataFrame, optional
            Logged speed traces by ``trip_id`` (see :meth:`HybridModel.fit`).

        Returns
        -------
        pandas.DataFrame
            A copy of ``trips`` with the physics columns plus
            ``energy_kwh_pred``, ``energy_kwh_lo``, ``energy_kwh_hi`` (kWh),
            ``soc_final_pred``, ``soc_final_lo``, ``soc_final_hi`` (in [0, 1]),
            ``in_domain`` (bool) and ``domain_score`` (see
            :mod:`hybridev.learning.domain`), ``confidence`` (kWh, the
            predictive standard deviation, out-of-domain spread included;
            higher means less sure) and ``confidence_rel`` (``confidence``
            over the energy scale ``max(|E|, 0.05 kWh/km d)``: scale-free,
            ranks the relative error). See :mod:`hybridev.learning.ood` and
            :mod:`hybridev.learning.physical`.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            When the model is not fitted (fit it, or load a fitted one).
        ValueError
            On a bad ``level`` (or one too high for the calibration trips) or
            a model without predictive spread (the paper's point model).

        Warns
        -----
        OutOfDomainWarning
            Once, with the count, when some trips lie outside the training domain.

        Examples
        --------
        >>> from hybridev import HybridModel, make_trips, simulate
        >>> t = simulate(make_trips(60, seed=0), n_steps=100)
        >>> t["energy_kwh"] = t["energy_kwh_physics"] * 1.1
        >>> m = HybridModel(n_members=2, calibrate_physics=False, conformal_fraction=0.25,
        ...                 max_epochs=3, n_steps=100).fit(t, seed=0)
        >>> out = m.predict_interval(t.drop(columns="energy_kwh"), level=0.8)
        >>> bool((out.energy_kwh_lo <= out.energy_kwh_pred).all()
        ...      and (out.energy_kwh_pred <= out.energy_kwh_hi).all())
        True
        """
        if (backend := lazy_backend(trips)) is not None:  # dask: hybridev.fleet.scoring
            return entry_point(f"{backend}.predict_interval")(self, trips, level, seed=seed,
                                                               timeseries=timeseries)
        self._require_probabilistic("predict_interval")
        check_seed(seed)
        self._check_level(level)  # before any work
        trips, traces = unpack_trips(trips, timeseries)
        return predictive_path(self, trips, traces, kind="interval", level=level, seed=seed)

    # -- persistence ----------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Save to a directory (JSON + ``.npz``, no pickle), atomically.

        See :mod:`hybridev.learning.persist` for the layout. An unfitted model is saved
        without a network and predicts the physics (with a warning) after
        :meth:`load`. A saved model takes about 18 kB for the paper's network
        and 72 kB for 5 heteroscedastic members
        (``benchmarks/results/bench_hybrid.md``).

        Examples
        --------
        >>> import tempfile
        >>> d = tempfile.mkdtemp() + "/model"
        >>> HybridModel(n_steps=100).save(d)
        >>> HybridModel.load(d).n_steps
        100
        """
        save_model(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike) -> HybridModel:
        """Load a model saved by :meth:`save` (by the same class).

        Raises
        ------
        ValueError
            Naming the file and the problem (missing, corrupted, another
            format or major version, wrong feature names or shapes).
        """
        return load_model(cls, path)

    def _extra_state(self) -> tuple[dict, dict[str, np.ndarray]]:
        """State a subclass keeps beyond the components (saved under ``extra``)."""
        return {}, {}

    def _set_extra_state(self, doc: dict, arrays: dict[str, np.ndarray]) -> None:
        """Restore :meth:`_extra_state`."""
