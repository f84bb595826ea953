"""Short-term motion prediction, the data (spec/prediction.md): Human3.6M and CMU exp-map files as rotation
sequences at the protocol's rate, their skeletons, and the training windows.

QuaterNet journal paper §4.1; the loading replicates the published code (spec/prediction.md §2).

* Human3.6M exp-map text files ``S{n}/{action}_{subaction}.txt`` (99 values per row, 50 Hz; :func:`load_h36m`)
  and the CMU exp-map layout ``{train,test}/{action}/{action}_{k}.txt`` (117 values per row; :func:`load_cmu`),
  read by :func:`refimpl.expmap.read_expmap` (``q = quat_from_axis_angle(−r)``, ``quat_fix``, H3.6M triplet 0
  discarded), decimated keeping every stride phase for training (``_d0``, ``_d1``) and phase 0 for testing.
* Training batches: one random window per training sequence (:func:`training_windows`).

The protocol, error and baselines are in :mod:`refimpl.protocols.prediction`.

Shape legend: B batch, T frames, J joints.
"""
from __future__ import annotations

import dataclasses
import math
import os
import re
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from refimpl.expmap import read_expmap
from refimpl.files import read_bytes
from refimpl.preprocess import downsample, fix_antipodal
from refimpl.skeleton import Skeleton
from refimpl.skeletons import cmu_asf_skeleton, h36m_skeleton
from refimpl.checkpoint_fields import TaskSchema, kind_of, require_fields

__all__ = ["CHECKPOINT_SCHEMA", 
    "H36M_ACTIONS", "H36M_TRAIN_SUBJECTS", "H36M_TEST_SUBJECT", "H36M_VALID_SUBJECT", "SUBJECT_DIR",
    "PredictionSequence", "PredictionData", "load_h36m", "load_cmu", "skeleton_of", "training_windows",
    "usable_training", "stride_of", "expmap_rows", "longest_file",
]

# The published evaluation's action order (spec/prediction.md §3).
H36M_ACTIONS = ("walking", "eating", "smoking", "discussion", "directions", "greeting", "phoning", "posing",
                "purchases", "sitting", "sittingdown", "takingphoto", "waiting", "walkingdog", "walkingtogether")
H36M_TRAIN_SUBJECTS = ("S1", "S6", "S7", "S8", "S9", "S11")
H36M_TEST_SUBJECT = "S5"
H36M_VALID_SUBJECT = "S6"

_H36M_FILE = re.compile(r"^([a-z]+)_([0-9]+)\.txt$")
#: A Human3.6M subject folder name (``S1`` ... ``S11``).
SUBJECT_DIR = re.compile(r"^S[0-9]+$")


# ------------------------------------------------------------------------------------------------------------
# data
# ------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True, eq=False)
class PredictionSequence:
    """One decimated sequence of local joint rotations.

    Attributes
    ----------
    rotations : ndarray, (T, J, 4), read-only
        Unit quaternions ``(w, x, y, z)``, antipodally continuous over time (``quat_fix`` after decimation).
    action : str
    subaction : int
        H3.6M sub-sequence (1 or 2); the ``k`` of a CMU file ``{action}_{k}.txt``.
    subject : str
        ``"S1"`` … for H3.6M, ``"cmu"`` for the CMU files.
    phase : int
        Decimation phase: frames ``phase, phase + stride, …`` of the file (QuaterNet's ``_d0`` / ``_d1``).
    path : str
        The source file.
    frame_time : float
        Seconds per frame after decimation.
    """

    rotations: np.ndarray
    action: str
    subaction: int
    subject: str
    phase: int
    path: str
    frame_time: float

    @property
    def num_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def key(self) -> str:
        """``"{subject}/{action}_{subaction}_d{phase}"``, the published code's naming."""
        return f"{self.subject}/{self.action}_{self.subaction}_d{self.phase}"


