"""QTG's commands of ``python -m deploy`` (``spec/deploy.md`` §8): its export options and export from a checkpoint
or a plain state dict, and ``run`` (a transition generated inside a BVH clip, optionally with the join option
and foot locking as NumPy post-processes, ``--join``). Reached through QTG's entry of the exporter table
(``deploy.models.qtg_io``); ``deploy/cli.py`` names no model.

Shape legend: T transition frames, P pose size.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from refimpl.bounds import bounded_float

__all__ = ["add_export_options", "add_run_options", "apply_join", "export_checkpoint", "run_command"]


def add_export_options(group) -> None:
    """QTG's options of ``python -m deploy export`` (all default ``None``)."""
    group.add_argument("--root-mean", type=float, nargs=3, default=None,
                       help="qtg: root translation mean (x y z, cm) of the training windows, only for a checkpoint "
                            "that does not store it (a `refimpl train` checkpoint does, and it is used)")
    group.add_argument("--root-std", type=float, nargs=3, default=None, help="qtg: root translation std (x y z, "
                                                                              "cm); as --root-mean")
    group.add_argument("--skeleton-bvh", default=None, help="qtg: BVH whose 22-joint subset goes into the metadata "
                                                            "(default: the CMU 22-joint rig of the embedded sample)")
    group.add_argument("--joints", choices=("cmu", "salsa"), default=None, help="qtg: rig of --skeleton-bvh "
                                                                                "(default cmu)")
    group.add_argument("--compact", choices=("float32", "int8", "int4"), default=None,
                       help="qtg: write the rollout model as the compact deployment variant with these weights "
                            "(onnxruntime only for int8/int4; spec/deploy.md §5.4)")


def add_run_options(group) -> None:
    """QTG's options of ``python -m deploy run``."""
    group.add_argument("--joints", choices=("cmu", "salsa"), default=None, help="qtg: rig of the BVH (default cmu)")
    group.add_argument("--source-fps", type=bounded_float("fps"), default=None,
                       help="qtg: override the BVH frame rate")
    group.add_argument("--join", choices=("none", "inertialize", "inertialize+footlock"), default=None,
                       help="qtg: inertialize: the join option (spec/qtg.md 7.4) in NumPy unless the models were "
                            "exported with it; inertialize+footlock: then pin the planted feet by two-bone IK (7.5), "
                            "as refimpl generate --join (default: the frames as the models return them)")


def apply_join(join, runtime, past, poses, target, skeleton, fps: float) -> np.ndarray:
    """``--join`` of ``deploy run`` on the generated ``poses (B, T, P)`` (un-normalised, window frame, cm).

    ``None``: ``poses`` as they are. ``"inertialize"``: :func:`~refimpl.protocols.transition_join.inertialize_joins`
    at frame time ``1 / fps`` unless the models' metadata ``join`` says they already apply it (the rollout graph
    or the runtime's step path). ``"inertialize+footlock"``: that, then
    :func:`~refimpl.protocols.transition_footlock.footlock` with ``skeleton`` (spec/qtg.md §7.5): the numbers
    of ``refimpl generate --join inertialize+footlock`` on the same frames.

    Raises
    ------
    ValueError
        ``"none"`` for models exported with the join option inside (it cannot be taken out).
    """
    from refimpl.protocols.transition_footlock import footlock
    from refimpl.protocols.transition_join import inertialize_joins

    if join is None:
        return poses
    exported = ((runtime.rollout_model or runtime.step_model).metadata.get("join") or {}).get("mode", "none")
    if join == "none":
        if exported != "none":
            raise ValueError(f"--join none: these models were exported with the join option {exported!r}; "
                             "export without --join for the network's own frames")
        return poses
    dt = 1.0 / fps
    joined = poses if exported != "none" else inertialize_joins(past, poses, target, dt=dt)
    if join == "inertialize+footlock":
        joined = footlock(past, joined, target, skeleton, dt=dt)
    return np.asarray(joined, dtype=np.float64)


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


