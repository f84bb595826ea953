"""Tests of refimpl.skeleton and refimpl.skeletons (spec/kinematics.md).

Three independent forward kinematics are compared everywhere: quaternions (QuaterNet's definition), 4x4
matrices, and current dual quaternions + root position (dual-quaternion paper Eq. 8-11), plus a slow per-joint
loop. They are checked on random skeletons (hypothesis), on hand-computed poses and on every real file.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.bvh import read_bvh
from refimpl.dualquat import dq_from_quat_translation
from refimpl.expmap import read_expmap
from refimpl.quat import quat_mul, quat_normalize
from refimpl.rotations import matrix_from_quat, quat_from_axis_angle
from refimpl.skeleton import UNIT_TOLERANCE, Skeleton, _forward_kinematics_naive, remove_joints
from refimpl.mirroring import mirror, random_rotate_about_up, rotate_about_up
from refimpl.current_dq import (_current_dq_from_local_naive, current_dq_from_local, local_from_current_dq,
                                offsets_from_current_dq, positions_from_current_dq)
from refimpl.skeletons import (CMU_ASF_PARENTS, CMU_PARENTS, H36M_PARENTS, LOCOMOTION_REMOVED_JOINTS,
                               cmu_asf_skeleton, cmu_skeleton, h36m_skeleton, quaternet_locomotion_skeleton)
from refimpl.strategies import skeleton_arrays, unit_quaternions
from refimpl.testing import assert_close, assert_quat_close

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"
TIGHT = dict(rtol=1e-10, atol=1e-10)


def random_unit(rng, shape):
    return quat_normalize(rng.normal(size=shape + (4,)))


@st.composite
def skeleton_and_pose(draw, max_joints=8):
    parents, offsets = draw(skeleton_arrays(1, max_joints))
    frames = draw(st.integers(1, 3))
    rot = draw(unit_quaternions((frames, len(parents))))
    root = draw(st.lists(st.floats(-5, 5), min_size=3 * frames, max_size=3 * frames))
    return Skeleton(parents, offsets), rot, np.array(root).reshape(frames, 3)


# ------------------------------------------------------------------------------------------------------------
# Skeleton value: validation and metadata (spec/kinematics.md §1)
# ------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("parents, match", [
    ([0, -1], "joint 0 must be the root"),
    ([-1, 0, -1], "exactly one root"),
    ([-1, 1], "parents must precede"),
    ([-1, 0, 3, 1], "parents must precede"),
    ([-1, 0, -2], "parents must precede"),
    ([], "non-empty"),
    ([-1, 0.5], "integers"),
])
def test_skeleton_rejects_bad_parents(parents, match):
    """spec/kinematics.md §1: topological order is required and checked."""
    with pytest.raises(ValueError, match=match):
        Skeleton(parents, np.zeros((len(parents), 3)))


def test_skeleton_rejects_bad_arguments():
    """spec/kinematics.md §1: offsets, names, End Sites and side lists are validated."""
    with pytest.raises(ValueError, match=r"offsets: expected shape \(2, 3\)"):
        Skeleton([-1, 0], np.zeros((3, 3)))
    with pytest.raises(ValueError, match="NaN"):
        Skeleton([-1, 0], [[0, 0, 0], [np.nan, 0, 0]])
    with pytest.raises(ValueError, match="unique"):
        Skeleton([-1, 0], np.zeros((2, 3)), names=["a", "a"])
    with pytest.raises(ValueError, match="expected 2 names"):
        Skeleton([-1, 0], np.zeros((2, 3)), names=["a"])
    with pytest.raises(ValueError, match="End Site must be a leaf"):
        Skeleton([-1, 0, 1], np.zeros((3, 3)), end_sites=[1])
    with pytest.raises(ValueError, match="out of range"):
        Skeleton([-1, 0], np.zeros((2, 3)), end_sites=[0])
    with pytest.raises(ValueError, match="both lists"):
        Skeleton([-1, 0, 0], np.zeros((3, 3)), joints_left=[1])
    with pytest.raises(ValueError, match="equal length"):
        Skeleton([-1, 0, 0], np.zeros((3, 3)), joints_left=[1, 2], joints_right=[2])
    with pytest.raises(ValueError, match="appears twice"):
        Skeleton([-1, 0, 0], np.zeros((3, 3)), joints_left=[1], joints_right=[1])


def test_skeleton_is_an_immutable_value():
    """spec/kinematics.md §1: read-only arrays, value equality, children metadata."""
    s = Skeleton([-1, 0, 1, 0], np.arange(12.0).reshape(4, 3), names=["r", "a", "b", "c"], end_sites=[2])
    assert s.num_joints == 4
    assert s.children == ((1, 3), (2,), (), ())
    assert s.end_sites == (2,)
    assert s.index("b") == 2
    with pytest.raises(ValueError, match="no joint called"):
        s.index("zz")
    with pytest.raises(ValueError):
        s.offsets[0, 0] = 1.0
    with pytest.raises(ValueError):
        s.parents[1] = 0
    t = Skeleton([-1, 0, 1, 0], np.arange(12.0).reshape(4, 3), names=["r", "a", "b", "c"], end_sites=[2])
    assert s == t and hash(s) == hash(t)
    assert s != Skeleton([-1, 0, 1, 0], np.zeros((4, 3)), names=["r", "a", "b", "c"], end_sites=[2])


def test_left_right_inferred_from_names():
    """spec/kinematics.md §1: side prefixes Left/L/l and Right/R/r pair joints with the same stem."""
    names = ["Hips", "LHipJoint", "RHipJoint", "LeftUpLeg", "RightUpLeg", "LowerBack", "lCollar", "rCollar",
             "leftEye", "rightEye", "LThumb", "Root", "lonely_L", "LOnlyLeft"]
    parents = [-1] + [0] * (len(names) - 1)
    s = Skeleton(parents, np.zeros((len(names), 3)), names=names)
    pairs = {(names[a], names[b]) for a, b in zip(s.joints_left, s.joints_right)}
    assert pairs == {("LHipJoint", "RHipJoint"), ("LeftUpLeg", "RightUpLeg"), ("lCollar", "rCollar"),
                     ("leftEye", "rightEye")}
    given_lists = Skeleton(parents, np.zeros((len(names), 3)), names=names, joints_left=[3], joints_right=[4])
    assert given_lists.joints_left == (3,) and given_lists.joints_right == (4,)


def test_builtin_skeleton_data():
    """spec/kinematics.md §6 and spec/data.md §3: the built-in tables (parents, End Sites, counts, sides)."""
    h = h36m_skeleton()
    assert h.num_joints == 32 and tuple(h.parents) == H36M_PARENTS
    assert h.end_sites == (5, 10, 15, 21, 23, 29, 31)
    # 3d-pose-baseline semantics: joint 1 right hip (x < 0), joint 6 left hip (x > 0)
    assert h.offsets[1, 0] < 0 < h.offsets[6, 0]
    assert h.joints_left == (6, 7, 8, 9, 10, 16, 17, 18, 19, 20, 21, 22, 23)
    assert h.joints_right == (1, 2, 3, 4, 5, 24, 25, 26, 27, 28, 29, 30, 31)
    a = cmu_asf_skeleton()
    assert a.num_joints == 38 and tuple(a.parents) == CMU_ASF_PARENTS
    assert a.end_sites == (6, 12, 19, 26, 28, 35, 37)
    assert_close(np.linalg.norm(a.offsets[3]), 7.5937, atol=1e-4)  # thigh, dualquat_acrnn_qtg.md §6
    c = cmu_skeleton()
    assert c.num_joints == 31 and tuple(c.parents) == CMU_PARENTS and c.end_sites == ()
    loco = quaternet_locomotion_skeleton()
    assert loco.num_joints == 31 and tuple(loco.parents) == CMU_PARENTS
    reduced = quaternet_locomotion_skeleton(reduced=True)
    assert reduced.num_joints == 26
    assert reduced.parents.tolist() == [-1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 0, 11, 12, 13, 14, 12, 16, 17, 18, 19,
                                        12, 21, 22, 23, 24]
    leaves = [j for j in range(26) if not reduced.children[j]]
    assert leaves == [5, 10, 15, 20, 25]
    # QuaterNet quirk §3.6: rest-pose top 7.59 with 31 joints, 5.54 with 26 (Spine1's offset dropped)
    ident = lambda n: np.tile([1.0, 0, 0, 0], (n, 1))  # noqa: E731
    top31 = loco.forward_kinematics(ident(31), np.zeros(3))[:, 1].max()
    top26 = reduced.forward_kinematics(ident(26), np.zeros(3))[:, 1].max()
    assert_close(top31, 7.59, atol=0.01)
    assert_close(top26, 5.54, atol=0.01)


# ------------------------------------------------------------------------------------------------------------
# forward kinematics (spec/kinematics.md §2)
# ------------------------------------------------------------------------------------------------------------

@given(skeleton_and_pose())
def test_fk_quaternions_matrices_dual_quaternions_agree(case):
    """spec/kinematics.md §2-3: FK by quaternions = by 4x4 matrices = current DQ translations + root = naive loop."""
    skel, rot, root = case
    p_quat = skel.forward_kinematics(rot, root)
    assert p_quat.shape == rot.shape[:-1] + (3,)
    assert_close(p_quat, skel.forward_kinematics_matrices(rot, root), **TIGHT)
    assert_close(p_quat, _forward_kinematics_naive(skel.parents, skel.offsets, rot, root), **TIGHT)
    dq = current_dq_from_local(rot, skel.offsets, skel.parents)
    assert_close(dq, _current_dq_from_local_naive(skel.parents, rot, skel.offsets), **TIGHT)
    assert_close(p_quat, positions_from_current_dq(dq) + root[..., None, :], **TIGHT)
    # world rotations: the real parts of the current DQs
    assert_close(skel.world_rotations(rot), dq[..., :4], **TIGHT)


def test_fk_hand_computed():
    """spec/kinematics.md §2: p_j = p_parent + R(q_world_parent) offset_j, q_world = q_parent ⊗ q_local."""
    skel = Skeleton([-1, 0, 1, 2], [[5.0, 5, 5], [1, 0, 0], [0, 2, 0], [0, 0, 3]])
    quarter_z = quat_from_axis_angle([0, 0, math.pi / 2])
    quarter_x = quat_from_axis_angle([math.pi / 2, 0, 0])
    rot = np.stack([quarter_z, quarter_x, [1.0, 0, 0, 0], [1.0, 0, 0, 0]])
    pos = skel.forward_kinematics(rot, np.array([10.0, 0, 0]))
    # root offset ignored; joint 1 = root + Rz(90°)(1,0,0); joint 2 = + Rz Rx (0,2,0) = + Rz (0,0,2)
    expected = np.array([[10, 0, 0], [10, 1, 0], [10, 1, 2], [10 + 3, 1, 2]], dtype=float)
    # joint 3: + Rz Rx (0,0,3) = Rz (0,-3,0) = (3,0,0)
    assert_close(pos, expected, atol=1e-12)
    # a leaf's own rotation never moves a position (QuaterNet §3.2)
    rot2 = rot.copy()
    rot2[3] = quarter_x
    assert_close(skel.forward_kinematics(rot2, np.array([10.0, 0, 0])), expected, atol=1e-12)


def test_fk_rest_pose_is_cumulative_offsets():
    """spec/kinematics.md §2: with identity rotations every joint sits at root + sum of offsets on its path."""
    skel = cmu_asf_skeleton()
    rot = np.tile([1.0, 0, 0, 0], (skel.num_joints, 1))
    pos = skel.forward_kinematics(rot, np.array([1.0, 2, 3]))
    for j in range(skel.num_joints):
        acc, k = np.array([1.0, 2, 3]), j
        while k > 0:
            acc = acc + skel.offsets[k]
            k = skel.parents[k]
        assert_close(pos[j], acc, atol=1e-12)


def test_fk_batch_float32_and_validation():
    """spec/kinematics.md §2: leading axes broadcast, float32 stays float32, bad input raises ValueError."""
    rng = np.random.default_rng(0)
    skel = h36m_skeleton()
    rot = random_unit(rng, (2, 5, 32))
    root = rng.normal(size=(2, 5, 3))
    p64 = skel.forward_kinematics(rot, root)
    p32 = skel.forward_kinematics(rot.astype(np.float32), root.astype(np.float32))
    assert p32.dtype == np.float32
    assert_close(p32, p64, rtol=1e-4, atol=1e-2)  # millimetres, float32
    for b in range(2):
        assert_close(skel.forward_kinematics(rot[b], root[b]), p64[b], **TIGHT)
    with pytest.raises(ValueError, match=r"rotations: expected shape \(\.\.\., 32, 4\)"):
        skel.forward_kinematics(rot[..., :31, :], root)
    with pytest.raises(ValueError, match="root_positions: expected shape"):
        skel.forward_kinematics(rot, root[:, :4])
    with pytest.raises(ValueError, match="unit quaternions"):
        skel.forward_kinematics(rot * (1 + 10 * UNIT_TOLERANCE), root)
    bad = rot.copy()
    bad[0, 0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        skel.forward_kinematics(bad, root)


# ------------------------------------------------------------------------------------------------------------
# current coordinates (spec/kinematics.md §3)
# ------------------------------------------------------------------------------------------------------------

@given(skeleton_and_pose())
def test_local_current_local_is_identity(case):
    """spec/kinematics.md §3 (paper Eq. 9-12): local → current → local returns ±q and the offsets."""
    skel, rot, _ = case
    dq = current_dq_from_local(rot, skel.offsets, skel.parents)
    assert dq.shape == rot.shape[:-1] + (8,)
    assert_close(dq[..., 0, 4:], np.zeros(dq.shape[:-2] + (4,)), atol=0)  # Eq. 9: root has no dual part
    back_rot, back_off = local_from_current_dq(dq, skel.parents)
    assert_quat_close(back_rot, rot, atol=1e-10)
    expected_off = np.broadcast_to(skel.offsets, back_off.shape).copy()
    expected_off[..., 0, :] = 0
    assert_close(back_off, expected_off, atol=1e-10)
    assert_close(offsets_from_current_dq(dq, skel.parents), expected_off, atol=1e-10)


def test_current_dq_matches_homogeneous_matrices():
    """spec/kinematics.md §3: C_j equals the DQ of M_curr,j = M_curr,parent · M_loc,j (Eq. 9-11)."""
    rng = np.random.default_rng(3)
    skel = cmu_skeleton()
    rot = random_unit(rng, (4, 31))
    dq = current_dq_from_local(rot, skel.offsets, skel.parents)
    mats = np.zeros((4, 31, 4, 4))
    for j, p in enumerate(skel.parents):
        local = np.eye(4)[None].repeat(4, 0)
        local[:, :3, :3] = matrix_from_quat(rot[:, j])
        local[:, :3, 3] = 0 if p < 0 else skel.offsets[j]
        mats[:, j] = local if p < 0 else mats[:, p] @ local
    from refimpl.dualquat import dq_from_matrix
    assert_quat_close(dq[..., :4], dq_from_matrix(mats)[..., :4], atol=1e-10)
    assert_close(positions_from_current_dq(dq), mats[..., :3, 3], atol=1e-10)
    # per-joint offsets may vary per frame (e.g. different subjects in one batch)
    offs = np.broadcast_to(skel.offsets, (4, 31, 3)) * rng.uniform(0.5, 2, size=(4, 1, 1))
    dq2 = current_dq_from_local(rot, offs, skel.parents)
    _, back = local_from_current_dq(dq2, skel.parents)
    assert_close(back[:, 1:], offs[:, 1:], atol=1e-10)


def test_current_dq_validation():
    """spec/kinematics.md §3: wrong shapes raise ValueError naming the argument."""
    skel = cmu_skeleton()
    with pytest.raises(ValueError, match="rotations"):
        current_dq_from_local(np.zeros((2, 30, 4)), skel.offsets, skel.parents)
    with pytest.raises(ValueError, match="offsets"):
        current_dq_from_local(np.tile([1.0, 0, 0, 0], (31, 1)), np.zeros((30, 3)), skel.parents)
    with pytest.raises(ValueError, match="dqs"):
        local_from_current_dq(np.zeros((2, 31, 7)), skel.parents)
    with pytest.raises(ValueError, match="parents"):
        local_from_current_dq(np.zeros((2, 2, 8)), [0, 0])


# ------------------------------------------------------------------------------------------------------------
# joint removal (spec/kinematics.md §4)
# ------------------------------------------------------------------------------------------------------------

def test_remove_end_sites_keeps_positions_exactly():
    """spec/kinematics.md §4: removing identity-rotation joints with offsets='compose' keeps every position."""
    rng = np.random.default_rng(1)
    asf = cmu_asf_skeleton()
    rot = random_unit(rng, (3, 38))
    rot[:, list(asf.end_sites)] = [1.0, 0, 0, 0]
    root = rng.normal(size=(3, 3))
    small, small_rot = remove_joints(asf, rot, asf.end_sites)
    kept = [j for j in range(38) if j not in asf.end_sites]
    assert small == cmu_skeleton()
    assert_close(small.forward_kinematics(small_rot, root), asf.forward_kinematics(rot, root)[:, kept], **TIGHT)


def test_remove_joint_pushes_rotation_into_children():
    """spec/kinematics.md §4: q_child ← q_removed ⊗ q_child; positions exact when the removed rotation is the
    identity."""
    rng = np.random.default_rng(2)
    skel = cmu_skeleton()  # LowerBack (11), LeftShoulder (17), LeftFingerBase (21) have zero offsets; Spine1 (13) not
    rot = random_unit(rng, (4, 31))
    rot[:, [11, 17, 21]] = [1.0, 0, 0, 0]
    root = rng.normal(size=(4, 3))
    full = skel.forward_kinematics(rot, root)
    for mode in ("compose", "drop"):  # zero offsets: both modes agree
        new, new_rot = remove_joints(skel, rot, ["LeftShoulder", 21, 11], offsets=mode)
        kept = [j for j in range(31) if j not in (11, 17, 21)]
        assert new.names == tuple(skel.names[j] for j in kept)
        assert new.joints_left == tuple(kept.index(j) for j in skel.joints_left if j not in (17, 21))
        assert_close(new.forward_kinematics(new_rot, root), full[:, kept], **TIGHT)
    # chains of removed joints compose in order: remove 12 and 13 (Spine, Spine1), identity rotations on them
    rot2 = rot.copy()
    rot2[:, [12, 13]] = [1.0, 0, 0, 0]
    full2 = skel.forward_kinematics(rot2, root)
    new, new_rot = remove_joints(skel, rot2, [13, 12], offsets="compose")
    kept = [j for j in range(31) if j not in (12, 13)]
    assert_close(new.forward_kinematics(new_rot, root), full2[:, kept], **TIGHT)
    # rest pose is preserved by compose even with non-zero offsets; drop loses the offset (QuaterNet)
    ident = np.tile([1.0, 0, 0, 0], (31, 1))
    rest = skel.forward_kinematics(ident, np.zeros(3))
    new_c = skel.remove_joints(["Spine1"], offsets="compose")
    new_d = skel.remove_joints(["Spine1"], offsets="drop")
    kept = [j for j in range(31) if j != 13]
    assert_close(new_c.forward_kinematics(ident[:30], np.zeros(3)), rest[kept], **TIGHT)
    assert_close(new_d.offsets, skel.offsets[kept], atol=0)
    # a rotated removed joint: rotation pushed (child rotation = q_r ⊗ q_c), geometry not exact
    assert not np.allclose(new_d.forward_kinematics(ident[:30], np.zeros(3)), rest[kept])
    new, new_rot = remove_joints(skel, rot, [13])
    child = skel.children[13][0]
    assert_close(new_rot[:, kept.index(child)], quat_mul(rot[:, 13], rot[:, child]), **TIGHT)


def test_remove_joints_quaternet_locomotion():
    """spec/kinematics.md §4: QuaterNet's 31 → 26 reduction (new → old index map and side lists)."""
    loco = quaternet_locomotion_skeleton()
    reduced = quaternet_locomotion_skeleton(reduced=True)
    old = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 14, 15, 16, 17, 18, 19, 20, 22, 24, 25, 26, 27, 29]
    assert reduced.names == tuple(loco.names[j] for j in old)
    assert_close(reduced.offsets, loco.offsets[old], atol=0)
    assert LOCOMOTION_REMOVED_JOINTS == (13, 21, 23, 28, 30)
    assert reduced.joints_left == (1, 2, 3, 4, 5, 16, 17, 18, 19, 20)
    assert reduced.joints_right == (6, 7, 8, 9, 10, 21, 22, 23, 24, 25)
    with pytest.raises(ValueError, match="root"):
        remove_joints(loco, None, [0])
    with pytest.raises(ValueError, match="offsets"):
        remove_joints(loco, None, [1], offsets="keep")
    with pytest.raises(ValueError, match="out of range"):
        remove_joints(loco, None, [31])