@dataclasses.dataclass(frozen=True, eq=False)
class PredictionData:
    """Train / validation / test sequences of one dataset.

    Attributes
    ----------
    dataset : {"h36m", "cmu"}
    skeleton : Skeleton
        32 joints (H3.6M) or the 38-joint CMU ASF skeleton; the rotations' joint axis follows it.
    frame_time : float
        Seconds per frame after decimation (H3.6M 1/25; CMU 1/60 for a 120 fps trial).
    train, valid : tuple of PredictionSequence
        Every decimation phase.
    test : tuple of PredictionSequence
        Phase 0 only (``_d0``), sorted by action order then sub-sequence.
    """

    dataset: str
    skeleton: Skeleton
    frame_time: float
    train: tuple
    valid: tuple
    test: tuple

    def test_actions(self) -> tuple:
        """Actions present in the test set, in the published order (H3.6M) or sorted (CMU)."""
        present = {s.action for s in self.test}
        order = H36M_ACTIONS if self.dataset == "h36m" else tuple(sorted(present))
        return tuple(a for a in order if a in present)


def _decimate(motion, stride: int, phases, meta: dict) -> list:
    out = []
    for phase in phases:
        m = fix_antipodal(downsample(motion, stride, phase))
        out.append(PredictionSequence(rotations=m.rotations, phase=phase, frame_time=m.frame_time, **meta))
    return out


def _check_stride(stride) -> int:
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ValueError(f"stride: expected a positive int, got {stride!r}")
    return int(stride)


def _read_cmu(path, frame_time: float, drop_reference_frame: bool):
    """One CMU exp-map file as :func:`load_cmu` reads it (root position zero, the reference row dropped)."""
    motion = read_expmap(path, layout="cmu", frame_time=frame_time, use_root_position=False)
    if drop_reference_frame:
        if motion.num_frames < 2:
            raise ValueError(f"{path}: expected at least 2 rows (reference pose + motion), got {motion.num_frames}")
        motion = dataclasses.replace(motion, rotations=motion.rotations[1:], root_positions=motion.root_positions[1:])
    return motion


def expmap_rows(path) -> int:
    """The rows :func:`refimpl.expmap.read_expmap` reads from an exp-map text file (its non-blank lines, commas
    counting as blanks), found without parsing a number (~8 × faster than reading the file)."""
    return _rows(read_bytes(path))


def _rows(data: bytes) -> int:
    text = data.decode("utf-8-sig", errors="replace").replace("\r\n", "\n").replace("\r", "\n")
    return sum(1 for line in text.split("\n") if line.replace(",", " ").strip())


def _rows_bound(data: bytes) -> int:
    """An upper bound of :func:`_rows` at the speed of the disk: the lines once trailing blanks are stripped
    (equal to the rows of a file without blank lines inside)."""
    d = data.rstrip()
    return d.count(b"\n") + d.count(b"\r") - d.count(b"\r\n") + 1 if d else 0


def longest_file(paths: Sequence) -> int:
    """Index of the file of ``paths`` with the most rows (:func:`expmap_rows`; the first of equals). Its
    decimated phase 0 is the longest sequence any of them gives (a sequence's length grows with its file's).

    Every file is read as bytes (not parsed); the rows are counted exactly only for files whose line count could
    beat the best so far (one file when none has blank lines inside)."""
    paths = list(paths)
    bounds = [_rows_bound(read_bytes(p)) for p in paths]
    best, best_rows = None, -1
    for i in sorted(range(len(bounds)), key=lambda k: (-bounds[k], k)):
        if bounds[i] < best_rows or (bounds[i] == best_rows and i > best):
            break
        rows = expmap_rows(paths[i])
        if rows > best_rows or (rows == best_rows and i < best):
            best, best_rows = i, rows
    if best is None:
        raise ValueError("paths: no file to choose from")
    return best


def _longest_training(jobs: list) -> list:
    """The one training job of ``jobs`` whose file has the most rows ([] without training files)."""
    train = [j for j in jobs if j[0] == "train"]
    return [train[longest_file([meta["path"] for _, meta in train])]] if train else []


