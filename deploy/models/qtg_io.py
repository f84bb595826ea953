"""QTG's entry of the exporter table (``deploy.models.EXPORTERS["qtg"]``): checkpoints in, model folders out,
and the runtime that drives the exported models.

* :func:`load_checkpoint` — ``(params, config, meta)`` from a ``refimpl train`` checkpoint or a state dict;
* :func:`export_dir` — ``qtg_init.onnx``, ``qtg_step.onnx``, ``qtg_rollout.onnx`` (validated, atomic);
* :class:`Runtime` — ``init`` + ``step`` (a game loop) or one ``rollout`` call, in onnxruntime.

The protocol's names (:class:`deploy.models.entry_api.ExporterEntry`) are defined here; the command hooks
(``add_export_options``, ``add_run_options``, ``export_checkpoint``, ``run_command``) call
``deploy/models/qtg_cli.py``.

Shape legend: B batch, T frames, P pose size.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from refimpl.bounds import MAX_TRANSITION_FRAMES as _BOUND_T
from refimpl.models.qtg import QTGConfig
from refimpl.protocols.transition import CHECKPOINT_SCHEMA
from refimpl.protocols.transition_join import inertialize_joins, join_blend_frames as default_blend

from deploy.graph import OPSET
from deploy.models.arguments import check_graph_inputs
from deploy.models.entry_io import checkpoint_params, read_checkpoint, write_models
from deploy.models.qtg import export_qtg_init, export_qtg_join, export_qtg_rollout, export_qtg_step, join_entry
from deploy.models.qtg_compact import export_qtg_rollout_compact
from deploy.portable import builder_options, check_target, portable_model
from deploy.quantize import WEIGHT_FORMATS
from deploy.runtime import DeployedModel, load_model

__all__ = ["load_checkpoint", "export_dir", "Runtime", "MAX_TRANSITION_FRAMES", "add_export_options",
           "add_run_options", "export_checkpoint", "run_command"]

#: Largest ``T`` :meth:`Runtime.transition` generates (5.5 minutes at 30 fps; a larger T would only hang); the
#: bound of ``refimpl``'s ``--transition-length`` too (``refimpl.bounds``).
MAX_TRANSITION_FRAMES = _BOUND_T
_STATE_KEYS = ("pose", "latent_prev", "hidden", "target_latent")
#: The inputs each role's graph takes (the runtime feeds them by name).
_GRAPH_INPUTS = {"init": ("past", "target"), "step": _STATE_KEYS, "rollout": ("past", "target"),
                 "join": ("past", "poses", "target")}


def load_checkpoint(path):
    """``(params, config, meta)`` from a QTG checkpoint (``refimpl.checkpoint``) or a plain state-dict ``.npz``.

    Parameters are the arrays named ``param.<name>`` (training checkpoints) or all arrays (state dicts); the
    config comes from ``meta["model_config"]`` (unknown keys ignored), else ``QTGConfig()``.

    The content is validated before it is returned (:mod:`refimpl.checkpoint_schema`, spec/robustness.md §9):
    the config's field types and ranges, stored statistics (``fps`` > 0, ``root_std`` > 0, finite), and every
    parameter's name, shape (from the config), dtype and finiteness.

    Raises
    ------
    ValueError
        A damaged file, or content that fails the schema (the message names the file and the field).
    """
    from refimpl.checkpoint_schema import (expected_param_shapes, validate_model_config, validate_params,
                                           validate_task_fields)
    from refimpl.models import qtg as qtg_model

    where = str(path)
    arrays, meta = read_checkpoint(path, state_dict_ok=True)
    cfg = meta.get("model_config", {})
    cfg = {} if cfg is None else cfg
    validate_task_fields(meta, CHECKPOINT_SCHEMA, where)  # top-level root_mean / root_std, when a caller stored them there
    if not isinstance(cfg, dict):
        raise ValueError(f"{where}: model_config: expected a JSON object, got {type(cfg).__name__}")
    validate_task_fields(cfg, CHECKPOINT_SCHEMA, where)
    config = validate_model_config(QTGConfig, cfg, where)
    params = checkpoint_params(arrays, state_dict_ok=True)
    validate_params(params, expected_param_shapes(qtg_model, QTGConfig, config), where, dtype=cfg.get("dtype"),
                    prefix="param." if any(k.startswith("param.") for k in arrays) else "")
    return params, config, meta


def export_dir(params, config, out_dir, *, normalization=None, skeleton=None, opset=None, dtype=np.float32,
                   mode: str = "scan", T: int | None = None, metadata=None,
                   compact: str | None = None, join: str = "none", join_blend_frames: int | None = None,
                   frame_rate: float | None = None, target: str = "default") -> dict[str, Path]:
    """Export, validate and atomically write ``qtg_init/step/rollout.onnx`` into ``out_dir``; return the paths.

    ``target="portable"`` (``deploy/portable.py``) writes ``qtg_init.onnx``, ``qtg_step.onnx`` and, with a join,
    ``qtg_join.onnx`` (:func:`deploy.models.qtg.export_qtg_join`) at batch 1 in primitive operators, with the
    host loop in their metadata (:func:`portable_loop`); no rollout model (``mode``, ``compact``, ``dtype``,
    ``opset`` do not apply).

    ``join="inertialize"`` bakes the join option into the rollout graph (``deploy/join.py``) and writes a ``join``
    entry into all three models' metadata (init and step: "apply after the T frames"; :meth:`Runtime.transition`
    does so on its step path). ``frame_rate`` (default: ``metadata["frame_rate"]``, else 30) sets the join's frame
    time and the metadata's rate.

    ``compact`` (``"float32"``, ``"int8"`` or ``"int4"``; float32 graphs only) writes the rollout model as the
    compact deployment variant with those weights (``deploy.qtg_compact``, ``spec/deploy.md`` §5.4) instead of
    the ``mode`` translation; the init and step models are unchanged.
    """
    if compact is not None:
        if compact not in WEIGHT_FORMATS:
            raise ValueError(f"compact: expected one of {WEIGHT_FORMATS} or None, got {compact!r}")
        if np.dtype(dtype) != np.float32:
            raise ValueError(f"compact: the compact rollout is a float32 graph, got dtype {np.dtype(dtype)}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rate = float(frame_rate or (metadata or {}).get("frame_rate") or 30.0)
    if check_target(target) == "portable":
        if compact is not None:
            raise ValueError("compact: the portable target has no rollout model (compact applies to it only)")
        return _export_portable(params, config, out, normalization=normalization, skeleton=skeleton, T=T,
                                metadata=metadata, join=join, join_blend_frames=join_blend_frames, frame_rate=rate)
    kw = dict(dtype=dtype, opset=OPSET if opset is None else opset, normalization=normalization,
              skeleton=skeleton, metadata=metadata, frame_rate=rate)
    jkw = dict(join=join, join_blend_frames=join_blend_frames)
    if compact is None:
        rollout = export_qtg_rollout(params, config, T=T, mode=mode, **kw, **jkw)
    else:
        rollout = export_qtg_rollout_compact(params, config, T=T, weights=compact, opset=kw["opset"],
                                             normalization=normalization, skeleton=skeleton, metadata=metadata,
                                             frame_rate=rate, **jkw)
    if join != "none":  # validated by the rollout exporter above
        T_eff = config.transition_length if T is None else int(T)
        n = default_blend(T_eff) if join_blend_frames is None else join_blend_frames
        kw["metadata"] = join_entry(metadata, join, T_eff, rate, n, in_graph=False)
    models = {"init": export_qtg_init(params, config, **kw), "step": export_qtg_step(params, config, **kw),
              "rollout": rollout}
    return write_models(models, out, "qtg")


def _export_portable(params, config, out, *, normalization, skeleton, T, metadata, join, join_blend_frames,
                     frame_rate) -> dict[str, Path]:
    """The portable target of :func:`export_dir`."""
    T_eff = config.transition_length if T is None else int(T)
    kw = dict(builder_options(), normalization=normalization, skeleton=skeleton, metadata=metadata,
              frame_rate=frame_rate)
    models = {}
    if join != "none":
        models["join"] = export_qtg_join(config, T=T_eff, join=join, join_blend_frames=join_blend_frames, **kw)
        kw["metadata"] = join_entry(metadata, join, T_eff, frame_rate,
                                    read_join_blend(models["join"]), in_graph=False)
    models = {"init": export_qtg_init(params, config, **kw), "step": export_qtg_step(params, config, **kw), **models}
    loop = portable_loop(config, T_eff, join != "none")
    return write_models({role: portable_model(m, host_loop=loop) for role, m in models.items()}, out, "qtg")


def read_join_blend(model) -> int:
    """``blend_frames`` of the ``join`` metadata entry of an exported QTG model."""
    from deploy.metadata import read_metadata

    return int(read_metadata(model)["join"]["blend_frames"])


def portable_loop(config, T: int, join: bool) -> dict:
    """The host loop of QTG's portable graphs (``metadata["target"]["host_loop"]``; deploy/README.md)."""
    Z, H, L, P = config.latent_size, config.gru_hidden, config.gru_layers, config.pose_size
    init_out = "an output of qtg_init.onnx"
    return {"summary": "init once per transition, step once per generated frame (T frames), then the join graph on "
                       "the T frames when there is one",
            "graphs": ["qtg_init.onnx", "qtg_step.onnx"] + (["qtg_join.onnx"] if join else []),
            "state": [{"input": "pose", "output": "pose_next", "shape": [1, P], "initial": init_out},
                      {"input": "latent_prev", "output": "latent_prev_next", "shape": [1, Z], "initial": init_out},
                      {"input": "hidden", "output": "hidden_next", "shape": [L, 1, H], "initial": init_out},
                      {"input": "target_latent", "output": None, "shape": [1, 2, Z],
                       "initial": init_out + "; the same for every step of the transition"}],
            "loop": ["past, target = input_transform of the four context frames, (1, 2, P) each",
                     "pose, latent_prev, hidden, target_latent = init(past=past, target=target)",
                     f"repeat T = {T} times: pose, latent_prev, hidden = step(pose=pose, latent_prev=latent_prev, "
                     "hidden=hidden, target_latent=target_latent); frames.append(pose)",
                     "poses = stack(frames, axis=1)   # (1, T, P)"]
            + (["poses = join(past=past, poses=poses, target=target).poses_joined"] if join else [])
            + ["output_transform of poses"]}


