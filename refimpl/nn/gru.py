"""Multi-layer (optionally bidirectional) GRU with PyTorch's equations, names and layouts (spec/layers.md §4).

Equations (PyTorch ``nn.GRU``; gate blocks in the order r, z, n)::

    r_t = sigmoid(W_ir x_t + b_ir + W_hr h_{t-1} + b_hr)
    z_t = sigmoid(W_iz x_t + b_iz + W_hz h_{t-1} + b_hz)
    n_t = tanh(W_in x_t + b_in + r_t * (W_hn h_{t-1} + b_hn))
    h_t = (1 - z_t) * n_t + z_t * h_{t-1}

Parameters (``k`` = layer, ``_reverse`` suffix for the backward direction of a bidirectional GRU)::

    {prefix}.weight_ih_l{k}  (3H, I_k)   rows [W_ir | W_iz | W_in]; I_0 = I, I_k = D*H for k > 0
    {prefix}.weight_hh_l{k}  (3H, H)     rows [W_hr | W_hz | W_hn]
    {prefix}.bias_ih_l{k}    (3H,)       [b_ir | b_iz | b_in]
    {prefix}.bias_hh_l{k}    (3H,)       [b_hr | b_hz | b_hn]

Shapes: B batch, T time, I input size, H hidden size, L layers, D directions (1 or 2).
``x (B, T, I)`` batch-first; ``h0, h_n (L*D, B, H)`` as PyTorch (row ``k*D + d``); ``y (B, T, D*H)`` the top
layer's outputs, forward direction first.

Implementation (spec/layers.md §4.3): a teacher-forced sequence is processed
layer by layer; the input projections of all time steps of a layer are ONE GEMM ``(T*B, I) @ W_ih^T``; the
per-step recurrent product uses a weight transposed once per call; back-propagation through time stores the
per-step pre-activation gradients and forms ``dW_hh``, ``dW_ih`` and ``dx`` with one GEMM each after the loop.
The step kernels ``cell_forward`` (and its element-wise part ``cell_update``, for a caller that formed
``W_hh h`` itself), ``input_gates`` and ``cell_backward`` form the kernel tier QTG's fused rollout builds on; the
factored reverse step it also uses lives in :mod:`refimpl.nn.gru_fast`.
Internally arrays are time-major ``(T, B, ...)`` so that each step reads contiguous rows.
The per-step, per-gate loop versions ``gru_forward_naive`` / ``gru_backward_naive`` (:mod:`refimpl.nn.gru_naive`)
are the test oracles.

Checks (spec/layers.md §4.5), once per public call, never inside the step loops: the sizes I and H are read
from layer 0's parameters first, then ``x`` / ``x_t`` (dtype, shape ``(.., I)``, finite) and ``h0`` / ``h``
(dtype, shape ``(L*D, B, H)``, finite) are checked against them, so a wrong input size is reported on the input,
with the expected and the actual shape; then every parameter's shape and dtype (not its values: that would cost
a pass over all weights per step). The backwards check their cotangents ``dy``, ``dh_n`` / ``dh_new`` (dtype,
shape, finite).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.nn.activations import sigmoid
from refimpl.nn.linear import matmul_wt
from refimpl.arrays import float_array
from refimpl.nn.params import check_same_dtype, fan_in_bound, get_param, init_uniform, param_name

__all__ = ["gru_forward", "gru_backward", "gru_step_forward", "gru_step_backward", "gru_init"]


# ----------------------------------------------------------------------------------------------------------
# parameters


def layer_suffix(layer: int, direction: int) -> str:
    """The parameter-name suffix of a layer and direction: ``l{layer}``, ``_reverse`` appended for direction 1."""
    return f"l{layer}" + ("_reverse" if direction else "")


def _all_weights(params, prefix, num_layers, directions):
    """Every layer's and direction's ``(W_ih (3H, I_k), W_hh (3H, H), b_ih (3H,), b_hh (3H,))``, checked.

    The sizes are read from layer 0 (``H`` from ``weight_hh_l0`` ``(3H, H)``, ``I`` from ``weight_ih_l0``
    ``(3H, I)``) BEFORE the inputs are checked, so that a wrong ``x`` / ``h0`` is reported on the input, not as a
    wrong parameter shape. Every parameter must have ``weight_hh_l0``'s dtype (float32 or float64); the values are
    not checked. Returns ``(weights, I, H)`` with ``weights[k][d]`` the tuple of layer ``k``, direction ``d``.
    """
    w_hh0 = get_param(params, prefix, "weight_hh_l0", (None, None))  # (3H, H)
    hid, dt = w_hh0.shape[1], w_hh0.dtype
    if w_hh0.shape[0] != 3 * hid:
        raise ValueError(f"params[{param_name(prefix, 'weight_hh_l0')!r}]: expected shape (3H, H) = "
                         f"({3 * hid}, {hid}), got {w_hh0.shape}")
    w_ih0 = get_param(params, prefix, "weight_ih_l0", (3 * hid, None), dt)  # (3H, I)
    in_size = w_ih0.shape[1]
    weights = []
    for k in range(num_layers):
        in_k = in_size if k == 0 else directions * hid
        dirs = []
        for d in range(directions):
            sfx = layer_suffix(k, d)
            first = k == 0 and d == 0
            dirs.append((w_ih0 if first else get_param(params, prefix, f"weight_ih_{sfx}", (3 * hid, in_k), dt),
                         w_hh0 if first else get_param(params, prefix, f"weight_hh_{sfx}", (3 * hid, hid), dt),
                         get_param(params, prefix, f"bias_ih_{sfx}", (3 * hid,), dt),
                         get_param(params, prefix, f"bias_hh_{sfx}", (3 * hid,), dt)))
        weights.append(dirs)
    return weights, in_size, hid


def _size_note(prefix: str, letter: str, size: int, name: str) -> str:
    """Where an expected size comes from, for an input's shape error: ``"I = 4 from params['rnn.weight_ih_l0']"``."""
    return f"{letter} = {size} from params[{param_name(prefix, name)!r}]"


