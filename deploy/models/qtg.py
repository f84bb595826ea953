"""ONNX export of QTG (``refimpl/models/qtg.py``): an init model, a step model and a whole-transition rollout model.

Its entry of the exporter table ``deploy.models.EXPORTERS["qtg"]`` is ``deploy/models/qtg_io.py``.

The exporter translates the NumPy model's functions one to one (``spec/deploy.md`` §5):

=============  =========================================================  =====================================
model          inputs → outputs                                           translates
=============  =========================================================  =====================================
``init``       ``past (B, 2, P)``, ``target (B, 2, P)`` →                  ``refimpl.models.qtg.init_state``
               ``latent_prev (B, Z)``, ``pose (B, P)``, ``hidden (L, B, H)``,
               ``target_latent (B, 2, Z)``
``step``       ``pose``, ``latent_prev``, ``hidden``, ``target_latent`` →   ``refimpl.models.qtg.step``
               ``pose_next (B, P)``, ``latent_prev_next (B, Z)``,
               ``hidden_next (L, B, H)``
``rollout``    ``past``, ``target`` → ``poses (B, T, P)``                  ``refimpl.models.qtg_fast.rollout_forward``
=============  =========================================================  =====================================

A game loop runs ``init`` once per transition and then ``step`` once per frame, feeding ``*_next`` back as the
next inputs; the ``rollout`` model does the whole transition in one call (``T`` fixed at export). One step::

    z_t     = E(p_t)                                   encoder: Gemm + LeakyRelu per layer
    x_t     = [z_t − z_{t−1} | e1 − z_t | e2 − e1]     Sub, Sub, Concat (e2 − e1 once per transition)
    s_{t+1} = GRU(x_t, s_t)                            one ONNX GRU node per layer (linear_before_reset = 1)
    p_{t+1} = D(z_t + W_v s_{t+1} + b_v)               Gemm, Add, decoder Gemms

The rollout repeats the step ``T`` times in a ``Scan`` over a constant tick tensor (``mode="scan"``, the default:
fastest or tied in every measurement here, ``benchmarks/bench_onnx.py``), in a ``Loop``, or unrolled; the weights
are shared initializers either way.

Pose space: the NumPy model works on normalised poses (root translation z-normalised, quaternions raw). With
``normalization=(mean, std)`` the graphs take and return *raw* poses and standardise inside (``deploy/features``);
without, they take and return normalised poses like the NumPy functions. Either way the statistics, the pose
layout and the skeleton go to the metadata (``deploy/metadata.py``).

Shape legend: B batch, T transition frames, P pose size, Z latent size, H GRU hidden size, L GRU layers.
"""
from __future__ import annotations

import numpy as np
import onnx
from typing import Mapping

from refimpl.models.qtg import QTGConfig, param_shapes
from refimpl.protocols.transition_join import check_export_join, join_blend_frames

from deploy.activations import leaky_relu
from deploy.features import destandardize, standardize
from deploy.graph import OPSET, GraphBuilder
from deploy.gru import gru_step
from deploy.join import inertialize_joins, join_metadata
from deploy.linear import linear
from deploy.metadata import EXPORTER_VERSION, build_metadata, io_entries
from deploy.recurrent import tiled_state

__all__ = ["export_qtg_init", "export_qtg_step", "export_qtg_rollout", "export_qtg_join", "ROLLOUT_MODES", "QTG_PAPER",
           "qtg_representation", "QTG_INPUT_TRANSFORM", "QTG_OUTPUT_TRANSFORM", "default_skeleton"]

ROLLOUT_MODES = ("scan", "loop", "unrolled")

QTG_PAPER = ("Geleijn, Radziszewski, van Straaten, Galvan Debarba: Lightweight Quaternion Transition Generation "
             "with Neural Networks. IEEE VR 2021 (abstracts and workshops)")


