"""Hostile inputs on the surfaces QuaterNet, locomotion and acRNN added (issue #28, spec/robustness.md §11.1).

Families (each case seeded from ``random.Random``, classified by ``tests.fuzz.campaign._classify``: bounded time per
case, only the allowed exceptions):

=================  ==========================================================================================
``wrapper-args``   the onnxruntime wrappers of the new models (``QuaterNetRuntime``, ``QuaterNetCNNRuntime``,
                   the long-term ``Runtime``, ``ACRNNRuntime``: ``predict``, ``start``, ``step``, ``pace``,
                   ``rollout``, ``initial_state``, ``generate``, ``zero_state``) with one argument spoiled:
                   strings, bytes, booleans, complex, objects, ``None``, NaN/inf, wrong ranks, empty axes,
                   non-integer / negative / huge counts. Only ``ValueError``; a spoiled argument must be
                   refused (accepting a string, bool or complex array or a ``3.5`` count is ``Coerced``);
                   a valid call gives finite floats of the asked shape; no case may run past 5 s
``task-ckpt``      re-signed checkpoints of every new model (acRNN, QuaterNet, its CNN, quaternet-long, pace)
                   with one task field or config field hostile (types, ranges, shapes, labels that disagree:
                   acRNN's ``data_representation`` / ``row`` / ``variant`` / ``frame_size``, a prediction
                   checkpoint's ``dataset`` / ``num_joints`` / ``frame_time``, locomotion ``rig``,
                   ``skeleton``, ``seed_clip``, ``mean`` / ``std``): ``load_trained`` raises only
                   ``BadInputError``; an accepted file must be consistent (an independent oracle of the labels
                   and the frame size) and ``refimpl generate`` on it exits 0 or 3 with one line
``cli-options``    ``refimpl`` commands with one hostile size or value (``--length``, ``--seconds``, ``--speed``,
                   ``--path`` specs, ``--samples-per-sequence``, ``--downsample``, ``--transition-length``,
                   ``--betas``, ``--window-length``, ``--locomotion-*``, ``--pace-chunk-length``, ``--set``
                   of every config field of the six models): exit 0 or 2, one line, never past 60 s
``cli-files``      files named on the command line: ``--path`` CSV files mutated (NaN, missing values, ``;``,
                   UTF-16, one column, huge coordinates, junk), ``--onnx`` folders of another model or with a
                   damaged ``.onnx``, 0-frame BVH files and ONNX files with deep or mistyped metadata for
                   ``info``, exp-map folders without training sequences: exit 0 or 3, one line naming the file
``divergence``     ``refimpl train --lr 1e30 --checkpoint-every 1`` of the new models: exit 1 with one line naming
                   the step; any checkpoint left is accepted by ``load_trained``
=================  ==========================================================================================

Usage::

    python -m tests.fuzz.surfaces [--scale 1.0] [--seed 0] [--only wrapper-args,task-ckpt]

``--scale 1`` runs 5,200 cases. Prints the table, writes ``tests/fuzz/results/fuzz_surfaces.json`` (atomic) and
exits 1 on any failure. ``tests/test_hostile_surfaces.py`` runs a small share and the regression cases of #28.
"""
from __future__ import annotations

import contextlib
import copy
import dataclasses
import io
import json
import random
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

from tests.fuzz import campaign as fc  # noqa: E402


SAMPLE = ROOT / "refimpl" / "data" / "sample"
WALK_TXT = SAMPLE / "expmap" / "test" / "walking" / "walking_1.txt"
SALSA = SAMPLE / "salsa" / "16.bvh"
WALK_BVH = SAMPLE / "bvh" / "02_01.bvh"

#: Cases per family at ``--scale 1``.
BASE_CASES = {"wrapper-args": 2600, "task-ckpt": 1700, "cli-options": 600, "cli-files": 280, "divergence": 20}
FAMILIES = tuple(BASE_CASES)

TINY = {
    "acrnn": ["--model", "acrnn", "--data", "sample", "--set", "hidden_size=8", "--set", "num_layers=2",
              "--batch-size", "3", "--window-length", "12", "--representation", "euler"],
    "quaternet": ["--model", "quaternet", "--set", "hidden_size=8", "--set", "num_layers=1", "--set",
                  "prefix_length=12", "--set", "target_length=4", "--batch-size", "6"],
    "quaternet-cnn": ["--model", "quaternet-cnn", "--set", "channels=8", "--set", "kernel_sizes=2,2,2", "--set",
                      "dilations=1,2,4", "--set", "skips=0:1", "--set", "prefix_length=8", "--set",
                      "target_length=4", "--batch-size", "6"],
    "quaternet-long": ["--model", "quaternet-long", "--data", "sample", "--set", "hidden_size=8",
                       "--locomotion-prefix", "6", "--locomotion-target", "8", "--batch-size", "4"],
    "pace": ["--model", "pace", "--data", "sample", "--batch-size", "4", "--pace-chunk-length", "60"],
    "qtg": ["--model", "qtg", "--data", str(WALK_BVH), "--batch-size", "8", "--stride", "8", "--test-fraction",
            "0.5", *fc.TINY],
}
EXPORT_DIRS = {"acrnn": "acrnn", "quaternet": "quaternet", "quaternet-cnn": "quaternet-cnn",
               "quaternet-long": "quaternet-long", "pace": "quaternet-long", "qtg": "qtg"}


