"""Benchmark: every model's training step with glibc's default allocator settings and with
:func:`refimpl.allocator.retain_freed_memory` (issue #17: no per-step page faults).

A training step allocates its caches afresh and frees them at the end; with glibc's defaults the freed pages go
back to the system and the next step faults them in again (spec/cli.md §3). The allocator setting is a process
setting that cannot be undone, so each variant runs in its own child process: per round and model, one child
with the system defaults (``system``) and one that calls ``retain_freed_memory()`` first (``retain``), in
alternating order. Each child builds the training step exactly as ``refimpl train`` does
(``bench_threads._training_case``: the recipe's adapter, paper-size network, its paper batch, float32, Adam),
runs two warm-up steps, then times steps for ``--min-time`` seconds with ``--threads`` BLAS threads and counts
the page faults (minor + major) per step. The parent pairs the two children of a round: ratio ``retain /
system`` of the median step time. Nothing asserts on time.

    python benchmarks/bench_allocator.py [--rounds 3] [--models qtg,quaternet] [--threads 2] [--out PATH]
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

MODELS = "qtg,quaternet,quaternet-cnn,acrnn,quaternet-long,pace"


def _faults() -> int:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_minflt + r.ru_majflt


def _child(name: str, mode: str, threads: int, min_time: float) -> dict:
    from threadpoolctl import threadpool_limits

    from refimpl.allocator import retain_freed_memory
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_threads import _training_case

    applied = retain_freed_memory() if mode == "retain" else False
    step, _, _, desc = _training_case(name, None)
    times, faults = [], []
    with threadpool_limits(limits=threads):
        step()
        step()
        t_end = time.perf_counter() + min_time
        while time.perf_counter() < t_end or len(times) < 3:
            f0, t0 = _faults(), time.perf_counter()
            step()
            times.append((time.perf_counter() - t0) * 1e3)
            faults.append(_faults() - f0)
    return {"model": name, "mode": mode, "applied": applied, "batch": desc["batch"], "steps": len(times),
            "ms_median": statistics.median(times), "ms": times, "faults_per_step": statistics.median(faults)}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--models", default=MODELS)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--min-time", type=float, default=3.0, help="seconds of timed steps per child")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_allocator.json"))
    ap.add_argument("--child", nargs=2, metavar=("MODEL", "MODE"), help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        print(json.dumps(_child(args.child[0], args.child[1], args.threads, args.min_time)))
        return {}

    from refimpl.atomic import atomic_write_text

    result = {"benchmark": "bench_allocator", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "threads": args.threads, "load_average_before": os.getloadavg(), "cases": {}}
    for name in [m for m in args.models.split(",") if m]:
        rows = []
        for r in range(args.rounds):
            row = {}
            for mode in (("system", "retain") if r % 2 == 0 else ("retain", "system")):
                out = subprocess.run([sys.executable, __file__, "--child", name, mode, "--threads", str(args.threads),
                                      "--min-time", str(args.min_time)], capture_output=True, text=True, check=True)
                row[mode] = json.loads(out.stdout.strip().splitlines()[-1])
                time.sleep(0.2)
            row["ratio_retain_over_system"] = row["retain"]["ms_median"] / row["system"]["ms_median"]
            row["load_average"] = os.getloadavg()[0]
            rows.append(row)
            print(f"{name:15s} round {r + 1}: system {row['system']['ms_median']:9.2f} ms "
                  f"({row['system']['faults_per_step']:,.0f} faults/step), retain {row['retain']['ms_median']:9.2f} ms "
                  f"({row['retain']['faults_per_step']:,.0f} faults/step): ratio {row['ratio_retain_over_system']:.2f} "
                  f"(load {row['load_average']:.1f})", flush=True)
        ratios = [row["ratio_retain_over_system"] for row in rows]
        result["cases"][name] = {"rounds": rows, "ratio_min": min(ratios), "ratio_median": statistics.median(ratios),
                                 "ratio_max": max(ratios)}
    result["load_average_after"] = os.getloadavg()
    print("\nmodel             retain / system (min / median / max)")
    for name, case in result["cases"].items():
        print(f"{name:15s}   {case['ratio_min']:.2f} / {case['ratio_median']:.2f} / {case['ratio_max']:.2f}")
    atomic_write_text(Path(args.out), json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
