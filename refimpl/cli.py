"""The ``refimpl`` command line (spec/cli.md): info, train, eval, export, generate, render, demo.

Run ``refimpl <command> --help`` (or ``python -m refimpl``). Every command is a thin layer over the library:

==========  ==============================================================================================
command     what it does (library functions it calls)
==========  ==============================================================================================
info        what a BVH, exp-map text file, checkpoint ``.npz`` or ``.onnx`` model holds
train       train a network by name (today ``qtg``) on the sample, ``../shared/data`` or a folder of BVH /
            exp-map files; resumable, progress with rate and ETA, CSV loss log
            (:func:`refimpl.train.train`)
eval        the QTG paper's protocol: QTG vs inertialisation vs interpolation on held-out windows, mean
            joint-position error per joint per frame in cm, per-frame curve (:mod:`refimpl.protocols.transition_metrics`)
export      ONNX models ``qtg_init/step/rollout.onnx`` via ``deploy`` (imported lazily: the ``deploy`` extra)
generate    a transition between two clips with QTG (NumPy or onnxruntime) or a baseline; BVH out
render      a BVH / exp-map motion (optionally against a second one) to a PNG strip or a GIF
demo        the whole tour on the embedded sample (:mod:`refimpl.demo`)
==========  ==============================================================================================

Exit codes (scripts may rely on them): 0 success; 1 runtime failure (including a missing optional dependency
and a diverged training run); 2 usage error (bad or missing options, from argparse); 3 bad input file (missing,
unreadable or malformed BVH / exp-map / checkpoint / ONNX file). Errors are one line on stderr,
``refimpl <command>: error: <message>``, without a traceback unless ``--traceback`` is given. Ctrl-C gives 130
(``train`` first saves a checkpoint at the step boundary).

This module is the argument parser, the ``cmd_*`` functions and what they print. The work is done by
:mod:`refimpl.services` (train, load, evaluate, export, verify), the models come from :mod:`refimpl.registry`
(``--model NAME``: a recipe in ``refimpl/recipes/``) and the data, protocol and generation from the model's task
(``refimpl/tasks/``), which also adds its own ``train`` options (spec/architecture.md).

Nothing here imports ``deploy``, onnx, onnxruntime or matplotlib at import time.

Shape legend: N windows, T transition frames, F frames of a clip, J joints, P pose size (3 + 4 J).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import sys
import time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from refimpl.allocator import retain_freed_memory
from refimpl.errors import DEPLOY_HINT, BadInputError, MissingDependency, UsageError, existing_file, reading
from refimpl.bounds import bounded_float, bounded_int
from refimpl.options import add_data_options, beta, nonneg_int, positive_float, positive_int
from refimpl.registry import MODELS, TASKS, task_of
from refimpl.services import (blas_threads, evaluate_model, export_onnx, load_trained, network_methods,
                              onnx_metadata, read_motion, train_model, verify_onnx)
from refimpl import weights_cli
from refimpl.tasks import transition
from refimpl.train import check_resumable, output_lock
from refimpl.protocols.transition_join import JOIN_MODES, with_join

__all__ = ["main", "build_parser", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_BAD_INPUT"]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_BAD_INPUT = 3


def _say(*parts) -> None:
    print(*parts, flush=True)


def _progress_line(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------------------------------------------
# commands
# ----------------------------------------------------------------------------------------------------------------


def _info_bvh(p: Path, args) -> None:
    from collections import Counter

    from refimpl.bvh import read_bvh, read_bvh_header

    with reading(p):
        header = read_bvh_header(p)
        motion = read_bvh(p, frame_time=None if args.fps is None else 1.0 / args.fps)
    skel = header.skeleton
    n_end = len(skel.end_sites)
    fps = motion.fps
    _say(f"file        {p}")
    _say("format      BVH")
    _say(f"joints      {skel.num_joints} ({skel.num_joints - n_end} joints + {n_end} End Sites), "
         f"root {skel.names[0]!r}")
    _say(f"frames      {motion.num_frames}")
    _say(f"frame time  {motion.frame_time:.7g} s ({fps:.6g} fps"
         + (", overridden by --fps" if args.fps else "") + f"), duration {motion.duration:.2f} s")
    _say(f"channels    {header.num_channels} per frame")
    groups = Counter(ch for ch in header.channels if ch)  # insertion order: the root's layout first
    for ch, count in groups.items():
        who = skel.names[header.channels.index(ch)] if count == 1 else f"{count} joints"
        _say(f"            {who}: {' '.join(ch)}")
    in_file = header.translated_joint_names
    _say(f"translations {len(in_file)} non-root joint(s) with position channels in the file"
         + (f": {', '.join(in_file[:8])}{' ...' if len(in_file) > 8 else ''}" if in_file else ""))
    if motion.skeleton.names[0] != skel.names[0]:
        _say(f"            re-rooted at {motion.skeleton.names[0]!r} (the motion is on a child of the static root "
             f"{skel.names[0]!r}; spec/data.md §2.1)")
    kept = motion.translated_joint_names
    if in_file:
        _say(f"            after reading: {', '.join(kept) if kept else 'none varying (folded into the offsets)'}")
    if motion.num_frames:  # a valid file may hold no frame at all
        pos = motion.positions()  # (T, J, 3)
        ext = pos.max(axis=(0, 1)) - pos.min(axis=(0, 1))
        _say(f"extent      x {ext[0]:.2f}  y {ext[1]:.2f}  z {ext[2]:.2f} (file units; root travel "
             f"{np.linalg.norm(motion.root_positions[-1] - motion.root_positions[0]):.2f})")
    _print_joints(skel, args)


def _print_joints(skel, args) -> None:
    if not args.joints:
        return
    depth = [0] * skel.num_joints
    for j in range(1, skel.num_joints):
        depth[j] = depth[int(skel.parents[j])] + 1
    ends = set(skel.end_sites)
    for j, name in enumerate(skel.names):
        off = np.asarray(skel.offsets[j])
        _say(f"  {j:3d} {'  ' * depth[j]}{name}{' (End Site)' if j in ends else ''}  "
             f"offset ({off[0]:.3f}, {off[1]:.3f}, {off[2]:.3f})")


def _info_expmap(p: Path, args) -> None:
    from refimpl.expmap import EXPMAP_LAYOUTS

    motion = read_motion(p, fps=args.fps, layout=args.layout)
    width = EXPMAP_LAYOUTS[args.layout][0]
    _say(f"file        {p}")
    _say(f"format      exp-map text, layout {args.layout!r} ({width} values per row = {width // 3} triplets)")
    _say(f"joints      {motion.num_joints} (built-in skeleton, {len(motion.skeleton.end_sites)} End Sites)")
    _say(f"frames      {motion.num_frames}")
    _say(f"frame time  {motion.frame_time:.7g} s ({motion.fps:.6g} fps, "
         + ("from --fps" if args.fps else "the layout's default; not stored in the file") + "), "
         f"duration {motion.duration:.2f} s")
    _print_joints(motion.skeleton, args)


def _shape_rows(arrays: Mapping[str, np.ndarray]) -> list[str]:
    width = max((len(k) for k in arrays), default=0)
    return [f"  {k.ljust(width)}  {str(tuple(v.shape)):>14}  {v.dtype}" for k, v in arrays.items()]


def _seconds(x) -> str:
    """``12.3 s`` for a number, else the stored value as text (metadata is data: never trusted to be a number)."""
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return f"{float(x):.1f} s"
    return f"{x!r:.40}"


def _info_npz(p: Path, args) -> None:
    from refimpl.checkpoint import load_checkpoint, load_state_dict_npz

    with reading(p):
        try:
            arrays, meta = load_checkpoint(p)
        except ValueError as exc:
            if "not a refimpl checkpoint" not in str(exc):
                raise
            arrays, meta = load_state_dict_npz(p), None
    training = meta is not None and meta.get("format") == "refimpl.train/1"
    if training:
        from refimpl.checkpoint_schema import validate_trained

        with reading(p):  # a training checkpoint must pass its schema (spec/robustness.md §9): exit 3 otherwise
            validate_trained(arrays, meta, MODELS, str(p), task_of=task_of)
    _say(f"file        {p}")
    if meta is None:
        n = sum(int(v.size) for v in arrays.values())
        _say(f"format      plain .npz state dict ({len(arrays)} arrays, {n:,} values)")
        for row in _shape_rows(arrays):
            _say(row)
        return
    params = {k[len("param."):]: v for k, v in arrays.items() if k.startswith("param.")}
    other = {k: v for k, v in arrays.items() if not k.startswith("param.")}
    _say(f"format      refimpl checkpoint ({meta.get('format', 'no format tag')}), checksum OK")
    if training:  # other metadata (any JSON object) is printed as it is, below
        cfg = dict(meta["model_config"])
        stats = {k: cfg.pop(k) for k in ("root_mean", "root_std") if k in cfg}
        _say(f"model       {meta['model']}")
        if isinstance(meta.get("imported"), dict):  # `refimpl import` (spec/import.md)
            imp = meta["imported"]
            _say(f"imported    from {imp.get('source')} ({imp.get('layout')} names, sha256 "
                 f"{str(imp.get('sha256'))[:16]}...), not trained here")
        _say(f"progress    step {meta.get('step')} of {meta.get('steps_target')}, epoch {meta.get('epoch')}, "
             f"trained for {_seconds(meta.get('elapsed_s', 0.0))}")
        _say(f"config      {json.dumps(cfg, sort_keys=True)}")
        if stats:
            _say(f"normalise   root mean {np.round(stats.get('root_mean', []), 3).tolist()} "
                 f"std {np.round(stats.get('root_std', []), 3).tolist()}")
        if meta.get("optim"):
            _say(f"optimiser   {json.dumps(meta['optim'], sort_keys=True)}, batch {meta.get('batch_size')}")
    else:
        _say(f"metadata    {json.dumps(meta, sort_keys=True)[:400]}")
    n = sum(int(v.size) for v in params.values())
    _say(f"parameters  {len(params)} arrays, {n:,} values")
    for row in _shape_rows(params):
        _say(row)
    if other:
        _say(f"other       {len(other)} arrays (optimiser state, sampler): "
             + ", ".join(sorted(other)[:6]) + (" ..." if len(other) > 6 else ""))


def _info_onnx(p: Path, args) -> None:
    try:
        import onnx
    except ImportError as exc:
        raise MissingDependency(f"reading .onnx files {DEPLOY_HINT}") from exc
    from collections import Counter

    with reading(p):
        try:
            model = onnx.load(str(p))
        except Exception as exc:  # onnx raises DecodeError and others on garbage
            raise ValueError(f"not a readable ONNX model ({type(exc).__name__}: {exc})") from exc
    g = model.graph

    def dims(vi):
        t = vi.type.tensor_type
        shape = [d.dim_param or d.dim_value for d in t.shape.dim]
        return f"{vi.name} {shape} {onnx.TensorProto.DataType.Name(t.elem_type).lower()}"

    inits = {i.name for i in g.initializer}
    n_values = sum(int(np.prod(i.dims)) for i in g.initializer)
    ops = Counter(n.op_type for n in g.node)
    _say(f"file        {p}")
    _say(f"format      ONNX, IR version {model.ir_version}, opsets "
         + ", ".join(f"{o.domain or 'ai.onnx'} {o.version}" for o in model.opset_import)
         + (f", producer {model.producer_name} {model.producer_version}".rstrip() if model.producer_name else ""))
    _say(f"graph       {g.name!r}: {len(g.node)} nodes ({', '.join(f'{k} {v}' for k, v in ops.most_common(6))}"
         + (" ..." if len(ops) > 6 else "") + f"), {len(inits)} initializers, {n_values:,} values")
    for vi in g.input:
        if vi.name not in inits:
            _say(f"input       {dims(vi)}")
    for vi in g.output:
        _say(f"output      {dims(vi)}")
    for prop in model.metadata_props:
        if prop.key == "io":
            continue
        try:  # metadata is data of unknown shape: a value that does not fit the summary is printed as text
            value = json.loads(prop.value)
            if prop.key == "skeleton" and isinstance(value, dict):
                value = f"{len(value.get('names', []))} joints: " + ", ".join(value.get("names", [])[:6]) + " ..."
            elif prop.key == "normalization" and isinstance(value, dict):
                value = (f"in graph: {value.get('in_graph')}, root mean "
                         f"{np.round(np.asarray(value.get('mean', [])[:3], dtype=float), 3).tolist()}")
            text = value if isinstance(value, str) else json.dumps(value, sort_keys=True)
        except (ValueError, TypeError, RecursionError):
            text = prop.value
        _say(f"meta        {prop.key}: {text[:300]}")


def cmd_info(args) -> int:
    """``refimpl info FILE``."""
    p = existing_file(args.file)
    kind = p.suffix.lower()
    handlers = {".bvh": _info_bvh, ".txt": _info_expmap, ".npz": _info_npz, ".onnx": _info_onnx}
    if kind not in handlers:
        raise BadInputError(f"{p}: unknown file type {p.suffix!r} (expected .bvh, .txt, .npz or .onnx)")
    handlers[kind](p, args)
    return EXIT_OK


def cmd_train(args) -> int:
    """``refimpl train``."""
    spec = MODELS[args.model]
    task = task_of(spec)
    rep = args.representation or spec.representations[0]
    if rep not in spec.representations:
        raise UsageError(f"--representation {rep!r}: model {spec.name!r} trains on {list(spec.representations)}")
    out = Path(args.out)
    ckpt = out / "checkpoint.npz"
    if args.resume and not ckpt.is_file():
        raise BadInputError(f"{ckpt}: no checkpoint to resume (train without --resume first)")
    if args.resume:
        load_trained(ckpt)  # a damaged or crafted checkpoint is exit 3 before anything is read or written
        with reading(ckpt):
            check_resumable(ckpt)  # and so is a bad training state (optimiser moments, counters, permutation)
    with output_lock(out):  # a second trainer on the same --out stops here (spec/cli.md §train)
        return _train_locked(args, spec, task, rep, out, ckpt)


def _train_locked(args, spec, task, rep, out, ckpt) -> int:
    if ckpt.is_file() and not (args.resume or args.overwrite):
        raise UsageError(f"{ckpt} exists: pass --resume to continue it or --overwrite to start again")
    if args.overwrite:
        for f in ("checkpoint.npz", "loss.csv", "loss_val.csv"):
            if (out / f).is_file():
                (out / f).unlink()
    if args.batch_size is None:
        args.batch_size = int(getattr(spec.recipe, "PAPER_BATCH", 32))
    t0 = time.perf_counter()
    _say(f"reading {args.data} ...")
    train_ds, test_ds = task.train_datasets(args)
    config = spec.make_config(train_ds, args.set)
    if args.batch_size is None:
        args.batch_size = int(getattr(spec.recipe, "PAPER_BATCH", 32))
    n = task.num_examples(train_ds)
    per_epoch = max(1, n // min(args.batch_size, n))
    steps = args.steps if args.steps is not None else args.epochs * per_epoch
    _say(f"data: {task.describe_data(train_ds, test_ds)} in {time.perf_counter() - t0:.1f} s; "
         f"{per_epoch} steps per epoch")
    described = config.to_dict() if hasattr(config, "to_dict") else dataclasses.asdict(config)
    _say(f"model: {spec.name} {json.dumps(described)}")
    lr = spec.optim.lr if args.lr is None else args.lr
    betas = tuple(spec.optim.betas if args.betas is None else args.betas)
    _say(f"training {steps} steps (batch {args.batch_size}, Adam lr {lr:g}, betas {betas}) -> {out}/")
    result = train_model(spec, config, train_ds, test_ds, out, steps=steps, batch_size=args.batch_size,
                         lr=lr, betas=betas, clip_norm=args.clip_norm, seed=args.seed,
                         dtype=np.dtype(args.dtype).type, resume=args.resume,
                         checkpoint_every=args.checkpoint_every, validate_every=args.validate_every,
                         progress_every=args.progress_every, progress=_progress_line)
    last = float(np.mean(result.losses[-20:])) if result.losses else float("nan")
    _say(f"{'interrupted' if result.interrupted else 'done'}: step {result.step}, epoch {result.epoch}, "
         f"recent loss {last:.5g}, {result.elapsed_s:.1f} s")
    _say(f"checkpoint  {result.checkpoint_path}")
    _say(f"loss log    {out / 'loss.csv'}" + (f", {out / 'loss_val.csv'}" if args.validate_every else ""))
    if result.interrupted:
        return 128 + int(getattr(result, "signal", None) or 2)  # 130 for SIGINT / Ctrl-C, 143 for SIGTERM
    return EXIT_OK


def _eval_prediction(args, model) -> int:
    """``refimpl eval`` on the prediction task: the network(s) and the baselines, the paper's table, JSON."""
    from refimpl.protocols import prediction as PP
    from refimpl.protocols import prediction_data as PD
    from refimpl.tasks import prediction

    _say(f"reading {args.data} ...")
    stride = PD.stride_of(model.extra["dataset"], model.extra["frame_time"]) if model else 2
    data = prediction.resolve_data(args.data, downsample=stride)
    if model is not None and model.extra.get("dataset") != data.dataset:
        raise UsageError(f"--data {args.data} is {data.dataset}, the model was trained on {model.extra.get('dataset')}")
    try:
        actions = prediction.eval_actions(args)
        protocol = prediction.eval_protocol(data.dataset, args.protocol, args.samples_per_sequence,
                                            horizons=getattr(args, "horizons", "default"), data=data, actions=actions)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    networks = network_methods(model, onnx_dir=args.onnx) if (model is not None or args.onnx) else {}
    try:
        results = PP.evaluate_all(data, prediction.methods(networks), protocol, progress=_progress_line,
                                  actions=actions)
    except ValueError as exc:
        raise BadInputError(f"--data {args.data}: {exc}") from exc
    if model is not None:
        _say(f"network {model.spec.name} from {model.path} (step {model.meta.get('step')})")
    _say("Mean Euler-angle error (radians, zyx, joint 0 excluded) per action and horizon:")
    _say(PP.format_table(results))
    if args.json:
        PP.write_results_json(args.json, results[0] if len(results) == 1 else results)
        _say(f"results          {args.json}")
    if args.plot:
        from refimpl.render import render_error_curves

        render_error_curves(args.plot, PP.average_curves(results), frame_time=protocol.frame_ms / 1000.0)
        _say(f"plot             {args.plot}")
    return EXIT_OK


