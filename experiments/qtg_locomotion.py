"""QTG on the Bandai Namco locomotion set: held-out results per style and transition kind, and the curve of error
against training time (issue 26 items 1-2, spec/qtg.md §11.3).

Two commands::

    # QTG, inertialisation and interpolation on the held-out takes: mean and per frame, overall, per style,
    # per transition kind (from each window's root motion) and per take content; JSON + a markdown table
    python -m experiments.qtg_locomotion eval --checkpoint runs/qtg_bn/checkpoint.npz \
        --data ../shared/data/bandai_namco_locomotion --out experiments/results/qtg_locomotion/results.json \
        --md experiments/results/qtg_locomotion/results.md

    # every snapshot of a run (runs/qtg_bn/snapshots/*.npz): held-out error against steps and training time
    python -m experiments.qtg_locomotion curve --run runs/qtg_bn --data ../shared/data/bandai_namco_locomotion \
        --out experiments/results/qtg_locomotion/curve.json

The metric is the paper's (spec/qtg.md §9): Euclidean joint-position error per joint per transition frame, cm,
over the 21 joints of the Bandai Namco rig. Windows: ``2 + 30 + 2`` poses every ``--stride`` frames of the held-out
takes (ids ending in 1), :mod:`refimpl.protocols.transition_locomotion`.

Shape legend: N windows, T transition frames.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
import time
from pathlib import Path

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.protocols.transition_locomotion import (grouped_errors, heldout_dataset, take_facts, window_kinds,
                                                     window_styles)
from refimpl.services import load_trained, network_methods
from refimpl.tasks import transition

FRAMES = (1, 2, 5, 10, 15, 20, 25, 29, 30)


def _say(*a):
    print(*a, flush=True)


def _groups(test_ds) -> dict:
    contents = np.array([take_facts(s.path).content for s in test_ds.sources])[test_ds.source_index]
    return {"style": window_styles(test_ds), "kind": window_kinds(test_ds.poses), "content": contents}


def _elapsed_at(run: Path, step: int) -> float | None:
    """Training seconds at ``step`` from the run's loss.csv (``elapsed_s`` column)."""
    log = run / "loss.csv"
    if not log.is_file():
        return None
    with log.open() as f:
        for row in csv.DictReader(f):
            if int(row["step"]) == step:
                return float(row["elapsed_s"])
    return None


def _ratio(results, name, base):
    return results[base]["mean_cm"] / results[name]["mean_cm"]


def markdown(results: dict, meta: dict) -> str:
    """The results as markdown tables: overall, per style, per kind, per content, per frame."""
    names = list(results)
    lines = [f"# QTG on held-out Bandai Namco locomotion takes", "",
             f"Checkpoint `{meta['checkpoint']}` (step {meta['step']}, {meta['training_s'] or 0:.0f} s of training); "
             f"{meta['num_windows']} held-out windows (stride {meta['stride']}) of {meta['num_takes']} takes. "
             "Error: mean Euclidean joint-position error per joint per transition frame (cm), 21 joints.", "",
             f"Command: `{meta['command']}`", ""]
    first = names[0]
    lines += ["| method | mean cm | baseline ÷ QTG | " + " | ".join(f"f{f}" for f in FRAMES) + " |",
              "|---|---|---|" + "---|" * len(FRAMES)]
    for n in names:
        pf = results[n]["per_frame_cm"]
        below = "" if n == first else f"{_ratio(results, first, n):.2f}"
        lines.append(f"| {n} | {results[n]['mean_cm']:.2f} | {below} | "
                     + " | ".join(f"{pf[f - 1]:.2f}" for f in FRAMES) + " |")
    for g in ("style", "kind", "content"):
        labels = list(results[first][f"by_{g}"])
        lines += ["", f"## by {g} (mean cm; windows)", "",
                  "| method | " + " | ".join(f"{lab} ({results[first][f'by_{g}'][lab]['num_windows']})"
                                             for lab in labels) + " |",
                  "|---|" + "---|" * len(labels)]
        for n in names:
            lines.append(f"| {n} | " + " | ".join(f"{results[n][f'by_{g}'][lab]['mean_cm']:.2f}" for lab in labels)
                         + " |")
    return "\n".join(lines) + "\n"


def cmd_eval(args) -> int:
    t0 = time.perf_counter()
    model = load_trained(args.checkpoint)
    test_ds = heldout_windows(args, model)
    _say(f"{test_ds.num_windows} held-out windows of {len(test_ds.sources)} takes in {time.perf_counter() - t0:.1f} s")
    methods = transition.methods(network_methods(model), fps=test_ds.fps)
    results = grouped_errors(test_ds, methods, _groups(test_ds))
    step = int(model.meta.get("step", 0))
    meta = {"checkpoint": str(args.checkpoint), "step": step,
            "training_s": _elapsed_at(Path(args.checkpoint).parent, step), "data": str(args.data),
            "stride": args.stride, "num_windows": test_ds.num_windows, "num_takes": len(test_ds.sources),
            "held_out_takes": [Path(s.path).name for s in test_ds.sources],
            "command": "python -m experiments.qtg_locomotion " + " ".join(sys.argv[1:])}
    for n, r in results.items():
        _say(f"{n:16s} mean {r['mean_cm']:6.2f} cm  f1 {r['per_frame_cm'][0]:6.2f}  f30 {r['per_frame_cm'][-1]:6.2f}  "
             + "  ".join(f"{k} {v['mean_cm']:.2f}" for k, v in r["by_style"].items()))
    atomic_write_text(Path(args.out), json.dumps({"meta": meta, "results": results}, indent=2) + "\n",
                      make_parents=True)
    _say(f"wrote {args.out}")
    if args.md:
        atomic_write_text(Path(args.md), markdown(results, meta), make_parents=True)
        _say(f"wrote {args.md}")
    return 0


