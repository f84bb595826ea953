"""Multi-layer LSTM with PyTorch's equations, names and layouts, plus acRNN's skewed stacking (spec/layers.md §5).

Equations (PyTorch ``nn.LSTM``; gate blocks in the order i, f, g, o)::

    i_t = sigmoid(W_ii x_t + b_ii + W_hi h_{t-1} + b_hi)
    f_t = sigmoid(W_if x_t + b_if + W_hf h_{t-1} + b_hf)
    g_t = tanh   (W_ig x_t + b_ig + W_hg h_{t-1} + b_hg)
    o_t = sigmoid(W_io x_t + b_io + W_ho h_{t-1} + b_ho)
    c_t = f_t * c_{t-1} + i_t * g_t
    h_t = o_t * tanh(c_t)

Parameters (``k`` = layer)::

    {prefix}.weight_ih_l{k}  (4H, I_k)   rows [W_ii | W_if | W_ig | W_io]; I_0 = I, I_k = H for k > 0
    {prefix}.weight_hh_l{k}  (4H, H)
    {prefix}.bias_ih_l{k}    (4H,)
    {prefix}.bias_hh_l{k}    (4H,)

Stacking. Ordinary (``skewed=False``, PyTorch): layer k reads layer k-1's output of the SAME step,
``x^k_t = h^{k-1}_t``. Skewed (``skewed=True``, acRNN's published code, spec/layers.md §5.3):
layer k reads layer k-1's output of the PREVIOUS step, ``x^k_t = h^{k-1}_{t-1}``, where ``h^{k-1}_{-1}`` is
layer k-1's initial state ``h0[k-1]`` (zeros in acRNN). Layer 0 reads ``x_t`` in both. The top layer's new
state is the output, so with L layers ``y_t`` depends on ``x_0 .. x_{t-L+1}`` only (for t < L-1, on no input).

Shapes: B batch, T time, I input size, H hidden size, L layers. ``x (B, T, I)`` batch-first;
``h0, c0, h_n, c_n (L, B, H)``; ``y (B, T, H)``. No bidirectional variant (no network here uses one).

Implementation (spec/layers.md §5.6): layer by layer, time-major and batch-major (``(T, B, ...)``, so that each
step reads contiguous rows): one GEMM for all input projections of a layer (both biases folded in), one
``_cell_forward`` / ``_cell_backward`` call per step with ``W_hh^T`` made contiguous once per call, and one GEMM
each for ``dW_hh``, ``dW_ih``, ``dx`` after the BPTT loop. The skew is only a shift of the input sequence: layer
k's inputs are ``[h0[k-1], h^{k-1}_0, ..., h^{k-1}_{T-2}]`` instead of ``[h^{k-1}_0, ..., h^{k-1}_{T-1}]``.
``_lstm_forward_naive`` / ``_lstm_backward_naive`` in :mod:`refimpl.nn.lstm_naive` (time-outer, per-gate loops,
as acRNN's code steps its cells) are the test oracles.

Checks (spec/layers.md §5.5), once per public call, never inside the step loops: I and H are read from layer 0's
parameters first, then ``x`` / ``x_t`` (dtype, shape ``(.., I)``, finite) and the state entries ``h0``, ``c0`` /
``h``, ``c`` (dtype, shape ``(L, B, H)``, finite) are checked against them, so a wrong input size is reported on
the input with the expected and the actual shape; then every parameter's shape and dtype (not its values). The
backwards check their cotangents ``dy`` and ``dh_n``, ``dc_n`` / ``dh_new``, ``dc_new`` (dtype, shape, finite).
"""
from __future__ import annotations

from typing import Mapping

import numpy as np

from refimpl.nn.activations import sigmoid
from refimpl.nn.linear import matmul_wt
from refimpl.arrays import float_array
from refimpl.nn.params import check_same_dtype, fan_in_bound, get_param, init_uniform, param_name

__all__ = ["lstm_forward", "lstm_backward", "lstm_step_forward", "lstm_step_backward", "lstm_init"]


# ----------------------------------------------------------------------------------------------------------
# parameters


