"""The residual network (paper, Sec. III-B/C) as a batched ensemble, in torch on the CPU.

:class:`EnsembleMLP` holds ``M`` independent multilayer perceptrons in one
module: layer ``i`` has weights of shape ``(M, n_in, n_out)`` and biases
``(M, 1, n_out)``, and a forward pass is one batched matrix product per layer,
so ``M`` members train in one pass. ``M = 1`` is the paper's single network:

* ``h1 = ReLU(W1 x + b1)`` (64), ``h2 = Dropout(ReLU(W2 h1 + b2))`` (32),
  ``h3 = Dropout(ReLU(W3 h2 + b3))`` (16), ``out = w4 h3 + b4`` (linear).
  With other ``hidden`` sizes, dropout follows every hidden layer but the first.
* Parameter count: ``(n_in + 1) 64 + 65 * 32 + 33 * 16 + 17``, i.e. 3,329 for
  10 inputs and 3,393 for the 11 inputs the paper actually lists. The paper's
  "approximately 5,400" matches neither; see :func:`n_parameters`.

Optionally (``heteroscedastic=True``) each member has a second output, the
variance ``softplus(raw) + VARIANCE_FLOOR`` (standardised units), trained with
the Gaussian negative log-likelihood: the members of a deep ensemble.

Training (:func:`train_ensemble`) follows the paper: mean squared error on the
(standardised) residual plus ``lambda ||theta||^2`` with ``lambda = 1e-4``,
Adam with learning rate 1e-3 decayed by 0.95 every 50 epochs, batch 32, at
most 200 epochs, early stopping with patience 20 on the validation loss,
restoring the best weights. The penalty is implemented exactly, as Adam's
(coupled, not AdamW) ``weight_decay = 2 lambda``: Adam adds ``weight_decay *
theta`` to the gradient, which is the gradient of ``lambda ||theta||^2``. Like
the paper's ``theta``, it covers all weights *and biases*. With ``M > 1`` the
loss is the sum of the members' losses, so each member gets exactly its own
gradient, Adam state and early stopping: members stop independently (a
per-member "stopped" mask; each keeps its own best weights; a stopped member's
weights keep moving in the batch, but its best weights are frozen and restored),
and training ends when all have stopped. Members differ in initialisation, dropout masks and
data order (each member draws its own permutation every epoch). All
randomness comes from one :class:`torch.Generator` seeded by ``seed``; the
global torch RNG is never touched, and the same seed gives identical weights.
"""

from __future__ import annotations

import contextlib
import itertools
import math
from collections.abc import Callable, Iterator, Sequence

import numpy as np
import torch
from torch import nn

__all__ = ["VARIANCE_FLOOR", "EnsembleMLP", "n_parameters", "single_thread", "train_ensemble"]

VARIANCE_FLOOR = 1e-4
"""Smallest variance of the variance head, in standardised target units."""


def n_parameters(n_inputs: int, hidden: Sequence[int] = (64, 32, 16), *,
                 heteroscedastic: bool = False) -> int:
    """Trainable parameters of one member.

    Examples
    --------
    >>> n_parameters(10), n_parameters(11), n_parameters(11, heteroscedastic=True)
    (3329, 3393, 3410)
    """
    sizes = (int(n_inputs), *(int(h) for h in hidden), 2 if heteroscedastic else 1)
    return sum((a + 1) * b for a, b in itertools.pairwise(sizes))


