"""Pictures of skeletal motion: animated GIFs, loss curves and per-frame error curves (frame strips:
``refimpl/render_strip.py``), and the drawing helpers both modules share (kernel tier, at the end).

matplotlib is an optional dependency (the ``render`` extra, ``pip install 'refimpl[render]'``). It is imported
lazily, inside the functions, so that ``import refimpl.render`` always works; a missing matplotlib raises
``ImportError`` with the install hint. Figures are built with the object-oriented API on the Agg canvas
(``matplotlib.figure.Figure`` + ``FigureCanvasAgg``): nothing here touches ``pyplot`` or changes the global
backend, so rendering is headless and safe inside a notebook or a test run.

Conventions
-----------
* Positions are world coordinates ``(T, J, 3)`` in the file's units (e.g. ``Motion.positions()``), with the
  parent index array ``parents`` ``(J,)`` of the skeleton (``-1`` for the root). A bone is drawn from each joint
  to its parent.
* ``up="y"`` (default, BVH convention) means the data is Y-up; ``up="z"`` means Z-up. The picture always shows
  the up axis vertical, with an equal aspect ratio on all three axes and an orthographic camera.
* Ground truth is drawn in blue, the prediction in red; frames outside ``highlight`` (the context frames of a
  transition) are drawn in green, as in the QTG paper's Figure 1. With ``sides`` left limbs are drawn in a
  darker and right limbs in a lighter shade of that colour.
* The floor grid is fixed in the world (:func:`grid_segments`), so that travel and sliding feet are visible.
* Every file is written atomically (temporary file in the same folder, fsync, ``os.replace``).

Shape legend: T frames, J joints, N drawn frames.
"""
from __future__ import annotations

import csv
import io
import os
import sys
import time
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from refimpl.atomic import atomic_path
from refimpl.files import read_text

__all__ = ["render_gif", "stderr_progress", "render_loss_curve", "render_error_curves", "read_loss_log",
           "render_path_motion"]

GT_COLOR = "tab:blue"
PRED_COLOR = "tab:red"
CONTEXT_COLOR = "tab:green"
GHOST_COLOR = "0.75"
_INSTALL_HINT = "rendering needs matplotlib: pip install 'refimpl[render]' (or pip install matplotlib)"


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
               up: str = "y", frame_numbers=None, panel_size: float = 2.6, dpi: float = 80, sides=None,
               progress=None) -> Path:
    """Animate a motion (and, side by side, a prediction) and save it as a GIF with Pillow.

    The camera follows the ground-truth root horizontally, with one fixed scale (equal aspect, orthographic).
    With ``prediction`` the left panel shows the ground truth (blue) and the right panel the prediction (red)
    over a grey ghost of the ground truth; frames outside ``highlight`` are drawn in green.

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
        As in :func:`refimpl.render_strip.render_strip`.
    progress : callable, optional
        ``progress(line)`` every ~5 s of drawing (``"walk.gif: frame 120 of 300, 11 s"``; the commands pass
        :func:`stderr_progress`: a long GIF takes a minute).

    Returns
    -------
    Path
        The written file.
    """
    try:
        from matplotlib.animation import PillowWriter
    except ImportError as exc:  # pragma: no cover
        raise ImportError(_INSTALL_HINT) from exc
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

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
    drawn = [gt_p] + ([] if pred_p is None else [pred_p])
    half = half_extent(drawn)
    floor = min(float(q[..., 2].min()) for q in drawn)
    mid = floor + half * 0.9

    cols = 1 if pred is None else 2
    fig = figure(panel_size * cols, panel_size + 0.3, dpi)
    panels = []  # (axes, floor grid, [(collection, source positions, main colour or None for a ghost)])
    sources = [(gt_p, GT_COLOR, [])] if pred_p is None else [(gt_p, GT_COLOR, []), (pred_p, PRED_COLOR, [gt_p])]
    for c, (src, color, ghosts) in enumerate(sources):
        ax = fig.add_subplot(1, cols, c + 1, projection="3d")
        grid = setup_axes(ax, half, floor)
        fig.text((c + 0.5) / cols, 0.93 if title else 0.97, labels[c], ha="center", va="top", fontsize=8,
                 color=color)
        layers = []
        for g in ghosts:
            coll = Line3DCollection(bone_segments(g[0], par), colors=GHOST_COLOR, linewidths=1.2)
            ax.add_collection3d(coll)
            layers.append((coll, g, None))
        coll = Line3DCollection(bone_segments(src[0], par), colors=bone_colors(color, par, sides), linewidths=1.8)
        ax.add_collection3d(coll)
        layers.append((coll, src, color))
        panels.append((ax, grid, layers))
    caption = fig.text(0.5, 0.01, "", ha="center", fontsize=7)
    if title:
        fig.suptitle(title, fontsize=8)
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.04, top=0.9, wspace=0.0)

    path = Path(path)
    writer = PillowWriter(fps=max(1.0, fps / int(stride)))
    with atomic_path(path, make_parents=True) as tmp:
        with writer.saving(fig, str(tmp), dpi):
            t0 = t_last = time.perf_counter()
            for k, t in enumerate(idx):  # one draw per frame: move the artists, then grab
                if progress is not None and time.perf_counter() - t_last > 5.0:
                    t_last = time.perf_counter()
                    progress(f"{path.name}: frame {k} of {len(idx)}, {t_last - t0:.0f} s")
                context = highlight is not None and not (start <= t < stop)
                for ax, grid, layers in panels:
                    centre_axes(ax, grid, gt_p[t, 0, :2], half, floor, mid)
                    for coll, src, color in layers:
                        coll.set_segments(bone_segments(src[t], par))
                        if color is not None:
                            coll.set_color(bone_colors(CONTEXT_COLOR if context else color, par, sides))
                caption.set_text(f"frame {numbers[t]}" + (" (context)" if context else ""))
                writer.grab_frame(facecolor="white")
    return path


