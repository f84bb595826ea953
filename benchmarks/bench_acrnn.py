"""Benchmark: acRNN at the paper's size (3 × 1024 LSTM, F = 251: dual quaternions on CMU's 31 joints).

1. **Step, batch 1** (the online use; spec/acrnn.md §8, spec/deploy.md §8.2): :func:`refimpl.models.acrnn.step`
   in NumPy float32, the exported ``acrnn_step.onnx`` in onnxruntime (float32, standardisation and the dual-quaternion
   decoding in the graph), and PyTorch (three ``nn.LSTMCell`` + ``nn.Linear`` float32, as acRNN's code steps, when torch is installed),
   interleaved round by round; median per-call time and ratios to NumPy.
2. **Training iteration** (``--train``): one auto-conditioned forward + backward of a batch of 32 windows of
   100 + 1 frames, float32 (:func:`refimpl.models.acrnn.sequence_forward` / ``sequence_backward``). The fast path
   once compared here (``acrnn_fast``) measured 1.12x and was removed (benchmarks/README.md).

All with one thread (BLAS, onnxruntime intra-op, torch). A table is printed and JSON written to
``benchmarks/results/bench_acrnn.json``. Nothing asserts on time; the machine is shared (±25-40 %).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_acrnn.py [--rounds 7] [--train] [--train-hidden 1024]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

from refimpl.allocator import retain_freed_memory  # noqa: E402
from refimpl.models import acrnn  # noqa: E402


def _per_call(fn, min_time=0.3):
    fn()
    t0 = time.perf_counter()
    fn()
    one = max(time.perf_counter() - t0, 1e-6)
    reps = max(1, int(min_time / one))
    t0 = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t0) / reps


def bench_step(rounds: int, hidden: int, frame_size: int) -> dict:
    cfg = acrnn.ACRNNConfig(frame_size=frame_size, hidden_size=hidden)
    rng = np.random.default_rng(0)
    params = acrnn.init_params(cfg, rng, np.float32)
    mean, std = np.zeros(frame_size), np.ones(frame_size)
    x = rng.standard_normal((1, frame_size)).astype(np.float32)
    state = acrnn.init_state(cfg, 1, np.float32)
    variants = {"numpy": lambda: acrnn.step(params, cfg, x, state)}
    try:
        from deploy.models.acrnn import export_acrnn_step
        from deploy.session import make_session

        sess = make_session(export_acrnn_step(params, cfg, mean=mean, std=std, representation="dual_quaternions"),
                            intra_op_threads=1)
        feeds = {"frame": x, "h": state[0], "c": state[1]}
        variants["onnxruntime"] = lambda: sess.run(None, feeds)
    except ImportError as exc:
        print(f"onnxruntime variant skipped: {exc}")
    try:
        import torch

        torch.set_num_threads(1)
        # three nn.LSTMCell, as acRNN's published code steps its network
        cells = [torch.nn.LSTMCell(frame_size if k == 0 else hidden, hidden) for k in range(3)]
        dec = torch.nn.Linear(hidden, frame_size)
        with torch.no_grad():
            for k, cell in enumerate(cells):
                for n in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"):
                    getattr(cell, n).copy_(torch.from_numpy(params[f"lstm.{n}_l{k}"]))
            dec.weight.copy_(torch.from_numpy(params["decoder.weight"]))
            dec.bias.copy_(torch.from_numpy(params["decoder.bias"]))
        tx = torch.from_numpy(x)
        th = [torch.from_numpy(state[0][k]) for k in range(3)]
        tc = [torch.from_numpy(state[1][k]) for k in range(3)]

        def torch_step():
            with torch.no_grad():
                inp = tx
                for k, cell in enumerate(cells):
                    inp, _ = cell(inp, (th[k], tc[k]))
                return dec(inp)

        variants["torch"] = torch_step
        ref = acrnn.step(params, cfg, x, state)[0]
        assert np.allclose(torch_step().numpy(), ref, atol=1e-4)
    except ImportError:
        print("torch variant skipped (not installed)")
    times = {k: [] for k in variants}
    for _ in range(rounds):
        for k, fn in variants.items():                    # interleaved
            times[k].append(_per_call(fn))
    med = {k: statistics.median(v) for k, v in times.items()}
    return {"hidden": hidden, "frame_size": frame_size, "rounds": rounds,
            "median_ms": {k: 1e3 * v for k, v in med.items()},
            "ratio_to_numpy": {k: v / med["numpy"] for k, v in med.items()}}


def bench_train(rounds: int, hidden: int, frame_size: int, batch: int = 32, length: int = 100) -> dict:
    cfg = acrnn.ACRNNConfig(frame_size=frame_size, hidden_size=hidden)
    rng = np.random.default_rng(0)
    params = acrnn.init_params(cfg, rng, np.float32)
    x = rng.standard_normal((batch, length + 1, frame_size)).astype(np.float32)
    d = rng.standard_normal((batch, length, frame_size)).astype(np.float32)

    times = []
    for r in range(rounds):
        t0 = time.perf_counter()
        pred, cache = acrnn.sequence_forward(params, cfg, x)
        acrnn.sequence_backward(d, cache)
        times.append(time.perf_counter() - t0)
        print(f"  train round {r}: {times[-1]:.2f} s", flush=True)
    return {"hidden": hidden, "frame_size": frame_size, "batch": batch, "length": length, "rounds": rounds,
            "seconds": times, "median_s": statistics.median(times)}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--hidden", type=int, default=1024)
    ap.add_argument("--frame-size", type=int, default=251)
    ap.add_argument("--train", action="store_true", help="also time one training iteration")
    ap.add_argument("--train-rounds", type=int, default=1)
    ap.add_argument("--train-hidden", type=int, default=1024)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_acrnn.json"))
    a = ap.parse_args()
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    res = {"step_batch1": bench_step(a.rounds, a.hidden, a.frame_size), "load_average": os.getloadavg()}
    s = res["step_batch1"]
    print(f"step, batch 1, 3 x {a.hidden} LSTM, F = {a.frame_size}, float32, 1 thread (median of {a.rounds}; load average {os.getloadavg()[0]:.1f}):", flush=True)
    for k, v in s["median_ms"].items():
        print(f"  {k:12s} {v:8.3f} ms   x{s['ratio_to_numpy'][k]:.2f} of numpy")
    if a.train:
        res["train_iteration"] = bench_train(a.train_rounds, a.train_hidden, a.frame_size)
        t = res["train_iteration"]
        print(f"training iteration (B 32, T 100, 3 x {a.train_hidden}): median {t['median_s']:.2f} s")
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(with_versions(res), indent=2) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
