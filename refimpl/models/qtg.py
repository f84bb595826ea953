"""Quaternion Transition Generator (QTG; Geleijn, Radziszewski, van Straaten, Galvan Debarba, IEEE VR 2021).

Generates the ``T`` frames of an animation transition from 2 past poses and 2 target poses, one frame at a
time, feeding each decoded pose back (spec/qtg.md). The paper gives the structure in words only (its Figure 2
with the layer sizes is missing from every available copy); the sizes below are our reconstruction, chosen so
that the per-frame operation count is ≈ 20 % of RTN's (the paper's "≈ 80 % fewer arithmetic operations"),
see spec/qtg.md §2 and :func:`macs_per_frame`.

Pose (P = 91 by default): ``[root translation (3, z-normalised) | 22 local joint quaternions (w, x, y, z)]``.

Network (defaults of :class:`QTGConfig`; every size configurable)::

    E  encoder   P -> 256 (LeakyReLU) -> 128 (LeakyReLU)       enc.0, enc.1       latent size Z = 128
    GRU          input 3Z = 384, hidden H = 256                gru.*_l0
    V  velocity  H -> Z, linear                                vel
    D  decoder   Z -> 256 (LeakyReLU) -> P (linear)            dec.0, dec.1

One step (spec/qtg.md §3), from the state ``(z_{t-1}, p_t, s_t)`` and the encoded targets ``e1 = E(g1)``,
``e2 = E(g2)``::

    z_t     = E(p_t)                                     (the fed-back pose is re-encoded)
    x_t     = [z_t - z_{t-1} | e1 - z_t | e2 - e1]       latent velocity, offset to target, target velocity
    s_{t+1} = GRU(x_t, s_t)
    v_t     = W_v s_{t+1} + b_v                          latent velocity (linear: signed)
    p_{t+1} = D(z_t + v_t)                               residual connection in latent space, then decode
    state  <- (z_t, p_{t+1}, s_{t+1})

Rollout: ``z_{-1} = E(p_{-1})``, ``p_0`` the last past pose, ``s_0 = 0``; steps ``t = 0 … T-1`` give
``p_1 … p_T``.

This module is the readable reference: the config, the parameters, the encoder and decoder
(:mod:`refimpl.nn.mlp`), :func:`init_state` and :func:`step` written with the layers' public functions, and the
test oracles (``_rollout_naive``, a per-sample loop from the equations; ``_rollout_backward_per_step``, BPTT with
per-step caches). The fast paths live beside it: :mod:`refimpl.models.qtg_fast` (the fused training rollout
:func:`~refimpl.models.qtg_fast.rollout_forward` / :func:`~refimpl.models.qtg_fast.rollout_backward`) and
:mod:`refimpl.models.qtg_fast_inference` (the in-place inference
:func:`~refimpl.models.qtg_fast_inference.rollout_inference`), tested equal to this reference (tests/test_qtg.py). ``check_params``, ``check_context`` and ``check_length`` are the boundary checks both use.

Shape legend: B batch, T transition frames, P pose size, Z latent size, H GRU hidden size, L GRU layers.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, NamedTuple

import numpy as np

from refimpl.models._shared import check_param_dict
from refimpl.nn.gru import gru_init, gru_step_backward, gru_step_forward
from refimpl.nn.linear import linear_backward, linear_forward, linear_init
from refimpl.nn.mlp import mlp_backward, mlp_forward
from refimpl.arrays import float_array
from refimpl.nn.params import accumulate_grads

__all__ = [
    "QTGConfig", "QTGState", "init_params", "count_parameters", "param_shapes",
    "encode", "init_state", "step", "macs_per_frame", "rtn_macs_per_frame",
]


# ----------------------------------------------------------------------------------------------------------------
# configuration and parameters
# ----------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class QTGConfig:
    """Sizes of the QTG network (defaults: our reconstruction, spec/qtg.md §2).

    Attributes
    ----------
    pose_size : int
        P, values per pose (3 root translation + 4 per joint; 91 for 22 joints).
    encoder_sizes : tuple of int
        Output sizes of the encoder's dense layers, all LeakyReLU; the last one is the latent size Z.
    gru_hidden : int
        H, GRU hidden size.
    gru_layers : int
        L, stacked GRU layers (1 in our reconstruction).
    decoder_sizes : tuple of int
        Hidden dense layers of the decoder (LeakyReLU); a final linear layer maps to ``pose_size``.
    negative_slope : float
        LeakyReLU slope (PyTorch default 0.01).
    transition_length : int
        Default T, frames generated per transition (30 = 1 s at 30 fps).
    """

    pose_size: int = 91
    encoder_sizes: tuple[int, ...] = (256, 128)
    gru_hidden: int = 256
    gru_layers: int = 1
    decoder_sizes: tuple[int, ...] = (256,)
    negative_slope: float = 0.01
    transition_length: int = 30

    def __post_init__(self):
        for name in ("pose_size", "gru_hidden", "gru_layers", "transition_length"):
            v = getattr(self, name)
            if not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"QTGConfig.{name}: expected a positive integer, got {v!r}")
        object.__setattr__(self, "encoder_sizes", tuple(int(s) for s in self.encoder_sizes))
        object.__setattr__(self, "decoder_sizes", tuple(int(s) for s in self.decoder_sizes))
        if len(self.encoder_sizes) < 1 or min(self.encoder_sizes) < 1:
            raise ValueError(f"QTGConfig.encoder_sizes: expected at least one positive size, got {self.encoder_sizes}")
        if self.decoder_sizes and min(self.decoder_sizes) < 1:
            raise ValueError(f"QTGConfig.decoder_sizes: expected positive sizes, got {self.decoder_sizes}")
        if not 0.0 <= float(self.negative_slope) < 1.0:
            raise ValueError(f"QTGConfig.negative_slope: expected a value in [0, 1), got {self.negative_slope}")

    @property
    def latent_size(self) -> int:
        """Z, the size of a latent pose (the encoder's last layer, the velocity head's output)."""
        return self.encoder_sizes[-1]

    @property
    def gru_input_size(self) -> int:
        """3 Z: latent velocity, offset to the target, target velocity."""
        return 3 * self.latent_size

    def to_dict(self) -> dict:
        """Plain JSON-friendly dict (for checkpoint metadata); ``QTGConfig(**d)`` rebuilds it."""
        return {"pose_size": self.pose_size, "encoder_sizes": list(self.encoder_sizes),
                "gru_hidden": self.gru_hidden, "gru_layers": self.gru_layers,
                "decoder_sizes": list(self.decoder_sizes), "negative_slope": float(self.negative_slope),
                "transition_length": self.transition_length}


def _mlp_sizes(config: QTGConfig, which: str) -> list[tuple[int, int]]:
    if which == "enc":
        sizes = (config.pose_size,) + config.encoder_sizes
    else:
        sizes = (config.latent_size,) + config.decoder_sizes + (config.pose_size,)
    return list(zip(sizes[:-1], sizes[1:]))


def param_shapes(config: QTGConfig) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every parameter (PyTorch layouts: ``weight (out, in)``, GRU blocks ``r|z|n``)."""
    shapes: dict[str, tuple[int, ...]] = {}
    for which in ("enc", "dec"):
        for i, (n_in, n_out) in enumerate(_mlp_sizes(config, which)):
            shapes[f"{which}.{i}.weight"] = (n_out, n_in)
            shapes[f"{which}.{i}.bias"] = (n_out,)
    H = config.gru_hidden
    for layer in range(config.gru_layers):
        n_in = config.gru_input_size if layer == 0 else H
        shapes[f"gru.weight_ih_l{layer}"] = (3 * H, n_in)
        shapes[f"gru.weight_hh_l{layer}"] = (3 * H, H)
        shapes[f"gru.bias_ih_l{layer}"] = (3 * H,)
        shapes[f"gru.bias_hh_l{layer}"] = (3 * H,)
    shapes["vel.weight"] = (config.latent_size, H)
    shapes["vel.bias"] = (config.latent_size,)
    return shapes


