"""QuaterNet long-term locomotion data: rigs, loading, mirroring, facing, phase, features, sequences, splits.

The data of the long-term system (spec/locomotion.md; QuaterNet
§3.7, §4.3; quaternet_reference_code.md §7, §8); the windows, pace data and protocol are in
:mod:`refimpl.protocols.locomotion`. Pipeline per file::

    load_* (BVH / exp-map)  →  prepare_motion (joint subset, units)  →  build_sequences (mirror × downsample
    phases; world positions, 8 features, phase)  →  pose_batch (windows + random rotation about Y)
                                                  →  sequence_spline → pace_training_data (training: the pace recipe)

Units: every position is in "QuaterNet units", the length unit of the CMU/Holden BVH files (CMU ASF units,
1 unit = 5.6444 cm), so that the reference's constants (spline density 5 points per unit, phase hysteresis 0.1,
walk ≈ 0.5 and run ≈ 1.2 units per frame) keep their meaning for every source. Frames: 30 per second.

Per-frame features (T, 8), reference ``extract_translations_controls`` (§7.3)::

    Δ = root xz displacement per frame (last row repeated), s = |Δ|, A = gaussian(s, σ = 5 frames)
    0  offset   = cumsum(s - A)                 translations (network outputs)
    1  height   = root y
    2, 3        = A cos φ, A sin φ              controls: phase φ (build_phase_track)
    4, 5        = A Δx/(|Δ|+1e-9), A Δz/(…)     controls: movement direction
    6, 7        = sin θ, cos θ                  controls: facing, θ = heading of the root (see facing_vectors)

Shape legend: T frames, J joints, B batch, P prefix, L = P + T_target window, N spline points.
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from refimpl.bvh import read_bvh, read_bvh_header
from refimpl.expmap import read_expmap
from refimpl.motion import TRANSLATION_TOLERANCE, Motion
from refimpl.quat import quat_fix, quat_mul, quat_rotate
from refimpl.rotations import matrix_from_quat, quat_from_matrix
from refimpl.skeleton import Skeleton, remove_joints
from refimpl.splines import gaussian_filter1d
from refimpl.checkpoint_fields import TaskSchema, int_field, kind_of, number_array, require_fields, skeleton_field

__all__ = ["CHECKPOINT_SCHEMA", 
    "QUATERNET_UNIT_CM", "FPS", "PHASE_EPSILON", "PHASE_COOLDOWN", "AMPLITUDE_SIGMA", "FEATURE_NAMES",
    "LocomotionRig", "CMU_RIG", "BANDAI_NAMCO_RIG", "load_cmu_bvh", "load_cmu_expmap", "load_bandai_namco",
    "prepare_motion", "mirror_motion", "facing_vectors", "build_phase_track", "extract_features",
    "LocomotionSequence", "downsample_strides", "build_sequences", "cmu_split", "bandai_namco_split",
]


#: Length of one QuaterNet (CMU/Holden BVH = CMU ASF) unit in centimetres (CMU FAQ: 0.056444 m).
QUATERNET_UNIT_CM = 5.6444
#: Frame rate of the locomotion data (the reference trains at 30 Hz).
FPS = 30.0
#: Phase detector hysteresis (units per frame) and cooldown (frames), reference ``build_phase_track``.
PHASE_EPSILON = 0.1
PHASE_COOLDOWN = 3
#: σ (frames) of the Gaussian low-pass filter giving the amplitude A (local speed).
AMPLITUDE_SIGMA = 5.0
FEATURE_NAMES = ("offset", "height", "phase_cos", "phase_sin", "direction_x", "direction_z", "facing_sin",
                 "facing_cos")



# ------------------------------------------------------------------------------------------------------------
# rigs: which joints, feet, hips, mirror plane and units for each data source
# ------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class LocomotionRig:
    """How a data source maps onto the locomotion pipeline.

    Attributes
    ----------
    name : str
    keep : tuple of str
        Joints kept, in skeleton order (the others are removed, their rotations pushed into the children).
    left_foot, right_foot : str
        Joints whose speeds drive the phase detector.
    left_hip, right_hip : str
        Their rest-pose difference, in the root's frame, is the root's "left" axis; the facing is
        ``left × up`` (see :func:`facing_vectors`).
    pairs : tuple of (str, str)
        Left/right partners for mirroring.
    unit_scale : float
        Multiplies the source's lengths to give QuaterNet units.
    remove_offsets : {"compose", "drop"}
        How :func:`refimpl.skeleton.remove_joints` treats a removed joint's offset ("drop" = QuaterNet's CMU
        quirk, which shortens the spine by Spine1's 2.05 units).
    """

    name: str
    keep: tuple
    left_foot: str
    right_foot: str
    left_hip: str
    right_hip: str
    pairs: tuple
    unit_scale: float = 1.0
    remove_offsets: str = "compose"


_CMU_KEEP = ("Hips", "LHipJoint", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "RHipJoint", "RightUpLeg",
             "RightLeg", "RightFoot", "RightToeBase", "LowerBack", "Spine", "Neck", "Neck1", "Head",
             "LeftShoulder", "LeftArm", "LeftForeArm", "LeftHand", "LeftHandIndex1",
             "RightShoulder", "RightArm", "RightForeArm", "RightHand", "RightHandIndex1")
_CMU_PAIRS = (("LHipJoint", "RHipJoint"),) + tuple(
    (n, n.replace("Left", "Right")) for n in _CMU_KEEP if n.startswith("Left"))

#: CMU (cgspeed BVH, 31 joints + End Sites, or the 38-joint ASF skeleton of the exp-map files) → QuaterNet's 26
#: joints (Spine1, the finger bases and thumbs and the End Sites removed; quaternet_reference_code.md §3.6).
CMU_RIG = LocomotionRig(name="cmu", keep=_CMU_KEEP, left_foot="LeftFoot", right_foot="RightFoot",
                        left_hip="LeftUpLeg", right_hip="RightUpLeg", pairs=_CMU_PAIRS, unit_scale=1.0)

_BN_KEEP = ("Hips", "Spine", "Chest", "Neck", "Head", "Shoulder_L", "UpperArm_L", "LowerArm_L", "Hand_L",
            "Shoulder_R", "UpperArm_R", "LowerArm_R", "Hand_R", "UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L",
            "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R")
#: Bandai Namco Research Motion Dataset 2: the 21 joints under the static ``joint_Root`` (its zero-offset End
#: Sites removed), centimetres → QuaterNet units.
BANDAI_NAMCO_RIG = LocomotionRig(
    name="bandai_namco", keep=_BN_KEEP, left_foot="Foot_L", right_foot="Foot_R", left_hip="UpperLeg_L",
    right_hip="UpperLeg_R", pairs=tuple((n, n[:-1] + "R") for n in _BN_KEEP if n.endswith("_L")),
    unit_scale=1.0 / QUATERNET_UNIT_CM)


# ------------------------------------------------------------------------------------------------------------
# loading
# ------------------------------------------------------------------------------------------------------------

def load_cmu_bvh(path, drop_first_frame: bool = True) -> Motion:
    """A CMU cgspeed BVH (Y up, 120 fps); the first frame (a reference pose added by the conversion) is dropped."""
    m = read_bvh(path)
    return _drop_first(m) if drop_first_frame else m


def load_cmu_expmap(path, drop_first_frame: bool = True, frame_time: float = 1.0 / 120.0) -> Motion:
    """A CMU exp-map text file (DMGNN / Li et al. layout, 38-joint ASF skeleton), assumed 120 fps."""
    m = read_expmap(path, layout="cmu", frame_time=frame_time)
    return _drop_first(m) if drop_first_frame else m


def _drop_first(m: Motion) -> Motion:
    if m.num_frames < 2:
        raise ValueError(f"{m.name}: expected at least 2 frames, got {m.num_frames}")
    return dataclasses.replace(m, rotations=m.rotations[1:], root_positions=m.root_positions[1:])


def load_bandai_namco(path, tolerance: float = TRANSLATION_TOLERANCE) -> Motion:
    """A Bandai Namco Research Motion Dataset 2 BVH, read by its documented convention.

    The files have a static ``joint_Root`` (6 channels, all zero) whose child ``Hips`` carries the root motion,
    and 6 channels on EVERY joint whose position channels hold the joint's local translation: they REPLACE the
    ``OFFSET`` (Blender's reading). :func:`refimpl.bvh.read_bvh` reads that convention (spec/data.md §2.1); with
    ``translations="rotations"`` it re-roots the motion at ``Hips`` and folds every other joint's translation,
    constant within ``tolerance`` (relative), into its offset, or raises. This function checks the layout (a root
    ``joint_Root`` whose only child is ``Hips``), sets the root's offset to 0 (the root position carries it) and
    makes the rotations continuous over time. Centimetres, 30 fps; :func:`prepare_motion` with
    :data:`BANDAI_NAMCO_RIG` keeps the 21 joints and converts the units.

    Returns
    -------
    Motion with the header's joints minus ``joint_Root`` (End Sites included), rotations continuous over time.
    """
    where = os.fspath(path)
    skel = read_bvh_header(path).skeleton
    if skel.names[0] != "joint_Root" or skel.num_joints < 2 or skel.names[1] != "Hips" or skel.children[0] != (1,):
        raise ValueError(f"{where}: expected a root 'joint_Root' whose only child is 'Hips', got root "
                         f"{skel.names[0]!r} with children {[skel.names[c] for c in skel.children[0]]}")
    m = read_bvh(path, translations="rotations", tolerance=tolerance)
    offsets = np.array(m.skeleton.offsets, dtype=np.float64)
    offsets[0] = 0.0
    sk = Skeleton(m.skeleton.parents, offsets, names=m.skeleton.names, end_sites=m.skeleton.end_sites)
    return Motion(skeleton=sk, rotations=quat_fix(m.rotations), root_positions=m.root_positions,
                  frame_time=m.frame_time, name=Path(where).stem)


# ------------------------------------------------------------------------------------------------------------
# joint subset, units, mirroring
# ------------------------------------------------------------------------------------------------------------

def prepare_motion(motion: Motion, rig: LocomotionRig) -> Motion:
    """Keep the rig's joints (rotations of removed joints pushed into their children) and convert to
    QuaterNet units. Joint order is the source's; ``joints_left``/``joints_right`` come from ``rig.pairs``."""
    if not isinstance(motion, Motion):
        raise ValueError(f"motion: expected a Motion, got {type(motion).__name__}")
    names = motion.skeleton.names
    missing = [n for n in rig.keep if n not in names]
    if missing:
        raise ValueError(f"motion {motion.name!r}: rig {rig.name!r} needs joints {missing}; the skeleton has {list(names)}")
    drop = [j for j, n in enumerate(names) if n not in rig.keep]
    skel, rot = remove_joints(motion.skeleton, motion.rotations, drop, offsets=rig.remove_offsets)
    if tuple(skel.names) != tuple(n for n in names if n in rig.keep):  # pragma: no cover - remove_joints keeps order
        raise AssertionError("joint order changed")
    idx = {n: j for j, n in enumerate(skel.names)}
    left = [idx[a] for a, _ in rig.pairs]
    right = [idx[b] for _, b in rig.pairs]
    skel = Skeleton(skel.parents, skel.offsets * rig.unit_scale, names=skel.names, end_sites=skel.end_sites,
                    joints_left=left, joints_right=right)
    return Motion(skeleton=skel, rotations=quat_fix(rot), root_positions=motion.root_positions * rig.unit_scale,
                  frame_time=motion.frame_time, name=motion.name)


def _mirror_frame_corrections(skel: Skeleton, perm: np.ndarray, reflect: np.ndarray) -> np.ndarray:
    """Per joint j, the rotation C_j (3, 3) with ``C_j · offset[perm[c]] ≈ M · offset[c]`` for j's children c
    (Wahba's problem by SVD; identity for leaves or when no rotation is determined)."""
    num = skel.num_joints
    out = np.tile(np.eye(3), (num, 1, 1))
    for j in range(num):
        kids = skel.children[j]
        if not kids:
            continue
        src = np.array([skel.offsets[perm[c]] for c in kids])              # offsets of the partner's children
        dst = np.array([reflect @ skel.offsets[c] for c in kids])
        if np.linalg.norm(src) < 1e-12:
            continue
        h = src.T @ dst                                                     # (3, 3)
        u, s, vt = np.linalg.svd(h)
        d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
        c = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
        if np.sum(s > 1e-9 * max(s[0], 1e-300)) < 2:  # one direction only: the minimal rotation src → dst
            c = _minimal_rotation(src[np.argmax(np.linalg.norm(src, axis=1))],
                                  dst[np.argmax(np.linalg.norm(src, axis=1))])
        out[perm[j]] = c
    return out


def _minimal_rotation(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v, c = np.cross(a, b), float(a @ b)
    if c < -1 + 1e-12:  # opposite: rotate by π about any axis orthogonal to a
        axis = np.cross(a, [1.0, 0, 0] if abs(a[0]) < 0.9 else [0, 1.0, 0])
        axis /= np.linalg.norm(axis)
        return 2 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def mirror_motion(motion: Motion, axis: str = "x") -> tuple[Motion, float]:
    """Mirror image of a motion across the world plane normal to ``axis``, left and right swapped.

    World rotations are reflected, ``Q'_{j'} = M Q_j M C_j`` with M the reflection, j' the partner of j and
    C_j a constant per-joint frame correction (:func:`_mirror_frame_corrections`); local rotations are rebuilt
    from them and the root position is reflected. For skeletons whose rest frames are themselves mirror
    symmetric (CMU: C = I) this is QuaterNet's ``(w, x, y, z) → (w, x, -y, -z)`` with swapped columns; for
    skeletons with per-joint oriented frames (Bandai Namco) the C_j make it exact too, as long as partners'
    offsets are mirror images.

    Returns
    -------
    motion : Motion (name + ``"_m"``)
    error : float
        Largest distance between the mirrored motion's joint positions and the reflected original's (swapped),
        over all frames: 0 up to rounding for an exactly symmetric skeleton.
    """
    a = "xyz".index(axis)
    skel = motion.skeleton
    perm = np.arange(skel.num_joints)
    left, right = np.array(skel.joints_left, dtype=int), np.array(skel.joints_right, dtype=int)
    perm[left], perm[right] = right, left
    reflect = np.eye(3)
    reflect[a, a] = -1.0
    corr = _mirror_frame_corrections(skel, perm, reflect)                   # (J, 3, 3) indexed by new joint
    world = skel.world_rotations(motion.rotations)                          # (T, J, 4)
    rw = matrix_from_quat(world)                                            # (T, J, 3, 3)
    new_world_m = reflect @ rw[:, perm] @ reflect @ corr                    # (T, J, 3, 3)
    new_world = quat_from_matrix(new_world_m)
    par = skel.parents
    new_local = np.empty_like(new_world)
    new_local[:, 0] = new_world[:, 0]
    inv_par = new_world[:, par[1:]] * np.array([1.0, -1, -1, -1])
    new_local[:, 1:] = quat_mul(inv_par, new_world[:, 1:])
    root = motion.root_positions * np.diag(reflect)
    out = Motion(skeleton=skel, rotations=quat_fix(new_local / np.linalg.norm(new_local, axis=-1, keepdims=True)),
                 root_positions=root, frame_time=motion.frame_time, name=motion.name + "_m")
    expected = (motion.positions() * np.diag(reflect))[:, perm]
    err = float(np.max(np.linalg.norm(out.positions() - expected, axis=-1))) if motion.num_frames else 0.0
    return out, err


# ------------------------------------------------------------------------------------------------------------
# facing, phase, features
# ------------------------------------------------------------------------------------------------------------

def _left_axis(skel: Skeleton, rig: LocomotionRig) -> np.ndarray:
    """The root's "left" axis in its own frame: rest position of the left hip minus the right hip's, normalised,
    with its vertical (rest-frame y) component kept (CMU: +x; Bandai Namco: -y of its rotated Hips frame)."""
    rest = skel.forward_kinematics(np.tile([1.0, 0, 0, 0], (skel.num_joints, 1)), np.zeros(3))
    v = rest[skel.index(rig.left_hip)] - rest[skel.index(rig.right_hip)]
    n = np.linalg.norm(v)
    if n < 1e-9:
        raise ValueError(f"rig {rig.name!r}: the hips {rig.left_hip!r} and {rig.right_hip!r} coincide at rest")
    return v / n


def facing_vectors(skeleton: Skeleton, rotations: np.ndarray, rig: LocomotionRig) -> np.ndarray:
    """Facing direction per frame as the ground vector ``(sin θ, cos θ)`` = its ``(x, z)`` components.

    ``a = R(q_root) · left_axis`` and facing = horizontal part of ``a × up`` = ``(-a_z, a_x)``, normalised.
    For the CMU skeleton (left axis +x) θ equals the root's yzx-Euler y angle, the reference's facing
    (``Ry Rz Rx e_x`` has heading θ whatever the z and x angles).

    Returns
    -------
    ndarray (T, 2)
    """
    a = quat_rotate(rotations[..., 0, :], _left_axis(skeleton, rig))       # (T, 3)
    f = np.stack([-a[..., 2], a[..., 0]], axis=-1)
    return f / (np.linalg.norm(f, axis=-1, keepdims=True) + 1e-12)


def build_phase_track(left_foot: np.ndarray, right_foot: np.ndarray, epsilon: float = PHASE_EPSILON,
                      cooldown: int = PHASE_COOLDOWN) -> np.ndarray:
    """Walk-cycle phase per frame from the two feet's world positions (reference ``build_phase_track``, §7.4).

    ``l, r`` = per-frame displacement norms of the feet (T - 1). Start: ``left = l[0] < r[0]``, phase π if
    ``left`` else 0, a key at frame 0. From frame ``cooldown`` on: while the left foot is the slow one and
    ``l[i] > r[i] + ε`` the right foot takes over (phase += π, key at i, skip ``cooldown`` frames), and
    symmetrically. Between keys the phase is linear; after the last key it is constant; the last frame
    extrapolates the one before. One cycle (2π) is two footsteps. (Issue #11: relative foot speed, not
    contact; the reference puts π at the left foot's contacts, the paper's text 0.)

    Parameters
    ----------
    left_foot, right_foot : ndarray (T, 3), T >= 2

    Returns
    -------
    ndarray (T,): unwrapped phase in radians (non-decreasing).
    """
    lf = np.asarray(left_foot, dtype=np.float64)
    rf = np.asarray(right_foot, dtype=np.float64)
    if lf.ndim != 2 or lf.shape[1] != 3 or rf.shape != lf.shape or lf.shape[0] < 2:
        raise ValueError(f"left_foot, right_foot: expected two (T >= 2, 3) arrays, got {lf.shape} and {rf.shape}")
    l = np.linalg.norm(np.diff(lf, axis=0), axis=-1)                        # (T-1,)
    r = np.linalg.norm(np.diff(rf, axis=0), axis=-1)
    n = l.size
    left = bool(l[0] < r[0])
    acc = math.pi if left else 0.0
    keys_t, keys_v = [0], [acc]
    i = cooldown
    while i < n:
        if left and l[i] > r[i] + epsilon:
            left, acc = False, acc + math.pi
            keys_t.append(i)
            keys_v.append(acc)
            i += cooldown
        elif not left and r[i] > l[i] + epsilon:
            left, acc = True, acc + math.pi
            keys_t.append(i)
            keys_v.append(acc)
            i += cooldown
        else:
            i += 1
    phase = np.interp(np.arange(n), keys_t, keys_v)                          # (T-1,) constant after the last key
    last = phase[-1] + (phase[-1] - phase[-2]) if n >= 2 else phase[-1]
    return np.concatenate([phase, [last]])


def extract_features(trajectory: np.ndarray, phase: np.ndarray, facing: np.ndarray,
                     sigma: float = AMPLITUDE_SIGMA) -> np.ndarray:
    """The 8 per-frame features (module docstring; reference ``extract_translations_controls``, §7.3).

    Parameters
    ----------
    trajectory : ndarray (T, 3)
        Root world positions (Y up), T >= 2.
    phase : ndarray (T,)
    facing : ndarray (T, 2)
        ``(sin θ, cos θ)`` from :func:`facing_vectors`.

    Returns
    -------
    ndarray (T, 8): ``[offset, height, A cos φ, A sin φ, A d_x, A d_z, sin θ, cos θ]``.
    """
    traj = np.asarray(trajectory, dtype=np.float64)
    num = traj.shape[0]
    if traj.ndim != 2 or traj.shape[1] != 3 or num < 2:
        raise ValueError(f"trajectory: expected shape (T >= 2, 3), got {traj.shape}")
    if np.shape(phase) != (num,) or np.shape(facing) != (num, 2):
        raise ValueError(f"phase, facing: expected shapes ({num},) and ({num}, 2), got {np.shape(phase)} and "
                         f"{np.shape(facing)}")
    xz = traj[:, [0, 2]]
    delta = np.diff(xz, axis=0)
    delta = np.concatenate([delta, delta[-1:]], axis=0)                      # (T, 2)
    speed = np.linalg.norm(delta, axis=-1)
    amp = gaussian_filter1d(speed, sigma, mode="reflect")
    feats = np.empty((num, 8))
    feats[:, 0] = np.cumsum(speed - amp)
    feats[:, 1] = traj[:, 1]
    feats[:, 2] = amp * np.cos(phase)
    feats[:, 3] = amp * np.sin(phase)
    feats[:, 4:6] = amp[:, None] * delta / (speed[:, None] + 1e-9)
    feats[:, 6:8] = facing
    return feats


# ------------------------------------------------------------------------------------------------------------
# sequences
# ------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True, eq=False)
class LocomotionSequence:
    """One training sequence at 30 fps (one source file × mirror × downsampling phase).

    Attributes
    ----------
    name : str
        ``<file stem>[_m]_d<k>``.
    source : str
        The file stem (the unit of the train/test split).
    skeleton : Skeleton
    rotations : (T, J, 4) local quaternions, continuous over time
    trajectory : (T, 3) root world position
    positions_world : (T, J, 3)
    positions_local : (T, J, 3) FK with the root's x and z set to 0 (height kept): the loss targets
    phase : (T,) unwrapped phase
    features : (T, 8), see :data:`FEATURE_NAMES`
    """

    name: str
    source: str
    skeleton: Skeleton
    rotations: np.ndarray
    trajectory: np.ndarray
    positions_world: np.ndarray
    positions_local: np.ndarray
    phase: np.ndarray
    features: np.ndarray

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])


