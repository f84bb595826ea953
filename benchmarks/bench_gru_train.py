"""Benchmark: one QuaterNet-sized GRU training iteration in NumPy (manual backprop), float32 (and float64).

What is timed (spec/layers.md §4.3; reference/performance_facts.md "Training iteration QuaterNet"):
a 2-layer GRU (input 128, hidden 1000, learned initial state (2, 1, 1000)), batch 32, 60 frames, teacher-forced,
a linear head 1000 -> 128 on every frame and an MSE loss; forward, backward, global gradient-norm clipping to 0.1
and one Adam step (``refimpl.optim``; if that module is absent they are left out and the table says so).
Matmul work: ~110 GFLOP per iteration (counted exactly below). The table gives milliseconds per phase and per
iteration (median of the timed iterations), the achieved GFLOP/s, the fraction of the machine's float32 GEMM
peak measured in the same run (a 2048^3 ``sgemm``), and the OpenBLAS kernel ("architecture" from
``threadpoolctl.threadpool_info()``) that ran. It also times Adam alone on the model's 9.5 M parameters and,
when ``torch`` is importable, the same iteration with ``torch.nn.GRU`` (ratio NumPy / torch).
Results are also written to ``benchmarks/results/bench_gru_train.json``.

Run it twice, once with the environment as it is (this project's machines set ``OPENBLAS_CORETYPE=Haswell`` and
``OPENBLAS_L2_SIZE=512``, which force OpenBLAS's AVX2 kernel) and once with OpenBLAS choosing its own kernel::

    python benchmarks/bench_gru_train.py
    env -u OPENBLAS_CORETYPE -u OPENBLAS_L2_SIZE python benchmarks/bench_gru_train.py

(each run overwrites the JSON file; the kernel is recorded in it). Options: ``--iters N`` (default 5),
``--no-float64`` (skip the float64 row), ``--threads N``
(limit the BLAS threads through threadpoolctl), ``--out PATH``. Run it on an otherwise idle machine: with other
processes competing for the 2 cores, OpenBLAS's two threads wait for each other on every small per-step GEMM
and a batch-32 step can become 10-50x slower (the 1-min load average is printed and recorded). This is a benchmark, not a test: nothing asserts on time.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

from refimpl.allocator import retain_freed_memory  # noqa: E402
from refimpl.nn.gru import gru_backward, gru_forward, gru_init  # noqa: E402
from refimpl.nn.linear import linear_backward, linear_forward, linear_init  # noqa: E402
from refimpl.nn.params import count_parameters, init_normal, merge_grads  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402

try:
    from refimpl.optim import adam_init, adam_step, clip_grad_norm  # noqa: E402
    HAVE_OPTIM = True
except ImportError:  # another module of the project; the benchmark still runs without it
    HAVE_OPTIM = False

B, T, I, H, L, O = 32, 60, 128, 1000, 2, 128
CLIP, LR = 0.1, 1e-3


def matmul_flops() -> int:
    """Exact matmul FLOPs of one iteration (2 per multiply-add): forward, backward of every GEMM."""
    n = B * T
    total = 0
    for k in range(L):
        in_k = I if k == 0 else H
        total += 3 * 2 * n * in_k * 3 * H  # input projection, dW_ih, dx
        total += 3 * 2 * n * H * 3 * H  # recurrent product, dW_hh, dh
    total += 3 * 2 * n * H * O  # head: forward, dW, dx
    return total


def blas_kernel() -> str:
    try:
        from threadpoolctl import threadpool_info
        infos = [d for d in threadpool_info() if d.get("user_api") == "blas"]
        return ", ".join(f"{d.get('internal_api')} {d.get('version')} {d.get('architecture')} "
                         f"({d.get('num_threads')} threads)" for d in infos) or "unknown"
    except ImportError:
        return "unknown (threadpoolctl not installed)"


def gemm_peak(dtype, n: int = 2048, reps: int = 5) -> float:
    """Best-of-``reps`` GFLOP/s of an n^3 GEMM in ``dtype``."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal((n, n)).astype(dtype)
    b = rng.standard_normal((n, n)).astype(dtype)
    c = np.empty((n, n), dtype)
    np.matmul(a, b, out=c)
    best = min(_timed(lambda: np.matmul(a, b, out=c)) for _ in range(reps))
    return 2 * n ** 3 / best / 1e9


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def make_model(dtype):
    rng = np.random.default_rng(0)
    params = gru_init(rng, I, H, L, "rnn", dtype=dtype)
    params.update(linear_init(rng, H, O, "fc", dtype=dtype))
    params["h0"] = init_normal(rng, (L, 1, H), 0.01, dtype=dtype)  # learned initial state (QuaterNet)
    x = rng.standard_normal((B, T, I)).astype(dtype)
    target = rng.standard_normal((B, T, O)).astype(dtype)
    return params, x, target


