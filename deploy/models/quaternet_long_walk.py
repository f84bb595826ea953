"""``python -m deploy run`` of QuaterNet long-term along a path (spec/deploy.md §8, §12): the exported step graph
(``quaternet-long_step.onnx`` + ``quaternet-long_h0.npy`` + ``quaternet-long_seed.npy``) and pace graph
(``quaternet-long_pace.onnx``, in the same folder or ``--pace DIR``) in onnxruntime, walked by the same loop as
``refimpl generate --model quaternet-long`` (:func:`refimpl.models.quaternet_long_walk.walk_path`, the pace
tracks by :func:`refimpl.models.pace.predict_with`)::

    python -m deploy run long/ circle:r=3 walk.bvh --pace pace/ --speed walk --seconds 10

INPUT is the path, as ``refimpl generate``'s ``--path`` takes it: ``circle[:r=M]``, ``figure8[:size=M]``,
``line-turn[:turn=DEG]`` or a CSV file of ``x,z`` points in metres (a ``.npy`` INPUT runs the step model on given
frames instead: :func:`deploy.models.run_commands.run_locomotion`). OUTPUT ``.bvh``: the walk in centimetres
(:func:`~refimpl.tasks.locomotion_generate.write_outputs`, End Sites added); ``.npy``: frames ``(N, 4J + 3)``,
the J unit local quaternions ``(w, x, y, z)`` then the root position ``(x, y, z)`` in QuaterNet units.

Everything comes from the exported files and their metadata (skeleton, seed clip, ``dq_scale``); nothing from
a checkpoint. Checked before any work (one line, ``deploy/cli.py``'s exit codes): option values and the path
(2; a missing or malformed path CSV: 3), the output's kind (2), the pace folder and the files beside the step
model (3).

Shape legend: N generated frames, J joints, P seed frames, L layers, H hidden.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

__all__ = ["walk_options_given", "run_walk", "walk_exported"]

_OPTIONS = ("pace", "speed", "seconds", "controls")


def walk_options_given(args) -> list:
    """The walk's options set on the command line (``--pace``, ``--speed``, ...)."""
    return [f"--{k}" for k in _OPTIONS if getattr(args, k, None) is not None]


def _seconds(text) -> float:
    from refimpl.errors import UsageError

    if text is None:
        return 10.0
    try:
        return float(text)
    except (TypeError, ValueError):
        raise UsageError(f"--seconds {text!r}: expected a number of seconds") from None


def _pace_runtime(runtime, args):
    """The runtime holding the pace graph: ``--pace DIR``, else MODEL_DIR's; ``BadInputError`` when there is
    none or the folder holds another network."""
    from refimpl.errors import BadInputError

    from deploy.models import model_name_of_dir

    if args.pace is None:
        if runtime.pace_graph is None:
            raise BadInputError(f"{args.model_dir}: no quaternet-long_pace.onnx (or _pace_step.onnx); pass --pace DIR (a folder written "
                                "by `python -m deploy export PACE_CHECKPOINT DIR`)")
        return runtime
    d = Path(args.pace)
    if not d.is_dir():
        raise BadInputError(f"--pace {args.pace}: no such folder of exported models")
    try:
        name = model_name_of_dir(d)
    except ValueError as exc:
        raise BadInputError(f"--pace {args.pace}: {exc}") from None
    if name != "quaternet-long":
        raise BadInputError(f"--pace {args.pace}: holds the models of {name}, not quaternet-long's pace network")
    try:
        pace_rt = type(runtime).from_dir(d, intra_op_threads=getattr(args, "threads", 1))
    except ValueError as exc:
        raise BadInputError(f"--pace {args.pace}: {exc}") from None
    if pace_rt.pace_graph is None:
        raise BadInputError(f"--pace {args.pace}: no quaternet-long_pace.onnx (or _pace_step.onnx) in the folder")
    return pace_rt


def _step_parts(runtime, model_dir):
    """``(skeleton, seed (P, 4J + 8), dual, dq_scale)`` of the exported step model; ``BadInputError`` for a
    folder without a step model, its seed clip or its skeleton (exported by an older version)."""
    from refimpl.errors import BadInputError
    from refimpl.skeleton import Skeleton

    if runtime.step_model is None:
        raise BadInputError(f"{model_dir}: no quaternet-long_step.onnx (a walk needs the pose network's step)")
    meta = runtime.step_model.metadata
    if runtime.h0 is None:
        raise BadInputError(f"{model_dir}: no quaternet-long_h0.npy beside the step model")
    if runtime.seed is None or not isinstance(meta.get("skeleton"), dict):
        raise BadInputError(f"{model_dir}: the export has no seed clip (quaternet-long_seed.npy) or no skeleton in "
                            "its metadata (exported by an older version); export the checkpoint again")
    sk = meta["skeleton"]
    try:
        skeleton = Skeleton(sk["parents"], np.asarray(sk["offsets"], np.float64), names=sk["names"])
    except (KeyError, TypeError, ValueError) as exc:
        raise BadInputError(f"{model_dir}: the step model's metadata skeleton is malformed ({exc})") from None
    J = skeleton.num_joints
    if runtime.seed.shape[1] != 4 * J + 8:
        raise BadInputError(f"{model_dir}: quaternet-long_seed.npy has frames of {runtime.seed.shape[1]} values, "
                            f"expected 4 J + 8 = {4 * J + 8} for the skeleton's {J} joints")
    dual = (meta.get("representation") or {}).get("kind") == "quaternet_long_dq"
    dq_scale = meta.get("dq_scale", 1.0 if not dual else None)
    if dual and not isinstance(dq_scale, (int, float)):
        raise BadInputError(f"{model_dir}: a dual-quaternion step model without dq_scale in its metadata (exported "
                            "by an older version); export the checkpoint again")
    return skeleton, runtime.seed, dual, float(dq_scale)


