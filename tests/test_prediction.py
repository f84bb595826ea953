"""Short-term prediction task (refimpl/tasks/prediction.py; spec/prediction.md): data loaders, the published
window sampler, the Euler error, baselines with known answers, table and JSON output, and the baselines on the
real CMU exp-map test files."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, strategies as st

from refimpl.protocols import prediction as PP
from refimpl.protocols import prediction_data as PD
from refimpl.rotations import quat_from_axis_angle
from refimpl.strategies import unit_quaternions
from refimpl.tasks import prediction as P

SAMPLE_CMU = P.__file__.rsplit("tasks", 1)[0] + "data/sample/expmap"


# ------------------------------------------------------------------------------------------------------------
# synthetic Human3.6M files: 99 values per row = translation triplet + 32 exp-maps, 50 Hz
# ------------------------------------------------------------------------------------------------------------

def _write_h36m(path, expmaps, translation=None):
    """expmaps: (T, 32, 3) in the file's convention (the reader negates); translation (T, 3) junk."""
    T = expmaps.shape[0]
    tr = np.random.default_rng(0).normal(size=(T, 3)) * 100 if translation is None else translation
    rows = np.concatenate([tr[:, None], expmaps], axis=1).reshape(T, 99)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(",".join(repr(float(v)) for v in r) for r in rows) + "\n")


def _ramp(T, rates):
    """File exp-maps of joints rotating about x at ``rates[j]`` rad per 50 Hz frame (q = quat(−e) → +angle)."""
    e = np.zeros((T, 32, 3))
    n = np.arange(T)
    for j, w in rates.items():
        e[:, j, 0] = -w * n
    return e


@pytest.fixture
def h36m_dir(tmp_path):
    """S5 walking (460 / 400 rows at 50 Hz → 230 / 200 at 25 Hz) and eating, S1 and S6 walking."""
    root = tmp_path / "h36m"
    rates = {3: 0.006, 17: 0.003, 0: 0.004}                  # joint 0 ramps too: the protocol drops it
    _write_h36m(root / "S5" / "walking_1.txt", _ramp(460, rates))
    _write_h36m(root / "S5" / "walking_2.txt", _ramp(400, rates))
    _write_h36m(root / "S5" / "eating_1.txt", np.zeros((420, 32, 3)))
    _write_h36m(root / "S5" / "eating_2.txt", np.zeros((440, 32, 3)))
    for s in ("S1", "S6"):
        _write_h36m(root / s / "walking_1.txt", _ramp(21, {5: 0.01}))
        _write_h36m(root / s / "walking_2.txt", _ramp(20, {5: 0.01}))
    (root / "S5" / "README").write_text("not a data file")     # non-.txt files are ignored
    (root / "other").mkdir()                                   # non-subject folders are ignored
    return root


# ------------------------------------------------------------------------------------------------------------
# protocol: the window sampler
# ------------------------------------------------------------------------------------------------------------

def _expected_starts(lengths, n, low, P_, K):
    rng = np.random.RandomState(1234567890)
    return [(i, rng.randint(low, t - P_ - K)) for _ in range(n) for i, t in enumerate(lengths)]


def test_window_starts_reproduce_the_published_sampler():
    standard = PP.make_protocol("h36m")
    got = PP.window_starts([200, 230], standard)
    assert got == _expected_starts([200, 230], 4, 16, 50, 100)
    # literal pin (RandomState's legacy stream is stable across NumPy versions)
    assert got == [(0, 18), (1, 79), (0, 28), (1, 67), (0, 49), (1, 59), (0, 30), (1, 25)]
    dense = PP.window_starts([200, 230], PP.make_protocol("h36m", dense=True))
    assert len(dense) == 256 and dense == _expected_starts([200, 230], 128, 16, 50, 100)
    assert dense[:8] == got                                    # same stream, more draws
    assert all(16 <= s < t - 150 for (i, s), t in zip(dense, [200, 230] * 128))
    # CMU adaptation: K = 25, low = 0, one sub-sequence
    assert PP.window_starts([81], PP.make_protocol("cmu")) == [(0, 2), (0, 4), (0, 3), (0, 1)]
    assert PP.window_starts([179], PP.make_protocol("cmu")) == [(0, 2), (0, 102), (0, 47), (0, 12)]


