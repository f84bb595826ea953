"""Recipe of QuaterNet's long-term pose network (Pavllo et al., IJCV 2019, §3.7, §4.3) on the ``locomotion`` task
(spec/locomotion.md §8).

* :class:`QuaterNetLongConfig` — the recipe's config (``--set hidden_size=256``): the network's sizes; J comes
  from the data; :meth:`QuaterNetLongConfig.network` is the :class:`~refimpl.models.quaternet.QuaterNetConfig`;
* :func:`loss_and_grads` — the paper's loss on one :class:`~refimpl.protocols.locomotion.PoseBatch`: FK positions
  with the longitudinal-offset term (:func:`refimpl.losses.fk_position_loss_forward`, through
  :mod:`refimpl.nn.kinematics_layers`) + 0.01 · the quaternion norm penalty (:func:`refimpl.losses.quat_norm_loss_forward`),
  backward through the scheduled-sampling unroll (:func:`refimpl.models.quaternet_sequence.backward`);
* :func:`make_adapter` — windows drawn by :func:`refimpl.protocols.locomotion.pose_batch` (random rotation about +Y),
  teacher-forcing ratio ``0.995^epoch`` (:func:`refimpl.schedules.teacher_forcing_ratio`, from the trainer's
  epoch), one mask per batch, ground-truth controls in free-running steps;
* :data:`PAPER_OPTIM` — Adam 1e-3, × 0.999 per epoch, gradient-norm clip 0.1; :data:`PAPER_BATCH` 40;
* :func:`make_method` — free-running prediction ``f(inputs (B, P + T, F), P)`` with the ground-truth controls;
  :func:`extra_methods` — a dual-quaternion model's positions read from its DQs, for ``refimpl eval``;
* ``output=dual_quaternion`` (Andreou et al. §6.2): frames of current dual quaternions, L_pos + L_offset + L_quat
  + 0.01 L_reg, decoding with Eq. 12 — :mod:`refimpl.models.quaternet_long_dq` (spec/locomotion.md §11).

Shape legend: B batch, P prefix, T target frames, J joints, F = 4J + 8 input features, G = 4J + 2 outputs
(8J + 8 and 8J + 2 for dual quaternions).
"""
from __future__ import annotations

import dataclasses
from typing import Callable, Mapping, Sequence

import numpy as np

from refimpl.errors import UsageError
from refimpl.losses import (QUATERNET_PENALTY_WEIGHT, fk_position_loss_backward, fk_position_loss_forward,
                            quat_norm_loss_backward, quat_norm_loss_forward)
from refimpl.losses import euclidean_loss_backward, euclidean_loss_forward
from refimpl.models import quaternet, quaternet_long_dq, quaternet_sequence
from refimpl.nn.quat_layers import (axis_angle_to_quat_backward, axis_angle_to_quat_forward, euler_to_quat_backward,
                                    euler_to_quat_forward)
from refimpl.rotations import axis_angle_from_quat, euler_from_quat
from refimpl.optim import QUATERNET_ADAM, QUATERNET_CLIP_NORM, QUATERNET_LR_DECAY
from refimpl.options import config_with_overrides
from refimpl.protocols.locomotion_data import skeleton_of
from refimpl.schedules import QUATERNET_TF_DECAY, scheduled_sampling_mask, teacher_forcing_ratio
from refimpl.train import ModelAdapter, OptimConfig

__all__ = ["published_names", "param_shapes", "NAME", "SUMMARY", "TASK", "REPRESENTATIONS", "CONFIG_TYPE", "EXPORTER", "PAPER_OPTIM",
           "PAPER_BATCH",
           "OUTPUTS", "QuaterNetLongConfig", "make_config", "rotations_from_quat", "quat_from_rotations",
           "quat_from_rotations_backward", "ablation_inputs", "loss_and_grads", "make_adapter", "rollout",
           "make_method", "extra_methods", "export_inputs", "reference_outputs", "verify_onnx"]

NAME = "quaternet-long"
SUMMARY = ("QuaterNet long-term pose network (Pavllo et al. 2019): GRU with controls and translations, FK "
           "position loss; locomotion along a path with the pace network")
