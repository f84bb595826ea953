"""Differentiable kinematics layers: forward kinematics and the dual-quaternion "current" ↔ "local" maps.

Pure forward/backward pairs (``spec/architecture.md``)::

    positions, cache = forward_kinematics_forward(rotations, root_positions, offsets, parents)
    drotations, droot_positions, doffsets = forward_kinematics_backward(dpositions, cache)

* ``forward_kinematics``        QuaterNet FK: ``q_world_j = q_world_p ⊗ q_j``, ``p_j = p_p + R(q_world_p) o_j``
* ``dq_from_quat_translation``  ``(q_r | ½ (0, t) ⊗ q_r)`` (Andreou et al. Eq. 6, translation on the LEFT)
* ``current_dq_from_local``     ``C_root = L_root``, ``C_j = C_p ⊗ L_j`` (Eq. 11 in dual-quaternion form)
* ``local_dq_from_current``     ``L_root = C_root``, ``L_j = C_p⁻¹ ⊗ C_j`` with ``C⁻¹ = (q_r* | q_d*)`` (Eq. 12)
* ``positions_from_dq``         ``t = vec(2 q_d ⊗ q_r*)`` (Eq. 8)
* ``offsets_from_dq``           ``o_j = vec(2 q_d ⊗ q_r*)`` of ``C_p⁻¹ ⊗ C_j``; root offset 0

Conventions: quaternions ``(w, x, y, z)``, Hamilton product, active rotations; dual quaternions ``(q_r | q_d)``
with ``q_d = ½ (0, t) ⊗ q_r`` (rotate, then translate). ``parents[0] == -1`` is the root and every other
joint's parent precedes it (``0 <= parents[j] < j``), as in QuaterNet and the CMU/H3.6M skeletons. The layers
assume unit (dual) quaternions where the geometry needs them (``R(q)`` is QuaterNet's ``qrot`` formula
``v + 2 (w (u × v) + u × (u × v))``, which equals ``q v q*`` only for unit ``q``; the inverse of a dual
quaternion is its quaternion conjugate only for unit ones) and differentiate the formulas as written, so
the gradients are exact for any input. Loops run over joints grouped by depth; batch/time axes are vectorised.

Specified in ``spec/losses.md`` §3; tested in ``tests/test_nn_kinematics_layers.py`` (also against
``refimpl.skeleton``).

Shape legend: ``...`` leading axes (e.g. B, T), J joints.
"""
from __future__ import annotations

import numpy as np

from refimpl.arrays import float_array
from refimpl.arrays import gradient_array
from refimpl.nn.quat_layers import unbroadcast
from refimpl.quat import quat_conj_kernel, quat_mul_kernel

__all__ = [
    "forward_kinematics_forward", "forward_kinematics_backward",
    "dq_from_quat_translation_forward", "dq_from_quat_translation_backward",
    "current_dq_from_local_forward", "current_dq_from_local_backward",
    "local_dq_from_current_forward", "local_dq_from_current_backward",
    "positions_from_dq_forward", "positions_from_dq_backward",
    "offsets_from_dq_forward", "offsets_from_dq_backward",
]


# --------------------------------------------------------------------------------------------------
# skeleton topology

def check_parents(parents, num_joints: int) -> np.ndarray:
    """Validate ``parents`` (root first, each parent before its child) for ``num_joints`` joints."""
    p = np.asarray(parents)
    if p.ndim != 1 or not (np.issubdtype(p.dtype, np.integer) or p.size == 0):
        raise ValueError(f"parents: expected a 1-D integer sequence, got shape {p.shape} dtype {p.dtype}")
    if p.shape[0] != num_joints:
        raise ValueError(f"parents: expected {num_joints} entries (one per joint), got {p.shape[0]}")
    if num_joints == 0 or p[0] != -1:
        raise ValueError(f"parents: expected parents[0] == -1 (joint 0 is the root), got {p[:1].tolist()}")
    j = np.arange(num_joints)
    bad = np.nonzero((p[1:] < 0) | (p[1:] >= j[1:]))[0] + 1
    if bad.size:
        k = int(bad[0])
        raise ValueError(f"parents: joint {k} has parent {int(p[k])}; expected 0 <= parent < {k} "
                         f"(a single root at index 0, parents before children)")
    return p.astype(np.intp)