def test_window_starts_rejects_short_sequences():
    with pytest.raises(ValueError, match="too short"):
        PP.window_starts([200, 166], PP.make_protocol("h36m"))   # 166 − 150 = 16: empty range [16, 16)
    assert PP.window_starts([167], PP.make_protocol("h36m", samples_per_sequence=3)) == [(0, 16)] * 3
    with pytest.raises(ValueError):
        PP.window_starts([], PP.make_protocol("h36m"))


def test_protocols():
    s, d, c = PP.make_protocol(), PP.make_protocol(dense=True), PP.make_protocol("cmu")
    assert (s.name, s.samples_per_sequence, s.prefix_length, s.target_length, s.low, s.seed) == \
        ("standard", 4, 50, 100, 16, 1234567890)
    assert (d.name, d.samples_per_sequence) == ("dense", 128)
    assert s.horizons_ms[:6] == (80, 160, 320, 400, 560, 1000)
    assert s.horizon_frames == (1, 3, 7, 9, 13, 24, 49, 74, 99)
    assert (c.target_length, c.low, c.horizon_frames) == (25, 0, (1, 3, 7, 9, 13, 24))
    with pytest.raises(ValueError, match="horizons_ms"):
        PP.Protocol(name="x", samples_per_sequence=4, horizons_ms=(100,))
    with pytest.raises(ValueError, match="horizons_ms"):
        PP.Protocol(name="x", samples_per_sequence=4, target_length=10, horizons_ms=(800,))
    with pytest.raises(ValueError, match="samples_per_sequence"):
        PP.Protocol(name="x", samples_per_sequence=0)
    with pytest.raises(ValueError, match="dataset"):
        PP.make_protocol("amass")


def test_windows_from_a_synthetic_directory_follow_the_seed(h36m_dir):
    data = PD.load_h36m(h36m_dir)
    assert data.test_actions() == ("walking", "eating")        # the published order
    for action, lengths in (("walking", [230, 200]), ("eating", [210, 220])):
        prefix, target, windows = PP.evaluation_windows(data, action, PP.make_protocol())
        exp = _expected_starts(lengths, 4, 16, 50, 100)
        assert [(w[0].rsplit("_", 1)[1], w[1]) for w in windows] == [(f"{i + 1}.txt", s) for i, s in exp]
        assert prefix.shape == (8, 50, 32, 4) and target.shape == (8, 100, 32, 4)
    # the walking windows hold the right frames: joint 3 is at angle 0.006 · (50 Hz row) = 0.012 · frame
    prefix, target, windows = PP.evaluation_windows(data, "walking", PP.make_protocol())
    for n, (_, s) in enumerate(windows):
        angle = 2 * np.arctan2(prefix[n, :, 3, 1], prefix[n, :, 3, 0])
        np.testing.assert_allclose(angle, 0.012 * np.arange(s, s + 50), atol=1e-12)
        angle = 2 * np.arctan2(target[n, :, 3, 1], target[n, :, 3, 0])
        np.testing.assert_allclose(angle, 0.012 * np.arange(s + 50, s + 150), atol=1e-12)
    # the starts pinned literally for this directory
    assert [w[1] for w in windows] == [(_expected_starts([230, 200], 4, 16, 50, 100))[i][1] for i in range(8)]
    assert [w[1] for w in windows] == [18, 28, 67, 49, 59, 30, 25, 20]


# ------------------------------------------------------------------------------------------------------------
# data: splits, decimation, conversion
# ------------------------------------------------------------------------------------------------------------

def test_h36m_splits_and_both_strides(h36m_dir):
    data = PD.load_h36m(h36m_dir)
    assert data.dataset == "h36m" and data.skeleton.num_joints == 32 and data.frame_time == pytest.approx(0.04)
    assert sorted(s.key for s in data.train) == sorted(
        f"{s}/walking_{k}_d{p}" for s in ("S1", "S6") for k in (1, 2) for p in (0, 1))
    assert [s.key for s in data.test] == ["S5/walking_1_d0", "S5/walking_2_d0", "S5/eating_1_d0", "S5/eating_2_d0"]
    assert data.valid == ()
    val = PD.load_h36m(h36m_dir, validation=True)
    assert {s.subject for s in val.train} == {"S1"} and {s.subject for s in val.valid} == {"S6"}
    assert {s.phase for s in val.valid} == {0, 1}
    only = PD.load_h36m(h36m_dir, actions=["eating"])
    assert only.train == () and only.test_actions() == ("eating",)
    with pytest.raises(ValueError, match="unknown"):
        PD.load_h36m(h36m_dir, actions=["jogging"])


