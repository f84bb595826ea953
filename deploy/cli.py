"""Command line of the deployment path: ``python -m deploy {export, run, info} ...`` (``spec/deploy.md`` §8).

``export CHECKPOINT OUT_DIR``
    Read a QTG checkpoint (``refimpl.checkpoint.load_checkpoint``; a plain state-dict ``.npz`` also works),
    export ``qtg_init.onnx``, ``qtg_step.onnx`` and ``qtg_rollout.onnx`` (validated, written atomically).
``run MODEL_DIR IN.bvh OUT.bvh --start S``
    Read a BVH, keep the 22-joint subset in centimetres at 30 fps (as ``refimpl.transitions``), replace frames
    ``S … S+T−1`` by a transition generated from frames ``S−2, S−1`` and ``S+T, S+T+1`` with the exported
    models, and write the result as BVH; prints the mean joint-position error against the original frames.
``info MODEL.onnx``
    Validate a model and print its inputs, outputs and metadata.

``main(argv)`` returns the exit status (0 success, 2 bad input), so the ``refimpl export`` subcommand can call it.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["main", "load_qtg_checkpoint", "export_qtg_dir"]


def load_qtg_checkpoint(path):
    """``(params, config, meta)`` from a QTG checkpoint (``refimpl.checkpoint``) or a plain state-dict ``.npz``.

    Parameters are the arrays named ``param.<name>`` (training checkpoints) or all arrays (state dicts); the
    config comes from ``meta["model_config"]`` (unknown keys ignored), else ``QTGConfig()``.
    """
    from refimpl.checkpoint import load_checkpoint, load_state_dict_npz
    from refimpl.models.qtg import QTGConfig

    try:
        arrays, meta = load_checkpoint(path)
    except ValueError as exc:
        if "not a refimpl checkpoint" not in str(exc):
            raise
        arrays, meta = load_state_dict_npz(path), {}
    params = {k[len("param."):]: v for k, v in arrays.items() if k.startswith("param.")} or dict(arrays)
    fields = {f.name for f in dataclasses.fields(QTGConfig)}
    cfg = {k: v for k, v in (meta.get("model_config") or {}).items() if k in fields}
    return params, QTGConfig(**cfg), meta


def export_qtg_dir(params, config, out_dir, *, normalization=None, skeleton=None, opset=None, dtype=np.float32,
                   mode: str = "scan", T: int | None = None, metadata=None,
                   compact: str | None = None) -> dict[str, Path]:
    """Export, validate and atomically write ``qtg_init/step/rollout.onnx`` into ``out_dir``; return the paths.

    ``compact`` (``"float32"``, ``"int8"`` or ``"int4"``; float32 graphs only) writes the rollout model as the
    compact deployment variant with those weights (``deploy.qtg_compact``, ``spec/deploy.md`` §5.4) instead of
    the ``mode`` translation; the init and step models are unchanged.
    """
    from deploy.graph import OPSET, save_model
    from deploy.qtg import export_qtg_init, export_qtg_rollout, export_qtg_step
    from deploy.qtg_compact import export_qtg_rollout_compact
    from deploy.quantize import WEIGHT_FORMATS
    from deploy.validate import validate_model

    if compact is not None:
        if compact not in WEIGHT_FORMATS:
            raise ValueError(f"compact: expected one of {WEIGHT_FORMATS} or None, got {compact!r}")
        if np.dtype(dtype) != np.float32:
            raise ValueError(f"compact: the compact rollout is a float32 graph, got dtype {np.dtype(dtype)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    kw = dict(dtype=dtype, opset=OPSET if opset is None else opset, normalization=normalization,
              skeleton=skeleton, metadata=metadata)
    if compact is None:
        rollout = export_qtg_rollout(params, config, T=T, mode=mode, **kw)
    else:
        rollout = export_qtg_rollout_compact(params, config, T=T, weights=compact, opset=kw["opset"],
                                             normalization=normalization, skeleton=skeleton, metadata=metadata)
    models = {"init": export_qtg_init(params, config, **kw), "step": export_qtg_step(params, config, **kw),
              "rollout": rollout}
    paths = {}
    for role, m in models.items():
        validate_model(m)
        paths[role] = out / f"qtg_{role}.onnx"
        save_model(m, paths[role])
    return paths


def _skeleton_from_bvh(path, joints: str):
    from refimpl.bvh import read_bvh
    from refimpl.transitions import (CMU_22_JOINTS, CMU_UNIT_CM, SALSA_22_JOINTS, SALSA_UNIT_CM, scale_skeleton,
                                     subset_22)

    motion = read_bvh(path)
    keep, unit = {"cmu": (CMU_22_JOINTS, CMU_UNIT_CM), "salsa": (SALSA_22_JOINTS, SALSA_UNIT_CM)}[joints]
    skel, _ = subset_22(motion.skeleton, np.asarray(motion.rotations)[:1], keep)
    return scale_skeleton(skel, unit)


def _cmd_export(args) -> int:
    params, config, meta = load_qtg_checkpoint(args.checkpoint)
    normalization = None
    mean = args.root_mean if args.root_mean is not None else meta.get("root_mean")
    std = args.root_std if args.root_std is not None else meta.get("root_std")
    if (mean is None) != (std is None):
        raise ValueError("--root-mean and --root-std: give both or neither")
    if mean is not None:
        normalization = (np.asarray(mean, dtype=np.float64), np.asarray(std, dtype=np.float64))
    else:
        print("note: no root statistics; the models take and return normalised poses", file=sys.stderr)
    skeleton = _skeleton_from_bvh(args.skeleton_bvh, args.joints) if args.skeleton_bvh else None
    dtype = {"float32": np.float32, "float64": np.float64}[args.dtype]
    paths = export_qtg_dir(params, config, args.out_dir, normalization=normalization, skeleton=skeleton,
                           opset=args.opset, dtype=dtype, mode=args.mode, T=args.frames, compact=args.compact,
                           metadata={"checkpoint": {"path": str(args.checkpoint), "step": meta.get("step")}})
    for role, p in paths.items():
        print(f"{role}: {p} ({p.stat().st_size / 1e6:.2f} MB)")
    return 0


def _to_world(poses_rel, h, r0):
    """Inverse of ``make_windows``' root-relative transform: ``r = R(h) r' + r0``, ``q_root = h ⊗ q'_root``."""
    from refimpl.quat import quat_mul, quat_normalize, quat_rotate
    from refimpl.transitions import split_pose

    root, quats = split_pose(poses_rel)                                  # (T, 3), (T, J, 4)
    quats = quat_normalize(quats)
    quats[:, 0] = quat_mul(h, quats[:, 0])
    return quat_rotate(h, root) + r0, quats


