"""The dual-quaternion output path of a network and its losses (Andreou et al. §5.2; spec/acrnn.md §3).

A network that predicts current dual quaternions (acRNN, the long-term QuaterNet) is trained through one path::

    raw (..., J, 8) ─────────────────────────────► L_reg  (Eq. 16, on the raw output)
        │ Eq. 13 normalisation per joint
        ▼
    unit current DQs ─► translations (Eq. 8) ────► L_pos
                     ─► local (Eq. 12), Eq. 8 ───► L_offset
                     ─► local rotations (Eq. 12) ► L_quat (local, the default "quat")
                     ─► current rotations ───────► L_quat (current, "quat_current")

``total = Σ_name weights[name] · L_name`` over any subset of the five names (the paper's ablation); the
defaults are acRNN's Appendix B weights without the MSE (:data:`DQ_TERMS`, from
:data:`refimpl.losses.WEIGHTS_ACRNN_DQ`). The MSE on the standardised frame is composed by the model
(refimpl/models/acrnn.py). The target is the ground truth's unit current dual quaternions.

This module is the readable reference: the composition of the public layers and losses. The fused kernel
that training runs (7-8x faster on acRNN's batches; benchmarks/README.md) is :mod:`refimpl.dq_output_fast`, with the
same contract and equal values and gradients up to rounding (``tests/test_dq_output_fast.py``). spec/acrnn.md §3.

Shape legend: ``...`` leading axes (B, T), J joints, M = prod(...), C components (8 DQ, 4 quaternion, 3 vector).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.losses import (WEIGHTS_ACRNN_DQ, dq_offset_loss_backward, dq_offset_loss_forward, dq_pos_loss_backward,
                            dq_pos_loss_forward, dq_reg_loss_backward, dq_reg_loss_forward, local_quat_loss_backward,
                            local_quat_loss_forward, quat_loss_backward, quat_loss_forward)
from refimpl.nn.kinematics_layers import check_parents
from refimpl.arrays import float_array
from refimpl.nn.quat_layers import dq_normalize_backward, dq_normalize_forward

__all__ = ["DQ_TERM_NAMES", "DQ_TERMS", "dq_output_loss_forward", "dq_output_loss_backward"]

#: Loss names of the dual-quaternion output path.
DQ_TERM_NAMES = ("reg", "pos", "offset", "quat", "quat_current")
#: Default weights (acRNN, Appendix B): L_pos, L_offset × 1/3, local L_quat × 1, L_reg × 0.01.
DQ_TERMS = {k: WEIGHTS_ACRNN_DQ[k] for k in ("reg", "pos", "offset", "quat")}


def check_weights(weights: Mapping[str, float]) -> dict:
    """``weights`` checked: a non-empty mapping from :data:`DQ_TERM_NAMES` to finite numbers; returns a dict of floats."""
    if not isinstance(weights, Mapping) or not weights:
        raise ValueError(f"weights: expected a non-empty mapping over {DQ_TERM_NAMES}, got {weights!r}")
    out = {}
    for k, w in weights.items():
        if k not in DQ_TERM_NAMES:
            raise ValueError(f"weights: unknown loss {k!r}; expected names from {DQ_TERM_NAMES}")
        if not np.isfinite(float(w)):
            raise ValueError(f"weights[{k!r}]: expected a finite number, got {w!r}")
        out[k] = float(w)
    return out


def dq_output_loss_forward(raw, target, parents, weights: Mapping[str, float] = DQ_TERMS, eps: float = 1e-12):
    """Weighted sum of the dual-quaternion losses of a raw network output.

    Parameters
    ----------
    raw : ndarray, shape (..., J, 8)
        The network's dual quaternions before normalisation (after de-standardisation), ``(q_r | q_d)``.
    target : ndarray, shape (..., J, 8)
        Ground-truth unit current dual quaternions.
    parents : sequence of int, length J
    weights : mapping
        Loss name (``"reg"``, ``"pos"``, ``"offset"``, ``"quat"`` = local L_quat, ``"quat_current"``) → weight.
    eps : float
        Clamp of ``|q_r|`` in the Eq. 13 normalisation.

    Returns
    -------
    total : float
        ``Σ weights[k] · L_k``.
    parts : dict
        Unweighted value of each selected loss.
    cache : tuple
    """
    raw, target, w = np.asarray(raw), np.asarray(target), check_weights(weights)
    check_inputs(raw, target, parents)
    return _composed_forward(raw, target, parents, w, eps)


def dq_output_loss_backward(dtotal, cache):
    """Gradient of :func:`dq_output_loss_forward` with respect to ``raw`` ``(..., J, 8)``."""
    return _composed_backward(dtotal, cache)


def check_inputs(raw, target, parents):
    """The checks of :func:`dq_output_loss_forward` on its arrays: equal shapes ``(..., J, 8)``, float and finite,
    valid ``parents``. Returns ``(x, t, par)``: the float arrays and the parents as an index array."""
    if raw.ndim < 2 or raw.shape[-1] != 8 or raw.shape != target.shape:
        raise ValueError(f"raw, target: expected equal shapes (..., J, 8), got {raw.shape} and {target.shape}")
    x = float_array(raw, "raw", last=8, min_ndim=2)
    t = float_array(target, "target", last=8, min_ndim=2)
    return x, t, check_parents(parents, x.shape[-2])


# --------------------------------------------------------------------------------------------------
# the composition of the public losses

def _composed_forward(raw, target, parents, w, eps):
    """:func:`dq_output_loss_forward` as the composition of the public layers and losses (inputs checked)."""
    parts, caches = {}, {}
    if "reg" in w:
        parts["reg"], caches["reg"] = dq_reg_loss_forward(raw)
    geometric = [k for k in w if k != "reg"]
    unit, ncache = (dq_normalize_forward(raw, eps) if geometric else (None, None))   # (..., J, 8)
    for k in geometric:
        if k == "pos":
            parts[k], caches[k] = dq_pos_loss_forward(unit, target)
        elif k == "offset":
            parts[k], caches[k] = dq_offset_loss_forward(unit, target, parents)
        elif k == "quat":
            parts[k], caches[k] = local_quat_loss_forward(unit, target, parents)
        else:
            parts[k], caches[k] = quat_loss_forward(unit, target)
    total = float(sum(w[k] * parts[k] for k in w))
    return total, parts, (w, caches, ncache, raw.shape, np.result_type(raw.dtype, np.float32))


_BACKWARD = {"pos": dq_pos_loss_backward, "offset": dq_offset_loss_backward, "quat": local_quat_loss_backward,
             "quat_current": quat_loss_backward}


def _composed_backward(dtotal, cache):
    """Gradient of :func:`_composed_forward` with respect to ``raw``."""
    w, caches, ncache, shape, dtype = cache
    d = float(dtotal)
    draw = np.zeros(shape, dtype=dtype)
    if "reg" in w:
        draw += dq_reg_loss_backward(d * w["reg"], caches["reg"])
    if ncache is not None:
        dunit = np.zeros(shape, dtype=draw.dtype)
        for k in w:
            if k != "reg":
                dunit += _BACKWARD[k](d * w[k], caches[k])
        draw += dq_normalize_backward(dunit, ncache)
    return draw


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# check_weights, check_inputs.
