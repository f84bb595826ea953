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
``p_1 … p_T``. Backward (:func:`rollout_backward`) runs the steps in reverse; gradients flow through the
fed-back poses, the carried latents, the GRU state and the target encodings (BPTT, no detaching). The training
path keeps every layer's inputs time-major (``_Record``); the reverse loop propagates only the input and state
cotangents and keeps the pre-activation cotangents, and each weight gradient is then ONE matrix product over the
stacked rows of all steps (``_weight_grads``). ``_rollout_backward_per_step`` is the per-step test oracle.

Shape legend: B batch, T transition frames, P pose size, Z latent size, H GRU hidden size, L GRU layers.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, NamedTuple

import numpy as np

from refimpl.nn.activations import leaky_relu_backward, leaky_relu_forward
from refimpl.nn.gru import _cell_backward, _cell_forward, _input_gates, gru_init, gru_step_backward, gru_step_forward
from refimpl.nn.linear import _matmul_wt, linear_backward, linear_forward, linear_init
from refimpl.nn.params import check_float_array

__all__ = [
    "QTGConfig", "QTGState", "QTGInference", "init_params", "count_parameters", "param_shapes",
    "encode", "init_state", "step", "rollout_forward", "rollout_backward",
    "prepare_inference", "rollout_inference", "macs_per_frame", "rtn_macs_per_frame",
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

    Sizes from the reference notes (dualquat_acrnn_qtg.md §3.3; a third-party re-implementation, unverified):
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
# building blocks: encoder and decoder MLPs
# ----------------------------------------------------------------------------------------------------------------

def _mlp_forward(x, params, prefix, n_layers, slope, last_linear):
    """Dense layers ``{prefix}.0 … {prefix}.{n-1}``, LeakyReLU after each (except the last when ``last_linear``)."""
    caches = []
    for i in range(n_layers):
        x, c_lin = linear_forward(x, params, f"{prefix}.{i}")
        c_act = None
        if not (last_linear and i == n_layers - 1):
            x, c_act = leaky_relu_forward(x, slope)
        caches.append((c_lin, c_act))
    return x, caches


def _mlp_backward(dy, caches, grads):
    """Backward of :func:`_mlp_forward`; adds the parameter gradients into ``grads`` and returns ``dx``."""
    for c_lin, c_act in reversed(caches):
        if c_act is not None:
            dy = leaky_relu_backward(dy, c_act)
        dy, g = linear_backward(dy, c_lin)
        _accumulate(grads, g)
    return dy


def _accumulate(total: dict, g: Mapping[str, np.ndarray]) -> None:
    """``total[k] += g[k]`` (first occurrence copied), for parameters used at every step."""
    for k, v in g.items():
        if k in total:
            total[k] += v
        else:
            total[k] = np.array(v, copy=True)


def _encoder_forward(x, params, config):
    return _mlp_forward(x, params, "enc", len(config.encoder_sizes), config.negative_slope, last_linear=False)


def _decoder_forward(x, params, config):
    return _mlp_forward(x, params, "dec", len(config.decoder_sizes) + 1, config.negative_slope, last_linear=True)


# ----------------------------------------------------------------------------------------------------------------
# public boundary checks
# ----------------------------------------------------------------------------------------------------------------

def _check_params(params: Mapping[str, np.ndarray], config: QTGConfig) -> np.dtype:
    if not isinstance(config, QTGConfig):
        raise ValueError(f"config: expected a QTGConfig, got {type(config).__name__}")
    dtype = None
    for name, shape in param_shapes(config).items():
        if name not in params:
            raise ValueError(f"params: missing parameter {name!r} (expected shape {shape})")
        a = params[name]
        if not isinstance(a, np.ndarray) or a.shape != shape:
            raise ValueError(f"params[{name!r}]: expected shape {shape}, got {np.shape(a)}")
        if dtype is None:
            dtype = a.dtype
        elif a.dtype != dtype:
            raise ValueError(f"params[{name!r}]: expected dtype {dtype} like the other parameters, got {a.dtype}")
    if dtype not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise ValueError(f"params: expected float32 or float64 arrays, got {dtype}")
    return dtype


def _check_context(past, target, config: QTGConfig, dtype) -> tuple[np.ndarray, np.ndarray]:
    P = config.pose_size
    past = check_float_array(past, "past", (None, 2, P))
    target = check_float_array(target, "target", (None, 2, P))
    if past.shape[0] != target.shape[0]:
        raise ValueError(f"target: expected batch size {past.shape[0]} like past, got shape {target.shape}")
    for name, a in (("past", past), ("target", target)):
        if a.dtype != dtype:
            raise ValueError(f"{name}: expected dtype {dtype} (the parameters' dtype), got {a.dtype}")
    return past, target


def _check_length(T, config: QTGConfig) -> int:
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
    dtype = _check_params(params, config)
    poses = check_float_array(poses, "poses", (..., config.pose_size))
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
    dtype = _check_params(params, config)
    past, target = _check_context(past, target, config, dtype)
    state, target_latent, _ = _init_forward(params, past, target, config)
    return state, target_latent


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
    dtype = _check_params(params, config)
    if not isinstance(state, tuple) or len(state) != 3:
        raise ValueError(f"state: expected a QTGState (latent_prev, pose, hidden), got {type(state).__name__}")
    Z, P, H, L = config.latent_size, config.pose_size, config.gru_hidden, config.gru_layers
    lat, pose, hid = state
    pose = check_float_array(pose, "state.pose", (None, P))
    B = pose.shape[0]
    lat = check_float_array(lat, "state.latent_prev", (B, Z))
    hid = check_float_array(hid, "state.hidden", (L, B, H))
    tl = check_float_array(target_latent, "target_latent", (B, 2, Z))
    for name, a in (("state.latent_prev", lat), ("state.pose", pose), ("state.hidden", hid), ("target_latent", tl)):
        if a.dtype != dtype:
            raise ValueError(f"{name}: expected dtype {dtype} (the parameters' dtype), got {a.dtype}")
    pose_next, new_state, _ = _step_forward(params, QTGState(lat, pose, hid), tl, config)
    return pose_next, new_state


# ----------------------------------------------------------------------------------------------------------------
# the training path: time-major records of a rollout, per-step kernels (spec/qtg.md §3, §4)
# ----------------------------------------------------------------------------------------------------------------

class _Weights(NamedTuple):
    """The parameters a rollout reads, looked up once (the arrays of ``params``, PyTorch layouts, no copies)."""

    enc: tuple  # ((W (n_{i+1}, n_i), b (n_{i+1},)), ...): encoder layers, LeakyReLU after each
    gru: tuple  # ((W_ih (3H, I_k), W_hh (3H, H), b_ih (3H,), b_hh (3H,)), ...): one per GRU layer
    vel: tuple  # (W_v (Z, H), b_v (Z,)): velocity head, linear
    dec: tuple  # ((W (m_{j+1}, m_j), b), ...): decoder layers, LeakyReLU after each but the last
    slope: np.floating  # LeakyReLU negative slope, in the parameters' dtype


def _gather_weights(params: Mapping[str, np.ndarray], config: QTGConfig) -> _Weights:
    def dense(prefix, n):
        return tuple((params[f"{prefix}.{i}.weight"], params[f"{prefix}.{i}.bias"]) for i in range(n))

    gru = tuple(tuple(params[f"gru.{name}_l{k}"] for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"))
                for k in range(config.gru_layers))
    slope = params["vel.weight"].dtype.type(config.negative_slope)
    return _Weights(dense("enc", len(config.encoder_sizes)), gru, (params["vel.weight"], params["vel.bias"]),
                    dense("dec", len(config.decoder_sizes) + 1), slope)


class _Record(NamedTuple):
    """Every layer's input at every step of a rollout, time-major (the cache :func:`rollout_backward` reads).

    Encoder arrays are stacked in blocks of B rows: block 0 ``g1``, block 1 ``g2``, block 2 ``p_{-1}`` (the
    context, encoded once), block ``3 + t`` the pose ``p_t`` that step t encodes. ``enc[0]`` has one more block,
    ``T + 3``, for the last generated pose ``p_T``. So ``enc[-1]`` holds ``e1, e2, z_{-1}, z_0 … z_{T-1}``: step t
    reads ``z_{t-1}`` from block ``2 + t`` and writes ``z_t`` into block ``3 + t``, and its decoder writes
    ``p_{t+1}`` into block ``4 + t`` of ``enc[0]``, the next step's input. With the context blocks first, the rows
    of every encoder layer's weight gradient (context and all steps) are one contiguous ``((T + 3) B, n)`` slice.
    A LeakyReLU's derivative is read from its output (``y > 0`` iff its input ``> 0``, for ``0 <= slope``), i.e.
    from the next layer's input: no masks are stored.
    """

    enc: list  # enc[i] (T + 3, B, n_i): input of encoder layer i (enc[0] has T + 4 blocks); enc[-1]: latents
    gru_x: np.ndarray  # (T, B, 3Z): x_t = [z_t − z_{t−1} | e1 − z_t | e2 − e1]
    hidden: np.ndarray  # (T + 1, L, B, H): s_t of every layer, s_0 = 0
    gates: np.ndarray  # (L, T, B, 3H): [r | u | W_hn s_t + b_hn] (refimpl.nn.gru._cell_forward)
    cand: np.ndarray  # (L, T, B, H): the candidate state n
    dec: list  # dec[j] (T, B, m_j): input of decoder layer j; dec[0] = z_t + v_t


def _new_record(B: int, T: int, config: QTGConfig, dtype) -> _Record:
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers
    hidden = np.empty((T + 1, L, B, H), dtype=dtype)  # (T + 1, L, B, H)
    hidden[0] = 0
    return _Record(
        enc=[np.empty((T + (4 if i == 0 else 3), B, n), dtype=dtype)
             for i, n in enumerate((config.pose_size,) + config.encoder_sizes)],
        gru_x=np.empty((T, B, 3 * Z), dtype=dtype), hidden=hidden,
        gates=np.empty((L, T, B, 3 * H), dtype=dtype), cand=np.empty((L, T, B, H), dtype=dtype),
        dec=[np.empty((T, B, m), dtype=dtype) for m in (Z,) + config.decoder_sizes])


def _dense(x, weight, bias, slope, out):
    """``out = x Wᵀ + b`` (x (N, I), out (N, O)), then LeakyReLU in place unless ``slope`` is None.

    ``max(a, slope a)`` equals ``a`` for ``a > 0`` and ``slope a`` otherwise, since ``0 <= slope < 1``."""
    _matmul_wt(x, weight, out=out)
    out += bias
    if slope is not None:
        np.maximum(out, out * slope, out=out)
    return out


def _leaky_backward(dy, y, slope, out):
    """``out = dy`` where the LeakyReLU output ``y > 0``, ``slope dy`` elsewhere (its input cotangent).

    Computed as ``dy · max([y > 0], slope)``: the factor is exactly 1 or ``slope`` (``out`` must not be ``dy``)."""
    np.greater(y, 0, out=out)
    np.maximum(out, slope, out=out)
    return np.multiply(out, dy, out=out)


def _encode_context(w: _Weights, rec: _Record, past, target) -> None:
    """Blocks 0-3 of ``rec.enc[0]`` = ``g1, g2, p_{-1}, p_0``; one encoder pass over blocks 0-2 (3B rows)."""
    B = past.shape[0]
    rec.enc[0][0:2] = target.transpose(1, 0, 2)  # g1, g2
    rec.enc[0][2:4] = past.transpose(1, 0, 2)  # p_{-1}, p_0
    x = rec.enc[0][:3].reshape(3 * B, past.shape[2])  # (3B, P)
    for i, (weight, bias) in enumerate(w.enc):
        x = _dense(x, weight, bias, w.slope, rec.enc[i + 1][:3].reshape(3 * B, weight.shape[0]))


def _init_forward(params, past, target, config, T: int = 0):
    """Record of a ``T``-step rollout with its context encoded: ``(state, target_latent, (weights, record))``."""
    w = _gather_weights(params, config)
    rec = _new_record(past.shape[0], T, config, past.dtype)
    _encode_context(w, rec, past, target)
    latents = rec.enc[-1]  # (T + 3, B, Z)
    state = QTGState(latents[2], rec.enc[0][3], rec.hidden[0])  # (z_{-1}, p_0, 0): views of the record
    return state, np.ascontiguousarray(latents[:2].transpose(1, 0, 2)), (w, rec)


def _step_into(w: _Weights, rec: _Record, t: int) -> np.ndarray:
    """Step t of the rollout held in ``rec`` (spec/qtg.md §3).

    Reads ``p_t``, ``z_{t-1}``, ``s_t`` and the target latents from ``rec``, writes every layer's output of the
    step into it and returns ``p_{t+1}`` (B, P), a view of block ``4 + t`` of ``rec.enc[0]``.
    """
    x = rec.enc[0][3 + t]  # p_t (B, P)
    for i, (weight, bias) in enumerate(w.enc):
        x = _dense(x, weight, bias, w.slope, rec.enc[i + 1][3 + t])
    latents = rec.enc[-1]
    z, z_prev, e1, e2 = x, latents[2 + t], latents[0], latents[1]  # (B, Z) each
    Z = z.shape[1]
    x_t = rec.gru_x[t]  # (B, 3Z)
    np.subtract(z, z_prev, out=x_t[:, :Z])
    np.subtract(e1, z, out=x_t[:, Z:2 * Z])
    np.subtract(e2, e1, out=x_t[:, 2 * Z:])
    inp = x_t
    for k, (w_ih, w_hh, b_ih, b_hh) in enumerate(w.gru):
        H = w_hh.shape[1]
        gi = _input_gates(inp, w_ih, b_ih, b_hh, H)  # (B, 3H)
        _cell_forward(gi, rec.hidden[t, k], w_hh, None, b_hh[2 * H:], rec.gates[k, t], rec.cand[k, t],
                      rec.hidden[t + 1, k])
        inp = rec.hidden[t + 1, k]  # s_{t+1} of layer k (B, H)
    h = _dense(inp, *w.vel, None, rec.dec[0][t])  # v_t (B, Z)
    h += z  # z_t + v_t
    last = len(w.dec) - 1
    for j, (weight, bias) in enumerate(w.dec):
        h = _dense(h, weight, bias, None if j == last else w.slope,
                   rec.enc[0][4 + t] if j == last else rec.dec[j + 1][t])
    return h  # p_{t+1} (B, P)


def _step_forward(params, state: QTGState, target_latent, config: QTGConfig):
    """One QTG step with its record: ``(p_{t+1}, new state, (weights, record))`` (spec/qtg.md §3).

    The same kernel as :func:`rollout_forward`'s steps (:func:`_step_into`), on a one-step record."""
    w = _gather_weights(params, config)
    rec = _new_record(state.pose.shape[0], 1, config, state.pose.dtype)
    rec.enc[-1][0:2] = np.asarray(target_latent).transpose(1, 0, 2)  # e1, e2
    rec.enc[-1][2] = state.latent_prev
    rec.enc[0][3] = state.pose
    rec.hidden[0] = state.hidden
    pose = _step_into(w, rec, 0)  # (B, P)
    return pose, QTGState(rec.enc[-1][3], pose, rec.hidden[1]), (w, rec)


class _Cotangents(NamedTuple):
    """Per-step cotangents of every layer's pre-activations, time-major; each pairs with a :class:`_Record` array
    for the weight gradients formed after the reverse loop."""

    enc: list  # enc[i] (T + 3, B, n_{i+1}): encoder layer i (blocks as in _Record); pairs with rec.enc[i]
    gru_in: np.ndarray  # (L, T, B, 3H): [da_r | da_u | da_n], pairs with the layer's input (x_t or s_{t+1} below)
    gru_hh: np.ndarray  # (L, T, B, 3H): [da_r | da_u | r da_n], pairs with rec.hidden[:-1] (s_t)
    vel: np.ndarray  # (T, B, Z): cotangent of z_t + v_t (the velocity head's output); pairs with s_{t+1} (top)
    dec: list  # dec[j] (T, B, m_{j+1}): decoder layer j; the last one is the total cotangent of p_{t+1}


def _new_cotangents(B: int, T: int, config: QTGConfig, dtype) -> _Cotangents:
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers
    return _Cotangents(
        enc=[np.empty((T + 3, B, n), dtype=dtype) for n in config.encoder_sizes],
        gru_in=np.empty((L, T, B, 3 * H), dtype=dtype), gru_hh=np.empty((L, T, B, 3 * H), dtype=dtype),
        vel=np.empty((T, B, Z), dtype=dtype),
        dec=[np.empty((T, B, m), dtype=dtype) for m in config.decoder_sizes + (config.pose_size,)])


def _step_backward(w: _Weights, rec: _Record, cot: _Cotangents, t: int, dhidden, dlatent, tmp, need_dpose: bool):
    """Backward of step t (spec/qtg.md §4): only the sequential input and state cotangents, no weight gradients.

    On entry ``cot.dec[-1][t]`` holds the total cotangent of ``p_{t+1}``, ``dhidden`` (L, B, H) that of
    ``s_{t+1}``, and ``dlatent`` (B, Z) or None that of ``z_t`` from step t + 1. Writes the step's pre-activation
    cotangents into ``cot``, overwrites ``dhidden`` with the cotangent of ``s_t`` (``tmp`` (B, H) is scratch) and
    returns ``(dz_{t-1} (B, Z), dp_t (B, P) or None unless need_dpose)``.
    """
    last = len(w.dec) - 1
    dy = cot.dec[last][t]  # (B, P)
    for j in range(last, -1, -1):
        if j < last:
            dy = _leaky_backward(dy, rec.dec[j + 1][t], w.slope, cot.dec[j][t])
        dy = np.matmul(dy, w.dec[j][0], out=cot.vel[t] if j == 0 else None)  # (B, m_j)
    dzv = dy  # (B, Z): d(z_t + v_t) = dv_t
    d_out = dzv @ w.vel[0]  # (B, H): ds_{t+1} (top layer) from the velocity head
    for k in range(len(w.gru) - 1, -1, -1):
        w_ih, w_hh = w.gru[k][:2]
        dh = dhidden[k]  # (B, H)
        dh += d_out
        _cell_backward(dh, rec.hidden[t, k], rec.gates[k, t], rec.cand[k, t], w_hh, cot.gru_in[k, t],
                       cot.gru_hh[k, t], tmp)
        if k > 0:
            d_out = cot.gru_in[k, t] @ w_ih  # (B, H): cotangent of the output of layer k − 1
    Z = dzv.shape[1]
    # dx_t[vel], dx_t[off] only; e1 and e2 get Σ_t dx_t, formed once after the loop
    dx = cot.gru_in[0, t] @ w.gru[0][0][:, :2 * Z]  # (B, 2Z)
    dx_vel, dx_off = dx[:, :Z], dx[:, Z:]  # (B, Z) each
    dz = dzv + dx_vel  # dz_t = d(z_t + v_t) + dx_t[vel] − dx_t[off] (+ from step t + 1)
    dz -= dx_off
    if dlatent is not None:
        dz += dlatent
    dy = dz
    for i in range(len(w.enc) - 1, -1, -1):
        da = _leaky_backward(dy, rec.enc[i + 1][3 + t], w.slope, cot.enc[i][3 + t])  # (B, n_{i+1})
        dy = da @ w.enc[i][0] if i > 0 or need_dpose else None  # (B, n_i)
    return -dx_vel, dy


def _weight_grads(w: _Weights, rec: _Record, cot: _Cotangents) -> dict[str, np.ndarray]:
    """Every parameter's gradient, formed once per rollout: ONE product over all stacked rows per weight.

    ``dW = Σ_rows da ⊗ x`` over the T·B step rows (and the 3B context rows for the encoder), ``db = Σ_rows da``.
    """
    def rows(a):
        return a.reshape(-1, a.shape[-1])

    grads: dict[str, np.ndarray] = {}

    def dense(name, da, x):
        da = rows(da)  # (N, O)
        grads[f"{name}.weight"] = da.T @ rows(x)  # (O, I)
        grads[f"{name}.bias"] = da.sum(axis=0)  # (O,)

    T = rec.gru_x.shape[0]
    for i in range(len(w.enc)):
        dense(f"enc.{i}", cot.enc[i], rec.enc[i][:T + 3])
    for k in range(len(w.gru)):
        dgi, dgh = rows(cot.gru_in[k]), rows(cot.gru_hh[k])  # (T B, 3H)
        x = rec.gru_x if k == 0 else rec.hidden[1:, k - 1]  # (T, B, I_k)
        grads[f"gru.weight_ih_l{k}"] = dgi.T @ rows(x)
        grads[f"gru.weight_hh_l{k}"] = dgh.T @ rows(rec.hidden[:-1, k])
        grads[f"gru.bias_ih_l{k}"] = dgi.sum(axis=0)
        grads[f"gru.bias_hh_l{k}"] = dgh.sum(axis=0)
    dense("vel", cot.vel, rec.hidden[1:, -1])
    for j in range(len(w.dec)):
        dense(f"dec.{j}", cot.dec[j], rec.dec[j])
    return grads


# ----------------------------------------------------------------------------------------------------------------
# rollout: forward and backward
# ----------------------------------------------------------------------------------------------------------------

def rollout_forward(params: Mapping[str, np.ndarray], past, target, T: int | None = None,
                    config: QTGConfig = QTGConfig()):
    """Generate a whole transition, feeding each decoded pose back (spec/qtg.md §3).

    Parameters
    ----------
    params : dict
    past : ndarray (B, 2, P)
        ``p_{-1}, p_0`` (normalised pose space: root translation z-normalised, quaternions raw).
    target : ndarray (B, 2, P)
        ``g1 = p_{T+1}, g2 = p_{T+2}``.
    T : int, optional
        Frames to generate (default ``config.transition_length``).
    config : QTGConfig

    Returns
    -------
    poses : ndarray (B, T, P)
        ``p_1 … p_T``.
    cache : dict
        For :func:`rollout_backward` (every layer's input at every step, time-major; it references ``params``,
        which must not be modified before the backward).
    """
    dtype = _check_params(params, config)
    past, target = _check_context(past, target, config, dtype)
    T = _check_length(T, config)
    _, _, (w, rec) = _init_forward(params, past, target, config, T)
    for t in range(T):
        _step_into(w, rec, t)
    B = past.shape[0]
    poses = np.ascontiguousarray(rec.enc[0][4:].transpose(1, 0, 2))  # (B, T, P), not a view of the cache
    return poses, {"weights": w, "record": rec, "config": config, "shape": (B, T, config.pose_size)}


def rollout_backward(dposes, cache, *, input_grads: bool = False):
    """Backpropagation through the whole rollout (BPTT through all steps; spec/qtg.md §4).

    The reverse loop over the steps propagates only the input and state cotangents (they are sequential) and
    keeps every layer's pre-activation cotangents; after the loop, each weight gradient is ONE matrix product
    over the stacked rows of all steps (for the encoder, also the context rows), each bias gradient one sum.

    Parameters
    ----------
    dposes : ndarray (B, T, P)
        Cotangent of the generated poses (e.g. from ``mae_loss_backward``), finite, in the parameters' dtype.
    cache : dict
        From :func:`rollout_forward` (not modified: it can be back-propagated again).
    input_grads : bool
        Also return the gradients with respect to ``past`` and ``target``.

    Returns
    -------
    grads : dict
        One array per parameter, same names, shapes and dtype as the parameters.
    dpast, dtarget : ndarray (B, 2, P)
        Only when ``input_grads``.
    """
    shape, w, rec, config = cache["shape"], cache["weights"], cache["record"], cache["config"]
    dtype = rec.gru_x.dtype
    dposes = check_float_array(dposes, "dposes", shape)
    if dposes.dtype != dtype:
        raise ValueError(f"dposes: expected dtype {dtype} (the parameters' dtype), got {dposes.dtype}")
    B, T, P = shape
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers
    cot = _new_cotangents(B, T, config, dtype)
    dhidden = np.zeros((L, B, H), dtype=dtype)  # cotangent of s_{t+1}, then of s_t
    tmp = np.empty((B, H), dtype=dtype)
    dlatent = None  # cotangent of z_t from its use as step t+1's z_{t-1}
    dpose = None  # cotangent of p_{t+1} from its use as step t+1's input pose
    for t in range(T - 1, -1, -1):
        dp = cot.dec[-1][t]  # (B, P): total cotangent of p_{t+1}
        if dpose is None:
            dp[...] = dposes[:, t]
        else:
            np.add(dposes[:, t], dpose, out=dp)
        dlatent, dpose = _step_backward(w, rec, cot, t, dhidden, dlatent, tmp, need_dpose=t > 0 or input_grads)
    # the context latents e1, e2 (used by every x_t) and z_{-1} (step 0), back through the initial encoder pass
    dx = cot.gru_in[0].sum(axis=0) @ w.gru[0][0]  # (B, 3Z): Σ_t dx_t = (Σ_t [da_r | da_u | da_n]_t) W_ih
    dy = np.concatenate([dx[:, Z:2 * Z] - dx[:, 2 * Z:], dx[:, 2 * Z:], dlatent])  # (3B, Z): de1, de2, dz_{-1}
    for i in range(len(w.enc) - 1, -1, -1):
        n = w.enc[i][0].shape[0]
        da = _leaky_backward(dy, rec.enc[i + 1][:3].reshape(3 * B, n), w.slope, cot.enc[i][:3].reshape(3 * B, n))
        dy = da @ w.enc[i][0] if i > 0 or input_grads else None  # (3B, n_i)
    grads = _weight_grads(w, rec, cot)
    if not input_grads:
        return grads
    dctx = dy.reshape(3, B, P)  # g1, g2, p_{-1}
    dpast = np.stack([dctx[2], dpose], axis=1)  # (B, 2, P)
    return grads, dpast, np.ascontiguousarray(dctx[:2].transpose(1, 0, 2))


# ----------------------------------------------------------------------------------------------------------------
# lean inference path (no caches; weights folded, transposed and bias-augmented once; buffers reused per step)
# ----------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class QTGInference:
    """Weights rearranged for fast inference by :func:`prepare_inference` (read-only arrays; spec/qtg.md §6).

    Matrices are stored transposed and, where a bias follows, *bias-augmented*: ``A = [Wᵀ ; bᵀ]``
    ``(in + 1, out)``, so that ``[x | 1] A = x Wᵀ + b``. With ``W_ih = [W1 | W2 | W3]`` the column blocks of the
    first GRU layer's input weight (acting on the three parts of ``x_t``), and every ``r, z`` gate column
    pre-multiplied by ½:

    * ``enc``, ``dec``: the encoder and decoder layers, ``(n_i + 1, n_{i+1})`` each.
    * ``z_product`` ``(Z, 6H)``: ``[(W1 − W2)ᵀ | W1ᵀ]``.
    * ``target_product`` ``(2Z + 1, 3H)``: ``[W2ᵀ ; W3ᵀ ; b_ih0ᵀ]`` (``b_ih0`` is ``b_ih`` with ``b_hr, b_hz``
      added), for the constant target term ``k = W2 e1 + W3 (e2 − e1) + b_ih0`` of a transition.
    * ``upper_ih``, ``lower_hh``: ``W_ih`` of layers 1 … L−1 (bias row ``b_ih + [b_hr, b_hz, 0]``) and ``W_hh``
      of layers 0 … L−2 (bias row ``[0, 0, b_hn]``).
    * ``h_product`` ``(H + 1, 3H + Z)``: the top layer's ``[W_hhᵀ | W_vᵀ]``, bias row ``[0, 0, b_hn | b_v]``:
      one product of the new state gives the velocity ``v_t`` and the next step's ``W_hh s``.
    """

    config: QTGConfig
    enc: tuple
    z_product: np.ndarray
    target_product: np.ndarray
    upper_ih: tuple
    lower_hh: tuple
    h_product: np.ndarray
    dec: tuple

    @property
    def dtype(self) -> np.dtype:
        """The dtype of every weight (that of the parameters given to :func:`prepare_inference`)."""
        return self.z_product.dtype


def prepare_inference(params: Mapping[str, np.ndarray], config: QTGConfig = QTGConfig()) -> QTGInference:
    """Rearrange ``params`` for :func:`rollout_inference` (transposed, bias-augmented, contiguous; same dtype).

    Exact rewrites (spec/qtg.md §6):

    1. ``W_ih x_t + b_ih = (W1 − W2) z_t + c_t`` with ``c_t = k − W1 z_{t−1}``: one product of ``z_t`` gives this
       step's ``(W1 − W2) z_t`` and the next step's ``W1 z_t``.
    2. One product of the top layer's new state ``s`` gives ``W_v s + b_v`` and the next step's
       ``W_hh s + (0, 0, b_hn)`` (``b_hr, b_hz`` are in ``k``).
    3. ``σ(a) = ½ + ½ tanh(a/2)``: the ``r, z`` columns are halved (exact in binary floating point).
    4. Biases ride in an extra weight row, multiplied by a constant 1 column of the input buffers.
    """
    dtype = _check_params(params, config)
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers

    def ro(a):
        a = np.ascontiguousarray(a, dtype=dtype)
        a.setflags(write=False)
        return a

    def aug(wT, b):  # [Wᵀ ; bᵀ] (in + 1, out)
        return ro(np.concatenate([wT, np.asarray(b)[None, :]], axis=0))

    def half_rz(a):  # a (..., 3H) with gate blocks r | z | n along the last axis: halve r and z
        a = np.array(a, copy=True)
        a[..., :2 * H] *= 0.5
        return a

    def b_hh_n(layer):  # [0, 0, b_hn]
        return np.concatenate([np.zeros(2 * H, dtype=dtype), params[f"gru.bias_hh_l{layer}"][2 * H:]])

    def b_ih_rz(layer):  # b_ih + [b_hr, b_hz, 0]
        b = params[f"gru.bias_ih_l{layer}"].copy()
        b[:2 * H] += params[f"gru.bias_hh_l{layer}"][:2 * H]
        return half_rz(b)

    def dense(prefix, n):
        return tuple(aug(params[f"{prefix}.{i}.weight"].T, params[f"{prefix}.{i}.bias"]) for i in range(n))

    w_ih = params["gru.weight_ih_l0"]  # (3H, 3Z)
    w1, w2, w3 = w_ih[:, :Z], w_ih[:, Z:2 * Z], w_ih[:, 2 * Z:]
    top = L - 1
    return QTGInference(
        config=config,
        enc=dense("enc", len(config.encoder_sizes)),
        z_product=ro(np.concatenate([half_rz((w1 - w2).T), half_rz(w1.T)], axis=1)),
        target_product=aug(half_rz(np.concatenate([w2.T, w3.T], axis=0)), b_ih_rz(0)),
        upper_ih=tuple(aug(half_rz(params[f"gru.weight_ih_l{k}"].T), b_ih_rz(k)) for k in range(1, L)),
        lower_hh=tuple(aug(half_rz(params[f"gru.weight_hh_l{k}"].T), b_hh_n(k)) for k in range(L - 1)),
        h_product=aug(np.concatenate([half_rz(params[f"gru.weight_hh_l{top}"].T), params["vel.weight"].T], axis=1),
                      np.concatenate([b_hh_n(top), params["vel.bias"]])),
        dec=dense("dec", len(config.decoder_sizes) + 1))


def _augmented(B: int, n: int, dtype) -> tuple[np.ndarray, np.ndarray]:
    """A buffer ``(B, n + 1)`` whose last column is 1, and the view of its first ``n`` columns."""
    a = np.empty((B, n + 1), dtype=dtype)
    a[:, n] = 1
    return a, a[:, :n]


def rollout_inference(model: QTGInference, past, target, T: int | None = None) -> np.ndarray:
    """Same result as :func:`rollout_forward` (up to rounding), without caches, for deployment and benchmarks.

    Parameters
    ----------
    model : QTGInference
        From :func:`prepare_inference`.
    past, target : ndarray (B, 2, P)
        Same dtype as the model's weights.
    T : int, optional

    Returns
    -------
    poses : ndarray (B, T, P)

    Notes
    -----
    Every per-step array is allocated once per call, with its views, and written in place (``out=``); the
    inputs of the dense layers carry a constant 1 column so that the bias rows of the augmented weights add
    the biases. Per step (default sizes): 6 matrix products and 19 element-wise calls (spec/qtg.md §6).
    """
    if not isinstance(model, QTGInference):
        raise ValueError(f"model: expected a QTGInference from prepare_inference, got {type(model).__name__}")
    config, dtype = model.config, model.dtype
    past, target = _check_context(past, target, config, dtype)
    T = _check_length(T, config)
    B, P, Z, H, L = past.shape[0], config.pose_size, config.latent_size, config.gru_hidden, config.gru_layers
    H2, H3 = 2 * H, 3 * H
    matmul, maximum, multiply, add, subtract, tanh = np.matmul, np.maximum, np.multiply, np.add, np.subtract, np.tanh
    slope = dtype.type(config.negative_slope)

    def encode_(x):  # context poses only
        for a in model.enc:
            x = matmul(x, a[:-1])
            add(x, a[-1], out=x)
            maximum(x, multiply(x, slope), out=x)
        return x

    ctx = encode_(np.concatenate([past[:, 0], target[:, 0], target[:, 1]], axis=0))  # (3B, Z)
    z_prev, e1, e2 = ctx[:B], ctx[B:2 * B], ctx[2 * B:]
    targets = np.concatenate([e1, e2 - e1, np.ones((B, 1), dtype=dtype)], axis=1)  # (B, 2Z + 1)
    k = targets @ model.target_product  # (B, 3H): k = W2 e1 + W3 (e2 − e1) + b_ih0, constant over the transition
    c = k - z_prev @ model.z_product[:, H3:]  # (B, 3H): c_t = k − W1 z_{t−1}

    # buffers and their views, allocated once; the loop only calls NumPy kernels with out=
    frames = np.empty((T + 1, B, P + 1), dtype=dtype)  # [p_t | 1], t = 0 … T
    frames[..., P] = 1
    frames[0, :, :P] = past[:, 1]
    layers = []  # (augmented weight, pre-activation, scratch, output view, next input) of the LeakyReLU layers
    n_enc = len(model.enc)
    dense_in = [_augmented(B, a.shape[0] - 1, dtype) for a in model.enc[1:] + model.dec]
    z = np.empty((B, Z), dtype=dtype)
    for i, a in enumerate(model.enc + model.dec[:-1]):
        nxt, dst = (z, z) if i == n_enc - 1 else dense_in[i]
        layers.append((a, np.empty((B, a.shape[1]), dtype=dtype), np.empty((B, a.shape[1]), dtype=dtype), dst, nxt))
    enc_layers, dec_layers = layers[:n_enc], layers[n_enc:]
    dec_first = dense_in[n_enc - 1]  # [z_t + v_t | 1] and its first Z columns
    dec_last = model.dec[-1]
    slopes = {m: np.full((B, m), slope, dtype=dtype) for m in {lay[1].shape[1] for lay in layers}}
    zz = np.empty((B, 6 * H), dtype=dtype)  # [(W1 − W2) z_t | W1 z_t] (r, z halved)
    zz_a, zz_b = zz[:, :H3], zz[:, H3:]
    hs = [_augmented(B, H, dtype) for _ in range(L)]  # GRU states [s | 1], start at 0
    for h_aug, _ in hs:
        h_aug[:, :H] = 0
    gi = [np.empty((B, H3), dtype=dtype) for _ in range(L)]
    gh = [np.empty((B, H3), dtype=dtype) for _ in range(L - 1)]
    hm = np.empty((B, model.h_product.shape[1]), dtype=dtype)  # [W_hh s + (0, 0, b_hn) | W_v s + b_v], top layer
    hm[...] = model.h_product[-1]  # s = 0: the bias row
    gh.append(hm[:, :H3])
    velocity = hm[:, H3:]
    n, d = np.empty((B, H), dtype=dtype), np.empty((B, H), dtype=dtype)
    half = np.full((B, H2), 0.5, dtype=dtype)
    cells = [(g_i[:, :H2], g_h[:, :H2], g_h[:, H2:], g_i[:, H2:], g_i[:, :H], g_i[:, H:H2], h_aug, h)
             for g_i, g_h, (h_aug, h) in zip(gi, gh, hs)]

    def dense(x, lays):  # LeakyReLU dense layers (0 <= slope < 1: max(a, slope a)); returns the last buffer
        for a, pre, tmp, dst, nxt in lays:
            matmul(x, a, out=pre)
            multiply(pre, slopes[pre.shape[1]], out=tmp)
            maximum(pre, tmp, out=dst)
            x = nxt
        return x

    for t in range(T):
        dense(frames[t], enc_layers)  # z_t = E(p_t)
        matmul(z, model.z_product, out=zz)
        add(zz_a, c, out=gi[0])  # W_ih x_t + b_ih (+ b_hr, b_hz), r and z halved
        subtract(k, zz_b, out=c)  # c_{t+1} = k − W1 z_t
        for layer, (rz, gh_rz, gh_n, gi_n, r, u, h_aug, h) in enumerate(cells):
            if layer:
                matmul(hs[layer - 1][0], model.upper_ih[layer - 1], out=gi[layer])
            if layer < L - 1:
                matmul(h_aug, model.lower_hh[layer], out=gh[layer])
            add(rz, gh_rz, out=rz)  # halved pre-activations of r | u
            tanh(rz, out=rz)
            multiply(rz, half, out=rz)
            add(rz, half, out=rz)  # r | u = ½ + ½ tanh(a/2) = σ(a)
            multiply(gh_n, r, out=n)  # r (W_hn s + b_hn)
            add(n, gi_n, out=n)
            tanh(n, out=n)
            subtract(h, n, out=d)
            multiply(d, u, out=d)
            add(d, n, out=h)  # s' = n + u (s − n) = (1 − u) n + u s
        matmul(hs[-1][0], model.h_product, out=hm)  # v_t and the next step's W_hh s (top layer)
        add(velocity, z, out=dec_first[1])  # z_t + v_t
        x = dense(dec_first[0], dec_layers)
        matmul(x, dec_last, out=frames[t + 1, :, :P])  # p_{t+1}
    return np.ascontiguousarray(frames[1:, :, :P].transpose(1, 0, 2))  # (B, T, P)


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
        _accumulate(grads, g)
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