# ------------------------------------------------------------------------------------------------------------
# mirroring and rotation about the up axis (spec/kinematics.md §5)
# ------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_mirror_is_exact_reflection_and_an_involution(axis):
    """spec/kinematics.md §5: M R M as quaternion sign flips; swap; mirroring twice is the identity."""
    rng = np.random.default_rng(4)
    skel = cmu_asf_skeleton()
    rot = random_unit(rng, (5, 38))
    root = rng.normal(size=(5, 3))
    a = "xyz".index(axis)
    m = np.eye(3)
    m[a, a] = -1
    s2, r2, p2 = mirror(skel, rot, root, axis=axis, mirror_offsets=True)
    # each local rotation becomes M R M (after the swap)
    perm = np.arange(38)
    perm[list(skel.joints_left)] = skel.joints_right
    perm[list(skel.joints_right)] = skel.joints_left
    assert_close(matrix_from_quat(r2), m @ matrix_from_quat(rot[:, perm]) @ m, atol=1e-12)
    # with the skeleton mirrored too, positions are the mirror image with left and right swapped
    assert_close(s2.forward_kinematics(r2, p2), skel.forward_kinematics(rot, root)[:, perm] @ m, **TIGHT)
    s3, r3, p3 = mirror(s2, r2, p2, axis=axis, mirror_offsets=True)
    assert s3 == skel
    assert_close(r3, rot, atol=0)
    assert_close(p3, root, atol=0)


