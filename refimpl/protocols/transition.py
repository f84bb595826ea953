"""Transition data for QTG: pose layout, 22-joint subsets, root-relative windows, splits (spec/qtg.md §8).

Pose layout (P = 3 + 4 J; 91 for J = 22)::

    pose = [root translation (x, y, z) | q_0 (w, x, y, z) | q_1 | … | q_{J-1}]

``q_j`` is joint ``j``'s LOCAL rotation (joint 0 = root, its rotation relative to the window frame). Lengths
(root translation, skeleton offsets) are in CENTIMETRES for every data set (:func:`load_source` converts the
CMU units, 5.6444 cm each). The network sees the root translation z-normalised per axis with the TRAINING set's mean and std
(:func:`normalize_poses`); quaternions are never normalised by statistics.

A window is ``2 past + T + 2 target`` consecutive poses at 30 fps (34 for T = 30), expressed relative to its
FIRST pose (paper: "the root joint transformation of each pose is relative to the first pose"):

* translation: ``r'_k = R(h)⁻¹ (r_k − r_0)``, so the first pose's root is at the origin;
* rotation about the up axis (y): ``h`` = the heading (twist about +y) of the first pose's root rotation,
  ``h = normalise(w, 0, y, 0)`` of ``q_root,0``; every root rotation becomes ``h⁻¹ ⊗ q_root,k``.

This is one rigid motion of the whole window (a rotation about y plus a translation), so forward-kinematics
positions transform the same way: ``FK'(k) = R(h)⁻¹ (FK(k) − r_0)`` (tested). Quaternion signs: within a
window the first pose's quaternions have ``w >= 0`` and later frames are made continuous (``quat_fix``).

Shape legend: N windows, W window length (T + 4), T transition frames, J joints, P pose size, F frames of a clip.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Iterable, Mapping

import numpy as np

from refimpl.bvh import read_bvh
from refimpl.expmap import read_expmap
from refimpl.arrays import float_array
from refimpl.preprocess import denormalize_features, normalize_features
from refimpl.quat import quat_conj, quat_fix, quat_mul, quat_rotate
from refimpl.rigs import (CMU_22_JOINTS, CMU_UNIT_CM, SALSA_22_JOINTS, SALSA_UNIT_CM, heading_from_root,
                          scale_skeleton, subset_22)
from refimpl.skeleton import Skeleton
from refimpl.checkpoint_fields import TaskSchema, positive_int, vector3

__all__ = ["CHECKPOINT_SCHEMA", 
    "pose_size", "split_pose", "join_pose", "pose_statistics", "normalize_poses", "denormalize_poses",
    "CMU_22_JOINTS", "SALSA_22_JOINTS", "CMU_UNIT_CM", "SALSA_UNIT_CM",
    "TransitionSource", "TransitionDataset", "subset_22", "scale_skeleton", "heading_from_root", "make_windows",
    "window_to_world", "declared_rate", "load_source", "build_transition_datasets", "sample_sources",
    "shared_sources", "SAMPLE_DIR",
]

#: The embedded CMU sample (see its README.md): the default data of ``refimpl train``, ``eval`` and ``demo``.
SAMPLE_DIR = Path(__file__).resolve().parent.parent / "data" / "sample"


# ----------------------------------------------------------------------------------------------------------------
# pose layout and normalisation
# ----------------------------------------------------------------------------------------------------------------

def pose_size(num_joints: int) -> int:
    """``3 + 4 J`` values per pose (91 for 22 joints)."""
    return 3 + 4 * int(num_joints)


def split_pose(poses) -> tuple[np.ndarray, np.ndarray]:
    """``(..., P)`` -> root translation ``(..., 3)`` and local quaternions ``(..., J, 4)`` (views)."""
    poses = np.asarray(poses)
    P = poses.shape[-1]
    if P < 7 or (P - 3) % 4:
        raise ValueError(f"poses: expected a last axis of 3 + 4 J values, got shape {poses.shape}")
    return poses[..., :3], poses[..., 3:].reshape(poses.shape[:-1] + ((P - 3) // 4, 4))


def join_pose(root, quats) -> np.ndarray:
    """Root translation ``(..., 3)`` and quaternions ``(..., J, 4)`` -> poses ``(..., 3 + 4 J)``."""
    root = np.asarray(root)
    quats = np.asarray(quats)
    if root.shape[-1:] != (3,) or quats.shape[-1:] != (4,) or quats.shape[:-2] != root.shape[:-1]:
        raise ValueError(f"root, quats: expected shapes (..., 3) and (..., J, 4) with equal leading axes, "
                         f"got {root.shape} and {quats.shape}")
    lead = root.shape[:-1]
    return np.concatenate([root, quats.reshape(lead + (-1,))], axis=-1)


def _check_stats(mean, std):
    mean = float_array(np.asarray(mean, dtype=np.float64), "root_mean", (3,), cast=False)
    std = float_array(np.asarray(std, dtype=np.float64), "root_std", (3,), cast=False)
    if np.any(std <= 0):
        raise ValueError(f"root_std: expected positive values, got {std}")
    return mean, std


def pose_statistics(root_mean, root_std, pose_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Whole-pose statistics ``(mean (P,), std (P,))`` from the root's: root values, then 0 / 1 for quaternions.

    With them, :func:`refimpl.preprocess.normalize_features` is :func:`normalize_poses` (the one normalisation
    API: ``(x − mean) / std`` over the last axis; ``(q − 0) / 1 = q`` exactly).
    """
    mean, std = _check_stats(root_mean, root_std)
    full_mean, full_std = np.zeros(int(pose_size)), np.ones(int(pose_size))
    full_mean[:3], full_std[:3] = mean, std
    return full_mean, full_std


