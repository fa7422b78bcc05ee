"""Fused physics kernel: a trip's synthetic speed trace and its force sums in one pass.

:func:`hybridev.physics.stats_build.trip_stats` spends most of its time
building synthetic traces (:func:`hybridev.synthesize_speed_trace`) and
summing the force terms over them (``_trace_sums``), each a dozen numpy
passes over ``(n_trips, n_steps + 1)`` arrays. :func:`synthetic_sums` does
the same per trip in one compiled loop (numba): the trace is written to a
small buffer (it stays in the L1 cache), then the force sums, the moving time
and the top speed are accumulated from it. The per-trip constants (cycle count,
swing amplitudes' caps) and the keyed normal draws stay in numpy, with the
very same formulas as :func:`~hybridev.physics.kinematics.synthesize_speed_trace`
and only the draws each trip uses (:func:`~hybridev.physics.kinematics.keyed_normals_ragged`).

Results equal the numpy path's to rounding (sums in another order: about
1e-12 relative, tested to 1e-9), and each trip's numbers depend on that trip
alone, so any split into batches or partitions gives the same bits.

numba is imported on first use, never on import of this module. Without it,
or with the environment variable ``HYBRIDEV_NO_NUMBA=1``, :func:`synthetic_sums`
returns ``None`` and the caller uses the numpy path. The compiled code is
cached on disk (``cache=True``), so only the first process pays compilation.
"""

from __future__ import annotations

import os

import numpy as np

from hybridev.physics.kinematics import MIN_STEPS_PER_CYCLE, keyed_normals_ragged, profile_table

__all__ = ["N_ACC", "fused_available", "synthetic_sums"]

N_ACC = 12
"""Per-trip accumulators of the kernel: the moments ``[v, v^2, v^3, m a v]`` over
driving intervals, the same over (uncapped) braking ones, the moving intervals,
the top speed, the braking intervals at the regen limit and the sum of their SoC
derating factors. One more per-interval statistic is one more column of ``out`` here."""

_ENV = "HYBRIDEV_NO_NUMBA"
_compiled = None  # the jitted kernel, or False when numba cannot be imported


def _trips_kernel(ratio, inv_fa, one_minus_fb, inv_fb, n_cyc, h0, sig, half_sig2, h_hi, w,
                  vb, d_m, duration, dt, m_over_dt, grade_force, brake_limit_w, derate_a,
                  derate_b, z, z_start, n_steps, k_aero, lin_n_per_mps, moving_sum_mps,
                  out):  # pragma: no cover
    """Synthesise each trip's trace and accumulate its sums into ``out`` (n, N_ACC).

    Same arithmetic, operation by operation, as ``synthesize_speed_trace``
    followed by ``_trace_sums`` (one grade per trip); only the order of the
    sums differs. The regen limit of interval ``k`` is ``brake_limit_w`` times the
    SoC derating factor ``clip(derate_a + derate_b (k - 1/2) / n_steps, 0, 1)``
    (:mod:`hybridev.physics.derate`). Compiled by numba; plain Python also runs it (slowly).
    """
    n = ratio.shape[0]
    v = np.empty(n_steps + 1)
    for i in range(n):
        nc = n_cyc[i]
        z0 = z_start[i]
        hsum = 0.0
        for j in range(nc):
            hsum += min(h0[i] * np.exp(sig[i] * z[z0 + j] - half_sig2[i]), h_hi[i])
        base = vb[i] - w[i] * hsum / nc
        # the unit cycle shape times the cycle's swing, cycle by cycle: cycle j holds
        # the samples k with floor(k nc / N) = j (the last sample closes the last cycle)
        r, ia, ob, ib = ratio[i], inv_fa[i], one_minus_fb[i], inv_fb[i]
        total = 0.0
        k = 0
        for j in range(nc):
            hj = min(h0[i] * np.exp(sig[i] * z[z0 + j] - half_sig2[i]), h_hi[i])
            stop = ((j + 1) * n_steps + nc - 1) // nc if j < nc - 1 else n_steps + 1
            while k < stop:
                tau = k * r
                tau -= np.floor(tau)
                up = min(tau * ia, 1.0)
                down = max((tau - ob) * ib, 0.0)
                x = (up - down) * hj
                v[k] = x
                total += x
                k += 1
        swing_dist = (total - 0.5 * (v[0] + v[n_steps])) * dt[i]
        floor = base + (d_m[i] - base * duration[i] - swing_dist) / duration[i]
        # force sums over the intervals, split by the sign of the wheel force
        mdt, gf, lim = m_over_dt[i], grade_force[i], -brake_limit_w[i]
        da, db = derate_a[i], derate_b[i] / n_steps
        p0 = p2 = p3 = p4 = q0 = q2 = q3 = q4 = 0.0
        moving = capped = capped_f = 0.0
        prev = max(v[0] + floor, 0.0)
        vmax = prev
        for k in range(1, n_steps + 1):
            cur = max(v[k] + floor, 0.0)
            vmax = max(vmax, cur)
            s = cur + prev
            moving += 1.0 if s > moving_sum_mps else 0.0
            vm = s * 0.5
            inert = (cur - prev) * mdt
            force = vm * k_aero
            if lin_n_per_mps != 0.0:
                force += lin_n_per_mps
            force *= vm
            force += gf
            force += inert
            v2 = vm * vm
            v3 = v2 * vm
            iv = inert * vm
            if force > 0.0:
                p0 += vm
                p2 += v2
                p3 += v3
                p4 += iv
            else:
                f = min(max(da + db * (k - 0.5), 0.0), 1.0)  # SoC derating along the trip
                if force * vm < lim * f:  # braking power beyond the regen limit: only its time
                    capped += 1.0
                    capped_f += f
                else:
                    q0 += vm
                    q2 += v2
                    q3 += v3
                    q4 += iv
            prev = cur
        o = out[i]
        o[0], o[1], o[2], o[3] = p0, p2, p3, p4
        o[4], o[5], o[6], o[7] = q0, q2, q3, q4
        o[8], o[9], o[10], o[11] = moving, vmax, capped, capped_f