def test_mirror_quaternet_convention():
    """spec/kinematics.md §5: QuaterNet mirrors across x = 0, (w, x, y, z) → (w, x, −y, −z), offsets kept."""
    rng = np.random.default_rng(5)
    skel = quaternet_locomotion_skeleton(reduced=True)
    rot = random_unit(rng, (2, 26))
    root = rng.normal(size=(2, 3))
    s2, r2, p2 = mirror(skel, rot, root)
    assert s2 is skel
    assert_close(r2[:, 0], rot[:, 0] * [1, 1, -1, -1], atol=0)
    assert_close(r2[:, 1], rot[:, 6] * [1, 1, -1, -1], atol=0)  # LHipJoint ← RHipJoint
    assert_close(p2, root * [-1, 1, 1], atol=0)
    with pytest.raises(ValueError, match="axis"):
        mirror(skel, rot, root, axis="w")


def test_rotate_about_up_is_rigid():
    """spec/kinematics.md §5: rotating the root rotation and position rotates every joint position about y."""
    rng = np.random.default_rng(6)
    skel = cmu_skeleton()
    rot = random_unit(rng, (2, 4, 31))
    root = rng.normal(size=(2, 4, 3))
    angles = np.array([0.3, -2.0])
    r2, p2 = rotate_about_up(rot, root, angles[:, None])
    for b, ang in enumerate(angles):
        c, s = math.cos(ang), math.sin(ang)
        ry = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        assert_close(skel.forward_kinematics(r2[b], p2[b]), skel.forward_kinematics(rot[b], root[b]) @ ry.T, **TIGHT)
    assert_close(r2[..., 1:, :], rot[..., 1:, :], atol=0)
    r3, p3, ang = random_rotate_about_up(rot, root, np.random.default_rng(0))
    assert -math.pi <= ang <= math.pi
    r4, p4 = rotate_about_up(rot, root, ang)
    assert_close(r3, r4, atol=0)
    assert_close(p3, p4, atol=0)
    with pytest.raises(ValueError, match="angle"):
        rotate_about_up(rot, root, np.zeros(3))
    with pytest.raises(ValueError, match="rng"):
        random_rotate_about_up(rot, root, 0)


