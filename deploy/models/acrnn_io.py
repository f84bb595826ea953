"""acRNN's entry of the exporter table (``deploy.models.EXPORTERS["acrnn"]``; protocol
:class:`deploy.models.entry_api.ExporterEntry`): checkpoints in, model folders out,
and the runtime that drives the exported models (spec/deploy.md §8.2).

* :func:`load_checkpoint` — ``(params, config, meta)`` from a ``refimpl train --model acrnn`` checkpoint;
* :func:`export_dir` — ``acrnn_step.onnx`` and ``acrnn_generate.onnx`` (validated, atomic);
* :class:`Runtime` — a host loop of ``step`` calls or one ``generate`` call, in onnxruntime;
* :func:`run_command` — ``python -m deploy run`` (:mod:`deploy.models.run_commands`).

Shape legend: B batch, S seed frames, N generated frames, F frame size, H hidden, L layers.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from refimpl.models.acrnn import ACRNNConfig
from refimpl.protocols.synthesis import CHECKPOINT_SCHEMA

from deploy.graph import OPSET
from deploy.models.arguments import check_graph_inputs, count, frames_array
from deploy.models.acrnn import export_acrnn_generate, export_acrnn_step
from deploy.models.entry_io import (checked_params, checkpoint_params, config_from_meta, read_checkpoint,
                                    write_models)
from deploy.portable import builder_options, check_target, portable_model
from deploy.runtime import DeployedModel, load_model

__all__ = ["load_checkpoint", "export_dir", "Runtime", "run_command"]


def load_checkpoint(path):
    """``(params, config, meta)`` of an acRNN training checkpoint (parameters ``param.<name>``, config from
    ``meta["model_config"]``; the statistics, representation and skeleton are in ``meta["model_config"]`` too)."""
    arrays, meta = read_checkpoint(path)
    config = config_from_meta(ACRNNConfig, meta, schema=CHECKPOINT_SCHEMA, where=str(path))
    return checked_params(checkpoint_params(arrays), config, str(path)), config, meta


def export_dir(params, config, out_dir, *, mean, std, representation, parents=None, opset=None,
                     dtype=np.float32, mode: str = "loop", metadata=None, skeleton=None,
                     T: int | None = None, target: str = "default") -> dict:
    """Export, validate and atomically write ``acrnn_step.onnx`` and ``acrnn_generate.onnx`` into ``out_dir``.

    ``mode`` is accepted for the command line's sake (the generator is always a Scan over the seed and a Loop
    of ``num_frames`` steps); ``T`` is ignored (N is an input). ``parents`` goes into the metadata.
    ``target="portable"`` (``deploy/portable.py``): the step graph only, at batch 1 in primitive operators, with
    the host loop in its metadata (:func:`portable_loop`).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    extra = dict(metadata or {})
    frame_rate = float(extra.pop("frame_rate", 30.0))
    if parents is not None:
        extra["parents"] = [int(p) for p in parents]
    extra.setdefault("input_transform", {
        "summary": "raw frames in metres at 30 fps (the graphs standardise inside: normalization.in_graph)",
        "steps": ["a BVH take: keep every 2nd frame of 60 fps (30 fps), drop the End Sites, multiply offsets and "
                  "root positions by 0.01 (centimetres -> metres)",
                  f"frame t = [x_(t+1) - x_t, y_t, z_(t+1) - z_t | the joints of frame t as representation."
                  f"fields[1].layout], {representation}; quaternion-like values made continuous over time (negate a "
                  "joint's values when their rotation part has a negative dot product with the previous frame's)",
                  "seed: 10 such frames in the paper's protocol; any S >= 1 works"]})
    extra.setdefault("output_transform", {
        "summary": "frames as the inputs, in metres; the hip's ground position is x_0 + cumulative sum of dx (and "
                   "z likewise), its height y; the decoded outputs (joints, positions) are computed in the graph",
        "steps": ["to write the source BVH's units again, multiply lengths by 100 (metres -> centimetres)"]})
    kw = dict(mean=np.asarray(mean), std=np.asarray(std), representation=representation, dtype=dtype,
              opset=OPSET if opset is None else opset, skeleton=skeleton, frame_rate=frame_rate, metadata=extra)
    if check_target(target) == "portable":
        kw.update(builder_options())
        step = portable_model(export_acrnn_step(params, config, **kw), host_loop=portable_loop(config))
        return write_models({"step": step}, out, "acrnn")
    models = {"step": export_acrnn_step(params, config, **kw), "generate": export_acrnn_generate(params, config, **kw)}
    return write_models(models, out, "acrnn")


