"""Foot locking: a planted foot stays where it landed, by two-bone IK on the generated frames of a transition.

A network's transition may move a foot along the floor while it should be planted (foot skating, spec/qtg.md
§9.1). Games pin such a foot and bend the leg to reach the pin (e.g. Unreal's leg IK / foot placement).
``join="inertialize+footlock"`` (spec/qtg.md §7.5) does that after the join option, as a NumPy post-process of
the rollout's output; the paper's numbers are without it.

Algorithm, on the whole sequence ``p_{-1}, p_0 | G_1 … G_T | g1, g2`` (frames ``0 … F − 1``, the generated ones
``[start, stop) = [2, T + 2)``; forward-kinematics positions ``x`` in the window frame, cm, y up):

1. **legs** (:func:`leg_chains`): every foot joint (:func:`~refimpl.protocols.transition_quality.foot_joints`)
   whose parent is not a foot joint is an *ankle*; its parent is the *knee*, its grandparent the *hip*, the foot
   joints below it its *toes* (CMU: LeftUpLeg/LeftLeg/LeftFoot/LeftToeBase; Bandai Namco:
   UpperLeg_L/LowerLeg_L/Foot_L/Toes_L; salsa: lThigh/lShin/lFoot).
2. **contacts** (:func:`detect_contacts`): a leg is planted at frame ``k`` when one of its foot joints is within
   ``height`` (:data:`FOOTLOCK_HEIGHT_CM`) of its floor (its lowest height over the ``F`` frames: no ground truth
   at run time) AND moves slower than ``speed`` (:data:`FOOTLOCK_SPEED_CM_S`) horizontally (the mean of the
   steps into and out of ``k``). Why these values: spec/qtg.md §7.5.
3. **pins** (:func:`lock_weights`): each run ``[s, e]`` of planted frames is pinned at one frame ``p``: the
   last past frame ``start − 1`` when the run starts in the past context, else the first target frame ``stop``
   when it reaches the target context, else its first frame ``s``. Its weight is 1 on the *hold* and falls to 0
   over ``n`` (:data:`FOOTLOCK_BLEND_FRAMES`) frames outside it with ``S(u) = 3u² − 2u³``: hold ``[s_h, e_h]``
   with ``s_h = max(s, start)`` (``max(s, start + n)`` when ``p = stop``, so that the blend in has room), and
   ``e_h = stop − 1`` when ``p = stop``, else ``min(e, stop − 2 − n)`` (so that the blend out ends at ``G_T``);
   ``w(k) = min(S((k − s_h + m + 1)/(m + 1)), S((e_h + n + 1 − k)/(n + 1)))`` with ``m = min(n, s_h − start)``
   when ``p = stop``, else ``m = 0`` (pinned where it lands, the foot needs no blend in), ``S`` clipped to
   ``[0, 1]``; ``w = 0`` outside ``[start, stop)``.
4. **targets**: with the runs' weights ``w_r`` at frame ``k``, ``W = Σ w_r`` and ``c = max(1, W)``, the ankle's
   target is ``x_a + Σ_r w_r (x_a[p_r] − x_a) / c`` with its height replaced by ``x_a``'s own (the pin holds
   the foot's horizontal position; heel lift and toe-off stay the motion's), and the foot's world rotation
   ``normalize((1 − W/c) Q_a + Σ_r w_r Q_a[p_r] / c)`` (each pin's quaternion in ``Q_a``'s hemisphere).
5. **IK** (:func:`two_bone_ik`) moves the ankle onto its target; the ankle's local rotation is set to give the
   target world rotation, so the toes follow the foot. A target out of the leg's reach (the body has moved on
   too far from the pin) gives the straight leg pointing at it: the foot is then dragged, and lifted off the
   floor, until the run ends.

Frames outside ``[start, stop)`` and frames where no leg has weight are returned bit for bit.

Shape legend: B batch, F frames (2 + T + 2), T transition frames, J joints, P pose size (3 + 4 J), K foot joints
of a leg, M solved frames, ``...`` any leading axes.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from refimpl.arrays import float_array
from refimpl.protocols.transition import join_pose, split_pose
from refimpl.protocols.transition_baselines import check_context, check_length
from refimpl.protocols.transition_quality import foot_joints
from refimpl.quat import hemisphere_sign, quat_conj, quat_mul, quat_rotate
from refimpl.rotations import quat_from_axis_angle
from refimpl.skeleton import Skeleton

__all__ = ["FOOTLOCK_HEIGHT_CM", "FOOTLOCK_SPEED_CM_S", "FOOTLOCK_BLEND_FRAMES", "LegChain", "leg_chains", "two_bone_ik",
           "detect_contacts", "lock_weights", "lock_feet", "footlock", "FootLocked"]

#: A foot joint within this height (cm) of its lowest height in the sequence may be planted (spec/qtg.md §7.5:
#: §9.1's 2 cm plus 1 cm, as generated feet sink 0.5-2.3 cm below the ground truth's floor).
FOOTLOCK_HEIGHT_CM = 3.0
#: ... and is planted below this horizontal speed (cm/s); faster, it is a swing foot passing the floor (§7.5).
FOOTLOCK_SPEED_CM_S = 400.0
#: Frames of the blend into and out of a pin (0.1 s at 30 fps).
FOOTLOCK_BLEND_FRAMES = 3

_TINY = 1e-12


@dataclasses.dataclass(frozen=True)
class LegChain:
    """One leg's joint indices: ``hip`` (its rotation swings the leg), ``knee``, ``ankle``, and ``feet``: the
    ankle and the foot joints below it (the joints whose contact pins the leg)."""

    hip: int
    knee: int
    ankle: int
    feet: tuple


def leg_chains(skeleton: Skeleton) -> tuple[LegChain, ...]:
    """The legs of ``skeleton``, from its joint names and tree (module docstring, step 1).

    Raises
    ------
    ValueError
        No foot joint, or an ankle without a knee and a hip below the root.
    """
    par = skeleton.parents
    feet = set(foot_joints(skeleton))
    legs = []
    for a in sorted(j for j in feet if par[j] not in feet):
        knee = int(par[a])
        hip = int(par[knee]) if knee > 0 else -1
        if hip <= 0:
            raise ValueError(f"skeleton: foot joint {skeleton.names[a]!r} has no knee and hip below the root")
        below, stack = [a], [a]
        while stack:
            stack += [c for c in skeleton.children[stack.pop()] if c in feet]
            below += [c for c in stack if c not in below]
        legs.append(LegChain(hip=hip, knee=knee, ankle=a, feet=tuple(below)))
    return tuple(legs)


def _norm(v):
    return np.sqrt(np.sum(v * v, axis=-1))


def _perpendicular(v):
    """A unit vector perpendicular to each ``v (..., 3)`` (deterministic)."""
    e = np.eye(3)[np.argmin(np.abs(v), axis=-1)]  # the axis least aligned with v
    p = np.cross(v, e)
    return p / np.maximum(_norm(p), _TINY)[..., None]


def two_bone_ik(hip, knee, ankle, target, hint=None) -> tuple[np.ndarray, np.ndarray]:
    """Analytic two-bone IK: world rotations that move the ankle of the chain hip → knee → ankle onto ``target``.

    The knee bends in its current plane (normal ``n = (knee − hip) × (ankle − knee)``) until the hip–ankle
    distance is ``d = clip(|target − hip|, |l1 − l2|, l1 + l2)`` (interior knee angle
    ``φ = 2 atan2(√((d + l2 − l1)(d + l1 − l2)), √((l1 + l2 + d)(l1 + l2 − d)))``), then the whole leg turns about
    the hip along the shortest arc from the new ankle direction to ``target − hip``. An unreachable target gives
    the straight leg pointing at it. A straight leg has no plane: ``n = hint × (knee − hip)`` (e.g. the foot's
    forward direction, so that the knee bends forward), else any normal.

    Parameters
    ----------
    hip, knee, ankle, target : ndarray (..., 3)
        World positions.
    hint : ndarray (..., 3), optional

    Returns
    -------
    rot_hip, rot_knee : ndarray (..., 4)
        World-frame rotations: the new knee is ``hip + R(rot_hip)(knee − hip)``, the new ankle
        ``knee' + R(rot_hip ⊗ rot_knee)(ankle − knee)``; the hip joint's world rotation becomes
        ``rot_hip ⊗ Q_hip``, the knee's ``rot_hip ⊗ rot_knee ⊗ Q_knee``.
    """
    hip, knee, ankle, target = (np.asarray(v, dtype=np.float64) for v in (hip, knee, ankle, target))
    a, b = knee - hip, ankle - knee  # (..., 3)
    l1, l2 = _norm(a), _norm(b)
    n = np.cross(a, b)
    if hint is not None:
        n = np.where((_norm(n) <= 1e-9 * l1 * l2)[..., None], np.cross(np.asarray(hint, np.float64), a), n)
    n = np.where((_norm(n) <= 1e-9 * l1 * l2)[..., None], _perpendicular(a), n)
    n = n / np.maximum(_norm(n), _TINY)[..., None]
    d = np.clip(_norm(target - hip), np.abs(l1 - l2), l1 + l2)
    want = 2.0 * np.arctan2(np.sqrt(np.maximum((d + l2 - l1) * (d + l1 - l2), 0.0)),
                            np.sqrt(np.maximum((l1 + l2 + d) * (l1 + l2 - d), 0.0)))
    now = np.arctan2(_norm(np.cross(-a, b)), np.sum(-a * b, axis=-1))
    rot_knee = quat_from_axis_angle(n * (now - want)[..., None])  # turning b about n opens the knee
    u = a + quat_rotate(rot_knee, b)  # hip → new ankle
    v = target - hip
    axis = np.cross(u, v)
    s = _norm(axis)
    axis = np.where((s <= 1e-12 * _norm(u) * _norm(v))[..., None], n, axis / np.maximum(s, _TINY)[..., None])
    rot_hip = quat_from_axis_angle(axis * np.arctan2(s, np.sum(u * v, axis=-1))[..., None])
    return rot_hip, rot_knee


def detect_contacts(positions, feet, dt: float, *, height: float = FOOTLOCK_HEIGHT_CM,
                    speed: float = FOOTLOCK_SPEED_CM_S, up: int = 1) -> np.ndarray:
    """Frames where a leg is planted (module docstring, step 2).

    Parameters
    ----------
    positions : ndarray (B, F, J, 3)
        Whole sequences (F >= 2).
    feet : sequence of int (K,)
        The leg's foot joints (:attr:`LegChain.feet`).
    dt : float
        Frame time (s).
    height, speed : float
        Thresholds (cm, cm/s).
    up : int

    Returns
    -------
    ndarray (B, F), bool
    """
    x = positions[:, :, list(feet)]  # (B, F, K, 3)
    low = x[..., up] - x[..., up].min(axis=1, keepdims=True) < height  # (B, F, K)
    flat = [i for i in range(3) if i != up]
    step = _norm(np.diff(x[..., flat], axis=1)) / dt  # (B, F − 1, K)
    v = np.concatenate([step[:, :1], 0.5 * (step[:, 1:] + step[:, :-1]), step[:, -1:]], axis=1)  # (B, F, K)
    return np.any(low & (v < speed), axis=-1)


def _smooth(u):
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def lock_weights(contact, start: int, stop: int, blend_frames: int = FOOTLOCK_BLEND_FRAMES) -> list:
    """The pins of one leg and their weights (module docstring, step 3).

    Parameters
    ----------
    contact : ndarray (B, F), bool
        :func:`detect_contacts`.
    start, stop : int
        The generated frames ``[start, stop)``, ``1 <= start < stop <= F − 1``.
    blend_frames : int

    Returns
    -------
    list of (b, p, w)
        Sequence ``b``, pinned frame ``p`` and weights ``w (F,)`` of each run (non-zero only in ``[start, stop)``).
    """
    n = int(blend_frames)
    F = contact.shape[1]
    k = np.arange(F)
    out = []
    pad = np.pad(np.asarray(contact, bool), ((0, 0), (1, 1)))
    for b, s, e in _runs(pad):
        if s < start:
            p, s_h, e_h = start - 1, start, min(e, stop - 2 - n)
        elif e >= stop:
            p, s_h, e_h = stop, max(s, start + n), stop - 1
        else:
            p, s_h, e_h = s, s, min(e, stop - 2 - n)
        m = min(n, s_h - start) if p == stop else 0  # a pin at the run's own start needs no blend in
        w = np.minimum(_smooth((k - s_h + m + 1) / (m + 1)), _smooth((e_h + n + 1 - k) / (n + 1)))
        w[:start], w[stop:] = 0.0, 0.0
        if np.any(w > 0):
            out.append((b, p, w))
    return out


def _runs(pad):
    """``(b, s, e)`` of every run of True in the rows of ``pad (B, F + 2)`` (False at both ends), frames of the
    unpadded row, ``e`` inclusive."""
    edges = np.diff(pad.astype(np.int8), axis=1)  # (B, F + 1): +1 at a run's first frame, −1 after its last
    bs, ss = np.nonzero(edges == 1)
    _, es = np.nonzero(edges == -1)
    return zip(bs.tolist(), ss.tolist(), (es - 1).tolist())


def lock_feet(poses, skeleton: Skeleton, start: int, stop: int, dt: float = 1.0 / 30.0, *,
              height: float = FOOTLOCK_HEIGHT_CM, speed: float = FOOTLOCK_SPEED_CM_S,
              blend_frames: int = FOOTLOCK_BLEND_FRAMES, up: int = 1) -> np.ndarray:
    """Pin the planted feet of frames ``[start, stop)`` of whole sequences (module docstring).

    Parameters
    ----------
    poses : ndarray (B, F, P)
        ``[root (3) | J local quaternions]``, un-normalised; frames outside ``[start, stop)`` are context.
    skeleton : Skeleton with J joints (centimetres)
    start, stop : int
        ``1 <= start < stop <= F − 1``.
    dt : float
        Frame time (s).
    height, speed : float
        Contact thresholds (cm, cm/s), :func:`detect_contacts`.
    blend_frames : int
        ``n`` of :func:`lock_weights`, >= 1.
    up : int
        Index of the vertical axis.

    Returns
    -------
    ndarray (B, F, P), float64
        Changed frames carry unit quaternions; all other frames are ``poses``' values.
    """
    seq = float_array(poses, "poses", (None, None, None), cast=False).astype(np.float64)
    root, q = split_pose(seq)
    if q.shape[-2] != skeleton.num_joints:
        raise ValueError(f"poses: expected 3 + 4·{skeleton.num_joints} values, got {seq.shape[-1]}")
    if not 1 <= start < stop <= seq.shape[1] - 1:
        raise ValueError(f"start, stop: expected 1 <= start < stop <= F - 1 = {seq.shape[1] - 1}, got {start}, {stop}")
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: expected a positive frame time, got {dt!r}")
    if not isinstance(blend_frames, (int, np.integer)) or blend_frames < 1:
        raise ValueError(f"blend_frames: expected a positive integer, got {blend_frames!r}")
    norm = _norm(q)
    if np.any(norm < _TINY):
        raise ValueError("poses: a joint quaternion is zero")
    q = q / norm[..., None]
    world = skeleton.world_rotations(q)  # (B, F, J, 4)
    pos = skeleton.forward_kinematics(q, root)  # (B, F, J, 3)
    q_new = q.copy()
    changed = np.zeros(seq.shape[:2], bool)
    for leg in leg_chains(skeleton):
        contact = detect_contacts(pos, leg.feet, dt, height=height, speed=speed, up=up)
        wsum = np.zeros(seq.shape[:2])  # (B, F)
        pin_pos = np.zeros(seq.shape[:2] + (3,))  # Σ w_r x_a[p_r]
        pin_rot = np.zeros(seq.shape[:2] + (4,))  # Σ w_r Q_a[p_r], hemisphere of Q_a
        for b, p, w in lock_weights(contact, start, stop, blend_frames):
            wsum[b] += w
            pin_pos[b] += w[:, None] * pos[b, p, leg.ankle]
            qa = world[b, :, leg.ankle]  # (F, 4)
            pin_rot[b] += w[:, None] * hemisphere_sign(qa, world[b, p, leg.ankle][None]) * world[b, p, leg.ankle]
        bs, ks = np.nonzero(wsum > 0)  # (M,), (M,)
        if bs.size == 0:
            continue
        c = np.maximum(1.0, wsum[bs, ks])[:, None]  # (M, 1)
        keep = 1.0 - wsum[bs, ks, None] / c
        x_a = pos[bs, ks, leg.ankle]
        target = keep * x_a + pin_pos[bs, ks] / c  # (M, 3)
        target[:, up] = x_a[:, up]  # the pin holds the foot's horizontal position; its height is the motion's
        q_foot = keep * world[bs, ks, leg.ankle] + pin_rot[bs, ks] / c  # (M, 4)
        q_foot /= _norm(q_foot)[..., None]
        hint = pos[bs, ks, leg.feet[1]] - x_a if len(leg.feet) > 1 else None
        rot_hip, rot_knee = two_bone_ik(pos[bs, ks, leg.hip], pos[bs, ks, leg.knee], x_a, target, hint)
        w_par, w_hip, w_knee = (world[bs, ks, j] for j in (skeleton.parents[leg.hip], leg.hip, leg.knee))
        q_new[bs, ks, leg.hip] = quat_mul(quat_conj(w_par), quat_mul(rot_hip, w_hip))
        q_new[bs, ks, leg.knee] = quat_mul(quat_conj(w_hip), quat_mul(rot_knee, w_knee))
        knee_world = quat_mul(rot_hip, quat_mul(rot_knee, w_knee))
        q_new[bs, ks, leg.ankle] = quat_mul(quat_conj(knee_world), q_foot)
        changed[bs, ks] = True
    out = seq.copy()
    out[changed] = join_pose(root, q_new)[changed]
    return out


def footlock(past, poses, target, skeleton: Skeleton, dt: float = 1.0 / 30.0, **options) -> np.ndarray:
    """:func:`lock_feet` of a generated transition between its contexts.

    Parameters
    ----------
    past, target : ndarray (B, 2, P)
        Un-normalised context poses (never changed).
    poses : ndarray (B, T, P)
        The generated transition.
    skeleton : Skeleton
    dt : float
    **options
        ``height``, ``speed``, ``blend_frames``, ``up`` of :func:`lock_feet`.

    Returns
    -------
    ndarray (B, T, P), float64
    """
    past, target = check_context(past, target)
    poses = float_array(poses, "poses", (past.shape[0], None, past.shape[2]), cast=False)
    T = check_length(poses.shape[1])
    seq = np.concatenate([past, poses, target], axis=1)
    return lock_feet(seq, skeleton, 2, T + 2, dt, **options)[:, 2:T + 2]


class FootLocked:
    """``f(past, target, T, skeleton) -> poses``: ``method``'s transition followed by :func:`footlock`.

    ``needs_skeleton`` tells the callers (:func:`refimpl.protocols.transition_metrics.predict_transitions`,
    :func:`refimpl.tasks.transition_generate.make_transition`) to pass each window's skeleton.
    """

    needs_skeleton = True

    def __init__(self, method, dt: float = 1.0 / 30.0):
        self.method, self.dt = method, float(dt)

    def __call__(self, past, target, T, skeleton: Skeleton | None = None):
        if not isinstance(skeleton, Skeleton):
            raise ValueError("footlock: the method needs the windows' skeleton (skeleton=...)")
        return footlock(past, self.method(past, target, T), target, skeleton, dt=self.dt)