# ------------------------------------------------------------------------------------------------------------
# real data: every file, a few hundred frames (spec/kinematics.md §2-3)
# ------------------------------------------------------------------------------------------------------------

def _check_three_fks(motion, frames=200):
    skel = motion.skeleton
    rot = np.asarray(motion.rotations[:frames])
    root = np.asarray(motion.root_positions[:frames])
    p = skel.forward_kinematics(rot, root)
    scale = max(1.0, float(np.abs(p).max()))
    assert_close(skel.forward_kinematics_matrices(rot, root), p, rtol=0, atol=1e-11 * scale)
    dq = current_dq_from_local(rot, skel.offsets, skel.parents)
    assert_close(positions_from_current_dq(dq) + root[:, None], p, rtol=0, atol=1e-11 * scale)
    back, _ = local_from_current_dq(dq, skel.parents)
    assert_quat_close(back, rot, atol=1e-10)


def _all_real_files(root: Path):
    return sorted(root.glob("**/*.bvh")) + sorted(root.glob("**/*.txt"))


def _read_any(path: Path):
    return read_bvh(path) if path.suffix == ".bvh" else read_expmap(path, layout="cmu")


def test_three_fks_agree_on_every_shared_file(shared_data):
    """spec/kinematics.md §2-3: quaternion FK = matrix FK = current DQ + root on every real CMU file (the 830 Bandai
    Namco files carry per-joint translations; tests/test_bvh_oracle.py checks their FK against an independent reader)."""
    files = [p for p in _all_real_files(shared_data) if p.relative_to(shared_data).parts[0] != "bandai_namco_locomotion"]
    assert len(files) == 11 + 12
    for path in files:
        _check_three_fks(_read_any(path))


def test_three_fks_agree_on_embedded_sample():
    """spec/kinematics.md §2-3: the same on the embedded sample (no ../shared needed)."""
    files = _all_real_files(SAMPLE)
    assert len(files) == 4 + 12
    for path in files:
        _check_three_fks(_read_any(path), frames=100)


def test_dq_frame_of_real_cmu_walk_has_251_values():
    """spec/kinematics.md §3: CMU 02_01 without End Sites → 31 current DQs; translations = FK positions."""
    motion = read_bvh(SAMPLE / "bvh" / "02_01.bvh")
    skel, rot = remove_joints(motion.skeleton, motion.rotations, motion.skeleton.end_sites)
    assert skel == cmu_skeleton()
    dq = current_dq_from_local(rot, skel.offsets, skel.parents)
    assert 3 + dq[0].size == 251
    assert_close(dq_from_quat_translation(rot[:, 0], np.zeros(3)), dq[:, 0], atol=0)
