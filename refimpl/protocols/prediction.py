"""Short-term motion prediction, the evaluation (spec/prediction.md): protocol, error, baselines, tables.

QuaterNet journal paper §4.2, Tables 1-2; the protocol is the one of the published evaluation
(spec/prediction.md §3), which replicates Fragkiadaki et al. / Martinez et al. The data is in
:mod:`refimpl.protocols.prediction_data`.

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
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.protocols.prediction_data import PredictionData
from refimpl.rotations import euler_from_quat, quat_from_euler

__all__ = [
    "SEED", "Protocol", "TABLE2_HORIZONS_MS", "table2_protocol", "make_protocol", "window_starts",
    "evaluation_windows", "euler_errors", "PredictionResult", "evaluate", "zero_velocity", "running_average",
    "baseline_methods", "format_table", "results_to_dict", "write_results_json", "evaluate_all", "canonical_prefix",
    "average_curves",
]

#: Seed of the fresh ``RandomState`` each action's window draws start from (the published evaluation).
SEED = 1234567890


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
    """
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


def evaluate_all(data: PredictionData, methods_by_name: Mapping[str, Callable], protocol: Protocol | None = None,
                 *, progress: Callable[[str], None] | None = None, actions: Sequence[str] | None = None) -> list:
    """:func:`evaluate` of every method under ``protocol`` (default: the dataset's standard one) on ``actions``
    (default all); a list of :class:`PredictionResult` in the methods' order."""
    protocol = make_protocol(data.dataset) if protocol is None else protocol
    return [evaluate(m, data, protocol, method_name=name, progress=progress, actions=actions)
            for name, m in methods_by_name.items()]


def canonical_prefix(prefix) -> np.ndarray:
    """The published predict's canonicalisation (reference §6.5, §12 item 12): quaternions -> zyx Euler ->
    quaternions -> ``quat_fix`` over time. ``(B, P, J, 4) -> (B, P, J, 4)``, the same rotations."""
    from refimpl.quat import quat_fix

    x = np.asarray(prefix, dtype=np.float64)
    q = quat_from_euler(euler_from_quat(x, "zyx"), "zyx")  # (B, P, J, 4)
    return np.ascontiguousarray(np.swapaxes(quat_fix(np.swapaxes(q, 0, 1)), 0, 1))


def average_curves(results: Sequence[PredictionResult]) -> dict:
    """``method -> (K,)`` mean per-frame error over the actions (for a plot)."""
    return {r.method: np.mean(np.stack(list(r.curves.values())), axis=0) for r in results}