def stderr_progress(line: str) -> None:
    """Print a progress line to stderr at once (the ``progress`` of the commands' pictures)."""
    print(line, file=sys.stderr, flush=True)


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
                       panel_size: float = 3.2, dpi: float = 80) -> Path:
    """Draw a character following a ground path: a ``.png`` (left: the poses at ``num_frames`` evenly spaced
    frames in 3-D with the path on the floor; right: the map — path in grey, root track in red, start marked)
    or an animated ``.gif`` (left: the character followed by the camera, the path on the floor; right: the map
    with the current position).

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
    """
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    par = check_parents(parents)
    pos = check_positions(positions, "positions", par)
    pts = np.asarray(path_points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2:
        raise ValueError(f"path_points: expected shape (M >= 2, 2), got {pts.shape}")
    suffix = Path(path).suffix.lower()
    if suffix not in (".png", ".gif"):
        raise ValueError(f"path: expected a .png or .gif file name, got {path}")
    if closed:
        pts = np.concatenate([pts, pts[:1]])
    pp = to_plot(pos, "y")                                                 # (T, J, 3), Z up
    floor = float(pp[..., 2].min())
    path3 = np.stack([pts[:, 0], -pts[:, 1], np.full(len(pts), floor)], axis=-1)  # (M, 3)
    fig = figure(2 * panel_size, panel_size + 0.3, dpi)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    ax2 = fig.add_subplot(1, 2, 2)
    ax2.plot(pts[:, 0], pts[:, 1], color="0.6", lw=1.5, label="path")
    ax2.plot(pos[:, 0, 0], pos[:, 0, 2], color=PRED_COLOR, lw=1.0, label="root")
    ax2.plot(pos[0, 0, 0], pos[0, 0, 2], "o", color=CONTEXT_COLOR, ms=4, label="start")
    ax2.set_aspect("equal")
    ax2.invert_yaxis()  # the map seen from above with x right and z down, as the 3-D view's floor
    ax2.set_xlabel("x")
    ax2.set_ylabel("z")
    ax2.legend(fontsize=6, loc="upper right")
    ax2.tick_params(labelsize=6)
    if title:
        fig.suptitle(title, fontsize=8)
    if suffix == ".png":
        ax.set_proj_type("ortho")
        ax.view_init(elev=25.0, azim=-60.0)
        ax.set_axis_off()
        lo = np.minimum(path3.min(0), pp.reshape(-1, 3).min(0))
        hi = np.maximum(path3.max(0), pp.reshape(-1, 3).max(0))
        centre, half = 0.5 * (lo + hi), 0.55 * float(np.max(hi - lo))
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[1] - half, centre[1] + half)
        ax.set_zlim(floor, floor + 2 * half)
        ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.2)
        ax.plot(path3[:, 0], path3[:, 1], path3[:, 2], color="0.6", lw=1.2)
        for k, t in enumerate(np.linspace(0, len(pp) - 1, max(1, int(num_frames))).round().astype(int)):
            ax.add_collection3d(Line3DCollection(bone_segments(pp[t], par), colors=PRED_COLOR, linewidths=1.2))
            ax2.plot(pos[t, 0, 0], pos[t, 0, 2], ".", color="k", ms=3)
        fig.subplots_adjust(left=0.0, right=0.98, bottom=0.12, top=0.9, wspace=0.15)
        return save_figure(fig, path)

    try:
        from matplotlib.animation import PillowWriter
    except ImportError as exc:  # pragma: no cover
        raise ImportError(_INSTALL_HINT) from exc
    half = half_extent([pp])
    grid = setup_axes(ax, half, floor)
    ax.plot(path3[:, 0], path3[:, 1], path3[:, 2], color="0.6", lw=1.5)
    bones = Line3DCollection(bone_segments(pp[0], par), colors=PRED_COLOR, linewidths=1.8)
    ax.add_collection3d(bones)
    (dot,) = ax2.plot([pos[0, 0, 0]], [pos[0, 0, 2]], "o", color=PRED_COLOR, ms=5)
    caption = fig.text(0.25, 0.01, "", ha="center", fontsize=7)
    fig.subplots_adjust(left=0.0, right=0.98, bottom=0.12, top=0.9, wspace=0.15)
    idx = np.arange(0, pp.shape[0], max(1, int(stride)))
    writer = PillowWriter(fps=max(1.0, fps / max(1, int(stride))))
    path = Path(path)
    with atomic_path(path, make_parents=True) as tmp:
        with writer.saving(fig, str(tmp), dpi):
            for t in idx:
                centre_axes(ax, grid, pp[t, 0, :2], half, floor, floor + half * 0.9)
                bones.set_segments(bone_segments(pp[t], par))
                dot.set_data([pos[t, 0, 0]], [pos[t, 0, 2]])
                caption.set_text(f"frame {t} ({t / fps:.1f} s)")
                writer.grab_frame(facecolor="white")
    return path


