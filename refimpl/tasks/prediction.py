"""Short-term motion prediction: data, evaluation protocol and baselines (spec/prediction.md).

QuaterNet journal paper §4.1-4.2, Tables 1-2; the protocol is the one of the published evaluation
(quaternet_reference_code.md §6), which replicates Fragkiadaki et al. / Martinez et al.

* Data: Human3.6M exp-map text files ``S{n}/{action}_{subaction}.txt`` (99 values per row, 50 Hz;
  :func:`load_h36m`) and the CMU exp-map layout ``{train,test}/{action}/{action}_{k}.txt`` (117 values per row;
  :func:`load_cmu`), read by :func:`refimpl.expmap.read_expmap` (``q = quat_from_axis_angle(−r)``, ``quat_fix``,
  H3.6M triplet 0 discarded), decimated keeping every stride phase for training (``_d0``, ``_d1``) and phase 0
  for testing.
* Protocol (:class:`Protocol`, :func:`make_protocol`): a fresh ``RandomState(1234567890)`` per action, draws
  alternating over the action's test sub-sequences (H3.6M: 1, 2, 1, 2, ...), starts in
  ``[low, T − prefix − target)``; ``samples_per_sequence`` = 4 (standard) or 128 (dense, Table 2).
* Error (:func:`euler_errors`): zyx Euler angles of prediction and ground truth, joint 0 dropped, Euclidean norm
  over the remaining ``3(J − 1)`` values per frame, averaged over the windows of an action (:func:`evaluate`).
* Methods: any callable ``method(prefix, n_future) -> quaternions`` (the *method interface*, see
  :func:`evaluate`); baselines :func:`zero_velocity` and :func:`running_average` (Table 1's top rows).
* Output: :func:`format_table` (text) and :func:`write_results_json` (atomic).

Shape legend: N windows, B batch, P prefix frames, K predicted (target) frames, T frames, J joints,
H reported horizons.
"""
from __future__ import annotations

import dataclasses
import json
import os
import re
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.expmap import read_expmap
from refimpl.preprocess import downsample, fix_antipodal
from refimpl.quat import euler_from_quat, quat_from_euler
from refimpl.skeleton import Skeleton
from refimpl.skeletons import cmu_asf_skeleton, h36m_skeleton

__all__ = [
    "H36M_ACTIONS", "H36M_TRAIN_SUBJECTS", "H36M_TEST_SUBJECT", "H36M_VALID_SUBJECT", "SEED",
    "PredictionSequence", "PredictionData", "load_h36m", "load_cmu",
    "Protocol", "make_protocol", "window_starts", "evaluation_windows",
    "euler_errors", "evaluate", "PredictionResult",
    "zero_velocity", "running_average", "baseline_methods",
    "format_table", "results_to_dict", "write_results_json",
    "NAME", "SAMPLE_EXPMAP_DIR", "add_train_options", "add_eval_options", "resolve_data", "train_datasets",
    "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint", "trained_fields", "skeleton_of",
    "onnx_method", "methods", "evaluate_all", "task_evaluate", "canonical_prefix", "training_windows",
    "usable_training", "eval_protocol", "average_curves", "stride_of", "load_clip", "Prediction",
    "make_prediction", "render_prediction", "verify_inputs", "TABLE2_HORIZONS_MS", "table2_protocol", "eval_actions",
]

# The published evaluation's action order (quaternet_reference_code.md §6.6).
H36M_ACTIONS = ("walking", "eating", "smoking", "discussion", "directions", "greeting", "phoning", "posing",
                "purchases", "sitting", "sittingdown", "takingphoto", "waiting", "walkingdog", "walkingtogether")
H36M_TRAIN_SUBJECTS = ("S1", "S6", "S7", "S8", "S9", "S11")
H36M_TEST_SUBJECT = "S5"
H36M_VALID_SUBJECT = "S6"
SEED = 1234567890

_H36M_FILE = re.compile(r"^([a-z]+)_([0-9]+)\.txt$")
_SUBJECT_DIR = re.compile(r"^S[0-9]+$")


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


