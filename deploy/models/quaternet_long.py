"""ONNX graphs of QuaterNet's long-term locomotion networks (spec/deploy.md §12, spec/locomotion.md §10).

* :func:`export_pose_step` — one step of the long-term pose network (``refimpl.models.quaternet.step`` with
  controls and translations, absolute rotations): ``x (B, 4J + 2 + 6)``, ``state (L, B, H)`` →
  ``y (B, 4J + 2)`` (unit quaternions per joint, then offset and height), ``state_next (L, B, H)``.
  A generation loop feeds ``[y | controls]`` back (``refimpl.models.quaternet_long_walk``).
* :func:`export_pace` — the bidirectional pace network over a whole path: ``x (B, N, 2)``
  ``[turning_angle, average_speed]`` → ``y (B, N, 4)`` ``[A, ω, cos Δ, sin Δ]`` (raw; the clipping and facing of
  ``refimpl.models.pace.predict`` stay in the host).

Shape legend: B batch, N spline points, J joints, L GRU layers, H hidden, F input features, G outputs.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import onnx

from refimpl.models import pace
from refimpl.models.quaternet import QuaterNetConfig, check_params

from deploy.activations import leaky_relu
from deploy.graph import OPSET, GraphBuilder
from deploy.gru import gru, gru_pair_unrolled, gru_step
from deploy.linear import linear
from deploy.metadata import EXPORTER_VERSION, build_metadata, io_entries, skeleton_metadata
from deploy.quat import dq_normalize, quat_normalize
from deploy.recurrent import tiled_state

__all__ = ["NAME", "QUATERNET_PAPER", "export_pose_step", "export_pace", "export_pace_step"]

NAME = "quaternet-long"
QUATERNET_PAPER = ("Pavllo, Feichtenhofer, Auli, Grangier: Modeling Human Motion with Quaternion-based Neural "
                   "Networks, IJCV 2019 (long-term locomotion, §3.7)")


#: Points per call of the portable pace graph (:func:`export_pace_step`), chosen by measurement
#: (``benchmarks/bench_portable.py --pace-chunks``: the time per point flattens once the ``run`` overhead is spread
#: over a few dozen points; larger K only grows the graph and the padding of short paths).
PACE_CHUNK = 64

#: Length unit of the long-term networks (QuaterNet's locomotion data; spec/locomotion.md).
UNITS = "QuaterNet units (1 unit = 5.6444 cm)"


def _representation(config: QuaterNetConfig) -> dict:
    """Layout of the step model's frames ``[rotations | offset, height | 6 controls]`` with units."""
    J = int(config.num_joints)
    D = config.joint_width
    dual = D == 8
    rot = ({"name": "joint_dual_quaternions", "start": 0, "size": 8 * J, "joints": J,
            "meaning": "per joint the current dual quaternion (q_r | q_d), each (w, x, y, z), relative to the root "
                       "joint; unit (Eq. 13 in the graph on y); translation t = 2 (q_d ⊗ conj(q_r)) scaled by "
                       "model.config's dq_scale, QuaterNet units"} if dual else
           {"name": "joint_rotations", "start": 0, "size": 4 * J, "joints": J,
            "meaning": "per joint the local quaternion (w, x, y, z), Hamilton, relative to the parent joint; the "
                       "root's absolute about +y (facing); unit on y (normalised in the graph)"})
    fields = [rot,
              {"name": "offset", "start": D * J, "size": 1, "units": UNITS,
               "meaning": "signed distance of the root ahead of the path point reached (s + offset is where the "
                          "root goes on the path)"},
              {"name": "height", "start": D * J + 1, "size": 1, "units": UNITS, "meaning": "root height (y)"},
              {"name": "controls", "start": D * J + 2, "size": 6, "inputs_only": True,
               "meaning": "[A cos phi, A sin phi, A tx, A tz, fx, fz]: A amplitude (units per frame) and phi phase "
                          "of the gait (pace model), (tx, tz) the unit path tangent, (fx, fz) the unit facing "
                          "direction, all in the path's (x, z) ground plane"}]
    return {"name": "quaternet_long_dq" if dual else "quaternet_long",
            "kind": "quaternet_long_dq" if dual else "quaternet_long", "size": D * J + 8,
            "num_joints": J, "units": UNITS, "fields": fields}


