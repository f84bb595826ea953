"""Pieces shared by the GRU and LSTM builders: gate-block reordering, layouts, states, primitive recurrences.

Layouts live here (``spec/deploy.md`` §2): ``refimpl`` is batch-first ``(B, T, F)``; the ONNX GRU/LSTM operators
are time-major ``(T, B, F)`` with ``layout = 0`` (onnxruntime's CPU kernels reject ``layout = 1``), so the
builders transpose around them. PyTorch stacks gates ``r|z|n`` (GRU) and ``i|f|g|o`` (LSTM); ONNX wants
``z|r|h`` and ``i|o|f|c``: :func:`reorder_gate_blocks` with ``GRU_PERM`` / ``LSTM_PERM``.

The *primitive* form (``GraphBuilder.primitive``) writes the recurrence with ``MatMul``/``Add``/``Split``/
``Sigmoid``/``Tanh`` inside a ``Scan`` over time, which onnxruntime runs in float64 too; the input projections
of all time steps are one ``MatMul`` before the ``Scan``. Gate blocks stay in PyTorch order there.

Shape legend: T time, B batch, I input features, H hidden, L layers, D directions (1 or 2), G gates (3 or 4).
"""
from __future__ import annotations

from typing import Callable, Mapping, Sequence

import numpy as np

from deploy.graph import GraphBuilder, get_param

__all__ = ["GRU_PERM", "LSTM_PERM", "reorder_gate_blocks", "tiled_state"]

GRU_PERM = (1, 0, 2)
"""PyTorch GRU blocks r|z|n taken in the order z, r, n = ONNX z|r|h."""

LSTM_PERM = (0, 3, 1, 2)
"""PyTorch LSTM blocks i|f|g|o taken in the order i, o, f, g = ONNX i|o|f|c."""


def reorder_gate_blocks(a: np.ndarray, perm: Sequence[int]) -> np.ndarray:
    """Split ``a`` ``(G·H, ...)`` into G row blocks of H rows and concatenate them in the order ``perm``."""
    a = np.asarray(a)
    blocks = np.split(a, len(perm), axis=0)                              # G × (H, ...)
    return np.concatenate([blocks[p] for p in perm], axis=0)             # (G·H, ...)


def tiled_state(g: GraphBuilder, state: np.ndarray, like: str, *, name: str, batch_axis: int = 0) -> str:
    """A learned initial state repeated over the batch: ``(L, H)`` or ``(L, 1, H)`` → ``(L, B, H)``.

    ``B`` is read at run time from axis ``batch_axis`` of the tensor ``like``, so the batch stays symbolic.
    """
    s = np.asarray(state)
    if s.ndim == 2:
        s = s[:, None, :]                                                # (L, 1, H)
    if s.ndim != 3 or s.shape[1] != 1:
        raise ValueError(f"state: expected shape (L, H) or (L, 1, H), got {np.shape(state)}")
    const = g.weight(f"{name}.value", s)                                 # (L, 1, H)
    b = g.node("Shape", [like], f"{name}.batch", start=batch_axis, end=batch_axis + 1)  # (1,) = [B]
    shape = g.node("Concat", [g.ints([1]), b, g.ints([1])], f"{name}.shape", axis=0)   # [1, B, 1]
    return g.node("Expand", [const, shape], name)                        # (L, B, H)


# ---------------------------------------------------------------------------------------------- layouts
def time_major(g: GraphBuilder, x: str, name: str) -> str:
    return g.node("Transpose", [x], name, perm=[1, 0, 2])                # (B, T, F) <-> (T, B, F)


def split_layers(g: GraphBuilder, h: str, num_layers: int, per_layer: int, name: str) -> list[str]:
    """``(L·D, B, H)`` → L tensors ``(D, B, H)``."""
    if num_layers == 1:
        return [h]
    outs = g.node("Split", [h, g.ints([per_layer] * num_layers)], name, axis=0,
                  outputs=tuple(f"l{k}" for k in range(num_layers)))
    return list(outs)


def concat_layers(g: GraphBuilder, hs: list[str], name: str) -> str:
    return hs[0] if len(hs) == 1 else g.node("Concat", hs, name, axis=0)  # (L·D, B, H)


def merge_directions(g: GraphBuilder, y: str, num_directions: int, name: str) -> str:
    """ONNX ``Y`` ``(T, D, B, H)`` → ``(T, B, D·H)`` (forward direction first)."""
    if num_directions == 1:
        return g.node("Squeeze", [y, g.ints([1])], name)                 # (T, B, H)
    yt = g.node("Transpose", [y], f"{name}.tr", perm=[0, 2, 1, 3])       # (T, B, D, H)
    return g.node("Reshape", [yt, g.ints([0, 0, -1])], name)             # (T, B, D·H)


