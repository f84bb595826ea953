"""Slow oracles of :mod:`refimpl.nn.lstm` (spec/layers.md §5): the multi-layer LSTM as a time-outer loop over all
layers (as acRNN's code steps its cells), per gate, in obvious code. Test oracles; equations, the skew, parameter
names and layouts as :mod:`refimpl.nn.lstm`.

Shapes: B batch, T time, I input size, H hidden size, L layers. ``x (B, T, I)``; ``h0, c0, h_n, c_n (L, B, H)``;
``y (B, T, H)``.
"""
from __future__ import annotations

import numpy as np

from refimpl.nn.params import param_name

__all__: list[str] = []


def _sig(a):
    return 1.0 / (1.0 + np.exp(-a))


def _gates(params, prefix, k, hid):
    w_ih = params[param_name(prefix, f"weight_ih_l{k}")]
    w_hh = params[param_name(prefix, f"weight_hh_l{k}")]
    b = params[param_name(prefix, f"bias_ih_l{k}")] + params[param_name(prefix, f"bias_hh_l{k}")]
    split = lambda a: [a[j * hid:(j + 1) * hid] for j in range(4)]  # noqa: E731  i, f, g, o
    return split(w_ih), split(w_hh), split(b)


def _lstm_naive_records(x, h0, c0, params, prefix, num_layers, skewed):
    batch, t_len, _ = x.shape
    hid = h0.shape[-1]
    h = [h0[k] for k in range(num_layers)]
    c = [c0[k] for k in range(num_layers)]
    recs = []  # recs[t][k]
    for t in range(t_len):
        h_old = list(h)
        step = []
        for k in range(num_layers):
            (w_ii, w_if, w_ig, w_io), (w_hi, w_hf, w_hg, w_ho), (b_i, b_f, b_g, b_o) = _gates(params, prefix, k, hid)
            inp = x[:, t] if k == 0 else (h_old[k - 1] if skewed else h[k - 1])
            i = _sig(inp @ w_ii.T + h[k] @ w_hi.T + b_i)
            f = _sig(inp @ w_if.T + h[k] @ w_hf.T + b_f)
            g = np.tanh(inp @ w_ig.T + h[k] @ w_hg.T + b_g)
            o = _sig(inp @ w_io.T + h[k] @ w_ho.T + b_o)
            c_new = f * c[k] + i * g
            h_new = o * np.tanh(c_new)
            step.append(dict(x=inp, h_prev=h[k], c_prev=c[k], i=i, f=f, g=g, o=o, c=c_new, h=h_new))
            h[k], c[k] = h_new, c_new
        recs.append(step)
    return recs, h, c


def _lstm_forward_naive(x, state, params, prefix, num_layers=1, skewed=False):
    """Slow oracle for :func:`lstm_forward`: returns ``(y, (h_n, c_n))``."""
    h0, c0 = state
    recs, h, c = _lstm_naive_records(x, h0, c0, params, prefix, num_layers, skewed)
    y = np.stack([recs[t][-1]["h"] for t in range(x.shape[1])], axis=1)
    return y, (np.stack(h), np.stack(c))


def _lstm_backward_naive(dy, dstate_n, x, state, params, prefix, num_layers=1, skewed=False):
    """Slow oracle for :func:`lstm_backward` (recomputes the forward): returns ``(dx, (dh0, dc0), grads)``.

    Time-outer reverse loop; every cotangent of a state is accumulated in ``dh_acc[t][k]`` /
    ``dc_acc[t][k]`` (index t+1 = state after step t, index 0 = initial state)."""
    h0, c0 = state
    batch, t_len, _ = x.shape
    hid = h0.shape[-1]
    recs, _, _ = _lstm_naive_records(x, h0, c0, params, prefix, num_layers, skewed)
    dh_acc = [[np.zeros((batch, hid)) for _ in range(num_layers)] for _ in range(t_len + 1)]
    dc_acc = [[np.zeros((batch, hid)) for _ in range(num_layers)] for _ in range(t_len + 1)]
    if dstate_n is not None:
        for k in range(num_layers):
            if dstate_n[0] is not None:
                dh_acc[t_len][k] += dstate_n[0][k]
            if dstate_n[1] is not None:
                dc_acc[t_len][k] += dstate_n[1][k]
    for t in range(t_len):
        dh_acc[t + 1][num_layers - 1] += dy[:, t]
    dx = np.zeros_like(x)
    gsum = {}

    def add(name, value):
        gsum[name] = gsum.get(name, 0.0) + value

    for t in range(t_len - 1, -1, -1):
        for k in range(num_layers - 1, -1, -1):
            s = recs[t][k]
            (w_ii, w_if, w_ig, w_io), (w_hi, w_hf, w_hg, w_ho), _ = _gates(params, prefix, k, hid)
            dh = dh_acc[t + 1][k]
            dc = dc_acc[t + 1][k] + dh * s["o"] * (1 - np.tanh(s["c"]) ** 2)
            da_o = dh * np.tanh(s["c"]) * s["o"] * (1 - s["o"])
            da_i = dc * s["g"] * s["i"] * (1 - s["i"])
            da_f = dc * s["c_prev"] * s["f"] * (1 - s["f"])
            da_g = dc * s["i"] * (1 - s["g"] ** 2)
            for gate, da in (("i", da_i), ("f", da_f), ("g", da_g), ("o", da_o)):
                add(f"wi{gate}{k}", da.T @ s["x"])
                add(f"wh{gate}{k}", da.T @ s["h_prev"])
                add(f"b{gate}{k}", da.sum(0))
            d_inp = da_i @ w_ii + da_f @ w_if + da_g @ w_ig + da_o @ w_io
            dh_acc[t][k] += da_i @ w_hi + da_f @ w_hf + da_g @ w_hg + da_o @ w_ho
            dc_acc[t][k] += dc * s["f"]
            if k == 0:
                dx[:, t] += d_inp
            elif skewed:
                dh_acc[t][k - 1] += d_inp  # input was the OLD state of layer k-1
            else:
                dh_acc[t + 1][k - 1] += d_inp  # input was the new state of layer k-1
    grads = {}
    for k in range(num_layers):
        grads[param_name(prefix, f"weight_ih_l{k}")] = np.concatenate([gsum[f"wi{q}{k}"] for q in "ifgo"])
        grads[param_name(prefix, f"weight_hh_l{k}")] = np.concatenate([gsum[f"wh{q}{k}"] for q in "ifgo"])
        grads[param_name(prefix, f"bias_ih_l{k}")] = np.concatenate([gsum[f"b{q}{k}"] for q in "ifgo"])
        grads[param_name(prefix, f"bias_hh_l{k}")] = grads[param_name(prefix, f"bias_ih_l{k}")].copy()
    dh0 = np.stack([dh_acc[0][k] for k in range(num_layers)])
    dc0 = np.stack([dc_acc[0][k] for k in range(num_layers)])
    return dx, (dh0, dc0), grads
