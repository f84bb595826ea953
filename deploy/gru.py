"""ONNX builders for the multi-layer (optionally bidirectional) GRU of ``refimpl/nn/gru.py`` (PyTorch ``nn.GRU``).

Equations (PyTorch, gate blocks ``r|z|n`` in ``weight_ih_l{k}`` ``(3H, I)``, ``weight_hh_l{k}`` ``(3H, H)``)::

    r = σ(x W_irᵀ + b_ir + h W_hrᵀ + b_hr)
    z = σ(x W_izᵀ + b_iz + h W_hzᵀ + b_hz)
    n = tanh(x W_inᵀ + b_in + r ⊙ (h W_hnᵀ + b_hn))
    h' = (1 − z) ⊙ n + z ⊙ h

The ONNX ``GRU`` operator computes the same with ``linear_before_reset = 1`` (the reset gate multiplies
``h W_hnᵀ + b_hn``), gates in the order ``z|r|h`` and the six bias blocks ``[Wb_z, Wb_r, Wb_h, Rb_z, Rb_r, Rb_h]``
kept apart (``spec/deploy.md`` §2.3). Layer ``k`` of a stack reads the top output of layer ``k − 1``; a
bidirectional layer feeds ``[forward | backward]`` ``(T, B, 2H)`` upwards.

Fused form (default for float32): one ``GRU`` node per layer, transposes at the batch-first boundary.
Primitive form (``g.primitive``, float64): ``MatMul`` of all input projections, then a ``Scan`` over time whose
body is the cell above written with ``MatMul``/``Split``/``Sigmoid``/``Tanh`` as ``h' = n + z ⊙ (h − n)``.
Quantised step (``gru_step(..., weights="int8" | "int4")``, onnxruntime only): both products of each layer as
``com.microsoft.MatMulNBits`` with block-quantised weights (``deploy.quantize``), the cell element-wise, written
``h' = n + z ⊙ (h − n)``.
Paired unrolled form (:func:`gru_pair_unrolled`, the portable pace graph): two one-layer GRUs over a fixed number
of steps, no ``Scan``, advanced together with block-diagonal weights (9 nodes per step for both).

Shape legend: B batch, T time, I input features, H hidden, L layers, D directions.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from deploy.graph import GraphBuilder
from deploy.quantize import WEIGHT_FORMATS, WeightMatmul
from deploy.recurrent import (GRU_PERM, check_layer_shapes, concat_layers,
                              input_projection, merge_directions,
                              onnx_layer_weights,
                              primitive_layer_weights, scan_recurrence,
                              split_layers, squeeze0, time_major,
                              unsqueeze0)

__all__ = ["gru", "gru_step", "gru_pair_unrolled", "gru_onnx_weights"]


def gru_onnx_weights(params: Mapping[str, np.ndarray], prefix: str, layer: int = 0,
                     bidirectional: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ONNX ``W (D, 3H, I)``, ``R (D, 3H, H)``, ``B (D, 6H)`` of GRU layer ``layer`` (gates z|r|h).

    Missing biases count as zeros. The reverse direction reads the ``*_reverse`` parameters.
    """
    w, r, b, _ = onnx_layer_weights(params, prefix, layer, 2 if bidirectional else 1, GRU_PERM)
    return w, r, b


