"""refimpl.arrays: the one home of the array checks (float_array, check_finite, finite_float, real_number,
gradient_array, shape_text)."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.arrays import check_finite, finite_float, float_array, gradient_array, real_number, shape_text


def test_shape_text():
    assert shape_text((..., None, 3)) == "(..., *, 3)"
    assert shape_text(()) == "()"
    assert shape_text((2, 4)) == "(2, 4)"


def test_check_finite_returns_the_array_and_refuses_nan_and_inf():
    a = np.ones((2, 3))
    assert check_finite(a, "a") is a
    for bad in (np.nan, np.inf, -np.inf):
        b = a.copy()
        b[1, 2] = bad
        with pytest.raises(ValueError, match=r"^b: expected finite values, got NaN or inf$"):
            check_finite(b, "b")


def test_finite_float():
    assert finite_float("2.5", "x") == 2.5 and finite_float(3, "x") == 3.0
    assert type(finite_float(np.float32(1.5), "x")) is float
    for bad in ("1e999", "nan", float("inf"), "abc", None, [1.0]):
        with pytest.raises(ValueError, match=r"^x: expected a finite number, got "):
            finite_float(bad, "x")


def test_float_array_casts_integers_and_booleans_and_keeps_floating_dtypes():
    assert float_array([1, 2], "x").dtype == np.float64
    assert float_array(np.array([True, False]), "x").dtype == np.float64
    assert float_array(np.ones(2, np.uint8), "x").dtype == np.float64
    f32 = np.ones(3, np.float32)
    assert float_array(f32, "x") is f32
    assert float_array(np.ones(3, np.float16), "x").dtype == np.float16


@pytest.mark.parametrize("bad", [np.ones(3, complex), np.array(["a", "b"]), np.array([None, 1.0], dtype=object)])
def test_float_array_refuses_what_is_not_real(bad):
    with pytest.raises(ValueError, match=r"^x: expected a real floating array, got dtype "):
        float_array(bad, "x")


def test_float_array_refuses_ragged_input_with_one_line():
    with pytest.raises(ValueError, match=r"^x: expected a real floating array, got list \("):
        float_array([[1.0, 2.0], [3.0]], "x")


def test_float_array_without_cast_takes_float32_and_float64_only():
    a = np.zeros((2, 3), np.float32)
    assert float_array(a, "x", (2, 3), cast=False) is a
    for bad in (np.zeros(3, np.int64), np.zeros(3, np.float16), np.zeros(3, bool)):
        with pytest.raises(ValueError, match=r"^x: expected a float32 or float64 array, got dtype "):
            float_array(bad, "x", cast=False)


def test_float_array_whole_shape():
    assert float_array(np.zeros((2, 3)), "x", (None, 3)).shape == (2, 3)
    assert float_array(np.zeros((5, 2, 3)), "x", (..., 3)).shape == (5, 2, 3)
    assert float_array(np.zeros(3), "x", (..., 3)).shape == (3,)
    assert float_array(np.float64(1.0), "x", ()).shape == ()
    with pytest.raises(ValueError, match=r"^x: expected shape \(\*, 3\), got \(2, 4\)$"):
        float_array(np.zeros((2, 4)), "x", (None, 3))
    with pytest.raises(ValueError, match=r"^x: expected shape \(\*, 3\), got \(3,\)$"):
        float_array(np.zeros(3), "x", (None, 3))
    with pytest.raises(ValueError, match=r"^x: expected shape \(\.\.\., 3, 3\), got \(3,\)$"):
        float_array(np.zeros(3), "x", (..., 3, 3))
    with pytest.raises(ValueError, match=r"^x: expected shape \(2\), got \(3,\); I = 2 from p$"):
        float_array(np.zeros(3), "x", (2,), context="I = 2 from p")


def test_float_array_last_axis_and_fewest_axes():
    assert float_array(np.zeros((2, 8)), "q", last=(4, 8)).shape == (2, 8)
    with pytest.raises(ValueError, match=r"^q: expected shape \(\.\.\., 4\) or \(\.\.\., 8\), got \(2, 3\)$"):
        float_array(np.zeros((2, 3)), "q", last=(4, 8))
    with pytest.raises(ValueError, match=r"^q: expected shape \(\.\.\., 4\) \(at least 1 dimension\(s\)\), got shape \(\)$"):
        float_array(np.float64(1.0), "q", last=4)
    with pytest.raises(ValueError, match=r"^q: expected shape \(\.\.\., 4\) \(at least 2 dimension\(s\)\), got shape \(4,\)$"):
        float_array(np.zeros(4), "q", last=4, min_ndim=2)
    with pytest.raises(ValueError, match=r"^x: expected at least 1 dimension\(s\), got shape \(\)$"):
        float_array(2.0, "x", min_ndim=1)


def test_float_array_finite_unless_told():
    a = np.array([1.0, np.inf])
    with pytest.raises(ValueError, match=r"^x: expected finite values, got NaN or inf$"):
        float_array(a, "x")
    assert float_array(a, "x", finite=False) is a
    with pytest.raises(ValueError, match=r"^x: expected finite values, got NaN or inf$"):
        float_array(np.array([np.nan], np.float32), "x", (1,), cast=False)


def test_real_number_intervals_and_types():
    assert real_number(3, "n") == 3.0 and type(real_number(np.float32(0.5), "n")) is float
    assert real_number(np.array(2.0), "n") == 2.0                        # a 0-d real array
    assert real_number(0.0, "eps", 0.0) == 0.0
    assert real_number(0.999, "b", 0.0, 1.0, high_open=True) == 0.999
    cases = [(lambda: real_number(0.0, "eps", 0.0, low_open=True), r"^eps: expected a finite number > 0.0, got 0.0$"),
             (lambda: real_number(-1e-9, "tol", 0.0), r"^tol: expected a finite number >= 0.0, got -1e-09$"),
             (lambda: real_number(1.0, "b", 0.0, 1.0, high_open=True), r"^b: expected a finite number in \[0.0, 1.0\), got 1.0$"),
             (lambda: real_number(2.0, "h", high=1.0), r"^h: expected a finite number <= 1.0, got 2.0$"),
             (lambda: real_number(float("nan"), "x"), r"^x: expected a finite number, got nan$"),
             (lambda: real_number(np.inf, "x", 0.0), r"^x: expected a finite number >= 0.0, got inf$"),
             (lambda: real_number(True, "x"), r"^x: expected a real number, got bool True$"),
             (lambda: real_number("1", "x"), r"^x: expected a real number, got str '1'$"),
             (lambda: real_number(np.array([1.0]), "x"), r"^x: expected a real number, got ndarray"),
             (lambda: real_number(1 + 2j, "x"), r"^x: expected a real number, got complex")]
    for call, message in cases:
        with pytest.raises(ValueError, match=message):
            call()


def test_gradient_array_shape_dtype_finite():
    g = np.ones((2, 4))
    assert gradient_array(g, (2, 4)) is g                                 # no copy
    assert gradient_array(np.ones((2, 4), np.int64), (2, 4)).dtype == np.int64
    with pytest.raises(ValueError, match=r"^dy: expected shape \(2, 4\), got \(4,\)$"):
        gradient_array(np.ones(4), (2, 4))
    with pytest.raises(ValueError, match=r"^dq: expected a real floating array, got dtype complex128$"):
        gradient_array(np.ones((2, 4), complex), (2, 4), "dq")
    bad = g.copy()
    bad[1, 3] = np.nan
    with pytest.raises(ValueError, match=r"^dy: expected finite values, got NaN or inf$"):
        gradient_array(bad, (2, 4))