def test_decimation_keeps_both_strides_and_converts_with_negated_expmap(h36m_dir):
    data = PD.load_h36m(h36m_dir)
    d0, d1 = [s for s in data.train if s.subject == "S1" and s.subaction == 1]
    assert (d0.phase, d1.phase, d0.num_frames, d1.num_frames) == (0, 1, 11, 10)   # 21 rows → 11 + 10
    rows = np.arange(21)
    for seq, sel in ((d0, rows[0::2]), (d1, rows[1::2])):
        expected = quat_from_axis_angle(np.stack([0.01 * sel, 0 * sel, 0 * sel], axis=-1))   # −e = +0.01 n x̂
        np.testing.assert_allclose(seq.rotations[:, 5], expected, atol=1e-15)
        np.testing.assert_array_equal(seq.rotations[:, 1], np.tile([1.0, 0, 0, 0], (seq.num_frames, 1)))
        assert seq.frame_time == pytest.approx(0.04)
    assert not d0.rotations.flags.writeable


def test_antipodal_continuity_after_decimation(tmp_path):
    # joint 2 spins at 170° per 50 Hz frame: consecutive 50 Hz frames stay in one hemisphere, but the 25 Hz
    # frames (340° apart) would not without a second quat_fix
    root = tmp_path / "h"
    _write_h36m(root / "S1" / "walking_1.txt", _ramp(30, {2: math.radians(170)}))
    _write_h36m(root / "S1" / "walking_2.txt", _ramp(30, {}))
    data = PD.load_h36m(root)
    for s in data.train:
        dots = np.sum(s.rotations[1:] * s.rotations[:-1], axis=-1)
        assert np.all(dots >= 0)


def test_cmu_loader_on_the_embedded_sample():
    data = PD.load_cmu(SAMPLE_CMU)
    assert data.dataset == "cmu" and data.skeleton.num_joints == 38
    assert data.frame_time == pytest.approx(1 / 60)
    assert [(s.key, s.num_frames) for s in data.test] == [("cmu/running_1_d0", 81), ("cmu/walking_1_d0", 179)]
    assert len(data.train) == 20 and {s.phase for s in data.train} == {0, 1}
    walk1 = [s for s in data.train if s.action == "walking" and s.subaction == 1]
    assert [s.num_frames for s in walk1] == [172, 171]                                  # 344 rows − 1 reference
    keep = PD.load_cmu(SAMPLE_CMU, drop_reference_frame=False)
    assert [s.num_frames for s in keep.test] == [82, 180]
    assert data.test_actions() == ("running", "walking")


# ------------------------------------------------------------------------------------------------------------
# malformed inputs
# ------------------------------------------------------------------------------------------------------------

def test_malformed_directories_raise_naming_the_file(tmp_path, h36m_dir):
    with pytest.raises(ValueError, match="no subject folders"):
        PD.load_h36m(tmp_path / "h36m" / "other")
    with pytest.raises(ValueError, match="not a directory"):
        PD.load_h36m(tmp_path / "missing")
    bad = h36m_dir / "S5" / "walking.txt"
    bad.write_text("0," * 98 + "0\n")
    with pytest.raises(ValueError, match=r"walking\.txt"):
        PD.load_h36m(h36m_dir)
    bad.unlink()
    (h36m_dir / "S1" / "jogging_1.txt").write_text("0," * 98 + "0\n")
    with pytest.raises(ValueError, match=r"jogging_1\.txt"):
        PD.load_h36m(h36m_dir)
    (h36m_dir / "S1" / "jogging_1.txt").unlink()
    (h36m_dir / "S1" / "walking_2.txt").write_text("0," * 97 + "0\n")           # 98 values
    with pytest.raises(ValueError, match=r"S1/walking_2\.txt:1"):
        PD.load_h36m(h36m_dir)
    _write_h36m(h36m_dir / "S1" / "walking_2.txt", np.zeros((5, 32, 3)))
    (h36m_dir / "S5" / "eating_2.txt").unlink()
    with pytest.raises(ValueError, match=r"S5/eating_2\.txt: missing"):
        PD.load_h36m(h36m_dir)