def qtg_representation(pose_size: int, model_io: str = "raw") -> dict:
    """Layout of a QTG pose vector: root translation (3) then ``(P − 3) / 4`` local joint quaternions (w, x, y, z).

    ``model_io``: ``"raw"`` (the graph standardises inside: root translation in centimetres) or ``"normalized"``
    (root translation z-normalised with ``normalization.mean/std``, or in whatever space the model was trained
    when there are no statistics).
    """
    joints = (pose_size - 3) // 4
    root = {"raw": "centimetres",
            "normalized": "z-normalised per axis with the training statistics: (r' - normalization.mean[:3]) / "
                          "normalization.std[:3] (normalization null: the statistics are not in this file)"}[model_io]
    return {"name": "qtg_pose", "size": int(pose_size),
            "fields": [{"name": "root_translation", "start": 0, "size": 3, "units": "cm" if model_io == "raw" else
                        "normalized", "meaning": f"root position r' relative to the window's first pose, heading "
                        f"removed (input_transform), (x, y, z), y up; {root}"},
                       {"name": "joint_rotations", "start": 3, "size": 4 * joints, "joints": joints,
                        "joint_names": "skeleton.names (slot j = joint j, slot 0 = the root)",
                        "quaternion": "(w, x, y, z), Hamilton, local to the parent joint (root: relative to the "
                                      "window frame); inputs unit, outputs not normalised"}]}


#: How a consumer builds QTG's inputs from world-space frames (``metadata["input_transform"]``, deploy/README.md).
QTG_INPUT_TRANSFORM = {
    "summary": "4 context frames (2 before, 2 after the transition) made relative to the first of them: heading "
               "about +y removed, root translated to the origin; then flattened to poses of P = 3 + 4 J values",
    "frames": ["past[:, 0] = p_-1", "past[:, 1] = p_0", "target[:, 0] = g1 = p_T+1", "target[:, 1] = g2 = p_T+2"],
    "data": "each frame: root position r_k (x, y, z) in centimetres, y up, and the local rotation of every joint "
            "as a unit quaternion (w, x, y, z), joints in the order of skeleton.names, sampled at frame_rate fps",
    "steps": [
        "1. h = normalise(w, 0, y, 0) of the root rotation q_root of the first frame p_-1 (its twist about +y; "
        "the identity (1, 0, 0, 0) when w = y = 0).",
        "2. for each of the 4 frames k: r'_k = rotate(conj(h), r_k - r_first), with rotate(q, v) the vector part "
        "of q (0, v) conj(q) (Hamilton product), r_first = the root position of p_-1.",
        "3. q'_root,k = conj(h) * q_root,k (Hamilton product); the other joints' quaternions are unchanged.",
        "4. signs: if the first frame's quaternion of a joint has w < 0, negate it; then, frame by frame in the "
        "order p_-1, p_0, g1, g2, negate a joint's quaternion when its dot product with the same joint's quaternion "
        "in the previous frame is negative.",
        "5. pose_k = [r'_k (3) | q'_0,k (4) | q_1,k (4) | ... | q_J-1,k (4)] (representation); with "
        "normalization.in_graph false, normalise it: (pose - normalization.mean) / normalization.std.",
    ],
    "reference": "refimpl.protocols.transition.make_windows(rotations (4, J, 4), root_positions (4, 3), length=4)",
}

#: How a consumer maps QTG's outputs back to world space (``metadata["output_transform"]``).
QTG_OUTPUT_TRANSFORM = {
    "summary": "generated poses are relative to the same window frame: undo the input transform and normalise "
               "the quaternions",
    "steps": [
        "1. with normalization.in_graph false, de-normalise: pose = pose_n * normalization.std + "
        "normalization.mean.",
        "2. r_k = rotate(h, r'_k) + r_first (h, r_first from input_transform step 1-2).",
        "3. q_root,k = h * q'_root,k (Hamilton product).",
        "4. divide every joint quaternion by its norm (the network's are not unit).",
    ],
    "frames": "poses[:, t] is frame p_t+1, t = 0 ... T-1: the frames between p_0 and g1",
    "reference": "refimpl.protocols.transition.window_to_world(poses, h, r_first)",
}


def default_skeleton(pose_size: int):
    """The 22-joint CMU skeleton (centimetres) of the embedded sample's ``02_01.bvh`` when ``pose_size`` is 91,
    else ``None``: the joint order every transition data set is mapped to (``refimpl.rigs.CMU_22_JOINTS``)."""
    if (pose_size - 3) // 4 != 22 or (pose_size - 3) % 4:
        return None
    from refimpl.bvh import read_bvh_header
    from refimpl.rigs import CMU_22_JOINTS, CMU_UNIT_CM, scale_skeleton, subset_22
    from refimpl.protocols.transition import SAMPLE_DIR

    skel = read_bvh_header(SAMPLE_DIR / "bvh" / "02_01.bvh").skeleton
    ident = np.zeros((1, skel.num_joints, 4))
    ident[..., 0] = 1.0
    sub, _ = subset_22(skel, ident, CMU_22_JOINTS)
    return scale_skeleton(sub, CMU_UNIT_CM)


