"""acRNN from ``acrnn_step.onnx`` (a host loop with zero LSTM state) and ``acrnn_generate.onnx`` (one call): raw
frames in metres in and out, the standardisation inside (deploy/README.md, "acRNN")."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.consumers.common import metadata, session


def generate_loop(folder, seed: np.ndarray, n: int) -> np.ndarray:
    """``seed (B, S, F)`` raw → ``(B, n, F)`` raw, by ``step`` calls."""
    s = session(Path(folder) / "acrnn_step.onnx")
    cfg = metadata(s)["model"]["config"]
    B = seed.shape[0]
    h = np.zeros((cfg["num_layers"], B, cfg["hidden_size"]), np.float32)
    c = h.copy()
    names = [o.name for o in s.get_outputs()]
    for t in range(seed.shape[1]):
        out = dict(zip(names, s.run(None, {"frame": seed[:, t].astype(np.float32), "h": h, "c": c})))
        h, c = out["h_next"], out["c_next"]
    frames = [out["next_frame"]]
    for _ in range(n - 1):
        out = dict(zip(names, s.run(None, {"frame": frames[-1], "h": h, "c": c})))
        h, c = out["h_next"], out["c_next"]
        frames.append(out["next_frame"])
    return np.stack(frames, axis=1)


def generate(folder, seed: np.ndarray, n: int) -> dict:
    """``acrnn_generate.onnx``: every output by name (``frames`` and the decoded joints)."""
    s = session(Path(folder) / "acrnn_generate.onnx")
    outs = s.run(None, {"seed": seed.astype(np.float32), "num_frames": np.array(n, np.int64)})
    return dict(zip([o.name for o in s.get_outputs()], outs))


def hip_positions(frames: np.ndarray, start_xz=(0.0, 0.0)) -> np.ndarray:
    """The output_transform: hip ``(x, y, z)`` per frame in metres from ``[dx, y, dz | ...]`` frames ``(N, F)``
    (the frame's own position is before its dx, dz)."""
    x = start_xz[0] + np.concatenate([[0.0], np.cumsum(frames[:-1, 0])])
    z = start_xz[1] + np.concatenate([[0.0], np.cumsum(frames[:-1, 2])])
    return np.stack([x, frames[:, 1], z], axis=-1)
