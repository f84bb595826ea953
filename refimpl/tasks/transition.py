"""The transition task (QTG's; spec/qtg.md §7-§9, spec/cli.md): 2 past + 2 target poses -> the T frames between.

The task interface (:class:`refimpl.task_api.Task`) for this task, and nothing about a particular network:

* options: :func:`add_train_options` (``--transition-length``), :func:`add_eval_options`,
  :func:`add_export_options`, :func:`add_generate_options`; ``--data``: :func:`resolve_data` (the embedded
  sample, ``../shared/data``, a folder, a file), :func:`source_for_file`, :func:`build_datasets`,
  :func:`train_datasets`; the checkpoint facts (:func:`checkpoint_extra`, :func:`check_checkpoint`,
  :func:`trained_fields`: ``root_mean``, ``root_std``, ``transition_length``);
* baselines and protocol: :func:`methods` (the networks' methods, then inertialisation and interpolation from
  :mod:`refimpl.protocols.transition_baselines`); :func:`evaluate`, :func:`print_results`, :func:`write_results`
  from :mod:`refimpl.tasks.transition_report` (each method's predictions once, the paper's metric and the
  animator's measures; table, per-frame curve, CSV, JSON);
* commands: :func:`eval_command`, :func:`generate_command` (a transition between two clips,
  :mod:`refimpl.tasks.transition_generate`), :func:`export_options`, :func:`verify_inputs`
  (:func:`random_context`: context poses for numerical checks), :func:`clip_for`.

The building blocks live below: windows, sources and datasets in :mod:`refimpl.protocols.transition`, the
baselines in :mod:`refimpl.protocols.transition_baselines`, the metric in
:mod:`refimpl.protocols.transition_metrics`.

Shape legend: N windows, T transition frames, F frames of a clip, J joints, P pose size (3 + 4 J), B batch.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from refimpl.progress import stderr_line
from refimpl.bvh import read_bvh_header
from refimpl.errors import BadInputError, UsageError, existing_file, file_error, reading
from refimpl.expmap import EXPMAP_LAYOUTS
from refimpl.bounds import bounded_float, bounded_int
from refimpl.options import export_length, nonneg_int
from refimpl.protocols.transition import CHECKPOINT_SCHEMA  # the task's checkpoint schema (task interface)
from refimpl.protocols.transition import (CMU_22_JOINTS, SALSA_22_JOINTS, SAMPLE_DIR, TransitionSource,
                                          build_transition_datasets, declared_rate, join_pose, load_source,
                                          sample_sources, shared_sources, split_pose)
from refimpl.protocols.transition_baselines import METHOD_NAMES, method_registry
from refimpl.protocols.transition_cache import cached_loader
from refimpl.protocols.transition_join import EXPORT_JOIN_MODES, JOIN_MODES, check_join, with_join
from refimpl.protocols.transition_locomotion import JOINTS as BANDAI_NAMCO_JOINTS, KIND as BANDAI_NAMCO_KIND
from refimpl.protocols.transition_locomotion import build_datasets as build_bandai_namco, is_bandai_namco_folder
from refimpl.protocols.transition_locomotion import find_takes, scored_takes, take_facts
from refimpl.protocols.transition_locomotion import load_bandai_namco_source
from refimpl.rotations import quat_from_axis_angle
from refimpl.registry import generate_usage, require_source
from refimpl.services import checkpoint_for, evaluate_model, network_methods, onnx_frame_rate
from refimpl.tasks.transition_generate import make_transition, render_transition, with_end_sites
from refimpl.tasks.transition_report import evaluate, print_results, write_results  # the task interface's

__all__ = [
    "CHECKPOINT_SCHEMA", "NAME", "EVAL_SUMMARY", "GENERATE_USAGE", "add_train_options", "add_eval_options",
    "add_export_options", "add_generate_options", "source_for_file", "resolve_data", "build_datasets",
    "train_datasets", "import_datasets", "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint",
    "trained_fields", "JoinedOnnxMethod", "onnx_method", "methods", "evaluate", "print_results", "write_results",
    "clip_for", "random_context", "eval_command", "generate_command", "export_options", "verify_inputs",
]

NAME = "transition"
EVAL_SUMMARY = ("transition (qtg): the QTG paper's protocol, mean joint-position error per joint per frame (cm) on "
                "held-out transition windows with the per-frame curve, against inertialisation and interpolation")
GENERATE_USAGE = "refimpl generate --source FILE --source-frame S [...]  (a transition)"


def _say(*parts) -> None:
    print(*parts, flush=True)



# ----------------------------------------------------------------------------------------------------------------
# data
# ----------------------------------------------------------------------------------------------------------------

def add_train_options(parser) -> None:
    """The task's options of ``refimpl train`` (its data options are the command line's common ones)."""
    parser.add_argument("--transition-length", type=bounded_int("transition_length"), default=30,
                        help="T (default 30 = 1 s)")


def add_eval_options(parser) -> None:
    """The task's options of ``refimpl eval``: ``--transition-length``, ``--csv``, ``--join``."""
    parser.add_argument("--transition-length", type=bounded_int("transition_length"), default=None,
                        help="T (default: the model's)")
    parser.add_argument("--csv", default=None, help="write the per-frame curve as CSV")
    parser.add_argument("--join", default="none", choices=JOIN_MODES,
                        help="inertialize: also evaluate each network with its joins inertialised (spec/qtg.md "
                             "7.4), as <name>+join beside the paper-faithful row; inertialize+footlock: also "
                             "<name>+join+footlock, planted feet pinned by two-bone IK (7.5) (default none)")
    parser.add_argument("--takes", nargs="+", default=None, metavar="FILE",
                        help="score exactly these .bvh / exp-map files (no training split: the normalisation is "
                             "the checkpoint's; instead of --data). A folder of Bandai Namco takes given as "
                             "--data is scored on its held-out takes (ids ending in 1) when it holds both sides "
                             "of the project's split, else whole; a train/ + test/ folder on test/")


