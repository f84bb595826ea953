"""The short-term prediction task of the application (QuaterNet): ``refimpl train/eval/generate``'s options,
data resolution, checkpoint fields, methods, ``generate``'s predictions and pictures, ``export``'s check inputs
(spec/prediction.md §7, spec/architecture.md §tasks). The data is in :mod:`refimpl.protocols.prediction_data`,
the protocol, error and baselines in :mod:`refimpl.protocols.prediction`.

Shape legend: B batch, P prefix frames, K predicted frames, F frames of a file, J joints.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.progress import stderr_line
from refimpl.options import export_length
from refimpl.errors import BadInputError, UsageError
from refimpl.expmap import read_expmap
from refimpl.preprocess import downsample, fix_antipodal
from refimpl.protocols.prediction import (Protocol, average_curves, baseline_methods, canonical_prefix, euler_errors,
                                          evaluate_all, format_table, make_protocol, table2_protocol,
                                          write_results_json)
from refimpl.protocols.prediction_data import CHECKPOINT_SCHEMA  # the task's checkpoint schema (task interface)
from refimpl.protocols.prediction_data import (SUBJECT_DIR, PredictionData, load_cmu, load_h36m, skeleton_of,
                                               stride_of)
from refimpl.registry import require_source
from refimpl.services import checkpoint_for, network_methods, onnx_frame_rate, onnx_metadata
from refimpl.skeleton import Skeleton

__all__ = [
    "CHECKPOINT_SCHEMA", "NAME", "EVAL_SUMMARY", "GENERATE_USAGE", "SAMPLE_EXPMAP_DIR", "add_train_options",
    "add_eval_options", "add_export_options", "add_generate_options", "resolve_data", "train_datasets",
    "import_datasets", "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint", "trained_fields",
    "onnx_method", "methods", "evaluate", "eval_protocol", "eval_actions", "load_clip", "Prediction",
    "make_prediction", "render_prediction", "check_prefixes", "eval_command", "generate_command", "export_options",
    "verify_inputs",
]

# ------------------------------------------------------------------------------------------------------------
# the task interface of the application layer (spec/architecture.md §tasks; spec/prediction.md §7)
# ------------------------------------------------------------------------------------------------------------

NAME = "prediction"
EVAL_SUMMARY = ("prediction (quaternet, quaternet-cnn): the published short-term protocol, Euler-angle error per "
                "action and horizon, against zero-velocity and running averages")
GENERATE_USAGE = "refimpl generate --checkpoint CKPT --source FILE [...]  (prediction)"
#: ``--data sample``: the embedded CMU exp-map sample.
SAMPLE_EXPMAP_DIR = Path(__file__).resolve().parent.parent / "data" / "sample" / "expmap"


def add_train_options(parser) -> None:
    """The task's options of ``refimpl train`` (``--downsample``); its data is ``--data`` (:func:`resolve_data`)."""
    from refimpl.bounds import bounded_int

    parser.add_argument("--downsample", type=bounded_int("downsample"), default=2,
                        help="prediction task: keep every k-th frame, every phase for training (default 2: "
                             "H3.6M 50 -> 25 Hz, CMU 120 -> 60 fps)")


def add_eval_options(parser) -> None:
    """The task's options of ``refimpl eval`` (``--protocol``, ``--samples-per-sequence``, ``--wrap``)."""
    parser.add_argument("--protocol", default="standard", choices=("standard", "dense"),
                        help="prediction task: 4 (standard, Table 1) or 128 (dense, Table 2) samples per sequence")
    from refimpl.bounds import bounded_int

    parser.add_argument("--samples-per-sequence", type=bounded_int("samples"), default=None,
                        help="prediction task: override the protocol's samples per sequence")
    parser.add_argument("--horizons", default="default", choices=("default", "table2"),
                        help="prediction task: the dataset's horizons (default) or the dual-quaternion paper's "
                             "Table 2 horizons 80 ms ... 4 s at the data's real frame rate, those the test files "
                             "allow (table2)")
    parser.add_argument("--actions", default=None,
                        help="prediction task: comma-separated test actions to evaluate (default all)")


