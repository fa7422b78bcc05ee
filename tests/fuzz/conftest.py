"""Shared inputs of the fuzz suite: small tables and a fitted tiny model, made once."""

import hashlib
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hybridev import HybridModel, make_trips, simulate
from hybridev.apps.demo import example_schedule, example_tariff

N_STEPS = 100


def snapshot(root: Path) -> dict[str, str]:
    """SHA-256 of every file under ``root`` (relative paths)."""
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in root.rglob("*") if p.is_file()}


def lost_files(before: dict[str, str], after: dict[str, str], allowed=()) -> list[str]:
    """Files of ``before`` missing or changed in ``after`` (except those in ``allowed``)."""
    return sorted(k for k, v in before.items() if k not in allowed and after.get(k) != v)


@pytest.fixture(scope="session")
def fuzz_files(tmp_path_factory):
    """A folder of valid inputs plus two fitted models (default config and paper's)."""
    d = tmp_path_factory.mktemp("fuzz")
    t = simulate(make_trips(60, seed=11), n_steps=N_STEPS, seed=11)
    z = np.random.default_rng(11).normal(size=len(t))
    t["energy_kwh"] = t["energy_kwh_physics"] * 1.05 * (1.0 + 0.03 * z)
    meas = t[["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
              "soc_initial", "hour", "energy_kwh"]]
    meas.to_csv(d / "measured.csv", index=False)
    meas.drop(columns=["energy_kwh"]).to_csv(d / "trips.csv", index=False)
    sched = example_schedule(2, seed=0)
    sched.to_csv(d / "schedule.csv", index=False)
    example_tariff(3).to_csv(d / "tariff.csv", index=False)
    HybridModel(max_epochs=3, n_steps=N_STEPS, n_members=2).fit(meas, seed=0).save(d / "model")
    HybridModel(n_members=1, heteroscedastic=False, calibrate_physics=False,
                conformal_fraction=0.0, max_epochs=2, n_steps=N_STEPS).fit(
        meas, seed=0).save(d / "paper")
    return d


@pytest.fixture
def work(fuzz_files, tmp_path):
    """A private copy of the inputs in ``tmp_path`` (tests may try to destroy it)."""
    for p in fuzz_files.iterdir():
        (shutil.copytree if p.is_dir() else shutil.copy2)(p, tmp_path / p.name)
    return tmp_path


def measured_table(fuzz_files) -> pd.DataFrame:
    return pd.read_csv(fuzz_files / "measured.csv")
