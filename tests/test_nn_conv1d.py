"""Tests of refimpl.nn.conv1d (spec/layers.md §6): PyTorch golden vectors, the per-(b, t, k) loop oracle,
central differences, the vector-Jacobian identity, causality, dtypes, errors."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import load_golden
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.nn.conv1d import (_conv1d_causal_backward_naive, _conv1d_causal_forward_naive, conv1d_causal_backward,
                               conv1d_causal_forward, conv1d_init)
from refimpl.testing import TOL_EXACT, TOL_GOLDEN, assert_close


def _case(seed, batch, t_len, c_in, c_out, taps, dtype=np.float64):
    rng = np.random.default_rng(seed)
    params = conv1d_init(rng, c_in, c_out, taps, "conv", dtype)
    x = rng.standard_normal((batch, t_len, c_in)).astype(dtype)
    gy = rng.standard_normal((batch, t_len, c_out)).astype(dtype)
    return params, x, gy


# the golden set holds (K, d) = (2, 1), (2, 4), (3, 2); see tests/golden/README.md
@pytest.mark.parametrize("name", ["conv1d_causal_k2_d1", "conv1d_causal_k2_d4", "conv1d_causal_k3_d2"])
def test_golden(name):
    """spec/layers.md §6 vs PyTorch nn.Conv1d on the left-padded input: y and the gradients of x, weight, bias."""
    g = load_golden(f"{name}.npz")
    params = {"weight": g["param.weight"], "bias": g["param.bias"]}
    assert params["weight"].shape[2] == int(g["meta.kernel_size"])
    y, cache = conv1d_causal_forward(g["in.x"], params, "", int(g["meta.dilation"]))
    assert_close(y, g["out.y"], **TOL_GOLDEN, name="y")
    dx, grads = conv1d_causal_backward(g["in.gy"], cache)
    assert_close(dx, g["grad.x"], **TOL_GOLDEN, name="grad.x")
    assert_close(grads["weight"], g["grad.weight"], **TOL_GOLDEN, name="grad.weight")
    assert_close(grads["bias"], g["grad.bias"], **TOL_GOLDEN, name="grad.bias")


shapes = st.tuples(st.integers(0, 2**31 - 1), st.integers(1, 3), st.integers(1, 12), st.integers(1, 4),
                   st.integers(1, 4), st.integers(1, 4), st.integers(1, 4))


@given(shapes)
def test_matches_loop_oracle(case):
    """spec/layers.md §6: the one-GEMM convolution equals the per-(b, t, k) loop, forward and backward."""
    seed, batch, t_len, c_in, c_out, taps, dilation = case
    params, x, gy = _case(seed, batch, t_len, c_in, c_out, taps)
    y, cache = conv1d_causal_forward(x, params, "conv", dilation)
    assert_close(y, _conv1d_causal_forward_naive(x, params, "conv", dilation), **TOL_EXACT, name="y")
    dx, grads = conv1d_causal_backward(gy, cache)
    dx_ref, grads_ref = _conv1d_causal_backward_naive(gy, x, params, "conv", dilation)
    assert_close(dx, dx_ref, **TOL_EXACT, name="dx")
    for k in grads_ref:
        assert_close(grads[k], grads_ref[k], **TOL_EXACT, name=k)


@given(shapes)
def test_vjp_identity(case):
    """spec/layers.md §6: <J v, w> = <v, J^T w> w.r.t. x, weight and bias."""
    seed, batch, t_len, c_in, c_out, taps, dilation = case
    params, x, _ = _case(seed, batch, t_len, c_in, c_out, taps)

    def vjp(douts):
        dx, grads = conv1d_causal_backward(douts[0], conv1d_causal_forward(x, params, "conv", dilation)[1])
        return {"x": dx, **grads}

    check_vjp(lambda: conv1d_causal_forward(x, params, "conv", dilation)[0], {"x": x, **params}, vjp)


@pytest.mark.parametrize("taps,dilation", [(1, 1), (2, 3), (3, 2)])
def test_central_differences(taps, dilation):
    """spec/layers.md §6: every gradient entry against central differences."""
    params, x, gy = _case(4, 2, 7, 3, 2, taps)
    _, cache = conv1d_causal_forward(x, params, "conv", dilation)
    dx, grads = conv1d_causal_backward(gy, cache)
    check_gradients(lambda: float(np.sum(conv1d_causal_forward(x, params, "conv", dilation)[0] * gy)),
                    {"x": x, **params}, {"x": dx, **grads}, max_entries=None)


@pytest.mark.parametrize("taps,dilation", [(2, 1), (3, 2), (4, 3)])
def test_causal_receptive_field(taps, dilation):
    """spec/layers.md §6: y_t depends on exactly x_{t - (K-1) d}, ..., x_{t - d}, x_t (never on the future)."""
    params, x, _ = _case(5, 1, 14, 2, 3, taps)
    y, _ = conv1d_causal_forward(x, params, "conv", dilation)
    s = 3
    x2 = x.copy()
    x2[:, s] += 1.0
    y2, _ = conv1d_causal_forward(x2, params, "conv", dilation)
    changed = set(np.flatnonzero(np.any(y2 != y, axis=(0, 2))))
    assert changed == {s + k * dilation for k in range(taps) if s + k * dilation < 14}


def test_float32_stays_float32():
    """spec/architecture.md dtype rule: float32 in -> float32 out and gradients."""
    params, x, gy = _case(6, 2, 9, 3, 4, 3, dtype=np.float32)
    y, cache = conv1d_causal_forward(x, params, "conv", 2)
    dx, grads = conv1d_causal_backward(gy, cache)
    assert y.dtype == dx.dtype == np.float32
    assert all(g.dtype == np.float32 for g in grads.values())
    p64 = {k: v.astype(np.float64) for k, v in params.items()}
    assert_close(y, _conv1d_causal_forward_naive(x.astype(np.float64), p64, "conv", 2), rtol=1e-5, atol=1e-5)


def test_init_shapes_and_bound():
    """spec/layers.md §6: nn.Conv1d layout (C_out, C_in, K) and default init U(±1/sqrt(C_in K))."""
    p = conv1d_init(np.random.default_rng(0), 8, 5, 2, "tcn.0")
    assert p["tcn.0.weight"].shape == (5, 8, 2) and p["tcn.0.bias"].shape == (5,)
    assert max(np.abs(v).max() for v in p.values()) <= 0.25


def test_rejects_bad_input():
    """spec/architecture.md: ValueError naming the argument and the expected and actual shape / value."""
    params, x, gy = _case(1, 2, 5, 3, 4, 2)
    with pytest.raises(ValueError, match=r"x: expected shape \(\*, \*, 3\), got \(2, 5, 2\)"):
        conv1d_causal_forward(x[:, :, :2], params, "conv")
    with pytest.raises(ValueError, match="dilation"):
        conv1d_causal_forward(x, params, "conv", dilation=0)
    with pytest.raises(ValueError, match="missing parameter 'c.weight'"):
        conv1d_causal_forward(x, params, "c")
    with pytest.raises(ValueError, match="conv.weight: expected dtype float32"):
        conv1d_causal_forward(x.astype(np.float32), params, "conv")
    _, cache = conv1d_causal_forward(x, params, "conv")
    with pytest.raises(ValueError, match=r"dy: expected shape \(2, 5, 4\)"):
        conv1d_causal_backward(gy[:, :4], cache)
    for bad in (np.nan, np.inf, -np.inf):  # spec/robustness.md B13
        dy = gy.copy()
        dy[1, 3, 2] = bad
        with pytest.raises(ValueError, match=r"^dy: expected finite"):
            conv1d_causal_backward(dy, cache)