def test_too_short_test_sequence_names_the_file(tmp_path):
    root = tmp_path / "h"
    _write_h36m(root / "S5" / "posing_1.txt", np.zeros((400, 32, 3)))
    _write_h36m(root / "S5" / "posing_2.txt", np.zeros((300, 32, 3)))                  # 150 frames at 25 Hz
    data = PD.load_h36m(root)
    with pytest.raises(ValueError, match=r"posing_2\.txt"):
        PP.evaluate(PP.zero_velocity, data, PP.make_protocol())


def test_cmu_malformed(tmp_path):
    with pytest.raises(ValueError, match="no 'train' or 'test'"):
        PD.load_cmu(tmp_path)
    (tmp_path / "test" / "walking").mkdir(parents=True)
    (tmp_path / "test" / "walking" / "running_1.txt").write_text("0," * 116 + "0\n" + "0," * 116 + "0\n")
    with pytest.raises(ValueError, match=r"running_1\.txt"):
        PD.load_cmu(tmp_path)


def test_method_output_shape_is_checked(h36m_dir):
    data = PD.load_h36m(h36m_dir)
    with pytest.raises(ValueError, match="expected output shape"):
        PP.evaluate(lambda prefix, k: prefix[:, -k:], data, PP.make_protocol(), method_name="bad")
    with pytest.raises(ValueError, match="method"):
        PP.evaluate("zero", data, PP.make_protocol())
    with pytest.raises(ValueError, match="not finite"):
        PP.evaluate(lambda prefix, k: np.full(prefix.shape[:1] + (k,) + prefix.shape[2:], np.nan), data,
                   PP.make_protocol(), method_name="nan")
    with pytest.raises(ValueError, match="batch_size"):
        PP.evaluate(PP.zero_velocity, data, PP.make_protocol(), batch_size=0)
    with pytest.raises(ValueError, match="jogging"):
        PP.evaluate(PP.zero_velocity, data, PP.make_protocol(), actions=["jogging"])


# ------------------------------------------------------------------------------------------------------------
# error and baselines with known answers
# ------------------------------------------------------------------------------------------------------------

def test_constant_motion_has_zero_error(h36m_dir):
    data = PD.load_h36m(h36m_dir, actions=["eating"])
    for name, m in PP.baseline_methods().items():
        res = PP.evaluate(m, data, PP.make_protocol(), method_name=name)
        assert res.actions["eating"] == [0.0] * 9
    rng = np.random.default_rng(1)
    q = quat_from_axis_angle(rng.normal(size=(3, 1, 5, 3)))
    prefix = np.repeat(q, 10, axis=1)                                                  # (3, 10, 5, 4) constant
    target = np.repeat(q, 7, axis=1)
    assert np.all(PP.euler_errors(PP.zero_velocity(prefix, 7), target) == 0)
    np.testing.assert_allclose(PP.euler_errors(PP.running_average(4)(prefix, 7), target), 0, atol=1e-12)


