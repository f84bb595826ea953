"""The salsa synthesis protocol (refimpl/protocols/synthesis.py): data, split, frames, windows, seeds, evaluation, training."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from refimpl.bvh import read_bvh
from refimpl.bvh_write import write_bvh
from refimpl.representations import REPRESENTATIONS, positions_from_frames
from refimpl.protocols import synthesis as S

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample" / "salsa"


@pytest.fixture(scope="module")
def motion():
    return S.load_salsa_motion(SAMPLE / "16.bvh")


def test_load_salsa_motion_is_30fps_without_end_sites_in_metres(motion):
    raw = read_bvh(SAMPLE / "16.bvh", frame_time=S.SALSA_FRAME_TIME)
    assert raw.num_frames == 2243 and raw.num_joints == 57
    assert motion.num_frames == 1122 and motion.num_joints == 43
    assert motion.frame_time == pytest.approx(1 / 30)
    assert motion.skeleton.end_sites == ()
    np.testing.assert_allclose(motion.root_positions, raw.root_positions[::2] * 0.01)
    # End Sites carry identity rotations, so the remaining joints' positions are unchanged
    keep = [i for i in range(57) if i not in raw.skeleton.end_sites]
    np.testing.assert_allclose(
        motion.skeleton.forward_kinematics(motion.rotations, motion.root_positions),
        raw.skeleton.forward_kinematics(raw.rotations[::2], raw.root_positions[::2])[:, keep] * 0.01, atol=1e-12)


def test_frames_use_hip_differences(motion):
    f = S.motion_to_frames("quaternions", motion)
    assert f.shape == (1121, 3 + 4 * 43)
    np.testing.assert_allclose(f[:, 0], np.diff(motion.root_positions[:, 0]))
    np.testing.assert_allclose(f[:, 2], np.diff(motion.root_positions[:, 2]))
    np.testing.assert_allclose(f[:, 1], motion.root_positions[:-1, 1])


@pytest.mark.parametrize("rep", list(REPRESENTATIONS))
def test_every_representation_round_trips_motion_frames_motion(motion, rep):
    f = S.motion_to_frames(rep, motion)
    fk = motion.skeleton.forward_kinematics(motion.rotations[:-1], motion.root_positions[:-1])
    if not REPRESENTATIONS[rep].invertible:
        # positions: the stored positions are exactly the root-relative FK positions
        rel = f.copy()
        rel[:, [0, 2]] = 0.0
        np.testing.assert_allclose(positions_from_frames(rep, motion.skeleton, rel) + fk[:, :1] * [1, 0, 1], fk,
                                   atol=1e-12)
        # and back to a motion by the bone directions (spec/kinematics.md §7): the same joint positions
        back = S.frames_to_motion(rep, motion.skeleton, f, start=motion.root_positions[0, [0, 2]])
        np.testing.assert_allclose(back.skeleton.forward_kinematics(back.rotations, back.root_positions), fk,
                                   atol=1e-8)
        return
    back = S.frames_to_motion(rep, motion.skeleton, f, start=motion.root_positions[0, [0, 2]])
    np.testing.assert_allclose(back.skeleton.forward_kinematics(back.rotations, back.root_positions), fk, atol=1e-11)
    d = np.abs(np.sum(back.rotations * motion.rotations[:-1], axis=-1))   # q ≡ −q
    np.testing.assert_allclose(d, 1.0, atol=1e-9)


def test_decoded_frames_write_a_bvh(tmp_path, motion):
    f = S.motion_to_frames("dual_quaternions", motion)[:20]
    back = S.frames_to_motion("dual_quaternions", motion.skeleton, f, name="gen")
    write_bvh(tmp_path / "gen.bvh", back)
    again = read_bvh(tmp_path / "gen.bvh")
    assert again.num_frames == 20 and again.num_joints == 43 + len(again.skeleton.end_sites)


def test_quaternion_frames_are_antipodally_continuous(motion):
    for rep in ("quaternions", "dual_quaternions"):
        f = S.motion_to_frames(rep, motion)
        D = REPRESENTATIONS[rep].dim
        q = f[:, 3:].reshape(len(f), 43, D)[..., :4]
        assert np.all(np.sum(q[1:] * q[:-1], axis=-1) >= 0), rep


def test_load_synthesis_data_sample_split_and_statistics():
    data = S.load_synthesis_data("dual_quaternions", SAMPLE, S.SAMPLE_TRAIN, S.SAMPLE_TEST)
    assert data.train_names == ("01",) and data.test_names == ("16",)
    assert data.frame_size == 3 + 8 * 43 == 347
    np.testing.assert_allclose(data.standardise(data.train[0]).mean(axis=0), 0, atol=1e-9)
    np.testing.assert_allclose(data.destandardise(data.standardise(data.test[0])), data.test[0], atol=1e-12)
    with pytest.raises(ValueError, match="share"):
        S.load_synthesis_data("quaternions", SAMPLE, ("01",), ("01",))


def test_protocol_constants():
    assert [S.horizon_frames(ms) for ms in S.HORIZONS_MS] == [3, 12, 30]
    assert (S.SEED_LENGTH, S.SEED_STRIDE, S.MAX_SEEDS, S.ACCELERATION_FRAMES) == (10, 7, 400, 300)
    assert not set(S.SALSA_TRAIN) & set(S.SALSA_TEST)


def test_seed_windows_are_pinned():
    np.testing.assert_array_equal(S.seed_windows([30, 25], horizon=5),
                                  [[0, 0], [0, 7], [0, 14], [1, 0], [1, 7]])
    # the sample's test take (1121 frames): starts 0, 7, ..., 805 for 10 seed + 300 frames
    w = S.seed_windows([1121], horizon=300)
    assert len(w) == 116 and w[-1].tolist() == [0, 805] and np.all(np.diff(w[:, 1]) == 7)
    assert len(S.seed_windows([1121], horizon=3)) == 159
    assert len(S.seed_windows([5000, 5000], horizon=30)) == 400  # cut at MAX_SEEDS
    assert S.seed_windows([12], horizon=5).shape == (0, 2)


def test_seed_windows_on_the_test_takes(shared_data):
    data = S.load_synthesis_data("ortho6d", shared_data / "acrnn_cmu_salsa")
    assert data.test_names == ("05", "20") and [len(s) for s in data.test] == [839, 839]
    assert [len(s) for s in data.train] == [1121, 1050, 915, 1121, 1050, 915]
    w = S.seed_windows([839, 839], horizon=300)
    assert len(w) == 152 and w[75].tolist() == [0, 525] and w[76].tolist() == [1, 0]


def test_sample_windows_shapes_and_margin():
    rng = np.random.default_rng(0)
    seqs = [np.arange(130.0)[:, None] * np.ones((1, 3)), np.arange(200.0)[:, None] * np.ones((1, 3)) + 1000]
    b = S.sample_windows(rng, seqs, batch_size=64, length=100)
    assert b.shape == (64, 101, 3)
    starts = b[:, 0, 0] % 1000
    assert starts.min() >= 10 and np.all(np.diff(b[:, :, 0], axis=1) == 1)
    assert np.all(starts[b[:, 0, 0] < 1000] <= 130 - 101 - 10)
    with pytest.raises(ValueError, match="at least 101"):
        S.sample_windows(rng, [np.zeros((50, 3))], 2, 100)


def test_evaluate_is_zero_for_the_ground_truth_continuation():
    data = S.load_synthesis_data("quaternions", SAMPLE, S.SAMPLE_TRAIN, S.SAMPLE_TEST)
    test = data.test[0]

    def oracle(seed, n):
        out = []
        for s in data.destandardise(seed):
            start = int(np.argmin(np.abs(test[:len(test) - 10, 3:] - s[0, 3:]).sum(axis=1)))
            out.append(test[start + 10:start + 10 + n])
        return data.standardise(np.stack(out))

    res = S.evaluate_generator(oracle, data, max_seeds=20)
    assert res["num_seeds"] == 20
    for ms, r in res["horizons"].items():
        assert r["frames"] == S.horizon_frames(ms)
        assert r["euclidean"] < 1e-9 and r["npss_power"] < 1e-9 and r["npss_real"] < 1e-9
    assert res["acceleration"]["abs_diff"] < 1e-9 and res["acceleration"]["gt"] > 0