def export_pose_step(params: Mapping[str, np.ndarray], config: QuaterNetConfig, *, dtype=np.float32,
                     opset: int = OPSET, primitive: bool | None = None, skeleton=None, frame_rate: float = 30.0,
                     metadata: Mapping | None = None, h0_file: str | None = None) -> onnx.ModelProto:
    """The ``step`` model of the long-term pose network (QN Fig. 1 with the controls block, spec/quaternet.md §1).

    Graph: ``a = LReLU(fc2(LReLU(fc1(c))))``, ``h' = GRU([q | τ | a], h)``, ``o = fc(h'_top)``,
    ``q̂_j = o_j / max(‖o_j‖, ε)``, ``y = [q̂ | τ']``.
    """
    check_params(params, config)
    if config.velocity or config.num_controls == 0:
        raise ValueError(f"config: expected a long-term (absolute, with controls) network, got {config}")
    J, O, C = config.num_joints, config.num_outputs, config.num_controls
    G, F, H, L = config.output_size, config.input_size, config.hidden_size, config.num_layers
    g = GraphBuilder(f"{NAME}_step", dtype=dtype, opset=opset, primitive=primitive)
    x = g.input("x", ["B", F])
    state = g.input("state", [L, "B", H])
    pose, ctrl = g.node("Split", [x, g.ints([G, C])], "x.split", axis=1, outputs=("pose", "controls"))
    a = leaky_relu(g, linear(g, ctrl, params, "fc1", name="fc1", rank2=True), name="fc1.act",
                   alpha=config.negative_slope)
    a = leaky_relu(g, linear(g, a, params, "fc2", name="fc2", rank2=True), name="fc2.act",
                   alpha=config.negative_slope)
    gin = g.node("Concat", [pose, a], "gru_in", axis=1)                          # (B, I)
    top, h_new = gru_step(g, gin, state, params, "rnn", name="rnn", num_layers=L)  # (B, H), (L, B, H)
    o = linear(g, top, params, "fc", name="fc", rank2=True)                       # (B, G)
    D = config.joint_width  # 4, or 8 for current dual quaternions (Andreou et al. §6.2: Eq. 13 in the graph)
    q, tau = g.node("Split", [o, g.ints([D * J, O])], "o.split", axis=1, outputs=("q", "tau"))
    q = g.node("Reshape", [q, g.ints([0, J, D])], "q.joints")                     # (B, J, D)
    q = (dq_normalize if D == 8 else quat_normalize)(g, q, name="q.unit", eps=float(config.eps))
    q = g.node("Reshape", [q, g.ints([0, D * J])], "q.flat")                      # (B, DJ)
    y = g.node("Concat", [q, tau], "y", axis=1)                                   # (B, G)
    g.output(y, "y", ["B", G])
    g.output(h_new, "state_next", [L, "B", H])
    R = D * J
    io = {"inputs": io_entries(("x", ["B", F], f"frame t: [rotations {R} | offset, height | 6 controls] "
                                "(representation); the seed's frames, then [y | the next controls]"),
                               ("state", [L, "B", H], "GRU state: the initial state (initial_state) at the start, "
                                "then state_next")),
          "outputs": io_entries(("y", ["B", G], f"frame t + 1: [rotations {R} (unit) | offset, height]"),
                                ("state_next", [L, "B", H], "GRU state after this frame"))}
    extra = dict(metadata or {})
    extra["initial_state"] = {
        "file": h0_file, "shape": [L, 1, H], "dtype": np.dtype(dtype).name, "format": "NumPy .npy (no pickle)",
        "meaning": "the learned initial GRU state h0; repeat it over the batch (axis 1) for the first call"}
    sk = skeleton_metadata(skeleton)
    if sk is not None:
        sk.setdefault("units", UNITS)
    inp = {"summary": "no normalisation; frames as representation; the root's facing is absolute about +y",
           "steps": ["seed: P frames of rotations (root facing aligned with the path's facing at its start), "
                     "offset, height and the frames' controls; run step on each with the carried state",
                     "generation: x = [y | controls of the next frame] (6 numbers, representation.fields[3])"]}
    out = {"summary": "y[:R] unit rotations per joint; root position: the path point at arc length s + offset "
                      "(x, z) and height (y), QuaterNet units", "steps": []}
    meta = build_metadata(g, name=NAME, role="step", config=config.to_dict(), io=io,
                          representation=_representation(config), skeleton=sk, frame_rate=frame_rate,
                          source_paper=QUATERNET_PAPER, variant="float", extra=extra,
                          input_transform=inp, output_transform=out)
    return g.model(metadata=meta, doc_string="QuaterNet long-term pose network: one step",
                   producer_version=EXPORTER_VERSION)


