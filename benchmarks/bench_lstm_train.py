"""Benchmark: the acRNN-sized LSTM training iteration and acRNN's auto-conditioned training iteration, NumPy vs
PyTorch eager.

What is timed (spec/layers.md §5.6; reference/performance_facts.md "Training acRNN"): a 3-layer LSTM 251 -> 1024
(acRNN's skewed stack for NumPy; PyTorch's ``nn.LSTM`` is the ordinary stack, which has exactly the same products),
zero initial states, a linear head 1024 -> 251 on every frame, an MSE loss, the backward pass and one Adam step
(acRNN: lr 1e-4, no clipping), batch 32, 100 frames, float32. Matmul work: 427 GFLOP per iteration (counted below).

Variants, interleaved in every round (the order rotates from round to round; 0.15 s of settling between variants,
because OpenBLAS and PyTorch thread pools spin after a call and slow the next framework's first call):

* ``numpy_fast`` (the key of the recorded results; there is one NumPy LSTM): ``lstm_forward`` / ``lstm_backward`` +
  ``refimpl.optim.adam_step``;
* ``torch``: ``torch.nn.LSTM`` (oneDNN) + ``nn.Linear`` + ``mse_loss`` + ``torch.optim.Adam`` (its default
  implementation on CPU), if ``torch`` is importable;
* ``acrnn_numpy`` (unless ``--no-acrnn``): acRNN's training iteration with auto-conditioning (mask 5 ground-truth /
  5 own frames, the prediction fed back not detached; ordinary stack, the config's default):
  :func:`refimpl.models.acrnn.sequence_forward` rollout and BPTT + MSE against the next frames + Adam;
* ``acrnn_torch``: the same in PyTorch eager, as fast as eager allows: each ground-truth segment one ``nn.LSTM``
  call (oneDNN, all layers), each own-output step one ``nn.LSTM`` call on the previous prediction.

Every round also measures the float32 GEMM peak (best of 3 ``2048^3`` products, NumPy/OpenBLAS with the same
threads), so each iteration is paired with the peak of its own round: "share of limit" = (matmul GFLOP / peak) /
time. The ratios numpy_fast / torch and acrnn_numpy / acrnn_torch are taken per
round (paired) and reported as ranges, with the 1-min load average at the end of each round; absolute times on
this shared 2-vCPU machine drift by ±25-40 % within minutes (far more when other jobs run) and are not comparable
between runs.

Before timing, the benchmark checks that NumPy and PyTorch compute the same thing in float32 (same weights): the
ordinary stack against ``nn.LSTM`` (outputs, loss, the gradient of every parameter and of the input), the
skewed stack against a PyTorch ``nn.LSTMCell`` loop with acRNN's skew (``--skew-check-frames`` frames), and the
auto-conditioned acRNN rollout against the PyTorch rollout above (predictions, loss, every parameter gradient),
with the largest error relative to the largest magnitude of each array (float32 precision: < 1e-4 required).

Usage::

    python benchmarks/bench_lstm_train.py [--rounds 3] [--threads 2] [--no-acrnn] [--out PATH]

Writes ``benchmarks/results/bench_lstm_train.json`` (atomically). A benchmark, not a test: nothing asserts on time.
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
from refimpl.models import acrnn  # noqa: E402
from refimpl.nn.linear import linear_backward, linear_forward, linear_init  # noqa: E402
from refimpl.nn.lstm import lstm_backward, lstm_forward, lstm_init  # noqa: E402
from refimpl.nn.params import count_parameters, merge_grads  # noqa: E402
from refimpl.optim import ACRNN_ADAM, adam_init, adam_step  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_gru_train import _timed, gemm_peak  # noqa: E402  (best-of-n 2048^3 GEMM; one timed call)

B, T, I, H, L = 32, 100, 251, 1024, 3
O = I  # acRNN's decoder maps back to the frame's features
SETTLE = 0.15
CHECK_TOL = 1e-4


def matmul_flops(t_len: int) -> int:
    """Exact matmul FLOPs of one iteration (2 per multiply-add): every product of the forward and backward."""
    n = B * t_len
    total = 0
    for k in range(L):
        in_k = I if k == 0 else H
        total += 3 * 2 * n * in_k * 4 * H  # input projection, dW_ih, dx
        total += 3 * 2 * n * H * 4 * H  # recurrent product, dW_hh, dh
    total += 3 * 2 * n * H * O  # head: forward, dW, dx
    return total


def make_numpy_model():
    rng = np.random.default_rng(0)
    params = lstm_init(rng, I, H, L, "rnn", dtype=np.float32)
    params.update(linear_init(rng, H, O, "fc", dtype=np.float32))
    x = rng.standard_normal((B, T, I)).astype(np.float32)
    target = rng.standard_normal((B, T, O)).astype(np.float32)
    return params, x, target


def numpy_loss_and_grads(params, x, target, skewed: bool):
    """Forward, MSE, backward. Returns (y, loss, grads, dx, seconds forward, seconds backward)."""
    t0 = time.perf_counter()
    zeros = np.zeros((L, x.shape[0], H), np.float32)
    y, _, cache = lstm_forward(x, (zeros, zeros), params, "rnn", L, skewed)
    pred, hcache = linear_forward(y, params, "fc")
    diff = pred - target
    loss = float(np.mean(diff * diff, dtype=np.float64))
    t1 = time.perf_counter()
    dpred = diff * np.float32(2.0 / diff.size)
    dy, g_head = linear_backward(dpred, hcache)
    dx, _, g_rnn = lstm_backward(dy, None, cache)
    grads = merge_grads(g_rnn, g_head)
    t2 = time.perf_counter()
    return y, loss, grads, dx, t1 - t0, t2 - t1


def numpy_iteration(params, x, target, state) -> dict:
    _, _, grads, _, tf, tb = numpy_loss_and_grads(params, x, target, True)
    return _with_adam(tf, tb, params, grads, state)


def _with_adam(tf, tb, params, grads, state) -> dict:
    """One timed Adam step after a forward (tf s) and a backward (tb s): the iteration's times."""
    ta = _timed(lambda: adam_step(params, grads, state, **ACRNN_ADAM))
    return {"forward": tf, "backward": tb, "adam": ta, "iteration": tf + tb + ta}