def downsample_strides(frame_time: float, fps: float = FPS) -> int:
    """Stride taking ``1/frame_time`` to ``fps`` (120 → 4, 60 → 2, 30 → 1); ValueError unless it is an integer."""
    ratio = 1.0 / (float(frame_time) * fps)
    k = int(round(ratio))
    if k < 1 or abs(ratio - k) > 1e-3 * k:
        raise ValueError(f"frame_time: {frame_time} s ({1 / frame_time:.6g} fps) is not an integer multiple of {fps} fps")
    return k


def _sequence(name, source, motion: Motion, rig: LocomotionRig) -> LocomotionSequence:
    skel = motion.skeleton
    rot = np.array(motion.rotations)
    traj = np.array(motion.root_positions)
    pw = skel.forward_kinematics(rot, traj)
    local_root = traj * np.array([0.0, 1.0, 0.0])
    pl = skel.forward_kinematics(rot, local_root)
    phase = build_phase_track(pw[:, skel.index(rig.left_foot)], pw[:, skel.index(rig.right_foot)])
    feats = extract_features(traj, phase, facing_vectors(skel, rot, rig))
    return LocomotionSequence(name=name, source=source, skeleton=skel, rotations=rot, trajectory=traj,
                              positions_world=pw, positions_local=pl, phase=phase, features=feats)


