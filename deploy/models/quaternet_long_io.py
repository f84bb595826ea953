"""QuaterNet long-term's entry of the exporter table (``deploy.models.EXPORTERS["quaternet-long"]``; protocol
:class:`deploy.models.entry_api.ExporterEntry`): the pose
network's step and the pace network (spec/deploy.md §12).

* :func:`load_checkpoint` — ``(params, config, meta)`` of a ``refimpl train`` checkpoint of ``quaternet-long``
  (config: :class:`~refimpl.models.quaternet.QuaterNetConfig`) or ``pace`` (:class:`~refimpl.models.pace.PaceConfig`);
* :func:`export_dir` — ``quaternet-long_step.onnx`` (+ ``quaternet-long_h0.npy``, the learned initial state, and
  ``quaternet-long_seed.npy``, the checkpoint's seed clip that starts a walk) for a pose network,
  ``quaternet-long_pace.onnx`` for a pace network (validated, atomic);
* :class:`Runtime` — ``step(x, state)`` and ``pace(x)`` in onnxruntime, a ``rollout`` for evaluation, and the
  seed clip (``seed``);
* :func:`run_command`, :func:`add_run_options` — ``python -m deploy run`` (a walk along a path,
  :mod:`deploy.models.quaternet_long_walk`, or ``.npy`` frames).

Shape legend: B batch, F input features, G outputs, L layers, H hidden, N points, P prefix, T frames.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from refimpl.bounds import MAX_CONFIG_SIZE
from refimpl.checkpoint_schema import validate_task_schema
from refimpl.models import pace
from refimpl.models.quaternet import QuaterNetConfig
from refimpl.protocols.locomotion_data import CHECKPOINT_SCHEMA

from deploy.graph import save_model
from deploy.models.arguments import count, frames_array
from deploy.models.entry_io import (checked_params, checkpoint_params, config_from_meta, read_checkpoint,
                                    write_npy as _write_npy)
from deploy.models.quaternet_long import NAME, PACE_CHUNK, export_pace, export_pace_step, export_pose_step
from deploy.portable import builder_options, check_target, portable_model
from deploy.runtime import DeployedModel, load_model
from deploy.validate import validate_model

__all__ = ["load_checkpoint", "export_dir", "Runtime", "run_command", "add_run_options", "STEP_FILE", "PACE_FILE",
           "H0_FILE", "SEED_FILE", "PACE_STEP_FILE", "PACE_H0_FILE"]

STEP_FILE = f"{NAME}_step.onnx"
PACE_FILE = f"{NAME}_pace.onnx"
PACE_STEP_FILE = f"{NAME}_pace_step.onnx"
PACE_H0_FILE = f"{NAME}_pace_h0.npy"
H0_FILE = f"{NAME}_h0.npy"
SEED_FILE = f"{NAME}_seed.npy"


def load_checkpoint(path):
    """``(params, config, meta)``: a ``quaternet-long`` checkpoint gives its ``QuaterNetConfig`` (long-term), a
    ``pace`` checkpoint its ``PaceConfig``."""
    arrays, meta = read_checkpoint(path)
    params = checkpoint_params(arrays)
    where = str(path)
    if meta.get("model") == "pace":
        config = config_from_meta(pace.PaceConfig, meta, schema=CHECKPOINT_SCHEMA, where=where)
        return checked_params(params, config, where), config, meta
    if meta.get("model") != NAME:
        raise ValueError(f"{path}: expected a quaternet-long or pace checkpoint, got model {meta.get('model')!r}")
    cfg = meta.get("model_config")
    fields = {"num_joints": int, "hidden_size": int, "num_layers": int, "controls_hidden": int,
              "negative_slope": float}
    if not isinstance(cfg, dict) or any(k not in cfg for k in fields):
        raise ValueError(f"{where}: model_config: expected an object with {sorted(fields)}")
    values = {k: _config_number(cfg[k], t, f"{where}: model_config.{k}") for k, t in fields.items()}
    if cfg.get("output", "quaternion") not in ("quaternion", "dual_quaternion"):
        raise ValueError(f"{where}: model_config.output: expected 'quaternion' or 'dual_quaternion' for export, got "
                         f"{cfg.get('output')!r}")
    try:
        net = QuaterNetConfig.long_term(**values, representation="dual_quaternion"
                                        if cfg.get("output") == "dual_quaternion" else "quaternion")
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: model_config: {exc}") from None
    validate_task_schema(CHECKPOINT_SCHEMA, cfg, net, where)
    return checked_params(params, net, where), net, meta


def _config_number(value, kind, name):
    """One config number of a long-term checkpoint: an int (not bool) within ``±MAX_CONFIG_SIZE`` or a finite
    float; ``ValueError`` naming ``name``."""
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int) or abs(value) > MAX_CONFIG_SIZE:
            raise ValueError(f"{name}: expected an integer within {MAX_CONFIG_SIZE}, got {value!r:.40}")
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise ValueError(f"{name}: expected a finite number, got {value!r:.40}")
    return float(value)


def _network(config):
    """The recipe's config → the network's (``QuaterNetLongConfig.network()``), others unchanged."""
    return config.network() if hasattr(config, "network") else config


def export_dir(params, config, out_dir, *, dtype=np.float32, metadata=None, skeleton=None, seed_clip=None,
               target: str = "default", **_ignored) -> dict[str, Path]:
    """Export, validate and write the model(s) of ``config`` into ``out_dir``; returns role -> path.

    A pose network writes ``step`` (and its ``h0`` as ``.npy``; with ``seed_clip``, the checkpoint's
    ``{"name", "rotations" (P, J, 4), "features" (P, 8)}``, the frames ``(P, 4J + 8)`` as ``seed``), a pace
    network ``pace``. Options of other exporters (``mode``, ``T``) are ignored. ``target="portable"``
    (``deploy/portable.py``): the same step at batch 1 in primitive operators, and for a pace network
    ``pace_step`` (K points of both directions per call, :func:`deploy.models.quaternet_long.export_pace_step`) with its
    initial states ``pace_h0`` (``.npy``) instead of ``pace``; the host loops in the metadata.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    config = _network(config)
    portable = check_target(target) == "portable"
    kw = builder_options() if portable else {"dtype": dtype}
    dtype = kw["dtype"]
    if isinstance(config, pace.PaceConfig) and portable:
        m = portable_model(export_pace_step(params, config, metadata=metadata, h0_file=PACE_H0_FILE, **kw),
                           host_loop=pace_portable_loop(config, PACE_CHUNK))
        save_model(validate_model(m), out / PACE_STEP_FILE)
        _write_npy(out / PACE_H0_FILE, np.asarray(params["h0"], dtype=dtype).reshape(2, 1, -1))
        return {"pace_step": out / PACE_STEP_FILE, "pace_h0": out / PACE_H0_FILE}
    if isinstance(config, pace.PaceConfig):
        m = validate_model(export_pace(params, config, dtype=dtype, metadata=metadata))
        save_model(m, out / PACE_FILE)
        return {"pace": out / PACE_FILE}
    seed = None if seed_clip is None else _seed_frames(seed_clip, config.num_joints)
    if seed is not None:
        metadata = {**dict(metadata or {}), "seed_clip": {
            "file": SEED_FILE, "shape": list(seed.shape), "dtype": np.dtype(dtype).name, "format": "NumPy .npy (no "
            "pickle)", "name": str(seed_clip.get("name", "")),
            "meaning": "the training clip that starts a walk: P frames [rotations 4J (local quaternions, the "
                       "root's absolute about +y) | offset, height | 6 controls] in the quaternion layout (a "
                       "dual-quaternion step takes them as current DQs); turn it about +y to the path's facing "
                       "and feed it through step"}}
    m = export_pose_step(params, config, **kw, metadata=metadata, skeleton=skeleton, h0_file=H0_FILE)
    if portable:
        m = portable_model(m, host_loop=step_portable_loop(config, seed is not None))
    save_model(validate_model(m), out / STEP_FILE)
    paths = {"step": out / STEP_FILE, "h0": out / H0_FILE}
    _write_npy(out / H0_FILE, np.asarray(params["h0"], dtype=dtype))
    if seed is not None:
        paths["seed"] = out / SEED_FILE
        _write_npy(paths["seed"], seed.astype(dtype))
    return paths