# ------------------------------------------------------------------------------------------------- checks
def check_params(params: Mapping[str, np.ndarray], config: QTGConfig) -> None:
    if not isinstance(config, QTGConfig):
        raise ValueError(f"config: expected a QTGConfig, got {type(config).__name__}")
    for key, shape in param_shapes(config).items():
        if key not in params:
            raise ValueError(f"params: missing parameter {key!r} (expected shape {shape})")
        a = np.asarray(params[key])
        if a.shape != shape:
            raise ValueError(f"params[{key!r}]: expected shape {shape}, got {a.shape}")
        if a.dtype.kind != "f" or not np.all(np.isfinite(a)):
            raise ValueError(f"params[{key!r}]: expected finite floating values")


def check_normalization(normalization, config: QTGConfig):
    """``(mean (P,), std (P,))`` float64 from ``(mean, std)`` of shape ``(P,)`` or root-only ``(3,)``.

    Root-only statistics (``refimpl.protocols.transition``: ``root_mean``, ``root_std``) are padded with mean 0 and std 1
    for the quaternion entries, for which the in-graph ``(x − 0) / 1`` and ``x · 1 + 0`` are exact.
    """
    if normalization is None:
        return None
    try:
        mean, std = normalization
    except (TypeError, ValueError) as exc:
        raise ValueError("normalization: expected a pair (mean, std) of arrays of shape (P,) or (3,)") from exc
    mean = np.asarray(mean, dtype=np.float64)
    std = np.asarray(std, dtype=np.float64)
    P = config.pose_size
    if mean.shape == (3,) and std.shape == (3,):
        mean = np.concatenate([mean, np.zeros(P - 3)])
        std = np.concatenate([std, np.ones(P - 3)])
    if mean.shape != (P,) or std.shape != (P,):
        raise ValueError(f"normalization: expected mean and std of shape ({P},) or (3,), got {mean.shape} and "
                         f"{std.shape}")
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(std)) and np.all(std > 0)):
        raise ValueError("normalization: expected a finite mean and finite, strictly positive std")
    return mean, std


# --------------------------------------------------------------------------------------------- builders
def _mlp(g: GraphBuilder, x: str, params, prefix: str, n_layers: int, slope: float, last_linear: bool, *,
         name: str, rank2: bool) -> str:
    """Dense layers ``{prefix}.0 … {prefix}.{n-1}``, LeakyReLU after each (not the last when ``last_linear``)."""
    for i in range(n_layers):
        x = linear(g, x, params, f"{prefix}.{i}", name=f"{name}.{i}", wname=f"{prefix}.{i}", rank2=rank2)
        if not (last_linear and i == n_layers - 1):
            x = leaky_relu(g, x, name=f"{name}.{i}.act", alpha=slope)
    return x


def _encoder(g, x, params, config, *, name, rank2):
    return _mlp(g, x, params, "enc", len(config.encoder_sizes), config.negative_slope, False, name=name,
                rank2=rank2)                                             # (..., Z)


def _decoder(g, x, params, config, *, name):
    return _mlp(g, x, params, "dec", len(config.decoder_sizes) + 1, config.negative_slope, True, name=name,
                rank2=True)                                              # (B, P)


def _step(g: GraphBuilder, latent_prev: str, pose: str, hidden: str, e1: str, e21: str, params,
          config: QTGConfig, *, name: str) -> tuple[str, str, str]:
    """One QTG step (``refimpl.models.qtg.step``): returns ``p_{t+1} (B, P)``, ``z_t (B, Z)``, ``s_{t+1} (L, B, H)``.

    ``e1`` ``(B, Z)`` = E(g1); ``e21`` ``(B, Z)`` = E(g2) − E(g1).
    """
    z = _encoder(g, pose, params, config, name=f"{name}.enc", rank2=True)          # (B, Z)
    dz = g.node("Sub", [z, latent_prev], f"{name}.latent_velocity")                 # (B, Z)
    off = g.node("Sub", [e1, z], f"{name}.target_offset")                           # (B, Z)
    x = g.node("Concat", [dz, off, e21], f"{name}.gru_input", axis=-1)              # (B, 3Z)
    y, hidden_new = gru_step(g, x, hidden, params, "gru", name=f"{name}.gru", wname="gru",
                             num_layers=config.gru_layers)                          # (B, H), (L, B, H)
    v = linear(g, y, params, "vel", name=f"{name}.vel", wname="vel", rank2=True)   # (B, Z)
    a = g.node("Add", [z, v], f"{name}.latent_next")                                # (B, Z)
    pose_next = _decoder(g, a, params, config, name=f"{name}.dec")                  # (B, P)
    return pose_next, z, hidden_new


