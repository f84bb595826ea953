"""Pose representations compared by the dual-quaternion paper, as one registry (spec/representations.md).

Every representation turns (skeleton, local rotations, root positions) into frame vectors

    frame = [root position (3) | joint 0 (D) | joint 1 (D) | ... | joint J−1 (D)]      size 3 + D·J

(paper §6.1: ``m_f ∈ R^{3+DJ}``; 251 values for dual quaternions on CMU's 31 joints) and back where an
inverse exists:

================================  ==  ==========================================================  =========
name                              D   per joint                                                    inverse
================================  ==  ==========================================================  =========
``"positions"``                   3   position relative to the root, world axes (current coords)   no (IK)
``"euler"``                       3   local Euler angles (radians) in ``order`` (default "zyx")     yes
``"expmap"``                      3   local rotation vector θ·n (column-vector convention)          yes
``"quaternions"``                 4   local unit quaternion (w, x, y, z)                           yes
``"ortho6d"``                     6   first two columns of the local rotation matrix (Zhou et al.)   yes
``"dual_quaternions"``            8   current dual quaternion (q_r | q_d) (paper Eq. 9-11)          yes
``"quaternions+positions"``       7   local quaternion (4) then current position (3)              yes
``"ortho6d+positions"``           9   ortho6D (6) then current position (3)                        yes
``"positions_acrnn"``             3   as ``"positions"``, without the root's own (zero) block       no (IK)
================================  ==  ==========================================================  =========

``"positions_acrnn"`` is the published acRNN code's frame (spec/acrnn.md §1.1): the root position, then every
other joint relative to the root, size ``3 + 3·(J − 1)`` (171 on the salsa skeleton with its End Sites, 57
nodes); the representation with ``root_block=False``.

"Current position" is the joint position minus the root position (the translation of the current dual
quaternion, Eq. 8). The root's own entry is included in every block (its position entry is 0, its rotation
is the root rotation). Decoding normalises what a network may have left non-unit (quaternions by
``quat_normalize``, dual quaternions by Eq. 13, 6-D by Gram-Schmidt); the ``+positions`` blocks are ignored
by :func:`decode` and used by :func:`positions_from_frames`.

Shape legend: ``...`` leading axes (T or B, T), J joints, D values per joint, F = 3 + D·J.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from refimpl.dualquat import dq_fix, dq_normalize, translation_from_dq
from refimpl.quat import quat_fix, quat_normalize
from refimpl.rotations import (axis_angle_from_quat, euler_from_quat, matrix_from_ortho6d, matrix_from_quat,
                               ortho6d_from_matrix, quat_from_axis_angle, quat_from_euler, quat_from_matrix)
from refimpl.arrays import float_array
from refimpl.skeleton import Skeleton
from refimpl.current_dq import current_dq_from_local, local_from_current_dq

__all__ = ["Representation", "REPRESENTATIONS", "encode", "decode", "frame_size", "positions_from_frames",
           "fix_antipodal_frames"]


@dataclasses.dataclass(frozen=True)
class Representation:
    """One entry of the registry: ``name``, values per joint ``dim`` (D), whether :func:`decode` exists."""

    name: str
    dim: int
    invertible: bool
    description: str
    #: False: joint 0's block (zero for positions) is left out of the frame, ``F = 3 + D·(J − 1)``.
    root_block: bool = True

    def joints_stored(self, num_joints: int) -> int:
        """Joint blocks in a frame of a ``num_joints`` skeleton (J, or J − 1 without the root's block)."""
        return int(num_joints) - (0 if self.root_block else 1)


REPRESENTATIONS = {r.name: r for r in (
    Representation("positions", 3, False, "joint positions relative to the root (current coordinates)"),
    Representation("euler", 3, True, "local Euler angles in radians, in the given order"),
    Representation("expmap", 3, True, "local rotation vectors (exponential map)"),
    Representation("quaternions", 4, True, "local unit quaternions (w, x, y, z)"),
    Representation("ortho6d", 6, True, "first two columns of the local rotation matrices"),
    Representation("dual_quaternions", 8, True, "current dual quaternions (q_r | q_d)"),
    Representation("quaternions+positions", 7, True, "local quaternion then current position"),
    Representation("ortho6d+positions", 9, True, "ortho6D then current position"),
    Representation("positions_acrnn", 3, False, "the published acRNN's frame: root position, then every other "
                   "joint relative to the root", root_block=False),
)}


def _lookup(name: str) -> Representation:
    rep = REPRESENTATIONS.get(name) if isinstance(name, str) else None
    if rep is None:
        raise ValueError(f"name: expected one of {list(REPRESENTATIONS)}, got {name!r}")
    return rep


def frame_size(name: str, num_joints: int) -> int:
    """Values per frame, ``3 + D·J`` (e.g. 251 for ``"dual_quaternions"`` with J = 31; ``3 + D·(J − 1)`` for a
    representation without the root's block)."""
    rep = _lookup(name)
    if isinstance(num_joints, bool) or not isinstance(num_joints, (int, np.integer)) or num_joints < 1:
        raise ValueError(f"num_joints: expected a positive int, got {num_joints!r}")
    return 3 + rep.dim * rep.joints_stored(num_joints)


def _check_skeleton(skeleton) -> Skeleton:
    if not isinstance(skeleton, Skeleton):
        raise ValueError(f"skeleton: expected a Skeleton, got {type(skeleton).__name__}")
    return skeleton


def encode(name: str, skeleton: Skeleton, rotations, root_positions, order: str = "zyx") -> np.ndarray:
    """Frame vectors of one representation.

    Parameters
    ----------
    name : str
        A key of ``REPRESENTATIONS``.
    skeleton : Skeleton
    rotations : array_like, shape (..., J, 4)
        Local unit quaternions.
    root_positions : array_like, shape (..., 3)
    order : str
        Euler order for ``"euler"`` (ignored otherwise).

    Returns
    -------
    ndarray, shape (..., 3 + D·J), dtype of the inputs.
    """
    rep = _lookup(name)
    skel = _check_skeleton(skeleton)
    rot, pos = skel._check_motion(rotations, root_positions, unit=True)
    per_joint = _encode_joints(rep.name, skel, rot, order)                 # (..., J, D)
    if not rep.root_block:
        per_joint = per_joint[..., 1:, :]                                  # (..., J − 1, D)
    return np.concatenate([pos, per_joint.reshape(per_joint.shape[:-2] + (-1,))], axis=-1)


def _current_positions(skel: Skeleton, rot: np.ndarray) -> np.ndarray:
    return skel.forward_kinematics(rot, np.zeros(rot.shape[:-2] + (3,), dtype=rot.dtype))   # (..., J, 3)


def _ortho6d(rot: np.ndarray) -> np.ndarray:
    return ortho6d_from_matrix(matrix_from_quat(rot))                      # (..., J, 6)


def _encode_joints(name: str, skel: Skeleton, rot: np.ndarray, order: str) -> np.ndarray:
    if name in ("positions", "positions_acrnn"):
        return _current_positions(skel, rot)
    if name == "euler":
        return euler_from_quat(rot, order)
    if name == "expmap":
        return axis_angle_from_quat(rot)
    if name == "quaternions":
        return rot.copy()
    if name == "ortho6d":
        return _ortho6d(rot)
    if name == "dual_quaternions":
        return current_dq_from_local(rot, skel.offsets.astype(rot.dtype), skel.parents)
    if name == "quaternions+positions":
        return np.concatenate([rot, _current_positions(skel, rot)], axis=-1)
    if name == "ortho6d+positions":
        return np.concatenate([_ortho6d(rot), _current_positions(skel, rot)], axis=-1)
    raise AssertionError(name)  # pragma: no cover - the registry and this switch list the same names


def _split_frames(rep: Representation, skel: Skeleton, frames) -> tuple[np.ndarray, np.ndarray]:
    x = float_array(frames, "frames")
    stored = rep.joints_stored(skel.num_joints)
    size = 3 + rep.dim * stored
    if x.ndim < 1 or x.shape[-1] != size:
        raise ValueError(f"frames: expected shape (..., {size}) for {rep.name!r} with {skel.num_joints} joints "
                         f"(3 + {rep.dim}·{stored}), got {x.shape}")
    per_joint = x[..., 3:].reshape(x.shape[:-1] + (stored, rep.dim))   # (..., J, D)
    if not rep.root_block:  # the root's own block is zero
        zero = np.zeros(per_joint.shape[:-2] + (1, rep.dim), dtype=per_joint.dtype)
        per_joint = np.concatenate([zero, per_joint], axis=-2)
    return x[..., :3], per_joint


def decode(name: str, skeleton: Skeleton, frames, order: str = "zyx") -> tuple[np.ndarray, np.ndarray]:
    """Local rotations and root positions from frame vectors (inverse of :func:`encode`).

    Parameters
    ----------
    name : str
        A key of ``REPRESENTATIONS`` with ``invertible=True`` (``"positions"`` would need IK).
    skeleton : Skeleton
    frames : array_like, shape (..., 3 + D·J)
    order : str
        Euler order for ``"euler"``.

    Returns
    -------
    rotations : ndarray, shape (..., J, 4)
        Unit quaternions (sign not canonicalised; ``q ≡ −q``).
    root_positions : ndarray, shape (..., 3)
    """
    rep = _lookup(name)
    skel = _check_skeleton(skeleton)
    if not rep.invertible:
        raise ValueError(f"name: {name!r} has no inverse (recovering rotations from positions needs inverse "
                         "kinematics); use positions_from_frames for its positions")
    root, block = _split_frames(rep, skel, frames)
    if name == "euler":
        rot = quat_from_euler(block, order)
    elif name == "expmap":
        rot = quat_from_axis_angle(block)
    elif name in ("quaternions", "quaternions+positions"):
        rot = quat_normalize(block[..., :4])
    elif name in ("ortho6d", "ortho6d+positions"):
        rot = quat_from_matrix(matrix_from_ortho6d(block[..., :6]))
    else:  # dual_quaternions
        rot, _ = local_from_current_dq(dq_normalize(block), skel.parents)
        rot = quat_normalize(rot)
    return rot, root.copy()


def positions_from_frames(name: str, skeleton: Skeleton, frames, order: str = "zyx") -> np.ndarray:
    """World joint positions implied by frame vectors of any representation.

    ``"positions"`` and the ``+positions`` representations read their stored positions, ``"dual_quaternions"``
    the translations of the normalised current DQs (Eq. 8, no FK), the others run forward kinematics on the
    decoded rotations; the root position is added in every case.

    Returns
    -------
    ndarray, shape (..., J, 3)
    """
    rep = _lookup(name)
    skel = _check_skeleton(skeleton)
    root, block = _split_frames(rep, skel, frames)
    if name in ("positions", "positions_acrnn"):
        rel = block
    elif name.endswith("+positions"):
        rel = block[..., -3:]
    elif name == "dual_quaternions":
        rel = translation_from_dq(dq_normalize(block))
    else:
        rot, _ = decode(name, skel, frames, order=order)
        return skel.forward_kinematics(rot, root)
    return rel + root[..., None, :]


def fix_antipodal_frames(name: str, frames) -> np.ndarray:
    """Antipodal continuity over time (axis 0) of the quaternion blocks of frame vectors.

    ``"quaternions"`` and ``"quaternions+positions"``: ``quat_fix`` on each joint's quaternion (its positions
    untouched); ``"dual_quaternions"``: ``dq_fix`` (all 8 numbers flip with the real part, paper §5.1); other
    representations have no sign ambiguity and are returned as a copy.

    Parameters
    ----------
    name : str
    frames : array_like, shape (T, ..., 3 + D·J)
        J is inferred from the last axis.

    Returns
    -------
    ndarray, same shape and dtype.
    """
    rep = _lookup(name)
    x = float_array(frames, "frames")
    if x.ndim < 2 or x.shape[-1] < 3 + rep.dim or (x.shape[-1] - 3) % rep.dim:
        raise ValueError(f"frames: expected shape (T, ..., 3 + {rep.dim}·J) for {name!r}, got {x.shape}")
    num_joints = (x.shape[-1] - 3) // rep.dim
    out = x.copy()
    block = out[..., 3:].reshape(out.shape[:-1] + (num_joints, rep.dim))   # (T, ..., J, D), a copy
    if name in ("quaternions", "quaternions+positions"):
        block[..., :4] = quat_fix(block[..., :4])
    elif name == "dual_quaternions":
        block = dq_fix(block)
    else:
        return out
    out[..., 3:] = block.reshape(out.shape[:-1] + (-1,))
    return out