def load_h36m(root, *, validation: bool = False, actions: Sequence[str] | None = None,
              stride: int = 2, longest_training_only: bool = False) -> PredictionData:
    """Read a Human3.6M exp-map directory (the Jain et al. / Martinez et al. release, e.g. ``h3.6m/dataset``).

    Layout ``root/S{n}/{action}_{subaction}.txt``, 99 values per row at 50 Hz (:func:`read_expmap`,
    ``layout="h36m"``: triplet 0, the "corrupted" translation, is discarded and the root position is zero;
    ``q = quat_from_axis_angle(−r)``; ``quat_fix``). Each file is decimated by ``stride`` (50 → 25 Hz) keeping
    every phase for training (QuaterNet's ``_d0``, ``_d1``: 15 actions × 2 × 6 subjects × 2 = 360 sequences)
    and phase 0 for the test subject S5. Splits: train S1, S6, S7, S8, S9, S11; with ``validation=True`` S6
    moves to ``valid``. Subjects missing from the directory are simply absent; other ``S{n}`` folders are
    ignored.

    Parameters
    ----------
    root : path-like
    validation : bool
    actions : sequence of str, optional
        Subset of :data:`H36M_ACTIONS` to load (default: every action found).
    stride : int
        Decimation factor (2).
    longest_training_only : bool
        Parse only the training file with the most rows (:func:`longest_file`; every file's name is still
        checked): ``train`` holds its phases, ``valid`` and ``test`` are empty. What ``refimpl import`` needs (the
        skeleton, the frame time and whether a training window fits), without parsing the whole folder.

    Raises
    ------
    ValueError
        No ``S{n}`` folder; a ``.txt`` file whose name is not ``{action}_{1|2}.txt`` with a known action
        (message names the file); a malformed file (from :func:`read_expmap`, naming file and line); an action
        of S5 with only one of its two sub-sequences (names the missing file).
    """
    stride = _check_stride(stride)
    base = Path(root)
    if not base.is_dir():
        raise ValueError(f"root: {os.fspath(root)!r} is not a directory (expected S{{n}}/{{action}}_{{k}}.txt)")
    if actions is not None:
        actions = tuple(actions)
        bad = [a for a in actions if a not in H36M_ACTIONS]
        if bad:
            raise ValueError(f"actions: unknown {bad}; expected names from {list(H36M_ACTIONS)}")
    subjects = sorted((p for p in base.iterdir() if p.is_dir() and SUBJECT_DIR.match(p.name)),
                      key=lambda p: int(p.name[1:]))
    if not subjects:
        raise ValueError(f"{base}: no subject folders S1 … S11 (expected the layout S{{n}}/{{action}}_{{k}}.txt, "
                         f"e.g. the 'dataset' folder of h3.6m.zip)")
    split_of = {s: "train" for s in H36M_TRAIN_SUBJECTS}
    split_of[H36M_TEST_SUBJECT] = "test"
    if validation:
        split_of[H36M_VALID_SUBJECT] = "valid"
    splits = {"train": [], "valid": [], "test": []}
    order = {a: i for i, a in enumerate(H36M_ACTIONS)}
    jobs = []  # (split, sequence facts with the path), in the reading order
    for sdir in subjects:
        name = sdir.name
        if name not in split_of:
            continue
        found = {}
        for f in sorted(sdir.iterdir()):
            if f.suffix != ".txt" or f.name.startswith("."):
                continue
            m = _H36M_FILE.match(f.name)
            if m is None or m.group(1) not in H36M_ACTIONS or m.group(2) not in ("1", "2"):
                raise ValueError(f"{f}: expected a file named {{action}}_{{1|2}}.txt with an action from "
                                 f"{list(H36M_ACTIONS)}")
            if actions is None or m.group(1) in actions:
                found[(m.group(1), int(m.group(2)))] = f
        if name == H36M_TEST_SUBJECT:
            for action, sub in list(found):
                if (action, 3 - sub) not in found:
                    raise ValueError(f"{sdir / f'{action}_{3 - sub}.txt'}: missing (the test protocol draws from "
                                     f"both sub-sequences of {action!r})")
        jobs += [(split_of[name], dict(action=action, subaction=sub, subject=name, path=os.fspath(f)))
                 for (action, sub), f in sorted(found.items(), key=lambda kv: (order[kv[0][0]], kv[0][1]))]
    for split, meta in _longest_training(jobs) if longest_training_only else jobs:
        motion = read_expmap(meta["path"], layout="h36m")
        splits[split] += _decimate(motion, stride, (0,) if split == "test" else range(stride), meta)
    return PredictionData(dataset="h36m", skeleton=h36m_skeleton(), frame_time=stride / 50.0,
                          train=tuple(splits["train"]), valid=tuple(splits["valid"]), test=tuple(splits["test"]))