def _main(argv) -> tuple[int, str]:
    """``refimpl``'s ``main(argv)`` in-process: ``(exit code, stderr)``."""
    from refimpl.cli import main

    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["--blas-threads", "1", *map(str, argv)])
    return code, err.getvalue()


def make_seeds(tmp: Path) -> dict:
    """Tiny checkpoints of the six models (2 steps each) and the exported folders of the five new ones."""
    seeds = {}
    for name, argv in TINY.items():
        run = tmp / f"seed_{name}"
        code, err = _main(["train", *argv, "--out", run, "--steps", "2", "--progress-every", "10"])
        if code != 0:
            raise SystemExit(f"could not train the {name} seed (exit {code}): {err[-300:]}")
        seeds[name] = run / "checkpoint.npz"
        if name != "qtg":
            code, err = _main(["export", "--checkpoint", seeds[name], "--out", tmp / f"onnx_{name}", "--no-verify"])
            if code != 0:
                raise SystemExit(f"could not export the {name} seed (exit {code}): {err[-300:]}")
            seeds[f"onnx:{name}"] = tmp / f"onnx_{name}"
    code, err = _main(["export", "--checkpoint", seeds["qtg"], "--out", tmp / "onnx_qtg", "--no-verify",
                       "--transition-length", "4"])
    seeds["onnx:qtg"] = tmp / "onnx_qtg"
    return seeds


# ------------------------------------------------------------------------------------------------------------
# wrapper-args
# ------------------------------------------------------------------------------------------------------------

COUNTS_BAD = [True, False, "3", -1, 0, 1.5, 3.0, None, 10**9, 2**70, 100_001, [3], np.float64(3.0), complex(3, 0),
              np.array([3]), b"3"]
COUNTS_OK = [1, 2, 3, np.int64(2), np.int32(3)]
ARRAY_BAD = ["str", "bytes", "bool", "complex", "object", "none", "nan", "inf", "zero_d", "empty", "extra_axis",
             "wrong_last", "dict", "ragged", "huge"]
ARRAY_OK = ["int", "float64", "list"]


def _spoil(a: np.ndarray, kind: str):
    if kind == "str":
        return a.astype(str)
    if kind == "bytes":
        return a.astype("S8")
    if kind == "bool":
        return a > 0
    if kind == "complex":
        return a.astype(np.complex64)
    if kind == "object":
        return a.astype(object)
    if kind == "none":
        return None
    if kind in ("nan", "inf"):
        b = a.astype(np.float32).copy()
        b.reshape(-1)[0] = np.nan if kind == "nan" else np.inf
        return b
    if kind == "zero_d":
        return np.float32(1.0)
    if kind == "empty":
        return a[:0]
    if kind == "extra_axis":
        return a[None]
    if kind == "wrong_last":
        return a[..., :-1]
    if kind == "dict":
        return {"x": a}
    if kind == "ragged":
        return [a.tolist(), [1.0]]
    if kind == "huge":
        return np.full(a.shape, 1e39)
    if kind == "int":
        return np.round(a).astype(np.int64)
    if kind == "float64":
        return a.astype(np.float64)
    if kind == "list":
        return a.tolist()
    raise ValueError(kind)


