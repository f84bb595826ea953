"""The convolutional QuaterNet from ``quaternet-cnn_window.onnx``: the prefix canonicalised (input_transform),
then one window call per predicted frame with the last ``receptive_field`` frames (deploy/README.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.consumers.common import metadata, session
from tests.consumers.quaternet import canonical


def predict(folder, prefix: np.ndarray, k: int) -> np.ndarray:
    s = session(Path(folder) / "quaternet-cnn_window.onnx")
    R = int(metadata(s)["receptive_field"])
    B, P, J, _ = prefix.shape
    window = canonical(prefix).reshape(B, P, 4 * J).astype(np.float32)[:, -R:]
    ys = []
    for _ in range(k):
        (y,) = s.run(None, {"window": window})
        ys.append(y)
        window = np.concatenate([window, y[:, None]], axis=1)[:, -R:]
    return np.stack(ys, axis=1).reshape(B, k, J, 4)
