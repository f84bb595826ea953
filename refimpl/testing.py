"""Tolerances and comparison helpers shared by the tests, the benchmarks and users' own tests.

All tolerances live here, so that a change of policy is one edit:

==========================================  ==========  ==========
comparison                                   rtol        atol
==========================================  ==========  ==========
float64 kernel vs float64 kernel (exact)     1e-10       1e-12
float64 vs central differences               1e-5        1e-8
float64 vs PyTorch golden (float64)          1e-9        1e-11
float32 NumPy vs onnxruntime, one step       1e-4        1e-5
float32 NumPy vs onnxruntime, rollout        1e-3        1e-4
==========================================  ==========  ==========
"""
from __future__ import annotations

import numpy as np

__all__ = ["TOL_EXACT", "TOL_FD", "TOL_GOLDEN", "TOL_ORT_STEP", "TOL_ORT_ROLLOUT",
           "assert_close", "assert_quat_close"]

TOL_EXACT = dict(rtol=1e-10, atol=1e-12)
TOL_FD = dict(rtol=1e-5, atol=1e-8)
TOL_GOLDEN = dict(rtol=1e-9, atol=1e-11)
TOL_ORT_STEP = dict(rtol=1e-4, atol=1e-5)
TOL_ORT_ROLLOUT = dict(rtol=1e-3, atol=1e-4)


def assert_close(actual, expected, rtol: float = 1e-7, atol: float = 0.0, name: str = "array") -> None:
    """Assert ``|actual - expected| <= atol + rtol |expected|`` elementwise, with a message that shows the mismatch.

    The message gives both shapes, the max abs difference, its index and the first few differing pairs
    (in the spirit of llm.c's ``check_tensor``).
    """
    a = np.asarray(actual)
    e = np.asarray(expected)
    if a.shape != e.shape:
        raise AssertionError(f"{name}: expected shape {e.shape}, got {a.shape}")
    diff = np.abs(a.astype(np.float64) - e.astype(np.float64))
    bad = ~(diff <= atol + rtol * np.abs(e.astype(np.float64)))  # NaN counts as bad
    if np.any(bad):
        idx = np.argwhere(bad)
        diff_nan_inf = np.where(np.isnan(diff), np.inf, diff)
        worst = np.unravel_index(int(np.argmax(diff_nan_inf)), a.shape)
        pairs = ", ".join(f"{tuple(int(i) for i in j)}: {a[tuple(j)]!r} vs {e[tuple(j)]!r}" for j in idx[:5])
        raise AssertionError(
            f"{name}: {len(idx)} of {a.size} entries differ (rtol={rtol}, atol={atol}); "
            f"max |diff| {np.max(diff_nan_inf):.3g} at {tuple(int(i) for i in worst)}; first: {pairs}")


def assert_quat_close(actual, expected, atol: float = 1e-9, name: str = "quaternion") -> None:
    """Assert two arrays of quaternions ``(..., 4)`` are equal up to the sign of each quaternion (``q ≡ −q``)."""
    a = np.asarray(actual, dtype=np.float64)
    e = np.asarray(expected, dtype=np.float64)
    if a.shape != e.shape or a.shape[-1:] != (4,):
        raise AssertionError(f"{name}: expected matching shapes (..., 4), got {a.shape} and {e.shape}")
    sign = np.where(np.sum(a * e, axis=-1, keepdims=True) < 0, -1.0, 1.0)
    assert_close(a * sign, e, rtol=0.0, atol=atol, name=name)