def init_params(config: QTGConfig, rng: np.random.Generator, dtype=np.float64) -> dict[str, np.ndarray]:
    """PyTorch-default initialisation of every layer (spec/qtg.md §2).

    Dense layers ``U(±1/sqrt(in))``, GRU ``U(±1/sqrt(H))`` (``refimpl.nn`` initialisers).

    Parameters
    ----------
    config : QTGConfig
    rng : numpy.random.Generator
    dtype : float32 or float64

    Returns
    -------
    dict
        Names ``enc.{i}.weight/bias``, ``gru.weight_ih_l{k}``…, ``vel.weight/bias``, ``dec.{i}.weight/bias``.
    """
    params: dict[str, np.ndarray] = {}
    for i, (n_in, n_out) in enumerate(_mlp_sizes(config, "enc")):
        params.update(linear_init(rng, n_in, n_out, f"enc.{i}", dtype=dtype))
    params.update(gru_init(rng, config.gru_input_size, config.gru_hidden, config.gru_layers, "gru", dtype=dtype))
    params.update(linear_init(rng, config.gru_hidden, config.latent_size, "vel", dtype=dtype))
    for i, (n_in, n_out) in enumerate(_mlp_sizes(config, "dec")):
        params.update(linear_init(rng, n_in, n_out, f"dec.{i}", dtype=dtype))
    return params