# ----------------------------------------------------------------------------------------------------------
# Kernel tier: unchecked helpers shared with refimpl/render_strip.py (public names, not in __all__)


def figure(width: float, height: float, dpi: float):
    """A new Agg-backed ``Figure`` (no pyplot, no global backend change)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - exercised only without matplotlib
        raise ImportError(_INSTALL_HINT) from exc
    fig = Figure(figsize=(width, height), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path: str | os.PathLike) -> Path:
    """Save ``fig`` as PNG to ``path`` atomically."""
    path = Path(path)
    with atomic_path(path, make_parents=True) as tmp:
        fig.savefig(tmp, format="png", facecolor="white")
    return path


def check_positions(positions, name: str, parents=None) -> np.ndarray:
    """Validate a ``(T, J, 3)`` finite position array (and, given ``parents``, its joint count)."""
    p = np.asarray(positions, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or p.shape[0] < 1 or p.shape[1] < 1:
        raise ValueError(f"{name} must have shape (T, J, 3) with T, J >= 1, got {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name} contains NaN or inf")
    if parents is not None and p.shape[1] != len(parents):
        raise ValueError(f"{name} has {p.shape[1]} joints but parents has {len(parents)} entries")
    return p


def check_parents(parents) -> np.ndarray:
    """Validate a parent index array ``(J,)``: ``-1`` or an earlier-or-any valid joint index."""
    par = np.asarray(parents)
    if par.ndim != 1 or par.size < 1 or not np.issubdtype(par.dtype, np.integer):
        raise ValueError(f"parents must be a 1-D integer array (J,), got shape {par.shape} dtype {par.dtype}")
    if np.any(par < -1) or np.any(par >= par.size) or np.any(par == np.arange(par.size)):
        raise ValueError(f"parents must hold -1 or another joint's index in [0, {par.size}), got {par.tolist()}")
    return par.astype(np.int64)


def check_sides(sides, num_joints: int):
    """Validate ``sides`` (None or ``(J,)`` of −1 / 0 / +1: left / centre / right joints)."""
    if sides is None:
        return None
    s = np.asarray(sides)
    if s.shape != (num_joints,) or not np.issubdtype(s.dtype, np.integer) or np.any(np.abs(s) > 1):
        raise ValueError(f"sides must be {num_joints} integers in {{-1, 0, 1}} (left, centre, right), got {s.tolist()}")
    return s.astype(np.int64)


def check_up(up: str) -> str:
    if up not in ("y", "z"):
        raise ValueError(f"up must be 'y' or 'z', got {up!r}")
    return up


def to_plot(p: np.ndarray, up: str) -> np.ndarray:
    """Data coordinates ``(..., 3)`` → matplotlib 3-D coordinates (Z vertical), a proper rotation.

    Y-up data ``(x, y, z)`` becomes ``(x, -z, y)``: right-handed is kept (x̂ × (−ẑ) = ŷ).
    """
    if up == "z":
        return p
    return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)  # (..., 3)


def bone_segments(p: np.ndarray, parents: np.ndarray) -> np.ndarray:
    """Bones of one pose as segments ``(J_bones, 2, 3)`` from each non-root joint to its parent."""
    child = np.flatnonzero(parents >= 0)
    return np.stack([p[parents[child]], p[child]], axis=1)  # (J_bones, 2, 3)


def half_extent(plot_positions: Sequence[np.ndarray]) -> float:
    """Half side of the cube that holds every drawn pose centred on its root's horizontal position."""
    ext = 0.0
    for q in plot_positions:  # (T, J, 3) each
        rel = q[..., :2] - q[:, :1, :2]  # (T, J, 2) horizontal offsets from the root
        ext = max(ext, float(np.max(np.abs(rel))), 0.5 * float(np.ptp(q[..., 2], axis=1).max()))
    return 1.1 * ext if ext > 0 else 1.0


