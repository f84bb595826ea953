"""The transition task (QTG's; spec/qtg.md §7-§9, spec/cli.md): 2 past + 2 target poses -> the T frames between.

Everything the application layer needs about this task, and nothing about a particular network:

* data options: :func:`add_train_options` (``--transition-length``), :func:`resolve_data` (``--data``: the
  embedded sample, ``../shared/data``, a folder, a file), :func:`source_for_file`, :func:`build_datasets`,
  :func:`train_datasets`; the checkpoint facts the task needs (:func:`checkpoint_extra`, :func:`check_checkpoint`);
* baselines and protocol: :func:`methods` (the networks' methods, then inertialisation and interpolation from
  :mod:`refimpl.protocols.transition_baselines`), :func:`evaluate` (:func:`refimpl.protocols.transition_metrics.evaluate_methods`, the paper's metric),
  :func:`print_results` / :func:`write_results` (table, per-frame curve, CSV, JSON);
* generation: :func:`make_transition` between two clips in world coordinates, :func:`with_end_sites` for BVH
  readers, :func:`render_transition`, :func:`clip_for`, :func:`random_context` (context poses for numerical checks).

The building blocks live below: windows, sources and datasets in :mod:`refimpl.protocols.transition`, the baselines in
:mod:`refimpl.protocols.transition_baselines`, the metric in :mod:`refimpl.protocols.transition_metrics`.

Shape legend: N windows, T transition frames, F frames of a clip, J joints, P pose size (3 + 4 J), B batch.
"""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any, Callable, Mapping

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.protocols.transition_baselines import method_registry
from refimpl.bvh import read_bvh_header
from refimpl.errors import BadInputError, UsageError, existing_file, file_error, reading
from refimpl.expmap import EXPMAP_LAYOUTS
from refimpl.protocols.transition_metrics import evaluate_methods, format_table
from refimpl.motion import Motion
from refimpl.bounds import bounded_int
from refimpl.quat import quat_conj, quat_from_axis_angle, quat_mul, quat_rotate
from refimpl.skeleton import Skeleton
from refimpl.protocols.transition import (CMU_22_JOINTS, SALSA_22_JOINTS, SAMPLE_DIR, TransitionSource,
                                 build_transition_datasets, declared_rate, heading_from_root, join_pose, load_source,
                                 make_windows, sample_sources, shared_sources, split_pose, window_to_world)
from refimpl.protocols.transition_join import JOIN_MODES, check_join, with_join
from refimpl.protocols.transition_quality import evaluate_quality, foot_joints, format_quality

__all__ = [
    "NAME", "add_train_options", "resolve_data", "source_for_file", "build_datasets", "train_datasets",
    "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint", "trained_fields", "onnx_method",
    "add_eval_options", "methods", "evaluate",
    "print_results", "write_results", "Transition", "make_transition", "with_end_sites", "render_transition",
    "clip_for", "random_context",
]

NAME = "transition"


def _say(*parts) -> None:
    print(*parts, flush=True)


# ----------------------------------------------------------------------------------------------------------------
# data
# ----------------------------------------------------------------------------------------------------------------

def add_train_options(parser) -> None:
    """The task's options of ``refimpl train`` (its data options are the command line's common ones)."""
    parser.add_argument("--transition-length", type=bounded_int("transition_length"), default=30,
                        help="T (default 30 = 1 s)")


def source_for_file(path, *, fps: float | None = None, label: str | None = None, frames=(0.0, 1.0)):
    """A :class:`~refimpl.protocols.transition.TransitionSource` for one BVH / exp-map file, its kind found from its joints.

    ``.txt`` files are CMU exp-map files (117 values per row, 120 fps unless ``fps``). ``.bvh`` files must have
    the CMU cgspeed joints (:data:`~refimpl.protocols.transition.CMU_22_JOINTS`) or the DAZ salsa joints
    (:data:`~refimpl.protocols.transition.SALSA_22_JOINTS`); their rate is the declared ``Frame Time`` unless ``fps``
    (the CMU salsa files declare 120 fps but are 60 fps).
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
    for kind, keep in (("cmu_bvh", CMU_22_JOINTS), ("salsa_bvh", SALSA_22_JOINTS)):
        if names.issuperset(keep):
            return TransitionSource(str(p), kind, float(fps or declared_rate(header.frame_time)), label, frames)
    missing = sorted(set(CMU_22_JOINTS) - names)
    raise BadInputError(f"{p}: skeleton not supported for transitions: needs the 22 CMU joints "
                        f"({', '.join(CMU_22_JOINTS[:4])}, ...) or the salsa ones; missing e.g. {missing[:5]}")


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


def build_datasets(data: str, T: int, stride: int, *, fps=None, test_fraction=0.2, test_stride=None):
    """Train and test :class:`~refimpl.protocols.transition.TransitionDataset` of ``2 + T + 2``-pose windows for ``--data``
    (:func:`resolve_data`, :func:`refimpl.protocols.transition.build_transition_datasets`)."""
    train_src, test_src = resolve_data(data, fps=fps, test_fraction=test_fraction)
    try:
        return build_transition_datasets(train_src, test_src, T=T, stride=stride, test_stride=test_stride)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {data}: {exc}") from exc


def train_datasets(args):
    """Train and held-out datasets of ``refimpl train``'s options (``--data``, ``--transition-length``, ...)."""
    return build_datasets(args.data, args.transition_length, args.stride, fps=args.fps,
                          test_fraction=args.test_fraction)


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
    """The :class:`~refimpl.registry.TrainedModel` fields of this task from a checkpoint's model config: root
    statistics, frame rate and T."""
    return {"root_mean": np.asarray(model_config["root_mean"], dtype=np.float64),
            "root_std": np.asarray(model_config["root_std"], dtype=np.float64),
            "fps": float(model_config.get("fps", 30.0)),
            "transition_length": int(model_config.get("transition_length", config.transition_length))}


