"""Fault injection on the real write paths: model folder, prediction file, fleet folder,
report folder and demo folder (slow: each case runs the writer in new processes).

As in :mod:`tests.core.test_crash`: an old output is written, a run that would
write a different new output is killed at a named step (``HYBRIDEV_FAULT``),
and the path must then hold the complete old or the complete new output; the
next run writes the new output and leaves nothing else beside it.

The old output and the reference new output of each writer are written once per
module by real runs (:func:`_made`); each case starts from a copy of the old
output's folder (the same bytes: ownership and manifests are by content and
relative name), so a case costs two processes, the killed run and the next one.

Those processes are fresh interpreters (``python -m hybridev.cli ...``) for the cases of
each writer's first step (every signal) and for the report's SIGTERM case; the other
cases run the same command in a forked child of one warm server per module
(``tests/docs/warm_cli.py``: the child gets the case's environment, so
``HYBRIDEV_FAULT``, and is killed by the real signal at the named step), which saves each
process the 3-4 CPU-seconds of importing torch, dask and the rest.
"""

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hybridev.core import swap
from hybridev.core.outputs import MANIFEST_FILE, REGISTER_FILE

sys.path.insert(0, str(Path(__file__).parents[1] / "docs"))
from warm_cli import WarmCli, client_argv  # tests/docs is not a package

pytestmark = pytest.mark.slow
ROOT = Path(__file__).parents[2]
SIGNALS = ("SIGINT", "SIGTERM", "SIGKILL")
DIR_STEPS = [s for s in swap.STEPS["dir"] if s != "dir.old_moved"]


def _py(args, fault=None, timeout=600, warm=None):
    """``python *args`` (``-m hybridev.cli ...`` or ``-c CODE``) in a fresh interpreter, or
    through the warm server ``warm``; ``fault``: ``HYBRIDEV_FAULT`` of the run."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("HYBRIDEV_FAULT", None)
    if fault:
        env["HYBRIDEV_FAULT"] = fault
    cmd, program = [sys.executable, *args], None
    if warm is not None and args[:2] == ["-m", "hybridev.cli"]:
        cmd = client_argv(warm, args[2:])
    elif warm is not None:
        assert args[0] == "-c" and len(args) == 2, args
        cmd, program = client_argv(warm, [], python=True), args[1]
    return subprocess.run(cmd, env=env, input=program, capture_output=True, text=True,
                          timeout=timeout, preexec_fn=lambda: [
                              signal.signal(s, signal.SIG_DFL)
                              for s in (signal.SIGINT, signal.SIGTERM)])


def snapshot(path: Path):
    if not path.exists():
        return None
    if path.is_file():
        return hashlib.sha256(path.read_bytes()).hexdigest()
    return {p.relative_to(path).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(path.rglob("*")) if p.is_file()
            and not p.relative_to(path).parts[0].startswith(".hybridev")}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    from hybridev import HybridModel, make_trips, simulate

    d = tmp_path_factory.mktemp("crash")
    t = simulate(make_trips(60, seed=3), n_steps=100, seed=3)
    t["energy_kwh"] = t["energy_kwh_physics"] * (1.05 + 0.03 * np.random.default_rng(3)
                                                 .normal(size=len(t)))
    meas = t[["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
              "soc_initial", "hour", "energy_kwh"]]
    meas.to_csv(d / "measured.csv", index=False)
    trips = meas.drop(columns=["energy_kwh"])
    trips.to_csv(d / "trips1.csv", index=False)
    trips.head(30).to_csv(d / "trips2.csv", index=False)
    for v, tab in (("1", trips), ("2", trips.head(30))):
        (d / f"ds{v}").mkdir()
        tab.to_parquet(d / f"ds{v}" / "part.parquet")
    HybridModel(max_epochs=3, n_steps=100, n_members=2).fit(meas, seed=0).save(d / "model1")
    HybridModel(max_epochs=3, n_steps=100, n_members=1, heteroscedastic=False,
                calibrate_physics=False, conformal_fraction=0.0).fit(
        meas, seed=0).save(d / "model2")
    return d


def _complete(path: Path) -> bool:
    """A folder whose manifest lists every file it holds, each with its SHA-256."""
    import json

    man = path / MANIFEST_FILE
    if not man.is_file():
        return False
    files = json.loads(man.read_text())["files"]
    held = {p.relative_to(path).as_posix() for p in path.rglob("*") if p.is_file()
            and not p.relative_to(path).parts[0].startswith(".hybridev")} - {MANIFEST_FILE}
    listed = {k for k, v in files.items() if v != "folder"}
    return held == listed and all(
        hashlib.sha256((path / k).read_bytes()).hexdigest() == files[k] for k in listed)


@pytest.fixture(scope="module")
def warm(tmp_path_factory):
    """The warm ``hybridev`` server of the module's cases (see the module docstring)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg")
    env.pop("HYBRIDEV_FAULT", None)
    cli = WarmCli(tmp_path_factory.mktemp("warm"), env)
    yield cli
    cli.close()


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """Folder of the once-written old and reference outputs, by writer."""
    return tmp_path_factory.mktemp("made")


