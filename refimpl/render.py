"""Pictures of skeletal motion: animated GIFs, a character walking a path, loss curves and per-frame error
curves (frame strips: ``refimpl/render_strip.py``; the drawing helpers all of them share:
``refimpl/render_kernel.py``).

matplotlib is an optional dependency (the ``render`` extra, ``pip install 'refimpl[render]'``; the GIF frames are
written with Pillow, which matplotlib depends on). It is imported lazily, inside the functions, so that
``import refimpl.render`` always works; a missing matplotlib raises ``ImportError`` with the install hint.
Figures are built with the object-oriented API on the Agg canvas (``matplotlib.figure.Figure`` +
``FigureCanvasAgg``): nothing here touches ``pyplot`` or changes the global backend, so rendering is headless and
safe inside a notebook or a test run.

Conventions
-----------
* Positions are world coordinates ``(T, J, 3)`` in the file's units (e.g. ``Motion.positions()``), with the
  parent index array ``parents`` ``(J,)`` of the skeleton (``-1`` for the root). A bone is drawn from each joint
  to its parent.
* ``up="y"`` (default, BVH convention) means the data is Y-up; ``up="z"`` means Z-up. The picture always shows
  the up axis vertical, with an equal aspect ratio on all three axes and an orthographic camera.
* Ground truth is drawn in blue, the prediction in red; frames outside ``highlight`` (the context frames of a
  transition) are drawn in green, as in the QTG paper's Figure 1. With ``sides`` left limbs are drawn in a
  darker and right limbs in a lighter shade of that colour (the same rule for every model).
* The floor is FIXED for the whole clip: one height (the ground truth's lowest joint over all its frames), one
  square of one size around the character, its grid lines fixed in the world, so that travel, sliding feet and a
  foot off the floor are visible.
* Every picture has a title when one is given, wrapped and shrunk to fit the picture (never clipped).
* Every file is written atomically (temporary file in the same folder, fsync, ``os.replace``).

Shape legend: T frames, J joints, N drawn frames, M path points.
"""
from __future__ import annotations

import csv
import io
import os
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from refimpl.files import read_text
from refimpl.progress import Throttle
from refimpl.render_kernel import (CONTEXT_COLOR, GHOST_COLOR, GT_COLOR, PRED_COLOR, SIDES_NOTE, bone_colors,
                                   bone_segments, centre_axes, check_highlight, check_numbers, check_parents,
                                   check_positions, check_sides, check_up, clip_floor, clip_segments, figure,
                                   fit_text, gif_writer, half_extent, save_figure,
                                   setup_axes, title_height, to_plot, wrap_title)

__all__ = ["render_gif", "render_loss_curve", "render_error_curves", "read_loss_log",
           "render_path_motion", "GIF_MIN_HEIGHT"]

#: Height in pixels a GIF has at least (its default panel size and resolution): a foot contact can be judged.
GIF_MIN_HEIGHT = 400
#: Seconds of drawing between two progress lines.
_TITLE_SIZE = 10.0

# ----------------------------------------------------------------------------------------------------------
# public pictures (the frame strip is in refimpl/render_strip.py)


def _finish_plot(fig, ax, title, path) -> Path:
    """Grid, legend and title of a line plot, then save it as PNG (atomically)."""
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path)


