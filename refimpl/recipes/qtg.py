"""Recipe of QTG (Geleijn et al., IEEE VR 2021) on the ``transition`` task (spec/qtg.md §10, spec/architecture.md).

Everything the application layer needs to train, run and export QTG, and nothing else:

* :func:`make_config` — :class:`~refimpl.models.qtg.QTGConfig` from the training dataset (pose size, T) and
  ``--set FIELD=VALUE`` overrides;
* :func:`qtg_adapter` / :func:`make_adapter` — the trainer's :class:`~refimpl.train.ModelAdapter` (MAE on the
  normalised windows, the paper's loss); :func:`train_qtg` trains a :class:`~refimpl.protocols.transition.TransitionDataset`
  with the paper's optimiser (:data:`PAPER_OPTIM`);
* :func:`qtg_method` / :func:`make_method` — NumPy inference ``f(past, target, T)`` on un-normalised poses
  (:func:`refimpl.models.qtg_fast_inference.rollout_inference`);
* :data:`EXPORTER` — the key of QTG's exporter in ``deploy``'s table, and :func:`export_inputs`, what it needs
  (pose normalisation, frame rate, training metadata).

Shape legend: N windows, W window length (T + 4), T transition frames, P pose size, B batch.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.progress import stderr_line
from refimpl.options import config_with_overrides, parse_overrides  # noqa: F401 (re-exported)
from refimpl.losses import mae_loss_backward, mae_loss_forward
from refimpl.models.qtg import QTGConfig, init_params
from refimpl.models.qtg_fast import rollout_backward, rollout_forward
from refimpl.models.qtg_fast_inference import prepare_inference, rollout_inference
from refimpl.optim import QTG_ADAM
from refimpl.train import ModelAdapter, OptimConfig, StepInfo, TrainConfig, TrainResult, train
from refimpl.protocols.transition import denormalize_poses, join_pose, normalize_poses, pose_statistics, split_pose
from refimpl.protocols.transition_join import inertialize_joins

__all__ = ["NAME", "SUMMARY", "TASK", "REPRESENTATIONS", "CONFIG_TYPE", "EXPORTER", "PAPER_OPTIM", "PAPER_BATCH",
           "parse_overrides", "make_config", "qtg_adapter", "make_adapter", "train_qtg", "qtg_method",
           "make_method", "pose_normalization", "export_inputs", "reference_outputs"]

NAME = "qtg"
SUMMARY = "Quaternion Transition Generator (Geleijn et al., IEEE VR 2021): 2 past + 2 target poses -> T frames"
TASK = "transition"
#: Pose representations it trains on (``--representation``); the first is the default.
REPRESENTATIONS = ("quat",)
CONFIG_TYPE = QTGConfig
#: Key of the exporter in ``deploy.models.EXPORTERS``.
EXPORTER = "qtg"
#: The paper's optimiser (:data:`refimpl.optim.QTG_ADAM`: Adam, lr 1e-4, β = (0.5, 0.9)); no clipping, no decay.
PAPER_OPTIM = OptimConfig(**QTG_ADAM)
#: The paper's batch size.
PAPER_BATCH = 32


def make_config(train_ds, overrides: Sequence[str] = ()) -> QTGConfig:
    """The config for ``train_ds`` (its pose size P and transition length T) with ``--set`` overrides.

    Raises
    ------
    UsageError
        An unknown field, a bad value, or ``pose_size`` different from the data's.
    """
    pose_size, T = int(train_ds.poses.shape[-1]), int(train_ds.transition_length)
    base = QTGConfig(pose_size=pose_size, transition_length=T)
    return config_with_overrides(base, overrides, "pose_size", f"the data has poses of {pose_size} values")


def qtg_adapter(train_poses, config=None, dtype=np.float32, validation_poses=None, name: str = "qtg") -> ModelAdapter:
    """A :class:`~refimpl.train.ModelAdapter` for QTG on normalised windows (spec/qtg.md §10.2).

    Parameters
    ----------
    train_poses : ndarray (N, 2 + T + 2, P)
        NORMALISED windows (``TransitionDataset.normalized()``).
    config : QTGConfig, optional
    dtype : float32 or float64
        Training dtype (parameters and batches).
    validation_poses : ndarray (M, 2 + T + 2, P), optional
        Normalised windows; ``validate`` returns their MAE (``val_mae``).

    Notes
    -----
    Loss: ``mean |p_pred − p_gt|`` over the B·T·P values of the generated transition (MAE, paper), in the
    normalised pose space.
    """
    config = QTGConfig() if config is None else config
    poses = np.ascontiguousarray(train_poses, dtype=dtype)
    if poses.ndim != 3 or poses.shape[1] < 5 or poses.shape[2] != config.pose_size:
        raise ValueError(f"train_poses: expected shape (N, 2 + T + 2, {config.pose_size}), got {poses.shape}")
    T = poses.shape[1] - 4

    def get_batch(idx, ctx):
        return poses[idx]  # (B, W, P)

    def loss_and_grads(params, batch):
        pred, cache = rollout_forward(params, batch[:, :2], batch[:, -2:], T, config)
        loss, lcache = mae_loss_forward(pred, batch[:, 2:-2])
        return loss, rollout_backward(mae_loss_backward(1.0, lcache), cache)

    validate = None
    if validation_poses is not None:
        vposes = np.ascontiguousarray(validation_poses, dtype=dtype)

        def validate(params):
            total = 0.0
            for i in range(0, len(vposes), 512):
                b = vposes[i:i + 512]
                pred, _ = rollout_forward(params, b[:, :2], b[:, -2:], T, config)
                total += float(np.abs(pred - b[:, 2:-2]).astype(np.float64).sum())
            return {"val_mae": total / vposes[:, 2:-2].size}

    return ModelAdapter(name=name, num_examples=len(poses),
                        init_params=lambda rng: init_params(config, rng, dtype=dtype),
                        get_batch=get_batch, loss_and_grads=loss_and_grads, validate=validate,
                        config=dict(config.to_dict(), dtype=np.dtype(dtype).name, transition_length=T))


def _validation_poses(train_ds, val_ds):
    if val_ds is None or not val_ds.num_windows:
        return None
    return normalize_poses(val_ds.poses, train_ds.root_mean, train_ds.root_std)


def make_adapter(train_ds, val_ds, config: QTGConfig, dtype, extra: Mapping) -> ModelAdapter:
    """:func:`qtg_adapter` on ``train_ds``'s normalised windows, validated on ``val_ds`` (normalised with
    ``train_ds``'s statistics); ``extra`` goes into the checkpoint's model config."""
    adapter = qtg_adapter(train_ds.normalized(), config=config, dtype=dtype,
                          validation_poses=_validation_poses(train_ds, val_ds))
    return dataclasses.replace(adapter, config=dict(adapter.config, **extra))


def train_qtg(train_data, steps: int, *, config=None, optim: OptimConfig = PAPER_OPTIM, batch_size: int = PAPER_BATCH,
              seed: int = 0, dtype=np.float32, checkpoint_path: str | None = None, checkpoint_every: int = 1000,
              log_path: str | None = None, validation_data=None, validate_every: int | None = None,
              progress: Callable[[str], None] | None = stderr_line, resume: bool = True,
              callback: Callable[[StepInfo], None] | None = None) -> TrainResult:
    """Train QTG on a :class:`refimpl.protocols.transition.TransitionDataset` (paper: MAE, Adam 1e-4, β = (0.5, 0.9),
    batch 32).

    Parameters
    ----------
    train_data : TransitionDataset
        Its ``normalized()`` windows are the training examples.
    steps : int
    validation_data : TransitionDataset, optional
        Normalised with ``train_data``'s statistics; its MAE is logged every ``validate_every`` steps.
    Other parameters as :class:`~refimpl.train.TrainConfig` / :func:`~refimpl.train.train`.

    Returns
    -------
    TrainResult
    """
    adapter = qtg_adapter(train_data.normalized(), config=config, dtype=dtype,
                          validation_poses=_validation_poses(train_data, validation_data))
    tc = TrainConfig(steps=steps, batch_size=batch_size, seed=seed, checkpoint_path=checkpoint_path,
                     checkpoint_every=checkpoint_every, log_path=log_path, validate_every=validate_every)
    return train(adapter, optim, tc, resume=resume, callback=callback, progress=progress)


def qtg_method(params: Mapping[str, np.ndarray], config: QTGConfig, root_mean, root_std) -> Callable:
    """Wrap a trained QTG as ``f(past, target, T) -> poses`` in un-normalised pose space.

    ``f`` z-normalises the root translation of the inputs with ``root_mean``/``root_std`` (the training
    statistics), runs the network (:func:`refimpl.models.qtg_fast_inference.rollout_inference` in the parameters'
    dtype), de-normalises the output's root translation and normalises its joint quaternions to unit length.
    """
    from refimpl.protocols.transition_baselines import check_context, check_length

    model = prepare_inference(params, config)
    dtype = model.dtype
    mean = np.asarray(root_mean, dtype=np.float64)
    std = np.asarray(root_std, dtype=np.float64)

    def qtg(past, target, T):
        past, target = check_context(past, target)
        pn = normalize_poses(past.astype(np.float64), mean, std).astype(dtype)
        tn = normalize_poses(target.astype(np.float64), mean, std).astype(dtype)
        out = rollout_inference(model, pn, tn, check_length(T)).astype(np.float64)  # (B, T, P)
        root, quats = split_pose(denormalize_poses(out, mean, std))
        quats = quats / np.maximum(np.sqrt(np.sum(quats * quats, axis=-1, keepdims=True)), 1e-12)
        return join_pose(root, quats)

    return qtg


def make_method(model) -> Callable:
    """:func:`qtg_method` of a :class:`~refimpl.registry.TrainedModel`."""
    return qtg_method(model.params, model.config, model.fields["root_mean"], model.fields["root_std"])


def pose_normalization(model) -> tuple[np.ndarray, np.ndarray]:
    """``(mean (P,), std (P,))`` of a trained model's whole pose vector: its root statistics (the transition
    task's ``fields``), then 0 / 1 for the quaternions (:func:`refimpl.protocols.transition.pose_statistics`)."""
    return pose_statistics(model.fields["root_mean"], model.fields["root_std"], model.config.pose_size)


