"""Pace network (spec/locomotion.md §4): parameter counts, the three gradient oracles, online step, inference."""
import numpy as np
import pytest

from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.models import pace
from refimpl.splines import circle_path, line_with_turn_path
from refimpl.testing import assert_close

SMALL = {"bi": pace.PaceConfig(bidirectional=True, hidden_size=3),
         "delayed": pace.PaceConfig(bidirectional=False, hidden_size=3, delay=2)}


def _setup(config, seed=0, batch=2, n=4):
    rng = np.random.default_rng(seed)
    params = pace.init_params(config, rng)
    params = {k: v + 0.3 * rng.standard_normal(v.shape) for k, v in params.items()}  # eos, h0 away from 0
    x = rng.standard_normal((batch, n, config.input_size))
    return params, x


def test_parameter_counts_match_the_paper():
    bi, delayed = pace.PaceConfig(), pace.PaceConfig(bidirectional=False)
    assert pace.count_parameters(bi) == 6424
    assert pace.count_parameters(delayed) == 3216
    for cfg in (bi, delayed):
        p = pace.init_params(cfg, np.random.default_rng(0))
        assert sum(v.size for v in p.values()) == pace.count_parameters(cfg)
        assert {k: v.shape for k, v in p.items()} == pace.param_shapes(cfg)
    assert pace.param_shapes(bi)["fc.weight"] == (4, 60) and pace.param_shapes(bi)["h0"] == (2, 1, 30)
    assert pace.param_shapes(delayed)["eos"] == (2,) and pace.param_shapes(delayed)["fc.weight"] == (4, 30)
    p = pace.init_params(delayed, np.random.default_rng(0))
    assert np.all(p["eos"] == 0) and abs(p["h0"].std() - 0.01) < 0.01


