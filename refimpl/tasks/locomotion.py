"""The locomotion task of the application (QuaterNet long-term: the pose and pace networks): ``refimpl train``'s
options and data resolution, checkpoint facts (rig, skeleton, seed clip), methods, ``eval``'s data
(spec/locomotion.md §8, spec/architecture.md §tasks). The data is in :mod:`refimpl.protocols.locomotion_data`,
the windows, pace data, datasets and protocol in :mod:`refimpl.protocols.locomotion`; generation along a path's options, files and
metrics in :mod:`refimpl.tasks.locomotion_generate` (the walk itself is :mod:`refimpl.models.quaternet_long_walk`).

Shape legend: B batch, P prefix, T target frames, F = 4 J + 8 values per input frame, J joints.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Callable, Mapping

import numpy as np

from refimpl.options import export_length
from refimpl.atomic import atomic_write_text
from refimpl.bounds import bounded_float, check_number
from refimpl.errors import UsageError, existing_file, reading
from refimpl.models.quaternet_long_walk import generate_walk
from refimpl.protocols.locomotion import LocomotionDataset, build_dataset, evaluate, format_results, zero_velocity
from refimpl.protocols.locomotion_data import CHECKPOINT_SCHEMA  # the task's checkpoint schema (task interface)
from refimpl.protocols.locomotion_data import skeleton_of
from refimpl.protocols.locomotion_data import (BANDAI_NAMCO_RIG, CMU_RIG, FPS, QUATERNET_UNIT_CM, LocomotionRig,
                                               bandai_namco_split, cmu_split)
from refimpl.services import load_trained, network_methods
from refimpl.tasks.locomotion_generate import (SPEEDS, bone_length_drift, dq_bone_length_drift, facing_of,
                                              foot_skating, parse_path, parse_speed, read_path_file, write_outputs)

__all__ = [
    "CHECKPOINT_SCHEMA", "NAME", "EVAL_SUMMARY", "GENERATE_USAGE", "SEED_FRAMES", "add_train_options",
    "add_eval_options", "add_export_options", "add_generate_options", "resolve_files", "train_datasets",
    "import_datasets", "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint", "trained_fields",
    "skeleton_of", "rig_of", "onnx_method", "methods", "evaluate", "load_eval_data", "eval_command", "walk_options",
    "walk_from_checkpoints", "describe_walk", "short_walk_warning", "skating_phrase", "generate_command",
    "export_options", "verify_inputs",
]

NAME = "locomotion"
EVAL_SUMMARY = ("locomotion (quaternet-long): free-running position and velocity error over the held-out windows "
                "with ground-truth controls, against zero-velocity")
GENERATE_USAGE = ("refimpl generate --model quaternet-long --checkpoint POSE.npz --pace PACE.npz [--path ...]  "
                  "(locomotion)")
#: Frames of the seed clip stored in a pose-network checkpoint (the generation prefix).
SEED_FRAMES = 30


def add_train_options(parser) -> None:
    """The locomotion task's options of ``refimpl train`` (its own names: every task adds its options to the
    same parser)."""
    from refimpl.bounds import bounded_int

    parser.add_argument("--locomotion-prefix", type=bounded_int("window"), default=30, metavar="P",
                        help="locomotion: conditioning frames of a pose window (default 30)")
    parser.add_argument("--locomotion-target", type=bounded_int("window"), default=60, metavar="T",
                        help="locomotion: predicted frames of a pose window (default 60)")
    parser.add_argument("--locomotion-max-files", type=bounded_int("files"), default=0, metavar="N",
                        help="locomotion: use at most N training and N held-out files (evenly spaced; 0 = all)")
    parser.add_argument("--pace-chunk-length", type=bounded_int("chunk"), default=0, metavar="N",
                        help="locomotion: spline points per pace-network chunk (default: min(1000, median))")


def add_eval_options(parser) -> None:
    """The task's options of ``refimpl eval``: none."""