def _all_weights(params, prefix, num_layers):
    """Every layer's ``(W_ih (4H, I_k), W_hh (4H, H), b_ih (4H,), b_hh (4H,))``, checked.

    The sizes are read from layer 0 (``H`` from ``weight_hh_l0`` ``(4H, H)``, ``I`` from ``weight_ih_l0``
    ``(4H, I)``) BEFORE the inputs are checked, so that a wrong ``x`` / state is reported on the input, not as a
    wrong parameter shape. Every parameter must have ``weight_hh_l0``'s dtype (float32 or float64); the values are
    not checked. Returns ``(weights, I, H)`` with ``weights[k]`` the tuple of layer ``k``.
    """
    w_hh0 = get_param(params, prefix, "weight_hh_l0", (None, None))  # (4H, H)
    hid, dt = w_hh0.shape[1], w_hh0.dtype
    if w_hh0.shape[0] != 4 * hid:
        raise ValueError(f"params[{param_name(prefix, 'weight_hh_l0')!r}]: expected shape (4H, H) = "
                         f"({4 * hid}, {hid}), got {w_hh0.shape}")
    w_ih0 = get_param(params, prefix, "weight_ih_l0", (4 * hid, None), dt)  # (4H, I)
    in_size = w_ih0.shape[1]
    weights = []
    for k in range(num_layers):
        weights.append((w_ih0 if k == 0 else get_param(params, prefix, f"weight_ih_l{k}", (4 * hid, hid), dt),
                        w_hh0 if k == 0 else get_param(params, prefix, f"weight_hh_l{k}", (4 * hid, hid), dt),
                        get_param(params, prefix, f"bias_ih_l{k}", (4 * hid,), dt),
                        get_param(params, prefix, f"bias_hh_l{k}", (4 * hid,), dt)))
    return weights, in_size, hid


def _size_note(prefix: str, letter: str, size: int, name: str) -> str:
    """Where an expected size comes from, for an input's shape error: ``"I = 4 from params['rnn.weight_ih_l0']"``."""
    return f"{letter} = {size} from params[{param_name(prefix, name)!r}]"


def _check_layers(num_layers: int) -> None:
    if not (isinstance(num_layers, (int, np.integer)) and num_layers >= 1):
        raise ValueError(f"num_layers: expected an integer >= 1, got {num_layers!r}")


def _check_state(state, name, entries, shape, x, x_name, prefix, weights):
    """The state tuple ``(h, c)``: each entry a finite array of ``shape`` = (L, B, H) and of ``x``'s dtype, which
    must also be the parameters' dtype. ``entries`` names them in messages (``("h0", "c0")``: ``"state[0] (h0)"``)."""
    if not (isinstance(state, (tuple, list)) and len(state) == 2):
        raise ValueError(f"{name}: expected a tuple ({', '.join(entries)}) of two (L, B, H) arrays, "
                         f"got {type(state).__name__}")
    context = f"L = {shape[0]}, B = {shape[1]} from {x_name}, " + _size_note(prefix, "H", shape[2], "weight_hh_l0")
    names = [f"{name}[{j}] ({e})" for j, e in enumerate(entries)]
    h = float_array(state[0], names[0], shape, context=context, cast=False)
    c = float_array(state[1], names[1], shape, context=context, cast=False)
    check_same_dtype(x, x_name, {names[0]: h, names[1]: c})
    dt = weights[0][1].dtype
    if dt != x.dtype:
        raise ValueError(f"params[{param_name(prefix, 'weight_hh_l0')!r}]: expected dtype {x.dtype} (the dtype of "
                         f"{x_name}), got {dt}")
    return h, c


