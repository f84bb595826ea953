"""``refimpl demo``: the whole tour on the embedded CMU sample, in a few minutes on 2 cores (spec/cli.md §demo).

Steps (each prints what it did and where the files are):

1. data      — 22-joint transition windows (2 past + T = 30 + 2 target poses at 30 fps) from the sample in
               ``refimpl/data/sample``, split by file / by time into training and held-out windows;
2. train     — QTG with the paper's loss and optimiser (MAE, Adam β = (0.5, 0.9)) but a smaller network
               and a larger learning rate, so that it trains in minutes (:data:`DEMO_CONFIG`);
3. evaluate  — QTG (and QTG with ``--join inertialize``, spec/qtg.md §7.4, and ``inertialize+footlock``, §7.5) vs
               inertialisation vs interpolation on the held-out windows, the paper's metric (mean joint-position error per joint per frame, cm) as a
               table and a per-frame curve, and the animator's measures (joins, foot skating, first and last
               frame; spec/qtg.md §9.1);
4. export    — ONNX ``init``/``step``/``rollout`` models (``deploy``; skipped with a message without it);
5. verify    — onnxruntime against NumPy on held-out context poses (max abs difference);
6. generate  — a held-out transition (with its ground truth) and a walk-to-run transition between two
               held-out clips, with NumPy and with onnxruntime, with and without the join option, written as BVH;
7. render    — PNG strips (ground truth vs QTG, without and with the join option: the frames on both sides of
               each join, left / right limbs in two shades, foot tracks, a floor fixed in the world), GIFs, the
               loss curve and the per-frame error curve
               (matplotlib; skipped with a message without it).

Deterministic for a given ``seed`` (one BLAS thread; the trainer's Generator drives initialisation and
batches). ``quick=True`` uses a tiny network and a few dozen steps: a smoke test of every step (< 60 s), not
a trained model.

Shape legend: N windows, T transition frames, J joints, P pose size.
"""
from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from refimpl.protocols.transition import SAMPLE_DIR
from refimpl.protocols.transition_join import with_join
from refimpl.registry import MODELS
from refimpl.threads import blas_thread_pool
from refimpl.services import (evaluate_model, export_onnx, load_trained, network_methods, train_model,
                              verify_onnx)
from refimpl.tasks.transition import print_results, write_results
from refimpl.tasks.transition_generate import make_transition, render_transition, with_end_sites

__all__ = ["run_demo", "DemoResult", "DEMO_CONFIG", "DEMO_STEPS", "DEMO_BATCH", "DEMO_LR", "QUICK_CONFIG",
           "QUICK_STEPS"]

#: Network of the full demo (QTGConfig fields; the paper-sized default is 256/128/256 with 0.64 M parameters).
DEMO_CONFIG = dict(encoder_sizes=(128, 64), gru_hidden=128, decoder_sizes=(128,))
#: Training of the full demo: steps, batch, learning rate (the paper: 1000 epochs at 1e-4).
DEMO_STEPS = 3000
DEMO_BATCH = 32
DEMO_LR = 1e-3
#: The quick smoke test.
QUICK_CONFIG = dict(encoder_sizes=(32, 16), gru_hidden=32, decoder_sizes=(32,))
QUICK_STEPS = 40

_T = 30


@dataclasses.dataclass
class DemoResult:
    """What :func:`run_demo` produced.

    Attributes
    ----------
    out_dir : Path
    files : dict name -> Path
        Every file written (checkpoint, logs, tables, ONNX models, BVH files, pictures).
    results : dict
        :func:`refimpl.protocols.transition_metrics.evaluate_methods` output on the held-out windows.
    verify : dict or None
        :func:`refimpl.services.verify_onnx` output (None when ONNX was skipped).
    skipped : list of str
        Steps skipped, with the reason.
    elapsed_s : float
    """

    out_dir: Path
    files: dict
    results: dict
    verify: dict | None
    skipped: list
    elapsed_s: float


def _missing(module: str) -> str | None:
    """The reason ``module`` cannot be imported, or None when it can."""
    try:
        __import__(module)
    except ImportError as exc:
        return str(exc)
    return None