def _encode_context(g, past, target, params, config, *, name):
    """``E(p_{-1})``, ``p_0``, ``E(g1)``, ``E(g2) − E(g1)`` and the stacked ``[E(g1), E(g2)]`` from the inputs."""
    p_m1, p_0 = g.node("Split", [past, g.ints([1, 1])], f"{name}.past", axis=1, outputs=("m1", "0"))  # (B, 1, P)
    ctx = g.node("Concat", [p_m1, target], f"{name}.ctx", axis=1)                 # (B, 3, P): p_{-1}, g1, g2
    lat = _encoder(g, ctx, params, config, name=f"{name}.enc", rank2=False)       # (B, 3, Z)
    l_m1, tl = g.node("Split", [lat, g.ints([1, 2])], f"{name}.lat", axis=1, outputs=("m1", "target"))
    latent_prev = g.node("Squeeze", [l_m1, g.ints([1])], f"{name}.latent_prev")   # (B, Z)
    pose = g.node("Squeeze", [p_0, g.ints([1])], f"{name}.pose")                  # (B, P)
    e1, e2 = g.node("Split", [tl, g.ints([1, 1])], f"{name}.e", axis=1, outputs=("1", "2"))  # (B, 1, Z)
    e1 = g.node("Squeeze", [e1, g.ints([1])], f"{name}.e1")                       # (B, Z)
    e2 = g.node("Squeeze", [e2, g.ints([1])], f"{name}.e2")                       # (B, Z)
    e21 = g.node("Sub", [e2, e1], f"{name}.e21")                                  # (B, Z)
    return latent_prev, pose, e1, e21, tl


def _zero_hidden(g, like, config, *, name):
    return tiled_state(g, np.zeros((config.gru_layers, config.gru_hidden)), like, name=name)  # (L, B, H)


# ---------------------------------------------------------------------------------------------- metadata
def qtg_metadata(config, role, io, normalization, in_graph, skeleton, frame_rate, g, variant, extra, T=None):
    """:func:`deploy.metadata.build_metadata` of a QTG model (name ``qtg``, its pose layout, paper and window
    transforms). ``skeleton=None`` writes :func:`default_skeleton` (the CMU 22 joints, for P = 91); ``False``
    writes ``null``."""
    from deploy.metadata import skeleton_metadata

    if skeleton is None:
        default = default_skeleton(config.pose_size)
        skeleton = None if default is None else skeleton_metadata(
            default, units="cm", source="default: CMU 22-joint rig (refimpl.rigs.CMU_22_JOINTS) of the embedded "
                                        "sample 02_01.bvh; offsets of that actor")
    elif skeleton is False:
        skeleton = None
    elif not isinstance(skeleton, Mapping):
        skeleton = skeleton_metadata(skeleton, units="cm")
    model_io = "raw" if in_graph else "normalized"
    return build_metadata(g, name="qtg", role=role, config=config.to_dict(), io=io,
                          representation=qtg_representation(config.pose_size, model_io),
                          normalization=normalization, in_graph=in_graph, skeleton=skeleton, frame_rate=frame_rate,
                          source_paper=QTG_PAPER, variant=variant, extra=extra, T=T,
                          input_transform=QTG_INPUT_TRANSFORM, output_transform=QTG_OUTPUT_TRANSFORM)


def join_blend(join, blend_frames, T, stats, norm):
    """Validate the join option (``join``, ``join_blend_frames`` of the rollout exporters); the blend in frames
    (None for ``"none"``)."""
    if check_export_join(join) == "none":
        return None
    if stats is not None and norm is None:
        raise ValueError("join: the join works on raw poses; it needs normalize_in_graph=True")
    n = join_blend_frames(T) if blend_frames is None else blend_frames
    if not isinstance(n, (int, np.integer)) or n < 1:
        raise ValueError(f"join_blend_frames: expected a positive integer, got {blend_frames!r}")
    return int(n)