def add_export_options(parser) -> None:
    """The task's options of ``refimpl export``: none."""


def add_generate_options(parser) -> None:
    """The task's options of ``refimpl generate`` (``--model quaternet-long``): the pace network, the path, the
    speed, the length, the controls output."""
    parser.add_argument("--pace", default=None, help="pace-network checkpoint (`refimpl train --model pace`)")
    parser.add_argument("--path", default="circle:r=3",
                        help="circle[:r=M], figure8[:size=M], line-turn[:turn=DEG] or a CSV of x,z points in metres")
    parser.add_argument("--speed", default="walk", help="walk, jog, run or units per frame (default walk)")
    parser.add_argument("--seconds", type=bounded_float("seconds"), default=10.0,
                        help="length of the motion (default 10)")
    parser.add_argument("--controls", default=None, help="also write the per-frame controls as JSON")


def _evenly(items: list, n: int) -> list:
    if n <= 0 or n >= len(items):
        return list(items)
    idx = np.unique(np.linspace(0, len(items) - 1, n).round().astype(int))
    return [items[i] for i in idx]


def resolve_files(data: str) -> tuple[str, list, list]:
    """``(source kind, train files, test files)`` for ``--data``.

    * ``"sample"``: the embedded CMU exp-map walks and runs (``refimpl/data/sample/expmap``, 10 training and 2
      held-out files, :func:`cmu_split`; 40-150 frames each at 30 fps, so use short windows);
    * a folder of Bandai Namco files (``dataset-2_*.bvh``), or a folder holding ``bandai_namco_locomotion``
      (``../shared/data``): :func:`bandai_namco_split`;
    * a folder with ``dmgnn_cmu_expmap`` or a DMGNN-like ``train/``, ``test/`` tree of CMU exp-map ``.txt``:
      :func:`cmu_split`;
    * any other folder of CMU ``.bvh`` files: sorted, the last 20 % held out.
    """
    from refimpl.errors import BadInputError
    if data == "sample":
        from refimpl.protocols.transition import SAMPLE_DIR
        data = str(Path(SAMPLE_DIR) / "expmap")
    root = Path(data)
    if not root.is_dir():
        raise BadInputError(f"{root}: no such folder (locomotion --data takes 'sample' or a folder)")
    if (root / "bandai_namco_locomotion").is_dir():
        root = root / "bandai_namco_locomotion"
    bn = sorted(root.glob("dataset-2_*.bvh"))
    if bn:
        train, test = bandai_namco_split(bn)
        return "bandai_namco", [str(p) for p in train], [str(p) for p in test]
    if (root / "dmgnn_cmu_expmap").is_dir():
        root = root / "dmgnn_cmu_expmap"
    txt = sorted(p for p in root.rglob("*.txt") if "readme" not in p.name.lower())
    if txt:
        train, test = cmu_split(txt)
        return "cmu_expmap", [str(p) for p in train], [str(p) for p in test]
    bvh = sorted(root.rglob("*.bvh"))
    if len(bvh) < 2:
        raise BadInputError(f"{root}: found {len(bvh)} .bvh files; locomotion needs at least 2 (train and test)")
    n_test = max(1, int(round(0.2 * len(bvh))))
    return "cmu_bvh", [str(p) for p in bvh[:-n_test]], [str(p) for p in bvh[-n_test:]]


def train_datasets(args, *, held_out: bool = True):
    """Train and held-out :class:`LocomotionDataset` of ``refimpl train``'s options (``--data``,
    ``--locomotion-*``); with ``held_out=False`` the held-out one is None (its files are not read)."""
    from refimpl.errors import BadInputError, UsageError
    P, T = int(args.locomotion_prefix), int(args.locomotion_target)
    if P < 1 or T < 2:
        raise UsageError(f"--locomotion-prefix must be >= 1 and --locomotion-target >= 2, got {P}, {T}")
    kind, train, test = resolve_files(args.data)
    n = int(getattr(args, "locomotion_max_files", 0) or 0)
    train, test = _evenly(train, n), _evenly(test, n)
    chunk = int(getattr(args, "pace_chunk_length", 0) or 0)
    try:
        return (build_dataset(kind, train, prefix=P, target=T, pace_chunk_length=chunk, progress=print),
                build_dataset(kind, test, prefix=P, target=T, pace_chunk_length=chunk, progress=print)
                if held_out else None)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {args.data}: {exc}") from exc