def grid_segments(centre: np.ndarray, half: float, floor: float) -> np.ndarray:
    """Floor grid lines FIXED IN THE WORLD (at multiples of a round spacing, about ``half / 2``) that cross the
    square of side ``2 half`` around ``centre``, as segments ``(M, 2, 3)``: the character travels and its feet
    slide over a grid that stays put."""
    step = _round_step(half / 2.0)
    x0, x1, y0, y1 = centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half
    xs = np.arange(np.ceil(x0 / step), np.floor(x1 / step) + 1) * step
    ys = np.arange(np.ceil(y0 / step), np.floor(y1 / step) + 1) * step
    along_y = [[(x, y0, floor), (x, y1, floor)] for x in xs]
    along_x = [[(x0, y, floor), (x1, y, floor)] for y in ys]
    return np.asarray(along_y + along_x, dtype=np.float64).reshape(-1, 2, 3)


def _round_step(x: float) -> float:
    """The largest 1, 2 or 5 times a power of ten that is <= ``x`` (> 0)."""
    e = 10.0 ** np.floor(np.log10(x))
    return float(max(m * e for m in (1.0, 2.0, 5.0) if m * e <= x * (1 + 1e-12)))


def bone_colors(color, parents: np.ndarray, sides=None) -> list:
    """Colour of every bone of :func:`bone_segments`: ``color`` for the centre, darker for left limbs and lighter
    for right limbs (``sides (J,)``: −1 left, +1 right, 0 centre, the side of the bone's child joint)."""
    from matplotlib.colors import to_rgb

    child = np.flatnonzero(parents >= 0)
    base = np.asarray(to_rgb(color))
    if sides is None:
        return [tuple(base)] * len(child)
    shade = {-1: 0.55 * base, 0: base, 1: base + 0.55 * (1.0 - base)}
    return [tuple(shade[int(np.sign(sides[j]))]) for j in child]


def setup_axes(ax, half: float, floor: float):
    """Orthographic, equal-aspect 3-D axes without decoration, plus a floor grid; returns the grid collection."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection

    ax.set_proj_type("ortho")
    ax.view_init(elev=12.0, azim=-60.0)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.35)
    ax.computed_zorder = False  # draw in call order: the prediction over the ground-truth ghost
    ax.set_axis_off()
    grid = Line3DCollection(grid_segments(np.zeros(2), half, floor), colors="0.72", linewidths=0.6)
    ax.add_collection3d(grid)
    return grid


def centre_axes(ax, grid, centre: np.ndarray, half: float, floor: float, vertical_mid: float) -> None:
    """Centre the camera box (side ``2 half``) on ``centre`` (horizontal) and move the floor grid with it."""
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(vertical_mid - half, vertical_mid + half)
    grid.set_segments(grid_segments(centre, half, floor))


def pick_frames(num_total: int, frames, num_frames: int) -> np.ndarray:
    if frames is None:
        if num_frames < 1:
            raise ValueError(f"num_frames must be >= 1, got {num_frames}")
        return np.unique(np.linspace(0, num_total - 1, min(num_frames, num_total)).round().astype(np.int64))
    idx = np.asarray(frames, dtype=np.int64).reshape(-1)
    if idx.size == 0 or np.any(idx < 0) or np.any(idx >= num_total):
        raise ValueError(f"frames must be indices in [0, {num_total}), got {idx.tolist()}")
    return idx


def check_highlight(highlight, num_total: int):
    if highlight is None:
        return 0, num_total
    start, stop = (int(v) for v in highlight)
    if not 0 <= start <= stop <= num_total:
        raise ValueError(f"highlight must be (start, stop) with 0 <= start <= stop <= {num_total}, got {highlight}")
    return start, stop


def check_numbers(frame_numbers, num_total: int) -> np.ndarray:
    if frame_numbers is None:
        return np.arange(num_total)
    numbers = np.asarray(frame_numbers).reshape(-1)
    if numbers.shape != (num_total,) or not np.issubdtype(numbers.dtype, np.integer):
        raise ValueError(f"frame_numbers must be {num_total} integers, got shape {numbers.shape} "
                         f"dtype {numbers.dtype}")
    return numbers
