"""The shipped trained models (issue 32, spec/cli.md §10): the commands that train them, and their model cards.

Every shipped model is trained by the project's own command line, in the background on one core
(``--blas-threads 1``), resumable (``--resume`` continues bit for bit). Two sub-commands::

    # print (or, with --run, run) the training command of a model, e.g. into runs/qtg_bn
    python -m experiments.pretrained train qtg-locomotion --runs /work/runs [--run]

    # from a finished run: the weights-only model.npz, its evaluation files and card.{json,md} in pretrained/<name>/
    python -m experiments.pretrained card qtg-locomotion --runs /work/runs

``card`` strips the checkpoint to its weights (:func:`refimpl.pretrained.weights_only`: no optimiser state),
evaluates the stripped file through ``refimpl eval`` exactly as its card says (``evaluation.command``, with
``pretrained:<name>``; the full results beside the card as ``eval.json``, and ``eval_sample.json`` on the embedded
sample where the model's rig is in it), exports it to ONNX and times one frame in onnxruntime at batch 1, and
writes ``card.json`` (the data :data:`refimpl.pretrained.CARD_FIELDS` name) and ``card.md`` (the same for people).
``tests/test_pretrained.py`` re-runs each card's evaluation commands and compares.

Shape legend: none (commands and files).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.checkpoint import load_checkpoint, save_checkpoint
from refimpl.pretrained import PREFIX, sha256_of, weights_only

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "pretrained"
BN = "../shared/data/bandai_namco_locomotion"
SALSA = "../shared/data/acrnn_cmu_salsa"
CMU = "../shared/data"

_CMU_TERMS = ("CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu; created with funding from NSF "
              "EIA-0196217): free for research; may be included in commercially-sold products, but not resold "
              "directly")
_BN_TERMS = ("Bandai-Namco-Research-Motiondataset, (c) 2022 Bandai Namco Research Inc., CC BY-NC 4.0 "
             "(non-commercial use only, with attribution)")
_BN_SPLIT = "split by whole takes: ids ending in 1 held out (95 of 830 takes), every content x style on both sides"
_CMU_DATA = {"name": "CMU walking and running, exp-map text (the CMU short-term benchmark)",
             "folder": CMU + "/dmgnn_cmu_expmap", "split": "the benchmark's train/ and test/ folders",
             "licence": _CMU_TERMS}
_SALSA_DATA = {"name": "CMU salsa, subjects 60 and 61 (acRNN's data), BVH", "folder": SALSA,
               "split": "the acRNN protocol's test takes (spec/acrnn.md)", "licence": _CMU_TERMS}
_BN_DATA = {"name": "Bandai Namco locomotion (dataset-2): walks, turns and runs in six styles, 830 BVH takes",
            "folder": BN, "split": _BN_SPLIT, "licence": _BN_TERMS}
_WEIGHTS_BN = ("CC BY-NC 4.0: these weights are trained on the Bandai Namco set and carry its non-commercial "
               "terms; they are not part of the installed package (the wheel)")
_WEIGHTS_CMU = "trained on CMU motion capture: CMU's terms (above) apply to the data; the weights are MIT like the code"

#: name -> what the card says and how the model is trained and evaluated. ``train``: the ``refimpl train``
#: arguments after the sub-command (``--out`` added: ``<runs>/<run>``); ``eval``: ``refimpl eval`` arguments after
#: ``--checkpoint pretrained:<name>`` on the real data (``../shared/data``) and, where the rig is in the embedded
#: sample, ``eval_sample`` on it.
MODELS = {
    "qtg-locomotion": {
        "title": "QTG transition generator, Bandai Namco locomotion, 100,000 steps at the paper's settings",
        "system": "QTG (Geleijn et al., IEEE VR 2021)", "model": "qtg", "run": "qtg_bn",
        "train": ["--model", "qtg", "--data", BN, "--stride", "2", "--steps", "100000", "--seed", "0",
                  "--checkpoint-every", "2000", "--validate-every", "2000", "--progress-every", "500"],
        "eval": ["--data", BN, "--join", "inertialize+footlock"], "eval_sample": None,
        "per_frame": ("qtg_step.onnx", 1),
        "data": _BN_DATA, "weights": _WEIGHTS_BN,
        "use": "transitions of 30 frames between two Bandai Namco-rig clips (21 joints, cm, 30 fps): "
               "`refimpl generate --checkpoint pretrained:qtg-locomotion --source A.bvh --target B.bvh ...`",
    },
    "quaternet-cmu": {
        "title": "QuaterNet short-term (2 x 512 GRU, velocity mode), CMU walking and running, 2,000 steps",
        "system": "QuaterNet (Pavllo et al., BMVC 2018 / IJCV 2020), short-term prediction", "model": "quaternet",
        "run": "qn_cmu",
        "train": ["--model", "quaternet", "--data", CMU, "--set", "hidden_size=512", "--steps", "2000",
                  "--seed", "0", "--checkpoint-every", "200"],
        "eval": ["--data", CMU, "--horizons", "table2"], "eval_sample": ["--data", "sample"],
        "per_frame": ("quaternet_step.onnx", 1),
        "data": _CMU_DATA, "weights": _WEIGHTS_CMU,
        "use": "continue a CMU exp-map clip from a 50-frame prefix: `refimpl generate --checkpoint "
               "pretrained:quaternet-cmu --source clip.txt --source-frame 80 --length 25 --out pred.bvh`",
    },
    "quaternet-cnn-cmu": {
        "title": "QuaterNet convolutional (512 channels, our reconstruction), CMU walking and running, 1,500 steps",
        "system": "QuaterNet (Pavllo et al., IJCV 2020 §3.2), causal dilated CNN", "model": "quaternet-cnn",
        "run": "qncnn_cmu",
        "train": ["--model", "quaternet-cnn", "--data", CMU, "--set", "channels=512", "--steps", "1500",
                  "--seed", "0", "--checkpoint-every", "200"],
        "eval": ["--data", CMU, "--horizons", "table2"], "eval_sample": ["--data", "sample"],
        "per_frame": ("quaternet-cnn_window.onnx", 1),
        "data": _CMU_DATA, "weights": _WEIGHTS_CMU,
        "use": "continue a CMU exp-map clip from a 32-frame window (`refimpl generate --checkpoint "
               "pretrained:quaternet-cnn-cmu ...`)",
    },
    "pace-locomotion": {
        "title": "QuaterNet pace network (bidirectional GRU, 30 units), Bandai Namco locomotion, 300 steps",
        "system": "QuaterNet (Pavllo et al., IJCV 2020 §3.7), long-term locomotion: the pace network",
        "model": "pace", "run": "pace_bn",
        "train": ["--model", "pace", "--data", BN, "--pace-chunk-length", "250", "--steps", "300", "--seed", "0"],
        "eval": None, "eval_sample": None, "per_frame": ("quaternet-long_pace.onnx", None), "sizes": {"N": 300},
        "data": _BN_DATA, "weights": _WEIGHTS_BN,
        "use": "the companion of quaternet-long-locomotion: `--pace pretrained:pace-locomotion` (one call per "
               "path: timed on a path of N = 300 points)",
    },
    "quaternet-long-locomotion": {
        "title": "QuaterNet long-term pose network (2 x 256 GRU), Bandai Namco locomotion, 1,000 steps",
        "system": "QuaterNet (Pavllo et al., IJCV 2020 §3.7), long-term locomotion along a path",
        "model": "quaternet-long", "run": "long_bn",
        "train": ["--model", "quaternet-long", "--data", BN, "--set", "hidden_size=256", "--set", "tf_decay=0.9",
                  "--steps", "1000", "--seed", "0", "--checkpoint-every", "250"],
        "eval": ["--data", BN], "eval_sample": None, "per_frame": ("quaternet-long_step.onnx", 1),
        "data": _BN_DATA, "weights": _WEIGHTS_BN,
        "use": "walk a path: `refimpl generate --model quaternet-long --checkpoint "
               "pretrained:quaternet-long-locomotion --pace pretrained:pace-locomotion --path circle:r=3 "
               "--speed walk --seconds 60 --out walk.bvh`",
    },
    "acrnn-dq-salsa": {
        "title": "acRNN (3 x 128 LSTM, auto-conditioning) with dual quaternions and all losses, CMU salsa, 600 steps",
        "system": "Dual-quaternion pose representation (Andreou et al.) inside acRNN (Zhou, Li et al. 2018)",
        "model": "acrnn", "run": "acrnn_dq",
        "train": ["--model", "acrnn", "--representation", "dq-all", "--data", SALSA, "--set", "hidden_size=128",
                  "--steps", "600", "--seed", "0", "--checkpoint-every", "100"],
        "eval": ["--data", SALSA], "eval_sample": ["--data", "sample"], "per_frame": ("acrnn_step.onnx", 1),
        "data": _SALSA_DATA, "weights": _WEIGHTS_CMU,
        "use": "long-term salsa from a 10-frame seed: `refimpl generate --checkpoint pretrained:acrnn-dq-salsa "
               "--source take.bvh --length 300 --out salsa.bvh`",
    },
    "acrnn-positions-salsa": {
        "title": "acRNN (3 x 128 LSTM) with the published positional frame (171 values), CMU salsa, 600 steps",
        "system": "acRNN (Zhou, Li et al. 2018), the published code's positional representation",
        "model": "acrnn", "run": "acrnn_pos",
        "train": ["--model", "acrnn", "--representation", "positions-published", "--data", SALSA, "--set",
                  "hidden_size=128", "--steps", "600", "--seed", "0", "--checkpoint-every", "100"],
        "eval": ["--data", SALSA], "eval_sample": ["--data", "sample"], "per_frame": ("acrnn_step.onnx", 1),
        "data": _SALSA_DATA, "weights": _WEIGHTS_CMU,
        "use": "long-term salsa from a 10-frame seed, as joint positions (`refimpl generate` writes BVH)",
    },
}


def _say(*a):
    print(*a, file=sys.stderr, flush=True)


def library_versions() -> dict:
    """Python, NumPy, its BLAS (name, version, kernel, threads; threadpoolctl) and onnx / onnxruntime versions."""
    out = {"python": platform.python_version(), "numpy": np.__version__, "machine": platform.machine(),
           "cpu_count": os.cpu_count()}
    try:
        from threadpoolctl import threadpool_info

        blas = [i for i in threadpool_info() if i.get("user_api") == "blas"]
        if blas:
            out["blas"] = {k: blas[0].get(k) for k in ("internal_api", "version", "architecture", "num_threads")}
    except ImportError:
        pass
    for name in ("onnx", "onnxruntime"):
        with contextlib.suppress(ImportError):
            out[name] = __import__(name).__version__
    return out


def train_command(name: str, runs: Path) -> list[str]:
    """The ``refimpl`` command line that trains ``name`` into ``<runs>/<run>`` (one BLAS thread)."""
    m = MODELS[name]
    return ["refimpl", "--blas-threads", "1", "train", *m["train"], "--out", str(runs / m["run"])]


def eval_command(name: str, which: str = "eval") -> list[str] | None:
    """The ``refimpl eval`` command of a card (``which``: ``eval`` on the real data, ``eval_sample``)."""
    args = MODELS[name][which]
    return None if args is None else ["refimpl", "--blas-threads", "1", "eval", "--checkpoint", PREFIX + name,
                                      *args]


def run_eval(argv: list[str], json_path: Path) -> dict:
    """Run an evaluation command in this process (from the repository root, so that ``../shared`` resolves) and
    return its ``--json`` results."""
    from refimpl.cli import main

    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        rc = main([*argv[1:], "--json", str(json_path)])
    finally:
        os.chdir(cwd)
    if rc != 0:
        raise RuntimeError(f"{shlex.join(argv)}: exit {rc}")
    return json.loads(json_path.read_text())


def _strip(run_dir: Path, out_dir: Path) -> tuple[Path, dict]:
    """``<run>/checkpoint.npz`` without its training state as ``<out>/model.npz``; returns the path and the
    source checkpoint's metadata."""
    arrays, meta = load_checkpoint(run_dir / "checkpoint.npz")
    if meta.get("steps_target") is not None and meta.get("step") != meta.get("steps_target"):
        raise SystemExit(f"{run_dir}: the run stopped at step {meta.get('step')} of {meta.get('steps_target')} "
                         "(resume it first)")
    kept, kept_meta = weights_only(arrays, meta)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "model.npz"
    save_checkpoint(path, kept, kept_meta)
    return path, meta


