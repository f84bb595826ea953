"""The recurrent QuaterNet's entry of the exporter table (``deploy.models.EXPORTERS["quaternet"]``; the protocol
:class:`deploy.models.entry_api.ExporterEntry`): checkpoints in, model folders out, and the runtime that drives
the exported models (spec/deploy.md §11).

* :func:`load_checkpoint`, :func:`export_dir`, :class:`Runtime` — ``quaternet_init.onnx``, ``quaternet_step.onnx``
  (a frame loop) and ``quaternet_predict.onnx`` (prefix → k frames in one call);
* :func:`run_command`, :func:`add_run_options` — ``python -m deploy run`` (shared with the convolutional network's
  entry, ``deploy/models/quaternet_cnn_io.py``, which also uses this module's kernel tier).

Shape legend: B batch, P prefix frames, k predicted frames, J joints, F input features, G output features,
L layers, H hidden size.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from refimpl.models.quaternet import QuaterNetConfig
from refimpl.protocols.prediction_data import CHECKPOINT_SCHEMA

from deploy.graph import OPSET
from deploy.models.arguments import count, frames_array, metadata_int
from deploy.models.entry_io import (checked_params, checkpoint_params, config_from_meta, read_checkpoint,
                                    write_models)
from deploy.models.quaternet import export_quaternet_init, export_quaternet_predict, export_quaternet_step
from deploy.portable import builder_options, check_target, portable_model
from deploy.runtime import DeployedModel, load_model

__all__ = ["load_checkpoint", "export_dir", "Runtime", "run_command", "add_run_options"]


def read_entry_checkpoint(path):
    arrays, meta = read_checkpoint(path, state_dict_ok=True)
    return checkpoint_params(arrays, state_dict_ok=True), meta


def load_checkpoint(path):
    """``(params, QuaterNetConfig, meta)`` from a ``refimpl train`` checkpoint (``--model quaternet``) or a plain
    state-dict ``.npz`` (the config's defaults: the paper's short-term model)."""
    params, meta = read_entry_checkpoint(path)
    legacy = {"quat": "quaternion"}  # the registry's representation name, stored by checkpoints before §9
    config = config_from_meta(QuaterNetConfig, meta, lambda c: {
        **c, **({"representation": legacy[c["representation"]]} if c.get("representation") in legacy else {})},
        schema=CHECKPOINT_SCHEMA if meta else None, where=str(path))
    return checked_params(params, config, str(path)), config, meta


def network_config(config):
    """The network config of a recipe config (``.network``) or the network config itself."""
    return getattr(config, "network", config)


def frame_rate_of(metadata):
    return float((metadata or {}).get("frame_rate", 25.0))


def export_dir(params, config, out_dir, *, dtype=np.float32, opset=None, k: int = 10, T: int | None = None,
               skeleton=None, metadata=None, mode: str = "unrolled", target: str = "default") -> dict:
    """Export, validate and atomically write ``quaternet_init/step/predict.onnx`` into ``out_dir``.

    ``k`` (or ``T``, its name in ``refimpl export``) is the predictor's number of frames; ``mode`` is accepted for
    the table's contract (the predictor is always unrolled). ``target="portable"`` (``deploy/portable.py``) writes
    the init and step graphs only, at batch 1 in primitive operators, with the host loop in their metadata
    (:func:`portable_loop`); ``dtype`` and ``opset`` are then the portable target's.
    """
    cfg = network_config(config)
    k = int(T or k)
    kw = dict(dtype=dtype, opset=OPSET if opset is None else opset, skeleton=skeleton,
              frame_rate=frame_rate_of(metadata), metadata=metadata)
    if check_target(target) == "portable":
        kw.update(builder_options())
        loop = portable_loop(cfg)
        models = {role: portable_model(f(params, cfg, **kw), host_loop=loop)
                  for role, f in (("init", export_quaternet_init), ("step", export_quaternet_step))}
        return write_models(models, out_dir, "quaternet")
    models = {"init": export_quaternet_init(params, cfg, **kw), "step": export_quaternet_step(params, cfg, **kw)}
    if cfg.num_controls == 0:
        models["predict"] = export_quaternet_predict(params, cfg, k=k, **kw)
    return write_models(models, out_dir, "quaternet")


def portable_loop(config) -> dict:
    """The host loop of QuaterNet's portable init + step graphs (``metadata["target"]["host_loop"]``)."""
    L, H = config.num_layers, config.hidden_size
    return {"summary": "init once per sequence, then one step per frame: the prefix frames, then each prediction "
                       "fed back (with the frame's controls appended when the config has controls)",
            "graphs": ["quaternet_init.onnx", "quaternet_step.onnx"],
            "state": [{"input": "hidden", "output": "hidden_next", "shape": [L, 1, H],
                       "initial": "output hidden of quaternet_init.onnx (the learned h0)"}],
            "loop": ["x[0..P-1] = the prefix frames (1, F) after input_transform (the sign rule)",
                     "hidden = init(x=x[0]).hidden",
                     "for t in 0 .. P-1: y, hidden = step(x=x[t], hidden=hidden)",
                     "repeat k-1 times: y, hidden = step(x=y, hidden=hidden)   # y: each predicted frame"]}