TASK = "locomotion"
REPRESENTATIONS = ("quat",)
EXPORTER = "quaternet-long"
#: Adam lr 1e-3, β = (0.9, 0.999), lr × 0.999 per epoch, global-norm clip 0.1 (ref §5.1).
PAPER_OPTIM = OptimConfig(**QUATERNET_ADAM, clip_norm=QUATERNET_CLIP_NORM, lr_decay=QUATERNET_LR_DECAY)
PAPER_BATCH = 40
#: Output parameterisations (``--set output=...``; QN §4.4.2-4.4.3, spec/locomotion.md §8): quaternions (the
#: model), Euler angles (orders xyz, yzx) and axis-angle vectors converted to quaternions before FK, and joint
#: positions (no FK); and current dual quaternions (Andreou et al. §6.2: positions read from the DQs, Eq. 8).
OUTPUTS = ("quaternion", "euler_xyz", "euler_yzx", "axis_angle", "positions", "dual_quaternion")


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
    #: ``output=dual_quaternion`` only: the DQs' translation unit as a multiple of the data's unit (1 = QuaterNet
    #: units of 5.6444 cm; 0.056444 = metres), spec/locomotion.md §11.
    dq_scale: float = 1.0

    def __post_init__(self):
        if self.output not in OUTPUTS:
            raise ValueError(f"output: expected one of {OUTPUTS}, got {self.output!r}")
        if not 0.0 <= float(self.tf_decay) <= 1.0:
            raise ValueError(f"tf_decay: expected a value in [0, 1], got {self.tf_decay}")
        if not (np.isfinite(float(self.dq_scale)) and float(self.dq_scale) > 0):
            raise ValueError(f"dq_scale: expected a finite value > 0, got {self.dq_scale}")
        self.network()  # validates the sizes

    def network(self) -> quaternet.QuaterNetConfig:
        """The recurrent network. Quaternions: J joints, 2 translations. The ablations reuse the same network
        with ONE placeholder quaternion and ``3J + 2`` raw "translations" (the 3-D rotation parameters or
        positions, then offset and height): same GRU, controls block and full BPTT through the feedback, plus
        4 constant-ish inputs and outputs (the placeholder, fed back normalised, outside every loss but the
        0.01 norm penalty)."""
        kw = dict(hidden_size=self.hidden_size, num_layers=self.num_layers, controls_hidden=self.controls_hidden,
                  negative_slope=self.negative_slope)
        if self.output == "quaternion":
            return quaternet.QuaterNetConfig.long_term(num_joints=self.num_joints, **kw)
        if self.output == "dual_quaternion":
            return quaternet.QuaterNetConfig.long_term(num_joints=self.num_joints, representation="dual_quaternion",
                                                       **kw)
        return quaternet.QuaterNetConfig.long_term(num_joints=1, num_outputs=3 * self.num_joints + 2, **kw)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


CONFIG_TYPE = QuaterNetLongConfig


def param_shapes(config: QuaterNetLongConfig) -> dict:
    """Name -> shape of every parameter of the network ``config`` describes (the checkpoint schema's reference,
    spec/robustness.md §9): the recurrent network's ``param_shapes`` of ``config.network`` (ablations included)."""
    return quaternet.param_shapes(config.network())


def published_names(config: QuaterNetLongConfig) -> dict:
    """Our parameter name -> (published name, shape): the published long-term state dict's names
    (:func:`refimpl.models.quaternet.published_names` of ``config.network()``; the identity)."""
    return quaternet.published_names(config.network())


def make_config(train_ds, overrides: Sequence[str] = ()) -> QuaterNetLongConfig:
    """J from the data's skeleton, then ``--set`` overrides (``num_joints`` cannot change)."""
    J = int(train_ds.skeleton.num_joints)
    base = QuaterNetLongConfig(num_joints=J)
    return config_with_overrides(base, overrides, "num_joints", f"the data has {J} joints")


# ----------------------------------------------------------------------------------------------------------------
# the ablations' rotation parameterisations (QN §4.4.2): differentiable conversion to quaternions before FK
# (the layers are refimpl.nn.quat_layers' euler_to_quat and axis_angle_to_quat)
# ----------------------------------------------------------------------------------------------------------------

def rotations_from_quat(q: np.ndarray, output: str) -> np.ndarray:
    """Ground-truth quaternions (..., J, 4) in an ablation's parameterisation (..., J, 3)."""
    if output.startswith("euler_"):
        return euler_from_quat(q, output[len("euler_"):])
    return axis_angle_from_quat(q)


