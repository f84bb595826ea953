"""Fuzz campaign for the deployment runtime (spec/robustness.md "Runtime wrapper and model-size limits").

Drives ``deploy.runtime.load_model`` / ``DeployedModel.run`` and ``deploy.models.qtg_io.QTGRuntime`` (``start``,
``step``, ``transition``) with hostile inputs and hostile models, and checks the contract:

* the only exception that escapes is ``ValueError``, and a hostile input is refused (never silently accepted);
* a valid input gives finite outputs of the documented shape;
* every case ends within ``--limit`` seconds (a ``SIGALRM`` at 5 × the limit stops a real hang);
* the process survives (a batch of 0 reaching onnxruntime's GRU kernel kills it) and its peak memory stays
  bounded (a model bomb reaching onnxruntime allocates gigabytes): ``ru_maxrss`` is reported.

Families (one drawn per case):

=============  ======================================================================================
``valid``      well-formed inputs of random batch (1-4), float32 / float64 / int arrays: must run
``batch``      past/target or step-state batches that disagree; a batch of 0 (any input)
``nonfinite``  NaN, ±inf, or float64 values that overflow float32 (1e39 … 1e308) in one entry
``dtype``      object arrays (None, mixed), complex, strings, bytes, datetime64, bool, None, a dict, a ragged
               list, a list of strings
``shape``      wrong rank, wrong pose size, wrong context length, an extra axis, 0-d
``T``          ``transition(T=...)`` with huge, zero, negative, bool, float, string, list values
``state``      ``step(state)`` with None, missing keys, wrong shapes, wrong types
``bomb``       a tiny model whose constant subgraph (``ConstantOfShape``, ``Expand``, ``Tile``, ``Range``,
               ``Pad``, ``OneHot``; also inside a ``Loop``/``If`` body) or declared initializer / Constant
               expands to 0.3-40 GB, or a ``Loop`` with a 10^7 … 10^15 constant trip count: must be refused
               before any session is created
``corrupt``    an exported model's bytes with bit flips, truncation or junk: refused or loaded (then it
               must run or refuse the input with ``ValueError``)
``metadata``   an exported model's metadata values replaced with junk JSON / non-JSON
=============  ======================================================================================

``make_case(rng)`` builds a case from a ``random.Random``; ``run_case(case)`` classifies it
(``tests/test_deploy_fuzz.py`` runs a few hundred).

Usage::

    python -m tests.fuzz.deploy_runtime --cases 5000 [--seed 0] [--limit 2.0] [--out tests/fuzz/results/fuzz_deploy.json]

Prints a table of outcomes per family, writes JSON (atomically, ``refimpl.atomic``), exits 1 on any failure.
"""
from __future__ import annotations

import argparse
import json
import random
import resource
import signal
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

import onnx  # noqa: E402
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.models.qtg import QTGConfig, init_params  # noqa: E402

from deploy.models.qtg import export_qtg_init, export_qtg_rollout, export_qtg_step  # noqa: E402
from deploy.models.qtg_io import Runtime as QTGRuntime  # noqa: E402
from deploy.runtime import load_model  # noqa: E402

FAMILIES = ("valid", "batch", "nonfinite", "dtype", "shape", "T", "state", "bomb", "corrupt", "metadata")
CONFIG = QTGConfig(pose_size=15, encoder_sizes=(8,), gru_hidden=6, decoder_sizes=(8,), transition_length=4)
P, Z, H, L = CONFIG.pose_size, CONFIG.latent_size, CONFIG.gru_hidden, CONFIG.gru_layers

_FIXTURE: dict = {}


