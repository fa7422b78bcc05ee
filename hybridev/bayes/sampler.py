"""Bayesian calibration of the physics parameters from measured trip energies (emcee).

Model (not in the paper, which uses fixed nominal parameters; this is the
probabilistic layer of the project):

* parameters ``theta``: any of drag area ``C_dA``, rolling resistance
  ``C_r``, linear drag ``b``, drivetrain efficiency ``eta_d``, base auxiliary
  power ``P_b``, a regen scale ``s`` (multiplies every profile's regen
  efficiency) and an HVAC scale (multiplies the four HVAC band powers), plus
  the relative noise ``sigma_rel``; the default set is the first five without
  ``b``;
* priors (:class:`PhysicsPrior`) centred on the vehicle's nominal values;
* likelihood: the relative residual ``E_obs / E(theta) - 1`` is Student-t
  with scale ``sigma_rel`` and ``PhysicsPrior.noise_dof`` (4) degrees of
  freedom (normal with ``noise_dof=None``), relative because trip energies
  span two orders of magnitude; a prediction below a fifth of the measured
  energy (even <= 0) counts as that floor, so no trip zeroes the posterior
  and, with the heavy tails, no odd trip drags it
  (:mod:`hybridev.bayes.likelihood`). The trips the fit treats as outliers,
  and why, are in ``PhysicsPosterior.outliers_`` (:mod:`hybridev.bayes.outliers`);
* trips without a ``mode``: by default the likelihood is the equal-weight
  mixture over the three profiles (log-sum-exp over modes, each with its own
  trace, efficiency multiplier, regen efficiency and mode auxiliary power);
  ``missing_mode="infer"`` also samples the mixture weights (one set shared
  by all unlabelled trips, Dirichlet(1, 1, 1) prior), which matters for
  predicting new unlabelled trips: the equal-weight mixture mean is poor when
  the data say most trips are of one kind; ``missing_mode="normal"`` (or a
  custom :class:`DrivingProfile`) assigns one profile.

``E(theta)`` comes from sufficient statistics (:mod:`hybridev.physics.stats`),
so one log-posterior evaluation of 32 walkers on 1,000 trips is one small
matrix product. Sampling: :class:`emcee.EnsembleSampler` (vectorised),
walkers started from a Gaussian fitted at the maximum a posteriori point
(scipy optimiser plus a finite-difference Hessian); the sign split of the
statistics is rebuilt at that point first. By default the chain runs in
chunks until it is at least 50 integrated autocorrelation times long after
burn-in (3 tau discarded, thinned by tau/2) or ``max_steps`` is reached.
"""

from __future__ import annotations

import dataclasses
import time
import warnings

import emcee
import numpy as np
import pandas as pd

from hybridev.bayes.groups import AUTO_GROUP_COLUMNS, _group_codes, auto_group_labels, group_labels
from hybridev.bayes.heater import select_heater_kind
from hybridev.bayes.likelihood import PREDICTED_FLOOR_REL, _LogPosterior, _map_and_cov
from hybridev.bayes.outliers import attach_outliers
from hybridev.bayes.posterior import PhysicsPosterior, vehicle_with
from hybridev.bayes.priors import (
    CLIMATE_PARAMS,
    DEFAULT_PARAMS,
    REGEN_EFFICIENCY_MAX,
    PhysicsPrior,
)
from hybridev.core.checks import check_seed
from hybridev.data.logs import MeasuredTrips, measured_from_frames
from hybridev.data.measured import validate_measured_trips
from hybridev.data.parked import with_parked_minutes
from hybridev.physics.params import PROFILES, DrivingProfile, VehicleParams
from hybridev.physics.stats import STAT_PARAMS, energy_from_stats
from hybridev.physics.stats_build import trip_stats
from hybridev.physics.traces import LoggedTraces

__all__ = [
    "AUTO_GROUP_COLUMNS",
    "PhysicsPosterior",
    "auto_group_labels",
    "calibrate_physics",
    "group_labels",
    "simulate_measured",
    "warm_start_walkers",
]

def _moves():
    """Differential-evolution proposals (emcee's ``DEMove``).

    On these posteriors (strong C_dA-C_r-eta_d correlation) they mix about
    three times faster per step than emcee's default stretch move. emcee's
    ``DESnookerMove`` is deliberately not used: in emcee 3.1.6 it does not
    sample the target (on a 6-D standard normal its samples have sd 0.82, and
    0.96 in a 20 % mix with DEMove; ``tests/test_calibrate.py`` checks the
    moves used here).
    """
    return emcee.moves.DEMove()


