"""Tests of refimpl.losses (spec/losses.md §4-§6): values against direct formulas and independent modules
(refimpl.skeleton, refimpl.quat), gradients against central differences and the VJP identity (the backward is
linear in dvalue), finiteness at edge cases (zero differences, denormals, huge values)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import refimpl.losses as L
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.quat import quat_mul, quat_conj
from refimpl.rotations import euler_from_quat, quat_from_euler
from refimpl.skeleton import Skeleton
from refimpl.current_dq import current_dq_from_local, positions_from_current_dq
from refimpl.testing import TOL_EXACT, TOL_FD, assert_close

PARENTS = [-1, 0, 1, 2, 0, 4, 0, 6, 6, 8]
J = len(PARENTS)
lead_shapes = st.lists(st.integers(1, 3), min_size=1, max_size=3).map(tuple)
seeds = st.integers(0, 2**31 - 1)


def _unit(rng, shape):
    q = rng.standard_normal(shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _current(rng, lead, jitter=0.0):
    rot = _unit(rng, lead + (J,))
    off = rng.standard_normal((J, 3))
    cur = current_dq_from_local(rot, off, PARENTS)
    return cur + jitter * rng.standard_normal(cur.shape)


def _check_loss(forward, backward, pred, *args, max_entries=12):
    """VJP identity (all entries at once; the directional derivative is a central difference, hence TOL_FD),
    central differences on ``max_entries`` entries (None: all), and
    linearity of the backward in dvalue."""
    value, cache = forward(pred, *args)
    assert isinstance(value, float) and math.isfinite(value)
    g = backward(1.0, cache)
    check_vjp(lambda: np.array(forward(pred, *args)[0]), {"pred": pred},
              lambda w: {"pred": backward(float(w[0]), forward(pred, *args)[1])}, **TOL_FD)
    check_gradients(lambda: forward(pred, *args)[0], {"pred": pred}, {"pred": g}, max_entries=max_entries)
    assert_close(backward(-2.5, cache), -2.5 * g, **TOL_EXACT)
    return value, g


# ------------------------------------------------------------------------------------------------
# weights (§5)

def test_paper_weights():
    """spec/losses.md §5: Andreou et al. Appendix B and QuaterNet's rot_reg as named constants."""
    assert L.WEIGHTS_ACRNN_DQ == {"mse": 1.0, "quat": 1.0, "pos": 1 / 3, "offset": 1 / 3, "reg": 0.01}
    assert L.WEIGHTS_QUATERNET_DQ == {"quat": 1.0, "pos": 1.0, "offset": 1.0, "reg": 0.01}
    assert L.WEIGHT_ACRNN_QUAT_FK == 0.25 and L.QUATERNET_PENALTY_WEIGHT == 0.01
    assert L.QUATERNET_EULER_EPS == 1e-6
    with pytest.raises(TypeError):
        L.WEIGHTS_ACRNN_DQ["reg"] = 1.0  # read-only


# ------------------------------------------------------------------------------------------------
# MSE, MAE (§4.1, §4.2)

@given(lead_shapes, seeds)
def test_mse_and_mae_values_and_gradients(lead, seed):
    """spec/losses.md §4.1-§4.2: mean((p-t)²) and mean|p-t| over all entries; gradients (central differences)."""
    rng = np.random.default_rng([seed, 7])
    p, t = rng.standard_normal(lead + (5,)), rng.standard_normal(lead + (5,))
    v, _ = _check_loss(L.mse_loss_forward, L.mse_loss_backward, p, t)
    assert abs(v - np.mean((p - t) ** 2)) <= 1e-12 * max(1.0, v)
    v, _ = _check_loss(L.mae_loss_forward, L.mae_loss_backward, p, t)
    assert abs(v - np.mean(np.abs(p - t))) <= 1e-12 * max(1.0, v)


