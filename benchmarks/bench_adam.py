"""Benchmark: one Adam step on QuaterNet's 9.5 M float32 parameters, NumPy vs PyTorch, and the memory floor.

Variants, interleaved in every round (order rotated between rounds, 0.15 s of settling between variants):

* ``numpy_2threads``: ``refimpl.optim.adam_step`` as called by training (2 threads for a model this size);
* ``numpy_1thread``: the same with ``threads=1``;
* ``numpy_block_32768``: the same with L2-sized blocks of 32,768 elements (p, g, m, v blocks = 512 KiB);
* ``numpy_naive``: ``_adam_step_naive``, torch's formulas on whole arrays with temporaries (the oracle);
* ``numpy_12_adds``: ``adam_step``'s machinery (blocks, threads, scratch, validation) with its 12 ufunc passes per
  block replaced by 12 ``np.add`` passes on the same operands (no sqrt, no division): the floor of any NumPy Adam
  that makes 12 passes, as ``twelve_adds_over_torch_fused`` (not an Adam: its numbers are thrown away);
* ``torch_fused``, ``torch_foreach``, ``torch_default``: ``torch.optim.Adam`` with ``fused=True``,
  ``foreach=True`` and the default (single-tensor loop on CPU), when ``torch`` is importable.

Each variant takes ``--steps`` consecutive steps per round; its round time is their median. Ratios to
``torch_fused`` are paired per round and reported as ranges: absolute times on this shared 2-vCPU machine drift
by ±25-40 % within minutes.

Memory floor: a step must read p, g, m, v and write p, m, v (28 bytes per float32 parameter). The streaming
bandwidth is measured in the same rounds with the same access pattern on arrays far larger than the 32 MiB L3
(``a += b`` on two 160 MB arrays, halves on two threads: 12 bytes per element, in-place so no write-allocate
traffic), floor = 28 B x parameters / bandwidth. ``torch_fused`` (one compiled pass) is the practical floor.

Checks before timing: one step of ``adam_step`` with 1 and 2 threads is bit-identical, and agrees with
``torch.optim.Adam(fused=True)`` from the same state to float32 rounding.

Usage: ``python benchmarks/bench_adam.py [--rounds 5] [--steps 5] [--out PATH]``; writes
``benchmarks/results/bench_adam.json`` atomically. A benchmark, not a test: nothing asserts on time.
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

import refimpl.optim as optim  # noqa: E402
from refimpl.allocator import retain_freed_memory  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.nn.gru import gru_init  # noqa: E402
from refimpl.nn.linear import linear_init  # noqa: E402
from refimpl.nn.params import count_parameters, init_normal  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_gru_train import _timed  # noqa: E402

LR = 1e-3
SETTLE = 0.15
BYTES_PER_PARAM = 28  # read p, g, m, v; write p, m, v (float32)


def quaternet_params():
    """QuaterNet short-term model's parameter shapes: GRU 2 x (128 -> 1000), head 1000 -> 128, learned h0."""
    rng = np.random.default_rng(0)
    params = gru_init(rng, 128, 1000, 2, "rnn", dtype=np.float32)
    params.update(linear_init(rng, 1000, 128, "fc", dtype=np.float32))
    params["h0"] = init_normal(rng, (2, 1, 1000), 0.01, dtype=np.float32)
    grads = {k: (1e-3 * rng.standard_normal(v.shape)).astype(np.float32) for k, v in params.items()}
    return params, grads


