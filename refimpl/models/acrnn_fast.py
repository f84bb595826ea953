"""Fast training path of acRNN (spec/acrnn.md §2.1): the same auto-conditioned rollout and BPTT as
:func:`refimpl.models.acrnn.sequence_forward` / :func:`~refimpl.models.acrnn.sequence_backward`, equal to them
within float64 round-off (``tests/test_acrnn_fast.py``, atol 1e-10), organised for speed.

What is different from the step-by-step reference:

* **one GEMM per layer and step** in the forward: layer k's gates are ``z_t @ [W_ih | W_hh]^T + b`` with
  ``z_t = [input_t | h_{t-1}]`` written into a preallocated ``(T, B, I_k + H)`` buffer, which the backward
  reuses;
* layer 0's input projections of **every ground-truth step are one GEMM** before the loop (auto-conditioning
  makes only the own-output steps wait for the previous output); the decoder runs inside the loop only for the
  outputs that are fed back, and once over all steps at the end;
* the backward keeps the **gate cotangents of all steps** ``(T, B, 4H)`` and forms every weight gradient once
  per sequence: ``dW_k = dG_k^T Z_k`` (one GEMM over the ``T·B`` rows), ``db = Σ dG``, ``dW_dec = dY^T H_top``;
* no allocation inside the step loops (every buffer is allocated once per call, kernels write with ``out=``).

The cell kernels are :mod:`refimpl.nn.lstm`'s (kernel tier: ``cell_activate``, ``cell_gates_backward``, the
caller forming ``dh_prev``); the checks are
:func:`refimpl.models.acrnn.check_sequence_inputs`.

Shape legend: B batch, T steps, F frame size, H hidden size, L layers, I_k input size of layer k (F, then H),
G = 4H gate pre-activations (i | f | g | o, PyTorch order).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.models.acrnn import ACRNNConfig, loss_and_grads_with
from refimpl.models.acrnn import check_sequence_inputs as _check_sequence
from refimpl.nn.lstm import cell_activate as _cell_activate, cell_gates_backward as _cell_gates_backward
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
    xt = np.ascontiguousarray(x.transpose(1, 0, 2))                           # (T + 1, B, F)
    w_cat, bias = [], []
    for k in range(L):
        w_cat.append(np.ascontiguousarray(np.concatenate(
            [params[f"lstm.weight_ih_l{k}"], params[f"lstm.weight_hh_l{k}"]], axis=1)))   # (4H, I_k + H)
        bias.append(params[f"lstm.bias_ih_l{k}"] + params[f"lstm.bias_hh_l{k}"])          # (4H,)
    w_dec, b_dec = params["decoder.weight"], params["decoder.bias"]                        # (F, H), (F,)
    w_hh0_t = np.ascontiguousarray(params["lstm.weight_hh_l0"].T)                          # (H, 4H)
    w_dec_t = np.ascontiguousarray(w_dec.T)                                                # (H, F)
    wcat_t = [np.ascontiguousarray(w.T) for w in w_cat]                                    # (I_k + H, 4H)

    # buffers: inputs z_t = [input | h_prev] per layer, activated gates, cell states, tanh(c)
    Z = [np.empty((T, B, (F if k == 0 else H) + H), dtype=dt) for k in range(L)]
    gates = np.empty((L, T, B, 4 * H), dtype=dt)
    cs = np.zeros((L, T + 1, B, H), dtype=dt)                                 # index 0: initial state (zeros)
    hs = np.zeros((L, T + 1, B, H), dtype=dt)
    tcs = np.empty((L, T, B, H), dtype=dt)
    feed = np.empty((B, F), dtype=dt)                                          # a fed-back output
    # ground-truth steps: layer 0's input projection in one GEMM
    gt = np.flatnonzero(mask)
    Z[0][gt, :, :F] = xt[gt]
    gi0 = np.empty((T, B, 4 * H), dtype=dt)
    gi0[gt] = (xt[gt].reshape(-1, F) @ wcat_t[0][:F]).reshape(len(gt), B, 4 * H)
    gi0[gt] += bias[0]
    for t in range(T):
        for k in range(L):
            g = gates[k, t]
            if k == 0:
                if mask[t]:
                    np.matmul(hs[0, t], w_hh0_t, out=g)
                    g += gi0[t]
                    Z[0][t, :, F:] = hs[0, t]
                else:
                    Z[0][t, :, :F] = feed
                    Z[0][t, :, F:] = hs[0, t]
                    np.matmul(Z[0][t], wcat_t[0], out=g)
                    g += bias[0]
            else:
                Z[k][t, :, :H] = hs[k - 1, t] if skew else hs[k - 1, t + 1]
                Z[k][t, :, H:] = hs[k, t]
                np.matmul(Z[k][t], wcat_t[k], out=g)
                g += bias[k]
            _cell_activate(g, cs[k, t], cs[k, t + 1], tcs[k, t], hs[k, t + 1])
        if t + 1 < T and not mask[t + 1]:
            np.matmul(hs[L - 1, t + 1], w_dec_t, out=feed)
            feed += b_dec
    top = hs[L - 1, 1:]                                                        # (T, B, H)
    pred_t = (top.reshape(T * B, H) @ w_dec_t).reshape(T, B, F)
    pred_t += b_dec
    pred = np.ascontiguousarray(pred_t.transpose(1, 0, 2))                     # (B, T, F)
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
    dp = check_float_array(dpred, "dpred", (B, T, F)).astype(dt, copy=False)
    Z, gates, cs, tcs, hs = cache["Z"], cache["gates"], cache["cs"], cache["tcs"], cache["hs"]
    w_cat, w_dec = cache["w_cat"], cache["w_dec"]
    w_hh0 = np.ascontiguousarray(w_cat[0][:, F:])                              # (4H, H)
    dY = np.ascontiguousarray(dp.transpose(1, 0, 2))                           # (T, B, F) grows by the carries
    dtop = (dY.reshape(T * B, F) @ w_dec).reshape(T, B, H)                     # decoder backward of the loss part
    dG = np.empty((L, T, B, 4 * H), dtype=dt)
    dh = np.zeros((L, B, H), dtype=dt)
    dc = np.zeros((L, B, H), dtype=dt)
    tmp = np.empty((B, H), dtype=dt)
    dz = [np.empty((B, (F if k == 0 else H) + H), dtype=dt) for k in range(L)]
    dh_top_carry = np.empty((B, H), dtype=dt)
    carry = None                                                               # (B, F): d y_t from step t + 1
    for t in range(T - 1, -1, -1):
        if carry is not None:
            dY[t] += carry
            np.matmul(carry, w_dec, out=dh_top_carry)
            dh[L - 1] += dh_top_carry
        dh[L - 1] += dtop[t]
        pending = None                                                         # skewed: d h_{k, t-1} from above
        carry = None
        for k in range(L - 1, -1, -1):
            g = dG[k, t]
            _cell_gates_backward(dh[k], dc[k], cs[k, t], gates[k, t], tcs[k, t], g, tmp)
            n_in = F if k == 0 else H
            if k == 0 and mask[t]:
                np.matmul(g, w_hh0, out=dh[0])                                 # the input is data: no dx
            else:
                np.matmul(g, w_cat[k], out=dz[k])                              # d[input | h_prev]
                dh[k] = dz[k][:, n_in:]
            if pending is not None:
                dh[k] += pending
                pending = None
            if k == 0:
                carry = None if mask[t] else dz[0][:, :F]
            elif skew:
                pending = dz[k][:, :H]
            else:
                dh[k - 1] += dz[k][:, :H]
    grads = {}
    for k in range(L):
        n_in = F if k == 0 else H
        g2 = dG[k].reshape(T * B, 4 * H)
        dw = g2.T @ Z[k].reshape(T * B, n_in + H)                              # (4H, I_k + H), one GEMM
        grads[f"lstm.weight_ih_l{k}"] = np.ascontiguousarray(dw[:, :n_in])
        grads[f"lstm.weight_hh_l{k}"] = np.ascontiguousarray(dw[:, n_in:])
        db = g2.sum(axis=0)
        grads[f"lstm.bias_ih_l{k}"] = db
        grads[f"lstm.bias_hh_l{k}"] = db.copy()
    grads["decoder.weight"] = dY.reshape(T * B, F).T @ hs[L - 1, 1:].reshape(T * B, H)     # (F, H)
    grads["decoder.bias"] = dY.reshape(T * B, F).sum(axis=0)
    return grads


def loss_and_grads(params: Mapping[str, np.ndarray], config: ACRNNConfig, frames, spec, mask=None):
    """:func:`refimpl.models.acrnn.loss_and_grads` on the fast path: ``(total, parts, grads)``."""
    return loss_and_grads_with(sequence_forward, sequence_backward, params, config, frames, spec, mask)
