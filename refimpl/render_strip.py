"""Frame strips of skeletal motion (matplotlib, optional): :func:`render_strip`, and for transitions
:func:`join_frames` (the frames on both sides of each join) and :func:`limb_sides` (left / right colouring).

What an animator looks for in a transition, and how the strip shows it:

* the joins — with :func:`join_frames` the strip holds the last past frames, the first generated frames, the
  last generated frames and the first target frames, labelled so; a pop shows as a jump between neighbours;
* travel and sliding — one floor for the whole clip (one height, one square size), its grid fixed in the world
  (:func:`refimpl.render_kernel.grid_segments`) while each panel is centred on the character, and with ``feet``
  the floor track of each foot in contact at the frame shown, over its last :data:`FOOT_TRACK` contact frames:
  a planted foot is a dot under it, a skating foot a streak ending under it;
* left and right — with ``sides`` (:func:`limb_sides`, the one rule of every model's pictures) left limbs are
  drawn in a darker, right limbs in a lighter shade.

Conventions as in :mod:`refimpl.render` (the drawing helpers are in :mod:`refimpl.render_kernel`). Shape legend: T frames,
J joints, N drawn frames.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from refimpl.render_kernel import (CONTEXT_COLOR, GHOST_COLOR, GT_COLOR, PRED_COLOR, SIDES_NOTE, bone_colors,
                                   bone_segments, centre_axes, check_highlight, check_numbers, check_parents,
                                   check_positions, check_sides, check_up, clip_floor, figure, fit_text, half_extent,
                                   joint_colors, pick_frames, save_figure, setup_axes, title_height, to_plot,
                                   wrap_title)

__all__ = ["render_strip", "join_frames", "limb_sides", "FOOT_TRACK"]

_TITLE_SIZE = 10.0

#: Frames of foot track drawn in each panel (0.2 s at 30 fps).
FOOT_TRACK = 6


def join_frames(start: int, stop: int, num_total: int, *, middle: int = 1) -> list[int]:
    """The frames a transition strip shows: the 2 last past frames, the 2 first generated frames, ``middle``
    frames spread inside, the 2 last generated frames and the 2 first target frames (those that exist).

    Parameters
    ----------
    start, stop : int
        The generated frames are ``[start, stop)``; ``0 <= start < stop <= num_total``.
    num_total : int
    middle : int

    Returns
    -------
    list of int, sorted, unique
    """
    if not 0 <= start < stop <= num_total:
        raise ValueError(f"start, stop: expected 0 <= start < stop <= {num_total}, got {start}, {stop}")
    inner = np.linspace(start, stop - 1, middle + 2)[1:-1].round().astype(int).tolist() if middle > 0 else []
    cand = [start - 2, start - 1, start, start + 1, *inner, stop - 2, stop - 1, stop, stop + 1]
    return sorted({int(f) for f in cand if 0 <= f < num_total})


def limb_sides(skeleton) -> np.ndarray:
    """``(J,)`` −1 for the skeleton's left joints, +1 for its right joints, 0 for the others: the ONE rule of
    every model's pictures (QuaterNet, acRNN, QTG, the walker).

    A joint's side is the side its name says — a prefix ``Left`` / ``Right`` (any case) or a single ``L`` / ``l``
    / ``R`` / ``r`` before an upper-case letter, a digit or ``_`` (``LeftFoot``, ``LHipJoint``, ``lShldr``,
    ``RThumb``; not ``LowerBack``), or a suffix ``_L`` / ``.l`` / ``_R`` / ``.r`` (``Foot_L``, ``hand.l``: the
    Bandai-Namco and Blender conventions) — else its parent's side (an End Site or a finger without a side in its
    name is on its hand's side). Names say nothing first, then the mirror map: a skeleton whose names carry no
    side at all is read from ``joints_left`` / ``joints_right``. (Names come first because a mirror map may be
    swapped against anatomy: QuaterNet's own lists are, spec/kinematics.md.)
    """
    names, parents = list(skeleton.names), np.asarray(skeleton.parents)
    sides = np.zeros(len(names), dtype=np.int64)
    said = False
    for j, name in enumerate(names):  # parents come before their children
        side = _name_side(name)
        said |= side != 0
        sides[j] = side if side != 0 or parents[j] < 0 else sides[parents[j]]
    if said:
        return sides
    sides[:] = 0
    sides[list(skeleton.joints_left)] = -1
    sides[list(skeleton.joints_right)] = 1
    return sides


def _name_side(name: str) -> int:
    """−1 / +1 / 0: the side a joint name says by its prefix or suffix (see :func:`limb_sides`)."""
    low = name.lower()
    for side, sign in (("left", -1), ("right", 1)):
        if low.startswith(side) and len(name) > len(side):
            return sign
    if len(name) > 1 and name[0] in "lLrR" and (name[1].isupper() or name[1].isdigit() or name[1] == "_"):
        return -1 if name[0] in "lL" else 1
    tail = low[-2:]
    return -1 if tail in ("_l", ".l") else 1 if tail in ("_r", ".r") else 0


def render_strip(path: str | os.PathLike, positions, parents, *, prediction=None, frames=None,
                 num_frames: int = 8, highlight: tuple[int, int] | None = None,
                 labels: tuple[str, str] = ("ground truth", "prediction"), title: str | None = None,
                 up: str = "y", frame_time: float | None = None, frame_numbers=None,
                 panel_size: float = 1.8, dpi: float = 100, sides=None, feet=None,
                 contact_height: float = 2.0) -> Path:
    """Draw several frames of a motion side by side and save them as a PNG strip.

    One row shows ``positions`` (ground truth, blue); with ``prediction`` a second row shows the prediction
    (red) over a light-grey ghost of the ground truth, frame for frame in the same camera box, so that the
    difference is visible. Each panel is centred on the ground-truth root's horizontal position of that frame;
    all panels share one scale and one floor, both of the WHOLE clip (equal aspect, orthographic camera, a
    floor square at the ground truth's lowest joint height over all ``T`` frames, its grid lines fixed in the
    world so that travel and sliding show). The title is wrapped and shrunk to fit. With ``highlight`` each panel is labelled with
    its place in the transition: ``past``, ``first generated``, ``last generated``, ``target`` (the frames on both
    sides of each join, :func:`join_frames`), ``context``, or none inside the transition.

    Parameters
    ----------
    path : str or PathLike
        Output ``.png`` file (written atomically; folders are created).
    positions : array_like, shape (T, J, 3)
        Ground-truth world positions, components (x, y, z) in the file's units.
    parents : array_like of int, shape (J,)
        Parent index of each joint, ``-1`` for the root.
    prediction : array_like, shape (T, J, 3), optional
        Predicted positions on the same skeleton and frames.
    frames : sequence of int, optional
        Frame indices to draw. Default: ``num_frames`` evenly spaced frames from first to last.
    num_frames : int
        Number of frames when ``frames`` is not given.
    highlight : (int, int), optional
        ``[start, stop)`` of the frames of interest (the generated transition); the other frames are context
        and are drawn in green.
    labels : (str, str)
        Row labels for ground truth and prediction.
    title : str, optional
        Figure title (every command's strip has one).
    up : {"y", "z"}
        The data's up axis.
    frame_time : float, optional
        Seconds per frame (of the numbering in ``frame_numbers``); when given, panels are labelled with times
        ``number · frame_time`` as well as frame numbers.
    frame_numbers : sequence of int, shape (T,), optional
        The number each of the T frames has in its source (e.g. the file's frame numbers of a selected range);
        default ``0 … T − 1``. Only the labels use it.
    panel_size : float
        Size of one panel in inches.
    dpi : float
        Resolution of the PNG.
    sides : array_like of int, shape (J,), optional
        −1 left, +1 right, 0 centre joint (:func:`limb_sides`): left limbs darker, right limbs lighter.
    feet : sequence of int, optional
        Foot joints whose floor track over the last :data:`FOOT_TRACK` frames is drawn in each panel while they
        are in contact (within ``contact_height`` of their lowest ground-truth height, the rule of
        :mod:`refimpl.protocols.transition_quality`): a planted foot leaves a dot, a skating foot a streak.
    contact_height : float
        In the positions' unit (2.0: centimetres).

    Returns
    -------
    Path
        The written file.
    """
    par = check_parents(parents)
    gt = check_positions(positions, "positions", par)  # (T, J, 3)
    pred = None if prediction is None else check_positions(prediction, "prediction", par)
    if pred is not None and pred.shape != gt.shape:
        raise ValueError(f"prediction must have the shape of positions {gt.shape}, got {pred.shape}")
    up = check_up(up)
    sides = check_sides(sides, len(par))
    feet = [] if feet is None else [int(j) for j in feet]
    if any(not 0 <= j < len(par) for j in feet):
        raise ValueError(f"feet must be joint indices in [0, {len(par)}), got {feet}")
    idx = pick_frames(gt.shape[0], frames, num_frames)  # (N,)
    start, stop = check_highlight(highlight, gt.shape[0])
    numbers = check_numbers(frame_numbers, gt.shape[0])

    gt_p = to_plot(gt, up)  # (T, J, 3)
    pred_p = None if pred is None else to_plot(pred, up)
    half = half_extent([gt_p] + ([] if pred_p is None else [pred_p]))  # one box for the whole clip
    floor = clip_floor(gt_p)  # one floor height for the whole clip: the ground truth's lowest joint
    foot_floor = gt_p[:, feet, 2].min(axis=0)  # (K,) each foot's lowest ground-truth height
    low = {id(x): x[:, feet, 2] - foot_floor < contact_height for x in (gt_p, pred_p) if x is not None}  # (T, K)

    rows = 1 if pred is None else 2
    width = panel_size * len(idx) + 0.3
    text = wrap_title(title, width, _TITLE_SIZE)
    head, foot = title_height(text, _TITLE_SIZE) + 0.45, 0.2  # title, panel labels; the sides note
    height = panel_size * rows + head + foot
    fig = figure(width, height, dpi)
    scene = {"gt": gt_p, "pred": pred_p, "par": par, "sides": sides, "feet": feet, "low": low, "half": half,
             "floor": floor, "rows": rows, "cols": len(idx)}
    for col, t in enumerate(idx):
        role = _role(t, start, stop) if highlight is not None else ""
        label = f"frame {numbers[t]}" + (f"\n{numbers[t] * frame_time:.2f} s" if frame_time else "")
        _strip_column(fig, scene, col, t, not (start <= t < stop), label + (f" ({role})" if role else ""),
                      role in ("first generated", "last generated"))
    y_rows = 1.0 - (head + 0.5 * panel_size * np.arange(1, 2 * rows, 2)) / height  # the rows' middles
    fig.text(0.005, y_rows[0], labels[0], rotation=90, va="center", color=GT_COLOR, fontsize=8)
    if pred_p is not None:
        fig.text(0.005, y_rows[1], labels[1], rotation=90, va="center", color=PRED_COLOR, fontsize=8)
    if sides is not None:
        fig.text(0.995, 0.04 / height, SIDES_NOTE, ha="right", va="bottom", fontsize=6, color="0.3")
    if text:
        fit_text(fig, fig.text(0.5, 1.0 - 0.05 / height, text, ha="center", va="top", fontsize=_TITLE_SIZE))
    fig.subplots_adjust(left=0.02, right=0.995, bottom=foot / height, top=1.0 - head / height, wspace=0.0,
                        hspace=0.08)
    return save_figure(fig, path)


def _strip_column(fig, scene: dict, col: int, t: int, context: bool, label: str, bold: bool) -> None:
    """The panels of frame ``t``: the ground truth (and below it the prediction over its ghost), centred on
    the ground-truth root, over the clip's floor."""
    gt_p, pred_p, par, sides, half, floor = (scene[k] for k in ("gt", "pred", "par", "sides", "half", "floor"))
    centre, mid = gt_p[t, 0, :2], floor + half * 0.9
    ax = fig.add_subplot(scene["rows"], scene["cols"], col + 1, projection="3d")
    centre_axes(ax, setup_axes(ax, half, floor), centre, half, floor, mid)
    color = CONTEXT_COLOR if context else GT_COLOR
    _draw_feet(ax, gt_p, t, scene["feet"], scene["low"][id(gt_p)], floor, color, sides)
    _draw_pose(ax, gt_p[t], par, color, 1.6, sides)
    ax.set_title(label, fontsize=7, fontweight="bold" if bold else "normal")
    if pred_p is not None:
        ax2 = fig.add_subplot(scene["rows"], scene["cols"], scene["cols"] + col + 1, projection="3d")
        centre_axes(ax2, setup_axes(ax2, half, floor), centre, half, floor, mid)
        _draw_pose(ax2, gt_p[t], par, GHOST_COLOR, 1.2)
        color = CONTEXT_COLOR if context else PRED_COLOR
        _draw_feet(ax2, pred_p, t, scene["feet"], scene["low"][id(pred_p)], floor, color, sides)
        _draw_pose(ax2, pred_p[t], par, color, 1.6, sides)


def _role(t: int, start: int, stop: int) -> str:
    """A frame's place around the joins of the transition ``[start, stop)``."""
    if t in (start - 2, start - 1):
        return "past"
    if t in (stop, stop + 1):
        return "target"
    if t == start:
        return "first generated"
    if t == stop - 1:
        return "last generated"
    return "" if start <= t < stop else "context"


def _draw_pose(ax, pose: np.ndarray, parents: np.ndarray, color: str, width: float, sides=None) -> None:
    """Draw one pose ``(J, 3)`` (plot coordinates) as bone segments plus joint dots, both in the left / right
    shades (a joint's dot is where its bone ends: every joint drawn is a bone's end or the root)."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    ax.add_collection3d(Line3DCollection(bone_segments(pose, parents), colors=bone_colors(color, parents, sides),
                                         linewidths=width))
    ax.scatter(pose[:, 0], pose[:, 1], pose[:, 2], s=1.5, c=joint_colors(color, len(pose), sides),
               depthshade=False)


def _draw_feet(ax, positions: np.ndarray, t: int, feet, low, floor: float, color, sides) -> None:
    """The floor track of each foot joint that is in contact AT frame ``t``: its floor positions over the
    contact frames that end at ``t`` (at most FOOT_TRACK steps back; plot coordinates; ``low (T, K)``: the foot
    is in contact). A planted foot is a dot under the foot, a skating foot a streak ending under it; a foot off
    the floor at ``t`` has no track (no dot left behind where it was planted)."""
    a = max(0, t - FOOT_TRACK)
    for k, j in enumerate(feet):
        on = low[a:t + 1, k]
        if not on[-1]:
            continue
        first = len(on) - int(np.argmin(on[::-1])) if not on.all() else 0  # the contact run ending at t
        c = joint_colors(color, 1, None if sides is None else sides[j:j + 1])[0]  # j's shade
        tr = positions[a + first:t + 1, j]  # (K, 3)
        if len(tr) > 1:
            ax.plot(tr[:, 0], tr[:, 1], np.full(len(tr), floor), color=c, lw=1.6, alpha=0.9)
        ax.scatter(tr[-1:, 0], tr[-1:, 1], [floor], s=5, color=c, depthshade=False)
