"""Locomotion data pipeline (spec/locomotion.md §3, §5): rigs, mirroring, phase, the 8 features, augmentation,
splits, per-sequence splines and pace-network data."""
import math
from pathlib import Path

import numpy as np
import pytest

from refimpl.augment import rotate_controls
from refimpl.motion import Motion
from refimpl.protocols import locomotion as L
from refimpl.protocols import locomotion_data as LD
from refimpl.quat import quat_mul, quat_rotate
from refimpl.rotations import euler_from_quat, quat_from_axis_angle, quat_from_euler
from refimpl.mirroring import mirror, rotate_about_up
from refimpl.skeletons import quaternet_locomotion_skeleton
from refimpl.testing import assert_close

SAMPLE_BVH = Path(__file__).resolve().parents[1] / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"


def _straight_walk(speed=0.6, direction=0.4, heading=0.1, height=16.0, frames=120, frame_time=1 / 30):
    """Rigid identity pose translated at constant speed along ``direction`` (radians from +z towards +x),
    the root turned by ``heading`` about +Y."""
    skel = quaternet_locomotion_skeleton()
    rot = np.zeros((frames, skel.num_joints, 4))
    rot[..., 0] = 1.0
    rot[:, 0] = quat_from_axis_angle(np.array([0.0, heading, 0.0]))
    t = np.arange(frames)[:, None]
    pos = np.array([1.0, height, -2.0]) + speed * t * np.array([math.sin(direction), 0.0, math.cos(direction)])
    return Motion(skeleton=skel, rotations=rot, root_positions=pos, frame_time=frame_time, name="walk")


