"""CPU time of the test suites: the default one and ``-m slow``, each as CI runs it.

Run from the repository root::

    python benchmarks/bench_test_suite.py                   # both suites, one after the other
    python benchmarks/bench_test_suite.py --parallel        # both at once (same CPU figures)
    python benchmarks/bench_test_suite.py --suite default   # one of them

Each suite is ``python -m pytest -q -p no:cacheprovider -n 2 --dist loadfile`` (plus
``-m slow``), the README's test command, in a child process. Its CPU time is user +
system time of that process and of every process it waited for (the xdist workers,
the CLI and notebook-kernel subprocesses, the dask workers, the warm CLI server of the
docs tests), read with ``os.wait4``; so the figure does not depend on how loaded the
shared machine is, unlike the wall time printed beside it with the load average.
Target (issue 34): default suite <= 4 CPU-minutes, ``-m slow`` <= 10.

The plugin ``benchmarks/_pytest_cpu.py`` also logs each test's CPU time (its process
and its waited-for children); the 15 costliest tests of each suite are listed.
The result goes to ``benchmarks/results/bench_test_suite.md`` (``--out``). This
script does not set the one-thread BLAS variables of the other benchmarks
(``_common.py``): the suites run as a developer runs them.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results" / "bench_test_suite.md"
SUITES = {"default": [], "slow": ["-m", "slow"]}
TARGET_MIN = {"default": 4.0, "slow": 10.0}
BASE = ["-m", "pytest", "-q", "-p", "no:cacheprovider", "-p", "_pytest_cpu",
        "-n", "2", "--dist", "loadfile"]


def _load() -> tuple[float, float, float]:
    return os.getloadavg()


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def start(name: str, log: Path, nice: int) -> dict:
    env = dict(os.environ, HYBRIDEV_TEST_CPU_LOG=str(log),
               PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT / "benchmarks"),
                                                        os.environ.get("PYTHONPATH")])))
    out = open(log.with_suffix(".out"), "w+", encoding="utf-8")
    cmd = [sys.executable, *BASE, *SUITES[name]]
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=subprocess.STDOUT,
                            preexec_fn=(lambda: os.nice(nice)) if nice else None)
    return {"name": name, "proc": proc, "out": out, "log": log, "cmd": cmd,
            "t0": time.perf_counter(), "load0": _load()}


def finish(run: dict, status: int, usage) -> dict:
    run["wall_s"] = time.perf_counter() - run["t0"]
    run["load1"] = _load()
    run["rc"] = os.waitstatus_to_exitcode(status)
    run["user_s"], run["sys_s"] = usage.ru_utime, usage.ru_stime
    run["out"].seek(0)
    text = run["out"].read()
    run["out"].close()
    tail = [ln for ln in text.strip().splitlines() if re.search(r"passed|failed|error", ln)]
    run["summary"] = tail[-1].strip("= ") if tail else "(no summary line)"
    rows = []
    if run["log"].exists():
        rows = [json.loads(ln) for ln in run["log"].read_text().splitlines() if ln.strip()]
    run["tests"] = sorted(rows, key=lambda r: -r["cpu_s"])
    return run


def wait_all(runs: list[dict]) -> list[dict]:
    left = {r["proc"].pid: r for r in runs}
    done = []
    while left:
        pid, status, usage = os.wait4(-1, 0)
        if pid in left:
            done.append(finish(left.pop(pid), status, usage))
    return done


def report(runs: list[dict], parallel: bool, nice: int) -> str:
    import hybridev

    lines = ["# Test suite CPU time", "",
             f"Written by `python benchmarks/{Path(__file__).name}` on "
             f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC"
             f"{' (--parallel: both suites at once)' if parallel else ''}"
             f", at niceness {os.nice(0) + nice}. CPU time = user + system time of the "
             "pytest process and of every process it waited for (xdist workers, CLI and "
             "kernel subprocesses, dask workers), from `os.wait4`; the wall time depends on "
             "the machine's load, given beside it.", "",
             "| suite | command | result | CPU time | wall time | load average at start / end "
             "(1 min) | target | |", "|---|---|---|---|---|---|---|---|"]
    for r in sorted(runs, key=lambda r: list(SUITES).index(r["name"])):
        cpu = r["user_s"] + r["sys_s"]
        ok = cpu / 60 <= TARGET_MIN[r["name"]] and r["rc"] == 0
        lines.append(
            f"| {r['name']} | `python {' '.join(BASE[:5] + BASE[7:])}"
            f"{' ' + ' '.join(SUITES[r['name']]) if SUITES[r['name']] else ''}` | "
            f"{r['summary']} (exit {r['rc']}) | **{cpu / 60:.2f} min** ({r['user_s']:.0f} s "
            f"user + {r['sys_s']:.0f} s system) | {r['wall_s'] / 60:.2f} min | "
            f"{r['load0'][0]:.1f} / {r['load1'][0]:.1f} | <= {TARGET_MIN[r['name']]:g} min | "
            f"{'met' if ok else 'MISSED'} |")
    for r in runs:
        lines += ["", f"## The 15 costliest tests of the {r['name']} suite (CPU s)", "",
                  "CPU time of the test's process and its waited-for children during setup, "
                  "call and teardown (a session fixture is charged to the first test that "
                  "uses it); wall time under the load above.", "",
                  "| CPU s | wall s | test |", "|---:|---:|---|"]
        lines += [f"| {t['cpu_s']:.1f} | {t['wall_s']:.1f} | `{t['nodeid']}` |"
                  for t in r["tests"][:15]]
        lines.append(f"\n{len(r['tests'])} tests logged, {sum(t['cpu_s'] for t in r['tests']):.0f}"
                     " CPU s in them (the rest: collection and start-up of the workers).")
    lines += ["", "## Machine", "",
              f"- CPU: {_cpu_model()}; {os.cpu_count()} cores visible, shared with other jobs",
              f"- Python {platform.python_version()}, hybridev {hybridev.__version__}", ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--suite", choices=["both", *SUITES], default="both")
    p.add_argument("--parallel", action="store_true", help="run the two suites at once")
    p.add_argument("--nice", type=int, default=0, help="run the suites at this niceness")
    p.add_argument("--out", type=Path, default=None,
                   help="result file (markdown; default results/bench_test_suite.md, "
                        "or bench_test_suite_<suite>.md for one suite)")
    args = p.parse_args(argv)
    if args.out is None:
        args.out = OUT if args.suite == "both" else OUT.with_name(f"{OUT.stem}_{args.suite}.md")
    names = list(SUITES) if args.suite == "both" else [args.suite]
    with tempfile.TemporaryDirectory() as tmp:
        logs = {n: Path(tmp) / f"{n}.jsonl" for n in names}
        if args.parallel:
            runs = wait_all([start(n, logs[n], args.nice) for n in names])
        else:
            runs = [wait_all([start(n, logs[n], args.nice)])[0] for n in names]
        text = report(runs, args.parallel, args.nice)
    from hybridev.core.fileio import atomic_path

    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out) as tmp_out:
        tmp_out.write_text(text, encoding="utf-8")
    print(text)
    return max(r["rc"] for r in runs)


if __name__ == "__main__":
    sys.exit(main())