def _made(write, made: Path, key: str, name: str, deterministic: bool = True):
    """``(folder holding the old output, new snapshot)`` of writer ``key``, written once.

    ``deterministic=False``: no reference run (two runs' outputs differ), new snapshot None."""
    home = made / key
    if not home.exists():
        work = made / f".{key}"
        (work / "ref").mkdir(parents=True)
        (work / "old").mkdir()
        new = None
        if deterministic:
            r = write("2", work / "ref" / name, None)
            assert r.returncode == 0, r.stderr
            new = snapshot(work / "ref" / name)
        (work / "new.json").write_text(json.dumps(new))
        r = write("1", work / "old" / name, None)
        assert r.returncode == 0, r.stderr
        work.rename(home)
    return home / "old", json.loads((home / "new.json").read_text())


def _case(write, target: Path, step: str, sig: str, expected: set[str], made: Path, key: str,
          deterministic: bool = True):
    """``write(version, path, fault)`` -> CompletedProcess.

    ``deterministic=False`` (a report, which records its own run time): the new output of
    two runs differs, so "the complete new output" is a folder other than the old one
    that its manifest describes completely."""
    old_dir, new = _made(write, made, key, target.name, deterministic)
    shutil.copytree(old_dir, target.parent, symlinks=True)  # the old output, as written
    old = snapshot(target)
    assert old is not None and old != new
    r = write("2", target, f"{step}:{sig}")
    assert r.returncode != 0, (step, sig, r.stdout, r.stderr)
    assert "Traceback" not in r.stderr or (sig == "SIGINT" and "KeyboardInterrupt" in r.stderr)
    got = snapshot(target)
    assert got in (old, new) or (not deterministic and _complete(target)), (step, sig)
    r = write("2", target, None)
    assert r.returncode == 0, (step, sig, r.stderr)
    if deterministic:
        assert snapshot(target) == new
    else:
        assert _complete(target) and snapshot(target) != old
    assert sorted(os.listdir(target.parent)) == sorted(expected), (step, sig)


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("step", DIR_STEPS)
def test_model_folder(files, made, warm, tmp_path, step, sig):
    server = None if step == DIR_STEPS[0] else warm

    def write(v, path, fault):
        code = (f"from hybridev import HybridModel; "
                f"HybridModel.load({str(files / f'model{v}')!r}).save({str(path)!r})")
        return _py(["-c", code], fault, warm=server)

    _case(write, tmp_path / "out" / "m", step, sig, {"m"}, made, "model")


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("step", swap.STEPS["file"])
def test_prediction_file(files, made, warm, tmp_path, step, sig):
    server = None if step == swap.STEPS["file"][0] else warm

    def write(v, path, fault):
        return _py(["-m", "hybridev.cli", "predict", str(files / "model1"),
                    str(files / f"trips{v}.csv"), "--out", str(path)], fault, warm=server)

    _case(write, tmp_path / "out" / "p.csv", step, sig, {"p.csv", REGISTER_FILE}, made, "pred")


