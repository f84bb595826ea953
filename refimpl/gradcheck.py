"""Gradient-check harness: the three oracles every backward in the project is tested with.

1. ``numerical_gradient``: float64 central differences, entry by entry.
2. ``check_vjp``: the vector-Jacobian identity ``<J v, w> = <v, J^T w>`` with random directions ``v`` and ``w``
   (the directional derivative ``J v`` is itself a central difference, so this checks all entries at once).
3. The slow loop versions of vectorised kernels live beside the kernels (``_naive`` functions); tests compare
   them with the fast ones through :func:`refimpl.testing.assert_close`.

Both checkers take plain callables and dicts of arrays, so they work for layers, losses and whole models.
They mutate the arrays they perturb and restore them before returning.
"""
from __future__ import annotations

from typing import Callable, Mapping

import numpy as np

__all__ = ["numerical_gradient", "check_gradients", "check_vjp"]


def numerical_gradient(f: Callable[[], float], x: np.ndarray, eps: float = 1e-6,
                       indices: np.ndarray | None = None) -> np.ndarray:
    """Central-difference gradient of the scalar ``f()`` with respect to the array ``x`` (perturbed in place).

    Parameters
    ----------
    f : callable
        Takes no argument, reads ``x`` (by reference) and returns a scalar.
    x : ndarray, float64
        The array to differentiate with respect to; restored on return.
    eps : float
        Step of the central difference ``(f(x + eps e_i) - f(x - eps e_i)) / (2 eps)``.
    indices : ndarray of int, optional
        Flat indices to evaluate; the others are left at 0. Default: all entries.

    Returns
    -------
    ndarray, same shape as ``x``
    """
    if x.dtype != np.float64:
        raise ValueError(f"numerical_gradient needs a float64 array, got {x.dtype}")
    grad = np.zeros_like(x)
    flat = x.reshape(-1)  # a view: x must be contiguous
    if not np.shares_memory(flat, x):
        raise ValueError("numerical_gradient needs a contiguous array")
    gflat = grad.reshape(-1)
    idx = np.arange(flat.size) if indices is None else np.asarray(indices)
    for i in idx:
        old = flat[i]
        flat[i] = old + eps
        fp = float(f())
        flat[i] = old - eps
        fm = float(f())
        flat[i] = old
        gflat[i] = (fp - fm) / (2.0 * eps)
    return grad


def check_gradients(f: Callable[[], float], arrays: Mapping[str, np.ndarray],
                    analytic: Mapping[str, np.ndarray], *, eps: float = 1e-6, rtol: float = 1e-5,
                    atol: float = 1e-8, max_entries: int | None = 64, seed: int = 0) -> None:
    """Compare analytic gradients with central differences, array by array.

    Parameters
    ----------
    f : callable
        ``f() -> float``, the scalar loss, reading the arrays in ``arrays`` by reference.
    arrays : mapping name -> float64 ndarray
        The inputs/parameters to check (perturbed in place, restored).
    analytic : mapping name -> ndarray
        The backward pass's gradients, same keys and shapes as ``arrays``.
    max_entries : int or None
        Check at most this many randomly chosen entries per array (None: all).

    Raises
    ------
    AssertionError
        With the name, the worst entry and both values, when any entry differs by more than
        ``atol + rtol * |numerical|``.
    """
    rng = np.random.default_rng(seed)
    for name, x in arrays.items():
        if name not in analytic:
            raise AssertionError(f"no analytic gradient for {name!r}")
        g = np.asarray(analytic[name])
        if g.shape != x.shape:
            raise AssertionError(f"gradient {name!r}: expected shape {x.shape}, got {g.shape}")
        n = x.size
        idx = None if (max_entries is None or n <= max_entries) else rng.choice(n, max_entries, replace=False)
        num = numerical_gradient(f, x, eps=eps, indices=idx)
        sel = np.arange(n) if idx is None else idx
        a, b = g.reshape(-1)[sel], num.reshape(-1)[sel]
        err = np.abs(a - b) - (atol + rtol * np.abs(b))
        if np.any(err > 0):
            k = int(np.argmax(err))
            raise AssertionError(
                f"gradient {name!r} differs from central differences at flat index {int(sel[k])}: "
                f"analytic {a[k]:.10g}, numerical {b[k]:.10g} (|diff| {abs(a[k] - b[k]):.3g}; "
                f"{int(np.sum(err > 0))} of {len(sel)} checked entries fail)")


def _as_tuple(y):
    return tuple(y) if isinstance(y, (tuple, list)) else (y,)


def check_vjp(fn: Callable[[], object], arrays: Mapping[str, np.ndarray],
              vjp: Callable[[tuple], Mapping[str, np.ndarray]], *, eps: float = 1e-6,
              rtol: float = 1e-6, atol: float = 1e-10, seed: int = 0) -> None:
    """Check the vector-Jacobian identity ``<J v, w> = <v, J^T w>``.

    Parameters
    ----------
    fn : callable
        ``fn() -> ndarray or tuple of ndarrays``, reading ``arrays`` by reference.
    arrays : mapping name -> float64 ndarray
        Inputs/parameters; each gets a random direction ``v`` (perturbed in place, restored).
    vjp : callable
        ``vjp(douts) -> mapping name -> gradient``: the backward pass given one cotangent per output.

    Notes
    -----
    ``J v`` is computed as ``(fn(x + eps v) - fn(x - eps v)) / (2 eps)`` with all arrays moved together,
    so one check covers every entry; float64 only.
    """
    rng = np.random.default_rng(seed)
    outs = _as_tuple(fn())
    ws = tuple(rng.standard_normal(np.shape(o)) for o in outs)
    grads = vjp(ws)
    vs = {k: rng.standard_normal(x.shape) for k, x in arrays.items()}
    olds = {k: x.copy() for k, x in arrays.items()}
    for k, x in arrays.items():
        x += eps * vs[k]
    plus = _as_tuple(fn())
    for k, x in arrays.items():
        x[...] = olds[k] - eps * vs[k]
    minus = _as_tuple(fn())
    for k, x in arrays.items():
        x[...] = olds[k]
    lhs = sum(float(np.sum((np.asarray(p) - np.asarray(m)) / (2 * eps) * w)) for p, m, w in zip(plus, minus, ws))
    rhs = sum(float(np.sum(vs[k] * np.asarray(grads[k]))) for k in arrays)
    if not abs(lhs - rhs) <= atol + rtol * max(abs(lhs), abs(rhs)):
        raise AssertionError(f"vector-Jacobian identity fails: <J v, w> = {lhs:.12g}, <v, J^T w> = {rhs:.12g}")
