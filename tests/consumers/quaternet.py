"""QuaterNet (recurrent) from ``quaternet_init.onnx`` + ``quaternet_step.onnx``: the online loop with a carried
state, the prefix first mapped by the sign rule of ``input_transform`` (deploy/README.md, "QuaterNet")."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.consumers.common import metadata, session


def canonical(prefix: np.ndarray) -> np.ndarray:
    """The metadata's sign rule: ``(B, P, J, 4) -> (B, P, J, 4)`` unit quaternions, canonical signs."""
    q = np.asarray(prefix, np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = (q[:, 0, :, i] for i in range(4))
    sigma, delta = np.arctan2(z + x, w - y), np.arctan2(z - x, w + y)
    lock_dif = np.hypot(z - x, w + y) <= 1.49e-8
    lock_sum = (np.hypot(z + x, w - y) <= 1.49e-8) & ~lock_dif
    alpha = np.where(lock_dif, 2 * sigma, np.where(lock_sum, 2 * delta, sigma + delta))
    gamma = np.where(lock_dif | lock_sum, 0.0, sigma - delta)
    n = ((alpha >= np.pi) | (alpha < -np.pi)).astype(int) + ((gamma >= np.pi) | (gamma < -np.pi)).astype(int)
    s0 = (-1.0) ** n                                                              # (B, J)
    c = np.cumsum(np.sum(q[:, 1:] * q[:, :-1], axis=-1) < 0, axis=1)              # (B, P-1, J)
    sign = np.concatenate([np.ones_like(s0)[:, None], (-1.0) ** c], axis=1) * s0[:, None]
    return q * sign[..., None]


def predict(folder, prefix: np.ndarray, k: int) -> np.ndarray:
    """``k`` frames after ``prefix (B, P, J, 4)``: ``(B, k, J, 4)``."""
    init, step = session(Path(folder) / "quaternet_init.onnx"), session(Path(folder) / "quaternet_step.onnx")
    meta = metadata(step)
    assert meta["representation"]["name"] == "quaternet_frame" and meta["input_transform"]["in_graph"] is False
    B, P, J, _ = prefix.shape
    x = canonical(prefix).reshape(B, P, 4 * J).astype(np.float32)
    return step_loop(init, step, x, k).reshape(B, k, J, 4)


def step_loop(init, step, x: np.ndarray, k: int) -> np.ndarray:
    """The online loop of the README: ``hidden = init(x_0)``, one ``step`` per frame of ``x (B, P, F)`` with the
    carried state, then ``k − 1`` steps feeding each prediction back; returns ``(B, k, G)``."""
    (h,) = init.run(None, {"x": x[:, 0]})
    for t in range(x.shape[1]):
        y, h = step.run(None, {"x": x[:, t], "hidden": h})
    ys = [y]
    for _ in range(k - 1):
        y, h = step.run(None, {"x": y, "hidden": h})
        ys.append(y)
    return np.stack(ys, axis=1)


def predict_graph(folder, prefix: np.ndarray) -> np.ndarray:
    """``quaternet_predict.onnx``: any signs in (the graph canonicalises), ``(B, k, J, 4)`` out."""
    s = session(Path(folder) / "quaternet_predict.onnx")
    B, P, J, _ = prefix.shape
    (out,) = s.run(None, {"prefix": np.asarray(prefix, np.float32).reshape(B, P, 4 * J)})
    return out.reshape(B, out.shape[1], J, 4)