def build_sequences(motion: Motion, rig: LocomotionRig, mirror: bool = True, all_phases: bool = True,
                    fps: float = FPS, source: str | None = None, mirror_axis: str = "x",
                    mirror_tolerance: float | None = None) -> list[LocomotionSequence]:
    """All training sequences of one source motion: original and mirrored, every downsampling phase.

    Parameters
    ----------
    motion : Motion
        As loaded (any joint set containing the rig's); converted by :func:`prepare_motion`.
    rig : LocomotionRig
    mirror : bool
        Add the mirror images (``_m``; QuaterNet mirrors across x = 0).
    all_phases : bool
        Keep every phase of the decimation (``_d0`` … ``_d{k-1}``; QuaterNet keeps the 4 of 120 → 30 Hz), else
        phase 0 only. Sources already at ``fps`` give ``_d0`` only.
    mirror_tolerance : float, optional
        Raise ValueError when the mirrored FK differs from the reflected original by more (units).

    Returns
    -------
    list of LocomotionSequence, sequences shorter than 2 frames skipped.
    """
    prepared = prepare_motion(motion, rig)
    stride = downsample_strides(prepared.frame_time, fps)
    src = source if source is not None else motion.name
    variants = [(prepared, "")]
    if mirror:
        mirrored, err = mirror_motion(prepared, axis=mirror_axis)
        if mirror_tolerance is not None and err > mirror_tolerance:
            raise ValueError(f"{motion.name}: mirrored positions differ by {err:.3g} units (> {mirror_tolerance})")
        variants.append((mirrored, "_m"))
    out = []
    for m, suffix in variants:
        for k in range(stride if all_phases else 1):
            rot, pos = m.rotations[k::stride], m.root_positions[k::stride]
            if rot.shape[0] < 2:
                continue
            sub = Motion(skeleton=m.skeleton, rotations=rot, root_positions=pos, frame_time=m.frame_time * stride,
                         name=m.name)
            out.append(_sequence(f"{src}{suffix}_d{k}", src, sub, rig))
    return out