def stream_bandwidth(pool, n: int = 40_000_000) -> tuple:
    a = np.ones(n, np.float32)
    b = np.zeros(n, np.float32)
    halves = [(a[:n // 2], b[:n // 2]), (a[n // 2:], b[n // 2:])]

    def run():
        list(pool.map(lambda ab: np.add(ab[0], ab[1], out=ab[0]), halves))
    run()
    return lambda: 12 * n / _timed(run) / 1e9


def numpy_variant(params, grads, **kw):
    p = {k: v.copy() for k, v in params.items()}
    st = optim.adam_init(p)
    block = kw.pop("block", None)

    def step():
        if block is None:
            optim.adam_step(p, grads, st, lr=LR, **kw)
        else:
            old = optim._BLOCK
            optim._BLOCK = block
            try:
                optim.adam_step(p, grads, st, lr=LR, **kw)
            finally:
                optim._BLOCK = old
    return step


def _twelve_adds(p, g, m, v, t, *scalars) -> None:
    """12 ``np.add`` passes with ``_adam_block``'s operands and outputs (values meaningless: a timing floor)."""
    add = np.add
    for _ in range(3):
        add(g, m, t)
        add(m, t, t)
        add(t, v, t)
        add(p, t, t)


def twelve_adds_variant(params, grads):
    p = {k: v.copy() for k, v in params.items()}
    st = optim.adam_init(p)

    def step():
        old = optim._adam_block
        optim._adam_block = _twelve_adds
        try:
            optim.adam_step(p, grads, st, lr=LR, threads=2)
        finally:
            optim._adam_block = old
    return step


def naive_variant(params, grads):
    p = {k: v.copy() for k, v in params.items()}
    st = optim.adam_init(p)
    return lambda: optim._adam_step_naive(p, grads, st, lr=LR)


def torch_variant(torch, params, grads, **kw):
    ps = [torch.nn.Parameter(torch.from_numpy(v.copy())) for v in params.values()]
    for p, g in zip(ps, grads.values()):
        p.grad = torch.from_numpy(g.copy())
    opt = torch.optim.Adam(ps, lr=LR, **kw)
    return opt.step


def checks(torch, params, grads) -> dict:
    out = {}
    runs = {}
    for th in (1, 2):
        p = {k: v.copy() for k, v in params.items()}
        st = optim.adam_init(p)
        for _ in range(2):
            optim.adam_step(p, grads, st, lr=LR, threads=th)
        runs[th] = p
    out["threads_1_vs_2_bit_identical"] = all(np.array_equal(runs[1][k], runs[2][k]) for k in params)
    if torch is not None:
        ps = [torch.nn.Parameter(torch.from_numpy(v.copy())) for v in params.values()]
        opt = torch.optim.Adam(ps, lr=LR, fused=True)
        for _ in range(2):
            for p, g in zip(ps, grads.values()):
                p.grad = torch.from_numpy(g.copy())
            opt.step()
        err = 0.0
        for (k, v), p in zip(params.items(), ps):
            step = p.detach().numpy().astype(np.float64) - v  # what torch moved each entry
            ours = runs[2][k].astype(np.float64) - v
            err = max(err, float(np.max(np.abs(ours - step)) / max(np.max(np.abs(step)), 1e-30)))
        out["max_relative_difference_vs_torch_fused_update"] = err
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=5)
    ap.add_argument("--threads", type=int, default=2, help="torch threads (numpy: see the variants)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bench_adam.json")
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    try:
        import torch
        torch.set_num_threads(args.threads)
    except ImportError:
        torch = None
    params, grads = quaternet_params()
    n = count_parameters(params)
    load_start = os.getloadavg()
    print(f"Adam step on {n:,} float32 parameters ({len(params)} arrays, QuaterNet GRU 2x1000); block "
          f"{optim._BLOCK} elements; torch: {'absent' if torch is None else torch.__version__}", flush=True)
    chk = checks(torch, params, grads)
    print("checks: " + ", ".join(f"{k} = {v}" for k, v in chk.items()), flush=True)

    variants = {"numpy_2threads": numpy_variant(params, grads, threads=2),
                "numpy_1thread": numpy_variant(params, grads, threads=1),
                "numpy_block_32768": numpy_variant(params, grads, threads=2, block=32768),
                "numpy_naive": naive_variant(params, grads),
                "numpy_12_adds": twelve_adds_variant(params, grads)}
    if torch is not None:
        for name, kw in (("torch_fused", {"fused": True}), ("torch_foreach", {"foreach": True}),
                         ("torch_default", {})):
            variants[name] = torch_variant(torch, params, grads, **kw)
    pool = ThreadPoolExecutor(max_workers=2)
    bandwidth = stream_bandwidth(pool)
    for fn in variants.values():
        fn()
    names = list(variants)
    rounds = []
    for r in range(args.rounds):
        order = names[r % len(names):] + names[:r % len(names)]
        row = {"order": order}
        row["stream_gb_s"] = max(bandwidth() for _ in range(3))
        time.sleep(SETTLE)
        for name in order:
            row[name] = 1e3 * statistics.median(_timed(variants[name]) for _ in range(args.steps))
            time.sleep(SETTLE)
        row["memory_floor_ms"] = BYTES_PER_PARAM * n / (row["stream_gb_s"] * 1e9) * 1e3
        if torch is not None:
            row["numpy_over_torch_fused"] = row["numpy_2threads"] / row["torch_fused"]
            row["twelve_adds_over_torch_fused"] = row["numpy_12_adds"] / row["torch_fused"]
        row["numpy_over_floor"] = row["numpy_2threads"] / row["memory_floor_ms"]
        rounds.append(row)
        print(f"round {r + 1}: " + ", ".join(f"{k} {row[k]:.1f} ms" for k in names)
              + f"; stream {row['stream_gb_s']:.0f} GB/s, floor {row['memory_floor_ms']:.1f} ms"
              + (f"; numpy/torch_fused {row['numpy_over_torch_fused']:.2f}" if torch is not None else ""), flush=True)
    pool.shutdown()

    def rng_of(key):
        vals = [r[key] for r in rounds]
        return {"min": min(vals), "median": statistics.median(vals), "max": max(vals)}
    summary = {k: rng_of(k) for k in names + ["memory_floor_ms", "stream_gb_s", "numpy_over_floor"]}
    if torch is not None:
        summary["numpy_over_torch_fused"] = rng_of("numpy_over_torch_fused")
        summary["twelve_adds_over_torch_fused"] = rng_of("twelve_adds_over_torch_fused")
    load_end = os.getloadavg()
    print("summary (min / median / max over rounds):")
    for k, v in summary.items():
        print(f"  {k}: " + " / ".join(f"{x:.2f}" for x in v.values()))
    print(f"1-min load average at start / end: {load_start[0]:.1f} / {load_end[0]:.1f} on {os.cpu_count()} CPUs")
    result = {"benchmark": "bench_adam", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                          "numpy": np.__version__, "loadavg_start": load_start, "loadavg_end": load_end},
              "torch": None if torch is None else torch.__version__, "torch_threads": args.threads,
              "n_params": n, "block": optim._BLOCK, "bytes_per_param": BYTES_PER_PARAM, "checks": chk,
              "rounds": rounds, "summary": summary}
    atomic_write_text(args.out, json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
