"""The fast training path of acRNN equals the step-by-step reference (spec/acrnn.md §2.1)."""
import numpy as np
import pytest

from refimpl.models import acrnn, acrnn_fast


@pytest.mark.parametrize("skewed", [False, True])
@pytest.mark.parametrize("F,H,L,B,T,gt,cond", [(7, 5, 3, 3, 23, 3, 2), (9, 6, 1, 2, 12, 5, 5), (5, 4, 2, 1, 3, 1, 1),
                                               (6, 3, 2, 2, 9, 4, 0)])
def test_fast_path_equals_the_reference(skewed, F, H, L, B, T, gt, cond):
    cfg = acrnn.ACRNNConfig(frame_size=F, hidden_size=H, num_layers=L, skewed=skewed, ground_truth_length=gt,
                            condition_length=cond)
    rng = np.random.default_rng(F * H + L)
    p = acrnn.init_params(cfg, rng)
    x = rng.standard_normal((B, T + 1, F))
    pred, cache = acrnn.sequence_forward(p, cfg, x)
    pred_f, cache_f = acrnn_fast.sequence_forward(p, cfg, x)
    np.testing.assert_allclose(pred_f, pred, rtol=0, atol=1e-10)
    d = rng.standard_normal(pred.shape)
    g = acrnn.sequence_backward(d, cache)
    g_f = acrnn_fast.sequence_backward(d, cache_f)
    assert set(g_f) == set(g)
    for k in g:
        np.testing.assert_allclose(g_f[k], g[k], rtol=0, atol=1e-10, err_msg=k)


def test_fast_path_with_an_explicit_mask_and_float32():
    cfg = acrnn.ACRNNConfig(frame_size=4, hidden_size=3, num_layers=2)
    rng = np.random.default_rng(1)
    p = acrnn.init_params(cfg, rng, np.float32)
    x = rng.standard_normal((2, 8, 4)).astype(np.float32)
    mask = np.array([1, 0, 0, 1, 1, 0, 1], bool)
    pred, cache = acrnn.sequence_forward(p, cfg, x, mask)
    pred_f, cache_f = acrnn_fast.sequence_forward(p, cfg, x, mask)
    assert pred_f.dtype == np.float32
    np.testing.assert_allclose(pred_f, pred, rtol=0, atol=1e-5)
    g, g_f = acrnn.sequence_backward(np.ones_like(pred), cache), acrnn_fast.sequence_backward(np.ones_like(pred), cache_f)
    for k in g:
        assert g_f[k].dtype == np.float32
        np.testing.assert_allclose(g_f[k], g[k], rtol=1e-4, atol=1e-5, err_msg=k)


def test_fast_loss_and_grads_equals_the_reference_for_dq_all():
    J, parents = 3, (-1, 0, 1)
    cfg = acrnn.config_for("dual_quaternions", J, hidden_size=5, num_layers=2, ground_truth_length=2,
                           condition_length=2)
    rng = np.random.default_rng(2)
    p = acrnn.init_params(cfg, rng)

    class Sk:
        pass

    sk = Sk()
    sk.parents, sk.offsets = parents, rng.standard_normal((J, 3))
    F = cfg.frame_size
    spec = acrnn.LossSpec.for_variant("dual_quaternions_all", rng.standard_normal(F), 0.5 + rng.random(F), sk)
    x = rng.standard_normal((2, 9, F))
    t, parts, g = acrnn.loss_and_grads(p, cfg, x, spec)
    t_f, parts_f, g_f = acrnn_fast.loss_and_grads(p, cfg, x, spec)
    assert abs(t - t_f) < 1e-10 and parts.keys() == parts_f.keys()
    for k in g:
        np.testing.assert_allclose(g_f[k], g[k], rtol=0, atol=1e-10, err_msg=k)


def test_fast_path_refuses_bad_inputs():
    cfg = acrnn.ACRNNConfig(frame_size=4, hidden_size=3, num_layers=1)
    p = acrnn.init_params(cfg, np.random.default_rng(0))
    with pytest.raises(ValueError, match="frames"):
        acrnn_fast.sequence_forward(p, cfg, np.zeros((2, 5, 3)))
    with pytest.raises(ValueError, match="mask"):
        acrnn_fast.sequence_forward(p, cfg, np.zeros((2, 5, 4)), np.zeros(4, bool))
    with pytest.raises(ValueError, match="decoder.bias"):
        acrnn_fast.sequence_forward({k: v for k, v in p.items() if k != "decoder.bias"}, cfg, np.zeros((2, 5, 4)))
