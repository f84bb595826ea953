"""Locomotion along a path, the task's part: the ``--path`` and ``--speed`` options, the output files (BVH,
pictures, controls JSON) and the metrics of a generated walk (foot skating, bone lengths, facing) (spec/locomotion.md
§9). The walk itself, the pace network and the long-term pose network run online, is
:mod:`refimpl.models.quaternet_long_walk`; ``refimpl generate --model quaternet-long`` calls its
:func:`~refimpl.models.quaternet_long_walk.generate_walk`, then :func:`write_outputs`.

Shape legend: N generated frames, J joints, M path points.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Mapping

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.bounds import BOUNDS, check_number
from refimpl.models.quaternet_long_walk import GeneratedWalk
from refimpl.motion import Motion
from refimpl.protocols.locomotion_data import FPS, QUATERNET_UNIT_CM
from refimpl.skeleton import Skeleton
from refimpl.splines import Spline, circle_path, figure_eight_path, line_with_turn_path, read_path_csv

__all__ = ["parse_path", "read_path_file", "parse_speed", "foot_skating", "bone_length_drift", "dq_bone_length_drift",
           "facing_of", "write_outputs", "BUILTIN_PATHS", "SPEEDS"]

#: Built-in paths of ``--path``, sizes in metres: ``circle[:r=R]`` (default 3 m), ``figure8[:size=S]`` (default
#: 4 m), ``line-turn[:turn=DEG]`` (6 m straight, a 2 m-radius turn of DEG degrees, default 90, then 6 m); or a CSV
#: file of x,z points in metres.
BUILTIN_PATHS = ("circle", "figure8", "line-turn")
#: Target speeds of ``refimpl generate --speed`` in units per frame at 30 fps (the reference notebook: walk 0.5,
#: run 1.2; jog between them is ours).
SPEEDS = {"walk": 0.5, "jog": 0.85, "run": 1.2}
_M = 100.0 / QUATERNET_UNIT_CM  # units per metre


def parse_path(text: str) -> Spline:
    """``circle[:r=METRES]``, ``figure8[:size=METRES]``, ``line-turn[:turn=DEG]``, or a CSV file of ``x,z``
    points in metres; the result is in QuaterNet units.

    Raises
    ------
    ValueError
    """
    name, _, rest = text.partition(":")
    opts = {}
    for item in filter(None, rest.split(",")):
        k, sep, v = item.partition("=")
        if not sep:
            raise ValueError(f"--path {text!r}: expected NAME:KEY=VALUE[,KEY=VALUE]")
        try:
            opts[k.strip()] = float(v)
        except ValueError:
            raise ValueError(f"--path {text!r}: {v!r} is not a number") from None
    if name == "circle":
        r = check_number(opts.pop("r", 3.0), f"--path {text!r}: r", "path_metres")
        _no_extra(opts, text)
        return circle_path(r * _M)
    if name == "figure8":
        size = check_number(opts.pop("size", 4.0), f"--path {text!r}: size", "path_metres")
        _no_extra(opts, text)
        return figure_eight_path(size * _M)
    if name == "line-turn":
        turn = check_number(opts.pop("turn", 90.0), f"--path {text!r}: turn", "path_turn")
        _no_extra(opts, text)
        return line_with_turn_path(6.0 * _M, turn, 2.0 * _M, 6.0 * _M)
    p = Path(text)
    if p.suffix.lower() == ".csv":
        return read_path_file(p)
    raise ValueError(f"--path {text!r}: expected circle[:r=M], figure8[:size=M], line-turn[:turn=DEG] or a .csv file")


def read_path_file(path) -> Spline:
    """A ``--path`` CSV file (``x,z`` metres, :func:`refimpl.splines.read_path_csv`) in QuaterNet units, within
    the bounds of :mod:`refimpl.bounds` (coordinates, length); ``ValueError`` naming the file (and line)."""
    sp = read_path_csv(path)
    lo, hi = BOUNDS["path_csv_metres"].lo, BOUNDS["path_csv_metres"].hi
    bad = np.flatnonzero(~((sp.points >= lo) & (sp.points <= hi)).all(axis=1))
    if bad.size:
        raise ValueError(f"{path}: point {int(bad[0]) + 1} ({sp.points[bad[0], 0]:.6g}, {sp.points[bad[0], 1]:.6g})"
                         f": expected coordinates in [{lo:g}, {hi:g}] metres")
    if sp.length > BOUNDS["path_length_metres"].hi:
        raise ValueError(f"{path}: the path is {sp.length:.6g} m long, more than the limit "
                         f"{BOUNDS['path_length_metres'].hi:g} m")
    return Spline(sp.points * _M, closed=False)


def _no_extra(opts: Mapping, text: str) -> None:
    if opts:
        raise ValueError(f"--path {text!r}: unknown option(s) {sorted(opts)}")


def parse_speed(text) -> float:
    """``walk``, ``jog``, ``run`` (:data:`SPEEDS`) or a number of units per frame."""
    if text in SPEEDS:
        return SPEEDS[text]
    try:
        v = float(text)
    except (TypeError, ValueError):
        raise ValueError(f"--speed {text!r}: expected walk, jog, run or units per frame") from None
    return check_number(v, f"--speed {text!r}", "speed")


def facing_of(walk: GeneratedWalk, rig) -> np.ndarray:
    """The character's facing per frame (:func:`refimpl.protocols.locomotion_data.facing_vectors`), (N, 2) as (x, z)."""
    from refimpl.protocols.locomotion_data import facing_vectors
    return facing_vectors(walk.motion.skeleton, walk.motion.rotations, rig)


