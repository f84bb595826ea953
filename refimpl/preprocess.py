"""Preprocessing: temporal downsampling, antipodal fix, sliding windows, file splits, feature statistics.

(spec/data.md §5.) Conventions: time is axis 0 of a motion's arrays and of ``windows``' input; feature
statistics reduce every axis but the last.

Shape legend: T frames, J joints, F features, N windows, L window length.
"""
from __future__ import annotations

import dataclasses
from typing import Sequence

import numpy as np

from refimpl.motion import Motion
from refimpl.quat import quat_fix

__all__ = ["downsample", "fix_antipodal", "windows", "split_by_file", "feature_statistics",
           "normalize_features", "denormalize_features"]


def _positive_int(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name}: expected a positive int, got {value!r}")
    return int(value)


def downsample(motion: Motion, stride: int, phase: int = 0) -> Motion:
    """Keep every ``stride``-th frame starting at ``phase``; the frame time is multiplied by ``stride``.

    QuaterNet: H3.6M 50 → 25 Hz with ``stride=2`` and keeps both phases as separate sequences (``_d0``,
    ``_d1``); the locomotion data 120 → 30 Hz with ``stride=4`` (spec/prediction.md §2, spec/locomotion.md §3.2).
    No filtering is applied (plain decimation, as the references do).

    Parameters
    ----------
    motion : Motion
    stride : int >= 1
    phase : int, 0 <= phase < stride

    Returns
    -------
    Motion with frames ``phase, phase + stride, ...`` (``ceil((T − phase) / stride)`` frames) and
    ``frame_time · stride``; same skeleton and name.
    """
    if not isinstance(motion, Motion):
        raise ValueError(f"motion: expected a Motion, got {type(motion).__name__}")
    stride = _positive_int(stride, "stride")
    if isinstance(phase, bool) or not isinstance(phase, (int, np.integer)) or not 0 <= phase < stride:
        raise ValueError(f"phase: expected an int in 0..{stride - 1}, got {phase!r}")
    extra = {} if motion.translations is None else {"translations": motion.translations[phase::stride]}
    return dataclasses.replace(motion, rotations=motion.rotations[phase::stride],
                               root_positions=motion.root_positions[phase::stride],
                               frame_time=motion.frame_time * stride, **extra)


def fix_antipodal(motion: Motion) -> Motion:
    """Make every joint's quaternion track continuous over time (``quat_fix``: frame t is negated when it lies in
    the other hemisphere than the corrected frame t − 1; QuaterNet's ``qfix``, dual-quaternion paper §5.1).

    The rotations are unchanged (``q ≡ −q``). The readers already apply it; use it after editing rotations.
    For frame arrays of a representation use :func:`refimpl.representations.fix_antipodal_frames`.
    """
    if not isinstance(motion, Motion):
        raise ValueError(f"motion: expected a Motion, got {type(motion).__name__}")
    if motion.num_frames == 0:
        return motion
    return dataclasses.replace(motion, rotations=quat_fix(motion.rotations))


def windows(array, length: int, stride: int = 1) -> np.ndarray:
    """Sliding windows along axis 0, as a read-only VIEW (no copy).

    Parameters
    ----------
    array : array_like, shape (T, ...)
    length : int >= 1
        Window length L.
    stride : int >= 1
        Step between window starts.

    Returns
    -------
    ndarray, shape (N, L, ...) with ``N = (T − L) // stride + 1`` (0 when ``T < L``); window ``n`` is
    ``array[n·stride : n·stride + L]``. It shares memory with ``array`` (read-only; copy before editing).
    """
    arr = np.asarray(array)
    length = _positive_int(length, "length")
    stride = _positive_int(stride, "stride")
    if arr.ndim < 1:
        raise ValueError(f"array: expected shape (T, ...), got a scalar")
    if arr.shape[0] < length:
        out = np.empty((0, length) + arr.shape[1:], dtype=arr.dtype)
        out.flags.writeable = False
        return out
    view = np.lib.stride_tricks.sliding_window_view(arr, length, axis=0)  # (T − L + 1, ..., L)
    return np.moveaxis(view, -1, 1)[::stride]                              # (N, L, ...)


def _windows_naive(array: np.ndarray, length: int, stride: int = 1) -> np.ndarray:
    """Loop version of :func:`windows` (test oracle)."""
    starts = range(0, array.shape[0] - length + 1, stride)
    return np.array([array[s:s + length] for s in starts]).reshape((-1, length) + array.shape[1:])


def split_by_file(files: Sequence, fractions: Sequence[float] = (0.8, 0.1, 0.1), seed: int = 0) -> tuple:
    """Split a list of files (or any hashable items) into disjoint groups, whole files only.

    Splitting by file (not by window) keeps overlapping windows of one recording out of different groups.
    Deterministic: the items are sorted by ``str``, shuffled with ``numpy.random.default_rng(seed)`` and cut
    at the cumulative fractions (rounded to the nearest count; the last group takes the rest).

    Parameters
    ----------
    files : sequence
        Distinct items, e.g. paths.
    fractions : sequence of float
        Non-negative, summing to 1 (within 1e-9), e.g. (train, valid, test).
    seed : int

    Returns
    -------
    tuple of lists, one per fraction, each in sorted order; together they hold every item exactly once.
    """
    items = list(files)
    keys = [str(f) for f in items]
    if len(set(keys)) != len(keys):
        raise ValueError("files: items must be distinct")
    fr = np.asarray(fractions, dtype=np.float64)
    if fr.ndim != 1 or fr.size == 0 or not np.all(np.isfinite(fr)) or np.any(fr < 0) or abs(fr.sum() - 1) > 1e-9:
        raise ValueError(f"fractions: expected non-negative numbers summing to 1, got {list(fractions)!r}")
    order = sorted(range(len(items)), key=lambda i: keys[i])
    perm = np.random.default_rng(seed).permutation(len(items))
    shuffled = [order[i] for i in perm]
    cuts = np.rint(np.cumsum(fr) * len(items)).astype(int)
    cuts[-1] = len(items)
    groups, start = [], 0
    for c in cuts:
        chosen = shuffled[start:max(c, start)]
        groups.append([items[i] for i in sorted(chosen, key=lambda i: keys[i])])
        start = max(c, start)
    return tuple(groups)