def _cmd_run(args) -> int:
    from deploy.runtime import QTGRuntime
    from refimpl.bvh import read_bvh, write_bvh
    from refimpl.motion import Motion
    from refimpl.transitions import (CMU_22_JOINTS, CMU_UNIT_CM, SALSA_22_JOINTS, SALSA_UNIT_CM,
                                     heading_from_root, make_windows, normalize_poses, denormalize_poses,
                                     scale_skeleton, subset_22)

    rt = QTGRuntime.from_dir(args.model_dir, intra_op_threads=args.threads)
    some = rt.rollout_model or rt.step_model
    meta = some.metadata
    T = int(args.frames or meta["model"].get("transition_length") or meta["model"]["config"]["transition_length"])
    motion = read_bvh(args.input, frame_time=None if args.source_fps is None else 1.0 / args.source_fps)
    keep, unit = {"cmu": (CMU_22_JOINTS, CMU_UNIT_CM), "salsa": (SALSA_22_JOINTS, SALSA_UNIT_CM)}[args.joints]
    skel, rot = subset_22(motion.skeleton, np.asarray(motion.rotations), keep)
    skel = scale_skeleton(skel, unit)
    pos = np.asarray(motion.root_positions) * unit
    k = int(round(motion.fps / args.fps))
    if k < 1 or abs(motion.fps / args.fps - k) > 1e-3 * k:  # BVH frame times are rounded (0.008333)
        raise ValueError(f"--fps: the file's rate {motion.fps:g} must be an integer multiple of {args.fps:g}")
    rot, pos = rot[::k], pos[::k]
    s = args.start
    if s < 2 or s + T + 2 > len(rot):
        raise ValueError(f"--start: expected 2 <= S <= {len(rot) - T - 2} for T = {T} at {args.fps:g} fps "
                         f"({len(rot)} frames), got {s}")
    window = make_windows(rot[s - 2:s + T + 2], pos[s - 2:s + T + 2], length=T + 4)[0]   # (T + 4, P)
    norm = meta.get("normalization")
    past, target = window[None, :2], window[None, -2:]
    if norm is not None and not norm["in_graph"]:
        m, sd = np.asarray(norm["mean"][:3]), np.asarray(norm["std"][:3])
        gen = denormalize_poses(rt.transition(normalize_poses(past, m, sd), normalize_poses(target, m, sd), T),
                                m, sd)[0]
    else:
        gen = rt.transition(past, target, T)[0]                          # (T, P)
    h = heading_from_root(rot[s - 2, 0])
    new_pos, new_rot = _to_world(gen.astype(np.float64), h, pos[s - 2])
    truth = skel.forward_kinematics(rot[s:s + T], pos[s:s + T])
    out_rot, out_pos = rot.copy(), pos.copy()
    out_rot[s:s + T], out_pos[s:s + T] = new_rot, new_pos
    result = Motion(skel, out_rot, out_pos, frame_time=1.0 / args.fps, name=f"{motion.name}_qtg")
    err = np.linalg.norm(skel.forward_kinematics(new_rot, new_pos) - truth, axis=-1).mean()
    write_bvh(args.output, result)
    print(f"generated frames {s}..{s + T - 1} of {len(rot)} at {args.fps:g} fps; mean joint position error vs "
          f"the original: {err:.3f} cm; wrote {args.output}")
    return 0


