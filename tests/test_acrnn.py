"""acRNN (refimpl/models/acrnn.py) and the dual-quaternion output path (refimpl/dq_output.py); spec/acrnn.md."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given

from refimpl.dq_output import DQ_TERMS, dq_output_loss_backward, dq_output_loss_forward
from refimpl.dualquat import dq_from_quat_translation, dq_inv, dq_mul, dq_normalize, translation_from_dq
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.losses import WEIGHTS_ACRNN_DQ, mse_loss_forward
from refimpl.models import acrnn
from refimpl.protocols.synthesis import VARIANTS
from refimpl.nn.linear import linear_backward, linear_forward
from refimpl.nn.lstm import lstm_backward, lstm_forward
from refimpl.nn.params import count_parameters as count_arrays
from refimpl.quat import quat_normalize
from refimpl.representations import REPRESENTATIONS, frame_size
from refimpl.skeleton import Skeleton
from refimpl.strategies import unit_dual_quaternions

PARENTS = (-1, 0, 1, 1, 3)


def _skeleton(rng):
    return Skeleton(PARENTS, rng.standard_normal((len(PARENTS), 3)))


# ---------------------------------------------------------------------------------------------------------------
# parameter counts (Table 4)

def test_table4_parameter_counts_from_shapes():
    for rep, F, expected in acrnn.TABLE4_PARAMETERS:
        assert acrnn.count_parameters(acrnn.ACRNNConfig(frame_size=F)) == expected, rep
        assert expected == 5121 * F + 20_996_096  # 4H(F+H) + 8H + 2(8H² + 8H) + (H+1)F at H = 1024


def test_table4_frame_sizes_are_3_plus_DJ_for_cmu_except_positions():
    for rep, F, expected in acrnn.TABLE4_PARAMETERS:
        cfg = acrnn.config_for(rep, 31)
        if rep == "positions":
            # the paper's 114 = 38 CMU nodes × 3 (End Sites included); ours for 31 joints is 3 + 3·31 = 96
            assert cfg.frame_size == 96 and acrnn.count_parameters(cfg) == 5121 * 96 + 20_996_096
            assert acrnn.count_parameters(acrnn.config_for(rep, 37)) == expected  # 3 + 3·37 = 114
        else:
            assert cfg.frame_size == F and acrnn.count_parameters(cfg) == expected, rep


def test_one_allocation_at_paper_size_matches_table4():
    cfg = acrnn.ACRNNConfig(frame_size=251)
    params = acrnn.init_params(cfg, np.random.default_rng(0), np.float32)
    assert count_arrays(params) == 22_281_467
    assert {k: v.shape for k, v in params.items()} == acrnn.param_shapes(cfg)


# ---------------------------------------------------------------------------------------------------------------
# helpers: a small model and unit-DQ data

def _small(rep, rng, skewed=False, hidden=5, u=2, v=2, J=len(PARENTS)):
    cfg = acrnn.config_for(rep, J, hidden_size=hidden, ground_truth_length=u, condition_length=v, skewed=skewed)
    return cfg, acrnn.init_params(cfg, rng)


def _frames(rep, rng, B, T1, F, mean, std):
    """Standardised frames whose de-standardised rotation blocks are valid (unit quaternions / unit DQs)."""
    raw = rng.standard_normal((B, T1, F))
    D = REPRESENTATIONS[rep].dim
    J = (F - 3) // D
    blocks = raw[..., 3:].reshape(B, T1, J, D)
    if rep == "dual_quaternions":
        blocks = dq_normalize(blocks)
    elif rep.startswith("quaternions"):
        blocks[..., :4] = quat_normalize(blocks[..., :4])
    raw[..., 3:] = blocks.reshape(B, T1, J * D)
    return (raw - mean) / std


def _setup(variant, rng, skewed=False, weights=None):
    rep = VARIANTS[variant].representation
    skel = _skeleton(rng)
    cfg, params = _small(rep, rng, skewed)
    mean = 0.1 * rng.standard_normal(cfg.frame_size)
    std = 0.5 + rng.random(cfg.frame_size)
    spec = acrnn.LossSpec.for_variant(VARIANTS[variant], mean, std, skel, weights)
    frames = _frames(rep, rng, 2, 8, cfg.frame_size, mean, std)
    return cfg, params, spec, frames


# ---------------------------------------------------------------------------------------------------------------
# gradients through acRNN with auto-conditioning: three oracles

@pytest.mark.parametrize("skewed", [False, True])
@pytest.mark.parametrize("variant", ["dual_quaternions_all", "quaternions_fk", "ortho6d+positions"])
def test_gradients_central_differences(variant, skewed):
    rng = np.random.default_rng(1)
    cfg, params, spec, frames = _setup(variant, rng, skewed)
    total, parts, grads = acrnn.loss_and_grads(params, cfg, frames, spec)
    assert set(parts) == set(spec.weights)
    assert total == pytest.approx(sum(spec.weights[k] * parts[k] for k in parts))

    def f():
        return acrnn.loss_forward(acrnn.sequence_forward(params, cfg, frames)[0], frames[:, 1:], spec)[0]

    check_gradients(f, params, grads, max_entries=16, rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize("skewed", [False, True])
def test_sequence_backward_vjp_identity(skewed):
    rng = np.random.default_rng(2)
    cfg, params = _small("dual_quaternions", rng, skewed)
    frames = rng.standard_normal((3, 9, cfg.frame_size))
    _, cache = acrnn.sequence_forward(params, cfg, frames)
    check_vjp(lambda: acrnn.sequence_forward(params, cfg, frames)[0], params,
              lambda ws: acrnn.sequence_backward(ws[0], cache))


def _sig(a):
    return 1.0 / (1.0 + np.exp(-a))


def _rollout_naive(params, cfg, frames, mask):
    """Slow oracle: explicit per-gate LSTM equations, a Python loop over steps and layers."""
    B, T1, F = frames.shape
    L, H = cfg.num_layers, cfg.hidden_size
    h = np.zeros((L, B, H))
    c = np.zeros((L, B, H))
    out = np.zeros((B, T1 - 1, F))
    for t in range(T1 - 1):
        x = frames[:, t] if mask[t] else out[:, t - 1]
        h_old = h.copy()
        for k in range(L):
            inp = x if k == 0 else (h_old[k - 1] if cfg.skewed else h[k - 1])
            a = (inp @ params[f"lstm.weight_ih_l{k}"].T + params[f"lstm.bias_ih_l{k}"]
                 + h_old[k] @ params[f"lstm.weight_hh_l{k}"].T + params[f"lstm.bias_hh_l{k}"])
            i, f, g, o = _sig(a[:, :H]), _sig(a[:, H:2 * H]), np.tanh(a[:, 2 * H:3 * H]), _sig(a[:, 3 * H:])
            c[k] = f * c[k] + i * g
            h[k] = o * np.tanh(c[k])
        out[:, t] = h[-1] @ params["decoder.weight"].T + params["decoder.bias"]
    return out


@pytest.mark.parametrize("skewed", [False, True])
def test_sequence_forward_equals_slow_oracle(skewed):
    rng = np.random.default_rng(3)
    cfg, params = _small("quaternions", rng, skewed, u=3, v=2)
    frames = rng.standard_normal((2, 12, cfg.frame_size))
    pred, _ = acrnn.sequence_forward(params, cfg, frames)
    np.testing.assert_allclose(pred, _rollout_naive(params, cfg, frames, cfg.mask(11)), rtol=1e-12, atol=1e-13)


@pytest.mark.parametrize("skewed", [False, True])
def test_teacher_forced_backward_equals_sequence_kernels(skewed):
    """With condition_length 0 the rollout is an ordinary LSTM + linear: compare with lstm_forward/backward."""
    rng = np.random.default_rng(4)
    cfg, params = _small("ortho6d", rng, skewed, u=1, v=0)
    frames = rng.standard_normal((2, 7, cfg.frame_size))
    dpred = rng.standard_normal((2, 6, cfg.frame_size))
    pred, cache = acrnn.sequence_forward(params, cfg, frames)
    grads = acrnn.sequence_backward(dpred, cache)
    h0 = np.zeros((cfg.num_layers, 2, cfg.hidden_size))
    y, _, lc = lstm_forward(frames[:, :-1], (h0, h0.copy()), params, "lstm", cfg.num_layers, skewed)
    out, dc = linear_forward(y, params, "decoder")
    np.testing.assert_allclose(pred, out, rtol=1e-12, atol=1e-13)
    dy, g_dec = linear_backward(dpred, dc)
    _, _, g_lstm = lstm_backward(dy, None, lc)
    for k, v in {**g_lstm, **g_dec}.items():
        np.testing.assert_allclose(grads[k], v, rtol=1e-10, atol=1e-12, err_msg=k)


def test_auto_conditioning_feeds_own_output_and_gradient_flows_through_it():
    rng = np.random.default_rng(5)
    cfg, params = _small("quaternions", rng, u=2, v=3)
    frames = rng.standard_normal((1, 11, cfg.frame_size))
    changed = frames.copy()
    changed[:, 3] += 1.0  # step 3 is an own-output step (mask 1,1,0,0,0,1,1,...): its GT frame is never read
    assert list(cfg.mask(10)) == [True, True, False, False, False, True, True, False, False, False]
    np.testing.assert_array_equal(acrnn.sequence_forward(params, cfg, frames)[0],
                                  acrnn.sequence_forward(params, cfg, changed)[0])


def test_step_and_generate_agree_with_the_rollout():
    rng = np.random.default_rng(6)
    cfg, params = _small("dual_quaternions", rng, skewed=True)
    seed = rng.standard_normal((2, 4, cfg.frame_size))
    gen = acrnn.generate(params, cfg, seed, 5)
    state = acrnn.init_state(cfg, 2)
    for t in range(4):
        y, state = acrnn.step(params, cfg, seed[:, t], state)
    outs = [y]
    for _ in range(4):
        y, state = acrnn.step(params, cfg, y, state)
        outs.append(y)
    np.testing.assert_allclose(gen, np.stack(outs, axis=1), rtol=1e-13, atol=1e-14)
    # the same through the training rollout: 4 ground-truth steps, then own outputs
    frames = np.concatenate([seed, np.zeros((2, 5, cfg.frame_size))], axis=1)
    pred, _ = acrnn.sequence_forward(params, cfg, frames, mask=np.arange(8) < 4)
    np.testing.assert_allclose(pred[:, 3:], gen[:, :5], rtol=1e-13, atol=1e-14)


def test_float32_rollout_stays_float32():
    rng = np.random.default_rng(7)
    cfg = acrnn.ACRNNConfig(frame_size=11, hidden_size=4)
    params = acrnn.init_params(cfg, rng, np.float32)
    pred, cache = acrnn.sequence_forward(params, cfg, rng.standard_normal((2, 6, 11)).astype(np.float32))
    assert pred.dtype == np.float32
    assert all(g.dtype == np.float32 for g in acrnn.sequence_backward(np.ones_like(pred), cache).values())


# ---------------------------------------------------------------------------------------------------------------
# loss composition

def test_every_table1_variant_trains_with_one_option():
    rng = np.random.default_rng(8)
    expected = {"positions", "euler", "quaternions", "quaternions_fk", "quaternions+positions", "ortho6d",
                "ortho6d+positions", "dual_quaternions", "dual_quaternions_all", "positions_acrnn"}
    assert set(VARIANTS) == expected
    for name in expected:
        cfg, params, spec, frames = _setup(name, rng)
        total, parts, grads = acrnn.loss_and_grads(params, cfg, frames, spec)
        assert np.isfinite(total) and set(grads) == set(params)
        assert set(parts) == set(VARIANTS[name].weights)


def test_variant_weights_follow_appendix_b():
    assert VARIANTS["dual_quaternions_all"].weights == {"mse": 1.0, **DQ_TERMS}
    assert DQ_TERMS == {"reg": 0.01, "pos": 1 / 3, "offset": 1 / 3, "quat": 1.0}
    assert dict(WEIGHTS_ACRNN_DQ) == {"mse": 1.0, **DQ_TERMS}
    assert VARIANTS["quaternions_fk"].weights == {"mse": 1.0, "quat": 1.0, "fk": 0.25}
    for name in ("positions", "quaternions", "ortho6d", "dual_quaternions", "quaternions+positions"):
        assert VARIANTS[name].weights == {"mse": 1.0}


def test_mse_only_loss_is_mse_of_standardised_frames():
    rng = np.random.default_rng(9)
    cfg, params, spec, frames = _setup("ortho6d", rng)
    pred = rng.standard_normal(frames[:, 1:].shape)
    assert acrnn.loss_forward(pred, frames[:, 1:], spec)[0] == mse_loss_forward(pred, frames[:, 1:])[0]


@pytest.mark.parametrize("weights", [{"pos": 1.0}, {"pos": 1.0, "offset": 1.0}, {"offset": 0.5, "quat": 2.0},
                                     {"reg": 1.0}, {"quat_current": 1.0, "mse": 0.3}])
def test_dq_ablation_combinations_have_exact_gradients(weights):
    rng = np.random.default_rng(10)
    cfg, params, spec, frames = _setup("dual_quaternions_all", rng, weights=weights)
    pred = rng.standard_normal(frames[:, 1:].shape)
    total, parts, cache = acrnn.loss_forward(pred, frames[:, 1:], spec)
    assert set(parts) == set(weights)
    check_gradients(lambda: acrnn.loss_forward(pred, frames[:, 1:], spec)[0], {"pred": pred},
                    {"pred": acrnn.loss_backward(1.0, cache)}, max_entries=40)


def test_loss_spec_rejects_terms_of_another_representation():
    rng = np.random.default_rng(11)
    skel = _skeleton(rng)
    F = frame_size("ortho6d", len(PARENTS))
    with pytest.raises(ValueError, match="weights"):
        acrnn.LossSpec("ortho6d", {"mse": 1.0, "pos": 1.0}, np.zeros(F), np.ones(F), skel.parents)
    with pytest.raises(ValueError, match="mean, std"):
        acrnn.LossSpec("ortho6d", {"mse": 1.0}, np.zeros(F + 1), np.ones(F + 1))
    with pytest.raises(ValueError, match="offsets"):
        acrnn.LossSpec("quaternions", {"fk": 1.0}, np.zeros(23), np.ones(23), PARENTS)


def test_config_and_input_validation():
    with pytest.raises(ValueError, match="hidden_size"):
        acrnn.ACRNNConfig(hidden_size=0)
    rng = np.random.default_rng(12)
    cfg, params = _small("ortho6d", rng)
    with pytest.raises(ValueError, match="frames"):
        acrnn.sequence_forward(params, cfg, np.zeros((2, 5, cfg.frame_size + 1)))
    with pytest.raises(ValueError, match="mask"):
        acrnn.sequence_forward(params, cfg, np.zeros((2, 5, cfg.frame_size)), mask=np.zeros(4, bool))
    with pytest.raises(ValueError, match="decoder.bias"):
        acrnn.step({k: v for k, v in params.items() if k != "decoder.bias"}, cfg, np.zeros((1, cfg.frame_size)),
                   acrnn.init_state(cfg, 1))
    assert acrnn.ACRNNConfig(**cfg.to_dict()) == cfg


# ---------------------------------------------------------------------------------------------------------------
# the dual-quaternion output path (refimpl/dq_output.py)

def _unit_dq(rng, shape):
    return dq_normalize(rng.standard_normal(shape + (8,)))


ALL_DQ = {"reg": 0.01, "pos": 1 / 3, "offset": 1 / 3, "quat": 1.0, "quat_current": 0.5}


def test_dq_output_path_central_differences_and_vjp():
    rng = np.random.default_rng(13)
    raw = rng.standard_normal((2, 3, len(PARENTS), 8))
    target = _unit_dq(rng, raw.shape[:-1])
    _, _, cache = dq_output_loss_forward(raw, target, PARENTS, ALL_DQ)
    g = dq_output_loss_backward(1.0, cache)
    check_gradients(lambda: dq_output_loss_forward(raw, target, PARENTS, ALL_DQ)[0], {"raw": raw}, {"raw": g},
                    max_entries=None)
    check_vjp(lambda: np.array(dq_output_loss_forward(raw, target, PARENTS, ALL_DQ)[0]), {"raw": raw},
              lambda ws: {"raw": dq_output_loss_backward(float(ws[0]), cache)})


def _dq_path_naive(raw, target, parents):
    """Slow oracle: per frame, per joint, with the scalar dual-quaternion algebra of refimpl.dualquat."""
    lead = raw.shape[:-2]
    J = raw.shape[-2]
    reg = pos = off = quat = quat_cur = 0.0
    n = 0
    ident = np.array([1.0, 0, 0, 0, 0, 0, 0, 0])
    for idx in np.ndindex(*lead):
        for j in range(J):
            r = raw[idx + (j,)]
            reg += (r[:4] @ r[:4] - 1) ** 2 + (r[:4] @ r[4:]) ** 2
            u, t = dq_normalize(r), target[idx + (j,)]
            pos += np.linalg.norm(translation_from_dq(u) - translation_from_dq(t))
            pu = ident if parents[j] < 0 else dq_normalize(raw[idx + (parents[j],)])
            pt = ident if parents[j] < 0 else target[idx + (parents[j],)]
            lu, lt = dq_mul(dq_inv(pu), u), dq_mul(dq_inv(pt), t)
            if parents[j] >= 0:  # the root's offset is 0 by definition (offsets_from_current_dq)
                off += np.linalg.norm(translation_from_dq(lu) - translation_from_dq(lt))
            quat += abs(1 - quat_normalize(lu[:4]) @ quat_normalize(lt[:4]))
            quat_cur += abs(1 - u[:4] @ t[:4])
            n += 1
    return {"reg": reg / n, "pos": pos / n, "offset": off / n, "quat": quat / n, "quat_current": quat_cur / n}


def test_dq_output_path_equals_slow_loop_oracle():
    rng = np.random.default_rng(14)
    raw = rng.standard_normal((2, 2, len(PARENTS), 8))
    target = _unit_dq(rng, raw.shape[:-1])
    total, parts, _ = dq_output_loss_forward(raw, target, PARENTS, ALL_DQ)
    naive = _dq_path_naive(raw, target, PARENTS)
    for k in ALL_DQ:
        assert parts[k] == pytest.approx(naive[k], rel=1e-12, abs=1e-14), k
    assert total == pytest.approx(sum(ALL_DQ[k] * naive[k] for k in ALL_DQ), rel=1e-12)


def test_l_reg_is_exactly_zero_on_unit_dual_quaternions():
    # exactly representable unit rotations and dyadic translations: every product is exact
    q = np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0.5, 0.5, 0.5, 0.5], [0.5, -0.5, 0.5, -0.5], [0, 0, 0, -1]], float)
    t = np.array([[0.25, -1.5, 2.0], [0, 0, 0], [3.0, 0.5, -0.125], [1, 2, 4], [-8, 0.75, 0]], float)
    dq = dq_from_quat_translation(q, t)
    value, _, cache = dq_output_loss_forward(dq, dq, PARENTS, {"reg": 1.0})
    assert value == 0.0
    assert np.all(dq_output_loss_backward(1.0, cache) == 0.0)
    # normalised random DQs: zero up to rounding
    u = _unit_dq(np.random.default_rng(15), (50, len(PARENTS)))
    assert dq_output_loss_forward(u, u, PARENTS, {"reg": 1.0})[0] < 1e-29


def test_dq_geometric_losses_vanish_at_the_target_up_to_scale():
    """The Eq. 13 normalisation makes the geometric losses blind to a positive scale of the raw output."""
    rng = np.random.default_rng(16)
    target = _unit_dq(rng, (3, len(PARENTS)))
    geometric = {"pos": 1.0, "offset": 1.0, "quat": 1.0, "quat_current": 1.0}
    total, parts, _ = dq_output_loss_forward(2.5 * target, target, PARENTS, geometric)
    assert total < 1e-13
    assert dq_output_loss_forward(2.5 * target, target, PARENTS, {"reg": 1.0})[0] > 1.0


def test_dq_output_rejects_unknown_terms_and_shapes():
    x = np.zeros((2, len(PARENTS), 8))
    with pytest.raises(ValueError, match="unknown loss"):
        dq_output_loss_forward(x, x, PARENTS, {"mse": 1.0})
    with pytest.raises(ValueError, match="raw, target"):
        dq_output_loss_forward(x, x[..., :4], PARENTS, DQ_TERMS)


@pytest.mark.parametrize("rep", ["quaternions", "quaternions+positions"])
def test_quaternion_terms_have_exact_gradients(rep):
    rng = np.random.default_rng(17)
    skel = _skeleton(rng)
    F = frame_size(rep, len(PARENTS))
    mean, std = 0.1 * rng.standard_normal(F), 0.5 + rng.random(F)
    spec = acrnn.LossSpec(rep, {"mse": 0.5, "quat": 1.0, "fk": 0.25, "reg": 0.01}, mean, std, skel.parents,
                          skel.offsets)
    target = _frames(rep, rng, 2, 3, F, mean, std)
    pred = rng.standard_normal(target.shape)
    total, parts, cache = acrnn.loss_forward(pred, target, spec)
    assert set(parts) == {"mse", "quat", "fk", "reg"}
    check_gradients(lambda: acrnn.loss_forward(pred, target, spec)[0], {"pred": pred},
                    {"pred": acrnn.loss_backward(1.0, cache)}, max_entries=60)
    # at the target the geometric terms vanish
    _, at_target, _ = acrnn.loss_forward(target, target, spec)
    assert max(at_target.values()) < 1e-12


@given(unit_dual_quaternions((3, len(PARENTS))))
def test_l_reg_vanishes_on_random_unit_dual_quaternions(dq):
    assert dq_output_loss_forward(dq, dq, PARENTS, {"reg": 1.0})[0] < 1e-24
