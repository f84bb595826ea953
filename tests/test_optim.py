"""Tests of refimpl.optim (spec/optim.md §1-§4): Adam and gradient clipping against the PyTorch golden vectors
and a naive oracle, in-place behaviour, dtype, validation, and learning-rate decay."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import refimpl.optim as optim
from conftest import load_golden
from refimpl.checkpoint import load_checkpoint, save_checkpoint
from refimpl.optim import (
    ACRNN_ADAM,
    QTG_ADAM,
    QUATERNET_ADAM,
    QUATERNET_CLIP_NORM,
    QUATERNET_LR_DECAY,
    _adam_step_naive,
    adam_init,
    adam_step,
    clip_grad_norm,
    exponential_lr,
)
from refimpl.testing import TOL_EXACT, TOL_GOLDEN, assert_close


def _params(rng, dtype=np.float64):
    return {"rnn.weight_ih_l0": rng.standard_normal((6, 5)).astype(dtype),
            "rnn.bias_ih_l0": rng.standard_normal(6).astype(dtype),
            "h0": rng.standard_normal((2, 1, 3)).astype(dtype),
            "scalar": np.array(0.5, dtype=dtype)}


def _copy(d):
    return {k: v.copy() for k, v in d.items()}


# ------------------------------------------------------------------------------------------------
# golden vectors (§1, §2)

@pytest.mark.parametrize("name", ["adam_default.npz", "adam_qtg.npz"])
def test_adam_golden(name):
    """spec/optim.md §1 vs torch.optim.Adam (default betas and QTG's (0.5, 0.9)): 5 steps, every step."""
    g = load_golden(name)
    params = {"p": g["in.p0"].copy()}
    state = adam_init(params)
    for i in range(g["in.grads"].shape[0]):
        adam_step(params, {"p": g["in.grads"][i]}, state, lr=float(g["meta.lr"]),
                  betas=tuple(float(b) for b in g["meta.betas"]), eps=float(g["meta.eps"]))
        assert_close(params["p"], g["out.params_after_each_step"][i], **TOL_GOLDEN, name=f"step {i + 1}")
    assert int(state["step"]) == g["in.grads"].shape[0]


def test_clip_grad_norm_golden():
    """spec/optim.md §2 vs torch.nn.utils.clip_grad_norm_([a, b], 0.1): returned norm and clipped gradients."""
    g = load_golden("clip_grad_norm_0p1.npz")
    grads = {"a": g["in.grad_a"].copy(), "b": g["in.grad_b"].copy()}
    total = clip_grad_norm(grads, float(g["meta.max_norm"]))
    assert abs(total - float(g["out.total_norm"])) <= 1e-12 * total
    assert_close(grads["a"], g["out.grad_a"], **TOL_GOLDEN)
    assert_close(grads["b"], g["out.grad_b"], **TOL_GOLDEN)


# ------------------------------------------------------------------------------------------------
# Adam against the naive oracle (§1)

@given(st.sampled_from([(0.9, 0.999), (0.5, 0.9), (0.0, 0.0), (0.6, 0.99)]), st.sampled_from([0.0, 0.1]),
       st.sampled_from([1, 3, 1000]), st.integers(0, 2**31 - 1))
def test_adam_matches_naive(betas, weight_decay, block, seed):
    """spec/optim.md §1: the blocked in-place kernel equals torch's formulas written plainly (several steps),
    for blocks smaller than, equal to and larger than the arrays (lerp branches β1 < 0.5 and >= 0.5)."""
    old_block = optim._BLOCK
    optim._BLOCK = block
    try:
        rng = np.random.default_rng(seed)
        p1 = _params(rng)
        p2 = _copy(p1)
        s1, s2 = adam_init(p1), adam_init(p2)
        for _ in range(3):
            grads = {k: rng.standard_normal(v.shape) for k, v in p1.items()}
            adam_step(p1, grads, s1, lr=1e-2, betas=betas, weight_decay=weight_decay)
            _adam_step_naive(p2, grads, s2, lr=1e-2, betas=betas, weight_decay=weight_decay)
        for k in p1:
            assert_close(p1[k], p2[k], rtol=1e-12, atol=1e-15, name=k)
            assert_close(s1["m." + k], s2["m." + k], rtol=1e-12, atol=1e-15)
            assert_close(s1["v." + k], s2["v." + k], rtol=1e-12, atol=1e-15)
    finally:
        optim._BLOCK = old_block


def test_adam_in_place_float32_and_strided():
    """spec/optim.md §1: arrays are updated in place (same objects), grads untouched, float32 stays float32,
    non-contiguous parameter views are handled."""
    rng = np.random.default_rng(1)
    params = _params(rng, np.float32)
    base = rng.standard_normal((6, 8)).astype(np.float32)
    params["strided"] = base[:, ::2]  # a non-contiguous view
    ids = {k: id(v) for k, v in params.items()}
    before = _copy(params)
    grads = {k: rng.standard_normal(v.shape).astype(np.float32) for k, v in params.items()}
    grads_before = _copy(grads)
    state = adam_init(params)
    adam_step(params, grads, state, **QUATERNET_ADAM)
    assert {k: id(v) for k, v in params.items()} == ids
    assert all(v.dtype == np.float32 for v in list(params.values()) + list(state.values())[1:])
    assert all(np.array_equal(grads[k], grads_before[k]) for k in grads)
    assert not np.array_equal(base[:, ::2], before["strided"])  # the view's base changed
    naive = _copy(before)
    _adam_step_naive(naive, grads, adam_init(naive), **QUATERNET_ADAM)
    for k in params:
        assert_close(params[k], naive[k], rtol=1e-5, atol=1e-7, name=k)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_adam_threads_give_identical_bits(dtype):
    """spec/optim.md §1: the blocks shared between threads give the same bits as one thread (many small blocks,
    a strided view, weight decay, several steps), and the default picks the same result."""
    old_block = optim._BLOCK
    optim._BLOCK = 7
    try:
        rng = np.random.default_rng(3)
        base = _params(rng, dtype)
        base["strided"] = rng.standard_normal((6, 8)).astype(dtype)[:, ::2]
        runs = {}
        for threads in (1, 2, 3, None):
            p = _copy(base)
            p["strided"] = base["strided"].base.copy()[:, ::2]
            state = adam_init(p)
            for step in range(3):
                g = {k: np.random.default_rng(10 + step).standard_normal(v.shape).astype(dtype) for k, v in p.items()}
                adam_step(p, g, state, lr=1e-2, weight_decay=0.01, threads=threads)
            runs[threads] = (p, state)
        for threads in (2, 3, None):
            for k in base:
                assert np.array_equal(runs[threads][0][k], runs[1][0][k]), (threads, k)
                assert np.array_equal(runs[threads][1]["v." + k], runs[1][1]["v." + k]), (threads, k)
        assert not np.array_equal(runs[1][0]["h0"], base["h0"])
    finally:
        optim._BLOCK = old_block


def test_adam_first_step_is_lr_sign():
    """spec/optim.md §1: with bias correction the first step moves each entry by lr·g/(|g| + eps) ≈ lr·sign(g)."""
    params = {"w": np.zeros(4)}
    g = np.array([3.0, -0.5, 1e-3, -2.0])
    adam_step(params, {"w": g}, adam_init(params), lr=0.1, eps=0.0)
    assert_close(params["w"], -0.1 * np.sign(g), **TOL_EXACT)


def test_adam_validation_leaves_state_untouched():
    """spec/optim.md §1: missing/extra keys, wrong shapes or dtypes, NaN/inf or overflowing gradients and bad
    hyper-parameters raise ValueError before anything is modified."""
    rng = np.random.default_rng(2)
    params = _params(rng, np.float32)
    state = adam_init(params)
    grads = {k: np.ones_like(v) for k, v in params.items()}
    snapshot = (_copy(params), _copy(state))
    bad_cases = [
        ({k: v for k, v in grads.items() if k != "h0"}, {}, "missing"),
        (dict(grads, extra=np.ones(2, np.float32)), {}, "unexpected"),
        (dict(grads, h0=np.ones((2, 3), np.float32)), {}, "h0"),
        (dict(grads, h0=np.ones((2, 1, 3))), {}, "dtype"),
        (dict(grads, h0=np.full((2, 1, 3), np.nan, np.float32)), {}, "NaN"),
        (dict(grads, h0=np.full((2, 1, 3), 1e20, np.float32)), {}, "overflow"),
        (grads, {"lr": -1.0}, "lr"),
        (grads, {"betas": (1.0, 0.9)}, "betas"),
        (grads, {"eps": math.nan}, "eps"),
        (grads, {"threads": 0}, "threads"),
        (grads, {"threads": 1.5}, "threads"),
    ]
    for g, kw, msg in bad_cases:
        with pytest.raises(ValueError, match=msg):
            adam_step(params, g, state, **{"lr": 1e-3, **kw})
    for k in params:
        assert np.array_equal(params[k], snapshot[0][k])
    for k in state:
        assert np.array_equal(state[k], snapshot[1][k])
    with pytest.raises(ValueError, match="state"):
        adam_step(params, grads, {}, lr=1e-3)


def test_adam_state_checkpoint_resume(tmp_path):
    """spec/optim.md §1, §5: the state dict goes through a checkpoint under 'optim.' and training resumes exactly."""
    rng = np.random.default_rng(3)
    params = _params(rng)
    state = adam_init(params)
    grads = [{k: rng.standard_normal(v.shape) for k, v in params.items()} for _ in range(4)]
    for g in grads[:2]:
        adam_step(params, g, state, **QTG_ADAM)
    save_checkpoint(tmp_path / "ck.npz", {**params, **{"optim." + k: v for k, v in state.items()}}, {"epoch": 2})
    arrays, meta = load_checkpoint(tmp_path / "ck.npz")
    p2 = {k: v for k, v in arrays.items() if not k.startswith("optim.")}
    s2 = {k[len("optim."):]: v for k, v in arrays.items() if k.startswith("optim.")}
    for g in grads[2:]:
        adam_step(params, g, state, **QTG_ADAM)
        adam_step(p2, g, s2, **QTG_ADAM)
    for k in params:
        assert np.array_equal(params[k], p2[k])
    assert int(s2["step"]) == 4 and meta == {"epoch": 2}


# ------------------------------------------------------------------------------------------------
# clipping (§2)

def test_clip_grad_norm_semantics():
    """spec/optim.md §2: coef = max_norm/(norm + 1e-6) applied only when < 1, in place, dtype kept."""
    g = {"a": np.array([3.0, 4.0], dtype=np.float32), "b": np.zeros((2, 2), dtype=np.float32)}
    assert clip_grad_norm(g, 10.0) == pytest.approx(5.0)
    assert np.array_equal(g["a"], np.array([3.0, 4.0], dtype=np.float32))  # not clipped
    a = g["a"]
    total = clip_grad_norm(g, 1.0)
    assert total == pytest.approx(5.0) and g["a"] is a and a.dtype == np.float32
    assert_close(a, np.array([3.0, 4.0]) / (5.0 + 1e-6), rtol=1e-6)
    assert clip_grad_norm({}, 1.0) == 0.0


def test_clip_grad_norm_extremes_and_nonfinite():
    """spec/optim.md §2: float32 gradients whose squares overflow, and denormal ones, give the exact norm;
    NaN/inf gradients raise ValueError naming the array."""
    big = {"a": np.full(100, 1e30, dtype=np.float32)}
    assert clip_grad_norm(big, QUATERNET_CLIP_NORM) == pytest.approx(1e31, rel=1e-6)
    assert_close(big["a"], np.full(100, 1e30 * 0.1 / 1e31), rtol=1e-5)
    tiny = {"a": np.full(4, 1e-300)}
    assert clip_grad_norm(tiny, 1.0) == pytest.approx(2e-300, rel=1e-12)
    with pytest.raises(ValueError, match="'b'"):
        clip_grad_norm({"a": np.ones(2), "b": np.array([1.0, np.inf])}, 1.0)
    with pytest.raises(ValueError, match="max_norm"):
        clip_grad_norm({"a": np.ones(2)}, -1.0)


# ------------------------------------------------------------------------------------------------
# decay and settings (§3, §4)

def test_exponential_lr_and_paper_settings():
    """spec/optim.md §3-§4: lr0·γ^epoch (QuaterNet: 1e-3 → 4.97e-5 after 3000 epochs); the papers' settings."""
    assert exponential_lr(1e-3, QUATERNET_LR_DECAY, 0) == 1e-3
    assert exponential_lr(1e-3, QUATERNET_LR_DECAY, 3000) == pytest.approx(4.97e-5, rel=1e-3)
    lr = 1e-3
    for _ in range(100):
        lr *= QUATERNET_LR_DECAY
    assert exponential_lr(1e-3, QUATERNET_LR_DECAY, 100) == pytest.approx(lr, rel=1e-13)
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="epoch"):
            exponential_lr(1e-3, 0.999, bad)
    assert QUATERNET_ADAM["lr"] == 1e-3 and QUATERNET_ADAM["betas"] == (0.9, 0.999)
    assert QUATERNET_CLIP_NORM == 0.1 and QUATERNET_LR_DECAY == 0.999
    assert QTG_ADAM["lr"] == 1e-4 and QTG_ADAM["betas"] == (0.5, 0.9)
    assert ACRNN_ADAM["lr"] == 1e-4 and ACRNN_ADAM["betas"] == (0.9, 0.999)