def _unique_parent_groups(joints, parents) -> list[tuple[np.ndarray, np.ndarray]]:
    """Split ``joints`` into groups in which no parent repeats (so ``x[..., par, :] += y`` is a valid scatter)."""
    groups: list[tuple[list, list]] = []
    for j in joints:
        p = parents[j]
        for js, ps in groups:
            if p not in ps:
                js.append(j)
                ps.append(p)
                break
        else:
            groups.append(([j], [p]))
    return [(np.array(js, dtype=np.intp), np.array(ps, dtype=np.intp)) for js, ps in groups]


def _depth_schedule(parents: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Non-root joints as ``(joints, their parents)`` groups in depth order, parents unique within a group."""
    depth = np.zeros(len(parents), dtype=np.intp)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    schedule = []
    for d in range(1, int(depth.max(initial=0)) + 1):
        schedule.extend(_unique_parent_groups(np.nonzero(depth == d)[0], parents))
    return schedule


# --------------------------------------------------------------------------------------------------
# rotation of vectors and dual-quaternion products (internal kernels)

def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """QuaterNet ``qrot``: ``v + 2 (w (u × v) + u × (u × v))`` with ``q = (w, u)``; ``= q v q*`` for unit q."""
    w, u = q[..., :1], q[..., 1:]
    uv = _cross(u, v)
    return v + 2.0 * (w * uv + _cross(u, uv))


def _quat_rotate_backward(g: np.ndarray, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of :func:`_quat_rotate` (same shapes, no broadcasting).

    ``dv = g - 2 w (u × g) + 2 u × (u × g)`` (the transposed linear map), ``dw = 2 <g, u × v>``,
    ``du = 2 w (v × g) + 2 ((u·v) g + (u·g) v - 2 (g·v) u)``.
    """
    w, u = q[..., :1], q[..., 1:]
    ug = _cross(u, g)
    dv = g - 2.0 * w * ug + 2.0 * _cross(u, ug)
    dq = np.empty(q.shape, dtype=np.result_type(q, g, v))
    dq[..., :1] = 2.0 * np.sum(g * _cross(u, v), axis=-1, keepdims=True)
    uv_dot = np.sum(u * v, axis=-1, keepdims=True)
    ug_dot = np.sum(u * g, axis=-1, keepdims=True)
    gv_dot = np.sum(g * v, axis=-1, keepdims=True)
    dq[..., 1:] = 2.0 * w * _cross(v, g) + 2.0 * (uv_dot * g + ug_dot * v - 2.0 * gv_dot * u)
    return dq, dv


def _dq_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dual-quaternion product ``(a_r ⊗ b_r | a_r ⊗ b_d + a_d ⊗ b_r)`` (Eq. 1)."""
    ar, ad, br, bd = a[..., :4], a[..., 4:], b[..., :4], b[..., 4:]
    return np.concatenate([quat_mul_kernel(ar, br), quat_mul_kernel(ar, bd) + quat_mul_kernel(ad, br)], axis=-1)


def _dq_mul_backward(g: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of :func:`_dq_mul` (same shapes)."""
    ar, ad, br, bd = a[..., :4], a[..., 4:], b[..., :4], b[..., 4:]
    gr, gd = g[..., :4], g[..., 4:]
    da = np.concatenate([quat_mul_kernel(gr, quat_conj_kernel(br)) + quat_mul_kernel(gd, quat_conj_kernel(bd)),
                         quat_mul_kernel(gd, quat_conj_kernel(br))], axis=-1)
    db = np.concatenate([quat_mul_kernel(quat_conj_kernel(ar), gr) + quat_mul_kernel(quat_conj_kernel(ad), gd),
                         quat_mul_kernel(quat_conj_kernel(ar), gd)], axis=-1)
    return da, db


def _dq_conj(x: np.ndarray) -> np.ndarray:
    """Quaternion conjugate of both parts ``(q_r* | q_d*)``: the inverse of a unit dual quaternion."""
    out = -x
    out[..., 0] = x[..., 0]
    out[..., 4] = x[..., 4]
    return out


def _translation(dq: np.ndarray) -> np.ndarray:
    """``vec(2 q_d ⊗ q_r*)`` (Eq. 8)."""
    return 2.0 * quat_mul_kernel(dq[..., 4:], quat_conj_kernel(dq[..., :4]))[..., 1:]


def _translation_backward(g: np.ndarray, dq: np.ndarray) -> np.ndarray:
    """Gradient of :func:`_translation`: with ``G = (0, g)``, ``dq_d = 2 G ⊗ q_r``, ``dq_r = 2 G* ⊗ q_d``."""
    g4 = np.concatenate([np.zeros(g.shape[:-1] + (1,), dtype=g.dtype), g], axis=-1)
    return np.concatenate([2.0 * quat_mul_kernel(quat_conj_kernel(g4), dq[..., 4:]),
                           2.0 * quat_mul_kernel(g4, dq[..., :4])], axis=-1)


# --------------------------------------------------------------------------------------------------
# forward kinematics

def _check_joint_array(x, name: str, last: int) -> np.ndarray:
    """A per-joint array ``(..., J, last)`` (at least 2 axes), validated."""
    return float_array(x, name, last=last, min_ndim=2)


def forward_kinematics_forward(rotations, root_positions, offsets, parents):
    """QuaterNet forward kinematics (``Skeleton.forward_kinematics``).

    For the root (joint 0): ``q_world_0 = q_0`` and ``p_0 = root_position`` (``offsets[0]`` is ignored, as in
    QuaterNet). For every other joint j with parent p::

        q_world_j = q_world_p ⊗ q_j
        p_j = p_p + R(q_world_p) o_j        (R(q) v = v + 2 (w (u × v) + u × (u × v)))

    A leaf's own rotation therefore never moves any position (its gradient is 0).

    Parameters
    ----------
    rotations : ndarray, shape (..., J, 4)
        Local joint rotations ``(w, x, y, z)``, unit.
    root_positions : ndarray, shape (..., 3)
        Root trajectory; its leading axes equal those of ``rotations``.
    offsets : ndarray, shape (J, 3) or broadcastable to (..., J, 3)
        Bone offsets in the parent's frame.
    parents : sequence of int, length J
        ``parents[0] == -1``, ``0 <= parents[j] < j``.

    Returns
    -------
    positions : ndarray, shape (..., J, 3)
    cache : tuple
    """
    rot = _check_joint_array(rotations, "rotations", 4)
    lead, num_joints = rot.shape[:-2], rot.shape[-2]
    root = float_array(root_positions, "root_positions", last=3)
    if root.shape != lead + (3,):
        raise ValueError(f"root_positions: expected shape {lead + (3,)}, got {root.shape}")
    off = float_array(offsets, "offsets", last=3)
    try:
        ok = off.ndim <= rot.ndim and np.broadcast_shapes(off.shape, lead + (num_joints, 3)) == lead + (num_joints, 3)
    except ValueError:
        ok = False
    if not ok:
        raise ValueError(f"offsets: expected shape ({num_joints}, 3) or broadcastable to "
                         f"{lead + (num_joints, 3)}, got {off.shape}")
    par = check_parents(parents, num_joints)
    dtype = np.result_type(rot, root)
    rot = rot.astype(dtype, copy=False)
    offb = np.broadcast_to(off.astype(dtype, copy=False), lead + (num_joints, 3))
    schedule = _depth_schedule(par)
    positions, qw = _forward_kinematics(rot, root.astype(dtype, copy=False), offb, schedule)
    return positions, (rot, qw, offb, off.shape, schedule)


def _forward_kinematics(rot, root, offb, schedule):
    qw = np.empty_like(rot)  # (..., J, 4) world rotations
    pos = np.empty(rot.shape[:-1] + (3,), dtype=rot.dtype)  # (..., J, 3)
    qw[..., 0, :] = rot[..., 0, :]
    pos[..., 0, :] = root
    for joints, pars in schedule:
        qp = qw[..., pars, :]  # (..., n, 4)
        pos[..., joints, :] = pos[..., pars, :] + _quat_rotate(qp, offb[..., joints, :])
        qw[..., joints, :] = quat_mul_kernel(qp, rot[..., joints, :])
    return pos, qw


def _forward_kinematics_naive(rotations, root_positions, offsets, parents):
    """Slow oracle: one joint at a time, rotations through 3×3 matrices (unit quaternions only)."""
    rot = np.asarray(rotations, dtype=np.float64)
    lead, num_joints = rot.shape[:-2], rot.shape[-2]
    offb = np.broadcast_to(np.asarray(offsets, dtype=np.float64), lead + (num_joints, 3))
    world = [None] * num_joints
    pos = np.zeros(lead + (num_joints, 3))
    for j in range(num_joints):
        w, x, y, z = (rot[..., j, k] for k in range(4))
        local = np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], -2)
        if parents[j] == -1:
            world[j] = local
            pos[..., j, :] = root_positions
        else:
            p = parents[j]
            pos[..., j, :] = pos[..., p, :] + np.einsum("...ab,...b->...a", world[p], offb[..., j, :])
            world[j] = world[p] @ local
    return pos


