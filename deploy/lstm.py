"""ONNX builders for the multi-layer LSTM of ``refimpl/nn/lstm.py`` (PyTorch ``nn.LSTM``), incl. acRNN's skew.

Equations (PyTorch, gate blocks ``i|f|g|o`` in ``weight_ih_l{k}`` ``(4H, I)`` and ``weight_hh_l{k}`` ``(4H, H)``)::

    i = σ(x W_iiᵀ + b_ii + h W_hiᵀ + b_hi)      f = σ(... f ...)
    g = tanh(x W_igᵀ + b_ig + h W_hgᵀ + b_hg)    o = σ(... o ...)
    c' = f ⊙ c + i ⊙ g
    h' = o ⊙ tanh(c')

ONNX ``LSTM`` orders gates ``i|o|f|c`` (``LSTM_PERM``), has no peepholes here, and keeps input and recurrent
biases apart (``B (D, 8H)``), ``spec/deploy.md`` §2.4.

*Skewed* stacking (acRNN's published code, ``spec/layers.md``): layer ``k ≥ 1`` at step ``t`` reads the
*previous* step's output of layer ``k − 1``, ``h^{k−1}_{t−1}`` (``h^{k−1}_{−1}`` = that layer's initial state),
instead of ``h^{k−1}_t``. Over a sequence this is an ordinary LSTM layer whose input is the layer below's output
shifted one step later in time with its initial state in front: ``[h0^{k−1}, y^{k−1}_0, …, y^{k−1}_{T−2}]``.

Shape legend: B batch, T time, I input features, H hidden, L layers, D directions.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from deploy.graph import GraphBuilder
from deploy.recurrent import (LSTM_PERM, check_layer_shapes, concat_layers,
                              input_projection, merge_directions,
                              onnx_layer_weights,
                              primitive_layer_weights, scan_recurrence,
                              split_layers, squeeze0, time_major,
                              unsqueeze0)

__all__ = ["lstm", "lstm_step", "lstm_onnx_weights"]


def lstm_onnx_weights(params: Mapping[str, np.ndarray], prefix: str, layer: int = 0,
                      bidirectional: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ONNX ``W (D, 4H, I)``, ``R (D, 4H, H)``, ``B (D, 8H)`` of LSTM layer ``layer`` (gates i|o|f|c)."""
    w, r, b, _ = onnx_layer_weights(params, prefix, layer, 2 if bidirectional else 1, LSTM_PERM)
    return w, r, b


def lstm(g: GraphBuilder, x: str, h0: str, c0: str, params: Mapping[str, np.ndarray], prefix: str, *,
         name: str, num_layers: int = 1, bidirectional: bool = False,
         skewed: bool = False, wname: str | None = None) -> tuple[str, str, str]:
    """Append an LSTM over a whole sequence.

    Parameters
    ----------
    x : str
        Input ``(B, T, I)``, batch-first.
    h0, c0 : str
        Initial states ``(L·D, B, H)`` each.
    params : dict
        ``{prefix}.weight_ih_l{k}[_reverse]`` ``(4H, I_k)``, ``weight_hh_l{k}`` ``(4H, H)``, ``bias_ih_l{k}``,
        ``bias_hh_l{k}`` ``(4H,)``, gate blocks ``i|f|g|o``.
    name : str
        Graph path (``"rnn"``).
    wname : str, optional
        Path of the initializers (default ``name``), shared between calls with the same ``wname``.
    num_layers, bidirectional
        As ``nn.LSTM``.
    skewed : bool
        acRNN's stacking (module docstring); unidirectional only.

    Returns
    -------
    y : str
        ``(B, T, D·H)``: top layer's outputs.
    h_n, c_n : str
        ``(L·D, B, H)``.
    """
    if skewed and bidirectional:
        raise ValueError("skewed: the skewed stacking is defined for unidirectional LSTMs only")
    dirs = 2 if bidirectional else 1
    seq = time_major(g, x, f"{name}.x_tm")                              # (T, B, I)
    h0s = split_layers(g, h0, num_layers, dirs, f"{name}.h0")           # L × (D, B, H)
    c0s = split_layers(g, c0, num_layers, dirs, f"{name}.c0")
    hns, cns = [], []
    for k in range(num_layers):
        check_layer_shapes(params, prefix, k, 4, dirs)
        lname, wl = f"{name}.l{k}", f"{wname or name}.l{k}"
        if skewed and k > 0:
            # input of layer k at step t is h^{k-1}_{t-1}: [h0^{k-1}, y^{k-1}_0 .. y^{k-1}_{T-2}]
            prev = g.node("Slice", [seq, g.ints([0]), g.ints([-1]), g.ints([0])], f"{lname}.prev")  # (T-1, B, H)
            seq = g.node("Concat", [h0s[k - 1], prev], f"{lname}.x_skew", axis=0)                 # (T, B, H)
        if g.primitive:
            seq, hn, cn = _primitive_layer(g, seq, h0s[k], c0s[k], params, prefix, k, dirs, lname, wl)
        else:
            w, r, b, hidden = onnx_layer_weights(params, prefix, k, dirs, LSTM_PERM)
            y, hn, cn = g.node("LSTM", [seq, g.weight(f"{wl}.W", w), g.weight(f"{wl}.R", r),
                                        g.weight(f"{wl}.B", b), "", h0s[k], c0s[k]],
                               lname, outputs=("Y", "Y_h", "Y_c"), hidden_size=hidden,
                               direction="bidirectional" if bidirectional else "forward")  # (T, D, B, H)
            seq = merge_directions(g, y, dirs, f"{lname}.y")           # (T, B, D·H)
        hns.append(hn)
        cns.append(cn)
    y = time_major(g, seq, f"{name}.y")                                 # (B, T, D·H)
    return y, concat_layers(g, hns, f"{name}.h_n"), concat_layers(g, cns, f"{name}.c_n")


