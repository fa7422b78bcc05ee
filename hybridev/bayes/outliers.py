"""Which measured trips the calibration treats as outliers, and why.

After sampling, :func:`hybridev.bayes.sampler.calibrate_physics` evaluates every
trip at the posterior median parameters: the relative residual
``r = y / E - 1`` (``E`` floored at
:data:`~hybridev.bayes.likelihood.PREDICTED_FLOOR_REL` of ``y``, as in the
likelihood), minus its day's shrunken mean effect
``u_g = tau^2 sum_g w r / (sigma^2 + tau^2 sum_g w)`` (the best linear
predictor of the day random effect, with the trips' Student-t weights ``w``
iterated so that an outlier does not shift its day-mates; 0 without groups),
over the noise scale ``sigma``:
the standardized residual ``z``. Under the Student-t likelihood a trip's weight
in the fit is ``w = (nu + 1) / (nu + z^2)`` (1 for a typical trip; the weight of
the iteratively reweighted view of the t, Lange, Little & Taylor 1989), and its
two-sided tail probability is ``p = 2 (1 - T_nu(|z|))``. A trip is an outlier
when ``p < OUTLIER_TAIL_PROB`` or when the physics predicts ``E <= 0``. The
reason names the likely cause from the sign of the residual.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats as sps

from hybridev.bayes.likelihood import PREDICTED_FLOOR_REL
from hybridev.physics.stats import energy_from_stats

__all__ = ["OUTLIER_COLUMNS", "OUTLIER_TAIL_PROB", "attach_outliers", "trip_residuals"]

OUTLIER_TAIL_PROB = 1e-3
"""Two-sided tail probability below which a trip is reported as an outlier (about 1 in
1,000 trips of a model that fits is flagged by chance)."""

OUTLIER_COLUMNS = ["trip_id", "energy_kwh", "predicted_kwh", "residual_rel", "z", "weight",
                   "tail_prob", "outlier", "reason"]
"""Columns of :func:`trip_residuals` and of ``PhysicsPosterior.outliers_``."""


def _reason(pred: float, resid: float, outlier: bool) -> str:
    if pred <= 0:
        return ("physics predicts <= 0 kWh (a descent that regenerates more than the trip "
                "uses at these parameters): check the grades or elevation, the regen limit "
                "and the measured energy")
    if not outlier:
        return ""
    if resid < 0:
        return ("measured energy far below the physics: a charge on the way, a wrong SoC "
                "reading or a trace that does not match the trip?")
    return ("measured energy far above the physics: a wrong SoC reading, an unlogged part of "
            "the trip, a heavy load or a climate load the model does not know?")


def trip_residuals(trip_id, energy_kwh, predicted_kwh, sigma: float, *, group_sd: float = 0.0,
                   groups=None, noise_dof: float | None = None) -> pd.DataFrame:
    """Standardized residual, weight and outlier flag of every trip.

    Parameters
    ----------
    trip_id : array_like, shape (n_trips,)
    energy_kwh : array_like, shape (n_trips,), kWh
        Measured energies (> 0).
    predicted_kwh : array_like, shape (n_trips,), kWh
        Physics energies at the posterior median (may be <= 0).
    sigma : float
        Noise scale of the relative residual within a day (the likelihood's
        ``sigma``, not the total sd).
    group_sd : float
        Scale ``tau`` of the day random effect (0: none).
    groups : array_like of int, shape (n_trips,), optional
        Group code per trip (``None``: independent trips).
    noise_dof : float, optional
        Student-t degrees of freedom (``None``: normal).

    Returns
    -------
    pandas.DataFrame
        :data:`OUTLIER_COLUMNS`, one row per trip in input order.

    Examples
    --------
    >>> t = trip_residuals(["a", "b", "c"], [1.0, 1.0, 1.0], [1.02, 0.97, -0.1], 0.05,
    ...                    noise_dof=4.0)
    >>> t.outlier.tolist(), t.reason.str[:24].tolist()[2]
    ([False, False, True], 'physics predicts <= 0 kW')
    """
    y = np.asarray(energy_kwh, dtype=float)
    e = np.asarray(predicted_kwh, dtype=float)
    r = y / np.maximum(e, PREDICTED_FLOOR_REL * y) - 1.0
    u = np.zeros_like(r)
    if groups is not None and group_sd > 0:
        g = np.asarray(groups, dtype=np.intp)
        w = np.ones_like(r)
        for _ in range(20):  # iteratively reweighted: an outlier does not move its day
            u = (group_sd**2 * np.bincount(g, w * r)
                 / (sigma**2 + group_sd**2 * np.bincount(g, w)))[g]
            if noise_dof is None:
                break
            zz = (r - u) / sigma
            w = (noise_dof + 1.0) / (noise_dof + zz * zz)
    z = (r - u) / sigma
    if noise_dof is None:
        w = np.ones_like(z)
        p = 2.0 * sps.norm.sf(np.abs(z))
    else:
        w = (noise_dof + 1.0) / (noise_dof + z * z)
        p = 2.0 * sps.t.sf(np.abs(z), noise_dof)
    out = (p < OUTLIER_TAIL_PROB) | (e <= 0)
    return pd.DataFrame({
        "trip_id": np.asarray(trip_id, dtype=object), "energy_kwh": y, "predicted_kwh": e,
        "residual_rel": r, "z": z, "weight": w, "tail_prob": p, "outlier": out,
        "reason": [_reason(a, b, c) for a, b, c in zip(e, r, out, strict=True)]},
        columns=OUTLIER_COLUMNS)


def attach_outliers(post, stats, trips: pd.DataFrame, energy_kwh: np.ndarray, groups,
                    noise_dof: float | None) -> None:
    """Residuals of every trip at ``post``'s median; the outliers go to ``post.diagnostics``.

    Sets ``diagnostics["n_outliers"]`` and ``diagnostics["outliers"]`` (a list of
    records with :data:`OUTLIER_COLUMNS`, JSON-able), read by
    ``PhysicsPosterior.outliers_``. ``stats`` are the calibration's statistics,
    ``groups`` its group codes (None: independent trips).
    """
    med = post.median()
    draw = np.array([[med[n] for n in post.param_names]])
    e = energy_from_stats(stats, post.as_params(draw))[0]
    d = post.diagnostics
    sigma = d.get("sigma_within", med["noise_rel"])
    tau = d.get("group_sd", 0.0) if groups is not None else 0.0
    if noise_dof is not None:  # back from the reported sds to the t's scales
        sigma, tau = (x * np.sqrt((noise_dof - 2.0) / noise_dof) for x in (sigma, tau))
    ids = trips["trip_id"].to_numpy(object) if "trip_id" in trips.columns else trips.index
    res = trip_residuals(ids, energy_kwh, e, sigma, group_sd=tau, groups=groups,
                         noise_dof=noise_dof)
    flagged = res[res["outlier"]]
    d["n_outliers"] = len(flagged)
    d["outliers"] = [{k: (v.item() if hasattr(v, "item") else v) for k, v in row.items()}
                     for row in flagged.to_dict(orient="records")]