def forward_kinematics_backward(dpositions, cache):
    """Gradients of :func:`forward_kinematics_forward`, joints in reverse depth order.

    Per joint j with parent p (``g_j`` the accumulated position gradient, ``G_j`` the world-rotation gradient)::

        G_p += G_j ⊗ q_j*  +  ∂(R(q_world_p) o_j)/∂q_world_pᵀ g_j        dq_j = q_world_p* ⊗ G_j
        g_p += g_j                                                      do_j = R(q_world_p)ᵀ g_j

    and at the root ``dq_0 = G_0``, ``droot = g_0``.

    Returns
    -------
    drotations : ndarray, shape (..., J, 4)
    droot_positions : ndarray, shape (..., 3)
    doffsets : ndarray, shape of ``offsets`` (the root row is 0)
    """
    rot, qw, offb, off_shape, schedule = cache
    g = gradient_array(dpositions, rot.shape[:-1] + (3,), "dpositions")
    dpos = np.array(g, dtype=np.result_type(rot, g))  # (..., J, 3), accumulates children
    dqw = np.zeros(rot.shape, dtype=dpos.dtype)  # (..., J, 4)
    drot = np.zeros(rot.shape, dtype=dpos.dtype)
    doff = np.zeros(offb.shape, dtype=dpos.dtype)
    for joints, pars in reversed(schedule):
        qp = qw[..., pars, :]
        gj = dpos[..., joints, :]
        gq = dqw[..., joints, :]
        dqp_rot, doff_j = _quat_rotate_backward(gj, qp, offb[..., joints, :])
        dqp_mul = quat_mul_kernel(gq, quat_conj_kernel(rot[..., joints, :]))
        drot[..., joints, :] = quat_mul_kernel(quat_conj_kernel(qp), gq)
        doff[..., joints, :] = doff_j
        dqw[..., pars, :] += dqp_rot + dqp_mul
        dpos[..., pars, :] += gj
    drot[..., 0, :] = dqw[..., 0, :]
    return drot, dpos[..., 0, :].copy(), unbroadcast(doff, off_shape)