def render_gif(path: str | os.PathLike, positions, parents, *, prediction=None, fps: float = 30.0,
               stride: int = 1, highlight: tuple[int, int] | None = None,
               labels: tuple[str, str] = ("ground truth", "prediction"), title: str | None = None,
               up: str = "y", frame_numbers=None, panel_size: float = 4.4, dpi: float = 100, sides=None,
               progress=None) -> Path:
    """Animate a motion (and, side by side, a prediction) and save it as a GIF.

    The camera follows the ground-truth root horizontally, with one fixed scale (equal aspect, orthographic) and
    one fixed floor (height and square, :func:`refimpl.render_kernel.clip_floor`) for the whole clip. With
    ``prediction`` the left panel shows the ground truth (blue) and the right panel the prediction (red) over a
    grey ghost of the ground truth; frames outside ``highlight`` are drawn in green. The GIF is at least
    :data:`GIF_MIN_HEIGHT` pixels tall (the resolution is raised for a small ``panel_size``) and its title is
    wrapped and shrunk to fit.

    Parameters
    ----------
    path : str or PathLike
        Output ``.gif`` file (written atomically).
    positions : array_like, shape (T, J, 3)
        Ground-truth world positions (x, y, z).
    parents : array_like of int, shape (J,)
        Parent index of each joint, ``-1`` for the root.
    prediction : array_like, shape (T, J, 3), optional
        Predicted positions on the same frames.
    fps : float
        Playback rate of the GIF, before ``stride`` (a stride of 2 halves the GIF's frame rate so that the
        motion keeps its real speed).
    stride : int
        Draw every ``stride``-th frame.
    highlight, labels, title, up, frame_numbers, panel_size, dpi, sides
        As in :func:`refimpl.render_strip.render_strip` (``panel_size`` in inches, ``dpi`` pixels per inch).
    progress : callable, optional
        ``progress(line)`` every ~5 s of drawing (``"walk.gif: frame 120 of 300, 11 s"``; the commands pass
        :func:`refimpl.progress.stderr_line`).

    Returns
    -------
    Path
        The written file.
    """
    par = check_parents(parents)
    gt = check_positions(positions, "positions", par)
    pred = None if prediction is None else check_positions(prediction, "prediction", par)
    if pred is not None and pred.shape != gt.shape:
        raise ValueError(f"prediction must have the shape of positions {gt.shape}, got {pred.shape}")
    sides = check_sides(sides, len(par))
    if int(stride) < 1:
        raise ValueError(f"stride must be >= 1, got {stride}")
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps}")
    up = check_up(up)
    start, stop = check_highlight(highlight, gt.shape[0])
    numbers = check_numbers(frame_numbers, gt.shape[0])
    idx = np.arange(0, gt.shape[0], int(stride))  # (N,)
    gt_p = to_plot(gt, up)
    pred_p = None if pred is None else to_plot(pred, up)
    half = half_extent([gt_p] + ([] if pred_p is None else [pred_p]))
    floor = clip_floor(gt_p)  # one floor for the whole clip
    cols = 1 if pred is None else 2
    fig, box = _gif_figure(cols, panel_size, dpi, title)
    sources = [(gt_p, GT_COLOR, [])] + ([] if pred_p is None else [(pred_p, PRED_COLOR, [gt_p])])
    panels = [_gif_panel(fig, box, cols, c, s, labels[c], half, floor, par, sides) for c, s in enumerate(sources)]
    caption = fig.text(0.02, 0.5 * box["bottom"], "", va="center", fontsize=8)
    if sides is not None:
        fig.text(0.98, 0.5 * box["bottom"], SIDES_NOTE, ha="right", va="center", fontsize=7, color="0.3")

    def update(k: int) -> None:
        t = idx[k]
        context = highlight is not None and not (start <= t < stop)
        for ax, floor_artists, layers in panels:
            centre_axes(ax, floor_artists, gt_p[t, 0, :2], half, floor, floor + half * 0.9)
            for coll, src, color in layers:
                coll.set_segments(bone_segments(src[t], par))
                if color is not None:
                    coll.set_color(bone_colors(CONTEXT_COLOR if context else color, par, sides))
        caption.set_text(f"frame {numbers[t]}" + (" (context)" if context else ""))

    return _write_gif(path, fig, len(idx), update, max(1.0, fps / int(stride)), progress)