def test_mse_mae_edge_cases():
    """spec/losses.md §6: zero differences give 0 and zero gradients; denormals and huge values stay finite."""
    z = np.ones((2, 3))
    for fw, bw in ((L.mse_loss_forward, L.mse_loss_backward), (L.mae_loss_forward, L.mae_loss_backward)):
        v, c = fw(z, z)
        assert v == 0.0 and np.all(bw(1.0, c) == 0.0)
        v, c = fw(np.full((4, 4), 1e-310), np.zeros((4, 4)))
        assert math.isfinite(v) and np.all(np.isfinite(bw(1.0, c)))
    v, c = L.mae_loss_forward(np.full((1000,), 1e300), np.full((1000,), -1e300))
    assert v == pytest.approx(2e300) and np.all(np.isfinite(L.mae_loss_backward(1.0, c)))
    v, c = L.mse_loss_forward(np.full((1000,), 1e150), np.zeros(1000))  # naive sum of squares would overflow
    assert v == pytest.approx(1e300) and np.all(np.isfinite(L.mse_loss_backward(1.0, c)))
    with pytest.raises(ValueError, match="target"):
        L.mse_loss_forward(np.ones(3), np.ones(4))
    with pytest.raises(ValueError, match="pred: expected finite values, got NaN"):
        L.mae_loss_forward(np.array([np.nan]), np.ones(1))


def test_mse_float32():
    """spec/architecture.md dtype rule: float32 gradients for float32 inputs."""
    p = np.ones((2, 3), dtype=np.float32)
    _, c = L.mse_loss_forward(p, np.zeros_like(p))
    assert L.mse_loss_backward(1.0, c).dtype == np.float32


# ------------------------------------------------------------------------------------------------
# L_quat (§4.3, §4.4)

@given(lead_shapes, seeds)
def test_quat_loss_current(lead, seed):
    """spec/losses.md §4.3 (Eq. 15): mean |1 - <q, q̃>| over (B, T, J); for DQs only the real part counts."""
    rng = np.random.default_rng([seed, 7])
    p, t = _unit(rng, lead), _unit(rng, lead)
    v, g = _check_loss(L.quat_loss_forward, L.quat_loss_backward, p, t)
    assert abs(v - np.mean(np.abs(1 - np.sum(p * t, -1)))) < 1e-12
    pd = np.concatenate([p, rng.standard_normal(lead + (4,))], -1)
    td = np.concatenate([t, rng.standard_normal(lead + (4,))], -1)
    vd, gd = _check_loss(L.quat_loss_forward, L.quat_loss_backward, pd, td)
    assert vd == v and np.all(gd[..., 4:] == 0)


def _local_naive(q):
    """normalize(q_parent* ⊗ q_j) joint by joint with refimpl.quat (root: q_0 normalised)."""
    out = np.empty_like(q)
    for j, p in enumerate(PARENTS):
        r = q[..., j, :] if p < 0 else quat_mul(quat_conj(q[..., p, :]), q[..., j, :])
        out[..., j, :] = r / np.linalg.norm(r, axis=-1, keepdims=True)
    return out


@given(st.lists(st.integers(1, 3), min_size=0, max_size=2).map(tuple), seeds)
def test_local_quat_loss(lead, seed):
    """spec/losses.md §4.4: local rotations normalize(q_p* ⊗ q_j) (root parent = identity) then Eq. 15."""
    rng = np.random.default_rng([seed, 7])
    p = _unit(rng, lead + (J,)) * rng.uniform(0.8, 1.2, lead + (J, 1))
    t = _unit(rng, lead + (J,))
    v, _ = _check_loss(L.local_quat_loss_forward, L.local_quat_loss_backward, p, t, PARENTS)
    expect = np.mean(np.abs(1 - np.sum(_local_naive(p) * _local_naive(t), -1)))
    assert abs(v - expect) < 1e-12


def test_quat_losses_zero_and_huge():
    """spec/losses.md §6: identical rotations give 0 with zero (sub)gradient; huge quaternions stay finite."""
    q = _unit(np.random.default_rng(0), (2, J))
    for v, c, bw in ((*L.quat_loss_forward(q, q), L.quat_loss_backward),
                     (*L.local_quat_loss_forward(q, q, PARENTS), L.local_quat_loss_backward)):
        assert abs(v) < 1e-15 and np.all(np.isfinite(bw(1.0, c)))
    v, c = L.quat_loss_forward(q * 1e300, q)
    assert math.isfinite(v) and np.all(np.isfinite(L.quat_loss_backward(1.0, c)))
    v, c = L.local_quat_loss_forward(q * 1e-310, q, PARENTS)
    assert math.isfinite(v) and np.all(np.isfinite(L.local_quat_loss_backward(1.0, c)))


