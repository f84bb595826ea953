"""``Motion``: one clip of skeletal animation as an immutable value (spec/data.md §1).

A motion is a :class:`~refimpl.skeleton.Skeleton`, local joint rotations ``(T, J, 4)`` (unit quaternions
``(w, x, y, z)``, End Sites identity), world root positions ``(T, 3)``, the frame time in seconds and a name.
The arrays are stored read-only (copy before editing; :func:`dataclasses.replace` builds a new, re-validated
value). float32 arrays stay float32; anything else numeric becomes float64.

Shape legend: T frames, J joints.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from refimpl.skeleton import Skeleton, check_unit as _check_unit

__all__ = ["Motion"]


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

    Raises
    ------
    ValueError
        Wrong types or shapes, NaN/inf, non-unit quaternions, non-positive frame time.
    """

    skeleton: Skeleton
    rotations: np.ndarray
    root_positions: np.ndarray
    frame_time: float
    name: str = ""

    def __post_init__(self):
        if not isinstance(self.skeleton, Skeleton):
            raise ValueError(f"skeleton: expected a Skeleton, got {type(self.skeleton).__name__}")
        num = self.skeleton.num_joints
        rot = _as_stored(self.rotations, "rotations")
        if rot.ndim != 3 or rot.shape[1:] != (num, 4):
            raise ValueError(f"rotations: expected shape (T, {num}, 4), got {rot.shape}")
        _check_unit(rot, "rotations")
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

    def positions(self) -> np.ndarray:
        """World joint positions by quaternion forward kinematics, shape (T, J, 3)."""
        return self.skeleton.forward_kinematics(self.rotations, self.root_positions)

    def __repr__(self) -> str:
        return (f"Motion(name={self.name!r}, num_frames={self.num_frames}, num_joints={self.num_joints}, "
                f"fps={self.fps:.6g}, dtype={self.rotations.dtype})")


def _as_stored(x, name: str) -> np.ndarray:
    """A read-only float copy of ``x`` (float32 kept, other numeric types → float64), checked finite."""
    arr = np.asarray(x)
    if arr.dtype.kind not in "fiub":
        raise ValueError(f"{name}: expected a real numeric array, got dtype {arr.dtype}")
    arr = np.array(arr, dtype=arr.dtype if arr.dtype in (np.float32, np.float64) else np.float64, copy=True)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: contains NaN or infinite values")
    arr.flags.writeable = False
    return arr
