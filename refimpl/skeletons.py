"""Built-in skeletons, stored as data (parents, offsets, names).

Every table here was transcribed from the project's reference notes, which record the numbers of the public
code bases as data (spec/data.md §3 gives the provenance of each):

* :func:`h36m_skeleton` — the Human3.6M 32-joint exp-map skeleton of Martinez et al. / QuaterNet
  (spec/kinematics.md §6), millimetres, no trajectory. "Offsets of Subject 1" (QuaterNet issue #9).
* :func:`cmu_asf_skeleton` — the CMU ASF skeleton of subject 02 behind the 117-value CMU exp-map files
  (DMGNN ``_some_variables``; spec/data.md §3): 31 joints with rotations + 7 End Sites = 38 joints,
  CMU ASF length units (≈ 5.6 cm). Identical to the hierarchy of the cgspeed BVH of CMU 02_01.
* :func:`cmu_skeleton` — the same skeleton without its End Sites: the 31-joint CMU list used by the
  dual-quaternion paper (251-value frames) and QuaterNet.
* :func:`quaternet_locomotion_skeleton` — QuaterNet's 31-joint CMU/Holden locomotion skeleton
  (spec/kinematics.md §6), optionally reduced to 26 joints the way QuaterNet does it.

Names: the joint names of the corresponding BVH; End Sites are called ``<parent>_end``; H3.6M names are the
project's own (the source code has none), chosen so that the side prefixes give anatomically correct
``joints_left`` / ``joints_right`` — QuaterNet's own lists are swapped relative to anatomy (§3.5, §3.6), which
only matters for colours because mirroring swaps both lists.

All skeletons are Y-up (H3.6M: the legs point along −y in the rest pose, QuaterNet's frame).
"""
from __future__ import annotations

import numpy as np

from refimpl.skeleton import Skeleton, remove_joints

__all__ = [
    "h36m_skeleton", "cmu_asf_skeleton", "cmu_skeleton", "quaternet_locomotion_skeleton",
    "H36M_PARENTS", "CMU_ASF_PARENTS", "CMU_PARENTS", "LOCOMOTION_PARENTS", "LOCOMOTION_REMOVED_JOINTS",
]

# ------------------------------------------------------------------------------------------------------------
# Human3.6M, 32 joints (spec/kinematics.md §6)
# ------------------------------------------------------------------------------------------------------------

H36M_PARENTS = (-1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 0, 11, 12, 13, 14, 12, 16, 17, 18, 19, 20, 19, 22, 12, 24, 25,
                26, 27, 28, 27, 30)

_H36M_OFFSETS = (
    (0.0, 0.0, 0.0),
    (-132.948591, 0.0, 0.0),
    (0.0, -442.894612, 0.0),
    (0.0, -454.206447, 0.0),
    (0.0, 0.0, 162.767078),
    (0.0, 0.0, 74.999437),
    (132.948826, 0.0, 0.0),
    (0.0, -442.894413, 0.0),
    (0.0, -454.20659, 0.0),
    (0.0, 0.0, 162.767426),
    (0.0, 0.0, 74.999948),
    (0.0, 0.1, 0.0),
    (0.0, 233.383263, 0.0),
    (0.0, 257.077681, 0.0),
    (0.0, 121.134938, 0.0),
    (0.0, 115.002227, 0.0),
    (0.0, 257.077681, 0.0),
    (0.0, 151.034226, 0.0),
    (0.0, 278.882773, 0.0),
    (0.0, 251.733451, 0.0),
    (0.0, 0.0, 0.0),
    (0.0, 0.0, 99.999627),
    (0.0, 100.000188, 0.0),
    (0.0, 0.0, 0.0),
    (0.0, 257.077681, 0.0),
    (0.0, 151.031437, 0.0),
    (0.0, 278.892924, 0.0),
    (0.0, 251.72868, 0.0),
    (0.0, 0.0, 0.0),
    (0.0, 0.0, 99.999888),
    (0.0, 137.499922, 0.0),
    (0.0, 0.0, 0.0),
)