def test_phase_track_on_a_synthetic_gait():
    frames = 61
    # foot speeds: the right foot swings on [0, 10), [20, 30), [40, 50); the left one on [10, 20), [30, 40), [50, 60)
    left_speed = np.array([1.0 if (i // 10) % 2 == 1 else 0.0 for i in range(frames - 1)])
    right_speed = 1.0 - left_speed
    left_speed[12] = 5.0  # a glitch inside the cooldown after the switch at 10 is ignored ...
    lf = np.concatenate([[[0.0, 0, 0]], np.cumsum(left_speed)[:, None] * [[1.0, 0, 0]]])
    rf = np.concatenate([[[0.0, 0, 0]], np.cumsum(right_speed)[:, None] * [[1.0, 0, 0]]])
    ph = LD.build_phase_track(lf, rf)
    assert ph.shape == (frames,)
    # starts with the left foot planted (l[0] < r[0]) → π; each switch adds π at the frame of the switch
    for frame, k in ((0, 1), (10, 2), (20, 3), (30, 4), (40, 5), (50, 6)):
        assert ph[frame] == pytest.approx(k * math.pi)
    assert ph[5] == pytest.approx(1.5 * math.pi) and ph[45] == pytest.approx(5.5 * math.pi)
    assert ph[55] == pytest.approx(6 * math.pi) and ph[-1] == pytest.approx(6 * math.pi)  # constant after the last key
    assert np.all(np.diff(ph) >= 0)
    # same feet, hysteresis larger than the speed difference: no switch at all
    assert_close(LD.build_phase_track(lf, rf, epsilon=10.0), np.full(frames, math.pi))


def test_eight_features_on_a_synthetic_straight_walk():
    speed, direction, heading, height = 0.6, 0.4, 0.1, 16.0
    seqs = LD.build_sequences(_straight_walk(speed, direction, heading, height), LD.CMU_RIG, mirror=False)
    assert [s.name for s in seqs] == ["walk_d0"]
    f = seqs[0].features
    assert f.shape == (120, 8)
    assert_close(f[:, 0], np.zeros(120), atol=1e-12)                       # constant speed: no offset
    assert_close(f[:, 1], np.full(120, height))
    # A = speed; both feet move alike, so the detector never switches: a constant phase (0 or π by rounding)
    assert_close(np.hypot(f[:, 2], f[:, 3]), np.full(120, speed), atol=1e-9)
    assert_close(np.abs(f[:, 2]), np.full(120, speed), atol=1e-9)
    assert np.ptp(seqs[0].phase) == 0
    assert_close(f[:, 4:6], np.tile(speed * np.array([math.sin(direction), math.cos(direction)]), (120, 1)),
                 atol=1e-8)
    assert_close(f[:, 6:8], np.tile([math.sin(heading), math.cos(heading)], (120, 1)), atol=1e-12)
    # the spline and the pace targets of the same walk
    sp = L.sequence_spline(seqs[0])
    x, y = L.pace_training_data(sp)
    assert sp.length == pytest.approx(speed * 119, abs=0.2)
    assert_close(x[:, 0], np.zeros(len(x)), atol=1e-9)
    assert_close(x[:, 1], np.full(len(x), speed), rtol=1e-9)
    delta = heading - direction  # signed angle from the tangent to the facing, in (x, z) coordinates
    assert_close(y, np.tile([speed, 0.0, math.cos(delta), -math.sin(delta)], (len(y), 1)), atol=1e-8)


def test_downsampling_keeps_every_phase():
    m = _straight_walk(frames=121, frame_time=1 / 120)
    seqs = LD.build_sequences(m, LD.CMU_RIG)
    assert [s.name for s in seqs] == [f"walk{m_}_d{k}" for m_ in ("", "_m") for k in range(4)]
    assert [s.num_frames for s in seqs[:4]] == [31, 30, 30, 30]
    assert_close(seqs[1].trajectory[0], m.root_positions[1])
    assert_close(np.hypot(*seqs[0].features[:, 2:4].T), np.full(31, 4 * 0.6), rtol=1e-9)  # speed per 30-Hz frame
    with pytest.raises(ValueError, match="integer multiple"):
        LD.downsample_strides(1 / 50)


def test_facing_is_the_yzx_euler_heading_for_cmu():
    rng = np.random.default_rng(0)
    skel = LD.prepare_motion(_straight_walk(), LD.CMU_RIG).skeleton
    angles = rng.uniform(-1, 1, size=(50, 3)) * [math.pi, 1.2, 1.2]     # (y, z, x)
    rot = np.zeros((50, skel.num_joints, 4))
    rot[..., 0] = 1
    rot[:, 0] = quat_from_euler(angles, "yzx")
    f = LD.facing_vectors(skel, rot, LD.CMU_RIG)
    theta = euler_from_quat(rot[:, 0], "yzx")[:, 0]
    assert_close(f, np.stack([np.sin(theta), np.cos(theta)], axis=-1), atol=1e-9)


def test_rotation_augmentation_and_feature_invariance():
    seq = LD.build_sequences(LD.load_cmu_bvh(SAMPLE_BVH), LD.CMU_RIG, mirror=False, all_phases=False)[0]
    angle = 1.3
    motion = Motion(skeleton=seq.skeleton, rotations=seq.rotations, root_positions=seq.trajectory,
                    frame_time=1 / 30, name="x")
    rot, pos = rotate_about_up(motion.rotations, motion.root_positions, angle)
    turned = LD.build_sequences(Motion(skeleton=motion.skeleton, rotations=rot, root_positions=pos,
                                      frame_time=1 / 30, name="x"), LD.CMU_RIG, mirror=False)[0]
    # offset, height and phase are invariant; direction and facing rotate like the augmentation rotates them
    assert_close(turned.features[:, :4], seq.features[:, :4], atol=1e-9)
    assert_close(turned.features, rotate_controls(seq.features, angle), atol=1e-9)
    # the batch's augmentation = the features of the rotated motion, and the FK targets rotate rigidly
    rng = np.random.default_rng(3)
    b = L.pose_batch([seq], rng, batch_size=3, prefix=10, target=20, augment=True)
    j = seq.skeleton.num_joints
    for k in range(3):
        st, a = b.starts[k], b.angles[k]
        r = np.array([math.cos(a / 2), 0, math.sin(a / 2), 0])
        rot_in = b.inputs[k, :, :4 * j].reshape(30, j, 4)
        assert_close(rot_in[:, 0], quat_mul(r, seq.rotations[st:st + 30, 0]), atol=1e-12)
        assert_close(b.inputs[k, :, 4 * j:], rotate_controls(seq.features[st:st + 30], a), atol=1e-12)
        local_root = seq.trajectory[st + 10:st + 30] * [0, 1, 0]
        fk = seq.skeleton.forward_kinematics(rot_in[10:], local_root)
        assert_close(b.target_positions[k], fk, atol=1e-9)                 # FK of the rotated input = target
        assert_close(b.target_positions[k], quat_rotate(r, seq.positions_local[st + 10:st + 30]), atol=1e-9)
        assert_close(b.target_translations[k], seq.features[st + 10:st + 30, :2])
    plain = L.pose_batch([seq], np.random.default_rng(3), batch_size=2, prefix=10, target=20, augment=False)
    assert np.all(plain.angles == 0) and plain.inputs.shape == (2, 30, 4 * j + 8)
    with pytest.raises(ValueError, match="frames"):
        L.pose_batch([seq], rng, prefix=30, target=60)


def test_mirroring_cmu_matches_quaternet_and_is_an_involution():
    m = LD.prepare_motion(LD.load_cmu_bvh(SAMPLE_BVH), LD.CMU_RIG)
    mm, err = LD.mirror_motion(m)
    assert err < 0.5  # the CMU legs differ in length by up to ~0.26 units
    _, rq, pq = mirror(m.skeleton, m.rotations, m.root_positions)
    dots = np.abs(np.sum(rq * mm.rotations, axis=-1))
    assert np.all(dots > 1 - 1e-3)                                       # QuaterNet's sign flip, within ~3.6°
    assert_close(mm.root_positions, pq)
    back, _ = LD.mirror_motion(mm)
    assert_close(back.positions(), m.positions(), atol=1e-8)
    # with the skeleton made exactly symmetric the mirror image is exact
    sym, _, _ = mirror(m.skeleton, m.rotations, m.root_positions, mirror_offsets=True)
    avg = 0.5 * (m.skeleton.offsets + sym.offsets)
    from refimpl.skeleton import Skeleton
    sk = Skeleton(m.skeleton.parents, avg, names=m.skeleton.names, joints_left=m.skeleton.joints_left,
                  joints_right=m.skeleton.joints_right)
    _, err_sym = LD.mirror_motion(Motion(skeleton=sk, rotations=m.rotations, root_positions=m.root_positions,
                                        frame_time=m.frame_time, name="s"))
    assert err_sym < 1e-9


def test_prepare_motion_keeps_the_papers_26_joints():
    m = LD.prepare_motion(LD.load_cmu_bvh(SAMPLE_BVH), LD.CMU_RIG)
    assert m.skeleton.names == LD.CMU_RIG.keep and m.num_joints == 26
    ref = quaternet_locomotion_skeleton(reduced=True)
    assert_close(m.skeleton.parents, ref.parents)
    assert len(m.skeleton.joints_left) == 10
    with pytest.raises(ValueError, match="needs joints"):
        LD.prepare_motion(m, LD.BANDAI_NAMCO_RIG)


def test_splits_are_file_disjoint(tmp_path):
    names = [f"dataset-2_{c}_{s}_{i:03d}.bvh" for c in ("walk", "run", "walk-turn-left") for s in ("normal", "elderly")
             for i in range(1, 25)]
    train, test = LD.bandai_namco_split(names)
    assert not set(train) & set(test) and len(train) + len(test) == len(names)
    assert all(int(Path(n).stem[-3:]) % 10 == 1 for n in test) and len(test) == 3 * 2 * 3
    with pytest.raises(ValueError, match="dataset-2"):
        LD.bandai_namco_split(["foo.bvh"])
    cmu = ["d/train/walking/walking_1.txt", "d/test/walking/walking_1.txt", "d/train/running/running_2.txt"]
    tr, te = LD.cmu_split(cmu)
    assert te == ["d/test/walking/walking_1.txt"] and len(tr) == 2
    # every sequence built from a file stays on that file's side
    seqs = {f: LD.build_sequences(_straight_walk(frames=40, frame_time=1 / 120), LD.CMU_RIG, source=f) for f in cmu}
    train_sources = {s.source for f in tr for s in seqs[f]}
    test_sources = {s.source for f in te for s in seqs[f]}
    assert train_sources and test_sources and not train_sources & test_sources


def test_bandai_namco_loader(shared_data):
    path = shared_data / "bandai_namco_locomotion" / "dataset-2_walk-turn-left_normal_001.bvh"
    raw = LD.load_bandai_namco(path)
    assert raw.skeleton.names[0] == "Hips" and raw.fps == pytest.approx(30, rel=1e-4)
    pos = raw.positions()
    # position channels replace the OFFSET: the bone Hips→Spine keeps the file's OFFSET length (15.7357 cm)
    assert_close(np.linalg.norm(pos[:, 1] - pos[:, 0], axis=-1), np.full(raw.num_frames, 15.7357), rtol=1e-5)
    assert 80 < raw.root_positions[:, 1].mean() < 100                    # hips ≈ 93 cm above the floor
    seqs = LD.build_sequences(raw, LD.BANDAI_NAMCO_RIG, mirror_tolerance=1e-3)
    assert [s.name for s in seqs] == [path.stem + "_d0", path.stem + "_m_d0"] and seqs[0].skeleton.num_joints == 21
    f = seqs[0].features
    cos_dir_facing = np.sum(f[:, 4:6] * f[:, 6:8], axis=-1) / np.linalg.norm(f[:, 4:6], axis=-1)
    assert np.median(cos_dir_facing) > 0.9                               # walks forward
    sp = L.sequence_spline(seqs[0])
    # Y up, right-handed: seen from above, (x, z) → a left turn is clockwise, a negative turning angle ...
    assert np.sum(sp.track("turning_angle")) < -0.5
    sp_m = L.sequence_spline(seqs[1])
    assert np.sum(sp_m.track("turning_angle")) > 0.5                     # ... and its mirror image turns right


_BN_STYLE = """HIERARCHY
ROOT joint_Root
{
\tOFFSET 0.0 0.0 0.0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Hips
\t{
\t\tOFFSET 0.0 90.0 0.0
\t\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\t\tJOINT Spine
\t\t{
\t\t\tOFFSET 10.0 0.0 0.0
\t\t\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\t\t\tEnd Site
\t\t\t{
\t\t\t\tOFFSET 0.0 0.0 0.0
\t\t\t}
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 0 0 0 0 0\t5 90 1 90 0 0\t10 0 0 0 0 0
0 0 0 0 0 0\t6 91 3 90 0 0\t10 0 0 0 0 0
"""


def test_bandai_namco_convention_on_a_small_file(tmp_path):
    path = tmp_path / "bn.bvh"
    path.write_text(_BN_STYLE)
    m = LD.load_bandai_namco(path)
    assert m.skeleton.names == ("Hips", "Spine", "Spine_end") and m.skeleton.parents.tolist() == [-1, 0, 1]
    # the Hips position channels replace its OFFSET; Spine's channels (= its OFFSET) are not added twice
    assert_close(m.root_positions, [[5.0, 90.0, 1.0], [6.0, 91.0, 3.0]])
    assert_close(m.skeleton.offsets[1], [10.0, 0.0, 0.0])
    pos = m.positions()
    assert_close(pos[:, 1] - pos[:, 0], np.tile([0.0, 10.0, 0.0], (2, 1)), atol=1e-9)  # Zrotation 90°: x → y
    bad = tmp_path / "bad.bvh"
    bad.write_text(_BN_STYLE.replace("10 0 0 0 0 0\n0 0 0", "12 0 0 0 0 0\n0 0 0"))
    with pytest.raises(ValueError, match="Spine"):
        LD.load_bandai_namco(bad)
    with pytest.raises(ValueError, match="joint_Root"):
        LD.load_bandai_namco(SAMPLE_BVH)
    short = tmp_path / "short.bvh"
    short.write_text(_BN_STYLE.replace("Frames: 2", "Frames: 3"))
    with pytest.raises(ValueError, match="3 frames"):
        LD.load_bandai_namco(short)


def test_cmu_expmap_loader_gives_the_same_26_joints():
    path = Path(__file__).resolve().parents[1] / "refimpl/data/sample/expmap/train/walking/walking_1.txt"
    m = LD.prepare_motion(LD.load_cmu_expmap(path), LD.CMU_RIG)
    b = LD.prepare_motion(LD.load_cmu_bvh(SAMPLE_BVH), LD.CMU_RIG)  # the same trial (CMU 02_01)
    assert m.skeleton.names == b.skeleton.names and m.num_frames == b.num_frames
    assert_close(m.root_positions, b.root_positions, atol=1e-3)
    fm = LD.build_sequences(m, LD.CMU_RIG, mirror=False, all_phases=False)[0].features
    fb = LD.build_sequences(b, LD.CMU_RIG, mirror=False, all_phases=False)[0].features
    assert_close(fm[:, :6], fb[:, :6], atol=1e-3)
    assert_close(fm[:, 6:], fb[:, 6:], atol=2e-2)  # the exp-map root agrees with the BVH to ~1e-2 only