def quat_from_rotations(r: np.ndarray, output: str) -> tuple[np.ndarray, object]:
    """An ablation's 3-D rotations (..., 3) as quaternions, with the cache of the conversion."""
    if output.startswith("euler_"):
        return euler_to_quat_forward(r, output[len("euler_"):])
    return axis_angle_to_quat_forward(r)


def quat_from_rotations_backward(dq: np.ndarray, cache, output: str) -> np.ndarray:
    if output.startswith("euler_"):
        return euler_to_quat_backward(dq, cache)
    return axis_angle_to_quat_backward(dq, cache)


def ablation_inputs(inputs: np.ndarray, output: str, skeleton) -> np.ndarray:
    """Windows ``[q (4J) | offset, height | controls]`` (B, L, 4J + 8) → the ablation network's input frames
    ``[placeholder (1, 0, 0, 0) | 3J rotation parameters or local positions | offset, height | controls]``."""
    B, Lw, F = inputs.shape
    J = (F - 8) // 4
    q = inputs[..., :4 * J].reshape(B, Lw, J, 4).astype(np.float64)
    if output == "positions":
        root = np.zeros((B, Lw, 3))
        root[..., 1] = inputs[..., 4 * J + 1]
        r3 = skeleton.forward_kinematics(q, root)                             # (B, L, J, 3) positions_local
    else:
        r3 = rotations_from_quat(q, output)                                   # (B, L, J, 3)
    ph = np.zeros((B, Lw, 4))
    ph[..., 0] = 1.0
    return np.concatenate([ph, r3.reshape(B, Lw, 3 * J), inputs[..., 4 * J:]], axis=-1).astype(inputs.dtype)


def loss_and_grads(params: Mapping[str, np.ndarray], batch: Mapping, net: quaternet.QuaterNetConfig, offsets,
                   parents, penalty: float = QUATERNET_PENALTY_WEIGHT, output: str = "quaternion",
                   dq_scale: float = 1.0):
    """The long-term loss and its gradient on one batch.

    Quaternions (QN §3.4, §3.7; ref §7.5)::

        loss = mean_{B,T,J} (‖FK(q̂)_j + (0, h, 0) − p_j‖ + |o − õ|) + penalty · mean_{B,T,J} (‖Δ_j‖² − 1)²

    Euler / axis-angle ablations (QN §4.4.2): the 3J outputs are converted to quaternions
    (:func:`euler_to_quat_forward`, :func:`axis_angle_to_quat_forward`) before the same FK loss; the penalty
    acts on the placeholder quaternion only. Positions (QN §4.4.3): ``mean ‖p̂_j − p_j‖ + mean |o − õ| +
    mean |h − h̃|`` (the height is inside the FK positions of the other models; here it is its own output).
    Dual quaternions (Andreou et al. §6.2): :func:`refimpl.models.quaternet_long_dq.loss_and_grads` with the
    DQs' unit ``dq_scale`` (``batch["inputs"]`` from :func:`~refimpl.models.quaternet_long_dq.dq_inputs`).

    Parameters
    ----------
    batch : dict with ``inputs (B, P + T, F)`` (the network's input frames: :func:`ablation_inputs` for the
        ablations), ``target_positions (B, T, J, 3)``, ``target_translations (B, T, 2)``, ``mask (T − 1,)``
        bool, ``prefix`` (P)
    net : QuaterNetConfig (:meth:`QuaterNetLongConfig.network`)
    offsets : (J, 3); parents : (J,)

    Returns
    -------
    loss : float (position loss + penalty); grads : dict
    """
    if output == "dual_quaternion":  # Andreou et al. §6.2 (quaternet_long_dq.loss_and_grads)
        value, grads, _ = quaternet_long_dq.loss_and_grads(params, batch, net, parents, scale=dq_scale)
        return value, grads
    x, P = batch["inputs"], int(batch["prefix"])
    B, L, _ = x.shape
    T, R = L - P, 4 * net.num_joints
    tpos, ttr = batch["target_positions"], batch["target_translations"]
    J = tpos.shape[-2]
    y, pre, cache = quaternet_sequence.forward(params, x[:, :P], x[:, P:], batch["mask"], net)
    pen, pc = quat_norm_loss_forward(pre.reshape(B, T, net.num_joints, 4))
    dy = np.zeros(y.shape, dtype=np.float64)
    if output == "quaternion":
        value, lc = fk_position_loss_forward(y[..., :R].reshape(B, T, J, 4), y[..., R:], tpos, ttr, offsets, parents)
        drot, dtr = fk_position_loss_backward(1.0, lc)
        dy[..., :R] = drot.reshape(B, T, R)
        dy[..., R:] = dtr
    elif output == "positions":
        value, ec = euclidean_loss_forward(y[..., R:R + 3 * J].reshape(B, T, J, 3), tpos)
        dy[..., R:R + 3 * J] = euclidean_loss_backward(1.0, ec).reshape(B, T, 3 * J)
        d = y[..., R + 3 * J:] - ttr                                           # (B, T, 2)
        value += float(np.abs(d).mean(axis=(0, 1)).sum())
        dy[..., R + 3 * J:] = np.sign(d) / (B * T)
    else:
        q, qc = quat_from_rotations(y[..., R:R + 3 * J].reshape(B, T, J, 3).astype(np.float64), output)
        value, lc = fk_position_loss_forward(q, y[..., R + 3 * J:], tpos, ttr, offsets, parents)
        dq, dtr = fk_position_loss_backward(1.0, lc)
        dy[..., R:R + 3 * J] = quat_from_rotations_backward(dq, qc, output).reshape(B, T, 3 * J)
        dy[..., R + 3 * J:] = dtr
    dpre = (penalty * quat_norm_loss_backward(1.0, pc)).reshape(B, T, R).astype(y.dtype, copy=False)
    grads = quaternet_sequence.backward(dy.astype(y.dtype, copy=False), dpre, cache)
    return value + penalty * pen, grads