def walk_exported(runtime, pace_runtime, path, speed: float, frames: int, model_dir=""):
    """The walk of ``refimpl generate --model quaternet-long`` with the exported graphs: the pace tracks from
    ``pace_runtime.pace`` (:func:`refimpl.models.pace.predict_with`), the loop of
    :func:`~refimpl.models.quaternet_long_walk.walk_path` with ``runtime.step`` from the learned ``h0``.

    Parameters
    ----------
    runtime : :class:`deploy.models.quaternet_long_io.Runtime` with the step model, ``h0`` and the seed clip
    pace_runtime : one with the pace model
    path : refimpl.splines.Spline in QuaterNet units; speed : units per frame; frames : N

    Returns
    -------
    refimpl.models.quaternet_long_walk.GeneratedWalk
    """
    from refimpl.models import pace
    from refimpl.models.quaternet_long_walk import walk_path
    from refimpl.protocols.locomotion_data import FPS

    skeleton, seed, dual, dq_scale = _step_parts(runtime, model_dir)
    J, P = skeleton.num_joints, seed.shape[0]
    points = float((pace_runtime.pace_graph.metadata.get("representation") or {}).get("points_per_unit", 5.0))
    tracks = pace.predict_with(pace_runtime.pace, path, speed, points_per_unit=points, dtype=np.float32)
    return walk_path(lambda x, h: runtime.step(x, h), runtime.initial_state(1), tracks, skeleton,
                     seed[:, :4 * J].reshape(P, J, 4).astype(np.float64), seed[:, 4 * J:].astype(np.float64),
                     frames, dual=dual, dq_scale=dq_scale, dtype=np.float32, fps=FPS)


def run_walk(runtime, args) -> int:
    """``run DIR PATH OUT.bvh|OUT.npy [--pace DIR] [--speed S] [--seconds T] [--controls C.json]``."""
    from refimpl.errors import BadInputError, UsageError
    from refimpl.tasks.locomotion import describe_walk, short_walk_warning, walk_options
    from refimpl.tasks.locomotion_generate import write_outputs

    from deploy.models.entry_io import write_npy

    out = str(args.output)
    kind = Path(out).suffix.lower()
    if kind not in (".bvh", ".npy"):
        raise UsageError(f"output {out!r}: a quaternet-long walk writes .bvh (centimetres) or .npy frames")
    for flag in ("--start", "--frames"):
        if getattr(args, flag[2:], None) is not None:
            raise UsageError(f"{flag}: not an option of a quaternet-long walk (its length is --seconds)")
    text = str(args.input)
    if Path(text).suffix.lower() != ".csv" and Path(text).is_file():
        raise BadInputError(f"{text}: expected a path (circle[:r=M], figure8[:size=M], line-turn[:turn=DEG], a .csv "
                            "of x,z points) or .npy frames with controls")
    seconds = _seconds(args.seconds)
    path, speed, frames = walk_options(text, args.speed or "walk", seconds)
    pace_rt = _pace_runtime(runtime, args)
    _step_parts(runtime, args.model_dir)              # every file checked before the walk and before any write
    try:
        walk = walk_exported(runtime, pace_rt, path, speed, frames, args.model_dir)
    except ValueError as exc:                          # e.g. a path CSV too short for one frame: a bad file
        raise (BadInputError if Path(text).suffix.lower() == ".csv" else UsageError)(f"{text}: {exc}") from None
    m = walk.motion
    if kind == ".npy":
        write_npy(out, np.concatenate([m.rotations.reshape(m.num_frames, -1), m.root_positions], axis=1))
        if args.controls:
            write_outputs(walk, controls=args.controls)
        what = f"frames ({m.num_frames}, {4 * m.num_joints + 3}): [J quaternions | root x, y, z], QuaterNet units"
    else:
        write_outputs(walk, bvh=out, controls=args.controls)
        what = describe_walk(walk)
    warning = short_walk_warning(walk, seconds, given=args.seconds is not None)
    if warning:
        print(f"python -m deploy run: warning: {warning}", file=sys.stderr, flush=True)
    print(f"wrote {out}: {what}" + (f"; controls {args.controls}" if args.controls else ""))
    return 0