def join_entry(metadata, join, T, frame_rate, blend, *, in_graph: bool):
    """``metadata`` with the ``join`` entry (:func:`deploy.join.join_metadata`) when ``join`` is not ``"none"``."""
    if join == "none" or blend is None:
        return metadata
    return {**dict(metadata or {}), "join": join_metadata(join, T, frame_rate, blend, in_graph)}


def _builder(name, dtype, opset, primitive):
    return GraphBuilder(name, dtype=dtype, opset=opset, primitive=primitive)


def _context_inputs(g, norm, P: int):
    """Graph inputs ``past (B, 2, P)``, ``target (B, 2, P)`` and their normalised forms."""
    past = g.input("past", ["B", 2, P])
    target = g.input("target", ["B", 2, P])
    return past, target, pose_in(g, past, norm, name="past_norm"), pose_in(g, target, norm, name="target_norm")


def pose_in(g, x, norm, *, name):
    return x if norm is None else standardize(g, x, norm[0], norm[1], name=name, wname="pose_norm")


def pose_out(g, x, norm, *, name):
    return x if norm is None else destandardize(g, x, norm[0], norm[1], name=name, wname="pose_norm")


# ------------------------------------------------------------------------------------------------ public
def export_qtg_init(params: Mapping[str, np.ndarray], config: QTGConfig = QTGConfig(), *, dtype=np.float32,
                    opset: int = OPSET, primitive: bool | None = None, normalization=None,
                    normalize_in_graph: bool = True, skeleton=None, frame_rate: float = 30.0,
                    metadata: Mapping | None = None) -> onnx.ModelProto:
    """The ``init`` model: ``init_state`` of ``refimpl.models.qtg`` (encodings of the context poses, zero state).

    Parameters
    ----------
    params : dict
        QTG parameters (``refimpl.models.qtg.param_shapes``), float32 or float64.
    config : QTGConfig
    dtype : float32 or float64
        Float type of the graph (float64 implies primitive operators, runnable in onnxruntime).
    opset : int
        Default-domain opset (17 default; 21 tested too).
    primitive : bool, optional
        Force primitive operators (see ``GraphBuilder``).
    normalization : (mean, std), optional
        Standardise inside the graph, so inputs and outputs are raw poses: shapes ``(P,)``, or ``(3,)`` for the
        root translation only (``refimpl.protocols.transition.normalize_poses``' ``root_mean``, ``root_std``).
    normalize_in_graph : bool
        With ``False`` the statistics only go to the metadata (``"in_graph": false``) and the graph works on
        normalised poses like the NumPy model.
    skeleton : refimpl.skeleton.Skeleton, dict or False, optional
        Written to the metadata (centimetres); default (``None``): :func:`default_skeleton`; ``False``: ``null``.
    frame_rate : float
        Written to the metadata.
    metadata : dict, optional
        Extra metadata entries (JSON-serialisable), added to or replacing the standard ones.

    Returns
    -------
    onnx.ModelProto
        Inputs ``past (B, 2, P)``, ``target (B, 2, P)``; outputs ``latent_prev (B, Z)``, ``pose (B, P)``,
        ``hidden (L, B, H)``, ``target_latent (B, 2, Z)``.
    """
    check_params(params, config)
    stats = check_normalization(normalization, config)
    norm = stats if normalize_in_graph else None
    P, Z, H, L = config.pose_size, config.latent_size, config.gru_hidden, config.gru_layers
    g = _builder("qtg_init", dtype, opset, primitive)
    past, target, past_n, target_n = _context_inputs(g, norm, P)
    latent_prev, pose, _, _, tl = _encode_context(g, past_n, target_n, params, config, name="init")
    hidden = _zero_hidden(g, past, config, name="init.hidden")
    g.output(latent_prev, "latent_prev", ["B", Z])
    g.output(pose_out(g, pose, norm, name="pose_raw") if norm is not None else pose, "pose", ["B", P])
    g.output(hidden, "hidden", [L, "B", H])
    g.output(tl, "target_latent", ["B", 2, Z])
    io = {"inputs": io_entries(("past", ["B", 2, P], "p_{-1}, p_0: the two poses before the transition"),
                        ("target", ["B", 2, P], "g1 = p_{T+1}, g2 = p_{T+2}: the two poses after it")),
          "outputs": io_entries(("latent_prev", ["B", Z], "E(p_{-1}); feed to step"),
                         ("pose", ["B", P], "p_0; feed to step"),
                         ("hidden", [L, "B", H], "GRU state s_0 = 0; feed to step"),
                         ("target_latent", ["B", 2, Z], "[E(g1), E(g2)]; feed to every step unchanged"))}
    meta = qtg_metadata(config, "init", io, stats, norm is not None, skeleton, frame_rate, g, "float", metadata)
    return g.model(metadata=meta, doc_string="QTG init: context encodings and zero GRU state",
                   producer_version=EXPORTER_VERSION)