def load_cmu(root, *, stride: int = 2, drop_reference_frame: bool = True, frame_time: float = 1.0 / 120.0,
             longest_training_only: bool = False) -> PredictionData:
    """Read the CMU exp-map layout (Li et al. 2018 / DMGNN): ``root/{train,test}/{action}/{action}_{k}.txt``.

    117 values per row (:func:`read_expmap`, ``layout="cmu"``, 38-joint :func:`cmu_asf_skeleton`); the root
    position is set to zero, as for H3.6M (the task predicts rotations only). The first row of every file is
    the reference pose the BVH conversion added (not motion) and is dropped by default. Files are decimated by
    ``stride`` (2, as DMGNN's loader: 120 → 60 fps), every phase for training, phase 0 for testing. There is no
    validation split.

    Parameters
    ----------
    root : path-like
        E.g. ``refimpl/data/sample/expmap`` or ``../shared/data/dmgnn_cmu_expmap``.
    stride : int
    drop_reference_frame : bool
    frame_time : float
        Seconds per frame of the files (1/120: verified for ``walking_1`` = CMU 02_01; the other trials are
        undocumented).
    longest_training_only : bool
        Parse only the training file with the most rows (as :func:`load_h36m`'s).

    Raises
    ------
    ValueError
        No ``train`` and no ``test`` folder; a ``.txt`` file not named ``{action}_{k}.txt`` after its folder
        (names the file); malformed rows (from :func:`read_expmap`).
    """
    stride = _check_stride(stride)
    base = Path(root)
    if not base.is_dir():
        raise ValueError(f"root: {os.fspath(root)!r} is not a directory (expected {{train,test}}/{{action}}/…)")
    if not (base / "train").is_dir() and not (base / "test").is_dir():
        raise ValueError(f"{base}: no 'train' or 'test' folder "
                         f"(expected {{train,test}}/{{action}}/{{action}}_{{k}}.txt)")
    jobs = []  # (split, sequence facts with the path), in the reading order
    for split in ("train", "test"):
        sdir = base / split
        if sdir.is_dir():
            for adir in sorted(p for p in sdir.iterdir() if p.is_dir()):
                pattern = re.compile(rf"^{re.escape(adir.name)}_([0-9]+)\.txt$")
                for f in sorted(adir.iterdir(), key=lambda p: p.name):
                    if f.suffix != ".txt" or f.name.startswith("."):
                        continue
                    m = pattern.match(f.name)
                    if m is None:
                        raise ValueError(f"{f}: expected a file named {adir.name}_{{k}}.txt in folder {adir.name}")
                    jobs.append((split, dict(action=adir.name, subaction=int(m.group(1)), subject="cmu",
                                             path=os.fspath(f))))
    seqs = {"train": [], "test": []}
    for split, meta in _longest_training(jobs) if longest_training_only else jobs:
        seqs[split] += _decimate(_read_cmu(meta["path"], frame_time, drop_reference_frame), stride,
                                 (0,) if split == "test" else range(stride), meta)
    splits = {k: tuple(sorted(v, key=lambda s: (s.action, s.subaction, s.phase))) for k, v in seqs.items()}
    return PredictionData(dataset="cmu", skeleton=cmu_asf_skeleton(), frame_time=frame_time * stride,
                          train=splits["train"], valid=(), test=splits["test"])


