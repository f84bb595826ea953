"""QuaterNet long-term locomotion data: rigs, loading, mirroring, features, phase, splines, batches, pace data.

Everything of the long-term system that does not depend on the pose network (spec/locomotion.md; QuaterNet
§3.7, §4.3; quaternet_reference_code.md §7, §8). Pipeline per file::

    load_* (BVH / exp-map)  →  prepare_motion (joint subset, units)  →  build_sequences (mirror × downsample
    phases; world positions, 8 features, phase)  →  pose_batch (windows + random rotation about Y)
                                                  →  sequence_spline → pace_training_data → train_pace_network

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
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np

from refimpl.bvh import read_bvh, read_bvh_header
from refimpl.expmap import read_expmap
from refimpl.motion import TRANSLATION_TOLERANCE, Motion
from refimpl.optim import QUATERNET_LR_DECAY, adam_init, adam_step, exponential_lr
from refimpl.quat import matrix_from_quat, quat_fix, quat_from_matrix, quat_mul, quat_rotate
from refimpl.skeleton import Skeleton, remove_joints
from refimpl.splines import Spline, gaussian_filter1d

__all__ = [
    "LocomotionRig", "CMU_RIG", "BANDAI_NAMCO_RIG", "QUATERNET_UNIT_CM", "FPS", "PHASE_EPSILON",
    "PHASE_COOLDOWN", "AMPLITUDE_SIGMA", "FEATURE_NAMES",
    "load_cmu_bvh", "load_cmu_expmap", "load_bandai_namco", "prepare_motion", "mirror_motion",
    "facing_vectors", "build_phase_track", "extract_features", "LocomotionSequence", "build_sequences",
    "downsample_strides", "cmu_split", "bandai_namco_split", "PoseBatch", "pose_batch", "rotate_controls",
    "sequence_spline", "pace_training_data", "pace_batch", "train_pace_network",
    "NAME", "SPEEDS", "SEED_FRAMES", "LocomotionDataset", "add_train_options", "resolve_files", "build_dataset",
    "train_datasets", "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint", "trained_fields",
    "skeleton_of", "rig_of", "onnx_method", "evaluation_windows", "zero_velocity", "methods", "position_errors",
    "evaluate", "format_results",
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


# ------------------------------------------------------------------------------------------------------------
# pose-network windows and augmentation
# ------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class PoseBatch:
    """One batch of windows (reference ``PoseNetworkLongTerm``, §7.5).

    Attributes
    ----------
    inputs : (B, P + T, 4J + 8)
        ``[J local quaternions | offset, height | 6 controls]`` of frames ``s … s + P + T - 1``.
    target_positions : (B, T, J, 3)
        ``positions_local`` of frames ``s + P … s + P + T - 1``.
    target_translations : (B, T, 2)
        offset and height of the same frames.
    angles : (B,) rotation about +Y applied to each window (0 without augmentation).
    names : tuple of str, the sequence of each window; starts : (B,) window starts.
    """

    inputs: np.ndarray
    target_positions: np.ndarray
    target_translations: np.ndarray
    angles: np.ndarray
    names: tuple
    starts: np.ndarray


def rotate_controls(features: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Rotate the direction and facing controls about +Y: the ``(x, z)`` pairs (4, 5) and (6, 7) map as
    ``(x, z) → (x cos a + z sin a, -x sin a + z cos a)``; offset, height and phase are unchanged.

    Parameters
    ----------
    features : (..., 8)
    angles : broadcastable to ``features.shape[:-1]``
    """
    f = np.array(features, dtype=np.float64)
    c, s = np.cos(angles), np.sin(angles)
    for i in (4, 6):
        x, z = f[..., i].copy(), f[..., i + 1].copy()
        f[..., i] = x * c + z * s
        f[..., i + 1] = -x * s + z * c
    return f