def import_datasets(args):
    """``(train, None)`` for ``refimpl import``: a checkpoint stores the seed clip chosen over every training
    sequence, so the training side is read (from the data cache after the first command); the held-out side,
    which only validates a training run, is not."""
    return train_datasets(args, held_out=False)


def num_examples(dataset: LocomotionDataset) -> int:
    """Training examples: sequences with at least one pose window (the reference's ⌈#seq / batch⌉ batches per
    epoch; our trainer takes ⌊N / batch⌋)."""
    return max(1, len(dataset.windows))


def describe_data(train_ds: LocomotionDataset, test_ds: LocomotionDataset) -> str:
    """``"1470 training sequences (735 files, ...) / 190 held-out ..."``."""
    return (f"{len(train_ds.sequences)} training sequences ({len(train_ds.files)} files, {train_ds.num_frames} "
            f"frames, {len(train_ds.windows)} with a {train_ds.prefix}+{train_ds.target}-frame window) / "
            f"{len(test_ds.sequences)} held-out ({len(test_ds.files)} files), {train_ds.rig.name} rig, "
            f"{train_ds.skeleton.num_joints} joints, {train_ds.fps:g} fps")


def _seed_clip(ds: LocomotionDataset) -> dict:
    """The first SEED_FRAMES frames of the training sequence whose average speed is closest to a walk, for the
    generation prefix."""
    best, best_d = None, np.inf
    for s in ds.sequences:
        if s.num_frames < SEED_FRAMES + 1:
            continue
        amp = float(np.hypot(s.features[:SEED_FRAMES, 2], s.features[:SEED_FRAMES, 3]).mean())
        d = abs(amp - SPEEDS["walk"])
        if d < best_d:
            best, best_d = s, d
    if best is None:
        best = max(ds.sequences, key=lambda s: s.num_frames)
    n = min(SEED_FRAMES, best.num_frames)
    return {"name": best.name, "rotations": np.round(best.rotations[:n], 6).tolist(),
            "features": np.round(best.features[:n], 6).tolist()}


def checkpoint_extra(train_ds: LocomotionDataset) -> dict:
    """What a locomotion checkpoint carries: frame rate, rig, window sizes, the skeleton (FK and BVH output), and
    a seed clip (the generation prefix)."""
    sk = train_ds.skeleton
    return {"fps": float(train_ds.fps), "rig": train_ds.rig.name, "prefix": int(train_ds.prefix),
            "target": int(train_ds.target),
            "skeleton": {"names": list(sk.names), "parents": [int(p) for p in sk.parents],
                         "offsets": np.asarray(sk.offsets, np.float64).tolist(),
                         "joints_left": [int(j) for j in sk.joints_left],
                         "joints_right": [int(j) for j in sk.joints_right]},
            "seed_clip": _seed_clip(train_ds)}


def check_checkpoint(model_config: Mapping, path) -> None:
    """Refuse (BadInputError) a checkpoint without :func:`checkpoint_extra`'s skeleton."""
    from refimpl.errors import BadInputError
    if "skeleton" not in model_config or "rig" not in model_config:
        raise BadInputError(f"{path}: the checkpoint has no locomotion skeleton/rig; train it with `refimpl train`")


def trained_fields(model_config: Mapping, config) -> dict:
    """The :class:`~refimpl.registry.TrainedModel` fields of this task: the frame rate."""
    return {"fps": float(model_config.get("fps", FPS))}