def count_parameters(config: QTGConfig) -> int:
    """Number of scalar parameters of the network with ``config`` (638,811 for the defaults)."""
    return int(sum(int(np.prod(s)) for s in param_shapes(config).values()))


def macs_per_frame(config: QTGConfig = QTGConfig()) -> int:
    """Multiply-accumulates of the dense and GRU matrix products per generated frame (spec/qtg.md §5).

    One encoder pass (the fed-back pose), the GRU's input and recurrent products, the velocity head and the
    decoder. The target encodings and ``E(p_{-1})`` are computed once per transition and not counted; biases and
    element-wise operations (gates, activations, additions: about ``6 H + 4 Z + …`` per frame, < 1 %) are not
    counted either. Defaults: 636,416.
    """
    macs = sum(i * o for i, o in _mlp_sizes(config, "enc")) + sum(i * o for i, o in _mlp_sizes(config, "dec"))
    H = config.gru_hidden
    for layer in range(config.gru_layers):
        n_in = config.gru_input_size if layer == 0 else H
        macs += 3 * H * (n_in + H)
    macs += H * config.latent_size
    return int(macs)


def rtn_macs_per_frame(pose_size: int = 91, frame_encoder: tuple[int, ...] = (512, 512),
                       offset_encoder: tuple[int, ...] = (128, 128), target_encoder: tuple[int, ...] = (128, 128),
                       lstm_hidden: int = 512, decoder: tuple[int, ...] = (256, 128),
                       count_target_encoder: bool = False) -> int:
    """Multiply-accumulates per generated frame of the Recurrent Transition Network (Harvey & Pal 2018).

    Sizes as spec/qtg.md §5 states them (a third-party re-implementation, unverified):
    frame encoder ``P -> 512 -> 512``, offset encoder (target − current) ``P -> 128 -> 128``, target encoder
    ``P -> 128 -> 128``, one LSTM of 512 on the concatenation (768 inputs), decoder ``512 -> 256 -> 128 -> P``.
    The target encoding is constant over a transition and counted once per transition, i.e. not per frame,
    unless ``count_target_encoder``. Defaults: 3,133,696 (3,161,728 with the target encoder).
    """
    def mlp(n_in, sizes):
        dims = (n_in,) + tuple(sizes)
        return sum(a * b for a, b in zip(dims[:-1], dims[1:]))

    lstm_in = frame_encoder[-1] + offset_encoder[-1] + target_encoder[-1]
    macs = mlp(pose_size, frame_encoder) + mlp(pose_size, offset_encoder)
    macs += 4 * lstm_hidden * (lstm_in + lstm_hidden)
    macs += mlp(lstm_hidden, tuple(decoder) + (pose_size,))
    if count_target_encoder:
        macs += mlp(pose_size, target_encoder)
    return int(macs)


# ----------------------------------------------------------------------------------------------------------------
# building blocks: encoder and decoder MLPs (refimpl.nn.mlp)
# ----------------------------------------------------------------------------------------------------------------

def _encoder_forward(x, params, config):
    return mlp_forward(x, params, "enc", len(config.encoder_sizes), config.negative_slope, last_linear=False)


def _decoder_forward(x, params, config):
    return mlp_forward(x, params, "dec", len(config.decoder_sizes) + 1, config.negative_slope, last_linear=True)