def _uniforms_kernel(k, counts, start, u):  # pragma: no cover (compiled)
    """Uniforms of :func:`~hybridev.physics.kinematics.keyed_normals_ragged` before ``ndtri``.

    ``k`` (n,) uint64 is the splitmix64 hash of each key with the seed; draw
    ``c`` of key ``i`` goes to ``u[start[i] + c]``. Integer arithmetic modulo
    2**64 and an exact conversion of 53 bits: the same numbers as numpy's.
    """
    gold = np.uint64(0x9E3779B97F4A7C15)
    m1 = np.uint64(0xBF58476D1CE4E5B9)
    m2 = np.uint64(0x94D049BB133111EB)
    for i in range(k.shape[0]):
        x0 = k[i] + gold
        for c in range(counts[i]):
            x = x0 + np.uint64(c) * gold
            x = (x ^ (x >> np.uint64(30))) * m1
            x = (x ^ (x >> np.uint64(27))) * m2
            x = x ^ (x >> np.uint64(31))
            u[start[i] + c] = (np.float64(x >> np.uint64(11)) + 0.5) * 2.0**-53


def _kernel():
    """The compiled kernels ``(trips, uniforms)``, or None (no numba, or ``HYBRIDEV_NO_NUMBA=1``)."""
    global _compiled
    if os.environ.get(_ENV, "") not in ("", "0"):
        return None
    if _compiled is None:
        try:
            import numba
        except ImportError:  # optional at run time: the numpy path is used
            _compiled = False
        else:
            jit = numba.njit(cache=True, nogil=True)
            _compiled = (jit(_trips_kernel), jit(_uniforms_kernel))
    return _compiled or None


