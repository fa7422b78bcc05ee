"""Calibration report from measured trips: fit, score on held-out trips, write HTML + JSON.

:func:`calibration_report` splits the measured trips into a training part and
a held-out test part (whole groups, e.g. driving sessions, when a group
column is present: back-to-back trips share routes and weather, so a random
split would leak), fits on the training part and scores three predictors on
the test part:

(a) **nominal physics**: the force-balance model with the nominal vehicle;
(b) **calibrated physics**: the emcee posterior of the physics parameters
    (:func:`hybridev.bayes.sampler.calibrate_physics`); point prediction at the
    posterior medians, intervals from the posterior predictive (parameter
    uncertainty plus the inferred relative noise);
(c) **hybrid**: :class:`hybridev.learning.model.HybridModel` with its probabilistic
    defaults (physics posterior + deep ensemble + normalised split conformal).

All three run their physics on the logged speed traces when the measured trips
have them (:func:`hybridev.data.logs.read_measured_trips` with a time series), and
on synthesised traces otherwise.

Conventions (documented choices):

* Trips without a ``mode``: (b) uses ``missing_mode="infer"`` (mixture over the
  paper's profiles with learned weights) unless told otherwise, (a) uses the
  ``"normal"`` profile (:data:`hybridev.learning.features.UNKNOWN_MODE_PHYSICS`) or the
  profile given to (b); with logged traces, unlabelled trips use the library's
  ``logged`` profile in both (their trace holds the driving style).
* Conformal calibration share of (c): at least 15 % (the model's default) and
  enough trips for the report's ``level`` to be reachable
  (``n_cal >= level / (1 - level)``, 9 trips at 90 %), at most 50 %. Higher
  levels may still be unreachable with few trips: their intervals are
  unbounded, reported as such (coverage 1, width ``null`` in JSON).
* Trips with a missing group value form a group of their own.
* ``confidence`` flags: the ``FLAG_FRACTION`` (10 %) held-out trips with the
  largest predictive standard deviation of (c).

Figures: :mod:`hybridev.apps.report.figures`. The output directory is written
atomically (:func:`hybridev.core.fileio.atomic_dir`): a failed run leaves none.

Module size (about 410 lines): one workflow, fit, score and write, kept in one
place so the report's numbers come from one visible code path; the figures
(:mod:`hybridev.apps.report.figures`), the scoring
(:mod:`hybridev.apps.report.scoring`) and the HTML (:mod:`hybridev.apps.report.html`)
are already apart.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from hybridev.apps.report.html import write_report
from hybridev.apps.report.quality import data_notes
from hybridev.apps.report.scoring import FLAG_FRACTION, REPORT_LEVELS, score_holdout
from hybridev.bayes.groups import auto_group_column, group_labels
from hybridev.bayes.priors import DEFAULT_PARAMS
from hybridev.bayes.sampler import calibrate_physics
from hybridev.data.logs import MeasuredTrips, measured_from_frames
from hybridev.learning.features import UNKNOWN_MODE_PHYSICS
from hybridev.physics.params import PROFILES, VehicleParams
from hybridev.physics.stats import energy_from_stats
from hybridev.physics.stats_build import trip_stats

__all__ = ["FLAG_FRACTION", "REPORT_LEVELS", "HoldoutResult", "calibration_report",
           "holdout_evaluation", "score_holdout", "split_trips", "write_report"]

_PREDICTIVE_DRAWS = 4000


@dataclass(eq=False)
class HoldoutResult:
    """Predictions of the three predictors on held-out trips (see the module docstring).

    Attributes
    ----------
    predictions : pandas.DataFrame
        One row per held-out trip: ``trip_id`` and the group (when known),
        the trip features, ``max_speed_kmh`` (of the trace the physics used),
        ``energy_kwh`` (measured), ``energy_kwh_nominal``,
        ``energy_kwh_calibrated`` with ``_lo``/``_hi``/``_sd`` (posterior
        predictive at ``level``), the hybrid's physics term
        ``energy_kwh_hybrid_physics``, ``energy_kwh_pred``, ``energy_kwh_lo``,
        ``energy_kwh_hi`` (infinite when unbounded), ``soc_final_pred``,
        ``soc_final_lo``, ``soc_final_hi`` and ``confidence`` (predictive sd,
        higher = less sure); energies in kWh.
    levels : numpy.ndarray, shape (L,)
        Nominal levels of ``intervals``.
    intervals : dict
        ``{"calibrated" | "hybrid": (lo (L, n), hi (L, n))}``, kWh; the hybrid's
        may be infinite where the conformal step cannot reach the level.
    calibrated_draws : numpy.ndarray, shape (n_draws, n), kWh
        Posterior predictive draws of (b).
    hybrid_mixture : tuple or None
        ``(means (n, K), stds (n, K), weights (K,))`` of (c)'s predictive
        distribution at ``level`` (None if the level is unreachable).
    posterior : PhysicsPosterior
        Posterior of (b), fitted on the training trips.
    model : HybridModel
        Fitted hybrid (c).
    level : float
    n_train, n_test, n_train_groups, n_test_groups : int
    logged_traces : bool
        Whether (a) and (b) used logged traces.
    warnings : list of str
        Warnings raised while fitting (e.g. a short MCMC chain).
    config : dict
        Settings of the run.
    """

    predictions: pd.DataFrame
    levels: np.ndarray
    intervals: dict
    calibrated_draws: np.ndarray
    hybrid_mixture: tuple | None
    posterior: object
    model: object
    level: float
    n_train: int
    n_test: int
    n_train_groups: int | None
    n_test_groups: int | None
    logged_traces: bool
    warnings: list = field(default_factory=list)
    config: dict = field(default_factory=dict)


def _groups(trips: pd.DataFrame, group_column: str | None) -> np.ndarray | None:
    if group_column == "auto":
        group_column = auto_group_column(trips)
    if not group_column or group_column not in trips.columns:
        return None
    g = group_labels(trips, group_column).astype(object)  # a date: its calendar day
    missing = g.isna().to_numpy()
    out = g.astype(str).to_numpy(object)
    out[missing] = [f"\0row{i}" for i in np.flatnonzero(missing)]  # each its own group
    return out


def split_trips(trips: pd.DataFrame, test_fraction: float = 0.2, *, seed: int = 0,
                group_column: str | None = "auto") -> np.ndarray:
    """Boolean test mask: whole groups held out when ``group_column`` exists, else random.

    ``"auto"`` (default) holds out whole days (``date``, timestamps cut to the
    calendar day), else whole ``session_group`` values, else the days of
    ``start_time``, as ``fit(groups="auto")``
    (:func:`hybridev.bayes.groups.auto_group_column`); a ``date`` column named
    explicitly is cut to days too.

    Parameters
    ----------
    trips : pandas.DataFrame
    test_fraction : float in (0, 1)
        Share of the groups (sklearn ``GroupShuffleSplit``) or, without
        groups, of the trips (``ShuffleSplit``) held out.
    seed : int
    group_column : str or None

    Returns
    -------
    numpy.ndarray, shape (n_trips,), bool

    Examples
    --------
    >>> t = pd.DataFrame({"session_group": ["a", "a", "b", "b", "c"]})
    >>> m = split_trips(t, 0.3, seed=0)  # no date column: the sessions
    >>> int(m.sum()) in (1, 2), len(set(t.session_group[m])) == 1
    (True, True)
    """
    from sklearn.model_selection import GroupShuffleSplit, ShuffleSplit

    if not (isinstance(test_fraction, int | float) and 0.0 < test_fraction < 1.0):
        raise ValueError(f"test_fraction={test_fraction!r} is outside the allowed range (0, 1)")
    n = len(trips)
    groups = _groups(trips, group_column)
    if groups is not None and len(set(groups)) < 2:
        raise ValueError(f"group column {group_column!r} has {len(set(groups))} distinct "
                         "value(s); at least 2 are needed to hold whole groups out")
    if n < 2:
        raise ValueError(f"measured trips: {n} valid row(s); at least 2 are needed to hold "
                         "some out for testing")
    cls = GroupShuffleSplit if groups is not None else ShuffleSplit
    splitter = cls(n_splits=1, test_size=test_fraction, random_state=int(seed))
    _, test = next(splitter.split(np.zeros(n), groups=groups))
    mask = np.zeros(n, dtype=bool)
    mask[test] = True
    if mask.all() or not mask.any():
        raise ValueError(f"test_fraction={test_fraction!r} leaves no training or no test trips")
    return mask


def _conformal_fraction(level: float, n_train: int) -> float:
    need = math.ceil(level / (1.0 - level) - 1e-9)
    return float(min(0.5, max(0.15, need / max(n_train, 1))))


def holdout_evaluation(measured: MeasuredTrips, test: np.ndarray, *,
                       vehicle: VehicleParams | None = None, seed: int = 0, level: float = 0.9,
                       n_members: int = 5, physics_params: Sequence[str] = DEFAULT_PARAMS,
                       physics_missing_mode=None, model_params: dict | None = None,
                       calibrate_kwargs: dict | None = None, group_column: str | None = None,
                       stage: Callable[[str], None] | None = None) -> HoldoutResult:
    """Fit (b) and (c) on the training trips and predict the held-out ones.

    Parameters
    ----------
    measured : MeasuredTrips
    test : array_like of bool, shape (n_trips,)
        Held-out trips (e.g. from :func:`split_trips`).
    vehicle : VehicleParams, optional
        Nominal vehicle. Default: the one the trips were read for
        (``measured.vehicle``, from ``read_measured_trips(..., vehicle=...)``),
        else the paper's. A ``vehicle`` that differs from the trips' warns.
    seed : int
        Seeds the MCMC, the network training and the predictive draws.
    level : float
        Main interval level, in (0, 1).
    n_members : int
        Ensemble size of the hybrid.
    physics_params : sequence of str
        Parameters calibrated in (b) (:func:`~hybridev.bayes.sampler.calibrate_physics`).
    physics_missing_mode : str or DrivingProfile, optional
        ``missing_mode`` of (b); default ``"infer"`` when some training trip
        has no mode, else ``"marginalize"``.
    model_params : dict, optional
        Overrides of the :class:`~hybridev.learning.model.HybridModel` parameters.
    calibrate_kwargs : dict, optional
        Extra arguments of ``calibrate_physics`` (e.g. ``n_walkers``).
    group_column : str, optional
        Counted per split in the result.
    stage : callable, optional
        Called with ``"calibrate"``, ``"train"``, ``"evaluate"`` when each is done.

    Returns
    -------
    HoldoutResult
    """
    from hybridev.learning.model import HybridModel

    if not 0.0 < level < 1.0:
        raise ValueError(f"level={level!r} is outside the allowed range (0, 1)")
    veh = vehicle or VehicleParams()
    test = np.asarray(test, dtype=bool)
    if test.shape != (len(measured.trips),) or test.all() or not test.any():
        raise ValueError("test must be a boolean mask over the trips with at least one "
                         "training and one test trip")
    train, held = measured.select(~test), measured.select(test)
    done = stage or (lambda _name: None)
    caught: list[str] = []
    mm = physics_missing_mode
    if mm is None:
        mm = "infer" if train.trips["mode"].isna().any() else "marginalize"
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        post = calibrate_physics(train, veh, params=tuple(physics_params), seed=int(seed),
                                 missing_mode=mm, **(calibrate_kwargs or {}))
        done("calibrate")
        params = {"n_members": int(n_members),
                  "conformal_fraction": _conformal_fraction(level, len(train.trips)),
                  "missing_mode": mm, "physics_params": tuple(physics_params)}
        params.update(model_params or {})
        model = HybridModel(veh, **params).fit(train, seed=int(seed))  # with its traces
        done("train")
        caught += [f"{w.category.__name__}: {w.message}" for w in rec]
    y = held.trips["energy_kwh"].to_numpy(float)

    # (a) nominal physics, (b) calibrated physics: logged traces where available
    nominal_mode = mm if not (isinstance(mm, str) and mm in ("infer", "marginalize")) \
        else ("marginalize" if held.traces is not None else UNKNOWN_MODE_PHYSICS)
    st = trip_stats(held.trips, veh, traces=held.traces, n_steps=post.trace_steps,
                    seed=post.trace_seed, missing_mode=nominal_mode)
    stats = post.stats_for(held.trips, held.traces)
    med = {k: v for k, v in post.median().items() if k != "noise_rel"}
    draws = post.predictive(stats, _PREDICTIVE_DRAWS, int(seed))
    levels = np.unique(np.round(np.r_[REPORT_LEVELS, level], 10))
    q = np.quantile(draws, np.r_[(1 - levels) / 2, (1 + levels) / 2], axis=0)
    cal_lo, cal_hi = q[:len(levels)], q[len(levels):]
    i_main = int(np.flatnonzero(np.isclose(levels, level))[0])

    # (c) hybrid (physics on the logged traces too); levels beyond its conformal calibration
    # trips give unbounded intervals
    cp = getattr(model, "conformal_", None)
    n = len(held.trips)
    h_lo, h_hi = np.full((len(levels), n), -np.inf), np.full((len(levels), n), np.inf)
    tabs = {}
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        for i, lv in enumerate(levels):
            if cp is None or np.isfinite(cp.quantile(float(lv))):
                tabs[i] = model.predict_interval(held.trips, float(lv), seed=int(seed),
                                                 timeseries=held.traces)
                h_lo[i], h_hi[i] = (tabs[i][c].to_numpy(float)
                                    for c in ("energy_kwh_lo", "energy_kwh_hi"))
        mix = (model.predict_distribution(held.trips, level=level, seed=int(seed),
                                          timeseries=held.traces).components()
               if i_main in tabs else None)
        caught += [f"{w.category.__name__}: {w.message}" for w in rec]
    hyb = tabs[min(tabs)]  # point prediction and confidence do not depend on the level
    keep = [c for c in ("trip_id", group_column, "distance_km", "avg_speed_kmh",
                        "temperature_c", "hour", "soc_initial", "mode", "parked_min")
            if c and c in held.trips.columns]
    pred = held.trips[keep].reset_index(drop=True).assign(
        max_speed_kmh=st.max_speed_kmh, energy_kwh=y,
        energy_kwh_nominal=energy_from_stats(st),
        energy_kwh_calibrated=energy_from_stats(stats, med),
        energy_kwh_calibrated_lo=cal_lo[i_main], energy_kwh_calibrated_hi=cal_hi[i_main],
        energy_kwh_calibrated_sd=draws.std(axis=0))
    pred["energy_kwh_hybrid_physics"] = hyb["energy_kwh_physics"].to_numpy(float)
    pred["energy_kwh_pred"] = hyb["energy_kwh_pred"].to_numpy(float)
    pred["energy_kwh_lo"], pred["energy_kwh_hi"] = h_lo[i_main], h_hi[i_main]
    for c in ("soc_final_pred", "soc_final_lo", "soc_final_hi"):
        pred[c] = tabs[i_main][c].to_numpy(float) if i_main in tabs else np.nan
    pred["confidence"] = hyb["confidence"].to_numpy(float)
    for c in ("confidence_rel", "in_domain", "domain_score"):
        if c in hyb:
            pred[c] = hyb[c].to_numpy()
    done("evaluate")
    n_tr_g = n_te_g = None
    if group_column and group_column in measured.trips.columns:
        g = _groups(measured.trips, group_column)
        n_tr_g, n_te_g = len(set(g[~test])), len(set(g[test]))
    cfg = {"seed": int(seed), "level": float(level),
           "physics_params": list(post.param_names),  # sampled (climate scales included)
           "physics_missing_mode": mm if isinstance(mm, str) else getattr(mm, "name", str(mm)),
           "nominal_missing_mode": nominal_mode if isinstance(nominal_mode, str)
           else getattr(nominal_mode, "name", str(nominal_mode)),
           "model_params": {k: v for k, v in model.get_params().items() if k != "vehicle"},
           "calibrate_kwargs": dict(calibrate_kwargs or {}),
           "predictive_draws": _PREDICTIVE_DRAWS, "group_column": group_column}
    return HoldoutResult(
        predictions=pred, levels=levels,
        intervals={"calibrated": (cal_lo, cal_hi), "hybrid": (h_lo, h_hi)},
        calibrated_draws=draws, hybrid_mixture=mix, posterior=post, model=model,
        level=float(level), n_train=int((~test).sum()), n_test=int(test.sum()),
        n_train_groups=n_tr_g, n_test_groups=n_te_g, logged_traces=held.traces is not None,
        warnings=list(dict.fromkeys(caught)), config=cfg)


def calibration_report(measured: MeasuredTrips | pd.DataFrame, *, out_dir: str | os.PathLike,
                       vehicle: VehicleParams | None = None, seed: int = 0, level: float = 0.9,
                       n_members: int = 5, test_fraction: float = 0.2,
                       group_column: str | None = "auto",
                       physics_params: Sequence[str] = DEFAULT_PARAMS,
                       physics_missing_mode=None, model_params: dict | None = None,
                       calibrate_kwargs: dict | None = None, quiet: bool = True,
                       source: str | None = None) -> dict:
    """Fit on measured trips, score on held-out trips and write the report to ``out_dir``.

    Writes ``report.html`` (self-contained: figures embedded as base64 PNG),
    ``summary.json``, ``predictions.csv`` (held-out trips), ``rejected.csv``
    and ``figures/*.png`` into ``out_dir``, atomically (replaced as a whole;
    a failed run leaves no output). ``out_dir`` is checked before the work: it
    must be new, empty or a report folder hybridev wrote (see
    :mod:`hybridev.core.outputs`); otherwise a ``ValueError`` names ``out_dir``.

    Parameters
    ----------
    measured : MeasuredTrips or pandas.DataFrame
        From :func:`hybridev.data.logs.read_measured_trips` (bad rows already
        collected in ``rejected``); a DataFrame is validated the same way.
    out_dir : path
    vehicle : VehicleParams, optional
        Nominal vehicle. Default: the one the trips were read for
        (``measured.vehicle``, from ``read_measured_trips(..., vehicle=...)``),
        else the paper's. A ``vehicle`` that differs from the trips' warns.
    seed : int
        Seeds the split, the MCMC, the training and the predictive draws.
    level : float
        Main interval level, in (0, 1).
    n_members : int
        Ensemble size of the hybrid.
    test_fraction : float in (0, 1)
        Share of groups (or trips) held out.
    group_column : str or None
        Column of whole groups to hold out (ignored when absent); ``"auto"``
        (default): ``date`` by calendar day, else ``session_group``, else the
        day of ``start_time``, else a random split (:func:`split_trips`).
    physics_params, physics_missing_mode, model_params, calibrate_kwargs
        See :func:`holdout_evaluation`.
    quiet : bool
        No stage progress bar (stderr) when True.
    source : str, optional
        Name of the input, shown in the report.

    Returns
    -------
    dict
        The summary written to ``summary.json`` (see :func:`score_holdout`
        for the metrics; plus data, split, parameters, diagnostics,
        rejected rows, flagged trips and settings).

    Examples
    --------
    >>> from hybridev import make_trips
    >>> from hybridev.bayes.sampler import simulate_measured
    >>> t = simulate_measured(make_trips(80, seed=0), noise_rel=0.03, seed=1)
    >>> s = calibration_report(t, out_dir="report")  # doctest: +SKIP
    >>> sorted(s["metrics"])  # doctest: +SKIP
    ['calibrated', 'hybrid', 'nominal']
    """
    from hybridev.apps.report.html import legacy_report
    from hybridev.core.outputs import check_output
    from hybridev.core.progress import progress_bar

    check_output(out_dir, option="out_dir", kind="dir", legacy=legacy_report)  # before the work
    if isinstance(measured, pd.DataFrame):
        measured = measured_from_frames(measured, None, vehicle)
    if not isinstance(measured, MeasuredTrips):
        raise ValueError("measured must be a MeasuredTrips (hybridev.data.logs.read_measured_trips) "
                         f"or a DataFrame; got {type(measured).__name__}")
    if len(measured.trips) == 0:
        raise ValueError("measured trips: no valid rows to fit on")
    read_for = getattr(measured, "vehicle", None)
    if vehicle is None:
        vehicle = read_for  # the car the trips were read (and checked) for
    elif read_for is not None and read_for != vehicle:
        warnings.warn(f"calibration_report: the measured trips were read for another vehicle "
                      f"(battery {read_for.battery_capacity_kwh:g} kWh, mass "
                      f"{read_for.mass_kg:g} kg) than vehicle= (battery "
                      f"{vehicle.battery_capacity_kwh:g} kWh, mass {vehicle.mass_kg:g} kg); "
                      "the report uses vehicle=", UserWarning, stacklevel=2)
    t0 = time.perf_counter()
    timing = {}
    with progress_bar(total=4, desc="calibration report", unit="stage", quiet=quiet) as bar:
        def stage(name: str) -> None:
            timing[name] = round(time.perf_counter() - t0, 2)
            bar.set_postfix_str(name)
            bar.update(1)

        if group_column == "auto":
            group_column = auto_group_column(measured.trips)
        test = split_trips(measured.trips, test_fraction, seed=seed, group_column=group_column)
        result = holdout_evaluation(
            measured, test, vehicle=vehicle, seed=seed, level=level, n_members=n_members,
            physics_params=physics_params, physics_missing_mode=physics_missing_mode,
            model_params=model_params, calibrate_kwargs=calibrate_kwargs,
            group_column=group_column, stage=stage)
        summary = score_holdout(result, measured.rejected)
        summary.update(data_notes(measured, result.posterior))  # data quality, outliers
        summary["data"]["source"] = source
        summary["config"]["test_fraction"] = float(test_fraction)
        summary["config"]["vehicle"] = dataclasses.asdict(vehicle or VehicleParams())
        summary["config"]["profiles"] = list(PROFILES)
        summary["timing_s"] = dict(timing)  # seconds since start at the end of each stage
        write_report(result, summary, measured.rejected, out_dir)
        stage("report")
    return summary
