"""Tests of the QuaterNet recurrent pose network (spec/quaternet.md §1-§4)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.losses import quat_norm_loss_backward, quat_norm_loss_forward
from refimpl.models.quaternet import (QuaterNetConfig, check_params, count_parameters, init_params, init_state,
                                      param_shapes, predict, step)
from refimpl.models.quaternet_sequence import _backward_per_step, _forward_per_step, backward, forward
from refimpl.dualquat import dq_from_quat_translation, dq_mul, dq_normalize
from refimpl.quat import quat_mul, quat_normalize
from refimpl.schedules import scheduled_sampling_mask
from refimpl.testing import TOL_EXACT, TOL_FD, assert_close

# tiny configurations covering the published modes
VEL = QuaterNetConfig(num_joints=2, hidden_size=4)  # short-term shape: velocity, no extras
ABS_LT = QuaterNetConfig(num_joints=2, num_outputs=2, num_controls=3, velocity=False, hidden_size=4,
                         controls_hidden=5)  # long-term shape: absolute, translations, controls
VEL_LT = QuaterNetConfig(num_joints=2, num_outputs=1, num_controls=2, velocity=True, hidden_size=3, num_layers=1,
                         controls_hidden=3, negative_slope=0.2)
# the dual-quaternion variants (Andreou et al. §6.2, spec/quaternet.md §9): 8 numbers per joint
DQ_VEL = QuaterNetConfig(num_joints=2, hidden_size=4, representation="dual_quaternion")
DQ_ABS_LT = QuaterNetConfig(num_joints=2, num_outputs=2, num_controls=3, velocity=False, hidden_size=4,
                            controls_hidden=5, representation="dual_quaternion")
CONFIGS = [VEL, ABS_LT, VEL_LT, DQ_VEL, DQ_ABS_LT]


def _frames(rng, cfg, B, n, dtype=np.float64):
    """Random frames: unit quaternions (or unit dual quaternions) per joint, then translations and controls."""
    x = rng.standard_normal((B, n, cfg.input_size))
    R, J = cfg.rotation_size, cfg.num_joints
    q = quat_normalize(x[..., :4 * J].reshape(B, n, J, 4))
    if cfg.joint_width == 8:
        q = dq_from_quat_translation(q, x[..., 4 * J:R].reshape(B, n, J, 4)[..., :3])
    x[..., :R] = q.reshape(B, n, R)
    return x.astype(dtype)


def _normalized_blocks(cfg, a):
    """Eq. 13 for dual quaternions, plain normalisation for quaternions, on (..., D) blocks."""
    return dq_normalize(a) if cfg.joint_width == 8 else quat_normalize(a)


def _product(cfg, a, b):
    return dq_mul(a, b) if cfg.joint_width == 8 else quat_mul(a, b)


def _published_names(num_controls: int) -> set[str]:
    """State-dict keys of the published model (reference/quaternet_reference_code.md §4.4)."""
    names = {"h0", "fc.weight", "fc.bias"}
    for k in (0, 1):
        names |= {f"rnn.weight_ih_l{k}", f"rnn.weight_hh_l{k}", f"rnn.bias_ih_l{k}", f"rnn.bias_hh_l{k}"}
    if num_controls:
        names |= {"fc1.weight", "fc1.bias", "fc2.weight", "fc2.bias"}
    return names


def test_paper_sizes_names_and_counts():
    """spec/quaternet.md §2: published names and shapes; 9,526,128 (short-term) and 9,529,246 (long-term)."""
    st, lt = QuaterNetConfig(), QuaterNetConfig.long_term()
    assert st == QuaterNetConfig.short_term() and st.velocity and not lt.velocity
    assert (st.input_size, st.gru_input_size, st.output_size) == (128, 128, 128)
    assert (lt.input_size, lt.gru_input_size, lt.output_size) == (112, 136, 106)
    assert count_parameters(st) == 9_526_128
    assert count_parameters(lt) == 9_529_246
    for J in (22, 26, 31):  # spec/quaternet.md §2: per-joint growth 4 (3H + H + 1) with the long-term extras
        assert count_parameters(QuaterNetConfig.long_term(num_joints=J)) == 9_529_246 + 4 * 4001 * (J - 26)
    # dual quaternions (spec/quaternet.md §9): 8J instead of 4J in the GRU input and the head
    dq = QuaterNetConfig(representation="dual_quaternion")
    assert (dq.input_size, dq.output_size) == (256, 256)
    assert count_parameters(dq) == 9_526_128 + 3 * 1000 * 128 + 128 * 1001 == 10_038_256
    with pytest.raises(ValueError, match="representation"):
        QuaterNetConfig(representation="euler")
    assert QuaterNetConfig(**dq.to_dict()) == dq
    # the hand arithmetic of spec/quaternet.md §2
    assert count_parameters(st) == 3 * 1000 * (128 + 1000) + 6000 + 3 * 1000 * 2000 + 6000 + 2000 + 128 * 1001
    ss, sl = param_shapes(st), param_shapes(lt)
    assert set(ss) == _published_names(0) and set(sl) == _published_names(6)
    assert ss["h0"] == (2, 1, 1000) and ss["rnn.weight_ih_l0"] == (3000, 128) and ss["fc.weight"] == (128, 1000)
    assert sl["rnn.weight_ih_l0"] == (3000, 136) and sl["fc.weight"] == (106, 1000)
    assert sl["fc1.weight"] == (30, 6) and sl["fc2.weight"] == (30, 30)
    for cfg in (st, lt):  # allocated at float32 (~38 MB): the same count, names and shapes
        p = init_params(cfg, np.random.default_rng(0), dtype=np.float32)
        assert sum(v.size for v in p.values()) == count_parameters(cfg)
        assert {k: v.shape for k, v in p.items()} == param_shapes(cfg)
        assert all(v.dtype == np.float32 for v in p.values())
        assert check_params(p, cfg) == np.float32
        # PyTorch-default bounds, h0 ~ N(0, 0.01²)
        assert np.abs(p["rnn.weight_hh_l1"]).max() <= 1 / np.sqrt(1000)
        assert np.abs(p["fc.weight"]).max() <= 1 / np.sqrt(1000)
        assert 0.008 < p["h0"].std() < 0.012
        if cfg.num_controls:
            assert np.abs(p["fc1.weight"]).max() <= 1 / np.sqrt(6) and np.abs(p["fc1.weight"]).max() > 0.35
        del p


@pytest.mark.parametrize("cfg", CONFIGS)
def test_forward_equals_loop_of_steps(cfg):
    """spec/quaternet.md §3: the vectorised-prefix sequence forward == every frame through the public step()."""
    rng = np.random.default_rng(1)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, 3, 4), _frames(rng, cfg, 3, 6)
    for mask in (np.ones(5, bool), np.zeros(5, bool), np.array([True, False, False, True, False]),
                 np.array([True, True, False, True, True]), np.array([False, True, True, True, False])):
        y, pre, _ = forward(params, prefix, future, mask, cfg)
        assert y.shape == (3, 6, cfg.output_size) and pre.shape == (3, 6, cfg.rotation_size)
        assert_close(y, _forward_per_step(params, prefix, future, mask, cfg), **TOL_EXACT, name=str(mask))
        q = y[..., :cfg.rotation_size].reshape(3, 6, cfg.num_joints, cfg.joint_width)
        assert_close(np.linalg.norm(q[..., :4], axis=-1), np.ones((3, 6, cfg.num_joints)), **TOL_EXACT)
        if cfg.joint_width == 8:  # Eq. 3: <q_r, q_d> = 0
            assert_close(np.sum(q[..., :4] * q[..., 4:], axis=-1), np.zeros((3, 6, cfg.num_joints)), **TOL_EXACT)


@pytest.mark.parametrize("cfg", CONFIGS)
def test_predict_equals_free_running_forward(cfg):
    """spec/quaternet.md §4: predict (built on step) == forward with an all-False mask (ground-truth controls)."""
    rng = np.random.default_rng(2)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, 2, 3), _frames(rng, cfg, 2, 5)
    y, _, _ = forward(params, prefix, future, np.zeros(4, bool), cfg)
    G = cfg.output_size
    controls = future[:, :4, G:] if cfg.num_controls else None
    assert_close(predict(params, prefix, 5, cfg, controls=controls), y, **TOL_EXACT)
    assert predict(params, prefix, 1, cfg, controls=future[:, :0, G:] if cfg.num_controls else None).shape == (2, 1, G)


@pytest.mark.parametrize("cfg", [VEL, VEL_LT, ABS_LT, DQ_VEL, DQ_ABS_LT])
def test_velocity_mode_is_qmul_with_the_fed_input(cfg):
    """§3.6: velocity mode y_q = normalize(Δ ⊗ q_in), q_in = the fed frame's quaternion; absolute: normalize(Δ).
    Dual quaternions (spec/quaternet.md §9): the dual-quaternion product and Eq. 13."""
    rng = np.random.default_rng(3)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, 2, 3), _frames(rng, cfg, 2, 4)
    mask = np.array([True, False, True])
    y, pre, _ = forward(params, prefix, future, mask, cfg)
    J, R, D = cfg.num_joints, cfg.rotation_size, cfg.joint_width
    fed = [prefix[:, -1]] + [future[:, i] if mask[i] else y[:, i] for i in range(3)]
    for t in range(4):
        delta = pre[:, t].reshape(2, J, D)
        q_in = fed[t][:, :R].reshape(2, J, D)
        expected = _normalized_blocks(cfg, _product(cfg, delta, q_in) if cfg.velocity else delta)
        assert_close(y[:, t, :R].reshape(2, J, D), expected, **TOL_EXACT, name=f"t={t}")
    # translations are the raw head outputs: the same as with a zero rotation part of the fed frame
    if cfg.num_outputs:
        h = init_state(params, 2, cfg)
        for t in range(3):
            _, h = step(params, h, prefix[:, t], cfg)
        top = h[-1]
        assert_close(y[:, 0, R:], top @ params["fc.weight"][R:].T + params["fc.bias"][R:], **TOL_EXACT)


def test_scheduled_sampling_mask_semantics():
    """spec/quaternet.md §3.1: mask[i] True feeds future[:, i]; False feeds y_i plus future[:, i]'s controls."""
    cfg = ABS_LT
    rng = np.random.default_rng(4)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, 2, 3), _frames(rng, cfg, 2, 5)
    G = cfg.output_size
    mask = np.array([True, False, True, False])
    y, _, _ = forward(params, prefix, future, mask, cfg)
    # all True = teacher forcing: the predictions of one step() pass over the ground-truth frames
    yt, _, _ = forward(params, prefix, future, np.ones(4, bool), cfg)
    h = init_state(params, 2, cfg)
    frames = np.concatenate([prefix, future[:, :4]], axis=1)
    outs = []
    for t in range(frames.shape[1]):
        o, h = step(params, h, frames[:, t], cfg)
        outs.append(o)
    assert_close(yt, np.stack(outs, axis=1)[:, 2:], **TOL_EXACT)
    # a replaced frame's pose/translations do not matter; its controls do; the last future frame is never fed
    for i, ground_truth in enumerate(mask):
        f2 = future.copy()
        f2[:, i, :G] += 0.3
        changed = not np.allclose(forward(params, prefix, f2, mask, cfg)[0], y)
        assert changed == bool(ground_truth)
        f3 = future.copy()
        f3[:, i, G:] += 0.3
        y3 = forward(params, prefix, f3, mask, cfg)[0]
        assert_close(y3[:, :i + 1], y[:, :i + 1], **TOL_EXACT)  # causal
        assert not np.allclose(y3[:, i + 1], y[:, i + 1])
    f4 = future.copy()
    f4[:, -1] += 1.0
    assert_close(forward(params, prefix, f4, mask, cfg)[0], y, **TOL_EXACT)
    # the schedule's mask plugs in directly (T - 1 decisions, one per step, shared by the batch)
    m = scheduled_sampling_mask(0.5, 4, np.random.default_rng(0))
    forward(params, prefix, future, m, cfg)


