"""The array checks of every public boundary (layer 0: the math, kinematics, data, layers, models and protocols all
use these, and ``deploy`` through them).

* :func:`float_array` — an argument as a real floating ndarray of an expected shape (a whole shape, the sizes the
  last axis may take, or a fewest number of axes), finite unless told otherwise;
* :func:`check_finite` — refuse NaN and inf;
* :func:`finite_float` — a scalar as a finite Python float (also the strict JSON readers' number hook);
* :func:`real_number` — a numeric argument (tolerance, step size, rate) as a finite float in an interval;
* :func:`gradient_array` — the upstream gradient of a backward pass: finite, real, exactly the output's shape;
* :func:`shape_text` — an expected shape as the messages print it, ``(..., *, 3)``.

Every refusal is one ``ValueError`` line that starts with the argument's name: ``"q: expected shape (..., 4), got
(3,)"``, ``"x: expected a float32 or float64 array, got dtype int64"``, ``"pred: expected finite values, got NaN or inf"``.

Shape legend: ``...`` any number (zero or more) of leading axes, ``*`` (``None`` in a shape) any size of one axis.
"""
from __future__ import annotations

import math
import numbers

import numpy as np

__all__ = ["float_array", "check_finite", "finite_float", "real_number", "gradient_array", "shape_text"]

_FLOAT_DTYPES = (np.dtype(np.float32), np.dtype(np.float64))


def shape_text(shape) -> str:
    """An expected shape as error messages print it.

    Parameters
    ----------
    shape : tuple
        Sizes (int), ``None`` for any size, a leading ``...`` for any leading axes.

    Returns
    -------
    str
        e.g. ``"(..., *, 3)"`` for ``(..., None, 3)``, ``"()"`` for ``()``.
    """
    return "(" + ", ".join("..." if s is Ellipsis else ("*" if s is None else str(s)) for s in shape) + ")"


def check_finite(a: np.ndarray, name: str) -> np.ndarray:
    """Refuse NaN and inf.

    Parameters
    ----------
    a : ndarray
        Any shape, a numeric dtype.
    name : str
        The argument's name, first word of the message.

    Returns
    -------
    ndarray
        ``a`` itself.

    Raises
    ------
    ValueError
        ``"<name>: expected finite values, got NaN or inf"`` when an entry is not finite.
    """
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: expected finite values, got NaN or inf")
    return a


def finite_float(x, name: str) -> float:
    """A scalar (a number or its text) as a finite Python float.

    Parameters
    ----------
    x : real number or str
        ``float(x)`` must succeed.
    name : str
        The argument's name, first word of the message.

    Returns
    -------
    float

    Raises
    ------
    ValueError
        ``"<name>: expected a finite number, got ..."`` for NaN, inf, a text that overflows a float (``"1e999"``) or
        anything ``float`` refuses.
    """
    try:
        v = float(x)
    except (TypeError, ValueError, OverflowError):
        v = math.nan
    if not math.isfinite(v):
        raise ValueError(f"{name}: expected a finite number, got {x!r:.60}")
    return v


def real_number(x, name: str, low: float = -math.inf, high: float = math.inf, *, low_open: bool = False,
                high_open: bool = False) -> float:
    """A numeric argument (a tolerance, a step size, a rate) as a finite Python float in an interval.

    Parameters
    ----------
    x : int, float, NumPy integer or floating scalar, or a 0-d real array
        Not a bool, not a text.
    name : str
        The argument's name, first word of the message.
    low, high : float
        The interval's ends (default: the whole real line).
    low_open, high_open : bool
        Whether an end is excluded.

    Returns
    -------
    float
        ``x`` as a Python float, inside the interval.

    Raises
    ------
    ValueError
        ``"<name>: expected a real number, got str '1'"`` for another type; ``"<name>: expected a finite number
        >= 0.0, got nan"`` (the interval as ``>= a``, ``> a``, ``in [a, b)``, ...) for NaN, inf or a value outside.
    """
    if isinstance(x, np.ndarray) and x.ndim == 0 and x.dtype.kind in "iuf":
        x = x.item()
    if isinstance(x, (bool, np.bool_)) or not isinstance(x, (numbers.Real, np.integer, np.floating)):
        raise ValueError(f"{name}: expected a real number, got {type(x).__name__} {x!r:.60}")
    v = float(x)
    inside = (v > low if low_open else v >= low) and (v < high if high_open else v <= high)
    if not (math.isfinite(v) and inside):
        raise ValueError(f"{name}: expected a finite number{_interval_text(low, high, low_open, high_open)}, got {v!r}")
    return v