def onnx_method(runtime) -> Callable:
    """``f(past, target, T) -> poses`` running an exported transition model's runtime (``runtime.transition``).

    The models standardise inside the graph, so ``f`` takes and returns raw poses like the NumPy methods; output
    quaternions are normalised to unit length.
    """
    def network_onnx(past, target, T):
        out = np.asarray(runtime.transition(np.asarray(past, np.float32), np.asarray(target, np.float32), int(T)),
                         dtype=np.float64)  # (B, T, P)
        root, quats = split_pose(out)
        quats = quats / np.maximum(np.linalg.norm(quats, axis=-1, keepdims=True), 1e-12)
        return join_pose(root, quats)

    return network_onnx


# ----------------------------------------------------------------------------------------------------------------
# baselines and protocol
# ----------------------------------------------------------------------------------------------------------------

def add_eval_options(group) -> None:
    """The task's options of ``refimpl eval``: ``--join``."""
    group.add_argument("--join", default="none", choices=JOIN_MODES,
                       help="inertialize: also evaluate each network with its joins inertialised (spec/qtg.md "
                            "7.4), as <name>+join beside the paper-faithful row (default none)")


def methods(networks: Mapping[str, Callable] | None = None, *, fps: float = 30.0, join: str = "none") -> dict:
    """``name -> f(past, target, T)``: the given networks' methods (in order; with ``join="inertialize"`` each
    followed by ``<name>+join``, :func:`refimpl.protocols.transition_join.with_join`), then both baselines
    (:func:`refimpl.protocols.transition_baselines.method_registry` with ``dt = 1 / fps``)."""
    out = {}
    for name, f in dict(networks or {}).items():
        out[name] = f
        if check_join(join) != "none":
            out[f"{name}+join"] = with_join(f, join, dt=1.0 / fps)
    return {**out, **method_registry(dt=1.0 / fps)}


def evaluate(test_ds, methods_by_name: Mapping[str, Callable]) -> dict:
    """The paper's protocol on ``test_ds`` (:func:`refimpl.protocols.transition_metrics.evaluate_methods`) and,
    under each method's ``"quality"``, the animator's measures
    (:func:`refimpl.protocols.transition_quality.evaluate_quality`: joins, foot skating, first and last frame, with
    the ground truth's numbers)."""
    results = evaluate_methods(test_ds, methods_by_name)
    for name, q in evaluate_quality(test_ds, methods_by_name).items():
        results[name]["quality"] = q
    return results


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
            return [conv(float(x)) for x in v]
        if isinstance(v, dict):
            return {k: conv(x) for k, x in v.items()}
        if isinstance(v, (np.floating, np.integer)):
            v = v.item()
        if isinstance(v, float) and not np.isfinite(v):
            return None  # e.g. skating without a contact: null, so that the file is strict JSON
        return v

    return json.dumps({k: conv(v) for k, v in results.items()}, indent=2, sort_keys=True, allow_nan=False) + "\n"


def _curve_table(results: Mapping[str, dict], frame_time: float) -> str:
    names = list(results)
    T = len(results[names[0]]["per_frame_cm"])
    head = ["frame", "ms"] + names
    rows = [head] + [[str(t + 1), f"{(t + 1) * frame_time * 1000:.0f}"]
                     + [f"{results[n]['per_frame_cm'][t]:.2f}" for n in names] for t in range(T)]
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in rows)


def _protocol_line(ds, model=None) -> str:
    labels = sorted({ds.sources[i].label for i in np.unique(ds.source_index)})
    return (f"protocol: {ds.num_windows} held-out windows ({', '.join(labels)}) from {len(ds.sources)} sources, "
            f"{ds.past} past + T = {ds.transition_length} + {ds.future} target poses at {ds.fps:g} fps, "
            "22 joints; error = mean over windows and joints of the Euclidean joint-position error (cm) per "
            "transition frame" + ("" if model is None else f"; network {model.spec.name} from {model.path}"))


