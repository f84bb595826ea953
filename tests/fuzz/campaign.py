"""The whole hostile-input campaign (spec/robustness.md §11): readers, math, checkpoints, ONNX, command line.

One run draws cases from seeded ``random.Random`` generators in these families and checks each against its
contract, in bounded time (a per-case ``SIGALRM``) and memory (``tracemalloc`` where the work is Python's: every
reader case, one checkpoint-schema case in ten; command-line subprocesses run under a 4 GiB address-space limit):

================  ==========================================================================================
``readers``       BVH and both exp-map layouts: ``tests/fuzz/readers.py``'s mutators (ValueError or a
                  correct result)
``npz``           the checkpoint container (``load_checkpoint``): readers' zip/npy/re-signed mutators
``math``          ``tests/fuzz/math_api.py``'s families (ValueError or a finite result, no warning)
``ckpt-schema``   training checkpoints with one or two fields mutated and the checksum recomputed, through
                  ``refimpl.services.load_trained`` (only ``BadInputError``) and deploy's ``load_qtg_checkpoint``
                  (only ``ValueError``); an accepted file must be sane: a config of the declared types, every
                  parameter of the implied shape, finite, ``fps`` and ``root_std`` > 0, and the loaded network
                  must run (finite output) on a small input
``onnx``          exported models: readers' ONNX mutators (``deploy.runtime.load_model``)
``onnx-meta``     a tiny exported QTG with metadata values replaced (wrong types, 0 frame rate, huge T, ...),
                  opened with its runtime (``deploy.models.runtime_for_dir``) and run once: ValueError or finite
                  poses
``onnx-args``     the valid runtime's ``transition(past, target, T)`` with hostile arguments: ValueError or
                  finite poses of the asked shape
``cli``           ``refimpl info / export / eval / generate / train --resume`` on damaged and crafted checkpoints
                  and ``generate --backend onnx`` on models with bad metadata, in-process (``main``): exit code 0, 2
                  or 3 only, at most one error line (``refimpl <command>: error: ...``), no warning, no traceback
``cli-process``   a bounded number of the same cases as real subprocesses (``python -m refimpl``)
================  ==========================================================================================

Usage::

    python -m tests.fuzz.campaign [--scale 1.0] [--seed 0] [--only ckpt-schema,cli]

``--scale 1`` runs about 26,000 cases. Prints a table (cases, accepted, expected errors, failures, slowest case,
peak memory per family; failure types with examples), writes ``tests/fuzz/results/fuzz_campaign.json`` through
``refimpl.atomic`` and exits 1 if any case failed. ``tests/test_fuzz_campaign.py`` runs a few hundred cases.
"""
from __future__ import annotations

import argparse
import contextlib
import copy
import io
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
import tracemalloc
import warnings
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

from tests.fuzz import math_api, readers  # noqa: E402

from refimpl.atomic import atomic_write_text  # noqa: E402

WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
TINY = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]
TRAIN = ["--data", str(WALK_BVH), "--batch-size", "8", "--stride", "8", "--test-fraction", "0.5", *TINY]

#: Cases per family at ``--scale 1`` (about 26,000 in all).
BASE_CASES = {"readers": 6000, "npz": 1500, "math": 10000, "ckpt-schema": 6000, "onnx": 1500, "onnx-meta": 300,
              "onnx-args": 300, "cli": 500, "cli-process": 40}
FAMILIES = tuple(BASE_CASES)
MEM_LIMIT = 256 * 2**20  # per in-process case (tracemalloc), beyond the campaign's own state


class _Timeout(BaseException):
    pass


def _alarm(signum, frame):
    raise _Timeout


@contextlib.contextmanager
def _time_limit(seconds: float):
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _quiet(fn, *a, **kw):
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return fn(*a, **kw)


# ------------------------------------------------------------------------------------------------------------
# seeds: a tiny trained QTG, its export
# ------------------------------------------------------------------------------------------------------------

