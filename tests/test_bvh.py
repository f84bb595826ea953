"""Tests of refimpl.bvh and refimpl.motion (spec/data.md §1-2).

Real files: frame counts, joint counts and channel layouts as their README files state; write → read round
trips; a catalogue of malformed files, each rejected with a ValueError naming the line and the problem.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from refimpl.bvh import BvhHeader, read_bvh, read_bvh_header
from refimpl.bvh_write import write_bvh
from refimpl.motion import Motion
from refimpl.quat import quat_normalize
from refimpl.rotations import TAIT_BRYAN_ORDERS, matrix_from_quat, quat_from_euler
from refimpl.skeleton import Skeleton, remove_joints
from refimpl.skeletons import cmu_asf_skeleton, h36m_skeleton, quaternet_locomotion_skeleton
from refimpl.strategies import skeleton_arrays, unit_quaternions
from refimpl.testing import assert_close, assert_quat_close

SAMPLE = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample"

SALSA_NAMES = ("hip abdomen chest neck head leftEye rightEye rCollar rShldr rForeArm rHand rThumb1 rThumb2 rIndex1 "
               "rIndex2 rMid1 rMid2 rRing1 rRing2 rPinky1 rPinky2 lCollar lShldr lForeArm lHand lThumb1 lThumb2 "
               "lIndex1 lIndex2 lMid1 lMid2 lRing1 lRing2 lPinky1 lPinky2 rButtock rThigh rShin rFoot lButtock "
               "lThigh lShin lFoot").split()
CGSPEED_NAMES = ("Hips LHipJoint LeftUpLeg LeftLeg LeftFoot LeftToeBase RHipJoint RightUpLeg RightLeg RightFoot "
                 "RightToeBase LowerBack Spine Spine1 Neck Neck1 Head LeftShoulder LeftArm LeftForeArm LeftHand "
                 "LeftFingerBase {LF} LThumb RightShoulder RightArm RightForeArm RightHand RightFingerBase {RF} "
                 "RThumb").split()

# (folder, file, frames, frame time, joints with channels, End Sites, channels per frame, CRLF) from the READMEs
SHARED_FILES = [
    ("acrnn_cmu_salsa", name, frames, 0.00833333, 43, 14, 132, True)
    for name, frames in [("01.bvh", 2243), ("02.bvh", 2102), ("03.bvh", 1831), ("05.bvh", 1679), ("16.bvh", 2243),
                         ("17.bvh", 2102), ("18.bvh", 1831), ("20.bvh", 1679)]
] + [
    ("acrnn_cmu_salsa", "standard.bvh", 3, 0.03333, 43, 14, 132, False),
    ("bvhtodeepmimic_cmu_bvh", "02_01.bvh", 344, 0.0083333, 31, 7, 96, False),
    ("fairmotion_cmu_bvh", "01_01.bvh", 2752, 0.0083333, 31, 7, 96, False),
]


def _check_layout(header: BvhHeader, motion: Motion, frames, frame_time, joints, ends, channels):
    skel = header.skeleton
    assert header.num_frames == frames and motion.num_frames == frames
    assert header.frame_time == frame_time and motion.frame_time == frame_time
    assert len(skel.end_sites) == ends and skel.num_joints == joints + ends == motion.num_joints
    assert header.num_channels == channels
    with_channels = [j for j in range(skel.num_joints) if j not in skel.end_sites]
    assert len(with_channels) == joints
    assert header.channels[0][:3] == ("Xposition", "Yposition", "Zposition")
    assert header.rotation_orders[0] == "zyx"  # root: Zrotation Yrotation Xrotation in every file
    names = [skel.names[j] for j in with_channels]
    if joints == 43:  # salsa: other joints Zrotation Xrotation Yrotation
        assert names == SALSA_NAMES
        assert {header.rotation_orders[j] for j in with_channels[1:]} == {"zxy"}
        assert skel.num_joints == 57  # acRNN's Joints_num
    else:  # cgspeed MotionBuilder-friendly: all ZYX
        assert {header.rotation_orders[j] for j in with_channels} == {"zyx"}
        lf, rf = ("LeftHandIndex1", "RightHandIndex1") if "LeftHandIndex1" in names else ("LFingers", "RFingers")
        assert names == [n.format(LF=lf, RF=rf) for n in CGSPEED_NAMES]
    for j in skel.end_sites:
        assert header.channels[j] == ()
        assert_close(motion.rotations[:, j], np.tile([1.0, 0, 0, 0], (frames, 1)), atol=0)
    # rotations continuous over time (quat_fix applied)
    assert np.all(np.sum(motion.rotations[1:] * motion.rotations[:-1], axis=-1) >= 0)


@pytest.mark.parametrize("folder, name, frames, frame_time, joints, ends, channels, crlf", SHARED_FILES)
def test_real_files_match_their_readme(shared_data, folder, name, frames, frame_time, joints, ends, channels, crlf):
    """spec/data.md §2, §6: each shared BVH gives the frame count, joints and channel layout its README states."""
    path = shared_data / folder / name
    assert (b"\r\n" in path.read_bytes()) == crlf
    header = read_bvh_header(path)
    motion = read_bvh(path)
    _check_layout(header, motion, frames, frame_time, joints, ends, channels)


def test_embedded_sample_files():
    """spec/data.md §6: the embedded sample reads the same way (salsa at its true 60 fps by override)."""
    for rel, frames, joints, ends, channels in [("bvh/01_01.bvh", 2752, 31, 7, 96), ("bvh/02_01.bvh", 344, 31, 7, 96),
                                                ("salsa/01.bvh", 2243, 43, 14, 132),
                                                ("salsa/16.bvh", 2243, 43, 14, 132)]:
        path = SAMPLE / rel
        header = read_bvh_header(path)
        motion = read_bvh(path)
        _check_layout(header, motion, frames, header.frame_time, joints, ends, channels)
    salsa = read_bvh(SAMPLE / "salsa" / "01.bvh", frame_time=1 / 60)
    assert salsa.fps == pytest.approx(60.0) and salsa.name == "01"
    # salsa units are centimetres: hip height about 85 in the first frames (README)
    assert 80 < salsa.root_positions[0, 1] < 90


def test_cgspeed_skeletons_equal_builtin_tables():
    """spec/data.md §3: CMU 02_01's hierarchy is the CMU ASF table; CMU 01_01's is QuaterNet's locomotion table."""
    m02 = read_bvh(SAMPLE / "bvh" / "02_01.bvh")
    assert m02.skeleton == cmu_asf_skeleton()
    m01 = read_bvh(SAMPLE / "bvh" / "01_01.bvh")
    small, _ = remove_joints(m01.skeleton, None, m01.skeleton.end_sites)
    assert_close(small.offsets, quaternet_locomotion_skeleton().offsets, atol=1e-12)
    # first and last root positions of 02_01 (README cross-check)
    assert_close(m02.root_positions[0], [10.4194, 16.7048, -30.1003], atol=0)
    assert_close(m02.root_positions[-1], [11.0237, 17.502, 29.4538], atol=0)


