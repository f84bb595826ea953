"""Locomotion along a path: the pace network and the long-term pose network run online, the character placed on
the path (QN §3.7, ref §7.6; spec/locomotion.md §9). ``refimpl generate --model quaternet-long`` calls
:func:`generate_walk`, then :func:`write_outputs`; ``python -m deploy run`` calls the same loop,
:func:`walk_path`, with the exported step and pace graphs in onnxruntime.

Loop (per generated frame, from the reference's ``generate_motion``)::

    tracks = pace.predict(path, speed)               reparameterised path + amplitude A, frequency ω, facing f
    seed clip (P frames) turned about +Y so that its last facing equals f(0); fed through the GRU → y
    s = 0, φ = atan2(seed phase)
    repeat:  t̂, f, A, ω = tracks at s
             c = [A cos φ, A sin φ, A t̂, f]          6 controls
             y, h = step([y | c], h)                 rotations (J quaternions), offset δ, height
             φ ← φ + ω;  s ← s + A;  root xz = path point at s + δ, root y = height

A dual-quaternion network (``QuaterNetConfig.representation``) is fed the seed as current DQs and its outputs
are decoded per frame (Eq. 12 for the rotations, Eq. 8 for :attr:`GeneratedWalk.dq_positions`).

Shape legend: N generated frames, J joints, P seed frames, M path points.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Mapping

import numpy as np

from refimpl.atomic import atomic_write_text
from refimpl.bounds import BOUNDS, check_number
from refimpl.models import pace, quaternet
from refimpl.motion import Motion
from refimpl.protocols.locomotion import rotate_controls
from refimpl.protocols.locomotion_data import FPS, QUATERNET_UNIT_CM
from refimpl.quat import quat_mul
from refimpl.models import quaternet_long_dq
from refimpl.skeleton import Skeleton
from refimpl.splines import Spline, circle_path, figure_eight_path, line_with_turn_path, read_path_csv

__all__ = ["GeneratedWalk", "parse_path", "read_path_file", "parse_speed", "align_seed", "generate_walk", "walk_path",
           "foot_skating", "bone_length_drift", "dq_bone_length_drift", "facing_of", "write_outputs", "BUILTIN_PATHS",
           "SPEEDS"]

#: Built-in paths of ``--path``, sizes in metres: ``circle[:r=R]`` (default 3 m), ``figure8[:size=S]`` (default
#: 4 m), ``line-turn[:turn=DEG]`` (6 m straight, a 2 m-radius turn of DEG degrees, default 90, then 6 m); or a CSV
#: file of x,z points in metres.
BUILTIN_PATHS = ("circle", "figure8", "line-turn")
#: Target speeds of ``refimpl generate --speed`` in units per frame at 30 fps (the reference notebook: walk 0.5,
#: run 1.2; jog between them is ours).
SPEEDS = {"walk": 0.5, "jog": 0.85, "run": 1.2}
_M = 100.0 / QUATERNET_UNIT_CM  # units per metre


@dataclasses.dataclass(frozen=True)
class GeneratedWalk:
    """A generated motion along a path.

    Attributes
    ----------
    motion : Motion
        N frames, the training skeleton, QuaterNet units, 30 fps.
    controls : (N, 6) the controls fed at each step ``[A cos φ, A sin φ, A t̂x, A t̂z, f_x, f_z]``.
    distance : (N,) arc length s + δ where the root was placed.
    travelled : (N,) arc length s at which the frame's controls were read (before ``s ← s + A``).
    phase : (N,) φ after each step (radians, wrapped to [0, 2π)).
    path : Spline — the pace network's reparameterised path with its tracks (``amplitude``, ``frequency``,
        ``direction``).
    dq_positions : (N, J, 3) or None — dual-quaternion networks only: the world positions read from the predicted
        current DQs (Eq. 8) plus the root; ``motion`` holds the rotations decoded from them (Eq. 12), whose FK
        positions keep the skeleton's bone lengths while these do not.
    """

    motion: Motion
    controls: np.ndarray
    distance: np.ndarray
    travelled: np.ndarray
    phase: np.ndarray
    path: Spline
    dq_positions: np.ndarray | None = None


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


def _angle(v) -> float:
    return math.atan2(float(v[1]), float(v[0]))


def align_seed(rotations: np.ndarray, features: np.ndarray, facing) -> tuple[np.ndarray, np.ndarray]:
    """Turn a seed clip about +Y so that its last facing ``(f6, f7)`` equals ``facing`` (a 2-D (x, z) vector):
    root quaternions ``r ⊗ q`` with ``r = (cos a/2, 0, sin a/2, 0)``, controls by
    :func:`~refimpl.protocols.locomotion.rotate_controls` (the augmentation's map, so ``a = ∠f_seed − ∠facing``)."""
    rot = np.array(rotations, dtype=np.float64)
    feats = np.asarray(features, dtype=np.float64)
    a = _angle(feats[-1, 6:8]) - _angle(facing)
    r = np.array([math.cos(a / 2), 0.0, math.sin(a / 2), 0.0])
    rot[:, 0] = quat_mul(r, rot[:, 0])
    return rot, rotate_controls(feats, a)


def generate_walk(pose_params: Mapping, net: quaternet.QuaterNetConfig, pace_params: Mapping,
                  pace_config: pace.PaceConfig, skeleton: Skeleton, seed_rotations, seed_features, path: Spline,
                  speed: float, num_frames: int, dq_scale: float = 1.0) -> GeneratedWalk:
    """Generate ``num_frames`` frames along ``path`` (fewer if an open path ends first).

    Parameters
    ----------
    pose_params, net : the long-term pose network (``net.num_controls == 6``, ``num_outputs == 2``), over local
        quaternions or current dual quaternions (``net.representation``; the seed converted with
        :func:`refimpl.models.quaternet_long_dq.dq_inputs`, the outputs decoded with Eq. 12 / Eq. 8)
    pace_params, pace_config : the pace network (bidirectional or delayed, run offline over the whole path)
    skeleton : the training skeleton (J joints, QuaterNet units)
    seed_rotations : (P, J, 4); seed_features : (P, 8) — the conditioning clip
    path : Spline in QuaterNet units
    speed : target average speed (units per frame)
    num_frames : int
    dq_scale : dual-quaternion networks: the DQs' translation unit (``QuaterNetLongConfig.dq_scale``)

    Returns
    -------
    GeneratedWalk
    """
    J, dual = net.num_joints, net.representation == "dual_quaternion"
    if net.num_controls != 6 or net.num_outputs != 2 or skeleton.num_joints != J:
        raise ValueError(f"net: expected a long-term network of {skeleton.num_joints} joints with 2 translations and "
                         f"6 controls, got {net}")
    tracks = pace.predict(pace_params, pace_config, path, speed)
    return walk_path(lambda x, h: quaternet.step(pose_params, h, x, net), quaternet.init_state(pose_params, 1, net),
                     tracks, skeleton, seed_rotations, seed_features, num_frames, dual=dual, dq_scale=dq_scale,
                     dtype=np.asarray(pose_params["h0"]).dtype)


def walk_path(step, state, tracks: Spline, skeleton: Skeleton, seed_rotations, seed_features, num_frames: int, *,
              dual: bool = False, dq_scale: float = 1.0, dtype=np.float64) -> GeneratedWalk:
    """The walk loop of the module docstring with any implementation of the pose network's step (NumPy in
    :func:`generate_walk`, the exported step graph in onnxruntime in ``python -m deploy run``).

    Parameters
    ----------
    step : callable ``(x (1, F), state) -> (y (1, G), state)``, F = R + 8, G = R + 2, R = 4J (8J: dual quaternions)
    state : the initial state (the learned ``h0``)
    tracks : the pace network's reparameterised path with its tracks (:func:`refimpl.models.pace.predict`)
    skeleton, seed_rotations, seed_features, num_frames, dq_scale : as :func:`generate_walk`
    dual : the step reads and writes current dual quaternions
    dtype : the dtype of the frames fed to ``step``

    Returns
    -------
    GeneratedWalk
    """
    J = skeleton.num_joints
    R = (8 if dual else 4) * J
    rot, feats = align_seed(seed_rotations, seed_features, tracks.interpolate(0.0, "direction"))
    P = rot.shape[0]
    if P < 1 or rot.shape[1:] != (J, 4) or feats.shape != (P, 8):
        raise ValueError(f"seed: expected rotations (P, {J}, 4) and features (P, 8), got {rot.shape}, {feats.shape}")
    seed = np.concatenate([rot.reshape(P, 4 * J), feats], axis=1)                  # (P, 4J + 8)
    if dual:  # current DQs of the seed (Andreou et al. §6.2)
        seed = quaternet_long_dq.dq_inputs(seed[None], skeleton, dq_scale)[0]               # (P, 8J + 8)
    seed = seed.astype(dtype)
    h = state
    for t in range(P):
        y, h = step(seed[t:t + 1], h)
    if np.shape(y) != (1, R + 2):
        raise ValueError(f"step: expected outputs (1, {R + 2}) for {J} joints, got {np.shape(y)}")
    phi = math.atan2(feats[-1, 3], feats[-1, 2])
    s = 0.0
    rots, roots, ctrls, dists, phases, arcs, dqs = [], [], [], [], [], [], []
    for _ in range(int(num_frames)):
        tan = tracks.interpolate(s, "tangent")
        tan = tan / (np.linalg.norm(tan) + 1e-9)
        face = tracks.interpolate(s, "direction")
        amp = float(tracks.interpolate(s, "amplitude")[0])
        freq = float(tracks.interpolate(s, "frequency")[0])
        c = np.array([amp * math.cos(phi), amp * math.sin(phi), amp * tan[0], amp * tan[1], face[0], face[1]])
        y, h = step(np.concatenate([y, c[None]], axis=1).astype(dtype), h)
        arc = s
        phi = (phi + freq) % (2 * math.pi)
        s += amp
        nxt = s + float(y[0, R])
        if not tracks.closed and nxt >= tracks.length:
            break
        xz = tracks.interpolate(nxt)
        if dual:
            dqs.append(y[0, :R].astype(np.float64).reshape(J, 8))
        else:
            q = y[0, :R].astype(np.float64).reshape(J, 4)
            rots.append(q / np.linalg.norm(q, axis=-1, keepdims=True))
        roots.append([xz[0], float(y[0, R + 1]), xz[1]])
        ctrls.append(c)
        dists.append(nxt)
        arcs.append(arc)
        phases.append(phi)
    if not roots:
        raise ValueError("path: too short for one frame")
    roots = np.array(roots)
    dq_positions = None
    if dual:  # rotations decoded current → local (Eq. 12); the DQs' own positions (Eq. 8) kept beside them
        dec = quaternet_long_dq.decode(np.stack(dqs), np.zeros((len(dqs), 2)), skeleton, dq_scale)
        rots = dec["rotations"]
        dq_positions = dec["dq_positions"] + roots[:, None, :]
    motion = Motion(skeleton, np.stack(rots), roots, 1.0 / FPS, "generated")
    return GeneratedWalk(motion=motion, controls=np.array(ctrls), distance=np.array(dists),
                         travelled=np.array(arcs), phase=np.array(phases),
                         path=tracks, dq_positions=dq_positions)


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
        from refimpl.render import render_path_motion, stderr_progress
        from refimpl.render_strip import limb_sides
        pos = cm.positions()
        path_pts = walk.path.points * QUATERNET_UNIT_CM
        for out in filter(None, (png, gif)):
            written.append(render_path_motion(out, pos, np.asarray(cm.skeleton.parents), path_pts,
                                              closed=walk.path.closed, fps=FPS, stride=gif_stride, title=title,
                                              sides=limb_sides(cm.skeleton), progress=stderr_progress))
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