def gru(g: GraphBuilder, x: str, h0: str, params: Mapping[str, np.ndarray], prefix: str, *, name: str,
        num_layers: int = 1, bidirectional: bool = False, wname: str | None = None) -> tuple[str, str]:
    """Append a GRU over a whole sequence.

    Parameters
    ----------
    g : GraphBuilder
    x : str
        Input ``(B, T, I)``, batch-first.
    h0 : str
        Initial state ``(L·D, B, H)`` (PyTorch layout; layer-major, forward direction first). Use
        :func:`deploy.recurrent.tiled_state` for a learned state, a graph input otherwise.
    params : dict
        ``{prefix}.weight_ih_l{k}[_reverse]`` ``(3H, I_k)``, ``weight_hh_l{k}`` ``(3H, H)``, ``bias_ih_l{k}``,
        ``bias_hh_l{k}`` ``(3H,)``, gate blocks ``r|z|n``.
    name : str
        Graph path (``"enc.gru"``): initializers ``{name}.l{k}.W`` etc.
    wname : str, optional
        Path of the initializers (default ``name``), shared between calls with the same ``wname``.
    num_layers, bidirectional
        As ``nn.GRU``.

    Returns
    -------
    y : str
        ``(B, T, D·H)``: top layer's outputs, forward direction first.
    h_n : str
        ``(L·D, B, H)``: final state of every layer and direction.
    """
    dirs = 2 if bidirectional else 1
    seq = time_major(g, x, f"{name}.x_tm")                              # (T, B, I)
    h0s = split_layers(g, h0, num_layers, dirs, f"{name}.h0")           # L × (D, B, H)
    hns = []
    for k in range(num_layers):
        check_layer_shapes(params, prefix, k, 3, dirs)
        lname, wl = f"{name}.l{k}", f"{wname or name}.l{k}"
        if g.primitive:
            seq, hn = _primitive_layer(g, seq, h0s[k], params, prefix, k, dirs, lname, wl)
        else:
            w, r, b, hidden = onnx_layer_weights(params, prefix, k, dirs, GRU_PERM)
            y, hn = g.node("GRU", [seq, g.weight(f"{wl}.W", w), g.weight(f"{wl}.R", r),
                                   g.weight(f"{wl}.B", b), "", h0s[k]],
                           lname, outputs=("Y", "Y_h"), hidden_size=hidden, linear_before_reset=1,
                           direction="bidirectional" if bidirectional else "forward")  # (T, D, B, H), (D, B, H)
            seq = merge_directions(g, y, dirs, f"{lname}.y")           # (T, B, D·H)
        hns.append(hn)
    y = time_major(g, seq, f"{name}.y")                                 # (B, T, D·H)
    return y, concat_layers(g, hns, f"{name}.h_n")                     # (L·D, B, H)


