"""Validation of trip tables at the public boundary.

Every check names the field, the offending value and the allowed range.
``check_table(..., on_error="raise")`` raises :class:`ValueError` on the first
failing field; ``on_error="collect"`` returns the good rows and a table of
rejected rows with one reason each (used for measured-trip files, whose bad
rows are reported and counted, never silently dropped).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hybridev.physics.params import PROFILES

__all__ = [
    "OPTIONAL_TRIP_COLUMNS",
    "REQUIRED_TRIP_COLUMNS",
    "FieldRule",
    "check_table",
    "validate_trips",
]

REQUIRED_TRIP_COLUMNS = ("distance_km", "avg_speed_kmh", "mode", "temperature_c", "soc_initial")
"""Columns every trip table must have."""

OPTIONAL_TRIP_COLUMNS = ("hour", "grade_pct", "trip_id", "parked_min", "duration_s",
                         "elevation_gain_m", "elevation_loss_m")
"""Columns a trip table may have."""


@dataclass(frozen=True)
class FieldRule:
    """Allowed range of one numeric column: ``lo < x`` or ``lo <= x``, same for ``hi``."""

    lo: float
    hi: float
    lo_open: bool = False
    hi_open: bool = False
    hint: str = ""
    """Likely cause of a bad value, appended to the message (e.g. a unit mix-up)."""
    missing_ok: bool = False
    """An empty cell (NaN/None) is allowed and means "unknown"; text is still refused."""

    def describe(self) -> str:
        rng = f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
        return rng + (" or empty" if self.missing_ok else "")

    def bad_mask(self, x: np.ndarray, missing: np.ndarray | None = None) -> np.ndarray:
        """Rows outside the range; ``missing`` marks empty raw cells (allowed if ``missing_ok``)."""
        lo_ok = x > self.lo if self.lo_open else x >= self.lo
        hi_ok = x < self.hi if self.hi_open else x <= self.hi
        bad = ~(np.isfinite(x) & lo_ok & hi_ok)
        if self.missing_ok and missing is not None:
            bad &= ~missing
        return bad


TRIP_RULES: dict[str, FieldRule] = {
    "distance_km": FieldRule(0.0, 2000.0, lo_open=True),
    "avg_speed_kmh": FieldRule(0.0, 250.0, lo_open=True),
    "temperature_c": FieldRule(-50.0, 60.0, hint="°C; not kelvin or °F"),
    "soc_initial": FieldRule(0.0, 1.0, hint="a fraction; a SoC in percent divides by 100"),
    "hour": FieldRule(0.0, 24.0, hi_open=True),
    "grade_pct": FieldRule(-30.0, 30.0),
    "elevation_gain_m": FieldRule(0.0, 20000.0, missing_ok=True,
                                  hint="total climb over the trip in metres (planned trips); "
                                       "empty: unknown"),
    "elevation_loss_m": FieldRule(0.0, 20000.0, missing_ok=True,
                                  hint="total descent over the trip in metres, >= 0 (planned "
                                       "trips); empty: unknown"),
    "parked_min": FieldRule(0.0, 1e7, missing_ok=True,
                            hint="minutes parked since the previous trip ended; empty: "
                                 "unknown, taken as soaked to ambient"),
    "duration_s": FieldRule(0.0, 1e6, missing_ok=True,
                            hint="the trip's duration in seconds; with start_time it ends the "
                                 "trip for the next trip's parking time"),
}


_NO_REJECTED = pd.DataFrame(columns=["row", "field", "value", "reason"])
"""Template of the (empty) rejected-rows table; :func:`check_table` returns copies."""


def _numeric(col: pd.Series, field: str = "column", what: str = "trips") -> np.ndarray:
    """Numbers of a column; a bool, date or complex column is refused, bool cells are NaN."""
    if col.dtype == np.float64:  # already numbers: no conversion (to_numeric is a no-op)
        return col.to_numpy()
    kind = col.dtype.kind
    if kind in "bcmM" or str(col.dtype) == "boolean":
        raise ValueError(f"{what}: column {field!r} has dtype {col.dtype}; numbers are "
                         "required (a boolean or date is not a number)")
    if kind == "O":
        col = col.map(lambda v: np.nan if isinstance(v, bool | np.bool_) else v)
    return pd.to_numeric(col, errors="coerce").to_numpy(dtype=float, na_value=np.nan)


def check_table(table: pd.DataFrame, *, required: tuple[str, ...], rules: dict[str, FieldRule],
                modes: tuple[str, ...] | None = None, mode_required: bool = True,
                on_error: str = "raise", what: str = "trips"
                ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Check a table's columns and rows.

    Parameters
    ----------
    table : pandas.DataFrame
    required : tuple of str
        Columns that must be present.
    rules : dict of str to FieldRule
        Range rules for numeric columns (applied when the column exists).
    modes : tuple of str, optional
        Allowed values of a ``mode`` column (default: the keys of ``PROFILES``).
    mode_required : bool
        If False, a missing or empty ``mode`` is allowed.
    on_error : {"raise", "collect"}
    what : str
        Name of the table used in messages.

    Returns
    -------
    good : pandas.DataFrame
        The rows that passed, numeric columns as float.
    rejected : pandas.DataFrame
        Columns ``row`` (original index), ``field``, ``value``, ``reason``.
        Empty in ``"raise"`` mode.
    """
    good, rejected, _ = _check_table(table, required=required, rules=rules, modes=modes,
                                     mode_required=mode_required, on_error=on_error, what=what)
    return good, rejected


