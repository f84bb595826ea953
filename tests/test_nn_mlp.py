"""Tests of refimpl.nn.mlp (dense layers with LeakyReLU; QTG's encoder and decoder) and accumulate_grads."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.gradcheck import check_gradients
from refimpl.nn.mlp import mlp_backward, mlp_forward, mlp_init
from refimpl.nn.params import accumulate_grads
from refimpl.testing import TOL_GOLDEN, assert_close

from conftest import load_golden


def test_mlp_matches_pytorch_golden():
    """spec/layers.md §2-§3 vs PyTorch: leaky_relu(fc2(leaky_relu(fc1(x), 0.05)), 0.05), outputs and all grads."""
    g = load_golden("mlp_leaky005.npz")
    params = {f"m.{i}.{w}": g[f"param.fc{i + 1}.{w}"] for i in range(2) for w in ("weight", "bias")}
    y, cache = mlp_forward(g["in.x"], params, "m", 2, slope=0.05)
    assert_close(y, g["out.y"], **TOL_GOLDEN, name="y")
    dx, grads = mlp_backward(g["in.gy"], cache)
    assert_close(dx, g["grad.x"], **TOL_GOLDEN, name="grad.x")
    assert sorted(grads) == sorted(params)
    for i in range(2):
        for w in ("weight", "bias"):
            assert_close(grads[f"m.{i}.{w}"], g[f"grad.fc{i + 1}.{w}"], **TOL_GOLDEN, name=f"m.{i}.{w}")


@pytest.mark.parametrize("last_linear", [False, True])
def test_mlp_gradients_and_shapes(last_linear):
    """Central differences on every parameter and the input; the last layer linear or not."""
    rng = np.random.default_rng(0)
    params = mlp_init(rng, (4, 6, 3), "enc")
    assert {k: v.shape for k, v in params.items()} == {"enc.0.weight": (6, 4), "enc.0.bias": (6,),
                                                      "enc.1.weight": (3, 6), "enc.1.bias": (3,)}
    x = rng.standard_normal((2, 5, 4))
    gy = rng.standard_normal((2, 5, 3))
    y, cache = mlp_forward(x, params, "enc", 2, slope=0.2, last_linear=last_linear)
    assert y.shape == (2, 5, 3)
    dx, grads = mlp_backward(gy, cache)
    check_gradients(lambda: float(np.sum(mlp_forward(x, params, "enc", 2, 0.2, last_linear)[0] * gy)),
                    {"x": x, **params}, {"x": dx, **grads}, max_entries=None)


def test_mlp_init_refuses_bad_sizes():
    with pytest.raises(ValueError, match="sizes"):
        mlp_init(np.random.default_rng(0), (4,), "m")


def test_accumulate_grads_copies_then_adds():
    a = np.ones(3)
    total = accumulate_grads({}, {"w": a})
    assert total["w"] is not a and np.array_equal(total["w"], a)
    accumulate_grads(total, {"w": 2 * a, "b": np.zeros(1)})
    assert np.array_equal(total["w"], 3 * a) and np.array_equal(a, np.ones(3)) and "b" in total
