"""The synthesis task of the application (acRNN on the CMU salsa takes): ``refimpl train/eval/generate``'s
options, data resolution, checkpoint fields, methods, results output and seed continuation (spec/acrnn.md §8,
spec/architecture.md §tasks). The paper's data, windows, seeds, metrics and evaluation are in
:mod:`refimpl.protocols.synthesis`.

Shape legend: T frames, F frame size, B batch, S seed frames, N generated frames.
"""
from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Mapping

import numpy as np

from refimpl.options import export_length
from refimpl.errors import UsageError
from refimpl.protocols.synthesis import CHECKPOINT_SCHEMA  # the task's checkpoint schema (task interface)
from refimpl.protocols.synthesis import VARIANTS, count_windows
from refimpl.protocols.synthesis import (ACCELERATION_FRAMES, DEFAULT_ROW, END_SITE_REPRESENTATIONS, FPS, MAX_SEEDS,
                                         SALSA_TEST, SALSA_TRAIN, SAMPLE_TEST, SAMPLE_TRAIN, SEED_LENGTH, SEED_STRIDE,
                                         TABLE1_ROWS, SynthesisData, evaluate_generator, frames_to_motion,
                                         in_source_units, load_salsa_motion, load_synthesis_data, motion_to_frames,
                                         skeleton_of)
from refimpl.registry import require_source
from refimpl.services import checkpoint_for, network_methods
from refimpl.skeleton import Skeleton
from refimpl.tasks.transition_generate import with_end_sites

__all__ = [
    "CHECKPOINT_SCHEMA", "NAME", "EVAL_SUMMARY", "GENERATE_USAGE", "NPSS_REPORTED", "SAMPLE_SALSA", "TrainingSet",
    "add_train_options", "add_eval_options", "add_export_options", "add_generate_options", "resolve_data",
    "train_datasets", "import_datasets", "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint",
    "trained_fields", "onnx_method", "methods", "evaluate", "load_eval_data", "print_results", "write_results",
    "random_inputs", "continue_seed", "eval_command", "generate_command", "export_options", "verify_inputs",
]

# ----------------------------------------------------------------------------------------------------------------
# the task interface (spec/architecture.md §the application; spec/acrnn.md §8): ``refimpl train/eval/generate``
# ----------------------------------------------------------------------------------------------------------------

NAME = "synthesis"
EVAL_SUMMARY = ("synthesis (acrnn): the dual-quaternion paper's Table 1 on the salsa test takes (Euclidean error, "
                "NPSS, acceleration), against holding the last seed frame")
GENERATE_USAGE = "refimpl generate --checkpoint CKPT --source FILE [...]  (synthesis: acrnn continues a seed)"

#: The NPSS the table shows first: ``"real"`` (``P = (Re X)²``, LaFAN1's fast_npss, which the dual-quaternion
#: paper's evaluation code used for its Table 1); ``"power"`` (``|X|²``, Gopalakrishnan et al.'s original) is
#: printed beside it in brackets (spec/acrnn.md §6).
NPSS_REPORTED = "real"

#: The embedded salsa sample (tests and smoke runs).
SAMPLE_SALSA = Path(__file__).resolve().parent.parent / "data" / "sample" / "salsa"


def _say(*parts) -> None:
    print(*parts, flush=True)


@dataclasses.dataclass(frozen=True, eq=False)
class TrainingSet:
    """What ``refimpl train`` trains on: the data, the Table 1 row and its loss weights, the window length.

    Attributes
    ----------
    data : SynthesisData
    row : str
        Key of :data:`TABLE1_ROWS` (``--representation``).
    weights : dict or None
        ``--losses`` override of the row's loss weights (the ablation), None = the row's.
    window_length : int
        T, predicted frames per training window (100).
    motions : tuple of Motion
        With ``augment``: the training takes at 30 fps (each parity), from which the windows are cut, turned to a
        random heading (:func:`refimpl.augment.random_heading_windows`) and encoded per batch. Else empty.
    augment : bool
        ``--augment-heading``: the published trainer's random heading per window (spec/acrnn.md §1.1).
    """

    data: SynthesisData
    row: str
    weights: dict | None = None
    window_length: int = 100
    motions: tuple = ()
    augment: bool = False

    @property
    def variant(self) -> str:
        return TABLE1_ROWS[self.row]


def _parse_losses(text: str | None) -> dict | None:
    from refimpl.errors import UsageError

    if not text:
        return None
    out = {}
    for item in text.split(","):
        key, sep, value = item.partition("=")
        try:
            out[key.strip()] = float(value) if sep else 1.0
        except ValueError:
            raise UsageError(f"--losses {text!r}: expected NAME=WEIGHT,... (e.g. mse=1,pos=0.333)") from None
    return out


