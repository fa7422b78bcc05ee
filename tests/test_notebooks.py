"""The tutorial notebooks run top to bottom, carry no outputs and are what ``_build.py`` writes.

Each notebook is executed with nbclient in a kernel started on *this* interpreter
(a temporary kernelspec whose argv is ``sys.executable``), so a fresh virtual
environment needs no ``ipykernel install``. The notebooks' own cells hold the
checks of their narrative (e.g. save/load round trip, every file row accounted
for); here a notebook fails on any cell error and on anything written to
stderr (warnings in a tutorial are how it goes stale).

Run time: each execution is a fresh kernel (about 3-5 s of start-up and
imports) plus the notebook. 01 and 04 (one small model fit each) run in the
default suite; 02 (four fits) and 03 (two MCMC runs, a fit and an HTML report)
take 15-30 s each on a loaded 2-core machine, which would push the four past a
minute, so they are marked slow (``pytest -m slow tests/test_notebooks.py``).
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import nbformat
import pytest
from jupyter_client import AsyncKernelManager
from jupyter_client.kernelspec import KernelSpecManager
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
NB_DIR = ROOT / "notebooks"
EXPECTED = (
    "01_quickstart.ipynb",
    "02_reproducing_the_paper.ipynb",
    "03_calibration_from_measured_trips.ipynb",
    "04_range_and_charging.ipynb",
)
NOTEBOOKS = sorted(p.name for p in NB_DIR.glob("*.ipynb"))
SLOW = {"02_reproducing_the_paper.ipynb", "03_calibration_from_measured_trips.ipynb"}
"""Notebooks run with ``-m slow`` only: 02 (four fits) and 03 (two MCMC runs, a fit and
an HTML report); 01 and 04 (one small fit each) run in the default suite."""
KERNEL_NAME = "hybridev-test-python"


def _load_build():
    spec = importlib.util.spec_from_file_location("_notebooks_build", NB_DIR / "_build.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="session")
def kernel_dir(tmp_path_factory) -> str:
    """A kernelspec directory whose only kernel runs on sys.executable."""
    base = tmp_path_factory.mktemp("kernels")
    spec = base / KERNEL_NAME
    spec.mkdir()
    (spec / "kernel.json").write_text(json.dumps({
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "hybridev tests (this interpreter)",
        "language": "python",
    }))
    return str(base)


def _files(folder: Path) -> set[str]:
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*")
            if ".ipynb_checkpoints" not in p.parts and "__pycache__" not in p.parts}


def test_the_four_tutorials_exist_and_nothing_else():
    assert set(EXPECTED) <= set(NOTEBOOKS)
    assert set(NOTEBOOKS) == set(_load_build().NOTEBOOKS)  # every notebook is generated


@pytest.mark.parametrize("name", NOTEBOOKS)
def test_notebook_is_committed_without_outputs(name):
    nb = nbformat.read(NB_DIR / name, as_version=4)
    nbformat.validate(nb)
    assert nb.metadata["kernelspec"]["name"] == "python3"
    for cell in nb.cells:
        assert "execution" not in cell.metadata, cell.id
        if cell.cell_type == "code":
            assert cell.outputs == [] and cell.execution_count is None, cell.id


def test_build_regenerates_the_committed_notebooks():
    rendered = _load_build().render()
    for name, text in rendered.items():
        assert (NB_DIR / name).read_text(encoding="utf-8") == text, (
            f"{name} differs from notebooks/_build.py: run python notebooks/_build.py")


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n in SLOW else n
                                  for n in NOTEBOOKS])
def test_notebook_runs_top_to_bottom(name, kernel_dir):
    nb = nbformat.read(NB_DIR / name, as_version=4)
    before = _files(NB_DIR)
    km = AsyncKernelManager(kernel_name=KERNEL_NAME,
                            kernel_spec_manager=KernelSpecManager(kernel_dirs=[kernel_dir]))
    client = NotebookClient(nb, km=km, timeout=600, kernel_name=KERNEL_NAME,
                            resources={"metadata": {"path": str(NB_DIR)}})
    client.execute(cleanup_kc=True)  # raises CellExecutionError naming the failing cell
    assert not km.has_kernel
    stderr = [(cell.id, out.text) for cell in nb.cells if cell.cell_type == "code"
              for out in cell.outputs if out.output_type == "stream" and out.name == "stderr"]
    assert not stderr, f"{name} wrote to stderr: {stderr}"
    assert all(cell.execution_count for cell in nb.cells if cell.cell_type == "code")
    assert _files(NB_DIR) == before, "a notebook wrote files into the repository"
