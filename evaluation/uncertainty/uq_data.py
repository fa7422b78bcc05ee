"""Data for the uncertainty experiments: per-seed datasets, splits and fresh test sets.

Part of ``evaluation/uncertainty/uncertainty.py`` (not imported by the library).

* ``make_dataset(1500, truth, seed=s, vehicle=TRUTH_VEHICLE)`` gives the
  paper-protocol data of the truth's own car (:data:`TRUTH_VEHICLE`: the
  paper's vehicle with mass +8 %, drag and rolling resistance +10 %, as in
  ``evaluation/shift_and_small_data``); its physics traces use trace seed
  ``s`` and keys ``trip_id = 0..1499``. Every model of seed ``s`` is built with
  ``physics_seed = PHYSICS_SEED_OFFSET + s`` and the nominal (paper) vehicle,
  so neither the truth's traces nor its car are the model's.
* A fresh test set must not reuse those traces: its trips come from
  ``make_trips(n, seed=FRESH_BASE + s)`` with ``trip_id`` offset by
  :data:`TRIP_ID_OFFSET`, and its energies are built by :func:`truth_energy`,
  which repeats ``hybridev.physics.truth.make_dataset``'s recipe (``E* = max(E_p (1 + S), 0)
  max(1 + eta, MIN_NOISE_FACTOR)``) with trace seed ``s`` and an independent noise
  stream. :func:`check_recipe` asserts that the recipe reproduces
  ``make_dataset`` bit for bit on the training data of every seed.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pandas as pd

from hybridev import VehicleParams, make_trips, simulate
from hybridev.physics.truth import (
    MIN_NOISE_FACTOR,
    PAPER_NOISE_SIGMAS,
    STRUCTURED_NOISE_SIGMA,
    effect_breakdown,
    make_dataset,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shift_and_small_data"))
from shift_and_small_data import TRUTH_VEHICLE

__all__ = ["N_FIT", "N_TOTAL", "PHYSICS_SEED_OFFSET", "TRIP_ID_OFFSET", "TRUTH_VEHICLE",
           "check_recipe", "conformal_split", "fresh_dataset", "paper_split", "truth_energy"]


PHYSICS_SEED_OFFSET = 500
"""The models of seed ``s`` synthesise their own speed traces with ``physics_seed = 500 + s``."""

N_TOTAL, N_FIT = 1500, 1275
"""Paper protocol: 1,500 trips, 1,275 to fit (1,050 train + 225 validation), 225 test."""

TRIP_ID_OFFSET = 1_000_000
"""Added to the fresh test trips' ``trip_id`` (the training trips use 0..1499)."""

FRESH_BASE = 10_000
"""Trip-design seed of the fresh test set of seed ``s`` is ``FRESH_BASE + s``."""

_NOISE_STREAM = {"paper": 1, "structured": 2}  # make_dataset's default_rng([seed, k])
_FRESH_STREAM = {"paper": 3, "structured": 4}
_CAPACITY_KWH = VehicleParams().battery_capacity_kwh


def truth_energy(trips: pd.DataFrame, truth: str, trace_seed: int, noise_key) -> np.ndarray:
    """Measured energy (kWh, (n,)) of ``trips`` under ``truth``, make_dataset's recipe.

    ``trace_seed`` is simulate's seed (traces keyed by ``trip_id``); ``noise_key``
    seeds ``numpy.random.default_rng`` for ``eta``.
    """
    sim = simulate(trips, TRUTH_VEHICLE, n_steps=1000, seed=int(trace_seed))
    ep = sim["energy_kwh_physics"].to_numpy(float)
    n = len(trips)
    rng = np.random.default_rng(noise_key)
    if truth == "paper":
        sig = np.array(list(PAPER_NOISE_SIGMAS.values()))
        eta = (rng.standard_normal((n, sig.size)) * sig).sum(1)
        mean = ep
    else:
        eta = STRUCTURED_NOISE_SIGMA * rng.standard_normal(n)
        mean = ep * (1.0 + effect_breakdown(sim, vehicle=TRUTH_VEHICLE)["total"].to_numpy(float))
    return np.maximum(mean, 0.0) * np.maximum(1.0 + eta, MIN_NOISE_FACTOR)


def _with_truth(trips: pd.DataFrame, energy: np.ndarray) -> pd.DataFrame:
    s0 = trips["soc_initial"].to_numpy(float)
    return trips.assign(energy_kwh=energy,
                        soc_final=np.maximum(0.0, s0 - energy / _CAPACITY_KWH))


def check_recipe(dataset: pd.DataFrame, truth: str, seed: int) -> None:
    """Assert that :func:`truth_energy` reproduces ``make_dataset(len, truth, seed)`` exactly."""
    trips = make_trips(len(dataset), seed=seed)
    e = truth_energy(trips, truth, seed, [seed, _NOISE_STREAM[truth]])
    if not np.array_equal(e, dataset["energy_kwh"].to_numpy(float)):
        raise RuntimeError(f"the fresh-test recipe no longer matches make_dataset (truth={truth}, "
                           f"seed={seed}); hybridev.physics.truth changed: update uq_data.truth_energy")


def dataset(truth: str, seed: int) -> pd.DataFrame:
    """The paper-protocol dataset of one seed (recipe checked)."""
    ds = make_dataset(N_TOTAL, truth=truth, seed=seed, vehicle=TRUTH_VEHICLE)
    check_recipe(ds, truth, seed)
    return ds


def paper_split(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random (fit, test) row indices, 1,275 / 225, sorted."""
    idx = np.random.default_rng([seed, 99]).permutation(N_TOTAL)
    return np.sort(idx[:N_FIT]), np.sort(idx[N_FIT:])


def fresh_dataset(truth: str, seed: int, n: int) -> pd.DataFrame:
    """``n`` fresh measured trips for the models of ``seed`` (same truth and trace seed).

    New trip keys (``TRIP_ID_OFFSET + i``): new traces, new conditions, new noise.
    """
    trips = make_trips(n, seed=FRESH_BASE + seed)
    trips["trip_id"] = TRIP_ID_OFFSET + np.arange(n)
    e = truth_energy(trips, truth, seed, [FRESH_BASE + seed, _FRESH_STREAM[truth]])
    return _with_truth(trips, e)


def conformal_split(n: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(calibration, rest) row indices of ``HybridModel.fit(..., seed=seed)``'s conformal split.

    Repeats the split in ``hybridev/model.py`` (``SeedSequence(seed).spawn(2)[0]``,
    a permutation, the first ``round(fraction n)`` rows); the caller verifies it
    against the fitted model's ``conformal_.residuals``.
    """
    split_ss, _ = np.random.SeedSequence(int(seed)).spawn(2)
    order = np.random.default_rng(split_ss).permutation(n)
    n_cal = round(fraction * n)
    return np.sort(order[:n_cal]), np.sort(order[n_cal:])
