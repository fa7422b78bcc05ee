"""The paper's experiments (Secs. IV-V) on a known truth: protocol, models, one run per seed.

Used by :mod:`evaluation.reproduce`; every function here is deterministic given
its arguments (seeds are explicit) and runs single-threaded, so runs can be
spread over processes.

Protocol (the paper's, Sec. III-C / V-A)
----------------------------------------
* ``make_dataset(1500, truth=truth, seed=s)``: trips of the paper's design,
  physics ``E_p = simulate(trips, seed=s)`` and measured ``E*`` from the truth.
* A random 15 % test split (225 trips, permutation from
  ``default_rng([s, SPLIT_STREAM])``); the remaining 1,275 trips go to
  ``fit``, which holds out ``val_fraction = 0.15 / 0.85`` of them (225) for
  early stopping and trains on 1,050.
* Every physics computation uses ``physics_seed = s``: the models see the
  same ``E_p`` the truth was built on (as in the paper, where ``E*`` is a
  perturbation of ``E_p``).
* The fit seed of every network is ``s``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
import torch

from hybridev import (
    ConstantRate,
    HybridModel,
    LinearBaseline,
    PhysicsOnly,
    PureML,
    VehicleParams,
    effect_breakdown,
    make_dataset,
    oracle_energy_kwh,
    simulate,
)
from hybridev.learning.features import FEATURE_NAMES
from hybridev.learning.model import PAPER_CONFIG

__all__ = [
    "ABLATIONS",
    "LC_MODELS",
    "MAIN_MODELS",
    "PAPER_NET",
    "PAPER_NET_RELATIVE",
    "Config",
    "baseline_trips",
    "learning_curve_pool",
    "observed_soc_trips",
    "run_learning_curve",
    "run_main",
    "soc_grid_trips",
]

PAPER_NET = dict(PAPER_CONFIG)
"""The paper's point model (``hybridev.learning.model.PAPER_CONFIG``): one MSE network on the absolute
residual ``E* - E_p`` (kWh), no physics posterior, no ensemble, no conformal step."""
PAPER_NET_RELATIVE = {**PAPER_NET, "residual_target": "relative"}
"""The paper's network on the library's default target, the relative residual."""

SPLIT_STREAM = 7
LC_SEED = 1000  # dataset seed of the learning-curve pool (not one of the main seeds)
LC_POOL_REPLICATES = 10  # the pool has room for this many disjoint replicates
TRIP_COLUMNS = ["trip_id", "distance_km", "avg_speed_kmh", "mode", "temperature_c",
                "soc_initial", "hour"]

MAIN_MODELS = {  # key: label (order of the tables)
    "physics": "Physics only",
    "constant": "Constant rate 0.185 kWh/km (paper)",
    "constant_fit": "Constant rate, fitted sum(E)/sum(d)",
    "ols": "OLS on trip endpoints (LinearBaseline)",
    "pure_ml": "Pure ML (paper network, 9 inputs, no physics)",
    "hybrid_paper": "Hybrid, paper network (1 MSE net, absolute residual)",
    "hybrid_paper_rel": "Hybrid, paper network on the relative residual",
    "physics_calibrated": "Physics, emcee-calibrated (default hybrid's E_p)",
    "hybrid_default": "Hybrid, default (relative residual, posterior, 5-member ensemble, "
                      "conformal)",
}
"""Models of the comparison table."""

_PHYS = ("energy_kwh_physics", "kwh_per_km_physics")
ABLATIONS = {  # key: (label, dropped features, paper's MAPE)
    "full": ("Full model (all 11 features)", (), 0.8),
    "no_ep": ("Without E_p (energy_kwh_physics; E_p/d kept)", ("energy_kwh_physics",), 1.6),
    "no_phys": ("Without E_p and E_p/d (no physics inputs)", _PHYS, 1.6),
    "no_mode": ("Without driving behaviour (mode one-hot)",
                ("mode_eco", "mode_normal", "mode_aggressive"), 1.2),
    "no_speed": ("Without velocity (avg and max speed)", ("avg_speed_kmh", "max_speed_kmh"), 1.4),
    "no_env": ("Without environment (temperature, hour)", ("temperature_c", "hour"), 0.9),
    "no_soc": ("Without battery state (initial SoC)", ("soc_initial",), 1.0),
}
"""Feature-ablation variants of the paper network (the residual target is kept)."""

LC_MODELS = {
    "physics": "Physics only",
    "ols": "OLS (LinearBaseline)",
    "pure_ml": "Pure ML, paper network",
    "hybrid_paper": "Hybrid, paper network",
    "hybrid_paper_rel": "Hybrid, paper network, relative residual",
    "pure_ml_ens": "Pure ML, 5-member heteroscedastic ensemble",
    "hybrid_default": "Hybrid, default (relative residual, posterior, ensemble; conformal 0)",
}
"""Models of the learning curve."""


@dataclass(frozen=True)
class Config:
    """What to run. ``quick()`` is a smoke run (minutes), not a result."""

    truths: tuple[str, ...] = ("paper", "structured")
    seeds: tuple[int, ...] = (0, 1, 2, 3, 4)
    n_trips: int = 1500
    n_test: int = 225
    lc_sizes: tuple[int, ...] = (50, 100, 200, 500, 1050)
    lc_replicates: int = 5
    lc_test: int = 1000
    max_epochs: int = 200  # the paper's maximum
    quick: bool = False

    @classmethod
    def quick_run(cls) -> Config:
        return replace(cls(), seeds=(0,), lc_sizes=(50, 200), lc_replicates=1, lc_test=300,
                       max_epochs=15, quick=True)


def _net(cls, cfg: Config, physics_seed: int, **kw):
    return cls(physics_seed=physics_seed, max_epochs=cfg.max_epochs, **kw)


def split(n_trips: int, n_test: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(fit rows, test rows), sorted, from ``default_rng([seed, SPLIT_STREAM])``."""
    perm = np.random.default_rng([seed, SPLIT_STREAM]).permutation(n_trips)
    return np.sort(perm[n_test:]), np.sort(perm[:n_test])


