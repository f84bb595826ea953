"""Benchmark: the cost table per model (issue #33 item 5): what a game or a device pays per generated frame.

Per model at its paper size with random weights (``bench_portable.make_model``: default configs, ``init_params``
with seed 0, float32; no training): parameters, file size of the per-frame graph (float32; int8 where the
exporter offers it: QTG's compact rollout), multiply-adds per frame, µs per frame in onnxruntime at batch 1 for
today's graphs and the portable graphs (``--target portable``) with 1 and 2 intra-op threads, NumPy per frame
(the function each graph translates; 1 and 2 BLAS threads), and the machine's limit for that frame, all side by
side in one run with the ratios.

* **Frame** (``bench_portable.frame_calls``): one ``step`` call (QTG, QuaterNet, acRNN, long-term), one
  ``window`` call on the last R frames (the CNN), one path point of the pace network (today: the
  bidirectional graph over 200 points in one call / 200; portable: the host loop over the same 200 points,
  ``ceil(200 / K)`` ``pace_step`` calls of K points with the state carried, the padding included / 200). NumPy:
  ``qtg.step``, ``quaternet.step`` (both QuaterNets), ``quaternet_cnn.step``, ``acrnn.step``, ``pace.forward``
  over 200 points / 200.
* **Multiply-adds** (:func:`graph_macs`): counted in today's per-frame graph after shape inference at batch 1:
  ``MatMul``/``Gemm`` (M·K·N), ``Conv`` (outputs × C_in/groups × kernel), ``GRU`` (T·D·3H(I + H)), ``LSTM``
  (T·D·4H(I + H)), divided by the frames per call; elementwise work not counted (QTG: equal to
  ``refimpl.models.qtg.macs_per_frame``, tested).
* **Limit** (:func:`probe_machine`, measured in the same run, best of a few calls): a batch-1 frame must read the
  per-frame graph's weights (initializer bytes per frame) at the memory bandwidth of a float32 ``W @ x`` over
  256 MB (streamed from DRAM), and do 2·MACs at the float32 GEMM peak (``A @ B``, 1024²); the limit is the
  larger of the two times (``bound``: which one). Weights that fit in the 32 MiB L3 can beat the DRAM term.
* **Timing** (:func:`time_variants`): one process, interleaved rounds (every variant once per round, so load
  hits all alike), each a block of ≈ ``--min-time`` seconds, 0.15 s of settling after each block (spinning
  BLAS/OpenMP threads), NumPy's BLAS limited with threadpoolctl; medians over rounds, minima beside them; wall
  time and the calling thread's CPU time of every block. The table gives one thread in CPU time (the cost on one
  core, whatever else runs: the 1-thread probes are timed so too) and two threads in wall time (which needs both
  cores free: on a loaded machine it shows the contention, not the graph). Sessions:
  ``deploy.session.make_session`` (sequential, full optimisation, no spinning).

The JSON records numpy, BLAS (threadpoolctl: library, version, kernel architecture, threads), onnxruntime, onnx,
python, machine (CPU model), and the load average before and after: the machine is shared with trainings, so
absolute times drift; compare within one run and read the ratios. Nothing asserts on time. A table is printed
and JSON written atomically to ``benchmarks/results/bench_cost.json``.

    python benchmarks/bench_cost.py [--rounds 5] [--min-time 0.2] [--models qtg ...] [--quick] [--out FILE]
    python benchmarks/bench_cost.py --markdown benchmarks/results/bench_cost.json   # deploy/README.md's table
"""
from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import onnx  # noqa: E402
import onnxruntime as ort  # noqa: E402

from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.versions import with_versions  # noqa: E402

try:
    from threadpoolctl import threadpool_info, threadpool_limits
except ImportError:  # optional: then NumPy runs with its default threads and the JSON says so
    threadpool_info = threadpool_limits = None

#: Table rows: model -> label.
LABELS = {"qtg": "QTG", "quaternet": "QuaterNet GRU", "quaternet-cnn": "QuaterNet CNN", "acrnn": "acRNN",
          "quaternet-long": "long-term pose", "pace": "long-term pace"}
PACE_POINTS = 200
SETTLE_S = 0.15