def load_h36m(root, *, validation: bool = False, actions: Sequence[str] | None = None,
              stride: int = 2) -> PredictionData:
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
    subjects = sorted((p for p in base.iterdir() if p.is_dir() and _SUBJECT_DIR.match(p.name)),
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
        split = split_of[name]
        for (action, sub), f in sorted(found.items(), key=lambda kv: (order[kv[0][0]], kv[0][1])):
            motion = read_expmap(f, layout="h36m")
            meta = dict(action=action, subaction=sub, subject=name, path=os.fspath(f))
            splits[split] += _decimate(motion, stride, (0,) if split == "test" else range(stride), meta)
    return PredictionData(dataset="h36m", skeleton=h36m_skeleton(), frame_time=stride / 50.0,
                          train=tuple(splits["train"]), valid=tuple(splits["valid"]), test=tuple(splits["test"]))


def load_cmu(root, *, stride: int = 2, drop_reference_frame: bool = True, frame_time: float = 1.0 / 120.0
             ) -> PredictionData:
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
    splits = {}
    for split in ("train", "test"):
        sdir = base / split
        seqs = []
        if sdir.is_dir():
            for adir in sorted(p for p in sdir.iterdir() if p.is_dir()):
                pattern = re.compile(rf"^{re.escape(adir.name)}_([0-9]+)\.txt$")
                for f in sorted(adir.iterdir(), key=lambda p: p.name):
                    if f.suffix != ".txt" or f.name.startswith("."):
                        continue
                    m = pattern.match(f.name)
                    if m is None:
                        raise ValueError(f"{f}: expected a file named {adir.name}_{{k}}.txt in folder {adir.name}")
                    motion = read_expmap(f, layout="cmu", frame_time=frame_time, use_root_position=False)
                    if drop_reference_frame:
                        if motion.num_frames < 2:
                            raise ValueError(f"{f}: expected at least 2 rows (reference pose + motion), "
                                             f"got {motion.num_frames}")
                        motion = dataclasses.replace(motion, rotations=motion.rotations[1:],
                                                     root_positions=motion.root_positions[1:])
                    meta = dict(action=adir.name, subaction=int(m.group(1)), subject="cmu", path=os.fspath(f))
                    seqs += _decimate(motion, stride, (0,) if split == "test" else range(stride), meta)
        splits[split] = tuple(sorted(seqs, key=lambda s: (s.action, s.subaction, s.phase)))
    return PredictionData(dataset="cmu", skeleton=cmu_asf_skeleton(), frame_time=frame_time * stride,
                          train=splits["train"], valid=(), test=splits["test"])


# ------------------------------------------------------------------------------------------------------------
# protocol
# ------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Protocol:
    """The window sampler and the reported horizons of an evaluation.

    Attributes
    ----------
    name : str
        ``"standard"`` (4 samples per sequence, Table 1) or ``"dense"`` (128, Table 2), or any label.
    samples_per_sequence : int
        Draws per test sub-sequence (per action: this times the number of sub-sequences).
    prefix_length, target_length : int
        P conditioning frames, K predicted frames (50, 100).
    low : int
        Smallest window start (16 for H3.6M, as Fragkiadaki et al.).
    seed : int
        ``RandomState`` seed, fresh for every action (1234567890).
    horizons_ms : tuple of float
        Reported horizons; frame ``k`` (0-based) of the prediction is at ``(k + 1) · frame_ms``.
    frame_ms : float
        Milliseconds per frame used to label horizons (40 at 25 Hz).
    round_horizons : bool
        False (default): every horizon must be a whole number of frames. True (:func:`table2_protocol`, at the
        data's real frame rate): the nearest frame, ``max(1, round(ms / frame_ms))``; its real time is
        :attr:`horizon_times_ms`.
    """

    name: str
    samples_per_sequence: int
    prefix_length: int = 50
    target_length: int = 100
    low: int = 16
    seed: int = SEED
    horizons_ms: tuple = (80, 160, 320, 400, 560, 1000, 2000, 3000, 4000)
    frame_ms: float = 40.0
    round_horizons: bool = False

    def __post_init__(self):
        for field in ("samples_per_sequence", "prefix_length", "target_length"):
            v = getattr(self, field)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{field}: expected a positive int, got {v!r}")
        if isinstance(self.low, bool) or not isinstance(self.low, (int, np.integer)) or self.low < 0:
            raise ValueError(f"low: expected a non-negative int, got {self.low!r}")
        if not (np.isfinite(self.frame_ms) and self.frame_ms > 0):
            raise ValueError(f"frame_ms: expected a positive number, got {self.frame_ms!r}")
        object.__setattr__(self, "horizons_ms", tuple(self.horizons_ms))
        self.horizon_frames  # validates

    @property
    def horizon_frames(self) -> tuple:
        """0-based prediction frame of each horizon, ``round(ms / frame_ms) − 1``."""
        frames = []
        for ms in self.horizons_ms:
            k = ms / self.frame_ms
            if self.round_horizons:
                k = max(1, int(round(k)))
                if k > self.target_length:
                    raise ValueError(f"horizons_ms: {ms} ms is frame {k} at {self.frame_ms:.4g} ms per frame, "
                                     f"beyond the {self.target_length}-frame target")
            if abs(k - round(k)) > 1e-9 or not 1 <= round(k) <= self.target_length:
                raise ValueError(f"horizons_ms: {ms} ms is not a multiple of {self.frame_ms} ms within the "
                                 f"{self.target_length}-frame target")
            frames.append(int(round(k)) - 1)
        return tuple(frames)

    @property
    def horizon_times_ms(self) -> tuple:
        """Time of each horizon's frame, ``(k + 1) · frame_ms`` (equal to ``horizons_ms`` unless rounded)."""
        return tuple((k + 1) * self.frame_ms for k in self.horizon_frames)


#: The horizons of the dual-quaternion paper's Table 2 (Andreou et al.), out to 4 s.
TABLE2_HORIZONS_MS = (80, 160, 320, 400, 600, 800, 1000, 2000, 3000, 4000)


def table2_protocol(data: "PredictionData", name: str = "standard", samples_per_sequence: int | None = None, *,
                    prefix_length: int = 50, actions: Sequence[str] | None = None,
                    horizons_ms: Sequence[float] = TABLE2_HORIZONS_MS) -> Protocol:
    """The long-horizon protocol (Table 2 of the dual-quaternion paper: 80 ms … 4 s) at the data's real rate.

    Each horizon becomes the nearest frame at ``data.frame_time`` (``round(ms / frame_ms)``, at least 1; CMU at
    60 fps: 80 ms → frame 5 = 83 ms, 160 → 10 = 167 ms, 320 → 19 = 317 ms, the others exact). A window needs
    ``P + K`` frames with starts in ``[low, T − P − K)`` (``low`` as :func:`make_protocol`: 16 for H3.6M, 0 for
    CMU), so the horizons kept are those whose frame ``K`` fits the shortest test sequence of every evaluated
    action (``K <= T_min − P − low − 1``); ``target_length`` = the last kept horizon's frame. The sampler, seed
    and samples per sequence are those of :func:`make_protocol` (``name`` standard = 4, dense = 128).

    Parameters
    ----------
    data : PredictionData
    name : str
        ``"standard"`` or ``"dense"``.
    samples_per_sequence : int, optional
    prefix_length : int
        P (50, the models' training prefix).
    actions : sequence of str, optional
        The actions the horizons must fit (default every test action).
    horizons_ms : sequence of float

    Raises
    ------
    ValueError
        Not even the first horizon fits (names the shortest sequence).
    """
    if name not in ("standard", "dense"):
        raise ValueError(f"protocol: expected 'standard' or 'dense', got {name!r}")
    base = make_protocol(data.dataset, dense=name == "dense", samples_per_sequence=samples_per_sequence)
    acts = data.test_actions() if actions is None else tuple(actions)
    seqs = [s for s in data.test if s.action in acts]
    if not seqs:
        raise ValueError(f"actions: no test sequence for {list(acts)}; present: {list(data.test_actions())}")
    shortest = min(seqs, key=lambda s: s.num_frames)
    k_max = shortest.num_frames - prefix_length - base.low - 1
    frame_ms = float(data.frame_time) * 1000.0
    frames = [max(1, int(round(ms / frame_ms))) for ms in horizons_ms]
    kept = [(ms, k) for ms, k in zip(horizons_ms, frames) if k <= k_max]
    if not kept:
        raise ValueError(f"{shortest.path}: {shortest.num_frames} frames leave at most {max(k_max, 0)} predicted "
                         f"frames after a {prefix_length}-frame prefix; {horizons_ms[0]} ms needs {frames[0]}")
    return dataclasses.replace(base, prefix_length=prefix_length, target_length=max(k for _, k in kept),
                               horizons_ms=tuple(ms for ms, _ in kept), frame_ms=frame_ms, round_horizons=True)


def make_protocol(dataset: str = "h36m", dense: bool = False, samples_per_sequence: int | None = None
                  ) -> Protocol:
    """The evaluation protocol of a dataset.

    * ``"h36m"``: P = 50, K = 100, starts in ``[16, T − 150)``, horizons 80 … 4000 ms at 40 ms per frame.
    * ``"cmu"`` (our adaptation, spec/prediction.md §5): the test trials are short (running: 81 decimated
      frames), so K = 25 and starts in ``[0, T − 75)``; horizons 80 … 1000 ms at a *nominal* 40 ms per frame,
      i.e. the same frame indices as the H3.6M columns (a decimated 120 fps trial really has 16.7 ms per frame).

    ``dense=False`` gives 4 samples per sequence (``"standard"``), ``dense=True`` 128 (``"dense"``);
    ``samples_per_sequence`` overrides the count (for the variance study of the paper's Fig. 7).
    """
    if dataset not in ("h36m", "cmu"):
        raise ValueError(f"dataset: expected 'h36m' or 'cmu', got {dataset!r}")
    name = "dense" if dense else "standard"
    n = (128 if dense else 4) if samples_per_sequence is None else samples_per_sequence
    if dataset == "h36m":
        return Protocol(name=name, samples_per_sequence=n)
    return Protocol(name=name, samples_per_sequence=n, prefix_length=50, target_length=25, low=0,
                    horizons_ms=(80, 160, 320, 400, 560, 1000), frame_ms=40.0)


def window_starts(lengths: Sequence[int], protocol: Protocol) -> list:
    """The sampler of the published evaluation, for one action.

    A fresh ``np.random.RandomState(protocol.seed)``; ``samples_per_sequence`` rounds, each drawing one start
    per sub-sequence in order (H3.6M: sub-sequence 1, then 2), ``rng.randint(low, T_s − P − K)`` (upper bound
    exclusive). The standard protocol gives 1, 2, 1, 2, 1, 2, 1, 2.

    Parameters
    ----------
    lengths : sequence of int
        Frames T_s of each sub-sequence, in sub-sequence order.
    protocol : Protocol

    Returns
    -------
    list of (sequence_index, start) in draw order; window = frames ``[start, start + P + K)``.

    Raises
    ------
    ValueError
        When some ``T_s − P − K <= low`` (the range is empty).
    """
    lengths = [int(t) for t in lengths]
    if not lengths:
        raise ValueError("lengths: expected at least one sub-sequence")
    P, K, low = protocol.prefix_length, protocol.target_length, protocol.low
    for i, t in enumerate(lengths):
        if t - P - K <= low:
            raise ValueError(f"lengths[{i}]: a sequence of {t} frames is too short for starts in "
                             f"[{low}, T − {P} − {K}); needs more than {low + P + K} frames")
    rng = np.random.RandomState(protocol.seed)
    return [(i, int(rng.randint(low, t - P - K))) for _ in range(protocol.samples_per_sequence)
            for i, t in enumerate(lengths)]


def evaluation_windows(data: PredictionData, action: str, protocol: Protocol) -> tuple:
    """The test windows of one action.

    Returns
    -------
    prefix : ndarray (N, P, J, 4)
    target : ndarray (N, K, J, 4)
        Ground truth of the K frames after the prefix.
    windows : list of (path, start)
        Source file and first frame (decimated indexing) of each window, in draw order.
    """
    seqs = sorted((s for s in data.test if s.action == action), key=lambda s: s.subaction)
    if not seqs:
        raise ValueError(f"action: no test sequence for {action!r}; present: {list(data.test_actions())}")
    try:
        draws = window_starts([s.num_frames for s in seqs], protocol)
    except ValueError as e:
        raise ValueError(f"{action}: {e} (files {[s.path for s in seqs]}, frames "
                         f"{[s.num_frames for s in seqs]})") from None
    P, K = protocol.prefix_length, protocol.target_length
    chunks = np.stack([seqs[i].rotations[s:s + P + K] for i, s in draws])     # (N, P + K, J, 4)
    return chunks[:, :P].copy(), chunks[:, P:].copy(), [(seqs[i].path, s) for i, s in draws]


# ------------------------------------------------------------------------------------------------------------
# error and evaluation
# ------------------------------------------------------------------------------------------------------------

def euler_errors(pred, target, *, drop_joints: Sequence[int] = (0,), wrap: bool = False,
                 mask_constant: bool = False) -> np.ndarray:
    """Per-window, per-frame Euler-angle error of the published evaluation.

    ``e[n, k] = ‖ E(pred[n, k]) − E(target[n, k]) ‖₂`` over the ``3 · (J − len(drop_joints))`` zyx Euler
    angles (:func:`refimpl.euler_from_quat`, order ``"zyx"``) of the joints kept (joint 0, the global rotation,
    is dropped).

    Parameters
    ----------
    pred, target : array_like (N, K, J, 4)
        Non-zero quaternions (scale and sign are irrelevant).
    drop_joints : sequence of int
    wrap : bool
        Wrap each angle difference to ``[−π, π)`` (the best match modulo 2π). The published evaluation does
        not (default False): an angle crossing ±π between prediction and ground truth costs about 2π.
    mask_constant : bool
        Martinez et al.'s rule: per window, keep only the angles whose ground-truth standard deviation over
        the K frames exceeds 1e-4 (QuaterNet's evaluator keeps all; default False).

    Returns
    -------
    ndarray (N, K)
    """
    pred = np.asarray(pred, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if target.ndim != 4 or target.shape[-1] != 4:
        raise ValueError(f"target: expected shape (N, K, J, 4), got {target.shape}")
    if pred.shape != target.shape:
        raise ValueError(f"pred: expected shape {target.shape} (as target), got {pred.shape}")
    J = target.shape[2]
    keep = np.setdiff1d(np.arange(J), np.asarray(drop_joints, dtype=int))
    gt = euler_from_quat(target[:, :, keep], "zyx")                           # (N, K, J', 3)
    d = euler_from_quat(pred[:, :, keep], "zyx") - gt                         # (N, K, J', 3)
    if wrap:
        d = np.mod(d + np.pi, 2 * np.pi) - np.pi
    d = d.reshape(d.shape[0], d.shape[1], -1)                                  # (N, K, 3J')
    if mask_constant:
        d = d * (np.std(gt.reshape(d.shape), axis=1, keepdims=True) > 1e-4)
    return np.sqrt(np.sum(d * d, axis=-1))


@dataclasses.dataclass(frozen=True, eq=False)
class PredictionResult:
    """Errors of one method under one protocol.

    Attributes
    ----------
    dataset : str
    protocol : Protocol
    method : str
    curves : dict action -> ndarray (K,)
        Mean error per predicted frame over the action's windows.
    windows_per_action : dict action -> int
    frame_time : float
        Real seconds per frame of the evaluated data (the horizon labels use ``protocol.frame_ms``; they differ
        for the CMU adaptation).
    """

    dataset: str
    protocol: Protocol
    method: str
    curves: dict
    windows_per_action: dict
    frame_time: float

    @property
    def actions(self) -> dict:
        """action -> list of errors at ``protocol.horizons_ms``."""
        f = list(self.protocol.horizon_frames)
        return {a: [float(v) for v in c[f]] for a, c in self.curves.items()}

    @property
    def average(self) -> list:
        """Mean over the actions present, per horizon (the paper's "Average" row)."""
        rows = np.array(list(self.actions.values()))
        return [float(v) for v in rows.mean(axis=0)]


def evaluate(method: Callable, data: PredictionData, protocol: Protocol, *, method_name: str = "method",
             actions: Sequence[str] | None = None, wrap: bool = False, mask_constant: bool = False,
             batch_size: int | None = None, progress: Callable[[str], None] | None = None) -> PredictionResult:
    """Run a prediction method on the test windows of every action and measure it.

    **Method interface**: ``method(prefix, n_future) -> ndarray (B, n_future, J, 4)`` where ``prefix`` is a
    read-only float64 array (B, P, J, 4) of unit quaternions ``(w, x, y, z)`` in the dataset skeleton's joint
    order (root first), antipodally continuous over time, and ``n_future = K``. The output may have any
    non-zero scale and either sign per quaternion (only the rotation is scored). A network plugs in with a
    closure, e.g. ``lambda prefix, k: model_predict(params, prefix, k)``.

    Parameters
    ----------
    method : callable
    data : PredictionData
    protocol : Protocol
    method_name : str
        Label in tables and JSON.
    actions : sequence of str, optional
        Default: every test action present.
    wrap, mask_constant : bool
        See :func:`euler_errors` (defaults = the published evaluation).
    batch_size : int, optional
        Windows per call (default: all windows of an action in one call).
    progress : callable(str), optional
        Called with a line per action.

    Returns
    -------
    PredictionResult
        (The application layer's form ``evaluate(data, {name: method})`` returns :func:`task_evaluate`'s list.)
    """
    if isinstance(method, PredictionData) and isinstance(data, Mapping):  # the task interface's form
        return task_evaluate(method, data)
    if not callable(method):
        raise ValueError(f"method: expected a callable method(prefix, n_future), got {type(method).__name__}")
    acts = data.test_actions() if actions is None else tuple(actions)
    if not acts:
        raise ValueError(f"data: no test sequences to evaluate ({data.dataset})")
    if batch_size is not None and (isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer))
                                   or batch_size < 1):
        raise ValueError(f"batch_size: expected a positive int or None, got {batch_size!r}")
    curves, counts = {}, {}
    K = protocol.target_length
    for action in acts:
        prefix, target, _ = evaluation_windows(data, action, protocol)
        prefix.flags.writeable = False
        step = prefix.shape[0] if batch_size is None else int(batch_size)
        preds = []
        for i in range(0, prefix.shape[0], step):
            p = np.asarray(method(prefix[i:i + step], K))
            want = (min(step, prefix.shape[0] - i), K) + prefix.shape[2:]
            if p.shape != want:
                raise ValueError(f"method {method_name!r}: expected output shape {want} (B, n_future, J, 4), "
                                 f"got {p.shape}")
            if p.dtype.kind not in "fiu" or not np.all(np.isfinite(p)):
                raise ValueError(f"method {method_name!r}: the prediction for {action!r} is not finite real numbers")
            preds.append(p)
        err = euler_errors(np.concatenate(preds), target, wrap=wrap, mask_constant=mask_constant)   # (N, K)
        curves[action] = err.mean(axis=0)
        counts[action] = int(err.shape[0])
        if progress is not None:
            progress(f"{method_name} {action}: {counts[action]} windows, "
                     + " ".join(f"{v:.3f}" for v in curves[action][list(protocol.horizon_frames)]))
    return PredictionResult(dataset=data.dataset, protocol=protocol, method=method_name, curves=curves,
                            windows_per_action=counts, frame_time=float(data.frame_time))


