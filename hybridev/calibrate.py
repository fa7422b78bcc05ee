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
* likelihood: ``E_obs ~ N(E(theta), (sigma_rel E(theta))^2)`` per trip,
  relative because trip energies span two orders of magnitude; ``E(theta) <= 0``
  has zero likelihood;
* trips without a ``mode``: by default the likelihood is the equal-weight
  mixture over the three profiles (log-sum-exp over modes, each with its own
  trace, efficiency multiplier, regen efficiency and mode auxiliary power);
  ``missing_mode="infer"`` also samples the mixture weights (one set shared
  by all unlabelled trips, Dirichlet(1, 1, 1) prior), which matters for
  predicting new unlabelled trips: the equal-weight mixture mean is poor when
  the data say most trips are of one kind; ``missing_mode="normal"`` (or a
  custom :class:`DrivingProfile`) assigns one profile.

``E(theta)`` comes from sufficient statistics (:mod:`hybridev.physics_stats`),
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
from dataclasses import dataclass, field

import emcee
import numpy as np
import pandas as pd
from scipy.optimize import minimize

from .logs import LoggedTraces, MeasuredTrips, measured_from_frames
from .measured import validate_measured_trips
from .params import PROFILES, DrivingProfile, VehicleParams
from .physics_posterior import PhysicsPosterior, vehicle_with
from .physics_stats import STAT_PARAMS, PhysicsStats, energy_from_stats, trip_stats

__all__ = ["DEFAULT_PARAMS", "ConvergenceWarning", "PhysicsPosterior", "PhysicsPrior",
           "calibrate_physics", "simulate_measured"]

DEFAULT_PARAMS = ("drag_area_m2", "rolling_resistance_coef", "drivetrain_efficiency",
                  "aux_base_kw", "regen_scale")


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


class ConvergenceWarning(UserWarning):
    """The MCMC chain is shorter than 50 autocorrelation times."""