def _load_portable():
    """``benchmarks/bench_portable.py`` (not a package): models, exports, per-frame callables."""
    spec = importlib.util.spec_from_file_location("bench_portable", ROOT / "benchmarks" / "bench_portable.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# ------------------------------------------------------------------------------------------------------------
# counting
# ------------------------------------------------------------------------------------------------------------

def _static(model: onnx.ModelProto, sizes: dict) -> onnx.ModelProto:
    """A copy of ``model`` with its symbolic input dimensions set (``sizes``, default 1), shapes inferred."""
    m = onnx.ModelProto()
    m.CopyFrom(model)
    for i in m.graph.input:
        for d in i.type.tensor_type.shape.dim:
            if not d.HasField("dim_value"):
                d.dim_value = int(sizes.get(d.dim_param, 1))
    return onnx.shape_inference.infer_shapes(m, data_prop=True)


def graph_macs(model: onnx.ModelProto, sizes: dict | None = None) -> int:
    """Multiply-adds of one call of ``model`` (module docstring), symbolic input dimensions from ``sizes``
    (default 1). Nodes inside subgraphs (Scan, Loop) are not counted: use per-frame graphs.

    Raises
    ------
    ValueError
        A counted node whose shapes inference left unknown.
    """
    m = _static(model, sizes or {})
    shapes = {}
    for v in list(m.graph.input) + list(m.graph.value_info) + list(m.graph.output):
        dims = [d.dim_value if d.HasField("dim_value") else None for d in v.type.tensor_type.shape.dim]
        shapes[v.name] = dims
    for t in m.graph.initializer:
        shapes[t.name] = list(t.dims)

    def shape(name):
        s = shapes.get(name)
        if s is None or any(d is None for d in s):
            raise ValueError(f"graph_macs: unknown shape of {name!r}")
        return s

    total = 0
    for n in m.graph.node:
        if n.op_type == "MatMul":
            total += int(np.prod(shape(n.output[0]))) * shape(n.input[0])[-1]
        elif n.op_type == "Gemm":
            trans_a = next((a.i for a in n.attribute if a.name == "transA"), 0)
            a = shape(n.input[0])
            total += int(np.prod(shape(n.output[0]))) * (a[0] if trans_a else a[1])
        elif n.op_type == "Conv":
            w = shape(n.input[1])  # (C_out, C_in / groups, k...)
            total += int(np.prod(shape(n.output[0]))) * int(np.prod(w[1:]))
        elif n.op_type in ("GRU", "LSTM"):
            x, w, r = shape(n.input[0]), shape(n.input[1]), shape(n.input[2])  # (T, B, I), (D, gH, I), (D, gH, H)
            total += x[0] * x[1] * w[0] * w[1] * (w[2] + r[2])
    return int(total)


def initializer_bytes(model: onnx.ModelProto) -> int:
    """Bytes of the graph's initializers (the weights a call reads)."""
    from onnx import numpy_helper

    return int(sum(numpy_helper.to_array(t).nbytes for t in model.graph.initializer))


# ------------------------------------------------------------------------------------------------------------
# the machine's limits
# ------------------------------------------------------------------------------------------------------------

def _limits(threads: int):
    return threadpool_limits(threads) if threadpool_limits is not None else contextlib.nullcontext()


def _best(fn, repeats: int, clock=time.perf_counter) -> float:
    fn()
    best = float("inf")
    for _ in range(repeats):
        t0 = clock()
        fn()
        best = min(best, clock() - t0)
    return best


def probe_machine(quick: bool = False) -> dict:
    """``{threads: {"stream_gb_s", "gemm_gflop_s"}}`` for 1 and 2 BLAS threads: a float32 ``W @ x`` over
    256 MB (``quick``: 32 MB) and a float32 1024² ``A @ B`` (``quick``: 256²), best of a few calls; 1 thread
    timed in the calling thread's CPU time (robust to other processes' load), 2 threads in wall time."""
    rng = np.random.default_rng(0)
    rows = 2048 if quick else 8192
    w = rng.standard_normal((rows, 4096 if quick else 8192), dtype=np.float32)
    x = rng.standard_normal(w.shape[1], dtype=np.float32)
    n = 256 if quick else 1024
    a, b = rng.standard_normal((n, n), dtype=np.float32), rng.standard_normal((n, n), dtype=np.float32)
    out = {}
    for threads in (1, 2):
        clock = time.thread_time if threads == 1 else time.perf_counter
        with _limits(threads):
            t_stream = _best(lambda: w @ x, 3 if quick else 7, clock)
            t_gemm = _best(lambda: a @ b, 3 if quick else 9, clock)
        out[str(threads)] = {"stream_gb_s": w.nbytes / t_stream / 1e9, "gemm_gflop_s": 2 * n ** 3 / t_gemm / 1e9,
                             "stream_bytes": int(w.nbytes), "gemm_n": n,
                             "clock": "cpu" if threads == 1 else "wall"}
        time.sleep(SETTLE_S)
    return out


def frame_limit_us(weight_bytes: float, macs: float, probe: dict) -> dict:
    """Lower bound of a frame's time (µs): weights streamed at ``probe``'s bandwidth, or 2·MACs at its GEMM
    peak, whichever is longer."""
    t_mem = weight_bytes / (probe["stream_gb_s"] * 1e9) * 1e6
    t_flop = 2.0 * macs / (probe["gemm_gflop_s"] * 1e9) * 1e6
    return {"memory_us": t_mem, "compute_us": t_flop, "limit_us": max(t_mem, t_flop),
            "bound": "memory" if t_mem >= t_flop else "compute"}


# ------------------------------------------------------------------------------------------------------------
# NumPy per frame
# ------------------------------------------------------------------------------------------------------------

def numpy_frame(name: str, params: dict, cfg, window: int = 1):
    """``(callable, frames per call)``: the NumPy function the per-frame graph of ``name`` translates, at batch 1
    on random inputs (``window``: the CNN's R)."""
    from refimpl.models import acrnn, pace, qtg, quaternet, quaternet_cnn

    rng = np.random.default_rng(2)
    rand = lambda *s: (0.1 * rng.standard_normal(s)).astype(np.float32)  # noqa: E731
    if name == "qtg":
        past, target = rand(1, 2, cfg.pose_size), rand(1, 2, cfg.pose_size)
        state, latent = qtg.init_state(params, past, target, cfg)
        return (lambda: qtg.step(params, state, latent, cfg)), 1
    if name in ("quaternet", "quaternet-long"):
        state = quaternet.init_state(params, 1, cfg)
        x = rand(1, cfg.input_size)
        return (lambda: quaternet.step(params, state, x, cfg)), 1
    if name == "quaternet-cnn":
        w = rand(1, window, cfg.rotation_size)
        return (lambda: quaternet_cnn.step(params, w, cfg)), 1
    if name == "acrnn":
        state = acrnn.init_state(cfg, 1, np.float32)
        x = rand(1, cfg.frame_size)
        return (lambda: acrnn.step(params, cfg, x, state)), 1
    if name == "pace":
        x = rand(1, PACE_POINTS, cfg.input_size)
        return (lambda: pace.forward(params, cfg, x)), PACE_POINTS
    raise ValueError(f"model: expected one of {sorted(LABELS)}, got {name!r}")


# ------------------------------------------------------------------------------------------------------------
# timing
# ------------------------------------------------------------------------------------------------------------

def time_variants(variants: dict, rounds: int, min_time: float) -> dict:
    """``{key: (callable, frames per call, blas threads or None)}`` timed in interleaved rounds (module
    docstring): ``{key: {"median_us", "min_us", "cpu_median_us", "cpu_min_us", "calls"}}`` per frame (wall
    time, and the calling thread's CPU time: for one thread, the cost on a core whatever else the machine
    runs; onnxruntime with one intra-op thread and NumPy with one BLAS thread compute in the calling thread)."""
    reps = {}
    for k, (fn, _, threads) in variants.items():
        with _limits(threads) if threads else contextlib.nullcontext():
            fn()
            t0 = time.perf_counter()
            fn()
            reps[k] = max(1, int(min_time / max(time.perf_counter() - t0, 1e-7)))
    per = {k: [] for k in variants}
    cpu = {k: [] for k in variants}
    for _ in range(rounds):
        for k, (fn, frames, threads) in variants.items():
            with _limits(threads) if threads else contextlib.nullcontext():
                t0, c0 = time.perf_counter(), time.thread_time()
                for _ in range(reps[k]):
                    fn()
                per[k].append((time.perf_counter() - t0) / reps[k] / frames * 1e6)
                cpu[k].append((time.thread_time() - c0) / reps[k] / frames * 1e6)
            time.sleep(SETTLE_S)
    return {k: {"median_us": statistics.median(v), "min_us": min(v), "cpu_median_us": statistics.median(cpu[k]),
                "cpu_min_us": min(cpu[k]), "calls": reps[k]} for k, v in per.items()}


# ------------------------------------------------------------------------------------------------------------
# one model
# ------------------------------------------------------------------------------------------------------------

def _frame_graph(bp, name: str, folder: Path, target: str) -> tuple[Path, int, dict]:
    """(path of the per-frame graph, frames per call, symbolic sizes) of an exported folder."""
    from deploy.metadata import read_metadata

    prefix = bp.MODELS[name][1]
    if name == "pace":
        if target == "default":
            return folder / f"{prefix}_pace.onnx", PACE_POINTS, {"N": PACE_POINTS}
        path = folder / f"{prefix}_pace_step.onnx"
        return path, int(read_metadata(str(path))["points_per_call"]), {}
    path = folder / f"{prefix}_{'window' if name == 'quaternet-cnn' else 'step'}.onnx"
    return path, 1, {"W": int(read_metadata(str(path)).get("receptive_field", 1))}


def _export(bp, name: str, folder: Path, target: str, quick: bool) -> bool:
    """Export one target; False when this exporter has no such target (the portable column stays empty)."""
    try:
        bp.export_model(name, folder, target, quick)
    except TypeError:  # an exporter without ``target=``
        return False
    return True


def _int8_size(name: str, params, cfg, kw, folder: Path) -> int | None:
    """File size of the int8 variant the exporter offers (QTG's compact rollout), else None."""
    if name != "qtg":
        return None
    from deploy.models import exporter

    paths = exporter("qtg").export_dir(params, cfg, folder, compact="int8", **kw)
    return int(paths["rollout"].stat().st_size)


def measure_model(bp, name: str, tmp: Path, probe: dict, rounds: int, min_time: float, quick: bool) -> dict:
    """The cost row of one model (module docstring)."""
    params, cfg, kw = bp.make_model(name, quick)
    folders = {t: tmp / name / t for t in ("default", "portable")}
    targets = [t for t in folders if _export(bp, name, folders[t], t, quick)]
    path, per_call, sizes = _frame_graph(bp, name, folders["default"], "default")
    model = onnx.load(str(path))
    macs = graph_macs(model, sizes) / per_call
    weight_bytes = initializer_bytes(model) / per_call
    files = {t: _frame_graph(bp, name, folders[t], t)[0].stat().st_size for t in targets}
    variants = {}
    for t in targets:
        for threads in (1, 2):
            calls = bp.frame_calls(name, folders[t], t, threads)
            fn, frames = calls["point" if name == "pace" else "frame"]
            variants[f"ort_{t}_{threads}thr"] = (fn, frames, None)
    fn, frames = numpy_frame(name, params, cfg, sizes.get("W", 1))
    for threads in (1, 2):
        variants[f"numpy_{threads}thr"] = (fn, frames, threads)
    times = time_variants(variants, rounds, min_time)
    limits = {thr: frame_limit_us(weight_bytes, macs, p) for thr, p in probe.items()}
    return {"label": LABELS[name], "parameters": int(sum(np.asarray(v).size for v in params.values())),
            "file_bytes": files, "file_graph": {t: _frame_graph(bp, name, folders[t], t)[0].name for t in targets},
            "int8_file_bytes": _int8_size(name, params, cfg, kw, tmp / name / "int8"),
            "int8_file": "qtg_rollout.onnx (compact int8)" if name == "qtg" else None,
            "macs_per_frame": int(round(macs)), "weight_bytes_per_frame": int(round(weight_bytes)),
            "frames_per_call": {t: _frame_graph(bp, name, folders[t], t)[1] for t in targets},
            "times": times, "limit": limits, "ratios": _ratios(times, limits)}


def _ratios(times: dict, limits: dict) -> dict:
    """Ratios of medians: one thread in CPU time (as its probes), two threads in wall time."""
    med = {k: v["cpu_median_us" if k.endswith("_1thr") else "median_us"] for k, v in times.items()}
    out = {"numpy_1thr/ort_default_1thr": med["numpy_1thr"] / med["ort_default_1thr"],
           "ort_default_1thr/limit_1thr": med["ort_default_1thr"] / limits["1"]["limit_us"],
           "ort_default_2thr/limit_2thr": med["ort_default_2thr"] / limits["2"]["limit_us"],
           "numpy_1thr/limit_1thr": med["numpy_1thr"] / limits["1"]["limit_us"]}
    if "ort_portable_1thr" in med:
        out["ort_portable_1thr/ort_default_1thr"] = med["ort_portable_1thr"] / med["ort_default_1thr"]
        out["ort_portable_2thr/ort_default_2thr"] = med["ort_portable_2thr"] / med["ort_default_2thr"]
    return out


# ------------------------------------------------------------------------------------------------------------
# the run
# ------------------------------------------------------------------------------------------------------------

def environment() -> dict:
    """Library versions, BLAS (threadpoolctl), machine, load average."""
    cpu = ""
    with contextlib.suppress(OSError):
        cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                    if ln.startswith("model name")), "")
    blas = [{k: d.get(k) for k in ("internal_api", "version", "architecture", "num_threads", "threading_layer")}
            for d in (threadpool_info() if threadpool_info is not None else [])]
    commit = ""
    with contextlib.suppress(OSError, subprocess.SubprocessError):
        commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True,
                                timeout=10).stdout.strip()
    return {"commit": commit, "numpy": np.__version__, "onnxruntime": ort.__version__, "onnx": onnx.__version__,
            "python": platform.python_version(), "machine": platform.machine(), "cpu": cpu,
            "platform": platform.platform(), "cpu_count": os.cpu_count(), "blas": blas,
            "threadpoolctl": threadpool_limits is not None}


