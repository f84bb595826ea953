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
            joint-position error per joint per frame in cm, per-frame curve (:mod:`refimpl.metrics`)
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

Models plug in through :data:`MODELS` (name -> :class:`ModelSpec`): how to build the config, the trainer's
:class:`~refimpl.train.ModelAdapter`, the NumPy inference callable and the ONNX exporter. Today only QTG is
registered; QuaterNet and acRNN enter the same table by name.

Nothing here imports ``deploy``, onnx, onnxruntime or matplotlib at import time.

Shape legend: N windows, T transition frames, F frames of a clip, J joints, P pose size (3 + 4 J).
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.models.qtg import QTGConfig

__all__ = [
    "main", "build_parser", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_BAD_INPUT", "BadInputError",
    "UsageError", "ModelSpec", "MODELS", "TrainedModel", "SAMPLE_DIR", "resolve_data", "source_for_file",
    "read_motion", "load_trained", "train_model", "evaluate_model", "export_onnx", "verify_onnx", "onnx_method",
    "transition_methods", "Transition", "make_transition", "with_end_sites", "blas_threads", "print_results",
    "write_results", "render_transition",
]

EXIT_OK = 0
EXIT_FAILURE = 1
EXIT_USAGE = 2
EXIT_BAD_INPUT = 3

#: The embedded CMU sample (see its README.md): the default data of ``train``, ``eval`` and ``demo``.
SAMPLE_DIR = Path(__file__).resolve().parent / "data" / "sample"

_DEPLOY_HINT = "needs the deploy extra: pip install 'refimpl[deploy]' (onnx and onnxruntime)"


class BadInputError(Exception):
    """A file named on the command line is missing, unreadable or malformed (exit code 3)."""


class UsageError(Exception):
    """Options that parse but do not make sense together (exit code 2)."""


class _MissingDependency(Exception):
    """An optional dependency is not installed (exit code 1)."""


# ----------------------------------------------------------------------------------------------------------------
# files and data
# ----------------------------------------------------------------------------------------------------------------

def _file_error(path, exc: BaseException) -> BadInputError:
    """A :class:`BadInputError` for ``path`` from the reader's exception (its message already names the file)."""
    msg = str(exc)
    if isinstance(exc, FileNotFoundError):
        msg = f"{path}: no such file"
    elif isinstance(exc, IsADirectoryError):
        msg = f"{path}: is a directory, expected a file"
    elif isinstance(exc, PermissionError):
        msg = f"{path}: permission denied"
    elif isinstance(exc, UnicodeDecodeError):
        msg = f"{path}: not a text file ({exc.reason})"
    elif str(path) not in msg:
        msg = f"{path}: {msg}"
    return BadInputError(msg)


@contextlib.contextmanager
def _reading(path):
    """Turn the readers' errors about ``path`` into :class:`BadInputError`."""
    try:
        yield
    except (OSError, ValueError, UnicodeDecodeError, EOFError, KeyError) as exc:
        raise _file_error(path, exc) from exc


def _existing_file(path) -> Path:
    p = Path(path)
    if not p.exists():
        raise BadInputError(f"{p}: no such file")
    if p.is_dir():
        raise BadInputError(f"{p}: is a directory, expected a file")
    return p


def read_motion(path, *, fps: float | None = None, layout: str = "cmu"):
    """Read a ``.bvh`` or exp-map ``.txt`` file into a :class:`~refimpl.motion.Motion`.

    Raises
    ------
    BadInputError
        Missing, unreadable or malformed file, or an unknown suffix.
    """
    from refimpl.bvh import read_bvh
    from refimpl.expmap import read_expmap

    p = _existing_file(path)
    frame_time = None if fps is None else 1.0 / fps
    with _reading(p):
        if p.suffix.lower() == ".bvh":
            return read_bvh(p, frame_time=frame_time)
        if p.suffix.lower() == ".txt":
            return read_expmap(p, layout=layout, frame_time=frame_time)
    raise BadInputError(f"{p}: unknown motion file type {p.suffix!r} (expected .bvh or an exp-map .txt)")


def _declared_rate(frame_time: float) -> float:
    """Frames per second from a declared frame time, snapped to the nearest integer within 0.1 %
    (``Frame Time: .0083333`` is 120 fps, not 120.00048)."""
    fps = 1.0 / frame_time
    return float(round(fps)) if abs(fps - round(fps)) <= 1e-3 * fps else fps


def source_for_file(path, *, fps: float | None = None, label: str | None = None, frames=(0.0, 1.0)):
    """A :class:`~refimpl.transitions.TransitionSource` for one BVH / exp-map file, its kind found from its joints.

    ``.txt`` files are CMU exp-map files (117 values per row, 120 fps unless ``fps``). ``.bvh`` files must have
    the CMU cgspeed joints (:data:`~refimpl.transitions.CMU_22_JOINTS`) or the DAZ salsa joints
    (:data:`~refimpl.transitions.SALSA_22_JOINTS`); their rate is the declared ``Frame Time`` unless ``fps``
    (the CMU salsa files declare 120 fps but are 60 fps).
    """
    from refimpl.bvh import read_bvh_header
    from refimpl.expmap import EXPMAP_LAYOUTS
    from refimpl.transitions import CMU_22_JOINTS, SALSA_22_JOINTS, TransitionSource

    p = _existing_file(path)
    label = label or p.parent.name or p.stem
    if p.suffix.lower() == ".txt":
        return TransitionSource(str(p), "cmu_expmap", float(fps or 1.0 / EXPMAP_LAYOUTS["cmu"][1]), label, frames)
    if p.suffix.lower() != ".bvh":
        raise BadInputError(f"{p}: unknown motion file type {p.suffix!r} (expected .bvh or an exp-map .txt)")
    with _reading(p):
        header = read_bvh_header(p)
    names = set(header.skeleton.names)
    for kind, keep in (("cmu_bvh", CMU_22_JOINTS), ("salsa_bvh", SALSA_22_JOINTS)):
        if names.issuperset(keep):
            return TransitionSource(str(p), kind, float(fps or _declared_rate(header.frame_time)), label, frames)
    missing = sorted(set(CMU_22_JOINTS) - names)
    raise BadInputError(f"{p}: skeleton not supported for transitions: needs the 22 CMU joints "
                        f"({', '.join(CMU_22_JOINTS[:4])}, ...) or the salsa ones; missing e.g. {missing[:5]}")


