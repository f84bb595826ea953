"""QTG's transition windows from the Bandai Namco locomotion set (spec/qtg.md §8.4).

``../shared/data/bandai_namco_locomotion`` (830 BVH takes at 30 fps: walk, walk-turn-left, walk-turn-right, run,
in six styles) is the nearest available stand-in for the Holden et al. locomotion set that QTG was trained on.
This module turns it into :class:`~refimpl.protocols.transition.TransitionDataset` windows built exactly as the CMU ones
(:func:`refimpl.protocols.transition.build_transition_datasets`: ``2 + T + 2`` poses, root relative to the first pose,
root translation z-normalised with the training windows' statistics), with:

* the reader :func:`load_bandai_namco_source` (the locomotion task's :func:`~refimpl.protocols.locomotion_data.load_bandai_namco`,
  then the 21 joints of :data:`~refimpl.protocols.locomotion_data.BANDAI_NAMCO_RIG` in centimetres — this rig has 21
  joints, not the paper's 22: ``Hips``, 2 spine, neck, head, 2 × 4 arm and 2 × 4 leg joints; the static
  ``joint_Root`` carries no motion and is dropped, P = 3 + 4·21 = 87);
* the split by whole takes :func:`bandai_namco_sources` (the locomotion task's
  :func:`~refimpl.protocols.locomotion_data.bandai_namco_split`: take ids ending in 1 held out, every content × style in
  both sides);
* labels for the evaluation: :func:`take_facts` (content, style, id of a take) and :func:`window_kinds`
  (the transition a window asks for, from its own root motion: ``walk->run``, ``stand->walk``, ``walk turn``...).

Shape legend: N windows, W window length (T + 4), F frames of a clip, J joints (21), P pose size (87).
"""
from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from refimpl.rigs import heading_from_root, subset_22
from refimpl.protocols.locomotion_data import BANDAI_NAMCO_RIG, bandai_namco_split, load_bandai_namco
from refimpl.protocols.transition import TransitionSource, build_transition_datasets, split_pose
from refimpl.protocols.transition_cache import cached_loader
from refimpl.protocols.transition_metrics import joint_position_errors, predict_transitions

__all__ = ["KIND", "FOLDER", "JOINTS", "TakeFacts", "take_facts", "find_takes", "is_bandai_namco_folder",
           "bandai_namco_sources", "load_bandai_namco_source", "build_datasets", "heldout_dataset", "scored_takes",
           "window_groups", "window_speeds", "window_kinds", "window_styles", "grouped_errors",
           "STAND_MAX_CM_S", "RUN_MIN_CM_S", "TURN_MIN_DEG"]

#: :class:`~refimpl.protocols.transition.TransitionSource` kind of a Bandai Namco take.
KIND = "bandai_namco_bvh"
#: Name of the data set's folder in ``../shared/data``.
FOLDER = "bandai_namco_locomotion"
#: The 21 joints kept (skeleton order, ``Hips`` = root): the locomotion rig's.
JOINTS = tuple(BANDAI_NAMCO_RIG.keep)

#: Horizontal root speed (cm/s) below which a window's end is "stand", and from which it is "run"; between: "walk".
STAND_MAX_CM_S = 40.0
RUN_MIN_CM_S = 200.0
#: Heading change (degrees) between a window's first and last pose from which it is a turn.
TURN_MIN_DEG = 45.0

_TAKE = re.compile(r"dataset-2_(?P<content>[a-z-]+)_(?P<style>[a-z]+)_(?P<id>\d+)")


@dataclasses.dataclass(frozen=True)
class TakeFacts:
    """What a take's file name says: ``dataset-2_<content>_<style>_<id>.bvh``."""

    content: str
    style: str
    id: int


def take_facts(path) -> TakeFacts:
    """Content, style and id of a take from its file name (ValueError for another name)."""
    m = _TAKE.fullmatch(Path(path).stem)
    if m is None:
        raise ValueError(f"path: {str(path)!r} is not named dataset-2_<content>_<style>_<id>.bvh")
    return TakeFacts(m.group("content"), m.group("style"), int(m.group("id")))


def _folder(root) -> Path:
    root = Path(root)
    return root / FOLDER if (root / FOLDER).is_dir() else root


def find_takes(root) -> list[Path]:
    """The ``dataset-2_*.bvh`` takes of a Bandai Namco folder (or of the folder holding ``bandai_namco_locomotion``),
    sorted."""
    return sorted(_folder(root).glob("dataset-2_*.bvh"))


def is_bandai_namco_folder(root) -> bool:
    """True for a folder of Bandai Namco takes, or one holding ``bandai_namco_locomotion`` without the CMU data
    (``../shared/data`` itself stays the CMU set of :func:`refimpl.protocols.transition.shared_sources`)."""
    root = Path(root)
    if not root.is_dir() or (root / "dmgnn_cmu_expmap").is_dir():
        return False
    return bool(find_takes(root))