def _loss_and_backward(cfg, rng, mask, B=2, P=3, T=4):
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, B, P), _frames(rng, cfg, B, T)
    w = rng.standard_normal((B, T, cfg.output_size))
    wp = rng.standard_normal((B, T, cfg.rotation_size))

    def loss():
        y, pre, _ = forward(params, prefix, future, mask, cfg)
        return float(np.sum(w * y) + np.sum(wp * pre))

    _, _, cache = forward(params, prefix, future, mask, cfg)
    grads, dprefix, dfuture = backward(w, wp, cache, input_grads=True)
    return params, prefix, future, loss, grads, dprefix, dfuture


@pytest.mark.parametrize("cfg", CONFIGS)
@pytest.mark.parametrize("mask", [[False, False, False], [True, False, True], [True, True, True], [True, True, False]])
def test_gradients_central_differences(cfg, mask):
    """spec/quaternet.md §3.2: BPTT through fed-back predictions (no detach), the QMul's q_in, controls, h0.

    Every parameter entry and every input entry (prefix, future) against float64 central differences."""
    mask = np.array(mask)
    rng = np.random.default_rng(5)
    params, prefix, future, loss, grads, dprefix, dfuture = _loss_and_backward(cfg, rng, mask)
    assert set(grads) == set(params)
    assert all(grads[k].shape == params[k].shape for k in params)
    arrays = dict(params, prefix=prefix, future=future)
    check_gradients(loss, arrays, dict(grads, prefix=dprefix, future=dfuture), **TOL_FD, max_entries=None)
    G = cfg.output_size
    assert np.all(dfuture[:, -1] == 0)  # the last future frame is only a target
    for i, gt in enumerate(mask):
        if not gt:  # replaced by the prediction: only its controls are read
            assert np.all(dfuture[:, i, :G] == 0)