def make_seeds(tmp: Path, with_onnx: bool = True) -> dict:
    """A 2-step tiny QTG checkpoint and (when deploy is installed) its exported models."""
    from refimpl.checkpoint import load_checkpoint
    from refimpl.cli import main

    run = tmp / "seed_run"
    code = _quiet(main, ["train", "--out", str(run), "--steps", "2", "--progress-every", "1", *TRAIN])
    if code != 0:
        raise SystemExit(f"could not train the seed checkpoint (exit {code})")
    seeds = {"checkpoint": run / "checkpoint.npz", "content": load_checkpoint(run / "checkpoint.npz"), "onnx": None}
    if with_onnx:
        try:
            import onnxruntime  # noqa: F401
        except ImportError:
            return seeds
        onnx_dir = tmp / "seed_onnx"
        code = _quiet(main, ["export", "--checkpoint", str(seeds["checkpoint"]), "--out", str(onnx_dir),
                             "--no-verify", "--transition-length", "4"])
        if code == 0:
            seeds["onnx"] = onnx_dir
    return seeds


# ------------------------------------------------------------------------------------------------------------
# checkpoint schema mutations
# ------------------------------------------------------------------------------------------------------------

HOSTILE = [None, True, False, 0, -1, 1, 2, 3, 1.5, -0.0, 1e308, 10**30, 2**63, "", "8", "x" * 300, "0.01",
           [], [1], [1, 2], [8.5], [True, 8], [None], ["a", "b", "c"], [1.0, 0.0, 1.0], [1.0, 1.0, -1.0],
           [[1, 2]], {}, {"a": 1}, "float16", "float64", "float32", "quat", 30, 30.0, 91, 16, 8, 1e-300, 0.5]
PARAM_EDITS = ("nan", "inf", "neg_inf", "grow", "shrink", "transpose", "drop_axis", "add_axis", "zero_d", "empty",
               "int32", "float16", "float64", "complex", "bool", "delete", "extra", "rename", "huge")
META_KEYS = ("format", "model", "model_config")


def _edit_param(arrays: dict, rng: random.Random, edit: str) -> str:
    names = sorted(k for k in arrays if k.startswith("param."))
    if not names:
        arrays["param.extra"] = np.zeros(3, np.float32)
        return "param.extra:added"
    name = rng.choice(names)
    a = arrays[name]
    if a.ndim == 0 or a.size == 0:  # already spoiled by a first edit: give the second one something to work on
        a = np.zeros(3, a.dtype) if a.size == 0 else a.reshape(1)
    if edit in ("nan", "inf", "neg_inf"):
        b = a.copy() if a.dtype.kind in "fc" else a.astype(np.float32)
        b.reshape(-1)[rng.randrange(b.size)] = {"nan": np.nan, "inf": np.inf, "neg_inf": -np.inf}[edit]
        arrays[name] = b
    elif edit == "grow":
        arrays[name] = np.concatenate([a, a[:1]], axis=0)
    elif edit == "shrink":
        arrays[name] = a[:-1].copy()
    elif edit == "transpose":
        arrays[name] = a.T.copy() if a.ndim == 2 else a[:, None].copy()
    elif edit == "drop_axis":
        arrays[name] = a.reshape(-1).copy()
    elif edit == "add_axis":
        arrays[name] = a[None].copy()
    elif edit == "zero_d":
        arrays[name] = np.array(a.reshape(-1)[0])
    elif edit == "empty":
        arrays[name] = a[:0].copy()
    elif edit in ("int32", "float16", "float64", "complex", "bool"):
        arrays[name] = a.astype({"int32": np.int32, "float16": np.float16, "float64": np.float64,
                                 "complex": np.complex64, "bool": np.bool_}[edit])
    elif edit == "delete":
        del arrays[name]
    elif edit == "extra":
        arrays["param.extra" + str(rng.randrange(3))] = np.zeros(rng.randrange(1, 5), a.dtype)
    elif edit == "rename":
        arrays[name.replace("param.", "param.x", 1)] = arrays.pop(name)
    elif edit == "huge":
        arrays[name] = np.full(a.shape, 3e38, a.dtype)
    return f"{name}:{edit}"


def mutate_checkpoint(content, rng: random.Random) -> tuple[dict, dict, str]:
    """One or two random edits of ``(arrays, meta)``; returns the edited copies and a description."""
    with np.errstate(all="ignore"):  # casts of NaN/inf to integers in the generator itself
        return _mutate_checkpoint(content, rng)


