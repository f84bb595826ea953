"""Current coordinates (dual-quaternion paper Eq. 8-12): local rotations and offsets ↔ current (root-relative)
dual quaternions, and the joint positions and offsets they hold.

Conventions (spec/kinematics.md, spec/conventions.md): a skeleton's ``parents`` in topological order (as
:class:`refimpl.skeleton.Skeleton`); ``C[0] = (q[0] | 0)`` (rotation only), ``C[j] = C[p(j)] ⊗ DQ(q[j], offset[j])``
with ``DQ(q, t) = (q | ½ (0, t) ⊗ q)``. The translation of ``C[j]`` (Eq. 8) is joint ``j``'s position relative to
the root position, in world axes.

Shape legend: ``...`` any leading axes (batch B, time T), J joints, 4 quaternion, 8 dual quaternion, 3 vector.
"""
from __future__ import annotations

import numpy as np

from refimpl.dualquat import (dq_conj_kernel, dq_from_quat_translation_kernel, dq_mul_kernel, dq_from_quat_translation,
                              dq_mul, translation_from_dq)
from refimpl.quat import finite_output
from refimpl.arrays import float_array
from refimpl.skeleton import check_last_axes, depth_levels, validate_parents

__all__ = ["current_dq_from_local", "local_from_current_dq", "positions_from_current_dq", "offsets_from_current_dq"]


@finite_output
def current_dq_from_local(rotations, offsets, parents) -> np.ndarray:
    """Current (root-relative) dual quaternions from local rotations and offsets (paper Eq. 9-11).

    ``C[0] = (q[0] | 0)`` (rotation only, zero dual part, Eq. 9);
    ``C[j] = C[p(j)] ⊗ DQ(q[j], offset[j])`` with ``DQ(q, t) = (q | ½ (0, t) ⊗ q)`` (Eq. 10-11 as dual
    quaternions). ``offsets[0]`` is ignored.

    Parameters
    ----------
    rotations : array_like, shape (..., J, 4)
        Local unit quaternions ``(w, x, y, z)``.
    offsets : array_like, shape (J, 3) or (..., J, 3)
        Local bone offsets (broadcast against ``rotations``).
    parents : sequence of int, length J
        Topologically ordered parents (``parents[0] == -1``, ``parents[j] < j``).

    Returns
    -------
    ndarray, shape (..., J, 8): ``(q_r | q_d)`` per joint; the translation of ``C[j]`` is joint ``j``'s
    position relative to the root.
    """
    par = validate_parents(parents)
    rot = float_array(rotations, "rotations")
    check_last_axes(rot, "rotations", (par.size, 4), f"(..., {par.size}, 4)")
    off = float_array(offsets, "offsets")
    check_last_axes(off, "offsets", (par.size, 3), f"({par.size}, 3) or (..., {par.size}, 3)")
    dtype = np.result_type(rot.dtype, off.dtype)
    return _current_dq_from_local(depth_levels(par), rot.astype(dtype, copy=False), off.astype(dtype, copy=False))


def _current_dq_from_local(levels, rot, off):
    off = np.broadcast_to(off, rot.shape[:-1] + (3,))
    local = dq_from_quat_translation_kernel(rot, off)                             # (..., J, 8)
    cur = np.empty_like(local)
    cur[..., 0, :4] = rot[..., 0, :]
    cur[..., 0, 4:] = 0.0
    for idx, par in levels:
        cur[..., idx, :] = dq_mul_kernel(cur[..., par, :], local[..., idx, :])
    return cur


def _current_dq_from_local_naive(parents, rot, off):
    """Slow per-joint loop version of :func:`_current_dq_from_local` through 4x4-free DQ products (test oracle)."""
    off = np.broadcast_to(off, rot.shape[:-1] + (3,))
    cur = np.empty(rot.shape[:-1] + (8,), dtype=rot.dtype)
    for j, p in enumerate(parents):
        if p < 0:
            cur[..., j, :] = dq_from_quat_translation(rot[..., j, :], np.zeros(3, dtype=rot.dtype))
        else:
            cur[..., j, :] = dq_mul(cur[..., p, :], dq_from_quat_translation(rot[..., j, :], off[..., j, :]))
    return cur


@finite_output
def local_from_current_dq(dqs, parents) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations and offsets from current dual quaternions (paper Eq. 12).

    ``L[j] = C[p(j)]⁻¹ ⊗ C[j]`` (for a unit DQ the inverse is ``(q_r* | q_d*)``), ``L[0] = C[0]``; the local
    rotation is the real part of ``L[j]`` and the local offset its translation ``vec(2 q_d ⊗ q_r*)`` (Eq. 8).
    The inputs are assumed unit (normalise network outputs first with ``refimpl.dualquat.dq_normalize``).

    Parameters
    ----------
    dqs : array_like, shape (..., J, 8)
    parents : sequence of int, length J

    Returns
    -------
    rotations : ndarray, shape (..., J, 4)
        Local quaternions (sign as produced by the product; ``q`` and ``-q`` are the same rotation).
    offsets : ndarray, shape (..., J, 3)
        Local offsets (the root's is its own translation, 0 for data built by :func:`current_dq_from_local`).
    """
    par = validate_parents(parents)
    dq = float_array(dqs, "dqs")
    check_last_axes(dq, "dqs", (par.size, 8), f"(..., {par.size}, 8)")
    local = _local_dq_from_current(par, dq)
    return local[..., :4].copy(), translation_from_dq(local)


def _local_dq_from_current(par, dq):
    parent_dq = dq[..., np.maximum(par, 0), :].copy()                       # (..., J, 8)
    parent_dq[..., 0, :] = np.array([1, 0, 0, 0, 0, 0, 0, 0], dtype=dq.dtype)
    return dq_mul_kernel(dq_conj_kernel(parent_dq), dq)                                 # (..., J, 8)


@finite_output
def positions_from_current_dq(dqs) -> np.ndarray:
    """Root-relative joint positions from current dual quaternions: ``p[j] = vec(2 q_d ⊗ q_r*)`` (paper Eq. 8).

    Add the root position to get world positions (the root DQ has no translation).

    Parameters
    ----------
    dqs : array_like, shape (..., J, 8)

    Returns
    -------
    ndarray, shape (..., J, 3)
    """
    dq = float_array(dqs, "dqs")
    check_last_axes(dq, "dqs", (8,), "(..., 8)")
    return translation_from_dq(dq)


@finite_output
def offsets_from_current_dq(dqs, parents) -> np.ndarray:
    """Local bone offsets ``vec(2 L_d ⊗ L_r*)`` with ``L[j] = C[p(j)]⁻¹ ⊗ C[j]`` (root: its own translation).

    Parameters
    ----------
    dqs : array_like, shape (..., J, 8)
    parents : sequence of int, length J

    Returns
    -------
    ndarray, shape (..., J, 3)
    """
    return local_from_current_dq(dqs, parents)[1]
