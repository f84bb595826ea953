"""Dual-quaternion frames and loss of the short-term prediction task (Andreou et al. §6.2, §7.2, Table 2;
spec/quaternet.md §9).

QuaterNet with dual quaternions (``QuaterNetConfig(representation="dual_quaternion")``) reads and predicts each
joint's *current* (root-relative) unit dual quaternion ``(q_r | q_d)``; the task's data and its error are local
quaternions. This module is the bridge, in both directions::

    local rotations (T, J, 4) + skeleton offsets ──Eq. 9-11, dq_fix over time──► current DQs (T, J, 8)   (inputs)

    network output y = unit current DQs (..., J, 8) ──Eq. 12──► local rotations (..., J, 4) ─► L_rot  (loss)
    raw head output pre = ΔD (..., J, 8) ───────────────────────────────────────────────────► L_reg  (Eq. 16)

    total = L_rot + reg_weight · L_reg           (Appendix B, QuaterNet: rotational loss × 1, L_reg × 0.01)

``L_rot`` is the quaternion twin's loss on the decoded local rotations: QuaterNet's wrapped-Euler L1
(``kind="euler"``, :func:`refimpl.losses.euler_l1_loss_forward`, the paper's "local rotational loss" of the
short-term task whose errors are in Euler space) or ``mean |1 − p·q|`` (``kind="quat"``,
:func:`refimpl.losses.quat_loss_forward`). Only the real parts of the current DQs reach ``L_rot``: the local
rotation is the real part of ``C_p⁻¹ ⊗ C_j`` (:func:`refimpl.nn.kinematics_layers.local_dq_from_current_forward`),
which for unit DQs is ``q_p* ⊗ q_j``. The dual parts are trained through ``L_reg`` and through BPTT (a fed-back
prediction is the next step's input).

Functions: :func:`dq_frames_from_rotations` (inputs), :func:`rotations_from_dq_frames` (inference decode),
:func:`local_rotations_from_dq_forward` / ``_backward`` (the differentiable decode, with its loop oracle
``_local_rotations_from_dq_backward_naive``), :func:`dq_rotation_loss_forward` / ``_backward`` (the training
loss).

Shape legend: ``...`` leading axes (B, T), T frames, J joints.
"""
from __future__ import annotations

import numpy as np

from refimpl.dualquat import dq_fix
from refimpl.losses import (dq_reg_loss_backward, dq_reg_loss_forward, euler_l1_loss_backward,
                            euler_l1_loss_forward, quat_loss_backward, quat_loss_forward)
from refimpl.nn.kinematics_layers import local_dq_from_current_backward, local_dq_from_current_forward
from refimpl.quat import quat_conj, quat_mul
from refimpl.skeleton import Skeleton
from refimpl.current_dq import current_dq_from_local, local_from_current_dq

__all__ = ["ROTATION_LOSSES", "dq_frames_from_rotations", "rotations_from_dq_frames",
           "local_rotations_from_dq_forward", "local_rotations_from_dq_backward", "dq_rotation_loss_forward",
           "dq_rotation_loss_backward"]

#: ``L_rot`` kinds: wrapped-Euler L1 (short-term default) or ``mean |1 − p·q|`` (the teacher-forced variant).
ROTATION_LOSSES = ("euler", "quat")


