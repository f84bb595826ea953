"""Benchmark: time of one QTG transition (30 frames) in NumPy float32, and arithmetic per frame vs RTN.

Paper (Geleijn et al. 2021): 0.33 ms per 1-second (30-frame) transition on a 6-core Core i7-8700, and
≈ 80 % fewer arithmetic operations than RTN. What is measured here (spec/qtg.md §5-§6):

* ``rollout_inference`` (the lean path: pre-transposed contiguous float32 weights, no caches) for a 30-frame
  transition at batch 1 and batch 64, with the BLAS thread pool as configured and limited to 1 thread;
  median over ``--rounds`` rounds of the per-call time; at batch 64 also the time per transition;
* ``rollout_forward`` (the training path, with caches) at batch 1 for comparison;
* multiply-accumulates per generated frame of QTG (:func:`refimpl.models.qtg.macs_per_frame`) and RTN
  (:func:`refimpl.models.qtg.rtn_macs_per_frame`), and their ratio; parameters and weight bytes.

With ``--train``: the QTG training step (issue #17) at the paper size, batch 32 (``--train-batch``), float32:
``rollout_forward`` + MAE loss + ``rollout_backward`` + ``adam_step`` (QTG's Adam settings) against the same
step in PyTorch eager (``nn.Linear`` / ``nn.GRUCell`` modules, ``L1Loss``, ``torch.optim.Adam``) with the same
parameters, batch and thread count (``--threads``, NumPy's BLAS limited to it through threadpoolctl), interleaved
per round (0.15 s settling between them), each round's time the median of ``--steps`` consecutive steps; the
ratio NumPy / PyTorch is paired per round, for the wall time and for the process CPU time (all threads; with one
thread the CPU-time ratio is the one that other jobs on the machine disturb least). Before timing, the
loss and every gradient are compared with PyTorch's (float32 precision). A third variant in the same rounds,
``products``, runs only the step's matrix products (same shapes, layouts and order; ``_products_floor``): the
floor of this design with this BLAS, reported as ``products_over_torch``. Written into the JSON under ``train``.

With ``--ort``: ``rollout_inference`` at batch 1 against onnxruntime running the exports of ``deploy``
(``export_qtg_rollout_compact`` float32 and the unrolled ``export_qtg_rollout``), one thread each, interleaved,
wall and CPU time, ratios paired per round (issue #17: NumPy within 1.1 × onnxruntime); JSON under ``ort``.

Target: ≤ 2 ms at batch 1 (reference/performance_facts.md: the physical limit on the 2-core development VM
is 0.6-0.8 ms, because every step streams ~2.1 MB of float32 weights from L3). The ONNX timings are
another benchmark's. A table is printed and JSON written to ``benchmarks/results/bench_qtg.json``.
Nothing asserts on time.

    python benchmarks/bench_qtg.py [--rounds 7] [--out PATH] [--train | --ort] [--train-rounds 5] [--steps 5]
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

from refimpl.allocator import retain_freed_memory  # noqa: E402
from refimpl.models.qtg import (QTGConfig, count_parameters, init_params, macs_per_frame,  # noqa: E402
                                rtn_macs_per_frame)
from refimpl.models.qtg_fast import rollout_backward, rollout_forward  # noqa: E402
from refimpl.models.qtg_fast_inference import prepare_inference, rollout_inference  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.losses import mae_loss_backward, mae_loss_forward  # noqa: E402
from refimpl.optim import QTG_ADAM, adam_init, adam_step  # noqa: E402

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


# ------------------------------------------------------------------------------------------- training step
SETTLE = 0.15


def _numpy_train_step(params, past, target, truth, cfg):
    """One training step of the project (forward, MAE loss, backward, Adam in place); returns the loss."""
    state = adam_init(params)

    def step():
        pred, cache = rollout_forward(params, past, target, truth.shape[1], cfg)
        loss, lcache = mae_loss_forward(pred, truth)
        grads = rollout_backward(mae_loss_backward(1.0, lcache), cache)
        adam_step(params, grads, state, **QTG_ADAM)
        return loss
    return step


def _torch_qtg(torch, params, cfg):
    """QTG (spec/qtg.md §3) as a PyTorch eager module with the given float32 parameters (PyTorch names)."""
    nn = torch.nn

    class QTG(nn.Module):
        def __init__(self):
            super().__init__()
            sizes = (cfg.pose_size,) + cfg.encoder_sizes
            self.enc = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))
            self.gru = nn.ModuleList(nn.GRUCell(3 * cfg.latent_size if k == 0 else cfg.gru_hidden, cfg.gru_hidden)
                                     for k in range(cfg.gru_layers))
            self.vel = nn.Linear(cfg.gru_hidden, cfg.latent_size)
            sizes = (cfg.latent_size,) + cfg.decoder_sizes + (cfg.pose_size,)
            self.dec = nn.ModuleList(nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))

        def encode(self, x):
            for lin in self.enc:
                x = nn.functional.leaky_relu(lin(x), cfg.negative_slope)
            return x

        def forward(self, past, target, T):
            z_prev, pose = self.encode(past[:, 0]), past[:, 1]
            e1, e2 = self.encode(target[:, 0]), self.encode(target[:, 1])
            hs = [past.new_zeros(past.shape[0], cfg.gru_hidden) for _ in self.gru]
            out = []
            for _ in range(T):
                z = self.encode(pose)
                x = torch.cat([z - z_prev, e1 - z, e2 - e1], dim=1)
                for k, cell in enumerate(self.gru):
                    hs[k] = x = cell(x, hs[k])
                h = z + self.vel(x)
                for j, lin in enumerate(self.dec):
                    h = lin(h)
                    if j < len(self.dec) - 1:
                        h = nn.functional.leaky_relu(h, cfg.negative_slope)
                out.append(h)
                pose, z_prev = h, z
            return torch.stack(out, dim=1)

    model = QTG()
    names = dict(model.named_parameters())
    missing = set(params) ^ set(_torch_names(names, cfg))
    if missing:
        raise RuntimeError(f"parameter names differ: {sorted(missing)}")
    with torch.no_grad():
        for k, v in _torch_names(names, cfg).items():
            v.copy_(torch.from_numpy(params[k]))
    return model


def _torch_names(named, cfg):
    """Map the project's parameter names to the module's tensors (``gru.weight_ih_l0`` <- ``gru.0.weight_ih``)."""
    out = {}
    for k, v in named.items():
        parts = k.split(".")
        if parts[0] == "gru":
            out[f"gru.{parts[2]}_l{parts[1]}"] = v
        else:
            out[k] = v
    return out


def _torch_train_step(torch, model, past, target, truth):
    past, target, truth = (torch.from_numpy(a) for a in (past, target, truth))
    opt = torch.optim.Adam(model.parameters(), lr=QTG_ADAM["lr"], betas=QTG_ADAM["betas"], eps=QTG_ADAM["eps"])
    loss_fn = torch.nn.L1Loss()

    def step():
        opt.zero_grad(set_to_none=True)
        loss = loss_fn(model(past, target, truth.shape[1]), truth)
        loss.backward()
        opt.step()
        return float(loss.detach())
    return step


def _train_check(torch, params, past, target, truth, cfg) -> dict:
    """Loss and gradients of one step, NumPy vs PyTorch: max |difference| / max |value| per array."""
    pred, cache = rollout_forward(params, past, target, truth.shape[1], cfg)
    loss, lcache = mae_loss_forward(pred, truth)
    grads = rollout_backward(mae_loss_backward(1.0, lcache), cache)
    model = _torch_qtg(torch, params, cfg)
    tpred = model(torch.from_numpy(past), torch.from_numpy(target), truth.shape[1])
    tloss = torch.nn.L1Loss()(tpred, torch.from_numpy(truth))
    tloss.backward()
    tgrads = {k: v.grad.numpy() for k, v in _torch_names(dict(model.named_parameters()), cfg).items()}

    def rel(a, b):
        return float(np.max(np.abs(a - b)) / max(float(np.max(np.abs(b))), 1e-30))
    return {"poses_max_rel": rel(pred, tpred.detach().numpy()), "loss_rel": abs(loss - float(tloss.detach())) / float(tloss.detach()),
            "grads_max_rel": max(rel(grads[k], tgrads[k]) for k in grads),
            "worst_grad": max(grads, key=lambda k: rel(grads[k], tgrads[k]))}


def _products_floor(cfg, B: int, T: int, dtype=np.float32):
    """The matrix products of one training step (``rollout_forward`` + ``rollout_backward``, spec/qtg.md §4) with
    the same shapes, operand layouts and order, and nothing else: a callable that runs them, and their GFLOP.

    Per step of the forward: encoder (2), ``z_t [W1 − W2 ; W1]ᵀ``, ``s_{t+1} [W_hh ; W_v]ᵀ``, decoder (2), each as
    ``matmul_wt`` computes it (``W @ xᵀ`` into the transposed output); per step of the backward: decoder (2),
    ``[W_hh ; W_v]``, ``[W1 − W2 ; W1]`` (two products in one broadcast call), encoder (2; the first one not at
    t = 0); the context encoding and target term once; after the loop one ``daᵀ x`` product per weight over all
    stacked rows. The time of this is the floor of any implementation that keeps this BLAS and these products.
    """
    rng = np.random.default_rng(3)
    P, Z, H, (E1, E2), (D1,) = cfg.pose_size, cfg.latent_size, cfg.gru_hidden, cfg.encoder_sizes, cfg.decoder_sizes
    H3 = 3 * H

    def a(*shape):
        return rng.standard_normal(shape).astype(dtype)

    dense_f = [(a(E1, P), a(B, P), a(B, E1)), (a(E2, E1), a(B, E1), a(B, E2)), (a(2 * H3, Z), a(B, Z), a(B, 2 * H3)),
               (a(H3 + Z, H), a(B, H), a(B, H3 + Z)), (a(D1, Z), a(B, Z), a(B, D1)), (a(P, D1), a(B, D1), a(B, P))]
    ctx_f = [(a(E1, P), a(3 * B, P), a(3 * B, E1)), (a(E2, E1), a(3 * B, E1), a(3 * B, E2)),
             (a(H3, 2 * Z), a(B, 2 * Z), a(B, H3)), (a(H3, Z), a(B, Z), a(B, H3))]
    back = [(a(B, P), a(P, D1), a(B, D1)), (a(B, D1), a(D1, Z), a(B, Z)), (a(B, H3 + Z), a(H3 + Z, H), a(B, H)),
            (a(B, H3), a(2, H3, Z), a(2, B, Z)), (a(B, E2), a(E2, E1), a(B, E1))]
    back_enc0 = (a(B, E1), a(E1, P), a(B, P))
    n_enc, n_gru = (T + 3) * B, T * B
    wgrad = [(a(n_enc, E1), a(n_enc, P)), (a(n_enc, E2), a(n_enc, E1)), (a(n_gru, H3), a(n_gru, 3 * Z)),
             (a(n_gru, H3), a(n_gru, H)), (a(n_gru, Z), a(n_gru, H)), (a(n_gru, D1), a(n_gru, Z)),
             (a(n_gru, P), a(n_gru, D1))]
    mm = np.matmul

    def run():
        for w, x, o in ctx_f:
            mm(w, x.T, out=o.T)
        for _ in range(T):
            for w, x, o in dense_f:
                mm(w, x.T, out=o.T)
        for t in range(T - 1, -1, -1):
            for x, w, o in back:
                mm(x, w, out=o)
            if t:
                mm(back_enc0[0], back_enc0[1], out=back_enc0[2])
        for da, x in wgrad:
            da.T @ x

    flops = 2 * (sum(w.size * x.shape[0] for w, x, _ in ctx_f) + T * sum(w.size * x.shape[0] for w, x, _ in dense_f)
                 + T * sum(x.size * w.shape[-1] * (w.shape[0] if w.ndim == 3 else 1) for x, w, _ in back)
                 + (T - 1) * back_enc0[0].size * P + sum(da.size * x.shape[1] for da, x in wgrad))
    return run, flops / 1e9


def _time_block(row: dict, name: str, fn, steps: int, calls: int = 1) -> None:
    """After a settle pause, ``steps`` timings of ``calls`` calls of ``fn``; writes the medians per call into
    ``row[name + "_ms"]`` (wall) and ``row[name + "_cpu_ms"]`` (CPU time of all threads: robust to other load)."""
    time.sleep(SETTLE)
    ts, cs = [], []
    for _ in range(steps):
        t0, c0 = time.perf_counter(), time.process_time()
        for _ in range(calls):
            fn()
        ts.append((time.perf_counter() - t0) / calls)
        cs.append((time.process_time() - c0) / calls)
    row[name + "_ms"] = 1e3 * statistics.median(ts)
    row[name + "_cpu_ms"] = 1e3 * statistics.median(cs)


def bench_train(args, cfg) -> dict:
    """Paired, interleaved rounds of the NumPy and PyTorch training steps (see the module docstring)."""
    import torch
    torch.set_num_threads(args.threads)
    rng = np.random.default_rng(1)
    B, T = args.train_batch, cfg.transition_length
    params = init_params(cfg, rng, dtype=np.float32)
    past, target = (rng.standard_normal((B, 2, cfg.pose_size)).astype(np.float32) for _ in range(2))
    truth = rng.standard_normal((B, T, cfg.pose_size)).astype(np.float32)
    check = _train_check(torch, params, past, target, truth, cfg)
    print("train check vs PyTorch: " + ", ".join(f"{k} {v:.2e}" if isinstance(v, float) else f"{k} {v}"
                                                 for k, v in check.items()), flush=True)
    products, products_gflop = _products_floor(cfg, B, T)
    variants = {"numpy": _numpy_train_step({k: v.copy() for k, v in params.items()}, past, target, truth, cfg),
                "torch": _torch_train_step(torch, _torch_qtg(torch, params, cfg), past, target, truth),
                "products": products}
    print(f"the step's matrix products alone: {products_gflop:.2f} GFLOP (forward + backward of the model: "
          f"{6 * B * T * macs_per_frame(cfg) / 1e9:.2f})", flush=True)
    for fn in variants.values():
        fn()
    load_start = os.getloadavg()
    rounds = []
    names = list(variants)
    for r in range(args.train_rounds):
        order = names[r % len(names):] + names[:r % len(names)]
        row = {"order": order}
        for name in order:
            _time_block(row, name, variants[name], args.steps)
        row["numpy_over_torch"] = row["numpy_ms"] / row["torch_ms"]
        row["numpy_over_torch_cpu"] = row["numpy_cpu_ms"] / row["torch_cpu_ms"]
        row["products_over_torch"] = row["products_ms"] / row["torch_ms"]
        row["products_gflops"] = products_gflop / row["products_ms"] * 1e3
        row["loadavg_1min"] = os.getloadavg()[0]
        rounds.append(row)
        print(f"train round {r + 1}: numpy {row['numpy_ms']:.1f} ms (CPU {row['numpy_cpu_ms']:.1f}), torch "
              f"{row['torch_ms']:.1f} ms (CPU {row['torch_cpu_ms']:.1f}); ratio {row['numpy_over_torch']:.2f}, "
              f"CPU-time ratio {row['numpy_over_torch_cpu']:.2f}; products alone {row['products_ms']:.1f} ms "
              f"({row['products_gflops']:.0f} GF/s, {row['products_over_torch']:.2f} x torch) "
              f"(load {row['loadavg_1min']:.1f})", flush=True)
    ratios = [r["numpy_over_torch"] for r in rounds]
    cpu_ratios = [r["numpy_over_torch_cpu"] for r in rounds]
    out = {"batch": B, "T": T, "threads": args.threads, "torch": torch.__version__, "check": check,
           "rounds": rounds, "loadavg_start": load_start, "loadavg_end": os.getloadavg(),
           "numpy_over_torch": {"min": min(ratios), "median": statistics.median(ratios), "max": max(ratios)},
           "numpy_over_torch_cpu": {"min": min(cpu_ratios), "median": statistics.median(cpu_ratios),
                                    "max": max(cpu_ratios)},
           "products_gflop": products_gflop}
    for key in ("products_over_torch", "products_gflops"):
        vals = [r[key] for r in rounds]
        out[key] = {"min": min(vals), "median": statistics.median(vals), "max": max(vals)}
    for key in ("numpy_over_torch", "numpy_over_torch_cpu", "products_over_torch", "products_gflops"):
        print(f"train {key} (min / median / max): " + " / ".join(f"{v:.2f}" for v in out[key].values()))
    return out


# ------------------------------------------------------------------------------- inference against onnxruntime
def _inference_products(model, T: int):
    """Only the matrix products of :func:`rollout_inference` at batch 1 (its prepared weights, shapes, order):
    the context encoding and target term once, then per step the encoder (2), ``z_t`` times the z product, the
    top state times the h product and the decoder (2). The floor of that code's design with this BLAS."""
    rng = np.random.default_rng(4)
    dt = model.dtype
    pairs = [(rng.standard_normal((3, a.shape[0] - 1)).astype(dt), a[:-1]) for a in model.enc]
    pairs += [(rng.standard_normal((1, model.target_product.shape[0])).astype(dt), model.target_product),
              (rng.standard_normal((1, model.z_product.shape[0])).astype(dt), model.z_product[:, model.z_product.shape[1] // 2:])]
    step = [(rng.standard_normal((1, a.shape[0])).astype(dt), a) for a in model.enc]
    step += [(rng.standard_normal((1, w.shape[0])).astype(dt), w) for w in (model.z_product, model.h_product)]
    step += [(rng.standard_normal((1, a.shape[0])).astype(dt), a) for a in model.dec]
    outs = {id(w): np.empty((x.shape[0], w.shape[1]), dtype=dt) for x, w in pairs + step}
    mm = np.matmul

    def run():
        for x, w in pairs:
            mm(x, w, out=outs[id(w)])
        for _ in range(T):
            for x, w in step:
                mm(x, w, out=outs[id(w)])
    return run


def bench_ort(args, cfg) -> dict:
    """NumPy ``rollout_inference`` vs the onnxruntime exports (``deploy``) of the same float32 30-frame transition
    at batch 1, one thread each (NumPy's BLAS limited through threadpoolctl when available), interleaved per
    round (order rotated), each round's value the median over ``--steps`` blocks of 20 calls; wall and process
    CPU time, ratios paired per round. Checks the exports' poses against NumPy first. ``numpy_products``
    (:func:`_inference_products`) times the NumPy path's matrix products alone."""
    from deploy.models.qtg import export_qtg_rollout
    from deploy.models.qtg_compact import export_qtg_rollout_compact
    from deploy.session import make_session

    rng = np.random.default_rng(2)
    params = init_params(cfg, rng, dtype=np.float32)
    model = prepare_inference(params, cfg)
    past, target = (rng.standard_normal((1, 2, cfg.pose_size)).astype(np.float32) for _ in range(2))
    feeds = {"past": past, "target": target}
    sessions = {"ort_compact_float32": make_session(export_qtg_rollout_compact(params, cfg, weights="float32")),
                "ort_unrolled": make_session(export_qtg_rollout(params, cfg, mode="unrolled"))}
    ref = rollout_inference(model, past, target)
    check = {k: float(np.max(np.abs(s.run(None, feeds)[0] - ref))) for k, s in sessions.items()}
    print("onnxruntime vs NumPy max |difference| of the poses: "
          + ", ".join(f"{k} {v:.1e}" for k, v in check.items()), flush=True)
    variants = {"numpy": lambda: rollout_inference(model, past, target),
                "numpy_products": _inference_products(model, cfg.transition_length)}
    variants.update({k: (lambda s=s: s.run(None, feeds)) for k, s in sessions.items()})
    names = list(variants)
    rounds = []
    limits = threadpool_limits(1) if threadpool_limits is not None else None
    try:
        for r in range(args.train_rounds):
            order = names[r % len(names):] + names[:r % len(names)]
            row = {"order": order}
            for name in order:
                _time_block(row, name, variants[name], args.steps, calls=20)
            for k in sessions:
                row[f"numpy_products_over_{k}"] = row["numpy_products_ms"] / row[k + "_ms"]
                row[f"numpy_over_{k}"] = row["numpy_ms"] / row[k + "_ms"]
                row[f"numpy_over_{k}_cpu"] = row["numpy_cpu_ms"] / row[k + "_cpu_ms"]
            row["loadavg_1min"] = os.getloadavg()[0]
            rounds.append(row)
            print(f"ort round {r + 1}: " + ", ".join(f"{k} {row[k + '_ms']:.2f} ms (CPU {row[k + '_cpu_ms']:.2f})"
                                                     for k in names)
                  + f"; NumPy / compact {row['numpy_over_ort_compact_float32']:.2f}, its products alone / compact "
                  f"{row['numpy_products_over_ort_compact_float32']:.2f} "
                  f"(CPU {row['numpy_over_ort_compact_float32_cpu']:.2f}) (load {row['loadavg_1min']:.1f})",
                  flush=True)
    finally:
        if limits is not None:
            limits.restore_original_limits()
    summary = {}
    for key in rounds[0]:
        if key.startswith(("numpy_over", "numpy_products_over")):
            vals = [r[key] for r in rounds]
            summary[key] = {"min": min(vals), "median": statistics.median(vals), "max": max(vals)}
    for k, v in summary.items():
        print(f"  {k} (min / median / max): " + " / ".join(f"{x:.2f}" for x in v.values()))
    return {"batch": 1, "T": cfg.transition_length, "threads": 1, "check_max_abs_diff": check, "rounds": rounds,
            "summary": summary}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=7)
    ap.add_argument("--T", type=int, default=30)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_qtg.json"))
    ap.add_argument("--train", action="store_true",
                    help="time the training step against PyTorch instead (JSON: bench_qtg_train.json)")
    ap.add_argument("--ort", action="store_true",
                    help="time rollout_inference against onnxruntime at batch 1 instead (JSON: bench_qtg_ort.json)")
    ap.add_argument("--train-batch", type=int, default=32)
    ap.add_argument("--train-rounds", type=int, default=5)
    ap.add_argument("--steps", type=int, default=5, help="training steps per round and variant")
    ap.add_argument("--threads", type=int, default=2, help="training: PyTorch intra-op and NumPy BLAS threads")
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)

    cfg = QTGConfig()
    T = args.T
    rng = np.random.default_rng(0)
    params = init_params(cfg, rng, dtype=np.float32)
    model = prepare_inference(params, cfg)
    ctx = {b: (rng.standard_normal((b, 2, cfg.pose_size)).astype(np.float32),
               rng.standard_normal((b, 2, cfg.pose_size)).astype(np.float32)) for b in (1, 64)}

    if args.ort:
        out = Path(args.out).with_name("bench_qtg_ort.json") if args.out.endswith("bench_qtg.json") else Path(args.out)
        result = {"benchmark": "bench_qtg --ort", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                  "config": cfg.to_dict(), "machine": {"platform": platform.platform(), "cpu_count": os.cpu_count(),
                                                       "numpy": np.__version__, "blas": _blas(),
                                                       "loadavg_start": os.getloadavg()},
                  "ort": bench_ort(args, cfg)}
        atomic_write_text(out, json.dumps(with_versions(result), indent=2), make_parents=True)
        print(f"wrote {out}")
        return result
    if args.train:
        out = Path(args.out).with_name("bench_qtg_train.json") if args.out.endswith("bench_qtg.json") else Path(args.out)
        result = {"benchmark": "bench_qtg --train", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
                  "config": cfg.to_dict(), "machine": {"platform": platform.platform(), "cpu_count": os.cpu_count(),
                                                       "numpy": np.__version__, "blas": _blas()},
                  "numpy_blas_threads": args.threads}
        if threadpool_limits is not None:  # NumPy's BLAS gets the same thread count as PyTorch
            with threadpool_limits(args.threads):
                result["train"] = bench_train(args, cfg)
        else:
            result["numpy_blas_threads"] = "default (threadpoolctl absent)"
            result["train"] = bench_train(args, cfg)
        atomic_write_text(out, json.dumps(with_versions(result), indent=2), make_parents=True)
        print(f"wrote {out}")
        return result

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
        json.dump(with_versions(result), f, indent=2)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, out)
    print(f"wrote {out}")
    return result


if __name__ == "__main__":
    main()
