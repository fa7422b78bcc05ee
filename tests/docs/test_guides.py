"""Every code block of the README, the get-started and the how-to pages runs, in order.

A page becomes one bash script (:func:`page_script`): its ```bash blocks verbatim, and
each run of consecutive ```python blocks as one ``python`` process (so a later block
sees an earlier one's variables), with ``hybridev`` on the PATH from this source tree
and ``TMPDIR`` inside the test's temporary folder (so ``cd "$(mktemp -d)"`` lands
there and nothing is left behind). Blocks in other languages are not run: ``text``
(output, diagrams) and ``sh``, kept for the installation commands, which must not run
here (they create environments and download packages).

* Default suite: the model fits are made small (:data:`FAST`: 2 networks, 15 epochs;
  :data:`PAGE_FAST`: fewer trips where a page's fit is dear), which changes the
  numbers, not the commands; every substitution must match.
* Slow: the pages exactly as written, and the fleet page (a dask cluster; with the
  default suite's substitutions and half its vehicles).

``hybridev`` and the python blocks run in one warm server per test process
(``warm_cli.py``: forked per call, no re-import of torch); the console command in a
fresh interpreter is tested by ``tests/cli`` (every command's exit codes) and by the
own-car guide on the real trips.

``docs/own_car.md`` has its own test (``test_own_car_guide.py``: real trips).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from warm_cli import hybridev_bin

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
PAGES = ("../README.md", "get-started/first-prediction.md", "get-started/your-own-car.md", "how-to/range.md",
         "how-to/charging.md", "how-to/report.md")
SLOW_PAGES = ("how-to/fleet.md",)
FAST = (  # (pattern, replacement): smaller fits for the default suite
    (r"^(hybridev (?:fit|calibrate) .*)$", r"\1 --members 2 --max-epochs 15"),
    (r"HybridModel\(\)", "HybridModel(n_members=2, max_epochs=15)"),
    (r"HybridModel\(car\)", "HybridModel(car, n_members=2, max_epochs=15)"),
)
PAGE_FAST = {  # page: further (pattern, replacement), smaller data where the page's fit is dear
    # the README's coast-down car: its posterior runs about 19,000 MCMC steps on 250 trips
    # (22 CPU-seconds), about 5,700 on 50; the code is the same, the numbers smaller
    "../README.md": ((r"make_dataset\(300,", "make_dataset(60,"),
                     (r"iloc\[:250\]", "iloc[:50]"), (r"iloc\[250:\]", "iloc[50:]")),
    # the fleet page (slow): half the vehicles, the same commands (a posterior and a model
    # per vehicle; 6 still make a fleet prior and the robust z-scores of the flags)
    "how-to/fleet.md": ((r"make_fleet\(n_vehicles=12,", "make_fleet(n_vehicles=6,"),),
}
_BLOCK = re.compile(r"^```(\w+)\n(.*?)^```\s*$", re.M | re.S)


def blocks(page: str) -> list[tuple[str, str]]:
    """``(language, code)`` of every fenced block of ``docs/<page>``, in order."""
    return [(m.group(1), m.group(2)) for m in _BLOCK.finditer((DOCS / page).read_text())]


def page_script(page: str) -> str:
    """The page's bash and python blocks as one bash script (python runs grouped)."""
    parts, py = ["set -euo pipefail"], []

    def flush():
        if py:
            parts.append('"$HYBRIDEV_PYTHON" - <<\'HYBRIDEV_DOC_PY\'\n' + "\n".join(py)
                         + "\nHYBRIDEV_DOC_PY")
            py.clear()

    for lang, code in blocks(page):
        if lang == "python":
            py.append(code)
        elif lang == "bash":
            flush()
            parts.append(code)
    flush()
    return "\n".join(parts) + "\n"


def fast(script: str, page: str | None = None) -> str:
    for pattern, repl in (*FAST, *PAGE_FAST.get(page, ())):
        script = re.sub(pattern, repl, script, flags=re.M)
    return script


def run_page(script: str, workdir: Path, timeout: int = 1200, warm=None) -> str:
    """Run ``script``; ``hybridev`` is a fresh interpreter per call, or ``warm``'s client."""
    bin_dir = hybridev_bin(workdir, warm)
    python = sys.executable if warm is None else str(warm.write_python(bin_dir))
    tmp = workdir / "tmp"
    tmp.mkdir()
    env = dict(os.environ, PATH=f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
               PYTHONPATH=f"{ROOT}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
               HYBRIDEV_PYTHON=python, TMPDIR=str(tmp), MPLBACKEND="Agg")
    res = subprocess.run(["bash", "-c", script], cwd=tmp, env=env, capture_output=True,
                         text=True, timeout=timeout)
    assert res.returncode == 0, f"page failed:\n{script}\n{res.stdout}\n{res.stderr}"
    return res.stdout


def test_every_page_has_runnable_blocks_and_fast_substitutions_match():
    for page in (*PAGES, *SLOW_PAGES):
        langs = {lang for lang, _ in blocks(page)}
        assert langs & {"bash", "python"}, page
        assert langs <= {"bash", "python", "text", "sh"}, (page, langs)
        sh = [code for lang, code in blocks(page) if lang == "sh"]
        assert all("pip install" in code for code in sh), (page, "sh is for installation only")
    script = "\n".join(page_script(p) for p in (*PAGES, *SLOW_PAGES))
    for pattern, _ in FAST:
        assert re.search(pattern, script, flags=re.M), pattern
    for page, subs in PAGE_FAST.items():
        for pattern, _ in subs:
            assert re.search(pattern, page_script(page), flags=re.M), (page, pattern)


def test_page_script_groups_python_runs():
    script = page_script("get-started/first-prediction.md")
    assert script.count("\"$HYBRIDEV_PYTHON\" -") == 1  # three python blocks, one process


@pytest.mark.parametrize("page", PAGES)
def test_page_runs(page, tmp_path, warm_cli):
    out = run_page(fast(page_script(page), page), tmp_path, warm=warm_cli)
    if page == "how-to/range.md":
        band = [float(v) for v in re.findall(r"q[159]0\s+([0-9.]+) km", out)]
        assert len(band) == 3 and band[0] <= band[1] <= band[2]
        assert list(tmp_path.glob("tmp/tmp*/fan.png"))
    if page == "how-to/report.md":
        assert list(tmp_path.glob("tmp/tmp*/report/report.html"))
    if page == "get-started/first-prediction.md":
        assert "new trips inside their 90 % interval" in out


@pytest.mark.slow
@pytest.mark.parametrize("page", SLOW_PAGES)
def test_slow_page_runs(page, tmp_path):
    pytest.importorskip("dask.dataframe")
    out = run_page(fast(page_script(page), page), tmp_path)
    assert "energy_kwh_pred" in out
    assert list(tmp_path.glob("tmp/fleet-report/fleet_report.html"))


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES)
def test_page_runs_as_written(page, tmp_path, warm_cli):
    run_page(page_script(page), tmp_path, warm=warm_cli)