def _gif_figure(cols: int, panel_size: float, dpi: float, title: str | None):
    """A GIF's figure: ``cols`` square panels under the (wrapped, fitted) title and a row of labels, over a
    caption row; ``(fig, {"top", "bottom", "label"})`` as figure fractions. At least GIF_MIN_HEIGHT pixels."""
    text = wrap_title(title, panel_size * cols, _TITLE_SIZE)
    head = title_height(text, _TITLE_SIZE) + 0.3  # the title, then the panels' labels
    foot = 0.3                                     # the caption (frame number)
    height = panel_size + head + foot
    fig = figure(panel_size * cols, height, max(float(dpi), GIF_MIN_HEIGHT / height))
    if text:
        fit_text(fig, fig.text(0.5, 1.0 - 0.05 / height, text, ha="center", va="top", fontsize=_TITLE_SIZE))
    box = {"top": 1.0 - head / height, "bottom": foot / height, "label": 1.0 - (head - 0.28) / height}
    fig.subplots_adjust(left=0.0, right=1.0, bottom=box["bottom"], top=box["top"], wspace=0.0)
    return fig, box


def _gif_panel(fig, box, cols: int, c: int, source, label: str, half: float, floor: float, par, sides):
    """One GIF panel: 3-D axes with the floor, its label, a ghost per ``ghosts`` and the pose's bones."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    src, color, ghosts = source
    ax = fig.add_subplot(1, cols, c + 1, projection="3d")
    floor_artists = setup_axes(ax, half, floor)
    fig.text((c + 0.5) / cols, box["label"], label, ha="center", va="top", fontsize=9, color=color)
    layers = []
    for g in ghosts:
        coll = Line3DCollection(bone_segments(g[0], par), colors=GHOST_COLOR, linewidths=1.4)
        ax.add_collection3d(coll)
        layers.append((coll, g, None))
    coll = Line3DCollection(bone_segments(src[0], par), colors=bone_colors(color, par, sides), linewidths=2.2)
    ax.add_collection3d(coll)
    layers.append((coll, src, color))
    return ax, floor_artists, layers


def _write_gif(path, fig, num_frames: int, update, fps: float, progress) -> Path:
    """Draw ``num_frames`` frames (``update(k)`` moves the artists of frame ``k``) into a GIF, each streamed to
    the file as it is drawn; ``progress(line)`` every ~5 s (:class:`refimpl.progress.Throttle`)."""
    path = Path(path)
    tick = Throttle()
    with gif_writer(path, fps) as add:
        for k in range(num_frames):
            if progress is not None and tick.due():
                progress(f"{path.name}: frame {k} of {num_frames}, {tick.elapsed:.0f} s")
            update(k)
            add(fig)
    return path


def read_loss_log(csv_path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a training log CSV (header row, numeric columns) into ``{column: (N,) float64}``.

    Non-numeric or empty cells become NaN, so a column that is only written every few steps (e.g. a
    validation loss) still lines up with the step column.
    """
    path = Path(csv_path)
    with io.StringIO(read_text(path, encoding="utf-8"), newline="") as f:  # a regular file, read to its size
        reader = csv.reader(f)
        try:
            header = next(reader)
        except StopIteration:
            raise ValueError(f"loss log {path} is empty (expected a header row)") from None
        rows = [r for r in reader if r]
    cols: dict[str, np.ndarray] = {}
    for j, name in enumerate(header):
        vals = []
        for r in rows:
            try:
                vals.append(float(r[j]) if j < len(r) and r[j] != "" else np.nan)
            except ValueError:
                vals.append(np.nan)
        cols[name.strip()] = np.asarray(vals, dtype=np.float64)
    return cols


