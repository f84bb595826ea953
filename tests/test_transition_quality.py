"""Tests of the animator's measures (refimpl/protocols/transition_quality.py, spec/qtg.md §9.1) on constructed
motions whose answers are known, and on the embedded sample."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.rigs import CMU_22_JOINTS
from refimpl.skeleton import Skeleton
from refimpl.protocols.transition_quality import (CONTACT_HEIGHT_CM, contact_floor, evaluate_quality, foot_contacts,
                                        foot_joints, format_quality, join_displacement, skate_speed,
                                        step_displacement, window_quality)

DT = 1.0 / 30.0


def _pose(J=5, rng=None):
    """A (J, 3) pose with joint 0..1 'feet' at height 0 and the others above."""
    rng = np.random.default_rng(0) if rng is None else rng
    p = rng.uniform(-20, 20, (J, 3))
    p[:, 1] = rng.uniform(10, 100, J)
    p[:2, 1] = 0.0
    return p


def _slide(N=3, F=12, v=(2.0, 0.0, 1.5), J=5):
    """Every joint moves by ``v`` cm per frame: (N, F, J, 3)."""
    base = _pose(J)
    k = np.arange(F)[None, :, None, None]
    return np.broadcast_to(base + k * np.asarray(v), (N, F, J, 3)).copy()


def test_static_pose_has_zero_displacement_and_skating():
    x = np.broadcast_to(_pose(), (2, 10, 5, 3)).copy()
    assert np.all(step_displacement(x) == 0)
    into, out = join_displacement(x, 2, 8)
    assert np.all(into == 0) and np.all(out == 0)
    speed, share = skate_speed(x, (0, 1), contact_floor(x, (0, 1)), DT)
    assert speed == 0.0 and share == 1.0


def test_constant_velocity_slide_skates_at_that_velocity():
    v = np.array([2.0, 0.0, 1.5])  # cm per frame, horizontal
    x = _slide(v=v)
    speed, share = skate_speed(x, (0, 1), contact_floor(x, (0, 1)), DT)
    assert speed == pytest.approx(np.linalg.norm(v) / DT, rel=1e-12)  # 75 cm/s
    assert share == 1.0
    assert np.allclose(step_displacement(x), np.linalg.norm(v))


def test_vertical_motion_is_not_skating_and_lifted_feet_are_not_in_contact():
    x = _slide(v=(0.0, 0.5, 0.0))  # rising 0.5 cm per frame: contact while within 2 cm of the floor
    floor = contact_floor(x, (0, 1))
    c = foot_contacts(x, (0, 1), floor)
    # heights 0, 0.5, 1, 1.5, 2.0: steps 0-1, 1-2, 2-3 have both frames below 2 cm
    assert c[0, :, 0].tolist() == [True, True, True] + [False] * 8
    speed, share = skate_speed(x, (0, 1), floor, DT)
    assert speed == 0.0 and share == pytest.approx(3 / 11)
    lifted = x.copy()
    lifted[:, :, :2, 1] += 10.0
    speed, share = skate_speed(lifted, (0, 1), floor, DT)
    assert np.isnan(speed) and share == 0.0


def test_a_jump_of_d_at_each_join_is_d():
    d_in, d_out = np.array([3.0, 4.0, 0.0]), np.array([0.0, 0.0, -7.0])
    x = np.broadcast_to(_pose(), (2, 10, 5, 3)).copy()  # past 0-1, generated 2-7, target 8-9
    x[:, 2:8] += d_in  # the generated frames are 5 cm away from the past ...
    x[:, 8:] += d_in + d_out  # ... and the target 7 cm away from them
    into, out = join_displacement(x, 2, 8)
    assert np.allclose(into, 5.0) and np.allclose(out, 7.0)
    q = window_quality(x, np.broadcast_to(_pose(), x.shape) + (x - x), (0, 1), DT)
    assert q["join_in_cm"] == pytest.approx(5.0) and q["join_out_cm"] == pytest.approx(7.0)


def test_window_quality_against_the_truth():
    """Ground truth against itself: equal joins, zero error; ratios against the truth's median step."""
    rng = np.random.default_rng(1)
    gt = np.cumsum(rng.normal(0, 1, (4, 10, 5, 3)), axis=1)
    q = window_quality(gt, gt, (0, 1), DT)
    assert q["first_frame_cm"] == 0 and q["last_frame_cm"] == 0
    g = q["ground_truth"]
    assert q["join_in_cm"] == g["join_in_cm"] and q["join_out_cm"] == g["join_out_cm"]
    assert g["median_step_cm"] == pytest.approx(np.median(step_displacement(gt)))
    assert q["join_in_ratio"] == pytest.approx(q["join_in_cm"] / g["median_step_cm"])
    pred = gt.copy()
    pred[:, 2] += 1.0  # first generated frame off by (1, 1, 1)
    q = window_quality(pred, gt, (0, 1), DT)
    assert q["first_frame_cm"] == pytest.approx(np.sqrt(3)) and q["last_frame_cm"] == 0


