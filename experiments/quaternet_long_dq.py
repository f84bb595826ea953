"""Long-term QuaterNet, quaternions vs dual quaternions (Andreou et al. §6.2, §7.2; spec/locomotion.md §11).

Evaluation half of the experiment: two ``refimpl train --model quaternet-long`` checkpoints trained with identical
settings (``--set output=quaternion`` and ``--set output=dual_quaternion``) and one pace checkpoint. Prints and
writes (``--json``):

* the held-out protocol (spec/locomotion.md §8: windows of P + T frames from the held-out Bandai Namco files, free
  running with the ground-truth controls): position error per horizon frame and velocity error, for the
  quaternion model (FK), the DQ model read two ways (FK of the rotations decoded with Eq. 12; the DQs' own
  positions, Eq. 8) and zero velocity; on the same windows, the gap between the DQ model's two position readings
  and the bone-length drift of its DQ positions;
* a walk of ``--seconds`` (default 120) on a circle of radius 3 m at walking speed for both models: the root's
  distance to the centre, facing agreement with the pace network, foot skating (whole walk, first and last
  20 s), mean joint speed of the root-relative pose per 10-s block (a frozen character goes to 0), root height
  range, and for the DQ model the DQ-vs-FK gap and the DQ bone-length drift over the walk;
* ``--png`` / ``--gif``: the two walks side by side (left quaternions, right dual quaternions), same path.

Usage::

    OPENBLAS_NUM_THREADS=1 python -m experiments.quaternet_long_dq \\
        --quat Q/checkpoint.npz --dq D/checkpoint.npz --pace P/checkpoint.npz --json R.json --png W.png
"""
from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from refimpl.protocols import locomotion as LP
from refimpl.protocols import locomotion_data as LD
from refimpl.recipes import quaternet_long as recipe
from refimpl.models import quaternet_long_dq as dqr
from refimpl.services import load_trained
from refimpl.tasks import locomotion as L
from refimpl.tasks import locomotion_generate as G
from refimpl.tasks.locomotion import walk_from_checkpoints

DATA = str(Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "bandai_namco_locomotion")
CM = LD.QUATERNET_UNIT_CM
HORIZONS = (1, 10, 30, 60)


def _say(*a):
    print(*a, flush=True)


def _errors(res):
    p = np.asarray(res["position"])
    return {**{f"frame_{h}": float(p[h - 1]) for h in HORIZONS if h <= len(p)},
            "mean": float(p.mean()), "mean_cm": float(p.mean() * CM), "velocity_mean": float(np.mean(res["velocity"])),
            "position": [round(float(v), 5) for v in p]}


def held_out(quat, dq, data_dir: str, max_files: int = 0) -> dict:
    data = L.load_eval_data(data_dir, quat.extra, max_files=max_files)
    res = LP.evaluate(data, L.methods({"quaternion": recipe.make_method(quat), "dual_quaternion_fk": recipe.make_method(dq),
                                      "dual_quaternion_dq_positions": recipe.extra_methods(dq)[
                                          "quaternet-long_dq_positions"]}))
    out = {k: _errors(v) for k, v in res.items()}
    # the DQ model's two readings on the same windows
    inputs, _, _ = LP.evaluation_windows(data)
    sk = L.skeleton_of(dq.extra)
    gaps, drifts = [], []
    for i in range(0, len(inputs), 64):
        d, tr = dqr.rollout(dq.params, dq.config.network(), inputs[i:i + 64], data.prefix, sk, dq.config.dq_scale)
        dec = dqr.decode(d, tr, sk, dq.config.dq_scale)
        gaps.append(np.linalg.norm(dec["dq_positions"] - dec["fk_positions"], axis=-1).ravel())
        drifts.append(np.abs(dqr.bone_lengths(dec["dq_positions"], sk.parents)
                             - np.linalg.norm(np.asarray(sk.offsets)[1:], axis=-1)).ravel())
    gap, drift = np.concatenate(gaps) * CM, np.concatenate(drifts) * CM
    rest = np.linalg.norm(np.asarray(sk.offsets)[1:], axis=-1) * CM
    out["dq_vs_fk_cm"] = {"mean": float(gap.mean()), "p95": float(np.percentile(gap, 95)), "max": float(gap.max())}
    out["dq_bone_length_drift_cm"] = {"mean": float(drift.mean()), "p95": float(np.percentile(drift, 95)),
                                      "max": float(drift.max()), "mean_rest_length": float(rest.mean())}
    out["windows"] = int(res["zero_velocity"]["windows"])
    out["files"] = len(data.files)
    return out


