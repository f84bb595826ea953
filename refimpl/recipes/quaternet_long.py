"""Recipe of QuaterNet's long-term pose network (Pavllo et al., IJCV 2019, §3.7, §4.3) on the ``locomotion`` task
(spec/locomotion.md §8).

* :class:`QuaterNetLongConfig` — the recipe's config (``--set hidden_size=256``): the network's sizes; J comes
  from the data; :meth:`QuaterNetLongConfig.network` is the :class:`~refimpl.models.quaternet.QuaterNetConfig`;
* :func:`loss_and_grads` — the paper's loss on one :class:`~refimpl.tasks.locomotion.PoseBatch`: FK positions
  with the longitudinal-offset term (:func:`refimpl.losses.fk_position_loss_forward`, through
  :mod:`refimpl.nn.kinematics_layers`) + 0.01 · the quaternion norm penalty (:func:`refimpl.losses.quat_norm_loss_forward`),
  backward through the scheduled-sampling unroll (:func:`refimpl.models.quaternet.backward`);
* :func:`make_adapter` — windows drawn by :func:`refimpl.tasks.locomotion.pose_batch` (random rotation about +Y),
  teacher-forcing ratio ``0.995^epoch`` (:func:`refimpl.schedules.teacher_forcing_ratio`, from the trainer's
  epoch), one mask per batch, ground-truth controls in free-running steps;
* :data:`PAPER_OPTIM` — Adam 1e-3, × 0.999 per epoch, gradient-norm clip 0.1; :data:`PAPER_BATCH` 40;
* :func:`make_method` — free-running prediction ``f(inputs (B, P + T, F), P)`` with the ground-truth controls.

Shape legend: B batch, P prefix, T target frames, J joints, F = 4J + 8 input features, G = 4J + 2 outputs.
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.errors import UsageError
from refimpl.losses import (QUATERNET_PENALTY_WEIGHT, fk_position_loss_backward, fk_position_loss_forward,
                            quat_norm_loss_backward, quat_norm_loss_forward)
from refimpl.models import quaternet
from refimpl.optim import QUATERNET_ADAM, QUATERNET_CLIP_NORM, QUATERNET_LR_DECAY
from refimpl.recipes.qtg import parse_overrides
from refimpl.schedules import QUATERNET_TF_DECAY, scheduled_sampling_mask, teacher_forcing_ratio
from refimpl.train import ModelAdapter, OptimConfig

__all__ = ["NAME", "SUMMARY", "TASK", "REPRESENTATIONS", "CONFIG_TYPE", "EXPORTER", "PAPER_OPTIM", "PAPER_BATCH",
           "OUTPUTS", "QuaterNetLongConfig", "make_config", "loss_and_grads", "make_adapter", "rollout",
           "make_method", "export_inputs", "reference_outputs", "verify_onnx"]

NAME = "quaternet-long"
SUMMARY = ("QuaterNet long-term pose network (Pavllo et al. 2019): GRU with controls and translations, FK "
           "position loss; locomotion along a path with the pace network")
TASK = "locomotion"
REPRESENTATIONS = ("quat",)
EXPORTER = "quaternet-long"
#: Adam lr 1e-3, β = (0.9, 0.999), lr × 0.999 per epoch, global-norm clip 0.1 (ref §5.1).
PAPER_OPTIM = OptimConfig(**QUATERNET_ADAM, clip_norm=QUATERNET_CLIP_NORM, lr_decay=QUATERNET_LR_DECAY)
PAPER_BATCH = 40
#: Output parameterisations (``--set output=...``). Only quaternions are implemented (spec/locomotion.md §8.5).
OUTPUTS = ("quaternion",)


@dataclasses.dataclass(frozen=True)
class QuaterNetLongConfig:
    """The long-term pose network's recipe config (defaults: the paper's sizes; J from the data)."""

    num_joints: int = 26
    hidden_size: int = 1000
    num_layers: int = 2
    controls_hidden: int = 30
    negative_slope: float = 0.05
    output: str = "quaternion"
    #: Teacher-forcing ratio decay per epoch (the paper's 0.995; a larger decay suits a short CPU budget).
    tf_decay: float = QUATERNET_TF_DECAY

    def __post_init__(self):
        if self.output not in OUTPUTS:
            raise ValueError(f"output: expected one of {OUTPUTS}, got {self.output!r} (the Euler, axis-angle and "
                             "position ablations are not implemented)")
        if not 0.0 <= float(self.tf_decay) <= 1.0:
            raise ValueError(f"tf_decay: expected a value in [0, 1], got {self.tf_decay}")
        self.network()  # validates the sizes

    def network(self) -> quaternet.QuaterNetConfig:
        return quaternet.QuaterNetConfig.long_term(num_joints=self.num_joints, hidden_size=self.hidden_size,
                                                   num_layers=self.num_layers, controls_hidden=self.controls_hidden,
                                                   negative_slope=self.negative_slope)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


CONFIG_TYPE = QuaterNetLongConfig


def make_config(train_ds, overrides: Sequence[str] = ()) -> QuaterNetLongConfig:
    """J from the data's skeleton, then ``--set`` overrides (``num_joints`` cannot change)."""
    J = int(train_ds.skeleton.num_joints)
    base = QuaterNetLongConfig(num_joints=J)
    values = parse_overrides(QuaterNetLongConfig, dataclasses.asdict(base), overrides)
    if values.get("num_joints", J) != J:
        raise UsageError(f"--set num_joints={values['num_joints']}: the data has {J} joints")
    try:
        return dataclasses.replace(base, **values)
    except ValueError as exc:
        raise UsageError(f"--set: {exc}") from None


