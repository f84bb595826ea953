"""Benchmark table of issue #17 in one command: every per-model benchmark, the machine's peaks, one table.

Runs the benchmarks of ``benchmarks/`` one after the other, each in its own process (``bench_qtg`` — with
``--train`` when it has it —, ``bench_quaternet``, ``bench_quaternet_cnn``, ``bench_gru_train``,
``bench_lstm_train``, ``bench_acrnn``, ``bench_long_term``, ``bench_adam``, ``bench_onnx``, ``bench_locomotion``), with few rounds
(``--rounds``; each benchmark gets the options it has: ``--rounds``/``--iters``/``--train-rounds``, ``--threads``,
``--out``), collects the JSON each writes, measures the machine's peaks before and after them in the same run —
float32 GEMM (NumPy ``sgemm`` 2048², best of several, with 1 and with 2 BLAS threads), DRAM bandwidth (a 2 × 256 MB
copy split over 2 threads and over 1; read + write bytes counted) and the batch-1 weight-reading floor (a NumPy
``(1, K) @ (K, N)`` product over a weight matrix of the model's size, 1 and 2 threads) — and prints one table:

    workload | project NumPy | PyTorch eager | onnxruntime | NumPy / PyTorch | limit here | NumPy's share | threads

* times are the benchmarks' own medians (each benchmark interleaves its variants; the ratio column is the
  paired per-round median when the benchmark records one, else the ratio of the medians — marked ``~``);
* *limit here* is computed from the peaks measured in this run (the best of the before/after measurements): for
  training and batch ≥ 32 the matrix-product FLOPs of the workload over the GEMM peak at the row's thread count;
  for Adam the bytes it must move (28 per parameter) over the DRAM bandwidth; for batch-1 steps the weights read
  per step over the DRAM bandwidth when they exceed the 32 MiB L3, else the measured weight-reading floor;
  *share* = limit / the best of the project's times (NumPy, or onnxruntime for deployment rows);
* a field a benchmark does not (yet) write is reported under "missing" instead of a number.

The machine is shared: the load average before and after every benchmark is in the JSON and under the table.
Nothing asserts on time. JSON: ``benchmarks/results/bench_all.json`` (the benchmarks' own files go to
``--results`` so that a quick run does not overwrite the recorded full runs in ``benchmarks/results/``).

    python benchmarks/bench_all.py [--rounds 2] [--threads 2] [--only onnx,adam] [--skip acrnn] [--table-only]
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

from refimpl.atomic import atomic_write_text  # noqa: E402

try:
    from threadpoolctl import threadpool_limits
except ImportError:  # optional extra; then the BLAS default is measured twice
    threadpool_limits = None

L3_BYTES = 32 * 2 ** 20
#: name -> (script, JSON files it writes (first: the main one)).
BENCHMARKS = {
    "qtg": ("bench_qtg.py", ("bench_qtg.json", "bench_qtg_train.json")),
    "quaternet": ("bench_quaternet.py", ("bench_quaternet.json",)),
    "quaternet_cnn": ("bench_quaternet_cnn.py", ("bench_quaternet_cnn.json",)),
    "gru_train": ("bench_gru_train.py", ("bench_gru_train.json",)),
    "long_term": ("bench_long_term.py", ("bench_long_term.json",)),
    "lstm_train": ("bench_lstm_train.py", ("bench_lstm_train.json",)),
    "acrnn": ("bench_acrnn.py", ("bench_acrnn.json",)),
    "adam": ("bench_adam.py", ("bench_adam.json",)),
    "onnx": ("bench_onnx.py", ("bench_onnx.json",)),
    "locomotion": ("bench_locomotion.py", ("bench_locomotion.json",)),
}


# ---------------------------------------------------------------------------------------------------- peaks
def _limit(n):
    return threadpool_limits(limits=n) if threadpool_limits is not None else _Null()


class _Null:
    def __enter__(self):
        return self

    def __exit__(self, *a):
        return False


def _best(fn, reps: int) -> float:
    fn()
    best = float("inf")
    for _ in range(reps):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def measure_peaks(reps: int = 5) -> dict:
    """GEMM float32 GF/s (1 and 2 threads), copy bandwidth GB/s (1 and 2 threads), batch-1 weight floors."""
    rng = np.random.default_rng(0)
    n = 2048
    a, b = (rng.standard_normal((n, n)).astype(np.float32) for _ in range(2))
    c = np.empty((n, n), np.float32)
    out = {}
    for t in (1, 2):
        with _limit(t):
            out[f"gemm_f32_gflops_{t}thr"] = 2 * n ** 3 / _best(lambda: np.matmul(a, b, out=c), reps) / 1e9
    del a, b, c
    m = 64 * 2 ** 20                                          # 256 MB of float32 per array
    src, dst = np.ones(m, np.float32), np.zeros(m, np.float32)
    for t in (1, 2):
        chunks = np.array_split(np.arange(m), t)
        bounds = [(int(ch[0]), int(ch[-1]) + 1) for ch in chunks]

        def copy():
            ths = [threading.Thread(target=np.copyto, args=(dst[lo:hi], src[lo:hi])) for lo, hi in bounds]
            for th in ths:
                th.start()
            for th in ths:
                th.join()

        out[f"copy_gb_s_{t}thr"] = 2 * src.nbytes / _best(copy, reps) / 1e9
    del src, dst
    # batch-1 floor: read a weight matrix of the model's size once (QTG step: 538,112 weights, 2.15 MB)
    for name, (K, N) in {"qtg_step_2.15MB": (538, 1000), "gru2x1000_step_37.5MB": (3128, 3000)}.items():
        w = rng.standard_normal((K, N)).astype(np.float32)
        x = rng.standard_normal((1, K)).astype(np.float32)
        y = np.empty((1, N), np.float32)
        for t in (1, 2):
            with _limit(t):
                out[f"gemv_floor_ms_{name}_{t}thr"] = _best(lambda: np.matmul(x, w, out=y), 4 * reps) * 1e3
    return out


def best_peaks(before: dict, after: dict | None) -> dict:
    """Per quantity the best of the two measurements (highest rate, lowest floor time)."""
    if not after:
        return dict(before)
    return {k: (min if k.startswith("gemv") else max)(before[k], after.get(k, before[k])) for k in before}


# --------------------------------------------------------------------------------------------- running them
def _options(script: Path) -> str:
    try:
        return subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True,
                              timeout=120, env=_env(), cwd=str(ROOT)).stdout
    except subprocess.TimeoutExpired:
        return ""


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def command(name: str, args, help_text: str, results: Path) -> list[str]:
    """The command line of benchmark ``name`` with the options it has."""
    script, files = BENCHMARKS[name]
    cmd = [sys.executable, str(ROOT / "benchmarks" / script)]
    has = lambda opt: f"{opt} " in help_text or f"{opt}\n" in help_text or f"{opt}]" in help_text  # noqa: E731
    if name == "qtg" and has("--train"):
        cmd += ["--train"] + (["--train-rounds", str(args.rounds)] if has("--train-rounds") else [])
    elif has("--rounds"):
        cmd += ["--rounds", str(args.rounds)]
    elif has("--iters"):
        cmd += ["--iters", str(max(2, args.rounds))]
    if has("--threads") and args.threads:
        cmd += ["--threads", str(args.threads)]
    if name == "gru_train" and has("--no-float64"):
        cmd += ["--no-float64"]
    if name == "onnx" and has("--train-steps"):
        cmd += ["--train-steps", str(args.onnx_train_steps)]
    if has("--out"):
        cmd += ["--out", str(results / files[0])]
    return cmd


def run_benchmark(name: str, args, results: Path) -> dict:
    script, files = BENCHMARKS[name]
    path = ROOT / "benchmarks" / script
    if not path.is_file():
        return {"status": "absent", "script": script}
    cmd = command(name, args, _options(path), results)
    load0, t0 = os.getloadavg(), time.perf_counter()
    print(f"[{name}] {' '.join(cmd[1:])}", flush=True)
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=args.timeout, env=_env(), cwd=str(ROOT))
        status = "ok" if proc.returncode == 0 else f"exit {proc.returncode}"
        tail = (proc.stdout + proc.stderr).strip().splitlines()[-12:]
    except subprocess.TimeoutExpired:
        status, tail = f"timeout after {args.timeout} s", []
    if "--out" not in cmd:                                # it wrote into benchmarks/results: copy it over
        for f in files:
            src = ROOT / "benchmarks" / "results" / f
            if src.is_file() and src.stat().st_mtime >= time.time() - (time.perf_counter() - t0) - 1:
                shutil.copyfile(src, results / f)
    info = {"status": status, "command": cmd[1:], "seconds": time.perf_counter() - t0, "load_before": load0,
            "load_after": os.getloadavg()}
    if status != "ok":
        info["output_tail"] = tail
    print(f"[{name}] {status} in {info['seconds']:.0f} s (load {load0[0]:.1f} -> {info['load_after'][0]:.1f})",
          flush=True)
    return info


# ----------------------------------------------------------------------------------------------- extraction
def _get(d, path, default=None):
    for k in path.split("/"):
        if not isinstance(d, dict) or k not in d:
            return default
        d = d[k]
    return d


def _load(results: Path, name: str):
    p = results / name
    return json.loads(p.read_text()) if p.is_file() else None


def _row(workload, numpy=None, torch=None, ort=None, ratio=None, paired=False, limit=None, basis="", threads="",
         missing=(), ort_is_project=False, note="", goal=None):
    """One table row; ``goal``: the issue's ratio goal NumPy / PyTorch (training rows), for the share it needs."""
    return {"workload": workload, "numpy_ms": numpy, "torch_ms": torch, "ort_ms": ort, "ratio": ratio,
            "ratio_paired": paired, "limit_ms": limit, "limit_basis": basis, "threads": threads,
            "missing": list(missing), "ort_is_project": ort_is_project, "note": note, "goal": goal}


