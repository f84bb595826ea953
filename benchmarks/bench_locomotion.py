"""Benchmark: frames per second of online locomotion generation at batch 1 (spec/locomotion.md §10).

One generated frame = one step of the long-term pose network (controls block, 2-layer GRU, head, per-joint
normalisation) plus the host work of the generation loop (path interpolation, controls). Measured, interleaved
in one run, float32, batch 1, one thread:

* ``numpy step``: :func:`refimpl.models.quaternet.step`;
* ``ort step``: the exported step model (``deploy.models.quaternet_long.export_pose_step``) in onnxruntime;
* ``numpy generate``: :func:`refimpl.models.quaternet_long_walk.generate_walk` per frame (step + host loop),
  with the paper-size pace network run once over the path beforehand (its time per path is reported apart).

Sizes: the paper's (H = 1000, 2 layers) and our trained size (H = 256), for the Bandai Namco rig (J = 21).
The published code reports 900 FPS at batch 1 on a P100 GPU (quaternet_reference_code.md §10). The machine is
a shared 2-core VM (load average printed): ratios between variants of one run are meaningful, absolute numbers
drift ±25-40 %. A table is printed and JSON written to ``benchmarks/results/bench_locomotion.json``.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_locomotion.py [--rounds 5] [--out PATH]
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

from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.models import pace, quaternet  # noqa: E402
from refimpl.skeleton import Skeleton  # noqa: E402
from refimpl.splines import circle_path  # noqa: E402
from refimpl.models.quaternet_long_walk import generate_walk  # noqa: E402
from refimpl.protocols.locomotion_data import FPS  # noqa: E402

J = 21


def _median_time(fn, rounds: int, reps: int) -> float:
    fn()
    out = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        for _ in range(reps):
            fn()
        out.append((time.perf_counter() - t0) / reps)
    return statistics.median(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_locomotion.json"))
    args = ap.parse_args(argv)
    rng = np.random.default_rng(0)
    pc = pace.PaceConfig()
    pp = pace.init_params(pc, rng, dtype=np.float32)
    path = circle_path(50.0)
    t0 = time.perf_counter()
    pace.predict(pp, pc, path, 0.5)
    pace_ms = 1000 * (time.perf_counter() - t0)
    rows, results = [], {}
    try:
        import onnxruntime  # noqa: F401
        from deploy.models.quaternet_long import export_pose_step
        from deploy.runtime import load_model
    except ImportError:
        export_pose_step = None
    for H in (256, 1000):
        net = quaternet.QuaterNetConfig.long_term(num_joints=J, hidden_size=H)
        params = quaternet.init_params(net, rng, dtype=np.float32)
        x = rng.standard_normal((1, net.input_size)).astype(np.float32)
        h = quaternet.init_state(params, 1, net)
        variants = {"numpy step": lambda: quaternet.step(params, h, x, net)}
        if export_pose_step is not None:
            ort = load_model(export_pose_step(params, net).SerializeToString(), intra_op_threads=1)
            variants["ort step"] = lambda: ort.run(x=x, state=h)
        sk = Skeleton([-1] + list(range(J - 1)), np.ones((J, 3)))
        seed = np.tile(np.array([1.0, 0, 0, 0]), (30, J, 1))
        feats = np.zeros((30, 8))
        feats[:, 7] = 1.0
        n_gen = 60
        variants["numpy generate"] = lambda: generate_walk(params, net, pp, pc, sk, seed, feats, path, 0.5, n_gen,
                                                                   fps=FPS)
        times = {k: [] for k in variants}
        for _ in range(args.rounds):  # interleaved
            for k, fn in variants.items():
                reps = 1 if k == "numpy generate" else 50
                times[k].append(_median_time(fn, 1, reps))
        for k, ts in times.items():
            t = statistics.median(ts)
            if k == "numpy generate":  # 30 seed steps + n_gen generated frames per call, pace network excluded
                t = max(t - pace_ms / 1000, 1e-9) / (30 + n_gen)
            results[f"H{H} {k}"] = {"ms_per_frame": 1000 * t, "fps": 1.0 / t, "params": quaternet.count_parameters(net)}
            rows.append((f"H = {H}", k, f"{1000 * t:.3f}", f"{1 / t:.0f}"))
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"online locomotion generation, batch 1, float32, J = {J}; load average {load:.1f}; "
          f"pace network over a {path.length:.0f}-unit circle (paper size): {pace_ms:.1f} ms once per path")
    w = [max(len(r[i]) for r in rows + [("size", "variant", "ms/frame", "FPS")]) for i in range(4)]
    for r in [("size", "variant", "ms/frame", "FPS")] + rows:
        print("  ".join(c.rjust(x) for c, x in zip(r, w)))
    print("reference: 900 FPS on a P100 GPU (published code, paper size, batch 1)")
    doc = {"machine": platform.platform(), "load_average": load, "pace_ms_per_path": pace_ms,
           "results": results, "reference_fps_p100": 900}
    atomic_write_text(Path(args.out), json.dumps(with_versions(doc), indent=2) + "\n", make_parents=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
