"""``python -m deploy run`` for the models other than QTG (``spec/deploy.md`` §8), each reached through its entry of
the exporter table (``run_command``, ``add_run_options``), and ``export`` of a ``refimpl train`` checkpoint as
``refimpl export`` does it (:func:`export_trained`).

* :func:`run_prediction` — QuaterNet (recurrent and convolutional): a prefix of an exp-map ``.txt`` → the next
  ``k`` frames; a BVH of prefix + prediction (the dataset's skeleton, root at the origin), or ``.npy`` of the
  predicted joint quaternions ``(k, J, 4)``;
* :func:`run_synthesis` — acRNN: 10 seed frames of a BVH take → ``N`` generated frames; a BVH in the take's own
  units (centimetres: the network's metres × 100), or ``.npy`` of the raw frames ``(N, F)`` (metres);
* :func:`run_locomotion` — QuaterNet long-term: a path in, a BVH (or ``.npy``) walk out
  (:mod:`deploy.models.quaternet_long_walk`); or ``.npy`` inputs in, ``.npy`` outputs out (the step model:
  ``(B, P + T, F)`` frames with their controls → the free-running ``(B, T, G)`` after the P-frame prefix; the pace
  model: ``(B, N, 2)`` → ``(B, N, 4)``).

Everything a run needs comes from the models' metadata (dataset, prefix length, skeleton, statistics, frame
rate); nothing from a checkpoint.

Shape legend: k predicted frames, J joints, N generated frames, F frame size, P prefix frames.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from refimpl.bounds import bounded_int

from deploy.models.entry_io import write_npy

__all__ = ["add_prediction_run_options", "run_prediction", "run_synthesis", "run_locomotion", "export_trained"]


def export_trained(entry, args) -> dict:
    """``refimpl export``'s export (``refimpl.services.export_onnx``: the recipe's exporter inputs, the checkpoint
    validated against its schema) into ``args.out_dir``; returns role -> Path."""
    from refimpl.services import export_onnx, load_trained

    model = load_trained(args.checkpoint)
    options = {"mode": args.mode or "unrolled", "dtype": {"float32": np.float32, "float64": np.float64}[args.dtype],
               "T": args.frames or None}
    if getattr(args, "target", "default") != "default":
        options["target"] = args.target
    if args.opset is not None:
        options["opset"] = args.opset
    return export_onnx(model, Path(args.out_dir), **options)


def _read_npy(path) -> np.ndarray:
    from refimpl.errors import BadInputError, existing_file
    from refimpl.npy_files import read_npy

    p = existing_file(path)
    try:
        a = read_npy(p, kinds="fiu")  # the declared shape checked against the file's size before allocating
    except (OSError, ValueError) as exc:
        raise BadInputError(f"{p}: not a readable .npy array of numbers ({exc})") from None
    if not isinstance(a, np.ndarray) or a.dtype.kind not in "fiu":
        raise BadInputError(f"{p}: expected a numeric .npy array")
    return a


def add_prediction_run_options(group) -> None:
    """QuaterNet's option of ``python -m deploy run``."""
    group.add_argument("--prefix", type=bounded_int("frames"), default=None, help="quaternet, quaternet-cnn: prefix frames (default: "
                                                                 "the metadata's prefix_length)")


def run_prediction(runtime, args) -> int:
    """QuaterNet: ``run DIR IN.txt OUT.bvh|OUT.npy --start S [--frames k] [--prefix P]``: the ``k`` frames after
    frame ``S`` (default: the last possible) predicted from the ``P`` frames ending at ``S``."""
    from refimpl.bvh_write import write_bvh
    from refimpl.tasks import prediction

    model = runtime.predict_model if getattr(runtime, "predict_model", None) is not None else None
    model = model or getattr(runtime, "step_model", None) or getattr(runtime, "window_model", None)
    meta = model.metadata
    dataset, fps = meta.get("dataset"), float(meta["frame_rate"])
    if dataset not in ("cmu", "h36m"):
        raise ValueError(f"{args.model_dir}: the models' metadata names no prediction dataset (cmu or h36m)")
    P = int(args.prefix or meta.get("prefix_length") or 50)
    k = int(args.frames or meta.get("k") or 10)
    if P < 1 or k < 1:
        raise ValueError(f"--prefix, --frames: expected positive integers, got {P}, {k}")
    rotations = prediction.load_clip(args.input, dataset, 1.0 / fps)                      # (F, J, 4)
    s = len(rotations) - 1 if args.start is None else int(args.start)
    pr = prediction.make_prediction(prediction.onnx_method(runtime), rotations, s, P, k,
                                    skeleton=prediction.skeleton_of(dataset), frame_time=1.0 / fps,
                                    method_name=f"{meta['model']['name']}_onnx", name=Path(args.output).stem,
                                    option="--start", source=str(args.input))
    if str(args.output).lower().endswith(".npy"):
        write_npy(args.output, pr.motion.rotations[pr.start:pr.stop])
    else:
        write_bvh(args.output, pr.motion)
    err = pr.euler_error()
    tail = "" if err is None else f"; Euler-angle error at the last predicted frame: {err[-1]:.3f} rad"
    print(f"predicted frames {s + 1}..{s + k} from the {P} frames ending at {s} ({dataset}, {fps:g} fps){tail}; "
          f"wrote {args.output}")
    return 0