# ------------------------------------------------------------------------------------------------------------
# whole-file splits
# ------------------------------------------------------------------------------------------------------------

def cmu_split(paths: Iterable) -> tuple[list, list]:
    """CMU exp-map files: the DMGNN split, ``…/test/…`` files held out (test/walking_1, test/running_1)."""
    train, test = [], []
    for p in paths:
        (test if "test" in Path(p).parts else train).append(p)
    return sorted(train, key=str), sorted(test, key=str)


_BN_RE = re.compile(r"dataset-2_(?P<content>[a-z-]+)_(?P<style>[a-z]+)_(?P<id>\d+)$")


def bandai_namco_split(paths: Iterable) -> tuple[list, list]:
    """Bandai Namco files: those whose numeric id ends in 1 (``_001``, ``_011``, …) are held out for testing
    (about 10 % of every content × style group); the others train. ValueError for an unexpected file name."""
    train, test = [], []
    for p in paths:
        m = _BN_RE.match(Path(p).stem)
        if m is None:
            raise ValueError(f"paths: {os.fspath(p)!r} is not named dataset-2_<content>_<style>_<id>.bvh")
        (test if int(m.group("id")) % 10 == 1 else train).append(p)
    return sorted(train, key=str), sorted(test, key=str)


# ---- what the task stores in a checkpoint (spec/robustness.md §9.1) ----

