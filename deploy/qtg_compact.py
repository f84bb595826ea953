"""Deployment variant of the QTG rollout: rearranged weights, fewer nodes, optionally int8 weights that fit in L2.

The plain export (``deploy/qtg.py``) translates ``refimpl.models.qtg.step`` node for node. This variant computes
the same function (``spec/deploy.md`` §5.4) with the algebra of ``refimpl.models.qtg.prepare_inference``:

* the GRU input ``x_t = [z_t − z_{t−1} | e1 − z_t | e2 − e1]`` with ``W_ih = [W1 | W2 | W3]`` gives
  ``W_ih x_t = (W1 − W2) z_t + c_t`` with ``c_t = k − W1 z_{t−1}``, ``k = W2 e1 + W3 (e2 − e1) + b_ih +
  [b_hr, b_hz, 0]`` computed once per transition; so each step multiplies ``z_t`` by ``(W1 − W2)`` and ``−W1``
  (2·Z·3H weights instead of 3Z·3H) and needs no Sub/Concat;
* the GRU cell is written with ``MatMul`` and element-wise operators (the ONNX ``GRU`` operator cannot take the
  per-sample term ``c_t``, nor int8 weights); ``h' = n + u ⊙ (h − n)`` equals ``(1 − u) n + u h``;
* the velocity bias folds into the first decoder layer: ``D_0(z + W_v s + b_v) = W_d0 (z + W_v s) + (b_d0 +
  W_d0 b_v)``, so ``z + W_v s`` is one ``Gemm`` with ``C = z``.

``weights="int8"`` (or ``"int4"``) stores every weight matrix block-wise quantised (:func:`quantize_blocks`) and
multiplies with onnxruntime's ``com.microsoft.MatMulNBits`` kernel (``accuracy_level = 4``: int8 activations,
integer dot products): 0.64 MB of weights for the default sizes instead of 2.6 MB, so they fit in a 1 MiB L2
cache. This makes the variant onnxruntime-specific. The standard ``DequantizeLinear`` → ``MatMul`` form is not
used: onnxruntime 1.32 fuses it into ``MatMulNBits`` only when the int8 initializer has one consumer, so with the
weights shared by the unrolled steps it dequantises every matrix at every step, and inside a ``Loop`` body session
creation fails (``spec/deploy.md`` §5.4). ``weights="float32"`` gives the same graph with float ``Gemm`` s. The
accuracy cost of int8/int4 is measured by ``benchmarks/bench_onnx.py`` (``spec/deploy.md`` §9).

Shape legend: B batch, T frames, P pose size, Z latent size, H GRU hidden size, L GRU layers.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import onnx

from refimpl.models.qtg import QTGConfig

from deploy.graph import OPSET, GraphBuilder
from deploy.metadata import EXPORTER_VERSION
from deploy.qtg import _check_normalization, _check_params, _io, _metadata, _pose_in, _pose_out
from deploy.quantize import WEIGHT_FORMATS, WeightMatmul, quantize_blocks  # noqa: F401 (re-exported)

__all__ = ["export_qtg_rollout_compact"]


def _prepare(params, config: QTGConfig):
    """Weights of the rearranged step (module docstring), float64, matrices laid out ``(in, out)``."""
    Z, H = config.latent_size, config.gru_hidden
    p = {k: np.asarray(v, dtype=np.float64) for k, v in params.items()}
    w_ih = p["gru.weight_ih_l0"]                                          # (3H, 3Z), blocks r|z|n
    w1, w2, w3 = w_ih[:, :Z], w_ih[:, Z:2 * Z], w_ih[:, 2 * Z:]
    b_hh = p["gru.bias_hh_l0"]
    k_bias = p["gru.bias_ih_l0"] + np.concatenate([b_hh[:2 * H], np.zeros(H)])
    dec0_w = p["dec.0.weight"] if config.decoder_sizes else None
    return {"A": (w1 - w2).T, "W1neg": -w1.T, "W2": w2.T, "W3": w3.T, "k_bias": k_bias,
            "b_hn": np.concatenate([np.zeros(2 * H), b_hh[2 * H:]]), "p": p, "dec0_w": dec0_w}


def _gru_cell(g, gi, gh, h, hidden, name):
    """``r, u = σ(gi_rz + gh_rz)``; ``n = tanh(gi_n + r ⊙ gh_n)``; ``h' = n + u ⊙ (h − n)``; all ``(B, ·)``."""
    sizes = g.ints([2 * hidden, hidden])
    i_rz, i_n = g.node("Split", [gi, sizes], f"{name}.gi", axis=-1, outputs=("rz", "n"))
    h_rz, h_n = g.node("Split", [gh, sizes], f"{name}.gh", axis=-1, outputs=("rz", "n"))
    rz = g.node("Sigmoid", [g.node("Add", [i_rz, h_rz], f"{name}.rz_pre")], f"{name}.rz")     # (B, 2H)
    r, u = g.node("Split", [rz, g.ints([hidden, hidden])], f"{name}.gates", axis=-1, outputs=("r", "u"))
    n = g.node("Tanh", [g.node("Add", [i_n, g.node("Mul", [r, h_n], f"{name}.r_hn")], f"{name}.n_pre")],
               f"{name}.n")                                                                    # (B, H)
    d = g.node("Mul", [u, g.node("Sub", [h, n], f"{name}.h_n")], f"{name}.u_d")
    return g.node("Add", [n, d], f"{name}.h_new")                                             # (B, H)