def _block_speeds(pos, seconds=10):
    """Mean joint speed (cm/s) of the root-relative pose per block of ``seconds``."""
    rel = pos - pos[:, :1]
    v = np.linalg.norm(np.diff(rel, axis=0), axis=-1).mean(-1) * LD.FPS * CM
    n = int(seconds * LD.FPS)
    return [round(float(v[i:i + n].mean()), 2) for i in range(0, len(v) - n + 1, n)]


def walk_stats(model, pace, seconds: float, path: str = "circle:r=3"):
    t0 = time.time()
    walk = walk_from_checkpoints(model, pace, path, "walk", seconds)
    m = walk.motion
    rig = L.rig_of(model.extra)
    feet = [m.skeleton.index(rig.left_foot), m.skeleton.index(rig.right_foot)]
    pos = m.positions()
    n20 = int(20 * LD.FPS)
    face = G.facing_of(walk, rig)
    ang = np.degrees(np.arccos(np.clip(np.sum(face * walk.controls[:, 4:6], -1), -1, 1)))
    radius = np.hypot(m.root_positions[:, 0], m.root_positions[:, 2]) * CM
    out = {"frames": int(m.num_frames), "seconds": float(m.num_frames / LD.FPS), "wall_s": round(time.time() - t0, 1),
           "root_radius_cm": [float(radius.min()), float(radius.max())],
           "root_height_cm": [float(m.root_positions[:, 1].min() * CM), float(m.root_positions[:, 1].max() * CM)],
           "facing_deg": {"median": float(np.median(ang)), "p90": float(np.percentile(ang, 90))},
           "foot_skating_cm_s": {"all": G.foot_skating(pos, feet)["speed_cm_s"],
                                 "first_20s": G.foot_skating(pos[:n20], feet)["speed_cm_s"],
                                 "last_20s": G.foot_skating(pos[-n20:], feet)["speed_cm_s"],
                                 "contact_fraction": G.foot_skating(pos, feet)["contact_fraction"]},
           "pose_speed_cm_s_per_10s": _block_speeds(pos),
           "fk_bone_length_drift_cm": G.bone_length_drift(m) * CM}
    if walk.dq_positions is not None:
        gap = np.linalg.norm(walk.dq_positions - pos, axis=-1) * CM
        drift = G.dq_bone_length_drift(walk.dq_positions, m.skeleton)
        out["dq_vs_fk_cm"] = {"mean": float(gap.mean()), "max": float(gap.max()),
                              "first_20s": float(gap[:n20].mean()), "last_20s": float(gap[-n20:].mean())}
        out["dq_bone_length_drift_cm"] = {"mean": drift["mean"] * CM, "max": drift["max"] * CM,
                                          "mean_relative": drift["mean_relative"]}
        out["dq_foot_skating_cm_s"] = G.foot_skating(walk.dq_positions, feet)["speed_cm_s"]
    return walk, out


