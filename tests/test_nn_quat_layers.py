"""Tests of refimpl.nn.quat_layers (spec/losses.md §2): forwards against refimpl.quat / refimpl.dualquat and
naive formulas, backwards against central differences and the vector-Jacobian identity, edge cases."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.dualquat import dq_from_quat_translation, dq_mul, dq_normalize
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.nn.quat_layers import (
    EULER_ORDERS,
    axis_angle_to_quat_backward,
    axis_angle_to_quat_forward,
    dq_normalize_backward,
    dq_normalize_forward,
    euler_from_quat_backward,
    euler_from_quat_forward,
    euler_to_quat_backward,
    euler_to_quat_forward,
    dq_velocity_backward,
    dq_velocity_forward,
    qmul_velocity_backward,
    qmul_velocity_forward,
    quat_mul_backward,
    quat_mul_forward,
    quat_normalize_backward,
    quat_normalize_forward,
)
from refimpl.quat import quat_mul, quat_normalize
from refimpl.rotations import euler_from_quat, quat_from_axis_angle, quat_from_euler
from refimpl.testing import TOL_EXACT, TOL_FD, assert_close

lead_shapes = st.lists(st.integers(1, 3), min_size=0, max_size=3).map(tuple)
seeds = st.integers(0, 2**31 - 1)


def _unit(rng, shape):
    q = rng.standard_normal(shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _quat_mul_naive(a, b):
    """Hamilton product through the 4x4 left-multiplication matrix (an independent formula)."""
    w, x, y, z = (a[..., k] for k in range(4))
    L = np.stack([np.stack([w, -x, -y, -z], -1), np.stack([x, w, -z, y], -1),
                  np.stack([y, z, w, -x], -1), np.stack([z, -y, x, w], -1)], -2)
    return np.einsum("...ij,...j->...i", L, b)


# ------------------------------------------------------------------------------------------------
# quat_normalize (§2.1)

@given(lead_shapes, seeds)
def test_quat_normalize_forward_and_vjp(lead, seed):
    """spec/losses.md §2.1: y = q/|q| (agrees with refimpl.quat.quat_normalize), VJP identity of the backward."""
    rng = np.random.default_rng([seed, 7])  # a stream distinct from check_vjp's own
    q = rng.standard_normal(lead + (4,)) * rng.uniform(0.1, 10.0)
    y, cache = quat_normalize_forward(q)
    assert_close(y, quat_normalize(q), **TOL_EXACT)
    assert_close(np.linalg.norm(y, axis=-1), np.ones(lead), **TOL_EXACT)
    check_vjp(lambda: quat_normalize_forward(q)[0], {"q": q},
              lambda w: {"q": quat_normalize_backward(w[0], quat_normalize_forward(q)[1])})


def test_quat_normalize_central_differences():
    """spec/losses.md §2.1: the backward against central differences, entry by entry."""
    rng = np.random.default_rng(0)
    q = rng.standard_normal((3, 5, 4))
    w = rng.standard_normal(q.shape)
    _, cache = quat_normalize_forward(q)
    check_gradients(lambda: float(np.sum(quat_normalize_forward(q)[0] * w)), {"q": q},
                    {"q": quat_normalize_backward(w, cache)}, max_entries=None)


def test_quat_normalize_clamp_and_zero():
    """spec/losses.md §2.1: |q| < eps gives q/eps with gradient dy/eps; the zero quaternion gives 0, finite grads."""
    eps = 1e-3
    q = np.array([[1e-4, 2e-4, 0.0, -3e-4], [0.0, 0.0, 0.0, 0.0]])
    y, cache = quat_normalize_forward(q, eps=eps)
    assert_close(y, q / eps, **TOL_EXACT)
    dy = np.arange(8.0).reshape(2, 4)
    assert_close(quat_normalize_backward(dy, cache), dy / eps, **TOL_EXACT)
    check_gradients(lambda: float(np.sum(quat_normalize_forward(q[:1], eps=eps)[0] * dy[:1])), {"q": q[:1]},
                    {"q": quat_normalize_backward(dy[:1], quat_normalize_forward(q[:1], eps=eps)[1])},
                    eps=1e-8)
    y0, c0 = quat_normalize_forward(np.zeros(4))
    assert np.all(y0 == 0) and np.all(np.isfinite(quat_normalize_backward(np.ones(4), c0)))


def test_quat_normalize_extreme_magnitudes():
    """spec/losses.md §6: 1e300 and denormal quaternions (with an eps below their norm) normalise to unit length
    without overflow/underflow; with the default eps a denormal quaternion is clamped to q/eps (and the gradient,
    at most 1/eps, stays finite; the true 1/|q| of a denormal |q| would overflow)."""
    base = np.array([1.0, -2.0, 2.0, 4.0])
    for scale, eps in ((1e300, 1e-12), (1e-310, 1e-315)):
        y, cache = quat_normalize_forward(base * scale, eps=eps)
        assert_close(y, base / 5.0, rtol=1e-12, atol=0)
    assert np.all(np.isfinite(quat_normalize_backward(np.ones(4), quat_normalize_forward(base * 1e300)[1])))
    y, cache = quat_normalize_forward(base * 1e-310)
    assert_close(y, base * 1e-310 / 1e-12, rtol=1e-6, atol=0)
    assert np.all(np.isfinite(quat_normalize_backward(np.ones(4), cache)))


def test_quat_normalize_float32_and_validation():
    """spec/architecture.md: float32 stays float32; bad shapes/NaN raise ValueError naming the argument."""
    q = np.ones((2, 4), dtype=np.float32)
    y, cache = quat_normalize_forward(q)
    assert y.dtype == np.float32 and quat_normalize_backward(np.ones_like(y), cache).dtype == np.float32
    with pytest.raises(ValueError, match=r"q: expected shape \(\.\.\., 4\)"):
        quat_normalize_forward(np.ones((2, 3)))
    with pytest.raises(ValueError, match="q: expected finite values, got NaN"):
        quat_normalize_forward(np.array([np.nan, 0, 0, 1.0]))
    with pytest.raises(ValueError, match="eps"):
        quat_normalize_forward(q, eps=0.0)
    with pytest.raises(ValueError, match="dy"):
        quat_normalize_backward(np.ones((3, 4)), cache)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_backward_refuses_non_finite_upstream_gradient(bad):
    """spec/robustness.md §3 (bug B8): every layer backward refuses a NaN/inf (or non-numeric) upstream gradient
    with ValueError naming it, instead of propagating it."""
    rng = np.random.default_rng(2)
    q = _unit(rng, (2, 3))
    cases = [(quat_normalize_backward, quat_normalize_forward(q)[1], (2, 3, 4), "dy"),
             (quat_mul_backward, quat_mul_forward(q, q)[1], (2, 3, 4), "dy"),
             (qmul_velocity_backward, qmul_velocity_forward(q, q)[1], (2, 3, 4), "dy"),
             (dq_normalize_backward, dq_normalize_forward(rng.standard_normal((2, 3, 8)))[1], (2, 3, 8), "dy"),
             (dq_velocity_backward, dq_velocity_forward(rng.standard_normal((2, 3, 8)),
                                                        rng.standard_normal((2, 3, 8)))[1], (2, 3, 8), "dy"),
             (euler_from_quat_backward, euler_from_quat_forward(q)[1], (2, 3, 3), "dangles")]
    for backward, cache, shape, name in cases:
        g = np.ones(shape)
        g[1, 2, 0] = bad
        with pytest.raises(ValueError, match=rf"^{name}: expected finite values, got NaN or inf"):
            backward(g, cache)
        with pytest.raises(ValueError, match=rf"^{name}: expected a real floating array"):
            backward(np.full(shape, "a"), cache)


def test_zero_dimensional_inputs_are_refused():
    """spec/robustness.md §3 (bug B7): a 0-d value where a (..., 4) / (..., 8) array is expected → ValueError naming
    the argument and the expected shape (not IndexError)."""
    for call, name, want in ((lambda: quat_normalize_forward(np.float64(1.0)), "q", r"\(\.\.\., 4\)"),
                             (lambda: dq_normalize_forward(np.array(1.0)), "dq", r"\(\.\.\., 8\)"),
                             (lambda: quat_mul_forward(np.ones(4), 2.0), "b", r"\(\.\.\., 4\)")):
        with pytest.raises(ValueError, match=rf"^{name}: expected shape {want}.*, got shape \(\)"):
            call()


# ------------------------------------------------------------------------------------------------
# quat_mul (§2.2)

@given(lead_shapes, seeds)
def test_quat_mul_forward_and_vjp(lead, seed):
    """spec/losses.md §2.2: Hamilton product (vs refimpl.quat and the matrix form); VJP with broadcasting."""
    rng = np.random.default_rng([seed, 7])  # a stream distinct from check_vjp's own
    a = rng.standard_normal(lead + (4,))
    b = rng.standard_normal((1,) * len(lead) + (4,))  # broadcast over every leading axis
    y, cache = quat_mul_forward(a, b)
    assert_close(y, _quat_mul_naive(a, np.broadcast_to(b, a.shape)), **TOL_EXACT)
    assert_close(y, quat_mul(a, b), **TOL_EXACT)

    def vjp(w):
        da, db = quat_mul_backward(w[0], quat_mul_forward(a, b)[1])
        return {"a": da, "b": db}

    check_vjp(lambda: quat_mul_forward(a, b)[0], {"a": a, "b": b}, vjp)


def test_quat_mul_central_differences():
    """spec/losses.md §2.2: both gradients against central differences."""
    rng = np.random.default_rng(1)
    a, b = rng.standard_normal((2, 3, 4)), rng.standard_normal((3, 4))
    w = rng.standard_normal((2, 3, 4))
    da, db = quat_mul_backward(w, quat_mul_forward(a, b)[1])
    assert db.shape == b.shape
    check_gradients(lambda: float(np.sum(quat_mul_forward(a, b)[0] * w)), {"a": a, "b": b}, {"a": da, "b": db},
                    max_entries=None)


def test_quat_mul_kernel_is_shared_and_keeps_float32():
    """spec/losses.md §2.2: the layer uses refimpl.quat's Hamilton-product kernel (one implementation); float32
    inputs give float32 outputs and gradients, mixed inputs follow NumPy's promotion."""
    import refimpl.nn.quat_layers as QL
    import refimpl.quat as Q

    assert QL.quat_mul_kernel is Q.quat_mul_kernel
    a32 = np.ones((2, 4), np.float32)
    y, cache = quat_mul_forward(a32, a32[:1])
    assert y.dtype == np.float32 and all(g.dtype == np.float32 for g in quat_mul_backward(np.ones_like(y), cache))
    assert quat_mul_forward(a32, np.ones(4))[0].dtype == np.float64


