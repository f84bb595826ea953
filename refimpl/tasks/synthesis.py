"""Long-term motion synthesis with acRNN on the CMU salsa takes: data, split, windows, seeds and evaluation
(the dual-quaternion paper's §7.1 protocol; spec/acrnn.md §5-6).

Protocol (our choices where the paper is silent are marked in spec/acrnn.md):

* Files: ``../shared/data/acrnn_cmu_salsa/NN.bvh`` (acRNN's DAZ-style skeleton), read at **60 fps** (the headers
  say 120, README of the folder), decimated to **30 fps** (every 2nd frame, phase 0), End Sites removed (43
  joints), lengths scaled by 0.01 (cm → m, as acRNN does).
* Split by whole takes: test = take 05 of both partners (``05.bvh``, ``20.bvh``), train = takes 01, 02, 03 of both
  partners (:data:`SALSA_TRAIN`, :data:`SALSA_TEST`). No validation set (the paper's is only used for curves).
* Frame ``f_t = [Δx_t, y_t, Δz_t | joint blocks of frame t]`` with ``Δx_t = x_{t+1} − x_t`` (forward difference of
  the hip's horizontal position, acRNN), so a take of T frames gives T − 1 frames; antipodal continuity over time
  for quaternions and dual quaternions; standardised by the training frames' mean and std.
* Training windows: ``T + 1 = 101`` consecutive frames, a take chosen uniformly (acRNN weights every clip
  equally), the start uniformly with a margin of 10 frames at both ends (:func:`sample_windows`).
* Test seeds: 10 frames, starts ``0, 7, 14, …`` in every test file (file order) while the seed and the horizon
  fit, at most 400 (:func:`seed_windows`). Horizons: 100, 400, 1000 ms = 3, 12, 30 frames at 30 fps (the paper's
  "µs" read as ms, as its evaluation script's 30 generated frames suggest); acceleration over 300 frames.

Shape legend: T frames, F frame size, B batch, K seeds, N generated frames, J joints.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from refimpl.bvh import read_bvh
from refimpl.metrics import (acceleration_comparison, mean_joint_error, npss, root_zeroed_positions)
from refimpl.models import acrnn, acrnn_fast
from refimpl.motion import Motion
from refimpl.optim import ACRNN_ADAM, adam_init, adam_step
from refimpl.preprocess import downsample, feature_statistics
from refimpl.representations import REPRESENTATIONS, decode, encode, fix_antipodal_frames
from refimpl.skeleton import Skeleton, remove_joints

__all__ = [
    "SALSA_FRAME_TIME", "SALSA_TRAIN", "SALSA_TEST", "SAMPLE_TRAIN", "SAMPLE_TEST", "LENGTH_SCALE", "FPS",
    "SEED_LENGTH", "SEED_STRIDE", "MAX_SEEDS", "HORIZONS_MS", "ACCELERATION_FRAMES", "WINDOW_MARGIN",
    "horizon_frames", "load_salsa_motion", "motion_to_frames", "frames_to_motion", "SynthesisData",
    "load_synthesis_data", "sample_windows", "seed_windows", "evaluate_generator", "train_acrnn",
    # the task interface of the application layer (spec/architecture.md, spec/acrnn.md §8)
    "NAME", "TABLE1_ROWS", "DEFAULT_ROW", "NPSS_REPORTED", "TrainingSet", "add_train_options", "resolve_data",
    "train_datasets", "num_examples", "describe_data", "checkpoint_extra", "check_checkpoint", "trained_fields",
    "skeleton_of", "onnx_method", "methods", "evaluate", "print_results", "write_results", "random_inputs",
    "continue_seed",
]

#: Seconds per frame of the salsa files (60 fps, although the headers say 120).
SALSA_FRAME_TIME = 1.0 / 60.0
#: Training takes (both partners of takes 01, 02, 03) and the held-out test take (05, both partners).
SALSA_TRAIN = ("01", "02", "03", "16", "17", "18")
SALSA_TEST = ("05", "20")
#: The embedded sample (refimpl/data/sample/salsa): one take, partner 01 trains, partner 16 tests (tests only).
SAMPLE_TRAIN = ("01",)
SAMPLE_TEST = ("16",)
#: cm → m (acRNN scales positions by 0.01).
LENGTH_SCALE = 0.01
FPS = 30
SEED_LENGTH = 10
SEED_STRIDE = 7
MAX_SEEDS = 400
HORIZONS_MS = (100, 400, 1000)
ACCELERATION_FRAMES = 300
WINDOW_MARGIN = 10


def horizon_frames(ms: float, fps: int = FPS) -> int:
    """Frames in ``ms`` milliseconds at ``fps`` (rounded): 100, 400, 1000 ms → 3, 12, 30 at 30 fps."""
    return int(round(ms * fps / 1000.0))


def load_salsa_motion(path, stride: int = 2, scale: float = LENGTH_SCALE) -> Motion:
    """One salsa file at 30 fps without End Sites, lengths × ``scale``.

    Parameters
    ----------
    path : path of a salsa BVH (60 fps)
    stride : int
        Decimation (2: 60 → 30 fps).
    scale : float
        Length factor for offsets and root positions.

    Returns
    -------
    Motion with 43 joints, frame time 1/30 s.
    """
    m = downsample(read_bvh(path, frame_time=SALSA_FRAME_TIME), stride)
    skel, rot = remove_joints(m.skeleton, m.rotations, m.skeleton.end_sites)
    s = skel
    skel = Skeleton(s.parents, s.offsets * scale, s.names, (), s.joints_left, s.joints_right)
    return Motion(skel, rot, m.root_positions * scale, m.frame_time, m.name)


def motion_to_frames(representation: str, motion: Motion) -> np.ndarray:
    """Frames of a motion: hip x/z as forward differences, antipodal continuity.

    Returns
    -------
    ndarray (T − 1, 3 + D·J)
        ``[x_{t+1} − x_t, y_t, z_{t+1} − z_t | joints of frame t]``.
    """
    if motion.num_frames < 2:
        raise ValueError(f"motion: expected at least 2 frames, got {motion.num_frames}")
    f = encode(representation, motion.skeleton, motion.rotations, motion.root_positions)   # (T, F)
    f = fix_antipodal_frames(representation, f)
    root = motion.root_positions
    out = f[:-1].copy()
    out[:, 0] = root[1:, 0] - root[:-1, 0]
    out[:, 2] = root[1:, 2] - root[:-1, 2]
    return out


def frames_to_motion(representation: str, skeleton: Skeleton, frames, frame_time: float = 1.0 / FPS,
                     start=(0.0, 0.0), name: str = "") -> Motion:
    """Inverse of :func:`motion_to_frames` (for BVH export of generated frames).

    The hip's horizontal position is the running sum of the differences from ``start`` (x, z):
    ``x_0 = start[0]``, ``x_{t+1} = x_t + Δx_t``; the height is read as is. Rotations by
    :func:`refimpl.representations.decode` (``"positions"`` has no inverse and raises ValueError).

    Parameters
    ----------
    frames : ndarray (T, 3 + D·J)
        De-standardised frames.

    Returns
    -------
    Motion with T frames.
    """
    x = np.asarray(frames, dtype=np.float64)
    rot, root = decode(representation, skeleton, x)
    pos = np.empty_like(root)
    pos[:, 1] = root[:, 1]
    for axis, s in ((0, start[0]), (2, start[1])):
        pos[0, axis] = s
        pos[1:, axis] = s + np.cumsum(root[:-1, axis])
    return Motion(skeleton, rot, pos, frame_time, name)


@dataclasses.dataclass(frozen=True, eq=False)
class SynthesisData:
    """Frames of one representation, split by take, with the training statistics.

    Attributes
    ----------
    representation : str
    skeleton : Skeleton (43 joints for salsa)
    train, test : tuple of ndarray (T_i, F)
        De-standardised frames per take.
    train_names, test_names : tuple of str
    mean, std : ndarray (F,)
        Training-set statistics (``feature_statistics``; std < 1e-4 → 1).
    """

    representation: str
    skeleton: Skeleton
    train: tuple
    test: tuple
    train_names: tuple
    test_names: tuple
    mean: np.ndarray
    std: np.ndarray

    @property
    def frame_size(self) -> int:
        return int(self.mean.size)

    @property
    def fps(self) -> float:
        """Frame rate of the frames (30)."""
        return float(FPS)

    def standardise(self, frames) -> np.ndarray:
        return (np.asarray(frames) - self.mean) / self.std

    def destandardise(self, frames) -> np.ndarray:
        return np.asarray(frames) * self.std + self.mean


def load_synthesis_data(representation: str, folder, train: Sequence[str] = SALSA_TRAIN,
                        test: Sequence[str] = SALSA_TEST, scale: float = LENGTH_SCALE) -> SynthesisData:
    """Read the salsa takes of ``folder`` (``<name>.bvh``) into frames of ``representation``.

    Example: ``load_synthesis_data("dual_quaternions", "../shared/data/acrnn_cmu_salsa")``; the embedded sample
    ``refimpl/data/sample/salsa`` with ``train=SAMPLE_TRAIN, test=SAMPLE_TEST``.
    """
    if representation not in REPRESENTATIONS:
        raise ValueError(f"representation: expected one of {list(REPRESENTATIONS)}, got {representation!r}")
    folder = Path(folder)
    if set(train) & set(test):
        raise ValueError(f"train and test share takes: {sorted(set(train) & set(test))}")
    motions = {n: load_salsa_motion(folder / f"{n}.bvh", scale=scale) for n in (*train, *test)}
    skel = motions[train[0]].skeleton
    frames = {n: motion_to_frames(representation, m) for n, m in motions.items()}
    mean, std = feature_statistics([frames[n] for n in train])
    return SynthesisData(representation, skel, tuple(frames[n] for n in train), tuple(frames[n] for n in test),
                         tuple(train), tuple(test), mean, std)


def sample_windows(rng: np.random.Generator, sequences: Sequence[np.ndarray], batch_size: int = 32,
                   length: int = 100, margin: int = WINDOW_MARGIN) -> np.ndarray:
    """A training batch of windows of ``length + 1`` consecutive frames.

    Each window: a sequence chosen uniformly (equal weight per take, as acRNN), a start uniformly in
    ``[margin, T − (length + 1) − margin]`` (the margin drops to 0 for short sequences).

    Returns
    -------
    ndarray (B, length + 1, F)
    """
    need = length + 1
    if not sequences or min(len(s) for s in sequences) < need:
        raise ValueError(f"sequences: expected every sequence to have at least {need} frames")
    out = np.empty((batch_size, need, sequences[0].shape[-1]), dtype=sequences[0].dtype)
    for b in range(batch_size):
        s = sequences[int(rng.integers(len(sequences)))]
        m = margin if len(s) - need - 2 * margin >= 0 else 0
        start = int(rng.integers(m, len(s) - need - m + 1))
        out[b] = s[start:start + need]
    return out


def seed_windows(lengths: Sequence[int], horizon: int, seed_length: int = SEED_LENGTH, stride: int = SEED_STRIDE,
                 max_count: int = MAX_SEEDS) -> np.ndarray:
    """Seed positions over the test sequences: a sliding window of stride 7.

    In every sequence (in order) starts ``0, stride, 2·stride, …`` while ``start + seed_length + horizon <= T``;
    the list is cut at ``max_count``.

    Returns
    -------
    ndarray (K, 2) of int: (sequence index, start frame).
    """
    rows = [(i, s) for i, T in enumerate(lengths) for s in range(0, int(T) - seed_length - horizon + 1, stride)]
    return np.array(rows[:max_count], dtype=np.int64).reshape(-1, 2)


def evaluate_generator(generate_fn, data: SynthesisData, horizons_ms: Sequence[float] = HORIZONS_MS,
             acceleration_frames: int = ACCELERATION_FRAMES, max_seeds: int = MAX_SEEDS,
             batch_size: int = 64) -> dict:
    """Table 1 metrics of a generator on the test takes.

    Parameters
    ----------
    generate_fn : callable
        ``generate_fn(seed (B, S, F) standardised, n) -> (B, n, F)`` standardised frames after the seed
        (e.g. ``lambda s, n: acrnn.generate(params, config, s, n)``).
    data : SynthesisData

    Returns
    -------
    dict
        ``{"horizons": {ms: {"frames", "euclidean", "npss_power", "npss_real", "num_seeds"}},
        "acceleration": {"pred", "gt", "abs_diff", "num_seeds"}}``; positions root-zeroed, in metres.
    """
    lengths = [len(s) for s in data.test]
    needs = {ms: horizon_frames(ms) for ms in horizons_ms}
    longest = max([*needs.values(), acceleration_frames])
    seeds = seed_windows(lengths, longest, max_count=max_seeds)
    if len(seeds) == 0:
        raise ValueError(f"data: the test takes {lengths} are too short for {SEED_LENGTH} + {longest} frames")
    preds, gts = [], []
    for b in range(0, len(seeds), batch_size):
        rows = seeds[b:b + batch_size]
        seed = np.stack([data.standardise(data.test[i][s:s + SEED_LENGTH]) for i, s in rows])
        gen = data.destandardise(generate_fn(seed, longest))                              # (B, N, F)
        gt = np.stack([data.test[i][s + SEED_LENGTH:s + SEED_LENGTH + longest] for i, s in rows])
        preds.append(root_zeroed_positions(data.representation, data.skeleton, gen))
        gts.append(root_zeroed_positions(data.representation, data.skeleton, gt))
    pred, gt = np.concatenate(preds), np.concatenate(gts)                                  # (K, N, J, 3)
    out = {"horizons": {}, "num_seeds": int(len(seeds))}
    for ms, n in needs.items():
        out["horizons"][ms] = {"frames": n, "euclidean": mean_joint_error(pred[:, :n], gt[:, :n]),
                               "npss_power": npss(gt[:, :n], pred[:, :n], "power"),
                               "npss_real": npss(gt[:, :n], pred[:, :n], "real")}
    out["acceleration"] = acceleration_comparison(pred[:, :acceleration_frames], gt[:, :acceleration_frames])
    return out


def train_acrnn(params: dict, config: "acrnn.ACRNNConfig", data: SynthesisData, spec: "acrnn.LossSpec",
                steps: int, rng: np.random.Generator, batch_size: int = 32, length: int = 100,
                lr: float = ACRNN_ADAM["lr"], state: dict | None = None, log=None) -> list:
    """A plain acRNN training loop (Adam, constant lr 1e-4, batch 32, windows of 100 + 1 frames by default), on the
    fast path (:func:`refimpl.models.acrnn_fast.loss_and_grads`; ``refimpl train --model acrnn`` is the
    resumable, checkpointed version).

    Parameters
    ----------
    params : dict
        Updated in place.
    state : dict, optional
        Adam state (``adam_init(params)`` when None; pass the same dict to continue a run).
    log : callable, optional
        ``log(step, total, parts)`` after every step (progress).

    Returns
    -------
    list of float
        The training loss of every step.
    """
    train = [data.standardise(s).astype(next(iter(params.values())).dtype) for s in data.train]
    state = adam_init(params) if state is None else state
    losses = []
    for k in range(int(steps)):
        frames = sample_windows(rng, train, batch_size, length)
        total, parts, grads = acrnn_fast.loss_and_grads(params, config, frames, spec)
        adam_step(params, grads, state, lr, ACRNN_ADAM["betas"], ACRNN_ADAM["eps"])
        losses.append(total)
        if log is not None:
            log(k, total, parts)
    return losses


# ----------------------------------------------------------------------------------------------------------------
# the task interface (spec/architecture.md §the application; spec/acrnn.md §8): ``refimpl train/eval/generate``
# ----------------------------------------------------------------------------------------------------------------

NAME = "synthesis"

#: ``--representation`` value -> row of Table 1 (a key of :data:`refimpl.models.acrnn.VARIANTS`).
TABLE1_ROWS = {
    "dq-all": "dual_quaternions_all",            # dual quaternions (all losses), the paper's proposal
    "dq-mse": "dual_quaternions",                # dual quaternions (MSE)
    "quaternions": "quaternions",                # quaternions (MSE)
    "quaternions-fk": "quaternions_fk",          # quaternions (MSE + L_quat + FK positions)
    "quaternions+positions": "quaternions+positions",
    "ortho6d": "ortho6d",
    "ortho6d+positions": "ortho6d+positions",
    "positions": "positions",                    # the original acRNN
    "euler": "euler",                            # Table 4 only
}
DEFAULT_ROW = "dq-all"
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
    """

    data: SynthesisData
    row: str
    weights: dict | None = None
    window_length: int = 100

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
    try:
        data = load_synthesis_data(acrnn.VARIANTS[TABLE1_ROWS[row]].representation, folder, train, test)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"--data {args.data}: {exc}") from exc
    length = int(getattr(args, "window_length", 100))
    if min(len(s) for s in data.train) < length + 1:
        raise UsageError(f"--window-length {length}: the shortest training take has "
                         f"{min(len(s) for s in data.train)} frames")
    return TrainingSet(data, row, _parse_losses(getattr(args, "losses", None)), length), data


