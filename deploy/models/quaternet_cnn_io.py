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
from deploy.portable import builder_options, check_target, is_portable, portable_model
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
               k: int = 10, T: int | None = None, mode: str = "unrolled", target: str = "default") -> dict:
    """Export, validate and atomically write ``quaternet-cnn_window.onnx`` into ``out_dir`` (``k``, ``T`` and
    ``mode`` accepted for the table's contract; the window model has no fixed length). ``target="portable"``:
    the window fixed at the receptive field R, batch 1, recurrent-free graph in the portable target's operators
    (``deploy/portable.py``), the host loop in its metadata (:func:`portable_loop`)."""
    net = network_config(config)
    kw = dict(dtype=dtype, opset=OPSET if opset is None else opset)
    if check_target(target) == "portable":
        kw = builder_options()
    m = export_quaternet_cnn_window(params, net, **kw, skeleton=skeleton, frame_rate=frame_rate_of(metadata),
                                   metadata=metadata)
    if target == "portable":
        m = portable_model(m, host_loop=portable_loop(net), static={"W": int(net.receptive_field)})
    return write_models({"window": m}, out_dir, "quaternet-cnn")


def portable_loop(config) -> dict:
    """The host loop of the portable window graph of the convolutional QuaterNet."""
    R = int(config.receptive_field)
    return {"summary": f"no recurrent state: the window of the last {R} frames is the state; append each "
                       "prediction and drop the oldest frame",
            "graphs": ["quaternet-cnn_window.onnx"],
            "state": [{"input": "window", "output": None, "shape": [1, R, int(config.rotation_size)],
                       "initial": f"the last {R} prefix frames after input_transform (the sign rule); a prefix "
                                  f"needs at least {R} frames",
                       "update": "window = concat(window[:, 1:], pose_next[:, None])"}],
            "loop": [f"window = the last {R} prefix frames (1, {R}, 4J), canonicalised",
                     "repeat k times: pose_next = window_model(window=window); "
                     "window = concat(window[:, 1:], pose_next[:, None], axis=1)"]}


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
        """``pose_next (B, 4J)`` from ``window (B, W, 4J)`` (the last R frames are sent; a portable window graph
        takes exactly R, so fewer are refused)."""
        w, _ = prefix_frames(window, "window")
        R = self.receptive_field
        if w.shape[1] < R and is_portable(self.window_model.metadata):
            raise ValueError(f"window: the portable window graph takes the last R = {R} frames; got {w.shape[1]} "
                             f"(give a prefix of at least {R} frames)")
        return self.window_model.run(window=w[:, -R:])["pose_next"]

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