def fixture() -> dict:
    """The exported tiny QTG (init, step, rollout protos and bytes) and a runtime on them, built once."""
    if not _FIXTURE:
        params = init_params(CONFIG, np.random.default_rng(0), dtype=np.float32)
        stats = (np.array([0.0, 90.0, 0.0]), np.array([30.0, 5.0, 30.0]))
        protos = {"init": export_qtg_init(params, CONFIG, normalization=stats),
                  "step": export_qtg_step(params, CONFIG, normalization=stats),
                  "rollout": export_qtg_rollout(params, CONFIG, normalization=stats)}
        _FIXTURE.update(protos=protos, bytes={k: m.SerializeToString() for k, m in protos.items()},
                        runtime=QTGRuntime(**protos))
    return _FIXTURE


# ------------------------------------------------------------------------------------------------------ inputs
def _poses(rng: random.Random, B: int, C: int = 2) -> np.ndarray:
    nr = np.random.default_rng(rng.getrandbits(32))
    x = nr.standard_normal((B, C, P))
    x[..., :3] = x[..., :3] * 20 + np.array([0.0, 90.0, 0.0])
    return x


def _junk_value(rng: random.Random, like: np.ndarray):
    kind = rng.choice(["none_obj", "mixed_obj", "complex", "str", "bytes", "datetime", "bool", "None", "dict",
                       "ragged", "strlist", "pystr", "set"])
    if kind == "none_obj":
        return np.full(like.shape, None, dtype=object)
    if kind == "mixed_obj":
        a = like.astype(object)
        a.flat[0] = "x"
        return a
    if kind == "complex":
        return like + 1j
    if kind == "str":
        return like.astype(str)
    if kind == "bytes":
        return like.astype("S8")
    if kind == "datetime":
        return np.zeros(like.shape, dtype="datetime64[s]")
    if kind == "bool":
        return like > 0
    if kind == "None":
        return None
    if kind == "dict":
        return {"a": 1}
    if kind == "ragged":
        return [[1.0, 2.0], [3.0]]
    if kind == "strlist":
        return [["a"] * like.shape[-1]]
    if kind == "set":
        return {1, 2}
    return "past"


def make_case(rng: random.Random) -> dict:
    """One case: ``{"family", "kind", "hostile": bool, ...}`` (the arguments are built lazily in run_case)."""
    family = rng.choice(FAMILIES)
    return {"family": family, "seed": rng.getrandbits(32)}