class _Wrappers:
    """The four wrappers loaded from the seed folders, and their valid arguments."""

    def __init__(self, seeds):
        from deploy.models.acrnn_io import Runtime as ACRNNRuntime
        from deploy.models.quaternet_cnn_io import Runtime as QuaterNetCNNRuntime
        from deploy.models.quaternet_io import Runtime as QuaterNetRuntime
        from deploy.models.quaternet_long_io import Runtime as LongRuntime

        self.qn = QuaterNetRuntime.from_dir(seeds["onnx:quaternet"])
        self.cnn = QuaterNetCNNRuntime.from_dir(seeds["onnx:quaternet-cnn"])
        self.long = LongRuntime.from_dir(seeds["onnx:quaternet-long"])
        self.pace = LongRuntime.from_dir(seeds["onnx:pace"])
        self.acrnn = ACRNNRuntime.from_dir(seeds["onnx:acrnn"])
        g = np.random.default_rng(0)
        q = g.standard_normal((2, 6, 38, 4)).astype(np.float32)
        self.prefix = q / np.linalg.norm(q, axis=-1, keepdims=True)
        F_long = self.long.step_model.inputs[0][1][1]
        L, _, H = self.long.h0.shape
        self.long_x = (0.1 * g.standard_normal((2, F_long))).astype(np.float32)
        self.long_inputs = (0.1 * g.standard_normal((2, 9, F_long))).astype(np.float32)
        self.pace_x = np.cumsum(0.3 * np.ones((2, 12, 2), np.float32), axis=1)
        cfg = self.acrnn.config
        F = int(cfg["frame_size"])
        self.seed = (0.05 * g.standard_normal((2, 4, F))).astype(np.float32)
        self.frame = self.seed[:, 0]
        self.state = self.acrnn.zero_state(2)
        qcfg = self.qn.init_model.metadata["model"]["config"]
        self.hidden = np.zeros((qcfg["num_layers"], 2, qcfg["hidden_size"]), np.float32)
        self.long_state = np.zeros((L, 2, H), np.float32)

    def targets(self):
        """name -> (callable, {argument: (valid value, 'array' | 'count')}, check(result, args) -> str|None)."""
        def frames_check(k_key, lead):
            def check(out, args):
                out = np.asarray(out)
                if out.dtype.kind != "f" or not np.isfinite(out).all():
                    return f"non-finite or non-float output {out.dtype}"
                k = int(args[k_key])
                if out.shape[:2] != (lead, k):
                    return f"output shape {out.shape}, expected ({lead}, {k}, ...)"
                return None
            return check

        def finite(out, args):
            parts = out if isinstance(out, tuple) else (out,)
            for p in parts:
                for v in (p.values() if isinstance(p, dict) else (p,)):
                    v = np.asarray(v)
                    if v.dtype.kind != "f" or not np.isfinite(v).all():
                        return f"non-finite or non-float output {v.dtype}"
            return None

        return {
            "qn.predict": (lambda a: self.qn.predict(a["prefix"], a["k"]),
                           {"prefix": (self.prefix, "array"), "k": (3, "count")}, frames_check("k", 2)),
            "qn.predict_loop": (lambda a: self.qn.predict(a["prefix"], a["k"], use_graph=False),
                                {"prefix": (self.prefix, "array"), "k": (2, "count")}, frames_check("k", 2)),
            "qn.step": (lambda a: self.qn.step(a["x"], a["hidden"]),
                        {"x": (self.prefix[:, 0].reshape(2, -1), "array"), "hidden": (self.hidden, "array")}, finite),
            "cnn.predict": (lambda a: self.cnn.predict(a["prefix"], a["k"]),
                            {"prefix": (self.prefix, "array"), "k": (3, "count")}, frames_check("k", 2)),
            "cnn.step": (lambda a: self.cnn.step(a["window"]), {"window": (self.prefix, "array")}, finite),
            "long.step": (lambda a: self.long.step(a["x"], a["state"]),
                          {"x": (self.long_x, "array"), "state": (self.long_state, "array")}, finite),
            "long.rollout": (lambda a: self.long.rollout(a["inputs"], a["prefix"]),
                             {"inputs": (self.long_inputs, "array"), "prefix": (4, "count")}, finite),
            "long.initial_state": (lambda a: self.long.initial_state(a["batch"]), {"batch": (2, "count")}, finite),
            "pace.pace": (lambda a: self.pace.pace(a["x"]), {"x": (self.pace_x, "array")}, finite),
            "acrnn.generate": (lambda a: self.acrnn.generate(a["seed"], a["num_frames"]),
                               {"seed": (self.seed, "array"), "num_frames": (3, "count")},
                               frames_check("num_frames", 2)),
            "acrnn.generate_loop": (lambda a: self.acrnn.generate(a["seed"], a["num_frames"], use_generator=False),
                                    {"seed": (self.seed, "array"), "num_frames": (2, "count")},
                                    frames_check("num_frames", 2)),
            "acrnn.step": (lambda a: self.acrnn.step(a["frame"], a["state"]),
                           {"frame": (self.frame, "array"), "state": (self.state, "state")}, finite),
            "acrnn.zero_state": (lambda a: self.acrnn.zero_state(a["batch"]), {"batch": (2, "count")}, finite),
        }


def fam_wrapper_args(stats, n, seed, seeds, log):
    w = _Wrappers(seeds)
    targets = w.targets()
    names = sorted(targets)
    rng = random.Random(seed)
    for i in range(n):
        name = names[i % len(names)]
        fn, spec, check = targets[name]
        args = {k: v for k, (v, _) in spec.items()}
        arg = rng.choice(sorted(spec))
        value, kind = spec[arg]
        if kind == "count":
            bad = rng.random() < 0.7
            args[arg] = rng.choice([c for c in COUNTS_BAD if arg != "batch" or not (type(c) is int and c == 100_001)]
                                   if bad else COUNTS_OK)
            what = f"{name} {arg}={args[arg]!r:.30}"
        elif kind == "state":
            bad = True
            args[arg] = rng.choice([None, (), (w.hidden,), "hc", {"h": 1}, (None, None), [w.state[0]] * 3])
            what = f"{name} {arg}={type(args[arg]).__name__}"
        else:
            bad = rng.random() < 0.75
            spoil = rng.choice(ARRAY_BAD if bad else ARRAY_OK)
            args[arg] = _spoil(np.asarray(value), spoil)
            if name == "long.step" and arg == "state" and spoil == "none":
                bad = False  # None is the learned initial state
            what = f"{name} {arg}:{spoil}"

        def case():
            out = fn(args)
            if bad:
                return f"Coerced: {what} was accepted"
            return check(out, args)
        kind_, failure, detail, sec, peak = fc._classify(case, (ValueError,), 5.0, check_memory=False)
        if failure == "AcceptedMalformed" and detail.startswith("Coerced"):
            failure = "Coerced"
        stats.add("wrapper-args", kind_, failure, detail, sec, peak, what)
        if log and (i + 1) % 1000 == 0:
            log(f"  wrapper-args {i + 1}/{n}")


