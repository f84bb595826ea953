"""``Motion``: one clip of skeletal animation as an immutable value (spec/data.md §1).

A motion is a :class:`~refimpl.skeleton.Skeleton`, local joint rotations ``(T, J, 4)`` (unit quaternions
``(w, x, y, z)``, End Sites identity), world root positions ``(T, 3)``, the frame time in seconds and a name,
and optionally per-frame local translations ``(T, J, 3)`` for the joints listed in ``translated_joints``
(BVH position channels on non-root joints: they replace the OFFSET). The arrays are stored read-only (copy
before editing; :func:`dataclasses.replace` builds a new, re-validated value). float32 arrays stay float32;
anything else numeric becomes float64.

The networks take rotations + root trajectory only: :func:`simplify_translations` turns a motion with
translations into one without (re-rooting at the moving child of a static root, folding translations that
are constant within a tolerance into the offsets), :func:`reroot_at_child` and
:func:`fold_constant_translations` are its two steps.

Shape legend: T frames, J joints.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from refimpl.arrays import check_finite, float_array
from refimpl.quat import quat_mul, quat_rotate
from refimpl.skeleton import Skeleton, check_unit

__all__ = ["Motion", "simplify_translations", "reroot_at_child", "fold_constant_translations",
           "TRANSLATION_TOLERANCE"]

#: default tolerance of :func:`fold_constant_translations`: a joint's translation is constant when its spread
#: (max − min over frames, per axis) is at most ``TRANSLATION_TOLERANCE · max(1, |t|max)`` (skeleton units;
#: Blender's BVH export writes constant translations with about 1e-5 of float noise)
TRANSLATION_TOLERANCE = 1e-4


@dataclasses.dataclass(frozen=True, eq=False)
class Motion:
    """One motion clip.

    Parameters
    ----------
    skeleton : Skeleton
    rotations : array_like, shape (T, J, 4)
        Local unit quaternions ``(w, x, y, z)`` (| |q| − 1 | <= ``refimpl.skeleton.UNIT_TOLERANCE``).
    root_positions : array_like, shape (T, 3)
        World position of the root (joint 0) per frame, in the skeleton's units.
    frame_time : float
        Seconds per frame (> 0), e.g. 1/120.
    name : str
        Free text (file stem by default in the readers).
    translations : array_like, shape (T, J, 3), optional
        Per-frame local translation of each joint from its parent (in the parent's frame), used by
        :meth:`positions` instead of ``skeleton.offsets`` for the joints in ``translated_joints``. The rows
        of the other joints are ignored and stored equal to the offsets. Default None: offsets everywhere.
    translated_joints : sequence of int, optional
        Indices (1..J−1, not End Sites) of the joints whose translation is per frame. Default: every
        non-root, non-End-Site joint when ``translations`` is given, none otherwise.

    Raises
    ------
    ValueError
        Wrong types or shapes, NaN/inf, non-unit quaternions, non-positive frame time, ``translated_joints``
        without ``translations`` or out of range.
    """

    skeleton: Skeleton
    rotations: np.ndarray
    root_positions: np.ndarray
    frame_time: float
    name: str = ""
    translations: np.ndarray | None = None
    translated_joints: tuple = None

    def __post_init__(self):
        if not isinstance(self.skeleton, Skeleton):
            raise ValueError(f"skeleton: expected a Skeleton, got {type(self.skeleton).__name__}")
        num = self.skeleton.num_joints
        rot = _as_stored(self.rotations, "rotations")
        if rot.ndim != 3 or rot.shape[1:] != (num, 4):
            raise ValueError(f"rotations: expected shape (T, {num}, 4), got {rot.shape}")
        check_unit(rot, "rotations")
        pos = _as_stored(self.root_positions, "root_positions")
        if pos.shape != (rot.shape[0], 3):
            raise ValueError(f"root_positions: expected shape ({rot.shape[0]}, 3) to match rotations "
                             f"{rot.shape}, got {pos.shape}")
        try:
            ft = float(self.frame_time)
        except (TypeError, ValueError):
            raise ValueError(f"frame_time: expected a positive number of seconds, got {self.frame_time!r}") from None
        if not (math.isfinite(ft) and ft > 0):
            raise ValueError(f"frame_time: expected a positive finite number of seconds, got {self.frame_time!r}")
        if not isinstance(self.name, str):
            raise ValueError(f"name: expected a str, got {type(self.name).__name__}")
        object.__setattr__(self, "rotations", rot)
        object.__setattr__(self, "root_positions", pos)
        object.__setattr__(self, "frame_time", ft)
        self._set_translations(rot)

    def _set_translations(self, rot: np.ndarray) -> None:
        skel, num = self.skeleton, self.skeleton.num_joints
        given = self.translated_joints
        if self.translations is None:
            if given:
                raise ValueError(f"translated_joints: {tuple(given)} given without translations")
            object.__setattr__(self, "translated_joints", ())
            return
        ends = set(skel.end_sites)
        movable = [j for j in range(1, num) if j not in ends]
        if given is None:
            joints = tuple(movable)
        else:
            try:
                joints = tuple(sorted({int(j) for j in given}))
                ok = all(not isinstance(j, bool) for j in given) and set(joints) <= set(movable)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise ValueError(f"translated_joints: expected indices of non-root, non-End-Site joints "
                                 f"(1..{num - 1}), got {given!r}")
        tr = _as_stored(self.translations, "translations")
        if tr.shape != rot.shape[:1] + (num, 3):
            raise ValueError(f"translations: expected shape ({rot.shape[0]}, {num}, 3), got {tr.shape}")
        if not joints:
            object.__setattr__(self, "translations", None)
            object.__setattr__(self, "translated_joints", ())
            return
        tr = np.array(tr)                                                  # (T, J, 3) writable copy
        fixed = np.ones(num, dtype=bool)
        fixed[list(joints)] = False
        tr[:, fixed, :] = skel.offsets[fixed].astype(tr.dtype)
        tr.flags.writeable = False
        object.__setattr__(self, "translations", tr)
        object.__setattr__(self, "translated_joints", joints)

    @property
    def num_frames(self) -> int:
        """Number of frames T."""
        return int(self.rotations.shape[0])

    @property
    def num_joints(self) -> int:
        """Number of joints J (End Sites included)."""
        return self.skeleton.num_joints

    @property
    def fps(self) -> float:
        """Frames per second, ``1 / frame_time``."""
        return 1.0 / self.frame_time

    @property
    def duration(self) -> float:
        """``num_frames · frame_time`` in seconds."""
        return self.num_frames * self.frame_time

    @property
    def translated_joint_names(self) -> tuple:
        """Names of the joints that carry per-frame translations (``()`` for a rotations-only motion)."""
        return tuple(self.skeleton.names[j] for j in self.translated_joints)

    def positions(self) -> np.ndarray:
        """World joint positions by quaternion forward kinematics, shape (T, J, 3) (per-frame translations
        used where the motion has them)."""
        return self.skeleton.forward_kinematics(self.rotations, self.root_positions, self.translations)

    def __repr__(self) -> str:
        extra = f", translated_joints={self.translated_joint_names}" if self.translated_joints else ""
        return (f"Motion(name={self.name!r}, num_frames={self.num_frames}, num_joints={self.num_joints}, "
                f"fps={self.fps:.6g}, dtype={self.rotations.dtype}{extra})")


def _as_stored(x, name: str) -> np.ndarray:
    """A read-only float copy of ``x`` (float32 kept, other numeric types → float64), checked finite
    (:func:`refimpl.arrays.float_array`)."""
    arr = float_array(x, name, finite=False)
    arr = check_finite(np.array(arr, dtype=arr.dtype if arr.dtype in (np.float32, np.float64) else np.float64,
                                copy=True), name)
    arr.flags.writeable = False
    return arr


# ---------------------------------------------------------------------------------------------------------
# from translations to rotations + root trajectory
# ---------------------------------------------------------------------------------------------------------

def _spread_ok(values: np.ndarray, tolerance: float) -> bool:
    """``values`` (T, 3) constant within ``tolerance · max(1, |values|max)``."""
    if values.shape[0] == 0:
        return True
    spread = float(np.max(np.ptp(values, axis=0)))
    return spread <= tolerance * max(1.0, float(np.max(np.abs(values))))


def _check_motion_arg(motion) -> None:
    if not isinstance(motion, Motion):
        raise ValueError(f"motion: expected a Motion, got {type(motion).__name__}")


def _check_tolerance(tolerance) -> float:
    try:
        tol = float(tolerance)
    except (TypeError, ValueError):
        tol = float("nan")
    if isinstance(tolerance, bool) or not (math.isfinite(tol) and tol >= 0):
        raise ValueError(f"tolerance: expected a finite number >= 0, got {tolerance!r}")
    return tol


def reroot_at_child(motion: Motion) -> Motion:
    """Remove the root joint when it has exactly one child; that child becomes the root (exact).

    Root motion carried by the child of a static root (``joint_Root`` at the origin and the trajectory on
    ``Hips``, as in the Bandai Namco files) becomes the root trajectory the networks use. With ``c`` the only
    child of the root ``0`` (translation ``t_c``, per frame or its offset)::

        root_positions' = root_positions + R(q_0) · t_c          q_c' = q_0 ⊗ q_c

    and every other joint keeps its rotation and translation, so :meth:`Motion.positions` gives the same
    world positions without joint 0 (tested). ``skeleton.offsets`` of the new root is the old ``offset[c]``.

    Parameters
    ----------
    motion : Motion

    Returns
    -------
    Motion
        ``J − 1`` joints, same names (minus the root), End Sites and translated joints renumbered.

    Raises
    ------
    ValueError
        The root does not have exactly one child, or that child is an End Site.
    """
    _check_motion_arg(motion)
    skel = motion.skeleton
    kids = skel.children[0]
    if len(kids) != 1 or kids[0] in skel.end_sites:
        raise ValueError(f"motion: the root {skel.names[0]!r} must have exactly one child joint to be removed, "
                         f"it has {len(kids)} children")
    c = kids[0]
    rot = motion.rotations
    t_c = motion.translations[:, c, :] if motion.translations is not None else skel.offsets[c]
    root_q = rot[:, 0, :]                                                   # (T, 4)
    new_root = motion.root_positions + quat_rotate(root_q, np.broadcast_to(t_c, root_q.shape[:-1] + (3,)).astype(rot.dtype))
    new_rot = np.array(rot[:, 1:, :])                                       # (T, J-1, 4)
    new_rot[:, c - 1, :] = quat_mul(root_q, rot[:, c, :])
    keep = list(range(1, skel.num_joints))
    parents = [-1 if skel.parents[j] == 0 else int(skel.parents[j]) - 1 for j in keep]
    new_skel = Skeleton(parents, skel.offsets[keep], names=[skel.names[j] for j in keep],
                        end_sites=[e - 1 for e in skel.end_sites])
    translated = [j - 1 for j in motion.translated_joints if j != c]
    translations = motion.translations[:, 1:, :] if translated else None
    return Motion(skeleton=new_skel, rotations=new_rot, root_positions=new_root, frame_time=motion.frame_time,
                  name=motion.name, translations=translations, translated_joints=translated if translated else None)


def fold_constant_translations(motion: Motion, tolerance: float = TRANSLATION_TOLERANCE,
                               varying: str = "keep") -> Motion:
    """Fold the per-frame translations that are constant (within ``tolerance``) into the skeleton's offsets.

    A translated joint whose spread (max − min over frames, per axis) is at most
    ``tolerance · max(1, max |t|)`` gets ``offset = mean over frames`` and leaves ``translated_joints``.

    Parameters
    ----------
    motion : Motion
    tolerance : float
        Relative tolerance (default :data:`TRANSLATION_TOLERANCE` = 1e-4).
    varying : {"keep", "error", "mean"}
        Joints whose translation varies more: kept as per-frame translations, ``ValueError``, or folded as
        their mean (lossy: the variation is dropped).

    Returns
    -------
    Motion
    """
    _check_motion_arg(motion)
    tol = _check_tolerance(tolerance)
    if varying not in ("keep", "error", "mean"):
        raise ValueError(f"varying: expected 'keep', 'error' or 'mean', got {varying!r}")
    if not motion.translated_joints:
        return motion
    skel, tr = motion.skeleton, motion.translations
    offsets = skel.offsets.copy()
    remaining = []
    for j in motion.translated_joints:
        values = tr[:, j, :].astype(np.float64)                             # (T, 3)
        if not _spread_ok(values, tol):
            if varying == "error":
                spread = float(np.max(np.ptp(values, axis=0)))
                raise ValueError(f"motion: joint {skel.names[j]!r} has translations that vary over time (spread "
                                 f"{spread:.3g} > tolerance {tol:g}); pass varying='keep' to keep them or "
                                 "'mean' to fold their mean (lossy)")
            if varying == "keep":
                remaining.append(j)
                continue
        if values.shape[0]:
            offsets[j] = values.mean(axis=0)
    new_skel = Skeleton(skel.parents, offsets, names=skel.names, end_sites=skel.end_sites,
                        joints_left=skel.joints_left, joints_right=skel.joints_right)
    return Motion(skeleton=new_skel, rotations=motion.rotations, root_positions=motion.root_positions,
                  frame_time=motion.frame_time, name=motion.name, translations=tr if remaining else None,
                  translated_joints=remaining if remaining else None)


def simplify_translations(motion: Motion, tolerance: float = TRANSLATION_TOLERANCE,
                          varying: str = "keep") -> Motion:
    """Rotations + root trajectory from a motion with per-frame translations (spec/data.md §2.1).

    1. While the root is static (position and rotation constant within ``tolerance``) and has exactly one
       child whose translation varies (beyond ``tolerance``), :func:`reroot_at_child` (the root motion is on
       the child of a static root, as in Bandai Namco; only a constant point is dropped);
    2. :func:`fold_constant_translations` (Blender exports: constant translations with float noise).

    Parameters
    ----------
    motion : Motion
    tolerance : float
        See :func:`fold_constant_translations`.
    varying : {"keep", "error", "mean"}
        What happens to translations still varying after both steps (see :func:`fold_constant_translations`);
        ``"error"`` guarantees a result with ``translated_joints == ()``.

    Returns
    -------
    Motion
        Same world positions (exactly for steps 1-2 up to the tolerance; ``"mean"`` is lossy).
    """
    _check_motion_arg(motion)
    tol = _check_tolerance(tolerance)
    while True:
        skel = motion.skeleton
        kids = skel.children[0]
        static_root = (_spread_ok(motion.root_positions.astype(np.float64), tol)
                       and _spread_ok(motion.rotations[:, 0, :].astype(np.float64), tol))
        if (static_root and len(kids) == 1 and kids[0] in motion.translated_joints
                and not _spread_ok(motion.translations[:, kids[0], :].astype(np.float64), tol)):
            motion = reroot_at_child(motion)
        else:
            break
    return fold_constant_translations(motion, tol, varying)