def test_channel_angles_match_hand_conversion():
    """spec/data.md §2: a joint's rotation is R_c0 R_c1 R_c2 of its channels in file order, in degrees."""
    path = SAMPLE / "salsa" / "16.bvh"
    header = read_bvh_header(path)
    motion = read_bvh(path, frame_time=1 / 60)
    text = path.read_bytes().decode().replace("\r\n", "\n")
    row = np.array(text.split("Frame Time:")[1].split("\n")[1 + 7].split(), dtype=float)  # frame index 7
    skel = header.skeleton
    col = 0
    for j, chans in enumerate(header.channels):
        angles = {c[0].lower(): np.deg2rad(row[col + k]) for k, c in enumerate(chans) if c.endswith("rotation")}
        if j == 0:
            assert_close(motion.root_positions[7], row[:3], atol=0)  # position channels replace the OFFSET
        if angles:
            order = header.rotation_orders[j]
            expected = quat_from_euler(np.array([angles[a] for a in order]), order)
            assert_quat_close(motion.rotations[7, j], expected, atol=1e-14)
        col += len(chans)


# ------------------------------------------------------------------------------------------------------------
# writing and round trips (spec/data.md §2.2)
# ------------------------------------------------------------------------------------------------------------

def _assert_same_motion(a: Motion, b: Motion, precision: int = 6):
    """Equal to the printed precision: rotations by matrix entries, positions by decimals.

    BVH stores joints depth-first and names End Sites ``<parent>_end``: ``b``'s joints are matched to ``a``'s
    by name (End Sites by their parent), so a skeleton whose index order is not depth-first compares too.
    """
    sa, sb = a.skeleton, b.skeleton
    assert sa.num_joints == sb.num_joints and len(sa.end_sites) == len(sb.end_sites)
    perm = []  # perm[j] = index in b of a's joint j
    for j in range(sa.num_joints):
        if j in sa.end_sites:
            parent_in_b = perm[sa.parents[j]]
            perm.append(next(k for k in sb.children[parent_in_b] if k in sb.end_sites and k not in perm))
        else:
            perm.append(sb.index(sa.names[j]))
    assert [-1] + [perm[p] for p in sa.parents[1:]] == [sb.parents[k] for k in perm]
    assert_close(sb.offsets[perm], sa.offsets, atol=0.51 * 10.0 ** -precision)
    assert_close(b.root_positions, a.root_positions, atol=1.02 * 10.0 ** -precision)  # OFFSET + channel, each rounded
    keep = [j for j in range(sa.num_joints) if j not in sa.end_sites]
    ra = matrix_from_quat(a.rotations[:, keep])
    rb = matrix_from_quat(b.rotations[:, [perm[j] for j in keep]])
    # printed-precision rounding of three angles, plus the documented error of euler_from_quat within its gimbal
    # lock threshold (<= ~sqrt(eps), spec/math.md §3.2), which shows once the printed precision is finer than it
    gimbal = 2 * np.sqrt(np.finfo(np.float64).eps)
    assert_close(rb, ra, atol=3 * np.deg2rad(0.5 * 10.0 ** -precision) + gimbal)
    assert b.frame_time == pytest.approx(a.frame_time, rel=1e-9)
    scale = 1 + np.abs(a.positions()).max()
    assert_close(b.positions()[:, perm], a.positions(), atol=2e-5 * 10.0 ** (6 - precision) * scale)