# ------------------------------------------------------------------------------------------------------------
# task-ckpt
# ------------------------------------------------------------------------------------------------------------

def _skeleton_variants(sk: dict) -> list:
    J = len(sk["parents"])
    out = [{}, {"parents": sk["parents"]}, dict(sk, parents=[-1] + [J + 5] * (J - 1)),
           dict(sk, parents=sk["parents"][:-1]), dict(sk, names=[sk["names"][0]] * J),
           dict(sk, offsets=[[1e300, 0.0, 0.0]] * J), dict(sk, offsets="x"), dict(sk, names=5),
           dict(sk, parents=[True] * J), dict(sk, offsets=[[0.0, 0.0]] * J)]
    if "joints_left" in sk:
        out += [dict(sk, joints_left=[J + 3]), dict(sk, joints_left=sk["joints_left"][:-1]),
                {k: v for k, v in sk.items() if k != "joints_right"}]
    return out


def _task_values(model: str, cfg: dict) -> dict:
    """field -> hostile values for the task fields of ``model``'s checkpoints."""
    from refimpl.protocols.synthesis import VARIANTS
    from refimpl.representations import REPRESENTATIONS
    from refimpl.protocols.synthesis import TABLE1_ROWS

    common = {"fps": [0, -30.0, 1e308, "30", None, True, 1e-300], "dtype": ["float16", 1, None],
              "representation": ["bogus", 3, None, "quaternion", "positions", "euler", "dq-all"]}
    if model == "acrnn":
        F = cfg["frame_size"]
        return {**common,
                "data_representation": list(REPRESENTATIONS) + ["bogus", 3, None],
                "row": list(TABLE1_ROWS) + ["bogus", 7],
                "representation": list(TABLE1_ROWS) + ["bogus", None],
                "variant": list(VARIANTS) + ["bogus", []],
                "frame_size": [F - 1, F + 1, 3 + 4 * 43, 3 + 8 * 43, 0, -1, 1.5],
                "mean": [[0.0] * (F - 1), [1e308] * F, ["x"] * F, "x", [], [[0.0]] * F],
                "std": [[0.0] * F, [1e-300] * F, [-1.0] * F, [1.0] * (F + 1), None, [1e308] * F],
                "skeleton": _skeleton_variants(cfg["skeleton"]) + ["x", None, []],
                "loss_weights": [{}, {"mse": -1.0}, {"mse": "x"}, [], {"mse": 1e308}],
                "window_length": [0, -5, 1.5, "12", 10**30],
                "train_takes": [[1], "01", None]}
    if model in ("quaternet", "quaternet-cnn"):
        return {**common, "dataset": ["h36m", "bogus", None, 3, ["cmu"]],
                "frame_time": [0, -0.1, 1e-300, 1e308, "0.01", None, 1.0 / 30],
                "num_joints": [32, 37, 39, 0, -1, 10**9, True], "fps": [0, 25.0, 1e308, -1]}
    seed_clip = cfg.get("seed_clip")
    out = {**common, "rig": ["bogus", "salsa", None, 3, "bandai_namco", "cmu"],
           "skeleton": _skeleton_variants(cfg["skeleton"]) + ["x", None],
           "prefix": [0, -1, 1.5, "6"], "target": [0, -1, None]}
    if seed_clip is not None:
        rot = np.asarray(seed_clip["rotations"])
        feat = np.asarray(seed_clip["features"])
        out["seed_clip"] = [{}, "x", None, dict(seed_clip, rotations=np.zeros_like(rot).tolist()),
                            dict(seed_clip, rotations=rot[:, :-1].tolist()), dict(seed_clip, features=feat[:, :-1].tolist()),
                            dict(seed_clip, features=(feat * 1e300).tolist()), dict(seed_clip, rotations=[]),
                            dict(seed_clip, features=feat[:1].tolist()), {"rotations": rot.tolist()}]
        out["num_joints"] = [25, 27, 0, 10**9]
    return out


def _acrnn_labels_agree(cfg: dict) -> str | None:
    """The oracle of an accepted acRNN checkpoint: the labels and the frame size agree (computed here from the
    paper's tables, not with the schema's code)."""
    from refimpl.protocols.synthesis import VARIANTS
    from refimpl.representations import REPRESENTATIONS
    from refimpl.protocols.synthesis import TABLE1_ROWS

    rep, variant, row = cfg.get("data_representation"), cfg.get("variant"), cfg.get("row")
    if variant not in VARIANTS or VARIANTS[variant].representation != rep:
        return f"variant {variant!r} with data_representation {rep!r}"
    for r in (row, cfg.get("representation")):
        if r is not None and TABLE1_ROWS.get(r) != variant:
            return f"row {r!r} with variant {variant!r}"
    J = len(cfg["skeleton"]["parents"])
    if cfg.get("frame_size") != 3 + REPRESENTATIONS[rep].dim * J:
        return f"frame_size {cfg.get('frame_size')} for {rep} frames of {J} joints"
    return None


