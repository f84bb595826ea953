"""Hypothesis strategies for property tests of rotation and skeleton code (test support; needs ``hypothesis``).

Users import these to property-test their own implementations against ``refimpl``. Every strategy draws
float64 NumPy arrays that are well-conditioned: norms bounded away from 0, angles bounded away from gimbal lock
and from the ``±π`` wrap unless the strategy says otherwise. Conventions as in ``refimpl.quat`` and
``refimpl.dualquat``: quaternions ``(w, x, y, z)``, dual quaternions ``(q_r | q_d)`` with ``q_d = ½ (0, t) ⊗ q_r``.

``shape`` arguments are the LEADING shape (a tuple, an int, or a hypothesis strategy of tuples such as
:func:`small_shapes`); the object axes (4, 8, 3, (3, 3)) are appended.

Shape legend: ``...`` leading shape, J joints.
"""
from __future__ import annotations

import math

import numpy as np
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from refimpl.dualquat import dq_from_quat_translation_kernel
from refimpl.rotations import EULER_ORDERS, TAIT_BRYAN_ORDERS, matrix_from_quat_kernel

__all__ = [
    "small_shapes", "unit_quaternions", "quaternions", "translations", "unit_dual_quaternions", "angles",
    "euler_orders", "tait_bryan_orders", "euler_angles", "rotation_matrices", "skeleton_arrays",
]

_MIN_DRAW_NORM = 0.1  # raw draws below this norm are replaced (keeps directions well-conditioned)


def small_shapes(max_dims: int = 2, max_side: int = 3, min_dims: int = 0) -> st.SearchStrategy:
    """Leading shapes with ``min_dims..max_dims`` axes of sizes ``1..max_side`` (``()`` included when min_dims=0)."""
    return hnp.array_shapes(min_dims=min_dims, max_dims=max_dims, min_side=1, max_side=max_side)


def _shape_strategy(shape) -> st.SearchStrategy:
    if isinstance(shape, st.SearchStrategy):
        return shape
    if isinstance(shape, (int, np.integer)):
        return st.just((int(shape),))
    return st.just(tuple(shape))


def _uniform(shape, low: float, high: float) -> st.SearchStrategy:
    """Arrays of float64 in ``[low, high]`` with leading ``shape`` (tuple) — no NaN/inf, no subnormals."""
    return hnp.arrays(np.float64, shape, elements=st.floats(low, high, allow_nan=False, allow_infinity=False,
                                                            allow_subnormal=False, width=64))


def _directions(shape: tuple, n: int) -> st.SearchStrategy:
    """Unit vectors of size ``n``: a box draw in ``[−1, 1]^n``, rows with norm < 0.1 replaced by ``e_0``, normalised."""
    def fix(a: np.ndarray) -> np.ndarray:
        norm = np.linalg.norm(a, axis=-1, keepdims=True)
        e0 = np.zeros(n)
        e0[0] = 1
        a = np.where(norm < _MIN_DRAW_NORM, e0, a)
        return a / np.linalg.norm(a, axis=-1, keepdims=True)
    return _uniform(shape + (n,), -1.0, 1.0).map(fix)


def unit_quaternions(shape=()) -> st.SearchStrategy:
    """Unit quaternions ``(..., 4)`` float64, both signs of ``w`` (each a box draw normalised)."""
    return _shape_strategy(shape).flatmap(lambda s: _directions(s, 4))


def quaternions(shape=(), min_norm: float = 0.5, max_norm: float = 2.0) -> st.SearchStrategy:
    """Non-unit quaternions ``(..., 4)``: a unit quaternion times a norm in ``[min_norm, max_norm]`` (> 0)."""
    if not 0 < min_norm <= max_norm:
        raise ValueError(f"min_norm, max_norm: expected 0 < min_norm <= max_norm, got {min_norm}, {max_norm}")

    def build(s):
        return st.tuples(_directions(s, 4), _uniform(s + (1,), min_norm, max_norm)).map(lambda p: p[0] * p[1])
    return _shape_strategy(shape).flatmap(build)