def add_export_options(parser) -> None:
    """The task's options of ``refimpl export``: ``--join``."""
    parser.add_argument("--join", default="none", choices=EXPORT_JOIN_MODES,
                        help="transition models: inertialize = bake the join option into the rollout graph "
                             "(spec/qtg.md 7.4; the C example gets it too); default none")


def add_generate_options(parser) -> None:
    """The task's options of ``refimpl generate``: the target clip, the method, the context and the alignment."""
    parser.add_argument("--target", default=None, help=".bvh or exp-map .txt (default: --source)")
    parser.add_argument("--target-frame", type=nonneg_int, default=None,
                        help="g, first target frame (default: s + T + 1 in the same file, else 1)")
    parser.add_argument("--method", default=METHOD_NAMES[0], choices=METHOD_NAMES)
    parser.add_argument("--context", type=bounded_int("context"), default=10,
                        help="frames kept on each side (default 10)")
    parser.add_argument("--join", default="none", choices=JOIN_MODES,
                        help="inertialize: carry the jump at each end of the transition away (spec/qtg.md 7.4); "
                             "inertialize+footlock: then pin the planted feet by two-bone IK (7.5)")
    parser.add_argument("--align", default="auto", choices=("auto", "none", "continue"),
                        help="place the target clip: none = as in its file, continue = after the source (default: "
                             "none for one file, continue for two)")
    parser.add_argument("--fps", type=bounded_float("fps"), default=None, help="true frame rate of the input files")