def add_train_options(parser) -> None:
    """The task's options of ``refimpl train``: ``--window-length`` and ``--losses`` (loss-weight override)."""
    from refimpl.bounds import bounded_int

    parser.add_argument("--window-length", type=bounded_int("window"), default=100,
                        help="synthesis: predicted frames per training window (default 100, acRNN)")
    parser.add_argument("--losses", default=None, metavar="NAME=W,...",
                        help="synthesis: override the row's loss weights, e.g. mse=1,reg=0.01,pos=0.333 "
                             "(dual quaternions: mse reg pos offset quat quat_current; quaternions: mse quat fk reg)")
    parser.add_argument("--augment-heading", action="store_true",
                        help="synthesis: turn every training window to a random heading about the vertical (the "
                             "published acRNN trainer; spec/acrnn.md §1.1)")
    parser.add_argument("--parities", type=int, default=1, choices=(1, 2),
                        help="synthesis: 2 = train on both parities of the 60 fps frames (the published trainer); "
                             "default 1 (frames 0, 2, 4, ...)")
    parser.add_argument("--raw-frames", action="store_true",
                        help="synthesis: no per-feature standardisation (mean 0, std 1; the published trainer's raw "
                             "metres) instead of the dual-quaternion paper's training mean/std")


def add_eval_options(parser) -> None:
    """The task's options of ``refimpl eval``: none."""


def add_export_options(parser) -> None:
    """The task's options of ``refimpl export``: none."""


def add_generate_options(parser) -> None:
    """The task's options of ``refimpl generate``: none (``--source``, ``--source-frame`` (first seed frame,
    default 1: frame 0 is the reference T-pose), ``--length`` (default 300) are common)."""


def resolve_data(data: str) -> tuple[Path, tuple, tuple]:
    """``--data`` -> (folder, training takes, test takes): ``sample`` = the embedded salsa sample (take 01 trains,
    16 tests); a folder holding the CMU salsa takes (``../shared/data/acrnn_cmu_salsa`` or ``../shared/data``)."""
    from refimpl.errors import BadInputError

    if data == "sample":
        return SAMPLE_SALSA, SAMPLE_TRAIN, SAMPLE_TEST
    root = Path(data)
    if (root / "acrnn_cmu_salsa").is_dir():
        root = root / "acrnn_cmu_salsa"
    missing = [n for n in (*SALSA_TRAIN, *SALSA_TEST) if not (root / f"{n}.bvh").is_file()]
    if missing:
        raise BadInputError(f"--data {data}: expected the CMU salsa takes "
                            f"{', '.join(n + '.bvh' for n in (*SALSA_TRAIN, *SALSA_TEST))}; missing {missing}")
    return root, SALSA_TRAIN, SALSA_TEST


def train_datasets(args):
    """(:class:`TrainingSet`, :class:`SynthesisData`) for ``refimpl train``'s options."""
    from refimpl.errors import BadInputError, UsageError

    row = args.representation or DEFAULT_ROW
    if row not in TABLE1_ROWS:
        raise UsageError(f"--representation {row!r}: expected one of {list(TABLE1_ROWS)}")
    folder, train, test = resolve_data(args.data)
    parities, augment = int(getattr(args, "parities", 1)), bool(getattr(args, "augment_heading", False))
    representation = VARIANTS[TABLE1_ROWS[row]].representation
    try:
        data = load_synthesis_data(representation, folder, train, test, parities=parities,
                                   standardise=not getattr(args, "raw_frames", False))
        keep = representation in END_SITE_REPRESENTATIONS
        motions = tuple(load_salsa_motion(folder / f"{n}.bvh", phase=p, end_sites=keep) for p in range(parities)
                        for n in train) if augment else ()
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {args.data}: {exc}") from exc
    length = int(getattr(args, "window_length", 100))
    if min(len(s) for s in data.train) < length + 1:
        raise UsageError(f"--window-length {length}: the shortest training take has "
                         f"{min(len(s) for s in data.train)} frames")
    return TrainingSet(data, row, _parse_losses(getattr(args, "losses", None)), length, motions, augment), data


def import_datasets(args):
    """:func:`train_datasets` (``refimpl import``): a checkpoint stores the feature statistics of every training
    take, so the whole training side is needed (the salsa takes: a few seconds)."""
    return train_datasets(args)


