"""Tests of the transition baselines (spec/qtg.md §7): Bollo inertialisation and temporal interpolation."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.protocols.transition_baselines import (METHOD_NAMES, _inertialization_coefficients, _inertialize_naive, inertialize,
                               interpolate, method_registry, quintic_inertialization)
from refimpl.models.qtg import QTGConfig, init_params
from refimpl.models.qtg_fast import rollout_forward
from refimpl.quat import quat_angle, quat_mul, quat_normalize
from refimpl.rotations import quat_from_axis_angle
from refimpl.recipes.qtg import qtg_method
from refimpl.testing import TOL_EXACT, assert_close, assert_quat_close
from refimpl.protocols.transition import denormalize_poses, join_pose, normalize_poses, split_pose


def _random_poses(rng, B, J):
    root = rng.standard_normal((B, 2, 3)) * 10
    q = quat_normalize(rng.standard_normal((B, 2, J, 4)))
    return join_pose(root, q)


def _poly(x0, v0, t1):
    """The quintic as a numpy poly1d plus the clamped parameters."""
    v0c, t1c, a0, A, B, C, active = _inertialization_coefficients(x0, v0, t1)
    return np.poly1d([float(A), float(B), float(C), float(a0) / 2, float(v0c), float(x0)]), float(v0c), float(t1c), \
        float(a0), bool(active)


@given(st.floats(0.01, 10.0), st.floats(-30.0, 10.0), st.floats(0.1, 2.0))
def test_quintic_boundary_conditions(x0, v0, t1):
    """spec/qtg.md §7.1: x(0)=x0, x'(0)=v0 (clamped), x''(0)=a0, x(t1)=x'(t1)=x''(t1)=0, no overshoot."""
    p, v0c, t1c, a0, active = _poly(x0, v0, t1)
    assert active
    assert v0c == min(v0, 0.0)
    assert t1c <= t1 and t1c * v0c + 5 * x0 >= -1e-9
    assert a0 >= 0
    scale = max(1.0, abs(x0), abs(v0c))
    assert p(0) == pytest.approx(x0)
    assert p.deriv()(0) == pytest.approx(v0c, abs=1e-9 * scale)
    assert p.deriv(2)(0) == pytest.approx(a0, abs=1e-6 * scale / t1c ** 2)
    assert abs(p(t1c)) <= 1e-9 * scale
    assert abs(p.deriv()(t1c)) <= 1e-8 * scale / t1c
    assert abs(p.deriv(2)(t1c)) <= 1e-7 * scale / t1c ** 2
    t = np.linspace(0, 1.2 * t1, 200)
    x = quintic_inertialization(x0, v0, t1, t)
    assert_close(x[t < t1c], p(t[t < t1c]), rtol=1e-9, atol=1e-9 * scale)
    assert np.all(x[t >= t1c] == 0)
    assert np.all(x >= -1e-9 * scale)  # never overshoots the target


def test_quintic_degenerate_and_bad_inputs():
    """spec/qtg.md §7.1: a zero offset stays zero; bad arguments raise ValueError."""
    assert np.all(quintic_inertialization(0.0, -3.0, 1.0, np.linspace(0, 1, 5)) == 0)
    with pytest.raises(ValueError, match="x0"):
        quintic_inertialization(-1.0, 0.0, 1.0, [0.0])
    with pytest.raises(ValueError, match="blend_time"):
        quintic_inertialization(1.0, 0.0, 0.0, [0.0])
    with pytest.raises(ValueError, match="t"):
        quintic_inertialization(1.0, 0.0, 1.0, [[0.0]])


def test_inertialize_follows_the_scalar_curves():
    """spec/qtg.md §7.1: root offset along a fixed axis and joint rotation about a fixed axis follow x(t)."""
    dt, T = 1 / 30, 12
    axis = np.array([0.6, 0.0, 0.8])
    g_root = np.array([1.0, 2.0, 3.0])
    g_q = quat_normalize(np.array([0.9, 0.1, -0.3, 0.2]))
    raxis = np.array([0.0, 0.6, -0.8])
    past_root = np.stack([g_root + 5.0 * axis, g_root + 4.5 * axis])  # approaching
    past_q = np.stack([quat_mul(quat_from_axis_angle(a * raxis), g_q) for a in (0.9, 0.8)])
    past = join_pose(past_root[None], past_q[None, :, None])  # (1, 2, 7)
    target = join_pose(np.stack([g_root, g_root + 1])[None], np.stack([g_q, g_q])[None, :, None])
    out = inertialize(past, target, T, dt=dt)
    root, quats = split_pose(out[0])
    t = dt * np.arange(1, T + 1)
    x = quintic_inertialization(4.5, -0.5 / dt, (T + 1) * dt, t)
    assert_close(root, g_root + x[:, None] * axis, **TOL_EXACT)
    ang = quintic_inertialization(0.8, -0.1 / dt, (T + 1) * dt, t)
    assert_quat_close(quats[:, 0], quat_mul(quat_from_axis_angle(ang[:, None] * raxis), g_q), atol=1e-12)


def test_inertialize_starts_with_the_source_velocity_and_ends_on_target():
    """spec/qtg.md §7.1: frame 1 ≈ p0 + v0 dt (collinear velocity, no clamp), frames after t1 equal g1."""
    rng = np.random.default_rng(0)
    dt, T = 1e-3, 400
    g = _random_poses(rng, 1, 3)
    g[:, 1] = g[:, 0]
    d_root = np.array([0.3, -0.2, 0.5])
    raxis = quat_normalize(rng.standard_normal((3, 4)))[:, 1:]
    raxis /= np.linalg.norm(raxis, axis=-1, keepdims=True)
    g_root, g_q = split_pose(g[0, 0])

    def pose(s):  # offset s * (d, angle) from the target: source moving towards it as s decreases
        q = quat_mul(quat_from_axis_angle(0.5 * s * raxis), g_q)
        return join_pose(g_root + s * d_root, q)

    past = np.stack([pose(1.0), pose(1.0 - 0.2 * dt)])[None]  # speed 0.2 per second, slow (no t1 clamp)
    out = inertialize(past, g, T, dt=dt, blend_time=0.3)
    vel = (out[0, 0] - past[0, 1]) / dt
    expected = (past[0, 1] - past[0, 0]) / dt
    assert_close(vel[:3], expected[:3], rtol=0, atol=1e-2)
    q0 = split_pose(past[0, 1])[1]
    q1 = split_pose(out[0, 0])[1]
    assert_close(quat_angle(q0, q1) / dt, np.full(3, 0.5 * 0.2), rtol=0, atol=1e-3)
    after = out[0, int(round(0.3 / dt)):]
    assert np.all(after[:, :3] == g_root)
    assert_quat_close(split_pose(after)[1], np.broadcast_to(g_q, (len(after), 3, 4)), atol=1e-12)


def test_inertialize_matches_naive_loop_and_sign_invariance():
    """spec/qtg.md §7.1: vectorised == per-channel loop; q and −q in the inputs give the same rotations."""
    rng = np.random.default_rng(1)
    past, target = _random_poses(rng, 5, 4), _random_poses(rng, 5, 4)
    past[:, 0] = past[:, 1] + 0.05 * rng.standard_normal(past[:, 1].shape)  # small velocities
    out = inertialize(past, target, 9)
    assert_close(out, _inertialize_naive(past, target, 9), rtol=1e-10, atol=1e-12)
    flipped = past.copy()
    flipped[..., 3:] *= -1
    r1, q1 = split_pose(out)
    r2, q2 = split_pose(inertialize(flipped, target, 9))
    assert_close(r1, r2, **TOL_EXACT)
    assert_quat_close(q1, q2, atol=1e-10)
    assert_close(np.linalg.norm(q1, axis=-1), np.ones(q1.shape[:-1]), rtol=1e-12)
    assert out.shape == (5, 9, 19)


def test_interpolate_endpoints_and_spacing():
    """spec/qtg.md §7.2: α_k = k/(T+1); α=0 is p_0, α=1 is g1; root linear, rotations at constant angular speed."""
    rng = np.random.default_rng(2)
    past, target = _random_poses(rng, 3, 5), _random_poses(rng, 3, 5)
    T = 6
    out = interpolate(past, target, T)
    assert out.shape == (3, T, 23)
    full = np.concatenate([past[:, 1:], out, target[:, :1]], axis=1)  # p_0, p_1..p_T, g1
    root, quats = split_pose(full)
    steps = np.diff(root, axis=1)
    assert_close(steps, np.broadcast_to(steps[:, :1], steps.shape), rtol=1e-10, atol=1e-12)
    ang = quat_angle(quats[:, :-1], quats[:, 1:])  # (3, T+1, 5)
    assert_close(ang, np.broadcast_to(ang[:, :1], ang.shape), rtol=1e-8, atol=1e-10)
    # shortest path: total angle travelled <= π per joint
    assert np.all(ang.sum(axis=1) <= np.pi + 1e-9)
    # endpoints of the underlying interpolant
    from refimpl.protocols.transition_baselines import _interpolate_at
    ends = _interpolate_at(past[:, 1], target[:, 0], np.array([0.0, 1.0]))
    assert_close(ends[:, 0, :3], past[:, 1, :3], **TOL_EXACT)
    assert_close(ends[:, 1, :3], target[:, 0, :3], **TOL_EXACT)
    assert_quat_close(split_pose(ends[:, 0])[1], split_pose(past[:, 1])[1], atol=1e-12)
    assert_quat_close(split_pose(ends[:, 1])[1], split_pose(target[:, 0])[1], atol=1e-12)


def test_registry_and_qtg_method():
    """spec/qtg.md §7.3: the three methods share one interface in un-normalised space."""
    rng = np.random.default_rng(3)
    cfg = QTGConfig(pose_size=11, encoder_sizes=(6, 4), gru_hidden=5, decoder_sizes=(6,))
    params = init_params(cfg, rng)
    mean, std = np.array([1.0, -2.0, 3.0]), np.array([2.0, 0.5, 4.0])
    f = qtg_method(params, cfg, mean, std)
    methods = method_registry(f)
    assert tuple(methods) == METHOD_NAMES
    assert tuple(method_registry()) == METHOD_NAMES[1:]
    past, target = _random_poses(rng, 4, 2), _random_poses(rng, 4, 2)
    for name, m in methods.items():
        out = m(past, target, 5)
        assert out.shape == (4, 5, 11), name
        assert_close(np.linalg.norm(split_pose(out)[1], axis=-1), np.ones((4, 5, 2)), rtol=1e-9)
    ref, _ = rollout_forward(params, normalize_poses(past, mean, std), normalize_poses(target, mean, std), 5, cfg)
    ref = denormalize_poses(ref, mean, std)
    out = f(past, target, 5)
    assert_close(out[..., :3], ref[..., :3], rtol=1e-9, atol=1e-10)
    q = split_pose(ref)[1]
    assert_close(split_pose(out)[1], q / np.linalg.norm(q, axis=-1, keepdims=True), rtol=1e-9, atol=1e-10)


def test_bad_inputs():
    """Public boundaries raise ValueError naming the argument."""
    rng = np.random.default_rng(4)
    past, target = _random_poses(rng, 2, 2), _random_poses(rng, 2, 2)
    with pytest.raises(ValueError, match="target"):
        interpolate(past, target[:1], 3)
    with pytest.raises(ValueError, match="past"):
        inertialize(past[..., :10], target[..., :10], 3)
    with pytest.raises(ValueError, match="T"):
        interpolate(past, target, 0)
    with pytest.raises(ValueError, match="dt"):
        inertialize(past, target, 3, dt=0.0)
    zero = past.copy()
    zero[0, 1, 3:7] = 0
    with pytest.raises(ValueError, match="zero quaternion"):
        inertialize(zero, target, 3)
