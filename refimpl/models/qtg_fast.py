"""QTG's fast training path (spec/qtg.md §4): the fused training rollout and its backward; the in-place inference
rollout is in :mod:`refimpl.models.qtg_fast_inference`.

Same network and equations as the readable reference :mod:`refimpl.models.qtg` (config, parameters,
:func:`~refimpl.models.qtg.step`), rearranged for speed; tests/test_qtg.py checks both against the reference
step and the oracles there (``_rollout_naive``, ``_rollout_backward_per_step``) to ``TOL_EXACT``.

:func:`rollout_forward` / :func:`rollout_backward`: the rollout keeps every layer's inputs time-major
(``_Record``); the reverse loop propagates only the input and state cotangents and keeps the pre-activation
cotangents, and each weight gradient is then ONE matrix product over the stacked rows of all steps
(``_weight_grads``). Gradients flow through the fed-back poses, the carried latents, the GRU state and the
target encodings (BPTT, no detaching). Fused per step (spec/qtg.md §4): layer 0's input gates from one product
of ``z_t`` with ``[W1 − W2 ; W1]``, the top GRU state times ``[W_hh ; W_v]`` once (forward and backward), the
gate and LeakyReLU factors of the backward formed for all steps before the reverse loop (``_Factors``).

Kernels from the layers' kernel tier: :func:`refimpl.nn.linear.matmul_wt`, :func:`refimpl.nn.gru.input_gates`,
:func:`refimpl.nn.gru.cell_forward`, :func:`refimpl.nn.gru.cell_update`, :func:`refimpl.nn.gru_fast.backward_factors`,
:func:`refimpl.nn.gru_fast.cell_backward_gates` (no checks; the public functions
here validate at their boundary with :func:`refimpl.models.qtg.check_params` and friends).

Shape legend: B batch, T transition frames, P pose size, Z latent size, H GRU hidden size, L GRU layers.
"""
from __future__ import annotations

from typing import Mapping, NamedTuple

import numpy as np

from refimpl.models.qtg import QTGConfig, check_context, check_length, check_params
from refimpl.nn.gru import cell_forward, cell_update, input_gates
from refimpl.nn.gru_fast import backward_factors, cell_backward_gates
from refimpl.nn.linear import matmul_wt
from refimpl.arrays import float_array

__all__ = ["rollout_forward", "rollout_backward"]


# ----------------------------------------------------------------------------------------------------------------
# the training path: time-major records of a rollout, per-step kernels (spec/qtg.md §3, §4)
# ----------------------------------------------------------------------------------------------------------------

class _Weights(NamedTuple):
    """The parameters a rollout reads, looked up once, and the few products of them its fused kernels use.

    The arrays of ``params`` are referenced (PyTorch layouts, no copies); ``z_stack``, ``k_bias`` and ``hv_stack``
    are formed once per rollout by contiguous row copies (no transposes; ≈ 0.5 MB at the default size). With
    ``W_ih = [W1 | W2 | W3]`` the column blocks of layer 0's input weight acting on the three parts of ``x_t``.
    """

    enc: tuple  # ((W (n_{i+1}, n_i), b (n_{i+1},)), ...): encoder layers, LeakyReLU after each
    gru: tuple  # ((W_ih (3H, I_k), W_hh (3H, H), b_ih (3H,), b_hh (3H,)), ...): one per GRU layer
    vel: tuple  # (W_v (Z, H), b_v (Z,)): velocity head, linear
    dec: tuple  # ((W (m_{j+1}, m_j), b), ...): decoder layers, LeakyReLU after each but the last
    slope: np.floating  # LeakyReLU negative slope, in the parameters' dtype
    z_stack: np.ndarray  # (2, 3H, Z): [W1 − W2 ; W1]: this step's (W1 − W2) z_t and the next step's W1 z_t
    k_bias: np.ndarray  # (3H,): b_ih + [b_hr, b_hz, 0] of layer 0
    hv_stack: np.ndarray  # (3H + Z, H): [W_hh ; W_v] of the top layer: the next step's W_hh s and this v_t