def loss_and_grads(params: Mapping[str, np.ndarray], batch: Mapping, net: quaternet.QuaterNetConfig, offsets,
                   parents, penalty: float = QUATERNET_PENALTY_WEIGHT):
    """The long-term loss and its gradient on one batch.

    ``loss = mean_{B,T,J} (‖FK(q̂)_j + (0, h, 0) − p_j‖ + |o − õ|) + penalty · mean_{B,T,J} (‖Δ_j‖² − 1)²``
    (QN §3.4, §3.7; ref §7.5).

    Parameters
    ----------
    batch : dict with ``inputs (B, P + T, F)``, ``target_positions (B, T, J, 3)``, ``target_translations
        (B, T, 2)``, ``mask (T − 1,)`` bool, ``prefix`` (P)
    net : QuaterNetConfig
    offsets : (J, 3); parents : (J,)

    Returns
    -------
    loss : float (position loss + penalty); grads : dict
    """
    x, P = batch["inputs"], int(batch["prefix"])
    B, L, _ = x.shape
    T, J = L - P, net.num_joints
    y, pre, cache = quaternet.forward(params, x[:, :P], x[:, P:], batch["mask"], net)
    rot = y[..., :4 * J].reshape(B, T, J, 4)
    value, lc = fk_position_loss_forward(rot, y[..., 4 * J:], batch["target_positions"], batch["target_translations"],
                                         offsets, parents)
    pen, pc = quat_norm_loss_forward(pre.reshape(B, T, J, 4))
    drot, dtr = fk_position_loss_backward(1.0, lc)
    dy = np.concatenate([drot.reshape(B, T, 4 * J), dtr], axis=-1).astype(y.dtype, copy=False)
    dpre = (penalty * quat_norm_loss_backward(1.0, pc)).reshape(B, T, 4 * J).astype(y.dtype, copy=False)
    grads = quaternet.backward(dy, dpre, cache)
    return value + penalty * pen, grads


def rollout(params: Mapping[str, np.ndarray], net: quaternet.QuaterNetConfig, inputs, prefix: int):
    """Free-running prediction of frames ``P … P + T − 1`` from ``inputs[:, :P]``, with the ground-truth controls
    of ``inputs[:, P:]`` (:func:`refimpl.models.quaternet.predict`).

    Returns
    -------
    rotations (B, T, J, 4), translations (B, T, 2)
    """
    dtype = np.asarray(params["h0"]).dtype
    x = np.asarray(inputs).astype(dtype)
    B, L, _ = x.shape
    P, G, J = int(prefix), net.output_size, net.num_joints
    y = quaternet.predict(params, x[:, :P], L - P, net, controls=np.ascontiguousarray(x[:, P:L - 1, G:]))
    return y[..., :4 * J].reshape(B, L - P, J, 4), y[..., 4 * J:]


