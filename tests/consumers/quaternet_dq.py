"""QuaterNet with dual quaternions from ``quaternet_predict.onnx`` (``representation.name =
"quaternet_dq_frame"``): the sign rule on the local rotations, the current dual quaternions from the metadata's
skeleton, the prediction, and the local rotations decoded from it (deploy/README.md, "Dual-quaternion variant")."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.consumers.common import metadata, session
from tests.consumers.quaternet import canonical, step_loop


def qmul(a, b):
    """Hamilton product of ``(..., 4)`` arrays."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def current_dqs(rotations, parents, offsets) -> np.ndarray:
    """``(B, P, J, 4)`` local rotations → ``(B, P, J, 8)`` current DQs, continuous over time."""
    B, P, J, _ = rotations.shape
    out = np.zeros((B, P, J, 8))
    for j in range(J):
        q = rotations[..., j, :]
        o = np.broadcast_to(offsets[j], q.shape[:-1] + (3,))
        local_d = 0.5 * qmul(np.concatenate([np.zeros(q.shape[:-1] + (1,)), o], axis=-1), q)
        if parents[j] < 0:
            out[..., j, :4] = q
        else:
            pr, pd = out[..., parents[j], :4], out[..., parents[j], 4:]
            out[..., j, :4] = qmul(pr, q)
            out[..., j, 4:] = qmul(pr, local_d) + qmul(pd, q)
    for t in range(1, P):                                     # continuity of the real parts
        flip = np.sum(out[:, t, :, :4] * out[:, t - 1, :, :4], axis=-1) < 0
        out[:, t][flip] *= -1
    return out


def predict(folder, prefix: np.ndarray) -> np.ndarray:
    """Local rotations ``(B, k, J, 4)`` predicted after ``prefix (B, P, J, 4)`` (local unit quaternions)."""
    s = session(Path(folder) / "quaternet_predict.onnx")
    meta = metadata(s)
    assert meta["representation"]["name"] == "quaternet_dq_frame"
    sk = meta["skeleton"]
    parents = sk["parents"]
    B, P, J, _ = prefix.shape
    x = current_dqs(canonical(prefix), parents, np.asarray(sk["offsets"], np.float64))
    (y,) = s.run(None, {"prefix": x.reshape(B, P, 8 * J).astype(np.float32)})
    return local_rotations(y.reshape(B, y.shape[1], J, 8), parents)


def predict_steps(folder, prefix: np.ndarray, k: int) -> np.ndarray:
    """As :func:`predict` with ``quaternet_init.onnx`` + ``quaternet_step.onnx`` (the online loop; also the portable
    graphs): the prefix's current DQs fed one frame per call with the carried state, then each prediction."""
    init, step = session(Path(folder) / "quaternet_init.onnx"), session(Path(folder) / "quaternet_step.onnx")
    sk = metadata(step)["skeleton"]
    B, P, J, _ = prefix.shape
    x = current_dqs(canonical(prefix), sk["parents"], np.asarray(sk["offsets"], np.float64))
    y = step_loop(init, step, x.reshape(B, P, 8 * J).astype(np.float32), k)             # (B, k, 8J)
    return local_rotations(y.reshape(B, k, J, 8), sk["parents"])


def local_rotations(frames: np.ndarray, parents) -> np.ndarray:
    """``(B, k, J, 8)`` current DQs → local unit rotations ``(B, k, J, 4)`` (the output transform)."""
    c = frames.astype(np.float64)[..., :4]                                                    # real parts
    out = np.empty_like(c)
    for j in range(c.shape[-2]):
        out[..., j, :] = c[..., j, :] if parents[j] < 0 else qmul(conj(c[..., parents[j], :]), c[..., j, :])
    return out / np.linalg.norm(out, axis=-1, keepdims=True)