# ------------------------------------------------------------------------------------------------------------
# baselines (Martinez et al. 2017; Table 1's top rows)
# ------------------------------------------------------------------------------------------------------------

def _check_prefix(prefix, n_future) -> np.ndarray:
    x = np.asarray(prefix, dtype=np.float64)
    if x.ndim != 4 or x.shape[-1] != 4 or x.shape[1] < 1:
        raise ValueError(f"prefix: expected shape (B, P, J, 4) with P >= 1, got {x.shape}")
    if isinstance(n_future, bool) or not isinstance(n_future, (int, np.integer)) or n_future < 1:
        raise ValueError(f"n_future: expected a positive int, got {n_future!r}")
    return x


def zero_velocity(prefix, n_future: int) -> np.ndarray:
    """Repeat the last prefix frame: ``(B, P, J, 4) -> (B, n_future, J, 4)``."""
    x = _check_prefix(prefix, n_future)
    return np.repeat(x[:, -1:], n_future, axis=1)


def running_average(k: int) -> Callable:
    """The running-average baseline over the last ``k`` prefix frames, as a method.

    Martinez et al. average the Euler angles (the zyx angles of the evaluation) of the last ``k`` frames
    componentwise and hold the result: ``ē = mean_{t=P−k}^{P−1} E(q_t)``, prediction ``quat_from_euler(ē, "zyx")``
    for every future frame. (The mean of angles in range stays in range, so the evaluation's Euler conversion
    recovers ``ē``; no wrap-around handling, as published: averaging 3.1 and −3.1 gives 0.)
    ``k = 1`` is :func:`zero_velocity` up to rounding.
    """
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k: expected a positive int, got {k!r}")
    k = int(k)

    def method(prefix, n_future: int) -> np.ndarray:
        x = _check_prefix(prefix, n_future)
        if x.shape[1] < k:
            raise ValueError(f"prefix: expected at least {k} frames for a running average over {k}, got {x.shape}")
        mean = euler_from_quat(x[:, -k:], "zyx").mean(axis=1)                   # (B, J, 3)
        return np.repeat(quat_from_euler(mean, "zyx")[:, None], n_future, axis=1)

    method.__name__ = f"running_average_{k}"
    method.__qualname__ = method.__name__
    return method