def feature_statistics(frames, min_std: float = 1e-4) -> tuple[np.ndarray, np.ndarray]:
    """Per-feature mean and standard deviation over every axis but the last (population std, ddof = 0).

    Features whose std is below ``min_std`` (constant features, e.g. always-zero exp-map components) get
    std 1, so normalising leaves them at ``x − mean`` instead of amplifying noise (DMGNN's rule:
    std < 1e-4 → 1; spec/data.md §5.5).

    Parameters
    ----------
    frames : array_like, shape (..., F), or a sequence of arrays (T_i, F)
        Training frames; a sequence is concatenated along axis 0.
    min_std : float >= 0

    Returns
    -------
    mean, std : ndarray, shape (F,), float64
    """
    if isinstance(frames, (list, tuple)):
        if not frames:
            raise ValueError("frames: expected at least one array")
        parts = [np.asarray(f) for f in frames]
        widths = {p.shape[-1] if p.ndim else None for p in parts}
        if len(widths) != 1 or None in widths:
            raise ValueError(f"frames: arrays must share the last axis F, got shapes {[p.shape for p in parts]}")
        x = np.concatenate([p.reshape(-1, p.shape[-1]) for p in parts], axis=0)
    else:
        x = np.asarray(frames)
        if x.ndim < 1:
            raise ValueError("frames: expected shape (..., F), got a scalar")
        x = x.reshape(-1, x.shape[-1])
    if x.dtype.kind not in "fiub":
        raise ValueError(f"frames: expected a numeric array, got dtype {x.dtype}")
    if x.shape[0] == 0:
        raise ValueError("frames: expected at least one frame")
    if not np.all(np.isfinite(x)):
        raise ValueError("frames: contains NaN or infinite values")
    if not (np.isfinite(min_std) and min_std >= 0):
        raise ValueError(f"min_std: expected a non-negative number, got {min_std!r}")
    x = x.astype(np.float64)
    mean = x.mean(axis=0)
    std = x.std(axis=0)
    std = np.where(std < min_std, 1.0, std)
    return mean, std


def _feature_args(frames, mean, std) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate ``frames (..., F)``, ``mean (F,)``, ``std (F,)``: real numbers, finite, ``std > 0``."""
    x = np.asarray(frames)
    if x.dtype.kind not in "biuf":
        raise ValueError(f"frames: expected a real numeric array, got dtype {x.dtype}")
    if x.ndim < 1:
        raise ValueError(f"frames: expected shape (..., F), got {x.shape}")
    stats = []
    for name, value in (("mean", mean), ("std", std)):
        a = np.asarray(value)
        if a.dtype.kind not in "biuf":
            raise ValueError(f"{name}: expected a real numeric array, got dtype {a.dtype}")
        if a.shape != (x.shape[-1],):
            raise ValueError(f"{name}: expected shape ({x.shape[-1]},) (the last axis of frames {x.shape}), "
                             f"got {a.shape}")
        stats.append(a)
    mean, std = stats
    if not np.all(np.isfinite(x)):
        raise ValueError(f"frames: contains NaN or inf (shape {x.shape})")
    if not np.all(np.isfinite(mean)):
        raise ValueError("mean: contains NaN or inf")
    if not np.all(np.isfinite(std) & (std > 0)):
        raise ValueError("std: expected finite positive values (as returned by feature_statistics), got "
                         f"{std[~(np.isfinite(std) & (std > 0))][:3].tolist()}")
    return x, mean, std


def normalize_features(frames, mean, std) -> np.ndarray:
    """``(frames − mean) / std`` with the statistics of :func:`feature_statistics`; dtype of ``frames`` kept
    (integer frames give float64).

    Parameters
    ----------
    frames : array_like, shape (..., F)
        Finite real numbers.
    mean, std : array_like, shape (F,)
        Finite; ``std > 0``.

    Raises
    ------
    ValueError
        Non-numeric dtype, wrong shapes, NaN/inf anywhere, or ``std <= 0``.
    """
    x, mean, std = _feature_args(frames, mean, std)
    dtype = x.dtype if x.dtype.kind == "f" else np.float64
    return ((x - mean) / std).astype(dtype, copy=False)


def denormalize_features(frames, mean, std) -> np.ndarray:
    """``frames · std + mean``, the inverse of :func:`normalize_features` (same arguments and checks)."""
    x, mean, std = _feature_args(frames, mean, std)
    dtype = x.dtype if x.dtype.kind == "f" else np.float64
    return (x * std + mean).astype(dtype, copy=False)
