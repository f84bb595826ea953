"""Transition baselines with the same interface as the network: inertialisation and temporal interpolation.

Both take the 2 past poses and the 2 target poses of a transition and return the ``T`` frames in between
(spec/qtg.md §7). Unlike the network, they work in UN-normalised pose space: root translation in the data's
length unit (relative to the window's first pose, see refimpl/protocols/transition.py), joint rotations as local
quaternions. Input quaternions are normalised before use; output quaternions are unit.

Indexing: past context ``p_{-1}, p_0``; transition ``p_1 … p_T``; targets ``g1 = p_{T+1}``, ``g2 = p_{T+2}``;
frame ``k`` is at time ``t_k = k·dt`` after ``p_0``.

:func:`method_registry` gives every evaluation the three methods ``{"qtg", "inertialization",
"interpolation"}`` as callables ``f(past, target, T) -> poses`` on un-normalised ``(B, 2, P)`` arrays.

Shape legend: B batch, T transition frames, P pose size (3 + 4 J), J joints, K sample times.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from refimpl.arrays import float_array
from refimpl.protocols.transition import join_pose, split_pose
from refimpl.quat import quat_conj, quat_mul, quat_slerp
from refimpl.rotations import quat_from_axis_angle

__all__ = [
    "quintic_inertialization", "inertialize", "interpolate", "method_registry", "METHOD_NAMES", "check_context",
    "check_length",
]

METHOD_NAMES = ("qtg", "inertialization", "interpolation")

_TINY = 1e-12


# ----------------------------------------------------------------------------------------------------------------
# inertialisation (Bollo, GDC 2018)
# ----------------------------------------------------------------------------------------------------------------

def _inertialization_coefficients(x0, v0, t1):
    """Clamped ``v0, t1, a0`` and quintic coefficients ``A, B, C`` (spec/qtg.md §7.1).

    ``x0 >= 0`` is the offset magnitude, ``v0`` its rate of change, ``t1 > 0`` the blend time; all broadcast.
    Returns ``(v0, t1, a0, A, B, C, active)`` where ``active`` is False where the offset is (numerically) zero
    or the blend time collapsed, and the curve is identically 0 there.
    """
    x0, v0, t1 = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x0, v0, t1)))
    v0 = np.minimum(v0, 0.0)  # moving away from the target: v0 <- 0
    with np.errstate(over="ignore"):  # -5 x0 / v0 = inf for a subnormal v0: then t1 stays
        t1 = np.where(v0 < 0, np.minimum(t1, -5.0 * x0 / np.where(v0 < 0, v0, -1.0)), t1)  # no overshoot
    active = (x0 > _TINY) & (t1 > _TINY)
    t1s = np.where(active, t1, 1.0)
    a0 = np.maximum((-8.0 * v0 * t1s - 20.0 * x0) / t1s ** 2, 0.0)
    A = -(a0 * t1s ** 2 + 6.0 * v0 * t1s + 12.0 * x0) / (2.0 * t1s ** 5)
    B = (3.0 * a0 * t1s ** 2 + 16.0 * v0 * t1s + 30.0 * x0) / (2.0 * t1s ** 4)
    C = -(3.0 * a0 * t1s ** 2 + 12.0 * v0 * t1s + 20.0 * x0) / (2.0 * t1s ** 3)
    return v0, t1, a0, A, B, C, active


def _quintic(x0, v0, t1, t):
    """Evaluate the clamped quintic at times ``t`` (..., K) for parameters of shape (...)."""
    v0, t1, a0, A, B, C, active = _inertialization_coefficients(x0, v0, t1)
    x0 = np.broadcast_to(np.asarray(x0, dtype=np.float64), v0.shape)
    t = np.asarray(t, dtype=np.float64)
    e = lambda a: a[..., None]  # noqa: E731  (..., 1)
    x = ((((e(A) * t + e(B)) * t + e(C)) * t + e(a0) / 2.0) * t + e(v0)) * t + e(x0)  # Horner, (..., K)
    return np.where(e(active) & (t < e(t1)), x, 0.0)


def quintic_inertialization(x0, v0, blend_time, t) -> np.ndarray:
    """Bollo's inertialisation curve: the offset ``x(t)`` that decays from ``x0`` to 0 (spec/qtg.md §7.1).

    Clamps (in this order): ``v0 ← min(v0, 0)`` (never move away from the target); if ``v0 < 0``:
    ``t1 ← min(t1, −5 x0 / v0)`` (no overshoot); ``a0 = (−8 v0 t1 − 20 x0) / t1²``, then ``a0 ← max(a0, 0)``.
    Then ``x(t) = A t⁵ + B t⁴ + C t³ + a0/2 t² + v0 t + x0`` for ``0 <= t < t1`` and 0 afterwards, with

    * ``A = −(a0 t1² + 6 v0 t1 + 12 x0) / (2 t1⁵)``
    * ``B = (3 a0 t1² + 16 v0 t1 + 30 x0) / (2 t1⁴)``
    * ``C = −(3 a0 t1² + 12 v0 t1 + 20 x0) / (2 t1³)``

    so that ``x(0) = x0``, ``x'(0) = v0``, ``x''(0) = a0``, ``x(t1) = x'(t1) = x''(t1) = 0``.

    Parameters
    ----------
    x0 : array_like (...), >= 0
        Offset magnitude at the switch (distance or angle).
    v0 : array_like (...)
        Its rate of change at the switch (negative: approaching the target).
    blend_time : array_like (...), > 0
        ``t1`` before clamping.
    t : array_like (K,)
        Sample times.

    Returns
    -------
    ndarray (..., K), float64
    """
    x0 = np.asarray(x0, dtype=np.float64)
    if not np.all(np.isfinite(x0)) or np.any(x0 < 0):
        raise ValueError("x0: expected finite magnitudes >= 0")
    v0 = np.asarray(v0, dtype=np.float64)
    if not np.all(np.isfinite(v0)):
        raise ValueError("v0: expected finite values, got NaN or inf")
    t1 = np.asarray(blend_time, dtype=np.float64)
    if not np.all(np.isfinite(t1)) or np.any(t1 <= 0):
        raise ValueError(f"blend_time: expected finite values > 0, got {blend_time!r}")
    t = np.asarray(t, dtype=np.float64)
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise ValueError(f"t: expected a finite 1-D array of times, got shape {t.shape}")
    return _quintic(x0, v0, t1, t)


def _unit_quats(q, name):
    n = np.sqrt(np.sum(q * q, axis=-1, keepdims=True))
    if np.any(n < 1e-8):
        raise ValueError(f"{name}: expected non-zero joint quaternions, got a zero quaternion")
    return q / n


def check_context(past, target):
    """Validate a transition's context: ``past (B, 2, P)`` and ``target (B, 2, P)`` with ``P = 3 + 4 J``."""
    past = float_array(past, "past", (None, 2, None), cast=False)
    P = past.shape[-1]
    if (P - 3) % 4 != 0 or P < 7:
        raise ValueError(f"past: expected pose size 3 + 4 J, got {P}")
    target = float_array(target, "target", (past.shape[0], 2, P), cast=False)
    return past, target


