"""Transition metrics: joint-position error per joint per frame, and the three-method comparison table.

The QTG paper reports "the Mean Absolute Error per joint per frame" in centimetres (its Fig. 3) without a
formula. We define it (spec/qtg.md §9) from forward-kinematics positions of the 22-joint skeleton, root
included, in the window frame (root-relative, refimpl/transitions.py), in centimetres:

    e[n, t, j] = ‖ FK(pred)[n, t, j] − FK(gt)[n, t, j] ‖₂          (Euclidean distance of joint j)
    curve[t]   = mean over n, j of e[n, t, j]                       (per-frame curve, t = 1 … T)
    mean       = mean over t of curve[t]                            (one number per method)

Predicted quaternions are normalised before FK (the network's raw outputs are not unit). As a secondary
number we also give the per-coordinate mean absolute error ``mean |Δx|, |Δy|, |Δz|`` (the literal "MAE").

Synthesis metrics (the dual-quaternion paper's Table 1, spec/acrnn.md §6): :func:`root_zeroed_positions`,
:func:`mean_joint_error` (Euclidean, root zeroed), :func:`npss` (Gopalakrishnan et al.'s power spectrum
``|X|²`` = ``"power"``, or the LaFAN1 ``fast_npss`` copy used by the dual-quaternion paper's evaluation,
``(Re X)²`` = ``"real"``) and :func:`mean_acceleration` / :func:`acceleration_comparison`.

Shape legend: N windows, T transition frames, J joints, P pose size, D features.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from refimpl.nn.params import check_float_array
from refimpl.representations import REPRESENTATIONS, decode, positions_from_frames
from refimpl.skeleton import Skeleton
from refimpl.transitions import TransitionDataset, split_pose

__all__ = ["positions_from_poses", "joint_position_errors", "evaluate_methods", "predict_transitions", "format_table",
           "NPSS_VARIANTS", "root_zeroed_positions", "mean_joint_error", "npss", "mean_acceleration",
           "acceleration_comparison"]


def positions_from_poses(poses, skeleton: Skeleton) -> np.ndarray:
    """Forward kinematics of poses ``[root (3) | J quaternions]``; quaternions normalised first.

    Parameters
    ----------
    poses : ndarray (..., P)
    skeleton : Skeleton with J joints

    Returns
    -------
    ndarray (..., J, 3)
    """
    poses = check_float_array(poses, "poses", (..., None))
    root, quats = split_pose(poses)
    if quats.shape[-2] != skeleton.num_joints:
        raise ValueError(f"poses: expected 3 + 4·{skeleton.num_joints} values for the skeleton's "
                         f"{skeleton.num_joints} joints, got {poses.shape[-1]}")
    n = np.sqrt(np.sum(quats * quats, axis=-1, keepdims=True))
    if np.any(n < 1e-12):
        raise ValueError("poses: a joint quaternion is zero")
    return skeleton.forward_kinematics(quats / n, root)


def joint_position_errors(pred, gt, skeletons, skeleton_index) -> tuple[np.ndarray, np.ndarray]:
    """Per-joint position errors of predicted against ground-truth transitions.

    Parameters
    ----------
    pred, gt : ndarray (N, T, P)
        Un-normalised poses (root translation in the skeletons' unit, centimetres here).
    skeletons : sequence of Skeleton
    skeleton_index : ndarray (N,), int
        Which skeleton each window uses.

    Returns
    -------
    dist : ndarray (N, T, J)
        Euclidean distance ``‖FK(pred) − FK(gt)‖₂`` per joint.
    abs_coord : ndarray (N, T, J)
        Mean over x, y, z of ``|FK(pred) − FK(gt)|``.
    """
    pred = check_float_array(pred, "pred", (None, None, None))
    gt = check_float_array(gt, "gt", pred.shape)
    idx = np.asarray(skeleton_index)
    if idx.shape != (pred.shape[0],):
        raise ValueError(f"skeleton_index: expected shape ({pred.shape[0]},), got {idx.shape}")
    J = (pred.shape[-1] - 3) // 4
    dist = np.empty(pred.shape[:2] + (J,))
    absc = np.empty(pred.shape[:2] + (J,))
    for k in np.unique(idx):
        sel = idx == k
        d = positions_from_poses(pred[sel], skeletons[int(k)]) - positions_from_poses(gt[sel], skeletons[int(k)])
        dist[sel] = np.sqrt(np.sum(d * d, axis=-1))
        absc[sel] = np.mean(np.abs(d), axis=-1)
    return dist, absc


def evaluate_methods(dataset: TransitionDataset, methods: Mapping[str, Callable], batch_size: int = 1024,
                     labels: bool = True) -> dict:
    """Run every method on every window of ``dataset`` and measure it (spec/qtg.md §9).

    Parameters
    ----------
    dataset : TransitionDataset
    methods : mapping name -> f(past, target, T) -> poses
        E.g. :func:`refimpl.baselines.method_registry`; un-normalised poses in and out.
    batch_size : int
        Windows per call.
    labels : bool
        Also break the mean down by source label (walk, run, jump, salsa).

    Returns
    -------
    dict name -> {"mean_cm": float, "per_frame_cm": ndarray (T,), "abs_coord_cm": float,
                  "by_label": {label: mean_cm}, "num_windows": N}
    """
    _check_dataset(dataset)
    gt = dataset.context()[1]
    label_of = np.array([dataset.sources[i].label for i in dataset.source_index])
    out = {}
    for name, f in methods.items():
        pred = predict_transitions(dataset, f, name, batch_size)
        dist, absc = joint_position_errors(pred, gt, dataset.skeletons, dataset.skeleton_index)
        res = {"mean_cm": float(dist.mean()), "per_frame_cm": dist.mean(axis=(0, 2)),
               "abs_coord_cm": float(absc.mean()), "num_windows": int(dataset.num_windows)}
        if labels:
            res["by_label"] = {lab: float(dist[label_of == lab].mean()) for lab in sorted(set(label_of))}
        out[name] = res
    return out


def _check_dataset(dataset) -> None:
    if not isinstance(dataset, TransitionDataset):
        raise ValueError(f"dataset: expected a TransitionDataset, got {type(dataset).__name__}")
    if dataset.num_windows == 0:
        raise ValueError("dataset: no windows to evaluate")


def predict_transitions(dataset: TransitionDataset, method: Callable, name: str = "method",
                        batch_size: int = 1024) -> np.ndarray:
    """``method``'s transitions of every window of ``dataset``, ``batch_size`` windows per call.

    Parameters
    ----------
    dataset : TransitionDataset
    method : f(past (B, 2, P), target (B, 2, P), T) -> poses (B, T, P), un-normalised
    name : str
        For the error message.
    batch_size : int

    Returns
    -------
    ndarray (N, T, P), float64
    """
    _check_dataset(dataset)
    past, gt, target = dataset.context()
    T = dataset.transition_length
    pred = np.concatenate([np.asarray(method(past[i:i + batch_size], target[i:i + batch_size], T), dtype=np.float64)
                           for i in range(0, dataset.num_windows, batch_size)])
    if pred.shape != gt.shape:
        raise ValueError(f"methods[{name!r}]: expected output shape {gt.shape}, got {pred.shape}")
    return pred


def format_table(results: Mapping[str, dict], frames: tuple[int, ...] = (1, 5, 10, 20, 30)) -> str:
    """Plain-text table of :func:`evaluate_methods` results: mean, per-coordinate MAE, per-label means and
    the per-frame curve at the given (1-based) frames."""
    names = list(results)
    if not names:
        return ""
    labels = sorted(results[names[0]].get("by_label", {}))
    T = len(results[names[0]]["per_frame_cm"])
    frames = tuple(f for f in frames if 1 <= f <= T)
    head = ["method", "mean cm", "|Δ| cm"] + [f"{lab} cm" for lab in labels] + [f"f{f}" for f in frames]
    rows = [head]
    for n in names:
        r = results[n]
        rows.append([n, f"{r['mean_cm']:.2f}", f"{r['abs_coord_cm']:.2f}"]
                    + [f"{r['by_label'][lab]:.2f}" for lab in labels]
                    + [f"{r['per_frame_cm'][f - 1]:.2f}" for f in frames])
    widths = [max(len(row[i]) for row in rows) for i in range(len(head))]
    return "\n".join("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(row, widths)))
                     for row in rows)


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
    pred = check_float_array(pred, "pred", (..., 3))
    gt = check_float_array(gt, "gt", pred.shape)
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
    x = check_float_array(positions, "positions", (None, None, None, 3))
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
