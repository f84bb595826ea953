"""Tests of refimpl.nn.kinematics_layers (spec/losses.md §3): forwards against the slow `_naive` versions and
against refimpl.skeleton / refimpl.dualquat, backwards against central differences and the VJP identity."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.dualquat import dq_conj, dq_from_quat_translation
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.nn.kinematics_layers import (
    _current_dq_from_local_naive,
    _dq_conj,
    _forward_kinematics_naive,
    _local_dq_from_current_naive,
    current_dq_from_local_backward,
    current_dq_from_local_forward,
    dq_from_quat_translation_backward,
    dq_from_quat_translation_forward,
    forward_kinematics_backward,
    forward_kinematics_forward,
    local_dq_from_current_backward,
    local_dq_from_current_forward,
    offsets_from_dq_backward,
    offsets_from_dq_forward,
    positions_from_dq_backward,
    positions_from_dq_forward,
)
from refimpl.skeleton import Skeleton
from refimpl.current_dq import (current_dq_from_local, local_from_current_dq, offsets_from_current_dq,
                                positions_from_current_dq)
from refimpl.strategies import skeleton_arrays
from refimpl.testing import TOL_EXACT, assert_close

lead_shapes = st.lists(st.integers(1, 3), min_size=1, max_size=2).map(tuple)
seeds = st.integers(0, 2**31 - 1)
# a branching tree: several children per parent at the same depth (exercises the scatter groups)
PARENTS = [-1, 0, 1, 2, 0, 4, 0, 6, 6, 8, 8, 8]


def _unit(rng, shape):
    q = rng.standard_normal(shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _motion(rng, lead, parents):
    J = len(parents)
    rot = _unit(rng, lead + (J,))
    root = rng.standard_normal(lead + (3,))
    off = rng.standard_normal((J, 3))
    return rot, root, off


def _current(rng, lead, parents, jitter=0.0):
    """Unit current DQs of a random motion (optionally perturbed off the unit manifold)."""
    rot, _, off = _motion(rng, lead, parents)
    cur = current_dq_from_local(rot, off, parents)
    return cur + jitter * rng.standard_normal(cur.shape), rot, off


# ------------------------------------------------------------------------------------------------
# forward kinematics (§3.1)

@given(skeleton_arrays(max_joints=7), lead_shapes, seeds)
def test_fk_matches_naive_and_skeleton(skel, lead, seed):
    """spec/losses.md §3.1: QuaterNet FK equals the per-joint matrix oracle, Skeleton.forward_kinematics and
    Skeleton.forward_kinematics_matrices (refimpl.skeleton)."""
    parents, offsets = skel
    rng = np.random.default_rng([seed, 7])
    rot, root, _ = _motion(rng, lead, parents)
    pos, _ = forward_kinematics_forward(rot, root, offsets, parents)
    assert_close(pos, _forward_kinematics_naive(rot, root, offsets, parents), **TOL_EXACT)
    sk = Skeleton(parents, offsets)
    assert_close(pos, sk.forward_kinematics(rot, root), **TOL_EXACT)
    assert_close(pos, sk.forward_kinematics_matrices(rot, root), rtol=1e-10, atol=1e-11)


@given(skeleton_arrays(max_joints=7), seeds)
def test_fk_vjp(skel, seed):
    """spec/losses.md §3.1: vector-Jacobian identity into rotations, root positions and offsets."""
    parents, offsets = skel
    rng = np.random.default_rng([seed, 7])
    rot, root, _ = _motion(rng, (2,), parents)
    off = np.array(offsets)

    def vjp(w):
        dr, dro, do = forward_kinematics_backward(w[0], forward_kinematics_forward(rot, root, off, parents)[1])
        return {"rot": dr, "root": dro, "off": do}

    check_vjp(lambda: forward_kinematics_forward(rot, root, off, parents)[0],
              {"rot": rot, "root": root, "off": off}, vjp)


def test_fk_central_differences_and_leaf_gradient():
    """spec/losses.md §3.1: all gradients vs central differences; leaf rotations and the root offset get 0."""
    rng = np.random.default_rng(0)
    rot, root, off = _motion(rng, (2, 2), PARENTS)
    w = rng.standard_normal((2, 2, len(PARENTS), 3))
    pos, cache = forward_kinematics_forward(rot, root, off, PARENTS)
    dr, dro, do = forward_kinematics_backward(w, cache)
    check_gradients(lambda: float(np.sum(forward_kinematics_forward(rot, root, off, PARENTS)[0] * w)),
                    {"rot": rot, "root": root, "off": off}, {"rot": dr, "root": dro, "off": do}, max_entries=None)
    leaves = [j for j in range(len(PARENTS)) if j not in PARENTS]
    assert np.all(dr[..., leaves, :] == 0) and np.all(do[0] == 0)


def test_fk_per_frame_offsets_and_float32():
    """spec/losses.md §3.1: offsets (..., J, 3) get a gradient of their own shape; float32 stays float32."""
    rng = np.random.default_rng(1)
    rot, root, _ = _motion(rng, (3,), PARENTS)
    off = rng.standard_normal((3, len(PARENTS), 3))
    w = rng.standard_normal((3, len(PARENTS), 3))
    dr, dro, do = forward_kinematics_backward(w, forward_kinematics_forward(rot, root, off, PARENTS)[1])
    assert do.shape == off.shape
    check_gradients(lambda: float(np.sum(forward_kinematics_forward(rot, root, off, PARENTS)[0] * w)),
                    {"off": off}, {"off": do})
    p32, c32 = forward_kinematics_forward(rot.astype(np.float32), root.astype(np.float32), off, PARENTS)
    assert p32.dtype == np.float32
    assert all(g.dtype == np.float32 for g in forward_kinematics_backward(np.ones_like(p32), c32)[:2])


def test_fk_validation():
    """spec/architecture.md: bad parents and shapes raise ValueError naming the argument."""
    rot, root, off = _motion(np.random.default_rng(2), (2,), PARENTS)
    with pytest.raises(ValueError, match="parents"):
        forward_kinematics_forward(rot, root, off, [0] + PARENTS[1:])
    with pytest.raises(ValueError, match="parents"):
        forward_kinematics_forward(rot, root, off, PARENTS[:-1] + [11])
    with pytest.raises(ValueError, match="root_positions"):
        forward_kinematics_forward(rot, root[:1], off, PARENTS)
    with pytest.raises(ValueError, match="offsets"):
        forward_kinematics_forward(rot, root, off[:3], PARENTS)


# ------------------------------------------------------------------------------------------------
# dual quaternions (§3.2 - §3.6)

@given(lead_shapes, seeds)
def test_dq_from_quat_translation(lead, seed):
    """spec/losses.md §3.2: (q | ½ (0, t) ⊗ q) equals refimpl.dualquat; its translation is t; VJP."""
    rng = np.random.default_rng([seed, 7])
    q, t = _unit(rng, lead), rng.standard_normal(lead + (3,))
    dq, _ = dq_from_quat_translation_forward(q, t)
    assert_close(dq, dq_from_quat_translation(q, t), **TOL_EXACT)
    assert_close(positions_from_dq_forward(dq)[0], t, **TOL_EXACT)

    def vjp(w):
        dq_, dt = dq_from_quat_translation_backward(w[0], dq_from_quat_translation_forward(q, t)[1])
        return {"q": dq_, "t": dt}

    check_vjp(lambda: dq_from_quat_translation_forward(q, t)[0], {"q": q, "t": t}, vjp)


@given(skeleton_arrays(max_joints=7), lead_shapes, seeds)
def test_current_dq_matches_skeleton_and_fk(skel, lead, seed):
    """spec/losses.md §3.3, §3.5: current DQs equal refimpl.current_dq.current_dq_from_local and the naive loop;
    their translations (Eq. 8) are the FK positions relative to the root."""
    parents, offsets = skel
    rng = np.random.default_rng([seed, 7])
    rot, root, _ = _motion(rng, lead, parents)
    t = np.broadcast_to(offsets, lead + offsets.shape).copy()
    t[..., 0, :] = 0.0
    local, _ = dq_from_quat_translation_forward(rot, t)
    cur, _ = current_dq_from_local_forward(local, parents)
    assert_close(cur, _current_dq_from_local_naive(local, parents), **TOL_EXACT)
    assert_close(cur, current_dq_from_local(rot, offsets, parents), **TOL_EXACT)
    pos, _ = positions_from_dq_forward(cur)
    assert_close(pos, positions_from_current_dq(cur), **TOL_EXACT)
    fk, _ = forward_kinematics_forward(rot, root, offsets, parents)
    assert_close(pos + root[..., None, :], fk, rtol=1e-10, atol=1e-11)


@given(skeleton_arrays(max_joints=7), lead_shapes, seeds)
def test_local_dq_and_offsets_invert_current(skel, lead, seed):
    """spec/losses.md §3.4, §3.6: local_dq_from_current inverts current_dq_from_local (Eq. 12), agrees with the
    naive loop and refimpl.current_dq.local_from_current_dq; offsets_from_dq recovers the offsets (root 0)."""
    parents, offsets = skel
    rng = np.random.default_rng([seed, 7])
    rot, _, _ = _motion(rng, lead, parents)
    cur = current_dq_from_local(rot, offsets, parents)
    loc, _ = local_dq_from_current_forward(cur, parents)
    assert_close(loc, _local_dq_from_current_naive(cur, parents), **TOL_EXACT)
    back, _ = current_dq_from_local_forward(loc, parents)
    assert_close(back, cur, rtol=1e-10, atol=1e-11)
    sk_rot, sk_off = local_from_current_dq(cur, parents)
    assert_close(loc[..., :4], sk_rot, **TOL_EXACT)
    off, _ = offsets_from_dq_forward(cur, parents)
    expect = np.broadcast_to(offsets, off.shape).copy()
    expect[..., 0, :] = 0.0
    assert_close(off, expect, rtol=1e-10, atol=1e-11)
    assert_close(off[..., 1:, :], sk_off[..., 1:, :], rtol=1e-10, atol=1e-11)
    assert_close(off[..., 1:, :], offsets_from_current_dq(cur, parents)[..., 1:, :], rtol=1e-10, atol=1e-11)
    # the inverse used is the quaternion conjugate of both parts, refimpl.dualquat.dq_conj
    assert_close(_dq_conj(cur), dq_conj(cur), **TOL_EXACT)


@given(skeleton_arrays(max_joints=6), seeds)
def test_dq_layers_vjp(skel, seed):
    """spec/losses.md §3.3-§3.6: VJP identity of every DQ layer on non-unit inputs (exact for any input)."""
    parents, _ = skel
    rng = np.random.default_rng([seed, 7])
    x = rng.standard_normal((2, len(parents), 8))
    for fw, bw in ((current_dq_from_local_forward, current_dq_from_local_backward),
                   (local_dq_from_current_forward, local_dq_from_current_backward),
                   (offsets_from_dq_forward, offsets_from_dq_backward)):
        check_vjp(lambda: fw(x, parents)[0], {"x": x}, lambda w: {"x": bw(w[0], fw(x, parents)[1])})
    check_vjp(lambda: positions_from_dq_forward(x)[0], {"x": x},
              lambda w: {"x": positions_from_dq_backward(w[0], positions_from_dq_forward(x)[1])})


def test_dq_layers_central_differences():
    """spec/losses.md §3.2-§3.6: each DQ layer's gradient against central differences (branching skeleton)."""
    rng = np.random.default_rng(3)
    cur, _, _ = _current(rng, (2,), PARENTS, jitter=0.1)
    w8 = rng.standard_normal(cur.shape)
    w3 = rng.standard_normal(cur.shape[:-1] + (3,))
    for fw, bw, w in ((current_dq_from_local_forward, current_dq_from_local_backward, w8),
                      (local_dq_from_current_forward, local_dq_from_current_backward, w8),
                      (offsets_from_dq_forward, offsets_from_dq_backward, w3)):
        _, cache = fw(cur, PARENTS)
        check_gradients(lambda: float(np.sum(fw(cur, PARENTS)[0] * w)), {"x": cur}, {"x": bw(w, cache)},
                        max_entries=None)
    _, cache = positions_from_dq_forward(cur)
    check_gradients(lambda: float(np.sum(positions_from_dq_forward(cur)[0] * w3)), {"x": cur},
                    {"x": positions_from_dq_backward(w3, cache)}, max_entries=None)
    q, t = rng.standard_normal((3, 4)), rng.standard_normal((3, 3))
    w = rng.standard_normal((3, 8))
    dq, dt = dq_from_quat_translation_backward(w, dq_from_quat_translation_forward(q, t)[1])
    check_gradients(lambda: float(np.sum(dq_from_quat_translation_forward(q, t)[0] * w)), {"q": q, "t": t},
                    {"q": dq, "t": dt}, max_entries=None)


def test_dq_layers_validation():
    """spec/architecture.md: wrong trailing shapes and bad parents raise ValueError."""
    x = np.zeros((2, len(PARENTS), 8))
    x[..., 0] = 1.0
    with pytest.raises(ValueError, match="local_dqs"):
        current_dq_from_local_forward(x[..., :4], PARENTS)
    with pytest.raises(ValueError, match="parents"):
        local_dq_from_current_forward(x, PARENTS[:-1])
    with pytest.raises(ValueError, match="translations"):
        dq_from_quat_translation_forward(np.ones((2, 4)), np.ones((3, 3)))
    with pytest.raises(ValueError, match="dqs"):
        positions_from_dq_forward(np.ones((2, 7)))
