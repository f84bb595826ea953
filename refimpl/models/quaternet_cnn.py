"""QuaterNet convolutional pose network (Pavllo et al., IJCV 2019, §3.2, Fig. 2; never released by its authors).

The recurrent backbone (GRU + linear head) is replaced by a stack of causal dilated 1-D convolutions over time
(spec/quaternet.md §5). What the paper fixes: 5 layers, width W = 2, exponentially growing dilation (effective
1, 2, 4, 8, 16, receptive field 32 frames; W = 3 in the last layer gives 48), causal, C = 1024 channels except the
first and last layers (which map from and to the 4J rotation parameters), skip connections between every other
layer, velocity mode by QMul with the input, no normalisation layers. What it leaves open and we chose (our
reconstruction, labelled so in spec/quaternet.md §5.2, all configurable): ReLU after every layer but the last;
skips ``a_2 += a_0`` and ``a_3 += a_1`` (0-based layers; every layer whose input and output both have C channels
receives the output of the layer two below it, added after its activation); PyTorch ``nn.Conv1d`` layouts and
default initialisation; parameter names ``convs.{k}.weight (C_out, C_in, K)``, ``convs.{k}.bias``::

    a_{-1} = x (B, T, 4J)
    a_k    = act(conv_k(a_{k-1})) (+ a_s for each skip (s, k))         k = 0 … N-2   (C channels)
    Δ      = conv_{N-1}(a_{N-2})                                       (4J channels, no activation)
    y_t    = normalize(Δ_t,j ⊗ x_t,j) per joint (velocity) or normalize(Δ_t,j) (absolute)

``y_t`` predicts frame ``t + 1`` and depends on ``x_{t-R+1} … x_t`` only (R = 1 + Σ_k (K_k − 1) d_k).

Training (spec/quaternet.md §5.3): teacher forcing is one vectorised pass (:func:`forward`, :func:`backward`).
Scheduled sampling (:func:`forward_scheduled`, :func:`backward_scheduled`) builds the fed sequence step by step
(each fed-back prediction computed from its window), then runs one vectorised pass over it; as the paper says for
the CNN ("the gradient flows only across the first term", as in Bengio et al. 2015) the fed-back predictions are
treated as constants: no gradient reaches a prediction through the later inputs it was fed into.

Online use: :func:`step` (the prediction from a window of the latest frames; only the last R are read),
:func:`predict` (prefix -> k frames, built on :func:`step`), and the incremental :func:`init_stream_state` /
:func:`stream_step` (per-layer buffers of past inputs: one new output per layer and frame).

Shape legend: B batch, T time, P prefix frames, J joints, C channels, K taps, N layers, R receptive field.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from refimpl.models._shared import check_param_dict
from refimpl.nn.activations import (leaky_relu_backward, leaky_relu_forward, relu_backward, relu_forward,
                                    tanh_backward, tanh_forward)
from refimpl.nn.conv1d import conv1d_causal_backward, conv1d_causal_forward, conv1d_init
from refimpl.arrays import float_array
from refimpl.nn.quat_layers import (qmul_velocity_backward, qmul_velocity_forward, quat_normalize_backward,
                                    quat_normalize_forward)

__all__ = [
    "ACTIVATIONS", "QuaterNetCNNConfig", "param_shapes", "count_parameters", "init_params", "check_params",
    "forward", "backward", "forward_scheduled", "backward_scheduled", "step", "predict",
    "init_stream_state", "stream_step",
]

#: Activations the config accepts (applied after every layer but the last).
ACTIVATIONS = ("relu", "leaky_relu", "tanh", "none")


# ----------------------------------------------------------------------------------------------------------------
# configuration and parameters
# ----------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class QuaterNetCNNConfig:
    """Sizes and choices of the convolutional pose network (defaults: paper size, J = 32, R = 32).

    Attributes
    ----------
    num_joints : int
        J; input and output have ``4 J`` features ``(w, x, y, z)`` per joint.
    channels : int
        C, channels of every layer but the last (1024 in the paper).
    kernel_sizes : tuple of int
        Width W of each layer (paper: 2 everywhere; ``(2, 2, 2, 2, 3)`` gives R = 48).
    dilations : tuple of int
        Dilation of each layer (effective paper values 1, 2, 4, 8, 16; spec/quaternet.md §5.1).
    skips : tuple of (int, int)
        Pairs ``(s, k)`` of 0-based layers: the output of layer s is added to the output of layer k (after its
        activation); needs ``s < k`` and equal output channels. Ours: ``((0, 2), (1, 3))``; ``()`` = none.
    activation : str
        One of :data:`ACTIVATIONS` (ours: ``"relu"``; the paper names none).
    negative_slope : float
        Slope of ``"leaky_relu"``.
    velocity : bool
        Velocity mode (QMul with the input quaternion of the same frame); False = absolute rotations ("CNN abs.").
    eps : float
        Normalisation clamp ``q / max(|q|, eps)``.
    """

    num_joints: int = 32
    channels: int = 1024
    kernel_sizes: tuple[int, ...] = (2, 2, 2, 2, 2)
    dilations: tuple[int, ...] = (1, 2, 4, 8, 16)
    skips: tuple[tuple[int, int], ...] = ((0, 2), (1, 3))
    activation: str = "relu"
    negative_slope: float = 0.01
    velocity: bool = True
    eps: float = 1e-12

    def __post_init__(self):
        for name in ("num_joints", "channels"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"QuaterNetCNNConfig.{name}: expected a positive integer, got {v!r}")
        ks = tuple(int(k) for k in self.kernel_sizes)
        ds = tuple(int(d) for d in self.dilations)
        if len(ks) < 2 or len(ks) != len(ds) or min(ks) < 1 or min(ds) < 1:
            raise ValueError(f"QuaterNetCNNConfig: expected kernel_sizes and dilations of one length >= 2 with "
                             f"entries >= 1, got {self.kernel_sizes} and {self.dilations}")
        object.__setattr__(self, "kernel_sizes", ks)
        object.__setattr__(self, "dilations", ds)
        skips = tuple((int(s), int(k)) for s, k in self.skips)
        n = len(ks)
        for s, k in skips:
            if not 0 <= s < k < n:
                raise ValueError(f"QuaterNetCNNConfig.skips: expected pairs 0 <= s < k < {n}, got {(s, k)}")
            if self.layer_channels[s][1] != self.layer_channels[k][1]:
                raise ValueError(f"QuaterNetCNNConfig.skips: layers {s} and {k} have different output channels "
                                 f"({self.layer_channels[s][1]} and {self.layer_channels[k][1]})")
        object.__setattr__(self, "skips", skips)
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"QuaterNetCNNConfig.activation: expected one of {ACTIVATIONS}, got {self.activation!r}")
        if not 0.0 <= float(self.negative_slope) < 1.0:
            raise ValueError("QuaterNetCNNConfig.negative_slope: expected a value in [0, 1), "
                             f"got {self.negative_slope}")
        if not isinstance(self.velocity, (bool, np.bool_)):
            raise ValueError(f"QuaterNetCNNConfig.velocity: expected a bool, got {self.velocity!r}")
        if not (np.isfinite(self.eps) and self.eps > 0):
            raise ValueError(f"QuaterNetCNNConfig.eps: expected a finite value > 0, got {self.eps}")

    @property
    def num_layers(self) -> int:
        """N."""
        return len(self.kernel_sizes)

    @property
    def rotation_size(self) -> int:
        """4 J, input and output features."""
        return 4 * self.num_joints

    @property
    def layer_channels(self) -> list[tuple[int, int]]:
        """``(C_in, C_out)`` of each layer: ``(4J, C), (C, C), …, (C, 4J)``."""
        n, R, C = len(self.kernel_sizes), 4 * self.num_joints, self.channels
        return [(R if k == 0 else C, R if k == n - 1 else C) for k in range(n)]

    @property
    def receptive_field(self) -> int:
        """R = 1 + Σ_k (K_k − 1) d_k input frames per output (32 for the defaults)."""
        return 1 + sum((k - 1) * d for k, d in zip(self.kernel_sizes, self.dilations))

    def to_dict(self) -> dict:
        """Plain JSON-friendly dict; ``QuaterNetCNNConfig(**d)`` rebuilds it."""
        return {"num_joints": int(self.num_joints), "channels": int(self.channels),
                "kernel_sizes": list(self.kernel_sizes), "dilations": list(self.dilations),
                "skips": [list(p) for p in self.skips], "activation": self.activation,
                "negative_slope": float(self.negative_slope), "velocity": bool(self.velocity),
                "eps": float(self.eps)}


def param_shapes(config: QuaterNetCNNConfig = QuaterNetCNNConfig()) -> dict[str, tuple[int, ...]]:
    """Name -> shape: ``convs.{k}.weight (C_out, C_in, K_k)``, ``convs.{k}.bias (C_out,)`` (nn.Conv1d layout)."""
    shapes: dict[str, tuple[int, ...]] = {}
    for k, ((c_in, c_out), taps) in enumerate(zip(config.layer_channels, config.kernel_sizes)):
        shapes[f"convs.{k}.weight"] = (c_out, c_in, taps)
        shapes[f"convs.{k}.bias"] = (c_out,)
    return shapes


def count_parameters(config: QuaterNetCNNConfig = QuaterNetCNNConfig()) -> int:
    """Number of scalar parameters (6,819,968 for the defaults; 6,951,040 with W = 3 in the last layer)."""
    return int(sum(int(np.prod(s)) for s in param_shapes(config).values()))


def init_params(config: QuaterNetCNNConfig = QuaterNetCNNConfig(), rng: np.random.Generator | None = None,
                dtype=np.float64) -> dict[str, np.ndarray]:
    """PyTorch-default ``nn.Conv1d`` initialisation, weight and bias ``U(±1/sqrt(C_in K))`` (our choice)."""
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    _check_config(config)
    params: dict[str, np.ndarray] = {}
    for k, ((c_in, c_out), taps) in enumerate(zip(config.layer_channels, config.kernel_sizes)):
        params.update(conv1d_init(rng, c_in, c_out, taps, f"convs.{k}", dtype=dtype))
    return params


def _check_config(config) -> QuaterNetCNNConfig:
    if not isinstance(config, QuaterNetCNNConfig):
        raise ValueError(f"config: expected a QuaterNetCNNConfig, got {type(config).__name__}")
    return config


def check_params(params: Mapping[str, np.ndarray], config: QuaterNetCNNConfig = QuaterNetCNNConfig()) -> np.dtype:
    """Validate names, shapes and the one float dtype of ``params`` (extra entries refused); return the dtype."""
    _check_config(config)
    return check_param_dict(params, param_shapes(config))


def _check_frames(x, name: str, config: QuaterNetCNNConfig, dtype, batch=None) -> np.ndarray:
    R = config.rotation_size
    x = float_array(x, name, (batch, None, R), context=f"4J = {R} from the config", cast=False)
    if x.shape[1] < 1:
        raise ValueError(f"{name}: expected at least one frame (B, T >= 1, 4J), got {x.shape}")
    if x.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {dtype} (the parameters' dtype), got {x.dtype}")
    return x


# ----------------------------------------------------------------------------------------------------------------
# the network on a whole sequence (teacher forcing)
# ----------------------------------------------------------------------------------------------------------------

def _act_forward(x, config: QuaterNetCNNConfig):
    a = config.activation
    if a == "relu":
        return relu_forward(x)
    if a == "leaky_relu":
        return leaky_relu_forward(x, config.negative_slope)
    if a == "tanh":
        return tanh_forward(x)
    return x, None


def _act_backward(dy, cache, config: QuaterNetCNNConfig):
    a = config.activation
    if a == "relu":
        return relu_backward(dy, cache)
    if a == "leaky_relu":
        return leaky_relu_backward(dy, cache)
    if a == "tanh":
        return tanh_backward(dy, cache)
    return dy


def _forward_core(params, x, config: QuaterNetCNNConfig):
    """Vectorised pass over ``x (B, T, 4J)``: ``(y, pre, cache)``, ``y``/``pre`` ``(B, T, 4J)``."""
    n = config.num_layers
    skips_into = {k: [s for s, kk in config.skips if kk == k] for k in range(n)}
    acts, layer_caches = [], []
    a = x
    for k in range(n):
        z, cc = conv1d_causal_forward(a, params, f"convs.{k}", config.dilations[k])
        ac = None
        if k < n - 1:
            z, ac = _act_forward(z, config)
        for s in skips_into[k]:
            z = z + acts[s]
        acts.append(z)
        layer_caches.append((cc, ac))
        a = z
    B, T, R = x.shape
    J = config.num_joints
    pre = a  # Δ (B, T, 4J)
    if config.velocity:
        q, qc = qmul_velocity_forward(pre.reshape(B, T, J, 4), x.reshape(B, T, J, 4), config.eps)
    else:
        q, qc = quat_normalize_forward(pre.reshape(B, T, J, 4), config.eps)
    return q.reshape(B, T, R), pre, dict(config=config, layers=layer_caches, quat=qc, shape=(B, T),
                                          dtype=x.dtype)


def _backward_core(dy, dpre, cache):
    """Backward of :func:`_forward_core`: ``(grads, dx (B, T, 4J))``."""
    config: QuaterNetCNNConfig = cache["config"]
    B, T = cache["shape"]
    J, R, n = config.num_joints, config.rotation_size, config.num_layers
    dq = dy.reshape(B, T, J, 4)
    if config.velocity:
        dd, dx_q = qmul_velocity_backward(dq, cache["quat"])
        dx = dx_q.reshape(B, T, R)
    else:
        dd, dx = quat_normalize_backward(dq, cache["quat"]), None
    da = dd.reshape(B, T, R)
    if dpre is not None:
        da = da + dpre
    dacts: list = [None] * n  # extra cotangents reaching a_s through skips
    grads: dict = {}
    for k in range(n - 1, -1, -1):
        if dacts[k] is not None:
            da = da + dacts[k]
        for s, kk in config.skips:
            if kk == k:
                dacts[s] = da if dacts[s] is None else dacts[s] + da
        cc, ac = cache["layers"][k]
        dz = _act_backward(da, ac, config) if k < n - 1 else da
        da, g = conv1d_causal_backward(np.ascontiguousarray(dz), cc)
        grads.update(g)
    dx = da if dx is None else dx + da
    return grads, dx


def forward(params: Mapping[str, np.ndarray], x, config: QuaterNetCNNConfig = QuaterNetCNNConfig()):
    """Teacher-forced pass over a whole sequence (spec/quaternet.md §5.1).

    Parameters
    ----------
    params : dict
        From :func:`init_params`.
    x : ndarray (B, T, 4J)
        Input frames (unit quaternions per joint).

    Returns
    -------
    y : ndarray (B, T, 4J)
        ``y[:, t]`` predicts frame ``t + 1`` from ``x[:, t-R+1 … t]`` (zeros before the start at every layer,
        i.e. causal padding, as PyTorch's left-padded ``conv1d``).
    pre : ndarray (B, T, 4J)
        Δ, the last layer's output before the QMul/normalisation (for the norm penalty).
    cache : dict
    """
    dtype = check_params(params, config)
    x = _check_frames(x, "x", config, dtype)
    return _forward_core(params, x, config)


def backward(dy, dpre, cache, input_grads: bool = False):
    """Gradients of :func:`forward`: ``grads`` (and ``dx (B, T, 4J)`` with ``input_grads``).

    ``dy (B, T, 4J)`` cotangent of ``y``; ``dpre (B, T, 4J)`` of ``pre`` or None (zero)."""
    B, T = cache["shape"]
    R = cache["config"].rotation_size
    dy = float_array(dy, "dy", (B, T, R), cast=False)
    if dpre is not None:
        dpre = float_array(dpre, "dpre", (B, T, R), cast=False)
    grads, dx = _backward_core(dy, dpre, cache)
    return (grads, dx) if input_grads else grads


# ----------------------------------------------------------------------------------------------------------------
# online: window step and predict
# ----------------------------------------------------------------------------------------------------------------

def step(params: Mapping[str, np.ndarray], window, config: QuaterNetCNNConfig = QuaterNetCNNConfig()) -> np.ndarray:
    """Prediction of the frame after ``window`` (spec/quaternet.md §5.4).

    Parameters
    ----------
    window : ndarray (B, n, 4J), n >= 1
        The latest frames, oldest first. Only the last R (receptive field) are read; with ``n < R`` the window
        is taken to be the start of the sequence (the layers' causal zero padding applies), so the result
        equals :func:`forward` on the whole sequence at its last frame.

    Returns
    -------
    ndarray (B, 4J)
    """
    dtype = check_params(params, config)
    window = _check_frames(window, "window", config, dtype)
    return _forward_core(params, window[:, -config.receptive_field:], config)[0][:, -1]


def predict(params: Mapping[str, np.ndarray], prefix, k: int,
            config: QuaterNetCNNConfig = QuaterNetCNNConfig()) -> np.ndarray:
    """Predict ``k`` frames after ``prefix (B, P, 4J)`` by repeated :func:`step`, feeding each prediction back.

    Returns
    -------
    ndarray (B, k, 4J)
        Equals :func:`forward_scheduled` with an all-False mask.
    """
    dtype = check_params(params, config)
    prefix = _check_frames(prefix, "prefix", config, dtype)
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k: expected a positive integer number of frames, got {k!r}")
    R = config.receptive_field
    window = prefix[:, -R:]
    out = []
    for _ in range(k):
        y = step(params, window, config)
        out.append(y)
        window = np.concatenate([window, y[:, None]], axis=1)[:, -R:]
    return np.stack(out, axis=1)


def init_stream_state(params: Mapping[str, np.ndarray], batch_size: int,
                      config: QuaterNetCNNConfig = QuaterNetCNNConfig()) -> tuple[np.ndarray, ...]:
    """Zero state for :func:`stream_step`: per layer k the last ``(K_k − 1) d_k`` inputs, ``(B, (K_k−1) d_k, C_in)``.

    Zeros are exactly the causal zero padding of every layer at the start of a sequence."""
    dtype = check_params(params, config)
    if isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
        raise ValueError(f"batch_size: expected a positive integer, got {batch_size!r}")
    return tuple(np.zeros((int(batch_size), (taps - 1) * d, c_in), dtype=dtype)
                 for (c_in, _), taps, d in zip(config.layer_channels, config.kernel_sizes, config.dilations))


def stream_step(params: Mapping[str, np.ndarray], state, x, config: QuaterNetCNNConfig = QuaterNetCNNConfig()):
    """Incremental online step: one frame ``x (B, 4J)`` in, the prediction of the next frame out (§5.4).

    Each layer computes its one new output from its buffered past inputs (``state``, from
    :func:`init_stream_state` or the previous call): ``N`` frame-layer evaluations per frame instead of the
    window step's ``N·R``. Repeated over a sequence it gives exactly :func:`forward`'s outputs.

    Returns
    -------
    y : ndarray (B, 4J)
    state : tuple of ndarray
        The updated buffers (new arrays; the input state is not modified).
    """
    dtype = check_params(params, config)
    R = config.rotation_size
    x = float_array(x, "x", (None, R), context=f"4J = {R} from the config", cast=False)
    if x.dtype != dtype:
        raise ValueError(f"x: expected dtype {dtype} (the parameters' dtype), got {x.dtype}")
    B, n = x.shape[0], config.num_layers
    if not isinstance(state, (tuple, list)) or len(state) != n:
        raise ValueError(f"state: expected a tuple of {n} buffers (init_stream_state), got {type(state).__name__}")
    new_state, acts = [], []
    a = x
    for k, ((c_in, _), taps, d) in enumerate(zip(config.layer_channels, config.kernel_sizes, config.dilations)):
        buf = float_array(state[k], f"state[{k}]", (B, (taps - 1) * d, c_in), cast=False)
        full = np.concatenate([buf, a[:, None]], axis=1)  # (B, (K-1) d + 1, C_in), oldest first
        w = params[f"convs.{k}.weight"]  # (C_out, C_in, K)
        z = params[f"convs.{k}.bias"] + sum(full[:, j * d] @ w[:, :, j].T for j in range(taps))  # (B, C_out)
        new_state.append(full[:, 1:])
        if k < n - 1:
            z = _act_forward(z, config)[0]
        for s, kk in config.skips:
            if kk == k:
                z = z + acts[s]
        acts.append(z)
        a = z
    J = config.num_joints
    if config.velocity:
        q = qmul_velocity_forward(a.reshape(B, J, 4), x.reshape(B, J, 4), config.eps)[0]
    else:
        q = quat_normalize_forward(a.reshape(B, J, 4), config.eps)[0]
    return q.reshape(B, R), tuple(new_state)


# ----------------------------------------------------------------------------------------------------------------
# training with scheduled sampling (gradient through the first term only)
# ----------------------------------------------------------------------------------------------------------------

def forward_scheduled(params: Mapping[str, np.ndarray], prefix, future, mask,
                      config: QuaterNetCNNConfig = QuaterNetCNNConfig()):
    """Scheduled-sampling forward (spec/quaternet.md §5.3), the same schedule as the recurrent network.

    The fed sequence is ``s_t = prefix[:, t]`` for ``t < P`` and, for step ``i`` (``0 <= i < T - 1``),
    ``s_{P+i} = future[:, i]`` if ``mask[i]`` else the prediction of frame ``P + i`` (computed from its own
    window, then held constant). Then one vectorised pass over ``s``; the predictions are its outputs at
    ``P - 1 … P + T - 2``. Because the network is causal, each equals the prediction made before it was fed.

    Parameters
    ----------
    prefix : ndarray (B, P, 4J)
    future : ndarray (B, T, 4J)
        Ground truth of frames ``P … P+T-1`` (the targets).
    mask : ndarray of bool (T - 1,)
        True = feed the ground truth at that step.

    Returns
    -------
    y : ndarray (B, T, 4J)
    pre : ndarray (B, T, 4J)
    cache : dict
        For :func:`backward_scheduled`; ``cache["fed"]`` is the fed sequence ``(B, P + T - 1, 4J)``.
    """
    dtype = check_params(params, config)
    prefix = _check_frames(prefix, "prefix", config, dtype)
    B, P, _ = prefix.shape
    future = _check_frames(future, "future", config, dtype, batch=B)
    T = future.shape[1]
    m = np.asarray(mask)
    if m.dtype != np.bool_ or m.shape != (T - 1,):
        raise ValueError(f"mask: expected a bool array of shape ({T - 1},) (T - 1 decisions), "
                         f"got dtype {m.dtype} shape {m.shape}")
    R = config.receptive_field
    fed = np.concatenate([prefix, future[:, :T - 1]], axis=1)  # (B, P + T - 1, 4J)
    for i in range(T - 1):
        if not m[i]:
            s = P + i  # the prediction of frame s, from fed[:, s-R … s-1], replaces the ground truth
            fed[:, s] = _forward_core(params, fed[:, max(0, s - R):s], config)[0][:, -1]
    y, pre, cache = _forward_core(params, fed, config)
    cache.update(scheduled=(P, T, m), fed=fed)
    return y[:, P - 1:], pre[:, P - 1:], cache


def backward_scheduled(dy, dpre, cache, input_grads: bool = False):
    """Gradients of :func:`forward_scheduled` with the fed-back predictions held constant (first term only).

    Returns
    -------
    grads : dict
    dprefix : ndarray (B, P, 4J)
        Only with ``input_grads``.
    dfuture : ndarray (B, T, 4J)
        Only with ``input_grads``; zero at replaced frames and at the last frame.
    """
    P, T, m = cache["scheduled"]
    B = cache["shape"][0]
    R = cache["config"].rotation_size
    dy = float_array(dy, "dy", (B, T, R), cast=False)
    if dpre is not None:
        dpre = float_array(dpre, "dpre", (B, T, R), cast=False)
    L = P + T - 1
    dy_full = np.zeros((B, L, R), dtype=cache["dtype"])
    dy_full[:, P - 1:] = dy
    dpre_full = None
    if dpre is not None:
        dpre_full = np.zeros_like(dy_full)
        dpre_full[:, P - 1:] = dpre
    grads, dfed = _backward_core(dy_full, dpre_full, cache)
    if not input_grads:
        return grads
    dfuture = np.zeros((B, T, R), dtype=dfed.dtype)
    dfuture[:, :T - 1] = dfed[:, P:]
    dfuture[:, :T - 1][:, ~m] = 0
    return grads, dfed[:, :P].copy(), dfuture


# ----------------------------------------------------------------------------------------------------------------
# slow oracle
# ----------------------------------------------------------------------------------------------------------------

def _forward_naive(params, x, config: QuaterNetCNNConfig):
    """Per-frame, per-tap loop of the equations in the module docstring (independent of the conv kernel)."""
    B, T, R = x.shape
    J, n = config.num_joints, config.num_layers
    acts = []
    a = x
    for k in range(n):
        w, b = params[f"convs.{k}.weight"], params[f"convs.{k}.bias"]
        taps, d = config.kernel_sizes[k], config.dilations[k]
        z = np.zeros((B, T, w.shape[0]))
        for t in range(T):
            z[:, t] = b
            for j in range(taps):
                s = t - (taps - 1 - j) * d
                if s >= 0:
                    z[:, t] += a[:, s] @ w[:, :, j].T
        if k < n - 1:
            if config.activation == "relu":
                z = np.maximum(z, 0)
            elif config.activation == "leaky_relu":
                z = np.where(z > 0, z, config.negative_slope * z)
            elif config.activation == "tanh":
                z = np.tanh(z)
        for s_, kk in config.skips:
            if kk == k:
                z = z + acts[s_]
        acts.append(z)
        a = z
    delta = a.reshape(B, T, J, 4)
    out = np.empty_like(delta)
    for bi in range(B):
        for t in range(T):
            for j in range(J):
                d4 = delta[bi, t, j]
                if config.velocity:
                    w0, x0, y0, z0 = d4
                    w1, x1, y1, z1 = x[bi, t, 4 * j:4 * j + 4]
                    d4 = np.array([w0 * w1 - x0 * x1 - y0 * y1 - z0 * z1, w0 * x1 + x0 * w1 + y0 * z1 - z0 * y1,
                                   w0 * y1 - x0 * z1 + y0 * w1 + z0 * x1, w0 * z1 + x0 * y1 - y0 * x1 + z0 * w1])
                out[bi, t, j] = d4 / max(np.sqrt(np.sum(d4 ** 2)), config.eps)
    return out.reshape(B, T, R)