def pose_batch(sequences: Sequence[LocomotionSequence], rng: np.random.Generator, batch_size: int = 40,
               prefix: int = 30, target: int = 60, augment: bool = True) -> PoseBatch:
    """Draw one batch: sequences with replacement, probability ∝ length (those shorter than P + T excluded),
    a uniform window start, and (``augment``) a random rotation θ ~ U(-2π, 2π) about +Y per window:
    root quaternions ← r ⊗ q_root with ``r = (cos θ/2, 0, sin θ/2, 0)``, target positions ← r · p, direction
    and facing controls rotated (:func:`rotate_controls`); phase and translations unchanged."""
    length = prefix + target
    pool = [s for s in sequences if s.num_frames >= length]
    if not pool:
        raise ValueError(f"sequences: none has the {length} frames a window needs")
    sizes = np.array([s.num_frames for s in pool], dtype=np.float64)
    pick = rng.choice(len(pool), size=batch_size, p=sizes / sizes.sum())
    num_j = pool[0].skeleton.num_joints
    inputs = np.empty((batch_size, length, 4 * num_j + 8))
    tpos = np.empty((batch_size, target, num_j, 3))
    ttr = np.empty((batch_size, target, 2))
    angles = rng.uniform(-2 * np.pi, 2 * np.pi, size=batch_size) if augment else np.zeros(batch_size)
    starts = np.empty(batch_size, dtype=np.int64)
    for b, k in enumerate(pick):
        s = pool[k]
        st = int(rng.integers(0, s.num_frames - length + 1))
        starts[b] = st
        rot = s.rotations[st:st + length].copy()
        feats = s.features[st:st + length]
        pos = s.positions_local[st + prefix:st + length]
        a = angles[b]
        if augment:
            r = np.array([math.cos(a / 2), 0.0, math.sin(a / 2), 0.0])
            rot[:, 0] = quat_mul(r, rot[:, 0])
            pos = quat_rotate(r, pos)
            feats = rotate_controls(feats, a)
        inputs[b, :, :4 * num_j] = rot.reshape(length, -1)
        inputs[b, :, 4 * num_j:] = feats
        tpos[b] = pos
        ttr[b] = s.features[st + prefix:st + length, :2]
    return PoseBatch(inputs=inputs, target_positions=tpos, target_translations=ttr, angles=angles,
                     names=tuple(pool[k].name for k in pick), starts=starts)


# ------------------------------------------------------------------------------------------------------------
# splines and pace-network data
# ------------------------------------------------------------------------------------------------------------

def sequence_spline(sequence: LocomotionSequence, points_per_unit: float = 5.0, smoothing: float = 1.0) -> Spline:
    """The sequence's ground path as a spline (reference ``compute_splines``, §8.2).

    Points: root ``(x, z)`` per frame (frames that do not move, closer than 1e-9 to the previous kept one, are
    skipped). Tracks: ``direction`` = facing ``(sin θ, cos θ)`` (circular), ``amplitude`` = A (linear),
    ``frequency`` = phase increment per frame, wrapped to (-π, π], last value repeated (linear). Then
    reparameterised (5 points per unit, smoothing 1) and given the constant track ``average_speed`` = the mean
    of the resampled amplitude.
    """
    xz = sequence.trajectory[:, [0, 2]]
    keep = [0]
    for t in range(1, xz.shape[0]):
        if np.linalg.norm(xz[t] - xz[keep[-1]]) > 1e-9:
            keep.append(t)
    keep = np.array(keep)
    if keep.size < 2:
        raise ValueError(f"sequence {sequence.name!r}: the root does not move")
    f = sequence.features
    amp = np.hypot(f[:, 2], f[:, 3])
    dphi = np.angle(np.exp(1j * np.diff(sequence.phase)))
    freq = np.concatenate([dphi, dphi[-1:]])
    sp = Spline(xz[keep], closed=False, tracks={"direction": (f[keep, 6:8], "circular"),
                                                 "amplitude": (amp[keep], "linear"),
                                                 "frequency": (freq[keep], "linear")})
    sp = sp.reparameterize(points_per_unit, smoothing)
    avg = float(sp.track("amplitude").mean())
    return sp.with_tracks(average_speed=(np.full(sp.num_points, avg), "linear"))


def pace_training_data(spline: Spline) -> tuple[np.ndarray, np.ndarray]:
    """Inputs and targets of the pace network along a sequence spline (§8.3).

    Returns
    -------
    inputs : (N, 2) ``[turning_angle, average_speed]``
    targets : (N, 4) ``[A, ω, cos Δ, sin Δ]`` with ``cos Δ = f · t``, ``sin Δ = t_0 f_1 - t_1 f_0`` (t the unit
    tangent, f the facing): Δ is the signed angle from the tangent to the facing.
    """
    t = spline.track("tangent")
    f = spline.track("direction")
    inputs = np.stack([spline.track("turning_angle")[:, 0], spline.track("average_speed")[:, 0]], axis=-1)
    targets = np.stack([spline.track("amplitude")[:, 0], spline.track("frequency")[:, 0],
                        np.sum(f * t, axis=-1), t[:, 0] * f[:, 1] - t[:, 1] * f[:, 0]], axis=-1)
    return inputs, targets