def _check_table(table: pd.DataFrame, *, required: tuple[str, ...], rules: dict[str, FieldRule],
                 modes: tuple[str, ...] | None = None, mode_required: bool = True,
                 on_error: str = "raise", what: str = "trips", _meta: dict | None = None
                 ) -> tuple[pd.DataFrame, pd.DataFrame, dict[str, np.ndarray]]:
    """:func:`check_table`, plus the checked columns as arrays.

    The third item maps each checked numeric column to its float values and
    ``"mode"`` (when present) to its cells (object), for every row of
    ``table``: in ``"raise"`` mode these are the columns of ``good``, so
    callers need not look the columns up again (slow on small tables).
    ``_meta`` (a dict) receives ``"mode_normal"``: whether every ``mode`` cell is an
    allowed mode in a column of the dtype that setting those cells gives (so
    setting the normalised modes would change nothing).
    """
    if on_error not in ("raise", "collect"):
        raise ValueError(f"on_error={on_error!r}; allowed: 'raise', 'collect'")
    if not isinstance(table, pd.DataFrame):
        raise ValueError(f"{what} must be a pandas DataFrame; got {type(table).__name__}")
    missing = [c for c in required if c not in table.columns]
    if missing:
        raise ValueError(f"{what} is missing required column(s) {missing}; "
                         f"required: {list(required)}{_close_names(missing, table.columns)}")
    if len(table) == 0:
        raise ValueError(f"{what} is empty: at least one row is required")
    modes = tuple(PROFILES) if modes is None else modes
    out = table  # read only until the converted columns are set, once, below
    bad_any = np.zeros(len(out), dtype=bool)
    reasons: list[pd.DataFrame] = []

    errors: list[str] = []  # "raise" mode: every invalid field, raised together at the end

    def report(field: str, mask: np.ndarray, values, allowed: str) -> None:
        nonlocal bad_any
        if on_error == "raise":
            if mask.any():
                i = int(np.flatnonzero(mask)[0])
                errors.append(
                    f"{int(mask.sum())} row(s) have an invalid {field!r}; first at row "
                    f"{out.index[i]!r}: {field}={np.asarray(values(), dtype=object)[i]!r}, "
                    f"allowed {allowed}")
            return
        new = mask & ~bad_any
        if not new.any():
            return
        values = values()  # the raw cells, only built when some row fails
        vals = np.asarray(values, dtype=object)[new]
        reasons.append(pd.DataFrame({
            "row": out.index[new], "field": field, "value": vals,
            "reason": [f"{field}={v!r} outside allowed {allowed}" for v in vals.tolist()]}))
        bad_any |= mask

    conv = {}
    arrays: dict[str, np.ndarray] = {}
    for field, rule in rules.items():
        if field not in out.columns:
            continue
        raw = out[field]
        if raw.dtype == np.float64:  # numbers already: NaN is the only empty cell
            x = raw.to_numpy()
            miss = np.isnan(x) if rule.missing_ok else None
        else:
            x = _numeric(raw, field, what)
            miss = raw.isna().to_numpy() if rule.missing_ok else None
        report(field, rule.bad_mask(x, miss), lambda raw=raw: raw.to_numpy(dtype=object),
               rule.describe() + (f" ({rule.hint})" if rule.hint else ""))
        if raw.dtype != np.float64:  # float64 columns are kept as they are
            conv[field] = x
        arrays[field] = x
    # One (lazy, copy-on-write) copy with every numeric column as float: column
    # replacements are slow on small tables, so only the converted ones are set.
    out = table.assign(**conv) if conv else table.copy(deep=False)
    if "mode" in out.columns:
        m = out["mode"]
        # pd.NA (a "string" column's empty cell) as NaN: it cannot be compared
        cells = m.to_numpy(dtype=object, **({"na_value": np.nan}
                                            if getattr(m.dtype, "na_value", None) is pd.NA
                                            else {}))
        arrays["mode"] = cells
        known = np.zeros(len(cells), dtype=bool)
        for name in modes:  # the common case: every mode is a known one
            known |= cells == name
        if _meta is not None:  # the cells as they are make a normalised mode column
            _meta["mode_normal"] = bool(known.all()) and m.dtype == _str_dtype()
        if not known.all():
            present = m.notna() & (m.astype(str).str.len() > 0)
            ok = m.isin(modes).to_numpy() | (~present.to_numpy() & (not mode_required))
            report("mode", ~ok, lambda: cells, f"one of {list(modes)}")
    if errors:
        raise ValueError(f"{what}: " + errors[0] + "".join(f"; also {e}" for e in errors[1:]))
    good = out.loc[~bad_any] if bad_any.any() else out
    rejected = (pd.concat(reasons, ignore_index=True) if reasons
                else _NO_REJECTED.copy())  # building an empty frame costs more than copying
    if on_error == "collect" and len(good) == 0:
        raise ValueError(f"{what}: all {len(out)} rows were rejected; first reason: "
                         f"{rejected['reason'].iloc[0]}")
    return good, rejected, arrays


