"""Fault injection: a process killed at every step of every writer leaves old or new, never neither.

Each case runs a small writer in a subprocess: the old output, written once per
module by a first run, is copied in (its reference new output too, see ``_made``);
a second run is killed (SIGINT, SIGTERM or SIGKILL, sent by the process to itself
at a named step through ``HYBRIDEV_FAULT``: no timing); a third run writes again. After the kill the user's path holds the complete old
or the complete new output (for a merged folder after SIGKILL past its journal:
the journal is there, and the next run completes the new output); after the
third run it holds the new output and nothing else is left beside it.
"""

import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from hybridev.core import swap
from hybridev.core.manifest import MANIFEST_FILE
from hybridev.core.owned import REGISTER_FILE

ROOT = Path(__file__).parents[2]
SIGNALS = ("SIGINT", "SIGTERM", "SIGKILL")

_WRITER = textwrap.dedent("""
    import sys
    from hybridev.core.outputs import atomic_file, output_dir
    kind, target, version = sys.argv[1], sys.argv[2], sys.argv[3]
    if kind == "file":
        with atomic_file(target) as tmp:
            tmp.write_text("trip_id,energy_kwh\\n" + version * 1000 + "\\n")
    else:
        with output_dir(target, kind=kind) as tmp:
            (tmp / "a.txt").write_text(version * 1000)
            if kind == "merge_dir":  # a sub-folder of a merged folder carries its own marker
                with output_dir(tmp / "sub", kind="dir") as sub:
                    (sub / "b.txt").write_text(version + "b")
            else:
                (tmp / "sub").mkdir()
                (tmp / "sub" / "b.txt").write_text(version + "b")
""")


def _run(kind, target, version, fault=None, no_exchange=False):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    env.pop("HYBRIDEV_FAULT", None)
    env.pop("HYBRIDEV_NO_EXCHANGE", None)
    if fault:
        env["HYBRIDEV_FAULT"] = fault
    if no_exchange:
        env["HYBRIDEV_NO_EXCHANGE"] = "1"
    return subprocess.run([sys.executable, "-c", _WRITER, kind, str(target), version],
                          env=env, capture_output=True, text=True, timeout=120,
                          preexec_fn=lambda: [signal.signal(s, signal.SIG_DFL)
                                              for s in (signal.SIGINT, signal.SIGTERM)])


def snapshot(path: Path) -> dict[str, str] | None:
    """Relative path -> content of every file (None: the path does not exist)."""
    if not path.exists():
        return None
    if path.is_file():
        return {".": path.read_text()}
    # a merged folder's hidden staging and journal are not part of the output (the final
    # check of each case lists the folder: they are gone after the next run)
    return {p.relative_to(path).as_posix(): p.read_text() for p in sorted(path.rglob("*"))
            if p.is_file() and not p.relative_to(path).parts[0].startswith(".hybridev")}


def _leftovers(parent: Path, expected: set[str]) -> list[str]:
    return sorted(set(os.listdir(parent)) - expected)


def _user_files(snap):
    return {k: v for k, v in (snap or {}).items() if k != MANIFEST_FILE}


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """Per writer kind, the once-written old output and the reference new one (see _made)."""
    return tmp_path_factory.mktemp("made"), {}


def _made(made, kind):
    """``(folder holding the old output, old snapshot, new snapshot)`` of ``kind``.

    Written once per module by real runs: the old output (run "1"), and the new output
    of a second run over an old one (runs "1" then "2"), as every case expects it.
    Each case starts from a byte copy of the old output's folder (manifests and the
    file register name files relative to their folder), so it costs two runs, the
    killed one and the next one, instead of four.
    """
    root, cache = made
    if kind not in cache:
        home = root / kind
        parent = home / "out"
        target = parent / ("p.csv" if kind == "file" else "res")
        if kind == "merge_dir":
            target.mkdir(parents=True)
            (target / "mine.txt").write_text("the user's")  # kept by every run
        assert _run(kind, target, "1").returncode == 0
        ref = home / "ref" / target.name
        if kind == "merge_dir":
            ref.mkdir(parents=True)
            (ref / "mine.txt").write_text("the user's")
        assert _run(kind, ref, "1").returncode == 0
        assert _run(kind, ref, "2").returncode == 0
        cache[kind] = parent, snapshot(target), snapshot(ref)
    return cache[kind]


def _check_case(made, tmp_path, kind, step, sig, no_exchange=False):
    old_parent, old, new = _made(made, kind)
    parent = tmp_path / "out"
    shutil.copytree(old_parent, parent)
    target = parent / ("p.csv" if kind == "file" else "res")
    assert snapshot(target) == old
    assert _user_files(old) != _user_files(new)
    r = _run(kind, target, "2", fault=f"{step}:{sig}", no_exchange=no_exchange)
    assert r.returncode != 0, (step, sig, r.stderr)  # the fault fired
    after = snapshot(target)
    journal = kind == "merge_dir" and any(n.startswith(".hybridev-merge.")
                                          for n in os.listdir(target))
    fallback_gap = no_exchange and step == "dir.old_moved" and sig == "SIGKILL"
    if not (journal or fallback_gap):
        assert after in (old, new), (step, sig, after)
    if fallback_gap:  # the journal (.old) is there; recovery puts the old folder back
        swap.recover(target)
        assert snapshot(target) == old
    # the next run succeeds, and leaves the new output and nothing else
    r = _run(kind, target, "2")
    assert r.returncode == 0, (step, sig, r.stderr)
    assert snapshot(target) == new
    expected = {target.name, REGISTER_FILE} if kind == "file" else {target.name}
    assert _leftovers(parent, expected) == [], (step, sig)
    if kind == "merge_dir":
        assert sorted(os.listdir(target)) == sorted([MANIFEST_FILE, "a.txt", "sub", "mine.txt"])


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("step", [s for s in swap.STEPS["dir"] if s != "dir.old_moved"])
def test_folder_replacement_is_old_or_new_at_every_step(made, tmp_path, step, sig):
    _check_case(made, tmp_path, "model_dir", step, sig)


@pytest.mark.slow
@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("step", swap.STEPS["dir"])
def test_folder_replacement_without_exchange_recovers(made, tmp_path, step, sig):
    _check_case(made, tmp_path, "dir", step, sig, no_exchange=True)


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("step", swap.STEPS["file"])
def test_file_replacement_is_old_or_new_at_every_step(made, tmp_path, step, sig):
    _check_case(made, tmp_path, "file", step, sig)


@pytest.mark.parametrize("sig", SIGNALS)
@pytest.mark.parametrize("step", swap.STEPS["merge"])
def test_merged_folder_is_old_or_new_or_completed_from_its_journal(made, tmp_path, step, sig):
    _check_case(made, tmp_path, "merge_dir", step, sig)


def test_recovery_says_what_it_did(tmp_path):
    parent = tmp_path / "out"
    target = parent / "res"
    assert _run("dir", target, "1").returncode == 0
    r = _run("dir", target, "2", fault="dir.swapped:SIGKILL")
    assert r.returncode == -signal.SIGKILL
    assert len(os.listdir(parent)) == 2  # the new output and the old one under a hidden name
    r = _run("dir", target, "3")
    assert r.returncode == 0
    assert "RecoveryWarning" in r.stderr and "interrupted earlier run" in r.stderr
    assert os.listdir(parent) == ["res"]


def test_leftovers_of_running_processes_are_left_alone(tmp_path):
    target = tmp_path / "res"
    target.mkdir()
    mine = tmp_path / f".res.{os.getpid()}.abc.tmp"
    mine.mkdir()
    assert swap.recover(target) == []
    assert mine.exists()
