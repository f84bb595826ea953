"""``python -m deploy run`` walks a path with the exported long-term graphs (spec/deploy.md §8, §12; issue #24).

Tiny ``quaternet-long`` and ``pace`` checkpoints (``refimpl train`` on the embedded sample) are exported with
``python -m deploy export`` into two folders; ``python -m deploy run LONG PATH OUT --pace PACE`` must reproduce
``refimpl generate --model quaternet-long`` on the same checkpoints (NumPy, float64) up to the float32 graphs:
joint positions and root track of the BVH, the ``.npy`` frames, the controls. Bad invocations: one line, exit 2
(option values, the path's grammar and bounds, the output's kind) or 3 (files: a missing path CSV, a missing
``--pace`` folder, another model's folder, an export without its seed clip).
"""
from __future__ import annotations

import json

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from deploy.cli import main as deploy_main  # noqa: E402
from refimpl.bvh import read_bvh  # noqa: E402
from refimpl.cli import main as refimpl_main  # noqa: E402

SMALL = ["--data", "sample", "--set", "hidden_size=8", "--locomotion-prefix", "6", "--locomotion-target", "8",
         "--batch-size", "4", "--progress-every", "1", "--checkpoint-every", "1"]


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """``{"pose", "pace": checkpoint, "long", "pacedir": export folder, "qn": another model's folder}``."""
    root = tmp_path_factory.mktemp("deploy_walk")
    assert refimpl_main(["--blas-threads", "1", "train", "--model", "quaternet-long", *SMALL, "--steps", "2",
                         "--out", str(root / "pose")]) == 0
    assert refimpl_main(["--blas-threads", "1", "train", "--model", "pace", "--data", "sample", "--steps", "2",
                         "--batch-size", "4", "--pace-chunk-length", "60", "--out", str(root / "pace")]) == 0
    assert refimpl_main(["--blas-threads", "1", "train", "--model", "quaternet", "--steps", "1", "--batch-size", "6",
                         "--set", "hidden_size=8", "--set", "num_layers=1", "--set", "prefix_length=12",
                         "--set", "target_length=4", "--out", str(root / "qn")]) == 0
    out = {"pose": root / "pose" / "checkpoint.npz", "pace": root / "pace" / "checkpoint.npz"}
    for key, ck, folder in (("long", out["pose"], "long"), ("pacedir", out["pace"], "pacedir"),
                            ("qn", root / "qn" / "checkpoint.npz", "qn_onnx")):
        assert deploy_main(["export", str(ck), str(root / folder)]) == 0
        out[key] = root / folder
    return out


def _generate(exported, tmp_path, path, seconds, speed="walk"):
    ref = tmp_path / "ref.bvh"
    assert refimpl_main(["generate", "--model", "quaternet-long", "--checkpoint", str(exported["pose"]),
                         "--pace", str(exported["pace"]), "--path", path, "--speed", speed, "--seconds", seconds,
                         "--out", str(ref), "--controls", str(tmp_path / "ref.json")]) == 0
    return read_bvh(ref), json.loads((tmp_path / "ref.json").read_text())


def _relative(a, b) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-9))


@pytest.mark.parametrize("path,speed", [("circle:r=3", "walk"), ("figure8:size=4", "0.8")])
def test_walk_matches_refimpl_generate(exported, tmp_path, capsys, path, speed):
    """The BVH of ``deploy run`` against ``refimpl generate`` (NumPy) on the same checkpoints: same frames,
    joint positions and root track to 1e-4 relative (float32 graphs), same controls."""
    ref, ref_controls = _generate(exported, tmp_path, path, "2", speed)
    out = tmp_path / "walk.bvh"
    capsys.readouterr()
    assert deploy_main(["run", str(exported["long"]), path, str(out), "--pace", str(exported["pacedir"]),
                        "--speed", speed, "--seconds", "2", "--controls", str(tmp_path / "c.json")]) == 0, \
        capsys.readouterr().err
    assert "wrote" in capsys.readouterr().out
    got = read_bvh(out)
    assert got.num_frames == ref.num_frames == 60
    assert got.skeleton.names == ref.skeleton.names
    pos, ref_pos = got.positions(), ref.positions()
    assert _relative(pos, ref_pos) <= 1e-4
    assert _relative(got.root_positions, ref.root_positions) <= 1e-4
    controls = np.array([f["controls"] for f in json.loads((tmp_path / "c.json").read_text())["frames"]])
    ref_c = np.array([f["controls"] for f in ref_controls["frames"]])
    assert np.abs(controls - ref_c).max() <= 1e-4
    # the character moves: a walk, not a standing pose
    assert np.linalg.norm(np.diff(ref.root_positions[:, [0, 2]], axis=0), axis=-1).sum() > 1.0


