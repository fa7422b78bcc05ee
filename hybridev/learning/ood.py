"""Out-of-domain spread of the hybrid model's predictions (see :mod:`hybridev.learning.domain`).

A trip outside the training domain gets the spread ``sd_ood`` instead of the
model's own (conformally calibrated) one:

* outside the training ranges or in a gap of them (largest gap ``g > 1``):
  ``sqrt(var_draws + inflation(g)^2 * rest)``, with
  ``rest = (noise_rel E_p)^2 + (mu - E_p)^2 + max(sd^2 - var_draws, 0)``: the
  physics posterior predictive (the spread of the posterior draws,
  ``var_draws``, and the posterior's relative noise ``noise_rel``), the
  residual's departure from the physics (which the training data no longer
  vouch for) and the rest of the model's own spread (network members and
  noise), with
  :meth:`~hybridev.learning.domain.TrainingDomain.inflation` on everything but
  the posterior draws. The draws are not inflated: where the training trips
  did not pin a parameter down (the heating of a car logged in summer only),
  the posterior there *is* its prior, whose spread already says how little is
  known, and inflating it as well gave a summer-trained real car intervals
  several times its cold trips' energy (``evaluation/shift_and_small_data``,
  the M1 warm-trained folds). The inflation is for what the posterior cannot
  know: the model's own misspecification away from its data;
* lacking the ``mode`` every training trip had: marginalised over the three
  modes: the spread between the three modes' predictions is added (no
  inflation);
* lacking the logged trace most training trips had: a gap of 2, and the spread
  ``trace_gap_rel * mu`` added in quadrature: ``fit_info_["trace_gap_rel"]`` is
  the root-mean-square log ratio of the measured energy to the prediction of
  the same training trip on a synthesised trace instead of its own (how far a
  synthesised trace's physics is from how this car is driven: a stop-and-go
  winter commute can use 15-20 % more than the smooth synthetic trace; a
  lower bound, in-sample for the network).

Intervals of such trips are ``mu +- z_level * sd_ood``, never narrower than
the final model's own conformally calibrated interval ``mu +- q sd``. With
CV+ the CV+ interval is not used for them: its guarantee rests on the new trip
being exchangeable with the training trips, which an out-of-domain trip is
not, and there its width measures only how far the fold models' predictions
spread. :meth:`predict_distribution` scales each trip's spread by
``sd_ood / sd``.
"""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from hybridev.learning.domain import (
    MISSING_INPUT_SCORE,
    domain_quantities,
    warn_out_of_domain,
)
from hybridev.learning.features import MODE_NAMES
from hybridev.learning.planned import gap_inflation
from hybridev.learning.predictive import EnergyDistribution

__all__ = ["OutOfDomainMixin", "trace_gap"]

_PHYSICS_COLUMNS = ("energy_kwh_physics", "soc_final_physics", "max_speed_kmh",
                    "kwh_per_km_physics")


