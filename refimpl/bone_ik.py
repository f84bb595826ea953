"""Local rotations from joint positions by the skeleton's bone directions (spec/kinematics.md §7).

A positional pose (acRNN's published 171-value frame, the ``"positions"`` representations) has no rotations; a
BVH needs them. Each joint's global rotation is the one that turns its rest bones (the offsets of its children,
in the joint's own frame) onto the observed bones (child position − joint position), found in hierarchy order:

* one child ``c`` (a limb segment): the shortest arc from the parent-carried rest direction ``R_parent · o_c`` to
  the observed ``p_c − p_j``, composed after the parent's rotation: ``R_j = arc(R_parent o_c, p_c − p_j) ⊗
  R_parent`` — the twist about the bone, which positions cannot tell, is the parent's (no invented twist);
* two or more children with non-collinear offsets (hips, chest): the best-fitting rotation of all rest bones
  onto the observed ones (Kabsch / Wahba by SVD, reflection excluded);
* no child with a non-zero offset (an end of the chain): the parent's rotation (local identity).

Local rotation ``q_j = R_parent⁻¹ ⊗ R_j``; the root's position is the first joint's. Forward kinematics of the
result with the same skeleton gives back every position that a bone direction determines (all of them when every
joint has a child or End Site, as in acRNN's frame) to rounding, whenever the observed bone lengths are the
skeleton's; other lengths keep the directions and the skeleton's lengths.

Shape legend: ``...`` leading axes (T, or B, T), J joints.
"""
from __future__ import annotations

import numpy as np

from refimpl.arrays import float_array
from refimpl.quat import quat_conj_kernel, quat_mul_kernel, quat_rotate_kernel
from refimpl.rotations import quat_from_matrix_kernel
from refimpl.skeleton import Skeleton

__all__ = ["quat_between", "rotations_from_positions"]

#: Bones shorter than this (in the skeleton's units) carry no direction.
_MIN_LENGTH = 1e-9


def quat_between(u, v) -> np.ndarray:
    """The shortest-arc unit quaternion turning direction ``u`` onto direction ``v`` (``(..., 3)`` each, any
    non-zero length): ``q ⊗ (0, û) ⊗ q* = (0, v̂)``; opposite directions turn by π about an axis perpendicular to
    ``u``. Returns ``(..., 4)`` (w, x, y, z), ``w ≥ 0``."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if u.shape[-1:] != (3,) or v.shape[-1:] != (3,):
        raise ValueError(f"u, v: expected (..., 3), got {u.shape} and {v.shape}")
    u, v = np.broadcast_arrays(u, v)
    nu, nv = np.linalg.norm(u, axis=-1, keepdims=True), np.linalg.norm(v, axis=-1, keepdims=True)
    if np.any(nu <= _MIN_LENGTH) or np.any(nv <= _MIN_LENGTH) or not np.all(np.isfinite(u) & np.isfinite(v)):
        raise ValueError("u, v: expected finite non-zero directions")
    a, b = u / nu, v / nv
    q = np.concatenate([1.0 + np.sum(a * b, axis=-1, keepdims=True), np.cross(a, b)], axis=-1)  # (..., 4)
    opposite = q[..., 0] < 1e-12
    if np.any(opposite):  # any axis perpendicular to a: a × e for the basis vector least aligned with a
        e = np.eye(3)[np.argmin(np.abs(a[opposite]), axis=-1)]
        axis = np.cross(a[opposite], e)
        q[opposite] = np.concatenate([np.zeros(axis.shape[:-1] + (1,)), axis], axis=-1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _kabsch(rest: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """Rotation matrices ``(..., 3, 3)`` minimising ``Σ_c |R rest_c − seen_c|²`` (``(K, 3)`` and ``(..., K, 3)``)."""
    h = np.einsum("kc,...kd->...dc", rest, seen)                      # (..., 3, 3): Σ seen_c rest_cᵀ
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt))                                 # (...,) reflection guard
    fix = np.ones(h.shape[:-1])
    fix[..., -1] = d
    return (u * fix[..., None, :]) @ vt


def rotations_from_positions(skeleton: Skeleton, positions) -> tuple[np.ndarray, np.ndarray]:
    """Local rotations and root positions whose forward kinematics puts the bones along ``positions``.

    Parameters
    ----------
    skeleton : Skeleton
        Its offsets are the rest bones (any units, the same as ``positions``).
    positions : array_like (..., J, 3)
        World positions of every joint.

    Returns
    -------
    rotations : ndarray (..., J, 4)
        Local unit quaternions (w, x, y, z), parent first (module docstring for the rule per joint).
    root_positions : ndarray (..., 3)
        ``positions[..., 0, :]``.
    """
    if not isinstance(skeleton, Skeleton):
        raise ValueError(f"skeleton: expected a Skeleton, got {type(skeleton).__name__}")
    J = skeleton.num_joints
    p = float_array(positions, "positions", (..., J, 3)).astype(np.float64, copy=False)    # (..., J, 3)
    offsets = np.asarray(skeleton.offsets, dtype=np.float64)             # (J, 3)
    parents = list(skeleton.parents)
    children = [[c for c in range(J) if parents[c] == j and np.linalg.norm(offsets[c]) > _MIN_LENGTH]
                for j in range(J)]
    lead = p.shape[:-2]
    glob = np.zeros(lead + (J, 4))                                       # (..., J, 4) global rotations
    local = np.zeros(lead + (J, 4))
    ident = np.zeros(lead + (4,))
    ident[..., 0] = 1.0
    for j in range(J):                                                   # parents come before their children
        parent = ident if parents[j] < 0 else glob[..., parents[j], :]
        kids = children[j]
        rest = offsets[kids]                                             # (K, 3)
        seen = p[..., kids, :] - p[..., j:j + 1, :]                      # (..., K, 3)
        if len(kids) >= 2 and np.linalg.matrix_rank(rest, tol=1e-6 * np.abs(rest).max()) >= 2:
            g = quat_from_matrix_kernel(_kabsch(rest, seen))
        elif kids:
            carried = quat_rotate_kernel(parent, np.broadcast_to(rest[0], lead + (3,)))
            ok = np.linalg.norm(seen[..., 0, :], axis=-1) > _MIN_LENGTH
            arc = np.where(ok[..., None], quat_between(carried, np.where(ok[..., None], seen[..., 0, :], carried)),
                           ident)
            g = quat_mul_kernel(arc, parent)
        else:
            g = parent
        g = g / np.linalg.norm(g, axis=-1, keepdims=True)
        glob[..., j, :] = g
        local[..., j, :] = quat_mul_kernel(quat_conj_kernel(parent), g)
    return local, p[..., 0, :].copy()