def cmd_eval(args) -> int:
    """``refimpl eval``."""
    model = load_trained(args.checkpoint) if args.checkpoint else None
    task_name = model.spec.task if model is not None else (MODELS[args.model].task if args.model else "transition")
    if task_name == "prediction":
        return _eval_prediction(args, model)
    if task_name == "synthesis":
        return _eval_synthesis(args, model)
    if task_name == "locomotion":
        return _eval_locomotion(args, model)
    T = args.transition_length or (model.transition_length if model else 30)
    _say(f"reading {args.data} ...")
    _, test_ds = transition.build_datasets(args.data, T, args.stride, fps=args.fps, test_fraction=args.test_fraction)
    if test_ds.num_windows == 0:
        raise BadInputError(f"--data {args.data}: no held-out window of {T + 4} frames")
    results = evaluate_model(model, test_ds, onnx_dir=args.onnx, join=args.join)
    transition.print_results(results, test_ds, model)
    frame_time = 1.0 / test_ds.fps
    transition.write_results(results, frame_time, json_path=args.json, csv_path=args.csv)
    if args.csv:
        _say(f"per-frame curve  {args.csv}")
    if args.json:
        _say(f"results          {args.json}")
    if args.plot:
        from refimpl.render import render_error_curves

        render_error_curves(args.plot, {k: v["per_frame_cm"] for k, v in results.items()}, frame_time=frame_time)
        _say(f"plot             {args.plot}")
    return EXIT_OK