def portable_loop(config) -> dict:
    """The host loop of acRNN's portable step graph (``metadata["target"]["host_loop"]``)."""
    L, H = int(config.num_layers), int(config.hidden_size)
    return {"summary": "one step per frame: the seed frames, then each next_frame fed back",
            "graphs": ["acrnn_step.onnx"],
            "state": [{"input": "h", "output": "h_next", "shape": [L, 1, H], "initial": "zeros"},
                      {"input": "c", "output": "c_next", "shape": [L, 1, H], "initial": "zeros"}],
            "loop": ["h = c = zeros (L, 1, H)",
                     "for t in 0 .. S-1: out = step(frame=seed[t], h=h, c=c); h, c = out.h_next, out.c_next",
                     "frames = [out.next_frame]",
                     "repeat N-1 times: out = step(frame=frames[-1], h=h, c=c); h, c = out.h_next, out.c_next; "
                     "frames.append(out.next_frame)"]}


class Runtime:
    """acRNN inference from exported ``step`` / ``generate`` models (either or both).

    Parameters
    ----------
    step, generate : path, ModelProto, DeployedModel or None
    intra_op_threads : int
    """

    def __init__(self, step=None, generate=None, *, intra_op_threads: int = 1):
        def load(m):
            if m is None or isinstance(m, DeployedModel):
                return m
            return load_model(m, intra_op_threads=intra_op_threads)

        self.step_model, self.generate_model = load(step), load(generate)
        for m, role in ((self.step_model, "step"), (self.generate_model, "generate")):
            if m is not None and m.role != role:
                raise ValueError(f"{role}: expected a model with metadata role {role!r}, got {m.role!r}")
            if m is not None:
                check_graph_inputs(m, role, {"step": ("frame", "h", "c"), "generate": ("seed", "num_frames")}[role])
        if self.step_model is None and self.generate_model is None:
            raise ValueError("Runtime: expected a step or a generate model")

    @classmethod
    def from_dir(cls, directory, *, intra_op_threads: int = 1) -> "Runtime":
        """Load ``acrnn_step.onnx`` and ``acrnn_generate.onnx`` from ``directory`` (those present)."""
        d = Path(directory)
        found = {k: (d / f"acrnn_{k}.onnx" if (d / f"acrnn_{k}.onnx").is_file() else None)
                 for k in ("step", "generate")}
        if not any(found.values()):
            raise ValueError(f"directory: no acrnn_step/generate.onnx in {str(d)!r}")
        return cls(**found, intra_op_threads=intra_op_threads)

    @property
    def config(self) -> dict:
        """The network's config from the metadata (``model.config``); ``ValueError`` when it is not an object."""
        model = (self.step_model or self.generate_model).metadata.get("model")
        cfg = model.get("config") if isinstance(model, dict) else None
        if not isinstance(cfg, dict):
            raise ValueError(f"metadata['model']['config']: expected a JSON object, got {type(cfg).__name__}")
        return cfg

    def zero_state(self, batch: int) -> tuple[np.ndarray, np.ndarray]:
        """Zero ``(h, c)``, each ``(L, B, H)``."""
        batch = count(batch, "batch", "batch")
        cfg = self.config
        L = count(cfg.get("num_layers"), "metadata config.num_layers", "layers")
        H = count(cfg.get("hidden_size"), "metadata config.hidden_size", "frames")
        z = np.zeros((L, batch, H), dtype=np.float32)
        return z, z.copy()

    def step(self, frame, state) -> tuple[dict, tuple]:
        """One step: ``(outputs dict with next_frame (B, F) and the decoded joints, (h, c))``."""
        if self.step_model is None:
            raise ValueError("step: no step model loaded")
        frame = frames_array(frame, "frame", ranks=(2,))
        if not isinstance(state, (tuple, list)) or len(state) != 2:
            raise ValueError(f"state: expected a pair (h, c) of (L, B, H) arrays, got {type(state).__name__}")
        out = self.step_model.run(frame=frame, h=state[0], c=state[1])
        return out, (out["h_next"], out["c_next"])

    def generate(self, seed, num_frames: int, *, use_generator: bool = True) -> np.ndarray:
        """Raw frames ``(B, N, F)`` after the raw ``seed (B, S, F)``: one ``generate`` call, or the seed and N − 1
        fed-back frames through ``step`` (host loop)."""
        seed = frames_array(seed, "seed", ranks=(3,))
        n = count(num_frames, "num_frames")
        if use_generator and self.generate_model is not None:
            return self.generate_model.run(seed=seed, num_frames=np.array(n, dtype=np.int64))["frames"]
        state = self.zero_state(seed.shape[0])
        for t in range(seed.shape[1]):
            out, state = self.step(seed[:, t], state)
        frames = [out["next_frame"]]
        for _ in range(n - 1):
            out, state = self.step(frames[-1], state)
            frames.append(out["next_frame"])
        return np.stack(frames, axis=1)                                      # (B, N, F)


def run_command(runtime, args) -> int:
    """``python -m deploy run`` for acRNN (:func:`deploy.models.run_commands.run_synthesis`)."""
    from deploy.models.run_commands import run_synthesis

    return run_synthesis(runtime, args)