def _check_params_dtype(x: np.ndarray, x_name: str, weights, prefix: str) -> None:
    """The parameters (all of ``weight_hh_l0``'s dtype, see :func:`_all_weights`) must have the input's dtype."""
    dt = weights[0][0][1].dtype
    if dt != x.dtype:
        raise ValueError(f"params[{param_name(prefix, 'weight_hh_l0')!r}]: expected dtype {x.dtype} (the dtype of "
                         f"{x_name}), got {dt}")


def _check_layers(num_layers: int) -> None:
    if not (isinstance(num_layers, (int, np.integer)) and num_layers >= 1):
        raise ValueError(f"num_layers: expected an integer >= 1, got {num_layers!r}")


def gru_init(rng: np.random.Generator, input_size: int, hidden_size: int, num_layers: int, prefix: str,
             bidirectional: bool = False, dtype=np.float64) -> dict[str, np.ndarray]:
    """PyTorch-default initialisation of ``nn.GRU``: every parameter ``~ U(-1/sqrt(H), 1/sqrt(H))``.

    Returns
    -------
    dict
        ``{prefix}.weight_ih_l{k}[_reverse]`` ``(3H, I_k)``, ``weight_hh`` ``(3H, H)``, ``bias_ih``/``bias_hh``
        ``(3H,)`` for ``k < num_layers`` (and both directions when ``bidirectional``).
    """
    _check_layers(num_layers)
    bound = fan_in_bound(hidden_size)
    d_count = 2 if bidirectional else 1
    out = {}
    for k in range(num_layers):
        in_k = input_size if k == 0 else d_count * hidden_size
        for d in range(d_count):
            sfx = layer_suffix(k, d)
            for name, shape in ((f"weight_ih_{sfx}", (3 * hidden_size, in_k)),
                                (f"weight_hh_{sfx}", (3 * hidden_size, hidden_size)),
                                (f"bias_ih_{sfx}", (3 * hidden_size,)),
                                (f"bias_hh_{sfx}", (3 * hidden_size,))):
                out[param_name(prefix, name)] = init_uniform(rng, shape, bound, dtype)
    return out