def check_length(T):
    """Validate a transition length ``T`` (a positive integer); returns it as ``int``."""
    if not isinstance(T, (int, np.integer)) or T < 1:
        raise ValueError(f"T: expected a positive integer number of frames, got {T!r}")
    return int(T)


def inertialize(past, target, T: int, dt: float = 1.0 / 30.0, blend_time: float | None = None) -> np.ndarray:
    """Inertialisation from the past context onto the (static) first target pose (spec/qtg.md §7.1).

    The source animation is the past context (its last pose ``p_0`` and velocity ``(p_0 − p_{-1}) / dt``);
    the target animation is the first target pose ``g1`` held still (only two target poses are known). Each
    channel's offset is inertialised along a FIXED axis with :func:`quintic_inertialization`:

    * root translation: ``x0 = |p_0 − g1|``, axis ``X = (p_0 − g1)/x0``, ``x_{-1} = (p_{-1} − g1)·X``;
      output ``g1 + x(t) X``;
    * each joint rotation: ``q0 = p_0 ⊗ g1⁻¹`` taken with ``w >= 0``, ``X = vec(q0)/|vec(q0)|``,
      ``x0 = 2 atan2(|vec q0|, w0)``; ``q_{-1} = p_{-1} ⊗ g1⁻¹`` taken in ``q0``'s hemisphere,
      ``x_{-1} = 2 atan2(vec(q_{-1})·X, w_{-1})``; output ``quat(X, x(t)) ⊗ g1``;

    with ``v0 = (x0 − x_{-1}) / dt`` and frames at ``t_k = k dt``, ``k = 1 … T``.

    Parameters
    ----------
    past, target : ndarray (B, 2, P)
        Un-normalised poses ``[root (3) | J quaternions (4 each)]``.
    T : int
        Frames to generate.
    dt : float
        Frame time in seconds (1/30).
    blend_time : float, optional
        ``t1`` before clamping; default ``(T + 1) dt``, the time of ``g1`` (so the offset reaches 0 when the
        target pose is due, like :func:`interpolate`).

    Returns
    -------
    ndarray (B, T, P), float64 (or the inputs' dtype)
    """
    past, target = check_context(past, target)
    T = check_length(T)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: expected a positive frame time, got {dt!r}")
    t1 = (T + 1) * dt if blend_time is None else float(blend_time)
    if not (np.isfinite(t1) and t1 > 0):
        raise ValueError(f"blend_time: expected a positive time, got {blend_time!r}")
    dtype = past.dtype
    p = past.astype(np.float64)
    g = target.astype(np.float64)
    times = dt * np.arange(1, T + 1)  # (T,)
    root_m1, q_m1 = split_pose(p[:, 0])  # (B, 3), (B, J, 4)
    root_0, q_0 = split_pose(p[:, 1])
    root_g, q_g = split_pose(g[:, 0])
    q_m1, q_0, q_g = (_unit_quats(q, n) for q, n in ((q_m1, "past"), (q_0, "past"), (q_g, "target")))

    # root translation
    off0 = root_0 - root_g  # (B, 3)
    x0 = np.sqrt(np.sum(off0 * off0, axis=-1))  # (B,)
    axis = off0 / np.where(x0 > _TINY, x0, 1.0)[..., None]  # (B, 3); 0 when x0 = 0
    xm1 = np.sum((root_m1 - root_g) * axis, axis=-1)  # (B,)
    x = _quintic(x0, (x0 - xm1) / dt, t1, times)  # (B, T)
    root = root_g[:, None] + x[..., None] * axis[:, None]  # (B, T, 3)

    # joint rotations
    g_inv = quat_conj(q_g)  # (B, J, 4)
    d0 = quat_mul(q_0, g_inv)  # (B, J, 4)
    d0 = np.where(d0[..., :1] < 0, -d0, d0)
    dm1 = quat_mul(q_m1, g_inv)
    dm1 = np.where(np.sum(dm1 * d0, axis=-1, keepdims=True) < 0, -dm1, dm1)
    s0 = np.sqrt(np.sum(d0[..., 1:] ** 2, axis=-1))  # (B, J)
    raxis = d0[..., 1:] / np.where(s0 > _TINY, s0, 1.0)[..., None]  # (B, J, 3)
    a0 = 2.0 * np.arctan2(s0, d0[..., 0])  # (B, J) in [0, π]
    am1 = 2.0 * np.arctan2(np.sum(dm1[..., 1:] * raxis, axis=-1), dm1[..., 0])  # (B, J)
    ang = _quintic(a0, (a0 - am1) / dt, t1, times)  # (B, J, T)
    ang = np.moveaxis(ang, -1, 1)  # (B, T, J)
    q_off = quat_from_axis_angle(ang[..., None] * raxis[:, None])  # (B, T, J, 4)
    quats = quat_mul(q_off, q_g[:, None])  # (B, T, J, 4)
    return join_pose(root, quats).astype(dtype, copy=False)