def lstm_step(g: GraphBuilder, x_t: str, h: str, c: str, params: Mapping[str, np.ndarray], prefix: str, *,
              name: str, num_layers: int = 1, skewed: bool = False,
              wname: str | None = None) -> tuple[str, str, str]:
    """Append one LSTM time step (unidirectional stack).

    Parameters
    ----------
    x_t : str
        Input ``(B, I)``.
    h, c : str
        States ``(L, B, H)``.
    skewed : bool
        Layer ``k ≥ 1`` reads the old state ``h[k − 1]`` instead of the new one.
    wname : str, optional
        Path of the initializers (default ``name``).

    Returns
    -------
    y : str
        ``(B, H)``: top layer's new ``h``.
    h_new, c_new : str
        ``(L, B, H)``.
    """
    hs = split_layers(g, h, num_layers, 1, f"{name}.h")                 # L × (1, B, H)
    cs = split_layers(g, c, num_layers, 1, f"{name}.c")
    h_out, c_out = [], []
    inp = g.node("Unsqueeze", [x_t, g.ints([0])], f"{name}.x_seq")       # (1, B, I)
    for k in range(num_layers):
        check_layer_shapes(params, prefix, k, 4, 1)
        lname, wl = f"{name}.l{k}", f"{wname or name}.l{k}"
        if skewed and k > 0:
            inp = hs[k - 1]                                              # (1, B, H): old state of layer k-1
        if g.primitive:
            w_ih, w_hh, b_ih, b_hh = primitive_layer_weights(params, prefix, k, False)
            xp = input_projection(g, squeeze0(g, inp, f"{lname}.x"), w_ih, b_ih, lname, wl)  # (B, 4H)
            wh, bh = g.weight(f"{wl}.Wh", w_hh.T), g.weight(f"{wl}.bh", b_hh)
            hk, ck = _lstm_cell(g, xp, squeeze0(g, hs[k], f"{lname}.h"), squeeze0(g, cs[k], f"{lname}.c"),
                                wh, bh, w_hh.shape[1], f"{lname}.cell")  # (B, H) each
            hn, cn = unsqueeze0(g, hk, f"{lname}.h_new"), unsqueeze0(g, ck, f"{lname}.c_new")
        else:
            w, r, b, hidden = onnx_layer_weights(params, prefix, k, 1, LSTM_PERM)
            _, hn, cn = g.node("LSTM", [inp, g.weight(f"{wl}.W", w), g.weight(f"{wl}.R", r),
                                        g.weight(f"{wl}.B", b), "", hs[k], cs[k]],
                               lname, outputs=("", "Y_h", "Y_c"), hidden_size=hidden)  # (1, B, H) each
        h_out.append(hn)
        c_out.append(cn)
        inp = hn
    y = squeeze0(g, inp, f"{name}.y")                                   # (B, H)
    return y, concat_layers(g, h_out, f"{name}.h_new"), concat_layers(g, c_out, f"{name}.c_new")