def cmd_curve(args) -> int:
    run = Path(args.run)
    snaps = sorted((run / "snapshots").glob("*.npz")) + ([Path(c) for c in args.checkpoint] if args.checkpoint else [])
    if not snaps:
        raise SystemExit(f"{run}/snapshots: no checkpoint")
    done = {}
    if Path(args.out).is_file():  # points of an earlier call on the same data are kept, not measured again
        prev = json.loads(Path(args.out).read_text())
        if prev.get("data") == str(args.data) and prev.get("stride") == args.stride:
            done = {p["checkpoint"]: p for p in prev["points"]}
    models = [load_trained(s) for s in snaps]
    test_ds = heldout_windows(args, models[0])
    groups = _groups(test_ds)
    base = grouped_errors(test_ds, transition.methods({}, fps=test_ds.fps), groups)
    points = []
    seen = set()
    for path, model in zip(snaps, models):
        step = int(model.meta.get("step", 0))
        if step in seen:
            continue
        seen.add(step)
        if path.name in done and done[path.name]["step"] == step:
            points.append(done[path.name])
            continue
        r = grouped_errors(test_ds, network_methods(model), groups)[model.spec.name]
        points.append({"checkpoint": path.name, "step": step, "training_s": _elapsed_at(run, step),
                       "mean_cm": r["mean_cm"], "frame_1_cm": r["per_frame_cm"][0],
                       "frame_T_cm": r["per_frame_cm"][-1],
                       "by_style": {k: v["mean_cm"] for k, v in r["by_style"].items()},
                       "by_kind": {k: v["mean_cm"] for k, v in r["by_kind"].items()}})
        _say(f"step {step:7d} ({points[-1]['training_s'] or 0:7.0f} s): mean {r['mean_cm']:.2f} cm, "
             f"f1 {r['per_frame_cm'][0]:.2f}, f30 {r['per_frame_cm'][-1]:.2f}")
    points.sort(key=lambda p: p["step"])
    out = {"run": str(run), "data": str(args.data), "stride": args.stride, "num_windows": test_ds.num_windows,
           "baselines": {n: {"mean_cm": v["mean_cm"], "frame_1_cm": v["per_frame_cm"][0],
                             "frame_T_cm": v["per_frame_cm"][-1]} for n, v in base.items()},
           "points": points,
           "command": "python -m experiments.qtg_locomotion " + " ".join(sys.argv[1:])}
    atomic_write_text(Path(args.out), json.dumps(out, indent=2) + "\n", make_parents=True)
    _say(f"wrote {args.out}")
    if args.plot:
        _plot(out, args.plot)
        _say(f"wrote {args.plot}")
    return 0


def _plot(curve: dict, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    pts = [p for p in curve["points"] if p["training_s"] is not None]
    x = [p["training_s"] / 60 for p in pts]
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(x, [p["mean_cm"] for p in pts], "o-", label="QTG mean")
    ax.plot(x, [p["frame_1_cm"] for p in pts], ".--", label="QTG frame 1")
    ax.plot(x, [p["frame_T_cm"] for p in pts], ".--", label="QTG frame 30")
    for n, v in curve["baselines"].items():
        ax.axhline(v["mean_cm"], ls=":", color="gray")
        ax.text(x[0] if x else 0, v["mean_cm"], f" {n} {v['mean_cm']:.1f}", va="bottom", fontsize=8)
    best = min(v["mean_cm"] for v in curve["baselines"].values())
    ax.axhline(best / 3, ls="-.", color="red", lw=0.8)
    ax.text(x[0] if x else 0, best / 3, f" 3x below the best baseline ({best / 3:.1f})", va="bottom", fontsize=8)
    ax.set_xlabel("training time (min, one core)")
    ax.set_ylabel("held-out error (cm per joint)")
    ax.set_yscale("log")
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def heldout_windows(args, model):
    """The held-out windows of ``--data`` every ``--stride`` frames, with the model's root statistics and T."""
    f = model.fields
    return heldout_dataset(args.data, f["root_mean"], f["root_std"], f["transition_length"], args.stride)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    e = sub.add_parser("eval")
    e.add_argument("--checkpoint", required=True)
    e.add_argument("--data", default="../shared/data/bandai_namco_locomotion")
    e.add_argument("--stride", type=int, default=2)
    e.add_argument("--out", required=True)
    e.add_argument("--md", default=None)
    e.set_defaults(func=cmd_eval)
    c = sub.add_parser("curve")
    c.add_argument("--run", required=True)
    c.add_argument("--checkpoint", nargs="*", default=None, help="further checkpoints (e.g. the run's last)")
    c.add_argument("--data", default="../shared/data/bandai_namco_locomotion")
    c.add_argument("--stride", type=int, default=4)
    c.add_argument("--out", required=True)
    c.add_argument("--plot", default=None)
    c.set_defaults(func=cmd_curve)
    args = p.parse_args(argv)
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
