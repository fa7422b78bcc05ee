"""Write the tutorial notebooks in this folder from the cell lists below.

Run from anywhere::

    python notebooks/_build.py           # (re)write notebooks/*.ipynb
    python notebooks/_build.py --check   # exit 1 if a committed notebook differs

The notebooks are generated, not edited by hand: this file is what reviewers
read, and the ``.ipynb`` files carry no outputs (cells are executed top to
bottom by ``tests/test_notebooks.py``). Cell ids are fixed (``<stem>-<nn>``)
so that regenerating gives byte-identical files.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

import nbformat

from hybridev.core.fileio import atomic_path

HERE = Path(__file__).resolve().parent

KERNELSPEC = {"display_name": "Python 3 (ipykernel)", "language": "python", "name": "python3"}
LANGUAGE_INFO = {"name": "python", "pygments_lexer": "ipython3"}


def md(text: str) -> tuple[str, str]:
    return "markdown", textwrap.dedent(text).strip()


def code(text: str) -> tuple[str, str]:
    return "code", textwrap.dedent(text).strip()


# ---------------------------------------------------------------------------------------
# 01 quickstart
# ---------------------------------------------------------------------------------------
QUICKSTART = [
    md("""
    # Quickstart: physics, the hybrid model and its intervals

    `hybridev` predicts the battery energy of an electric-vehicle trip, and how sure it is:

    * a **physics core** (force balance on a synthesised, kinematically consistent speed trace,
      paper Sec. II),
    * a **hybrid model**: physics plus a small network that learns the residual
      `E* - E_p` from measured trips (paper Secs. III-V),
    * a **probabilistic layer** (not in the paper): an emcee posterior over the physics
      parameters, a deep ensemble of residual networks and a split-conformal step, giving
      intervals for energy and final state of charge (SoC).

    This notebook walks through the public API in that order. **All numbers below come from a
    reduced run** (600 trips, 200-step speed traces, 40 training epochs) so that it executes in
    seconds; the full-size results are in `evaluation/paper_experiments/REPRODUCTION.md` (point accuracy) and
    `evaluation/uncertainty/UNCERTAINTY.md` (intervals).
    """),
    code("""
    %matplotlib inline
    import dataclasses
    import tempfile
    import warnings
    from pathlib import Path

    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    import hybridev
    from hybridev import (
        PROFILES,
        HybridModel,
        OutOfDomainWarning,
        VehicleParams,
        coverage,
        make_dataset,
        make_trips,
        mape,
        noise_floor_pct,
        simulate,
        trip_traces,
    )

    pd.set_option("display.precision", 3)
    pd.set_option("display.max_columns", 30)
    hybridev.__version__
    """),
    md("""
    ## 1. Vehicle and driving profiles

    Parameter sets are frozen dataclasses that document their source. SI units inside, the
    unit in every field name. The defaults are the paper's vehicle (Sec. II-C).
    """),
    code("""
    vehicle = VehicleParams()
    vehicle
    """),
    md("""
    Variants are made with `dataclasses.replace`, which re-validates the values (a bad value
    raises a `ValueError` naming the field and the allowed range). Vehicles known only by
    their coast-down coefficients can be built with `VehicleParams.from_coastdown`.
    """),
    code("""
    heavy = dataclasses.replace(vehicle, mass_kg=2200.0)
    try:
        dataclasses.replace(vehicle, drivetrain_efficiency=1.2)
    except ValueError as err:
        print("ValueError:", err)
    """),
    md("""
    The three driving profiles of the paper shape the synthesised speed trace (acceleration,
    cycle period and amplitude) and the energy bookkeeping (efficiency multiplier, regenerative
    braking efficiency, extra auxiliary power).
    """),
    code("""
    pd.DataFrame({name: dataclasses.asdict(p) for name, p in PROFILES.items()}).drop(
        ["name", "source"])
    """),
    md("""
    ## 2. Simulate trips

    A *trip table* has one row per trip: `distance_km`, `avg_speed_kmh`, `mode`,
    `temperature_c`, `soc_initial` (optional `hour`, `grade_pct`, `trip_id`). `make_trips`
    draws the paper's experimental design; `simulate` adds the physics columns. Model outputs
    carry their source as a suffix (`*_physics`, `*_pred`, `*_lo`, `*_hi`); measured
    quantities are unsuffixed.
    """),
    code("""
    trips = make_trips(6, seed=0)
    simulate(trips, seed=0)
    """),
    md("""
    Any table with those columns works. Here is the paper's baseline scenario (100 km at
    90 km/h, 20 °C, 80 % SoC) for each profile, for the nominal and the heavier vehicle. The
    `seed` fixes the speed traces: same seed, same numbers.
    """),
    code("""
    baseline = pd.DataFrame({"distance_km": 100.0, "avg_speed_kmh": 90.0,
                             "mode": list(PROFILES), "temperature_c": 20.0,
                             "soc_initial": 0.8})
    nominal = simulate(baseline, seed=0)
    nominal.assign(energy_kwh_physics_heavy=simulate(baseline, heavy, seed=0)
                   ["energy_kwh_physics"])
    """),
    md("""
    `trip_traces` returns the per-step speed, battery power and SoC that `simulate` integrates,
    for plotting a handful of trips.
    """),
    code("""
    tr = trip_traces(baseline, n_steps=1000, seed=0)
    fig, (ax_v, ax_p, ax_s) = plt.subplots(3, 1, figsize=(8, 7), layout="constrained")
    for i, mode in enumerate(baseline["mode"]):
        t_min = tr.time_s[i] / 60.0
        ax_v.plot(t_min, tr.speed_mps[i] * 3.6, lw=1, label=mode)
        ax_p.step(t_min[:-1], tr.power_kw[i], where="post", lw=0.8)
        ax_s.plot(t_min, 100 * tr.soc[i], lw=1.5, label=mode)
    ax_v.set(xlim=(0, 10), ylabel="speed (km/h)", title="First 10 minutes")
    ax_p.set(xlim=(0, 10), xlabel="time (min)", ylabel="battery power (kW)")
    ax_p.axhline(0, color="0.5", lw=0.5)
    ax_s.set(xlabel="time (min)", ylabel="SoC (%)", title="Whole trip")
    ax_v.legend(ncol=3, fontsize=8)
    ax_s.legend(fontsize=8);
    """),
    md("""
    Negative power is regenerative braking. The aggressive profile accelerates harder and
    more often, so it spends more energy on the same 100 km.

    ## 3. Fit the hybrid model on measured trips

    A *measured-trip table* is a trip table plus a measured `energy_kwh` and/or `soc_final`.
    `make_dataset` builds one with a known synthetic ground truth. We use
    `truth="structured"`: the physics energy times smooth, physically motivated effects the
    physics leaves out (internal resistance, stop-and-go at rush hour, cabin heating, wind),
    times 3.5 % i.i.d. noise; see notebook 02 for why the paper's own truth has nothing to
    learn.
    """),
    code("""
    N_STEPS = 200  # intervals per synthesised trace (the paper uses 1000); model and data agree
    data = make_dataset(600, truth="structured", seed=0, n_steps=N_STEPS)
    is_test = np.random.default_rng(0).random(len(data)) < 0.2
    train, test = data[~is_test], data[is_test]
    print(f"{len(train)} training trips, {len(test)} held-out trips")
    train.head()
    """),
    md("""
    `HybridModel()` with its defaults is the probabilistic model: it samples a posterior over
    five physics parameters with emcee, trains a 5-member ensemble of heteroscedastic residual
    networks and holds out 15 % of the trips for the conformal calibration of its intervals.
    Only the trace length and the training length are reduced here (the default is up to 200
    epochs with early stopping). `fit` returns the model; learned state ends in `_`.
    """),
    code("""
    model = HybridModel(n_steps=N_STEPS, max_epochs=40).fit(train, seed=0)
    model.fit_info_
    """),
    code("""
    model.posterior_.summary()
    """),
    md("""
    ## 4. Predictions with intervals

    `predict_interval(trips, level)` takes a plain trip table (no measured columns; `mode`
    and `hour` may be missing) and returns it with:

    | column | unit | meaning |
    |---|---|---|
    | `energy_kwh_physics` | kWh | physics energy at the posterior-median parameters |
    | `energy_kwh_pred` | kWh | hybrid point prediction (physics + mean residual) |
    | `energy_kwh_lo`, `energy_kwh_hi` | kWh | central interval at `level` |
    | `soc_final_pred`, `soc_final_lo`, `soc_final_hi` | 0-1 | final SoC `s0 - E / C`, clipped to [0, 1], and its interval |
    | `in_domain`, `domain_score` | -- | inside the conditions the model was trained on? (score: largest gap, in tolerances) |
    | `confidence` | kWh | predictive standard deviation: **higher means less sure** |
    | `confidence_rel` | -- | `confidence` over the energy: ranks the relative error |

    (plus `soc_final_physics`, `max_speed_kmh`, `kwh_per_km_physics` as from `simulate`).
    Trips outside the training domain get wider intervals and one `OutOfDomainWarning`
    with their count; here the random split happens to leave the shortest trips in the
    held-out set, shorter than any training trip, so we show that warning.
    `predict` gives the point columns only, `predict_distribution` the full predictive
    distribution (used by the range and charging tools of notebook 04).
    """),
    code("""
    new_trips = test.drop(columns=["energy_kwh", "soc_final"])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        pred = model.predict_interval(new_trips, level=0.9)
    print(*sorted({str(w.message) for w in caught}), sep="\\n")
    cols = ["energy_kwh_physics", "energy_kwh_pred", "energy_kwh_lo", "energy_kwh_hi",
            "soc_final_pred", "soc_final_lo", "soc_final_hi", "in_domain", "domain_score",
            "confidence", "confidence_rel"]
    pred[["distance_km", "avg_speed_kmh", "mode", "temperature_c", "soc_initial", *cols]].head()
    """),
    md("""
    On the held-out trips we know the truth, so we can check. The noise floor is the MAPE of
    an oracle that knows everything except the i.i.d. noise: no model can beat it on average.
    """),
    code("""
    y = test["energy_kwh"]
    pd.Series({
        "MAPE %, physics (calibrated)": mape(y, pred["energy_kwh_physics"]),
        "MAPE %, hybrid": mape(y, pred["energy_kwh_pred"]),
        "MAPE %, noise floor": noise_floor_pct("structured"),
        "90 % interval coverage, energy": coverage(y, pred["energy_kwh_lo"],
                                                   pred["energy_kwh_hi"]),
        "90 % interval coverage, final SoC": coverage(test["soc_final"], pred["soc_final_lo"],
                                                      pred["soc_final_hi"]),
    }).round(3)
    """),
    code("""
    se = np.sqrt(0.9 * 0.1 / len(test))
    print(f"standard error of a 90 % coverage estimate on {len(test)} trips: {se:.3f}")
    """),
    md("""
    So a coverage a few points off 0.9 is within the sampling noise of one small test set;
    `evaluation/uncertainty/UNCERTAINTY.md` measures coverage over many trips and seeds.
    """),
    code("""
    fig, ax = plt.subplots(figsize=(5.5, 5), layout="constrained")
    p = pred["energy_kwh_pred"]
    ax.errorbar(y, p, yerr=[p - pred["energy_kwh_lo"], pred["energy_kwh_hi"] - p], fmt="o",
                ms=3, alpha=0.6, elinewidth=0.8, label="hybrid, 90 % interval")
    lim = [0, 1.05 * max(y.max(), pred["energy_kwh_hi"].max())]
    ax.plot(lim, lim, "k--", lw=1)
    ax.set(xlim=lim, ylim=lim, xlabel="measured energy (kWh)", ylabel="predicted energy (kWh)",
           title="Held-out trips (reduced run)")
    ax.legend(loc="upper left");
    """),
    md("""
    ## 5. Save and load

    `save` writes a directory of JSON and `.npz` files (no pickle), atomically; `load`
    restores the same predictions.
    """),
    code("""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "model"
        model.save(path)
        print({f.name: f"{f.stat().st_size / 1e3:.1f} kB" for f in sorted(path.iterdir())})
        loaded = HybridModel.load(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", OutOfDomainWarning)  # shown above
        again = loaded.predict_interval(new_trips, level=0.9)
    assert np.allclose(again[cols].astype(float), pred[cols].astype(float))  # same predictions
    """),
    md("""
    ## Next

    * `02_reproducing_the_paper.ipynb`: the paper's tables on its own truth and on ours.
    * `03_calibration_from_measured_trips.ipynb`: reading measured trips, the physics
      posterior, the calibration report, real trips.
    * `04_range_and_charging.ipynb`: range with confidence bands and risk-aware charging.
    * From a shell, `hybridev demo` runs the whole pipeline at full size and writes figures
      and a report.
    """),
]

# ---------------------------------------------------------------------------------------
# 02 reproducing the paper
# ---------------------------------------------------------------------------------------
PAPER = [
    md("""
    # Reproducing the paper

    The paper (*hybrid physics-residual EV discharge*, in `../shared/paper/`) reports a physics
    model with a baseline-scenario table, a ground truth built from physics plus noise, and a
    hybrid (physics + residual network) that cuts the physics-only MAPE from 2.1 % to 0.8 %.
    This notebook reproduces each step in miniature:

    1. the baseline-scenario table of the physics model;
    2. the paper's ground truth against our learnable "structured" truth, and the noise floor
       that bounds every model;
    3. physics only vs the paper's point model (`PAPER_CONFIG`) vs the default probabilistic
       hybrid on a held-out split, for both truths.

    **Reduced run**: 800 trips, 200-step traces, 60 epochs, one seed. The full-size tables
    (1,500 trips, 5 seeds, learning curves, ablations, timing) are produced by
    `python -m evaluation.paper_experiments.reproduce` into `evaluation/paper_experiments/REPRODUCTION.md` and
    `evaluation/paper_experiments/tables/`; the physics-only tables and every deviation from the paper are in
    `evaluation/physics_reproduction/physics_reproduction.md`.
    """),
    code("""
    %matplotlib inline
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd

    from hybridev import (
        PROFILES,
        HybridModel,
        coverage,
        effect_breakdown,
        make_dataset,
        mape,
        noise_floor_pct,
        simulate,
    )
    from hybridev.learning.model import PAPER_CONFIG
    from hybridev.physics.truth import noise_sigma
    from hybridev.physics.oracle import oracle_mape_pct

    pd.set_option("display.precision", 3)
    """),
    md("""
    ## 1. Baseline scenario (physics only)

    100 km at 90 km/h, 20 °C, starting at 80 % SoC, 75 kWh battery. The paper's values are
    quoted from its table "Driving Modes Comparison in the Baseline Scenario". Our physics
    uses the paper's parameters untuned; the spread over trace seeds shows how much one
    synthesised trace matters.
    """),
    code("""
    paper = pd.DataFrame({"energy_kwh_paper": [13.3, 17.5, 23.8],
                          "soc_final_pct_paper": [62.3, 56.7, 48.2]},
                         index=pd.Index(list(PROFILES), name="mode"))
    scenario = pd.DataFrame({"distance_km": 100.0, "avg_speed_kmh": 90.0,
                             "mode": list(PROFILES), "temperature_c": 20.0, "soc_initial": 0.8})
    runs = np.array([simulate(scenario, n_steps=1000, seed=s)["energy_kwh_physics"]
                     for s in range(10)])            # (seed, mode), kWh
    base = simulate(scenario, n_steps=1000, seed=0).set_index("mode")
    paper.assign(
        energy_kwh_physics=base["energy_kwh_physics"],
        energy_kwh_seeds_0_9=[f"{m:.2f} ± {s:.2f}" for m, s in
                              zip(runs.mean(0), runs.std(0, ddof=1), strict=True)],
        soc_final_pct_physics=100 * base["soc_final_physics"],
        diff_pct=100 * (base["energy_kwh_physics"] / paper["energy_kwh_paper"] - 1),
    )
    """),
    md("""
    The `diff_pct` column is our physics against the paper's table. The profiles are not
    re-tuned to close the gaps: `evaluation/physics_reproduction/physics_reproduction.md` traces them to the
    paper's own equations (its trace construction and profile parameters) and lists every
    deviation.

    ## 2. Two ground truths and the noise floor

    The paper builds its measured energy as `E* = E_p (1 + eps_terrain + eps_traffic +
    eps_driver + eps_weather)` with independent Gaussian terms (sd 5, 8, 6 and 3 %): noise
    **independent of every input**. There is nothing for a network to learn, and the best
    possible MAPE is that of an oracle that knows `E_p` exactly; `noise_floor_pct` computes it
    by quadrature (below). It is far above the paper's 0.8 % hybrid and even its 2.1 %
    physics-only MAPE, which therefore cannot be reached on the paper's own data.

    Our `truth="structured"` (not in the paper, documented in `hybridev/truth.py`) is
    `E* = E_p (1 + S(x)) (1 + eta)`: `S` sums smooth physical effects of the trip's inputs,
    `eta` is 3.5 % i.i.d. noise.
    """),
    code("""
    pd.DataFrame({truth: {"i.i.d. noise sd (relative)": noise_sigma(truth),
                          "noise floor: expected oracle MAPE %": noise_floor_pct(truth)}
                  for truth in ("paper", "structured")}).round(4)
    """),
    md("""
    The structured effects as a fraction of the physics energy, averaged by ambient
    temperature: cold costs most (heating, internal resistance, denser air).
    """),
    code("""
    N_TRIPS, N_STEPS, EPOCHS, SEED = 800, 200, 60, 0
    data = {truth: make_dataset(N_TRIPS, truth=truth, seed=SEED, n_steps=N_STEPS)
            for truth in ("paper", "structured")}
    effects = effect_breakdown(data["structured"], n_steps=N_STEPS, seed=SEED)
    (100 * effects.groupby(data["structured"]["temperature_c"]).mean()).round(2).rename_axis(
        "temperature_c (effects in % of E_p)")
    """),
    md("""
    ## 3. Physics vs paper network vs default hybrid on held-out trips

    Split as in `evaluation/paper_experiments/reproduce.py`: 15 % of the trips held out (permutation from
    `default_rng([seed, 7])`). Three predictors:

    * **physics**: the nominal force-balance model (the paper's physics-only baseline);
    * **paper network**: `HybridModel(**PAPER_CONFIG)`, one MSE network on the absolute
      residual against the nominal physics, the paper's recipe;
    * **default hybrid**: `HybridModel()`, physics posterior + 5-member ensemble + conformal
      intervals.

    The oracle on the same test trips is the floor for this finite sample.
    """),
    code("""
    def split(table, seed=SEED, test_share=0.15):
        order = np.random.default_rng([seed, 7]).permutation(len(table))
        n_test = round(test_share * len(table))
        return table.iloc[np.sort(order[n_test:])], table.iloc[np.sort(order[:n_test])]


    rows, held_out = {}, {}
    for truth, table in data.items():
        train, test = split(table)
        x_test = test.drop(columns=["energy_kwh", "soc_final"])
        paper_net = HybridModel(**PAPER_CONFIG, n_steps=N_STEPS, physics_seed=SEED,
                                max_epochs=EPOCHS).fit(train, seed=SEED)
        hybrid = HybridModel(n_steps=N_STEPS, physics_seed=SEED,
                             max_epochs=EPOCHS).fit(train, seed=SEED)
        p_paper = paper_net.predict(x_test)     # its physics column is the nominal physics
        p_hybrid = hybrid.predict_interval(x_test, level=0.9)
        y = test["energy_kwh"]
        rows[truth] = {
            "physics (nominal)": mape(y, p_paper["energy_kwh_physics"]),
            "paper network": mape(y, p_paper["energy_kwh_pred"]),
            "default hybrid": mape(y, p_hybrid["energy_kwh_pred"]),
            "oracle on these trips": oracle_mape_pct(test, truth=truth, seed=SEED,
                                                     n_steps=N_STEPS),
            "noise floor (expected)": noise_floor_pct(truth),
            "default hybrid: 90 % coverage": coverage(y, p_hybrid["energy_kwh_lo"],
                                                      p_hybrid["energy_kwh_hi"]),
        }
        held_out[truth] = (test, p_paper, p_hybrid)
    results = pd.DataFrame(rows)
    results.round(3)
    """),
    md("""
    How to read it (MAPE in %, coverage as a fraction of the held-out trips):

    * **Paper truth**: the physics *is* the oracle up to a constant factor, and the error is
      pure noise, so the networks have nothing to learn: expect every predictor near the
      oracle, and no gain from the hybrid. This is the honest version of the paper's claim on
      its own data.
    * **Structured truth**: the physics misses the unmodelled effects; the hybrids learn them
      and should approach the oracle.

    With one seed and 120 test trips, differences of a few tenths of a percent are noise. The
    full-size reduction (5 seeds x 225 test trips, up to 200 epochs) is in the summary table
    of `evaluation/paper_experiments/REPRODUCTION.md`.
    """),
    code("""
    reduction = 100 * (1 - results.loc[["paper network", "default hybrid"]]
                       / results.loc["physics (nominal)"])
    reduction.round(1).rename_axis("MAPE reduction vs physics, %")
    """),
    code("""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), layout="constrained")
    for ax, truth in zip(axes, data, strict=True):
        test, p_paper, p_hybrid = held_out[truth]
        y = test["energy_kwh"].to_numpy()
        for col, table, label in (("energy_kwh_physics", p_paper, "physics"),
                                  ("energy_kwh_pred", p_hybrid, "default hybrid")):
            err = 100 * (table[col].to_numpy() / y - 1)
            ax.hist(err, bins=np.linspace(-40, 40, 41), alpha=0.55,
                    label=f"{label} (MAPE {mape(y, table[col]):.1f} %)")
        ax.set(title=f"truth={truth!r}: relative error on held-out trips",
               xlabel="prediction / measured - 1 (%)", ylabel="trips")
        ax.legend(fontsize=8)
    """),
    md("""
    The paper truth's error distribution is the noise itself, whatever the model; on the
    structured truth the hybrid's errors shrink to the 3.5 % noise. Full-size versions of this
    figure: `evaluation/paper_experiments/figures/repro_error_distribution_paper.png` and
    `..._structured.png`.
    """),
]

# ---------------------------------------------------------------------------------------
# 03 calibration from measured trips
# ---------------------------------------------------------------------------------------
CALIBRATION = [
    md("""
    # Calibration from measured trips

    Real vehicles differ from their data sheet: tyres, load, wind and auxiliaries move the
    drag area, rolling resistance, efficiency and auxiliary power. `calibrate_physics`
    samples the posterior of these parameters from measured trip energies (emcee), so the
    physics becomes *this* car's physics, with honest uncertainty.

    1. Synthetic measured trips from a car whose parameters we know (`simulate_measured`).
    2. `calibrate_physics`: posterior summary against the truth, and a corner plot.
    3. Reading a measured-trip CSV with malformed rows (`read_measured_trips`): every bad row
       is reported with its reason, none silently dropped.
    4. `calibration_report`: fit on training trips, score nominal physics, calibrated physics
       and the hybrid on held-out trips, write an HTML report.
    5. Optional: real logged trips, if `../shared/realtrips` is present.

    **Reduced run** (300 trips, 200-step traces, a 2-member ensemble trained for 20 epochs).
    Parameter recovery over many seeds is in `evaluation/uncertainty/UNCERTAINTY.md`; the full calibration
    report on the real trips is `calibration/results/realtrips_report.md`.
    """),
    code("""
    %matplotlib inline
    import shutil
    import sys
    import tempfile
    import warnings
    from pathlib import Path

    import corner
    import matplotlib.pyplot as plt
    import numpy as np
    import pandas as pd
    from IPython.display import Image, display

    from hybridev import (
        VehicleParams,
        calibrate_physics,
        energy_from_stats,
        make_trips,
        mape,
        read_measured_trips,
        simulate,
        simulate_measured,
        trip_stats,
    )
    from hybridev.bayes.priors import DEFAULT_PARAMS
    from hybridev.bayes.posterior import PhysicsPosterior
    from hybridev.apps.report.build import calibration_report

    pd.set_option("display.precision", 4)
    pd.set_option("display.max_columns", 30)
    workdir = Path(tempfile.mkdtemp(prefix="hybridev_nb03_"))  # removed at the end
    """),
    md("""
    ## 1. Measured trips from a car with known parameters

    The "true" car has a 9 % larger drag area, 20 % more rolling resistance, a less efficient
    drivetrain, a heavier auxiliary load and weaker regeneration than the nominal vehicle.
    `simulate_measured` runs the exact physics with these values on the same synthesised
    traces as `simulate` and adds 3 % relative noise.
    """),
    code("""
    N_STEPS = 200
    TRUE = {"drag_area_m2": 0.60, "rolling_resistance_coef": 0.012,
            "drivetrain_efficiency": 0.87, "aux_base_kw": 0.8, "regen_scale": 0.85}
    NOISE = 0.03
    trips = make_trips(300, seed=1)
    measured = simulate_measured(trips, true_params=TRUE, noise_rel=NOISE, seed=2,
                                 n_steps=N_STEPS)
    nominal = PhysicsPosterior.nominal_values(VehicleParams())
    pd.DataFrame({"nominal": {k: nominal[k] for k in DEFAULT_PARAMS}, "true": TRUE})
    """),
    code("""
    e_nominal = simulate(trips, n_steps=N_STEPS)["energy_kwh_physics"]
    print(f"nominal physics MAPE on these trips: {mape(measured['energy_kwh'], e_nominal):.1f} %")
    """),
    md("""
    ## 2. The physics posterior

    Five parameters plus the relative noise, priors centred on the nominal vehicle (widths in
    `PhysicsPrior`). The chain runs until it is at least 50 autocorrelation times long.
    """),
    code("""
    post = calibrate_physics(measured, trace_steps=N_STEPS, seed=0)
    summary = post.summary(level=0.9)
    summary["true"] = pd.Series({**TRUE, "noise_rel": NOISE})
    summary["true inside 90 %"] = summary["true"].between(summary["q05"], summary["q95"])
    summary
    """),
    code("""
    d = post.diagnostics
    print(f"{d['n_walkers']} walkers x {d['n_steps']} steps, tau_max {d['tau_max']:.1f} steps, "
          f"{d['chain_length_tau']:.0f} tau after burn-in, acceptance {d['acceptance_mean']:.2f}, "
          f"{d['elapsed_s']:.1f} s")
    """),
    md("""
    A 90 % credible interval misses its true value one time in ten on average, so a miss in
    one data set is no alarm; whether the intervals miss at the right rate is a question for
    many seeds (`evaluation/uncertainty/UNCERTAINTY.md`). Single parameters are loosely pinned because
    trip energies only see combinations of them: the posterior correlations show which ones
    trade off (e.g. a per-distance loss against a per-time one, as rolling resistance against
    auxiliary power), and misses tend to come in such pairs.
    """),
    code("""
    print(f"{int((~summary['true inside 90 %']).sum())} of {len(summary)} intervals miss")
    pd.DataFrame(post.samples, columns=post.param_names).corr().round(2)
    """),
    code("""
    labels = [*post.param_names, "noise_rel"]
    fig = corner.corner(np.column_stack([post.samples, post.noise_rel]), labels=labels,
                        truths=[*(TRUE[p] for p in post.param_names), NOISE],
                        quantiles=[0.05, 0.5, 0.95], show_titles=True, title_fmt=".3g",
                        title_kwargs={"fontsize": 8}, label_kwargs={"fontsize": 8})
    """),
    md("""
    The calibrated physics (posterior medians) on the same trips, in-sample; held-out scores
    follow in section 4.
    """),
    code("""
    median = {k: v for k, v in post.median().items() if k != "noise_rel"}
    e_calibrated = energy_from_stats(post.stats_for(measured), median)
    print(f"MAPE: nominal {mape(measured['energy_kwh'], e_nominal):.1f} %, "
          f"calibrated {mape(measured['energy_kwh'], e_calibrated):.1f} % "
          f"(noise alone: about {100 * NOISE * np.sqrt(2 / np.pi):.1f} %)")
    """),
    md("""
    ## 3. Reading a measured-trip file with malformed rows

    Real files have bad rows. We write the trips to a CSV with a `session_group` (trips driven
    back to back; the report holds out whole sessions) and damage a few rows on purpose.
    """),
    code("""
    table = measured.drop(columns=["energy_kwh_true"]).assign(
        session_group=measured["trip_id"] // 10).astype(object)
    table.loc[3, "distance_km"] = -12.0                 # negative distance
    table.loc[7, "temperature_c"] = 85.0                # outside [-50, 60] °C
    table.loc[11, "avg_speed_kmh"] = "fast"             # not a number
    table.loc[15, "energy_kwh"] = -1.2                  # negative energy
    table.loc[19, "mode"] = "sporty"                    # unknown driving profile
    table.loc[23, "soc_initial"] = None                 # missing value
    table = pd.concat([table, table.loc[[30]]], ignore_index=True)  # duplicated trip_id
    csv_path = workdir / "measured_trips.csv"
    table.to_csv(csv_path, index=False)
    print(f"{csv_path.name}: {len(table)} rows")
    """),
    code("""
    m = read_measured_trips(csv_path)
    print(f"{len(m.trips)} valid trips, {m.n_rejected} rejected")
    m.rejected
    """),
    md("""
    Every row of the file is accounted for: valid rows plus rejected trip rows equal the rows
    read. The same `MeasuredTrips` object goes straight into `calibrate_physics`,
    `HybridModel.fit` and `calibration_report`; with a logged time series
    (`read_measured_trips(trips_csv, timeseries_parquet)`) the physics runs on the real
    speed traces instead of synthesised ones.
    """),
    code("""
    assert len(m.trips) + int((m.rejected["source"] == "trips").sum()) == len(table)
    """),
    md("""
    ## 4. Calibration report

    `calibration_report` (the function behind `hybridev calibrate`) holds out 20 % of the
    sessions, fits the physics posterior and the hybrid on the rest, and scores on the held-out
    trips: (a) nominal physics, (b) calibrated physics (posterior predictive intervals),
    (c) the hybrid (posterior + residual ensemble + conformal intervals). It writes
    `report.html`, `summary.json`, `predictions.csv`, `rejected.csv` and figures, atomically.
    """),
    code("""
    report = calibration_report(
        m, out_dir=workdir / "report", seed=0, n_members=2,
        model_params={"n_steps": N_STEPS, "max_epochs": 20},
        calibrate_kwargs={"trace_steps": N_STEPS},
        source="notebook 03: simulate_measured + damaged rows")
    sorted(p.relative_to(workdir / "report").as_posix()
           for p in (workdir / "report").rglob("*") if p.is_file())
    """),
    code("""
    scores = pd.DataFrame({
        name: {"MAPE %": s["mape_pct"],
               "90 % coverage": s.get("coverage", {}).get("0.9", np.nan),
               "90 % width (kWh)": s.get("mean_width_kwh", np.nan)}
        for name, s in report["metrics"].items()}).T
    print(f"held out: {report['split']['n_test']} trips in {report['split']['n_test_groups']} "
          f"sessions; trained on {report['split']['n_train']}")
    scores
    """),
    md("""
    On this synthetic car the residual network has little left to learn once the physics is
    calibrated (the truth *is* the physics plus noise), so (b) and (c) should be close; on real
    trips the hybrid also absorbs what the physics does not model. One of the report's figures,
    the reliability diagram (nominal vs empirical coverage at several levels):
    """),
    code("""
    display(Image(filename=str(workdir / "report" / "figures" / "reliability.png"), width=520))
    """),
    md("""
    ## 5. Optional: real logged trips

    The project's development set of 104 real trips of one car (1 Hz speed, GPS elevation and
    temperature logs; see `../shared/realtrips/README.md`) is not part of the repository. This
    section runs only when it is present next to the repository; otherwise it says so and
    skips. It loads the trips exactly as `calibration/realtrips_report.py` does (the same
    column mapping, vehicle from the coast-down coefficients and a `logged` profile for the
    unlabelled traces), shows a few traces and the nominal physics on the logged traces.
    """),
    code("""
    REPO = Path.cwd().resolve().parent  # notebooks run from notebooks/
    DATA = REPO.parent / "shared" / "realtrips"
    HAVE_REAL = (DATA / "trips.csv").exists() and (DATA / "timeseries_1hz.parquet").exists()
    print(f"real trips {'found' if HAVE_REAL else 'not found'} at {DATA}"
          + ("" if HAVE_REAL else ": skipping this section"))
    """),
    code("""
    if HAVE_REAL:
        sys.path.insert(0, str(REPO / "calibration"))
        from realtrips_physics import LOGGED, VEHICLE
        from realtrips_report import load

        import warnings

        from hybridev import DataWarning

        with warnings.catch_warnings(record=True) as caught:  # shown here, not on stderr
            warnings.simplefilter("always", DataWarning)
            real = load(DATA)  # MeasuredTrips with the logged traces
        for w in caught:
            print(f"{w.category.__name__}: {w.message}")
        print(f"{len(real.trips)} valid trips with {len(real.traces)} logged traces, "
              f"{real.n_rejected} rejected")
        display(real.rejected[["trip_id", "field", "reason"]].head(3))
        display(real.trips.head())
    """),
    code("""
    if HAVE_REAL:
        ids = real.trips["trip_id"].iloc[[0, 1, 2]].tolist()
        tr = real.traces.select(ids)
        fig, (ax_v, ax_g) = plt.subplots(2, 1, figsize=(8, 5), sharex=True, layout="constrained")
        for i, tid in enumerate(ids):
            s = slice(tr.offsets[i], tr.offsets[i + 1])
            t_min = (tr.t_s[s] - tr.t_s[s][0]) / 60.0
            ax_v.plot(t_min, tr.speed_mps[s] * 3.6, lw=0.8, label=str(tid))
            ax_g.plot(t_min, 100 * np.tan(tr.grade_rad[s]), lw=0.8)
        ax_v.set(ylabel="speed (km/h)", title="Logged 1 Hz traces of three real trips")
        ax_g.set(xlabel="time (min)", ylabel="grade from GPS elevation (%)")
        ax_v.legend(fontsize=8)
        plt.show()
    """),
    code("""
    if HAVE_REAL:
        stats = trip_stats(real.trips, VEHICLE, traces=real.traces, missing_mode=LOGGED)
        e_real = energy_from_stats(stats)
        y_real = real.trips["energy_kwh"]
        print(f"nominal physics on the logged traces: MAPE {mape(y_real, e_real):.1f} % over "
              f"{len(y_real)} trips; measured mean {y_real.mean():.2f} kWh, "
              f"physics mean {e_real.mean():.2f} kWh")
    """),
    md("""
    The calibrated physics and the hybrid on these trips, with cross-validation over driving
    sessions, are in `calibration/results/realtrips_report.md` (re-run with
    `python calibration/realtrips_report.py`, a few minutes).
    """),
    code("""
    shutil.rmtree(workdir)
    """),
]

# ---------------------------------------------------------------------------------------
# 04 range and charging
# ---------------------------------------------------------------------------------------
RANGE = [
    md("""
    # Range with confidence bands, and risk-aware charging

    A predictive distribution is only useful if it drives decisions. This notebook uses a
    fitted probabilistic `HybridModel` for two:

    1. **Range**: how far can I go from 90 % SoC to a 10 % reserve, and how sure is that?
       (`predict_range`, `soc_fan`, `plot_soc_fan`)
    2. **Charging**: the cheapest week of home charging such that the probability of ever
       arriving below 10 % SoC is at most 5 % (`plan_charging`), compared with planning on mean
       energies.

    **Reduced run** (600 trips, 200-step traces, 40 epochs). Full-size figures and the
    coverage of the range bands: `evaluation/range_bands/range_bands.md`; the full demo (`hybridev demo`)
    writes the same figures for a 1,500-trip model.
    """),
    code("""
    %matplotlib inline
    import matplotlib.pyplot as plt
    import pandas as pd

    import warnings

    from hybridev import (
        HybridModel,
        OutOfDomainWarning,
        make_dataset,
        plan_charging,
        predict_range,
    )
    from hybridev.apps.demo import example_schedule, example_tariff
    from hybridev.apps.range_plot import plot_soc_fan, soc_fan

    # The example week's temperatures (about -5 to 10 °C) lie between the training design
    # points (-5, 20, 32 °C): the model flags those trips (in_domain, domain_score) and
    # widens their spread. The OutOfDomainWarning would repeat on every call (notebook 01
    # shows it), so it is silenced here; the in_domain column says which trips it concerns.
    warnings.simplefilter("ignore", OutOfDomainWarning)

    pd.set_option("display.precision", 3)
    pd.set_option("display.max_columns", 30)
    N_STEPS = 200
    data = make_dataset(600, truth="structured", seed=0, n_steps=N_STEPS)
    model = HybridModel(n_steps=N_STEPS, max_epochs=40).fit(data, seed=0)
    print(f"fitted on {model.fit_info_['n_train']} trips; battery {model.capacity_kwh:g} kWh")
    """),
    md("""
    ## 1. Range for a few conditions

    A condition is a trip table without distance and SoC: mean speed, mode, temperature
    (optional hour, grade). `range_km_q10` is the distance reached with probability 90 %,
    `range_km_q50` the median, `range_km_q90` the distance reached with probability 10 %;
    `range_km_physics` is the physics alone.
    """),
    code("""
    conditions = pd.DataFrame({
        "avg_speed_kmh": [50.0, 90.0, 90.0, 120.0],
        "mode": ["eco", "normal", "normal", "aggressive"],
        "temperature_c": [20.0, 20.0, -5.0, 20.0],
        "hour": 10.0,
    })
    ranges = predict_range(model, conditions, soc_initial=0.9, soc_reserve=0.1, seed=0)
    ranges
    """),
    md("""
    Mind the caveat in `hybridev.apps.range`: a full battery's range (hundreds of km) is beyond the
    20-200 km training trips, so the network would extrapolate in distance. Such ranges are flagged
    out of the training domain (`in_domain` false) and their bands widened from the physics posterior.
    `evaluation/range_bands/range_bands.md` measures their coverage within and beyond the training
    distances, and for a model trained on longer trips.

    ## 2. SoC fan chart

    `soc_fan` gives quantiles of the SoC left after each distance under one condition;
    `plot_soc_fan` draws the median with its 50 % and 90 % bands and marks the predicted
    range. Here mild and cold weather at 90 km/h.
    """),
    code("""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True, layout="constrained")
    for ax, row in zip(axes, [1, 2], strict=True):
        fan = soc_fan(model, conditions.iloc[row], soc_initial=0.9, seed=0)
        cond = conditions.iloc[row]
        plot_soc_fan(fan, soc_reserve=0.1, ranges=ranges.iloc[row], ax=ax,
                     title=f"{cond['mode']}, {cond['avg_speed_kmh']:.0f} km/h, "
                           f"{cond['temperature_c']:+.0f} °C")
    fan.iloc[::10]
    """),
    md("""
    ## 3. A week of charging

    `example_schedule` is a week of planned trips (weekday commutes and errands, a long
    Saturday round trip, temperatures around 2 °C); `example_tariff` a time-of-use tariff in
    15-minute slots (0.12 per kWh at night, 0.40 at the evening peak, 0.25 otherwise). Any
    tables with these columns work.
    """),
    code("""
    schedule, tariff = example_schedule(7, seed=0), example_tariff(7)
    print(f"{len(schedule)} trips, {schedule['distance_km'].sum():.0f} km; {len(tariff)} slots")
    schedule.head(6)
    """),
    md("""
    `plan_charging` asks the model for the *joint* predictive distribution of all the week's
    trip energies (one physics draw and ensemble member shared across a sample, so the trips
    are not treated as independent coin flips), then solves for the cheapest charger power per
    slot with `P(SoC < soc_min at some arrival) <= risk`. It reports the achieved risk on fresh
    samples, and by default also the risk-neutral plan that only covers the *mean* energies.
    """),
    code("""
    plan = plan_charging(model, schedule, soc_now=0.5, tariff=tariff, charger_kw=7.4,
                         soc_min=0.1, risk=0.05, seed=0)
    print(plan.summary())
    """),
    md("""
    Compare the last two lines: planning on mean energies leaves no margin for a week that
    costs more than average, so the risk-neutral plan is cheaper but its achieved risk is far
    above the target. Per trip (the `_lo`/`_hi` columns are the central 90 % band):
    """),
    code("""
    plan.trips[["trip_id", "departure", "energy_kwh_pred", "energy_kwh_lo", "energy_kwh_hi",
                "soc_arrival_lo", "soc_arrival_pred", "p_below_soc_min"]]
    """),
    md("""
    Cost against risk: the price of certainty. (At a 1 % target this week is infeasible:
    the battery window cannot hold the 99 % energy between two charging stops, and
    `plan_charging` says so, naming the trip.)
    """),
    code("""
    pd.DataFrame([{"risk target": r, "cost": p.cost,
                   "achieved risk (fresh samples)": p.risk_achieved,
                   "grid kWh": p.plan["grid_kwh"].sum()}
                  for r in (0.02, 0.05, 0.2)
                  for p in [plan_charging(model, schedule, soc_now=0.5, tariff=tariff,
                                          charger_kw=7.4, risk=r, compare=False, seed=0)]])
    """),
    code("""
    fig, (ax, ax_price) = plt.subplots(2, 1, figsize=(10, 5.5), sharex=True,
                                       height_ratios=[3, 1], layout="constrained")
    for p, name, color in ((plan, "risk 5 %", "tab:blue"),
                           (plan.neutral, "risk-neutral", "tab:orange")):
        pl = p.plan
        ax.fill_between(pl["slot_start"], pl["soc_end_lo"], pl["soc_end_hi"], color=color,
                        alpha=0.25, lw=0)
        ax.plot(pl["slot_start"], pl["soc_end_pred"], color=color, lw=1.2,
                label=f"{name}: median SoC, 90 % band")
    ax.axhline(0.1, color="r", ls="--", lw=0.8, label="soc_min")
    ax.set(ylabel="state of charge", title="One week: SoC under two charging plans")
    ax.legend(loc="lower left", fontsize=8)
    ax_price.step(tariff["start"], tariff["price_per_kwh"], where="post", color="0.4", lw=0.8)
    ax_c = ax_price.twinx()
    ax_c.bar(plan.plan["slot_start"], plan.plan["charge_kw"], width=0.25, align="edge",
             color="tab:green", alpha=0.7)
    ax_price.set(xlabel="hours from Monday 00:00", ylabel="price / kWh")
    ax_c.set_ylabel("charging, risk 5 % (kW)");
    """),
    md("""
    The green bars show when the risk-aware plan charges, against the tariff below them; the
    shaded bands show how low the SoC may go under each plan. `hybridev plan-charging` does
    the same from the command line with a saved model.
    """),
]

NOTEBOOKS = {
    "01_quickstart.ipynb": QUICKSTART,
    "02_reproducing_the_paper.ipynb": PAPER,
    "03_calibration_from_measured_trips.ipynb": CALIBRATION,
    "04_range_and_charging.ipynb": RANGE,
}


def build(name: str, cells: list[tuple[str, str]]) -> nbformat.NotebookNode:
    """The notebook ``name`` from ``(kind, source)`` cells, without outputs."""
    stem = name.split("_", 1)[0]
    nb = nbformat.v4.new_notebook()
    nb.metadata = {"kernelspec": dict(KERNELSPEC), "language_info": dict(LANGUAGE_INFO)}
    for i, (kind, source) in enumerate(cells):
        new = nbformat.v4.new_markdown_cell if kind == "markdown" else nbformat.v4.new_code_cell
        nb.cells.append(new(source, id=f"nb{stem}-{i:02d}"))
    nbformat.validate(nb)
    return nb


def render() -> dict[str, str]:
    """File name -> the exact text of each notebook."""
    return {name: nbformat.writes(build(name, cells)) + "\n"
            for name, cells in NOTEBOOKS.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="compare with the files on disk instead of writing them")
    args = ap.parse_args(argv)
    stale = []
    for name, text in render().items():
        path = HERE / name
        if args.check:
            if not path.exists() or path.read_text(encoding="utf-8") != text:
                stale.append(name)
        else:
            with atomic_path(path) as tmp:  # all notebooks are rendered before any is written
                tmp.write_text(text, encoding="utf-8")
    if stale:
        print("out of date (run python notebooks/_build.py):", ", ".join(stale))
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