def test_round_trip_real_file_keeps_layout(tmp_path):
    """spec/data.md §2.2: read → write (file's own channel orders) → read is the identity to printed precision,
    and writing twice gives the same text."""
    path = SAMPLE / "salsa" / "01.bvh"
    header = read_bvh_header(path)
    motion = read_bvh(path)
    short = Motion(motion.skeleton, motion.rotations[:150], motion.root_positions[:150], motion.frame_time, "s")
    out = tmp_path / "out.bvh"
    write_bvh(out, short, order=header.rotation_orders)
    back = read_bvh(out)
    assert read_bvh_header(out).channels == header.channels
    assert back.skeleton.names == motion.skeleton.names
    _assert_same_motion(short, back)
    out2 = tmp_path / "out2.bvh"
    write_bvh(out2, back, order=read_bvh_header(out).rotation_orders)
    assert out2.read_text() == out.read_text()
    # and the printed numbers are exactly the file's own for the channels (6 decimals in, 6 out)
    assert_close(read_bvh(out2).rotations, back.rotations, atol=1e-12)


@settings(max_examples=15)
@given(skeleton_arrays(1, 7), st.integers(1, 4), st.sampled_from(TAIT_BRYAN_ORDERS), st.integers(3, 9),
       st.data())
def test_round_trip_random_motion(tmp_path_factory, arrays, frames, order, precision, data):
    """spec/data.md §2.2: write → read is the identity to printed precision, for any Tait-Bryan order."""
    parents, offsets = arrays
    leaves = [j for j in range(1, len(parents)) if j not in parents]
    ends = leaves[:1]
    skel = Skeleton(parents, offsets, end_sites=ends)
    rot = data.draw(unit_quaternions((frames, len(parents))))
    rot[:, ends] = [1.0, 0, 0, 0]
    root = data.draw(st.lists(st.floats(-100, 100), min_size=3 * frames, max_size=3 * frames))
    motion = Motion(skel, rot, np.array(root).reshape(frames, 3), 1 / 30, "random")
    out = tmp_path_factory.mktemp("bvh") / "random.bvh"
    write_bvh(out, motion, order=order, precision=precision)
    back = read_bvh(out)
    _assert_same_motion(motion, back, precision)