def numpy_iteration(params, x, target, opt_state, times: dict):
    """One training iteration; adds the seconds of each phase into ``times``."""
    t0 = time.perf_counter()
    h0 = np.broadcast_to(params["h0"], (L, B, H))
    y, _, cache = gru_forward(x, h0, params, "rnn", L)
    t1 = time.perf_counter()
    pred, hcache = linear_forward(y, params, "fc")
    diff = pred - target
    loss = float(np.mean(diff * diff))
    dpred = diff * diff.dtype.type(2.0 / diff.size)  # d mean(diff^2) / d pred
    dy, g_head = linear_backward(dpred, hcache)
    t2 = time.perf_counter()
    _, dh0, g_rnn = gru_backward(dy, None, cache)
    grads = merge_grads(g_rnn, g_head, {"h0": dh0.sum(axis=1, keepdims=True)})
    t3 = time.perf_counter()
    if HAVE_OPTIM:
        clip_grad_norm(grads, CLIP)
        t4 = time.perf_counter()
        adam_step(params, grads, opt_state, lr=LR)
        t5 = time.perf_counter()
    else:
        t4 = t5 = t3
    for k, v in (("gru forward", t1 - t0), ("head + MSE fwd/bwd", t2 - t1), ("gru backward", t3 - t2),
                 ("clip grad norm", t4 - t3), ("adam step", t5 - t4), ("iteration", t5 - t0)):
        times.setdefault(k, []).append(v)
    return loss


def bench_numpy(dtype, iters: int) -> dict:
    params, x, target = make_model(dtype)
    opt_state = adam_init(params) if HAVE_OPTIM else None
    warm: dict = {}
    numpy_iteration(params, x, target, opt_state, warm)  # warm-up (allocations, page faults)
    times: dict = {}
    losses = [numpy_iteration(params, x, target, opt_state, times) for _ in range(iters)]
    return {"n_params": count_parameters(params), "loss_first_last": [losses[0], losses[-1]],
            "ms_median": {k: 1e3 * statistics.median(v) for k, v in times.items()},
            "ms_min": {k: 1e3 * min(v) for k, v in times.items()}}