def resolve_data(data: str, *, fps: float | None = None, test_fraction: float = 0.2):
    """Train and test sources for ``--data``.

    * ``"sample"``: the embedded sample's fixed split (:func:`refimpl.transitions.sample_sources`);
    * a folder laid out like ``../shared/data`` (``dmgnn_cmu_expmap`` ...): :func:`refimpl.transitions.shared_sources`;
    * a folder with ``train/`` and ``test/`` sub-folders: their ``*.bvh`` / ``*.txt`` files (recursively);
    * any other folder: its files sorted by path, the last ``test_fraction`` of them held out (split by file);
    * a single file: its first ``1 − test_fraction`` of frames for training, the rest for testing (split by time).

    Returns
    -------
    train, test : list of TransitionSource
    """
    from refimpl.transitions import sample_sources, shared_sources

    if data == "sample":
        return sample_sources(SAMPLE_DIR)
    root = Path(data)
    if not root.exists():
        raise BadInputError(f"{root}: no such file or folder (--data takes 'sample', a folder or a file)")
    if not 0.0 < test_fraction < 1.0:
        raise UsageError(f"--test-fraction must lie in (0, 1), got {test_fraction}")
    if root.is_file():
        split = 1.0 - test_fraction
        return ([source_for_file(root, fps=fps, frames=(0.0, split))],
                [source_for_file(root, fps=fps, frames=(split, 1.0))])
    if (root / "dmgnn_cmu_expmap").is_dir():
        return shared_sources(root)

    def files(folder: Path):
        return sorted(f for f in folder.rglob("*") if f.is_file() and f.suffix.lower() in (".bvh", ".txt")
                      and not f.name.lower().startswith("readme"))

    if (root / "train").is_dir() and (root / "test").is_dir():
        train = [source_for_file(f, fps=fps) for f in files(root / "train")]
        test = [source_for_file(f, fps=fps) for f in files(root / "test")]
    else:
        found = files(root)
        if len(found) == 1:
            return resolve_data(str(found[0]), fps=fps, test_fraction=test_fraction)
        n_test = max(1, int(round(test_fraction * len(found)))) if found else 0
        train = [source_for_file(f, fps=fps) for f in found[:len(found) - n_test]]
        test = [source_for_file(f, fps=fps) for f in found[len(found) - n_test:]]
    if not train or not test:
        raise BadInputError(f"{root}: found {len(train)} training and {len(test)} test files (.bvh / .txt); "
                            "need at least one of each")
    return train, test


def _build_datasets(data: str, T: int, stride: int, *, fps=None, test_fraction=0.2, test_stride=None):
    from refimpl.transitions import build_transition_datasets

    train_src, test_src = resolve_data(data, fps=fps, test_fraction=test_fraction)
    try:
        return build_transition_datasets(train_src, test_src, T=T, stride=stride, test_stride=test_stride)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {data}: {exc}") from exc


# ----------------------------------------------------------------------------------------------------------------
# models
# ----------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ModelSpec:
    """How the command line trains, runs and exports one network (an entry of :data:`MODELS`).

    Attributes
    ----------
    name : str
        ``--model`` value, stored in checkpoints.
    summary : str
    task : str
        ``"transition"`` (2 past + 2 target poses -> T frames; evaluated with :mod:`refimpl.metrics`).
    representations : tuple of str
        Pose representations it trains on (``--representation``); the first is the default.
    config_type : type
        Frozen dataclass of the network's sizes (``--set field=value`` overrides a field).
    make_config : callable ``(pose_size, T, overrides) -> config``
    make_adapter : callable ``(train_ds, val_ds, config, dtype, extra) -> ModelAdapter``
        ``extra`` (dict) goes into the checkpoint's model config (normalisation statistics ...).
    make_method : callable ``TrainedModel -> f(past, target, T) -> poses``
        NumPy inference on un-normalised poses (:func:`refimpl.baselines.method_registry` interface).
    export : callable ``(TrainedModel, out_dir, **options) -> dict role -> Path``, optional
    """

    name: str
    summary: str
    task: str
    representations: tuple
    config_type: type
    make_config: Callable
    make_adapter: Callable
    make_method: Callable
    export: Callable | None = None


@dataclasses.dataclass(frozen=True)
class TrainedModel:
    """A trained network read from a ``refimpl train`` checkpoint, ready for inference.

    Attributes
    ----------
    spec : ModelSpec
    config : the model's config dataclass
    params : dict name -> ndarray
    root_mean, root_std : ndarray (3,)
        Root-translation statistics of the training windows (the network's input normalisation).
    fps : float
        Frame rate of the training windows.
    transition_length : int
        T the network was trained for.
    meta : dict
        The checkpoint's metadata.
    path : str
    """

    spec: ModelSpec
    config: Any
    params: dict
    root_mean: np.ndarray
    root_std: np.ndarray
    fps: float
    transition_length: int
    meta: dict
    path: str = ""

    @property
    def pose_normalization(self) -> tuple[np.ndarray, np.ndarray]:
        """``(mean (P,), std (P,))`` over the whole pose vector: root statistics, then 0 / 1 for quaternions."""
        P = self.config.pose_size
        mean, std = np.zeros(P), np.ones(P)
        mean[:3], std[:3] = self.root_mean, self.root_std
        return mean, std


def _parse_overrides(config_type, defaults: Mapping[str, Any], overrides: Sequence[str]) -> dict:
    """``["gru_hidden=128", "encoder_sizes=128,64"]`` -> typed values, by the type of the default."""
    fields = {f.name for f in dataclasses.fields(config_type)}
    out = {}
    for item in overrides or ():
        key, sep, value = item.partition("=")
        key = key.strip().replace("-", "_")
        if not sep or key not in fields:
            raise UsageError(f"--set {item!r}: expected FIELD=VALUE with FIELD one of {sorted(fields)}")
        default = defaults[key]
        try:
            if isinstance(default, tuple):
                out[key] = tuple(int(v) for v in value.split(",") if v.strip())
            elif isinstance(default, bool):
                out[key] = value.lower() in ("1", "true", "yes")
            elif isinstance(default, int):
                out[key] = int(value)
            elif isinstance(default, float):
                out[key] = float(value)
            else:
                out[key] = value
        except ValueError:
            raise UsageError(f"--set {item!r}: {value!r} is not a valid {type(default).__name__}") from None
    return out


def _qtg_config(pose_size: int, T: int, overrides: Sequence[str] = ()):
    base = QTGConfig(pose_size=pose_size, transition_length=T)
    values = _parse_overrides(QTGConfig, dataclasses.asdict(base), overrides)
    for fixed in ("pose_size",):
        if fixed in values and values[fixed] != pose_size:
            raise UsageError(f"--set pose_size={values[fixed]}: the data has poses of {pose_size} values")
    try:
        return dataclasses.replace(base, **values)
    except ValueError as exc:
        raise UsageError(f"--set: {exc}") from None


def _qtg_adapter(train_ds, val_ds, config, dtype, extra):
    from refimpl.train import qtg_adapter
    from refimpl.transitions import normalize_poses

    vposes = None
    if val_ds is not None and val_ds.num_windows:
        vposes = normalize_poses(val_ds.poses, train_ds.root_mean, train_ds.root_std)
    adapter = qtg_adapter(train_ds.normalized(), config=config, dtype=dtype, validation_poses=vposes)
    return dataclasses.replace(adapter, config=dict(adapter.config, **extra))


def _qtg_method(model: TrainedModel):
    from refimpl.baselines import qtg_method

    return qtg_method(model.params, model.config, model.root_mean, model.root_std)


def _qtg_export(model: TrainedModel, out_dir: Path, *, mode: str = "unrolled", dtype=np.float32,
                T: int | None = None) -> dict:
    try:
        from deploy.cli import export_qtg_dir
    except ImportError as exc:
        raise _MissingDependency(f"ONNX export {_DEPLOY_HINT} ({exc})") from exc
    meta = {"frame_rate": float(model.fps),
            "training": {"checkpoint_step": model.meta.get("step"), "root_mean": [float(v) for v in model.root_mean],
                         "root_std": [float(v) for v in model.root_std]}}
    return export_qtg_dir(model.params, model.config, out_dir, normalization=model.pose_normalization,
                          dtype=dtype, mode=mode, T=T or model.transition_length, metadata=meta)