def gru_step(g: GraphBuilder, x_t: str, h: str, params: Mapping[str, np.ndarray], prefix: str, *, name: str,
             num_layers: int = 1, wname: str | None = None, weights: str = "float32",
             block_size: int = 32, accuracy_level: int = 4) -> tuple[str, str]:
    """Append one GRU time step (unidirectional stack, as ``refimpl.nn.gru.gru_step_forward``).

    Parameters
    ----------
    g : GraphBuilder
    x_t : str
        Input ``(B, I)``.
    h : str
        State ``(L, B, H)``.
    params, prefix, num_layers
        As :func:`gru` (only the forward-direction parameters are read).
    name : str
        Graph path of the nodes.
    wname : str, optional
        Path of the initializers (default ``name``).
    weights : {"float32", "int8", "int4"}, optional
        ``"float32"`` (default): float weights; a fused ``GRU`` node per layer, or the primitive cell when
        ``g.primitive``. ``"int8"`` / ``"int4"``: the quantised step below (float32 graphs without
        ``primitive`` only).
    block_size : int, optional
        Quantisation block length along the input axis of each product (a power of two ≥ 16; default 32, as
        ``deploy.qtg_compact``). Larger blocks mean fewer scales and a faster kernel (2×1000 step, batch 1, one
        thread: about 0.47 ms at 32, 0.42 ms at 128 in our measurement; 0.30 / 0.28 ms with two threads) at a
        small accuracy cost. Ignored for float32.
    accuracy_level : {4, 1}, optional
        Compute type of the int8/int4 products (:class:`deploy.quantize.WeightMatmul`): 4 (default) int8
        activations and integer dot products, 1 float32 compute with the dequantised weights. Ignored for
        float32.

    Returns
    -------
    y : str
        ``(B, H)``: top layer's new state.
    h_new : str
        ``(L, B, H)``.

    Raises
    ------
    ValueError
        ``weights`` not in :data:`deploy.quantize.WEIGHT_FORMATS`; int8/int4 asked of a primitive or float64
        graph (``MatMulNBits`` is an onnxruntime contrib operator with float32/float16 kernels only, which the
        primitive form, meant for the standard operator set and the reference evaluator, does not use); with
        int8/int4 a bad ``block_size`` or ``accuracy_level``; mis-shaped parameters.

    Notes
    -----
    Quantised step, layer ``k`` (input ``x`` = ``x_t`` for ``k = 0``, else layer ``k − 1``'s new state;
    ``h`` = ``h[k]``), PyTorch gate blocks ``r|z|n`` kept as they are (no reordering)::

        g_i = x W_ihᵀ + b_ih          (B, 3H)   MatMulNBits, weights quant(W_ihᵀ) (I, 3H), bias b_ih
        g_h = h W_hhᵀ + b_hh          (B, 3H)   MatMulNBits, weights quant(W_hhᵀ) (H, 3H), bias b_hh
        [r | z] = σ(g_i[:2H] + g_h[:2H])
        n  = tanh(g_i[2H:] + r ⊙ g_h[2H:])
        h' = n + z ⊙ (h − n)          (= (1 − z) ⊙ n + z ⊙ h)

    ``quant`` is :func:`deploy.quantize.quantize_blocks` (symmetric, blocks of ``block_size`` along the input
    axis, one float32 scale per block and output column). 13 nodes per layer: 2 ``MatMulNBits`` (the biases are
    the kernel's own bias input), 3 ``Split``, ``Add``, ``Sigmoid``, ``Mul``, ``Add``, ``Tanh``, ``Sub``, ``Mul``,
    ``Add``; plus a ``Squeeze`` for ``y`` and, when ``L > 1``, one ``Split`` of ``h`` and one ``Concat`` of the new
    states. The layer states stay ``(1, B, ·)`` (``MatMulNBits`` takes any leading axes), so no
    Squeeze/Unsqueeze per layer. The two
    products are kept apart rather than fused into one ``[x | h] @ [[W_ir W_iz W_in 0], [W_hr W_hz 0 W_hn]]``
    product, which would save 2 nodes but read a third more weight bytes. Initializers ``{wname}.l{k}.ih.Wq8``
    (``.Wq4``), ``.ih.scales``, ``.ih.b`` and the same for ``.hh``. The model needs onnxruntime (domain
    ``com.microsoft``); the ONNX checker and shape inference accept it (``deploy.validate.validate_model``).
    Accuracy: ``y`` equals ``refimpl.nn.gru.gru_step_forward`` run with the dequantised weights to float32
    rounding at ``accuracy_level = 1``. Against the float weights (default ``accuracy_level = 4``, QuaterNet
    size 2×1000, PyTorch-style init, random inputs) ``max |h_new − float|`` is about 4e-3 for int8 and 5e-2 for
    int4 (``benchmarks/bench_onnx.py``, ``spec/deploy.md`` §9).
    """
    if weights not in WEIGHT_FORMATS:
        raise ValueError(f"weights: expected one of {WEIGHT_FORMATS}, got {weights!r}")
    if weights != "float32":
        if g.primitive or np.dtype(g.dtype) != np.float32:
            raise ValueError(f"weights: {weights!r} needs a float32 graph with primitive=False (MatMulNBits, an "
                             f"onnxruntime contrib operator), got dtype {np.dtype(g.dtype)}, "
                             f"primitive={g.primitive}")
        return _quantized_step(g, x_t, h, params, prefix, name, num_layers, wname or name,
                               WeightMatmul(g, weights, block_size=block_size, accuracy_level=accuracy_level))
    hs = split_layers(g, h, num_layers, 1, f"{name}.h")                 # L × (1, B, H)
    hn = []
    if g.primitive:
        inp = x_t                                                        # (B, I)
        for k in range(num_layers):
            check_layer_shapes(params, prefix, k, 3, 1)
            lname, wl = f"{name}.l{k}", f"{wname or name}.l{k}"
            w_ih, w_hh, b_ih, b_hh = primitive_layer_weights(params, prefix, k, False)
            xp = input_projection(g, inp, w_ih, b_ih, lname, wl)           # (B, 3H)
            wh, bh = g.weight(f"{wl}.Wh", w_hh.T), g.weight(f"{wl}.bh", b_hh)
            h_k = squeeze0(g, hs[k], f"{lname}.h")                      # (B, H)
            inp = _gru_cell(g, xp, h_k, wh, bh, w_hh.shape[1], f"{lname}.cell")  # (B, H)
            hn.append(unsqueeze0(g, inp, f"{lname}.h_new"))             # (1, B, H)
        return inp, concat_layers(g, hn, f"{name}.h_new")
    inp = g.node("Unsqueeze", [x_t, g.ints([0])], f"{name}.x_seq")       # (1, B, I)
    for k in range(num_layers):
        check_layer_shapes(params, prefix, k, 3, 1)
        lname, wl = f"{name}.l{k}", f"{wname or name}.l{k}"
        w, r, b, hidden = onnx_layer_weights(params, prefix, k, 1, GRU_PERM)
        (_, inp) = g.node("GRU", [inp, g.weight(f"{wl}.W", w), g.weight(f"{wl}.R", r),
                                  g.weight(f"{wl}.B", b), "", hs[k]],
                          lname, outputs=("", "Y_h"), hidden_size=hidden, linear_before_reset=1)  # (1, B, H)
        hn.append(inp)
    y = squeeze0(g, inp, f"{name}.y")                                   # (B, H)
    return y, concat_layers(g, hn, f"{name}.h_new")                    # (L, B, H)