def _check_traces(traces) -> None:
    if traces is not None and not isinstance(traces, LoggedTraces):
        raise ValueError("timeseries must be a LoggedTraces or a time-series DataFrame; got "
                         f"{type(traces).__name__}")


def _prepare(measured_trips, vehicle, timeseries) -> tuple[pd.DataFrame, LoggedTraces | None]:
    if isinstance(measured_trips, MeasuredTrips):
        traces = measured_trips.traces if timeseries is None else timeseries
        trips = measured_trips.trips
    else:
        traces = timeseries
        if isinstance(timeseries, pd.DataFrame):
            m = measured_from_frames(measured_trips, timeseries, vehicle)
            if m.n_rejected:
                raise ValueError(f"{m.n_rejected} measured trip(s) or trace(s) were rejected; "
                                 f"first: {m.rejected['reason'].iloc[0]} (inspect them with "
                                 "hybridev.data.logs.read_measured_trips)")
            trips, traces = m.trips, m.traces
        else:
            _check_traces(traces)  # before their durations end the trips (parked_min)
            trips, _ = validate_measured_trips(with_parked_minutes(measured_trips, traces),
                                               vehicle)
    _check_traces(traces)
    return trips, traces


def calibrate_physics(measured_trips, vehicle: VehicleParams | None = None, *,
                      params: tuple[str, ...] = DEFAULT_PARAMS, n_walkers: int = 32,
                      n_steps: int | None = None, seed: int = 0, timeseries=None,
                      progress: bool = False, prior: PhysicsPrior | None = None,
                      missing_mode: str | DrivingProfile = "marginalize",
                      max_steps: int = 20000, trace_steps: int = 1000, trace_seed: int = 0,
                      refine_sign: bool = True, groups="auto",
                      climate_params: bool | None = None,
                      sign_vehicle: VehicleParams | None = None,
                      init_walkers: np.ndarray | None = None) -> PhysicsPosterior:
    """Sample the posterior of physics parameters given measured trip energies.

    Parameters
    ----------
    measured_trips : pandas.DataFrame or MeasuredTrips
        Measured-trip table (``energy_kwh`` and/or ``soc_final``; ``mode`` may
        be missing) or the result of :func:`hybridev.data.logs.read_measured_trips`.
    vehicle : VehicleParams, optional
        Nominal vehicle: prior centres and all parameters not sampled. Default:
        the vehicle a ``MeasuredTrips`` was read for, else the paper's (a
        different explicit one warns). A
        ``heater_kind="auto"`` (the default of ``from_coastdown``) is first
        resolved from the trips (:func:`hybridev.bayes.heater.select_heater_kind`;
        the outcome is in ``diagnostics["heater"]``) and the posterior's
        ``vehicle`` carries the chosen kind.
    params : tuple of str
        Sampled parameters, a subset of
        :data:`hybridev.physics.stats.STAT_PARAMS`.
    n_walkers : int
        Walkers, >= 2 * (len(params) + 1).
    n_steps : int, optional
        Run exactly this many steps; default: adaptive (at least 50 tau after
        burn-in, at most ``max_steps``).
    seed : int
        Seeds the walker start and the sampler; same seed, same chain.
    timeseries : LoggedTraces or pandas.DataFrame, optional
        Logged traces (by ``trip_id``); trips without one use synthesised traces.
    progress : bool
        Show emcee's progress bar.
    prior : PhysicsPrior, optional
    missing_mode : "marginalize", "infer", mode name or DrivingProfile
        Treatment of trips without ``mode`` (see module docstring):
        equal-weight mixture over the three profiles, a mixture whose weights
        are sampled too (Dirichlet(1, 1, 1) prior; they appear in the
        summary as ``weight_<mode>``), or one assigned profile.
    max_steps, trace_steps, trace_seed : int
        Step cap of the adaptive run; synthesis settings (as ``simulate``'s
        ``n_steps`` and ``seed``) for trips without a logged trace.
    refine_sign : bool
        Rebuild the statistics' sign split at the MAP before sampling.
    climate_params : bool, optional
        Also sample :data:`~hybridev.bayes.priors.CLIMATE_PARAMS` (climate
        power and warm-up scales, and the heating onset ``heating_offset_k``,
        which the paper's band model does not have) when not in ``params``. Default: yes for a
        vehicle with the continuous climate model (its climate load is the
        least known part of a new car), no for the paper's band model.
    sign_vehicle : VehicleParams, optional
        Split the wheel power by sign at this vehicle's road load instead
        (no refinement): posteriors sampled with the same ``sign_vehicle``
        share their statistics (the CV+ folds of :class:`hybridev.HybridModel`
        use the full posterior's ``reference_vehicle``).
    init_walkers : numpy.ndarray, shape (n_walkers, n_dim), optional
        Start the walkers here (rows of another posterior's ``sampler_draws_``
        with the same parameters, e.g. the full posterior for a CV+ fold's
        trips) instead of around the MAP, which is then not searched: a warm
        start (:func:`warm_start_walkers`). The first half of the run is discarded
        whatever the run's own autocorrelation estimate says (too short a run
        underestimates it): the walkers must first forget the other posterior's
        trips, so the run should span several of *that* posterior's
        autocorrelation times (:mod:`hybridev.learning.cvplus`).
    groups : "auto", str, array_like (n_trips,) or None
        Trips that share a day or session share part of their error (same
        weather, traffic, driver, tyre pressure). With groups the likelihood
        gets a group random effect ``u_g ~ N(0, tau^2)`` on the relative
        residual (``tau`` sampled, half-normal prior), so that correlated
        trips do not overstate certainty; ``noise_rel`` of the posterior is
        then the total sd ``sqrt(sigma^2 + tau^2)`` of a trip on a new day.
        ``"auto"`` (default): the ``date`` column if the table has one, else
        ``session_group``, else none; a column name; one label per trip;
        ``None``: independent trips. Missing labels form their own groups.
        Trips whose mode is marginalised (no label, no logged trace) cannot
        share a group effect: ``"auto"`` then falls back to independent trips
        and explicit groups raise a ``ValueError``.

    Returns
    -------
    PhysicsPosterior
        Its ``sampler_draws_`` (not saved with a model) holds the thinned chain in the
        sampler's coordinates, ``(n_draws, n_dim)``: the start of a warm run.

    Warns
    -----
    ConvergenceWarning
        When the chain is shorter than 50 autocorrelation times.

    Examples
    --------
    >>> from hybridev import make_trips
    >>> from hybridev.bayes.sampler import simulate_measured
    >>> m = simulate_measured(make_trips(60, seed=0), noise_rel=0.03, seed=1)
    >>> post = calibrate_physics(m, params=("aux_base_kw",), n_walkers=8)
    >>> post.samples.shape[1], bool(post.summary().loc["aux_base_kw", "q05"] < 0.5)
    (1, True)
    """
    seed = check_seed(seed)
    read_for = measured_trips.vehicle if isinstance(measured_trips, MeasuredTrips) else None
    if vehicle is None:
        vehicle = read_for  # the car the trips were read for (read_measured_trips(vehicle=))
    elif read_for is not None and read_for != vehicle:
        warnings.warn(f"the measured trips were read for another vehicle (battery "
                      f"{read_for.battery_capacity_kwh:g} kWh, mass {read_for.mass_kg:g} kg) "
                      f"than the vehicle= given here (battery {vehicle.battery_capacity_kwh:g} "
                      f"kWh, mass {vehicle.mass_kg:g} kg); the given one is calibrated",
                      UserWarning, stacklevel=2)
    veh = vehicle or VehicleParams()
    pr = prior or PhysicsPrior()
    names = tuple(params)
    if climate_params is None:
        climate_params = veh.climate_model == "continuous"
    if climate_params:
        names += tuple(n for n in CLIMATE_PARAMS if n not in names and (
            n != "heating_offset_k" or veh.climate_model == "continuous"))  # no onset in bands
    if len(set(names)) != len(names) or not names:
        raise ValueError(f"params={params!r} must be distinct names from {list(STAT_PARAMS)}")
    for n in names:
        if n not in STAT_PARAMS:
            raise ValueError(f"params has unknown parameter {n!r}; allowed: {list(STAT_PARAMS)}")
    infer = want_infer = isinstance(missing_mode, str) and missing_mode == "infer"
    n_alr = 2 if infer else 0
    ndim = len(names) + n_alr + 2  # + group sd (if any) + noise; checked again below
    if n_walkers < 2 * (ndim - 1):
        raise ValueError(f"n_walkers={n_walkers!r} is outside the allowed range "
                         f"[{2 * (ndim - 1)}, inf) for {ndim - 1} sampled dimension(s)")
    if n_steps is not None and int(n_steps) < 1:
        raise ValueError(f"n_steps={n_steps!r} is outside the allowed range [1, inf)")
    trips, traces = _prepare(measured_trips, veh, timeseries)
    codes = _group_codes(trips, groups)
    y = trips["energy_kwh"].to_numpy(float)
    if np.any(y <= 0):
        raise ValueError(f"energy_kwh={y[y <= 0][0]!r}: the relative-noise likelihood needs "
                         "measured energies > 0")
    t0 = time.perf_counter()

    def build(v):
        return trip_stats(trips, v, traces=traces, n_steps=trace_steps, seed=trace_seed,
                          missing_mode="marginalize" if want_infer else missing_mode)

    heater = None
    if veh.heater_kind == "auto" and veh.climate_model == "continuous":
        heater = select_heater_kind(build, veh, y, groups=codes, prior=pr)  # bayes.heater
        veh = dataclasses.replace(veh, heater_kind=heater.kind)
    if sign_vehicle is not None and sign_vehicle.heater_kind != veh.heater_kind:
        sign_vehicle = dataclasses.replace(sign_vehicle, heater_kind=veh.heater_kind)
    stats = build(veh if sign_vehicle is None else sign_vehicle)
    unlabelled = ("mode" not in trips.columns
                  or bool((trips["mode"].isna() | (trips["mode"].astype(str) == "")).any()))
    if infer and unlabelled and not stats.marginalised:
        infer, n_alr = False, 0  # every unlabelled trip has a logged trace: nothing to infer
    if codes is not None and stats.marginalised:
        # A trip whose mode is a mixture has no single energy for the shared day effect.
        if isinstance(groups, str) and groups == "auto":
            codes = None
        else:
            raise ValueError("groups need trips with a known mode or a logged trace; some "
                             "trips are a mixture over modes (missing_mode="
                             f"{missing_mode!r}): label them or pass groups=None")
    n_group = 0 if codes is None else 1
    ndim = len(names) + n_alr + n_group + 1
    if n_walkers < 2 * ndim:
        raise ValueError(f"n_walkers={n_walkers!r} is outside the allowed range "
                         f"[{2 * ndim}, inf) for {ndim} sampled dimension(s)")
    nominal = PhysicsPosterior.nominal_values(veh)
    cd = veh.road_load_source == "coastdown"
    specs = [pr.spec(n, nominal[n], REGEN_EFFICIENCY_MAX, coastdown=cd) for n in names]
    fixed = {n: nominal[n] for n in STAT_PARAMS if n not in names}
    scale = np.array([max(np.atleast_1d(s[2])) * (np.exp(s[1]) if s[0] == "lognormal" else 1.0)
                      for s in specs]
                     + [1.0] * n_alr + [pr.group_sd_scale] * n_group + [1.0])
    x0 = np.r_[[nominal[n] for n in names], np.zeros(n_alr), [0.5 * pr.group_sd_scale] * n_group]
    logpost = _LogPosterior(stats, y, names, specs, pr, fixed, infer, codes)
    with np.errstate(all="ignore"):  # robust start: median absolute relative residual
        e0 = np.maximum(energy_from_stats(stats), PREDICTED_FLOOR_REL * y)
        s0 = float(1.4826 * np.median(np.abs(y / e0 - 1.0)))
    s0 = np.clip(s0 if np.isfinite(s0) else 0.1,
                 *(np.array(pr.noise_rel_bounds) * [1.01, 0.99]))
    start = np.r_[x0, np.log(s0)]
    if init_walkers is not None and np.shape(init_walkers) == (n_walkers, ndim):
        return _warm_run(init_walkers, logpost, n_walkers, ndim, n_steps, seed, progress,
                         post_kw=dict(names=names, vehicle=veh,
                                      reference_vehicle=veh if sign_vehicle is None
                                      else sign_vehicle, prior=pr,
                                      missing_mode="marginalize" if want_infer and not infer
                                      else missing_mode,
                                      trace_steps=trace_steps, trace_seed=trace_seed,
                                      n_group=n_group, noise_dof=pr.noise_dof),
                         t0=t0, finish=lambda post: attach_outliers(
                             post, stats, trips, y, codes if n_group else None, pr.noise_dof))
    theta, cov = _map_and_cov(logpost, start, scale)
    ref = veh if sign_vehicle is None else sign_vehicle
    if sign_vehicle is None and refine_sign and {"drag_area_m2", "rolling_resistance_coef",
                        "linear_drag_n_per_mps"} & set(names):
        sign = ("drag_area_m2", "rolling_resistance_coef", "linear_drag_n_per_mps")
        try:
            ref = vehicle_with(veh, {n: x for n, x in zip(names, theta[:len(names)],
                                                          strict=True) if n in sign})
        except ValueError:  # MAP outside VehicleParams' ranges: keep the nominal split
            ref = veh
        if ref is not veh:
            stats = build(ref)
            logpost = _LogPosterior(stats, y, names, specs, pr, fixed, infer, codes)
            theta, cov = _map_and_cov(logpost, theta, scale)
    if not np.isfinite(logpost(theta[None, :])[0]):  # the floored likelihood is finite
        raise RuntimeError("the log posterior is not finite at its maximum (internal error: "
                           "every measured trip has a finite likelihood); please report it")
    rng = np.random.default_rng(seed)
    if cov is None:
        cov = np.diag((1e-3 * scale) ** 2)
    p0 = rng.multivariate_normal(theta, cov, size=n_walkers)
    for _ in range(50):
        bad = ~np.isfinite(logpost(p0))
        if not bad.any():
            break
        p0[bad] = rng.multivariate_normal(theta, cov * 0.25, size=int(bad.sum()))
    else:
        p0[bad] = theta + 1e-6 * scale * rng.standard_normal((int(bad.sum()), ndim))
    sampler = emcee.EnsembleSampler(n_walkers, ndim, logpost, vectorize=True, moves=_moves())
    legacy_seed = seed if seed < 2**32 else int(np.random.SeedSequence(seed).generate_state(1)[0])
    sampler.random_state = np.random.RandomState(legacy_seed).get_state()  # 32-bit seeds only
    state = p0
    if n_steps is not None:
        sampler.run_mcmc(state, int(n_steps), progress=progress)
    else:
        chunk, done = 1000, 0
        while True:
            state = sampler.run_mcmc(state, chunk, progress=progress)
            done += chunk
            tau = float(np.max(sampler.get_autocorr_time(tol=0)))
            need = int(np.ceil(55 * tau))
            if done >= need or done >= max_steps:
                break
            chunk = int(min(max(need - done, 200), max_steps - done))
    mm_out = ("marginalize" if isinstance(missing_mode, str) and missing_mode == "infer"
              and not infer else missing_mode)
    post = PhysicsPosterior.from_sampler(
        sampler, names, vehicle=veh, reference_vehicle=ref, prior=pr, map_theta=theta,
        missing_mode=mm_out, trace_steps=trace_steps, trace_seed=trace_seed,
        elapsed_s=time.perf_counter() - t0, n_group=n_group, noise_dof=pr.noise_dof)
    post.sampler_draws_ = _thinned_chain(sampler, post)
    post.diagnostics["warm_start"] = False
    if heater is not None:
        post.diagnostics["heater"] = heater.to_dict()
    attach_outliers(post, stats, trips, y, codes if n_group else None, pr.noise_dof)
    return post