# ----------------------------------------------------------------------------------------------------------
# one cell step (internal kernels, no checks; all outputs written into preallocated arrays)


def cell_forward(gi, h, w_hh, whh_t, b_hn, g, n, h_new):
    """One GRU step.

    gi (B, 3H): ``W_ih x + b_ih`` with ``b_hr, b_hz`` already added to the r, z blocks.
    h (B, H): previous state. ``whh_t`` (H, 3H) C-contiguous ``W_hh^T`` or None (then ``w_hh`` is used via
    :func:`~refimpl.nn.linear.matmul_wt`). Writes g (B, 3H) = [r | z | W_hn h + b_hn], n (B, H), h_new (B, H).
    """
    if whh_t is not None:
        np.matmul(h, whh_t, out=g)  # (B, 3H)
    else:
        matmul_wt(h, w_hh, out=g)  # (B, 3H)
    cell_update(gi, h, b_hn, g, n, h_new)


def cell_update(gi, h, b_hn, g, n, h_new):
    """The element-wise part of :func:`cell_forward`, for a caller that formed ``g = W_hh h`` (B, 3H) itself
    (e.g. in one product with another weight); ``g`` may be a strided view. Overwrites g with
    [r | z | W_hn h + b_hn] and writes n (B, H), h_new (B, H)."""
    hid = h.shape[1]
    rz = g[:, :2 * hid]  # (B, 2H)
    rz += gi[:, :2 * hid]
    sigmoid(rz, out=rz)
    ghn = g[:, 2 * hid:]  # (B, H)
    ghn += b_hn
    np.multiply(g[:, :hid], ghn, out=n)  # r * (W_hn h + b_hn)
    n += gi[:, 2 * hid:]
    np.tanh(n, out=n)
    np.subtract(h, n, out=h_new)  # h' = n + z * (h - n)
    h_new *= g[:, hid:2 * hid]
    h_new += n


def cell_backward(dh, h, g, n, w_hh, dgi, dgh, tmp):
    """Back-propagate one GRU step.

    dh (B, H): total cotangent of h' on entry, overwritten with the cotangent of the previous state h.
    Writes dgi (B, 3H): cotangents of the input-side pre-activations [a_r | a_z | a_n]
    (a_n = W_in x + b_in + r * (W_hn h + b_hn)), and dgh (B, 3H): those of the recurrent products
    [a_r | a_z | r * a_n]. tmp (B, H) is scratch.
    """
    hid = h.shape[1]
    r, z, ghn = g[:, :hid], g[:, hid:2 * hid], g[:, 2 * hid:]
    dar, daz, dan = dgi[:, :hid], dgi[:, hid:2 * hid], dgi[:, 2 * hid:]
    np.subtract(1, z, out=tmp)  # 1 - z
    np.multiply(n, n, out=dan)  # dL/da_n = dh (1 - z) (1 - n^2)
    np.subtract(1, dan, out=dan)
    dan *= tmp
    dan *= dh
    np.subtract(h, n, out=daz)  # dL/da_z = dh (h - n) z (1 - z)
    daz *= dh
    daz *= z
    daz *= tmp
    np.subtract(1, r, out=dar)  # dL/da_r = dL/da_n (W_hn h + b_hn) r (1 - r)
    dar *= r
    dar *= ghn
    dar *= dan
    dgh[:, :2 * hid] = dgi[:, :2 * hid]
    np.multiply(dan, r, out=dgh[:, 2 * hid:])
    dh *= z  # dL/dh = dh z + dgh W_hh
    np.matmul(dgh, w_hh, out=tmp)
    dh += tmp


def input_gates(x2, w_ih, b_ih, b_hh, hid, out=None):
    """``x W_ih^T + b_ih``, with ``b_hr, b_hz`` folded into the r, z blocks: (N, 3H)."""
    gi = matmul_wt(x2, w_ih, out=out)  # (N, 3H)
    gi += b_ih
    gi[:, :2 * hid] += b_hh[:2 * hid]
    return gi


