"""Tests of ``refimpl demo`` (spec/cli.md §9): the quick demo end to end, its files, determinism, skips."""
from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from refimpl.cli import EXIT_OK, main
from refimpl.demo import QUICK_STEPS, run_demo
from refimpl.services import load_trained


def _png_ok(path) -> None:
    from PIL import Image

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", path
    with Image.open(path) as im:
        img = np.asarray(im.convert("RGB"), dtype=np.float64)
    assert img.shape[0] > 150 and img.shape[1] > 300, (path, img.shape)
    assert img.var() > 0, path


def _onnxruntime_available() -> bool:
    try:
        import onnxruntime  # noqa: F401

        import deploy.models.qtg  # noqa: F401
    except ImportError:
        return False
    return True


def test_quick_demo_end_to_end(tmp_path, capsys):
    """spec/cli.md §9: `refimpl demo --quick` trains, evaluates, exports, verifies, generates and renders."""
    from refimpl.bvh import read_bvh

    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out)]) == EXIT_OK
    stdout = capsys.readouterr().out
    for step in range(1, 8):
        assert f"[{step}/7]" in stdout
    assert "done in" in stdout and str(out) in stdout

    model = load_trained(out / "train" / "checkpoint.npz")
    assert model.meta["step"] == QUICK_STEPS
    assert len((out / "train" / "loss.csv").read_text().splitlines()) == QUICK_STEPS + 1
    results = json.loads((out / "eval.json").read_text())
    assert set(results) == {"qtg", "qtg+join", "qtg+join+footlock", "inertialization", "interpolation", "versions",
                            "run"}
    assert results["versions"]["numpy"] == np.__version__ and "kernel" in results["versions"]["blas"]
    q = results["qtg+join"]["quality"]
    for key in ("join_in_cm", "join_out_cm", "skate_cm_s", "first_frame_cm", "last_frame_cm", "ground_truth"):
        assert key in q
    assert "Joins (mean joint displacement" in stdout and "joins in/out" in stdout
    assert len(results["qtg"]["per_frame_cm"]) == 30
    assert len((out / "eval_per_frame.csv").read_text().splitlines()) == 31

    for name in ("heldout_qtg", "heldout_qtg_join", "heldout_truth", "walk_to_run", "walk_to_run_join"):
        motion = read_bvh(out / f"{name}.bvh")
        assert motion.num_joints == 27  # 22 joints + 5 End Sites
        assert motion.fps == pytest.approx(30.0, rel=1e-4)
    assert read_bvh(out / "heldout_qtg.bvh").num_frames == 10 + 30 + 10
    assert read_bvh(out / "walk_to_run.bvh").num_frames == 15 + 30 + 15

    if _onnxruntime_available():
        for role in ("init", "step", "rollout"):
            assert (out / "onnx" / f"qtg_{role}.onnx").stat().st_size > 1000
        assert "max |diff|" in stdout and "-> OK" in stdout
        a = read_bvh(out / "heldout_qtg.bvh").positions()
        b = read_bvh(out / "heldout_qtg_onnx.bvh").positions()
        assert np.abs(a - b).max() < 1e-2  # cm; BVH files keep 6 decimals
    else:
        assert "skipped" in stdout and "refimpl[deploy]" in stdout

    pytest.importorskip("matplotlib")
    for name in ("heldout_strip", "heldout_join_strip", "walk_to_run", "walk_to_run_join", "loss", "error_curve"):
        _png_ok(out / f"{name}.png")
    for name in ("heldout", "walk_to_run"):
        assert (out / f"{name}.gif").read_bytes()[:3] == b"GIF"


@pytest.mark.slow
def test_demo_is_deterministic_and_skips_without_onnxruntime(tmp_path, monkeypatch):
    """spec/cli.md §9: the same seed gives the same parameters and results; a missing onnxruntime is skipped
    with a message, not an error."""
    lines = []
    a = run_demo(tmp_path / "a", seed=3, quick=True, steps=3, onnx=False, render=False, say=lines.append)
    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    b = run_demo(tmp_path / "b", seed=3, quick=True, steps=3, onnx=True, render=False, say=lines.append)
    assert a.verify is None and b.verify is None
    assert any("refimpl[deploy]" in s for s in b.skipped)
    assert not (tmp_path / "b" / "onnx").exists()
    pa, pb = load_trained(a.files["checkpoint"]).params, load_trained(b.files["checkpoint"]).params
    assert pa.keys() == pb.keys()
    for k in pa:
        np.testing.assert_array_equal(pa[k], pb[k], err_msg=k)
    for method in a.results:
        np.testing.assert_array_equal(a.results[method]["per_frame_cm"], b.results[method]["per_frame_cm"])
    assert (tmp_path / "a" / "heldout_qtg.bvh").read_bytes() == (tmp_path / "b" / "heldout_qtg.bvh").read_bytes()