# 3d-pose-baseline semantics: 1 = right hip, 6 = left hip, 17 = left shoulder, 25 = right shoulder.
_H36M_NAMES = (
    "Hips",
    "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToeBase_end",
    "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToeBase_end",
    "Spine", "Spine1", "Neck", "Head", "Head_end",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftHandThumb", "LeftHandThumb_end",
    "LeftWristEnd", "LeftWristEnd_end",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightHandThumb", "RightHandThumb_end",
    "RightWristEnd", "RightWristEnd_end",
)
_H36M_END_SITES = (5, 10, 15, 21, 23, 29, 31)


def h36m_skeleton() -> Skeleton:
    """Human3.6M 32-joint skeleton (Martinez et al., as QuaterNet reads the Human3.6M data set), millimetres.

    The 7 leaves (5, 10, 15, 21, 23, 29, 31) are flagged as End Sites (their rotations never move a position).
    Rest pose (all identity) is not a T-pose: legs along −y, spine and both arm chains along +y.

    Returns
    -------
    Skeleton with 32 joints.
    """
    return Skeleton(H36M_PARENTS, np.array(_H36M_OFFSETS), names=_H36M_NAMES, end_sites=_H36M_END_SITES)


# ------------------------------------------------------------------------------------------------------------
# CMU ASF (subject 02), 38 joints incl. 7 End Sites (spec/data.md §3)
# ------------------------------------------------------------------------------------------------------------

CMU_ASF_PARENTS = (-1, 0, 1, 2, 3, 4, 5, 0, 7, 8, 9, 10, 11, 0, 13, 14, 15, 16, 17, 18, 15, 20, 21, 22, 23, 24, 25,
                   23, 27, 15, 29, 30, 31, 32, 33, 34, 32, 36)

