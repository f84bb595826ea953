"""The factored reverse step of the GRU, for callers that run their own step loops: QTG's fused training rollout
(:mod:`refimpl.models.qtg_fast`, spec/qtg.md §4). Kernel tier (spec/architecture.md): unchecked, not in ``__all__``.

``backward_factors`` forms the state-independent factors of every step's gate cotangents for a whole sequence at
once; ``cell_backward_gates`` turns a step's state cotangent into its pre-activation cotangents from them (4 calls
instead of the per-step kernel's 19). ``tests/test_nn_gru.py`` holds the factored step (these two, then
``dh_prev = dh z + dgh W_hh``) equal to :func:`refimpl.nn.gru.cell_backward`. QTG's fast path as a whole pays
(spec/qtg.md §4); inside :func:`refimpl.nn.gru.gru_backward` the factored step measured the same CPU time as the
per-step kernel (0.99-1.03, GEMM-bound), so the sequence backward keeps the per-step kernel.

Shape legend: B batch, H hidden size, ``...`` any leading axes (steps, batch).
"""
from __future__ import annotations

import numpy as np

__all__: list[str] = []


def backward_factors(h, g, n):
    """The state-independent factors of the GRU backward, for many steps at once (fast path of BPTT).

    h (..., H): the states each step started from; g (..., 3H) = [r | z | W_hn h + b_hn] and n (..., H) from
    :func:`refimpl.nn.gru.cell_forward`. Returns f (..., 3H) = [a_r | a_z | a_n] with
    ``a_r = (1 - r) r (W_hn h + b_hn)``, ``a_z = (h - n) z (1 - z)``, ``a_n = (1 - n²)(1 - z)``, so that a step's
    pre-activation cotangents are ``da_n = dh a_n``, ``da_z = dh a_z``, ``da_r = da_n a_r``
    (:func:`cell_backward_gates`); ``a_n`` and ``a_r`` are formed in the order :func:`refimpl.nn.gru.cell_backward`
    uses (same rounding), ``a_z`` multiplies ``dh`` last.
    """
    hid = h.shape[-1]
    r, z, ghn = g[..., :hid], g[..., hid:2 * hid], g[..., 2 * hid:]
    f = np.empty_like(g)  # (..., 3H)
    f_r, f_z, f_n = f[..., :hid], f[..., hid:2 * hid], f[..., 2 * hid:]
    one_minus_z = np.subtract(1, z)  # (..., H)
    np.multiply(n, n, out=f_n)
    np.subtract(1, f_n, out=f_n)
    f_n *= one_minus_z
    np.subtract(h, n, out=f_z)
    f_z *= z
    f_z *= one_minus_z
    np.subtract(1, r, out=f_r)
    f_r *= r
    f_r *= ghn
    return f


def cell_backward_gates(dh, f, r, dgi, dgh):
    """A step's pre-activation cotangents from its state cotangent ``dh`` (B, H) and factors ``f`` (B, 3H)
    (:func:`backward_factors`): writes dgi (B, 3H) = [da_r | da_z | da_n] (C-contiguous rows) and dgh (B, 3H) =
    [da_r | da_z | r da_n] (may be a strided view); ``r`` (B, H). Four element-wise calls; dh is not changed."""
    batch, hid = dh.shape
    np.multiply(f[:, hid:].reshape(batch, 2, hid), dh[:, None, :],
                out=dgi.reshape(batch, 3, hid)[:, 1:])  # da_z, da_n in one call
    np.multiply(dgi[:, 2 * hid:], f[:, :hid], out=dgi[:, :hid])  # da_r
    dgh[:, :2 * hid] = dgi[:, :2 * hid]
    np.multiply(dgi[:, 2 * hid:], r, out=dgh[:, 2 * hid:])
