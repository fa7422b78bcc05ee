"""The residual learner of the hybrid model: standardisation, ensemble, distance hold.

:class:`ResidualLearner` learns what the physics misses. Its target is the residual
``(E* - E_p) / s`` (``s`` from :func:`~hybridev.learning.physics_stage.residual_scale`;
``PureML``: the energy itself), standardised by its training mean and spread; its inputs
are the trip features (:mod:`hybridev.learning.features`) standardised the same way and
held inside their training range (:meth:`hybridev.learning.domain.TrainingDomain.clip_features`).
The learner itself is a deep ensemble (:func:`hybridev.learning.nn.train_ensemble`);
the stacking gate (:class:`hybridev.learning.gate.ResidualGate`, ``gate_``) scales the
members' means in :meth:`ResidualLearner.moments`, so every prediction (point, CV+ fold,
interval) uses the gated correction; when the gate chose the simpler learner
(:mod:`hybridev.learning.linear`, a ridge line on the same standardised inputs), the
members' means are replaced by its gated correction there.

**Training-distance hold** (:func:`hold_inputs`). The networks take distance (and
the physics energy, which scales with it) as inputs; outside the distances of the
training trips they would extrapolate. The features of a trip longer (shorter) than the
longest (shortest) training trip are those of a trip of the boundary length under the
same conditions, so the relative residual ``dE / E_p`` is held at its boundary value
(for the paper's absolute residual, the residual per km is held). The training
distances are ``fit_info_["distance_km_range"]``; models saved before it existed are not
held.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import torch

from hybridev.learning.features import _feature_matrix, fit_standardizer, trip_features
from hybridev.learning.nn import EnsembleMLP, n_parameters, train_ensemble
from hybridev.learning.support import interpolation_support, support_and_gaps

__all__ = ["MIN_BLOCK_ROWS", "PREDICT_BLOCK_ROWS", "ResidualLearner", "hold_distances",
           "hold_inputs", "residual_scale"]

PREDICT_BLOCK_ROWS = 65_536
MIN_BLOCK_ROWS = 32
"""Smaller blocks are zero-padded to this many rows before the networks: the CPU matrix
kernels take another summation order for a handful of rows (seen below 13 rows with MKL),
which changed a trip's prediction in the last float32 bit depending on how many trips
were scored with it. Padded, a row's prediction does not depend on its batch (checked by
``tests/fleet/test_scoring.py``: pandas and dask partitions agree)."""


_MIN_SCALE_KWH_PER_KM = 0.05  # floor of the relative-residual scale (no EV uses less)


def residual_scale(energy_physics_kwh, distance_km, relative: bool) -> np.ndarray:
    """Scale of the residual target: 1 (absolute) or ``max(|E_p|, 0.05 kWh/km d)``, kWh."""
    e = np.asarray(energy_physics_kwh, dtype=float)
    if not relative:
        return np.ones_like(e)
    return np.maximum(np.abs(e), _MIN_SCALE_KWH_PER_KM * np.asarray(distance_km, float))


def hold_distances(distance_km, distance_range) -> np.ndarray:
    """Distances the networks see: clipped to ``distance_range`` (km; None: unchanged)."""
    d = np.asarray(distance_km, float)
    if not distance_range:
        return d
    return np.clip(d, float(distance_range[0]), float(distance_range[1]))


def _held_ratio(d: np.ndarray, distance_range) -> tuple[np.ndarray, np.ndarray | None]:
    """Held distances and ``d_held / d`` (None when no trip is held)."""
    held = hold_distances(d, distance_range)
    ratio = np.divide(held, d, out=np.ones_like(d), where=d > 0)
    return held, (None if np.all(ratio == 1.0) else ratio)


def hold_inputs(table, distance_range, relative: bool):
    """Physics table (or dict of column arrays) as the networks see it, and the scale factor.

    Trips outside ``distance_range`` (km) get the distance of the boundary and
    their physics energy scaled by ``d_held / d`` (same consumption); the
    returned factor ``d / d_held`` multiplies an absolute residual (the
    residual per km is held; for ``PureML`` the energy per km), and is 1 for
    the ``relative`` target, whose scale already grows with the trip.
    """
    frame = isinstance(table, pd.DataFrame)
    d = table["distance_km"].to_numpy(float) if frame else table["distance_km"]
    held, ratio = _held_ratio(d, distance_range)
    if ratio is None:
        return table, np.ones_like(d)
    out = table.copy() if frame else {**table, "distance_km": held}
    if frame:
        out["distance_km"] = held
    if "energy_kwh_physics" in (out.columns if frame else out):
        e = out["energy_kwh_physics"]
        out["energy_kwh_physics"] = (e.to_numpy(float) if frame else e) * ratio
    return out, (np.ones_like(d) if relative else 1.0 / ratio)


def _column(table, name: str) -> np.ndarray:
    """Column ``name`` (float) of a table or of a dict of column arrays."""
    return table[name] if isinstance(table, dict) else table[name].to_numpy(float)


class ResidualLearner:
    """Standardised deep ensemble on the physics residual.

    Parameters
    ----------
    feature_names : tuple of str
    residual : bool
        Learn ``E* - E_p`` (True) or ``E*`` itself (``PureML``).
    relative : bool
        Scale the residual by :func:`residual_scale`.
    **net : ensemble settings
        ``n_members, hidden, dropout, heteroscedastic, max_epochs, patience,
        batch_size, learning_rate, weight_decay, lr_decay, lr_decay_every`` of
        :func:`hybridev.learning.nn.train_ensemble`.

    Attributes
    ----------
    net_ : EnsembleMLP
        The fitted ensemble (eval mode).
    history_ : dict
        Per-epoch ``train_loss``/``val_loss`` (n_epochs, n_members),
        ``best_epoch``, ``stopped_epoch`` (n_members,), ``n_epochs``.
    feature_mean_, feature_std_ : numpy.ndarray, shape (n_features,)
        Standardisation of the inputs, in the units of the features.
    target_mean_, target_std_ : float
        Standardisation of the target (the scaled residual; ``PureML``: kWh).
    n_parameters_ : int
        Trainable parameters per member (3,393 for the paper's network on the 11
        listed inputs; 3,329 with 10).
    """

    def __init__(self, feature_names, *, residual: bool, relative: bool, **net) -> None:
        self.feature_names = tuple(feature_names)
        self.residual = bool(residual)
        self.relative = bool(relative) and self.residual
        self.net = net

    # -- fit ---------------------------------------------------------------------------
    def target_scale(self, energy_physics_kwh, distance_km) -> np.ndarray:
        """Scale of the target per trip (1 for an absolute residual or ``PureML``), kWh."""
        return residual_scale(energy_physics_kwh, distance_km, self.relative)

    def fit_scalers(self, x: np.ndarray, y: np.ndarray) -> ResidualLearner:
        """Standardisation of the raw features ``x`` and targets ``y`` (training rows)."""
        self.feature_mean_, self.feature_std_ = fit_standardizer(x)
        self.target_mean_ = float(np.mean(y))
        sd = float(np.std(y))
        self.target_std_ = sd if sd > 1e-12 else 1.0
        return self

    def scaled(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Standardised float32 inputs and targets."""
        xs = ((x - self.feature_mean_) / self.feature_std_).astype(np.float32)
        ys = ((y - self.target_mean_) / self.target_std_).astype(np.float32)
        return xs, ys

    def train(self, xs, ys, tr_idx, val_idx, seed: int, progress=None):
        """A new ensemble on rows ``tr_idx``, early stopping on ``val_idx``: ``(net, history)``."""
        v = len(val_idx) > 0
        p = self.net
        return train_ensemble(
            xs[tr_idx], ys[tr_idx], xs[val_idx] if v else None, ys[val_idx] if v else None,
            n_members=int(p["n_members"]), hidden=tuple(int(h) for h in p["hidden"]),
            dropout=float(p["dropout"]), heteroscedastic=bool(p["heteroscedastic"]),
            max_epochs=int(p["max_epochs"]), patience=int(p["patience"]),
            batch_size=int(p["batch_size"]), learning_rate=float(p["learning_rate"]),
            weight_decay=float(p["weight_decay"]), lr_decay=float(p["lr_decay"]),
            lr_decay_every=int(p["lr_decay_every"]), seed=int(seed), progress=progress)

    def fit(self, xs, ys, tr_idx, val_idx, seed: int, progress=None) -> ResidualLearner:
        """Train ``net_`` (after :meth:`fit_scalers`)."""
        self.net_, self.history_ = self.train(xs, ys, tr_idx, val_idx, seed, progress)
        self.n_parameters_ = self.net_.n_parameters_per_member
        return self

    def new_net(self) -> EnsembleMLP:
        """An untrained ensemble of this learner's architecture (to load weights into)."""
        p = self.net
        return EnsembleMLP(len(self.feature_names), p["hidden"], n_members=p["n_members"],
                           dropout=p["dropout"], heteroscedastic=p["heteroscedastic"])

    def n_weights(self) -> int:
        """Weights of the whole ensemble (checked before a saved one is allocated)."""
        p = self.net
        return int(p["n_members"]) * n_parameters(len(self.feature_names), p["hidden"],
                                                  heteroscedastic=bool(p["heteroscedastic"]))

    # -- predict -----------------------------------------------------------------------
    def standardized(self, x: np.ndarray, domain=None) -> np.ndarray:
        """Standardised float32 inputs of the raw feature matrix ``x``, held in ``domain``'s range."""
        xs = ((x - self.feature_mean_) / self.feature_std_).astype(np.float32)
        if domain is None:
            return xs  # as TrainingDomain.clip_features: no extrapolation
        return np.clip(xs, domain.feature_lo, domain.feature_hi).astype(xs.dtype)

    def features(self, physics_table, domain=None) -> np.ndarray:
        """Standardised network inputs (n_trips, n_features) of a physics table (or of
        its columns as arrays by name, :meth:`column_features`)."""
        if isinstance(physics_table, dict):
            return self.column_features(physics_table, len(physics_table["distance_km"]),
                                        domain)
        return self.standardized(trip_features(physics_table, self.feature_names), domain)

    def column_features(self, columns: dict, n_trips: int, domain=None) -> np.ndarray:
        """:meth:`features` of a table given as arrays by column name."""
        return self.standardized(_feature_matrix(columns, n_trips, self.feature_names), domain)

    def moments(self, x: np.ndarray, scale=1.0, net=None, support=None
                ) -> tuple[np.ndarray, np.ndarray | None]:
        """Per-member output in kWh: ``mean (n_members, n_trips)`` and ``var`` or None.

        ``x`` standardised inputs (:meth:`features`); ``scale`` (n_trips,) the target
        scale; ``net`` another ensemble with this standardisation (a CV+ fold model).
        The mean is each member's residual (``PureML``: energy), scaled by the gate's
        weight when ``gate_`` is set, and by ``support`` (n_trips,), the correction's
        support between training values (:mod:`hybridev.learning.support`; None: 1);
        the variance its predicted noise (kWh^2; None without variance heads).
        """
        net = self.net_ if net is None else net
        x = np.ascontiguousarray(x, dtype=np.float32)
        means, variances = [], []
        with torch.inference_mode():  # blocks of rows bound the (M, rows, 64) activations
            for start in range(0, max(len(x), 1), PREDICT_BLOCK_ROWS):
                blk = x[start:start + PREDICT_BLOCK_ROWS]
                k = len(blk)
                if k < MIN_BLOCK_ROWS:  # see MIN_BLOCK_ROWS
                    blk = np.concatenate([blk, np.zeros((MIN_BLOCK_ROWS - k, blk.shape[1]),
                                                        np.float32)])
                m, v = net(torch.from_numpy(blk))
                means.append(m.numpy()[:, :k])
                variances.append(None if v is None else v.numpy()[:, :k])
        scale = np.asarray(scale, dtype=float)
        mean = (np.concatenate(means, axis=1).astype(float) * self.target_std_
                + self.target_mean_) * scale
        gate = getattr(self, "gate_", None)  # the stacking gate (hybridev.learning.gate)
        if gate is not None and self.residual:
            mean = gate.apply(mean, x, np.broadcast_to(scale, (x.shape[0],)))
        if support is not None and self.residual:  # revert to the physics in data gaps
            mean = mean * np.asarray(support, float)[None, :]
        if variances[0] is None:
            return mean, None
        return mean, np.concatenate(variances, axis=1).astype(float) * (self.target_std_ * scale)**2

    def predict_moments(self, tables: list, index: list[int], nets: list, distance_range,
                        domain=None) -> list[tuple[np.ndarray, np.ndarray | None]]:
        """Step 3 of the predictive path: :meth:`moments` of each ensemble in ``nets``.

        ``tables``: physics tables (one per physics; or their columns as arrays by
        name, :meth:`PhysicsDraws.entry_columns`); ``index[i]``: the table of
        ``nets[i]`` (``None``: ``net_``). Inputs are held inside ``distance_range``
        (km, :func:`hold_inputs`) and ``domain``'s feature range, and the correction
        is weighted by its support (:func:`~hybridev.learning.support.interpolation_support`);
        each table's inputs are built once. The noise of a trip in a gap between training
        values is drawn toward the noise at the bracketing values (:meth:`_gap_noise`).
        """
        inputs, out = {}, []
        for net, e in zip(nets, index, strict=True):
            if e not in inputs:
                table = tables[e]
                held, factor = hold_inputs(table, distance_range, self.relative)
                scale = self.target_scale(_column(table, "energy_kwh_physics"),
                                          _column(table, "distance_km")) * factor
                # the held table differs from the trips' only in distance and energy:
                # one bracketing gives the support and the gaps
                inputs[e] = (self.features(held, domain), scale, held,
                             *support_and_gaps(table, domain))
            x, scale, held, support, gaps = inputs[e]
            mean, var = self.moments(x, scale, net=net, support=support)
            out.append((mean, self._gap_noise(held, scale, var, net, domain, gaps)))
        return out

    def _gap_noise(self, table, scale, var, net, domain, gaps):
        """Member noise variances (n_members, n_trips) with each trip in a gap between
        training values drawn toward the noise at the bracketing values: ``w var(x) +
        (1 - w) var_ab`` per gap quantity, ``var_ab`` the log-linear interpolation between
        the noise of the same trip with that quantity set to the lower and to the upper
        training value, ``w`` the support, ``gaps`` the trips in a gap
        (:func:`~hybridev.learning.support.support_and_gaps`)."""
        if not gaps or var is None:
            return var
        var = var.copy()
        scale = np.broadcast_to(np.asarray(scale, float), (var.shape[1],))
        for g in gaps:
            ends = []
            for value in (g.lo, g.hi):
                if isinstance(table, dict):
                    sub = {k: (np.asarray(v)[g.rows] if np.ndim(v) else v)
                           for k, v in table.items()}
                    sub[g.name] = value
                else:
                    sub = table.iloc[g.rows].assign(**{g.name: value})
                ends.append(self.moments(self.features(sub, domain), scale[g.rows],
                                         net=net)[1])
            log_ab = (1.0 - g.t) * np.log(ends[0]) + g.t * np.log(ends[1])
            var[:, g.rows] = g.support * var[:, g.rows] + (1.0 - g.support) * np.exp(log_ab)
        return var

    def point(self, table, domain=None) -> np.ndarray:
        """Point energy (kWh) of a physics table (or its columns as arrays by name),
        without the distance hold (n_trips,)."""
        e = _column(table, "energy_kwh_physics")
        scale = self.target_scale(e, _column(table, "distance_km"))
        support = interpolation_support(table, domain)
        return self.combine(e, self.moments(self.features(table, domain), scale,
                                            support=support)[0].mean(0))

    def point_of_columns(self, columns: dict, n_trips: int, distance_range, domain=None
                         ) -> np.ndarray:
        """Point energy (kWh, before the floor) of a table given as arrays by column name."""
        e = columns["energy_kwh_physics"]
        held, factor = hold_inputs(columns, distance_range, self.relative)
        scale = self.target_scale(e, columns["distance_km"]) * factor
        x = self.column_features(held, n_trips, domain)
        support = interpolation_support(columns, domain)
        return self.combine(e, self.moments(x, scale, support=support)[0].mean(0))

    def combine(self, energy_physics: np.ndarray, network_mean: np.ndarray) -> np.ndarray:
        """Point energy (kWh) from the physics and the members' mean output.

        The residual may not turn a consuming trip into a generating one:
        ``max(E_p + dE, min(E_p, 0))``; ``PureML``: ``max(E, 0)``.
        """
        if not self.residual:
            return np.maximum(network_mean, 0.0)
        return np.maximum(energy_physics + network_mean, np.minimum(energy_physics, 0.0))

    # -- persistence -------------------------------------------------------------------
    def to_arrays(self) -> tuple[dict, dict[str, np.ndarray]]:
        """``(json_doc, arrays)`` of the fitted learner (see :mod:`hybridev.learning.modelfile`)."""
        h = self.history_
        doc = {"feature_names": list(self.feature_names), "target_mean": self.target_mean_,
               "target_std": self.target_std_,
               "history": {"best_epoch": np.asarray(h["best_epoch"]).tolist(),
                           "stopped_epoch": np.asarray(h["stopped_epoch"]).tolist(),
                           "n_epochs": int(h["n_epochs"])}}
        arrays = {f"net.{k}": v for k, v in self.net_.to_arrays().items()}
        arrays.update(feature_mean=self.feature_mean_, feature_std=self.feature_std_,
                      train_loss=h["train_loss"], val_loss=h["val_loss"])
        return doc, arrays

    def set_arrays(self, doc: dict, arrays: dict[str, np.ndarray]) -> ResidualLearner:
        """Inverse of :meth:`to_arrays` (ValueError naming the bad entry)."""
        import math

        names = tuple(doc["feature_names"])
        if names != self.feature_names:
            raise ValueError(f"feature_names={list(names)!r} do not match the model's features "
                             f"{list(self.feature_names)!r}")
        stored = sum(int(v.size) for k, v in arrays.items() if k.startswith("net."))
        if self.n_weights() != stored:  # checked before the network is allocated
            raise ValueError(f"the configuration (n_members={self.net['n_members']}, hidden="
                             f"{list(self.net['hidden'])}) needs {self.n_weights()} network "
                             f"weights, but arrays.npz stores {stored}")
        net = self.new_net()
        net.load_arrays({k[4:]: v for k, v in arrays.items() if k.startswith("net.")},
                        what="network")
        net.eval()
        for key in ("feature_mean", "feature_std"):
            a = arrays.get(key)
            if a is None or a.shape != (len(names),) or not np.all(np.isfinite(a)):
                raise ValueError(f"array {key!r} must be {len(names)} finite values")
        if np.any(arrays["feature_std"] <= 0):
            raise ValueError("array 'feature_std' must be positive")
        t_mean, t_std = float(doc["target_mean"]), float(doc["target_std"])
        if not (math.isfinite(t_mean) and math.isfinite(t_std) and t_std > 0):
            raise ValueError(f"target_mean={t_mean!r}, target_std={t_std!r} must be "
                             "finite, target_std > 0")
        h = doc["history"]
        self.history_ = {"train_loss": arrays["train_loss"], "val_loss": arrays["val_loss"],
                         "best_epoch": np.asarray(h["best_epoch"]),
                         "stopped_epoch": np.asarray(h["stopped_epoch"]),
                         "n_epochs": int(h["n_epochs"])}
        self.feature_mean_ = arrays["feature_mean"].astype(float)
        self.feature_std_ = arrays["feature_std"].astype(float)
        self.target_mean_, self.target_std_ = t_mean, t_std
        self.n_parameters_ = net.n_parameters_per_member
        self.net_ = net
        return self
