"""Tests of the transition data and metrics (spec/qtg.md §8-§9)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from refimpl.bvh import read_bvh
from refimpl.protocols.transition_metrics import evaluate_methods, format_table, joint_position_errors, positions_from_poses
from refimpl.quat import quat_conj, quat_mul, quat_normalize, quat_rotate
from refimpl.rotations import quat_from_axis_angle
from refimpl.testing import TOL_EXACT, assert_close, assert_quat_close
from refimpl.protocols.transition import (CMU_22_JOINTS, CMU_UNIT_CM, SALSA_22_JOINTS, TransitionDataset, TransitionSource,
                                 build_transition_datasets, denormalize_poses, heading_from_root, join_pose,
                                 load_source, make_windows, normalize_poses, pose_size, sample_sources,
                                 scale_skeleton, split_pose, subset_22)

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"


def test_pose_layout_and_normalisation():
    """spec/qtg.md §8.1: [root (3) | J × (w, x, y, z)], z-normalised root only."""
    rng = np.random.default_rng(0)
    root, quats = rng.standard_normal((4, 5, 3)), rng.standard_normal((4, 5, 22, 4))
    poses = join_pose(root, quats)
    assert poses.shape == (4, 5, pose_size(22)) == (4, 5, 91)
    assert_close(poses[..., 3:7], quats[..., 0, :], **TOL_EXACT)
    r, q = split_pose(poses)
    assert np.array_equal(r, root) and np.array_equal(q, quats)
    mean, std = np.array([1.0, 2.0, 3.0]), np.array([2.0, 4.0, 0.5])
    n = normalize_poses(poses, mean, std)
    assert_close(n[..., :3], (root - mean) / std, **TOL_EXACT)
    assert np.array_equal(n[..., 3:], poses[..., 3:])
    assert_close(denormalize_poses(n, mean, std), poses, **TOL_EXACT)
    with pytest.raises(ValueError, match="poses"):
        split_pose(np.zeros((2, 10)))
    with pytest.raises(ValueError, match="root_std"):
        normalize_poses(poses, mean, np.zeros(3))


def test_heading_is_the_twist_about_y():
    """spec/qtg.md §8.2: h = normalise(w, 0, y, 0); h⁻¹ ⊗ q has no rotation about y left in its twist."""
    rng = np.random.default_rng(1)
    q = quat_normalize(rng.standard_normal((50, 4)))
    h = heading_from_root(q)
    assert_close(h[:, [1, 3]], np.zeros((50, 2)), **TOL_EXACT)
    assert_close(np.linalg.norm(h, axis=-1), np.ones(50), **TOL_EXACT)
    rest = quat_mul(quat_conj(h), q)
    assert_close(rest[:, 2], np.zeros(50), rtol=0, atol=1e-12)
    yaw = quat_from_axis_angle(np.array([[0.0, 0.7, 0.0]]))
    assert_quat_close(heading_from_root(yaw), yaw, atol=1e-12)


def _clip():
    motion = read_bvh(SAMPLE / "bvh" / "02_01.bvh")
    skel, rot = subset_22(motion.skeleton, np.asarray(motion.rotations)[1:120:4], CMU_22_JOINTS)
    return skel, rot, np.asarray(motion.root_positions)[1:120:4]


def test_windows_are_root_relative_and_consistent_with_fk():
    """spec/qtg.md §8.2: FK of a window = R(h)⁻¹ (FK of the clip − r_0): one rigid motion per window."""
    skel, rot, pos = _clip()
    W = 10
    win = make_windows(rot, pos, length=W, stride=3)
    assert win.shape == ((len(rot) - W) // 3 + 1, W, 91)
    fk_clip = skel.forward_kinematics(rot, pos)  # (F, 22, 3)
    for i in range(len(win)):
        s = 3 * i
        r0, h = pos[s], heading_from_root(rot[s, 0])
        expected = quat_rotate(quat_conj(h), fk_clip[s:s + W] - r0)
        assert_close(positions_from_poses(win[i], skel), expected, rtol=0, atol=1e-9)
        root, quats = split_pose(win[i])
        assert_close(root[0], np.zeros(3), rtol=0, atol=1e-12)
        assert_close(heading_from_root(quats[0, 0]), np.array([1.0, 0, 0, 0]), rtol=0, atol=1e-12)
        assert np.all(quats[0, :, 0] >= 0)  # first frame in the w >= 0 hemisphere
        assert np.all(np.sum(quats[1:] * quats[:-1], axis=-1) >= 0)  # continuous
    plain = make_windows(rot, pos, length=W, stride=3, relative_heading=False)
    assert_close(split_pose(plain)[0][0], pos[:W] - pos[0], rtol=0, atol=1e-12)
    assert_close(split_pose(plain)[1][:, :, 1:], split_pose(win)[1][:, :, 1:], rtol=0, atol=0)  # only the root differs
    assert make_windows(rot[:5], pos[:5], length=W).shape == (0, W, 91)


def test_subset_positions():
    """spec/qtg.md §8.1: the 22-joint subsets keep the kept joints' positions (CMU: except Neck1/Head,
    because Neck's rotation is pushed into Neck1; salsa: exact)."""
    motion = read_bvh(SAMPLE / "bvh" / "02_01.bvh")
    rot, pos = np.asarray(motion.rotations)[1:60], np.asarray(motion.root_positions)[1:60]
    full = motion.skeleton.forward_kinematics(rot, pos)
    skel, r22 = subset_22(motion.skeleton, rot, CMU_22_JOINTS)
    assert skel.names == CMU_22_JOINTS
    sub = skel.forward_kinematics(r22, pos)
    for j, name in enumerate(CMU_22_JOINTS):
        err = np.abs(sub[:, j] - full[:, motion.skeleton.index(name)]).max()
        if name in ("Neck1", "Head"):
            assert err < 0.5  # ASF units; ≈ |offset| × neck angle
        else:
            assert err < 1e-9, name
    salsa = read_bvh(SAMPLE / "salsa" / "01.bvh", frame_time=1 / 60)
    rot, pos = np.asarray(salsa.rotations)[1:40], np.asarray(salsa.root_positions)[1:40]
    skel, r22 = subset_22(salsa.skeleton, rot, SALSA_22_JOINTS)
    full = salsa.skeleton.forward_kinematics(rot, pos)
    idx = [salsa.skeleton.index(n) for n in SALSA_22_JOINTS]
    assert_close(skel.forward_kinematics(r22, pos), full[:, idx], rtol=0, atol=1e-9)
    with pytest.raises(ValueError, match="keep"):
        subset_22(salsa.skeleton, rot, ("abdomen", "hip"))