def source_for_file(path, *, fps: float | None = None, label: str | None = None, frames=(0.0, 1.0)):
    """A :class:`~refimpl.protocols.transition.TransitionSource` for one BVH / exp-map file, its kind found from its joints.

    ``.txt`` files are CMU exp-map files (117 values per row, 120 fps unless ``fps``). ``.bvh`` files must have
    the CMU cgspeed joints (:data:`~refimpl.protocols.transition.CMU_22_JOINTS`), the DAZ salsa joints
    (:data:`~refimpl.protocols.transition.SALSA_22_JOINTS`) or the Bandai Namco locomotion rig's 21
    (:data:`~refimpl.protocols.transition_locomotion.JOINTS`, spec/qtg.md §8.4); their rate is the declared
    ``Frame Time`` unless ``fps`` (the CMU salsa files declare 120 fps but are 60 fps).
    """
    p = existing_file(path)
    label = label or p.parent.name or p.stem
    if p.suffix.lower() == ".txt":
        return TransitionSource(str(p), "cmu_expmap", float(fps or 1.0 / EXPMAP_LAYOUTS["cmu"][1]), label, frames)
    if p.suffix.lower() != ".bvh":
        raise BadInputError(f"{p}: unknown motion file type {p.suffix!r} (expected .bvh or an exp-map .txt)")
    with reading(p):
        header = read_bvh_header(p)
    names = set(header.skeleton.names)
    for kind, keep in (("cmu_bvh", CMU_22_JOINTS), ("salsa_bvh", SALSA_22_JOINTS),
                       (BANDAI_NAMCO_KIND, BANDAI_NAMCO_JOINTS)):
        if names.issuperset(keep):
            return TransitionSource(str(p), kind, float(fps or declared_rate(header.frame_time)), label, frames)
    missing = sorted(set(CMU_22_JOINTS) - names)
    raise BadInputError(f"{p}: skeleton not supported for transitions: needs the 22 CMU joints "
                        f"({', '.join(CMU_22_JOINTS[:4])}, ...), the salsa or the Bandai Namco ones; missing e.g. "
                        f"{missing[:5]}")


def _motion_files(folder: Path) -> list[Path]:
    """The ``.bvh`` / exp-map ``.txt`` files under ``folder`` (recursively, README files aside), sorted."""
    return sorted(f for f in folder.rglob("*") if f.is_file() and f.suffix.lower() in (".bvh", ".txt")
                  and not f.name.lower().startswith("readme"))


def resolve_data(data: str, *, fps: float | None = None, test_fraction: float = 0.2):
    """Train and test sources for ``--data``.

    * ``"sample"``: the embedded sample's fixed split (:func:`refimpl.protocols.transition.sample_sources`);
    * a folder laid out like ``../shared/data`` (``dmgnn_cmu_expmap`` ...): :func:`refimpl.protocols.transition.shared_sources`;
    * a folder with ``train/`` and ``test/`` sub-folders: their ``*.bvh`` / ``*.txt`` files (recursively);
    * any other folder: its files sorted by path, the last ``test_fraction`` of them held out (split by file);
    * a single file: its first ``1 − test_fraction`` of frames for training, the rest for testing (split by time).

    Returns
    -------
    train, test : list of TransitionSource
    """
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

    if (root / "train").is_dir() and (root / "test").is_dir():
        train = [source_for_file(f, fps=fps) for f in _motion_files(root / "train")]
        test = [source_for_file(f, fps=fps) for f in _motion_files(root / "test")]
    else:
        found = _motion_files(root)
        if len(found) == 1:
            return resolve_data(str(found[0]), fps=fps, test_fraction=test_fraction)
        n_test = max(1, int(round(test_fraction * len(found)))) if found else 0
        train = [source_for_file(f, fps=fps) for f in found[:len(found) - n_test]]
        test = [source_for_file(f, fps=fps) for f in found[len(found) - n_test:]]
    if not train or not test:
        raise BadInputError(f"{root}: found {len(train)} training and {len(test)} test files (.bvh / .txt); "
                            "need at least one of each")
    return train, test


def _load_any(source, fps: float = 30.0):
    """The loader of a source of any kind: the Bandai Namco takes' own, else the CMU / salsa one."""
    if source.kind == BANDAI_NAMCO_KIND:
        return load_bandai_namco_source(source, fps)
    return load_source(source, fps)


def _take_content(path) -> str | None:
    """A Bandai Namco take's content (walk, run, ...: its label, as in training), else None (the folder's name)."""
    try:
        return take_facts(path).content
    except ValueError:
        return None