@dataclass(frozen=True)
class PhysicsPrior:
    """Prior of the calibrated physics parameters, centred on the nominal vehicle.

    Widths are the project's choice (stated here; change them with
    :func:`dataclasses.replace`): coast-down and data-sheet values of
    ``C_dA`` and ``C_r`` are rarely more than 20-30 % off for a real car
    (tyres, load, wind), efficiency is known to a few points, auxiliary
    load only to a factor of ~1.6.

    Parameters
    ----------
    drag_area_log_sd : float
        ``log C_dA ~ N(log nominal, sd)``: lognormal, 0.25 ~ 25 %.
    rolling_resistance_log_sd : float
        Same for ``C_r``.
    linear_drag_sd_n_per_mps : float, N/(m/s)
        ``b ~ N(nominal, sd)`` truncated to ``b >= 0``.
    efficiency_sd : float
        ``eta_d ~ N(nominal, sd)`` truncated to ``efficiency_bounds`` (open).
    efficiency_bounds : tuple of 2 float
    aux_log_sd : float
        ``log P_b ~ N(log nominal, sd)``; needs a nominal ``P_b > 0``.
    hvac_log_sd : float
        ``log hvac_scale ~ N(0, sd)``; the scale multiplies all four HVAC bands.
    regen_scale_sd : float
        ``s ~ N(1, sd)`` truncated to ``(0, 1 / max eta_r)`` so that no
        profile regenerates more than the braking energy.
    noise_rel_bounds : tuple of 2 float
        ``sigma_rel`` log-uniform on this range (scale-free).

    Examples
    --------
    >>> import dataclasses
    >>> wide = dataclasses.replace(PhysicsPrior(), drag_area_log_sd=0.5)
    >>> wide.drag_area_log_sd
    0.5
    """

    drag_area_log_sd: float = 0.25
    rolling_resistance_log_sd: float = 0.25
    linear_drag_sd_n_per_mps: float = 2.0
    efficiency_sd: float = 0.05
    efficiency_bounds: tuple[float, float] = (0.5, 1.0)
    aux_log_sd: float = 0.5
    hvac_log_sd: float = 0.5
    regen_scale_sd: float = 0.2
    noise_rel_bounds: tuple[float, float] = (1e-3, 0.5)
    source: str = field(default="hybridev defaults (see class docstring)", compare=False)

    def __post_init__(self) -> None:
        for name in ("drag_area_log_sd", "rolling_resistance_log_sd", "linear_drag_sd_n_per_mps",
                     "efficiency_sd", "aux_log_sd", "hvac_log_sd", "regen_scale_sd"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ValueError(f"PhysicsPrior.{name}={v!r} is outside the allowed range "
                                 "(0, inf)")
        lo, hi = (float(x) for x in self.efficiency_bounds)
        if not 0.0 <= lo < hi <= 1.0:
            raise ValueError(f"PhysicsPrior.efficiency_bounds={self.efficiency_bounds!r} must "
                             "satisfy 0 <= lo < hi <= 1")
        nlo, nhi = (float(x) for x in self.noise_rel_bounds)
        if not 0.0 < nlo < nhi <= 10.0:
            raise ValueError(f"PhysicsPrior.noise_rel_bounds={self.noise_rel_bounds!r} must "
                             "satisfy 0 < lo < hi <= 10")
        object.__setattr__(self, "efficiency_bounds", (lo, hi))
        object.__setattr__(self, "noise_rel_bounds", (nlo, nhi))

    def spec(self, name: str, nominal: float, eta_r_max: float) -> tuple:
        """``(kind, centre, sd, lo, hi)`` of one parameter's prior (natural units)."""
        if name in ("drag_area_m2", "rolling_resistance_coef", "aux_base_kw"):
            sd = {"drag_area_m2": self.drag_area_log_sd,
                  "rolling_resistance_coef": self.rolling_resistance_log_sd,
                  "aux_base_kw": self.aux_log_sd}[name]
            if not nominal > 0:
                raise ValueError(f"{name}={nominal!r}: a lognormal prior needs a nominal value "
                                 "> 0; set it on the vehicle or leave the parameter out")
            return "lognormal", float(np.log(nominal)), sd, 0.0, np.inf
        if name == "hvac_scale":
            return "lognormal", 0.0, self.hvac_log_sd, 0.0, np.inf
        if name == "linear_drag_n_per_mps":
            return "normal", nominal, self.linear_drag_sd_n_per_mps, 0.0, np.inf
        if name == "drivetrain_efficiency":
            lo, hi = self.efficiency_bounds
            if not lo < nominal < hi:
                raise ValueError(f"drivetrain_efficiency={nominal!r} is outside the prior "
                                 f"support ({lo}, {hi})")
            return "normal", nominal, self.efficiency_sd, lo, hi
        if name == "regen_scale":
            return "normal", 1.0, self.regen_scale_sd, 0.0, 1.0 / eta_r_max
        raise ValueError(f"params has unknown parameter {name!r}; allowed: {list(STAT_PARAMS)}")


class _LogPosterior:
    """Vectorised log posterior over ``theta = (params..., [mode logits,] log sigma_rel)``.

    With ``infer_modes`` the mixture weights of unlabelled trips are
    ``pi = softmax(0, a_normal, a_aggressive)`` (eco first, as in PROFILES) with a
    Dirichlet(1, 1, 1) prior on ``pi``, i.e. ``log p(a) = sum(log pi)`` in these
    coordinates; ``|a| < 20``.
    """

    def __init__(self, stats: PhysicsStats, energy_kwh: np.ndarray, names, specs, prior,
                 fixed: dict[str, float], infer_modes: bool = False):
        self.names = list(names)
        self.n_alr = 2 if infer_modes else 0
        self.F = stats.features()
        self.y = energy_kwh[stats.trip]
        self.log_w = stats.log_weight
        self.n_trips = stats.n_trips
        specs = list(specs) + [("alr", 0.0, np.inf, -20.0, 20.0)] * self.n_alr
        self.kind_log = np.array([s[0] == "lognormal" for s in specs])
        self.centre = np.array([s[1] for s in specs], dtype=float)
        self.sd = np.array([s[2] for s in specs], dtype=float)
        self.lo = np.array([s[3] for s in specs], dtype=float)
        self.hi = np.array([s[4] for s in specs], dtype=float)
        self.log_noise = np.log(prior.noise_rel_bounds)
        self.fixed = fixed
        self.shape = None
        if stats.marginalised:
            # Padded layout (max_alt, n_trips): padding columns have zero features,
            # hence zero energy and zero likelihood, and weight -inf.
            starts = np.flatnonzero(np.r_[True, stats.trip[1:] != stats.trip[:-1]])
            counts = np.diff(np.r_[starts, stats.n_rows])
            k = np.arange(counts.max())
            live = k[:, None] < counts[None, :]
            idx = np.where(live, starts[None, :] + k[:, None], 0).ravel()
            self.F = np.where(live.ravel(), self.F[:, idx], 0.0)
            self.y = np.where(live.ravel(), self.y[idx], 1.0)
            self.log_w = np.where(live.ravel(), 0.0 if infer_modes else self.log_w[idx], -np.inf)
            self.shape = live.shape
            self.unknown = (counts > 1).astype(float)
        if infer_modes and (self.shape is None or self.shape[0] != 3):
            raise ValueError("missing_mode='infer' needs at least one trip without a mode "
                             "(its weights are learned from unlabelled trips)")

    def values(self, theta: np.ndarray) -> dict[str, np.ndarray]:
        out = {n: np.full(len(theta), v) for n, v in self.fixed.items()}
        out.update({n: theta[:, i] for i, n in enumerate(self.names)})
        return out

    def log_prior(self, theta: np.ndarray) -> np.ndarray:
        x = theta[:, :-1]
        inside = (x > self.lo) & (x < self.hi)
        lx = np.log(np.where(self.kind_log & inside, x, 1.0))
        z = (np.where(self.kind_log, lx, x) - self.centre) / self.sd
        lp = (-0.5 * z * z - np.where(self.kind_log, lx, 0.0)).sum(axis=1)
        if self.n_alr:
            lp = lp + self.log_pi(theta).sum(axis=1)  # Dirichlet(1, 1, 1) in alr coordinates
        ls = theta[:, -1]
        ok = inside.all(axis=1) & (ls > self.log_noise[0]) & (ls < self.log_noise[1])
        return np.where(ok, lp, -np.inf)

    def log_pi(self, theta: np.ndarray) -> np.ndarray:
        """Log mixture weights (n, 3) from the two logits."""
        n = len(self.names)
        logits = np.column_stack([np.zeros(len(theta)), theta[:, n:n + 2]])
        mx = logits.max(axis=1, keepdims=True)
        return logits - mx - np.log(np.exp(logits - mx).sum(axis=1, keepdims=True))

    def log_lik(self, theta: np.ndarray) -> np.ndarray:
        v = self.values(theta)
        inv = 1.0 / v["drivetrain_efficiency"]
        s = v["regen_scale"]
        cr, cda, b = v["rolling_resistance_coef"], v["drag_area_m2"], v["linear_drag_n_per_mps"]
        coef = np.stack([cr * inv, cda * inv, b * inv, inv, s * cr, s * cda, s * b, s,
                         v["aux_base_kw"], v["hvac_scale"], np.ones(len(theta))], axis=1)
        e = coef @ self.F
        log_sig = theta[:, -1]
        # log N(y | e, (sigma e)^2) = -(y/e - 1)^2 / (2 sigma^2) - log e - log sigma - log(2 pi)/2,
        # in place (hot path); e <= 0 has zero likelihood.
        ll = np.divide(self.y, e)
        ll -= 1.0
        ll *= ll
        ll *= (-0.5 * np.exp(-2.0 * log_sig))[:, None]
        ll -= np.log(e)
        bad = ~(e > 0)
        if bad.any():
            ll[bad] = -np.inf
        const = self.n_trips * (-log_sig - 0.5 * np.log(2 * np.pi))
        if self.shape is None:
            return ll.sum(axis=1) + const
        ll += self.log_w
        ll = ll.reshape(len(theta), *self.shape)
        if self.n_alr:
            ll += self.log_pi(theta)[:, :, None] * self.unknown
        m = ll.max(axis=1)
        m[~np.isfinite(m)] = 0.0
        ll -= m[:, None, :]
        np.exp(ll, out=ll)
        return (np.log(ll.sum(axis=1)) + m).sum(axis=1) + const

    def __call__(self, theta) -> np.ndarray:
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        out = np.full(len(theta), -np.inf)
        with np.errstate(all="ignore"):
            lp = self.log_prior(theta)
            ok = np.isfinite(lp) & np.isfinite(theta).all(axis=1)
            if ok.any():
                out[ok] = lp[ok] + self.log_lik(theta[ok])
        out[~np.isfinite(out)] = -np.inf
        return out


def _map_and_cov(logpost: _LogPosterior, start: np.ndarray, scale: np.ndarray):
    """MAP by L-BFGS-B in scaled coordinates, then a finite-difference Gaussian."""
    lo = np.r_[logpost.lo, logpost.log_noise[0]]
    hi = np.r_[logpost.hi, logpost.log_noise[1]]
    margin = 1e-6 * (np.minimum(hi, start + 50 * scale) - np.maximum(lo, start - 50 * scale))
    bounds = [((a + m - s0) / sc if np.isfinite(a) else None,
               (b - m - s0) / sc if np.isfinite(b) else None)
              for a, b, m, s0, sc in zip(lo, hi, margin, start, scale, strict=True)]

    def f(z):
        v = logpost((start + z * scale)[None, :])[0]
        return -v if np.isfinite(v) else 1e12

    res = minimize(f, np.zeros(len(start)), method="L-BFGS-B", bounds=bounds)
    theta = start + res.x * scale
    steps = scale * 1e-3
    cov = None
    for _ in range(2):  # second pass: steps of 0.1 posterior sd
        with np.errstate(all="ignore"):
            h = _hessian(logpost, theta, steps)
        if not np.all(np.isfinite(h)):
            break
        try:
            c = np.linalg.inv(-h)
            if not np.all(np.linalg.eigvalsh(0.5 * (c + c.T)) > 0):
                break
        except np.linalg.LinAlgError:
            break
        cov = 0.5 * (c + c.T)
        steps = 0.1 * np.sqrt(np.diag(cov))
    return theta, cov


def _hessian(logpost, theta: np.ndarray, h: np.ndarray) -> np.ndarray:
    p = len(theta)
    eye = np.eye(p) * h
    pts = [theta]
    pts += [theta + eye[i] for i in range(p)] + [theta - eye[i] for i in range(p)]
    pairs = [(i, j) for i in range(p) for j in range(i + 1, p)]
    for i, j in pairs:
        pts += [theta + eye[i] + eye[j], theta + eye[i] - eye[j],
                theta - eye[i] + eye[j], theta - eye[i] - eye[j]]
    f = logpost(np.array(pts))
    f0, fp, fm = f[0], f[1:p + 1], f[p + 1:2 * p + 1]
    hess = np.diag((fp - 2 * f0 + fm) / h**2)
    for k, (i, j) in enumerate(pairs):
        a, b, c, d = f[2 * p + 1 + 4 * k: 2 * p + 5 + 4 * k]
        hess[i, j] = hess[j, i] = (a - b - c + d) / (4 * h[i] * h[j])
    return hess


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
                                 "hybridev.logs.read_measured_trips)")
            trips, traces = m.trips, m.traces
        else:
            trips, _ = validate_measured_trips(measured_trips, vehicle)
    if traces is not None and not isinstance(traces, LoggedTraces):
        raise ValueError("timeseries must be a LoggedTraces or a time-series DataFrame; got "
                         f"{type(traces).__name__}")
    return trips, traces