def add_export_options(parser) -> None:
    """The task's options of ``refimpl export``: none."""


def add_generate_options(parser) -> None:
    """The task's options of ``refimpl generate``: none (``--source``, ``--source-frame``, ``--length`` are
    common)."""


def resolve_data(data: str, *, downsample: int = 2, longest_training_only: bool = False) -> PredictionData:
    """The data of ``--data``: ``"sample"`` (:data:`SAMPLE_EXPMAP_DIR`), a folder like ``../shared/data``
    (its ``dmgnn_cmu_expmap``), a CMU exp-map folder (``train/``, ``test/``: :func:`load_cmu`) or a Human3.6M
    folder (``S1`` … ``S11``: :func:`load_h36m`). ``longest_training_only``: parse only the training file with the
    most rows (the loaders' option; what ``refimpl import`` needs).

    Raises
    ------
    BadInputError
        Missing folder, unknown layout, malformed files.
    """
    from refimpl.errors import BadInputError

    root = SAMPLE_EXPMAP_DIR if data == "sample" else Path(data)
    if not root.is_dir():
        raise BadInputError(f"{root}: no such folder (the prediction task's --data takes 'sample', a CMU exp-map "
                            "folder with train/ and test/, or a Human3.6M folder with S1 ... S11)")
    if (root / "dmgnn_cmu_expmap").is_dir():
        root = root / "dmgnn_cmu_expmap"
    try:
        if (root / "train").is_dir() or (root / "test").is_dir():
            return load_cmu(root, stride=downsample, longest_training_only=longest_training_only)
        if any(p.is_dir() and SUBJECT_DIR.match(p.name) for p in root.iterdir()):
            return load_h36m(root, stride=downsample, longest_training_only=longest_training_only)
    except ValueError as exc:
        raise BadInputError(f"--data {data}: {exc}") from exc
    raise BadInputError(f"{root}: neither a CMU exp-map folder (train/, test/) nor a Human3.6M folder (S1 ... S11)")


def train_datasets(args):
    """``(data, data)``: the :class:`PredictionData` of ``refimpl train``'s ``--data`` (its ``train`` sequences
    are the training examples, its ``test`` sequences the held-out ones)."""
    from refimpl.errors import BadInputError

    data = resolve_data(args.data, downsample=getattr(args, "downsample", 2))
    if not data.train:
        raise BadInputError(f"--data {args.data}: no training sequences")
    return data, data


def import_datasets(args):
    """``(data, data)`` for ``refimpl import``: what an imported checkpoint stores from the data (the dataset's
    name, skeleton and joint count, the frame time) and the recipe's check that a training window fits need only
    the longest training file, so only that one is parsed (:func:`resolve_data` with
    ``longest_training_only``; the others' names are checked and their rows counted, spec/import.md §1). The
    checkpoint is the one :func:`train_datasets`' data gives."""
    from refimpl.errors import BadInputError

    data = resolve_data(args.data, downsample=getattr(args, "downsample", 2), longest_training_only=True)
    if not data.train:
        raise BadInputError(f"--data {args.data}: no training sequences")
    return data, data


def num_examples(dataset: PredictionData) -> int:
    """Training examples: the training sequences (one random window of each per epoch, the published epoch)."""
    return len(dataset.train)


def describe_data(train_ds: PredictionData, test_ds=None) -> str:
    """``"cmu: 20 training sequences (75-299 frames), 2 test sequences, 38 joints at 16.7 ms per frame"``."""
    lengths = [s.num_frames for s in train_ds.train]
    return (f"{train_ds.dataset}: {len(train_ds.train)} training sequences "
            f"({min(lengths, default=0)}-{max(lengths, default=0)} frames), {len(train_ds.test)} test sequences, "
            f"{train_ds.skeleton.num_joints} joints at {train_ds.frame_time * 1000:.1f} ms per frame")


