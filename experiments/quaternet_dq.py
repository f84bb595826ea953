"""The Table 2 analogue (Andreou et al. §7.2) on our data: short-term QuaterNet with quaternions against its
dual-quaternion twin, beside zero-velocity (spec/quaternet.md §9.3).

Train both first with identical settings (same seed, steps, batch, schedules; ``--set representation=...``), e.g.::

    OPENBLAS_NUM_THREADS=1 refimpl train --model quaternet --data ../shared/data --set hidden_size=512 \\
        --set representation=quaternion --steps N --seed 0 --out runs/q
    OPENBLAS_NUM_THREADS=1 refimpl train --model quaternet --data ../shared/data --set hidden_size=512 \\
        --set representation=dual_quaternion --steps N --seed 0 --out runs/dq

then ``python -m experiments.quaternet_dq --quat runs/q/checkpoint.npz --dq runs/dq/checkpoint.npz``.

Evaluates the Table 2 horizons at the data's real frame rate (refimpl.protocols.prediction.table2_protocol) under
the standard (4 windows) and dense (128) samplers, once over both test actions (out to 400 ms: the running test
file is short) and once on walking alone (out to 2000 ms). Writes ``<out>/<protocol>_<actions>.json`` (the
task's result objects) and ``<out>/table.md``, and prints the tables.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.protocols import prediction as PP
from refimpl.protocols import prediction_data as PD
from refimpl.services import load_trained
from refimpl.tasks import prediction as pr

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data"
OUT = ROOT / "experiments" / "results" / "quaternet_dq"
#: The paper's Table 2 (H3.6M subject 5, average over actions, Euler-angle error, radians).
PAPER_TABLE2 = {"horizons_ms": [80, 160, 320, 400, 600, 800, 1000, 2000, 3000, 4000],
                "quaternions": [0.3871, 0.6766, 1.0117, 1.1452, 1.4327, 1.7983, 2.3004, 6.0033, 10.7987, 13.1485],
                "dual quaternions": [0.4091, 0.7250, 1.1086, 1.2612, 1.5686, 1.8111, 2.0584, 2.8334, 3.8045,
                                     4.7124]}
SETS = (("standard", None), ("dense", None), ("standard", ("walking",)), ("dense", ("walking",)))


def _row(label, values):
    return f"| {label} | " + " | ".join(f"{v:.3f}" for v in values) + " |"


def _table(results, protocol) -> list:
    hs = [f"{h:g}" for h in protocol.horizons_ms]
    real = [f"{t:.0f}" for t in protocol.horizon_times_ms]
    lines = []
    actions = list(results[0].curves)
    blocks = actions + (["average"] if len(actions) > 1 else [])
    for a in blocks:
        lines += [f"*{a}* (ms: " + ", ".join(f"{h} = frame {k + 1} ({t} ms)" for h, k, t in
                                            zip(hs, protocol.horizon_frames, real)) + ")", "",
                  "| method | " + " | ".join(hs) + " |", "|---|" + "---|" * len(hs)]
        for r in results:
            lines.append(_row(r.method, r.average if a == "average" else r.actions[a]))
        lines.append("")
    return lines


def _offset_drift(model, data) -> dict:
    """Mean error of the bone offsets implied by the DQ network's predicted frames (Eq. 12), per Table 2 horizon,
    on the standard walking windows: how far the unsupervised dual parts drift when the network runs free."""
    from refimpl.dq_prediction import dq_frames_from_rotations
    from refimpl.models import quaternet as net
    from refimpl.current_dq import local_from_current_dq

    protocol = PP.table2_protocol(data, "standard", actions=("walking",))
    prefix, _, _ = PP.evaluation_windows(data, "walking", protocol)
    B, P, J, _ = prefix.shape
    skel = data.skeleton
    x = dq_frames_from_rotations(PP.canonical_prefix(prefix), skel).reshape(B, P, 8 * J)
    y = net.predict(model.params, x.astype(np.float32), protocol.target_length, model.config.network)
    _, off = local_from_current_dq(y.astype(np.float64).reshape(B, -1, J, 8), skel.parents)   # (B, K, J, 3)
    err = np.linalg.norm(off[..., 1:, :] - skel.offsets[1:], axis=-1).mean(axis=(0, 2))       # (K,)
    return {"horizons_ms": list(protocol.horizons_ms), "horizon_frames": list(protocol.horizon_frames),
            "offset_error": [float(err[k]) for k in protocol.horizon_frames],
            "mean_bone_length": float(np.linalg.norm(skel.offsets[1:], axis=-1).mean())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quat", required=True, help="checkpoint of the quaternion network")
    ap.add_argument("--dq", required=True, help="checkpoint of the dual-quaternion network")
    ap.add_argument("--data", default=str(DATA))
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    models = {"quaternions": load_trained(args.quat), "dual quaternions": load_trained(args.dq)}
    steps = {k: m.meta.get("step") for k, m in models.items()}
    fts = {m.extra["frame_time"] for m in models.values()}
    if len(fts) != 1:
        raise SystemExit(f"the two checkpoints were trained at different frame times: {sorted(fts)}")
    data = pr.resolve_data(args.data, downsample=PD.stride_of("cmu", fts.pop()))
    methods = {"zero-velocity": PP.zero_velocity,
               **{f"QuaterNet {k}": m.spec.make_method(m) for k, m in models.items()}}
    md = ["# QuaterNet short-term: quaternions vs dual quaternions (Table 2 analogue)", "",
          f"Checkpoints: quaternions {args.quat} (step {steps['quaternions']}), dual quaternions {args.dq} "
          f"(step {steps['dual quaternions']}). Mean Euler-angle error (radians, zyx, joint 0 excluded).", ""]
    for name, actions in SETS:
        protocol = PP.table2_protocol(data, name, actions=actions)
        results = PP.evaluate_all(data, methods, protocol, actions=actions,
                                  progress=lambda line: print(line, flush=True))
        tag = f"{name}_{'-'.join(actions) if actions else 'all'}"
        PP.write_results_json(out / f"{tag}.json", results)
        md += [f"## {name} ({protocol.samples_per_sequence} samples per sequence), "
               f"{', '.join(actions) if actions else 'all actions'}, P = {protocol.prefix_length}, "
               f"K = {protocol.target_length}", ""] + _table(results, protocol)
    drift = _offset_drift(models["dual quaternions"], data)
    md += ["## Bone offsets implied by the DQ network's predictions (walking, standard windows)", "",
           "Mean |o_pred − o| over joints (the data's units; mean bone length "
           f"{drift['mean_bone_length']:.2f}, longest 7.6) of the local offsets Eq. 12 reads from the predicted "
           "current DQs (the loss never sees them):", "",
           "| ms | " + " | ".join(f"{h:g}" for h in drift["horizons_ms"]) + " |",
           "|---|" + "---|" * len(drift["horizons_ms"]), _row("offset error", drift["offset_error"]), ""]
    atomic_write_text(out / "offset_drift.json", json.dumps(drift, indent=1) + "\n")
    md += ["## The paper's Table 2 (H3.6M, average over actions)", "",
           "| method | " + " | ".join(str(h) for h in PAPER_TABLE2["horizons_ms"]) + " |",
           "|---|" + "---|" * len(PAPER_TABLE2["horizons_ms"]),
           _row("quaternions", PAPER_TABLE2["quaternions"]), _row("dual quaternions", PAPER_TABLE2["dual quaternions"]),
           ""]
    atomic_write_text(out / "table.md", "\n".join(md))
    atomic_write_text(out / "meta.json", json.dumps({"checkpoints": {"quaternions": str(args.quat),
                                                                      "dual quaternions": str(args.dq)},
                                                      "steps": steps, "paper_table2": PAPER_TABLE2,
                                                      "configs": {k: m.config.to_dict() for k, m in models.items()}},
                                                     indent=1) + "\n")
    print("\n".join(md))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
