"""``hybridev example-data DIR``: write the example trip schedule and tariff shipped with hybridev.

``schedule.csv``: a week of planned trips (weekday commutes and errands, a
long weekend trip; ``departure`` timestamps, ``distance_km``,
``avg_speed_kmh``, ``temperature_c``; no ``mode``, as real schedules).
``tariff.csv``: a 15-minute time-of-use tariff over the same week (0.12 per
kWh at night, 0.40 at the evening peak, 0.25 otherwise). Both are built by
:func:`hybridev.apps.demo.example_schedule` / :func:`~hybridev.apps.demo.example_tariff`
and dated from Monday 2026-01-05. Existing files are never overwritten.
"""

from __future__ import annotations

import argparse
from importlib.resources import files
from pathlib import Path

NAME = "example-data"
HELP = "write the example schedule.csv and tariff.csv (for plan-charging) into a directory"

EXAMPLE_FILES = ("schedule.csv", "tariff.csv")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("dir", help="directory to write into (created if missing; existing files "
                               "are never overwritten)")


def run(args: argparse.Namespace) -> int:
    from hybridev.core.fileio import atomic_path

    out = Path(args.dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"dir={args.dir!r} is an existing file; give a directory")
    clash = [n for n in EXAMPLE_FILES if (out / n).exists()]
    if clash:
        raise ValueError(f"dir={args.dir!r} already holds {clash}; example-data never "
                         "overwrites files: pick an empty directory")
    out.mkdir(parents=True, exist_ok=True)
    src = files("hybridev.cli").joinpath("examples")
    for name in EXAMPLE_FILES:
        with atomic_path(out / name) as tmp:
            Path(tmp).write_bytes(src.joinpath(name).read_bytes())
        print(f"wrote {out / name}")
    return 0