def eval_dataset(args, model, T: int):
    """The windows ``refimpl eval`` scores and one line saying which (spec/cli.md §4): ``--takes`` exactly;
    a Bandai Namco folder its held-out takes or all of them (:func:`~refimpl.protocols.transition_locomotion.scored_takes`);
    the ``test/`` of a ``train/`` + ``test/`` folder; otherwise the held-out windows of :func:`build_datasets`.
    Only the scored files are read when the statistics come from ``model`` (root z-normalisation)."""
    takes, why = list(args.takes or ()), None
    if takes and args.data != "sample":
        raise UsageError("--takes replaces --data: give one of them")
    root = Path(args.data)
    if not takes and args.data != "sample" and root.is_dir():
        if (root / "train").is_dir() and (root / "test").is_dir():
            takes = _motion_files(root / "test")
            why = f"the {len(takes)} files of {root / 'test'} (the train/ files are not read)"
        elif is_bandai_namco_folder(root):
            try:
                takes, why = scored_takes(find_takes(root))
            except ValueError as exc:
                raise BadInputError(f"--data {args.data}: {exc}") from None
    if not takes:
        _, test_ds = build_datasets(args.data, T, args.stride, fps=args.fps, test_fraction=args.test_fraction)
        return test_ds, f"the held-out windows of --data {args.data}"
    sources = [source_for_file(t, fps=args.fps, label=_take_content(t)) for t in takes]   # .bvh / .txt, rig known
    stats = (model.fields["root_mean"], model.fields["root_std"]) if model is not None else (np.zeros(3), np.ones(3))
    try:
        loader = _load_any  # Bandai Namco takes only: through the data cache (their entry holds just these takes)
        if all(s.kind == BANDAI_NAMCO_KIND for s in sources):
            loader = cached_loader((sources,), load_bandai_namco_source, progress=stderr_line)
        ds, _ = build_transition_datasets(sources, [], T=T, stride=args.stride, loader=loader)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"{'--takes' if args.takes else '--data ' + args.data}: {exc}") from exc
    ds = dataclasses.replace(ds, root_mean=np.asarray(stats[0], dtype=np.float64),
                             root_std=np.asarray(stats[1], dtype=np.float64))
    return ds, why or f"the {len(takes)} files of --takes (no training split; normalisation from the checkpoint)"


def build_datasets(data: str, T: int, stride: int, *, fps=None, test_fraction=0.2, test_stride=None,
                   train_only: bool = False):
    """Train and test :class:`~refimpl.protocols.transition.TransitionDataset` of ``2 + T + 2``-pose windows for ``--data``
    (:func:`resolve_data`, :func:`refimpl.protocols.transition.build_transition_datasets`); a folder of Bandai
    Namco locomotion takes: :func:`refimpl.protocols.transition_locomotion.build_datasets` (split by take,
    spec/qtg.md §8.4). ``train_only``: the held-out files are not read (the test dataset has no window)."""
    if data != "sample" and is_bandai_namco_folder(data):
        try:
            return build_bandai_namco(data, T=T, stride=stride, test_stride=test_stride, progress=stderr_line,
                                      train_only=train_only)
        except (OSError, ValueError) as exc:
            raise BadInputError(f"--data {data}: {exc}") from exc
    train_src, test_src = resolve_data(data, fps=fps, test_fraction=test_fraction)
    try:
        return build_transition_datasets(train_src, [] if train_only else test_src, T=T, stride=stride,
                                         test_stride=test_stride, loader=_load_any)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {data}: {exc}") from exc


def train_datasets(args):
    """Train and held-out datasets of ``refimpl train``'s options (``--data``, ``--transition-length``, ...)."""
    return build_datasets(args.data, args.transition_length, args.stride, fps=args.fps,
                          test_fraction=args.test_fraction)