def _mutate_checkpoint(content, rng):
    arrays, meta = copy.deepcopy(content[0]), copy.deepcopy(content[1])
    done = []
    for _ in range(1 if rng.random() < 0.8 else 2):
        r = rng.random()
        cfg = meta.get("model_config")
        if r < 0.45 and isinstance(cfg, dict) and cfg:
            key = rng.choice(sorted(cfg))
            if rng.random() < 0.1:
                del cfg[key]
                done.append(f"del model_config.{key}")
            else:
                cfg[key] = rng.choice(HOSTILE)
                done.append(f"model_config.{key}={cfg[key]!r:.40}")
        elif r < 0.85:
            done.append(_edit_param(arrays, rng, rng.choice(PARAM_EDITS)))
        else:
            key = rng.choice(META_KEYS)
            if rng.random() < 0.2:
                meta.pop(key, None)
                done.append(f"del {key}")
            else:
                meta[key] = rng.choice(HOSTILE + ["qtg", "refimpl.train/1"])
                done.append(f"{key}={meta[key]!r:.40}")
    return arrays, meta, "; ".join(done)


def write_crafted(path: Path, arrays: dict, meta: dict) -> None:
    """A checkpoint of ``arrays`` and ``meta`` with a correct SHA-256, written directly (the format is public:
    this is what a crafted file looks like; no fsync, so cases are fast)."""
    entries = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
    entries["__meta__"] = np.frombuffer(json.dumps(meta, sort_keys=True, allow_nan=False).encode("utf-8"),
                                        dtype=np.uint8).copy()
    entries["__checksum__"] = np.frombuffer(readers._documented_checksum(entries), dtype=np.uint8).copy()
    path.write_bytes(readers._zip({f"{k}.npy": readers._npy_of(v) for k, v in entries.items()}))


def _inference_content(content):
    """The seed without optimiser state and sampler (what inference reads), so each case is cheaper."""
    arrays, meta = content
    return {k: v for k, v in arrays.items() if k.startswith("param.")}, meta


def _sane_trained(model) -> str | None:
    """Why an accepted TrainedModel is not sane, or None."""
    from refimpl.checkpoint_schema import expected_param_shapes

    cfg = model.config
    for name, v in vars(cfg).items():
        for x in (v if isinstance(v, tuple) else (v,)):
            if isinstance(x, bool) or not isinstance(x, (int, float, str)):
                return f"config.{name} = {v!r}"
    shapes = expected_param_shapes(model.spec.recipe, model.spec.config_type, cfg)
    if set(shapes) != set(model.params):
        return "parameter names differ from the config's"
    for k, s in shapes.items():
        a = model.params[k]
        if a.shape != s or a.dtype.kind != "f" or not np.isfinite(a).all():
            return f"param {k} {a.dtype} {a.shape}"
    if model.fps is not None and not (np.isfinite(model.fps) and model.fps > 0):
        return f"fps {model.fps}"
    root_std = model.fields.get("root_std")
    if root_std is not None and not (np.isfinite(root_std).all() and (root_std > 0).all()):
        return f"root_std {root_std}"
    return None


def _run_loaded(model) -> str | None:
    from refimpl.tasks.transition import random_context

    past, target = random_context(model, np.random.default_rng(0), 2)
    try:
        with np.errstate(all="ignore"):
            out = model.spec.make_method(model)(past, target, 3)
    except ValueError:  # e.g. finite but huge weights whose output overflows: "finite result or ValueError"
        return None
    if not np.isfinite(out).all():
        return "the accepted network gives non-finite poses"
    return None


# ------------------------------------------------------------------------------------------------------------
# the case runner
# ------------------------------------------------------------------------------------------------------------

def _classify(fn, allowed: tuple, timeout: float, check_memory: bool = True):
    """Run ``fn()`` -> ``(kind, failure, detail, seconds, peak)``; ``fn`` returns None (fine) or a failure
    string (its result broke the contract)."""
    if check_memory:
        tracemalloc.start()
        base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    kind, failure, detail = "ok", None, ""
    try:
        with _time_limit(timeout), warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            bad = fn()
        if bad:
            kind, failure, detail = "ok", "AcceptedMalformed", bad
    except _Timeout:
        kind, failure, detail = "Timeout", "Timeout", f"> {timeout} s"
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # noqa: BLE001 - classifying is the point
        kind, detail = type(exc).__name__, str(exc)[:300]
        if not isinstance(exc, allowed):
            failure = kind
    seconds = time.perf_counter() - t0
    peak = 0
    if check_memory:
        peak = max(tracemalloc.get_traced_memory()[1] - base, 0)
        tracemalloc.stop()
        if peak > MEM_LIMIT and failure is None:
            failure, detail = "MemoryBound", f"peak {peak} B"
    return kind, failure, detail, seconds, peak