@pytest.mark.parametrize("cfg", [VEL, ABS_LT])
def test_gradients_vjp_identity_and_norm_penalty(cfg):
    """spec/quaternet.md §3.2: vector-Jacobian identity on (y, pre) jointly; the norm penalty through dpre."""
    rng = np.random.default_rng(6)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, 2, 3), _frames(rng, cfg, 2, 5)
    mask = np.array([False, True, False, False])
    arrays = dict(params, prefix=prefix, future=future)

    def fn():
        y, pre, _ = forward(params, prefix, future, mask, cfg)
        return y, pre

    def vjp(ws):
        _, _, cache = forward(params, prefix, future, mask, cfg)
        g, dp, df = backward(ws[0], ws[1], cache, input_grads=True)
        return dict(g, prefix=dp, future=df)

    check_vjp(fn, arrays, vjp)

    # the training loss shape: a loss on y plus 0.01 * the norm penalty on pre (dy only, then dpre = None path)
    def penalty_loss():
        y, pre, _ = forward(params, prefix, future, mask, cfg)
        return float(np.sum(y ** 2) + 0.01 * quat_norm_loss_forward(pre.reshape(2, 5, cfg.num_joints, 4))[0])

    y, pre, cache = forward(params, prefix, future, mask, cfg)
    _, pc = quat_norm_loss_forward(pre.reshape(2, 5, cfg.num_joints, 4))
    dpre = 0.01 * quat_norm_loss_backward(1.0, pc).reshape(pre.shape)
    grads = backward(2 * y, dpre, cache)
    check_gradients(penalty_loss, params, grads, **TOL_FD, max_entries=40)
    g_none = backward(2 * y, None, cache)
    g_zero = backward(2 * y, np.zeros_like(pre), cache)
    for k in g_none:
        assert_close(g_none[k], g_zero[k], **TOL_EXACT)


