"""Benchmark: QuaterNet (paper size, J = 32, velocity) — step latency, a 100-frame prediction, a training iteration.

Variants, float32, interleaved rounds (each variant timed once per round; medians and minima reported):

* ``step`` at batch 1 and 32: ``refimpl.models.quaternet.step`` (NumPy) vs the exported step model
  (``deploy.models.quaternet.export_quaternet_step``, onnxruntime) vs PyTorch (``torch.nn.GRU`` + ``Linear`` +
  QMul, eager, ``no_grad``) when installed;
* ``predict``: 50-frame prefix → 100 frames at batch 1 and 32: ``quaternet.predict`` vs the exported predict
  model (k = 100, one graph) vs PyTorch;
* ``train``: one training iteration at the published size (batch 60, prefix 50, target 10, all teacher forced):
  ``quaternet.forward`` + wrapped-Euler loss + penalty + ``backward`` (NumPy, manual backprop) vs PyTorch
  autograd on the same network with an L1 loss on the quaternions (the loss is a negligible part of the work).

Threads: ``--threads`` for BLAS (threadpoolctl), onnxruntime's intra-op pool and ``torch.set_num_threads``.
Nothing asserts on time. Prints a table and writes ``benchmarks/results/bench_quaternet.json`` atomically.

    python benchmarks/bench_quaternet.py [--threads 1] [--rounds 5] [--quick]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

from deploy.graph import save_model  # noqa: E402
from deploy.models.quaternet import export_quaternet_predict, export_quaternet_step  # noqa: E402
from deploy.runtime import load_model  # noqa: E402
from refimpl.allocator import retain_freed_memory  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.models import quaternet as net  # noqa: E402
from refimpl.models import quaternet_sequence  # noqa: E402
from refimpl.recipes.quaternet import ShortTermConfig, loss_terms  # noqa: E402


def _torch_model(params, config, threads):
    """PyTorch eager QuaterNet with the same weights, or None when torch is not installed."""
    try:
        import torch
    except ImportError:
        return None
    torch.set_num_threads(threads)
    J, H, L = config.num_joints, config.hidden_size, config.num_layers
    gru = torch.nn.GRU(4 * J, H, L, batch_first=True)
    fc = torch.nn.Linear(H, 4 * J)
    with torch.no_grad():
        for k, v in params.items():
            if k.startswith("rnn."):
                getattr(gru, k[4:]).copy_(torch.from_numpy(v))
        fc.weight.copy_(torch.from_numpy(params["fc.weight"]))
        fc.bias.copy_(torch.from_numpy(params["fc.bias"]))
    h0 = torch.from_numpy(params["h0"]).requires_grad_(True)

    def qmul(a, b):
        aw, ax, ay, az = a.unbind(-1)
        bw, bx, by, bz = b.unbind(-1)
        return torch.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)

    def head(top, x):
        B = top.shape[0]
        q = qmul(fc(top).view(B, -1, J, 4), x.view(B, -1, J, 4))
        return torch.nn.functional.normalize(q, dim=-1).view(B, -1, 4 * J)

    def step(x, h):
        y, h = gru(x[:, None], h)
        return head(y, x[:, None])[:, 0], h

    def predict(prefix, k):
        B = prefix.shape[0]
        y, h = gru(prefix, h0.expand(L, B, H).contiguous())
        out = [head(y[:, -1:], prefix[:, -1:])[:, 0]]
        for _ in range(k - 1):
            nxt, h = step(out[-1], h)
            out.append(nxt)
        return torch.stack(out, 1)

    def train_iter(x):
        B = x.shape[0]
        y, _ = gru(x[:, :-1], h0.expand(L, B, H).contiguous())
        pred = head(y[:, -10:], x[:, -11:-1])
        loss = (pred - x[:, -10:]).abs().mean()
        gru.zero_grad()
        fc.zero_grad()
        loss.backward()
        return float(loss.detach())

    return torch, step, predict, train_iter


#: Calls per timed block of a step variant: one cold call after a training iteration of another framework measures
#: its thread pools waking and its weights coming back from DRAM, not the step (performance_facts.md).
STEP_CALLS = 20
#: Pause before every timed block, so spinning BLAS/OpenMP threads of the previous variant settle.
SETTLE_S = 0.15


def _time(fn, rounds, results, name):
    """Time ``fn``: the mean of :data:`STEP_CALLS` calls after one warm-up call for the step variants, one call
    otherwise; each block after a :data:`SETTLE_S` pause."""
    calls = STEP_CALLS if name.startswith("step") else 1
    time.sleep(SETTLE_S)
    if calls > 1:
        fn()
    t0 = time.perf_counter()
    for _ in range(calls):
        fn()
    results.setdefault(name, []).append((time.perf_counter() - t0) / calls)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--quick", action="store_true", help="hidden 256 instead of 1000, 3 rounds")
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    rounds = 3 if args.quick else args.rounds
    config = ShortTermConfig(hidden_size=256 if args.quick else 1000).network
    rng = np.random.default_rng(0)
    params = net.init_params(config, rng, dtype=np.float32)
    from refimpl.rotations import quat_from_axis_angle

    frames = quat_from_axis_angle(0.3 * rng.standard_normal((60, 60, 32, 3))).astype(np.float32).reshape(60, 60, 128)
    try:
        from threadpoolctl import threadpool_limits
        threadpool_limits(limits=args.threads, user_api="blas")
    except ImportError:
        pass
    tmp = Path(tempfile.mkdtemp())
    save_model(export_quaternet_step(params, config), tmp / "step.onnx")
    save_model(export_quaternet_predict(params, config, k=100), tmp / "predict.onnx")
    ort_step = load_model(tmp / "step.onnx", intra_op_threads=args.threads)
    ort_pred = load_model(tmp / "predict.onnx", intra_op_threads=args.threads)
    tm = _torch_model(params, config, args.threads)
    res: dict = {}
    cases = []
    for B in (1, 32):
        x = frames[:B, 0]
        h = net.init_state(params, B, config)
        prefix = frames[:B, :50]
        cases += [(f"step B={B} numpy", lambda x=x, h=h: net.step(params, h, x, config)),
                  (f"step B={B} onnxruntime", lambda x=x, h=h: ort_step.run(x=x, hidden=h)),
                  (f"predict 100 B={B} numpy", lambda p=prefix: net.predict(params, p, 100, config)),
                  (f"predict 100 B={B} onnxruntime", lambda p=prefix: ort_pred.run(prefix=p))]
        if tm is not None:
            torch, t_step, t_pred, _ = tm
            xt, ht, pt = torch.from_numpy(x), torch.from_numpy(h), torch.from_numpy(prefix)

            def ts(xt=xt, ht=ht):
                with torch.no_grad():
                    t_step(xt, ht)

            def tp(pt=pt):
                with torch.no_grad():
                    t_pred(pt, 100)

            cases += [(f"step B={B} pytorch", ts), (f"predict 100 B={B} pytorch", tp)]
    scfg = ShortTermConfig(hidden_size=config.hidden_size, schedule="teacher_forcing", loss="euler")
    target = frames[:, 50:].reshape(60, 10, 32, 4)

    def np_train():
        y, pre, cache = quaternet_sequence.forward(params, frames[:, :50], frames[:, 50:], np.ones(9, bool), config)
        _, _, dy, dpre = loss_terms(y, pre, target, scfg)
        quaternet_sequence.backward(dy, dpre, cache)

    cases.append(("train iter B=60 numpy", np_train))
    if tm is not None:
        xt_all = tm[0].from_numpy(frames)
        cases.append(("train iter B=60 pytorch", lambda: tm[3](xt_all)))
    for _ in range(rounds):
        for name, fn in cases:
            _time(fn, rounds, res, name)
    rows = [(n, statistics.median(v) * 1000, min(v) * 1000) for n, v in res.items()]
    width = max(len(r[0]) for r in rows)
    print(f"QuaterNet J=32 H={config.hidden_size} float32, {args.threads} thread(s), {rounds} rounds, "
          f"load {os.getloadavg()[0]:.1f}")
    print(f"{'variant'.ljust(width)}  median ms    min ms")
    for n, med, mn in rows:
        print(f"{n.ljust(width)}  {med:9.2f} {mn:9.2f}")
    out = ROOT / "benchmarks" / "results" / "bench_quaternet.json"
    atomic_write_text(out, json.dumps(with_versions({"hidden_size": config.hidden_size, "threads": args.threads,
                                       "rounds": rounds, "loadavg": os.getloadavg(),
                                       "results_ms": {n: {"median": med, "min": mn} for n, med, mn in rows}}),
                                      indent=1) + "\n", make_parents=True)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