def foot_skating(positions: np.ndarray, feet, fps: float = FPS, contact_height: float = 2.0 / QUATERNET_UNIT_CM):
    """Horizontal foot speed while in contact: a foot is in contact on frames where its height is within
    ``contact_height`` (default 2 cm) of its lowest height over the clip.

    Parameters
    ----------
    positions : (N, J, 3) world positions (Y up, QuaterNet units)
    feet : joint indices

    Returns
    -------
    dict ``{"speed_cm_s": mean horizontal speed in contact (cm/s), "contact_fraction": share of foot-frames in
    contact}``
    """
    p = np.asarray(positions, np.float64)
    speeds, contact = [], []
    for j in feet:
        h = p[:, j, 1]
        c = (h[1:] <= h.min() + contact_height) & (h[:-1] <= h.min() + contact_height)
        v = np.linalg.norm(np.diff(p[:, j, [0, 2]], axis=0), axis=-1) * fps * QUATERNET_UNIT_CM
        speeds.append(v[c])
        contact.append(c)
    sp = np.concatenate(speeds)
    return {"speed_cm_s": float(sp.mean()) if sp.size else float("nan"),
            "contact_fraction": float(np.concatenate(contact).mean())}


def dq_bone_length_drift(positions, skeleton: Skeleton) -> dict:
    """Bone lengths of positions read from dual quaternions (not enforced by the representation) against the
    skeleton's rest lengths (units): ``{"max": largest |Δ|, "mean": mean |Δ|, "mean_relative": mean |Δ| / rest}``
    over frames and bones."""
    par = np.asarray(skeleton.parents)
    js = np.arange(1, skeleton.num_joints)
    p = np.asarray(positions, np.float64)
    rest = np.linalg.norm(np.asarray(skeleton.offsets, np.float64)[js], axis=-1)
    d = np.abs(np.linalg.norm(p[..., js, :] - p[..., par[js], :], axis=-1) - rest)
    keep = rest > 0
    return {"max": float(d.max()), "mean": float(d.mean()), "mean_relative": float((d[..., keep] / rest[keep]).mean())}


def bone_length_drift(motion: Motion) -> float:
    """Largest |bone length − rest length| over frames and bones (units): 0 up to rounding, as positions come
    from FK of the skeleton."""
    p = motion.positions()
    sk = motion.skeleton
    par = np.asarray(sk.parents)
    js = np.arange(1, sk.num_joints)
    lengths = np.linalg.norm(p[:, js] - p[:, par[js]], axis=-1)
    rest = np.linalg.norm(np.asarray(sk.offsets)[js], axis=-1)
    return float(np.abs(lengths - rest).max())


def _scaled(motion: Motion, scale: float) -> Motion:
    sk = motion.skeleton
    new = Skeleton(sk.parents, np.asarray(sk.offsets) * scale, names=sk.names, end_sites=sk.end_sites,
                   joints_left=sk.joints_left, joints_right=sk.joints_right)
    return Motion(new, motion.rotations, motion.root_positions * scale, motion.frame_time, motion.name)


def write_outputs(walk: GeneratedWalk, *, bvh=None, gif=None, png=None, controls=None, title=None,
                  gif_stride: int = 2) -> list:
    """Write the BVH (centimetres, End Sites added below leaves), the pictures (the path drawn ON the floor
    under the character, left and right limbs in two shades, progress on stderr) and the per-frame controls
    JSON."""
    from refimpl.bvh_write import write_bvh
    from refimpl.tasks.transition_generate import with_end_sites

    written = []
    cm = _scaled(walk.motion, QUATERNET_UNIT_CM)
    if bvh:
        write_bvh(bvh, with_end_sites(cm))
        written.append(Path(bvh))
    if gif or png:
        from refimpl.progress import stderr_line
        from refimpl.render import render_path_motion
        from refimpl.render_strip import limb_sides
        pos = cm.positions()
        path_pts = walk.path.points * QUATERNET_UNIT_CM
        for out in filter(None, (png, gif)):
            written.append(render_path_motion(out, pos, np.asarray(cm.skeleton.parents), path_pts,
                                              closed=walk.path.closed, fps=FPS, stride=gif_stride, title=title,
                                              sides=limb_sides(cm.skeleton), progress=stderr_line))
    if controls:
        doc = {"fps": FPS, "units": "QuaterNet units (1 = 5.6444 cm) per frame",
               "columns": ["phase_cos", "phase_sin", "direction_x", "direction_z", "facing_x", "facing_z"],
               "frames": [{"frame": i, "distance": round(float(walk.distance[i]), 5),
                           "phase": round(float(walk.phase[i]), 5),
                           "controls": [round(float(v), 6) for v in walk.controls[i]],
                           "root": [round(float(v), 5) for v in walk.motion.root_positions[i]]}
                          for i in range(walk.motion.num_frames)]}
        atomic_write_text(Path(controls), json.dumps(doc) + "\n", make_parents=True)
        written.append(Path(controls))
    return written