def _gather_weights(params: Mapping[str, np.ndarray], config: QTGConfig) -> _Weights:
    def dense(prefix, n):
        return tuple((params[f"{prefix}.{i}.weight"], params[f"{prefix}.{i}.bias"]) for i in range(n))

    gru = tuple(tuple(params[f"gru.{name}_l{k}"] for name in ("weight_ih", "weight_hh", "bias_ih", "bias_hh"))
                for k in range(config.gru_layers))
    slope = params["vel.weight"].dtype.type(config.negative_slope)
    Z, H = config.latent_size, config.gru_hidden
    w_ih, _, b_ih, b_hh = gru[0]
    w1, w2 = w_ih[:, :Z], w_ih[:, Z:2 * Z]  # (3H, Z) each
    z_stack = np.empty((2,) + w1.shape, dtype=w1.dtype)  # (2, 3H, Z)
    np.subtract(w1, w2, out=z_stack[0])
    z_stack[1] = w1
    k_bias = b_ih.copy()  # (3H,)
    k_bias[:2 * H] += b_hh[:2 * H]
    w_hh_top, w_v = gru[-1][1], params["vel.weight"]  # (3H, H), (Z, H)
    hv_stack = np.concatenate([w_hh_top, w_v], axis=0)  # (3H + Z, H)
    return _Weights(dense("enc", len(config.encoder_sizes)), gru, (w_v, params["vel.bias"]),
                    dense("dec", len(config.decoder_sizes) + 1), slope,
                    z_stack=z_stack, k_bias=k_bias, hv_stack=hv_stack)


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

    ``top[t] = s_t [W_hh ; W_v]ᵀ`` (``hv_stack``) of the top GRU layer's state ``s_t``: its first 3H columns,
    ``W_hh s_t``, become step t's gates (``gates[-1]`` is a view of them), its last Z columns, ``W_v s_t``, are
    step t − 1's velocity before its bias (``top[0] = 0`` since ``s_0 = 0``).
    """

    enc: list  # enc[i] (T + 3, B, n_i): input of encoder layer i (enc[0] has T + 4 blocks); enc[-1]: latents
    gru_x: np.ndarray  # (T, B, 3Z): x_t = [z_t − z_{t−1} | e1 − z_t | e2 − e1], filled after the loop
    hidden: np.ndarray  # (T + 1, L, B, H): s_t of every layer, s_0 = 0
    gates: list  # gates[k] (T, B, 3H): [r | u | W_hn s_t + b_hn] (refimpl.nn.gru.cell_update)
    cand: np.ndarray  # (L, T, B, H): the candidate state n
    dec: list  # dec[j] (T, B, m_j): input of decoder layer j; dec[0] = z_t + v_t
    top: np.ndarray  # (T + 1, B, 3H + Z): s_t hv_stackᵀ (top GRU layer)


def _new_record(B: int, T: int, config: QTGConfig, dtype) -> _Record:
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers
    hidden = np.empty((T + 1, L, B, H), dtype=dtype)  # (T + 1, L, B, H)
    hidden[0] = 0
    top = np.empty((T + 1, B, 3 * H + Z), dtype=dtype)  # (T + 1, B, 3H + Z)
    top[0] = 0
    return _Record(
        enc=[np.empty((T + (4 if i == 0 else 3), B, n), dtype=dtype)
             for i, n in enumerate((config.pose_size,) + config.encoder_sizes)],
        gru_x=np.empty((T, B, 3 * Z), dtype=dtype), hidden=hidden,
        gates=[np.empty((T, B, 3 * H), dtype=dtype) for _ in range(L - 1)] + [top[:T, :, :3 * H]],
        cand=np.empty((L, T, B, H), dtype=dtype),
        dec=[np.empty((T, B, m), dtype=dtype) for m in (Z,) + config.decoder_sizes], top=top)


def _dense(x, weight, bias, slope, out):
    """``out = x Wᵀ + b`` (x (N, I), out (N, O)), then LeakyReLU in place unless ``slope`` is None.

    ``max(a, slope a)`` equals ``a`` for ``a > 0`` and ``slope a`` otherwise, since ``0 <= slope < 1``."""
    matmul_wt(x, weight, out=out)
    out += bias
    if slope is not None:
        np.maximum(out, out * slope, out=out)
    return out


def _leaky_factor(y, slope):
    """``max([y > 0], slope)`` (shape of y): the LeakyReLU's derivative read from its output ``y`` (1 or slope)."""
    f = np.greater(y, 0).astype(y.dtype)
    return np.maximum(f, slope, out=f)


