"""Streaming ``hybridev predict`` for big single files: read, score and write in chunks.

A trip table larger than :data:`STREAM_MIN_BYTES` (and without ``--timeseries``,
whose traces are matched across the whole table) is read :data:`CHUNK_ROWS`
rows at a time (CSV by ``pandas.read_csv(chunksize=...)``, Parquet by row
groups/batches), each chunk is scored and appended to the temporary output,
which replaces ``--out`` only when complete (:func:`hybridev.core.outputs.atomic_file`).
Memory stays flat: about one chunk of trips with their physics traces, whatever
the number of trips (``benchmarks/bench_predict_memory.py``).

The numbers are those of one pass: each trip's prediction depends only on its
own row, the model and the seed (``tests/cli/test_cli_stream.py`` compares them).
Bad rows are reported with their row number in the whole file (each chunk keeps
the file's row index). Out-of-domain warnings are summed over the chunks into
one line; other warnings are shown once each.
"""

from __future__ import annotations

import argparse
import os
import warnings
from collections.abc import Iterator
from pathlib import Path

__all__ = ["CHUNK_ROWS", "STREAM_MIN_BYTES", "iter_table", "predict_streaming", "should_stream"]

CHUNK_ROWS = 10_000
"""Trips scored at once when streaming."""
STREAM_MIN_BYTES = 2 << 20
"""Trip tables from this size on (2 MiB, about 20,000 trips) are streamed."""


def should_stream(args: argparse.Namespace) -> bool:
    """A single big CSV/Parquet file without ``--timeseries``."""
    if getattr(args, "timeseries", None) is not None:
        return False
    try:
        return os.path.getsize(args.trips) >= STREAM_MIN_BYTES
    except OSError:
        return False


def iter_table(path, *, chunk_rows: int = CHUNK_ROWS, text_columns=()) -> Iterator:
    """Chunks of a CSV or Parquet table (pandas DataFrames indexed by file row)."""
    import pandas as pd

    path = Path(path)
    start = 0
    what = f"trips={str(path)!r}"
    try:
        if path.suffix.lower() in (".parquet", ".pq"):
            import pyarrow.parquet as pq

            batches = (b.to_pandas() for b in pq.ParquetFile(path).iter_batches(chunk_rows))
        else:
            batches = pd.read_csv(path, chunksize=chunk_rows,
                                  dtype=dict.fromkeys(text_columns, str) or None)
        for chunk in batches:
            chunk.index = pd.RangeIndex(start, start + len(chunk))
            start += len(chunk)
            yield chunk
    except pd.errors.EmptyDataError as exc:
        raise ValueError(f"{what} is empty (no header row)") from exc
    except (OSError, UnicodeDecodeError, pd.errors.ParserError) as exc:
        raise ValueError(f"{what} could not be read as a table: "
                         f"{' '.join(str(exc).split())}") from exc
    except Exception as exc:
        if isinstance(exc, ValueError):
            raise
        raise ValueError(f"{what} could not be read as a table: {type(exc).__name__}: "
                         f"{exc}") from exc


class _Sink:
    """Appends chunks to one CSV or Parquet file (Parquet: the first chunk's schema)."""

    def __init__(self, tmp: Path, parquet: bool):
        self.tmp, self.parquet, self.writer, self.n = tmp, parquet, None, 0

    def write(self, df) -> None:
        from hybridev.core.outputs import neutralise_formulas

        if self.parquet:
            import pyarrow as pa
            import pyarrow.parquet as pq

            if self.writer is None:
                table = pa.Table.from_pandas(df, preserve_index=False)
                self.writer = pq.ParquetWriter(self.tmp, table.schema)
            else:
                table = pa.Table.from_pandas(df, schema=self.writer.schema, preserve_index=False)
            self.writer.write_table(table)
        else:
            neutralise_formulas(df).to_csv(self.tmp, mode="w" if self.n == 0 else "a",
                                           header=self.n == 0, index=False)
        self.n += len(df)

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


def predict_streaming(model, args: argparse.Namespace, score, prepare) -> tuple[int, str]:
    """Score ``args.trips`` chunk by chunk into ``args.out``; return (rows, description).

    ``score(model, trips, args)`` -> (table, description); ``prepare(chunk)`` applies
    ``--columns`` and ``--soc-initial``.
    """
    from hybridev.core.errors import OutOfDomainWarning
    from hybridev.core.outputs import atomic_file
    from hybridev.learning.domain import warn_out_of_domain

    parquet = Path(args.out).suffix.lower() in (".parquet", ".pq")
    n_out, seen, what = 0, set(), "predictions"
    with atomic_file(args.out, option="--out") as tmp:
        sink = _Sink(tmp, parquet)
        try:
            for chunk in iter_table(args.trips):
                with warnings.catch_warnings(record=True) as caught:
                    warnings.simplefilter("always")
                    out, what = score(model, prepare(chunk), args)
                for w in caught:
                    if issubclass(w.category, OutOfDomainWarning):
                        continue
                    key = (w.category, str(w.message))
                    if key not in seen:
                        seen.add(key)
                        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
                if "in_domain" in out:
                    n_out += int((~out["in_domain"].astype(bool)).sum())
                sink.write(out)
        finally:
            sink.close()
    if n_out:
        warn_out_of_domain(n_out, sink.n, stacklevel=2)
    return sink.n, what