def checkpoint_extra(train_ds: PredictionData) -> dict:
    """What ``eval``, ``export`` and ``generate`` need later: the dataset (its skeleton) and the frame time."""
    return {"dataset": train_ds.dataset, "frame_time": float(train_ds.frame_time),
            "fps": float(1.0 / train_ds.frame_time), "num_joints": int(train_ds.skeleton.num_joints)}


def check_checkpoint(model_config: Mapping, path) -> None:
    """A prediction checkpoint names its dataset (``cmu`` or ``h36m``)."""
    from refimpl.errors import BadInputError

    if model_config.get("dataset") not in ("cmu", "h36m"):
        raise BadInputError(f"{path}: the checkpoint names no prediction dataset (model_config['dataset'] = "
                            f"{model_config.get('dataset')!r}); train it with `refimpl train`")


def trained_fields(model_config: Mapping, config) -> dict:
    """The :class:`~refimpl.registry.TrainedModel` fields of this task: the frame rate."""
    return {"fps": float(model_config.get("fps", 25.0))}


def _dq_skeleton_of_runtime(runtime):
    """The dataset skeleton of exported models whose frames are dual quaternions (metadata representation
    ``quaternet_dq_frame``), else None."""
    for m in (getattr(runtime, "predict_model", None), getattr(runtime, "step_model", None)):
        meta = getattr(m, "metadata", None) or {}
        if (meta.get("representation") or {}).get("name") == "quaternet_dq_frame":
            return skeleton_of(meta.get("dataset", "cmu"))
    return None


def onnx_method(runtime) -> Callable:
    """``method(prefix (B, P, J, 4), n_future) -> (B, n_future, J, 4)`` running an exported predictor
    (``runtime.predict``; for dual-quaternion frames, the prefix's current DQs in and the decoded local rotations
    out, spec/quaternet.md §9)."""
    skeleton = _dq_skeleton_of_runtime(runtime)

    def network_onnx(prefix, n_future):
        x = np.asarray(prefix, dtype=np.float64)
        if skeleton is not None:  # QuaterNet with dual quaternions: current DQs in, decoded local rotations out
            from refimpl.dq_prediction import dq_frames_from_rotations, rotations_from_dq_frames

            x = canonical_prefix(x)   # the sign rule first, as the NumPy method (metadata input_transform)
            y = np.asarray(runtime.predict(dq_frames_from_rotations(x, skeleton), int(n_future)), np.float64)
            return rotations_from_dq_frames(y, skeleton.parents)
        return np.asarray(runtime.predict(x, int(n_future)), dtype=np.float64)

    return network_onnx


def methods(networks: Mapping[str, Callable] | None = None, *, fps: float | None = None) -> dict:
    """``name -> method(prefix, n_future)``: the baselines in Table 1's order (zero-velocity, running averages
    over 2 and 4 frames), then the given networks' methods."""
    base = baseline_methods()
    return {**{k: base[k] for k in ("zero-velocity", "run. avg. 2", "run. avg. 4")}, **dict(networks or {})}


def evaluate(test_ds: PredictionData, methods_by_name: Mapping[str, Callable]) -> list:
    """The task interface's ``evaluate(test_ds, methods)``: :func:`~refimpl.protocols.prediction.evaluate_all`
    under the dataset's standard protocol."""
    return evaluate_all(test_ds, methods_by_name)


