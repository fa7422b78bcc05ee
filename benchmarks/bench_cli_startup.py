"""Benchmark: how fast the CLI answers before any heavy import (issue 32, item 6).

Run from the repository root::

    python benchmarks/bench_cli_startup.py [--quick] [--repeats N] [--out FILE]

Each command runs ``repeats`` times in a fresh process (``python -m hybridev.cli
...``); ``os.wait4`` gives the process's CPU time (user + system) beside the
wall time. Commands: ``--help``, ``predict --help``, ``--version``, a missing
input file (``predict MODEL missing.csv`` with an existing model folder), the
issue's form ``predict missing.csv --model m`` (an unknown option: the model is
positional) and a misspelt option (``range --sped 50``). Each must exit with 0
(help, version) or 2, and none may import torch (checked separately by
``tests/cli/test_cli_issue33.py``).

Target (issue 32): a missing input file reported in under 1 s.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _common as bench
import numpy as np

CASES = (
    ("hybridev --help", ["--help"], 0),
    ("hybridev predict --help", ["predict", "--help"], 0),
    ("hybridev --version", ["--version"], 0),
    ("hybridev predict m missing.csv", ["predict", "m", "missing.csv"], 2),
    ("hybridev predict missing.csv --model m", ["predict", "missing.csv", "--model", "m"], 2),
    ("hybridev range --sped 50 ...", ["range", "--sped", "50", "--soc", "0.9", "--temp", "5"],
     2),
)


def _once(argv, cwd) -> tuple[float, float, int]:
    env = dict(os.environ, PYTHONPATH=str(bench.ROOT))
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "hybridev.cli", *argv], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, ru = os.wait4(proc.pid, 0)
    return time.perf_counter() - t0, ru.ru_utime + ru.ru_stime, os.waitstatus_to_exitcode(status)


def main(argv=None) -> int:
    args = bench.parse_args(__doc__, argv, name="bench_cli_startup",
                            counts={"repeats": (7, 2, "runs of each command")})
    load = bench.load_average()
    rows, worst_missing = [], 0.0
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "m").mkdir()
        for label, cmd, want in CASES:
            runs = [_once(cmd, tmp) for _ in range(args.repeats)]
            codes = {c for _, _, c in runs}
            assert codes == {want}, (label, codes)
            wall = np.array([w for w, _, _ in runs])
            cpu = np.array([c for _, c, _ in runs])
            if "missing" in label:
                worst_missing = max(worst_missing, float(wall.max()))
            rows.append((f"`{label}`", want, bench.median_iqr(wall), bench.median_iqr(cpu),
                         f"{wall.max():.3f} s"))
            print(label, f"{np.median(wall):.3f} s wall, {np.median(cpu):.3f} s CPU", flush=True)
    ok = worst_missing < 1.0
    md = f"""# bench_cli_startup

Command: `{args.command}`

Fresh process per run (`python -m hybridev.cli ...`), {args.repeats} runs each; median
[IQR] of the wall and CPU time, and the slowest wall time.

{bench.markdown_table(["command", "exit code", "wall", "CPU", "slowest wall"], rows)}

Target (issue 32): a missing input reported in under 1 s: {bench.verdict(ok)}
(slowest {worst_missing:.3f} s wall).

{bench.machine_section(load=load, cores="no pinning", modules=(np,), times="wall times")}"""
    bench.write_result(md, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
