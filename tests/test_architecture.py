"""The package's architecture: layers, import direction, no circles, public names.

Layers, bottom to top (a module may import its own layer and the layers below):

``core`` < ``physics``, ``metrics`` < ``data`` < ``bayes`` < ``learning`` < ``apps`` < ``cli``
< ``fleet``.

The one way up: ``HybridModel.predict(dask_dataframe)`` (and ``predict_interval``,
``predict_range``, ``hybridev predict 'trips/*.parquet'``, ``calibrate --by``) reach the
dask code of ``fleet`` through the named entry points of ``hybridev.core.plugins``
(``"module:function"`` strings imported on first use, like packaging entry points),
never by an import statement; ``tests/fleet/test_plugins.py`` checks that they all
point into ``hybridev.fleet`` and that ``import hybridev`` loads no dask.
"""

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

import hybridev

PKG = Path(hybridev.__file__).resolve().parent
RANK = {"core": 0, "physics": 1, "metrics": 1, "data": 2, "bayes": 3, "learning": 4,
        "apps": 5, "cli": 6, "fleet": 7}


def _modules():
    for path in sorted(PKG.rglob("*.py")):
        rel = path.relative_to(PKG.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        yield ".".join(parts), path


def _imports(name: str, path: Path) -> set[str]:
    """Absolute hybridev modules imported anywhere in the file (top level or in functions)."""
    tree = ast.parse(path.read_text())
    pkg = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names if a.name.startswith("hybridev"))
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")
                base = base[: len(base) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.startswith("hybridev"):
                out.add(mod)
                out.update(f"{mod}.{a.name}" for a in node.names)
    return out


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in RANK else None


GRAPH = {name: _imports(name, path) for name, path in _modules()}


def test_every_module_is_in_a_layer():
    loose = [m for m in GRAPH if m.count(".") >= 1 and _layer(m) is None]
    assert loose == [], f"modules outside the layer subpackages: {loose}"


def test_imports_point_down_the_layers():
    bad = []
    for mod, deps in GRAPH.items():
        lay = _layer(mod)
        if lay is None:
            continue
        for dep in deps:
            dl = _layer(dep)
            if dl is not None and RANK[dl] > RANK[lay]:
                bad.append(f"{mod} -> {dep}")
            if dl is not None and lay != dl and RANK[dl] == RANK[lay]:
                bad.append(f"{mod} -> {dep} (sibling layer)")
    assert bad == [], "imports pointing up the layers:\n" + "\n".join(sorted(bad))


def test_no_import_cycles():
    nodes = set(GRAPH)
    edges = {m: {d for d in deps if d in nodes and d != m} for m, deps in GRAPH.items()}
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for d in sorted(edges[m]):
            if d.startswith(m + "."):  # a package importing its own submodule is fine
                continue
            if state.get(d) == 1:
                cycles.append([*stack[stack.index(d):], d])
            elif d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(nodes):
        if m not in state:
            visit(m)
    assert cycles == [], f"import cycles: {cycles}"


TORCH_FREE = ("core", "physics", "metrics", "data", "bayes")
"""The layers below learning, in the order of :data:`RANK`."""


@pytest.fixture(scope="module")
def layer_imports():
    """``{layer: (torch modules loaded, hybridev modules above the layer loaded)}``.

    One fresh process imports the layers' modules in :data:`TORCH_FREE`'s order (up the
    ranks) and records after each layer what is loaded: a module that loads torch or a
    module above it is caught at its own layer, since everything loaded before is from
    the layers below (whose own checks come first). One interpreter start, not five.
    """
    # ``import hybridev`` itself loads the physics layer (its names are top-level), so
    # what counts is what the layers' modules load beyond that.
    plan = {layer: ([m for m in sorted(GRAPH) if _layer(m) == layer],
                    [k for k, r in RANK.items() if r > RANK[layer]]) for layer in TORCH_FREE}
    code = ("import sys, importlib, json, hybridev\n"
            "base = set(sys.modules)\n"
            "out = {}\n"
            f"for layer, (mods, higher) in {plan!r}.items():\n"
            "    for m in mods: importlib.import_module(m)\n"
            "    bad = sorted(k for k in sys.modules if k == 'torch' or k.startswith('torch.'))\n"
            "    above = sorted(k for k in set(sys.modules) - base if k.startswith('hybridev.')\n"
            "                   and k.split('.')[1] in higher)\n"
            "    out[layer] = [len(bad), above]\n"
            "print(json.dumps(out))\n")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return __import__("json").loads(res.stdout)


@pytest.mark.parametrize("layer", TORCH_FREE)
def test_lower_layers_never_import_torch(layer, layer_imports):
    """Physics (and everything below learning) runs without torch: checked in a fresh process."""
    assert sorted(RANK, key=RANK.get)[:len(TORCH_FREE)] == sorted(TORCH_FREE, key=RANK.get)
    n_torch, above = layer_imports[layer]
    assert n_torch == 0, f"{layer} imports torch"
    assert above == [], f"{layer} loads modules above it: {above}"


PUBLIC = sorted("""
FEATURE_NAMES PAPER_CONFIG PROFILES CVPlusConformal CalibrationWarning ChargingPlan ConstantRate
ConvergenceWarning DrivingProfile OutOfDomainWarning
EnergyDistribution HybridModel LinearBaseline LoggedTraces MeasuredTrips NormalizedConformal
PhysicsFallbackWarning PhysicsOnly PhysicsPosterior PhysicsPrior PhysicsStats PureML TripTraces
VehicleParams __version__ aux_power_kw calibrate_physics calibration_report coverage
coverage_table crps_gaussian crps_mixture effect_breakdown energy_from_stats evaluate_charging
get_profile hvac_power_kw mae make_dataset make_trips mape miscalibration_area mixture_interval
mixture_quantile noise_floor_pct oracle_energy_kwh plan_charging
plan_charging_from_distribution plot_soc_fan positive_kinetic_energy predict_range
read_measured_trips reliability_curve rmse run_demo simulate simulate_measured soc_fan
soc_trajectory synthesize_speed_trace trace_energy_kwh trace_power_kw trip_stats trip_traces
validate_measured_trips validate_trips wheel_power_kw winkler_score
""".split())


def test_public_names_are_pinned():
    """``import hybridev`` names are part of the contract: adding is fine, removing is not."""
    missing = [n for n in PUBLIC if n not in hybridev.__all__]
    assert missing == []
    for n in hybridev.__all__:
        assert getattr(hybridev, n) is not None


def test_import_hybridev_is_light():
    res = subprocess.run([sys.executable, "-c", "import sys, hybridev; "
                          "print(sorted({k.split('.')[0] for k in sys.modules} & "
                          "{'torch', 'sklearn', 'emcee', 'matplotlib'}))"],
                         capture_output=True, text=True, check=True)
    assert res.stdout.strip() == "[]"


def test_library_text_writes_temperatures_one_way():
    """Docstrings, comments and messages write °C (and °F), never degC or degF."""
    pkg = Path(hybridev.__file__).parent
    bad = [f"{p.relative_to(pkg)}:{i}" for p in sorted(pkg.rglob("*.py"))
           for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
           if re.search(r"\bdeg ?[CF]\b", line)]
    assert bad == []