def test_single_frame_target_and_float32():
    """T = 1 (no decisions), P = 1; float32 parameters and inputs stay float32."""
    cfg = ABS_LT
    rng = np.random.default_rng(7)
    p32 = init_params(cfg, rng, dtype=np.float32)
    prefix, future = _frames(rng, cfg, 2, 1, np.float32), _frames(rng, cfg, 2, 1, np.float32)
    y, pre, cache = forward(p32, prefix, future, np.zeros(0, bool), cfg)
    assert y.dtype == np.float32 and pre.dtype == np.float32 and y.shape == (2, 1, cfg.output_size)
    grads = backward(np.ones_like(y), None, cache)
    assert all(g.dtype == np.float32 for g in grads.values())
    p64 = {k: v.astype(np.float64) for k, v in p32.items()}
    y64, _, _ = forward(p64, prefix.astype(np.float64), future.astype(np.float64), np.zeros(0, bool), cfg)
    assert_close(y, y64, rtol=1e-4, atol=1e-5)
    s, h = step(p32, init_state(p32, 2, cfg), prefix[:, 0], cfg)
    assert s.dtype == np.float32 and h.dtype == np.float32
    assert_close(s, y[:, 0], **TOL_EXACT)


def test_input_validation():
    """Public boundaries raise ValueError naming the argument."""
    cfg = VEL
    rng = np.random.default_rng(8)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, 2, 3), _frames(rng, cfg, 2, 4)
    with pytest.raises(ValueError, match="mask"):
        forward(params, prefix, future, np.ones(4, bool), cfg)  # T - 1 = 3 decisions
    with pytest.raises(ValueError, match="mask"):
        forward(params, prefix, future, np.ones(3), cfg)  # not bool
    with pytest.raises(ValueError, match="future"):
        forward(params, prefix, future[:1], np.ones(3, bool), cfg)
    with pytest.raises(ValueError, match="prefix"):
        forward(params, prefix[..., :5], future, np.ones(3, bool), cfg)
    with pytest.raises(ValueError, match="missing parameter 'h0'"):
        forward({k: v for k, v in params.items() if k != "h0"}, prefix, future, np.ones(3, bool), cfg)
    with pytest.raises(ValueError, match="unexpected"):
        check_params(dict(params, extra=np.zeros(1)), cfg)
    with pytest.raises(ValueError, match="fc.weight"):
        check_params(dict(params, **{"fc.weight": np.zeros((3, 4))}), cfg)
    with pytest.raises(ValueError, match="state"):
        step(params, np.zeros((1, 2, 4)), prefix[:, 0], cfg)
    with pytest.raises(ValueError, match="dtype"):
        step(params, init_state(params, 2, cfg), prefix[:, 0].astype(np.float32), cfg)
    with pytest.raises(ValueError, match="controls"):
        predict(init_params(ABS_LT, rng), _frames(rng, ABS_LT, 2, 3), 3, ABS_LT)
    with pytest.raises(ValueError, match="k"):
        predict(params, prefix, 0, cfg)
    with pytest.raises(ValueError, match="num_joints"):
        QuaterNetConfig(num_joints=0)
    with pytest.raises(ValueError, match="config"):
        init_params("short", np.random.default_rng(0))
    with pytest.raises(ValueError, match="rng"):
        init_params(cfg, 0)
    _, _, cache = forward(params, prefix, future, np.ones(3, bool), cfg)
    with pytest.raises(ValueError, match="dy"):
        backward(np.ones((2, 3, 8)), None, cache)
    assert QuaterNetConfig(**QuaterNetConfig.long_term().to_dict()) == QuaterNetConfig.long_term()