def test_linear_ramp_errors_in_closed_form(h36m_dir):
    # joints 3 and 17 rotate about x at 0.012 and 0.006 rad per 25 Hz frame (joint 0 too, but it is dropped):
    # zero-velocity error at future frame i is (i + 1)·|ω|, running average over k is (i + 1 + (k − 1)/2)·|ω|
    data = PD.load_h36m(h36m_dir, actions=["walking"])
    speed = math.hypot(0.012, 0.006)
    i = np.arange(100)
    for name, k in (("zero-velocity", 1), ("run. avg. 2", 2), ("run. avg. 4", 4)):
        method = PP.zero_velocity if k == 1 else PP.running_average(k)
        res = PP.evaluate(method, data, PP.make_protocol(), method_name=name)
        np.testing.assert_allclose(res.curves["walking"], (i + 1 + (k - 1) / 2) * speed, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(res.actions["walking"],
                                   [(f + 1 + (k - 1) / 2) * speed for f in res.protocol.horizon_frames], rtol=1e-9)
        assert res.windows_per_action == {"walking": 8}
    dense = PP.evaluate(PP.zero_velocity, data, PP.make_protocol(dense=True), batch_size=50)
    assert dense.windows_per_action == {"walking": 256}
    np.testing.assert_allclose(dense.curves["walking"], (i + 1) * speed, rtol=1e-9)


def test_running_average_is_the_euler_mean_of_the_last_frames():
    rng = np.random.default_rng(2)
    angles = rng.uniform(-1.2, 1.2, size=(2, 6, 4, 3))                                 # zyx, in range
    from refimpl.rotations import euler_from_quat, quat_from_euler
    prefix = quat_from_euler(angles, "zyx")
    for k in (1, 2, 4):
        out = PP.running_average(k)(prefix, 3)
        assert out.shape == (2, 3, 4, 4)
        np.testing.assert_allclose(euler_from_quat(out, "zyx"),
                                   np.repeat(angles[:, -k:].mean(axis=1, keepdims=True), 3, axis=1), atol=1e-12)
    np.testing.assert_allclose(PP.running_average(1)(prefix, 2), PP.zero_velocity(prefix, 2), atol=1e-12)
    with pytest.raises(ValueError, match="at least 7 frames"):
        PP.running_average(7)(prefix, 2)
    with pytest.raises(ValueError, match="k"):
        PP.running_average(0)
    with pytest.raises(ValueError, match="n_future"):
        PP.zero_velocity(prefix, 0)
    with pytest.raises(ValueError, match="prefix"):
        PP.zero_velocity(prefix[0], 2)


def test_euler_wrap_around():
    # joint 1 turns about z from 3.0 rad across π: its Euler z angle jumps from ≈ π to ≈ −π
    theta = np.array([3.0, 3.1, 3.2, 3.3])
    track = quat_from_axis_angle(np.stack([0 * theta, 0 * theta, theta], axis=-1))     # (4, 4)
    q = np.tile(np.array([1.0, 0, 0, 0]), (1, 4, 2, 1))
    q[0, :, 1] = track
    prefix, target = q[:, :2], q[:, 2:]                                                # last prefix angle 3.1
    plain = PP.euler_errors(PP.zero_velocity(prefix, 2), target)
    np.testing.assert_allclose(plain[0], [2 * np.pi - 0.1, 2 * np.pi - 0.2], atol=1e-12)  # the published metric
    wrapped = PP.euler_errors(PP.zero_velocity(prefix, 2), target, wrap=True)
    np.testing.assert_allclose(wrapped[0], [0.1, 0.2], atol=1e-12)
    # averaging across ±π is not wrap-aware either (as published): mean(3.0, 3.1) is fine, mean(3.1, −3.08) is ≈ 0
    ra = PP.running_average(2)(q[:, 1:3], 1)
    assert abs(2 * np.arctan2(ra[0, 0, 1, 3], ra[0, 0, 1, 0])) < 0.05


def test_error_drops_joint_0_and_masks_constant_angles():
    q = np.tile(np.array([1.0, 0, 0, 0]), (1, 3, 3, 1))
    pred = q.copy()
    pred[..., 0, :] = quat_from_axis_angle(np.array([0.5, 0, 0]))                     # root: ignored
    assert np.all(PP.euler_errors(pred, q) == 0)
    assert np.allclose(PP.euler_errors(pred, q, drop_joints=()), 0.5)
    pred[..., 2, :] = quat_from_axis_angle(np.array([0, 0.3, 0]))                     # constant GT joint
    assert np.allclose(PP.euler_errors(pred, q), 0.3)
    assert np.all(PP.euler_errors(pred, q, mask_constant=True) == 0)                   # Martinez's std rule
    with pytest.raises(ValueError, match="pred"):
        PP.euler_errors(pred[:, :2], q)
    with pytest.raises(ValueError, match="target"):
        PP.euler_errors(pred[0], q[0])


def _qeuler_zyx(q):
    """QuaterNet's qeuler(·, 'zyx') from its formula table (quaternet_reference_code.md §2.3), as (x, y, z)."""
    q0, q1, q2, q3 = np.moveaxis(q, -1, 0)
    x = np.arctan2(2 * (q0 * q1 + q2 * q3), 1 - 2 * (q1 * q1 + q2 * q2))
    y = np.arcsin(np.clip(2 * (q0 * q2 - q1 * q3), -1, 1))
    z = np.arctan2(2 * (q0 * q3 + q1 * q2), 1 - 2 * (q2 * q2 + q3 * q3))
    return np.stack([x, y, z], axis=-1)


def test_error_matches_the_published_formula_on_real_windows():
    data = PD.load_cmu(SAMPLE_CMU)
    for action in data.test_actions():
        prefix, target, _ = PP.evaluation_windows(data, action, PP.make_protocol("cmu", samples_per_sequence=16))
        pred = PP.running_average(2)(prefix, 25)
        d = _qeuler_zyx(pred[:, :, 1:]) - _qeuler_zyx(target[:, :, 1:])
        oracle = np.sqrt(np.sum(d.reshape(d.shape[0], d.shape[1], -1) ** 2, axis=-1))
        np.testing.assert_allclose(PP.euler_errors(pred, target), oracle, atol=1e-9)


# ------------------------------------------------------------------------------------------------------------
# output
# ------------------------------------------------------------------------------------------------------------

def test_json_schema_and_table(tmp_path, h36m_dir):
    data = PD.load_h36m(h36m_dir)
    results = [PP.evaluate(m, data, PP.make_protocol(), method_name=n) for n, m in PP.baseline_methods().items()]
    path = tmp_path / "out" / "zv.json"
    path.parent.mkdir()
    PP.write_results_json(path, results[-1])
    doc = json.loads(path.read_text())
    assert set(doc) >= {"dataset", "protocol", "method", "samples_per_sequence", "horizons_ms", "actions", "average"}
    assert (doc["dataset"], doc["protocol"], doc["method"], doc["samples_per_sequence"]) == \
        ("h36m", "standard", "zero-velocity", 4)
    assert doc["horizons_ms"] == [80, 160, 320, 400, 560, 1000, 2000, 3000, 4000]
    assert all(isinstance(h, int) for h in doc["horizons_ms"]) and doc["horizon_frames"][0] == 1
    assert list(doc["actions"]) == ["walking", "eating"]
    assert all(len(v) == 9 and all(isinstance(x, float) for x in v) for v in doc["actions"].values())
    np.testing.assert_allclose(doc["average"], np.mean([doc["actions"]["walking"], doc["actions"]["eating"]], axis=0))
    assert doc["windows_per_action"] == {"walking": 8, "eating": 8}
    assert doc["data_frame_time_s"] == pytest.approx(0.04) and doc["frame_ms"] == 40.0
    assert [p.name for p in path.parent.iterdir()] == ["zv.json"]                       # no temporary left
    PP.write_results_json(path, results)
    many = json.loads(path.read_text())
    assert [d["method"] for d in many] == ["run. avg. 4", "run. avg. 2", "zero-velocity"]
    with pytest.raises(ValueError):
        PP.write_results_json(path, [])
    table = PP.format_table(results)
    lines = table.splitlines()
    assert lines[0].startswith("dataset h36m, protocol standard (4 samples per sequence, 8 windows per action)")
    assert lines[1].split("|")[1:4] == ["    80 ", "   160 ", "   320 "]
    assert "walking" in lines and "eating" in lines and "average" in lines
    assert PP.format_table([]) == ""


# ------------------------------------------------------------------------------------------------------------
# the real CMU exp-map test files
# ------------------------------------------------------------------------------------------------------------

# zero-velocity / run. avg. 2 / run. avg. 4 at nominal 80, 160, 320, 400, 560, 1000 ms, standard protocol
CMU_STANDARD = {
    "zero-velocity": {"running": [0.581, 1.017, 1.352, 1.419, 1.538, 1.530],
                      "walking": [0.394, 0.571, 0.845, 0.931, 1.009, 1.345]},
    "run. avg. 2": {"running": [0.701, 1.131, 1.436, 1.475, 1.538, 1.528],
                    "walking": [0.429, 0.617, 0.894, 0.975, 1.042, 1.352]},
    "run. avg. 4": {"running": [0.913, 1.325, 1.582, 1.582, 1.556, 1.546],
                    "walking": [0.524, 0.700, 0.960, 1.031, 1.078, 1.346]},
}


def test_baselines_on_the_cmu_test_files():
    data = PD.load_cmu(SAMPLE_CMU)
    for name, method in PP.baseline_methods().items():
        res = PP.evaluate(method, data, PP.make_protocol("cmu"), method_name=name)
        for action, expected in CMU_STANDARD[name].items():
            np.testing.assert_allclose(res.actions[action], expected, atol=6e-4)
        np.testing.assert_allclose(res.average, np.mean(list(CMU_STANDARD[name].values()), axis=0), atol=6e-4)
    dense = PP.evaluate(PP.zero_velocity, data, PP.make_protocol("cmu", dense=True))
    assert dense.windows_per_action == {"running": 128, "walking": 128}
    np.testing.assert_allclose(dense.average[:4], [0.44, 0.75, 1.10, 1.20], atol=6e-3)


@pytest.mark.shared
def test_baselines_on_the_shared_cmu_copy(shared_data):
    a = PD.load_cmu(shared_data / "dmgnn_cmu_expmap")
    b = PD.load_cmu(SAMPLE_CMU)
    ra = PP.evaluate(PP.zero_velocity, a, PP.make_protocol("cmu"))
    rb = PP.evaluate(PP.zero_velocity, b, PP.make_protocol("cmu"))
    assert ra.actions == rb.actions
    np.testing.assert_allclose(ra.actions["walking"], CMU_STANDARD["zero-velocity"]["walking"], atol=6e-4)


def _rotmat2euler_srnn(m):
    """The SRNN / Martinez et al. evaluation's matrix → Euler rule (away from gimbal lock), as (E1, E2, E3)."""
    e2 = -np.arcsin(m[..., 0, 2])
    e1 = np.arctan2(m[..., 1, 2], m[..., 2, 2])
    e3 = np.arctan2(m[..., 0, 1], m[..., 0, 0])
    return np.stack([e1, e2, e3], axis=-1)


def test_zyx_euler_of_the_negated_expmap_equals_the_srnn_euler_of_the_file_expmap():
    # Martinez et al. take Euler angles of the Rodrigues matrix R(e) of the file's exp-map; the published
    # QuaterNet evaluation takes zyx Euler angles of q = quat(−e). Both give the same (x, y, z), so averaging
    # (running-average baselines) and the error norm agree.
    from refimpl.rotations import euler_from_quat, matrix_from_quat
    e = np.random.default_rng(3).normal(size=(500, 3)) * 1.5
    srnn = _rotmat2euler_srnn(matrix_from_quat(quat_from_axis_angle(e)))
    ours = euler_from_quat(quat_from_axis_angle(-e), "zyx")[..., ::-1]                # (z, y, x) → (x, y, z)
    np.testing.assert_allclose(srnn, ours, atol=1e-9)


def test_table_in_the_spec_is_what_format_table_prints():
    data = PD.load_cmu(SAMPLE_CMU)
    methods = PP.baseline_methods()
    results = [PP.evaluate(methods[n], data, PP.make_protocol("cmu"), method_name=n)
               for n in ("run. avg. 2", "zero-velocity")]
    assert PP.format_table(results) == """\
dataset cmu, protocol standard (4 samples per sequence, 4 windows per action)
horizons at a nominal 40 ms per frame; the data has 16.7 ms per frame
milliseconds     |    80 |   160 |   320 |   400 |   560 |  1000
running
  run. avg. 2    |  0.70 |  1.13 |  1.44 |  1.48 |  1.54 |  1.53
  zero-velocity  |  0.58 |  1.02 |  1.35 |  1.42 |  1.54 |  1.53
walking
  run. avg. 2    |  0.43 |  0.62 |  0.89 |  0.97 |  1.04 |  1.35
  zero-velocity  |  0.39 |  0.57 |  0.85 |  0.93 |  1.01 |  1.35
average
  run. avg. 2    |  0.57 |  0.87 |  1.17 |  1.23 |  1.29 |  1.44
  zero-velocity  |  0.49 |  0.79 |  1.10 |  1.17 |  1.27 |  1.44"""


@given(lengths=st.lists(st.integers(67, 400), min_size=1, max_size=3), n=st.integers(1, 20),
       low=st.integers(0, 16))
def test_window_starts_property(lengths, n, low):
    proto = PP.Protocol(name="x", samples_per_sequence=n, prefix_length=20, target_length=30, low=low,
                       horizons_ms=(40,))
    draws = PP.window_starts(lengths, proto)
    assert [i for i, _ in draws] == list(range(len(lengths))) * n
    assert all(low <= s < lengths[i] - 50 for i, s in draws)
    assert draws == _expected_starts(lengths, n, low, 20, 30)


@given(pred=unit_quaternions((2, 3, 4)), target=unit_quaternions((2, 3, 4)),
       scale=st.floats(0.5, 2.0), flip=st.lists(st.booleans(), min_size=24, max_size=24))
def test_euler_errors_ignore_scale_and_sign(pred, target, scale, flip):
    signs = np.where(np.array(flip).reshape(2, 3, 4, 1), -1.0, 1.0)
    base = PP.euler_errors(pred, target, wrap=True)          # wrap: angles are equal modulo 2π at the ±π seam
    np.testing.assert_allclose(PP.euler_errors(pred * signs * scale, target, wrap=True), base, atol=1e-9)