class EnsembleMLP(nn.Module):
    """``M`` independent MLPs evaluated as one batched network.

    Parameters
    ----------
    n_inputs : int
        Number of input features.
    hidden : sequence of int
        Hidden-layer widths (the paper: 64, 32, 16).
    n_members : int
        Ensemble size ``M`` (1 = the paper's single network).
    dropout : float
        Dropout probability after hidden layers 2, 3, ... (the paper: 0.2).
    heteroscedastic : bool
        Add a variance output per member.
    generator : torch.Generator, optional
        Source of the initial weights (torch's ``nn.Linear`` default: uniform
        on ``+-1/sqrt(fan_in)`` for weights and biases).

    Examples
    --------
    >>> net = EnsembleMLP(11, n_members=3, generator=torch.Generator().manual_seed(0))
    >>> mean, var = net(torch.zeros(5, 11))
    >>> tuple(mean.shape), var is None, net.n_parameters_per_member
    ((3, 5), True, 3393)
    """

    def __init__(self, n_inputs: int, hidden: Sequence[int] = (64, 32, 16), *,
                 n_members: int = 1, dropout: float = 0.2, heteroscedastic: bool = False,
                 generator: torch.Generator | None = None) -> None:
        super().__init__()
        self.n_inputs = int(n_inputs)
        self.hidden = tuple(int(h) for h in hidden)
        self.n_members = int(n_members)
        self.dropout = float(dropout)
        self.heteroscedastic = bool(heteroscedastic)
        sizes = (self.n_inputs, *self.hidden, 2 if self.heteroscedastic else 1)
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for a, b in itertools.pairwise(sizes):
            bound = 1.0 / math.sqrt(a)
            w = (torch.rand(self.n_members, a, b, generator=generator) * 2.0 - 1.0) * bound
            c = (torch.rand(self.n_members, 1, b, generator=generator) * 2.0 - 1.0) * bound
            self.weights.append(nn.Parameter(w))
            self.biases.append(nn.Parameter(c))

    @property
    def n_parameters_per_member(self) -> int:
        """Trainable parameters of one member."""
        return n_parameters(self.n_inputs, self.hidden, heteroscedastic=self.heteroscedastic)

    def forward(self, x: torch.Tensor, generator: torch.Generator | None = None
                ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """Evaluate all members.

        Parameters
        ----------
        x : torch.Tensor, shape (n, n_inputs) or (M, n, n_inputs)
            Standardised inputs, shared by all members or one batch per member.
        generator : torch.Generator, optional
            Source of the dropout masks in training mode.

        Returns
        -------
        mean : torch.Tensor, shape (M, n)
        var : torch.Tensor, shape (M, n), or None without a variance head
        """
        h = x
        last = len(self.weights) - 1
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            h = torch.baddbmm(b, h, w) if h.dim() == 3 else torch.matmul(h, w) + b
            if i == last:
                break
            h = torch.relu(h)
            if i >= 1 and self.training and self.dropout > 0.0:
                keep = 1.0 - self.dropout
                mask = torch.empty_like(h).bernoulli_(keep, generator=generator)
                h = h * mask * (1.0 / keep)
        if not self.heteroscedastic:
            return h[..., 0], None
        return h[..., 0], nn.functional.softplus(h[..., 1]) + VARIANCE_FLOOR

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Weights as float32 numpy arrays, keyed ``w0, b0, w1, ...``."""
        out = {}
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            out[f"w{i}"] = w.detach().cpu().numpy().astype(np.float32)
            out[f"b{i}"] = b.detach().cpu().numpy().astype(np.float32)
        return out

    def load_arrays(self, arrays: dict[str, np.ndarray], *, what: str = "weights") -> None:
        """Set the weights from :meth:`to_arrays` output; checks names and shapes."""
        with torch.no_grad():
            for kind, params in (("w", self.weights), ("b", self.biases)):
                for i, p in enumerate(params):
                    key = f"{kind}{i}"
                    if key not in arrays:
                        raise ValueError(f"{what}: array {key!r} is missing")
                    a = np.asarray(arrays[key])
                    if a.shape != tuple(p.shape):
                        raise ValueError(f"{what}: array {key!r} has shape {a.shape}, "
                                         f"expected {tuple(p.shape)}")
                    if not np.all(np.isfinite(a)):
                        raise ValueError(f"{what}: array {key!r} has NaN or infinite values")
                    p.copy_(torch.from_numpy(a.astype(np.float32)))


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """Run torch single-threaded inside the block, restoring the thread count after.

    The network is so small (batches of 32 x 64) that intra-op threads only
    add synchronisation: on 2 busy cores they made training several times
    slower, with identical results.
    """
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _loss(mean: torch.Tensor, var: torch.Tensor | None, y: torch.Tensor) -> torch.Tensor:
    """Per-member loss (M,): MSE, or Gaussian NLL (without the constant) with a variance head."""
    if var is None:
        return ((mean - y) ** 2).mean(dim=-1)
    return 0.5 * (torch.log(var) + (mean - y) ** 2 / var).mean(dim=-1)


@single_thread()
def train_ensemble(x_train: np.ndarray, y_train: np.ndarray, x_val: np.ndarray | None,
                   y_val: np.ndarray | None, *, n_members: int = 1,
                   hidden: Sequence[int] = (64, 32, 16), dropout: float = 0.2,
                   heteroscedastic: bool = False, max_epochs: int = 200, patience: int = 20,
                   batch_size: int = 32, learning_rate: float = 1e-3,
                   weight_decay: float = 1e-4, lr_decay: float = 0.95,
                   lr_decay_every: int = 50, seed: int = 0,
                   progress: Callable[[int], None] | None = None
                   ) -> tuple[EnsembleMLP, dict]:
    """Train an :class:`EnsembleMLP` (see the module docstring for the procedure).

    Runs single-threaded (:func:`single_thread`); the result does not depend
    on the thread count.

    Parameters
    ----------
    x_train : numpy.ndarray, shape (n_train, n_inputs)
        Standardised inputs.
    y_train : numpy.ndarray, shape (n_train,)
        Standardised target.
    x_val, y_val : numpy.ndarray or None
        Validation rows for early stopping; ``None`` trains ``max_epochs``
        epochs and keeps the last weights.
    weight_decay : float
        The paper's ``lambda`` in ``lambda ||theta||^2``.
    seed : int
        Seeds the one :class:`torch.Generator` behind initialisation, data
        order and dropout.
    progress : callable, optional
        Called with the number of finished epochs after each epoch.

    Returns
    -------
    net : EnsembleMLP
        In eval mode, with each member's best weights.
    history : dict
        ``train_loss`` and ``val_loss``, numpy arrays (n_epochs, M), NaN
        after a member stopped (it keeps computing in the batch, unrecorded);
        ``best_epoch`` and ``stopped_epoch`` (M,) int arrays (1-based epoch
        counts; ``stopped_epoch`` 0 = never stopped early); ``n_epochs``.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> x = rng.normal(size=(64, 3)); y = x[:, 0]
    >>> net, hist = train_ensemble(x[:48], y[:48], x[48:], y[48:], n_members=2, max_epochs=3)
    >>> hist["train_loss"].shape, hist["n_epochs"]
    ((3, 2), 3)
    """
    g = torch.Generator().manual_seed(int(seed))
    xt = torch.as_tensor(np.asarray(x_train), dtype=torch.float32)
    yt = torch.as_tensor(np.asarray(y_train), dtype=torch.float32)
    has_val = x_val is not None and len(x_val) > 0
    if has_val:
        xv = torch.as_tensor(np.asarray(x_val), dtype=torch.float32)
        yv = torch.as_tensor(np.asarray(y_val), dtype=torch.float32)
    m, n = int(n_members), xt.shape[0]
    net = EnsembleMLP(xt.shape[1], hidden, n_members=m, dropout=dropout,
                      heteroscedastic=heteroscedastic, generator=g)
    params = list(net.parameters())
    opt = torch.optim.Adam(params, lr=learning_rate, weight_decay=2.0 * weight_decay,
                           fused=True)
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=lr_decay_every, gamma=lr_decay)
    best = [p.detach().clone() for p in params]
    best_loss = torch.full((m,), math.inf)
    best_epoch = torch.zeros(m, dtype=torch.long)
    stopped_epoch = torch.zeros(m, dtype=torch.long)
    since = torch.zeros(m, dtype=torch.long)
    stopped = torch.zeros(m, dtype=torch.bool)
    train_hist, val_hist = [], []
    starts = range(0, n, int(batch_size))
    for epoch in range(1, int(max_epochs) + 1):
        net.train()
        perm = torch.argsort(torch.rand(m, n, generator=g), dim=1)
        xe, ye = xt[perm], yt[perm]  # (M, n, in), (M, n): each member its own order
        total = torch.zeros(m)
        for s in starts:
            mean, var = net(xe[:, s:s + batch_size], generator=g)
            loss = _loss(mean, var, ye[:, s:s + batch_size])
            opt.zero_grad(set_to_none=True)
            loss.sum().backward()
            opt.step()
            total += loss.detach() * mean.shape[1]
        sched.step()
        done = stopped.numpy().copy()  # members stopped in earlier epochs: no history
        train_hist.append(np.where(done, np.nan, (total / n).numpy()))
        net.eval()
        if not has_val:
            val_hist.append(np.full(m, np.nan, dtype=np.float32))
            best_epoch[:] = epoch
        else:
            with torch.no_grad():
                val = _loss(*net(xv), yv)
            val_hist.append(np.where(done, np.nan, val.numpy()))
            improved = (val < best_loss) & ~stopped
            if improved.any():
                with torch.no_grad():
                    for b, p in zip(best, params, strict=True):
                        b.copy_(torch.where(improved.view(-1, 1, 1), p, b))
                best_loss = torch.where(improved, val, best_loss)
                best_epoch = torch.where(improved, epoch, best_epoch)
            since = torch.where(improved, 0, since + 1)
            newly = (since >= patience) & ~stopped
            stopped_epoch = torch.where(newly, epoch, stopped_epoch)
            stopped |= newly
        if progress is not None:
            progress(epoch)
        if bool(stopped.all()):
            break
    if has_val:
        with torch.no_grad():
            for b, p in zip(best, params, strict=True):
                p.copy_(b)
    net.eval()
    history = {
        "train_loss": np.asarray(train_hist, dtype=np.float32).reshape(-1, m),
        "val_loss": np.asarray(val_hist, dtype=np.float32).reshape(-1, m),
        "best_epoch": best_epoch.numpy().copy(),
        "stopped_epoch": stopped_epoch.numpy().copy(),
        "n_epochs": len(train_hist),
    }
    return net, history
