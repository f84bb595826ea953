"""Time the data reads issue 35 named, writing ``benchmarks/results/qtg_data_cache.json``.

* QTG on the Bandai Namco locomotion set (``../shared/data/bandai_namco_locomotion``, 830 takes): ``refimpl train
  --model qtg --steps 1`` twice (files read, then the data cache, spec/data.md §7) and ``refimpl eval`` of that
  checkpoint twice (a fresh cache: the 95 held-out takes read; then their entry), each in a subprocess with
  ``--blas-threads 1`` and a temporary ``REFIMPL_CACHE``. Recorded: the wall time, the trainer's ``data: ... in X
  s`` and, for eval, the time until the ``scoring`` line (the data read).
* ``refimpl import``'s data (the prediction task): ``train_datasets`` (the whole folder, as before) against
  ``import_datasets`` (the longest training file parsed) on a synthetic Human3.6M folder (7 subjects x 15 actions x
  2, 99 values per row; the real one is not available here) and on ``../shared/data/dmgnn_cmu_expmap``.

The machine's load average is recorded with every number: on a shared machine the times are what it gave then.

    OMP_NUM_THREADS=1 python benchmarks/qtg_data_cache.py [--rows 400]
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from refimpl.atomic import atomic_write_text  # noqa: E402
from refimpl.versions import with_versions  # noqa: E402

SHARED = ROOT.parent / "shared" / "data"
BN = SHARED / "bandai_namco_locomotion"
OUT = ROOT / "benchmarks" / "results" / "qtg_data_cache.json"


def _run(cmd, cache: Path, mark: str | None = None) -> dict:
    env = dict(os.environ, REFIMPL_CACHE=str(cache), PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1")
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    p = subprocess.Popen([sys.executable, "-m", "refimpl", "--blas-threads", "1", *cmd], env=env, text=True,
                         stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    out, marked = [], None
    for line in p.stdout:
        out.append(line)
        if mark and marked is None and line.startswith(mark):
            marked = time.perf_counter() - t0
    if p.wait() != 0:
        raise SystemExit(f"{cmd}: exit {p.returncode}\n{''.join(out[-20:])}")
    text = "".join(out)
    m = re.search(r"^data: .* in ([0-9.]+) s", text, re.M)
    return {"command": "refimpl --blas-threads 1 " + " ".join(map(str, cmd)), "wall_s": round(time.perf_counter() - t0, 2),
            "data_s": float(m.group(1)) if m else None, "until_scoring_s": None if marked is None else round(marked, 2),
            "cache_hits": text.count("loaded from the cache"), "cached": text.count("cached as"),
            "load_before": round(load0, 2), "load_after": round(os.getloadavg()[0], 2)}


def bench_qtg(tmp: Path) -> dict:
    cache, run = tmp / "cache", tmp / "run"
    train = ["train", "--model", "qtg", "--data", str(BN), "--steps", "1", "--out", str(run)]
    res = {"train_first": _run(train, cache), "train_second": _run([*train, "--overwrite"], cache)}
    ev = ["eval", "--checkpoint", str(run / "checkpoint.npz"), "--data", str(BN)]
    res["eval_first"] = _run(ev, tmp / "cache-eval", mark="scoring")
    res["eval_second"] = _run(ev, tmp / "cache-eval", mark="scoring")
    res["entries_mb"] = {p.name: round(p.stat().st_size / 2**20, 1) for p in sorted(cache.glob("*.npz"))}
    return res


def _synthetic_h36m(root: Path, rows: int) -> None:
    import numpy as np

    from refimpl.protocols.prediction_data import H36M_ACTIONS, H36M_TEST_SUBJECT, H36M_TRAIN_SUBJECTS

    rng = np.random.default_rng(0)
    for subject in (*H36M_TRAIN_SUBJECTS, H36M_TEST_SUBJECT):
        (root / subject).mkdir(parents=True)
        for action in H36M_ACTIONS:
            for sub in (1, 2):
                n = rows + int(rng.integers(0, rows // 2))
                values = rng.normal(scale=0.3, size=(n, 99))
                np.savetxt(root / subject / f"{action}_{sub}.txt", values, fmt="%.7f", delimiter=",")


def _time_reads(data: str) -> dict:
    from refimpl.cli import build_parser
    from refimpl.registry import MODELS, task_of

    args = build_parser().parse_args(["import", "w.npz", "--model", "quaternet", "--out", "c.npz", "--data", data])
    task = task_of(MODELS["quaternet"])
    out = {}
    for name in ("train_datasets", "import_datasets"):
        t0 = time.perf_counter()
        ds, _ = getattr(task, name)(args)
        out[name] = {"s": round(time.perf_counter() - t0, 2), "training_sequences": len(ds.train)}
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=400, help="rows per synthetic H3.6M file (min; up to 1.5x)")
    ap.add_argument("--skip-qtg", action="store_true")
    a = ap.parse_args()
    if not 200 <= a.rows <= 100_000:  # a 50 + 10-frame window at half the 50 Hz rate needs 120 rows; 210 files written
        ap.error(f"--rows: expected 200 ... 100000 rows per file, got {a.rows}")
    res = {}
    with tempfile.TemporaryDirectory(prefix="qtg-data-cache-") as tmp:
        tmp = Path(tmp)
        if not a.skip_qtg and BN.is_dir():
            res["qtg_bandai_namco"] = bench_qtg(tmp)
        _synthetic_h36m(tmp / "h36m", a.rows)
        size = sum(p.stat().st_size for p in (tmp / "h36m").rglob("*.txt"))
        res["import_synthetic_h36m"] = {"files": 210, "mb": round(size / 2**20, 1), **_time_reads(str(tmp / "h36m"))}
        if (SHARED / "dmgnn_cmu_expmap").is_dir():
            res["import_dmgnn_cmu_expmap"] = _time_reads(str(SHARED / "dmgnn_cmu_expmap"))
    res["date_utc"] = time.strftime("%Y-%m-%d %H:%M", time.gmtime())
    atomic_write_text(OUT, json.dumps(with_versions(res), indent=2) + "\n", make_parents=True)
    print(json.dumps(res, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