def num_examples(dataset) -> int:
    """Training windows (every start of a ``T + 1``-frame window in every take; batches are drawn with
    :func:`sample_windows`, so an epoch is nominal)."""
    return count_windows(dataset.data.train, dataset.window_length)


def describe_data(train_ds, test_ds) -> str:
    """``"6 training takes (6172 frames) / 2 test takes (1678 frames), dual_quaternions F = 347 at 30 fps"``."""
    d = train_ds.data
    return (f"{len(d.train)} training takes ({sum(len(s) for s in d.train)} frames) / {len(d.test)} test takes "
            f"({sum(len(s) for s in d.test)} frames), row {train_ds.row} ({d.representation}, F = {d.frame_size}) "
            f"at {FPS} fps, windows of {train_ds.window_length} + 1 frames")


def checkpoint_extra(train_ds) -> dict:
    """What an acRNN checkpoint stores beside the network config: the feature statistics, the data
    representation, the Table 1 row and its loss weights, the window length and the skeleton (for BVH output)."""
    d = train_ds.data
    sk = d.skeleton
    weights = dict(VARIANTS[train_ds.variant].weights if train_ds.weights is None else train_ds.weights)
    return {"mean": [float(v) for v in d.mean], "std": [float(v) for v in d.std], "fps": float(FPS),
            "data_representation": d.representation, "variant": train_ds.variant, "row": train_ds.row,
            "loss_weights": weights, "window_length": int(train_ds.window_length),
            "augment_heading": bool(train_ds.augment), "standardised": bool(d.standardised), "parities": d.parities,
            "train_takes": list(d.train_names), "test_takes": list(d.test_names),
            "skeleton": {"parents": [int(p) for p in sk.parents], "names": list(sk.names),
                         "offsets": [[float(v) for v in o] for o in sk.offsets]}}


def check_checkpoint(model_config: Mapping, path) -> None:
    """Refuse (BadInputError) a checkpoint without :func:`checkpoint_extra`'s fields."""
    from refimpl.errors import BadInputError

    missing = [k for k in ("mean", "std", "data_representation", "skeleton", "variant") if k not in model_config]
    if missing:
        raise BadInputError(f"{path}: the synthesis checkpoint lacks {missing}; train it with `refimpl train`")


def trained_fields(model_config: Mapping, config) -> dict:
    """The :class:`~refimpl.registry.TrainedModel` fields of this task: the frame rate (the rest is in ``extra``)."""
    return {"fps": float(model_config.get("fps", FPS))}


def onnx_method(runtime):
    """``f(seed (B, S, F), n) -> (B, n, F)`` raw frames, running an exported acRNN generator / step loop."""
    def network_onnx(seed, n):
        return np.asarray(runtime.generate(np.asarray(seed, np.float32), int(n)), dtype=np.float64)

    return network_onnx


def _hold_last(seed, n):
    """Baseline: the last seed frame repeated (a frozen pose)."""
    s = np.asarray(seed, dtype=np.float64)
    return np.repeat(s[:, -1:], int(n), axis=1)


def methods(networks: Mapping | None = None, *, fps: float = FPS) -> dict:
    """``name -> f(seed (B, S, F), n) -> (B, n, F)`` on raw frames: the networks, then the ``hold`` baseline."""
    return {**dict(networks or {}), "hold": _hold_last}


def evaluate(test_ds: SynthesisData, methods_by_name: Mapping, max_seeds: int = MAX_SEEDS, progress=None) -> dict:
    """The protocol (:func:`evaluate_generator`) for each method on raw frames: ``{name: result}``;
    ``progress(line)``, when given, hears each method's start and end and every ~5 s of its seeds."""
    out = {}
    for k, (name, f) in enumerate(methods_by_name.items(), 1):
        def gen(seed, n, f=f):
            return test_ds.standardise(f(test_ds.destandardise(seed), n))
        t0 = time.perf_counter()
        if progress is not None:
            progress(f"evaluating {name} ({k} of {len(methods_by_name)}) ...")
        out[name] = evaluate_generator(gen, test_ds, max_seeds=max_seeds,
                                       progress=None if progress is None else (lambda line, n=name:
                                                                              progress(f"  {n}: {line}")))
        if progress is not None:
            progress(f"  {name}: {out[name]['num_seeds']} seeds in {time.perf_counter() - t0:.1f} s")
    return out


def load_eval_data(data: str, model_config: Mapping) -> SynthesisData:
    """The test takes of ``--data`` in the model's representation, standardised with the model's statistics."""
    from refimpl.errors import BadInputError

    folder, train, test = resolve_data(data)
    try:
        d = load_synthesis_data(model_config["data_representation"], folder, train, test)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {data}: {exc}") from exc
    mean, std = np.asarray(model_config["mean"]), np.asarray(model_config["std"])
    if mean.shape != d.mean.shape:
        raise BadInputError(f"--data {data}: frames of {d.mean.size} values, the model's have {mean.size}")
    return dataclasses.replace(d, mean=mean, std=std)


