"""Tests of refimpl.nn.lstm (spec/layers.md §5): PyTorch golden vectors, the time-outer per-gate loop oracle
(ordinary and skewed stacking), central differences, the vector-Jacobian identity, the step API (also in
output-feedback rollouts), the skew's dependency structure, dtypes, errors."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import load_golden
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.nn.lstm import lstm_backward, lstm_forward, lstm_init, lstm_step_backward, lstm_step_forward
from refimpl.nn.lstm_naive import _lstm_backward_naive, _lstm_forward_naive
from refimpl.nn.params import count_parameters
from refimpl.testing import TOL_EXACT, TOL_GOLDEN, assert_close

sizes = st.integers(1, 4)
seeds = st.integers(0, 2**31 - 1)


def _case(seed, batch, t_len, n_in, hid, layers, dtype=np.float64, prefix="lstm"):
    rng = np.random.default_rng(seed)
    params = lstm_init(rng, n_in, hid, layers, prefix, dtype)
    x = rng.standard_normal((batch, t_len, n_in)).astype(dtype)
    h0 = (0.5 * rng.standard_normal((layers, batch, hid))).astype(dtype)
    c0 = (0.5 * rng.standard_normal((layers, batch, hid))).astype(dtype)
    gy = rng.standard_normal((batch, t_len, hid)).astype(dtype)
    gh = rng.standard_normal((layers, batch, hid)).astype(dtype)
    gc = rng.standard_normal((layers, batch, hid)).astype(dtype)
    return params, x, (h0, c0), gy, (gh, gc)


def _assert_grads(actual, expected, tol, what=""):
    assert sorted(actual) == sorted(expected), what
    for k in expected:
        assert_close(actual[k], expected[k], **tol, name=f"{what}{k}")


def test_golden_lstm_3layer():
    """spec/layers.md §5 vs PyTorch nn.LSTM (float64): y, h_n, c_n and the gradients of x, h0, c0, parameters."""
    g = load_golden("lstm_3layer.npz")
    params = {k[len("param."):]: v for k, v in g.items() if k.startswith("param.")}
    y, (h_n, c_n), cache = lstm_forward(g["in.x"], (g["in.h0"], g["in.c0"]), params, "", 3)
    assert_close(y, g["out.y"], **TOL_GOLDEN, name="y")
    assert_close(h_n, g["out.h_n"], **TOL_GOLDEN, name="h_n")
    assert_close(c_n, g["out.c_n"], **TOL_GOLDEN, name="c_n")
    dx, (dh0, dc0), grads = lstm_backward(g["in.gy"], (g["in.gh"], g["in.gc"]), cache)
    assert_close(dx, g["grad.x"], **TOL_GOLDEN, name="grad.x")
    assert_close(dh0, g["grad.h0"], **TOL_GOLDEN, name="grad.h0")
    assert_close(dc0, g["grad.c0"], **TOL_GOLDEN, name="grad.c0")
    _assert_grads(grads, {k: g["grad." + k] for k in params}, TOL_GOLDEN, "grad.")


@given(seeds, sizes, sizes, sizes, sizes, sizes, st.booleans())
def test_matches_time_outer_loop_oracle(seed, batch, t_len, n_in, hid, layers, skewed):
    """spec/layers.md §5.1-5.3: the layer-by-layer vectorised LSTM equals the time-outer per-gate loop (acRNN's
    way of stepping its cells), forward and backward, ordinary and skewed."""
    params, x, s0, gy, gs = _case(seed, batch, t_len, n_in, hid, layers)
    y, (h_n, c_n), cache = lstm_forward(x, s0, params, "lstm", layers, skewed)
    y_ref, (h_ref, c_ref) = _lstm_forward_naive(x, s0, params, "lstm", layers, skewed)
    assert_close(y, y_ref, **TOL_EXACT, name="y")
    assert_close(h_n, h_ref, **TOL_EXACT, name="h_n")
    assert_close(c_n, c_ref, **TOL_EXACT, name="c_n")
    dx, (dh0, dc0), grads = lstm_backward(gy, gs, cache)
    dx_ref, (dh0_ref, dc0_ref), grads_ref = _lstm_backward_naive(gy, gs, x, s0, params, "lstm", layers, skewed)
    assert_close(dx, dx_ref, **TOL_EXACT, name="dx")
    assert_close(dh0, dh0_ref, **TOL_EXACT, name="dh0")
    assert_close(dc0, dc0_ref, **TOL_EXACT, name="dc0")
    _assert_grads(grads, grads_ref, TOL_EXACT)


@given(seeds, sizes, sizes, sizes, sizes, sizes, st.booleans())
def test_vjp_identity(seed, batch, t_len, n_in, hid, layers, skewed):
    """spec/layers.md §5.2: <J v, w> = <v, J^T w> for (y, h_n, c_n) w.r.t. x, h0, c0 and all parameters."""
    params, x, (h0, c0), _, _ = _case(seed, batch, t_len, n_in, hid, layers)

    def fn():
        y, (h_n, c_n), _ = lstm_forward(x, (h0, c0), params, "lstm", layers, skewed)
        return y, h_n, c_n

    def vjp(douts):
        _, _, cache = lstm_forward(x, (h0, c0), params, "lstm", layers, skewed)
        dx, (dh0, dc0), grads = lstm_backward(douts[0], (douts[1], douts[2]), cache)
        return {"x": dx, "h0": dh0, "c0": dc0, **grads}

    check_vjp(fn, {"x": x, "h0": h0, "c0": c0, **params}, vjp)


@pytest.mark.parametrize("layers,skewed", [(1, False), (3, False), (3, True)])
def test_central_differences(layers, skewed):
    """spec/layers.md §5.2: each gradient against central differences."""
    params, x, (h0, c0), gy, (gh, gc) = _case(7, 2, 4, 2, 3, layers)

    def loss():
        y, (h_n, c_n), _ = lstm_forward(x, (h0, c0), params, "lstm", layers, skewed)
        return float(np.sum(y * gy) + np.sum(h_n * gh) + np.sum(c_n * gc))

    _, _, cache = lstm_forward(x, (h0, c0), params, "lstm", layers, skewed)
    dx, (dh0, dc0), grads = lstm_backward(gy, (gh, gc), cache)
    check_gradients(loss, {"x": x, "h0": h0, "c0": c0, **params},
                    {"x": dx, "h0": dh0, "c0": dc0, **grads}, max_entries=20)


@pytest.mark.parametrize("layers", [1, 2, 3])
def test_skew_dependency_structure(layers):
    """spec/layers.md §5.3: with skewed stacking y_t depends on x_0..x_{t-L+1} only (the first L-1 outputs on no
    input at all); one layer is the same as ordinary stacking."""
    params, x, s0, _, _ = _case(3, 2, 6, 3, 4, layers)
    y, _, _ = lstm_forward(x, s0, params, "lstm", layers, skewed=True)
    for s in range(6):
        x2 = x.copy()
        x2[:, s] += 1.0
        y2, _, _ = lstm_forward(x2, s0, params, "lstm", layers, skewed=True)
        changed = np.any(np.abs(y2 - y) > 0, axis=(0, 2))  # (T,)
        expect = np.arange(6) >= s + layers - 1
        np.testing.assert_array_equal(changed, expect)
    if layers == 1:
        y_plain, _, _ = lstm_forward(x, s0, params, "lstm", 1, skewed=False)
        assert_close(y, y_plain, **TOL_EXACT)


@given(seeds, sizes, sizes, sizes, sizes, sizes, st.booleans())
def test_step_api_equals_sequence(seed, batch, t_len, n_in, hid, layers, skewed):
    """spec/layers.md §5.4: stepping equals the sequence (forward), and the reverse loop over step caches equals
    the sequence backward; ordinary and skewed."""
    params, x, s0, gy, gs = _case(seed, batch, t_len, n_in, hid, layers)
    y, (h_n, c_n), cache = lstm_forward(x, s0, params, "lstm", layers, skewed)
    dx, (dh0, dc0), grads = lstm_backward(gy, gs, cache)
    state, caches, ys = s0, [], []
    for t in range(t_len):
        y_t, state, c = lstm_step_forward(x[:, t], state, params, "lstm", layers, skewed)
        ys.append(y_t)
        caches.append(c)
    assert_close(np.stack(ys, axis=1), y, **TOL_EXACT, name="y")
    assert_close(state[0], h_n, **TOL_EXACT, name="h_n")
    assert_close(state[1], c_n, **TOL_EXACT, name="c_n")
    dstate, acc, dxs = gs, None, []
    for t in range(t_len - 1, -1, -1):
        dx_t, dstate, acc = lstm_step_backward(gy[:, t], dstate, caches[t], accumulate_into=acc)
        dxs.append(dx_t)
    assert_close(np.stack(dxs[::-1], axis=1), dx, **TOL_EXACT, name="dx")
    assert_close(dstate[0], dh0, **TOL_EXACT, name="dh0")
    assert_close(dstate[1], dc0, **TOL_EXACT, name="dc0")
    _assert_grads(acc, grads, TOL_EXACT)


def _rollout(x0, s0, params, layers, skewed, t_len):
    """Output-feedback rollout x_{t+1} = y_t (input size == hidden size)."""
    x_t, state, ys, caches = x0, s0, [], []
    for _ in range(t_len):
        y_t, state, c = lstm_step_forward(x_t, state, params, "lstm", layers, skewed)
        ys.append(y_t)
        caches.append(c)
        x_t = y_t
    return np.stack(ys, axis=1), state, caches


def _rollout_backward(gy, gstate, caches):
    dstate, acc, dx_next = gstate, None, None
    for t in range(len(caches) - 1, -1, -1):
        dy_t = gy[:, t] if dx_next is None else gy[:, t] + dx_next
        dx_next, dstate, acc = lstm_step_backward(dy_t, dstate, caches[t], accumulate_into=acc)
    return dx_next, dstate, acc


@settings(max_examples=15)
@given(seeds, sizes, sizes, sizes, sizes, st.booleans())
def test_feedback_rollout_vjp(seed, batch, t_len, hid, layers, skewed):
    """spec/layers.md §5.4: gradients flow through fed-back outputs (acRNN's self-conditioned steps)."""
    params, x, (h0, c0), _, _ = _case(seed, batch, 1, hid, hid, layers)
    x0 = x[:, 0].copy()

    def fn():
        ys, (h, c), _ = _rollout(x0, (h0, c0), params, layers, skewed, t_len)
        return ys, h, c

    def vjp(douts):
        _, _, caches = _rollout(x0, (h0, c0), params, layers, skewed, t_len)
        dx0, (dh0, dc0), grads = _rollout_backward(douts[0], (douts[1], douts[2]), caches)
        return {"x0": dx0, "h0": dh0, "c0": dc0, **grads}

    check_vjp(fn, {"x0": x0, "h0": h0, "c0": c0, **params}, vjp)


@pytest.mark.parametrize("skewed", [False, True])
def test_feedback_rollout_central_differences(skewed):
    """spec/layers.md §5.4: rollout gradients against central differences."""
    layers, hid, t_len = 3, 3, 5
    params, x, (h0, c0), _, _ = _case(11, 2, 1, hid, hid, layers)
    x0 = x[:, 0].copy()
    rng = np.random.default_rng(12)
    gy, gh, gc = (rng.standard_normal((2, t_len, hid)), rng.standard_normal((layers, 2, hid)),
                  rng.standard_normal((layers, 2, hid)))

    def loss():
        ys, (h, c), _ = _rollout(x0, (h0, c0), params, layers, skewed, t_len)
        return float(np.sum(ys * gy) + np.sum(h * gh) + np.sum(c * gc))

    _, _, caches = _rollout(x0, (h0, c0), params, layers, skewed, t_len)
    dx0, (dh0, dc0), grads = _rollout_backward(gy, (gh, gc), caches)
    check_gradients(loss, {"x0": x0, "h0": h0, "c0": c0, **params},
                    {"x0": dx0, "h0": dh0, "c0": dc0, **grads}, max_entries=16)


def test_none_cotangents():
    """spec/layers.md §5: dy, the state cotangent tuple, or either of its entries may be None (zero)."""
    params, x, s0, gy, (gh, gc) = _case(3, 2, 3, 2, 3, 2)
    _, _, cache = lstm_forward(x, s0, params, "lstm", 2)
    ref = lstm_backward(gy, (np.zeros_like(gh), np.zeros_like(gc)), cache)
    for ds in (None, (None, None), (np.zeros_like(gh), None)):
        out = lstm_backward(gy, ds, cache)
        assert_close(out[0], ref[0], **TOL_EXACT)
        _assert_grads(out[2], ref[2], TOL_EXACT)
    out = lstm_backward(None, (gh, gc), cache)
    ref = lstm_backward(np.zeros_like(gy), (gh, gc), cache)
    assert_close(out[1][1], ref[1][1], **TOL_EXACT)
    _, _, c = lstm_step_forward(x[:, 0], s0, params, "lstm", 2)
    a = lstm_step_backward(None, None, c)
    assert np.all(a[0] == 0) and all(np.all(g == 0) for g in a[2].values())


@pytest.mark.parametrize("skewed", [False, True])
def test_float32_stays_float32(skewed):
    """spec/architecture.md dtype rule: float32 in -> float32 outputs and gradients, close to the float64 run."""
    p64, x64, (h64, c64), gy64, (gh64, gc64) = _case(9, 3, 5, 4, 6, 3)
    p32 = {k: v.astype(np.float32) for k, v in p64.items()}
    f32 = lambda a: a.astype(np.float32)  # noqa: E731
    y, (h_n, c_n), cache = lstm_forward(f32(x64), (f32(h64), f32(c64)), p32, "lstm", 3, skewed)
    dx, (dh0, dc0), grads = lstm_backward(f32(gy64), (f32(gh64), f32(gc64)), cache)
    assert {a.dtype for a in (y, h_n, c_n, dx, dh0, dc0)} == {np.dtype(np.float32)}
    assert all(g.dtype == np.float32 for g in grads.values())
    y64, _, cache64 = lstm_forward(x64, (h64, c64), p64, "lstm", 3, skewed)
    dx64, _, g64 = lstm_backward(gy64, (gh64, gc64), cache64)
    assert_close(y, y64, rtol=1e-4, atol=1e-5, name="y")
    assert_close(dx, dx64, rtol=1e-4, atol=1e-4, name="dx")
    for k in g64:
        assert_close(grads[k], g64[k], rtol=1e-4, atol=1e-4, name=k)
    y_t, (h1, c1), c = lstm_step_forward(f32(x64[:, 0]), (f32(h64), f32(c64)), p32, "lstm", 3, skewed)
    dx_t, (dh, dc), g_t = lstm_step_backward(y_t, (h1, c1), c)
    assert {a.dtype for a in (y_t, h1, c1, dx_t, dh, dc)} == {np.dtype(np.float32)}
    assert all(g.dtype == np.float32 for g in g_t.values())


def test_init_names_shapes_and_count():
    """spec/layers.md §5.1: PyTorch names/layouts, U(±1/sqrt(H)); the count formula reproduces acRNN's published
    5121 D + 20,996,096 parameters (3x1024 LSTM + decoder, D = 251 dual-quaternion features)."""
    p = lstm_init(np.random.default_rng(0), 5, 16, 3, "lstm")
    assert p["lstm.weight_ih_l0"].shape == (64, 5) and p["lstm.weight_ih_l2"].shape == (64, 16)
    assert p["lstm.weight_hh_l1"].shape == (64, 16) and p["lstm.bias_hh_l2"].shape == (64,)
    assert len(p) == 12 and max(np.abs(v).max() for v in p.values()) <= 0.25
    h, i = 16, 5
    assert count_parameters(p) == 4 * (h * i + h * h + 2 * h) + 2 * 4 * (2 * h * h + 2 * h)
    h, d = 1024, 251
    stack = 4 * (h * d + h * h + 2 * h) + 2 * 4 * (2 * h * h + 2 * h)
    head = h * d + d  # the 1024 -> D decoder
    assert stack + head == 5121 * d + 20_996_096 == 22_281_467


def test_rejects_bad_input():
    """spec/architecture.md: ValueError naming the argument and the expected and actual shape / dtype."""
    params, x, (h0, c0), _, _ = _case(1, 2, 3, 4, 5, 2)
    with pytest.raises(ValueError, match=r"state\[1\] \(c0\): expected shape \(2, 2, 5\), got \(1, 2, 5\)"):
        lstm_forward(x, (h0, c0[:1]), params, "lstm", 2)
    with pytest.raises(ValueError, match="state: expected a tuple"):
        lstm_forward(x, h0, params, "lstm", 2)
    with pytest.raises(ValueError, match=r"weight_ih_l1'\]: expected shape \(20, 5\), got \(20, 4\)"):
        lstm_forward(x, (h0, c0), {**params, "lstm.weight_ih_l1": np.zeros((20, 4))}, "lstm", 2)
    with pytest.raises(ValueError, match=r"weight_hh_l0'\]: expected shape \(4H, H\) = \(16, 4\), got \(20, 4\)"):
        lstm_forward(x, (h0, c0), {**params, "lstm.weight_hh_l0": np.zeros((20, 4))}, "lstm", 2)
    with pytest.raises(ValueError, match=r"lstm.weight_hh_l0'\]: expected dtype float32 \(the dtype of x\)"):
        lstm_forward(x.astype(np.float32), (h0.astype(np.float32), c0.astype(np.float32)), params, "lstm", 2)
    with pytest.raises(ValueError, match="missing parameter 'lstm.weight_ih_l2'"):
        lstm_forward(x, (np.zeros((3, 2, 5)), np.zeros((3, 2, 5))), params, "lstm", 3)
    with pytest.raises(ValueError, match=r"state\[0\] \(h0\): expected dtype float64"):
        lstm_forward(x, (h0.astype(np.float32), c0), params, "lstm", 2)
    with pytest.raises(ValueError, match="x: expected finite"):
        lstm_forward(np.full_like(x, np.inf), (h0, c0), params, "lstm", 2)
    with pytest.raises(ValueError, match="at least one time step"):
        lstm_forward(x[:, :0], (h0, c0), params, "lstm", 2)
    _, _, cache = lstm_forward(x, (h0, c0), params, "lstm", 2)
    with pytest.raises(ValueError, match=r"dstate_n\[0\] \(dh_n\): expected shape \(2, 2, 5\)"):
        lstm_backward(None, (np.zeros((1, 2, 5)), None), cache)


@pytest.mark.parametrize("step", [False, True])
def test_wrong_input_size_names_the_input(step):
    """spec/layers.md §5.5, spec/robustness.md B11: an input or state entry with the wrong feature size is reported
    on that argument (expected and actual shape, and where I / H come from), not as a wrong parameter shape."""
    params, x, (h0, c0), _, _ = _case(2, 2, 3, 4, 5, 2)
    fwd = lstm_step_forward if step else lstm_forward
    xn, hn, cn = ("x_t", "h", "c") if step else ("x", "h0", "c0")
    x = x[:, 0] if step else x
    lead, got = (r"\(\*, ", "2, ") if step else (r"\(\*, \*, ", "2, 3, ")
    with pytest.raises(ValueError, match=rf"^{xn}: expected shape {lead}4\), got \({got}5\); "
                                         r"I = 4 from params\['lstm.weight_ih_l0'\]"):
        fwd(np.concatenate([x, x[..., :1]], axis=-1), (h0, c0), params, "lstm", 2)
    with pytest.raises(ValueError, match=rf"^{xn}: expected shape {lead}4\), got \({got}3\)"):
        fwd(x[..., :3], (h0, c0), params, "lstm", 2)
    wide = lambda a: np.concatenate([a, a[..., :1]], axis=-1)  # noqa: E731
    with pytest.raises(ValueError, match=rf"^state\[0\] \({hn}\): expected shape \(2, 2, 5\), got \(2, 2, 6\); "
                                         r".*H = 5 from params\['lstm.weight_hh_l0'\]"):
        fwd(x, (wide(h0), c0), params, "lstm", 2)
    with pytest.raises(ValueError, match=rf"^state\[1\] \({cn}\): expected shape \(2, 2, 5\), got \(2, 2, 6\)"):
        fwd(x, (h0, wide(c0)), params, "lstm", 2)
    with pytest.raises(ValueError, match=rf"^state\[0\] \({hn}\): expected shape \(2, 2, 5\), got \(1, 2, 5\)"):
        fwd(x, (h0[:1], c0[:1]), params, "lstm", 2)
    with pytest.raises(ValueError, match=rf"^state\[1\] \({cn}\): expected finite"):
        fwd(x, (h0, np.full_like(c0, np.nan)), params, "lstm", 2)


def test_backwards_refuse_non_finite_cotangents():
    """spec/layers.md §5.5, spec/robustness.md B13: NaN/inf in dy, dh_n, dc_n (sequence) or dy, dh_new, dc_new
    (step) → ValueError naming the argument."""
    params, x, (h0, c0), gy, (gh, gc) = _case(3, 2, 3, 4, 5, 2)
    _, _, cache = lstm_forward(x, (h0, c0), params, "lstm", 2)
    _, _, step_cache = lstm_step_forward(x[:, 0], (h0, c0), params, "lstm", 2)
    for bad in (np.nan, np.inf, -np.inf):
        dy, dh, dc = gy.copy(), gh.copy(), gc.copy()
        dy[0, 1, 2] = bad
        dh[1, 1, 0] = bad
        dc[0, 0, 4] = bad
        with pytest.raises(ValueError, match=r"^dy: expected finite"):
            lstm_backward(dy, (gh, gc), cache)
        with pytest.raises(ValueError, match=r"^dstate_n\[0\] \(dh_n\): expected finite"):
            lstm_backward(gy, (dh, gc), cache)
        with pytest.raises(ValueError, match=r"^dstate_n\[1\] \(dc_n\): expected finite"):
            lstm_backward(None, (None, dc), cache)
        with pytest.raises(ValueError, match=r"^dy: expected finite"):
            lstm_step_backward(dy[:, 1], (gh, gc), step_cache)
        with pytest.raises(ValueError, match=r"^dstate_new\[0\] \(dh_new\): expected finite"):
            lstm_step_backward(gy[:, 0], (dh, None), step_cache)
        with pytest.raises(ValueError, match=r"^dstate_new\[1\] \(dc_new\): expected finite"):
            lstm_step_backward(None, (gh, dc), step_cache)
    with pytest.raises(ValueError, match=r"^dy: expected shape \(2, 5\), got \(2, 4\)"):
        lstm_step_backward(gy[:, 0, :4], None, step_cache)