# --------------------------------------------------------------------------------------------------
# dual quaternions from rotation + translation

def dq_from_quat_translation_forward(rotations, translations):
    """Unit dual quaternion of "rotate by q, then translate by t": ``(q | ½ (0, t) ⊗ q)`` (Eq. 6, translation
    quaternion on the LEFT; the paper's Eq. 6 writes q_r by a typo).

    Parameters
    ----------
    rotations : ndarray, shape (..., 4)
    translations : ndarray, shape (..., 3)
        Same leading axes as ``rotations``.

    Returns
    -------
    dq : ndarray, shape (..., 8)
    cache : tuple
    """
    q = float_array(rotations, "rotations", last=4)
    t = float_array(translations, "translations", last=3)
    if t.shape[:-1] != q.shape[:-1]:
        raise ValueError(f"translations: expected shape {q.shape[:-1] + (3,)}, got {t.shape}")
    dtype = np.result_type(q, t)
    q, t = q.astype(dtype, copy=False), t.astype(dtype, copy=False)
    t4 = np.concatenate([np.zeros(t.shape[:-1] + (1,), dtype=dtype), t], axis=-1)
    return np.concatenate([q, 0.5 * quat_mul_kernel(t4, q)], axis=-1), (q, t4)


def dq_from_quat_translation_backward(ddq, cache):
    """Gradients of :func:`dq_from_quat_translation_forward`.

    ``dq = g_r + ½ (0, t)* ⊗ g_d``, ``dt = vec(½ g_d ⊗ q*)``.

    Returns
    -------
    drotations : ndarray, shape (..., 4)
    dtranslations : ndarray, shape (..., 3)
    """
    q, t4 = cache
    g = gradient_array(ddq, q.shape[:-1] + (8,), "ddq")
    gr, gd = g[..., :4], g[..., 4:]
    dq = gr + 0.5 * quat_mul_kernel(quat_conj_kernel(t4), gd)
    dt = 0.5 * quat_mul_kernel(gd, quat_conj_kernel(q))[..., 1:]
    return dq, dt