# ---------------------------------------------------------------------------------- fused ONNX weights
def onnx_layer_weights(params: Mapping[str, np.ndarray], prefix: str, layer: int, directions: int,
                        perm: Sequence[int]) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """ONNX ``W (D, G·H, I)``, ``R (D, G·H, H)``, ``B (D, 2·G·H)`` of one layer from PyTorch parameters."""
    ws, rs, bs = [], [], []
    for d in range(directions):
        sfx = f"_l{layer}" + ("_reverse" if d == 1 else "")
        w_ih = get_param(params, prefix, "weight_ih" + sfx)             # (G·H, I)
        w_hh = get_param(params, prefix, "weight_hh" + sfx)             # (G·H, H)
        gh = w_hh.shape[0]
        b_ih = _bias(params, prefix, "bias_ih" + sfx, gh)               # (G·H,)
        b_hh = _bias(params, prefix, "bias_hh" + sfx, gh)               # (G·H,)
        ws.append(reorder_gate_blocks(w_ih, perm))
        rs.append(reorder_gate_blocks(w_hh, perm))
        bs.append(np.concatenate([reorder_gate_blocks(b_ih, perm), reorder_gate_blocks(b_hh, perm)]))
    hidden = rs[0].shape[1]
    return np.stack(ws), np.stack(rs), np.stack(bs), hidden


def _bias(params, prefix, key, size):
    full = f"{prefix}.{key}" if prefix else key
    if full not in params:
        return np.zeros(size)
    return np.asarray(params[full])


def check_layer_shapes(params, prefix, layer, gates, directions, input_size=None):
    for d in range(directions):
        sfx = f"_l{layer}" + ("_reverse" if d == 1 else "")
        w_ih = get_param(params, prefix, "weight_ih" + sfx)
        w_hh = get_param(params, prefix, "weight_hh" + sfx)
        h = w_hh.shape[1] if w_hh.ndim == 2 else -1
        if w_hh.shape != (gates * h, h) or w_ih.ndim != 2 or w_ih.shape[0] != gates * h:
            raise ValueError(f"params[{prefix!r}]: layer {layer}: expected weight_hh ({gates}H, H) and weight_ih "
                             f"({gates}H, I), got {w_hh.shape} and {w_ih.shape}")


# ------------------------------------------------------------------------------------ primitive forms
def primitive_layer_weights(params, prefix, layer, reverse):
    sfx = f"_l{layer}" + ("_reverse" if reverse else "")
    w_ih = get_param(params, prefix, "weight_ih" + sfx)                 # (G·H, I)
    w_hh = get_param(params, prefix, "weight_hh" + sfx)                 # (G·H, H)
    b_ih = _bias(params, prefix, "bias_ih" + sfx, w_hh.shape[0])
    b_hh = _bias(params, prefix, "bias_hh" + sfx, w_hh.shape[0])
    return w_ih, w_hh, b_ih, b_hh


def scan_recurrence(g: GraphBuilder, xp: str, states: list[str], cell: Callable, *, name: str,
                     reverse: bool, state_shapes: list[list], xp_width: int | str) -> tuple[list[str], str]:
    """Run ``cell`` over time with ``Scan``: ``xp`` ``(T, B, G·H)`` precomputed input projections.

    ``cell(body, xp_t, states) -> (new_states, y_t)`` builds the body. Returns the final states and the stacked
    ``y`` ``(T, B, H)`` (in time order also when ``reverse``).
    """
    body = g.subgraph(f"{name}.body")
    s_in = [body.input(f"{name}.body.s{k}_in", shp) for k, shp in enumerate(state_shapes)]
    x_t = body.input(f"{name}.body.xp_t", ["B", xp_width])
    new_states, y_t = cell(body, x_t, s_in)
    for k, (s, shp) in enumerate(zip(new_states, state_shapes)):
        body.output(s, f"{name}.body.s{k}_out", shp)
    body.output(y_t, f"{name}.body.y_t", state_shapes[0])
    # reverse direction: flip time explicitly (Slice with step -1) around a forward Scan; the reference
    # evaluator implements forward Scans only
    if reverse:
        xp = _flip_time(g, xp, f"{name}.xp_rev")
    outs = g.node("Scan", states + [xp], name, outputs=tuple(f"s{k}" for k in range(len(states))) + ("Y",),
                  body=body.graph(), num_scan_inputs=1)
    if reverse:
        return list(outs[:-1]), _flip_time(g, outs[-1], f"{name}.Y_rev")
    return list(outs[:-1]), outs[-1]


def _flip_time(g: GraphBuilder, x: str, name: str) -> str:
    """Reverse axis 0 (time) of ``x``."""
    int64_min = -(2 ** 63)
    return g.node("Slice", [x, g.ints([-1]), g.ints([int64_min]), g.ints([0]), g.ints([-1])], name)


def input_projection(g: GraphBuilder, x: str, w_ih: np.ndarray, b_ih: np.ndarray, name: str,
                      wname: str) -> str:
    w = g.weight(f"{wname}.Wx", w_ih.T)                                  # (I, G·H)
    b = g.weight(f"{wname}.bx", b_ih)                                    # (G·H,)
    xw = g.node("MatMul", [x, w], f"{name}.xw")                          # (..., G·H)
    return g.node("Add", [xw, b], f"{name}.xp")                          # (..., G·H)


def squeeze0(g, x, name):
    return g.node("Squeeze", [x, g.ints([0])], name)                     # (1, B, H) -> (B, H)


def unsqueeze0(g, x, name):
    return g.node("Unsqueeze", [x, g.ints([0])], name)                   # (B, H) -> (1, B, H)


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# check_layer_shapes, concat_layers, input_projection, merge_directions, onnx_layer_weights, primitive_layer_weights,
# scan_recurrence, split_layers, squeeze0, time_major, unsqueeze0.