def export_inputs(model) -> dict:
    """Keyword arguments of QTG's exporter (``deploy.models.qtg.export_dir``) for a trained model: the pose
    normalisation (in the graphs) and the metadata (frame rate, training statistics, checkpoint step)."""
    meta = {"frame_rate": float(model.fps),
            "training": {"checkpoint_step": model.meta.get("step"),
                         "root_mean": [float(v) for v in model.fields["root_mean"]],
                         "root_std": [float(v) for v in model.fields["root_std"]]}}
    return {"normalization": pose_normalization(model), "metadata": meta, "T": model.fields["transition_length"]}


def reference_outputs(model, past, target, T: int) -> np.ndarray:
    """The NumPy outputs an exported QTG must reproduce: raw (de-standardised) poses ``(B, T, P)`` from
    :func:`refimpl.models.qtg_fast.rollout_forward` in the parameters' dtype, before any quaternion
    normalisation (``refimpl export``'s check, :func:`refimpl.services.verify_onnx`)."""
    dtype = next(iter(model.params.values())).dtype
    mean, std = model.fields["root_mean"], model.fields["root_std"]
    pn = normalize_poses(np.asarray(past, np.float64), mean, std).astype(dtype)
    tn = normalize_poses(np.asarray(target, np.float64), mean, std).astype(dtype)
    ref, _ = rollout_forward(model.params, pn, tn, T, model.config)
    return denormalize_poses(ref.astype(np.float64), mean, std)  # (B, T, P)


