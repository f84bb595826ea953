"""Tests of refimpl.preprocess (spec/data.md §5)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from refimpl.bvh import read_bvh
from refimpl.expmap import read_expmap
from refimpl.motion import Motion
from refimpl.preprocess import (_windows_naive, denormalize_features, downsample, feature_statistics, fix_antipodal,
                                normalize_features, split_by_file, windows)
from refimpl.testing import assert_close, assert_quat_close

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"


@pytest.fixture(scope="module")
def walk() -> Motion:
    return read_bvh(SAMPLE / "bvh" / "02_01.bvh")


def test_downsample_strides_and_phases(walk):
    """spec/data.md §5.1: every stride-th frame from phase; frame time × stride; phases partition the frames."""
    d4 = downsample(walk, 4)  # 120 → 30 Hz (QuaterNet locomotion)
    assert d4.num_frames == 86 and d4.fps == pytest.approx(30, rel=1e-4)
    assert_close(d4.rotations, walk.rotations[::4], atol=0)
    assert_close(d4.root_positions, walk.root_positions[::4], atol=0)
    assert d4.skeleton is walk.skeleton and d4.name == walk.name
    parts = [downsample(walk, 2, phase) for phase in (0, 1)]  # 50 → 25 Hz style, both phases (_d0, _d1)
    assert parts[0].num_frames + parts[1].num_frames == walk.num_frames
    assert_close(parts[1].rotations, walk.rotations[1::2], atol=0)
    assert downsample(walk, 1).num_frames == walk.num_frames
    for bad in (0, -2, 1.5, True):
        with pytest.raises(ValueError, match="stride"):
            downsample(walk, bad)
    with pytest.raises(ValueError, match="phase"):
        downsample(walk, 2, 2)
    with pytest.raises(ValueError, match="motion"):
        downsample(walk.rotations, 2)


def test_fix_antipodal(walk):
    """spec/data.md §5.2: consecutive quaternions in one hemisphere afterwards, same rotations."""
    rng = np.random.default_rng(0)
    flips = np.where(rng.random((walk.num_frames, walk.num_joints, 1)) < 0.5, -1.0, 1.0)
    flipped = Motion(walk.skeleton, walk.rotations * flips, walk.root_positions, walk.frame_time)
    fixed = fix_antipodal(flipped)
    assert np.all(np.sum(fixed.rotations[1:] * fixed.rotations[:-1], axis=-1) >= 0)
    assert_quat_close(fixed.rotations, walk.rotations, atol=0)
    assert_close(fixed.rotations[0], flipped.rotations[0], atol=0)  # frame 0 kept
    empty = Motion(walk.skeleton, walk.rotations[:0], walk.root_positions[:0], walk.frame_time)
    assert fix_antipodal(empty).num_frames == 0


@given(hnp.arrays(np.float64, st.tuples(st.integers(0, 12), st.integers(1, 3), st.integers(1, 2)),
                  elements=st.floats(-5, 5)),
       st.integers(1, 6), st.integers(1, 4))
def test_windows_match_loop_version(array, length, stride):
    """spec/data.md §5.3: sliding windows equal the loop version; a read-only view of the input."""
    w = windows(array, length, stride)
    expected_n = max(0, (array.shape[0] - length) // stride + 1)
    assert w.shape == (expected_n, length) + array.shape[1:]
    assert_close(w, _windows_naive(array, length, stride), atol=0)
    if expected_n:
        assert np.shares_memory(w, array)
    assert not w.flags.writeable


def test_windows_validation():
    """spec/data.md §5.3: length and stride must be positive ints."""
    for bad in (0, -1, 2.0):
        with pytest.raises(ValueError, match="length"):
            windows(np.zeros(5), bad)
        with pytest.raises(ValueError, match="stride"):
            windows(np.zeros(5), 2, bad)
    with pytest.raises(ValueError, match="array"):
        windows(np.float64(1.0), 1)


def test_split_by_file():
    """spec/data.md §5.4: disjoint whole-file groups, deterministic, independent of the input order."""
    files = [f"clip_{k:02d}.bvh" for k in range(20)]
    train, valid, test = split_by_file(files, (0.75, 0.1, 0.15), seed=3)
    assert (len(train), len(valid), len(test)) == (15, 2, 3)
    assert sorted(train + valid + test) == files
    assert train == sorted(train)
    assert split_by_file(list(reversed(files)), (0.75, 0.1, 0.15), seed=3) == (train, valid, test)
    assert split_by_file(files, (0.75, 0.1, 0.15), seed=4) != (train, valid, test)
    assert split_by_file(files, (1.0,)) == (files,)
    assert split_by_file([Path("b"), Path("a")], (0.5, 0.5), seed=0) in (([Path("a")], [Path("b")]),
                                                                         ([Path("b")], [Path("a")]))
    with pytest.raises(ValueError, match="fractions"):
        split_by_file(files, (0.5, 0.4))
    with pytest.raises(ValueError, match="fractions"):
        split_by_file(files, (1.5, -0.5))
    with pytest.raises(ValueError, match="distinct"):
        split_by_file(["a", "a"], (0.5, 0.5))


def test_feature_statistics_and_normalisation():
    """spec/data.md §5.5: mean and population std over all but the last axis; std < min_std → 1."""
    rng = np.random.default_rng(1)
    x = rng.normal(3.0, 2.0, size=(4, 50, 6))
    x[..., 2] = 7.0                     # constant feature
    x[..., 4] = 1.0 + 1e-6 * rng.normal(size=(4, 50))  # tiny std
    mean, std = feature_statistics(x)
    flat = x.reshape(-1, 6)
    assert_close(mean, flat.mean(0), rtol=1e-12)
    expected_std = flat.std(0)
    expected_std[[2, 4]] = 1.0
    assert_close(std, expected_std, rtol=1e-12)
    mean_list, std_list = feature_statistics([x[0], x[1], x[2], x[3]])
    assert_close(mean_list, mean, rtol=1e-12)
    assert_close(std_list, std, rtol=1e-12)
    z = normalize_features(x, mean, std)
    assert_close(z.reshape(-1, 6)[:, [0, 1, 3, 5]].std(0), np.ones(4), rtol=1e-12)
    assert_close(denormalize_features(z, mean, std), x, rtol=1e-12, atol=1e-12)
    z32 = normalize_features(x.astype(np.float32), mean, std)
    assert z32.dtype == np.float32
    with pytest.raises(ValueError, match="NaN"):
        feature_statistics(np.array([[np.nan, 1.0]]))
    with pytest.raises(ValueError, match="at least one frame"):
        feature_statistics(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="share the last axis"):
        feature_statistics([np.zeros((2, 3)), np.zeros((2, 4))])
    with pytest.raises(ValueError, match=r"mean: expected shape \(6,\)"):
        normalize_features(x, mean[:3], std)


@pytest.mark.parametrize("fn", [normalize_features, denormalize_features])
def test_feature_normalisation_validation(fn):
    """spec/data.md §5.5, spec/robustness.md §3 (bug B10): NaN/inf anywhere, std <= 0 or inf, strings, wrong
    shapes and 0-d frames are refused with ValueError naming the argument; nothing passes through silently."""
    x = np.arange(12.0).reshape(4, 3)
    mean, std = np.zeros(3), np.ones(3)
    fn(x, mean, std)
    bad_cases = [
        ("frames", (np.where(x == 5, np.nan, x), mean, std)), ("frames", (np.where(x == 5, np.inf, x), mean, std)),
        ("mean", (x, np.array([0.0, np.nan, 0.0]), std)), ("mean", (x, np.array([0.0, -np.inf, 0.0]), std)),
        ("std", (x, mean, np.array([1.0, np.inf, 1.0]))), ("std", (x, mean, np.array([1.0, np.nan, 1.0]))),
        ("std", (x, mean, np.array([1.0, 0.0, 1.0]))), ("std", (x, mean, np.array([1.0, -2.0, 1.0]))),
        ("frames", (np.full((4, 3), "a"), mean, std)), ("mean", (x, np.array(["a"] * 3), std)),
        ("std", (x, mean, np.array(["a"] * 3))), ("frames", (np.float64(1.0), mean, std)),
        ("mean", (x, np.zeros((1, 3)), std)), ("std", (x, mean, np.ones(4))),
    ]
    for name, args in bad_cases:
        with pytest.raises(ValueError, match=rf"^{name}:"):
            fn(*args)
    assert fn(np.arange(6).reshape(2, 3), mean, std).dtype == np.float64  # integers become float64


def test_statistics_of_real_expmap_data():
    """spec/data.md §5.5: on the CMU exp-map data the always-zero dimensions get std 1 (DMGNN's rule)."""
    rows = [np.loadtxt(p, delimiter=",") for p in sorted((SAMPLE / "expmap" / "train").glob("*/*.txt"))]
    mean, std = feature_statistics(rows)
    zero_dims = np.flatnonzero(np.all(np.concatenate(rows) == 0, axis=0))
    assert zero_dims.size >= 33 + 8
    assert np.all(std[zero_dims] == 1.0) and np.all(mean[zero_dims] == 0.0)
    assert read_expmap(SAMPLE / "expmap" / "train" / "walking" / "walking_1.txt").num_frames == rows[-5].shape[0]


def test_downsample_keeps_per_frame_translations():
    """spec/data.md §2.1: a motion that keeps per-frame joint translations is downsampled with them."""
    from refimpl import Motion, Skeleton
    from refimpl.preprocess import downsample

    sk = Skeleton([-1, 0], np.array([[0.0, 0, 0], [0, 1, 0]]))
    T = 6
    rot = np.tile(np.array([1.0, 0, 0, 0]), (T, 2, 1))
    tr = np.zeros((T, 2, 3))
    tr[:, 1, 1] = 1.0 + np.arange(T)
    m = Motion(sk, rot, np.zeros((T, 3)), 1 / 30, translations=tr, translated_joints=(1,))
    d = downsample(m, 2, phase=1)
    np.testing.assert_array_equal(d.translations[:, 1, 1], [2.0, 4.0, 6.0])
    np.testing.assert_allclose(d.positions()[:, 1, 1], [2.0, 4.0, 6.0])
