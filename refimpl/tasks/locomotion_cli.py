"""``refimpl generate --model quaternet-long``: load the two checkpoints, walk the path, write BVH / pictures /
controls, and print the stability numbers (spec/cli.md, spec/locomotion.md §9)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Callable

import numpy as np

from refimpl.bounds import check_number
from refimpl.errors import UsageError, existing_file, reading
from refimpl.protocols.locomotion_data import FPS, QUATERNET_UNIT_CM
from refimpl.tasks.locomotion import rig_of, skeleton_of
from refimpl.tasks.locomotion_generate import (bone_length_drift, dq_bone_length_drift, facing_of, foot_skating,
                                              generate_walk, parse_path, parse_speed, read_path_file,
                                              write_outputs)

__all__ = ["generate_command", "walk_options", "walk_from_checkpoints"]


def walk_options(path_text: str, speed_text: str, seconds) -> tuple:
    """``(path Spline, speed, frames)`` of ``--path``, ``--speed``, ``--seconds``, checked before any work: a value
    outside :mod:`refimpl.bounds` is a ``UsageError`` (exit 2), a ``--path`` CSV file that is missing or malformed a
    ``BadInputError`` naming the file and line (exit 3)."""
    try:
        speed = parse_speed(speed_text)
        seconds = check_number(seconds, "--seconds", "seconds")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if Path(path_text).suffix.lower() == ".csv":
        p = existing_file(path_text)
        with reading(p):
            path = read_path_file(p)
    else:
        try:
            path = parse_path(path_text)
        except ValueError as exc:
            raise UsageError(str(exc)) from None
    return path, speed, int(round(seconds * FPS))


def walk_from_checkpoints(pose_model, pace_model, path_text: str, speed_text: str, seconds: float):
    """:func:`~refimpl.tasks.locomotion_generate.generate_walk` from two loaded
    :class:`~refimpl.registry.TrainedModel` (``quaternet-long`` and ``pace``)."""
    if pose_model.spec.name != "quaternet-long":
        raise UsageError(f"--checkpoint: expected a quaternet-long checkpoint, got {pose_model.spec.name!r}")
    if pace_model.spec.name != "pace":
        raise UsageError(f"--pace: expected a pace checkpoint, got {pace_model.spec.name!r}")
    path, speed, frames = walk_options(path_text, speed_text, seconds)
    if pose_model.config.output not in ("quaternion", "dual_quaternion"):
        raise UsageError(f"--checkpoint: generation needs a quaternion or dual-quaternion model, got output = "
                         f"{pose_model.config.output!r} (an ablation)")
    seed = pose_model.extra["seed_clip"]
    return generate_walk(pose_model.params, pose_model.config.network(), pace_model.params, pace_model.config,
                         skeleton_of(pose_model.extra), np.asarray(seed["rotations"]), np.asarray(seed["features"]),
                         path, speed, frames, dq_scale=getattr(pose_model.config, "dq_scale", 1.0))


def generate_command(args, load_trained: Callable, say: Callable) -> int:
    """The locomotion branch of ``refimpl generate``."""
    if not args.checkpoint or not args.pace:
        raise UsageError("--model quaternet-long needs --checkpoint POSE.npz and --pace PACE.npz")
    if args.backend != "numpy":
        raise UsageError("--model quaternet-long runs in NumPy (use `python -m deploy` for the exported models)")
    walk_options(args.path, args.speed, args.seconds)  # option values and the path file before any work
    pose_model, pace_model = load_trained(args.checkpoint), load_trained(args.pace)
    walk = walk_from_checkpoints(pose_model, pace_model, args.path, args.speed, args.seconds)
    out = args.out if args.out != "transition.bvh" else "walk.bvh"
    if not str(out).lower().endswith(".bvh"):
        raise UsageError(f"--out {out}: expected a .bvh file name")
    m = walk.motion
    write_outputs(walk, bvh=out, gif=args.gif, png=args.png, controls=args.controls,
                  title=f"quaternet-long, {args.path}, {args.speed}")
    rig = rig_of(pose_model.extra)
    feet = [m.skeleton.index(rig.left_foot), m.skeleton.index(rig.right_foot)]
    skate = foot_skating(m.positions(), feet)
    face = facing_of(walk, rig)
    agree = np.sum(face * walk.controls[:, 4:6], axis=-1)
    dist = np.linalg.norm(np.diff(m.root_positions[:, [0, 2]], axis=0), axis=-1).sum() * QUATERNET_UNIT_CM / 100
    say(f"wrote {out}: {m.num_frames} frames at {FPS:g} fps ({m.num_frames / FPS:.1f} s), {m.num_joints} joints, "
        f"centimetres; root travelled {dist:.1f} m along a {walk.path.length * QUATERNET_UNIT_CM / 100:.1f} m path")
    say(f"facing vs the pace network: median angle {math.degrees(np.median(np.arccos(np.clip(agree, -1, 1)))):.1f}°;"
        f" foot skating {skate['speed_cm_s']:.1f} cm/s in contact ({100 * skate['contact_fraction']:.0f} % of "
        f"foot-frames); bone-length drift {bone_length_drift(m) * QUATERNET_UNIT_CM:.2g} cm")
    if walk.dq_positions is not None:  # dual quaternions: the positions the network's losses saw (Eq. 8)
        gap = np.linalg.norm(walk.dq_positions - m.positions(), axis=-1) * QUATERNET_UNIT_CM
        drift = dq_bone_length_drift(walk.dq_positions, m.skeleton)
        dq_skate = foot_skating(walk.dq_positions, feet)
        say(f"dual quaternions: positions read from the DQs (Eq. 8) vs FK of the decoded rotations (Eq. 12): mean "
            f"{gap.mean():.2f} cm, max {gap.max():.2f} cm; DQ bone-length drift mean {drift['mean'] * QUATERNET_UNIT_CM:.2f}"
            f" cm ({100 * drift['mean_relative']:.1f} %), max {drift['max'] * QUATERNET_UNIT_CM:.2f} cm (not enforced "
            f"by the representation); foot skating of the DQ positions {dq_skate['speed_cm_s']:.1f} cm/s")
    for f in (args.gif, args.png, args.controls):
        if f:
            say(f"wrote {f}")
    return 0
