"""Tests of refimpl.nn.activations (spec/layers.md §3)."""
from __future__ import annotations

import re
import warnings

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.nn.activations import (sigmoid, leaky_relu_backward, leaky_relu_forward, relu_backward, relu_forward,
                                    sigmoid_backward, sigmoid_forward, tanh_backward, tanh_forward)
from refimpl.testing import TOL_EXACT, assert_close

# values bounded away from the rectifiers' kink at 0, so central differences are valid
away_from_zero = st.floats(0.01, 5.0).flatmap(lambda m: st.sampled_from([m, -m]))
arrays = hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=3, max_side=4), elements=away_from_zero)

LAYERS = {
    "leaky_relu": (lambda x: leaky_relu_forward(x, 0.05), leaky_relu_backward),
    "leaky_relu_default": (leaky_relu_forward, leaky_relu_backward),
    "relu": (relu_forward, relu_backward),
    "tanh": (tanh_forward, tanh_backward),
    "sigmoid": (sigmoid_forward, sigmoid_backward),
}
FORMULAS = {
    "leaky_relu": lambda x: np.where(x > 0, x, 0.05 * x),
    "leaky_relu_default": lambda x: np.where(x > 0, x, 0.01 * x),
    "relu": lambda x: np.maximum(x, 0),
    "tanh": np.tanh,
    "sigmoid": lambda x: 1 / (1 + np.exp(-x)),
}


@pytest.mark.parametrize("name", sorted(LAYERS))
@given(x=arrays)
def test_activation_values_and_vjp(name, x):
    """spec/layers.md §3: forward formula and the vector-Jacobian identity of the backward."""
    fwd, bwd = LAYERS[name]
    y, cache = fwd(x)
    assert_close(y, FORMULAS[name](x), rtol=1e-14, atol=1e-15, name=name)
    check_vjp(lambda: fwd(x)[0], {"x": x}, lambda d: {"x": bwd(d[0], fwd(x)[1])})


@pytest.mark.parametrize("name", sorted(LAYERS))
def test_activation_central_differences(name):
    """spec/layers.md §3: every entry of the gradient against central differences."""
    fwd, bwd = LAYERS[name]
    rng = np.random.default_rng(0)
    x = rng.standard_normal((3, 4))
    x[np.abs(x) < 0.05] = 0.5
    gy = rng.standard_normal((3, 4))
    dx = bwd(gy, fwd(x)[1])
    check_gradients(lambda: float(np.sum(fwd(x)[0] * gy)), {"x": x}, {"x": dx}, max_entries=None)


@pytest.mark.parametrize("name", sorted(LAYERS))
def test_activation_float32_stays_float32(name):
    """spec/architecture.md dtype rule: float32 in -> float32 out and gradient."""
    fwd, bwd = LAYERS[name]
    x = np.linspace(-3, 3, 12, dtype=np.float32).reshape(3, 4)
    y, cache = fwd(x)
    assert y.dtype == np.float32
    assert bwd(np.ones_like(y), cache).dtype == np.float32


def test_rectifier_derivative_at_zero_is_left_derivative():
    """spec/layers.md §3: at x == 0 the rectifiers use slope (leaky) / 0 (relu), as PyTorch."""
    x = np.zeros(3)
    assert_close(leaky_relu_backward(np.ones(3), leaky_relu_forward(x, 0.05)[1]), np.full(3, 0.05), **TOL_EXACT)
    assert_close(relu_backward(np.ones(3), relu_forward(x)[1]), np.zeros(3), **TOL_EXACT)


def test_sigmoid_extremes_without_warnings():
    """spec/layers.md §3: the kernel sigmoid saturates to exactly 0 / 1 without overflow warnings, float32 and
    float64."""
    for dt in (np.float32, np.float64):
        x = np.array([-1e4, -100.0, 0.0, 100.0, 1e4], dtype=dt)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            y = sigmoid(x)
        assert y.dtype == dt
        assert y[0] == 0 and y[-1] == 1 and y[2] == 0.5
        assert np.all(np.isfinite(y))


def test_sigmoid_in_place_and_accuracy():
    """spec/layers.md §3: ``sigmoid(x, out=x)``; relative accuracy everywhere, including the tails, against an
    extended-precision evaluation."""
    x = np.linspace(-700, 30, 2001)
    xl = x.astype(np.longdouble)
    expect = (1 / (1 + np.exp(-xl))).astype(np.float64)
    y = x.copy()
    assert sigmoid(y, out=y) is y
    assert_close(y, expect, rtol=2e-15, atol=0.0)


def test_activations_reject_non_finite_and_non_float():
    """spec/architecture.md: NaN/inf or integer inputs raise ValueError naming x."""
    for fwd in (relu_forward, tanh_forward, sigmoid_forward, leaky_relu_forward):
        with pytest.raises(ValueError, match="x: expected finite"):
            fwd(np.array([0.0, np.nan]))
        with pytest.raises(ValueError, match="x: expected a float32 or float64"):
            fwd(np.array([1, 2]))


@pytest.mark.parametrize("name", sorted(LAYERS))
def test_backward_refuses_bad_upstream_gradient(name):
    """spec/layers.md §3, spec/robustness.md B13: dy with NaN/inf, of the wrong shape (even a broadcastable one)
    or not float → ValueError naming dy."""
    fwd, bwd = LAYERS[name]
    y, cache = fwd(np.linspace(-1, 1, 6).reshape(2, 3))
    for bad in (np.nan, np.inf, -np.inf):
        dy = np.ones((2, 3))
        dy[1, 2] = bad
        with pytest.raises(ValueError, match=r"^dy: expected finite"):
            bwd(dy, cache)
    for shape in ((2, 4), (3,), (1, 3), ()):
        with pytest.raises(ValueError, match=rf"^dy: expected shape \(2, 3\), got {re.escape(str(shape))}"):
            bwd(np.ones(shape), cache)
    with pytest.raises(ValueError, match=r"^dy: expected a float32 or float64 array"):
        bwd(np.ones((2, 3), int), cache)
    y0, cache0 = fwd(np.float64(0.5))  # 0-d input: 0-d dy
    assert np.shape(bwd(np.float64(2.0), cache0)) == ()