def cmd_export(args) -> int:
    """``refimpl export``."""
    model = load_trained(args.checkpoint)
    out = Path(args.out) if args.out else Path(model.path).parent / "onnx"
    join = {} if args.join == "none" else {"join": args.join}
    if join and model.spec.task != "transition":
        raise UsageError(f"--join applies to transition models, not {model.spec.name}")
    written = export_onnx(model, out, mode=args.mode, dtype=np.dtype(args.dtype).type, T=args.transition_length,
                          **join)
    for role, path in written.items():
        _say(f"{role:8s} {path} ({Path(path).stat().st_size / 1024:.0f} KiB)")
    if args.verify:
        rng = np.random.default_rng(args.seed)
        task = task_of(model.spec)
        if model.spec.task == "transition":
            past, target = transition.random_context(model, rng, 8)
            check = verify_onnx(model, out, past, target, T=args.transition_length)
        elif hasattr(task, "verify_inputs"):  # the task's own check inputs (prediction: real CMU windows)
            check = verify_onnx(model, out, *task.verify_inputs(model, rng, 8))
        elif hasattr(task, "random_inputs"):  # synthesis: random seeds in the data's range
            check = verify_onnx(model, out, *task.random_inputs(model, rng))
        else:  # locomotion: the recipe draws its own random inputs
            check = verify_onnx(model, out, seed=args.seed)
        for k, v in check.items():
            if k != "ok":
                _say(f"verify   onnxruntime vs NumPy ({k}): max |diff| = {v:.3g}")
        if not check["ok"]:
            raise RuntimeError("onnxruntime and NumPy disagree beyond the recipe's verification tolerance "
                               f"(refimpl.recipes.{model.spec.name.replace('-', '_')}; spec/cli.md)")
    return EXIT_OK


