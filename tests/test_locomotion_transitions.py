"""Tests of QTG's transition windows on the Bandai Namco locomotion set (spec/qtg.md §8.4).

The tests on real takes read a handful of files from ``../shared/data/bandai_namco_locomotion`` and are skipped
when it is absent; the split and kind tests on file names and synthetic windows always run.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from refimpl.errors import BadInputError
from refimpl.protocols.transition_locomotion import (FOLDER, JOINTS, KIND, RUN_MIN_CM_S, STAND_MAX_CM_S, bandai_namco_sources,
                                            build_datasets, grouped_errors, heldout_dataset, is_bandai_namco_folder,
                                            load_bandai_namco_source, take_facts, window_kinds, window_speeds,
                                            window_styles)
from refimpl.protocols.transition_metrics import positions_from_poses
from refimpl.quat import quat_mul, quat_rotate
from refimpl.rotations import quat_from_axis_angle
from refimpl.tasks import transition
from refimpl.protocols.locomotion_data import load_bandai_namco
from refimpl.testing import assert_close
from refimpl.protocols.transition import TransitionSource, join_pose, normalize_poses, split_pose

CONTENTS = ("walk", "walk-turn-left", "walk-turn-right", "run")
STYLES = ("active", "elderly", "exhausted", "feminine", "masculine", "normal")


@pytest.fixture(scope="module")
def bn_dir(shared_data) -> Path:
    d = shared_data / FOLDER
    if not d.is_dir():
        pytest.skip(f"../shared/data/{FOLDER} is not available")
    return d


@pytest.fixture(scope="module")
def few_takes(bn_dir, tmp_path_factory) -> Path:
    """A folder with 8 real takes: ids 001 (held out) and 002 (train) of walk/run x normal/elderly, plus turns."""
    out = tmp_path_factory.mktemp("bn")
    for content, style in (("walk", "normal"), ("run", "elderly"), ("walk-turn-left", "active"),
                           ("walk-turn-right", "feminine")):
        for i in (1, 2):
            f = bn_dir / f"dataset-2_{content}_{style}_{i:03d}.bvh"
            shutil.copy(f, out / f.name)
    return out


def _fake_names(tmp_path: Path, ids=range(1, 23)) -> Path:
    for c in CONTENTS:
        for s in STYLES:
            for i in ids:
                (tmp_path / f"dataset-2_{c}_{s}_{i:03d}.bvh").write_text("")
    return tmp_path


def test_take_facts_reads_the_name():
    f = take_facts("x/dataset-2_walk-turn-left_elderly_017.bvh")
    assert (f.content, f.style, f.id) == ("walk-turn-left", "elderly", 17)
    with pytest.raises(ValueError, match="dataset-2_"):
        take_facts("walk_01.bvh")


def test_split_holds_out_whole_takes_of_every_style_and_content(tmp_path):
    """Ids ending in 1 are held out; no take on both sides; every content x style on both sides."""
    root = _fake_names(tmp_path)
    train, test = bandai_namco_sources(root)
    tr, te = {s.path for s in train}, {s.path for s in test}
    assert not tr & te and len(tr) + len(te) == len(CONTENTS) * len(STYLES) * 22
    assert all(take_facts(p).id % 10 == 1 for p in te) and all(take_facts(p).id % 10 != 1 for p in tr)
    groups = {(c, s) for c in CONTENTS for s in STYLES}
    assert {(take_facts(p).content, take_facts(p).style) for p in te} == groups
    assert {(take_facts(p).content, take_facts(p).style) for p in tr} == groups
    assert all(s.kind == KIND and s.fps == 30.0 and s.label == take_facts(s.path).content for s in train + test)


def test_split_of_the_real_folder_covers_every_group(bn_dir):
    train, test = bandai_namco_sources(bn_dir)
    assert len(train) + len(test) == 830 and not {s.path for s in train} & {s.path for s in test}
    groups = {(c, s) for c in CONTENTS for s in STYLES}
    for side in (train, test):
        assert {(take_facts(s.path).content, take_facts(s.path).style) for s in side} == groups
    assert 0.08 < len(test) / 830 < 0.15


def test_folder_detection(tmp_path, shared_data):
    assert not is_bandai_namco_folder(tmp_path)
    assert not is_bandai_namco_folder(shared_data)  # ../shared/data itself stays the CMU set
    _fake_names(tmp_path, ids=(1, 2))
    assert is_bandai_namco_folder(tmp_path)
    assert not is_bandai_namco_folder(tmp_path / "dataset-2_walk_normal_001.bvh")


def test_loader_keeps_21_joints_and_the_fk_positions(bn_dir):
    """The 21 kept joints are where the full re-rooted take puts them (End Sites dropped: exact), in cm."""
    path = bn_dir / "dataset-2_walk_normal_002.bvh"
    skel, clips = load_bandai_namco_source(TransitionSource(str(path), KIND, 30.0, "walk"))
    rot, pos = clips[0]
    assert skel.names == JOINTS and len(JOINTS) == 21 and rot.shape[1:] == (21, 4)
    full = load_bandai_namco(path)
    idx = [full.skeleton.names.index(n) for n in JOINTS]
    assert_close(skel.forward_kinematics(rot, pos), full.positions()[:, idx], rtol=0, atol=1e-9)
    assert 80 < np.median(pos[:, 1]) < 105  # hips height in centimetres
    with pytest.raises(ValueError, match="kind"):
        load_bandai_namco_source(TransitionSource(str(path), "cmu_bvh", 30.0, "walk"))
    with pytest.raises(ValueError, match="30 fps"):
        load_bandai_namco_source(TransitionSource(str(path), KIND, 30.0, "walk"), fps=15.0)


def test_windows_on_real_takes(few_takes):
    """Shapes, root relative to the first pose, training statistics, normalisation identity, FK = rigid motion."""
    train, test = build_datasets(few_takes, T=30, stride=8)
    assert train.poses.shape[1:] == (34, 87) == test.poses.shape[1:]
    assert {take_facts(s.path).id for s in train.sources} == {2} and {take_facts(s.path).id for s in test.sources} == {1}
    root, quats = split_pose(train.poses)
    assert_close(root[:, 0], np.zeros_like(root[:, 0]), rtol=0, atol=1e-9)
    assert np.all(quats[:, 0, :, 0] >= 0)
    flat = train.poses[..., :3].reshape(-1, 3)
    assert_close(train.root_mean, flat.mean(0), rtol=1e-12, atol=1e-9)
    assert_close(train.root_std, flat.std(0), rtol=1e-12, atol=1e-9)
    assert np.array_equal(test.root_mean, train.root_mean)
    n = train.normalized()[..., :3].reshape(-1, 3)
    assert_close(n.mean(0), np.zeros(3), rtol=0, atol=1e-9)
    assert_close(n.std(0), np.ones(3), rtol=0, atol=1e-9)
    assert np.array_equal(train.normalized()[..., 3:], train.poses[..., 3:])
    assert_close(normalize_poses(train.poses, train.root_mean, train.root_std), train.normalized(), rtol=0, atol=0)
    # window 0 of the first training take is frames 0..33 of that take, moved rigidly
    skel, clips = load_bandai_namco_source(train.sources[0])
    rot, pos = clips[0]
    world = skel.forward_kinematics(rot[:34], pos[:34])  # (34, 21, 3)
    local = positions_from_poses(train.poses[0], train.skeletons[train.skeleton_index[0]])
    d_world = np.linalg.norm(world[:, None] - world[:, :, None], axis=-1)
    d_local = np.linalg.norm(local[:, None] - local[:, :, None], axis=-1)
    assert_close(d_local, d_world, rtol=0, atol=1e-8)
    assert_close(np.linalg.norm(local - local[:1, :1], axis=-1), np.linalg.norm(world - world[:1, :1], axis=-1),
                 rtol=0, atol=1e-8)


def test_transition_task_reads_the_folder(few_takes):
    """``refimpl train/eval --data <folder of takes>`` go through this data source."""
    train, test = transition.build_datasets(str(few_takes), 30, 8)
    assert train.poses.shape[-1] == 87 and test.num_windows > 0
    assert set(window_styles(test)) == {"normal", "elderly", "active", "feminine"}
    with pytest.raises(BadInputError, match="--data"):
        transition.build_datasets(str(few_takes), 400, 8)  # no training window of 404 frames


def _synthetic(speeds, turn_deg, W=34):
    """Windows moving along +z at ``speeds[k]`` cm/s (k = first/second half), heading turned by ``turn_deg``."""
    N = len(speeds)
    root = np.zeros((N, W, 3))
    for n, (a, b) in enumerate(speeds):
        v = np.where(np.arange(W) < W // 2, a, b) / 30.0
        root[n, :, 2] = np.concatenate([[0.0], np.cumsum(v[1:])])
    angles = np.linspace(0, 1, W)[None, :] * np.radians(np.asarray(turn_deg))[:, None]  # (N, W)
    q = np.tile(np.array([1.0, 0, 0, 0]), (N, W, 2, 1))
    q[:, :, 0] = quat_from_axis_angle(angles[..., None] * np.array([0.0, 1.0, 0.0]))
    return join_pose(root, q)


def test_window_kinds_from_root_motion():
    w = _synthetic([(0, 120), (120, 120), (120, 400), (400, 120), (400, 0), (120, 120)], [0, 0, 0, 0, 0, 90])
    start, end, turn = window_speeds(w)
    assert_close(start, np.array([0, 120, 120, 400, 400, 120.0]), rtol=0, atol=1e-9)
    assert_close(turn, np.array([0, 0, 0, 0, 0, 90.0]), rtol=0, atol=1e-9)
    assert list(window_kinds(w)) == ["stand->walk", "walk->walk", "walk->run", "run->walk", "run->stand",
                                     "walk->walk turn"]
    # rotating the whole window about y changes neither speeds nor kinds
    yaw = quat_from_axis_angle(np.array([0.0, 1.3, 0.0]))
    r, q = split_pose(w)
    q2 = q.copy()
    q2[:, :, 0] = quat_mul(yaw, q[:, :, 0])
    w2 = join_pose(quat_rotate(yaw, r), q2)
    assert list(window_kinds(w2)) == list(window_kinds(w))
    assert STAND_MAX_CM_S < 120 < RUN_MIN_CM_S < 400


def test_heldout_dataset_is_the_test_half(few_takes):
    train, test = build_datasets(few_takes, T=30, stride=8)
    held = heldout_dataset(few_takes, train.root_mean, train.root_std, T=30, stride=8)
    assert np.array_equal(held.poses, test.poses) and np.array_equal(held.root_std, train.root_std)
    assert [s.path for s in held.sources] == [s.path for s in test.sources]


def test_grouped_errors_metric_and_groups(few_takes):
    """Ground truth scores 0; a root shifted by (3, 0, 4) cm scores exactly 5 cm on every joint, in every group;
    the groups partition the windows."""
    _, test = build_datasets(few_takes, T=30, stride=8)
    past, gt, target = test.context()

    def truth(p, t, T):
        n = len(p)
        start = next(i for i in range(len(past)) if np.array_equal(past[i:i + n], p))
        return gt[start:start + n]

    def shifted(p, t, T):
        out = truth(p, t, T).copy()
        out[..., :3] += np.array([3.0, 0.0, 4.0])
        return out

    groups = {"style": window_styles(test), "kind": window_kinds(test.poses)}
    res = grouped_errors(test, {"truth": truth, "shifted": shifted}, groups, batch_size=7)
    assert res["truth"]["mean_cm"] == 0.0 and len(res["truth"]["per_frame_cm"]) == 30
    assert_close(np.array(res["shifted"]["per_frame_cm"]), np.full(30, 5.0), rtol=0, atol=1e-9)
    for g in groups:
        by = res["shifted"][f"by_{g}"]
        assert sum(v["num_windows"] for v in by.values()) == test.num_windows
        assert all(abs(v["mean_cm"] - 5.0) < 1e-9 for v in by.values())
    with pytest.raises(ValueError, match="groups"):
        grouped_errors(test, {"truth": truth}, {"style": np.array(["a"])})


def test_train_and_eval_commands_on_takes(few_takes, tmp_path, capsys):
    """``refimpl train --model qtg --data <takes>`` trains at the paper's settings; ``eval`` reads the same split."""
    from refimpl.cli import EXIT_OK, main

    out = tmp_path / "run"
    code = main(["train", "--model", "qtg", "--data", str(few_takes), "--out", str(out), "--steps", "2",
                 "--stride", "8", "--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"])
    text = capsys.readouterr().out
    assert code == EXIT_OK, text
    assert "batch 32, Adam lr 0.0001, betas (0.5, 0.9)" in text and '"pose_size": 87' in text
    code = main(["eval", "--checkpoint", str(out / "checkpoint.npz"), "--data", str(few_takes), "--stride", "8",
                 "--json", str(tmp_path / "r.json")])
    text = capsys.readouterr().out
    assert code == EXIT_OK, text
    assert "21 joints" in text and "from 4 sources" in text
    # the experiments' commands on the same checkpoint: grouped JSON + markdown, the end-frame diagnostic
    import json

    from experiments import qtg_ends, qtg_locomotion

    ck = str(out / "checkpoint.npz")
    assert qtg_locomotion.main(["eval", "--checkpoint", ck, "--data", str(few_takes), "--stride", "8",
                                "--out", str(tmp_path / "g.json"), "--md", str(tmp_path / "g.md")]) == 0
    res = json.loads((tmp_path / "g.json").read_text())
    assert set(res["results"]) == {"qtg", "inertialization", "interpolation"} and res["meta"]["step"] == 2
    assert set(res["results"]["qtg"]["by_style"]) == {"normal", "elderly", "active", "feminine"}
    assert "## by kind" in (tmp_path / "g.md").read_text()
    assert qtg_ends.main(["--checkpoint", ck, "--data", str(few_takes), "--stride", "8",
                          "--json", str(tmp_path / "e.json")]) == 0
    ends = json.loads((tmp_path / "e.json").read_text())[ck]
    assert len(ends["per_frame_cm"]) == 30 and set(ends["autoencoder_cm"]) == {"frame_1", "frame_30", "g1"}