def _check_checkpoint(cfg: Mapping, config, where: str) -> None:
    """The locomotion fields: ``rig`` ``cmu`` or ``bandai_namco`` and a ``skeleton`` with that rig's joints (both
    required), ``prefix`` / ``target`` positive integers; the pose network: ``num_joints`` = the skeleton's J,
    ``seed_clip`` with ``rotations`` (S, J, 4) of non-zero quaternions and ``features`` (S, 8) finite,
    1 <= S <= 1000."""
    require_fields(cfg, ("skeleton", "rig"), where, "locomotion")
    rigs = {r.name: r for r in (CMU_RIG, BANDAI_NAMCO_RIG)}
    if not isinstance(cfg["rig"], str) or cfg["rig"] not in rigs:
        raise ValueError(f"{where}: model_config.rig: expected one of {list(rigs)}, got {kind_of(cfg['rig'])}")
    sk = skeleton_field(cfg["skeleton"], where, want_sides=True)
    keep = set(rigs[cfg["rig"]].keep)
    if keep != set(sk.names):
        raise ValueError(f"{where}: model_config.skeleton does not have the joints of the {cfg['rig']!r} rig "
                         f"(missing {sorted(keep - set(sk.names))[:4]}, extra {sorted(set(sk.names) - keep)[:4]})")
    for key in ("prefix", "target"):
        if key in cfg:
            int_field(cfg, key, where)
    J = getattr(config, "num_joints", None)
    if J is None:  # the pace network stores the rig and skeleton only
        return
    if J != sk.num_joints:
        raise ValueError(f"{where}: model_config.num_joints {J!r} does not match the stored skeleton's "
                         f"{sk.num_joints} joints")
    require_fields(cfg, ("seed_clip",), where, "quaternet-long")
    seed = cfg["seed_clip"]
    if not isinstance(seed, Mapping) or "rotations" not in seed or "features" not in seed:
        raise ValueError(f"{where}: model_config.seed_clip: expected an object with rotations and features, got "
                         f"{kind_of(seed)}")
    rot = number_array(seed["rotations"], f"{where}: model_config.seed_clip.rotations", (None, J, 4))
    feat = number_array(seed["features"], f"{where}: model_config.seed_clip.features", (rot.shape[0], 8))
    if not 1 <= rot.shape[0] <= 1000:
        raise ValueError(f"{where}: model_config.seed_clip: expected 1 to 1000 frames, got {rot.shape[0]}")
    norms = np.linalg.norm(rot, axis=-1)
    if not np.all((norms > 0.5) & (norms < 2.0)):
        raise ValueError(f"{where}: model_config.seed_clip.rotations: expected unit quaternions, got norms from "
                         f"{norms.min():.3g} to {norms.max():.3g}")
    del feat


#: The locomotion task's checkpoint schema (``refimpl.tasks.locomotion.CHECKPOINT_SCHEMA``, deploy's long-term loader).
CHECKPOINT_SCHEMA = TaskSchema("locomotion", check=_check_checkpoint)