def bench(models=tuple(LABELS), rounds: int = 5, min_time: float = 0.2, quick: bool = False) -> dict:
    """Every model's row, the probes and the environment (the JSON)."""
    bp = _load_portable()
    load_before = list(os.getloadavg())
    probe = probe_machine(quick)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name in models:
            rows[name] = measure_model(bp, name, Path(tmp), probe, rounds, min_time, quick)
    return {"benchmark": "bench_cost", "sizes": "tiny" if quick else "paper", "rounds": rounds,
            "min_time_s": min_time, "batch": 1, "probe": probe, "rows": rows,
            "env": {**environment(), "load_average_before": load_before, "load_average_after": list(os.getloadavg())},
            "command": "python benchmarks/bench_cost.py" + (" --quick" if quick else "")}


def _rows(result: dict) -> list:
    """The rows in the table's order (:data:`LABELS`; the JSON's keys are sorted)."""
    return [result["rows"][k] for k in LABELS if k in result["rows"]]


def _medians(row: dict) -> dict:
    """µs per frame of the table: one thread in CPU time, two threads in wall time (medians)."""
    return {k: v["cpu_median_us" if k.endswith("_1thr") else "median_us"] for k, v in row["times"].items()}


def _us(v) -> str:
    return "-" if v is None else (f"{v:.0f}" if v >= 100 else f"{v:.1f}")