class Runtime:
    """QTG inference from exported ``init``/``step``/``rollout`` models (any subset), as a game loop would use them.

    Parameters
    ----------
    init, step, rollout : path, ModelProto, DeployedModel or None
        The exported models (``deploy.qtg``). ``transition`` needs ``rollout`` or both ``init`` and ``step``.
    intra_op_threads : int
    """

    def __init__(self, init=None, step=None, rollout=None, join=None, *, intra_op_threads: int = 1):
        def load(m):
            if m is None or isinstance(m, DeployedModel):
                return m
            return load_model(m, intra_op_threads=intra_op_threads)

        self.init_model, self.step_model, self.rollout_model = load(init), load(step), load(rollout)
        self.join_model = load(join)
        for m, role in ((self.init_model, "init"), (self.step_model, "step"), (self.rollout_model, "rollout"),
                        (self.join_model, "join")):
            if m is not None and m.role != role:
                raise ValueError(f"{role}: expected a model with metadata role {role!r}, got {m.role!r}")
            if m is not None:
                check_graph_inputs(m, role, _GRAPH_INPUTS[role])

    @classmethod
    def from_dir(cls, directory, *, intra_op_threads: int = 1) -> "Runtime":
        """Load ``qtg_init.onnx``, ``qtg_step.onnx``, ``qtg_rollout.onnx``, ``qtg_join.onnx`` from ``directory``
        (those present)."""
        d = Path(directory)
        files = {k: d / f"qtg_{k}.onnx" for k in ("init", "step", "rollout", "join")}
        found = {k: (p if p.is_file() else None) for k, p in files.items()}
        if not any(found.values()):
            raise ValueError(f"directory: no qtg_init/step/rollout.onnx in {str(d)!r}")
        return cls(**found, intra_op_threads=intra_op_threads)

    def start(self, past, target) -> dict[str, np.ndarray]:
        """Run ``init``: the state ``{"pose", "latent_prev", "hidden", "target_latent"}`` for :meth:`step`."""
        if self.init_model is None:
            raise ValueError("start: no init model loaded")
        out = self.init_model.run(past=past, target=target)
        return {"pose": out["pose"], "latent_prev": out["latent_prev"], "hidden": out["hidden"],
                "target_latent": out["target_latent"]}

    def step(self, state: Mapping[str, np.ndarray]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
        """Run ``step`` once: ``(pose_next (B, P), next state)``."""
        if self.step_model is None:
            raise ValueError("step: no step model loaded")
        if not isinstance(state, Mapping) or any(k not in state for k in _STATE_KEYS):
            raise ValueError(f"state: expected a mapping with keys {list(_STATE_KEYS)} (from start or step), got "
                             f"{sorted(map(str, state)) if isinstance(state, Mapping) else type(state).__name__}")
        out = self.step_model.run(pose=state["pose"], latent_prev=state["latent_prev"], hidden=state["hidden"],
                                  target_latent=state["target_latent"])
        new = {"pose": out["pose_next"], "latent_prev": out["latent_prev_next"], "hidden": out["hidden_next"],
               "target_latent": state["target_latent"]}
        return out["pose_next"], new

    def transition(self, past, target, T: int | None = None, *, use_rollout: bool = True) -> np.ndarray:
        """A whole transition ``(B, T, P)``: one rollout call, or ``init`` + ``T`` step calls (host loop).

        ``T`` defaults to the rollout model's length (or the config's ``transition_length``); the rollout model
        is used only when its baked-in length equals ``T``.

        Raises
        ------
        ValueError
            ``T`` not an integer in ``[1, MAX_TRANSITION_FRAMES]``; ``past``/``target`` refused by
            :meth:`deploy.runtime.DeployedModel.run` (shape, batch mismatch, batch 0, dtype, non-finite values).
        """
        meta = (self.rollout_model or self.step_model or self.init_model).metadata.get("model", {})
        cfg = meta.get("config")
        default_T = meta.get("transition_length") or (cfg.get("transition_length") if isinstance(cfg, Mapping)
                                                      else None)
        T = default_T if T is None else T
        if not isinstance(T, (int, np.integer)) or isinstance(T, (bool, np.bool_)) or not 1 <= T <= \
                MAX_TRANSITION_FRAMES:
            raise ValueError(f"T: expected an integer in [1, MAX_TRANSITION_FRAMES = {MAX_TRANSITION_FRAMES}], "
                             f"got {T!r}")
        if use_rollout and self.rollout_model is not None:
            rT = self.rollout_model.metadata.get("model", {}).get("transition_length")
            if rT == T:
                return self.rollout_model.run(past=past, target=target)["poses"]
        if self.init_model is None or self.step_model is None:
            raise ValueError(f"transition: T={T} needs a rollout model of that length or init + step models")
        state = self.start(past, target)
        poses = []
        for _ in range(int(T)):
            pose, state = self.step(state)
            poses.append(pose)
        poses = np.stack(poses, axis=1)                                  # (B, T, P)
        join = self.step_model.metadata.get("join") or {}
        if join.get("mode", "none") == "none":
            return poses
        # the join option of the export, after the frames (the step model cannot know the last frame)
        if self.join_model is not None and self.join_model.metadata.get("model", {}).get("transition_length") == T:
            return self.join_model.run(past=past, poses=poses, target=target)["poses_joined"]
        n = int(join["blend_frames"]) if join.get("transition_length") == T else default_blend(int(T))
        joined = inertialize_joins(past, poses, target, dt=float(join["frame_time"]), blend_frames=n)
        return joined.astype(poses.dtype)


# ``python -m deploy``'s commands for this model (deploy/cli.py calls them through the exporter table); their
# code reads clips and options (deploy/models/qtg_cli.py, the command layer)

def add_export_options(group) -> None:
    """QTG's options of ``python -m deploy export`` (:func:`deploy.models.qtg_cli.add_export_options`)."""
    from deploy.models import qtg_cli

    qtg_cli.add_export_options(group)


def add_run_options(group) -> None:
    """QTG's options of ``python -m deploy run`` (:func:`deploy.models.qtg_cli.add_run_options`)."""
    from deploy.models import qtg_cli

    qtg_cli.add_run_options(group)


def export_checkpoint(entry, args) -> dict:
    """``python -m deploy export`` of a QTG checkpoint or state dict (:func:`deploy.models.qtg_cli.export_checkpoint`)."""
    from deploy.models import qtg_cli

    return qtg_cli.export_checkpoint(entry, args)


def run_command(runtime, args) -> int:
    """``python -m deploy run`` for QTG (:func:`deploy.models.qtg_cli.run_command`)."""
    from deploy.models import qtg_cli

    return qtg_cli.run_command(runtime, args)