_configs = st.builds(QuaterNetConfig, num_joints=st.integers(1, 2), num_outputs=st.integers(0, 2),
                     num_controls=st.integers(0, 2), velocity=st.booleans(), hidden_size=st.integers(1, 4),
                     num_layers=st.integers(1, 3), controls_hidden=st.integers(1, 3),
                     negative_slope=st.sampled_from([0.0, 0.05, 0.3]),
                     representation=st.sampled_from(["quaternion", "dual_quaternion"]))


@given(_configs, st.integers(1, 3), st.integers(1, 4), st.integers(1, 3), st.integers(0, 2**31 - 1))
def test_property_forward_step_oracle_and_vjp(cfg, P, T, B, seed):
    """Hypothesis over configs and lengths: forward == per-step oracle; the VJP identity on every param/input."""
    rng = np.random.default_rng(seed)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, B, P), _frames(rng, cfg, B, T)
    mask = rng.random(T - 1) < 0.5
    y, pre, _ = forward(params, prefix, future, mask, cfg)
    assert_close(y, _forward_per_step(params, prefix, future, mask, cfg), **TOL_EXACT)

    def fn():
        return forward(params, prefix, future, mask, cfg)[:2]

    def vjp(ws):
        g, dp, df = backward(ws[0], ws[1], forward(params, prefix, future, mask, cfg)[2], input_grads=True)
        return dict(g, prefix=dp, future=df)

    check_vjp(fn, dict(params, prefix=prefix, future=future), vjp, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("cfg", CONFIGS)
@pytest.mark.parametrize("mask", [[False, True, False, False], [True, True, False, True], [False, True, True, True],
                                  [True, True, True, True], [True, False, True, True]])
def test_backward_equals_per_step_oracle(cfg, mask):
    """spec/quaternet.md §3.2: the vectorised backward (prefix and runs of teacher-forced steps) == every frame
    back-propagated one step at a time; the masks put runs at the start, the end, before a fed-back step."""
    rng = np.random.default_rng(9)
    params = init_params(cfg, rng)
    prefix, future = _frames(rng, cfg, 2, 4), _frames(rng, cfg, 2, 5)
    mask = np.array(mask)
    y, pre, cache = forward(params, prefix, future, mask, cfg)
    assert_close(y, _forward_per_step(params, prefix, future, mask, cfg), **TOL_EXACT, name="y")
    dy, dpre = rng.standard_normal(y.shape), rng.standard_normal(pre.shape)
    for dp in (dpre, None):
        grads, dprefix, dfuture = backward(dy, dp, cache, input_grads=True)
        g2, dprefix2, dfuture2 = _backward_per_step(dy, dp, params, prefix, future, mask, cfg)
        assert set(g2) == set(grads)
        for k in grads:
            assert_close(grads[k], g2[k], **TOL_EXACT, name=k)
        assert_close(dprefix, dprefix2, **TOL_EXACT, name="dprefix")
        assert_close(dfuture, dfuture2, **TOL_EXACT, name="dfuture")