# --------------------------------------------------------------------------------------------------
# current <-> local dual quaternions

def current_dq_from_local_forward(local_dqs, parents):
    """Current ("relative to the root") dual quaternions from local ones (Eq. 9-11 in dual-quaternion form).

    ``C_0 = L_0``; ``C_j = C_p ⊗ L_j`` for each joint j with parent p, in depth order. With
    ``L_j = (q_j | ½ (0, o_j) ⊗ q_j)`` (:func:`dq_from_quat_translation_forward`) and ``L_0 = (q_0 | 0)`` this
    is ``M_curr,j = M_curr,p · M_loc,j`` of the paper. No normalisation (unit in → unit out).

    Parameters
    ----------
    local_dqs : ndarray, shape (..., J, 8)
    parents : sequence of int, length J

    Returns
    -------
    current_dqs : ndarray, shape (..., J, 8)
    cache : tuple
    """
    loc = _check_joint_array(local_dqs, "local_dqs", 8)
    par = check_parents(parents, loc.shape[-2])
    schedule = _depth_schedule(par)
    cur = np.empty_like(loc)
    cur[..., 0, :] = loc[..., 0, :]
    for joints, pars in schedule:
        cur[..., joints, :] = _dq_mul(cur[..., pars, :], loc[..., joints, :])
    return cur, (loc, cur, schedule)


def _current_dq_from_local_naive(local_dqs, parents):
    """Slow oracle: one joint at a time in index order."""
    loc = np.asarray(local_dqs, dtype=np.float64)
    cur = np.empty_like(loc)
    for j, p in enumerate(parents):
        cur[..., j, :] = loc[..., j, :] if p == -1 else _dq_mul(cur[..., p, :], loc[..., j, :])
    return cur


def current_dq_from_local_backward(dcurrent, cache):
    """Gradient of :func:`current_dq_from_local_forward` (reverse depth order: ``G_p += ∂(C_p ⊗ L_j)/∂C_pᵀ G_j``).

    Returns
    -------
    dlocal : ndarray, shape (..., J, 8)
    """
    loc, cur, schedule = cache
    g = gradient_array(dcurrent, loc.shape, "dcurrent")
    dcur = np.array(g, dtype=np.result_type(loc, g))
    dloc = np.zeros_like(dcur)
    for joints, pars in reversed(schedule):
        da, db = _dq_mul_backward(dcur[..., joints, :], cur[..., pars, :], loc[..., joints, :])
        dloc[..., joints, :] = db
        dcur[..., pars, :] += da
    dloc[..., 0, :] = dcur[..., 0, :]
    return dloc


def local_dq_from_current_forward(current_dqs, parents):
    """Local dual quaternions from current ones (Eq. 12): ``L_0 = C_0``, ``L_j = C_p⁻¹ ⊗ C_j``.

    ``C⁻¹ = (q_r* | q_d*)`` (quaternion conjugate of both parts), the inverse of a UNIT dual quaternion; for
    non-unit input compose with :func:`refimpl.nn.quat_layers.dq_normalize_forward` first. Vectorised over all
    joints at once (no recursion needed).

    Parameters
    ----------
    current_dqs : ndarray, shape (..., J, 8)
    parents : sequence of int, length J

    Returns
    -------
    local_dqs : ndarray, shape (..., J, 8)
    cache : tuple
    """
    cur = _check_joint_array(current_dqs, "current_dqs", 8)
    par = check_parents(parents, cur.shape[-2])
    loc = np.empty_like(cur)
    loc[..., 0, :] = cur[..., 0, :]
    inv_par = _dq_conj(cur[..., par[1:], :])  # (..., J-1, 8)
    loc[..., 1:, :] = _dq_mul(inv_par, cur[..., 1:, :])
    groups = _unique_parent_groups(np.arange(1, len(par)), par)
    return loc, (cur, inv_par, par, groups)


