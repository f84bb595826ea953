"""Benchmark: one QuaterNet CNN training iteration, the project's NumPy against PyTorch eager (issue #17).

The convolutional QuaterNet at paper size (``QuaterNetCNNConfig()``: J = 32, C = 1024, 5 causal layers of width 2,
dilations 1…16, skips 0→2 and 1→3, ReLU, velocity mode; 6.9 M parameters), the published batch (60) and window
(prefix 32 = the receptive field, target 10: a fed sequence of 41 frames), float32. One iteration, as
``refimpl train --model quaternet-cnn`` runs it (spec/quaternet.md §5.3, §7):

    y, Δ = forward_scheduled(prefix, future, mask)          the fed-back frames computed from their windows
    loss = mean((y − future)²) + 0.01 · mean((‖Δ_j‖² − 1)²)  (a squared error stands in for the Euler L1 so that
                                                              both sides compute exactly the same function)
    grads = backward_scheduled(...); clip to global norm 0.1; Adam step (lr 1e-3)

PyTorch: ``nn.Conv1d`` layers with the same parameters, left zero padding ``(K − 1)·d``, the same skips, the
Hamilton product and ``F.normalize``; the fed-back predictions are computed under ``no_grad`` (the gradient flows
through the first term only, as in the NumPy model); autograd, ``clip_grad_norm_``, ``torch.optim.Adam``
(its default implementation on CPU). Before timing, the benchmark compares the loss, outputs and every clipped
gradient of one iteration with PyTorch's (relative errors in the JSON): in float32 on the timed batch (float32
rounding: ~1e-5 on the outputs, up to ~5e-3 of a gradient's largest entry at batch 60, where ReLU decisions
near zero can round either way), and in float64 on 4 windows (~1e-14: the same function).

``--free-steps k`` feeds back the model's own prediction at the last ``k`` of the 9 decisions (default 0: teacher
forcing, the schedule's first epoch). Rounds are interleaved (NumPy, PyTorch, alternating order) with a settle
pause between frameworks; the JSON has per-round times and the paired per-round ratio ``numpy / torch``, its
min/median/max, the matrix-product FLOPs of the iteration and the load average before and after. Threads:
``--threads`` for BLAS (threadpoolctl) and ``torch.set_num_threads``. Nothing asserts on time.

    python benchmarks/bench_quaternet_cnn.py [--rounds 3] [--threads 2] [--free-steps 0] [--out PATH]
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
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.models import quaternet_cnn as cnn  # noqa: E402
from refimpl.optim import adam_init, adam_step, clip_grad_norm  # noqa: E402

try:
    from threadpoolctl import threadpool_limits
except ImportError:  # optional
    threadpool_limits = None

SETTLE = 0.15
LR, CLIP, PENALTY = 1e-3, 0.1, 0.01


def _data(cfg, B, P, T, free_steps, seed=0):
    rng = np.random.default_rng(seed)
    q = rng.standard_normal((B, P + T, cfg.num_joints, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q = q.reshape(B, P + T, 4 * cfg.num_joints).astype(np.float32)
    mask = np.ones(T - 1, bool)
    if free_steps:
        mask[-free_steps:] = False
    return q[:, :P], q[:, P:], mask


def _numpy_loss(y, pre, future, J):
    """Loss and its cotangents ``dy``, ``dpre`` (module docstring)."""
    B, T, _ = y.shape
    d = y - future
    n2 = np.sum(pre.reshape(B, T, J, 4) ** 2, axis=-1)                      # (B, T, J)
    loss = float(np.mean(d * d) + PENALTY * np.mean((n2 - 1) ** 2))
    dy = 2 * d / d.size
    dpre = (PENALTY * 2 * (n2 - 1) / n2.size)[..., None] * 2 * pre.reshape(B, T, J, 4)
    return loss, dy, dpre.reshape(B, T, 4 * J).astype(y.dtype)


def numpy_iteration(params, state, cfg, prefix, future, mask):
    y, pre, cache = cnn.forward_scheduled(params, prefix, future, mask, cfg)
    loss, dy, dpre = _numpy_loss(y, pre, future, cfg.num_joints)
    grads = cnn.backward_scheduled(dy, dpre, cache)
    clip_grad_norm(grads, CLIP)
    adam_step(params, grads, state, LR)
    return loss, y, grads


def _torch_model(torch, params, cfg):
    F = torch.nn.functional

    class Net(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.convs = torch.nn.ModuleList()
            for k in range(cfg.num_layers):
                w = params[f"convs.{k}.weight"]
                c = torch.nn.Conv1d(w.shape[1], w.shape[0], w.shape[2], dilation=cfg.dilations[k])
                with torch.no_grad():
                    c.weight.copy_(torch.from_numpy(w.copy()))
                    c.bias.copy_(torch.from_numpy(params[f"convs.{k}.bias"].copy()))
                self.convs.append(c)

        def forward(self, x):                                               # x (B, T, 4J)
            B, T, _ = x.shape
            a, acts = x.transpose(1, 2), []
            for k, c in enumerate(self.convs):
                z = c(F.pad(a, ((c.kernel_size[0] - 1) * c.dilation[0], 0)))
                if k < len(self.convs) - 1:
                    z = torch.relu(z)
                for s, kk in cfg.skips:
                    if kk == k:
                        z = z + acts[s]
                acts.append(z)
                a = z
            pre = a.transpose(1, 2)                                         # (B, T, 4J)
            d, q = pre.reshape(B, T, -1, 4), x.reshape(B, T, -1, 4)
            w0, x0, y0, z0 = d.unbind(-1)
            w1, x1, y1, z1 = q.unbind(-1)
            p = torch.stack([w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1, w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
                             w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1, w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1], -1)
            return F.normalize(p, dim=-1, eps=cfg.eps).reshape(B, T, -1), pre

    return Net()


def torch_iteration_fn(torch, net, opt, cfg, prefix, future, mask):
    prefix_t, future_t = torch.from_numpy(prefix), torch.from_numpy(future)
    P, T, R = prefix.shape[1], future.shape[1], cfg.receptive_field

    def iteration():
        fed = torch.cat([prefix_t, future_t[:, :T - 1]], 1)
        with torch.no_grad():
            for i in range(T - 1):
                if not mask[i]:
                    s = P + i
                    fed[:, s] = net(fed[:, max(0, s - R):s])[0][:, -1]
        y, pre = net(fed)
        y, pre = y[:, P - 1:], pre[:, P - 1:]
        B = y.shape[0]
        n2 = (pre.reshape(B, T, -1, 4) ** 2).sum(-1)
        loss = ((y - future_t) ** 2).mean() + PENALTY * ((n2 - 1) ** 2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(net.parameters(), CLIP)
        opt.step()
        return loss, y

    return iteration


def check(torch, params, cfg, prefix, future, mask) -> dict:
    """Relative errors of one iteration's loss, outputs and clipped gradients (before the update), NumPy vs PyTorch."""
    p = {k: v.copy() for k, v in params.items()}
    y, pre, cache = cnn.forward_scheduled(p, prefix, future, mask, cfg)
    loss, dy, dpre = _numpy_loss(y, pre, future, cfg.num_joints)
    grads = cnn.backward_scheduled(dy, dpre, cache)
    clip_grad_norm(grads, CLIP)                                             # PyTorch's iteration clips too
    net = _torch_model(torch, params, cfg)
    opt = torch.optim.SGD(net.parameters(), lr=0.0)
    tloss, ty = torch_iteration_fn(torch, net, opt, cfg, prefix, future, mask)()
    rel = lambda a, b: float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-30))  # noqa: E731
    tg = {n: t.grad.numpy() for n, t in net.named_parameters()}
    errs = {n: rel(grads[n], tg[n]) for n in grads}
    worst = max(errs, key=errs.get)
    tloss = float(tloss.detach())
    return {"loss_rel": abs(loss - tloss) / abs(tloss), "y_max_rel": rel(y, ty.detach().numpy()),
            "grads_max_rel": errs[worst], "worst_grad": worst}