def test_write_per_joint_orders_and_syntax(tmp_path):
    """spec/data.md §2.2: standard syntax (tabs, End Site blocks, 6 root channels), per-joint orders."""
    skel = h36m_skeleton()
    rng = np.random.default_rng(0)
    rot = quat_normalize(rng.normal(size=(3, 32, 4)))
    rot[:, list(skel.end_sites)] = [1.0, 0, 0, 0]
    motion = Motion(skel, rot, rng.normal(size=(3, 3)), 0.02, "h36m")
    orders = ["zyx", "xyz"] * 16
    out = tmp_path / "h36m.bvh"
    write_bvh(out, motion, order=orders, precision=8)
    text = out.read_text()
    lines = text.split("\n")
    assert lines[:4] == ["HIERARCHY", "ROOT Hips", "{", "\tOFFSET 0.00000000 0.00000000 0.00000000"]
    assert lines[4] == "\tCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"
    assert lines[5] == "\tJOINT RightUpLeg" and lines[8] == "\t\tCHANNELS 3 Xrotation Yrotation Zrotation"
    assert text.count("End Site") == 7 and text.count("JOINT") == 24
    assert "\r" not in text and text.endswith("\n")
    assert re.search(r"^MOTION\nFrames: 3\nFrame Time: 0\.02\n", text, re.MULTILINE)
    header = read_bvh_header(out)
    assert [header.rotation_orders[j] for j in range(32) if j not in skel.end_sites] == \
        [orders[j] for j in range(32) if j not in skel.end_sites]
    _assert_same_motion(motion, read_bvh(out), 8)


def test_write_is_atomic_and_validates(tmp_path):
    """spec/data.md §2.2: atomic replace, no temporary left behind; bad arguments raise before touching the file."""
    motion = read_bvh(SAMPLE / "bvh" / "02_01.bvh")
    out = tmp_path / "walk.bvh"
    out.write_text("old content")
    write_bvh(out, motion)
    assert read_bvh(out).num_frames == 344
    assert sorted(os.listdir(tmp_path)) == ["walk.bvh"]
    before = out.read_text()
    with pytest.raises(ValueError, match="precision"):
        write_bvh(out, motion, precision=0)
    with pytest.raises(ValueError, match="order"):
        write_bvh(out, motion, order="zzx")
    with pytest.raises(ValueError, match="one Euler order per joint"):
        write_bvh(out, motion, order=["zyx"] * 3)
    with pytest.raises(ValueError, match="motion"):
        write_bvh(out, "not a motion")
    spaced = Motion(Skeleton([-1, 0], np.zeros((2, 3)), names=["root", "a b"]),
                    np.tile([1.0, 0, 0, 0], (1, 2, 1)), np.zeros((1, 3)), 0.1)
    with pytest.raises(ValueError, match="whitespace"):
        write_bvh(out, spaced)
    with pytest.raises(OSError):
        write_bvh(tmp_path / "missing_dir" / "x.bvh", motion)
    assert out.read_text() == before
    assert sorted(os.listdir(tmp_path)) == ["walk.bvh"]


# ------------------------------------------------------------------------------------------------------------
# reader features (spec/data.md §2.1)
# ------------------------------------------------------------------------------------------------------------

SMALL = """HIERARCHY
ROOT Hips
{
  OFFSET 1 2 3
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT LeftLeg
  {
    OFFSET 0 -5 0
    CHANNELS 3 Xrotation Yrotation Zrotation
    End Site
    {
      OFFSET 0 -4 0
    }
  }
  JOINT RightLeg
  {
    OFFSET 0 -5 0
    CHANNELS 3 Yrotation Zrotation Xrotation
    End Site
    {
      OFFSET 0 -4 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
0 0 0 10 20 30 40 50 60 70 80 89
1 2 3 -10 -20 -30 -40 -50 -60 -70 -80 -89
"""


