"""Benchmark: per-frame time of the portable graphs (``--target portable``, deploy/portable.py) against today's graphs
in onnxruntime, batch 1, every model at its paper size with random weights (issue #33: within 1.5×).

What one "frame" is, per model (the call a game or a device makes per generated frame):

* ``qtg``: one ``step`` call (today: the fused-GRU step graph; portable: the primitive step graph); and a whole
  transition of T frames: today's ``rollout`` graph (Scan) in one call against the portable host loop
  ``init`` + T ``step`` calls (+ ``join``), reported per frame;
* ``quaternet``, ``acrnn``, ``quaternet-long``: one ``step`` call;
* ``quaternet-cnn``: one ``window`` call on the last R frames;
* ``pace``: one path point of a whole path of N points: today's bidirectional graph over the N points in one
  call against the portable host loop (``pace_portable_loop``: ``ceil(N / K)`` ``pace_step`` calls of K points
  of both directions, the state carried, the last chunk zero-padded: the padded points are paid for), each
  divided by N; rows ``pace.point`` (N = 200) and ``pace.point_n1000`` (N = 1000: a path of 200 units, e.g. a
  circle of radius 1.8 m).
* ``--pace-chunks K ...``: the same two paths with the portable pace graph at each K (``export_pace_step(points=K)``),
  interleaved with today's graph (how ``PACE_CHUNK`` was chosen): ``result["pace_chunks"]``.

Timing: one process, interleaved rounds (every variant once per round), each a batch of calls of ≈ ``min_time``
seconds; medians over rounds in µs per frame, minima beside them, and the *paired* ratio: the median over rounds
of portable / today's within the same round (the machine drifts; a round's two blocks run back to back).
Sessions: ``deploy.session.make_session`` (the project's settings: sequential, full optimisation, no spinning)
with ``--threads`` intra-op threads. Inputs are random (timing only); nothing asserts on time. The load average
is recorded before and after. A table is printed and JSON written atomically to
``benchmarks/results/bench_portable.json``.

The pieces are importable for other benchmarks (``benchmarks/`` is not a package: load this file with
``importlib``, as ``tests/test_bench_all.py`` does): :data:`MODELS`, :func:`make_model` (params and config at
paper or tiny size), :func:`export_model` (a folder of either target), :func:`frame_calls` (the per-frame
callables of a folder), :func:`pace_host_loop` (the portable pace loop on one path), :func:`time_calls`
(interleaved timing).

    python benchmarks/bench_portable.py [--threads 1] [--rounds 7] [--min-time 0.2] [--quick] [--models ...]
                                        [--pace-chunks 16 32 64 128] [--out FILE]
"""
from __future__ import annotations

import argparse
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

import onnx  # noqa: E402
import onnxruntime as ort  # noqa: E402

from deploy.models import exporter  # noqa: E402
from deploy.session import make_session  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.npy_files import read_npy  # noqa: E402
from refimpl.versions import with_versions  # noqa: E402

#: Model -> (exporter key, file prefix).
MODELS = {"qtg": ("qtg", "qtg"), "quaternet": ("quaternet", "quaternet"),
          "quaternet-cnn": ("quaternet-cnn", "quaternet-cnn"), "acrnn": ("acrnn", "acrnn"),
          "quaternet-long": ("quaternet-long", "quaternet-long"), "pace": ("quaternet-long", "quaternet-long")}
#: Path lengths (points) of the pace rows: ``pace.point`` and ``pace.point_n1000``.
PACE_PATHS = {"point": 200, "point_n1000": 1000}
PACE_POINTS = PACE_PATHS["point"]


def make_model(name: str, quick: bool = False, seed: int = 0) -> tuple[dict, object, dict]:
    """``(params float32, config, export keyword arguments)`` of ``name`` at its paper size (``quick``: tiny)."""
    from refimpl.models import acrnn, pace, qtg, quaternet, quaternet_cnn

    rng = np.random.default_rng(seed)
    if name == "qtg":
        cfg = qtg.QTGConfig(encoder_sizes=(16, 8), gru_hidden=16, decoder_sizes=(16,)) if quick else qtg.QTGConfig()
        return qtg.init_params(cfg, rng, np.float32), cfg, {"normalization": (np.zeros(3), np.ones(3))}
    if name == "quaternet":
        cfg = quaternet.QuaterNetConfig(hidden_size=16 if quick else 1000)
        return quaternet.init_params(cfg, rng, np.float32), cfg, {}
    if name == "quaternet-cnn":
        cfg = quaternet_cnn.QuaterNetCNNConfig(channels=16) if quick else quaternet_cnn.QuaterNetCNNConfig()
        return quaternet_cnn.init_params(cfg, rng, np.float32), cfg, {}
    if name == "acrnn":
        cfg = acrnn.ACRNNConfig(hidden_size=16) if quick else acrnn.ACRNNConfig()
        F = cfg.frame_size
        return (acrnn.init_params(cfg, rng, np.float32), cfg,
                {"mean": np.zeros(F), "std": np.ones(F), "representation": "dual_quaternions"})
    if name == "quaternet-long":
        cfg = quaternet.QuaterNetConfig.long_term(hidden_size=16 if quick else 1000)
        return quaternet.init_params(cfg, rng, np.float32), cfg, {}
    if name == "pace":
        cfg = pace.PaceConfig()
        return pace.init_params(cfg, rng, np.float32), cfg, {}
    raise ValueError(f"model: expected one of {sorted(MODELS)}, got {name!r}")