def _mlp_backward(dy, cache, grads):
    """:func:`refimpl.nn.mlp.mlp_backward`, its parameter gradients added into ``grads``; returns ``dx``."""
    dx, g = mlp_backward(dy, cache)
    accumulate_grads(grads, g)
    return dx


# ----------------------------------------------------------------------------------------------------------------
# boundary checks (public names: refimpl.models.qtg_fast uses them)
# ----------------------------------------------------------------------------------------------------------------

def check_params(params: Mapping[str, np.ndarray], config: QTGConfig) -> np.dtype:
    if not isinstance(config, QTGConfig):
        raise ValueError(f"config: expected a QTGConfig, got {type(config).__name__}")
    shapes = param_shapes(config)
    # parameters beyond the config's are ignored here (unlike check_param_dict, which rejects them)
    return check_param_dict({k: v for k, v in params.items() if k in shapes}, shapes)


def check_context(past, target, config: QTGConfig, dtype) -> tuple[np.ndarray, np.ndarray]:
    P = config.pose_size
    past = float_array(past, "past", (None, 2, P), cast=False)
    target = float_array(target, "target", (None, 2, P), cast=False)
    if past.shape[0] != target.shape[0]:
        raise ValueError(f"target: expected batch size {past.shape[0]} like past, got shape {target.shape}")
    for name, a in (("past", past), ("target", target)):
        if a.dtype != dtype:
            raise ValueError(f"{name}: expected dtype {dtype} (the parameters' dtype), got {a.dtype}")
    return past, target


def check_length(T, config: QTGConfig) -> int:
    T = config.transition_length if T is None else T
    if not isinstance(T, (int, np.integer)) or T < 1:
        raise ValueError(f"T: expected a positive integer number of frames, got {T!r}")
    return int(T)


# ----------------------------------------------------------------------------------------------------------------
# the step
# ----------------------------------------------------------------------------------------------------------------

class QTGState(NamedTuple):
    """Recurrent state before generating frame ``t + 1``.

    Attributes
    ----------
    latent_prev : ndarray (B, Z)
        ``z_{t-1} = E(p_{t-1})``, the encoding of the second-latest pose.
    pose : ndarray (B, P)
        ``p_t``, the latest pose (given or generated), in the network's (normalised) pose space.
    hidden : ndarray (L, B, H)
        GRU state ``s_t`` (zeros at the start of a transition).
    """

    latent_prev: np.ndarray
    pose: np.ndarray
    hidden: np.ndarray


def encode(params: Mapping[str, np.ndarray], poses, config: QTGConfig = QTGConfig()) -> np.ndarray:
    """The pose encoder ``E`` (dense layers, LeakyReLU after each), over any leading axes.

    Parameters
    ----------
    poses : ndarray (..., P)

    Returns
    -------
    ndarray (..., Z)
    """
    dtype = check_params(params, config)
    poses = float_array(poses, "poses", (..., config.pose_size), cast=False)
    if poses.dtype != dtype:
        raise ValueError(f"poses: expected dtype {dtype} (the parameters' dtype), got {poses.dtype}")
    return _encoder_forward(poses, params, config)[0]


def init_state(params: Mapping[str, np.ndarray], past, target,
               config: QTGConfig = QTGConfig()) -> tuple[QTGState, np.ndarray]:
    """Initial state and target encodings of a transition (spec/qtg.md §3).

    Parameters
    ----------
    past : ndarray (B, 2, P)
        ``p_{-1}, p_0``, the two poses before the transition (normalised pose space).
    target : ndarray (B, 2, P)
        ``g1 = p_{T+1}, g2 = p_{T+2}``, the two poses after it.

    Returns
    -------
    state : QTGState
        ``(E(p_{-1}), p_0, zeros (L, B, H))``.
    target_latent : ndarray (B, 2, Z)
        ``[E(g1), E(g2)]``, constant over the transition.
    """
    dtype = check_params(params, config)
    past, target = check_context(past, target, config, dtype)
    ctx = np.concatenate([past[:, :1], target], axis=1)  # (B, 3, P): p_{-1}, g1, g2
    lat, _ = _encoder_forward(ctx, params, config)  # (B, 3, Z)
    hidden = np.zeros((config.gru_layers, past.shape[0], config.gru_hidden), dtype=dtype)  # (L, B, H)
    state = QTGState(np.ascontiguousarray(lat[:, 0]), np.ascontiguousarray(past[:, 1]), hidden)
    return state, np.ascontiguousarray(lat[:, 1:])