def _training_record(name: str, runs: Path, meta: dict) -> dict:
    """What the card says of the training: command, budget, wall time (the run's .start / .end stamps, written by
    the queue script around the command), training seconds (the checkpoint's ``elapsed_s``)."""
    m = MODELS[name]
    run = runs / m["run"]
    stamps = {k: (runs / f"{m['run']}.{k}").read_text().strip() if (runs / f"{m['run']}.{k}").is_file() else None
              for k in ("start", "end")}
    rec = {"command": shlex.join(train_command(name, Path("runs"))),
           "environment": "OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 MKL_NUM_THREADS=1, niced, in the background on "
                          "one core of the shared 2-core machine while other sessions worked",
           "budget_steps": meta.get("steps_target") or meta.get("step"), "step": meta.get("step"),
           "epoch": meta.get("epoch"), "batch_size": meta.get("batch_size"), "optimiser": meta.get("optim"),
           "training_s": round(float(meta.get("elapsed_s", 0.0)), 1),
           "started_utc": stamps["start"], "ended_utc": stamps["end"]}
    log = run / "loss.csv"
    if log.is_file():
        rows = log.read_text().strip().splitlines()
        rec["final_loss_row"] = dict(zip(rows[0].split(","), rows[-1].split(",")))
    return rec


def _time_graphs(onnx_dir: Path, sizes: dict, repeats: int = 50) -> dict:
    """Median µs per call of every graph in ``onnx_dir`` in onnxruntime (one thread, batch 1, the symbolic sizes
    of ``sizes``, every other 1, random inputs)."""
    import onnxruntime as ort

    out = {}
    for f in sorted(onnx_dir.glob("*.onnx")):
        so = ort.SessionOptions()
        so.intra_op_num_threads = so.inter_op_num_threads = 1
        sess = ort.InferenceSession(str(f), so, providers=["CPUExecutionProvider"])
        rng = np.random.default_rng(0)
        feeds = {}
        for i in sess.get_inputs():
            shape = [d if isinstance(d, int) else int(sizes.get(d, 1)) for d in i.shape]
            dtype = np.float64 if "double" in i.type else (np.int64 if "int64" in i.type else np.float32)
            if dtype is np.int64:   # a count (frames to generate): ``sizes[name]``, else 1
                feeds[i.name] = np.full(shape, int(sizes.get(i.name, 1)), dtype=np.int64)
            else:
                feeds[i.name] = np.asarray(rng.standard_normal(shape) * 0.1, dtype=dtype)
        for _ in range(3):
            sess.run(None, feeds)
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            sess.run(None, feeds)
            times.append(time.perf_counter() - t)
        out[f.name] = {"us_per_call": round(float(np.median(times)) * 1e6, 1),
                       "inputs": {i.name: [d if isinstance(d, int) else f"{d}={int(sizes.get(d, 1))}" for d in i.shape]
                                  for i in sess.get_inputs()}}
    return out