def translations(shape=(), max_abs: float = 10.0) -> st.SearchStrategy:
    """Translation vectors ``(..., 3)`` with components in ``[−max_abs, max_abs]``."""
    return _shape_strategy(shape).flatmap(lambda s: _uniform(s + (3,), -max_abs, max_abs))


def unit_dual_quaternions(shape=(), max_translation: float = 10.0) -> st.SearchStrategy:
    """Unit dual quaternions ``(..., 8)`` = ``(q | ½ (0, t) ⊗ q)`` from a unit quaternion and a translation."""
    def build(s):
        return st.tuples(_directions(s, 4), _uniform(s + (3,), -max_translation, max_translation)).map(
            lambda p: dq_from_quat_translation_kernel(p[0], p[1]))
    return _shape_strategy(shape).flatmap(build)


def angles(shape=(), low: float = -math.pi, high: float = math.pi) -> st.SearchStrategy:
    """Arrays of angles (radians) of the given FULL shape (nothing appended), in ``[low, high]``."""
    return _shape_strategy(shape).flatmap(lambda s: _uniform(s, low, high))


def euler_orders() -> st.SearchStrategy:
    """All 12 Euler orders (6 Tait-Bryan, 6 proper), lower case."""
    return st.sampled_from(EULER_ORDERS)


def tait_bryan_orders() -> st.SearchStrategy:
    """The 6 Tait-Bryan orders (three distinct axes), lower case."""
    return st.sampled_from(TAIT_BRYAN_ORDERS)


def euler_angles(order: str, shape=(), margin: float = 0.05) -> st.SearchStrategy:
    """Euler angles ``(..., 3)`` for ``order`` at least ``margin`` away from gimbal lock and from the ±π wrap.

    Outer angles in ``[−π + margin, π − margin]``; the middle angle in ``[−π/2 + margin, π/2 − margin]``
    (Tait-Bryan) or ``[margin, π − margin]`` (proper, ``order[0] == order[2]``). In these ranges
    ``euler_from_quat(quat_from_euler(a, order), order) == a``.
    """
    proper = order.lower()[0] == order.lower()[2]
    mid = (margin, math.pi - margin) if proper else (-math.pi / 2 + margin, math.pi / 2 - margin)

    def build(s):
        outer = _uniform(s + (2,), -math.pi + margin, math.pi - margin)
        middle = _uniform(s + (1,), *mid)
        return st.tuples(outer, middle).map(lambda p: np.concatenate([p[0][..., :1], p[1], p[0][..., 1:]], axis=-1))
    return _shape_strategy(shape).flatmap(build)


def rotation_matrices(shape=()) -> st.SearchStrategy:
    """Rotation matrices ``(..., 3, 3)`` (orthonormal, det +1 to rounding), from :func:`unit_quaternions`."""
    return unit_quaternions(shape).map(matrix_from_quat_kernel)


@st.composite
def skeleton_arrays(draw, min_joints: int = 1, max_joints: int = 8):
    """A random skeleton in topological order: ``(parents, offsets)``.

    Returns
    -------
    parents : list of int, length J
        ``parents[0] = −1`` and ``0 <= parents[j] < j`` for ``j >= 1``.
    offsets : ndarray float64, (J, 3)
        Root offset in ``[−1, 1]³``; every other offset has norm in ``[0.1, √3]`` (no zero-length bones).
    """
    if not 1 <= min_joints <= max_joints:
        raise ValueError(f"min_joints, max_joints: expected 1 <= min_joints <= max_joints, got {min_joints}, {max_joints}")
    j = draw(st.integers(min_joints, max_joints))
    parents = [-1] + [draw(st.integers(0, i - 1)) for i in range(1, j)]
    offsets = draw(_uniform((j, 3), -1.0, 1.0))
    norm = np.linalg.norm(offsets[1:], axis=-1, keepdims=True)
    offsets[1:] = np.where(norm < _MIN_DRAW_NORM, np.array([0.0, _MIN_DRAW_NORM, 0.0]), offsets[1:])
    return parents, offsets