def _encode_context(w: _Weights, rec: _Record, past, target) -> None:
    """Blocks 0-3 of ``rec.enc[0]`` = ``g1, g2, p_{-1}, p_0``; one encoder pass over blocks 0-2 (3B rows)."""
    B = past.shape[0]
    rec.enc[0][0:2] = target.transpose(1, 0, 2)  # g1, g2
    rec.enc[0][2:4] = past.transpose(1, 0, 2)  # p_{-1}, p_0
    x = rec.enc[0][:3].reshape(3 * B, past.shape[2])  # (3B, P)
    for i, (weight, bias) in enumerate(w.enc):
        x = _dense(x, weight, bias, w.slope, rec.enc[i + 1][:3].reshape(3 * B, weight.shape[0]))


def _target_term(w: _Weights, e1, e2):
    """``k = W2 e1 + W3 (e2 − e1) + b_ih + [b_hr, b_hz, 0]`` (B, 3H): layer 0's input term constant over the
    transition, so that ``W_ih x_t + b_ih + [b_hr, b_hz, 0] = (W1 − W2) z_t + k − W1 z_{t−1}``."""
    Z = e1.shape[1]
    k = matmul_wt(np.concatenate([e1, e2 - e1], axis=1), w.gru[0][0][:, Z:])  # (B, 3H)
    k += w.k_bias
    return k


def _step_into(w: _Weights, rec: _Record, t: int, k, c, zz, gi_up) -> np.ndarray:
    """Step t of the rollout held in ``rec`` (spec/qtg.md §3, §4: fused form).

    Reads ``p_t``, ``s_t``, ``top[t]`` from ``rec``; ``k`` (B, 3H) is :func:`_target_term`, ``c`` (B, 3H) holds
    ``k − W1 z_{t−1}`` and is advanced to ``k − W1 z_t``; ``zz`` (B, 6H) and ``gi_up`` (B, 3H) are scratch. Writes
    every layer's output of the step into ``rec`` and returns ``p_{t+1}`` (B, P), a view of block ``4 + t`` of
    ``rec.enc[0]``. ``x_t`` itself is not formed (``rec.gru_x`` is filled after the loop, for ``dW_ih``).
    """
    x = rec.enc[0][3 + t]  # p_t (B, P)
    for i, (weight, bias) in enumerate(w.enc):
        x = _dense(x, weight, bias, w.slope, rec.enc[i + 1][3 + t])
    z = x  # z_t (B, Z)
    H3 = c.shape[1]
    matmul_wt(z, w.z_stack.reshape(2 * H3, -1), out=zz)  # [(W1 − W2) z_t | W1 z_t] (B, 6H)
    gi = np.add(zz[:, :H3], c, out=gi_up)  # W_ih x_t + b_ih + [b_hr, b_hz, 0]
    np.subtract(k, zz[:, H3:], out=c)  # c_{t+1}
    top = len(w.gru) - 1
    for layer, (w_ih, w_hh, b_ih, b_hh) in enumerate(w.gru):
        H = w_hh.shape[1]
        if layer:
            gi = input_gates(rec.hidden[t + 1, layer - 1], w_ih, b_ih, b_hh, H, out=gi_up)  # (B, 3H)
        if layer < top:
            cell_forward(gi, rec.hidden[t, layer], w_hh, None, b_hh[2 * H:], rec.gates[layer][t],
                          rec.cand[layer, t], rec.hidden[t + 1, layer])
        else:
            cell_update(gi, rec.hidden[t, layer], b_hh[2 * H:], rec.gates[layer][t], rec.cand[layer, t],
                         rec.hidden[t + 1, layer])
    matmul_wt(rec.hidden[t + 1, top], w.hv_stack, out=rec.top[t + 1])  # [W_hh s_{t+1} | W_v s_{t+1}]
    h = np.add(rec.top[t + 1, :, H3:], w.vel[1], out=rec.dec[0][t])  # v_t (B, Z)
    h += z  # z_t + v_t
    last = len(w.dec) - 1
    for j, (weight, bias) in enumerate(w.dec):
        h = _dense(h, weight, bias, None if j == last else w.slope,
                   rec.enc[0][4 + t] if j == last else rec.dec[j + 1][t])
    return h  # p_{t+1} (B, P)