# ----------------------------------------------------------------------------------------------------------
# PyTorch


def torch_model(torch, params, rnn: str = "rnn", head: str = "fc"):
    """``nn.LSTM`` + ``nn.Linear`` holding the NumPy parameters ``{rnn}.*`` and ``{head}.*``."""
    lstm = torch.nn.LSTM(I, H, L, batch_first=True)
    fc = torch.nn.Linear(H, O)
    with torch.no_grad():
        for name, p in lstm.named_parameters():
            p.copy_(torch.from_numpy(params[f"{rnn}.{name}"]))
        fc.weight.copy_(torch.from_numpy(params[f"{head}.weight"]))
        fc.bias.copy_(torch.from_numpy(params[f"{head}.bias"]))
    return lstm, fc


def _torch_timed_step(opt, loss_fn) -> dict:
    """One timed PyTorch iteration: zero the gradients, ``loss_fn()`` (the forward), backward, ``opt.step()``."""
    t0 = time.perf_counter()
    opt.zero_grad(set_to_none=True)
    loss = loss_fn()
    t1 = time.perf_counter()
    loss.backward()
    t2 = time.perf_counter()
    opt.step()
    t3 = time.perf_counter()
    return {"forward": t1 - t0, "backward": t2 - t1, "adam": t3 - t2, "iteration": t3 - t0}


def _rel_err(a, b) -> float:
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-30))


