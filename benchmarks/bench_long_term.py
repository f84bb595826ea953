"""Benchmark: the locomotion networks against PyTorch eager — QuaterNet's long-term pose network and the pace
network, training iteration and batch-1 inference (issue #17: every recurrent model in the table).

What is timed, float32, ``--threads`` BLAS / intra-op threads for every framework (default 2, the command line's):

* **long-term training iteration** (``quaternet-long``, paper size: 2 × 1000 GRU, controls block 6 → 30 → 30,
  batch 40, the recipe's window): NumPy = what ``refimpl train`` runs per step (``bench_threads.adapter_case`` and
  ``training_step``: the recipe's adapter batch,
  ``loss_and_grads`` — forward under scheduled sampling, which at epoch 0 is all teacher forcing, FK position
  loss + norm penalty, manual backward — and ``adam_step``); PyTorch = the same network (``nn.Linear`` controls
  block, ``nn.GRU`` over the whole teacher-forced sequence in one call, ``nn.Linear`` head, per-joint
  normalisation) with an L1 loss on the outputs and ``torch.optim.Adam``. The PyTorch side does less work (no
  forward kinematics), so the ratio is conservative for NumPy;
* **pace training iteration** (bidirectional GRU 2 → 30, learned h0, linear 60 → 4, batch 40 chunks of the
  recipe's length, L1, Adam): NumPy = the recipe's adapter step; PyTorch = ``nn.GRU(bidirectional=True)`` +
  ``nn.Linear`` + ``L1Loss`` + Adam, the same computation;
* **long-term step at batch 1**: ``quaternet.step`` (NumPy) vs the exported step (``deploy.models.quaternet_long.
  export_pose_step``, onnxruntime) vs PyTorch (one GRU step + head, ``no_grad``);
* **pace over one path at batch 1** (the offline network: every point of a 250-point path): ``pace.forward`` vs
  the exported pace model (``deploy.models.quaternet_long.export_pace``, onnxruntime) vs PyTorch (``no_grad``).

Before timing, the PyTorch models are checked against NumPy with the same weights: the long-term network's
teacher-forced predictions and every parameter's gradient of the L1 loss on them (NumPy through
``quaternet_sequence.backward``), the long-term step (PyTorch and onnxruntime), the pace network's outputs, and in
float64 its L1 loss and every gradient of it (the recipe's ``loss_and_grads``) (max error relative to the largest
magnitude of each array; float32 precision, < 1e-4 required). Variants are interleaved per round (order rotated, 0.15 s of settling between
variants); each round's time is the median of ``--steps`` calls (training) or of blocks of 20 calls (inference);
ratios NumPy / PyTorch are paired per round. Nothing asserts on time.

    python benchmarks/bench_long_term.py [--rounds 3] [--steps 3] [--threads 2] [--out PATH]

Writes ``benchmarks/results/bench_long_term.json`` atomically.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_threads import adapter_case, training_step  # noqa: E402
from refimpl.allocator import retain_freed_memory  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.models import pace, quaternet, quaternet_sequence  # noqa: E402

SETTLE = 0.15
TOL = 1e-4


def _rel(a, b) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-30))


# ------------------------------------------------------------------------------------------- PyTorch models
def _load(torch, mods: dict, params):
    """Copy ``params`` (PyTorch state-dict names ``module.attribute``) into the modules ``mods``; returns ``h0`` as
    a new learnable tensor (it is no module's attribute)."""
    with torch.no_grad():
        for k, v in params.items():
            if k != "h0":
                mod, attr = k.split(".", 1)
                getattr(mods[mod], attr).copy_(torch.from_numpy(v))
    return torch.nn.Parameter(torch.from_numpy(params["h0"].copy()))


def _torch_long_term(torch, params, net):
    """The long-term pose network in PyTorch with ``params``: ``forward(x (B, L, F), P) -> y (B, L - P, G)``
    (all teacher forced), ``step(x (B, F), h) -> (y, h)``, and the modules' parameters."""
    nn = torch.nn
    G, J, H, L = net.output_size, net.num_joints, net.hidden_size, net.num_layers
    fc1, fc2 = nn.Linear(net.num_controls, net.controls_hidden), nn.Linear(net.controls_hidden, net.controls_hidden)
    gru, fc = nn.GRU(G + net.controls_hidden, H, L, batch_first=True), nn.Linear(H, G)
    mods = {"fc1": fc1, "fc2": fc2, "rnn": gru, "fc": fc}
    h0 = _load(torch, mods, params)
    slope = net.negative_slope
    leaky = torch.nn.functional.leaky_relu

    def gru_input(x):
        c = leaky(fc2(leaky(fc1(x[..., G:]), slope)), slope)
        return torch.cat([x[..., :G], c], dim=-1)

    def head(top):
        o = fc(top)
        q = torch.nn.functional.normalize(o[..., :4 * J].reshape(*o.shape[:-1], J, 4), dim=-1, eps=net.eps)
        return torch.cat([q.reshape(*o.shape[:-1], 4 * J), o[..., 4 * J:]], dim=-1)

    def forward(x, P):
        B, Lx = x.shape[:2]
        y, _ = gru(gru_input(x[:, :Lx - 1]), h0.expand(L, B, H).contiguous())
        return head(y[:, P - 1:])

    def step(x, h):
        y, h = gru(gru_input(x[:, None]), h)
        return head(y[:, 0]), h

    parameters = [p for m in mods.values() for p in m.parameters()] + [h0]
    return forward, step, parameters


def _torch_pace(torch, params, config):
    """The bidirectional pace network in PyTorch with ``params``: ``forward(x (B, N, 2)) -> (B, N, 4)``."""
    nn = torch.nn
    dt = torch.float64 if params["fc.weight"].dtype == np.float64 else torch.float32
    gru = nn.GRU(config.input_size, config.hidden_size, 1, batch_first=True, bidirectional=True).to(dt)
    fc = nn.Linear(2 * config.hidden_size, config.output_size).to(dt)
    mods = {"rnn": gru, "fc": fc}
    h0 = _load(torch, mods, params)

    def forward(x):
        y, _ = gru(x, h0.expand(2, x.shape[0], config.hidden_size).contiguous())
        return fc(y)

    return forward, list(gru.parameters()) + list(fc.parameters()) + [h0]


def _long_term_grad_check(torch, params, net, x, P, mask) -> dict:
    """Both frameworks' gradients of the same L1 loss on the teacher-forced outputs (the benchmark's PyTorch loss):
    NumPy through ``quaternet_sequence.forward`` / ``backward`` (the code the FK loss of the recipe also runs)."""
    fwd, _, t_params = _torch_long_term(torch, params, net)
    G = net.output_size
    target = np.ascontiguousarray(x[:, P:, :G])
    loss_t = (fwd(torch.from_numpy(x), P) - torch.from_numpy(target)).abs().mean()
    loss_t.backward()
    y, pre, cache = quaternet_sequence.forward(params, x[:, :P], x[:, P:], mask, net)
    grads = quaternet_sequence.backward((np.sign(y - target) / y.size).astype(y.dtype), None, cache)
    names = ["fc1.weight", "fc1.bias", "fc2.weight", "fc2.bias"] + [
        f"rnn.{n}_l{k}" for k in range(net.num_layers) for n in ("weight_ih", "weight_hh", "bias_ih", "bias_hh")] + [
        "fc.weight", "fc.bias", "h0"]
    return {"long_term_loss": _rel(float(loss_t), float(np.abs(y - target).mean())),
            "long_term_grads": max(_rel(p.grad.numpy(), grads[k]) for k, p in zip(names, t_params))}


def _torch_train_step(torch, forward, parameters, x, target, lr, betas):
    opt = torch.optim.Adam(parameters, lr=lr, betas=betas)

    def step():
        opt.zero_grad()
        loss = (forward(x) - target).abs().mean()
        loss.backward()
        opt.step()
    return step


# --------------------------------------------------------------------------------------------------- timing
def _time_block(fn, steps: int, calls: int) -> float:
    time.sleep(SETTLE)
    fn()
    ts = []
    for _ in range(steps):
        t0 = time.perf_counter()
        for _ in range(calls):
            fn()
        ts.append((time.perf_counter() - t0) / calls)
    return 1e3 * statistics.median(ts)


def _rounds(variants: dict, pairs: list, rounds: int, steps: int, calls: int, label: str) -> dict:
    """Interleaved rounds (order rotated); per round every variant's median ms and the paired ratios."""
    names = list(variants)
    rows = []
    for r in range(rounds):
        order = names[r % len(names):] + names[:r % len(names)]
        row = {name: _time_block(variants[name], steps, calls) for name in order}
        for a, b in pairs:
            row[f"{a}_over_{b}"] = row[a] / row[b]
        row["load_average"] = os.getloadavg()[0]
        rows.append(row)
        print(f"{label} round {r + 1}: " + ", ".join(f"{k} {row[k]:.3f} ms" for k in names)
              + "; " + ", ".join(f"{a}/{b} {row[f'{a}_over_{b}']:.2f}" for a, b in pairs)
              + f" (load {row['load_average']:.1f})", flush=True)
    summary = {}
    for key in list(names) + [f"{a}_over_{b}" for a, b in pairs]:
        vals = [row[key] for row in rows]
        summary[key] = {"min": min(vals), "median": statistics.median(vals), "max": max(vals)}
    return {"rounds": rows, "summary": summary}


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=3, help="training steps per round and variant")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_long_term.json"))
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    import torch
    from threadpoolctl import threadpool_limits
    torch.set_num_threads(args.threads)
    threadpool_limits(limits=args.threads, user_api="blas")
    result = {"benchmark": "bench_long_term", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "threads": args.threads,
              "torch": torch.__version__, "load_average_start": os.getloadavg(), "checks": {}, "cases": {}}

    # --- long-term pose network ---------------------------------------------------------------------------
    adapter, params, config, batch, spec = adapter_case("quaternet-long")
    net = config.network()
    x, P = batch["inputs"], int(batch["prefix"])
    assert bool(np.all(batch["mask"])), "epoch 0 should be all teacher forcing"
    B, Lx, _ = x.shape
    t_fwd, t_step, t_params = _torch_long_term(torch, params, net)
    y_np = quaternet_sequence.forward(params, x[:, :P], x[:, P:], batch["mask"], net)[0]
    xt = torch.from_numpy(x)
    with torch.no_grad():
        y_t = t_fwd(xt, P).numpy()
    result["checks"]["long_term_predictions"] = _rel(y_t, y_np)
    result["checks"].update(_long_term_grad_check(torch, params, net, x, P, batch["mask"]))
    step_np = training_step(adapter, {k: v.copy() for k, v in params.items()}, batch, spec)
    target = torch.from_numpy(np.ascontiguousarray(x[:, P:, :net.output_size]))
    step_t = _torch_train_step(torch, lambda v: t_fwd(v, P), t_params, xt, target, spec.optim.lr, spec.optim.betas)
    print(f"long-term network: B {B}, prefix {P} + target {Lx - P} frames, {quaternet.count_parameters(net):,} "
          f"parameters; PyTorch vs NumPy predictions {result['checks']['long_term_predictions']:.1e}", flush=True)
    H, I, G = net.hidden_size, net.output_size + net.controls_hidden, net.output_size
    macs = 3 * H * (I + H) + (net.num_layers - 1) * 3 * H * 2 * H + H * G  # per frame and sample: GRU + head
    result["cases"]["long_term_training"] = dict(
        batch=B, prefix=P, target=Lx - P, matmul_gflop=3 * 2 * macs * B * (Lx - 1) / 1e9, **_rounds({"numpy": step_np, "torch": step_t}, [("numpy", "torch")],
                                                    args.rounds, args.steps, 1, "long-term training"))
    x1 = x[:1, P]
    h1 = quaternet.init_state(params, 1, net)
    t_step = _torch_long_term(torch, params, net)[1]  # fresh modules: the training rounds changed the others
    variants = {"numpy": lambda: quaternet.step(params, h1, x1, net)}
    try:
        from deploy.models.quaternet_long import export_pose_step
        from deploy.runtime import load_model
        ort = load_model(export_pose_step(params, net).SerializeToString(), intra_op_threads=args.threads)
        variants["onnxruntime"] = lambda: ort.run(x=x1, state=h1)
        out = ort.run(x=x1, state=h1)  # dict by output name, the prediction first
        result["checks"]["long_term_step_onnxruntime"] = _rel(next(iter(out.values())),
                                                               quaternet.step(params, h1, x1, net)[0])
    except ImportError:
        pass
    x1t, h1t = torch.from_numpy(x1), torch.from_numpy(h1)

    def torch_step():
        with torch.no_grad():
            return t_step(x1t, h1t)
    variants["torch"] = torch_step
    result["checks"]["long_term_step_torch"] = _rel(torch_step()[0].numpy(), quaternet.step(params, h1, x1, net)[0])
    pairs = [("numpy", "torch")] + ([("numpy", "onnxruntime")] if "onnxruntime" in variants else [])
    result["cases"]["long_term_step_b1"] = _rounds(variants, pairs, args.rounds, 5, 20, "long-term step B=1")

    # --- pace network -------------------------------------------------------------------------------------
    adapter, params, config, batch, spec = adapter_case("pace")
    xp, yp = batch
    t_fwd, t_params = _torch_pace(torch, params, config)
    with torch.no_grad():
        result["checks"]["pace_outputs"] = _rel(t_fwd(torch.from_numpy(xp)).numpy(), pace.forward(params, config, xp)[0])
    # gradients in float64 (a float32 BPTT over 377 steps and 15,080 summed rows differs by ≈ 2e-4 between any
    # two summation orders): the recipe's L1 loss and manual backward against autograd on the same weights
    p64 = {k: v.astype(np.float64) for k, v in params.items()}
    f64, t64 = _torch_pace(torch, p64, config)
    x64, y64 = xp.astype(np.float64), yp.astype(np.float64)
    loss_t = (f64(torch.from_numpy(x64)) - torch.from_numpy(y64)).abs().mean()
    loss_t.backward()
    loss_n, grads_n = adapter.loss_and_grads(p64, (x64, y64))
    result["checks"]["pace_loss_float64"] = _rel(float(loss_t), loss_n)
    names = [k for k in params if k != "h0"] + ["h0"]  # t64: the GRU's and fc's in state-dict order, then h0
    result["checks"]["pace_grads_float64"] = max(_rel(p.grad.numpy(), grads_n[k]) for k, p in zip(names, t64))
    t_fwd, t_params = _torch_pace(torch, params, config)  # fresh modules (no gradients) for the timed steps
    step_np = training_step(adapter, {k: v.copy() for k, v in params.items()}, batch, spec)
    step_t = _torch_train_step(torch, t_fwd, t_params, torch.from_numpy(xp), torch.from_numpy(yp), spec.optim.lr,
                               spec.optim.betas)
    print(f"pace network: B {xp.shape[0]} chunks of {xp.shape[1]} points, {pace.count_parameters(config):,} "
          f"parameters; PyTorch vs NumPy outputs {result['checks']['pace_outputs']:.1e}", flush=True)
    result["cases"]["pace_training"] = dict(
        batch=int(xp.shape[0]), chunk=int(xp.shape[1]),
        **_rounds({"numpy": step_np, "torch": step_t}, [("numpy", "torch")], args.rounds, max(args.steps, 5), 1,
                  "pace training"))
    t_fwd = _torch_pace(torch, params, config)[0]  # fresh modules: the training rounds changed the others
    path = np.random.default_rng(3).standard_normal((1, 250, 2)).astype(np.float32)
    path_t = torch.from_numpy(path)

    def torch_path():
        with torch.no_grad():
            return t_fwd(path_t)
    with torch.no_grad():
        result["checks"]["pace_path"] = _rel(t_fwd(path_t).numpy(), pace.forward(params, config, path)[0])
    variants = {"numpy": lambda: pace.forward(params, config, path), "torch": torch_path}
    try:
        from deploy.models.quaternet_long import export_pace
        from deploy.runtime import load_model
        ort_pace = load_model(export_pace(params, config).SerializeToString(), intra_op_threads=args.threads)
        result["checks"]["pace_path_onnxruntime"] = _rel(next(iter(ort_pace.run(x=path).values())),
                                                         pace.forward(params, config, path)[0])
        variants["onnxruntime"] = lambda: ort_pace.run(x=path)
    except ImportError:
        pass
    pairs = [("numpy", "torch")] + ([("numpy", "onnxruntime")] if "onnxruntime" in variants else [])
    result["cases"]["pace_path_b1"] = dict(points=250, **_rounds(variants, pairs, args.rounds, 5, 5,
                                                                 "pace 250-point path B=1"))

    bad = {k: v for k, v in result["checks"].items() if not v < TOL}
    if bad:
        raise SystemExit(f"PyTorch and NumPy disagree beyond {TOL}: {bad}")
    result["load_average_end"] = os.getloadavg()
    print("\ncase                      NumPy / PyTorch (min / median / max)")
    for case, res in result["cases"].items():
        s = res["summary"]["numpy_over_torch"]
        print(f"{case:25s} {s['min']:.2f} / {s['median']:.2f} / {s['max']:.2f}"
              + (f"   NumPy / onnxruntime {res['summary']['numpy_over_onnxruntime']['median']:.2f}"
                 if "numpy_over_onnxruntime" in res["summary"] else ""))
    atomic_write_text(Path(args.out), json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