def _generate_prediction(args, model) -> int:
    """``refimpl generate`` on the prediction task: a prefix of ``--source`` -> ``--length`` frames, BVH out."""
    from refimpl.bvh import write_bvh
    from refimpl.protocols import prediction_data as PD
    from refimpl.tasks import prediction

    if args.backend == "onnx":
        if not args.onnx:
            raise UsageError("--backend onnx needs --onnx DIR (the folder written by `refimpl export`)")
        meta = onnx_metadata(args.onnx)
        fps, _ = _onnx_rate_and_length(args.onnx, 1)  # frame rate and model entry checked (exit 3 when wrong)
        P = meta.get("prefix_length", 50)
        if isinstance(P, bool) or not isinstance(P, int) or not 1 <= P <= 100_000:
            raise BadInputError(f"{args.onnx}: metadata prefix_length: expected an integer in [1, 100000], "
                                f"got {P!r}"[:300])
        model_name = (meta.get("model") or {}).get("name")
        if not isinstance(model_name, str):
            raise BadInputError(f"{args.onnx}: the models' metadata names no model (model.name)")
        dataset, frame_time, name = meta.get("dataset"), 1.0 / fps, f"{model_name}_onnx"
        if dataset not in ("cmu", "h36m"):
            raise BadInputError(f"{args.onnx}: the models' metadata names no prediction dataset")
    else:
        dataset, frame_time = model.extra["dataset"], float(model.extra["frame_time"])
        P, name = int(model.config.prefix_length), model.spec.name
    networks = network_methods(None if args.backend == "onnx" else model,
                               onnx_dir=args.onnx if args.backend == "onnx" else None, expect=model)
    rotations = prediction.load_clip(args.source, dataset, frame_time)
    k = args.length or 25
    pr = prediction.make_prediction(next(iter(networks.values())), rotations, args.source_frame, P, k,
                                    skeleton=PD.skeleton_of(dataset), frame_time=frame_time,
                                    method_name=name, name=Path(args.out).stem)
    write_bvh(args.out, pr.motion)
    _say(f"wrote {args.out}: {pr.motion.num_frames} frames at {1.0 / frame_time:g} fps ({dataset} skeleton, root "
         f"at the origin): prefix frames 0..{pr.start - 1}, predicted {pr.start}..{pr.stop - 1} ({name}, "
         f"{args.backend})")
    err = pr.euler_error()
    if err is not None:
        _say("ground truth available: Euler-angle error (rad) at predicted frames 2, 4, 8, 10: "
             + ", ".join(f"{err[i]:.3f}" for i in (1, 3, 7, 9) if i < len(err)))
        if args.truth:
            write_bvh(args.truth, pr.truth)
            _say(f"wrote {args.truth} (ground truth)")
    elif args.truth:
        raise UsageError(f"--truth: {args.source} ends before the {k} predicted frames")
    if args.png or args.gif:
        for f in prediction.render_prediction(pr, png=args.png, gif=args.gif):
            _say(f"wrote {f}")
    return EXIT_OK


def _model_task(args, model) -> str:
    """The task of ``--checkpoint``'s model, else of ``--model``, else of the exported models in ``--onnx``, else
    ``transition``."""
    if model is not None:
        return model.spec.task
    if getattr(args, "model", None):
        return MODELS[args.model].task
    if getattr(args, "backend", None) == "onnx" and args.onnx:
        model_meta = onnx_metadata(args.onnx).get("model") or {}
        if not isinstance(model_meta, dict):
            raise BadInputError(f"{args.onnx}: metadata model: expected a JSON object, got "
                                f"{type(model_meta).__name__}")
        name = model_meta.get("name")
        if isinstance(name, str) and name in MODELS:
            return MODELS[name].task
    return "transition"