def lstm_init(rng: np.random.Generator, input_size: int, hidden_size: int, num_layers: int, prefix: str,
              dtype=np.float64) -> dict[str, np.ndarray]:
    """PyTorch-default initialisation of ``nn.LSTM``: every parameter ``~ U(-1/sqrt(H), 1/sqrt(H))``.

    Returns
    -------
    dict
        ``{prefix}.weight_ih_l{k}`` ``(4H, I_k)``, ``weight_hh_l{k}`` ``(4H, H)``, ``bias_ih_l{k}``,
        ``bias_hh_l{k}`` ``(4H,)``.
    """
    _check_layers(num_layers)
    bound = fan_in_bound(hidden_size)
    out = {}
    for k in range(num_layers):
        in_k = input_size if k == 0 else hidden_size
        for name, shape in ((f"weight_ih_l{k}", (4 * hidden_size, in_k)),
                            (f"weight_hh_l{k}", (4 * hidden_size, hidden_size)),
                            (f"bias_ih_l{k}", (4 * hidden_size,)), (f"bias_hh_l{k}", (4 * hidden_size,))):
            out[param_name(prefix, name)] = init_uniform(rng, shape, bound, dtype)
    return out


# ----------------------------------------------------------------------------------------------------------
# one cell step (internal kernels, no checks; outputs written into preallocated arrays)


def _cell_forward(gi, h, c, w_hh, whh_t, g, c_new, tc, h_new):
    """One LSTM step.

    gi (B, 4H): ``W_ih x + b_ih + b_hh``. h, c (B, H): previous state. ``whh_t`` (H, 4H) C-contiguous
    ``W_hh^T`` or None (then ``w_hh`` is used via :func:`~refimpl.nn.linear.matmul_wt`). Writes g (B, 4H) =
    activated gates [i | f | g | o], c_new, tc = tanh(c_new), h_new (all (B, H)).
    """
    if whh_t is not None:
        np.matmul(h, whh_t, out=g)  # (B, 4H)
    else:
        matmul_wt(h, w_hh, out=g)
    g += gi
    hid = c.shape[1]
    sigmoid(g[:, :2 * hid], out=g[:, :2 * hid])  # i, f
    np.tanh(g[:, 2 * hid:3 * hid], out=g[:, 2 * hid:3 * hid])  # g
    sigmoid(g[:, 3 * hid:], out=g[:, 3 * hid:])  # o
    np.multiply(g[:, hid:2 * hid], c, out=c_new)  # c' = f c + i g
    np.multiply(g[:, :hid], g[:, 2 * hid:3 * hid], out=tc)
    c_new += tc
    np.tanh(c_new, out=tc)
    np.multiply(g[:, 3 * hid:], tc, out=h_new)  # h' = o tanh(c')


def _cell_backward(dh, dc, c, g, tc, w_hh, dg, tmp):
    """Back-propagate one LSTM step.

    dh, dc (B, H): total cotangents of h', c' on entry; overwritten with the cotangents of the previous
    h, c. c (B, H): previous cell state. Writes dg (B, 4H): cotangents of the gate pre-activations
    [a_i | a_f | a_g | a_o]. tmp (B, H) is scratch.
    """
    hid = c.shape[1]
    i, f, gg, o = g[:, :hid], g[:, hid:2 * hid], g[:, 2 * hid:3 * hid], g[:, 3 * hid:]
    di, df, dgg, do = dg[:, :hid], dg[:, hid:2 * hid], dg[:, 2 * hid:3 * hid], dg[:, 3 * hid:]
    np.subtract(1, o, out=do)  # da_o = dh tanh(c') o (1 - o)
    do *= o
    do *= tc
    do *= dh
    np.multiply(tc, tc, out=tmp)  # dc += dh o (1 - tanh(c')^2)
    np.subtract(1, tmp, out=tmp)
    tmp *= o
    tmp *= dh
    dc += tmp
    np.subtract(1, i, out=di)  # da_i = dc g i (1 - i)
    di *= i
    di *= gg
    di *= dc
    np.subtract(1, f, out=df)  # da_f = dc c f (1 - f)
    df *= f
    df *= c
    df *= dc
    np.multiply(gg, gg, out=dgg)  # da_g = dc i (1 - g^2)
    np.subtract(1, dgg, out=dgg)
    dgg *= i
    dgg *= dc
    dc *= f  # dc_prev = dc f
    np.matmul(dg, w_hh, out=dh)  # dh_prev = dg W_hh


# ----------------------------------------------------------------------------------------------------------
# one layer over the whole sequence (time-major, batch-major)