def _fill_gru_x(rec: _Record) -> None:
    """``rec.gru_x[t] = [z_t − z_{t−1} | e1 − z_t | e2 − e1]`` for all steps at once (three calls)."""
    T, _, Z3 = rec.gru_x.shape
    Z = Z3 // 3
    lat = rec.enc[-1]  # (T + 3, B, Z): e1, e2, z_{-1}, z_0 …
    np.subtract(lat[3:T + 3], lat[2:T + 2], out=rec.gru_x[:, :, :Z])
    np.subtract(lat[0], lat[3:T + 3], out=rec.gru_x[:, :, Z:2 * Z])
    np.subtract(lat[1], lat[0], out=rec.gru_x[:, :, 2 * Z:])


class _Cotangents(NamedTuple):
    """Per-step cotangents of every layer's pre-activations, time-major; each pairs with a :class:`_Record` array
    for the weight gradients formed after the reverse loop."""

    enc: list  # enc[i] (T + 3, B, n_{i+1}): encoder layer i (blocks as in _Record); pairs with rec.enc[i]
    gru_in: np.ndarray  # (L, T, B, 3H): [da_r | da_u | da_n], pairs with the layer's input (x_t or s_{t+1} below)
    gru_hh: list  # gru_hh[k] (T, B, 3H): [da_r | da_u | r da_n], pairs with rec.hidden[:-1, k] (s_t)
    vel: np.ndarray  # (T, B, Z): cotangent of z_t + v_t (the velocity head's output); pairs with s_{t+1} (top)
    dec: list  # dec[j] (T, B, m_{j+1}): decoder layer j; the last one is the total cotangent of p_{t+1}
    top: np.ndarray  # (T + 1, B, 3H + Z): row t = [gru_hh[-1][t] | vel[t − 1]], multiplied by hv_stack at once


def _new_cotangents(B: int, T: int, config: QTGConfig, dtype) -> _Cotangents:
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers
    top = np.empty((T + 1, B, 3 * H + Z), dtype=dtype)
    top[T, :, :3 * H] = 0  # no step T: its recurrent cotangent is 0
    return _Cotangents(
        enc=[np.empty((T + 3, B, n), dtype=dtype) for n in config.encoder_sizes],
        gru_in=np.empty((L, T, B, 3 * H), dtype=dtype),
        gru_hh=[np.empty((T, B, 3 * H), dtype=dtype) for _ in range(L - 1)] + [top[:T, :, :3 * H]],
        vel=top[1:, :, 3 * H:],
        dec=[np.empty((T, B, m), dtype=dtype) for m in config.decoder_sizes + (config.pose_size,)], top=top)


class _Factors(NamedTuple):
    """Everything of the backward that does not depend on the incoming cotangents, formed for all steps at once
    before the reverse loop (a few whole-rollout calls instead of many per step)."""

    gru: list  # gru[k] (T, B, 3H): refimpl.nn.gru_fast.backward_factors of layer k
    enc: list  # enc[i] (T + 3, B, n_{i+1}): LeakyReLU derivative of encoder layer i (1 or slope)
    dec: list  # dec[j] (T, B, m_{j+1}), j < last: LeakyReLU derivative of decoder layer j


def _factors(w: _Weights, rec: _Record) -> _Factors:
    return _Factors(
        gru=[backward_factors(rec.hidden[:-1, k], rec.gates[k], rec.cand[k]) for k in range(len(w.gru))],
        enc=[_leaky_factor(rec.enc[i + 1], w.slope) for i in range(len(w.enc))],
        dec=[_leaky_factor(rec.dec[j + 1], w.slope) for j in range(len(w.dec) - 1)])