def step_portable_loop(config, seed: bool) -> dict:
    """The host loop of the portable long-term step graph (``metadata["target"]["host_loop"]``)."""
    L, H = int(config.num_layers), int(config.hidden_size)
    return {"summary": "one step per frame with the carried GRU state: the seed clip's frames, then [y | the next "
                       "frame's controls]; python -m deploy run drives a walk along a path this way",
            "graphs": [STEP_FILE],
            "state": [{"input": "state", "output": "state_next", "shape": [L, 1, H], "initial": f"the file {H0_FILE}"}],
            "loop": ["state = load(initial_state.file)   # (L, 1, H)",
                     "for t in 0 .. P-1: y, state = step(x=frames[t], state=state)   # "
                     + (f"frames: {SEED_FILE} (seed_clip) to start a walk" if seed else "the seed frames"),
                     "each next frame: y, state = step(x=concat(y, controls of the frame), state=state)"]}


def pace_portable_loop(config, points: int) -> dict:
    """The host loop of the portable pace graph: both GRU directions, ``points`` path points per call."""
    H, K = int(config.hidden_size), int(points)
    return {"summary": f"a path of N points in ceil(N / {K}) calls: the forward direction reads the path, the "
                       "backward direction the reversed path, each zero-padded at its end to a multiple of "
                       f"{K}; the output of point n is y_forward[n] + y_backward[N-1-n] over the concatenated calls",
            "graphs": [PACE_STEP_FILE],
            "state": [{"input": "h_forward", "output": "h_forward_next", "shape": [1, 1, H],
                       "initial": f"{PACE_H0_FILE}[0:1]"},
                      {"input": "h_backward", "output": "h_backward_next", "shape": [1, 1, H],
                       "initial": f"{PACE_H0_FILE}[1:2]"}],
            "loop": [f"h0 = load({PACE_H0_FILE}); h_forward, h_backward = h0[0:1], h0[1:2]",
                     f"C = ceil(N / {K}); xf = pad(x, C*{K}); xb = pad(x[::-1], C*{K})   # zeros at the end",
                     f"for c in 0 .. C-1: out = pace_step(x_forward=xf[c*{K}:(c+1)*{K}], h_forward=h_forward, "
                     f"x_backward=xb[c*{K}:(c+1)*{K}], h_backward=h_backward); yf += out.y_forward; "
                     "yb += out.y_backward; h_forward, h_backward = out.h_forward_next, out.h_backward_next",
                     "y[n] = yf[n] + yb[N-1-n] for n in 0 .. N-1   # (N, 4), then output_transform"]}


