"""benchmarks/bench_all.py (issue #17's table) and benchmarks/bench_quaternet_cnn.py: the parts that are not timing."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load(name):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


PEAKS = {"gemm_f32_gflops_1thr": 100.0, "gemm_f32_gflops_2thr": 200.0, "copy_gb_s_1thr": 20.0,
         "copy_gb_s_2thr": 30.0, "gemv_floor_ms_qtg_step_2.15MB_1thr": 0.04, "gemv_floor_ms_qtg_step_2.15MB_2thr": 0.03,
         "gemv_floor_ms_gru2x1000_step_37.5MB_1thr": 1.0, "gemv_floor_ms_gru2x1000_step_37.5MB_2thr": 0.6}


def test_rows_ratios_limits_and_missing_fields(tmp_path):
    """Rows come from the benchmarks' JSON; limits from the peaks; absent files are reported as missing."""
    ba = _load("bench_all")
    (tmp_path / "bench_adam.json").write_text(json.dumps({
        "n_params": 1_000_000, "bytes_per_param": 28, "torch_threads": 2,
        "summary": {"numpy_2threads": {"median": 3.0}, "torch_fused": {"median": 2.0},
                    "numpy_over_torch_fused": {"median": 1.4}, "twelve_adds_over_torch_fused": {"median": 1.35}}}))
    (tmp_path / "bench_gru_train.json").write_text(json.dumps({
        "config": {"B": 32, "T": 60}, "matmul_gflop_per_iteration": 100.0,
        "numpy": {"float32": {"ms_median": {"iteration": 1000.0}}}, "torch": {"ms_median": 1250.0, "threads": 2}}))
    (tmp_path / "bench_qtg_train.json").write_text(json.dumps({"train": {
        "batch": 32, "T": 30, "threads": 2, "rounds": [{"numpy_ms": 40.0, "torch_ms": 58.0}],
        "numpy_over_torch": {"median": 0.69}, "products_over_torch": {"median": 0.43}}}))
    (tmp_path / "bench_lstm_train.json").write_text(json.dumps({
        "config": {"B": 32, "T": 100, "acrnn": {"matmul_gflop": 400.0}}, "threads": 2,
        "matmul_gflop_per_iteration": 427.0,
        "summary": {"seconds.numpy_fast": {"median": 3.2}, "seconds.torch": {"median": 2.7},
                    "fast_over_torch": {"median": 1.18}, "seconds.acrnn_numpy": {"median": 4.1},
                    "seconds.acrnn_torch": {"median": 8.5}, "acrnn_numpy_over_torch": {"median": 0.48}}}))
    (tmp_path / "bench_long_term.json").write_text(json.dumps({"threads": 2, "cases": {
        "long_term_training": {"batch": 40, "prefix": 30, "target": 60, "matmul_gflop": 300.0, "summary": {
            "numpy": {"median": 1500.0}, "torch": {"median": 1700.0}, "numpy_over_torch": {"median": 0.88}}},
        "pace_training": {"batch": 40, "chunk": 377, "summary": {
            "numpy": {"median": 88.0}, "torch": {"median": 146.0}, "numpy_over_torch": {"median": 0.6}}}}}))
    rows = {r["workload"].split(" (")[0].split(",")[0]: r for r in ba.rows_from(tmp_path, PEAKS)}
    lt = rows["QuaterNet long-term training iteration"]
    assert lt["numpy_ms"] == 1500.0 and lt["ratio"] == 0.88 and lt["limit_ms"] == pytest.approx(300.0 / 200.0 * 1e3)
    assert rows["pace network training iteration"]["ratio"] == 0.6
    ac = rows["acRNN training iteration"]
    assert ac["numpy_ms"] == 4100.0 and ac["torch_ms"] == 8500.0 and ac["ratio"] == 0.48
    assert ac["limit_ms"] == pytest.approx(400.0 / 200.0 * 1e3)
    assert rows["LSTM 3×1024 sequence training iteration"]["ratio"] == 1.18
    qtg = rows["QTG training step"]
    assert qtg["numpy_ms"] == 40.0 and qtg["ratio"] == 0.69 and qtg["goal"] == 0.5
    assert qtg["limit_ms"] == pytest.approx(6 * 636416 * 32 * 30 / 1e9 / 200.0 * 1e3)
    assert "its matrix products alone / PyTorch 0.43×" in qtg["note"]
    assert qtg["share_needed_for_goal"] == pytest.approx(qtg["limit_ms"] / 58.0 / 0.5)
    adam = rows["Adam"]
    assert adam["numpy_ms"] == 3.0 and adam["torch_ms"] == 2.0 and adam["ratio"] == 1.4 and adam["ratio_paired"]
    assert adam["limit_ms"] == pytest.approx(28 * 1e6 / 30e9 * 1e3)                     # bytes / bandwidth
    assert adam["share_of_limit"] == pytest.approx(adam["limit_ms"] / 3.0)
    assert "12 np.add passes alone / fused 1.35×" in adam["note"]
    gru = rows["QuaterNet GRU 2×1000 training iteration"]
    assert gru["ratio"] == pytest.approx(0.8) and not gru["ratio_paired"]
    assert gru["limit_ms"] == pytest.approx(100.0 / 200.0 * 1e3)                      # GFLOP / 2-thread peak
    # PyTorch takes 1250 ms for a 500 ms limit (40 %): NumPy at 0.6 x PyTorch would need 40 / 0.6 = 67 %
    assert gru["torch_share_of_limit"] == pytest.approx(0.4)
    assert gru["share_needed_for_goal"] == pytest.approx(0.4 / 0.6)
    assert "PyTorch at 40 % of the limit, so ≤ 0.6× needs 67 %" in gru["note"]
    assert any(r["missing"] for r in rows.values())                                     # the absent benchmarks
    text = ba.table(list(rows.values()), PEAKS, {"start": (1.0, 1.0, 1.0)})
    assert "| Adam" in text and "missing: bench_onnx.json" in text and "~0.80" in text