def _runtime_call(case: dict):
    """(callable, hostile, expected output shape or None) for the runtime families."""
    rng = random.Random(case["seed"])
    fam = case["family"]
    rt = fixture()["runtime"]
    B = rng.randint(1, 4)
    past, target = _poses(rng, B), _poses(rng, B)
    use_rollout = rng.random() < 0.5
    T = CONFIG.transition_length if use_rollout else rng.randint(1, 6)
    if fam == "valid":
        cast = rng.choice([np.float32, np.float64, np.int64, np.int32])
        case["kind"] = f"valid/{np.dtype(cast).name}"
        past, target = past.astype(cast), target.astype(cast)
        return (lambda: rt.transition(past, target, T, use_rollout=use_rollout)), False, (B, T, P)
    if fam == "batch":
        kind = rng.choice(["mismatch", "zero_past", "zero_both", "zero_state", "state_mismatch"])
        case["kind"] = f"batch/{kind}"
        if kind == "mismatch":
            target = _poses(rng, B + rng.randint(1, 3))
        elif kind == "zero_past":
            past = np.zeros((0, 2, P))
        elif kind == "zero_both":
            past, target = np.zeros((0, 2, P)), np.zeros((0, 2, P))
        else:
            state = rt.start(past, target)
            key = rng.choice(["pose", "latent_prev", "hidden", "target_latent"])
            a = state[key]
            axis = 1 if key == "hidden" else 0
            n = 0 if kind == "zero_state" else a.shape[axis] + rng.randint(1, 3)
            shape = list(a.shape)
            shape[axis] = n
            state = dict(state, **{key: np.zeros(shape, np.float32)})
            return (lambda: rt.step(state)), True, None
        return (lambda: rt.transition(past, target, T, use_rollout=use_rollout)), True, None
    if fam == "nonfinite":
        value = rng.choice([np.nan, np.inf, -np.inf, 10.0 ** rng.randint(39, 308), -(10.0 ** rng.randint(39, 308))])
        arr = rng.choice(["past", "target"])
        case["kind"] = f"nonfinite/{'nan' if value != value else ('inf' if abs(value) == np.inf else 'overflow')}"
        a = past if arr == "past" else target
        a.flat[rng.randrange(a.size)] = value
        return (lambda: rt.transition(past, target, T, use_rollout=use_rollout)), True, None
    if fam == "dtype":
        j = _junk_value(rng, past)
        case["kind"] = f"dtype/{type(j).__name__}/{getattr(j, 'dtype', '')}"
        if rng.random() < 0.5:
            return (lambda: rt.transition(j, target, T, use_rollout=use_rollout)), True, None
        return (lambda: rt.transition(past, j, T, use_rollout=use_rollout)), True, None
    if fam == "shape":
        kind = rng.choice(["rank2", "rank4", "pose", "context", "scalar", "step_pose"])
        case["kind"] = f"shape/{kind}"
        if kind == "rank2":
            past = past[:, 0]
        elif kind == "rank4":
            past = past[None]
        elif kind == "pose":
            target = np.concatenate([target, target[..., :1]], axis=-1)
        elif kind == "context":
            past = _poses(rng, B, C=rng.choice([1, 3, 4]))
        elif kind == "scalar":
            past = np.float64(1.0)
        else:
            state = rt.start(past, target)
            state = dict(state, pose=np.zeros((B, P + rng.randint(1, 4)), np.float32))
            return (lambda: rt.step(state)), True, None
        return (lambda: rt.transition(past, target, T, use_rollout=use_rollout)), True, None
    if fam == "T":
        bad = rng.choice([10 ** rng.randint(5, 18), 0, -rng.randint(1, 10 ** 6), True, False, 2.0, "30", [4],
                          np.float64(4.0), 10 ** 40, -1, np.int64(-5)])
        case["kind"] = f"T/{type(bad).__name__}"
        return (lambda: rt.transition(past, target, bad, use_rollout=use_rollout)), True, None
    if fam == "state":
        kind = rng.choice(["None", "list", "missing", "junk_value", "wrong_shape"])
        case["kind"] = f"state/{kind}"
        state = rt.start(past, target)
        if kind == "None":
            state = None
        elif kind == "list":
            state = list(state.values())
        elif kind == "missing":
            drop = rng.choice(list(state))
            state = {k: v for k, v in state.items() if k != drop}
        elif kind == "junk_value":
            key = rng.choice(list(state))
            state = dict(state, **{key: _junk_value(rng, state[key])})
        else:
            key = rng.choice(list(state))
            state = dict(state, **{key: state[key][..., :-1]})
        return (lambda: rt.step(state)), True, None
    raise AssertionError(fam)


# ------------------------------------------------------------------------------------------------------ models
def _graph_model(nodes, initializers=(), opset: int = 17, out_shape=(1,)) -> onnx.ModelProto:
    g = helper.make_graph(nodes, "bomb", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])],
                          [helper.make_tensor_value_info("y", TensorProto.FLOAT, list(out_shape))],
                          initializer=list(initializers))
    m = helper.make_model(g, opset_imports=[helper.make_opsetid("", opset)])
    m.ir_version = 8
    return m


def _const(name, array):
    return helper.make_node("Constant", [], [name], value=numpy_helper.from_array(np.asarray(array), name))


