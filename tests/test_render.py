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
    (dict(positions=np.zeros((4, 6, 2))), "positions must have shape"),
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