def _seed_frames(seed_clip, J: int) -> np.ndarray:
    """The checkpoint's seed clip as frames ``(P, 4J + 8)``; ``ValueError`` for another shape or non-finite
    values."""
    try:
        rot = np.asarray(seed_clip["rotations"], np.float64)
        feats = np.asarray(seed_clip["features"], np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"seed_clip: expected rotations and features arrays ({type(exc).__name__})") from None
    if rot.ndim != 3 or rot.shape[1:] != (J, 4) or feats.shape != (rot.shape[0], 8) or rot.shape[0] < 1 or \
            not (np.all(np.isfinite(rot)) and np.all(np.isfinite(feats))):
        raise ValueError(f"seed_clip: expected finite rotations (P, {J}, 4) and features (P, 8), got "
                         f"{rot.shape}, {feats.shape}")
    return np.concatenate([rot.reshape(len(rot), 4 * J), feats], axis=1)


def _read_array(path, ndim: int, what: str, ok=lambda a: True) -> np.ndarray:
    """A finite float ``.npy`` array of rank ``ndim`` beside the models (``ok(a)`` further checks the shape); a
    damaged or pickled file is refused with ``ValueError`` naming it and ``what`` was expected."""
    from refimpl.npy_files import read_npy

    try:
        a = read_npy(path)  # a regular file; the declared shape checked against its size before allocating
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: not a readable .npy array ({exc})") from None
    if not isinstance(a, np.ndarray) or a.dtype.kind != "f" or a.ndim != ndim or 0 in a.shape or not ok(a) or \
            not np.all(np.isfinite(a)):
        raise ValueError(f"{path}: expected a finite float array {what}, got {getattr(a, 'dtype', '?')} "
                         f"{getattr(a, 'shape', '?')}")
    return a