def step(params: Mapping[str, np.ndarray], state: QTGState, target_latent,
         config: QTGConfig = QTGConfig()) -> tuple[np.ndarray, QTGState]:
    """Generate one frame (spec/qtg.md §3); the function the ONNX exporter translates.

    ``z_t = E(p_t)``; ``x_t = [z_t − z_{t−1} | e1 − z_t | e2 − e1]``; ``s_{t+1} = GRU(x_t, s_t)``;
    ``p_{t+1} = D(z_t + W_v s_{t+1} + b_v)``.

    Parameters
    ----------
    params : dict
        From :func:`init_params` (float32 or float64).
    state : QTGState
        ``(latent_prev (B, Z), pose (B, P), hidden (L, B, H))``, from :func:`init_state` or the previous step.
    target_latent : ndarray (B, 2, Z)
        ``[E(g1), E(g2)]`` from :func:`init_state`.

    Returns
    -------
    pose_next : ndarray (B, P)
        ``p_{t+1}`` (normalised pose space; quaternions not normalised).
    state : QTGState
        ``(z_t, p_{t+1}, s_{t+1})``.
    """
    dtype = check_params(params, config)
    if not isinstance(state, tuple) or len(state) != 3:
        raise ValueError(f"state: expected a QTGState (latent_prev, pose, hidden), got {type(state).__name__}")
    Z, P, H, L = config.latent_size, config.pose_size, config.gru_hidden, config.gru_layers
    lat, pose, hid = state
    pose = float_array(pose, "state.pose", (None, P), cast=False)
    B = pose.shape[0]
    lat = float_array(lat, "state.latent_prev", (B, Z), cast=False)
    hid = float_array(hid, "state.hidden", (L, B, H), cast=False)
    tl = float_array(target_latent, "target_latent", (B, 2, Z), cast=False)
    for name, a in (("state.latent_prev", lat), ("state.pose", pose), ("state.hidden", hid), ("target_latent", tl)):
        if a.dtype != dtype:
            raise ValueError(f"{name}: expected dtype {dtype} (the parameters' dtype), got {a.dtype}")
    z, _ = _encoder_forward(pose, params, config)  # z_t (B, Z)
    e1, e2 = tl[:, 0], tl[:, 1]  # (B, Z) each
    x = np.concatenate([z - lat, e1 - z, e2 - e1], axis=-1)  # x_t (B, 3Z)
    y, hidden, _ = gru_step_forward(x, hid, params, "gru", num_layers=L)  # s_{t+1}: (B, H) top, (L, B, H)
    v, _ = linear_forward(y, params, "vel")  # v_t (B, Z)
    pose_next, _ = _decoder_forward(z + v, params, config)  # p_{t+1} (B, P)
    return pose_next, QTGState(z, pose_next, hidden)


# ----------------------------------------------------------------------------------------------------------------
# slow oracle
# ----------------------------------------------------------------------------------------------------------------

def _rollout_naive(params, past, target, T, config: QTGConfig = QTGConfig()) -> np.ndarray:
    """Per-sample, per-gate loop version of :func:`rollout_forward` written from the equations (test oracle)."""
    def lrelu(a):
        return np.where(a > 0, a, config.negative_slope * a)

    def enc(p):
        for i in range(len(config.encoder_sizes)):
            p = lrelu(params[f"enc.{i}.weight"] @ p + params[f"enc.{i}.bias"])
        return p

    def dec(z):
        n = len(config.decoder_sizes) + 1
        for i in range(n):
            z = params[f"dec.{i}.weight"] @ z + params[f"dec.{i}.bias"]
            if i < n - 1:
                z = lrelu(z)
        return z

    def sig(a):
        return 1.0 / (1.0 + np.exp(-a))

    H = config.gru_hidden
    B = past.shape[0]
    out = np.zeros((B, T, config.pose_size), dtype=np.float64)
    for b in range(B):
        z_prev, pose = enc(past[b, 0]), past[b, 1]
        e1, e2 = enc(target[b, 0]), enc(target[b, 1])
        s = [np.zeros(H) for _ in range(config.gru_layers)]
        for t in range(T):
            z = enc(pose)
            x = np.concatenate([z - z_prev, e1 - z, e2 - e1])
            for k in range(config.gru_layers):
                wi, wh = params[f"gru.weight_ih_l{k}"], params[f"gru.weight_hh_l{k}"]
                bi, bh = params[f"gru.bias_ih_l{k}"], params[f"gru.bias_hh_l{k}"]
                r = sig(wi[:H] @ x + bi[:H] + wh[:H] @ s[k] + bh[:H])
                u = sig(wi[H:2 * H] @ x + bi[H:2 * H] + wh[H:2 * H] @ s[k] + bh[H:2 * H])
                n = np.tanh(wi[2 * H:] @ x + bi[2 * H:] + r * (wh[2 * H:] @ s[k] + bh[2 * H:]))
                s[k] = (1 - u) * n + u * s[k]
                x = s[k]
            v = params["vel.weight"] @ s[-1] + params["vel.bias"]
            pose = dec(z + v)
            out[b, t] = pose
            z_prev = z
    return out


