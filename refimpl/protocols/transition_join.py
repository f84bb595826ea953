"""Joins without a pop: carry the offset at each end of a generated transition away by inertialisation.

A network's transition need not start where the past motion was heading nor arrive where the target begins: it
leaves a jump at either end (spec/qtg.md §7.4). Games remove such jumps by *inertialisation* (Bollo, GDC 2018):
at the switch, the offset between where the old motion would be and where the new one is decays to zero over a
short blend. ``join="inertialize"`` does that at both ends with the project's own decay curve,
:func:`refimpl.protocols.transition_baselines.quintic_inertialization`; ``join="none"`` (the default
everywhere) leaves the network's frames as they are (the paper's numbers). ``join="inertialize+footlock"`` also
pins the planted feet afterwards (:mod:`refimpl.protocols.transition_footlock`, a NumPy post-process that needs
the skeleton; not in the exported graphs).

With past ``p_{-1}, p_0``, generated ``G_1 … G_T`` and targets ``g1, g2``, frame time ``dt`` and blend time ``t1``
(:func:`join_blend_frames` frames):

* **start**: the past's continuation ``c = p_0 + (p_0 − p_{-1})`` (rotations: ``c = (q_0 ⊗ q_{-1}⁻¹) ⊗ q_0``) is
  where frame 1 would be; the offset ``c − G_1`` is carried along a fixed axis with magnitude ``x(t)``,
  ``x(0) = |c − G_1|``, its rate ``v0`` from the offset one frame earlier, ``p_0 − G_0`` with the generated
  motion continued backwards ``G_0 = G_1 + (G_1 − G_2)``; frame ``k`` (at ``t = (k − 1) dt``) becomes
  ``G_k + x(t) X`` (rotations: ``quat(X, x(t)) ⊗ G_k``, angles ``2 atan2(|vec d|, w)`` of ``d = c ⊗ G_1⁻¹`` with
  ``w >= 0``). So frame 1 continues the past at its own velocity.
* **end**: the same, time reversed, on the start-corrected frames: the target's backward continuation
  ``g1 + (g1 − g2)`` is where frame ``T`` should be, and the offset decays towards frame ``T − t1/dt``.

Both offsets use the clamps of :func:`~refimpl.protocols.transition_baselines.quintic_inertialization` (never
away from zero, no overshoot). The ONNX rollout graph bakes the same computation in when exported with
``join="inertialize"`` (``deploy/join.py``).

Shape legend: B batch, T (or K) frames, P pose size (3 + 4 J), J joints, C channels (1 + J).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from refimpl.protocols.transition_footlock import FootLocked
from refimpl.protocols.transition_baselines import check_context, check_length, quintic_inertialization
from refimpl.arrays import float_array
from refimpl.quat import quat_conj, quat_mul
from refimpl.rotations import quat_from_axis_angle
from refimpl.protocols.transition import join_pose, split_pose

__all__ = ["JOIN_MODES", "EXPORT_JOIN_MODES", "JOIN_BLEND_FRAMES", "check_join", "check_export_join",
           "join_blend_frames", "carry_offset", "inertialize_joins", "with_join"]

#: The join options: ``"none"`` (the network's frames, the paper's numbers), ``"inertialize"``, or
#: ``"inertialize+footlock"`` (then foot locking, :mod:`refimpl.protocols.transition_footlock`).
JOIN_MODES = ("none", "inertialize", "inertialize+footlock")
#: The join options the exported graphs can bake in (foot locking is a NumPy post-process of their output).
EXPORT_JOIN_MODES = ("none", "inertialize")
#: Blend length in frames (1/3 s at 30 fps), at most ``T // 2`` so that the two blends do not overlap.
JOIN_BLEND_FRAMES = 10

_TINY = 1e-12


def check_join(join) -> str:
    """Validate a join option (one of :data:`JOIN_MODES`); returns it."""
    if join not in JOIN_MODES:
        raise ValueError(f"join: expected one of {', '.join(JOIN_MODES)}, got {join!r}")
    return join


def check_export_join(join) -> str:
    """Validate a join option of the exported graphs (one of :data:`EXPORT_JOIN_MODES`); returns it."""
    if check_join(join) not in EXPORT_JOIN_MODES:
        raise ValueError(f"join: the exported graphs take {' or '.join(EXPORT_JOIN_MODES)}; {join} is a NumPy "
                         "post-process of their output (spec/qtg.md 7.5)")
    return join


def join_blend_frames(T: int) -> int:
    """Frames of each blend: ``max(1, min(JOIN_BLEND_FRAMES, T // 2))``."""
    return max(1, min(JOIN_BLEND_FRAMES, check_length(T) // 2))


def _unit(q):
    return q / np.maximum(np.sqrt(np.sum(q * q, axis=-1, keepdims=True)), 1e-8)


def carry_offset(prev, frames, dt: float, blend_time: float) -> np.ndarray:
    """Carry the offset between the continuation of ``prev`` and ``frames[:, 0]`` away over ``blend_time``.

    Parameters
    ----------
    prev : ndarray (B, 2, P)
        The two poses before the frames, in time order (``p_{-1}, p_0``).
    frames : ndarray (B, K, P)
        The new motion ``G_1 … G_K``; quaternions are normalised first.
    dt : float
        Frame time (s).
    blend_time : float
        ``t1`` of :func:`~refimpl.protocols.transition_baselines.quintic_inertialization` (s), > 0.

    Returns
    -------
    ndarray (B, K, P), float64
        Frame ``k`` (1-based) is ``G_k`` moved by the offset's value at ``t = (k − 1) dt``; frame 1 is the
        continuation ``p_0 + (p_0 − p_{-1})`` (unit quaternions).
    """
    prev = float_array(prev, "prev", (None, 2, None), cast=False).astype(np.float64)
    frames = float_array(frames, "frames", (prev.shape[0], None, prev.shape[2]), cast=False).astype(np.float64)
    if frames.shape[1] < 1:
        raise ValueError("frames: expected at least one frame")
    r_m1, q_m1 = split_pose(prev[:, 0])  # (B, 3), (B, J, 4)
    r_0, q_0 = split_pose(prev[:, 1])
    r_g, q_g = split_pose(frames)  # (B, K, 3), (B, K, J, 4)
    q_m1, q_0, q_g = _unit(q_m1), _unit(q_0), _unit(q_g)
    k2 = min(1, frames.shape[1] - 1)  # G_2, or G_1 for a single frame (no velocity)

    # root: the continuation's offset from G_1 along a fixed axis
    off = 2.0 * r_0 - r_m1 - r_g[:, 0]  # (B, 3)
    x0 = np.sqrt(np.sum(off * off, axis=-1))  # (B,)
    axis = off / np.where(x0 > _TINY, x0, 1.0)[:, None]  # (B, 3)
    xm1 = np.sum((r_0 - (2.0 * r_g[:, 0] - r_g[:, k2])) * axis, axis=-1)  # (B,)

    # rotations: d = c ⊗ G_1⁻¹ in the w >= 0 hemisphere, its angle about a fixed axis
    cont = quat_mul(quat_mul(q_0, quat_conj(q_m1)), q_0)  # (B, J, 4)
    g0 = quat_mul(quat_mul(q_g[:, 0], quat_conj(q_g[:, k2])), q_g[:, 0])  # (B, J, 4)
    d0 = quat_mul(cont, quat_conj(q_g[:, 0]))
    d0 = np.where(d0[..., :1] < 0, -d0, d0)
    dm1 = quat_mul(q_0, quat_conj(g0))
    dm1 = np.where(np.sum(dm1 * d0, axis=-1, keepdims=True) < 0, -dm1, dm1)
    s0 = np.sqrt(np.sum(d0[..., 1:] ** 2, axis=-1))  # (B, J)
    raxis = d0[..., 1:] / np.where(s0 > _TINY, s0, 1.0)[..., None]  # (B, J, 3)
    a0 = 2.0 * np.arctan2(s0, d0[..., 0])  # (B, J)
    am1 = 2.0 * np.arctan2(np.sum(dm1[..., 1:] * raxis, axis=-1), dm1[..., 0])  # (B, J)

    mag0 = np.concatenate([x0[:, None], a0], axis=1)  # (B, C)
    magm1 = np.concatenate([xm1[:, None], am1], axis=1)  # (B, C)
    times = dt * np.arange(frames.shape[1])  # (K,)
    x = quintic_inertialization(mag0, (mag0 - magm1) / dt, blend_time, times)  # (B, C, K)
    root = r_g + x[:, 0, :, None] * axis[:, None]  # (B, K, 3)
    rot = quat_from_axis_angle(np.moveaxis(x[:, 1:], -1, 1)[..., None] * raxis[:, None])  # (B, K, J, 4)
    return join_pose(root, quat_mul(rot, q_g))


def inertialize_joins(past, poses, target, dt: float = 1.0 / 30.0, blend_frames: int | None = None) -> np.ndarray:
    """Remove the jumps at both ends of a generated transition (``join="inertialize"``, module docstring).

    Parameters
    ----------
    past, target : ndarray (B, 2, P)
        Un-normalised context poses.
    poses : ndarray (B, T, P)
        The generated transition.
    dt : float
        Frame time (s).
    blend_frames : int, optional
        Frames of each blend; default :func:`join_blend_frames` ``(T)``.

    Returns
    -------
    ndarray (B, T, P), float64, unit quaternions
    """
    past, target = check_context(past, target)
    poses = float_array(poses, "poses", (past.shape[0], None, past.shape[2]), cast=False)
    T = check_length(poses.shape[1])
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: expected a positive frame time, got {dt!r}")
    n = join_blend_frames(T) if blend_frames is None else blend_frames
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"blend_frames: expected a positive integer, got {blend_frames!r}")
    t1 = n * dt
    out = carry_offset(past, poses, dt, t1)  # start
    return carry_offset(target[:, ::-1], out[:, ::-1], dt, t1)[:, ::-1]  # end, time reversed


def with_join(method: Callable, join: str = "inertialize", dt: float = 1.0 / 30.0,
              blend_frames: int | None = None) -> Callable:
    """``f(past, target, T) -> poses``: ``method``'s transition with :func:`inertialize_joins` applied (``join ==
    "inertialize"``), then its feet locked (``"inertialize+footlock"``: a
    :class:`~refimpl.protocols.transition_footlock.FootLocked`, called with ``skeleton=``), or ``method`` itself
    (``"none"``)."""
    if check_join(join) == "none":
        return method
    if join == "inertialize+footlock":
        return FootLocked(with_join(method, "inertialize", dt, blend_frames), dt=dt)

    def joined(past, target, T):
        return inertialize_joins(past, method(past, target, T), target, dt=dt, blend_frames=blend_frames)

    return joined