def bandai_namco_sources(root):
    """Train and test sources, split by whole takes (:func:`~refimpl.protocols.locomotion_data.bandai_namco_split`: ids
    ending in 1 held out). Each source's label is its take's content (walk, walk-turn-left, walk-turn-right, run).

    Returns
    -------
    train, test : list of TransitionSource (kind :data:`KIND`, 30 fps)
    """
    takes = find_takes(root)
    if not takes:
        raise ValueError(f"{root}: no dataset-2_*.bvh takes")
    train, test = bandai_namco_split(takes)

    def src(p):
        return TransitionSource(str(p), KIND, 30.0, take_facts(p).content)

    return [src(p) for p in train], [src(p) for p in test]


def load_bandai_namco_source(source: TransitionSource, fps: float = 30.0):
    """Read one take for :func:`~refimpl.protocols.transition.build_transition_datasets` (its ``loader``).

    :func:`~refimpl.protocols.locomotion_data.load_bandai_namco` (re-rooted at ``Hips``, centimetres, rotations continuous),
    then the 21 joints of :data:`JOINTS` (the End Sites dropped: exact). No frame is dropped (the takes have no
    reference pose). ``source.frames`` selects a fraction of the take; ``fps`` must be 30 (the takes' rate).

    Returns
    -------
    skeleton : Skeleton (21 joints, centimetres)
    clips : [(rotations (F, 21, 4), root_positions (F, 3))]
    """
    if source.kind != KIND:
        raise ValueError(f"source.kind: expected {KIND!r}, got {source.kind!r}")
    if abs(float(fps) - 30.0) > 1e-9 or abs(float(source.fps) - 30.0) > 1e-9:
        raise ValueError(f"fps: the Bandai Namco takes are 30 fps; got source {source.fps}, wanted {fps}")
    motion = load_bandai_namco(source.path)
    skel, rot = subset_22(motion.skeleton, np.asarray(motion.rotations), JOINTS)
    pos = np.asarray(motion.root_positions, dtype=np.float64)
    F = rot.shape[0]
    a, b = int(round(source.frames[0] * F)), int(round(source.frames[1] * F))
    return skel, [(rot[a:b], pos[a:b])]


def build_datasets(root, T: int = 30, stride: int = 4, test_stride: int | None = None, progress=None,
                   train_only: bool = False):
    """Train and test :class:`~refimpl.protocols.transition.TransitionDataset` of the takes in ``root`` (spec/qtg.md §8.4).

    Windows of ``2 + T + 2`` poses every ``stride`` frames of every take (``test_stride`` for the held-out takes,
    default ``stride``); root statistics from the training windows. The takes are read through the data cache
    (:mod:`refimpl.protocols.transition_cache`: one entry for the training takes, one for the held-out ones;
    ``REFIMPL_CACHE=off`` reads them every time). ``progress(line)``, when given, hears every ~5 s how many
    files have been read (``"read 212 of 830 files, 15 s"``) and whether the cache held them. ``train_only``: the
    held-out takes are not read (the test dataset has no window; ``refimpl import``).
    """
    train_src, test_src = bandai_namco_sources(root)
    test_src = [] if train_only else test_src
    loader = cached_loader((train_src, test_src), load_bandai_namco_source, progress=progress)
    return build_transition_datasets(train_src, test_src, T=T, stride=stride, test_stride=test_stride,
                                     loader=loader)


def heldout_dataset(root, root_mean, root_std, T: int = 30, stride: int = 4, progress=None):
    """Only the held-out windows of :func:`build_datasets` (reads the ~95 held-out takes, or their cache entry,
    not all 830), with the given root statistics (a trained model's): what an evaluation needs. Same windows as
    ``build_datasets(...)[1]`` with ``test_stride = stride``."""
    _, test_src = bandai_namco_sources(root)
    loader = cached_loader((test_src,), load_bandai_namco_source, progress=progress)
    test, _ = build_transition_datasets(test_src, [], T=T, stride=stride, loader=loader)
    return dataclasses.replace(test, root_mean=np.asarray(root_mean, dtype=np.float64),
                               root_std=np.asarray(root_std, dtype=np.float64))


def scored_takes(takes) -> tuple[list[Path], str]:
    """The takes an evaluation scores of a set of Bandai Namco takes, and why (spec/qtg.md §8.4).

    A set that holds takes of both sides of the project's split (:func:`bandai_namco_sources`: ids ending in 1
    held out) is the data set a model was trained on: its held-out side is scored. Any other set (only held-out
    takes, or takes a model has not been trained on) is scored whole: nothing in it is a training take of the
    split, or the split cannot say.

    Returns
    -------
    takes : list of Path (sorted)
    why : str
        One line for the user (how many takes, which rule).
    """
    takes = sorted((Path(t) for t in takes), key=str)
    if not takes:
        raise ValueError("takes: no dataset-2_*.bvh take to score")
    train, test = bandai_namco_split(takes)
    if train and test:
        return test, (f"the {len(test)} held-out takes (ids ending in 1) of {len(takes)}: the project's split "
                      "(a folder of only held-out or new takes is scored whole)")
    side = "held-out takes (ids ending in 1)" if test else "takes outside the held-out side of the project's split"
    return takes, f"all {len(takes)} takes ({side}; no training split, normalisation from the checkpoint)"