def matmul_gflop(cfg, B, L, P, T, mask) -> float:
    """Matrix-product FLOPs of one iteration: forward + weight gradients over the fed sequence (B, L), input
    gradients of every layer but the first, and a forward over each fed-back frame's window."""
    macs = [cfg.kernel_sizes[k] * w_in * w_out for k, (w_in, w_out) in enumerate(_widths(cfg))]
    per_frame_fwd, per_frame_dx = sum(macs), sum(macs[1:])
    R = cfg.receptive_field
    free = sum(min(R, P + i) for i in range(T - 1) if not mask[i])
    return 2 * (B * L * (2 * per_frame_fwd + per_frame_dx) + B * free * per_frame_fwd) / 1e9


def _widths(cfg):
    w = [4 * cfg.num_joints] + [cfg.channels] * (cfg.num_layers - 1) + [4 * cfg.num_joints]
    return list(zip(w[:-1], w[1:]))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--batch", type=int, default=60)
    ap.add_argument("--free-steps", type=int, default=0)
    ap.add_argument("--channels", type=int, default=1024, help="paper 1024; smaller only to try the script")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_quaternet_cnn.json"))
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    import torch
    torch.set_num_threads(args.threads)
    if threadpool_limits is not None:
        threadpool_limits(limits=args.threads)
    cfg = cnn.QuaterNetCNNConfig(channels=args.channels)
    P, T, B = cfg.receptive_field, 10, args.batch
    if not 0 <= args.free_steps <= T - 1:
        raise SystemExit(f"--free-steps: expected 0..{T - 1}, got {args.free_steps}")
    params = cnn.init_params(cfg, np.random.default_rng(0), dtype=np.float32)
    prefix, future, mask = _data(cfg, B, P, T, args.free_steps)
    chk = check(torch, params, cfg, prefix, future, mask)
    torch.set_default_dtype(torch.float64)                # the same in float64 on 4 windows: equal to rounding
    p64 = {k: v.astype(np.float64) for k, v in params.items()}
    chk64 = check(torch, p64, cfg, prefix[:4].astype(np.float64), future[:4].astype(np.float64), mask)
    torch.set_default_dtype(torch.float32)
    for name, c in (("float32", chk), ("float64, 4 windows", chk64)):
        print(f"check vs PyTorch ({name}, relative): " + ", ".join(
            f"{k} {v:.2e}" if isinstance(v, float) else f"{k} {v}" for k, v in c.items()), flush=True)
    p_np = {k: v.copy() for k, v in params.items()}
    st = adam_init(p_np)
    net = _torch_model(torch, params, cfg)
    variants = {"numpy": lambda: numpy_iteration(p_np, st, cfg, prefix, future, mask),
                "torch": torch_iteration_fn(torch, net, torch.optim.Adam(net.parameters(), lr=LR), cfg, prefix,
                                            future, mask)}
    for fn in variants.values():
        fn()
    load0 = os.getloadavg()
    rounds = []
    for r in range(args.rounds):
        order = ["numpy", "torch"] if r % 2 == 0 else ["torch", "numpy"]
        row = {"order": order}
        for name in order:
            time.sleep(SETTLE)
            t0 = time.perf_counter()
            variants[name]()
            row[f"{name}_ms"] = (time.perf_counter() - t0) * 1e3
        row["numpy_over_torch"] = row["numpy_ms"] / row["torch_ms"]
        row["loadavg_1min"] = os.getloadavg()[0]
        rounds.append(row)
        print(f"round {r + 1}: numpy {row['numpy_ms']:.0f} ms, torch {row['torch_ms']:.0f} ms, ratio "
              f"{row['numpy_over_torch']:.2f} (load {row['loadavg_1min']:.1f})", flush=True)
    stat = lambda key: {"min": min(x[key] for x in rounds), "median": statistics.median(x[key] for x in rounds),  # noqa: E731
                        "max": max(x[key] for x in rounds)}
    gflop = matmul_gflop(cfg, B, P + T - 1, P, T, mask)
    result = {"benchmark": "bench_quaternet_cnn", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "machine": {"platform": platform.platform(), "cpu_count": os.cpu_count(), "numpy": np.__version__,
                          "torch": torch.__version__},
              "threads": args.threads, "config": {"batch": B, "prefix": P, "target": T, "free_steps": args.free_steps,
                                                  "network": cfg.to_dict() if hasattr(cfg, "to_dict") else str(cfg),
                                                  "parameters": cnn.count_parameters(cfg)},
              "check_relative_error": chk, "check_relative_error_float64_batch4": chk64,
              "matmul_gflop_per_iteration": gflop, "rounds": rounds,
              "summary": {"numpy_ms": stat("numpy_ms"), "torch_ms": stat("torch_ms"),
                          "numpy_over_torch": stat("numpy_over_torch")},
              "loadavg_start": load0, "loadavg_end": os.getloadavg()}
    s = result["summary"]
    print(f"QuaterNet CNN training iteration (B={B}, {P}+{T} frames, {gflop:.1f} GFLOP, {args.threads} threads): "
          f"numpy {s['numpy_ms']['median']:.0f} ms, torch {s['torch_ms']['median']:.0f} ms, numpy/torch "
          f"{s['numpy_over_torch']['min']:.2f} / {s['numpy_over_torch']['median']:.2f} / "
          f"{s['numpy_over_torch']['max']:.2f} (min/median/max; goal ≤ 0.67)")
    atomic_write_text(Path(args.out), json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
