"""ONNX export of QuaterNet (``refimpl/models/quaternet.py``, ``refimpl/models/quaternet_cnn.py``; spec/deploy.md §11).

Its entries of the exporter table are in ``deploy/models/quaternet_io.py``. The exporter translates the NumPy
functions one to one:

=============  ==============================================================  ===================================
model          inputs → outputs                                                translates
=============  ==============================================================  ===================================
``init``       ``x (B, F)`` → ``hidden (L, B, H)``                              ``quaternet.init_state`` (learned
                                                                               ``h0`` tiled over the batch)
``step``       ``x (B, F)``, ``hidden (L, B, H)`` → ``y (B, G)``,                ``quaternet.step``
               ``hidden_next (L, B, H)``
``predict``    ``prefix (B, P, F)`` → ``frames (B, k, G)``                       ``quaternet.predict`` (P free, k
                                                                               fixed at export)
``window``     ``window (B, W, 4J)`` → ``pose_next (B, 4J)``                     ``quaternet_cnn.step`` (W free; the
                                                                               last R frames matter)
=============  ==============================================================  ===================================

One recurrent step::

    g_t     = [x_t[:G] | controls block(x_t[G:])]         Slice; Gemm, LeakyRelu, Gemm, LeakyRelu (C > 0 only)
    s_{t+1} = GRU(g_t, s_t)                               one ONNX GRU node per layer (linear_before_reset = 1)
    o       = fc(top)  = [Δ (4J) | τ (O)]                 Gemm, Split
    q̂       = normalize(Δ_j ⊗ x_t,j) (velocity) or normalize(Δ_j)   quat_mul (Gather, Mul, MatMul), quat_normalize
    y       = [q̂ | τ]                                     Concat

The predictor runs the GRU over the whole prefix (one ``GRU`` node per layer, state from the tiled ``h0``), the
head on its last output, then ``k − 1`` unrolled steps feeding each prediction back (shared initializers). The
window model is the convolution stack (``deploy.conv1d.conv1d_causal``, causal zero padding, activation, skip
additions) and the head on the last frame. The quaternion normalisation and the velocity QMul are in the
graphs: inputs and outputs are the network's own frames (unit quaternions, joint-major).

Shape legend: B batch, P prefix frames, k predicted frames, W window frames, J joints, F = 4J + O + C input
features, G = 4J + O output features, H hidden size, L GRU layers.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import onnx

from refimpl.models import quaternet as rnn
from refimpl.models import quaternet_cnn as cnn

from deploy.activations import activation, leaky_relu
from deploy.conv1d import conv1d_causal
from deploy.graph import OPSET, GraphBuilder
from deploy.gru import gru, gru_step
from deploy.linear import linear
from deploy.metadata import EXPORTER_VERSION, build_metadata, io_entries, skeleton_metadata
from deploy.models.quaternet_dq import dq_mul
from deploy.quat import dq_normalize, quat_mul, quat_normalize
from deploy.recurrent import tiled_state

__all__ = ["QUATERNET_PAPER", "quaternet_representation", "export_quaternet_init", "export_quaternet_step",
           "export_quaternet_predict", "export_quaternet_cnn_window"]

QUATERNET_PAPER = ("Pavllo, Feichtenhofer, Auli, Grangier: Modeling Human Motion with Quaternion-Based Neural "
                   "Networks. IJCV 128, 855-872 (2020)")

_INT64_MAX = 2 ** 63 - 1


def quaternet_representation(num_joints: int, num_outputs: int = 0, num_controls: int = 0,
                             representation: str = "quaternion") -> dict:
    """Layout of a QuaterNet frame: ``4J`` joint quaternions (or ``8J`` current dual quaternions for
    ``representation="dual_quaternion"``, spec/quaternet.md §9), then ``O`` translations, then ``C`` controls."""
    if representation == "dual_quaternion":
        R, name = 8 * num_joints, "quaternet_dq_frame"
        fields = [{"name": "joint_dual_quaternions", "start": 0, "size": R, "joints": int(num_joints),
                   "dual_quaternion": "(q_r | q_d), each (w, x, y, z), Hamilton; current (relative to the root "
                                      "joint), unit: |q_r| = 1, <q_r, q_d> = 0; translation t = 2 q_d q_r*"}]
    else:
        R, name = 4 * num_joints, "quaternet_frame"
        fields = [{"name": "joint_rotations", "start": 0, "size": R, "joints": int(num_joints),
                   "quaternion": "(w, x, y, z), Hamilton, local to the parent joint, unit length"}]
    if num_outputs:
        fields.append({"name": "translations", "start": R, "size": int(num_outputs)})
    if num_controls:
        fields.append({"name": "controls", "start": R + num_outputs, "size": int(num_controls),
                       "meaning": "inputs only"})
    return {"name": name, "size": R + num_outputs + num_controls, "fields": fields}


#: Length units of the skeletons of QuaterNet's prediction datasets (``metadata["dataset"]``).
SKELETON_UNITS = {"cmu": "CMU ASF length units (1 unit = 5.6444 cm = 0.056444 m)", "h36m": "mm"}


def _dual(config) -> bool:
    return getattr(config, "representation", "quaternion") == "dual_quaternion"


def frame_words(config) -> str:
    """What one frame's joint block is, for the ``io`` meanings."""
    if _dual(config):
        return "per joint the unit current dual quaternion (q_r | q_d), 8J values"
    return "per joint the unit local quaternion (w, x, y, z), 4J values"