def import_datasets(args):
    """``(train, None)`` for ``refimpl import``: a checkpoint stores the root statistics of every training window,
    so the training side is read (the Bandai Namco takes from the data cache after the first command); the
    held-out side, which only validates a training run, is not."""
    train, _ = build_datasets(args.data, args.transition_length, args.stride, fps=args.fps,
                              test_fraction=args.test_fraction, train_only=True)
    return train, None


def num_examples(dataset) -> int:
    """Training examples of a dataset (windows)."""
    return int(dataset.num_windows)


def describe_data(train_ds, test_ds) -> str:
    """``"1799 training / 96 held-out windows (T = 30 at 30 fps)"``."""
    return (f"{train_ds.num_windows} training / {test_ds.num_windows} held-out windows "
            f"(T = {train_ds.transition_length} at {train_ds.fps:g} fps)")


def checkpoint_extra(train_ds) -> dict:
    """What a checkpoint of this task stores beside the network's config: the training windows' root statistics
    (the network's input normalisation) and frame rate."""
    return {"root_mean": [float(v) for v in train_ds.root_mean], "root_std": [float(v) for v in train_ds.root_std],
            "fps": float(train_ds.fps)}


def check_checkpoint(model_config: Mapping, path) -> None:
    """Refuse (:class:`~refimpl.errors.BadInputError`) a checkpoint without :func:`checkpoint_extra`'s statistics."""
    if "root_mean" not in model_config or "root_std" not in model_config:
        raise BadInputError(f"{path}: the checkpoint has no normalisation statistics (root_mean/root_std); "
                            "train it with `refimpl train`")


def trained_fields(model_config: Mapping, config) -> dict:
    """The :class:`~refimpl.registry.TrainedModel` fields of this task from a checkpoint's model config: the
    frame rate, and the task's ``fields`` ``root_mean``, ``root_std`` (3,) and T (``transition_length``)."""
    return {"fps": float(model_config.get("fps", 30.0)),
            "fields": {"root_mean": np.asarray(model_config["root_mean"], dtype=np.float64),
                       "root_std": np.asarray(model_config["root_std"], dtype=np.float64),
                       "transition_length": int(model_config.get("transition_length", config.transition_length))}}


class JoinedOnnxMethod:
    """An exported transition model's method whose graphs carry the join option (metadata ``join``, spec/qtg.md
    §7.4): :func:`methods` lists it as ``<name>+join`` (e.g. ``qtg_onnx+join``)."""

    def __init__(self, method: Callable):
        self.method = method

    def __call__(self, past, target, T):
        return self.method(past, target, T)


def onnx_method(runtime) -> Callable:
    """``f(past, target, T) -> poses`` running an exported transition model's runtime (``runtime.transition``);
    a :class:`JoinedOnnxMethod` when the files were exported with the join option.

    The models standardise inside the graph, so ``f`` takes and returns raw poses like the NumPy methods; output
    quaternions are normalised to unit length.
    """
    def network_onnx(past, target, T):
        out = np.asarray(runtime.transition(np.asarray(past, np.float32), np.asarray(target, np.float32), int(T)),
                         dtype=np.float64)  # (B, T, P)
        root, quats = split_pose(out)
        quats = quats / np.maximum(np.linalg.norm(quats, axis=-1, keepdims=True), 1e-12)
        return join_pose(root, quats)

    join = (runtime.rollout_model or runtime.step_model).metadata.get("join") or {}
    return JoinedOnnxMethod(network_onnx) if join.get("mode", "none") != "none" else network_onnx


# ----------------------------------------------------------------------------------------------------------------
# baselines and protocol
# ----------------------------------------------------------------------------------------------------------------

