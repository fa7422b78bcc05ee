"""Predictive bands of each compared method and their metrics (for ``evaluation/uncertainty/uncertainty.py``).

Every method is reduced to a :class:`Bands`: point energy, the confidence
signal, and energy bounds at the 19 reliability levels 0.05..0.95 (central
``[lo, hi]`` and the one-sided lower bound ``lo_one``). Final-SoC intervals are
derived from them by :func:`soc_bounds`, the rule of
``HybridModel.predict_interval`` (image of the energy interval; one-sided
``[0, s0 - min(lo_one, mu) / C]`` when the upper energy bound can empty the
battery).
:func:`model_bands` rebuilds the model's intervals for all 19 levels at once
(one predictive distribution per test set instead of 19 ``predict_interval``
calls) from the model's public predictive distribution, its conformal scores
and the library's own pieces of the interval rule: the physical energy floor
(:func:`hybridev.learning.physical.energy_floor_kwh`) and the out-of-domain
spread (:mod:`hybridev.learning.ood`, :func:`hybridev.learning.pipeline.ood_sd`). Only
the arithmetic that combines them is repeated here; :func:`check_against_predict_interval`
asserts that the result equals ``predict_interval`` at the table levels (it
fails when the library's rule changes). Models calibrated by CV+ or per
Mondrian bin are refused (the study's fits use split conformal).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.special import ndtri

from hybridev import metrics as M
from hybridev.learning.conformal import NormalizedConformal
from hybridev.learning.physical import energy_floor_kwh
from hybridev.learning.pipeline import ood_sd
from hybridev.learning.predictive import EnergyDistribution, soc_from_energy

__all__ = ["LEVELS", "TABLE_LEVELS", "Bands", "check_against_predict_interval", "evaluate",
           "model_bands", "point_bands", "posterior_bands", "posterior_conformal", "soc_bounds"]

LEVELS = np.round(np.linspace(0.05, 0.95, 19), 2)
"""Nominal levels of the reliability curves."""
TABLE_LEVELS = (0.5, 0.8, 0.9, 0.95)
DIST_LEVEL = 0.9
"""Conformal level whose spread factor defines the calibrated distribution (CRPS, NLL)."""
N_POSTERIOR_PREDICTIVE = 1000
"""Posterior-predictive draws per trip for the posterior-only method."""


@dataclass
class Bands:
    """One method's predictions on one test set (energies in kWh).

    mu (n,): point energy; conf (n,) or None: confidence (predictive sd);
    lo, hi, lo_one (L, n): bounds at :data:`LEVELS`; crps, nll: scores of the
    (calibrated) predictive distribution, NaN when the method has none;
    in_domain (n,) or None: the model's ``in_domain`` flag (HybridModel only).
    """

    mu: np.ndarray
    conf: np.ndarray | None
    lo: np.ndarray
    hi: np.ndarray
    lo_one: np.ndarray
    crps: float = float("nan")
    nll: float = float("nan")
    phys_share: float = float("nan")
    in_domain: np.ndarray | None = None


def _floor(*arrays):
    return [np.maximum(a, 0.0) for a in arrays]  # baselines without a physics table: E >= 0


def soc_bounds(b: Bands, soc_initial: np.ndarray, capacity_kwh: float):
    """Final-SoC bounds (L, n) of the energy bounds, with the one-sided rule at SoC 0."""
    s0 = np.asarray(soc_initial, float)[None, :]
    may_empty = b.hi >= s0 * capacity_kwh
    lo_one = np.minimum(b.lo_one, b.mu[None, :])  # the SoC interval holds the point prediction
    lo = np.where(may_empty, 0.0, soc_from_energy(s0, b.hi, capacity_kwh))
    hi = soc_from_energy(s0, np.where(may_empty, lo_one, b.lo), capacity_kwh)
    return lo, hi


_PRED_COLUMNS = ("energy_kwh_pred", "soc_final_pred", "domain_score", "in_domain")
"""Columns ``predict`` adds to the physics table."""


def _raw(dist: EnergyDistribution) -> EnergyDistribution:
    return EnergyDistribution(dist.physics_draws_kwh, dist.residual_mean_kwh,
                              dist.residual_std_kwh)


def model_bands(model, trips: pd.DataFrame, y: np.ndarray, seed: int) -> Bands:
    """Bands of a fitted HybridModel (conformal if it has ``conformal_``).

    The rule of ``HybridModel.predict_interval`` at every level of :data:`LEVELS`:
    split-conformal ``mu +- q s`` (or the raw mixture's quantiles without a
    conformal step) and the conformal one-sided lower bound; bounds made to hold
    ``mu``; out-of-domain trips widened to ``mu +- z s_ood``; every bound floored at
    ``max(min(E_p, 0), physical floor)``, the point prediction too; the one-sided
    bound capped at the point prediction.
    """
    cp = getattr(model, "conformal_", None)
    if model.calibrator_.folds() or getattr(model, "mondrian", False):
        raise ValueError("model_bands reproduces split-conformal intervals only; this model "
                         "uses CV+ or Mondrian calibration (fit on >= 250 trips, "
                         "conformal='split', mondrian=False)")
    dist = model.predict_distribution(trips, level=DIST_LEVEL, seed=seed)
    raw = _raw(dist)
    mu, sd = raw.mean(), raw.std()
    table = model.predict(trips)  # the physics table (posterior-median physics)
    e_p = table["energy_kwh_physics"].to_numpy(float)
    floor = np.minimum(e_p, 0.0) if model._residual else np.zeros_like(e_p)
    floor = np.maximum(floor, energy_floor_kwh(table, model._vehicle()))
    if cp is None:
        q = raw.quantile(np.r_[(1 - LEVELS) / 2, (1 + LEVELS) / 2, 1 - LEVELS])
        lo, hi, lo_one = np.split(q, 3)
    else:
        qs = np.array([cp.quantile(lv) for lv in LEVELS])[:, None]
        lo, hi = mu - qs * sd, mu + qs * sd
        lo_one = np.stack([cp.lower_bound(mu, sd, lv) for lv in LEVELS])
    point = np.maximum(mu, floor)
    lo, hi = np.minimum(lo, mu), np.maximum(hi, mu)
    _, ok, sd_ood = ood_sd(model, table[[c for c in table.columns if c not in _PRED_COLUMNS]],
                           mu, sd, raw.physics_draws_kwh.var(axis=0))
    z2, z1 = ndtri(0.5 + LEVELS / 2.0)[:, None], ndtri(LEVELS)[:, None]
    lo = np.where(ok, lo, np.minimum(lo, mu - z2 * sd_ood))
    hi = np.where(ok, hi, np.maximum(hi, mu + z2 * sd_ood))
    lo_one = np.where(ok, lo_one, np.minimum(lo_one, mu - z1 * sd_ood))
    lo, hi, lo_one = (np.maximum(a, floor) for a in (lo, hi, lo_one))
    lo_one = np.minimum(lo_one, point)
    means, stds, w = dist.components()  # spread factor of DIST_LEVEL when conformal
    share = float(np.median(raw.physics_draws_kwh.var(axis=0) / np.maximum(sd, 1e-12) ** 2))
    return Bands(point, np.where(ok, sd, np.maximum(sd, sd_ood)), lo, hi, lo_one,
                 crps=M.crps_mixture(y, means, stds, w), nll=M.gaussian_nll(y, mu, dist.std()),
                 phys_share=share, in_domain=ok)


def check_against_predict_interval(model, trips: pd.DataFrame, b: Bands, seed: int,
                                   capacity_kwh: float) -> None:
    """Assert that ``b`` equals ``model.predict_interval`` at :data:`TABLE_LEVELS`."""
    s_lo, s_hi = soc_bounds(b, trips["soc_initial"].to_numpy(float), capacity_kwh)
    for lv in TABLE_LEVELS:
        i = int(np.flatnonzero(np.isclose(LEVELS, lv))[0])
        out = model.predict_interval(trips, lv, seed=seed)
        pairs = {"energy_kwh_pred": b.mu, "energy_kwh_lo": b.lo[i], "energy_kwh_hi": b.hi[i],
                 "soc_final_lo": s_lo[i], "soc_final_hi": s_hi[i], "confidence": b.conf}
        for col, mine in pairs.items():
            if not np.allclose(out[col].to_numpy(float), mine, rtol=1e-6, atol=1e-7):
                raise RuntimeError(f"bands differ from predict_interval in {col} at level {lv}: "
                                   "hybridev's interval rule changed; update uq_methods")


def _posterior_draws(post, trips: pd.DataFrame, seed: int) -> np.ndarray:
    return post.predictive(post.stats_for(trips), N_POSTERIOR_PREDICTIVE, seed)  # (S, n)


def posterior_conformal(post, cal_trips: pd.DataFrame, seed: int) -> NormalizedConformal:
    """Normalised conformal scores of the posterior predictive mean/sd on calibration trips."""
    e = _posterior_draws(post, cal_trips, seed)
    return NormalizedConformal.fit(cal_trips["energy_kwh"].to_numpy(float), e.mean(0),
                                   e.std(0, ddof=1))


def posterior_bands(post, trips: pd.DataFrame, y: np.ndarray, seed: int,
                    cp: NormalizedConformal | None = None) -> Bands:
    """Physics posterior predictive (parameters + inferred relative noise), optionally conformal."""
    e = _posterior_draws(post, trips, seed)
    mu, sd = e.mean(0), e.std(0, ddof=1)
    if cp is None:
        q = np.quantile(e, np.r_[(1 - LEVELS) / 2, (1 + LEVELS) / 2, 1 - LEVELS], axis=0)
        lo, hi, lo_one = np.split(q, 3)
        f = 1.0
    else:
        qs = np.array([cp.quantile(lv) for lv in LEVELS])[:, None]
        lo, hi = mu - qs * sd, mu + qs * sd
        lo_one = np.stack([cp.lower_bound(mu, sd, lv) for lv in LEVELS])
        f = cp.spread_factor(DIST_LEVEL)
    samples = (mu + f * (e - mu)).T
    return Bands(mu, sd, *_floor(lo, hi, lo_one), crps=M.crps_samples(y, samples),
                 nll=M.gaussian_nll(y, mu, f * sd))


def point_bands(yhat: np.ndarray, cp: NormalizedConformal) -> Bands:
    """Constant-width split conformal around a point prediction (scores ``|y - yhat|``)."""
    one = np.ones_like(yhat)
    qs = np.array([cp.quantile(lv) for lv in LEVELS])[:, None]
    lo_one = np.stack([cp.lower_bound(yhat, one, lv) for lv in LEVELS])
    return Bands(yhat, None, *_floor(yhat - qs, yhat + qs, lo_one))


def evaluate(b: Bands, test: pd.DataFrame, capacity_kwh: float) -> tuple[dict, dict]:
    """Scalar metrics and reliability curves of ``b`` on measured ``test`` trips."""
    y = test["energy_kwh"].to_numpy(float)
    soc = test["soc_final"].to_numpy(float)
    s_lo, s_hi = soc_bounds(b, test["soc_initial"].to_numpy(float), capacity_kwh)
    out = {"mape": M.mape(y, b.mu), "mae": M.mae(y, b.mu), "rmse": M.rmse(y, b.mu),
           "crps": b.crps, "nll": b.nll, "phys_share": b.phys_share,
           "bias_rel": float(np.median(b.mu / y - 1.0))}
    for lv in TABLE_LEVELS:
        i = int(np.flatnonzero(np.isclose(LEVELS, lv))[0])
        k = round(100 * lv)
        out[f"cov_e{k}"] = M.coverage(y, b.lo[i], b.hi[i])
        out[f"width_e{k}"] = M.mean_width(b.lo[i], b.hi[i])
        out[f"winkler_e{k}"] = M.winkler_score(y, b.lo[i], b.hi[i], lv)
        out[f"below_e{k}"] = float(np.mean(y < b.lo[i]))  # asymmetry of the misses
        out[f"above_e{k}"] = float(np.mean(y > b.hi[i]))
        out[f"cov_s{k}"] = M.coverage(soc, s_lo[i], s_hi[i])
        out[f"width_s{k}"] = M.mean_width(s_lo[i], s_hi[i])
    out["mca_e"] = M.miscalibration_area(y, (b.lo, b.hi), LEVELS)
    out["mca_s"] = M.miscalibration_area(soc, (s_lo, s_hi), LEVELS)
    # width when each method's interval shape mu +- k s is rescaled on the test set itself to
    # exactly the nominal coverage (an oracle comparison of how well s adapts, not a method)
    scale = np.ones_like(b.mu) if b.conf is None else b.conf
    score = np.abs(y - b.mu) / scale
    for lv in TABLE_LEVELS:
        k = float(np.quantile(score, lv, method="higher"))
        out[f"eqwidth_e{round(100 * lv)}"] = float(np.mean(2.0 * k * scale))
    # final SoC has a point mass at 0 (battery emptied); the one-sided rule serves those trips
    s0 = test["soc_initial"].to_numpy(float)
    out["frac_soc0"] = float(np.mean(soc == 0.0))
    for lv in (0.5, 0.9):
        i = int(np.flatnonzero(np.isclose(LEVELS, lv))[0])
        k = round(100 * lv)
        one = b.hi[i] >= s0 * capacity_kwh
        inside = (s_lo[i] <= soc) & (soc <= s_hi[i])
        out[f"frac_onesided{k}"] = float(one.mean())
        out[f"cov_s{k}_onesided"] = float(inside[one].mean()) if one.any() else float("nan")
        out[f"cov_s{k}_twosided"] = float(inside[~one].mean()) if (~one).any() else float("nan")
    if b.conf is not None:
        for rel, tag in ((False, "abs"), (True, "rel")):
            out[f"spearman_{tag}"] = M.spearman_confidence(y, b.mu, b.conf, relative=rel)
            out[f"auroc_{tag}"] = M.auroc_worst(y, b.mu, b.conf, worst_frac=0.1, relative=rel)
        ratio = b.conf / np.maximum(b.mu, 1e-9)  # relative confidence vs relative error
        out["spearman_relrel"] = M.spearman_confidence(y, b.mu, ratio, relative=True)
        out["auroc_relrel"] = M.auroc_worst(y, b.mu, ratio, worst_frac=0.1, relative=True)
    curves = {"energy": M.reliability_curve(y, (b.lo, b.hi), LEVELS).empirical,
              "soc": M.reliability_curve(soc, (s_lo, s_hi), LEVELS).empirical}
    return out, curves
