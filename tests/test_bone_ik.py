"""Rotations from positions by the bone directions (refimpl.bone_ik, spec/kinematics.md §7), and the published acRNN
positional frame written as BVH through ``refimpl generate`` (issue 32 item 6)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.bone_ik import quat_between, rotations_from_positions
from refimpl.bvh import read_bvh
from refimpl.cli import main
from refimpl.quat import quat_normalize, quat_rotate
from refimpl.skeleton import Skeleton
from refimpl.strategies import skeleton_arrays, unit_quaternions

ROOT = Path(__file__).resolve().parents[1]
SALSA = ROOT / "refimpl" / "data" / "sample" / "salsa"

_vec = st.lists(st.floats(-10, 10, allow_nan=False), min_size=3, max_size=3).map(np.array).filter(
    lambda v: np.linalg.norm(v) > 1e-3)


@given(_vec, _vec)
def test_quat_between_turns_u_onto_v(u, v):
    q = quat_between(u, v)
    assert np.isclose(np.linalg.norm(q), 1.0)
    np.testing.assert_allclose(quat_rotate(q, u / np.linalg.norm(u)), v / np.linalg.norm(v), atol=1e-9)


@given(_vec)
def test_quat_between_opposite_and_equal_directions(u):
    np.testing.assert_allclose(quat_rotate(quat_between(u, -u), u), -u, atol=1e-9 * np.linalg.norm(u) + 1e-12)
    np.testing.assert_allclose(quat_between(u, 3 * u), [1, 0, 0, 0], atol=1e-9)


def test_quat_between_is_the_shortest_arc():
    """Its angle is the angle between the directions (no extra twist)."""
    rng = np.random.default_rng(0)
    u, v = rng.standard_normal((200, 3)), rng.standard_normal((200, 3))
    q = quat_between(u, v)
    angle = 2 * np.arctan2(np.linalg.norm(q[:, 1:], axis=1), q[:, 0])
    cos = np.sum(u * v, 1) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1)
    np.testing.assert_allclose(angle, np.arccos(np.clip(cos, -1, 1)), atol=1e-9)
    np.testing.assert_allclose(np.cross(q[:, 1:], np.cross(u, v)), 0, atol=1e-9)   # axis ⟂ both


def test_quat_between_refuses_zero_and_nan():
    with pytest.raises(ValueError):
        quat_between([0, 0, 0], [1, 0, 0])
    with pytest.raises(ValueError):
        quat_between([np.nan, 0, 0], [1, 0, 0])


@given(skeleton_arrays(min_joints=2, max_joints=8), st.data())
def test_positions_round_trip_on_random_skeletons(skel_arrays, data):
    """FK of the recovered rotations gives back every position (with an End Site below every leaf, every joint's
    direction is determined)."""
    parents, offsets = skel_arrays
    J = len(parents)
    leaves = [j for j in range(J) if j not in parents]
    parents = parents + leaves                                   # an End Site below each leaf
    offsets = np.concatenate([offsets, offsets[leaves] * 0.5 + np.array([0.0, 0.3, 0.0])])
    skel = Skeleton(parents, offsets)
    rot = data.draw(unit_quaternions((3, len(parents))))
    root = np.array([[0.0, 1.0, 2.0], [1.0, 0.0, -1.0], [5.0, 5.0, 5.0]])
    pos = skel.forward_kinematics(rot, root)
    rec, rec_root = rotations_from_positions(skel, pos)
    np.testing.assert_allclose(np.linalg.norm(rec, axis=-1), 1.0, atol=1e-12)
    # 1e-6: children whose offsets are collinear to ~1e-7 leave the twist to that precision (the rank rule)
    np.testing.assert_allclose(skel.forward_kinematics(rec, rec_root), pos, atol=1e-6)


def test_single_child_keeps_the_parent_twist():
    """A chain: a joint's recovered rotation has no twist about its bone beyond the parent's (local twist 0)."""
    skel = Skeleton([-1, 0, 1, 2], [[0, 0, 0], [0, 1, 0], [0, 1, 0], [0, 1, 0]])
    rng = np.random.default_rng(3)
    rot = quat_normalize(rng.standard_normal((20, 4, 4)))
    pos = skel.forward_kinematics(rot, np.zeros((20, 3)))
    rec, _ = rotations_from_positions(skel, pos)
    for j in (1, 2):   # the bone of joint j's child is +y in j's frame: no rotation about +y in the local rotation
        swing = quat_between(np.array([0.0, 1.0, 0.0]), quat_rotate(rec[:, j], np.array([0.0, 1.0, 0.0])))
        np.testing.assert_allclose(np.abs(np.sum(swing * rec[:, j], -1)), 1.0, atol=1e-9)   # rec = pure swing
    np.testing.assert_allclose(skel.forward_kinematics(rec, np.zeros((20, 3))), pos, atol=1e-9)


def test_salsa_take_round_trip():
    m = read_bvh(SALSA / "01.bvh")
    pos = m.skeleton.forward_kinematics(np.asarray(m.rotations)[:40], np.asarray(m.root_positions)[:40])
    rec, root = rotations_from_positions(m.skeleton, pos)
    np.testing.assert_allclose(m.skeleton.forward_kinematics(rec, root), pos, atol=1e-8)


def test_bad_input():
    skel = Skeleton([-1, 0], [[0, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match="positions"):
        rotations_from_positions(skel, np.zeros((5, 3, 3)))
    with pytest.raises(ValueError, match="finite"):
        rotations_from_positions(skel, np.full((5, 2, 3), np.nan))
    with pytest.raises(ValueError, match="Skeleton"):
        rotations_from_positions("skel", np.zeros((2, 3)))


def test_positional_acrnn_generates_a_bvh(tmp_path):
    """The published 171-value positional frame goes through `refimpl generate` to a BVH whose seed frames are the
    source take's poses (joint positions to BVH text precision)."""
    run = tmp_path / "run"
    assert main(["--blas-threads", "1", "train", "--model", "acrnn", "--representation", "positions-published",
                 "--data", "sample", "--steps", "2", "--set", "hidden_size=16", "--out", str(run)]) == 0
    out = tmp_path / "s.bvh"
    assert main(["generate", "--checkpoint", str(run / "checkpoint.npz"), "--source", str(SALSA / "16.bvh"),
                 "--source-frame", "1", "--length", "12", "--out", str(out)]) == 0
    gen = read_bvh(out)
    assert gen.num_frames == 22 and gen.skeleton.num_joints == 57
    from refimpl.protocols.synthesis import load_salsa_motion, in_source_units

    src = in_source_units(load_salsa_motion(SALSA / "16.bvh", end_sites=True))
    want = src.positions()[1:11]
    got = gen.positions()[:10]
    want = want - want[:, :1] + got[:, :1]        # the horizontal start is the generator's
    np.testing.assert_allclose(got, want, atol=2e-3)  # cm: BVH text has 6 decimals of degrees