def rig_of(model_config: Mapping) -> LocomotionRig:
    return {r.name: r for r in (CMU_RIG, BANDAI_NAMCO_RIG)}[model_config["rig"]]


def onnx_method(runtime) -> Callable:
    """``f(inputs (B, P + T, F)) -> (rotations (B, T, J, 4), translations (B, T, 2))`` running an exported
    long-term pose network step by step (``runtime.rollout``)."""
    def network_onnx(inputs, prefix: int):
        return runtime.rollout(np.asarray(inputs, np.float32), int(prefix))

    return network_onnx


def methods(networks: Mapping[str, Callable] | None = None, *, fps: float = FPS) -> dict:
    """``name -> f(inputs (B, P + T, F), prefix) -> (rotations (B, T, J, 4), translations (B, T, 2))``: the
    networks (free-running with the ground-truth controls), then the zero-velocity baseline."""
    return {**dict(networks or {}), "zero_velocity": zero_velocity}


def load_eval_data(data: str, model_config: Mapping, max_files: int = 0) -> LocomotionDataset:
    """The held-out :class:`LocomotionDataset` of ``--data`` (:func:`resolve_files`' test files) with the window
    sizes a checkpoint was trained with (``model_config["prefix"]``, ``["target"]``), for ``refimpl eval``.

    Raises
    ------
    BadInputError
        ``--data`` cannot be read, or its rig is not the checkpoint's.
    """
    from refimpl.errors import BadInputError
    kind, _, test = resolve_files(data)
    test = _evenly(test, int(max_files or 0))
    try:
        ds = build_dataset(kind, test, prefix=int(model_config.get("prefix", 30)),
                           target=int(model_config.get("target", 60)),
                           progress=lambda line: print(line, file=sys.stderr, flush=True))
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {data}: {exc}") from exc
    if model_config.get("rig") not in (None, ds.rig.name):
        raise BadInputError(f"--data {data}: a {ds.rig.name} rig, but the checkpoint was trained on the "
                            f"{model_config.get('rig')} rig")
    return ds


# ------------------------------------------------------------------------------------------------------------
# commands (spec/cli.md, spec/locomotion.md §8-§9)
# ------------------------------------------------------------------------------------------------------------

def _say(*parts) -> None:
    print(*parts, flush=True)


