"""Numerical edge cases with defined behaviour (spec/robustness.md §2; the operations are stated in spec/math.md).

Each test names the section of spec/robustness.md whose rule it checks. Tests marked
``xfail(strict=True)`` document a bug found in another module (the reason says which); they turn into
failures (XPASS) the moment the bug is fixed, so the marker must then be removed.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from refimpl.testing import assert_close, assert_quat_close
from refimpl import quat as Q
from refimpl import rotations as R
from refimpl import dualquat as DQ

RNG_SEED = 1234


def _unit_quats(n, seed=RNG_SEED, dtype=np.float64):
    rng = np.random.default_rng(seed)
    q = rng.standard_normal((n, 4))
    return (q / np.linalg.norm(q, axis=-1, keepdims=True)).astype(dtype)


def _unit_dqs(n, seed=RNG_SEED):
    rng = np.random.default_rng(seed + 1)
    return DQ.dq_from_quat_translation(_unit_quats(n, seed), rng.standard_normal((n, 3)))


def _same_rotation(q1, q2, atol):
    """q1 ≡ ±q2 (after normalisation)."""
    q1 = np.asarray(q1, np.float64) / np.linalg.norm(q1, axis=-1, keepdims=True)
    q2 = np.asarray(q2, np.float64) / np.linalg.norm(q2, axis=-1, keepdims=True)
    assert_quat_close(q1, q2, atol=atol)


def _same_dq(a, b, atol):
    """a ≡ ±b (the same rigid transform), per row."""
    a, b = np.asarray(a), np.asarray(b)
    err = np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1))
    assert np.all(err <= atol), f"max error {err.max():.3g} > {atol}"


# ------------------------------------------------------------------------------------------------------------
# §2.1 zero and near-zero quaternions / dual quaternions
# ------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("fn", [Q.quat_normalize, Q.quat_inv, Q.quat_log, R.axis_angle_from_quat,
                                R.matrix_from_quat, lambda q: R.euler_from_quat(q, "zyx")])
def test_zero_quaternion_is_refused(fn):
    """spec/robustness.md §2.1: a zero quaternion has no direction: ValueError naming ``q``, no identity
    substituted."""
    q = np.array([[1.0, 0, 0, 0], [0.0, 0, 0, 0]])
    with pytest.raises(ValueError, match=r"\bq\b"):
        fn(q)


@pytest.mark.parametrize("scale", [1e-310, 1e-300, 1e-200, 1e-100, 1.0, 1e100, 1e200, 1e300])
@pytest.mark.parametrize("dtype", [np.float64])
def test_quat_normalize_near_zero_and_huge(scale, dtype):
    """spec/robustness.md §2.1: quat_normalize is exact for tiny (even subnormal) and huge non-zero inputs."""
    q = _unit_quats(16)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow/underflow warnings either
        out = Q.quat_normalize(q * scale)
    assert np.all(np.isfinite(out))
    assert_close(np.linalg.norm(out, axis=-1), np.ones(16), rtol=0, atol=1e-15 if scale >= 1e-300 else 1e-12)
    assert_close(out, q, rtol=0, atol=1e-15 if scale >= 1e-300 else 1e-12, name="direction")


def test_quat_normalize_float32_tiny():
    """spec/robustness.md §2.1: float32 stays float32 and normalises subnormal float32 inputs."""
    q = _unit_quats(8, dtype=np.float32) * np.float32(1e-40)
    out = Q.quat_normalize(q)
    assert out.dtype == np.float32
    assert_close(np.linalg.norm(out.astype(np.float64), axis=-1), np.ones(8), rtol=0, atol=1e-5)


def test_quat_normalize_eps_threshold():
    """spec/robustness.md §2.1: ``eps`` rejects |q| <= eps and accepts anything larger."""
    q = np.array([1e-9, 0, 0, 0])
    with pytest.raises(ValueError):
        Q.quat_normalize(q, eps=1e-8)
    assert_close(Q.quat_normalize(q, eps=1e-10), [1.0, 0, 0, 0])


def test_dq_zero_real_part_is_refused():
    """spec/robustness.md §2.1: a DQ with zero real part is no rigid transform: ValueError, even if q_d != 0."""
    a = np.zeros((2, 8))
    a[0, 0] = 1
    a[1, 5] = 1.0  # pure dual part
    for fn in (DQ.dq_normalize, DQ.translation_from_dq, DQ.matrix_from_dq, DQ.dq_inv, DQ.dq_norm,
               DQ.quat_translation_from_dq):
        with pytest.raises(ValueError, match="real part"):
            fn(a)


@pytest.mark.parametrize("scale", [1e-100, 1e-50, 1e50, 1e100, 1e150])
def test_dq_normalize_moderate_scales(scale):
    """spec/robustness.md §2.1: dq_normalize(s·a) = a for unit a and |log10 s| <= 150, and Eq. 3 holds after."""
    a = _unit_dqs(16)
    out = DQ.dq_normalize(a * scale)
    assert_close(out, a, rtol=0, atol=1e-13)
    assert np.all(DQ.dq_is_unit(out, atol_norm=1e-14, atol_dot=1e-14))


def test_dq_normalize_near_zero_real_part_with_large_dual():
    """spec/robustness.md §2.1: a tiny-but-nonzero real part is normalised (huge translation, still finite)."""
    a = DQ.dq_from_quat_translation(np.array([1.0, 0, 0, 0]), np.array([1.0, 2.0, 3.0]))
    a = a * np.array([1e-8] * 4 + [1.0] * 4)  # real part 1e-8, dual part O(1): translation ~1e8
    out = DQ.dq_normalize(a)
    assert np.all(np.isfinite(out))
    assert DQ.dq_is_unit(out, atol_norm=1e-12, atol_dot=1e-6 * np.abs(out).max())


_SCALE_INVARIANT = {
    # name: (function, input kind) — documented as depending on q/|q| only
    # (spec/math.md §1.6, §2.1, §3.2, §4.1, §4.3, §5.3, §5.5, §5.7, §5.8)
    "quat_angle": (lambda q: Q.quat_angle(q), "q"),
    "quat_angle[q, r]": (lambda q: Q.quat_angle(q, q[::-1]), "q"),
    "axis_angle_from_quat": (R.axis_angle_from_quat, "q"),
    "matrix_from_quat": (R.matrix_from_quat, "q"),
    "euler_from_quat": (lambda q: R.euler_from_quat(q, "zyx"), "q"),
    "quat_log[vector part]": (lambda q: Q.quat_log(q)[..., 1:], "q"),
    "quat_normalize": (Q.quat_normalize, "q"),
    "matrix_from_ortho6d": (lambda q: R.matrix_from_ortho6d(R.ortho6d_from_matrix(R.matrix_from_quat(q))), "6d"),
    "dq_normalize": (DQ.dq_normalize, "dq"),
    "translation_from_dq": (DQ.translation_from_dq, "dq"),
    "quat_translation_from_dq": (lambda a: np.concatenate(DQ.quat_translation_from_dq(a), axis=-1), "dq"),
    "matrix_from_dq": (DQ.matrix_from_dq, "dq"),
}


def _scale_case(name, scale):
    fn, kind = _SCALE_INVARIANT[name]
    x = _unit_dqs(16) if kind == "dq" else _unit_quats(16)
    expected = fn(x)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if kind == "6d":  # the 6-D input itself is scaled (each column independently invariant)
            actual = R.matrix_from_ortho6d(R.ortho6d_from_matrix(R.matrix_from_quat(x)) * scale)
        else:
            actual = fn(x * scale)
    assert_close(actual, expected, rtol=0, atol=1e-12, name=f"{name}(s·x) vs {name}(x), s={scale:g}")


@pytest.mark.parametrize("scale", [1e-100, 1e-50, 1e50, 1e100, 1e150])
@pytest.mark.parametrize("name", sorted(_SCALE_INVARIANT))
def test_scale_invariance_moderate(name, scale):
    """spec/robustness.md §2.1: functions of q/|q| are invariant to scales 1e-100 ... 1e150."""
    _scale_case(name, scale)


@pytest.mark.parametrize("scale", [1e-305, 1e-200, 1e200, 1e300])
@pytest.mark.parametrize("name", sorted(_SCALE_INVARIANT))
def test_scale_invariance_extreme(name, scale):
    """spec/robustness.md §2.1: the scale invariance holds over the whole finite range (public functions rescale
    by the power of two of the largest component before any sum of squares; fixed bug B1, §7)."""
    _scale_case(name, scale)


@pytest.mark.parametrize("scale", [1e-310, 1e-200, 1.0, 1e200, 1e300])
def test_norms_scale_exactly(scale):
    """spec/robustness.md §2.1: quat_norm(s·q) = s and dq_norm(s·a) = (s, 0) for unit q, a, without under/overflow
    while the result is representable (spec/math.md §1.3, §5.4)."""
    q, a = _unit_quats(16), _unit_dqs(16)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        n = Q.quat_norm(q * scale)
        real, dual = DQ.dq_norm(a * scale)
    rtol = 1e-15 if scale >= 1e-300 else 1e-9  # subnormal inputs carry fewer digits
    assert_close(n / scale, np.ones(16), rtol=0, atol=4 * rtol)
    assert_close(real / scale, np.ones(16), rtol=0, atol=4 * rtol)
    assert_close(dual / scale, np.zeros(16), rtol=0, atol=1e-12)


@pytest.mark.parametrize("scale", [1e-200, 1e200])
def test_dq_inv_extreme_scales(scale):
    """spec/robustness.md §2.1: dq_inv(s·a) = dq_inv(a)/s for unit a while representable (spec/math.md §5.3)."""
    a = _unit_dqs(16)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        inv = DQ.dq_inv(a * scale)
    assert_close(inv * scale, DQ.dq_conj(a), rtol=0, atol=1e-13)


@pytest.mark.parametrize("scale", [1e-300, 1e-200, 1e200, 1e300])
def test_dq_blend_extreme_weight_scales(scale):
    """spec/robustness.md §2.1: dq_blend depends on the weights' ratios only, over the whole finite range
    (spec/math.md §5.12)."""
    a = _unit_dqs(16).reshape(8, 2, 8)
    w = np.array([0.3, 0.7])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        out = DQ.dq_blend(w * scale, a)
    assert_close(out, DQ.dq_blend(w, a), rtol=0, atol=1e-13)


def test_scale_invariance_float32():
    """spec/robustness.md §2.1: float32 inputs of magnitude 1e-30 and 1e30 stay float32 and give the unit result."""
    q = _unit_quats(16, dtype=np.float32)
    for s in (np.float32(1e-30), np.float32(1e30)):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            m = R.matrix_from_quat(q * s)
            v = R.axis_angle_from_quat(q * s)
            lg = Q.quat_log(q * s)
        assert m.dtype == v.dtype == lg.dtype == np.float32
        assert_close(m, R.matrix_from_quat(q), rtol=0, atol=1e-6)
        assert_close(v, R.axis_angle_from_quat(q), rtol=0, atol=1e-5)
        assert_close(lg[..., 0], np.full(16, np.log(float(s)), np.float32), rtol=1e-6, atol=0)


def test_quat_log_extreme_norm():
    """spec/robustness.md §2.1: quat_log(s·q) = (log s, log(q)_vec) for unit q, s from 1e-310 to 1e300."""
    q = _unit_quats(16)
    for s in (1e-310, 1e-200, 1e200, 1e300):
        out = Q.quat_log(q * s)
        assert_close(out[..., 0], np.full(16, np.log(s)), rtol=1e-12, atol=0)
        assert_close(out[..., 1:], Q.quat_log(q)[..., 1:], rtol=0, atol=1e-9 if s < 1e-300 else 1e-13)


# ------------------------------------------------------------------------------------------------------------
# §2.2 antipodal and opposite inputs to slerp / ScLERP
# ------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("t", [0.0, 0.25, 0.5, 1.0, 1.5, -0.5])
def test_slerp_antipodal_is_constant(t):
    """spec/robustness.md §2.2: slerp(q, −q, t) = q for every t (the same rotation: shortest arc is empty)."""
    q = _unit_quats(32)
    out = Q.quat_slerp(q, -q, t)
    assert_close(out, q, rtol=0, atol=1e-15)


def test_slerp_near_antipodal_is_stable():
    """spec/robustness.md §2.2: slightly perturbed antipodes stay close to q (no 0/0, unit norm)."""
    q = _unit_quats(32)
    rng = np.random.default_rng(3)
    q1 = -q + 1e-9 * rng.standard_normal(q.shape)
    q1 /= np.linalg.norm(q1, axis=-1, keepdims=True)
    out = Q.quat_slerp(q, q1, np.linspace(0, 1, 32))
    assert np.all(np.isfinite(out))
    assert_close(np.linalg.norm(out, axis=-1), np.ones(32), rtol=0, atol=1e-12)
    assert np.all(Q.quat_angle(out, q) <= 1e-8)


def test_slerp_orthogonal_inputs_follow_the_given_arc():
    """spec/robustness.md §2.2: ⟨q0, q1⟩ = 0 (rotations 180° apart): unit result, endpoints exact, midpoint
    halfway."""
    q0 = _unit_quats(16)
    q1 = Q.quat_mul(q0, np.array([0.0, 0, 1, 0]))  # q0 then 180° about y: ⟨q0, q1⟩ = 0
    assert_close(Q.quat_slerp(q0, q1, 0.0), q0, rtol=0, atol=1e-15)
    # the computed ⟨q0, q1⟩ is ±1e-17, so q1 may be taken as −q1: the same rotation
    assert_quat_close(Q.quat_slerp(q0, q1, 1.0), q1, atol=1e-15)
    mid = Q.quat_slerp(q0, q1, 0.5)
    assert_close(np.linalg.norm(mid, axis=-1), np.ones(16), rtol=0, atol=1e-14)
    assert_close(Q.quat_angle(q0, mid), np.full(16, np.pi / 2), rtol=0, atol=1e-7)


@pytest.mark.parametrize("t", [0.0, 0.3, 1.0])
def test_sclerp_antipodal_is_constant(t):
    """spec/robustness.md §2.2: ScLERP(a, −a, t) = a (−a is the same rigid transform)."""
    a = _unit_dqs(16)
    assert_close(DQ.dq_sclerp(a, -a, t), a, rtol=0, atol=1e-14)


@pytest.mark.parametrize("t", [0.0, 0.5, 1.0])
def test_sclerp_half_turn_apart(t):
    """spec/robustness.md §2.2: relative rotation of exactly 180° (⟨a_r, b_r⟩ = 0): unit result, exact
    endpoints."""
    a = _unit_dqs(16)
    rel = DQ.dq_from_quat_translation(np.array([0.0, 0, 1, 0]), np.array([1.0, 0.5, -0.25]))
    b = DQ.dq_mul(a, rel)
    out = DQ.dq_sclerp(a, b, t)
    assert np.all(np.isfinite(out))
    assert np.all(DQ.dq_is_unit(out, atol_norm=1e-12, atol_dot=1e-12))
    if t == 0.0:
        _same_dq(out, a, 1e-14)
    if t == 1.0:
        _same_dq(out, b, 1e-12)


# ------------------------------------------------------------------------------------------------------------
# §2.3 rotations of exactly 180°
# ------------------------------------------------------------------------------------------------------------

def _half_turn_axes(n=24):
    rng = np.random.default_rng(7)
    axes = [np.eye(3)[i] for i in range(3)] + [np.array([1.0, 1, 0]), np.array([1.0, -1, 1]), np.array([0, 1.0, -1])]
    axes += list(rng.standard_normal((n, 3)))
    axes = np.array(axes)
    return axes / np.linalg.norm(axes, axis=-1, keepdims=True)


def test_half_turn_matrix_to_quat():
    """spec/robustness.md §2.3: quat_from_matrix of a 180° rotation: w = 0 and the axis recovered (up to sign)."""
    axes = _half_turn_axes()
    q = np.concatenate([np.zeros((len(axes), 1)), axes], axis=-1)
    m = 2 * axes[:, :, None] * axes[:, None, :] - np.eye(3)  # R = 2 n nᵀ − I, built without quaternions
    out = R.quat_from_matrix(m)
    assert_close(out[:, 0], np.zeros(len(axes)), rtol=0, atol=1e-15)
    assert_quat_close(out, q, atol=1e-14)
    assert_close(R.matrix_from_quat(out), m, rtol=0, atol=1e-14)


@pytest.mark.parametrize("delta", [0.0, 1e-15, 1e-12, 1e-8])
def test_near_half_turn_matrix_roundtrip(delta):
    """spec/robustness.md §2.3: rotations within 1e-8 of 180° convert accurately (no branch-switch jump)."""
    axes = _half_turn_axes()
    v = (np.pi - delta) * axes
    q = R.quat_from_axis_angle(v)
    out = R.quat_from_matrix(R.matrix_from_quat(q))
    assert_quat_close(out, q, atol=1e-14)


def test_half_turn_axis_angle():
    """spec/robustness.md §2.3: axis_angle_from_quat((0, n)) = π n (norm π, θ ∈ [0, π]); back to the same
    rotation."""
    axes = _half_turn_axes()
    q = np.concatenate([np.zeros((len(axes), 1)), axes], axis=-1)
    v = R.axis_angle_from_quat(q)
    assert_close(np.linalg.norm(v, axis=-1), np.full(len(axes), np.pi), rtol=0, atol=1e-14)
    _same_rotation(R.quat_from_axis_angle(v), q, 1e-15)
    v_neg = R.axis_angle_from_quat(-q)  # −q is the same rotation: π(−n) is as valid as πn
    _same_rotation(R.quat_from_axis_angle(v_neg), q, 1e-15)


# ------------------------------------------------------------------------------------------------------------
# §2.4 gimbal lock in every Euler order
# ------------------------------------------------------------------------------------------------------------

def _lock_angles(order, n, offset, seed):
    rng = np.random.default_rng(seed)
    a = rng.uniform(-np.pi, np.pi, (n, 3))
    mids = [0.0, np.pi] if order[0] == order[2] else [np.pi / 2, -np.pi / 2]
    a[:, 1] = np.array(mids)[rng.integers(0, 2, n)] + offset * rng.choice([-1.0, 1.0], n)
    return a


@pytest.mark.parametrize("offset", [0.0, 1e-12, 1e-9, 1e-6])
@pytest.mark.parametrize("order", R.EULER_ORDERS)
def test_gimbal_lock_reproduces_rotation(order, offset):
    """spec/robustness.md §2.4: at (and near) gimbal lock, the returned angles reproduce the rotation.

    Checked through the quaternion and the matrix paths; the last angle is 0 exactly at lock (documented
    convention), the middle angle is in its range.
    """
    a = _lock_angles(order, 64, offset, seed=hash(order) % 1000)
    q = R.quat_from_euler(a, order)
    e = R.euler_from_quat(q, order)
    assert np.all(np.isfinite(e))
    _same_rotation(R.quat_from_euler(e, order), q, 1e-8)
    m = R.matrix_from_euler(a, order)
    e2 = R.euler_from_matrix(m, order)
    assert_close(R.matrix_from_euler(e2, order), m, rtol=0, atol=2e-8)
    if order[0] == order[2]:
        assert np.all((e[:, 1] >= 0) & (e[:, 1] <= np.pi))
    else:
        assert np.all(np.abs(e[:, 1]) <= np.pi / 2 + 1e-15)
    if offset == 0.0:
        assert_close(e[:, 2], np.zeros(64), rtol=0, atol=1e-15, name="last angle at exact lock")


@pytest.mark.parametrize("order", R.EULER_ORDERS)
def test_gimbal_lock_float32(order):
    """spec/robustness.md §2.4: float32 inputs at lock stay float32 and reproduce the rotation to float32 accuracy."""
    a = _lock_angles(order, 32, 0.0, seed=5).astype(np.float32)
    q = R.quat_from_euler(a, order)
    e = R.euler_from_quat(q, order)
    assert e.dtype == np.float32
    _same_rotation(R.quat_from_euler(e, order), q, 1e-5)


@settings(max_examples=30, deadline=None)
@given(order=st.sampled_from(R.EULER_ORDERS), a0=st.floats(-np.pi, np.pi), a2=st.floats(-np.pi, np.pi),
       sign=st.sampled_from([0, 1]), tiny=st.sampled_from([0.0, 5e-324, 1e-300, 1e-16, 1e-10]))
def test_gimbal_lock_property(order, a0, a2, sign, tiny):
    """spec/robustness.md §2.4 (hypothesis): any outer angles at/near lock round-trip to the same rotation."""
    mid = ([0.0, np.pi] if order[0] == order[2] else [np.pi / 2, -np.pi / 2])[sign]
    a = np.array([a0, mid + tiny, a2])
    q = R.quat_from_euler(a, order)
    _same_rotation(R.quat_from_euler(R.euler_from_quat(q, order), order), q, 1e-8)


# ------------------------------------------------------------------------------------------------------------
# §2.5 axis-angle at 0 and 2π
# ------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("theta", [0.0, 1e-310, 1e-300, 1e-12, 1e-4])
def test_axis_angle_at_zero(theta):
    """spec/robustness.md §2.5: θ → 0 uses the series: identity at 0, q ≈ (1, v/2) for tiny θ, round trip
    exact."""
    n = np.array([0.6, 0.0, 0.8])
    v = theta * n
    q = R.quat_from_axis_angle(v)
    assert np.all(np.isfinite(q))
    assert_close(q[1:], 0.5 * v, rtol=1e-9, atol=1e-323)
    assert abs(np.linalg.norm(q) - 1) <= 1e-15
    back = R.axis_angle_from_quat(q)
    assert_close(back, v, rtol=1e-12, atol=1e-323)


@pytest.mark.parametrize("theta", [2 * np.pi, 2 * np.pi + 1e-9, 2 * np.pi - 1e-9, 4 * np.pi])
def test_axis_angle_at_full_turns(theta):
    """spec/robustness.md §2.5: θ = 2π (and 4π) is the identity rotation; q = (−1, 0, 0, 0) at 2π (no
    canonicalisation).

    The inverse map returns the equivalent vector with θ ∈ [0, π], i.e. ≈ 0 at 2π.
    """
    n = np.array([0.0, 0.6, -0.8])
    q = R.quat_from_axis_angle(theta * n)
    _same_rotation(q, np.array([1.0, 0, 0, 0]), 1e-8)
    if theta == 2 * np.pi:
        assert q[0] == pytest.approx(-1.0, abs=1e-15)
    back = R.axis_angle_from_quat(q)
    assert np.linalg.norm(back) <= 1e-8
    _same_rotation(R.quat_from_axis_angle(back), q, 1e-15)


def test_axis_angle_identity_both_signs():
    """spec/robustness.md §2.5: (±1, 0, 0, 0) both give the zero vector."""
    assert_close(R.axis_angle_from_quat(np.array([[1.0, 0, 0, 0], [-1.0, 0, 0, 0]])), np.zeros((2, 3)), rtol=0, atol=0)


# ------------------------------------------------------------------------------------------------------------
# §2.6 bones of zero length
# ------------------------------------------------------------------------------------------------------------

# root, a zero-length bone (joint 1 sits on the root), a normal bone, a zero-length leaf on joint 2, a branch
_ZB_PARENTS = [-1, 0, 1, 2, 1, 4]
_ZB_OFFSETS = np.array([[0.0, 0, 0], [0, 0, 0], [0, 1.0, 0], [0, 0, 0], [0.5, 0.2, 0], [0, 0, 0]])


def _zb_rotations(n=3, seed=11):
    return _unit_quats(n * len(_ZB_PARENTS), seed).reshape(n, len(_ZB_PARENTS), 4)


def test_zero_length_bones_forward_kinematics():
    """spec/robustness.md §2.6: a zero-length bone puts the child exactly on its parent, for any rotations."""
    from refimpl.skeleton import Skeleton

    skel = Skeleton(_ZB_PARENTS, _ZB_OFFSETS)
    rot = _zb_rotations()
    root = np.random.default_rng(0).standard_normal((3, 3))
    pos = skel.forward_kinematics(rot, root)
    assert np.all(np.isfinite(pos))
    assert_close(pos[:, 1], pos[:, 0], rtol=0, atol=0, name="joint 1 on the root")
    assert_close(pos[:, 3], pos[:, 2], rtol=0, atol=0, name="joint 3 on joint 2")
    assert_close(pos[:, 5], pos[:, 4], rtol=0, atol=0, name="joint 5 on joint 4")


def test_zero_length_bones_offsets_from_dq():
    """spec/robustness.md §2.6: local offsets recovered from current DQs are exactly 0 for zero-length bones."""
    from refimpl.current_dq import current_dq_from_local, offsets_from_current_dq, positions_from_current_dq

    rot = _zb_rotations()
    cur = current_dq_from_local(rot, _ZB_OFFSETS, _ZB_PARENTS)
    off = offsets_from_current_dq(cur, _ZB_PARENTS)
    assert np.all(np.isfinite(off))
    assert_close(off[:, 1:], np.broadcast_to(_ZB_OFFSETS[1:], off[:, 1:].shape), rtol=0, atol=1e-15)
    pos = positions_from_current_dq(cur)
    assert_close(pos[:, 1], pos[:, 0], rtol=0, atol=1e-15)


def _zb_dqs(seed, offsets=_ZB_OFFSETS):
    from refimpl.current_dq import current_dq_from_local

    return current_dq_from_local(_zb_rotations(2, seed), offsets, _ZB_PARENTS)


@pytest.mark.parametrize("loss", ["pos", "offset"])
def test_zero_length_bones_dq_loss_gradients(loss):
    """spec/robustness.md §2.6: L_pos / L_offset for a prediction with zero-length bones have finite gradients
    equal to central differences.

    The target's bones differ from the prediction's (its zero-length bones have length 1e-2), so no term of
    the loss sits at the kink of ‖·‖ at 0, where central differences are meaningless (see §2.6 on the kink).
    """
    from refimpl.gradcheck import check_gradients
    from refimpl.losses import (dq_offset_loss_backward, dq_offset_loss_forward, dq_pos_loss_backward,
                                dq_pos_loss_forward)

    t_off = 1.5 * _ZB_OFFSETS
    t_off[[1, 3, 5]] = 1e-2 * np.array([[1.0, 2, 2], [0, 0.6, 0.8], [1, 0, 0]]) / np.array([[3.0], [1], [1]])
    pred, target = _zb_dqs(1), _zb_dqs(2, t_off)
    if loss == "pos":
        f = lambda: dq_pos_loss_forward(pred, target)[0]  # noqa: E731
        g = dq_pos_loss_backward(1.0, dq_pos_loss_forward(pred, target)[1])
    else:
        f = lambda: dq_offset_loss_forward(pred, target, _ZB_PARENTS)[0]  # noqa: E731
        g = dq_offset_loss_backward(1.0, dq_offset_loss_forward(pred, target, _ZB_PARENTS)[1])
    assert np.all(np.isfinite(g))
    check_gradients(f, {"pred": pred}, {"pred": g}, max_entries=None)


@pytest.mark.parametrize("loss", ["pos", "offset"])
def test_zero_length_bones_identical_pred_target(loss):
    """spec/robustness.md §2.6: pred = target with zero-length bones: value 0 and gradient exactly 0 (no 0/0)."""
    from refimpl.losses import (dq_offset_loss_backward, dq_offset_loss_forward, dq_pos_loss_backward,
                                dq_pos_loss_forward)

    pred = _zb_dqs(3)
    if loss == "pos":
        v, c = dq_pos_loss_forward(pred, pred.copy())
        g = dq_pos_loss_backward(1.0, c)
    else:
        v, c = dq_offset_loss_forward(pred, pred.copy(), _ZB_PARENTS)
        g = dq_offset_loss_backward(1.0, c)
    assert v == 0.0
    assert np.all(g == 0.0)


def test_zero_length_bones_fk_loss_gradient():
    """spec/robustness.md §2.6: the FK position loss with zero-length bones has finite, correct gradients."""
    from refimpl.gradcheck import check_gradients
    from refimpl.losses import fk_position_loss_backward, fk_position_loss_forward

    rng = np.random.default_rng(4)
    rot = _zb_rotations(2, 5)
    tr = rng.standard_normal((2, 2))
    tpos = rng.standard_normal((2, len(_ZB_PARENTS), 3))
    ttr = rng.standard_normal((2, 2))
    args = lambda: (rot, tr, tpos, ttr, _ZB_OFFSETS, _ZB_PARENTS)  # noqa: E731
    v, c = fk_position_loss_forward(*args())
    drot, dtr = fk_position_loss_backward(1.0, c)
    assert np.all(np.isfinite(drot)) and np.all(np.isfinite(dtr))
    check_gradients(lambda: fk_position_loss_forward(*args())[0], {"rot": rot, "tr": tr},
                    {"rot": drot, "tr": dtr}, max_entries=None)


# ------------------------------------------------------------------------------------------------------------
# §2.7 denormal and very large values in losses and their gradients
# ------------------------------------------------------------------------------------------------------------

_J = 4
_PARENTS = [-1, 0, 1, 1]


def _loss_cases(scale, seed=0):
    """(name, forward, backward, args): every loss of refimpl.losses on inputs of magnitude ``scale``.

    Position-like quantities (differences, translations, offsets) are scaled; rotations stay unit except in
    the raw-output regularisers and the rotation losses, whose quaternion inputs are scaled.
    """
    from refimpl import losses as L

    rng = np.random.default_rng(seed)

    def uq(*shape):
        q = rng.standard_normal(shape + (4,))
        return q / np.linalg.norm(q, axis=-1, keepdims=True)

    def dqs():
        return DQ.dq_from_quat_translation(uq(2, _J), rng.standard_normal((2, _J, 3)) * scale)

    s = scale

    def normal(*shape):
        return rng.standard_normal(shape) * s

    return [
        ("mse", L.mse_loss_forward, L.mse_loss_backward, (normal(2, 3, 5), normal(2, 3, 5))),
        ("mae", L.mae_loss_forward, L.mae_loss_backward, (normal(2, 3, 5), normal(2, 3, 5))),
        ("euclidean", L.euclidean_loss_forward, L.euclidean_loss_backward, (normal(2, _J, 3), normal(2, _J, 3))),
        ("dq_pos", L.dq_pos_loss_forward, L.dq_pos_loss_backward, (dqs(), dqs())),
        ("dq_offset", L.dq_offset_loss_forward, L.dq_offset_loss_backward, (dqs(), dqs(), _PARENTS)),
        ("dq_reg", L.dq_reg_loss_forward, L.dq_reg_loss_backward, (rng.standard_normal((2, _J, 8)) * s,)),
        ("quat_norm", L.quat_norm_loss_forward, L.quat_norm_loss_backward, (uq(2, _J) * s,)),
        ("quat", L.quat_loss_forward, L.quat_loss_backward, (uq(2, _J) * s, uq(2, _J))),
        ("local_quat", L.local_quat_loss_forward, L.local_quat_loss_backward, (uq(2, _J) * s, uq(2, _J), _PARENTS)),
        ("euler_l1", L.euler_l1_loss_forward, L.euler_l1_loss_backward, (uq(2, _J) * s, uq(2, _J))),
        ("fk_position", L.fk_position_loss_forward, L.fk_position_loss_backward,
         (uq(2, _J), rng.standard_normal((2, 2)) * s, rng.standard_normal((2, _J, 3)) * s,
          rng.standard_normal((2, 2)) * s, rng.standard_normal((_J, 3)) * s, _PARENTS)),
    ]


_LOSS_NAMES = [c[0] for c in _loss_cases(1.0)]


def _run_loss(name, scale):
    case = {c[0]: c for c in _loss_cases(scale)}[name]
    _, fwd, bwd, args = case
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # an honest overflow to +inf may warn
        value, cache = fwd(*args)
        grads = bwd(1.0, cache)
    return value, grads if isinstance(grads, tuple) else (grads,)


@pytest.mark.parametrize("name", _LOSS_NAMES)
def test_losses_denormal_inputs(name):
    """spec/robustness.md §2.7: inputs of magnitude 1e-310 (subnormal): finite value and finite gradients."""
    value, grads = _run_loss(name, 1e-310)
    assert np.isfinite(value), value
    for g in grads:
        assert np.all(np.isfinite(g)), name


@pytest.mark.parametrize("name", _LOSS_NAMES)
def test_losses_large_inputs(name):
    """spec/robustness.md §2.7: inputs of magnitude 1e150: no NaN in value or gradients. The value is finite
    when the exact value is representable (every loss except the quartic regularisers, whose exact value
    ~1e600 is reported as +inf); gradients may be ±inf only where the exact gradient overflows."""
    value, grads = _run_loss(name, 1e150)
    assert not np.isnan(value), f"{name}: NaN loss from finite input"
    if name not in ("dq_reg", "quat_norm"):
        assert np.isfinite(value), value
    for g in grads:
        assert not np.any(np.isnan(g)), f"{name}: NaN gradient from finite input"


@pytest.mark.parametrize("name", ["mse", "mae", "euclidean"])
def test_losses_difference_overflow(name):
    """spec/robustness.md §2.7: finite inputs whose difference overflows give +inf, never NaN."""
    from refimpl import losses as L

    fwd, bwd = {"mse": (L.mse_loss_forward, L.mse_loss_backward), "mae": (L.mae_loss_forward, L.mae_loss_backward),
                "euclidean": (L.euclidean_loss_forward, L.euclidean_loss_backward)}[name]
    p = np.full((2, 3), 1.5e308)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        value, cache = fwd(p, -p)
        g = bwd(1.0, cache)
    assert value == np.inf
    assert not np.any(np.isnan(g))


@pytest.mark.parametrize("name", _LOSS_NAMES)
def test_losses_identical_inputs_zero_gradient(name):
    """spec/robustness.md §2.7: pred = target (zero differences): the subgradient 0 is used, gradients finite."""
    case = {c[0]: c for c in _loss_cases(1.0, seed=3)}[name]
    _, fwd, bwd, args = case
    if name in ("dq_reg", "quat_norm"):
        args = (args[0] / np.linalg.norm(args[0][..., :4], axis=-1, keepdims=True),)
    elif name == "fk_position":
        return  # target positions are independent data; covered by test_zero_length_bones_fk_loss_gradient
    elif name == "euler_l1":
        args = (args[1], args[1].copy())
    else:
        args = (args[0], args[0].copy()) + tuple(args[2:])
    value, cache = fwd(*args)
    grads = bwd(1.0, cache)
    for g in grads if isinstance(grads, tuple) else (grads,):
        assert np.all(np.isfinite(g))
    if name not in ("dq_reg",):
        assert abs(value) <= 1e-12, (name, value)


# ------------------------------------------------------------------------------------------------------------
# §5 training faults (what tests/test_train.py does not already cover)
# ------------------------------------------------------------------------------------------------------------

def _toy_adapter(bad_at=None, bad_value=float("inf")):
    """Least squares on 16 fixed examples; the loss becomes ``bad_value`` at step ``bad_at`` (1-based)."""
    from refimpl.train import ModelAdapter

    rng = np.random.default_rng(0)
    X, y = rng.standard_normal((16, 3)), rng.standard_normal(16)

    def loss_and_grads(params, batch):
        idx, step = batch
        r = X[idx] @ params["w"] - y[idx]
        loss = float(np.mean(r * r))
        if bad_at is not None and step + 1 == bad_at:
            loss = bad_value
        return loss, {"w": 2 * X[idx].T @ r / len(idx)}

    return ModelAdapter(name="toy", num_examples=16, init_params=lambda g: {"w": g.standard_normal(3)},
                        get_batch=lambda idx, ctx: (idx, ctx.step), loss_and_grads=loss_and_grads)


def _toy_config(tmp_path, steps, checkpoint_every=2, **kw):
    from refimpl.train import TrainConfig

    return TrainConfig(steps=steps, batch_size=4, seed=1, checkpoint_path=str(tmp_path / "ckpt.npz"),
                       checkpoint_every=checkpoint_every, **kw)


def _last_data_byte_offset(path, member):
    """File offset of the last byte of a stored (uncompressed) zip member's data."""
    import struct
    import zipfile

    with zipfile.ZipFile(path) as z:
        info = z.getinfo(member)
    with open(path, "rb") as f:
        f.seek(info.header_offset)
        head = f.read(30)
    name_len, extra_len = struct.unpack("<HH", head[26:30])
    return info.header_offset + 30 + name_len + extra_len + info.compress_size - 1