# ------------------------------------------------------------------------------------------------
# Euclidean, L_pos, L_offset (§4.5 - §4.7)

@given(lead_shapes, seeds)
def test_euclidean_loss(lead, seed):
    """spec/losses.md §4.5: mean over leading axes of ‖p - p̃‖₂ (not squared)."""
    rng = np.random.default_rng([seed, 7])
    p, t = rng.standard_normal(lead + (3,)), rng.standard_normal(lead + (3,))
    v, _ = _check_loss(L.euclidean_loss_forward, L.euclidean_loss_backward, p, t)
    assert abs(v - np.mean(np.linalg.norm(p - t, axis=-1))) < 1e-12


def test_euclidean_edge_cases():
    """spec/losses.md §6: gradient 0 (not NaN) where p = p̃; denormal and 1e300 differences are handled exactly."""
    p = np.array([[1.0, 2.0, 3.0], [0.0, 0.0, 0.0]])
    t = np.array([[1.0, 2.0, 3.0], [3.0, 4.0, 0.0]])
    v, c = L.euclidean_loss_forward(p, t)
    g = L.euclidean_loss_backward(1.0, c)
    assert v == 2.5 and np.all(g[0] == 0) and np.allclose(g[1], [-0.3, -0.4, 0.0])
    for scale in (1e-310, 1e300):
        v, c = L.euclidean_loss_forward(p * scale, t * scale)
        assert v == pytest.approx(2.5 * scale, rel=1e-12)
        assert_close(L.euclidean_loss_backward(1.0, c), g, rtol=1e-12, atol=1e-15)


@given(seeds)
def test_dq_pos_loss_is_fk_position_error(seed):
    """spec/losses.md §4.6: L_pos on current DQs = mean Euclidean error of root-relative positions (Eq. 8),
    which equal refimpl.skeleton's positions_from_current_dq."""
    rng = np.random.default_rng([seed, 7])
    p, t = _current(rng, (2, 3)), _current(rng, (2, 3))
    v, _ = L.dq_pos_loss_forward(p, t)
    expect = np.mean(np.linalg.norm(positions_from_current_dq(p) - positions_from_current_dq(t), axis=-1))
    assert abs(v - expect) < 1e-12
    # gradients off the unit manifold: the jitter also moves the root away from the kink at distance 0 (both
    # roots sit at the origin), where central differences have an O(eps) error
    pj = p + 0.05 * rng.standard_normal(p.shape)
    _check_loss(L.dq_pos_loss_forward, L.dq_pos_loss_backward, pj, t)


@given(seeds)
def test_dq_offset_loss(seed):
    """spec/losses.md §4.7: L_offset = mean over (B, T, J) of ‖o - õ‖ with o the translation of C_p⁻¹ ⊗ C_j;
    two motions of the same skeleton have zero offset error (up to rounding)."""
    rng = np.random.default_rng([seed, 7])
    rot_a, rot_b = _unit(rng, (2, J)), _unit(rng, (2, J))
    off = rng.standard_normal((J, 3))
    a = current_dq_from_local(rot_a, off, PARENTS)
    b = current_dq_from_local(rot_b, off, PARENTS)
    v, _ = L.dq_offset_loss_forward(a, b, PARENTS)
    assert v < 1e-12
    b2 = current_dq_from_local(rot_b, off * 1.5, PARENTS)
    v, _ = _check_loss(L.dq_offset_loss_forward, L.dq_offset_loss_backward, a, b2, PARENTS)
    expect = np.sum(np.linalg.norm(0.5 * off[1:], axis=-1)) / J  # root counts in J with offset 0
    assert abs(v - expect) < 1e-10