def baseline_methods() -> dict:
    """``{"zero-velocity", "run. avg. 2", "run. avg. 4"}`` -> method (Table 1's top rows)."""
    return {"run. avg. 4": running_average(4), "run. avg. 2": running_average(2), "zero-velocity": zero_velocity}


# ------------------------------------------------------------------------------------------------------------
# output
# ------------------------------------------------------------------------------------------------------------

def format_table(results: Sequence[PredictionResult], decimals: int = 2) -> str:
    """A text table shaped like the paper's: per action a block with one row per method, one column per
    horizon (ms), then the "average" block over the actions present."""
    results = [results] if isinstance(results, PredictionResult) else list(results)
    if not results:
        return ""
    first = results[0]
    for r in results[1:]:
        if r.protocol.horizons_ms != first.protocol.horizons_ms:
            raise ValueError("results: every result must use the same horizons")
    hs = [f"{h:g}" for h in first.protocol.horizons_ms]
    name_w = max(14, max(len(r.method) for r in results) + 4)
    col_w = max(decimals + 3, max(len(h) for h in hs))

    def row(label, values):
        return f"{label:<{name_w}}|" + "|".join(f" {v:>{col_w}} " for v in values)

    windows = sorted({n for r in results for n in r.windows_per_action.values()})
    lines = [f"dataset {first.dataset}, protocol {first.protocol.name} ({first.protocol.samples_per_sequence} "
             f"samples per sequence, {'/'.join(map(str, windows))} windows per action)"]
    if first.protocol.round_horizons:
        lines.append("horizon frames at " + f"{first.protocol.frame_ms:.4g} ms per frame: " + ", ".join(
            f"{h:g} ms = frame {k + 1} ({t:.0f} ms)" for h, k, t in zip(first.protocol.horizons_ms,
                                                                      first.protocol.horizon_frames,
                                                                      first.protocol.horizon_times_ms)))
    elif abs(first.frame_time * 1000 - first.protocol.frame_ms) > 1e-6:
        lines.append(f"horizons at a nominal {first.protocol.frame_ms:g} ms per frame; the data has "
                     f"{first.frame_time * 1000:.1f} ms per frame")
    lines.append(row("milliseconds", hs))
    actions = list(dict.fromkeys(a for r in results for a in r.curves))
    for a in actions + ["average"]:
        lines.append(a)
        for r in results:
            vals = r.average if a == "average" else r.actions.get(a)
            if vals is not None:
                lines.append(row("  " + r.method, [f"{v:.{decimals}f}" for v in vals]))
    return "\n".join(line.rstrip() for line in lines)


