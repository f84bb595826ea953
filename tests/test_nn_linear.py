"""Tests of refimpl.nn.linear (spec/layers.md §2) and the PyTorch golden MLP (QuaterNet's controls block,
spec/layers.md §2-§3)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from conftest import load_golden
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.nn.activations import leaky_relu_backward, leaky_relu_forward
from refimpl.nn.linear import matmul_wt, linear_backward, linear_forward, linear_init
from refimpl.nn.params import merge_grads
from refimpl.testing import TOL_EXACT, TOL_GOLDEN, assert_close

lead_shapes = st.lists(st.integers(1, 4), min_size=0, max_size=3).map(tuple)


def test_golden_mlp_leaky005():
    """spec/layers.md §2-§3 vs PyTorch: leaky_relu(fc2(leaky_relu(fc1(x), 0.05)), 0.05), outputs and all grads."""
    g = load_golden("mlp_leaky005.npz")
    params = {k[len("param."):]: v for k, v in g.items() if k.startswith("param.")}
    h1, c1 = linear_forward(g["in.x"], params, "fc1")
    a1, ca1 = leaky_relu_forward(h1, 0.05)
    h2, c2 = linear_forward(a1, params, "fc2")
    y, ca2 = leaky_relu_forward(h2, 0.05)
    assert_close(y, g["out.y"], **TOL_GOLDEN, name="y")
    dh2 = leaky_relu_backward(g["in.gy"], ca2)
    da1, grads2 = linear_backward(dh2, c2)
    dx, grads1 = linear_backward(leaky_relu_backward(da1, ca1), c1)
    grads = merge_grads(grads1, grads2)
    assert_close(dx, g["grad.x"], **TOL_GOLDEN, name="grad.x")
    assert sorted(grads) == sorted(params)
    for k in params:
        assert_close(grads[k], g["grad." + k], **TOL_GOLDEN, name="grad." + k)


@given(lead_shapes, st.integers(1, 5), st.integers(1, 5), st.booleans(), st.integers(0, 2**31 - 1))
def test_linear_vjp_and_formula(lead, n_in, n_out, bias, seed):
    """spec/layers.md §2: y = x W^T + b for any leading axes; vector-Jacobian identity of the backward."""
    rng = np.random.default_rng(seed)
    params = linear_init(rng, n_in, n_out, "fc", bias=bias)
    x = rng.standard_normal(lead + (n_in,))
    y, cache = linear_forward(x, params, "fc", bias=bias)
    expect = np.einsum("...i,oi->...o", x, params["fc.weight"]) + (params["fc.bias"] if bias else 0.0)
    assert_close(y, expect, **TOL_EXACT)
    arrays = {"x": x, **params}

    def vjp(douts):
        dx, grads = linear_backward(douts[0], linear_forward(x, params, "fc", bias=bias)[1])
        return {"x": dx, **grads}

    check_vjp(lambda: linear_forward(x, params, "fc", bias=bias)[0], arrays, vjp)


def test_linear_central_differences():
    """spec/layers.md §2: every gradient against central differences (3 leading axes)."""
    rng = np.random.default_rng(1)
    params = linear_init(rng, 4, 3, "head")
    x = rng.standard_normal((2, 3, 4))
    gy = rng.standard_normal((2, 3, 3))
    y, cache = linear_forward(x, params, "head")
    dx, grads = linear_backward(gy, cache)
    check_gradients(lambda: float(np.sum(linear_forward(x, params, "head")[0] * gy)),
                    {"x": x, **params}, {"x": dx, **grads}, max_entries=None)


def test_linear_float32_stays_float32():
    """spec/architecture.md dtype rule: float32 in -> float32 out and float32 gradients."""
    rng = np.random.default_rng(2)
    params = linear_init(rng, 5, 3, "", dtype=np.float32)
    x = rng.standard_normal((4, 5)).astype(np.float32)
    y, cache = linear_forward(x, params, "")
    dx, grads = linear_backward(np.ones_like(y), cache)
    assert y.dtype == dx.dtype == np.float32
    assert all(g.dtype == np.float32 for g in grads.values())
    assert set(grads) == {"weight", "bias"}


def test_linear_init_shapes_and_bound():
    """spec/layers.md §2: nn.Linear default init U(±1/sqrt(in)); PyTorch names and (out, in) layout."""
    p = linear_init(np.random.default_rng(3), 100, 7, "fc")
    assert p["fc.weight"].shape == (7, 100) and p["fc.bias"].shape == (7,)
    assert np.abs(p["fc.weight"]).max() <= 0.1 and np.abs(p["fc.weight"]).max() > 0.08
    assert set(linear_init(np.random.default_rng(3), 2, 2, "fc", bias=False)) == {"fc.weight"}


def test_matmul_wt_kernel():
    """spec/layers.md §2: the internal kernel x @ W^T that reads W in its stored layout."""
    rng = np.random.default_rng(4)
    a, w = rng.standard_normal((6, 5)), rng.standard_normal((3, 5))
    assert_close(matmul_wt(a, w), a @ w.T, **TOL_EXACT)
    out = np.empty((6, 3))
    assert matmul_wt(a, w, out=out) is out and out.flags.c_contiguous
    assert_close(out, a @ w.T, **TOL_EXACT)


def test_linear_rejects_bad_input():
    """spec/architecture.md: ValueError naming the argument and the expected and actual shape / dtype."""
    params = linear_init(np.random.default_rng(5), 4, 3, "fc")
    with pytest.raises(ValueError, match=r"x: expected shape \(\.\.\., 4\), got \(2, 5\)"):
        linear_forward(np.zeros((2, 5)), params, "fc")
    with pytest.raises(ValueError, match="missing parameter 'fc2.weight'"):
        linear_forward(np.zeros((2, 4)), params, "fc2")
    with pytest.raises(ValueError, match="fc.weight: expected dtype float32"):
        linear_forward(np.zeros((2, 4), np.float32), params, "fc")
    with pytest.raises(ValueError, match="finite"):
        linear_forward(np.full((2, 4), np.inf), params, "fc")
    with pytest.raises(ValueError, match="missing parameter 'fc.bias'"):
        linear_forward(np.zeros((2, 4)), {"fc.weight": params["fc.weight"]}, "fc")


def test_linear_backward_refuses_bad_upstream_gradient():
    """spec/layers.md §2, spec/robustness.md B13: dy with NaN/inf, of the wrong shape (even one with the right
    number of entries) or not float → ValueError naming dy."""
    params = linear_init(np.random.default_rng(6), 4, 3, "fc")
    _, cache = linear_forward(np.ones((2, 5, 4)), params, "fc")
    for bad in (np.nan, np.inf, -np.inf):
        dy = np.ones((2, 5, 3))
        dy[1, 4, 2] = bad
        with pytest.raises(ValueError, match=r"^dy: expected finite"):
            linear_backward(dy, cache)
    with pytest.raises(ValueError, match=r"^dy: expected shape \(2, 5, 3\), got \(10, 3\)"):
        linear_backward(np.ones((10, 3)), cache)
    with pytest.raises(ValueError, match=r"^dy: expected shape \(2, 5, 3\), got \(2, 5, 4\)"):
        linear_backward(np.ones((2, 5, 4)), cache)
    with pytest.raises(ValueError, match=r"^dy: expected a float32 or float64 array"):
        linear_backward(np.ones((2, 5, 3), int), cache)