def _generate_argv(model: str, path: Path, seeds: dict, out: Path) -> list:
    if model == "acrnn":
        return ["generate", "--checkpoint", path, "--source", SALSA, "--length", "3", "--out", out]
    if model in ("quaternet", "quaternet-cnn"):
        return ["generate", "--checkpoint", path, "--source", WALK_TXT, "--source-frame", "20", "--length", "3",
                "--out", out]
    if model == "pace":
        return ["generate", "--model", "quaternet-long", "--checkpoint", seeds["quaternet-long"], "--pace", path,
                "--seconds", "0.3", "--out", out]
    return ["generate", "--model", "quaternet-long", "--checkpoint", path, "--pace", seeds["pace"], "--seconds",
            "0.3", "--out", out]


def _check_cli(code, err, command, codes=(0, 2, 3), names=None) -> str | None:
    """Why ``(code, stderr)`` of ``refimpl <command>`` breaks the contract, or None: an allowed exit code, no
    traceback or warning, on failure exactly one line ``refimpl <command>: error: ...`` besides argparse's usage
    text, naming one of ``names`` (the file) when given."""
    if code not in codes:
        return f"exit {code} (expected one of {codes}): {err.strip()[-200:]}"
    if code == 2 and err.lstrip().startswith("usage:"):  # argparse: the usage text, then its one error line
        err = "\n".join(ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("usage:", " ")))
    if code == 0:  # success: progress lines on stderr are fine (eval, train), a traceback or warning is not
        return "traceback or warning on stderr" if ("Traceback" in err or "Warning" in err) else None
    bad = fc._check_cli(2, err, command)
    if bad is not None:
        return f"{bad}: {err.strip()[-200:]}"
    if code not in (0, 1) and names and not any(str(nm) in err for nm in names):
        return f"the error does not name {names[0]}: {err.strip()[-200:]}"
    return None


def fam_task_ckpt(stats, n, seed, seeds, tmp, log):
    from refimpl.checkpoint import load_checkpoint
    from refimpl.errors import BadInputError
    from refimpl.services import load_trained

    models = ["acrnn", "quaternet", "quaternet-cnn", "quaternet-long", "pace"]
    content = {m: fc._inference_content(load_checkpoint(seeds[m])) for m in models}
    values = {m: _task_values(m, content[m][1]["model_config"]) for m in models}
    rng = random.Random(seed)
    path = tmp / "task.npz"
    for i in range(n):
        model = models[i % len(models)]
        arrays, meta = content[model]
        meta = copy.deepcopy(meta)
        cfg = meta["model_config"]
        if rng.random() < 0.8:
            key = rng.choice(sorted(values[model]))
            cfg[key] = copy.deepcopy(rng.choice(values[model][key]))
        else:
            key = rng.choice(sorted(cfg))
            cfg[key] = copy.deepcopy(rng.choice(fc.HOSTILE))
        what = f"{model} model_config.{key}={cfg[key]!r:.50}"
        fc.write_crafted(path, arrays, meta)
        run_cli, refused = [False], [False]

        def case():
            try:
                loaded = load_trained(path)
            except BadInputError:
                refused[0] = True
                return None
            if model == "acrnn":
                bad = _acrnn_labels_agree(loaded.extra)
                if bad:
                    return f"AcceptedInconsistent: {bad}"
            run_cli[0] = True
            code, err = _main(_generate_argv(model, path, seeds, tmp / "task_out.bvh"))
            return _check_cli(code, err, "generate")
        kind, failure, detail, sec, peak = fc._classify(case, (), 60.0, check_memory=False)
        if failure == "AcceptedMalformed":
            failure = detail.split(":")[0] if detail.startswith("AcceptedInconsistent") else "CliContract"
        stats.add("task-ckpt", "BadInputError" if refused[0] else kind, failure, detail, sec, peak, what)
        if log and (i + 1) % 500 == 0:
            log(f"  task-ckpt {i + 1}/{n}")


# ------------------------------------------------------------------------------------------------------------
# cli-options
# ------------------------------------------------------------------------------------------------------------

SIZE_BAD = ["0", "-1", "1e20", "99999999999", "1" + "0" * 22, "100001", "nan", "inf", "-inf", "x", "", "1.5",
            "1e-12", "0.01", "0.04"]
SET_VALUES = ["0", "-1", "1", "2", "1" + "0" * 22, "99999999999", "100001", "1e308", "nan", "inf", "-inf", "", "x",
              "1,2", ",".join(["8"] * 1500), "true", "3.5", "bogus", "0:1", "8,8,8,8,8,8,8,8"]


