"""Benchmark: the training loss of acRNN's dual-quaternion rows per batch, before and after the fused kernel.

Variants, interleaved in every round (order rotated between rounds):

* ``composed``: ``refimpl.dq_output.dq_output_loss_forward`` / ``dq_output_loss_backward`` — the composition of
  the public losses (the path every batch took before the fused kernel, and still its readable reference);
* ``fused``: ``refimpl.dq_output_fast.dq_output_loss_forward`` / ``dq_output_loss_backward`` (the fused kernel);
* ``loss_composed`` / ``loss_fused``: the whole acRNN training loss ``refimpl.models.acrnn.loss_forward`` +
  ``loss_backward`` of the row "dual quaternions (all losses)" (MSE + 0.01 L_reg + ⅓ L_pos + ⅓ L_offset + local
  L_quat on the de-standardised output), with the DQ path switched between the two.

Shape: a batch of B × T frames (default 32 × 100, the paper's) of J joints (default 43, the salsa skeleton),
float32, random raw outputs around unit dual quaternions and unit targets. Each variant runs ``--reps`` times per
round; its round time is the median; ratios are paired per round. Usage:
``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_dq_output.py [--rounds 5] [--reps 3] [--joints 43]``; writes
``benchmarks/results/bench_dq_output.json`` atomically. A benchmark, not a test: nothing asserts on time.
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
from refimpl.versions import with_versions  # noqa: E402

from refimpl import dq_output, dq_output_fast  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.dualquat import dq_normalize  # noqa: E402
from refimpl.models import acrnn  # noqa: E402
from refimpl.protocols.synthesis import VARIANTS  # noqa: E402
from refimpl.skeleton import Skeleton  # noqa: E402


def _composed_public(raw, target, parents, weights=dq_output.DQ_TERMS, eps=1e-12):
    total, parts, cache = dq_output.dq_output_loss_forward(raw, target, parents, weights, eps)
    return total, parts, ("composed", cache)  # the fast module's backward dispatches on the tag


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--batch", type=int, default=32)
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--joints", type=int, default=43)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bench_dq_output.json")
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    B, T, J = a.batch, a.frames, a.joints
    parents = [-1] + [int(rng.integers(max(0, j - 4), j)) for j in range(1, J)]
    target = dq_normalize(rng.standard_normal((B, T, J, 8))).astype(np.float32)
    raw = (target + 0.1 * rng.standard_normal(target.shape)).astype(np.float32)
    w = dict(dq_output.DQ_TERMS)

    F = 3 + 8 * J
    frames = np.concatenate([rng.standard_normal((B, T, 3)), target.reshape(B, T, 8 * J)], axis=-1)
    mean, std = frames.reshape(-1, F).mean(0), frames.reshape(-1, F).std(0) + 1e-3
    spec = acrnn.LossSpec.for_variant(VARIANTS["dual_quaternions_all"], mean, std, Skeleton(parents, rng.standard_normal((J, 3))))
    tgt = ((frames - mean) / std).astype(np.float32)
    pred = (tgt + 0.1 * rng.standard_normal(tgt.shape)).astype(np.float32)

    def path(kind):
        fwd = _composed_public if kind == "composed" else dq_output_fast.dq_output_loss_forward

        def run():
            total, _, cache = fwd(raw, target, parents, w)
            return total, dq_output_fast.dq_output_loss_backward(1.0, cache)
        return run

    def whole(kind):
        def run():
            fast = dq_output_fast.dq_output_loss_forward
            acrnn.dq_output_loss_forward = _composed_public if kind == "composed" else fast
            total, _, cache = acrnn.loss_forward(pred, tgt, spec)
            return total, acrnn.loss_backward(1.0, cache)
        return run

    variants = {"composed": path("composed"), "fused": path("fused"),
                "loss_composed": whole("composed"), "loss_fused": whole("fused")}
    # checks before timing: the two paths agree
    (t0, g0), (t1, g1) = variants["composed"](), variants["fused"]()
    assert abs(t0 - t1) <= 1e-5 * abs(t0) and g1.dtype == np.float32, (t0, t1, g1.dtype)
    gdiff = float(np.max(np.abs(g0 - g1)) / np.max(np.abs(g0)))
    (l0, d0), (l1, d1) = variants["loss_composed"](), variants["loss_fused"]()
    ldiff = float(np.max(np.abs(d0 - d1)) / np.max(np.abs(d0)))
    print(f"check: total {t0:.6f} vs {t1:.6f}; max |Δdraw| / max |draw| = {gdiff:.1e}; whole loss {l0:.6f} vs "
          f"{l1:.6f}, max |Δdpred| / max |dpred| = {ldiff:.1e}", flush=True)

    names = list(variants)
    times = {k: [] for k in names}
    for rnd in range(a.rounds):
        order = names[rnd % len(names):] + names[:rnd % len(names)]
        for k in order:
            ts = []
            for _ in range(a.reps):
                s = time.perf_counter()
                variants[k]()
                ts.append(time.perf_counter() - s)
            times[k].append(statistics.median(ts))
        print(f"round {rnd + 1}/{a.rounds}: " + ", ".join(f"{k} {times[k][-1] * 1e3:.0f} ms" for k in names),
              flush=True)
    ratio = [c / f for c, f in zip(times["composed"], times["fused"])]
    lratio = [c / f for c, f in zip(times["loss_composed"], times["loss_fused"])]
    print(f"\n| variant (B {B}, T {T}, J {J}, float32) | median ms | min ms |\n|---|---|---|")
    for k in names:
        print(f"| {k} | {statistics.median(times[k]) * 1e3:.1f} | {min(times[k]) * 1e3:.1f} |")
    print(f"\nDQ path composed / fused: median {statistics.median(ratio):.1f}x (range {min(ratio):.1f}-"
          f"{max(ratio):.1f}); whole loss: median {statistics.median(lratio):.1f}x (range {min(lratio):.1f}-"
          f"{max(lratio):.1f})")
    result = {"shape": {"B": B, "T": T, "J": J, "dtype": "float32"}, "weights": w, "rounds": a.rounds,
              "reps": a.reps, "times_s": times, "ratio_dq_path": ratio, "ratio_whole_loss": lratio,
              "check": {"rel_grad_diff": gdiff, "rel_dpred_diff": ldiff},
              "load_average": os.getloadavg(), "platform": platform.platform(), "numpy": np.__version__,
              "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS")}
    atomic_write_text(a.out, json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