def _cmd_info(args) -> int:
    from deploy.runtime import load_model

    m = load_model(args.model)
    for title, entries in (("inputs", m.inputs), ("outputs", m.outputs)):
        print(f"{title}:")
        for n, shape, t in entries:
            print(f"  {n} {tuple(shape)} {None if t is None else np.dtype(t).name}")
    print("metadata:")
    for key, value in sorted(m.metadata.items()):
        if key == "skeleton" and value is not None:
            value = {"joints": len(value["names"]), "names": value["names"]}
        elif key == "normalization" and value is not None:
            value = {"in_graph": value["in_graph"], "root_mean": value["mean"][:3], "root_std": value["std"][:3]}
        elif key == "io":
            continue
        print(f"  {key}: {json.dumps(value)}")
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m deploy", description="Export QTG to ONNX and run exported models.")
    sub = p.add_subparsers(dest="command", required=True)
    e = sub.add_parser("export", help="export a QTG checkpoint to ONNX (init, step, rollout)")
    e.add_argument("checkpoint")
    e.add_argument("out_dir")
    e.add_argument("--root-mean", type=float, nargs=3, default=None, help="root translation mean (x y z)")
    e.add_argument("--root-std", type=float, nargs=3, default=None, help="root translation std (x y z)")
    e.add_argument("--skeleton-bvh", default=None, help="BVH whose 22-joint subset goes into the metadata")
    e.add_argument("--joints", choices=("cmu", "salsa"), default="cmu")
    e.add_argument("--opset", type=int, default=None)
    e.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    e.add_argument("--mode", choices=("scan", "loop", "unrolled"), default="scan")
    e.add_argument("--compact", choices=("float32", "int8", "int4"), default=None,
                   help="write the rollout model as the compact deployment variant with these weights "
                        "(onnxruntime only for int8/int4; spec/deploy.md §5.4)")
    e.add_argument("--frames", type=int, default=None, help="T of the rollout model (default: the config's)")
    e.set_defaults(func=_cmd_export)
    r = sub.add_parser("run", help="generate a transition inside a BVH clip with exported models")
    r.add_argument("model_dir")
    r.add_argument("input")
    r.add_argument("output")
    r.add_argument("--start", type=int, required=True, help="first generated frame (at --fps)")
    r.add_argument("--frames", type=int, default=None, help="T (default: the models')")
    r.add_argument("--joints", choices=("cmu", "salsa"), default="cmu")
    r.add_argument("--fps", type=float, default=30.0)
    r.add_argument("--source-fps", type=float, default=None, help="override the BVH frame rate")
    r.add_argument("--threads", type=int, default=1)
    r.set_defaults(func=_cmd_run)
    i = sub.add_parser("info", help="validate a model and print its contract")
    i.add_argument("model")
    i.set_defaults(func=_cmd_info)
    return p


def main(argv=None) -> int:
    """Entry point; returns 0 on success and 2 (with a message on stderr) on bad input or files."""
    args = _parser().parse_args(argv)
    try:
        return int(args.func(args))
    except (ValueError, FileNotFoundError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
