"""The posterior of the physics parameters: draws, diagnostics, summaries, serialisation.

Produced by :func:`hybridev.bayes.sampler.calibrate_physics`; kept in its own module
so that models can carry it (``to_dict``/``from_dict``: plain arrays plus
JSON-able metadata, no pickle).
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pandas as pd

from hybridev.core.errors import ConvergenceWarning
from hybridev.data.parked import with_parked_minutes
from hybridev.physics.params import PROFILES, DrivingProfile, VehicleParams
from hybridev.physics.stats import STAT_PARAMS, PhysicsStats, row_energy
from hybridev.physics.stats_build import trip_stats

__all__ = ["MIN_CHAIN_TAU", "PhysicsPosterior", "burn_and_thin", "vehicle_with"]

MIN_CHAIN_TAU = 50.0
"""Chains shorter than this many autocorrelation times (after burn-in) warn."""


def vehicle_with(vehicle: VehicleParams, values) -> VehicleParams:
    """``vehicle`` with any of :data:`~hybridev.physics.stats.STAT_PARAMS` replaced.

    ``drag_area_m2`` is applied through ``drag_coefficient`` (frontal area
    kept), ``hvac_scale`` multiplies ``hvac_kw`` (paper preset) and the
    cabin's ``UA`` and solar gain (continuous model; the same as scaling the
    climate power wherever the heater is below its cap), ``warmup_scale`` the
    cabin heat capacity and battery warm-up; ``regen_scale`` is not a vehicle
    property and is ignored.

    Examples
    --------
    >>> v = vehicle_with(VehicleParams(), {"drag_area_m2": 0.6, "regen_scale": 0.9})
    >>> round(v.drag_area_m2, 6)
    0.6
    """
    kw = {}
    for name, x in dict(values).items():
        if name not in STAT_PARAMS:
            raise ValueError(f"unknown parameter {name!r}; allowed: {list(STAT_PARAMS)}")
        if name == "drag_area_m2":
            kw["drag_coefficient"] = float(x) / vehicle.frontal_area_m2
        elif name == "hvac_scale":
            kw["hvac_kw"] = tuple(float(x) * h for h in vehicle.hvac_kw)
            kw["cabin_ua_w_per_k"] = float(x) * vehicle.cabin_ua_w_per_k
            kw["solar_gain_w"] = float(x) * vehicle.solar_gain_w
        elif name == "heating_scale":
            if vehicle.climate_model == "continuous":
                kw["heating_use"] = float(x) * vehicle.heating_use
            else:  # the paper's bands are all "heating" in the statistics
                kw["hvac_kw"] = tuple(float(x) * h for h in kw.get("hvac_kw", vehicle.hvac_kw))
        elif name == "cooling_scale":
            kw["cooling_use"] = float(x) * vehicle.cooling_use
        elif name == "warmup_scale":
            kw["cabin_heat_capacity_kj_per_k"] = float(x) * vehicle.cabin_heat_capacity_kj_per_k
            kw["battery_warmup_kwh_per_k"] = float(x) * vehicle.battery_warmup_kwh_per_k
        elif name != "regen_scale":
            kw[name] = float(x)
    return dataclasses.replace(vehicle, **kw)


def _vehicle_to_dict(v: VehicleParams) -> dict:
    d = dataclasses.asdict(v)
    d["hvac_kw"] = list(d["hvac_kw"])
    return d


def _vehicle_from_dict(d: dict) -> VehicleParams:
    return VehicleParams(**{**d, "hvac_kw": tuple(d["hvac_kw"])})


def burn_and_thin(tau, n_steps: int) -> tuple[float, int, int]:
    """``(tau_max, burn, thin)`` of an emcee run from its autocorrelation times.

    Burn-in ``min(ceil(3 tau_max), n_steps // 2)``, thinning ``max(1, tau_min / 2)``.
    A coordinate whose autocorrelation time emcee cannot estimate (NaN: met in a
    short warm-started CV+ fold run on 20 real trips) is left out instead of stopping
    the fit. With none finite the run counts as unconverged: ``tau_max = n_steps``
    (burn half, no thinning; the short-chain warning follows).

    Parameters
    ----------
    tau : array_like, shape (n_dim,)
        ``sampler.get_autocorr_time(tol=0)``, steps.
    n_steps : int
        Steps of the run.
    """
    tau = np.asarray(tau, dtype=float)
    finite = tau[np.isfinite(tau)]
    if not finite.size:
        return float(max(n_steps, 1)), n_steps // 2, 1
    tau_max = float(np.max(finite))
    return (tau_max, min(math.ceil(3.0 * tau_max), n_steps // 2),
            max(1, int(0.5 * float(np.min(finite)))))

class PhysicsPosterior:
    """Posterior draws of physics parameters and the relative noise.

    Parameters
    ----------
    param_names : sequence of str
        Sampled parameters (subset of ``STAT_PARAMS``).
    samples : array_like, shape (n_samples, n_params)
        Natural units (m^2, -, N/(m/s), -, kW, -).
    noise_rel : array_like, shape (n_samples,)
        Relative noise sd ``sigma_rel`` of each draw. When the calibration
        had groups it is the total ``sqrt(sigma^2 + tau^2)`` (a trip on a new
        day); the day/session effect's ``tau`` is in ``diagnostics["group_sd"]``.
    vehicle : VehicleParams
        Nominal vehicle (prior centre; values of parameters not sampled).
    reference_vehicle : VehicleParams, optional
        Vehicle whose sign split the statistics used (the MAP); default ``vehicle``.
    prior : dict, optional
        The :class:`~hybridev.bayes.sampler.PhysicsPrior` as a dict (metadata).
    diagnostics : dict, optional
        Chain diagnostics (see :meth:`hybridev.bayes.sampler.calibrate_physics`).
    missing_mode, trace_steps, trace_seed
        How trip statistics were built; :meth:`stats_for` repeats it.
    mode_weights : array_like, shape (n_samples, 3), optional
        Mixture weights of (eco, normal, aggressive) for unlabelled trips,
        when they were sampled (``missing_mode="infer"``).

    Examples
    --------
    >>> post = PhysicsPosterior(["aux_base_kw"], [[0.4], [0.6]], [0.05, 0.05],
    ...                         vehicle=VehicleParams())
    >>> post.median()["aux_base_kw"], post.median_vehicle().aux_base_kw
    (0.5, 0.5)
    """

    def __init__(self, param_names, samples, noise_rel, *, vehicle: VehicleParams,
                 reference_vehicle: VehicleParams | None = None, prior: dict | None = None,
                 diagnostics: dict | None = None, missing_mode="marginalize",
                 trace_steps: int = 1000, trace_seed: int = 0, mode_weights=None):
        self.param_names = tuple(param_names)
        for n in self.param_names:
            if n not in STAT_PARAMS:
                raise ValueError(f"unknown parameter {n!r}; allowed: {list(STAT_PARAMS)}")
        self.samples = np.asarray(samples, dtype=float).reshape(-1, len(self.param_names))
        self.noise_rel = np.asarray(noise_rel, dtype=float).reshape(-1)
        if len(self.noise_rel) != len(self.samples) or len(self.samples) == 0:
            raise ValueError(f"samples ({len(self.samples)} rows) and noise_rel "
                             f"({len(self.noise_rel)}) must be non-empty and of equal length")
        self.vehicle = vehicle
        self.reference_vehicle = reference_vehicle or vehicle
        self.prior = dict(prior or {})
        self.diagnostics = dict(diagnostics or {})
        self.missing_mode = missing_mode
        self.trace_steps = int(trace_steps)
        self.trace_seed = int(trace_seed)
        self.mode_weights = None
        if mode_weights is not None:
            self.mode_weights = np.asarray(mode_weights, dtype=float).reshape(-1, len(PROFILES))
            if len(self.mode_weights) != len(self.samples):
                raise ValueError("mode_weights must have one row per sample")

    @property
    def outliers_(self) -> pd.DataFrame:
        """Trips the calibration treated as outliers, with the reason.

        Columns :data:`hybridev.bayes.outliers.OUTLIER_COLUMNS` (``trip_id``,
        ``energy_kwh`` measured, ``predicted_kwh`` at the posterior median,
        ``residual_rel``, standardized residual ``z``, the trip's ``weight``
        in the Student-t fit, ``tail_prob``, ``outlier``, ``reason``); empty
        when none (or for a posterior made before outliers were reported).
        """
        from hybridev.bayes.outliers import OUTLIER_COLUMNS

        return pd.DataFrame(self.diagnostics.get("outliers", []), columns=OUTLIER_COLUMNS)

    @property
    def noise_dof(self) -> float | None:
        """Student-t degrees of freedom of the likelihood (``None``: normal)."""
        return self.prior.get("noise_dof")

    @staticmethod
    def nominal_values(vehicle: VehicleParams) -> dict[str, float]:
        """Values of every ``STAT_PARAMS`` entry for ``vehicle`` (regen scale 1)."""
        return {"drag_area_m2": vehicle.drag_area_m2,
                "rolling_resistance_coef": vehicle.rolling_resistance_coef,
                "linear_drag_n_per_mps": vehicle.linear_drag_n_per_mps,
                "drivetrain_efficiency": vehicle.drivetrain_efficiency,
                "aux_base_kw": vehicle.aux_base_kw, "regen_scale": 1.0, "hvac_scale": 1.0,
                "warmup_scale": 1.0, "heating_scale": 1.0, "cooling_scale": 1.0,
                "drive_loss_kw": vehicle.drive_loss_kw,
                "heating_offset_k": vehicle.heating_offset_k}

    @classmethod
    def from_sampler(cls, sampler, names, *, vehicle, reference_vehicle, prior, map_theta,
                     missing_mode, trace_steps, trace_seed, elapsed_s,
                     n_group: int = 0, noise_dof: float | None = None,
                     min_burn: int = 0) -> PhysicsPosterior:
        """Burn-in (3 tau), thinning (tau/2) and diagnostics of an emcee run; warns if short.

        ``min_burn``: discard at least this many steps (at most half the run), e.g. a
        warm-started run whose own autocorrelation estimate is too short to trust
        (:func:`hybridev.bayes.sampler.calibrate_physics` with ``init_walkers``).

        With a Student-t likelihood (``noise_dof``) the noise and day-effect
        scales are reported as standard deviations (``x sqrt(nu / (nu - 2))``).
        """
        n_steps = int(sampler.iteration)
        tau = np.asarray(sampler.get_autocorr_time(tol=0), dtype=float)
        tau_max, burn, thin = burn_and_thin(tau, n_steps)
        burn = max(burn, min(int(min_burn), n_steps // 2))
        chain = sampler.get_chain(discard=burn, thin=thin, flat=True)
        acc = np.asarray(sampler.acceptance_fraction, dtype=float)
        length_tau = (n_steps - burn) / tau_max
        n = len(names)
        n_alr = chain.shape[1] - n - 1 - n_group
        labels = [*names, *[f"logit_{m}" for m in list(PROFILES)[1:1 + n_alr]],
                  *(["group_sd"] if n_group else []), "noise_rel"]
        weights = None
        if n_alr:
            logits = np.column_stack([np.zeros(len(chain)), chain[:, n:n + n_alr]])
            weights = np.exp(logits - logits.max(axis=1, keepdims=True))
            weights /= weights.sum(axis=1, keepdims=True)
        diag = {
            "n_walkers": int(sampler.nwalkers), "n_steps": n_steps, "burn_in": burn,
            "thin": thin, "n_samples": len(chain),
            "tau": {n: float(t) if math.isfinite(t) else None  # JSON: no NaN
                    for n, t in zip(labels, tau, strict=True)},
            "tau_max": tau_max, "chain_length_tau": float(length_tau),
            "acceptance_mean": float(acc.mean()), "acceptance_min": float(acc.min()),
            "converged": bool(length_tau >= MIN_CHAIN_TAU), "elapsed_s": float(elapsed_s),
            "map": {k: float(x) for k, x in zip(labels[:-1], map_theta[:-1], strict=True)}
            | {"noise_rel": float(np.exp(map_theta[-1]))},
        }
        if length_tau < MIN_CHAIN_TAU:
            warnings.warn(f"MCMC chain is {length_tau:.1f} autocorrelation times long after "
                          f"burn-in (tau_max={tau_max:.1f} steps, {n_steps} steps); at least "
                          f"{MIN_CHAIN_TAU:g} are needed for reliable estimates: run more steps",
                          ConvergenceWarning, stacklevel=3)
        sd_factor = 1.0 if noise_dof is None else float(np.sqrt(noise_dof / (noise_dof - 2.0)))
        sigma = np.exp(chain[:, -1]) * sd_factor
        group_sd = np.abs(chain[:, -2]) * sd_factor if n_group else None
        if n_group:  # a trip on a new day: within-day noise plus a new day effect
            diag["sigma_within"] = float(np.median(sigma))
            diag["group_sd"] = float(np.median(group_sd))
            diag["group_sd_q05_q95"] = [float(x) for x in np.quantile(group_sd, [0.05, 0.95])]
            sigma = np.sqrt(sigma**2 + group_sd**2)
        return cls(names, chain[:, :n], sigma, vehicle=vehicle,
                   reference_vehicle=reference_vehicle, prior=dataclasses.asdict(prior),
                   diagnostics=diag, missing_mode=missing_mode, trace_steps=trace_steps,
                   trace_seed=trace_seed, mode_weights=weights)

    # ----------------------------------------------------------------- summaries
    def median(self) -> dict[str, float]:
        """Posterior median of each sampled parameter and of ``noise_rel``."""
        med = np.median(self.samples, axis=0)
        out = {n: float(x) for n, x in zip(self.param_names, med, strict=True)}
        out["noise_rel"] = float(np.median(self.noise_rel))
        return out

    def median_vehicle(self) -> VehicleParams:
        """Nominal vehicle with the posterior medians applied (``regen_scale`` aside)."""
        med = self.median()
        med.pop("noise_rel")
        return vehicle_with(self.vehicle, med)

    def summary(self, level: float = 0.9) -> pd.DataFrame:
        """Per parameter: nominal, median, mean, sd and the central ``level`` interval.

        Returns
        -------
        pandas.DataFrame
            Index: parameters and ``noise_rel``; columns ``nominal``,
            ``median``, ``mean``, ``sd``, ``q05``, ``q95`` (named for the
            default ``level=0.9``: they are the ``(1-level)/2`` and
            ``(1+level)/2`` quantiles) and ``tau`` (steps, when known).
        """
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        x = np.column_stack([self.samples, self.noise_rel])
        nom = self.nominal_values(self.vehicle)
        names = [*self.param_names, "noise_rel"]

        if self.mode_weights is not None:
            x = np.column_stack([x, self.mode_weights])
            names += [f"weight_{m}" for m in PROFILES]
            nom = nom | {f"weight_{m}": 1.0 / len(PROFILES) for m in PROFILES}
        q = np.quantile(x, [(1 - level) / 2, 0.5, (1 + level) / 2], axis=0)
        tau = self.diagnostics.get("tau", {})
        return pd.DataFrame({
            "nominal": [nom.get(n, np.nan) for n in names], "median": q[1],
            "mean": x.mean(axis=0), "sd": x.std(axis=0, ddof=1) if len(x) > 1 else np.nan,
            "q05": q[0], "q95": q[2], "tau": [tau.get(n, np.nan) for n in names],
        }, index=pd.Index(names, name="parameter"))

    def prior_check(self, level: float = 0.99) -> pd.DataFrame:
        """Posterior medians against the central ``level`` range of their priors.

        See :func:`hybridev.bayes.checks.prior_check`.

        Examples
        --------
        >>> post = PhysicsPosterior(["aux_base_kw"], [[0.4], [0.6]], [0.05, 0.05],
        ...                         vehicle=VehicleParams())
        >>> bool(post.prior_check().loc["aux_base_kw", "inside"])
        True
        """
        from hybridev.bayes.checks import prior_check

        return prior_check(self, level)

    def correlations(self) -> pd.DataFrame:
        """Posterior correlation matrix of the sampled parameters.

        Strong correlations (``|r| > 0.7``) mean the data fix only a
        combination of the parameters (e.g. efficiency and regeneration).
        """
        x = self.samples
        c = np.corrcoef(x.T) if x.shape[1] > 1 else np.ones((1, 1))
        return pd.DataFrame(np.atleast_2d(c), index=list(self.param_names),
                            columns=list(self.param_names))

    # ------------------------------------------------------------------- draws
    def sample(self, n: int, rng: np.random.Generator | int | None = None, *,
               with_noise: bool = False):
        """``n`` draws resampled from the chain, shape (n, n_params) (+ noise (n,))."""
        rng = np.random.default_rng(rng)
        idx = rng.integers(0, len(self.samples), int(n))
        return (self.samples[idx], self.noise_rel[idx]) if with_noise else self.samples[idx]

    def as_params(self, draws) -> dict[str, np.ndarray]:
        """Draws ``(n, n_params)`` as a mapping of every ``STAT_PARAMS`` entry to ``(n, 1)``.

        Parameters not sampled take their nominal value; feed the result to
        :func:`hybridev.physics.stats.energy_from_stats` for ``(n, n_trips)`` energies.
        """
        d = np.asarray(draws, dtype=float).reshape(-1, len(self.param_names))
        out = {k: np.full((len(d), 1), v) for k, v in self.nominal_values(self.vehicle).items()}
        out.update({n: d[:, i:i + 1] for i, n in enumerate(self.param_names)})
        return out

    def _infer(self) -> bool:
        return isinstance(self.missing_mode, str) and self.missing_mode == "infer"

    def stats_for(self, trips: pd.DataFrame, traces=None, *, columns=None) -> PhysicsStats:
        """Trip statistics built exactly as during calibration (sign split at the MAP).

        With inferred mode weights, unlabelled trips' rows carry the posterior
        mean weights (so :func:`~hybridev.physics.stats.energy_from_stats`
        returns the posterior-weighted mixture mean). A table with a
        ``start_time`` column and no ``parked_min`` gets the minutes parked
        before each trip derived from its own rows
        (:func:`hybridev.data.parked.with_parked_minutes`), as
        :func:`~hybridev.bayes.sampler.calibrate_physics` does. ``columns``: the
        trips' columns already read as arrays (see
        :func:`~hybridev.physics.stats_build.trip_stats`).
        """
        trips = with_parked_minutes(trips, traces)
        mm = "marginalize" if self._infer() else self.missing_mode
        st = trip_stats(trips, self.reference_vehicle, traces=traces, n_steps=self.trace_steps,
                        seed=self.trace_seed, missing_mode=mm, columns=columns)
        if self.mode_weights is None or not st.marginalised:
            return st
        counts = np.bincount(st.trip, minlength=st.n_trips)
        unknown = counts[st.trip] > 1
        k = np.arange(st.n_rows) - np.r_[0, np.cumsum(counts)[:-1]][st.trip]
        log_w = np.where(unknown, np.log(self.mode_weights.mean(axis=0))[k % len(PROFILES)],
                         st.log_weight)
        return dataclasses.replace(st, log_weight=log_w)

    def predictive(self, stats: PhysicsStats, n_draws: int = 2000, seed: int = 0, *,
                   noise: bool = True) -> np.ndarray:
        """Posterior predictive trip energies, shape (n_draws, n_trips), kWh.

        Each draw takes parameters from the chain, picks a mode for
        marginalised trips with its weight, and (``noise=True``) multiplies by
        ``1 + sigma_rel z``.
        """
        rng = np.random.default_rng(seed)
        idx = rng.integers(0, len(self.samples), int(n_draws))
        draws, sig = self.samples[idx], self.noise_rel[idx]
        e = row_energy(stats, self.as_params(draws))
        if stats.marginalised and self.mode_weights is not None:
            # per-draw weights for unlabelled trips (rows in PROFILES order)
            starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
            unknown = np.diff(np.r_[starts, stats.n_rows]) > 1
            cw = np.cumsum(self.mode_weights[idx], axis=1)[:, None, :]
            k = (rng.random((len(e), stats.n_trips, 1)) >= cw[..., :-1]).sum(axis=2)
            e = np.take_along_axis(e, starts + np.where(unknown, k, 0), axis=1)
        elif stats.marginalised:
            starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
            cw = np.cumsum(np.exp(stats.log_weight))
            base = np.r_[0.0, cw][starts]
            tot = np.add.reduceat(np.exp(stats.log_weight), starts)
            ends = np.r_[starts[1:], stats.n_rows] - 1
            u = base + rng.random((len(e), stats.n_trips)) * tot
            pick = np.clip(np.searchsorted(cw, u, side="right"), starts, ends)
            e = np.take_along_axis(e, pick, axis=1)
        if noise:
            dof = self.noise_dof
            z = (rng.standard_normal(e.shape) if dof is None  # unit-variance t otherwise
                 else rng.standard_t(dof, e.shape) * np.sqrt((dof - 2.0) / dof))
            e = e * (1.0 + sig[:, None] * z)
        return e

    def predict_interval(self, stats: PhysicsStats, level: float = 0.9, *, n_draws: int = 4000,
                         seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Posterior predictive median and central ``level`` interval, each (n_trips,) kWh."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        e = self.predictive(stats, n_draws, seed)
        lo, med, hi = np.quantile(e, [(1 - level) / 2, 0.5, (1 + level) / 2], axis=0)
        return med, lo, hi

    # ---------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        """``{"param_names", "samples", "noise_rel"}`` arrays plus JSON-able ``"meta"``."""
        mm = self.missing_mode
        if isinstance(mm, DrivingProfile):
            mm = {"profile": {**dataclasses.asdict(mm),
                              "phase_fractions": list(mm.phase_fractions)}}
        return {
            "param_names": list(self.param_names), "samples": self.samples.copy(),
            "noise_rel": self.noise_rel.copy(),
            "mode_weights": None if self.mode_weights is None else self.mode_weights.copy(),
            "meta": {"vehicle": _vehicle_to_dict(self.vehicle),
                     "reference_vehicle": _vehicle_to_dict(self.reference_vehicle),
                     "prior": {k: list(v) if isinstance(v, tuple) else v
                               for k, v in self.prior.items()},
                     "diagnostics": self.diagnostics, "missing_mode": mm,
                     "trace_steps": self.trace_steps, "trace_seed": self.trace_seed},
        }

    @classmethod
    def from_dict(cls, d: dict) -> PhysicsPosterior:
        """Inverse of :meth:`to_dict` (arrays may be lists)."""
        meta = d["meta"]
        mm = meta.get("missing_mode", "marginalize")
        if isinstance(mm, dict):
            p = mm["profile"]
            mm = DrivingProfile(**{**p, "phase_fractions": tuple(p["phase_fractions"])})
        return cls(d["param_names"], d["samples"], d["noise_rel"],
                   vehicle=_vehicle_from_dict(meta["vehicle"]),
                   reference_vehicle=_vehicle_from_dict(meta["reference_vehicle"]),
                   prior=meta.get("prior"), diagnostics=meta.get("diagnostics"),
                   missing_mode=mm, trace_steps=meta.get("trace_steps", 1000),
                   trace_seed=meta.get("trace_seed", 0), mode_weights=d.get("mode_weights"))

    def __repr__(self) -> str:
        d = self.diagnostics
        extra = (f", tau_max={d['tau_max']:.1f}, length={d['chain_length_tau']:.0f} tau"
                 if "tau_max" in d else "")
        return (f"PhysicsPosterior(params={list(self.param_names)}, "
                f"n_samples={len(self.samples)}{extra})")
