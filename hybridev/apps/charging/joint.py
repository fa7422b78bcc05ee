"""Joint scenarios of a schedule's trips with the trip-to-trip error correlation the data show.

A charging plan's risk is about *sums* of trip energies (the energy used between
two charging opportunities), so it depends on how the trips' errors co-vary, not
only on each trip's spread. The predictive distribution
(:class:`hybridev.learning.predictive.EnergyDistribution`) has a structural answer:
its physics posterior draw and ensemble member are common to every trip of a
scenario, its members' noise is independent per trip, and the conformal factor
scales both. Each trip's *total* spread is calibrated (the conformal step), but
the split between the shared and the independent part is not: on the charging
study (``evaluation/charging_risk``) the posterior draw alone gave the week's total
energy a spread about three times the scatter of the model's weekly error between
refits, as the networks absorb much of what a different physics draw would change.

This module measures the split from the data instead and samples with it:

* :func:`shared_fraction`: the intra-class correlation of the normalised
  out-of-sample calibration scores ``z_i = (E_i - mu_i) / s_i`` within the groups
  of trips that one fitted model scored, ``rho = sum_g (S_g^2 - Q_g) /
  sum_g n_g (n_g - 1) / mean(z^2)`` (``S_g``, ``Q_g`` the group's sum and sum of
  squares): the average product of two different trips' errors scored by the same
  model, over the average square. With CV+ scores (``K`` fold models) each fold is a
  group, so the shared error is seen ``K`` times; with split-conformal scores (one
  model) it is seen once (the held-out trips' common offset), a noisy estimate of
  this model's own offset. Clipped to [0, 1].
* :func:`model_shared_fraction`: that estimate from a fitted model's scores: the
  planned-trip scores (``planned_``, trips predicted from their summaries, as a
  schedule's trips are) when the model has them, else its conformal scores.
* :func:`joint_samples`: joint scenarios that keep every trip's mean and variance
  (and the structure of the model's shared part: which trips a posterior draw moves
  together) while the shared part of each trip's variance is ``rho``: the shared
  deviation (posterior draw and member) and the independent one (members' noise)
  are each scaled to unit variance per trip and recombined as ``sqrt(rho) shared +
  sqrt(1 - rho) independent``, times the calibrated spread. A trip without a shared
  (or independent) part gets a common (or own) standard normal one.
"""

from __future__ import annotations

import numpy as np

from hybridev.core.checks import check_seed
from hybridev.learning.predictive import EnergyDistribution

__all__ = ["check_correlation", "check_count", "check_distribution", "joint_samples",
           "model_shared_fraction", "sample_streams", "scenarios", "shared_fraction"]


def shared_fraction(scores, groups=None) -> float:
    """Share of a trip's error variance common to the trips one model scored, in [0, 1].

    Parameters
    ----------
    scores : array_like, shape (n,)
        Signed normalised out-of-sample scores ``(E - mu) / s`` (finite).
    groups : array_like of int, shape (n,), optional
        The model that scored each trip (e.g. the CV+ fold); default one model.

    Returns
    -------
    float
        ``sum_g (S_g^2 - Q_g) / sum_g n_g (n_g - 1)`` over ``mean(z^2)``, clipped to
        [0, 1]; 0 when no group has two scores or every score is 0.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> shared = np.repeat(rng.normal(0, 0.5, 200), 50)   # 200 models, 50 trips each
    >>> z = shared + rng.normal(0, np.sqrt(0.75), shared.size)
    >>> round(shared_fraction(z, np.repeat(np.arange(200), 50)), 2)   # 0.25 / 1.0
    0.25
    >>> shared_fraction(rng.normal(size=1000))   # independent errors, one model
    0.0
    """
    z = np.asarray(scores, float).ravel()
    if not np.all(np.isfinite(z)):
        raise ValueError("scores must be finite")
    g = np.zeros(z.size, np.int64) if groups is None else np.asarray(groups).ravel()
    if g.shape != z.shape:
        raise ValueError(f"groups must have one value per score ({z.size}); got {g.shape}")
    _, code = np.unique(g, return_inverse=True)
    n_g = np.bincount(code).astype(float)
    s_g = np.bincount(code, weights=z)
    q_g = np.bincount(code, weights=z * z)
    pairs = float((n_g * (n_g - 1.0)).sum())
    msq = float(q_g.sum()) / max(z.size, 1)
    if pairs <= 0 or msq <= 0:
        return 0.0
    cov = float((s_g**2 - q_g).sum()) / pairs
    return float(np.clip(cov / msq, 0.0, 1.0))


