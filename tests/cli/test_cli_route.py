"""Tests of ``hybridev route`` on the shipped example GPX (hybridev.cli.commands.route)."""

import re
import warnings
from pathlib import Path

import pandas as pd
import pytest

import hybridev.cli
from hybridev import HybridModel
from hybridev.cli.main import main
from hybridev.physics.truth import make_dataset

EXAMPLE = Path(hybridev.cli.__file__).parent / "examples" / "example_route.gpx"


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    data = make_dataset(250, truth="structured", seed=4, n_steps=100)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = HybridModel(n_steps=100, max_epochs=20, n_members=3,
                        n_posterior_draws=30).fit(data, seed=0)
    path = tmp_path_factory.mktemp("route") / "model"
    m.save(path)
    return str(path)


def test_route_on_the_example_gpx_prints_the_band_and_writes_the_fan(saved, tmp_path, capsys):
    png, legs = tmp_path / "fan.png", tmp_path / "legs.csv"
    code = main(["route", str(EXAMPLE), "--model", saved, "--soc", "0.8", "--temp", "5",
                 "--plot", str(png), "--out", str(legs)])
    out = capsys.readouterr().out
    assert code == 0
    m = re.search(r"arrival SoC +([0-9.]+) +\(90 % band ([0-9.]+) - ([0-9.]+)\)", out)
    assert m, out
    med, lo, hi = (float(x) for x in m.groups())
    assert 0.0 <= lo < med < hi <= 0.8
    p = re.search(r"P\(arriving below the reserve 0\.1\) = ([0-9.]+)", out)
    assert p and 0.0 <= float(p.group(1)) <= 1.0
    assert png.read_bytes()[:4] == b"\x89PNG" and png.stat().st_size > 5000
    t = pd.read_csv(legs)
    assert len(t) >= 12 and t["soc_arrival_pred"].iloc[-1] == pytest.approx(med, abs=5e-4)


def test_speed_profile_number_and_csv(saved, tmp_path, capsys):
    prof = tmp_path / "speeds.csv"
    pd.DataFrame({"from_km": [0.0, 30.0], "speed_kmh": [60.0, 80.0]}).to_csv(prof, index=False)
    for value in ("70", str(prof)):
        assert main(["route", str(EXAMPLE), "--model", saved, "--soc", "0.9", "--temp", "20",
                     "--speed-profile", value]) == 0
    assert capsys.readouterr().out.count("arrival SoC") == 2


@pytest.mark.parametrize(("argv", "match"), [
    (["--soc", "1.5"], "--soc=1.5 is outside the allowed range (0, 1]"),
    (["--soc", "0.5", "--reserve", "0.5"], "--reserve=0.5 is outside the allowed range [0, 0.5)"),
    (["--temp", "99"], "--temp=99.0 is outside the allowed range [-50, 60]"),
    (["--speed-profile", "0"], "--speed-profile='0' is outside the allowed range (0, 250]"),
    (["--speed-profile", "fast"], "--speed-profile='fast' must be a number"),
    (["--plot", "fan.txt"], "--plot='fan.txt' must end in one of"),
    (["--max-leg-km", "0.1"], "max_leg_km=0.1 is outside the allowed range [0.5, 100]"),
    (["--level", "1.2"], "level=1.2 is outside the allowed range (0, 1)"),
    (["--temp", None], "the route has no temperature: give temperature_c"),
])
def test_bad_input_exits_2_naming_the_field(saved, argv, match, capsys):
    args = {"--model": saved, "--soc": "0.8", "--temp": "5"}
    args.update(dict(zip(argv[::2], argv[1::2], strict=True)))
    flat = [x for k, v in args.items() if v is not None for x in (k, v)]
    assert main(["route", str(EXAMPLE), *flat]) == 2
    assert match in capsys.readouterr().err


def test_missing_route_file_exits_2(saved, tmp_path, capsys):
    assert main(["route", str(tmp_path / "none.gpx"), "--model", saved, "--soc", "0.8",
                 "--temp", "5"]) == 2
    assert "no such file" in capsys.readouterr().err
