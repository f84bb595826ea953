"""Mirroring a motion (left and right swapped across a plane) and turning it about the up axis (data
augmentation), on local rotations and root positions of a :class:`refimpl.skeleton.Skeleton`.

Conventions (spec/kinematics.md, spec/conventions.md): local rotations are unit quaternions ``(w, x, y, z)``
(Hamilton product, active rotations, column vectors); the root position is the per-frame ``root_positions``.

Shape legend: ``...`` any leading axes (batch B, time T), J joints, 4 quaternion, 3 vector.
"""
from __future__ import annotations

import numpy as np

from refimpl.arrays import real_number
from refimpl.quat import finite_output, quat_mul, quat_rotate
from refimpl.rotations import quat_from_axis_angle
from refimpl.arrays import float_array
from refimpl.skeleton import Skeleton, check_last_axes

__all__ = ["mirror", "rotate_about_up", "random_rotate_about_up"]

_AXES = {"x": 0, "y": 1, "z": 2}


def _axis_index(axis) -> int:
    if isinstance(axis, str) and axis.lower() in _AXES:
        return _AXES[axis.lower()]
    if isinstance(axis, (int, np.integer)) and 0 <= int(axis) <= 2:
        return int(axis)
    raise ValueError(f"axis: expected 'x', 'y', 'z' or 0, 1, 2, got {axis!r}")


@finite_output
def mirror(skeleton: Skeleton, rotations, root_positions, axis="x", mirror_offsets: bool = False):
    """Reflect a motion across the plane normal to ``axis`` through the origin and swap left and right.

    With ``M = diag(-1, 1, 1)`` for ``axis="x"``: every local rotation becomes ``M R M`` — for quaternions
    ``(w, x, y, z) → (w, x, -y, -z)`` (``axis="y"``: ``(w, -x, y, -z)``, ``axis="z"``: ``(w, -x, -y, z)``);
    the rotation columns of ``joints_left[i]`` and ``joints_right[i]`` are swapped; the root position's
    ``axis`` component is negated. This is QuaterNet's mirroring (spec/kinematics.md §5), which
    leaves the offsets alone (exact for a symmetric skeleton). With ``mirror_offsets=True`` the skeleton is
    mirrored too (offsets reflected by ``M`` and swapped between partners), which makes the result the exact
    mirror image: ``FK'(p)[swap(j)] = M · FK(p)[j]``. Mirroring twice is the identity. Consecutive frames keep
    their hemisphere (the quaternion dot products are unchanged), so no antipodal fix is needed.

    Parameters
    ----------
    skeleton : Skeleton
    rotations : array_like, shape (..., J, 4)
    root_positions : array_like, shape (..., 3)
    axis : {"x", "y", "z"} or {0, 1, 2}
        Normal of the mirror plane (QuaterNet: x).
    mirror_offsets : bool

    Returns
    -------
    skeleton : Skeleton (the same object unless ``mirror_offsets``)
    rotations : ndarray, shape (..., J, 4)
    root_positions : ndarray, shape (..., 3)
    """
    if not isinstance(skeleton, Skeleton):
        raise ValueError(f"skeleton: expected a Skeleton, got {type(skeleton).__name__}")
    a = _axis_index(axis)
    rot, pos = skeleton._check_motion(rotations, root_positions)
    perm = np.arange(skeleton.num_joints)
    left = np.asarray(skeleton.joints_left, dtype=np.int64)
    right = np.asarray(skeleton.joints_right, dtype=np.int64)
    perm[left], perm[right] = right, left
    sign_q = np.array([1.0, -1.0, -1.0, -1.0], dtype=rot.dtype)
    sign_q[1 + a] = 1.0
    new_rot = rot[..., perm, :] * sign_q                                    # (..., J, 4)
    sign_v = np.ones(3, dtype=pos.dtype)
    sign_v[a] = -1.0
    new_pos = pos * sign_v                                                  # (..., 3)
    new_skel = skeleton
    if mirror_offsets:
        new_skel = Skeleton(skeleton.parents, skeleton.offsets[perm] * sign_v.astype(np.float64),
                            names=skeleton.names, end_sites=skeleton.end_sites,
                            joints_left=skeleton.joints_left, joints_right=skeleton.joints_right)
    return new_skel, new_rot, new_pos


@finite_output
def rotate_about_up(rotations, root_positions, angle, up="y"):
    """Rotate a whole motion about the vertical axis through the origin (data augmentation).

    ``q[..., 0, :] ← q_up(angle) ⊗ q[..., 0, :]`` (only the root's local rotation changes) and
    ``root_position ← R_up(angle) · root_position``; world positions rotate rigidly about the ``up`` axis.

    Parameters
    ----------
    rotations : array_like, shape (..., J, 4)
    root_positions : array_like, shape (..., 3)
    angle : float or array_like broadcastable to ``root_positions.shape[:-1]``
        Radians, counter-clockwise seen from +up. For one angle per sequence of a ``(B, T, ...)`` batch pass
        shape ``(B, 1)``.
    up : {"x", "y", "z"}
        The up axis (y for every data set in this project).

    Returns
    -------
    rotations : ndarray, shape (..., J, 4)
    root_positions : ndarray, shape (..., 3)
    """
    a = _axis_index(up)
    rot = float_array(rotations, "rotations")
    check_last_axes(rot, "rotations", (4,), "(..., J, 4)")
    if rot.ndim < 2 or rot.shape[-2] == 0:
        raise ValueError(f"rotations: expected shape (..., J, 4) with J >= 1 joints, got {rot.shape}")
    pos = float_array(root_positions, "root_positions")
    if pos.shape != rot.shape[:-2] + (3,):
        raise ValueError(f"root_positions: expected shape {rot.shape[:-2] + (3,)}, got {pos.shape}")
    ang = float_array(angle, "angle")
    try:
        ang = np.broadcast_to(ang, pos.shape[:-1])
    except ValueError:
        raise ValueError(f"angle: expected a shape broadcastable to {pos.shape[:-1]}, got {ang.shape}") from None
    dtype = np.result_type(rot.dtype, pos.dtype)
    axis_vec = np.zeros(3, dtype=dtype)
    axis_vec[a] = 1.0
    q_up = quat_from_axis_angle(ang.astype(dtype)[..., None] * axis_vec)   # (..., 4)
    new_rot = rot.astype(dtype, copy=True)
    new_rot[..., 0, :] = quat_mul(q_up, new_rot[..., 0, :])
    return new_rot, quat_rotate(q_up, pos.astype(dtype))


@finite_output
def random_rotate_about_up(rotations, root_positions, rng: np.random.Generator, low: float = -np.pi,
                           high: float = np.pi, up="y"):
    """:func:`rotate_about_up` by one angle drawn from ``U(low, high)`` for the whole motion.

    Parameters
    ----------
    rotations : array_like, shape (..., J, 4)
    root_positions : array_like, shape (..., 3)
    rng : numpy.random.Generator
    low, high : float
        Range of the angle in radians (QuaterNet's long-term training draws from [-2π, 2π]).
    up : {"x", "y", "z"}

    Returns
    -------
    rotations, root_positions : as :func:`rotate_about_up`
    angle : float
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    low, high = real_number(low, "low"), real_number(high, "high")
    if not (high >= low and np.isfinite(high - low)):
        raise ValueError(f"low, high: expected low <= high with a finite difference, got {low!r}, {high!r}")
    angle = float(rng.uniform(low, high))
    rot, pos = rotate_about_up(rotations, root_positions, angle, up=up)
    return rot, pos, angle