#: Networks the command line knows, by ``--model`` name.
MODELS: dict[str, ModelSpec] = {
    "qtg": ModelSpec(
        name="qtg",
        summary="Quaternion Transition Generator (Geleijn et al., IEEE VR 2021): 2 past + 2 target poses -> T frames",
        task="transition", representations=("quat",), config_type=QTGConfig,
        make_config=_qtg_config, make_adapter=_qtg_adapter, make_method=_qtg_method, export=_qtg_export),
}


def load_trained(path) -> TrainedModel:
    """Read a checkpoint written by ``refimpl train`` (or :func:`train_model`).

    Raises
    ------
    BadInputError
        Missing or damaged file, not a training checkpoint, unknown model, or no normalisation statistics.
    """
    from refimpl.checkpoint import load_checkpoint

    p = _existing_file(path)
    with _reading(p):
        arrays, meta = load_checkpoint(p)
    if meta.get("format") != "refimpl.train/1":
        raise BadInputError(f"{p}: not a refimpl training checkpoint (format {meta.get('format')!r})")
    spec = MODELS.get(meta.get("model"))
    if spec is None:
        raise BadInputError(f"{p}: unknown model {meta.get('model')!r}; known: {sorted(MODELS)}")
    cfg = dict(meta.get("model_config") or {})
    if "root_mean" not in cfg or "root_std" not in cfg:
        raise BadInputError(f"{p}: the checkpoint has no normalisation statistics (root_mean/root_std); "
                            "train it with `refimpl train`")
    names = {f.name for f in dataclasses.fields(spec.config_type)}
    try:
        config = spec.config_type(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in cfg.items()
                                     if k in names})
    except (TypeError, ValueError) as exc:
        raise BadInputError(f"{p}: bad model config in the checkpoint: {exc}") from exc
    params = {k[len("param."):]: np.asarray(v) for k, v in arrays.items() if k.startswith("param.")}
    return TrainedModel(spec=spec, config=config, params=params,
                        root_mean=np.asarray(cfg["root_mean"], dtype=np.float64),
                        root_std=np.asarray(cfg["root_std"], dtype=np.float64),
                        fps=float(cfg.get("fps", 30.0)),
                        transition_length=int(cfg.get("transition_length", config.transition_length)),
                        meta=meta, path=str(p))


# ----------------------------------------------------------------------------------------------------------------
# the work behind train / eval / export / generate
# ----------------------------------------------------------------------------------------------------------------

@contextlib.contextmanager
def blas_threads(n: int | None):
    """Limit the BLAS thread pool to ``n`` threads inside the block (threadpoolctl, when installed).

    QTG-sized matrices are small: one thread is the fastest setting, and much faster than two on a busy
    machine. ``None`` or 0 leaves the library default.
    """
    if not n:
        yield
        return
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        yield
        return
    with threadpool_limits(limits=int(n), user_api="blas"):
        yield


def train_model(spec: ModelSpec, config, train_ds, val_ds, out_dir, *, steps: int, batch_size: int = 32,
                lr: float = 1e-4, betas=(0.5, 0.9), clip_norm: float | None = None, seed: int = 0,
                dtype=np.float32, resume: bool = False, checkpoint_every: int = 500,
                validate_every: int | None = None, progress_every: int = 100,
                progress: Callable[[str], None] | None = None):
    """Train ``spec``'s network into ``out_dir`` (``checkpoint.npz``, ``loss.csv``, ``loss_val.csv``).

    The checkpoint's model config also holds the training windows' root statistics, frame rate and T, so that
    ``eval``, ``export`` and ``generate`` need nothing else.

    Returns
    -------
    TrainResult
    """
    from refimpl.train import OptimConfig, TrainConfig, train

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    extra = {"root_mean": [float(v) for v in train_ds.root_mean], "root_std": [float(v) for v in train_ds.root_std],
             "fps": float(train_ds.fps), "representation": spec.representations[0]}
    adapter = spec.make_adapter(train_ds, val_ds, config, dtype, extra)
    optim = OptimConfig(lr=lr, betas=tuple(betas), clip_norm=clip_norm)
    tc = TrainConfig(steps=steps, batch_size=batch_size, seed=seed, checkpoint_path=str(out_dir / "checkpoint.npz"),
                     checkpoint_every=checkpoint_every, log_path=str(out_dir / "loss.csv"),
                     progress_every=progress_every, validate_every=validate_every)
    kw = {} if progress is None else {"progress": progress}
    return train(adapter, optim, tc, resume=resume, **kw)


def transition_methods(model: TrainedModel | None = None, *, onnx_dir=None, fps: float = 30.0) -> dict:
    """``name -> f(past, target, T)``: the network (NumPy, and onnxruntime from ``onnx_dir``) and both baselines."""
    from refimpl.baselines import method_registry

    methods = method_registry(qtg=None if model is None else model.spec.make_method(model), dt=1.0 / fps)
    if onnx_dir is not None:
        methods = {**({"qtg": methods.pop("qtg")} if "qtg" in methods else {}),
                   "qtg_onnx": onnx_method(onnx_dir), **methods}
    return methods


def evaluate_model(model: TrainedModel | None, test_ds, *, onnx_dir=None) -> dict:
    """:func:`refimpl.metrics.evaluate_methods` of the network and both baselines on ``test_ds``."""
    from refimpl.metrics import evaluate_methods

    return evaluate_methods(test_ds, transition_methods(model, onnx_dir=onnx_dir, fps=test_ds.fps))


def _import_runtime():
    try:
        from deploy.runtime import QTGRuntime
    except ImportError as exc:
        raise _MissingDependency(f"the ONNX backend {_DEPLOY_HINT} ({exc})") from exc
    return QTGRuntime


def onnx_method(onnx_dir, intra_op_threads: int = 1) -> Callable:
    """``f(past, target, T) -> poses`` running the exported models of ``onnx_dir`` in onnxruntime.

    The models standardise inside the graph (exported by :func:`export_onnx`), so ``f`` takes and returns raw
    poses like the NumPy methods; output quaternions are normalised to unit length.
    """
    from refimpl.transitions import join_pose, split_pose

    QTGRuntime = _import_runtime()
    d = Path(onnx_dir)
    if not d.is_dir():
        raise BadInputError(f"{d}: no such folder of ONNX models")
    with _reading(d):
        runtime = QTGRuntime.from_dir(d, intra_op_threads=intra_op_threads)

    def qtg_onnx(past, target, T):
        out = np.asarray(runtime.transition(np.asarray(past, np.float32), np.asarray(target, np.float32), int(T)),
                         dtype=np.float64)  # (B, T, P)
        root, quats = split_pose(out)
        quats = quats / np.maximum(np.linalg.norm(quats, axis=-1, keepdims=True), 1e-12)
        return join_pose(root, quats)

    return qtg_onnx


def export_onnx(model: TrainedModel, out_dir, **options) -> dict:
    """Export ``model`` to validated ONNX files ``<name>_<role>.onnx`` in ``out_dir`` (QTG: ``init``, ``step``,
    ``rollout``; standardisation inside the graphs, so they take and return raw poses).

    ``options``: ``mode`` (rollout graph: ``unrolled``, ``loop``, ``scan``), ``dtype``, ``T``.

    Returns
    -------
    dict role -> Path
    """
    if model.spec.export is None:
        raise UsageError(f"model {model.spec.name!r} has no ONNX exporter")
    return model.spec.export(model, Path(out_dir), **options)