def make_bomb(rng: random.Random) -> tuple[str, onnx.ModelProto]:
    """A tiny model whose constants expand to 0.3-40 GB (or a huge constant Loop), and its kind."""
    n = rng.randint(9000, 100000)
    dims = [n, rng.randint(9000, 100000)] if rng.random() < 0.7 else [n * rng.randint(10000, 400000)]
    shape = np.array(dims, np.int64)
    one = np.ones([1] * len(dims), np.float32)
    tail = [helper.make_node("ReduceMax", ["big"], ["m"], keepdims=0),
            helper.make_node("Add", ["x", "m"], ["y"])]
    kind = rng.choice(["ConstantOfShape", "Expand", "Tile", "Range", "Pad", "OneHot", "initializer", "Constant",
                       "Loop_trips", "Loop_body", "If_branch", "chain"])
    via_init = rng.random() < 0.5
    if kind == "ConstantOfShape":
        src = [_const("shape", shape)] if not via_init else []
        nodes = src + [helper.make_node("ConstantOfShape", ["shape"], ["big"],
                                        value=numpy_helper.from_array(np.ones(1, np.float32)))] + tail
        return kind, _graph_model(nodes, [numpy_helper.from_array(shape, "shape")] if via_init else [])
    if kind == "Expand":
        nodes = [_const("one", one), _const("shape", shape), helper.make_node("Expand", ["one", "shape"], ["big"])]
        return kind, _graph_model(nodes + tail)
    if kind == "Tile":
        nodes = [_const("one", one), _const("reps", shape), helper.make_node("Tile", ["one", "reps"], ["big"])]
        return kind, _graph_model(nodes + tail)
    if kind == "Range":
        total = float(np.prod(dims, dtype=np.float64))
        nodes = [_const("a", np.float32(0)), _const("b", np.float32(total)), _const("d", np.float32(1)),
                 helper.make_node("Range", ["a", "b", "d"], ["big"])]
        return kind, _graph_model(nodes + tail)
    if kind == "Pad":
        pads = np.array([0] * len(dims) + dims, np.int64)
        nodes = [_const("one", one), _const("pads", pads), helper.make_node("Pad", ["one", "pads"], ["big"])]
        return kind, _graph_model(nodes + tail)
    if kind == "OneHot":
        nodes = [_const("idx", np.zeros([1000], np.int64)), _const("depth", np.array(rng.randint(10 ** 5, 10 ** 7),
                                                                                      np.int64)),
                 _const("vals", np.array([0.0, 1.0], np.float32)),
                 helper.make_node("OneHot", ["idx", "depth", "vals"], ["big"])]
        return kind, _graph_model(nodes + tail)
    if kind == "initializer":
        t = onnx.TensorProto(name="big", data_type=TensorProto.FLOAT, dims=dims)
        t.raw_data = b"\0" * 16
        return kind, _graph_model(tail, [t])
    if kind == "Constant":
        t = onnx.TensorProto(name="bigc", data_type=TensorProto.FLOAT, dims=dims)
        t.raw_data = b"\0" * 16
        return kind, _graph_model([helper.make_node("Constant", [], ["big"], value=t)] + tail)
    if kind == "Loop_trips":
        body = helper.make_graph([helper.make_node("Identity", ["c_in"], ["c_out"]),
                                  helper.make_node("Add", ["v_in", "v_in"], ["v_out"])], "body",
                                 [helper.make_tensor_value_info("i", TensorProto.INT64, []),
                                  helper.make_tensor_value_info("c_in", TensorProto.BOOL, []),
                                  helper.make_tensor_value_info("v_in", TensorProto.FLOAT, [1])],
                                 [helper.make_tensor_value_info("c_out", TensorProto.BOOL, []),
                                  helper.make_tensor_value_info("v_out", TensorProto.FLOAT, [1])])
        nodes = [_const("M", np.array(10 ** rng.randint(7, 15), np.int64)), _const("cond", np.array(True)),
                 helper.make_node("Loop", ["M", "cond", "x"], ["y"], body=body)]
        return kind, _graph_model(nodes)
    if kind in ("Loop_body", "If_branch"):
        inner = helper.make_graph([_const("shape", shape),
                                   helper.make_node("ConstantOfShape", ["shape"], ["big"],
                                                    value=numpy_helper.from_array(np.ones(1, np.float32))),
                                   helper.make_node("ReduceMax", ["big"], ["m"], keepdims=0)],
                                  "inner", [], [helper.make_tensor_value_info("m", TensorProto.FLOAT, [])])
        if kind == "If_branch":
            nodes = [_const("cond", np.array(True)),
                     helper.make_node("If", ["cond"], ["m"], then_branch=inner, else_branch=inner),
                     helper.make_node("Add", ["x", "m"], ["y"])]
            return kind, _graph_model(nodes)
        body = helper.make_graph(
            [helper.make_node("Identity", ["c_in"], ["c_out"])] + list(inner.node)
            + [helper.make_node("Add", ["v_in", "m"], ["v_out"])], "body",
            [helper.make_tensor_value_info("i", TensorProto.INT64, []),
             helper.make_tensor_value_info("c_in", TensorProto.BOOL, []),
             helper.make_tensor_value_info("v_in", TensorProto.FLOAT, [1])],
            [helper.make_tensor_value_info("c_out", TensorProto.BOOL, []),
             helper.make_tensor_value_info("v_out", TensorProto.FLOAT, [1])])
        nodes = [_const("M", np.array(2, np.int64)), _const("cond", np.array(True)),
                 helper.make_node("Loop", ["M", "cond", "x"], ["y"], body=body)]
        return kind, _graph_model(nodes)
    # chain: a small ConstantOfShape, then Tile / Expand of it to the huge size (shape from Concat of constants)
    nodes = [_const("s1", np.array([4], np.int64)),
             helper.make_node("ConstantOfShape", ["s1"], ["small"],
                              value=numpy_helper.from_array(np.ones(1, np.float32))),
             _const("a", np.array(dims[:1], np.int64)), _const("b", np.array(dims[1:] or [1], np.int64)),
             helper.make_node("Concat", ["a", "b"], ["shape"], axis=0),
             _const("one", np.ones((1, 1), np.float32)), helper.make_node("Expand", ["one", "shape"], ["big"])]
    return kind, _graph_model(nodes + tail)


