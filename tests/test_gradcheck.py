"""The gradient oracles and comparison helpers themselves (spec/architecture.md, refimpl/gradcheck.py).

An oracle that cannot fail is worthless, so each check is shown to pass on a correct gradient and to fail on a
wrong one.
"""
import numpy as np
import pytest

from refimpl.gradcheck import check_gradients, check_vjp, numerical_gradient
from refimpl.testing import assert_close, assert_quat_close


def _setup():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((4, 3))
    x = rng.standard_normal(3)
    return A, x


def test_numerical_gradient_matches_closed_form():
    A, x = _setup()
    f = lambda: float(np.sum(np.tanh(A @ x) ** 2))  # noqa: E731
    g = numerical_gradient(f, x)
    t = np.tanh(A @ x)
    expected = A.T @ (2 * t * (1 - t ** 2))
    assert_close(g, expected, rtol=1e-7, atol=1e-9)


def test_numerical_gradient_rejects_float32():
    with pytest.raises(ValueError, match="float64"):
        numerical_gradient(lambda: 0.0, np.zeros(3, dtype=np.float32))


def test_check_gradients_accepts_right_and_rejects_wrong():
    A, x = _setup()
    f = lambda: float(np.sum((A @ x) ** 3))  # noqa: E731
    right = {"x": A.T @ (3 * (A @ x) ** 2), "A": np.outer(3 * (A @ x) ** 2, x)}
    check_gradients(f, {"x": x, "A": A}, right)
    wrong = dict(right, x=right["x"] * 1.01)
    with pytest.raises(AssertionError, match="'x'"):
        check_gradients(f, {"x": x, "A": A}, wrong)
    with pytest.raises(AssertionError, match="shape"):
        check_gradients(f, {"x": x}, {"x": right["x"][:2]})


def test_check_vjp_accepts_right_and_rejects_wrong():
    A, x = _setup()
    fn = lambda: (np.sin(A @ x), x ** 2)  # noqa: E731

    def vjp(ws):
        w0, w1 = ws
        return {"x": A.T @ (np.cos(A @ x) * w0) + 2 * x * w1}

    check_vjp(fn, {"x": x}, vjp)
    with pytest.raises(AssertionError, match="vector-Jacobian"):
        check_vjp(fn, {"x": x}, lambda ws: {"x": 1.1 * vjp(ws)["x"]})
    # arrays are restored after the check
    A2, x2 = _setup()
    assert np.array_equal(x, x2)


def test_assert_close_messages():
    assert_close(np.ones(3), np.ones(3))
    with pytest.raises(AssertionError, match="shape"):
        assert_close(np.ones(3), np.ones(4))
    with pytest.raises(AssertionError, match="max \\|diff\\|"):
        assert_close(np.array([1.0, 2.0]), np.array([1.0, 2.5]), atol=1e-3)
    with pytest.raises(AssertionError):
        assert_close(np.array([np.nan]), np.array([1.0]), atol=1.0)


def test_assert_quat_close_is_sign_invariant():
    q = np.array([[0.5, 0.5, 0.5, 0.5], [1.0, 0.0, 0.0, 0.0]])
    assert_quat_close(-q, q)
    with pytest.raises(AssertionError):
        assert_quat_close(q[::-1], q)