def eval_protocol(dataset: str, name: str = "standard", samples_per_sequence: int | None = None, *,
                  horizons: str = "default", data: "PredictionData | None" = None,
                  actions: Sequence[str] | None = None) -> Protocol:
    """``refimpl eval``'s ``--protocol standard|dense`` (and ``--samples-per-sequence``) for a dataset;
    ``horizons="table2"`` (``--horizons table2``): :func:`table2_protocol` of ``data`` (required) and ``actions``."""
    if name not in ("standard", "dense"):
        raise ValueError(f"protocol: expected 'standard' or 'dense', got {name!r}")
    if horizons == "table2":
        if data is None:
            raise ValueError("data: required for the table2 horizons (they depend on its frame rate)")
        return table2_protocol(data, name, samples_per_sequence, actions=actions)
    if horizons != "default":
        raise ValueError(f"horizons: expected 'default' or 'table2', got {horizons!r}")
    return make_protocol(dataset, dense=name == "dense", samples_per_sequence=samples_per_sequence)


def eval_actions(args) -> tuple | None:
    """The actions of ``--actions`` (comma-separated), or None (every test action)."""
    text = getattr(args, "actions", None)
    if not text:
        return None
    return tuple(a.strip() for a in text.split(",") if a.strip())


def load_clip(path, dataset: str, frame_time: float) -> np.ndarray:
    """One exp-map file at a model's rate: rotations ``(F, J, 4)`` (phase 0 of the decimation, ``quat_fix``;
    CMU: the reference row dropped), as the task's test sequences.

    Raises
    ------
    BadInputError
        Missing or malformed file, or one that is not an exp-map ``.txt`` of the dataset's layout.
    """
    from refimpl.errors import BadInputError, existing_file, reading

    p = existing_file(path)
    if p.suffix.lower() != ".txt":
        raise BadInputError(f"{p}: the prediction task reads exp-map .txt files ({dataset} layout)")
    with reading(p):
        motion = read_expmap(p, layout=dataset, use_root_position=False)
    if dataset == "cmu":
        motion = dataclasses.replace(motion, rotations=motion.rotations[1:], root_positions=motion.root_positions[1:])
    m = fix_antipodal(downsample(motion, stride_of(dataset, frame_time), 0))
    return np.asarray(m.rotations, dtype=np.float64)


@dataclasses.dataclass(frozen=True)
class Prediction:
    """A prediction from a file's prefix, with its ground truth when the file continues.

    Attributes
    ----------
    motion : Motion
        The prefix frames then the ``k`` predicted frames (root at the origin: the task predicts rotations).
    truth : Motion or None
        The same frames from the file (when it has them).
    start, stop : int
        The predicted frames are ``motion`` frames ``[start, stop)``.
    method : str
    """

    motion: object
    truth: object
    start: int
    stop: int
    method: str

    def euler_error(self) -> np.ndarray | None:
        """Per predicted frame, the protocol's error (:func:`euler_errors`) against the truth, or None."""
        if self.truth is None:
            return None
        a = np.asarray(self.motion.rotations)[None, self.start:self.stop]
        b = np.asarray(self.truth.rotations)[None, self.start:self.stop]
        return euler_errors(a, b)[0]


