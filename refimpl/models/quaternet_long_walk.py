"""QuaterNet's long-term system walking a path: the pace network and the long-term pose network run online, the
character placed on the path (QN §3.7, ref §7.6; spec/locomotion.md §9). ``refimpl generate --model quaternet-long``
calls :func:`generate_walk` (its options, files and metrics are :mod:`refimpl.tasks.locomotion_generate`);
``python -m deploy run`` calls the same loop, :func:`walk_path`, with the exported step and pace graphs in
onnxruntime.

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
import math
from typing import Mapping

import numpy as np

from refimpl.augment import rotate_controls
from refimpl.models import pace, quaternet, quaternet_long_dq
from refimpl.motion import Motion
from refimpl.quat import quat_mul
from refimpl.skeleton import Skeleton
from refimpl.splines import Spline

__all__ = ["GeneratedWalk", "align_seed", "generate_walk", "walk_path"]


@dataclasses.dataclass(frozen=True)
class GeneratedWalk:
    """A generated motion along a path.

    Attributes
    ----------
    motion : Motion
        N frames, the training skeleton, QuaterNet units, at the networks' frame rate (``fps``).
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


def _angle(v) -> float:
    return math.atan2(float(v[1]), float(v[0]))


def align_seed(rotations: np.ndarray, features: np.ndarray, facing) -> tuple[np.ndarray, np.ndarray]:
    """Turn a seed clip about +Y so that its last facing ``(f6, f7)`` equals ``facing`` (a 2-D (x, z) vector):
    root quaternions ``r ⊗ q`` with ``r = (cos a/2, 0, sin a/2, 0)``, controls by
    :func:`~refimpl.augment.rotate_controls` (the augmentation's map, so ``a = ∠f_seed − ∠facing``)."""
    rot = np.array(rotations, dtype=np.float64)
    feats = np.asarray(features, dtype=np.float64)
    a = _angle(feats[-1, 6:8]) - _angle(facing)
    r = np.array([math.cos(a / 2), 0.0, math.sin(a / 2), 0.0])
    rot[:, 0] = quat_mul(r, rot[:, 0])
    return rot, rotate_controls(feats, a)


def generate_walk(pose_params: Mapping, net: quaternet.QuaterNetConfig, pace_params: Mapping,
                  pace_config: pace.PaceConfig, skeleton: Skeleton, seed_rotations, seed_features, path: Spline,
                  speed: float, num_frames: int, dq_scale: float = 1.0, *, fps: float) -> GeneratedWalk:
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
    fps : the frame rate the networks were trained at (the data's,
        :data:`refimpl.protocols.locomotion_data.FPS`): speeds and frequencies are per frame of it

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
                     dtype=np.asarray(pose_params["h0"]).dtype, fps=fps)


def walk_path(step, state, tracks: Spline, skeleton: Skeleton, seed_rotations, seed_features, num_frames: int, *,
              dual: bool = False, dq_scale: float = 1.0, dtype=np.float64, fps: float) -> GeneratedWalk:
    """The walk loop of the module docstring with any implementation of the pose network's step (NumPy in
    :func:`generate_walk`, the exported step graph in onnxruntime in ``python -m deploy run``).

    Parameters
    ----------
    step : callable ``(x (1, F), state) -> (y (1, G), state)``, F = R + 8, G = R + 2, R = 4J (8J: dual quaternions)
    state : the initial state (the learned ``h0``)
    tracks : the pace network's reparameterised path with its tracks (:func:`refimpl.models.pace.predict`)
    skeleton, seed_rotations, seed_features, num_frames, dq_scale, fps : as :func:`generate_walk`
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
    motion = Motion(skeleton, np.stack(rots), roots, 1.0 / fps, "generated")
    return GeneratedWalk(motion=motion, controls=np.array(ctrls), distance=np.array(dists),
                         travelled=np.array(arcs), phase=np.array(phases),
                         path=tracks, dq_positions=dq_positions)
