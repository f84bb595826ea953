"""The drawing helpers every picture of skeletal motion shares (kernel tier of :mod:`refimpl.render`,
:mod:`refimpl.render_strip`): argument checks, the data → plot mapping, bones and their left / right shades,
the FIXED floor (one height and one extent for a whole clip; its grid lines fixed in the world), the camera box,
titles that fit, clipping a ground path to the floor square, and the GIF frames.

matplotlib (and Pillow, which it depends on) is imported inside the functions that draw, so importing this
module needs NumPy only. The functions do not check their arguments unless their name starts with ``check_``.

Colours, one rule for every model: the ground truth is blue, a prediction red, context frames green, a ghost of
the ground truth light grey; with ``sides`` (``refimpl.render_strip.limb_sides``) left limbs are drawn in a
darker and right limbs in a lighter shade of that colour.

Shape legend: T frames, J joints, M path points, K segments, H × W pixels.
"""
from __future__ import annotations

import contextlib
import os
import textwrap
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from refimpl.arrays import float_array
from refimpl.atomic import atomic_path

GT_COLOR = "tab:blue"
PRED_COLOR = "tab:red"
CONTEXT_COLOR = "tab:green"
GHOST_COLOR = "0.75"
FLOOR_COLOR = "0.93"   # the floor square's fill, under its grid lines
GRID_COLOR = "0.72"
SIDES_NOTE = "left limbs dark, right limbs light"
INSTALL_HINT = "rendering needs matplotlib: pip install 'refimpl[render]' (or pip install matplotlib)"


# ----------------------------------------------------------------------------------------------------------
# figures and files


def figure(width: float, height: float, dpi: float):
    """A new Agg-backed ``Figure`` (no pyplot, no global backend change)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:  # pragma: no cover - exercised only without matplotlib
        raise ImportError(INSTALL_HINT) from exc
    fig = Figure(figsize=(width, height), dpi=dpi)
    FigureCanvasAgg(fig)
    return fig


def save_figure(fig, path: str | os.PathLike) -> Path:
    """Save ``fig`` as PNG to ``path`` atomically."""
    path = Path(path)
    with atomic_path(path, make_parents=True) as tmp:
        fig.savefig(tmp, format="png", facecolor="white")
    return path


@contextlib.contextmanager
def gif_writer(path: str | os.PathLike, fps: float) -> Iterator:
    """Write a looping GIF at ``fps`` frame by frame (atomically): yields ``add(fig)``, which draws ``fig`` and
    appends it.

    Each frame is streamed to the file at once — only the rectangle that changed since the previous frame, as a
    256-colour palette image with its own colour table (Pillow's GIF encoder, ``GifImagePlugin.getheader`` /
    ``getdata``) — so that memory does not grow with the GIF's length (a 120 s walk has 1,800 frames).
    """
    from PIL import GifImagePlugin, Image

    duration = int(1000.0 / fps)
    state = {"prev": None}
    with atomic_path(path, make_parents=True) as tmp, open(tmp, "wb") as f:
        def add(fig) -> None:
            fig.canvas.draw()
            rgb = np.ascontiguousarray(np.asarray(fig.canvas.buffer_rgba())[..., :3])  # (H, W, 3) uint8
            x0, y0, x1, y1 = _changed_box(state["prev"], rgb)
            im = Image.fromarray(np.ascontiguousarray(rgb[y0:y1, x0:x1])).quantize(
                256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE)
            if state["prev"] is None:
                f.write(b"".join(GifImagePlugin.getheader(im, None, {"loop": 0, "duration": duration})[0]))
            f.write(b"".join(GifImagePlugin.getdata(im, offset=(x0, y0), duration=duration,
                                                    include_color_table=True)))
            state["prev"] = rgb

        yield add
        if state["prev"] is None:
            raise ValueError("a GIF needs at least one frame")
        f.write(b";")  # the GIF trailer


def _changed_box(prev, rgb: np.ndarray) -> tuple[int, int, int, int]:
    """``(x0, y0, x1, y1)`` of the pixels of ``rgb (H, W, 3)`` that differ from ``prev`` (all of them for the first
    frame; one pixel for an unchanged frame, which keeps its place in the timing)."""
    if prev is None:
        return 0, 0, rgb.shape[1], rgb.shape[0]
    changed = np.any(rgb != prev, axis=-1)  # (H, W)
    rows, cols = np.flatnonzero(changed.any(axis=1)), np.flatnonzero(changed.any(axis=0))
    if rows.size == 0:
        return 0, 0, 1, 1
    return int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1


def wrap_title(title: str | None, width_in: float, fontsize: float) -> str:
    """``title`` broken into lines that fit a figure ``width_in`` inches wide at ``fontsize`` points."""
    if not title:
        return ""
    per_line = max(12, int(0.9 * width_in * 72.0 / (0.56 * fontsize)))
    return "\n".join(textwrap.wrap(title, per_line)) or title


def title_height(text: str, fontsize: float) -> float:
    """Height in inches of a (wrapped) title of ``fontsize`` points, with its margins; 0 for none."""
    return 0.0 if not text else 0.08 + (text.count("\n") + 1) * 1.3 * fontsize / 72.0


def fit_text(fig, artist, min_size: float = 5.0) -> None:
    """Shrink ``artist``'s font until it lies inside the figure (a title is never clipped)."""
    renderer = fig.canvas.get_renderer()
    width, height = fig.bbox.width, fig.bbox.height
    while artist.get_fontsize() > min_size:
        box = artist.get_window_extent(renderer)
        if box.x0 >= 0 and box.y0 >= 0 and box.x1 <= width and box.y1 <= height:
            return
        artist.set_fontsize(artist.get_fontsize() - 0.5)