@pytest.mark.parametrize("variant", ["bi", "delayed"])
def test_backward_matches_central_differences(variant):
    cfg = SMALL[variant]
    params, x = _setup(cfg)
    target = np.random.default_rng(5).standard_normal((2, 4, 4))
    arrays = dict(params, x=x)

    def f():
        y, _ = pace.forward(params, cfg, arrays["x"])
        return pace.loss_forward(y, target)[0]

    y, cache = pace.forward(params, cfg, x)
    _, lcache = pace.loss_forward(y, target)
    dx, grads = pace.backward(pace.loss_backward(1.0, lcache), cache)
    check_gradients(f, arrays, dict(grads, x=dx), max_entries=None, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("variant", ["bi", "delayed"])
def test_vector_jacobian_identity(variant):
    cfg = SMALL[variant]
    params, x = _setup(cfg, seed=3, batch=3, n=5)
    arrays = dict(params, x=x)

    def vjp(ws):
        _, cache = pace.forward(params, cfg, arrays["x"])
        dx, g = pace.backward(ws[0], cache)
        return dict(g, x=dx)

    check_vjp(lambda: pace.forward(params, cfg, arrays["x"])[0], arrays, vjp)


@pytest.mark.parametrize("variant", ["bi", "delayed"])
def test_matches_the_slow_loop_oracle(variant):
    cfg = SMALL[variant]
    params, x = _setup(cfg, seed=7, batch=2, n=6)
    y, cache = pace.forward(params, cfg, x)
    assert_close(y, pace._forward_naive(params, cfg, x), rtol=1e-12, atol=1e-13)
    dy = np.random.default_rng(8).standard_normal(y.shape)
    dx, grads = pace.backward(dy, cache)
    dx_n, grads_n = pace._backward_naive(dy, params, cfg, x)
    assert_close(dx, dx_n, rtol=1e-11, atol=1e-12)
    assert set(grads) == set(pace.param_shapes(cfg)) == set(grads_n)
    for k in grads:
        assert_close(grads[k], grads_n[k], rtol=1e-11, atol=1e-12)


def test_delayed_step_by_step_equals_the_sequence():
    cfg = pace.PaceConfig(bidirectional=False, hidden_size=5, delay=4)
    params, x = _setup(cfg, seed=2, batch=3, n=7)
    y, _ = pace.forward(params, cfg, x)
    h = pace.init_state(params, cfg, 3)
    outs = []
    for t in range(7 + cfg.delay):
        o, h = pace.delayed_step(params, cfg, x[:, t] if t < 7 else None, h)
        outs.append(o)
    assert_close(np.stack(outs, axis=1)[:, cfg.delay:], y, rtol=1e-12, atol=1e-13)
    # the output for point t has not seen inputs after t + D
    x2 = x.copy()
    x2[:, 6] += 1.0
    y2, _ = pace.forward(params, cfg, x2)
    assert np.array_equal(y2[:, :6 - cfg.delay], y[:, :6 - cfg.delay])
    assert not np.allclose(y2[:, 6 - cfg.delay], y[:, 6 - cfg.delay])


def test_bidirectional_output_depends_on_the_future():
    cfg = SMALL["bi"]
    params, x = _setup(cfg)
    y, _ = pace.forward(params, cfg, x)
    x2 = x.copy()
    x2[:, -1] += 1.0
    assert not np.allclose(pace.forward(params, cfg, x2)[0][:, 0], y[:, 0])


def test_l1_loss_value():
    pred = np.array([[[1.0, -2.0, 0.5, 0.0]]])
    target = np.zeros((1, 1, 4))
    v, c = pace.loss_forward(pred, target)
    assert v == pytest.approx(3.5 / 4)
    assert_close(pace.loss_backward(1.0, c), np.sign(pred) / 4)


def test_facing_is_the_tangent_rotated_by_delta():
    t = np.array([[1.0, 0.0], [0.0, 1.0]])
    d = np.array([[0.0, 2.0], [np.cos(0.3), np.sin(0.3)]])  # +90° (unnormalised), +0.3 rad
    f = pace.facing_from_outputs(t, d)
    assert_close(f, [[0.0, 1.0], [-np.sin(0.3), np.cos(0.3)]], atol=1e-8)


def test_predict_clips_and_returns_unit_facing():
    cfg = pace.PaceConfig()
    params = pace.init_params(cfg, np.random.default_rng(0))
    params["fc.bias"][:] = [-5.0, -5.0, 0.0, 1.0]  # negative amplitude/frequency before clipping; Δ ≈ 90°
    sp = pace.predict(params, cfg, line_with_turn_path(10, 90, 5, 10), average_speed=0.5)
    assert np.all(sp.track("amplitude") >= pace.MIN_AMPLITUDE) and np.all(sp.track("frequency") >= 0)
    f = sp.track("direction")
    assert_close(np.linalg.norm(f, axis=-1), np.ones(sp.num_points), atol=1e-6)
    t = sp.track("tangent")
    cross = t[:, 0] * f[:, 1] - t[:, 1] * f[:, 0]
    assert np.all(cross > 0.9)  # facing ≈ tangent rotated +90°
    sp2 = pace.predict(params, cfg, circle_path(10), 1.0)
    assert sp2.closed and sp2.num_points == int(np.ceil(2 * np.pi * 10 * 5))  # 5 points per unit


def test_errors():
    cfg = pace.PaceConfig()
    p = pace.init_params(cfg, np.random.default_rng(0))
    with pytest.raises(ValueError, match="x"):
        pace.forward(p, cfg, np.zeros((1, 3, 3)))
    with pytest.raises(ValueError, match="dtype"):
        pace.forward(p, cfg, np.zeros((1, 3, 2), np.float32))
    with pytest.raises(ValueError, match="missing"):
        pace.forward({k: v for k, v in p.items() if k != "fc.bias"}, cfg, np.zeros((1, 3, 2)))
    with pytest.raises(ValueError, match="delayed"):
        pace.init_state(p, cfg, 1)
    with pytest.raises(ValueError):
        pace.PaceConfig(hidden_size=0)