def test_generate_between_two_takes_of_the_rig(few_takes, tmp_path, capsys):
    """``refimpl generate`` takes Bandai Namco BVH takes (two actors: the source's bone lengths are used, with a
    note), writes a 21-joint BVH whose context frames are the takes' own; a network of another rig is exit 3."""
    from refimpl.bvh import read_bvh
    from refimpl.cli import EXIT_BAD_INPUT, EXIT_OK, main

    out = tmp_path / "run"
    assert main(["train", "--model", "qtg", "--data", str(few_takes), "--out", str(out), "--steps", "1",
                 "--stride", "8", "--set", "encoder_sizes=16,8", "--set", "gru_hidden=8",
                 "--set", "decoder_sizes=16"]) == EXIT_OK
    src, tgt = few_takes / "dataset-2_walk_normal_001.bvh", few_takes / "dataset-2_run_elderly_001.bvh"
    bvh = tmp_path / "t.bvh"
    code = main(["generate", "--checkpoint", str(out / "checkpoint.npz"), "--join", "inertialize",
                 "--source", str(src), "--source-frame", "30", "--target", str(tgt), "--target-frame", "20",
                 "--out", str(bvh)])
    text = capsys.readouterr().out
    assert code == EXIT_OK, text
    m = read_bvh(bvh)
    joints = [n for n in m.skeleton.names if n not in set(m.skeleton.end_sites)] if m.skeleton.end_sites else \
        list(m.skeleton.names)
    assert m.num_frames == 10 + 30 + 10 and abs(m.frame_time - 1 / 30) < 1e-6
    assert set(joints) >= {"Hips", "Foot_L", "Foot_R", "Hand_L", "Hand_R"} and "LeftFoot" not in joints
    assert "other bone lengths" in text  # two actors of the rig
    # a CMU-rig network cannot run on this rig
    cmu = tmp_path / "cmu"
    assert main(["train", "--out", str(cmu), "--steps", "1", "--set", "encoder_sizes=16,8", "--set", "gru_hidden=8",
                 "--set", "decoder_sizes=16"]) == EXIT_OK
    capsys.readouterr()
    code = main(["generate", "--checkpoint", str(cmu / "checkpoint.npz"), "--source", str(src), "--source-frame",
                 "30", "--out", str(tmp_path / "x.bvh")])
    err = capsys.readouterr().err.strip()
    assert code == EXIT_BAD_INPUT and "21 joints" in err and err.count("\n") == 0, err
    assert not (tmp_path / "x.bvh").exists()