def _model_call(case: dict):
    rng = random.Random(case["seed"])
    fam = case["family"]
    fx = fixture()
    if fam == "bomb":
        kind, m = make_bomb(rng)
        case["kind"] = f"bomb/{kind}"
        return (lambda: load_model(m)), True, None
    role = rng.choice(["init", "step", "rollout"])
    if fam == "corrupt":
        data = bytearray(fx["bytes"][role])
        kind = rng.choice(["flip", "truncate", "junk", "splice"])
        case["kind"] = f"corrupt/{kind}"
        if kind == "flip":
            for _ in range(rng.randint(1, 8)):
                i = rng.randrange(len(data))
                data[i] ^= 1 << rng.randrange(8)
        elif kind == "truncate":
            data = data[:rng.randrange(len(data))]
        elif kind == "junk":
            data = bytearray(rng.getrandbits(8) for _ in range(rng.randint(0, 400)))
        else:
            i = rng.randrange(len(data))
            data[i:i + 16] = bytes(rng.getrandbits(8) for _ in range(16))
        blob = bytes(data)
        return (lambda: _load_and_run(blob)), None, None   # hostile or not: either outcome is fine if ValueError
    kind = rng.choice(["model", "io", "normalization", "skeleton", "frame_rate", "format", "input_transform",
                       "exporter"])
    junk = rng.choice(["NaN", "Infinity", "1e999", "[", '"x"', "[1, 2]", "{}", "null", "true", "__import__('os')",
                       "[" * 3000 + "]" * 3000, "3", '{"mean": "x"}'])
    case["kind"] = f"metadata/{kind}"
    m = onnx.ModelProto()
    m.CopyFrom(fx["protos"][role])
    for e in m.metadata_props:
        if e.key == kind:
            e.value = junk
    return (lambda: _load_and_run(m)), None, None