def quaternet_transforms(config, role: str) -> tuple[dict, dict]:
    """``(input_transform, output_transform)`` of a QuaterNet model (spec/deploy.md §11.1)."""
    from deploy.models.quaternet_sign import RULE

    in_graph = role == "predict" and not _dual(config)
    where = "applied inside this graph to the prefix" if in_graph else "apply it to the prefix before feeding it"
    steps = [f"sign rule ({where}): " + r for r in RULE]
    if _dual(config):
        steps = steps + [
            "then current dual quaternions per joint from the canonical local rotations q_j and skeleton.offsets o_j: "
            "C_root = (q_root | 0); C_j = C_parent ⊗ (q_j | 0.5 (0, o_j) ⊗ q_j) (dual-quaternion product "
            "(a_r|a_d) ⊗ (b_r|b_d) = (a_r b_r | a_r b_d + a_d b_r)); the root translation is not part of the frame",
            "then continuity over time: negate C_j (all 8 values) when its real part has a negative dot product with "
            "the previous frame's real part"]
    inp = {"summary": "QuaterNet reads the quaternions' numbers: map each prefix to the canonical representative "
                      "first (the NumPy predictor's canonical_prefix)" + ("; this graph does it itself (feed any "
                      "signs)" if in_graph else ""),
           "in_graph": in_graph, "steps": steps,
           "applies_to": "the prefix (frames fed before the first prediction); fed-back predictions are already "
                         "continuous"}
    if _dual(config):
        out = {"summary": "outputs are unit current dual quaternions (Eq. 13 in the graph); local rotations: "
                          "q_root = real part of C_root, q_j = conj(real(C_parent)) ⊗ real(C_j), each divided by "
                          "its norm (Eq. 12)", "steps": []}
    else:
        out = {"summary": "outputs are unit local quaternions (w, x, y, z) per joint, joint-major (normalised in "
                          "the graph); nothing to undo", "steps": []}
    return inp, out


def _metadata(g, name, role, config, io, skeleton, frame_rate, metadata, variant="float"):
    rep = quaternet_representation(config.num_joints, getattr(config, "num_outputs", 0),
                                   getattr(config, "num_controls", 0),
                                   getattr(config, "representation", "quaternion"))
    inp, out = quaternet_transforms(config, role)
    sk = skeleton_metadata(skeleton)
    if sk is not None and "units" not in sk:
        sk["units"] = SKELETON_UNITS.get((metadata or {}).get("dataset"), "the dataset's length units")
    return build_metadata(g, name=name, role=role, config=config.to_dict(), io=io, representation=rep,
                          normalization=None, skeleton=sk, frame_rate=frame_rate,
                          source_paper=QUATERNET_PAPER, variant=variant, extra=metadata,
                          input_transform=inp, output_transform=out)


def _builder(name, dtype, opset, primitive):
    return GraphBuilder(name, dtype=dtype, opset=opset, primitive=primitive)


def _slice(g, x, start, stop, axis, name):
    return g.node("Slice", [x, g.ints([start]), g.ints([stop]), g.ints([axis])], name)


# ------------------------------------------------------------------------------------------ recurrent
def _check_rnn(params, config):
    if not isinstance(config, rnn.QuaterNetConfig):
        raise ValueError(f"config: expected a QuaterNetConfig, got {type(config).__name__}")
    rnn.check_params(params, config)


