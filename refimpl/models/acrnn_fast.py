"""Fast training path of acRNN (spec/acrnn.md §2.1): the same auto-conditioned rollout and BPTT as
:func:`refimpl.models.acrnn.sequence_forward` / :func:`~refimpl.models.acrnn.sequence_backward`, equal to them
within float64 round-off (``tests/test_acrnn_fast.py``, atol 1e-10), organised for speed.

What is different from the step-by-step reference:

* **feature-major** arrays (the batch is the last, contiguous axis; spec/layers.md §5.6): every per-step product
  has the weight as its left operand, ``G_t = [W_ih | W_hh] @ z_t`` with ``z_t = [input_t ; h_{t-1}]`` (I_k + H, B),
  and every gate block of a step is one contiguous (H, B) slab;
* **one GEMM per layer and step** in the forward: ``z_t`` is written into a preallocated ``(I_k + H, T, B)`` buffer,
  which the backward reuses;
* layer 0's input projections of **every ground-truth step are one GEMM** before the loop (auto-conditioning
  makes only the own-output steps wait for the previous output); the decoder runs inside the loop only for the
  outputs that are fed back, and once over all steps at the end;
* the backward keeps the **gate cotangents of all steps** ``(4H, T, B)`` and forms every weight gradient once
  per sequence: ``dW_k = dG_k Z_k^T`` (one GEMM over the ``T·B`` columns), ``db = dG 1``, ``dW_dec = dY H_top^T``;
* no allocation inside the step loops (every buffer is allocated once per call, kernels write with ``out=``).

The step kernels are :mod:`refimpl.nn.lstm`'s feature-major ones (kernel tier: ``activate_fm``,
``gates_backward_fm``, the caller forming ``dh_prev``); the checks are
:func:`refimpl.models.acrnn.check_sequence_inputs`.

Shape legend: B batch, T steps, F frame size, H hidden size, L layers, I_k input size of layer k (F, then H),
G = 4H gate pre-activations (i ; f ; g ; o, PyTorch order).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.models.acrnn import ACRNNConfig, loss_and_grads_with
from refimpl.models.acrnn import check_sequence_inputs as _check_sequence
from refimpl.nn.lstm import activate_fm as _activate_fm, gates_backward_fm as _gates_backward_fm
from refimpl.nn.params import check_float_array

__all__ = ["sequence_forward", "sequence_backward", "loss_and_grads"]


def sequence_forward(params: Mapping[str, np.ndarray], config: ACRNNConfig, frames, mask=None):
    """Auto-conditioned rollout (same contract as :func:`refimpl.models.acrnn.sequence_forward`).

    Parameters
    ----------
    frames : ndarray (B, T + 1, F)
        Standardised ground-truth frames.
    mask : ndarray of bool (T,), optional
        True = step t reads ``frames[:, t]``; False = its own previous output. Default ``config.mask(T)``.

    Returns
    -------
    pred : ndarray (B, T, F)
    cache : dict
    """
    x, mask, dt = _check_sequence(params, config, frames, mask)
    B, T = x.shape[0], x.shape[1] - 1
    F, H, L, skew = config.frame_size, config.hidden_size, config.num_layers, config.skewed
    xf = np.ascontiguousarray(x.transpose(2, 1, 0))                           # (F, T + 1, B)
    w_cat, bias = [], []
    for k in range(L):
        w_cat.append(np.concatenate([params[f"lstm.weight_ih_l{k}"], params[f"lstm.weight_hh_l{k}"]],
                                    axis=1))                                   # (4H, I_k + H)
        bias.append((params[f"lstm.bias_ih_l{k}"] + params[f"lstm.bias_hh_l{k}"])[:, None])  # (4H, 1)
    w_dec, b_dec = params["decoder.weight"], params["decoder.bias"][:, None]  # (F, H), (F, 1)
    w_hh0 = w_cat[0][:, F:]                                                    # (4H, H) view

    # buffers: inputs z_t = [input ; h_prev] per layer, activated gates, cell states, tanh(c), hidden states
    Z = [np.empty(((F if k == 0 else H) + H, T, B), dtype=dt) for k in range(L)]
    gates = np.empty((L, T, 4 * H, B), dtype=dt)
    cs = np.empty((L, T + 1, H, B), dtype=dt)
    cs[:, 0] = 0                                                               # initial state (zeros)
    hs = np.empty((L, H, T + 1, B), dtype=dt)                                  # (H, T + 1, B) per layer
    hs[:, :, 0] = 0
    tcs = np.empty((L, T, H, B), dtype=dt)
    feed = np.empty((F, B), dtype=dt)                                          # a fed-back output
    # ground-truth steps: layer 0's input projection in one GEMM
    gt = np.flatnonzero(mask)
    slot = np.cumsum(mask) - 1                                                 # step -> column block of gi0
    xg = xf[:, gt]                                                             # (F, n_gt, B) copy
    Z[0][:F, gt] = xg
    gi0 = (w_cat[0][:, :F] @ xg.reshape(F, len(gt) * B)).reshape(4 * H, len(gt), B)
    gi0 += bias[0][:, :, None]
    with np.errstate(over="ignore"):  # exp(-a) -> inf for a < -88 (float32) gives sigmoid 0 exactly
        for t in range(T):
            for k in range(L):
                g = gates[k, t]                                                # (4H, B)
                if k == 0 and mask[t]:
                    np.matmul(w_hh0, hs[0, :, t], out=g)
                    g += gi0[:, slot[t]]
                    Z[0][F:, t] = hs[0, :, t]
                else:
                    n_in = F if k == 0 else H
                    if k > 0:
                        Z[k][:H, t] = hs[k - 1, :, t] if skew else hs[k - 1, :, t + 1]
                    Z[k][n_in:, t] = hs[k, :, t]                               # layer 0: input set by the feed
                    np.matmul(w_cat[k], Z[k][:, t], out=g)
                    g += bias[k]
                _activate_fm(g, cs[k, t], cs[k, t + 1], tcs[k, t], hs[k, :, t + 1])
            if t + 1 < T and not mask[t + 1]:
                np.matmul(w_dec, hs[L - 1, :, t + 1], out=feed)
                np.add(feed, b_dec, out=Z[0][:F, t + 1])
    top = hs[L - 1, :, 1:].reshape(H, T * B)                                  # (H, T*B) view
    pred_f = (w_dec @ top).reshape(F, T, B)
    pred_f += b_dec[:, :, None]
    pred = np.ascontiguousarray(pred_f.transpose(2, 1, 0))                     # (B, T, F)
    cache = dict(Z=Z, gates=gates, cs=cs, hs=hs, tcs=tcs, w_cat=w_cat, w_dec=w_dec, mask=mask, config=config,
                 shape=(B, T), dtype=dt)
    return pred, cache


def sequence_backward(dpred, cache) -> dict[str, np.ndarray]:
    """BPTT of :func:`sequence_forward` (same contract as :func:`refimpl.models.acrnn.sequence_backward`).

    Parameters
    ----------
    dpred : ndarray (B, T, F)

    Returns
    -------
    grads : dict full parameter name -> gradient
    """
    config, mask = cache["config"], cache["mask"]
    B, T = cache["shape"]
    dt = cache["dtype"]
    F, H, L, skew = config.frame_size, config.hidden_size, config.num_layers, config.skewed
    dp = check_float_array(dpred, "dpred", (B, T, F))
    Z, gates, cs, tcs, hs = cache["Z"], cache["gates"], cache["cs"], cache["tcs"], cache["hs"]
    w_cat, w_dec = cache["w_cat"], cache["w_dec"]
    w_cat_t = [np.ascontiguousarray(w.T) for w in w_cat]                      # (I_k + H, 4H)
    whh0_t = w_cat_t[0][F:]                                                    # (H, 4H) contiguous
    w_dec_t = np.ascontiguousarray(w_dec.T)                                    # (H, F)
    dY = np.array(dp.transpose(2, 1, 0), dtype=dt, order="C")                  # (F, T, B) grows by the carries
    dtop = (w_dec_t @ dY.reshape(F, T * B)).reshape(H, T, B)                   # decoder backward of the loss part
    dG = [np.empty((4 * H, T, B), dtype=dt) for _ in range(L)]
    dgs = np.empty((4 * H, B), dtype=dt)                                       # this step's gate cotangents
    dh = np.zeros((L, H, B), dtype=dt)
    dc = np.zeros((L, H, B), dtype=dt)
    tmp = np.empty((H, B), dtype=dt)
    dz = [np.empty(((F if k == 0 else H) + H, B), dtype=dt) for k in range(L)]
    dh_top_carry = np.empty((H, B), dtype=dt)
    carry = None                                                               # (F, B): d y_t from step t + 1
    for t in range(T - 1, -1, -1):
        if carry is not None:
            dY[:, t] += carry
            np.matmul(w_dec_t, carry, out=dh_top_carry)
            dh[L - 1] += dh_top_carry
        dh[L - 1] += dtop[:, t]
        pending = None                                                         # skewed: d h_{k, t-1} from above
        carry = None
        for k in range(L - 1, -1, -1):
            _gates_backward_fm(dh[k], dc[k], cs[k, t], gates[k, t], tcs[k, t], dgs, tmp)
            n_in = F if k == 0 else H
            if k == 0 and mask[t]:
                np.matmul(whh0_t, dgs, out=dh[0])                              # the input is data: no dx
            else:
                np.matmul(w_cat_t[k], dgs, out=dz[k])                          # d[input ; h_prev]
                dh[k] = dz[k][n_in:]
            dG[k][:, t] = dgs
            if pending is not None:
                dh[k] += pending
                pending = None
            if k == 0:
                carry = None if mask[t] else dz[0][:F]
            elif skew:
                pending = dz[k][:H]
            else:
                dh[k - 1] += dz[k][:H]
    grads = {}
    for k in range(L):
        n_in = F if k == 0 else H
        g2 = dG[k].reshape(4 * H, T * B)
        dw = g2 @ Z[k].reshape(n_in + H, T * B).T                              # (4H, I_k + H), one GEMM
        grads[f"lstm.weight_ih_l{k}"] = np.ascontiguousarray(dw[:, :n_in])
        grads[f"lstm.weight_hh_l{k}"] = np.ascontiguousarray(dw[:, n_in:])
        db = g2 @ np.ones(T * B, dtype=dt)                                     # (4H,), one GEMV
        grads[f"lstm.bias_ih_l{k}"] = db
        grads[f"lstm.bias_hh_l{k}"] = db.copy()
    dy2 = dY.reshape(F, T * B)
    grads["decoder.weight"] = dy2 @ hs[L - 1, :, 1:].reshape(H, T * B).T     # (F, H)
    grads["decoder.bias"] = dy2 @ np.ones(T * B, dtype=dt)
    return grads


def loss_and_grads(params: Mapping[str, np.ndarray], config: ACRNNConfig, frames, spec, mask=None):
    """:func:`refimpl.models.acrnn.loss_and_grads` on the fast path: ``(total, parts, grads)``."""
    return loss_and_grads_with(sequence_forward, sequence_backward, params, config, frames, spec, mask)