def results_to_dict(result: PredictionResult) -> dict:
    """The JSON object of one result: ``{"dataset", "protocol", "method", "samples_per_sequence",
    "horizons_ms", "actions": {action: [error per horizon]}, "average": [...]}`` plus ``"horizon_frames"``
    (0-based), ``"horizon_times_ms"`` (the real time of each horizon's frame at ``frame_ms``), ``"frame_ms"``
    (the labels' ms per frame), ``"prefix_length"``, ``"target_length"``, ``"seed"``,
    ``"windows_per_action"`` and ``"data_frame_time_s"`` (the data's real seconds per frame)."""
    p = result.protocol
    return {"dataset": result.dataset, "protocol": p.name, "method": result.method,
            "samples_per_sequence": int(p.samples_per_sequence),
            "horizons_ms": [int(h) if float(h).is_integer() else float(h) for h in p.horizons_ms],
            "actions": result.actions, "average": result.average,
            "horizon_frames": list(p.horizon_frames), "frame_ms": float(p.frame_ms),
            "prefix_length": int(p.prefix_length), "target_length": int(p.target_length), "seed": int(p.seed),
            "horizon_times_ms": [float(t) for t in p.horizon_times_ms],
            "windows_per_action": dict(result.windows_per_action),
            "data_frame_time_s": float(result.frame_time)}