def test_quat_mul_rejects_non_broadcasting():
    """spec/architecture.md: shapes that do not broadcast raise ValueError."""
    with pytest.raises(ValueError, match="broadcast"):
        quat_mul_forward(np.ones((2, 4)), np.ones((3, 4)))


# ------------------------------------------------------------------------------------------------
# qmul_velocity (§2.3)

@given(lead_shapes, seeds)
def test_qmul_velocity_is_normalized_left_product(lead, seed):
    """spec/losses.md §2.3: y = normalize(Δq ⊗ q_in), the delta on the LEFT; VJP into both inputs."""
    rng = np.random.default_rng([seed, 7])  # a stream distinct from check_vjp's own
    delta = rng.standard_normal(lead + (4,))
    q_in = _unit(rng, lead)
    y, cache = qmul_velocity_forward(delta, q_in)
    assert_close(y, quat_normalize(quat_mul(delta, q_in)), **TOL_EXACT)

    def vjp(w):
        dd, dq = qmul_velocity_backward(w[0], qmul_velocity_forward(delta, q_in)[1])
        return {"delta": dd, "q_in": dq}

    check_vjp(lambda: qmul_velocity_forward(delta, q_in)[0], {"delta": delta, "q_in": q_in}, vjp)


def test_qmul_velocity_order_and_central_differences():
    """spec/losses.md §2.3: the product order matters (Δq ⊗ q_in ≠ q_in ⊗ Δq); gradients vs central differences."""
    rng = np.random.default_rng(2)
    delta, q_in = rng.standard_normal((4, 4)), _unit(rng, (4,))
    y, cache = qmul_velocity_forward(delta, q_in)
    assert not np.allclose(y, quat_normalize(quat_mul(q_in, delta)))
    w = rng.standard_normal(y.shape)
    dd, dq = qmul_velocity_backward(w, cache)
    check_gradients(lambda: float(np.sum(qmul_velocity_forward(delta, q_in)[0] * w)),
                    {"delta": delta, "q_in": q_in}, {"delta": dd, "q_in": dq}, max_entries=None)
    with pytest.raises(ValueError, match="q_in"):
        qmul_velocity_forward(delta, q_in[:2])