def model_shared_fraction(model) -> float | None:
    """:func:`shared_fraction` of a fitted model's calibration scores (None: it has none).

    The planned-trip scores (``model.planned_.residuals_``) when the model has a
    planned-trip calibrator (a schedule's trips have no trace), else the conformal
    step's (``model.calibrator_.conformal_.residuals``); grouped by CV+ fold when the
    scores are CV+ (``fold``), else one group (the split step's single model).
    """
    cal = getattr(model, "calibrator_", None)
    cp = getattr(cal, "conformal_", None)
    planned = getattr(model, "planned_", None)
    scores = getattr(planned, "residuals_", None) if planned is not None else None
    if scores is None:
        scores = getattr(cp, "residuals", None)
    if scores is None:
        return None
    scores = np.asarray(scores, float)
    fold = getattr(cp, "fold", None)
    groups = fold if fold is not None and np.shape(fold) == scores.shape else None
    return shared_fraction(scores, groups) if scores.size >= 2 else None


def joint_samples(dist, n_samples: int, rng, rho: float) -> np.ndarray:
    """Joint energy scenarios with shared fraction ``rho``, shape (n_samples, n_trips), kWh.

    Parameters
    ----------
    dist : EnergyDistribution
        The trips' predictive distribution (its spread factor applied).
    n_samples : int
    rng : numpy.random.Generator or int
    rho : float
        Share of each trip's variance common to all trips of a scenario, [0, 1].

    Examples
    --------
    >>> from hybridev.learning.predictive import EnergyDistribution
    >>> d = EnergyDistribution(np.array([[9.0, 9.0], [11.0, 11.0]]), np.zeros((1, 2)),
    ...                        np.ones((1, 2)))
    >>> x = joint_samples(d, 100000, 0, 0.2)
    >>> x.mean(axis=0).round(1).tolist(), x.std(axis=0).round(1).tolist()
    ([10.0, 10.0], [1.4, 1.4])
    >>> round(float(np.corrcoef(x.T)[0, 1]), 2)
    0.2
    """
    r = float(rho)
    if not 0.0 <= r <= 1.0:
        raise ValueError(f"trip_correlation={rho!r} is outside the allowed range [0, 1]")
    rng = np.random.default_rng(rng)
    p, mu, sd = dist.physics_draws_kwh, dist.residual_mean_kwh, dist.residual_std_kwh
    k = dist.n_trips
    d = rng.integers(0, p.shape[0], n_samples)
    m = rng.integers(0, mu.shape[0], n_samples)
    z = rng.standard_normal((n_samples, k))
    u = rng.standard_normal((n_samples, 1))
    centre = p.mean(axis=0) + mu.mean(axis=0)
    v_a = p.var(axis=0) + mu.var(axis=0)
    v_b = (sd**2).mean(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(v_a > 0, (p[d] + mu[m] - centre) / np.sqrt(v_a), u)
        b = np.where(v_b > 0, sd[m] * z / np.sqrt(v_b), z)
    scale = np.asarray(dist.spread_factor, float) * np.sqrt(v_a + v_b)
    return centre + scale * (np.sqrt(r) * a + np.sqrt(1.0 - r) * b)


def sample_streams(seed) -> tuple[np.random.Generator, np.random.Generator]:
    """Two independent generators of ``seed``: the calibration and the evaluation samples."""
    cal, ev = np.random.default_rng(check_seed(seed)).spawn(2)
    return cal, ev


def scenarios(dist: EnergyDistribution, n: int, rng, perm, rho=None) -> np.ndarray:
    """Joint samples in departure order: the model's own joint law (``rho`` None) or
    :func:`~hybridev.apps.charging.joint.joint_samples` with shared fraction ``rho``."""
    return (dist.sample(n, rng) if rho is None else joint_samples(dist, n, rng, rho))[:, perm]


def check_correlation(value) -> float | None:
    """``trip_correlation`` checked: None or a number in [0, 1]."""
    if value is None:
        return None
    try:
        r = float(value)
    except (TypeError, ValueError):
        r = float("nan")
    if isinstance(value, bool) or not 0.0 <= r <= 1.0:
        raise ValueError(f"trip_correlation={value!r} is outside the allowed range [0, 1] "
                         "(or None, or \"auto\" with a model)")
    return r


def check_distribution(dist, problem) -> None:
    """ValueError unless ``dist`` is an EnergyDistribution of ``problem.n_trips`` trips."""
    if not isinstance(dist, EnergyDistribution):
        raise ValueError(f"dist must be an EnergyDistribution; got {type(dist).__name__}")
    if dist.n_trips != problem.n_trips:
        raise ValueError(f"the distribution has {dist.n_trips} trips but the schedule has "
                         f"{problem.n_trips}")


def check_count(name: str, value, lo: int) -> int:
    """``value`` as an int, ValueError naming ``name`` unless it is an integer >= ``lo``."""
    try:
        ok = not isinstance(value, bool) and int(value) == value and value >= lo
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ValueError(f"{name}={value!r} is outside the allowed range [{lo}, inf) (integers)")
    return int(value)