def _config_fields(model: str) -> list:
    from refimpl.registry import MODELS

    return [f.name for f in dataclasses.fields(MODELS[model].config_type)]


def _option_case(rng, seeds, tmp):
    """``(argv, description, allowed exit codes)`` of one command with one hostile option value."""
    out = tmp / "opt_out"
    bvh = out / "o.bvh"
    kind = rng.choice(["length-qn", "length-acrnn", "length-qtg", "context", "seconds", "speed", "path", "samples",
                       "downsample", "export-T", "eval-T", "betas", "window", "loco", "chunk", "set", "set",
                       "set", "set"])
    v = rng.choice(SIZE_BAD)
    loco = ["generate", "--model", "quaternet-long", "--checkpoint", seeds["quaternet-long"], "--pace",
            seeds["pace"], "--out", bvh]
    if kind == "length-qn":
        argv = ["generate", "--checkpoint", seeds["quaternet"], "--source", WALK_TXT, "--source-frame", "20",
                "--length", v, "--out", bvh]
    elif kind == "length-acrnn":
        argv = ["generate", "--checkpoint", seeds["acrnn"], "--source", SALSA, "--length", v, "--out", bvh]
    elif kind == "length-qtg":
        argv = ["generate", "--checkpoint", seeds["qtg"], "--source", WALK_BVH, "--source-frame", "20",
                "--length", v, "--out", bvh]
    elif kind == "context":
        argv = ["generate", "--checkpoint", seeds["qtg"], "--source", WALK_BVH, "--source-frame", "20",
                "--length", "3", "--context", v, "--out", bvh]
    elif kind == "seconds":
        argv = [*loco, "--seconds", v]
    elif kind == "speed":
        argv = [*loco, "--seconds", "0.5", "--speed", rng.choice(SIZE_BAD + ["1e300", "walk", "jog", "0.5"])]
    elif kind == "path":
        spec = rng.choice(["circle:r=", "figure8:size=", "line-turn:turn="]) + rng.choice(
            SIZE_BAD + ["1e5", "1e-12", "1e300", "3", "-3", "360"])
        argv = [*loco, "--seconds", "0.5", "--path", rng.choice([spec, "circle:r", "square", "circle:q=1",
                                                                 spec + ",r=2"])]
    elif kind == "samples":
        argv = ["eval", "--checkpoint", seeds["quaternet"], "--samples-per-sequence", v]
    elif kind == "downsample":
        argv = ["train", *TINY["quaternet"], "--out", out / "run", "--steps", "1", "--downsample", v]
    elif kind == "export-T":
        argv = ["export", "--checkpoint", seeds["qtg"], "--out", out / "onnx", "--no-verify",
                "--transition-length", v]
    elif kind == "eval-T":
        argv = ["eval", "--checkpoint", seeds["qtg"], "--data", WALK_BVH, "--transition-length", v]
    elif kind == "betas":
        argv = ["train", *TINY["pace"], "--out", out / "run", "--steps", "1", "--betas",
                rng.choice(["1", "1.5", "-0.1", "nan", "0.9", "0.999999"]), rng.choice(["1", "2", "0.9", "inf"])]
    elif kind == "window":
        argv = ["train", *TINY["acrnn"], "--out", out / "run", "--steps", "1", "--window-length", v]
    elif kind == "loco":
        opt = rng.choice(["--locomotion-prefix", "--locomotion-target", "--locomotion-max-files"])
        argv = ["train", *TINY["quaternet-long"], "--out", out / "run", "--steps", "1", opt, v]
    elif kind == "chunk":
        argv = ["train", *TINY["pace"], "--out", out / "run", "--steps", "1", "--pace-chunk-length", v]
    else:
        model = rng.choice(sorted(TINY))
        field = rng.choice(_config_fields(model))
        value = rng.choice(SET_VALUES)
        argv = ["train", *TINY[model], "--out", out / "run", "--steps", "1", "--set", f"{field}={value}"]
        kind = f"set {model} {field}={value[:20]}"
    return argv, f"{kind} {' '.join(map(str, argv[-2:]))[-60:]}", (0, 2)


def _cli_family(stats, name: str, n: int, seed: int, make_case, log) -> None:
    """``n`` command-line cases ``make_case(rng) -> (argv, description, allowed exit codes, names)`` run in-process
    under a 60 s limit and checked by :func:`_check_cli`."""
    rng = random.Random(seed)
    for i in range(n):
        argv, what, codes, names = make_case(rng)

        def case():
            code, err = _main(argv)
            return _check_cli(code, err, argv[0], codes, names)
        kind, failure, detail, sec, peak = fc._classify(case, (), 60.0, check_memory=False)
        if failure == "AcceptedMalformed":
            failure = "CliContract"
        stats.add(name, kind, failure, detail, sec, peak, what)
        if log and (i + 1) % 100 == 0:
            log(f"  {name} {i + 1}/{n}")


def fam_cli_options(stats, n, seed, seeds, tmp, log):
    def make(rng):
        shutil.rmtree(tmp / "opt_out", ignore_errors=True)
        (tmp / "opt_out").mkdir()
        return (*_option_case(rng, seeds, tmp), None)
    _cli_family(stats, "cli-options", n, seed, make, log)


