"""How far the residual correction is supported by training data between training values.

The residual ensemble learns its correction at the conditions the car was logged at.
Between two training values of an intensive condition (a temperature between two logged
ones, a speed between two driven ones) the networks interpolate a shape they have no data
for: a heater that switches on between -5 and 20 °C is, to them, a straight line from
the correction at -5 °C to the one at 20 °C. On the structured benchmark (whose
extra heating sets in below 5 °C) that line made the correction at 7.5 °C and
50 km/h +6.4 % of the physics, where the physics alone is within 0.2 % of the truth
(``evaluation/range_bands/range_bias.md``): the range bands there were pessimistic. The
physics, by contrast, is a model of the whole temperature axis.

So the correction is treated as a data-driven deviation from the physics with a smooth
prior of mean zero (the physics) and the posterior mean of a Gaussian process with
squared-exponential kernel of length scale ``ell`` on each intensive quantity: the
correction's **support** at ``x`` between the training values ``a < x < b`` is::

    w(x) = (k(x - a) + k(b - x)) / (1 + k(b - a)),   k(d) = exp(-d^2 / (2 ell^2))

the posterior mean at ``x`` of a function that is 1 at ``a`` and ``b`` (noise-free, the
two bracketing values), clipped to [0, 1]. It is exactly 1 at every training value,
close to 1 between values closer than about ``2 ell``, and falls to 0 in a gap many
length scales wide, where the prediction reverts to the physics. The network's mean
correction is multiplied by the product of the supports over the intensive quantities
(:meth:`hybridev.learning.residual.ResidualLearner.moments`). Beyond the training range
the support is 1: there the inputs are held at their edge and the out-of-domain
machinery widens the interval (:mod:`hybridev.learning.ood`).

The length scale is :data:`SUPPORT_LENGTH_TOLERANCES` domain tolerances of the quantity
(:data:`~hybridev.learning.domain.DOMAIN_TOLERANCES`: 3 °C, 8 km/h, 1 % grade), so a
car logged densely (real logs: temperatures every few degrees) keeps its correction
everywhere and only real gaps in its data revert to the physics.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybridev.learning.domain import DOMAIN_QUANTITIES, DOMAIN_TOLERANCES, INTENSIVE

__all__ = ["SUPPORT_LENGTH_TOLERANCES", "GapRows", "gap_rows", "interpolation_support",
           "support_and_gaps"]

SUPPORT_LENGTH_TOLERANCES = 2.0
"""Length scale of the support kernel, in domain tolerances (6 °C, 16 km/h, 2 %)."""


def _column(table, name: str) -> np.ndarray | None:
    if isinstance(table, dict):
        v = table.get(name)
    else:
        v = table[name] if name in table.columns else None
    return None if v is None else np.asarray(v, dtype=float)


def _brackets(x: np.ndarray, values: np.ndarray, ell: float):
    """``(w, a, b)``: support (n,) of ``x`` between the sorted unique training ``values``
    (1 outside them) and the bracketing training values ``a <= x <= b``."""
    n_val = len(values)
    if n_val < 2:
        return np.ones_like(x), x, x
    i = np.searchsorted(values, x)
    inside = (i > 0) & (i < n_val)
    a = values[np.clip(i - 1, 0, n_val - 1)]
    b = values[np.clip(i, 0, n_val - 1)]

    def k(d):
        return np.exp(-0.5 * (d / ell) ** 2)

    w = (k(x - a) + k(b - x)) / (1.0 + k(b - a))
    return np.where(inside, np.clip(w, 0.0, 1.0), 1.0), a, b


@dataclass(frozen=True)
class GapRows:
    """The trips inside a gap of one intensive quantity (support below 1).

    Attributes
    ----------
    name : str
        The quantity (a trip-table column).
    rows : numpy.ndarray of int, (k,)
        The trips in a gap.
    support : numpy.ndarray, (k,)
        Their support in this quantity, in [0, 1).
    lo, hi : numpy.ndarray, (k,)
        The bracketing training values, in the quantity's unit.
    t : numpy.ndarray, (k,)
        The trip's position between them, ``(x - lo) / (hi - lo)`` in (0, 1).
    """

    name: str
    rows: np.ndarray
    support: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    t: np.ndarray


def support_and_gaps(table, domain) -> tuple[np.ndarray | None, list[GapRows]]:
    """:func:`interpolation_support` and :func:`gap_rows` of a table, bracketed once.

    Returns
    -------
    support : numpy.ndarray, shape (n_trips,), or None
        The product of the supports over the intensive quantities present (None
        without a domain or without any of them).
    gaps : list of GapRows
        The trips in a gap, per quantity (empty without a domain).
    """
    support, gaps = None, []
    if domain is None:
        return support, gaps
    for j, name in enumerate(DOMAIN_QUANTITIES):
        x = _column(table, name) if INTENSIVE[j] else None
        if x is None:
            continue
        ell = SUPPORT_LENGTH_TOLERANCES * DOMAIN_TOLERANCES[j]
        w, a, b = _brackets(x, np.asarray(domain.values[j], float), ell)
        support = w if support is None else support * w
        rows = np.flatnonzero(w < 1.0)
        if rows.size:
            lo, hi = a[rows], b[rows]
            gaps.append(GapRows(name, rows, w[rows], lo, hi, (x[rows] - lo) / (hi - lo)))
    return support, gaps


def gap_rows(table, domain) -> list[GapRows]:
    """The trips in a gap between training values, per intensive quantity.

    Used to set the noise of a trip in a gap from the noise at the bracketing training
    values (:meth:`hybridev.learning.residual.ResidualLearner.predict_moments`): the
    noise head interpolates as blindly as the mean. Empty without a domain.
    """
    return support_and_gaps(table, domain)[1]


def interpolation_support(table, domain) -> np.ndarray | None:
    """Support of the residual correction at each trip's conditions, (n_trips,) in [0, 1].

    Parameters
    ----------
    table : pandas.DataFrame or dict of numpy.ndarray
        Trips (or their columns by name) with ``temperature_c``, ``avg_speed_kmh`` and,
        optionally, ``grade_pct`` (a missing quantity is not weighed).
    domain : TrainingDomain or None
        Its ``values`` are the training values of each domain quantity.

    Returns
    -------
    numpy.ndarray, shape (n_trips,), or None
        None without a domain (no weighting).

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> vals = (np.array([-5.0, 20.0, 32.0]), np.array([40.0, 60.0]), np.zeros(1),
    ...         np.zeros(1), np.zeros(1))
    >>> dom = SimpleNamespace(values=vals)
    >>> t = {"temperature_c": np.array([20.0, 26.0, 7.5, 40.0]),
    ...      "avg_speed_kmh": np.array([60.0, 50.0, 60.0, 60.0])}
    >>> interpolation_support(t, dom).round(2).tolist()
    [1.0, 1.0, 0.23, 1.0]
    """
    return support_and_gaps(table, domain)[0]
