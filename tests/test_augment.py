"""refimpl.augment: turning a motion about the vertical turns every joint's world position and nothing else."""
import numpy as np
import pytest

from refimpl.augment import random_heading_windows, rotate_heading
from refimpl.bvh import read_bvh
from refimpl.tasks.synthesis import SAMPLE_SALSA


@pytest.fixture(scope="module")
def motion():
    m = read_bvh(SAMPLE_SALSA / "01.bvh")
    return type(m)(m.skeleton, m.rotations[:40], m.root_positions[:40], m.frame_time, m.name)


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def test_world_positions_turn_about_the_vertical(motion):
    a = 0.7
    turned = rotate_heading(motion, a)
    np.testing.assert_allclose(turned.positions(), motion.positions() @ _rot_y(a).T, atol=1e-9)
    np.testing.assert_array_equal(turned.rotations[:, 1:], motion.rotations[:, 1:])
    back = rotate_heading(turned, -a)
    np.testing.assert_allclose(back.positions(), motion.positions(), atol=1e-9)


def test_bad_angle_or_axis_is_refused(motion):
    with pytest.raises(ValueError):
        rotate_heading(motion, 1.0, "w")
    with pytest.raises(ValueError):
        rotate_heading(read_bvh(SAMPLE_SALSA / "01.bvh"), float("nan"))


def test_random_windows_are_reproducible_and_in_range(motion):
    w1, a1 = random_heading_windows(np.random.default_rng(3), [motion], 6, 12, margin=2)
    w2, a2 = random_heading_windows(np.random.default_rng(3), [motion], 6, 12, margin=2)
    np.testing.assert_array_equal(a1, a2)
    assert all(w.num_frames == 12 for w in w1) and np.all(np.abs(a1) <= np.pi)
    for w, a in zip(w1, a1):   # each window is a slice of the motion, turned by its angle
        start = [s for s in range(2, 27) if np.allclose(rotate_heading(w, -a).root_positions,
                                                         motion.root_positions[s:s + 12], atol=1e-9)]
        assert len(start) == 1
    with pytest.raises(ValueError):
        random_heading_windows(np.random.default_rng(0), [motion], 2, 41)