def load_role(m, role, intra_op_threads):
    if m is None:
        return None
    dm = m if isinstance(m, DeployedModel) else load_model(m, intra_op_threads=intra_op_threads)
    if dm.role != role:
        raise ValueError(f"{role}: expected a model with metadata role {role!r}, got {dm.role!r}")
    return dm


def canonical_frames(x: np.ndarray, meta: dict) -> np.ndarray:
    """``x (B, P, F)`` with the sign rule (``deploy.models.quaternet_sign``) applied to its joint quaternions when
    the model's frames are quaternions (``representation.name == "quaternet_frame"``); else unchanged."""
    rep = meta.get("representation") or {}
    if rep.get("name") != "quaternet_frame":
        return x
    from deploy.models.quaternet_sign import canonical_signs

    R = int(rep["fields"][0]["size"])
    B, P = x.shape[:2]
    q = canonical_signs(x[..., :R].reshape(B, P, R // 4, 4)).reshape(B, P, R)
    return np.concatenate([q, x[..., R:]], axis=-1).astype(np.float32)


def prefix_frames(prefix, name="prefix") -> tuple[np.ndarray, tuple]:
    """``(B, P, J, 4)`` or ``(B, P, F)`` -> ``(B, P, F)`` float32 and the trailing shape to restore (refused, not
    coerced: :func:`deploy.models.arguments.frames_array`)."""
    x = frames_array(prefix, name, ranks=(3, 4))
    if x.ndim == 4:
        return x.reshape(x.shape[0], x.shape[1], -1), x.shape[2:]
    return x, x.shape[2:]


class Runtime:
    """The recurrent QuaterNet from exported ``init``/``step``/``predict`` models (any usable subset).

    Parameters
    ----------
    init, step, predict : path, ModelProto, DeployedModel or None
    intra_op_threads : int
    """

    def __init__(self, init=None, step=None, predict=None, *, intra_op_threads: int = 1):
        self.init_model = load_role(init, "init", intra_op_threads)
        self.step_model = load_role(step, "step", intra_op_threads)
        self.predict_model = load_role(predict, "predict", intra_op_threads)

    @classmethod
    def from_dir(cls, directory, *, intra_op_threads: int = 1) -> "Runtime":
        """Load ``quaternet_init/step/predict.onnx`` from ``directory`` (those present)."""
        d = Path(directory)
        found = {k: (d / f"quaternet_{k}.onnx" if (d / f"quaternet_{k}.onnx").is_file() else None)
                 for k in ("init", "step", "predict")}
        if not any(found.values()):
            raise ValueError(f"directory: no quaternet_init/step/predict.onnx in {str(d)!r}")
        return cls(**found, intra_op_threads=intra_op_threads)

    @property
    def k(self) -> int | None:
        """Frames of the ``predict`` model (None without one)."""
        return None if self.predict_model is None else metadata_int(self.predict_model, "k")

    def start(self, x) -> np.ndarray:
        """``hidden (L, B, H)``: the learned initial state for a batch of frames ``x (B, F)``."""
        if self.init_model is None:
            raise ValueError("start: no init model loaded")
        return self.init_model.run(x=frames_array(x, "x", ranks=(2,)))["hidden"]

    def step(self, x, hidden) -> tuple[np.ndarray, np.ndarray]:
        """One frame: ``(y (B, G), hidden_next (L, B, H))``."""
        if self.step_model is None:
            raise ValueError("step: no step model loaded")
        out = self.step_model.run(x=frames_array(x, "x", ranks=(2,)), hidden=hidden)
        return out["y"], out["hidden_next"]

    def predict(self, prefix, k: int, *, use_graph: bool = True) -> np.ndarray:
        """``k`` frames after ``prefix (B, P, J, 4)`` (or ``(B, P, F)``), in the prefix's trailing shape: the
        ``predict`` model when its ``k`` matches (and ``use_graph``), else ``init`` + a ``step`` loop."""
        x, tail = prefix_frames(prefix)
        k = count(k, "k")
        B, P, _ = x.shape
        if use_graph and self.predict_model is not None and self.k == k:
            out = self.predict_model.run(prefix=x)["frames"]
        else:
            x = canonical_frames(x, (self.step_model or self.init_model).metadata)   # the predict graph does it inside
            h = self.start(x[:, 0])
            for t in range(P):
                y, h = self.step(x[:, t], h)
            ys = [y]
            for _ in range(int(k) - 1):
                y, h = self.step(y, h)
                ys.append(y)
            out = np.stack(ys, axis=1)                                            # (B, k, G)
        return out.reshape((B, int(k)) + tuple(tail))


def add_run_options(group) -> None:
    """QuaterNet's option of ``python -m deploy run`` (:func:`deploy.models.run_commands.add_prediction_run_options`)."""
    from deploy.models.run_commands import add_prediction_run_options

    add_prediction_run_options(group)


def run_command(runtime, args) -> int:
    """``python -m deploy run`` for QuaterNet (:func:`deploy.models.run_commands.run_prediction`)."""
    from deploy.models.run_commands import run_prediction

    return run_prediction(runtime, args)


# Kernel tier (unchecked helpers shared with deploy/models/quaternet_cnn_io.py): read_entry_checkpoint,
# network_config, frame_rate_of, load_role, canonical_frames, prefix_frames