def test_walk_npy_frames_and_pace_in_the_same_folder(exported, tmp_path, capsys):
    """``.npy`` output: ``(N, 4J + 3)`` = unit quaternions then the root (QuaterNet units), equal to the NumPy
    walk; the pace model may sit in the step model's folder (no ``--pace``)."""
    from refimpl.services import load_trained
    from refimpl.tasks.locomotion import walk_from_checkpoints

    both = tmp_path / "both"
    assert deploy_main(["export", str(exported["pose"]), str(both)]) == 0
    assert deploy_main(["export", str(exported["pace"]), str(both)]) == 0
    out = tmp_path / "walk.npy"
    assert deploy_main(["run", str(both), "line-turn:turn=60", str(out), "--seconds", "1.5"]) == 0
    frames = np.load(out, allow_pickle=False)
    walk = walk_from_checkpoints(load_trained(exported["pose"]), load_trained(exported["pace"]), "line-turn:turn=60",
                                 "walk", 1.5)
    m = walk.motion
    J = m.num_joints
    assert frames.shape == (45, 4 * J + 3) == (m.num_frames, 4 * J + 3)
    q = frames[:, :4 * J].reshape(-1, J, 4)
    assert np.allclose(np.linalg.norm(q, axis=-1), 1, atol=1e-6)
    assert _relative(frames[:, 4 * J:], m.root_positions) <= 1e-4
    assert np.abs(np.abs(np.sum(q * m.rotations, axis=-1)) - 1).max() <= 1e-4   # same rotations (up to sign)


def test_walk_with_a_csv_path_warns_when_it_ends_early(exported, tmp_path, capsys):
    csv = tmp_path / "short.csv"
    csv.write_text("0,0\n0.5,0\n1,0\n")
    out = tmp_path / "short.bvh"
    capsys.readouterr()
    assert deploy_main(["run", str(exported["long"]), str(csv), str(out), "--pace", str(exported["pacedir"]),
                        "--seconds", "30"]) == 0
    err = capsys.readouterr().err
    frames = read_bvh(out).num_frames
    assert frames < 900 and f"the path ends after {frames / 30:.1f} s" in err and err.count("\n") == 1


def test_export_writes_the_seed_clip_named_in_the_metadata(exported):
    """``quaternet-long_seed.npy`` is the checkpoint's seed clip ``[rotations | features]``, named in the step
    model's metadata with its shape and dtype."""
    import onnx

    from refimpl.checkpoint import load_checkpoint

    meta = {p.key: json.loads(p.value) for p in onnx.load(str(exported["long"] / "quaternet-long_step.onnx"))
            .metadata_props}
    entry = meta["seed_clip"]
    seed = np.load(exported["long"] / entry["file"], allow_pickle=False)
    assert list(seed.shape) == entry["shape"] and seed.dtype.name == entry["dtype"]
    clip = load_checkpoint(exported["pose"])[1]["model_config"]["seed_clip"]
    rot, feats = np.asarray(clip["rotations"]), np.asarray(clip["features"])
    P, J = rot.shape[:2]
    np.testing.assert_allclose(seed, np.concatenate([rot.reshape(P, 4 * J), feats], axis=1), atol=1e-6)
    assert entry["name"] == clip["name"]