def make_prediction(method: Callable, rotations, frame: int, prefix_length: int, k: int, *, skeleton: Skeleton,
                    frame_time: float, method_name: str = "network", name: str = "prediction",
                    option: str = "--source-frame", source: str = "the clip") -> Prediction:
    """Predict ``k`` frames after frame ``frame`` of ``rotations (F, J, 4)`` from the ``prefix_length`` frames
    ending there (``method(prefix (1, P, J, 4), k)``); ``option`` names the option of ``frame`` in the error
    (``python -m deploy run``: ``--start``).

    Raises
    ------
    UsageError
        ``frame`` outside ``[prefix_length − 1, F − 1]`` (``option`` names it in the message).
    BadInputError
        A clip shorter than the prefix (``source`` names it).
    """
    from refimpl.errors import BadInputError, UsageError
    from refimpl.motion import Motion

    rot = np.asarray(rotations, dtype=np.float64)
    F = rot.shape[0]
    if F < prefix_length:
        raise BadInputError(f"{source}: too short: {F} frames at the model's rate, a prefix needs "
                            f"{prefix_length}")
    if not prefix_length - 1 <= frame <= F - 1:
        raise UsageError(f"{option} must lie in [{prefix_length - 1}, {F - 1}] (a {prefix_length}-frame "
                         f"prefix ending there, frames at the model's rate), got {frame}")
    prefix = rot[frame - prefix_length + 1:frame + 1]  # (P, J, 4)
    pred = np.asarray(method(prefix[None], int(k)), dtype=np.float64)[0]  # (k, J, 4)
    pred = pred / np.linalg.norm(pred, axis=-1, keepdims=True)
    out = np.concatenate([prefix, pred])
    zeros = np.zeros((out.shape[0], 3))
    motion = Motion(skeleton, out, zeros, frame_time, name)
    truth = None
    if frame + k < F:
        truth = Motion(skeleton, rot[frame - prefix_length + 1:frame + k + 1], zeros, frame_time, f"{name}_truth")
    return Prediction(motion=motion, truth=truth, start=prefix_length, stop=prefix_length + int(k),
                      method=method_name)