# ------------------------------------------------------------------------------------------------
# dq_velocity (spec/quaternet.md §9)

def _unit_dq(rng, lead):
    return dq_from_quat_translation(_unit(rng, lead), rng.standard_normal(lead + (3,)))


@given(lead_shapes, seeds)
def test_dq_velocity_is_normalized_left_dq_product(lead, seed):
    """spec/quaternet.md §9: y = N(ΔD ⊗ D_in) (Eq. 13 after the dual-quaternion product, delta on the LEFT),
    against refimpl.dualquat.dq_mul + dq_normalize; VJP into both inputs."""
    rng = np.random.default_rng([seed, 11])
    delta = rng.standard_normal(lead + (8,))
    d_in = _unit_dq(rng, lead)
    y, _ = dq_velocity_forward(delta, d_in)
    assert_close(y, dq_normalize(dq_mul(delta, d_in)), **TOL_EXACT)

    def vjp(w):
        dd, di = dq_velocity_backward(w[0], dq_velocity_forward(delta, d_in)[1])
        return {"delta": dd, "d_in": di}

    check_vjp(lambda: dq_velocity_forward(delta, d_in)[0], {"delta": delta, "d_in": d_in}, vjp)


def test_dq_velocity_identity_order_and_central_differences():
    """The identity delta keeps D_in; order matters (ΔD ⊗ D_in ≠ D_in ⊗ ΔD); gradients vs central differences
    (raw, non-unit inputs on both sides); mismatched shapes are refused."""
    rng = np.random.default_rng(5)
    d_in = _unit_dq(rng, (3,))
    ident = np.zeros((3, 8))
    ident[:, 0] = 1.0
    assert_close(dq_velocity_forward(ident, d_in)[0], d_in, **TOL_EXACT)
    delta, raw_in = rng.standard_normal((3, 8)), rng.standard_normal((3, 8))
    y, cache = dq_velocity_forward(delta, d_in)
    assert not np.allclose(y, dq_normalize(dq_mul(d_in, delta)))
    w = rng.standard_normal(y.shape)
    for a_in in (d_in, raw_in):
        dd, di = dq_velocity_backward(w, dq_velocity_forward(delta, a_in)[1])
        check_gradients(lambda: float(np.sum(dq_velocity_forward(delta, a_in)[0] * w)),
                        {"delta": delta, "d_in": a_in}, {"delta": dd, "d_in": di}, max_entries=None)
    with pytest.raises(ValueError, match="d_in"):
        dq_velocity_forward(delta, d_in[:2])