def dq_frames_from_rotations(rotations, skeleton: Skeleton, time_axis: int = -3) -> np.ndarray:
    """Current dual quaternions of local rotations, antipodally continuous over time.

    ``C_0 = (q_0 | 0)``, ``C_j = C_p ⊗ (q_j | ½ (0, o_j) ⊗ q_j)`` (Eq. 9-11, :func:`refimpl.skeleton.
    current_dq_from_local` with the skeleton's offsets; the root translation is not part of the frame), then
    :func:`refimpl.dualquat.dq_fix` along the time axis (every joint's real part has a non-negative dot
    product with the previous frame's; spec/acrnn.md §2).

    Parameters
    ----------
    rotations : array_like, shape (..., T, J, 4)
        Local unit quaternions ``(w, x, y, z)``.
    skeleton : Skeleton
        Its offsets (the data's units) and parents.
    time_axis : int
        The T axis (default −3).

    Returns
    -------
    ndarray, shape (..., T, J, 8), float64
    """
    if not isinstance(skeleton, Skeleton):
        raise ValueError(f"skeleton: expected a Skeleton, got {type(skeleton).__name__}")
    rot = np.asarray(rotations, dtype=np.float64)
    J = skeleton.num_joints
    if rot.ndim < 3 or rot.shape[-2:] != (J, 4):
        raise ValueError(f"rotations: expected shape (..., T, {J}, 4) for the {J}-joint skeleton, got {rot.shape}")
    dq = current_dq_from_local(rot, skeleton.offsets.astype(np.float64), skeleton.parents)  # (..., T, J, 8)
    moved = np.moveaxis(dq, time_axis, 0)                                                   # (T, ..., J, 8)
    return np.ascontiguousarray(np.moveaxis(dq_fix(moved), 0, time_axis))


def rotations_from_dq_frames(dqs, parents) -> np.ndarray:
    """Local rotations of (unit) current dual quaternions (Eq. 12; :func:`refimpl.current_dq.local_from_current_dq`),
    each made unit: ``(..., J, 8) -> (..., J, 4)``. The offsets the DQs imply are discarded (the task scores
    rotations)."""
    rot, _ = local_from_current_dq(dqs, parents)
    return rot / np.linalg.norm(rot, axis=-1, keepdims=True)


def local_rotations_from_dq_forward(current_dqs, parents):
    """The differentiable decode: local rotations ``l_j = Re(C_p⁻¹ ⊗ C_j)`` (``l_0 = Re C_0``; Eq. 12).

    For unit DQs this is ``q_p* ⊗ q_j`` (unit); no normalisation inside (the network's output is unit already).

    Parameters
    ----------
    current_dqs : ndarray, shape (..., J, 8)
    parents : sequence of int, length J

    Returns
    -------
    local : ndarray, shape (..., J, 4)
    cache : tuple
    """
    loc, cache = local_dq_from_current_forward(current_dqs, parents)  # (..., J, 8)
    return loc[..., :4].copy(), (cache, loc.shape)


def local_rotations_from_dq_backward(dlocal, cache):
    """Gradient of :func:`local_rotations_from_dq_forward`: ``(..., J, 4) -> (..., J, 8)`` (only the real parts
    of the current DQs receive gradient)."""
    kcache, shape = cache
    g = np.asarray(dlocal)
    if g.shape != shape[:-1] + (4,):
        raise ValueError(f"dlocal: expected shape {shape[:-1] + (4,)}, got {g.shape}")
    full = np.zeros(shape, dtype=np.result_type(g.dtype, np.float32))
    full[..., :4] = g
    return local_dq_from_current_backward(full, kcache)


def _left_matrix(a: np.ndarray) -> np.ndarray:
    """``L(a)`` with ``a ⊗ b = L(a) b`` (4 × 4)."""
    w, x, y, z = a
    return np.array([[w, -x, -y, -z], [x, w, -z, y], [y, z, w, -x], [z, -y, x, w]])


def _right_matrix(b: np.ndarray) -> np.ndarray:
    """``R(b)`` with ``a ⊗ b = R(b) a`` (4 × 4)."""
    w, x, y, z = b
    return np.array([[w, -x, -y, -z], [x, w, z, -y], [y, -z, w, x], [z, y, -x, w]])


_CONJ = np.diag([1.0, -1.0, -1.0, -1.0])


def _local_rotations_from_dq_naive(current_dqs, parents) -> np.ndarray:
    """Slow oracle of :func:`local_rotations_from_dq_forward`: one joint and one leading index at a time with
    :func:`refimpl.quat.quat_mul`."""
    cur = np.asarray(current_dqs, dtype=np.float64)
    lead = cur.shape[:-2]
    out = np.empty(lead + (cur.shape[-2], 4))
    for idx in np.ndindex(*lead):
        for j, p in enumerate(parents):
            q = cur[idx + (j, slice(0, 4))]
            out[idx + (j,)] = q if p == -1 else quat_mul(quat_conj(cur[idx + (p, slice(0, 4))]), q)
    return out


