"""Evaluation half of the acRNN representation experiment (experiments/acrnn_table1.py ``eval``).

For every trained row in ``<out>/<row>/checkpoint.npz``: the synthesis protocol (refimpl.tasks.synthesis.evaluate,
152 seeds on the salsa test takes 05 and 20), the long-run behaviour (:data:`LONG_FRAMES` frames from one seed:
mean joint speed per window, against the data's), a side-by-side picture and GIF of one seed continued by three
representations. Writes ``<out>/table1.json``, ``<out>/table1.md``, ``<out>/longrun.json``, ``<out>/side_by_side.png``,
``<out>/side_by_side.gif``.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.protocols import synthesis as SP
from refimpl.protocols.synthesis import root_zeroed_positions
from refimpl.registry import task_of
from refimpl.services import evaluate_model, load_trained
from refimpl.tasks import synthesis as S

DATA = str(Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "acrnn_cmu_salsa")
LABELS = {"quaternions": "Quaternions (MSE)", "quaternions-fk": "Quaternions-FK (MSE + L_quat + FK)",
          "ortho6d": "Ortho6D (MSE)", "dq-mse": "Dual quaternions (MSE)", "dq-all": "Dual quaternions (all losses)",
          "positions": "Positions (MSE)", "quaternions+positions": "Quaternions + positions (MSE)",
          "ortho6d+positions": "Ortho6D + positions (MSE)"}
ORDER = ("positions", "quaternions", "quaternions-fk", "quaternions+positions", "ortho6d", "ortho6d+positions",
         "dq-mse", "dq-all")
PICTURE_ROWS = ("quaternions", "ortho6d", "dq-all")
LONG_FRAMES = 3000
WINDOWS = ((0, 100), (100, 300), (300, 1000), (1000, 2000), (2000, 3000))
SEED = (0, 140)                      # (test take index, start frame) of the pictured / long-run seed


def _speed(pos, fps=30.0):
    """Mean joint speed per frame (m/s) of root-zeroed positions (N, J, 3) -> (N - 1,)."""
    return np.linalg.norm(np.diff(pos, axis=0), axis=-1).mean(axis=-1) * fps


def _draw(ax, pose, parents, color):
    for j, p in enumerate(parents):
        if p >= 0:
            ax.plot([pose[p, 0], pose[j, 0]], [pose[p, 1], pose[j, 1]], color=color, lw=1.2)


def _load_row(d: Path):
    """The cached evaluation of one row (``eval_row.json``, ``eval_clip.npz``), or None when missing or older than
    the checkpoint."""
    js, npz, ck = d / "eval_row.json", d / "eval_clip.npz", d / "checkpoint.npz"
    if not (js.is_file() and npz.is_file()) or js.stat().st_mtime < ck.stat().st_mtime:
        return None
    r = json.loads(js.read_text())
    with np.load(npz, allow_pickle=False) as z:
        clip = (z["pos"], z["gt_pos"], z["parents"])
    return r["results"], r["longrun"], clip


def _evaluate_row(d: Path):
    """Protocol of §5 and the long run of one trained row; written to ``eval_row.json`` / ``eval_clip.npz``
    (so rows can be evaluated as they finish: ``python -m experiments.acrnn_eval OUT ROW``)."""
    model = load_trained(d / "checkpoint.npz")
    task = task_of(model.spec)
    data = task.load_eval_data(DATA, model.extra)
    res = evaluate_model(model, data)
    # long run from one seed
    i, s = SEED
    seed = data.test[i][s:s + SP.SEED_LENGTH][None]
    gen = model.spec.make_method(model)(seed, LONG_FRAMES)[0]                          # (N, F)
    pos = root_zeroed_positions(data.representation, data.skeleton, gen)                # (N, J, 3)
    gt_pos = root_zeroed_positions(data.representation, data.skeleton, data.test[i][s + SP.SEED_LENGTH:])
    sp, gsp = _speed(pos), _speed(gt_pos)
    hip_y = gen[:, 1]
    longrun = {"windows": {f"{a}-{b}": float(sp[a:b - 1].mean()) for a, b in WINDOWS},
               "data_speed": float(gsp.mean()),
               "pose_std_last_1000": float(pos[-1000:].std(axis=0).mean()),
               "data_pose_std": float(gt_pos.std(axis=0).mean()),
               "hip_height_first_last": [float(hip_y[:100].mean()), float(hip_y[-100:].mean())]}
    S.write_results(res, d / "eval_results.json")          # JSON-friendly conversion of the protocol's output
    results = json.loads((d / "eval_results.json").read_text())
    atomic_write_text(d / "eval_row.json", json.dumps({"results": results, "longrun": longrun}, indent=2) + "\n")
    np.savez(d / "eval_clip.npz", pos=pos, gt_pos=gt_pos, parents=np.asarray(data.skeleton.parents))


def main(out: Path):
    rows = [r for r in ORDER if (out / r / "checkpoint.npz").is_file()]
    results, longrun, clips = {}, {}, {}
    hold = None
    for row in rows:
        t0 = time.time()
        cached = _load_row(out / row)
        if cached is None:
            _evaluate_row(out / row)
            cached = _load_row(out / row)
        res, longrun[row], clips[row] = cached
        results[row] = res["acrnn"]
        hold = hold or res["hold"]
        print(f"{row}: evaluated in {time.time() - t0:.0f} s; long run speeds {longrun[row]['windows']}", flush=True)
    results["hold"] = hold
    S.write_results(results, out / "table1.json")
    (out / "longrun.json").write_text(json.dumps(longrun, indent=2) + "\n")
    # markdown table in the shape of Table 1
    hz = ("100", "400", "1000")
    lines = ["| representation | E 100 ms | E 400 ms | E 1000 ms | NPSS 100 | NPSS 400 | NPSS 1000 | accel. (data) |",
             "|---|---|---|---|---|---|---|---|"]
    for row in [*rows, "hold"]:
        r = json.loads((out / "table1.json").read_text())[row]
        h = r["horizons"]
        lines.append(f"| {LABELS.get(row, 'hold last seed frame (baseline)')} | "
                     + " | ".join(f"{100 * h[k]['euclidean']:.2f}" for k in hz) + " | "
                     + " | ".join(f"{h[k]['npss_real']:.3f} ({h[k]['npss_power']:.3f})" for k in hz) + " | "
                     + f"{1000 * r['acceleration']['pred']:.2f} ({1000 * r['acceleration']['gt']:.2f}) |")
    (out / "table1.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    _pictures(out, clips)


def _pictures(out, clips):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in PICTURE_ROWS if r in clips]
    if not rows:
        return
    gt, parents = clips[rows[0]][1], clips[rows[0]][2]
    frames = [0, 15, 30, 60, 90, 150, 300, 600, 1500, 2990]
    panels = [("data", gt)] + [(r, clips[r][0]) for r in rows]
    fig, axes = plt.subplots(len(panels), len(frames), figsize=(1.5 * len(frames), 2.2 * len(panels)), dpi=90)
    for a, (name, pos) in enumerate(panels):
        for b, f in enumerate(frames):
            ax = axes[a, b]
            if f < len(pos):
                _draw(ax, pos[f], parents, "k" if name == "data" else "C%d" % a)
            ax.set_xlim(-1.0, 1.0)
            ax.set_ylim(-1.1, 0.9)
            ax.set_aspect("equal")
            ax.set_xticks([])
            ax.set_yticks([])
            if a == 0:
                ax.set_title(f"+{f / 30:.1f} s", fontsize=8)
            if b == 0:
                ax.set_ylabel(LABELS.get(name, name).split(" (")[0], fontsize=8)
    fig.suptitle("one seed (test take 05, frame 140) continued by three representations; root zeroed", fontsize=9)
    fig.tight_layout()
    fig.savefig(out / "side_by_side.png")
    plt.close(fig)
    # GIF: the first 150 generated frames, every 2nd
    from PIL import Image

    images = []
    for f in range(0, 150, 2):
        fig, axes = plt.subplots(1, len(panels), figsize=(2.0 * len(panels), 2.4), dpi=70)
        for ax, (name, pos) in zip(axes, panels):
            _draw(ax, pos[f], parents, "k" if name == "data" else "C0")
            ax.set_xlim(-1.0, 1.0)
            ax.set_ylim(-1.1, 0.9)
            ax.set_aspect("equal")
            ax.axis("off")
            ax.set_title(LABELS.get(name, name).split(" (")[0], fontsize=7)
        fig.canvas.draw()
        images.append(Image.fromarray(np.asarray(fig.canvas.buffer_rgba())[..., :3]))
        plt.close(fig)
    images[0].save(out / "side_by_side.gif", save_all=True, append_images=images[1:], duration=66, loop=0)
    print(f"wrote {out / 'side_by_side.png'}, {out / 'side_by_side.gif'}")


if __name__ == "__main__":
    import sys

    if len(sys.argv) > 2:                                  # one row: evaluate and cache it
        _evaluate_row(Path(sys.argv[1]) / sys.argv[2])
    else:
        main(Path(sys.argv[1] if len(sys.argv) > 1 else "runs/acrnn_table1"))