# ------------------------------------------------------------------------------------------------
# dq_normalize (§2.4, Eq. 13)

@given(lead_shapes, seeds)
def test_dq_normalize_unit_conditions_and_vjp(lead, seed):
    """spec/losses.md §2.4 (Eq. 13): |q̂_r| = 1, <q̂_r, q̂_d> = 0, equal to refimpl.dualquat.dq_normalize; VJP."""
    rng = np.random.default_rng([seed, 7])  # a stream distinct from check_vjp's own
    dq = rng.standard_normal(lead + (8,))
    dq[..., :4] *= rng.uniform(0.3, 3.0)
    y, cache = dq_normalize_forward(dq)
    assert_close(y, dq_normalize(dq), **TOL_EXACT)
    assert_close(np.linalg.norm(y[..., :4], axis=-1), np.ones(lead), **TOL_EXACT)
    assert_close(np.sum(y[..., :4] * y[..., 4:], axis=-1), np.zeros(lead), rtol=0, atol=1e-12)
    check_vjp(lambda: dq_normalize_forward(dq)[0], {"dq": dq},
              lambda w: {"dq": dq_normalize_backward(w[0], dq_normalize_forward(dq)[1])})


def test_dq_normalize_central_differences_and_idempotence():
    """spec/losses.md §2.4: gradients vs central differences; a unit DQ is a fixed point."""
    rng = np.random.default_rng(3)
    dq = rng.standard_normal((2, 3, 8))
    w = rng.standard_normal(dq.shape)
    check_gradients(lambda: float(np.sum(dq_normalize_forward(dq)[0] * w)), {"dq": dq},
                    {"dq": dq_normalize_backward(w, dq_normalize_forward(dq)[1])}, max_entries=None)
    y, _ = dq_normalize_forward(dq)
    assert_close(dq_normalize_forward(y)[0], y, **TOL_EXACT)


