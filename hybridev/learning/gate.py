"""The stacking gate: how much of the residual networks' correction a model keeps.

:class:`ResidualGate` chooses one weight ``w`` in [0, 1] per model so that the point
prediction is ``E_p + w dE`` (``E_p`` the physics, ``dE`` the members' mean residual).
It is fitted on out-of-sample predictions that the fit already makes: the CV+ folds'
predictions of their held-out trips, else the split-conformal calibration trips, else
the early-stopping (validation) trips; with none of them the weight stays 1.

**Rule.** ``w* = argmin_w mean_i |E*_i - E_p,i - w dE_i| / s_i`` (the out-of-fold mean
absolute relative error, ``s_i = max(|E*_i|, 0.05 kWh/km d_i)``) on a grid of step
0.01. The gain ``g = L(0) - L(w*)`` is averaged per group (day) and its standard
error ``se`` taken across groups (trips when there are fewer than 3 groups); the weight
is then shrunk by the positive-part James-Stein factor of that gain,
``w = w* max(0, 1 - (se / g)^2)``: a correction whose gain is within one standard
error of noise is dropped, a clear one is kept almost whole. Since ``L(w) <= L(0)``
is convex in ``w``, the chosen ``w`` never does worse than the physics on the trips
it was chosen on.

**Two candidates.** Given the trips' standardised network inputs (``features=``, the
CV+ path of :func:`hybridev.learning.fitting.fit_calibrator`), the gate also fits the
simpler learner of :mod:`hybridev.learning.linear` (a ridge on the out-of-fold physics
residual, its penalty chosen by grouped cross-validation) and weighs its own
out-of-fold predictions by the same rule. The candidate (``"networks"`` or
``"linear"``) with the smaller gated out-of-fold error is kept (the networks on a tie);
``evidence_`` records both. With the linear learner chosen, every member's mean is
replaced by ``w`` times the line's correction (the members then agree on the mean).

**What the gate scales.** Each member's residual mean (so the members' disagreement
shrinks with it); the members' noise heads are left as they are: they describe the
scatter of the measured energy around the prediction, which does not vanish when the
correction is dropped, and the conformal step rescales the spread on the same gated
predictions (the CV+ and split scores are computed with the gate applied, as at
prediction time).
"""

from __future__ import annotations

import math

import numpy as np

from hybridev.learning.linear import LinearResidual
from hybridev.learning.predictive import EnergyDistribution

__all__ = ["GRID_STEP", "MIN_KWH_PER_KM", "ResidualGate"]

GRID_STEP = 0.01
"""Step of the weight grid on [0, 1]."""
MIN_KWH_PER_KM = 0.05
"""Floor of the error scale per km (as :func:`hybridev.learning.residual.residual_scale`)."""