@pytest.mark.parametrize("bad", [float("inf"), float("-inf")])
def test_training_infinite_loss_stops_cleanly(tmp_path, bad):
    """spec/robustness.md §5: an infinite loss (test_train.py covers NaN) raises TrainingDiverged naming the step;
    the last good checkpoint (step 4) is byte-for-byte intact."""
    from refimpl.train import OptimConfig, TrainingDiverged, train

    ckpt = tmp_path / "ckpt.npz"
    train(_toy_adapter(), OptimConfig(lr=1e-2), _toy_config(tmp_path, 4), progress=None)
    before = ckpt.read_bytes()
    with pytest.raises(TrainingDiverged, match=r"inf.*step 6"):
        train(_toy_adapter(bad_at=6, bad_value=bad), OptimConfig(lr=1e-2), _toy_config(tmp_path, 10),
              progress=None)
    # steps 5 is done, checkpoint_every=2 wrote nothing at 5; the step-4 file on disk must be unchanged
    assert ckpt.read_bytes() == before


@pytest.mark.parametrize("damage", ["truncate", "flip", "empty", "junk"])
def test_training_resume_refuses_damaged_checkpoint(tmp_path, damage):
    """spec/robustness.md §5: resuming from a truncated/corrupted checkpoint raises ValueError before any step,
    and leaves the damaged file for inspection (no silent restart from scratch)."""
    from refimpl.train import OptimConfig, train

    ckpt = tmp_path / "ckpt.npz"
    train(_toy_adapter(), OptimConfig(lr=1e-2), _toy_config(tmp_path, 4), progress=None)
    data = ckpt.read_bytes()
    if damage == "truncate":
        data = data[: len(data) // 2]
    elif damage == "flip":
        b = bytearray(data)
        b[_last_data_byte_offset(ckpt, "param.w.npy")] ^= 0x01  # one bit of the last parameter value
        data = bytes(b)
    elif damage == "empty":
        data = b""
    else:
        data = b"\x00\x01junk" * 50
    ckpt.write_bytes(data)
    with pytest.raises(ValueError):
        train(_toy_adapter(), OptimConfig(lr=1e-2), _toy_config(tmp_path, 8), progress=None)
    assert ckpt.read_bytes() == data


def _tampered_checkpoint(tmp_path, edit):
    """The trainer's checkpoint with its metadata edited and the checksum recomputed (a crafted file)."""
    from refimpl.checkpoint import load_checkpoint, save_checkpoint

    ckpt = tmp_path / "ckpt.npz"
    arrays, meta = load_checkpoint(ckpt)
    edit(arrays, meta)
    save_checkpoint(ckpt, arrays, meta)
    return ckpt


@pytest.mark.parametrize("what", ["no-step", "no-perm"])
def test_training_resume_refuses_incomplete_checkpoint(tmp_path, what):
    """spec/robustness.md §5: a well-formed checkpoint missing trainer state is refused with ValueError."""
    from refimpl.train import OptimConfig, train

    train(_toy_adapter(), OptimConfig(lr=1e-2), _toy_config(tmp_path, 4), progress=None)

    def edit(arrays, meta):
        if what == "no-step":
            del meta["step"]
        else:
            del arrays["sampler.perm"]

    _tampered_checkpoint(tmp_path, edit)
    with pytest.raises(ValueError):
        train(_toy_adapter(), OptimConfig(lr=1e-2), _toy_config(tmp_path, 8), progress=None)


def test_training_sigint_signal_saves_checkpoint(tmp_path):
    """spec/robustness.md §5: a real SIGINT (Ctrl-C) during training ends the run at the next step boundary with
    ``interrupted=True`` and a checkpoint of the last completed step (test_train.py raises KeyboardInterrupt
    from the callback; this goes through the signal handler)."""
    import os
    import signal

    from refimpl.checkpoint import load_checkpoint
    from refimpl.train import OptimConfig, train

    def callback(info):
        if info.step == 3:
            os.kill(os.getpid(), signal.SIGINT)

    old = signal.getsignal(signal.SIGINT)
    res = train(_toy_adapter(), OptimConfig(lr=1e-2), _toy_config(tmp_path, 50, checkpoint_every=1000),
                callback=callback, progress=None)
    assert signal.getsignal(signal.SIGINT) is old  # the handler is restored
    assert res.interrupted and res.step == 3
    arrays, meta = load_checkpoint(tmp_path / "ckpt.npz")
    assert meta["step"] == 3
    assert np.array_equal(arrays["param.w"], res.params["w"])
