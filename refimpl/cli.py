"""The ``refimpl`` command line (spec/cli.md): info, train, eval, export, generate, render, demo.

Run ``refimpl <command> --help`` (or ``python -m refimpl``). Every command is a thin layer over the library:

==========  ==============================================================================================
command     what it does (library functions it calls)
==========  ==============================================================================================
info        what a BVH, exp-map text file, checkpoint ``.npz`` or ``.onnx`` model holds (:mod:`refimpl.cli_info`)
train       train a network by name (``--model``, :data:`refimpl.registry.MODELS`) on the sample,
            ``../shared/data`` or a folder of BVH / exp-map files; resumable, progress with rate and ETA, CSV
            loss log (:func:`refimpl.services.train_model`)
eval        a network against its task's baselines under the task's protocol (the task's ``eval_command``)
export      ONNX models via ``deploy`` (imported lazily: the ``deploy`` extra), checked against NumPy on the
            task's check inputs (its ``verify_inputs``)
generate    motion from a network or a baseline, BVH out (the task's ``generate_command``)
render      a BVH / exp-map motion (optionally against a second one) to a PNG strip or a GIF
demo        the whole tour on the embedded sample (:mod:`refimpl.demo`)
import      a PyTorch state dict (.npz, .safetensors, .pt) as a checkpoint; ``export-weights`` the reverse
            (:mod:`refimpl.weights_cli`, spec/import.md)
cache       the data cache's entries and size; ``--clear`` empties it (:mod:`refimpl.cache_cli`)
pretrained  the shipped trained models and their cards; ``--checkpoint pretrained:<name>`` everywhere
            (:mod:`refimpl.pretrained`)
==========  ==============================================================================================

Exit codes (scripts may rely on them): 0 success; 1 runtime failure (including a missing optional dependency
and a diverged training run); 2 usage error (bad or missing options, from argparse); 3 bad input file (missing,
unreadable or malformed BVH / exp-map / checkpoint / ONNX file). Errors are one line on stderr,
``refimpl <command>: error: <message>``, without a traceback unless ``--traceback`` is given. Ctrl-C gives 130
(``train`` first saves a checkpoint at the step boundary).

This module is the argument parser, the ``cmd_*`` functions and what they print. It names no model and no task:
the work is done by :mod:`refimpl.services` (train, load, evaluate, export, verify), the models come from
:mod:`refimpl.registry` (``--model NAME``: a recipe in ``refimpl/recipes/``) and everything task-specific from the
model's task module (``refimpl/tasks/``, the interface :class:`refimpl.task_api.Task`): its options of every
command, ``eval_command``, ``generate_command``, ``export_options``, ``verify_inputs`` (spec/architecture.md).

Nothing here imports ``deploy``, onnx, onnxruntime or matplotlib at import time.

Shape legend: none (the commands pass files and options; arrays live in the tasks).
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
from typing import Sequence

import numpy as np

from refimpl.progress import stderr_line
from refimpl import cache_cli, weights_cli
from refimpl.allocator import retain_freed_memory
from refimpl.cli_info import cmd_info, cmd_pretrained
from refimpl.errors import BadInputError, MissingDependency, UsageError, reading
from refimpl.bounds import bounded_float, bounded_int
from refimpl.threads import AUTO, threads_option
from refimpl.options import add_data_options, add_export_length_option, beta, check_overrides, positive_float, positive_int
from refimpl.registry import DEFAULT_MODEL, MODELS, TASKS, generate_usage, task_of
from refimpl.pretrained import shipped_name
from refimpl.run_options import RUN_OPTIONS, reconcile, restore_intervals, run_options
from refimpl.threads import blas_thread_pool
from refimpl.services import (export_onnx, load_trained, onnx_metadata, read_motion, train_model,
                              verify_onnx)
from refimpl.train_files import check_resumable, output_lock

__all__ = ["main", "build_parser", "blas_threads_for", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_BAD_INPUT"]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_BAD_INPUT = 3
DEFAULT_EPOCHS = 10  # `train` without --steps / --epochs


def _say(*parts) -> None:
    print(*parts, flush=True)



# ----------------------------------------------------------------------------------------------------------------
# commands
# ----------------------------------------------------------------------------------------------------------------


def _reuse_run_options(args, ckpt: Path) -> None:
    """``--resume``: the options stored in the checkpoint fill those not given; a given option that differs is a
    usage error listing only the differing fields, before any data is read (spec/cli.md §4). The run's budget
    and its checkpoint / validation / progress intervals come from its stored ``train_config`` when not given."""
    from refimpl.checkpoint import load_checkpoint

    with reading(ckpt):
        _, meta = load_checkpoint(ckpt)
    if not isinstance(meta, dict):
        return
    train_config = meta.get("train_config") if isinstance(meta.get("train_config"), dict) else {}
    stored = train_config.get("run_options")
    if isinstance(stored, dict):  # else a checkpoint written before the options were stored: the flags as given
        if stored.get("model") not in MODELS:
            raise BadInputError(f"{ckpt}: run option model {stored.get('model')!r} is not one of {sorted(MODELS)}")
        conflicts = reconcile(args, _resolved_defaults(stored), args.option_defaults)
        if conflicts:
            raise UsageError(f"--resume: {ckpt} was trained with other options:\n  " + "\n  ".join(conflicts)
                             + "\n(leave them out to continue with the checkpoint's, or start again with --overwrite)")
    restore_intervals(args, train_config, args.option_defaults)
    if args.steps is None and args.epochs is None and isinstance(train_config.get("steps"), int):
        args.steps = train_config["steps"]  # the stored budget (old: the default 10 epochs)
    args.resume_step = meta.get("step")  # a finished run is refused once the output folder is locked


def _resolved_defaults(stored: dict) -> dict:
    """The stored options with an unset ``lr`` / ``betas`` / ``batch_size`` (None: the model's default, as
    checkpoints before #35 stored them) replaced by the model's value, so that a conflict names a number."""
    spec = MODELS[stored["model"]]
    filled = {"lr": spec.optim.lr, "betas": list(spec.optim.betas), "batch_size": spec.batch_size}
    return {k: (filled[k] if v is None and k in filled else v) for k, v in stored.items()}


def _refuse_finished(done, steps, ckpt: Path) -> None:
    """UsageError when the checkpoint is already at (or beyond) the budget ``steps``: nothing would be trained."""
    if isinstance(done, int) and isinstance(steps, int) and done >= steps:
        raise UsageError(f"--resume: {ckpt} is at step {done} of a {steps}-step budget: nothing to train "
                         f"(pass --steps N with N > {done} to train further)")


def _resumable(args) -> tuple:
    """The options that decide a run: :data:`refimpl.run_options.RUN_OPTIONS` and every task's train options."""
    return RUN_OPTIONS + tuple(dest for options in args.task_options.values() for dest, _, _ in options)


def cmd_train(args) -> int:
    """``refimpl train``."""
    if args.steps == 0 or (args.steps is None and args.epochs == 0):
        raise UsageError("--steps 0 / --epochs 0: nothing to train (a checkpoint would hold an untrained network)")
    out = Path(args.out or f"runs/{args.model}")
    if args.resume and (out / "checkpoint.npz").is_file():
        _reuse_run_options(args, out / "checkpoint.npz")
    spec = MODELS[args.model]
    task = task_of(spec)
    _refuse_other_tasks_options(args, spec.task, spec.name)
    rep = args.representation or spec.representations[0]
    if rep not in spec.representations:
        raise UsageError(f"--representation {rep!r}: model {spec.name!r} trains on {list(spec.representations)}")
    check_overrides(spec.config_type, args.set)  # a --set typo is exit 2 before any data is read
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
        args.batch_size = spec.batch_size
    if args.resume:
        _refuse_finished(getattr(args, "resume_step", None), args.steps, ckpt)  # before the data is read
    t0 = time.perf_counter()
    _say(f"reading {args.data} ...")
    train_ds, test_ds = task.train_datasets(args)
    config = spec.make_config(train_ds, args.set)
    if args.batch_size is None:
        args.batch_size = spec.batch_size
    n = task.num_examples(train_ds)
    per_epoch = max(1, n // min(args.batch_size, n))
    steps = args.steps if args.steps is not None else (args.epochs or DEFAULT_EPOCHS) * per_epoch
    if args.resume:
        _refuse_finished(getattr(args, "resume_step", None), steps, ckpt)  # --epochs E: the budget is known once the data is read
    _say(f"data: {task.describe_data(train_ds, test_ds)} in {time.perf_counter() - t0:.1f} s; "
         f"{per_epoch} steps per epoch")
    described = config.to_dict() if hasattr(config, "to_dict") else dataclasses.asdict(config)
    _say(f"model: {spec.name} {json.dumps(described)}")
    lr = spec.optim.lr if args.lr is None else args.lr
    betas = tuple(spec.optim.betas if args.betas is None else args.betas)
    args.lr, args.betas = lr, betas  # stored as numbers (spec/cli.md §4)
    _say(f"training {steps} steps (batch {args.batch_size}, Adam lr {lr:g}, betas {betas}) -> {out}/")
    result = train_model(spec, config, train_ds, test_ds, out, steps=steps, batch_size=args.batch_size,
                         lr=lr, betas=betas, clip_norm=args.clip_norm, seed=args.seed,
                         dtype=np.dtype(args.dtype).type, resume=args.resume,
                         checkpoint_every=args.checkpoint_every, validate_every=args.validate_every,
                         progress_every=args.progress_every, progress=stderr_line,
                         run_options=run_options(args, _resumable(args)), on_step=_thread_poll(args))
    last = float(np.mean(result.losses[-20:])) if result.losses else float("nan")
    _say(f"{'interrupted' if result.interrupted else 'done'}: step {result.step}, epoch {result.epoch}, "
         f"recent loss {last:.5g}, {result.elapsed_s:.1f} s")
    if getattr(args, "blas_auto", None) is not None:
        _say(f"BLAS threads (auto): {' -> '.join(map(str, args.blas_auto.applied))}")
    _say(f"checkpoint  {result.checkpoint_path}")
    _say(f"loss log    {out / 'loss.csv'}" + (f", {out / 'loss_val.csv'}" if args.validate_every else ""))
    if result.interrupted:
        return 128 + int(getattr(result, "signal", None) or 2)  # 130 for SIGINT / Ctrl-C, 143 for SIGTERM
    return EXIT_OK


def blas_threads_for(args):
    """The BLAS thread setting of a parsed command line: ``--blas-threads`` when given, else the command's default
    (``auto``; ``demo``: 1, so that its numbers are the same on every machine, spec/cli.md §1)."""
    return args.blas_threads if args.blas_threads is not None else getattr(args, "default_blas_threads", AUTO)


def _thread_poll(args):
    """The per-step hook of a training run: ``--blas-threads auto``'s poll (main sets ``args.blas_auto``), or None."""
    auto = getattr(args, "blas_auto", None)
    return None if auto is None else auto.poll


def _check_model_option(args, model) -> None:
    """``--model`` and ``--checkpoint`` must name the same network (the checkpoint would silently win)."""
    if model is not None and getattr(args, "model", None) and args.model != model.spec.name:
        raise UsageError(f"--model {args.model}, but {args.checkpoint} holds a {model.spec.name} model "
                         f"(leave --model out, or pass a {args.model} checkpoint)")


def cmd_eval(args) -> int:
    """``refimpl eval``: the task of ``--checkpoint``'s model (else of ``--model``, else of the default model)."""
    model = load_trained(args.checkpoint) if args.checkpoint else None
    _check_model_option(args, model)
    spec = model.spec if model is not None else MODELS[args.model or DEFAULT_MODEL]
    _refuse_other_tasks_options(args, spec.task, spec.name)  # eval --join of a QuaterNet: exit 2, not ignored
    return task_of(spec).eval_command(args, model)


def _default_export_dir(checkpoint: str, model) -> Path:
    """``onnx/`` beside the checkpoint; ``onnx/<name>/`` in the working folder for a shipped model (its folder
    belongs to the repository)."""
    name = shipped_name(checkpoint)
    if name is not None:
        return Path("onnx") / name
    return Path(model.path).parent / "onnx"


def cmd_export(args) -> int:
    """``refimpl export``."""
    model = load_trained(args.checkpoint)
    out = Path(args.out) if args.out else _default_export_dir(args.checkpoint, model)
    task = task_of(model.spec)
    _refuse_other_tasks_options(args, model.spec.task, model.spec.name)
    target = {} if args.target == "default" else {"target": args.target}
    written = export_onnx(model, out, mode=args.mode, dtype=np.dtype(args.dtype).type, **task.export_options(args),
                          **target)
    for role, path in written.items():
        _say(f"{role:8s} {path} ({Path(path).stat().st_size / 1024:.0f} KiB)")
    if args.verify:
        inputs, options = task.verify_inputs(args, model)
        check = verify_onnx(model, out, *inputs, **options)
        for k, v in check.items():
            if k != "ok":
                _say(f"verify   onnxruntime vs NumPy ({k}): max |diff| = {v:.3g}")
        if not check["ok"]:
            raise RuntimeError("onnxruntime and NumPy disagree beyond the recipe's verification tolerance "
                               f"(refimpl.recipes.{model.spec.name.replace('-', '_')}; spec/cli.md)")
    return EXIT_OK


def _refuse_other_tasks_options(args, task: str, who: str) -> None:
    """UsageError for an option of another task's group given a value (``export --join`` of a model whose task
    has no such option; ``generate --target`` of a model whose task has no target clip)."""
    for task_name, options in args.task_options.items():
        for dest, default, flag in options:
            if task_name != task and getattr(args, dest) != default:
                raise UsageError(f"{flag} applies to {task_name} models, not {who}")


def _add_task_options(p, add) -> None:
    """Every task's options of a command, each in its own group (``add(task, group)``: the task's hook);
    ``args.task_options`` records them: task -> [(dest, default, flag)]."""
    owned = {}
    for task_name in TASKS:
        group = p.add_argument_group(f"{task_name} task")
        add(task_of(task_name), group)
        owned[task_name] = [(a.dest, a.default, a.option_strings[0]) for a in group._group_actions]
    p.set_defaults(task_options=owned)


def _generate_task(args):
    """``(task module, loaded --checkpoint or None)`` of ``refimpl generate``: the task of ``--model`` (the task
    then reads its checkpoints itself), else of ``--checkpoint``'s model, else of the exported models in
    ``--onnx``, else of the default model."""
    if args.model is not None:
        return task_of(MODELS[args.model]), None
    model = load_trained(args.checkpoint) if args.checkpoint else None
    if model is not None:
        return task_of(model.spec), model
    if args.backend == "onnx" and args.onnx:
        model_meta = onnx_metadata(args.onnx).get("model") or {}
        if not isinstance(model_meta, dict):
            raise BadInputError(f"{args.onnx}: metadata model: expected a JSON object, got "
                                f"{type(model_meta).__name__}")
        name = model_meta.get("name")
        if isinstance(name, str) and name in MODELS:
            return task_of(MODELS[name]), None
    return task_of(MODELS[DEFAULT_MODEL]), None


def cmd_generate(args) -> int:
    """``refimpl generate``: the task's ``generate_command`` (options of another task's group are refused)."""
    if args.model is not None and args.checkpoint:
        _check_model_option(args, load_trained(args.checkpoint))
    task, model = _generate_task(args)
    _refuse_other_tasks_options(args, task.NAME, model.spec.name if model is not None else f"a {task.NAME} run")
    return task.generate_command(args, model)


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
    title = args.title or (Path(args.file).name + (f" (blue) against {Path(args.compare).name} (red)"
                                                   if args.compare else ""))  # every picture has a title
    step = sel.step or 1
    for out in outs:
        suffix = Path(out).suffix.lower()
        if suffix == ".png":
            render_strip(out, pos, parents, prediction=pred, num_frames=args.num_frames, labels=labels,
                         up=args.up, frame_time=motion.frame_time, frame_numbers=idx, title=title, sides=sides)
        elif suffix == ".gif":
            render_gif(out, pos, parents, prediction=pred, fps=motion.fps / step, stride=args.stride, labels=labels,
                       progress=stderr_line,
                       up=args.up, frame_numbers=idx, title=title, sides=sides)
        else:
            raise UsageError(f"--out {out}: expected a .png or .gif file name")
        _say(f"wrote {out} ({len(idx)} frames of {args.file})")
    return EXIT_OK


def cmd_demo(args) -> int:
    """``refimpl demo``."""
    from refimpl.demo import run_demo

    run_demo(args.out, seed=args.seed, quick=args.quick, steps=args.steps, onnx=not args.no_onnx,
             render=not args.no_render, overwrite=args.overwrite, threads=0,
             on_step=_thread_poll(args))  # the pool is --blas-threads' (main)
    return EXIT_OK


# ----------------------------------------------------------------------------------------------------------------
# parser and main
# ----------------------------------------------------------------------------------------------------------------


def _add_pretrained_parser(sub) -> None:
    """``refimpl pretrained [NAME]``: the shipped trained models and their cards (spec/cli.md §11)."""
    p = sub.add_parser("pretrained", help="list the shipped trained models (pretrained:<name>) and their cards",
                       description="List the shipped trained models, or show one's card. Each is used by name "
                                   "wherever a checkpoint is accepted: --checkpoint pretrained:<name> (eval, "
                                   "generate, export, info, every checkpoint option, python -m deploy export); its file is checked "
                                   "against the card's sha256 first (a damaged or missing file: exit 3).")
    p.add_argument("name", nargs="?", default=None, help="a model's name: print its card")
    p.add_argument("--json", action="store_true", help="the card(s) as JSON")
    p.set_defaults(func=cmd_pretrained)


def _add_info_parser(sub) -> None:
    """``refimpl info FILE``: what a motion file, checkpoint or ONNX model holds."""
    p = sub.add_parser("info", help="what a .bvh, exp-map .txt, checkpoint .npz or .onnx file holds",
                       description="Print joints, frames, frame rate and channel layout of a motion file; "
                                   "parameters, shapes and metadata of a checkpoint or ONNX model.")
    p.add_argument("file")
    p.add_argument("--joints", action="store_true", help="list the joint hierarchy with offsets")
    p.add_argument("--layout", default="cmu", choices=("cmu", "h36m"), help="exp-map layout (default cmu)")
    p.add_argument("--fps", type=bounded_float("fps"), default=None, help="override the frame rate")
    p.set_defaults(func=cmd_info)


def _add_train_parser(sub) -> None:
    """``refimpl train``: the run's options (``--model``, data, length, optimiser, files) and every task's group."""
    p = sub.add_parser("train", help=f"train a network ({', '.join(sorted(MODELS))}) on motion files",
                       description="Train a network with Adam; checkpoint.npz (resumable), loss.csv and "
                                   "loss_val.csv go to --out. Progress lines (rate, ETA) go to stderr. "
                                   "Models: " + "; ".join(f"{n}: {s.summary}" for n, s in sorted(MODELS.items())))
    p.add_argument("--model", default=DEFAULT_MODEL, choices=sorted(MODELS), help=f"network (default {DEFAULT_MODEL})")
    p.add_argument("--representation", default=None,
                   help="pose representation (default: the model's first; "
                        + "; ".join(f"{n}: {', '.join(s.representations)}" for n, s in sorted(MODELS.items())) + ")")
    add_data_options(p)
    p.add_argument("--out", default=None, help="output folder (default runs/<model>)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--steps", type=bounded_int("steps"), default=None, help="optimiser steps")
    length.add_argument("--epochs", type=bounded_int("steps"), default=None,
                        help=f"epochs, when --steps is not given (default {DEFAULT_EPOCHS}; --resume: the stored budget)")
    p.add_argument("--batch-size", type=bounded_int("batch"), default=None,
                   help="batch size (default: the model's paper value; "
                        + ", ".join(f"{n} {s.batch_size}" for n, s in sorted(MODELS.items())) + ")")
    p.add_argument("--lr", type=positive_float, default=None,
                   help="Adam learning rate (default: the model's paper value; "
                        + ", ".join(f"{n} {s.optim.lr:g}" for n, s in sorted(MODELS.items())) + ")")
    p.add_argument("--betas", type=beta, nargs=2, default=None, metavar=("B1", "B2"),
                   help="Adam betas (default: the model's paper values)")
    p.add_argument("--clip-norm", type=positive_float, default=None, help="global gradient-norm clipping")
    _add_task_options(p, lambda task, group: task.add_train_options(group))
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a config field, e.g. --set gru_hidden=128 --set encoder_sizes=128,64")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--seed", type=int, default=0)
    resume = p.add_mutually_exclusive_group()
    resume.add_argument("--resume", action="store_true",
                        help="continue from --out/checkpoint.npz with the options stored in it (give only "
                             "--steps/--epochs; a different option is refused, field by field)")
    resume.add_argument("--overwrite", action="store_true", help="start again, replacing --out's checkpoint and logs")
    p.add_argument("--checkpoint-every", type=bounded_int("every"), default=500)
    p.add_argument("--validate-every", type=bounded_int("every"), default=None,
                   help="log the held-out MAE every N steps (loss_val.csv)")
    p.add_argument("--progress-every", type=bounded_int("every"), default=50)
    p.set_defaults(func=cmd_train, option_defaults={a.dest: a.default for a in p._actions})


def _add_eval_parser(sub) -> None:
    """``refimpl eval``: ``--checkpoint`` / ``--onnx``, data, outputs and every task's group."""
    p = sub.add_parser("eval", help="a network against its task's baselines, under its task's protocol",
                       description="Evaluate a network (--checkpoint, --onnx) or, without one, the baselines of "
                                   "--model's task, under the task's protocol. "
                                   + " ".join(f"{task_of(t).EVAL_SUMMARY[0].upper()}{task_of(t).EVAL_SUMMARY[1:]}."
                                              for t in TASKS))
    p.add_argument("--checkpoint", default=None, help="a `refimpl train` checkpoint (omit: baselines only)")
    p.add_argument("--onnx", default=None, help="also evaluate the exported models of this folder (onnxruntime)")
    add_data_options(p)
    p.add_argument("--json", default=None, help="write all results as JSON")
    p.add_argument("--plot", default=None, help="write the per-frame curves as PNG (matplotlib)")
    p.add_argument("--model", default=None, choices=sorted(MODELS),
                   help=f"without --checkpoint: evaluate the baselines of this model's task (default "
                        f"{DEFAULT_MODEL}'s); the checkpoint's model decides otherwise")
    _add_task_options(p, lambda task, group: task.add_eval_options(group))
    p.set_defaults(func=cmd_eval)


def _add_export_parser(sub) -> None:
    """``refimpl export``: ``--checkpoint``, the graph form and check, and every task's group."""
    p = sub.add_parser("export", help="export a checkpoint of any model to ONNX, verified (needs the deploy extra)",
                       description="Write the model's ONNX files <model>_<role>.onnx (validated; the exporter's "
                                   "roles); the graphs standardise inside (raw poses in and out) and carry their "
                                   "metadata. A folder holding another network's graphs is refused before anything "
                                   "is written.")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--out", default=None, help="output folder (default: onnx/ beside the checkpoint)")
    p.add_argument("--mode", default="unrolled", choices=("unrolled", "loop", "scan"), help="rollout graph form")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--target", default="default", choices=("default", "portable"),
                   help="default: today's graphs (onnxruntime); portable: per-call graphs at opset 15, batch 1, "
                        "primitive operators, the host loop in the metadata (deploy/README.md)")
    p.add_argument("--no-verify", dest="verify", action="store_false",
                   help="skip the onnxruntime-vs-NumPy check on the task's check inputs")
    p.add_argument("--seed", type=int, default=0, help="seed of the check's random inputs")
    add_export_length_option(p)
    _add_task_options(p, lambda task, group: task.add_export_options(group))
    p.set_defaults(func=cmd_export)