def run_synthesis(runtime, args) -> int:
    """acRNN: ``run DIR TAKE.bvh OUT.bvh|OUT.npy [--start S] [--frames N]``: the 10 seed frames from ``S`` (default 1,
    as ``refimpl generate``: frame 0 is the take's reference T-pose) continued for ``N`` frames (default 300)."""
    from refimpl.bvh_write import write_bvh
    from refimpl.tasks import synthesis
    from refimpl.tasks.transition_generate import with_end_sites

    meta = (runtime.generate_model or runtime.step_model).metadata
    if meta.get("skeleton") is None:
        raise ValueError(f"{args.model_dir}: the models carry no skeleton (exported before it was in the metadata; "
                         "export again)")
    config = {"data_representation": meta["representation"]["name"], "mean": meta["normalization"]["mean"],
              "skeleton": meta["skeleton"]}
    n = int(args.frames or 300)
    if n < 1:
        raise ValueError(f"--frames: expected a positive integer, got {n}")
    frames = []

    def method(seed, num):
        out = np.asarray(runtime.generate(np.asarray(seed, np.float32), int(num)), np.float64)
        frames.append(out[0])
        return out

    start = 1 if args.start is None else int(args.start)  # frame 0 of a salsa take is its reference T-pose
    motion, seeds = synthesis.continue_seed(method, config, args.input, start, n, option="--start")
    if str(args.output).lower().endswith(".npy"):
        write_npy(args.output, frames[0])
        what = f"raw frames ({n}, {frames[0].shape[1]}), metres"
    else:
        motion = synthesis.in_source_units(motion)
        write_bvh(args.output, with_end_sites(motion))
        what = f"{seeds} seed + {n} generated frames, centimetres (the take's units)"
    print(f"wrote {args.output}: {what}")
    return 0


def run_locomotion(runtime, args) -> int:
    """QuaterNet long-term: ``run DIR PATH OUT.bvh|OUT.npy [--pace DIR] ...``: a walk along a path
    (:func:`deploy.models.quaternet_long_walk.run_walk`); or ``run DIR IN.npy OUT.npy [--start P]``: the step
    model's free-running rollout after a ``P``-frame prefix (``(B, P + T, F)`` frames with the controls of every
    frame) or, with only the pace model, its raw outputs ``(B, N, 4)`` for ``(B, N, 2)`` inputs."""
    from deploy.models.quaternet_long_walk import run_walk, walk_options_given

    if not str(args.input).lower().endswith(".npy"):
        return run_walk(runtime, args)
    if walk_options_given(args):
        raise ValueError(f"{', '.join(walk_options_given(args))}: options of a walk along a path, not of .npy frames")
    x = _read_npy(args.input).astype(np.float32)
    if not str(args.output).lower().endswith(".npy"):
        raise ValueError(f"output: quaternet-long writes .npy arrays, got {args.output!r}")
    from refimpl.errors import BadInputError, reading

    if runtime.step_model is not None and not (runtime.pace_graph is not None and x.ndim == 3 and x.shape[-1] == 2):
        if x.ndim != 3 or x.shape[1] < 2:
            raise BadInputError(f"{args.input}: expected frames (B, P + T, F) with P + T >= 2, got shape {x.shape}")
        P = int(args.start or 1)
        if not 1 <= P < x.shape[1]:
            raise ValueError(f"--start: expected the prefix length P in [1, {x.shape[1] - 1}], got {P}")
        with reading(args.input):  # frames of another size or non-finite values: the file's fault, exit 3
            rot, tr = runtime.rollout(x, P)
        y = np.concatenate([rot.reshape(rot.shape[0], rot.shape[1], -1), tr], axis=-1)
        what = f"{y.shape[1]} frames after a {P}-frame prefix, [rotations | offset, height]"
    elif runtime.pace_graph is not None:
        with reading(args.input):
            y = runtime.pace(x)
        what = "pace outputs [A, omega, cos, sin] per point (before clipping)"
    else:
        raise ValueError(f"{args.model_dir}: no step model for frames (B, P + T, F)")
    write_npy(args.output, y)
    print(f"wrote {args.output}: {tuple(y.shape)} {what}")
    return 0