def bench_adam_alone(iters: int) -> dict | None:
    """Adam alone on the model's parameters: one and two threads interleaved, and the memory floor.

    The floor is the time to move Adam's minimum traffic (read p, g, m, v; write p, m, v in place: 28 bytes per
    float32 parameter) at the in-place streaming bandwidth measured in the same run (``a += b`` over two
    parameter-sized arrays, 12 bytes per element, the two halves done by two threads as the two-thread Adam runs).
    """
    if not HAVE_OPTIM:
        return None
    params, _, _ = make_model(np.float32)
    rng = np.random.default_rng(1)
    grads = {k: (1e-3 * rng.standard_normal(v.shape)).astype(np.float32) for k, v in params.items()}
    state = adam_init(params)
    adam_step(params, grads, state, lr=LR)
    n = count_parameters(params)
    a, b = np.ones(n, np.float32), np.zeros(n, np.float32)
    halves = [(a[:n // 2], b[:n // 2]), (a[n // 2:], b[n // 2:])]
    pool = ThreadPoolExecutor(max_workers=2)

    def stream2():  # a += b by halves: read a, b, write a
        list(pool.map(lambda ab: np.add(ab[0], ab[1], out=ab[0]), halves))
    ts = {1: [], 2: [], "stream": []}
    for _ in range(max(iters, 10)):
        for th in (1, 2):
            ts[th].append(_timed(lambda: adam_step(params, grads, state, lr=LR, threads=th)))
        ts["stream"].append(_timed(stream2))
    pool.shutdown()
    stream_gbs = 12 * n / min(ts["stream"]) / 1e9
    return {"n_params": n, "ms_median": 1e3 * statistics.median(ts[2]), "ms_min": 1e3 * min(ts[2]),
            "threads": 2, "one_thread_ms_median": 1e3 * statistics.median(ts[1]),
            "one_thread_ms_min": 1e3 * min(ts[1]), "stream_bandwidth_gb_s": stream_gbs,
            "memory_floor_ms": 28 * n / (stream_gbs * 1e9) * 1e3}


def bench_torch(iters: int, threads: int | None) -> dict | None:
    try:
        import torch
    except ImportError:
        return None
    torch.set_num_threads(threads or os.cpu_count() or 1)
    torch.manual_seed(0)
    gru = torch.nn.GRU(I, H, L, batch_first=True)
    fc = torch.nn.Linear(H, O)
    h0 = torch.nn.Parameter(torch.randn(L, 1, H) * 0.01)
    ps = list(gru.parameters()) + list(fc.parameters()) + [h0]
    opt = torch.optim.Adam(ps, lr=LR)
    x = torch.randn(B, T, I)
    target = torch.randn(B, T, O)

    def it():
        opt.zero_grad(set_to_none=True)
        y, _ = gru(x, h0.expand(L, B, H).contiguous())
        loss = torch.nn.functional.mse_loss(fc(y), target)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(ps, CLIP)
        opt.step()

    it()
    ts = [_timed(it) for _ in range(iters)]
    adam = {}  # torch.optim.Adam alone on the same parameters: default (for-loop), foreach and fused kernels
    for kind, kw in (("default", {}), ("foreach", {"foreach": True}), ("fused", {"fused": True})):
        try:
            o = torch.optim.Adam(ps, lr=LR, **kw)
        except (RuntimeError, TypeError, ValueError) as exc:  # a kernel this build lacks
            adam[kind] = f"unavailable: {exc}"
            continue
        o.step()
        ta = [_timed(o.step) for _ in range(max(iters, 10))]
        adam[kind] = {"ms_median": 1e3 * statistics.median(ta), "ms_min": 1e3 * min(ta)}
    return {"version": torch.__version__, "threads": torch.get_num_threads(),
            "ms_median": 1e3 * statistics.median(ts), "ms_min": 1e3 * min(ts), "adam_alone": adam}


def write_json_atomic(path: Path, obj) -> None:
    atomic_write_text(path, json.dumps(with_versions(obj), indent=2), make_parents=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iters", type=int, default=5)
    ap.add_argument("--no-float64", action="store_true")
    ap.add_argument("--threads", type=int, default=None,
                    help="limit the BLAS threads through threadpoolctl (default: the library's own setting)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bench_gru_train.json")
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    if args.threads is not None:
        from threadpoolctl import threadpool_limits
        threadpool_limits(limits=args.threads, user_api="blas")

    load_start = os.getloadavg()
    flop = matmul_flops()
    kernel = blas_kernel()
    env = {k: os.environ.get(k) for k in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE", "OPENBLAS_NUM_THREADS")}
    peak32 = gemm_peak(np.float32)
    peak64 = gemm_peak(np.float64)
    rows = {"float32": bench_numpy(np.float32, args.iters)}
    if not args.no_float64:
        rows["float64"] = bench_numpy(np.float64, max(2, args.iters // 2))
    adam = bench_adam_alone(args.iters)
    torch_row = bench_torch(args.iters, args.threads)

    load_end = os.getloadavg()
    print(f"GRU training iteration: {L}x GRU({I} -> {H}), head {H} -> {O}, batch {B}, {T} frames, "
          f"{flop / 1e9:.1f} GFLOP of matmuls per iteration")
    print(f"BLAS: {kernel}; env {env}")
    print(f"1-min load average at start / end: {load_start[0]:.1f} / {load_end[0]:.1f} on {os.cpu_count()} CPUs "
          "(other processes competing for the cores make every number below slower)")
    print(f"measured GEMM peak (2048^3): float32 {peak32:.0f} GFLOP/s, float64 {peak64:.0f} GFLOP/s")
    print("clip + Adam: " + ("included (refimpl.optim)" if HAVE_OPTIM else "EXCLUDED (refimpl.optim not found)"))
    phases = list(rows["float32"]["ms_median"])
    head = f"{'phase (median ms)':<22}" + "".join(f"{dt:>12}" for dt in rows)
    print(head)
    print("-" * len(head))
    for ph in phases:
        print(f"{ph:<22}" + "".join(f"{r['ms_median'][ph]:>12.1f}" for r in rows.values()))
    summary = {}
    for dt, r in rows.items():
        ms = r["ms_median"]["iteration"]
        gflops = flop / (ms / 1e3) / 1e9
        peak = peak32 if dt == "float32" else peak64
        summary[dt] = {"ms": ms, "gflops": gflops, "fraction_of_peak": gflops / peak}
        print(f"{dt}: {ms:.1f} ms/iteration (min {r['ms_min']['iteration']:.1f}), {gflops:.0f} GFLOP/s "
              f"= {100 * gflops / peak:.0f} % of the measured {dt} GEMM peak; {r['n_params']:,} parameters")
    if adam:
        print(f"Adam step alone, {adam['n_params']:,} float32 parameters: {adam['ms_median']:.1f} ms with 2 threads "
              f"(min {adam['ms_min']:.1f}), {adam['one_thread_ms_median']:.1f} ms with 1 (min "
              f"{adam['one_thread_ms_min']:.1f}); memory floor {adam['memory_floor_ms']:.1f} ms (28 B/parameter at "
              f"the {adam['stream_bandwidth_gb_s']:.0f} GB/s in-place streaming bandwidth measured here)")
    if torch_row:
        ratio = summary["float32"]["ms"] / torch_row["ms_median"]
        print(f"torch {torch_row['version']} ({torch_row['threads']} threads): "
              f"{torch_row['ms_median']:.1f} ms/iteration; NumPy / torch = {ratio:.2f}")
        ta = {k: (f"{v['ms_median']:.1f} ms" if isinstance(v, dict) else v) for k, v in torch_row["adam_alone"].items()}
        print("torch.optim.Adam alone (median): " + ", ".join(f"{k} {v}" for k, v in ta.items()))
    else:
        print("torch: not importable, no comparison")

    result = {"benchmark": "bench_gru_train", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "machine": {"platform": platform.platform(), "processor": platform.processor(), "cpus": os.cpu_count(),
                          "python": platform.python_version(), "numpy": np.__version__,
                          "loadavg_start": load_start, "loadavg_end": load_end},
              "blas_kernel": kernel, "env": env, "config": dict(B=B, T=T, I=I, H=H, L=L, O=O, clip=CLIP, lr=LR),
              "optim_included": HAVE_OPTIM, "matmul_gflop_per_iteration": flop / 1e9,
              "gemm_peak_gflops": {"float32": peak32, "float64": peak64}, "numpy": rows, "summary": summary,
              "adam_alone": adam, "torch": torch_row}
    write_json_atomic(args.out, result)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