def test_bad_inputs():
    x = np.zeros((1, 5, 3, 3))
    with pytest.raises(ValueError, match="start, stop"):
        join_displacement(x, 0, 3)
    with pytest.raises(ValueError, match="height"):
        foot_contacts(x, (0,), np.zeros((1, 1)), height=0.0)
    with pytest.raises(ValueError, match="dt"):
        skate_speed(x, (0,), np.zeros((1, 1)), -1.0)
    with pytest.raises(ValueError, match="pred_pos"):
        window_quality(x, np.zeros((1, 6, 3, 3)), (0,), DT)
    with pytest.raises(ValueError, match="foot"):
        foot_joints(Skeleton([-1, 0], np.zeros((2, 3)), names=["Hips", "Spine"]))


def test_foot_joints_of_the_cmu_rig():
    skel = Skeleton([-1] + [0] * 21, np.zeros((22, 3)), names=list(CMU_22_JOINTS))
    assert [CMU_22_JOINTS[j] for j in foot_joints(skel)] == ["LeftFoot", "LeftToeBase", "RightFoot", "RightToeBase"]


@pytest.fixture(scope="module")
def sample_test():
    from refimpl.tasks.transition import build_datasets

    _, test = build_datasets("sample", 30, 1, test_stride=4)
    return test


def test_evaluate_quality_of_the_truth_and_of_a_pop(sample_test):
    """A method that returns the ground truth has the ground truth's numbers; one shifted by 10 cm pops."""
    _, gt, _ = sample_test.context()

    def truth(past, target, T):
        return gt.copy()

    def shifted(past, target, T):
        out = gt.copy()
        out[..., :3] += np.array([10.0, 0.0, 0.0])
        return out

    q = evaluate_quality(sample_test, {"truth": truth, "shifted": shifted}, batch_size=10 ** 6)
    t, g = q["truth"], q["truth"]["ground_truth"]
    for key in ("join_in_cm", "join_out_cm", "skate_cm_s", "contact_share"):
        assert t[key] == pytest.approx(g[key], rel=1e-12)
    assert t["first_frame_cm"] == 0 and t["last_frame_cm"] == 0
    assert 0.5 < t["join_in_ratio"] < 2.0 and 0.5 < t["join_out_ratio"] < 2.0
    s = q["shifted"]
    assert s["join_in_cm"] > 5.0 and s["join_in_ratio"] > 2.0
    assert s["first_frame_cm"] == pytest.approx(10.0) and s["last_frame_cm"] == pytest.approx(10.0)
    assert q["truth"]["contact_rule"]["height_cm"] == CONTACT_HEIGHT_CM
    labels = np.array([sample_test.sources[i].label for i in sample_test.source_index])
    by = s["by_label"]
    assert sorted(by) == sorted(set(labels)) == ["jump", "run", "salsa", "walk"]
    n = {lab: int((labels == lab).sum()) for lab in by}  # pooled = window-weighted mean of the labels' means
    assert s["join_in_cm"] == pytest.approx(sum(by[lab]["join_in_cm"] * n[lab] for lab in by) / sum(n.values()))
    assert all(by[lab]["first_frame_cm"] == pytest.approx(10.0) for lab in by)
    text = format_quality(q)
    assert "ground truth" in text and "shifted" in text and "LeftToeBase" in text


def test_predict_transitions_batches_and_checks(sample_test):
    """refimpl.protocols.transition_metrics.predict_transitions: batches concatenate to one call's output; a wrong
    shape is refused."""
    from refimpl.protocols.transition_baselines import interpolate
    from refimpl.protocols.transition_metrics import predict_transitions

    past, _, target = sample_test.context()
    whole = interpolate(past, target, sample_test.transition_length)
    assert np.array_equal(predict_transitions(sample_test, interpolate, batch_size=7), whole)
    with pytest.raises(ValueError, match=r"methods\['bad'\]"):
        predict_transitions(sample_test, lambda p, t, T: np.zeros((len(p), T + 1, p.shape[-1])), "bad")
    with pytest.raises(ValueError, match="dataset"):
        predict_transitions(sample_test.select(np.zeros(sample_test.num_windows, bool)), interpolate)