def _pace_config(config) -> dict:
    return {"bidirectional": True, "hidden_size": int(config.hidden_size), "input_size": int(config.input_size),
            "output_size": int(config.output_size)}


#: The pace models' ``representation``, ``input_transform`` and ``output_transform`` metadata.
PACE_REPRESENTATION = {"kind": "pace", "name": "pace", "points_per_unit": 5.0, "units": UNITS,
                       "inputs": ["turning_angle (radians between consecutive tangents of the reparameterised path)",
                                  "average_speed (units per frame at 30 fps)"],
                       "outputs": ["amplitude", "frequency", "cos_delta", "sin_delta"]}
PACE_INPUT_TRANSFORM = {"summary": "the path reparameterised to points_per_unit points per unit of length (smoothing "
                                   "1.0); per point its turning angle and the target speed", "steps": []}
PACE_OUTPUT_TRANSFORM = {"summary": "A = max(A, 0.1), omega = max(omega, 0); facing = the unit tangent (tx, tz) "
                                    "rotated by (c, s) = (cos Δ, sin Δ) / (|(cos Δ, sin Δ)| + 1e-9): (tx c - tz s, "
                                    "tz c + tx s)", "steps": []}


def export_pace(params: Mapping[str, np.ndarray], config: pace.PaceConfig, *, dtype=np.float32, opset: int = OPSET,
                primitive: bool | None = None, frame_rate: float = 30.0,
                metadata: Mapping | None = None) -> onnx.ModelProto:
    """The ``pace`` model: the bidirectional pace network over a whole path (``refimpl.models.pace.forward``).

    Graph: ``h_0`` learned ``(2, 1, H)`` tiled over B, ``Y = BiGRU(x)`` ``(B, N, 2H)``, ``y = fc(Y)``.
    """
    if not config.bidirectional:
        raise ValueError("config: only the bidirectional pace network is exported (the delayed one runs in NumPy)")
    H = config.hidden_size
    for k in ("h0", "fc.weight"):
        if k not in params:
            raise ValueError(f"params: missing {k!r}")
    g = GraphBuilder(f"{NAME}_pace", dtype=dtype, opset=opset, primitive=primitive)
    x = g.input("x", ["B", "N", config.input_size])
    h0 = tiled_state(g, np.asarray(params["h0"], dtype=dtype), x, name="h0")      # (2, B, H)
    y, _ = gru(g, x, h0, params, "rnn", name="rnn", num_layers=1, bidirectional=True)  # (B, N, 2H)
    out = linear(g, y, params, "fc", name="fc")                                   # (B, N, 4)
    g.output(out, "y", ["B", "N", config.output_size])
    io = {"inputs": io_entries(("x", ["B", "N", 2], "[turning_angle, average_speed] per spline point")),
          "outputs": io_entries(("y", ["B", "N", 4], "[amplitude A (units per frame), frequency omega "
                                 "(radians of gait phase per frame), cos Δ, sin Δ] per point (before "
                                 "output_transform)"))}
    meta = build_metadata(g, name=NAME, role="pace", config=_pace_config(config), io=io,
                          representation=PACE_REPRESENTATION, frame_rate=frame_rate, source_paper=QUATERNET_PAPER,
                          variant="float", extra=dict(metadata or {}), input_transform=PACE_INPUT_TRANSFORM,
                          output_transform=PACE_OUTPUT_TRANSFORM)
    return g.model(metadata=meta, doc_string="QuaterNet pace network (bidirectional GRU + linear)",
                   producer_version=EXPORTER_VERSION)


