"""Tests of refimpl/models/_shared.py (parameter-dict validation, gradient accumulation)."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.models._shared import check_param_dict
from refimpl.nn.params import accumulate_grads


def test_check_param_dict():
    shapes = {"a.weight": (2, 3), "a.bias": (2,)}
    ok = {"a.weight": np.zeros((2, 3), np.float32), "a.bias": np.zeros(2, np.float32)}
    assert check_param_dict(ok, shapes) == np.float32
    with pytest.raises(ValueError, match="unexpected"):
        check_param_dict(dict(ok, b=np.zeros(1, np.float32)), shapes)
    with pytest.raises(ValueError, match="missing parameter 'a.bias'"):
        check_param_dict({"a.weight": ok["a.weight"]}, shapes)
    with pytest.raises(ValueError, match=r"params\['a.bias'\]: expected shape \(2,\)"):
        check_param_dict(dict(ok, **{"a.bias": np.zeros(3, np.float32)}), shapes)
    with pytest.raises(ValueError, match="like the other parameters"):
        check_param_dict(dict(ok, **{"a.bias": np.zeros(2)}), shapes)
    with pytest.raises(ValueError, match="float32 or float64"):
        check_param_dict({"a.weight": np.zeros((2, 3), int), "a.bias": np.zeros(2, int)}, shapes)


def test_accumulate_grads_copies_first_and_adds_in_place():
    g1 = {"w": np.ones(3)}
    total: dict = {}
    accumulate_grads(total, g1)
    assert total["w"] is not g1["w"]
    accumulate_grads(total, {"w": np.full(3, 2.0), "b": np.zeros(1)})
    np.testing.assert_array_equal(total["w"], [3.0, 3.0, 3.0])
    np.testing.assert_array_equal(g1["w"], [1.0, 1.0, 1.0])  # the first input is not modified
    assert set(total) == {"w", "b"}
