"""Noise floors and oracle predictors of the synthetic ground truths.

The best any model can do on a truth with multiplicative noise: the oracle
knows the noiseless energy and predicts the constant multiple of it that
minimises the expected MAPE (or the mean); its error is the noise floor.
"""

from __future__ import annotations

import functools

import numpy as np
import pandas as pd
from scipy import integrate, optimize, stats

from hybridev.physics.params import VehicleParams
from hybridev.physics.truth import (
    MIN_NOISE_FACTOR,
    _check_predictor,
    _check_truth,
    _with_physics,
    effect_breakdown,
    noise_sigma,
)

__all__ = ["noise_floor_pct", "oracle_energy_kwh", "oracle_factor", "oracle_mape_pct"]


@functools.lru_cache(maxsize=16)
def _factor_and_floor(sigma: float, predictor: str) -> tuple[float, float]:
    """(c, E|X - c| / X) for X = max(1 + eta, MIN_NOISE_FACTOR), eta ~ N(0, sigma^2)."""
    lo, fm = 1.0 - 12.0 * sigma, MIN_NOISE_FACTOR
    lo = max(lo, fm)
    p_clip = stats.norm.cdf((fm - 1.0) / sigma)

    def pdf(x):
        return stats.norm.pdf(x, loc=1.0, scale=sigma)

    def w_mass(a, b):  # integral of pdf(x) / x over [a, b]
        return integrate.quad(lambda x: pdf(x) / x, a, b, epsabs=1e-13, epsrel=1e-12)[0]

    hi = 1.0 + 12.0 * sigma
    if predictor == "mean":
        c = 1.0
    else:  # first-order condition of E|X - c| / X: equal 1/X-weighted mass either side
        c = optimize.brentq(lambda c: w_mass(lo, c) + p_clip / fm - w_mass(c, hi),
                            lo + 1e-9, hi - 1e-9, xtol=1e-13)
    mape = (integrate.quad(lambda x: abs(x - c) / x * pdf(x), lo, hi, points=[c],
                           epsabs=1e-13, epsrel=1e-12, limit=200)[0]
            + p_clip * abs(fm - c) / fm)
    return float(c), float(mape)


def oracle_factor(truth: str = "paper", *, predictor: str = "mape") -> float:
    """Multiplier ``c`` of the oracle prediction ``c E_p (1 + S)``.

    ``predictor="mean"`` gives the conditional mean (``c = 1``);
    ``"mape"`` the MAPE-optimal point prediction, the ``1/X``-weighted median
    of ``X = 1 + eta``, found by quadrature and root finding (error < 1e-10).

    Examples
    --------
    >>> round(oracle_factor("paper"), 4)
    0.9863
    """
    return _factor_and_floor(noise_sigma(truth), _check_predictor(predictor))[0]


def noise_floor_pct(truth: str = "paper", *, predictor: str = "mape") -> float:
    """Expected MAPE (%) of the oracle: the best any model can do on a truth.

    ``E|X - c| / X`` over ``X = 1 + eta``, by adaptive quadrature (absolute
    error < 1e-9 %); the same for every trip, since ``eta`` is multiplicative.
    A finite test set scatters around it: compare with
    :func:`oracle_mape_pct` on the same trips.

    Parameters
    ----------
    truth : {"paper", "structured"}
    predictor : {"mape", "mean"}
        The oracle's point prediction (see :func:`oracle_factor`).

    Returns
    -------
    float, %

    Examples
    --------
    >>> round(noise_floor_pct("paper"), 2), round(noise_floor_pct("paper", predictor="mean"), 2)
    (9.43, 9.5)
    >>> round(noise_floor_pct("structured"), 2)
    2.8
    """
    return 100.0 * _factor_and_floor(noise_sigma(truth), _check_predictor(predictor))[1]


def oracle_energy_kwh(table: pd.DataFrame, *, truth: str = "paper", predictor: str = "mape",
                      vehicle: VehicleParams | None = None, n_steps: int = 1000,
                      seed: int = 0) -> np.ndarray:
    """The oracle's energy prediction: everything known except the i.i.d. error.

    Parameters
    ----------
    table : pandas.DataFrame, (n_trips, ...)
        Trip or measured-trip table. ``E_p`` is its ``energy_kwh_physics``
        column if present, else ``simulate(table, vehicle, n_steps=, seed=)``;
        pass the ``vehicle``, ``n_steps`` and ``seed`` used by
        :func:`make_dataset`.
    truth : {"paper", "structured"}
    predictor : {"mape", "mean"}
        See :func:`oracle_factor`.
    vehicle : VehicleParams, optional
    n_steps, seed : int

    Returns
    -------
    numpy.ndarray, shape (n_trips,), kWh
        ``c * E_p * (1 + S)`` (``S = 0`` for the paper truth).

    Examples
    --------
    >>> from hybridev import make_dataset
    >>> ds = make_dataset(50, truth="structured", seed=3)
    >>> pred = oracle_energy_kwh(ds, truth="structured", predictor="mean", seed=3)
    >>> bool(abs(float(np.std(ds.energy_kwh / pred - 1)) - 0.035) < 0.02)
    True
    """
    c = oracle_factor(_check_truth(truth), predictor=predictor)
    t = _with_physics(table, vehicle or VehicleParams(), n_steps, seed)
    ep = t["energy_kwh_physics"].to_numpy(float)
    if truth == "paper":
        return c * ep
    return c * ep * (1.0 + effect_breakdown(t, vehicle=vehicle)["total"].to_numpy(float))


def oracle_mape_pct(dataset: pd.DataFrame, *, truth: str = "paper", predictor: str = "mape",
                    vehicle: VehicleParams | None = None, n_steps: int = 1000,
                    seed: int = 0) -> float:
    """MAPE (%) of the oracle on a measured dataset: the floor on *these* trips.

    Parameters as :func:`oracle_energy_kwh`; ``dataset`` needs ``energy_kwh``.

    Examples
    --------
    >>> from hybridev import make_dataset
    >>> ds = make_dataset(300, seed=1)
    >>> 7.0 < oracle_mape_pct(ds, seed=1) < 11.0
    True
    """
    if "energy_kwh" not in dataset.columns:
        raise ValueError("dataset needs the measured column 'energy_kwh'")
    y = dataset["energy_kwh"].to_numpy(float)
    pred = oracle_energy_kwh(dataset, truth=truth, predictor=predictor, vehicle=vehicle,
                             n_steps=n_steps, seed=seed)
    return float(100.0 * np.mean(np.abs(y - pred) / y))