def _ragged_normals(seed: int, keys: np.ndarray, counts: np.ndarray, uniforms
                    ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~hybridev.physics.kinematics.keyed_normals_ragged` with the hashing compiled."""
    if uniforms is None:
        return keyed_normals_ragged(seed, keys, counts)
    from scipy.special import ndtri

    from hybridev.physics.kinematics import _splitmix64

    start = np.zeros(len(counts), dtype=np.int64)
    np.cumsum(counts[:-1], out=start[1:])
    with np.errstate(over="ignore"):
        s = _splitmix64(np.uint64(seed & 0xFFFFFFFFFFFFFFFF) + np.zeros(1, np.uint64))
        k = _splitmix64(keys.astype(np.uint64) ^ s)
    u = np.empty(int(counts.sum()))
    uniforms(k, counts, start, u)
    return ndtri(u, out=u), start


def fused_available() -> bool:
    """True when :func:`synthetic_sums` runs compiled (numba importable and not disabled)."""
    return _kernel() is not None


_PROFILE_FIELDS = ("max_accel_mps2", "pke_mps2", "cycle_period_s", "amplitude_cv",
                   "phase_fractions")


def synthetic_sums(distance_km, avg_speed_kmh, profile, keys: np.ndarray, grade_rad,
                   n_steps: int, seed: int, vehicle, *, brake_limit_w=None, derate=None,
                   kernel=None):
    """Force sums of the synthetic traces of trips, without forming the traces.

    Parameters
    ----------
    distance_km, avg_speed_kmh : numpy.ndarray, shape (n,), km and km/h
        Finite and > 0 (checked by the caller).
    profile : DrivingProfile, str, or sequence of them (n,)
    keys : numpy.ndarray, shape (n,)
        Trace keys (:func:`~hybridev.physics.kinematics.trace_keys`).
    grade_rad : float or numpy.ndarray, shape (n,), rad
        One grade per trip.
    n_steps, seed : int
        Checked synthesis settings (as :func:`hybridev.synthesize_speed_trace`).
    vehicle : VehicleParams
        Fixes the sign split.
    brake_limit_w : numpy.ndarray, shape (n,), W, optional
        Braking wheel power beyond which regeneration runs at its limit
        (``stats_parts._regen_threshold``, before the SoC derating); ``inf`` or None: no limit.
    derate : tuple of numpy.ndarray (n,), optional
        ``(a, b)``: interval ``k``'s limit is ``brake_limit_w`` times
        ``clip(a + b (k - 1/2) / n_steps, 0, 1)`` (:func:`hybridev.physics.derate.derate_line`);
        None: no derating.
    kernel : tuple of callables, optional
        The kernels ``(trips, uniforms)`` to run (default: the compiled ones);
        tests pass the plain Python functions (``uniforms`` None: numpy).

    Returns
    -------
    tuple or None
        ``(sums_pos, sums_neg, duration_s, moving_s, max_speed_kmh, capped_s, capped_fs)``,
        the sums as lists ``[roll, aero, lin, rest]`` of arrays (n,) in kWh as
        ``_trace_sums`` returns them (braking sums without the intervals at the
        regen limit, whose time is ``capped_s``, and ``capped_fs`` that time weighted
        by the derating factor); None when the compiled kernel
        is unavailable.
    """
    kern = kernel or _kernel()
    if kern is None:
        return None
    kern, uniforms = kern
    from hybridev.physics.forces import MOVING_MPS
    from hybridev.physics.kinematics import _keys
    from hybridev.physics.stats import _J_PER_KWH

    d = np.asarray(distance_km, dtype=float)
    n = d.shape[0]
    # per-trip constants: the formulas of synthesize_speed_trace, operation by operation
    prof = profile_table(profile, n, _PROFILE_FIELDS)
    vb_mps = np.asarray(avg_speed_kmh, dtype=float) / 3.6
    duration = d * 1000.0 / vb_mps
    dt = duration / n_steps
    n_cyc = np.clip(np.rint(duration / prof["cycle_period_s"]), 1,
                    n_steps // MIN_STEPS_PER_CYCLE).astype(np.int64)
    period = duration / n_cyc
    fa, fc, fb = prof["fa"], prof["fc"], prof["fb"]
    w = 0.5 * fa + fc + 0.5 * fb
    slope_time = np.minimum(fa, fb) * period
    a_cap = prof["max_accel_mps2"] * slope_time
    h_cap = np.minimum(a_cap, 0.95 * vb_mps / w)
    target = prof["pke_mps2"] * period
    c = (2.0 * w - 1.0) / (2.0 * vb_mps)
    h_pke = 2.0 * target / (1.0 + np.sqrt(np.maximum(1.0 - 4.0 * c * target, 0.0)))
    h0 = np.minimum(h_pke, np.minimum(0.7 * a_cap, 0.8 * vb_mps / w))
    cv = prof["amplitude_cv"]
    sig = np.sqrt(np.log1p(cv**2))
    z, z_start = _ragged_normals(seed, _keys(keys, n), n_cyc, uniforms)
    veh = vehicle
    m, g = veh.mass_kg, veh.gravity_mps2
    th = np.broadcast_to(np.asarray(grade_rad, dtype=float), (n,))
    cos_th, sin_th = np.cos(th), np.sin(th)
    limit = (np.full(n, np.inf) if brake_limit_w is None
             else np.broadcast_to(np.asarray(brake_limit_w, dtype=float), (n,)))
    da, db = ((np.ones(n), np.zeros(n)) if derate is None else
              (np.broadcast_to(np.asarray(derate[0], float), (n,)),
               np.broadcast_to(np.asarray(derate[1], float), (n,))))
    out = np.empty((n, N_ACC))
    kern(n_cyc / n_steps, 1.0 / fa, 1.0 - fb, 1.0 / fb, n_cyc, h0, sig, 0.5 * sig**2,
         np.minimum(h_cap, 2.0 * h0), w, vb_mps, d * 1000.0, duration, dt, m / dt,
         (veh.rolling_resistance_coef * m * g) * cos_th + (m * g) * sin_th, limit,
         np.ascontiguousarray(da), np.ascontiguousarray(db), z, z_start,
         int(n_steps), 0.5 * veh.air_density_kg_m3 * veh.drag_area_m2,
         float(veh.linear_drag_n_per_mps), 2.0 * MOVING_MPS, out)
    cst = dt / _J_PER_KWH
    sums = []
    for s0, s2, s3, s4 in (out[:, 0:4].T, out[:, 4:8].T):  # as _trace_sums, one grade per trip
        roll = (m * g) * cos_th * s0 * cst
        rest_grade = (m * g) * sin_th * s0 * cst
        aero = (0.5 * veh.air_density_kg_m3) * s3 * cst
        lin = s2 * cst
        sums.append([roll, aero, lin, rest_grade + s4 * cst])
    return (sums[0], sums[1], dt * n_steps, out[:, 8] * dt, out[:, 9] * 3.6, out[:, 10] * dt,
            out[:, 11] * dt)
