"""Why does QTG miss the context at the first and last transition frames? (issue 26 item 4, spec/qtg.md §11.3)

For a trained QTG checkpoint and the held-out windows of ``--data`` this measures, in the paper's metric (mean
joint-position error per joint, cm, :func:`refimpl.protocols.transition_metrics.joint_position_errors`):

* ``per_frame_cm``: the network's error per transition frame (frame 1 … T);
* ``autoencoder_cm``: the decoder's precision floor, ``D(E(p))`` against ``p`` for the ground-truth poses of frame 1,
  frame T and the first target pose ``g1`` — a generated frame is a decoded latent, so it cannot be closer than
  this on average unless the latent path compensates;
* ``root_only_cm`` / ``rotations_only_cm``: the error with the predicted rotations (resp. root translation)
  replaced by the ground truth's, per frame — which part of the pose carries the miss;
* ``step_cm``: the ground truth's own displacement between consecutive frames (mean per joint), i.e. how far
  the last transition frame is from the target in the data.

Usage::

    python -m experiments.qtg_ends --checkpoint runs/qtg_bn/checkpoint.npz \
        --data ../shared/data/bandai_namco_locomotion --json experiments/results/qtg_locomotion/ends.json

Shape legend: N windows, T transition frames, P pose size, J joints, Z latent size.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from experiments.qtg_locomotion import heldout_windows
from refimpl.atomic import atomic_write_text
from refimpl.protocols.transition_metrics import joint_position_errors
from refimpl.models.qtg import encode
from refimpl.nn.mlp import mlp_forward
from refimpl.services import load_trained, network_methods
from refimpl.protocols.transition import denormalize_poses, join_pose, normalize_poses, split_pose


def autoencode(model, poses):
    """``D(E(p))`` of raw poses ``(N, P)`` through the checkpoint's encoder and decoder (quaternions unit)."""
    dtype = next(iter(model.params.values())).dtype
    mean, std = model.fields["root_mean"], model.fields["root_std"]
    pn = normalize_poses(poses, mean, std).astype(dtype)
    z = encode(model.params, pn, model.config)  # (N, Z)
    out, _ = mlp_forward(z, model.params, "dec", len(model.config.decoder_sizes) + 1, model.config.negative_slope,
                         last_linear=True)
    root, quats = split_pose(denormalize_poses(out.astype(np.float64), mean, std))
    return join_pose(root, quats / np.linalg.norm(quats, axis=-1, keepdims=True))


def measure(model, test_ds) -> dict:
    """The numbers of the module docstring for one checkpoint on one held-out dataset."""
    past, gt, target = test_ds.context()
    T = gt.shape[1]
    method = network_methods(model)[model.spec.name]
    pred = np.concatenate([method(past[i:i + 512], target[i:i + 512], T) for i in range(0, len(gt), 512)])
    sk, idx = test_ds.skeletons, test_ds.skeleton_index

    def err(a, b):
        return joint_position_errors(a, b, sk, idx)[0].mean(axis=(0, 2))  # (T',)

    gt_root, gt_q = split_pose(gt)
    pr_root, pr_q = split_pose(pred)
    out = {"num_windows": int(len(gt)), "per_frame_cm": err(pred, gt).tolist(),
           "root_only_cm": err(join_pose(pr_root, gt_q), gt).tolist(),
           "rotations_only_cm": err(join_pose(gt_root, pr_q), gt).tolist()}
    ends = {"frame_1": gt[:, :1], f"frame_{T}": gt[:, -1:], "g1": target[:, :1]}
    out["autoencoder_cm"] = {k: float(err(autoencode(model, v[:, 0])[:, None], v)[0]) for k, v in ends.items()}
    seq = np.concatenate([past, gt, target], axis=1)  # (N, T + 4, P)
    steps = err(seq[:, 1:], seq[:, :-1])  # consecutive ground-truth frames
    out["step_cm"] = {"into_frame_1": float(steps[1]), f"frame_{T}_to_g1": float(steps[T + 1]),
                      "median": float(np.median(steps))}
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--checkpoint", required=True, nargs="+")
    p.add_argument("--data", default="../shared/data/bandai_namco_locomotion")
    p.add_argument("--stride", type=int, default=4)
    p.add_argument("--json", default=None)
    args = p.parse_args(argv)
    t0 = time.perf_counter()
    models = [load_trained(c) for c in args.checkpoint]
    test_ds = heldout_windows(args, models[0])
    print(f"{test_ds.num_windows} held-out windows in {time.perf_counter() - t0:.1f} s", flush=True)
    results = {}
    for c, m in zip(args.checkpoint, models):
        r = measure(m, test_ds)
        r["step"] = m.meta.get("step")
        results[c] = r
        pf, ro, rr = r["per_frame_cm"], r["root_only_cm"], r["rotations_only_cm"]
        print(f"{c} (step {r['step']}): frame 1 {pf[0]:.2f} cm (root {ro[0]:.2f}, rotations {rr[0]:.2f}), "
              f"frame {len(pf)} {pf[-1]:.2f} cm (root {ro[-1]:.2f}, rotations {rr[-1]:.2f}), mean "
              f"{np.mean(pf):.2f}; autoencoder {json.dumps({k: round(v, 2) for k, v in r['autoencoder_cm'].items()})}"
              f"; ground-truth steps {json.dumps({k: round(v, 2) for k, v in r['step_cm'].items()})}", flush=True)
    if args.json:
        atomic_write_text(Path(args.json), json.dumps(results, indent=2) + "\n", make_parents=True)
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