def pace_batch(data: Sequence[tuple[np.ndarray, np.ndarray]], rng: np.random.Generator, batch_size: int = 40,
               chunk_length: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Chunks of ``chunk_length`` points: splines drawn with replacement ∝ their number of points (shorter ones
    excluded), uniform start. Returns ``x (B, N, 2)``, ``y (B, N, 4)``."""
    pool = [d for d in data if d[0].shape[0] >= chunk_length]
    if not pool:
        raise ValueError(f"data: no spline has {chunk_length} points")
    sizes = np.array([d[0].shape[0] for d in pool], dtype=np.float64)
    pick = rng.choice(len(pool), size=batch_size, p=sizes / sizes.sum())
    x = np.empty((batch_size, chunk_length, 2))
    y = np.empty((batch_size, chunk_length, 4))
    for b, k in enumerate(pick):
        inp, tgt = pool[k]
        st = int(rng.integers(0, inp.shape[0] - chunk_length + 1))
        x[b], y[b] = inp[st:st + chunk_length], tgt[st:st + chunk_length]
    return x, y


def train_pace_network(train_data, config=None, epochs: int = 10, batch_size: int = 40, chunk_length: int = 1000,
                       lr: float = 1e-3, lr_decay: float = QUATERNET_LR_DECAY, seed: int = 1234, params=None,
                       valid_data=None, log: Callable[[str], None] | None = print):
    """Train the pace network (reference ``train_pace_network.py``): L1 loss, Adam(lr) × ``lr_decay`` per epoch,
    no gradient clipping, ⌈(number of splines) / batch⌉ batches per epoch.

    Parameters
    ----------
    train_data, valid_data : sequence of (inputs (N, 2), targets (N, 4)) from :func:`pace_training_data`
    config : refimpl.models.pace.PaceConfig, default bidirectional

    Returns
    -------
    params : dict
    history : list of dict ``{"epoch", "train_l1", "valid_l1"}`` (valid: L1 over every valid chunk, or None)
    """
    from refimpl.models import pace
    config = pace.PaceConfig() if config is None else config
    rng = np.random.default_rng(seed)
    params = pace.init_params(config, rng) if params is None else params
    state = adam_init(params)
    usable = [d for d in train_data if d[0].shape[0] >= chunk_length]
    batches = max(1, math.ceil(len(usable) / batch_size))
    history = []
    for epoch in range(epochs):
        step_lr = exponential_lr(lr, lr_decay, epoch)
        total = 0.0
        for _ in range(batches):
            x, y = pace_batch(usable, rng, batch_size, chunk_length)
            pred, cache = pace.forward(params, config, x)
            loss, lcache = pace.loss_forward(pred, y)
            _, grads = pace.backward(pace.loss_backward(1.0, lcache), cache)
            adam_step(params, grads, state, step_lr)
            total += loss
        valid = None
        if valid_data:
            vals = [pace.loss_forward(pace.forward(params, config, inp[None])[0], tgt[None])[0]
                    for inp, tgt in valid_data]
            valid = float(np.mean(vals))
        history.append({"epoch": epoch + 1, "train_l1": total / batches, "valid_l1": valid})
        if log is not None:
            log(f"pace epoch {epoch + 1}/{epochs}: train L1 {total / batches:.5f}"
                + ("" if valid is None else f", valid L1 {valid:.5f}"))
    return params, history


# ============================================================================================================
# the task interface (spec/architecture.md §tasks; spec/locomotion.md §8): data options, datasets, checkpoint
# facts, protocol, baselines. Generation along a path: refimpl.locomotion_generate (layer 7).
# ============================================================================================================

NAME = "locomotion"
#: Target speeds of ``refimpl generate --speed`` in units per frame at 30 fps (the reference notebook: walk 0.5,
#: run 1.2; jog between them is ours).
SPEEDS = {"walk": 0.5, "jog": 0.85, "run": 1.2}
#: Frames of the seed clip stored in a pose-network checkpoint (the generation prefix).
SEED_FRAMES = 30


@dataclasses.dataclass(frozen=True)
class LocomotionDataset:
    """The locomotion sequences of one side of a whole-file split.

    Attributes
    ----------
    sequences : tuple of LocomotionSequence
    rig : LocomotionRig
    files : tuple of str
        The source files (the unit of the split).
    prefix, target : int
        P and T of the pose network's windows.
    pace_chunk_length : int
        Spline points per pace-network training chunk (0 = automatic: min(1000, median spline length)).
    fps : float
    """

    sequences: tuple
    rig: LocomotionRig
    files: tuple
    prefix: int = 30
    target: int = 60
    pace_chunk_length: int = 0
    fps: float = FPS

    @property
    def skeleton(self) -> Skeleton:
        return self.sequences[0].skeleton

    @property
    def windows(self) -> tuple:
        """Sequences long enough for one pose window (P + T frames)."""
        return tuple(s for s in self.sequences if s.num_frames >= self.prefix + self.target)

    @property
    def num_frames(self) -> int:
        return int(sum(s.num_frames for s in self.sequences))

    def pace_data(self) -> list:
        """``(inputs (N, 2), targets (N, 4))`` of every sequence's spline (:func:`pace_training_data`); sequences
        whose root does not move are skipped."""
        out = []
        for s in self.sequences:
            try:
                out.append(pace_training_data(sequence_spline(s)))
            except ValueError:
                continue
        return out


def add_train_options(parser) -> None:
    """The locomotion task's options of ``refimpl train`` (its own names: every task adds its options to the
    same parser)."""
    from refimpl.bounds import bounded_int

    parser.add_argument("--locomotion-prefix", type=bounded_int("window"), default=30, metavar="P",
                        help="locomotion: conditioning frames of a pose window (default 30)")
    parser.add_argument("--locomotion-target", type=bounded_int("window"), default=60, metavar="T",
                        help="locomotion: predicted frames of a pose window (default 60)")
    parser.add_argument("--locomotion-max-files", type=bounded_int("files"), default=0, metavar="N",
                        help="locomotion: use at most N training and N held-out files (evenly spaced; 0 = all)")
    parser.add_argument("--pace-chunk-length", type=bounded_int("chunk"), default=0, metavar="N",
                        help="locomotion: spline points per pace-network chunk (default: min(1000, median))")


def _evenly(items: list, n: int) -> list:
    if n <= 0 or n >= len(items):
        return list(items)
    idx = np.unique(np.linspace(0, len(items) - 1, n).round().astype(int))
    return [items[i] for i in idx]


def resolve_files(data: str) -> tuple[str, list, list]:
    """``(source kind, train files, test files)`` for ``--data``.

    * ``"sample"``: the embedded CMU exp-map walks and runs (``refimpl/data/sample/expmap``, 10 training and 2
      held-out files, :func:`cmu_split`; 40-150 frames each at 30 fps, so use short windows);
    * a folder of Bandai Namco files (``dataset-2_*.bvh``), or a folder holding ``bandai_namco_locomotion``
      (``../shared/data``): :func:`bandai_namco_split`;
    * a folder with ``dmgnn_cmu_expmap`` or a DMGNN-like ``train/``, ``test/`` tree of CMU exp-map ``.txt``:
      :func:`cmu_split`;
    * any other folder of CMU ``.bvh`` files: sorted, the last 20 % held out.
    """
    from refimpl.errors import BadInputError
    if data == "sample":
        from refimpl.transitions import SAMPLE_DIR
        data = str(Path(SAMPLE_DIR) / "expmap")
    root = Path(data)
    if not root.is_dir():
        raise BadInputError(f"{root}: no such folder (locomotion --data takes 'sample' or a folder)")
    if (root / "bandai_namco_locomotion").is_dir():
        root = root / "bandai_namco_locomotion"
    bn = sorted(root.glob("dataset-2_*.bvh"))
    if bn:
        train, test = bandai_namco_split(bn)
        return "bandai_namco", [str(p) for p in train], [str(p) for p in test]
    if (root / "dmgnn_cmu_expmap").is_dir():
        root = root / "dmgnn_cmu_expmap"
    txt = sorted(p for p in root.rglob("*.txt") if "readme" not in p.name.lower())
    if txt:
        train, test = cmu_split(txt)
        return "cmu_expmap", [str(p) for p in train], [str(p) for p in test]
    bvh = sorted(root.rglob("*.bvh"))
    if len(bvh) < 2:
        raise BadInputError(f"{root}: found {len(bvh)} .bvh files; locomotion needs at least 2 (train and test)")
    n_test = max(1, int(round(0.2 * len(bvh))))
    return "cmu_bvh", [str(p) for p in bvh[:-n_test]], [str(p) for p in bvh[-n_test:]]


def _load_file(kind: str, path: str) -> tuple[Motion, LocomotionRig]:
    if kind == "bandai_namco":
        return load_bandai_namco(path), BANDAI_NAMCO_RIG
    if kind == "cmu_expmap":
        return load_cmu_expmap(path), CMU_RIG
    return load_cmu_bvh(path), CMU_RIG


def build_dataset(kind: str, files: Sequence[str], *, prefix: int = 30, target: int = 60, mirror: bool = True,
                  pace_chunk_length: int = 0, progress: Callable[[str], None] | None = None) -> LocomotionDataset:
    """Load ``files`` of one ``kind`` (:func:`resolve_files`) into a :class:`LocomotionDataset`
    (:func:`build_sequences`: mirrored, every downsampling phase)."""
    seqs, rig = [], None
    for i, f in enumerate(files):
        motion, rig = _load_file(kind, f)
        seqs.extend(build_sequences(motion, rig, mirror=mirror, source=Path(f).stem))
        if progress is not None and (i + 1) % 100 == 0:
            progress(f"  loaded {i + 1}/{len(files)} files")
    if not seqs:
        raise ValueError("files: no sequence loaded")
    ref = seqs[0].skeleton
    for s in seqs:
        if s.skeleton.num_joints != ref.num_joints or not np.allclose(s.skeleton.offsets, ref.offsets, atol=1e-6):
            raise ValueError(f"{s.name}: its skeleton differs from {seqs[0].name}'s; the FK loss needs one skeleton")
    return LocomotionDataset(tuple(seqs), rig, tuple(str(f) for f in files), int(prefix), int(target),
                             int(pace_chunk_length))


def train_datasets(args):
    """Train and held-out :class:`LocomotionDataset` of ``refimpl train``'s options (``--data``,
    ``--locomotion-*``)."""
    from refimpl.errors import BadInputError, UsageError
    P, T = int(args.locomotion_prefix), int(args.locomotion_target)
    if P < 1 or T < 2:
        raise UsageError(f"--locomotion-prefix must be >= 1 and --locomotion-target >= 2, got {P}, {T}")
    kind, train, test = resolve_files(args.data)
    n = int(getattr(args, "locomotion_max_files", 0) or 0)
    train, test = _evenly(train, n), _evenly(test, n)
    chunk = int(getattr(args, "pace_chunk_length", 0) or 0)
    try:
        return (build_dataset(kind, train, prefix=P, target=T, pace_chunk_length=chunk, progress=print),
                build_dataset(kind, test, prefix=P, target=T, pace_chunk_length=chunk))
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {args.data}: {exc}") from exc


def num_examples(dataset: LocomotionDataset) -> int:
    """Training examples: sequences with at least one pose window (the reference's ⌈#seq / batch⌉ batches per
    epoch; our trainer takes ⌊N / batch⌋)."""
    return max(1, len(dataset.windows))


def describe_data(train_ds: LocomotionDataset, test_ds: LocomotionDataset) -> str:
    """``"1470 training sequences (735 files, ...) / 190 held-out ..."``."""
    return (f"{len(train_ds.sequences)} training sequences ({len(train_ds.files)} files, {train_ds.num_frames} "
            f"frames, {len(train_ds.windows)} with a {train_ds.prefix}+{train_ds.target}-frame window) / "
            f"{len(test_ds.sequences)} held-out ({len(test_ds.files)} files), {train_ds.rig.name} rig, "
            f"{train_ds.skeleton.num_joints} joints, {train_ds.fps:g} fps")


def _seed_clip(ds: LocomotionDataset) -> dict:
    """The first SEED_FRAMES frames of the training sequence whose average speed is closest to a walk, for the
    generation prefix."""
    best, best_d = None, np.inf
    for s in ds.sequences:
        if s.num_frames < SEED_FRAMES + 1:
            continue
        amp = float(np.hypot(s.features[:SEED_FRAMES, 2], s.features[:SEED_FRAMES, 3]).mean())
        d = abs(amp - SPEEDS["walk"])
        if d < best_d:
            best, best_d = s, d
    if best is None:
        best = max(ds.sequences, key=lambda s: s.num_frames)
    n = min(SEED_FRAMES, best.num_frames)
    return {"name": best.name, "rotations": np.round(best.rotations[:n], 6).tolist(),
            "features": np.round(best.features[:n], 6).tolist()}


def checkpoint_extra(train_ds: LocomotionDataset) -> dict:
    """What a locomotion checkpoint carries: frame rate, rig, window sizes, the skeleton (FK and BVH output), and
    a seed clip (the generation prefix)."""
    sk = train_ds.skeleton
    return {"fps": float(train_ds.fps), "rig": train_ds.rig.name, "prefix": int(train_ds.prefix),
            "target": int(train_ds.target),
            "skeleton": {"names": list(sk.names), "parents": [int(p) for p in sk.parents],
                         "offsets": np.asarray(sk.offsets, np.float64).tolist(),
                         "joints_left": [int(j) for j in sk.joints_left],
                         "joints_right": [int(j) for j in sk.joints_right]},
            "seed_clip": _seed_clip(train_ds)}


def check_checkpoint(model_config: Mapping, path) -> None:
    """Refuse (BadInputError) a checkpoint without :func:`checkpoint_extra`'s skeleton."""
    from refimpl.errors import BadInputError
    if "skeleton" not in model_config or "rig" not in model_config:
        raise BadInputError(f"{path}: the checkpoint has no locomotion skeleton/rig; train it with `refimpl train`")