def verify_onnx(model: TrainedModel, onnx_dir, past, target, T: int | None = None) -> dict:
    """Compare onnxruntime with the NumPy model on raw context poses ``past, target (B, 2, P)``.

    Both paths produce raw (de-standardised) poses before any quaternion normalisation: NumPy
    :func:`refimpl.models.qtg.rollout_forward` in the parameters' dtype, onnxruntime the ``rollout`` model and
    the ``init`` + ``step`` loop.

    Returns
    -------
    dict ``{"rollout": max |Δ|, "step_loop": max |Δ|, "ok": bool}``; ``ok`` against
    :data:`refimpl.testing.TOL_ORT_ROLLOUT`.
    """
    from refimpl.models.qtg import rollout_forward
    from refimpl.testing import TOL_ORT_ROLLOUT
    from refimpl.transitions import denormalize_poses, normalize_poses

    QTGRuntime = _import_runtime()
    T = int(T or model.transition_length)
    dtype = next(iter(model.params.values())).dtype
    pn = normalize_poses(np.asarray(past, np.float64), model.root_mean, model.root_std).astype(dtype)
    tn = normalize_poses(np.asarray(target, np.float64), model.root_mean, model.root_std).astype(dtype)
    ref, _ = rollout_forward(model.params, pn, tn, T, model.config)
    ref = denormalize_poses(ref.astype(np.float64), model.root_mean, model.root_std)  # (B, T, P)
    with _reading(onnx_dir):
        runtime = QTGRuntime.from_dir(onnx_dir)
    out = {}
    ok = True
    for key, use_rollout in (("rollout", True), ("step_loop", False)):
        if (use_rollout and runtime.rollout_model is None) or (not use_rollout and runtime.step_model is None):
            continue
        got = np.asarray(runtime.transition(np.asarray(past, np.float32), np.asarray(target, np.float32), T,
                                            use_rollout=use_rollout), dtype=np.float64)
        diff = np.abs(got - ref)
        out[key] = float(diff.max())
        ok &= bool(np.all(diff <= TOL_ORT_ROLLOUT["atol"] + TOL_ORT_ROLLOUT["rtol"] * np.abs(ref)))
    out["ok"] = ok
    return out


@dataclasses.dataclass(frozen=True)
class Transition:
    """A generated transition in world coordinates with its context frames.

    Attributes
    ----------
    motion : Motion
        ``context`` source frames ending at the source frame, the ``T`` generated frames, then ``context``
        target frames starting at the target frame (placed by the alignment), 22 joints, centimetres.
    truth : Motion or None
        The same frames from the data, when source and target come from one clip and
        ``target_frame = source_frame + T + 1`` (a held-out window): the ground truth to compare with.
    start, stop : int
        The generated frames are ``motion`` frames ``[start, stop)``.
    method : str
    """

    motion: Any
    truth: Any
    start: int
    stop: int
    method: str

    def error_cm(self) -> float | None:
        """Mean joint-position error (cm) of the generated frames against ``truth`` (None without truth)."""
        if self.truth is None:
            return None
        a = self.motion.positions()[self.start:self.stop]
        b = self.truth.positions()[self.start:self.stop]
        return float(np.mean(np.linalg.norm(a - b, axis=-1)))


def with_end_sites(motion, fraction: float = 0.4):
    """The motion with an End Site below every leaf joint, for BVH files that other tools read.

    The 22-joint transition skeleton has no End Sites (toes, head and hands are leaves). Each leaf ``j`` gets a
    child ``<name>_end`` with offset ``fraction · offsets[j]`` (the bone continued; straight up for a leaf with a
    zero offset) and identity rotation. Joint positions of the original joints are unchanged.
    """
    from refimpl.motion import Motion
    from refimpl.skeleton import Skeleton

    skel = motion.skeleton
    leaves = [j for j in range(skel.num_joints) if not skel.children[j] and j not in set(skel.end_sites)]
    if not leaves:
        return motion
    offsets = np.asarray(skel.offsets, dtype=np.float64)
    scale = float(np.median(np.linalg.norm(offsets[1:], axis=-1))) if skel.num_joints > 1 else 1.0
    extra = [fraction * offsets[j] if np.linalg.norm(offsets[j]) > 0 else np.array([0.0, fraction * scale, 0.0])
             for j in leaves]
    J = skel.num_joints
    new = Skeleton(list(skel.parents) + leaves, np.concatenate([offsets, np.asarray(extra)]),
                   names=list(skel.names) + [f"{skel.names[j]}_end" for j in leaves],
                   end_sites=tuple(skel.end_sites) + tuple(range(J, J + len(leaves))))
    rot = np.asarray(motion.rotations)
    ident = np.zeros(rot.shape[:1] + (len(leaves), 4), dtype=rot.dtype)
    ident[..., 0] = 1.0
    return Motion(new, np.concatenate([rot, ident], axis=1), motion.root_positions, motion.frame_time, motion.name)


def _heading(q_root) -> np.ndarray:
    from refimpl.transitions import heading_from_root

    return heading_from_root(np.asarray(q_root, dtype=np.float64))


def _align_target(src_rot, src_pos, s, tgt_rot, tgt_pos, g, T):
    """Move and turn the target clip about the vertical so that it continues the source clip.

    The target's heading at frame ``g`` is made equal to the source's at ``s``, and its root is placed (in the
    horizontal plane) where the source root would be after ``T + 1`` frames at the mean of the source's
    velocity at ``s`` and the (turned) target's velocity at ``g``. Heights are kept.
    """
    from refimpl.quat import quat_conj, quat_mul, quat_rotate

    turn = quat_mul(_heading(src_rot[s, 0]), quat_conj(_heading(tgt_rot[g, 0])))  # (4,)
    rot = np.array(tgt_rot, dtype=np.float64, copy=True)
    rot[:, 0] = quat_mul(turn[None], rot[:, 0])
    rel = quat_rotate(turn[None], np.asarray(tgt_pos, np.float64) - tgt_pos[g])  # (F, 3)
    v_src = src_pos[s] - src_pos[s - 1]
    v_tgt = rel[g + 1] - rel[g]
    anchor = src_pos[s] + (T + 1) * 0.5 * (v_src + v_tgt)
    anchor[1] = tgt_pos[g][1]  # keep the target's own root height (Y up)
    return rot, rel + anchor


