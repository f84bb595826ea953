"""Long-term motion synthesis on the CMU salsa takes (acRNN): data, split, windows, seeds, metrics and
evaluation (the dual-quaternion paper's §7.1 protocol; spec/acrnn.md §5-6). The application layer is
:mod:`refimpl.tasks.synthesis`.

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
* Metrics (Table 1, spec/acrnn.md §6): :func:`root_zeroed_positions`, :func:`mean_joint_error` (Euclidean,
  root zeroed), :func:`npss` (Gopalakrishnan et al.'s power spectrum ``|X|²`` = ``"power"``, or the LaFAN1
  ``fast_npss`` copy used by the dual-quaternion paper's evaluation, ``(Re X)²`` = ``"real"``) and
  :func:`mean_acceleration` / :func:`acceleration_comparison`; :func:`evaluate_generator` computes them all.

Shape legend: T frames, F frame size, B batch, K seeds, N generated frames, J joints.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Mapping, Sequence


import numpy as np

from refimpl.progress import Throttle
from refimpl.bone_ik import rotations_from_positions
from refimpl.bvh import read_bvh
from refimpl.dq_output import DQ_TERMS
from refimpl.losses import WEIGHT_ACRNN_QUAT_FK
from refimpl.motion import Motion
from refimpl.arrays import float_array
from refimpl.preprocess import downsample, feature_statistics
from refimpl.representations import REPRESENTATIONS, decode, encode, fix_antipodal_frames, positions_from_frames
from refimpl.skeleton import Skeleton, remove_joints
from refimpl.checkpoint_fields import (MAX_TASK_ABS, MIN_STD, TaskSchema, int_field, kind_of, number_array,
                                       require_fields, skeleton_field)

__all__ = ["Variant", "VARIANTS", "CHECKPOINT_SCHEMA", 
    "SALSA_FRAME_TIME", "SALSA_TRAIN", "SALSA_TEST", "SAMPLE_TRAIN", "SAMPLE_TEST", "LENGTH_SCALE", "FPS",
    "SEED_LENGTH", "SEED_STRIDE", "MAX_SEEDS", "HORIZONS_MS", "ACCELERATION_FRAMES", "WINDOW_MARGIN", "TABLE1_ROWS",
    "DEFAULT_ROW", "horizon_frames", "in_source_units", "END_SITE_REPRESENTATIONS", "load_salsa_motion",
    "motion_to_frames", "frames_to_motion", "SynthesisData", "skeleton_of", "load_synthesis_data", "sample_windows",
    "count_windows", "seed_windows", "evaluate_generator", "NPSS_VARIANTS", "root_zeroed_positions", "mean_joint_error", "npss",
    "mean_acceleration", "acceleration_comparison",
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


@dataclasses.dataclass(frozen=True)
class Variant:
    """One trainable row of Table 1: a representation and its loss weights (name → weight)."""

    name: str
    representation: str
    weights: Mapping[str, float] = dataclasses.field(default_factory=lambda: {"mse": 1.0})


#: Table 1 rows (plus the original positional acRNN). Weights: Appendix B (DQ: MSE + (L_pos + L_offset)/3 +
#: local L_quat + 0.01 L_reg; quaternions-FK: MSE + L_quat + 1/4 FK position loss).
VARIANTS = {v.name: v for v in (
    Variant("positions", "positions"),
    Variant("positions_acrnn", "positions_acrnn"),      # the published code's 171-value frame (End Sites kept)
    Variant("euler", "euler"),
    Variant("quaternions", "quaternions"),
    Variant("quaternions_fk", "quaternions", {"mse": 1.0, "quat": 1.0, "fk": WEIGHT_ACRNN_QUAT_FK}),
    Variant("quaternions+positions", "quaternions+positions"),
    Variant("ortho6d", "ortho6d"),
    Variant("ortho6d+positions", "ortho6d+positions"),
    Variant("dual_quaternions", "dual_quaternions"),
    Variant("dual_quaternions_all", "dual_quaternions", {"mse": 1.0, **DQ_TERMS}),
)}


#: ``--representation`` value -> row of Table 1 (a key of :data:`VARIANTS`).
TABLE1_ROWS = {
    "dq-all": "dual_quaternions_all",            # dual quaternions (all losses), the paper's proposal
    "dq-mse": "dual_quaternions",                # dual quaternions (MSE)
    "quaternions": "quaternions",                # quaternions (MSE)
    "quaternions-fk": "quaternions_fk",          # quaternions (MSE + L_quat + FK positions)
    "quaternions+positions": "quaternions+positions",
    "ortho6d": "ortho6d",
    "ortho6d+positions": "ortho6d+positions",
    "positions": "positions",                    # the original acRNN's positions in the paper's 3 + 3J frame
    "positions-published": "positions_acrnn",    # the published acRNN code's frame: 171 values, End Sites kept
    "euler": "euler",                            # Table 4 only
}
DEFAULT_ROW = "dq-all"


def horizon_frames(ms: float, fps: int = FPS) -> int:
    """Frames in ``ms`` milliseconds at ``fps`` (rounded): 100, 400, 1000 ms → 3, 12, 30 at 30 fps."""
    return int(round(ms * fps / 1000.0))


def in_source_units(motion: Motion, scale: float = LENGTH_SCALE) -> Motion:
    """``motion`` (the network's metres) back in the units of the takes it was read from: offsets and root
    positions divided by ``scale`` (0.01: metres -> centimetres, the salsa BVH's units)."""
    s = motion.skeleton
    skel = Skeleton(s.parents, np.asarray(s.offsets) / scale, s.names, s.end_sites, s.joints_left, s.joints_right)
    return Motion(skel, motion.rotations, np.asarray(motion.root_positions) / scale, motion.frame_time, motion.name)


#: Representations whose frames keep the End Sites (the published acRNN's 57 nodes, spec/acrnn.md §1.1).
END_SITE_REPRESENTATIONS = ("positions_acrnn",)


def load_salsa_motion(path, stride: int = 2, scale: float = LENGTH_SCALE, phase: int = 0,
                      end_sites: bool = False) -> Motion:
    """One salsa file at 30 fps without End Sites (``end_sites=True``: with them), lengths × ``scale``.

    Parameters
    ----------
    path : path of a salsa BVH (60 fps)
    stride : int
        Decimation (2: 60 → 30 fps).
    scale : float
        Length factor for offsets and root positions.
    phase : int
        First frame kept (0 or 1 at stride 2: the two parities of the 60 fps frames).

    end_sites : bool
        Keep the End Sites as joints (identity rotations), in the file's depth-first order.

    Returns
    -------
    Motion with 43 joints (57 with the End Sites), frame time 1/30 s.
    """
    m = downsample(read_bvh(path, frame_time=SALSA_FRAME_TIME), stride, phase)
    skel, rot = (m.skeleton, m.rotations) if end_sites else remove_joints(m.skeleton, m.rotations,
                                                                          m.skeleton.end_sites)
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
    :func:`refimpl.representations.decode`; the positional frames (``"positions"``, the published
    ``"positions_acrnn"``), which have no inverse, by the skeleton's bone directions
    (:func:`refimpl.bone_ik.rotations_from_positions`, spec/kinematics.md §7).

    Parameters
    ----------
    frames : ndarray (T, 3 + D·J)
        De-standardised frames.

    Returns
    -------
    Motion with T frames.
    """
    x = np.asarray(frames, dtype=np.float64)
    if REPRESENTATIONS[representation].invertible:
        rot, root = decode(representation, skeleton, x)
    else:  # joint positions (relative to the frame's root entry): rotations along the bones
        rot, _ = rotations_from_positions(skeleton, positions_from_frames(representation, skeleton, x))
        root = x[:, :3]
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
        Training-set statistics (``feature_statistics``; std < 1e-4 → 1); 0 and 1 when not ``standardised``.
    standardised : bool
        False: raw frames (the published trainer's), mean 0 and std 1.
    parities : int
        1, or 2 when the training takes' odd 60 fps frames are extra training sequences (``<name>/odd``).
    """

    representation: str
    skeleton: Skeleton
    train: tuple
    test: tuple
    train_names: tuple
    test_names: tuple
    mean: np.ndarray
    std: np.ndarray
    standardised: bool = True
    parities: int = 1

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


def skeleton_of(model_config: Mapping) -> Skeleton:
    """The skeleton stored in a checkpoint's model config."""
    s = model_config["skeleton"]
    return Skeleton(s["parents"], np.asarray(s["offsets"], dtype=np.float64), s["names"])


def load_synthesis_data(representation: str, folder, train: Sequence[str] = SALSA_TRAIN,
                        test: Sequence[str] = SALSA_TEST, scale: float = LENGTH_SCALE, parities: int = 1,
                        standardise: bool = True) -> SynthesisData:
    """Read the salsa takes of ``folder`` (``<name>.bvh``) into frames of ``representation``.

    Example: ``load_synthesis_data("dual_quaternions", "../shared/data/acrnn_cmu_salsa")``; the embedded sample
    ``refimpl/data/sample/salsa`` with ``train=SAMPLE_TRAIN, test=SAMPLE_TEST``. ``parities=2`` adds each
    training take's odd 60 fps frames as a second training sequence (the published trainer samples both; the test
    takes keep frames 0, 2, 4, ...); ``standardise=False`` stores mean 0 and std 1 (the published trainer's raw
    frames) instead of the training statistics (spec/acrnn.md §1.1).
    """
    if parities not in (1, 2):
        raise ValueError(f"parities: expected 1 or 2, got {parities!r}")
    if representation not in REPRESENTATIONS:
        raise ValueError(f"representation: expected one of {list(REPRESENTATIONS)}, got {representation!r}")
    folder = Path(folder)
    if set(train) & set(test):
        raise ValueError(f"train and test share takes: {sorted(set(train) & set(test))}")
    keep = representation in END_SITE_REPRESENTATIONS
    motions = {n: load_salsa_motion(folder / f"{n}.bvh", scale=scale, end_sites=keep) for n in (*train, *test)}
    skel = motions[train[0]].skeleton
    frames = {n: motion_to_frames(representation, m) for n, m in motions.items()}
    train_frames = [frames[n] for n in train]
    if parities == 2:
        train_frames += [motion_to_frames(representation, load_salsa_motion(folder / f"{n}.bvh", scale=scale,
                                                                            phase=1, end_sites=keep))
                         for n in train]
    mean, std = feature_statistics(train_frames)
    if not standardise:
        mean, std = np.zeros_like(mean), np.ones_like(std)
    return SynthesisData(representation, skel, tuple(train_frames), tuple(frames[n] for n in test),
                         tuple(train) + tuple(f"{n}/odd" for n in train if parities == 2), tuple(test), mean, std,
                         standardise, parities)


def count_windows(sequences: Sequence[np.ndarray], window_length: int) -> int:
    """Training windows of ``window_length + 1`` frames: every start in every sequence (an epoch of
    :func:`sample_windows` is nominal)."""
    return int(sum(len(s) - window_length for s in sequences))


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
             batch_size: int = 64, progress=None) -> dict:
    """Table 1 metrics of a generator on the test takes; ``progress(line)``, when given, is called after each
    batch of seeds that ends more than 5 s after the last call (``"128/640 seeds, 12 s"``).

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
    tick = Throttle()
    for b in range(0, len(seeds), batch_size):
        rows = seeds[b:b + batch_size]
        seed = np.stack([data.standardise(data.test[i][s:s + SEED_LENGTH]) for i, s in rows])
        gen = data.destandardise(generate_fn(seed, longest))                              # (B, N, F)
        gt = np.stack([data.test[i][s + SEED_LENGTH:s + SEED_LENGTH + longest] for i, s in rows])
        preds.append(root_zeroed_positions(data.representation, data.skeleton, gen))
        gts.append(root_zeroed_positions(data.representation, data.skeleton, gt))
        if progress is not None and tick.due():
            progress(f"{min(b + batch_size, len(seeds))}/{len(seeds)} seeds, {tick.elapsed:.0f} s")
    pred, gt = np.concatenate(preds), np.concatenate(gts)                                  # (K, N, J, 3)
    out = {"horizons": {}, "num_seeds": int(len(seeds))}
    for ms, n in needs.items():
        out["horizons"][ms] = {"frames": n, "euclidean": mean_joint_error(pred[:, :n], gt[:, :n]),
                               "npss_power": npss(gt[:, :n], pred[:, :n], "power"),
                               "npss_real": npss(gt[:, :n], pred[:, :n], "real")}
    out["acceleration"] = acceleration_comparison(pred[:, :acceleration_frames], gt[:, :acceleration_frames])
    return out


# --------------------------------------------------------------------------------------------------
# synthesis metrics (dual-quaternion paper, Table 1; spec/acrnn.md §6)

#: ``"power"``: Gopalakrishnan et al. (CVPR 2019), ``P = |X|²``; ``"real"``: LaFAN1 ``fast_npss`` as copied into
#: the dual-quaternion paper's evaluation code, ``P = (Re X)²``.
NPSS_VARIANTS = ("power", "real")


def root_zeroed_positions(representation: str, skeleton: Skeleton, frames, source: str = "fk") -> np.ndarray:
    """Joint positions implied by frame vectors with the root position set to 0 (the paper ignores the root).

    Parameters
    ----------
    representation : str
    skeleton : Skeleton with J joints
    frames : ndarray (..., 3 + D·J)
        De-standardised frames.
    source : {"fk", "stored"}
        ``"fk"`` (default; the paper: "computed using Forward Kinematics", and the DQ evaluation code decodes
        current DQs to local rotations first): forward kinematics of the decoded local rotations with the
        skeleton's offsets, for every representation with an inverse; ``"positions"`` has none and uses its stored
        positions. ``"stored"``: :func:`refimpl.representations.positions_from_frames` (stored positions of the
        ``+positions`` representations, Eq. 8 translations of dual quaternions).

    Returns
    -------
    ndarray (..., J, 3)
    """
    if source not in ("fk", "stored"):
        raise ValueError(f"source: expected 'fk' or 'stored', got {source!r}")
    x = np.array(frames, dtype=np.float64)
    x[..., :3] = 0.0
    rep = REPRESENTATIONS.get(representation)
    if source == "fk" and rep is not None and rep.invertible:
        rot, root = decode(representation, skeleton, x)
        return skeleton.forward_kinematics(rot, root)
    return positions_from_frames(representation, skeleton, x)


def mean_joint_error(pred, gt) -> float:
    """Euclidean joint-position error: ``mean over (..., J) of ‖p − p̃‖₂``.

    Parameters
    ----------
    pred, gt : ndarray (..., J, 3)
        Positions (root zeroed, :func:`root_zeroed_positions`).
    """
    pred = float_array(pred, "pred", (..., 3), cast=False)
    gt = float_array(gt, "gt", pred.shape, cast=False)
    return float(np.mean(np.sqrt(np.sum((pred - gt) ** 2, axis=-1))))


def _flat_sequences(x, name, shape=None):
    a = np.asarray(x, dtype=np.float64)
    if a.ndim < 3 or (shape is not None and a.shape != shape):
        raise ValueError(f"{name}: expected shape (N, T, D...) {'' if shape is None else shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: contains NaN or inf")
    return a.reshape(a.shape[0], a.shape[1], -1)


def npss(gt, pred, variant: str = "power") -> float:
    """Normalized Power Spectrum Similarity (Gopalakrishnan et al., CVPR 2019).

    Per sequence s and feature d, along time (FFT over the T frames, ``k = 0 … T−1``)::

        P[s,k,d] = |X[s,k,d]|²   ("power", the original)   or   (Re X[s,k,d])²   ("real", LaFAN1 fast_npss)
        p̂ = P / Σ_k P            (0 where the total is 0)
        EMD[s,d] = Σ_k | cumsum_k p̂_pred − cumsum_k p̂_gt |
        NPSS = Σ_{s,d} W[s,d] EMD[s,d] / Σ_{s,d} W[s,d],   W = Σ_k P_gt   (ground-truth total power)

    Parameters
    ----------
    gt, pred : ndarray (N, T, ...)
        Sequences; trailing axes are flattened into features (e.g. (N, T, J, 3) positions).
    variant : {"power", "real"}

    Returns
    -------
    float
        0 for identical sequences. ``"power"`` is invariant to a common circular time shift of both (and to a
        circular shift of either); ``"real"`` is not.
    """
    if variant not in NPSS_VARIANTS:
        raise ValueError(f"variant: expected one of {NPSS_VARIANTS}, got {variant!r}")
    g = _flat_sequences(gt, "gt")
    p = _flat_sequences(pred, "pred", np.shape(gt))
    X_g, X_p = np.fft.fft(g, axis=1), np.fft.fft(p, axis=1)                 # (N, T, D) complex
    if variant == "power":
        P_g, P_p = np.abs(X_g) ** 2, np.abs(X_p) ** 2
    else:
        P_g, P_p = X_g.real ** 2, X_p.real ** 2
    W_g, W_p = P_g.sum(axis=1), P_p.sum(axis=1)                              # (N, D)
    if not np.any(W_g > 0):
        raise ValueError("gt: every feature has zero power (NPSS is undefined)")
    n_g = np.divide(P_g, W_g[:, None], out=np.zeros_like(P_g), where=W_g[:, None] > 0)
    n_p = np.divide(P_p, W_p[:, None], out=np.zeros_like(P_p), where=W_p[:, None] > 0)
    emd = np.sum(np.abs(np.cumsum(n_p, axis=1) - np.cumsum(n_g, axis=1)), axis=1)   # (N, D)
    return float(np.sum(W_g * emd) / np.sum(W_g))


def mean_acceleration(positions) -> float:
    """Mean acceleration magnitude (VIBE-style, the paper's jitter measure), in position units per frame².

    ``a_t = p_{t+2} − 2 p_{t+1} + p_t``; ``‖a_t,j‖₂`` averaged over joints, frames and sequences.

    Parameters
    ----------
    positions : ndarray (N, T, J, 3), T >= 3
    """
    x = float_array(positions, "positions", (None, None, None, 3), cast=False)
    if x.shape[1] < 3:
        raise ValueError(f"positions: expected at least 3 frames, got shape {x.shape}")
    a = x[:, 2:] - 2.0 * x[:, 1:-1] + x[:, :-2]                            # (N, T-2, J, 3)
    return float(np.mean(np.sqrt(np.sum(a * a, axis=-1))))


def acceleration_comparison(pred, gt) -> dict:
    """Mean acceleration of the prediction and of the data, and their absolute difference.

    Returns
    -------
    dict with ``"pred"``, ``"gt"``, ``"abs_diff"`` (the paper's Table 1 column is one of these; it does not say
    which, spec/acrnn.md §6).
    """
    a_p, a_g = mean_acceleration(pred), mean_acceleration(gt)
    return {"pred": a_p, "gt": a_g, "abs_diff": abs(a_p - a_g)}


# ---- what the task stores in a checkpoint (spec/robustness.md §9.1) ----

def _check_checkpoint(cfg: Mapping, config, where: str) -> None:
    """The synthesis fields: ``row`` a Table 1 row, ``representation`` = ``row``, ``variant`` = the row's variant,
    ``data_representation`` = the variant's representation (required), ``skeleton`` (required), ``frame_size`` =
    ``3 + D · J`` of that representation and the skeleton's J, ``mean``/``std`` (required) ``frame_size`` finite
    numbers (``std`` in [1e-6, 1e6]), ``loss_weights`` finite numbers >= 0 by loss name, ``window_length`` /
    ``condition_length`` / ``ground_truth_length`` positive integers, ``train_takes`` / ``test_takes`` lists of
    strings."""
    from refimpl.representations import frame_size

    rows = TABLE1_ROWS  # --representation value -> variant
    require_fields(cfg, ("mean", "std", "data_representation", "skeleton", "variant"), where, "synthesis")
    rep = cfg["data_representation"]
    if not isinstance(rep, str) or rep not in REPRESENTATIONS:
        raise ValueError(f"{where}: model_config.data_representation: expected one of {sorted(REPRESENTATIONS)}, "
                         f"got {kind_of(rep)}")
    variant = cfg["variant"]
    if not isinstance(variant, str) or variant not in VARIANTS:
        raise ValueError(f"{where}: model_config.variant: expected one of {sorted(VARIANTS)}, got "
                         f"{kind_of(variant)}")
    if VARIANTS[variant].representation != rep:
        raise ValueError(f"{where}: model_config.data_representation {rep!r} does not match the variant "
                         f"{variant!r}, which trains on {VARIANTS[variant].representation!r}")
    for key in ("row", "representation"):
        if key in cfg:
            row = cfg[key]
            if not isinstance(row, str) or row not in rows:
                raise ValueError(f"{where}: model_config.{key}: expected one of {list(rows)}, got {kind_of(row)}")
            if rows[row] != variant:
                raise ValueError(f"{where}: model_config.{key} {row!r} is the variant {rows[row]!r}, but "
                                 f"model_config.variant is {variant!r}")
    if isinstance(cfg.get("row"), str) and isinstance(cfg.get("representation"), str) and \
            cfg["row"] != cfg["representation"]:
        raise ValueError(f"{where}: model_config.row {cfg['row']!r} differs from model_config.representation "
                         f"{cfg['representation']!r}")
    sk = skeleton_field(cfg["skeleton"], where)
    F = frame_size(rep, sk.num_joints)
    got = getattr(config, "frame_size", cfg.get("frame_size"))
    if got != F:
        raise ValueError(f"{where}: model_config.frame_size {got!r} does not match {rep!r} frames of the "
                         f"{sk.num_joints}-joint skeleton (3 + {REPRESENTATIONS[rep].dim} x {sk.num_joints} = {F})")
    number_array(cfg["mean"], f"{where}: model_config.mean", (F,))
    number_array(cfg["std"], f"{where}: model_config.std", (F,), MIN_STD, MAX_TASK_ABS)
    if "loss_weights" in cfg:
        w = cfg["loss_weights"]
        if not isinstance(w, Mapping) or not w or not all(
                isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and 0 <= v <= MAX_TASK_ABS for k, v in w.items()):
            raise ValueError(f"{where}: model_config.loss_weights: expected an object of loss name -> finite weight "
                             f">= 0, got {kind_of(w)}")
    for key in ("window_length", "condition_length", "ground_truth_length"):
        if key in cfg:
            int_field(cfg, key, where)
    for key in ("train_takes", "test_takes"):
        if key in cfg and (not isinstance(cfg[key], list) or not all(isinstance(t, str) for t in cfg[key])):
            raise ValueError(f"{where}: model_config.{key}: expected a list of take names, got {kind_of(cfg[key])}")


#: The synthesis task's checkpoint schema (``refimpl.tasks.synthesis.CHECKPOINT_SCHEMA``, deploy's acRNN loader).
CHECKPOINT_SCHEMA = TaskSchema("synthesis", check=_check_checkpoint)
