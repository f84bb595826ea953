"""benchmarks/bench_cost.py (issue #33 item 5): the multiply-add counter against the models' own counts, the limit
arithmetic, and a smoke run of the whole table at tiny sizes (the JSON's fields, versions, load and ratios)."""
from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

import onnx  # noqa: E402

from tests.test_bench_all import _load  # noqa: E402  (benchmarks/ is not a package)
from deploy.models.quaternet_long import PACE_CHUNK  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def bc():
    return _load("bench_cost")


@pytest.fixture(scope="module")
def exported(bc):
    """``{model: (params, config, {target: (graph, frames per call, sizes)})}`` of the tiny models."""
    bp = bc._load_portable()
    tmp = Path(tempfile.mkdtemp(prefix="bench_cost_"))
    out = {}
    for name in bc.LABELS:
        params, cfg, _ = bp.make_model(name, quick=True)
        graphs = {}
        for t in ("default", "portable"):
            bp.export_model(name, tmp / name / t, t, True)
            graphs[t] = bc._frame_graph(bp, name, tmp / name / t, t)
        out[name] = (params, cfg, graphs)
    return out


def test_graph_macs_equal_the_models_counts(bc, exported):
    """QTG's step graph counts ``macs_per_frame``; a recurrent step at batch 1 uses each weight matrix once, so its
    count is at least the 2-D weights (the QuaterNets and acRNN add the small products of their quaternion
    normalisation); today's and the portable graphs count the same work per frame, but the pace network's portable
    graph twice (its two GRU directions advance together with block-diagonal weights: the zero blocks count too)."""
    from refimpl.models import qtg

    for name, (params, cfg, graphs) in exported.items():
        counts = {t: bc.graph_macs(onnx.load(str(p)), sizes) / per for t, (p, per, sizes) in graphs.items()}
        assert counts["portable"] == (2 if name == "pace" else 1) * counts["default"], (name, counts)
        if name == "qtg":
            assert counts["default"] == qtg.macs_per_frame(cfg)
        elif name != "quaternet-cnn":
            w2 = sum(v.size for v in params.values() if np.ndim(v) == 2)
            assert w2 <= counts["default"] <= 1.06 * w2, (name, counts, w2)


def test_graph_macs_of_a_conv_and_a_gru_node(bc):
    """Hand-built graphs: Conv (outputs × C_in/groups × k) and GRU (T·D·3H(I + H)) counted by their formulas."""
    from onnx import TensorProto, helper, numpy_helper

    w = numpy_helper.from_array(np.zeros((6, 4, 3), np.float32), "w")
    conv = helper.make_graph([helper.make_node("Conv", ["x", "w"], ["y"])], "c",
                             [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["B", 4, 10])],
                             [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)], [w])
    m = helper.make_model(conv, opset_imports=[helper.make_opsetid("", 17)])
    assert bc.graph_macs(m, {"B": 2}) == 2 * 6 * 8 * 4 * 3
    W = numpy_helper.from_array(np.zeros((1, 15, 7), np.float32), "W")
    R = numpy_helper.from_array(np.zeros((1, 15, 5), np.float32), "R")
    gru = helper.make_graph([helper.make_node("GRU", ["x", "W", "R"], ["y"], hidden_size=5)], "g",
                            [helper.make_tensor_value_info("x", TensorProto.FLOAT, [3, 1, 7])],
                            [helper.make_tensor_value_info("y", TensorProto.FLOAT, None)], [W, R])
    m = helper.make_model(gru, opset_imports=[helper.make_opsetid("", 17)])
    assert bc.graph_macs(m) == 3 * 1 * 15 * (7 + 5)


def test_frame_limit_is_the_slower_of_memory_and_compute(bc):
    probe = {"stream_gb_s": 20.0, "gemm_gflop_s": 100.0}
    lim = bc.frame_limit_us(40e6, 1e6, probe)  # 40 MB at 20 GB/s = 2000 µs; 2 MFLOP at 100 GF/s = 20 µs
    assert lim["memory_us"] == pytest.approx(2000.0) and lim["compute_us"] == pytest.approx(20.0)
    assert lim["limit_us"] == pytest.approx(2000.0) and lim["bound"] == "memory"
    assert bc.frame_limit_us(1e3, 1e9, probe)["bound"] == "compute"


def test_smoke_run_writes_the_table_and_its_json(bc, tmp_path, capsys):
    """Two tiny models, one round: every column is there, with versions, load and ratios."""
    out = tmp_path / "cost.json"
    bc.main(["--quick", "--rounds", "1", "--min-time", "0.002", "--models", "qtg", "pace", "--out", str(out)])
    text = capsys.readouterr().out
    assert "QTG" in text and "long-term pace" in text and "probes:" in text
    r = json.loads(out.read_text())
    assert set(r["rows"]) == {"qtg", "pace"}
    for key in ("numpy", "onnxruntime", "python", "machine", "blas", "load_average_before", "load_average_after"):
        assert key in r["env"]
    q = r["rows"]["qtg"]
    assert q["parameters"] == 5451 and q["int8_file_bytes"] > 0 and q["macs_per_frame"] == 5216
    assert set(q["times"]) == {f"{k}_{t}thr" for k in ("ort_default", "ort_portable", "numpy") for t in (1, 2)}
    assert all(v["median_us"] > 0 for v in q["times"].values())
    assert q["limit"]["1"]["limit_us"] > 0 and q["ratios"]["ort_portable_1thr/ort_default_1thr"] > 0
    assert r["rows"]["pace"]["frames_per_call"] == {"default": 200, "portable": PACE_CHUNK}


def test_the_readme_table_is_the_results_file(bc):
    """deploy/README.md's cost table is ``--markdown`` of benchmarks/results/bench_cost.json, number for number."""
    result = json.loads((ROOT / "benchmarks" / "results" / "bench_cost.json").read_text())
    assert result["sizes"] == "paper"
    assert bc.markdown(result) in (ROOT / "deploy" / "README.md").read_text()
