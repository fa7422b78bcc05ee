"""Predictive distributions and intervals of the hybrid model (the probabilistic layer).

The user's design, beyond the paper: an emcee posterior over the physics
parameters (:func:`hybridev.bayes.sampler.calibrate_physics`) combined with a deep
ensemble of residual networks with mean and variance heads
(:mod:`hybridev.learning.nn`), made to cover by a conformal step
(:mod:`hybridev.learning.conformal`: CV+ on small fleets, split conformal on
large ones, optionally per bin, :mod:`hybridev.learning.mondrian`).

For a trip with features ``x``, posterior draws ``theta_d`` (d = 1..D) and
members ``m`` (m = 1..M):

``E = E_p(theta_d) - mean_d E_p(theta_d) + E_p(theta_hat) + dE_m(x) + sigma_m(x) z``,

where ``theta_hat`` is the posterior median (the physics the network was
trained against). :class:`hybridev.learning.predictive.EnergyDistribution` holds the
pieces; its mean is the point prediction ``energy_kwh_pred``.

Intervals (:meth:`ProbabilisticMixin.predict_interval`) are normalised
conformal intervals of energy: split conformal ``mu +- q_level * s``, with
``mu`` and ``s`` the mean and standard deviation of that distribution and
``q_level`` from calibration trips held out of every other fitting step, or
CV+ (:meth:`~hybridev.learning.conformal.CVPlusConformal.cv_interval`) from the
fold ensembles' means and spreads and the out-of-fold scores (widened to hold
``mu``). Trips outside the training domain get the wider out-of-domain
interval ``mu +- z s_ood`` (:mod:`hybridev.learning.ood`). Final SoC
``s0 - E / C`` (clipped to [0, 1]) is monotone in energy, so the SoC interval is the image
of the energy interval, except for trips that may empty the battery (energy
upper bound at or above ``s0 C``): their SoC has a point mass at 0, a central
interval would over-cover, and the interval is the one-sided
``[0, s0 - E_lo' / C]`` with the one-sided conformal lower energy bound
``E_lo'`` at the same level.

Energy bounds are floored like the point prediction (at ``min(E_p, 0)``, see
:mod:`hybridev.learning.model`, and at the physical floor of
:mod:`hybridev.learning.physical`), the one-sided bound is capped at the point prediction
(so every interval contains it), and SoC is clipped to [0, 1]
(:func:`hybridev.learning.predictive.soc_from_energy`). An unfitted model raises
:class:`sklearn.exceptions.NotFittedError` (only ``predict`` falls back to the
physics); the paper's point model (one MSE network, no posterior) has no
spread and raises a ``ValueError`` saying how to get one; a ``level`` above
``n_cal / (n_cal + 1)`` cannot be calibrated with ``n_cal`` calibration trips
and raises too.

Trips without a ``mode`` get the posterior-weighted (``missing_mode="infer"``)
or equal-weight mixture mean of the three profiles' physics. When the model
was trained on unlabelled trips too, the spread between the profiles is
carried by the members' noise heads and the conformal step; when every
training trip had a mode, such trips are out of the domain and the spread
between the three modes' predictions is added (:mod:`hybridev.learning.ood`).

``confidence`` is the predictive standard deviation ``s`` of the trip energy
in kWh (aleatoric noise of the members, their disagreement, and the physics
posterior spread; ``s_ood`` out of the domain): higher means less sure.
``confidence_rel`` divides it by the energy scale ``max(|E|, 0.05 kWh/km d)``:
scale-free, it ranks the relative error rather than the trip size, and rises
as trips leave the training domain. The conformal factor multiplies all trips
alike, so it does not change the ranking and is not applied.

Module size (about 440 lines, over the package's 400-line guide): the
probabilistic methods of the model; the conformal steps, the CV+ folds, the
domain and the out-of-domain spread already live in their own modules
(:mod:`~hybridev.learning.conformal`, :mod:`~hybridev.learning.cvplus`,
:mod:`~hybridev.learning.domain`, :mod:`~hybridev.learning.ood`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy.special import ndtri
from sklearn.exceptions import NotFittedError

from hybridev.bayes.discrepancy import TermDiscrepancy
from hybridev.bayes.posterior import PhysicsPosterior
from hybridev.bayes.sampler import calibrate_physics
from hybridev.core.checks import check_seed
from hybridev.core.plugins import entry_point, lazy_backend
from hybridev.learning.conformal import (
    CVPlusConformal,
    NormalizedConformal,
    min_calibration_trips,
)
from hybridev.learning.cvplus import (
    nets_from_arrays,
    nets_to_arrays,
    physics_from_arrays,
    physics_to_arrays,
)
from hybridev.learning.domain import TrainingDomain
from hybridev.learning.inputs import unpack_trips
from hybridev.learning.mondrian import mondrian_bins, mondrian_interval
from hybridev.learning.ood import OutOfDomainMixin
from hybridev.learning.physical import energy_floor_kwh, held_feature_table
from hybridev.learning.planned import (
    interval_bounds,
    planned_arrays,
    planned_distribution,
    set_planned_state,
    spread_factors,
)
from hybridev.learning.predictive import EnergyDistribution, soc_from_energy
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.trips import with_physics_columns

__all__ = ["KEEP_POSTERIOR_DRAWS", "ProbabilisticMixin"]

KEEP_POSTERIOR_DRAWS = 500
"""Posterior draws a fitted model keeps (evenly spaced over the thinned chain)."""


def _check_level(level) -> None:
    ok = (isinstance(level, int | float | np.integer | np.floating)
          and not isinstance(level, bool) and 0.0 < float(level) < 1.0)
    if not ok:
        raise ValueError(f"level={level!r} is outside the allowed range (0, 1) "
                         "(a confidence level, e.g. 0.9)")


class ProbabilisticMixin(OutOfDomainMixin):
    """Physics posterior, predictive distributions and conformal intervals for HybridModel."""

    # -- physics -----------------------------------------------------------------------
    def _posterior_physics(self, trips: pd.DataFrame, n_draws: int, seed: int,
                           traces=None, *, physics=None, stats=None, fade="auto"
                           ) -> tuple[pd.DataFrame, np.ndarray]:
        """Simulate-like table at the posterior median, and (n_draws, n_trips) energies.

        ``trips`` must be validated (:meth:`_validated`). The statistics are
        built once (or passed as ``stats``, from :meth:`_stats`); the median
        and the draws are one matrix product. ``physics``: see
        :meth:`_physics_energies`. ``fade``: the discrepancy's weight per trip
        (:meth:`_discrepancy_fade`, computed from ``trips`` and ``traces`` when
        ``"auto"``; None: 1 for every trip).
        """
        stats = self._stats(trips, traces) if stats is None else stats
        if isinstance(fade, str) and fade == "auto":
            fade = self._discrepancy_fade(trips, traces)
        energy = self._physics_energies(stats, n_draws, seed, physics, fade=fade)
        e_med = energy[0]
        e_draws = energy[1:] if n_draws else energy[:1]
        vmax = stats.max_speed_kmh
        if stats.marginalised:
            starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
            vmax = np.maximum.reduceat(vmax, starts)
        out = with_physics_columns(trips, e_med, vmax, self._vehicle().battery_capacity_kwh)
        return out, e_draws

    def _stats(self, trips: pd.DataFrame, traces=None):
        """Physics statistics of validated ``trips`` as the posterior builds them.

        CV+ fold posteriors share them: they are sampled with the same sign
        split (:func:`~hybridev.bayes.sampler.calibrate_physics`'s
        ``sign_vehicle``), and unlabelled trips take the full posterior's mode
        weights (a documented shortcut, :mod:`hybridev.learning.cvplus`).
        """
        post: PhysicsPosterior = self.posterior_
        return post.stats_for(trips, traces)

    def _physics_energies(self, stats, n_draws: int, seed: int, physics=None, *,
                          fade=None) -> np.ndarray:
        """Energies ``(1 + n_draws, n_trips)``: posterior median, then draws, kWh.

        ``physics`` is a ``(posterior, discrepancy)`` pair (default: the
        model's ``posterior_`` and ``discrepancy_``); the discrepancy's term
        weights (:mod:`hybridev.bayes.discrepancy`) multiply the physics terms,
        its draws pair with the parameter draws. ``fade`` (n_trips,), from
        :meth:`_discrepancy_fade`, blends each trip's energies from the
        calibrated physics (0) to the re-weighted one (1).
        """
        post, disc = physics or (self.posterior_, getattr(self, "discrepancy_", None))
        med = np.median(post.samples, axis=0)  # as PhysicsPosterior.median()
        rng = np.random.default_rng(seed)
        draws = post.sample(n_draws, rng) if n_draws else np.empty((0, med.size))
        params = post.as_params(np.vstack([med, draws]))
        if disc is None:
            return energy_from_stats(stats, params)
        weights = np.vstack([disc.weights, disc.sample(n_draws, rng)])
        energy = energy_from_stats(stats, params, term_weights=weights)
        if fade is not None:
            plain = energy_from_stats(stats, params)
            energy = plain + fade * (energy - plain)
        return energy

    def _discrepancy_fade(self, trips: pd.DataFrame, traces=None) -> np.ndarray | None:
        """Per-trip weight of the discrepancy stage, None when it is 1 for every trip.

        1 inside the training domain, fading to 0 with the trip's largest gap
        (:meth:`~hybridev.learning.domain.TrainingDomain.discrepancy_fade`): away from
        the fitting trips the prediction reverts to the calibrated physics, whose
        parameters the priors keep physical. A missing ``mode`` or trace alone does
        not fade it (they are handled by :mod:`hybridev.learning.ood`).
        """
        dom = getattr(self, "domain_", None)
        if dom is None or getattr(self, "discrepancy_", None) is None or not len(trips):
            return None
        gap = dom.gap(trips, traces)  # intensive conditions only (learning.domain)
        return None if np.all(gap <= 1.0) else dom.discrepancy_fade(gap)

    def _fit_discrepancy(self, post: PhysicsPosterior, measured: pd.DataFrame,
                         traces=None) -> TermDiscrepancy | None:
        """The term re-weighting of ``post``'s physics on ``measured`` (None when off)."""
        if not getattr(self, "discrepancy", False):
            return None
        stats = post.stats_for(measured, traces)
        med = post.as_params(np.median(post.samples, axis=0)[None, :])  # (1, 1) arrays
        e_p = energy_from_stats(stats, med)[0]
        scale = self._target_scale(e_p, measured["distance_km"].to_numpy(float))
        return TermDiscrepancy.fit(stats, med, measured["energy_kwh"].to_numpy(float),
                                   np.maximum(scale, 1e-9))

    def _fit_posterior(self, measured: pd.DataFrame, seed: int, traces=None) -> None:
        if not self.calibrate_physics or not self._residual:
            return
        self.posterior_, self.discrepancy_ = self._calibrate(measured, seed, traces)

    def _calibrate(self, measured: pd.DataFrame, seed: int, traces=None, *,
                   sign_vehicle=None, n_steps: int | None = None):
        """Posterior (thinned to :data:`KEEP_POSTERIOR_DRAWS`) and discrepancy on ``measured``."""
        mode = self.missing_mode
        if isinstance(mode, str) and mode == "infer" and measured["mode"].notna().all():
            mode = "marginalize"  # nothing to infer from: every trip is labelled
        post = calibrate_physics(
            measured, self._vehicle(), params=tuple(self.physics_params), seed=int(seed),
            missing_mode=mode, timeseries=traces, n_steps=n_steps, sign_vehicle=sign_vehicle,
            trace_steps=int(self.n_steps), trace_seed=int(self.physics_seed))
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

    # -- distribution ------------------------------------------------------------------
    def _has_spread(self) -> bool:
        """Whether the model can express uncertainty (else its intervals have zero width)."""
        return (int(self.n_members) > 1 or bool(self.heteroscedastic)
                or getattr(self, "posterior_", None) is not None)

    def _require_probabilistic(self, what: str) -> None:
        name = type(self).__name__
        if not hasattr(self, "net_"):
            raise NotFittedError(
                f"this {name} is not fitted yet: {what} needs the fitted network and its "
                "calibration; call fit(measured_trips) first or load a fitted model "
                "(predict() alone falls back to the physics)")
        if not self._has_spread():
            raise ValueError(
                f"this {name} has no predictive spread (n_members=1, heteroscedastic=False, "
                "no physics posterior: the paper's point model), so it has no "
                f"{what}; fit with n_members >= 2, heteroscedastic=True or "
                "calibrate_physics=True (the defaults) for one")

    def _distribution(self, trips: pd.DataFrame, *, seed: int = 0, traces=None
                      ) -> tuple[pd.DataFrame, EnergyDistribution]:
        """Physics table and the raw (spread factor 1) predictive distribution."""
        table, dists = self._distributions(trips, seed=seed, traces=traces)
        return table, dists[0]

    def _distributions(self, trips: pd.DataFrame, *, seed: int = 0, traces=None,
                       nets=(None,), physics=None
                       ) -> tuple[pd.DataFrame, list[EnergyDistribution]]:
        """Physics table and one raw predictive distribution per ensemble in ``nets``.

        ``None`` in ``nets`` is the fitted ensemble ``net_``; the others are CV+
        fold ensembles. ``physics`` (optional, one per net) gives each its own
        ``(posterior, discrepancy)`` pair (CV+ folds); ``None`` entries, or no
        ``physics``, use the model's. The statistics are built once. The
        returned table is that of the first entry.
        """
        self._require_fitted()
        physics = [None] * len(nets) if physics is None else list(physics)
        has_post = getattr(self, "posterior_", None) is not None
        if has_post:
            valid = self._validated(trips)
            stats = self._stats(valid, traces)
            fade = self._discrepancy_fade(valid, traces)  # once for every entry
        tables, dists, cache = [], [], {}
        for net, phys in zip(nets, physics, strict=True):
            key = id(phys)
            if key not in cache:  # the physics part of this entry (shared by entries)
                if has_post:
                    table, draws = self._posterior_physics(
                        valid, int(self.n_posterior_draws), seed, physics=phys, stats=stats,
                        fade=fade)
                else:
                    table = self._physics(trips, traces)
                    draws = table["energy_kwh_physics"].to_numpy(float)[None, :]
                e_p = table["energy_kwh_physics"].to_numpy(float)
                held, factor = held_feature_table(self, table)  # learning.physical
                scale = self._target_scale(e_p, table["distance_km"].to_numpy(float)) * factor
                if not self._residual:  # PureML: no physics part
                    centred = np.zeros_like(draws)
                else:
                    centred = draws - draws.mean(axis=0)
                    centred += e_p
                cache[key] = (table, self._features(held), scale, centred)
            table, feats, scale, centred = cache[key]
            mean, var = self._residual_moments(feats, scale, net=net)
            std = np.zeros_like(mean) if var is None else np.sqrt(var)
            tables.append(table)
            dists.append(EnergyDistribution(centred, mean, std))
        # planned trips (no trace): the learned mean correction (learning.planned)
        return tables[0], [planned_distribution(self, tables[0], traces, d) for d in dists]

    def _conformal_factor(self, level: float) -> float | None:
        """Conformal quantile for ``level``, None without a conformal step; checks ``level``."""
        _check_level(level)
        cp = getattr(self, "conformal_", None)
        if cp is None:
            return None
        q = cp.quantile(level)
        if not np.isfinite(q):
            raise ValueError(
                f"level={level!r} is too high for the {cp.n_calibration} calibration trips: "
                f"the highest level they support is "
                f"{cp.n_calibration / (cp.n_calibration + 1):.3f} (n / (n + 1)); use a lower "
                f"level or fit on at least {min_calibration_trips(level)} trips"
                + ("" if isinstance(cp, CVPlusConformal)
                   else " (conformal='cv+' calibrates on every trip)"))
        return q

    def _cv_nets(self) -> list:
        cp = getattr(self, "conformal_", None)
        nets = getattr(self, "cv_nets_", None) or []
        return nets if isinstance(cp, CVPlusConformal) and len(nets) == cp.n_folds else []

    def predict_distribution(self, trips: pd.DataFrame, *, level: float = 0.9,
                             seed: int = 0, timeseries=None) -> EnergyDistribution:
        """Predictive distribution of the trips' energies (joint across trips).

        Parameters
        ----------
        trips : pandas.DataFrame or MeasuredTrips
            Trip table (``mode`` may be missing); a
            :class:`~hybridev.data.logs.MeasuredTrips` brings its traces.
        level : float
            Confidence level in (0, 1) whose conformal correction sets the
            spread factor (see
            :meth:`hybridev.learning.conformal.NormalizedConformal.spread_factor`).
            Out-of-domain trips get the larger of that spread and their
            out-of-domain spread (a per-trip factor).
        seed : int
            Seeds the choice of posterior draws.
        timeseries : LoggedTraces or pandas.DataFrame, optional
            Logged speed traces by ``trip_id`` (see :meth:`HybridModel.fit`).

        Returns
        -------
        EnergyDistribution
            With ``n_trips`` in the row order of ``trips``.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            When the model is not fitted.
        ValueError
            On a bad ``level`` (or one too high for the calibration trips) or
            a model without predictive spread.

        Warns
        -----
        OutOfDomainWarning
            Once, with the count, when some trips lie outside the training domain.
        """
        self._require_probabilistic("predict_distribution")
        check_seed(seed)
        q = self._conformal_factor(level)
        trips, traces = unpack_trips(trips, timeseries)
        table, dist = self._distribution(trips, seed=seed, traces=traces)
        factor = 1.0 if q is None else max(self.conformal_.spread_factor(level), 1e-6)
        _, ok, sd_ood = self._ood_spread(table, dist, traces)
        factor = spread_factors(self, table, traces, factor, level)  # learning.planned
        sd = np.maximum(dist.std(), 1e-12)
        per_trip = np.where(ok, factor, np.maximum(factor, sd_ood / sd))
        if np.all(per_trip == factor):
            per_trip = factor
        return EnergyDistribution(dist.physics_draws_kwh, dist.residual_mean_kwh,
                                  dist.residual_std_kwh, spread_factor=per_trip)

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
            ranks the relative error). See the module docstring.

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
        q = self._conformal_factor(level)
        trips, traces = unpack_trips(trips, timeseries)
        cv = self._cv_nets()
        fold_physics = (getattr(self, "cv_physics_", None) or [None] * len(cv)) if cv else []
        table, dists = self._distributions(trips, seed=seed, traces=traces, nets=(None, *cv),
                                           physics=(None, *fold_physics))
        dist = dists[0]
        mu, sd = dist.mean(), dist.std()
        e_p = table["energy_kwh_physics"].to_numpy(float)
        floor = np.minimum(e_p, 0.0) if self._residual else np.zeros_like(e_p)
        floor = np.maximum(floor, energy_floor_kwh(table, self._vehicle()))  # learning.physical
        if cv:
            fm = np.stack([d.mean() for d in dists[1:]])
            fs = np.maximum(np.stack([d.std() for d in dists[1:]]), 1e-12)
            lo, hi = self.conformal_.cv_interval(fm, fs, level)
            lo_one = self.conformal_.cv_lower_bound(fm, fs, level)
        elif q is not None:
            lo, hi = mu - q * sd, mu + q * sd
            lo_one = self.conformal_.lower_bound(mu, sd, level)
        else:
            lo, hi = dist.interval(level)
            lo_one = dist.quantile(1.0 - level)
        if self.mondrian and q is not None:  # per-bin calibration where the data allow
            mlo, mhi, used = mondrian_interval(
                self.conformal_, self.conformal_bins_,
                mondrian_bins(table, self.mondrian_cut_km_), level, mean=mu, std=sd,
                fold_means=fm if cv else None, fold_stds=fs if cv else None)
            lo, hi = np.where(used, mlo, lo), np.where(used, mhi, hi)
        point = np.maximum(mu, floor)
        lo, hi = np.minimum(lo, mu), np.maximum(hi, mu)  # CV+ bounds need not hold mu
        score, ok, sd_ood = self._ood_spread(table, dist, traces)
        z2, z1 = float(ndtri(0.5 + level / 2.0)), float(ndtri(level))
        if cv and not ok.all():
            # out of the domain the CV+ interval is not used: its guarantee needs a trip
            # exchangeable with the training ones, and there its width measures only the
            # fold models' spread; the final model's own calibrated interval instead
            lo = np.where(ok, lo, mu - q * sd)
            hi = np.where(ok, hi, mu + q * sd)
            lo_one = np.where(ok, lo_one, self.conformal_.lower_bound(mu, sd, level))
        # planned trips (no trace) and the learned out-of-domain widening (learning.planned)
        lo, hi, lo_one = interval_bounds(self, table, traces, mu, sd, level, lo, hi, lo_one)
        # out of the domain: mu +- z sd_ood (learning.ood), never narrower than that
        lo = np.where(ok, lo, np.minimum(lo, mu - z2 * sd_ood))
        hi = np.where(ok, hi, np.maximum(hi, mu + z2 * sd_ood))
        lo_one = np.where(ok, lo_one, np.minimum(lo_one, mu - z1 * sd_ood))
        lo, hi, lo_one = (np.maximum(a, floor) for a in (lo, hi, lo_one))
        lo_one = np.minimum(lo_one, point)  # the SoC interval always holds the point prediction
        cap = self._vehicle().battery_capacity_kwh
        s0 = table["soc_initial"].to_numpy(float)
        may_empty = hi >= s0 * cap
        out = table
        out["energy_kwh_pred"] = point
        out["energy_kwh_lo"] = lo
        out["energy_kwh_hi"] = hi
        out["soc_final_pred"] = soc_from_energy(s0, point, cap)
        out["soc_final_lo"] = np.where(may_empty, 0.0, soc_from_energy(s0, hi, cap))
        out["soc_final_hi"] = soc_from_energy(s0, np.where(may_empty, lo_one, lo), cap)
        out["in_domain"] = ok
        out["domain_score"] = score
        conf = np.where(ok, sd, np.maximum(sd, sd_ood))
        out["confidence"] = conf
        out["confidence_rel"] = conf / self._target_scale_any(point, table)
        return out

    def _target_scale_any(self, energy_kwh, table: pd.DataFrame) -> np.ndarray:
        """Energy scale ``max(|E|, 0.05 kWh/km * d)`` of the relative confidence, kWh."""
        return np.maximum(np.abs(energy_kwh), 0.05 * table["distance_km"].to_numpy(float))

    @property
    def capacity_kwh(self) -> float:
        """Battery capacity of the model's vehicle, kWh."""
        return float(self._vehicle().battery_capacity_kwh)

    # -- persistence -------------------------------------------------------------------
    def _extra_state(self) -> tuple[dict, dict[str, np.ndarray]]:
        doc, arrays = {}, {}
        post = getattr(self, "posterior_", None)
        if post is not None:
            d = post.to_dict()
            doc["posterior"] = {"param_names": d["param_names"], "meta": d["meta"]}
            arrays["posterior_samples"] = d["samples"].astype(np.float32)
            arrays["posterior_noise_rel"] = d["noise_rel"].astype(np.float32)
            if d["mode_weights"] is not None:
                arrays["posterior_mode_weights"] = d["mode_weights"].astype(np.float32)
        disc = getattr(self, "discrepancy_", None)
        if disc is not None:
            arrays.update({f"discrepancy.{k}": v for k, v in disc.to_arrays().items()})
        cp = getattr(self, "conformal_", None)
        if cp is not None:
            arrays["conformal_residuals"] = cp.residuals
        if cp is not None and getattr(self, "conformal_bins_", None) is not None:
            doc["mondrian_cut_km"] = self.mondrian_cut_km_
            arrays["conformal_bins"] = np.asarray(self.conformal_bins_, np.int64)
        if self._cv_nets():
            doc["cv_folds"] = len(self.cv_nets_)
            arrays["conformal_fold"] = cp.fold
            arrays.update(nets_to_arrays(self.cv_nets_))
            arrays.update(physics_to_arrays(getattr(self, "cv_physics_", None) or []))
        dom = getattr(self, "domain_", None)
        if dom is not None:
            arrays.update({f"domain.{k}": v for k, v in dom.to_arrays().items()})
        arrays.update(planned_arrays(self))  # planned trips, gap rate (learning.planned)
        return doc, arrays

    def _set_extra_state(self, doc: dict, arrays: dict[str, np.ndarray]) -> None:
        if "posterior" in doc:
            p = doc["posterior"]
            self.posterior_ = PhysicsPosterior.from_dict({
                "param_names": p["param_names"], "meta": p["meta"],
                "samples": arrays["posterior_samples"],
                "noise_rel": arrays["posterior_noise_rel"],
                "mode_weights": arrays.get("posterior_mode_weights")})
        if any(k.startswith("discrepancy.") for k in arrays):
            self.discrepancy_ = TermDiscrepancy.from_arrays(
                {k[len("discrepancy."):]: v for k, v in arrays.items()
                 if k.startswith("discrepancy.")})
        if "conformal_residuals" in arrays:
            self.conformal_ = NormalizedConformal(arrays["conformal_residuals"])
        if "mondrian_cut_km" in doc:
            self.mondrian_cut_km_ = float(doc["mondrian_cut_km"])
            self.conformal_bins_ = np.asarray(arrays["conformal_bins"], np.int64)
        if "cv_folds" in doc:
            self.conformal_ = CVPlusConformal(arrays["conformal_residuals"],
                                              arrays["conformal_fold"])
            self.cv_nets_ = nets_from_arrays(self, arrays, int(doc["cv_folds"]))
            self.cv_physics_ = (physics_from_arrays(self, arrays, int(doc["cv_folds"]))
                                if getattr(self, "posterior_", None) is not None else [])
        if any(k.startswith("domain.") for k in arrays):
            self.domain_ = TrainingDomain.from_arrays(
                {k[len("domain."):]: v for k, v in arrays.items() if k.startswith("domain.")})
        set_planned_state(self, arrays)  # planned trips, gap rate (learning.planned)
