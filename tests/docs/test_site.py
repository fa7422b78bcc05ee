"""The documentation site builds offline with warnings as errors, and its generated parts
are current.

``mkdocs build --strict`` (slow: it renders the API reference of every module and runs
``hybridev <command> --help`` for the CLI reference) fails on any broken link, page
missing from the navigation or docstring that does not parse. Skipped when MkDocs is not
installed (``pip install -e ".[docs]"``; the ``dev`` extra includes it).
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs" / "scripts"))
sys.path.insert(0, str(ROOT / "docs" / "hooks"))

HAVE_MKDOCS = all(importlib.util.find_spec(m) for m in (
    "mkdocs", "material", "mkdocstrings_handlers.python", "mkdocs_jupyter", "latex2mathml"))


def test_results_pages_are_current():
    """docs/results/*.md equal what docs/scripts/gen_results.py writes from the committed
    evaluation outputs (after re-running a study: python docs/scripts/gen_results.py)."""
    import gen_results

    assert gen_results.main(["--check"]) == 0
    index = (ROOT / "docs" / "results" / "index.md").read_text()
    h = gen_results.headline()
    assert f"{h['mape']['hybrid']:.2f} %" in index and f"{h['mape']['nnls_stats']:.2f} %" in index


def test_readme_quotes_the_committed_results():
    """The README's headline figures are the results pages' (from committed outputs)."""
    import gen_results

    readme = (ROOT / "README.md").read_text()
    h = gen_results.headline()
    for key in ("hybrid", "nnls_stats", "linreg_summary", "median_kwh_per_km",
                "nominal_physics"):
        assert f"| {h['mape'][key]:.2f} % |" in readme, key
    for v in h["coverage"].values():
        assert f"| {v['coverage']:.3f} | {100 * v['rel_width']:.0f} % of the energy |" in readme
    p = h["planned"]
    assert (f"{p['mape']:.2f} % MAPE against {p['linreg']:.2f} %" in readme
            and f"{p['coverage']:.3f} inside the 90 % intervals" in readme)
    r = h["risk"]
    assert f"{100 * r['mean']:.1f} % ± {100 * r['se']:.1f} %" in readme
    assert f"did {100 * h['risk_neutral']:.0f} % of the time" in readme
    assert len(readme.splitlines()) <= 150
    assert "issue" not in readme.lower()


def test_every_evaluation_study_is_on_a_results_page():
    """evaluation/ keeps only the studies whose figures the docs quote."""
    import gen_results

    quoted = {study for study, _, _ in gen_results.STUDIES.values()}
    studies = {p.name for p in (ROOT / "evaluation").iterdir()
               if p.is_dir() and not p.name.startswith("_")}
    assert studies == quoted


@pytest.mark.skipif(not HAVE_MKDOCS, reason="mkdocs and its plugins are not installed")
def test_math_and_api_blocks():
    import generated

    html = generated._math("a \\(x^2\\) b `\\(not\\)`\n\n$$\nE = m c^2\n$$\n\n```text\n$$\n```\n")
    assert html.count("<math") == 2 and "`\\(not\\)`" in html and "```text\n$$\n```" in html
    blocks = generated.api_blocks("hybridev.apps")
    assert "::: hybridev.apps.report.card" in blocks and "::: hybridev.apps" in blocks


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_MKDOCS, reason="mkdocs and its plugins are not installed")
def test_site_builds_strict(tmp_path):
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir",
                          str(tmp_path / "site")], cwd=ROOT, env=env, capture_output=True,
                         text=True, timeout=900)
    assert res.returncode == 0, res.stderr[-5000:]
    cli = (tmp_path / "site" / "reference" / "cli" / "index.html").read_text()
    assert "hybridev calibrate" in cli and "--coastdown" in cli
    api = (tmp_path / "site" / "reference" / "api" / "learning" / "index.html").read_text()
    assert "HybridModel" in api
    assert (tmp_path / "site" / "notebooks" / "01_quickstart" / "index.html").exists()
    assert list((tmp_path / "site" / "results" / "figures").rglob("*.png"))