def test_command_uses_only_the_options_a_benchmark_has(tmp_path):
    ba = _load("bench_all")
    args = SimpleNamespace(rounds=2, threads=2, onnx_train_steps=0)
    cmd = ba.command("adam", args, "usage: [--rounds ROUNDS] [--threads THREADS] [--out OUT]\n", tmp_path)
    assert cmd[2:] == ["--rounds", "2", "--threads", "2", "--out", str(tmp_path / "bench_adam.json")]
    cmd = ba.command("locomotion", args, "usage: [--rounds ROUNDS]\n", tmp_path)
    assert cmd[2:] == ["--rounds", "2"]
    cmd = ba.command("qtg", args, "usage: [--train] [--train-rounds N] [--rounds R] [--out OUT]\n", tmp_path)
    assert cmd[2:5] == ["--train", "--train-rounds", "2"]


def test_work_counts():
    """QuaterNet's GRU 2×1000 is 19.0 MFLOP per frame (performance_facts.md); the CNN iteration's count."""
    ba, bc = _load("bench_all"), _load("bench_quaternet_cnn")
    assert 2 * ba.gru_macs_per_frame(128, 1000, 2, 128) == pytest.approx(19.0e6, rel=2e-3)
    from refimpl.models.quaternet_cnn import QuaterNetCNNConfig
    cfg = QuaterNetCNNConfig()
    per_frame = 2 * (128 * 1024 + 3 * 1024 * 1024 + 1024 * 128)                      # MACs, K = 2 taps
    no_dx0 = per_frame - 2 * 128 * 1024
    mask = np.ones(9, bool)
    assert bc.matmul_gflop(cfg, 60, 41, 32, 10, mask) == pytest.approx(2 * 60 * 41 * (2 * per_frame + no_dx0) / 1e9)
    mask[-2:] = False                                                                  # + two windows of R frames
    assert bc.matmul_gflop(cfg, 60, 41, 32, 10, mask) == pytest.approx(
        2 * (60 * 41 * (2 * per_frame + no_dx0) + 60 * 64 * per_frame) / 1e9)


def test_cnn_benchmark_loss_gradient():
    """The benchmark's loss cotangents equal central differences (float64)."""
    bc = _load("bench_quaternet_cnn")
    rng = np.random.default_rng(0)
    y, pre, fut = (rng.standard_normal((2, 3, 8)) for _ in range(3))
    _, dy, dpre = bc._numpy_loss(y, pre, fut, 2)
    for arr, grad in ((y, dy), (pre, dpre)):
        for idx in [(0, 0, 0), (1, 2, 7), (0, 1, 3)]:
            old = arr[idx]
            arr[idx] = old + 1e-6
            up = bc._numpy_loss(y, pre, fut, 2)[0]
            arr[idx] = old - 1e-6
            down = bc._numpy_loss(y, pre, fut, 2)[0]
            arr[idx] = old
            assert grad[idx] == pytest.approx((up - down) / 2e-6, rel=1e-6, abs=1e-9)


def test_cnn_benchmark_matches_pytorch_small():
    """The PyTorch side of the CNN benchmark computes the same iteration (float64, a small network)."""
    torch = pytest.importorskip("torch")
    bc = _load("bench_quaternet_cnn")
    from refimpl.models import quaternet_cnn as cnn
    cfg = cnn.QuaterNetCNNConfig(num_joints=3, channels=16)
    params = cnn.init_params(cfg, np.random.default_rng(0), dtype=np.float64)
    prefix, future, mask = bc._data(cfg, 2, cfg.receptive_field, 10, 3)
    old = torch.get_default_dtype()
    torch.set_default_dtype(torch.float64)
    try:
        chk = bc.check(torch, params, cfg, prefix.astype(np.float64), future.astype(np.float64), mask)
    finally:
        torch.set_default_dtype(old)
    assert chk["loss_rel"] < 1e-12 and chk["y_max_rel"] < 1e-12 and chk["grads_max_rel"] < 1e-10