def _local_dq_from_current_naive(current_dqs, parents):
    """Slow oracle: one joint at a time."""
    cur = np.asarray(current_dqs, dtype=np.float64)
    loc = np.empty_like(cur)
    for j, p in enumerate(parents):
        loc[..., j, :] = cur[..., j, :] if p == -1 else _dq_mul(_dq_conj(cur[..., p, :]), cur[..., j, :])
    return loc


def local_dq_from_current_backward(dlocal, cache):
    """Gradient of :func:`local_dq_from_current_forward` (each parent collects from all its children).

    Returns
    -------
    dcurrent : ndarray, shape (..., J, 8)
    """
    cur, inv_par, par, groups = cache
    g = gradient_array(dlocal, cur.shape, "dlocal")
    dcur = np.zeros(cur.shape, dtype=np.result_type(cur, g))
    dinv, dchild = _dq_mul_backward(g[..., 1:, :], inv_par, cur[..., 1:, :])  # (..., J-1, 8) each
    dcur[..., 1:, :] = dchild
    dcur[..., 0, :] += g[..., 0, :]
    dpar = _dq_conj(dinv)  # the conjugation is linear and its own transpose
    for joints, pars in groups:
        dcur[..., pars, :] += dpar[..., joints - 1, :]
    return dcur


# --------------------------------------------------------------------------------------------------
# positions and offsets from dual quaternions

def positions_from_dq_forward(dqs):
    """Translations encoded in unit dual quaternions, ``t = vec(2 q_d ⊗ q_r*)`` (Eq. 8).

    Applied to current dual quaternions this gives joint positions relative to the root (L_pos). No
    normalisation inside (the reference code normalises first; use
    :func:`refimpl.nn.quat_layers.dq_normalize_forward`).

    Parameters
    ----------
    dqs : ndarray, shape (..., 8)

    Returns
    -------
    positions : ndarray, shape (..., 3)
    cache : ndarray
    """
    dq = float_array(dqs, "dqs", last=8)
    return _translation(dq), dq


def positions_from_dq_backward(dpositions, cache):
    """Gradient of :func:`positions_from_dq_forward`: with ``G = (0, g)``, ``dq_r = 2 G* ⊗ q_d``,
    ``dq_d = 2 G ⊗ q_r``.

    Returns
    -------
    ddqs : ndarray, shape (..., 8)
    """
    dq = cache
    g = gradient_array(dpositions, dq.shape[:-1] + (3,), "dpositions")
    return _translation_backward(g, dq)


def offsets_from_dq_forward(current_dqs, parents):
    """Bone offsets encoded in current dual quaternions (L_offset; reference ``get_offsets``).

    ``o_j = vec(2 l_d ⊗ l_r*)`` with ``(l_r | l_d) = C_p⁻¹ ⊗ C_j`` (:func:`local_dq_from_current_forward`),
    i.e. the offset of joint j in its parent's frame; the root's offset is 0.

    Parameters
    ----------
    current_dqs : ndarray, shape (..., J, 8)
        Unit current dual quaternions.
    parents : sequence of int, length J

    Returns
    -------
    offsets : ndarray, shape (..., J, 3)
    cache : tuple
    """
    loc, lcache = local_dq_from_current_forward(current_dqs, parents)
    off = _translation(loc)
    off[..., 0, :] = 0.0
    return off, (loc, lcache)


def offsets_from_dq_backward(doffsets, cache):
    """Gradient of :func:`offsets_from_dq_forward` (the root row of ``doffsets`` is ignored).

    Returns
    -------
    dcurrent : ndarray, shape (..., J, 8)
    """
    loc, lcache = cache
    g = np.array(gradient_array(doffsets, loc.shape[:-1] + (3,), "doffsets"))
    g[..., 0, :] = 0.0
    return local_dq_from_current_backward(_translation_backward(g, loc), lcache)


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# check_parents.
