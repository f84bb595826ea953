"""Tests of the convolutional QuaterNet (spec/quaternet.md §5)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.models.quaternet_cnn import (QuaterNetCNNConfig, _forward_naive, backward, backward_scheduled,
                                          check_params, count_parameters, forward, forward_scheduled, init_params,
                                          init_stream_state, param_shapes, predict, step, stream_step)
from refimpl.quat import quat_mul, quat_normalize
from refimpl.testing import TOL_EXACT, TOL_FD, assert_close

# small configurations: receptive fields 8 (K = 2, d = 1, 2, 4) and 6 (W = 3 last), every activation, skips
RELU = QuaterNetCNNConfig(num_joints=2, channels=5, kernel_sizes=(2, 2, 2, 2), dilations=(1, 2, 4, 8),
                          skips=((0, 2),))
TANH = QuaterNetCNNConfig(num_joints=2, channels=4, kernel_sizes=(2, 2, 2, 2, 2), dilations=(1, 2, 4, 8, 16),
                          activation="tanh")
LEAKY_ABS = QuaterNetCNNConfig(num_joints=1, channels=6, kernel_sizes=(2, 2, 3), dilations=(1, 2, 4), skips=(),
                               activation="leaky_relu", negative_slope=0.1, velocity=False)
LINEAR = QuaterNetCNNConfig(num_joints=2, channels=3, kernel_sizes=(2, 1, 2), dilations=(1, 1, 2),
                            skips=((0, 1),), activation="none")
CONFIGS = [RELU, TANH, LEAKY_ABS, LINEAR]


def _frames(rng, cfg, B, T):
    return quat_normalize(rng.standard_normal((B, T, cfg.num_joints, 4))).reshape(B, T, cfg.rotation_size)


def test_paper_size_and_count():
    """spec/quaternet.md §5.2: 6,819,968 params at J = 32, C = 1024, W = 2 (R = 32); 6,951,040 with W = 3 last."""
    cfg = QuaterNetCNNConfig()
    assert cfg.receptive_field == 32 and cfg.num_layers == 5
    assert cfg.layer_channels == [(128, 1024), (1024, 1024), (1024, 1024), (1024, 1024), (1024, 128)]
    shapes = param_shapes(cfg)
    assert shapes["convs.0.weight"] == (1024, 128, 2) and shapes["convs.4.weight"] == (128, 1024, 2)
    assert count_parameters(cfg) == (128 * 2 * 1024 + 1024) + 3 * (1024 * 2 * 1024 + 1024) + (1024 * 2 * 128 + 128)
    assert count_parameters(cfg) == 6_819_968
    w3 = QuaterNetCNNConfig(kernel_sizes=(2, 2, 2, 2, 3))
    assert w3.receptive_field == 48 and count_parameters(w3) == 6_951_040
    assert QuaterNetCNNConfig(kernel_sizes=(2, 2, 2, 2, 1)).receptive_field == 16  # Fig. 2
    p = init_params(cfg, np.random.default_rng(0), dtype=np.float32)
    assert sum(v.size for v in p.values()) == 6_819_968 and check_params(p, cfg) == np.float32
    assert np.abs(p["convs.1.weight"]).max() <= 1 / np.sqrt(2048)
    del p


@pytest.mark.parametrize("cfg", CONFIGS)
def test_vectorised_equals_naive_and_window_steps(cfg):
    """spec/quaternet.md §5.1, §5.4: conv-kernel forward == per-frame/per-tap loop == window step() per frame."""
    rng = np.random.default_rng(1)
    params = init_params(cfg, rng)
    x = _frames(rng, cfg, 2, 3 * cfg.receptive_field)
    y, pre, _ = forward(params, x, cfg)
    assert_close(y, _forward_naive(params, x, cfg), **TOL_EXACT, name="naive")
    for t in range(x.shape[1]):
        assert_close(step(params, x[:, :t + 1], cfg), y[:, t], **TOL_EXACT, name=f"step t={t}")
    assert_close(np.linalg.norm(y.reshape(2, -1, cfg.num_joints, 4), axis=-1),
                 np.ones((2, x.shape[1], cfg.num_joints)), **TOL_EXACT)


@pytest.mark.parametrize("cfg", [RELU, TANH, LEAKY_ABS])
def test_velocity_mode_is_qmul_with_the_input(cfg):
    """§3.2: velocity mode y_t = normalize(Δ_t ⊗ x_t) per joint; absolute mode normalize(Δ_t)."""
    rng = np.random.default_rng(2)
    params = init_params(cfg, rng)
    x = _frames(rng, cfg, 2, 9)
    y, pre, _ = forward(params, x, cfg)
    J = cfg.num_joints
    d, q = pre.reshape(2, 9, J, 4), x.reshape(2, 9, J, 4)
    expected = quat_normalize(quat_mul(d, q) if cfg.velocity else d)
    assert_close(y.reshape(2, 9, J, 4), expected, **TOL_EXACT)


@pytest.mark.parametrize("cfg", [RELU, TANH, LEAKY_ABS])
def test_causality_and_receptive_field(cfg):
    """A change at frame t leaves every output before t unchanged; the output at t' depends on t iff
    t' - R < t <= t' (tested on the generic tanh / leaky configs; ReLU: only the 'unchanged' half)."""
    rng = np.random.default_rng(3)
    params = init_params(cfg, rng)
    R = cfg.receptive_field
    T = 2 * R + 3
    x = _frames(rng, cfg, 2, T)
    y, _, _ = forward(params, x, cfg)
    for t in (0, 1, R // 2, R, T - 1):
        x2 = x.copy()
        x2[:, t] = _frames(rng, cfg, 2, 1)[:, 0]
        y2, _, _ = forward(params, x2, cfg)
        assert np.array_equal(y2[:, :t], y[:, :t]), f"output before {t} changed"
        assert not np.allclose(y2[:, t], y[:, t])
        if cfg.activation != "relu":
            changed = [not np.array_equal(y2[:, s], y[:, s]) for s in range(T)]
            assert changed == [t <= s < t + R for s in range(T)]


@pytest.mark.parametrize("cfg", CONFIGS)
def test_teacher_forced_gradients(cfg):
    """spec/quaternet.md §5.1: central differences on every parameter and input entry; VJP identity on (y, pre)."""
    rng = np.random.default_rng(4)
    params = init_params(cfg, rng)
    x = _frames(rng, cfg, 2, 7)
    w = rng.standard_normal((2, 7, cfg.rotation_size))
    wp = rng.standard_normal((2, 7, cfg.rotation_size))

    def loss():
        y, pre, _ = forward(params, x, cfg)
        return float(np.sum(w * y) + np.sum(wp * pre))

    _, _, cache = forward(params, x, cfg)
    grads, dx = backward(w, wp, cache, input_grads=True)
    assert set(grads) == set(params)
    check_gradients(loss, dict(params, x=x), dict(grads, x=dx), **TOL_FD, max_entries=None)

    def fn():
        return forward(params, x, cfg)[:2]

    def vjp(ws):
        g, d = backward(ws[0], ws[1], forward(params, x, cfg)[2], input_grads=True)
        return dict(g, x=d)

    check_vjp(fn, dict(params, x=x), vjp)
    g_none = backward(w, None, cache)
    g_zero = backward(w, np.zeros_like(w), cache)
    assert all(np.array_equal(g_none[k], g_zero[k]) for k in g_none)


@pytest.mark.parametrize("cfg", [RELU, TANH])
def test_scheduled_sampling_forward(cfg):
    """spec/quaternet.md §5.3: mask semantics; all-True = teacher forcing; all-False = predict(); per-step oracle."""
    rng = np.random.default_rng(5)
    params = init_params(cfg, rng)
    P, T = 5, 6
    prefix, future = _frames(rng, cfg, 2, P), _frames(rng, cfg, 2, T)
    y_tf, _, _ = forward(params, np.concatenate([prefix, future[:, :T - 1]], axis=1), cfg)
    y, _, _ = forward_scheduled(params, prefix, future, np.ones(T - 1, bool), cfg)
    assert_close(y, y_tf[:, P - 1:], **TOL_EXACT)
    y0, _, _ = forward_scheduled(params, prefix, future, np.zeros(T - 1, bool), cfg)
    assert_close(y0, predict(params, prefix, T, cfg), **TOL_EXACT)
    mask = np.array([True, False, False, True, False])
    ym, pre, cache = forward_scheduled(params, prefix, future, mask, cfg)
    # per-step oracle: build the fed sequence with step() and compare every prediction
    fed = list(prefix.transpose(1, 0, 2))
    outs = [step(params, np.stack(fed, axis=1), cfg)]
    for i in range(T - 1):
        fed.append(future[:, i] if mask[i] else outs[-1])
        outs.append(step(params, np.stack(fed, axis=1), cfg))
    assert_close(ym, np.stack(outs, axis=1), **TOL_EXACT)
    assert_close(cache["fed"], np.stack(fed, axis=1), **TOL_EXACT)  # P + T - 1 fed frames
    # a replaced ground-truth frame does not matter; a fed one does
    for i, gt in enumerate(mask):
        f2 = future.copy()
        f2[:, i] = _frames(rng, cfg, 2, 1)[:, 0]
        assert (not np.allclose(forward_scheduled(params, prefix, f2, mask, cfg)[0], ym)) == bool(gt)


@pytest.mark.parametrize("cfg", [RELU, TANH, LEAKY_ABS])
def test_scheduled_sampling_gradient_first_term_only(cfg):
    """spec/quaternet.md §5.3: the gradient equals central differences of the loss with the fed-back
    predictions frozen (held at their values), and differs from the full derivative when predictions are fed."""
    rng = np.random.default_rng(6)
    params = init_params(cfg, rng)
    P, T = 4, 5
    prefix, future = _frames(rng, cfg, 2, P), _frames(rng, cfg, 2, T)
    mask = np.array([False, True, False, False])
    w = rng.standard_normal((2, T, cfg.rotation_size))
    wp = rng.standard_normal((2, T, cfg.rotation_size))
    y, pre, cache = forward_scheduled(params, prefix, future, mask, cfg)
    grads, dprefix, dfuture = backward_scheduled(w, wp, cache, input_grads=True)
    assert set(grads) == set(params)
    fed = cache["fed"].copy()  # frozen fed sequence: replaced frames are constants, the rest read from inputs
    replaced = np.concatenate([np.zeros(P, bool), ~mask])

    def frozen_loss():
        s = np.concatenate([prefix, future[:, :T - 1]], axis=1)
        s[:, replaced] = fed[:, replaced]
        yy, pp, _ = forward(params, s, cfg)
        return float(np.sum(w * yy[:, P - 1:]) + np.sum(wp * pp[:, P - 1:]))

    check_gradients(frozen_loss, dict(params, prefix=prefix, future=future),
                    dict(grads, prefix=dprefix, future=dfuture), **TOL_FD, max_entries=None)
    assert np.all(dfuture[:, -1] == 0) and np.all(dfuture[:, :T - 1][:, ~mask] == 0)

    def full_loss():
        yy, pp, _ = forward_scheduled(params, prefix, future, mask, cfg)
        return float(np.sum(w * yy) + np.sum(wp * pp))

    from refimpl.gradcheck import numerical_gradient
    full = numerical_gradient(full_loss, params["convs.0.weight"])
    assert not np.allclose(full, grads["convs.0.weight"], rtol=1e-4, atol=1e-6)  # the second term is dropped
    # with every step teacher-forced both are the same
    ones = np.ones(T - 1, bool)
    g1 = backward_scheduled(w, wp, forward_scheduled(params, prefix, future, ones, cfg)[2])

    def tf_loss():
        yy, pp, _ = forward_scheduled(params, prefix, future, ones, cfg)
        return float(np.sum(w * yy) + np.sum(wp * pp))

    check_gradients(tf_loss, params, g1, **TOL_FD, max_entries=30)


def test_float32_and_validation():
    cfg = RELU
    rng = np.random.default_rng(7)
    p32 = init_params(cfg, rng, dtype=np.float32)
    x = _frames(rng, cfg, 2, 6).astype(np.float32)
    y, pre, cache = forward(p32, x, cfg)
    assert y.dtype == np.float32 and pre.dtype == np.float32
    assert all(g.dtype == np.float32 for g in backward(np.ones_like(y), None, cache).values())
    p64 = {k: v.astype(np.float64) for k, v in p32.items()}
    assert_close(y, forward(p64, x.astype(np.float64), cfg)[0], rtol=1e-4, atol=1e-5)
    params = p64
    x = x.astype(np.float64)
    with pytest.raises(ValueError, match="x"):
        forward(params, x[..., :5], cfg)
    with pytest.raises(ValueError, match="dtype"):
        forward(params, x.astype(np.float32), cfg)
    with pytest.raises(ValueError, match="mask"):
        forward_scheduled(params, x[:, :3], x[:, :3], np.ones(3, bool), cfg)
    with pytest.raises(ValueError, match="mask"):
        forward_scheduled(params, x[:, :3], x[:, :3], np.ones(2, int), cfg)
    with pytest.raises(ValueError, match="missing"):
        forward({k: v for k, v in params.items() if k != "convs.0.bias"}, x, cfg)
    with pytest.raises(ValueError, match="unexpected"):
        check_params(dict(params, h0=np.zeros(1)), cfg)
    with pytest.raises(ValueError, match="window"):
        step(params, x[:, :0], cfg)
    with pytest.raises(ValueError, match="k"):
        predict(params, x, 0, cfg)
    with pytest.raises(ValueError, match="skips"):
        QuaterNetCNNConfig(skips=((0, 4),))  # 1024 -> 4J channels differ
    with pytest.raises(ValueError, match="skips"):
        QuaterNetCNNConfig(skips=((2, 1),))
    with pytest.raises(ValueError, match="activation"):
        QuaterNetCNNConfig(activation="gelu")
    with pytest.raises(ValueError, match="kernel_sizes"):
        QuaterNetCNNConfig(kernel_sizes=(2, 2), dilations=(1,))
    with pytest.raises(ValueError, match="dy"):
        backward(np.ones((2, 5, 8)), None, forward(params, x, cfg)[2])
    assert QuaterNetCNNConfig(**QuaterNetCNNConfig().to_dict()) == QuaterNetCNNConfig()



@st.composite
def _cnn_configs(draw):
    n = draw(st.integers(2, 4))
    ks = tuple(draw(st.integers(1, 3)) for _ in range(n))
    ds = tuple(draw(st.integers(1, 3)) for _ in range(n))
    candidates = [(s, k) for k in range(1, n - 1) for s in range(k)]  # C -> C layers only
    skips = tuple(draw(st.lists(st.sampled_from(candidates), unique=True, max_size=2))) if candidates else ()
    return QuaterNetCNNConfig(num_joints=draw(st.integers(1, 2)), channels=draw(st.integers(1, 4)), kernel_sizes=ks,
                              dilations=ds, skips=skips, activation=draw(st.sampled_from(["relu", "leaky_relu",
                                                                                          "tanh", "none"])),
                              negative_slope=0.2, velocity=draw(st.booleans()))


@given(_cnn_configs(), st.integers(1, 9), st.integers(0, 2**31 - 1))
def test_property_naive_causal_vjp(cfg, T, seed):
    """Hypothesis over layer counts, widths, dilations, skips, activations: forward == per-frame loop; outputs
    before a changed frame unchanged; step() == forward per frame; the VJP identity on every param and x."""
    rng = np.random.default_rng(seed)
    params = init_params(cfg, rng)
    x = _frames(rng, cfg, 2, T)
    y, _, _ = forward(params, x, cfg)
    assert_close(y, _forward_naive(params, x, cfg), **TOL_EXACT)
    t = int(rng.integers(T))
    x2 = x.copy()
    x2[:, t] = _frames(rng, cfg, 2, 1)[:, 0]
    assert np.array_equal(forward(params, x2, cfg)[0][:, :t], y[:, :t])
    assert_close(step(params, x[:, :t + 1], cfg), y[:, t], **TOL_EXACT)

    def fn():
        return forward(params, x, cfg)[:2]

    def vjp(ws):
        g, d = backward(ws[0], ws[1], forward(params, x, cfg)[2], input_grads=True)
        return dict(g, x=d)

    check_vjp(fn, dict(params, x=x), vjp, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("cfg", CONFIGS)
def test_stream_step_equals_forward(cfg):
    """spec/quaternet.md §5.4: the incremental per-layer-buffer step over a sequence == the vectorised forward,
    from the zero state (= causal padding); a free-running stream == predict()."""
    rng = np.random.default_rng(8)
    params = init_params(cfg, rng)
    x = _frames(rng, cfg, 2, 2 * cfg.receptive_field + 1)
    y, _, _ = forward(params, x, cfg)
    state = init_stream_state(params, 2, cfg)
    assert [b.shape[1] for b in state] == [(k - 1) * d for k, d in zip(cfg.kernel_sizes, cfg.dilations)]
    for t in range(x.shape[1]):
        s_old = [b.copy() for b in state]
        out, state2 = stream_step(params, state, x[:, t], cfg)
        assert all(np.array_equal(a, b) for a, b in zip(state, s_old))  # not modified in place
        state = state2
        assert_close(out, y[:, t], **TOL_EXACT, name=f"t={t}")
    prefix = x[:, :5]
    state = init_stream_state(params, 2, cfg)
    for t in range(5):
        out, state = stream_step(params, state, prefix[:, t], cfg)
    outs = [out]
    for _ in range(3):
        out, state = stream_step(params, state, out, cfg)
        outs.append(out)
    assert_close(np.stack(outs, axis=1), predict(params, prefix, 4, cfg), **TOL_EXACT)
    with pytest.raises(ValueError, match="state"):
        stream_step(params, state[:-1], x[:, 0], cfg)
    with pytest.raises(ValueError, match=r"state\[0\]"):
        stream_step(params, (np.zeros((3, 1, 8)),) + tuple(state[1:]), x[:, 0], cfg)