def _step_backward(w: _Weights, rec: _Record, cot: _Cotangents, fac: _Factors, t: int, dhidden, dz_next, bufs,
                   need_dpose: bool):
    """Backward of step t (spec/qtg.md §4): only the sequential input and state cotangents, no weight gradients.

    On entry ``cot.dec[-1][t]`` holds the total cotangent of ``p_{t+1}``; ``dhidden`` (L, B, H) holds, per layer,
    the part of the cotangent of ``s_{t+1}`` that step t + 1 formed without a product (``ds z`` of the top layer;
    everything for the lower layers); ``cot.top[t + 1]``'s first 3H columns hold step t + 1's ``gru_hh`` (0 at
    t = T − 1); ``dz_next`` (B, Z) or None is ``−W1ᵀ`` applied to step t + 1's layer-0 gate cotangents (the
    cotangent of ``z_t`` through ``x_{t+1}``). Writes the step's pre-activation cotangents into ``cot`` (``vel[t]``
    into ``top[t + 1]``), leaves in ``dhidden`` the same parts for ``s_t`` and returns
    ``(dz_prev (B, Z), dp_t (B, P) or None unless need_dpose)`` with ``dz_prev`` the (negated) ``W1`` part.
    """
    last = len(w.dec) - 1
    dy = cot.dec[last][t]  # (B, P)
    for j in range(last, -1, -1):
        if j < last:
            dy = np.multiply(dy, fac.dec[j][t], out=cot.dec[j][t])
        dy = np.matmul(dy, w.dec[j][0], out=cot.vel[t] if j == 0 else bufs["dec"][j])  # (B, m_j)
    dzv = dy  # (B, Z): d(z_t + v_t) = dv_t
    top = len(w.gru) - 1
    for k in range(top, -1, -1):
        w_ih, w_hh = w.gru[k][:2]
        dh = dhidden[k]  # (B, H)
        tmp = bufs["h"]
        if k == top:  # W_hhᵀ (step t + 1's recurrent cotangent) and W_vᵀ dv_t in one product
            np.matmul(cot.top[t + 1], w.hv_stack, out=tmp)
        else:
            np.matmul(cot.gru_in[k + 1, t], w.gru[k + 1][0], out=tmp)  # from layer k + 1's input
        dh += tmp  # total cotangent of s_{t+1} (layer k)
        g = rec.gates[k][t]
        H = w_hh.shape[1]
        cell_backward_gates(dh, fac.gru[k][t], g[:, :H], cot.gru_in[k, t], cot.gru_hh[k][t])
        dh *= g[:, H:2 * H]  # the part of ds_t without a product
        if k < top:  # lower layers: add their recurrent product now
            np.matmul(cot.gru_hh[k][t], w_hh, out=tmp)
            dh += tmp
    dx = np.matmul(cot.gru_in[0, t], w.z_stack, out=bufs["dx"][t % 2])  # (2, B, Z): da (W1 − W2), da W1
    dz = np.add(dzv, dx[0], out=bufs["dz"])  # dz_t = d(z_t + v_t) + (W1 − W2)ᵀ da_t − W1ᵀ da_{t+1}
    if dz_next is not None:
        dz -= dz_next
    dy = dz
    for i in range(len(w.enc) - 1, -1, -1):
        da = np.multiply(dy, fac.enc[i][3 + t], out=cot.enc[i][3 + t])  # (B, n_{i+1})
        dy = np.matmul(da, w.enc[i][0], out=bufs["enc"][i]) if i > 0 or need_dpose else None  # (B, n_i)
    return dx[1], dy


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
    dtype = check_params(params, config)
    past, target = check_context(past, target, config, dtype)
    T = check_length(T, config)
    B = past.shape[0]
    w = _gather_weights(params, config)
    rec = _new_record(B, T, config, past.dtype)
    _encode_context(w, rec, past, target)
    latents = rec.enc[-1]  # (T + 3, B, Z): e1, e2, z_{-1}, …
    H3 = 3 * config.gru_hidden
    k = _target_term(w, latents[0], latents[1])  # (B, 3H)
    c = k - matmul_wt(latents[2], w.z_stack[1])  # (B, 3H): k − W1 z_{-1}
    zz = np.empty((B, 2 * H3), dtype=dtype)
    gi = np.empty((B, H3), dtype=dtype)
    for t in range(T):
        _step_into(w, rec, t, k, c, zz, gi)
    _fill_gru_x(rec)
    poses = np.ascontiguousarray(rec.enc[0][4:].transpose(1, 0, 2))  # (B, T, P), not a view of the cache
    return poses, {"weights": w, "record": rec, "config": config, "shape": (B, T, config.pose_size)}