def calibrate_physics(measured_trips, vehicle: VehicleParams | None = None, *,
                      params: tuple[str, ...] = DEFAULT_PARAMS, n_walkers: int = 32,
                      n_steps: int | None = None, seed: int = 0, timeseries=None,
                      progress: bool = False, prior: PhysicsPrior | None = None,
                      missing_mode: str | DrivingProfile = "marginalize",
                      max_steps: int = 20000, trace_steps: int = 1000, trace_seed: int = 0,
                      refine_sign: bool = True) -> PhysicsPosterior:
    """Sample the posterior of physics parameters given measured trip energies.

    Parameters
    ----------
    measured_trips : pandas.DataFrame or MeasuredTrips
        Measured-trip table (``energy_kwh`` and/or ``soc_final``; ``mode`` may
        be missing) or the result of :func:`hybridev.logs.read_measured_trips`.
    vehicle : VehicleParams, optional
        Nominal vehicle: prior centres and all parameters not sampled.
    params : tuple of str
        Sampled parameters, a subset of
        :data:`hybridev.physics_stats.STAT_PARAMS`.
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

    Returns
    -------
    PhysicsPosterior

    Warns
    -----
    ConvergenceWarning
        When the chain is shorter than 50 autocorrelation times.

    Examples
    --------
    >>> from hybridev import make_trips
    >>> from hybridev.calibrate import simulate_measured
    >>> m = simulate_measured(make_trips(60, seed=0), noise_rel=0.03, seed=1)
    >>> post = calibrate_physics(m, params=("aux_base_kw",), n_walkers=8)
    >>> post.samples.shape[1], bool(post.summary().loc["aux_base_kw", "q05"] < 0.5)
    (1, True)
    """
    veh = vehicle or VehicleParams()
    pr = prior or PhysicsPrior()
    names = tuple(params)
    if len(set(names)) != len(names) or not names:
        raise ValueError(f"params={params!r} must be distinct names from {list(STAT_PARAMS)}")
    for n in names:
        if n not in STAT_PARAMS:
            raise ValueError(f"params has unknown parameter {n!r}; allowed: {list(STAT_PARAMS)}")
    infer = isinstance(missing_mode, str) and missing_mode == "infer"
    n_alr = 2 if infer else 0
    ndim = len(names) + n_alr + 1
    if n_walkers < 2 * ndim:
        raise ValueError(f"n_walkers={n_walkers!r} is outside the allowed range "
                         f"[{2 * ndim}, inf) for {ndim} sampled dimension(s)")
    if n_steps is not None and int(n_steps) < 1:
        raise ValueError(f"n_steps={n_steps!r} is outside the allowed range [1, inf)")
    trips, traces = _prepare(measured_trips, veh, timeseries)
    y = trips["energy_kwh"].to_numpy(float)
    if np.any(y <= 0):
        raise ValueError(f"energy_kwh={y[y <= 0][0]!r}: the relative-noise likelihood needs "
                         "measured energies > 0")
    t0 = time.perf_counter()

    def build(v):
        return trip_stats(trips, v, traces=traces, n_steps=trace_steps, seed=trace_seed,
                          missing_mode="marginalize" if infer else missing_mode)

    stats = build(veh)
    nominal = PhysicsPosterior.nominal_values(veh)
    specs = [pr.spec(n, nominal[n], float(stats.eta_r.max())) for n in names]
    fixed = {n: nominal[n] for n in STAT_PARAMS if n not in names}
    scale = np.array([s[2] * (np.exp(s[1]) if s[0] == "lognormal" else 1.0) for s in specs]
                     + [1.0] * (n_alr + 1))
    x0 = np.r_[[nominal[n] for n in names], np.zeros(n_alr)]
    logpost = _LogPosterior(stats, y, names, specs, pr, fixed, infer)
    with np.errstate(all="ignore"):
        s0 = float(np.sqrt(np.mean((y / energy_from_stats(stats) - 1.0) ** 2)))
    s0 = np.clip(s0 if np.isfinite(s0) else 0.1,
                 *(np.array(pr.noise_rel_bounds) * [1.01, 0.99]))
    start = np.r_[x0, np.log(s0)]
    theta, cov = _map_and_cov(logpost, start, scale)
    ref = veh
    if refine_sign and {"drag_area_m2", "rolling_resistance_coef",
                        "linear_drag_n_per_mps"} & set(names):
        sign = ("drag_area_m2", "rolling_resistance_coef", "linear_drag_n_per_mps")
        try:
            ref = vehicle_with(veh, {n: x for n, x in zip(names, theta[:len(names)],
                                                          strict=True) if n in sign})
        except ValueError:  # MAP outside VehicleParams' ranges: keep the nominal split
            ref = veh
        if ref is not veh:
            stats = build(ref)
            logpost = _LogPosterior(stats, y, names, specs, pr, fixed, infer)
            theta, cov = _map_and_cov(logpost, theta, scale)
    if not np.isfinite(logpost(theta[None, :])[0]):
        raise ValueError("the posterior is zero everywhere the optimiser looked: the physics "
                         "predicts energy <= 0 for some measured trip at any plausible "
                         "parameters (check grades, units and the trips' energy_kwh)")
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
    sampler.random_state = np.random.RandomState(seed).get_state()
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
    return PhysicsPosterior.from_sampler(
        sampler, names, vehicle=veh, reference_vehicle=ref, prior=pr, map_theta=theta,
        missing_mode=missing_mode, trace_steps=trace_steps, trace_seed=trace_seed,
        elapsed_s=time.perf_counter() - t0)


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
        Values of :data:`hybridev.physics_stats.STAT_PARAMS`; default nominal.
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
    from .physics import trace_power_kw
    from .trips import _blocks
    from .validation import validate_trips
    t = validate_trips(trips)
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