def export_qtg_step(params: Mapping[str, np.ndarray], config: QTGConfig = QTGConfig(), *, dtype=np.float32,
                    opset: int = OPSET, primitive: bool | None = None, normalization=None,
                    normalize_in_graph: bool = True, skeleton=None, frame_rate: float = 30.0,
                    metadata: Mapping | None = None) -> onnx.ModelProto:
    """The ``step`` model: one frame of ``refimpl.models.qtg.step``, state in → state out.

    Parameters as :func:`export_qtg_init`.

    Returns
    -------
    onnx.ModelProto
        Inputs ``pose (B, P)``, ``latent_prev (B, Z)``, ``hidden (L, B, H)``, ``target_latent (B, 2, Z)``;
        outputs ``pose_next (B, P)``, ``latent_prev_next (B, Z)``, ``hidden_next (L, B, H)``.
    """
    check_params(params, config)
    stats = check_normalization(normalization, config)
    norm = stats if normalize_in_graph else None
    P, Z, H, L = config.pose_size, config.latent_size, config.gru_hidden, config.gru_layers
    g = _builder("qtg_step", dtype, opset, primitive)
    pose = g.input("pose", ["B", P])
    latent_prev = g.input("latent_prev", ["B", Z])
    hidden = g.input("hidden", [L, "B", H])
    target_latent = g.input("target_latent", ["B", 2, Z])
    e1, e2 = g.node("Split", [target_latent, g.ints([1, 1])], "target", axis=1, outputs=("e1", "e2"))
    e1 = g.node("Squeeze", [e1, g.ints([1])], "e1")                               # (B, Z)
    e2 = g.node("Squeeze", [e2, g.ints([1])], "e2")                               # (B, Z)
    e21 = g.node("Sub", [e2, e1], "e21")                                          # (B, Z)
    pose_n = pose_in(g, pose, norm, name="pose_norm")
    pose_next, z, hidden_new = _step(g, latent_prev, pose_n, hidden, e1, e21, params, config, name="step")
    g.output(pose_out(g, pose_next, norm, name="pose_next_raw"), "pose_next", ["B", P])
    g.output(z, "latent_prev_next", ["B", Z])
    g.output(hidden_new, "hidden_next", [L, "B", H])
    io = {"inputs": io_entries(("pose", ["B", P], "p_t (from init, then pose_next)"),
                        ("latent_prev", ["B", Z], "z_{t-1} (from init, then latent_prev_next)"),
                        ("hidden", [L, "B", H], "GRU state s_t (from init, then hidden_next)"),
                        ("target_latent", ["B", 2, Z], "[E(g1), E(g2)] from init")),
          "outputs": io_entries(("pose_next", ["B", P], "p_{t+1}, the generated frame"),
                         ("latent_prev_next", ["B", Z], "z_t = E(p_t)"),
                         ("hidden_next", [L, "B", H], "s_{t+1}"))}
    meta = qtg_metadata(config, "step", io, stats, norm is not None, skeleton, frame_rate, g, "float", metadata)
    return g.model(metadata=meta, doc_string="QTG step: one generated frame, state in -> state out",
                   producer_version=EXPORTER_VERSION)


