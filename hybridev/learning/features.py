"""Input features of the residual network (paper, Sec. III-B).

The paper lists the network inputs as distance ``d``, mean speed ``v_bar``,
maximum speed ``v_max``, a one-hot driving behaviour (3 values), ambient
temperature ``T``, time of day, initial SoC ``s0``, the physics prediction
``E_p`` and the consumption rate ``E_p / d``. It calls these "10 input
features", but the list has **11** numbers; hybridev uses all 11 (see
:data:`FEATURE_NAMES`), so the paper's network is 11-64-32-16-1 here.

Two conventions for incomplete trip tables, both applied by
:func:`trip_features`:

* ``hour`` missing (no column): filled with :data:`DEFAULT_HOUR` (12, noon).
  A column with some empty values is rejected by validation instead, because
  a partly missing hour usually means a broken log.
* ``mode`` missing or ``None`` (real logs rarely label the driver): the
  one-hot becomes uniform, ``(1/3, 1/3, 1/3)``: "any of the three, equally
  likely". The physics baseline for such a row uses the ``"normal"`` profile
  (see :func:`physics_modes`).

Features are standardised with a mean and standard deviation fitted on the
training rows (:func:`fit_standardizer`); a constant column (e.g. ``hour``
when every trip lacks it) gets standard deviation 1, so it maps to 0.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import NoReturn

import numpy as np
import pandas as pd

from hybridev.physics.params import PROFILES

__all__ = [
    "DEFAULT_HOUR",
    "FEATURE_NAMES",
    "MODE_NAMES",
    "PHYSICS_FEATURES",
    "UNKNOWN_MODE_PHYSICS",
    "check_feature_names",
    "fit_standardizer",
    "mode_one_hot",
    "normalize_modes",
    "physics_modes",
    "trip_features",
]

MODE_NAMES = tuple(PROFILES)
"""Driving modes in one-hot order: ``("eco", "normal", "aggressive")``."""

FEATURE_NAMES = (
    "distance_km",
    "avg_speed_kmh",
    "max_speed_kmh",
    "mode_eco",
    "mode_normal",
    "mode_aggressive",
    "temperature_c",
    "hour",
    "soc_initial",
    "energy_kwh_physics",
    "kwh_per_km_physics",
)
"""The residual network's inputs, in the order of the paper's list (units in the names)."""

PHYSICS_FEATURES = ("energy_kwh_physics", "kwh_per_km_physics")
"""Features computed by the physics model (left out by the pure-ML baseline)."""

DEFAULT_HOUR = 12.0
"""Departure hour used when a trip table has no ``hour`` column (noon)."""

UNKNOWN_MODE_PHYSICS = "normal"
"""Driving profile the physics model uses for rows without a ``mode``."""


def check_feature_names(features: Sequence[str], *, what: str = "features") -> tuple[str, ...]:
    """Validate a feature subset and return it in canonical order.

    Raises
    ------
    ValueError
        On an unknown name, a duplicate or an empty selection.

    Examples
    --------
    >>> check_feature_names(["soc_initial", "distance_km"])
    ('distance_km', 'soc_initial')
    """
    if isinstance(features, str):
        features = (features,)
    names = [str(f) for f in features]
    unknown = [f for f in names if f not in FEATURE_NAMES]
    if unknown:
        raise ValueError(f"{what}={unknown!r} contains unknown feature name(s); "
                         f"allowed: {list(FEATURE_NAMES)}")
    if len(set(names)) != len(names) or not names:
        raise ValueError(f"{what}={names!r} must be a non-empty selection without duplicates")
    return tuple(f for f in FEATURE_NAMES if f in names)


def _mode_codes(arr: np.ndarray) -> np.ndarray:
    """Index into :data:`MODE_NAMES` of each element of an object array, -1 if none."""
    codes = np.full(arr.shape, -1, dtype=np.intp)
    for k, name in enumerate(MODE_NAMES):
        codes[arr == name] = k
    return codes


def normalize_modes(mode, n_trips: int | None = None) -> np.ndarray:
    """Driving modes with every form of "unknown" as ``None``.

    Parameters
    ----------
    mode : array_like (n_trips,) of str or None, or None
        ``"eco"``, ``"normal"``, ``"aggressive"``; ``None``, NaN and ``""``
        mean unknown. ``None`` for the whole argument (no ``mode`` column)
        means all unknown and needs ``n_trips``.

    Returns
    -------
    numpy.ndarray, shape (n_trips,), object

    Raises
    ------
    ValueError
        For any other value, naming it and the allowed values.

    Examples
    --------
    >>> normalize_modes(["eco", float("nan"), ""]).tolist()
    ['eco', None, None]
    """
    if mode is None:
        return np.full(int(n_trips or 0), None, dtype=object)
    arr = np.asarray(mode, dtype=object).reshape(-1)
    known = _mode_codes(arr) >= 0
    if not known.all():
        unk = arr[~known]
        bad = ~(pd.isna(unk) | (unk == ""))
        if bad.any():
            raise ValueError(f"trips: {int(bad.sum())} row(s) have an invalid 'mode'; first: "
                             f"mode={unk[bad][0]!r}, allowed one of {list(MODE_NAMES)} "
                             "or empty (unknown)")
        arr = np.where(known, arr, None)
    return arr


def mode_one_hot(mode) -> np.ndarray:
    """One-hot driving mode, uniform ``1/3`` for a missing mode.

    Parameters
    ----------
    mode : array_like (n_trips,) of str or None
        ``"eco"``, ``"normal"``, ``"aggressive"``; ``None``/NaN/``""`` = unknown.

    Returns
    -------
    numpy.ndarray, shape (n_trips, 3), in :data:`MODE_NAMES` order

    Examples
    --------
    >>> mode_one_hot(["eco", None]).round(3).tolist()
    [[1.0, 0.0, 0.0], [0.333, 0.333, 0.333]]
    """
    codes = _mode_codes(normalize_modes(mode))  # -1 for unknown
    known = codes >= 0
    out = np.full((len(codes), len(MODE_NAMES)), 1.0 / len(MODE_NAMES))
    out[known] = 0.0
    out[np.flatnonzero(known), codes[known]] = 1.0
    return out


def physics_modes(mode) -> np.ndarray:
    """Modes to run the physics with: unknown modes become :data:`UNKNOWN_MODE_PHYSICS`.

    Examples
    --------
    >>> physics_modes(["eco", None, ""]).tolist()
    ['eco', 'normal', 'normal']
    """
    m = normalize_modes(mode)
    return np.where(pd.isna(m), UNKNOWN_MODE_PHYSICS, m)


def trip_features(table: pd.DataFrame, features: Sequence[str] = FEATURE_NAMES) -> np.ndarray:
    """Raw (unstandardised) feature matrix of simulated trips.

    Parameters
    ----------
    table : pandas.DataFrame
        A trip table after :func:`hybridev.simulate` (needs ``max_speed_kmh``,
        ``energy_kwh_physics`` and ``kwh_per_km_physics`` when those features
        are selected). ``mode`` and ``hour`` may be missing, see the module
        docstring.
    features : sequence of str
        A subset of :data:`FEATURE_NAMES` (canonical order is used).

    Returns
    -------
    numpy.ndarray, shape (n_trips, n_features), float64
        Columns in the units of their names.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"distance_km": [10.0], "avg_speed_kmh": [50.0], "max_speed_kmh": [60.0],
    ...                   "temperature_c": [20.0], "soc_initial": [0.9],
    ...                   "energy_kwh_physics": [1.5], "kwh_per_km_physics": [0.15]})
    >>> trip_features(t).round(3).tolist()
    [[10.0, 50.0, 60.0, 0.333, 0.333, 0.333, 20.0, 12.0, 0.9, 1.5, 0.15]]
    """
    names = check_feature_names(features)
    n = len(table)
    cols: dict[str, np.ndarray] = {}
    for name in names:  # each column looked up once, in order (the first missing one raises)
        if name.startswith("mode_"):
            if "mode" not in cols and "mode" in table.columns:
                cols["mode"] = normalize_modes(table["mode"].to_numpy(object))
        elif name in table.columns:
            cols[name] = table[name].to_numpy(dtype=float)
        elif name != "hour":
            _missing_feature(name)
    return _feature_matrix(cols, n, names)


def _missing_feature(name: str) -> NoReturn:
    raise ValueError(f"feature {name!r} needs column {name!r}, which the table lacks; "
                     "run hybridev.simulate first for the physics columns")


def _feature_matrix(columns: Mapping[str, np.ndarray], n_trips: int,
                    features: Sequence[str] = FEATURE_NAMES) -> np.ndarray:
    """:func:`trip_features` from the table's columns as arrays.

    Parameters
    ----------
    columns : mapping of str to numpy.ndarray (n_trips,)
        Column values by name: float ones, and ``mode`` as object (``None``
        where unknown); ``mode`` and ``hour`` may be missing.
    n_trips : int
    features : sequence of str
        A subset of :data:`FEATURE_NAMES` (canonical order is used).

    Returns
    -------
    numpy.ndarray, shape (n_trips, n_features), float64
        As :func:`trip_features` on a table with those columns.
    """
    names = check_feature_names(features)
    n = int(n_trips)
    out = np.empty((n, len(names)))
    onehot = None
    for j, name in enumerate(names):
        if name.startswith("mode_"):
            if onehot is None:
                onehot = mode_one_hot(columns["mode"] if "mode" in columns
                                      else np.full(n, None, dtype=object))
            out[:, j] = onehot[:, MODE_NAMES.index(name[len("mode_"):])]
        elif name == "hour" and "hour" not in columns:
            out[:, j] = DEFAULT_HOUR
        else:
            if name not in columns:
                _missing_feature(name)
            out[:, j] = columns[name]
    if not np.all(np.isfinite(out)):
        j = int(np.flatnonzero(~np.isfinite(out).all(axis=0))[0])
        raise ValueError(f"feature {names[j]!r} has NaN or infinite values")
    return out


def fit_standardizer(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column means and standard deviations, with std 1 for constant columns.

    Uses :class:`sklearn.preprocessing.StandardScaler` (population std).

    Parameters
    ----------
    x : numpy.ndarray, shape (n_rows, n_features)

    Returns
    -------
    mean, std : numpy.ndarray, shape (n_features,) each

    Examples
    --------
    >>> m, s = fit_standardizer(np.array([[1.0, 5.0], [3.0, 5.0]]))
    >>> m.tolist(), s.tolist()
    ([2.0, 5.0], [1.0, 1.0])
    """
    from sklearn.preprocessing import StandardScaler

    sc = StandardScaler().fit(np.asarray(x, dtype=float))
    return sc.mean_.copy(), sc.scale_.copy()