class Stats:
    def __init__(self):
        self.families = {}
        self.examples = []

    def add(self, family, kind, failure, detail, seconds, peak, case=""):
        s = self.families.setdefault(family, {"cases": 0, "accepted": 0, "refused": 0, "failures": {},
                                              "outcomes": {}, "max_seconds": 0.0, "max_peak_bytes": 0})
        s["cases"] += 1
        s["outcomes"][kind] = s["outcomes"].get(kind, 0) + 1
        if failure is None:
            s["accepted" if kind == "ok" else "refused"] += 1
        else:
            s["failures"][failure] = s["failures"].get(failure, 0) + 1
            if sum(1 for e in self.examples if e["family"] == family and e["failure"] == failure) < 5:
                self.examples.append({"family": family, "failure": failure, "case": case[:300],
                                      "detail": str(detail)[:400]})
        s["max_seconds"] = max(s["max_seconds"], seconds)
        s["max_peak_bytes"] = max(s["max_peak_bytes"], peak)


# ------------------------------------------------------------------------------------------------------------
# families
# ------------------------------------------------------------------------------------------------------------

def fam_readers(stats, n, seed, only, name, log, include_whole=True):
    """readers' targets, seeds and mutators, one ``run_case`` per case (reference results of the unmodified
    seeds first). ``include_whole``: also the whole 02_01.bvh as a seed (slow to prepare; the full campaign)."""
    if n <= 0:
        return
    targets, skipped = readers.build_targets(include_whole=include_whole, only=only)
    for t, why in skipped.items():
        stats.examples.append({"family": name, "failure": "skipped", "case": t, "detail": why})
    if not targets:
        return
    rng = random.Random(seed)
    drawer = readers.RandomDrawer(rng)
    tracemalloc.start()
    try:
        with tempfile.TemporaryDirectory(prefix="fuzz_campaign_readers_") as tmp:
            tmp = Path(tmp)
            refs = {}
            for t in targets:
                for sname, sdata in t.seeds:
                    path = tmp / f"input{t.suffix}"
                    path.write_bytes(sdata)
                    try:
                        refs[(t.name, sname)] = t.call(str(path))
                    except Exception as exc:  # noqa: BLE001 - a seed that does not load is a failure
                        stats.add(name, type(exc).__name__, "SeedRejected", str(exc), 0.0, 0, f"{t.name}/{sname}")
            for i in range(n):
                t = targets[i % len(targets)]
                drawer.chosen = []
                sname, sdata = drawer.choice(t.seeds)
                mname = drawer.choice(sorted(t.mutators))
                data, expectation = readers.mutate(t, sdata, mname, drawer)
                out = readers.run_case(t, data, expectation, tmp / f"input{t.suffix}",
                                            refs.get((t.name, sname)), timeout=10.0, check_memory=True)
                failure = None if out.failure is None else f"{t.name}:{out.failure}"
                stats.add(name, out.kind, failure, out.detail, out.seconds,
                          0 if out.kind == "MemoryError" else out.peak, f"{t.name}/{mname}/{sname}")
                if log and (i + 1) % 2000 == 0:
                    log(f"  {name} {i + 1}/{n}")
    finally:
        tracemalloc.stop()


def fam_math(stats, n, seed, log):
    rng = random.Random(seed)
    for i in range(n):
        target, family, spoiled, kwargs, finite = math_api.make_case(rng)
        t0 = time.perf_counter()
        outcome, detail = math_api.run_case(target, kwargs, finite)
        failure = None if outcome in ("ok", "ValueError") else outcome
        stats.add("math", outcome, failure, detail, time.perf_counter() - t0, 0, f"{target}/{family}/{spoiled}")