def _load_and_run(model):
    m = load_model(model)
    rng = np.random.default_rng(0)
    feeds = {}
    for name, shape, _ in m.inputs:
        feeds[name] = rng.standard_normal([2 if isinstance(d, str) else d for d in shape])
    out = m.run(feeds)
    for v in out.values():
        if np.asarray(v).dtype.kind == "f" and not np.all(np.isfinite(v)):
            raise FloatingPointError("non-finite output")
    return out


# ----------------------------------------------------------------------------------------------------- running
class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang()


def run_case(case: dict, limit: float = 2.0) -> str:
    """Outcome of one case: ``refused`` / ``ok`` (fine) or ``AcceptedHostile``, ``BadResult``, ``Slow``,
    ``Hang``, ``<ExceptionName>`` (failures)."""
    if case["family"] in ("bomb", "corrupt", "metadata"):
        call, hostile, shape = _model_call(case)
    else:
        call, hostile, shape = _runtime_call(case)
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, 5 * limit)
    t0 = time.perf_counter()
    try:
        out = call()
        outcome = "ok"
    except ValueError:
        outcome = "refused"
        out = None
    except _Hang:
        return "Hang"
    except Exception as exc:  # noqa: BLE001 - the campaign classifies every escape
        return type(exc).__name__
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
    if time.perf_counter() - t0 > limit:
        return "Slow"
    if outcome == "ok" and hostile:
        return "AcceptedHostile"
    if outcome == "refused" and hostile is False:
        return "RefusedValid"
    if outcome == "ok" and shape is not None:
        a = np.asarray(out)
        if a.shape != shape or not np.all(np.isfinite(a)):
            return "BadResult"
    return outcome


FINE = ("ok", "refused")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=5000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=float, default=2.0, help="seconds per case (slower = failure)")
    ap.add_argument("--out", default=str(ROOT / "tests" / "fuzz" / "results" / "fuzz_deploy.json"))
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)
    fixture()
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    per_family: dict = defaultdict(Counter)
    per_kind: dict = defaultdict(Counter)
    failures = []
    t0 = time.perf_counter()
    for i in range(args.cases):
        case = make_case(rng)
        outcome = run_case(case, args.limit)
        per_family[case["family"]][outcome] += 1
        per_kind[case.get("kind", case["family"])][outcome] += 1
        if outcome not in FINE:
            failures.append({"case": i, "family": case["family"], "kind": case.get("kind"), "seed": case["seed"],
                             "outcome": outcome})
        if (i + 1) % 500 == 0:
            print(f"  {i + 1}/{args.cases} cases, {len(failures)} failures, {time.perf_counter() - t0:.0f} s",
                  flush=True)
    elapsed = time.perf_counter() - t0
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"\n{'family':<12} {'cases':>6} {'ok':>6} {'refused':>8} {'failures':>9}")
    for fam in FAMILIES:
        c = per_family[fam]
        n = sum(c.values())
        print(f"{fam:<12} {n:>6} {c['ok']:>6} {c['refused']:>8} {n - c['ok'] - c['refused']:>9}")
    total = sum(sum(c.values()) for c in per_family.values())
    print(f"{'total':<12} {total:>6}   failures: {len(failures)}; {elapsed:.0f} s; peak RSS {rss / 1024:.0f} MiB "
          f"(after the fixture {rss0 / 1024:.0f} MiB)")
    result = {"cases": total, "seed": args.seed, "limit_s": args.limit, "elapsed_s": round(elapsed, 1),
              "failures": failures[:200], "num_failures": len(failures),
              "peak_rss_mib": round(rss / 1024, 1), "rss_after_fixture_mib": round(rss0 / 1024, 1),
              "per_family": {k: dict(v) for k, v in per_family.items()},
              "per_kind": {k: dict(v) for k, v in sorted(per_kind.items())}}
    atomic_write_text(args.out, json.dumps(result, indent=1, sort_keys=True) + "\n", make_parents=True)
    print(f"wrote {args.out}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