def _rollout_backward_per_step(params, past, target, dposes, config: QTGConfig = QTGConfig()):
    """Slow oracle for :func:`rollout_forward` + :func:`rollout_backward`: the per-step formulation.

    Built from the layers' public functions (``linear_*``, ``leaky_relu_*``, ``gru_step_*``) with per-step caches;
    every step's weight gradients are formed inside the reverse loop and summed (the implementation before the
    batched backward). ``dposes`` (B, T, P). Returns ``(poses (B, T, P), grads, dpast, dtarget)``.
    """
    B, T, _ = dposes.shape
    Z, L = config.latent_size, config.gru_layers
    ctx = np.concatenate([past[:, :1], target], axis=1)  # (B, 3, P): p_{-1}, g1, g2
    lat, c_ctx = _encoder_forward(ctx, params, config)  # (B, 3, Z)
    z_prev, e1, e2, pose = lat[:, 0], lat[:, 1], lat[:, 2], past[:, 1]
    hidden = np.zeros((L, B, config.gru_hidden), dtype=past.dtype)  # (L, B, H)
    poses, caches = [], []
    for _ in range(T):
        z, c_enc = _encoder_forward(pose, params, config)  # (B, Z)
        x = np.concatenate([z - z_prev, e1 - z, e2 - e1], axis=-1)  # (B, 3Z)
        y, hidden, c_gru = gru_step_forward(x, hidden, params, "gru", num_layers=L)  # (B, H)
        v, c_vel = linear_forward(y, params, "vel")  # (B, Z)
        pose, c_dec = _decoder_forward(z + v, params, config)  # (B, P)
        poses.append(pose)
        caches.append((c_enc, c_gru, c_vel, c_dec))
        z_prev = z
    grads: dict[str, np.ndarray] = {}
    dpose = dlatent = dhidden = None
    dtarget_latent = 0.0
    for t in range(T - 1, -1, -1):
        c_enc, c_gru, c_vel, c_dec = caches[t]
        dp = dposes[:, t] if dpose is None else dposes[:, t] + dpose  # (B, P)
        dzv = _mlp_backward(dp, c_dec, grads)  # (B, Z): d(z_t + v_t)
        dy, g = linear_backward(dzv, c_vel)  # (B, H)
        accumulate_grads(grads, g)
        dx, dhidden, _ = gru_step_backward(dy, dhidden, c_gru, accumulate_into=grads)  # (B, 3Z), (L, B, H)
        dx_vel, dx_off, dx_tgt = dx[:, :Z], dx[:, Z:2 * Z], dx[:, 2 * Z:]
        dz = dzv + dx_vel - dx_off
        if dlatent is not None:
            dz += dlatent
        dlatent = -dx_vel
        dtarget_latent = dtarget_latent + np.stack([dx_off - dx_tgt, dx_tgt], axis=1)  # (B, 2, Z)
        dpose = _mlp_backward(dz, c_enc, grads)  # (B, P)
    dctx = _mlp_backward(np.concatenate([dlatent[:, None], dtarget_latent], axis=1), c_ctx, grads)  # (B, 3, P)
    return np.stack(poses, axis=1), grads, np.stack([dctx[:, 0], dpose], axis=1), dctx[:, 1:]