def _refuse_to_replace_a_fuller_run(out: Path, n_steps: int) -> None:
    """A demo of fewer steps (``--quick``) does not silently replace the results of a longer one in the same
    folder (as ``refimpl train`` refuses to replace a checkpoint): ``UsageError`` unless ``overwrite``."""
    from refimpl.checkpoint import load_checkpoint
    from refimpl.errors import UsageError

    ckpt = out / "train" / "checkpoint.npz"
    if not ckpt.is_file():
        return
    try:
        _, meta = load_checkpoint(ckpt)
        done = int(meta.get("steps_target") or 0)
    except (OSError, ValueError, TypeError):  # a damaged checkpoint is not results worth keeping
        return
    if done > n_steps:
        raise UsageError(f"{out} holds the results of a {done}-step demo; this {n_steps}-step run would replace "
                         "them: pass --out another folder, or --overwrite")


def run_demo(out_dir="demo_out", *, seed: int = 0, quick: bool = False, steps: int | None = None,
             onnx: bool = True, render: bool = True, threads: int | str = 1, overwrite: bool = False,
             say: Callable[[str], None] | None = None, on_step: Callable[..., None] | None = None) -> DemoResult:
    """Run the demo into ``out_dir`` (see the module docstring) and return what it wrote.

    Parameters
    ----------
    out_dir : str or Path
        Output folder (created; files of an earlier run are replaced, the training starts again; those of a
        longer run only with ``overwrite``).
    seed : int
        Seed of the training run.
    quick : bool
        Tiny network, :data:`QUICK_STEPS` steps.
    steps : int, optional
        Override the number of training steps.
    onnx, render : bool
        Do the ONNX steps (export, verify, ONNX generation) / the pictures, when their dependencies are installed.
    threads : int or "auto"
        BLAS threads (default 1; "auto": :class:`refimpl.threads.AutoThreads`; 0 leaves the pool as it is, which
        is what ``refimpl demo`` passes: its ``--blas-threads`` already set it).
    overwrite : bool
        Replace the results of a longer demo in ``out_dir`` (otherwise ``UsageError``).
    say : callable, optional
        Receives each report line (default: print to stdout).
    on_step : callable, optional
        The training loop's per-step callback (``refimpl demo`` passes its :meth:`~refimpl.threads.AutoThreads.poll`).
    """
    say = say or (lambda line: print(line, flush=True))
    if not overwrite:
        _refuse_to_replace_a_fuller_run(Path(out_dir), steps if steps is not None else
                                        (QUICK_STEPS if quick else DEMO_STEPS))
    with blas_thread_pool(threads) as auto:
        return _run(Path(out_dir), seed, quick, steps, onnx, render, say, on_step or (auto and auto.poll))


@dataclasses.dataclass
class _Tour:
    """What the demo's steps share: the folder, the switches, the report and what was written or skipped."""

    out: Path
    seed: int
    quick: bool
    n_steps: int
    onnx: bool
    render: bool
    say: Callable[[str], None]
    on_step: Callable[..., None] | None
    files: dict = dataclasses.field(default_factory=dict)
    skipped: list = dataclasses.field(default_factory=list)


def _run(out: Path, seed, quick, steps, onnx, render, say, on_step) -> DemoResult:
    """The seven steps of the tour, in order (module docstring)."""
    t_start = time.perf_counter()
    out.mkdir(parents=True, exist_ok=True)
    tour = _Tour(out, seed, quick, steps if steps is not None else (QUICK_STEPS if quick else DEMO_STEPS), onnx,
                 render, say, on_step)
    _check_extras(tour)
    train_src, test_src, train_ds, test_ds = _step_data(tour)
    model = _step_train(tour, train_ds, test_ds)
    results, verdict = _step_evaluate(tour, model, test_ds)
    check = _step_export_verify(tour, model, test_ds)
    transitions, crosses = _step_generate(tour, model, test_src)
    _step_render(tour, transitions, crosses, results, test_ds)
    elapsed = time.perf_counter() - t_start
    _summary(tour, verdict, elapsed)
    return DemoResult(out_dir=out, files=tour.files, results=results, verify=check, skipped=tour.skipped,
                      elapsed_s=elapsed)


def _check_extras(tour: _Tour) -> None:
    """Switch off the ONNX steps and the pictures when their optional dependencies are missing (said at the end)."""
    if tour.onnx and (why := _missing("deploy.models.qtg_io") or _missing("onnxruntime")):
        tour.skipped.append(f"ONNX export / verification / generation: {why} (pip install 'refimpl[deploy]')")
        tour.onnx = False
    if tour.render and (why := _missing("matplotlib")):
        tour.skipped.append(f"pictures: {why} (pip install 'refimpl[render]')")
        tour.render = False