# ----------------------------------------------------------------------------------------------------------
# one layer, one direction, whole sequence (time-major)


def _direction_forward(xs, h0, w_ih, w_hh, b_ih, b_hh, reverse):
    """Run one direction of one layer over xs (T, B, I). Returns hs (T+1, B, H) in processing order
    (hs[0] = h0), g (T, B, 3H) and n (T, B, H) per processing step."""
    t_len, batch, in_size = xs.shape
    hid = w_hh.shape[1]
    gi = input_gates(xs.reshape(t_len * batch, in_size), w_ih, b_ih, b_hh, hid).reshape(t_len, batch, 3 * hid)
    whh_t = np.ascontiguousarray(w_hh.T)  # (H, 3H), transposed once per call
    b_hn = b_hh[2 * hid:]
    hs = np.empty((t_len + 1, batch, hid), dtype=xs.dtype)  # (T+1, B, H)
    hs[0] = h0
    g = np.empty((t_len, batch, 3 * hid), dtype=xs.dtype)  # (T, B, 3H)
    n = np.empty((t_len, batch, hid), dtype=xs.dtype)  # (T, B, H)
    for s in range(t_len):
        t = t_len - 1 - s if reverse else s
        cell_forward(gi[t], hs[s], w_hh, whh_t, b_hn, g[s], n[s], hs[s + 1])
    return hs, g, n


def _direction_backward(dys, dh_last, xs, hs, g, n, w_ih, w_hh, reverse):
    """BPTT through one direction of one layer.

    dys (T, B, H): cotangents of this direction's outputs in natural time order (may be a strided view);
    dh_last (B, H) or None: cotangent of its final state. Returns dxs (T, B, I), dh0 (B, H),
    dW_ih, dW_hh, db_ih, db_hh.
    """
    t_len, batch, in_size = xs.shape
    hid = w_hh.shape[1]
    dgi = np.empty((t_len, batch, 3 * hid), dtype=xs.dtype)  # natural time order
    dgh = np.empty((t_len, batch, 3 * hid), dtype=xs.dtype)  # processing order (pairs with hs[:-1])
    dh = np.zeros((batch, hid), dtype=xs.dtype) if dh_last is None else np.array(dh_last, dtype=xs.dtype)
    tmp = np.empty((batch, hid), dtype=xs.dtype)
    for s in range(t_len - 1, -1, -1):
        t = t_len - 1 - s if reverse else s
        dh += dys[t]
        cell_backward(dh, hs[s], g[s], n[s], w_hh, dgi[t], dgh[s], tmp)
    dgi2 = dgi.reshape(t_len * batch, 3 * hid)  # (T*B, 3H)
    dgh2 = dgh.reshape(t_len * batch, 3 * hid)
    dw_hh = dgh2.T @ hs[:-1].reshape(t_len * batch, hid)  # (3H, H), one GEMM over all steps
    dw_ih = dgi2.T @ xs.reshape(t_len * batch, in_size)  # (3H, I)
    dxs = (dgi2 @ w_ih).reshape(t_len, batch, in_size)  # (T, B, I)
    return dxs, dh, dw_ih, dw_hh, dgi2.sum(axis=0), dgh2.sum(axis=0)


# ----------------------------------------------------------------------------------------------------------
# public: sequence