def _parameters(path: Path) -> int:
    arrays, _ = load_checkpoint(path)
    return int(sum(a.size for k, a in arrays.items() if k.startswith("param.")))


def _evaluations(name: str, folder: Path) -> dict:
    """Run the card's evaluation commands on the stripped file; their JSON goes beside the card."""
    out = {}
    for which, file in (("eval", "eval.json"), ("eval_sample", "eval_sample.json")):
        argv = eval_command(name, which)
        if argv is None:
            continue
        _say(f"{name}: {shlex.join(argv)}")
        t = time.perf_counter()
        results = run_eval(argv, folder / file)
        out[which] = {"command": shlex.join(argv) + f" --json {file}", "results_file": file,
                      "wall_s": round(time.perf_counter() - t, 1), "headline": headline(name, results)}
    return out


def _inference(name: str, model_path: Path) -> dict:
    """Export the model to ONNX (today's target) in a scratch folder and time each graph at batch 1."""
    from refimpl.services import export_onnx, load_trained

    model = load_trained(model_path)
    with tempfile.TemporaryDirectory() as tmp:
        with contextlib.redirect_stdout(io.StringIO()):
            export_onnx(model, Path(tmp) / "onnx")
        graphs = _time_graphs(Path(tmp) / "onnx", MODELS[name].get("sizes", {}))
    graph, frames = MODELS[name]["per_frame"]
    per_frame = None if frames is None else round(graphs[graph]["us_per_call"] / frames, 1)
    return {"us_per_frame": per_frame, "per_frame_graph": graph, "frames_per_call": frames,
            "onnxruntime_batch1_one_thread": graphs,
            "how": "python -m experiments.pretrained card: each exported graph (refimpl export, default target) "
                   "timed in onnxruntime, 1 intra-op thread, batch 1, other symbolic sizes 1, median of 50 calls "
                   "after 3 warm-up calls, on the machine and load of `versions`"}