def _local_rotations_from_dq_backward_naive(dlocal, current_dqs, parents) -> np.ndarray:
    """Slow oracle of :func:`local_rotations_from_dq_backward` with explicit 4 × 4 Jacobians per joint:
    ``∂(q_p* ⊗ q_j)/∂q_j = L(q_p*)``, ``∂/∂q_p = R(q_j) · diag(1, −1, −1, −1)``."""
    cur = np.asarray(current_dqs, dtype=np.float64)
    g = np.asarray(dlocal, dtype=np.float64)
    out = np.zeros_like(cur)
    for idx in np.ndindex(*cur.shape[:-2]):
        for j, p in enumerate(parents):
            gj = g[idx + (j,)]
            if p == -1:
                out[idx + (j, slice(0, 4))] += gj
                continue
            qp, qj = cur[idx + (p, slice(0, 4))], cur[idx + (j, slice(0, 4))]
            out[idx + (j, slice(0, 4))] += _left_matrix(quat_conj(qp)).T @ gj
            out[idx + (p, slice(0, 4))] += (_right_matrix(qj) @ _CONJ).T @ gj
    return out


def dq_rotation_loss_forward(pred, raw, target, parents, *, kind: str = "euler", reg_weight: float = 0.01):
    """Short-term loss of QuaterNet with dual quaternions: ``L_rot(decode(pred), target) + w · L_reg(raw)``.

    Parameters
    ----------
    pred : ndarray, shape (..., J, 8)
        The network's unit current dual quaternions (after Eq. 13 / the DQ velocity product).
    raw : ndarray, shape (..., J, 8)
        The raw head output ``ΔD`` (``pre``), on which L_reg (Eq. 16) is taken.
    target : ndarray, shape (..., J, 4)
        Ground-truth local unit quaternions.
    parents : sequence of int, length J
    kind : str
        ``"euler"`` (wrapped-Euler L1, zyx, every joint) or ``"quat"`` (``mean |1 − p·q|``).
    reg_weight : float
        Weight of L_reg (0.01, Appendix B).

    Returns
    -------
    total : float
    parts : dict
        ``{"rot": L_rot, "reg": L_reg}`` (unweighted).
    cache : tuple
    """
    if kind not in ROTATION_LOSSES:
        raise ValueError(f"kind: expected one of {ROTATION_LOSSES}, got {kind!r}")
    if not (np.isfinite(reg_weight) and reg_weight >= 0):
        raise ValueError(f"reg_weight: expected a finite value >= 0, got {reg_weight!r}")
    pred, raw, target = np.asarray(pred), np.asarray(raw), np.asarray(target)
    if pred.ndim < 2 or pred.shape[-1] != 8 or raw.shape != pred.shape or target.shape != pred.shape[:-1] + (4,):
        raise ValueError(f"pred, raw, target: expected shapes (..., J, 8), (..., J, 8), (..., J, 4), got "
                         f"{pred.shape}, {raw.shape}, {target.shape}")
    local, dcache = local_rotations_from_dq_forward(pred, parents)  # (..., J, 4)
    fwd = euler_l1_loss_forward if kind == "euler" else quat_loss_forward
    rot, rcache = fwd(local, target)
    reg, gcache = dq_reg_loss_forward(raw)
    total = float(rot) + float(reg_weight) * float(reg)
    return total, {"rot": float(rot), "reg": float(reg)}, (kind, float(reg_weight), dcache, rcache, gcache,
                                                           pred.dtype)


def dq_rotation_loss_backward(dtotal, cache):
    """Gradients of :func:`dq_rotation_loss_forward`: ``(dpred (..., J, 8), draw (..., J, 8))`` in the
    predictions' dtype."""
    kind, w, dcache, rcache, gcache, dtype = cache
    d = float(dtotal)
    dlocal = (euler_l1_loss_backward if kind == "euler" else quat_loss_backward)(d, rcache)
    dpred = local_rotations_from_dq_backward(dlocal, dcache)
    draw = dq_reg_loss_backward(d * w, gcache)
    return dpred.astype(dtype, copy=False), draw.astype(dtype, copy=False)