def skeleton_of(dataset: str) -> Skeleton:
    """The skeleton of a dataset name (``h36m``: 32 joints; ``cmu``: the 38-joint ASF skeleton)."""
    if dataset == "h36m":
        return h36m_skeleton()
    if dataset == "cmu":
        return cmu_asf_skeleton()
    raise ValueError(f"dataset: expected 'h36m' or 'cmu', got {dataset!r}")


def training_windows(data: PredictionData, indices, rng: np.random.Generator, length: int) -> np.ndarray:
    """One random window of ``length`` frames from each training sequence ``indices`` (the published short-term
    batch: start uniform in ``[0, T_s − length]``, reference §6.3). ``(B,) -> (B, length, J, 4)`` float64."""
    out = []
    for i in np.asarray(indices):
        rot = data.train[int(i)].rotations
        start = int(rng.integers(0, rot.shape[0] - length + 1))
        out.append(rot[start:start + length])
    return np.stack(out)


def usable_training(data: PredictionData, length: int) -> PredictionData:
    """``data`` keeping the training sequences of at least ``length`` frames.

    Raises
    ------
    ValueError
        None is long enough.
    """
    keep = tuple(s for s in data.train if s.num_frames >= length)
    if not keep:
        raise ValueError(f"no training sequence has the {length} frames of a window (longest "
                         f"{max((s.num_frames for s in data.train), default=0)})")
    return dataclasses.replace(data, train=keep)


def stride_of(dataset: str, frame_time: float) -> int:
    """Decimation stride of a trained model: its frame time over the files' (CMU 1/120 s, H3.6M 1/50 s)."""
    base = {"cmu": 1.0 / 120.0, "h36m": 1.0 / 50.0}[dataset]
    return max(1, int(round(frame_time / base)))


# ---- what the task stores in a checkpoint (spec/robustness.md §9.1) ----

def _check_checkpoint(cfg: Mapping, config, where: str) -> None:
    """The prediction fields: ``dataset`` ``cmu`` or ``h36m`` (required), ``num_joints`` = the dataset skeleton's,
    ``frame_time`` (required: eval, generate and export read it) seconds in [1e-4, 10] and ``fps`` = 1 /
    ``frame_time`` (0.1 %)."""
    from refimpl.skeletons import cmu_asf_skeleton, h36m_skeleton

    require_fields(cfg, ("dataset", "frame_time"), where, "prediction")
    dataset = cfg["dataset"]
    if dataset not in ("cmu", "h36m"):
        raise ValueError(f"{where}: model_config.dataset: expected 'cmu' or 'h36m', got {kind_of(dataset)}")
    J = (cmu_asf_skeleton() if dataset == "cmu" else h36m_skeleton()).num_joints
    got = getattr(config, "num_joints", cfg.get("num_joints"))
    if got is not None and got != J:
        raise ValueError(f"{where}: model_config.num_joints {got!r} does not match the {dataset} skeleton's {J}")
    if "frame_time" in cfg:
        ft = cfg["frame_time"]
        if not isinstance(ft, (int, float)) or isinstance(ft, bool) or not (math.isfinite(ft) and 1e-4 <= ft <= 10):
            raise ValueError(f"{where}: model_config.frame_time: expected seconds in [1e-4, 10], got {kind_of(ft)}")
        fps = cfg.get("fps")
        if isinstance(fps, (int, float)) and not isinstance(fps, bool) and abs(fps * ft - 1) > 1e-3:
            raise ValueError(f"{where}: model_config.fps {fps!r} does not match frame_time {ft!r} (1 / frame_time)")


#: The prediction task's checkpoint schema (``refimpl.tasks.prediction.CHECKPOINT_SCHEMA``, deploy's QuaterNet loaders).
CHECKPOINT_SCHEMA = TaskSchema("prediction", check=_check_checkpoint)
