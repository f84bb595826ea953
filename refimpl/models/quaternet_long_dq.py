"""The long-term QuaterNet over current dual quaternions (Andreou et al. §6.2, §7.2, Appendix B; spec/locomotion.md
§11): ``refimpl train --model quaternet-long --set output=dual_quaternion``.

* :func:`dq_inputs` — windows ``[q (4J) | offset, height | controls]`` → ``[C (8J) | offset, height | controls]``:
  each joint's current (root-relative) unit dual quaternion (Eq. 9-11, :func:`refimpl.current_dq.current_dq_from_local`,
  from the window's local quaternions after the augmentation's rotation and the skeleton's offsets), made
  antipodally continuous over the window's frames (:func:`refimpl.dualquat.dq_fix`, §5.1);
* :func:`loss_and_grads` — ``L_pos + L_offset + L_quat + 0.01 · L_reg`` of the raw head output through
  :func:`refimpl.dq_output_fast.dq_output_loss_forward` (weights :data:`refimpl.losses.WEIGHTS_QUATERNET_DQ`; positions
  read from the DQs with Eq. 8, no FK), plus the translations' ``mean |o − õ| + mean |h − h̃|`` (the height is
  inside the FK positions of the quaternion model; the DQs are root-relative, so it is its own term here);
* :func:`rollout` — free running: unit current DQs and translations; :func:`decode` — local rotations (Eq. 12)
  and the positions both ways: Eq. 8 on the DQs and FK of the decoded rotations, each with root ``(0, h, 0)``.

Shape legend: B batch, P prefix, T target frames, L = P + T window frames, J joints, R = 8J rotation block,
F = 8J + 8 input features, G = 8J + 2 outputs.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.dq_output_fast import dq_output_loss_backward, dq_output_loss_forward
from refimpl.dualquat import dq_fix, translation_from_dq
from refimpl.losses import WEIGHTS_QUATERNET_DQ
from refimpl.models import quaternet, quaternet_sequence
from refimpl.quat import quat_normalize
from refimpl.current_dq import current_dq_from_local, local_from_current_dq

__all__ = ["dq_inputs", "loss_and_grads", "rollout", "decode", "bone_lengths"]


def dq_inputs(inputs, skeleton, scale: float = 1.0) -> np.ndarray:
    """Windows ``[q (4J) | offset, height | controls]`` (B, L, 4J + 8) → ``[C (8J) | offset, height | controls]``
    (B, L, 8J + 8), ``C_j`` the current dual quaternion ``(q_r | q_d)`` of joint j (root at the origin, root
    DQ = ``(q_0 | 0)``) of the skeleton with its offsets × ``scale`` (the DQs' translation unit: 1 = the data's
    units; ``0.056444`` = metres for QuaterNet units), antipodally continuous along L (all 8 numbers flip with
    the real part)."""
    x = np.asarray(inputs)
    B, Lw, F = x.shape
    J = (F - 8) // 4
    if F != 4 * J + 8 or J != skeleton.num_joints:
        raise ValueError(f"inputs: expected (B, L, 4J + 8) with J = {skeleton.num_joints}, got {x.shape}")
    q = x[..., :4 * J].reshape(B, Lw, J, 4).astype(np.float64)
    off = np.asarray(skeleton.offsets, np.float64) * float(scale)
    cur = current_dq_from_local(q, off, skeleton.parents)                                     # (B, L, J, 8)
    cur = np.moveaxis(dq_fix(np.moveaxis(cur, 1, 0)), 0, 1)                                   # continuous in L
    return np.concatenate([cur.reshape(B, Lw, 8 * J), x[..., 4 * J:]], axis=-1).astype(x.dtype)


def loss_and_grads(params: Mapping[str, np.ndarray], batch: Mapping, net: quaternet.QuaterNetConfig, parents,
                   weights: Mapping[str, float] = WEIGHTS_QUATERNET_DQ, scale: float = 1.0):
    """The long-term dual-quaternion loss and its gradient on one batch::

        loss = Σ_k w_k L_k(Δ, C̃)  (k ∈ pos, offset, quat, reg; Eq. 13 inside, L_reg on the raw Δ)
               + mean_{B,T} |o − õ| + mean_{B,T} |h − h̃|

    ``Δ`` is the head's raw output (``pre``, before Eq. 13); the model's own Eq. 13 (the unit DQs fed back in
    free-running steps) is the same function with the same ε, so the loss's gradient enters as ``dpre`` and the
    fed-back frames' cotangents through the model's head (full BPTT).

    Parameters
    ----------
    batch : dict with ``inputs (B, P + T, 8J + 8)`` (:func:`dq_inputs`; the target DQs are ``inputs[:, P:, :8J]``),
        ``target_translations (B, T, 2)``, ``mask (T − 1,)`` bool, ``prefix`` (P)
    net : QuaterNetConfig with ``representation="dual_quaternion"``, absolute mode
    parents : (J,)
    weights : loss name → weight (:data:`refimpl.dq_output.DQ_TERM_NAMES`)
    scale : the DQs' translation unit (:func:`dq_inputs`); L_pos and L_offset are divided by it (Euclidean
        distances are homogeneous), so the loss is measured in the data's units whatever the DQs' unit

    Returns
    -------
    loss : float; grads : dict; parts : dict (the unweighted DQ losses and ``"translations"``)
    """
    if net.representation != "dual_quaternion" or net.velocity:
        raise ValueError(f"net: expected an absolute-mode dual-quaternion network, got {net}")
    x, P = batch["inputs"], int(batch["prefix"])
    B, L, _ = x.shape
    T, J, R = L - P, net.num_joints, net.rotation_size
    ttr = batch["target_translations"]
    y, pre, cache = quaternet_sequence.forward(params, x[:, :P], x[:, P:], batch["mask"], net)
    target = np.asarray(x[:, P:, :R], np.float64).reshape(B, T, J, 8)                      # (B, T, J, 8)
    w = {k: (v / float(scale) if k in ("pos", "offset") else v) for k, v in weights.items()}
    value, parts, dc = dq_output_loss_forward(pre.reshape(B, T, J, 8), target, parents, w, net.eps)
    dpre = dq_output_loss_backward(1.0, dc).reshape(B, T, R)
    d = np.asarray(y[..., R:], np.float64) - ttr                                             # (B, T, 2)
    tr_value = float(np.abs(d).mean(axis=(0, 1)).sum())
    dy = np.zeros(y.shape, dtype=np.float64)
    dy[..., R:] = np.sign(d) / (B * T)
    grads = quaternet_sequence.backward(dy.astype(y.dtype, copy=False), dpre.astype(y.dtype, copy=False), cache)
    parts = dict(parts, translations=tr_value)
    return value + tr_value, grads, parts


def rollout(params: Mapping[str, np.ndarray], net: quaternet.QuaterNetConfig, inputs, prefix: int, skeleton,
            scale: float = 1.0):
    """Free-running prediction of frames ``P … P + T − 1`` from the windows ``inputs`` (B, P + T, 4J + 8) (converted
    by :func:`dq_inputs`), with the ground-truth controls.

    Returns
    -------
    dq : (B, T, J, 8) unit current dual quaternions; translations : (B, T, 2)
    """
    dtype = np.asarray(params["h0"]).dtype
    x = dq_inputs(inputs, skeleton, scale).astype(dtype)
    B, L, _ = x.shape
    P, G, R = int(prefix), net.output_size, net.rotation_size
    y = quaternet.predict(params, x[:, :P], L - P, net, controls=np.ascontiguousarray(x[:, P:L - 1, G:]))
    return np.asarray(y[..., :R], np.float64).reshape(B, L - P, net.num_joints, 8), np.asarray(y[..., R:])


def decode(dq, translations, skeleton, scale: float = 1.0) -> dict:
    """Local rotations and the two position readings of predicted current DQs (..., J, 8) whose translations are
    in units of ``scale`` (:func:`dq_inputs`; the positions returned are in the data's units).

    Returns
    -------
    dict with ``rotations (..., J, 4)`` (Eq. 12, normalised; the BVH's), ``dq_positions (..., J, 3)`` (Eq. 8 +
    ``(0, h, 0)``: what the network's losses saw), ``fk_positions (..., J, 3)`` (FK of the rotations with the
    skeleton's offsets, root ``(0, h, 0)``)."""
    dq = np.asarray(dq, np.float64)
    tr = np.asarray(translations, np.float64)
    rot = quat_normalize(local_from_current_dq(dq, skeleton.parents)[0])
    root = np.zeros(dq.shape[:-2] + (3,))
    root[..., 1] = tr[..., 1]
    return {"rotations": rot, "dq_positions": translation_from_dq(dq) / float(scale) + root[..., None, :],
            "fk_positions": skeleton.forward_kinematics(rot, root)}


def bone_lengths(positions, parents) -> np.ndarray:
    """``‖p_j − p_parent(j)‖`` for j ≥ 1: (..., J − 1)."""
    p = np.asarray(positions, np.float64)
    par = np.asarray(parents)
    return np.linalg.norm(p[..., 1:, :] - p[..., par[1:], :], axis=-1)