def _direction_params(params: Mapping[str, np.ndarray], H: int) -> dict:
    """The pace network's GRU directions and head as one-direction layers: ``fwd``/``bwd`` (``rnn``'s forward and
    ``_reverse`` parameters as layer 0), ``head_f`` (``fc.weight[:, :H]``, no bias), ``head_b`` (``fc.weight[:, H:]``
    and ``fc.bias``)."""
    out = {}
    for key in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"):
        for d, sfx in (("fwd", ""), ("bwd", "_reverse")):
            if f"rnn.{key}_l0{sfx}" in params:
                out[f"{d}.{key}_l0"] = np.asarray(params[f"rnn.{key}_l0{sfx}"])
    w = np.asarray(params["fc.weight"])                                           # (4, 2H)
    out["head_f.weight"], out["head_b.weight"] = w[:, :H], w[:, H:]
    if "fc.bias" in params:
        out["head_b.bias"] = np.asarray(params["fc.bias"])
    return out


def export_pace_step(params: Mapping[str, np.ndarray], config: pace.PaceConfig, *, points: int = PACE_CHUNK,
                     dtype=np.float32, opset: int = OPSET, primitive: bool | str | None = None,
                     frame_rate: float = 30.0, metadata: Mapping | None = None,
                     h0_file: str | None = None) -> onnx.ModelProto:
    """The ``pace_step`` model: ``points`` points of each direction of the pace network per call, for a host that
    runs a path chunk by chunk (the portable target, ``deploy/portable.py``; no ``GRU`` node, no ``Scan``).

    Graph: both directions unrolled over the K points and advanced together (:func:`deploy.gru.gru_pair_unrolled`:
    state ``[h_f | h_b]``, block-diagonal weights, 9 nodes per point for both), then the head of all K points in
    one ``Gemm``: ``[y_f | y_b] = [h_f | h_b] [[W_fᵀ, 0], [0, W_bᵀ]] + [0 | b]``.

    The forward direction reads the path in order, the backward direction the reversed path, each padded at its
    end to a multiple of ``points`` (padding comes after the real points in both orders, so it changes nothing
    before it). The pace output of point ``n`` of ``N`` is ``y_forward[n] + y_backward[N − 1 − n]`` over the
    concatenated calls (``fc([h_f | h_b]) = W_f h_f + (W_b h_b + b)``), equal to :func:`export_pace`'s ``y``.

    Returns
    -------
    onnx.ModelProto
        Inputs ``x_forward (B, K, 2)``, ``h_forward (1, B, H)``, ``x_backward (B, K, 2)``, ``h_backward (1, B, H)``
        with ``K = points``; outputs ``y_forward (B, K, 4)``, ``h_forward_next (1, B, H)``, ``y_backward (B, K, 4)``,
        ``h_backward_next``.
    """
    if not config.bidirectional:
        raise ValueError("config: only the bidirectional pace network is exported (the delayed one runs in NumPy)")
    if isinstance(points, bool) or not isinstance(points, (int, np.integer)) or points < 1:
        raise ValueError(f"points: expected a positive integer, got {points!r}")
    K, H, I, G = int(points), int(config.hidden_size), int(config.input_size), int(config.output_size)
    p = _direction_params(params, H)
    g = GraphBuilder(f"{NAME}_pace_step", dtype=dtype, opset=opset, primitive=primitive)
    ins = {d: (g.input(f"x_{d}", ["B", K, I]), g.input(f"h_{d}", [1, "B", H])) for d in ("forward", "backward")}
    y, h_f, h_b = gru_pair_unrolled(g, (ins["forward"][0], ins["backward"][0]),
                                    (ins["forward"][1], ins["backward"][1]), p, ("fwd", "bwd"), name="rnn",
                                    steps=K)                             # (K·B, 2H) [h_f | h_b], 2 × (1, B, H)
    head = g.weight("head.W", np.block([[p["head_f.weight"].T, np.zeros((H, G))],
                                        [np.zeros((H, G)), p["head_b.weight"].T]]))    # (2H, 2G)
    bias = np.concatenate([np.zeros(G), p.get("head_b.bias", np.zeros(G))])
    o = g.node("Gemm", [y, head, g.weight("head.b", bias)], "head")                  # (K·B, 2G)
    o = g.node("Transpose", [g.node("Reshape", [o, g.ints([K, -1, 2 * G])], "head.tbg")], "head.btg",
               perm=[1, 0, 2])                                                       # (B, K, 2G)
    y_f, y_b = g.node("Split", [o, g.ints([G, G])], "y", axis=2, outputs=("f", "b"))  # (B, K, G) each
    for d, y_d, h_d in (("forward", y_f, h_f), ("backward", y_b, h_b)):
        g.output(y_d, f"y_{d}", ["B", K, G])
        g.output(h_d, f"h_{d}_next", [1, "B", H])
    io = {"inputs": io_entries(("x_forward", ["B", K, I], f"[turning_angle, average_speed] of points c K ... c K + "
                                f"{K - 1} (call c; zeros past the path's end)"),
                               ("h_forward", [1, "B", H], "forward GRU state (initial_state[0], then h_forward_next)"),
                               ("x_backward", ["B", K, I], "the same of the reversed path: points N-1-cK down to "
                                f"N-{K}-cK (zeros past its end)"),
                               ("h_backward", [1, "B", H], "backward GRU state (initial_state[1], then "
                                                           "h_backward_next)")),
          "outputs": io_entries(("y_forward", ["B", K, G], "forward parts of the pace outputs of those points"),
                                ("h_forward_next", [1, "B", H], "forward state after them"),
                                ("y_backward", ["B", K, G], "backward parts (with the bias) of the reversed path's "
                                                            "points"),
                                ("h_backward_next", [1, "B", H], "backward state after them"))}
    extra = dict(metadata or {}, points_per_call=K)
    extra["initial_state"] = {"file": h0_file, "shape": [2, 1, H], "dtype": np.dtype(dtype).name,
                              "format": "NumPy .npy (no pickle)",
                              "meaning": "the learned initial states: [0] forward, [1] backward"}
    meta = build_metadata(g, name=NAME, role="pace_step", config=_pace_config(config), io=io,
                          representation=PACE_REPRESENTATION, frame_rate=frame_rate, source_paper=QUATERNET_PAPER,
                          variant="float", extra=extra, input_transform=PACE_INPUT_TRANSFORM,
                          output_transform={**PACE_OUTPUT_TRANSFORM, "combine": "y[n] = y_forward[n] + "
                                            "y_backward[N - 1 - n] over the concatenated calls, then the output "
                                            "transform"})
    return g.model(metadata=meta, doc_string=f"QuaterNet pace network: {K} points of each GRU direction",
                   producer_version=EXPORTER_VERSION)
