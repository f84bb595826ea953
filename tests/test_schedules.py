"""Tests of refimpl.schedules (spec/optim.md §6): QuaterNet's scheduled sampling (ratio decay, one shared
Bernoulli draw per step, determinism) and acRNN's auto-conditioning pattern."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from refimpl.schedules import (
    ACRNN_CONDITION_LENGTH,
    ACRNN_GROUND_TRUTH_LENGTH,
    QUATERNET_TF_DECAY,
    auto_conditioning_mask,
    scheduled_sampling_mask,
    teacher_forcing_ratio,
)


def test_teacher_forcing_ratio_decay():
    """spec/optim.md §6.1: ratio = 0.995^epoch from 1 (0.61 at 100 epochs, crosses 0.5 at 139)."""
    assert QUATERNET_TF_DECAY == 0.995
    assert teacher_forcing_ratio(0) == 1.0
    assert teacher_forcing_ratio(100) == pytest.approx(0.6058, abs=1e-4)
    assert teacher_forcing_ratio(138) > 0.5 > teacher_forcing_ratio(139)
    r = 1.0
    for e in range(1, 50):
        r *= 0.995
        assert teacher_forcing_ratio(e) == pytest.approx(r, rel=1e-13)
    assert teacher_forcing_ratio(3, start=0.5, decay=0.5) == 0.0625
    with pytest.raises(ValueError, match="epoch"):
        teacher_forcing_ratio(-1)
    with pytest.raises(ValueError, match="decay"):
        teacher_forcing_ratio(1, decay=1.5)


@given(st.floats(0.0, 1.0), st.integers(0, 50), st.integers(0, 2**31 - 1))
def test_scheduled_sampling_deterministic_and_rng_use(ratio, steps, seed):
    """spec/optim.md §6.1: mask = rng.random(steps) < ratio: the same seed gives the same mask, and exactly
    `steps` uniforms are consumed (so the generator stream stays aligned)."""
    a = scheduled_sampling_mask(ratio, steps, np.random.default_rng(seed))
    b = scheduled_sampling_mask(ratio, steps, np.random.default_rng(seed))
    assert a.dtype == np.bool_ and a.shape == (steps,) and np.array_equal(a, b)
    rng, ref = np.random.default_rng(seed), np.random.default_rng(seed)
    m = scheduled_sampling_mask(ratio, steps, rng)
    u = ref.random(steps)
    assert np.array_equal(m, u < ratio) and rng.random() == ref.random()


def test_scheduled_sampling_statistics_and_limits():
    """spec/optim.md §6.1: P(True) = ratio (binomial check over 200k draws); ratio 1 → all ground truth,
    ratio 0 → all own predictions."""
    rng = np.random.default_rng(0)
    for ratio in (0.1, 0.5, 0.9):
        m = scheduled_sampling_mask(ratio, 200_000, rng)
        sd = np.sqrt(ratio * (1 - ratio) / m.size)
        assert abs(m.mean() - ratio) < 5 * sd
    assert scheduled_sampling_mask(1.0, 100, rng).all()
    assert not scheduled_sampling_mask(0.0, 100, rng).any()
    with pytest.raises(ValueError, match="ratio"):
        scheduled_sampling_mask(1.1, 3, rng)
    with pytest.raises(ValueError, match="rng"):
        scheduled_sampling_mask(0.5, 3, np.random.RandomState(0))
    with pytest.raises(ValueError, match="steps"):
        scheduled_sampling_mask(0.5, -1, rng)


def test_auto_conditioning_acrnn_pattern():
    """spec/optim.md §6.2: acRNN feeds 5 ground-truth frames, then 5 own outputs, repeating, from ground truth."""
    assert (ACRNN_GROUND_TRUTH_LENGTH, ACRNN_CONDITION_LENGTH) == (5, 5)
    m = auto_conditioning_mask(100)
    assert m.shape == (100,) and m.dtype == np.bool_ and m.sum() == 50
    expect = np.array(([True] * 5 + [False] * 5) * 10)
    assert np.array_equal(m, expect)


@given(st.integers(0, 40), st.integers(1, 6), st.integers(0, 6))
def test_auto_conditioning_configurable(steps, u, v):
    """spec/optim.md §6.2: mask[t] = (t mod (u+v)) < u; starts with ground truth; v = 0 is teacher forcing."""
    m = auto_conditioning_mask(steps, u, v)
    assert m.shape == (steps,)
    for t in range(steps):
        assert m[t] == ((t % (u + v)) < u)
    if steps:
        assert m[0]
    if v == 0:
        assert m.all()


def test_auto_conditioning_validation():
    """spec/architecture.md: non-integer or out-of-range lengths raise ValueError naming the argument."""
    with pytest.raises(ValueError, match="ground_truth_length"):
        auto_conditioning_mask(10, 0, 5)
    with pytest.raises(ValueError, match="condition_length"):
        auto_conditioning_mask(10, 5, -1)
    with pytest.raises(ValueError, match="steps"):
        auto_conditioning_mask(2.5)
