"""Shared command line and JSON output of the small M1 studies (``trace_gap``, ``band_m1``).

Not part of the library. A study script adds ``evaluation/`` to ``sys.path`` and calls
:func:`run_study` with its ``run(data_dir) -> rows`` function.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path

from hybridev.core.fileio import atomic_path

__all__ = ["DEFAULT_DATA", "run_study", "write_markdown"]

DEFAULT_DATA = Path(__file__).resolve().parents[2] / "shared" / "realtrips"
"""The M1 trips beside the repository (``../shared/realtrips``)."""


def run_study(doc: str, name: str, run: Callable[[Path], list], default_out: Path,
              argv=None) -> tuple[dict, Path]:
    """Parse ``--data`` and ``--out``, run the study, write ``<out>/<name>.json``.

    Returns the result (``rows`` and ``runtime_s``) and the output folder, for the
    script to write its Markdown table.
    """
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--data", type=Path, default=DEFAULT_DATA)
    ap.add_argument("--out", type=Path, default=default_out)
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    rows = run(args.data)
    res = {"rows": rows, "runtime_s": round(time.perf_counter() - t0, 1)}
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / f"{name}.json") as tmp:
        Path(tmp).write_text(json.dumps(res, indent=1))
    return res, args.out


def write_markdown(out: Path, name: str, lines: list[str], runtime_s: float) -> int:
    """Write ``<out>/<name>.md`` atomically from ``lines``, say so, and return exit code 0."""
    with atomic_path(out / f"{name}.md") as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    print(f"wrote {out / f'{name}.md'} in {runtime_s} s")
    return 0
