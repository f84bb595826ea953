"""Tests of refimpl.representations (spec/representations.md).

Frame sizes against the dual-quaternion paper's parameter table, encode → decode round trips for every
invertible representation, positions implied by every representation = forward kinematics, sign fixing.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.bvh import read_bvh
from refimpl.dualquat import dq_normalize
from refimpl.quat import quat_normalize
from refimpl.rotations import TAIT_BRYAN_ORDERS, euler_from_quat, quat_from_axis_angle
from refimpl.representations import (REPRESENTATIONS, decode, encode, fix_antipodal_frames, frame_size,
                                     positions_from_frames)
from refimpl.skeleton import Skeleton, remove_joints
from refimpl.current_dq import current_dq_from_local
from refimpl.skeletons import cmu_skeleton
from refimpl.strategies import skeleton_arrays, unit_quaternions
from refimpl.testing import assert_close, assert_quat_close

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"
NAMES = list(REPRESENTATIONS)
INVERTIBLE = [n for n in NAMES if REPRESENTATIONS[n].invertible]


def test_frame_sizes_match_the_paper():
    """spec/representations.md §1: 3 + D·J; CMU J = 31 gives the sizes solved from the paper's Appendix C."""
    expected = {"positions": 96, "euler": 96, "expmap": 96, "quaternions": 127, "ortho6d": 189,
                "dual_quaternions": 251, "quaternions+positions": 220, "ortho6d+positions": 282,
                "positions_acrnn": 93}    # the published acRNN's frame: no root block, 3 + 3·(J − 1)
    assert set(expected) == set(NAMES)
    for name, size in expected.items():
        assert frame_size(name, 31) == size
    assert frame_size("dual_quaternions", 25) == 203  # Mixamo
    assert frame_size("quaternions", 25) == 103
    with pytest.raises(ValueError, match="name"):
        frame_size("rotmat", 31)
    with pytest.raises(ValueError, match="num_joints"):
        frame_size("euler", 0)


@st.composite
def pose(draw):
    parents, offsets = draw(skeleton_arrays(1, 6))
    frames = draw(st.integers(1, 3))
    rot = draw(unit_quaternions((frames, len(parents))))
    root = np.array(draw(st.lists(st.floats(-5, 5), min_size=3 * frames, max_size=3 * frames))).reshape(frames, 3)
    return Skeleton(parents, offsets), rot, root


@pytest.mark.parametrize("name", NAMES)
@given(case=pose())
def test_encode_shape_positions_and_round_trip(name, case):
    """spec/representations.md §2-3: shape (..., 3 + D·J); root first; positions = FK; decode ∘ encode = id."""
    skel, rot, root = case
    frames = encode(name, skel, rot, root)
    assert frames.shape == (rot.shape[0], frame_size(name, skel.num_joints))
    assert_close(frames[:, :3], root, atol=0)
    fk = skel.forward_kinematics(rot, root)
    assert_close(positions_from_frames(name, skel, frames), fk, rtol=1e-9, atol=1e-9)
    if name in INVERTIBLE:
        back_rot, back_root = decode(name, skel, frames)
        # Euler: exact away from gimbal lock; random draws may come close, so compare rotations by FK too
        assert_quat_close(back_rot, rot, atol=1e-6 if name == "euler" else 1e-10)
        assert_close(back_root, root, atol=0)
    else:
        with pytest.raises(ValueError, match="no inverse"):
            decode(name, skel, frames)


def test_per_joint_blocks_are_what_they_claim():
    """spec/representations.md §2: each block's content and layout (joint-major, root entry included)."""
    rng = np.random.default_rng(0)
    skel = cmu_skeleton()
    rot = quat_normalize(rng.normal(size=(5, 31, 4)))
    root = rng.normal(size=(5, 3))
    rel = skel.forward_kinematics(rot, root) - root[:, None]
    blocks = {n: encode(n, skel, rot, root)[:, 3:].reshape(5, 31 - (not REPRESENTATIONS[n].root_block), -1)
              for n in NAMES}
    assert_close(blocks["positions"], rel, atol=1e-12)
    assert_close(blocks["positions_acrnn"], rel[:, 1:], atol=1e-12)   # no root block
    assert_close(blocks["positions"][:, 0], np.zeros((5, 3)), atol=0)
    assert_close(blocks["quaternions"], rot, atol=0)
    assert_close(blocks["euler"], euler_from_quat(rot, "zyx"), atol=0)
    assert_quat_close(quat_from_axis_angle(blocks["expmap"]), rot, atol=1e-12)
    assert np.all(np.linalg.norm(blocks["expmap"], axis=-1) <= np.pi + 1e-12)
    assert_close(blocks["dual_quaternions"], current_dq_from_local(rot, skel.offsets, skel.parents), atol=0)
    assert_close(blocks["quaternions+positions"][..., :4], rot, atol=0)
    assert_close(blocks["quaternions+positions"][..., 4:], rel, atol=1e-12)
    assert_close(blocks["ortho6d+positions"][..., :6], blocks["ortho6d"], atol=0)
    assert_close(blocks["ortho6d+positions"][..., 6:], rel, atol=1e-12)
    from refimpl.rotations import matrix_from_quat
    m = matrix_from_quat(rot)
    assert_close(blocks["ortho6d"], np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1), atol=0)