def _layer_forward(xs, h0, c0, w_ih, w_hh, b_ih, b_hh):
    """One layer over the sequence (one cell call per step). xs (T, B, I). Returns hs, cs (T+1, B, H)
    (index 0 = initial state), g (T, B, 4H), tc (T, B, H)."""
    t_len, batch, in_size = xs.shape
    hid = w_hh.shape[1]
    gi = matmul_wt(xs.reshape(t_len * batch, in_size), w_ih)  # (T*B, 4H), one GEMM for all steps
    gi += b_ih + b_hh
    gi = gi.reshape(t_len, batch, 4 * hid)
    whh_t = np.ascontiguousarray(w_hh.T)  # (H, 4H), transposed once per call
    dt = xs.dtype
    hs = np.empty((t_len + 1, batch, hid), dtype=dt)
    cs = np.empty((t_len + 1, batch, hid), dtype=dt)
    hs[0], cs[0] = h0, c0
    g = np.empty((t_len, batch, 4 * hid), dtype=dt)
    tc = np.empty((t_len, batch, hid), dtype=dt)
    for t in range(t_len):
        _cell_forward(gi[t], hs[t], cs[t], w_hh, whh_t, g[t], cs[t + 1], tc[t], hs[t + 1])
    return hs, cs, g, tc


def _layer_backward(dys, dh_last, dc_last, xs, hs, cs, g, tc, w_ih, w_hh):
    """BPTT through one layer. dys (T', B, H) cotangents of the outputs h_1..h_T' (T' <= T; the
    outputs after T' get none; may be a view); dh_last, dc_last (B, H) or None. Returns dxs (T, B, I), dh0, dc0,
    dW_ih, dW_hh, db (the same for b_ih and b_hh)."""
    t_len, batch, in_size = xs.shape
    hid = w_hh.shape[1]
    dt = xs.dtype
    dg = np.empty((t_len, batch, 4 * hid), dtype=dt)
    dh = np.zeros((batch, hid), dtype=dt) if dh_last is None else np.array(dh_last, dtype=dt)
    dc = np.zeros((batch, hid), dtype=dt) if dc_last is None else np.array(dc_last, dtype=dt)
    tmp = np.empty((batch, hid), dtype=dt)
    for t in range(t_len - 1, -1, -1):
        if t < len(dys):
            dh += dys[t]
        _cell_backward(dh, dc, cs[t], g[t], tc[t], w_hh, dg[t], tmp)
    dg2 = dg.reshape(t_len * batch, 4 * hid)  # (T*B, 4H)
    dw_hh = dg2.T @ hs[:-1].reshape(t_len * batch, hid)  # (4H, H), one GEMM over all steps
    dw_ih = dg2.T @ xs.reshape(t_len * batch, in_size)  # (4H, I)
    dxs = (dg2 @ w_ih).reshape(t_len, batch, in_size)  # (T, B, I)
    return dxs, dh, dc, dw_ih, dw_hh, dg2.sum(axis=0)


# ----------------------------------------------------------------------------------------------------------
# public: sequence


def lstm_forward(x: np.ndarray, state: tuple, params: Mapping[str, np.ndarray], prefix: str,
                 num_layers: int = 1, skewed: bool = False):
    """Run a multi-layer LSTM over a batch of sequences (PyTorch ``nn.LSTM(..., batch_first=True)``).

    Parameters
    ----------
    x : ndarray (B, T, I), float32 or float64, T >= 1
    state : tuple (h0, c0)
        Initial states, each ``(L, B, H)``, same dtype as ``x``.
    params : dict
        ``{prefix}.weight_ih_l{k}`` etc., see the module docstring.
    prefix : str
    num_layers : int
    skewed : bool
        acRNN's stacking: layer k reads layer k-1's output of the previous step (module docstring).

    Returns
    -------
    y : ndarray (B, T, H)
        Top-layer outputs ``h^{L-1}_t``.
    (h_n, c_n) : tuple of ndarray (L, B, H)
    cache : dict
        For :func:`lstm_backward`.

    Raises
    ------
    ValueError
        Naming ``x``, ``state`` or its entries ``state[0] (h0)``, ``state[1] (c0)`` (expected and actual shape,
        dtype, NaN/inf; I and H are those of the parameters), ``num_layers``, or the full name of a missing or
        mis-shaped parameter.
    """
    _check_layers(num_layers)
    weights, in_size, hid = _all_weights(params, prefix, num_layers)
    x = float_array(x, "x", (None, None, in_size), context=_size_note(prefix, "I", in_size, "weight_ih_l0"), cast=False)
    batch, t_len, _ = x.shape
    if t_len < 1:
        raise ValueError(f"x: expected at least one time step (B, T >= 1, I), got {x.shape}")
    h0, c0 = _check_state(state, "state", ("h0", "c0"), (num_layers, batch, hid), x, "x", prefix, weights)
    return _forward_layers(x, h0, c0, weights, prefix, num_layers, skewed)