def render_loss_curve(path: str | os.PathLike, log, *, x: str | None = None,
                      columns: Sequence[str] | None = None, logy: bool = True,
                      title: str | None = "training loss", dpi: float = 100) -> Path:
    """Plot loss curves from a training log and save them as PNG.

    Parameters
    ----------
    path : str or PathLike
        Output ``.png`` file.
    log : str, PathLike or mapping
        The training CSV log (see :func:`read_loss_log`) or an already read ``{column: (N,) array}``.
    x : str, optional
        Column for the horizontal axis. Default: the first of ``step``, ``iteration``, ``epoch`` present,
        else the row number.
    columns : sequence of str, optional
        Columns to plot. Default: every column whose name contains ``loss``.
    logy : bool
        Logarithmic vertical axis (used only when every plotted value is positive).
    title : str, optional
    dpi : float

    Returns
    -------
    Path
    """
    data = read_loss_log(log) if isinstance(log, (str, os.PathLike)) else {k: np.asarray(v, dtype=np.float64)
                                                                         for k, v in log.items()}
    if x is None:
        x = next((c for c in ("step", "iteration", "epoch") if c in data), None)
    if x is not None and x not in data:
        raise ValueError(f"x column {x!r} not in the log, which has {sorted(data)}")
    if columns is None:
        columns = [c for c in data if "loss" in c.lower() and c != x]
    columns = list(columns)
    missing = [c for c in columns if c not in data]
    if not columns or missing:
        raise ValueError(f"no loss columns to plot (asked {columns}, missing {missing}); log has {sorted(data)}")
    n = len(data[columns[0]])
    xs = np.arange(n, dtype=np.float64) if x is None else data[x]

    fig = figure(6.0, 3.6, dpi)
    ax = fig.add_subplot(1, 1, 1)
    positive = True
    for c in columns:
        ys = data[c]
        ok = np.isfinite(ys) & np.isfinite(xs)
        if not np.any(ok):
            continue
        positive &= bool(np.all(ys[ok] > 0))
        line, = ax.plot(xs[ok], ys[ok], lw=0.8, alpha=0.45 if ok.sum() > 50 else 1.0, label=c)
        if ok.sum() > 50:  # a moving average over ~2% of the run on top of the raw values
            w = max(3, int(ok.sum()) // 50)
            smooth = np.convolve(ys[ok], np.ones(w) / w, mode="valid")
            ax.plot(xs[ok][w - 1:], smooth, lw=1.6, color=line.get_color(), label=f"{c} (mean of {w})")
    if logy and positive:
        ax.set_yscale("log")
    ax.set_xlabel(x or "log row")
    ax.set_ylabel("loss")
    return _finish_plot(fig, ax, title, path)


def render_error_curves(path: str | os.PathLike, curves: Mapping[str, np.ndarray], *,
                        frame_time: float | None = None, ylabel: str = "mean joint-position error (cm)",
                        title: str | None = "error per transition frame", dpi: float = 100) -> Path:
    """Plot one per-frame error curve per method (as the QTG paper's Figure 3) and save it as PNG.

    Parameters
    ----------
    path : str or PathLike
        Output ``.png`` file.
    curves : mapping str -> array_like, shape (T,)
        Error of each method at transition frame ``1 … T`` (e.g. MAE per joint in cm).
    frame_time : float, optional
        Seconds per frame; when given the horizontal axis is time in ms, else the frame number.
    ylabel, title : str
    dpi : float

    Returns
    -------
    Path
    """
    if not curves:
        raise ValueError("curves must hold at least one method")
    fig = figure(6.0, 3.6, dpi)
    ax = fig.add_subplot(1, 1, 1)
    for name, ys in curves.items():
        ys = np.asarray(ys, dtype=np.float64)
        if ys.ndim != 1 or ys.size == 0:
            raise ValueError(f"curves[{name!r}] must have shape (T,) with T >= 1, got {ys.shape}")
        frames = np.arange(1, ys.size + 1, dtype=np.float64)
        xs = frames * frame_time * 1000.0 if frame_time else frames
        ax.plot(xs, ys, marker="o", ms=2.5, lw=1.4, label=f"{name} (mean {np.nanmean(ys):.2f})")
    ax.set_xlabel("time into the transition (ms)" if frame_time else "transition frame")
    ax.set_ylabel(ylabel)
    ax.set_ylim(bottom=0.0)
    return _finish_plot(fig, ax, title, path)


# ----------------------------------------------------------------------------------------------------------
# a character walking a path (locomotion generation)


def render_path_motion(path: str | os.PathLike, positions, parents, path_points, *, closed: bool = False,
                       fps: float = 30.0, stride: int = 2, num_frames: int = 8, title: str | None = None,
                       panel_size: float = 4.4, dpi: float = 100, sides=None, progress=None) -> Path:
    """Draw a character following a ground path: a ``.png`` (left: the poses at ``num_frames`` evenly spaced
    frames in 3-D over the floor, the path ON the floor; right: the map — path in grey, root track in red, start
    marked) or an animated ``.gif`` (left: the character followed by the camera over a fixed floor square, the
    part of the path inside that square drawn on it; right: the map with the root track up to the frame shown
    and the current position).

    The floor is the clip's lowest joint height (all frames, the up axis Y of the positions), the same in every
    frame; the path lies at that height.

    Parameters
    ----------
    path : str or PathLike
        ``.png`` or ``.gif`` (written atomically).
    positions : array_like (T, J, 3)
        World positions, Y up.
    parents : array_like (J,)
    path_points : array_like (M, 2)
        The path's ``(x, z)`` points in the positions' units.
    closed : bool
        Draw the closing segment.
    fps, stride : GIF playback rate and frame step.
    num_frames : poses of the PNG.
    title, panel_size, dpi, sides : as in :func:`render_gif`.
    progress : callable, optional
        As in :func:`render_gif` (GIF only).
    """
    par = check_parents(parents)
    pos = check_positions(positions, "positions", par)
    pts = np.asarray(path_points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise ValueError(f"path_points: expected shape (M >= 2, 2), got {pts.shape}")
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".gif"):
        raise ValueError(f"path: expected a .png or .gif file name, got {path}")
    sides = check_sides(sides, len(par))
    if closed:
        pts = np.concatenate([pts, pts[:1]])
    walk = {"pos": pos, "pp": to_plot(pos, "y"), "par": par, "sides": sides,
            "path_xy": np.stack([pts[:, 0], -pts[:, 1]], axis=-1), "pts": pts}  # the path in plot (x, y)
    walk["floor"] = clip_floor(walk["pp"])
    fig, box = _gif_figure(2, panel_size, dpi, title)
    ax2 = fig.add_axes((0.58, box["bottom"] + 0.08, 0.39, box["top"] - box["bottom"] - 0.1))
    _draw_map(ax2, pts, pos)
    if suffix == ".png":
        return _path_png(path, fig, walk, num_frames, ax2)
    return _path_gif(path, fig, box, walk, ax2, fps, stride, progress)


def _draw_map(ax2, pts: np.ndarray, pos: np.ndarray) -> None:
    """The map seen from above (x right, z down, as the 3-D view's floor): path, start."""
    ax2.plot(pts[:, 0], pts[:, 1], color="0.6", lw=1.5, label="path")
    ax2.plot(pos[0, 0, 0], pos[0, 0, 2], "o", color=CONTEXT_COLOR, ms=4, label="start")
    ax2.set_aspect("equal", adjustable="datalim")
    ax2.invert_yaxis()
    ax2.set_xlabel("x", fontsize=8)
    ax2.set_ylabel("z", fontsize=8)
    ax2.tick_params(labelsize=7)


def _path_png(path, fig, walk: dict, num_frames: int, ax2) -> Path:
    """The PNG: poses at evenly spaced frames over one floor that holds the whole path, the full root track."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    pp, par, floor, pos = walk["pp"], walk["par"], walk["floor"], walk["pos"]
    ax = fig.add_axes((0.0, 0.0, 0.55, fig.subplotpars.top), projection="3d")
    flat = np.concatenate([walk["path_xy"], pp[..., :2].reshape(-1, 2)])  # (M + T·J, 2)
    centre = 0.5 * (flat.min(0) + flat.max(0))
    half = 0.55 * float(np.max(flat.max(0) - flat.min(0)))
    floor_artists = setup_axes(ax, half, floor, elev=25.0, zoom=1.0)
    centre_axes(ax, floor_artists, centre, half, floor, floor + half * 0.5)
    ax.add_collection3d(Line3DCollection(_floor_path(walk, centre, half), colors="0.45", linewidths=1.4))
    for t in np.linspace(0, len(pp) - 1, max(1, int(num_frames))).round().astype(int):
        ax.add_collection3d(Line3DCollection(bone_segments(pp[t], par), linewidths=1.2,
                                             colors=bone_colors(PRED_COLOR, par, walk["sides"])))
        ax2.plot(pos[t, 0, 0], pos[t, 0, 2], ".", color="k", ms=3)
    ax2.plot(pos[:, 0, 0], pos[:, 0, 2], color=PRED_COLOR, lw=1.0, label="root")
    ax2.legend(fontsize=7, loc="lower right")
    return save_figure(fig, path)


def _floor_path(walk: dict, centre: np.ndarray, half: float) -> np.ndarray:
    """The path's segments inside the floor square around ``centre``, ON the floor: ``(K, 2, 3)``."""
    seg = clip_segments(walk["path_xy"], centre - half, centre + half)  # (K, 2, 2)
    return np.concatenate([seg, np.full(seg.shape[:2] + (1,), walk["floor"])], axis=-1)


def _path_gif(path, fig, box, walk: dict, ax2, fps: float, stride: int, progress) -> Path:
    """The GIF: the character over a floor square that follows it, the map with the root track so far."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    pp, par, floor, pos, sides = walk["pp"], walk["par"], walk["floor"], walk["pos"], walk["sides"]
    ax = fig.add_axes((0.0, box["bottom"], 0.5, box["top"] - box["bottom"]), projection="3d")
    half = half_extent([pp])
    floor_artists = setup_axes(ax, half, floor)
    road = Line3DCollection(_floor_path(walk, pp[0, 0, :2], half), colors="0.45", linewidths=2.0)
    ax.add_collection3d(road)
    bones = Line3DCollection(bone_segments(pp[0], par), colors=bone_colors(PRED_COLOR, par, sides), linewidths=2.2)
    ax.add_collection3d(bones)
    (trace,) = ax2.plot(pos[:1, 0, 0], pos[:1, 0, 2], color=PRED_COLOR, lw=1.0, label="root so far")
    (dot,) = ax2.plot(pos[:1, 0, 0], pos[:1, 0, 2], "o", color=PRED_COLOR, ms=5)
    ax2.legend(fontsize=7, loc="upper right")
    caption = fig.text(0.02, 0.5 * box["bottom"], "", va="center", fontsize=8)
    if sides is not None:
        fig.text(0.98, 0.5 * box["bottom"], SIDES_NOTE, ha="right", va="center", fontsize=7, color="0.3")
    idx = np.arange(0, pp.shape[0], max(1, int(stride)))

    def update(k: int) -> None:
        t = idx[k]
        centre_axes(ax, floor_artists, pp[t, 0, :2], half, floor, floor + half * 0.9)
        road.set_segments(_floor_path(walk, pp[t, 0, :2], half))
        bones.set_segments(bone_segments(pp[t], par))
        trace.set_data(pos[:t + 1, 0, 0], pos[:t + 1, 0, 2])
        dot.set_data([pos[t, 0, 0]], [pos[t, 0, 2]])
        caption.set_text(f"frame {t} ({t / fps:.1f} s)")

    return _write_gif(path, fig, len(idx), update, max(1.0, fps / max(1, int(stride))), progress)