def fam_ckpt_schema(stats, n, seed, seeds, tmp, log):
    from refimpl.errors import BadInputError
    from refimpl.services import load_trained

    try:
        from deploy.models.qtg_io import load_checkpoint as load_qtg_checkpoint
    except ImportError:
        load_qtg_checkpoint = None
    rng = random.Random(seed)
    path = tmp / "crafted.npz"
    content = _inference_content(seeds["content"])
    for i in range(n):
        arrays, meta, what = mutate_checkpoint(content, rng)
        write_crafted(path, arrays, meta)
        if i % 2 == 0 or load_qtg_checkpoint is None:
            def case():
                model = load_trained(path)
                return _sane_trained(model) or _run_loaded(model)
            stats.add("ckpt-schema", *_classify(case, (BadInputError,), 10.0, check_memory=i % 10 == 0),
                      f"load_trained {what}")
        else:
            def case():
                from refimpl.checkpoint_schema import validate_params
                from refimpl.models.qtg import param_shapes

                params, config, _ = load_qtg_checkpoint(path)
                try:
                    validate_params(params, param_shapes(config))
                except ValueError as exc:
                    return f"accepted: {exc}"
                return None
            stats.add("ckpt-schema", *_classify(case, (ValueError,), 10.0, check_memory=i % 10 == 1),
                      f"load_qtg_checkpoint {what}")
        if log and (i + 1) % 2000 == 0:
            log(f"  ckpt-schema {i + 1}/{n}")


ONNX_META_VALUES = [None, True, 0, -1, 0.0, -30.0, 1e308, 10**30, "30", "", "x" * 200, [], [30], {}, {"a": 1},
                    "qtg", ["qtg"], 4, 10**9, 2.5, "__import__('os')"]
ONNX_META_KEYS = ("frame_rate", "model", "model.transition_length", "model.name", "model.config", "role",
                  "normalization", "normalization.mean", "normalization.std", "io", "skeleton", "format", "exporter")


def _mutate_onnx_dir(src: Path, dst: Path, rng: random.Random) -> str:
    import onnx

    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(src, dst)
    key, value = rng.choice(ONNX_META_KEYS), rng.choice(ONNX_META_VALUES)
    files = sorted(dst.glob("*.onnx"))
    chosen = files if rng.random() < 0.6 else [rng.choice(files)]
    for f in chosen:
        m = onnx.load(str(f))
        props = {p.key: p.value for p in m.metadata_props}
        top, _, sub = key.partition(".")
        if sub:
            try:
                obj = json.loads(props.get(top, "{}"))
            except ValueError:
                obj = {}
            if isinstance(obj, dict):
                obj[sub] = value
            props[top] = json.dumps(obj)
        elif rng.random() < 0.1:
            props.pop(top, None)
        else:
            props[top] = json.dumps(value) if rng.random() < 0.9 else str(value)
        del m.metadata_props[:]
        for k, v in props.items():
            m.metadata_props.add(key=k, value=v)
        onnx.save(m, str(f))
    return f"{key}={value!r:.40} in {[f.name for f in chosen]}"


def _context(P=91, B=2):
    g = np.random.default_rng(0)
    past = g.standard_normal((B, 2, P)).astype(np.float32)
    target = g.standard_normal((B, 2, P)).astype(np.float32)
    return past, target


def fam_onnx_meta(stats, n, seed, seeds, tmp, log):
    if seeds.get("onnx") is None:
        return
    from deploy.models import runtime_for_dir

    rng = random.Random(seed)
    past, target = _context()
    for i in range(n):
        d = tmp / "onnx_case"
        what = _mutate_onnx_dir(seeds["onnx"], d, rng)

        def case():
            rt = runtime_for_dir(d)
            out = np.asarray(rt.transition(past, target))
            if out.dtype.kind != "f" or not np.isfinite(out).all():
                return f"non-finite or non-float poses {out.dtype}"
            return None
        stats.add("onnx-meta", *_classify(case, (ValueError,), 10.0, check_memory=False), what)


ARG_VALUES = {
    "T": [True, False, "3", -1, 0, 1.5, None, 10**9, 2**70, np.int64(3), [3], np.float64(3.0), 3, 4],
    "array": ["wrong_last", "zero_d", "nan", "inf", "object", "str", "complex", "int", "list", "none", "empty_batch",
              "extra_axis", "one_frame", "float64", "huge"],
}


def _spoil_array(a, kind):
    if kind == "wrong_last":
        return a[..., :-1]
    if kind == "zero_d":
        return np.float32(1.0)
    if kind in ("nan", "inf"):
        b = a.copy()
        b[0, 0, 0] = np.nan if kind == "nan" else np.inf
        return b
    if kind == "object":
        return a.astype(object)
    if kind == "str":
        return a.astype(str)
    if kind == "complex":
        return a.astype(np.complex64)
    if kind == "int":
        return a.astype(np.int64)
    if kind == "list":
        return a.tolist()
    if kind == "none":
        return None
    if kind == "empty_batch":
        return a[:0]
    if kind == "extra_axis":
        return a[None]
    if kind == "one_frame":
        return a[:, :1]
    if kind == "float64":
        return a.astype(np.float64)
    if kind == "huge":
        return np.full_like(a, 3e38)
    return a


