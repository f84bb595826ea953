"""QuaterNet recurrent pose network (Pavllo, Feichtenhofer, Auli, Grangier; IJCV 2019, §3.1, §3.6, §3.7).

An autoregressive 2-layer GRU over frames of joint quaternions (spec/quaternet.md §1-§4). One network definition
covers both published instances: the short-term Human3.6M model (velocity mode, 32 joints, no extra inputs) and
the long-term locomotion model (absolute rotations, 26 joints, 2 translations, 6 controls)::

    controls   c (C)  -> fc1 (C -> 30) -> LeakyReLU(0.05) -> fc2 (30 -> 30) -> LeakyReLU(0.05) -> a  (only if C > 0)
    GRU input  g = [q (4J) | translations (O) | a (30, if C > 0)]                        rnn.*_l0, rnn.*_l1
    state      h_t = GRU(g_t, h_{t-1}),  h_{-1} = h0 (learned, (L, 1, H) broadcast over the batch)
    head       o_t = fc(h_t) = [Δ (4J) | τ (O)]                                            fc
    rotations  velocity mode: q̂ = normalize(Δ_j ⊗ q_in,j) per joint j; absolute: q̂ = normalize(Δ_j)
    output     y_t = [q̂ (4J) | τ (O)]   (translations raw, no activation)

With ``representation="dual_quaternion"`` (Andreou et al. §6.2; spec/quaternet.md §9) every joint block is a
current (root-relative) dual quaternion of 8 numbers instead of a local quaternion of 4: ``D = 8`` replaces 4 in
every size below, the head normalises with Eq. 13 (``refimpl.nn.quat_layers.dq_normalize_forward``) and velocity
mode is ``N(ΔD_j ⊗ D_in,j)`` (``dq_velocity_forward``).

``y_t`` predicts frame ``t + 1``. ``Δ`` (called ``pre``, the un-normalised output before the QMul) feeds the
quaternion norm penalty (``refimpl.losses.quat_norm_loss_forward``). Parameters carry the state-dict names of the
published PyTorch code (``h0``, ``rnn.weight_ih_l0``…, ``fc.weight``, ``fc1.*``, ``fc2.*``) so a converted
published state dict loads unchanged: 9,526,128 parameters short-term (J = 32), 9,529,246 long-term (J = 26).

The training sequence (prefix, then scheduled sampling, full BPTT; spec/quaternet.md §3) is
:func:`refimpl.models.quaternet_sequence.forward` / ``backward``, built on this module's blocks.

Online use: :func:`init_state`, :func:`step` (one frame in, one prediction out; what the ONNX exporter
translates) and :func:`predict` (prefix -> k frames, built on :func:`step`).

Shape legend: B batch, P prefix frames, T predicted frames, J joints, O translations, C controls, H hidden size,
L GRU layers, D joint width (4 quaternions, 8 dual quaternions), F = DJ + O + C input features per frame,
G = DJ + O output features, I = DJ + O (+ 30) GRU input.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from refimpl.models._shared import check_param_dict
from refimpl.nn.activations import leaky_relu_backward, leaky_relu_forward
from refimpl.nn.gru import gru_backward, gru_forward, gru_init, gru_step_backward, gru_step_forward
from refimpl.nn.linear import linear_backward, linear_forward, linear_init
from refimpl.arrays import float_array
from refimpl.nn.params import accumulate_grads, init_normal
from refimpl.nn.quat_layers import (dq_normalize_backward, dq_normalize_forward, dq_velocity_backward,
                                    dq_velocity_forward, qmul_velocity_backward, qmul_velocity_forward,
                                    quat_normalize_backward, quat_normalize_forward)

__all__ = [
    "JOINT_WIDTH", "QuaterNetConfig", "param_shapes", "published_names", "count_parameters", "init_params", "check_params",
    "init_state", "step", "predict",
]

#: Hidden size of the controls block (two dense layers, hard-coded in the published code).
CONTROLS_HIDDEN = 30
#: Joint representations of the rotation block -> numbers per joint.
JOINT_WIDTH = {"quaternion": 4, "dual_quaternion": 8}


# ----------------------------------------------------------------------------------------------------------------
# configuration and parameters
# ----------------------------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class QuaterNetConfig:
    """Sizes and modes of the recurrent pose network (defaults: the paper's short-term Human3.6M model).

    Attributes
    ----------
    num_joints : int
        J; the rotation block is ``D J`` features, joint-major: ``(w, x, y, z)`` per joint, or ``(q_r | q_d)``
        for dual quaternions.
    num_outputs : int
        O, extra raw outputs fed back as inputs ("Translations" block; long-term: 2).
    num_controls : int
        C, input-only features passed through the controls block ("Controls"; long-term: 6). 0 = no block.
    velocity : bool
        Velocity mode: the output rotation is ``normalize(Δ ⊗ q_in)`` (QMul with the input quaternion of the same
        step); otherwise absolute rotations ``normalize(Δ)``. Short-term True, long-term False.
    hidden_size : int
        H, units per GRU layer (1000 in the paper).
    num_layers : int
        L, stacked GRU layers (2 in the paper).
    controls_hidden : int
        Width of both controls layers (30 in the paper).
    negative_slope : float
        LeakyReLU slope of the controls block (0.05 in the paper).
    eps : float
        Normalisation clamp ``q / max(|q|, eps)`` (PyTorch ``F.normalize`` default 1e-12).
    representation : str
        ``"quaternion"`` (QuaterNet: local quaternions, 4 per joint) or ``"dual_quaternion"`` (Andreou et al. §6.2:
        current dual quaternions ``(q_r | q_d)``, 8 per joint, Eq. 13 normalisation, dual-quaternion QMul).
    """

    num_joints: int = 32
    num_outputs: int = 0
    num_controls: int = 0
    velocity: bool = True
    hidden_size: int = 1000
    num_layers: int = 2
    controls_hidden: int = CONTROLS_HIDDEN
    negative_slope: float = 0.05
    eps: float = 1e-12
    representation: str = "quaternion"

    def __post_init__(self):
        for name, low in (("num_joints", 1), ("num_outputs", 0), ("num_controls", 0), ("hidden_size", 1),
                          ("num_layers", 1), ("controls_hidden", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < low:
                raise ValueError(f"QuaterNetConfig.{name}: expected an integer >= {low}, got {v!r}")
        if not isinstance(self.velocity, (bool, np.bool_)):
            raise ValueError(f"QuaterNetConfig.velocity: expected a bool, got {self.velocity!r}")
        if not 0.0 <= float(self.negative_slope) < 1.0:
            raise ValueError(f"QuaterNetConfig.negative_slope: expected a value in [0, 1), got {self.negative_slope}")
        if not (np.isfinite(self.eps) and self.eps > 0):
            raise ValueError(f"QuaterNetConfig.eps: expected a finite value > 0, got {self.eps}")
        if self.representation not in JOINT_WIDTH:
            raise ValueError(f"QuaterNetConfig.representation: expected one of {tuple(JOINT_WIDTH)}, "
                             f"got {self.representation!r}")

    @classmethod
    def short_term(cls, num_joints: int = 32, **kw) -> "QuaterNetConfig":
        """The short-term model (§3.6): velocity mode, no translations or controls (9,526,128 params at J = 32)."""
        return cls(num_joints=num_joints, num_outputs=0, num_controls=0, velocity=True, **kw)

    @classmethod
    def long_term(cls, num_joints: int = 26, num_outputs: int = 2, num_controls: int = 6, **kw) -> "QuaterNetConfig":
        """The long-term model (§3.7): absolute rotations, 2 translations, 6 controls (9,529,246 params at J = 26)."""
        return cls(num_joints=num_joints, num_outputs=num_outputs, num_controls=num_controls, velocity=False, **kw)

    @property
    def joint_width(self) -> int:
        """D: 4 (quaternions) or 8 (dual quaternions)."""
        return JOINT_WIDTH[self.representation]

    @property
    def rotation_size(self) -> int:
        """D J."""
        return self.joint_width * self.num_joints

    @property
    def output_size(self) -> int:
        """G = D J + O, features of a prediction ``[q̂ | τ]``."""
        return self.rotation_size + self.num_outputs

    @property
    def input_size(self) -> int:
        """F = D J + O + C, features of an input frame ``[q | τ | c]``."""
        return self.output_size + self.num_controls

    @property
    def gru_input_size(self) -> int:
        """I = D J + O (+ controls_hidden when C > 0)."""
        return self.output_size + (self.controls_hidden if self.num_controls > 0 else 0)

    def to_dict(self) -> dict:
        """Plain JSON-friendly dict; ``QuaterNetConfig(**d)`` rebuilds it."""
        return {"num_joints": int(self.num_joints), "num_outputs": int(self.num_outputs),
                "num_controls": int(self.num_controls), "velocity": bool(self.velocity),
                "hidden_size": int(self.hidden_size), "num_layers": int(self.num_layers),
                "controls_hidden": int(self.controls_hidden), "negative_slope": float(self.negative_slope),
                "eps": float(self.eps), "representation": str(self.representation)}


def param_shapes(config: QuaterNetConfig = QuaterNetConfig()) -> dict[str, tuple[int, ...]]:
    """Name -> shape of every parameter, the published state-dict names and PyTorch layouts.

    ``h0 (L, 1, H)``; ``rnn.weight_ih_l{k} (3H, I_k)``, ``rnn.weight_hh_l{k} (3H, H)``, ``rnn.bias_ih_l{k}``,
    ``rnn.bias_hh_l{k} (3H,)`` (gate blocks r|z|n); ``fc.weight (G, H)``, ``fc.bias (G,)``; with controls
    ``fc1.weight (30, C)``, ``fc1.bias (30,)``, ``fc2.weight (30, 30)``, ``fc2.bias (30,)``.
    """
    H, L = config.hidden_size, config.num_layers
    shapes: dict[str, tuple[int, ...]] = {}
    if config.num_controls > 0:
        K = config.controls_hidden
        shapes.update({"fc1.weight": (K, config.num_controls), "fc1.bias": (K,),
                       "fc2.weight": (K, K), "fc2.bias": (K,)})
    for k in range(L):
        shapes[f"rnn.weight_ih_l{k}"] = (3 * H, config.gru_input_size if k == 0 else H)
        shapes[f"rnn.weight_hh_l{k}"] = (3 * H, H)
        shapes[f"rnn.bias_ih_l{k}"] = (3 * H,)
        shapes[f"rnn.bias_hh_l{k}"] = (3 * H,)
    shapes["h0"] = (L, 1, H)
    shapes["fc.weight"] = (config.output_size, H)
    shapes["fc.bias"] = (config.output_size,)
    return shapes


def published_names(config: QuaterNetConfig = QuaterNetConfig()) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Name map to the published code (facebookresearch/QuaterNet ``common/quaternet.py``, the short-term and the
    long-term instance): our name -> ``(published name, published shape)``. The identity: our parameters carry
    the published names and layouts (:func:`param_shapes`)."""
    return {name: (name, shape) for name, shape in param_shapes(config).items()}


def count_parameters(config: QuaterNetConfig = QuaterNetConfig()) -> int:
    """Number of scalar parameters, from the shapes (nothing allocated): 9,526,128 for the defaults."""
    return int(sum(int(np.prod(s)) for s in param_shapes(config).values()))


def init_params(config: QuaterNetConfig = QuaterNetConfig(), rng: np.random.Generator | None = None,
                dtype=np.float64) -> dict[str, np.ndarray]:
    """The published code's initialisation (PyTorch defaults, spec/quaternet.md §2).

    GRU ``U(±1/sqrt(H))``; dense layers ``U(±1/sqrt(in))``; ``h0 ~ N(0, 0.01²)``.

    Parameters
    ----------
    config : QuaterNetConfig
    rng : numpy.random.Generator
        Required (no hidden global state).
    dtype : float32 or float64

    Returns
    -------
    dict
        Names and shapes of :func:`param_shapes`.
    """
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    _check_config(config)
    params: dict[str, np.ndarray] = {}
    if config.num_controls > 0:
        params.update(linear_init(rng, config.num_controls, config.controls_hidden, "fc1", dtype=dtype))
        params.update(linear_init(rng, config.controls_hidden, config.controls_hidden, "fc2", dtype=dtype))
    params.update(gru_init(rng, config.gru_input_size, config.hidden_size, config.num_layers, "rnn", dtype=dtype))
    params["h0"] = init_normal(rng, (config.num_layers, 1, config.hidden_size), 0.01, dtype=dtype)
    params.update(linear_init(rng, config.hidden_size, config.output_size, "fc", dtype=dtype))
    return params


# ----------------------------------------------------------------------------------------------------------------
# public boundary checks
# ----------------------------------------------------------------------------------------------------------------

def _check_config(config) -> QuaterNetConfig:
    if not isinstance(config, QuaterNetConfig):
        raise ValueError(f"config: expected a QuaterNetConfig, got {type(config).__name__}")
    return config


def check_params(params: Mapping[str, np.ndarray], config: QuaterNetConfig = QuaterNetConfig()) -> np.dtype:
    """Validate a parameter dict against ``config`` (names, shapes, one float dtype); return the dtype.

    Extra entries are refused too, so a state dict of a different model is not silently half-used.

    Raises
    ------
    ValueError
        Naming the missing, unexpected or mis-shaped parameter.
    """
    _check_config(config)
    return check_param_dict(params, param_shapes(config))


def check_frames(x, name: str, config: QuaterNetConfig, dtype, batch=None, ndim: int = 3) -> np.ndarray:
    F = config.input_size
    shape = (batch, None, F) if ndim == 3 else (batch, F)
    x = float_array(x, name, shape, context=f"F = DJ + O + C = {F} from the config", cast=False)
    if x.dtype != dtype:
        raise ValueError(f"{name}: expected dtype {dtype} (the parameters' dtype), got {x.dtype}")
    return x


def check_mask(mask, steps: int) -> np.ndarray:
    m = np.asarray(mask)
    if m.dtype != np.bool_ or m.shape != (steps,):
        raise ValueError(f"mask: expected a bool array of shape ({steps},) (T - 1 decisions), "
                         f"got dtype {m.dtype} shape {m.shape}")
    return m


# ----------------------------------------------------------------------------------------------------------------
# building blocks: controls block, output head, one frame
# ----------------------------------------------------------------------------------------------------------------

def input_forward(params, x, config: QuaterNetConfig):
    """GRU input ``g = [x[..., :G] | controls block (x[..., G:])]`` over any leading axes (x (..., F))."""
    G = config.output_size
    if config.num_controls == 0:
        return x, None
    s = config.negative_slope
    c1, l1 = linear_forward(x[..., G:], params, "fc1")
    a1, r1 = leaky_relu_forward(c1, s)
    c2, l2 = linear_forward(a1, params, "fc2")
    a2, r2 = leaky_relu_forward(c2, s)
    return np.concatenate([x[..., :G], a2], axis=-1), (l1, r1, l2, r2)


def input_backward(dg, cache, config: QuaterNetConfig, grads: dict) -> np.ndarray:
    """Cotangent of the frame ``x (..., F)`` from that of the GRU input ``g``; adds the controls-block grads."""
    if cache is None:
        return dg.copy()
    G = config.output_size
    l1, r1, l2, r2 = cache
    dx = np.empty(dg.shape[:-1] + (config.input_size,), dtype=dg.dtype)
    dx[..., :G] = dg[..., :G]
    d = leaky_relu_backward(np.ascontiguousarray(dg[..., G:]), r2)
    d, g2 = linear_backward(d, l2)
    d = leaky_relu_backward(d, r1)
    dx[..., G:], g1 = linear_backward(d, l1)
    accumulate_grads(grads, g2)
    accumulate_grads(grads, g1)
    return dx


def head_forward(params, top, x, config: QuaterNetConfig):
    """``o = fc(top)``, ``y = [normalize(Δ ⊗ q_in) or normalize(Δ) | τ]`` (Eq. 13 and the DQ product for
    dual quaternions).

    Returns ``(y (B, G), pre (B, DJ), cache)``.

    ``x (B, F)`` is the frame fed at this step (its joint blocks are ``q_in`` in velocity mode)."""
    B, R = top.shape[0], config.rotation_size
    J, D = config.num_joints, config.joint_width
    o, lc = linear_forward(top, params, "fc")  # (B, G)
    pre = o[:, :R]  # (B, DJ) view
    dual = D == 8
    if config.velocity:
        fwd = dq_velocity_forward if dual else qmul_velocity_forward
        q, qc = fwd(pre.reshape(B, J, D), x[:, :R].reshape(B, J, D), config.eps)
    else:
        q, qc = (dq_normalize_forward if dual else quat_normalize_forward)(pre.reshape(B, J, D), config.eps)
    y = np.concatenate([q.reshape(B, R), o[:, R:]], axis=1)  # (B, G)
    return y, pre.copy(), (lc, qc)


def head_backward(dy, dpre, cache, config: QuaterNetConfig, grads: dict):
    """Returns ``(dtop (B, H), dq_in (B, DJ) or None)``; adds the fc gradients into ``grads``."""
    lc, qc = cache
    B, R, J, D = dy.shape[0], config.rotation_size, config.num_joints, config.joint_width
    do = np.empty_like(dy)  # (B, G)
    dq = np.ascontiguousarray(dy[:, :R]).reshape(B, J, D)
    if config.velocity:
        dd, dqin = (dq_velocity_backward if D == 8 else qmul_velocity_backward)(dq, qc)
        dqin = dqin.reshape(B, R)
    else:
        dd, dqin = (dq_normalize_backward if D == 8 else quat_normalize_backward)(dq, qc), None
    do[:, :R] = dd.reshape(B, R)
    if dpre is not None:
        do[:, :R] += dpre
    do[:, R:] = dy[:, R:]
    dtop, g = linear_backward(do, lc)
    accumulate_grads(grads, g)
    return dtop, dqin


def frame_forward(params, x, h, config: QuaterNetConfig):
    """One step: frame ``x (B, F)``, state ``h (L, B, H)`` -> ``(y (B, G), pre (B, DJ), h_new, cache)``."""
    g, ic = input_forward(params, x, config)
    top, h_new, gc = gru_step_forward(g, h, params, "rnn", config.num_layers)
    y, pre, hc = head_forward(params, top, x, config)
    return y, pre, h_new, (ic, gc, hc)


def run_forward(params, frames, h, config: QuaterNetConfig):
    """Consecutive teacher-forced steps, vectorised: ``frames (B, n, F)`` fed from state ``h (L, B, H)`` through
    one sequence GRU pass (as the prefix) and the head on all ``n`` outputs at once (it works row by row).

    Returns ``(y (B, n, G), pre (B, n, DJ), h_new, cache)``: the same numbers as ``n`` calls of
    :func:`frame_forward` (up to the summation order of the products)."""
    B, n, F = frames.shape
    g, ic = input_forward(params, frames, config)  # (B, n, I)
    tops, h_new, gc = gru_forward(g, h, params, "rnn", config.num_layers)  # (B, n, H)
    y, pre, hc = head_forward(params, tops.reshape(B * n, -1), frames.reshape(B * n, F), config)
    return y.reshape(B, n, -1), pre.reshape(B, n, -1), h_new, (ic, gc, hc, n)


def run_backward(dy, dpre, dh_new, cache, config: QuaterNetConfig, grads: dict):
    """Backward of :func:`run_forward`: ``dy (B, n, G)``, ``dpre (B, n, DJ)`` or None, ``dh_new`` (L, B, H) or
    None -> ``(dframes (B, n, F), dh (L, B, H))``; adds into ``grads``."""
    ic, gc, hc, n = cache
    B = dy.shape[0]
    dtop, dqin = head_backward(dy.reshape(B * n, -1), None if dpre is None else dpre.reshape(B * n, -1), hc,
                                config, grads)
    dg, dh, g = gru_backward(dtop.reshape(B, n, -1), dh_new, gc)
    accumulate_grads(grads, g)
    dx = input_backward(dg, ic, config, grads)  # (B, n, F)
    if dqin is not None:
        dx[..., :config.rotation_size] += dqin.reshape(B, n, -1)
    return dx, dh


def frame_backward(dy, dpre, dh_new, cache, config: QuaterNetConfig, grads: dict):
    """Backward of :func:`frame_forward`: returns ``(dx (B, F), dh (L, B, H))``; adds into ``grads``."""
    ic, gc, hc = cache
    dtop, dqin = head_backward(dy, dpre, hc, config, grads)
    dg, dh, _ = gru_step_backward(dtop, dh_new, gc, accumulate_into=grads)
    dx = input_backward(dg, ic, config, grads)
    if dqin is not None:
        dx[:, :config.rotation_size] += dqin
    return dx, dh


# ----------------------------------------------------------------------------------------------------------------
# online use: state, step, predict
# ----------------------------------------------------------------------------------------------------------------

def init_state(params: Mapping[str, np.ndarray], batch_size: int,
               config: QuaterNetConfig = QuaterNetConfig()) -> np.ndarray:
    """The learned initial state ``h0`` repeated over the batch: ``(L, B, H)`` (a new array)."""
    check_params(params, config)
    if isinstance(batch_size, bool) or not isinstance(batch_size, (int, np.integer)) or batch_size < 1:
        raise ValueError(f"batch_size: expected a positive integer, got {batch_size!r}")
    h0 = params["h0"]
    return np.repeat(h0, int(batch_size), axis=1)  # (L, B, H)


def step(params: Mapping[str, np.ndarray], state, x,
         config: QuaterNetConfig = QuaterNetConfig()) -> tuple[np.ndarray, np.ndarray]:
    """One frame in, the prediction of the next frame out (spec/quaternet.md §1); what the exporter translates.

    Parameters
    ----------
    params : dict
        From :func:`init_params` (or a converted published state dict); float32 or float64.
    state : ndarray (L, B, H)
        GRU states after the previous frame (:func:`init_state` at the start).
    x : ndarray (B, F)
        The current frame ``[q (DJ) | τ (O) | c (C)]``: ground truth, or the previous prediction ``y`` with the
        frame's controls appended.

    Returns
    -------
    y : ndarray (B, G)
        ``[q̂ (DJ, unit per joint) | τ (O)]``, the prediction of the next frame.
    state : ndarray (L, B, H)
    """
    dtype = check_params(params, config)
    x = check_frames(x, "x", config, dtype, ndim=2)
    B = x.shape[0]
    state = float_array(state, "state", (config.num_layers, B, config.hidden_size),
                        context=f"L = {config.num_layers}, H = {config.hidden_size} from the config, "
                                f"B = {B} from x", cast=False)
    if state.dtype != dtype:
        raise ValueError(f"state: expected dtype {dtype} (the parameters' dtype), got {state.dtype}")
    y, _, h_new, _ = frame_forward(params, x, state, config)
    return y, h_new


def predict(params: Mapping[str, np.ndarray], prefix, k: int, config: QuaterNetConfig = QuaterNetConfig(),
            controls=None) -> np.ndarray:
    """Feed ``prefix`` frame by frame through :func:`step`, then run free for ``k - 1`` more frames.

    Parameters
    ----------
    prefix : ndarray (B, P, F), P >= 1
        Conditioning frames (ground truth).
    k : int
        Frames to predict (>= 1).
    controls : ndarray (B, k - 1, C), optional
        The controls appended to each fed-back prediction (frames P … P + k - 2); required when C > 0.

    Returns
    -------
    ndarray (B, k, G)
        Predictions of frames ``P … P + k - 1``. Equals :func:`forward` with an all-False mask.
    """
    dtype = check_params(params, config)
    prefix = check_frames(prefix, "prefix", config, dtype)
    B, P, _ = prefix.shape
    if P < 1:
        raise ValueError(f"prefix: expected at least one frame (B, P >= 1, F), got {prefix.shape}")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k: expected a positive integer number of frames, got {k!r}")
    C = config.num_controls
    if C > 0:
        if controls is None:
            raise ValueError(f"controls: required (shape ({B}, {k - 1}, {C})) when the config has controls")
        controls = float_array(controls, "controls", (B, k - 1, C), cast=False)
        if controls.dtype != dtype:
            raise ValueError(f"controls: expected dtype {dtype} (the parameters' dtype), got {controls.dtype}")
    elif controls is not None and np.size(controls) > 0:
        raise ValueError("controls: the config has no controls (num_controls = 0)")
    h = init_state(params, B, config)
    for t in range(P):
        y, h = step(params, h, prefix[:, t], config)
    out = [y]
    for i in range(k - 1):
        x = y if C == 0 else np.concatenate([y, controls[:, i]], axis=1)
        y, h = step(params, h, x, config)
        out.append(y)
    return np.stack(out, axis=1)  # (B, k, G)


# Kernel tier (spec/architecture.md; not in __all__, imported by refimpl.models.quaternet_sequence under these names):
# check_frames, check_mask, frame_backward, frame_forward, head_backward, head_forward, input_backward, input_forward,
# run_backward, run_forward.