def make_card(name: str, runs: Path) -> dict:
    """Strip the run, evaluate, time, and write ``pretrained/<name>/{model.npz, card.json, card.md, eval*.json}``."""
    m = MODELS[name]
    folder = OUT / name
    path, meta = _strip(runs / m["run"], folder)
    card = {"name": name, "title": m["title"], "system": m["system"], "model": m["model"],
            "representation": json.loads(json.dumps(meta.get("model_config", {}))).get("representation")
            if isinstance(meta.get("model_config"), dict) else None,
            "file": path.name, "sha256": sha256_of(path), "size_bytes": path.stat().st_size,
            "parameters": _parameters(path), "data": m["data"],
            "licence": {"weights": m["weights"], "code": "MIT (LICENSE)"}, "use": m["use"],
            "training": _training_record(name, runs, meta)}
    # the card must exist (with its checksum) before `pretrained:<name>` resolves in the evaluations
    card.update({"evaluation": {}, "inference": {}, "versions": library_versions()})
    atomic_write_text(folder / "card.json", json.dumps(card, indent=1, sort_keys=True) + "\n")
    card["evaluation"] = _evaluations(name, folder)
    card["evaluation"]["tolerance"] = TOLERANCE
    card["inference"] = _inference(name, path)
    card["versions"] = library_versions()
    with contextlib.suppress(OSError):
        card["versions"]["loadavg_1min"] = round(os.getloadavg()[0], 2)
    atomic_write_text(folder / "card.json", json.dumps(card, indent=1, sort_keys=True) + "\n")
    atomic_write_text(folder / "card.md", card_markdown(card))
    return card