def test_load_source_rates_and_units():
    """spec/qtg.md §8.3: every subsampling phase is a clip; CMU lengths converted to centimetres."""
    src = TransitionSource(str(SAMPLE / "bvh" / "02_01.bvh"), "cmu_bvh", 120.0, "walk")
    skel, clips = load_source(src)
    assert len(clips) == 4 and sum(len(r) for r, _ in clips) == 343
    motion = read_bvh(SAMPLE / "bvh" / "02_01.bvh")
    assert_close(clips[1][1], np.asarray(motion.root_positions)[2::4] * CMU_UNIT_CM, **TOL_EXACT)
    ref, _ = subset_22(motion.skeleton, np.asarray(motion.rotations)[:2], CMU_22_JOINTS)
    assert_close(skel.offsets, scale_skeleton(ref, CMU_UNIT_CM).offsets, **TOL_EXACT)
    s_src = TransitionSource(str(SAMPLE / "salsa" / "16.bvh"), "salsa_bvh", 60.0, "salsa", (0.0, 0.1))
    s_skel, s_clips = load_source(s_src)
    assert len(s_clips) == 2 and s_skel.names == SALSA_22_JOINTS
    with pytest.raises(ValueError, match="fps"):
        load_source(TransitionSource(src.path, "cmu_bvh", 100.0, "walk"))
    with pytest.raises(ValueError, match="kind"):
        load_source(TransitionSource(src.path, "bvh", 120.0, "walk"))