# ----------------------------------------------------------------------------------------------------------
# argument checks


def check_positions(positions, name: str, parents=None) -> np.ndarray:
    """Validate a ``(T, J, 3)`` finite position array (and, given ``parents``, its joint count)."""
    p = float_array(positions, name, (None, None, 3)).astype(np.float64, copy=False)    # (T, J, 3)
    if p.shape[0] < 1 or p.shape[1] < 1:
        raise ValueError(f"{name}: expected shape (T, J, 3) with T, J >= 1, got {p.shape}")
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


def pick_frames(num_total: int, frames, num_frames: int) -> np.ndarray:
    if frames is None:
        if num_frames < 1:
            raise ValueError(f"num_frames must be >= 1, got {num_frames}")
        return np.unique(np.linspace(0, num_total - 1, min(num_frames, num_total)).round().astype(np.int64))
    idx = np.asarray(frames, dtype=np.int64).reshape(-1)
    if idx.size == 0 or np.any(idx < 0) or np.any(idx >= num_total):
        raise ValueError(f"frames must be indices in [0, {num_total}), got {idx.tolist()}")
    return idx


# ----------------------------------------------------------------------------------------------------------
# geometry


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


def clip_floor(ground_truth: np.ndarray) -> float:
    """The floor height of a whole clip (plot coordinates ``(T, J, 3)``, Z up): its lowest joint over ALL its
    frames — one height for every panel and GIF frame, so that a foot above it is visibly off the floor."""
    return float(ground_truth[..., 2].min())


def half_extent(plot_positions: Sequence[np.ndarray]) -> float:
    """Half side of the cube that holds every pose of the clips (all their frames) centred on its root's
    horizontal position: one camera box, and one floor square, for the whole clip."""
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


def floor_square(centre: np.ndarray, half: float, floor: float) -> np.ndarray:
    """The floor's square of side ``2 half`` around ``centre`` at height ``floor``, corners ``(4, 3)``."""
    x0, x1, y0, y1 = centre[0] - half, centre[0] + half, centre[1] - half, centre[1] + half
    return np.array([[x0, y0, floor], [x1, y0, floor], [x1, y1, floor], [x0, y1, floor]], dtype=np.float64)


def clip_segments(points: np.ndarray, lo, hi) -> np.ndarray:
    """The parts of the polyline ``points (M, 2)`` inside the rectangle ``lo (2,) … hi (2,)`` as segments
    ``(K, 2, 2)`` (Liang–Barsky): a ground path drawn on the floor square and not past its edges."""
    a, d = points[:-1], np.diff(points, axis=0)  # (M-1, 2) each
    t0, t1 = np.zeros(len(a)), np.ones(len(a))
    keep = np.ones(len(a), dtype=bool)
    for k in range(2):
        for p, q in ((-d[:, k], a[:, k] - lo[k]), (d[:, k], hi[k] - a[:, k])):
            flat = p == 0
            keep &= ~(flat & (q < 0))
            r = np.divide(q, p, out=np.zeros_like(q), where=~flat)
            t0 = np.where(~flat & (p < 0), np.maximum(t0, r), t0)
            t1 = np.where(~flat & (p > 0), np.minimum(t1, r), t1)
    keep &= t0 < t1
    seg = np.stack([a + t0[:, None] * d, a + t1[:, None] * d], axis=1)  # (M-1, 2, 2)
    return seg[keep]


# ----------------------------------------------------------------------------------------------------------
# colours and axes


def bone_colors(color, parents: np.ndarray, sides=None) -> list:
    """Colour of every bone of :func:`bone_segments`: ``color`` for the centre, darker for left limbs and lighter
    for right limbs (``sides (J,)``: −1 left, +1 right, 0 centre, the side of the bone's child joint)."""
    child = np.flatnonzero(parents >= 0)
    cols = joint_colors(color, len(parents), sides)
    return [cols[j] for j in child]


def joint_colors(color, num_joints: int, sides=None) -> list:
    """Colour of every joint ``(J,)`` by the rule of :func:`bone_colors` (a joint's dot in its limb's shade)."""
    from matplotlib.colors import to_rgb

    base = np.asarray(to_rgb(color))
    if sides is None:
        return [tuple(base)] * num_joints
    shade = {-1: tuple(0.55 * base), 0: tuple(base), 1: tuple(base + 0.55 * (1.0 - base))}
    return [shade[int(np.sign(s))] for s in sides]


def setup_axes(ax, half: float, floor: float, elev: float = 12.0, zoom: float = 1.35):
    """Orthographic, equal-aspect 3-D axes without decoration, plus the floor (a light square under its grid
    lines); returns ``(floor fill, grid)`` for :func:`centre_axes`."""
    from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

    ax.set_proj_type("ortho")
    ax.view_init(elev=elev, azim=-60.0)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=zoom)
    ax.computed_zorder = False  # draw in call order: floor, grid, then the ghost, then the pose
    ax.set_axis_off()
    fill = Poly3DCollection([floor_square(np.zeros(2), half, floor)], facecolors=FLOOR_COLOR, edgecolors="none")
    ax.add_collection3d(fill)
    grid = Line3DCollection(grid_segments(np.zeros(2), half, floor), colors=GRID_COLOR, linewidths=0.6)
    ax.add_collection3d(grid)
    return fill, grid


def centre_axes(ax, floor_artists, centre: np.ndarray, half: float, floor: float, vertical_mid: float) -> None:
    """Centre the camera box (side ``2 half``) on ``centre`` (horizontal) and move the floor square with it
    (its grid lines stay at their world positions)."""
    fill, grid = floor_artists
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(vertical_mid - half, vertical_mid + half)
    fill.set_verts([floor_square(centre, half, floor)])
    grid.set_segments(grid_segments(centre, half, floor))
