"""Mocap rig conventions shared by every task: named joint subsets, length units, scaling, root heading.

The CMU recordings come in ASF length units (:data:`CMU_UNIT_CM` centimetres each); the acRNN salsa BVH files
are in centimetres. Every task works on a 22-joint subset of the recorded skeletons (:data:`CMU_22_JOINTS`,
:data:`SALSA_22_JOINTS`, :func:`subset_22`) with lengths in centimetres (:func:`scale_skeleton`). The heading of
a root rotation is its twist about the up axis (:func:`heading_from_root`, spec/qtg.md §8.2).

Shape legend: F frames, J joints.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from refimpl.arrays import float_array
from refimpl.skeleton import Skeleton, remove_joints

__all__ = ["CMU_22_JOINTS", "SALSA_22_JOINTS", "CMU_UNIT_CM", "SALSA_UNIT_CM", "RIGS", "subset_22",
           "scale_skeleton", "heading_from_root"]

CMU_UNIT_CM = 2.54 / 0.45  # 5.6444 cm per CMU ASF length unit (CMU mocap FAQ)
SALSA_UNIT_CM = 1.0  # the acRNN salsa BVH files are in centimetres

#: 22 joints kept from the CMU 31-joint cgspeed BVH / 38-joint ASF skeletons, in skeleton order.
#: Removed: LHipJoint, RHipJoint (rotation always 0 in the data: exact), the hand chains LeftFingerBase,
#: LeftHandIndex1/LFingers, LThumb and right counterparts (subtrees below the kept hands: exact), the End
#: Sites (exact), and Neck, whose rotation is pushed into Neck1 (``remove_joints``; approximate w.r.t. the
#: 31-joint skeleton: Neck has zero offset, so only Neck1/Head move, by at most |o_Neck1|·angle(Neck)).
#: This mirrors the common 22-joint (LaFAN1/Holden) layout: hips, 2 × 4 leg joints, 3 spine, neck, head,
#: 2 × 4 arm joints.
CMU_22_JOINTS = (
    "Hips", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RightUpLeg", "RightLeg", "RightFoot",
    "RightToeBase", "LowerBack", "Spine", "Spine1", "Neck1", "Head", "LeftShoulder", "LeftArm", "LeftForeArm",
    "LeftHand", "RightShoulder", "RightArm", "RightForeArm", "RightHand",
)

#: 22 joints kept from the 43-joint (57 with End Sites) DAZ-style salsa skeleton. Removed: the fingers
#: (subtrees below the hands), rightEye and the End Sites — all exact (leaves or subtrees). The body has 21
#: joints (a 5-joint spine chain, 2 × 4 leg and 2 × 4 arm joints), so a 22nd is needed: ``leftEye``, a leaf
#: with zero rotation in the data that marks the head's orientation.
SALSA_22_JOINTS = (
    "hip", "abdomen", "chest", "neck", "head", "leftEye", "rCollar", "rShldr", "rForeArm", "rHand", "lCollar",
    "lShldr", "lForeArm", "lHand", "rButtock", "rThigh", "rShin", "rFoot", "lButtock", "lThigh", "lShin", "lFoot",
)

#: Rig name -> (the 22 joints kept, centimetres per file length unit).
RIGS = {"cmu": (CMU_22_JOINTS, CMU_UNIT_CM), "salsa": (SALSA_22_JOINTS, SALSA_UNIT_CM)}


def subset_22(skeleton: Skeleton, rotations, keep: Sequence[str]):
    """Keep the joints named in ``keep`` (all others removed with :func:`refimpl.skeleton.remove_joints`).

    Removed joints push their rotation into their children (``offsets="compose"``), so positions of the kept
    joints are exact whenever the removed joints' rotations are the identity or the removed joints lie below
    every kept joint.

    Parameters
    ----------
    skeleton : Skeleton
    rotations : ndarray (F, J, 4)
    keep : sequence of str
        Joint names, in the skeleton's index order, the root first.

    Returns
    -------
    skeleton : Skeleton with ``len(keep)`` joints
    rotations : ndarray (F, len(keep), 4)
    """
    idx = [skeleton.index(n) for n in keep]
    if idx != sorted(idx) or idx[0] != 0:
        raise ValueError(f"keep: expected names in skeleton order starting with the root, got {list(keep)}")
    drop = [j for j in range(skeleton.num_joints) if j not in set(idx)]
    skel, rot = remove_joints(skeleton, rotations, drop, offsets="compose")
    return skel, rot


def scale_skeleton(skeleton: Skeleton, factor: float) -> Skeleton:
    """The same skeleton with every offset multiplied by ``factor`` (unit conversion)."""
    if not (np.isfinite(factor) and factor > 0):
        raise ValueError(f"factor: expected a positive number, got {factor!r}")
    return Skeleton(skeleton.parents, skeleton.offsets * float(factor), names=skeleton.names,
                    end_sites=skeleton.end_sites, joints_left=skeleton.joints_left,
                    joints_right=skeleton.joints_right)


def heading_from_root(root_rotations, up: str = "y") -> np.ndarray:
    """Heading quaternion: the twist of each root rotation about the ``up`` axis, ``normalise(w, 0, y, 0)``.

    Parameters
    ----------
    root_rotations : ndarray (..., 4)
    up : {"x", "y", "z"}

    Returns
    -------
    ndarray (..., 4)
        Unit rotations about ``up``; the identity where the twist is undefined (``w = y = 0``).
    """
    q = float_array(root_rotations, "root_rotations", (..., 4), cast=False)
    a = {"x": 1, "y": 2, "z": 3}.get(up)
    if a is None:
        raise ValueError(f"up: expected 'x', 'y' or 'z', got {up!r}")
    h = np.zeros_like(q)
    h[..., 0] = q[..., 0]
    h[..., a] = q[..., a]
    n = np.sqrt(h[..., 0] ** 2 + h[..., a] ** 2)  # (...)
    ok = n > 1e-9
    h = np.where(ok[..., None], h / np.where(ok, n, 1.0)[..., None], np.array([1.0, 0, 0, 0], dtype=q.dtype))
    return h