def test_dq_normalize_clamp_region():
    """spec/losses.md §2.4: below eps the real norm is the constant eps; gradients match central differences."""
    eps = 1e-2
    dq = np.array([[1e-3, -2e-3, 0.0, 4e-3, 0.3, -0.1, 0.2, 0.5]])
    w = np.random.default_rng(4).standard_normal(dq.shape)
    y, cache = dq_normalize_forward(dq, eps=eps)
    assert_close(y[..., :4], dq[..., :4] / eps, **TOL_EXACT)
    check_gradients(lambda: float(np.sum(dq_normalize_forward(dq, eps=eps)[0] * w)), {"dq": dq},
                    {"dq": dq_normalize_backward(w, cache)}, eps=1e-7, max_entries=None)
    y0, c0 = dq_normalize_forward(np.zeros(8))
    assert np.all(np.isfinite(y0)) and np.all(np.isfinite(dq_normalize_backward(np.ones(8), c0)))


# ------------------------------------------------------------------------------------------------
# euler_from_quat (§2.5)

def _axis_quat(axis: int, angle: np.ndarray) -> np.ndarray:
    q = np.zeros(angle.shape + (4,))
    q[..., 0] = np.cos(angle / 2)
    q[..., 1 + axis] = np.sin(angle / 2)
    return q


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_euler_round_trip_all_orders(order):
    """spec/losses.md §2.5: for q = q_{o0}(·) ⊗ q_{o1}(·) ⊗ q_{o2}(·) (QuaterNet euler_to_quaternion), qeuler
    returns the (x, y, z) angles; also against refimpl.rotations.euler_from_quat (angles in `order`)."""
    rng = np.random.default_rng(5)
    e = rng.uniform(-1.2, 1.2, (50, 3))  # (x, y, z), away from gimbal lock
    q = None
    for c in order:
        r = _axis_quat("xyz".index(c), e[:, "xyz".index(c)])
        q = r if q is None else _quat_mul_naive(q, r)
    got, _ = euler_from_quat_forward(q, order)
    assert_close(got, e, rtol=0, atol=1e-12)
    theirs = euler_from_quat(q, order)  # angles ordered as `order`
    assert_close(got[:, ["xyz".index(c) for c in order]], theirs, rtol=0, atol=1e-12)
    assert_close(euler_from_quat_forward(-q, order)[0], e, rtol=0, atol=1e-12)  # q and -q agree


@pytest.mark.parametrize("order", EULER_ORDERS)
def test_euler_backward_central_differences(order):
    """spec/losses.md §2.5: the gradient through atan2/asin against central differences, every order."""
    rng = np.random.default_rng(6)
    q = quat_from_euler(rng.uniform(-1.2, 1.2, (6, 3)), order)
    w = rng.standard_normal((6, 3))
    _, cache = euler_from_quat_forward(q, order, 1e-6)
    check_gradients(lambda: float(np.sum(euler_from_quat_forward(q, order, 1e-6)[0] * w)), {"q": q},
                    {"q": euler_from_quat_backward(w, cache)}, max_entries=None)


@given(st.sampled_from(EULER_ORDERS), seeds)
def test_euler_backward_vjp(order, seed):
    """spec/losses.md §2.5: vector-Jacobian identity for random (non-unit) quaternions away from singularities.

    The asin argument scales with |q|², so the middle angle stays below 0.72 rad: |arg| <= sin(0.72)·1.21 = 0.8
    (with 1.2 rad and |q| = 1.1 the argument was clipped and central differences met the kink)."""
    rng = np.random.default_rng([seed, 7])  # a stream distinct from check_vjp's own
    angles = rng.uniform(-1.2, 1.2, (3, 3)) * np.array([1.0, 0.6, 1.0])
    q = quat_from_euler(angles, order) * rng.uniform(0.9, 1.1, (3, 1))
    check_vjp(lambda: euler_from_quat_forward(q, order, 1e-6)[0], {"q": q},
              lambda w: {"q": euler_from_quat_backward(w[0], euler_from_quat_forward(q, order, 1e-6)[1])})


