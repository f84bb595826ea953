"""Synthesis metrics of refimpl/protocols/synthesis.py: Euclidean error, NPSS (two variants), acceleration (spec/acrnn.md §6)."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st

from refimpl.protocols import synthesis as metrics
from refimpl.quat import quat_normalize
from refimpl.representations import encode
from refimpl.skeleton import Skeleton


def _npss_naive(gt, pred, variant):
    """Slow oracle: explicit DFT sums, loops over sequences, features and frequencies."""
    N, T = gt.shape[:2]
    g, p = gt.reshape(N, T, -1), pred.reshape(N, T, -1)
    num = den = 0.0
    t = np.arange(T)
    for s in range(N):
        for d in range(g.shape[2]):
            spectra = []
            for x in (g[s, :, d], p[s, :, d]):
                P = []
                for k in range(T):
                    X = np.sum(x * np.exp(-2j * np.pi * k * t / T))
                    P.append(abs(X) ** 2 if variant == "power" else X.real ** 2)
                spectra.append(np.array(P))
            Pg, Pp = spectra
            w = Pg.sum()
            ng = Pg / w if w > 0 else 0 * Pg
            npd = Pp / Pp.sum() if Pp.sum() > 0 else 0 * Pp
            emd = sum(abs(np.sum(npd[:k + 1]) - np.sum(ng[:k + 1])) for k in range(T))
            num += w * emd
            den += w
    return num / den


@pytest.mark.parametrize("variant", metrics.NPSS_VARIANTS)
def test_npss_equals_slow_oracle(variant):
    rng = np.random.default_rng(0)
    gt = rng.standard_normal((3, 9, 2, 3))
    pred = gt + 0.5 * rng.standard_normal(gt.shape)
    assert metrics.npss(gt, pred, variant) == pytest.approx(_npss_naive(gt, pred, variant), rel=1e-10)


@pytest.mark.parametrize("variant", metrics.NPSS_VARIANTS)
def test_npss_is_zero_for_identical_sequences(variant):
    gt = np.random.default_rng(1).standard_normal((4, 30, 5, 3))
    assert metrics.npss(gt, gt.copy(), variant) == 0.0


def _periodic(rng, N=3, T=40, D=6, period=10):
    t = np.arange(T)[None, :, None]
    k = rng.integers(1, 4, size=(N, 1, D))
    phase = rng.uniform(0, 2 * np.pi, size=(N, 1, D))
    return np.sin(2 * np.pi * k * t / period + phase) + 0.3 * np.cos(2 * np.pi * 2 * k * t / period)


def test_power_npss_is_invariant_to_a_common_time_shift_of_a_periodic_signal():
    rng = np.random.default_rng(2)
    long_gt, long_pred = _periodic(rng, T=60), _periodic(rng, T=60)
    base = metrics.npss(long_gt[:, :40], long_pred[:, :40])
    for shift in (1, 3, 7, 10, 13):  # windows [shift, shift + 40): 40 = 4 periods
        assert metrics.npss(long_gt[:, shift:shift + 40], long_pred[:, shift:shift + 40]) == pytest.approx(base,
                                                                                                           abs=1e-12)
    # a shifted copy of the ground truth has the same power spectrum: NPSS 0
    assert metrics.npss(long_gt[:, :40], long_gt[:, 3:43]) == pytest.approx(0.0, abs=1e-12)


def test_real_part_npss_is_not_shift_invariant():
    """The LaFAN1 variant squares Re X only, which depends on the phase (documented in spec/acrnn.md §6)."""
    rng = np.random.default_rng(3)
    gt = _periodic(rng, T=60)
    assert metrics.npss(gt[:, :40], gt[:, 3:43], "real") > 1e-3


def test_npss_rejects_bad_input():
    x = np.zeros((2, 10, 3))
    with pytest.raises(ValueError, match="zero power"):
        metrics.npss(x, x)
    with pytest.raises(ValueError, match="variant"):
        metrics.npss(x + 1, x + 1, "abs")
    with pytest.raises(ValueError, match="pred"):
        metrics.npss(x + 1, x[:, :5])


def test_mean_joint_error_and_root_zeroed_positions():
    rng = np.random.default_rng(4)
    skel = Skeleton([-1, 0, 1, 0], rng.standard_normal((4, 3)))
    rot = quat_normalize(rng.standard_normal((5, 4, 4)))
    root = rng.standard_normal((5, 3))
    frames = encode("dual_quaternions", skel, rot, root)
    pos = metrics.root_zeroed_positions("dual_quaternions", skel, frames)
    np.testing.assert_allclose(pos, skel.forward_kinematics(rot, np.zeros((5, 3))), atol=1e-12)
    np.testing.assert_allclose(metrics.root_zeroed_positions("dual_quaternions", skel, frames, "stored"), pos,
                               atol=1e-12)
    # a network's DQ output with a wrong bone length: FK (default) keeps the skeleton's, Eq. 8 does not
    stretched = frames.copy()
    stretched[:, 3 + 8 * 3 + 4:] *= 2.0  # joint 3's dual part doubled: its translation doubles
    np.testing.assert_allclose(metrics.root_zeroed_positions("dual_quaternions", skel, stretched), pos, atol=1e-12)
    assert not np.allclose(metrics.root_zeroed_positions("dual_quaternions", skel, stretched, "stored"), pos)
    p_frames = encode("positions", skel, rot, root)
    np.testing.assert_allclose(metrics.root_zeroed_positions("positions", skel, p_frames), pos, atol=1e-12)
    with pytest.raises(ValueError, match="source"):
        metrics.root_zeroed_positions("positions", skel, p_frames, "ik")
    other = pos + np.array([0.0, 3.0, 4.0])
    assert metrics.mean_joint_error(other, pos) == pytest.approx(5.0)
    pred = pos + rng.standard_normal(pos.shape)
    loop = np.mean([np.linalg.norm(pred[t, j] - pos[t, j]) for t in range(5) for j in range(4)])
    assert metrics.mean_joint_error(pred, pos) == pytest.approx(loop, rel=1e-13)


def test_mean_acceleration_against_a_loop_and_constant_velocity():
    rng = np.random.default_rng(5)
    p = rng.standard_normal((2, 6, 3, 3))
    loop = np.mean([np.linalg.norm(p[n, t + 2, j] - 2 * p[n, t + 1, j] + p[n, t, j])
                    for n in range(2) for t in range(4) for j in range(3)])
    assert metrics.mean_acceleration(p) == pytest.approx(loop, rel=1e-13)
    linear = np.arange(10.0)[None, :, None, None] * np.ones((1, 10, 2, 3))
    assert metrics.mean_acceleration(linear) == 0.0
    cmp = metrics.acceleration_comparison(p, linear)
    assert cmp["gt"] == 0.0 and cmp["abs_diff"] == pytest.approx(cmp["pred"])
    with pytest.raises(ValueError, match="3 frames"):
        metrics.mean_acceleration(p[:, :2])


@given(st.integers(0, 2**32 - 1), st.integers(1, 3), st.integers(2, 12), st.integers(1, 4), st.integers(0, 11))
def test_npss_properties_hold_for_random_sequences(seed, N, T, D, shift):
    rng = np.random.default_rng(seed)
    gt = rng.standard_normal((N, T, D))
    pred = rng.standard_normal((N, T, D))
    for variant in metrics.NPSS_VARIANTS:
        assert metrics.npss(gt, gt, variant) == 0.0
        value = metrics.npss(gt, pred, variant)
        assert 0.0 <= value <= T  # each EMD term is at most T − 1 + 1
    # the power spectrum of a circularly shifted sequence is the same: invariance of the original NPSS
    s = shift % T
    assert metrics.npss(np.roll(gt, s, axis=1), np.roll(pred, s, axis=1)) == pytest.approx(metrics.npss(gt, pred),
                                                                                             abs=1e-12)
    assert metrics.npss(gt, np.roll(gt, s, axis=1)) == pytest.approx(0.0, abs=1e-12)
