"""Shared pieces of the benchmark scripts (not part of the library, never imported by it).

Importing this module sets ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``,
``OPENBLAS_NUM_THREADS``, ``NUMEXPR_NUM_THREADS`` and ``VECLIB_MAXIMUM_THREADS``
to 1, which only takes effect if numpy (and torch) are not loaded yet: each
script imports it before them. The scripts run as
``python benchmarks/bench_x.py`` from the repository root; Python then puts
``benchmarks/`` on ``sys.path``, so ``import _common`` finds this file.

Provides: the command line every script shares (``--quick``, ``--out``,
repeat counts), pinning to one core, timing loops (warm-up, then one timing
per call; wall and optionally CPU time), median/IQR formatting, the paper's
train/test split of the benchmark data, the "Machine" section of a result
file, a markdown table, the compressed sizes inside an ``.npz`` and the
atomic write of the result.
"""

from __future__ import annotations

import os
import sys
import warnings

THREAD_VARS = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
               "NUMEXPR_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
for _var in THREAD_VARS:
    os.environ[_var] = "1"  # before numpy and torch are imported
if "numpy" in sys.modules:
    warnings.warn("benchmarks/_common.py imported after numpy: the one-thread BLAS/OpenMP "
                  "setting may not apply", RuntimeWarning, stacklevel=2)

import argparse  # noqa: E402
import datetime as _dt  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import time  # noqa: E402
import zipfile  # noqa: E402
from collections.abc import Callable, Iterable, Mapping, Sequence  # noqa: E402
from pathlib import Path  # noqa: E402
from types import ModuleType  # noqa: E402
from typing import TypeVar  # noqa: E402

import numpy as np  # noqa: E402

__all__ = ["RESULTS", "ROOT", "THREADS_NOTE", "clock", "cpu_model", "iqr", "load_average",
           "machine_section", "markdown_table", "median_iqr", "npz_entry_sizes", "paper_split",
           "parse_args", "pin_one_core", "run_times", "show_path", "timed", "timed_cpu",
           "verdict", "write_result"]

_START = (time.perf_counter(), time.process_time())  # the run's clocks, from this import
ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
T = TypeVar("T")
THREADS_NOTE = "OMP/MKL/OPENBLAS_NUM_THREADS=1"


# -- command line ---------------------------------------------------------------------------
def _count(minimum: int) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = minimum - 1
        if value < minimum:
            raise argparse.ArgumentTypeError(f"must be an integer >= {minimum}; got {text!r}")
        return value
    return parse


def parse_args(doc: str, argv: Sequence[str] | None, *, name: str,
               counts: Mapping[str, tuple[int, int, str]] | None = None) -> argparse.Namespace:
    """The shared command line of a benchmark script.

    Parameters
    ----------
    doc : str
        The script's docstring (its first line is the description).
    argv : sequence of str or None
        Arguments (``None``: ``sys.argv[1:]``).
    name : str
        Script name without ``.py``, e.g. ``"bench_simulate"``.
    counts : mapping of str to (int, int, str)
        Repeat options: ``{"repeats": (full, quick, help)}`` gives ``--repeats``
        defaulting to ``full``, or ``quick`` with ``--quick``; at least 1
        (``warmup*`` options: at least 0).

    Returns
    -------
    argparse.Namespace
        With the counts resolved, ``quick``, ``out`` (a path, or ``None``:
        ``--quick`` without ``--out`` writes nothing) and ``command`` (the
        command line that reproduces the run, for the result file).
    """
    counts = dict(counts or {})
    ap = argparse.ArgumentParser(description=doc.strip().splitlines()[0])
    for opt, (full, quick, text) in counts.items():
        ap.add_argument(f"--{opt.replace('_', '-')}", default=None,
                        type=_count(0 if opt.startswith("warmup") else 1),
                        help=f"{text} (default {full}; {quick} with --quick)")
    ap.add_argument("--quick", action="store_true",
                    help="smoke run with few repeats; writes nothing unless --out is given")
    ap.add_argument("--out", type=Path, default=None,
                    help=f"result file (default benchmarks/results/{name}.md; none with --quick)")
    args = ap.parse_args(argv)
    for opt, (full, quick, _) in counts.items():
        if getattr(args, opt) is None:
            setattr(args, opt, quick if args.quick else full)
    if args.out is None and not args.quick:
        args.out = RESULTS / f"{name}.md"
    args.command = " ".join([f"python benchmarks/{name}.py", *(["--quick"] if args.quick else []),
                             *(f"--{opt.replace('_', '-')} {getattr(args, opt)}"
                               for opt in counts)])
    return args


def show_path(path: Path) -> str:
    """``path`` relative to the repository root when inside it."""
    path = Path(path).resolve()
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def write_result(text: str, out: Path | None) -> None:
    """Write a result file atomically (nothing when ``out`` is ``None``) and say so."""
    if out is None:
        print("quick run: result not written (give --out FILE to write it)")
        return
    from hybridev.core.fileio import atomic_path

    with atomic_path(out) as tmp:
        tmp.write_text(text, encoding="utf-8")
    print(f"wrote {show_path(out)}")