def methods(networks: Mapping[str, Callable] | None = None, *, fps: float = 30.0, join: str = "none") -> dict:
    """``name -> f(past, target, T)``: the given networks' methods (in order; an exported model with the join option
    as ``<name>+join``; with ``join="inertialize"`` each followed by ``<name>+join``,
    :func:`refimpl.protocols.transition_join.with_join`; with ``"inertialize+footlock"`` also by
    ``<name>+join+footlock``), then both baselines
    (:func:`refimpl.protocols.transition_baselines.method_registry` with ``dt = 1 / fps``)."""
    out = {}
    for name, f in dict(networks or {}).items():
        key = f"{name}+join" if isinstance(f, JoinedOnnxMethod) else name
        out[key] = f
        if check_join(join) != "none":
            out[f"{key}+join"] = with_join(f, "inertialize", dt=1.0 / fps)
        if join == "inertialize+footlock":
            out[f"{key}+join+footlock"] = with_join(f, join, dt=1.0 / fps)
    return {**out, **method_registry(dt=1.0 / fps)}


def clip_for(path, model_fps: float, fps_override):
    """(skeleton, (rotations, root_positions)) of a file at the model's rate (phase 0 of the resampling)."""
    src = source_for_file(path, fps=fps_override)
    load = load_bandai_namco_source if src.kind == BANDAI_NAMCO_KIND else load_source
    try:
        skel, clips = load(src, fps=model_fps)
    except (OSError, ValueError) as exc:
        raise file_error(path, exc) from exc
    return skel, clips[0], src


def random_context(model, rng, B: int):
    """Plausible raw context poses for a numerical check: root ~ N(mean, std), small random joint rotations."""
    J = (model.config.pose_size - 3) // 4
    root = model.fields["root_mean"] + model.fields["root_std"] * rng.standard_normal((B, 4, 3))  # (B, 4, 3)
    quats = quat_from_axis_angle(0.3 * rng.standard_normal((B, 4, J, 3)))  # (B, 4, J, 4)
    poses = join_pose(root, quats)
    return poses[:, :2], poses[:, 2:]


# ----------------------------------------------------------------------------------------------------------------
# commands (spec/cli.md)
# ----------------------------------------------------------------------------------------------------------------

def eval_command(args, model) -> int:
    """``refimpl eval`` on the transition task: the network(s) (``model``, ``--onnx``) and the baselines on the
    held-out windows of ``--data``; table, per-frame curve, JSON / CSV / PNG."""
    T = args.transition_length or (model.fields["transition_length"] if model else 30)
    _say(f"reading {' '.join(args.takes) if args.takes else args.data} ...")
    test_ds, why = eval_dataset(args, model, T)
    if test_ds.num_windows == 0:
        raise BadInputError(f"--data {args.data}: no held-out window of {T + 4} frames")
    _say(f"scoring {why}")
    results = evaluate_model(model, test_ds, onnx_dir=args.onnx, task=NAME, join=args.join)
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
    return 0


def _onnx_rate_and_length(onnx_dir, default_T: int) -> tuple[float, int]:
    """Frame rate and T from the exported models' metadata, checked (a T of the wrong type is exit 3)."""
    fps, model_meta = onnx_frame_rate(onnx_dir)
    T = model_meta.get("transition_length")
    if T is None:
        T = default_T
    elif isinstance(T, bool) or not isinstance(T, int) or not 1 <= T <= 100_000:
        raise BadInputError(f"{onnx_dir}: metadata model.transition_length: expected an integer in [1, 100000], "
                            f"got {T!r}"[:300])
    return fps, int(T)