def normalize_poses(poses, root_mean, root_std) -> np.ndarray:
    """z-normalise the root translation: ``(r − mean) / std`` per axis; quaternions unchanged (a copy).

    :func:`refimpl.preprocess.normalize_features` with :func:`pose_statistics`.

    Parameters
    ----------
    poses : ndarray (..., P)
    root_mean, root_std : array_like (3,)
    """
    poses = float_array(poses, "poses", (..., None), cast=False)
    split_pose(poses)
    mean, std = pose_statistics(root_mean, root_std, poses.shape[-1])
    return normalize_features(poses, mean, std)


def denormalize_poses(poses, root_mean, root_std) -> np.ndarray:
    """Inverse of :func:`normalize_poses`: ``r = r_n · std + mean`` (a copy;
    :func:`refimpl.preprocess.denormalize_features`)."""
    poses = float_array(poses, "poses", (..., None), cast=False)
    split_pose(poses)
    mean, std = pose_statistics(root_mean, root_std, poses.shape[-1])
    return denormalize_features(poses, mean, std)


# ----------------------------------------------------------------------------------------------------------------
# windows
# ----------------------------------------------------------------------------------------------------------------
def make_windows(rotations, root_positions, length: int = 34, stride: int = 1, up: str = "y",
                 relative_heading: bool = True) -> np.ndarray:
    """Cut a clip into root-relative windows of ``length`` poses (spec/qtg.md §8.2).

    Window ``i`` holds frames ``i·stride … i·stride + length − 1``. Within it, with ``r_0``, ``q_root,0`` the
    first frame's root position and rotation and ``h`` = :func:`heading_from_root` (``q_root,0``) (the
    identity when ``relative_heading`` is False):

    * ``root'_k = R(h)⁻¹ (root_k − r_0)``
    * ``q'_root,k = h⁻¹ ⊗ q_root,k``; other joints unchanged;
    * the first frame's quaternions are put in the ``w >= 0`` hemisphere, later frames follow continuously.

    Parameters
    ----------
    rotations : ndarray (F, J, 4)
        Local unit quaternions.
    root_positions : ndarray (F, 3)
    length, stride : int
    up : str
    relative_heading : bool

    Returns
    -------
    ndarray (N, length, 3 + 4 J), float64; ``N = max(0, (F − length) // stride + 1)``.
    """
    rot = float_array(rotations, "rotations", (None, None, 4), cast=False).astype(np.float64)
    pos = float_array(root_positions, "root_positions", (rot.shape[0], 3), cast=False).astype(np.float64)
    if not isinstance(length, (int, np.integer)) or length < 1:
        raise ValueError(f"length: expected a positive integer, got {length!r}")
    if not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ValueError(f"stride: expected a positive integer, got {stride!r}")
    F, J, _ = rot.shape
    if F < length:
        return np.zeros((0, length, pose_size(J)))
    starts = np.arange(0, F - length + 1, stride)  # (N,)
    idx = starts[:, None] + np.arange(length)[None, :]  # (N, W)
    wr = rot[idx]  # (N, W, J, 4)
    wp = pos[idx]  # (N, W, 3)
    if relative_heading:
        h_inv = quat_conj(heading_from_root(wr[:, 0, 0], up=up))  # (N, 4)
    else:
        h_inv = np.tile(np.array([1.0, 0, 0, 0]), (len(starts), 1))
    wp = quat_rotate(h_inv[:, None], wp - wp[:, :1])  # (N, W, 3)
    wr = wr.copy()
    wr[:, :, 0] = quat_mul(h_inv[:, None], wr[:, :, 0])  # (N, W, 4)
    wr[:, 0] = np.where(wr[:, 0, :, :1] < 0, -wr[:, 0], wr[:, 0])
    wr = np.moveaxis(quat_fix(np.moveaxis(wr, 1, 0)), 0, 1)  # continuity over W
    return join_pose(wp, wr)


