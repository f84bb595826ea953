"""The work behind ``refimpl``'s commands and its demo (spec/cli.md): train, load, evaluate, export, verify.

Both :mod:`refimpl.cli` and :mod:`refimpl.demo` call these; they know models only through
:mod:`refimpl.registry` (a :class:`~refimpl.registry.ModelSpec` from the model's recipe) and tasks only through
the task module the spec names. ``deploy`` (onnx, onnxruntime) is imported lazily, inside the functions that need
it, and its absence is a :class:`~refimpl.errors.MissingDependency` with the install hint.

Shape legend: none (arrays are the tasks' and the recipes', see their modules).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

import numpy as np

from refimpl.errors import (DEPLOY_HINT, BadInputError, MissingDependency, UsageError, existing_file, reading)
from refimpl.pretrained import resolve_checkpoint
from refimpl.registry import MODELS, ModelSpec, TrainedModel, task_of

__all__ = ["read_motion", "load_trained", "checkpoint_for", "train_model", "network_methods",
           "evaluate_model", "onnx_method", "export_onnx", "verify_onnx", "onnx_metadata", "onnx_frame_rate"]


def read_motion(path, *, fps: float | None = None, layout: str = "cmu"):
    """Read a ``.bvh`` or exp-map ``.txt`` file into a :class:`~refimpl.motion.Motion`.

    Raises
    ------
    BadInputError
        Missing, unreadable or malformed file, or an unknown suffix.
    """
    from refimpl.bvh import read_bvh
    from refimpl.expmap import read_expmap

    p = existing_file(path)
    frame_time = None if fps is None else 1.0 / fps
    with reading(p):
        if p.suffix.lower() == ".bvh":
            return read_bvh(p, frame_time=frame_time)
        if p.suffix.lower() == ".txt":
            return read_expmap(p, layout=layout, frame_time=frame_time)
    raise BadInputError(f"{p}: unknown motion file type {p.suffix!r} (expected .bvh or an exp-map .txt)")


def load_trained(path) -> TrainedModel:
    """Read a checkpoint written by ``refimpl train`` (or :func:`train_model`); ``pretrained:<name>`` reads a
    shipped model once its checksum matches its card (:mod:`refimpl.pretrained`).

    Raises
    ------
    BadInputError
        Missing or damaged file, not a training checkpoint, unknown model, missing task fields (the task's
        ``check_checkpoint``), or content that fails the checkpoint schema
        (:mod:`refimpl.checkpoint_schema`: a config field of the wrong type or range, ``fps`` or ``root_std``
        not > 0, a parameter missing, unexpected, mis-shaped, of another dtype or not finite); the message
        names the file and the field.
    """
    from refimpl.checkpoint import load_checkpoint
    from refimpl.checkpoint_schema import validate_trained

    p = existing_file(resolve_checkpoint(path))
    with reading(p):
        arrays, meta = load_checkpoint(p)
        # the whole schema (spec/robustness.md §9) before anything is built: config types, task fields,
        # every parameter's name, shape, dtype and finiteness against the config's shapes
        spec, config, params, cfg = validate_trained(arrays, meta, MODELS, str(p), task_of=task_of)
    task = task_of(spec)
    task.check_checkpoint(cfg, p)
    params = {k: np.asarray(v) for k, v in params.items()}
    return TrainedModel(spec=spec, config=config, params=params, meta=meta, path=str(p), extra=cfg,
                        **task.trained_fields(cfg, config))


def checkpoint_for(task: str, model: TrainedModel | None, path) -> TrainedModel | None:
    """``model``, else the checkpoint at ``path`` (None when there is none), checked to be a model of ``task``.

    Raises
    ------
    UsageError
        The checkpoint's model is registered for another task.
    """
    if model is None and path:
        model = load_trained(path)
    if model is not None and model.spec.task != task:
        raise UsageError(f"{model.path}: a {model.spec.name} model (task {model.spec.task}), not a model of the "
                         f"{task} task (--model and --checkpoint disagree)")
    return model


def train_model(spec: ModelSpec, config, train_ds, val_ds, out_dir, *, steps: int, batch_size: int = 32,
                lr: float | None = None, betas=None, clip_norm: float | None = None, seed: int = 0,
                dtype=np.float32, resume: bool = False, checkpoint_every: int = 500,
                validate_every: int | None = None, progress_every: int = 100,
                progress: Callable[[str], None] | None = None, run_options: dict | None = None,
                on_step: Callable[..., None] | None = None):
    """Train ``spec``'s network into ``out_dir`` (``checkpoint.npz``, ``loss.csv``, ``loss_val.csv``).

    ``lr`` and ``betas`` default to the recipe's paper values (``spec.optim``). The checkpoint's model config also
    holds what the task needs later (its ``checkpoint_extra``: statistics, frame rate, skeleton, ...), so that
    ``eval``, ``export`` and ``generate`` need nothing else; ``run_options`` (the command line's,
    :mod:`refimpl.run_options`) go into its ``train_config`` for ``--resume``. ``on_step`` is the training
    loop's per-step ``callback`` (the command line passes :meth:`refimpl.threads.AutoThreads.poll`).

    Returns
    -------
    TrainResult
    """
    from refimpl.train import TrainConfig, train

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    extra = dict(task_of(spec).checkpoint_extra(train_ds), representation=spec.representations[0])
    adapter = spec.make_adapter(train_ds, val_ds, config, dtype, extra)
    _check_writable_checkpoint(spec, adapter)
    optim = dataclasses.replace(spec.optim, lr=spec.optim.lr if lr is None else lr,
                                betas=tuple(spec.optim.betas if betas is None else betas),
                                clip_norm=spec.optim.clip_norm if clip_norm is None else clip_norm)
    tc = TrainConfig(steps=steps, batch_size=batch_size, seed=seed, checkpoint_path=str(out_dir / "checkpoint.npz"),
                     checkpoint_every=checkpoint_every, log_path=str(out_dir / "loss.csv"),
                     progress_every=progress_every, validate_every=validate_every, run_options=run_options)
    kw = {} if progress is None else {"progress": progress}
    return train(adapter, optim, tc, resume=resume, callback=on_step, **kw)


def _check_writable_checkpoint(spec: ModelSpec, adapter) -> None:
    """Refuse (``UsageError``, exit 2) a run whose checkpoint the loader would refuse — a config or task field
    outside the checkpoint schema (:func:`refimpl.checkpoint_schema.validate_checkpoint_config`) — or whose
    network exceeds :data:`refimpl.bounds.MAX_PARAMETERS`, before any parameter is allocated."""
    import json

    from refimpl.bounds import check_parameter_count
    from refimpl.checkpoint_schema import validate_checkpoint_config
    where = f"the checkpoint of this {spec.name} run"
    try:  # the model_config exactly as the checkpoint's JSON metadata will hold it
        model_config = json.loads(json.dumps(adapter.config, allow_nan=False,
                                             default=lambda v: v.item() if isinstance(v, np.generic) else str(v)))
        _, shapes = validate_checkpoint_config(spec, model_config, where, task_of)
        check_parameter_count(shapes, where)
    except ValueError as exc:
        raise UsageError(f"{exc} (the loader would refuse it; nothing trained)") from None


def network_methods(model: TrainedModel | None = None, *, onnx_dir=None, expect: TrainedModel | None = None) -> dict:
    """``name -> method`` of the network: NumPy (``<name>``) and, from ``onnx_dir``, onnxruntime (``<name>_onnx``,
    in the task's method interface: its ``onnx_method``).

    ``onnx_dir`` must hold the exported models of ``model`` (or of ``expect``, the checkpoint the command runs
    when only the exported models are run): another model's folder is a ``BadInputError`` naming the folder."""
    methods = {}
    if model is not None:
        methods[model.spec.name] = model.spec.make_method(model)
    if onnx_dir is not None:
        name = _onnx_model_name(onnx_dir)
        want = model if model is not None else expect
        if want is not None and name != want.spec.name:  # the folder must hold this command's model
            raise BadInputError(f"{onnx_dir}: holds exported {name!r} models, not the {want.spec.name!r} model of "
                                f"{want.path}")
        if want is not None:
            _check_same_network(onnx_dir, want)
        methods[f"{name}_onnx"] = onnx_method(onnx_dir)
    return methods


def _check_same_network(onnx_dir, want: TrainedModel) -> None:
    """The exported models' ``model.config`` must agree with the checkpoint's config on every field both hold
    (a folder of another pose representation has another ``frame_size``): ``BadInputError`` naming the field,
    when the folder is opened rather than at the first step."""
    import json

    exported = (onnx_metadata(onnx_dir).get("model") or {}).get("config")
    if not isinstance(exported, dict):
        raise BadInputError(f"{onnx_dir}: metadata model.config: expected a JSON object, got "
                            f"{type(exported).__name__}")
    ours = json.loads(json.dumps(want.extra, default=str))
    differ = [k for k in sorted(set(exported) & set(ours)) if json.dumps(exported[k]) != json.dumps(ours[k])]
    if differ:
        k = differ[0]
        raise BadInputError(f"{onnx_dir}: exported from another {want.spec.name} network than {want.path}: config "
                            f"{k} is {json.dumps(exported[k])[:60]} there, {json.dumps(ours[k])[:60]} in the "
                            f"checkpoint" + (f" (and {len(differ) - 1} more fields)" if len(differ) > 1 else ""))


def evaluate_model(model: TrainedModel | None, test_ds, *, onnx_dir=None, task: str | None = None, **options):
    """The task's protocol on ``test_ds`` (its ``evaluate``) for the network (NumPy, and onnxruntime from
    ``onnx_dir``) and the task's baselines; ``task`` names the task when there is no ``model``; ``options`` go to
    the task's ``methods``."""
    if model is None and task is None:
        raise ValueError("evaluate_model: pass a model or a task name")
    mod = task_of(model.spec if model is not None else task)
    return mod.evaluate(test_ds, mod.methods(network_methods(model, onnx_dir=onnx_dir), fps=test_ds.fps, **options))


def _deploy_models(what: str):
    try:
        import deploy.models
    except ImportError as exc:
        raise MissingDependency(f"{what} {DEPLOY_HINT} ({exc})") from exc
    return deploy.models


def _onnx_model_name(onnx_dir) -> str:
    d = Path(onnx_dir)
    if not d.is_dir():
        raise BadInputError(f"{d}: no such folder of ONNX models")
    models = _deploy_models("the ONNX backend")
    with reading(d):
        return models.model_name_of_dir(d)


def _open_runtime(onnx_dir, intra_op_threads: int = 1):
    d = Path(onnx_dir)
    if not d.is_dir():
        raise BadInputError(f"{d}: no such folder of ONNX models")
    models = _deploy_models("the ONNX backend")
    with reading(d):
        return models.runtime_for_dir(d, intra_op_threads=intra_op_threads)


def onnx_method(onnx_dir, intra_op_threads: int = 1) -> Callable:
    """The network of the exported models in ``onnx_dir``, run in onnxruntime, in its task's method interface
    (the task's ``onnx_method``).

    The runtime is the one of the model named in the files' metadata (``deploy.models.runtime_for_dir``); the
    task is the one that model is registered for.
    """
    name = _onnx_model_name(onnx_dir)
    spec = MODELS.get(name)
    if spec is None:
        raise BadInputError(f"{onnx_dir}: exported model {name!r} is not a known model; known: {sorted(MODELS)}")
    return task_of(spec).onnx_method(_open_runtime(onnx_dir, intra_op_threads))


def export_onnx(model: TrainedModel, out_dir, **options) -> dict:
    """Export ``model`` with its exporter (``deploy.models.EXPORTERS[spec.exporter]``) to validated ONNX files
    ``<name>_<role>.onnx`` in ``out_dir`` (the roles are the exporter's; standardisation inside the graphs).

    ``options``: ``mode`` (rollout graph: ``unrolled``, ``loop``, ``scan``; default ``unrolled``), ``dtype``
    (default float32), and the task's ``export_options`` (the exporter's keywords); an option given as None leaves
    the recipe's value (its ``export_inputs``).

    Returns
    -------
    dict role -> Path
    """
    if model.spec.exporter is None:
        raise UsageError(f"model {model.spec.name!r} has no ONNX exporter")
    entry = _deploy_models("ONNX export").exporter(model.spec.exporter)
    _check_export_dir(Path(out_dir), model.spec.exporter)
    kw = dict(model.spec.export_inputs(model)) if model.spec.export_inputs is not None else {}
    mode, dtype = options.pop("mode", "unrolled"), options.pop("dtype", np.float32)
    kw.update({k: v for k, v in options.items() if v is not None})
    return entry.export_dir(model.params, model.config, Path(out_dir), dtype=dtype, mode=mode, **kw)


def _check_export_dir(out_dir: Path, name: str) -> None:
    """Refuse, before anything is written, a folder holding ONNX models of another network than ``name``
    (exported side by side they would make the folder unusable for both: a runtime opens one network's
    models)."""
    if not out_dir.is_dir():
        return
    from deploy.metadata import read_metadata

    others = set()
    for f in sorted(out_dir.glob("*.onnx")):
        try:
            model = read_metadata(str(f)).get("model")
        except Exception:  # noqa: BLE001 - an unreadable .onnx is not ours to overwrite either
            model = None
        other = model.get("name") if isinstance(model, dict) else None
        if other != name:
            others.add(f"{f.name} ({other or 'no refimpl metadata'})")
    if others:
        raise UsageError(f"--out {out_dir}: holds ONNX models of another network: {', '.join(sorted(others)[:4])}"
                         f"{' ...' if len(others) > 4 else ''}; export {name} into another folder")


def verify_onnx(model: TrainedModel, onnx_dir, *inputs, **options) -> dict:
    """Compare onnxruntime with the NumPy model on the task's check inputs (``recipe.verify_onnx(model, runtime,
    *inputs, **options)``, ``ModelSpec.verify_onnx``; the inputs from the task's ``verify_inputs``).

    Returns
    -------
    dict ``{<graph>: max |Δ|, ..., "ok": bool}``
    """
    if model.spec.verify_onnx is None:
        raise UsageError(f"model {model.spec.name!r} has no ONNX check")
    return model.spec.verify_onnx(model, _open_runtime(onnx_dir), *inputs, **options)


def onnx_metadata(onnx_dir) -> dict:
    """The metadata of the first ``*_rollout.onnx`` (else ``*_step.onnx``, ``*_predict.onnx``, ``*_window.onnx``)
    model in ``onnx_dir``."""
    d = Path(onnx_dir)
    files = (sorted(d.glob("*_rollout.onnx")) + sorted(d.glob("*_step.onnx")) + sorted(d.glob("*_predict.onnx"))
             + sorted(d.glob("*_window.onnx")))
    if not files:
        raise BadInputError(f"{d}: no exported *_rollout.onnx / *_step.onnx / *_predict.onnx / *_window.onnx models")
    try:
        from deploy.metadata import read_metadata
    except ImportError as exc:
        raise MissingDependency(f"the ONNX backend {DEPLOY_HINT}") from exc
    with reading(files[0]):
        return read_metadata(str(files[0]))


def onnx_frame_rate(onnx_dir) -> tuple[float, dict]:
    """``(frame rate, metadata["model"])`` of the exported models in ``onnx_dir``, checked: a rate that is not a
    finite number > 0, or a model entry that is not a JSON object, is a bad input file (exit 3), not a
    ZeroDivisionError later.

    Raises
    ------
    BadInputError
    """
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
    return float(fps), model_meta
