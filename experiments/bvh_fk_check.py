"""Every shared BVH file, every frame: refimpl's reading + FK against the independent oracle (tests/bvh_oracle.py).

For each file: the default reading (``translations="auto"``: re-rooted and folded) and the raw one
(``"keep"``) are compared with the oracle's world positions of the joints they keep; prints a table per folder
(files, frames, max error in the files' units, seconds) and writes JSON. Exit 1 if any error exceeds 1e-6.

Usage::

    python -m experiments.bvh_fk_check [--data ../shared/data] [--out experiments/results/bvh_fk_check.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.bvh import read_bvh
from tests import bvh_oracle

ROOT = Path(__file__).resolve().parents[1]


def check(path: Path) -> dict:
    names, ref = bvh_oracle.world_positions(path)                        # (T, J, 3)
    out = {"frames": int(ref.shape[0])}
    for mode in ("auto", "keep"):
        m = read_bvh(path, translations=mode)
        idx = [names.index(n) for n in m.skeleton.names]
        out[mode] = float(np.max(np.abs(m.positions() - ref[:, idx]))) if ref.shape[0] else 0.0
        if mode == "auto":
            out["root"] = m.skeleton.names[0]
            out["translated"] = list(m.translated_joint_names)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--out", default=str(ROOT / "experiments" / "results" / "bvh_fk_check.json"))
    args = ap.parse_args(argv)
    files = sorted(Path(args.data).glob("*/*.bvh"))
    if not files:
        raise SystemExit(f"no BVH files under {args.data}")
    per_folder: dict[str, dict] = {}
    t0 = time.perf_counter()
    for k, f in enumerate(files, 1):
        r = check(f)
        s = per_folder.setdefault(f.parent.name, {"files": 0, "frames": 0, "max_err_auto": 0.0, "max_err_keep": 0.0,
                                                  "roots": set(), "translated": set()})
        s["files"] += 1
        s["frames"] += r["frames"]
        s["max_err_auto"] = max(s["max_err_auto"], r["auto"])
        s["max_err_keep"] = max(s["max_err_keep"], r["keep"])
        s["roots"].add(r["root"])
        s["translated"].add(tuple(r["translated"]))
        if k % 100 == 0:
            print(f"  {k}/{len(files)} files, {time.perf_counter() - t0:.0f} s", flush=True)
    print(f"{'folder':<28}{'files':>6}{'frames':>9}{'max err auto':>14}{'max err keep':>14}  root after auto")
    worst = 0.0
    for name, s in per_folder.items():
        worst = max(worst, s["max_err_auto"], s["max_err_keep"])
        print(f"{name:<28}{s['files']:>6}{s['frames']:>9}{s['max_err_auto']:>14.3g}{s['max_err_keep']:>14.3g}  "
              f"{sorted(s['roots'])} translated {sorted(s['translated'])}")
        s["roots"], s["translated"] = sorted(s["roots"]), sorted(map(list, s["translated"]))
    secs = time.perf_counter() - t0
    print(f"total {len(files)} files in {secs:.0f} s; worst error {worst:.3g}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(args.out, json.dumps({"folders": per_folder, "files": len(files), "seconds": round(secs, 1),
                                            "worst_error": worst}, indent=1))
    return 0 if worst < 1e-6 else 1


if __name__ == "__main__":
    sys.exit(main())
