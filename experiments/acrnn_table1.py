"""The acRNN representation experiment (issue #15, spec/acrnn.md §9): train Table 1 rows on the CMU salsa takes with
one budget per row, through the command line (``refimpl train --model acrnn``), two rows at a time.

    OPENBLAS_NUM_THREADS=1 python -m experiments.acrnn_table1 train --out runs/acrnn_table1
    python -m experiments.acrnn_table1 eval --out runs/acrnn_table1     # table, JSON, pictures, long run

Settings (reduced from the paper's 3 × 1024, batch 32, windows of 100 + 1, 150k iterations, lr 1e-4 to fit a
shared 2-core machine): 3 × :data:`HIDDEN` LSTM, :data:`STEPS` Adam steps at lr :data:`LR`, batch :data:`BATCH`,
windows of :data:`WINDOW` + 1 frames, 5/5 auto-conditioning, seed 0, float32.
Progress lines of every run go to ``<out>/<row>/train.log``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROWS = ("dq-all", "quaternions", "dq-mse", "quaternions-fk", "ortho6d")
HIDDEN = 256
STEPS = 1500
LR = 1e-3
BATCH = 16
WINDOW = 50
DATA = str(Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "acrnn_cmu_salsa")
ROOT = Path(__file__).resolve().parents[1]


def _train_cmd(row, out):
    return [sys.executable, "-m", "refimpl", "train", "--model", "acrnn", "--representation", row, "--data", DATA,
            "--set", f"hidden_size={HIDDEN}", "--steps", str(STEPS), "--lr", str(LR), "--batch-size", str(BATCH),
            "--window-length", str(WINDOW),
            "--out", str(out), "--checkpoint-every", "250", "--progress-every", "50"]


def train(out: Path, parallel: int = 2):
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONPATH=str(ROOT))
    pending, running = list(ROWS), []
    t0 = time.time()
    while pending or running:
        while pending and len(running) < parallel:
            row = pending.pop(0)
            d = out / row
            d.mkdir(parents=True, exist_ok=True)
            resume = ["--resume"] if (d / "checkpoint.npz").is_file() else []
            log = open(d / "train.log", "a")
            print(f"[{time.time() - t0:7.0f} s] start {row}", flush=True)
            running.append((row, subprocess.Popen(_train_cmd(row, d) + resume, stdout=log, stderr=subprocess.STDOUT,
                                                  env=env, cwd=ROOT), time.time()))
        time.sleep(5)
        for item in list(running):
            row, proc, ts = item
            if proc.poll() is not None:
                running.remove(item)
                print(f"[{time.time() - t0:7.0f} s] {row} exited {proc.returncode} after {time.time() - ts:.0f} s",
                      flush=True)
                (out / row / "wall_s.txt").write_text(f"{time.time() - ts:.1f}\n")


if __name__ == "__main__":
    ap = argparse.ArgumentParser()
    ap.add_argument("phase", choices=("train", "eval"))
    ap.add_argument("--out", default="runs/acrnn_table1")
    ap.add_argument("--parallel", type=int, default=2)
    a = ap.parse_args()
    if a.phase == "train":
        train(Path(a.out), a.parallel)
    else:
        from experiments import acrnn_eval
        acrnn_eval.main(Path(a.out))