def check_against_torch(torch, params, x, target, skew_frames: int) -> dict:
    """Float32 agreement of NumPy and PyTorch (same weights): ordinary stack vs nn.LSTM, skewed vs an LSTMCell loop."""
    lstm, fc = torch_model(torch, params)
    xt = torch.from_numpy(x).requires_grad_(True)
    yt, _ = lstm(xt)
    loss_t = torch.nn.functional.mse_loss(fc(yt), torch.from_numpy(target))
    loss_t.backward()
    y, loss, grads, dx, _, _ = numpy_loss_and_grads(params, x, target, skewed=False)
    errs = {"ordinary.y": _rel_err(y, yt.detach().numpy()), "ordinary.loss": abs(loss - loss_t.item()) / loss_t.item(),
            "ordinary.dx": _rel_err(dx, xt.grad.numpy())}
    for name, p in lstm.named_parameters():
        errs["ordinary.grad.rnn." + name] = _rel_err(grads["rnn." + name], p.grad.numpy())
    errs["ordinary.grad.fc.weight"] = _rel_err(grads["fc.weight"], fc.weight.grad.numpy())
    errs["ordinary.grad.fc.bias"] = _rel_err(grads["fc.bias"], fc.bias.grad.numpy())

    # skewed (acRNN): layer k reads layer k-1's state of the previous step (zeros at the first step)
    tf = min(skew_frames, x.shape[1])
    cells = [torch.nn.LSTMCell(I if k == 0 else H, H) for k in range(L)]
    with torch.no_grad():
        for k, cell in enumerate(cells):
            for nm in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"):
                getattr(cell, nm).copy_(torch.from_numpy(params[f"rnn.{nm}_l{k}"]))
    xs = torch.from_numpy(np.ascontiguousarray(x[:, :tf])).requires_grad_(True)
    h = [torch.zeros(B, H) for _ in range(L)]
    c = [torch.zeros(B, H) for _ in range(L)]
    outs = []
    for t in range(tf):
        old = list(h)
        for k, cell in enumerate(cells):
            h[k], c[k] = cell(xs[:, t] if k == 0 else old[k - 1], (h[k], c[k]))
        outs.append(h[-1])
    ys = torch.stack(outs, 1)
    loss_s = torch.nn.functional.mse_loss(fc(ys), torch.from_numpy(np.ascontiguousarray(target[:, :tf])))
    fc.zero_grad()
    loss_s.backward()
    y2, loss2, grads2, dx2, _, _ = numpy_loss_and_grads(params, np.ascontiguousarray(x[:, :tf]),
                                                        np.ascontiguousarray(target[:, :tf]), skewed=True)
    errs["skewed.y"] = _rel_err(y2, ys.detach().numpy())
    errs["skewed.loss"] = abs(loss2 - loss_s.item()) / loss_s.item()
    errs["skewed.dx"] = _rel_err(dx2, xs.grad.numpy())
    for k, cell in enumerate(cells):
        for nm in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"):
            errs[f"skewed.grad.rnn.{nm}_l{k}"] = _rel_err(grads2[f"rnn.{nm}_l{k}"], getattr(cell, nm).grad.numpy())
    errs["skewed.grad.fc.weight"] = _rel_err(grads2["fc.weight"], fc.weight.grad.numpy())
    return errs


def torch_iteration_fn(torch, params, x, target):
    lstm, fc = torch_model(torch, params)
    ps = list(lstm.parameters()) + list(fc.parameters())
    opt = torch.optim.Adam(ps, lr=ACRNN_ADAM["lr"])
    xt, tt = torch.from_numpy(x), torch.from_numpy(target)
    return lambda: _torch_timed_step(opt, lambda: torch.nn.functional.mse_loss(fc(lstm(xt)[0]), tt))


# ----------------------------------------------------------------------------------------------------------
# acRNN with auto-conditioning (the training iteration of refimpl.models.acrnn)


def acrnn_config() -> "acrnn.ACRNNConfig":
    """acRNN at the paper's size, ordinary stack (the config's default, = ``nn.LSTM``), auto-conditioning 5 / 5."""
    return acrnn.ACRNNConfig(frame_size=I, hidden_size=H, num_layers=L, skewed=False)