def print_results(results: Mapping, test_ds: SynthesisData, model=None) -> None:
    """The table in the shape of the paper's Table 1 (Euclidean error in cm at each horizon, NPSS, mean
    acceleration against the data's)."""
    first = next(iter(results.values()))
    hz = list(first["horizons"])
    _say(f"protocol: {first['num_seeds']} seeds of {SEED_LENGTH} frames (stride {SEED_STRIDE}) over the test takes "
         f"{', '.join(test_ds.test_names)} at {FPS} fps; Euclidean joint error with the root zeroed (cm); NPSS "
         f"'{NPSS_REPORTED}' (the DQ paper's evaluation code; 'power' = the original in brackets); acceleration "
         f"over {ACCELERATION_FRAMES} frames (m/frame², data's in brackets)"
         + ("" if model is None else f"; network from {model.path}"))
    head = ["method"] + [f"E {ms:g}ms" for ms in hz] + [f"NPSS {ms:g}ms" for ms in hz] + ["accel"]
    rows = [head]
    for name, r in results.items():
        h = r["horizons"]
        rows.append([name] + [f"{100 * h[ms]['euclidean']:.2f}" for ms in hz]
                    + [f"{h[ms]['npss_' + NPSS_REPORTED]:.3f} ({h[ms]['npss_power']:.3f})" for ms in hz]
                    + [f"{r['acceleration']['pred']:.3g} ({r['acceleration']['gt']:.3g})"])
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    for row in rows:
        _say("  ".join(c.rjust(w) for c, w in zip(row, widths)))


def write_results(results: Mapping, json_path) -> None:
    """Write the results as JSON."""
    import json

    from refimpl.atomic import atomic_write_text

    def conv(v):
        if isinstance(v, dict):
            return {str(k): conv(x) for k, x in v.items()}
        if isinstance(v, (np.floating, np.integer)):
            return v.item()
        if isinstance(v, np.ndarray):
            return v.tolist()
        return v

    atomic_write_text(Path(json_path), json.dumps(conv(results), indent=2, sort_keys=True) + "\n", make_parents=True)


def random_inputs(model, rng: np.random.Generator, batch: int = 2, seed_length: int = SEED_LENGTH):
    """Plausible raw seed frames ``(B, S, F)`` for a numerical check: the model's mean plus noise of its std."""
    mean, std = np.asarray(model.extra["mean"]), np.asarray(model.extra["std"])
    return (mean + std * rng.standard_normal((batch, seed_length, mean.size)),)


def continue_seed(method, model_config: Mapping, path, start: int, num_frames: int, *,
                  option: str = "--source-frame") -> tuple:
    """Seed frames ``[start, start + 10)`` of a salsa BVH at 30 fps continued by ``method`` for ``num_frames``
    (``option``: the command's name of ``start``, for its message; ``python -m deploy run`` calls it ``--start``).

    Returns
    -------
    motion : Motion
        Seed + generated frames (hip starting where the seed starts), the model's skeleton.
    seed_frames : int
        How many of its frames are the seed (10).
    """
    from refimpl.errors import BadInputError, UsageError

    rep = model_config["data_representation"]
    ends = rep in END_SITE_REPRESENTATIONS   # the published positional frame keeps the End Sites as joints
    try:
        motion = load_salsa_motion(path, end_sites=ends)
        frames = motion_to_frames(rep, motion)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"{path}: {exc}") from exc
    if frames.shape[1] != len(model_config["mean"]):
        raise BadInputError(f"{path}: frames of {frames.shape[1]} values, the model reads {len(model_config['mean'])}")
    if len(frames) < SEED_LENGTH:
        raise BadInputError(f"{path}: too short: {len(frames)} frames at 30 fps, a seed needs {SEED_LENGTH}")
    if not 0 <= start <= len(frames) - SEED_LENGTH:
        raise UsageError(f"{option} must lie in [0, {len(frames) - SEED_LENGTH}] (the first of {SEED_LENGTH} seed "
                         f"frames of {len(frames)} at 30 fps), got {start}")
    seed = frames[start:start + SEED_LENGTH]
    gen = np.asarray(method(seed[None], num_frames), dtype=np.float64)[0]           # (N, F)
    allf = np.concatenate([seed, gen])
    root0 = motion.root_positions[start]
    skel = skeleton_of(model_config)
    if ends:  # its leaves are the file's End Sites: written back as End Sites
        skel = Skeleton(skel.parents, skel.offsets, skel.names,
                        end_sites=[j for j in range(skel.num_joints) if not skel.children[j]])
    m = frames_to_motion(rep, skel, allf, start=(root0[0], root0[2]), name=Path(path).stem)
    return m, SEED_LENGTH


