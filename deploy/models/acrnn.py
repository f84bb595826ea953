"""ONNX graphs of acRNN (``refimpl/models/acrnn.py``) with the representation's decoding (spec/deploy.md §8.2).

Two models, both taking and returning **raw** frames (the training standardisation is inside the graph):

* ``acrnn_step``: one online step, ``frame (B, F)``, ``h, c (L, B, H)`` → ``next_frame (B, F)``, ``h_next``,
  ``c_next`` (:func:`refimpl.models.acrnn.step` between :func:`~deploy.features.standardize` and
  :func:`~deploy.features.destandardize`), plus the decoded joints of ``next_frame``;
* ``acrnn_generate``: ``seed (B, S, F)`` and ``num_frames`` (int64 scalar, N ≥ 1) → ``frames (B, N, F)``
  (:func:`refimpl.models.acrnn.generate`): the seed read by a ``Scan`` from a zero state, then a ``Loop`` of N
  steps feeding back the output; plus the decoded joints of every frame.

Decoding in the graph, by the representation of the frames (``F = 3 + D·J``):

* ``dual_quaternions``: ``joints (…, J, 8)`` = the Eq. 13 normalisation of each joint's dual quaternion
  (:func:`deploy.quat.dq_normalize`) and ``positions (…, J, 3)`` = their translations (Eq. 8,
  ``t = 2 (q_d ⊗ q_r*)`` vector part), in the frame's (root-relative, current) coordinates;
* ``quaternions``, ``quaternions+positions``: ``joints (…, J, 4)`` = the unit local quaternions;
* other representations: no decoded outputs.

Shape legend: B batch, S seed frames, N generated frames, F frame size, H hidden, L layers, J joints, D values per
joint.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np
import onnx

from refimpl.models.acrnn import ACRNNConfig, param_shapes
from refimpl.representations import REPRESENTATIONS

from deploy.features import destandardize, standardize
from deploy.graph import OPSET, GraphBuilder
from deploy.linear import linear
from deploy.lstm import lstm_step
from deploy.metadata import EXPORTER_VERSION, build_metadata, io_entries, skeleton_metadata
from deploy.quat import dq_normalize, quat_mul, quat_normalize
from deploy.recurrent import tiled_state

__all__ = ["export_acrnn_step", "export_acrnn_generate"]

SOURCE = ("Andreou, Aristidou, Chrysanthou: Pose Representations for Deep Skeletal Animation (SCA 2022), on "
          "acRNN (Zhou, Li et al., ICLR 2018)")
_CONJ = np.array([1.0, -1.0, -1.0, -1.0])


def _check(params, config, mean, std, representation):
    for name, shape in param_shapes(config).items():
        if name not in params or np.shape(params[name]) != shape:
            raise ValueError(f"params[{name!r}]: expected shape {shape}, got {np.shape(params.get(name))}")
    F = config.frame_size
    if np.shape(mean) != (F,) or np.shape(std) != (F,):
        raise ValueError(f"mean, std: expected shape ({F},), got {np.shape(mean)}, {np.shape(std)}")
    rep = REPRESENTATIONS.get(representation)
    if rep is None or (F - 3) % rep.dim:
        raise ValueError(f"representation: {representation!r} does not fit frames of {F} values")
    return (F - 3) // rep.dim, rep.dim


def _decode(g: GraphBuilder, frames: str, representation: str, J: int, D: int, lead: int, name: str) -> dict:
    """The decoded joints of raw frames ``(…, F)`` (``lead`` leading axes): dict output name → tensor."""
    zeros = [0] * lead
    blocks = g.node("Slice", [frames, g.ints([3]), g.ints([3 + J * D]), g.ints([-1])], f"{name}.blocks")
    blocks = g.node("Reshape", [blocks, g.ints(zeros + [J, D])], f"{name}.per_joint")    # (…, J, D)
    if representation == "dual_quaternions":
        dq = dq_normalize(g, blocks, name=f"{name}.dq_unit")                               # (…, J, 8), Eq. 13
        qr, qd = g.node("Split", [dq, g.ints([4, 4])], f"{name}.split", axis=-1, outputs=("qr", "qd"))
        conj = g.node("Mul", [qr, g.weight("const.quat_conj", _CONJ)], f"{name}.qr_conj")  # (…, J, 4)
        t = quat_mul(g, qd, conj, name=f"{name}.qd_qrc")                                  # (…, J, 4)
        t = g.node("Slice", [t, g.ints([1]), g.ints([4]), g.ints([-1])], f"{name}.t_half")
        pos = g.node("Mul", [t, g.scalar(2.0)], f"{name}.positions")                      # (…, J, 3), Eq. 8
        return {"joints": dq, "positions": pos}
    if representation in ("quaternions", "quaternions+positions"):
        q = blocks if D == 4 else g.node("Slice", [blocks, g.ints([0]), g.ints([4]), g.ints([-1])], f"{name}.q")
        return {"joints": quat_normalize(g, q, name=f"{name}.q_unit")}                    # (…, J, 4)
    return {}


def _decoded_shape(k: str, representation: str, lead: list, J: int) -> list:
    """The true shape of decoded output ``k``: ``lead + [J, 8]`` (dual-quaternion joints), ``[J, 4]`` (quaternion
    joints) or ``[J, 3]`` (positions)."""
    return lead + [J, 3 if k == "positions" else (8 if representation == "dual_quaternions" else 4)]


_DECODED_MEANING = {
    "joints": {"dual_quaternions": "per joint the unit current dual quaternion (q_r | q_d), each (w, x, y, z), "
                                   "Hamilton, relative to the root joint (Eq. 13 normalisation of the frame's 8 "
                                   "values: q_r / |q_r|, then q_d / |q_r| minus its component along q_r)",
               "quaternions": "per joint the unit local quaternion (w, x, y, z), relative to the parent joint "
                              "(the frame's 4 values divided by their norm)",
               "quaternions+positions": "per joint the unit local quaternion (w, x, y, z), relative to the parent "
                                        "joint (the first 4 of the joint's 7 values, divided by their norm)"},
    "positions": {"dual_quaternions": "per joint the position in metres relative to the root joint (current "
                                      "coordinates, root at the origin): t = 2 (q_d ⊗ conj(q_r)), vector part, "
                                      "of the unit dual quaternion"},
}

#: What the D values of one joint of a frame are, per representation (``refimpl.representations``).
_JOINT_LAYOUT = {
    "positions": "(x, y, z) position in metres relative to the root joint, current coordinates",
    "euler": "local Euler angles in radians, zyx order (angle about z, then y, then x)",
    "expmap": "local rotation vector (axis × angle, radians)",
    "quaternions": "local quaternion (w, x, y, z), Hamilton, relative to the parent joint",
    "ortho6d": "first two columns of the local rotation matrix (m00, m10, m20, m01, m11, m21)",
    "dual_quaternions": "current dual quaternion (q_r | q_d), each (w, x, y, z), relative to the root joint; "
                        "translation t = 2 (q_d ⊗ conj(q_r)) in metres",
    "quaternions+positions": "local quaternion (w, x, y, z) then current position (x, y, z) in metres",
    "ortho6d+positions": "ortho6D (6) then current position (x, y, z) in metres",
    "positions_acrnn": "(x, y, z) position in metres relative to the root joint (the published acRNN's frame)",
}


def _metadata(g, config, role, io, mean, std, representation, J, D, frame_rate, extra, skeleton):
    rep = {"name": representation, "size": config.frame_size, "units": "m",
           "fields": [{"name": "root", "start": 0, "size": 3, "units": "m",
                       "meaning": "hip dx = x_{t+1} - x_t, hip height y_t, hip dz = z_{t+1} - z_t (metres, y up; "
                                  "the hip's ground position is the running sum of dx, dz)"},
                      {"name": "joints", "start": 3, "size": J * D, "per_joint": D, "joints": J,
                       "joint_names": "skeleton.names (slot j = joint j)",
                       "layout": _JOINT_LAYOUT.get(representation, representation)}]}
    root_block = getattr(REPRESENTATIONS.get(representation), "root_block", True)
    if not root_block:  # the frames leave the root joint out (its position is the root block)
        rep["fields"][1]["joint_names"] = "skeleton.names[1:] (slot j = joint j + 1; the root joint has no slot)"
        rep["fields"][0]["meaning"] = "the root joint's position (x, y, z), metres, y up"
    sk = None
    if skeleton is not None:
        sk = skeleton_metadata(skeleton)
        sk.setdefault("units", "m")
        expected = J if root_block else J + 1
        if len(sk["names"]) != expected:
            raise ValueError(f"skeleton: expected {expected} joints (the frames' {J}"
                             f"{'' if root_block else ' and the root'}), got {len(sk['names'])}")
    return build_metadata(g, name="acrnn", role=role, config=config.to_dict(), io=io, representation=rep,
                          normalization=(mean, std), in_graph=True, skeleton=sk, frame_rate=frame_rate,
                          source_paper=SOURCE, variant="float", extra=extra)


def _step(g, x_n, h, c, params, config, name):
    """Standardised frame ``(B, F)`` → standardised prediction ``(B, F)``, new ``h, c``."""
    y, h_new, c_new = lstm_step(g, x_n, h, c, params, "lstm", name=f"{name}.lstm", num_layers=config.num_layers,
                                skewed=config.skewed, wname="lstm")
    out = linear(g, y, params, "decoder", name=f"{name}.decoder", rank2=True, wname="decoder")  # (B, F)
    return out, h_new, c_new


def export_acrnn_step(params: Mapping[str, np.ndarray], config: ACRNNConfig, *, mean, std, representation: str,
                      dtype=np.float32, opset: int = OPSET, primitive: bool | None = None, skeleton=None,
                      frame_rate: float = 30.0, metadata: Mapping | None = None) -> onnx.ModelProto:
    """The ``step`` model: inputs ``frame (B, F)`` raw, ``h, c (L, B, H)``; outputs ``next_frame (B, F)`` raw,
    ``h_next``, ``c_next``, and the decoded outputs of ``next_frame`` (dual quaternions: ``joints``, ``positions``;
    quaternions: ``joints``)."""
    J, D = _check(params, config, mean, std, representation)
    F, H, L = config.frame_size, config.hidden_size, config.num_layers
    g = GraphBuilder("acrnn_step", dtype=dtype, opset=opset, primitive=primitive)
    frame = g.input("frame", ["B", F])
    h = g.input("h", [L, "B", H])
    c = g.input("c", [L, "B", H])
    x_n = standardize(g, frame, mean, std, name="frame_n", wname="norm")
    y_n, h_new, c_new = _step(g, x_n, h, c, params, config, "step")
    y = destandardize(g, y_n, mean, std, name="next_frame_raw", wname="norm")
    g.output(y, "next_frame", ["B", F])
    g.output(h_new, "h_next", [L, "B", H])
    g.output(c_new, "c_next", [L, "B", H])
    dec = _decode(g, "next_frame", representation, J, D, 1, "decode")
    for k, v in dec.items():
        g.output(v, k, _decoded_shape(k, representation, ["B"], J))
    io = {"inputs": io_entries(("frame", ["B", F], "x_t, raw frame (the seed's, then next_frame)"),
                               ("h", [L, "B", H], "LSTM h (zeros at the start)"),
                               ("c", [L, "B", H], "LSTM c (zeros at the start)")),
          "outputs": io_entries(("next_frame", ["B", F], "prediction of frame t + 1, raw"),
                                ("h_next", [L, "B", H], "new h"), ("c_next", [L, "B", H], "new c"),
                                *[(k, _decoded_shape(k, representation, ["B"], J),
                                   _DECODED_MEANING[k][representation] + " (of next_frame)") for k in dec])}
    meta = _metadata(g, config, "step", io, mean, std, representation, J, D, frame_rate, metadata, skeleton)
    return g.model(metadata=meta, doc_string="acRNN step: one frame, state in -> state out",
                   producer_version=EXPORTER_VERSION)


def export_acrnn_generate(params: Mapping[str, np.ndarray], config: ACRNNConfig, *, mean, std, representation: str,
                          dtype=np.float32, opset: int = OPSET, primitive: bool | None = None, skeleton=None,
                          frame_rate: float = 30.0, metadata: Mapping | None = None) -> onnx.ModelProto:
    """The ``generate`` model: inputs ``seed (B, S, F)`` raw and ``num_frames`` (int64 scalar N ≥ 1); outputs
    ``frames (B, N, F)`` raw (the first is the prediction after the last seed frame) and the decoded outputs."""
    J, D = _check(params, config, mean, std, representation)
    F, H, L = config.frame_size, config.hidden_size, config.num_layers
    g = GraphBuilder("acrnn_generate", dtype=dtype, opset=opset, primitive=primitive)
    seed = g.input("seed", ["B", "S", F])
    num = g.input("num_frames", [], dtype=np.int64)
    seed_n = standardize(g, seed, mean, std, name="seed_n", wname="norm")                 # (B, S, F)
    seed_tm = g.node("Transpose", [seed_n], "seed_tm", perm=[1, 0, 2])                      # (S, B, F)
    zero = np.zeros((L, 1, H))
    h0 = tiled_state(g, zero, seed, name="h0")                                              # (L, B, H)
    c0 = tiled_state(g, zero, seed, name="c0")
    # the seed, teacher-forced: Scan over its frames, the state carried, the predictions stacked
    sb = g.subgraph("seedbody")
    sh, sc = sb.input("seedbody.h_in", [L, "B", H]), sb.input("seedbody.c_in", [L, "B", H])
    sx = sb.input("seedbody.x", ["B", F])
    sy, sh2, sc2 = _step(sb, sx, sh, sc, params, config, "seedbody.step")
    sb.output(sh2, "seedbody.h_out", [L, "B", H])
    sb.output(sc2, "seedbody.c_out", [L, "B", H])
    sb.output(sy, "seedbody.y", ["B", F])
    h1, c1, ys = g.node("Scan", [h0, c0, seed_tm], "seed_scan", body=sb.graph(), num_scan_inputs=1,
                        outputs=("h_seed", "c_seed", "seed_pred"))                          # ys (S, B, F)
    first = g.node("Gather", [ys, g.constant("last_index", np.array(-1, dtype=np.int64))], "first", axis=0)
    # generation: Loop of N steps; each iteration emits its carried frame, then steps (flattened 1-D scan output,
    # spec/deploy.md §5: onnxruntime and the reference evaluator agree on Loop scan outputs only for 1-D values)
    lb = g.subgraph("genbody")
    lb.input("genbody.iter", [], dtype=np.int64)
    cond_in = lb.input("genbody.cond_in", [], dtype=np.bool_)
    ly = lb.input("genbody.y_in", ["B", F])
    lh, lc = lb.input("genbody.h_in", [L, "B", H]), lb.input("genbody.c_in", [L, "B", H])
    ny, nh, nc = _step(lb, ly, lh, lc, params, config, "genbody.step")
    lb.output(lb.node("Identity", [cond_in], "genbody.cond"), "genbody.cond_out", [], dtype=np.bool_)
    lb.output(ny, "genbody.y_out", ["B", F])
    lb.output(nh, "genbody.h_out", [L, "B", H])
    lb.output(nc, "genbody.c_out", [L, "B", H])
    flat = lb.node("Reshape", [ly, g.ints([-1])], "genbody.y_flat")
    lb.output(flat, "genbody.y_scan", ["BF"])
    cond = g.constant("gen.cond", np.array(True))
    outs = g.node("Loop", [num, cond, first, h1, c1], "gen", body=lb.graph(),
                  outputs=("y_last", "h_last", "c_last", "frames_flat"))                     # (N, B·F)
    tm = g.node("Reshape", [outs[-1], g.ints([0, -1, F])], "frames_tm")                     # (N, B, F)
    fr_n = g.node("Transpose", [tm], "frames_n", perm=[1, 0, 2])                            # (B, N, F)
    g.output(destandardize(g, fr_n, mean, std, name="frames_raw", wname="norm"), "frames", ["B", "N", F])
    dec = _decode(g, "frames", representation, J, D, 2, "decode")
    for k, v in dec.items():
        g.output(v, k, _decoded_shape(k, representation, ["B", "N"], J))
    io = {"inputs": io_entries(("seed", ["B", "S", F], "raw seed frames (10 in the paper's protocol)"),
                               ("num_frames", [], "N, frames to generate (int64, >= 1)")),
          "outputs": io_entries(("frames", ["B", "N", F], "generated raw frames after the seed"),
                                *[(k, _decoded_shape(k, representation, ["B", "N"], J),
                                   _DECODED_MEANING[k][representation] + " (of every frame)") for k in dec])}
    meta = _metadata(g, config, "generate", io, mean, std, representation, J, D, frame_rate, metadata, skeleton)
    return g.model(metadata=meta, doc_string="acRNN generator: seed -> N frames", producer_version=EXPORTER_VERSION)