def _gru_input(g, x, params, config, *, name):
    """``g = [x[..., :G] | controls block(x[..., G:])]`` over any leading axes."""
    G = config.output_size
    if config.num_controls == 0:
        return x
    s = config.negative_slope
    c = _slice(g, x, G, _INT64_MAX, -1, f"{name}.controls")                      # (..., C)
    a = leaky_relu(g, linear(g, c, params, "fc1", name=f"{name}.fc1", wname="fc1"), name=f"{name}.act1", alpha=s)
    a = leaky_relu(g, linear(g, a, params, "fc2", name=f"{name}.fc2", wname="fc2"), name=f"{name}.act2", alpha=s)
    head = _slice(g, x, 0, G, -1, f"{name}.frame")                               # (..., G)
    return g.node("Concat", [head, a], f"{name}.gru_input", axis=-1)             # (..., I)


def _head(g, top, x, params, config, *, name):
    """``y (B, G)`` from the top GRU output ``top (B, H)`` and the fed frame ``x (B, F)`` (``rnn.head_forward``):
    per joint block of width D, ``normalize(Δ ⊗ q_in)`` (velocity) or ``normalize(Δ)``; for dual quaternions
    (D = 8, spec/quaternet.md §9) the product is the dual-quaternion one and the normalisation Eq. 13."""
    J, R = config.num_joints, config.rotation_size
    dual = getattr(config, "representation", "quaternion") == "dual_quaternion"
    D, mul, norm = (8, dq_mul, dq_normalize) if dual else (4, quat_mul, quat_normalize)
    o = linear(g, top, params, "fc", name=f"{name}.fc", wname="fc", rank2=True)   # (B, G)
    delta = o if config.num_outputs == 0 else _slice(g, o, 0, R, -1, f"{name}.delta")  # (B, DJ)
    dj = g.node("Reshape", [delta, g.ints([0, J, D])], f"{name}.delta_j")        # (B, J, D)
    if config.velocity:
        q_in = x if config.input_size == R else _slice(g, x, 0, R, -1, f"{name}.q_in_flat")
        q_in = g.node("Reshape", [q_in, g.ints([0, J, D])], f"{name}.q_in")      # (B, J, D)
        dj = mul(g, dj, q_in, name=f"{name}.{'dqmul' if dual else 'qmul'}")      # (B, J, D)
    q = norm(g, dj, name=f"{name}.{'dqnorm' if dual else 'qnorm'}", eps=config.eps)  # (B, J, D)
    q = g.node("Reshape", [q, g.ints([0, R])], f"{name}.q")                      # (B, DJ)
    if config.num_outputs == 0:
        return q
    tau = _slice(g, o, R, _INT64_MAX, -1, f"{name}.tau")                          # (B, O)
    return g.node("Concat", [q, tau], f"{name}.y", axis=-1)                      # (B, G)


def _step(g, x, hidden, params, config, *, name):
    gi = _gru_input(g, x, params, config, name=f"{name}.in")                     # (B, I)
    top, h_new = gru_step(g, gi, hidden, params, "rnn", name=f"{name}.rnn", wname="rnn",
                          num_layers=config.num_layers)                          # (B, H), (L, B, H)
    return _head(g, top, x, params, config, name=f"{name}.head"), h_new


def export_quaternet_init(params: Mapping[str, np.ndarray], config: rnn.QuaterNetConfig, *, dtype=np.float32,
                          opset: int = OPSET, primitive: bool | None = None, skeleton=None,
                          frame_rate: float = 25.0, metadata: Mapping | None = None,
                          name: str = "quaternet") -> onnx.ModelProto:
    """The ``init`` model: the learned initial state ``h0`` tiled to the batch of ``x (B, F)``
    (``refimpl.models.quaternet.init_state``)."""
    _check_rnn(params, config)
    F, L, H = config.input_size, config.num_layers, config.hidden_size
    g = _builder(f"{name}_init", dtype, opset, primitive)
    x = g.input("x", ["B", F])
    g.output(tiled_state(g, params["h0"], x, name="init.h0"), "hidden", [L, "B", H])
    io = {"inputs": io_entries(("x", ["B", F], "any frame of the batch (only its batch size is read)")),
          "outputs": io_entries(("hidden", [L, "B", H], "the learned initial GRU state; feed to step"))}
    meta = _metadata(g, name, "init", config, io, skeleton, frame_rate, metadata)
    return g.model(metadata=meta, doc_string="QuaterNet init: learned h0 tiled over the batch",
                   producer_version=EXPORTER_VERSION)