@functools.cache
def _str_dtype():
    """The dtype pandas gives a column set from an object array of strings."""
    return pd.Series(np.array(["eco"], dtype=object)).dtype


def _close_names(missing, columns) -> str:
    """``"; column 'x' looks like a misspelt 'y'"`` for columns close to a missing one."""
    import difflib

    have = [str(c) for c in columns]
    pairs = [(m, hit[0]) for m in missing
             if (hit := difflib.get_close_matches(m, have, n=1, cutoff=0.75))]
    if not pairs:
        return ""
    return "; " + ", ".join(f"column {h!r} looks like a misspelt {m!r}" for m, h in pairs)


def validate_trips(trips: pd.DataFrame) -> pd.DataFrame:
    """Validate a trip table and return a clean copy.

    Required columns: ``distance_km`` (0, 2000], ``avg_speed_kmh`` (0, 250],
    ``mode`` (a key of :data:`hybridev.PROFILES`), ``temperature_c``
    [-50, 60] and ``soc_initial`` [0, 1]. Optional: ``hour`` [0, 24),
    ``grade_pct`` [-30, 30], ``trip_id``, ``parked_min`` [0, 1e7] or empty
    (minutes the car stood parked since its previous trip ended: a short stop
    leaves the cabin warm, :func:`hybridev.physics.thermal.soak_fraction`;
    empty means unknown, taken as soaked to ambient; see
    :func:`hybridev.parked_minutes` to derive it from start times),
    ``duration_s`` [0, 1e6] or empty (ends the trip for the next trip's
    parking time).

    Parameters
    ----------
    trips : pandas.DataFrame

    Returns
    -------
    pandas.DataFrame
        A copy with numeric columns as float.

    Raises
    ------
    ValueError
        Naming each invalid field with its count of bad rows, the first bad
        row and value, and the allowed range.

    Examples
    --------
    >>> import pandas as pd
    >>> t = pd.DataFrame({"distance_km": [-1.0], "avg_speed_kmh": [60.0], "mode": ["eco"],
    ...                   "temperature_c": [20.0], "soc_initial": [0.8]})
    >>> validate_trips(t)
    Traceback (most recent call last):
    ...
    ValueError: trips: 1 row(s) have an invalid 'distance_km'; first at row 0: distance_km=-1.0, allowed (0, 2000]

    Every invalid field is named at once:

    >>> validate_trips(t.assign(temperature_c=295.0))
    Traceback (most recent call last):
    ...
    ValueError: trips: 1 row(s) have an invalid 'distance_km'; first at row 0: distance_km=-1.0, allowed (0, 2000]; also 1 row(s) have an invalid 'temperature_c'; first at row 0: temperature_c=295.0, allowed [-50, 60] (°C; not kelvin or °F)
    """
    good, _ = check_table(trips, required=REQUIRED_TRIP_COLUMNS, rules=TRIP_RULES)
    return good


def _validated_trip_columns(trips: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, np.ndarray]]:
    """:func:`validate_trips`, plus the checked columns as arrays (see :func:`_check_table`)."""
    good, _, arrays = _check_table(trips, required=REQUIRED_TRIP_COLUMNS, rules=TRIP_RULES)
    return good, arrays
