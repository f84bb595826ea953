"""Optimisation: Adam with PyTorch semantics, global gradient-norm clipping, exponential learning-rate decay.

Everything works in place on flat parameter dicts (``spec/architecture.md``: PyTorch state-dict names ->
arrays) and keeps the parameters' dtype (float32 stays float32). See ``spec/optim.md``.

* :func:`adam_init` / :func:`adam_step`: ``torch.optim.Adam`` (L2 ``weight_decay`` added to the gradient, bias
  corrections ``1 - β^t``). The optimiser state is a flat dict of arrays, ``"step"`` plus ``"m.<name>"`` and
  ``"v.<name>"`` per parameter, so it can be written to an ``.npz`` checkpoint unchanged (e.g. under the prefix
  ``"optim."``).
* :func:`clip_grad_norm`: ``torch.nn.utils.clip_grad_norm_`` (global L2 norm, ``coef = max_norm / (norm + 1e-6)``
  applied when < 1).
* :func:`exponential_lr`: ``lr0 · γ^epoch`` (QuaterNet multiplies the learning rate by 0.999 after every epoch).

The papers' settings are module constants: :data:`QUATERNET_ADAM`, :data:`QUATERNET_LR_DECAY`,
:data:`QUATERNET_CLIP_NORM` (QuaterNet), :data:`ACRNN_ADAM` (acRNN and the dual-quaternion acRNN),
:data:`QTG_ADAM` (QTG).

Speed: the Adam update streams each parameter in blocks of :data:`_BLOCK` elements through one scratch buffer
per thread, so the temporaries stay in cache and every array is read and written once (12 ufunc calls per
block). NumPy's ufuncs release the GIL, so for large models (:data:`_THREAD_MIN_SIZE` elements or more) the
blocks are shared between two threads; every element goes through the same operations whichever thread takes
its block, so the result does not depend on the thread count (bit for bit).
"""
from __future__ import annotations

import math
import os
from concurrent.futures import ThreadPoolExecutor
from types import MappingProxyType
from typing import Mapping, MutableMapping

import numpy as np

from refimpl.arrays import real_number

__all__ = [
    "QUATERNET_ADAM", "QUATERNET_LR_DECAY", "QUATERNET_CLIP_NORM", "ACRNN_ADAM", "QTG_ADAM",
    "adam_init", "adam_step", "clip_grad_norm", "exponential_lr",
]

#: QuaterNet (spec/optim.md §4): Adam lr 1e-3, default betas and eps, no weight decay.
QUATERNET_ADAM = MappingProxyType({"lr": 1e-3, "betas": (0.9, 0.999), "eps": 1e-8, "weight_decay": 0.0})
#: QuaterNet: the learning rate is multiplied by 0.999 after every epoch.
QUATERNET_LR_DECAY = 0.999
#: QuaterNet: ``clip_grad_norm_(model.parameters(), 0.1)`` every iteration.
QUATERNET_CLIP_NORM = 0.1
#: acRNN (spec/optim.md §4, spec/acrnn.md §1.1): Adam lr 1e-4 (constant), default betas; no clipping.
ACRNN_ADAM = MappingProxyType({"lr": 1e-4, "betas": (0.9, 0.999), "eps": 1e-8, "weight_decay": 0.0})
#: QTG (Geleijn et al.): Adam lr 1e-4, β1 = 0.5, β2 = 0.9.
QTG_ADAM = MappingProxyType({"lr": 1e-4, "betas": (0.5, 0.9), "eps": 1e-8, "weight_decay": 0.0})

_BLOCK = 1 << 17  # elements per block in adam_step (benchmarks/README.md "Adam": 2^15 blocks were not faster)
_THREAD_MIN_SIZE = 1 << 20  # adam_step uses two threads from this many parameter elements on (when threads=None)


# --------------------------------------------------------------------------------------------------
# validation

def _check_param_dict(arrays, name: str) -> Mapping[str, np.ndarray]:
    if not isinstance(arrays, Mapping):
        raise ValueError(f"{name}: expected a dict name -> ndarray, got {type(arrays).__name__}")
    for k, a in arrays.items():
        if not isinstance(a, np.ndarray) or not np.issubdtype(a.dtype, np.floating):
            raise ValueError(f"{name}[{k!r}]: expected a floating ndarray, got "
                             f"{type(a).__name__}{'' if not isinstance(a, np.ndarray) else ' ' + str(a.dtype)}")
    return arrays