def _write(tmp_path, text, name="f.bvh", newline="\n"):
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode())
    return path


def test_small_file_by_hand(tmp_path):
    """spec/data.md §2.1: root position = its position channels (they replace the OFFSET); per-joint orders;
    End Sites named <parent>_end."""
    m = read_bvh(_write(tmp_path, SMALL))
    s = m.skeleton
    assert s.names == ("Hips", "LeftLeg", "LeftLeg_end", "RightLeg", "RightLeg_end")
    assert s.end_sites == (2, 4) and s.joints_left == (1, 2) and s.joints_right == (3, 4)
    assert_close(m.root_positions, [[0, 0, 0], [1, 2, 3]], atol=0)
    assert_close(m.skeleton.offsets[0], [1, 2, 3], atol=0)
    assert m.frame_time == 0.5 and m.name == "f"
    d = np.deg2rad
    assert_quat_close(m.rotations[0, 0], quat_from_euler(d([10, 20, 30]), "zxy"), atol=1e-15)
    assert_quat_close(m.rotations[1, 1], quat_from_euler(d([-40, -50, -60]), "xyz"), atol=1e-15)
    assert_quat_close(m.rotations[1, 3], quat_from_euler(d([-70, -80, -89]), "yzx"), atol=1e-15)
    assert read_bvh(_write(tmp_path, SMALL), frame_time=0.25, name="x").frame_time == 0.25


@pytest.mark.parametrize("newline", ["\r\n", "\r"])
def test_line_endings_tabs_and_case(tmp_path, newline):
    """spec/data.md §2.1: CRLF, CR, mixed line endings, tabs, lower-case keywords and channel names."""
    ref = read_bvh(_write(tmp_path, SMALL))
    variant = SMALL.replace("  ", "\t").replace("CHANNELS 3 Xrotation", "channels 3 xROTATION")
    variant = variant.replace("End Site", "end site").replace("Frame Time:", "Frame Time:\t")
    m = read_bvh(_write(tmp_path, variant, newline=newline))
    assert_close(m.rotations, ref.rotations, atol=0)
    mixed = SMALL.replace("\n", "\r\n", 5)
    m2 = read_bvh(_write(tmp_path, mixed, name="mixed.bvh"))
    assert_close(m2.rotations, ref.rotations, atol=0)
    # braces on the keyword's line, joint names with spaces kept whole
    compact = SMALL.replace("ROOT Hips\n{", "ROOT Hips {").replace("JOINT LeftLeg\n  {", "JOINT Left Leg {")
    m3 = read_bvh(_write(tmp_path, compact, name="compact.bvh"))
    assert m3.skeleton.names[1] == "Left Leg"
    assert_close(m3.rotations, ref.rotations, atol=0)


