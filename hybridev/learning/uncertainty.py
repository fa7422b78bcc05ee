"""Predictive distributions and intervals of the hybrid model (the probabilistic layer).

The user's design, beyond the paper: an emcee posterior over the physics
parameters (:func:`hybridev.bayes.sampler.calibrate_physics`) combined with a deep
ensemble of residual networks with mean and variance heads
(:mod:`hybridev.learning.nn`), made to cover by a split-conformal step
(:mod:`hybridev.learning.conformal`).

For a trip with features ``x``, posterior draws ``theta_d`` (d = 1..D) and
members ``m`` (m = 1..M):

``E = E_p(theta_d) - mean_d E_p(theta_d) + E_p(theta_hat) + dE_m(x) + sigma_m(x) z``,

where ``theta_hat`` is the posterior median (the physics the network was
trained against). :class:`hybridev.learning.predictive.EnergyDistribution` holds the
pieces; its mean is the point prediction ``energy_kwh_pred``.

Intervals (:meth:`ProbabilisticMixin.predict_interval`) are normalised split-
conformal intervals ``mu +- q_level * s`` of energy, with ``mu`` and ``s`` the
mean and standard deviation of that distribution and ``q_level`` from
calibration trips held out of every other fitting step. Final SoC
``s0 - E / C`` (clipped to [0, 1]) is monotone in energy, so the SoC interval is the image
of the energy interval, except for trips that may empty the battery (energy
upper bound at or above ``s0 C``): their SoC has a point mass at 0, a central
interval would over-cover, and the interval is the one-sided
``[0, s0 - E_lo' / C]`` with the one-sided conformal lower energy bound
``E_lo'`` at the same level.

Energy bounds are floored like the point prediction (at ``min(E_p, 0)``, see
:mod:`hybridev.learning.model`), the one-sided bound is capped at the point prediction
(so every interval contains it), and SoC is clipped to [0, 1]
(:func:`hybridev.learning.predictive.soc_from_energy`). An unfitted model raises
:class:`sklearn.exceptions.NotFittedError` (only ``predict`` falls back to the
physics); the paper's point model (one MSE network, no posterior) has no
spread and raises a ``ValueError`` saying how to get one; a ``level`` above
``n_cal / (n_cal + 1)`` cannot be calibrated with ``n_cal`` calibration trips
and raises too.

Trips without a ``mode`` get the posterior-weighted (``missing_mode="infer"``)
or equal-weight mixture mean of the three profiles' physics; the spread
between the profiles is not part of the physics draws, so it is carried by
the members' noise heads (when the training trips were unlabelled too) and by
the conformal step. Intervals for unlabelled trips from a model fitted and
calibrated on labelled ones are therefore not covered by the conformal
guarantee.

``confidence`` is the predictive standard deviation ``s`` of the trip energy
in kWh (aleatoric noise of the members, their disagreement, and the physics
posterior spread): higher means less sure. The conformal factor multiplies all
trips alike, so it does not change the ranking and is not applied.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from sklearn.exceptions import NotFittedError

from hybridev.bayes.posterior import PhysicsPosterior
from hybridev.bayes.sampler import calibrate_physics
from hybridev.core.plugins import entry_point, lazy_backend
from hybridev.data.timeseries import as_traces
from hybridev.learning.conformal import NormalizedConformal
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


class ProbabilisticMixin:
    """Physics posterior, predictive distributions and conformal intervals for HybridModel."""

    # -- physics -----------------------------------------------------------------------
    def _posterior_physics(self, trips: pd.DataFrame, n_draws: int, seed: int,
                           traces=None) -> tuple[pd.DataFrame, np.ndarray]:
        """Simulate-like table at the posterior median, and (n_draws, n_trips) energies.

        ``trips`` must be validated (:meth:`_validated`). The statistics are
        built once; the median and the draws are one matrix product.
        """
        post: PhysicsPosterior = self.posterior_
        stats = post.stats_for(trips, traces)
        med = np.median(post.samples, axis=0)  # as PhysicsPosterior.median()
        draws = (post.sample(n_draws, np.random.default_rng(seed)) if n_draws
                 else np.empty((0, med.size)))
        energy = energy_from_stats(stats, post.as_params(np.vstack([med, draws])))
        e_med = energy[0]
        e_draws = energy[1:] if n_draws else energy[:1]
        vmax = stats.max_speed_kmh
        if stats.marginalised:
            starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
            vmax = np.maximum.reduceat(vmax, starts)
        out = with_physics_columns(trips, e_med, vmax, self._vehicle().battery_capacity_kwh)
        return out, e_draws

    def _fit_posterior(self, measured: pd.DataFrame, seed: int, traces=None) -> None:
        if not self.calibrate_physics or not self._residual:
            return
        mode = self.missing_mode
        if isinstance(mode, str) and mode == "infer" and measured["mode"].notna().all():
            mode = "marginalize"  # nothing to infer from: every trip is labelled
        post = calibrate_physics(
            measured, self._vehicle(), params=tuple(self.physics_params), seed=int(seed),
            missing_mode=mode, timeseries=traces,
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
        self.posterior_ = post

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
        self._require_fitted()
        if getattr(self, "posterior_", None) is not None:
            table, draws = self._posterior_physics(self._validated(trips),
                                                   int(self.n_posterior_draws), seed, traces)
        else:
            table = self._physics(trips, traces)
            draws = table["energy_kwh_physics"].to_numpy(float)[None, :]
        e_p = table["energy_kwh_physics"].to_numpy(float)
        scale = self._target_scale(e_p, table["distance_km"].to_numpy(float))
        mean, var = self._residual_moments(self._features(table), scale)
        std = np.zeros_like(mean) if var is None else np.sqrt(var)
        if not self._residual:  # PureML: no physics part
            centred = np.zeros_like(draws)
        else:
            centred = draws - draws.mean(axis=0)
            centred += e_p
        return table, EnergyDistribution(centred, mean, std)

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
                "level or fit on more trips / a larger conformal_fraction")
        return q

    def predict_distribution(self, trips: pd.DataFrame, *, level: float = 0.9,
                             seed: int = 0, timeseries=None) -> EnergyDistribution:
        """Predictive distribution of the trips' energies (joint across trips).

        Parameters
        ----------
        trips : pandas.DataFrame
            Trip table (``mode`` may be missing).
        level : float
            Confidence level in (0, 1) whose conformal correction sets the
            spread factor (see
            :meth:`hybridev.learning.conformal.NormalizedConformal.spread_factor`).
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
        """
        self._require_probabilistic("predict_distribution")
        q = self._conformal_factor(level)
        _, dist = self._distribution(trips, seed=seed, traces=as_traces(timeseries))
        if q is None:
            return dist
        factor = self.conformal_.spread_factor(level)
        return EnergyDistribution(dist.physics_draws_kwh, dist.residual_mean_kwh,
                                  dist.residual_std_kwh, spread_factor=max(factor, 1e-6))

    def predict_interval(self, trips: pd.DataFrame, level: float = 0.9, *,
                         seed: int = 0, timeseries=None) -> pd.DataFrame:
        """Predict energy and final SoC with intervals at confidence ``level``.

        Parameters
        ----------
        trips : pandas.DataFrame or dask.dataframe.DataFrame
            Trip table (``mode`` may be missing); a dask DataFrame gives a
            lazy dask DataFrame with the same rows (:mod:`hybridev.fleet.scoring`).
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
            ``soc_final_pred``, ``soc_final_lo``, ``soc_final_hi`` (in [0, 1])
            and ``confidence`` (kWh, the predictive standard deviation; higher
            means less sure). See the module docstring for the construction.

        Raises
        ------
        sklearn.exceptions.NotFittedError
            When the model is not fitted (fit it, or load a fitted one).
        ValueError
            On a bad ``level`` (or one too high for the calibration trips) or
            a model without predictive spread (the paper's point model).

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
        q = self._conformal_factor(level)
        table, dist = self._distribution(trips, seed=seed, traces=as_traces(timeseries))
        mu, sd = dist.mean(), dist.std()
        e_p = table["energy_kwh_physics"].to_numpy(float)
        floor = np.minimum(e_p, 0.0) if self._residual else np.zeros_like(e_p)
        if q is not None:
            lo, hi = mu - q * sd, mu + q * sd
            lo_one = self.conformal_.lower_bound(mu, sd, level)
        else:
            lo, hi = dist.interval(level)
            lo_one = dist.quantile(1.0 - level)
        point = np.maximum(mu, floor)
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
        out["confidence"] = sd
        return out

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
        cp = getattr(self, "conformal_", None)
        if cp is not None:
            arrays["conformal_residuals"] = cp.residuals
        return doc, arrays

    def _set_extra_state(self, doc: dict, arrays: dict[str, np.ndarray]) -> None:
        if "posterior" in doc:
            p = doc["posterior"]
            self.posterior_ = PhysicsPosterior.from_dict({
                "param_names": p["param_names"], "meta": p["meta"],
                "samples": arrays["posterior_samples"],
                "noise_rel": arrays["posterior_noise_rel"],
                "mode_weights": arrays.get("posterior_mode_weights")})
        if "conformal_residuals" in arrays:
            self.conformal_ = NormalizedConformal(arrays["conformal_residuals"])