def baseline_trips() -> pd.DataFrame:
    """The paper's baseline scenario (100 km, 90 km/h, 80 %, 20 °C), one trip per mode.

    ``trip_id`` 0, 1, 2 as in ``evaluation/physics_reproduction/physics_reproduction.py`` (same traces at
    seed 0); ``hour`` 12 (the paper gives none).
    """
    return pd.DataFrame({"trip_id": [0, 1, 2], "distance_km": 100.0, "avg_speed_kmh": 90.0,
                         "mode": ["eco", "normal", "aggressive"], "temperature_c": 20.0,
                         "soc_initial": 0.8, "hour": 12.0})


def soc_grid_trips() -> pd.DataFrame:
    """Normal driving at 90 km/h from 80 %, 20 °C, noon, 2-120 km (one trace key)."""
    d = np.arange(2.0, 122.0, 2.0)
    return pd.DataFrame({"trip_id": 50_000, "distance_km": d, "avg_speed_kmh": 90.0,
                         "mode": "normal", "temperature_c": 20.0, "soc_initial": 0.8,
                         "hour": 12.0})


def truth_mean_kwh(trips: pd.DataFrame, truth: str, seed: int) -> np.ndarray:
    """``E_p (1 + S)``: the truth without its i.i.d. noise (``S = 0`` for the paper's)."""
    sim = simulate(trips, seed=seed)
    ep = sim["energy_kwh_physics"].to_numpy(float)
    if truth == "paper":
        return ep
    return ep * (1.0 + effect_breakdown(sim)["total"].to_numpy(float))


def _quiet():
    warnings.filterwarnings("ignore", category=UserWarning)
    torch.set_num_threads(1)


