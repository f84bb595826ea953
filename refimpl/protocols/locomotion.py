"""QuaterNet long-term locomotion protocol: pose-network windows and augmentation, splines and pace-network data,
the whole-file datasets, and the held-out evaluation (free-running position and velocity error over the horizon
with ground-truth controls) with its zero-velocity baseline (spec/locomotion.md; QuaterNet §3.7, §4.3-4.4;
spec/locomotion.md §3, §5). The data (rigs, loading, features, sequences) is in
:mod:`refimpl.protocols.locomotion_data`.

Units: QuaterNet units (CMU ASF units, 1 unit = 5.6444 cm), 30 frames per second.

Shape legend: T frames, J joints, B batch, P prefix, L = P + T_target window, N spline points or windows,
F = 4 J + 8 values per input frame.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.progress import Throttle
from refimpl.augment import rotate_controls
from refimpl.motion import Motion
from refimpl.protocols.locomotion_cache import load_pace_data, load_sequences, sequences_key
from refimpl.protocols.locomotion_data import (BANDAI_NAMCO_RIG, CMU_RIG, FPS, QUATERNET_UNIT_CM, LocomotionRig,
                                               LocomotionSequence, build_sequences, load_bandai_namco, load_cmu_bvh,
                                               load_cmu_expmap)
from refimpl.quat import quat_mul, quat_rotate
from refimpl.skeleton import Skeleton
from refimpl.splines import Spline

__all__ = [
    "PoseBatch", "pose_batch", "sequence_spline", "pace_training_data", "pace_batch",
    "LocomotionDataset", "build_dataset", "evaluation_windows", "zero_velocity",
    "position_errors", "evaluate", "format_results",
]


# ------------------------------------------------------------------------------------------------------------
# pose-network windows and augmentation
# ------------------------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class PoseBatch:
    """One batch of windows (reference ``PoseNetworkLongTerm``, §7.5).

    Attributes
    ----------
    inputs : (B, P + T, 4J + 8)
        ``[J local quaternions | offset, height | 6 controls]`` of frames ``s … s + P + T - 1``.
    target_positions : (B, T, J, 3)
        ``positions_local`` of frames ``s + P … s + P + T - 1``.
    target_translations : (B, T, 2)
        offset and height of the same frames.
    angles : (B,) rotation about +Y applied to each window (0 without augmentation).
    names : tuple of str, the sequence of each window; starts : (B,) window starts.
    """

    inputs: np.ndarray
    target_positions: np.ndarray
    target_translations: np.ndarray
    angles: np.ndarray
    names: tuple
    starts: np.ndarray


def pose_batch(sequences: Sequence[LocomotionSequence], rng: np.random.Generator, batch_size: int = 40,
               prefix: int = 30, target: int = 60, augment: bool = True) -> PoseBatch:
    """Draw one batch: sequences with replacement, probability ∝ length (those shorter than P + T excluded),
    a uniform window start, and (``augment``) a random rotation θ ~ U(-2π, 2π) about +Y per window:
    root quaternions ← r ⊗ q_root with ``r = (cos θ/2, 0, sin θ/2, 0)``, target positions ← r · p, direction
    and facing controls rotated (:func:`rotate_controls`); phase and translations unchanged."""
    length = prefix + target
    pool = [s for s in sequences if s.num_frames >= length]
    if not pool:
        raise ValueError(f"sequences: none has the {length} frames a window needs")
    sizes = np.array([s.num_frames for s in pool], dtype=np.float64)
    pick = rng.choice(len(pool), size=batch_size, p=sizes / sizes.sum())
    num_j = pool[0].skeleton.num_joints
    inputs = np.empty((batch_size, length, 4 * num_j + 8))
    tpos = np.empty((batch_size, target, num_j, 3))
    ttr = np.empty((batch_size, target, 2))
    angles = rng.uniform(-2 * np.pi, 2 * np.pi, size=batch_size) if augment else np.zeros(batch_size)
    starts = np.empty(batch_size, dtype=np.int64)
    for b, k in enumerate(pick):
        s = pool[k]
        st = int(rng.integers(0, s.num_frames - length + 1))
        starts[b] = st
        rot = s.rotations[st:st + length].copy()
        feats = s.features[st:st + length]
        pos = s.positions_local[st + prefix:st + length]
        a = angles[b]
        if augment:
            r = np.array([math.cos(a / 2), 0.0, math.sin(a / 2), 0.0])
            rot[:, 0] = quat_mul(r, rot[:, 0])
            pos = quat_rotate(r, pos)
            feats = rotate_controls(feats, a)
        inputs[b, :, :4 * num_j] = rot.reshape(length, -1)
        inputs[b, :, 4 * num_j:] = feats
        tpos[b] = pos
        ttr[b] = s.features[st + prefix:st + length, :2]
    return PoseBatch(inputs=inputs, target_positions=tpos, target_translations=ttr, angles=angles,
                     names=tuple(pool[k].name for k in pick), starts=starts)


# ------------------------------------------------------------------------------------------------------------
# splines and pace-network data
# ------------------------------------------------------------------------------------------------------------

def sequence_spline(sequence: LocomotionSequence, points_per_unit: float = 5.0, smoothing: float = 1.0) -> Spline:
    """The sequence's ground path as a spline (reference ``compute_splines``, §8.2).

    Points: root ``(x, z)`` per frame (frames that do not move, closer than 1e-9 to the previous kept one, are
    skipped). Tracks: ``direction`` = facing ``(sin θ, cos θ)`` (circular), ``amplitude`` = A (linear),
    ``frequency`` = phase increment per frame, wrapped to (-π, π], last value repeated (linear). Then
    reparameterised (5 points per unit, smoothing 1) and given the constant track ``average_speed`` = the mean
    of the resampled amplitude.
    """
    xz = sequence.trajectory[:, [0, 2]]
    keep = [0]
    for t in range(1, xz.shape[0]):
        if np.linalg.norm(xz[t] - xz[keep[-1]]) > 1e-9:
            keep.append(t)
    keep = np.array(keep)
    if keep.size < 2:
        raise ValueError(f"sequence {sequence.name!r}: the root does not move")
    f = sequence.features
    amp = np.hypot(f[:, 2], f[:, 3])
    dphi = np.angle(np.exp(1j * np.diff(sequence.phase)))
    freq = np.concatenate([dphi, dphi[-1:]])
    sp = Spline(xz[keep], closed=False, tracks={"direction": (f[keep, 6:8], "circular"),
                                                 "amplitude": (amp[keep], "linear"),
                                                 "frequency": (freq[keep], "linear")})
    sp = sp.reparameterize(points_per_unit, smoothing)
    avg = float(sp.track("amplitude").mean())
    return sp.with_tracks(average_speed=(np.full(sp.num_points, avg), "linear"))


def pace_training_data(spline: Spline) -> tuple[np.ndarray, np.ndarray]:
    """Inputs and targets of the pace network along a sequence spline (§8.3).

    Returns
    -------
    inputs : (N, 2) ``[turning_angle, average_speed]``
    targets : (N, 4) ``[A, ω, cos Δ, sin Δ]`` with ``cos Δ = f · t``, ``sin Δ = t_0 f_1 - t_1 f_0`` (t the unit
    tangent, f the facing): Δ is the signed angle from the tangent to the facing.
    """
    t = spline.track("tangent")
    f = spline.track("direction")
    inputs = np.stack([spline.track("turning_angle")[:, 0], spline.track("average_speed")[:, 0]], axis=-1)
    targets = np.stack([spline.track("amplitude")[:, 0], spline.track("frequency")[:, 0],
                        np.sum(f * t, axis=-1), t[:, 0] * f[:, 1] - t[:, 1] * f[:, 0]], axis=-1)
    return inputs, targets


def pace_batch(data: Sequence[tuple[np.ndarray, np.ndarray]], rng: np.random.Generator, batch_size: int = 40,
               chunk_length: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """Chunks of ``chunk_length`` points: splines drawn with replacement ∝ their number of points (shorter ones
    excluded), uniform start. Returns ``x (B, N, 2)``, ``y (B, N, 4)``."""
    pool = [d for d in data if d[0].shape[0] >= chunk_length]
    if not pool:
        raise ValueError(f"data: no spline has {chunk_length} points")
    sizes = np.array([d[0].shape[0] for d in pool], dtype=np.float64)
    pick = rng.choice(len(pool), size=batch_size, p=sizes / sizes.sum())
    x = np.empty((batch_size, chunk_length, 2))
    y = np.empty((batch_size, chunk_length, 4))
    for b, k in enumerate(pick):
        inp, tgt = pool[k]
        st = int(rng.integers(0, inp.shape[0] - chunk_length + 1))
        x[b], y[b] = inp[st:st + chunk_length], tgt[st:st + chunk_length]
    return x, y


@dataclasses.dataclass(frozen=True)
class LocomotionDataset:
    """The locomotion sequences of one side of a whole-file split.

    Attributes
    ----------
    sequences : tuple of LocomotionSequence
    rig : LocomotionRig
    files : tuple of str
        The source files (the unit of the split).
    prefix, target : int
        P and T of the pose network's windows.
    pace_chunk_length : int
        Spline points per pace-network training chunk (0 = automatic: min(1000, median spline length)).
    fps : float
    cache_key : str
        The data-cache key of the sequences (:func:`refimpl.protocols.locomotion_cache.sequences_key`; "" = the
        pace data are not cached).
    """

    sequences: tuple
    rig: LocomotionRig
    files: tuple
    prefix: int = 30
    target: int = 60
    pace_chunk_length: int = 0
    fps: float = FPS
    cache_key: str = ""

    @property
    def skeleton(self) -> Skeleton:
        return self.sequences[0].skeleton

    @property
    def windows(self) -> tuple:
        """Sequences long enough for one pose window (P + T frames)."""
        return tuple(s for s in self.sequences if s.num_frames >= self.prefix + self.target)

    @property
    def num_frames(self) -> int:
        return int(sum(s.num_frames for s in self.sequences))

    def pace_data(self) -> list:
        """``(inputs (N, 2), targets (N, 4))`` of every sequence's spline (:func:`pace_training_data`); sequences
        whose root does not move are skipped. Through the data cache when the dataset has a ``cache_key``."""
        def build():
            out = []
            for s in self.sequences:
                try:
                    out.append(pace_training_data(sequence_spline(s)))
                except ValueError:
                    continue
            return out

        return load_pace_data(self.cache_key, build) if self.cache_key else build()


def _load_file(kind: str, path: str) -> tuple[Motion, LocomotionRig]:
    if kind == "bandai_namco":
        return load_bandai_namco(path), BANDAI_NAMCO_RIG
    if kind == "cmu_expmap":
        return load_cmu_expmap(path), CMU_RIG
    return load_cmu_bvh(path), CMU_RIG


def build_dataset(kind: str, files: Sequence[str], *, prefix: int = 30, target: int = 60, mirror: bool = True,
                  pace_chunk_length: int = 0, progress: Callable[[str], None] | None = None) -> LocomotionDataset:
    """Load ``files`` of one ``kind`` (:func:`resolve_files`) into a :class:`LocomotionDataset`
    (:func:`build_sequences`: mirrored, every downsampling phase), through the data cache
    (:mod:`refimpl.protocols.locomotion_cache`; ``REFIMPL_CACHE=off`` reads the files every time)."""
    def read():
        seqs, rig = [], None
        tick = Throttle()                                    # the 830 files take a minute or more
        for i, f in enumerate(files):
            motion, rig = _load_file(kind, f)
            seqs.extend(build_sequences(motion, rig, mirror=mirror, source=Path(f).stem))
            if progress is not None and tick.due():
                progress(f"  loaded {i + 1}/{len(files)} files, {tick.elapsed:.0f} s")
        if not seqs:
            raise ValueError("files: no sequence loaded")
        return seqs, rig

    options = dict(kind=kind, mirror=bool(mirror), fps=FPS)
    seqs, rig = load_sequences(files, read, sequence_type=LocomotionSequence, rigs=(BANDAI_NAMCO_RIG, CMU_RIG),
                               options=options, progress=progress)
    ref = seqs[0].skeleton
    for s in seqs:
        if s.skeleton.num_joints != ref.num_joints or not np.allclose(s.skeleton.offsets, ref.offsets, atol=1e-6):
            raise ValueError(f"{s.name}: its skeleton differs from {seqs[0].name}'s; the FK loss needs one skeleton")
    return LocomotionDataset(tuple(seqs), rig, tuple(str(f) for f in files), int(prefix), int(target),
                             int(pace_chunk_length),
                             cache_key=sequences_key(files, read, LocomotionSequence, options))


# ------------------------------------------------------------------------------------------------------------
# protocol: free-running position error over the horizon, with ground-truth controls
# ------------------------------------------------------------------------------------------------------------

def evaluation_windows(ds: LocomotionDataset, stride: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deterministic held-out windows: every sequence with P + T frames, starts every ``stride`` frames (default
    T), no augmentation.

    Returns
    -------
    inputs : (N, P + T, 4J + 8); target_positions : (N, T, J, 3) ``positions_local``;
    target_translations : (N, T, 2)
    """
    P, T = ds.prefix, ds.target
    stride = T if stride is None else int(stride)
    ins, pos, tr = [], [], []
    for s in ds.windows:
        for st in range(0, s.num_frames - P - T + 1, stride):
            ins.append(np.concatenate([s.rotations[st:st + P + T].reshape(P + T, -1), s.features[st:st + P + T]], 1))
            pos.append(s.positions_local[st + P:st + P + T])
            tr.append(s.features[st + P:st + P + T, :2])
    if not ins:
        raise ValueError(f"dataset: no sequence has the {P + T} frames of a window")
    return np.stack(ins), np.stack(pos), np.stack(tr)