class ResidualGate:
    """Weight of the residual correction, chosen on out-of-sample trips.

    Attributes
    ----------
    weight_ : float
        In [0, 1]; 1 for a model without evidence (and for models saved before the
        gate), 0 keeps the physics alone.
    evidence_ : dict
        JSON-serialisable: ``source`` ("cv+", "split", "validation" or "none"),
        ``n_trips``, ``n_groups``, ``mape_physics``, ``mape_hybrid`` (ungated),
        ``mape_gated`` (%), ``weight_unshrunk`` and ``gain_t`` (gain over its
        standard error) of the chosen candidate; ``learner``; with the linear
        candidate fitted, ``candidates``: the same figures per candidate and the
        line's ``alpha``.
    learner_ : {"networks", "linear"}
        The residual the weight applies to.
    linear_ : LinearResidual or None
        The line, when it was fitted (saved only when it is the chosen learner).

    Parameters
    ----------
    features : array_like, shape (n_trips, n_features), optional
        Standardised network inputs of the trips :meth:`fit` will see, in the same
        order: enables the linear candidate.
    relative : bool
        The residual scale is relative (as the learner's target).
    """

    def __init__(self, features=None, *, relative: bool = True) -> None:
        self.features = None if features is None else np.asarray(features, dtype=float)
        self.relative = bool(relative)
        self.weight_ = 1.0
        self.evidence_ = {"source": "none", "n_trips": 0}
        self.learner_, self.linear_ = "networks", None
        self._fit_rows = None

    def fit(self, energy_kwh, energy_physics_kwh, residual_kwh, distance_km, groups=None,
            *, source: str = "cv+") -> ResidualGate:
        """Choose ``weight_`` from out-of-sample trips.

        Parameters
        ----------
        energy_kwh, energy_physics_kwh, residual_kwh : array_like, shape (n_trips,), kWh
            Measured energy, the physics and the members' mean residual of each trip,
            all predicted without that trip.
        distance_km : array_like, shape (n_trips,), km
        groups : array_like, shape (n_trips,), optional
            Group (day) of each trip; the standard error of the gain is taken across
            groups.
        source : str
            Where the predictions come from (recorded in ``evidence_``).
        """
        e = np.asarray(energy_kwh, float)
        p = np.asarray(energy_physics_kwh, float)
        r = np.asarray(residual_kwh, float)
        d = np.asarray(distance_km, float)
        s = np.maximum(np.abs(e), MIN_KWH_PER_KM * d)
        ok = np.isfinite(e) & np.isfinite(p) & np.isfinite(r) & (s > 0)
        self.learner_, self.linear_, self._fit_rows = "networks", None, None
        x = self.features
        if x is not None and x.shape[0] != len(e):
            raise ValueError(f"gate features have {x.shape[0]} rows for {len(e)} trips")
        e, p, r, s, d = e[ok], p[ok], r[ok], s[ok], d[ok]
        g = np.arange(len(e)) if groups is None else np.asarray(groups)[ok]
        self.weight_, self.evidence_ = 1.0, {"source": source, "n_trips": len(e)}
        if len(e) < 2:
            return self
        w, ev = self._choose(e, p, r, s, g)
        if x is not None and len(np.unique(g)) >= 3:
            scale = self._scale(p, d)
            lin = LinearResidual().fit(x[ok], (e - p) / scale, g)
            w_lin, ev_lin = self._choose(e, p, lin.oof_ * scale, s, g)
            ev_lin["alpha"] = float(lin.alpha_)
            ev["candidates"] = {"networks": {**ev, "weight": w},
                                "linear": {**ev_lin, "weight": w_lin}}
            self.linear_ = lin  # its out-of-fold predictions score the trips it saw
            self._fit_rows = (x, np.asarray(distance_km, float), ok, lin.oof_)
            if ev_lin["mape_gated"] < ev["mape_gated"] - 1e-9:
                self.learner_ = "linear"
                w, ev = w_lin, {**ev_lin, "candidates": ev["candidates"]}
        self.weight_ = w
        self.evidence_.update(learner=self.learner_, **ev)
        return self

    def _scale(self, energy_physics_kwh, distance_km) -> np.ndarray:
        """The residual scale of the learner's target (1 when absolute), kWh."""
        p = np.asarray(energy_physics_kwh, float)
        if not self.relative:
            return np.ones_like(p)
        return np.maximum(np.abs(p), MIN_KWH_PER_KM * np.asarray(distance_km, float))

    @staticmethod
    def _choose(e, p, r, s, g) -> tuple[float, dict]:
        """The rule of the module docstring: ``(weight, evidence)`` of one residual."""
        grid = np.linspace(0.0, 1.0, round(1 / GRID_STEP) + 1)
        err = np.abs((e - p)[None, :] - grid[:, None] * r[None, :]) / s  # (n_grid, n)
        loss = err.mean(axis=1)
        best = int(np.argmin(loss))
        gain_i = err[0] - err[best]
        _, codes = np.unique(g, return_inverse=True)
        if codes.max() + 1 < 3:
            codes = np.arange(len(e))
        per = np.bincount(codes, gain_i) / np.bincount(codes)
        gain = float(gain_i.mean())
        se = float(per.std(ddof=1) / math.sqrt(len(per))) if len(per) > 1 else math.inf
        t = gain / se if se > 0 else (math.inf if gain > 0 else 0.0)
        factor = max(0.0, 1.0 - 1.0 / t**2) if t > 0 else 0.0
        w = float(np.clip(grid[best] * factor, 0.0, 1.0))
        gated = float(np.mean(np.abs(e - p - w * r) / s))
        return w, {"n_groups": len(np.unique(g)), "weight_unshrunk": float(grid[best]),
                   "gain_t": float(min(t, 1e6)), "mape_physics": round(100 * float(loss[0]), 4),
                   "mape_hybrid": round(100 * float(loss[-1]), 4),
                   "mape_gated": round(100 * gated, 4)}

    def fit_distributions(self, energy_kwh, dists: list[EnergyDistribution], distance_km,
                          groups=None, *, source: str) -> ResidualGate:
        """:meth:`fit` on the (ungated) raw distributions of the held-out trips.

        ``dists``: one per trip block, each giving the physics (mean of its posterior
        draws) and the members' mean residual of its trips; concatenated in the order
        of ``energy_kwh``.
        """
        p = np.concatenate([d.physics_draws_kwh.mean(axis=0) for d in dists])
        r = np.concatenate([d.residual_mean_kwh.mean(axis=0) for d in dists])
        return self.fit(energy_kwh, p, r, distance_km, groups, source=source)

    def apply(self, member_means: np.ndarray, x=None, scale=None) -> np.ndarray:
        """The members' residual means (..., n_trips), kWh, with the gate applied.

        Networks: scaled by ``weight_``. Linear: every member's mean replaced by
        ``weight_`` times the line's correction of the standardised inputs ``x``
        (n_trips, n_features) times the target ``scale`` (n_trips,), kWh.
        """
        if self.learner_ == "linear":
            if x is None or scale is None:
                raise ValueError("the linear residual needs the trips' inputs and scale")
            corr = self.weight_ * self.linear_.predict(x) * np.asarray(scale, float)
            return np.broadcast_to(corr, np.shape(member_means)).astype(float)
        return member_means if self.weight_ == 1.0 else member_means * self.weight_

    def gated(self, dist: EnergyDistribution) -> EnergyDistribution:
        """An ungated raw distribution of the trips :meth:`fit` saw, with the gate applied
        to its members' means. With the linear learner, each trip gets the line's
        out-of-fold correction (the line was fitted on these trips: its in-sample
        corrections would make their conformal scores too small), its scale from the
        distribution's own physics."""
        means = dist.residual_mean_kwh
        if self.learner_ == "linear":  # the line's own out-of-fold corrections: scores of
            x, d, ok, oof = self._fit_rows  # trips it was fitted on are not in-sample
            scale = self._scale(dist.physics_draws_kwh.mean(axis=0), d)
            rel = self.linear_.predict(x)
            rel[ok] = oof
            means = np.broadcast_to(self.weight_ * rel * scale, np.shape(means)).astype(float)
        else:
            means = self.apply(means)
        return EnergyDistribution(dist.physics_draws_kwh, means,
                                  dist.residual_std_kwh, spread_factor=dist.spread_factor)

    def summary(self) -> dict:
        """``fit_info_["residual_gate"]``: the weight and its evidence (JSON-serialisable)."""
        return {"weight": round(float(self.weight_), 4), **self.evidence_}

    # -- persistence ---------------------------------------------------------------------
    def to_arrays(self) -> tuple[dict, dict[str, np.ndarray]]:
        """``(json_doc, arrays)``: the weight and its evidence; with the linear learner
        chosen, also ``learner``, ``linear`` (its document) and ``linear.coef``."""
        doc = {"weight": float(self.weight_), "evidence": dict(self.evidence_)}
        if self.learner_ != "linear":
            return doc, {}
        ldoc, larr = self.linear_.to_arrays()
        return ({**doc, "learner": "linear", "linear": ldoc},
                {f"linear.{k}": v for k, v in larr.items()})

    def set_arrays(self, doc: dict, arrays: dict[str, np.ndarray] | None = None
                   ) -> ResidualGate:
        """Inverse of :meth:`to_arrays`; an empty ``doc`` (a model saved before the gate)
        gives weight 1 (ValueError on a weight outside [0, 1])."""
        w = float(doc.get("weight", 1.0))
        if not (math.isfinite(w) and 0.0 <= w <= 1.0):
            raise ValueError(f"gate weight={w!r} must be in [0, 1]")
        self.weight_ = w
        self.evidence_ = dict(doc.get("evidence", {"source": "none", "n_trips": 0}))
        self.learner_, self.linear_, self._fit_rows = "networks", None, None
        learner = doc.get("learner", "networks")  # models saved before it: the networks
        if learner == "linear":
            self.linear_ = LinearResidual().set_arrays(doc["linear"], {
                k[len("linear."):]: v for k, v in (arrays or {}).items()
                if k.startswith("linear.")})
            self.learner_ = "linear"
        elif learner != "networks":
            raise ValueError(f"gate learner={learner!r} must be 'networks' or 'linear'")
        return self
