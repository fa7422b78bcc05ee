"""A randomised sweep over the CLI: odd inputs, odd paths, odd numbers, any command.

Each case runs ``hybridev.cli.main`` in-process on a fresh copy of a folder of
inputs and asserts: no exception escapes, the exit code is 0 or 2, no
traceback is printed, no file of the folder is lost or changed (except a
regular file the case itself named as the output of a successful run, which is
what ``--out FILE`` means), no temporary file is left behind, and a failed run
writes no file. The sweep is a slow test (``-m slow``): 500 cases (it replaced a
10-case sweep that drew from the same generator, a subset of what it checks).
The sweep checks the commands' handling of their arguments and files, which does
not depend on the data's size nor on the chains' length, so a ``demo`` case runs
on 200 generated trips instead of the CLI's 1,500 (``tests/apps/test_demo.py``
checks the full-size output) and every physics posterior of a ``fit`` or
``calibrate`` case (the report's, the model's and its CV+ folds') runs
:data:`MCMC_STEPS` steps instead of adaptively to convergence (as in
``tests/apps/test_report.py``; the converged runs are tested there and in
``tests/bayes``).
"""

import contextlib
import functools
import io
import shutil
from collections import Counter

import numpy as np
import pandas as pd
import pytest

import hybridev.apps.demo
import hybridev.apps.report.build
import hybridev.learning.physics_stage
from hybridev.cli.main import main
from hybridev.core.owned import REGISTER_FILE

from .conftest import lost_files, snapshot
from .test_cli_odd import _bad_tables

FIT = ["--max-epochs", "2", "--n-steps", "60", "--quiet", "--members", "2"]
BAD = ["nan", "inf", "bool", "text", "huge", "dup", "header_only"]
DEMO_TRIPS = 200
MCMC_STEPS = 200


@pytest.fixture(scope="module")
def pool(fuzz_files, tmp_path_factory):
    d = tmp_path_factory.mktemp("pool")
    for p in fuzz_files.iterdir():
        (shutil.copytree if p.is_dir() else shutil.copy2)(p, d / p.name)
    for src in ("measured.csv", "trips.csv", "schedule.csv"):
        for kind, table in _bad_tables(pd.read_csv(d / src)).items():
            table.to_csv(d / f"{kind}_{src}", index=False)
    (d / "empty.csv").write_bytes(b"")
    (d / "garbage.csv").write_bytes(bytes(range(256)) * 8)
    (d / "user.csv").write_text("the user's table\n")
    (d / "notes.txt").write_text("the user's notes\n")
    (d / "userdir").mkdir()
    (d / "userdir" / "summary.json").write_text("{}")
    broken = d / "broken_model"
    shutil.copytree(d / "model", broken)
    arr = broken / "arrays.npz"
    arr.write_bytes(arr.read_bytes()[:-7])
    return d


def _pick(rng, items):
    return items[int(rng.integers(len(items)))]


def _table_arg(rng, src):
    return _pick(rng, [src, src, src, *(f"{k}_{src}" for k in BAD), "empty.csv", "garbage.csv",
                       "userdir", "missing.csv", "model"])


def _out(rng, kind):
    ext = {"table": ".csv", "figure": ".png", "dir": "", "merge": ""}[kind]
    new = f"new{ext}" if ext else "newdir"
    return _pick(rng, [new, new, f"deep/er/{new}", "user.csv", "notes.txt", "userdir", ".",
                       "model", f"notes.txt/x{ext}", "measured.csv", f"o.xlsx{ext}"[:6],
                       "trips.csv", "", f"model/in{ext}"])


def _num(rng, good, *bad):
    return str(_pick(rng, [good, good, good, *bad]))


