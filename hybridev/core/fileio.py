"""Small I/O helpers: reading tables, and the historic names of the atomic writers.

Every write goes through :mod:`hybridev.core.outputs` (checks before the work,
atomic replacement, clean-up on error and on SIGINT/SIGTERM, folders replaced
only when hybridev wrote them); the names here delegate to it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

import pandas as pd

from hybridev.core import outputs

__all__ = ["atomic_dir", "atomic_path", "read_table", "write_table"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, *, option: str = "path") -> Iterator[Path]:
    """Yield a temporary file path that replaces ``path`` only on success.

    The plain atomic write (:func:`hybridev.core.outputs.atomic_replace`), for
    outputs the caller owns (the workflow scripts' committed outputs, files
    the caller checked itself); command outputs go through
    :func:`hybridev.core.outputs.atomic_file`, which never replaces a file
    hybridev did not write.
    """
    with outputs.atomic_replace(path, option=option) as tmp:
        yield tmp


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, *, option: str = "path", kind: str = "dir",
               manifest: dict | None = None) -> Iterator[Path]:
    """Yield a temporary directory that replaces ``path`` only on success.

    An existing directory at ``path`` is replaced as a whole only when it is
    empty or was written by hybridev (see :func:`hybridev.core.outputs.output_dir`);
    on failure it is left untouched and the temporary directory is removed.
    """
    with outputs.output_dir(path, option=option, kind=kind, manifest=manifest) as tmp:
        yield tmp


def read_table(path: str | os.PathLike, *, option: str | None = None,
               text_columns: tuple[str, ...] = ()) -> pd.DataFrame:
    """Read a CSV or Parquet table, with a clear error for a missing or unreadable file.

    ``text_columns``: CSV columns read as text, not numbers (identifiers such as
    ``trip_id``: ``007`` stays ``"007"`` and matches the same id in a Parquet file);
    names the file lacks are ignored.

    Examples
    --------
    >>> read_table("/nonexistent/x.csv")
    Traceback (most recent call last):
    ...
    ValueError: file '/nonexistent/x.csv' does not exist
    """
    path = Path(path)
    what = f"{option}={str(path)!r}" if option else f"file {str(path)!r}"
    if not path.exists():
        raise ValueError(f"{what} does not exist")
    if path.is_dir():
        raise ValueError(f"{what} is a directory; give a .csv or .parquet file")
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            return pd.read_parquet(path)
        table = pd.read_csv(path, dtype=dict.fromkeys(text_columns, str) or None)
    except pd.errors.EmptyDataError as exc:
        raise ValueError(f"{what} is empty (no header row)") from exc
    except (OSError, ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        msg = " ".join(str(exc).split())  # one line
        raise ValueError(f"could not read {str(path)!r} as a table: {msg}") from exc
    except Exception as exc:  # pyarrow raises its own errors for a damaged file
        raise ValueError(f"could not read {str(path)!r} as a table: "
                         f"{type(exc).__name__}: {exc}") from exc
    first = str(table.columns[0]) if len(table.columns) else ""
    if first.lstrip().startswith("#"):
        raise ValueError(f"{what} starts with a comment line ({first[:40]!r}); the first line "
                         "must be the header (column names): remove the comment lines")
    padded = [c for c in table.columns if isinstance(c, str) and c != c.strip()]
    if padded:
        import warnings

        from hybridev.core.errors import DataWarning

        warnings.warn(f"{what}: column name(s) {padded[:5]} have spaces around them; read as "
                      f"{[c.strip() for c in padded[:5]]}", DataWarning, stacklevel=2)
        table = table.rename(columns={c: c.strip() for c in padded})
    if len(table.columns) == 1 and any(c in str(table.columns[0]) for c in ";\t"):
        sep = "';'" if ";" in str(table.columns[0]) else "tabs"
        raise ValueError(f"{what}: one column {str(table.columns[0])[:60]!r}: the file is "
                         f"separated by {sep}, but CSV files are read comma-separated (with "
                         "'.' as the decimal point); save it as comma-separated CSV")
    return table


def write_table(df: pd.DataFrame, path: str | os.PathLike, *, option: str = "--out") -> None:
    """Write CSV or Parquet (by suffix) atomically (:func:`hybridev.core.outputs.write_table`)."""
    outputs.write_table(df, path, option=option)
