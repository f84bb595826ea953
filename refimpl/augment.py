"""Heading augmentation of motions: turn a motion about the vertical axis (spec/acrnn.md §1.1).

The published acRNN trainer (papagina/Auto_Conditioned_RNN_motion) turns every training window to a random heading
about the vertical axis before it computes its features: angle ``θ = (u − 0.5)·2π``, ``u ~ U(0, 1)``, applied
to the whole window in world space. On local rotations this is one product on the root,
``q_0' = r(θ) ⊗ q_0`` with ``r(θ) = (cos θ/2, sin θ/2 · up)``, and the root positions turn with it,
``p' = R(θ) p`` (about the vertical through the origin; the translation the published code adds as well is
cancelled by the hip-velocity features, so it is not reproduced). Every representation is then computed from the
turned window, so the augmentation is the same for positions, rotations and dual quaternions.

QuaterNet's long-term locomotion features (spec/locomotion.md §3) turn with the motion: :func:`rotate_controls`
rotates their direction and facing controls about +Y (the pose batches' augmentation, and the seed clip of the
walk turned to the path's first facing).

Shape legend: T frames, J joints, B windows; locomotion features (..., 8).
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from refimpl.mirroring import rotate_about_up
from refimpl.motion import Motion

__all__ = ["rotate_heading", "random_heading_windows", "rotate_controls"]


def rotate_heading(motion: Motion, angle: float, up: str = "y") -> Motion:
    """``motion`` turned by ``angle`` radians about the vertical axis ``up`` through the origin
    (:func:`refimpl.mirroring.rotate_about_up` on a :class:`~refimpl.motion.Motion`).

    Parameters
    ----------
    motion : Motion
        Local rotations ``(T, J, 4)``, root positions ``(T, 3)``.
    angle : float
    up : ``"x"``, ``"y"`` (default; BVH and CMU) or ``"z"``

    Returns
    -------
    Motion
        Root rotations ``r ⊗ q_0``, root positions ``R(r) p``; the other joints' local rotations unchanged.
    """
    if not np.isfinite(angle):
        raise ValueError(f"angle: expected a finite number, got {angle!r}")
    rot, pos = rotate_about_up(motion.rotations, motion.root_positions, float(angle), up)
    return Motion(motion.skeleton, rot, pos, motion.frame_time, motion.name)


def random_heading_windows(rng: np.random.Generator, motions: Sequence[Motion], batch_size: int, length: int,
                           margin: int = 0, up: str = "y") -> tuple[list[Motion], np.ndarray]:
    """``batch_size`` windows of ``length`` consecutive frames, each turned to a random heading.

    Each window: a motion chosen uniformly (equal weight per take, as acRNN), a start uniformly in
    ``[margin, T − length − margin]`` (the margin drops to 0 for short motions), an angle ``U(−π, π)``.

    Returns
    -------
    windows : list of B Motion (``length`` frames each)
    angles : ndarray (B,)
    """
    if not motions or min(m.num_frames for m in motions) < length:
        raise ValueError(f"motions: expected every motion to have at least {length} frames")
    windows, angles = [], np.empty(batch_size)
    for b in range(batch_size):
        m = motions[int(rng.integers(len(motions)))]
        pad = margin if m.num_frames - length - 2 * margin >= 0 else 0
        start = int(rng.integers(pad, m.num_frames - length - pad + 1))
        angles[b] = rng.uniform(-np.pi, np.pi)
        piece = Motion(m.skeleton, m.rotations[start:start + length], m.root_positions[start:start + length],
                       m.frame_time, m.name)
        windows.append(rotate_heading(piece, angles[b], up))
    return windows, angles


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
