"""QuaterNet's training sequence (spec/quaternet.md §3): the recurrent network of :mod:`refimpl.models.quaternet`
unrolled over a prefix and ``T`` predicted frames under scheduled sampling, and its backward.

:func:`forward`: the ``P`` prefix frames are fed (teacher forced, one vectorised GRU pass), giving the first
prediction; then ``T - 1`` steps, each fed either the ground-truth frame (``mask[i]`` True) or the previous
prediction with the ground-truth controls of that frame (``mask[i]`` False). The mask is one Bernoulli draw per
time step shared by the batch (``refimpl.schedules.scheduled_sampling_mask``). No detach: :func:`backward`
back-propagates through the fed-back predictions (and, in velocity mode, through the QMul's input quaternion),
i.e. full BPTT through the autoregressive loop.

Shape legend: B batch, P prefix frames, T predicted frames, J joints, O translations, C controls, H hidden size,
L GRU layers, D joint width (4 quaternions, 8 dual quaternions), F = DJ + O + C input features per frame,
G = DJ + O output features, R = DJ rotation features.
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.nn.params import accumulate_grads
from refimpl.models.quaternet import (QuaterNetConfig, check_frames, check_mask, check_params, frame_backward,
                                      frame_forward, head_backward, head_forward, init_state, input_backward,
                                      input_forward, run_backward, run_forward, step)
from refimpl.nn.gru import gru_backward, gru_forward
from refimpl.arrays import float_array

__all__ = ["forward", "backward"]


def forward(params: Mapping[str, np.ndarray], prefix, future, mask, config: QuaterNetConfig = QuaterNetConfig()):
    """Training forward: prefix, then ``T - 1`` steps under scheduled sampling (spec/quaternet.md §3).

    Step ``i`` (``0 <= i < T - 1``) produces the prediction of future frame ``i + 1`` from the fed frame
    ``x = future[:, i]`` if ``mask[i]`` (teacher forcing) else ``x = [y_i | future[:, i, G:]]`` (the previous
    prediction with the ground-truth controls of that frame). The hidden state is carried throughout.

    Parameters
    ----------
    params : dict
    prefix : ndarray (B, P, F), P >= 1
        Ground-truth frames ``0 … P-1``; the GRU runs over them in one vectorised pass.
    future : ndarray (B, T, F), T >= 1
        Ground-truth frames ``P … P+T-1``; the targets are ``future[..., :G]``.
    mask : ndarray of bool (T - 1,)
        True = feed the ground truth at that step (one draw per step, shared by the batch;
        ``refimpl.schedules.scheduled_sampling_mask(ratio, T - 1, rng)``).

    Returns
    -------
    y : ndarray (B, T, G)
        Predictions of frames ``P … P+T-1``: unit quaternions per joint, then the raw translations.
    pre : ndarray (B, T, DJ)
        The un-normalised head output ``Δ`` before the QMul (for the norm penalty).
    cache : dict
        For :func:`backward`.
    """
    dtype = check_params(params, config)
    prefix = check_frames(prefix, "prefix", config, dtype)
    B, P, _ = prefix.shape
    future = check_frames(future, "future", config, dtype, batch=B)
    T = future.shape[1]
    if P < 1 or T < 1:
        raise ValueError(f"prefix, future: expected at least one frame each, got {prefix.shape} and {future.shape}")
    mask = check_mask(mask, T - 1)
    G, L = config.output_size, config.num_layers
    h0 = np.repeat(params["h0"], B, axis=1)  # (L, B, H)
    g, ic = input_forward(params, prefix, config)  # (B, P, I)
    tops, h, gc = gru_forward(g, h0, params, "rnn", L)
    y, pre, hc = head_forward(params, tops[:, -1], prefix[:, -1], config)
    ys, pres, segments = [y[:, None]], [pre[:, None]], []
    i = 0
    while i < T - 1:
        if mask[i]:  # a run of teacher-forced steps: its frames are known, one vectorised GRU pass as the prefix
            j = i + 1
            while j < T - 1 and mask[j]:
                j += 1
            y, pre, h, c = run_forward(params, future[:, i:j], h, config)
            ys.append(y)
            pres.append(pre)
            segments.append(("run", i, j, c))
            y = y[:, -1]
            i = j
        else:
            x = np.concatenate([y, future[:, i, G:]], axis=1)  # the prediction fed back, with its controls
            y, pre, h, c = frame_forward(params, x, h, config)
            ys.append(y[:, None])
            pres.append(pre[:, None])
            segments.append(("step", i, i + 1, c))
            i += 1
    cache = dict(config=config, mask=mask, shape=(B, P, T), prefix=(ic, gc, hc), segments=segments, dtype=dtype)
    return np.concatenate(ys, axis=1), np.concatenate(pres, axis=1), cache


def backward(dy, dpre, cache, input_grads: bool = False):
    """Back-propagation through the whole unrolled sequence of :func:`forward` (spec/quaternet.md §3.2).

    The cotangent of each prediction is the loss's plus, when it was fed back (``mask[i]`` False), the cotangent
    of the next step's input ``x[:, :G]`` (through the GRU input and, in velocity mode, the QMul's ``q_in``).

    Parameters
    ----------
    dy : ndarray (B, T, G)
        Cotangent of ``y``.
    dpre : ndarray (B, T, DJ) or None
        Cotangent of ``pre`` (the norm penalty's gradient), or None (zero).
    cache : dict
        From :func:`forward`.
    input_grads : bool
        Also return the cotangents of ``prefix`` and ``future``.

    Returns
    -------
    grads : dict
        Full parameter names -> gradients (every parameter, ``h0`` included).
    dprefix : ndarray (B, P, F)
        Only with ``input_grads``.
    dfuture : ndarray (B, T, F)
        Only with ``input_grads``. Zero at frames that were replaced by a fed-back prediction, except their
        controls; zero at the last future frame (never fed).
    """
    config: QuaterNetConfig = cache["config"]
    B, P, T = cache["shape"]
    G, R = config.output_size, config.rotation_size
    dy = float_array(dy, "dy", (B, T, G), cast=False)
    if dpre is not None:
        dpre = float_array(dpre, "dpre", (B, T, R), cast=False)
    dtype = cache["dtype"]
    grads: dict = {}
    dfuture = np.zeros((B, T, config.input_size), dtype=dtype)
    carry = None  # cotangent of the prediction fed back into the step after it
    dh = None
    for kind, i, j, c in reversed(cache["segments"]):  # steps i … j − 1 predict frames i + 1 … j
        d = dy[:, i + 1:j + 1].copy()  # (B, j − i, G)
        if carry is not None:  # step j fed back the prediction of frame j
            d[:, -1] += carry
        dp = None if dpre is None else dpre[:, i + 1:j + 1]
        if kind == "run":
            dfuture[:, i:j], dh = run_backward(d, dp, dh, c, config, grads)
            carry = None
        else:
            dx, dh = frame_backward(d[:, 0], None if dp is None else dp[:, 0], dh, c, config, grads)
            dfuture[:, i, G:] = dx[:, G:]
            carry = dx[:, :G]
    ic, gc, hc = cache["prefix"]
    d = dy[:, 0] if carry is None else dy[:, 0] + carry
    dtop, dqin = head_backward(d, None if dpre is None else dpre[:, 0], hc, config, grads)
    dtops = np.zeros((B, P, config.hidden_size), dtype=dtype)
    dtops[:, -1] = dtop
    dg, dh0, g = gru_backward(dtops, dh, gc)
    accumulate_grads(grads, g)
    grads["h0"] = dh0.sum(axis=1, keepdims=True)
    dprefix = input_backward(dg, ic, config, grads)
    if dqin is not None:
        dprefix[:, -1, :R] += dqin
    if input_grads:
        return grads, dprefix, dfuture
    return grads


def _forward_per_step(params, prefix, future, mask, config: QuaterNetConfig = QuaterNetConfig()):
    """Slow oracle of :func:`forward`: every frame, prefix included, through the public :func:`step`."""
    B, P, _ = prefix.shape
    G = config.output_size
    h = init_state(params, B, config)
    for t in range(P):
        y, h = step(params, h, prefix[:, t], config)
    ys = [y]
    for i in range(future.shape[1] - 1):
        x = future[:, i] if mask[i] else np.concatenate([y, future[:, i, G:]], axis=1)
        y, h = step(params, h, x, config)
        ys.append(y)
    return np.stack(ys, axis=1)


def _backward_per_step(dy, dpre, params, prefix, future, mask, config: QuaterNetConfig = QuaterNetConfig()):
    """Slow oracle of :func:`backward`: forward and backward of every frame, prefix included, one step at a time
    (:func:`frame_forward` / :func:`frame_backward`, no vectorised prefix). Returns ``(grads, dprefix, dfuture)``."""
    B, P, _ = prefix.shape
    T = future.shape[1]
    G = config.output_size
    h = np.repeat(params["h0"], B, axis=1)
    caches, fed_back = [], []
    y = None
    for s in range(P + T - 1):  # frame s of the fed sequence; from s = P - 1 on its output is a prediction
        i = s - P
        if s < P:
            x = prefix[:, s]
        elif mask[i]:
            x = future[:, i]
        else:
            x = np.concatenate([y, future[:, i, G:]], axis=1)
        y, _, h, c = frame_forward(params, x, h, config)
        caches.append(c)
        fed_back.append(s >= P and not mask[i])
    grads: dict = {}
    dprefix = np.zeros_like(prefix)
    dfuture = np.zeros_like(future)
    dh, carry = None, None
    for s in range(P + T - 2, -1, -1):
        t = s - (P - 1)  # index of the prediction this frame makes (< 0: none)
        d = np.zeros((B, G), dtype=prefix.dtype) if t < 0 else dy[:, t].copy()
        if carry is not None:
            d += carry
        dp = None if (t < 0 or dpre is None) else dpre[:, t]
        dx, dh = frame_backward(d, dp, dh, caches[s], config, grads)
        carry = None
        if s < P:
            dprefix[:, s] = dx
        elif fed_back[s]:
            carry = dx[:, :G]
            dfuture[:, s - P, G:] = dx[:, G:]
        else:
            dfuture[:, s - P] = dx
    grads["h0"] = dh.sum(axis=1, keepdims=True)
    return grads, dprefix, dfuture
