"""QTG's fast inference path (spec/qtg.md §6): the network of :mod:`refimpl.models.qtg` with its weights folded,
transposed and bias-augmented once (:func:`prepare_inference`), and :func:`rollout_inference`, which runs the
steps with buffers allocated once per call and written in place (no caches). The training rollout is in
:mod:`refimpl.models.qtg_fast`; tests/test_qtg.py checks both against the reference step to ``TOL_EXACT``.

Shape legend: B batch, T transition frames, P pose size, Z latent size, H GRU hidden size, L GRU layers.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from refimpl.models.qtg import QTGConfig, check_context, check_length, check_params

__all__ = ["QTGInference", "prepare_inference", "rollout_inference"]


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
    dtype = check_params(params, config)
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


def _rollout_buffers(model: QTGInference, past: np.ndarray, B: int, T: int) -> tuple:
    """The buffers of :func:`rollout_inference` and their views, allocated once per call (the loop only calls
    NumPy kernels with ``out=``): frames ``(T + 1, B, P + 1)`` starting at ``past[:, 1]``, the dense layers'
    buffers, the GRU states (at 0) and gate buffers."""
    config, dtype = model.config, model.dtype
    P, Z, H, L = config.pose_size, config.latent_size, config.gru_hidden, config.gru_layers
    H2, H3 = 2 * H, 3 * H
    slope = dtype.type(config.negative_slope)
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

    return (frames, z, enc_layers, dec_layers, dec_first, dec_last, slopes, zz, zz_a, zz_b, hs, gi, gh, hm, velocity,
            n, d, half, cells)


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
    past, target = check_context(past, target, config, dtype)
    T = check_length(T, config)
    B, P, H, L = past.shape[0], config.pose_size, config.gru_hidden, config.gru_layers
    H3 = 3 * H
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

    (frames, z, enc_layers, dec_layers, dec_first, dec_last, slopes, zz, zz_a, zz_b, hs, gi, gh, hm, velocity, n, d,
     half, cells) = _rollout_buffers(model, past, B, T)

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