def _check_same_layout(params, grads, name: str) -> None:
    missing = sorted(set(params) - set(grads))
    extra = sorted(set(grads) - set(params))
    if missing or extra:
        raise ValueError(f"{name}: keys differ from params: missing {missing}, unexpected {extra}")
    for k, p in params.items():
        g = grads[k]
        if g.shape != p.shape or g.dtype != p.dtype:
            raise ValueError(f"{name}[{k!r}]: expected shape {p.shape} dtype {p.dtype}, "
                             f"got shape {g.shape} dtype {g.dtype}")


def _check_finite_squares(grads: Mapping[str, np.ndarray]) -> None:
    """Refuse NaN/inf, and gradients whose squares overflow (Adam's second moment would become inf)."""
    for k, g in grads.items():
        flat = g.reshape(-1)
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is what this test looks for
            sq = np.dot(flat, flat)
        if not np.isfinite(sq):
            raise ValueError(f"grads[{k!r}]: contains NaN/inf or values whose square overflows {g.dtype}")


# --------------------------------------------------------------------------------------------------
# Adam

def adam_init(params: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Zero Adam state for ``params``.

    Parameters
    ----------
    params : dict name -> ndarray
        The model's parameters (PyTorch names).

    Returns
    -------
    state : dict
        ``"step"``: int64 0-d array (number of steps taken), ``"m.<name>"`` and ``"v.<name>"``: zero arrays with
        the shape and dtype of each parameter (``exp_avg`` and ``exp_avg_sq`` of ``torch.optim.Adam``).
    """
    _check_param_dict(params, "params")
    state: dict[str, np.ndarray] = {"step": np.zeros((), dtype=np.int64)}
    for k, p in params.items():
        state[f"m.{k}"] = np.zeros_like(p)
        state[f"v.{k}"] = np.zeros_like(p)
    return state


def _adam_block(p, g, m, v, t, w1, b1, b2, w2, eps_s, neg_step_s) -> None:
    """One block of the update, in place (``t`` is scratch of the same size; the scalars are of the arrays' dtype).

    12 ufunc passes, the output always given positionally (no keyword parsing per call); with a block that fits
    the core's L2 cache together with its scratch, only the first read of p, g, m, v and the final writes of
    p, m, v reach memory.
    """
    sub, mul, add = np.subtract, np.multiply, np.add
    # m <- lerp(m, g, 1 - β1), as torch's lerp_: m + w (g - m) for w < 0.5, else g - (g - m)(1 - w)
    sub(g, m, t)
    if w1 < 0.5:
        mul(t, w1, t)
        add(m, t, m)
    else:
        mul(t, b1, t)  # b1 = 1 - w1
        sub(g, t, m)
    # v <- β2 v + (1 - β2) g²
    mul(g, g, t)
    mul(t, w2, t)
    mul(v, b2, v)
    add(v, t, v)
    # p <- p - lr/bc1 · m / (sqrt(v)/sqrt(bc2) + eps)  =  p + m / (sqrt(v) + eps·sqrt(bc2)) · (-lr sqrt(bc2)/bc1)
    np.sqrt(v, t)
    add(t, eps_s, t)
    np.divide(m, t, t)
    mul(t, neg_step_s, t)
    add(p, t, p)


def adam_step(params: MutableMapping[str, np.ndarray], grads: Mapping[str, np.ndarray],
              state: MutableMapping[str, np.ndarray], lr: float, betas: tuple[float, float] = (0.9, 0.999),
              eps: float = 1e-8, weight_decay: float = 0.0, threads: int | None = None) -> None:
    """One Adam step, in place on ``params`` and ``state`` (``torch.optim.Adam``, ``amsgrad=False``).

    With ``t = step + 1`` and ``g = grad + weight_decay · p``::

        m ← β1 m + (1 - β1) g                      (computed as torch's lerp)
        v ← β2 v + (1 - β2) g²
        p ← p - lr / (1 - β1^t) · m / (sqrt(v) / sqrt(1 - β2^t) + eps)

    The last line is evaluated as ``p + m / (sqrt(v) + eps sqrt(1 - β2^t)) · (-lr sqrt(1 - β2^t) / (1 - β1^t))``
    (the same number up to rounding, one ufunc pass fewer).

    Parameters
    ----------
    params : dict name -> ndarray
        Updated in place (contiguous arrays are processed in cache-sized blocks).
    grads : dict name -> ndarray
        Same keys, shapes and dtypes as ``params``. Not modified. NaN/inf gradients, and gradients whose squares
        overflow the dtype, raise ValueError before anything is changed.
    state : dict
        From :func:`adam_init`; updated in place (``state["step"]`` is incremented).
    lr : float
        Learning rate (>= 0).
    betas : (float, float)
        ``β1, β2`` in [0, 1). QTG uses (0.5, 0.9).
    eps : float
        Added to the bias-corrected ``sqrt(v)`` (>= 0).
    weight_decay : float
        L2 penalty added to the gradient (PyTorch ``Adam``, not ``AdamW``), >= 0.
    threads : int, optional
        Threads sharing the blocks (>= 1). Default: 2 when the parameters hold at least
        :data:`_THREAD_MIN_SIZE` elements and the machine has 2 or more CPUs, else 1. The result is the same
        for every value.
    """
    _check_param_dict(params, "params")
    _check_param_dict(grads, "grads")
    _check_same_layout(params, grads, "grads")
    if not isinstance(state, MutableMapping) or "step" not in state:
        raise ValueError("state: expected the dict returned by adam_init (with a 'step' entry)")
    for k, p in params.items():
        for slot in ("m", "v"):
            a = state.get(f"{slot}.{k}")
            if not isinstance(a, np.ndarray) or a.shape != p.shape or a.dtype != p.dtype:
                got = "missing" if a is None else f"shape {getattr(a, 'shape', None)} dtype {getattr(a, 'dtype', None)}"
                raise ValueError(f"state[{slot + '.' + k!r}]: expected shape {p.shape} dtype {p.dtype}, got {got}")
    lr = real_number(lr, "lr", 0.0)
    if len(betas) != 2:
        raise ValueError(f"betas: expected two values (beta1, beta2), got {betas!r}")
    b1 = real_number(betas[0], "betas[0]", 0.0, 1.0, high_open=True)
    b2 = real_number(betas[1], "betas[1]", 0.0, 1.0, high_open=True)
    eps = real_number(eps, "eps", 0.0)
    weight_decay = real_number(weight_decay, "weight_decay", 0.0)
    if threads is None:
        big = sum(p.size for p in params.values()) >= _THREAD_MIN_SIZE
        threads = 2 if big and (os.cpu_count() or 1) >= 2 else 1
    elif isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
        raise ValueError(f"threads: expected a positive integer or None, got {threads!r}")
    _check_finite_squares(grads)

    step = int(state["step"]) + 1
    state["step"] = np.asarray(step, dtype=np.int64)
    bc1 = 1.0 - b1 ** step
    bc2_sqrt = math.sqrt(1.0 - b2 ** step)
    neg_step_s = -lr / bc1 * bc2_sqrt
    eps_s = eps * bc2_sqrt

    blocks = []  # (p, g, m, v) views: cache-sized pieces of contiguous arrays, strided arrays whole
    for k, p in params.items():
        g, m, v = grads[k], state[f"m.{k}"], state[f"v.{k}"]
        if weight_decay:
            g = g + weight_decay * p  # one temporary per parameter: torch's grad.add(param, alpha=wd)
        if all(a.flags.c_contiguous for a in (p, g, m, v)):
            pf, gf, mf, vf = (a.reshape(-1) for a in (p, g, m, v))
            blocks += [(pf[s:s + _BLOCK], gf[s:s + _BLOCK], mf[s:s + _BLOCK], vf[s:s + _BLOCK])
                       for s in range(0, pf.size, _BLOCK)]
        else:
            blocks.append((p, g, m, v))

    scalars = {}  # dtype -> (w1, β1, β2, w2, eps_s, neg_step_s) as scalars of that dtype
    for p in params.values():
        if p.dtype not in scalars:
            scalars[p.dtype] = tuple(p.dtype.type(c) for c in (1.0 - b1, 1.0 - (1.0 - b1), b2, 1.0 - b2, eps_s,
                                                               neg_step_s))

    def run(first: int) -> None:  # blocks first, first + threads, ...; one scratch buffer per dtype and thread
        scratch: dict[np.dtype, np.ndarray] = {}
        for p, g, m, v in blocks[first::threads]:
            if p.ndim != 1:  # strided views: a full-size scratch
                _adam_block(p, g, m, v, np.empty_like(p), *scalars[p.dtype])
                continue
            buf = scratch.get(p.dtype)
            if buf is None or buf.size < p.size:
                buf = scratch[p.dtype] = np.empty(p.size, dtype=p.dtype)
            _adam_block(p, g, m, v, buf[:p.size], *scalars[p.dtype])

    if threads == 1 or len(blocks) < 2:
        run(0)
    else:
        with ThreadPoolExecutor(max_workers=threads) as pool:
            list(pool.map(run, range(threads)))  # list(): re-raises a worker's exception here


def _adam_step_naive(params, grads, state, lr, betas=(0.9, 0.999), eps=1e-8, weight_decay=0.0) -> None:
    """Slow oracle: torch.optim.Adam's single-tensor formulas verbatim, whole arrays, with temporaries."""
    b1, b2 = betas
    step = int(state["step"]) + 1
    state["step"] = np.asarray(step, dtype=np.int64)
    for k, p in params.items():
        g = grads[k] + weight_decay * p if weight_decay else grads[k]
        m, v = state[f"m.{k}"], state[f"v.{k}"]
        m[...] = b1 * m + (1 - b1) * g
        v[...] = b2 * v + (1 - b2) * g * g
        denom = np.sqrt(v) / math.sqrt(1 - b2 ** step) + eps
        p -= lr / (1 - b1 ** step) * m / denom


# --------------------------------------------------------------------------------------------------
# clipping and decay

def _tensor_norm(g: np.ndarray) -> float:
    """L2 norm of one array as float64: BLAS dot first; scaled float64 recomputation on overflow/underflow."""
    flat = g.reshape(-1)
    with np.errstate(over="ignore", invalid="ignore"):  # handled below by the scaled recomputation
        sq = float(np.dot(flat, flat))
    if math.isfinite(sq) and (sq > 0.0 or not flat.any()):
        return math.sqrt(sq)
    s = float(np.max(np.abs(flat)))
    if not math.isfinite(s):
        return math.nan if np.isnan(s) else math.inf
    if s == 0.0:
        return 0.0
    u = flat.astype(np.float64) / s
    return s * math.sqrt(float(np.dot(u, u)))


def clip_grad_norm(grads: MutableMapping[str, np.ndarray], max_norm: float) -> float:
    """Clip the global L2 norm of all gradients in place (``torch.nn.utils.clip_grad_norm_``, norm type 2).

    ``total = sqrt(Σ_k ‖g_k‖²)``, ``coef = max_norm / (total + 1e-6)``; when ``coef < 1`` every gradient is
    multiplied by ``coef`` (in its own dtype), otherwise nothing changes. QuaterNet uses ``max_norm = 0.1``.

    Parameters
    ----------
    grads : dict name -> ndarray
        Modified in place.
    max_norm : float
        >= 0.

    Returns
    -------
    total_norm : float
        The norm before clipping (computed in float64 from per-array norms, without overflow).

    Raises
    ------
    ValueError
        When a gradient contains NaN or inf (PyTorch's ``error_if_nonfinite=True``), naming the array.
    """
    _check_param_dict(grads, "grads")
    max_norm = real_number(max_norm, "max_norm", 0.0)
    norms = []
    for k, g in grads.items():
        n = _tensor_norm(g)
        if not math.isfinite(n):
            raise ValueError(f"grads[{k!r}]: non-finite gradient (norm {n}); refusing to clip")
        norms.append(n)
    big = max(norms, default=0.0)
    total = 0.0 if big == 0.0 else big * math.sqrt(math.fsum((n / big) ** 2 for n in norms))
    coef = max_norm / (total + 1e-6)
    if coef < 1.0:
        for g in grads.values():
            np.multiply(g, coef, out=g)
    return total


def exponential_lr(lr0: float, gamma: float, epoch: int) -> float:
    """Learning rate after ``epoch`` per-epoch decays: ``lr0 · gamma^epoch`` (QuaterNet: γ = 0.999).

    Parameters
    ----------
    lr0 : float
        Initial learning rate (>= 0).
    gamma : float
        Decay per epoch, in [0, 1] (1: constant).
    epoch : int
        Number of completed epochs (>= 0).
    """
    lr0 = real_number(lr0, "lr0", 0.0)
    gamma = real_number(gamma, "gamma", 0.0, 1.0)
    if isinstance(epoch, bool) or not isinstance(epoch, (int, np.integer)) or epoch < 0:
        raise ValueError(f"epoch: expected an integer >= 0, got {epoch!r}")
    return lr0 * gamma ** int(epoch)