def test_dq_pos_offset_central_differences_off_manifold():
    """spec/losses.md §4.6-§4.7: gradients are exact also for non-unit (perturbed) DQs, every entry."""
    rng = np.random.default_rng(4)
    p, t = _current(rng, (2,), jitter=0.05), _current(rng, (2,))
    _check_loss(L.dq_pos_loss_forward, L.dq_pos_loss_backward, p, t, max_entries=None)
    _check_loss(L.dq_offset_loss_forward, L.dq_offset_loss_backward, p, t, PARENTS, max_entries=None)
    v, c = L.dq_pos_loss_forward(t, t)
    assert v == 0.0 and np.all(L.dq_pos_loss_backward(1.0, c) == 0)


# ------------------------------------------------------------------------------------------------
# L_reg and the norm penalty (§4.8, §4.9)

@given(lead_shapes, seeds)
def test_dq_reg_and_norm_penalty(lead, seed):
    """spec/losses.md §4.8 (Eq. 16) and §4.9: (|q_r|²-1)² + <q_r, q_d>² averaged; QuaterNet's mean((Σq²-1)²)."""
    rng = np.random.default_rng([seed, 7])
    x = rng.standard_normal(lead + (8,))
    v, _ = _check_loss(L.dq_reg_loss_forward, L.dq_reg_loss_backward, x)
    r, d = x[..., :4], x[..., 4:]
    expect = np.mean((np.sum(r * r, -1) - 1) ** 2 + np.sum(r * d, -1) ** 2)
    assert abs(v - expect) <= 1e-12 * max(1.0, expect)
    q = rng.standard_normal(lead + (4,))
    v, _ = _check_loss(L.quat_norm_loss_forward, L.quat_norm_loss_backward, q)
    assert abs(v - np.mean((np.sum(q * q, -1) - 1) ** 2)) <= 1e-12 * max(1.0, v)
    assert L.dq_reg_loss_forward(q)[0] == v  # plain quaternions: only the first term


def test_reg_zero_on_unit():
    """spec/losses.md §4.8: unit dual quaternions (Eq. 3) have L_reg = 0 and zero gradient (to rounding)."""
    cur = _current(np.random.default_rng(5), (2,))
    v, c = L.dq_reg_loss_forward(cur)
    assert v < 1e-28 and np.max(np.abs(L.dq_reg_loss_backward(1.0, c))) < 1e-13
    with pytest.raises(ValueError, match="raw"):
        L.dq_reg_loss_forward(np.ones((2, 5)))


# ------------------------------------------------------------------------------------------------
# Euler L1 (§4.10)

def test_euler_l1_value_matches_quaternet_formula():
    """spec/losses.md §4.10: d = (e - ẽ + π) mod 2π - π with zyx Euler angles (QuaterNet qeuler, x/y/z order),
    mean |d| over all angles including the root; target as quaternions or as Euler angles gives the same value."""
    rng = np.random.default_rng(6)
    p, t = _unit(rng, (2, 3, 4)), _unit(rng, (2, 3, 4))
    v, _ = L.euler_l1_loss_forward(p, t)
    ep = euler_from_quat(p, "zyx")[..., ::-1]  # refimpl.quat gives (z, y, x) for 'zyx'
    et = euler_from_quat(t, "zyx")[..., ::-1]
    d = np.remainder(ep - et + np.pi, 2 * np.pi) - np.pi
    assert abs(v - np.mean(np.abs(d))) < 1e-9  # the prediction's asin is clipped at 1 - 1e-6
    v2, _ = L.euler_l1_loss_forward(p, et)
    assert v2 == v


def test_euler_l1_wrap():
    """spec/losses.md §4.10: angles just either side of ±π are 0.02 apart, not 2π - 0.02."""
    e_pred = np.array([[np.pi - 0.01, 0.1, 0.2]])  # (x, y, z)
    e_true = np.array([[-np.pi + 0.01, 0.1, 0.2]])
    q = quat_from_euler(e_pred[:, ::-1], "zyx")  # refimpl.quat takes angles in order: (z, y, x)
    v, c = L.euler_l1_loss_forward(q, e_true)
    assert v == pytest.approx(0.02 / 3, abs=1e-9)