def rollout(params: Mapping[str, np.ndarray], net: quaternet.QuaterNetConfig, inputs, prefix: int,
            output: str = "quaternion", skeleton=None, dq_scale: float = 1.0):
    """Free-running prediction of frames ``P … P + T − 1`` from ``inputs[:, :P]``, with the ground-truth controls
    of ``inputs[:, P:]`` (:func:`refimpl.models.quaternet.predict`); ``inputs`` in the window layout
    ``[q (4J) | offset, height | controls]`` (converted by :func:`ablation_inputs` for the ablations, which need
    ``skeleton`` for positions).

    Returns
    -------
    rotations (B, T, J, 4) — or positions (B, T, J, 3) for ``output = "positions"`` — and translations (B, T, 2)
    """
    if output == "dual_quaternion":  # local rotations decoded from the DQs (Eq. 12)
        dq, tr = quaternet_long_dq.rollout(params, net, inputs, prefix, skeleton, dq_scale)
        return quaternet_long_dq.decode(dq, tr, skeleton, dq_scale)["rotations"], tr
    dtype = np.asarray(params["h0"]).dtype
    x = np.asarray(inputs)
    B, L, F = x.shape
    J = (F - 8) // 4
    if output != "quaternion":
        x = ablation_inputs(x, output, skeleton)
    x = x.astype(dtype)
    P, G, R = int(prefix), net.output_size, 4 * net.num_joints
    y = quaternet.predict(params, x[:, :P], L - P, net, controls=np.ascontiguousarray(x[:, P:L - 1, G:]))
    if output == "quaternion":
        return y[..., :R].reshape(B, L - P, J, 4), y[..., R:]
    r3 = y[..., R:R + 3 * J].reshape(B, L - P, J, 3).astype(np.float64)
    if output == "positions":
        return r3, y[..., R + 3 * J:]
    return quat_from_rotations(r3, output)[0], y[..., R + 3 * J:]


