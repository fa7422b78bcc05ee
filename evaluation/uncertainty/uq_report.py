"""Markdown tables of ``evaluation/uncertainty/uncertainty.py`` (aggregation over seeds and formatting)."""

from __future__ import annotations

import numpy as np
import pandas as pd

__all__ = ["METHODS", "agg", "fmt", "md", "method_label", "pm", "tables"]

METHODS = [("posterior", "before"), ("posterior", "after"), ("ensemble", "before"),
           ("ensemble", "after"), ("combined", "before"), ("combined", "after"),
           ("point+conformal", "after")]
KEYS = ["truth", "test", "method", "stage"]


def method_label(meth: str, stage: str) -> str:
    if meth == "point+conformal":
        return "point net + const. conformal"
    return f"{meth}, {'conformal' if stage == 'after' else 'raw'}"


def md(header: list[str], rows: list[list[str]]) -> str:
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def fmt(x: float, scale: float = 1.0, digits: int = 2) -> str:
    return "n/a" if x is None or not np.isfinite(x) else f"{scale * x:.{digits}f}"


def pm(mean: float, sd: float, scale: float = 1.0, digits: int = 1) -> str:
    """``mean ± sd`` (sd omitted when there is one seed)."""
    if mean is None or not np.isfinite(mean):
        return "n/a"
    s = f"{scale * mean:.{digits}f}"
    return s if sd is None or not np.isfinite(sd) else f"{s} ± {scale * sd:.{digits}f}"


def agg(df: pd.DataFrame, keys=KEYS) -> pd.DataFrame:
    """Mean and sd over seeds of every numeric column, columns ``(metric, mean|std)``."""
    num = df.drop(columns=["seed"]).select_dtypes("number").columns
    return df.groupby(keys, sort=False)[list(num)].agg(["mean", "std"])


def _get(a: pd.DataFrame, key, col) -> tuple[float, float]:
    if key not in a.index or col not in a.columns.get_level_values(0):
        return float("nan"), float("nan")
    r = a.loc[key]
    return float(r[(col, "mean")]), float(r[(col, "std")])


def metric_tables(a: pd.DataFrame, test: str, n_seeds: int, n_test: int) -> str:
    parts = []
    cov_cols = [("cov_e50", "E 50"), ("cov_e80", "E 80"), ("cov_e90", "E 90"),
                ("cov_e95", "E 95"), ("cov_s50", "SoC 50"), ("cov_s80", "SoC 80"),
                ("cov_s90", "SoC 90"), ("cov_s95", "SoC 95")]
    score_cols = [("width_e90", "width E90, kWh", 1, 2), ("width_s90", "width SoC90, pts", 100, 2),
                  ("winkler_e90", "Winkler E90, kWh", 1, 2), ("crps", "CRPS, kWh", 1, 3),
                  ("nll", "NLL, nats", 1, 3), ("mca_e", "MCA E, pts", 100, 1),
                  ("mca_s", "MCA SoC, pts", 100, 1)]
    point_cols = [("mape", "MAPE, %", 1, 2), ("mae", "MAE, kWh", 1, 3), ("rmse", "RMSE, kWh", 1, 3),
                  ("spearman_abs", "Spearman abs", 1, 3), ("spearman_rel", "Spearman rel", 1, 3),
                  ("auroc_abs", "AUROC abs", 1, 3), ("auroc_rel", "AUROC rel", 1, 3),
                  ("spearman_relrel", "Spearman rel/rel", 1, 3),
                  ("auroc_relrel", "AUROC rel/rel", 1, 3)]
    for truth in ("paper", "structured"):
        rows_c, rows_s, rows_p = [], [], []
        for meth, stage in METHODS:
            key = (truth, test, meth, stage)
            lab = method_label(meth, stage)
            rows_c.append([lab] + [pm(*_get(a, key, c), 100) for c, _ in cov_cols])
            rows_s.append([lab] + [pm(*_get(a, key, c), s, d) for c, _, s, d in score_cols])
            rows_p.append([lab] + [pm(*_get(a, key, c), s, d) for c, _, s, d in point_cols])
        parts += [f"### {truth} truth: coverage, % (nominal 50 / 80 / 90 / 95)", "",
                  md(["method"] + [h for _, h in cov_cols], rows_c), "",
                  f"### {truth} truth: width and scores", "",
                  md(["method"] + [h for _, h, _, _ in score_cols], rows_s), "",
                  f"### {truth} truth: point accuracy and confidence signal", "",
                  md(["method"] + [h for _, h, _, _ in point_cols], rows_p), ""]
    head = (f"Test set: **{test}** ({n_test} trips per seed), mean ± sd over {n_seeds} seeds. "
            "E = energy interval, SoC = final-SoC interval; widths of SoC in percentage "
            "points of SoC; MCA = miscalibration area (mean |empirical - nominal| over levels "
            "0.05..0.95), in points; CRPS/NLL of the calibrated distribution (spread factor "
            "of the 90 % level) for conformal methods; NLL Gaussian with the predictive "
            "mean and sd; Spearman/AUROC of `confidence` (predictive sd) against |error| "
            "(abs) or |error| / energy (rel), AUROC for the worst 10 %; rel/rel: "
            "confidence / predicted energy against |error| / energy.")
    return "\n".join([head, "", *parts])