def test_euler_gimbal_lock_finite_and_clip():
    """spec/losses.md §2.5 and §6: at gimbal lock (atan2(0, 0), asin(±1)) gradients are finite; a clipped
    asin argument passes no gradient; eps = 0 at the pole gives a zero (not infinite) derivative."""
    q = np.array([[np.sqrt(0.5), 0.0, np.sqrt(0.5), 0.0]])  # 'zyx': y = +90°
    for eps in (0.0, 1e-6):
        e, cache = euler_from_quat_forward(q, "zyx", eps)
        g = euler_from_quat_backward(np.ones((1, 3)), cache)
        assert np.all(np.isfinite(e)) and np.all(np.isfinite(g))
    e, _ = euler_from_quat_forward(q, "zyx", 1e-6)
    assert abs(e[0, 1] - np.arcsin(1 - 1e-6)) < 1e-12
    with pytest.raises(ValueError, match="order"):
        euler_from_quat_forward(q, "xyx")
    with pytest.raises(ValueError, match="eps"):
        euler_from_quat_forward(q, "zyx", 1.0)


def test_euler_float32():
    """spec/architecture.md dtype rule for the Euler layer."""
    q = quat_from_euler(np.array([[0.1, 0.2, 0.3]]), "zyx").astype(np.float32)
    e, cache = euler_from_quat_forward(q, "zyx", 1e-6)
    assert e.dtype == np.float32 and euler_from_quat_backward(np.ones_like(e), cache).dtype == np.float32


@pytest.mark.parametrize("order", ["xyz", "yzx"])
def test_euler_to_quat_layer(order):
    """spec/losses.md §2: the Euler ablation's conversion equals refimpl.rotations.quat_from_euler; its backward =
    central differences; it inverts euler_from_quat (up to sign)."""
    rng = np.random.default_rng(1)
    a = rng.uniform(-3, 3, (6, 3))
    q, cache = euler_to_quat_forward(a, order)
    assert np.allclose(q, quat_from_euler(a, order), atol=1e-15)
    w = rng.standard_normal(q.shape)
    check_gradients(lambda: float(np.sum(w * euler_to_quat_forward(a, order)[0])), {"a": a},
                    {"a": euler_to_quat_backward(w, cache)}, **TOL_FD, max_entries=None)
    q2, _ = euler_to_quat_forward(euler_from_quat(q, order), order)
    assert np.allclose(np.abs(np.sum(q2 * q, -1)), 1.0, atol=1e-12)


def test_axis_angle_to_quat_layer():
    """spec/losses.md §2: the axis-angle conversion equals refimpl.rotations.quat_from_axis_angle (also below the series
    threshold θ = 1e-4); its backward = central differences."""
    rng = np.random.default_rng(2)
    v = rng.standard_normal((6, 3)) * np.array([[1e-7], [1e-5], [0.3], [1.0], [2.5], [3.0]])
    q, cache = axis_angle_to_quat_forward(v)
    assert np.allclose(q, quat_from_axis_angle(v), atol=1e-15)
    w = rng.standard_normal(q.shape)
    check_gradients(lambda: float(np.sum(w * axis_angle_to_quat_forward(v)[0])), {"v": v},
                    {"v": axis_angle_to_quat_backward(w, cache)}, eps=1e-8, rtol=1e-5, atol=1e-7,
                    max_entries=None)


def test_euler_and_axis_angle_layers_check_their_inputs():
    with pytest.raises(ValueError, match="order"):
        euler_to_quat_forward(np.zeros((2, 3)), "xyx")
    with pytest.raises(ValueError, match=r"angles: expected shape \(\.\.\., 3\)"):
        euler_to_quat_forward(np.zeros((2, 4)), "xyz")
    with pytest.raises(ValueError, match="v: expected finite values, got NaN"):
        axis_angle_to_quat_forward(np.full((2, 3), np.nan))