def export_model(name: str, folder, target: str, quick: bool = False) -> Path:
    """Export ``name`` (:func:`make_model`) with ``target`` (``"default"`` or ``"portable"``) into ``folder``."""
    params, cfg, kw = make_model(name, quick)
    exporter(MODELS[name][0]).export_dir(params, cfg, Path(folder), target=target, **kw)
    return Path(folder)


def _feeds(sess: ort.InferenceSession, rng, sizes: dict) -> dict:
    """Random float32 inputs of every input of ``sess``, symbolic dimensions from ``sizes`` (default 1)."""
    out = {}
    for i in sess.get_inputs():
        shape = [d if isinstance(d, int) else sizes.get(d, 1) for d in i.shape]
        out[i.name] = (0.1 * rng.standard_normal(shape)).astype(np.float32)
    return out


def _session(path, threads):
    return make_session(onnx.load(str(path)), intra_op_threads=threads)


def _carry(sess, feeds):
    """A callable running ``sess`` once on ``feeds``."""
    return lambda: sess.run(None, feeds)


def frame_calls(name: str, folder, target: str, threads: int = 1) -> dict[str, tuple]:
    """``{variant: (callable, frames per call)}`` of the per-frame work of a folder (module docstring)."""
    from deploy.metadata import read_metadata

    d, prefix = Path(folder), MODELS[name][1]
    rng = np.random.default_rng(1)
    if name == "pace":
        if target == "default":
            return pace_default_calls(_session(d / f"{prefix}_pace.onnx", threads), rng)
        h0 = read_npy(d / f"{prefix}_pace_h0.npy")
        return pace_portable_calls(_session(d / f"{prefix}_pace_step.onnx", threads), h0, rng)
    role = "window" if name == "quaternet-cnn" else "step"
    path = d / f"{prefix}_{role}.onnx"
    s = _session(path, threads)
    sizes = {"W": int(read_metadata(str(path)).get("receptive_field", 1))}
    calls = {"frame": (_carry(s, _feeds(s, rng, sizes)), 1)}
    if name == "qtg":
        T = int(read_metadata(str(path))["model"]["config"]["transition_length"])
        if target == "default":
            r = _session(d / "qtg_rollout.onnx", threads)
            calls["transition"] = (_carry(r, _feeds(r, rng, {})), T)
        else:
            calls["transition"] = (_qtg_host_loop(d, threads, rng, T), T)
    return calls


def _pace_paths(rng) -> dict[str, np.ndarray]:
    """``{variant: x (N, 2)}`` random pace inputs of the :data:`PACE_PATHS` lengths (the same for both targets)."""
    rng = np.random.default_rng(2)
    return {k: (0.1 * rng.standard_normal((n, 2))).astype(np.float32) for k, n in PACE_PATHS.items()}


def pace_default_calls(sess, rng) -> dict[str, tuple]:
    """Today's pace graph: one call per path, ``{variant: (callable, N)}``."""
    return {k: (_carry(sess, {"x": x[None]}), len(x)) for k, x in _pace_paths(rng).items()}