def fam_onnx_args(stats, n, seed, seeds, tmp, log):
    if seeds.get("onnx") is None:
        return
    from deploy.models import runtime_for_dir

    rt = runtime_for_dir(seeds["onnx"])
    rng = random.Random(seed)
    past0, target0 = _context()
    for i in range(n):
        past, target, T = past0, target0, 4
        which = rng.choice(("past", "target", "T"))
        if which == "T":
            T = rng.choice(ARG_VALUES["T"])
            what = f"T={T!r}"
        else:
            kind = rng.choice(ARG_VALUES["array"])
            what = f"{which}:{kind}"
            if which == "past":
                past = _spoil_array(past0, kind)
            else:
                target = _spoil_array(target0, kind)
        finite_in = not any(k in what for k in (":nan", ":inf"))

        def case():
            out = np.asarray(rt.transition(past, target, T))
            if out.dtype.kind != "f":
                return f"poses of dtype {out.dtype}"
            if not np.isfinite(out).all():
                return "non-finite poses" if finite_in else "non-finite input accepted"
            if not finite_in:
                return "non-finite input accepted"
            return None
        stats.add("onnx-args", *_classify(case, (ValueError,), 5.0, check_memory=False), what)


CHECKPOINT_DAMAGE = ("empty", "truncated", "bitflip", "junk", "text", "crafted", "crafted", "crafted", "container")


def _damaged_checkpoint(seeds, rng: random.Random, dst: Path) -> str:
    data = seeds["checkpoint"].read_bytes()
    kind = rng.choice(CHECKPOINT_DAMAGE)
    if kind == "empty":
        dst.write_bytes(b"")
    elif kind == "truncated":
        dst.write_bytes(data[:rng.randrange(len(data))])
    elif kind == "bitflip":
        b = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        dst.write_bytes(bytes(b))
    elif kind == "junk":
        dst.write_bytes(bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 4000))))
    elif kind == "text":
        dst.write_text(rng.choice(["{}", "PK", "checkpoint", "\x00" * 10, json.dumps({"model": "qtg"})]))
    elif kind == "container":
        target = next(t for t in readers.build_targets(False, {"checkpoint"})[0])
        drawer = readers.RandomDrawer(rng)
        mname = rng.choice(sorted(target.mutators))
        out, _ = readers.mutate(target, data, mname, drawer)
        dst.write_bytes(out)
        return f"container/{mname}"
    else:
        arrays, meta, what = mutate_checkpoint(seeds["content"], rng)
        write_crafted(dst, arrays, meta)
        return f"crafted/{what}"
    return kind


def _cli_case(seeds, rng: random.Random, tmp: Path) -> tuple[list[str], str, Path]:
    """``(argv, description, folder)`` of one command-line case."""
    case_dir = tmp / "cli_case"
    if case_dir.exists():
        shutil.rmtree(case_dir)
    case_dir.mkdir()
    command = rng.choice(("info", "export", "eval", "generate", "train", "generate-onnx")
                         if seeds.get("onnx") is not None else ("info", "export", "eval", "generate", "train"))
    if command == "generate-onnx":
        d = case_dir / "models"
        what = _mutate_onnx_dir(seeds["onnx"], d, rng)
        argv = ["generate", "--backend", "onnx", "--onnx", str(d), "--source", str(WALK_BVH), "--source-frame",
                "20", "--length", "4", "--out", str(case_dir / "t.bvh")]
        return argv, f"generate-onnx {what}", case_dir
    if command == "train":
        run = case_dir / "run"
        run.mkdir()
        what = _damaged_checkpoint(seeds, rng, run / "checkpoint.npz")
        argv = ["train", "--out", str(run), "--resume", "--steps", "3", "--progress-every", "1", *TRAIN]
        return argv, f"train {what}", case_dir
    bad = case_dir / "bad.npz"
    what = _damaged_checkpoint(seeds, rng, bad)
    argv = {"info": ["info", str(bad)],
            "export": ["export", "--checkpoint", str(bad), "--out", str(case_dir / "onnx"), "--no-verify",
                       "--transition-length", "4"],
            "eval": ["eval", "--checkpoint", str(bad), "--data", str(WALK_BVH), "--transition-length", "4"],
            "generate": ["generate", "--source", str(WALK_BVH), "--source-frame", "20", "--checkpoint", str(bad),
                         "--length", "4", "--out", str(case_dir / "t.bvh")]}[command]
    return argv, f"{command} {what}", case_dir