_GENERATE_USAGE = ("usage: refimpl generate --source FILE --source-frame S [...]  (a transition)\n"
                   "       refimpl generate --checkpoint CKPT --source FILE [...]  (prediction, acrnn)\n"
                   "       refimpl generate --model quaternet-long --checkpoint POSE.npz --pace PACE.npz "
                   "[--path ...]  (locomotion)")


def cmd_generate(args) -> int:
    """``refimpl generate``."""
    from refimpl.bvh import write_bvh

    if args.model is not None and MODELS[args.model].task == "locomotion":
        from refimpl.tasks.locomotion_cli import generate_command

        return generate_command(args, load_trained, _say)
    first = load_trained(args.checkpoint) if args.checkpoint else None
    task_name = _model_task(args, first)
    if task_name == "locomotion":
        raise UsageError("a quaternet-long / pace checkpoint: pass --model quaternet-long --checkpoint POSE.npz "
                         "--pace PACE.npz [--path ...]")
    if args.source is None:
        raise UsageError("the following argument is required: --source (the prefix, seed or source clip)\n"
                         + _GENERATE_USAGE)
    if task_name == "prediction":
        if args.backend == "numpy" and first is None:
            raise UsageError("--backend numpy needs --checkpoint")
        return _generate_prediction(args, first)
    model = None
    if task_name == "synthesis":
        return _generate_synthesis(args)
    if args.source_frame is None:
        raise UsageError("the following arguments are required for a transition: --source, --source-frame\n"
                         + _GENERATE_USAGE)
    if args.method == "qtg":
        if args.backend == "numpy" and not args.checkpoint:
            raise UsageError("--method qtg with --backend numpy needs --checkpoint")
        if args.backend == "onnx" and not args.onnx:
            raise UsageError("--backend onnx needs --onnx DIR (the folder written by `refimpl export`)")
        if args.checkpoint:
            model = load_trained(args.checkpoint)
            if model.spec.task != "transition":
                return _generate_synthesis(args, model)
    elif args.backend == "onnx":
        raise UsageError(f"--backend onnx runs the network; --method {args.method} is a NumPy baseline")
    fps, T_model = (model.fps, model.transition_length) if model else (30.0, 30)
    if args.backend == "onnx" and model is None:
        fps, T_model = _onnx_rate_and_length(args.onnx, T_model)
    T = args.length or T_model
    target_path = args.target or args.source
    skel, src_clip, src = transition.clip_for(args.source, fps, args.fps)
    skel2, tgt_clip, tgt = transition.clip_for(target_path, fps, args.fps)
    if skel != skel2:
        raise BadInputError(f"{target_path}: its 22-joint skeleton differs from {args.source}'s "
                            "(both clips must come from the same skeleton)")
    if args.method == "qtg":
        networks = network_methods(None if args.backend == "onnx" else model,
                                   onnx_dir=args.onnx if args.backend == "onnx" else None, expect=model)
        method = next(iter(networks.values()))
    else:
        method = transition.methods(fps=fps)[args.method]
    method = with_join(method, args.join, dt=1.0 / fps)
    same = Path(args.source).resolve() == Path(target_path).resolve()
    target_frame = args.target_frame if args.target_frame is not None else (
        args.source_frame + T + 1 if same else 1)
    tr = transition.make_transition(method, skel, src_clip, args.source_frame, tgt_clip, target_frame, T,
                         frame_time=1.0 / fps, context=args.context, align=args.align, same_clip=same,
                         method_name=args.method + ("" if args.join == "none" else "+join"),
                         name=Path(args.out).stem)
    write_bvh(args.out, transition.with_end_sites(tr.motion))
    _say(f"wrote {args.out}: {tr.motion.num_frames} frames at {fps:g} fps, 22 joints (centimetres); "
         f"generated frames {tr.start}..{tr.stop - 1} ({tr.method}, {args.backend})")
    err = tr.error_cm()
    if err is not None:
        _say(f"ground truth available (same clip, target = source + T + 1): mean joint error {err:.2f} cm")
        if args.truth:
            write_bvh(args.truth, transition.with_end_sites(tr.truth))
            _say(f"wrote {args.truth} (ground truth)")
    elif args.truth:
        raise UsageError("--truth needs --target-frame = --source-frame + T + 1 in the same file (and --align none)")
    if args.png or args.gif:
        transition.render_transition(tr, png=args.png, gif=args.gif)
    return EXIT_OK


def _onnx_rate_and_length(onnx_dir, default_T: int) -> tuple[float, int]:
    """Frame rate and T from the exported models' metadata, checked: a rate that is not a finite number > 0, or
    a model entry / T of the wrong type, is a bad input file (exit 3), not a ZeroDivisionError later."""
    meta = onnx_metadata(onnx_dir)
    where = f"{onnx_dir}: metadata"
    fps = meta.get("frame_rate", 30.0)
    try:
        ok = not isinstance(fps, bool) and isinstance(fps, (int, float)) and 0 < float(fps) < float("inf")
    except OverflowError:  # an integer beyond the float range
        ok = False
    if not ok:
        raise BadInputError(f"{where} frame_rate: expected a finite number > 0, got {fps!r}"[:300])
    model_meta = meta.get("model", {})
    if not isinstance(model_meta, dict):
        raise BadInputError(f"{where} model: expected a JSON object, got {type(model_meta).__name__}")
    T = model_meta.get("transition_length")
    if T is None:
        T = default_T
    elif isinstance(T, bool) or not isinstance(T, int) or not 1 <= T <= 100_000:
        raise BadInputError(f"{where} model.transition_length: expected an integer in [1, 100000], got {T!r}"[:300])
    return float(fps), int(T)


def _parse_slice(text: str | None, n: int) -> slice:
    if not text:
        return slice(0, n)
    parts = text.split(":")
    try:
        vals = [int(v) if v.strip() else None for v in parts]
    except ValueError:
        raise UsageError(f"--frames {text!r}: expected START:STOP[:STEP] with integers") from None
    if len(vals) == 1:
        vals = [vals[0], None if vals[0] is None else vals[0] + 1]
    if len(vals) > 3 or (len(vals) == 3 and vals[2] is not None and vals[2] < 1):
        raise UsageError(f"--frames {text!r}: expected START:STOP[:STEP] with a positive STEP")
    return slice(*vals)