def make_transition(method: Callable, skeleton, source_clip, source_frame: int, target_clip, target_frame: int,
                    T: int, *, frame_time: float, context: int = 10, align: str = "auto", same_clip: bool = False,
                    method_name: str = "qtg", name: str = "transition") -> Transition:
    """Generate the ``T`` frames between two clips and return them in world coordinates.

    The four context poses (source frames ``s − 1, s``, target frames ``g, g + 1``) are expressed relative to
    the first one (:func:`refimpl.transitions.make_windows` on the 4 frames), ``method`` generates the
    transition in that frame, and the result is moved back to the world.

    Parameters
    ----------
    method : callable ``f(past (1, 2, P), target (1, 2, P), T) -> (1, T, P)`` (un-normalised poses)
    skeleton : Skeleton
        The 22-joint skeleton of both clips (centimetres).
    source_clip, target_clip : (rotations (F, J, 4), root_positions (F, 3))
    source_frame, target_frame : int
        ``s`` (the last source frame kept, ``>= 1``) and ``g`` (the first target frame, ``<= F − 2``).
    T : int
    frame_time : float
    context : int
        Source frames before and target frames after the transition included in the output (>= 1).
    align : {"auto", "none", "continue"}
        ``none`` keeps the target clip where it is; ``continue`` places it after the source
        (:func:`_align_target`); ``auto`` = ``none`` for one clip, ``continue`` for two.
    same_clip : bool
        Both clips are the same one (enables the ground truth).
    """
    from refimpl.motion import Motion
    from refimpl.quat import quat_mul, quat_rotate
    from refimpl.transitions import make_windows, split_pose

    src_rot, src_pos = (np.asarray(a, np.float64) for a in source_clip)
    tgt_rot, tgt_pos = (np.asarray(a, np.float64) for a in target_clip)
    s, g = int(source_frame), int(target_frame)
    if not 1 <= s < len(src_rot):
        raise UsageError(f"--source-frame must lie in [1, {len(src_rot) - 1}] (frames at the model's rate), got {s}")
    if not 0 <= g < len(tgt_rot) - 1:
        raise UsageError(f"--target-frame must lie in [0, {len(tgt_rot) - 2}] (frames at the model's rate), got {g}")
    if context < 1:
        raise UsageError(f"--context must be >= 1, got {context}")
    if align not in ("auto", "none", "continue"):
        raise UsageError(f"--align must be auto, none or continue, got {align!r}")
    if align == "continue" or (align == "auto" and not same_clip):
        tgt_rot, tgt_pos = _align_target(src_rot, src_pos, s, tgt_rot, tgt_pos, g, T)

    rot4 = np.stack([src_rot[s - 1], src_rot[s], tgt_rot[g], tgt_rot[g + 1]])  # (4, J, 4)
    pos4 = np.stack([src_pos[s - 1], src_pos[s], tgt_pos[g], tgt_pos[g + 1]])  # (4, 3)
    window = make_windows(rot4, pos4, length=4)  # (1, 4, P) relative to source frame s - 1
    pred = np.asarray(method(window[:, :2], window[:, 2:], T), dtype=np.float64)[0]  # (T, P)
    root_rel, quats = split_pose(pred)  # (T, 3), (T, J, 4)
    h = _heading(src_rot[s - 1, 0])  # (4,)
    gen_pos = quat_rotate(h[None], root_rel) + src_pos[s - 1]  # (T, 3)
    gen_rot = np.array(quats, copy=True)
    gen_rot[:, 0] = quat_mul(h[None], gen_rot[:, 0])
    gen_rot /= np.linalg.norm(gen_rot, axis=-1, keepdims=True)

    a = max(0, s - context + 1)
    b = min(len(tgt_rot), g + context)
    rot = np.concatenate([src_rot[a:s + 1], gen_rot, tgt_rot[g:b]])  # (F, J, 4)
    pos = np.concatenate([src_pos[a:s + 1], gen_pos, tgt_pos[g:b]])  # (F, 3)
    start = s + 1 - a
    motion = Motion(skeleton, rot, pos, frame_time, name)
    truth = None
    if same_clip and g == s + T + 1 and align in ("auto", "none"):
        truth = Motion(skeleton, src_rot[a:b], src_pos[a:b], frame_time, f"{name}_truth")
    return Transition(motion=motion, truth=truth, start=start, stop=start + T, method=method_name)


# ----------------------------------------------------------------------------------------------------------------
# output helpers
# ----------------------------------------------------------------------------------------------------------------

def _say(*parts) -> None:
    print(*parts, flush=True)


def _progress_line(line: str) -> None:
    print(line, file=sys.stderr, flush=True)


def _curve_csv(results: Mapping[str, dict], frame_time: float) -> str:
    names = list(results)
    T = len(results[names[0]]["per_frame_cm"])
    lines = ["frame,time_ms," + ",".join(f"{n}_cm" for n in names)]
    for t in range(T):
        lines.append(f"{t + 1},{(t + 1) * frame_time * 1000:.1f},"
                     + ",".join(f"{results[n]['per_frame_cm'][t]:.4f}" for n in names))
    return "\n".join(lines) + "\n"


def _results_json(results: Mapping[str, dict]) -> str:
    def conv(v):
        if isinstance(v, np.ndarray):
            return [float(x) for x in v]
        if isinstance(v, dict):
            return {k: conv(x) for k, x in v.items()}
        if isinstance(v, (np.floating, np.integer)):
            return v.item()
        return v

    return json.dumps({k: conv(v) for k, v in results.items()}, indent=2, sort_keys=True) + "\n"


def _curve_table(results: Mapping[str, dict], frame_time: float) -> str:
    names = list(results)
    T = len(results[names[0]]["per_frame_cm"])
    head = ["frame", "ms"] + names
    rows = [head] + [[str(t + 1), f"{(t + 1) * frame_time * 1000:.0f}"]
                     + [f"{results[n]['per_frame_cm'][t]:.2f}" for n in names] for t in range(T)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in rows)


def _protocol_line(ds, model: TrainedModel | None) -> str:
    labels = sorted({ds.sources[i].label for i in np.unique(ds.source_index)})
    return (f"protocol: {ds.num_windows} held-out windows ({', '.join(labels)}) from {len(ds.sources)} sources, "
            f"{ds.past} past + T = {ds.transition_length} + {ds.future} target poses at {ds.fps:g} fps, "
            "22 joints; error = mean over windows and joints of the Euclidean joint-position error (cm) per "
            "transition frame" + ("" if model is None else f"; network {model.spec.name} from {model.path}"))


# ----------------------------------------------------------------------------------------------------------------
# commands
# ----------------------------------------------------------------------------------------------------------------

def _info_bvh(p: Path, args) -> None:
    from collections import Counter

    from refimpl.bvh import read_bvh, read_bvh_header

    with _reading(p):
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


def _info_npz(p: Path, args) -> None:
    from refimpl.checkpoint import load_checkpoint, load_state_dict_npz

    with _reading(p):
        try:
            arrays, meta = load_checkpoint(p)
        except ValueError as exc:
            if "not a refimpl checkpoint" not in str(exc):
                raise
            arrays, meta = load_state_dict_npz(p), None
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
    if "model" in meta:
        cfg = dict(meta.get("model_config") or {})
        stats = {k: cfg.pop(k) for k in ("root_mean", "root_std") if k in cfg}
        _say(f"model       {meta['model']}")
        _say(f"progress    step {meta.get('step')} of {meta.get('steps_target')}, epoch {meta.get('epoch')}, "
             f"trained for {meta.get('elapsed_s', 0.0):.1f} s")
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
        raise _MissingDependency(f"reading .onnx files {_DEPLOY_HINT}") from exc
    from collections import Counter

    with _reading(p):
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
        try:
            value = json.loads(prop.value)
        except ValueError:
            value = prop.value
        if prop.key == "skeleton" and isinstance(value, dict):
            value = f"{len(value.get('names', []))} joints: " + ", ".join(value.get("names", [])[:6]) + " ..."
        elif prop.key == "normalization" and isinstance(value, dict):
            value = f"in graph: {value.get('in_graph')}, root mean {np.round(value.get('mean', [])[:3], 3).tolist()}"
        elif prop.key == "io":
            continue
        text = value if isinstance(value, str) else json.dumps(value, sort_keys=True)
        _say(f"meta        {prop.key}: {text[:300]}")


def cmd_info(args) -> int:
    """``refimpl info FILE``."""
    p = _existing_file(args.file)
    kind = p.suffix.lower()
    handlers = {".bvh": _info_bvh, ".txt": _info_expmap, ".npz": _info_npz, ".onnx": _info_onnx}
    if kind not in handlers:
        raise BadInputError(f"{p}: unknown file type {p.suffix!r} (expected .bvh, .txt, .npz or .onnx)")
    handlers[kind](p, args)
    return EXIT_OK


