"""Where the 20-trip CV+ over-coverage lives: design, conditions, held-out scores (study).

Run from the repository root::

    python evaluation/cvplus_small_n/mechanism.py [--out DIR] [--draws 16]
        [--refit-draws 12] [--jobs 2]

``cvplus_small_n.py`` and ``exchangeability.py`` find that the default (CV+) 90 %
intervals cover about 0.95 of new trips at 20 synthetic training trips, with no
defect in the scoring. This script tests three more explanations, on the truth and
test set of ``shift_and_small_data`` (``truth(n, seed)``, 1,000 test trips from seed
999, ``HybridModel()`` defaults):

A. **The balanced design.** ``make_trips`` splits the driving modes equally, so the
   trips of one draw are not independent: a held-out trip's mode is
   under-represented in its fold's training trips, which would make the
   out-of-fold scores pessimistic. The same fit on 20 trips drawn at random from a
   2,000-trip pool (independent modes) tells whether this matters.
B. **Coverage by condition.** The library's interval and width per temperature of
   the in-domain test trips, and the mean normalised score ``|y - mu_k| / s_k`` of
   the fold models on their held-out trips and on the test trips, per temperature:
   whether the normalisation (the predictive sd) follows how hard each condition is.
C. **Are held-out scores exchangeable with new trips' scores?** For each training
   trip, the share ``p`` of the test trips whose score under the same fold model is at
   least the trip's out-of-fold score. Exchangeable scores give uniform ``p`` and a
   second-smallest ``p`` of each draw of ``2/21 = 0.095`` on average (which is one
   minus the coverage of the pooled 19th-of-20 threshold). The same for standalone
   refits (a ``HybridModel`` fitted from scratch on the 16 other trips of each of 5
   folds, sharing nothing with the held-out trips). Extreme held-out scores
   (``p < 0.05``) are then split by how many trips of the same temperature and mode
   the fold's training trips hold.
D. **What if the normalisation followed the temperature band?** A what-if, not the
   library: each score is divided by a difficulty factor of its temperature band
   (cold < 5 degC <= mild < 20 degC <= warm, the Mondrian bands), the band's mean
   absolute out-of-fold score over all bands' (shrunk towards 1 by
   :data:`SHRINK_TRIPS` pseudo-trips), estimated for each training trip from the
   *other* folds' trips only (cross-fitted, so a trip's factor does not see its own
   score) and for new trips from all of them; the CV+ interval then uses the fold
   models' spreads times the new trip's factor. Coverage and width overall and by
   temperature, on the same balanced fits as part B.

E. **Is it how CV+ combines the fold models?** The same 20 out-of-fold scores and
   their pooled threshold ``q`` (the 19th smallest), combined with the fold models in
   five ways: the CV+ interval; each fold model alone (``mu_k +- q s_k``, coverage
   averaged over the folds); the mean of the fold models; the final model; Vovk's
   cross-conformal set. If combining were the cause, each fold model alone would cover
   about ``19/21 = 0.905``. Also the CV+ coverage of every test trip (no
   out-of-domain widening), and the share flagged out of the domain.

Writes ``mechanism.md`` and ``.json`` to ``--out`` (default: this folder). Uses the
raw distributions of :func:`hybridev.learning.pipeline.raw_distributions`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "shift_and_small_data"))
import shift_and_small_data as ssd  # the truth of the size study

from hybridev import HybridModel
from hybridev.core.fileio import atomic_path
from hybridev.learning.conformal import CVPlusConformal
from hybridev.learning.mondrian import TEMPERATURE_BANDS_C
from hybridev.learning.pipeline import raw_distributions

HERE = Path(__file__).resolve().parent
LEVEL = 0.9
N = 20
TEMPS = (-5.0, 20.0, 32.0)  # the truth's temperatures (make_trips)
K_TH = int(np.ceil((N + 1) * LEVEL))  # the pooled threshold's rank (19 of 20)
SHRINK_TRIPS = 3.0
"""Pseudo-trips at factor 1 in part D's band factors (a band of 3 trips moves half-way)."""


def _beta_sd() -> float:
    """Sd of Beta(K_TH, N + 1 - K_TH): one draw's coverage under exchangeability."""
    a, b = K_TH, N + 1 - K_TH
    return float(np.sqrt(a * b / ((a + b) ** 2 * (a + b + 1))))


def _test():
    test = ssd.truth(1000, 999)
    return test.drop(columns=["energy_kwh", "soc_final"]), test["energy_kwh"].to_numpy(float)


