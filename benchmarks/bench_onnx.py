"""Benchmark: onnxruntime latency of the exported models next to the NumPy forward, and the int8 accuracy cost.

What is measured (spec/deploy.md §9), all float32 unless stated, one process, interleaved rounds (every variant
timed once per round, so that machine load hits all of them alike; medians and minima over rounds are reported).
The onnxruntime variants are interleaved with each other and the NumPy ones timed in a separate group after
them: OpenBLAS's worker threads keep spinning for a while after each NumPy product and would slow the next
onnxruntime call (seen: the 2-thread fused GRU step at 4-8 ms instead of 0.9 ms when interleaved).

* GRU 2×1000 step (QuaterNet size: input 128, 2 layers, hidden 1000) through the GRU builder (``deploy.gru``,
  fused ONNX ``GRU`` nodes, the primitive form, and the int8 / int4 ``MatMulNBits`` step, int8 also with blocks
  of 128) at batch 1 and 32, against ``refimpl.nn.gru.gru_step_forward``. Targets: ≤ 0.55 ms at batch 1,
  ≤ 2.0 ms at batch 32. Next to them a float32 floor: a NumPy ``x @ W`` over the concatenation of the four
  weight matrices (37.5 MB, the bytes a float32 step must read), at 1 and 2 BLAS threads; and the accuracy cost of
  each ORT form (max/mean ``|h_new − gru_step_forward|``, float32 NumPy, batch 32, ``x ~ N(0, 1)``,
  ``h = tanh(N(0, 1))``).
* QTG (default sizes): one step at batch 1 and 32 (step model vs ``refimpl.models.qtg.step``); a whole 30-frame
  transition at batch 1, 32 and 64: the rollout model in every form (``unrolled``, ``loop``, ``scan``; the compact
  deployment variant with float32, int8 and int4 weights) against ``rollout_inference`` (the lean NumPy path) and
  ``rollout_forward`` (the training path); the in-graph rollout against a host loop over the step model
  (init + 30 ``run`` calls). Paper: 0.33 ms per transition (Core i7-8700).
* Accuracy of every rollout form against the float64 NumPy model on real CMU/salsa transition windows (the
  embedded sample, test split) and on random contexts: max/mean absolute error in the network's pose space,
  joint-rotation angle error (degrees) and forward-kinematics joint-position error (cm), next to the model's
  own error against the ground truth. Parameters: ``--checkpoint`` (a QTG checkpoint), else a model trained for
  ``--train-steps`` steps on the sample (0: the random initialisation).

NumPy's BLAS is limited to the same number of threads as onnxruntime's intra-op pool (threadpoolctl). Besides
the ``--threads`` sessions (no spinning, the project's default), the fused and int8 GRU steps and the compact
float32 and int8 rollouts also run in sessions with two threads and spinning worker threads
(``make_session(..., intra_op_threads=2, spinning=True)``; keys ``*_2thr_spin``), the setting for one session
driven alone at batch 1. PyTorch is
timed only when installed (eager mode, ``torch.no_grad()``, the same thread count): ``torch.nn.GRU`` for the GRU
step, and the QTG rollout written with ``torch.nn.functional`` and ``GRUCell`` (checked against NumPy). Settings recorded in the JSON:
onnxruntime version and session options, BLAS libraries (threadpoolctl), BLAS environment variables, load
average before and after. Nothing asserts on time. A table is printed and JSON written atomically to
``benchmarks/results/bench_onnx.json``.

    python benchmarks/bench_onnx.py [--threads 1] [--rounds 9] [--train-steps 300] [--checkpoint PATH] [--quick]
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import onnxruntime as ort  # noqa: E402

from deploy.graph import GraphBuilder  # noqa: E402
from deploy.gru import gru_step  # noqa: E402
from deploy.models.qtg import export_qtg_init, export_qtg_rollout, export_qtg_step  # noqa: E402
from deploy.models.qtg_compact import export_qtg_rollout_compact  # noqa: E402
from deploy.runtime import make_session  # noqa: E402
from deploy.validate import validate_model  # noqa: E402
from refimpl.allocator import retain_freed_memory  # noqa: E402
from refimpl.models.qtg import QTGConfig, init_params, init_state, step  # noqa: E402
from refimpl.models.qtg_fast import rollout_forward  # noqa: E402
from refimpl.models.qtg_fast_inference import prepare_inference, rollout_inference  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.nn.gru import gru_init, gru_step_forward  # noqa: E402
from refimpl.quat import quat_normalize  # noqa: E402
from refimpl.protocols.transition import denormalize_poses, split_pose  # noqa: E402

try:
    from threadpoolctl import threadpool_info, threadpool_limits
except ImportError:  # optional
    threadpool_info = threadpool_limits = None
try:
    import torch
    HAVE_TORCH = True
except ImportError:
    torch = None
    HAVE_TORCH = False


# ------------------------------------------------------------------------------------------------- timing
def _time(fns: dict, rounds: int, min_time: float) -> dict:
    """Interleaved timing: per round, each callable runs ``reps`` times (≈ ``min_time`` s); ms per call."""
    reps = {}
    for k, fn in fns.items():
        fn()
        t0 = time.perf_counter()
        fn()
        reps[k] = max(1, int(min_time / max(time.perf_counter() - t0, 1e-6)))
    per = {k: [] for k in fns}
    for _ in range(rounds):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            for _ in range(reps[k]):
                fn()
            per[k].append((time.perf_counter() - t0) / reps[k] * 1e3)
    return {k: {"median_ms": statistics.median(v), "min_ms": min(v)} for k, v in per.items()}


def _env(threads: int) -> dict:
    blas = []
    if threadpool_info is not None:
        blas = [{k: v for k, v in i.items() if k in ("internal_api", "version", "num_threads", "architecture")}
                for i in threadpool_info()]
    return {"python": platform.python_version(), "numpy": np.__version__, "onnxruntime": ort.__version__,
            "platform": platform.platform(), "cpu_count": os.cpu_count(), "blas": blas,
            "blas_env": {k: os.environ.get(k) for k in ("OPENBLAS_CORETYPE", "OPENBLAS_L2_SIZE",
                                                        "OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")},
            "numpy_blas_threads": threads if threadpool_limits is not None else "as configured",
            "ort_session": {"intra_op_num_threads": threads, "inter_op_num_threads": 1,
                            "execution_mode": "sequential", "graph_optimization": "all",
                            "session.intra_op.allow_spinning": "0",
                            "also": "keys *_2thr_spin: 2 intra-op threads, allow_spinning 1"},
            "torch": (f"{torch.__version__}, {threads} intra-op thread(s), torch.no_grad()" if HAVE_TORCH
                      else "not installed (not timed)")}


# -------------------------------------------------------------------------------------------------- torch
def _torch_gru(params, I, H, L):
    """``torch.nn.GRU`` with the same (PyTorch-layout) parameters, or None without torch."""
    if not HAVE_TORCH:
        return None
    gru = torch.nn.GRU(I, H, L)
    with torch.no_grad():
        for name, p in gru.named_parameters():
            p.copy_(torch.from_numpy(np.ascontiguousarray(params[f"gru.{name}"])))
    return gru


def _torch_qtg_rollout(params, cfg):
    """The QTG rollout (spec/qtg.md §3) in PyTorch eager mode with the same float32 parameters, or None."""
    if not HAVE_TORCH:
        return None
    P = {k: torch.from_numpy(np.ascontiguousarray(v)) for k, v in params.items()}
    n_enc, n_dec = len(cfg.encoder_sizes), len(cfg.decoder_sizes) + 1
    lrelu = torch.nn.functional.leaky_relu
    cells = []
    for k in range(cfg.gru_layers):
        c = torch.nn.GRUCell(P[f"gru.weight_ih_l{k}"].shape[1], cfg.gru_hidden)
        with torch.no_grad():
            for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"):
                getattr(c, name).copy_(P[f"gru.{name}_l{k}"])
        cells.append(c)

    def enc(x):
        for i in range(n_enc):
            x = lrelu(torch.nn.functional.linear(x, P[f"enc.{i}.weight"], P[f"enc.{i}.bias"]), cfg.negative_slope)
        return x

    def dec(x):
        for j in range(n_dec):
            x = torch.nn.functional.linear(x, P[f"dec.{j}.weight"], P[f"dec.{j}.bias"])
            if j < n_dec - 1:
                x = lrelu(x, cfg.negative_slope)
        return x

    @torch.no_grad()
    def rollout(past, target):
        past, target = torch.from_numpy(past), torch.from_numpy(target)
        B = past.shape[0]
        z_prev, pose = enc(past[:, 0]), past[:, 1]
        e1, e2 = enc(target[:, 0]), enc(target[:, 1])
        hs = [torch.zeros(B, cfg.gru_hidden) for _ in cells]
        out = []
        for _ in range(cfg.transition_length):
            z = enc(pose)
            x = torch.cat([z - z_prev, e1 - z, e2 - e1], dim=1)
            for k, c in enumerate(cells):
                hs[k] = x = c(x, hs[k])
            pose = dec(z + torch.nn.functional.linear(x, P["vel.weight"], P["vel.bias"]))
            out.append(pose)
            z_prev = z
        return torch.stack(out, dim=1).numpy()

    return rollout


# ---------------------------------------------------------------------------------------------------- GRU
def bench_gru(threads: int, rounds: int, min_time: float) -> dict:
    """GRU 2x1000 step: ORT fused / primitive / int8 / int4 at ``threads`` and at 2 threads (the targets' setting),
    NumPy, the float32 weight-streaming floor; and the accuracy of each ORT form against float32 NumPy."""
    I, H, L = 128, 1000, 2
    rng = np.random.default_rng(0)
    params = gru_init(rng, I, H, L, "gru", dtype=np.float32)
    variants = {"fused": {}, "primitive": {"primitive": True}, "int8": {"weights": "int8"},
                "int8_b128": {"weights": "int8", "block_size": 128}, "int4": {"weights": "int4"}}
    thread_counts = sorted({threads, 2})
    tgru = _torch_gru(params, I, H, L)
    sessions = {}
    for name, kw in variants.items():
        kw = dict(kw)
        g = GraphBuilder("gru_step", primitive=kw.pop("primitive", False))
        x, h = g.input("x", ["B", I]), g.input("h", [L, "B", H])
        y, h_new = gru_step(g, x, h, params, "gru", name="gru", num_layers=L, **kw)
        g.output(h_new, "h_new", [L, "B", H])
        m = g.model()
        validate_model(m)
        for n in thread_counts:
            sessions[f"ort_{name}_{n}thr"] = make_session(m, intra_op_threads=n)
        if name in ("fused", "int8"):                     # the deployment setting for one session at batch 1
            sessions[f"ort_{name}_2thr_spin"] = make_session(m, intra_op_threads=2, spinning=True)
    # the float32 floor: one product reading every weight of the step once (K = I + 3H rows, 3H columns)
    w_all = np.ascontiguousarray(np.concatenate([params[f"gru.weight_{t}_l{k}"] for k in range(L)
                                                 for t in ("ih", "hh")], axis=1).T)  # (I + 3H, 3H) float32
    out = {"floor_weight_mb": w_all.nbytes / 1e6}
    for B in (1, 32):
        xv = rng.standard_normal((B, I)).astype(np.float32)
        hv = rng.standard_normal((L, B, H)).astype(np.float32)
        fns = {k: (lambda s=s: s.run(None, {"x": xv, "h": hv})) for k, s in sessions.items()}
        res = _time(fns, rounds, min_time)
        res.update(_time({"numpy": lambda: gru_step_forward(xv, hv, params, "gru", num_layers=L)}, rounds, min_time))
        if tgru is not None:
            xt, ht = torch.from_numpy(xv[None]), torch.from_numpy(hv)

            def torch_step():
                with torch.no_grad():
                    return tgru(xt, ht)

            res.update(_time({"torch": torch_step}, rounds, min_time))
        xa = rng.standard_normal((B, w_all.shape[0])).astype(np.float32)
        buf = np.empty((B, w_all.shape[1]), np.float32)
        for n in thread_counts:                          # BLAS threads set outside the timed call
            limit = threadpool_limits(limits=n) if threadpool_limits is not None else contextlib.nullcontext()
            with limit:
                res.update(_time({f"numpy_floor_x@W_{n}thr": lambda: np.matmul(xa, w_all, out=buf)},
                                 rounds, min_time))
        out[f"batch{B}"] = res
    B = 32                                               # accuracy cost on random inputs, one batch of 32
    xv = rng.standard_normal((B, I)).astype(np.float32)
    hv = np.tanh(rng.standard_normal((L, B, H))).astype(np.float32)
    _, ref, _ = gru_step_forward(xv, hv, params, "gru", num_layers=L)      # float32 NumPy
    acc = {}
    for name in variants:
        (h_new,) = sessions[f"ort_{name}_{thread_counts[0]}thr"].run(None, {"x": xv, "h": hv})
        d = np.abs(h_new.astype(np.float64) - ref)
        acc[name] = {"h_new_max_abs": float(d.max()), "h_new_mean_abs": float(d.mean())}
    out["accuracy_vs_numpy_float32"] = {"batch": B, "inputs": "x ~ N(0, 1), h = tanh(N(0, 1))", "errors": acc}
    return out


# ---------------------------------------------------------------------------------------------------- QTG
def _qtg_sessions(params, cfg, threads):
    kw = dict(intra_op_threads=threads)
    models = {"rollout_unrolled": export_qtg_rollout(params, cfg, mode="unrolled"),
              "rollout_unrolled_primitive": export_qtg_rollout(params, cfg, mode="unrolled", primitive=True),
              "rollout_loop": export_qtg_rollout(params, cfg, mode="loop"),
              "rollout_scan": export_qtg_rollout(params, cfg, mode="scan"),
              "compact_float32": export_qtg_rollout_compact(params, cfg, weights="float32"),
              "compact_int8": export_qtg_rollout_compact(params, cfg, weights="int8"),
              "compact_int4": export_qtg_rollout_compact(params, cfg, weights="int4")}
    info = {}
    for k, m in models.items():
        validate_model(m)
        info[k] = {"nodes": len(m.graph.node), "bytes": len(m.SerializeToString())}
    sessions = {k: make_session(m, **kw) for k, m in models.items()}
    for k in ("compact_float32", "compact_int8"):          # two threads with spinning worker threads
        sessions[f"{k}_2thr_spin"] = make_session(models[k], intra_op_threads=2, spinning=True)
    sessions["init"] = make_session(export_qtg_init(params, cfg), **kw)
    sessions["step"] = make_session(export_qtg_step(params, cfg), **kw)
    sessions["step_primitive"] = make_session(export_qtg_step(params, cfg, primitive=True), **kw)
    return sessions, info


def _host_loop(init, stp, past, target, T):
    lp, pose, hid, tl = init.run(None, {"past": past, "target": target})
    poses = []
    for _ in range(T):
        pose, lp, hid = stp.run(None, {"pose": pose, "latent_prev": lp, "hidden": hid, "target_latent": tl})
        poses.append(pose)
    return np.stack(poses, axis=1)


def bench_qtg(params32, cfg, sessions, rounds, min_time) -> dict:
    rng = np.random.default_rng(1)
    lean = prepare_inference(params32, cfg)
    trollout = _torch_qtg_rollout(params32, cfg)
    T = cfg.transition_length
    out = {}
    for B in (1, 32, 64):
        past = rng.standard_normal((B, 2, cfg.pose_size)).astype(np.float32)
        target = rng.standard_normal((B, 2, cfg.pose_size)).astype(np.float32)
        state, tl = init_state(params32, past, target, cfg)
        sf = {"pose": state.pose, "latent_prev": state.latent_prev, "hidden": state.hidden, "target_latent": tl}
        if B < 64:
            out[f"step_batch{B}"] = _time({"ort_step": lambda: sessions["step"].run(None, sf),
                                           "ort_step_primitive": lambda: sessions["step_primitive"].run(None, sf)},
                                          rounds, min_time)
            out[f"step_batch{B}"].update(_time({"numpy_step": lambda: step(params32, state, tl, cfg)}, rounds,
                                               min_time))
        feeds = {"past": past, "target": target}
        fns = {f"ort_{k}": (lambda s=sessions[k]: s.run(None, feeds))
               for k in sessions if k.startswith(("rollout", "compact"))}
        fns["ort_host_loop_step"] = lambda: _host_loop(sessions["init"], sessions["step"], past, target, T)
        out[f"rollout_batch{B}"] = _time(fns, rounds, min_time)
        out[f"rollout_batch{B}"].update(_time(
            {"numpy_rollout_inference": lambda: rollout_inference(lean, past, target),
             "numpy_rollout_forward": lambda: rollout_forward(params32, past, target, config=cfg)},
            rounds, min_time))
        if trollout is not None:
            diff = float(np.abs(trollout(past, target) - rollout_inference(lean, past, target)).max())
            out[f"rollout_batch{B}"].update(_time({"torch_eager": lambda: trollout(past, target)}, rounds, min_time))
            out[f"rollout_batch{B}"]["torch_eager"]["max_abs_diff_vs_numpy"] = diff
    return out


# ----------------------------------------------------------------------------------------------- accuracy
def _errors(pred, ref, truth, stats, skeletons, skel_index) -> dict:
    """Errors of ``pred`` vs ``ref`` (and of ``ref`` vs ``truth``) in pose space, rotation angle and FK cm."""
    res = {"pose_max_abs": float(np.abs(pred - ref).max()), "pose_mean_abs": float(np.abs(pred - ref).mean())}

    def angles(a, b):
        qa, qb = quat_normalize(split_pose(a)[1]), quat_normalize(split_pose(b)[1])
        dot = np.clip(np.abs(np.sum(qa * qb, axis=-1)), 0.0, 1.0)
        return np.degrees(2 * np.arccos(dot))

    ang = angles(pred, ref)
    res.update(angle_max_deg=float(ang.max()), angle_mean_deg=float(ang.mean()))
    if stats is not None and skeletons is not None:
        def fk(poses):
            raw = denormalize_poses(poses, *stats)
            root, q = split_pose(raw)
            out = np.empty(q.shape[:-1] + (3,))
            for k, sk in enumerate(skeletons):
                sel = skel_index == k
                if np.any(sel):
                    out[sel] = sk.forward_kinematics(quat_normalize(q[sel]), root[sel])
            return out

        d = np.linalg.norm(fk(pred) - fk(ref), axis=-1)
        res.update(fk_max_cm=float(d.max()), fk_mean_cm=float(d.mean()))
        if truth is not None:
            e = np.linalg.norm(fk(ref) - fk(truth), axis=-1)
            res["model_vs_truth_fk_mean_cm"] = float(e.mean())
    return res


def accuracy(params64, cfg, sessions, data) -> dict:
    out = {}
    contexts = {}
    if data is not None:
        past, trans, target = data.context(normalized=True)
        contexts["cmu_sample_test"] = (past, target, trans, (data.root_mean, data.root_std), data.skeletons,
                                       data.skeleton_index)
    rng = np.random.default_rng(2)
    contexts["random"] = (rng.standard_normal((16, 2, cfg.pose_size)), rng.standard_normal((16, 2, cfg.pose_size)),
                          None, None, None, None)
    for name, (past, target, truth, stats, skels, sidx) in contexts.items():
        ref, _ = rollout_forward(params64, past, target, config=cfg)
        feeds = {"past": past.astype(np.float32), "target": target.astype(np.float32)}
        res = {}
        for k, s in sessions.items():
            if k.startswith(("rollout", "compact")) and not k.endswith("_spin"):
                pred = s.run(None, feeds)[0].astype(np.float64)
                res[k] = _errors(pred, ref, truth, stats, skels, sidx)
        host = _host_loop(sessions["init"], sessions["step"], feeds["past"], feeds["target"], cfg.transition_length)
        res["host_loop_step"] = _errors(host.astype(np.float64), ref, truth, stats, skels, sidx)
        out[name] = {"windows": int(past.shape[0]), "errors_vs_numpy_float64": res}
    return out


def _model_params(args, cfg):
    """``(params float64, description, test data or None)``."""
    data = None
    try:
        from refimpl.protocols.transition import build_transition_datasets, sample_sources
        train, data = build_transition_datasets(*sample_sources(), stride=5, test_stride=10)
    except Exception as exc:  # the sample is part of the package; keep the benchmark running regardless
        print(f"note: no sample data ({exc}); accuracy on random contexts only", file=sys.stderr)
        train = None
    if args.checkpoint:
        from deploy.models.qtg_io import load_checkpoint as load_qtg_checkpoint
        params, ck_cfg, _ = load_qtg_checkpoint(args.checkpoint)
        if ck_cfg != cfg:
            raise SystemExit("--checkpoint: only the default QTGConfig is benchmarked")
        return {k: np.asarray(v, np.float64) for k, v in params.items()}, f"checkpoint {args.checkpoint}", data
    if args.train_steps > 0 and train is not None:
        from refimpl.recipes.qtg import train_qtg
        with tempfile.TemporaryDirectory() as d:
            res = train_qtg(train, args.train_steps, config=cfg, dtype=np.float32, progress=None,
                            checkpoint_path=str(Path(d) / "ck.npz"), checkpoint_every=10 ** 9)
        desc = f"trained {args.train_steps} steps on the embedded sample (final loss {res.losses[-1]:.4g})"
        return {k: np.asarray(v, np.float64) for k, v in res.params.items()}, desc, data
    return init_params(cfg, np.random.default_rng(0)), "random initialisation (seed 0)", data


# ------------------------------------------------------------------------------------------------- report
def _table(result) -> str:
    lines = []
    g = result["gru_2x1000_step"]
    lines.append("GRU 2x1000 step (input 128)       batch 1 ms (min)     batch 32 ms (min)   (targets 0.55 / 2.0)")
    for k in g["batch1"]:
        b1, b32 = g["batch1"][k], g["batch32"][k]
        lines.append(f"  {k:30s} {b1['median_ms']:8.3f} ({b1['min_ms']:.3f}) {b32['median_ms']:10.3f} "
                     f"({b32['min_ms']:.3f})")
    lines.append(f"  (numpy_floor_x@W: x @ W over all {g['floor_weight_mb']:.1f} MB of float32 weights)")
    a = g["accuracy_vs_numpy_float32"]
    lines.append(f"GRU 2x1000 step accuracy vs float32 NumPy (batch {a['batch']}, {a['inputs']}): "
                 "max / mean |h_new diff|")
    for k, e in a["errors"].items():
        lines.append(f"  {k:30s} {e['h_new_max_abs']:.2e} / {e['h_new_mean_abs']:.2e}")
    q = result["qtg"]
    for B in (1, 32, 64):
        st = q.get(f"step_batch{B}")
        if st:
            lines.append(f"QTG step, batch {B}: ort {st['ort_step']['median_ms']:.3f} ms (primitive GRU "
                         f"{st['ort_step_primitive']['median_ms']:.3f}), numpy {st['numpy_step']['median_ms']:.3f} "
                         f"ms (numpy/ort {st['numpy_step']['median_ms'] / st['ort_step']['median_ms']:.2f}x)")
        ro = q[f"rollout_batch{B}"]
        base = ro["numpy_rollout_inference"]["median_ms"]
        lines.append(f"QTG 30-frame transition, batch {B}       median ms    min ms   numpy_lean/this")
        for k, v in ro.items():
            lines.append(f"  {k:34s} {v['median_ms']:9.3f} {v['min_ms']:9.3f} {base / v['median_ms']:9.2f}")
    acc = result["accuracy"]
    for name, a in acc.items():
        lines.append(f"accuracy vs float64 NumPy ({name}, {a['windows']} windows): max|d| pose, mean angle deg, "
                     f"mean FK cm")
        for k, e in a["errors_vs_numpy_float64"].items():
            fk = f"{e['fk_mean_cm']:.4f}" if "fk_mean_cm" in e else "-"
            lines.append(f"  {k:22s} {e['pose_max_abs']:.2e}  {e['angle_mean_deg']:.2e}  {fk}")
        first = next(iter(a["errors_vs_numpy_float64"].values()))
        if "model_vs_truth_fk_mean_cm" in first:
            lines.append(f"  (the float64 model itself vs the ground truth: {first['model_vs_truth_fk_mean_cm']:.2f} cm)")
    return "\n".join(lines)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1, help="onnxruntime intra-op threads")
    ap.add_argument("--rounds", type=int, default=9)
    ap.add_argument("--min-time", type=float, default=0.1, help="seconds per variant per round")
    ap.add_argument("--train-steps", type=int, default=300)
    ap.add_argument("--checkpoint", default=None)
    ap.add_argument("--quick", action="store_true", help="3 rounds, short rounds, no training")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_onnx.json"))
    args = ap.parse_args(argv)
    retain_freed_memory()  # the command line's allocator setting (spec/cli.md §1, benchmarks/bench_allocator.py)
    if args.quick:
        args.rounds, args.min_time, args.train_steps = 3, 0.03, 0
    load_before = os.getloadavg()
    if threadpool_limits is not None:                  # NumPy's BLAS gets as many threads as onnxruntime
        threadpool_limits(limits=args.threads)
    if HAVE_TORCH:                                     # and so does PyTorch
        torch.set_num_threads(args.threads)
    cfg = QTGConfig()
    params64, desc, data = _model_params(args, cfg)
    params32 = {k: v.astype(np.float32) for k, v in params64.items()}
    sessions, info = _qtg_sessions(params32, cfg, args.threads)
    result = {"environment": _env(args.threads), "load_average_before": load_before, "model": desc,
              "gru_2x1000_step": bench_gru(args.threads, args.rounds, args.min_time),
              "qtg": bench_qtg(params32, cfg, sessions, args.rounds, args.min_time),
              "qtg_models": info,
              "accuracy": accuracy(params64, cfg, sessions, data),
              "load_average_after": os.getloadavg()}
    print(_table(result))
    print(f"load average before {load_before}, after {result['load_average_after']}; model: {desc}")
    out = Path(args.out)
    atomic_write_text(out, json.dumps(result, indent=2), make_parents=True)
    print(f"wrote {out}")
    return result


if __name__ == "__main__":
    main()