def gru_forward(x: np.ndarray, h0: np.ndarray, params: Mapping[str, np.ndarray], prefix: str,
                num_layers: int = 1, bidirectional: bool = False):
    """Run a multi-layer GRU over a batch of sequences (PyTorch ``nn.GRU(..., batch_first=True)``).

    Parameters
    ----------
    x : ndarray (B, T, I), float32 or float64, T >= 1
    h0 : ndarray (L*D, B, H), same dtype
        Initial states; row ``k*D + d`` is layer ``k``, direction ``d`` (0 forward, 1 reverse).
    params : dict
        ``{prefix}.weight_ih_l{k}[_reverse]`` etc., see the module docstring; same dtype as ``x``.
    prefix : str
    num_layers : int
    bidirectional : bool

    Returns
    -------
    y : ndarray (B, T, D*H)
        Top-layer outputs, forward direction in ``[..., :H]``, reverse in ``[..., H:]``.
    h_n : ndarray (L*D, B, H)
        Final states (for the reverse direction: its state after reading ``x[:, 0]``).
    cache : dict
        For :func:`gru_backward`.

    Raises
    ------
    ValueError
        Naming ``x`` or ``h0`` (expected and actual shape, dtype, NaN/inf; I and H are those of the parameters),
        ``num_layers``, or the full name of a missing or mis-shaped parameter.
    """
    _check_layers(num_layers)
    d_count = 2 if bidirectional else 1
    weights, in_size, hid = _all_weights(params, prefix, num_layers, d_count)
    x = float_array(x, "x", (None, None, in_size), context=_size_note(prefix, "I", in_size, "weight_ih_l0"), cast=False)
    batch, t_len, _ = x.shape
    if t_len < 1:
        raise ValueError(f"x: expected at least one time step (B, T >= 1, I), got {x.shape}")
    h_note = _size_note(prefix, "H", hid, "weight_hh_l0")
    h0 = float_array(h0, "h0", (num_layers * d_count, batch, hid),
                     context=f"L*D = {num_layers * d_count}, B = {batch} from x, {h_note}", cast=False)
    check_same_dtype(x, "x", {"h0": h0})
    _check_params_dtype(x, "x", weights, prefix)

    xs = np.array(x.transpose(1, 0, 2), order="C")  # (T, B, I), always a copy (the cache must not alias x)
    h_n = np.empty((num_layers * d_count, batch, hid), dtype=x.dtype)
    layers = []
    for k in range(num_layers):
        dirs = []
        for d in range(d_count):
            hs, g, n = _direction_forward(xs, h0[k * d_count + d], *weights[k][d], reverse=d == 1)
            dirs.append((hs, g, n))
            h_n[k * d_count + d] = hs[-1]
        layers.append((xs, dirs))
        if d_count == 1:
            xs = dirs[0][0][1:]  # (T, B, H), a contiguous view of hs
        else:
            xs = np.concatenate([dirs[0][0][1:], dirs[1][0][:0:-1]], axis=-1)  # (T, B, 2H), reverse re-ordered
    y = np.array(xs.transpose(1, 0, 2), order="C")  # (B, T, D*H), a copy (the cache must not alias y)
    cache = dict(layers=layers, weights=weights, prefix=prefix, num_layers=num_layers, directions=d_count,
                 shape=(batch, t_len, in_size, hid))
    return y, h_n, cache