def _add_generate_parser(sub) -> None:
    """``refimpl generate``: the source, backend, outputs and every task's group."""
    p = sub.add_parser("generate", help="generate motion with a network or a baseline, BVH out (every model: "
                                        "`refimpl generate --help` lists each task's form)",
                       description="Generate motion with the task of --model (else of --checkpoint's model, else "
                                   f"of the exported models in --onnx, else {DEFAULT_MODEL}'s) and write a BVH.",
                       usage=generate_usage().replace("usage: ", "", 1))
    p.add_argument("--source", default=None, help=".bvh or exp-map .txt: the source clip, prefix or seed")
    p.add_argument("--source-frame", type=bounded_int("frame_index"), default=None,
                   help="frame of --source where the task starts (see the usage lines above)")
    p.add_argument("--checkpoint", default=None, help="a `refimpl train` checkpoint (NumPy backend)")
    p.add_argument("--backend", default="numpy", choices=("numpy", "onnx"))
    p.add_argument("--onnx", default=None, help="folder of exported models (ONNX backend)")
    p.add_argument("--length", type=bounded_int("frames"), default=None,
                   help="frames to generate (default: the task's)")
    p.add_argument("--out", default=None, help="output BVH (default: the task's)")
    p.add_argument("--truth", default=None, help="also write the ground truth, when the file has it")
    p.add_argument("--png", default=None, help="also render a PNG strip (matplotlib)")
    p.add_argument("--gif", default=None, help="also render a GIF (matplotlib)")
    p.add_argument("--model", default=None, choices=sorted(MODELS),
                   help="the network, and so the task, when the checkpoint does not say it (default: the "
                        "checkpoint's model)")
    _add_task_options(p, lambda task, group: task.add_generate_options(group))
    p.set_defaults(func=cmd_generate)


