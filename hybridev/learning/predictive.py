"""The predictive distribution of trip energy.

The probabilistic hybrid model describes the energy of each trip as

``E = E_p(theta) + dE_m + sigma_m(x) * z``,

* ``theta`` a draw from the physics posterior (shared by all trips of one
  vehicle: when the drag area is higher than thought, it is higher on every
  trip),
* ``m`` an ensemble member, with residual mean ``dE_m(x)`` and noise scale
  ``sigma_m(x)`` (also shared across trips: epistemic),
* ``z`` standard normal noise, independent between trips (aleatoric),
* and a conformal factor that rescales the spread so that coverage holds on
  exchangeable data.

:class:`EnergyDistribution` holds these pieces for a batch of trips. Its
*marginal* per-trip law is the Gaussian mixture over members

``sum_m w_m N(mean_phys + dE_m, sqrt(var_phys + sigma_m^2))``

(the physics draws moment-matched per trip: with hundreds of calibration trips
the posterior is tight and energy is close to linear in the parameters). Its
*joint* law across trips, used for anything summed over several trips
(charging schedules, cumulative SoC), is sampled by :meth:`sample`, which
keeps the physics draw and member common to all trips of one sample.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hybridev.learning.physical import soc_from_energy
from hybridev.learning.steps import RawPrediction
from hybridev.metrics.mixture import mixture_quantile

__all__ = ["EnergyDistribution", "build_distribution", "raw_prediction", "soc_from_energy"]

_MIN_STD_KWH = 1e-9
"""Width given to zero-variance mixture components when computing quantiles, kWh."""


@dataclass(frozen=True)
class EnergyDistribution:
    """Predictive distribution of the energy of ``n_trips`` trips, kWh.

    Parameters
    ----------
    physics_draws_kwh : numpy.ndarray, shape (n_draws, n_trips), kWh
        Physics energy under each posterior draw (``n_draws=1`` and the
        nominal physics when the model has no posterior).
    residual_mean_kwh : numpy.ndarray, shape (n_members, n_trips), kWh
        Each ensemble member's residual mean ``dE_m``.
    residual_std_kwh : numpy.ndarray, shape (n_members, n_trips), kWh
        Each member's aleatoric noise scale ``sigma_m`` (zeros for a
        point network without variance head).
    spread_factor : float or numpy.ndarray, shape (n_trips,)
        Conformal factor applied to all spread (physics and residual
        deviations from their centre); 1 means uncalibrated. Per trip when
        some trips are out of the training domain (their spread is widened).

    Examples
    --------
    >>> d = EnergyDistribution(np.array([[10.0, 20.0]]), np.zeros((2, 2)), np.ones((2, 2)))
    >>> d.mean().tolist()
    [10.0, 20.0]
    >>> d.sample(4, np.random.default_rng(0)).shape
    (4, 2)
    """

    physics_draws_kwh: np.ndarray
    residual_mean_kwh: np.ndarray
    residual_std_kwh: np.ndarray
    spread_factor: float = 1.0
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        p = np.asarray(self.physics_draws_kwh, float)
        mu = np.asarray(self.residual_mean_kwh, float)
        sd = np.asarray(self.residual_std_kwh, float)
        if p.ndim != 2 or mu.ndim != 2 or mu.shape != sd.shape or mu.shape[1] != p.shape[1]:
            raise ValueError(
                "EnergyDistribution needs physics_draws_kwh (n_draws, n_trips) and residual "
                f"mean/std (n_members, n_trips); got {p.shape}, {mu.shape}, {sd.shape}")
        c = np.asarray(self.spread_factor, float)
        if not (c.ndim == 0 or c.shape == (p.shape[1],)) or not (
                np.all(np.isfinite(c)) and np.all(c > 0)):
            raise ValueError(f"spread_factor={self.spread_factor!r} must be finite and > 0, "
                             f"a number or one per trip ({p.shape[1]})")
        object.__setattr__(self, "spread_factor", float(c) if c.ndim == 0 else c)
        object.__setattr__(self, "physics_draws_kwh", p)
        object.__setattr__(self, "residual_mean_kwh", mu)
        object.__setattr__(self, "residual_std_kwh", sd)

    @property
    def n_trips(self) -> int:
        return self.physics_draws_kwh.shape[1]

    def components(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Marginal mixture ``(means (n_trips, K), stds (n_trips, K), weights (K,))``.

        Spreads are scaled by ``spread_factor`` about the mixture mean.
        """
        if "comp" not in self._cache:
            p_mean = self.physics_draws_kwh.mean(axis=0)
            p_var = self.draws_var()
            means = (p_mean[None, :] + self.residual_mean_kwh).T
            var = (p_var[None, :] + self.residual_std_kwh**2).T
            k = means.shape[1]
            c = np.reshape(self.spread_factor, (-1, 1)) if np.ndim(self.spread_factor) else \
                self.spread_factor
            centre = means.mean(axis=1, keepdims=True)
            means = centre + c * (means - centre)
            stds = c * np.sqrt(var)
            self._cache["comp"] = (means, stds, np.full(k, 1.0 / k))
        return self._cache["comp"]

    def draws_var(self) -> np.ndarray:
        """Variance of the physics draws per trip, shape (n_trips,), kWh^2 (computed once)."""
        if "p_var" not in self._cache:
            self._cache["p_var"] = self.physics_draws_kwh.var(axis=0)
        return self._cache["p_var"]

    def mean(self) -> np.ndarray:
        """Predictive mean energy per trip, shape (n_trips,), kWh."""
        means, _, w = self.components()
        return means @ w

    def std(self) -> np.ndarray:
        """Predictive standard deviation per trip, shape (n_trips,), kWh."""
        means, stds, w = self.components()
        m = means @ w
        return np.sqrt(((stds**2 + means**2) @ w) - m**2).clip(min=0.0)

    def excess_var(self) -> np.ndarray:
        """Predictive variance beyond the physics draws' own, shape (n_trips,), kWh^2.

        ``std()**2 - var(physics draws)`` computed from its parts (members'
        noise and spread, and the spread factor ``c``) instead of by
        subtraction, which loses the digits when the draws dominate:
        ``(c^2 - 1) var_p + c^2 (mean_m sigma_m^2 + var_m dE_m)``, at least 0.

        Examples
        --------
        >>> d = EnergyDistribution(np.array([[1.0, 2.0], [3.0, 2.0]]),
        ...                        np.array([[0.0, 0.0], [2.0, 0.0]]), np.ones((2, 2)))
        >>> d.excess_var().tolist()
        [2.0, 1.0]
        >>> (d.std() ** 2 - d.physics_draws_kwh.var(axis=0)).round(12).tolist()  # the same
        [2.0, 1.0]
        """
        c2 = np.asarray(self.spread_factor, float) ** 2
        p_var = self.draws_var()
        rest = (self.residual_std_kwh**2).mean(axis=0) + self.residual_mean_kwh.var(axis=0)
        return np.maximum((c2 - 1.0) * p_var + c2 * rest, 0.0)

    def quantile(self, q) -> np.ndarray:
        """Marginal quantiles of energy, shape ``np.shape(q) + (n_trips,)``, kWh."""
        means, stds, w = self.components()
        # point components (no variance head, no posterior) get a negligible width
        return mixture_quantile(means, np.maximum(stds, _MIN_STD_KWH), w, q)

    def interval(self, level: float) -> tuple[np.ndarray, np.ndarray]:
        """Central interval of the given confidence ``level`` per trip, kWh."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
        lo, hi = self.quantile([(1.0 - level) / 2.0, (1.0 + level) / 2.0])
        return lo, hi

    def sample(self, n_samples: int, rng: np.random.Generator | int | None = None
               ) -> np.ndarray:
        """Joint samples of all trips' energies, shape (n_samples, n_trips), kWh.

        Each sample uses one physics draw and one member for every trip (the
        correlated, epistemic part) and independent noise per trip.
        """
        rng = np.random.default_rng(rng)
        n_draws = self.physics_draws_kwh.shape[0]
        n_members = self.residual_mean_kwh.shape[0]
        d = rng.integers(0, n_draws, n_samples)
        m = rng.integers(0, n_members, n_samples)
        means, _, w = self.components()
        centre = (means @ w)[None, :]
        raw = (self.physics_draws_kwh[d] + self.residual_mean_kwh[m]
               + self.residual_std_kwh[m] * rng.standard_normal((n_samples, self.n_trips)))
        return centre + self.spread_factor * (raw - centre)


def build_distribution(physics_draws_kwh: np.ndarray, energy_physics_kwh: np.ndarray,
                       residual_mean_kwh: np.ndarray, residual_var_kwh2: np.ndarray | None,
                       *, residual: bool = True) -> EnergyDistribution:
    """The raw (spread factor 1) predictive distribution from its parts.

    Parameters
    ----------
    physics_draws_kwh : numpy.ndarray, shape (n_draws, n_trips), kWh
        Physics energies of the posterior draws; centred on their mean and moved to
        ``energy_physics_kwh`` (the posterior median the networks were trained
        against). ``residual=False`` (``PureML``): no physics part (zeros).
    energy_physics_kwh : numpy.ndarray, shape (n_trips,), kWh
    residual_mean_kwh, residual_var_kwh2 : numpy.ndarray, shape (n_members, n_trips)
        The members' residual means (kWh) and noise variances (kWh^2; None: no noise).
    """
    mean = residual_mean_kwh
    std = np.zeros_like(mean) if residual_var_kwh2 is None else np.sqrt(residual_var_kwh2)
    if not residual:
        centred = np.zeros_like(physics_draws_kwh)
    else:
        centred = physics_draws_kwh - physics_draws_kwh.mean(axis=0)
        centred += energy_physics_kwh
    return EnergyDistribution(centred, mean, std)


def raw_prediction(table, dists: list[EnergyDistribution], mode_means=None, *,
                   physics=None, columns=None) -> RawPrediction:
    """The :class:`~hybridev.learning.steps.RawPrediction` of the fitted model's
    distribution ``dists[0]`` and the CV+ folds' ``dists[1:]``, with the moments the
    calibrator and the out-of-domain step read. ``physics``: physics columns still to
    append to ``table``; ``columns``: the physics table's columns as arrays."""
    dist, folds = dists[0], dists[1:]
    return RawPrediction(
        base=table, physics=dict(physics or {}), columns=columns,
        dist=dist, folds=folds, mode_means=mode_means, mean=dist.mean(),
        std=dist.std(),
        fold_means=np.stack([d.mean() for d in folds]) if folds else None,
        fold_stds=(np.maximum(np.stack([d.std() for d in folds]), 1e-12) if folds else None),
        var_draws=dist.draws_var(), excess_var=dist.excess_var())
