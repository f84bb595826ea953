"""Per-frame local translations (BVH position channels on non-root joints), spec/data.md §1-§2.

FK with translations against the matrix FK and the slow loop; ``Motion`` validation; re-rooting and folding
keep the world positions; the writer's ``position_channels`` round trips.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from refimpl.bvh import read_bvh, read_bvh_header
from refimpl.bvh_write import write_bvh
from refimpl.motion import (TRANSLATION_TOLERANCE, Motion, fold_constant_translations, reroot_at_child,
                            simplify_translations)
from refimpl.quat import quat_normalize
from refimpl.skeleton import Skeleton, _forward_kinematics_naive


def _motion(rng, T=6, static_root=True, noise=0.0):
    """Static root R -> Hips (moving) -> Spine -> Head + End Site, and Hips -> Leg + End Site."""
    parents = [-1, 0, 1, 2, 3, 1, 5]
    offsets = np.array([[0, 0, 0], [0, 90, 0], [0, 10, 0], [0, 20, 0], [0, 5, 0], [8, -40, 0], [0, -40, 0.0]])
    skel = Skeleton(parents, offsets, names=["Root", "Hips", "Spine", "Head", "Head_end", "Leg", "Leg_end"],
                    end_sites=[4, 6])
    rot = quat_normalize(rng.normal(size=(T, 7, 4)))
    rot[:, [4, 6]] = [1, 0, 0, 0]
    root = np.zeros((T, 3))
    if static_root:
        rot[:, 0] = [1, 0, 0, 0]
    else:
        root = rng.normal(size=(T, 3))
    tr = np.broadcast_to(offsets, (T, 7, 3)).copy()
    tr[:, 1] = offsets[1] + rng.normal(size=(T, 3)) * 30                  # Hips moves
    tr[:, 2] = offsets[2] + rng.uniform(-noise, noise, size=(T, 3))       # Spine constant (+ noise)
    tr[:, 5] = offsets[5] + rng.normal(size=(T, 3))                       # Leg varies
    return Motion(skel, rot, root, 1 / 30, "m", translations=tr, translated_joints=[1, 2, 5])


def test_fk_with_translations_three_ways():
    rng = np.random.default_rng(0)
    m = _motion(rng, static_root=False)
    s = m.skeleton
    a = s.forward_kinematics(m.rotations, m.root_positions, m.translations)
    b = s.forward_kinematics_matrices(m.rotations, m.root_positions, m.translations)
    c = _forward_kinematics_naive(s.parents, m.translations, m.rotations, m.root_positions)
    np.testing.assert_allclose(a, b, atol=1e-12)
    np.testing.assert_allclose(a, c, atol=1e-12)
    np.testing.assert_allclose(m.positions(), a, atol=0)
    # translations equal to the offsets give the plain FK
    plain = s.forward_kinematics(m.rotations, m.root_positions)
    same = s.forward_kinematics(m.rotations, m.root_positions, np.broadcast_to(s.offsets, m.translations.shape))
    np.testing.assert_allclose(same, plain, atol=1e-12)
    with pytest.raises(ValueError, match="translations: expected shape"):
        s.forward_kinematics(m.rotations, m.root_positions, m.translations[:, :3])


def test_motion_translation_fields():
    rng = np.random.default_rng(1)
    m = _motion(rng)
    assert m.translated_joints == (1, 2, 5) and m.translated_joint_names == ("Hips", "Spine", "Leg")
    assert not m.translations.flags.writeable
    np.testing.assert_array_equal(m.translations[:, 3], np.broadcast_to(m.skeleton.offsets[3], (6, 3)))
    assert "translated_joints=('Hips', 'Spine', 'Leg')" in repr(m)
    plain = Motion(m.skeleton, m.rotations, m.root_positions, 0.1)
    assert plain.translations is None and plain.translated_joints == () and plain.translated_joint_names == ()
    every = Motion(m.skeleton, m.rotations, m.root_positions, 0.1, translations=m.translations)
    assert every.translated_joints == (1, 2, 3, 5)                        # default: all but root and End Sites
    for bad in ([0], [4], [7], ["x"], [True]):
        with pytest.raises(ValueError, match="translated_joints"):
            Motion(m.skeleton, m.rotations, m.root_positions, 0.1, translations=m.translations, translated_joints=bad)
    with pytest.raises(ValueError, match="without translations"):
        Motion(m.skeleton, m.rotations, m.root_positions, 0.1, translated_joints=[1])
    with pytest.raises(ValueError, match="translations: expected shape"):
        Motion(m.skeleton, m.rotations, m.root_positions, 0.1, translations=m.translations[:2])
    with pytest.raises(ValueError, match="NaN"):
        Motion(m.skeleton, m.rotations, m.root_positions, 0.1, translations=np.full((6, 7, 3), np.nan))
    with pytest.raises(ValueError, match="translations"):
        dataclasses.replace(m, rotations=m.rotations[:3], root_positions=m.root_positions[:3])


def test_reroot_keeps_world_positions():
    rng = np.random.default_rng(2)
    for static in (True, False):
        m = _motion(rng, static_root=static)
        r = reroot_at_child(m)
        assert r.skeleton.names == m.skeleton.names[1:] and r.skeleton.end_sites == (3, 5)
        assert r.translated_joint_names == ("Spine", "Leg")
        np.testing.assert_allclose(r.positions(), m.positions()[:, 1:], atol=1e-12)
    with pytest.raises(ValueError, match="exactly one child"):
        reroot_at_child(r)                                                 # Hips has Spine and Leg
    with pytest.raises(ValueError, match="motion: expected a Motion"):
        reroot_at_child("m")


def test_fold_and_simplify():
    rng = np.random.default_rng(3)
    m = _motion(rng, noise=1e-5)
    f = fold_constant_translations(m)
    assert f.translated_joint_names == ("Hips", "Leg")                     # Spine folded
    np.testing.assert_allclose(f.positions(), m.positions(), atol=1e-3)
    np.testing.assert_allclose(f.skeleton.offsets[2], m.translations[:, 2].mean(axis=0), atol=0)
    with pytest.raises(ValueError, match="joint 'Hips' has translations that vary"):
        fold_constant_translations(m, varying="error")
    mean = fold_constant_translations(m, varying="mean")
    assert mean.translated_joints == ()
    s = simplify_translations(m)
    assert s.skeleton.names[0] == "Hips" and s.translated_joint_names == ("Leg",)
    np.testing.assert_allclose(s.positions(), m.positions()[:, 1:], atol=1e-3)
    with pytest.raises(ValueError, match="'Leg' has translations that vary"):
        simplify_translations(m, varying="error")
    # a moving root is never removed
    moving = _motion(rng, static_root=False)
    assert simplify_translations(moving).skeleton.names[0] == "Root"
    # tolerance: 0 keeps the noisy Spine per frame
    assert "Spine" in fold_constant_translations(m, tolerance=0).translated_joint_names
    for bad in (-1, float("nan"), "x", True):
        with pytest.raises(ValueError, match="tolerance"):
            fold_constant_translations(m, tolerance=bad)
    with pytest.raises(ValueError, match="varying"):
        simplify_translations(m, varying="drop")
    assert TRANSLATION_TOLERANCE == 1e-4


@pytest.mark.parametrize("mode", ["auto", "all"])
def test_writer_position_channels_round_trip(tmp_path, mode):
    rng = np.random.default_rng(4)
    m = _motion(rng, static_root=False)
    path = tmp_path / "t.bvh"
    write_bvh(path, m, order="zxy", precision=9, position_channels=mode)
    header = read_bvh_header(path)
    six = {header.skeleton.names[j] for j, c in enumerate(header.channels) if len(c) == 6}
    assert six == ({"Root", "Hips", "Spine", "Leg"} if mode == "auto" else {"Root", "Hips", "Spine", "Head", "Leg"})
    back = read_bvh(path, translations="keep")
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-6)
    assert set(back.translated_joint_names) == six - {"Root"}
    np.testing.assert_allclose(back.root_positions, m.root_positions, atol=1e-9)


def test_writer_root_only_refuses_translations(tmp_path):
    rng = np.random.default_rng(5)
    m = _motion(rng)
    with pytest.raises(ValueError, match="position_channels: 'root' would drop"):
        write_bvh(tmp_path / "x.bvh", m, position_channels="root")
    with pytest.raises(ValueError, match="position_channels: expected"):
        write_bvh(tmp_path / "x.bvh", m, position_channels="some")
    s = simplify_translations(m, varying="mean")
    write_bvh(tmp_path / "x.bvh", s, position_channels="root")
    back = read_bvh(tmp_path / "x.bvh")
    np.testing.assert_allclose(back.positions(), s.positions(), atol=1e-5)