def _floor_note(label, value):
    return f"{label} {value:.2f}×" if value is not None else ""


def _gemm_limit(gflop, peaks, threads):
    t = 2 if str(threads).startswith("2") else 1
    return gflop / peaks[f"gemm_f32_gflops_{t}thr"] * 1e3, f"{gflop:.3g} GFLOP / GEMM {t}thr"


def gru_macs_per_frame(I, H, L, O):
    """Matrix-product MACs per frame and sample of an L-layer GRU (input I, hidden H) with an O-output head."""
    return 3 * H * (I + H) + (L - 1) * 3 * H * 2 * H + H * O


def rows_from(results: Path, peaks: dict) -> list[dict]:
    rows = []
    # --- QTG training step (bench_qtg --train) and transitions (bench_onnx) --------------------------------
    qt = _load(results, "bench_qtg_train.json")
    tr = _get(qt, "train")
    if tr:
        B, T = tr.get("batch", 32), tr.get("T", 30)
        med = lambda key: statistics.median(r[key] for r in tr["rounds"])  # noqa: E731
        gflop = 3 * 2 * 636416 * B * T / 1e9
        lim, basis = _gemm_limit(gflop, peaks, tr.get("threads", 2))
        rows.append(_row(f"QTG training step, paper size, B={B} (≤ 0.5×)", med("numpy_ms"), med("torch_ms"),
                         ratio=_get(tr, "numpy_over_torch/median"), paired=True, limit=lim, basis=basis,
                         threads=f"{tr.get('threads')}", goal=0.5,
                         note=_floor_note("its matrix products alone / PyTorch", _get(tr, "products_over_torch/median"))))
    else:
        rows.append(_row("QTG training step, paper size, B=32", missing=["bench_qtg_train.json: train (bench_qtg has "
                                                                        "no --train on this branch)"]))
    on = _load(results, "bench_onnx.json")
    thr = _get(on, "environment/ort_session/intra_op_num_threads", "?")
    for B, target in ((1, "≤ 1.5 ms f32"), (64, "≤ 20 ms")):
        ro = _get(on, f"qtg/rollout_batch{B}")
        if not ro:
            rows.append(_row(f"QTG 30-frame transition, B={B}", missing=[f"bench_onnx.json: qtg/rollout_batch{B}"]))
            continue
        f32 = {k: v["median_ms"] for k, v in ro.items() if k.startswith("ort_") and "int" not in k
               and "host_loop" not in k}
        best = min(f32, key=f32.get) if f32 else None
        num = _get(ro, "numpy_rollout_inference/median_ms")
        tor = _get(ro, "torch_eager/median_ms")
        if B == 1:
            t = 2 if str(thr) == "2" or (best or "").endswith("_spin") else 1
            lim, basis = 30 * peaks[f"gemv_floor_ms_qtg_step_2.15MB_{t}thr"], f"30 × weight floor (2.15 MB, {t}thr)"
        else:
            lim, basis = _gemm_limit(2 * 636416 * B * 30 / 1e9, peaks, thr)
        rows.append(_row(f"QTG 30-frame transition, B={B} ({target})", num, tor, f32.get(best),
                         ratio=num / tor if num and tor else None, limit=lim, basis=basis,
                         threads=f"{thr}" + (", ort 2 + spinning" if best and best.endswith("_spin") else ""),
                         note=f"ort best float32 form: {best[4:] if best else None}"))
        q8 = {k: v["median_ms"] for k, v in ro.items() if k.startswith("ort_compact_int")}
        if q8:
            k8 = min(q8, key=q8.get)
            rows.append(_row(f"QTG transition, B={B}, quantised ({k8[12:]})", ort=q8[k8], threads=f"{thr}",
                             ort_is_project=True, note="stretch ≤ 0.5 ms at B=1" if B == 1 else ""))
    # --- GRU 2x1000 step (bench_onnx) ---------------------------------------------------------------------
    g1 = _get(on, "gru_2x1000_step/batch1")
    if g1:
        f32 = {k: v["median_ms"] for k, v in g1.items() if k.startswith(("ort_fused", "ort_primitive"))}
        q8 = {k: v["median_ms"] for k, v in g1.items() if k.startswith("ort_int8")}
        best, b8 = min(f32, key=f32.get), min(q8, key=q8.get)
        lim = 37.5e6 / (peaks["copy_gb_s_2thr"] * 1e9) * 1e3                # bytes moved per second by a copy
        num, tor = _get(g1, "numpy/median_ms"), _get(g1, "torch/median_ms")
        rows.append(_row("GRU 2×1000 step, B=1 (≤ 1.3 ms f32)", num, tor, f32[best],
                         ratio=num / tor if num and tor else None, limit=lim,
                         basis="37.5 MB / DRAM bandwidth (2thr)", threads=f"ort {best[-4:]}, numpy "
                         f"and torch {thr}", note=f"{1e3 / f32[best]:.0f} frames/s float32"))
        rows.append(_row("GRU 2×1000 step, B=1, int8 (≥ 2,000 frames/s)", ort=g1[b8]["median_ms"], threads=b8[-4:],
                         ort_is_project=True, note=f"{1e3 / g1[b8]['median_ms']:.0f} frames/s"))
    else:
        rows.append(_row("GRU 2×1000 step, B=1", missing=["bench_onnx.json: gru_2x1000_step/batch1"]))
    # --- QuaterNet (bench_quaternet) ------------------------------------------------------------------------
    qn = _load(results, "bench_quaternet.json")
    r = _get(qn, "results_ms") or {}
    qthr = _get(qn, "threads", "?")
    if r:
        for key, label in (("step B=1", "QuaterNet step, B=1"), ("step B=32", "QuaterNet step, B=32"),
                           ("train iter B=60", "QuaterNet GRU training iteration, B=60, 50+10 frames")):
            num, tor, ort = (_get(r, f"{key} {v}/median") for v in ("numpy", "pytorch", "onnxruntime"))
            lim = basis = None
            if key.startswith("train"):
                lim, basis = _gemm_limit(3 * 2 * gru_macs_per_frame(128, 1000, 2, 128) * 60 * 60 / 1e9, peaks, qthr)
                label += " (≤ 0.6×)"
            rows.append(_row(label, num, tor, ort, ratio=num / tor if num and tor else None, limit=lim,
                             basis=basis or "", threads=str(qthr), goal=0.6 if key.startswith("train") else None))
    else:
        rows.append(_row("QuaterNet step / training iteration", missing=["bench_quaternet.json: results_ms"]))
    # --- QuaterNet CNN (bench_quaternet_cnn) ---------------------------------------------------------------
    cn = _load(results, "bench_quaternet_cnn.json")
    if cn:
        s = cn["summary"]
        lim, basis = _gemm_limit(cn["matmul_gflop_per_iteration"], peaks, cn["threads"])
        rows.append(_row(f"QuaterNet CNN training iteration, B={cn['config']['batch']} (≤ 0.67× PyTorch)",
                         s["numpy_ms"]["median"], s["torch_ms"]["median"], ratio=s["numpy_over_torch"]["median"],
                         paired=True, limit=lim, basis=basis, threads=str(cn["threads"]), goal=0.67))
    else:
        rows.append(_row("QuaterNet CNN training iteration", missing=["bench_quaternet_cnn.json"]))
    # --- GRU training (bench_gru_train) -------------------------------------------------------------------
    gt = _load(results, "bench_gru_train.json")
    num, tor = _get(gt, "numpy/float32/ms_median/iteration"), _get(gt, "torch/ms_median")
    if num:
        c = _get(gt, "config", {})
        gflop = _get(gt, "matmul_gflop_per_iteration")
        thr_g = _get(gt, "torch/threads", "?")
        lim, basis = _gemm_limit(gflop, peaks, thr_g)
        rows.append(_row(f"QuaterNet GRU 2×1000 training iteration, B={c.get('B')} T={c.get('T')} (≤ 0.6×)", num,
                         tor, ratio=num / tor if tor else None, limit=lim, basis=basis, threads=str(thr_g),
                         missing=[] if tor else ["bench_gru_train.json: torch/ms_median"], goal=0.6))
    else:
        rows.append(_row("QuaterNet GRU training iteration", missing=["bench_gru_train.json: numpy/float32"]))
    # --- LSTM training (bench_lstm_train) and step (bench_acrnn) ------------------------------------------------
    lt = _load(results, "bench_lstm_train.json")
    if _get(lt, "summary"):
        c = _get(lt, "config", {})
        num = _get(lt, "summary/seconds.numpy_fast/median")
        tor = _get(lt, "summary/seconds.torch/median")
        lim, basis = _gemm_limit(_get(lt, "matmul_gflop_per_iteration"), peaks, _get(lt, "threads", 2))
        rows.append(_row(f"LSTM 3×1024 sequence training iteration (acRNN size, teacher-forced), B={c.get('B')} "
                         f"T={c.get('T')} (≤ 0.85×)",
                         num * 1e3 if num else None, tor * 1e3 if tor else None,
                         ratio=_get(lt, "summary/fast_over_torch/median"), paired=True, limit=lim, basis=basis,
                         threads=str(_get(lt, "threads")), goal=0.85,
                         note="PyTorch: oneDNN nn.LSTM over the whole sequence"))
        num, tor = (_get(lt, f"summary/seconds.{k}/median") for k in ("acrnn_numpy", "acrnn_torch"))
        if num and tor:
            a_lim, a_basis = _gemm_limit(_get(lt, "config/acrnn/matmul_gflop", 425.7), peaks, _get(lt, "threads", 2))
            rows.append(_row(f"acRNN training iteration (auto-conditioning 5/5), B={c.get('B')} T={c.get('T')} "
                             f"(≤ 0.85×)", num * 1e3, tor * 1e3, ratio=_get(lt, "summary/acrnn_numpy_over_torch/median"),
                             paired=True, limit=a_lim, basis=a_basis, threads=str(_get(lt, "threads")), goal=0.85,
                             note="as acRNN trains: own predictions fed back every other 5 frames"))
    else:
        rows.append(_row("acRNN LSTM training iteration", missing=["bench_lstm_train.json: summary"]))
    ac = _load(results, "bench_acrnn.json")
    st = _get(ac, "step_batch1/median_ms")
    if st:
        num, tor = st.get("numpy"), st.get("torch")
        lim = 89.1e6 / (peaks["copy_gb_s_2thr"] * 1e9) * 1e3
        rows.append(_row("acRNN LSTM 3×1024 step, B=1", num, tor, st.get("onnxruntime"),
                         ratio=num / tor if num and tor else None, limit=lim,
                         basis="89.1 MB / DRAM bandwidth (2thr)", threads="BLAS default / 1 (bench_acrnn)"))
    else:
        rows.append(_row("acRNN LSTM step, B=1", missing=["bench_acrnn.json: step_batch1"]))
    # --- Adam (bench_adam) ------------------------------------------------------------------------------
    ad = _load(results, "bench_adam.json")
    s = _get(ad, "summary")
    if s:
        num_key = "numpy_2threads" if "numpy_2threads" in s else next((k for k in s if k.startswith("numpy")), None)
        n = _get(ad, "n_params", 9526128)
        lim = _get(ad, "bytes_per_param", 28) * n / (peaks["copy_gb_s_2thr"] * 1e9) * 1e3
        rows.append(_row(f"Adam, {n / 1e6:.1f} M parameters (≤ 1.5× fused)", _get(s, f"{num_key}/median"),
                         _get(s, "torch_fused/median"), ratio=_get(s, "numpy_over_torch_fused/median"), paired=True,
                         limit=lim, basis="28 B/parameter / DRAM bandwidth (2thr)",
                         threads=f"numpy {num_key}, torch {_get(ad, 'torch_threads')}",
                         note="; ".join(x for x in ("PyTorch: fused Adam", _floor_note(
                             "12 np.add passes alone / fused", _get(s, "twelve_adds_over_torch_fused/median"))) if x)))
    else:
        rows.append(_row("Adam", missing=["bench_adam.json: summary"]))
    # --- long-term and pace networks against PyTorch (bench_long_term) ---------------------------------------
    lg = _load(results, "bench_long_term.json")
    if _get(lg, "cases"):
        thr_l = str(_get(lg, "threads", "?"))
        c = lg["cases"]
        s = lambda case, key: _get(c, f"{case}/summary/{key}/median")  # noqa: E731
        if "long_term_training" in c:
            t = c["long_term_training"]
            lim, basis = (_gemm_limit(t["matmul_gflop"], peaks, thr_l) if t.get("matmul_gflop") else (None, ""))
            rows.append(_row(f"QuaterNet long-term training iteration, B={t['batch']}, {t['prefix']}+{t['target']} "
                             f"frames", s("long_term_training", "numpy"), s("long_term_training", "torch"),
                             ratio=s("long_term_training", "numpy_over_torch"), paired=True, limit=lim, basis=basis,
                             threads=thr_l, note="PyTorch: same network, L1 loss instead of the FK loss"))
        if "long_term_step_b1" in c:
            rows.append(_row("QuaterNet long-term step, B=1", s("long_term_step_b1", "numpy"),
                             s("long_term_step_b1", "torch"), s("long_term_step_b1", "onnxruntime"),
                             ratio=s("long_term_step_b1", "numpy_over_torch"), paired=True, threads=thr_l))
        if "pace_training" in c:
            t = c["pace_training"]
            rows.append(_row(f"pace network training iteration, B={t['batch']}, {t['chunk']} points",
                             s("pace_training", "numpy"), s("pace_training", "torch"),
                             ratio=s("pace_training", "numpy_over_torch"), paired=True, threads=thr_l))
        if "pace_path_b1" in c:
            rows.append(_row(f"pace network over a {c['pace_path_b1'].get('points')}-point path, B=1",
                             s("pace_path_b1", "numpy"), s("pace_path_b1", "torch"), s("pace_path_b1", "onnxruntime"),
                             ratio=s("pace_path_b1", "numpy_over_torch"), paired=True, threads=thr_l))
    else:
        rows.append(_row("QuaterNet long-term and pace networks", missing=["bench_long_term.json: cases"]))
    # --- locomotion (bench_locomotion) ----------------------------------------------------------------------
    lo = _load(results, "bench_locomotion.json")
    r = _get(lo, "results")
    if r:
        for H in ("H1000", "H256"):
            num, ort = _get(r, f"{H} numpy step/ms_per_frame"), _get(r, f"{H} ort step/ms_per_frame")
            if num:
                rows.append(_row(f"QuaterNet long-term step ({H}), B=1", num, None, ort, threads="BLAS default",
                                 missing=["bench_locomotion.json: no PyTorch timing"]))
    else:
        rows.append(_row("QuaterNet long-term step", missing=["bench_locomotion.json: results"]))
    for row in rows:
        mine = [v for v in (row["numpy_ms"], row["ort_ms"] if row["ort_is_project"] or row["ort_ms"] else None)
                if v]
        row["share_of_limit"] = (row["limit_ms"] / min(mine)) if row["limit_ms"] and mine else None
        if row["goal"] and row["limit_ms"] and row["torch_ms"]:
            # NumPy at goal × PyTorch's time would run at (PyTorch's share) / goal of the limit
            row["torch_share_of_limit"] = row["limit_ms"] / row["torch_ms"]
            row["share_needed_for_goal"] = row["torch_share_of_limit"] / row["goal"]
            need = (f"PyTorch at {100 * row['torch_share_of_limit']:.0f} % of the limit, so ≤ {row['goal']}× needs "
                    f"{100 * row['share_needed_for_goal']:.0f} %")
            row["note"] = "; ".join(x for x in (row["note"], need) if x)
    return rows