def trained_fields(model_config: Mapping, config) -> dict:
    """The :class:`~refimpl.registry.TrainedModel` fields of this task: the frame rate."""
    return {"fps": float(model_config.get("fps", FPS))}


def skeleton_of(model_config: Mapping) -> Skeleton:
    """The training skeleton stored by :func:`checkpoint_extra`."""
    s = model_config["skeleton"]
    return Skeleton(s["parents"], np.asarray(s["offsets"], dtype=np.float64), names=s["names"],
                    joints_left=s.get("joints_left"), joints_right=s.get("joints_right"))


def rig_of(model_config: Mapping) -> LocomotionRig:
    return {r.name: r for r in (CMU_RIG, BANDAI_NAMCO_RIG)}[model_config["rig"]]


def onnx_method(runtime) -> Callable:
    """``f(inputs (B, P + T, F)) -> (rotations (B, T, J, 4), translations (B, T, 2))`` running an exported
    long-term pose network step by step (``runtime.rollout``)."""
    def network_onnx(inputs, prefix: int):
        return runtime.rollout(np.asarray(inputs, np.float32), int(prefix))

    return network_onnx


# ------------------------------------------------------------------------------------------------------------
# protocol: free-running position error over the horizon, with ground-truth controls
# ------------------------------------------------------------------------------------------------------------

