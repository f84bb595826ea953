"""Benchmark: time of one QTG transition (30 frames) in NumPy float32, and arithmetic per frame vs RTN.

Paper (Geleijn et al. 2021): 0.33 ms per 1-second (30-frame) transition on a 6-core Core i7-8700, and
≈ 80 % fewer arithmetic operations than RTN. What is measured here (spec/qtg.md §5-§6):

* ``rollout_inference`` (the lean path: pre-transposed contiguous float32 weights, no caches) for a 30-frame
  transition at batch 1 and batch 64, with the BLAS thread pool as configured and limited to 1 thread;
  median over ``--rounds`` rounds of the per-call time; at batch 64 also the time per transition;
* ``rollout_forward`` (the training path, with caches) at batch 1 for comparison;
* multiply-accumulates per generated frame of QTG (:func:`refimpl.models.qtg.macs_per_frame`) and RTN
  (:func:`refimpl.models.qtg.rtn_macs_per_frame`), and their ratio; parameters and weight bytes.

Target: ≤ 2 ms at batch 1 (reference/performance_facts.md: the physical limit on the 2-core development VM
is 0.6-0.8 ms, because every step streams ~2.1 MB of float32 weights from L3). The ONNX timings are
another benchmark's. A table is printed and JSON written to ``benchmarks/results/bench_qtg.json``.
Nothing asserts on time.

    python benchmarks/bench_qtg.py [--rounds 7] [--out PATH]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from refimpl.models.qtg import (QTGConfig, count_parameters, init_params, macs_per_frame,  # noqa: E402
                                rtn_macs_per_frame)
from refimpl.models.qtg_fast import prepare_inference, rollout_forward, rollout_inference  # noqa: E402

try:
    from threadpoolctl import threadpool_info, threadpool_limits
except ImportError:  # optional
    threadpool_info = threadpool_limits = None


def _time(fn, rounds: int, min_time: float = 0.2) -> float:
    """Median over ``rounds`` of the mean per-call time (seconds), each round at least ``min_time`` long."""
    fn()
    t0 = time.perf_counter()
    fn()
    one = max(time.perf_counter() - t0, 1e-6)
    reps = max(1, int(min_time / one))
    per_call = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        per_call.append((time.perf_counter() - t0) / reps)
    return statistics.median(per_call)


def _blas():
    if threadpool_info is None:
        return []
    return [{k: v for k, v in i.items() if k in ("internal_api", "version", "num_threads", "architecture")}
            for i in threadpool_info()]


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--T", type=int, default=30)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_qtg.json"))
    args = ap.parse_args(argv)

    cfg = QTGConfig()
    T = args.T
    rng = np.random.default_rng(0)
    params = init_params(cfg, rng, dtype=np.float32)
    model = prepare_inference(params, cfg)
    ctx = {b: (rng.standard_normal((b, 2, cfg.pose_size)).astype(np.float32),
               rng.standard_normal((b, 2, cfg.pose_size)).astype(np.float32)) for b in (1, 64)}

    rows = []

    def run(label, fn, batch, threads):
        if threads is not None and threadpool_limits is not None:
            with threadpool_limits(threads):
                t = _time(fn, args.rounds)
        else:
            t = _time(fn, args.rounds)
        rows.append({"case": label, "batch": batch, "blas_threads": threads or "default",
                     "ms_per_call": t * 1e3, "ms_per_transition": t * 1e3 / batch})

    for threads in (None, 1):
        for b in (1, 64):
            past, target = ctx[b]
            run("rollout_inference f32", lambda: rollout_inference(model, past, target, T), b, threads)
        past, target = ctx[1]
        run("rollout_forward f32 (training path)", lambda: rollout_forward(params, past, target, T, cfg), 1, threads)

    q, r = macs_per_frame(cfg), rtn_macs_per_frame(cfg.pose_size)
    ops = {"qtg_macs_per_frame": q, "rtn_macs_per_frame": r, "ratio": q / r, "reduction": 1 - q / r,
           "qtg_flops_per_transition": 2 * q * T, "parameters": count_parameters(cfg),
           "weight_bytes_float32": 4 * count_parameters(cfg)}
    result = {"benchmark": "bench_qtg", "T": T, "config": cfg.to_dict(), "timings": rows, "ops": ops,
              "paper": {"ms_per_transition": 0.33, "cpu": "Intel Core i7-8700 (6 cores)", "reduction_vs_rtn": 0.8},
              "target_ms_batch1": 2.0,
              "machine": {"platform": platform.platform(), "python": platform.python_version(),
                          "numpy": np.__version__, "cpu_count": os.cpu_count(),
                          "loadavg_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
                          "blas": _blas(),
                          "env": {k: os.environ.get(k) for k in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE",
                                                                 "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}}}

    print(f"QTG {T}-frame transition, NumPy float32 (median of {args.rounds} rounds; "
          f"1-min load average {result['machine']['loadavg_1min']})")
    print(f"{'case':38s} {'batch':>5s} {'BLAS threads':>12s} {'ms/call':>9s} {'ms/transition':>14s}")
    for row in rows:
        print(f"{row['case']:38s} {row['batch']:5d} {str(row['blas_threads']):>12s} {row['ms_per_call']:9.3f} "
              f"{row['ms_per_transition']:14.4f}")
    print(f"\nmultiply-accumulates per frame: QTG {q:,}  RTN {r:,}  ratio {q / r:.3f} "
          f"({100 * (1 - q / r):.1f} % fewer; paper ≈ 80 %)")
    print(f"parameters {ops['parameters']:,} ({ops['weight_bytes_float32'] / 1e6:.2f} MB float32); "
          f"paper: 0.33 ms per transition on a 6-core i7-8700; target here ≤ 2 ms at batch 1")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(".json.tmp")
    with open(tmp, "w") as f:
        json.dump(result, f, indent=2)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, out)
    print(f"wrote {out}")
    return result


if __name__ == "__main__":
    main()