def _interval_text(low: float, high: float, low_open: bool, high_open: bool) -> str:
    if math.isinf(high) and math.isinf(low):
        return ""
    if math.isinf(high):
        return f" {'>' if low_open else '>='} {low}"
    if math.isinf(low):
        return f" {'<' if high_open else '<='} {high}"
    return f" in {'(' if low_open else '['}{low}, {high}{')' if high_open else ']'}"


def gradient_array(dy, shape: tuple, name: str = "dy") -> np.ndarray:
    """The upstream gradient of a backward pass: a finite real array of exactly the forward output's shape.

    Parameters
    ----------
    dy : array-like
        The gradient with respect to the forward output; integer and bool arrays are taken as they are (the
        kernels promote them), nothing is copied.
    shape : tuple of int
        The forward output's shape.
    name : str
        The argument's name, first word of the message.

    Returns
    -------
    ndarray — ``np.asarray(dy)``.

    Raises
    ------
    ValueError
        ``"<name>: expected shape (2, 4), got (4,)"``, ``"<name>: expected a real floating array, got dtype
        complex128"``, ``"<name>: expected finite values, got NaN or inf"``.
    """
    a = np.asarray(dy)
    if a.shape != tuple(shape):
        raise ValueError(f"{name}: expected shape {tuple(shape)}, got {a.shape}")
    if a.dtype.kind not in "biuf":
        raise ValueError(f"{name}: expected a real floating array, got dtype {a.dtype}")
    return check_finite(a, name)


def float_array(x, name: str, shape: tuple | None = None, *, last: int | tuple[int, ...] | None = None,
                min_ndim: int = 0, finite: bool = True, cast: bool = True, context: str = "") -> np.ndarray:
    """An argument as a real floating ndarray of the expected shape.

    Parameters
    ----------
    x : array-like
        The argument.
    name : str
        Its name, first word of every message.
    shape : tuple, optional
        The whole expected shape: a size per axis, ``None`` for any size, a leading ``...`` for any number (zero
        or more) of leading axes (``(..., 4)``: a last axis of 4).
    last : int or tuple of int, optional
        The sizes the last axis may take (``(4, 8)``: ``(..., 4)`` or ``(..., 8)``); implies at least one axis.
    min_ndim : int
        The fewest axes.
    finite : bool
        Also refuse NaN and inf (:func:`check_finite`).
    cast : bool
        True: boolean and integer arrays become float64, floating arrays keep their dtype; False: only float32 and
        float64 arrays are accepted, returned as they are (no silent change of dtype).
    context : str
        Appended to a shape error after ``"; "``: where the expected sizes come from (e.g.
        ``"I = 4 from params['rnn.weight_ih_l0']"``).

    Returns
    -------
    ndarray
        ``x`` as an ndarray (float64 for a cast boolean or integer array).

    Raises
    ------
    ValueError
        One line naming ``name``: not an array of real numbers (ragged, complex, text, objects), another dtype
        than float32/float64 (``cast=False``), the wrong shape, or NaN/inf (``finite``).
    """
    try:
        a = np.asarray(x)
    except (TypeError, OverflowError, ValueError) as exc:  # ragged nesting, objects refusing conversion
        raise ValueError(f"{name}: expected a real floating array, got {type(x).__name__} ({exc})") from None
    if not cast:
        if a.dtype not in _FLOAT_DTYPES:
            raise ValueError(f"{name}: expected a float32 or float64 array, got dtype {a.dtype}")
    elif a.dtype.kind in "biu":
        a = a.astype(np.float64)
    elif a.dtype.kind != "f":
        raise ValueError(f"{name}: expected a real floating array, got dtype {a.dtype}")
    _check_shape(a.shape, name, shape, last, min_ndim, f"; {context}" if context else "")
    return check_finite(a, name) if finite else a


def _check_shape(got: tuple, name: str, shape, last, min_ndim: int, note: str) -> None:
    if shape is not None:
        fixed = shape[1:] if shape and shape[0] is Ellipsis else shape
        n = len(fixed)
        ok = len(got) >= n if fixed is not shape else len(got) == n
        if not ok or any(s is not None and s != d for s, d in zip(fixed, got[len(got) - n:])):
            raise ValueError(f"{name}: expected shape {shape_text(shape)}, got {got}{note}")
    lasts = () if last is None else (last,) if isinstance(last, int) else tuple(last)
    ndim = max(min_ndim, 1 if lasts else 0)  # a last-axis rule needs a last axis
    if len(got) >= ndim and (not lasts or got[-1] in lasts):
        return
    want = " or ".join(f"(..., {n})" for n in lasts)
    if len(got) >= ndim:
        raise ValueError(f"{name}: expected shape {want}, got {got}{note}")
    expected = f"shape {want} (at least {ndim} dimension(s))" if lasts else f"at least {ndim} dimension(s)"
    raise ValueError(f"{name}: expected {expected}, got shape {got}{note}")