def export_quaternet_step(params: Mapping[str, np.ndarray], config: rnn.QuaterNetConfig, *, dtype=np.float32,
                          opset: int = OPSET, primitive: bool | None = None, skeleton=None,
                          frame_rate: float = 25.0, metadata: Mapping | None = None,
                          name: str = "quaternet") -> onnx.ModelProto:
    """The ``step`` model: one frame in, the prediction of the next out, state in → state out
    (``refimpl.models.quaternet.step``; velocity QMul and quaternion normalisation in the graph).

    Returns
    -------
    onnx.ModelProto
        Inputs ``x (B, F)`` (ground truth, or the previous ``y`` with the frame's controls appended), ``hidden
        (L, B, H)``; outputs ``y (B, G)``, ``hidden_next (L, B, H)``.
    """
    _check_rnn(params, config)
    F, G, L, H = config.input_size, config.output_size, config.num_layers, config.hidden_size
    g = _builder(f"{name}_step", dtype, opset, primitive)
    x = g.input("x", ["B", F])
    hidden = g.input("hidden", [L, "B", H])
    y, h_new = _step(g, x, hidden, params, config, name="step")
    g.output(y, "y", ["B", G])
    g.output(h_new, "hidden_next", [L, "B", H])
    io = {"inputs": io_entries(("x", ["B", F], f"frame t: {frame_words(config)} (representation), then "
                                "translations (O) and controls (C) when the config has them; the prefix's frames "
                                "canonicalised (input_transform), then the fed-back y"),
                               ("hidden", [L, "B", H], "GRU state (from init, then hidden_next)")),
          "outputs": io_entries(("y", ["B", G], f"prediction of frame t + 1: {frame_words(config)}, then "
                                 "translations (O)"),
                                ("hidden_next", [L, "B", H], "GRU state after frame t"))}
    meta = _metadata(g, name, "step", config, io, skeleton, frame_rate, metadata)
    return g.model(metadata=meta, doc_string="QuaterNet step: one frame, state in -> state out",
                   producer_version=EXPORTER_VERSION)


def export_quaternet_predict(params: Mapping[str, np.ndarray], config: rnn.QuaterNetConfig, *, k: int = 10,
                             dtype=np.float32, opset: int = OPSET, primitive: bool | None = None, skeleton=None,
                             frame_rate: float = 25.0, metadata: Mapping | None = None,
                             name: str = "quaternet") -> onnx.ModelProto:
    """The ``predict`` model: ``refimpl.models.quaternet.predict`` in one graph, prefix → ``k`` frames.

    The prefix length is free; ``k`` is fixed at export (``k − 1`` unrolled steps, shared weights). No controls
    (``num_controls = 0``): a fed-back prediction would need the controls of the future frames.

    Returns
    -------
    onnx.ModelProto
        Input ``prefix (B, P, F)``; output ``frames (B, k, G)``.
    """
    _check_rnn(params, config)
    if config.num_controls:
        raise ValueError("config: the predict model needs num_controls = 0 (export the step model instead)")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k: expected a positive integer number of frames, got {k!r}")
    k = int(k)
    F, G, L = config.input_size, config.output_size, config.num_layers
    g = _builder(f"{name}_predict", dtype, opset, primitive)
    prefix = g.input("prefix", ["B", "P", F])
    h0 = tiled_state(g, params["h0"], prefix, name="prefix.h0")                 # (L, B, H)
    if not _dual(config):  # the sign rule of deploy.models.quaternet_sign, inside the graph
        from deploy.models.quaternet_sign import canonical_signs_graph

        R = config.rotation_size
        canon = canonical_signs_graph(g, prefix if F == R else _slice(g, prefix, 0, R, -1, "prefix.q"),
                                      config.num_joints, name="prefix.canon")
        prefix = canon if F == R else g.node("Concat", [canon, _slice(g, prefix, R, _INT64_MAX, -1, "prefix.rest")],
                                             "prefix.canonical", axis=-1)                   # (B, P, F)
    tops, h = gru(g, prefix, h0, params, "rnn", name="prefix.rnn", wname="rnn", num_layers=L)  # (B, P, H)
    top = g.node("Squeeze", [_slice(g, tops, -1, _INT64_MAX, 1, "prefix.top_last"), g.ints([1])], "prefix.top")
    x = g.node("Squeeze", [_slice(g, prefix, -1, _INT64_MAX, 1, "prefix.x_last"), g.ints([1])], "prefix.x")
    y = _head(g, top, x, params, config, name="t000.head")                       # (B, G)
    ys = [y]
    for t in range(1, k):
        y, h = _step(g, y, h, params, config, name=f"t{t:03d}")
        ys.append(y)
    cols = [g.node("Unsqueeze", [v, g.ints([1])], f"frames.{t:03d}") for t, v in enumerate(ys)]  # (B, 1, G)
    out = cols[0] if k == 1 else g.node("Concat", cols, "frames.all", axis=1)    # (B, k, G)
    g.output(out, "frames", ["B", k, G])
    io = {"inputs": io_entries(("prefix", ["B", "P", F], f"conditioning frames, oldest first: {frame_words(config)}"
                                + ("; any signs (canonicalised inside)" if not _dual(config) else
                                   "; built by input_transform"))),
          "outputs": io_entries(("frames", ["B", k, G], f"predictions of the k frames after the prefix: "
                                 f"{frame_words(config)}"))}
    meta = _metadata(g, name, "predict", config, io, skeleton, frame_rate, dict(metadata or {}, k=k))
    return g.model(metadata=meta, doc_string=f"QuaterNet predict: prefix -> {k} frames",
                   producer_version=EXPORTER_VERSION)