# ------------------------------------------------------------------------------------------------------------
# cli-files
# ------------------------------------------------------------------------------------------------------------

CSV_GOOD = "x,z\n0,0\n1,0\n2,0.5\n3,1.5\n3.5,3\n"


def _csv_case(rng, path: Path) -> str:
    kind = rng.choice(["nan", "missing", "semicolon", "utf16", "one-column", "huge", "junk", "empty", "header",
                       "inf", "text", "dup", "good", "nul", "1e400"])
    edits = {"nan": ("2,0.5", "2,nan"), "missing": ("2,0.5", "2,"), "semicolon": (",", ";"),
             "huge": ("3.5,3", rng.choice(["1e30,3", "3.5,1e300", "1e6,1e6", "-1e12,0"])), "inf": ("1,0", "inf,0"),
             "text": ("1,0", "one,zero"), "dup": ("1,0\n", "1,0\n1,0\n"), "nul": ("1,0", "1\x00,0"),
             "1e400": ("1,0", "1e400,0")}
    whole = {"one-column": "\n".join(ln.split(",")[0] for ln in CSV_GOOD.splitlines()), "empty": "", "header": "x,z\n",
             "junk": "".join(chr(rng.randrange(1, 256)) for _ in range(200))}
    text = CSV_GOOD.replace(*edits[kind]) if kind in edits else whole.get(kind, CSV_GOOD)
    if kind == "utf16":
        path.write_bytes(CSV_GOOD.encode("utf-16"))
    else:
        path.write_bytes(text.encode("utf-8", "surrogateescape"))
    return kind


def _damaged_onnx_dir(src: Path, dst: Path, rng) -> str:
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(src, dst)
    f = rng.choice(sorted(dst.glob("*.onnx")))
    data = f.read_bytes()
    flipped = np.frombuffer(data, np.uint8).copy()
    for _ in range(rng.randint(1, 8)):
        flipped[rng.randrange(flipped.size)] ^= np.uint8(1 << rng.randrange(8))
    damage = {"truncate": lambda: data[:rng.randrange(1, len(data))], "bitflip": flipped.tobytes,
              "junk": lambda: bytes(rng.getrandbits(8) for _ in range(rng.randint(1, 500))), "empty": lambda: b""}
    kind = rng.choice(sorted(damage))
    f.write_bytes(damage[kind]())
    return f"{kind} {f.name}"


def _odd_metadata_onnx(src: Path, dst: Path, rng) -> str:
    import onnx

    m = onnx.load(str(src))
    key = rng.choice(["skeleton", "normalization", "model", "frame_rate", "representation", "io", "custom"])
    value = rng.choice(["[" * 5000 + "]" * 5000, json.dumps({"names": 5}), json.dumps({"mean": "x"}),
                        json.dumps({"mean": [[1, 2], [3]]}), "{", json.dumps([1, 2]), "nan", json.dumps({"a": {}}),
                        json.dumps({"names": [1, None]}), "x" * 20000])
    props = {p.key: p.value for p in m.metadata_props}
    props[key] = value
    del m.metadata_props[:]
    for k, v in props.items():
        m.metadata_props.add(key=k, value=v)
    onnx.save(m, str(dst))
    return f"{key}={value[:30]!r}"


