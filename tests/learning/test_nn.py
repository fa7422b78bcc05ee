"""Tests of the batched-ensemble residual network and its training."""

import numpy as np
import pytest
import torch

from hybridev.learning.nn import VARIANCE_FLOOR, EnsembleMLP, n_parameters, train_ensemble


def _gen(seed=0):
    return torch.Generator().manual_seed(seed)


def _data(n=300, seed=0):
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, 4)).astype(np.float32)
    y = (np.sin(2.0 * x[:, 0]) + 0.5 * x[:, 1] * x[:, 2] + 0.05 * rng.normal(size=n))
    return x, y.astype(np.float32)


def test_parameter_count_of_the_paper_network():
    # 10-64-32-16-1: 704 + 2080 + 528 + 17 (the paper's "~5,400" is wrong).
    assert n_parameters(10) == 3329
    net = EnsembleMLP(10, generator=_gen())
    assert sum(p.numel() for p in net.parameters()) == 3329 == net.n_parameters_per_member
    # The 11 inputs the paper actually lists; 3 members; a variance head.
    net3 = EnsembleMLP(11, n_members=3, heteroscedastic=True, generator=_gen())
    assert sum(p.numel() for p in net3.parameters()) == 3 * (3393 + 17)


def test_forward_shapes_and_variance_floor():
    net = EnsembleMLP(5, n_members=4, heteroscedastic=True, generator=_gen()).eval()
    mean, var = net(torch.randn(7, 5, generator=_gen(1)))
    assert mean.shape == var.shape == (4, 7)
    assert bool((var >= VARIANCE_FLOOR).all())
    mean2, _ = net(torch.randn(4, 3, 5, generator=_gen(1)))  # one batch per member
    assert mean2.shape == (4, 3)


def test_batched_members_equal_separate_networks():
    net = EnsembleMLP(3, hidden=(8, 6), n_members=3, generator=_gen()).eval()
    x = torch.randn(10, 3, generator=_gen(2))
    mean, _ = net(x)
    for m in range(3):
        h = x
        for i, (w, b) in enumerate(zip(net.weights, net.biases, strict=True)):
            h = h @ w[m] + b[m, 0]
            if i < 2:
                h = torch.relu(h)
        torch.testing.assert_close(mean[m], h[:, 0])
    assert not torch.equal(mean[0], mean[1])  # members differ in initialisation


def test_dropout_only_in_training_mode_and_seeded():
    net = EnsembleMLP(3, n_members=2, dropout=0.5, generator=_gen())
    x = torch.randn(20, 3, generator=_gen(3))
    net.train()
    a, _ = net(x, generator=_gen(5))
    b, _ = net(x, generator=_gen(5))
    c, _ = net(x, generator=_gen(6))
    torch.testing.assert_close(a, b)
    assert not torch.equal(a, c)
    net.eval()
    torch.testing.assert_close(net(x)[0], net(x, generator=_gen(9))[0])


def test_training_is_deterministic_per_seed():
    x, y = _data()
    kw = dict(n_members=2, max_epochs=5)
    n1, h1 = train_ensemble(x[:240], y[:240], x[240:], y[240:], seed=3, **kw)
    n2, h2 = train_ensemble(x[:240], y[:240], x[240:], y[240:], seed=3, **kw)
    n3, _ = train_ensemble(x[:240], y[:240], x[240:], y[240:], seed=4, **kw)
    for p, q in zip(n1.parameters(), n2.parameters(), strict=True):
        assert torch.equal(p, q)
    np.testing.assert_array_equal(h1["val_loss"], h2["val_loss"])
    assert not torch.equal(n1.weights[0], n3.weights[0])


def test_training_learns_and_restores_each_members_best_weights():
    x, y = _data(400)
    net, hist = train_ensemble(x[:320], y[:320], x[320:], y[320:], n_members=3,
                               max_epochs=60, patience=5, seed=0)
    assert hist["train_loss"].shape == hist["val_loss"].shape == (hist["n_epochs"], 3)
    # Learned: validation MSE well below the target variance (about 0.8).
    assert np.nanmin(hist["val_loss"]) < 0.35 * float(np.var(y[320:]))
    with torch.no_grad():
        mean, _ = net(torch.from_numpy(x[320:]))
    val_now = ((mean - torch.from_numpy(y[320:])) ** 2).mean(dim=1).numpy()
    # Restored weights are the ones of each member's best epoch.
    np.testing.assert_allclose(val_now, np.nanmin(hist["val_loss"], axis=0), rtol=1e-5)
    best = hist["best_epoch"]
    np.testing.assert_array_equal(best, np.nanargmin(hist["val_loss"], axis=0) + 1)
    stopped = hist["stopped_epoch"]
    assert np.all((stopped == 0) | (stopped == best + 5))
    # No history after a member stopped.
    for m in np.flatnonzero(stopped):
        assert np.isnan(hist["val_loss"][stopped[m]:, m]).all()
        assert np.isfinite(hist["val_loss"][:stopped[m], m]).all()


def test_early_stopping_ends_training_when_all_members_stopped():
    x, y = _data(200)
    # With patience 3 the noisy validation loss soon fails to improve 3 epochs running.
    _, hist = train_ensemble(x[:160], y[:160], x[160:], y[160:], n_members=2, max_epochs=200,
                             patience=3, learning_rate=1e-2, seed=0)
    assert hist["n_epochs"] < 200
    assert hist["n_epochs"] == hist["stopped_epoch"].max()
    assert np.all(hist["stopped_epoch"] > 0)


def test_l2_penalty_shrinks_weights():
    x, y = _data(200)
    norms = []
    for lam in (0.0, 0.05):
        net, _ = train_ensemble(x, y, None, None, max_epochs=15, weight_decay=lam, seed=1)
        norms.append(sum(float((p.detach()**2).sum()) for p in net.parameters()))
    assert norms[1] < 0.8 * norms[0]


def test_heteroscedastic_training_learns_the_noise_level():
    rng = np.random.default_rng(0)
    x = rng.uniform(-1, 1, size=(1000, 1)).astype(np.float32)
    sd = np.where(x[:, 0] > 0, 1.0, 0.1)
    y = (sd * rng.normal(size=1000)).astype(np.float32)
    net, _ = train_ensemble(x, y, None, None, heteroscedastic=True, max_epochs=30, seed=0)
    with torch.no_grad():
        _, var = net(torch.tensor([[-0.5], [0.5]]))
    ratio = float(var[0, 1] / var[0, 0])
    # True variance ratio 100; the tolerance is a factor 3 either way.
    assert 33 < ratio < 300


def test_no_validation_keeps_last_epoch_and_thread_count_is_restored():
    torch.set_num_threads(2)
    x, y = _data(64)
    _, hist = train_ensemble(x, y, None, None, max_epochs=4, seed=0)
    assert hist["n_epochs"] == 4 and np.isnan(hist["val_loss"]).all()
    assert torch.get_num_threads() == 2


def test_arrays_roundtrip_and_shape_errors():
    net = EnsembleMLP(4, n_members=2, generator=_gen())
    arrays = net.to_arrays()
    assert all(a.dtype == np.float32 for a in arrays.values())
    other = EnsembleMLP(4, n_members=2, generator=_gen(7))
    other.load_arrays(arrays)
    for p, q in zip(net.parameters(), other.parameters(), strict=True):
        assert torch.equal(p, q)
    with pytest.raises(ValueError, match="'w0' has shape"):
        EnsembleMLP(5, n_members=2).load_arrays(arrays)
    del arrays["b3"]
    with pytest.raises(ValueError, match="'b3' is missing"):
        other.load_arrays(arrays)
