"""Auto-conditioned recurrent network (acRNN; Zhou, Li et al., ICLR 2018) with the pose representations and losses
of the dual-quaternion paper (Andreou et al. 2022, §6.1, Table 1, Appendix B-C); spec/acrnn.md.

Network (defaults of :class:`ACRNNConfig` = the papers' sizes)::

    lstm     3 LSTM layers, hidden H = 1024, input F          lstm.weight_ih_l{k}, ... (PyTorch nn.LSTM names)
    decoder  linear H -> F                                   decoder.weight (F, H), decoder.bias (F,)

``F = 3 + D·J`` is the frame vector of the chosen representation (refimpl/representations.py), standardised
with the training set's mean and std. ``skewed=True`` is the published code's stacking (layer k reads layer
k-1's PREVIOUS output, spec/layers.md §5.3); ``skewed=False`` (default) the paper's ordinary
stack. Parameters: ``5121·F + 20,996,096`` at H = 1024 (:func:`count_parameters`, Table 4).

Auto-conditioning (training, :func:`sequence_forward`): a window of ``T + 1`` standardised frames
``f_0 … f_T``; step t reads ``x_t = f_t`` when ``mask[t]`` (ground truth) and ``x_t = y_{t-1}`` (its own previous
output, NOT detached) otherwise, with ``mask = auto_conditioning_mask(T, 5, 5)`` (5 ground-truth / 5 own frames,
starting with ground truth); ``y_t`` predicts ``f_{t+1}``. The loss (:func:`loss_forward`) is taken over every
step. Backward (:func:`sequence_backward`) runs the steps in reverse; the gradient of an output fed back at step
t+1 is added to the loss gradient of ``y_t``.

Losses (the rows of Table 1, :data:`refimpl.protocols.synthesis.VARIANTS`, reach :class:`LossSpec` through
:meth:`LossSpec.for_variant`): MSE on the standardised frames; for quaternions L_quat and the FK position loss
(quaternions-FK); for dual quaternions the output path of refimpl/dq_output.py on the
de-standardised output (L_reg on the raw values, Eq. 13, L_pos, L_offset, local L_quat), any subset selectable.

Shape legend: B batch, T steps, S seed frames, N generated frames, F frame size, H hidden size, L layers,
J joints, D values per joint.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from refimpl.models._shared import check_param_dict
from refimpl.dq_output import DQ_TERM_NAMES
from refimpl.dq_output_fast import dq_output_loss_backward, dq_output_loss_forward
from refimpl.losses import (euclidean_loss_backward, euclidean_loss_forward,
                            mse_loss_backward, mse_loss_forward, quat_loss_backward, quat_loss_forward,
                            quat_norm_loss_backward, quat_norm_loss_forward)
from refimpl.nn.kinematics_layers import forward_kinematics_backward, forward_kinematics_forward
from refimpl.nn.linear import linear_backward, linear_forward, linear_init
from refimpl.nn.lstm import lstm_init, lstm_step_backward, lstm_step_forward
from refimpl.arrays import float_array
from refimpl.nn.quat_layers import quat_normalize_backward, quat_normalize_forward
from refimpl.representations import REPRESENTATIONS, frame_size
from refimpl.schedules import ACRNN_CONDITION_LENGTH, ACRNN_GROUND_TRUTH_LENGTH, auto_conditioning_mask

__all__ = [
    "ACRNNConfig", "LossSpec", "TABLE4_PARAMETERS",
    "param_shapes", "published_names", "count_parameters", "init_params", "init_state", "step",
    "sequence_forward", "sequence_backward", "generate",
    "loss_forward", "loss_backward", "loss_and_grads", "config_for",
]

#: The dual-quaternion paper's Table 4 (acRNN on CMU, J = 31) as (representation, frame size, parameters).
TABLE4_PARAMETERS = (
    ("positions", 114, 21_579_890),            # 38 CMU nodes × 3 (End Sites included, root absolute)
    ("euler", 96, 21_487_712),
    ("quaternions", 127, 21_646_463),
    ("ortho6d", 189, 21_963_965),
    ("dual_quaternions", 251, 22_281_467),
    ("quaternions+positions", 220, 22_122_716),
    ("ortho6d+positions", 282, 22_440_218),
)


# ----------------------------------------------------------------------------------------------------------------
# configuration and parameters
# ----------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ACRNNConfig:
    """Sizes and schedule of acRNN (defaults: the paper's).

    Attributes
    ----------
    frame_size : int
        F = 3 + D·J, input = output size (251: dual quaternions on CMU's 31 joints).
    hidden_size : int
        H, LSTM hidden size (1024).
    num_layers : int
        L, stacked LSTM layers (3).
    skewed : bool
        The published code's layer skew (layer k reads layer k-1's previous output); False = the paper's stack.
    ground_truth_length, condition_length : int
        Auto-conditioning: ground-truth frames then own frames per period (5, 5).
    """

    frame_size: int = 251
    hidden_size: int = 1024
    num_layers: int = 3
    skewed: bool = False
    ground_truth_length: int = ACRNN_GROUND_TRUTH_LENGTH
    condition_length: int = ACRNN_CONDITION_LENGTH

    def __post_init__(self):
        for name in ("frame_size", "hidden_size", "num_layers", "ground_truth_length"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1:
                raise ValueError(f"ACRNNConfig.{name}: expected a positive integer, got {v!r}")
        v = self.condition_length
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"ACRNNConfig.condition_length: expected an integer >= 0, got {v!r}")

    def mask(self, steps: int) -> np.ndarray:
        """The auto-conditioning mask of ``steps`` steps (True = ground truth)."""
        return auto_conditioning_mask(steps, self.ground_truth_length, self.condition_length)

    def to_dict(self) -> dict:
        """Plain JSON-friendly dict; ``ACRNNConfig(**d)`` rebuilds it."""
        return {"frame_size": self.frame_size, "hidden_size": self.hidden_size, "num_layers": self.num_layers,
                "skewed": bool(self.skewed), "ground_truth_length": self.ground_truth_length,
                "condition_length": self.condition_length}


def param_shapes(config: ACRNNConfig) -> dict[str, tuple[int, ...]]:
    """Every parameter's name and shape (PyTorch ``nn.LSTM`` + ``nn.Linear`` layouts), without allocating."""
    F, H = config.frame_size, config.hidden_size
    shapes = {}
    for k in range(config.num_layers):
        shapes[f"lstm.weight_ih_l{k}"] = (4 * H, F if k == 0 else H)
        shapes[f"lstm.weight_hh_l{k}"] = (4 * H, H)
        shapes[f"lstm.bias_ih_l{k}"] = (4 * H,)
        shapes[f"lstm.bias_hh_l{k}"] = (4 * H,)
    shapes["decoder.weight"] = (F, H)
    shapes["decoder.bias"] = (F,)
    return shapes


def published_names(config: ACRNNConfig) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Name map to the published code (papagina/Auto_Conditioned_RNN_motion; spec/import.md):
    our name -> ``(published name, published shape)``.

    The published network holds one ``nn.LSTMCell`` per layer, ``lstm1`` … ``lstm3`` (``lstm{k+1}.weight_ih``
    ``(4H, I_k)``, ``weight_hh``, ``bias_ih``, ``bias_hh``, gate blocks i|f|g|o as ``nn.LSTM``), and
    ``decoder.weight`` / ``decoder.bias``; the tensors are ours (``lstm.weight_ih_l{k}``, ...) under other names.
    Its stack is the skewed one (``skewed=True``, spec/acrnn.md §1).
    """
    out = {}
    for name, shape in param_shapes(config).items():
        if name.startswith("lstm."):
            what, _, layer = name[len("lstm."):].rpartition("_l")
            out[name] = (f"lstm{int(layer) + 1}.{what}", shape)
        else:
            out[name] = (name, shape)
    return out


def count_parameters(config: ACRNNConfig) -> int:
    """Number of parameters: ``4H(F + H) + 8H + (L-1)(4H·2H + 8H) + (H + 1)F`` (= 5121·F + 20,996,096 at H = 1024,
    L = 3), computed from :func:`param_shapes`."""
    return int(sum(int(np.prod(s)) for s in param_shapes(config).values()))


def init_params(config: ACRNNConfig, rng: np.random.Generator, dtype=np.float64) -> dict[str, np.ndarray]:
    """PyTorch-default initialisation (every LSTM parameter ``U(±1/√H)``, the decoder ``U(±1/√H)``)."""
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    params = lstm_init(rng, config.frame_size, config.hidden_size, config.num_layers, "lstm", dtype)
    params.update(linear_init(rng, config.hidden_size, config.frame_size, "decoder", dtype))
    return params


def _check_params(params: Mapping[str, np.ndarray], config: ACRNNConfig) -> np.dtype:
    """:func:`refimpl.models._shared.check_param_dict` on the parameters this config names (others are ignored)."""
    shapes = param_shapes(config)
    return check_param_dict({k: v for k, v in params.items() if k in shapes}, shapes)


# ----------------------------------------------------------------------------------------------------------------
# step, sequence forward/backward, generation
# ----------------------------------------------------------------------------------------------------------------

def init_state(config: ACRNNConfig, batch: int, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Zero LSTM state ``(h, c)``, each ``(L, B, H)`` (acRNN starts from zeros)."""
    shape = (config.num_layers, int(batch), config.hidden_size)
    return np.zeros(shape, dtype=dtype), np.zeros(shape, dtype=dtype)


def _step(params, config, x_t, state):
    h_top, new_state, lcache = lstm_step_forward(x_t, state, params, "lstm", config.num_layers, config.skewed)
    y_t, dcache = linear_forward(h_top, params, "decoder")                 # (B, F)
    return y_t, new_state, (lcache, dcache)


def step(params: Mapping[str, np.ndarray], config: ACRNNConfig, x_t, state):
    """One online step: read frame ``x_t`` ``(B, F)`` (standardised), return the predicted next frame.

    Returns
    -------
    y_t : ndarray (B, F)
        Standardised prediction of the next frame.
    state : tuple (h, c), each (L, B, H)
    """
    _check_params(params, config)
    y_t, new_state, _ = _step(params, config, x_t, state)
    return y_t, new_state


def _check_sequence(params, config, frames, mask):
    """Checks of :func:`sequence_forward`'s arguments: ``(frames (B, T + 1, F), mask (T,) bool, dtype)``."""
    dt = _check_params(params, config)
    x = float_array(frames, "frames", (None, None, config.frame_size), cast=False)
    if x.dtype != dt:
        raise ValueError(f"frames: expected dtype {dt} (the parameters'), got {x.dtype}")
    T = x.shape[1] - 1
    if T < 1:
        raise ValueError(f"frames: expected at least 2 frames (T + 1 with T >= 1), got shape {x.shape}")
    mask = config.mask(T) if mask is None else np.asarray(mask, dtype=bool)
    if mask.shape != (T,) or not mask[0]:
        raise ValueError(f"mask: expected a bool array of shape ({T},) starting with True, got {mask.shape}")
    return x, mask, dt


def sequence_forward(params: Mapping[str, np.ndarray], config: ACRNNConfig, frames, mask=None):
    """Auto-conditioned training rollout over a window.

    Parameters
    ----------
    params : dict
    config : ACRNNConfig
    frames : ndarray (B, T + 1, F)
        Standardised ground-truth frames ``f_0 … f_T``.
    mask : ndarray of bool (T,), optional
        True where step t reads the ground truth ``f_t``, False where it reads its own previous output;
        ``mask[0]`` must be True. Default ``config.mask(T)``.

    Returns
    -------
    pred : ndarray (B, T, F)
        ``pred[:, t]`` predicts ``frames[:, t + 1]``.
    cache : dict
    """
    x, mask, dt = _check_sequence(params, config, frames, mask)
    B, T = x.shape[0], x.shape[1] - 1
    state = init_state(config, B, dt)
    pred = np.empty((B, T, config.frame_size), dtype=dt)
    caches = []
    for t in range(T):
        x_t = x[:, t] if mask[t] else pred[:, t - 1]                      # (B, F)
        pred[:, t], state, c = _step(params, config, x_t, state)
        caches.append(c)
    return pred, dict(caches=caches, mask=mask, dtype=dt)


def sequence_backward(dpred, cache) -> dict[str, np.ndarray]:
    """Back-propagation through time of :func:`sequence_forward`.

    Parameters
    ----------
    dpred : ndarray (B, T, F)
        Cotangent of ``pred`` (the loss gradient).

    Returns
    -------
    grads : dict
        Full parameter name → gradient.
    """
    caches, mask = cache["caches"], cache["mask"]
    T = len(caches)
    dpred = float_array(dpred, "dpred", (None, T, None), cast=False)
    grads: dict[str, np.ndarray] = {}
    dstate = None
    carry = None  # gradient of y_t from step t+1's input (own-output steps)
    for t in range(T - 1, -1, -1):
        lcache, dcache = caches[t]
        dy = dpred[:, t] if carry is None else dpred[:, t] + carry
        dh_top, g_dec = linear_backward(dy, dcache)
        for k, v in g_dec.items():
            grads[k] = grads[k] + v if k in grads else v
        dx_t, dstate, _ = lstm_step_backward(dh_top, dstate, lcache, accumulate_into=grads)
        carry = None if mask[t] else dx_t
    return grads


def generate(params: Mapping[str, np.ndarray], config: ACRNNConfig, seed, num_frames: int,
             state=None) -> np.ndarray:
    """Synthesis from a seed: read the seed frames, then feed back the own output.

    Parameters
    ----------
    seed : ndarray (B, S, F)
        Standardised seed frames (S = 10 in the paper's evaluation).
    num_frames : int
        N, frames to generate after the seed.
    state : tuple, optional
        Initial LSTM state (default zeros).

    Returns
    -------
    ndarray (B, N, F)
        Standardised frames ``S … S + N − 1``: the first is the prediction after the last seed frame.
    """
    dt = _check_params(params, config)
    s = float_array(seed, "seed", (None, None, config.frame_size), cast=False)
    if s.shape[1] < 1 or s.dtype != dt:
        raise ValueError(f"seed: expected (B, S >= 1, {config.frame_size}) of dtype {dt}, got {s.shape} {s.dtype}")
    if isinstance(num_frames, bool) or not isinstance(num_frames, (int, np.integer)) or num_frames < 1:
        raise ValueError(f"num_frames: expected a positive integer, got {num_frames!r}")
    state = init_state(config, s.shape[0], dt) if state is None else state
    for t in range(s.shape[1]):
        y, state, _ = _step(params, config, s[:, t], state)
    out = np.empty((s.shape[0], num_frames, config.frame_size), dtype=dt)
    out[:, 0] = y
    for n in range(1, num_frames):
        out[:, n], state, _ = _step(params, config, out[:, n - 1], state)
    return out


# ----------------------------------------------------------------------------------------------------------------
# losses: the rows of Table 1
# ----------------------------------------------------------------------------------------------------------------

_QUAT_REPS = ("quaternions", "quaternions+positions")
_QUAT_TERMS = ("quat", "fk", "reg")


@dataclass(frozen=True)
class LossSpec:
    """Everything :func:`loss_forward` needs besides the arrays.

    Attributes
    ----------
    representation : str
        A key of ``refimpl.representations.REPRESENTATIONS``.
    weights : mapping
        ``"mse"`` (every representation); for dual quaternions also ``"reg"``, ``"pos"``, ``"offset"``,
        ``"quat"`` (local), ``"quat_current"``; for quaternion representations ``"quat"`` (L_quat on the
        normalised local quaternions), ``"fk"`` (mean Euclidean distance of FK positions, root at 0), ``"reg"``
        (quaternion norm penalty on the raw output).
    mean, std : ndarray (F,)
        The training set's feature statistics (the loss de-standardises the output for the geometric terms).
    parents : tuple of int (J,)
    offsets : ndarray (J, 3)
        Bone offsets (only for ``"fk"``).
    """

    representation: str
    weights: Mapping[str, float]
    mean: np.ndarray
    std: np.ndarray
    parents: tuple = ()
    offsets: np.ndarray | None = None

    def __post_init__(self):
        rep = REPRESENTATIONS.get(self.representation)
        if rep is None:
            raise ValueError(f"representation: expected one of {list(REPRESENTATIONS)}, got {self.representation!r}")
        allowed = {"mse"}
        if self.representation == "dual_quaternions":
            allowed |= set(DQ_TERM_NAMES)
        elif self.representation in _QUAT_REPS:
            allowed |= set(_QUAT_TERMS)
        if not self.weights or set(self.weights) - allowed:
            raise ValueError(f"weights: expected a non-empty subset of {sorted(allowed)} for "
                             f"{self.representation!r}, got {sorted(self.weights)}")
        mean, std = np.asarray(self.mean, dtype=np.float64), np.asarray(self.std, dtype=np.float64)
        if mean.ndim != 1 or mean.shape != std.shape or (mean.size - 3) % rep.dim or np.any(std <= 0):
            raise ValueError(f"mean, std: expected equal shapes (3 + {rep.dim}·J,) with std > 0, got "
                             f"{mean.shape}, {std.shape}")
        object.__setattr__(self, "mean", mean)
        object.__setattr__(self, "std", std)
        J = (mean.size - 3) // rep.dim
        geometric = set(self.weights) - {"mse"}
        if geometric:
            if len(self.parents) != J:
                raise ValueError(f"parents: expected {J} entries for frames of size {mean.size}, got "
                                 f"{len(self.parents)}")
            if "fk" in self.weights and (self.offsets is None or np.shape(self.offsets) != (J, 3)):
                raise ValueError(f"offsets: expected shape ({J}, 3) for the FK loss, got {np.shape(self.offsets)}")
        object.__setattr__(self, "parents", tuple(int(p) for p in self.parents))

    @classmethod
    def for_variant(cls, variant, mean, std, skeleton=None, weights=None) -> "LossSpec":
        """The loss of a row of Table 1 (``variant``: its ``representation`` and loss ``weights``, a
        :class:`refimpl.protocols.synthesis.Variant`; ``weights`` overrides them, e.g. for the ablation)."""
        v = variant
        w = dict(v.weights if weights is None else weights)
        parents = tuple(skeleton.parents) if skeleton is not None else ()
        offsets = skeleton.offsets if skeleton is not None else None
        return cls(v.representation, w, mean, std, parents, offsets)

    @property
    def num_joints(self) -> int:
        """Joint blocks in a frame (J, or J − 1 for a representation without the root's block)."""
        return (self.mean.size - 3) // REPRESENTATIONS[self.representation].dim


def loss_forward(pred, target, spec: LossSpec):
    """Training loss of acRNN over every step.

    ``total = w_mse · MSE(pred, target) + Σ geometric terms`` on the de-standardised output
    ``raw = pred · std + mean`` (dual quaternions: :func:`refimpl.dq_output_fast.dq_output_loss_forward`; quaternions:
    normalise per joint, then L_quat and the FK position loss).

    Parameters
    ----------
    pred, target : ndarray (B, T, F)
        Standardised prediction and ground truth.
    spec : LossSpec

    Returns
    -------
    total : float
    parts : dict
        Unweighted value of each term.
    cache : tuple
    """
    p = float_array(pred, "pred", (None, None, spec.mean.size), cast=False)
    t = float_array(target, "target", p.shape, cast=False)
    w = dict(spec.weights)
    parts, caches = {}, {}
    if "mse" in w:
        parts["mse"], caches["mse"] = mse_loss_forward(p, t)
    rest = {k: v for k, v in w.items() if k != "mse"}
    if rest:
        mean, std = spec.mean.astype(p.dtype), spec.std.astype(p.dtype)
        J, D = spec.num_joints, REPRESENTATIONS[spec.representation].dim
        raw = (p * std + mean)[..., 3:].reshape(p.shape[:2] + (J, D))     # (B, T, J, D)
        gt = (t * std + mean)[..., 3:].reshape(p.shape[:2] + (J, D))
        if spec.representation == "dual_quaternions":
            _, sub, caches["dq"] = dq_output_loss_forward(raw, gt, spec.parents, rest)
            parts.update(sub)
        else:
            caches["quat"] = _quat_terms_forward(raw[..., :4], gt[..., :4], spec, rest, parts)
    total = float(sum(w[k] * parts[k] for k in w))
    return total, parts, (spec, caches, p.shape, p.dtype)


def _quat_terms_forward(raw_q, gt_q, spec, weights, parts):
    """L_reg, L_quat and the FK position loss of a quaternion output ``raw_q (B, T, J, 4)``."""
    caches = {}
    if "reg" in weights:
        parts["reg"], caches["reg"] = quat_norm_loss_forward(raw_q)
    if "quat" in weights or "fk" in weights:
        q, caches["norm"] = quat_normalize_forward(raw_q)                  # (B, T, J, 4)
        gq = gt_q / np.linalg.norm(gt_q, axis=-1, keepdims=True)
        if "quat" in weights:
            parts["quat"], caches["quat"] = quat_loss_forward(q, gq)
        if "fk" in weights:
            offsets = np.asarray(spec.offsets, dtype=q.dtype)
            zero = np.zeros(q.shape[:-2] + (3,), dtype=q.dtype)
            pos, caches["fk"] = forward_kinematics_forward(q, zero, offsets, spec.parents)   # (B, T, J, 3)
            gpos, _ = forward_kinematics_forward(gq, zero, offsets, spec.parents)
            parts["fk"], caches["fk_e"] = euclidean_loss_forward(pos, gpos)
    return caches


def loss_backward(dtotal, cache) -> np.ndarray:
    """Gradient of :func:`loss_forward` with respect to ``pred`` ``(B, T, F)``."""
    spec, caches, shape, dtype = cache
    d = float(dtotal)
    w = spec.weights
    dpred = np.zeros(shape, dtype=dtype)
    if "mse" in w:
        dpred += mse_loss_backward(d * w["mse"], caches["mse"])
    J, D = spec.num_joints, REPRESENTATIONS[spec.representation].dim
    draw = None
    if "dq" in caches:
        draw = dq_output_loss_backward(d, caches["dq"])                    # (B, T, J, 8)
    elif "quat" in caches:
        c = caches["quat"]
        draw = np.zeros(shape[:2] + (J, D), dtype=dtype)
        dq = np.zeros(shape[:2] + (J, 4), dtype=dtype)
        if "reg" in c:
            draw[..., :4] += quat_norm_loss_backward(d * w["reg"], c["reg"])
        if "quat" in c:
            dq += quat_loss_backward(d * w["quat"], c["quat"])
        if "fk" in c:
            dpos = euclidean_loss_backward(d * w["fk"], c["fk_e"])
            dq += forward_kinematics_backward(dpos, c["fk"])[0]
        if "norm" in c:
            draw[..., :4] += quat_normalize_backward(dq, c["norm"])
    if draw is not None:
        dpred[..., 3:] += draw.reshape(shape[:2] + (J * D,)) * spec.std[3:].astype(dtype)
    return dpred


def loss_and_grads(params: Mapping[str, np.ndarray], config: ACRNNConfig, frames, spec: LossSpec, mask=None):
    """One training evaluation: auto-conditioned rollout, loss over every step, gradients.

    Parameters
    ----------
    frames : ndarray (B, T + 1, F)
        Standardised window (targets are ``frames[:, 1:]``).

    Returns
    -------
    total : float
    parts : dict
    grads : dict
    """
    if config.frame_size != spec.mean.size:
        raise ValueError(f"spec: expected frames of size {config.frame_size} (config.frame_size), got "
                         f"{spec.mean.size}")
    pred, cache = sequence_forward(params, config, frames, mask)
    total, parts, lcache = loss_forward(pred, np.asarray(frames)[:, 1:], spec)
    grads = sequence_backward(loss_backward(1.0, lcache), cache)
    return total, parts, grads


def config_for(representation: str, num_joints: int, **kwargs) -> ACRNNConfig:
    """The config whose frame size is ``3 + D·J`` for ``representation``."""
    return ACRNNConfig(frame_size=frame_size(representation, num_joints), **kwargs)
