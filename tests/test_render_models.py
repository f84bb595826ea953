"""Every model's pictures through `refimpl generate --png/--gif` with the shipped models (spec/cli.md §8, issue 35):
the same left / right shades (the skeleton's joint names, `limb_sides`), a title, a GIF tall enough to judge a
foot contact with its title not clipped."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("matplotlib")
from PIL import Image  # noqa: E402

from refimpl.cli import EXIT_OK, main  # noqa: E402
from refimpl.render import GIF_MIN_HEIGHT  # noqa: E402

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"
BLUE = np.array([31, 119, 180], dtype=np.float64)   # tab:blue, the ground truth (and a motion drawn alone)
RED = np.array([214, 39, 40], dtype=np.float64)     # tab:red, a prediction
DARK, LIGHT = 0.55, 0.55                             # left = 0.55 · colour, right = colour + 0.55 · (1 − colour)


def _rgb(path, frame: int | None = None) -> np.ndarray:
    with Image.open(path) as im:
        if frame is not None:
            im.seek(frame)
        return np.asarray(im.convert("RGB"), dtype=np.float64)


def _count(img: np.ndarray, color: np.ndarray, tol: float = 18.0) -> int:
    return int(np.all(np.abs(img - color) < tol, axis=-1).sum())


def _shades(img: np.ndarray, base: np.ndarray) -> tuple[int, int]:
    """Pixels of the left (dark) and of the right (light) shade of ``base``."""
    return _count(img, DARK * base), _count(img, base + LIGHT * (255.0 - base))


def _title_ink(img: np.ndarray, rows: int = 16) -> int:
    """Dark (text) pixels in the picture's top ``rows`` rows: the title, above the panels' labels."""
    return int(np.all(img[:rows] < 110, axis=-1).sum())


@pytest.fixture(autouse=True)
def _shipped(monkeypatch):
    monkeypatch.delenv("REFIMPL_PRETRAINED", raising=False)


def test_quaternet_prediction_strip_and_gif(tmp_path):
    """QuaterNet: left and right limbs in two shades of blue (truth) and red (prediction); title; tall GIF."""
    png, gif = tmp_path / "qn.png", tmp_path / "qn.gif"
    assert main(["generate", "--checkpoint", "pretrained:quaternet-cmu", "--source",
                 str(SAMPLE / "expmap" / "test" / "walking" / "walking_1.txt"), "--source-frame", "80",
                 "--length", "12", "--out", str(tmp_path / "p.bvh"), "--png", str(png), "--gif", str(gif)]) == EXIT_OK
    img = _rgb(png)
    for base in (BLUE, RED):
        left, right = _shades(img, base)
        assert left > 100 and right > 100, (base, left, right)  # old: one colour, no shades
    assert _title_ink(img) > 30
    with Image.open(gif) as im:
        last = im.n_frames - 1  # a predicted frame (the first 10 are context, green)
    frame = _rgb(gif, last)
    assert frame.shape[0] >= GIF_MIN_HEIGHT and min(_shades(frame, RED)) > 50
    assert _title_ink(frame, 20) > 30


def test_acrnn_synthesis_strip_has_shades_and_a_title(tmp_path):
    """acRNN: the strip (old: one blue, no title) and the GIF (old: 232 px tall, no title)."""
    png, gif = tmp_path / "ac.png", tmp_path / "ac.gif"
    assert main(["generate", "--model", "acrnn", "--checkpoint", "pretrained:acrnn-dq-salsa", "--source",
                 str(SAMPLE / "salsa" / "16.bvh"), "--length", "12", "--out", str(tmp_path / "s.bvh"),
                 "--png", str(png), "--gif", str(gif)]) == EXIT_OK
    img = _rgb(png)
    left, right = _shades(img, BLUE)
    assert left > 100 and right > 100, (left, right)
    assert _title_ink(img) > 30
    frame = _rgb(gif, 15)
    assert frame.shape[0] >= GIF_MIN_HEIGHT and _title_ink(frame, 20) > 30


def test_qtg_generate_png_has_a_title(tmp_path):
    """QTG: `generate --png` (old: no title) keeps its shades."""
    png = tmp_path / "t.png"
    assert main(["generate", "--checkpoint", "pretrained:qtg-cmu-sample", "--source",
                 str(SAMPLE / "bvh" / "02_01.bvh"), "--source-frame", "40", "--target",
                 str(SAMPLE / "bvh" / "01_01.bvh"), "--target-frame", "400", "--out", str(tmp_path / "t.bvh"),
                 "--png", str(png)]) == EXIT_OK
    img = _rgb(png)
    assert _title_ink(img) > 30
    left, right = _shades(img, BLUE)
    assert left > 100 and right > 100
