"""Out-of-domain spread of the hybrid model's predictions (see :mod:`hybridev.learning.domain`).

A trip outside the training domain gets the spread ``sd_ood`` instead of the
model's own (conformally calibrated) one:

* outside the training ranges or in a gap of them (largest intensive gap ``g > 1``):
  ``sqrt(var_draws + inflation(g)^2 * rest)`` (``inflation`` at the rate learned at fit,
  :class:`~hybridev.learning.shift.GapRate`, when the model has one; with it the
  interval is also at least ``mu +- q s inflation(g)`` with the trip's own conformal
  ``q``), with
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

A trip *between* training values of its intensive conditions (a temperature
between two logged ones) is in the domain: it keeps the model's own calibrated
spread, times the learned rate's interpolation inflation (1 within a tolerance
of the data; :class:`~hybridev.learning.shift.GapRate`, :meth:`OutOfDomainSpread.rate_inflation`).

**With a learned rate** (``rate.learned_``: enough of the fit's own scored trips lay
beyond their fold's conditions), a trip beyond the intensive conditions gets the
interval the rate was learned for, its conformal ``mu +- q s inflation(g)``, and no
floor at ``sd_ood``: the rate measured how much wider the conformal interval must be
there, and the trip's own ``s`` already holds its posterior draws' spread (the prior of
a heater never seen working). Stacking the raw spread on it made the flagged M1 trips
at 40 training trips far wider than the in-domain ones at similar errors
(``evaluation/planned_trips``). The floor below stays for a missing mode or trace,
and with a fixed rate.

Otherwise intervals of such trips are ``mu +- z_level * sd_ood``, never narrower than
the final model's own conformally calibrated interval ``mu +- q sd``. With
CV+ the CV+ interval is not used for them: its guarantee rests on the new trip
being exchangeable with the training trips, which an out-of-domain trip is
not, and there its width measures only how far the fold models' predictions
spread. ``predict_distribution`` scales each trip's spread by
``sd_ood / sd``.

:class:`OutOfDomainSpread` is the step of the predictive path
(:mod:`hybridev.learning.pipeline`) that does this: it reads the training domain's
:class:`~hybridev.learning.steps.DomainAssessment`, the raw prediction and the
calibrated interval, and widens the intervals of the trips out of the domain.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from scipy.special import ndtri

from hybridev.learning.steps import CalibratedInterval, DomainAssessment, RawPrediction

__all__ = ["OutOfDomainSpread", "trace_gap"]

_PHYSICS_COLUMNS = ("energy_kwh_physics", "soc_final_physics", "max_speed_kmh",
                    "kwh_per_km_physics")


@dataclass(frozen=True)
class OutOfDomainSpread:
    """The out-of-domain spread of a fitted model (see the module docstring).

    Parameters
    ----------
    noise_rel : float
        The physics posterior's median relative noise (0 without a posterior).
    trace_gap_rel : float
        ``fit_info_["trace_gap_rel"]`` (0 when not fitted on logged traces).
    rate : GapRate or None
        The learned widening rate (:class:`~hybridev.learning.shift.GapRate`, the
        model's ``gap_rate_``); None: the fixed
        :meth:`~hybridev.learning.domain.TrainingDomain.inflation` of the assessment.
    """

    noise_rel: float = 0.0
    trace_gap_rel: float = 0.0
    rate: object = None

    def inflation(self, gap: np.ndarray, fixed: np.ndarray | None = None) -> np.ndarray:
        """Width multiplier at ``gap``: the learned rate's, else ``fixed`` (the
        assessment's fixed-rate inflation)."""
        return fixed if self.rate is None else self.rate.inflation(gap)

    def sd(self, assessment: DomainAssessment | None, table: pd.DataFrame, mu: np.ndarray,
           sd: np.ndarray, var_draws: np.ndarray, *, excess_var=None, dist=None,
           mode_means=None) -> np.ndarray:
        """``sd_ood`` (kWh) per trip: the model's own ``sd`` in the domain.

        ``var_draws`` (n_trips,): the variance of the physics draws; ``excess_var``: the
        predictive variance beyond the draws' (or ``dist``, the raw distribution, whose
        :meth:`~hybridev.learning.predictive.EnergyDistribution.excess_var` gives it;
        with neither ``max(sd^2 - var_draws, 0)``, which loses digits when the draws
        dominate). ``mode_means``: for the trips lacking a trained-with mode, their point
        energies under the three modes (3, n_no_mode), or a callable giving them from
        those trips' table. ``table``: the physics table, or (with ``mode_means`` an
        array) its columns as arrays by name.
        """
        if assessment is None or assessment.in_domain.all():
            return sd
        a = assessment
        gap = a.ood_gap
        e_p = table["energy_kwh_physics"]  # a table's column, or an array (raw.columns)
        e_p = e_p if isinstance(e_p, np.ndarray) else e_p.to_numpy(float)
        # the posterior draws' spread as it is; the rest (noise, network) inflated
        if excess_var is None:
            excess_var = (dist.excess_var() if dist is not None
                          else np.maximum(sd**2 - var_draws, 0.0))
        rest = (self.noise_rel * e_p) ** 2 + (mu - e_p) ** 2 + excess_var
        infl = self.inflation(gap, a.inflation)  # learned rate (learning.shift) or fixed
        sd_ood = np.where(gap > 1.0, np.sqrt(var_draws + infl**2 * rest), sd)
        no_trace = a.no_trace
        if self.trace_gap_rel > 0 and no_trace.any():  # what the missing trace alone can change
            sd_ood[no_trace] = np.sqrt(sd_ood[no_trace] ** 2
                                       + (self.trace_gap_rel * mu[no_trace]) ** 2)
        no_mode = a.no_mode
        if no_mode.any():
            mus = mode_means
            if callable(mus):
                mus = mus(table.loc[no_mode, [c for c in table.columns
                                              if c not in _PHYSICS_COLUMNS]])
            between = mus.var(axis=0) + (mu[no_mode] - mus.mean(axis=0)) ** 2
            sd_ood[no_mode] = np.sqrt(sd_ood[no_mode] ** 2 + between)
        return sd_ood

    def _raw_sd(self, assessment, raw: RawPrediction) -> tuple[np.ndarray, np.ndarray]:
        """``(ok, sd_ood)``: the trips whose interval is not floored at ``mu +- z
        sd_ood``, and ``sd_ood`` (kWh).

        With a rate learned from the fit's own shifted trips (``rate.learned_``), a trip
        out of the domain only for its intensive conditions is ``ok``: the learned rate
        says how much wider its conformal interval ``mu +- q s`` must be
        (:meth:`_rate_widened`), and the raw spread is not stacked on it. The floor stays
        for trips lacking a mode or (with ``trace_gap_rel``) their trace, and with a
        fixed rate.
        """
        n = len(raw.mean)
        ok = np.ones(n, dtype=bool) if assessment is None else assessment.in_domain
        if assessment is not None and getattr(self.rate, "learned_", False):
            other = np.asarray(assessment.no_mode, bool) & np.ones(n, dtype=bool)
            if self.trace_gap_rel > 0:
                other = other | np.asarray(assessment.no_trace, bool)
            ok = ok | ~other
        cols = raw.columns  # the columns as arrays: the table is built once, at the output
        table = cols if cols is not None and not callable(raw.mode_means) else raw.table
        return ok, self.sd(assessment, table, raw.mean, raw.std, raw.var_draws,
                           excess_var=raw.excess_var, mode_means=raw.mode_means)

    def widen(self, assessment: DomainAssessment | None, raw: RawPrediction,
              cal: CalibratedInterval, level: float) -> tuple[CalibratedInterval, np.ndarray]:
        """Step 6: intervals of out-of-domain trips widened to ``mu +- z sd_ood``.

        Returns the interval (never narrower than ``cal``'s) and ``confidence``, the
        predictive standard deviation per trip (kWh, ``sd_ood`` out of the domain).
        """
        mu, sd = cal.mean, cal.std
        ok, sd_ood = self._raw_sd(assessment, raw)
        z2, z1 = float(ndtri(0.5 + level / 2.0)), float(ndtri(level))
        if self.rate is not None and assessment is not None and cal.quantile is not None:
            cal = self._rate_widened(assessment, cal)
        lo = np.where(ok, cal.lo, np.minimum(cal.lo, mu - z2 * sd_ood))
        hi = np.where(ok, cal.hi, np.maximum(cal.hi, mu + z2 * sd_ood))
        lo_one = np.where(ok, cal.lo_one, np.minimum(cal.lo_one, mu - z1 * sd_ood))
        wide = CalibratedInterval(mean=mu, std=sd, lo=lo, hi=hi, lo_one=lo_one,
                                  spread_factor=cal.spread_factor, quantile=cal.quantile)
        if self.rate is not None and assessment is not None:
            sd = sd * self.rate_inflation(assessment)  # the learned widening, as a spread
        return wide, np.where(ok, sd, np.maximum(sd, sd_ood))

    def rate_inflation(self, a: DomainAssessment) -> np.ndarray:
        """The learned rate's width multiplier per trip: beyond the intensive conditions
        (``gap``) times between them (``interp_gap``, :class:`~hybridev.learning.shift.
        GapRate`); (n_trips,)."""
        return self.rate.inflation(a.gap) * self.rate.interp_inflation(a.interp_gap)

    def _rate_widened(self, a: DomainAssessment, cal: CalibratedInterval
                      ) -> CalibratedInterval:
        """With a learned rate: trips beyond the intensive conditions (``gap > 1``) or
        far between them (``interp_gap > 1``) at least ``mu +- q s inflation`` with their
        own conformal ``q`` (and ``q'``), the inflation :meth:`rate_inflation`."""
        n = len(cal.mean)
        q = np.broadcast_to(np.asarray(cal.quantile, float), (n,))
        q1 = np.broadcast_to(np.asarray(np.nan if cal.quantile_one is None
                                        else cal.quantile_one, float), (n,))
        infl_all = self.rate_inflation(a) * np.ones(n)
        out = (infl_all > 1.0) & np.isfinite(q)
        if not out.any():
            return cal
        mu, sd = cal.mean[out], cal.std[out]
        infl = infl_all[out]
        lo, hi, lo_one = (np.array(v, float, copy=True) for v in (cal.lo, cal.hi, cal.lo_one))
        lo[out] = np.minimum(lo[out], mu - q[out] * sd * infl)
        hi[out] = np.maximum(hi[out], mu + q[out] * sd * infl)
        lo_one[out] = np.minimum(lo_one[out], mu - q1[out] * sd * infl)
        return replace(cal, lo=lo, hi=hi, lo_one=lo_one)

    def spread_factor(self, assessment: DomainAssessment | None, raw: RawPrediction,
                      factor):
        """Step 6 of ``predict_distribution``: the per-trip spread factor.

        ``factor`` (the calibrators', a number or per trip) times the learned rate's
        inflation of the intensive gap and interpolation gap (:meth:`rate_inflation`),
        in the domain; at least ``sd_ood / sd`` out of
        it; a number when every trip has the same.
        """
        if self.rate is not None and assessment is not None:
            factor = np.broadcast_to(factor, (len(raw.mean),)) * self.rate_inflation(
                assessment)
            if len(factor) and np.all(factor == factor[0]):
                factor = float(factor[0])
        ok, sd_ood = self._raw_sd(assessment, raw)
        sd = np.maximum(raw.std, 1e-12)
        per_trip = np.where(ok, factor, np.maximum(factor, sd_ood / sd))
        return factor if np.all(per_trip == factor) else per_trip


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