def pace_host_loop(sess, h0: np.ndarray, x: np.ndarray, K: int) -> np.ndarray:
    """The portable pace host loop (``deploy.models.quaternet_long_io.pace_portable_loop``) on one path
    ``x (N, 2)`` with ``sess`` (K points per call) and the initial states ``h0 (2, 1, H)``: ``y (N, 4)``."""
    N = len(x)
    C = -(-N // K)
    pad = np.zeros((C * K - N, x.shape[1]), np.float32)
    xf, xb = np.concatenate([x, pad])[None], np.concatenate([x[::-1], pad])[None]
    hf, hb = h0[0:1], h0[1:2]
    yf, yb = [], []
    for c in range(C):
        f, hf, b, hb = sess.run(None, {"x_forward": xf[:, c * K:(c + 1) * K], "h_forward": hf,
                                       "x_backward": xb[:, c * K:(c + 1) * K], "h_backward": hb})
        yf.append(f[0])
        yb.append(b[0])
    return np.concatenate(yf)[:N] + np.concatenate(yb)[:N][::-1]


def pace_portable_calls(sess, h0: np.ndarray, rng) -> dict[str, tuple]:
    """The portable pace graph: the host loop per path, ``{variant: (callable, N)}``."""
    names = [o.name for o in sess.get_outputs()]
    if names != ["y_forward", "h_forward_next", "y_backward", "h_backward_next"]:
        raise ValueError(f"pace_step: unexpected outputs {names}")
    K = int(sess.get_inputs()[0].shape[1])
    h0 = np.asarray(h0, np.float32)
    return {k: ((lambda x=x: pace_host_loop(sess, h0, x, K)), len(x)) for k, x in _pace_paths(rng).items()}


def _qtg_host_loop(d: Path, threads: int, rng, T: int):
    """The portable QTG host loop (init, T steps, join when present) as one callable."""
    init, step = _session(d / "qtg_init.onnx", threads), _session(d / "qtg_step.onnx", threads)
    join = _session(d / "qtg_join.onnx", threads) if (d / "qtg_join.onnx").is_file() else None
    ctx = _feeds(init, rng, {})
    names = [o.name for o in init.get_outputs()]

    def run():
        st = dict(zip(names, init.run(None, ctx)))
        pose, lat, hid, tl = st["pose"], st["latent_prev"], st["hidden"], st["target_latent"]
        for _ in range(T):
            pose, lat, hid = step.run(None, {"pose": pose, "latent_prev": lat, "hidden": hid, "target_latent": tl})
        return pose
    return run


def time_calls(fns: dict, rounds: int, min_time: float) -> dict:
    """Interleaved timing of ``{key: (callable, frames per call)}``: µs per frame, median and minimum over
    ``rounds`` rounds of ≈ ``min_time`` seconds per variant."""
    reps = {}
    for k, (fn, _) in fns.items():
        fn()
        t0 = time.perf_counter()
        fn()
        reps[k] = max(1, int(min_time / max(time.perf_counter() - t0, 1e-7)))
    per = {k: [] for k in fns}
    for _ in range(rounds):
        for k, (fn, frames) in fns.items():
            t0 = time.perf_counter()
            for _ in range(reps[k]):
                fn()
            per[k].append((time.perf_counter() - t0) / reps[k] / frames * 1e6)
    return {k: {"median_us": statistics.median(v), "min_us": min(v), "calls_per_round": reps[k], "rounds_us": v}
            for k, v in per.items()}


def paired_ratio(a: dict, b: dict) -> float:
    """Median over rounds of ``b / a`` within the same round (:func:`time_calls` entries)."""
    return statistics.median(y / x for x, y in zip(a["rounds_us"], b["rounds_us"]))


def _row(a: dict, b: dict) -> dict:
    return {"default": a, "portable": b, "ratio_median": b["median_us"] / a["median_us"],
            "ratio_paired": paired_ratio(a, b)}


def pace_chunk_sweep(chunks, threads: int, rounds: int, min_time: float, quick: bool) -> dict:
    """Today's pace graph against the portable one at each K of ``chunks`` (both paths of :data:`PACE_PATHS`),
    interleaved: ``{"K": {variant: row}}``, ``"call"`` (one ``pace_step`` call alone, per point: the graph
    without the host loop's Python and padding) and ``"nodes"``, ``"bytes"`` of each portable graph."""
    from deploy.models.quaternet_long import export_pace, export_pace_step
    from deploy.portable import builder_options

    params, cfg, _ = make_model("pace", quick)
    rng = np.random.default_rng(1)
    h0 = np.asarray(params["h0"], np.float32).reshape(2, 1, -1)
    fns = {(k, "default"): c for k, c in pace_default_calls(make_session(export_pace(params, cfg),
                                                                         intra_op_threads=threads), rng).items()}
    graphs = {}
    for K in chunks:
        graphs[K] = export_pace_step(params, cfg, points=int(K), **builder_options())
        sess = make_session(graphs[K], intra_op_threads=threads)
        for k, c in pace_portable_calls(sess, h0, rng).items():
            fns[(k, K)] = c
        x = _pace_paths(rng)["point_n1000"][None]
        fns[("call", K)] = (_carry(sess, {"x_forward": x[:, :K], "h_forward": h0[0:1], "x_backward": x[:, K:2 * K],
                                          "h_backward": h0[1:2]}), int(K))
    t = time_calls(fns, rounds, min_time)
    return {str(K): {**{k: _row(t[(k, "default")], t[(k, K)]) for k in PACE_PATHS}, "call": t[("call", K)],
                     "nodes": len(graphs[K].graph.node), "bytes": graphs[K].ByteSize()} for K in chunks}


def bench(threads: int = 1, rounds: int = 7, min_time: float = 0.2, quick: bool = False,
          models=tuple(MODELS), pace_chunks=()) -> dict:
    """Export every model with both targets into a temporary folder and time them; the JSON result."""
    rows = {}
    load_before = list(os.getloadavg())
    with tempfile.TemporaryDirectory() as tmp:
        for name in models:
            fns = {}
            for target in ("default", "portable"):
                folder = export_model(name, Path(tmp) / name / target, target, quick)
                for variant, call in frame_calls(name, folder, target, threads).items():
                    fns[(variant, target)] = call
            t = time_calls(fns, rounds, min_time)
            for variant in sorted({v for v, _ in fns}):
                rows[f"{name}.{variant}"] = _row(t[(variant, "default")], t[(variant, "portable")])
    out = {"benchmark": "bench_portable", "threads": threads, "rounds": rounds, "min_time_s": min_time,
           "sizes": "tiny" if quick else "paper", "pace_paths": dict(PACE_PATHS), "rows": rows}
    if pace_chunks:
        out["pace_chunks"] = pace_chunk_sweep(pace_chunks, threads, rounds, min_time, quick)
    out["env"] = {"python": platform.python_version(), "onnxruntime": ort.__version__, "onnx": onnx.__version__,
                  "platform": platform.platform(), "cpu_count": os.cpu_count(), "load_average_before": load_before,
                  "load_average": list(os.getloadavg())}
    return out


def table(result: dict) -> str:
    """The result as a text table: µs per frame (median, minimum), portable / default (of the medians, and
    paired within rounds)."""
    env = result.get("env", {})
    lines = [f"per-frame time in onnxruntime, batch 1, {result['threads']} thread(s), {result['sizes']} sizes "
             f"(µs per frame: median [min]); load average {env.get('load_average_before', ['?'])[0]} before, "
             f"{env.get('load_average', ['?'])[0]} after",
             f"{'model.frame':28s} {'default':>18s} {'portable':>18s} {'ratio':>7s} {'paired':>7s}"]
    for k, r in result["rows"].items():
        a, b = r["default"], r["portable"]
        lines.append(f"{k:28s} {a['median_us']:10.1f} [{a['min_us']:6.1f}] {b['median_us']:10.1f} "
                     f"[{b['min_us']:6.1f}] {r['ratio_median']:7.2f} {r['ratio_paired']:7.2f}")
    for K, rows in result.get("pace_chunks", {}).items():
        for k in PACE_PATHS:
            r = rows[k]
            lines.append(f"{f'pace.{k} K={K}':28s} {r['default']['median_us']:10.1f} [{r['default']['min_us']:6.1f}] "
                         f"{r['portable']['median_us']:10.1f} [{r['portable']['min_us']:6.1f}] "
                         f"{r['ratio_median']:7.2f} {r['ratio_paired']:7.2f}   ({rows['nodes']} nodes, "
                         f"{rows['bytes']} bytes; one call {rows['call']['median_us']:.1f} µs per point)")
    return "\n".join(lines)


#: The largest K of ``--pace-chunks`` (a graph of 9 K nodes; K = 128 is 1,428 nodes, 139 KB).
MAX_PACE_CHUNK = 1024


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=7)
    p.add_argument("--min-time", type=float, default=0.2)
    p.add_argument("--quick", action="store_true", help="tiny sizes (a smoke run)")
    p.add_argument("--models", nargs="*", default=list(MODELS), choices=list(MODELS))
    p.add_argument("--pace-chunks", nargs="*", type=int, default=[], help="also time the portable pace graph at "
                   "these K (points per call)")
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_portable.json"))
    a = p.parse_args(argv)
    if any(not 1 <= K <= MAX_PACE_CHUNK for K in a.pace_chunks):
        p.error(f"--pace-chunks: expected points per call in [1, {MAX_PACE_CHUNK}], got {a.pace_chunks}")
    result = bench(a.threads, a.rounds, a.min_time, a.quick, tuple(a.models), tuple(a.pace_chunks))
    print(table(result))
    atomic_write_text(Path(a.out), json.dumps(with_versions(result), indent=1, sort_keys=True) + "\n")
    print(f"wrote {a.out}")
    return result


if __name__ == "__main__":
    main()