def write_results_json(path, results) -> None:
    """Write one result (an object) or several (a list of objects) as JSON, atomically."""
    if isinstance(results, PredictionResult):
        doc = results_to_dict(results)
    else:
        doc = [results_to_dict(r) for r in results]
        if not doc:
            raise ValueError("results: expected at least one PredictionResult")
    atomic_write_text(path, json.dumps(doc, indent=1, allow_nan=False) + "\n")


# ------------------------------------------------------------------------------------------------------------
# the task interface of the application layer (spec/architecture.md §tasks; spec/prediction.md §7)
# ------------------------------------------------------------------------------------------------------------

NAME = "prediction"
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


def resolve_data(data: str, *, downsample: int = 2) -> PredictionData:
    """The data of ``--data``: ``"sample"`` (:data:`SAMPLE_EXPMAP_DIR`), a folder like ``../shared/data``
    (its ``dmgnn_cmu_expmap``), a CMU exp-map folder (``train/``, ``test/``: :func:`load_cmu`) or a Human3.6M
    folder (``S1`` … ``S11``: :func:`load_h36m`).

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
            return load_cmu(root, stride=downsample)
        if any(p.is_dir() and _SUBJECT_DIR.match(p.name) for p in root.iterdir()):
            return load_h36m(root, stride=downsample)
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


def skeleton_of(dataset: str) -> Skeleton:
    """The skeleton of a dataset name (``h36m``: 32 joints; ``cmu``: the 38-joint ASF skeleton)."""
    if dataset == "h36m":
        return h36m_skeleton()
    if dataset == "cmu":
        return cmu_asf_skeleton()
    raise ValueError(f"dataset: expected 'h36m' or 'cmu', got {dataset!r}")


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

            y = np.asarray(runtime.predict(dq_frames_from_rotations(x, skeleton), int(n_future)), np.float64)
            return rotations_from_dq_frames(y, skeleton.parents)
        return np.asarray(runtime.predict(x, int(n_future)), dtype=np.float64)

    return network_onnx


def methods(networks: Mapping[str, Callable] | None = None, *, fps: float | None = None) -> dict:
    """``name -> method(prefix, n_future)``: the baselines in Table 1's order (zero-velocity, running averages
    over 2 and 4 frames), then the given networks' methods."""
    base = baseline_methods()
    return {**{k: base[k] for k in ("zero-velocity", "run. avg. 2", "run. avg. 4")}, **dict(networks or {})}