def test_build_datasets_split_and_statistics():
    """spec/qtg.md §8.3: split by file, statistics from the training windows only."""
    run = sorted((SAMPLE / "expmap" / "train" / "running").glob("*.txt"))[:2]
    train_src = [TransitionSource(str(f), "cmu_expmap", 120.0, "run") for f in run]
    test_src = [TransitionSource(str(SAMPLE / "expmap" / "test" / "running" / "running_1.txt"), "cmu_expmap",
                                 120.0, "run")]
    train, test = build_transition_datasets(train_src, test_src, T=10, stride=2)
    assert train.poses.shape[1:] == (14, 91) and test.transition_length == 10
    assert len(train.skeletons) == 1 and np.all(train.skeleton_index == 0)
    root = train.poses[..., :3].reshape(-1, 3)
    assert_close(train.root_mean, root.mean(0), **TOL_EXACT)
    assert np.array_equal(test.root_mean, train.root_mean) and np.array_equal(test.root_std, train.root_std)
    assert set(train.source_index) == {0, 1} and set(test.source_index) == {0}
    past, trans, target = test.context()
    assert past.shape[1] == 2 and trans.shape[1] == 10 and target.shape[1] == 2
    assert_close(test.context(normalized=True)[0][..., :3], (past[..., :3] - train.root_mean) / train.root_std,
                 **TOL_EXACT)
    sub = train.select(train.source_index == 1)
    assert sub.num_windows == int(np.sum(train.source_index == 1)) and set(sub.source_index) == {1}
    assert np.array_equal(sub.poses, train.poses[train.source_index == 1])
    assert sub.skeletons is train.skeletons and np.array_equal(sub.root_std, train.root_std)
    with pytest.raises(ValueError, match="also a training source"):
        build_transition_datasets(train_src, train_src[:1], T=10)
    tr, te = sample_sources()
    assert not {(s.path, s.frames) for s in tr} & {(s.path, s.frames) for s in te}
    assert not any(s.path.endswith("walking_1.txt") and "train" in s.path for s in tr)
    assert {s.label for s in tr} == {s.label for s in te} == {"walk", "run", "jump", "salsa"}


def test_metrics():
    """spec/qtg.md §9: Euclidean joint error per joint per frame in cm; evaluation table of all methods."""
    skel, rot, pos = _clip()
    win = make_windows(rot, pos, length=9, stride=4)  # T = 5
    n = len(win)
    shifted = win.copy()
    shifted[..., :3] += np.array([3.0, 0.0, 4.0])  # every joint moves by 5
    dist, absc = joint_position_errors(shifted, win, [skel], np.zeros(n, int))
    assert_close(dist, np.full(dist.shape, 5.0), rtol=1e-12)
    assert_close(absc, np.full(dist.shape, 7.0 / 3.0), rtol=1e-12)
    scaled = win.copy()
    scaled[..., 3:] *= 2.0  # not unit: normalised before FK
    assert np.abs(joint_position_errors(scaled, win, [skel], np.zeros(n, int))[0]).max() < 1e-9
    ds = TransitionDataset(poses=win, skeleton_index=np.zeros(n, int), skeletons=(skel,),
                           source_index=np.zeros(n, int), sources=(TransitionSource("x", "cmu_bvh", 120.0, "walk"),),
                           root_mean=np.zeros(3), root_std=np.ones(3))
    gt = ds.context()[1]

    def oracle(past, target, T):
        i = [int(np.flatnonzero(np.all(ds.poses[:, :2] == p, axis=(1, 2)))[0]) for p in past]
        return gt[i]

    def off(past, target, T):
        return oracle(past, target, T) + np.r_[3.0, 0.0, 4.0, np.zeros(88)]

    res = evaluate_methods(ds, {"oracle": oracle, "off": off}, batch_size=2)
    assert res["oracle"]["mean_cm"] == 0.0 and res["off"]["mean_cm"] == pytest.approx(5.0)
    assert res["off"]["per_frame_cm"].shape == (5,) and res["off"]["by_label"] == {"walk": pytest.approx(5.0)}
    table = format_table(res)
    assert "oracle" in table and "off" in table and "5.00" in table
    with pytest.raises(ValueError, match="methods"):
        evaluate_methods(ds, {"bad": lambda p, t, T: gt[:len(p), :2]})


def test_shared_sources_exist_and_are_disjoint(shared_data):
    """spec/qtg.md §8.3: the ../shared/data split names existing files, split by file (01_01 by time)."""
    from refimpl.protocols.transition import shared_sources

    tr, te = shared_sources(shared_data)
    for s in tr + te:
        assert Path(s.path).is_file(), s.path
    assert not {(s.path, s.frames) for s in tr} & {(s.path, s.frames) for s in te}
    by_time = {s.path for s in tr} & {s.path for s in te}
    assert {Path(p).name for p in by_time} == {"01_01.bvh"}
    assert {Path(s.path).name for s in te if s.label == "salsa"} == {"05.bvh", "20.bvh"}