@pytest.mark.parametrize("order", TAIT_BRYAN_ORDERS)
def test_euler_orders(order):
    """spec/representations.md §2: the Euler order is a parameter of encode and decode."""
    rng = np.random.default_rng(1)
    skel = cmu_skeleton()
    rot = quat_normalize(rng.normal(size=(3, 31, 4)))
    frames = encode("euler", skel, rot, np.zeros((3, 3)), order=order)
    assert_quat_close(decode("euler", skel, frames, order=order)[0], rot, atol=1e-9)


def test_decode_normalises_network_outputs():
    """spec/representations.md §3: non-unit quaternions / DQs / 6-D vectors decode to the same rotations."""
    rng = np.random.default_rng(2)
    skel = cmu_skeleton()
    rot = quat_normalize(rng.normal(size=(4, 31, 4)))
    root = rng.normal(size=(4, 3))
    for name in ("quaternions", "dual_quaternions", "ortho6d", "quaternions+positions", "ortho6d+positions"):
        frames = encode(name, skel, rot, root)
        block = frames[:, 3:].reshape(4, 31, -1)
        scaled = block * rng.uniform(0.5, 2.0, size=(4, 31, 1))
        if name.startswith("ortho6d"):  # shear the second column too: Gram-Schmidt removes it
            scaled[..., 3:6] += 0.3 * block[..., 0:3]
        noisy = np.concatenate([root, scaled.reshape(4, -1)], axis=1)
        back, _ = decode(name, skel, noisy)
        assert_quat_close(back, rot, atol=1e-10)
        if name == "dual_quaternions":
            expected = skel.forward_kinematics(rot, root)
            assert_close(positions_from_frames(name, skel, noisy), expected, atol=1e-10)
            assert_close(dq_normalize(scaled), block, atol=1e-10)


def test_real_cmu_walk_in_every_representation():
    """spec/representations.md §2: CMU 02_01 (31 joints after removing End Sites): sizes and round trips."""
    motion = read_bvh(SAMPLE / "bvh" / "02_01.bvh")
    skel, rot = remove_joints(motion.skeleton, motion.rotations[:120], motion.skeleton.end_sites)
    root = motion.root_positions[:120]
    fk = skel.forward_kinematics(rot, root)
    for name in NAMES:
        frames = encode(name, skel, rot, root)
        assert frames.shape == (120, frame_size(name, 31))
        assert_close(positions_from_frames(name, skel, frames), fk, atol=1e-10)
        if name in INVERTIBLE:
            back, _ = decode(name, skel, frames)
            assert_close(skel.forward_kinematics(back, root), fk, atol=1e-9)
    assert encode("dual_quaternions", skel, rot, root).shape[-1] == 251


def test_fix_antipodal_frames():
    """spec/representations.md §4: quaternion / DQ blocks made continuous over time; positions untouched."""
    rng = np.random.default_rng(3)
    skel = cmu_skeleton()
    rot = quat_normalize(np.cumsum(rng.normal(scale=0.05, size=(30, 31, 4)), axis=0) + [1, 0, 0, 0])
    root = rng.normal(size=(30, 3))
    flips = np.where(rng.random((30, 31, 1)) < 0.5, -1.0, 1.0)
    for name in ("quaternions", "dual_quaternions", "quaternions+positions"):
        clean = encode(name, skel, rot, root)
        d = REPRESENTATIONS[name].dim
        block = clean[:, 3:].reshape(30, 31, d).copy()
        block[..., :4 if d == 7 else d] *= flips
        messy = np.concatenate([root, block.reshape(30, -1)], axis=1)
        fixed = fix_antipodal_frames(name, messy)
        fb = fixed[:, 3:].reshape(30, 31, d)
        assert np.all(np.sum(fb[1:, :, :4] * fb[:-1, :, :4], axis=-1) >= 0)
        assert_close(positions_from_frames(name, skel, fixed), positions_from_frames(name, skel, clean), atol=1e-10)
        if d == 7:
            assert_close(fb[..., 4:], clean[:, 3:].reshape(30, 31, 7)[..., 4:], atol=0)
    eul = encode("euler", skel, rot, root)
    assert_close(fix_antipodal_frames("euler", eul), eul, atol=0)
    with pytest.raises(ValueError, match="frames"):
        fix_antipodal_frames("quaternions", np.zeros((3, 10)))


def test_validation():
    """spec/representations.md: unknown names, wrong widths, non-unit inputs and bad skeletons raise ValueError."""
    skel = cmu_skeleton()
    rot = np.tile([1.0, 0, 0, 0], (2, 31, 1))
    with pytest.raises(ValueError, match="name"):
        encode("matrices", skel, rot, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="skeleton"):
        encode("euler", skel.parents, rot, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="unit quaternions"):
        encode("euler", skel, rot * 3, np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"frames: expected shape \(\.\.\., 251\)"):
        decode("dual_quaternions", skel, np.zeros((2, 250)))
    with pytest.raises(ValueError, match="NaN"):
        decode("quaternions", skel, np.full((2, 127), np.nan))