def table(result: dict) -> str:
    """The cost table as text (µs per frame: medians; limit with 1 / 2 threads)."""
    head = (f"{'model':15s} {'params':>10s} {'MB f32':>7s} {'MB int8':>7s} {'MACs/frame':>11s} "
            f"{'ORT 1t':>7s} {'ORT 2t':>7s} {'port 1t':>7s} {'port 2t':>7s} {'NumPy 1t':>8s} {'NumPy 2t':>8s} "
            f"{'limit 1t':>8s} {'limit 2t':>8s} {'bound':>7s} {'port/ORT':>8s} {'ORT/lim':>7s}")
    lines = [f"cost per frame at batch 1 (µs, medians of {result['rounds']} interleaved rounds, 1 thread: CPU time, "
             f"2 threads: wall time; "
             f"load {result['env']['load_average_before'][0]:.1f} → {result['env']['load_average_after'][0]:.1f})",
             head]
    for r in _rows(result):
        t = _medians(r)
        int8 = r["int8_file_bytes"]
        lines.append(
            f"{r['label']:15s} {r['parameters']:10,d} {r['file_bytes']['default'] / 1e6:7.2f} "
            f"{'-' if int8 is None else f'{int8 / 1e6:.2f}':>7s} {r['macs_per_frame']:11,d} "
            f"{_us(t['ort_default_1thr']):>7s} {_us(t['ort_default_2thr']):>7s} "
            f"{_us(t.get('ort_portable_1thr')):>7s} {_us(t.get('ort_portable_2thr')):>7s} "
            f"{_us(t['numpy_1thr']):>8s} {_us(t['numpy_2thr']):>8s} {_us(r['limit']['1']['limit_us']):>8s} "
            f"{_us(r['limit']['2']['limit_us']):>8s} {r['limit']['1']['bound']:>7s} "
            f"{r['ratios'].get('ort_portable_1thr/ort_default_1thr', float('nan')):8.2f} "
            f"{r['ratios']['ort_default_1thr/limit_1thr']:7.1f}")
    p = result["probe"]
    lines.append(f"probes: DRAM stream {p['1']['stream_gb_s']:.1f} / {p['2']['stream_gb_s']:.1f} GB/s, GEMM peak "
                 f"{p['1']['gemm_gflop_s']:.0f} / {p['2']['gemm_gflop_s']:.0f} GF/s (1 / 2 threads)")
    return "\n".join(lines)


