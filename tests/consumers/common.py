"""What every consumer needs: a session and the model's metadata, read through onnxruntime only."""
from __future__ import annotations

import json

import onnxruntime as ort


def session(path) -> ort.InferenceSession:
    """A one-thread CPU session of ``path``."""
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    return ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])


def metadata(sess: ort.InferenceSession) -> dict:
    """Every metadata entry decoded as JSON (the README's "The model contract")."""
    return {k: json.loads(v) for k, v in sess.get_modelmeta().custom_metadata_map.items()}
