"""QuaterNet long-term from ``quaternet-long_step.onnx`` + the initial state file its metadata names, fed by
controls; and the pace network ``quaternet-long_pace.onnx`` (or the portable ``quaternet-long_pace_step.onnx``) with its
output transform (deploy/README.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.consumers.common import metadata, session


def rollout(folder, inputs: np.ndarray, prefix: int) -> np.ndarray:
    """``inputs (B, P + T, F)`` (frames with the controls of every frame) → the free-running ``(B, T, G)``: the
    prefix fed, then each ``y`` with the next frame's controls."""
    s = session(Path(folder) / "quaternet-long_step.onnx")
    meta = metadata(s)
    state_info = meta["initial_state"]
    h0 = np.load(Path(folder) / state_info["file"], allow_pickle=False)               # (L, 1, H)
    G = next(o for o in meta["io"]["outputs"] if o["name"] == "y")["shape"][1]
    x = np.asarray(inputs, np.float32)
    h = np.repeat(h0, x.shape[0], axis=1)
    for t in range(prefix):
        y, h = s.run(None, {"x": x[:, t], "state": h})
    ys = [y]
    for t in range(prefix, x.shape[1] - 1):
        y, h = s.run(None, {"x": np.concatenate([y, x[:, t, G:]], axis=1), "state": h})
        ys.append(y)
    return np.stack(ys, axis=1)


def pace(folder, turning_angle: np.ndarray, speed: float, tangent: np.ndarray) -> dict:
    """Per path point ``[A, omega, facing (2)]`` after the output transform: ``turning_angle (N,)``, the target
    speed, unit tangents ``(N, 2)``."""
    s = session(Path(folder) / "quaternet-long_pace.onnx")
    x = np.stack([turning_angle, np.full_like(turning_angle, speed)], axis=-1)[None].astype(np.float32)
    (y,) = s.run(None, {"x": x})
    return _pace_output(y[0].astype(np.float64), tangent)


def pace_steps(folder, turning_angle: np.ndarray, speed: float, tangent: np.ndarray) -> dict:
    """As :func:`pace` from the portable graph ``quaternet-long_pace_step.onnx``: its metadata's host loop (K points
    per call, both GRU directions at once, the reversed path for the backward one, zero padding at the ends, the
    initial states from the file its metadata names)."""
    s = session(Path(folder) / "quaternet-long_pace_step.onnx")
    meta = metadata(s)
    h0 = np.load(Path(folder) / meta["initial_state"]["file"], allow_pickle=False)        # (2, 1, H)
    K = meta["points_per_call"]
    x = np.stack([turning_angle, np.full_like(turning_angle, speed)], axis=-1).astype(np.float32)
    N = len(x)
    C = -(-N // K)
    pad = np.zeros((C * K - N, 2), np.float32)
    xf, xb = np.concatenate([x, pad]), np.concatenate([x[::-1], pad])
    names = [o.name for o in s.get_outputs()]
    hf, hb, yf, yb = h0[0:1], h0[1:2], [], []
    for c in range(C):
        out = dict(zip(names, s.run(None, {"x_forward": xf[None, c * K:(c + 1) * K], "h_forward": hf,
                                           "x_backward": xb[None, c * K:(c + 1) * K], "h_backward": hb})))
        yf.append(out["y_forward"][0])
        yb.append(out["y_backward"][0])
        hf, hb = out["h_forward_next"], out["h_backward_next"]
    y = np.concatenate(yf)[:N].astype(np.float64) + np.concatenate(yb)[:N][::-1]
    return _pace_output(y, tangent)


def _pace_output(y: np.ndarray, tangent: np.ndarray) -> dict:
    """The pace output transform of the metadata on ``y (N, 4)``."""
    cs = y[:, 2:4] / (np.linalg.norm(y[:, 2:4], axis=-1, keepdims=True) + 1e-9)
    facing = np.stack([tangent[:, 0] * cs[:, 0] - tangent[:, 1] * cs[:, 1],
                       tangent[:, 1] * cs[:, 0] + tangent[:, 0] * cs[:, 1]], axis=-1)
    return {"amplitude": np.maximum(y[:, 0], 0.1), "frequency": np.maximum(y[:, 1], 0.0), "facing": facing}


def walk(folder, seed: np.ndarray, controls: np.ndarray) -> np.ndarray:
    """A walked path: ``seed (P, F)`` frames (rotations with the root facing the path's start, offset, height,
    controls) fed with the carried state, then one step per ``controls (N, 6)`` row with ``[y | controls]``;
    returns the ``N`` generated frames ``(N, G)`` (unit rotations, offset, height)."""
    s = session(Path(folder) / "quaternet-long_step.onnx")
    meta = metadata(s)
    h = np.load(Path(folder) / meta["initial_state"]["file"], allow_pickle=False)        # (L, 1, H)
    for t in range(seed.shape[0]):
        y, h = s.run(None, {"x": seed[t:t + 1].astype(np.float32), "state": h})
    out = []
    for c in controls:
        y, h = s.run(None, {"x": np.concatenate([y, c[None].astype(np.float32)], axis=1), "state": h})
        out.append(y[0])
    return np.stack(out)