# ----------------------------------------------------------------------------------------------------------------
# commands (spec/cli.md, spec/acrnn.md §8)
# ----------------------------------------------------------------------------------------------------------------

def eval_command(args, model) -> int:
    """``refimpl eval`` for a synthesis model (acRNN): Table 1's metrics on the test takes (spec/acrnn.md §8)."""
    if model is None:
        raise UsageError("--model acrnn: evaluation needs --checkpoint (the statistics and the representation)")
    _say(f"reading {args.data} ...")
    data = load_eval_data(args.data, model.extra)
    seen = sorted(set(data.test_names) & set(model.extra.get("train_takes") or ()))
    if seen:
        print(f"refimpl eval: warning: take(s) {', '.join(seen)} of --data {args.data} were training takes of "
              f"{args.checkpoint} (trained on {', '.join(model.extra.get('train_takes'))}): these scores are not "
              "held-out (pass --data with the model's own test takes)", file=sys.stderr, flush=True)
    results = evaluate(data, methods(network_methods(model, onnx_dir=args.onnx), fps=data.fps),
                       progress=lambda line: print(line, file=sys.stderr, flush=True))  # a minute or more
    print_results(results, data, model)
    if args.json:
        write_results(results, args.json)
        _say(f"results          {args.json}")
    return 0


def generate_command(args, model) -> int:
    """``refimpl generate --model acrnn``: seed frames of ``--source`` continued for ``--length`` frames, BVH out."""
    from refimpl.bvh_write import write_bvh

    require_source(args)
    if model is None and not args.checkpoint:
        raise UsageError("--model acrnn needs --checkpoint (with --backend onnx too: skeleton and statistics)")
    model = checkpoint_for(NAME, model, args.checkpoint)
    if args.backend == "onnx" and not args.onnx:
        raise UsageError("--backend onnx needs --onnx DIR (the folder written by `refimpl export`)")
    networks = network_methods(None if args.backend == "onnx" else model,
                               onnx_dir=args.onnx if args.backend == "onnx" else None, expect=model)
    method = next(iter(networks.values()))
    n = args.length or 300
    out = args.out or "synthesis.bvh"
    start = 1 if args.source_frame is None else args.source_frame  # frame 0 of a CMU file: its reference T-pose
    motion, seed_frames = continue_seed(method, model.extra, args.source, start, n)
    write_bvh(out, with_end_sites(in_source_units(motion)))   # the take's centimetres
    _say(f"wrote {out}: {seed_frames} seed frames of {args.source} (from frame {start} at "
         f"30 fps) + {n} generated frames ({model.extra.get('row')}, {args.backend}), {motion.num_joints} joints, "
         "centimetres (the take's units)")
    if args.png or args.gif:
        from refimpl.progress import stderr_line
        from refimpl.render import render_gif
        from refimpl.render_strip import limb_sides, render_strip

        pos = motion.positions()
        parents = np.asarray(motion.skeleton.parents)
        labels = (f"acrnn {model.extra.get('row')}", "")
        sides = limb_sides(motion.skeleton)  # the one left / right rule of every model's pictures
        title = (f"acrnn {model.extra.get('row')}: {seed_frames} seed frames of {Path(args.source).name} "
                 f"(green) + {n} generated")
        if args.png:
            render_strip(args.png, pos, parents, highlight=(seed_frames, motion.num_frames), labels=labels,
                         frame_time=motion.frame_time, title=title, sides=sides)
            _say(f"wrote {args.png}")
        if args.gif:
            render_gif(args.gif, pos, parents, fps=motion.fps, highlight=(seed_frames, motion.num_frames),
                       progress=stderr_line, labels=labels, title=title, sides=sides)
            _say(f"wrote {args.gif}")
    return 0


def export_options(args) -> dict:
    """The exporter's options of ``refimpl export``: ``T`` (``--transition-length``, when given)."""
    return export_length(args)


def verify_inputs(args, model) -> tuple:
    """``(random_inputs(...), {})``: random seeds in the data's range (:func:`random_inputs`, ``--seed``) for
    ``refimpl export``'s check."""
    return random_inputs(model, np.random.default_rng(args.seed)), {}