def window_groups(dataset) -> dict:
    """``{"style": ..., "kind": ...}``: each window's take style and the transition it asks for, ``(N,)`` of str
    each (:func:`window_styles`, :func:`window_kinds`), the groups an evaluation reports by."""
    return {"style": window_styles(dataset), "kind": window_kinds(dataset.poses, dataset.fps)}


def window_speeds(poses, fps: float = 30.0, past: int = 2, future: int = 2):
    """Horizontal root speeds at both ends of each window and its heading change.

    Parameters
    ----------
    poses : ndarray (N, W, P)
        UN-normalised windows (root translation in cm, y up).

    Returns
    -------
    start, end : ndarray (N,)
        ``|r_1 − r_0|`` and ``|r_{W−1} − r_{W−2}|`` in the ground plane, cm/s (the two past / target poses).
    turn_deg : ndarray (N,)
        Signed heading change (degrees, about +y) from the first to the last pose, in (−180, 180].
    """
    root, quats = split_pose(np.asarray(poses, dtype=np.float64))  # (N, W, 3), (N, W, J, 4)
    if root.shape[1] < past + future + 1:
        raise ValueError(f"poses: expected windows of more than {past + future} poses, got {root.shape[1]}")
    ground = root[..., [0, 2]]
    start = np.linalg.norm(ground[:, past - 1] - ground[:, 0], axis=-1) * fps / max(past - 1, 1)
    end = np.linalg.norm(ground[:, -1] - ground[:, -future], axis=-1) * fps / max(future - 1, 1)
    h0, h1 = heading_from_root(quats[:, 0, 0]), heading_from_root(quats[:, -1, 0])  # (N, 4)
    a0, a1 = 2 * np.arctan2(h0[:, 2], h0[:, 0]), 2 * np.arctan2(h1[:, 2], h1[:, 0])
    turn = np.degrees(np.angle(np.exp(1j * (a1 - a0))))
    return start, end, turn


def _gait(speed):
    return np.where(speed < STAND_MAX_CM_S, "stand", np.where(speed < RUN_MIN_CM_S, "walk", "run"))


def window_kinds(poses, fps: float = 30.0) -> np.ndarray:
    """The transition each window asks for, from its own root motion (spec/qtg.md §8.4).

    ``"<gait at the past poses>-><gait at the target poses>"`` with gait ``stand`` (horizontal root speed below
    :data:`STAND_MAX_CM_S`), ``run`` (from :data:`RUN_MIN_CM_S`) or ``walk``, and ``" turn"`` appended when the
    heading changes by :data:`TURN_MIN_DEG` or more over the window.

    Returns
    -------
    ndarray (N,) of str
    """
    start, end, turn = window_speeds(poses, fps)
    kinds = np.char.add(np.char.add(_gait(start), "->"), _gait(end))
    return np.where(np.abs(turn) >= TURN_MIN_DEG, np.char.add(kinds, " turn"), kinds)


def window_styles(dataset) -> np.ndarray:
    """The style (active, elderly, ...) of each window's take, ``(N,)`` of str."""
    styles = np.array([take_facts(s.path).style for s in dataset.sources])
    return styles[np.asarray(dataset.source_index, dtype=int)]


def grouped_errors(dataset, methods, groups, batch_size: int = 1024) -> dict:
    """The paper's metric (spec/qtg.md §9) of every method on ``dataset``, overall and per group of windows.

    Parameters
    ----------
    dataset : TransitionDataset
    methods : mapping name -> f(past, target, T) -> poses (un-normalised)
    groups : mapping grouping name -> ndarray (N,) of str
        E.g. ``{"style": window_styles(ds), "kind": window_kinds(ds.poses)}``.

    Returns
    -------
    dict name -> {"mean_cm", "per_frame_cm" (T,), "num_windows",
                  "by_<grouping>": {label: {"mean_cm", "per_frame_cm" (T,), "num_windows"}}}
        Means over windows, transition frames and joints of ``‖FK(pred) − FK(gt)‖₂`` (cm).
    """
    if dataset.num_windows == 0:
        raise ValueError("dataset: no windows to evaluate")
    labels = {g: np.asarray(v) for g, v in groups.items()}
    for g, v in labels.items():
        if v.shape != (dataset.num_windows,):
            raise ValueError(f"groups[{g!r}]: expected shape ({dataset.num_windows},), got {v.shape}")
    gt = dataset.context()[1]
    out = {}
    for name, f in methods.items():
        pred = predict_transitions(dataset, f, name, batch_size)
        per_window = joint_position_errors(pred, gt, dataset.skeletons, dataset.skeleton_index)[0].mean(axis=2)
        res = _summary(per_window)  # (N, T) -> summary
        for g, v in labels.items():
            res[f"by_{g}"] = {lab: _summary(per_window[v == lab]) for lab in sorted(set(v.tolist()))}
        out[name] = res
    return out


def _summary(per_window: np.ndarray) -> dict:
    curve = per_window.mean(axis=0)  # (T,)
    return {"mean_cm": float(curve.mean()), "per_frame_cm": [float(c) for c in curve],
            "num_windows": int(per_window.shape[0])}
