"""Time the README's commands (its "how long" column), writing ``benchmarks/results/readme_timings.json``.

Runs each paper's commands as a newcomer would (``python -m refimpl ...`` in a subprocess, the default
``--blas-threads``), into a temporary folder: the full ``refimpl demo``; and for each paper a short training
run whose per-step time (median of the trainer's ``loss.csv`` ``elapsed_s`` differences) is projected to the
README's budget, then its ``eval`` / ``generate`` / ``export`` on that checkpoint. For the locomotion set the
pose network's training command runs twice on the same files, so the JSON holds the time to the first step of a
cold (files read) and a warm (data cache, spec/data.md §7) start, and so does the pace network's (its
first run also prepares and caches the pace data)
(``first_step_done_s``: from the launch until the first step's row is in ``loss.csv``). The demo's ``eval.json`` is copied to
``benchmarks/results/demo_eval.json`` (the README's QTG numbers).

The machine's load average is recorded before and after every command; on a shared machine the times are
what a newcomer would see there, not a property of the code. Needs ``../shared/data`` for all but the demo.

    python benchmarks/readme_timings.py [--only demo,quaternet,acrnn,locomotion] [--cache DIR]
"""
from __future__ import annotations

import argparse
import csv
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.versions import with_versions  # noqa: E402

from refimpl.atomic import atomic_write_text  # noqa: E402

SHARED = ROOT.parent / "shared" / "data"
SAMPLE = ROOT / "refimpl" / "data" / "sample"
GROUPS = ("demo", "quaternet", "acrnn", "locomotion")