def _check_cli(code, err: str, command: str) -> str | None:
    if code not in (0, 2, 3):
        return f"exit {code}"
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith("[")]
    if "Traceback" in err or "Warning" in err:
        return "traceback or warning on stderr"
    if code != 0:
        if len(lines) != 1 or not lines[0].startswith(f"refimpl {command}: error: "):
            return f"{len(lines)} error lines"
    elif lines and command != "train" and command != "export":
        return "stderr lines on success"
    return None


def fam_cli(stats, n, seed, seeds, tmp, log):
    from refimpl.cli import main

    rng = random.Random(seed)
    for i in range(n):
        argv, what, _ = _cli_case(seeds, rng, tmp)
        err_buf, codes = io.StringIO(), []

        def case():
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err_buf):
                codes.append(main(argv))
            bad = _check_cli(codes[-1], err_buf.getvalue(), argv[0])
            return None if bad is None else f"{bad}: {err_buf.getvalue()[-300:]}"
        kind, failure, detail, seconds, peak = _classify(case, (), 120.0, check_memory=False)
        if failure == "AcceptedMalformed":
            failure = "CliContract"
        if codes and kind == "ok":
            kind = "ok" if codes[-1] == 0 else f"exit {codes[-1]}"
        stats.add("cli", kind, failure, detail, seconds, peak, what)
        if log and (i + 1) % 100 == 0:
            log(f"  cli {i + 1}/{n}")


def _limit_memory():  # pragma: no cover - runs in the child
    import resource

    resource.setrlimit(resource.RLIMIT_AS, (4 * 2**30, 4 * 2**30))


def fam_cli_process(stats, n, seed, seeds, tmp, log):
    rng = random.Random(seed + 1)
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    for i in range(n):
        argv, what, _ = _cli_case(seeds, rng, tmp)
        t0 = time.perf_counter()
        try:
            r = subprocess.run([sys.executable, "-m", "refimpl", *argv], capture_output=True, text=True, env=env,
                               timeout=120, preexec_fn=_limit_memory if os.name == "posix" else None)
            bad = _check_cli(r.returncode, r.stderr, argv[0])
            kind = f"exit {r.returncode}"
            failure, detail = (None, "") if bad is None else ("CliContract", f"{bad}: {r.stderr[-300:]}")
        except subprocess.TimeoutExpired:
            kind, failure, detail = "Timeout", "Timeout", "> 120 s"
        stats.add("cli-process", "ok" if kind == "exit 0" else kind, failure, detail, time.perf_counter() - t0, 0,
                  what)


# ------------------------------------------------------------------------------------------------------------
# campaign
# ------------------------------------------------------------------------------------------------------------

def campaign(scale: float = 1.0, seed: int = 0, only: set | None = None, log=print,
             counts: dict | None = None) -> dict:
    """Run the families (``counts``: cases per family, default :data:`BASE_CASES` × ``scale``)."""
    counts = dict(counts or {k: int(round(v * scale)) for k, v in BASE_CASES.items()})
    if only:
        counts = {k: v for k, v in counts.items() if k in only}
    stats = Stats()
    seconds = {}
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fuzz_campaign_") as tmp:
        tmp = Path(tmp)
        need_seeds = any(k in counts for k in ("ckpt-schema", "onnx-meta", "onnx-args", "cli", "cli-process"))
        seeds = make_seeds(tmp, with_onnx=any(k in counts for k in ("onnx-meta", "onnx-args", "cli",
                                                                      "cli-process"))) if need_seeds else {}
        for fam, n in counts.items():
            t0 = time.perf_counter()
            if log:
                log(f"{fam}: {n} cases ...")
            if fam == "readers":
                fam_readers(stats, n, seed, {"bvh", "expmap-cmu", "expmap-h36m"}, "readers", log,
                            include_whole=n >= 1000)
            elif fam == "npz":
                fam_readers(stats, n, seed + 1, {"checkpoint"}, "npz", log)
            elif fam == "onnx":
                fam_readers(stats, n, seed + 2, {"onnx"}, "onnx", log)
            elif fam == "math":
                fam_math(stats, n, seed, log)
            elif fam == "ckpt-schema":
                fam_ckpt_schema(stats, n, seed, seeds, tmp, log)
            elif fam == "onnx-meta":
                fam_onnx_meta(stats, n, seed, seeds, tmp, log)
            elif fam == "onnx-args":
                fam_onnx_args(stats, n, seed, seeds, tmp, log)
            elif fam == "cli":
                fam_cli(stats, n, seed, seeds, tmp, log)
            elif fam == "cli-process":
                fam_cli_process(stats, n, seed, seeds, tmp, log)
            seconds[fam] = round(time.perf_counter() - t0, 1)
            if fam in stats.families:
                stats.families[fam]["seconds"] = seconds[fam]
    return summary(stats, seed, scale, counts, t_all)