def render_prediction(pr: Prediction, png=None, gif=None, title=None, context: int = 10) -> list:
    """Draw a :class:`Prediction` (against its ground truth when it has one): the last ``context`` prefix frames
    and the predicted ones, as a PNG strip and / or a GIF, numbered as in the BVH the prediction is written to,
    with a title (default: the method and the predicted frames), left and right limbs in two shades
    (:func:`refimpl.render_strip.limb_sides`, the rule of every model's pictures) over the clip's one floor."""
    from refimpl.progress import stderr_line
    from refimpl.render import render_gif
    from refimpl.render_strip import limb_sides, render_strip

    a = max(0, pr.start - context)
    parents = np.asarray(pr.motion.skeleton.parents)
    pred = pr.motion.positions()[a:]
    gt = pr.truth.positions()[a:] if pr.truth is not None else pred
    hl = (pr.start - a, pr.stop - a)
    numbers = np.arange(a, a + pred.shape[0])  # the panels carry the BVH's frame numbers
    title = title or f"{pr.method}: frames {pr.start}-{pr.stop - 1} predicted"
    labels = ("ground truth", pr.method) if pr.truth is not None else (pr.method, "")
    sides = limb_sides(pr.motion.skeleton)
    written = []
    if png:
        n = pred.shape[0]
        frames = sorted(set([0, hl[0] - 1] + list(range(hl[0], hl[1], max(1, (hl[1] - hl[0]) // 6))) + [n - 1]))
        written.append(render_strip(png, gt, parents, prediction=pred if pr.truth is not None else None,
                                    frames=frames, highlight=hl, labels=labels, title=title,
                                    frame_time=pr.motion.frame_time, frame_numbers=numbers, sides=sides))
    if gif:
        written.append(render_gif(gif, gt, parents, prediction=pred if pr.truth is not None else None,
                                  progress=stderr_line,
                                  fps=pr.motion.fps, highlight=hl, labels=labels, title=title,
                                  frame_numbers=numbers, sides=sides))
    return written


def check_prefixes(model, rng: np.random.Generator, batch: int = 8) -> np.ndarray:
    """``prefix (B, P, J, 4)`` for ``refimpl export``'s check: real CMU test windows of the embedded sample
    (prefix of the model's training length) for a CMU model, small random rotations otherwise."""
    from refimpl.rotations import quat_from_axis_angle

    P = int(getattr(model.config, "prefix_length", 50))
    if model.extra.get("dataset") == "cmu":
        data = load_cmu(SAMPLE_EXPMAP_DIR, stride=stride_of("cmu", model.extra["frame_time"]))
        windows = [s.rotations[i:i + P] for s in data.test
                   for i in rng.integers(0, s.num_frames - P + 1, size=batch)]
        return np.stack(windows[:batch])
    J = int(model.config.num_joints)
    return quat_from_axis_angle(0.3 * rng.standard_normal((batch, P, J, 3)))


# ------------------------------------------------------------------------------------------------------------
# commands (spec/cli.md)
# ------------------------------------------------------------------------------------------------------------

def _say(*parts) -> None:
    print(*parts, flush=True)



def eval_command(args, model) -> int:
    """``refimpl eval`` on the prediction task: the network(s) and the baselines, the paper's table, JSON, PNG."""
    _say(f"reading {args.data} ...")
    stride = stride_of(model.extra["dataset"], model.extra["frame_time"]) if model else 2
    data = resolve_data(args.data, downsample=stride)
    if model is not None and model.extra.get("dataset") != data.dataset:
        raise UsageError(f"--data {args.data} is {data.dataset}, the model was trained on {model.extra.get('dataset')}")
    actions = eval_actions(args)
    try:
        protocol = eval_protocol(data.dataset, args.protocol, args.samples_per_sequence, horizons=args.horizons,
                                 data=data, actions=actions)
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    networks = network_methods(model, onnx_dir=args.onnx) if (model is not None or args.onnx) else {}
    try:
        results = evaluate_all(data, methods(networks), protocol, progress=stderr_line, actions=actions)
    except ValueError as exc:
        raise BadInputError(f"--data {args.data}: {exc}") from exc
    if model is not None:
        _say(f"network {model.spec.name} from {model.path} (step {model.meta.get('step')})")
    _say("Mean Euler-angle error (radians, zyx, joint 0 excluded) per action and horizon:")
    _say(format_table(results))
    if args.json:
        write_results_json(args.json, results[0] if len(results) == 1 else results)
        _say(f"results          {args.json}")
    if args.plot:
        from refimpl.render import render_error_curves

        render_error_curves(args.plot, average_curves(results), frame_time=protocol.frame_ms / 1000.0)
        _say(f"plot             {args.plot}")
    return 0


def generate_command(args, model) -> int:
    """``refimpl generate`` on the prediction task: a prefix of ``--source`` -> ``--length`` frames, BVH out."""
    from refimpl.bvh_write import write_bvh

    require_source(args)
    if args.backend == "numpy":
        model = checkpoint_for(NAME, model, args.checkpoint)
        if model is None:
            raise UsageError("--backend numpy needs --checkpoint")
    if args.backend == "onnx":
        if not args.onnx:
            raise UsageError("--backend onnx needs --onnx DIR (the folder written by `refimpl export`)")
        fps, _ = onnx_frame_rate(args.onnx)  # frame rate and model entry checked (exit 3 when wrong)
        meta = onnx_metadata(args.onnx)
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
    rotations = load_clip(args.source, dataset, frame_time)
    k = args.length or 25
    out = args.out or "prediction.bvh"
    pr = make_prediction(next(iter(networks.values())), rotations, args.source_frame, P, k,
                         skeleton=skeleton_of(dataset), frame_time=frame_time, method_name=name, name=Path(out).stem,
                         source=str(args.source))
    write_bvh(out, pr.motion)
    _say(f"wrote {out}: {pr.motion.num_frames} frames at {1.0 / frame_time:g} fps ({dataset} skeleton, root "
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
        title = f"{name}: frames {pr.start}-{pr.stop - 1} predicted from {Path(args.source).name}"
        for f in render_prediction(pr, png=args.png, gif=args.gif, title=title):
            _say(f"wrote {f}")
    return 0


def export_options(args) -> dict:
    """The exporter's options of ``refimpl export``: ``T`` (``--transition-length``, when given)."""
    return export_length(args)


def verify_inputs(args, model) -> tuple:
    """``((prefix,), {})``: 8 check prefixes (:func:`check_prefixes`, ``--seed``) for ``refimpl export``'s check."""
    return (check_prefixes(model, np.random.default_rng(args.seed), 8),), {}
