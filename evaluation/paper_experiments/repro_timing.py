"""Inference time per trip of the compared models (paper Table "Model Performance Comparison").

Wall-clock times with :func:`time.perf_counter`, one thread, in the calling
process (run it when nothing else of ours is running). ``predict`` is timed
end to end: input validation, the physics simulation (``n_steps=1000``), the
network and the output table. The dedicated speed benchmark with its targets
is ``benchmarks/bench_hybrid.py``.
"""

from __future__ import annotations

import os
import platform
import time

import numpy as np
import pandas as pd
import torch

from hybridev import ConstantRate, HybridModel, LinearBaseline, PhysicsOnly, PureML, make_dataset

from .repro_experiments import PAPER_NET, TRIP_COLUMNS, Config, split

__all__ = ["machine_info", "time_models"]

TIMED_MODELS = ("physics", "constant", "ols", "pure_ml", "hybrid_paper", "hybrid_default")


def machine_info() -> dict[str, str]:
    """CPU, cores, load average, library versions: the context of a timing."""
    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as fh:
            cpu = next((ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name")),
                       cpu)
    except OSError:
        pass
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg())
    return {"CPU": cpu, "cores visible": str(os.cpu_count()),
            "load average (1/5/15 min) before timing": load,
            "threads": "torch.set_num_threads(1)",
            "Python / numpy / pandas / torch": (f"{platform.python_version()} / {np.__version__}"
                                                f" / {pd.__version__} / {torch.__version__}")}


def _median_ms(fn, repeats: int, per: int = 1) -> tuple[float, float, float]:
    fn()  # warm-up
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t0) * 1e3 / per)
    q1, med, q3 = np.percentile(ts, [25, 50, 75])
    return float(med), float(q1), float(q3)


def time_models(cfg: Config, *, truth: str = "structured", seed: int = 0,
                repeats: int = 60) -> pd.DataFrame:
    """Median (IQR) ms per trip: one trip per call, batches of 20 and of the 225 test trips."""
    torch.set_num_threads(1)
    ds = make_dataset(cfg.n_trips, truth=truth, seed=seed)
    fit_rows, test_rows = split(len(ds), cfg.n_test, seed)
    fit, test = ds.iloc[fit_rows], ds.iloc[test_rows][TRIP_COLUMNS].reset_index(drop=True)
    kw = dict(physics_seed=seed, max_epochs=cfg.max_epochs)
    models = {"physics": PhysicsOnly(physics_seed=seed), "constant": ConstantRate(),
              "ols": LinearBaseline(), "pure_ml": PureML(**PAPER_NET, **kw),
              "hybrid_paper": HybridModel(**PAPER_NET, **kw), "hybrid_default": HybridModel(**kw)}
    rows = []
    for key in TIMED_MODELS:
        m = models[key]
        m.fit(fit, **({"seed": seed} if isinstance(m, HybridModel) else {}))
        singles = [test.iloc[[i]] for i in range(repeats)]
        it = iter(singles * 2)
        single = _median_ms(lambda m=m, it=it: m.predict(next(it)), repeats)
        b20 = _median_ms(lambda m=m: m.predict(test.iloc[:20]), max(repeats // 2, 3), per=20)
        ball = _median_ms(lambda m=m: m.predict(test), max(repeats // 3, 3), per=len(test))
        rows.append({"model": key, "single_ms": single[0], "single_q1": single[1],
                     "single_q3": single[2], "batch20_ms": b20[0], "batch_all_ms": ball[0],
                     "batch_all_n": len(test)})
    return pd.DataFrame(rows)