def num_examples(dataset) -> int:
    """Training windows (every start of a ``T + 1``-frame window in every take; batches are drawn with
    :func:`sample_windows`, so an epoch is nominal)."""
    return int(sum(len(s) - dataset.window_length for s in dataset.data.train))


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
    weights = dict(acrnn.VARIANTS[train_ds.variant].weights if train_ds.weights is None else train_ds.weights)
    return {"mean": [float(v) for v in d.mean], "std": [float(v) for v in d.std], "fps": float(FPS),
            "data_representation": d.representation, "variant": train_ds.variant, "row": train_ds.row,
            "loss_weights": weights, "window_length": int(train_ds.window_length),
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


def skeleton_of(model_config: Mapping) -> Skeleton:
    """The skeleton stored in a checkpoint's model config."""
    s = model_config["skeleton"]
    return Skeleton(s["parents"], np.asarray(s["offsets"], dtype=np.float64), s["names"])


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


def evaluate(test_ds: SynthesisData, methods_by_name: Mapping, max_seeds: int = MAX_SEEDS) -> dict:
    """The protocol (:func:`evaluate_generator`) for each method on raw frames: ``{name: result}``."""
    out = {}
    for name, f in methods_by_name.items():
        def gen(seed, n, f=f):
            return test_ds.standardise(f(test_ds.destandardise(seed), n))
        out[name] = evaluate_generator(gen, test_ds, max_seeds=max_seeds)
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


def continue_seed(method, model_config: Mapping, path, start: int, num_frames: int) -> tuple:
    """Seed frames ``[start, start + 10)`` of a salsa BVH at 30 fps continued by ``method`` for ``num_frames``.

    Returns
    -------
    motion : Motion
        Seed + generated frames (hip starting where the seed starts), the model's skeleton.
    seed_frames : int
        How many of its frames are the seed (10).
    """
    from refimpl.errors import BadInputError, UsageError

    rep = model_config["data_representation"]
    if not REPRESENTATIONS[rep].invertible:
        raise UsageError(f"representation {rep!r} has no rotation decoding (no BVH); use another row")
    try:
        motion = load_salsa_motion(path)
        frames = motion_to_frames(rep, motion)
    except (OSError, ValueError) as exc:
        raise BadInputError(f"{path}: {exc}") from exc
    if frames.shape[1] != len(model_config["mean"]):
        raise BadInputError(f"{path}: frames of {frames.shape[1]} values, the model reads {len(model_config['mean'])}")
    if not 0 <= start <= len(frames) - SEED_LENGTH:
        raise UsageError(f"--source-frame must lie in [0, {len(frames) - SEED_LENGTH}], got {start}")
    seed = frames[start:start + SEED_LENGTH]
    gen = np.asarray(method(seed[None], num_frames), dtype=np.float64)[0]           # (N, F)
    allf = np.concatenate([seed, gen])
    root0 = motion.root_positions[start]
    m = frames_to_motion(rep, skeleton_of(model_config), allf, start=(root0[0], root0[2]),
                         name=Path(path).stem)
    return m, SEED_LENGTH