def _block_diagonal(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``[[a, 0], [0, b]]``."""
    out = np.zeros((a.shape[0] + b.shape[0], a.shape[1] + b.shape[1]), dtype=np.result_type(a, b))
    out[:a.shape[0], :a.shape[1]], out[a.shape[0]:, a.shape[1]:] = a, b
    return out


def _pair_weights(params: Mapping[str, np.ndarray], prefixes: tuple[str, str]) -> tuple[list, int]:
    """Per gate (r, z, n) of two one-layer GRUs ``a``, ``b``: ``(W_x (2I, 2H), W_h (2H, 2H), b_x (2H,),
    b_h (2H,))``, the matrices block-diagonal, the biases ``[a | b]``; and H."""
    layers = []
    for prefix in prefixes:
        check_layer_shapes(params, prefix, 0, 3, 1)
        layers.append([np.asarray(a) for a in primitive_layer_weights(params, prefix, 0, False)])
    H = layers[0][1].shape[1]
    if layers[1][1].shape[1] != H or layers[0][0].shape[1] != layers[1][0].shape[1]:
        raise ValueError(f"params: the two GRUs {prefixes} differ in hidden or input size")
    gates = []
    for k in range(3):
        blk = [[a[k * H:(k + 1) * H] for a in layer] for layer in layers]   # per GRU: w_ih, w_hh, b_ih, b_hh
        gates.append((_block_diagonal(blk[0][0].T, blk[1][0].T), _block_diagonal(blk[0][1].T, blk[1][1].T),
                      np.concatenate([blk[0][2], blk[1][2]]), np.concatenate([blk[0][3], blk[1][3]])))
    return gates, H


def _pair_cell(g: GraphBuilder, s: str, c: tuple[str, str, str], w_h: list[str], b_hn: str, name: str) -> str:
    """One step of :func:`gru_pair_unrolled`: 9 nodes, ``s (B, 2H)`` → ``s' (B, 2H)``."""
    r = g.node("Sigmoid", [g.node("Gemm", [s, w_h[0], c[0]], f"{name}.ar")], f"{name}.r")
    z = g.node("Sigmoid", [g.node("Gemm", [s, w_h[1], c[1]], f"{name}.az")], f"{name}.z")
    hn = g.node("Gemm", [s, w_h[2], b_hn], f"{name}.hn")
    n = g.node("Tanh", [g.node("Add", [c[2], g.node("Mul", [r, hn], f"{name}.rhn")], f"{name}.n_pre")], f"{name}.n")
    return g.node("Add", [n, g.node("Mul", [z, g.node("Sub", [s, n], f"{name}.s_n")], f"{name}.z_d")], f"{name}.s")


def gru_pair_unrolled(g: GraphBuilder, xs: tuple[str, str], hs: tuple[str, str], params: Mapping[str, np.ndarray],
                      prefixes: tuple[str, str], *, name: str, steps: int) -> tuple[str, str, str]:
    """Append two independent one-layer GRUs ``a`` and ``b`` (a bidirectional layer's directions, each on its own
    sequence) over ``steps`` time steps, unrolled (no ``Scan``, no ``GRU`` node) and advanced together.

    The state is ``s = [h_a | h_b]`` ``(B, 2H)`` and the weights are block-diagonal, so one node per stage of the
    cell serves both GRUs (at a small hidden size the per-node cost of a runtime dominates). Before the loop, one
    ``Gemm`` per gate over all steps, ``c_r[t] = x[t] W_irᵀ + b_ir + b_hr``, ``c_z[t]`` likewise,
    ``c_n[t] = x[t] W_inᵀ + b_in`` (``x[t] = [x_a[t] | x_b[t]]``), each ``Split`` into the steps. Per step 9
    nodes (onnxruntime fuses each ``Gemm`` + ``Sigmoid`` into one kernel)::

        r = σ(Gemm(s, W_hr, c_r[t]));  z = σ(Gemm(s, W_hz, c_z[t]));  n = tanh(c_n[t] + r ⊙ Gemm(s, W_hn, b_hn))
        s' = n + z ⊙ (s − n)

    Parameters
    ----------
    xs : (str, str)
        The inputs ``(B, K, I)`` of ``a`` and ``b``, ``K = steps``.
    hs : (str, str)
        Their initial states ``(1, B, H)``.
    params, prefixes
        Layer 0 of ``prefixes[0]`` and of ``prefixes[1]`` (as :func:`gru`; forward weights each).

    Returns
    -------
    y : str
        ``(K·B, 2H)``: the states ``[h_a | h_b]`` after each step, time-major (row ``t·B + b``).
    h_a, h_b : str
        ``(1, B, H)``: the last states.
    """
    if isinstance(steps, bool) or not isinstance(steps, (int, np.integer)) or steps < 1:
        raise ValueError(f"steps: expected a positive integer, got {steps!r}")
    K = int(steps)
    gates, H = _pair_weights(params, prefixes)
    x = g.node("Concat", [g.node("Transpose", [x_], f"{name}.x{i}.tm", perm=[1, 0, 2]) for i, x_ in enumerate(xs)],
               f"{name}.x", axis=2)                                                     # (K, B, 2I)
    x = g.node("Reshape", [x, g.ints([-1, gates[0][0].shape[0]])], f"{name}.x.rows")     # (K·B, 2I)
    c = []
    for k, gate in enumerate("rzn"):
        w_x, _, b_x, b_h = gates[k]
        proj = g.node("Gemm", [x, g.weight(f"{name}.{gate}.Wx", w_x),
                               g.weight(f"{name}.{gate}.bx", b_x + b_h if gate != "n" else b_x)],
                      f"{name}.c{gate}")                                                # (K·B, 2H)
        c.append(g.node("Split", [proj], f"{name}.c{gate}.t", axis=0, outputs=tuple(str(t) for t in range(K)))
                 if K > 1 else (proj,))                                                 # K × (B, 2H)
    w_h = [g.weight(f"{name}.{gate}.Wh", gates[k][1]) for k, gate in enumerate("rzn")]
    b_hn = g.weight(f"{name}.n.bh", gates[2][3])
    s = squeeze0(g, g.node("Concat", list(hs), f"{name}.h0", axis=2), f"{name}.s0")       # (B, 2H)
    ys = []
    for t in range(K):
        s = _pair_cell(g, s, (c[0][t], c[1][t], c[2][t]), w_h, b_hn, f"{name}.t{t}")     # (B, 2H)
        ys.append(s)
    y = ys[0] if K == 1 else g.node("Concat", ys, f"{name}.y", axis=0)                   # (K·B, 2H)
    h_a, h_b = g.node("Split", [s, g.ints([H, H])], f"{name}.h_n", axis=1, outputs=("a", "b"))  # (B, H) each
    return y, unsqueeze0(g, h_a, f"{name}.h_a"), unsqueeze0(g, h_b, f"{name}.h_b")


# --------------------------------------------------------------------------------------- quantised step
def _quantized_step(g: GraphBuilder, x_t: str, h: str, params, prefix: str, name: str, num_layers: int,
                    wname: str, W: WeightMatmul) -> tuple[str, str]:
    """The int8/int4 step of :func:`gru_step` (its Notes); layer states kept ``(1, B, H)``."""
    hs = split_layers(g, h, num_layers, 1, f"{name}.h")                 # L × (1, B, H)
    inp, hn = x_t, []                                                    # (B, I), then (1, B, H)
    for k in range(num_layers):
        check_layer_shapes(params, prefix, k, 3, 1)
        lname, wl = f"{name}.l{k}", f"{wname}.l{k}"
        w_ih, w_hh, b_ih, b_hh = primitive_layer_weights(params, prefix, k, False)
        gi = W.matmul(inp, np.asarray(w_ih).T, f"{wl}.ih", f"{lname}.gi", bias=np.asarray(b_ih))  # (·, B, 3H)
        gh = W.matmul(hs[k], np.asarray(w_hh).T, f"{wl}.hh", f"{lname}.gh", bias=np.asarray(b_hh))  # (1, B, 3H)
        inp = _gates(g, gi, gh, hs[k], w_hh.shape[1], f"{lname}.cell")   # (1, B, H)
        hn.append(inp)
    y = squeeze0(g, inp, f"{name}.y")                                   # (B, H)
    return y, concat_layers(g, hn, f"{name}.h_new")                    # (L, B, H)


def _gates(g: GraphBuilder, gi: str, gh: str, h: str, hidden: int, name: str) -> str:
    """The cell of the quantised step from whole products ``gi = x W_ihᵀ + b_ih``, ``gh = h W_hhᵀ + b_hh``."""
    sizes = g.ints([2 * hidden, hidden])
    i_rz, i_n = g.node("Split", [gi, sizes], f"{name}.gi", axis=-1, outputs=("rz", "n"))  # (·, B, 2H), (·, B, H)
    h_rz, h_n = g.node("Split", [gh, sizes], f"{name}.gh", axis=-1, outputs=("rz", "n"))  # (1, B, 2H), (1, B, H)
    return gru_gates(g, i_rz, i_n, h_rz, h_n, h, hidden, name)          # (1, B, H)


def gru_gates(g: GraphBuilder, i_rz: str, i_n: str, h_rz: str | None, h_n: str, h: str | None, hidden: int,
               name: str) -> str:
    """The GRU cell from its split pre-activations (gate order r|z|n); shared by every primitive-operator form.

    ``i_rz (·, 2H)``, ``i_n (·, H)``: the input side ``x W_iᵀ + b_i``; ``h_rz``, ``h_n``: the recurrent side
    ``h W_hᵀ + b_h``. ``h_rz = None`` means 0 and ``h_n`` may be a constant ``(H,)`` (``b_hn``) for the state 0,
    which ``h = None`` stands for::

        r, z = σ(i_rz + h_rz);   n = tanh(i_n + r ⊙ h_n);   h' = n + z ⊙ (h − n)   (n − z ⊙ n for h = 0)

    ``n + z ⊙ (h − n)`` equals ``(1 − z) ⊙ n + z ⊙ h`` and is what ``refimpl.nn.gru`` computes.
    """
    rz_pre = i_rz if h_rz is None else g.node("Add", [i_rz, h_rz], f"{name}.rz_pre")   # (·, 2H)
    rz = g.node("Sigmoid", [rz_pre], f"{name}.rz")
    r, z = g.node("Split", [rz, g.ints([hidden, hidden])], f"{name}.gates", axis=-1, outputs=("r", "z"))
    n = g.node("Tanh", [g.node("Add", [i_n, g.node("Mul", [r, h_n], f"{name}.rhn")], f"{name}.n_pre")],
               f"{name}.n")                                              # (·, H)
    if h is None:
        return g.node("Sub", [n, g.node("Mul", [z, n], f"{name}.z_n")], f"{name}.h_new")
    d = g.node("Mul", [z, g.node("Sub", [h, n], f"{name}.h_n")], f"{name}.z_d")  # (·, H)
    return g.node("Add", [n, d], f"{name}.h_new")                        # (·, H)


# --------------------------------------------------------------------------------------- primitive form
def _gru_cell(g: GraphBuilder, xp: str, h: str, wh: str, bh: str, hidden: int, name: str) -> str:
    """One GRU cell from primitives; ``xp = x W_iᵀ + b_i`` ``(B, 3H)`` (blocks r|z|n), ``h`` ``(B, H)``."""
    hw = g.node("MatMul", [h, wh], f"{name}.hw")                         # (B, 3H)
    hp = g.node("Add", [hw, bh], f"{name}.hp")                           # (B, 3H)
    sizes = g.ints([2 * hidden, hidden])
    x_rz, x_n = g.node("Split", [xp, sizes], f"{name}.xs", axis=-1, outputs=("rz", "n"))  # (B, 2H), (B, H)
    h_rz, h_n = g.node("Split", [hp, sizes], f"{name}.hs", axis=-1, outputs=("rz", "n"))  # (B, 2H), (B, H)
    return gru_gates(g, x_rz, x_n, h_rz, h_n, h, hidden, name)          # (B, H)


def _primitive_layer(g, seq, h0_layer, params, prefix, layer, dirs, lname, wl):
    """One layer (both directions) in primitive form: ``seq`` ``(T, B, I)`` → ``(T, B, D·H)``, ``(D, B, H)``."""
    ys, hs = [], []
    h0_dirs = [h0_layer] if dirs == 1 else list(
        g.node("Split", [h0_layer, g.ints([1, 1])], f"{lname}.h0", axis=0, outputs=("f", "b")))
    for d in range(dirs):
        dname, wd = f"{lname}.d{d}", f"{wl}.d{d}"
        w_ih, w_hh, b_ih, b_hh = primitive_layer_weights(params, prefix, layer, d == 1)
        hidden = w_hh.shape[1]
        xp = input_projection(g, seq, w_ih, b_ih, dname, wd)                # (T, B, 3H)
        wh, bh = g.weight(f"{wd}.Wh", w_hh.T), g.weight(f"{wd}.bh", b_hh)
        h_init = squeeze0(g, h0_dirs[d], f"{dname}.h_init")             # (B, H)

        def cell(body, x_t, states, wh=wh, bh=bh, hidden=hidden, dname=dname):
            h_new = _gru_cell(body, x_t, states[0], wh, bh, hidden, f"{dname}.body.cell")
            return [h_new], h_new

        (h_last,), y = scan_recurrence(g, xp, [h_init], cell, name=f"{dname}.scan", reverse=d == 1,
                                        state_shapes=[["B", hidden]], xp_width=3 * hidden)
        ys.append(y)                                                     # (T, B, H)
        hs.append(unsqueeze0(g, h_last, f"{dname}.h_n"))               # (1, B, H)
    y = ys[0] if dirs == 1 else g.node("Concat", ys, f"{lname}.y", axis=-1)     # (T, B, D·H)
    hn = hs[0] if dirs == 1 else g.node("Concat", hs, f"{lname}.h_n", axis=0)   # (D, B, H)
    return y, hn


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# gru_gates.
