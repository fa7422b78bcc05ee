"""Semantic validation of a loaded model: beyond checksums, does it make sense?

The manifest's SHA-256 sums (:mod:`hybridev.learning.persist`) prove that the
files are those hybridev wrote, or that someone re-signed them. They do not
prove that the model is sound: a hand-edited ``model.json`` with its manifest
recomputed, or a buggy writer, can carry ``target_std = 1e300`` or NaN domain
bounds and predict NaN for every trip. :func:`check_model_sanity` runs before
``HybridModel.load`` returns and refuses such a model with a ``ValueError``
naming the file and the field:

* the vehicle within the limits :class:`~hybridev.VehicleParams` accepts, and the
  vehicle the physics posterior was calibrated on (all but the battery capacity);
* every array finite (the discrepancy's upper bounds may be ``+inf``), the
  network weights (ensemble and CV+ folds) at most :data:`MAX_ABS_WEIGHT` in
  size, the feature scales positive and at least :data:`MIN_FEATURE_STD`;
* ``target_std`` in ``(0, MAX_TARGET_SCALE]``, ``|target_mean| <=
  MAX_TARGET_SCALE``;
* posterior draws (main and CV+ folds) inside their priors' support and the
  vehicle limits (:data:`DRAW_LIMITS`), relative noise in ``(0, 1]``, mode
  weights a probability vector per draw;
* conformal scores finite and their fold and bin indices in range;
* the training domain's values sorted and its feature bounds ordered;
* a smoke prediction on :data:`REFERENCE_TRIP` (20 km at 50 km/h, 20 °C) with
  finite point and interval values (``lo <= pred <= hi``) and an energy in
  ``(0, MAX_KWH_PER_KM]`` kWh/km.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings

import numpy as np

__all__ = ["DRAW_LIMITS", "MAX_ABS_WEIGHT", "MAX_KWH_PER_KM", "MAX_TARGET_SCALE",
           "MIN_FEATURE_STD", "REFERENCE_TRIP", "check_model_sanity"]

MAX_ABS_WEIGHT = 1e3
"""Largest network weight or bias accepted (trained members stay below about 10)."""
MAX_TARGET_SCALE = 1e3
"""Largest ``target_std`` and ``|target_mean|`` accepted (relative residuals are O(0.1),
absolute ones a few kWh)."""
MIN_FEATURE_STD = 1e-9
"""Smallest feature scale accepted (smaller would blow a standardised input up)."""
MAX_KWH_PER_KM = 2.0
"""Largest energy per km accepted on the reference trip (a 40 t electric truck spends
about 1.3 kWh/km; no battery vehicle on a flat 50 km/h trip spends 2)."""
REFERENCE_TRIP = {"trip_id": 0, "distance_km": 20.0, "avg_speed_kmh": 50.0,
                  "mode": "normal", "temperature_c": 20.0, "soc_initial": 0.8, "hour": 8.0}
"""The trip of the smoke prediction: flat, mild, mid-speed."""

_POSITIVE = (0.0, math.inf, True)  # lo, hi, lo open
DRAW_LIMITS: dict[str, tuple[float, float, bool]] = {
    "drag_area_m2": (0.0, 40.0, True),            # C_d <= 2 on up to 20 m^2 (VehicleParams)
    "rolling_resistance_coef": (0.0, 0.1, True),
    "linear_drag_n_per_mps": (0.0, 1000.0, False),
    "aux_base_kw": (0.0, 50.0, True),
    "drive_loss_kw": (0.0, 50.0, True),
    "regen_scale": (0.0, 10.0, False),
    "hvac_scale": (0.0, 100.0, True),
    "warmup_scale": (0.0, 100.0, True),
    "heating_scale": (0.0, 100.0, True),
    "cooling_scale": (0.0, 100.0, True),
}
"""Support of each sampled parameter (lo, hi, lo open): the priors' lognormal and
truncated supports intersected with :class:`~hybridev.VehicleParams`' limits;
``drivetrain_efficiency`` and ``heating_offset_k`` use the saved prior's bounds."""


def _fail(where: str, field: str, msg: str) -> ValueError:
    return ValueError(f"{where}: {field} {msg}; the model does not make sense "
                      "(edited or damaged file): re-fit it")