def generate_command(args, model) -> int:
    """``refimpl generate`` on the transition task: frames s-1, s of ``--source`` and g, g+1 of ``--target``, the
    T frames between them from the network (``--method qtg``, NumPy or onnxruntime) or a baseline, BVH out."""
    from refimpl.bvh_write import write_bvh

    require_source(args)
    if args.source_frame is None:
        raise UsageError("the following arguments are required for a transition: --source, --source-frame\n"
                         + generate_usage())
    network = None
    if args.method == METHOD_NAMES[0]:
        if args.backend == "numpy" and not args.checkpoint:
            raise UsageError(f"--method {args.method} with --backend numpy needs --checkpoint")
        if args.backend == "onnx" and not args.onnx:
            raise UsageError("--backend onnx needs --onnx DIR (the folder written by `refimpl export`)")
        network = checkpoint_for(NAME, model, args.checkpoint)
    elif args.backend == "onnx":
        raise UsageError(f"--backend onnx runs the network; --method {args.method} is a NumPy baseline")
    fps, T_model = (network.fps, network.fields["transition_length"]) if network else (30.0, 30)
    if args.backend == "onnx" and network is None:
        fps, T_model = _onnx_rate_and_length(args.onnx, T_model)
    T = args.length or T_model
    target_path = args.target or args.source
    skel, src_clip, src = clip_for(args.source, fps, args.fps)
    skel2, tgt_clip, tgt = clip_for(target_path, fps, args.fps)
    if tuple(skel.names) != tuple(skel2.names) or tuple(skel.parents) != tuple(skel2.parents):
        raise BadInputError(f"{target_path}: its {skel2.num_joints}-joint skeleton differs from {args.source}'s "
                            "(both clips must come from the same skeleton)")
    if skel != skel2:  # the same joints, other bone lengths (another actor of the same rig)
        _say(f"note: {target_path} has other bone lengths than {args.source}; the transition and the BVH use "
             "the source's skeleton")
    if network is not None and 3 + 4 * skel.num_joints != network.config.pose_size:
        raise BadInputError(f"{args.source}: {skel.num_joints} joints, but the network was trained on "
                            f"{(network.config.pose_size - 3) // 4} (a take of the rig it was trained on is needed)")
    if args.method == METHOD_NAMES[0]:
        networks = network_methods(None if args.backend == "onnx" else network,
                                   onnx_dir=args.onnx if args.backend == "onnx" else None, expect=network)
        method = next(iter(networks.values()))
    else:
        method = methods(fps=fps)[args.method]
    method = with_join(method, args.join, dt=1.0 / fps)
    same = Path(args.source).resolve() == Path(target_path).resolve()
    target_frame = args.target_frame if args.target_frame is not None else (
        args.source_frame + T + 1 if same else 1)
    out = args.out or "transition.bvh"
    tr = make_transition(method, skel, src_clip, args.source_frame, tgt_clip, target_frame, T,
                         frame_time=1.0 / fps, context=args.context, align=args.align, same_clip=same,
                         method_name=args.method + _JOIN_SUFFIX[args.join], name=Path(out).stem)
    write_bvh(out, with_end_sites(tr.motion))
    _say(f"wrote {out}: {tr.motion.num_frames} frames at {fps:g} fps, {tr.motion.num_joints} joints (centimetres); "
         f"generated frames {tr.start}..{tr.stop - 1} ({tr.method}, {args.backend})")
    err = tr.error_cm()
    if err is not None:
        _say(f"ground truth available (same clip, target = source + T + 1): mean joint error {err:.2f} cm")
        if args.truth:
            write_bvh(args.truth, with_end_sites(tr.truth))
            _say(f"wrote {args.truth} (ground truth)")
    elif args.truth:
        raise UsageError("--truth needs --target-frame = --source-frame + T + 1 in the same file (and --align none)")
    if args.png or args.gif:
        title = (f"{tr.method}: {Path(args.source).name} frame {args.source_frame} -> {Path(target_path).name} "
                 f"frame {target_frame}, {T} frames generated; green = context")
        render_transition(tr, png=args.png, gif=args.gif, title=title)
    return 0


_JOIN_SUFFIX = {"none": "", "inertialize": "+join", "inertialize+footlock": "+join+footlock"}


def export_options(args) -> dict:
    """The exporter's options of ``refimpl export``: ``T`` (``--transition-length``, when given), ``join``
    (``--join``, when not ``none``)."""
    return {**export_length(args), **({} if args.join == "none" else {"join": args.join})}


def verify_inputs(args, model) -> tuple:
    """``((past, target), {"T": ...})``: 8 random context poses (:func:`random_context`, ``--seed``) for
    ``refimpl export``'s check."""
    past, target = random_context(model, np.random.default_rng(args.seed), 8)
    return (past, target), {"T": args.transition_length}