def _inertialize_naive(past, target, T, dt=1.0 / 30.0, blend_time=None):
    """Slow loop version of :func:`inertialize` (one scalar curve per batch item and channel), for tests."""
    import math

    past = np.asarray(past, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    B, _, P = past.shape
    J = (P - 3) // 4
    t1_0 = (T + 1) * dt if blend_time is None else blend_time
    out = np.zeros((B, T, P))

    def curve(x0, xm1, t):
        v0 = (x0 - xm1) / dt
        t1 = t1_0
        if v0 > 0:
            v0 = 0.0
        if v0 < 0:
            t1 = min(t1, -5 * x0 / v0)
        if x0 <= _TINY or t1 <= _TINY or t >= t1:
            return 0.0
        a0 = max((-8 * v0 * t1 - 20 * x0) / (t1 * t1), 0.0)
        A = -(a0 * t1 ** 2 + 6 * v0 * t1 + 12 * x0) / (2 * t1 ** 5)
        Bc = (3 * a0 * t1 ** 2 + 16 * v0 * t1 + 30 * x0) / (2 * t1 ** 4)
        C = -(3 * a0 * t1 ** 2 + 12 * v0 * t1 + 20 * x0) / (2 * t1 ** 3)
        return A * t ** 5 + Bc * t ** 4 + C * t ** 3 + a0 / 2 * t ** 2 + v0 * t + x0

    def qmul(a, b):
        w1, x1, y1, z1 = a
        w2, x2, y2, z2 = b
        return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                         w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])

    for b in range(B):
        pm1, p0, g = past[b, 0], past[b, 1], target[b, 0]
        off = p0[:3] - g[:3]
        x0 = float(np.linalg.norm(off))
        ax = off / x0 if x0 > _TINY else np.zeros(3)
        xm1 = float(np.dot(pm1[:3] - g[:3], ax))
        for k in range(T):
            out[b, k, :3] = g[:3] + curve(x0, xm1, (k + 1) * dt) * ax
        for j in range(J):
            sl = slice(3 + 4 * j, 7 + 4 * j)
            qm1, q0, qg = (v[sl] / np.linalg.norm(v[sl]) for v in (pm1, p0, g))
            ginv = qg * np.array([1, -1, -1, -1])
            d0 = qmul(q0, ginv)
            if d0[0] < 0:
                d0 = -d0
            dm1 = qmul(qm1, ginv)
            if np.dot(dm1, d0) < 0:
                dm1 = -dm1
            s0 = float(np.linalg.norm(d0[1:]))
            ax_r = d0[1:] / s0 if s0 > _TINY else np.zeros(3)
            a0 = 2 * math.atan2(s0, d0[0])
            am1 = 2 * math.atan2(float(np.dot(dm1[1:], ax_r)), dm1[0])
            for k in range(T):
                ang = curve(a0, am1, (k + 1) * dt)
                qo = np.concatenate([[math.cos(ang / 2)], math.sin(ang / 2) * ax_r])
                out[b, k, sl] = qmul(qo, qg)
    return out