# -- machine --------------------------------------------------------------------------------
def cpu_model() -> str:
    """CPU model name from ``/proc/cpuinfo`` (or :func:`platform.processor`)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def pin_one_core() -> str:
    """Pin this process to its lowest allowed CPU; returns a description for the report."""
    if hasattr(os, "sched_setaffinity"):
        cpu = min(os.sched_getaffinity(0))
        os.sched_setaffinity(0, {cpu})
        return f"pinned to CPU {cpu} (sched_setaffinity)"
    return "not pinned (no sched_setaffinity on this OS); 1 BLAS/OpenMP thread"


def load_average() -> tuple[float, float, float]:
    """1/5/15-minute load average (NaN where the OS has none)."""
    return os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3


def run_times() -> dict[str, float]:
    """Wall and CPU seconds of this run so far (since ``_common`` was imported).

    ``cpu_self_s`` is this process's user + system time
    (:func:`time.process_time`), ``cpu_children_s`` that of its finished,
    waited-for child processes (``resource.getrusage(RUSAGE_CHILDREN)``: worker
    processes count once their cluster is closed). On an idle core a
    single-threaded run has ``cpu_self_s`` close to ``wall_s``; a much smaller
    ratio means other jobs took the core, and the wall times are inflated.
    """
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return {"wall_s": time.perf_counter() - _START[0],
            "cpu_self_s": time.process_time() - _START[1],
            "cpu_children_s": ch.ru_utime + ch.ru_stime}


def machine_section(*, load: Sequence[float], cores: str, threads: str = THREADS_NOTE,
                    modules: Iterable[ModuleType] = (),
                    times: str = "times") -> str:
    """The ``## Machine`` section of a result file.

    Parameters
    ----------
    load : sequence of 3 float
        :func:`load_average` at the start of the run.
    cores : str
        What follows the core count, e.g. ``"benchmark pinned to CPU 0 (...)"``.
    threads : str
        The thread settings.
    modules : iterable of module
        Packages whose ``__version__`` to report (besides Python and hybridev).
    times : str
        What the load may inflate (``"times"``, ``"wall times"``).
    """
    import hybridev

    run = run_times()
    end = load_average()
    mods = list(modules)
    names = " / ".join(m.__name__ for m in mods)
    versions = " / ".join(str(m.__version__) for m in mods)
    rows = [
        ("CPU", cpu_model()),
        ("cores visible", f"{os.cpu_count()}; {cores}"),
        ("threads", threads),
        ("load average at start (1/5/15 min)",
         f"{load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (shared machine: other jobs may "
         f"inflate {times})"),
        ("load average at end (1/5/15 min)", f"{end[0]:.2f} / {end[1]:.2f} / {end[2]:.2f}"),
        ("whole run: wall / CPU time",
         f"{run['wall_s']:.1f} s wall; CPU {run['cpu_self_s']:.1f} s in this process "
         f"({run['cpu_self_s'] / max(run['wall_s'], 1e-9):.0%} of wall) + "
         f"{run['cpu_children_s']:.1f} s in child processes"),
        ("Python", f"{platform.python_version()} ({platform.python_implementation()})"),
        *([(names, versions)] if mods else []),
        ("hybridev", hybridev.__version__),
        ("OS", platform.platform()),
        ("date", _dt.date.today().isoformat()),
    ]
    return "## Machine\n\n| | |\n|---|---|\n" + "".join(f"| {k} | {v} |\n" for k, v in rows)


# -- timing ---------------------------------------------------------------------------------
def clock(fn: Callable[[], T]) -> tuple[T, float]:
    """Result and wall seconds of one call of ``fn`` (no warm-up)."""
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def timed(fn: Callable[[], object], repeats: int, *, warmup: int = 1) -> np.ndarray:
    """Wall seconds of ``repeats`` calls of ``fn`` after ``warmup`` untimed calls.

    Returns
    -------
    numpy.ndarray, shape (repeats,), s
    """
    for _ in range(warmup):
        fn()
    out = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        fn()
        out[i] = time.perf_counter() - t0
    return out


def timed_cpu(fn: Callable[[], object], repeats: int, *, warmup: int = 1
              ) -> tuple[np.ndarray, np.ndarray]:
    """Wall and CPU (process) seconds of ``repeats`` calls after ``warmup`` calls.

    Returns
    -------
    wall, cpu : numpy.ndarray, shape (repeats,), s
    """
    for _ in range(warmup):
        fn()
    wall, cpu = np.empty(repeats), np.empty(repeats)
    for i in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        wall[i], cpu[i] = time.perf_counter() - t0, time.process_time() - c0
    return wall, cpu


def iqr(t: np.ndarray, scale: float = 1.0, digits: int = 3) -> str:
    """Interquartile range of ``t * scale`` as ``"lo-hi"``."""
    return "-".join(f"{x * scale:.{digits}f}" for x in np.quantile(t, [0.25, 0.75]))


def median_iqr(t: np.ndarray, scale: float = 1.0, unit: str = "s", digits: int = 3) -> str:
    """``**median unit** (IQR lo-hi unit; n runs)`` of ``t * scale``."""
    return (f"**{np.median(t) * scale:.{digits}f} {unit}** (IQR {iqr(t, scale, digits)} {unit}; "
            f"{len(t)} runs)")


def verdict(ok: bool) -> str:
    """``"met"`` or ``"MISSED"``."""
    return "met" if ok else "MISSED"


# -- data ---------------------------------------------------------------------------------
def paper_split(n_test: int = 225):
    """``(train, test)`` of ``make_dataset(1500, truth="structured", seed=0)``.

    The paper's split (Sec. III-C): ``n_test`` test trips drawn at random
    (``default_rng(0)``), the other 1,275 for ``fit``.
    """
    from hybridev.physics.truth import make_dataset

    data = make_dataset(1500, truth="structured", seed=0)
    test_idx = np.sort(np.random.default_rng(0).permutation(len(data))[:n_test])
    return data.drop(index=data.index[test_idx]), data.iloc[test_idx]


# -- markdown and files ---------------------------------------------------------------------
def markdown_table(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """A markdown table (no trailing newline)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def npz_entry_sizes(path: Path) -> dict[str, int]:
    """Compressed bytes of each array in an ``.npz`` file, by array name."""
    with zipfile.ZipFile(path) as zf:
        return {zi.filename.removesuffix(".npy"): zi.compress_size for zi in zf.infolist()}