def cmd_train(args) -> int:
    """``refimpl train``."""
    spec = MODELS[args.model]
    rep = args.representation or spec.representations[0]
    if rep not in spec.representations:
        raise UsageError(f"--representation {rep!r}: model {spec.name!r} trains on {list(spec.representations)}")
    out = Path(args.out)
    ckpt = out / "checkpoint.npz"
    if args.resume and not ckpt.is_file():
        raise BadInputError(f"{ckpt}: no checkpoint to resume (train without --resume first)")
    if ckpt.is_file() and not (args.resume or args.overwrite):
        raise UsageError(f"{ckpt} exists: pass --resume to continue it or --overwrite to start again")
    if args.overwrite:
        for f in ("checkpoint.npz", "loss.csv", "loss_val.csv"):
            if (out / f).is_file():
                (out / f).unlink()
    t0 = time.perf_counter()
    _say(f"reading {args.data} ...")
    train_ds, test_ds = _build_datasets(args.data, args.transition_length, args.stride, fps=args.fps,
                                        test_fraction=args.test_fraction)
    P = train_ds.poses.shape[-1]
    config = spec.make_config(P, args.transition_length, args.set)
    per_epoch = max(1, train_ds.num_windows // min(args.batch_size, train_ds.num_windows))
    steps = args.steps if args.steps is not None else args.epochs * per_epoch
    _say(f"data: {train_ds.num_windows} training / {test_ds.num_windows} held-out windows "
         f"(T = {args.transition_length} at {train_ds.fps:g} fps) in {time.perf_counter() - t0:.1f} s; "
         f"{per_epoch} steps per epoch")
    described = config.to_dict() if hasattr(config, "to_dict") else dataclasses.asdict(config)
    _say(f"model: {spec.name} {json.dumps(described)}")
    _say(f"training {steps} steps (batch {args.batch_size}, Adam lr {args.lr:g}, betas {tuple(args.betas)}) "
         f"-> {out}/")
    result = train_model(spec, config, train_ds, test_ds, out, steps=steps, batch_size=args.batch_size,
                         lr=args.lr, betas=args.betas, clip_norm=args.clip_norm, seed=args.seed,
                         dtype=np.dtype(args.dtype).type, resume=args.resume,
                         checkpoint_every=args.checkpoint_every, validate_every=args.validate_every,
                         progress_every=args.progress_every, progress=_progress_line)
    last = float(np.mean(result.losses[-20:])) if result.losses else float("nan")
    _say(f"{'interrupted' if result.interrupted else 'done'}: step {result.step}, epoch {result.epoch}, "
         f"recent loss {last:.5g}, {result.elapsed_s:.1f} s")
    _say(f"checkpoint  {result.checkpoint_path}")
    _say(f"loss log    {out / 'loss.csv'}" + (f", {out / 'loss_val.csv'}" if args.validate_every else ""))
    return 130 if result.interrupted else EXIT_OK


def cmd_eval(args) -> int:
    """``refimpl eval``."""
    model = load_trained(args.checkpoint) if args.checkpoint else None
    T = args.transition_length or (model.transition_length if model else 30)
    _say(f"reading {args.data} ...")
    _, test_ds = _build_datasets(args.data, T, args.stride, fps=args.fps, test_fraction=args.test_fraction)
    if test_ds.num_windows == 0:
        raise BadInputError(f"--data {args.data}: no held-out window of {T + 4} frames")
    results = evaluate_model(model, test_ds, onnx_dir=args.onnx)
    print_results(results, test_ds, model)
    frame_time = 1.0 / test_ds.fps
    write_results(results, frame_time, json_path=args.json, csv_path=args.csv)
    if args.csv:
        _say(f"per-frame curve  {args.csv}")
    if args.json:
        _say(f"results          {args.json}")
    if args.plot:
        from refimpl.render import render_error_curves

        render_error_curves(args.plot, {k: v["per_frame_cm"] for k, v in results.items()}, frame_time=frame_time)
        _say(f"plot             {args.plot}")
    return EXIT_OK


def print_results(results: Mapping[str, dict], test_ds, model: TrainedModel | None = None, *,
                  curve: bool = True) -> None:
    """Print :func:`evaluate_model` results as the paper's comparison: protocol line, table, per-frame curve."""
    from refimpl.metrics import format_table

    _say(_protocol_line(test_ds, model))
    _say("")
    _say("Mean joint-position error per joint per frame (cm), by motion category and at transition frames fK:")
    _say(format_table(results))
    if curve:
        _say("")
        _say("Per-frame curve (cm):")
        _say(_curve_table(results, 1.0 / test_ds.fps))


def write_results(results: Mapping[str, dict], frame_time: float, *, json_path=None, csv_path=None) -> None:
    """Write :func:`evaluate_model` results as JSON (everything) and / or CSV (the per-frame curves)."""
    if json_path:
        atomic_write_text(Path(json_path), _results_json(results), make_parents=True)
    if csv_path:
        atomic_write_text(Path(csv_path), _curve_csv(results, frame_time), make_parents=True)


def cmd_export(args) -> int:
    """``refimpl export``."""
    model = load_trained(args.checkpoint)
    out = Path(args.out) if args.out else Path(model.path).parent / "onnx"
    written = export_onnx(model, out, mode=args.mode, dtype=np.dtype(args.dtype).type, T=args.transition_length)
    for role, path in written.items():
        _say(f"{role:8s} {path} ({Path(path).stat().st_size / 1024:.0f} KiB)")
    if args.verify:
        rng = np.random.default_rng(args.seed)
        past, target = _random_context(model, rng, 8)
        check = verify_onnx(model, out, past, target, T=args.transition_length)
        for k, v in check.items():
            if k != "ok":
                _say(f"verify   onnxruntime vs NumPy ({k}): max |diff| = {v:.3g}")
        if not check["ok"]:
            raise RuntimeError("onnxruntime and NumPy disagree beyond the rollout tolerance "
                               "(refimpl.testing.TOL_ORT_ROLLOUT)")
    return EXIT_OK


def _random_context(model: TrainedModel, rng, B: int):
    """Plausible raw context poses for a numerical check: root ~ N(mean, std), small random joint rotations."""
    from refimpl.quat import quat_from_axis_angle
    from refimpl.transitions import join_pose

    J = (model.config.pose_size - 3) // 4
    root = model.root_mean + model.root_std * rng.standard_normal((B, 4, 3))  # (B, 4, 3)
    quats = quat_from_axis_angle(0.3 * rng.standard_normal((B, 4, J, 3)))  # (B, 4, J, 4)
    poses = join_pose(root, quats)
    return poses[:, :2], poses[:, 2:]


def _clip_for(path, model_fps: float, fps_override):
    """(skeleton, (rotations, root_positions)) of a file at the model's rate (phase 0 of the resampling)."""
    from refimpl.transitions import load_source

    src = source_for_file(path, fps=fps_override)
    try:
        skel, clips = load_source(src, fps=model_fps)
    except (OSError, ValueError) as exc:
        raise _file_error(path, exc) from exc
    return skel, clips[0], src


def cmd_generate(args) -> int:
    """``refimpl generate``."""
    from refimpl.bvh import write_bvh

    model = None
    if args.method == "qtg":
        if args.backend == "numpy" and not args.checkpoint:
            raise UsageError("--method qtg with --backend numpy needs --checkpoint")
        if args.backend == "onnx" and not args.onnx:
            raise UsageError("--backend onnx needs --onnx DIR (the folder written by `refimpl export`)")
        if args.checkpoint:
            model = load_trained(args.checkpoint)
    elif args.backend == "onnx":
        raise UsageError(f"--backend onnx runs the network; --method {args.method} is a NumPy baseline")
    fps, T_model = (model.fps, model.transition_length) if model else (30.0, 30)
    if args.backend == "onnx" and model is None:
        meta = _onnx_meta(args.onnx)
        fps = float(meta.get("frame_rate", 30.0))
        T_model = int((meta.get("model") or {}).get("transition_length") or T_model)
    T = args.length or T_model
    target_path = args.target or args.source
    skel, src_clip, src = _clip_for(args.source, fps, args.fps)
    skel2, tgt_clip, tgt = _clip_for(target_path, fps, args.fps)
    if skel != skel2:
        raise BadInputError(f"{target_path}: its 22-joint skeleton differs from {args.source}'s "
                            "(both clips must come from the same skeleton)")
    if args.method == "qtg":
        method = onnx_method(args.onnx) if args.backend == "onnx" else model.spec.make_method(model)
    else:
        method = transition_methods(None, fps=fps)[args.method]
    same = Path(args.source).resolve() == Path(target_path).resolve()
    target_frame = args.target_frame if args.target_frame is not None else (
        args.source_frame + T + 1 if same else 1)
    tr = make_transition(method, skel, src_clip, args.source_frame, tgt_clip, target_frame, T,
                         frame_time=1.0 / fps, context=args.context, align=args.align, same_clip=same,
                         method_name=args.method, name=Path(args.out).stem)
    write_bvh(args.out, with_end_sites(tr.motion))
    _say(f"wrote {args.out}: {tr.motion.num_frames} frames at {fps:g} fps, 22 joints (centimetres); "
         f"generated frames {tr.start}..{tr.stop - 1} ({args.method}, {args.backend})")
    err = tr.error_cm()
    if err is not None:
        _say(f"ground truth available (same clip, target = source + T + 1): mean joint error {err:.2f} cm")
        if args.truth:
            write_bvh(args.truth, with_end_sites(tr.truth))
            _say(f"wrote {args.truth} (ground truth)")
    elif args.truth:
        raise UsageError("--truth needs --target-frame = --source-frame + T + 1 in the same file (and --align none)")
    if args.png or args.gif:
        render_transition(tr, png=args.png, gif=args.gif)
    return EXIT_OK


def _onnx_meta(onnx_dir) -> dict:
    d = Path(onnx_dir)
    files = sorted(d.glob("*_rollout.onnx")) + sorted(d.glob("*_step.onnx"))
    if not files:
        raise BadInputError(f"{d}: no exported *_rollout.onnx / *_step.onnx models")
    try:
        from deploy.metadata import read_metadata
    except ImportError as exc:
        raise _MissingDependency(f"the ONNX backend {_DEPLOY_HINT}") from exc
    with _reading(files[0]):
        return read_metadata(str(files[0]))


def render_transition(tr: Transition, png=None, gif=None, title=None) -> list:
    """Draw a :class:`Transition` (against its ground truth when it has one) as a PNG strip and / or a GIF."""
    from refimpl.render import render_gif, render_strip

    parents = np.asarray(tr.motion.skeleton.parents)
    gt = (tr.truth if tr.truth is not None else tr.motion).positions()
    pred = tr.motion.positions() if tr.truth is not None else None
    labels = ("ground truth", tr.method) if pred is not None else (tr.method, "")
    written = []
    if png:
        n = tr.motion.num_frames
        frames = sorted(set([0, tr.start - 1] + list(range(tr.start, tr.stop, max(1, (tr.stop - tr.start) // 6)))
                            + [tr.stop - 1, n - 1]))
        written.append(render_strip(png, gt, parents, prediction=pred, frames=frames, highlight=(tr.start, tr.stop),
                                    labels=labels, title=title, frame_time=tr.motion.frame_time))
        _say(f"wrote {png}")
    if gif:
        written.append(render_gif(gif, gt, parents, prediction=pred, fps=tr.motion.fps,
                                  highlight=(tr.start, tr.stop), labels=labels, title=title))
        _say(f"wrote {gif}")
    return written


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
    from refimpl.render import render_gif, render_strip

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
    labels = (Path(args.file).stem, Path(args.compare).stem if args.compare else "")
    step = sel.step or 1
    for out in outs:
        suffix = Path(out).suffix.lower()
        if suffix == ".png":
            render_strip(out, pos, parents, prediction=pred, num_frames=args.num_frames, labels=labels,
                         up=args.up, frame_time=motion.frame_time, frame_numbers=idx, title=args.title)
        elif suffix == ".gif":
            render_gif(out, pos, parents, prediction=pred, fps=motion.fps / step, stride=args.stride, labels=labels,
                       up=args.up, frame_numbers=idx, title=args.title)
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


# ----------------------------------------------------------------------------------------------------------------
# parser and main
# ----------------------------------------------------------------------------------------------------------------

def _number_parser(convert, accept, expected: str):
    """An argparse ``type`` that converts with ``convert`` and accepts the value when ``accept(value)``."""
    def parse(text: str):
        try:
            v = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None
        if not accept(v):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return v
    return parse


_positive_int = _number_parser(int, lambda v: v >= 1, "a positive integer")
_nonneg_int = _number_parser(int, lambda v: v >= 0, "an integer >= 0")
_positive_float = _number_parser(float, lambda v: math.isfinite(v) and v > 0, "a positive number")


def _add_data_options(p, default="sample") -> None:
    p.add_argument("--data", default=default,
                   help="'sample' (the embedded CMU sample, default), a folder like ../shared/data, a folder of "
                        ".bvh / exp-map .txt files (train/ and test/ sub-folders, or split by file), or one file "
                        "(split by time)")
    p.add_argument("--fps", type=_positive_float, default=None,
                   help="true frame rate of the files when the header is wrong (CMU salsa: 60)")
    p.add_argument("--test-fraction", type=float, default=0.2, help="held-out share when splitting (default 0.2)")
    p.add_argument("--stride", type=_positive_int, default=4, help="frames between window starts (default 4)")


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
    parser.add_argument("--blas-threads", type=_nonneg_int, default=1,
                        help="BLAS threads for NumPy (default 1, fastest for these small networks; 0 = library "
                             "default; needs threadpoolctl)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    p = sub.add_parser("info", help="what a .bvh, exp-map .txt, checkpoint .npz or .onnx file holds",
                       description="Print joints, frames, frame rate and channel layout of a motion file; "
                                   "parameters, shapes and metadata of a checkpoint or ONNX model.")
    p.add_argument("file")
    p.add_argument("--joints", action="store_true", help="list the joint hierarchy with offsets")
    p.add_argument("--layout", default="cmu", choices=("cmu", "h36m"), help="exp-map layout (default cmu)")
    p.add_argument("--fps", type=_positive_float, default=None, help="override the frame rate")
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("train", help="train a network (today: qtg) on motion files",
                       description="Train a network with Adam; checkpoint.npz (resumable), loss.csv and "
                                   "loss_val.csv go to --out. Progress lines (rate, ETA) go to stderr.")
    p.add_argument("--model", default="qtg", choices=sorted(MODELS), help="network (default qtg)")
    p.add_argument("--representation", default=None, help="pose representation (qtg: quat)")
    _add_data_options(p)
    p.add_argument("--out", default="runs/qtg", help="output folder (default runs/qtg)")
    length = p.add_mutually_exclusive_group()
    length.add_argument("--steps", type=_nonneg_int, default=None, help="optimiser steps")
    length.add_argument("--epochs", type=_nonneg_int, default=10, help="epochs, when --steps is not given (default 10)")
    p.add_argument("--batch-size", type=_positive_int, default=32)
    p.add_argument("--lr", type=_positive_float, default=1e-4, help="Adam learning rate (paper: 1e-4)")
    p.add_argument("--betas", type=float, nargs=2, default=(0.5, 0.9), metavar=("B1", "B2"),
                   help="Adam betas (paper: 0.5 0.9)")
    p.add_argument("--clip-norm", type=_positive_float, default=None, help="global gradient-norm clipping")
    p.add_argument("--transition-length", type=_positive_int, default=30, help="T (default 30 = 1 s)")
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="override a config field, e.g. --set gru_hidden=128 --set encoder_sizes=128,64")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--seed", type=int, default=0)
    resume = p.add_mutually_exclusive_group()
    resume.add_argument("--resume", action="store_true", help="continue from --out/checkpoint.npz")
    resume.add_argument("--overwrite", action="store_true", help="start again, replacing --out's checkpoint and logs")
    p.add_argument("--checkpoint-every", type=_positive_int, default=500)
    p.add_argument("--validate-every", type=_positive_int, default=None,
                   help="log the held-out MAE every N steps (loss_val.csv)")
    p.add_argument("--progress-every", type=_positive_int, default=50)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("eval", help="QTG vs inertialisation vs interpolation on held-out windows",
                       description="The QTG paper's protocol: mean joint-position error per joint per frame (cm) "
                                   "on held-out transition windows, with the per-frame curve.")
    p.add_argument("--checkpoint", default=None, help="a `refimpl train` checkpoint (omit: baselines only)")
    p.add_argument("--onnx", default=None, help="also evaluate the exported models of this folder (onnxruntime)")
    _add_data_options(p)
    p.add_argument("--transition-length", type=_positive_int, default=None, help="T (default: the model's)")
    p.add_argument("--csv", default=None, help="write the per-frame curve as CSV")
    p.add_argument("--json", default=None, help="write all results as JSON")
    p.add_argument("--plot", default=None, help="write the per-frame curves as PNG (matplotlib)")
    p.set_defaults(func=cmd_eval)

    p = sub.add_parser("export", help="export a checkpoint to ONNX (needs the deploy extra)",
                       description="Write <model>_init.onnx, <model>_step.onnx, <model>_rollout.onnx (validated); "
                                   "the graphs standardise inside (raw poses in and out) and carry their metadata.")
    p.add_argument("--checkpoint", required=True)
    p.add_argument("--out", default=None, help="output folder (default: onnx/ beside the checkpoint)")
    p.add_argument("--mode", default="unrolled", choices=("unrolled", "loop", "scan"), help="rollout graph form")
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    p.add_argument("--transition-length", type=_positive_int, default=None, help="T of the rollout model")
    p.add_argument("--no-verify", dest="verify", action="store_false",
                   help="skip the onnxruntime-vs-NumPy check on random context poses")
    p.add_argument("--seed", type=int, default=0, help="seed of the check's random poses")
    p.set_defaults(func=cmd_export)

    p = sub.add_parser("generate", help="generate a transition between two clips, BVH out",
                       description="Take frames s-1, s of --source and g, g+1 of --target (frame numbers at the "
                                   "model's rate, 30 fps, after the files' first reference frame), generate the T "
                                   "frames between them and write a BVH with --context frames on both sides.")
    p.add_argument("--source", required=True, help=".bvh or exp-map .txt")
    p.add_argument("--source-frame", type=_positive_int, required=True, help="s, last frame of the source kept")
    p.add_argument("--target", default=None, help=".bvh or exp-map .txt (default: --source)")
    p.add_argument("--target-frame", type=_nonneg_int, default=None,
                   help="g, first target frame (default: s + T + 1 in the same file, else 1)")
    p.add_argument("--method", default="qtg", choices=("qtg", "inertialization", "interpolation"))
    p.add_argument("--checkpoint", default=None, help="a `refimpl train` checkpoint (NumPy backend)")
    p.add_argument("--backend", default="numpy", choices=("numpy", "onnx"))
    p.add_argument("--onnx", default=None, help="folder of exported models (ONNX backend)")
    p.add_argument("--length", type=_positive_int, default=None, help="T (default: the model's)")
    p.add_argument("--context", type=_positive_int, default=10, help="frames kept on each side (default 10)")
    p.add_argument("--align", default="auto", choices=("auto", "none", "continue"),
                   help="place the target clip: none = as in its file, continue = after the source (default: "
                        "none for one file, continue for two)")
    p.add_argument("--fps", type=_positive_float, default=None, help="true frame rate of the input files")
    p.add_argument("--out", default="transition.bvh")
    p.add_argument("--truth", default=None, help="also write the ground truth (same file, g = s + T + 1)")
    p.add_argument("--png", default=None, help="also render a PNG strip (matplotlib)")
    p.add_argument("--gif", default=None, help="also render a GIF (matplotlib)")
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("render", help="draw a motion as a PNG strip or GIF (matplotlib)",
                       description="Draw a .bvh / exp-map motion, optionally beside a second one (--compare) on "
                                   "the same skeleton, as a PNG strip of frames or an animated GIF.")
    p.add_argument("file")
    p.add_argument("--compare", default=None, help="a second motion drawn in red over the first")
    p.add_argument("--out", action="append", default=None,
                   help=".png and/or .gif output (repeatable; default <file stem>.png)")
    p.add_argument("--frames", default=None, help="START:STOP[:STEP] frame range (default all)")
    p.add_argument("--num-frames", type=_positive_int, default=8, help="panels in a PNG strip (default 8)")
    p.add_argument("--stride", type=_positive_int, default=1, help="draw every k-th frame in a GIF")
    p.add_argument("--up", default="y", choices=("y", "z"), help="the data's up axis (BVH: y)")
    p.add_argument("--title", default=None)
    p.add_argument("--layout", default="cmu", choices=("cmu", "h36m"), help="exp-map layout")
    p.add_argument("--fps", type=_positive_float, default=None, help="override the frame rate")
    p.set_defaults(func=cmd_render)

    p = sub.add_parser("demo", help="train, evaluate, export, verify, generate and render on the sample",
                       description="The whole tour on the embedded CMU sample in a few minutes on 2 cores.")
    p.add_argument("--out", default="demo_out", help="output folder (default ./demo_out)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quick", action="store_true", help="a tiny network and a few steps (a smoke test, ~30 s)")
    p.add_argument("--steps", type=_positive_int, default=None, help="override the number of training steps")
    p.add_argument("--no-onnx", action="store_true", help="skip export and verification")
    p.add_argument("--no-render", action="store_true", help="skip the pictures")
    p.set_defaults(func=cmd_demo)
    return parser


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
    try:
        with blas_threads(args.blas_threads):
            return int(args.func(args) or EXIT_OK)
    except BadInputError as exc:
        if args.traceback:
            raise
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except UsageError as exc:
        if args.traceback:
            raise
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except (_MissingDependency, ImportError) as exc:  # an optional dependency (matplotlib, onnx) is missing
        if args.traceback:
            raise
        print(f"{prog}: error: {exc}", file=sys.stderr)
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
        print(f"{prog}: error: {kind}{exc} (run with --traceback for details)", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
