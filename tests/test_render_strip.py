"""Tests of the transition strip's parts (refimpl/render_strip.py, refimpl/render.py's grid and colours;
spec/cli.md §Pictures): join frames, left/right shades, a floor grid fixed in the world, foot tracks."""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")
from PIL import Image  # noqa: E402

from refimpl.render_kernel import bone_colors, grid_segments  # noqa: E402
from refimpl.render_strip import join_frames, limb_sides, render_strip  # noqa: E402
from refimpl.rigs import CMU_22_JOINTS  # noqa: E402
from refimpl.skeleton import Skeleton  # noqa: E402

# root, spine, left leg, left foot, right leg, right foot (Y-up)
_PARENTS = np.array([-1, 0, 0, 2, 0, 4])
_NAMES = ["Hips", "Spine", "LeftLeg", "LeftFoot", "RightLeg", "RightFoot"]


def _png(path):
    with Image.open(path) as im:
        return np.asarray(im.convert("RGB"), dtype=np.float64)


def test_join_frames_hold_both_sides_of_each_join():
    assert join_frames(10, 40, 55) == [8, 9, 10, 11, 24, 38, 39, 40, 41]
    assert join_frames(10, 40, 55, middle=0) == [8, 9, 10, 11, 38, 39, 40, 41]
    assert join_frames(1, 3, 3) == [0, 1, 2]  # clipped to the frames that exist
    with pytest.raises(ValueError, match="start, stop"):
        join_frames(5, 5, 10)


def test_limb_sides_from_the_mirror_map():
    skel = Skeleton([-1] + [0] * 21, np.ones((22, 3)), names=list(CMU_22_JOINTS))
    sides = limb_sides(skel)
    names = dict(zip(CMU_22_JOINTS, sides))
    assert names["LeftFoot"] == -1 and names["RightHand"] == 1 and names["Spine"] == 0 and names["Hips"] == 0
    assert (sides == -1).sum() == (sides == 1).sum() == 8
    bandai = ["Hips", "Spine", "UpperLeg_L", "Foot_L", "UpperLeg_R", "Foot_R"]  # no prefixes: suffixes
    assert limb_sides(Skeleton(_PARENTS, np.ones((6, 3)), names=bandai)).tolist() == [0, 0, -1, -1, 1, 1]


def test_bone_colors_shade_left_darker_and_right_lighter():
    cols = np.array(bone_colors("tab:blue", _PARENTS, np.array([0, 0, -1, -1, 1, 1])))  # bones of joints 1..5
    centre, left, right = cols[0], cols[1], cols[3]
    assert left.sum() < centre.sum() < right.sum()
    assert np.allclose(cols[1], cols[2]) and np.allclose(cols[3], cols[4])
    assert len(set(map(tuple, bone_colors("tab:red", _PARENTS)))) == 1


def test_floor_grid_is_fixed_in_the_world():
    """Moving the camera centre by less than a grid step keeps the lines where they are (only clipped)."""
    a = grid_segments(np.array([0.0, 0.0]), 100.0, 0.0)
    b = grid_segments(np.array([13.0, -7.0]), 100.0, 0.0)
    xs = lambda g: sorted({round(s[0, 0], 9) for s in g if s[0, 0] == s[1, 0]})  # noqa: E731  lines along y
    assert set(xs(a)) & set(xs(b)) and all(x % 50 == 0 for x in xs(a) + xs(b))
    assert a[:, :, 2].max() == 0.0


