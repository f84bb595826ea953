"""Tests of refimpl.render (spec/cli.md §Pictures): PNG strips, GIFs, loss and error curves.

Every picture is rendered to a file and checked: it exists, is a valid PNG/GIF of plausible size, and is not
blank (pixel variance > 0). One test renders a real sample BVH and checks that the skeleton fills the panel.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")
from PIL import Image  # noqa: E402  (pillow is a matplotlib dependency)

from refimpl.render import read_loss_log, render_error_curves, render_gif, render_loss_curve  # noqa: E402
from refimpl.render_strip import render_strip  # noqa: E402

SAMPLE_BVH = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"

# A 6-joint stick figure (Y-up): root, spine, head, left and right leg, one arm.
_PARENTS = np.array([-1, 0, 1, 0, 0, 1])
_OFFSETS = np.array([[0, 10, 0], [0, 5, 0], [0, 3, 0], [2, -10, 0], [-2, -10, 0], [4, 0, 0]], dtype=np.float64)


def _walk(num_frames: int = 12, shift: float = 0.0) -> np.ndarray:
    """Positions ``(T, 6, 3)`` of the stick figure walking along +x with swinging legs."""
    t = np.arange(num_frames)[:, None]
    pos = np.zeros((num_frames, 6, 3))
    pos[:, 0] = np.hstack([2.0 * t, np.full_like(t, 10.0), np.zeros_like(t)], dtype=np.float64)
    for j in range(1, 6):
        swing = np.zeros((num_frames, 3))
        if j in (3, 4):
            swing[:, 0] = (1 if j == 3 else -1) * 3.0 * np.sin(0.5 * t[:, 0])
        pos[:, j] = pos[:, _PARENTS[j]] + _OFFSETS[j] + swing + shift
    return pos


def _load_png(path: Path) -> np.ndarray:
    data = Path(path).read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG file"
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.float64)


def test_strip_png_is_valid_and_not_blank(tmp_path):
    """§Pictures: ground truth and prediction rows, one panel per frame."""
    gt = _walk()
    out = render_strip(tmp_path / "sub" / "strip.png", gt, _PARENTS, prediction=_walk(shift=0.5),
                       num_frames=4, highlight=(2, 10), title="walk", frame_time=1 / 30)
    assert out == tmp_path / "sub" / "strip.png"
    img = _load_png(out)
    h, w, _ = img.shape
    assert w > 1.5 * h > 400  # four panels side by side, two rows
    assert img.var() > 0
    # both colours are present: blue ground truth (tab:blue) and red prediction (tab:red)
    blue = np.all(np.abs(img - [31, 119, 180]) < 40, axis=-1).sum()
    red = np.all(np.abs(img - [214, 39, 40]) < 40, axis=-1).sum()
    assert blue > 50 and red > 50
    assert not list(tmp_path.glob("sub/.*")), "temporary file left behind"


def test_strip_single_row_and_explicit_frames(tmp_path):
    """§Pictures: without a prediction there is one row; ``frames`` selects the panels."""
    out = render_strip(tmp_path / "one.png", _walk(), _PARENTS, frames=[0, 5, 11], up="y",
                       frame_numbers=np.arange(100, 112), frame_time=0.01)
    img = _load_png(out)
    assert img.shape[1] > 2 * img.shape[0]
    assert img.var() > 0


def test_strip_z_up_differs_from_y_up(tmp_path):
    """§Pictures: the ``up`` axis changes which data axis is drawn vertical."""
    a = _load_png(render_strip(tmp_path / "y.png", _walk(), _PARENTS, num_frames=2, up="y"))
    b = _load_png(render_strip(tmp_path / "z.png", _walk(), _PARENTS, num_frames=2, up="z"))
    assert a.shape == b.shape and np.abs(a - b).sum() > 0


@pytest.mark.parametrize("kwargs, match", [
    (dict(positions=np.zeros((4, 6, 2))), "positions: expected shape"),
    (dict(positions=np.full((4, 6, 3), np.nan)), "NaN"),
    (dict(parents=np.array([-1, 0, 1])), "joints but parents"),
    (dict(parents=np.array([-1, 0, 1, 0, 0, 9])), "parents must hold"),
    (dict(prediction=np.zeros((3, 6, 3))), "prediction must have the shape"),
    (dict(frames=[0, 99]), "frames must be indices"),
    (dict(highlight=(5, 2)), "highlight"),
    (dict(up="x"), "up must be"),
    (dict(frame_numbers=[0, 1]), "frame_numbers"),
])
def test_strip_rejects_bad_input(tmp_path, kwargs, match):
    """§Pictures: bad arrays raise ValueError naming the argument; nothing is written."""
    args = dict(positions=_walk(4), parents=_PARENTS)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        render_strip(tmp_path / "bad.png", args.pop("positions"), args.pop("parents"), **args)
    assert not list(tmp_path.iterdir())


def test_gif_has_frames_and_content(tmp_path):
    """§Pictures: an animated GIF, ground truth beside prediction, one GIF frame per drawn frame."""
    out = render_gif(tmp_path / "walk.gif", _walk(10), _PARENTS, prediction=_walk(10, shift=0.5), stride=2,
                     highlight=(2, 8))
    assert out.read_bytes()[:6] in (b"GIF89a", b"GIF87a")
    with Image.open(out) as im:
        assert im.n_frames == 5
        assert im.size[0] > im.size[1] > 100
        im.seek(2)
        frame = np.asarray(im.convert("RGB"), dtype=np.float64)
    assert frame.var() > 0


def test_gif_rejects_bad_stride(tmp_path):
    """§Pictures: stride must be a positive integer."""
    with pytest.raises(ValueError, match="stride"):
        render_gif(tmp_path / "x.gif", _walk(4), _PARENTS, stride=0)


def test_loss_curve_from_csv(tmp_path):
    """§Pictures: loss curves from the training CSV log (columns containing 'loss'; x = step)."""
    log = tmp_path / "loss.csv"
    steps = np.arange(1, 121)
    rows = ["step,epoch,train_loss,val_loss,seconds"]
    for s in steps:
        val = f"{0.5 / s ** 0.5:.6f}" if s % 20 == 0 else ""
        rows.append(f"{s},{s // 40},{1.0 / s ** 0.5 + 0.01 * np.sin(s):.6f},{val},{0.1 * s:.2f}")
    log.write_text("\n".join(rows) + "\n")
    data = read_loss_log(log)
    assert set(data) == {"step", "epoch", "train_loss", "val_loss", "seconds"}
    assert np.isnan(data["val_loss"][0]) and data["val_loss"][19] == pytest.approx(0.5 / 20 ** 0.5, rel=1e-5)
    img = _load_png(render_loss_curve(tmp_path / "loss.png", log))
    assert img.shape[0] > 200 and img.shape[1] > 300 and img.var() > 0


def test_loss_curve_needs_loss_columns(tmp_path):
    """§Pictures: a log without loss columns is a clear ValueError."""
    with pytest.raises(ValueError, match="no loss columns"):
        render_loss_curve(tmp_path / "x.png", {"step": np.arange(3), "lr": np.ones(3)})
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    with pytest.raises(ValueError, match="empty"):
        read_loss_log(empty)


def test_error_curves(tmp_path):
    """§Pictures: per-frame error curves, one per method (QTG paper, Fig. 3)."""
    t = np.arange(1, 31)
    curves = {"QTG": 2 + 0.05 * t, "inertialization": 10 * np.sin(np.pi * t / 31), "interpolation": 8 + 0 * t}
    img = _load_png(render_error_curves(tmp_path / "err.png", curves, frame_time=1 / 30))
    assert img.var() > 0
    with pytest.raises(ValueError, match="curves"):
        render_error_curves(tmp_path / "e.png", {})
    with pytest.raises(ValueError, match=r"curves\['a'\]"):
        render_error_curves(tmp_path / "e.png", {"a": np.zeros((2, 2))})


def test_sample_bvh_renders_a_person(tmp_path):
    """§Pictures: a real CMU BVH frame is drawn upright (taller than wide) in the panel, not blank."""
    bvh = pytest.importorskip("refimpl.bvh")
    motion = bvh.read_bvh(SAMPLE_BVH)
    pos = motion.positions()[1:200:20]  # (10, J, 3), skip the reference T-pose of frame 0
    parents = np.asarray(motion.skeleton.parents)
    img = _load_png(render_strip(tmp_path / "person.png", pos, parents, frames=[3]))
    ink = np.all(np.abs(img - [31, 119, 180]) < 60, axis=-1)  # the skeleton's blue (tab:blue)
    ink[:, : img.shape[1] // 10] = False  # the row label on the left is blue too
    rows, cols = np.nonzero(ink)
    assert ink.sum() > 100
    height, width = rows.max() - rows.min(), cols.max() - cols.min()
    assert height > 1.5 * width, "a standing walker should be taller than wide"


# ----------------------------------------------------------------------------------------------------------
# issue 35: GIFs tall enough, titles not clipped, one fixed floor, the walk's path on the floor

FLOOR = 0.93 * 255  # refimpl.render_kernel.FLOOR_COLOR, the floor square's fill
ROAD = 0.45 * 255   # the ground path's grey in the walk's 3-D view


def _gif_frames(path) -> list[np.ndarray]:
    with Image.open(path) as im:
        out = []
        for k in range(im.n_frames):
            im.seek(k)
            out.append(np.asarray(im.convert("RGB"), dtype=np.float64))
    return out


def _grey(img: np.ndarray, level: float, tol: float = 6.0) -> np.ndarray:
    return np.all(np.abs(img - level) < tol, axis=-1)


def test_gif_is_tall_enough_and_its_title_is_not_clipped(tmp_path):
    """§8: at least GIF_MIN_HEIGHT px tall even for a small panel, a long title wrapped inside the picture
    (old: 2.6-inch panels at 80 dpi, 232 px tall, the title cut at both sides)."""
    from refimpl.render import GIF_MIN_HEIGHT

    title = "a long title that names the model, the source file, the frames and the colours of the context"
    out = render_gif(tmp_path / "t.gif", _walk(6), _PARENTS, title=title, panel_size=2.0, dpi=80)
    img = _gif_frames(out)[0]
    h, w, _ = img.shape
    assert h >= GIF_MIN_HEIGHT
    ink = np.all(img < 120, axis=-1)  # black text
    band = ink[: h // 8]
    assert band.sum() > 100                        # the title is there, in the top rows
    assert not band[:2].any() and not band[:, :2].any() and not band[:, -2:].any()  # and touches no edge


def test_gif_floor_rows_are_identical_across_frames(tmp_path):
    """§8: one floor height and square for the whole clip: the floor's rows are the same in every frame while
    the character walks across the world-fixed grid."""
    frames = _gif_frames(render_gif(tmp_path / "f.gif", _walk(12), _PARENTS, prediction=_walk(12, shift=0.5)))
    rows = []
    for img in frames:
        r = np.flatnonzero(_grey(img, FLOOR).sum(axis=1) > 3)
        rows.append((r.min(), r.max()))
    assert len(set(rows)) == 1 and rows[0][1] - rows[0][0] > 20, rows


def test_strip_floor_is_the_whole_clips(tmp_path):
    """§8: the floor height is the clip's lowest joint over ALL its frames, not only the frames drawn (old:
    the drawn frames' lowest joint, so a strip of frame 5 alone put the floor under frame 5's feet)."""
    a = _walk(12)
    b = a.copy()
    b[0, :, 1] -= 8.0  # frame 0 is lower: the floor of the clip is lower (the box's size is unchanged)
    img_a = _load_png(render_strip(tmp_path / "a.png", a, _PARENTS, frames=[5]))
    img_b = _load_png(render_strip(tmp_path / "b.png", b, _PARENTS, frames=[5]))
    fa, fb = (np.flatnonzero(_grey(i, FLOOR).sum(axis=1) > 3) for i in (img_a, img_b))
    assert (fa.min(), fa.max()) == (fb.min(), fb.max())  # the floor is drawn at the same place ...
    blue = [np.flatnonzero(np.all(np.abs(i - [31, 119, 180]) < 40, axis=-1)[:, i.shape[1] // 10:].any(axis=1))
            for i in (img_a, img_b)]
    assert blue[1].max() < blue[0].max() - 3  # ... and frame 5's feet stand above it (old: the same picture)


def _straight_walk(num_frames: int = 30):
    """The stick figure walking along +x at height 0 (Y up), and a path from x = −100 to 200 along it."""
    pos = _walk(num_frames)
    pos[..., 1] -= pos[..., 1].min()
    return pos, np.array([[-100.0, 0.0], [200.0, 0.0]])


def test_walk_gif_path_lies_on_the_floor(tmp_path):
    """§8: the walk's 3-D view draws the part of the path inside the floor square, ON it (old: the whole path,
    unclipped, so that it ran above the floor to the panel's edges)."""
    from refimpl.render import render_path_motion

    pos, path = _straight_walk()
    frames = _gif_frames(render_path_motion(tmp_path / "w.gif", pos, _PARENTS, path, stride=3))
    for img in frames:
        view = img[:, : img.shape[1] // 2]   # the 3-D view (the map is on the right)
        floor_rows = np.flatnonzero(_grey(view, FLOOR).sum(axis=1) > 3)
        road_rows = np.flatnonzero(_grey(view, ROAD, 14.0).sum(axis=1) > 0)
        assert road_rows.size > 5
        assert floor_rows.min() - 2 <= road_rows.min() and road_rows.max() <= floor_rows.max() + 2


def test_walk_gif_map_shows_the_root_trace_so_far(tmp_path):
    """§8: the map at frame k holds the root's trace of frames 0 … k only (old: the whole trace from frame 0)."""
    from refimpl.render import render_path_motion

    pos, path = _straight_walk()
    frames = _gif_frames(render_path_motion(tmp_path / "w.gif", pos, _PARENTS, path, stride=3))
    red = np.array([214, 39, 40])
    counts = [int(np.all(np.abs(img[:, img.shape[1] // 2:] - red) < 40, axis=-1).sum()) for img in frames]
    # frame 0: the legend's line and the dot only; then the trace grows (old: all of it from frame 0)
    assert counts[-1] > counts[0] + 40 and counts[0] < 0.7 * counts[-1], counts