#: Tolerance of :func:`verify_onnx` (``refimpl export``'s check), in normalised units (``atol`` times the pose std).
#: :data:`refimpl.testing.TOL_ORT_ROLLOUT` (atol 1e-4) holds for the tests' small random networks, but a trained
#: network amplifies float32 rounding over 30 recurrent frames: on the README's 6000-step model, 8 random contexts
#: per seed, NumPy float32 is up to 2.3e-4 and onnxruntime float32 up to 5.6e-4 (normalised units) away from NumPy
#: float64, and the two float32 paths up to 7.8e-4 apart; atol 2e-3 (0.03-0.09 cm of root for a 13-45 cm std)
#: still catches any real translation error (a wrong statistic or weight moves poses by centimetres).
VERIFY_TOL = dict(rtol=1e-3, atol=2e-3)


def verify_onnx(model, runtime, past, target, T: int | None = None) -> dict:
    """Compare an exported QTG's onnxruntime outputs with :func:`reference_outputs` on raw context poses
    ``past, target (B, 2, P)``: the ``rollout`` model and the ``init`` + ``step`` loop.

    Models exported with the join option (metadata ``join``) are compared with
    :func:`refimpl.protocols.transition_join.inertialize_joins` of the reference outputs.

    Returns
    -------
    dict ``{"rollout": max |Δ|, "step_loop": max |Δ|, "ok": bool}``; ``ok`` against
    :data:`VERIFY_TOL` in the network's (normalised) units: ``|Δ| <= atol · std + rtol · |ref|`` with ``std`` the
    pose statistics (root: the training std in cm; quaternions: 1).
    """
    T = int(T or model.fields["transition_length"])
    std = np.asarray(pose_normalization(model)[1], dtype=np.float64)  # (P,)
    ref = reference_outputs(model, past, target, T)  # (B, T, P)
    join = (runtime.rollout_model or runtime.step_model).metadata.get("join") or {}
    if join.get("mode", "none") != "none":  # exported with the join option: NumPy's join after the network
        n = int(join["blend_frames"]) if join.get("transition_length") == T else None
        ref = inertialize_joins(past, ref, target, dt=float(join["frame_time"]), blend_frames=n)
    out = {}
    ok = True
    for key, use_rollout in (("rollout", True), ("step_loop", False)):
        if (use_rollout and runtime.rollout_model is None) or (not use_rollout and runtime.step_model is None):
            continue
        got = np.asarray(runtime.transition(np.asarray(past, np.float32), np.asarray(target, np.float32), T,
                                            use_rollout=use_rollout), dtype=np.float64)
        diff = np.abs(got - ref)
        out[key] = float(diff.max())
        ok &= bool(np.all(diff <= VERIFY_TOL["atol"] * std + VERIFY_TOL["rtol"] * np.abs(ref)))
    out["ok"] = ok
    return out