def zero_velocity(inputs: np.ndarray, prefix: int):
    """Baseline: the last prefix frame's pose and translations, held for the T frames."""
    B, L, F = inputs.shape
    J = (F - 8) // 4
    T = L - prefix
    rot = np.repeat(inputs[:, prefix - 1:prefix, :4 * J].reshape(B, 1, J, 4), T, axis=1)
    tr = np.repeat(inputs[:, prefix - 1:prefix, 4 * J:4 * J + 2], T, axis=1)
    return rot, tr


def position_errors(skeleton: Skeleton, rotations, translations, target_positions) -> tuple[np.ndarray, np.ndarray]:
    """Per horizon frame: mean joint-position error and mean joint-velocity error (units), positions from FK
    with root ``(0, height, 0)`` as the loss, or ``rotations`` themselves when they are positions (..., J, 3)
    (QN §4.4.2: velocity error = Euclidean error of the first difference of the positions).

    Returns
    -------
    position : (T,); velocity : (T - 1,)
    """
    rot = np.asarray(rotations, np.float64)
    tr = np.asarray(translations, np.float64)
    if rot.shape[-1] == 3:  # a position-output model: the positions themselves
        pos = rot
    else:
        root = np.zeros(rot.shape[:-2] + (3,))
        root[..., 1] = tr[..., 1]
        pos = skeleton.forward_kinematics(rot, root)                        # (B, T, J, 3)
    tgt = np.asarray(target_positions, np.float64)
    perr = np.linalg.norm(pos - tgt, axis=-1).mean(axis=(0, 2))
    verr = np.linalg.norm(np.diff(pos, axis=1) - np.diff(tgt, axis=1), axis=-1).mean(axis=(0, 2))
    return perr, verr