def family_counts(base: dict, scale: float, only: set | None = None, counts: dict | None = None) -> dict:
    """Cases per family: ``counts``, else ``base`` × ``scale``; only the families of ``only`` when given."""
    counts = dict(counts or {k: int(round(v * scale)) for k, v in base.items()})
    return {k: v for k, v in counts.items() if k in only} if only else counts


def run_families(stats: Stats, counts: dict, runners: dict, log=print) -> None:
    """Run ``runners[family](n)`` for every family of ``counts``, timing each into ``stats.families``."""
    for fam, n in counts.items():
        t0 = time.perf_counter()
        if log:
            log(f"{fam}: {n} cases ...")
        runners[fam](n)
        if fam in stats.families:
            stats.families[fam]["seconds"] = round(time.perf_counter() - t0, 1)


def summary(stats: Stats, seed: int, scale: float, counts: dict, t_all: float) -> dict:
    """The result object of a campaign (totals, per family, examples) from its :class:`Stats`."""
    total = sum(s["cases"] for s in stats.families.values())
    failures = sum(sum(s["failures"].values()) for s in stats.families.values())
    return {"seed": seed, "scale": scale, "cases": total, "failures": failures,
            "seconds": round(time.perf_counter() - t_all, 1), "families": stats.families,
            "examples": stats.examples, "requested": counts}


def print_table(res: dict) -> None:
    rows = [[name, str(s["cases"]), str(s["accepted"]), str(s["refused"]), str(sum(s["failures"].values())),
             f"{s['max_seconds']:.2f}", f"{s['max_peak_bytes'] / 2**20:.1f}", str(s.get("seconds", ""))]
            for name, s in res["families"].items()]
    print(readers._table(["family", "cases", "accepted", "refused", "failures", "max s", "max MB",
                               "total s"], rows))
    fails = Counter()
    for name, s in res["families"].items():
        for f, c in s["failures"].items():
            fails[(name, f)] += c
    if fails:
        print()
        print(readers._table(["family", "failure", "count"], [[k[0], k[1], str(v)] for k, v in
                                                                   sorted(fails.items())]))
        shown = set()
        for e in res["examples"]:
            if (e["family"], e["failure"]) not in shown:
                shown.add((e["family"], e["failure"]))
                print(f"  e.g. [{e['family']}] {e['failure']} <- {e['case'][:120]}: {e['detail'][:160]}")
    print(f"total: {res['cases']} cases in {res['seconds']} s, {res['failures']} failures")


def run_main(argv, doc: str, families, run, default_out: str) -> int:
    """The command line of a campaign: ``--scale``, ``--seed``, ``--only``, ``--out``; ``run(scale, seed, only)``
    returns the result, which is printed, written (atomically) and gives exit 1 on any failure."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--scale", type=float, default=1.0, help="multiplies every family's number of cases")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--only", default="", help=f"comma-separated families ({','.join(families)})")
    ap.add_argument("--out", default=str(ROOT / "tests" / "fuzz" / "results" / default_out))
    args = ap.parse_args(argv)
    only = {s.strip() for s in args.only.split(",") if s.strip()} or None
    res = run(args.scale, args.seed, only)
    print_table(res)
    atomic_write_text(Path(args.out), json.dumps(res, indent=1, sort_keys=True, default=str), make_parents=True)
    print(f"wrote {args.out}")
    return 1 if res["failures"] else 0


def main(argv=None) -> int:
    return run_main(argv, __doc__, FAMILIES, campaign, "fuzz_campaign.json")


if __name__ == "__main__":
    sys.exit(main())