#: How a re-evaluation must agree with the card (tests/test_pretrained.py). Evaluation is inference only, in one
#: BLAS thread: on the card's library versions it is deterministic, so equal to the last bit; another NumPy /
#: OpenBLAS build (another kernel) sums the float32 matrix products in another order, which moves each number by
#: rounding only (no training amplifies it), well inside the relative tolerance below.
TOLERANCE = {"same_versions": {"rtol": 0.0, "atol": 0.0}, "other_versions": {"rtol": 1e-4, "atol": 1e-6},
             "versions_compared": ["numpy", "blas", "onnxruntime", "python"]}


def _compact(v, depth: int = 0):
    """The results without long per-frame lists and deep nesting: what a card shows."""
    if isinstance(v, dict):
        return {k: _compact(x, depth + 1) for k, x in v.items()
                if depth < 4 and not (isinstance(x, list) and len(x) > 12)}
    if isinstance(v, list):
        return [_compact(x, depth + 1) for x in v] if len(v) <= 12 else None
    return round(v, 4) if isinstance(v, float) else v


def headline(name: str, results) -> object:
    """The numbers a card shows of an evaluation's JSON (``refimpl eval --json``), per task."""
    task = {"qtg": "transition", "quaternet": "prediction", "quaternet-cnn": "prediction",
            "quaternet-long": "locomotion", "acrnn": "synthesis", "pace": "locomotion"}[MODELS[name]["model"]]
    if task == "transition":
        return {m: {"mean_cm": round(r["mean_cm"], 3),
                    **{k: (None if r["quality"].get(k) is None else round(r["quality"][k], 3))
                       for k in ("join_in_cm", "join_out_cm", "skate_cm_s", "contact_share")},
                    **({"ground_truth": {k: round(v, 3) for k, v in r["quality"]["ground_truth"].items()
                                         if isinstance(v, float)}} if "ground_truth" in r["quality"] else {})}
                for m, r in results.items()}
    if task == "prediction":
        rows = results if isinstance(results, list) else [results]
        return [{"method": r["method"], "horizons_ms": r["horizons_ms"],
                 "average": [round(v, 4) for v in r["average"]]} for r in rows]
    return _compact(results)