def _finite(where, field, a, *, allow_inf_above=False) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == bool or a.size == 0:
        return a
    x = a.astype(float)
    bad = np.isnan(x) | (np.isneginf(x)) | (np.isposinf(x) & (not allow_inf_above))
    if bad.any():
        i = int(np.flatnonzero(bad.ravel())[0])
        raise _fail(where, field, f"has a non-finite value {x.ravel()[i]!r} at flat index {i}")
    return x


def _range(where, field, x, lo, hi, lo_open=False):
    x = np.asarray(x, float).ravel()
    if x.size == 0:
        return
    bad = (x <= lo if lo_open else x < lo) | (x > hi) | np.isnan(x)
    if bad.any():
        v = float(x[np.flatnonzero(bad)[0]])
        raise _fail(where, field, f"= {v:.6g} is outside the allowed range "
                                  f"{'(' if lo_open else '['}{lo:g}, {hi:g}]")


def _posterior(where: str, prefix: str, post) -> None:
    from hybridev.bayes.priors import PhysicsPrior

    prior = post.prior or {}
    default = PhysicsPrior()
    eff = tuple(prior.get("efficiency_bounds", default.efficiency_bounds))
    off = tuple(prior.get("heating_offset_bounds_k", default.heating_offset_bounds_k))
    s = _finite(where, f"{prefix}posterior_samples", post.samples)
    for j, name in enumerate(post.param_names):
        field = f"{prefix}posterior_samples[:, {j}] ({name})"
        if name == "drivetrain_efficiency":
            _range(where, field, s[:, j], max(float(eff[0]), 0.0), min(float(eff[1]), 1.0),
                   lo_open=True)
        elif name == "heating_offset_k":
            nominal = float(post.vehicle.heating_offset_k)
            _range(where, field, s[:, j], nominal + float(off[0]), nominal + float(off[1]))
        else:
            lo, hi, lo_open = DRAW_LIMITS.get(name, _POSITIVE)
            _range(where, field, s[:, j], lo, hi, lo_open)
    _range(where, f"{prefix}posterior_noise_rel",
           _finite(where, f"{prefix}posterior_noise_rel", post.noise_rel), 0.0, 1.0, True)
    if post.mode_weights is not None:
        w = _finite(where, f"{prefix}posterior_mode_weights", post.mode_weights)
        _range(where, f"{prefix}posterior_mode_weights", w, 0.0, 1.0)
        if np.any(np.abs(w.sum(axis=1) - 1.0) > 1e-3):
            raise _fail(where, f"{prefix}posterior_mode_weights", "rows do not sum to 1")
    for v in (post.vehicle, post.reference_vehicle):
        dataclasses.replace(v)  # VehicleParams' own range checks


def _net(where: str, prefix: str, net) -> None:
    for name, a in net.to_arrays().items():
        x = _finite(where, f"{prefix}{name}", a)
        _range(where, f"{prefix}{name}", np.abs(x), 0.0, MAX_ABS_WEIGHT)


def _discrepancy(where: str, prefix: str, disc) -> None:
    if disc is None:
        return
    for name, a in disc.to_arrays().items():
        _finite(where, f"{prefix}discrepancy.{name}", a, allow_inf_above=(name == "upper"))