def test_partial_channels_and_joint_positions(tmp_path):
    """spec/data.md §2.1: 1-2 rotation channels (missing axes 0), root without position channels, non-root
    position channels folded into the offset when constant, rejected (or averaged) when they vary."""
    text = """HIERARCHY
ROOT r
{
OFFSET 7 8 9
CHANNELS 1 Yrotation
JOINT a
{
OFFSET 1 0 0
CHANNELS 5 Xposition Yposition Zposition Zrotation Xrotation
}
}
MOTION
Frames: 2
Frame Time: 0.1
90 0.5 0 0 10 20
45 0.5 0 0 -10 -20
"""
    m = read_bvh(_write(tmp_path, text))
    assert_close(m.root_positions, [[7, 8, 9], [7, 8, 9]], atol=0)  # no position channels: the OFFSET
    assert_close(m.skeleton.offsets[1], [0.5, 0, 0], atol=0)       # channels replace the OFFSET (1 0 0)
    assert m.translated_joints == ()
    assert_quat_close(m.rotations[0, 0], quat_from_euler(np.deg2rad([90, 0, 0]), "yxz"), atol=1e-15)
    assert_quat_close(m.rotations[1, 1], quat_from_euler(np.deg2rad([-10, -20, 0]), "zxy"), atol=1e-15)
    varying = text.replace("45 0.5 0 0", "45 0.7 0 0")
    raw = read_bvh(_write(tmp_path, varying), translations="keep")
    assert raw.translated_joint_names == ("a",)
    assert_close(raw.translations[:, 1], [[0.5, 0, 0], [0.7, 0, 0]], atol=0)
    # the root rotates (not static): no re-rooting, the varying translation is kept per frame
    auto = read_bvh(_write(tmp_path, varying))
    assert auto.translated_joint_names == ("a",)
    assert_close(auto.positions(), raw.positions(), atol=0)
    with pytest.raises(ValueError, match=r"joint 'a' has translations that vary"):
        read_bvh(_write(tmp_path, varying), translations="rotations")
    # a static root whose only child moves: re-rooted at it, same world positions, no translations left
    static = varying.replace("90 0.5", "0 0.5").replace("45 0.7", "0 0.7")
    raw = read_bvh(_write(tmp_path, static), translations="keep")
    auto = read_bvh(_write(tmp_path, static), translations="rotations")
    assert auto.skeleton.names == ("a",) and auto.translated_joints == ()
    assert_close(auto.positions()[:, 0], raw.positions()[:, 1], atol=1e-12)
    m2 = read_bvh(_write(tmp_path, varying.replace("JOINT a", "JOINT b\n{\nOFFSET 0 1 0\n}\nJOINT a")),
                  translations="mean")
    assert_close(m2.skeleton.offsets[2], [0.6, 0, 0], atol=1e-12)
    with pytest.raises(ValueError, match="translations"):
        read_bvh(_write(tmp_path, text), translations="add")


def test_zero_frames_and_frame_time_override_validation(tmp_path):
    """spec/data.md §2.1: a file with 0 frames is a valid empty motion; a bad override is rejected."""
    text = SMALL.split("Frames:")[0] + "Frames: 0\nFrame Time: 0.5\n"
    m = read_bvh(_write(tmp_path, text))
    assert m.num_frames == 0 and m.rotations.shape == (0, 5, 4) and m.positions().shape == (0, 5, 3)
    for bad in (0, -1, float("nan"), "fast"):
        with pytest.raises(ValueError, match="frame_time"):
            read_bvh(_write(tmp_path, SMALL), frame_time=bad)


# ------------------------------------------------------------------------------------------------------------
# malformed files (spec/data.md §2.3)
# ------------------------------------------------------------------------------------------------------------

def _replace_line(text, lineno, new):
    lines = text.split("\n")
    lines[lineno - 1] = new
    return "\n".join(lines)