def _iid_draw(rep: int):
    """20 trips drawn at random from a 2,000-trip pool: modes independent between trips."""
    pool = ssd.truth(2000, 300 + rep)
    out = pool.sample(N, random_state=rep).reset_index(drop=True)
    out["trip_id"] = np.arange(N)
    return out


def _fold_moments(model: HybridModel, x, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Predictive means and spreads of each fold model on ``x``, (n_folds, n_trips)."""
    d = raw_distributions(model, x, seed=seed, nets=tuple(model.calibrator_.folds()),
                          physics=tuple(model.cv_physics_))[0]
    mu = np.stack([q.mean() for q in d])
    return mu, np.maximum(np.stack([q.std() for q in d]), 1e-12)


def _band(t) -> np.ndarray:
    return np.searchsorted(TEMPERATURE_BANDS_C, np.asarray(t, float), side="right")


def _band_factors(scores: np.ndarray, band: np.ndarray, use: np.ndarray) -> np.ndarray:
    """Difficulty factor of each band (3,) from the scores of the trips ``use``."""
    total = scores[use].mean()
    out = np.ones(3)
    for b in range(3):
        sel = use & (band == b)
        out[b] = (scores[sel].sum() + SHRINK_TRIPS * total) / (sel.sum() + SHRINK_TRIPS) / total
    return out


def band_normalised(cp: CVPlusConformal, band_train: np.ndarray, band_new: np.ndarray,
                    mu: np.ndarray, sd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Part D's CV+ interval with cross-fitted band difficulty factors."""
    r = np.abs(cp.residuals)
    g_train = np.array([_band_factors(r, band_train, cp.fold != cp.fold[i])[band_train[i]]
                        for i in range(r.size)])
    g_new = _band_factors(r, band_train, np.ones(r.size, dtype=bool))[band_new]
    scaled = CVPlusConformal(cp.residuals / g_train, cp.fold)
    return scaled.cv_interval(mu, sd * g_new[None, :], LEVEL)


def design_draw(rep: int) -> dict:
    """Parts A, B and the CV+ half of C for one training draw."""
    x, y = _test()
    t_test = x["temperature_c"].to_numpy(float)
    out = {"draw": rep}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for design, train in (("balanced", ssd.truth(N, 100 + rep)), ("iid", _iid_draw(rep))):
            model = HybridModel(conformal="cv+").fit(train, seed=rep)
            pred = model.predict_interval(x, LEVEL, seed=rep)
            ok = pred["in_domain"].to_numpy(bool)
            lo, hi = pred["energy_kwh_lo"].to_numpy(float), pred["energy_kwh_hi"].to_numpy(float)
            inside = (y >= lo) & (y <= hi)
            row = {"coverage_in": float(inside[ok].mean()),
                   "rel_width_in": float(np.mean((hi - lo)[ok] / y[ok]))}
            if design == "balanced":
                cp = model.conformal_
                t_train = train["temperature_c"].to_numpy(float)
                oof = np.abs(cp.residuals)
                mu, sd = _fold_moments(model, x, rep)
                sc = np.abs(y[None, :] - mu) / sd
                blo, bhi = band_normalised(cp, _band(t_train), _band(t_test), mu, sd)
                b_in = (y >= blo) & (y <= bhi)
                row["band_coverage_in"] = float(b_in[ok].mean())
                row["band_rel_width_in"] = float(np.mean((bhi - blo)[ok] / y[ok]))
                for t in TEMPS:
                    sel = ok & (t_test == t)
                    row[f"coverage_{t:g}"] = float(inside[sel].mean())
                    row[f"rel_width_{t:g}"] = float(np.mean((hi - lo)[sel] / y[sel]))
                    row[f"test_score_{t:g}"] = float(sc[:, sel].mean())
                    row[f"band_coverage_{t:g}"] = float(b_in[sel].mean())
                    row[f"band_rel_width_{t:g}"] = float(np.mean((bhi - blo)[sel] / y[sel]))
                    m = t_train == t
                    row[f"oof_score_{t:g}"] = float(oof[m].mean()) if m.any() else None
                    row[f"n_train_{t:g}"] = int(m.sum())
                row["held_out"] = _held_out_rows(train, cp.fold, oof, sc[:, ok])
                row.update(_aggregation(model, cp, x, y, ok, mu, sd, sc, rep))
            out[design] = row
    return out


def _aggregation(model: HybridModel, cp: CVPlusConformal, x, y: np.ndarray, ok: np.ndarray,
                 mu: np.ndarray, sd: np.ndarray, sc: np.ndarray, rep: int) -> dict:
    """Part E: the same 20 scores, combined with the fold models in five ways."""
    k = int(np.ceil((cp.n_calibration + 1) * LEVEL))
    q = np.sort(np.abs(cp.residuals))[k - 1]  # the pooled threshold (19th of 20)
    out = {}
    lo, hi = cp.cv_interval(mu, sd, LEVEL)
    out["E_cvplus"] = ((y >= lo) & (y <= hi), hi - lo)
    per = np.abs(y[None, :] - mu) <= q * sd  # (K, m): each fold model alone
    out["E_per_fold"] = (per.mean(axis=0), 2 * q * sd.mean(axis=0))
    mb, sb = mu.mean(axis=0), sd.mean(axis=0)
    out["E_fold_mean"] = (np.abs(y - mb) <= q * sb, 2 * q * sb)
    d = raw_distributions(model, x, seed=rep)[0][0]
    mf, sf = d.mean(), np.maximum(d.std(), 1e-12)
    out["E_final"] = (np.abs(y - mf) <= q * sf, 2 * q * sf)
    # Vovk's cross-conformal set {y: (1 + #{i: |r_i| >= score of y under fold k(i)}) / (n + 1)
    # > alpha}; coverage only (its set need not be an interval)
    count = (np.abs(cp.residuals)[:, None] >= sc[cp.fold]).sum(axis=0)
    out["E_cross"] = ((1 + count) / (cp.n_calibration + 1) > 1 - LEVEL, None)
    row = {}
    for name, (cov, width) in out.items():
        row[f"{name}_coverage"] = float(np.mean(cov[ok]))
        if width is not None:
            row[f"{name}_width"] = float(np.mean(width[ok] / y[ok]))
    cov_all, w_all = out["E_cvplus"]
    row["E_cvplus_all_coverage"] = float(np.mean(cov_all))  # every test trip, no OOD widening
    row["E_cvplus_all_width"] = float(np.mean(w_all / y))
    row["E_cvplus_flagged_coverage"] = float(np.mean(cov_all[~ok])) if (~ok).any() else None
    row["E_flagged_share"] = float(np.mean(~ok))
    row["E_fold_spread"] = float(np.mean(mu[:, ok].std(axis=0, ddof=1) / sb[ok]))
    row["E_score_corr"] = float(np.mean(np.corrcoef(sc[:, ok])[np.triu_indices(len(mu), 1)]))
    return row


def _cell_count(train, fold: np.ndarray, i: int) -> int:
    """Trips of trip ``i``'s temperature and mode among its fold's training trips."""
    rest = (fold != fold[i])
    same = ((train["temperature_c"].to_numpy(float) == train["temperature_c"].iloc[i])
            & (train["mode"].to_numpy(object) == train["mode"].iloc[i]))
    return int((rest & same).sum())


def _held_out_rows(train, fold: np.ndarray, held_scores: np.ndarray,
                   test_scores: np.ndarray) -> list[dict]:
    """p of each held-out score against its fold model's scores on the test trips."""
    return [{"p": float(np.mean(test_scores[fold[i]] >= held_scores[i])),
             "cell": _cell_count(train, fold, i)} for i in range(len(held_scores))]


def refit_draw(rep: int) -> dict:
    """The standalone half of C: 5 refits on the other 16 trips of each fold."""
    x, y = _test()
    train = ssd.truth(N, 100 + rep)
    fold = np.random.default_rng(rep).permutation(np.arange(N) % 5)
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in range(5):
            rest = train[fold != k].reset_index(drop=True)
            held = train[fold == k]
            model = HybridModel(conformal_fraction=0.0).fit(rest, seed=10 * rep + k)
            dt = raw_distributions(model, x, seed=rep)[0][0]
            dh = raw_distributions(model, held.drop(columns=["energy_kwh", "soc_final"]),
                                   seed=rep)[0][0]
            st = np.abs(y - dt.mean()) / np.maximum(dt.std(), 1e-12)
            sh = np.abs(held["energy_kwh"].to_numpy(float) - dh.mean()) / np.maximum(dh.std(),
                                                                                     1e-12)
            for j, i in enumerate(np.flatnonzero(fold == k)):
                rows.append({"p": float(np.mean(st >= sh[j])),
                             "cell": _cell_count(train, fold, int(i))})
    return {"draw": rep, "held_out": rows}


def _p_summary(draws: list[list[dict]]) -> dict:
    p = np.array([r["p"] for d in draws for r in d])
    p2 = [float(np.sort([r["p"] for r in d])[1]) for d in draws]
    return {"n": int(p.size), "share_below_0.05": float(np.mean(p < 0.05)),
            "share_below_0.10": float(np.mean(p < 0.10)), "mean_second_smallest_p": p2}


def _cell_part(draws: list[list[dict]], lo: int, hi: int) -> str:
    """"trips | share p < 0.05" of the held-out trips with lo..hi same-cell training trips."""
    p = np.array([x["p"] for d in draws for x in d if lo <= x["cell"] <= hi])
    return f"{p.size} | {np.mean(p < 0.05):.3f}" if p.size else "0 | -"


def _ms(v) -> str:
    v = np.asarray([u for u in v if u is not None], float)
    return f"{v.mean():.3f} +- {v.std(ddof=1) / np.sqrt(len(v)):.3f}"


def write(res: dict, out: Path) -> None:
    a, r = res["design"], res["refit"]
    lines = ["# CV+ at 20 trips: design, conditions and held-out scores (study)", "",
             f"Generated by `python evaluation/cvplus_small_n/mechanism.py` in "
             f"{res['runtime_s']} s; do not edit by hand. Set-up: the script's docstring. "
             "Mean +- standard error over the draws.", "",
             f"## A. Balanced against independent modes ({len(a)} draws)", "",
             "| training draw | 90 % coverage, in-domain test trips | width / energy |",
             "|---|---|---|"]
    for design, label in (("balanced", "`truth(20, seed)`: modes split equally"),
                          ("iid", "20 trips at random from a 2,000-trip pool")):
        lines.append(f"| {label} | {_ms([d[design]['coverage_in'] for d in a])} | "
                     f"{_ms([d[design]['rel_width_in'] for d in a])} |")
    lines += ["", "## B. By temperature (balanced draws, in-domain test trips)", "",
              "| temperature | training trips per draw | 90 % coverage | width / energy | "
              "mean score, held-out trips | mean score, test trips |", "|---|---|---|---|---|---|"]
    for t in TEMPS:
        b = [d["balanced"] for d in a]
        lines.append(f"| {t:g} degC | {np.mean([x[f'n_train_{t:g}'] for x in b]):.1f} | "
                     f"{_ms([x[f'coverage_{t:g}'] for x in b])} | "
                     f"{_ms([x[f'rel_width_{t:g}'] for x in b])} | "
                     f"{_ms([x[f'oof_score_{t:g}'] for x in b])} | "
                     f"{_ms([x[f'test_score_{t:g}'] for x in b])} |")
    cv = _p_summary([d["balanced"]["held_out"] for d in a])
    sa = _p_summary([d["held_out"] for d in r])
    lines += ["", "## C. Held-out scores against the same model's scores on new trips", "",
              "`p`: share of the test trips scoring at least as high as the held-out trip. "
              "Exchangeable: 0.05 and 0.10 below 0.05 and 0.10; second-smallest `p` of a "
              "draw 0.095 on average (one minus the coverage of the 19th of 20 scores).", "",
              "| models | held-out trips | share p < 0.05 | share p < 0.10 | "
              "second-smallest p per draw |", "|---|---|---|---|---|",
              f"| CV+ fold models in the fit ({len(a)} draws) | {cv['n']} | "
              f"{cv['share_below_0.05']:.3f} | {cv['share_below_0.10']:.3f} | "
              f"{_ms(cv['mean_second_smallest_p'])} |",
              f"| standalone refits on 16 trips ({len(r)} draws) | {sa['n']} | "
              f"{sa['share_below_0.05']:.3f} | {sa['share_below_0.10']:.3f} | "
              f"{_ms(sa['mean_second_smallest_p'])} |", "",
              "Share of extreme held-out scores (p < 0.05) by the number of trips of the same "
              "temperature and mode among the fold's training trips:", "",
              "| same-cell training trips | CV+ fold models: trips | p < 0.05 | "
              "standalone: trips | p < 0.05 |", "|---|---|---|---|---|"]
    for lo_, hi_, label in ((0, 0, "0"), (1, 1, "1"), (2, 99, "2 or more")):
        lines.append(f"| {label} | {_cell_part([d['balanced']['held_out'] for d in a], lo_, hi_)}"
                     f" | {_cell_part([d['held_out'] for d in r], lo_, hi_)} |")
    b = [d["balanced"] for d in a]
    lines += ["", f"## D. What if: band-normalised scores (balanced draws, {len(b)} draws)", "",
              "| test trips | library: coverage | library: width / energy | "
              "band-normalised: coverage | band-normalised: width / energy |",
              "|---|---|---|---|---|",
              f"| all in-domain | {_ms([x['coverage_in'] for x in b])} | "
              f"{_ms([x['rel_width_in'] for x in b])} | "
              f"{_ms([x['band_coverage_in'] for x in b])} | "
              f"{_ms([x['band_rel_width_in'] for x in b])} |"]
    for t in TEMPS:
        lines.append(f"| {t:g} degC | {_ms([x[f'coverage_{t:g}'] for x in b])} | "
                     f"{_ms([x[f'rel_width_{t:g}'] for x in b])} | "
                     f"{_ms([x[f'band_coverage_{t:g}'] for x in b])} | "
                     f"{_ms([x[f'band_rel_width_{t:g}'] for x in b])} |")
    lines += ["", f"## E. One set of scores, five ways to combine the fold models ({len(b)} "
              "draws)", "",
              "The same 20 out-of-fold scores and pooled threshold `q` (their 19th smallest), "
              "in-domain test trips:", "",
              "| interval | 90 % coverage | width / energy |", "|---|---|---|"]
    for name, label in (("E_cvplus", "CV+ (the library): quantiles over the 20 fold-model "
                                     "endpoints"),
                        ("E_per_fold", "each fold model alone, `mu_k +- q s_k` (mean over k)"),
                        ("E_fold_mean", "mean of the fold models, `mean mu_k +- q mean s_k`"),
                        ("E_final", "final model (all 20 trips), `mu +- q s`"),
                        ("E_cross", "Vovk's cross-conformal set (coverage only)")):
        w = [x.get(f"{name}_width") for x in b]
        lines.append(f"| {label} | {_ms([x[f'{name}_coverage'] for x in b])} | "
                     f"{_ms(w) if w[0] is not None else '-'} |")
    lines += ["", "CV+ on every test trip, without the out-of-domain widening: coverage "
              f"{_ms([x['E_cvplus_all_coverage'] for x in b])}, width "
              f"{_ms([x['E_cvplus_all_width'] for x in b])}; share of test trips flagged out "
              f"of the domain {_ms([x['E_flagged_share'] for x in b])}.", "",
              "Reference: with exchangeable scores, the coverage of one draw's pooled "
              f"threshold is Beta({K_TH}, {N + 1 - K_TH}) distributed: mean "
              f"{K_TH / (N + 1):.3f}, sd {_beta_sd():.3f}; the standard error of a mean "
              f"over {len(b)} draws is {_beta_sd() / np.sqrt(len(b)):.3f} (8 draws: "
              f"{_beta_sd() / np.sqrt(8):.3f})."]
    lines += ["", "Spread of the fold models' means at a test trip over their mean predictive "
              f"sd: {_ms([x['E_fold_spread'] for x in b])}; mean correlation between two "
              f"fold models' normalised scores on the test trips: "
              f"{_ms([x['E_score_corr'] for x in b])}."]
    with atomic_path(out / "mechanism.md") as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")


def _one_thread() -> None:
    import torch

    torch.set_num_threads(1)  # one core per worker process


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--draws", type=int, default=16, help="training draws of parts A-C")
    ap.add_argument("--refit-draws", type=int, default=12,
                    help="draws of the standalone refits of part C (5 fits each)")
    ap.add_argument("--from-json", action="store_true",
                    help="rewrite mechanism.md from the saved mechanism.json (no fits)")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (results do not "
                    "depend on it: every draw has its own seeds)")
    args = ap.parse_args(argv)
    if args.from_json:
        write(json.loads((args.out / "mechanism.json").read_text()), args.out)
        print(f"wrote {args.out / 'mechanism.md'} from mechanism.json")
        return 0
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(1, args.jobs),
                             initializer=_one_thread if args.jobs > 1 else None) as ex:
        design = list(ex.map(design_draw, range(args.draws)))
        refit = list(ex.map(refit_draw, range(args.refit_draws)))
    res = {"design": design, "refit": refit, "runtime_s": round(time.perf_counter() - t0, 1),
           "jobs": args.jobs}
    args.out.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out / "mechanism.json") as tmp:
        Path(tmp).write_text(json.dumps(res, indent=1))
    write(res, args.out)
    print(f"wrote {args.out / 'mechanism.md'} in {res['runtime_s']} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