# ----------------------------------------------------------------------------------------------------------------
# temporal interpolation
# ----------------------------------------------------------------------------------------------------------------

def _interpolate_at(p0, g1, alphas):
    """Lerp/slerp between poses ``p0`` and ``g1`` (B, P) at the fractions ``alphas`` (K,) -> (B, K, P)."""
    r0, q0 = split_pose(p0)  # (B, 3), (B, J, 4)
    r1, q1 = split_pose(g1)
    q0 = _unit_quats(q0, "past")
    q1 = _unit_quats(q1, "target")
    a = alphas[None, :, None]  # (1, K, 1)
    root = (1.0 - a) * r0[:, None] + a * r1[:, None]  # (B, K, 3)
    quats = quat_slerp(q0[:, None], q1[:, None], alphas[None, :, None])  # (B, K, J, 4)
    return join_pose(root, quats)


def interpolate(past, target, T: int) -> np.ndarray:
    """Temporal interpolation from the last past pose to the first target pose (spec/qtg.md §7.2).

    With ``α_k = k / (T + 1)``, ``k = 1 … T`` (so ``α = 0`` would be ``p_0`` and ``α = 1`` would be ``g1``):
    root translation ``(1 − α) r(p_0) + α r(g1)``; each joint quaternion ``slerp(q(p_0), q(g1), α)`` along
    the shortest arc (:func:`refimpl.quat.quat_slerp`; the end quaternion is negated when ``⟨q0, q1⟩ < 0``).

    Parameters
    ----------
    past, target : ndarray (B, 2, P)
        Un-normalised poses; ``past[:, 0]`` and ``target[:, 1]`` are not used.
    T : int

    Returns
    -------
    ndarray (B, T, P)
    """
    past, target = check_context(past, target)
    T = check_length(T)
    alphas = np.arange(1, T + 1, dtype=past.dtype) / past.dtype.type(T + 1)  # (T,)
    return _interpolate_at(past[:, 1], target[:, 0], alphas)


# ----------------------------------------------------------------------------------------------------------------
# the common interface
# ----------------------------------------------------------------------------------------------------------------

def method_registry(qtg: Callable | None = None, dt: float = 1.0 / 30.0,
                    blend_time: float | None = None) -> dict[str, Callable]:
    """The transition methods evaluated side by side, as ``name -> f(past, target, T) -> poses``.

    Parameters
    ----------
    qtg : callable, optional
        The network's method (QTG: :func:`refimpl.recipes.qtg.qtg_method`); left out of the registry when None.
    dt, blend_time : float
        Passed to :func:`inertialize`.

    Returns
    -------
    dict
        Keys in the order of :data:`METHOD_NAMES` (``"qtg"`` only when given). All callables take
        un-normalised ``past, target (B, 2, P)`` and ``T`` and return ``(B, T, P)``.
    """
    methods: dict[str, Callable] = {}
    if qtg is not None:
        methods["qtg"] = qtg
    methods["inertialization"] = lambda past, target, T: inertialize(past, target, T, dt=dt, blend_time=blend_time)
    methods["interpolation"] = interpolate
    return methods