# --------------------------------------------------------------------------------------- primitive form
def _lstm_cell(g: GraphBuilder, xp: str, h: str, c: str, wh: str, bh: str, hidden: int,
               name: str) -> tuple[str, str]:
    """One LSTM cell from primitives; ``xp = x W_iᵀ + b_i`` ``(B, 4H)`` (blocks i|f|g|o); ``h, c`` ``(B, H)``."""
    hw = g.node("MatMul", [h, wh], f"{name}.hw")                         # (B, 4H)
    s = g.node("Add", [xp, hw], f"{name}.xh")                            # (B, 4H)
    s = g.node("Add", [s, bh], f"{name}.pre")                            # (B, 4H)
    i_f, gg, o = g.node("Split", [s, g.ints([2 * hidden, hidden, hidden])], f"{name}.split", axis=-1,
                        outputs=("if", "g", "o"))
    i_f = g.node("Sigmoid", [i_f], f"{name}.if_act")                    # (B, 2H)
    i, f = g.node("Split", [i_f, g.ints([hidden, hidden])], f"{name}.if_split", axis=-1, outputs=("i", "f"))
    gg = g.node("Tanh", [gg], f"{name}.g_act")                           # (B, H)
    o = g.node("Sigmoid", [o], f"{name}.o_act")                          # (B, H)
    c_new = g.node("Add", [g.node("Mul", [f, c], f"{name}.fc"), g.node("Mul", [i, gg], f"{name}.ig")],
                   f"{name}.c_new")                                      # (B, H)
    h_new = g.node("Mul", [o, g.node("Tanh", [c_new], f"{name}.tanh_c")], f"{name}.h_new")  # (B, H)
    return h_new, c_new


def _primitive_layer(g, seq, h0_layer, c0_layer, params, prefix, layer, dirs, lname, wl):
    """One layer in primitive form: ``seq`` ``(T, B, I)`` → ``(T, B, D·H)``, ``h_n``/``c_n`` ``(D, B, H)``."""
    ys, hs, cs = [], [], []
    if dirs == 1:
        h0_dirs, c0_dirs = [h0_layer], [c0_layer]
    else:
        h0_dirs = list(g.node("Split", [h0_layer, g.ints([1, 1])], f"{lname}.h0", axis=0, outputs=("f", "b")))
        c0_dirs = list(g.node("Split", [c0_layer, g.ints([1, 1])], f"{lname}.c0", axis=0, outputs=("f", "b")))
    for d in range(dirs):
        dname, wd = f"{lname}.d{d}", f"{wl}.d{d}"
        w_ih, w_hh, b_ih, b_hh = primitive_layer_weights(params, prefix, layer, d == 1)
        hidden = w_hh.shape[1]
        xp = input_projection(g, seq, w_ih, b_ih, dname, wd)                # (T, B, 4H)
        wh, bh = g.weight(f"{wd}.Wh", w_hh.T), g.weight(f"{wd}.bh", b_hh)
        h_init = squeeze0(g, h0_dirs[d], f"{dname}.h_init")             # (B, H)
        c_init = squeeze0(g, c0_dirs[d], f"{dname}.c_init")             # (B, H)

        def cell(body, x_t, states, wh=wh, bh=bh, hidden=hidden, dname=dname):
            h_new, c_new = _lstm_cell(body, x_t, states[0], states[1], wh, bh, hidden, f"{dname}.body.cell")
            return [h_new, c_new], h_new

        (h_last, c_last), y = scan_recurrence(g, xp, [h_init, c_init], cell, name=f"{dname}.scan",
                                               reverse=d == 1, state_shapes=[["B", hidden], ["B", hidden]],
                                               xp_width=4 * hidden)
        ys.append(y)                                                     # (T, B, H)
        hs.append(unsqueeze0(g, h_last, f"{dname}.h_n"))
        cs.append(unsqueeze0(g, c_last, f"{dname}.c_n"))
    if dirs == 1:
        return ys[0], hs[0], cs[0]
    return (g.node("Concat", ys, f"{lname}.y", axis=-1), g.node("Concat", hs, f"{lname}.h_n", axis=0),
            g.node("Concat", cs, f"{lname}.c_n", axis=0))
