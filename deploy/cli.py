"""Command line of the deployment path: ``python -m deploy {export, run, info} ...`` (``spec/deploy.md`` §8).

``export CHECKPOINT OUT_DIR``
    Read a checkpoint (``refimpl.checkpoint.load_checkpoint``; a plain state-dict ``.npz`` also works) and export
    it, standardising inside the graphs with the root statistics the checkpoint stores (``--root-mean/--root-std``
    only for a checkpoint without them), with the exporter of the model it names (``deploy.models.EXPORTERS``;
    ``--model`` for a state dict, default ``qtg``): for QTG ``qtg_init.onnx``, ``qtg_step.onnx`` and ``qtg_rollout.onnx`` (validated, written
    atomically).
``run MODEL_DIR IN.bvh OUT.bvh --start S``
    Open the folder's models with the runtime of the model named in their metadata
    (``deploy.models.runtime_for_dir``); read a BVH, keep the 22-joint subset in centimetres at 30 fps
    (``refimpl.protocols.transition.load_source``, the same clip loading as ``refimpl``), replace frames ``S … S+T−1`` by a
    transition generated from frames ``S−2, S−1`` and ``S+T, S+T+1`` with the exported models, and write the
    result as BVH; prints the mean joint-position error against the original frames.
``info MODEL.onnx``
    Validate a model and print its inputs, outputs and metadata.

``main(argv)`` returns the exit status (0 success, 2 bad input), so the ``refimpl export`` subcommand can call it.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

__all__ = ["main"]


def _checkpoint_model(path, override: str | None) -> str:
    """The model name stored in a ``refimpl train`` checkpoint (``--model`` overrides; a state dict: ``qtg``)."""
    from refimpl.checkpoint import load_checkpoint

    if override:
        return override
    try:
        _, meta = load_checkpoint(path)
    except ValueError as exc:
        if "not a refimpl checkpoint" not in str(exc):
            raise
        return "qtg"
    return str(meta.get("model") or "qtg")


def _skeleton_from_bvh(path, joints: str):
    from refimpl.bvh import read_bvh
    from refimpl.rigs import RIGS, scale_skeleton, subset_22

    motion = read_bvh(path)
    keep, unit = RIGS[joints]
    skel, _ = subset_22(motion.skeleton, np.asarray(motion.rotations)[:1], keep)
    return scale_skeleton(skel, unit)


def _root_statistics(args, meta):
    """Root mean / std for the export: the checkpoint's (``refimpl train`` stores the training windows'
    ``root_mean``/``root_std`` in ``meta["model_config"]``), or ``--root-mean/--root-std`` for a checkpoint
    without them; ``None`` when neither (the models then take normalised poses)."""
    cfg = meta.get("model_config") if isinstance(meta.get("model_config"), dict) else {}
    stored = (cfg.get("root_mean"), cfg.get("root_std"))
    given = (args.root_mean, args.root_std)
    if (given[0] is None) != (given[1] is None):
        raise ValueError("--root-mean and --root-std: give both or neither")
    if stored[0] is not None and stored[1] is not None:
        if given[0] is not None and not (np.allclose(given[0], stored[0]) and np.allclose(given[1], stored[1])):
            raise ValueError(f"--root-mean/--root-std {given[0]} / {given[1]} differ from the statistics the "
                             f"network was trained with (stored in the checkpoint: {stored[0]} / {stored[1]}); "
                             "leave them out")
        return np.asarray(stored[0], dtype=np.float64), np.asarray(stored[1], dtype=np.float64)
    if given[0] is not None:
        return np.asarray(given[0], dtype=np.float64), np.asarray(given[1], dtype=np.float64)
    return None


def _cmd_export(args) -> int:
    from deploy.models import exporter

    entry = exporter(_checkpoint_model(args.checkpoint, args.model))
    params, config, meta = entry.load_checkpoint(args.checkpoint)
    normalization = _root_statistics(args, meta)
    if normalization is None:
        print("note: no root statistics in the checkpoint and no --root-mean/--root-std; the models take and "
              "return normalised poses (metadata normalization: null)", file=sys.stderr)
    skeleton = _skeleton_from_bvh(args.skeleton_bvh, args.joints) if args.skeleton_bvh else None
    dtype = {"float32": np.float32, "float64": np.float64}[args.dtype]
    extra = {"checkpoint": {"path": str(args.checkpoint), "step": meta.get("step")}}
    cfg = meta.get("model_config") if isinstance(meta.get("model_config"), dict) else {}
    if isinstance(cfg.get("fps"), (int, float)) and not isinstance(cfg.get("fps"), bool):
        extra["frame_rate"] = float(cfg["fps"])
    paths = entry.export_dir(params, config, args.out_dir, normalization=normalization, skeleton=skeleton,
                             opset=args.opset, dtype=dtype, mode=args.mode, T=args.frames, compact=args.compact,
                             metadata=extra)
    for role, p in paths.items():
        print(f"{role}: {p} ({p.stat().st_size / 1e6:.2f} MB)")
    return 0


def _cmd_run(args) -> int:
    from deploy.models import runtime_for_dir
    from refimpl.bvh import read_bvh_header, write_bvh
    from refimpl.motion import Motion
    from refimpl.protocols.transition import (TransitionSource, declared_rate, denormalize_poses, heading_from_root,
                                     load_source, make_windows, normalize_poses, window_to_world)

    rt = runtime_for_dir(args.model_dir, intra_op_threads=args.threads)
    some = rt.rollout_model or rt.step_model
    meta = some.metadata
    T = int(args.frames or meta["model"].get("transition_length") or meta["model"]["config"]["transition_length"])
    rate = args.source_fps or declared_rate(read_bvh_header(args.input).frame_time)
    source = TransitionSource(str(args.input), f"{args.joints}_bvh", float(rate), Path(args.input).stem)
    skel, clips = load_source(source, fps=args.fps, skip_start=0)  # 22 joints, cm, phase 0 at --fps
    rot, pos = clips[0]
    s = args.start
    if s < 2 or s + T + 2 > len(rot):
        raise ValueError(f"--start: expected 2 <= S <= {len(rot) - T - 2} for T = {T} at {args.fps:g} fps "
                         f"({len(rot)} frames), got {s}")
    context = [s - 2, s - 1, s + T, s + T + 1]               # p_-1, p_0, g1, g2: never the frames to replace
    window = make_windows(rot[context], pos[context], length=4)[0]   # (4, P), the metadata's input_transform
    norm = meta.get("normalization")
    past, target = window[None, :2], window[None, 2:]
    if norm is not None and not norm["in_graph"]:
        m, sd = np.asarray(norm["mean"][:3]), np.asarray(norm["std"][:3])
        gen = denormalize_poses(rt.transition(normalize_poses(past, m, sd), normalize_poses(target, m, sd), T),
                                m, sd)[0]
    else:
        gen = rt.transition(past, target, T)[0]                          # (T, P)
    h = heading_from_root(rot[s - 2, 0])
    new_pos, new_rot = window_to_world(gen.astype(np.float64), h, pos[s - 2])
    truth = skel.forward_kinematics(rot[s:s + T], pos[s:s + T])
    out_rot, out_pos = rot.copy(), pos.copy()
    out_rot[s:s + T], out_pos[s:s + T] = new_rot, new_pos
    name = meta["model"]["name"]
    result = Motion(skel, out_rot, out_pos, frame_time=1.0 / args.fps, name=f"{Path(args.input).stem}_{name}")
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
            value = {"in_graph": value["in_graph"], "model_io": value.get("model_io"),
                     "root_mean": value["mean"][:3], "root_std": value["std"][:3]}
        elif key in ("input_transform", "output_transform") and isinstance(value, dict):
            print(f"  {key}: {value.get('summary', '')}")
            for step in value.get("steps", []):
                print(f"    {step}")
            continue
        elif key == "io":
            continue
        print(f"  {key}: {json.dumps(value)}")
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m deploy",
                                description="Export trained networks to ONNX and run exported models (the runtime "
                                            "is chosen by the model name in the files' metadata).")
    sub = p.add_subparsers(dest="command", required=True)
    e = sub.add_parser("export", help="export a checkpoint to ONNX with its model's exporter (qtg: init, step, "
                                      "rollout)")
    e.add_argument("checkpoint")
    e.add_argument("out_dir")
    e.add_argument("--model", default=None, help="exporter (default: the model named in the checkpoint; a plain "
                                                  "state dict: qtg)")
    e.add_argument("--root-mean", type=float, nargs=3, default=None,
                   help="root translation mean (x y z, cm) of the training windows, only for a checkpoint that "
                        "does not store it (a `refimpl train` checkpoint does, and it is used)")
    e.add_argument("--root-std", type=float, nargs=3, default=None, help="root translation std (x y z, cm); as "
                                                                          "--root-mean")
    e.add_argument("--skeleton-bvh", default=None, help="BVH whose 22-joint subset goes into the metadata "
                                                        "(default: the CMU 22-joint rig of the embedded sample)")
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