def side_by_side(walks, titles, png=None, gif=None):
    """Render each walk with :func:`refimpl.render.render_path_motion` and put the pictures side by side."""
    import tempfile

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from refimpl.atomic import atomic_write_bytes
    from refimpl.render import render_path_motion
    with tempfile.TemporaryDirectory() as tmp:
        if png:
            imgs = []
            for i, (w, t) in enumerate(zip(walks, titles)):
                f = Path(tmp) / f"{i}.png"
                render_path_motion(f, w.motion.positions() * CM, w.motion.skeleton.parents, w.path.points * CM,
                                   closed=w.path.closed, title=t)
                imgs.append(plt.imread(f))
            h = max(im.shape[0] for im in imgs)
            fig = plt.figure(figsize=(sum(im.shape[1] for im in imgs) / 80, h / 80), dpi=80)
            for i, im in enumerate(imgs):
                ax = fig.add_subplot(1, len(imgs), i + 1)
                ax.imshow(im)
                ax.set_axis_off()
            fig.subplots_adjust(0, 0, 1, 1, 0, 0)
            import io
            buf = io.BytesIO()
            fig.savefig(buf, format="png")
            plt.close(fig)
            atomic_write_bytes(png, buf.getvalue())
        if gif:
            from refimpl.render import render_gif
            # one GIF, the first 20 s: the two poses side by side, root x/z removed (the paths are in the PNG)
            a, b = (w.motion.positions() * CM for w in walks)
            a, b = (p - p[:, :1] * np.array([1.0, 0.0, 1.0]) for p in (a, b))
            n = min(len(a), len(b), int(20 * LD.FPS))
            render_gif(gif, a[:n], walks[0].motion.skeleton.parents, prediction=b[:n], fps=LD.FPS, stride=2,
                       up="y", labels=tuple(titles), title="same circle, same pace network")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quat", required=True)
    ap.add_argument("--dq", required=True)
    ap.add_argument("--pace", required=True)
    ap.add_argument("--data", default=DATA)
    ap.add_argument("--max-files", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=120.0)
    ap.add_argument("--json")
    ap.add_argument("--png")
    ap.add_argument("--gif")
    ap.add_argument("--skip-held-out", action="store_true")
    args = ap.parse_args()
    quat, dq, pace = load_trained(args.quat), load_trained(args.dq), load_trained(args.pace)
    assert quat.config.output == "quaternion" and dq.config.output == "dual_quaternion"
    report = {"checkpoints": {"quaternion": {"path": args.quat, "step": quat.meta.get("step"),
                                             "config": quat.config.to_dict()},
                              "dual_quaternion": {"path": args.dq, "step": dq.meta.get("step"),
                                                  "config": dq.config.to_dict()},
                              "pace": {"path": args.pace, "step": pace.meta.get("step")}}}
    if not args.skip_held_out:
        t0 = time.time()
        report["held_out"] = held_out(quat, dq, args.data, args.max_files)
        _say(f"held-out ({report['held_out']['windows']} windows, {time.time() - t0:.0f} s):")
        for k in ("quaternion", "dual_quaternion_fk", "dual_quaternion_dq_positions", "zero_velocity"):
            r = report["held_out"][k]
            _say(f"  {k:30s} " + " ".join(f"@{h} {r[f'frame_{h}']:.3f}" for h in HORIZONS if f'frame_{h}' in r)
                 + f"  mean {r['mean']:.3f} ({r['mean_cm']:.1f} cm)  vel {r['velocity_mean']:.3f}")
        _say(f"  DQ vs FK positions (cm): {report['held_out']['dq_vs_fk_cm']}")
        _say(f"  DQ bone-length drift (cm): {report['held_out']['dq_bone_length_drift_cm']}")
    walks = {}
    for name, model in (("quaternion", quat), ("dual_quaternion", dq)):
        walks[name], report.setdefault("circle_walk", {})[name] = walk_stats(model, pace, args.seconds)
        _say(f"circle walk {name}: {json.dumps(report['circle_walk'][name])}")
    if args.png or args.gif:
        side_by_side([walks["quaternion"], walks["dual_quaternion"]],
                     [f"quaternions (step {quat.meta.get('step')})", f"dual quaternions (step {dq.meta.get('step')})"],
                     png=args.png, gif=args.gif)
    if args.json:
        from refimpl.atomic import atomic_write_text
        atomic_write_text(args.json, json.dumps(report, indent=1) + "\n", make_parents=True)
        _say(f"wrote {args.json}")
    return report


if __name__ == "__main__":
    main()
