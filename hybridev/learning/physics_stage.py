"""The physics stage of the hybrid model: vehicle, physics posterior and discrepancy.

:class:`PhysicsStage` is the first learned component of :class:`hybridev.HybridModel`
(see ``docs/architecture.md``). At fit it resolves the heater kind when the vehicle
leaves it to the data (:mod:`hybridev.bayes.heater`), samples the posterior over the
physics parameters with emcee (:func:`hybridev.bayes.sampler.calibrate_physics`,
thinned to :data:`KEEP_POSTERIOR_DRAWS` float32-rounded draws) and fits the
model-discrepancy stage on it (:mod:`hybridev.bayes.discrepancy`). At prediction it
turns validated trips into a physics table (the posterior-median energy, or the nominal
physics without a posterior) and ``(n_draws, n_trips)`` energies of posterior draws:
:class:`PhysicsDraws`.

For a trip, with posterior draws ``theta_d``, discrepancy term weights ``w_d`` and the
discrepancy's weight ``f`` of the trip (1 inside the training domain, fading to 0 away
from it, :meth:`~hybridev.learning.domain.TrainingDomain.discrepancy_fade`)::

    E_p(theta_d) = E(theta_d) + f (E_w(theta_d, w_d) - E(theta_d))

where ``E`` is the physics of :func:`hybridev.physics.stats.energy_from_stats` and
``E_w`` the same with the terms re-weighted.
"""

from __future__ import annotations

import copy
import dataclasses
import functools

import numpy as np
import pandas as pd

from hybridev.bayes.discrepancy import TermDiscrepancy
from hybridev.bayes.heater import HeaterSelection, select_heater_kind
from hybridev.bayes.posterior import PhysicsPosterior
from hybridev.bayes.sampler import calibrate_physics
from hybridev.learning.features import MODE_NAMES, normalize_modes, physics_modes
from hybridev.learning.inputs import validate_prediction_columns, validate_prediction_trips
from hybridev.learning.residual import residual_scale
from hybridev.learning.steps import ARRAY_COLUMNS, PhysicsDraws, table_columns
from hybridev.physics.params import VehicleParams
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.stats_build import trip_stats
from hybridev.physics.trips import _simulate_columns, with_physics_columns

__all__ = ["ARRAY_COLUMNS", "KEEP_POSTERIOR_DRAWS", "PhysicsStage", "residual_scale",
           "table_columns"]

KEEP_POSTERIOR_DRAWS = 500
"""Posterior draws a fitted model keeps (evenly spaced over the thinned chain)."""

_PHYSICS_COLUMNS = ("energy_kwh_physics", "soc_final_physics", "max_speed_kmh",
                    "kwh_per_km_physics")


def _sample_median(post: PhysicsPosterior) -> np.ndarray:
    """``np.median(post.samples, axis=0)`` (as :meth:`PhysicsPosterior.median`), computed
    once per posterior and cached on it (keyed on its samples: new samples, new median)."""
    cached = post.__dict__.get("_sample_median")
    if cached is None or cached[0] is not post.samples:
        cached = post._sample_median = (post.samples, np.median(post.samples, axis=0))
    return cached[1]


def _draw_params(post: PhysicsPosterior, disc, n_draws: int, seed: int):
    """``(params, term_weights)`` of the posterior median and ``n_draws`` draws seeded by
    ``seed`` (term weights None without a discrepancy ``disc``), read-only.

    A function of the learned state, ``n_draws`` and ``seed`` only, so the last one is
    cached on ``post`` (keyed on its samples and ``disc``, as :func:`_sample_median`):
    repeated predictions with one seed draw them once.
    """
    key = (post.samples, disc, getattr(disc, "weights", None), n_draws, seed)
    cached = post.__dict__.get("_draw_params")
    if cached is not None and all(a is b for a, b in zip(cached[0][:3], key[:3], strict=True)) \
            and cached[0][3:] == key[3:]:
        return cached[1]
    med = _sample_median(post)
    rng = np.random.default_rng(seed)
    draws = post.sample(n_draws, rng) if n_draws else np.empty((0, med.size))
    params = post.as_params(np.vstack([med, draws]))
    weights = None if disc is None else np.vstack([disc.weights, disc.sample(n_draws, rng)])
    for a in (*params.values(), *([] if weights is None else [weights])):
        a.flags.writeable = False
    post._draw_params = (key, (params, weights))
    return params, weights