def evaluation_windows(ds: LocomotionDataset, stride: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deterministic held-out windows: every sequence with P + T frames, starts every ``stride`` frames (default
    T), no augmentation.

    Returns
    -------
    inputs : (N, P + T, 4J + 8); target_positions : (N, T, J, 3) ``positions_local``;
    target_translations : (N, T, 2)
    """
    P, T = ds.prefix, ds.target
    stride = T if stride is None else int(stride)
    ins, pos, tr = [], [], []
    for s in ds.windows:
        for st in range(0, s.num_frames - P - T + 1, stride):
            ins.append(np.concatenate([s.rotations[st:st + P + T].reshape(P + T, -1), s.features[st:st + P + T]], 1))
            pos.append(s.positions_local[st + P:st + P + T])
            tr.append(s.features[st + P:st + P + T, :2])
    if not ins:
        raise ValueError(f"dataset: no sequence has the {P + T} frames of a window")
    return np.stack(ins), np.stack(pos), np.stack(tr)


def zero_velocity(inputs: np.ndarray, prefix: int):
    """Baseline: the last prefix frame's pose and translations, held for the T frames."""
    B, L, F = inputs.shape
    J = (F - 8) // 4
    T = L - prefix
    rot = np.repeat(inputs[:, prefix - 1:prefix, :4 * J].reshape(B, 1, J, 4), T, axis=1)
    tr = np.repeat(inputs[:, prefix - 1:prefix, 4 * J:4 * J + 2], T, axis=1)
    return rot, tr


def methods(networks: Mapping[str, Callable] | None = None, *, fps: float = FPS) -> dict:
    """``name -> f(inputs (B, P + T, F), prefix) -> (rotations (B, T, J, 4), translations (B, T, 2))``: the
    networks (free-running with the ground-truth controls), then the zero-velocity baseline."""
    return {**dict(networks or {}), "zero_velocity": zero_velocity}


def position_errors(skeleton: Skeleton, rotations, translations, target_positions) -> tuple[np.ndarray, np.ndarray]:
    """Per horizon frame: mean joint-position error and mean joint-velocity error (units), positions from FK
    with root ``(0, height, 0)`` as the loss, or ``rotations`` themselves when they are positions (..., J, 3)
    (QN §4.4.2: velocity error = Euclidean error of the first difference of the positions).

    Returns
    -------
    position : (T,); velocity : (T - 1,)
    """
    rot = np.asarray(rotations, np.float64)
    tr = np.asarray(translations, np.float64)
    if rot.shape[-1] == 3:  # a position-output model: the positions themselves
        pos = rot
    else:
        root = np.zeros(rot.shape[:-2] + (3,))
        root[..., 1] = tr[..., 1]
        pos = skeleton.forward_kinematics(rot, root)                        # (B, T, J, 3)
    tgt = np.asarray(target_positions, np.float64)
    perr = np.linalg.norm(pos - tgt, axis=-1).mean(axis=(0, 2))
    verr = np.linalg.norm(np.diff(pos, axis=1) - np.diff(tgt, axis=1), axis=-1).mean(axis=(0, 2))
    return perr, verr


def evaluate(test_ds: LocomotionDataset, methods_by_name: Mapping[str, Callable], batch: int = 64) -> dict:
    """Free-running held-out error of every method over the T-frame horizon (:func:`evaluation_windows`,
    :func:`position_errors`): ``{name: {"position": (T,), "velocity": (T-1,), "mean_position", "mean_velocity",
    "windows"}}`` in QuaterNet units (× 5.6444 for cm)."""
    inputs, tpos, _ = evaluation_windows(test_ds)
    out = {}
    for name, f in methods_by_name.items():
        rots, trs = [], []
        for i in range(0, len(inputs), batch):
            r, t = f(inputs[i:i + batch], test_ds.prefix)
            rots.append(np.asarray(r, np.float64))
            trs.append(np.asarray(t, np.float64))
        perr, verr = position_errors(test_ds.skeleton, np.concatenate(rots), np.concatenate(trs), tpos)
        out[name] = {"position": perr, "velocity": verr, "mean_position": float(perr.mean()),
                     "mean_velocity": float(verr.mean()), "windows": int(len(inputs))}
    return out


def load_eval_data(data: str, model_config: Mapping, max_files: int = 0) -> LocomotionDataset:
    """The held-out :class:`LocomotionDataset` of ``--data`` (:func:`resolve_files`' test files) with the window
    sizes a checkpoint was trained with (``model_config["prefix"]``, ``["target"]``), for ``refimpl eval``.

    Raises
    ------
    BadInputError
        ``--data`` cannot be read, or its rig is not the checkpoint's.
    """
    from refimpl.errors import BadInputError
    kind, _, test = resolve_files(data)
    test = _evenly(test, int(max_files or 0))
    try:
        ds = build_dataset(kind, test, prefix=int(model_config.get("prefix", 30)),
                           target=int(model_config.get("target", 60)))
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {data}: {exc}") from exc
    if model_config.get("rig") not in (None, ds.rig.name):
        raise BadInputError(f"--data {data}: a {ds.rig.name} rig, but the checkpoint was trained on the "
                            f"{model_config.get('rig')} rig")
    return ds


def format_results(results: Mapping[str, dict], horizons=(1, 10, 30, 60)) -> str:
    """A table of the position error (units and cm) at a few horizon frames, and the mean velocity error."""
    names = list(results)
    T = len(results[names[0]]["position"])
    hs = [h for h in horizons if h <= T]
    head = ["method"] + [f"pos@{h}" for h in hs] + ["pos mean", "pos mean cm", "vel mean"]
    rows = [head]
    for n in names:
        r = results[n]
        rows.append([n] + [f"{r['position'][h - 1]:.3f}" for h in hs]
                    + [f"{r['mean_position']:.3f}", f"{r['mean_position'] * QUATERNET_UNIT_CM:.2f}",
                       f"{r['mean_velocity']:.4f}"])
    w = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(x) for c, x in zip(r, w)) for r in rows)