def cmd_render(args) -> int:
    """``refimpl render``."""
    from refimpl.render import render_gif
    from refimpl.render_strip import limb_sides, render_strip

    motion = read_motion(args.file, fps=args.fps, layout=args.layout)
    other = read_motion(args.compare, fps=args.fps, layout=args.layout) if args.compare else None
    if other is not None and other.num_joints != motion.num_joints:
        raise BadInputError(f"{args.compare}: {other.num_joints} joints, but {args.file} has {motion.num_joints}")
    n = motion.num_frames if other is None else min(motion.num_frames, other.num_frames)
    sel = _parse_slice(args.frames, n)
    idx = np.arange(n)[sel]
    if idx.size == 0:
        raise UsageError(f"--frames {args.frames!r} selects no frame of {n}")
    pos = motion.positions()[idx]  # (N, J, 3)
    pred = None if other is None else other.positions()[idx]
    parents = np.asarray(motion.skeleton.parents)
    outs = args.out or [Path(args.file).stem + ".png"]
    sides = limb_sides(motion.skeleton)  # left limbs dark, right limbs light (the skeleton's mirror map)
    labels = (Path(args.file).stem, Path(args.compare).stem if args.compare else "")
    step = sel.step or 1
    for out in outs:
        suffix = Path(out).suffix.lower()
        if suffix == ".png":
            render_strip(out, pos, parents, prediction=pred, num_frames=args.num_frames, labels=labels,
                         up=args.up, frame_time=motion.frame_time, frame_numbers=idx, title=args.title, sides=sides)
        elif suffix == ".gif":
            render_gif(out, pos, parents, prediction=pred, fps=motion.fps / step, stride=args.stride, labels=labels,
                       up=args.up, frame_numbers=idx, title=args.title, sides=sides)
        else:
            raise UsageError(f"--out {out}: expected a .png or .gif file name")
        _say(f"wrote {out} ({len(idx)} frames of {args.file})")
    return EXIT_OK


def cmd_demo(args) -> int:
    """``refimpl demo``."""
    from refimpl.demo import run_demo

    run_demo(args.out, seed=args.seed, quick=args.quick, steps=args.steps, onnx=not args.no_onnx,
             render=not args.no_render)
    return EXIT_OK


def _eval_synthesis(args, model) -> int:
    """``refimpl eval`` for a synthesis model (acRNN): Table 1's metrics on the test takes (spec/acrnn.md §8)."""
    task = task_of(model.spec if model is not None else MODELS[args.model])
    if model is None:
        raise UsageError("--model acrnn: evaluation needs --checkpoint (the statistics and the representation)")
    _say(f"reading {args.data} ...")
    data = task.load_eval_data(args.data, model.extra)
    results = evaluate_model(model, data, onnx_dir=args.onnx)
    task.print_results(results, data, model)
    if args.json:
        task.write_results(results, args.json)
        _say(f"results          {args.json}")
    return EXIT_OK


def _eval_locomotion(args, model) -> int:
    """``refimpl eval`` for the long-term pose network: free-running position and velocity error over the held-out
    windows (QN §4.4.2; spec/locomotion.md §8), against zero-velocity."""
    task = task_of("locomotion")
    if model is None or model.spec.name != "quaternet-long":
        raise UsageError("locomotion: evaluation needs --checkpoint of a quaternet-long model (the pace network's "
                         "held-out L1 is its loss_val.csv)")
    _say(f"reading {args.data} ...")
    data = task.load_eval_data(args.data, model.extra)
    extra = getattr(model.spec.recipe, "extra_methods", None)  # e.g. a DQ model's positions read from the DQs
    nets = {**network_methods(model), **(extra(model) if extra else {})}
    results = task.evaluate(data, task.methods(nets))
    _say(f"held-out windows: {next(iter(results.values()))['windows']} of {data.prefix} + {data.target} frames "
         f"({len(data.files)} files); error in QuaterNet units (1 unit = 5.6444 cm)")
    from refimpl.protocols.locomotion import format_results

    _say(format_results(results))
    if args.json:
        from refimpl.atomic import atomic_write_text

        serial = {n: {k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()}
                  for n, r in results.items()}
        atomic_write_text(args.json, json.dumps(serial, indent=1) + "\n")
        _say(f"results          {args.json}")
    return EXIT_OK


def _generate_synthesis(args, model=None) -> int:
    """``refimpl generate --model acrnn``: seed frames of --source continued for --length frames, BVH out."""
    from refimpl.bvh import write_bvh

    if model is None:
        if not args.checkpoint:
            raise UsageError("--model acrnn needs --checkpoint (with --backend onnx too: skeleton and statistics)")
        model = load_trained(args.checkpoint)
    task = task_of(model.spec)
    if args.backend == "onnx" and not args.onnx:
        raise UsageError("--backend onnx needs --onnx DIR (the folder written by `refimpl export`)")
    networks = network_methods(None if args.backend == "onnx" else model,
                               onnx_dir=args.onnx if args.backend == "onnx" else None, expect=model)
    method = next(iter(networks.values()))
    n = args.length or 300
    motion, seed_frames = task.continue_seed(method, model.extra, args.source, args.source_frame or 0, n)
    write_bvh(args.out, transition.with_end_sites(task.in_source_units(motion)))   # the take's centimetres
    _say(f"wrote {args.out}: {seed_frames} seed frames of {args.source} (from frame {args.source_frame or 0} at "
         f"30 fps) + {n} generated frames ({model.extra.get('row')}, {args.backend}), {motion.num_joints} joints, "
         "centimetres (the take's units)")
    if args.png or args.gif:
        from refimpl.render import render_gif
        from refimpl.render_strip import render_strip

        pos = motion.positions()
        parents = np.asarray(motion.skeleton.parents)
        labels = (f"acrnn {model.extra.get('row')}", "")
        if args.png:
            render_strip(args.png, pos, parents, highlight=(seed_frames, motion.num_frames), labels=labels,
                         frame_time=motion.frame_time)
            _say(f"wrote {args.png}")
        if args.gif:
            render_gif(args.gif, pos, parents, fps=motion.fps, highlight=(seed_frames, motion.num_frames),
                       labels=labels)
            _say(f"wrote {args.gif}")
    return EXIT_OK