def _fmt(v, digits=3):
    if v is None:
        return "–"
    return f"{v:.{digits}g}" if v < 100 else f"{v:.0f}"


def table(rows, peaks, loads) -> str:
    head = ("| workload | project NumPy ms | PyTorch eager ms | onnxruntime ms | NumPy / PyTorch | limit here ms | "
            "share of limit | threads |")
    lines = [head, "|" + "---|" * 8]
    for r in rows:
        ratio = "–" if r["ratio"] is None else ("" if r["ratio_paired"] else "~") + f"{r['ratio']:.2f}"
        lim = "–" if r["limit_ms"] is None else f"{_fmt(r['limit_ms'])} ({r['limit_basis']})"
        share = "–" if r.get("share_of_limit") is None else f"{100 * r['share_of_limit']:.0f} %"
        extra = "; ".join(x for x in (r["note"], *(f"missing: {m}" for m in r["missing"])) if x)
        lines.append(f"| {r['workload']}{' — ' + extra if extra else ''} | {_fmt(r['numpy_ms'])} | "
                     f"{_fmt(r['torch_ms'])} | {_fmt(r['ort_ms'])} | {ratio} | {lim} | {share} | {r['threads']} |")
    lines.append("")
    lines.append("peaks measured in this run (best of before/after): GEMM float32 "
                 f"{peaks['gemm_f32_gflops_1thr']:.0f} GF/s (1 thread), {peaks['gemm_f32_gflops_2thr']:.0f} GF/s "
                 f"(2 threads); copy bandwidth {peaks['copy_gb_s_1thr']:.1f} GB/s (1 thread), "
                 f"{peaks['copy_gb_s_2thr']:.1f} GB/s (2 threads); batch-1 weight floor QTG step "
                 f"{peaks['gemv_floor_ms_qtg_step_2.15MB_1thr'] * 1e3:.0f} µs (1 thread), GRU 2×1000 step "
                 f"{peaks['gemv_floor_ms_gru2x1000_step_37.5MB_2thr']:.2f} ms (2 threads)")
    lines.append(f"load average: {loads}")
    lines.append("ratio: paired per-round median when the benchmark records it, '~' = ratio of medians; share = "
                 "limit / the project's best time (NumPy, or onnxruntime for deployment rows)")
    return "\n".join(lines)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2, help="rounds passed to every benchmark (few: 2-3)")
    ap.add_argument("--threads", type=int, default=2, help="--threads passed to the benchmarks that have it (0: "
                    "their own defaults)")
    ap.add_argument("--onnx-train-steps", type=int, default=0, help="bench_onnx --train-steps (accuracy model)")
    ap.add_argument("--only", default="", help="comma-separated subset of " + ",".join(BENCHMARKS))
    ap.add_argument("--skip", default="")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per benchmark")
    ap.add_argument("--results", default=str(ROOT / "benchmarks" / "results" / "all"),
                    help="folder for the benchmarks' JSON files")
    ap.add_argument("--table-only", action="store_true", help="run nothing but the peaks; tabulate --results")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_all.json"))
    args = ap.parse_args(argv)
    results = Path(args.results)
    results.mkdir(parents=True, exist_ok=True)
    names = [n for n in (args.only.split(",") if args.only else BENCHMARKS) if n]
    unknown = [n for n in names + [s for s in args.skip.split(",") if s] if n not in BENCHMARKS]
    if unknown:
        raise SystemExit(f"--only/--skip: unknown {unknown}; known: {', '.join(BENCHMARKS)}")
    names = [n for n in names if n not in args.skip.split(",")]
    print("measuring peaks ...", flush=True)
    loads = {"start": os.getloadavg()}
    before = measure_peaks()
    runs = {}
    if not args.table_only:
        for n in names:
            runs[n] = run_benchmark(n, args, results)
        after = measure_peaks()
    else:
        after = None
    loads["end"] = os.getloadavg()
    peaks = best_peaks(before, after)
    rows = rows_from(results, peaks)
    text = table(rows, peaks, loads)
    print(text)
    result = {"benchmark": "bench_all", "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "rounds": args.rounds,
              "threads": args.threads, "peaks_before": before, "peaks_after": after, "peaks": peaks,
              "load_average": loads, "runs": runs, "rows": rows, "results_folder": str(results)}
    atomic_write_text(Path(args.out), json.dumps(with_versions(result), indent=2), make_parents=True)
    print(f"wrote {args.out}")
    return result


if __name__ == "__main__":
    main()
