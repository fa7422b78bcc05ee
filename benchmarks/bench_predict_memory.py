"""Benchmark: peak memory of ``hybridev predict`` on one big CSV file (streaming, issue 33).

Run from the repository root (nice: it takes a few CPU-minutes)::

    nice -n 10 python benchmarks/bench_predict_memory.py [--quick] [--out FILE]

Model: ``HybridModel(max_epochs=30)`` with otherwise default settings (physics
posterior, 5 heteroscedastic members, CV+ conformal step) fitted on 200
simulated trips (``simulate(make_trips(200, seed=0))``, energy = physics x 1.05
with 3 % noise). Trips: ``make_trips(n, seed=1)`` written as one CSV file.

Each size runs ``hybridev predict MODEL trips.csv --out preds.csv`` (default:
calibrated 90 % intervals) in a fresh process; ``os.wait4`` gives that
process's peak resident set size (``ru_maxrss``) and its CPU time (user +
system), beside the wall time and the load average. Sizes: 100,000 and
1,000,000 trips (``--quick``: 20,000 and 100,000). A streamed run reads, scores
and writes ``hybridev.cli.stream.CHUNK_ROWS`` trips at a time, so the peak
should not grow with the number of trips.

Target (issue 33): 1,000,000 trips from one CSV file under 2 GB peak.
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
import pandas as pd

TARGET_BYTES = 2 << 30


def _fit(folder: Path) -> Path:
    from hybridev import HybridModel, make_trips, simulate

    t = simulate(make_trips(200, seed=0), seed=0)
    z = np.random.default_rng(0).normal(size=len(t))
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.05 * (1.0 + 0.03 * z)
    HybridModel(max_epochs=30).fit(t, seed=0).save(folder / "model")
    return folder / "model"


def _run(model: Path, trips: Path, out: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(bench.ROOT))
    load0 = bench.load_average()
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "hybridev.cli", "predict", str(model),
                             str(trips), "--out", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    _, status, ru = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    stdout, stderr = proc.stdout.read().decode(), proc.stderr.read().decode()
    if os.waitstatus_to_exitcode(status) != 0:
        raise RuntimeError(f"predict failed: {stderr}")
    return {"peak_bytes": ru.ru_maxrss * 1024, "cpu_s": ru.ru_utime + ru.ru_stime,
            "wall_s": wall, "load": load0, "stdout": stdout.strip()}


def main(argv=None) -> int:
    args = bench.parse_args(__doc__, argv, name="bench_predict_memory")
    sizes = (20_000, 100_000) if args.quick else (100_000, 1_000_000)
    load = bench.load_average()
    from hybridev.cli import stream

    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_predict_memory.") as tmp:
        tmp = Path(tmp)
        t0 = time.process_time()
        model = _fit(tmp)
        fit_cpu = time.process_time() - t0
        from hybridev import make_trips

        for n in sizes:
            trips = tmp / f"trips{n}.csv"
            make_trips(n, seed=1).to_csv(trips, index=False)
            size = trips.stat().st_size
            r = _run(model, trips, tmp / f"preds{n}.csv")
            n_out = len(pd.read_csv(tmp / f"preds{n}.csv", usecols=["energy_kwh_pred"]))
            assert n_out == n, (n_out, n)
            print(f"{n} trips: peak {r['peak_bytes'] / 2**30:.2f} GiB, CPU {r['cpu_s']:.0f} s, "
                  f"wall {r['wall_s']:.0f} s ({r['stdout']})", flush=True)
            rows.append((f"{n:,}", f"{size / 2**20:.0f} MiB",
                         "yes" if size >= stream.STREAM_MIN_BYTES else "no",
                         f"{r['peak_bytes'] / 2**30:.2f} GiB ({r['peak_bytes'] / n:.0f} B/trip)",
                         f"{r['cpu_s']:.0f}", f"{r['wall_s']:.0f}",
                         " / ".join(f"{x:.2f}" for x in r["load"])))
            biggest = r
            trips.unlink()
    ok = biggest["peak_bytes"] < TARGET_BYTES
    md = f"""# bench_predict_memory

Command: `{args.command}`

Peak resident memory of `hybridev predict MODEL trips.csv --out preds.csv` (90 %
calibrated intervals) in a fresh process, by number of trips in one CSV file;
chunks of {stream.CHUNK_ROWS:,} trips when the file is at least
{stream.STREAM_MIN_BYTES / 2**20:.0f} MiB. Model fitted in {fit_cpu:.0f} CPU-s
(HybridModel(max_epochs=30), 200 trips).

{bench.markdown_table(["trips", "CSV size", "streamed", "peak RSS", "CPU s", "wall s",
                       "load average at start (1/5/15 min)"], rows)}

Target (issue 33): {sizes[-1]:,} trips under 2 GiB peak:
{bench.verdict(ok)} ({biggest['peak_bytes'] / 2**30:.2f} GiB).

{bench.machine_section(load=load, cores="no pinning (one predict process at a time)",
                       modules=(np, pd), times="wall times")}"""
    bench.write_result(md, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