def window_to_world(poses, heading, origin) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`make_windows`' root-relative transform, for poses generated in a window's frame.

    ``root_k = R(h) root'_k + r_0``; ``q_root,k = h ⊗ q'_root,k``; then every quaternion is normalised to unit
    length (generated poses are not unit).

    Parameters
    ----------
    poses : ndarray (F, P)
        Poses relative to the window's first pose.
    heading : ndarray (4,)
        ``h`` = :func:`heading_from_root` of the window's first root rotation.
    origin : ndarray (3,)
        ``r_0``, the window's first root position.

    Returns
    -------
    root_positions : ndarray (F, 3)
    rotations : ndarray (F, J, 4), unit
    """
    root_rel, quats = split_pose(np.asarray(poses, dtype=np.float64))  # (F, 3), (F, J, 4)
    h = np.asarray(heading, dtype=np.float64)
    pos = quat_rotate(h[None], root_rel) + np.asarray(origin, dtype=np.float64)  # (F, 3)
    rot = np.array(quats, copy=True)
    rot[:, 0] = quat_mul(h[None], rot[:, 0])
    rot /= np.linalg.norm(rot, axis=-1, keepdims=True)
    return pos, rot


# ----------------------------------------------------------------------------------------------------------------
# sources and datasets
# ----------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class TransitionSource:
    """One motion file and how to turn it into windows.

    Attributes
    ----------
    path : str
    kind : {"cmu_bvh", "cmu_expmap", "salsa_bvh"}
        Reader and 22-joint subset: cgspeed BVH (31 joints) / CMU exp-map text (38-joint ASF skeleton) with
        :data:`CMU_22_JOINTS`; DAZ salsa BVH with :data:`SALSA_22_JOINTS`.
    fps : float
        TRUE capture rate (salsa: 60, although the header says 120).
    label : str
        Motion category ("walk", "run", "jump", "salsa").
    frames : (float, float)
        Fraction of the clip to use, ``[start, stop)`` (used to split a single file by time).
    """

    path: str
    kind: str
    fps: float
    label: str
    frames: tuple[float, float] = (0.0, 1.0)


def declared_rate(frame_time: float) -> float:
    """Frames per second from a file's declared frame time, snapped to the nearest integer within 0.1 %
    (``Frame Time: .0083333`` is 120 fps, not 120.00048)."""
    fps = 1.0 / frame_time
    return float(round(fps)) if abs(fps - round(fps)) <= 1e-3 * fps else fps


_KINDS = {"cmu_bvh": (CMU_22_JOINTS, CMU_UNIT_CM), "cmu_expmap": (CMU_22_JOINTS, CMU_UNIT_CM),
          "salsa_bvh": (SALSA_22_JOINTS, SALSA_UNIT_CM)}


def load_source(source: TransitionSource, fps: float = 30.0, skip_start: int = 1):
    """Read one source, drop its first ``skip_start`` frames (the conversion's reference pose), keep the
    22-joint subset, convert lengths to centimetres (CMU: × :data:`CMU_UNIT_CM`), select ``source.frames``
    and resample to ``fps`` by taking every ``k``-th frame.

    Every phase ``0 … k−1`` of the subsampling is returned as a separate clip (``k = source.fps / fps`` must be
    an integer), which multiplies the number of distinct windows by ``k`` without inventing poses.

    Returns
    -------
    skeleton : Skeleton (22 joints, centimetres)
    clips : list of (rotations (F, 22, 4), root_positions (F, 3))
    """
    if source.kind not in _KINDS:
        raise ValueError(f"source.kind: expected one of {sorted(_KINDS)}, got {source.kind!r}")
    keep, unit_cm = _KINDS[source.kind]
    if source.kind == "cmu_expmap":
        motion = read_expmap(source.path, layout="cmu", frame_time=1.0 / source.fps)
    else:
        motion = read_bvh(source.path, frame_time=1.0 / source.fps)
    ratio = source.fps / fps
    k = int(round(ratio))
    if k < 1 or abs(ratio - k) > 1e-9:
        raise ValueError(f"fps: the source rate {source.fps} must be an integer multiple of {fps}")
    skel, rot = subset_22(motion.skeleton, np.asarray(motion.rotations)[skip_start:], keep)
    skel = scale_skeleton(skel, unit_cm)
    pos = np.asarray(motion.root_positions)[skip_start:] * unit_cm  # (F, 3) cm
    F = rot.shape[0]
    a, b = int(round(source.frames[0] * F)), int(round(source.frames[1] * F))
    rot, pos = rot[a:b], pos[a:b]
    return skel, [(rot[p::k], pos[p::k]) for p in range(k)]


@dataclasses.dataclass(frozen=True, eq=False)
class TransitionDataset:
    """Windows of ``past + T + future`` poses with what is needed to evaluate them.

    Attributes
    ----------
    poses : ndarray (N, W, P), float64
        UN-normalised root-relative poses (:func:`make_windows`), root translation in centimetres.
    skeleton_index : ndarray (N,), int
        Index into ``skeletons`` of each window's skeleton (for forward kinematics).
    skeletons : tuple of Skeleton
        22-joint skeletons, offsets in centimetres.
    source_index : ndarray (N,), int
        Index into ``sources`` of each window's file.
    sources : tuple of TransitionSource
    root_mean, root_std : ndarray (3,)
        Statistics of the root translation over the TRAINING windows (all W poses).
    fps : float
    past, future : int
        Context poses before and after the transition (2 and 2).
    """

    poses: np.ndarray
    skeleton_index: np.ndarray
    skeletons: tuple
    source_index: np.ndarray
    sources: tuple
    root_mean: np.ndarray
    root_std: np.ndarray
    fps: float = 30.0
    past: int = 2
    future: int = 2

    def __post_init__(self):
        p = float_array(self.poses, "poses", (None, None, None), cast=False)
        n, w, _ = p.shape
        split_pose(p)
        if w <= self.past + self.future:
            raise ValueError(f"poses: expected windows longer than past + future = {self.past + self.future}, "
                             f"got {w}")
        for name in ("skeleton_index", "source_index"):
            a = np.asarray(getattr(self, name))
            if a.shape != (n,):
                raise ValueError(f"{name}: expected shape ({n},), got {a.shape}")
        _check_stats(self.root_mean, self.root_std)

    @property
    def num_windows(self) -> int:
        """N."""
        return int(self.poses.shape[0])

    @property
    def transition_length(self) -> int:
        """T = W − past − future."""
        return int(self.poses.shape[1] - self.past - self.future)

    def normalized(self, dtype=np.float64) -> np.ndarray:
        """Poses with the root translation z-normalised by ``root_mean``/``root_std``, ``(N, W, P)``."""
        return normalize_poses(self.poses, self.root_mean, self.root_std).astype(dtype)

    def context(self, normalized: bool = False):
        """``past (N, 2, P)``, ``transition (N, T, P)``, ``target (N, 2, P)``."""
        p = self.normalized() if normalized else self.poses
        a, b = self.past, self.poses.shape[1] - self.future
        return p[:, :a], p[:, a:b], p[:, b:]

    def select(self, mask) -> "TransitionDataset":
        """The windows where ``mask`` (N,) is True (or the given indices); statistics unchanged."""
        sel = np.asarray(mask)
        return dataclasses.replace(self, poses=self.poses[sel], skeleton_index=self.skeleton_index[sel],
                                   source_index=self.source_index[sel])


def _stats(poses: np.ndarray):
    root = poses[..., :3].reshape(-1, 3)
    return root.mean(axis=0), np.maximum(root.std(axis=0), 1e-6)


def build_transition_datasets(train_sources: Iterable[TransitionSource], test_sources: Iterable[TransitionSource],
                              T: int = 30, stride: int = 1, test_stride: int | None = None, fps: float = 30.0,
                              relative_heading: bool = True, loader=None):
    """Train and test :class:`TransitionDataset` from two disjoint lists of sources (split by file).

    Windows have ``2 + T + 2`` poses, cut every ``stride`` frames from each 30-fps clip (every phase of the
    subsampling, :func:`load_source`); the root statistics come from the training windows and are shared by
    both datasets. Each distinct 22-joint skeleton (compared by value) gets one entry in ``skeletons``.
    ``loader(source, fps=fps) -> (skeleton, clips)`` reads a source (default :func:`load_source`; the Bandai
    Namco locomotion set passes its own, :mod:`refimpl.locomotion_transitions`).

    Returns
    -------
    train, test : TransitionDataset
    """
    train_sources, test_sources = list(train_sources), list(test_sources)
    paths_train = {(s.path, s.frames) for s in train_sources}
    for s in test_sources:
        if (s.path, s.frames) in paths_train:
            raise ValueError(f"test_sources: {s.path} {s.frames} is also a training source")
    length = T + 4
    load = load_source if loader is None else loader
    skeletons: list[Skeleton] = []

    def build(sources, st):
        poses, sk_idx, src_idx = [], [], []
        for i, src in enumerate(sources):
            skel, clips = load(src, fps=fps)
            k = next((j for j, s in enumerate(skeletons) if s == skel), None)
            if k is None:
                skeletons.append(skel)
                k = len(skeletons) - 1
            for rot, pos in clips:
                w = make_windows(rot, pos, length=length, stride=st, relative_heading=relative_heading)
                poses.append(w)
                sk_idx.append(np.full(len(w), k))
                src_idx.append(np.full(len(w), i))
        if not poses:
            return np.zeros((0, length, pose_size(22))), np.zeros(0, int), np.zeros(0, int)
        return np.concatenate(poses), np.concatenate(sk_idx), np.concatenate(src_idx)

    tr = build(train_sources, stride)
    te = build(test_sources, stride if test_stride is None else test_stride)
    if len(tr[0]) == 0:
        raise ValueError("train_sources: no window could be cut (clips shorter than the window?)")
    mean, std = _stats(tr[0])
    common = dict(skeletons=tuple(skeletons), root_mean=mean, root_std=std, fps=fps)
    train = TransitionDataset(poses=tr[0], skeleton_index=tr[1], source_index=tr[2], sources=tuple(train_sources),
                              **common)
    test = TransitionDataset(poses=te[0], skeleton_index=te[1], source_index=te[2], sources=tuple(test_sources),
                             **common)
    return train, test


def sample_sources(root: str | Path | None = None):
    """Train/test split of the embedded sample ``refimpl/data/sample`` (spec/qtg.md §8.3).

    * exp-map walking/running: the files' own ``train``/``test`` folders, except ``train/walking/walking_1.txt``,
      which is CMU 02_01, the same trial as ``bvh/02_01.bvh`` (kept, train);
    * ``bvh/01_01.bvh`` (jumps; one file): first 80 % train, last 20 % test (split by time);
    * ``salsa/01.bvh`` and ``salsa/16.bvh`` (the two partners of take 01, 60 fps): first 80 % train, last 20 %
      test of each.

    Returns
    -------
    train, test : list of TransitionSource
    """
    root = SAMPLE_DIR if root is None else Path(root)
    train, test = [], []
    for split, out in (("train", train), ("test", test)):
        for action, label in (("walking", "walk"), ("running", "run")):
            for f in sorted((root / "expmap" / split / action).glob("*.txt")):
                if split == "train" and f.name == "walking_1.txt":
                    continue
                out.append(TransitionSource(str(f), "cmu_expmap", 120.0, label))
    train.append(TransitionSource(str(root / "bvh" / "02_01.bvh"), "cmu_bvh", 120.0, "walk"))
    train.append(TransitionSource(str(root / "bvh" / "01_01.bvh"), "cmu_bvh", 120.0, "jump", (0.0, 0.8)))
    test.append(TransitionSource(str(root / "bvh" / "01_01.bvh"), "cmu_bvh", 120.0, "jump", (0.8, 1.0)))
    for name in ("01", "16"):
        train.append(TransitionSource(str(root / "salsa" / f"{name}.bvh"), "salsa_bvh", 60.0, "salsa", (0.0, 0.8)))
        test.append(TransitionSource(str(root / "salsa" / f"{name}.bvh"), "salsa_bvh", 60.0, "salsa", (0.8, 1.0)))
    return train, test


def shared_sources(root: str | Path):
    """Train/test split of the bigger data set in ``../shared/data`` (spec/qtg.md §8.3).

    * ``dmgnn_cmu_expmap``: its ``train``/``test`` folders (walking_1 = 02_01 is dropped in favour of the BVH);
    * ``bvhtodeepmimic_cmu_bvh/02_01.bvh``: train; ``fairmotion_cmu_bvh/01_01.bvh``: first 80 % train, last
      20 % test;
    * ``acrnn_cmu_salsa``: takes 01, 02, 03 of both partners (01/16, 02/17, 03/18) train, take 05 (05/20) test.

    Returns
    -------
    train, test : list of TransitionSource
    """
    root = Path(root)
    train, test = [], []
    for split, out in (("train", train), ("test", test)):
        for action, label in (("walking", "walk"), ("running", "run")):
            for f in sorted((root / "dmgnn_cmu_expmap" / split / action).glob("*.txt")):
                if split == "train" and f.name == "walking_1.txt":
                    continue
                out.append(TransitionSource(str(f), "cmu_expmap", 120.0, label))
    train.append(TransitionSource(str(root / "bvhtodeepmimic_cmu_bvh" / "02_01.bvh"), "cmu_bvh", 120.0, "walk"))
    jumps = str(root / "fairmotion_cmu_bvh" / "01_01.bvh")
    train.append(TransitionSource(jumps, "cmu_bvh", 120.0, "jump", (0.0, 0.8)))
    test.append(TransitionSource(jumps, "cmu_bvh", 120.0, "jump", (0.8, 1.0)))
    salsa = root / "acrnn_cmu_salsa"
    for name in ("01", "02", "03", "16", "17", "18"):
        train.append(TransitionSource(str(salsa / f"{name}.bvh"), "salsa_bvh", 60.0, "salsa"))
    for name in ("05", "20"):
        test.append(TransitionSource(str(salsa / f"{name}.bvh"), "salsa_bvh", 60.0, "salsa"))
    return train, test


# ---- what the task stores in a checkpoint (spec/robustness.md §9.1) ----

def _check_checkpoint(cfg: Mapping, config, where: str) -> None:
    """The transition fields: ``root_mean`` / ``root_std`` required (their types: :data:`CHECKPOINT_SCHEMA`'s
    ``fields``)."""
    if "root_mean" not in cfg or "root_std" not in cfg:
        raise ValueError(f"{where}: the checkpoint has no normalisation statistics (root_mean/root_std); train it "
                         "with `refimpl train`")


#: The transition task's checkpoint schema (``refimpl.tasks.transition.CHECKPOINT_SCHEMA``, deploy's QTG loader):
#: ``root_mean`` 3 finite numbers, ``root_std`` 3 finite numbers > 0, ``transition_length`` a positive integer.
CHECKPOINT_SCHEMA = TaskSchema("transition", fields={"root_mean": vector3(positive=False),
                                                     "root_std": vector3(positive=True),
                                                     "transition_length": positive_int},
                               check=_check_checkpoint)