def evaluate(test_ds: LocomotionDataset, methods_by_name: Mapping[str, Callable], batch: int = 64) -> dict:
    """Free-running held-out error of every method over the T-frame horizon (:func:`evaluation_windows`,
    :func:`position_errors`): ``{name: {"position": (T,), "velocity": (T-1,), "mean_position", "mean_velocity",
    "windows"}}`` in QuaterNet units (× 5.6444 for cm)."""
    inputs, tpos, _ = evaluation_windows(test_ds)
    out = {}
    for name, f in methods_by_name.items():
        rots, trs = [], []
        for i in range(0, len(inputs), batch):
            r, t = f(inputs[i:i + batch], test_ds.prefix)
            rots.append(np.asarray(r, np.float64))
            trs.append(np.asarray(t, np.float64))
        perr, verr = position_errors(test_ds.skeleton, np.concatenate(rots), np.concatenate(trs), tpos)
        out[name] = {"position": perr, "velocity": verr, "mean_position": float(perr.mean()),
                     "mean_velocity": float(verr.mean()), "windows": int(len(inputs))}
    return out


def format_results(results: Mapping[str, dict], horizons=(1, 10, 30, 60)) -> str:
    """A table of the position error (units and cm) at a few horizon frames, and the mean velocity error."""
    names = list(results)
    T = len(results[names[0]]["position"])
    hs = [h for h in horizons if h <= T]
    head = ["method"] + [f"pos@{h}" for h in hs] + ["pos mean", "pos mean cm", "vel mean"]
    rows = [head]
    for n in names:
        r = results[n]
        rows.append([n] + [f"{r['position'][h - 1]:.3f}" for h in hs]
                    + [f"{r['mean_position']:.3f}", f"{r['mean_position'] * QUATERNET_UNIT_CM:.2f}",
                       f"{r['mean_velocity']:.4f}"])
    w = [max(len(r[i]) for r in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(x) for c, x in zip(r, w)) for r in rows)