def gru_backward(dy: np.ndarray | None, dh_n: np.ndarray | None, cache):
    """Back-propagation through time for :func:`gru_forward`.

    Parameters
    ----------
    dy : ndarray (B, T, D*H) or None
        Cotangent of ``y`` (None: zero); float32 or float64, finite.
    dh_n : ndarray (L*D, B, H) or None
        Cotangent of ``h_n`` (None: zero); float32 or float64, finite.
    cache : dict
        From :func:`gru_forward`.

    Returns
    -------
    dx : ndarray (B, T, I)
    dh0 : ndarray (L*D, B, H)
        Gradient into the initial states (sum it over B for a learned ``(L, 1, H)`` initial state).
    grads : dict
        Full parameter names -> gradients, same shapes as the parameters.

    Notes
    -----
    Per step (spec/layers.md §4.2), with ``dh`` the total cotangent of ``h_t``::

        da_n = dh (1 - z) (1 - n^2)         da_z = dh (h_{t-1} - n) z (1 - z)
        da_r = da_n (W_hn h_{t-1} + b_hn) r (1 - r)
        dh_{t-1} = dh z + [da_r | da_z | r da_n] W_hh
        dW_ih += [da_r | da_z | da_n]^T x_t     dW_hh += [da_r | da_z | r da_n]^T h_{t-1}
    """
    layers, weights, prefix = cache["layers"], cache["weights"], cache["prefix"]
    num_layers, d_count = cache["num_layers"], cache["directions"]
    batch, t_len, in_size, hid = cache["shape"]
    dtype = layers[0][0].dtype
    if dy is None:
        dys = np.zeros((t_len, batch, d_count * hid), dtype=dtype)
    else:
        dy = float_array(dy, "dy", (batch, t_len, d_count * hid), cast=False)
        dys = dy.transpose(1, 0, 2)  # (T, B, D*H) view
    if dh_n is not None:
        dh_n = float_array(dh_n, "dh_n", (num_layers * d_count, batch, hid), cast=False)
    dh0 = np.empty((num_layers * d_count, batch, hid), dtype=dtype)
    grads = {}
    for k in range(num_layers - 1, -1, -1):
        xs, dirs = layers[k]
        dxs = None
        for d in range(d_count):
            hs, g, n = dirs[d]
            w_ih, w_hh, _, _ = weights[k][d]
            row = k * d_count + d
            dxs_d, dh0[row], dw_ih, dw_hh, db_ih, db_hh = _direction_backward(
                dys[:, :, d * hid:(d + 1) * hid], None if dh_n is None else dh_n[row],
                xs, hs, g, n, w_ih, w_hh, reverse=d == 1)
            dxs = dxs_d if dxs is None else dxs + dxs_d
            sfx = layer_suffix(k, d)
            grads[param_name(prefix, f"weight_ih_{sfx}")] = dw_ih
            grads[param_name(prefix, f"weight_hh_{sfx}")] = dw_hh
            grads[param_name(prefix, f"bias_ih_{sfx}")] = db_ih
            grads[param_name(prefix, f"bias_hh_{sfx}")] = db_hh
        dys = dxs  # (T, B, I_k): cotangent of the layer below's outputs
    dx = np.ascontiguousarray(dys.transpose(1, 0, 2))  # (B, T, I)
    return dx, dh0, grads


# ----------------------------------------------------------------------------------------------------------
# public: single step (for autoregressive use)


def gru_step_forward(x_t: np.ndarray, h: np.ndarray, params: Mapping[str, np.ndarray], prefix: str,
                     num_layers: int = 1):
    """One time step of a unidirectional multi-layer GRU (all layers), for output-feedback loops.

    Parameters
    ----------
    x_t : ndarray (B, I), float32 or float64
    h : ndarray (L, B, H), same dtype
        States after the previous step.
    params : dict
        As for :func:`gru_forward` (no ``_reverse`` entries are read).
    prefix : str
    num_layers : int

    Returns
    -------
    y : ndarray (B, H)
        The top layer's new state (a copy, equal to ``h_new[-1]``).
    h_new : ndarray (L, B, H)
    cache : dict
        For :func:`gru_step_backward`.

    Raises
    ------
    ValueError
        Naming ``x_t`` or ``h`` (expected and actual shape, dtype, NaN/inf; I and H are those of the parameters),
        ``num_layers``, or the full name of a missing or mis-shaped parameter. The weights' values are not
        checked (this is called once per step of a rollout).

    Notes
    -----
    ``gru_step_forward`` repeated over t gives exactly the outputs of :func:`gru_forward` on the whole sequence.
    """
    _check_layers(num_layers)
    weights, in_size, hid = _all_weights(params, prefix, num_layers, 1)
    x_t = float_array(x_t, "x_t", (None, in_size), context=_size_note(prefix, "I", in_size, "weight_ih_l0"), cast=False)
    batch = x_t.shape[0]
    h_note = _size_note(prefix, "H", hid, "weight_hh_l0")
    h = float_array(h, "h", (num_layers, batch, hid), context=f"L = {num_layers}, B = {batch} from x_t, {h_note}",
                    cast=False)
    check_same_dtype(x_t, "x_t", {"h": h})
    _check_params_dtype(x_t, "x_t", weights, prefix)
    x_t, h = x_t.copy(), h.copy()  # the cache must not alias the caller's (possibly reused) buffers
    h_new = np.empty_like(h)  # (L, B, H)
    layers = []
    inp = x_t
    for k in range(num_layers):
        w_ih, w_hh, b_ih, b_hh = weights[k][0]
        gi = input_gates(inp, w_ih, b_ih, b_hh, hid)  # (B, 3H)
        g = np.empty((batch, 3 * hid), dtype=x_t.dtype)
        n = np.empty((batch, hid), dtype=x_t.dtype)
        cell_forward(gi, h[k], w_hh, None, b_hh[2 * hid:], g, n, h_new[k])
        layers.append((inp, h[k], g, n))
        inp = h_new[k]
    cache = dict(layers=layers, weights=weights, prefix=prefix, num_layers=num_layers, shape=(batch, in_size, hid))
    return h_new[-1].copy(), h_new, cache


