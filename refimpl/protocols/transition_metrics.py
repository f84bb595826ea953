"""Transition metrics: joint-position error per joint per frame, and the three-method comparison table.

The QTG paper reports "the Mean Absolute Error per joint per frame" in centimetres (its Fig. 3) without a
formula. We define it (spec/qtg.md §9) from forward-kinematics positions of the 22-joint skeleton, root
included, in the window frame (root-relative, refimpl/protocols/transition.py), in centimetres:

    e[n, t, j] = ‖ FK(pred)[n, t, j] − FK(gt)[n, t, j] ‖₂          (Euclidean distance of joint j)
    curve[t]   = mean over n, j of e[n, t, j]                       (per-frame curve, t = 1 … T)
    mean       = mean over t of curve[t]                            (one number per method)

Predicted quaternions are normalised before FK (the network's raw outputs are not unit). As a secondary
number we also give the per-coordinate mean absolute error ``mean |Δx|, |Δy|, |Δz|`` (the literal "MAE").

The synthesis metrics (NPSS, acceleration) are in :mod:`refimpl.protocols.synthesis`.

Shape legend: N windows, T transition frames, J joints, P pose size, D features.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from refimpl.arrays import float_array
from refimpl.protocols.transition import TransitionDataset, split_pose
from refimpl.skeleton import Skeleton

__all__ = ["positions_from_poses", "joint_position_errors", "evaluate_methods", "prediction_errors", "check_groups",
           "predict_transitions", "format_table"]


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
    poses = float_array(poses, "poses", (..., None), cast=False)
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
    pred = float_array(pred, "pred", (None, None, None), cast=False)
    gt = float_array(gt, "gt", pred.shape, cast=False)
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
                     labels: bool = True, groups: Mapping[str, np.ndarray] | None = None) -> dict:
    """Run every method on every window of ``dataset`` and measure it (spec/qtg.md §9): each method's
    :func:`predict_transitions`, then their :func:`prediction_errors`.

    Parameters
    ----------
    dataset : TransitionDataset
    methods : mapping name -> f(past, target, T) -> poses
        E.g. :func:`refimpl.protocols.transition_baselines.method_registry`; un-normalised poses in and out.
    batch_size : int
        Windows per call.
    labels : bool
        Also break the mean down by source label (walk, run, jump, salsa).
    groups : mapping grouping name -> ndarray (N,) of str, optional
        More breakdowns, e.g. ``{"style": ..., "kind": ...}``
        (:func:`refimpl.protocols.transition_locomotion.window_groups`): ``by_<name>``.

    Returns
    -------
    dict name -> :func:`prediction_errors`' dict
    """
    _check_dataset(dataset)
    groups = check_groups(groups, dataset.num_windows)
    return {name: prediction_errors(dataset, predict_transitions(dataset, f, name, batch_size), labels=labels,
                                    groups=groups)
            for name, f in methods.items()}


def prediction_errors(dataset: TransitionDataset, pred, labels: bool = True,
                      groups: Mapping[str, np.ndarray] | None = None) -> dict:
    """The paper's measure (spec/qtg.md §9) of one method's transitions of every window of ``dataset``.

    Parameters
    ----------
    dataset : TransitionDataset
    pred : ndarray (N, T, P)
        The method's un-normalised poses, e.g. :func:`predict_transitions`.
    labels : bool
        Also break the mean down by source label (walk, run, jump, salsa).
    groups : mapping grouping name -> ndarray (N,) of str, optional
        More breakdowns (:func:`evaluate_methods`): ``by_<name>``.

    Returns
    -------
    dict {"mean_cm": float, "per_frame_cm": ndarray (T,), "abs_coord_cm": float,
          "by_label": {label: mean_cm}, "by_<group>": {label: mean_cm}, "num_windows": N}
    """
    _check_dataset(dataset)
    gt = dataset.context()[1]
    pred = float_array(pred, "pred", gt.shape, cast=False)
    groups = check_groups(groups, dataset.num_windows)
    dist, absc = joint_position_errors(pred, gt, dataset.skeletons, dataset.skeleton_index)
    res = {"mean_cm": float(dist.mean()), "per_frame_cm": dist.mean(axis=(0, 2)),
           "abs_coord_cm": float(absc.mean()), "num_windows": int(dataset.num_windows)}
    if labels:
        label_of = np.array([dataset.sources[i].label for i in dataset.source_index])
        res["by_label"] = {lab: float(dist[label_of == lab].mean()) for lab in sorted(set(label_of))}
    for g, v in groups.items():
        res[f"by_{g}"] = {lab: float(dist[v == lab].mean()) for lab in sorted(set(v.tolist()))}
    return res


def check_groups(groups: Mapping[str, np.ndarray] | None, num_windows: int) -> dict:
    """``groups`` as ``{name: ndarray (N,) of str}``, checked (ValueError naming the group otherwise)."""
    out = {}
    for g, v in dict(groups or {}).items():
        v = np.asarray(v)
        if v.shape != (num_windows,):
            raise ValueError(f"groups[{g!r}]: expected shape ({num_windows},), got {v.shape}")
        out[str(g)] = v
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
        A method with ``needs_skeleton`` set (foot locking) is called per skeleton with ``skeleton=``.
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
    if getattr(method, "needs_skeleton", False):
        pred = np.zeros(gt.shape)
        for k in np.unique(dataset.skeleton_index):
            sel = np.flatnonzero(dataset.skeleton_index == k)
            for i in range(0, sel.size, batch_size):
                idx = sel[i:i + batch_size]
                out = np.asarray(method(past[idx], target[idx], T, skeleton=dataset.skeletons[int(k)]), np.float64)
                if out.shape != (idx.size,) + gt.shape[1:]:
                    raise ValueError(f"methods[{name!r}]: expected output shape {(idx.size,) + gt.shape[1:]}, "
                                     f"got {out.shape}")
                pred[idx] = out
        return pred
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