def make_acrnn_model(t_len: int):
    cfg = acrnn_config()
    rng = np.random.default_rng(1)
    params = acrnn.init_params(cfg, rng, np.float32)
    frames = rng.standard_normal((B, t_len + 1, I)).astype(np.float32)
    return cfg, params, frames


def acrnn_matmul_flops(t_len: int) -> int:
    """Exact matmul FLOPs of one auto-conditioned acRNN iteration (ordinary stack, mask 5 / 5): as
    :func:`matmul_flops`, but layer 0's input cotangent only at the own-output steps, plus the decoder products of
    the fed-back outputs (forward) and of their cotangents (backward)."""
    mask = acrnn_config().mask(t_len)
    n, n_own = B * t_len, B * int((~mask).sum())
    total = matmul_flops(t_len) - 2 * (n - n_own) * I * 4 * H
    return total + 2 * 2 * n_own * H * O


def acrnn_numpy_loss_and_grads(params, cfg, frames):
    """Auto-conditioned rollout (refimpl.models.acrnn), MSE against ``frames[:, 1:]``, BPTT. Returns (pred, loss, grads, tf,
    tb)."""
    t0 = time.perf_counter()
    pred, cache = acrnn.sequence_forward(params, cfg, frames)
    diff = pred - frames[:, 1:]
    loss = float(np.mean(diff * diff, dtype=np.float64))
    t1 = time.perf_counter()
    grads = acrnn.sequence_backward(diff * np.float32(2.0 / diff.size), cache)
    t2 = time.perf_counter()
    return pred, loss, grads, t1 - t0, t2 - t1


def acrnn_numpy_iteration(params, cfg, frames, state) -> dict:
    _, _, grads, tf, tb = acrnn_numpy_loss_and_grads(params, cfg, frames)
    return _with_adam(tf, tb, params, grads, state)


def acrnn_torch_forward(torch, lstm, fc, frames_t, mask):
    """PyTorch eager rollout with auto-conditioning, as fast as eager allows: each ground-truth segment is one
    ``nn.LSTM`` call over its frames (oneDNN, all layers), each own-output step one ``nn.LSTM`` call on the previous
    prediction (not detached). Returns pred (B, T, F)."""
    preds, state, t, t_len = [], None, 0, len(mask)
    while t < t_len:
        if mask[t]:
            e = t
            while e < t_len and mask[e]:
                e += 1
            y, state = lstm(frames_t[:, t:e], state)
            t = e
        else:
            y, state = lstm(preds[-1][:, -1:], state)
            t += 1
        preds.append(fc(y))
    return torch.cat(preds, 1)


def acrnn_check_against_torch(torch, params, cfg, frames) -> dict:
    """Float32 agreement of the auto-conditioned rollout, loss and every gradient with PyTorch (same weights)."""
    lstm, fc = torch_model(torch, params, "lstm", "decoder")
    ft = torch.from_numpy(frames)
    pred_t = acrnn_torch_forward(torch, lstm, fc, ft, cfg.mask(frames.shape[1] - 1))
    loss_t = torch.nn.functional.mse_loss(pred_t, ft[:, 1:])
    loss_t.backward()
    pred, loss, grads, _, _ = acrnn_numpy_loss_and_grads(params, cfg, frames)
    errs = {"acrnn.pred": _rel_err(pred, pred_t.detach().numpy()),
            "acrnn.loss": abs(loss - loss_t.item()) / loss_t.item()}
    for name, p in lstm.named_parameters():
        errs["acrnn.grad.lstm." + name] = _rel_err(grads["lstm." + name], p.grad.numpy())
    errs["acrnn.grad.decoder.weight"] = _rel_err(grads["decoder.weight"], fc.weight.grad.numpy())
    errs["acrnn.grad.decoder.bias"] = _rel_err(grads["decoder.bias"], fc.bias.grad.numpy())
    return errs


