"""Tests of refimpl.nn.gru (spec/layers.md §4): PyTorch golden vectors, per-gate loop oracles, central
differences, the vector-Jacobian identity, the step API (also in output-feedback rollouts), dtypes, errors."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import load_golden
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.nn.gru import gru_backward, gru_forward, gru_init, gru_step_backward, gru_step_forward
from refimpl.nn.gru_naive import gru_backward_naive, gru_forward_naive
from refimpl.nn.params import count_parameters
from refimpl.testing import TOL_EXACT, TOL_GOLDEN, assert_close

sizes = st.integers(1, 4)
seeds = st.integers(0, 2**31 - 1)


def _case(seed, batch, t_len, n_in, hid, layers, bidirectional, dtype=np.float64, prefix="rnn"):
    rng = np.random.default_rng(seed)
    params = gru_init(rng, n_in, hid, layers, prefix, bidirectional, dtype)
    d = 2 if bidirectional else 1
    x = rng.standard_normal((batch, t_len, n_in)).astype(dtype)
    h0 = (0.5 * rng.standard_normal((layers * d, batch, hid))).astype(dtype)
    gy = rng.standard_normal((batch, t_len, d * hid)).astype(dtype)
    gh = rng.standard_normal((layers * d, batch, hid)).astype(dtype)
    return params, x, h0, gy, gh


def _assert_grads(actual, expected, tol, what=""):
    assert sorted(actual) == sorted(expected), what
    for k in expected:
        assert_close(actual[k], expected[k], **tol, name=f"{what}{k}")


@pytest.mark.parametrize("name,layers,bidirectional", [("gru_2layer", 2, False), ("gru_bidirectional", 1, True)])
def test_golden(name, layers, bidirectional):
    """spec/layers.md §4 vs PyTorch nn.GRU (float64): y, h_n and the gradients of x, h0 and every parameter."""
    g = load_golden(f"{name}.npz")
    params = {k[len("param."):]: v for k, v in g.items() if k.startswith("param.")}
    y, h_n, cache = gru_forward(g["in.x"], g["in.h0"], params, "", layers, bidirectional)
    assert_close(y, g["out.y"], **TOL_GOLDEN, name="y")
    assert_close(h_n, g["out.h_n"], **TOL_GOLDEN, name="h_n")
    dx, dh0, grads = gru_backward(g["in.gy"], g["in.gh"], cache)
    assert_close(dx, g["grad.x"], **TOL_GOLDEN, name="grad.x")
    assert_close(dh0, g["grad.h0"], **TOL_GOLDEN, name="grad.h0")
    _assert_grads(grads, {k: g["grad." + k] for k in params}, TOL_GOLDEN, "grad.")


@given(seeds, sizes, sizes, sizes, sizes, sizes, st.booleans())
def test_matches_per_gate_loop_oracle(seed, batch, t_len, n_in, hid, layers, bidirectional):
    """spec/layers.md §4.1-4.3: the vectorised GRU equals the per-step, per-gate loop (forward and backward)."""
    params, x, h0, gy, gh = _case(seed, batch, t_len, n_in, hid, layers, bidirectional)
    y, h_n, cache = gru_forward(x, h0, params, "rnn", layers, bidirectional)
    y_ref, h_ref = gru_forward_naive(x, h0, params, "rnn", layers, bidirectional)
    assert_close(y, y_ref, **TOL_EXACT, name="y")
    assert_close(h_n, h_ref, **TOL_EXACT, name="h_n")
    dx, dh0, grads = gru_backward(gy, gh, cache)
    dx_ref, dh0_ref, grads_ref = gru_backward_naive(gy, gh, x, h0, params, "rnn", layers, bidirectional)
    assert_close(dx, dx_ref, **TOL_EXACT, name="dx")
    assert_close(dh0, dh0_ref, **TOL_EXACT, name="dh0")
    _assert_grads(grads, grads_ref, TOL_EXACT)


@given(seeds, sizes, sizes, sizes, sizes, sizes, st.booleans())
def test_vjp_identity(seed, batch, t_len, n_in, hid, layers, bidirectional):
    """spec/layers.md §4.2: <J v, w> = <v, J^T w> for (y, h_n) w.r.t. x, h0 and all parameters."""
    params, x, h0, _, _ = _case(seed, batch, t_len, n_in, hid, layers, bidirectional)
    arrays = {"x": x, "h0": h0, **params}

    def fn():
        y, h_n, _ = gru_forward(x, h0, params, "rnn", layers, bidirectional)
        return y, h_n

    def vjp(douts):
        _, _, cache = gru_forward(x, h0, params, "rnn", layers, bidirectional)
        dx, dh0, grads = gru_backward(douts[0], douts[1], cache)
        return {"x": dx, "h0": dh0, **grads}

    check_vjp(fn, arrays, vjp)


@pytest.mark.parametrize("layers,bidirectional", [(1, False), (2, False), (2, True)])
def test_central_differences(layers, bidirectional):
    """spec/layers.md §4.2: each gradient (x, h0, each parameter) against central differences."""
    params, x, h0, gy, gh = _case(7, 2, 3, 2, 3, layers, bidirectional)

    def loss():
        y, h_n, _ = gru_forward(x, h0, params, "rnn", layers, bidirectional)
        return float(np.sum(y * gy) + np.sum(h_n * gh))

    _, _, cache = gru_forward(x, h0, params, "rnn", layers, bidirectional)
    dx, dh0, grads = gru_backward(gy, gh, cache)
    check_gradients(loss, {"x": x, "h0": h0, **params}, {"x": dx, "h0": dh0, **grads}, max_entries=24)


def test_none_cotangents():
    """spec/layers.md §4: dy or dh_n = None means a zero cotangent."""
    params, x, h0, gy, gh = _case(3, 2, 3, 2, 3, 2, True)
    _, _, cache = gru_forward(x, h0, params, "rnn", 2, True)
    dx_a, dh0_a, g_a = gru_backward(gy, None, cache)
    dx_b, dh0_b, g_b = gru_backward(gy, np.zeros_like(gh), cache)
    assert_close(dx_a, dx_b, **TOL_EXACT)
    assert_close(dh0_a, dh0_b, **TOL_EXACT)
    _assert_grads(g_a, g_b, TOL_EXACT)
    dx_c, dh0_c, g_c = gru_backward(None, gh, cache)
    dx_d, dh0_d, g_d = gru_backward(np.zeros_like(gy), gh, cache)
    assert_close(dx_c, dx_d, **TOL_EXACT)
    _assert_grads(g_c, g_d, TOL_EXACT)


@given(seeds, sizes, sizes, sizes, sizes, sizes)
def test_step_api_equals_sequence(seed, batch, t_len, n_in, hid, layers):
    """spec/layers.md §4.4: stepping gives the sequence outputs, and the reverse loop over step caches gives the
    sequence gradients (with and without accumulate_into)."""
    params, x, h0, gy, gh = _case(seed, batch, t_len, n_in, hid, layers, False)
    y, h_n, cache = gru_forward(x, h0, params, "rnn", layers)
    dx, dh0, grads = gru_backward(gy, gh, cache)
    h, caches, ys = h0, [], []
    for t in range(t_len):
        y_t, h, c = gru_step_forward(x[:, t], h, params, "rnn", layers)
        ys.append(y_t)
        caches.append(c)
    assert_close(np.stack(ys, axis=1), y, **TOL_EXACT, name="y")
    assert_close(h, h_n, **TOL_EXACT, name="h_n")
    for accumulate in (False, True):
        dh, acc, dxs, per_step = gh, None, [], []
        for t in range(t_len - 1, -1, -1):
            dx_t, dh, g_t = gru_step_backward(gy[:, t], dh, caches[t], accumulate_into=acc if accumulate else None)
            dxs.append(dx_t)
            if accumulate:
                acc = g_t
            else:
                per_step.append(g_t)
        total = acc if accumulate else {k: sum(g[k] for g in per_step) for k in per_step[0]}
        assert_close(np.stack(dxs[::-1], axis=1), dx, **TOL_EXACT, name="dx")
        assert_close(dh, dh0, **TOL_EXACT, name="dh0")
        _assert_grads(total, grads, TOL_EXACT)


def _rollout(x0, h0, params, layers, t_len):
    """Output-feedback rollout: x_{t+1} = y_t (input size == hidden size). Returns outputs (B, T, H), h_T, caches."""
    x_t, h, ys, caches = x0, h0, [], []
    for _ in range(t_len):
        y_t, h, c = gru_step_forward(x_t, h, params, "rnn", layers)
        ys.append(y_t)
        caches.append(c)
        x_t = y_t
    return np.stack(ys, axis=1), h, caches


def _rollout_backward(gy, gh, caches):
    """Reverse loop: the cotangent of y_t is gy_t plus the gradient from its use as input x_{t+1}."""
    dh, acc, dx_next = gh, None, None
    for t in range(len(caches) - 1, -1, -1):
        dy_t = gy[:, t] if dx_next is None else gy[:, t] + dx_next
        dx_next, dh, acc = gru_step_backward(dy_t, dh, caches[t], accumulate_into=acc)
    return dx_next, dh, acc


@settings(max_examples=15)
@given(seeds, sizes, sizes, sizes, sizes)
def test_feedback_rollout_vjp(seed, batch, t_len, hid, layers):
    """spec/layers.md §4.4: gradients flow through the fed-back outputs (VJP identity over a whole rollout)."""
    params, x, h0, _, _ = _case(seed, batch, 1, hid, hid, layers, False)
    x0 = x[:, 0].copy()

    def fn():
        ys, h, _ = _rollout(x0, h0, params, layers, t_len)
        return ys, h

    def vjp(douts):
        _, _, caches = _rollout(x0, h0, params, layers, t_len)
        dx0, dh0, grads = _rollout_backward(douts[0], douts[1], caches)
        return {"x0": dx0, "h0": dh0, **grads}

    check_vjp(fn, {"x0": x0, "h0": h0, **params}, vjp)


def test_feedback_rollout_central_differences():
    """spec/layers.md §4.4: rollout gradients against central differences."""
    layers, hid, t_len = 2, 3, 4
    params, x, h0, _, _ = _case(11, 2, 1, hid, hid, layers, False)
    x0 = x[:, 0].copy()
    rng = np.random.default_rng(12)
    gy, gh = rng.standard_normal((2, t_len, hid)), rng.standard_normal((layers, 2, hid))

    def loss():
        ys, h, _ = _rollout(x0, h0, params, layers, t_len)
        return float(np.sum(ys * gy) + np.sum(h * gh))

    _, _, caches = _rollout(x0, h0, params, layers, t_len)
    dx0, dh0, grads = _rollout_backward(gy, gh, caches)
    check_gradients(loss, {"x0": x0, "h0": h0, **params}, {"x0": dx0, "h0": dh0, **grads}, max_entries=24)


def test_step_none_cotangents():
    """spec/layers.md §4.4: either step cotangent may be None (zero)."""
    params, x, h0, gy, gh = _case(5, 2, 1, 3, 4, 2, False)
    _, _, c = gru_step_forward(x[:, 0], h0, params, "rnn", 2)
    a = gru_step_backward(None, gh, c)
    b = gru_step_backward(np.zeros((2, 4)), gh, c)
    assert_close(a[0], b[0], **TOL_EXACT)
    assert_close(a[1], b[1], **TOL_EXACT)
    a = gru_step_backward(gy[:, 0], None, c)
    b = gru_step_backward(gy[:, 0], np.zeros_like(gh), c)
    assert_close(a[0], b[0], **TOL_EXACT)
    _assert_grads(a[2], b[2], TOL_EXACT)


@pytest.mark.parametrize("bidirectional", [False, True])
def test_float32_stays_float32(bidirectional):
    """spec/architecture.md dtype rule: float32 in -> float32 outputs and gradients, close to the float64 run."""
    p64, x64, h64, gy64, gh64 = _case(9, 3, 5, 4, 6, 2, bidirectional)
    p32 = {k: v.astype(np.float32) for k, v in p64.items()}
    args32 = [a.astype(np.float32) for a in (x64, h64, gy64, gh64)]
    y, h_n, cache = gru_forward(args32[0], args32[1], p32, "rnn", 2, bidirectional)
    dx, dh0, grads = gru_backward(args32[2], args32[3], cache)
    assert y.dtype == h_n.dtype == dx.dtype == dh0.dtype == np.float32
    assert all(g.dtype == np.float32 for g in grads.values())
    y64, _, c64 = gru_forward(x64, h64, p64, "rnn", 2, bidirectional)
    dx64, _, g64 = gru_backward(gy64, gh64, c64)
    assert_close(y, y64, rtol=1e-4, atol=1e-5, name="y")
    assert_close(dx, dx64, rtol=1e-4, atol=1e-4, name="dx")
    for k in g64:
        assert_close(grads[k], g64[k], rtol=1e-4, atol=1e-4, name=k)
    if bidirectional:
        return  # the step API is unidirectional
    y_t, h_new, c = gru_step_forward(args32[0][:, 0], args32[1], p32, "rnn", 2)
    dx_t, dh, g_t = gru_step_backward(y_t, h_new, c)
    assert y_t.dtype == h_new.dtype == dx_t.dtype == dh.dtype == np.float32
    assert all(g.dtype == np.float32 for g in g_t.values())


def test_init_names_shapes_and_count():
    """spec/layers.md §4.1: PyTorch names/layouts; every parameter U(±1/sqrt(H)); parameter count formula."""
    p = gru_init(np.random.default_rng(0), 5, 16, 2, "rnn", bidirectional=True)
    assert p["rnn.weight_ih_l0"].shape == (48, 5)
    assert p["rnn.weight_ih_l1_reverse"].shape == (48, 32)
    assert p["rnn.weight_hh_l1"].shape == (48, 16)
    assert p["rnn.bias_hh_l0_reverse"].shape == (48,)
    assert len(p) == 16
    assert max(np.abs(v).max() for v in p.values()) <= 0.25
    h, i = 16, 5
    assert count_parameters(p) == 2 * 3 * (h * i + h * h + 2 * h) + 2 * 3 * (h * 2 * h + h * h + 2 * h)
    q = gru_init(np.random.default_rng(0), 3, 4, 1, "", dtype=np.float32)
    assert set(q) == {"weight_ih_l0", "weight_hh_l0", "bias_ih_l0", "bias_hh_l0"}
    assert all(v.dtype == np.float32 for v in q.values())


def test_rejects_bad_input():
    """spec/architecture.md: ValueError naming the argument and the expected and actual shape / dtype."""
    params, x, h0, _, _ = _case(1, 2, 3, 4, 5, 2, False)
    with pytest.raises(ValueError, match=r"h0: expected shape \(2, 2, 5\), got \(1, 2, 5\)"):
        gru_forward(x, h0[:1], params, "rnn", 2)
    with pytest.raises(ValueError, match=r"weight_ih_l1'\]: expected shape \(15, 5\), got \(15, 4\)"):
        gru_forward(x, h0, {**params, "rnn.weight_ih_l1": np.zeros((15, 4))}, "rnn", 2)
    with pytest.raises(ValueError, match=r"weight_hh_l0'\]: expected shape \(3H, H\) = \(12, 4\), got \(15, 4\)"):
        gru_forward(x, h0, {**params, "rnn.weight_hh_l0": np.zeros((15, 4))}, "rnn", 2)
    with pytest.raises(ValueError, match="missing parameter 'rnn.weight_ih_l2'"):
        gru_forward(x, np.zeros((3, 2, 5)), params, "rnn", 3)
    with pytest.raises(ValueError, match="missing parameter 'rnn.weight_ih_l0_reverse'"):
        gru_forward(x, np.zeros((4, 2, 5)), params, "rnn", 2, bidirectional=True)
    with pytest.raises(ValueError, match="h0: expected dtype float64"):
        gru_forward(x, h0.astype(np.float32), params, "rnn", 2)
    with pytest.raises(ValueError, match="expected dtype float32"):
        gru_forward(x.astype(np.float32), h0.astype(np.float32), params, "rnn", 2)
    with pytest.raises(ValueError, match="x: expected finite"):
        gru_forward(np.full_like(x, np.nan), h0, params, "rnn", 2)
    with pytest.raises(ValueError, match="at least one time step"):
        gru_forward(x[:, :0], h0, params, "rnn", 2)
    with pytest.raises(ValueError, match="num_layers"):
        gru_forward(x, h0, params, "rnn", 0)
    with pytest.raises(ValueError, match=r"x_t: expected shape \(\*, 4\), got \(2, 3, 4\)"):
        gru_step_forward(x, h0, params, "rnn", 2)
    _, _, cache = gru_forward(x, h0, params, "rnn", 2)
    with pytest.raises(ValueError, match=r"dy: expected shape \(2, 3, 5\)"):
        gru_backward(np.zeros((2, 3, 4)), None, cache)


@pytest.mark.parametrize("step", [False, True])
def test_wrong_input_size_names_the_input(step):
    """spec/layers.md §4.5, spec/robustness.md B11: an input or state with the wrong feature size is reported on
    that argument (expected and actual shape, and where I / H come from), not as a wrong parameter shape."""
    params, x, h0, _, _ = _case(2, 2, 3, 4, 5, 2, False)
    fwd = gru_step_forward if step else gru_forward
    xn, hn = ("x_t", "h") if step else ("x", "h0")
    x = x[:, 0] if step else x
    lead = r"\(\*, " if step else r"\(\*, \*, "
    with pytest.raises(ValueError, match=rf"^{xn}: expected shape {lead}4\), got \({'2, ' if step else '2, 3, '}5\); "
                                         r"I = 4 from params\['rnn.weight_ih_l0'\]"):
        fwd(np.concatenate([x, x[..., :1]], axis=-1), h0, params, "rnn", 2)
    with pytest.raises(ValueError, match=rf"^{xn}: expected shape {lead}4\), got \({'2, ' if step else '2, 3, '}3\)"):
        fwd(x[..., :3], h0, params, "rnn", 2)
    with pytest.raises(ValueError, match=rf"^{hn}: expected shape \(2, 2, 5\), got \(2, 2, 6\); .*"
                                         r"H = 5 from params\['rnn.weight_hh_l0'\]"):
        fwd(x, np.concatenate([h0, h0[..., :1]], axis=-1), params, "rnn", 2)
    with pytest.raises(ValueError, match=rf"^{hn}: expected shape \(2, 2, 5\), got \(2, 3, 5\)"):
        fwd(x, np.concatenate([h0, h0[:, :1]], axis=1), params, "rnn", 2)
    with pytest.raises(ValueError, match=rf"^{hn}: expected finite"):
        fwd(x, np.full_like(h0, np.inf), params, "rnn", 2)


def test_backwards_refuse_non_finite_cotangents():
    """spec/layers.md §4.5, spec/robustness.md B13: NaN/inf in dy, dh_n (sequence) or dy, dh_new (step) →
    ValueError naming the argument; a cotangent of the wrong shape too."""
    params, x, h0, gy, gh = _case(3, 2, 3, 4, 5, 2, False)
    _, _, cache = gru_forward(x, h0, params, "rnn", 2)
    _, _, step_cache = gru_step_forward(x[:, 0], h0, params, "rnn", 2)
    for bad in (np.nan, np.inf, -np.inf):
        dy, dh = gy.copy(), gh.copy()
        dy[1, 2, 3] = bad
        dh[1, 0, 4] = bad
        with pytest.raises(ValueError, match=r"^dy: expected finite"):
            gru_backward(dy, gh, cache)
        with pytest.raises(ValueError, match=r"^dh_n: expected finite"):
            gru_backward(gy, dh, cache)
        with pytest.raises(ValueError, match=r"^dh_n: expected finite"):
            gru_backward(None, dh, cache)
        with pytest.raises(ValueError, match=r"^dy: expected finite"):
            gru_step_backward(dy[:, 2], gh, step_cache)
        with pytest.raises(ValueError, match=r"^dh_new: expected finite"):
            gru_step_backward(gy[:, 0], dh, step_cache)
    with pytest.raises(ValueError, match=r"^dh_new: expected shape \(2, 2, 5\), got \(1, 2, 5\)"):
        gru_step_backward(None, gh[:1], step_cache)
    with pytest.raises(ValueError, match=r"^dy: expected shape \(2, 5\), got \(2, 4\)"):
        gru_step_backward(gy[:, 0, :4], None, step_cache)
    with pytest.raises(ValueError, match=r"^dy: expected a float32 or float64 array"):
        gru_backward(gy.astype(int), None, cache)


@pytest.mark.parametrize("B, H", [(1, 1), (3, 5), (4, 16)])
def test_factored_cell_backward_equals_reference_kernel(B, H):
    """spec/layers.md §4.3: the factored reverse step of refimpl/nn/gru_fast.py (``backward_factors`` over all
    steps, then per step ``cell_backward_gates`` and ``dh_prev = dh z + dgh W_hh``, as QTG's rollout runs it) equals
    the per-step kernel ``cell_backward`` (float64), and the forward's element-wise part ``cell_update`` after an
    outside product equals ``cell_forward``."""
    from refimpl.nn import gru as G
    from refimpl.nn.gru_fast import backward_factors, cell_backward_gates
    rng = np.random.default_rng(B * 100 + H)
    T = 3
    w_hh = rng.standard_normal((3 * H, H))
    b_hn = rng.standard_normal(H)
    gi = rng.standard_normal((T, B, 3 * H))
    hs = np.zeros((T + 1, B, H))
    hs[0] = rng.standard_normal((B, H))
    g, n = np.empty((T, B, 3 * H)), np.empty((T, B, H))
    for t in range(T):
        G.cell_forward(gi[t], hs[t], w_hh, None, b_hn, g[t], n[t], hs[t + 1])
        g2, n2, h2 = hs[t] @ w_hh.T, np.empty((B, H)), np.empty((B, H))
        G.cell_update(gi[t], hs[t], b_hn, g2, n2, h2)
        assert np.array_equal(g2, g[t]) and np.array_equal(n2, n[t]) and np.array_equal(h2, hs[t + 1])
    f = backward_factors(hs[:-1], g, n)
    dh_ref = rng.standard_normal((B, H))
    dh_fast = dh_ref.copy()
    for t in range(T - 1, -1, -1):
        out_ref = [np.empty((B, 3 * H)), np.empty((B, 3 * H)), np.empty((B, H))]
        out_fast = [np.empty((B, 3 * H)), np.full((B, 3 * H), np.nan), np.empty((B, H))]
        G.cell_backward(dh_ref, hs[t], g[t], n[t], w_hh, *out_ref)
        dgi, dgh, tmp = out_fast
        cell_backward_gates(dh_fast, f[t], g[t, :, :H], dgi, dgh)
        dh_fast *= g[t, :, H:2 * H]
        dh_fast += dgh @ w_hh
        assert_close(out_fast[0], out_ref[0], **TOL_EXACT, name="dgi")
        assert_close(out_fast[1], out_ref[1], **TOL_EXACT, name="dgh")
        assert_close(dh_fast, dh_ref, **TOL_EXACT, name="dh")
