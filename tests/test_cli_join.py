"""The join option and the animator's measures on the command line (spec/cli.md §5-§7, spec/qtg.md §7.4, §9.1):
``refimpl eval --join``, ``refimpl export --join``, ``refimpl generate --join``."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from refimpl.cli import EXIT_OK, EXIT_USAGE, main

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"
WALK_BVH = SAMPLE / "bvh" / "02_01.bvh"
TINY = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]
DATA = ["--data", str(WALK_BVH), "--stride", "8", "--test-fraction", "0.5"]


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    out = tmp_path_factory.mktemp("train_join")
    assert main(["train", *DATA, "--out", str(out), "--steps", "3", "--batch-size", "8", *TINY]) == EXIT_OK
    return out / "checkpoint.npz"


def test_eval_join_rows_and_quality_json(capsys, ckpt, tmp_path):
    js = tmp_path / "res.json"
    code, out, _ = _run(capsys, "eval", "--checkpoint", ckpt, *DATA, "--join", "inertialize", "--json", js)
    assert code == EXIT_OK
    assert "\nqtg+join " in out and "Joins (mean joint displacement" in out and "ground truth" in out
    res = json.loads(js.read_text())
    assert list(res) == ["inertialization", "interpolation", "qtg", "qtg+join"]  # sorted keys
    q, g = res["qtg+join"]["quality"], res["qtg"]["quality"]["ground_truth"]
    assert set(q) >= {"join_in_cm", "join_out_cm", "join_in_ratio", "join_out_ratio", "skate_cm_s",
                      "contact_share", "first_frame_cm", "last_frame_cm", "ground_truth", "contact_rule"}
    assert abs(q["join_out_cm"] / g["join_out_cm"] - 1) < 0.5  # the joined network arrives like the truth
    code, _, err = _run(capsys, "eval", "--checkpoint", ckpt, *DATA, "--join", "smooth")
    assert code == EXIT_USAGE and "--join" in err


def test_export_and_generate_with_join(capsys, ckpt, tmp_path):
    pytest.importorskip("onnxruntime")
    from refimpl.bvh import read_bvh
    from refimpl.services import onnx_metadata

    onnx_dir = tmp_path / "onnx"
    code, out, _ = _run(capsys, "export", "--checkpoint", ckpt, "--out", onnx_dir, "--join", "inertialize")
    assert code == EXIT_OK and "max |diff|" in out  # verified against NumPy's join
    assert onnx_metadata(onnx_dir)["join"]["mode"] == "inertialize"
    code, out, _ = _run(capsys, "eval", "--checkpoint", ckpt, *DATA, "--onnx", onnx_dir, "--join", "inertialize",
                        "--json", tmp_path / "r.json")
    assert code == EXIT_OK
    res = json.loads((tmp_path / "r.json").read_text())
    assert abs(res["qtg_onnx+join"]["mean_cm"] - res["qtg+join"]["mean_cm"]) < 1e-2

    a, b = tmp_path / "a.bvh", tmp_path / "b.bvh"
    for path, backend in ((a, ["--checkpoint", ckpt, "--join", "inertialize"]), (b, ["--backend", "onnx", "--onnx",
                                                                                   onnx_dir])):
        code, out, _ = _run(capsys, "generate", *backend, "--source", WALK_BVH, "--source-frame", 20, "--out", path,
                            "--context", 5)
        assert code == EXIT_OK
    assert "qtg+join" in _run(capsys, "generate", "--checkpoint", ckpt, "--join", "inertialize", "--source",
                              WALK_BVH, "--source-frame", 20, "--out", tmp_path / "c.bvh", "--context", 5)[1]
    ma, mb = read_bvh(a), read_bvh(b)
    root = ma.root_positions  # (F, 3) world; frames 0-4 source (s-4 .. s), 5-34 generated, 35-39 target
    np.testing.assert_allclose(root[5], 2 * root[4] - root[3], atol=1e-4)  # frame 1 continues the past
    np.testing.assert_allclose(root[34], 2 * root[35] - root[36], atol=1e-4)  # frame T leads into the target
    assert np.abs(ma.positions() - mb.positions()).max() < 1e-2  # NumPy join = the graph's join (cm)


def test_results_json_is_strict():
    """Skating without a single contact is NaN in Python and null in the JSON file (strict JSON, spec/cli.md §5)."""
    from refimpl.tasks.transition_report import results_json

    text = results_json({"m": {"quality": {"skate_cm_s": float("nan"), "by_label": {"walk": {"skate_cm_s": 3.0}}},
                                "per_frame_cm": np.array([1.0, np.nan])}})
    assert json.loads(text)["m"] == {"quality": {"skate_cm_s": None, "by_label": {"walk": {"skate_cm_s": 3.0}}},
                                     "per_frame_cm": [1.0, None]}