def _mlp(g, W, x, p, prefix, n_layers, slope, last_linear, name, first_bias=None):
    for i in range(n_layers):
        b = p[f"{prefix}.{i}.bias"] if (i > 0 or first_bias is None) else first_bias
        x = W.matmul(x, p[f"{prefix}.{i}.weight"].T, f"{prefix}.{i}", f"{name}.{i}", bias=b)
        if not (last_linear and i == n_layers - 1):
            x = g.node("LeakyRelu", [x], f"{name}.{i}.act", alpha=float(slope))
    return x


def export_qtg_rollout_compact(params: Mapping[str, np.ndarray], config: QTGConfig = QTGConfig(), *,
                               T: int | None = None, weights: str = "int8", opset: int = OPSET,
                               normalization=None, normalize_in_graph: bool = True, skeleton=None,
                               frame_rate: float = 30.0, metadata: Mapping | None = None) -> onnx.ModelProto:
    """The compact (deployment) rollout model: same I/O contract as ``deploy.qtg.export_qtg_rollout``.

    Parameters
    ----------
    weights : {"int8", "float32"}
        Storage of the per-step weight matrices (module docstring).
    Others as ``deploy.qtg.export_qtg_rollout``; the graph is float32 and unrolled over ``T`` steps.

    Returns
    -------
    onnx.ModelProto
        Inputs ``past (B, 2, P)``, ``target (B, 2, P)``; output ``poses (B, T, P)``.
    """
    _check_params(params, config)
    if weights not in WEIGHT_FORMATS:
        raise ValueError(f"weights: expected one of {WEIGHT_FORMATS}, got {weights!r}")
    if config.gru_layers != 1:
        raise ValueError(f"config.gru_layers: the compact variant supports 1 GRU layer, got {config.gru_layers}")
    stats = _check_normalization(normalization, config)
    norm = stats if normalize_in_graph else None
    T = config.transition_length if T is None else T
    if not isinstance(T, (int, np.integer)) or T < 1:
        raise ValueError(f"T: expected a positive integer number of frames, got {T!r}")
    T = int(T)
    P, Z, H = config.pose_size, config.latent_size, config.gru_hidden
    slope = config.negative_slope
    prep = _prepare(params, config)
    p = prep["p"]
    n_enc, n_dec = len(config.encoder_sizes), len(config.decoder_sizes) + 1
    g = GraphBuilder("qtg_rollout_compact", dtype=np.float32, opset=opset)
    W = WeightMatmul(g, weights)
    past = _pose_in(g, g.input("past", ["B", 2, P]), norm, name="past_norm")
    target = _pose_in(g, g.input("target", ["B", 2, P]), norm, name="target_norm")

    # once per transition: encodings of p_{-1}, g1, g2; the constant k and c_0 = k - W1 z_{-1}
    p_m1, pose = g.node("Split", [past, g.ints([1, 1])], "init.past", axis=1, outputs=("m1", "0"))
    ctx = g.node("Concat", [p_m1, target], "init.ctx", axis=1)                      # (B, 3, P)
    ctx = g.node("Reshape", [ctx, g.ints([-1, P])], "init.ctx2")                    # (3B, P) rows b-major
    lat = _mlp(g, W, ctx, p, "enc", n_enc, slope, False, "init.enc")               # (3B, Z)
    lat = g.node("Reshape", [lat, g.ints([-1, 3, Z])], "init.lat")                  # (B, 3, Z)
    z_m1, e1, e2 = g.node("Split", [lat, g.ints([1, 1, 1])], "init.split", axis=1, outputs=("zm1", "e1", "e2"))
    z_m1, e1, e2 = (g.node("Squeeze", [v, g.ints([1])], f"init.{k}") for v, k in ((z_m1, "z_m1"), (e1, "e1_2d"),
                                                                                   (e2, "e2_2d")))
    e21 = g.node("Sub", [e2, e1], "init.e21")                                       # (B, Z)
    k_const = g.node("Add", [W.matmul(e1, prep["W2"], "gru.W2", "init.k1"),
                             W.matmul(e21, prep["W3"], "gru.W3", "init.k2", bias=prep["k_bias"])],
                     "init.k")                                                       # (B, 3H)
    c = W.matmul(z_m1, prep["W1neg"], "gru.W1neg", "init.c0", bias=k_const)        # (B, 3H)
    pose = g.node("Squeeze", [pose, g.ints([1])], "init.pose")                      # (B, P)
    h = g.node("Expand", [g.weight("init.h0", np.zeros((1, H))),
                          g.node("Concat", [g.node("Shape", [past], "init.B", start=0, end=1), g.ints([H])],
                                 "init.h_shape", axis=0)], "init.h")                 # (B, H)
    dec0_bias = (p["dec.0.bias"] + p["dec.0.weight"] @ p["vel.bias"]) if config.decoder_sizes else None
    poses = []
    for t in range(T):
        s = f"t{t:03d}"
        z = _mlp(g, W, pose, p, "enc", n_enc, slope, False, f"{s}.enc")             # (B, Z)
        gi = W.matmul(z, prep["A"], "gru.A", f"{s}.gi", bias=c)                     # (B, 3H)
        if t < T - 1:
            c = W.matmul(z, prep["W1neg"], "gru.W1neg", f"{s}.c", bias=k_const)     # (B, 3H)
        gh = W.matmul(h, p["gru.weight_hh_l0"].T, "gru.Whh", f"{s}.gh", bias=prep["b_hn"])  # (B, 3H)
        h = _gru_cell(g, gi, gh, h, H, f"{s}.cell")                                  # (B, H)
        if config.decoder_sizes:
            a = W.matmul(h, p["vel.weight"].T, "vel", f"{s}.zv", bias=z)             # z + W_v s, (B, Z)
            pose = _mlp(g, W, a, p, "dec", n_dec, slope, True, f"{s}.dec", first_bias=dec0_bias)  # (B, P)
        else:
            a = W.matmul(h, p["vel.weight"].T, "vel", f"{s}.v", bias=p["vel.bias"])
            a = g.node("Add", [z, a], f"{s}.zv")
            pose = _mlp(g, W, a, p, "dec", n_dec, slope, True, f"{s}.dec")
        poses.append(pose)
    flat = poses[0] if T == 1 else g.node("Concat", poses, "poses_flat", axis=-1)  # (B, T·P)
    out = g.node("Reshape", [flat, g.ints([0, T, P])], "poses_n")                   # (B, T, P)
    g.output(_pose_out(g, out, norm, name="poses_raw"), "poses", ["B", T, P])
    io = {"inputs": _io(("past", ["B", 2, P], "p_{-1}, p_0: the two poses before the transition"),
                        ("target", ["B", 2, P], "g1 = p_{T+1}, g2 = p_{T+2}: the two poses after it")),
          "outputs": _io(("poses", ["B", T, P], "p_1 ... p_T, the generated transition"))}
    meta = _metadata(config, "rollout", io, stats, norm is not None, skeleton, frame_rate, g,
                     f"compact.{weights}", metadata, T=T)
    return g.model(metadata=meta, doc_string=f"QTG rollout, compact variant, {weights} weights, {T} frames",
                   producer_version=EXPORTER_VERSION)