def sharpness_table(a: pd.DataFrame, test: str) -> str:
    rows = []
    for truth in ("paper", "structured"):
        for meth, stage in [("combined", "after"), ("ensemble", "after"), ("posterior", "after"),
                            ("point+conformal", "after")]:
            key = (truth, test, meth, stage)
            r = [truth, method_label(meth, stage)]
            for lv in (50, 80, 90, 95):
                r.append(" / ".join([pm(*_get(a, key, f"cov_e{lv}"), 100),
                                     pm(*_get(a, key, f"width_e{lv}"), 1, 2),
                                     pm(*_get(a, key, f"eqwidth_e{lv}"), 1, 2),
                                     pm(*_get(a, key, f"winkler_e{lv}"), 1, 2)]))
            r.append(f"{pm(*_get(a, key, 'cov_s90'), 100)} / "
                     f"{pm(*_get(a, key, 'width_s90'), 100, 2)}")
            rows.append(r)
    return md(["truth", "method", "50 %: cov % / width / eq. width / Winkler (kWh)", "80 %",
               "90 %", "95 %", "SoC 90 %: cov % / width pts"], rows)


def soc_table(a: pd.DataFrame, test: str) -> str:
    rows = []
    for truth in ("paper", "structured"):
        for meth, stage in [("combined", "after"), ("combined", "before"),
                            ("point+conformal", "after")]:
            key = (truth, test, meth, stage)
            r = [truth, method_label(meth, stage), pm(*_get(a, key, "frac_soc0"), 100)]
            for lv in (50, 90):
                r += [pm(*_get(a, key, f"frac_onesided{lv}"), 100),
                      pm(*_get(a, key, f"cov_s{lv}_onesided"), 100),
                      pm(*_get(a, key, f"cov_s{lv}_twosided"), 100),
                      pm(*_get(a, key, f"cov_e{lv}"), 100)]
            rows.append(r)
    return md(["truth", "method", "trips emptied (SoC 0), %",
               "50 %: one-sided share %", "cov one-sided", "cov two-sided", "cov energy",
               "90 %: one-sided share %", "cov one-sided", "cov two-sided", "cov energy"], rows)