def test_strip_with_sides_and_skating_feet(tmp_path):
    """A character sliding with both feet on the floor: the prediction row shows foot streaks (red shades on the
    floor), the truth (feet planted) none."""
    T = 12
    base = np.array([[0, 90, 0], [0, 140, 0], [-10, 45, 0], [-10, 0, 0], [10, 45, 0], [10, 0, 0]], dtype=float)
    truth = np.broadcast_to(base, (T, 6, 3)).copy()
    slide = truth.copy()
    slide[:, :, 0] += 6.0 * np.arange(T)[:, None]  # 6 cm per frame, feet on the floor
    sides = limb_sides(Skeleton(_PARENTS, np.ones((6, 3)), names=_NAMES))
    args = dict(frames=join_frames(2, 10, T), highlight=(2, 10), sides=sides, labels=("truth", "slide"))
    with_feet = _png(render_strip(tmp_path / "a.png", truth, _PARENTS, prediction=slide, feet=[3, 5], **args))
    no_feet = _png(render_strip(tmp_path / "b.png", truth, _PARENTS, prediction=slide, **args))
    h = with_feet.shape[0]
    diff = np.abs(with_feet - no_feet).sum(axis=-1) > 30
    assert diff[h // 2:].sum() > 3 * max(1, diff[:h // 2].sum())  # streaks (prediction) against dots (truth)
    with pytest.raises(ValueError, match="sides"):
        render_strip(tmp_path / "c.png", truth, _PARENTS, sides=[0, 0, 2, 0, 0, 0])
    with pytest.raises(ValueError, match="feet"):
        render_strip(tmp_path / "c.png", truth, _PARENTS, feet=[9])


def test_limb_sides_follow_the_names_over_a_swapped_mirror_map():
    """The one rule of every model's pictures: the side a joint's name says (prefix or suffix), else its
    parent's (an End Site); the mirror map only for a skeleton whose names say no side."""
    parents = [-1, 0, 1, 0, 3, 0]
    names = ["Hips", "LeftHand", "LeftHand_end", "rShldr", "finger", "Spine"]
    skel = Skeleton(parents, np.ones((6, 3)), names=names, joints_left=[3], joints_right=[1])  # swapped map
    assert limb_sides(skel).tolist() == [0, -1, -1, 1, 1, 0]
    anonymous = Skeleton(parents, np.ones((6, 3)), joints_left=[1], joints_right=[3])  # joint_0 ... joint_5
    assert limb_sides(anonymous).tolist() == [0, -1, 0, 1, 0, 0]


def test_a_lifted_foot_leaves_no_dot_behind(tmp_path):
    """The foot track is drawn only for a foot in contact at the frame shown (old: the contact steps of the
    last 6 frames, so a toe just lifted left a dot on the floor detached from its foot — the demo strip's
    'toe dot')."""
    T = 10
    base = np.array([[0, 90, 0], [0, 140, 0], [-10, 45, 0], [-10, 0, 0], [10, 45, 0], [10, 0, 0]], dtype=float)
    pos = np.broadcast_to(base, (T, 6, 3)).copy()
    pos[:6, 3, 0] += 1.5 * np.arange(6)  # the left foot slides a little while planted ...
    pos[6:, 2:4, 1] += 12.0              # ... then lifts (12 cm) from frame 6 on
    args = dict(frames=[7], sides=limb_sides(Skeleton(_PARENTS, np.ones((6, 3)), names=_NAMES)))
    with_feet = _png(render_strip(tmp_path / "a.png", pos, _PARENTS, feet=[3], **args))
    no_feet = _png(render_strip(tmp_path / "b.png", pos, _PARENTS, **args))
    assert np.abs(with_feet - no_feet).max() == 0
    planted = _png(render_strip(tmp_path / "c.png", pos, _PARENTS, feet=[3], frames=[4], sides=args["sides"]))
    bare = _png(render_strip(tmp_path / "d.png", pos, _PARENTS, frames=[4], sides=args["sides"]))
    assert (np.abs(planted - bare).sum(axis=-1) > 30).sum() > 3  # a foot in contact still shows its track


def test_clip_segments_keeps_the_path_inside_the_floor_square():
    from refimpl.render_kernel import clip_segments

    pts = np.array([[-5.0, 0.0], [5.0, 0.0], [5.0, 5.0], [0.5, 0.5]])
    seg = clip_segments(pts, np.array([-1.0, -1.0]), np.array([1.0, 1.0]))
    assert np.allclose(seg, [[[-1, 0], [1, 0]], [[1, 1], [0.5, 0.5]]])
    assert clip_segments(np.array([[3.0, 3.0], [4.0, 3.0]]), -np.ones(2), np.ones(2)).shape == (0, 2, 2)


def test_kernel_titles_floor_and_joint_colours(tmp_path):
    """refimpl/render_kernel.py's small helpers: a wrapped title and its height, a text shrunk into the figure,
    the clip's floor and its square, joint colours in the bone rule's shades, a GIF streamed frame by frame."""
    from refimpl import render_kernel as K

    text = K.wrap_title("word " * 40, 3.0, 10.0)
    assert text.count("\n") >= 2 and max(len(line) for line in text.split("\n")) <= 40
    assert K.title_height("", 10) == 0.0 < K.title_height("a", 10) < K.title_height(text, 10)
    fig = K.figure(2.0, 1.0, 100)
    artist = fig.text(0.5, 0.5, "x" * 80, ha="center", fontsize=12)
    K.fit_text(fig, artist)
    box = artist.get_window_extent(fig.canvas.get_renderer())
    assert artist.get_fontsize() < 12 and (box.x0 >= 0 and box.x1 <= fig.bbox.width or artist.get_fontsize() == 5)
    pos = np.zeros((3, 2, 3))
    pos[1, 1, 2] = -4.0
    assert K.clip_floor(pos) == -4.0
    assert np.allclose(K.floor_square(np.array([1.0, 2.0]), 1.0, -4.0)[:, 2], -4.0)
    cols = K.joint_colors("tab:blue", 3, np.array([-1, 0, 1]))
    assert sum(cols[0]) < sum(cols[1]) < sum(cols[2]) and len(set(K.joint_colors("tab:red", 3))) == 1
    with K.gif_writer(tmp_path / "x.gif", 10.0) as add:
        add(fig)
        artist.set_text("y")
        add(fig)
        add(fig)  # unchanged: still a frame of its own
    with Image.open(tmp_path / "x.gif") as im:
        assert im.n_frames == 3 and im.size == (200, 100) and im.info["loop"] == 0
        im.seek(1)
        second = np.asarray(im.convert("RGB"))
    fig.canvas.draw()
    assert np.abs(second.astype(int) - np.asarray(fig.canvas.buffer_rgba())[..., :3]).max() < 40
    with pytest.raises(ValueError, match="at least one frame"):
        with K.gif_writer(tmp_path / "empty.gif", 10.0):
            pass
    assert not (tmp_path / "empty.gif").exists()