def _file_case(rng, seeds, tmp):
    """``(argv, description, allowed exit codes, names the error must contain)``."""
    d = tmp / "file_case"
    shutil.rmtree(d, ignore_errors=True)
    d.mkdir()
    kind = rng.choice(["csv", "csv", "csv", "onnx-other", "onnx-damaged", "onnx-damaged", "info-bvh",
                       "info-onnx", "info-onnx", "expmap"])
    loco = ["generate", "--model", "quaternet-long", "--checkpoint", seeds["quaternet-long"], "--pace",
            seeds["pace"], "--seconds", "0.5", "--out", d / "w.bvh"]
    if kind == "csv":
        p = d / "path.csv"
        what = _csv_case(rng, p)
        return [*loco, "--path", p], f"csv {what}", (0, 3), [p]
    if kind in ("onnx-other", "onnx-damaged"):
        model = rng.choice(["acrnn", "quaternet", "quaternet-cnn"])
        if kind == "onnx-other":
            other = rng.choice([m for m in ("acrnn", "quaternet", "quaternet-cnn", "qtg", "quaternet-long")
                                if m != model])
            onnx_dir, what = seeds[f"onnx:{other}"], f"{model} with {other}'s folder"
        else:
            onnx_dir = d / "onnx"
            what = f"{model} {_damaged_onnx_dir(seeds[f'onnx:{model}'], onnx_dir, rng)}"
        command = rng.choice(["generate", "eval"])
        if command == "eval" and model != "acrnn":
            argv = ["eval", "--checkpoint", seeds[model], "--onnx", onnx_dir, "--samples-per-sequence", "1"]
        elif model == "acrnn":
            argv = ["generate", "--checkpoint", seeds[model], "--backend", "onnx", "--onnx", onnx_dir, "--source",
                    SALSA, "--length", "3", "--out", d / "o.bvh"]
        else:
            argv = ["generate", "--checkpoint", seeds[model], "--backend", "onnx", "--onnx", onnx_dir, "--source",
                    WALK_TXT, "--source-frame", "20", "--length", "3", "--out", d / "o.bvh"]
        return argv, f"{kind} {argv[0]} {what}", (0, 3), [onnx_dir]
    if kind == "info-bvh":
        text = WALK_BVH.read_text()
        head = text[:text.index("MOTION")]
        frames = rng.choice([0, 0, 1, 2])
        rows = text[text.index("Frame Time"):].splitlines()[1:1 + frames]
        p = d / "clip.bvh"
        p.write_text(head + f"MOTION\nFrames: {frames}\nFrame Time: 0.008333\n" + "".join(r + "\n" for r in rows))
        return ["info", p], f"info-bvh {frames} frames", (0,), [p]
    if kind == "info-onnx":
        src = rng.choice(sorted(seeds[f"onnx:{rng.choice(['acrnn', 'quaternet', 'qtg'])}"].glob("*.onnx")))
        p = d / "model.onnx"
        what = _odd_metadata_onnx(src, p, rng)
        return ["info", p], f"info-onnx {what}", (0, 3), [p]
    root = d / "expmap"
    (root / "train").mkdir(parents=True)
    (root / "test").mkdir()
    shutil.copy(WALK_TXT, root / "test" / "walking_1.txt")
    if rng.random() < 0.5:
        (root / "train" / "x.txt").write_text("")
    return (["train", *TINY["quaternet"], "--data", root, "--out", d / "run", "--steps", "1"],
            "expmap folder without training sequences", (3,), [root])


def fam_cli_files(stats, n, seed, seeds, tmp, log):
    _cli_family(stats, "cli-files", n, seed, lambda rng: _file_case(rng, seeds, tmp), log)


# ------------------------------------------------------------------------------------------------------------
# divergence
# ------------------------------------------------------------------------------------------------------------

def fam_divergence(stats, n, seed, seeds, tmp, log):
    from refimpl.errors import BadInputError
    from refimpl.services import load_trained

    rng = random.Random(seed)
    models = ["quaternet", "quaternet-cnn", "acrnn", "quaternet-long", "pace", "qtg"]
    for i in range(n):
        model = models[i % len(models)]
        lr = rng.choice(["1e30", "1e20", "1e12", "1e300"])
        run = tmp / "div_run"
        shutil.rmtree(run, ignore_errors=True)
        argv = ["train", *TINY[model], "--out", run, "--steps", "4", "--checkpoint-every", "1", "--lr", lr,
                "--progress-every", "10"]

        def case():
            code, err = _main(argv)
            if code == 0:
                return None  # a model whose loss saturates may survive a huge rate: nothing to check
            bad = _check_cli(code, err, "train", (1,))
            if bad:
                return bad
            line = err.strip().splitlines()[-1]
            if "step" not in line:
                return f"the error does not name the step: {line[-200:]}"
            if (run / "checkpoint.npz").exists():
                try:
                    load_trained(run / "checkpoint.npz")
                except BadInputError as exc:
                    return f"training left a checkpoint its loader refuses: {str(exc)[-200:]}"
            return None
        kind, failure, detail, sec, peak = fc._classify(case, (), 120.0, check_memory=False)
        if failure == "AcceptedMalformed":
            failure = "CliContract"
        stats.add("divergence", kind, failure, detail, sec, peak, f"{model} --lr {lr}")


# ------------------------------------------------------------------------------------------------------------
# campaign
# ------------------------------------------------------------------------------------------------------------

def campaign(scale: float = 1.0, seed: int = 0, only: set | None = None, log=print,
             counts: dict | None = None) -> dict:
    """Run the families (``counts``: cases per family, default :data:`BASE_CASES` × ``scale``)."""
    counts = fc.family_counts(BASE_CASES, scale, only, counts)
    stats = fc.Stats()
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fuzz_surfaces_") as tmp:
        tmp = Path(tmp)
        if log:
            log("training and exporting the seed models ...")
        seeds = make_seeds(tmp)
        runners = {"wrapper-args": lambda n: fam_wrapper_args(stats, n, seed, seeds, log),
                   "task-ckpt": lambda n: fam_task_ckpt(stats, n, seed, seeds, tmp, log),
                   "cli-options": lambda n: fam_cli_options(stats, n, seed, seeds, tmp, log),
                   "cli-files": lambda n: fam_cli_files(stats, n, seed, seeds, tmp, log),
                   "divergence": lambda n: fam_divergence(stats, n, seed, seeds, tmp, log)}
        fc.run_families(stats, counts, runners, log)
    return fc.summary(stats, seed, scale, counts, t_all)


def main(argv=None) -> int:
    return fc.run_main(argv, __doc__, FAMILIES, campaign, "fuzz_surfaces.json")


if __name__ == "__main__":
    sys.exit(main())