def evaluate_all(data: PredictionData, methods_by_name: Mapping[str, Callable], protocol: Protocol | None = None,
                 *, progress: Callable[[str], None] | None = None, actions: Sequence[str] | None = None) -> list:
    """:func:`evaluate` of every method under ``protocol`` (default: the dataset's standard one) on ``actions``
    (default all); a list of :class:`PredictionResult` in the methods' order."""
    protocol = make_protocol(data.dataset) if protocol is None else protocol
    return [evaluate(m, data, protocol, method_name=name, progress=progress, actions=actions)
            for name, m in methods_by_name.items()]


def task_evaluate(test_ds: PredictionData, methods_by_name: Mapping[str, Callable]) -> list:
    """The task interface's ``evaluate(test_ds, methods)`` (standard protocol): :func:`evaluate_all`."""
    return evaluate_all(test_ds, methods_by_name)


def canonical_prefix(prefix) -> np.ndarray:
    """The published predict's canonicalisation (reference §6.5, §12 item 12): quaternions -> zyx Euler ->
    quaternions -> ``quat_fix`` over time. ``(B, P, J, 4) -> (B, P, J, 4)``, the same rotations."""
    from refimpl.quat import quat_fix

    x = np.asarray(prefix, dtype=np.float64)
    q = quat_from_euler(euler_from_quat(x, "zyx"), "zyx")  # (B, P, J, 4)
    return np.ascontiguousarray(np.swapaxes(quat_fix(np.swapaxes(q, 0, 1)), 0, 1))


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


