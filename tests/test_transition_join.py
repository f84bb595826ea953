"""Tests of the join option (refimpl/protocols/transition_join.py, spec/qtg.md §7.4): the inertialised joins."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.protocols.transition_baselines import inertialize
from refimpl.models.qtg import QTGConfig, init_params
from refimpl.quat import quat_conj, quat_mul, quat_normalize
from refimpl.rotations import quat_from_axis_angle
from refimpl.recipes.qtg import qtg_method
from refimpl.testing import assert_close, assert_quat_close
from refimpl.protocols.transition_join import (JOIN_BLEND_FRAMES, carry_offset, check_join, inertialize_joins,
                                     join_blend_frames, with_join)
from refimpl.protocols.transition_quality import evaluate_quality
from refimpl.protocols.transition import join_pose, split_pose

DT = 1.0 / 30.0


def _poses(rng, B, F, J, spread=0.3):
    root = rng.standard_normal((B, F, 3)) * 10
    q = quat_from_axis_angle(spread * rng.standard_normal((B, F, J, 3)))
    return join_pose(root, q)


def test_carry_offset_reproduces_the_inertialization_baseline():
    """Onto a static pose, carry_offset is the baseline's inertialisation: with the past moved one frame back
    (``a = 2 p_{-1} − p_0``, rotations ``q_{-1} ⊗ q_0⁻¹ ⊗ q_{-1}``) its frame 0 is ``p_0`` and frames 1 … T
    equal :func:`refimpl.protocols.transition_baselines.inertialize`."""
    rng = np.random.default_rng(0)
    B, J, T = 5, 4, 8
    past, target = _poses(rng, B, 2, J), _poses(rng, B, 2, J)
    (r_m1, q_m1), (r_0, q_0) = split_pose(past[:, 0]), split_pose(past[:, 1])
    a = join_pose(2 * r_m1 - r_0, quat_mul(quat_mul(q_m1, quat_conj(q_0)), q_m1))
    prev = np.stack([a, past[:, 0]], axis=1)
    frames = np.repeat(target[:, :1], T + 1, axis=1)
    got = carry_offset(prev, frames, DT, (T + 1) * DT)
    want = inertialize(past, target, T, dt=DT)
    assert_close(got[:, 1:, :3], want[..., :3], rtol=1e-10, atol=1e-10)
    assert_quat_close(split_pose(got[:, 1:])[1], split_pose(want)[1], atol=1e-10)
    assert_close(got[:, 0, :3], past[:, 1, :3], rtol=1e-10, atol=1e-10)


def test_first_and_last_frames_continue_the_context_and_the_middle_is_untouched():
    rng = np.random.default_rng(1)
    B, J, T = 3, 5, 30
    past, target = _poses(rng, B, 2, J, 0.1), _poses(rng, B, 2, J, 0.1)
    gen = _poses(rng, B, T, J, 0.5)
    out = inertialize_joins(past, gen, target, dt=DT)
    (r_m1, q_m1), (r_0, q_0) = split_pose(past[:, 0]), split_pose(past[:, 1])
    (r_g1, q_g1), (r_g2, q_g2) = split_pose(target[:, 0]), split_pose(target[:, 1])
    assert_close(out[:, 0, :3], 2 * r_0 - r_m1, rtol=1e-10, atol=1e-10)
    assert_quat_close(split_pose(out[:, 0])[1], quat_mul(quat_mul(q_0, quat_conj(q_m1)), q_0), atol=1e-10)
    assert_close(out[:, -1, :3], 2 * r_g1 - r_g2, rtol=1e-10, atol=1e-10)
    assert_quat_close(split_pose(out[:, -1])[1], quat_mul(quat_mul(q_g1, quat_conj(q_g2)), q_g1), atol=1e-10)
    n = join_blend_frames(T)
    assert n == JOIN_BLEND_FRAMES
    assert_close(out[:, n:T - n, :3], gen[:, n:T - n, :3], rtol=0, atol=1e-12)  # outside both blends: unchanged
    assert_quat_close(split_pose(out[:, n:T - n])[1], split_pose(gen[:, n:T - n])[1], atol=1e-12)
    assert np.allclose(np.linalg.norm(split_pose(out)[1], axis=-1), 1.0)


def test_a_transition_without_offset_is_unchanged():
    """Context and frames on one constant-velocity line: nothing to carry away."""
    J, T = 3, 12
    q = quat_normalize(np.array([1.0, 0.2, -0.1, 0.3]))
    k = np.arange(-1, T + 3)[None, :, None]
    root = np.array([2.0, 0.0, 1.0]) * k  # (1, T + 4, 3)
    poses = join_pose(root, np.broadcast_to(q, (1, T + 4, J, 4)))
    out = inertialize_joins(poses[:, :2], poses[:, 2:-2], poses[:, -2:], dt=DT)
    assert_close(out, poses[:, 2:-2], rtol=0, atol=1e-12)


def test_options():
    assert check_join("none") == "none" and check_join("inertialize") == "inertialize"
    with pytest.raises(ValueError, match="join"):
        check_join("smooth")
    f = lambda past, target, T: np.zeros((1, T, 7))  # noqa: E731
    assert with_join(f, "none") is f
    assert join_blend_frames(1) == 1 and join_blend_frames(7) == 3 and join_blend_frames(100) == JOIN_BLEND_FRAMES
    past = np.zeros((1, 2, 7))
    past[..., 3] = 1
    with pytest.raises(ValueError, match="blend_frames"):
        inertialize_joins(past, np.repeat(past, 2, axis=1), past, blend_frames=0)
    with pytest.raises(ValueError, match="poses"):
        inertialize_joins(past, np.zeros((1, 3, 11)), past)


@pytest.fixture(scope="module")
def sample_test():
    from refimpl.tasks.transition import build_datasets

    train, test = build_datasets("sample", 30, 1, test_stride=4)
    return train, test


def test_joins_within_1_5x_of_the_truth_on_the_sample(sample_test):
    """On real held-out windows, an untrained QTG pops at both ends; with the join option the displacement into
    the first and out of the last frame is within 1.5x of the ground truth's."""
    train, test = sample_test
    config = QTGConfig(pose_size=91, encoder_sizes=(32, 16), gru_hidden=32, decoder_sizes=(32,), transition_length=30)
    net = qtg_method(init_params(config, np.random.default_rng(0)), config, train.root_mean, train.root_std)
    q = evaluate_quality(test, {"qtg": net, "qtg+join": with_join(net, dt=DT)})
    raw, joined, truth = q["qtg"], q["qtg+join"], q["qtg"]["ground_truth"]
    assert raw["join_in_cm"] > 2 * truth["join_in_cm"] and raw["join_out_cm"] > 2 * truth["join_out_cm"]
    for key in ("join_in_cm", "join_out_cm"):
        assert truth[key] / 1.5 <= joined[key] <= 1.5 * truth[key], (key, joined[key], truth[key])
