"""The fused kernel of the dual-quaternion output path (spec/acrnn.md §3): the contract of
:func:`refimpl.dq_output.dq_output_loss_forward` / :func:`~refimpl.dq_output.dq_output_loss_backward`, computed in
one pass on component-major arrays. Training runs this path (acRNN's loss, the long-term QuaterNet with dual
quaternions); it measured 7-8x faster than the readable composition on acRNN's batches (benchmarks/README.md,
``benchmarks/bench_dq_output.py``), and ``tests/test_dq_output_fast.py`` holds it equal to that composition in
values and gradients up to rounding.

The whole path, forward and backward, runs on component-major arrays ``(C, J, M)`` (``M`` = the product of the
leading axes; every component of every joint one contiguous row), shares the local dual quaternions between
L_offset and the local L_quat, and gathers parents in one indexing per side. Outside the ordinary range (huge
outputs whose fourth powers could overflow, real parts under the ``eps`` clamp) it falls back to the composition.

Shape legend: ``...`` leading axes (B, T), J joints, M = prod(...), C components (8 DQ, 4 quaternion, 3 vector).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl import dq_output
from refimpl.dq_output import DQ_TERMS, check_inputs, check_weights

__all__ = ["dq_output_loss_forward", "dq_output_loss_backward"]


def dq_output_loss_forward(raw, target, parents, weights: Mapping[str, float] = DQ_TERMS, eps: float = 1e-12):
    """:func:`refimpl.dq_output.dq_output_loss_forward` (same arguments, checks and results up to rounding) on the
    fused kernel. Returns ``(total, parts, cache)``; the cache is ``("fused", gradient at dtotal = 1)`` or, outside
    the ordinary range, ``("composed", the composition's cache)``."""
    raw, target, w = np.asarray(raw), np.asarray(target), check_weights(weights)
    x, t, par = check_inputs(raw, target, parents)
    if x.size and eps > 0 and np.isfinite(eps):
        out = _fused_forward(x, t, par, w, float(eps))
        if out is not None:
            return out
    total, parts, cache = dq_output.dq_output_loss_forward(raw, target, parents, w, eps)
    return total, parts, ("composed", cache)


def dq_output_loss_backward(dtotal, cache):
    """Gradient of :func:`dq_output_loss_forward` with respect to ``raw`` ``(..., J, 8)``."""
    kind, inner = cache
    return _fused_backward(dtotal, inner) if kind == "fused" else dq_output.dq_output_loss_backward(dtotal, inner)


# --------------------------------------------------------------------------------------------------
# the fused kernel: component-major arrays (C, J, M), every component a contiguous (J, M) slab
#
# Strided (..., J, 8) views make every elementwise product of the composed path walk memory with a
# stride of 8 numbers and allocate a temporary per term; on (32, 100, 43, 8) batches that, not the
# arithmetic, was the cost. Here the output and the target are transposed once, every Hamilton product
# is 16 products of contiguous rows, and the local dual quaternions (Eq. 12) serve L_offset and the
# local L_quat alike.

def _soa(x: np.ndarray) -> np.ndarray:
    """``(..., J, C)`` → ``(C, J, M)`` contiguous (one transposing copy)."""
    J, C = x.shape[-2], x.shape[-1]
    return np.ascontiguousarray(x.reshape(-1, J, C).transpose(2, 1, 0))


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``Σ_c a[c] b[c]`` over the leading (component) axis."""
    out = a[0] * b[0]
    for c in range(1, a.shape[0]):
        out += a[c] * b[c]
    return out


def _conj(q: np.ndarray) -> np.ndarray:
    """``(w, -x, -y, -z)`` of component-major quaternions ``(4, ...)``."""
    out = -q
    out[0] = q[0]
    return out


def _qmul(a: np.ndarray, b: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` of component-major quaternions ``(4, ...)`` (same formula as
    :func:`refimpl.quat.quat_mul`)."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    if out is None:
        out = np.empty(np.broadcast_shapes(a.shape, b.shape), dtype=np.result_type(a, b))
    out[0] = aw * bw - ax * bx - ay * by - az * bz
    out[1] = aw * bx + ax * bw + ay * bz - az * by
    out[2] = aw * by - ax * bz + ay * bw + az * bx
    out[3] = aw * bz + ax * by - ay * bx + az * bw
    return out


def _pure_mul(g: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``(0, g) ⊗ q`` for vectors ``g (3, ...)`` and quaternions ``q (4, ...)``."""
    gx, gy, gz = g
    qw, qx, qy, qz = q
    out = np.empty((4,) + np.broadcast_shapes(g.shape[1:], q.shape[1:]), dtype=np.result_type(g, q))
    out[0] = -(gx * qx + gy * qy + gz * qz)
    out[1] = gx * qw + gy * qz - gz * qy
    out[2] = -gx * qz + gy * qw + gz * qx
    out[3] = gx * qy - gy * qx + gz * qw
    return out


def _translation(r: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Eq. 8, ``vec(2 d ⊗ r*)`` ``(3, ...)`` (only the vector part is formed)."""
    rw, rx, ry, rz = r
    dw, dx, dy, dz = d
    out = np.empty((3,) + r.shape[1:], dtype=np.result_type(r, d))
    out[0] = dx * rw - dw * rx - dy * rz + dz * ry
    out[1] = dy * rw - dw * ry + dx * rz - dz * rx
    out[2] = dz * rw - dw * rz - dx * ry + dy * rx
    out *= 2
    return out


def _translation_backward(g: np.ndarray, r: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients of :func:`_translation`: ``dr = 2 G* ⊗ d = -2 G ⊗ d``, ``dd = 2 G ⊗ r`` with ``G = (0, g)``."""
    dr = _pure_mul(g, d)
    dr *= -2
    dd = _pure_mul(g, r)
    dd *= 2
    return dr, dd


def _distance(p: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(|p − t|, (p − t)/|p − t|)`` per point of ``(3, ...)`` arrays, scaled by the largest component (no
    underflow of the squares); the direction of a zero difference is 0 (the subgradient)."""
    diff = p - t  # (3, ...)
    s = np.maximum(np.maximum(np.abs(diff[0]), np.abs(diff[1])), np.abs(diff[2]))
    nz = s > 0
    safe = np.where(nz, s, 1)
    u = diff / safe
    r = np.sqrt(_dot(u, u))
    direction = u / np.where(nz, r, 1)
    direction *= nz
    return s * r, direction


def _local(r: np.ndarray, d: np.ndarray, par: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 12 for every joint at once: ``L_j = C_p⁻¹ ⊗ C_j`` ``= (r_p* ⊗ r_j | r_p* ⊗ d_j + d_p* ⊗ r_j)``;
    the root row of ``L_r`` is ``r_0`` (its ``L_d`` is not formed: the root's offset is 0). Parents gathered
    in one indexing; returns ``L_r (4, J, M)``, ``L_d (4, J − 1, M)``."""
    rpc, dpc = _conj(r[:, par[1:]]), _conj(d[:, par[1:]])  # (4, J-1, M)
    lr = np.empty_like(r)
    lr[:, 0] = r[:, 0]
    _qmul(rpc, r[:, 1:], out=lr[:, 1:])
    ld = _qmul(rpc, d[:, 1:])
    ld += _qmul(dpc, r[:, 1:])
    return lr, ld


def _sibling_rounds(par: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Non-root joints in rounds ``(children, their parents)`` with no parent twice in a round, so that
    ``g[:, parents] += x[:, children − 1]`` is a valid scatter-add (round k holds every k-th child)."""
    rank = np.zeros(len(par), dtype=np.intp)
    rounds: list[tuple[list, list]] = []
    for j in range(1, len(par)):
        k = rank[par[j]]
        rank[par[j]] += 1
        if k == len(rounds):
            rounds.append(([], []))
        rounds[k][0].append(j)
        rounds[k][1].append(par[j])
    return [(np.array(c, dtype=np.intp), np.array(p, dtype=np.intp)) for c, p in rounds]


#: Frames per chunk of the fused kernel: a chunk's arrays (8 × J × 512 numbers each) stay in the CPU caches.
CHUNK_FRAMES = 512


def _fused_forward(x, t, par, w, eps, chunk: int = CHUNK_FRAMES):
    """Value and gradient (at ``dtotal = 1``) of the whole path, chunk by chunk over the frames; ``None`` when
    the output is outside the ordinary range (then the caller composes): ``max |raw| > 2^(maxexp/8)`` (fourth
    powers could overflow) or a real part with ``|q_r| < eps`` (the clamp of Eq. 13)."""
    dtype = np.result_type(x, t, np.float32)
    limit = 2.0 ** (np.finfo(dtype).maxexp // 8)
    if max(float(x.max()), -float(x.min())) > limit or max(float(t.max()), -float(t.min())) > limit:
        return None
    J = x.shape[-2]
    x2 = x.reshape(-1, J, 8).astype(dtype, copy=False)          # (M, J, 8)
    t2 = t.reshape(-1, J, 8).astype(dtype, copy=False)
    M = x2.shape[0]
    count = J * M
    scale = {k: v / count for k, v in w.items()}                # dL_total / d(term summed over M·J)
    rounds = _sibling_rounds(par)
    sums = dict.fromkeys(w, 0.0)
    grad = np.empty(x2.shape, dtype=np.result_type(x.dtype, np.float32))
    for m0 in range(0, M, chunk):
        g = _fused_chunk(_soa(x2[m0:m0 + chunk]), _soa(t2[m0:m0 + chunk]), par, rounds, scale, eps, sums)
        if g is None:
            return None
        grad[m0:m0 + chunk] = g.transpose(2, 1, 0)
    parts = {k: sums[k] / count for k in w}
    total = float(sum(w[k] * parts[k] for k in w))
    return total, parts, ("fused", grad.reshape(x.shape))


def _fused_backward(dtotal, grad):
    """The cached gradient at ``dtotal = 1`` times ``dtotal`` (the loss is a scalar: its gradient is linear in
    ``dtotal``)."""
    d = float(dtotal)
    if not np.isfinite(d):
        raise ValueError(f"dtotal: expected a finite number, got {dtotal!r}")
    return grad * grad.dtype.type(d)


def _sum(x: np.ndarray) -> float:
    return float(np.sum(x, dtype=np.float64))


def _fused_chunk(X, Y, par, rounds, scale, eps, sums):
    """One chunk ``X``, ``Y`` ``(8, J, m)`` (raw output, target): adds each term's sum over the chunk to ``sums``
    and returns the chunk's gradient ``(8, J, m)`` of ``Σ_k scale[k] · (sum of term k)``; ``None`` if a real
    part is under the clamp. Forward then backward of every term on ``(r̂, d̂)``, then the Eq. 13 backward (as
    :func:`refimpl.nn.quat_layers.dq_normalize_backward`, clamp inactive) plus L_reg's."""
    r, d, tr, td = X[:4], X[4:], Y[:4], Y[4:]
    rr = _dot(r, r)                                                   # (J, m) |q_r|²
    n = np.sqrt(rr)
    if float(n.min()) < eps:
        return None
    rh = r / n                                                        # Eq. 13
    ad = _dot(rh, d)                                                  # <r̂, q_d>
    dh = (d - rh * ad) / n
    g_rh = np.zeros_like(rh)                                          # cotangents of (r̂, d̂)
    g_dh = np.zeros_like(dh)
    if "pos" in scale:                                                # Eq. 8
        dist, direction = _distance(_translation(rh, dh), _translation(tr, td))
        sums["pos"] += _sum(dist)
        dr, dd = _translation_backward(direction * scale["pos"], rh, dh)
        g_rh += dr
        g_dh += dd
    if "offset" in scale or "quat" in scale:                          # Eq. 12, shared by both terms
        lr, ld = _local(rh, dh, par)
        tlr, tld = _local(tr, td, par)
        g_lr = np.zeros_like(lr)                                      # (4, J, m), root row: L_r,0 = r̂_0
        g_ld = np.zeros_like(ld)                                      # (4, J-1, m)
        if "offset" in scale:                                         # Eq. 12, 8; the root's offset is 0
            dist, direction = _distance(_translation(lr[:, 1:], ld), _translation(tlr[:, 1:], tld))
            sums["offset"] += _sum(dist)
            dr, dd = _translation_backward(direction * scale["offset"], lr[:, 1:], ld)
            g_lr[:, 1:] += dr
            g_ld += dd
        if "quat" in scale:                                           # Eq. 15 on normalised local rotations
            nl = np.sqrt(_dot(lr, lr))
            tl = tlr / np.maximum(np.sqrt(_dot(tlr, tlr)), eps)
            l = lr / np.maximum(nl, eps)
            e = 1 - _dot(l, tl)
            sums["quat"] += _sum(np.abs(e))
            gl = tl * (np.sign(e) * -scale["quat"])
            radial = np.where(nl >= eps, _dot(l, gl), 0)              # normalisation backward
            g_lr += (gl - l * radial) / np.maximum(nl, eps)
        # L = a ⊗ b with a = (r_p*, d_p*), b = (r̂_j, d̂_j): da = (g_r ⊗ b_r* + g_d ⊗ b_d*, g_d ⊗ b_r*),
        # db = (a_r* ⊗ g_r + a_d* ⊗ g_d, a_r* ⊗ g_d), a_r* = r_p, a_d* = d_p
        rp, dp = rh[:, par[1:]], dh[:, par[1:]]
        glc = g_lr[:, 1:]
        g_rh[:, 0] += g_lr[:, 0]
        g_rh[:, 1:] += _qmul(rp, glc) + _qmul(dp, g_ld)
        g_dh[:, 1:] += _qmul(rp, g_ld)
        rcc = _conj(rh[:, 1:])
        g_rp = _conj(_qmul(glc, rcc) + _qmul(g_ld, _conj(dh[:, 1:])))  # conj: a_r = r_p*
        g_dp = _conj(_qmul(g_ld, rcc))
        for children, parents in rounds:                              # each parent collects from its children
            g_rh[:, parents] += g_rp[:, children - 1]
            g_dh[:, parents] += g_dp[:, children - 1]
    if "quat_current" in scale:                                       # Eq. 15 on current rotations
        e = 1 - _dot(rh, tr)
        sums["quat_current"] += _sum(np.abs(e))
        g_rh += tr * (np.sign(e) * -scale["quat_current"])
    # Eq. 13 backward (dq_normalize_backward with |q_r| >= eps)
    out = np.empty_like(X)
    rgd = _dot(rh, g_dh)
    np.divide(g_dh - rh * rgd, n, out=out[4:])
    g_rhat = g_rh - (ad * g_dh + d * rgd) / n
    g_n = -_dot(g_dh, dh) / n
    np.add((g_rhat - rh * _dot(rh, g_rhat)) / n, rh * g_n, out=out[:4])
    if "reg" in scale:                                                # Eq. 16: dq_r += (4 a q_r + 2 b q_d) c,
        a, b = rr - 1, _dot(r, d)                                     # dq_d += 2 b q_r c
        sums["reg"] += _sum(a * a + b * b)
        c = scale["reg"]
        out[:4] += (4 * c) * a * r + (2 * c) * b * d
        out[4:] += (2 * c) * b * r
    return out