@given(seeds)
def test_euler_l1_gradient(seed):
    """spec/losses.md §4.10: gradient through the wrap and the quaternion → Euler conversion (central diffs)."""
    rng = np.random.default_rng([seed, 7])
    p = quat_from_euler(rng.uniform(-1.2, 1.2, (2, 3, 3)), "zyx")
    t = rng.uniform(-np.pi, np.pi, (2, 3, 3))
    _check_loss(L.euler_l1_loss_forward, L.euler_l1_loss_backward, p, t)


def test_euler_l1_edge_cases():
    """spec/losses.md §6: zero error and gimbal-locked predictions give finite values and gradients."""
    q = quat_from_euler(np.array([[0.3, 0.2, 0.1]]), "zyx")
    v, c = L.euler_l1_loss_forward(q, q)
    assert v < 1e-12 and np.all(np.isfinite(L.euler_l1_loss_backward(1.0, c)))
    lock = np.array([[np.sqrt(0.5), 0.0, np.sqrt(0.5), 0.0], [1.0, 0, 0, 0]])
    v, c = L.euler_l1_loss_forward(lock, np.zeros((2, 3)))
    assert math.isfinite(v) and np.all(np.isfinite(L.euler_l1_loss_backward(1.0, c)))
    with pytest.raises(ValueError, match="target"):
        L.euler_l1_loss_forward(lock, np.zeros((3, 3)))


# ------------------------------------------------------------------------------------------------
# QuaterNet FK position loss (§4.11)

def _fk_case(rng, lead=(2, 3)):
    rot = _unit(rng, lead + (J,))
    tr = rng.standard_normal(lead + (2,))
    tpos = rng.standard_normal(lead + (J, 3))
    ttr = rng.standard_normal(lead + (2,))
    # keep |o − õ| >= 0.1, away from the kink of |·| that finite differences would straddle (hypothesis found
    # o − õ = 4e-7)
    ttr[..., 0] = tr[..., 0] - rng.choice([-1.0, 1.0], lead) * rng.uniform(0.1, 2.0, lead)
    off = rng.standard_normal((J, 3))
    return rot, tr, tpos, ttr, off


def test_fk_position_loss_value():
    """spec/losses.md §4.11: FK (refimpl.skeleton) with root (0, h, 0), per-joint Euclidean error, plus |o - õ|
    added to every joint's term, mean over (N, T, J)."""
    rng = np.random.default_rng(7)
    rot, tr, tpos, ttr, off = _fk_case(rng)
    root = np.zeros(tr.shape[:-1] + (3,))
    root[..., 1] = tr[..., 1]
    pos = Skeleton(PARENTS, off).forward_kinematics(rot, root)
    per_joint = np.linalg.norm(pos - tpos, axis=-1) + np.abs(tr[..., :1] - ttr[..., :1])
    v, _ = L.fk_position_loss_forward(rot, tr, tpos, ttr, off, PARENTS)
    assert abs(v - np.mean(per_joint)) < 1e-12


def test_fk_position_loss_central_differences():
    """spec/losses.md §4.11: gradients into the rotations and both translations, every entry."""
    rot, tr, tpos, ttr, off = _fk_case(np.random.default_rng(9), (2,))
    v, c = L.fk_position_loss_forward(rot, tr, tpos, ttr, off, PARENTS)
    drot, dtr = L.fk_position_loss_backward(1.0, c)
    check_gradients(lambda: L.fk_position_loss_forward(rot, tr, tpos, ttr, off, PARENTS)[0],
                    {"rot": rot, "tr": tr}, {"rot": drot, "tr": dtr}, max_entries=None)


@given(lead_shapes, seeds)
def test_fk_position_loss_vjp(lead, seed):
    """spec/losses.md §4.11: vector-Jacobian identity for random leading shapes."""
    rot, tr, tpos, ttr, off = _fk_case(np.random.default_rng([seed, 7]), lead)

    def vjp(w):
        drot, dtr = L.fk_position_loss_backward(float(w[0]),
                                                L.fk_position_loss_forward(rot, tr, tpos, ttr, off, PARENTS)[1])
        return {"rot": drot, "tr": dtr}

    check_vjp(lambda: np.array(L.fk_position_loss_forward(rot, tr, tpos, ttr, off, PARENTS)[0]),
              {"rot": rot, "tr": tr}, vjp, **TOL_FD)