@pytest.fixture(scope="module")
def scheduler():
    """The address of one single-worker dask cluster shared by the fleet cases.

    Each killed run and each next run is a fresh ``hybridev predict`` process that
    writes the fleet folder; they score on this cluster (``--scheduler``) rather than
    each starting its own worker process, which imports torch and hybridev for its
    first task. (The fleet how-to page, run by ``tests/docs/test_guides.py`` with
    ``-m slow``, runs ``hybridev predict --workers 2`` on its own cluster.)"""
    pytest.importorskip("dask.distributed")
    from hybridev.fleet.cluster import local_cluster

    cluster = local_cluster(1, memory_limit="2GiB")
    yield cluster.scheduler_address
    cluster.close()


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("step", DIR_STEPS)
def test_fleet_folder(files, made, scheduler, warm, tmp_path, step, sig):
    server = None if step == DIR_STEPS[0] else warm

    def write(v, path, fault):
        return _py(["-m", "hybridev.cli", "predict", str(files / "model1"), str(files / f"ds{v}"),
                    "--out", str(path), "--scheduler", scheduler], fault, warm=server)

    _case(write, tmp_path / "out" / "preds", step, sig, {"preds"}, made, "fleet")


@pytest.mark.parametrize("sig", SIGNALS)
def test_report_folder(files, made, warm, tmp_path, sig):
    server = None if sig == "SIGTERM" else warm

    def write(v, path, fault):
        meas = pd.read_csv(files / "measured.csv")
        src = tmp_path / f"measured{v}.csv"
        (meas if v == "1" else meas.head(50)).to_csv(src, index=False)
        return _py(["-m", "hybridev.cli", "calibrate", str(src), "--out", str(path),
                    "--members", "1", "--max-epochs", "3", "--posterior-steps", "100",
                    "--quiet"], fault, warm=server)

    _case(write, tmp_path / "out" / "rep", "dir.swapped", sig, {"rep"}, made, "report",
          deterministic=False)
    summary = json.loads((tmp_path / "out" / "rep" / "summary.json").read_text())
    assert summary["split"]["n_train"] + summary["split"]["n_test"] == 50  # the new input
    assert summary["config"]["calibrate_kwargs"] == {"n_steps": 100}  # --posterior-steps


def test_demo_folder_killed_mid_merge_is_completed_by_the_next_start(tmp_path):
    from hybridev.apps.demo import DEMO_OUTPUTS, _legacy_demo
    from hybridev.core.manifest import sha256_file
    from hybridev.core.outputs import check_output

    out = tmp_path / "results"
    out.mkdir()
    (out / "notes.txt").write_text("the user's")
    # the demo's merge of its outputs, on 300 trips rather than the CLI's 1,500 (the same
    # stages and files; tests/apps/test_demo.py runs the CLI's size): killed mid-merge
    code = ("import sys; from hybridev.apps.demo import run_demo; "
            "run_demo(sys.argv[1], quick=True, n_trips=300, echo=lambda s: None)")
    r = _py(["-c", code, str(out)], fault="merge.moved:SIGKILL", timeout=1800)
    assert r.returncode == -signal.SIGKILL, r.stderr
    assert any(n.startswith(".hybridev-merge.") for n in os.listdir(out))  # the journal
    check_output(out, kind="merge_dir", names=DEMO_OUTPUTS, legacy=_legacy_demo)  # next start
    names = sorted(os.listdir(out))
    assert not [n for n in names if n.startswith(".")], names
    assert (out / "notes.txt").read_text() == "the user's"
    man = __import__("json").loads((out / MANIFEST_FILE).read_text())
    for name, digest in man["files"].items():
        if digest != "folder":
            assert sha256_file(out / name) == digest
    assert (out / "report" / "report.html").is_file()