def card_markdown(card: dict) -> str:
    """``card.md``: the card for people (every number is the card.json's)."""
    t, e, inf = card["training"], card["evaluation"], card["inference"]
    lines = [f"# {card['name']}: {card['title']}", "", f"*System*: {card['system']}. *Model*: `{card['model']}`"
             + (f", representation `{card['representation']}`" if card.get("representation") else "") + ".", "",
             f"*Use*: {card['use']}", "",
             "| | |", "|---|---|",
             f"| file | `{card['file']}`, {card['size_bytes'] / 1e6:.2f} MB, {card['parameters']:,} parameters |",
             f"| sha256 | `{card['sha256']}` |",
             f"| data | {card['data']['name']} (`{card['data']['folder']}`) |",
             f"| split | {card['data']['split']} |",
             f"| data licence | {card['data']['licence']} |",
             f"| weights licence | {card['licence']['weights']} |",
             f"| training | `{t['command']}` |",
             f"| budget | {t['budget_steps']} steps (epoch {t['epoch']}, batch {t['batch_size']}), "
             f"{t['training_s'] / 60:.1f} min of training, {t['started_utc']} to {t['ended_utc']}; {t['environment']} |",
             f"| library versions | {json.dumps(card['versions'], sort_keys=True)} |", ""]
    for which in ("eval", "eval_sample"):
        if which in e:
            lines += [f"## Evaluation{' on the embedded sample' if which == 'eval_sample' else ''}", "",
                      f"`{e[which]['command']}` ({e[which]['wall_s']} s; all numbers in `{e[which]['results_file']}`):",
                      "", "```json", json.dumps(e[which]["headline"], indent=1), "```", ""]
    if "tolerance" in e:
        lines += ["Re-evaluated by `tests/test_pretrained.py`: " + json.dumps(e["tolerance"]) + ".", ""]
    per = ("" if inf.get("us_per_frame") is None else
           f"**{inf['us_per_frame']} µs per frame** (`{inf['per_frame_graph']}`, {inf['frames_per_call']} frame(s) "
           "per call). ")
    lines += ["## Inference", "", per + inf.get("how", ""), "", "| graph | inputs | µs per call |", "|---|---|---|"]
    lines += [f"| `{g}` | {json.dumps(v['inputs'])} | {v['us_per_call']} |"
              for g, v in inf.get("onnxruntime_batch1_one_thread", {}).items()]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m experiments.pretrained", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    for cmd in ("train", "card"):
        p = sub.add_parser(cmd)
        p.add_argument("names", nargs="+", choices=sorted(MODELS))
        p.add_argument("--runs", type=Path, default=ROOT / "runs", help="folder of the training runs")
        if cmd == "train":
            p.add_argument("--run", action="store_true", help="run the command (else print it)")
    args = ap.parse_args(argv)
    from refimpl.threads import blas_thread_pool

    with blas_thread_pool(1):   # one BLAS thread, as the cards' commands (--blas-threads 1)
        return _run(args)


def _run(args) -> int:
    for name in args.names:
        if args.command == "train":
            cmd = train_command(name, args.runs)
            print(shlex.join(cmd))
            if args.run:
                subprocess.run(cmd, check=True, cwd=ROOT)
        else:
            card = make_card(name, args.runs)
            print(f"{name}: pretrained/{name}/card.json ({card['size_bytes'] / 1e6:.2f} MB, sha256 "
                  f"{card['sha256'][:12]}…)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