def markdown(result: dict) -> str:
    """The cost table as the Markdown of deploy/README.md ("Cost per model"), every number from ``result``."""
    lines = ["| model | parameters | file MB float32 (int8) | MACs per frame | onnxruntime today, 1 / 2 thr | "
             "portable, 1 / 2 thr | NumPy, 1 / 2 thr | limit, 1 / 2 thr (bound) | portable / today, 1 thr | "
             "today / limit, 1 thr | NumPy / today, 1 thr |", "|" + "---|" * 11]
    for r in _rows(result):
        t = {k: _us(v) for k, v in _medians(r).items()}
        q = r["ratios"]
        int8 = "" if r["int8_file_bytes"] is None else f" ({r['int8_file_bytes'] / 1e6:.2f})"
        port = q.get("ort_portable_1thr/ort_default_1thr")
        lines.append(
            f"| {r['label']} | {r['parameters']:,d} | {r['file_bytes']['default'] / 1e6:.2f}{int8} | "
            f"{r['macs_per_frame']:,d} | {t['ort_default_1thr']} / {t['ort_default_2thr']} | "
            f"{t.get('ort_portable_1thr', '-')} / {t.get('ort_portable_2thr', '-')} | "
            f"{t['numpy_1thr']} / {t['numpy_2thr']} | {_us(r['limit']['1']['limit_us'])} / "
            f"{_us(r['limit']['2']['limit_us'])} ({r['limit']['1']['bound']}) | "
            f"{'-' if port is None else f'{port:.2f}'} | {q['ort_default_1thr/limit_1thr']:.1f} | "
            f"{q['numpy_1thr/ort_default_1thr']:.2f} |")
    return "\n".join(lines)


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--min-time", type=float, default=0.2)
    p.add_argument("--quick", action="store_true", help="tiny sizes and small probes (a smoke run)")
    p.add_argument("--models", nargs="*", default=list(LABELS), choices=list(LABELS))
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_cost.json"))
    p.add_argument("--markdown", metavar="JSON", default=None,
                   help="print the Markdown table of a results file (deploy/README.md) and stop")
    a = p.parse_args(argv)
    if a.markdown:
        result = json.loads(Path(a.markdown).read_text())
        print(markdown(result))
        return result
    result = bench(tuple(a.models), a.rounds, a.min_time, a.quick)
    print(table(result))
    atomic_write_text(Path(a.out), json.dumps(with_versions(result), indent=1, sort_keys=True) + "\n")
    print(f"wrote {a.out}")
    return result


if __name__ == "__main__":
    main()