def export_qtg_rollout(params: Mapping[str, np.ndarray], config: QTGConfig = QTGConfig(), *, T: int | None = None,
                       mode: str = "scan", dtype=np.float32, opset: int = OPSET, primitive: bool | None = None,
                       normalization=None, normalize_in_graph: bool = True, skeleton=None,
                       frame_rate: float = 30.0, metadata: Mapping | None = None, join: str = "none",
                       join_blend_frames: int | None = None) -> onnx.ModelProto:
    """The ``rollout`` model: a whole transition (``refimpl.models.qtg_fast.rollout_forward``) in one graph.

    Parameters
    ----------
    T : int, optional
        Frames to generate, fixed in the graph (default ``config.transition_length``).
    mode : {"scan", "loop", "unrolled"}
        ``scan`` (default): an ONNX ``Scan`` over a constant ``(T, 1)`` tick tensor, the state carried;
        ``loop``: an ONNX ``Loop`` with the state carried; ``unrolled``: T copies of the step (shared weights).
    join : {"none", "inertialize"}
        ``"inertialize"`` bakes :func:`refimpl.protocols.transition_join.inertialize_joins` into the graph after the
        network (``deploy/join.py``; raw poses, so it needs the statistics in the graph when there are any); the
        metadata's ``join`` entry says so. ``"none"`` (default): the network's frames.
    join_blend_frames : int, optional
        Frames of each blend (default :func:`refimpl.protocols.transition_join.join_blend_frames` of ``T``).
    Others as :func:`export_qtg_init`.

    Returns
    -------
    onnx.ModelProto
        Inputs ``past (B, 2, P)``, ``target (B, 2, P)``; output ``poses (B, T, P)`` (``p_1 … p_T``).
    """
    check_params(params, config)
    stats = check_normalization(normalization, config)
    norm = stats if normalize_in_graph else None
    T = config.transition_length if T is None else T
    if not isinstance(T, (int, np.integer)) or T < 1:
        raise ValueError(f"T: expected a positive integer number of frames, got {T!r}")
    if mode not in ROLLOUT_MODES:
        raise ValueError(f"mode: expected one of {ROLLOUT_MODES}, got {mode!r}")
    T = int(T)
    blend = join_blend(join, join_blend_frames, T, stats, norm)
    P, Z, H, L = config.pose_size, config.latent_size, config.gru_hidden, config.gru_layers
    g = _builder("qtg_rollout", dtype, opset, primitive)
    past, target, past_n, target_n = _context_inputs(g, norm, P)
    latent_prev, pose, e1, e21, _ = _encode_context(g, past_n, target_n, params, config, name="init")
    hidden = _zero_hidden(g, past, config, name="init.hidden")
    if mode == "unrolled":
        poses = []
        for t in range(T):
            pose, latent_prev, hidden = _step(g, latent_prev, pose, hidden, e1, e21, params, config,
                                              name=f"t{t:03d}")
            poses.append(pose)                                                    # (B, P)
        flat = poses[0] if T == 1 else g.node("Concat", poses, "poses_flat", axis=-1)  # (B, T·P)
        out = g.node("Reshape", [flat, g.ints([0, T, P])], "poses_n")            # (B, T, P)
    else:
        body = g.subgraph("body")
        shapes = [["B", Z], ["B", P], [L, "B", H]]
        if mode == "loop":
            body.input("body.iter", [], dtype=np.int64)
            cond_in = body.input("body.cond_in", [], dtype=np.bool_)
        s_in = [body.input(f"body.{k}_in", s) for k, s in zip(("latent_prev", "pose", "hidden"), shapes)]
        if mode == "scan":
            body.input("body.tick", [1])
        pose_next, z, hidden_new = _step(body, s_in[0], s_in[1], s_in[2], e1, e21, params, config, name="body.step")
        if mode == "loop":
            body.output(body.node("Identity", [cond_in], "body.cond"), "body.cond_out", [], dtype=np.bool_)
        body.output(z, "body.latent_prev_out", shapes[0])
        body.output(pose_next, "body.pose_out", shapes[1])
        body.output(hidden_new, "body.hidden_out", shapes[2])
        if mode == "loop":
            # per-iteration scan output flattened to 1-D (B·P,): onnxruntime stacks Loop scan outputs on a new
            # axis, the reference evaluator with np.vstack; the two agree only for 1-D values (spec/deploy.md §5)
            flat_pose = body.node("Reshape", ["body.pose_out", g.ints([-1])], "body.pose_flat")
            body.output(flat_pose, "body.pose_scan", ["BP"])
        else:
            body.output("body.pose_out", "body.pose_scan", shapes[1])
        carried = [latent_prev, pose, hidden]
        if mode == "loop":
            trip = g.constant("rollout.T", np.array(T, dtype=np.int64))
            cond = g.constant("rollout.cond", np.array(True))
            outs = g.node("Loop", [trip, cond] + carried, "rollout", body=body.graph(),
                          outputs=("latent_prev", "pose", "hidden", "poses_flat"))
            outs = outs[:-1] + (g.node("Reshape", [outs[-1], g.ints([T, -1, P])], "rollout.poses_tm"),)
        else:
            ticks = g.weight("rollout.ticks", np.zeros((T, 1)))
            outs = g.node("Scan", carried + [ticks], "rollout", body=body.graph(), num_scan_inputs=1,
                          outputs=("latent_prev", "pose", "hidden", "poses_tm"))
        out = g.node("Transpose", [outs[-1]], "poses_n", perm=[1, 0, 2])         # (B, T, P)
    out = pose_out(g, out, norm, name="poses_raw")
    if join == "inertialize":
        out = inertialize_joins(g, past, out, target, T, P, frame_rate, blend, name="join")
    g.output(out, "poses", ["B", T, P])
    io = {"inputs": io_entries(("past", ["B", 2, P], "p_{-1}, p_0: the two poses before the transition"),
                        ("target", ["B", 2, P], "g1 = p_{T+1}, g2 = p_{T+2}: the two poses after it")),
          "outputs": io_entries(("poses", ["B", T, P], "p_1 ... p_T, the generated transition"))}
    meta = qtg_metadata(config, "rollout", io, stats, norm is not None, skeleton, frame_rate, g, f"float.{mode}",
                        join_entry(metadata, join, T, frame_rate, blend, in_graph=True), T=T)
    return g.model(metadata=meta, doc_string=f"QTG rollout: {T} frames, {mode}", producer_version=EXPORTER_VERSION)