# ----------------------------------------------------------------------------------------------------------------
# parser and main
# ----------------------------------------------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``refimpl`` (see spec/cli.md)."""
    from refimpl import __version__

    parser = argparse.ArgumentParser(
        prog="refimpl",
        description="Reference NumPy implementation of QuaterNet, the dual-quaternion representation and QTG: "
                    "inspect files, train, evaluate, export to ONNX, generate transitions, render. "
                    "Start with `refimpl demo`.",
        epilog="exit codes: 0 ok, 1 runtime failure, 2 usage error, 3 bad input file")
    parser.add_argument("--version", action="version", version=f"refimpl {__version__}")
    parser.add_argument("--traceback", action="store_true", help="show the full traceback of an error")
    parser.add_argument("--blas-threads", type=bounded_int("threads"), default=2,
                        help="BLAS threads for NumPy (default 2: measured fastest on an idle 2-core machine, "
                             "0.58-0.74x the one-thread time per training step of every network and equal or "
                             "faster at batch 1, benchmarks/bench_threads.py; pass 1 when other jobs share the "
                             "cores, where two threads were 1.2-20x slower; 0 = library default; needs "
                             "threadpoolctl)")
    parser.add_argument("--malloc", choices=("retain", "system"), default="retain",
                        help="C allocator settings (glibc): 'retain' (default) keeps freed memory for the next "
                             "training step instead of faulting it in again (QTG step time 0.76-0.99x, pace 0.80-0.83x, "
                             "benchmarks/bench_allocator.py); 'system' leaves glibc's defaults")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("info", help="what a .bvh, exp-map .txt, checkpoint .npz or .onnx file holds",
                       description="Print joints, frames, frame rate and channel layout of a motion file; "
                                   "parameters, shapes and metadata of a checkpoint or ONNX model.")
    p.add_argument("file")
    p.add_argument("--joints", action="store_true", help="list the joint hierarchy with offsets")
    p.add_argument("--layout", default="cmu", choices=("cmu", "h36m"), help="exp-map layout (default cmu)")
    p.add_argument("--fps", type=positive_float, default=None, help="override the frame rate")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("train", help="train a network (qtg, quaternet, quaternet-cnn, acrnn) on motion files",
                       description="Train a network with Adam; checkpoint.npz (resumable), loss.csv and "
                                   "loss_val.csv go to --out. Progress lines (rate, ETA) go to stderr. "
                                   "Models: " + "; ".join(f"{n}: {s.summary}" for n, s in sorted(MODELS.items())))
    p.add_argument("--model", default="qtg", choices=sorted(MODELS), help="network (default qtg)")
    p.add_argument("--representation", default=None, help="pose representation (qtg: quat)")
    add_data_options(p)
    p.add_argument("--out", default="runs/qtg", help="output folder (default runs/qtg)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--steps", type=bounded_int("steps"), default=None, help="optimiser steps")
    length.add_argument("--epochs", type=bounded_int("steps"), default=10, help="epochs, when --steps is not given (default 10)")
    p.add_argument("--batch-size", type=bounded_int("batch"), default=None,
                   help="batch size (default: the model's paper value; qtg 32, quaternet 60, quaternet-long and "
                        "pace 40)")
    p.add_argument("--lr", type=positive_float, default=None,
                   help="Adam learning rate (default: the model's paper value; qtg 1e-4)")
    p.add_argument("--betas", type=beta, nargs=2, default=None, metavar=("B1", "B2"),
                   help="Adam betas (default: the model's paper values; qtg 0.5 0.9)")
    p.add_argument("--clip-norm", type=positive_float, default=None, help="global gradient-norm clipping")
    for task_name in sorted(TASKS):  # each task adds its own options, in its own group
        task_of(task_name).add_train_options(p.add_argument_group(f"{task_name} task"))
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a config field, e.g. --set gru_hidden=128 --set encoder_sizes=128,64")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--seed", type=int, default=0)
    resume = p.add_mutually_exclusive_group()
    resume.add_argument("--resume", action="store_true", help="continue from --out/checkpoint.npz")
    resume.add_argument("--overwrite", action="store_true", help="start again, replacing --out's checkpoint and logs")
    p.add_argument("--checkpoint-every", type=bounded_int("every"), default=500)
    p.add_argument("--validate-every", type=bounded_int("every"), default=None,
                   help="log the held-out MAE every N steps (loss_val.csv)")
    p.add_argument("--progress-every", type=bounded_int("every"), default=50)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("eval", help="a network against its task's baselines (QTG: transitions; QuaterNet: "
                                    "short-term prediction)",
                       description="Transition task (qtg): the QTG paper's protocol, mean joint-position error per "
                                   "joint per frame (cm) on held-out transition windows, with the per-frame curve. "
                                   "Prediction task (quaternet, quaternet-cnn): the published short-term protocol, "
                                   "Euler-angle error per action and horizon, with zero-velocity and running "
                                   "averages.")
    p.add_argument("--checkpoint", default=None, help="a `refimpl train` checkpoint (omit: baselines only)")
    p.add_argument("--onnx", default=None, help="also evaluate the exported models of this folder (onnxruntime)")
    add_data_options(p)
    p.add_argument("--transition-length", type=bounded_int("transition_length"), default=None,
                   help="T (default: the model's)")
    p.add_argument("--csv", default=None, help="write the per-frame curve as CSV")
    p.add_argument("--json", default=None, help="write all results as JSON")
    p.add_argument("--plot", default=None, help="write the per-frame curves as PNG (matplotlib)")
    p.add_argument("--model", default=None, choices=sorted(MODELS),
                   help="without --checkpoint: evaluate the baselines of this model's task (default qtg's); the "
                        "checkpoint's model decides otherwise (acrnn: Table 1 metrics on the salsa test takes)")
    for task_name in sorted(TASKS):
        if hasattr(task_of(task_name), "add_eval_options"):
            task_of(task_name).add_eval_options(p.add_argument_group(f"{task_name} task"))
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("export", help="export a checkpoint to ONNX (needs the deploy extra)",
                       description="Write <model>_init.onnx, <model>_step.onnx, <model>_rollout.onnx (validated); "
                                   "the graphs standardise inside (raw poses in and out) and carry their metadata.")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--out", default=None, help="output folder (default: onnx/ beside the checkpoint)")
    p.add_argument("--mode", default="unrolled", choices=("unrolled", "loop", "scan"), help="rollout graph form")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--transition-length", type=bounded_int("transition_length"), default=None,
                   help="T of the rollout model")
    p.add_argument("--no-verify", dest="verify", action="store_false",
                   help="skip the onnxruntime-vs-NumPy check on random context poses")
    p.add_argument("--seed", type=int, default=0, help="seed of the check's random poses")
    p.add_argument("--join", default="none", choices=JOIN_MODES,
                   help="transition models: inertialize = bake the join option into the rollout graph (spec/qtg.md "
                        "7.4; the C example gets it too); default none")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("generate", help="generate a transition between two clips, BVH out",
                       description="Take frames s-1, s of --source and g, g+1 of --target (frame numbers at the "
                                   "model's rate, 30 fps, after the files' first reference frame), generate the T "
                                   "frames between them and write a BVH with --context frames on both sides.")
    p.add_argument("--source", default=None, help=".bvh or exp-map .txt (every task but locomotion)")
    p.add_argument("--source-frame", type=nonneg_int, default=None,
                   help="s, last frame of the source kept (transitions, required); acrnn: first seed frame (default 0)")
    p.add_argument("--target", default=None, help=".bvh or exp-map .txt (default: --source)")
    p.add_argument("--target-frame", type=nonneg_int, default=None,
                   help="g, first target frame (default: s + T + 1 in the same file, else 1)")
    p.add_argument("--method", default="qtg", choices=("qtg", "inertialization", "interpolation"))
    p.add_argument("--checkpoint", default=None, help="a `refimpl train` checkpoint (NumPy backend)")
    p.add_argument("--backend", default="numpy", choices=("numpy", "onnx"))
    p.add_argument("--onnx", default=None, help="folder of exported models (ONNX backend)")
    p.add_argument("--length", type=bounded_int("frames"), default=None, help="T (default: the model's)")
    p.add_argument("--context", type=bounded_int("context"), default=10, help="frames kept on each side (default 10)")
    p.add_argument("--join", default="none", choices=JOIN_MODES,
                   help="inertialize: carry the jump at each end of the transition away (spec/qtg.md 7.4)")
    p.add_argument("--align", default="auto", choices=("auto", "none", "continue"),
                   help="place the target clip: none = as in its file, continue = after the source (default: "
                        "none for one file, continue for two)")
    p.add_argument("--fps", type=positive_float, default=None, help="true frame rate of the input files")
    p.add_argument("--out", default="transition.bvh")
    p.add_argument("--truth", default=None, help="also write the ground truth (same file, g = s + T + 1)")
    p.add_argument("--png", default=None, help="also render a PNG strip (matplotlib)")
    p.add_argument("--gif", default=None, help="also render a GIF (matplotlib)")
    loco = p.add_argument_group("locomotion (--model quaternet-long)")
    loco.add_argument("--model", default=None, choices=sorted(MODELS),
                      help="the network when the checkpoint does not say it: quaternet-long walks a path (needs "
                           "--checkpoint, --pace); acrnn continues 10 seed frames of --source for --length frames "
                           "(default 300); default: the checkpoint's model, else a transition")
    loco.add_argument("--pace", default=None, help="pace-network checkpoint (`refimpl train --model pace`)")
    loco.add_argument("--path", default="circle:r=3",
                      help="circle[:r=M], figure8[:size=M], line-turn[:turn=DEG] or a CSV of x,z points in metres")
    loco.add_argument("--speed", default="walk", help="walk, jog, run or units per frame (default walk)")
    loco.add_argument("--seconds", type=bounded_float("seconds"), default=10.0,
                      help="length of the motion (default 10)")
    loco.add_argument("--controls", default=None, help="also write the per-frame controls as JSON")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("render", help="draw a motion as a PNG strip or GIF (matplotlib)",
                       description="Draw a .bvh / exp-map motion, optionally beside a second one (--compare) on "
                                   "the same skeleton, as a PNG strip of frames or an animated GIF.")
    p.add_argument("file")
    p.add_argument("--compare", default=None, help="a second motion drawn in red over the first")
    p.add_argument("--out", action="append", default=None,
                   help=".png and/or .gif output (repeatable; default <file stem>.png)")
    p.add_argument("--frames", default=None, help="START:STOP[:STEP] frame range (default all)")
    p.add_argument("--num-frames", type=bounded_int("panels"), default=8, help="panels in a PNG strip (default 8)")
    p.add_argument("--stride", type=positive_int, default=1, help="draw every k-th frame in a GIF")
    p.add_argument("--up", default="y", choices=("y", "z"), help="the data's up axis (BVH: y)")
    p.add_argument("--title", default=None)
    p.add_argument("--layout", default="cmu", choices=("cmu", "h36m"), help="exp-map layout")
    p.add_argument("--fps", type=positive_float, default=None, help="override the frame rate")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("demo", help="train, evaluate, export, verify, generate and render on the sample",
                       description="The whole tour on the embedded CMU sample in a few minutes on 2 cores.")
    p.add_argument("--out", default="demo_out", help="output folder (default ./demo_out)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="a tiny network and a few steps (a smoke test, ~30 s)")
    p.add_argument("--steps", type=positive_int, default=None, help="override the number of training steps")
    p.add_argument("--no-onnx", action="store_true", help="skip export and verification")
    p.add_argument("--no-render", action="store_true", help="skip the pictures")
    p.set_defaults(func=cmd_demo)

    weights_cli.add_parsers(sub)  # import, export-weights (spec/import.md)
    return parser


def _one_line(exc: BaseException, limit: int = 1000) -> str:
    """An exception's message as one line (a checker's report may span several), at most ``limit`` characters."""
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def _prog(args) -> str:
    return f"refimpl {args.command}" if getattr(args, "command", None) else "refimpl"


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``refimpl`` command line; returns the exit code (0 ok, 1 failure, 2 usage, 3 bad input file)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse: --help / --version (0) or a usage error (2)
        return exc.code if isinstance(exc.code, int) else (EXIT_OK if exc.code is None else EXIT_USAGE)
    if args.command is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    prog = _prog(args)
    if args.malloc == "retain":
        retain_freed_memory()
    try:
        with blas_threads(args.blas_threads):
            return int(args.func(args) or EXIT_OK)
    except BadInputError as exc:
        if args.traceback:
            raise
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except UsageError as exc:
        if args.traceback:
            raise
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    except (MissingDependency, ImportError) as exc:  # an optional dependency (matplotlib, onnx) is missing
        if args.traceback:
            raise
        print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (`refimpl info x.bvh | head`): stop quietly
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_FAILURE
    except Exception as exc:  # noqa: BLE001 - the command line's last line of defence: one message, exit 1
        if args.traceback:
            raise
        kind = "" if isinstance(exc, (RuntimeError, ValueError, OSError)) else f"{type(exc).__name__}: "
        print(f"{prog}: error: {kind}{_one_line(exc)} (run with --traceback for details)", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