_CMU_ASF_OFFSETS = (
    (0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (1.65674, -1.80282, 0.62477),
    (2.59720, -7.13576, 0.0),
    (2.49236, -6.84770, 0.0),
    (0.19704, -0.54136, 2.14581),
    (0.0, 0.0, 1.11249),
    (0.0, 0.0, 0.0),
    (-1.61070, -1.80282, 0.62476),
    (-2.59502, -7.12977, 0.0),
    (-2.46780, -6.78024, 0.0),
    (-0.23024, -0.63258, 2.13368),
    (0.0, 0.0, 1.11569),
    (0.0, 0.0, 0.0),
    (0.01961, 2.05450, -0.14112),
    (0.01021, 2.06436, -0.05921),
    (0.0, 0.0, 0.0),
    (0.00713, 1.56711, 0.14968),
    (0.03429, 1.56041, -0.10006),
    (0.01305, 1.62560, -0.05265),
    (0.0, 0.0, 0.0),
    (3.54205, 0.90436, -0.17364),
    (4.86513, 0.0, 0.0),
    (3.35554, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (0.66117, 0.0, 0.0),
    (0.53306, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (0.54120, 0.0, 0.54120),
    (0.0, 0.0, 0.0),
    (-3.49802, 0.75994, -0.32616),
    (-5.02649, 0.0, 0.0),
    (-3.36431, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (-0.73041, 0.0, 0.0),
    (-0.58887, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (-0.59786, 0.0, 0.59786),
)

_CMU_ASF_NAMES = (
    "Hips",
    "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftToeBase_end",
    "RHipJoint", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightToeBase_end",
    "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head", "Head_end",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftFingerBase", "LeftHandIndex1",
    "LeftHandIndex1_end", "LThumb", "LThumb_end",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightFingerBase", "RightHandIndex1",
    "RightHandIndex1_end", "RThumb", "RThumb_end",
)
_CMU_ASF_END_SITES = (6, 12, 19, 26, 28, 35, 37)

CMU_PARENTS = (-1, 0, 1, 2, 3, 4, 0, 6, 7, 8, 9, 0, 11, 12, 13, 14, 15, 13, 17, 18, 19, 20, 21, 20, 13, 24, 25, 26,
               27, 28, 27)


def cmu_asf_skeleton() -> Skeleton:
    """CMU ASF skeleton of subject 02 (the skeleton of the 117-value CMU exp-map files), 38 joints.

    Joint ``j`` owns values ``3 + 3j … 5 + 3j`` of a 117-value row (joint 0's triplet is the root rotation).
    Units: CMU ASF length units (the CMU FAQ's factor 0.056444 converts to metres).

    Returns
    -------
    Skeleton with 38 joints, End Sites 6, 12, 19, 26, 28, 35, 37.
    """
    return Skeleton(CMU_ASF_PARENTS, np.array(_CMU_ASF_OFFSETS), names=_CMU_ASF_NAMES, end_sites=_CMU_ASF_END_SITES)


def cmu_skeleton() -> Skeleton:
    """The 31-joint CMU skeleton (subject 02 offsets): :func:`cmu_asf_skeleton` without its End Sites.

    Its parents are ``CMU_PARENTS``, the list used by the dual-quaternion paper (frame size 3 + 8·31 = 251) and
    by QuaterNet's locomotion skeleton.
    """
    asf = cmu_asf_skeleton()
    skel, _ = remove_joints(asf, None, asf.end_sites, offsets="compose")
    return skel


# ------------------------------------------------------------------------------------------------------------
# QuaterNet locomotion (CMU/Holden), 31 → 26 joints (spec/data.md §3, spec/locomotion.md §3.1)
# ------------------------------------------------------------------------------------------------------------

LOCOMOTION_PARENTS = CMU_PARENTS
LOCOMOTION_REMOVED_JOINTS = (13, 21, 23, 28, 30)

_LOCOMOTION_OFFSETS = (
    (0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (1.36306, -1.79463, 0.83929),
    (2.44811, -6.72613, 0.0),
    (2.5622, -7.03959, 0.0),
    (0.15764, -0.43311, 2.32255),
    (0.0, 0.0, 0.0),
    (-1.30552, -1.79463, 0.83929),
    (-2.54253, -6.98555, 0.0),
    (-2.56826, -7.05623, 0.0),
    (-0.16473, -0.45259, 2.36315),
    (0.0, 0.0, 0.0),
    (0.02827, 2.03559, -0.19338),
    (0.05672, 2.04885, -0.04275),
    (0.0, 0.0, 0.0),
    (-0.05417, 1.74624, 0.17202),
    (0.10407, 1.76136, -0.12397),
    (0.0, 0.0, 0.0),
    (3.36241, 1.20089, -0.31121),
    (4.983, 0.0, 0.0),
    (3.48356, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (0.71526, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (-3.1366, 1.37405, -0.40465),
    (-5.2419, 0.0, 0.0),
    (-3.44417, 0.0, 0.0),
    (0.0, 0.0, 0.0),
    (-0.62253, 0.0, 0.0),
    (0.0, 0.0, 0.0),
)

_LOCOMOTION_NAMES = (
    "Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
    "RHipJoint", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase",
    "LowerBack", "Spine", "Spine1", "Neck", "Neck1", "Head",
    "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftFingerBase", "LeftHandIndex1", "LThumb",
    "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightFingerBase", "RightHandIndex1", "RThumb",
)


def quaternet_locomotion_skeleton(reduced: bool = False) -> Skeleton:
    """QuaterNet's CMU/Holden locomotion skeleton (the CMU/Holden locomotion data set; spec/locomotion.md §3.1).

    Parameters
    ----------
    reduced : bool
        False: the 31 joints. True: QuaterNet's 26-joint version, ``remove_joints(LOCOMOTION_REMOVED_JOINTS,
        offsets="drop")`` — Spine1's non-zero offset is dropped as in QuaterNet, so the upper body is about
        2.05 units shorter than the BVH (spec/locomotion.md §3.1).

    Returns
    -------
    Skeleton with 31 or 26 joints. The offsets equal those of the cgspeed BVH of CMU 01_01 (subject 01).
    """
    skel = Skeleton(LOCOMOTION_PARENTS, np.array(_LOCOMOTION_OFFSETS), names=_LOCOMOTION_NAMES)
    if reduced:
        skel, _ = remove_joints(skel, None, LOCOMOTION_REMOVED_JOINTS, offsets="drop")
    return skel