def _forward_layers(x, h0, c0, weights, prefix, num_layers, skewed):
    """The layer loop of :func:`lstm_forward` (inputs checked). The cache's ``layers[k]`` holds layer k's
    ``(inputs, hs, cs, g, tc)``, time-major."""
    batch, t_len, in_size = x.shape
    h_n = np.empty_like(h0)
    c_n = np.empty_like(c0)
    layers = []
    xs = np.array(x.transpose(1, 0, 2), order="C")  # (T, B, I), always a copy
    for k in range(num_layers):
        hs, cs, g, tc = _layer_forward(xs, h0[k], c0[k], *weights[k])
        layers.append((xs, hs, cs, g, tc))
        h_n[k], c_n[k] = hs[-1], cs[-1]
        xs = hs[:-1] if skewed else hs[1:]  # (T, B, H) contiguous views: the next layer's inputs
    y = np.array(hs[1:].transpose(1, 0, 2), order="C")  # (B, T, H)
    cache = dict(layers=layers, weights=weights, prefix=prefix, num_layers=num_layers, skewed=skewed,
                 shape=(batch, t_len, in_size, h0.shape[-1]))
    return y, (h_n, c_n), cache


def lstm_backward(dy: np.ndarray | None, dstate_n, cache):
    """Back-propagation through time for :func:`lstm_forward`.

    Parameters
    ----------
    dy : ndarray (B, T, H) or None
        Cotangent of ``y`` (None: zero); float32 or float64, finite.
    dstate_n : tuple (dh_n, dc_n) or None
        Cotangents of ``(h_n, c_n)``, each ``(L, B, H)`` (float32 or float64, finite) or None (zero).
    cache : dict
        From :func:`lstm_forward`.

    Returns
    -------
    dx : ndarray (B, T, I)
    (dh0, dc0) : tuple of ndarray (L, B, H)
    grads : dict
        Full parameter names -> gradients.

    Notes
    -----
    Per step (spec/layers.md §5.2), with ``dh``, ``dc`` the total cotangents of ``h_t``, ``c_t``::

        da_o = dh tanh(c_t) o (1 - o)        dc += dh o (1 - tanh(c_t)^2)
        da_i = dc g i (1 - i)   da_f = dc c_{t-1} f (1 - f)   da_g = dc i (1 - g^2)
        dc_{t-1} = dc f         dh_{t-1} = [da_i | da_f | da_g | da_o] W_hh
        dW_ih += da^T x_t       dW_hh += da^T h_{t-1}        db_ih = db_hh = sum da
    """
    layers, weights, prefix = cache["layers"], cache["weights"], cache["prefix"]
    num_layers, skewed = cache["num_layers"], cache["skewed"]
    batch, t_len, in_size, hid = cache["shape"]
    dt = layers[0][0].dtype
    if dy is not None:
        dy = float_array(dy, "dy", (batch, t_len, hid), cast=False)
    dh_n = dc_n = None
    if dstate_n is not None:
        if not (isinstance(dstate_n, (tuple, list)) and len(dstate_n) == 2):
            raise ValueError("dstate_n: expected None or a tuple (dh_n, dc_n)")
        dh_n, dc_n = dstate_n
        if dh_n is not None:
            dh_n = float_array(dh_n, "dstate_n[0] (dh_n)", (num_layers, batch, hid), cast=False)
        if dc_n is not None:
            dc_n = float_array(dc_n, "dstate_n[1] (dc_n)", (num_layers, batch, hid), cast=False)
    dys = np.zeros((0, batch, hid), dtype=dt) if dy is None else dy.transpose(1, 0, 2)  # (T, B, H) view
    dh0 = np.empty((num_layers, batch, hid), dtype=dt)
    dc0 = np.empty((num_layers, batch, hid), dtype=dt)
    grads = {}
    skew_dh0 = None  # skewed: cotangent of h0[k] through layer k+1's first input
    for k in range(num_layers - 1, -1, -1):
        w_ih, w_hh, _, _ = weights[k]
        dxs, dh_k, dc_k, dw_ih, dw_hh, db = _layer_backward(
            dys, None if dh_n is None else dh_n[k], None if dc_n is None else dc_n[k], *layers[k], w_ih, w_hh)
        dh0[k], dc0[k] = dh_k, dc_k
        if skew_dh0 is not None:
            dh0[k] += skew_dh0
        grads[param_name(prefix, f"weight_ih_l{k}")] = dw_ih
        grads[param_name(prefix, f"weight_hh_l{k}")] = dw_hh
        grads[param_name(prefix, f"bias_ih_l{k}")] = db
        grads[param_name(prefix, f"bias_hh_l{k}")] = db.copy()
        if skewed and k > 0:
            # inputs were [h0[k-1], h_0, ..., h_{T-2}] of layer k-1: the first input's cotangent goes to dh0[k-1],
            # the others to the outputs of layer k-1 one step earlier (h_{T-1} gets none); views, no copies
            skew_dh0 = dxs[0]
            dys = dxs[1:]
        else:
            dys = dxs
    dx = np.ascontiguousarray(dys.transpose(1, 0, 2))  # (B, T, I)
    return dx, (dh0, dc0), grads