def tables(res: dict) -> dict[str, str]:
    """All ``evaluation/uncertainty/tables/uq_*.md`` contents from the collected results."""
    rows = pd.DataFrame(res["rows"])
    a = agg(rows)
    n_seeds = rows.seed.nunique()
    out = {}
    for test, n in (("fresh", res["n_fresh"]), ("split", 225)):
        out[f"uq_metrics_{test}.md"] = (
            f"# UQ metrics, {test} test set\n\nGenerated by `python evaluation/uncertainty/uncertainty.py`; "
            f"do not edit.\n\n{metric_tables(a, test, n_seeds, n)}")
    out["uq_sharpness.md"] = "\n".join([
        "# Sharpness at equal coverage: adaptive conformal intervals vs a constant-width "
        "conformal interval around the paper's point network", "",
        "Generated by `python evaluation/uncertainty/uncertainty.py`; do not edit. Energy intervals; each "
        "cell: empirical coverage % / mean width / equal-coverage width / Winkler score "
        "(kWh), mean ± sd over "
        f"{n_seeds} seeds. All four use the same 191 calibration trips per seed.", "",
        "eq. width: the width each method's interval shape `mu ± k s` (s = its "
        "confidence; s = 1 for the constant interval) needs for exactly the nominal coverage "
        "on the test set itself, k tuned on the test labels: an oracle comparison of "
        "adaptivity at truly equal coverage, not a usable method.", "",
        "## Fresh test set", "", sharpness_table(a, "fresh"), "",
        "## Paper split (225 test trips)", "", sharpness_table(a, "split"), ""])
    out["uq_soc.md"] = "\n".join([
        "# Final-SoC intervals and the point mass at SoC 0", "",
        "Generated by `python evaluation/uncertainty/uncertainty.py`; do not edit. A trip whose energy "
        "exceeds the charge on board ends at SoC 0 (the truth's `soc_final = max(0, s0 - E/C)`). "
        "When the upper energy bound reaches `s0 C`, the SoC interval is the one-sided "
        "`[0, s0 - E_lo'/C]` (one-sided lower energy bound at the same level); otherwise it "
        "is the image of the energy interval. Per level: share of test trips that get the "
        "one-sided interval, SoC coverage on those and on the others, and the energy "
        f"coverage for comparison. Fresh test set, mean ± sd over {n_seeds} seeds, in %.", "",
        soc_table(a, "fresh"), ""])
    out["uq_conditional.md"] = conditional_table(pd.DataFrame(res["conditional"]), n_seeds)
    per = rows[(rows.method == "combined") & (rows.stage == "after")]
    prow = [[r.truth, r.test, r.seed, fmt(r.cov_e50, 100, 1), fmt(r.cov_e80, 100, 1),
             fmt(r.cov_e90, 100, 1), fmt(r.cov_e95, 100, 1), fmt(r.cov_s90, 100, 1),
             fmt(r.width_e90), fmt(r.mape), fmt(r.spearman_abs, 1, 3), fmt(r.auroc_abs, 1, 3)]
            for r in per.itertuples()]
    out["uq_per_seed.md"] = "\n".join([
        "# Per-seed results of the combined model (conformal)", "",
        "Generated by `python evaluation/uncertainty/uncertainty.py`; do not edit. Coverage in %.", "",
        md(["truth", "test", "seed", "E50", "E80", "E90", "E95", "SoC90", "width E90, kWh",
            "MAPE, %", "Spearman abs", "AUROC abs"], prow), ""])
    if res["shift"]:
        out["uq_shift.md"] = shift_table(res["shift"])
    out["uq_recovery.md"] = "\n".join([
        recovery_table(res["recovery"], res["recovery_info"]), "",
        "## Before the fix: DEMove + 20 % DESnookerMove (hybridev's earlier sampler)", "",
        recovery_table(res["recovery_old"], res["recovery_old_info"]).split("\n", 2)[2]])
    return out


def conditional_table(cond: pd.DataFrame, n_seeds: int) -> str:
    ca = cond.groupby(["truth", "by", "group", "method"], sort=False).agg(
        n=("n", "mean"), e=("cov_e90", "mean"), e_sd=("cov_e90", "std"), s=("cov_s90", "mean"),
        s_sd=("cov_s90", "std"))
    rows = []
    for (t, b, g), d in ca.groupby(level=[0, 1, 2], sort=False):
        c = d.xs((t, b, g), level=[0, 1, 2])
        r = [t, b, g, f"{c['n'].iloc[0]:.0f}"]
        for meth in ("combined", "point+conformal"):
            x = c.loc[meth]
            r += [pm(x.e, x.e_sd, 100), pm(x.s, x.s_sd, 100)]
        rows.append(r)
    return "\n".join([
        "# Conditional coverage of the 90 % intervals, fresh test set", "",
        "Generated by `python evaluation/uncertainty/uncertainty.py`; do not edit. Combined model "
        "(conformal) vs the point network with constant-width conformal intervals. Mean ± sd "
        f"over {n_seeds} seeds; n = trips per seed in the group. Marginal coverage can hide "
        "groups that are under- or over-covered.", "",
        md(["truth", "grouped by", "group", "n", "combined: energy", "combined: SoC",
            "point+conformal: energy", "point+conformal: SoC"], rows), ""])


def shift_summary(shift: list) -> pd.DataFrame:
    df = pd.DataFrame([{k: v for k, v in r.items() if k != "ratio"} for r in shift])
    return df.groupby(["truth", "shift", "model", "part", "range"], sort=False).agg(
        ["mean", "std"]).drop(columns=["seed"], level=0)