MALFORMED = [
    ("empty", "", r":1: empty file"),
    ("no hierarchy keyword", SMALL.replace("HIERARCHY\n", ""), r":1: expected HIERARCHY, got 'ROOT'"),
    ("truncated hierarchy", SMALL.split("  JOINT RightLeg")[0], r"unexpected end of file.*truncated hierarchy"),
    ("hierarchy cut before MOTION", SMALL.replace("  }\n}\nMOTION", "  }\nMOTION"),
     r":24: MOTION before the hierarchy is closed"),
    ("missing MOTION", SMALL.split("MOTION")[0], r"missing MOTION"),
    ("too few channel names",
     SMALL.replace("CHANNELS 3 Xrotation Yrotation Zrotation", "CHANNELS 3 Xrotation Yrotation"),
     r":9: CHANNELS 3 for 'LeftLeg': expected 3 channel names .*found 'End' on line 10 after 2"),
    ("too many channel names", SMALL.replace("CHANNELS 3 Xrotation Yrotation Zrotation",
                                             "CHANNELS 2 Xrotation Yrotation Zrotation"),
     r":9: CHANNELS 2 for 'LeftLeg' lists more than 2"),
    ("unknown channel", SMALL.replace("Yrotation Zrotation Xrotation", "Yrotation Zrotation Wrotation"),
     r":18: CHANNELS 3 for 'RightLeg'.*found 'Wrotation' after 2"),
    ("repeated channel", SMALL.replace("Yrotation Zrotation Xrotation", "Yrotation Zrotation Yrotation"),
     r":18: CHANNELS for 'RightLeg' repeats a channel"),
    ("channel count not a number", SMALL.replace("CHANNELS 3 Xrotation", "CHANNELS three Xrotation"),
     r":9: CHANNELS: expected a channel count, got 'three'"),
    ("channel count too large", SMALL.replace("CHANNELS 3 Xrotation", "CHANNELS 7 Xrotation"),
     r":9: CHANNELS: expected between 0 and 6"),
    ("missing OFFSET", SMALL.replace("    OFFSET 0 -5 0\n    CHANNELS 3 Xrotation", "    CHANNELS 3 Xrotation"),
     r"missing OFFSET for 'LeftLeg'"),
    ("bad OFFSET number", SMALL.replace("OFFSET 1 2 3", "OFFSET 1 two 3"), r":4: OFFSET: expected a number, got 'two'"),
    ("NaN OFFSET", SMALL.replace("OFFSET 1 2 3", "OFFSET 1 nan 3"), r":4: OFFSET: expected a finite number"),
    ("End Site with channels", SMALL.replace("      OFFSET 0 -4 0\n", "      OFFSET 0 -4 0\n      CHANNELS 0\n", 1),
     r":13: an End Site cannot have CHANNELS"),
    ("second root", SMALL.replace("MOTION", "ROOT Other\n{\nOFFSET 0 0 0\n}\nMOTION"), r":25: a second ROOT"),
    ("frames missing", SMALL.replace("Frames: 2\n", ""), r":26: expected 'Frames: <value>'"),
    ("frames negative", SMALL.replace("Frames: 2", "Frames: -2"), r":26: Frames: expected a non-negative integer"),
    ("frames not integer", SMALL.replace("Frames: 2", "Frames: 2.5"), r"Frames: expected a non-negative integer"),
    ("frame time zero", SMALL.replace("Frame Time: 0.5", "Frame Time: 0"), r":27: Frame Time: expected a positive"),
    ("frame time text", SMALL.replace("Frame Time: 0.5", "Frame Time: fast"), r":27: Frame Time: expected a number"),
    ("fewer frames than declared", SMALL.replace("Frames: 2", "Frames: 3"), r":29: Frames: declares 3 frames .* 2"),
    ("more frames than declared", SMALL.replace("Frames: 2", "Frames: 1"), r"declares 1 frames but the file has 2"),
    ("absurd frame count", SMALL.replace("Frames: 2", "Frames: 1000000000000000"),
     r"declares 1000000000000000 frames but the file has 2"),
    ("fewer numbers on a line", _replace_line(SMALL, 29, "1 2 3 -10 -20 -30 -40 -50 -60 -70 -80"),
     r":29: frame 2: expected 12 numbers .* got 11"),
    ("more numbers on a line", _replace_line(SMALL, 28, "0 0 0 10 20 30 40 50 60 70 80 89 1"),
     r":28: frame 1: expected 12 numbers .* got 13"),
    ("non-numeric value", _replace_line(SMALL, 29, "1 2 3 -10 -20 -30 -40 x -60 -70 -80 -89"),
     r":29: frame 2: non-numeric value 'x'"),
    ("NaN value", _replace_line(SMALL, 28, "0 0 0 10 20 nan 40 50 60 70 80 89"),
     r":28: frame 1: non-finite value 'nan'"),
    ("inf value", _replace_line(SMALL, 28, "0 0 0 10 20 inf 40 50 60 70 80 89"), r":28: frame 1: non-finite value"),
    ("channels after a child", SMALL.replace(
        "    CHANNELS 3 Xrotation Yrotation Zrotation\n    End Site\n    {\n      OFFSET 0 -4 0\n    }\n",
        "    End Site\n    {\n      OFFSET 0 -4 0\n    }\n    CHANNELS 3 Xrotation Yrotation Zrotation\n"),
     r":13: CHANNELS for 'LeftLeg' after its first child"),
    ("stray token", SMALL.replace("  JOINT RightLeg", "  BONE RightLeg"), r":15: unexpected 'BONE'"),
    ("End without Site", SMALL.replace("End Site", "End Point", 1), r":10: expected 'End Site', got 'End Point'"),
    ("missing brace", SMALL.replace("ROOT Hips\n{", "ROOT Hips\n"), r":4: expected '\{' after 'Hips', got 'OFFSET'"),
    ("missing joint name", SMALL.replace("JOINT LeftLeg", "JOINT"), r":6: missing joint name"),
    ("duplicate names", SMALL.replace("JOINT RightLeg", "JOINT LeftLeg"), r":15: duplicate joint name 'LeftLeg' \(first on line 6\)"),
    ("not utf-8", None, r"not a UTF-8"),
]