def make_case(rng):
    cmd = _pick(rng, ["fit", "predict", "predict", "simulate", "range", "range",
                      "plan-charging", "calibrate", "demo", "fit"])
    if cmd == "fit":
        argv = ["fit", _table_arg(rng, "measured.csv"), "--out", _out(rng, "dir"), *FIT,
                "--seed", _num(rng, 0, -1, 2**70)]
        if rng.random() < 0.7:
            argv.append("--no-calibrate-physics")
        if rng.random() < 0.3:
            argv.append("--skip-bad-rows")
        return argv, "dir"
    if cmd == "predict":
        model = _pick(rng, ["model", "model", "paper", "broken_model", "userdir", "nomodel"])
        argv = ["predict", model, _table_arg(rng, "trips.csv"), "--out", _out(rng, "table")]
        if rng.random() < 0.3:
            argv += ["--level", _num(rng, 0.8, 0, 1, "nan", -0.5, 0.999)]
        return argv, "table"
    if cmd == "simulate":
        return ["simulate", "--quiet", "--n-trips", _num(rng, 5, 0, -3, 10**12), "--n-steps",
                _num(rng, 50, 2, 10**10), "--seed", _num(rng, 1, -1), "--out",
                _out(rng, "table")], "table"
    if cmd == "range":
        argv = ["range", "--soc", _num(rng, 0.8, 0, 1.5, "nan"), "--speed",
                _num(rng, 60, 0, 1e308, "inf"), "--temp", _num(rng, 5, -80, "nan"),
                "--seed", _num(rng, 0, -1)]
        if rng.random() < 0.6:
            argv += ["--model", _pick(rng, ["model", "model", "broken_model", "userdir"])]
        if rng.random() < 0.6:
            argv += ["--plot", _out(rng, "figure")]
        return argv, "figure"
    if cmd == "plan-charging":
        argv = ["plan-charging", _table_arg(rng, "schedule.csv"), "--tariff",
                _pick(rng, ["tariff.csv", "tariff.csv", "empty.csv", "measured.csv"]),
                "--soc-now", _num(rng, 0.6, -1, 2, "nan"), "--model",
                _pick(rng, ["model", "model", "paper", "broken_model"]), "--n-eval", "400",
                "--out", _out(rng, "table")]
        if rng.random() < 0.4:
            argv += ["--trips-out", _out(rng, "table")]
        return argv, "table"
    if cmd == "calibrate":
        argv = ["calibrate", _table_arg(rng, "measured.csv"), "--out", _out(rng, "dir"),
                "--max-epochs", "2", "--members", "2", "--quiet", "--seed", _num(rng, 0, -1)]
        if rng.random() < 0.3:
            argv += ["--posterior-steps", _num(rng, 50, 0, -5, 10**9)]
        return argv, "dir"
    # demo: a full run takes ~20 s, so most draws have a bad seed or path
    return ["demo", "--quick", "--quiet", "--seed", _num(rng, 0, -1, -1, -1, -1, -1),
            "--out", _out(rng, "merge")], "merge"


def _short_chain(calibrate_physics, *args, n_steps=None, **kwargs):
    """``calibrate_physics`` with a fixed run of at most :data:`MCMC_STEPS` steps."""
    return calibrate_physics(*args, n_steps=min(n_steps or MCMC_STEPS, MCMC_STEPS), **kwargs)


def run_case(pool_dir, work, case, monkeypatch):
    rng = np.random.default_rng(case)
    argv, _ = make_case(rng)
    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(pool_dir, work)
    monkeypatch.chdir(work)
    monkeypatch.setattr(hybridev.apps.demo, "run_demo",
                        functools.partial(hybridev.apps.demo.run_demo, n_trips=DEMO_TRIPS))
    before = snapshot(work)
    err, out = io.StringIO(), io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            rc = main(argv)
        except SystemExit as exc:
            rc = exc.code
    err = err.getvalue()
    after = snapshot(work)
    outs = {argv[i + 1] for i, a in enumerate(argv[:-1]) if a in ("--out", "--trips-out", "--plot")}
    allowed = set() if rc != 0 else {o for o in outs if (pool_dir / o).is_file()}
    assert rc in (0, 2), (argv, rc, err)
    assert "Traceback" not in err, (argv, err)
    assert lost_files(before, after, allowed) == [], (argv, err)
    assert not [p for p in work.rglob(".*")  # the marker and the register of file outputs
                if p.name not in ("_hybridev-manifest.json", REGISTER_FILE)], (
        argv, "temporary file left")
    if rc == 2:
        assert set(after) <= set(before), (argv, "a failed run wrote", set(after) - set(before))
        last = err.strip().splitlines()[-1]  # bad rows may be reported before the error
        assert last.startswith(f"hybridev {argv[0]}: error:"), err
    return argv[0], rc


def _sweep(pool, tmp_path, monkeypatch, cases):
    tally = Counter()
    for module in (hybridev.apps.report.build, hybridev.learning.physics_stage):
        monkeypatch.setattr(module, "calibrate_physics", functools.partial(
            _short_chain, module.calibrate_physics))
    for case in cases:
        cmd, rc = run_case(pool, tmp_path / "w", case, monkeypatch)
        tally[cmd, rc] += 1
    return tally


@pytest.mark.slow
def test_cli_sweep_500(pool, tmp_path, monkeypatch):
    tally = _sweep(pool, tmp_path, monkeypatch, range(1000, 1500))
    print("CLI sweep, 500 cases, (command, exit code) -> count:", dict(sorted(tally.items())))
    assert sum(tally.values()) == 500
    for cmd in {c for c, _ in tally}:  # each command both ran through and refused a case
        assert tally[cmd, 0] > 0 and tally[cmd, 2] > 0, (cmd, dict(tally))