def test_fk_position_loss_zero_error_and_validation():
    """spec/losses.md §6: a perfect prediction gives 0 and finite (zero) gradients; shape errors name arguments."""
    rng = np.random.default_rng(8)
    rot, tr, _, ttr, off = _fk_case(rng, (2,))
    root = np.zeros((2, 3))
    root[:, 1] = tr[:, 1]
    tpos = Skeleton(PARENTS, off).forward_kinematics(rot, root)
    v, c = L.fk_position_loss_forward(rot, tr, tpos, tr, off, PARENTS)
    drot, dtr = L.fk_position_loss_backward(1.0, c)
    assert v < 1e-14 and np.all(np.isfinite(drot)) and np.all(np.isfinite(dtr))
    with pytest.raises(ValueError, match="target_positions"):
        L.fk_position_loss_forward(rot, tr, tpos[:, :3], ttr, off, PARENTS)
    with pytest.raises(ValueError, match="pred_translations"):
        L.fk_position_loss_forward(rot, tr[:, :1], tpos, ttr, off, PARENTS)


# ------------------------------------------------------------------------------------------------
# every loss at the edges (§6)

def _edge_cases():
    """(name, forward, backward, make(scale) -> args, huge scale where the value is representable: the local
    L_quat multiplies two quaternions, L_reg and the norm penalty take 4th powers, the Euler loss needs unit
    quaternions)."""
    rng = np.random.default_rng(10)
    x, y = rng.standard_normal((2, 3, 4)), rng.standard_normal((2, 3, 4))
    q, r = _unit(rng, (2, J)), _unit(rng, (2, J))
    rot = _unit(rng, (2, J))
    off = rng.standard_normal((J, 3))

    def dq(scale):  # unit current DQs whose translations scale with `scale`
        return current_dq_from_local(rot, off * scale, PARENTS), current_dq_from_local(q, off * scale, PARENTS)

    tr, tpos, ttr = rng.standard_normal((2, 2)), rng.standard_normal((2, J, 3)), rng.standard_normal((2, 2))
    return [
        ("mse", L.mse_loss_forward, L.mse_loss_backward, lambda s: (x * s, y * s), 1e150),
        ("mae", L.mae_loss_forward, L.mae_loss_backward, lambda s: (x * s, y * s), 1e300),
        ("quat", L.quat_loss_forward, L.quat_loss_backward, lambda s: (q * s, r), 1e300),
        ("local_quat", L.local_quat_loss_forward, L.local_quat_loss_backward, lambda s: (q * s, r, PARENTS), 1e150),
        ("euclidean", L.euclidean_loss_forward, L.euclidean_loss_backward, lambda s: (x * s, y * s), 1e300),
        ("dq_pos", L.dq_pos_loss_forward, L.dq_pos_loss_backward, lambda s: dq(s), 1e100),
        ("dq_offset", L.dq_offset_loss_forward, L.dq_offset_loss_backward, lambda s: (*dq(s), PARENTS), 1e100),
        ("dq_reg", L.dq_reg_loss_forward, L.dq_reg_loss_backward, lambda s: (np.concatenate([q, r], -1) * s,), 1e75),
        ("quat_norm", L.quat_norm_loss_forward, L.quat_norm_loss_backward, lambda s: (q * s,), 1e75),
        ("euler_l1", L.euler_l1_loss_forward, L.euler_l1_loss_backward, lambda s: (q * min(s, 1.0), r), None),
        ("fk_position", L.fk_position_loss_forward, L.fk_position_loss_backward,
         lambda s: (rot, tr * s, tpos * s, ttr * s, off * s, PARENTS), 1e100),
    ]


