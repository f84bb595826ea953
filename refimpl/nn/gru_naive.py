"""Slow oracles of :mod:`refimpl.nn.gru` (spec/layers.md §4): the multi-layer (optionally bidirectional) GRU per
time step and per gate, in obvious code, with the weight gradients accumulated step by step. Test oracles (and
the pace network's reference backward); equations, parameter names and layouts as :mod:`refimpl.nn.gru`.

Shapes: B batch, T time, I input size, H hidden size, L layers, D directions (1 or 2). ``x (B, T, I)``;
``h0, h_n (L*D, B, H)``; ``y (B, T, D*H)``.
"""
from __future__ import annotations

import numpy as np

from refimpl.nn.gru import layer_suffix
from refimpl.nn.params import param_name

__all__: list[str] = []


def _sig(a):
    return 1.0 / (1.0 + np.exp(-a))


def _gate_params(params, prefix, k, d, hid):
    sfx = layer_suffix(k, d)
    w_ih = params[param_name(prefix, f"weight_ih_{sfx}")]
    w_hh = params[param_name(prefix, f"weight_hh_{sfx}")]
    b_ih = params[param_name(prefix, f"bias_ih_{sfx}")]
    b_hh = params[param_name(prefix, f"bias_hh_{sfx}")]
    blocks = lambda a: (a[:hid], a[hid:2 * hid], a[2 * hid:])  # noqa: E731  r, z, n
    return blocks(w_ih), blocks(w_hh), blocks(b_ih), blocks(b_hh)


def _gru_naive_direction(inp, h, params, prefix, k, d):
    """Per-step, per-gate forward of one direction; returns the per-step records in natural time order."""
    batch, t_len, _ = inp.shape
    hid = h.shape[-1]
    (w_ir, w_iz, w_in), (w_hr, w_hz, w_hn), (b_ir, b_iz, b_in), (b_hr, b_hz, b_hn) = _gate_params(
        params, prefix, k, d, hid)
    steps = {}
    order = range(t_len) if d == 0 else range(t_len - 1, -1, -1)
    for t in order:
        x_t = inp[:, t]
        r = _sig(x_t @ w_ir.T + b_ir + h @ w_hr.T + b_hr)
        z = _sig(x_t @ w_iz.T + b_iz + h @ w_hz.T + b_hz)
        hn = h @ w_hn.T + b_hn
        n = np.tanh(x_t @ w_in.T + b_in + r * hn)
        h_new = (1 - z) * n + z * h
        steps[t] = dict(x=x_t, h_prev=h, r=r, z=z, hn=hn, n=n, h=h_new)
        h = h_new
    return steps, h


def gru_forward_naive(x, h0, params, prefix, num_layers=1, bidirectional=False):
    """Slow oracle for :func:`gru_forward`: returns ``(y, h_n)``."""
    d_count = 2 if bidirectional else 1
    inp = x
    h_n = []
    for k in range(num_layers):
        outs = []
        for d in range(d_count):
            steps, h_last = _gru_naive_direction(inp, h0[k * d_count + d], params, prefix, k, d)
            outs.append(np.stack([steps[t]["h"] for t in range(inp.shape[1])], axis=1))
            h_n.append(h_last)
        inp = np.concatenate(outs, axis=-1)
    return inp, np.stack(h_n)


def gru_backward_naive(dy, dh_n, x, h0, params, prefix, num_layers=1, bidirectional=False):
    """Slow oracle for :func:`gru_backward` (recomputes the forward): returns ``(dx, dh0, grads)``.

    Per step and per gate, weight gradients accumulated step by step."""
    d_count = 2 if bidirectional else 1
    batch, t_len, _ = x.shape
    hid = h0.shape[-1]
    inputs, records = [], []
    inp = x
    for k in range(num_layers):
        recs, outs = [], []
        for d in range(d_count):
            steps, _ = _gru_naive_direction(inp, h0[k * d_count + d], params, prefix, k, d)
            recs.append(steps)
            outs.append(np.stack([steps[t]["h"] for t in range(t_len)], axis=1))
        inputs.append(inp)
        records.append(recs)
        inp = np.concatenate(outs, axis=-1)
    grads = {}
    dh0 = np.zeros_like(h0)
    d_above = dy
    for k in range(num_layers - 1, -1, -1):
        d_inp = np.zeros_like(inputs[k])
        for d in range(d_count):
            (w_ir, w_iz, w_in), (w_hr, w_hz, w_hn), _, _ = _gate_params(params, prefix, k, d, hid)
            g = {n: 0.0 for n in ("w_ir", "w_iz", "w_in", "w_hr", "w_hz", "w_hn",
                                  "b_ir", "b_iz", "b_in", "b_hr", "b_hz", "b_hn")}
            row = k * d_count + d
            dh = np.zeros((batch, hid)) if dh_n is None else dh_n[row].copy()
            order = range(t_len - 1, -1, -1) if d == 0 else range(t_len)
            for t in order:
                s = records[k][d][t]
                dh = dh + d_above[:, t, d * hid:(d + 1) * hid]
                dn = dh * (1 - s["z"])
                dz = dh * (s["h_prev"] - s["n"])
                da_n = dn * (1 - s["n"] ** 2)
                da_z = dz * s["z"] * (1 - s["z"])
                dr = da_n * s["hn"]
                da_r = dr * s["r"] * (1 - s["r"])
                dhn = da_n * s["r"]
                g["w_ir"] = g["w_ir"] + da_r.T @ s["x"]
                g["w_iz"] = g["w_iz"] + da_z.T @ s["x"]
                g["w_in"] = g["w_in"] + da_n.T @ s["x"]
                g["w_hr"] = g["w_hr"] + da_r.T @ s["h_prev"]
                g["w_hz"] = g["w_hz"] + da_z.T @ s["h_prev"]
                g["w_hn"] = g["w_hn"] + dhn.T @ s["h_prev"]
                g["b_ir"] = g["b_ir"] + da_r.sum(0)
                g["b_iz"] = g["b_iz"] + da_z.sum(0)
                g["b_in"] = g["b_in"] + da_n.sum(0)
                g["b_hr"] = g["b_hr"] + da_r.sum(0)
                g["b_hz"] = g["b_hz"] + da_z.sum(0)
                g["b_hn"] = g["b_hn"] + dhn.sum(0)
                d_inp[:, t] += da_r @ w_ir + da_z @ w_iz + da_n @ w_in
                dh = dh * s["z"] + da_r @ w_hr + da_z @ w_hz + dhn @ w_hn
            dh0[row] = dh
            sfx = layer_suffix(k, d)
            grads[param_name(prefix, f"weight_ih_{sfx}")] = np.concatenate([g["w_ir"], g["w_iz"], g["w_in"]])
            grads[param_name(prefix, f"weight_hh_{sfx}")] = np.concatenate([g["w_hr"], g["w_hz"], g["w_hn"]])
            grads[param_name(prefix, f"bias_ih_{sfx}")] = np.concatenate([g["b_ir"], g["b_iz"], g["b_in"]])
            grads[param_name(prefix, f"bias_hh_{sfx}")] = np.concatenate([g["b_hr"], g["b_hz"], g["b_hn"]])
        d_above = d_inp
    return d_above, dh0, grads


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# gru_forward_naive, gru_backward_naive.