# ----------------------------------------------------------------------------------------------------------
# public: single step


def lstm_step_forward(x_t: np.ndarray, state: tuple, params: Mapping[str, np.ndarray], prefix: str,
                      num_layers: int = 1, skewed: bool = False):
    """One time step of the multi-layer LSTM (all layers), for output-feedback loops.

    Parameters
    ----------
    x_t : ndarray (B, I)
    state : tuple (h, c), each (L, B, H)
        States after the previous step.
    params, prefix, num_layers, skewed
        As for :func:`lstm_forward`. With ``skewed`` layer k reads ``h[k-1]`` (the OLD state of the layer
        below), as acRNN's code does; otherwise the new one.

    Returns
    -------
    y : ndarray (B, H)
        The top layer's new ``h`` (a copy of ``h_new[-1]``).
    (h_new, c_new) : tuple of ndarray (L, B, H)
    cache : dict
        For :func:`lstm_step_backward`.

    Raises
    ------
    ValueError
        Naming ``x_t``, ``state`` or its entries ``state[0] (h)``, ``state[1] (c)`` (expected and actual shape,
        dtype, NaN/inf; I and H are those of the parameters), ``num_layers``, or the full name of a missing or
        mis-shaped parameter. The weights' values are not checked (this is called once per step of a rollout).

    Notes
    -----
    Repeated over t it gives exactly :func:`lstm_forward` (with the same ``skewed``).
    """
    _check_layers(num_layers)
    weights, in_size, hid = _all_weights(params, prefix, num_layers)
    x_t = float_array(x_t, "x_t", (None, in_size), context=_size_note(prefix, "I", in_size, "weight_ih_l0"), cast=False)
    batch = x_t.shape[0]
    h, c = _check_state(state, "state", ("h", "c"), (num_layers, batch, hid), x_t, "x_t", prefix, weights)
    x_t, h, c = x_t.copy(), h.copy(), c.copy()  # the cache must not alias the caller's buffers
    h_new, c_new = np.empty_like(h), np.empty_like(c)
    layers = []
    for k in range(num_layers):
        w_ih, w_hh, b_ih, b_hh = weights[k]
        inp = x_t if k == 0 else (h[k - 1] if skewed else h_new[k - 1])  # (B, I_k)
        gi = matmul_wt(inp, w_ih)  # (B, 4H)
        gi += b_ih
        gi += b_hh
        g = np.empty((batch, 4 * hid), dtype=x_t.dtype)
        tc = np.empty((batch, hid), dtype=x_t.dtype)
        _cell_forward(gi, h[k], c[k], w_hh, None, g, c_new[k], tc, h_new[k])
        layers.append((inp, h[k], c[k], g, tc))
    cache = dict(layers=layers, weights=weights, prefix=prefix, num_layers=num_layers, skewed=skewed,
                 shape=(batch, in_size, hid))
    return h_new[-1].copy(), (h_new, c_new), cache