@pytest.mark.parametrize("case", _edge_cases(), ids=lambda c: c[0])
def test_every_loss_finite_at_edges(case):
    """spec/losses.md §6: for every loss, identical pred/target gives 0 with a finite gradient; denormal-scale
    (1e-300) and huge (where representable) inputs give finite values and finite gradients."""
    name, fw, bw, make, huge = case
    scales = [1e-300, 1e-310, 1.0] + ([huge] if huge else [])
    for scale in scales:
        args = make(scale)
        v, c = fw(*args)
        grads = bw(1.0, c)
        grads = grads if isinstance(grads, tuple) else (grads,)
        assert math.isfinite(v), (name, scale, v)
        assert all(np.all(np.isfinite(g)) for g in grads), (name, scale)
    args = list(make(1.0))
    if name in ("dq_reg", "quat_norm"):
        return  # no target
    if name == "fk_position":
        rot_, tr_, _, _, off_, par = args
        root = np.zeros((2, 3))
        root[:, 1] = tr_[:, 1]
        args[2], args[3] = Skeleton(par, off_).forward_kinematics(rot_, root), tr_
    else:
        args[1] = args[0]
    v, c = fw(*args)
    grads = bw(1.0, c)
    grads = grads if isinstance(grads, tuple) else (grads,)
    assert abs(v) < 1e-12 and all(np.all(np.isfinite(g)) for g in grads), (name, v)


# ------------------------------------------------------------------------------------------------
# overflow: defined behaviour (§6; spec/robustness.md §2.7, bugs B2, B3)

def test_overflowing_difference_gives_inf_value_finite_gradient():
    """spec/losses.md §6: when pred − target overflows for finite inputs the value is +inf (the true value is not
    representable) and the gradient is the exact one where representable: no NaN (bug B3)."""
    with np.errstate(over="ignore"):
        _overflowing_difference_cases()


def _overflowing_difference_cases():
    p = np.full((2, 3), 1.5e308)
    v, c = L.mse_loss_forward(p, -p)
    assert v == math.inf
    assert_close(L.mse_loss_backward(1.0, c), np.full((2, 3), 1e308), rtol=1e-15)  # 2 (p − t) / N = 2·3e308/6
    v, c = L.mae_loss_forward(p, -p)
    assert v == math.inf and np.all(L.mae_loss_backward(1.0, c) == 1 / 6)
    # the mean is representable although one difference is not: MAE and the Euclidean loss report it exactly
    big = np.zeros((4, 3))
    big[0, 0], tgt = 1.5e308, np.zeros((4, 3))
    tgt[0, 0] = -1.5e308
    v, c = L.mae_loss_forward(big, tgt)
    assert v == pytest.approx(1.5e308 / 6) and np.all(np.isfinite(L.mae_loss_backward(1.0, c)))
    v, c = L.euclidean_loss_forward(big, tgt)
    assert v == pytest.approx(1.5e308 / 2)
    assert_close(L.euclidean_loss_backward(1.0, c)[0], [0.25, 0, 0], **TOL_EXACT)
    v, c = L.euclidean_loss_forward(p, -p)
    assert v == math.inf and np.all(np.isfinite(L.euclidean_loss_backward(1.0, c)))


def test_regularisers_overflow_to_inf_never_nan():
    """spec/losses.md §6: L_reg and the norm penalty are quartic: for raw outputs ≳ 1e77 the value is +inf and
    the gradient is ±inf only where its exact value overflows (bug B2); below, the scaled evaluation equals the
    direct formula."""
    rng = np.random.default_rng(3)
    x = rng.standard_normal((3, 5, 8))
    for s in (1e77, 1e150, 1e200, 1e300):
        with np.errstate(over="ignore"):  # the honest overflow of the value and of some gradient entries
            v, c = L.dq_reg_loss_forward(x * s)
            g = L.dq_reg_loss_backward(1.0, c)
            assert v == math.inf and not np.any(np.isnan(g))
            v, c = L.quat_norm_loss_forward(x[..., :4] * s)
            g = L.quat_norm_loss_backward(1.0, c)
            assert v == math.inf and not np.any(np.isnan(g))
    # 1e60: the exact value ~1e240 is representable, the gradient ~1e180 too: both finite and exact
    xs = x * 1e60
    r, d = xs[..., :4], xs[..., 4:]
    a, b = np.sum(r * r, -1) - 1, np.sum(r * d, -1)
    v, c = L.dq_reg_loss_forward(xs)
    assert v == pytest.approx(np.mean(a * a + b * b), rel=1e-14)
    g = L.dq_reg_loss_backward(1.0, c)
    n = a.size
    gr, gd = (4 * a[..., None] * r + 2 * b[..., None] * d) / n, 2 * b[..., None] * r / n
    assert_close(g[..., :4], gr, rtol=0, atol=1e-14 * np.abs(gr).max())  # the two terms may cancel
    assert_close(g[..., 4:], gd, rtol=1e-14)
    # a row of mixed magnitudes: the large terms overflow, the gradient of the small row stays exact
    mixed = np.stack([x[0, 0] * 1e200, x[0, 1]])
    with np.errstate(over="ignore"):
        v, c = L.dq_reg_loss_forward(mixed)
        g = L.dq_reg_loss_backward(1.0, c)
    r1, d1 = x[0, 1, :4], x[0, 1, 4:]
    a1, b1 = r1 @ r1 - 1, r1 @ d1
    assert_close(g[1, :4], (4 * a1 * r1 + 2 * b1 * d1) / 2, rtol=0, atol=1e-14)


