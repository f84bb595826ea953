"""Benchmark: the default training command against 1 and 2 BLAS threads, alone and beside two CPU-bound jobs.

Issue #27 asks for a ``--blas-threads`` default that is never much slower than the best setting, both on an
idle machine and with two other CPU-bound processes running. This runs the command a newcomer runs,
``python -m refimpl [--blas-threads N] train --out DIR --steps S`` (QTG on the embedded sample, the recipe's
default network), as a subprocess, for each setting:

* ``default`` — no ``--blas-threads`` flag (whatever the parser's default is now: ``auto``, which measures what
  other processes use and sets the thread count from it, refimpl/threads.py; the counts it chose are recorded);
* ``1`` and ``2`` — the flag given.

Each setting runs under two conditions: ``alone`` (nothing started by the benchmark; the machine may still be
busy with other work, so the load average is recorded before and after every run) and ``2 hogs`` (the benchmark
starts two Python processes that spin on the CPU, bounded by ``--hog-seconds``, and ends them after the run).
The time per step is the median of the per-step differences of ``elapsed_s`` in the run's ``loss.csv`` after
``--skip`` warm-up steps, so start-up (imports, data) is not counted. Settings alternate order between rounds.
The children's environment has ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS`` and ``MKL_NUM_THREADS`` removed,
so only the command line decides the thread count. Nothing asserts on time. ``--conditions`` runs only some
conditions (e.g. ``2hogs`` now and ``alone`` later, when the machine is idle), each into its own ``--out``.

    python benchmarks/bench_thread_default.py [--rounds 2] [--steps 30] [--conditions alone,2hogs] [--out FILE.json]

Prints a table (median ms per step, steps/s, the ratio to the fastest setting of the same condition, the load
average before each run) and writes the JSON.
"""
from __future__ import annotations

import argparse
import csv
import json
import os
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

SETTINGS = ("default", "1", "2")
CONDITIONS = ("alone", "2 hogs")
_AUTO_LINE = "BLAS threads (auto): "
_HOG = "import time\nend = time.time() + {s}\nx = 0\nwhile time.time() < end:\n    x += 1\n"


def _child_env() -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _step_times(loss_csv: Path, skip: int) -> list[float]:
    """Per-step wall times (s) from the trainer's ``loss.csv`` (column ``elapsed_s``), after ``skip`` steps."""
    with open(loss_csv, newline="") as f:
        elapsed = [float(r["elapsed_s"]) for r in csv.DictReader(f)]
    return [b - a for a, b in zip(elapsed[skip:], elapsed[skip + 1:])]


def run_once(setting: str, steps: int, skip: int, timeout: float) -> dict:
    """One ``refimpl train`` run; returns the median step time, the wall time and the load around it."""
    with tempfile.TemporaryDirectory() as d:
        flag = [] if setting == "default" else ["--blas-threads", setting]
        cmd = [sys.executable, "-m", "refimpl", *flag, "train", "--out", d, "--steps", str(steps)]
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, cwd=ROOT, env=_child_env(), capture_output=True, text=True, timeout=timeout)
        wall = time.perf_counter() - t0
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed ({proc.returncode}): {proc.stderr.strip()[-300:]}")
        dts = _step_times(Path(d) / "loss.csv", skip)
    auto = [line[len(_AUTO_LINE):] for line in proc.stdout.splitlines() if line.startswith(_AUTO_LINE)]
    return dict(setting=setting, step_ms=1e3 * statistics.median(dts), steps_timed=len(dts), wall_s=wall,
                load_before=load0, load_after=os.getloadavg()[0], auto_threads=auto[0] if auto else None)


def _start_hogs(n: int, seconds: float) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, "-c", _HOG.format(s=seconds)]) for _ in range(n)]


def _stop(hogs: list[subprocess.Popen]) -> None:
    for h in hogs:
        h.terminate()
    for h in hogs:
        try:
            h.wait(timeout=10)
        except subprocess.TimeoutExpired:
            h.kill()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--steps", type=int, default=30, help="training steps per run (default 30)")
    ap.add_argument("--skip", type=int, default=5, help="warm-up steps not timed (default 5)")
    ap.add_argument("--hog-seconds", type=float, default=900.0,
                    help="upper bound on each CPU hog's life (they are ended after every run; default 900)")
    ap.add_argument("--timeout", type=float, default=900.0, help="upper bound on one run (default 900 s)")
    ap.add_argument("--conditions", default="alone,2hogs",
                    help="comma-separated conditions to run: alone, 2hogs (default both)")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "bench_thread_default.json"))
    a = ap.parse_args(argv)
    names = {"alone": "alone", "2hogs": "2 hogs"}
    try:
        conditions = [names[c.strip()] for c in a.conditions.split(",")]
    except KeyError:
        ap.error(f"--conditions: expected a comma-separated list of alone, 2hogs; got {a.conditions!r}")

    from refimpl.cli import build_parser

    default = build_parser().get_default("blas_threads")
    runs = []
    for r in range(a.rounds):
        for cond in conditions:
            order = SETTINGS if r % 2 == 0 else SETTINGS[::-1]
            for setting in order:
                hogs = _start_hogs(2, a.hog_seconds) if cond == "2 hogs" else []
                try:
                    if hogs:
                        time.sleep(1.0)
                    res = run_once(setting, a.steps, a.skip, a.timeout)
                finally:
                    _stop(hogs)
                res.update(round=r, condition=cond)
                runs.append(res)
                chose = f", auto chose {res['auto_threads']}" if res["auto_threads"] else ""
                print(f"round {r} {cond:7s} threads {setting:7s} {res['step_ms']:8.1f} ms/step "
                      f"(load {res['load_before']:.1f} -> {res['load_after']:.1f}, wall {res['wall_s']:.0f} s"
                      f"{chose})", flush=True)

    summary = {}
    print(f"\n--blas-threads default of the command line: {default}; {a.steps} steps per run, median after "
          f"{a.skip}; {a.rounds} rounds")
    print(f"| condition | setting | ms/step (median of rounds) | steps/s | / fastest | load before each run |")
    print("|---|---|---|---|---|---|")
    for cond in conditions:
        med = {s: statistics.median(x["step_ms"] for x in runs if x["condition"] == cond and x["setting"] == s)
               for s in SETTINGS}
        best = min(med.values())
        for s in SETTINGS:
            loads = [round(x["load_before"], 1) for x in runs if x["condition"] == cond and x["setting"] == s]
            label = f"default ({default})" if s == "default" else s
            chose = [x["auto_threads"] for x in runs if x["condition"] == cond and x["setting"] == s]
            summary.setdefault(cond, {})[s] = dict(step_ms=med[s], ratio_to_fastest=med[s] / best, loads=loads,
                                                   **({"auto_threads": chose} if s == "default" else {}))
            print(f"| {cond} | {label} | {med[s]:.1f} | {1e3 / med[s]:.1f} | {med[s] / best:.2f} | "
                  f"{', '.join(map(str, loads))} |")
    out = dict(command="python -m refimpl [--blas-threads N] train --out DIR --steps %d" % a.steps,
               default_blas_threads=default, conditions=conditions, rounds=a.rounds, steps=a.steps, skip=a.skip,
               cpu_count=os.cpu_count(), time_utc=time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
               summary=summary, runs=runs)
    atomic_write_text(a.out, json.dumps(with_versions(out), indent=1) + "\n", make_parents=True)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