def print_results(results: Mapping[str, dict], test_ds, model=None, *,
                  curve: bool = True) -> None:
    """Print :func:`refimpl.services.evaluate_model` results as the paper's comparison: protocol line, table,
    per-frame curve."""
    _say(_protocol_line(test_ds, model))
    _say("")
    _say("Mean joint-position error per joint per frame (cm), by motion category and at transition frames fK:")
    _say(format_table(results))
    if all("quality" in r for r in results.values()):
        _say("")
        _say("Joins (mean joint displacement into frame 1 and out of frame T), foot skating (horizontal speed of "
             "the foot joints in contact) and the error at the first and last frames:")
        _say(format_quality({k: r["quality"] for k, r in results.items()}))
    if curve:
        _say("")
        _say("Per-frame curve (cm):")
        _say(_curve_table(results, 1.0 / test_ds.fps))


def write_results(results: Mapping[str, dict], frame_time: float, *, json_path=None, csv_path=None) -> None:
    """Write :func:`refimpl.services.evaluate_model` results as JSON (everything) and / or CSV (the per-frame
    curves)."""
    if json_path:
        atomic_write_text(Path(json_path), _results_json(results), make_parents=True)
    if csv_path:
        atomic_write_text(Path(csv_path), _curve_csv(results, frame_time), make_parents=True)


# ----------------------------------------------------------------------------------------------------------------
# generation
# ----------------------------------------------------------------------------------------------------------------

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
    return heading_from_root(np.asarray(q_root, dtype=np.float64))


def _align_target(src_rot, src_pos, s, tgt_rot, tgt_pos, g, T):
    """Move and turn the target clip about the vertical so that it continues the source clip.

    The target's heading at frame ``g`` is made equal to the source's at ``s``, and its root is placed (in the
    horizontal plane) where the source root would be after ``T + 1`` frames at the mean of the source's
    velocity at ``s`` and the (turned) target's velocity at ``g``. Heights are kept.
    """
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
    the first one (:func:`refimpl.protocols.transition.make_windows` on the 4 frames), ``method`` generates the
    transition in that frame, and the result is moved back to the world (:func:`refimpl.protocols.transition.window_to_world`).

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
    gen_pos, gen_rot = window_to_world(pred, _heading(src_rot[s - 1, 0]), src_pos[s - 1])  # (T, 3), (T, J, 4)

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


def render_transition(tr: Transition, png=None, gif=None, title=None) -> list:
    """Draw a :class:`Transition` (against its ground truth when it has one) as a PNG strip and / or a GIF.

    The strip shows the frames on both sides of each join (:func:`refimpl.render_strip.join_frames`: last past,
    first generated, a middle one, last generated, first target), left and right limbs in two shades
    (:func:`refimpl.render_strip.limb_sides`), the feet's floor tracks
    (:func:`refimpl.protocols.transition_quality.foot_joints`) and a floor grid fixed in the world (spec/cli.md).
    """
    from refimpl.render import render_gif
    from refimpl.render_strip import join_frames, limb_sides, render_strip

    skel = tr.motion.skeleton
    parents = np.asarray(skel.parents)
    gt = (tr.truth if tr.truth is not None else tr.motion).positions()
    pred = tr.motion.positions() if tr.truth is not None else None
    labels = ("ground truth", tr.method) if pred is not None else (tr.method, "")
    sides = limb_sides(skel)
    written = []
    if png:
        frames = join_frames(tr.start, tr.stop, tr.motion.num_frames)
        written.append(render_strip(png, gt, parents, prediction=pred, frames=frames, highlight=(tr.start, tr.stop),
                                    labels=labels, title=title, frame_time=tr.motion.frame_time, sides=sides,
                                    feet=_feet(skel)))
        _say(f"wrote {png}")
    if gif:
        written.append(render_gif(gif, gt, parents, prediction=pred, fps=tr.motion.fps,
                                  highlight=(tr.start, tr.stop), labels=labels, title=title, sides=sides))
        _say(f"wrote {gif}")
    return written


def _feet(skel):
    try:
        return foot_joints(skel)
    except ValueError:  # a skeleton without foot joints: no tracks
        return None


def clip_for(path, model_fps: float, fps_override):
    """(skeleton, (rotations, root_positions)) of a file at the model's rate (phase 0 of the resampling)."""
    src = source_for_file(path, fps=fps_override)
    try:
        skel, clips = load_source(src, fps=model_fps)
    except (OSError, ValueError) as exc:
        raise file_error(path, exc) from exc
    return skel, clips[0], src


def random_context(model, rng, B: int):
    """Plausible raw context poses for a numerical check: root ~ N(mean, std), small random joint rotations."""
    J = (model.config.pose_size - 3) // 4
    root = model.root_mean + model.root_std * rng.standard_normal((B, 4, 3))  # (B, 4, 3)
    quats = quat_from_axis_angle(0.3 * rng.standard_normal((B, 4, J, 3)))  # (B, 4, J, 4)
    poses = join_pose(root, quats)
    return poses[:, :2], poses[:, 2:]
