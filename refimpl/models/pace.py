"""QuaterNet's pace network: trajectory parameters along a spline from its curvature and a target speed.

QuaterNet §3.7 (spec/locomotion.md §4). Per spline point (5 points per
unit of length) the network reads ``x = [turning angle, average speed]`` (I = 2) and predicts
``y = [amplitude A, frequency ω, cos Δ, sin Δ]`` (4): the local speed, the phase increment per frame and the
facing direction relative to the tangent. Two variants:

* **bidirectional** (offline, the default)::

      GRU(2 → 30, 1 layer, bidirectional), learned h0 (2, 1, 30)       rnn.*_l0, rnn.*_l0_reverse, h0
      y = Linear(60 → 4)([h_fwd | h_bwd])                               fc.weight (4, 60), fc.bias (4,)
      parameters: 2 · (3·30·(2 + 30) + 6·30) + 60 + 60·4 + 4 = 6,424

* **delayed** (online; the reference's ``DelayedModel(delay = 100)``)::

      x' = [x_0 … x_{N-1} | eos × D]        (D = 100 learned 2-vectors ``eos``, zero-initialised)
      h = GRU(2 → 30)(x'), learned h0 (1, 1, 30)
      y_t = Linear(30 → 4)(h_{t+D}),  t = 0 … N-1
      parameters: 3·30·(2 + 30) + 6·30 + 30 + 2 + 30·4 + 4 = 3,216

  So the output for point t has read the inputs up to point t + D (a 20-unit look-ahead at 5 points per unit).
  :func:`delayed_step` runs it point by point (the online form): after feeding input k the step emits the output
  for input k − D.

Parameter names follow the published model's attribute names as far as the reference notes give them (the
pose network's ``rnn`` / ``h0`` / ``fc``, and ``eos``), with PyTorch layouts (spec/architecture.md).
Loss: L1 (mean absolute error over all outputs), :func:`loss_forward` / :func:`loss_backward`.
Inference: :func:`predict` reparameterises the path, runs the network, clips ``A >= 0.1`` and ``ω >= 0``,
normalises ``(cos Δ, sin Δ)`` and returns the facing track, the tangent rotated by Δ; :func:`predict_with` does
the same around any implementation of the network (the exported graph in onnxruntime).

Shape legend: B batch, N spline points, I = 2 inputs, H = 30 hidden, O = 4 outputs, D delay (points).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from refimpl.models._shared import check_param_dict
from refimpl.losses import mae_loss_backward, mae_loss_forward
from refimpl.nn.gru import gru_backward, gru_forward, gru_init, gru_step_forward
from refimpl.nn.linear import linear_backward, linear_forward, linear_init
from refimpl.arrays import float_array
from refimpl.nn.params import init_normal

__all__ = [
    "PaceConfig", "init_params", "count_parameters", "param_shapes", "published_names", "forward", "backward",
    "loss_forward", "loss_backward", "init_state", "delayed_step", "predict", "predict_with",
    "facing_from_outputs",
    "MIN_AMPLITUDE", "MIN_FREQUENCY", "INPUT_NAMES", "OUTPUT_NAMES",
]

#: Inference clipping (reference ``predict``): amplitude >= 0.1, frequency >= 0.
MIN_AMPLITUDE = 0.1
MIN_FREQUENCY = 0.0
INPUT_NAMES = ("turning_angle", "average_speed")
OUTPUT_NAMES = ("amplitude", "frequency", "cos_delta", "sin_delta")


@dataclass(frozen=True)
class PaceConfig:
    """Sizes of the pace network (defaults: the paper's).

    Attributes
    ----------
    bidirectional : bool
        True: the offline bidirectional model; False: the delayed unidirectional model.
    hidden_size : int
        H (30).
    delay : int
        D, points of look-ahead of the unidirectional model (100); unused when bidirectional.
    input_size, output_size : int
        2 and 4.
    """

    bidirectional: bool = True
    hidden_size: int = 30
    delay: int = 100
    input_size: int = 2
    output_size: int = 4

    def __post_init__(self):
        for name in ("hidden_size", "input_size", "output_size"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"PaceConfig.{name}: expected a positive integer, got {v!r}")
        if isinstance(self.delay, bool) or not isinstance(self.delay, (int, np.integer)) or self.delay < 0:
            raise ValueError(f"PaceConfig.delay: expected an integer >= 0, got {self.delay!r}")

    @property
    def directions(self) -> int:
        return 2 if self.bidirectional else 1


def param_shapes(config: PaceConfig) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every parameter (PyTorch state-dict names and layouts)."""
    h, i, o, d = config.hidden_size, config.input_size, config.output_size, config.directions
    shapes = {}
    for sfx in ("l0", "l0_reverse")[:d]:
        shapes[f"rnn.weight_ih_{sfx}"] = (3 * h, i)
        shapes[f"rnn.weight_hh_{sfx}"] = (3 * h, h)
        shapes[f"rnn.bias_ih_{sfx}"] = (3 * h,)
        shapes[f"rnn.bias_hh_{sfx}"] = (3 * h,)
    shapes["h0"] = (d, 1, h)
    if not config.bidirectional:
        shapes["eos"] = (i,)
    shapes["fc.weight"] = (o, d * h)
    shapes["fc.bias"] = (o,)
    return shapes


def published_names(config: PaceConfig) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Name map to the published code (facebookresearch/QuaterNet's long-term pace network, spec/locomotion.md §4,
    ``BidirectionalModel`` / ``DelayedModel``): our name -> ``(published name, published shape)``. The same names;
    only the delayed model's ``eos`` differs in shape, ``(1, 1, I)`` there and ``(I,)`` here."""
    out = {name: (name, shape) for name, shape in param_shapes(config).items()}
    if "eos" in out:
        out["eos"] = ("eos", (1, 1, config.input_size))
    return out


def count_parameters(config: PaceConfig) -> int:
    """Number of scalar parameters: 6,424 (bidirectional) or 3,216 (delayed) at the paper's sizes."""
    return int(sum(int(np.prod(s)) for s in param_shapes(config).values()))


def init_params(config: PaceConfig, rng: np.random.Generator, dtype=np.float64) -> dict[str, np.ndarray]:
    """PyTorch-default initialisation: GRU and Linear ``U(±1/sqrt(fan))``, ``h0 ~ N(0, 0.01²)``, ``eos = 0``."""
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    h, d = config.hidden_size, config.directions
    params = gru_init(rng, config.input_size, h, 1, "rnn", bidirectional=config.bidirectional, dtype=dtype)
    params["h0"] = init_normal(rng, (d, 1, h), 0.01, dtype=dtype)
    if not config.bidirectional:
        params["eos"] = np.zeros(config.input_size, dtype=dtype)
    params.update(linear_init(rng, d * h, config.output_size, "fc", dtype=dtype))
    return params


def _check_params(params: Mapping[str, np.ndarray], config: PaceConfig) -> np.dtype:
    """:func:`refimpl.models._shared.check_param_dict` on the parameters this config names (others are ignored)."""
    shapes = param_shapes(config)
    return check_param_dict({k: v for k, v in params.items() if k in shapes}, shapes)


def forward(params: Mapping[str, np.ndarray], config: PaceConfig, x: np.ndarray):
    """Run the pace network over whole splines.

    Parameters
    ----------
    params : dict
        From :func:`init_params`.
    config : PaceConfig
    x : ndarray (B, N, I)
        Per spline point ``[turning angle, average speed]``; the dtype of the parameters.

    Returns
    -------
    y : ndarray (B, N, O)
        ``[A, ω, cos Δ, sin Δ]`` per point (raw: no clipping, no normalisation; see :func:`predict`).
    cache : dict
        For :func:`backward`.
    """
    dt = _check_params(params, config)
    x = float_array(x, "x", (None, None, config.input_size), cast=False)
    if x.dtype != dt:
        raise ValueError(f"x: expected dtype {dt} (the parameters'), got {x.dtype}")
    batch, n, _ = x.shape
    if n < 1:
        raise ValueError(f"x: expected at least one point (B, N >= 1, {config.input_size}), got {x.shape}")
    h0 = np.broadcast_to(params["h0"], (config.directions, batch, config.hidden_size))  # (D, B, H)
    if config.bidirectional:
        seq = x
    else:
        pad = np.broadcast_to(params["eos"], (batch, config.delay, config.input_size))
        seq = np.concatenate([x, pad], axis=1)                              # (B, N + D, I)
    hs, _, gcache = gru_forward(seq, h0, params, "rnn", 1, bidirectional=config.bidirectional)
    if not config.bidirectional:
        hs = hs[:, config.delay:]                                           # (B, N, H)
    y, lcache = linear_forward(hs, params, "fc")                            # (B, N, O)
    return y, dict(gru=gcache, fc=lcache, config=config, shape=(batch, n))


def backward(dy: np.ndarray, cache) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Gradients of :func:`forward`.

    Parameters
    ----------
    dy : ndarray (B, N, O)
        Cotangent of ``y``.

    Returns
    -------
    dx : ndarray (B, N, I)
    grads : dict
        Every parameter name of :func:`param_shapes` -> gradient (``h0``: summed over the batch; ``eos``: summed
        over the batch and the D padding steps).
    """
    config, (batch, n) = cache["config"], cache["shape"]
    dhs, grads = linear_backward(dy, cache["fc"])                           # (B, N, D*H)
    if not config.bidirectional:
        full = np.zeros((batch, n + config.delay, config.hidden_size), dtype=dhs.dtype)
        full[:, config.delay:] = dhs
        dhs = full
    dseq, dh0, ggrads = gru_backward(dhs, None, cache["gru"])
    grads.update(ggrads)
    grads["h0"] = dh0.sum(axis=1, keepdims=True)                            # (D, 1, H)
    if config.bidirectional:
        dx = dseq
    else:
        dx = dseq[:, :n]
        grads["eos"] = dseq[:, n:].sum(axis=(0, 1))                         # (I,)
    return np.ascontiguousarray(dx), grads


def loss_forward(pred: np.ndarray, target: np.ndarray):
    """L1 training loss (spec/locomotion.md §5): ``mean |pred - target|`` over B, N and the 4 outputs."""
    return mae_loss_forward(pred, target)


def loss_backward(dvalue: float, cache) -> np.ndarray:
    """Gradient of :func:`loss_forward` with respect to ``pred``."""
    return mae_loss_backward(dvalue, cache)


# ------------------------------------------------------------------------------------------------------------
# online form of the delayed model
# ------------------------------------------------------------------------------------------------------------

def init_state(params: Mapping[str, np.ndarray], config: PaceConfig, batch: int) -> np.ndarray:
    """The learned initial state expanded to a batch: ``(1, B, H)`` (delayed model only)."""
    if config.bidirectional:
        raise ValueError("config: the online step exists for the delayed (unidirectional) model only")
    _check_params(params, config)
    return np.repeat(np.asarray(params["h0"]), int(batch), axis=1)


def delayed_step(params: Mapping[str, np.ndarray], config: PaceConfig, x_t: np.ndarray | None, h: np.ndarray):
    """One point of the delayed model: read ``x_t`` (or the learned ``eos`` when None), emit an output.

    Feeding the N inputs then D times ``None`` gives N + D outputs; outputs ``D … N + D - 1`` equal
    :func:`forward`'s ``y[:, 0 … N-1]`` (the first D outputs belong to no input).

    Parameters
    ----------
    x_t : ndarray (B, I) or None
    h : ndarray (1, B, H)

    Returns
    -------
    y : ndarray (B, O)
        The output for the input fed D steps earlier.
    h_new : ndarray (1, B, H)
    """
    if config.bidirectional:
        raise ValueError("config: the online step exists for the delayed (unidirectional) model only")
    _check_params(params, config)
    if x_t is None:
        x_t = np.broadcast_to(params["eos"], (h.shape[1], config.input_size)).copy()
    hy, h_new, _ = gru_step_forward(x_t, h, params, "rnn", 1)
    y, _ = linear_forward(hy, params, "fc")
    return y, h_new


# ------------------------------------------------------------------------------------------------------------
# inference along a path
# ------------------------------------------------------------------------------------------------------------

def facing_from_outputs(tangent: np.ndarray, cos_sin_delta: np.ndarray) -> np.ndarray:
    """Facing directions: the unit tangent rotated by Δ, ``(t0 c - t1 s, t1 c + t0 s)`` (after normalising
    ``(c, s)`` with ``+1e-9``).

    Parameters
    ----------
    tangent : ndarray (..., 2)
    cos_sin_delta : ndarray (..., 2)

    Returns
    -------
    ndarray (..., 2)
    """
    cs = np.asarray(cos_sin_delta, dtype=np.float64)
    cs = cs / (np.linalg.norm(cs, axis=-1, keepdims=True) + 1e-9)
    t = np.asarray(tangent, dtype=np.float64)
    c, s = cs[..., 0], cs[..., 1]
    return np.stack([t[..., 0] * c - t[..., 1] * s, t[..., 1] * c + t[..., 0] * s], axis=-1)


def predict(params: Mapping[str, np.ndarray], config: PaceConfig, spline, average_speed: float,
            points_per_unit: float = 5.0, smoothing: float = 1.0):
    """Trajectory parameters along a path (reference ``PaceNetwork.predict``).

    The spline is reparameterised (``points_per_unit``, ``smoothing``); the network reads
    ``[turning_angle, average_speed]`` per point; then ``A = max(A, 0.1)``, ``ω = max(ω, 0)``, and the facing
    direction is the tangent rotated by the normalised ``(cos Δ, sin Δ)`` (:func:`predict_with` with
    :func:`forward`).

    Parameters
    ----------
    spline : refimpl.splines.Spline
    average_speed : float
        Target speed in units per frame (30 fps); the reference notebook uses 0.5 for a walk, 1.2 for a run.

    Returns
    -------
    Spline
        The reparameterised path with tracks ``amplitude`` (linear), ``frequency`` (linear) and ``direction``
        (circular: the facing, a unit 2-D vector in the path's coordinates).
    """
    return predict_with(lambda x: forward(params, config, x)[0], spline, average_speed, points_per_unit,
                        smoothing, dtype=np.asarray(params["h0"]).dtype)


def predict_with(network, spline, average_speed: float, points_per_unit: float = 5.0, smoothing: float = 1.0,
                 dtype=np.float64):
    """:func:`predict` with any implementation of the network (e.g. the exported ``pace`` graph in onnxruntime).

    Parameters
    ----------
    network : callable ``x (1, N, 2) -> y (1, N, 4)`` (raw outputs, before the clipping)
    spline, average_speed, points_per_unit, smoothing : as :func:`predict`
    dtype : the dtype of ``x``

    Returns
    -------
    Spline — as :func:`predict`.
    """
    from refimpl.splines import Spline
    if not isinstance(spline, Spline):
        raise ValueError(f"spline: expected a refimpl.splines.Spline, got {type(spline).__name__}")
    speed = float(average_speed)
    if not np.isfinite(speed):
        raise ValueError(f"average_speed: expected a finite number, got {average_speed!r}")
    sp = spline.reparameterize(points_per_unit, smoothing)
    x = np.empty((1, sp.num_points, 2), dtype=dtype)
    x[0, :, 0] = sp.track("turning_angle")[:, 0]
    x[0, :, 1] = speed
    y = np.asarray(network(x))
    if y.shape != (1, sp.num_points, 4):
        raise ValueError(f"network: expected outputs (1, {sp.num_points}, 4), got {y.shape}")
    y = y[0].astype(np.float64)                                             # (N, 4)
    amplitude = np.maximum(y[:, 0], MIN_AMPLITUDE)
    frequency = np.maximum(y[:, 1], MIN_FREQUENCY)
    facing = facing_from_outputs(sp.track("tangent"), y[:, 2:4])
    return sp.with_tracks(amplitude=(amplitude, "linear"), frequency=(frequency, "linear"),
                          direction=(facing, "circular"))


# ------------------------------------------------------------------------------------------------------------
# slow oracles (tests): per-step GRU loops and explicit per-point linear maps
# ------------------------------------------------------------------------------------------------------------

def _forward_naive(params, config: PaceConfig, x: np.ndarray) -> np.ndarray:
    """Loop oracle for :func:`forward`: the GRU's per-gate loop and one ``W h + b`` per point."""
    from refimpl.nn.gru_naive import gru_forward_naive
    batch, n, _ = x.shape
    h0 = np.repeat(params["h0"], batch, axis=1)
    seq = x if config.bidirectional else np.concatenate(
        [x, np.tile(params["eos"], (batch, config.delay, 1))], axis=1)
    hs, _ = gru_forward_naive(seq, h0, params, "rnn", 1, config.bidirectional)
    if not config.bidirectional:
        hs = hs[:, config.delay:]
    y = np.empty((batch, n, config.output_size))
    for b in range(batch):
        for t in range(n):
            y[b, t] = params["fc.weight"] @ hs[b, t] + params["fc.bias"]
    return y


def _backward_naive(dy: np.ndarray, params, config: PaceConfig, x: np.ndarray):
    """Loop oracle for :func:`backward` (recomputes the forward): ``(dx, grads)``."""
    from refimpl.nn.gru_naive import gru_backward_naive, gru_forward_naive
    batch, n, _ = x.shape
    h0 = np.repeat(params["h0"], batch, axis=1)
    seq = x if config.bidirectional else np.concatenate(
        [x, np.tile(params["eos"], (batch, config.delay, 1))], axis=1)
    hs, _ = gru_forward_naive(seq, h0, params, "rnn", 1, config.bidirectional)
    off = 0 if config.bidirectional else config.delay
    dw = np.zeros_like(params["fc.weight"])
    db = np.zeros_like(params["fc.bias"])
    dhs = np.zeros_like(hs)
    for b in range(batch):
        for t in range(n):
            dw += np.outer(dy[b, t], hs[b, off + t])
            db += dy[b, t]
            dhs[b, off + t] = params["fc.weight"].T @ dy[b, t]
    dseq, dh0, grads = gru_backward_naive(dhs, None, seq, h0, params, "rnn", 1, config.bidirectional)
    grads = dict(grads)
    grads["fc.weight"], grads["fc.bias"] = dw, db
    grads["h0"] = dh0.sum(axis=1, keepdims=True)
    if not config.bidirectional:
        grads["eos"] = dseq[:, n:].sum(axis=(0, 1))
    return dseq[:, :n], grads