class PhysicsStage:
    """Vehicle physics, with a posterior over its parameters and a discrepancy stage.

    Parameters
    ----------
    vehicle : VehicleParams
    n_steps, physics_seed : int
        Synthesised speed traces (see :func:`hybridev.simulate`).
    missing_mode : str or DrivingProfile
        Physics of trips without ``mode`` (see :class:`hybridev.HybridModel`).
    physics_params : tuple of str
        Parameters the posterior samples.
    calibrate : bool
        Sample a posterior at :meth:`fit` (else the nominal physics).
    discrepancy : bool
        Fit the term re-weighting after the posterior.
    relative : bool
        The discrepancy's residual scale is relative (:func:`residual_scale`).

    Attributes
    ----------
    heater_kind_ : str or None
        Heater kind learned at fit when the vehicle has ``heater_kind="auto"``.
    posterior_ : PhysicsPosterior or None
    discrepancy_ : TermDiscrepancy or None
    """

    def __init__(self, vehicle: VehicleParams, *, n_steps: int, physics_seed: int,
                 missing_mode, physics_params: tuple[str, ...], calibrate: bool,
                 discrepancy: bool, relative: bool) -> None:
        self.base_vehicle = vehicle
        self.n_steps = int(n_steps)
        self.physics_seed = int(physics_seed)
        self.missing_mode = missing_mode
        self.physics_params = tuple(physics_params)
        self.calibrate = bool(calibrate)
        self.discrepancy = bool(discrepancy)
        self.relative = bool(relative)
        self.heater_kind_ = None
        self.posterior_ = None
        self.discrepancy_ = None
        self._vehicle = vehicle

    # -- fit ---------------------------------------------------------------------------
    def vehicle(self) -> VehicleParams:
        """The vehicle, with the heater kind learned at fit when it was ``"auto"``."""
        return self._vehicle

    def for_vehicle(self, vehicle: VehicleParams) -> PhysicsStage:
        """This stage with another nominal vehicle (e.g. another battery capacity).

        The learned state is shared; a heater kind learned at fit replaces ``"auto"``.
        ``self`` when ``vehicle`` is this stage's own.
        """
        if vehicle is self.base_vehicle:
            return self
        other = copy.copy(self)
        other.base_vehicle = vehicle
        kind = self.heater_kind_
        other._vehicle = (vehicle if kind is None or vehicle.heater_kind != "auto"
                          else dataclasses.replace(vehicle, heater_kind=kind))
        return other

    def select_heater(self, good: pd.DataFrame, traces, codes: np.ndarray
                      ) -> HeaterSelection | None:
        """Resolve ``heater_kind="auto"`` from the trips (:mod:`hybridev.bayes.heater`)."""
        self.heater_kind_, self._vehicle = None, self.base_vehicle
        v = self.base_vehicle
        if v.heater_kind != "auto" or v.climate_model != "continuous":
            return None
        mm = "marginalize" if self.missing_mode == "infer" else self.missing_mode
        sel = select_heater_kind(
            lambda w: trip_stats(good, w, traces=traces, n_steps=self.n_steps,
                                 seed=self.physics_seed, missing_mode=mm),
            v, good["energy_kwh"].to_numpy(float), groups=codes)
        self.heater_kind_ = sel.kind
        self._vehicle = dataclasses.replace(v, heater_kind=sel.kind)
        return sel

    def fit(self, measured: pd.DataFrame, seed: int, traces=None) -> PhysicsStage:
        """Sample the posterior and fit the discrepancy on ``measured`` (when ``calibrate``)."""
        self.posterior_ = self.discrepancy_ = None
        if self.calibrate:
            self.posterior_, self.discrepancy_ = self.calibrated(measured, seed, traces)
        return self

    def calibrated(self, measured: pd.DataFrame, seed: int, traces=None, *,
                   sign_vehicle=None, n_steps: int | None = None, init_walkers=None):
        """Posterior (thinned to :data:`KEEP_POSTERIOR_DRAWS`) and discrepancy on ``measured``.

        ``sign_vehicle``, ``n_steps``, ``init_walkers``: as
        :func:`~hybridev.bayes.sampler.calibrate_physics` (a CV+ fold's warm start).
        """
        mode = self.missing_mode
        if isinstance(mode, str) and mode == "infer" and measured["mode"].notna().all():
            mode = "marginalize"  # nothing to infer from: every trip is labelled
        post = calibrate_physics(
            measured, self.vehicle(), params=self.physics_params, seed=int(seed),
            missing_mode=mode, timeseries=traces, n_steps=n_steps, sign_vehicle=sign_vehicle,
            trace_steps=self.n_steps, trace_seed=self.physics_seed, init_walkers=init_walkers)
        # Keep at most KEEP_POSTERIOR_DRAWS evenly spaced draws, rounded to float32,
        # so that the saved model stays small and loads to exactly this posterior.
        keep = np.unique(np.linspace(0, len(post.samples) - 1,
                                     min(len(post.samples), KEEP_POSTERIOR_DRAWS)).round()
                         .astype(int))
        post.samples = post.samples[keep].astype(np.float32).astype(float)
        post.noise_rel = post.noise_rel[keep].astype(np.float32).astype(float)
        if post.mode_weights is not None:
            post.mode_weights = post.mode_weights[keep].astype(np.float32).astype(float)
        return post, self._fit_discrepancy(post, measured, traces)

    def _fit_discrepancy(self, post: PhysicsPosterior, measured: pd.DataFrame,
                         traces=None) -> TermDiscrepancy | None:
        if not self.discrepancy:
            return None
        stats = post.stats_for(measured, traces)
        med = post.as_params(np.median(post.samples, axis=0)[None, :])  # (1, 1) arrays
        e_p = energy_from_stats(stats, med)[0]
        scale = residual_scale(e_p, measured["distance_km"].to_numpy(float), self.relative)
        return TermDiscrepancy.fit(stats, med, measured["energy_kwh"].to_numpy(float),
                                   np.maximum(scale, 1e-9), noise_dof=post.noise_dof)

    # -- transform ---------------------------------------------------------------------
    def stats(self, valid: pd.DataFrame, traces=None, columns=None):
        """Physics statistics of validated trips as the posterior builds them (CV+ folds
        share them); ``columns``: their columns as the validation read them."""
        return self.posterior_.stats_for(valid, traces, columns=columns)

    def _energies(self, stats, n_draws: int, seed: int, physics=None):
        """Energies ``(1 + n_draws, n_trips)`` with the discrepancy at full weight, and a
        callable giving them without it (None without a discrepancy)."""
        post, disc = physics or (self.posterior_, self.discrepancy_)
        params, weights = _draw_params(post, disc, int(n_draws), int(seed))
        if disc is None:
            return energy_from_stats(stats, params), None
        return (energy_from_stats(stats, params, term_weights=weights),
                functools.partial(energy_from_stats, stats, params))

    def energies(self, stats, n_draws: int, seed: int, physics=None, *, fade=None
                 ) -> np.ndarray:
        """Energies ``(1 + n_draws, n_trips)``: posterior median, then draws, kWh.

        ``physics``: a ``(posterior, discrepancy)`` pair (default: this stage's);
        ``fade`` (n_trips,) blends each trip from the calibrated physics (0) to the
        re-weighted one (1); None: 1 for every trip.
        """
        energy, plain = self._energies(stats, n_draws, seed, physics)
        if fade is not None and plain is not None:
            p = plain()
            energy = p + fade * (energy - p)
        return energy

    def transform(self, trips: pd.DataFrame, traces=None, *, n_draws: int = 0, seed: int = 0,
                  physics=(None,), modes: bool = False) -> PhysicsDraws:
        """Step 1 of the predictive path: the physics of ``trips`` (validated here).

        ``physics``: the ``(posterior, discrepancy)`` pairs to draw from (``None``: this
        stage's), e.g. the model's and the CV+ folds'; the statistics are built once.
        Without a posterior the nominal physics (:meth:`columns`). ``modes``: also the
        physics of the trips without a ``mode`` under each mode. The discrepancy's
        per-trip weight comes later (:meth:`PhysicsDraws.faded`).
        """
        if not isinstance(trips, pd.DataFrame):
            raise ValueError(f"trips must be a pandas DataFrame; got {type(trips).__name__}")
        if self.posterior_ is not None:
            valid, cols = validate_prediction_columns(trips)
            stats = self.stats(valid, traces, cols)
            pairs = [self._energies(stats, n_draws, seed, p) for p in physics]
            vmax = stats.max_speed_kmh
            if stats.marginalised:
                starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
                vmax = np.maximum.reduceat(vmax, starts)
            out = PhysicsDraws(table=valid, columns=cols,
                               energies=[e for e, _ in pairs],
                               plain=[p for _, p in pairs], n_draws=int(n_draws),
                               max_speed_kmh=vmax,
                               capacity_kwh=self.vehicle().battery_capacity_kwh)
        else:
            table, cols, append = self.columns(trips, traces)
            out = PhysicsDraws(table=table, columns=cols, append=append,
                               energies=[None] * len(physics), plain=[None] * len(physics))
        if modes:
            no_mode = pd.isna(out.columns["mode"] if "mode" in out.columns
                              else out.table["mode"].to_numpy(object))
            if no_mode.any():
                sub = out.table.loc[no_mode, [c for c in out.table.columns
                                              if c not in _PHYSICS_COLUMNS]]
                out.modes = {m: self.transform(sub.assign(mode=m), traces)
                             for m in MODE_NAMES}
        return out

    def posterior_table(self, valid: pd.DataFrame, n_draws: int, seed: int, traces=None, *,
                        physics=None, stats=None, fade=None
                        ) -> tuple[pd.DataFrame, np.ndarray]:
        """Simulate-like table at the posterior median and (n_draws, n_trips) energies.

        ``valid``: validated trips; ``stats`` from :meth:`stats` (built when None).
        """
        stats = self.stats(valid, traces) if stats is None else stats
        energy = self.energies(stats, n_draws, seed, physics, fade=fade)
        e_med = energy[0]
        e_draws = energy[1:] if n_draws else energy[:1]
        vmax = stats.max_speed_kmh
        if stats.marginalised:
            starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
            vmax = np.maximum.reduceat(vmax, starts)
        out = with_physics_columns(valid, e_med, vmax, self.vehicle().battery_capacity_kwh)
        return out, e_draws

    def columns(self, trips: pd.DataFrame, traces=None, *, valid=None, fade=None
                ) -> tuple[pd.DataFrame, dict[str, np.ndarray], dict[str, np.ndarray]]:
        """The physics of ``trips`` as ``(table, columns, physics)``.

        ``table`` is the validated trips (``mode`` normalised, ``None`` where unknown),
        with the physics columns unless ``physics`` holds them still to append;
        ``columns`` the :data:`ARRAY_COLUMNS` and ``mode`` as arrays, each looked up
        once (column access is slow on small tables). With a posterior the physics is
        its median (``valid``: the trips already validated; ``fade`` as
        :meth:`energies`); with ``traces``, trips with a logged trace use it; else
        unknown modes are simulated as ``"normal"`` (or ``missing_mode`` when it is a
        profile or a mode name).
        """
        if not isinstance(trips, pd.DataFrame):
            raise ValueError(f"trips must be a pandas DataFrame; got {type(trips).__name__}")
        if self.posterior_ is not None:
            valid = validate_prediction_trips(trips) if valid is None else valid
            out = self.posterior_table(valid, 0, 0, traces, fade=fade)[0]
            return out, table_columns(out), {}
        if traces is not None:
            t = validate_prediction_trips(trips) if valid is None else valid
            mm = self.missing_mode if self.missing_mode not in ("infer", "marginalize") \
                else "normal"
            st = trip_stats(t, self.vehicle(), traces=traces, n_steps=self.n_steps,
                            seed=self.physics_seed, missing_mode=mm)
            out = with_physics_columns(t, energy_from_stats(st), st.max_speed_kmh,
                                       self.vehicle().battery_capacity_kwh)
            return out, table_columns(out), {}
        modes = normalize_modes(trips.get("mode"), len(trips))
        t, cols, physics = _simulate_columns(trips.assign(mode=physics_modes(modes)),
                                             self.vehicle(), n_steps=self.n_steps,
                                             seed=self.physics_seed)
        if pd.isna(modes).any():  # else the physics modes are these: same values and dtype
            t["mode"] = modes  # simulate raises on any bad row, so rows are unchanged
        cols["mode"] = modes
        return t, {**cols, **physics}, physics

    def table(self, trips: pd.DataFrame, traces=None) -> pd.DataFrame:
        """Validated trips with the physics columns (the posterior median, discrepancy at
        full weight): the physics the networks are trained against."""
        draws = self.transform(trips, traces).faded(None)
        return draws.tables[0]

    # -- persistence -------------------------------------------------------------------
    def to_arrays(self) -> tuple[dict, dict[str, np.ndarray]]:
        """``(json_doc, arrays)`` of the posterior and discrepancy (empty without them)."""
        doc, arrays = {}, {}
        post = self.posterior_
        if post is not None:
            d = post.to_dict()
            doc["posterior"] = {"param_names": d["param_names"], "meta": d["meta"]}
            arrays["posterior_samples"] = d["samples"].astype(np.float32)
            arrays["posterior_noise_rel"] = d["noise_rel"].astype(np.float32)
            if d["mode_weights"] is not None:
                arrays["posterior_mode_weights"] = d["mode_weights"].astype(np.float32)
        if self.discrepancy_ is not None:
            arrays.update({f"discrepancy.{k}": v
                           for k, v in self.discrepancy_.to_arrays().items()})
        return doc, arrays

    def set_arrays(self, doc: dict, arrays: dict[str, np.ndarray]) -> PhysicsStage:
        """Inverse of :meth:`to_arrays`."""
        if "posterior" in doc:
            p = doc["posterior"]
            self.posterior_ = PhysicsPosterior.from_dict({
                "param_names": p["param_names"], "meta": p["meta"],
                "samples": arrays["posterior_samples"],
                "noise_rel": arrays["posterior_noise_rel"],
                "mode_weights": arrays.get("posterior_mode_weights")})
        disc = {k[len("discrepancy."):]: v for k, v in arrays.items()
                if k.startswith("discrepancy.")}
        if disc:
            self.discrepancy_ = TermDiscrepancy.from_arrays(disc)
        return self