def _read_h0(path) -> np.ndarray:
    """The learned initial state ``(L, 1, H)`` beside a step model."""
    return _read_array(path, 3, "(L, 1, H)", lambda a: a.shape[1] == 1)


def _read_seed(path) -> np.ndarray:
    """The seed clip ``(P, 4J + 8)`` beside a step model."""
    return _read_array(path, 2, "(P, 4J + 8)", lambda a: a.shape[1] >= 12 and (a.shape[1] - 8) % 4 == 0)


class Runtime:
    """The exported long-term models in onnxruntime (any of ``step`` and ``pace``)."""

    def __init__(self, step=None, pace_model=None, h0=None, seed=None, *, pace_step=None, pace_h0=None,
                 intra_op_threads: int = 1):
        def load(m):
            return m if m is None or isinstance(m, DeployedModel) else load_model(m, intra_op_threads=intra_op_threads)

        self.step_model, self.pace_model = load(step), load(pace_model)
        #: the portable pace graph (K points of both directions per call) and its initial states (2, 1, H), or None
        self.pace_step_model = load(pace_step)
        self.pace_h0 = None if pace_h0 is None else np.asarray(pace_h0)
        if self.pace_step_model is not None and self.pace_h0 is None:
            raise ValueError(f"pace_step: the portable pace graph needs its initial states ({PACE_H0_FILE})")
        self.h0 = None if h0 is None else np.asarray(h0)
        #: the checkpoint's seed clip (P, 4J + 8) that starts a walk, or None (exported before it was written)
        self.seed = None if seed is None else np.asarray(seed)
        # the `refimpl export` check compares against these
        self.rollout_model = None

    @classmethod
    def from_dir(cls, directory, *, intra_op_threads: int = 1) -> "Runtime":
        d = Path(directory)
        step, pm, h0, seed = d / STEP_FILE, d / PACE_FILE, d / H0_FILE, d / SEED_FILE
        ps, ps_h0 = d / PACE_STEP_FILE, d / PACE_H0_FILE
        if not step.is_file() and not pm.is_file() and not ps.is_file():
            raise ValueError(f"directory: no {STEP_FILE}, {PACE_FILE} or {PACE_STEP_FILE} in {str(d)!r}")
        return cls(step if step.is_file() else None, pm if pm.is_file() else None,
                   _read_h0(h0) if h0.is_file() else None, _read_seed(seed) if seed.is_file() else None,
                   pace_step=ps if ps.is_file() else None,
                   pace_h0=_read_array(ps_h0, 3, "(2, 1, H)", lambda a: a.shape[:2] == (2, 1))
                   if ps.is_file() and ps_h0.is_file() else None, intra_op_threads=intra_op_threads)

    @property
    def pace_graph(self):
        """The loaded pace model: ``pace`` (today's target) or ``pace_step`` (portable), or None."""
        return self.pace_model if self.pace_model is not None else self.pace_step_model

    def initial_state(self, batch: int) -> np.ndarray:
        """``h0`` repeated: ``(L, B, H)``."""
        batch = count(batch, "batch", "batch")
        if self.h0 is None:
            raise ValueError("initial_state: no h0 file beside the step model")
        return np.repeat(self.h0, batch, axis=1)

    def step(self, x, state=None):
        """One frame: ``(y (B, G), state_next (L, B, H))``; ``state`` None = the learned initial state."""
        if self.step_model is None:
            raise ValueError("step: no step model loaded")
        x = frames_array(x, "x", ranks=(2,))
        state = self.initial_state(x.shape[0]) if state is None else state
        out = self.step_model.run(x=x, state=state)
        return out["y"], out["state_next"]

    def pace(self, x) -> np.ndarray:
        """Raw pace outputs ``(B, N, 4)`` for ``x (B, N, 2)``."""
        x = frames_array(x, "x", ranks=(3,))
        if self.pace_model is None and self.pace_step_model is not None:
            return np.stack([self._pace_steps(xb) for xb in x])                  # the portable host loop
        if self.pace_model is None:
            raise ValueError("pace: no pace model loaded")
        return self.pace_model.run(x=x)["y"]

    def _pace_steps(self, x: np.ndarray) -> np.ndarray:
        """The portable pace graph's host loop (``pace_portable_loop``) on one path ``x (N, 2)`` → ``(N, 4)``."""
        N, K = len(x), int(self.pace_step_model.metadata["points_per_call"])
        C = -(-N // K)
        pad = np.zeros((C * K - N, x.shape[1]), np.float32)
        xf, xb = np.concatenate([x, pad]), np.concatenate([x[::-1], pad])
        hf, hb = self.pace_h0[0:1], self.pace_h0[1:2]
        yf, yb = [], []
        for c in range(C):
            out = self.pace_step_model.run(x_forward=xf[None, c * K:(c + 1) * K], h_forward=hf,
                                           x_backward=xb[None, c * K:(c + 1) * K], h_backward=hb)
            yf.append(out["y_forward"][0])
            yb.append(out["y_backward"][0])
            hf, hb = out["h_forward_next"], out["h_backward_next"]
        return np.concatenate(yf)[:N] + np.concatenate(yb)[:N][::-1]

    def rollout(self, inputs, prefix: int):
        """Free-running prediction with the ground-truth controls (the task's method interface):
        ``inputs (B, P + T, F)`` → ``rotations (B, T, J, 4)``, ``translations (B, T, 2)``."""
        x = frames_array(inputs, "inputs", ranks=(3,))
        prefix = count(prefix, "prefix")
        if self.step_model is None:
            raise ValueError("rollout: no step model loaded")
        B, Ltot, F = x.shape
        if not prefix < Ltot:
            raise ValueError(f"prefix: expected fewer than the {Ltot} frames of inputs, got {prefix}")
        if F < 12 or (F - 8) % 4:
            raise ValueError(f"inputs: expected F = 4 J + 8 features per frame, got {F}")
        if (self.step_model.metadata.get("representation") or {}).get("kind") == "quaternet_long_dq":
            raise ValueError("rollout: a dual-quaternion step model takes current-DQ frames; evaluate it in NumPy "
                             "(refimpl eval --checkpoint)")
        G = F - 6
        J = (G - 2) // 4
        h = None
        for t in range(prefix):
            y, h = self.step(x[:, t], h)
        ys = [y]
        for t in range(prefix, Ltot - 1):
            y, h = self.step(np.concatenate([y, x[:, t, G:]], axis=1), h)
            ys.append(y)
        y = np.stack(ys, axis=1)
        return y[..., :4 * J].reshape(B, -1, J, 4), y[..., 4 * J:]


def add_run_options(group) -> None:
    """quaternet-long's options of ``python -m deploy run`` (a walk; ``refimpl generate``'s names)."""
    group.add_argument("--pace", default=None, metavar="DIR", help="quaternet-long: folder of the exported pace "
                                                                    "network (default: MODEL_DIR)")
    group.add_argument("--speed", default=None, help="quaternet-long: walk, jog, run or units per frame "
                                                     "(default walk)")
    group.add_argument("--seconds", default=None, help="quaternet-long: length of the walk (default 10)")
    group.add_argument("--controls", default=None, help="quaternet-long: also write the per-frame controls as JSON")


def run_command(runtime, args) -> int:
    """``python -m deploy run`` for QuaterNet long-term (:func:`deploy.models.run_commands.run_locomotion`)."""
    from deploy.models.run_commands import run_locomotion

    return run_locomotion(runtime, args)
