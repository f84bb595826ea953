"""Deployment variant of the QTG rollout: rearranged weights, fewer nodes, optionally int8 or int4 weights.

The plain export (``deploy/qtg.py``) translates ``refimpl.models.qtg.step`` node for node. This variant computes
the same function (``spec/deploy.md`` §5.4) with the algebra of
``refimpl.models.qtg_fast_inference.prepare_inference`` (``spec/qtg.md`` §6), arranged for onnxruntime, where at batch 1 every node costs a dispatch on top of the
weight bytes it reads (measured on the development VM: ~0.55 µs per element-wise node, ~1.4 µs per
``MatMulNBits`` plus ~0.044 µs per 1000 int8 weights):

* the GRU input ``x_t = [z_t − z_{t−1} | e1 − z_t | e2 − e1]`` with ``W_ih = [W1 | W2 | W3]`` gives
  ``W_ih x_t + b = −W1 z_{t−1} + (W1 − W2) z_t + k`` with ``k = (W2 − W3) e1 + W3 e2 + b_ih + [b_hr, b_hz, 0]``
  computed once per transition; each step multiplies the pair ``[z_{t−1} | z_t]`` ``(B, 2Z)`` by the stacked
  ``[−W1ᵀ ; (W1 − W2)ᵀ]`` ``(2Z, 3H)`` — one product, 2·Z·3H weights instead of 3Z·3H, ``k`` its per-sample bias;
* one product of each GRU layer's new state ``s`` gives everything that state feeds: ``[W_hhᵀ | W_vᵀ]`` for the
  top layer (the next step's recurrent term and this step's velocity ``v_t``; bias ``[0, 0, b_hn | 0]``),
  ``[W_hh,lᵀ | W_ih,l+1ᵀ]`` for a lower layer (its next recurrent term and the input term of the layer above);
  ``b_hr, b_hz`` ride in the input biases. At step 0 the state is 0, so the recurrent term is the constant
  ``[0, 0, b_hn]`` and the cell simplifies to ``s' = n − u ⊙ n``; the last step multiplies by ``W_vᵀ`` only;
* the velocity bias folds into the first decoder layer, ``D_0(z + W_v s + b_v) = W_d0 (z + W_v s) + (b_d0 +
  W_d0 b_v)``; the GRU cell is ``r, u = σ(·)``, ``n = tanh(i_n + r ⊙ h_n)``, ``s' = n + u ⊙ (s − n)``;
* the init encodes ``p_{−1}, p_0, g1, g2`` in one batched pass (rows ``4B``), so step 0 needs no encoder pass and
  its pair ``[z_{−1} | z_0]`` is a slice of the init's output.

Nodes per middle step (default sizes: two encoder layers, one GRU layer, one decoder hidden layer): 6 matrix
products (encoder 2, pair 1, state 1, decoder 2) and 17 others — Concat (the pair), Split ×3 (gate inputs, state
product, ``r | u``), Add ×5 (``+ k``, ``r, u`` pre-activation, ``n`` pre-activation, ``s'``, ``z + v``), Mul ×2,
Sub, Sigmoid, Tanh, LeakyRelu ×3 — 23 in all (22 with float32 weights, where ``+ k`` is the ``C`` input of the
``Gemm``; onnxruntime further fuses ``Gemm`` + ``LeakyRelu``), against 8 products and 17 others before this
arrangement. The weights read per step are unchanged: 538,112 for the default sizes, ``macs_per_frame − 3ZH``.
Not adopted, because slower here: fusing the decoder's output layer with the next step's first encoder layer
(``[W_dᵀ | W_dᵀ W_e0ᵀ]`` saves a product but reads 42 k more weights per step).

The ONNX ``GRU`` operator is not used: it cannot take the per-sample term ``k`` nor quantised weights.
``weights="int8"`` (or ``"int4"``) stores every weight matrix block-wise quantised
(:func:`deploy.quantize.quantize_blocks`) and multiplies with onnxruntime's ``com.microsoft.MatMulNBits`` kernel (``accuracy_level = 4``: int8 activations,
integer dot products; constant biases are the kernel's own bias input, a per-sample one — ``k``, ``z`` — an
``Add``). A step then reads 0.61 MB of weights and scales (int4: 0.34 MB) instead of 2.16 MB of float32 for
the default sizes, about the size of a per-core L2 cache (512 KiB on the development VM). This makes the variant
onnxruntime-specific. The standard ``DequantizeLinear`` → ``MatMul`` form is not used:
onnxruntime 1.32 fuses it into ``MatMulNBits`` only when the int8 initializer has one consumer, so with the
weights shared by the unrolled steps it dequantises every matrix at every step, and inside a ``Loop`` body
session creation fails (``spec/deploy.md`` §5.4). ``weights="float32"`` gives the same graph with float
``Gemm`` s. The accuracy cost of int8/int4 is measured by ``benchmarks/bench_onnx.py`` (``spec/deploy.md`` §9).

Shape legend: B batch, T frames, P pose size, Z latent size, H GRU hidden size, L GRU layers.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import onnx

from refimpl.models.qtg import QTGConfig

from deploy.graph import OPSET, GraphBuilder
from deploy.gru import gru_gates
from deploy.metadata import EXPORTER_VERSION, io_entries
from deploy.join import inertialize_joins
from deploy.models.qtg import (check_normalization, check_params, join_blend, join_entry, pose_in, pose_out,
                               qtg_metadata)
from deploy.quantize import WEIGHT_FORMATS, WeightMatmul

__all__ = ["export_qtg_rollout_compact"]


def _prepare(params, config: QTGConfig) -> dict:
    """Weights of the rearranged step (module docstring), float64, matrices laid out ``(in, out)``.

    Returns a dict with ``pair (2Z, 3H)``, ``target (2Z, 3H)`` and ``target_b (3H,)``; per GRU layer ``l``
    ``state[l]`` (the fused product of its new state: ``(H, 3H + Z)`` for the top layer, ``(H, 6H)`` below),
    ``state_b[l]``, ``last[l]`` and ``last_b[l]`` (the last step's part: ``W_vᵀ`` resp. ``W_ih,l+1ᵀ``);
    ``hn_b[l] (H,)``; ``dec0_b`` (``b_d0 + W_d0 b_v``) and the float64 parameters ``p``.
    """
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers
    p = {k: np.asarray(v, dtype=np.float64) for k, v in params.items()}

    def in_bias(layer):  # b_ih + [b_hr, b_hz, 0]
        return p[f"gru.bias_ih_l{layer}"] + np.concatenate([p[f"gru.bias_hh_l{layer}"][:2 * H], np.zeros(H)])

    def hh_bias(layer):  # [0, 0, b_hn]
        return np.concatenate([np.zeros(2 * H), p[f"gru.bias_hh_l{layer}"][2 * H:]])

    w_ih = p["gru.weight_ih_l0"]                                          # (3H, 3Z), blocks r|z|n
    w1, w2, w3 = w_ih[:, :Z], w_ih[:, Z:2 * Z], w_ih[:, 2 * Z:]
    prep = {"pair": np.concatenate([-w1.T, (w1 - w2).T], axis=0),        # acts on [z_{t-1} | z_t]
            "target": np.concatenate([(w2 - w3).T, w3.T], axis=0),       # acts on [e1 | e2]
            "target_b": in_bias(0), "state": [], "state_b": [], "last": [], "last_b": [],
            "hn_b": [p[f"gru.bias_hh_l{k}"][2 * H:] for k in range(L)],
            "dec0_b": p["dec.0.bias"] + p["dec.0.weight"] @ p["vel.bias"], "p": p}
    for k in range(L):
        if k < L - 1:
            nxt, nxt_b = p[f"gru.weight_ih_l{k + 1}"].T, in_bias(k + 1)     # (H, 3H): input term of layer k+1
        else:
            nxt, nxt_b = p["vel.weight"].T, np.zeros(Z)                    # (H, Z): velocity (b_v in dec0_b)
        prep["state"].append(np.concatenate([p[f"gru.weight_hh_l{k}"].T, nxt], axis=1))
        prep["state_b"].append(np.concatenate([hh_bias(k), nxt_b]))
        prep["last"].append(nxt)
        prep["last_b"].append(nxt_b)
    return prep


def _mlp(g, W, x, p, prefix, n_layers, slope, last_linear, name, first_bias=None):
    """Dense layers ``{prefix}.i`` (``(in, out)`` weights ``p[...].T``), LeakyReLU after each but a linear last."""
    for i in range(n_layers):
        b = p[f"{prefix}.{i}.bias"] if (i > 0 or first_bias is None) else first_bias
        x = W.matmul(x, p[f"{prefix}.{i}.weight"].T, f"{prefix}.{i}", f"{name}.{i}", bias=b)
        if not (last_linear and i == n_layers - 1):
            x = g.node("LeakyRelu", [x], f"{name}.{i}.act", alpha=float(slope))
    return x


def export_qtg_rollout_compact(params: Mapping[str, np.ndarray], config: QTGConfig = QTGConfig(), *,
                               T: int | None = None, weights: str = "int8", opset: int = OPSET,
                               normalization=None, normalize_in_graph: bool = True, skeleton=None,
                               frame_rate: float = 30.0, metadata: Mapping | None = None, join: str = "none",
                               join_blend_frames: int | None = None) -> onnx.ModelProto:
    """The compact (deployment) rollout model: same I/O contract as ``deploy.qtg.export_qtg_rollout``.

    Parameters
    ----------
    weights : {"int8", "int4", "float32"}
        Storage of the weight matrices (module docstring): block-quantised (blocks of 32 along the input axis)
        for ``MatMulNBits``, or float ``Gemm``.
    Others as ``deploy.qtg.export_qtg_rollout``; the graph is float32 and unrolled over ``T`` steps. Any number
    of GRU layers, encoder and decoder layers.

    Returns
    -------
    onnx.ModelProto
        Inputs ``past (B, 2, P)``, ``target (B, 2, P)``; output ``poses (B, T, P)``.

    Raises
    ------
    ValueError
        Bad ``params`` / ``config`` / ``normalization`` (as ``export_qtg_rollout``), ``weights`` not one of
        :data:`deploy.quantize.WEIGHT_FORMATS`, ``T`` not a positive integer.
    """
    check_params(params, config)
    if weights not in WEIGHT_FORMATS:
        raise ValueError(f"weights: expected one of {WEIGHT_FORMATS}, got {weights!r}")
    stats = check_normalization(normalization, config)
    norm = stats if normalize_in_graph else None
    T = config.transition_length if T is None else T
    if not isinstance(T, (int, np.integer)) or T < 1:
        raise ValueError(f"T: expected a positive integer number of frames, got {T!r}")
    T = int(T)
    blend = join_blend(join, join_blend_frames, T, stats, norm)
    P, Z, H, L = config.pose_size, config.latent_size, config.gru_hidden, config.gru_layers
    slope = config.negative_slope
    prep = _prepare(params, config)
    p = prep["p"]
    n_enc, n_dec = len(config.encoder_sizes), len(config.decoder_sizes) + 1
    g = GraphBuilder("qtg_rollout_compact", dtype=np.float32, opset=opset)
    W = WeightMatmul(g, weights)
    past, target = g.input("past", ["B", 2, P]), g.input("target", ["B", 2, P])

    # once per transition: E(p_{-1}), E(p_0), E(g1), E(g2) in one pass; k = (W2 - W3) e1 + W3 e2 + b
    ctx = pose_in(g, g.node("Concat", [past, target], "init.ctx", axis=1), norm, name="init.ctx_norm")  # (B, 4, P)
    ctx = g.node("Reshape", [ctx, g.ints([-1, P])], "init.rows")                    # (4B, P) rows b-major
    lat = _mlp(g, W, ctx, p, "enc", n_enc, slope, False, "init.enc")               # (4B, Z)
    lat = g.node("Reshape", [lat, g.ints([-1, 4 * Z])], "init.lat")                 # (B, 4Z) [z_-1|z_0|e1|e2]
    pair, e12 = g.node("Split", [lat, g.ints([2 * Z, 2 * Z])], "init.split", axis=-1, outputs=("pair", "e12"))
    z = g.node("Slice", [pair, g.ints([Z]), g.ints([2 * Z]), g.ints([1])], "init.z0")     # (B, Z)
    k = W.matmul(e12, prep["target"], "gru.target", "init.k", bias=prep["target_b"])     # (B, 3H)

    states = [None] * L      # s_t per GRU layer; None: the zero state before step 0
    recurrent = [None] * L   # (W_hh s_t)_rz and (W_hh s_t + b_hn)_n per layer, from the previous step's product
    poses = []
    for t in range(T):
        s, last = f"t{t:03d}", t == T - 1
        if t > 0:
            z_prev = z
            z = _mlp(g, W, poses[-1], p, "enc", n_enc, slope, False, f"{s}.enc")    # z_t = E(p_t), (B, Z)
            pair = g.node("Concat", [z_prev, z], f"{s}.pair", axis=-1)              # (B, 2Z)
        gi = W.matmul(pair, prep["pair"], "gru.pair", f"{s}.gi", bias=k)            # W_ih x_t + b, (B, 3H)
        i_rz, i_n = g.node("Split", [gi, g.ints([2 * H, H])], f"{s}.gi_split", axis=-1, outputs=("rz", "n"))
        for layer in range(L):
            c, top = f"{s}.l{layer}", layer == L - 1
            h_rz, h_n = recurrent[layer] or (None, g.weight(f"gru.l{layer}.b_hn", prep["hn_b"][layer]))
            states[layer] = gru_gates(g, i_rz, i_n, h_rz, h_n, states[layer], H, f"{c}.cell")  # (B, H)
            # one product of the new state: the next step's recurrent term (none after the last step) and the
            # term the state feeds now, v_t (top layer) or the input term of layer + 1
            if last:
                wname, w, b, rec = f"gru.l{layer}.last", prep["last"][layer], prep["last_b"][layer], ()
            else:
                wname, w, b, rec = f"gru.l{layer}.state", prep["state"][layer], prep["state_b"][layer], (2 * H, H)
            if top and last:
                a = W.matmul(states[layer], w, wname, f"{c}.zv", bias=z)            # z_t + W_v s, (B, Z)
                continue
            y = W.matmul(states[layer], w, wname, f"{c}.y", bias=b)                 # (B, [3H +] Z or 3H)
            sizes, names = rec + ((Z,) if top else (2 * H, H)), ("h_rz", "h_n")[:len(rec)]
            parts = g.node("Split", [y, g.ints(sizes)], f"{c}.split", axis=-1,
                           outputs=names + (("v",) if top else ("rz", "n")))
            if rec:
                recurrent[layer] = parts[:2]
            if top:
                a = g.node("Add", [z, parts[-1]], f"{s}.zv")                        # z_t + W_v s, (B, Z)
            else:
                i_rz, i_n = parts[-2:]                                              # input term of layer + 1
        pose = _mlp(g, W, a, p, "dec", n_dec, slope, True, f"{s}.dec", first_bias=prep["dec0_b"])  # (B, P)
        poses.append(pose)
    flat = poses[0] if T == 1 else g.node("Concat", poses, "poses_flat", axis=-1)  # (B, T·P)
    out = g.node("Reshape", [flat, g.ints([0, T, P])], "poses_n")                   # (B, T, P)
    out = pose_out(g, out, norm, name="poses_raw")
    if join == "inertialize":
        out = inertialize_joins(g, past, out, target, T, P, frame_rate, blend, name="join")
    g.output(out, "poses", ["B", T, P])
    io = {"inputs": io_entries(("past", ["B", 2, P], "p_{-1}, p_0: the two poses before the transition"),
                        ("target", ["B", 2, P], "g1 = p_{T+1}, g2 = p_{T+2}: the two poses after it")),
          "outputs": io_entries(("poses", ["B", T, P], "p_1 ... p_T, the generated transition"))}
    meta = qtg_metadata(config, "rollout", io, stats, norm is not None, skeleton, frame_rate, g,
                     f"compact.{weights}", join_entry(metadata, join, T, frame_rate, blend, in_graph=True), T=T)
    return g.model(metadata=meta, doc_string=f"QTG rollout, compact variant, {weights} weights, {T} frames",
                   producer_version=EXPORTER_VERSION)