def make_adapter(train_ds, val_ds, config: QuaterNetLongConfig, dtype, extra: Mapping) -> ModelAdapter:
    """The trainer's adapter: windows of :func:`refimpl.protocols.locomotion.pose_batch` (augmented), the
    scheduled-sampling mask of ratio ``0.995^epoch``, :func:`loss_and_grads`; validation = free-running mean
    position error (units) on the held-out windows (:func:`refimpl.protocols.locomotion.evaluation_windows`, at most
    256 of them)."""
    from refimpl.protocols.locomotion import evaluation_windows, pose_batch, position_errors

    net = config.network()
    skel = train_ds.skeleton
    offsets = np.asarray(skel.offsets, dtype=dtype)
    parents = list(skel.parents)
    seqs = train_ds.windows
    P, T = train_ds.prefix, train_ds.target

    def get_batch(idx, ctx):
        b = pose_batch(seqs, ctx.rng, len(idx), P, T, augment=True)
        mask = scheduled_sampling_mask(teacher_forcing_ratio(ctx.epoch, decay=config.tf_decay), T - 1, ctx.rng)
        if config.output == "dual_quaternion":
            inputs = quaternet_long_dq.dq_inputs(b.inputs, skel, config.dq_scale)
        elif config.output == "quaternion":
            inputs = b.inputs
        else:
            inputs = ablation_inputs(b.inputs, config.output, skel)
        return {"inputs": inputs.astype(dtype), "target_positions": b.target_positions.astype(dtype),
                "target_translations": b.target_translations.astype(dtype), "mask": mask, "prefix": P}

    validate = None
    if val_ds is not None and val_ds.windows:
        vin, vpos, _ = evaluation_windows(val_ds)
        sel = np.linspace(0, len(vin) - 1, min(256, len(vin))).round().astype(int)
        vin, vpos = vin[sel], vpos[sel]

        def validate(params):
            if config.output == "dual_quaternion":  # FK of the decoded rotations, and the DQs' own positions
                dq, tr = quaternet_long_dq.rollout(params, net, vin, P, skel, config.dq_scale)
                dec = quaternet_long_dq.decode(dq, tr, skel, config.dq_scale)
                perr, verr = position_errors(skel, dec["fk_positions"], tr, vpos)
                dq_err, _ = position_errors(skel, dec["dq_positions"], tr, vpos)
                return {"val_position": float(perr.mean()), "val_velocity": float(verr.mean()),
                        "val_position_dq": float(dq_err.mean())}
            rot, tr = rollout(params, net, vin, P, config.output, skel)
            perr, verr = position_errors(skel, rot, tr, vpos)
            return {"val_position": float(perr.mean()), "val_velocity": float(verr.mean())}

    return ModelAdapter(name=NAME, num_examples=max(1, len(seqs)),
                        init_params=lambda rng: quaternet.init_params(net, rng, dtype=dtype),
                        get_batch=get_batch,
                        loss_and_grads=lambda params, batch: loss_and_grads(params, batch, net, offsets, parents,
                                                                            output=config.output,
                                                                            dq_scale=config.dq_scale),
                        validate=validate,
                        config=dict(config.to_dict(), dtype=np.dtype(dtype).name, **extra))


def make_method(model) -> Callable:
    """``f(inputs (B, P + T, F), P) -> (rotations, translations)``: :func:`rollout` of a trained model."""
    net = model.config.network()
    skel = skeleton_of(model.extra)

    def quaternet_long(inputs, prefix):
        return rollout(model.params, net, inputs, prefix, model.config.output, skel, model.config.dq_scale)

    return quaternet_long


def extra_methods(model) -> dict:
    """Further methods of ``refimpl eval`` beside :func:`make_method`: for a dual-quaternion model,
    ``quaternet-long_dq_positions`` returns the positions read from the predicted DQs (Eq. 8, root ``(0, h, 0)``)
    instead of FK of the decoded rotations; none for the other outputs."""
    if model.config.output != "dual_quaternion":
        return {}
    net = model.config.network()
    skel = skeleton_of(model.extra)

    def dq_positions(inputs, prefix):
        dq, tr = quaternet_long_dq.rollout(model.params, net, inputs, prefix, skel, model.config.dq_scale)
        return quaternet_long_dq.decode(dq, tr, skel, model.config.dq_scale)["dq_positions"], tr

    return {f"{NAME}_dq_positions": dq_positions}


def export_inputs(model) -> dict:
    """Keyword arguments of the exporter (``deploy.models.quaternet_long_io.export_dir``): metadata, skeleton and
    the seed clip that starts a walk; quaternion and dual-quaternion models (the step graph normalises each
    joint's 8 numbers with Eq. 13; ``dq_scale`` in the metadata)."""
    if model.config.output not in ("quaternion", "dual_quaternion"):
        raise UsageError(f"export: only quaternion- and dual-quaternion-output models are exported (this one: "
                         f"{model.config.output})")
    metadata = {"frame_rate": float(model.fps or 30.0),
                "training": {"checkpoint_step": model.meta.get("step"), "rig": model.extra.get("rig")}}
    if model.config.output == "dual_quaternion":  # the DQs' translation unit, for a walk from the exported step
        metadata["dq_scale"] = float(model.config.dq_scale)
    return {"metadata": metadata, "skeleton": skeleton_of(model.extra), "seed_clip": model.extra.get("seed_clip")}


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