class OutOfDomainMixin:
    """Domain scores and out-of-domain spreads for :class:`hybridev.HybridModel`."""

    def _ood_spread(self, table: pd.DataFrame, dist: EnergyDistribution, traces
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(domain_score, in_domain, sd_ood)`` per trip; warns once when some are out.

        ``sd_ood`` (kWh) of a trip outside the training ranges or in a gap of
        them is the spread of the physics posterior draws, plus the posterior's
        relative noise, the residual's departure from the physics and the rest
        of the model's own spread, these three times the inflation
        :meth:`~hybridev.learning.domain.TrainingDomain.inflation` of its
        largest gap. A trip only lacking the ``mode`` the model was trained
        with is marginalised over the three modes instead: its spread adds
        the spread between the three modes' predictions (no inflation). A trip
        lacking a trained-with logged trace counts as a gap of 2.
        """
        score, ok, sd_ood = self._ood_sd(table, dist.mean(), dist.std(),
                                         dist.physics_draws_kwh.var(axis=0), traces, dist=dist)
        n_out = int((~ok).sum())
        if n_out:
            warn_out_of_domain(n_out, dist.n_trips, stacklevel=4,
                               reasons=self.domain_.reasons(table, traces))
        return score, ok, sd_ood

    def _ood_sd(self, table: pd.DataFrame, mu: np.ndarray, sd: np.ndarray,
                var_draws: np.ndarray, traces=None, *, dist: EnergyDistribution | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_ood_spread` from the pieces: means, spreads and physics-draw variances.

        ``dist``: the distribution behind them; its
        :meth:`~EnergyDistribution.excess_var` gives the variance beyond the
        draws' (only when some trip is out of the domain). Without it,
        ``max(sd^2 - var_draws, 0)``, which loses digits when the draws dominate.
        """
        dom = getattr(self, "domain_", None)
        n = len(table)
        if dom is None:
            return np.zeros(n), np.ones(n, dtype=bool), sd
        score, ok = dom.score(table, traces)
        if ok.all():
            return score, ok, sd
        gap = dom.gap(table, traces)  # intensive conditions only (learning.domain)
        no_trace = dom.needs_trace & ~domain_quantities(table, traces)[1]
        gap = np.where(no_trace, np.maximum(gap, MISSING_INPUT_SCORE), gap)
        post = getattr(self, "posterior_", None)
        noise = float(np.median(post.noise_rel)) if post is not None else 0.0
        e_p = table["energy_kwh_physics"].to_numpy(float)
        # the posterior draws' spread as it is; the rest (noise, network) inflated
        var_rest = (dist.excess_var() if dist is not None
                    else np.maximum(sd**2 - var_draws, 0.0))
        rest = (noise * e_p) ** 2 + (mu - e_p) ** 2 + var_rest
        infl = gap_inflation(self, gap)  # learned rate (learning.planned / learning.shift)
        sd_ood = np.where(gap > 1.0, np.sqrt(var_draws + infl**2 * rest), sd)
        gap_rel = float((getattr(self, "fit_info_", None) or {}).get("trace_gap_rel", 0.0))
        if gap_rel > 0 and no_trace.any():  # what the missing trace alone can change
            sd_ood[no_trace] = np.sqrt(sd_ood[no_trace] ** 2 + (gap_rel * mu[no_trace]) ** 2)
        no_mode = (table["mode"].isna().to_numpy() if dom.needs_mode and "mode" in table
                   else np.zeros(n, dtype=bool))
        if no_mode.any():
            sub = table.loc[no_mode, [c for c in table.columns if c not in _PHYSICS_COLUMNS]]
            mus = np.stack([self._mode_prediction(sub.assign(mode=m), traces)
                            for m in MODE_NAMES])
            between = mus.var(axis=0) + (mu[no_mode] - mus.mean(axis=0)) ** 2
            sd_ood[no_mode] = np.sqrt(sd_ood[no_mode] ** 2 + between)
        return score, ok, sd_ood

    def _mode_prediction(self, trips: pd.DataFrame, traces) -> np.ndarray:
        """Point energy (kWh) of ``trips`` with their given modes, shape (n_trips,)."""
        tab = self._physics(trips, traces)
        e = tab["energy_kwh_physics"].to_numpy(float)
        sc = self._target_scale(e, tab["distance_km"].to_numpy(float))
        return self._combine(e, self._residual_moments(self._features(tab), sc)[0].mean(0))


def trace_gap(model, good: pd.DataFrame, e_meas: np.ndarray, traces) -> float:
    """``fit_info_["trace_gap_rel"]`` of a model just fitted on logged traces.

    Root-mean-square log ratio of the measured energy ``e_meas`` (kWh, one per row of
    ``good``) to ``model``'s prediction of the same training trip *without* its logged
    trace (on a synthesised one), over the trips that have a trace: the spread a trip
    predicted without its trace adds (module docstring). In-sample for the network, so
    a lower bound of the gap on new trips; what it measures is mostly how far the
    synthesised trace's physics is from the driving logged (stop-and-go, speed
    variation).
    """
    has = good["trip_id"].astype(object).isin(pd.Index(traces.trip_id)).to_numpy()
    if not has.any():
        return 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # every trip is out of the domain here
        mu = model.predict(good.loc[has].drop(columns=["energy_kwh", "soc_final"],
                                              errors="ignore"))["energy_kwh_pred"]
    ratio = e_meas[has] / np.maximum(mu.to_numpy(float), 1e-9)
    return float(np.sqrt(np.mean(np.log(np.maximum(ratio, 1e-9)) ** 2)))