def test_regularisers_float32_scaled():
    """spec/losses.md §6: float32 raw outputs stay float32; 1e12 (quartic terms overflow float32) → +inf, no NaN."""
    x = np.random.default_rng(4).standard_normal((2, 3, 8)).astype(np.float32)
    for s in (np.float32(1), np.float32(1e12)):
        with np.errstate(over="ignore"):
            v, c = L.dq_reg_loss_forward(x * s)
            g = L.dq_reg_loss_backward(1.0, c)
        assert g.dtype == np.float32 and not np.any(np.isnan(g))
        assert (v == math.inf) == (s > 1)


@pytest.mark.parametrize("seed", range(3))
def test_no_nan_from_any_finite_input(seed):
    """spec/losses.md §6: MSE, MAE, Euclidean, L_quat (current), L_reg and the norm penalty never return NaN (value
    or gradient) for finite inputs of any magnitude, subnormal to the largest float, mixed signs, any dvalue."""
    rng = np.random.default_rng(seed)
    fmax = np.finfo(np.float64).max

    def arr(shape):
        a = rng.standard_normal(shape) * 10.0 ** rng.integers(-320, 308, shape)
        a[rng.random(shape) < 0.25] = fmax * rng.choice([-1.0, 1.0])
        return np.where(np.isfinite(a), a, fmax)

    for _ in range(20):
        cases = [(L.mse_loss_forward, L.mse_loss_backward, (arr((3, 5)), arr((3, 5)))),
                 (L.mae_loss_forward, L.mae_loss_backward, (arr((3, 5)), arr((3, 5)))),
                 (L.euclidean_loss_forward, L.euclidean_loss_backward, (arr((3, 3)), arr((3, 3)))),
                 (L.quat_loss_forward, L.quat_loss_backward, (arr((3, 4)), arr((3, 4)))),
                 (L.dq_reg_loss_forward, L.dq_reg_loss_backward, (arr((3, 8)),)),
                 (L.quat_norm_loss_forward, L.quat_norm_loss_backward, (arr((3, 4)),))]
        for fw, bw, args in cases:
            with np.errstate(over="ignore"):
                v, c = fw(*args)
                for dvalue in (1.0, 1e300, 1e-300, -fmax):
                    assert not np.any(np.isnan(bw(dvalue, c))), fw.__name__
            assert not math.isnan(v), fw.__name__


def test_dvalue_validation():
    """spec/losses.md §1, spec/robustness.md §3 (bug B9): dvalue is a finite real scalar — a Python or NumPy
    scalar or a 0-d array; arrays of any other shape, strings, NaN/inf are refused with ValueError naming it."""
    p, t = np.ones((2, 3)), np.zeros((2, 3))
    _, c = L.mse_loss_forward(p, t)
    g = L.mse_loss_backward(1.0, c)
    for ok in (np.float64(1.0), np.float32(1.0), np.array(1.0), 1, np.int64(1), True):
        assert_close(L.mse_loss_backward(ok, c), g, **TOL_EXACT)
    for bad in (np.ones(3), np.ones(1), np.ones((1, 1)), "1.0", np.array("1"), None, 1j, np.nan, np.inf, -np.inf,
                np.array(np.nan)):
        with pytest.raises(ValueError, match="dvalue"):
            L.mse_loss_backward(bad, c)