def make_adapter(train_ds, val_ds, config: QuaterNetLongConfig, dtype, extra: Mapping) -> ModelAdapter:
    """The trainer's adapter: windows of :func:`refimpl.tasks.locomotion.pose_batch` (augmented), the
    scheduled-sampling mask of ratio ``0.995^epoch``, :func:`loss_and_grads`; validation = free-running mean
    position error (units) on the held-out windows (:func:`refimpl.tasks.locomotion.evaluation_windows`, at most
    256 of them)."""
    from refimpl.tasks.locomotion import evaluation_windows, pose_batch, position_errors

    net = config.network()
    skel = train_ds.skeleton
    offsets = np.asarray(skel.offsets, dtype=dtype)
    parents = list(skel.parents)
    seqs = train_ds.windows
    P, T = train_ds.prefix, train_ds.target

    def get_batch(idx, ctx):
        b = pose_batch(seqs, ctx.rng, len(idx), P, T, augment=True)
        mask = scheduled_sampling_mask(teacher_forcing_ratio(ctx.epoch, decay=config.tf_decay), T - 1, ctx.rng)
        return {"inputs": b.inputs.astype(dtype), "target_positions": b.target_positions.astype(dtype),
                "target_translations": b.target_translations.astype(dtype), "mask": mask, "prefix": P}

    validate = None
    if val_ds is not None and val_ds.windows:
        vin, vpos, _ = evaluation_windows(val_ds)
        sel = np.linspace(0, len(vin) - 1, min(256, len(vin))).round().astype(int)
        vin, vpos = vin[sel], vpos[sel]

        def validate(params):
            rot, tr = rollout(params, net, vin, P)
            perr, verr = position_errors(skel, rot, tr, vpos)
            return {"val_position": float(perr.mean()), "val_velocity": float(verr.mean())}

    return ModelAdapter(name=NAME, num_examples=max(1, len(seqs)),
                        init_params=lambda rng: quaternet.init_params(net, rng, dtype=dtype),
                        get_batch=get_batch,
                        loss_and_grads=lambda params, batch: loss_and_grads(params, batch, net, offsets, parents),
                        validate=validate,
                        config=dict(config.to_dict(), dtype=np.dtype(dtype).name, **extra))


def make_method(model) -> Callable:
    """``f(inputs (B, P + T, F), P) -> (rotations, translations)``: :func:`rollout` of a trained model."""
    net = model.config.network()

    def quaternet_long(inputs, prefix):
        return rollout(model.params, net, inputs, prefix)

    return quaternet_long


def export_inputs(model) -> dict:
    """Keyword arguments of the exporter (``deploy.models.quaternet_long_io.export_dir``)."""
    return {"metadata": {"frame_rate": float(model.fps or 30.0),
                         "training": {"checkpoint_step": model.meta.get("step"), "rig": model.extra.get("rig")}}}


def reference_outputs(model, x, state=None):
    """One NumPy step (:func:`refimpl.models.quaternet.step`) from ``state`` (default ``h0``): ``(y (B, G),
    state (L, B, H))``, what the exported step model must reproduce."""
    net = model.config.network()
    dtype = np.asarray(model.params["h0"]).dtype
    x = np.asarray(x).astype(dtype)
    h = quaternet.init_state(model.params, x.shape[0], net) if state is None else np.asarray(state, dtype)
    return quaternet.step(model.params, h, x, net)


def verify_onnx(model, runtime, x=None, steps: int = 5, seed: int = 0) -> dict:
    """Run ``steps`` exported steps against :func:`reference_outputs` from random frames ``x (B, F)``.

    Returns
    -------
    dict ``{"step": max |Δ|, "ok": bool}`` (``ok``: max |Δ| <= 1e-4)."""
    net = model.config.network()
    rng = np.random.default_rng(seed)
    if x is None:
        x = rng.standard_normal((2, net.input_size)).astype(np.float32)
    h_ref = None
    h_ort = None
    worst = 0.0
    xx = np.asarray(x, np.float32)
    for _ in range(int(steps)):
        y_ref, h_ref = reference_outputs(model, xx, h_ref)
        y_ort, h_ort = runtime.step(xx, h_ort)
        worst = max(worst, float(np.abs(np.asarray(y_ort, np.float64) - y_ref).max()),
                    float(np.abs(np.asarray(h_ort, np.float64) - h_ref).max()))
        xx = np.concatenate([np.asarray(y_ref, np.float32), xx[:, net.output_size:]], axis=1)
    return {"step": worst, "ok": worst <= 1e-4}