def export_qtg_join(config: QTGConfig = QTGConfig(), *, T: int | None = None, join: str = "inertialize",
                    join_blend_frames: int | None = None, dtype=np.float32, opset: int = OPSET,
                    primitive: bool | None = None, normalization=None, normalize_in_graph: bool = True,
                    skeleton=None, frame_rate: float = 30.0, metadata: Mapping | None = None) -> onnx.ModelProto:
    """The ``join`` model: the join option alone (``deploy.join.inertialize_joins``, spec/qtg.md §7.4), for a host
    that generates the T frames with ``init`` + ``step`` (the portable target, ``deploy/portable.py``).

    Returns
    -------
    onnx.ModelProto
        Inputs ``past (B, 2, P)``, ``poses (B, T, P)`` (the T generated raw frames), ``target (B, 2, P)``; output
        ``poses_joined (B, T, P)``. No weights: the same graph for every checkpoint of a config and ``T``.
    """
    stats = check_normalization(normalization, config)
    norm = stats if normalize_in_graph else None
    T = config.transition_length if T is None else T
    if not isinstance(T, (int, np.integer)) or isinstance(T, bool) or T < 1:
        raise ValueError(f"T: expected a positive integer number of frames, got {T!r}")
    T = int(T)
    blend = join_blend(join, join_blend_frames, T, stats, norm)
    if blend is None:
        raise ValueError("join: the join model needs a join mode other than 'none'")
    P = config.pose_size
    g = _builder("qtg_join", dtype, opset, primitive)
    past, poses, target = g.input("past", ["B", 2, P]), g.input("poses", ["B", T, P]), g.input("target", ["B", 2, P])
    g.output(inertialize_joins(g, past, poses, target, T, P, frame_rate, blend, name="join"), "poses_joined",
             ["B", T, P])
    io = {"inputs": io_entries(("past", ["B", 2, P], "p_{-1}, p_0, as fed to init (raw poses)"),
                               ("poses", ["B", T, P], "p_1 ... p_T: the T pose_next outputs of step, in order"),
                               ("target", ["B", 2, P], "g1, g2, as fed to init")),
          "outputs": io_entries(("poses_joined", ["B", T, P], "p_1 ... p_T with the join applied (unit "
                                 "quaternions)"))}
    meta = qtg_metadata(config, "join", io, stats, norm is not None, skeleton, frame_rate, g, f"join.{join}",
                        join_entry(metadata, join, T, frame_rate, blend, in_graph=True), T=T)
    return g.model(metadata=meta, doc_string=f"QTG join ({join}) of {T} generated frames",
                   producer_version=EXPORTER_VERSION)