def _run(argv: list, timeout: float, env: dict, first_row: Path | None = None) -> dict:
    """Run ``refimpl argv``; with ``first_row`` (a training run's ``loss.csv``) also the time from the launch
    until the first step's row is written (polled every 0.05 s)."""
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    first = None
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        p = subprocess.Popen([sys.executable, "-m", "refimpl", *argv], cwd=ROOT, env=env, stdout=out, stderr=err,
                             text=True)
        while p.poll() is None:
            if first is None and first_row is not None and first_row.is_file() and \
                    len(first_row.read_text().splitlines()) >= 2:
                first = time.perf_counter() - t0
            if time.perf_counter() - t0 > timeout:
                p.kill()
            time.sleep(0.05)
        out.seek(0)
        err.seek(0)
        stdout, stderr = out.read(), err.read()
    wall = time.perf_counter() - t0
    res = dict(command="refimpl " + " ".join(argv), rc=p.returncode, wall_s=round(wall, 2),
               load_before=round(load0, 2), load_after=round(os.getloadavg()[0], 2))
    if first is not None:
        res["first_step_done_s"] = round(first, 2)
    if p.returncode != 0:
        res["stderr"] = stderr.strip()[-400:]
    m = re.search(r"(\d+) steps per epoch", stdout)
    if m:
        res["steps_per_epoch"] = int(m.group(1))
    res["time_utc"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print(f"  {res['wall_s']:8.1f} s  rc {p.returncode}  load {load0:.1f}  {res['command'][:110]}", flush=True)
    return res


def _train(argv: list, out: Path, budget_steps: int, timeout: float, env: dict, budget_epochs: int = 0) -> dict:
    """A short training run; its median step time projected to the README's ``budget_steps`` (or
    ``budget_epochs`` × the steps per epoch the trainer printed)."""
    res = _run(argv + ["--out", str(out)], timeout, env, first_row=out / "loss.csv")
    if budget_epochs and "steps_per_epoch" in res:
        budget_steps = budget_epochs * res["steps_per_epoch"]
    log = out / "loss.csv"
    if res["rc"] == 0 and log.is_file():
        with open(log, newline="") as f:
            el = [float(r["elapsed_s"]) for r in csv.DictReader(f)]
        dts = [b - a for a, b in zip(el[1:], el[2:])] or [el[0]]
        step = statistics.median(dts)
        res.update(steps_run=len(el), step_s=round(step, 4), first_step_elapsed_s=el[0],
                   startup_s=round(res["wall_s"] - el[-1], 2), budget_steps=budget_steps,
                   projected_budget_min=round((res["wall_s"] - el[-1] + budget_steps * step) / 60.0, 1))
    return res


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=",".join(GROUPS))
    ap.add_argument("--steps", type=int, default=12, help="training steps of each short run (default 12)")
    ap.add_argument("--cache", default=None, help="REFIMPL_CACHE for the runs (default: a fresh temporary folder, "
                                                  "so the first locomotion command is a cold start)")
    ap.add_argument("--timeout", type=float, default=1800.0)
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "readme_timings.json"))
    a = ap.parse_args(argv)
    only = [g for g in a.only.split(",") if g]
    tmp = Path(tempfile.mkdtemp(prefix="readme_timings_"))
    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env["REFIMPL_CACHE"] = a.cache or str(tmp / "cache")
    S = str(a.steps)
    out: dict = dict(cpu_count=os.cpu_count(), short_run_steps=a.steps, results={})
    if Path(a.out).is_file():  # a run of some groups keeps the other groups' recorded results
        with open(a.out) as f:
            out["results"] = json.load(f).get("results", {})
    R = out["results"]
    try:
        if "demo" in only:
            print("demo", flush=True)
            R["demo"] = _run(["demo", "--out", str(tmp / "demo")], a.timeout, env)
            ev = tmp / "demo" / "eval.json"
            if ev.is_file():
                shutil.copy(ev, ROOT / "benchmarks" / "results" / "demo_eval.json")
        if "quaternet" in only:
            print("quaternet", flush=True)
            R["quaternet_eval_baselines"] = _run(["eval", "--model", "quaternet", "--protocol", "dense"],
                                                 a.timeout, env)
            qn = tmp / "qn"
            R["quaternet_train"] = _train(["train", "--model", "quaternet", "--data", str(SHARED),
                                           "--set", "hidden_size=512", "--steps", S], qn, 0, a.timeout, env,
                                          budget_epochs=1500)
            R["quaternet_eval"] = _run(["eval", "--checkpoint", str(qn / "checkpoint.npz"), "--data", str(SHARED),
                                        "--json", str(tmp / "qn.json")], a.timeout, env)
            R["quaternet_generate"] = _run(
                ["generate", "--checkpoint", str(qn / "checkpoint.npz"), "--source",
                 str(SAMPLE / "expmap/test/walking/walking_1.txt"), "--source-frame", "80", "--length", "25",
                 "--out", str(tmp / "pred.bvh")], a.timeout, env)
            R["quaternet_export"] = _run(["export", "--checkpoint", str(qn / "checkpoint.npz")], a.timeout, env)
        if "acrnn" in only:
            print("acrnn", flush=True)
            ac = tmp / "acrnn"
            salsa = SHARED / "acrnn_cmu_salsa"
            R["acrnn_train"] = _train(["train", "--model", "acrnn", "--representation", "dq-all", "--data",
                                       str(salsa), "--set", "hidden_size=128", "--steps", S], ac, 600, a.timeout,
                                      env)
            R["acrnn_eval"] = _run(["eval", "--checkpoint", str(ac / "checkpoint.npz"), "--data", str(salsa)],
                                   a.timeout, env)
            R["acrnn_generate"] = _run(["generate", "--model", "acrnn", "--checkpoint", str(ac / "checkpoint.npz"),
                                        "--source", str(salsa / "05.bvh"), "--length", "300",
                                        "--out", str(tmp / "salsa.bvh")], a.timeout, env)
        if "locomotion" in only:
            print("locomotion", flush=True)
            bn = SHARED / "bandai_namco_locomotion"
            pose = ["train", "--model", "quaternet-long", "--data", str(bn), "--set", "hidden_size=256",
                    "--set", "tf_decay=0.9", "--steps", S]
            R["locomotion_pose_train_cold"] = _train(pose, tmp / "pose_cold", 720, a.timeout, env)
            R["locomotion_pose_train_warm"] = _train(pose, tmp / "pose", 720, a.timeout, env)
            pace = ["train", "--model", "pace", "--data", str(bn), "--pace-chunk-length", "250", "--steps", S]
            R["locomotion_pace_train"] = _train(pace, tmp / "pace_first", 300, a.timeout, env)  # builds pace data
            R["locomotion_pace_train_warm"] = _train(pace, tmp / "pace", 300, a.timeout, env)
            R["locomotion_generate"] = _run(
                ["generate", "--model", "quaternet-long", "--checkpoint", str(tmp / "pose" / "checkpoint.npz"),
                 "--pace", str(tmp / "pace" / "checkpoint.npz"), "--path", "circle:r=3", "--speed", "walk",
                 "--seconds", "120", "--out", str(tmp / "walk.bvh")], a.timeout, env)
    finally:
        atomic_write_text(a.out, json.dumps(with_versions(out), indent=1) + "\n", make_parents=True)
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"wrote {a.out}")
    bad = [k for k, v in R.items() if v.get("rc") != 0]
    if bad:
        print("failed: " + ", ".join(bad))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
