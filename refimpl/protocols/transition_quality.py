"""What an animator checks in a transition: the joins, foot skating, and the error at its first and last frames.

The paper's metric (:mod:`refimpl.protocols.transition_metrics`) averages the error over all frames; it does not
show a pop at either end of the transition or feet that slide. These measures do (spec/qtg.md §9.1). All of them work on
forward-kinematics joint positions in a window's frame (centimetres, y up, :mod:`refimpl.protocols.transition`), of the
whole sequence ``p_{-1}, p_0 | p_1 … p_T | g1, g2`` (``W = T + 4`` frames; the transition is frames
``[start, stop) = [2, T + 2)``):

* **join** — the mean joint displacement of one step, ``d[k] = mean_j ‖x[k + 1, j] − x[k, j]‖``: *into* the
  transition is the step ``p_0 → p_1`` (``d[start − 1]``), *out of* it ``p_T → g1`` (``d[stop − 1]``). Each is
  reported in cm and as a ratio to the ground truth's median step (over all windows and steps), so that 1 is
  an ordinary frame and a pop shows as a ratio of 2-3.
* **foot skating** — the mean horizontal speed (cm/s) of the foot joints (:func:`foot_joints`: names with
  ``foot`` or ``toe``) over the steps where the foot is *in contact*. Contact rule (:data:`CONTACT_HEIGHT_CM`):
  the joint is within 2 cm of its *floor* in both frames of the step, the floor being that joint's lowest
  height over the ground-truth window (all ``W`` frames). Height only, no speed criterion: a speed criterion
  applied to the generated motion would call a sliding foot "not in contact" and hide the very artefact
  measured. The same floor and rule are applied to the generated and the ground-truth frames; the share of
  foot steps in contact is reported beside the speed (a motion whose feet float never skates by this rule,
  and shows as a low contact share instead). Steps measured: the ``T + 1`` steps from ``p_0`` to ``g1``.
* **first / last frame error** — the paper's per-frame error (mean Euclidean joint error, cm) at ``p_1`` and
  ``p_T``.

Shape legend: N windows, F frames, J joints, K foot joints, T transition frames, P pose size.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

from refimpl.protocols.transition_metrics import check_groups, positions_from_poses, predict_transitions
from refimpl.arrays import float_array
from refimpl.protocols.transition import TransitionDataset

__all__ = ["CONTACT_HEIGHT_CM", "FOOT_WORDS", "foot_joints", "step_displacement", "join_displacement",
           "contact_floor", "foot_contacts", "skate_speed", "window_quality", "evaluate_quality", "prediction_quality",
           "format_groups", "format_quality"]

#: A foot joint is in contact when it is within this height (cm) of its floor (its lowest height over the
#: ground-truth window). Why 2 cm: spec/qtg.md §9.1 (on the sample's held-out windows it marks 51 % of the walks'
#: ground-truth foot steps as contacts, at 31 cm/s: the toe rolling off, heels lifting).
CONTACT_HEIGHT_CM = 2.0
#: Words (case-insensitive) that mark a foot joint's name: CMU ``LeftFoot``/``LeftToeBase``, salsa ``lFoot``.
FOOT_WORDS = ("foot", "toe", "ankle")


def foot_joints(skeleton) -> tuple[int, ...]:
    """Indices of the skeleton's foot joints: names containing one of :data:`FOOT_WORDS`.

    Raises
    ------
    ValueError
        The skeleton has no such joint.
    """
    feet = tuple(j for j, n in enumerate(skeleton.names) if any(w in n.lower() for w in FOOT_WORDS))
    if not feet:
        raise ValueError(f"skeleton: no foot joint (a name containing {' or '.join(FOOT_WORDS)}) among "
                         f"{list(skeleton.names)[:6]} ...")
    return feet


def _positions(positions, name="positions") -> np.ndarray:
    return float_array(positions, name, (None, None, None, 3), cast=False).astype(np.float64, copy=False)


def step_displacement(positions) -> np.ndarray:
    """Mean joint displacement of every step, ``d[n, k] = mean_j ‖x[n, k + 1, j] − x[n, k, j]‖``.

    Parameters
    ----------
    positions : ndarray (N, F, J, 3)

    Returns
    -------
    ndarray (N, F − 1)
    """
    x = _positions(positions)
    return np.linalg.norm(np.diff(x, axis=1), axis=-1).mean(axis=-1)


def join_displacement(positions, start: int, stop: int) -> tuple[np.ndarray, np.ndarray]:
    """Displacement into the first generated frame and out of the last one.

    Parameters
    ----------
    positions : ndarray (N, F, J, 3)
        Context and generated frames; frames ``[start, stop)`` are generated, ``1 <= start < stop <= F − 1``.
    start, stop : int

    Returns
    -------
    into, out : ndarray (N,)
        ``d[start − 1]`` (frame ``start − 1 → start``) and ``d[stop − 1]`` (frame ``stop − 1 → stop``) of
        :func:`step_displacement`.
    """
    x = _positions(positions)
    if not 1 <= start < stop <= x.shape[1] - 1:
        raise ValueError(f"start, stop: expected 1 <= start < stop <= F - 1 = {x.shape[1] - 1}, got {start}, {stop}")
    d = step_displacement(x[:, start - 1:stop + 1])  # (N, stop − start + 1)
    return d[:, 0], d[:, -1]


def contact_floor(positions, feet, up: int = 1) -> np.ndarray:
    """Each foot joint's floor: its lowest height over the frames, ``min_k x[n, k, feet, up]``.

    Parameters
    ----------
    positions : ndarray (N, F, J, 3)
        The ground truth of the whole window.
    feet : sequence of int (K,)
    up : int
        Index of the vertical axis (1: y up).

    Returns
    -------
    ndarray (N, K)
    """
    x = _positions(positions)
    return x[:, :, list(feet), up].min(axis=1)


def foot_contacts(positions, feet, floor, *, height: float = CONTACT_HEIGHT_CM, up: int = 1) -> np.ndarray:
    """Contacts of the foot joints per STEP: both frames of step ``k → k + 1`` within ``height`` of the floor.

    Parameters
    ----------
    positions : ndarray (N, F, J, 3)
    feet : sequence of int (K,)
    floor : ndarray (N, K)
        :func:`contact_floor` of the ground truth.
    height : float
        Contact threshold in the positions' unit.
    up : int

    Returns
    -------
    ndarray (N, F − 1, K), bool
    """
    x = _positions(positions)
    feet = list(feet)
    floor = float_array(floor, "floor", (x.shape[0], len(feet)), cast=False)
    if not (np.isfinite(height) and height > 0):
        raise ValueError(f"height: expected a positive threshold, got {height!r}")
    low = x[:, :, feet, up] - floor[:, None] < height  # (N, F, K)
    return low[:, 1:] & low[:, :-1]


def skate_speed(positions, feet, floor, dt: float, *, height: float = CONTACT_HEIGHT_CM,
                up: int = 1) -> tuple[float, float]:
    """Mean horizontal speed of the foot joints over the steps where they are in contact (:func:`foot_contacts`).

    Parameters
    ----------
    positions : ndarray (N, F, J, 3)
    feet : sequence of int (K,)
    floor : ndarray (N, K)
    dt : float
        Frame time (s).
    height : float
    up : int

    Returns
    -------
    speed : float
        ``mean over contact steps of ‖Δx_horizontal‖ / dt`` (position unit per second); NaN without contacts.
    share : float
        Contact steps / all ``N (F − 1) K`` foot steps.
    """
    x = _positions(positions)
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: expected a positive frame time, got {dt!r}")
    total, count, steps = _contact_speeds(x, feet, floor, dt, height, up)
    n = count.sum()
    return (float(total.sum() / n) if n else float("nan")), float(n / (steps * len(total)))


def _contact_speeds(x, feet, floor, dt, height, up):
    """Per window: the sum of horizontal foot speeds over contact steps ``(N,)``, their number ``(N,)``, and the
    number of foot steps of one window ``(F − 1) K``."""
    contact = foot_contacts(x, feet, floor, height=height, up=up)  # (N, F − 1, K)
    flat = [a for a in range(3) if a != up]
    v = np.linalg.norm(np.diff(x[:, :, list(feet)][..., flat], axis=1), axis=-1) / dt  # (N, F − 1, K)
    return np.where(contact, v, 0.0).sum(axis=(1, 2)), contact.sum(axis=(1, 2)), contact[0].size


def window_quality(pred_pos, gt_pos, feet, dt: float, *, past: int = 2, future: int = 2,
                   height: float = CONTACT_HEIGHT_CM, up: int = 1) -> dict:
    """All measures of one method on windows whose context frames equal the ground truth's.

    Parameters
    ----------
    pred_pos, gt_pos : ndarray (N, W, J, 3)
        Whole windows (``past`` context, ``T`` frames, ``future`` context); ``pred_pos``' context frames are the
        ground truth's, its transition frames the method's.
    feet : sequence of int
    dt : float
    past, future : int
    height : float
    up : int

    Returns
    -------
    dict
        ``join_in_cm``, ``join_out_cm`` (means over windows), ``join_in_ratio``, ``join_out_ratio`` (against
        ``ground_truth.median_step_cm``), ``skate_cm_s``, ``contact_share``, ``first_frame_cm``,
        ``last_frame_cm``, and ``ground_truth``: the same join, skating and contact numbers of ``gt_pos`` plus
        its ``median_step_cm`` (all steps of all windows).
    """
    return _summarise(_window_arrays(pred_pos, gt_pos, feet, dt, past, future, height, up))


def _window_arrays(pred_pos, gt_pos, feet, dt, past, future, height, up) -> dict:
    """Per-window numbers of :func:`window_quality`, so that any subset of windows can be summarised exactly."""
    pred, gt = _positions(pred_pos, "pred_pos"), _positions(gt_pos, "gt_pos")
    if pred.shape != gt.shape:
        raise ValueError(f"pred_pos: expected the shape of gt_pos {gt.shape}, got {pred.shape}")
    W = gt.shape[1]
    start, stop = past, W - future
    floor = contact_floor(gt, feet, up=up)  # (N, K)
    out = {"gt_steps": step_displacement(gt),  # (N, W − 1)
           "err": np.linalg.norm(pred[:, start:stop] - gt[:, start:stop], axis=-1).mean(axis=-1)}  # (N, T)
    for tag, x in (("", pred), ("gt_", gt)):
        out[tag + "into"], out[tag + "out"] = join_displacement(x, start, stop)  # (N,), (N,)
        total, count, steps = _contact_speeds(x[:, start - 1:stop + 1], feet, floor, dt, height, up)
        out[tag + "skate_sum"], out[tag + "contacts"] = total, count
        out[tag + "foot_steps"] = np.full(len(total), steps)
    return out


def _summarise(a: dict, sel=None) -> dict:
    """:func:`window_quality`'s dict of the windows ``sel`` (default all) of :func:`_window_arrays`' arrays."""
    a = a if sel is None else {k: v[sel] for k, v in a.items()}
    median = float(np.median(a["gt_steps"]))

    def measures(tag):
        n = a[tag + "contacts"].sum()
        return {"join_in_cm": float(a[tag + "into"].mean()), "join_out_cm": float(a[tag + "out"].mean()),
                "skate_cm_s": float(a[tag + "skate_sum"].sum() / n) if n else float("nan"),
                "contact_share": float(n / a[tag + "foot_steps"].sum())}

    res = measures("")
    err = a["err"].mean(axis=0)  # (T,)
    res.update(join_in_ratio=_ratio(res["join_in_cm"], median), join_out_ratio=_ratio(res["join_out_cm"], median),
               first_frame_cm=float(err[0]), last_frame_cm=float(err[-1]),
               ground_truth=dict(measures("gt_"), median_step_cm=median), num_windows=int(a["err"].shape[0]))
    return res


def evaluate_quality(dataset: TransitionDataset, methods: Mapping[str, Callable], batch_size: int = 1024,
                     height: float = CONTACT_HEIGHT_CM, labels: bool = True,
                     groups: Mapping[str, np.ndarray] | None = None) -> dict:
    """:func:`prediction_quality` of every method's :func:`~refimpl.protocols.transition_metrics.predict_transitions`
    on all windows of ``dataset``.

    Parameters
    ----------
    dataset : TransitionDataset
    methods : mapping name -> f(past, target, T) -> poses
        Un-normalised poses in and out, as :func:`refimpl.protocols.transition_metrics.evaluate_methods`.
    batch_size : int
    height : float
        Contact threshold (cm).
    labels : bool
        Also ``by_label`` (:func:`prediction_quality`).
    groups : mapping grouping name -> ndarray (N,) of str, optional
        More breakdowns (:func:`refimpl.protocols.transition_metrics.evaluate_methods`): ``by_<name>``.

    Returns
    -------
    dict name -> :func:`prediction_quality`'s dict
    """
    groups = check_groups(groups, dataset.num_windows) if isinstance(dataset, TransitionDataset) else {}
    return {name: prediction_quality(dataset, predict_transitions(dataset, f, name, batch_size),  # validates dataset
                                     height=height, labels=labels, groups=groups)
            for name, f in methods.items()}


def prediction_quality(dataset: TransitionDataset, pred, height: float = CONTACT_HEIGHT_CM, labels: bool = True,
                       groups: Mapping[str, np.ndarray] | None = None) -> dict:
    """:func:`window_quality` of one method's transitions of all windows of ``dataset`` (windows of every skeleton
    pooled: means over windows, the median step and the skating over all of them) and, with ``labels``, per source
    label.

    Parameters
    ----------
    dataset : TransitionDataset
    pred : ndarray (N, T, P)
        The method's un-normalised poses, e.g. :func:`refimpl.protocols.transition_metrics.predict_transitions`.
    height : float
        Contact threshold (cm).
    labels : bool
        Also ``by_label``: ``{label: window_quality's dict}`` (walk, run, ... or a locomotion set's styles).
    groups : mapping grouping name -> ndarray (N,) of str, optional
        More breakdowns (:func:`refimpl.protocols.transition_metrics.evaluate_methods`): ``by_<name>``.

    Returns
    -------
    dict
        :func:`window_quality`'s dict, plus ``contact_rule`` (threshold, floor, foot joints), ``by_label`` and
        ``by_<group>``.
    """
    if not isinstance(dataset, TransitionDataset) or dataset.num_windows == 0:
        raise ValueError("dataset: no windows to evaluate" if isinstance(dataset, TransitionDataset) else
                         f"dataset: expected a TransitionDataset, got {type(dataset).__name__}")
    past, gt, target = dataset.context()
    pred = float_array(pred, "pred", gt.shape, cast=False)
    groups = check_groups(groups, dataset.num_windows)
    whole = np.concatenate([past, pred, target], axis=1)  # (N, W, P)
    arrays: dict = {}
    for k in np.unique(dataset.skeleton_index):
        sel = np.flatnonzero(dataset.skeleton_index == k)
        skel = dataset.skeletons[int(k)]
        part = _window_arrays(positions_from_poses(whole[sel], skel), positions_from_poses(dataset.poses[sel], skel),
                              foot_joints(skel), 1.0 / dataset.fps, dataset.past, dataset.future, height, 1)
        for key, v in part.items():
            arrays.setdefault(key, np.zeros((dataset.num_windows,) + v.shape[1:], v.dtype))[sel] = v
    res = _summarise(arrays)
    res["contact_rule"] = {
        "height_cm": float(height), "floor": "each foot joint's lowest height over the ground-truth window",
        "foot_joints": sorted({dataset.skeletons[int(k)].names[j] for k in np.unique(dataset.skeleton_index)
                               for j in foot_joints(dataset.skeletons[int(k)])})}
    if labels:
        label_of = np.array([dataset.sources[i].label for i in dataset.source_index])
        res["by_label"] = {lab: _summarise(arrays, label_of == lab) for lab in sorted(set(label_of))}
    for g, v in groups.items():
        res[f"by_{g}"] = {lab: _summarise(arrays, v == lab) for lab in sorted(set(v.tolist()))}
    return res


def _ratio(a: float, m: float) -> float:
    """``a / m``; NaN when the ground truth does not move (``m = 0``)."""
    return a / m if m > 0 else float("nan")


def format_quality(quality: Mapping[str, dict]) -> str:
    """Plain-text table of :func:`evaluate_quality`: one row per method, then the ground truth."""
    names = list(quality)
    if not names:
        return ""
    head = ["method", "join in cm", "(×gt step)", "join out cm", "(×gt step)", "skate cm/s", "contact",
            "f1 err cm", "fT err cm"]
    rows = [head]
    for n in names:
        q = quality[n]
        rows.append([n, f"{q['join_in_cm']:.2f}", f"{q['join_in_ratio']:.2f}", f"{q['join_out_cm']:.2f}",
                     f"{q['join_out_ratio']:.2f}", f"{q['skate_cm_s']:.1f}", f"{q['contact_share']:.2f}",
                     f"{q['first_frame_cm']:.2f}", f"{q['last_frame_cm']:.2f}"])
    g = quality[names[0]]["ground_truth"]
    m = g["median_step_cm"]
    rows.append(["ground truth", f"{g['join_in_cm']:.2f}", f"{_ratio(g['join_in_cm'], m):.2f}",
                 f"{g['join_out_cm']:.2f}", f"{_ratio(g['join_out_cm'], m):.2f}", f"{g['skate_cm_s']:.1f}",
                 f"{g['contact_share']:.2f}", "0", "0"])
    widths = [max(len(r[i]) for r in rows) for i in range(len(head))]
    rule = quality[names[0]].get("contact_rule", {})
    note = (f"ground truth median step {m:.2f} cm; contact: a foot joint ({', '.join(rule.get('foot_joints', []))}) "
            f"within {rule.get('height_cm', CONTACT_HEIGHT_CM):g} cm of its lowest ground-truth height in the "
            "window, in both frames of a step")
    return "\n".join("  ".join(c.rjust(w) if i else c.ljust(w) for i, (c, w) in enumerate(zip(r, widths)))
                     for r in rows) + "\n" + note


def format_groups(results: Mapping[str, dict]) -> list[tuple[str, str]]:
    """``[(grouping, table)]`` for every ``by_<grouping>`` breakdown of evaluation results (``by_label`` aside;
    e.g. ``style``, ``kind``): per label, each method's mean error (cm) and its foot skating (cm/s) at its contact
    share, then the ground truth's skating, contact share and number of windows."""
    first = next(iter(results.values()), {})
    names = [k[3:] for k in first if k.startswith("by_") and k != "by_label" and isinstance(first[k], dict)]
    return [(g, _group_table(results, g)) for g in names]


def _group_table(results: Mapping[str, dict], group: str) -> str:
    """Rows: the group's labels; columns: each method's mean error and skating at its contact share."""
    names = list(results)
    key = f"by_{group}"
    labels = list(results[names[0]][key])

    def cell(q):
        skate = "-" if q["skate_cm_s"] is None or not np.isfinite(q["skate_cm_s"]) else f"{q['skate_cm_s']:.1f}"
        return f"{skate}@{q['contact_share']:.2f}"

    rows = [[group] + names + ["ground truth"]]
    for lab in labels:
        row = [lab]
        for n in names:
            q = results[n].get("quality", {}).get(key, {}).get(lab)
            row.append(f"{results[n][key][lab]:.2f} | {cell(q)}" if q else f"{results[n][key][lab]:.2f}")
        gt = results[names[0]].get("quality", {}).get(key, {}).get(lab)
        row.append(f"{cell(gt['ground_truth'])} [{gt['num_windows']}]" if gt else "")
        rows.append(row)
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) if not i else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
                     for r in rows)