def eval_command(args, model) -> int:
    """``refimpl eval`` for the long-term pose network: free-running position and velocity error over the held-out
    windows (QN §4.4.2; spec/locomotion.md §8), against zero-velocity."""
    if model is None or model.spec.name != "quaternet-long":
        raise UsageError("locomotion: evaluation needs --checkpoint of a quaternet-long model (the pace network's "
                         "held-out L1 is its loss_val.csv)")
    _say(f"reading {args.data} ...")
    data = load_eval_data(args.data, model.extra)
    extra = model.spec.extra_methods  # e.g. a DQ model's positions read from the DQs
    nets = {**network_methods(model), **(extra(model) if extra else {})}
    results = evaluate(data, methods(nets))
    _say(f"held-out windows: {next(iter(results.values()))['windows']} of {data.prefix} + {data.target} frames "
         f"({len(data.files)} files); error in QuaterNet units (1 unit = 5.6444 cm)")
    _say(format_results(results))
    if args.json:
        serial = {n: {k: (np.asarray(v).tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()}
                  for n, r in results.items()}
        atomic_write_text(args.json, json.dumps(serial, indent=1) + "\n")
        _say(f"results          {args.json}")
    return 0


def walk_options(path_text: str, speed_text: str, seconds) -> tuple:
    """``(path Spline, speed, frames)`` of ``--path``, ``--speed``, ``--seconds``, checked before any work: a value
    outside :mod:`refimpl.bounds` is a ``UsageError`` (exit 2), a ``--path`` CSV file that is missing or malformed a
    ``BadInputError`` naming the file and line (exit 3)."""
    try:
        speed = parse_speed(speed_text)
        seconds = check_number(seconds, "--seconds", "seconds")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if Path(path_text).suffix.lower() == ".csv":
        p = existing_file(path_text)
        with reading(p):
            path = read_path_file(p)
    else:
        try:
            path = parse_path(path_text)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    return path, speed, int(round(seconds * FPS))


def walk_from_checkpoints(pose_model, pace_model, path_text: str, speed_text: str, seconds: float):
    """:func:`~refimpl.models.quaternet_long_walk.generate_walk` from two loaded
    :class:`~refimpl.registry.TrainedModel` (``quaternet-long`` and ``pace``)."""
    if pose_model.spec.name != "quaternet-long":
        raise UsageError(f"--checkpoint: expected a quaternet-long checkpoint, got {pose_model.spec.name!r}")
    if pace_model.spec.name != "pace":
        raise UsageError(f"--pace: expected a pace checkpoint, got {pace_model.spec.name!r}")
    path, speed, frames = walk_options(path_text, speed_text, seconds)
    if pose_model.config.output not in ("quaternion", "dual_quaternion"):
        raise UsageError(f"--checkpoint: generation needs a quaternion or dual-quaternion model, got output = "
                         f"{pose_model.config.output!r} (an ablation)")
    seed = pose_model.extra["seed_clip"]
    return generate_walk(pose_model.params, pose_model.config.network(), pace_model.params, pace_model.config,
                         skeleton_of(pose_model.extra), np.asarray(seed["rotations"]), np.asarray(seed["features"]),
                         path, speed, frames, dq_scale=getattr(pose_model.config, "dq_scale", 1.0), fps=FPS)


def describe_walk(walk) -> str:
    """``"300 frames at 30 fps (10.0 s), 26 joints, centimetres; root travelled 11.6 m along a 18.8 m path"``
    (the BVH of :func:`~refimpl.tasks.locomotion_generate.write_outputs` is in centimetres)."""
    m = walk.motion
    dist = np.linalg.norm(np.diff(m.root_positions[:, [0, 2]], axis=0), axis=-1).sum() * QUATERNET_UNIT_CM / 100
    return (f"{m.num_frames} frames at {FPS:g} fps ({m.num_frames / FPS:.1f} s), {m.num_joints} joints, "
            f"centimetres; root travelled {dist:.1f} m along a {walk.path.length * QUATERNET_UNIT_CM / 100:.1f} m path")


def skating_phrase(skate: dict) -> str:
    """``foot skating 3.2 cm/s in contact (41 % of foot-frames)`` of a :func:`foot_skating` result, or, when no
    foot-frame is in contact (a briefly trained network's feet may never rest), ``foot skating: no foot in contact``
    (not ``nan cm/s``)."""
    if not math.isfinite(skate["speed_cm_s"]):
        return "foot skating: no foot in contact (no foot-frame within 2 cm of its lowest height)"
    return (f"foot skating {skate['speed_cm_s']:.1f} cm/s in contact ({100 * skate['contact_fraction']:.0f} % of "
            f"foot-frames)")


def short_walk_warning(walk, seconds: float, given: bool = True) -> str | None:
    """The warning when an open path ended before ``seconds`` (the motion is shorter than asked), else None;
    ``given=False``: ``seconds`` is the default length, not a ``--seconds`` of the command line."""
    asked, n = int(round(seconds * FPS)), walk.motion.num_frames
    if n >= asked:
        return None
    what = f"--seconds {seconds:g} asked for" if given else f"the default length ({seconds:g} s) is"
    return f"the path ends after {n / FPS:.1f} s at this speed; {what} {asked} frames, the motion has {n}"


def generate_command(args, model) -> int:
    """``refimpl generate --model quaternet-long``: load the two checkpoints, walk the path, write BVH / pictures /
    controls, and print the stability numbers (spec/cli.md, spec/locomotion.md §9)."""
    if args.model is None:  # the task came from a checkpoint or exported models: both networks are needed
        raise UsageError("a quaternet-long / pace checkpoint: pass --model quaternet-long --checkpoint POSE.npz "
                         "--pace PACE.npz [--path ...]")
    if not args.checkpoint or not args.pace:
        raise UsageError("--model quaternet-long needs --checkpoint POSE.npz and --pace PACE.npz")
    if args.backend != "numpy":
        raise UsageError("--model quaternet-long runs in NumPy (the exported models walk a path with `python -m "
                         "deploy run ONNX_DIR PATH walk.bvh --pace PACE_DIR`)")
    walk_options(args.path, args.speed, args.seconds)  # option values and the path file before any work
    pose_model, pace_model = load_trained(args.checkpoint), load_trained(args.pace)
    try:
        walk = walk_from_checkpoints(pose_model, pace_model, args.path, args.speed, args.seconds)
    except ValueError as exc:  # the path cannot be walked (too short for a frame): a bad file (CSV) or option
        from refimpl.errors import BadInputError
        raise (BadInputError if str(args.path).lower().endswith(".csv") else UsageError)(
            f"--path {args.path}: {exc}") from None
    out = args.out or "walk.bvh"
    if not str(out).lower().endswith(".bvh"):
        raise UsageError(f"--out {out}: expected a .bvh file name")
    m = walk.motion
    write_outputs(walk, bvh=out, gif=args.gif, png=args.png, controls=args.controls,
                  title=f"quaternet-long, {args.path}, {args.speed}")
    warning = short_walk_warning(walk, args.seconds)
    if warning:  # an open path ended before --seconds: say so (the motion is shorter)
        print(f"refimpl generate: warning: {warning}", file=sys.stderr, flush=True)
    rig = rig_of(pose_model.extra)
    feet = [m.skeleton.index(rig.left_foot), m.skeleton.index(rig.right_foot)]
    skate = foot_skating(m.positions(), feet)
    face = facing_of(walk, rig)
    agree = np.sum(face * walk.controls[:, 4:6], axis=-1)
    _say(f"wrote {out}: {describe_walk(walk)}")
    _say(f"facing vs the pace network: median angle {math.degrees(np.median(np.arccos(np.clip(agree, -1, 1)))):.1f}°;"
        f" {skating_phrase(skate)}; bone-length drift {bone_length_drift(m) * QUATERNET_UNIT_CM:.2g} cm")
    if walk.dq_positions is not None:  # dual quaternions: the positions the network's losses saw (Eq. 8)
        gap = np.linalg.norm(walk.dq_positions - m.positions(), axis=-1) * QUATERNET_UNIT_CM
        drift = dq_bone_length_drift(walk.dq_positions, m.skeleton)
        dq_skate = foot_skating(walk.dq_positions, feet)
        _say(f"dual quaternions: positions read from the DQs (Eq. 8) vs FK of the decoded rotations (Eq. 12): mean "
            f"{gap.mean():.2f} cm, max {gap.max():.2f} cm; DQ bone-length drift mean {drift['mean'] * QUATERNET_UNIT_CM:.2f}"
            f" cm ({100 * drift['mean_relative']:.1f} %), max {drift['max'] * QUATERNET_UNIT_CM:.2f} cm (not enforced "
            f"by the representation); of the DQ positions: {skating_phrase(dq_skate)}")
    for f in (args.gif, args.png, args.controls):
        if f:
            _say(f"wrote {f}")
    return 0


def export_options(args) -> dict:
    """The exporter's options of ``refimpl export``: ``T`` (``--transition-length``, when given)."""
    return export_length(args)


def verify_inputs(args, model) -> tuple:
    """``((), {"seed": ...})``: the recipe draws its own random inputs (``--seed``) for ``refimpl export``'s
    check."""
    return (), {"seed": args.seed}
