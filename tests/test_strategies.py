"""Tests of refimpl.strategies: every strategy meets its documented contract (spec/math.md §7)."""
from __future__ import annotations

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from refimpl import strategies as S
from refimpl.rotations import EULER_ORDERS, TAIT_BRYAN_ORDERS, euler_from_quat, quat_from_euler
from refimpl.strategies import (angles, euler_angles, euler_orders, quaternions, rotation_matrices, skeleton_arrays,
                                small_shapes, tait_bryan_orders, translations, unit_dual_quaternions,
                                unit_quaternions)
from refimpl.testing import assert_close


@given(small_shapes(max_dims=3, max_side=4))
def test_small_shapes(shape):
    """spec/math.md §7: tuples of 0..3 sides in 1..4."""
    assert isinstance(shape, tuple) and len(shape) <= 3 and all(1 <= s <= 4 for s in shape)


@given(unit_quaternions(small_shapes()))
def test_unit_quaternions(q):
    """spec/math.md §7: float64, (..., 4), unit norm."""
    assert q.dtype == np.float64 and q.shape[-1] == 4
    assert_close(np.linalg.norm(q, axis=-1), np.ones(q.shape[:-1]), rtol=1e-14)


@given(unit_quaternions((2, 3)), unit_quaternions(5))
def test_fixed_shapes(q, r):
    """spec/math.md §7: a tuple or int shape is the leading shape."""
    assert q.shape == (2, 3, 4) and r.shape == (5, 4)


@given(quaternions(small_shapes()), quaternions((), min_norm=3.0, max_norm=4.0))
def test_quaternions_norm_bounds(q, r):
    """spec/math.md §7: non-unit quaternions with norms in [min_norm, max_norm]."""
    n = np.linalg.norm(q, axis=-1)
    assert np.all((n >= 0.5 - 1e-12) & (n <= 2.0 + 1e-12))
    assert 3.0 - 1e-12 <= np.linalg.norm(r) <= 4.0 + 1e-12


@given(unit_dual_quaternions(small_shapes()), translations((3,), max_abs=2.0))
def test_unit_dual_quaternions_and_translations(a, t):
    """spec/math.md §7: unit DQs satisfy Eq. 3 and have translations in the box; translations are bounded."""
    r, d = a[..., :4], a[..., 4:]
    assert a.shape[-1] == 8 and a.dtype == np.float64
    assert_close(np.linalg.norm(r, axis=-1), np.ones(a.shape[:-1]), rtol=1e-14)
    assert np.all(np.abs(np.sum(r * d, axis=-1)) <= 1e-12)
    assert t.shape == (3, 3) and np.all(np.abs(t) <= 2.0)


@given(angles((4,), low=-1.0, high=0.5))
def test_angles(a):
    """spec/math.md §7: angles of the given full shape within [low, high]."""
    assert a.shape == (4,) and np.all((a >= -1.0) & (a <= 0.5))


@given(euler_orders(), tait_bryan_orders())
def test_orders(o, tb):
    """spec/math.md §7: the 12 orders and the 6 Tait-Bryan ones."""
    assert o in EULER_ORDERS and tb in TAIT_BRYAN_ORDERS and len(set(tb)) == 3


@given(st.data(), euler_orders())
def test_euler_angles_away_from_lock(data, order):
    """spec/math.md §7, §3.2: drawn angles are in the canonical ranges with the margin, so they round-trip."""
    a = data.draw(euler_angles(order, small_shapes(), margin=0.1))
    proper = order[0] == order[2]
    mid = a[..., 1]
    if proper:
        assert np.all((mid >= 0.1) & (mid <= math.pi - 0.1))
    else:
        assert np.all(np.abs(mid) <= math.pi / 2 - 0.1)
    assert np.all(np.abs(a[..., [0, 2]]) <= math.pi - 0.1)
    assert_close(euler_from_quat(quat_from_euler(a, order), order), a, rtol=1e-9, atol=1e-9)


@given(rotation_matrices(small_shapes()))
def test_rotation_matrices(m):
    """spec/math.md §7: orthonormal with determinant +1."""
    assert m.shape[-2:] == (3, 3)
    assert_close(np.swapaxes(m, -1, -2) @ m, np.broadcast_to(np.eye(3), m.shape), rtol=0, atol=1e-14)
    assert_close(np.linalg.det(m), np.ones(m.shape[:-2]), rtol=1e-13)


@given(skeleton_arrays(min_joints=2, max_joints=6))
def test_skeleton_arrays(sk):
    """spec/math.md §7: parents[0] = −1, 0 <= parents[j] < j, offsets (J, 3) float64 with bone norms >= 0.1."""
    parents, offsets = sk
    assert isinstance(parents, list) and all(isinstance(p, int) for p in parents)
    j = len(parents)
    assert 2 <= j <= 6 and parents[0] == -1
    assert all(0 <= parents[i] < i for i in range(1, j))
    assert offsets.shape == (j, 3) and offsets.dtype == np.float64
    assert np.all(np.linalg.norm(offsets[1:], axis=-1) >= 0.1 - 1e-15)


def test_all_names():
    """spec/math.md §7: __all__ is complete."""
    for name in S.__all__:
        assert hasattr(S, name), name