def run_main(truth: str, seed: int, cfg: Config) -> dict:
    """All models of the comparison, the ablation and the scenario predictions for one seed.

    Returns
    -------
    dict
        ``test``: the test trips with ``energy_kwh``, ``oracle`` (MAPE-optimal
        oracle) and ``pred_<model>`` for every key of :data:`MAIN_MODELS` and
        ``abl_<variant>`` for :data:`ABLATIONS`, all kWh; ``fit``: epochs per
        network; ``baseline``/``soc_grid``: predictions on :func:`baseline_trips`
        and :func:`soc_grid_trips`; ``coverage90``: default hybrid's 90 %
        interval coverage on the test trips.
    """
    _quiet()
    ds = make_dataset(cfg.n_trips, truth=truth, seed=seed)
    fit_rows, test_rows = split(len(ds), cfg.n_test, seed)
    fit = ds.iloc[fit_rows].reset_index(drop=True)
    test = ds.iloc[test_rows].reset_index(drop=True)
    x_test = test[TRIP_COLUMNS]
    out = test.copy()
    out["oracle"] = oracle_energy_kwh(x_test, truth=truth, seed=seed)
    models = {
        "physics": PhysicsOnly(physics_seed=seed),
        "constant": ConstantRate(),
        "constant_fit": ConstantRate(None),
        "ols": LinearBaseline(),
        "pure_ml": _net(PureML, cfg, seed, **PAPER_NET),
        "hybrid_paper": _net(HybridModel, cfg, seed, **PAPER_NET),
        "hybrid_paper_rel": _net(HybridModel, cfg, seed, **PAPER_NET_RELATIVE),
        "hybrid_default": _net(HybridModel, cfg, seed),
    }
    fit_info, extra = {}, {}
    scen = {"baseline": baseline_trips(), "soc_grid": soc_grid_trips()}
    scen_pred = {k: v.copy() for k, v in scen.items()}
    for key, model in models.items():
        model.fit(fit, **({"seed": seed} if isinstance(model, HybridModel) else {}))
        pred = model.predict(x_test)
        out[f"pred_{key}"] = pred["energy_kwh_pred"].to_numpy(float)
        if key == "hybrid_default":
            out["pred_physics_calibrated"] = pred["energy_kwh_physics"].to_numpy(float)
            iv = model.predict_interval(x_test, level=0.9)
            y = out["energy_kwh"].to_numpy(float)
            extra["coverage90"] = float(np.mean((iv["energy_kwh_lo"].to_numpy() <= y)
                                                & (y <= iv["energy_kwh_hi"].to_numpy())))
        if hasattr(model, "fit_info_"):
            fit_info[key] = int(model.fit_info_["n_epochs"])
            extra.setdefault("counts", {})[key] = {
                k: int(model.fit_info_.get(k, 0)) for k in ("n_train", "n_val", "n_cal")}
        if key in ("physics", "hybrid_paper", "hybrid_default", "pure_ml", "constant"):
            for name, trips in scen.items():
                scen_pred[name][key] = model.predict(trips)["energy_kwh_pred"].to_numpy(float)
    for name, trips in scen.items():
        scen_pred[name]["truth_mean"] = truth_mean_kwh(trips, truth, seed)
        scen_pred[name]["seed"] = seed
    for key, (_, drop, _) in ABLATIONS.items():
        if key == "full":
            out["abl_full"] = out["pred_hybrid_paper"]
            continue
        feats = [f for f in FEATURE_NAMES if f not in drop]
        m = _net(HybridModel, cfg, seed, features=feats, **PAPER_NET).fit(fit, seed=seed)
        out[f"abl_{key}"] = m.predict(x_test)["energy_kwh_pred"].to_numpy(float)
        fit_info[f"abl_{key}"] = int(m.fit_info_["n_epochs"])
    out["truth"], out["seed"] = truth, seed
    return {"truth": truth, "seed": seed, "test": out, "fit": fit_info,
            "baseline": scen_pred["baseline"], "soc_grid": scen_pred["soc_grid"], **extra}


def learning_curve_pool(truth: str, cfg: Config
                        ) -> tuple[pd.DataFrame, pd.DataFrame, list[np.ndarray]]:
    """(dataset, test table, replicate pools of row indices) of the learning curve.

    One dataset ``make_dataset(lc_test + 10 * 1,275, truth, seed=LC_SEED)`` (a fixed
    size, so the test set does not depend on the number of replicates), split at
    random into the fixed test set and 10 disjoint pools of 1,275 trips; replicate
    ``r`` takes nested prefixes of pool ``r``. One dataset (one physics seed) lets
    every model see exactly the ``E_p`` the truth was built on, on test trips too.
    """
    n_fit_max = fit_size(max(cfg.lc_sizes))
    ds = make_dataset(cfg.lc_test + LC_POOL_REPLICATES * n_fit_max, truth=truth, seed=LC_SEED)
    perm = np.random.default_rng([LC_SEED, SPLIT_STREAM]).permutation(len(ds))
    pools = [perm[cfg.lc_test + r * n_fit_max: cfg.lc_test + (r + 1) * n_fit_max]
             for r in range(LC_POOL_REPLICATES)]
    return ds, ds.iloc[np.sort(perm[:cfg.lc_test])].reset_index(drop=True), pools


def fit_size(n_train: int) -> int:
    """Labelled trips handed to ``fit`` so that it trains on ``n_train`` (70:15 train:val)."""
    return n_train + round(n_train * 15 / 70)