def acrnn_torch_iteration_fn(torch, params, cfg, frames):
    lstm, fc = torch_model(torch, params, "lstm", "decoder")
    opt = torch.optim.Adam(list(lstm.parameters()) + list(fc.parameters()), lr=ACRNN_ADAM["lr"])
    ft = torch.from_numpy(frames)
    mask = cfg.mask(frames.shape[1] - 1)
    return lambda: _torch_timed_step(
        opt, lambda: torch.nn.functional.mse_loss(acrnn_torch_forward(torch, lstm, fc, ft, mask), ft[:, 1:]))


# ----------------------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    global T
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2, help="BLAS threads (threadpoolctl) and torch threads")
    ap.add_argument("--skew-check-frames", type=int, default=30)
    ap.add_argument("--no-torch", action="store_true")
    ap.add_argument("--no-acrnn", action="store_true", help="leave out the auto-conditioned acRNN iteration")
    ap.add_argument("--frames", type=int, default=T, help="sequence length (default 100; smaller only to try the "
                    "script out quickly)")
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results" / "bench_lstm_train.json")
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    try:
        from threadpoolctl import threadpool_info, threadpool_limits
        threadpool_limits(limits=args.threads, user_api="blas")
        blas = ", ".join(f"{d.get('internal_api')} {d.get('version')} {d.get('architecture')} "
                         f"({d.get('num_threads')} threads)" for d in threadpool_info() if d.get("user_api") == "blas")
    except ImportError:
        blas = "unknown (threadpoolctl not installed: BLAS threads not limited)"
    torch = None
    if not args.no_torch:
        try:
            import torch
            torch.set_num_threads(args.threads)
        except ImportError:
            torch = None
    load_start = os.getloadavg()
    T = args.frames
    flop = matmul_flops(T)
    print(f"acRNN LSTM training iteration: {L}x LSTM({I} -> {H}), head {H} -> {O}, batch {B}, {T} frames, float32, "
          f"{flop / 1e9:.1f} GFLOP of matmuls; BLAS: {blas}; torch: "
          f"{'absent' if torch is None else torch.__version__ + f' ({torch.get_num_threads()} threads)'}", flush=True)

    params, x, target = make_numpy_model()
    if not args.no_acrnn:
        acfg, aparams, aframes = make_acrnn_model(T)
        aflop = acrnn_matmul_flops(T)
        print(f"acRNN auto-conditioned iteration: ordinary stack, mask {acfg.ground_truth_length} / "
              f"{acfg.condition_length}, {aflop / 1e9:.1f} GFLOP of matmuls", flush=True)
    checks = None
    if torch is not None:
        print("checking NumPy against PyTorch (float32, same weights) ...", flush=True)
        checks = check_against_torch(torch, params, x, target, args.skew_check_frames)
        if not args.no_acrnn:
            checks.update(acrnn_check_against_torch(torch, aparams, acfg, aframes))
        worst = max(checks, key=checks.get)
        print(f"  largest relative error {checks[worst]:.2e} ({worst}); "
              f"{'OK' if checks[worst] < CHECK_TOL else 'MISMATCH'} (tolerance {CHECK_TOL:g})", flush=True)

    variants = {}
    p = {k: v.copy() for k, v in params.items()}
    st = adam_init(p)
    variants["numpy_fast"] = lambda p=p, st=st: numpy_iteration(p, x, target, st)
    if torch is not None:
        variants["torch"] = torch_iteration_fn(torch, params, x, target)
    if not args.no_acrnn:
        p = {k: v.copy() for k, v in aparams.items()}
        st = adam_init(p)
        variants["acrnn_numpy"] = lambda p=p, st=st: acrnn_numpy_iteration(p, acfg, aframes, st)
        if torch is not None:
            variants["acrnn_torch"] = acrnn_torch_iteration_fn(torch, aparams, acfg, aframes)
    for name, fn in variants.items():  # warm-up (allocations, page faults, oneDNN primitive creation)
        fn()
        time.sleep(SETTLE)

    rounds = []
    names = list(variants)
    for r in range(args.rounds):
        peak = gemm_peak(np.float32, reps=3)
        time.sleep(SETTLE)
        order = names[r % len(names):] + names[:r % len(names)]
        row = {"gemm_peak_gflops": peak, "order": order}
        for name in order:
            row[name] = variants[name]()
            time.sleep(SETTLE)
        peak_after = gemm_peak(np.float32, reps=3)
        row["gemm_peak_after_gflops"] = peak_after
        limit = flop / (max(peak, peak_after) * 1e9)
        row["limit_s"] = limit
        row["share_of_limit"] = {n: (aflop if n.startswith("acrnn") else flop) / (max(peak, peak_after) * 1e9)
                                 / row[n]["iteration"] for n in names}
        if torch is not None:
            row["fast_over_torch"] = row["numpy_fast"]["iteration"] / row["torch"]["iteration"]
            if not args.no_acrnn:
                row["acrnn_numpy_over_torch"] = row["acrnn_numpy"]["iteration"] / row["acrnn_torch"]["iteration"]
        rounds.append(row)
        print(f"round {r + 1}: peak {peak:.0f}/{peak_after:.0f} GF/s, limit {limit:.2f} s; " + "; ".join(
            f"{n} {row[n]['iteration']:.2f} s (fwd {row[n]['forward']:.2f}, bwd {row[n]['backward']:.2f}, "
            f"adam {1e3 * row[n]['adam']:.0f} ms; {100 * row['share_of_limit'][n]:.0f} % of limit)" for n in names)
            + (f"; fast/torch {row['fast_over_torch']:.2f}" if torch is not None else "")
            + (f"; acrnn numpy/torch {row['acrnn_numpy_over_torch']:.2f}" if "acrnn_numpy_over_torch" in row else "")
            + f"; load {os.getloadavg()[0]:.1f}", flush=True)

    def rng_of(key):
        vals = [r[key] for r in rounds]
        return {"min": min(vals), "median": statistics.median(vals), "max": max(vals)}
    summary = {}
    if torch is not None:
        summary["fast_over_torch"] = rng_of("fast_over_torch")
        if not args.no_acrnn:
            summary["acrnn_numpy_over_torch"] = rng_of("acrnn_numpy_over_torch")
    for n in names:
        vals = [r["share_of_limit"][n] for r in rounds]
        summary[f"share_of_limit.{n}"] = {"min": min(vals), "median": statistics.median(vals), "max": max(vals)}
        summary[f"seconds.{n}"] = {"min": min(r[n]["iteration"] for r in rounds),
                                   "median": statistics.median(r[n]["iteration"] for r in rounds)}
    load_end = os.getloadavg()
    print("summary (paired per round; min / median / max):")
    for k, v in summary.items():
        print(f"  {k}: " + " / ".join(f"{x:.2f}" for x in v.values()))
    print(f"1-min load average at start / end: {load_start[0]:.1f} / {load_end[0]:.1f} (this VM; other agents' VMs "
          "share the host's cores, which this number does not show)")
    result = {"benchmark": "bench_lstm_train", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
              "machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "python": platform.python_version(),
                          "numpy": np.__version__, "loadavg_start": load_start, "loadavg_end": load_end},
              "blas": blas, "threads": args.threads, "torch": None if torch is None else torch.__version__,
              "config": dict(B=B, T=T, I=I, H=H, L=L, O=O, dtype="float32", adam=dict(ACRNN_ADAM),
                             numpy_stack="skewed (acRNN)", torch_stack="ordinary (nn.LSTM)",
                             acrnn=None if args.no_acrnn else dict(stack="ordinary", mask="5 / 5",
                                                                   matmul_gflop=aflop / 1e9)),
              "n_params": count_parameters(params), "matmul_gflop_per_iteration": flop / 1e9,
              "checks_relative_error": checks, "check_tolerance": CHECK_TOL, "rounds": rounds, "summary": summary}
    atomic_write_text(args.out, json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