def gru_step_backward(dy: np.ndarray | None, dh_new: np.ndarray | None, cache, accumulate_into=None):
    """Back-propagate one :func:`gru_step_forward`.

    Parameters
    ----------
    dy : ndarray (B, H) or None
        Cotangent of ``y`` (None: zero); float32 or float64, finite.
    dh_new : ndarray (L, B, H) or None
        Cotangent of ``h_new`` (None: zero), i.e. the ``dh`` returned by the backward of the NEXT step; float32 or
        float64, finite.
    cache : dict
        From :func:`gru_step_forward`.
    accumulate_into : dict, optional
        A gradient dict (full names -> arrays of the parameters' shapes, e.g. the one returned by the backward
        of the following step) to ADD this step's gradients into, in place; it is then returned as ``grads``.
        Lets a reverse loop over a rollout accumulate without allocating a new dict per step.

    Returns
    -------
    dx_t : ndarray (B, I)
    dh : ndarray (L, B, H)
        Cotangent of the previous states ``h``.
    grads : dict
        Full parameter names -> gradients of this step (plus ``accumulate_into`` when given).
    """
    layers, weights, prefix = cache["layers"], cache["weights"], cache["prefix"]
    num_layers = cache["num_layers"]
    batch, in_size, hid = cache["shape"]
    dtype = layers[0][2].dtype
    if dy is not None:
        dy = float_array(dy, "dy", (batch, hid), cast=False)
    if dh_new is not None:
        dh_new = float_array(dh_new, "dh_new", (num_layers, batch, hid), cast=False)
    grads = {} if accumulate_into is None else accumulate_into
    dh_prev = np.empty((num_layers, batch, hid), dtype=dtype)
    tmp = np.empty((batch, hid), dtype=dtype)
    d_out = dy  # cotangent flowing into the current layer's output from above
    for k in range(num_layers - 1, -1, -1):
        inp, h, g, n = layers[k]
        w_ih, w_hh, _, _ = weights[k][0]
        dh = dh_prev[k]
        if dh_new is None:
            dh[...] = 0
        else:
            dh[...] = dh_new[k]
        if d_out is not None:
            dh += d_out
        dgi = np.empty((batch, 3 * hid), dtype=dtype)
        dgh = np.empty((batch, 3 * hid), dtype=dtype)
        cell_backward(dh, h, g, n, w_hh, dgi, dgh, tmp)
        sfx = layer_suffix(k, 0)
        for name, value in ((f"weight_ih_{sfx}", dgi.T @ inp), (f"weight_hh_{sfx}", dgh.T @ h),
                            (f"bias_ih_{sfx}", dgi.sum(axis=0)), (f"bias_hh_{sfx}", dgh.sum(axis=0))):
            full = param_name(prefix, name)
            if full in grads:
                grads[full] += value
            else:
                grads[full] = value
        d_out = dgi @ w_ih  # (B, I_k)
    return d_out, dh_prev, grads


# Kernel tier (spec/architecture.md; unchecked, not in __all__, imported by other modules under these names):
# cell_forward, cell_update, cell_backward, input_gates, layer_suffix.
