"""Use refimpl as an oracle for your own implementation: a worked example (README "Use it as an oracle").

You wrote a quaternion product layer (forward and a hand-written backward, in NumPy, and perhaps in PyTorch).
This script checks it three ways with what refimpl offers:

1. **forward** against :func:`refimpl.quat.quat_mul` on property-based inputs drawn by
   :mod:`refimpl.strategies` (hypothesis), compared with :func:`refimpl.testing.assert_close`;
2. **your backward** against central differences (:func:`refimpl.gradcheck.check_gradients`) and the
   vector-Jacobian identity (:func:`refimpl.gradcheck.check_vjp`), and against refimpl's own backward
   (:func:`refimpl.nn.quat_mul_backward`);
3. **a PyTorch version** (skipped when torch is not installed): its autograd gradients against refimpl's.

    python examples/oracle_check.py            # exit 0, one line per check
    python examples/oracle_check.py --broken   # a wrong sign in the backward: the oracles catch it, exit 1

Replace ``my_quat_mul`` / ``my_quat_mul_backward`` by your code. Shapes: (B, 4) quaternions ``(w, x, y, z)``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a clone without installing

from refimpl.gradcheck import check_gradients, check_vjp  # noqa: E402
from refimpl.nn import quat_mul_backward, quat_mul_forward  # noqa: E402
from refimpl.quat import quat_mul  # noqa: E402
from refimpl.strategies import quaternions, unit_quaternions  # noqa: E402
from refimpl.testing import TOL_EXACT, TOL_FD, assert_close  # noqa: E402

BROKEN = "--broken" in sys.argv


# ------------------------------------------------------------------------------------- your implementation

def my_quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Your forward: ``a ⊗ b`` as the left-multiplication matrix L(a) times b. a, b (B, 4) -> (B, 4)."""
    w, x, y, z = a[:, 0], a[:, 1], a[:, 2], a[:, 3]
    L = np.stack([np.stack([w, -x, -y, -z], -1), np.stack([x, w, -z, y], -1),
                  np.stack([y, z, w, -x], -1), np.stack([z, -y, x, w], -1)], 1)   # (B, 4, 4)
    return np.einsum("bij,bj->bi", L, b)


def my_quat_mul_backward(dy: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Your backward: ``da = dy ⊗ b*``, ``db = a* ⊗ dy`` (``--broken`` flips a sign)."""
    conj = np.array([1.0, -1.0, -1.0, -1.0])
    da = my_quat_mul(dy, b * conj)
    db = my_quat_mul(a * conj, dy)
    if BROKEN:
        db[:, 1] = -db[:, 1]
    return da, db


# ------------------------------------------------------------------------------------- the checks

@settings(max_examples=50, deadline=None, derandomize=True)
@given(st.integers(1, 5).flatmap(lambda n: st.tuples(quaternions((n,)), unit_quaternions((n,)))))
def check_forward(ab):
    """1. Forward against refimpl on drawn quaternions (general norms and unit ones)."""
    a, b = ab
    assert_close(my_quat_mul(a, b), quat_mul(a, b), **TOL_EXACT, name="a ⊗ b")


def check_backward(seed: int = 0) -> None:
    """2. Your backward against central differences, the VJP identity and refimpl's backward."""
    rng = np.random.default_rng(seed)
    a, b = rng.standard_normal((3, 4)), rng.standard_normal((3, 4))
    w = rng.standard_normal((3, 4))                       # the loss is sum(w * (a ⊗ b))
    da, db = my_quat_mul_backward(w, a, b)
    check_gradients(lambda: float(np.sum(w * my_quat_mul(a, b))), {"a": a, "b": b}, {"a": da, "b": db}, **TOL_FD)
    check_vjp(lambda: my_quat_mul(a, b), {"a": a, "b": b},
              lambda dys: dict(zip("ab", my_quat_mul_backward(dys[0], a, b))))
    _, cache = quat_mul_forward(a, b)
    ref_da, ref_db = quat_mul_backward(w, cache)
    assert_close(da, ref_da, **TOL_EXACT, name="da vs refimpl")
    assert_close(db, ref_db, **TOL_EXACT, name="db vs refimpl")


def check_torch(seed: int = 0) -> bool:
    """3. A PyTorch quaternion product: forward and autograd gradients against refimpl. False if no torch."""
    try:
        import torch
    except ImportError:
        return False
    rng = np.random.default_rng(seed)
    a, b, w = (rng.standard_normal((5, 4)) for _ in range(3))
    ta, tb = (torch.tensor(v, dtype=torch.float64, requires_grad=True) for v in (a, b))
    aw, ax, ay, az = ta.unbind(-1)
    bw, bx, by, bz = tb.unbind(-1)
    y = torch.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], -1)
    (y * torch.tensor(w)).sum().backward()
    ref_y, cache = quat_mul_forward(a, b)
    ref_da, ref_db = quat_mul_backward(w, cache)
    assert_close(y.detach().numpy(), ref_y, **TOL_EXACT, name="torch forward")
    assert_close(ta.grad.numpy(), ref_da, **TOL_EXACT, name="torch da")
    assert_close(tb.grad.numpy(), ref_db, **TOL_EXACT, name="torch db")
    return True


def main() -> int:
    try:
        check_forward()
        print("forward: matches refimpl.quat.quat_mul on 50 hypothesis draws")
        check_backward()
        print("backward: matches central differences, the VJP identity and refimpl.nn.quat_mul_backward")
        print("pytorch: forward and autograd gradients match refimpl" if check_torch()
              else "pytorch: not installed, skipped")
    except AssertionError as exc:
        print(f"MISMATCH: {str(exc).splitlines()[0]}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