def _step_data(tour: _Tour):
    """1. The embedded CMU sample: ``(train sources, test sources, train windows, held-out windows)``."""
    from refimpl.protocols.transition import build_transition_datasets, sample_sources

    t0 = time.perf_counter()
    tour.say(f"[1/7] data: the embedded CMU sample ({SAMPLE_DIR})")
    train_src, test_src = sample_sources(SAMPLE_DIR)
    train_ds, test_ds = build_transition_datasets(train_src, test_src, T=_T, stride=4,
                                                  test_stride=16 if tour.quick else 4)
    tour.say(f"      {train_ds.num_windows} training windows from {len(train_src)} sources, {test_ds.num_windows} "
             f"held-out windows from {len(test_src)} (split by file, and by time inside 01_01 and the salsa takes); "
             f"2 past + {_T} + 2 target poses at 30 fps, 22 joints, cm ({time.perf_counter() - t0:.1f} s)")
    return train_src, test_src, train_ds, test_ds


def _step_train(tour: _Tour, train_ds, test_ds):
    """2. Train QTG into ``out/train`` (the files of an earlier run removed); the loaded checkpoint."""
    from refimpl.models.qtg import count_parameters

    spec = MODELS["qtg"]
    sizes = QUICK_CONFIG if tour.quick else DEMO_CONFIG
    train_dir = tour.out / "train"
    for stale in ("checkpoint.npz", "loss.csv", "loss_val.csv"):
        if (train_dir / stale).is_file():
            (train_dir / stale).unlink()
    overrides = [f"{k}={','.join(map(str, v)) if isinstance(v, tuple) else v}" for k, v in sizes.items()]
    config = spec.make_config(train_ds, overrides)
    n_steps = tour.n_steps
    tour.say(f"[2/7] train: QTG {sizes} ({count_parameters(config):,} parameters), {n_steps} steps of batch "
             f"{DEMO_BATCH}, MAE loss, Adam lr {DEMO_LR:g} betas (0.5, 0.9), seed {tour.seed}; progress on stderr")
    result = train_model(spec, config, train_ds, test_ds, train_dir, steps=n_steps, batch_size=DEMO_BATCH,
                         lr=DEMO_LR, seed=tour.seed, checkpoint_every=max(n_steps, 1),
                         validate_every=max(1, n_steps // 10), progress_every=max(1, n_steps // 20),
                         progress=lambda line: print("      " + line, file=sys.stderr, flush=True),
                         on_step=tour.on_step)
    files = tour.files
    files.update(checkpoint=train_dir / "checkpoint.npz", loss_log=train_dir / "loss.csv",
                 validation_log=train_dir / "loss_val.csv")
    losses = result.losses
    tour.say(f"      loss {np.mean(losses[:10]):.4f} -> {np.mean(losses[-10:]):.4f} in {result.elapsed_s:.1f} s "
             f"({n_steps / max(result.elapsed_s, 1e-9):.1f} steps/s); checkpoint {files['checkpoint']}")
    return load_trained(files["checkpoint"])


def _step_evaluate(tour: _Tour, model, test_ds):
    """3. QTG (with the join option and foot locking, spec/qtg.md 7.4, 7.5) against the baselines on the held-out
    windows; ``(results, verdict line)``."""
    t0 = time.perf_counter()
    say, files = tour.say, tour.files
    say("[3/7] evaluate: QTG vs inertialisation vs interpolation on the held-out windows")
    results = evaluate_model(model, test_ds, join="inertialize+footlock")
    print_results(results, test_ds, model, curve=False)
    files["eval_json"] = tour.out / "eval.json"
    files["eval_curve_csv"] = tour.out / "eval_per_frame.csv"
    write_results(results, 1.0 / test_ds.fps, json_path=files["eval_json"], csv_path=files["eval_curve_csv"])
    q = results["qtg"]["mean_cm"]
    best = min((k for k in results if not k.startswith("qtg")), key=lambda k: results[k]["mean_cm"])
    b = results[best]["mean_cm"]
    verdict = (f"QTG {q:.2f} cm vs best baseline ({best}) {b:.2f} cm: "
               + (f"{100 * (1 - q / b):.0f} % lower" if q < b else f"NOT better ({100 * (q / b - 1):.0f} % higher)"))
    say(f"      {verdict}" + ("  [quick mode: a smoke test, not a trained model]" if tour.quick else ""))
    qa, qj, gt = results["qtg"]["quality"], results["qtg+join"]["quality"], results["qtg"]["quality"]["ground_truth"]
    qf = results["qtg+join+footlock"]["quality"]
    say(f"      joins in/out: QTG {qa['join_in_cm']:.1f}/{qa['join_out_cm']:.1f} cm, with --join inertialize "
        f"{qj['join_in_cm']:.1f}/{qj['join_out_cm']:.1f} cm, ground truth {gt['join_in_cm']:.1f}/"
        f"{gt['join_out_cm']:.1f} cm; foot skating {qa['skate_cm_s']:.0f} / {qj['skate_cm_s']:.0f} / "
        f"{qf['skate_cm_s']:.0f} with inertialize+footlock / {gt['skate_cm_s']:.0f} cm/s")
    say(f"      tables {files['eval_json']}, {files['eval_curve_csv']} ({time.perf_counter() - t0:.1f} s)")
    return results, verdict


def _step_export_verify(tour: _Tour, model, test_ds):
    """4. Export to ``out/onnx``, 5. onnxruntime against NumPy on held-out transitions; the check (None when
    skipped)."""
    if not tour.onnx:
        tour.say("[4/7] export: skipped" + "".join(f" ({r})" for r in tour.skipped if r.startswith("ONNX")))
        tour.say("[5/7] verify: skipped")
        return None
    t0 = time.perf_counter()
    onnx_dir = tour.out / "onnx"
    written = export_onnx(model, onnx_dir)
    for role, path in written.items():
        tour.files[f"onnx_{role}"] = Path(path)
    tour.say("[4/7] export: " + ", ".join(f"{p.name} ({p.stat().st_size / 1024:.0f} KiB)"
                                          for p in map(Path, written.values()))
             + f" in {onnx_dir} ({time.perf_counter() - t0:.1f} s)")
    past, _, target = test_ds.context()
    check = verify_onnx(model, onnx_dir, past[:64], target[:64])
    tour.say(f"[5/7] verify: onnxruntime vs NumPy on {min(64, len(past))} held-out transitions: max |diff| "
             f"rollout model {check.get('rollout', float('nan')):.2e}, init+step loop "
             f"{check.get('step_loop', float('nan')):.2e} -> {'OK' if check['ok'] else 'MISMATCH'} "
             "(tolerance rtol 1e-3, atol 2e-3 x pose std: the recipe's VERIFY_TOL)")
    if not check["ok"]:
        raise RuntimeError("onnxruntime and NumPy disagree beyond the rollout tolerance")
    return check


def _step_generate(tour: _Tour, model, test_src):
    """6. Transitions as BVH: a held-out window by every method, then walk -> run across two held-out clips;
    ``(transitions, crosses)``."""
    from refimpl.bvh_write import write_bvh
    from refimpl.protocols.transition import load_source

    out, files, say = tour.out, tour.files, tour.say
    say("[6/7] generate: transitions written as BVH (22 joints, centimetres, 30 fps)")
    methods = network_methods(model, onnx_dir=out / "onnx" if tour.onnx else None)  # qtg (NumPy), qtg_onnx
    methods["qtg+join"] = with_join(methods["qtg"], "inertialize", dt=1.0 / 30)
    walk = next(s for s in test_src if s.label == "walk")
    run = next(s for s in test_src if s.label == "run")
    skel, walk_clips = load_source(walk)
    _, run_clips = load_source(run)
    walk_clip = walk_clips[0]
    s = len(walk_clip[0]) // 2 - _T // 2
    transitions = {}
    for name, f in methods.items():
        tr = make_transition(f, skel, walk_clip, s, walk_clip, s + _T + 1, _T, frame_time=1 / 30, context=10,
                             same_clip=True, method_name=name, name=f"heldout_{name.replace('+', '_')}")
        transitions[name] = tr
        key = name.replace("+", "_")
        files[f"heldout_{key}_bvh"] = out / f"heldout_{key}.bvh"
        write_bvh(files[f"heldout_{key}_bvh"], with_end_sites(tr.motion))
    files["heldout_truth_bvh"] = out / "heldout_truth.bvh"
    write_bvh(files["heldout_truth_bvh"], with_end_sites(transitions["qtg"].truth))
    say(f"      held-out window of {Path(walk.path).name} (frames {s - 1}..{s + _T + 2}): mean joint error "
        + ", ".join(f"{k} {tr.error_cm():.2f} cm" for k, tr in transitions.items())
        + f"; {files['heldout_qtg_bvh'].name}, {files['heldout_truth_bvh'].name}"
        + (f", {files['heldout_qtg_onnx_bvh'].name}" if tour.onnx else ""))
    if tour.onnx:
        d = np.abs(transitions["qtg"].motion.positions() - transitions["qtg_onnx"].motion.positions()).max()
        say(f"      NumPy vs onnxruntime transition: max joint-position difference {d:.2e} cm")
    crosses = {}
    for name, key in (("qtg", "walk_to_run"), ("qtg+join", "walk_to_run_join")):
        crosses[name] = make_transition(methods[name], skel, walk_clip, s, run_clips[0], len(run_clips[0][0]) // 2,
                                        _T, frame_time=1 / 30, context=15, align="continue", method_name=name,
                                        name=key)
        files[f"{key}_bvh"] = out / f"{key}.bvh"
        write_bvh(files[f"{key}_bvh"], with_end_sites(crosses[name].motion))
    say(f"      walk -> run between two held-out clips ({Path(walk.path).name} -> {Path(run.path).name}, target "
        f"placed to continue the walk): {files['walk_to_run_bvh']}, {files['walk_to_run_join_bvh'].name} (--join "
        "inertialize)")
    return transitions, crosses


def _step_render(tour: _Tour, transitions, crosses, results, test_ds) -> None:
    """7. Strips and GIFs of the transitions, the loss curve and the per-frame error curves."""
    if not tour.render:
        tour.say("[7/7] render: skipped" + "".join(f" ({r})" for r in tour.skipped if r.startswith("pictures")))
        return
    from refimpl.render import render_error_curves, render_loss_curve

    t0 = time.perf_counter()
    out, files, say = tour.out, tour.files, tour.say
    files["strip_png"] = out / "heldout_strip.png"
    files["strip_join_png"] = out / "heldout_join_strip.png"
    files["heldout_gif"] = out / "heldout.gif"
    files["walk_to_run_gif"] = out / "walk_to_run.gif"
    files["walk_to_run_png"] = out / "walk_to_run.png"
    files["walk_to_run_join_png"] = out / "walk_to_run_join.png"
    files["loss_png"] = out / "loss.png"
    files["error_curve_png"] = out / "error_curve.png"
    say("[7/7] render:")
    render_transition(transitions["qtg"], png=files["strip_png"], gif=files["heldout_gif"],
                      title="held-out transition: ground truth (top/left) vs QTG; green = context")
    render_transition(transitions["qtg+join"], png=files["strip_join_png"],
                      title="the same with --join inertialize; green = context")
    render_transition(crosses["qtg"], png=files["walk_to_run_png"], gif=files["walk_to_run_gif"],
                      title="QTG transition walk -> run; green = context")
    render_transition(crosses["qtg+join"], png=files["walk_to_run_join_png"],
                      title="QTG walk -> run with --join inertialize; green = context")
    render_loss_curve(files["loss_png"], _merged_log(out / "train"), title="QTG training loss (MAE, normalised)")
    say(f"wrote {files['loss_png']}")
    render_error_curves(files["error_curve_png"], {k: v["per_frame_cm"] for k, v in results.items()},
                        frame_time=1.0 / test_ds.fps,
                        title=f"held-out error per transition frame ({test_ds.num_windows} windows)")
    say(f"wrote {files['error_curve_png']}  ({time.perf_counter() - t0:.1f} s)")


def _summary(tour: _Tour, verdict: str, elapsed: float) -> None:
    """The closing lines: the verdict, the files, what was skipped, what to try next."""
    say, files = tour.say, tour.files
    say("")
    say(f"done in {elapsed:.0f} s. {verdict}. Files in {tour.out}/:")
    for key, path in files.items():
        if Path(path).is_file():
            say(f"  {key:22s} {path}")
    for reason in tour.skipped:
        say(f"  skipped: {reason}")
    say("next: `refimpl info " + str(files["checkpoint"]) + "`, `refimpl eval --checkpoint "
        + str(files["checkpoint"]) + "`, `refimpl render " + str(files["heldout_qtg_bvh"]) + " --compare "
        + str(files["heldout_truth_bvh"]) + " --out x.gif`")


def _merged_log(train_dir: Path) -> dict:
    """Training loss (every step) and held-out MAE (every ``validate_every`` steps) on one step axis."""
    from refimpl.render import read_loss_log

    log = read_loss_log(train_dir / "loss.csv")
    data = {"step": log["step"], "train loss": log["loss"]}
    val_path = train_dir / "loss_val.csv"
    if val_path.is_file():
        val = read_loss_log(val_path)
        held = np.full(len(log["step"]), np.nan)
        pos = np.searchsorted(log["step"], val["step"])
        ok = pos < len(held)
        held[pos[ok]] = val["val_mae"][ok]
        data["held-out loss"] = held
    return data