def rollout_backward(dposes, cache, *, input_grads: bool = False):
    """Backpropagation through the whole rollout (BPTT through all steps; spec/qtg.md §4).

    Before the reverse loop, every factor that does not depend on the incoming cotangents (the GRU's gate factors,
    the LeakyReLU derivatives) is formed for all steps at once; the loop over the steps then propagates only the
    input and state cotangents (they are sequential) with preallocated buffers and keeps every layer's
    pre-activation cotangents; after the loop, each weight gradient is ONE matrix product over the stacked rows of
    all steps (for the encoder, also the context rows), each bias gradient one sum.

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
    dposes = float_array(dposes, "dposes", shape, cast=False)
    if dposes.dtype != dtype:
        raise ValueError(f"dposes: expected dtype {dtype} (the parameters' dtype), got {dposes.dtype}")
    B, T, P = shape
    Z, H, L = config.latent_size, config.gru_hidden, config.gru_layers
    cot = _new_cotangents(B, T, config, dtype)
    fac = _factors(w, rec)
    dhidden = np.zeros((L, B, H), dtype=dtype)  # the product-free part of the cotangent of s_{t+1}, then s_t
    bufs = {"h": np.empty((B, H), dtype=dtype), "dx": np.empty((2, 2, B, Z), dtype=dtype),  # alternate: step t reads step t + 1's
            "dz": np.empty((B, Z), dtype=dtype),
            "dec": [np.empty((B, m), dtype=dtype) for m in (Z,) + config.decoder_sizes],
            "enc": [np.empty((B, n), dtype=dtype) for n in (P,) + config.encoder_sizes[:-1]]}
    dz_next = None  # W1ᵀ da_{t+1}: the cotangent of z_t through x_{t+1}, negated
    dpose = None  # cotangent of p_{t+1} from its use as step t+1's input pose
    for t in range(T - 1, -1, -1):
        dp = cot.dec[-1][t]  # (B, P): total cotangent of p_{t+1}
        if dpose is None:
            dp[...] = dposes[:, t]
        else:
            np.add(dposes[:, t], dpose, out=dp)
        dz_next, dpose = _step_backward(w, rec, cot, fac, t, dhidden, dz_next, bufs,
                                        need_dpose=t > 0 or input_grads)
    dlatent = -dz_next  # (B, Z): cotangent of z_{-1} (through x_0)
    # the context latents e1, e2 (used by every x_t) and z_{-1} (step 0), back through the initial encoder pass
    dx = cot.gru_in[0].sum(axis=0) @ w.gru[0][0]  # (B, 3Z): Σ_t dx_t = (Σ_t [da_r | da_u | da_n]_t) W_ih
    dy = np.concatenate([dx[:, Z:2 * Z] - dx[:, 2 * Z:], dx[:, 2 * Z:], dlatent])  # (3B, Z): de1, de2, dz_{-1}
    for i in range(len(w.enc) - 1, -1, -1):
        n = w.enc[i][0].shape[0]
        da = np.multiply(dy, fac.enc[i][:3].reshape(3 * B, n), out=cot.enc[i][:3].reshape(3 * B, n))
        dy = da @ w.enc[i][0] if i > 0 or input_grads else None  # (3B, n_i)
    grads = _weight_grads(w, rec, cot)
    if not input_grads:
        return grads
    dctx = dy.reshape(3, B, P)  # g1, g2, p_{-1}
    dpast = np.stack([dctx[2], dpose], axis=1)  # (B, 2, P)
    return grads, dpast, np.ascontiguousarray(dctx[:2].transpose(1, 0, 2))