def run_learning_curve(truth: str, replicate: int, test: pd.DataFrame, data: pd.DataFrame,
                       pool: np.ndarray, cfg: Config) -> pd.DataFrame:
    """Test MAPE of :data:`LC_MODELS` at every training size, for one replicate.

    Returns a long table: truth, replicate, n_train, n_fit, model, mape_pct,
    mae_kwh, oracle_mape_pct, n_epochs.
    """
    _quiet()
    from hybridev.metrics import mae, mape

    x_test = test[TRIP_COLUMNS]
    y = test["energy_kwh"].to_numpy(float)
    oracle = mape(y, oracle_energy_kwh(x_test, truth=truth, seed=LC_SEED))
    physics = PhysicsOnly(physics_seed=LC_SEED).fit(data.iloc[pool]).predict(x_test)
    physics = physics["energy_kwh_pred"]
    rows = []
    for n in cfg.lc_sizes:
        fit = data.iloc[pool[:fit_size(n)]].reset_index(drop=True)
        models = {
            "ols": LinearBaseline(),
            "pure_ml": _net(PureML, cfg, LC_SEED, **PAPER_NET),
            "hybrid_paper": _net(HybridModel, cfg, LC_SEED, **PAPER_NET),
            "hybrid_paper_rel": _net(HybridModel, cfg, LC_SEED, **PAPER_NET_RELATIVE),
            "pure_ml_ens": _net(PureML, cfg, LC_SEED, conformal_fraction=0.0),
            "hybrid_default": _net(HybridModel, cfg, LC_SEED, conformal_fraction=0.0),
        }
        preds = {"physics": physics.to_numpy(float)}
        epochs = {}
        for key, model in models.items():
            model.fit(fit, **({"seed": replicate} if isinstance(model, HybridModel) else {}))
            preds[key] = model.predict(x_test)["energy_kwh_pred"].to_numpy(float)
            if hasattr(model, "fit_info_"):
                if model.fit_info_["n_train"] != n:
                    raise RuntimeError(f"{key} trained on {model.fit_info_['n_train']} trips, "
                                       f"expected {n}")
                epochs[key] = int(model.fit_info_["n_epochs"])
        for key in LC_MODELS:
            rows.append({"truth": truth, "replicate": replicate, "n_train": n,
                         "n_fit": len(fit), "model": key, "mape_pct": mape(y, preds[key]),
                         "mae_kwh": mae(y, preds[key]), "oracle_mape_pct": oracle,
                         "n_epochs": epochs.get(key, 0)})
    return pd.DataFrame(rows)


def observed_soc_trips(truth: str, n_trips: int = 150, seed: int = 0) -> pd.DataFrame:
    """Trips for the SoC-depletion figure, measured like :func:`hybridev.make_dataset`.

    Normal driving at 90 km/h (not one of the paper's design speeds, so
    ``make_dataset`` cannot produce them), 20 °C, 80 % initial SoC, distance
    uniform over 5-120 km, departure hour uniform over 0-23, trace seed
    ``seed``. ``E* = E_p (1 + S) max(1 + eta, MIN_NOISE_FACTOR)`` with the
    truth's ``S`` (:func:`hybridev.effect_breakdown`; 0 for the paper's) and
    ``eta`` the truth's i.i.d. noise (the paper's four terms, or
    ``N(0, 0.035^2)``) from ``default_rng([seed, 12])``: the formula of
    ``make_dataset``, applied to custom trips.
    """
    from hybridev.physics.truth import MIN_NOISE_FACTOR, PAPER_NOISE_SIGMAS, STRUCTURED_NOISE_SIGMA

    rng = np.random.default_rng([seed, 11])
    trips = pd.DataFrame({"trip_id": 60_000 + np.arange(n_trips),
                          "distance_km": rng.uniform(5.0, 120.0, n_trips),
                          "avg_speed_kmh": 90.0, "mode": "normal", "temperature_c": 20.0,
                          "soc_initial": 0.8, "hour": rng.integers(0, 24, n_trips).astype(float)})
    noise = np.random.default_rng([seed, 12])
    if truth == "paper":
        sig = np.array(list(PAPER_NOISE_SIGMAS.values()))
        eta = (noise.standard_normal((n_trips, sig.size)) * sig).sum(1)
    else:
        eta = STRUCTURED_NOISE_SIGMA * noise.standard_normal(n_trips)
    energy = truth_mean_kwh(trips, truth, seed) * np.maximum(1.0 + eta, MIN_NOISE_FACTOR)
    trips["energy_kwh"] = energy
    cap = VehicleParams().battery_capacity_kwh
    trips["soc_final"] = np.maximum(0.0, 0.8 - energy / cap)
    return trips
