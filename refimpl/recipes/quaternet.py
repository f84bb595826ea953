"""Recipe of the recurrent QuaterNet short-term model (Pavllo et al., IJCV 2019, §3.3-3.6, §4.1) on the
``prediction`` task (spec/quaternet.md §7, spec/architecture.md).

Everything the application layer needs to train, run and export it:

* :class:`ShortTermConfig` — the network's sizes (:class:`~refimpl.models.quaternet.QuaterNetConfig` fields) and
  the training settings (prefix, target, schedule, loss, penalty), one flat dataclass so that ``--set
  FIELD=VALUE`` reaches every field (``--set velocity=false`` = the absolute-rotation model, ``--set
  schedule=teacher_forcing`` = the "vel. TF" variant with the ``1 − p·q`` loss);
* :func:`make_adapter` — the trainer's :class:`~refimpl.train.ModelAdapter`: the published short-term batches
  (one random window of ``prefix + target`` frames per training sequence per epoch; every random number from the
  trainer's Generator, so resuming is bit-for-bit), scheduled sampling with one Bernoulli draw per time step
  shared by the batch and ratio ``0.995^epoch``, the wrapped-Euler L1 loss plus ``0.01 ×`` the norm penalty;
* :func:`make_method` — NumPy inference in the task's method interface ``f(prefix (B, P, J, 4), k)``;
* ``--set representation=dual_quaternion`` — QuaterNet with dual quaternions (Andreou et al. §6.2, Table 2;
  spec/quaternet.md §9): the frames are current dual quaternions (:func:`refimpl.dq_prediction.
  dq_frames_from_rotations`), the predictions are decoded to local quaternions (Eq. 12) for the same loss and
  the same error, and the penalty is L_reg (Eq. 16) on the raw head output
  (:func:`refimpl.dq_prediction.dq_rotation_loss_forward`);
* :data:`EXPORTER`, :func:`export_inputs`, :func:`reference_outputs`, :func:`verify_onnx` — ONNX export.

The paper's settings are the named constants below and the defaults of :class:`ShortTermConfig`.

Shape legend: B batch, P prefix frames, T target frames, K predicted frames, J joints.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.losses import (QUATERNET_PENALTY_WEIGHT, euler_l1_loss_backward, euler_l1_loss_forward,
                            quat_loss_backward, quat_loss_forward, quat_norm_loss_backward, quat_norm_loss_forward)
from refimpl.dq_prediction import (dq_frames_from_rotations, dq_rotation_loss_backward, dq_rotation_loss_forward,
                                   rotations_from_dq_frames)
from refimpl.models import quaternet as net
from refimpl.models import quaternet_sequence
from refimpl.optim import QUATERNET_ADAM, QUATERNET_CLIP_NORM, QUATERNET_LR_DECAY
from refimpl.options import config_with_overrides
from refimpl.schedules import QUATERNET_TF_DECAY, scheduled_sampling_mask, teacher_forcing_ratio
from refimpl.train import ModelAdapter, OptimConfig

__all__ = ["published_names", "param_shapes", "NAME", "SUMMARY", "TASK", "REPRESENTATIONS", "CONFIG_TYPE", "EXPORTER", "PAPER_OPTIM",
           "PAPER_BATCH",
           "PAPER_PREFIX", "PAPER_TARGET", "PAPER_EPOCHS", "SCHEDULES", "LOSSES", "ShortTermConfig", "make_config",
           "make_adapter", "loss_terms", "resolve_loss", "teacher_forcing_mask", "network_method", "raw_outputs", "predictor",
           "make_method", "export_inputs", "reference_outputs", "verify_onnx", "dq_loss_terms", "dq_network_method",
           "network_frames"]

NAME = "quaternet"
SUMMARY = ("QuaterNet recurrent pose network (Pavllo et al., IJCV 2019), short-term: 50-frame prefix -> "
           "next frames; velocity (default) or absolute mode")
TASK = "prediction"
REPRESENTATIONS = ("quat",)
EXPORTER = "quaternet"
#: Adam lr 1e-3, default betas, clipping 0.1, lr × 0.999 per epoch (reference §5.1).
PAPER_OPTIM = OptimConfig(**QUATERNET_ADAM, clip_norm=QUATERNET_CLIP_NORM, lr_decay=QUATERNET_LR_DECAY)
#: The published short-term batch size.
PAPER_BATCH = 60
#: Prefix and target of a training window (2 s and 400 ms at 25 Hz).
PAPER_PREFIX = 50
PAPER_TARGET = 10
#: The published number of epochs (one window per training sequence each; H3.6M: 6 batches per epoch).
PAPER_EPOCHS = 3000
#: ``scheduled``: teacher-forcing ratio ``0.995^epoch``, one draw per step shared by the batch (paper);
#: ``teacher_forcing``: always the ground truth ("vel. TF"); ``free``: always the model's own output.
SCHEDULES = ("scheduled", "teacher_forcing", "free")
#: ``euler``: L1 of the zyx Euler angles, best match modulo 2π (short-term); ``quat``: ``mean |1 − p·q|``
#: (the teacher-forced variants); ``auto``: ``quat`` for ``teacher_forcing``, else ``euler``.
LOSSES = ("auto", "euler", "quat")


@dataclasses.dataclass(frozen=True)
class ShortTermConfig:
    """Network sizes and training settings of the short-term recipe (defaults: the paper's).

    Attributes
    ----------
    num_joints, velocity, hidden_size, num_layers
        As :class:`~refimpl.models.quaternet.QuaterNetConfig` (no translations, no controls).
    prefix_length, target_length : int
        P and T of a training window (50, 10).
    schedule : str
        One of :data:`SCHEDULES`.
    tf_decay : float
        Teacher-forcing ratio decay per epoch (0.995).
    loss : str
        One of :data:`LOSSES`.
    penalty_weight : float
        Weight of the quaternion norm penalty (0.01); with dual quaternions, of L_reg (Eq. 16; 0.01, Appendix B).
    representation : str
        ``"quaternion"`` (QuaterNet) or ``"dual_quaternion"`` (current dual quaternions, spec/quaternet.md §9).
    """

    num_joints: int = 32
    velocity: bool = True
    hidden_size: int = 1000
    num_layers: int = 2
    prefix_length: int = PAPER_PREFIX
    target_length: int = PAPER_TARGET
    schedule: str = "scheduled"
    tf_decay: float = QUATERNET_TF_DECAY
    loss: str = "auto"
    penalty_weight: float = QUATERNET_PENALTY_WEIGHT
    representation: str = "quaternion"

    def __post_init__(self):
        if self.representation == "quat":  # checkpoints older than the field store the registry's name here
            object.__setattr__(self, "representation", "quaternion")
        self.network  # validates the network fields
        for name in ("prefix_length", "target_length"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"{name}: expected a positive integer, got {v!r}")
        if self.schedule not in SCHEDULES:
            raise ValueError(f"schedule: expected one of {SCHEDULES}, got {self.schedule!r}")
        if self.loss not in LOSSES:
            raise ValueError(f"loss: expected one of {LOSSES}, got {self.loss!r}")
        if not 0.0 <= float(self.tf_decay) <= 1.0:
            raise ValueError(f"tf_decay: expected a value in [0, 1], got {self.tf_decay}")
        if not (np.isfinite(self.penalty_weight) and self.penalty_weight >= 0):
            raise ValueError(f"penalty_weight: expected a finite value >= 0, got {self.penalty_weight}")

    @property
    def network(self) -> net.QuaterNetConfig:
        """The :class:`~refimpl.models.quaternet.QuaterNetConfig` of these sizes."""
        return net.QuaterNetConfig(num_joints=self.num_joints, velocity=self.velocity,
                                   hidden_size=self.hidden_size, num_layers=self.num_layers,
                                   representation=self.representation)

    @property
    def dual(self) -> bool:
        """True for ``representation="dual_quaternion"``."""
        return self.representation == "dual_quaternion"

    @property
    def loss_kind(self) -> str:
        """``euler`` or ``quat`` (``auto`` resolved by :func:`resolve_loss`)."""
        return resolve_loss(self.loss, self.schedule)

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


CONFIG_TYPE = ShortTermConfig


def resolve_loss(loss: str, schedule: str) -> str:
    """The loss of a short-term config: ``loss`` unless ``"auto"``, which is ``"quat"`` under pure teacher forcing
    and ``"euler"`` under scheduled sampling (the recurrent and the convolutional recipe alike)."""
    if loss != "auto":
        return loss
    return "quat" if schedule == "teacher_forcing" else "euler"


def param_shapes(config) -> dict:
    """Name -> shape of every parameter of the network ``config`` describes (the checkpoint schema's reference,
    spec/robustness.md §9): the model module's ``param_shapes`` of ``config.network``."""
    return net.param_shapes(config.network)


def published_names(config) -> dict:
    """Our parameter name -> (published name, shape): the published short-term state dict's names
    (:func:`refimpl.models.quaternet.published_names` of ``config.network``; the identity)."""
    return net.published_names(config.network)


def make_config(train_ds, overrides: Sequence[str] = (), config_type=ShortTermConfig):
    """The config for ``train_ds`` (its joint count) with ``--set`` overrides.

    Raises
    ------
    UsageError
        An unknown field, a bad value, or ``num_joints`` different from the data's.
    """
    J = int(train_ds.skeleton.num_joints)
    base = config_type(num_joints=J)
    return config_with_overrides(base, overrides, "num_joints", f"the data has {J} joints")


def teacher_forcing_mask(config, epoch: int, rng: np.random.Generator) -> np.ndarray:
    """The ``T − 1`` feeding decisions of a batch (True = ground truth): :data:`SCHEDULES`."""
    steps = config.target_length - 1
    if config.schedule == "teacher_forcing":
        return np.ones(steps, dtype=bool)
    if config.schedule == "free":
        return np.zeros(steps, dtype=bool)
    return scheduled_sampling_mask(teacher_forcing_ratio(epoch, 1.0, config.tf_decay), steps, rng)


def loss_terms(y, pre, target, config):
    """Training loss of predictions ``y (B, T, 4J)`` (unit quaternions) with raw head outputs ``pre (B, T, 4J)``
    against target quaternions ``(B, T, J, 4)``: ``L + w · mean((‖pre‖² − 1)²)`` with ``L`` the wrapped-Euler L1
    (zyx, all joints, :func:`refimpl.losses.euler_l1_loss_forward`) or ``mean |1 − p·q|``.

    Returns
    -------
    loss : float
        The main loss (the published log excludes the penalty).
    total : float
    dy, dpre : ndarray (B, T, 4J)
        Gradients of ``total``.
    """
    B, T = y.shape[:2]
    J = config.num_joints
    q = y.reshape(B, T, J, 4)
    if config.loss_kind == "euler":
        value, c = euler_l1_loss_forward(q, target)
        dq = euler_l1_loss_backward(1.0, c)
    else:
        value, c = quat_loss_forward(q, target)
        dq = quat_loss_backward(1.0, c)
    pen, pc = quat_norm_loss_forward(pre.reshape(B, T, J, 4))
    dpre = (config.penalty_weight * quat_norm_loss_backward(1.0, pc)).reshape(B, T, 4 * J)
    return (float(value), float(value) + config.penalty_weight * float(pen),
            np.asarray(dq, dtype=y.dtype).reshape(B, T, 4 * J), dpre.astype(y.dtype, copy=False))


def dq_loss_terms(y, pre, target, config, parents):
    """:func:`loss_terms` of the dual-quaternion network: predictions ``y (B, T, 8J)`` (unit current DQs) and raw
    head outputs ``pre (B, T, 8J)`` against target local quaternions ``(B, T, J, 4)``: the same main loss on the
    decoded local rotations (Eq. 12) plus ``w · L_reg(pre)`` (Eq. 16;
    :func:`refimpl.dq_prediction.dq_rotation_loss_forward`).

    Returns
    -------
    loss, total : float
    dy, dpre : ndarray (B, T, 8J)
    """
    B, T = y.shape[:2]
    J = config.num_joints
    total, parts, c = dq_rotation_loss_forward(y.reshape(B, T, J, 8), pre.reshape(B, T, J, 8), target, parents,
                                               kind=config.loss_kind, reg_weight=config.penalty_weight)
    dy, dpre = dq_rotation_loss_backward(1.0, c)
    return parts["rot"], total, dy.reshape(B, T, 8 * J), dpre.reshape(B, T, 8 * J)


def _dq_tracks(data, skeleton) -> list:
    """Current-DQ frames ``(T_s, J, 8)`` of every training sequence (continuous over each whole sequence)."""
    return [dq_frames_from_rotations(s.rotations, skeleton) for s in data.train]


class _RecurrentTraining:
    """The recurrent network's training interface (``forward(params, prefix, future, mask, config)``,
    ``backward(dy, dpre, cache)``, ``init_params``): :mod:`refimpl.models.quaternet_sequence` and
    :func:`refimpl.models.quaternet.init_params`."""

    forward = staticmethod(quaternet_sequence.forward)
    backward = staticmethod(quaternet_sequence.backward)
    init_params = staticmethod(net.init_params)


def make_adapter(train_ds, val_ds, config: ShortTermConfig, dtype, extra: Mapping, *, name: str = NAME,
                 model_module=_RecurrentTraining) -> ModelAdapter:
    """The trainer's adapter on ``train_ds`` (a :class:`~refimpl.protocols.prediction_data.PredictionData`).

    Examples are the training sequences (long enough for a window); ``get_batch`` draws one window start per
    sequence and the feeding mask from the trainer's Generator, and reads the epoch for the teacher-forcing ratio.
    The loss the trainer logs is the total (main loss + penalty).
    """
    from refimpl.protocols.prediction_data import training_windows, usable_training

    P, T = config.prefix_length, config.target_length
    data = usable_training(train_ds, P + T)
    J = config.num_joints
    ncfg = config.network

    dual = getattr(config, "dual", False)
    if dual:
        parents = data.skeleton.parents
        tracks = _dq_tracks(data, data.skeleton)

    def get_batch(idx, ctx):
        if dual:  # the same window draws as the quaternion twin: one start per sequence, then the mask
            starts = [int(ctx.rng.integers(0, data.train[int(i)].num_frames - (P + T) + 1)) for i in idx]
            w = np.stack([data.train[int(i)].rotations[s:s + P + T] for i, s in zip(idx, starts)]).astype(dtype)
            d = np.stack([tracks[int(i)][s:s + P + T] for i, s in zip(idx, starts)]).astype(dtype)
            mask = teacher_forcing_mask(config, ctx.epoch, ctx.rng)
            return d.reshape(len(idx), P + T, 8 * J), w[:, P:], mask
        w = training_windows(data, idx, ctx.rng, P + T).astype(dtype)  # (B, P + T, J, 4)
        mask = teacher_forcing_mask(config, ctx.epoch, ctx.rng)
        return w.reshape(len(idx), P + T, 4 * J), w[:, P:], mask

    def loss_and_grads(params, batch):
        x, target, mask = batch
        y, pre, cache = model_module.forward(params, x[:, :P], x[:, P:], mask, ncfg)
        if dual:
            _, total, dy, dpre = dq_loss_terms(y, pre, target, config, parents)
        else:
            _, total, dy, dpre = loss_terms(y, pre, target, config)
        return total, model_module.backward(dy, dpre, cache)

    return ModelAdapter(name=name, num_examples=len(data.train),
                        init_params=lambda rng: model_module.init_params(ncfg, rng, dtype=dtype),
                        get_batch=get_batch, loss_and_grads=loss_and_grads,
                        # the config's own fields win over the task's extra (``representation``: the service
                        # stores the registry's "quat"; the network's field is "quaternion"/"dual_quaternion")
                        config={**dict(extra), **config.to_dict(), "dtype": np.dtype(dtype).name})


def _param_dtype(params) -> np.dtype:
    return next(iter(params.values())).dtype


def network_method(predict_fn: Callable, params: Mapping[str, np.ndarray], network_config, name: str) -> Callable:
    """``f(prefix (B, P, J, 4), k) -> (B, k, J, 4)``: the published predict (canonical prefix, then
    ``predict_fn(params, frames (B, P, 4J), k, network_config)``) in the parameters' dtype."""
    from refimpl.protocols.prediction import canonical_prefix

    dtype = _param_dtype(params)

    def method(prefix, k):
        x = canonical_prefix(prefix)
        B, P, J, _ = x.shape
        y = predict_fn(params, x.reshape(B, P, 4 * J).astype(dtype), int(k), network_config)
        return y.astype(np.float64).reshape(B, int(k), J, 4)

    method.__name__ = method.__qualname__ = name
    return method


def raw_outputs(predict_fn: Callable, params: Mapping[str, np.ndarray], network_config, prefix, k: int):
    """``predict_fn`` on the raw frames ``(B, P, J, D)`` (no canonicalisation; D = 4, or 8 for current dual
    quaternions) in the parameters' dtype: ``(B, k, J, D)`` float64, what an exported model must reproduce."""
    x = np.asarray(prefix)
    B, P, J, D = x.shape
    y = predict_fn(params, x.reshape(B, P, D * J).astype(_param_dtype(params)), int(k), network_config)
    return y.astype(np.float64).reshape(B, int(k), J, D)


def dq_network_method(params: Mapping[str, np.ndarray], network_config, skeleton, name: str) -> Callable:
    """``f(prefix (B, P, J, 4), k) -> (B, k, J, 4)`` of the dual-quaternion network: the published
    canonicalisation of the prefix, its current dual quaternions (:func:`refimpl.dq_prediction.
    dq_frames_from_rotations` with ``skeleton``), :func:`refimpl.models.quaternet.predict` in the parameters'
    dtype, and the predicted DQs decoded to unit local quaternions (Eq. 12)."""
    from refimpl.protocols.prediction import canonical_prefix

    dtype = _param_dtype(params)
    parents = skeleton.parents

    def method(prefix, k):
        x = canonical_prefix(prefix)
        B, P, J, _ = x.shape
        d = dq_frames_from_rotations(x, skeleton).reshape(B, P, 8 * J).astype(dtype)
        y = net.predict(params, d, int(k), network_config)
        return rotations_from_dq_frames(y.astype(np.float64).reshape(B, int(k), J, 8), parents)

    method.__name__ = method.__qualname__ = name
    return method


def predictor(params: Mapping[str, np.ndarray], config: ShortTermConfig, skeleton=None) -> Callable:
    """:func:`network_method` of :func:`refimpl.models.quaternet.predict` (:func:`dq_network_method` with the
    data's ``skeleton`` for ``representation="dual_quaternion"``)."""
    if getattr(config, "dual", False):
        if skeleton is None:
            raise ValueError("skeleton: required by the dual-quaternion network (its offsets build the frames)")
        return dq_network_method(params, config.network, skeleton, NAME)
    return network_method(net.predict, params, config.network, NAME)


def make_method(model) -> Callable:
    """:func:`predictor` of a :class:`~refimpl.registry.TrainedModel` (the skeleton of its dataset)."""
    from refimpl.protocols.prediction_data import skeleton_of

    skeleton = skeleton_of(model.extra["dataset"]) if getattr(model.config, "dual", False) else None
    return predictor(model.params, model.config, skeleton)


def export_inputs(model) -> dict:
    """Keyword arguments of the exporter (``deploy.models.quaternet.export_dir``): metadata (dataset, frame rate,
    skeleton, checkpoint step) and the predictor's default k."""
    from refimpl.protocols.prediction_data import skeleton_of

    skel = skeleton_of(model.extra["dataset"])
    meta = {"frame_rate": float(model.fps), "dataset": model.extra["dataset"],
            "prefix_length": int(model.config.prefix_length),
            "training": {"checkpoint_step": model.meta.get("step")}}
    return {"metadata": meta, "skeleton": skel, "k": 10}


def network_frames(model, prefix) -> np.ndarray:
    """The network's own input frames of a raw prefix ``(B, P, J, 4)`` (no canonicalisation): the prefix itself,
    or its current dual quaternions ``(B, P, J, 8)`` for the dual-quaternion network (what the exported graphs
    take)."""
    if not getattr(model.config, "dual", False):
        return np.asarray(prefix)
    from refimpl.protocols.prediction_data import skeleton_of

    return dq_frames_from_rotations(prefix, skeleton_of(model.extra["dataset"]))


def reference_outputs(model, prefix, k: int) -> np.ndarray:
    """What an exported model must reproduce: :func:`refimpl.models.quaternet.predict` of the raw prefix
    ``(B, P, J, 4)`` (no canonicalisation; dual quaternions: of its :func:`network_frames`) in the parameters'
    dtype, ``(B, k, J, D)`` float64 (the network's own frames)."""
    return raw_outputs(net.predict, model.params, model.config.network, network_frames(model, prefix), k)


def verify_onnx(model, runtime, prefix, k: int = 10) -> dict:
    """Compare onnxruntime with :func:`reference_outputs` on a raw prefix ``(B, P, J, 4)`` (fed as the network's
    :func:`network_frames`): the ``predict``
    graph and the ``step`` loop. ``{"predict": max |Δ|, "step_loop": max |Δ|, "ok": bool}`` against
    :data:`refimpl.testing.TOL_ORT_ROLLOUT` (dual quaternions, whose dual parts carry translations in the data's
    units: ``|Δ| <= (atol + rtol) · max(1, max |ref|)`` over each predicted frame)."""
    from refimpl.testing import TOL_ORT_ROLLOUT

    from refimpl.protocols.prediction import canonical_prefix

    prefix = canonical_prefix(prefix)   # the published sign rule, as the predictor (the predict graph repeats it)
    ref = reference_outputs(model, prefix, k)
    frames = network_frames(model, prefix)
    # float32 rounding scales with the largest number of a frame: for dual quaternions the dual parts carry the
    # joints' root-relative translations (the data's units, ~10 on CMU), so the bound is relative to the frame:
    # |Δ| <= (atol + rtol) · max(1, max |ref of the frame|)
    dual = getattr(model.config, "dual", False)
    scale = np.maximum(1.0, np.abs(ref).max(axis=(-2, -1), keepdims=True)) if dual else None
    out, ok = {}, True
    for key, use_graph in (("predict", True), ("step_loop", False)):
        got = np.asarray(runtime.predict(np.asarray(frames, np.float32), int(k), use_graph=use_graph), np.float64)
        diff = np.abs(got - ref)
        out[key] = float(diff.max())
        bound = ((TOL_ORT_ROLLOUT["atol"] + TOL_ORT_ROLLOUT["rtol"]) * scale if dual
                 else TOL_ORT_ROLLOUT["atol"] + TOL_ORT_ROLLOUT["rtol"] * np.abs(ref))
        ok &= bool(np.all(diff <= bound))
    out["ok"] = ok
    return out
