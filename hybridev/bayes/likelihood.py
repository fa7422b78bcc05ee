"""Log-posterior of the physics parameters given measured trip energies, and its mode.

The log-likelihood is vectorised over walkers: a (n_walkers, n_params) block of
parameters gives (n_walkers,) log-probabilities with one matrix product over the
trips' sufficient statistics (hybridev.physics.stats).

Residual: ``r = y / E_eff - 1`` with ``E_eff = max(E(theta), PREDICTED_FLOOR_REL * y)``
(the Jacobian ``-log E_eff`` included). A prediction at or below a fifth of
the measured energy (even <= 0, e.g. a descent with too much regeneration at
these parameters) is thus a large, finite residual, never a zero likelihood:
no trip can make the posterior vanish. The residual is Student-t with
``nu = PhysicsPrior.noise_dof`` degrees of freedom (normal when ``None``);
with groups, each group's residuals are multivariate t with scale matrix
``sigma^2 I + tau^2 1 1^T`` (the day random effect), in closed form
(Sherman-Morrison). Heavy tails bound the influence of any one trip: as its
residual grows, its pull on the parameters vanishes.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize
from scipy.special import gammaln

from hybridev.physics.stats import (
    HEATING_TERM,
    WARMUP_TERM,
    PhysicsStats,
    coefficients,
    interp_offset,
)

__all__ = ["PREDICTED_FLOOR_REL"]

PREDICTED_FLOOR_REL = 0.2
"""Floor of the predicted energy in the residual, as a share of the measured energy."""


def _log_t_norm(n, nu):
    """Normalising constant of an n-variate t with nu dof (unit scale)."""
    return gammaln(0.5 * (nu + n)) - gammaln(0.5 * nu) - 0.5 * n * np.log(nu * np.pi)


class _LogPosterior:
    """Vectorised log posterior over ``theta = (params..., [mode logits,] [tau,] log sigma_rel)``.

    With ``groups`` (integer codes per trip; one row per trip) a group random
    effect of relative sd ``tau`` (half-normal prior) is marginalised
    analytically (:meth:`_group_log_lik`).

    With ``infer_modes`` the mixture weights of unlabelled trips are
    ``pi = softmax(0, a_normal, a_aggressive)`` (eco first, as in PROFILES) with a
    Dirichlet(1, 1, 1) prior on ``pi``, i.e. ``log p(a) = sum(log pi)`` in these
    coordinates; ``|a| < 20``.
    """

    def __init__(self, stats: PhysicsStats, energy_kwh: np.ndarray, names, specs, prior,
                 fixed: dict[str, float], infer_modes: bool = False, groups=None):
        self.names = list(names)
        self.n_alr = 2 if infer_modes else 0
        f = stats.features()
        self.rows = np.flatnonzero(np.abs(f).sum(axis=1) > 0)  # all-zero terms cost nothing
        self.F = f[self.rows]
        # heating onset: energy changes on the offset grid (continuous climate model)
        self.offset0 = stats.vehicle.heating_offset_k
        self.dH = self.dW = None
        moves = "heating_offset_k" in self.names or fixed.get(
            "heating_offset_k", self.offset0) != self.offset0
        if moves:
            if stats.heating_offset_dkwh is None:
                raise ValueError("heating_offset_k needs the continuous climate model "
                                 "(VehicleParams(climate_model='continuous'))")
            self.dH, self.dW = stats.heating_offset_dkwh, stats.warmup_offset_dkwh
        self.y = energy_kwh[stats.trip]
        self.y_trip = np.asarray(energy_kwh, dtype=float)
        self.log_w = stats.log_weight
        self.n_trips = stats.n_trips
        self.n_group = 0
        specs = list(specs) + [("alr", 0.0, np.inf, -20.0, 20.0)] * self.n_alr
        if groups is not None:  # group codes (n_trips,), 0..n_groups-1
            if stats.marginalised:
                raise ValueError("a group random effect needs one row per trip "
                                 "(no trip marginalised over modes)")
            g = np.asarray(groups, dtype=np.intp)
            self.G = np.zeros((self.n_trips, int(g.max()) + 1))
            self.G[np.arange(self.n_trips), g] = 1.0
            self.n_g = self.G.sum(axis=0)
            self.n_group = 1
            specs.append(("normal", 0.0, prior.group_sd_scale, 0.0, 0.5))  # half-normal tau
        self.kind_log = np.array([s[0] == "lognormal" for s in specs])
        self.centre = np.array([s[1] for s in specs], dtype=float)
        # split normal: its own sd below the centre (others: the same on both sides)
        self.sd = np.array([s[2][1] if s[0] == "splitnormal" else s[2] for s in specs],
                           dtype=float)
        self.sd_below = np.array([s[2][0] if s[0] == "splitnormal" else s[2] for s in specs],
                                 dtype=float)
        self.lo = np.array([s[3] for s in specs], dtype=float)
        self.hi = np.array([s[4] for s in specs], dtype=float)
        self.log_noise = np.log(prior.noise_rel_bounds)
        self.nu = getattr(prior, "noise_dof", None)
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
            if self.dH is not None:
                self.dH = np.where(live.ravel()[:, None], self.dH[idx], 0.0)
                self.dW = np.where(live.ravel()[:, None], self.dW[idx], 0.0)
            self.y = np.where(live.ravel(), self.y[idx], 1.0)
            self.log_w = np.where(live.ravel(), 0.0 if infer_modes else self.log_w[idx], -np.inf)
            self.shape = live.shape
            self.unknown = (counts > 1).astype(float)
        self.floor = PREDICTED_FLOOR_REL * self.y  # per row (padded layout when marginalised)
        self.floor_trip = PREDICTED_FLOOR_REL * self.y_trip
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
        d = np.where(self.kind_log, lx, x) - self.centre
        z = d / np.where(d < 0, self.sd_below, self.sd)
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

    def _group_log_lik(self, theta: np.ndarray, e: np.ndarray) -> np.ndarray:
        """Relative residuals with a shared group effect, marginalised in closed form.

        ``y_i / e_i - 1 = u_g + eps_i`` with ``u_g ~ N(0, tau^2)`` per group and
        ``eps_i ~ N(0, sigma^2)``: each group's residuals are jointly normal
        with covariance ``sigma^2 I + tau^2 1 1^T`` (Sherman-Morrison).
        """
        e = np.maximum(e, self.floor_trip)
        r = self.y_trip / e - 1.0
        s2 = np.exp(2.0 * theta[:, -1])[:, None]
        t2 = (theta[:, -2] ** 2)[:, None]
        s1 = r @ self.G
        sq = (r * r) @ self.G
        den = s2 + self.n_g * t2
        q = sq / s2 - t2 * s1 * s1 / (s2 * den)  # Mahalanobis distance of each group
        logdet = (self.n_g - 1.0) * np.log(s2) + np.log(den)
        if self.nu is None:
            ll = -0.5 * q - 0.5 * logdet - 0.5 * self.n_g * np.log(2 * np.pi)
        else:  # multivariate t per group (closed form, same scale matrix)
            ll = (_log_t_norm(self.n_g, self.nu) - 0.5 * logdet
                  - 0.5 * (self.nu + self.n_g) * np.log1p(q / self.nu))
        return ll.sum(axis=1) - np.log(e).sum(axis=1)

    def log_lik(self, theta: np.ndarray) -> np.ndarray:
        v = self.values(theta)
        coef = coefficients(v)
        full = np.empty((len(theta), len(coef)))
        for i, c in enumerate(coef):  # as stacking broadcast columns, without their overhead
            full[:, i] = c
        e = full[:, self.rows] @ self.F
        if self.dH is not None:  # the heating onset moves the heating and warm-up terms
            d = v["heating_offset_k"][:, None] - self.offset0
            e = (e + full[:, HEATING_TERM, None] * interp_offset(self.dH, d)
                 + full[:, WARMUP_TERM, None] * interp_offset(self.dW, d))
        if self.n_group:
            return self._group_log_lik(theta, e)
        log_sig = theta[:, -1]
        # log N(y | e, (sigma e)^2) = -(y/e - 1)^2 / (2 sigma^2) - log e - log sigma - log(2 pi)/2
        # (Student t: -(nu + 1)/2 log(1 + z^2 / nu) + its constant), in place (hot path);
        # e below the floor counts as the floor: a large but finite residual.
        np.maximum(e, self.floor, out=e)
        ll = np.divide(self.y, e)
        ll -= 1.0
        ll *= ll
        if self.nu is None:
            ll *= (-0.5 * np.exp(-2.0 * log_sig))[:, None]
            const = self.n_trips * (-log_sig - 0.5 * np.log(2 * np.pi))
        else:
            ll *= (np.exp(-2.0 * log_sig) / self.nu)[:, None]
            np.log1p(ll, out=ll)
            ll *= -0.5 * (self.nu + 1.0)
            const = self.n_trips * (-log_sig + _log_t_norm(1, self.nu))
        ll -= np.log(e)
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