def _thinned_chain(sampler, post: PhysicsPosterior) -> np.ndarray:
    """The chain behind ``post`` in the sampler's coordinates (same burn-in and thinning)."""
    d = post.diagnostics
    return sampler.get_chain(discard=d["burn_in"], thin=d["thin"], flat=True)


def warm_start_walkers(draws: np.ndarray, n_walkers: int, seed: int) -> np.ndarray:
    """``n_walkers`` distinct rows of ``draws`` (a posterior's ``sampler_draws_``), seeded.

    Fewer rows than walkers: rows are repeated with a jitter of 1e-3 of each
    coordinate's spread, so that the ensemble is not degenerate.
    """
    draws = np.asarray(draws, dtype=float)
    rng = np.random.default_rng(seed)
    if len(draws) >= n_walkers:
        return draws[np.sort(rng.choice(len(draws), n_walkers, replace=False))]
    p0 = draws[rng.integers(0, len(draws), n_walkers)]
    sd = np.maximum(draws.std(axis=0), 1e-9)
    return p0 + 1e-3 * sd * rng.standard_normal(p0.shape)


def _warm_run(p0, logpost, n_walkers: int, ndim: int, n_steps, seed: int, progress: bool,
              *, post_kw: dict, t0: float, finish) -> PhysicsPosterior:
    """A fixed-length emcee run from ``p0`` (no MAP search): :func:`calibrate_physics`
    with ``init_walkers``."""
    p0 = np.array(p0, dtype=float)
    if n_steps is None:
        raise ValueError("init_walkers needs n_steps (a warm run has a fixed length)")
    if not np.all(np.isfinite(logpost(p0))):
        raise ValueError("init_walkers has rows outside the prior's support")
    sampler = emcee.EnsembleSampler(n_walkers, ndim, logpost, vectorize=True, moves=_moves())
    legacy_seed = seed if seed < 2**32 else int(np.random.SeedSequence(seed).generate_state(1)[0])
    sampler.random_state = np.random.RandomState(legacy_seed).get_state()
    sampler.run_mcmc(p0, int(n_steps), progress=progress)
    # burn half the run: a short run's own autocorrelation time underestimates how long
    # the walkers remember their start (the other posterior's draws)
    post = PhysicsPosterior.from_sampler(sampler, map_theta=np.median(p0, axis=0),
                                         elapsed_s=time.perf_counter() - t0,
                                         min_burn=int(n_steps) // 2, **post_kw)
    post.diagnostics["warm_start"] = True
    post.sampler_draws_ = _thinned_chain(sampler, post)
    finish(post)
    return post


def simulate_measured(trips: pd.DataFrame, vehicle: VehicleParams | None = None,
                      true_params: dict[str, float] | None = None, noise_rel: float = 0.05,
                      seed: int = 0, *, n_steps: int = 1000, trace_seed: int = 0,
                      hide_mode: bool = False) -> pd.DataFrame:
    """Measured trips generated by the exact physics with known parameters plus noise.

    ``energy_kwh = E_true (1 + noise_rel z)``, ``z ~ N(0, 1)``, where
    ``E_true`` is :func:`hybridev.trace_energy_kwh` on the same synthesised
    traces as :func:`hybridev.simulate` for the vehicle with ``true_params``
    applied (``regen_scale`` multiplies each profile's regen efficiency). For
    coverage studies: loop over seeds, calibrate, check the intervals.

    Parameters
    ----------
    trips : pandas.DataFrame
        Trip table (with modes).
    vehicle : VehicleParams, optional
    true_params : dict, optional
        Values of :data:`hybridev.physics.stats.STAT_PARAMS`; default nominal.
    noise_rel : float
        Relative noise sd, [0, 0.2].
    seed : int
        Noise seed.
    n_steps, trace_seed : int
        Trace synthesis settings.
    hide_mode : bool
        Set ``mode`` to ``None`` (unlabelled trips).

    Returns
    -------
    pandas.DataFrame
        ``trips`` plus ``energy_kwh`` and ``energy_kwh_true``.

    Examples
    --------
    >>> from hybridev import make_trips
    >>> m = simulate_measured(make_trips(3, seed=0), noise_rel=0.0)
    >>> bool((m.energy_kwh == m.energy_kwh_true).all())
    True
    """
    if not (np.isfinite(noise_rel) and 0.0 <= noise_rel <= 0.2):
        raise ValueError(f"noise_rel={noise_rel!r} is outside the allowed range [0, 0.2]")
    from hybridev.physics.forces import trace_power_kw
    from hybridev.physics.trips import _blocks
    from hybridev.physics.validation import validate_trips
    t = validate_trips(trips)
    check_seed(seed)
    tp = dict(true_params or {})
    veh = vehicle_with(vehicle or VehicleParams(), tp)
    s = float(tp.get("regen_scale", 1.0))
    scaled = {k: dataclasses.replace(p, regen_efficiency=p.regen_efficiency * s)
              for k, p in PROFILES.items()}
    profiles = t["mode"].map(scaled).to_numpy(object)
    temp = t["temperature_c"].to_numpy(float)
    energy = np.empty(len(t))
    for sl, v, dt, grade in _blocks(t, n_steps, trace_seed):
        p = trace_power_kw(v, dt, vehicle=veh, profile=list(profiles[sl]),
                           temperature_c=temp[sl], grade_rad=grade)
        energy[sl] = p.sum(axis=1) * dt / 3600.0
    z = np.random.default_rng(seed).standard_normal(len(t))
    out = t.assign(energy_kwh=energy * (1.0 + noise_rel * z), energy_kwh_true=energy)
    if hide_mode:
        out["mode"] = None
    return out

