"""Tests of refimpl.nn.params: names, sub-dicts, gradient merging, counting, initialisers, boundary checks
(spec/layers.md §1)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.arrays import float_array
from refimpl.nn.params import (check_same_dtype, count_parameters, fan_in_bound, get_param,
                               init_normal, init_uniform, merge_grads, param_name, subdict)


def test_param_name_with_and_without_prefix():
    """spec/layers.md §1: "rnn" -> "rnn.weight_ih_l0"; the empty prefix means no dot."""
    assert param_name("rnn", "weight_ih_l0") == "rnn.weight_ih_l0"
    assert param_name("controls.fc1", "bias") == "controls.fc1.bias"
    assert param_name("", "weight") == "weight"


def test_subdict_strips_prefix_and_keeps_arrays():
    """spec/layers.md §1: subdict selects one layer's entries by prefix (exact dot boundary)."""
    a, b, c = np.zeros(2), np.ones(3), np.full(1, 2.0)
    p = {"rnn.weight_ih_l0": a, "rnn2.weight": b, "fc.weight": c}
    s = subdict(p, "rnn")
    assert list(s) == ["weight_ih_l0"] and s["weight_ih_l0"] is a
    assert subdict(p, "") == p and subdict(p, "") is not p


def test_merge_grads_sums_shared_keys_without_mutating_inputs():
    """spec/layers.md §1: a model's gradient is the union of its layers' dicts, summed where shared."""
    g1 = {"w": np.array([1.0, 2.0]), "a": np.array([5.0])}
    g2 = {"w": np.array([10.0, 20.0]), "b": np.array([7.0])}
    g3 = {"w": np.array([100.0, 200.0])}
    m = merge_grads(g1, g2, g3)
    np.testing.assert_array_equal(m["w"], [111.0, 222.0])
    np.testing.assert_array_equal(m["a"], [5.0])
    np.testing.assert_array_equal(m["b"], [7.0])
    np.testing.assert_array_equal(g1["w"], [1.0, 2.0])  # inputs untouched
    np.testing.assert_array_equal(g2["w"], [10.0, 20.0])
    assert merge_grads() == {}


def test_count_parameters_dict_and_iterable():
    """spec/layers.md §1: the number of scalars; QuaterNet's 2x1000 GRU on 128 inputs by the PyTorch formula."""
    p = {"a": np.zeros((3, 4)), "b": np.zeros(5)}
    assert count_parameters(p) == 17
    assert count_parameters(list(p.values())) == 17
    h, i = 1000, 128
    gru = 3 * (h * i + h * h + 2 * h) + 3 * (h * h + h * h + 2 * h)
    assert gru == 9_396_000
    head = 1000 * 128 + 128
    assert gru + head + 2 * h == 9_526_128  # with the learned h0 (2, 1, 1000): QuaterNet's "9.52 M"


@given(st.integers(1, 5000), st.sampled_from([np.float32, np.float64]), st.integers(0, 2**31 - 1))
def test_init_uniform_bound_and_dtype(fan_in, dtype, seed):
    """spec/layers.md §1: PyTorch's default U(-1/sqrt(fan_in), 1/sqrt(fan_in)), in the requested dtype."""
    rng = np.random.default_rng(seed)
    bound = fan_in_bound(fan_in)
    assert bound == pytest.approx(1 / np.sqrt(fan_in))
    w = init_uniform(rng, (7, 3), bound, dtype)
    assert w.dtype == dtype and w.shape == (7, 3)
    assert np.all(np.abs(w) <= bound)


def test_init_uniform_and_normal_statistics():
    """spec/layers.md §1: mean and spread of the initialisers (large sample)."""
    rng = np.random.default_rng(0)
    u = init_uniform(rng, (200_000,), 0.5)
    assert abs(u.mean()) < 0.01 and u.std() == pytest.approx(0.5 / np.sqrt(3), rel=0.02)
    n = init_normal(rng, (200_000,), 0.01, dtype=np.float32)
    assert n.dtype == np.float32
    assert abs(float(n.mean())) < 1e-4 and float(n.std()) == pytest.approx(0.01, rel=0.02)


def test_fan_in_bound_rejects_nonpositive():
    with pytest.raises(ValueError, match="fan_in"):
        fan_in_bound(0)


def test_float_array_without_cast_shapes_dtypes_and_finiteness():
    """spec/architecture.md: public boundaries raise ValueError naming the argument, expected and actual shape."""
    x = np.zeros((2, 3, 4))
    assert float_array(x, "x", (None, 3, 4), cast=False) is x
    assert float_array(x, "x", (..., 4), cast=False) is x
    assert float_array(np.zeros(4, np.float32), "x", (..., 4), cast=False).dtype == np.float32
    with pytest.raises(ValueError, match=r"x: expected shape \(\*, 5, 4\), got \(2, 3, 4\)"):
        float_array(x, "x", (None, 5, 4), cast=False)
    with pytest.raises(ValueError, match=r"expected shape \(\.\.\., 5\)"):
        float_array(x, "x", (..., 5), cast=False)
    with pytest.raises(ValueError, match="float32 or float64"):
        float_array(np.zeros((2, 3), int), "h0", (2, 3), cast=False)
    bad = x.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="x: expected finite"):
        float_array(bad, "x", (None, 3, 4), cast=False)
    float_array(bad, "x", (None, 3, 4), finite=False, cast=False)
    with pytest.raises(ValueError, match=r"^x: expected shape \(\*, 5, 4\), got \(2, 3, 4\); I = 5 from here$"):
        float_array(x, "x", (None, 5, 4), context="I = 5 from here", cast=False)
    assert float_array(np.float64(np.inf), "x", (), finite=False, cast=False).shape == ()
    with pytest.raises(ValueError, match="x: expected finite"):
        float_array(np.float64(np.inf), "x", (), cast=False)


def test_get_param_and_check_same_dtype():
    """spec/layers.md §1: missing or misshapen parameters are named by their full name."""
    p = {"fc.weight": np.zeros((3, 2)), "fc.bias": np.zeros(3, np.float32)}
    assert get_param(p, "fc", "weight", (3, 2)) is p["fc.weight"]
    with pytest.raises(ValueError, match="missing parameter 'fc.gain'"):
        get_param(p, "fc", "gain", (3,))
    with pytest.raises(ValueError, match=r"params\['fc.weight'\]: expected shape \(3, 5\), got \(3, 2\)"):
        get_param(p, "fc", "weight", (3, 5))
    with pytest.raises(ValueError, match="expected dtype float64"):
        get_param(p, "fc", "bias", (3,), np.float64)
    with pytest.raises(ValueError, match="fc.bias: expected dtype float64"):
        check_same_dtype(p["fc.weight"], "x", {"fc.bias": p["fc.bias"], "none": None})
