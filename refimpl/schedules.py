"""Exposure-bias schedules: which time steps are fed ground truth and which the model's own output.

A mask is a boolean array over the decision steps: ``True`` = feed the ground-truth frame (teacher forcing),
``False`` = feed the model's previous prediction. In both schedules the gradient flows through the fed-back
predictions (no detach): a manual backward must add the next step's input gradient to the output gradient
of the step whose prediction was fed back. See ``spec/optim.md``.

* QuaterNet scheduled sampling (Pavllo et al. §3.3; spec/optim.md §6.1): the teacher-forcing ratio starts at 1
  and is multiplied by 0.995 after every epoch (:func:`teacher_forcing_ratio`); for each batch, ONE Bernoulli
  draw per time step, shared by the whole batch (:func:`scheduled_sampling_mask`). QuaterNet decides the
  ``T - 1`` steps after the first prediction of a ``T``-frame target, i.e. it calls this with ``steps = T - 1``.
* acRNN auto-conditioning (Zhou et al.; ``Groundtruth_num = Condition_num = 5``): ``u`` ground-truth steps,
  then ``v`` steps of the model's own output, repeating, starting with ground truth
  (:func:`auto_conditioning_mask`). Deterministic.

Shape legend: T time steps.
"""
from __future__ import annotations

import numpy as np

__all__ = [
    "QUATERNET_TF_DECAY", "ACRNN_GROUND_TRUTH_LENGTH", "ACRNN_CONDITION_LENGTH",
    "teacher_forcing_ratio", "scheduled_sampling_mask", "auto_conditioning_mask",
]

#: QuaterNet: the teacher-forcing ratio is multiplied by 0.995 after every epoch (from 1.0).
QUATERNET_TF_DECAY = 0.995
#: acRNN: ground-truth frames per period (``Groundtruth_num``).
ACRNN_GROUND_TRUTH_LENGTH = 5
#: acRNN: self-conditioned frames per period (``Condition_num``).
ACRNN_CONDITION_LENGTH = 5


def _check_count(x, name: str, minimum: int = 0) -> int:
    if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < minimum:
        raise ValueError(f"{name}: expected an integer >= {minimum}, got {x!r}")
    return int(x)


def _check_probability(x, name: str) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a number in [0, 1], got {x!r}") from None
    if not (0.0 <= v <= 1.0):  # also refuses NaN
        raise ValueError(f"{name}: expected a value in [0, 1], got {x!r}")
    return v


def teacher_forcing_ratio(epoch: int, start: float = 1.0, decay: float = QUATERNET_TF_DECAY) -> float:
    """Teacher-forcing probability after ``epoch`` completed epochs: ``start · decay^epoch``.

    QuaterNet: ``start = 1``, ``decay = 0.995`` (0.61 after 100 epochs, 0.5 after about 138).

    Parameters
    ----------
    epoch : int
        >= 0.
    start : float
        In [0, 1].
    decay : float
        In [0, 1].

    Returns
    -------
    float, in [0, 1]
    """
    epoch = _check_count(epoch, "epoch")
    return _check_probability(start, "start") * _check_probability(decay, "decay") ** epoch


def scheduled_sampling_mask(ratio: float, steps: int, rng: np.random.Generator) -> np.ndarray:
    """QuaterNet's scheduled-sampling mask: ``u_t < ratio`` with ``u_t ~ U[0, 1)`` i.i.d., one per step.

    The same mask applies to every sequence of the batch (one draw per time step, not per sample), and a new
    mask is drawn for every batch. Exactly ``steps`` uniforms are consumed from ``rng`` (``rng.random(steps)``),
    so the mask is reproducible from the generator's state.

    Parameters
    ----------
    ratio : float
        Teacher-forcing probability in [0, 1] (:func:`teacher_forcing_ratio`). 1 → all True, 0 → all False.
    steps : int
        Number of decisions (QuaterNet: target length − 1).
    rng : numpy.random.Generator

    Returns
    -------
    mask : ndarray of bool, shape (steps,)
        True = feed the ground-truth frame at that step.
    """
    ratio = _check_probability(ratio, "ratio")
    steps = _check_count(steps, "steps")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng: expected a numpy.random.Generator, got {type(rng).__name__}")
    return rng.random(steps) < ratio


def auto_conditioning_mask(steps: int, ground_truth_length: int = ACRNN_GROUND_TRUTH_LENGTH,
                           condition_length: int = ACRNN_CONDITION_LENGTH) -> np.ndarray:
    """acRNN's auto-conditioning schedule: ``ground_truth_length`` True, then ``condition_length`` False, repeated.

    ``mask[t] = (t mod (u + v)) < u`` with ``u = ground_truth_length``, ``v = condition_length``: it starts with
    ground truth (acRNN: steps 0-4 ground truth, 5-9 own output, 10-14 ground truth, ...).

    Parameters
    ----------
    steps : int
        Sequence length (acRNN: 100).
    ground_truth_length : int
        ``u`` >= 1.
    condition_length : int
        ``v`` >= 0 (0: pure teacher forcing).

    Returns
    -------
    mask : ndarray of bool, shape (steps,)
        True = feed the ground-truth frame.
    """
    steps = _check_count(steps, "steps")
    u = _check_count(ground_truth_length, "ground_truth_length", 1)
    v = _check_count(condition_length, "condition_length")
    return (np.arange(steps) % (u + v)) < u