def test_bad_walk_invocations(exported, tmp_path, capsys):
    """One line on stderr, exit 2 (values, grammar, output kind, options of .npy frames) or 3 (files), and
    nothing written."""
    long, pace, qn = str(exported["long"]), str(exported["pacedir"]), str(exported["qn"])
    out = tmp_path / "w.bvh"
    no_seed = tmp_path / "no_seed"
    no_seed.mkdir()
    for f in exported["long"].iterdir():
        if not f.name.endswith("_seed.npy"):
            (no_seed / f.name).write_bytes(f.read_bytes())
    txt = tmp_path / "walk.txt"
    txt.write_text("1 2 3\n")
    tiny, bad = tmp_path / "tiny.csv", tmp_path / "bad.csv"
    tiny.write_text("0,0\n0.01,0\n")
    bad.write_text("0,0\nx,1\n")
    cases = [(["circle:r=0", "--pace", pace], 2, "r:"),
             (["square", "--pace", pace], 2, "square"),
             (["circle", "--pace", pace, "--seconds", "0"], 2, "--seconds"),
             (["circle", "--pace", pace, "--seconds", "ten"], 2, "--seconds"),
             (["circle", "--pace", pace, "--speed", "fly"], 2, "--speed"),
             (["circle", "--pace", pace, "--speed", "99"], 2, "--speed"),
             (["circle", "--pace", pace, "--frames", "9"], 2, "--frames"),
             (["circle", "--pace", pace, "--prefix", "3"], 2, "--prefix"),
             ([str(tmp_path / "absent.csv"), "--pace", pace], 3, "absent.csv"),
             ([str(txt), "--pace", pace], 3, "walk.txt"),
             ([str(tiny), "--pace", pace], 3, "tiny.csv"),
             ([str(bad), "--pace", pace], 3, "bad.csv:2"),
             (["circle", "--pace", str(tmp_path / "absent")], 3, "absent"),
             (["circle", "--pace", qn], 3, "quaternet"),
             (["circle", "--pace", long], 3, "pace"),
             (["circle"], 3, "--pace")]
    for extra, code, word in cases:
        argv = ["run", long, extra[0], str(out), *extra[1:]]
        assert deploy_main(argv) == code, (argv, capsys.readouterr().err)
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and word in err and "Traceback" not in err, (argv, err)
    np.save(tmp_path / "x.npy", np.zeros((1, 4, 8), np.float32))   # frames given: --pace is the wrong option
    more = [(["run", long, "circle", str(tmp_path / "w.txt"), "--pace", pace], 2, "w.txt"),
            (["run", str(no_seed), "circle", str(out), "--pace", pace], 3, "seed"),
            (["run", pace, "circle", str(out)], 3, "step"),
            (["run", long, str(tmp_path / "x.npy"), str(tmp_path / "y.npy"), "--pace", pace], 2, "--pace")]
    for argv, code, word in more:
        assert deploy_main(argv) == code, (argv, capsys.readouterr().err)
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and word in err and "Traceback" not in err, (argv, err)
    assert not out.exists() and not (tmp_path / "w.txt").exists()


def test_refimpl_generate_refuses_a_csv_path_too_short_for_a_frame(exported, tmp_path, capsys):
    """``refimpl generate`` on a path CSV too short for one frame: exit 3 naming the file, as ``deploy run`` (it
    used to end in exit 1 with the bare ValueError); nothing written."""
    tiny = tmp_path / "tiny.csv"
    tiny.write_text("0,0\n0.01,0\n")
    out = tmp_path / "walk.bvh"
    code = refimpl_main(["generate", "--model", "quaternet-long", "--checkpoint", str(exported["pose"]),
                         "--pace", str(exported["pace"]), "--path", str(tiny), "--seconds", "2", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 3 and len(err) == 1 and "tiny.csv" in err[-1], err
    assert not out.exists()