def _add_render_parser(sub) -> None:
    """``refimpl render``: a motion (and a second one to compare) to PNG / GIF."""
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
    p.add_argument("--fps", type=bounded_float("fps"), default=None, help="override the frame rate")
    p.set_defaults(func=cmd_render)


def _add_demo_parser(sub) -> None:
    """``refimpl demo``: the tour's folder, seed and switches."""
    p = sub.add_parser("demo", help="train, evaluate, export, verify, generate and render on the sample",
                       description="The whole tour on the embedded CMU sample in a few minutes on 2 cores.")
    p.add_argument("--out", default="demo_out", help="output folder (default ./demo_out)")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the results of a longer demo in --out (a --quick run refuses otherwise)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="a tiny network and a few steps (a smoke test, ~30 s)")
    p.add_argument("--steps", type=positive_int, default=None, help="override the number of training steps")
    p.add_argument("--no-onnx", action="store_true", help="skip export and verification")
    p.add_argument("--no-render", action="store_true", help="skip the pictures")
    p.set_defaults(func=cmd_demo, default_blas_threads=1)  # reproducible numbers: BLAS rounding depends on threads


def _add_global_options(parser) -> None:
    """The options before the command: ``--traceback``, ``--blas-threads``, ``--malloc``."""
    parser.add_argument("--traceback", action="store_true", help="show the full traceback of an error")
    parser.add_argument("--blas-threads", type=threads_option, default=None, metavar="{auto,N}",
                        help="BLAS threads for NumPy (default auto, except demo: 1, so that its numbers are the "
                             "same on every machine; auto = the cores other processes leave free, measured "
                             "from /proc at the start and every ~2 s of training; 1 without /proc. A fixed count "
                             "N forces it: 2 threads are faster on an idle 2-core machine but 8-31x slower when "
                             "other jobs share the cores, benchmarks/bench_thread_default.py; 0 = library default; "
                             "needs threadpoolctl)")
    parser.add_argument("--malloc", choices=("retain", "system"), default="retain",
                        help="C allocator settings (glibc): 'retain' (default) keeps freed memory for the next "
                             "training step instead of faulting it in again (step time 0.76-0.99x of glibc's defaults, "
                             "benchmarks/bench_allocator.py); 'system' leaves glibc's defaults")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``refimpl`` (see spec/cli.md)."""
    import refimpl

    what = refimpl.__doc__.splitlines()[0].partition(": ")[2].rstrip(".")  # the package's one-line summary
    parser = argparse.ArgumentParser(
        prog="refimpl",
        description=f"{what[0].upper()}{what[1:]}: inspect files, train, evaluate, export to ONNX, generate "
                    "motion, render. Start with `refimpl demo`.",
        epilog="exit codes: 0 ok, 1 runtime failure, 2 usage error, 3 bad input file")
    parser.add_argument("--version", action="version", version=f"refimpl {refimpl.__version__}")
    _add_global_options(parser)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    _add_info_parser(sub)
    _add_train_parser(sub)
    _add_eval_parser(sub)
    _add_export_parser(sub)
    _add_generate_parser(sub)
    _add_render_parser(sub)
    _add_demo_parser(sub)
    weights_cli.add_parsers(sub)  # import, export-weights (spec/import.md)
    _add_pretrained_parser(sub)
    cache_cli.add_parser(sub)  # cache [--clear] (spec/cli.md §11)
    return _global_options_after_the_command(parser)


#: The top-level options that every sub-command also accepts after its name (spec/cli.md §1).
GLOBAL_OPTIONS = ("--traceback", "--blas-threads", "--malloc")


def _global_options_after_the_command(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Copy :data:`GLOBAL_OPTIONS` into every sub-command's parser (``refimpl train ... --blas-threads 1``), with
    no default there, so that a value given before the command is kept unless given again after it."""
    top = {a.option_strings[0]: a for a in parser._actions if a.option_strings}
    for sub in _subparsers(parser).choices.values():
        group = sub.add_argument_group("options of every command (also before it)")
        for flag in GLOBAL_OPTIONS:
            a = top[flag]
            extra = {} if a.nargs == 0 else {"type": a.type, "choices": a.choices, "metavar": a.metavar}
            group.add_argument(flag, dest=a.dest, default=argparse.SUPPRESS, help=a.help,
                               **({"action": "store_true"} if a.nargs == 0 else extra))
    return parser


def _subparsers(parser: argparse.ArgumentParser):
    return next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))


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
        args, unknown = parser.parse_known_args(argv)
        if unknown:  # with the sub-command's usage (`train --modle qtg`), not the top level's
            command = _subparsers(parser).choices.get(getattr(args, "command", None), parser)
            command.error(f"unrecognized arguments: {' '.join(unknown)}")
    except SystemExit as exc:  # argparse: --help / --version (0) or a usage error (2)
        return exc.code if isinstance(exc.code, int) else (EXIT_OK if exc.code is None else EXIT_USAGE)
    if args.command is None:
        parser.print_help(sys.stderr)
        return EXIT_USAGE
    prog = _prog(args)
    if args.malloc == "retain":
        retain_freed_memory()
    try:
        with blas_thread_pool(blas_threads_for(args)) as auto:
            args.blas_auto = auto  # train polls it every step (refimpl/threads.py)
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