@pytest.mark.parametrize("label, text, match", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_files_are_rejected(tmp_path, label, text, match):
    """spec/data.md §2.3: each malformed variant raises ValueError("<file>:<line>: <problem>")."""
    path = tmp_path / "bad.bvh"
    if text is None:
        path.write_bytes(SMALL.encode() + b"\xff\xfe\x00")
    else:
        path.write_bytes(text.encode())
    with pytest.raises(ValueError, match=match) as info:
        read_bvh(path)
    assert str(path) in str(info.value) or "path" in str(info.value)


def test_missing_file_is_value_error(tmp_path):
    """spec/data.md §2.3: an unreadable path is a ValueError naming it."""
    with pytest.raises(ValueError, match="cannot read"):
        read_bvh(tmp_path / "nope.bvh")


def test_huge_declared_frame_count_does_not_allocate(tmp_path):
    """spec/data.md §2.3: memory is bounded by the file size, not the declared count (10^18 frames, 12 channels)."""
    path = _write(tmp_path, SMALL.replace("Frames: 2", "Frames: 1000000000000000000"))
    header = read_bvh_header(path)  # the header alone is fine to read
    assert header.num_frames == 10 ** 18
    with pytest.raises(ValueError, match="declares 1000000000000000000 frames"):
        read_bvh(path)


# ------------------------------------------------------------------------------------------------------------
# Motion value (spec/data.md §1)
# ------------------------------------------------------------------------------------------------------------

def test_motion_value_and_validation():
    """spec/data.md §1: read-only arrays, derived properties, FK positions, validation of every field."""
    skel = Skeleton([-1, 0], [[0, 0, 0], [1, 0, 0]])
    rot = np.tile([1.0, 0, 0, 0], (3, 2, 1))
    m = Motion(skel, rot, np.zeros((3, 3)), 1 / 120, "m")
    assert m.num_frames == 3 and m.num_joints == 2 and m.fps == pytest.approx(120) and m.duration == 3 / 120
    assert not m.rotations.flags.writeable and not m.root_positions.flags.writeable
    rot[0, 0, 0] = 5.0  # the motion holds its own copy
    assert m.rotations[0, 0, 0] == 1.0
    assert_close(m.positions(), np.tile([[0.0, 0, 0], [1, 0, 0]], (3, 1, 1)), atol=0)
    m32 = Motion(skel, np.tile(np.float32([1, 0, 0, 0]), (3, 2, 1)), np.zeros((3, 3), np.float32), 0.1)
    assert m32.rotations.dtype == np.float32 and m32.positions().dtype == np.float32
    good = np.tile([1.0, 0, 0, 0], (3, 2, 1))
    with pytest.raises(ValueError, match="skeleton"):
        Motion("skel", good, np.zeros((3, 3)), 0.1)
    with pytest.raises(ValueError, match=r"rotations: expected shape \(T, 2, 4\)"):
        Motion(skel, good[:, :1], np.zeros((3, 3)), 0.1)
    with pytest.raises(ValueError, match="root_positions"):
        Motion(skel, good, np.zeros((2, 3)), 0.1)
    with pytest.raises(ValueError, match="unit quaternions"):
        Motion(skel, good * 2, np.zeros((3, 3)), 0.1)
    with pytest.raises(ValueError, match="NaN"):
        Motion(skel, good, np.full((3, 3), np.nan), 0.1)
    for bad in (0.0, -1.0, float("inf"), "x"):
        with pytest.raises(ValueError, match="frame_time"):
            Motion(skel, good, np.zeros((3, 3)), bad)
    with pytest.raises(ValueError, match="name"):
        Motion(skel, good, np.zeros((3, 3)), 0.1, name=3)