def _arrays(model, where: str) -> None:
    veh = model._vehicle()
    try:
        dataclasses.replace(veh)
    except ValueError as exc:
        raise _fail(where, "vehicle", str(exc)) from None
    if hasattr(model, "net_"):
        tm, ts = float(model.target_mean_), float(model.target_std_)
        _range(where, "learner.target_std", ts, 0.0, MAX_TARGET_SCALE, lo_open=True)
        _range(where, "learner.target_mean", abs(tm), 0.0, MAX_TARGET_SCALE)
        _range(where, "learner.feature_mean", np.abs(_finite(where, "learner.feature_mean", model.feature_mean_)),
               0.0, 1e12)
        _range(where, "learner.feature_std", _finite(where, "learner.feature_std", model.feature_std_),
               MIN_FEATURE_STD, 1e12)
        _net(where, "learner.net.", model.net_)
    for k, net in enumerate(getattr(model, "cv_nets_", None) or []):
        _net(where, f"calibrator.cv{k}.", net)
    post = getattr(model, "posterior_", None)
    if post is not None:
        _posterior(where, "physics.", post)
        fields = [f.name for f in dataclasses.fields(veh)
                  if f.name not in ("battery_capacity_kwh", "source", "heater_kind")]
        diff = [f for f in fields if getattr(veh, f) != getattr(post.vehicle, f)]
        if diff:
            f = diff[0]
            raise _fail(where, f"vehicle.{f}", f"= {getattr(veh, f)!r} differs from the "
                        f"vehicle the physics posterior was calibrated on "
                        f"({getattr(post.vehicle, f)!r})")
    _discrepancy(where, "physics.", getattr(model, "discrepancy_", None))
    for k, (p, d) in enumerate(getattr(model, "cv_physics_", None) or []):
        _posterior(where, f"calibrator.cv{k}.", p)
        _discrepancy(where, f"calibrator.cv{k}.", d)
    cp = getattr(model, "conformal_", None)
    if cp is not None:
        r = _finite(where, "calibrator.conformal_residuals", cp.residuals)
        if r.size == 0:
            raise _fail(where, "calibrator.conformal_residuals", "is empty")
        fold = getattr(cp, "fold", None)
        if fold is not None:
            n = len(getattr(model, "cv_nets_", None) or [])
            _range(where, "calibrator.conformal_fold", fold, 0, max(n - 1, 0))
    bins = getattr(model, "conformal_bins_", None)
    if bins is not None:
        _range(where, "calibrator.mondrian_cut_km", getattr(model, "mondrian_cut_km_", 1.0), 0.0, 1e6,
               lo_open=True)
        _range(where, "calibrator.conformal_bins", bins, 0, 1e6)
    dom = getattr(model, "domain_", None)
    if dom is not None:
        for j, v in enumerate(dom.values):
            v = _finite(where, f"domain.q{j}", v)
            if np.any(np.diff(v) < 0):
                raise _fail(where, f"domain.q{j}", "is not sorted")
        lo = _finite(where, "domain.feature_lo", dom.feature_lo)
        hi = _finite(where, "domain.feature_hi", dom.feature_hi)
        if lo.shape != hi.shape or np.any(lo > hi):
            raise _fail(where, "domain.feature_lo/feature_hi", "are not ordered (lo <= hi)")


def _smoke(model, where: str) -> None:
    import pandas as pd

    trip = pd.DataFrame([REFERENCE_TRIP])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with np.errstate(all="ignore"):
            try:
                # 0.5: every calibration of n >= 1 trips supports it (n / (n + 1))
                out = model.predict_interval(trip, 0.5, seed=0)
                cols = ["energy_kwh_pred", "energy_kwh_lo", "energy_kwh_hi"]
            except ValueError as exc:
                if "spread" not in str(exc) and "interval" not in str(exc):
                    raise
                out, cols = model.predict(trip), ["energy_kwh_pred"]
    vals = out[cols].to_numpy(float)[0]
    soc = out["soc_final_pred"].to_numpy(float) if "soc_final_pred" in out else np.zeros(1)
    if not (np.all(np.isfinite(vals)) and np.all(np.isfinite(soc))):
        raise _fail(where, "the smoke prediction", f"on the reference trip "
                    f"{REFERENCE_TRIP} is not finite ({dict(zip(cols, vals.tolist(), strict=True))})")
    pred = vals[0]
    if len(vals) == 3 and not vals[1] <= pred <= vals[2]:
        raise _fail(where, "the smoke prediction", f"interval [{vals[1]:.4g}, {vals[2]:.4g}] "
                    f"kWh does not hold the prediction {pred:.4g} kWh")
    per_km = pred / REFERENCE_TRIP["distance_km"]
    if not 0.0 < per_km <= MAX_KWH_PER_KM:
        raise _fail(where, "the smoke prediction", f"on a flat 20 km trip at 50 km/h, 20 °C "
                    f"is {per_km:.4g} kWh/km, outside (0, {MAX_KWH_PER_KM:g}] kWh/km")


def check_model_sanity(model, path: str | os.PathLike) -> None:
    """Refuse a loaded model whose values make no sense (``ValueError`` naming file and field).

    Parameters
    ----------
    model : HybridModel
        Just restored by :func:`hybridev.learning.persist.load_model`.
    path : path-like
        Its folder (named in the message with the file that holds the field).
    """
    where = f"{os.fspath(path)!r} (model.json / arrays.npz)"
    try:
        _arrays(model, where)
        _smoke(model, where)
    except ValueError:
        raise
    except (TypeError, AttributeError, IndexError, OverflowError, RuntimeError,
            FloatingPointError) as exc:
        raise ValueError(f"{where}: the model fails its sanity check: "
                         f"{type(exc).__name__}: {exc}") from exc