def lstm_step_backward(dy: np.ndarray | None, dstate_new, cache, accumulate_into=None):
    """Back-propagate one :func:`lstm_step_forward`.

    Parameters
    ----------
    dy : ndarray (B, H) or None
        Cotangent of ``y`` (None: zero); float32 or float64, finite.
    dstate_new : tuple (dh_new, dc_new) or None
        Cotangents of the new states (each ``(L, B, H)``, float32 or float64, finite, or None), i.e. what the next
        step's backward returned.
    cache : dict
        From :func:`lstm_step_forward`.
    accumulate_into : dict, optional
        Gradient dict to add this step's parameter gradients into, in place (returned as ``grads``).

    Returns
    -------
    dx_t : ndarray (B, I)
    (dh, dc) : tuple of ndarray (L, B, H)
        Cotangents of the previous states.
    grads : dict
    """
    layers, weights, prefix = cache["layers"], cache["weights"], cache["prefix"]
    num_layers, skewed = cache["num_layers"], cache["skewed"]
    batch, in_size, hid = cache["shape"]
    dt = layers[0][3].dtype
    if dy is not None:
        dy = float_array(dy, "dy", (batch, hid), cast=False)
    dh_new = dc_new = None
    if dstate_new is not None:
        if not (isinstance(dstate_new, (tuple, list)) and len(dstate_new) == 2):
            raise ValueError("dstate_new: expected None or a tuple (dh_new, dc_new)")
        dh_new, dc_new = dstate_new
        if dh_new is not None:
            dh_new = float_array(dh_new, "dstate_new[0] (dh_new)", (num_layers, batch, hid), cast=False)
        if dc_new is not None:
            dc_new = float_array(dc_new, "dstate_new[1] (dc_new)", (num_layers, batch, hid), cast=False)
    grads = {} if accumulate_into is None else accumulate_into
    dh_prev = np.empty((num_layers, batch, hid), dtype=dt)
    dc_prev = np.empty((num_layers, batch, hid), dtype=dt)
    tmp = np.empty((batch, hid), dtype=dt)
    d_out = dy  # cotangent of this layer's new h from the layer above (ordinary stacking) or from y
    skew_pending = None  # skewed: cotangent of this layer's OLD h from the layer above
    d_in = None
    for k in range(num_layers - 1, -1, -1):
        inp, h, c, g, tc = layers[k]
        w_ih, w_hh, _, _ = weights[k]
        dh, dc = dh_prev[k], dc_prev[k]
        dh[...] = 0 if dh_new is None else dh_new[k]
        dc[...] = 0 if dc_new is None else dc_new[k]
        if d_out is not None:
            dh += d_out
        dg = np.empty((batch, 4 * hid), dtype=dt)
        _cell_backward(dh, dc, c, g, tc, w_hh, dg, tmp)
        if skew_pending is not None:
            dh += skew_pending
        db = dg.sum(axis=0)
        for name, value in ((f"weight_ih_l{k}", dg.T @ inp), (f"weight_hh_l{k}", dg.T @ h),
                            (f"bias_ih_l{k}", db), (f"bias_hh_l{k}", db.copy())):
            full = param_name(prefix, name)
            if full in grads:
                grads[full] += value
            else:
                grads[full] = value
        d_in = dg @ w_ih  # (B, I_k): cotangent of this layer's input
        if skewed and k > 0:
            d_out, skew_pending = None, d_in
        else:
            d_out, skew_pending = d_in, None
    return d_in, (dh_prev, dc_prev), grads