# ----------------------------------------------------------------------------------------- convolutional
def export_quaternet_cnn_window(params: Mapping[str, np.ndarray], config: cnn.QuaterNetCNNConfig, *,
                                dtype=np.float32, opset: int = OPSET, primitive: bool | None = None,
                                skeleton=None, frame_rate: float = 25.0, metadata: Mapping | None = None,
                                name: str = "quaternet-cnn") -> onnx.ModelProto:
    """The ``window`` model: ``refimpl.models.quaternet_cnn.step``, the prediction of the frame after a window.

    Frames before the window count as zeros at every layer (causal padding), as the NumPy step; only the last
    ``R`` (receptive field) frames matter, so a runtime feeds at most ``R``.

    Returns
    -------
    onnx.ModelProto
        Input ``window (B, W, 4J)``; output ``pose_next (B, 4J)``.
    """
    if not isinstance(config, cnn.QuaterNetCNNConfig):
        raise ValueError(f"config: expected a QuaterNetCNNConfig, got {type(config).__name__}")
    cnn.check_params(params, config)
    J, R, n = config.num_joints, config.rotation_size, config.num_layers
    kind = {"none": "identity"}.get(config.activation, config.activation)
    g = _builder(f"{name}_window", dtype, opset, primitive)
    x = g.input("window", ["B", "W", R])
    acts, a = [], x
    for k in range(n):
        z = conv1d_causal(g, a, params, f"convs.{k}", name=f"conv{k}", dilation=config.dilations[k])  # (B, W, C)
        if k < n - 1:
            z = activation(g, z, kind, name=f"conv{k}.act", alpha=config.negative_slope)
        for s, kk in config.skips:
            if kk == k:
                z = g.node("Add", [z, acts[s]], f"conv{k}.skip{s}")
        acts.append(z)
        a = z
    last = g.node("Squeeze", [_slice(g, a, -1, _INT64_MAX, 1, "head.delta_last"), g.ints([1])], "head.delta")
    d4 = g.node("Reshape", [last, g.ints([0, J, 4])], "head.delta_j")            # (B, J, 4)
    if config.velocity:
        xl = g.node("Squeeze", [_slice(g, x, -1, _INT64_MAX, 1, "head.x_last"), g.ints([1])], "head.x")
        d4 = quat_mul(g, d4, g.node("Reshape", [xl, g.ints([0, J, 4])], "head.q_in"), name="head.qmul")
    q = quat_normalize(g, d4, name="head.qnorm", eps=config.eps)
    g.output(g.node("Reshape", [q, g.ints([0, R])], "head.q"), "pose_next", ["B", R])
    io = {"inputs": io_entries(("window", ["B", "W", R], "the latest frames, oldest first: per joint the unit "
                                "local quaternion (w, x, y, z), 4J values (the prefix canonicalised, "
                                f"input_transform, then the fed-back predictions); the last "
                                f"{config.receptive_field} matter")),
          "outputs": io_entries(("pose_next", ["B", R], "prediction of the frame after the window"))}
    meta = _metadata(g, name, "window", config, io, skeleton, frame_rate,
                     dict(metadata or {}, receptive_field=config.receptive_field))
    return g.model(metadata=meta, doc_string="QuaterNet CNN window: latest frames -> next frame",
                   producer_version=EXPORTER_VERSION)