def average_curves(results: Sequence[PredictionResult]) -> dict:
    """``method -> (K,)`` mean per-frame error over the actions (for a plot)."""
    return {r.method: np.mean(np.stack(list(r.curves.values())), axis=0) for r in results}


def stride_of(dataset: str, frame_time: float) -> int:
    """Decimation stride of a trained model: its frame time over the files' (CMU 1/120 s, H3.6M 1/50 s)."""
    base = {"cmu": 1.0 / 120.0, "h36m": 1.0 / 50.0}[dataset]
    return max(1, int(round(frame_time / base)))


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
                    frame_time: float, method_name: str = "network", name: str = "prediction") -> Prediction:
    """Predict ``k`` frames after frame ``frame`` of ``rotations (F, J, 4)`` from the ``prefix_length`` frames
    ending there (``method(prefix (1, P, J, 4), k)``).

    Raises
    ------
    UsageError
        ``frame`` outside ``[prefix_length − 1, F − 1]``.
    """
    from refimpl.errors import UsageError
    from refimpl.motion import Motion

    rot = np.asarray(rotations, dtype=np.float64)
    F = rot.shape[0]
    if not prefix_length - 1 <= frame <= F - 1:
        raise UsageError(f"--source-frame must lie in [{prefix_length - 1}, {F - 1}] (a {prefix_length}-frame "
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
    and the predicted ones, as a PNG strip and / or a GIF."""
    from refimpl.render import render_gif, render_strip

    a = max(0, pr.start - context)
    parents = np.asarray(pr.motion.skeleton.parents)
    pred = pr.motion.positions()[a:]
    gt = pr.truth.positions()[a:] if pr.truth is not None else pred
    hl = (pr.start - a, pr.stop - a)
    labels = ("ground truth", pr.method) if pr.truth is not None else (pr.method, "")
    written = []
    if png:
        n = pred.shape[0]
        frames = sorted(set([0, hl[0] - 1] + list(range(hl[0], hl[1], max(1, (hl[1] - hl[0]) // 6))) + [n - 1]))
        written.append(render_strip(png, gt, parents, prediction=pred if pr.truth is not None else None,
                                    frames=frames, highlight=hl, labels=labels, title=title,
                                    frame_time=pr.motion.frame_time))
    if gif:
        written.append(render_gif(gif, gt, parents, prediction=pred if pr.truth is not None else None,
                                  fps=pr.motion.fps, highlight=hl, labels=labels, title=title))
    return written


def verify_inputs(model, rng: np.random.Generator, batch: int = 8) -> tuple:
    """``(prefix (B, P, J, 4),)`` for ``refimpl export``'s check: real CMU test windows of the embedded sample
    (prefix of the model's training length) for a CMU model, small random rotations otherwise."""
    from refimpl.quat import quat_from_axis_angle

    P = int(getattr(model.config, "prefix_length", 50))
    if model.extra.get("dataset") == "cmu":
        data = load_cmu(SAMPLE_EXPMAP_DIR, stride=stride_of("cmu", model.extra["frame_time"]))
        windows = [s.rotations[i:i + P] for s in data.test
                   for i in rng.integers(0, s.num_frames - P + 1, size=batch)]
        return (np.stack(windows[:batch]),)
    J = int(model.config.num_joints)
    return (quat_from_axis_angle(0.3 * rng.standard_normal((batch, P, J, 3))),)
