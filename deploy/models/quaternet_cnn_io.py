"""The convolutional QuaterNet's entry of the exporter table (``deploy.models.EXPORTERS["quaternet-cnn"]``; the
protocol :class:`deploy.models.entry_api.ExporterEntry`): checkpoints in, ``quaternet-cnn_window.onnx`` out, and
the runtime that drives it (spec/deploy.md §11).

* :func:`load_checkpoint`, :func:`export_dir`, :class:`Runtime` — the window model;
* ``run_command``, ``add_run_options`` — the recurrent QuaterNet's (``deploy/models/quaternet_io.py``): one
  ``python -m deploy run`` form for both networks.

Shape legend: B batch, P prefix frames, W window frames, R receptive field, k predicted frames, J joints.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from refimpl.models.quaternet_cnn import QuaterNetCNNConfig
from refimpl.protocols.prediction_data import CHECKPOINT_SCHEMA

from deploy.graph import OPSET
from deploy.models.arguments import count, metadata_int
from deploy.models.entry_io import checked_params, config_from_meta, write_models
from deploy.models.quaternet import export_quaternet_cnn_window
from deploy.models.quaternet_io import (add_run_options, canonical_frames, frame_rate_of, load_role, network_config,
                                        prefix_frames, read_entry_checkpoint, run_command)

__all__ = ["load_checkpoint", "export_dir", "Runtime", "run_command", "add_run_options"]


def load_checkpoint(path):
    """``(params, QuaterNetCNNConfig, meta)`` from a ``refimpl train`` checkpoint (``--model quaternet-cnn``)."""
    def convert(cfg):
        cfg = dict(cfg)
        if isinstance(cfg.get("skips"), str):  # the recipe stores the skips as text "s:k,s:k"
            cfg["skips"] = tuple(tuple(int(v) for v in item.split(":")) for item in cfg["skips"].split(",")
                                 if item.strip())
        return cfg

    params, meta = read_entry_checkpoint(path)
    config = config_from_meta(QuaterNetCNNConfig, meta, convert, schema=CHECKPOINT_SCHEMA if meta else None, where=str(path))
    return checked_params(params, config, str(path)), config, meta


def export_dir(params, config, out_dir, *, dtype=np.float32, opset=None, skeleton=None, metadata=None,
               k: int = 10, T: int | None = None, mode: str = "unrolled") -> dict:
    """Export, validate and atomically write ``quaternet-cnn_window.onnx`` into ``out_dir`` (``k``, ``T`` and
    ``mode`` accepted for the table's contract; the window model has no fixed length)."""
    m = export_quaternet_cnn_window(params, network_config(config), dtype=dtype, opset=OPSET if opset is None else opset,
                                   skeleton=skeleton, frame_rate=frame_rate_of(metadata), metadata=metadata)
    return write_models({"window": m}, out_dir, "quaternet-cnn")


class Runtime:
    """The convolutional QuaterNet from an exported ``window`` model: predictions by repeated window calls, each
    prediction appended to the window (``refimpl.models.quaternet_cnn.predict``)."""

    def __init__(self, window, *, intra_op_threads: int = 1):
        self.window_model = load_role(window, "window", intra_op_threads)
        if self.window_model is None:
            raise ValueError("window: expected an exported quaternet-cnn window model, got None")
        self.receptive_field = metadata_int(self.window_model, "receptive_field")

    @classmethod
    def from_dir(cls, directory, *, intra_op_threads: int = 1) -> "Runtime":
        p = Path(directory) / "quaternet-cnn_window.onnx"
        if not p.is_file():
            raise ValueError(f"directory: no quaternet-cnn_window.onnx in {str(directory)!r}")
        return cls(p, intra_op_threads=intra_op_threads)

    def step(self, window) -> np.ndarray:
        """``pose_next (B, 4J)`` from ``window (B, W, 4J)`` (the last R frames are sent)."""
        w, _ = prefix_frames(window, "window")
        return self.window_model.run(window=w[:, -self.receptive_field:])["pose_next"]

    def predict(self, prefix, k: int, *, use_graph: bool = True) -> np.ndarray:
        """``k`` frames after ``prefix (B, P, J, 4)`` (or ``(B, P, 4J)``) in the prefix's trailing shape."""
        x, tail = prefix_frames(prefix)
        k = count(k, "k")
        R = self.receptive_field
        x = canonical_frames(x, self.window_model.metadata)   # the sign rule on the whole prefix (input_transform)
        window, ys = x[:, -R:], []
        for _ in range(int(k)):
            y = self.step(window)
            ys.append(y)
            window = np.concatenate([window, y[:, None]], axis=1)[:, -R:]
        return np.stack(ys, axis=1).reshape((x.shape[0], int(k)) + tuple(tail))