def shift_table(shift: list) -> str:
    s = shift_summary(shift)
    rows = []
    for key, r in s.iterrows():
        truth, sh, model, part, rng = key
        rows.append([truth, sh, model, f"{rng} ({'in' if part == 'in' else 'shifted'})",
                     f"{r[('n_train', 'mean')]:.0f}", f"{r[('n_test', 'mean')]:.0f}",
                     pm(r[("cov_e90", "mean")], r[("cov_e90", "std")], 100),
                     pm(r[("cov_s90", "mean")], r[("cov_s90", "std")], 100),
                     pm(r[("cov_s50", "mean")], r[("cov_s50", "std")], 100),
                     pm(r[("mape", "mean")], r[("mape", "std")], 1, 2),
                     pm(r[("conf_median_kwh", "mean")], r[("conf_median_kwh", "std")], 1, 3),
                     pm(r[("ratio_median", "mean")], r[("ratio_median", "std")], 100, 2),
                     pm(r[("ood_share", "mean")], r[("ood_share", "std")], 100)])
    n = pd.DataFrame(shift).seed.nunique()
    return "\n".join([
        "# Distribution shift: coverage and confidence in range vs shifted", "",
        "Generated by `python evaluation/uncertainty/uncertainty.py`; do not edit. `shift-trained`: "
        "HybridModel() defaults fitted on the fit trips inside the range only; "
        "`all-conditions`: the combined model of the main experiment (fitted on all "
        f"conditions) on the same test trips. Fresh test trips; mean ± sd over {n} seeds. "
        "ratio = confidence / predicted energy (median over trips); out of domain = share "
        "of the test trips the model flags `in_domain=False` (their intervals are widened, "
        "`hybridev.learning.ood`).", "",
        md(["truth", "shift", "model", "test range", "n train", "n test", "cov E90 %",
            "cov SoC90 %", "cov SoC50 %", "MAPE %", "median conf, kWh", "median ratio, %",
            "out of domain %"],
           rows), ""])


def recovery_table(rec: pd.DataFrame, info: dict) -> str:
    lv = info["level"]
    g = rec.groupby("parameter", sort=False)
    rows = []
    for name, d in g:
        n = len(d)
        rows.append([name, n, fmt(d.inside.mean(), 100, 1),
                     fmt(np.sqrt(lv * (1 - lv) / n), 100, 1),
                     fmt(np.median((d["hi"] - d["lo"]) / d["truth"].abs()), 100, 1),
                     fmt(np.mean((d["median"] - d["truth"]) / d["sd"]), 1, 2),
                     fmt(np.std((d["median"] - d["truth"]) / d["sd"], ddof=1), 1, 2)])
    for label, d in (("all physics parameters", rec[rec.parameter != "noise_rel"]),
                     ("all incl. noise_rel", rec)):
        per_seed = d.groupby("seed").inside.mean()  # seeds are independent, parameters not
        rows.append([label, len(d), fmt(d.inside.mean(), 100, 1),
                     fmt(per_seed.std(ddof=1) / np.sqrt(len(per_seed)), 100, 1), "", "", ""])
    sampler = ("library sampler (`calibrate_physics` as is)" if info["sampler"] == "library"
               else "pre-fix sampler (DEMove + 20 % DESnookerMove)")
    return "\n".join([
        f"# Parameter recovery: coverage of the {lv:.0%} credible intervals", "",
        f"Generated by `python evaluation/uncertainty/uncertainty.py`; do not edit. {sampler}; "
        f"{info['n_seeds']} seeds x 300 trips; true parameters drawn from the prior "
        "(set-up in `evaluation/uncertainty/uq_recovery.py`); ConvergenceWarnings: "
        f"{info['warnings']}; calibration time {info['seconds']:.0f} s in total. "
        "SE = binomial standard error at the nominal rate per parameter; for the overall "
        "lines the standard error of the mean over seeds of each seed's share (parameters "
        "of one seed are correlated); z = (median - truth) / sd: "
        "mean near 0 and sd near 1 for a calibrated posterior.", "",
        md(["parameter", "n", "coverage %", "SE %", "median width / truth, %", "mean z",
            "sd z"], rows), ""])
