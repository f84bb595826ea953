"""Tests of the QTG generator (spec/qtg.md §2-§6)."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.models.qtg import (QTGConfig, QTGState, _rollout_backward_per_step, _rollout_naive, count_parameters,
                                encode, init_params, init_state, macs_per_frame, param_shapes, rtn_macs_per_frame,
                                step)
from refimpl.models.qtg_fast import rollout_backward, rollout_forward
from refimpl.models.qtg_fast_inference import prepare_inference, rollout_inference
from refimpl.testing import TOL_EXACT, TOL_FD, assert_close

TINY = QTGConfig(pose_size=11, encoder_sizes=(6, 4), gru_hidden=5, decoder_sizes=(6,), transition_length=4)
TINY2 = QTGConfig(pose_size=11, encoder_sizes=(5,), gru_hidden=4, gru_layers=2, decoder_sizes=(),
                  negative_slope=0.2, transition_length=3)
TINY3 = QTGConfig(pose_size=11, encoder_sizes=(7, 6, 4), gru_hidden=3, gru_layers=3, decoder_sizes=(5, 6),
                  negative_slope=0.1, transition_length=5)
TINY4 = QTGConfig(pose_size=9, encoder_sizes=(6, 5), gru_hidden=4, gru_layers=2, decoder_sizes=(7,),
                  negative_slope=0.0, transition_length=4)


def _context(rng, B, P, dtype=np.float64):
    return rng.standard_normal((B, 2, P)).astype(dtype), rng.standard_normal((B, 2, P)).astype(dtype)


def test_default_sizes_and_names():
    """spec/qtg.md §2: reconstructed sizes, PyTorch names, parameter count."""
    cfg = QTGConfig()
    params = init_params(cfg, np.random.default_rng(0))
    assert params["enc.0.weight"].shape == (256, 91)
    assert params["enc.1.weight"].shape == (128, 256)
    assert params["gru.weight_ih_l0"].shape == (768, 384)
    assert params["gru.weight_hh_l0"].shape == (768, 256)
    assert params["vel.weight"].shape == (128, 256)
    assert params["dec.0.weight"].shape == (256, 128)
    assert params["dec.1.weight"].shape == (91, 256)
    assert {k: v.shape for k, v in params.items()} == param_shapes(cfg)
    assert count_parameters(cfg) == sum(v.size for v in params.values()) == 638_811
    assert all(v.dtype == np.float64 for v in params.values())
    p32 = init_params(cfg, np.random.default_rng(0), dtype=np.float32)
    assert all(v.dtype == np.float32 for v in p32.values())
    # PyTorch-default bounds
    assert np.abs(params["enc.0.weight"]).max() <= 1 / np.sqrt(91)
    assert np.abs(params["gru.weight_ih_l0"]).max() <= 1 / np.sqrt(256)


def test_op_counts():
    """spec/qtg.md §5: MACs per frame, ≈ 80 % fewer than RTN."""
    assert macs_per_frame(QTGConfig()) == 636_416
    assert rtn_macs_per_frame() == 3_133_696
    assert rtn_macs_per_frame(count_target_encoder=True) == 3_161_728
    ratio = macs_per_frame() / rtn_macs_per_frame()
    assert 0.19 < ratio < 0.21
    # a hand count of the tiny config: enc 11*6+6*4, GRU 3*5*(12+5), vel 5*4, dec 4*6+6*11
    assert macs_per_frame(TINY) == 66 + 24 + 255 + 20 + 24 + 66
    assert macs_per_frame(TINY2) == 11 * 5 + 3 * 4 * (15 + 4) + 3 * 4 * (4 + 4) + 4 * 5 + 5 * 11


@pytest.mark.parametrize("cfg", [TINY, TINY2])
def test_rollout_matches_naive_and_step(cfg):
    """spec/qtg.md §3: rollout_forward == per-sample loop from the equations == repeated step()."""
    rng = np.random.default_rng(1)
    params = init_params(cfg, rng)
    past, target = _context(rng, 3, cfg.pose_size)
    poses, _ = rollout_forward(params, past, target, 5, cfg)
    assert poses.shape == (3, 5, cfg.pose_size)
    assert_close(poses, _rollout_naive(params, past, target, 5, cfg), **TOL_EXACT, name="naive")
    state, tl = init_state(params, past, target, cfg)
    assert_close(state.latent_prev, encode(params, past[:, 0], cfg), **TOL_EXACT)
    assert_close(tl, encode(params, target, cfg), **TOL_EXACT)
    assert np.all(state.hidden == 0) and state.hidden.shape == (cfg.gru_layers, 3, cfg.gru_hidden)
    for t in range(5):
        pose_prev = state.pose
        p, state = step(params, state, tl, cfg)
        assert_close(p, poses[:, t], **TOL_EXACT, name=f"step {t}")
        assert_close(state.latent_prev, encode(params, pose_prev, cfg), **TOL_EXACT)
        assert state.pose is p


def test_default_length_and_float32():
    """spec/qtg.md §3: T defaults to config.transition_length; float32 stays float32."""
    rng = np.random.default_rng(2)
    params = init_params(TINY, rng, dtype=np.float32)
    past, target = _context(rng, 2, TINY.pose_size, np.float32)
    poses, _ = rollout_forward(params, past, target, config=TINY)
    assert poses.shape == (2, TINY.transition_length, 11) and poses.dtype == np.float32
    p64 = {k: v.astype(np.float64) for k, v in params.items()}
    ref, _ = rollout_forward(p64, past.astype(np.float64), target.astype(np.float64), config=TINY)
    assert_close(poses, ref, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("cfg", [TINY, TINY2, TINY3])
def test_whole_generator_gradients(cfg):
    """spec/qtg.md §4: BPTT through fed-back poses, latents, GRU state and target encodings.

    Central differences on every parameter and on both inputs, plus the vector-Jacobian identity."""
    rng = np.random.default_rng(3)
    params = init_params(cfg, rng)
    past, target = _context(rng, 2, cfg.pose_size)
    T = 4
    w = rng.standard_normal((2, T, cfg.pose_size))

    def loss():
        return float(np.sum(w * rollout_forward(params, past, target, T, cfg)[0]))

    poses, cache = rollout_forward(params, past, target, T, cfg)
    grads, dpast, dtarget = rollout_backward(w, cache, input_grads=True)
    assert set(grads) == set(params)
    assert rollout_backward(w, cache).keys() == grads.keys()
    arrays = dict(params, past=past, target=target)
    check_gradients(loss, arrays, dict(grads, past=dpast, target=dtarget), **TOL_FD, max_entries=None)

    def fn():
        return rollout_forward(params, past, target, T, cfg)[0]

    def vjp(ws):
        g, dp, dt = rollout_backward(ws[0], rollout_forward(params, past, target, T, cfg)[1], input_grads=True)
        return dict(g, past=dp, target=dt)

    check_vjp(fn, arrays, vjp)


@pytest.mark.parametrize("cfg, B, T", [(TINY, 3, 4), (TINY2, 2, 1), (TINY3, 2, 6), (TINY4, 1, 5), (QTGConfig(), 2, 3)])
def test_batched_backward_equals_per_step_oracle(cfg, B, T):
    """spec/qtg.md §4: weight gradients formed once over the stacked rows of all steps (and the context rows)
    equal the per-step formulation (every step's gradients formed and summed in the reverse loop), float64;
    float32 stays float32 and agrees to float32 rounding."""
    rng = np.random.default_rng(7)
    params = init_params(cfg, rng)
    past, target = _context(rng, B, cfg.pose_size)
    w = rng.standard_normal((B, T, cfg.pose_size))
    poses, cache = rollout_forward(params, past, target, T, cfg)
    grads, dpast, dtarget = rollout_backward(w, cache, input_grads=True)
    ref_poses, ref_grads, ref_dpast, ref_dtarget = _rollout_backward_per_step(params, past, target, w, cfg)
    assert_close(poses, ref_poses, **TOL_EXACT, name="poses")
    assert list(grads) == list(params) and set(ref_grads) == set(params)
    for k, g in grads.items():
        assert g.shape == params[k].shape and g.dtype == np.float64
        assert_close(g, ref_grads[k], **TOL_EXACT, name=k)
    assert_close(dpast, ref_dpast, **TOL_EXACT, name="dpast")
    assert_close(dtarget, ref_dtarget, **TOL_EXACT, name="dtarget")
    only = rollout_backward(w, cache)
    assert all(np.array_equal(only[k], grads[k]) for k in grads)

    p32 = {k: v.astype(np.float32) for k, v in params.items()}
    _, c32 = rollout_forward(p32, past.astype(np.float32), target.astype(np.float32), T, cfg)
    g32, dp32, dt32 = rollout_backward(w.astype(np.float32), c32, input_grads=True)
    assert dp32.dtype == dt32.dtype == np.float32
    for k, g in g32.items():
        assert g.dtype == np.float32
        scale = float(np.abs(grads[k]).max())
        assert_close(g, grads[k], rtol=1e-3, atol=1e-4 * max(scale, 1.0), name=f"float32 {k}")


def test_backward_leaves_cache_and_inputs_intact():
    """spec/qtg.md §4: rollout_backward reads its cache and dposes only (a second backward gives the same
    gradients); the returned poses are not a view of the cache."""
    rng = np.random.default_rng(8)
    params = init_params(TINY3, rng)
    past, target = _context(rng, 3, TINY3.pose_size)
    w = rng.standard_normal((3, 4, TINY3.pose_size))
    w_copy = w.copy()
    poses, cache = rollout_forward(params, past, target, 4, TINY3)
    first = rollout_backward(w, cache, input_grads=True)
    poses[...] = 0.0
    second = rollout_backward(w, cache, input_grads=True)
    assert np.array_equal(w, w_copy)
    for a, b in zip([*first[0].values(), *first[1:]], [*second[0].values(), *second[1:]]):
        assert np.array_equal(a, b)


def test_gradient_reaches_targets_and_past():
    """spec/qtg.md §4: the first frame depends on both past poses and both targets (no detached path)."""
    rng = np.random.default_rng(4)
    params = init_params(TINY, rng)
    past, target = _context(rng, 1, 11)
    _, cache = rollout_forward(params, past, target, 1, TINY)
    d = np.zeros((1, 1, 11))
    d[0, 0, 0] = 1.0
    _, dpast, dtarget = rollout_backward(d, cache, input_grads=True)
    for a in (dpast[0, 0], dpast[0, 1], dtarget[0, 0], dtarget[0, 1]):
        assert np.any(a != 0)


@pytest.mark.parametrize("cfg", [TINY, TINY2, TINY3, QTGConfig()])
def test_rollout_inference_equals_rollout_forward(cfg):
    """spec/qtg.md §6: the lean inference path computes the same function."""
    rng = np.random.default_rng(5)
    params = init_params(cfg, rng)
    past, target = _context(rng, 3, cfg.pose_size)
    ref, _ = rollout_forward(params, past, target, 7, cfg)
    out = rollout_inference(prepare_inference(params, cfg), past, target, 7)
    assert_close(out, ref, rtol=1e-9, atol=1e-11)
    p32 = {k: v.astype(np.float32) for k, v in params.items()}
    out32 = rollout_inference(prepare_inference(p32, cfg), past.astype(np.float32), target.astype(np.float32), 7)
    assert out32.dtype == np.float32
    assert_close(out32, ref, rtol=1e-3, atol=1e-4)


def test_inference_weights_are_read_only():
    """spec/qtg.md §6: prepared weights cannot be modified by accident."""
    model = prepare_inference(init_params(TINY, np.random.default_rng(0)), TINY)
    with pytest.raises(ValueError):
        model.z_product[0, 0] = 1.0


def test_bad_inputs():
    """Public boundaries raise ValueError naming the argument."""
    rng = np.random.default_rng(6)
    params = init_params(TINY, rng)
    past, target = _context(rng, 2, 11)
    with pytest.raises(ValueError, match="past"):
        rollout_forward(params, past[:, :1], target, 3, TINY)
    with pytest.raises(ValueError, match="target"):
        rollout_forward(params, past, target[:1], 3, TINY)
    bad = past.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="past"):
        rollout_forward(params, bad, target, 3, TINY)
    with pytest.raises(ValueError, match="dtype"):
        rollout_forward(params, past.astype(np.float32), target.astype(np.float32), 3, TINY)
    with pytest.raises(ValueError, match="T"):
        rollout_forward(params, past, target, 0, TINY)
    missing = dict(params)
    del missing["vel.bias"]
    with pytest.raises(ValueError, match="vel.bias"):
        rollout_forward(missing, past, target, 3, TINY)
    with pytest.raises(ValueError, match="enc.0.weight"):
        rollout_forward(params, past, target, 3, QTGConfig())
    with pytest.raises(ValueError, match="pose_size"):
        QTGConfig(pose_size=0)
    with pytest.raises(ValueError, match="negative_slope"):
        QTGConfig(negative_slope=1.5)
    state, tl = init_state(params, past, target, TINY)
    with pytest.raises(ValueError, match="state.hidden"):
        step(params, QTGState(state.latent_prev, state.pose, state.hidden[:, :1]), tl, TINY)
    with pytest.raises(ValueError, match="dposes"):
        _, cache = rollout_forward(params, past, target, 3, TINY)
        rollout_backward(np.zeros((2, 4, 11)), cache)
    nan = np.zeros((2, 3, 11))
    nan[1, 2, 3] = np.nan
    with pytest.raises(ValueError, match="dposes"):
        rollout_backward(nan, cache)
    with pytest.raises(ValueError, match="dposes: expected dtype"):
        rollout_backward(np.zeros((2, 3, 11), dtype=np.float32), cache)
    with pytest.raises(ValueError, match="model"):
        rollout_inference(params, past, target, 3)