def export_checkpoint(entry, args) -> dict:
    """``python -m deploy export`` for QTG: a ``refimpl train`` checkpoint or a plain state dict; returns
    role -> Path."""
    params, config, meta = entry.load_checkpoint(args.checkpoint)
    normalization = _root_statistics(args, meta)
    if normalization is None:
        print("note: no root statistics in the checkpoint and no --root-mean/--root-std; the models take and "
              "return normalised poses (metadata normalization: null)", file=sys.stderr)
    skeleton = _skeleton_from_bvh(args.skeleton_bvh, args.joints or "cmu") if args.skeleton_bvh else None
    dtype = {"float32": np.float32, "float64": np.float64}[args.dtype]
    extra = {"checkpoint": {"path": str(args.checkpoint), "step": meta.get("step")}}
    cfg = meta.get("model_config") if isinstance(meta.get("model_config"), dict) else {}
    if isinstance(cfg.get("fps"), (int, float)) and not isinstance(cfg.get("fps"), bool):
        extra["frame_rate"] = float(cfg["fps"])
    target = getattr(args, "target", "default")
    return entry.export_dir(params, config, args.out_dir, normalization=normalization, skeleton=skeleton,
                            opset=args.opset, dtype=dtype, mode=args.mode or "scan", T=args.frames,
                            compact=args.compact, metadata=extra, **({"target": target} if target != "default" else {}))


def run_command(runtime, args) -> int:
    """``python -m deploy run DIR IN.bvh OUT.bvh --start S [--join MODE]``: frames ``S … S+T−1`` of the clip
    replaced by a transition generated from frames ``S−2, S−1`` and ``S+T, S+T+1`` (then :func:`apply_join`);
    prints the mean joint-position error."""
    from refimpl.bounds import check_count, check_number
    from refimpl.bvh import read_bvh_header
    from refimpl.bvh_write import write_bvh
    from refimpl.errors import existing_file, reading
    from refimpl.motion import Motion
    from refimpl.protocols.transition import (TransitionSource, declared_rate, denormalize_poses,
                                              heading_from_root, load_source, make_windows, normalize_poses,
                                              window_to_world)

    if args.start is None:
        raise ValueError("--start: required for qtg (the first generated frame)")
    rt = runtime
    some = rt.rollout_model or rt.step_model
    meta = some.metadata
    T = args.frames
    if T is None:
        model = meta["model"]  # a JSON object with a name (deploy.runtime checks it on loading)
        stored = model.get("transition_length") or (model.get("config") or {}).get("transition_length")
        with reading(args.model_dir):
            T = check_count(stored, "metadata model.transition_length", "transition_length")
    fps = args.fps or 30.0
    joints = args.joints or "cmu"
    with reading(existing_file(args.input)):  # a damaged or foreign BVH is a bad input file: exit 3
        rate = args.source_fps or check_number(declared_rate(read_bvh_header(args.input).frame_time),
                                               "its declared frame rate", "fps")
        source = TransitionSource(str(args.input), f"{joints}_bvh", float(rate), Path(args.input).stem)
        skel, clips = load_source(source, fps=fps, skip_start=0)  # 22 joints, cm, phase 0 at --fps
    rot, pos = clips[0]
    s = args.start
    if s < 2 or s + T + 2 > len(rot):
        raise ValueError(f"--start: expected 2 <= S <= {len(rot) - T - 2} for T = {T} at {fps:g} fps "
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
    gen = apply_join(args.join, rt, past, gen[None].astype(np.float64), target, skel, fps)[0]
    h = heading_from_root(rot[s - 2, 0])
    new_pos, new_rot = window_to_world(gen.astype(np.float64), h, pos[s - 2])
    truth = skel.forward_kinematics(rot[s:s + T], pos[s:s + T])
    out_rot, out_pos = rot.copy(), pos.copy()
    out_rot[s:s + T], out_pos[s:s + T] = new_rot, new_pos
    name = meta["model"]["name"] + {None: "", "none": "", "inertialize": "+join",
                                    "inertialize+footlock": "+join+footlock"}[args.join]
    result = Motion(skel, out_rot, out_pos, frame_time=1.0 / fps, name=f"{Path(args.input).stem}_{name}")
    err = np.linalg.norm(skel.forward_kinematics(new_rot, new_pos) - truth, axis=-1).mean()
    write_bvh(args.output, result)
    print(f"generated frames {s}..{s + T - 1} of {len(rot)} at {fps:g} fps; mean joint position error vs "
          f"the original: {err:.3f} cm; wrote {args.output}")
    return 0
