"""Tests of the ``refimpl`` command line (spec/cli.md): exit codes, error messages, and every subcommand.

A tiny QTG is trained once per session on one sample BVH file (split by time), then evaluated, exported,
used to generate transitions (NumPy and onnxruntime) and rendered.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from refimpl.cli import EXIT_BAD_INPUT, EXIT_FAILURE, EXIT_OK, EXIT_USAGE, main
from refimpl.tasks.transition import source_for_file

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "refimpl" / "data" / "sample"
WALK_BVH = SAMPLE / "bvh" / "02_01.bvh"
WALK_TXT = SAMPLE / "expmap" / "test" / "walking" / "walking_1.txt"
RUN_TXT = SAMPLE / "expmap" / "test" / "running" / "running_1.txt"
TINY = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]


def _run(capsys, *argv):
    """``main(argv)`` -> (exit code, stdout, stderr)."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="session")
def trained(tmp_path_factory):
    """spec/cli.md §train: a 3-step tiny QTG on 02_01.bvh (first half train, second half held out)."""
    out = tmp_path_factory.mktemp("train")
    code = main(["train", "--data", str(WALK_BVH), "--out", str(out), "--steps", "3", "--batch-size", "8",
                 "--stride", "8", "--test-fraction", "0.5", "--validate-every", "2", "--progress-every", "1", *TINY])
    assert code == EXIT_OK
    return out


# ---------------------------------------------------------------------------------------------------------
# exit codes and messages


@pytest.mark.parametrize("argv", [
    [], ["nonsense"], ["train", "--bogus"], ["train", "--steps", "-1"], ["train", "--lr", "zero"],
    ["generate"], ["info"], ["export"], ["demo", "--steps", "0"], ["train", "--model", "rnn"],
    ["train", "--steps", "3", "--epochs", "2"], ["train", "--resume", "--overwrite"],
])
def test_usage_errors_exit_2(capsys, argv):
    """spec/cli.md §exit codes: argparse usage errors give 2 and a usage message on stderr."""
    code, out, err = _run(capsys, *argv)
    assert code == EXIT_USAGE
    assert "usage: refimpl" in err


def test_help_and_version_exit_0(capsys):
    """spec/cli.md §exit codes: --help and --version succeed."""
    assert main(["--help"]) == EXIT_OK
    assert "exit codes" in capsys.readouterr().out
    assert main(["--version"]) == EXIT_OK
    assert "refimpl" in capsys.readouterr().out
    for cmd in ("info", "train", "eval", "export", "generate", "render", "demo"):
        assert main([cmd, "--help"]) == EXIT_OK
    capsys.readouterr()


def test_missing_file_exit_3(capsys, tmp_path):
    """spec/cli.md §exit codes: a missing input file is exit 3 with one clear line, no traceback."""
    for argv in (["info", tmp_path / "nope.bvh"], ["render", tmp_path / "nope.bvh"],
                 ["eval", "--checkpoint", tmp_path / "nope.npz"], ["export", "--checkpoint", tmp_path / "x.npz"],
                 ["eval", "--data", tmp_path / "no_folder"], ["info", tmp_path]):
        code, out, err = _run(capsys, *argv)
        assert code == EXIT_BAD_INPUT, argv
        assert err.startswith(f"refimpl {argv[0]}: error: ") and "Traceback" not in err
        assert str(tmp_path) in err


def test_malformed_files_exit_3(capsys, tmp_path):
    """spec/cli.md §exit codes: malformed BVH / exp-map / checkpoint / ONNX files are exit 3, naming the file."""
    bad_bvh = tmp_path / "bad.bvh"
    bad_bvh.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0\n")
    bad_txt = tmp_path / "bad.txt"
    bad_txt.write_text("1,2,3\n")
    bad_npz = tmp_path / "bad.npz"
    bad_npz.write_bytes(b"PK\x03\x04 not really a zip")
    bad_onnx = tmp_path / "bad.onnx"
    bad_onnx.write_bytes(b"\x00\xff garbage")
    other = tmp_path / "notes.md"
    other.write_text("hello")
    for path in (bad_bvh, bad_txt, bad_npz, other):
        code, _, err = _run(capsys, "info", path)
        assert code == EXIT_BAD_INPUT, path
        assert str(path) in err and "Traceback" not in err
    pytest.importorskip("onnx")
    code, _, err = _run(capsys, "info", bad_onnx)
    assert code == EXIT_BAD_INPUT and "bad.onnx" in err
    code, _, err = _run(capsys, "eval", "--checkpoint", bad_npz)
    assert code == EXIT_BAD_INPUT
    code, _, err = _run(capsys, "render", bad_bvh)
    assert code == EXIT_BAD_INPUT and "bad.bvh:" in err


def test_info_bvh(capsys):
    """spec/cli.md §info: joints, frames, frame rate and channel layout of a sample BVH."""
    code, out, _ = _run(capsys, "info", WALK_BVH, "--joints")
    assert code == EXIT_OK
    assert "joints      38 (31 joints + 7 End Sites)" in out
    assert "frames      344" in out
    assert "120 fps" in out
    assert "Hips: Xposition Yposition Zposition Zrotation Yrotation Xrotation" in out
    assert "30 joints: Zrotation Yrotation Xrotation" in out
    assert "LeftToeBase_end (End Site)" in out
    assert "translations 0 non-root joint(s) with position channels" in out


def test_info_bvh_with_translations_and_static_root(capsys, tmp_path):
    """spec/cli.md §info: a studio-style file (static root, motion and position channels on its child) shows the
    translated joints and the re-rooting."""
    bvh = tmp_path / "studio.bvh"
    bvh.write_text(
        "HIERARCHY\nROOT joint_Root\n{\n  OFFSET 0 0 0\n  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "  JOINT Hips\n  {\n    OFFSET 0 90 0\n    CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "    JOINT Spine\n    {\n      OFFSET 0 10 0\n      CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation\n"
        "      End Site\n      {\n        OFFSET 0 5 0\n      }\n    }\n  }\n}\n"
        "MOTION\nFrames: 2\nFrame Time: 0.0333333\n"
        "0 0 0 0 0 0 0 90 0 0 0 0 0 10 0 0 0 0\n0 0 0 0 0 0 5 90 0 0 0 10 0 10 0 0 0 0\n")
    code, out, _ = _run(capsys, "info", str(bvh))
    assert code == EXIT_OK
    assert "translations 2 non-root joint(s) with position channels in the file: Hips, Spine" in out
    assert "re-rooted at 'Hips'" in out
    assert "none varying (folded into the offsets)" in out


def test_info_expmap(capsys):
    """spec/cli.md §info: an exp-map file on the built-in CMU skeleton."""
    n_rows = sum(1 for line in WALK_TXT.read_text().splitlines() if line.strip())
    code, out, _ = _run(capsys, "info", WALK_TXT)
    assert code == EXIT_OK
    assert f"frames      {n_rows}" in out and "117 values per row" in out and "joints      38" in out


def test_info_checkpoint_and_state_dict(capsys, trained, tmp_path):
    """spec/cli.md §info: a training checkpoint (model, step, config, parameter shapes) and a plain .npz."""
    code, out, _ = _run(capsys, "info", trained / "checkpoint.npz")
    assert code == EXIT_OK
    assert "model       qtg" in out and "step 3 of 3" in out and "checksum OK" in out
    assert "gru.weight_ih_l0" in out and "(24, 24)" in out  # 3 H x 3 Z with H = 8, Z = 8
    plain = tmp_path / "state.npz"
    np.savez(plain, **{"fc.weight": np.zeros((2, 3), np.float32)})
    code, out, _ = _run(capsys, "info", plain)
    assert code == EXIT_OK and "plain .npz state dict" in out and "fc.weight" in out


def test_train_outputs_and_resume(capsys, trained):
    """spec/cli.md §train: checkpoint + CSV logs; --resume continues; re-running without it is a usage error."""
    log = (trained / "loss.csv").read_text().splitlines()
    assert log[0] == "step,epoch,loss,grad_norm,lr,elapsed_s" and len(log) == 4
    assert (trained / "loss_val.csv").is_file()
    code, _, err = _run(capsys, "train", "--data", WALK_BVH, "--out", trained, "--steps", "3", *TINY)
    assert code == EXIT_USAGE and "--resume" in err
    code, out, err = _run(capsys, "train", "--data", WALK_BVH, "--out", trained, "--steps", "5", "--batch-size",
                          "8", "--stride", "8", "--test-fraction", "0.5", "--validate-every", "2", "--resume", *TINY)
    assert code == EXIT_OK and "step 5" in out
    assert "it/s" in err and "ETA" in err  # progress lines with rate and ETA on stderr
    assert len((trained / "loss.csv").read_text().splitlines()) == 6


def test_train_errors(capsys, tmp_path):
    """spec/cli.md §train: --resume without a checkpoint is exit 3; bad --set / representation exit 2."""
    code, _, err = _run(capsys, "train", "--out", tmp_path, "--resume", "--steps", "1")
    assert code == EXIT_BAD_INPUT and "no checkpoint to resume" in err
    code, _, err = _run(capsys, "train", "--data", WALK_BVH, "--out", tmp_path, "--steps", "1", "--set", "size=3")
    assert code == EXIT_USAGE and "FIELD=VALUE" in err
    code, _, err = _run(capsys, "train", "--data", WALK_BVH, "--out", tmp_path, "--steps", "1",
                        "--representation", "dualquat")
    assert code == EXIT_USAGE and "quat" in err


def test_eval_prints_table_and_curve(capsys, trained, tmp_path):
    """spec/cli.md §eval: the three methods in a table, the per-frame curve, CSV and JSON files."""
    csv, js = tmp_path / "curve.csv", tmp_path / "res.json"
    code, out, _ = _run(capsys, "eval", "--checkpoint", trained / "checkpoint.npz", "--data", WALK_BVH,
                        "--stride", "8", "--test-fraction", "0.5", "--csv", csv, "--json", js)
    assert code == EXIT_OK
    for name in ("qtg", "inertialization", "interpolation"):
        assert name in out
    assert "Per-frame curve (cm):" in out and "mean cm" in out
    rows = csv.read_text().splitlines()
    assert rows[0] == "frame,time_ms,qtg_cm,inertialization_cm,interpolation_cm" and len(rows) == 31
    assert '"per_frame_cm"' in js.read_text()


def test_eval_baselines_only(capsys):
    """spec/cli.md §eval: without a checkpoint only the baselines are evaluated."""
    code, out, _ = _run(capsys, "eval", "--data", WALK_BVH, "--stride", "8", "--test-fraction", "0.5")
    assert code == EXIT_OK and "inertialization" in out and "\nqtg " not in out


def test_export_generate_render(capsys, trained, tmp_path):
    """spec/cli.md §export, §generate, §render: ONNX files, BVH out with NumPy and onnxruntime, PNG / GIF."""
    pytest.importorskip("onnxruntime")
    from refimpl.bvh import read_bvh

    onnx_dir = tmp_path / "onnx"
    ckpt = trained / "checkpoint.npz"
    code, out, _ = _run(capsys, "export", "--checkpoint", ckpt, "--out", onnx_dir)
    assert code == EXIT_OK and "max |diff|" in out
    assert sorted(p.name for p in onnx_dir.iterdir()) == ["qtg_init.onnx", "qtg_rollout.onnx", "qtg_step.onnx"]
    code, out, _ = _run(capsys, "info", onnx_dir / "qtg_rollout.onnx")
    assert code == EXIT_OK and "input       past ['B', 2, 91] float" in out and "output      poses" in out

    a, b, truth = tmp_path / "a.bvh", tmp_path / "b.bvh", tmp_path / "truth.bvh"
    code, out, _ = _run(capsys, "generate", "--checkpoint", ckpt, "--source", WALK_BVH, "--source-frame", 20,
                        "--out", a, "--truth", truth, "--context", 5)
    assert code == EXIT_OK and "ground truth available" in out
    code, out, _ = _run(capsys, "generate", "--backend", "onnx", "--onnx", onnx_dir, "--source", WALK_BVH,
                        "--source-frame", 20, "--out", b, "--context", 5)
    assert code == EXIT_OK
    ma, mb, mt = read_bvh(a), read_bvh(b), read_bvh(truth)
    assert ma.num_frames == mb.num_frames == mt.num_frames == 5 + 30 + 5
    assert ma.num_joints == 27  # 22 joints + End Sites below toes, head and hands
    assert np.abs(ma.positions() - mb.positions()).max() < 1e-2  # NumPy vs onnxruntime, cm (BVH rounding)

    code, out, _ = _run(capsys, "generate", "--method", "interpolation", "--source", WALK_TXT, "--source-frame",
                        10, "--target", RUN_TXT, "--target-frame", 5, "--out", tmp_path / "c.bvh")
    assert code == EXIT_OK and (tmp_path / "c.bvh").is_file()

    pytest.importorskip("matplotlib")
    png, gif = tmp_path / "a.png", tmp_path / "a.gif"
    code, out, _ = _run(capsys, "render", a, "--compare", truth, "--out", png, "--out", gif, "--frames", "0:40:4")
    assert code == EXIT_OK
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and gif.read_bytes()[:3] == b"GIF"


def test_generate_errors(capsys, trained, tmp_path):
    """spec/cli.md §generate: option combinations that cannot work are usage errors (2)."""
    ckpt = trained / "checkpoint.npz"
    base = ["generate", "--source", WALK_BVH, "--source-frame", "5", "--out", tmp_path / "x.bvh"]
    assert _run(capsys, *base)[0] == EXIT_USAGE  # qtg needs --checkpoint
    assert _run(capsys, *base, "--backend", "onnx")[0] == EXIT_USAGE  # needs --onnx
    code, _, err = _run(capsys, *base, "--checkpoint", ckpt, "--source-frame", "9999")
    assert code == EXIT_USAGE and "--source-frame" in err
    code, _, err = _run(capsys, *base, "--checkpoint", ckpt, "--target", WALK_TXT, "--truth", tmp_path / "t.bvh")
    assert code == EXIT_USAGE and "--truth" in err


def test_render_usage_errors(capsys, tmp_path):
    """spec/cli.md §render: an unknown output type or an empty frame range is a usage error."""
    pytest.importorskip("matplotlib")
    assert _run(capsys, "render", WALK_BVH, "--out", tmp_path / "x.jpg")[0] == EXIT_USAGE
    assert _run(capsys, "render", WALK_BVH, "--frames", "10:5", "--out", tmp_path / "x.png")[0] == EXIT_USAGE
    assert _run(capsys, "render", WALK_BVH, "--frames", "a:b")[0] == EXIT_USAGE


def test_missing_matplotlib_is_exit_1(capsys, tmp_path, monkeypatch):
    """spec/cli.md §exit codes: a missing optional dependency is a runtime failure (1) with the install hint."""
    for mod in ("matplotlib", "matplotlib.figure", "matplotlib.backends.backend_agg"):
        monkeypatch.setitem(sys.modules, mod, None)
    code, _, err = _run(capsys, "render", WALK_BVH, "--out", tmp_path / "x.png")
    assert code == EXIT_FAILURE and "refimpl[render]" in err


def test_runtime_failure_is_exit_1(capsys, trained, tmp_path):
    """spec/cli.md §exit codes: a failure while working (here: the output folder is a file) is exit 1."""
    blocker = tmp_path / "file"
    blocker.write_text("x")
    code, _, err = _run(capsys, "export", "--checkpoint", trained / "checkpoint.npz", "--out", blocker / "sub")
    assert code == EXIT_FAILURE and err.startswith("refimpl export: error:")


def test_import_is_light_and_module_entry_point():
    """spec/cli.md: importing the CLI loads neither deploy, onnx, onnxruntime nor matplotlib; python -m works."""
    code = ("import sys, refimpl.cli, refimpl.demo, refimpl.render; "
            "bad = [m for m in ('deploy', 'onnx', 'onnxruntime', 'matplotlib') if m in sys.modules]; "
            "print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-m", "refimpl", "info", str(WALK_BVH)], cwd=ROOT, capture_output=True,
                       text=True)
    assert r.returncode == 0 and "frames      344" in r.stdout
    r = subprocess.run([sys.executable, "-m", "refimpl", "info", "missing.bvh"], cwd=ROOT, capture_output=True,
                       text=True)
    assert r.returncode == EXIT_BAD_INPUT and "Traceback" not in r.stderr


# ---------------------------------------------------------------------------------------------------------
# the library functions behind the commands


def test_source_for_file_and_resolve_data(tmp_path):
    """spec/cli.md §2: file kinds from the joints, rates snapped, the four split rules."""
    from refimpl.errors import BadInputError
    from refimpl.tasks.transition import resolve_data

    s = source_for_file(WALK_BVH)
    assert (s.kind, s.fps) == ("cmu_bvh", 120.0)
    s = source_for_file(SAMPLE / "salsa" / "01.bvh", fps=60)
    assert (s.kind, s.fps) == ("salsa_bvh", 60.0)
    assert source_for_file(WALK_TXT).kind == "cmu_expmap"
    train, test = resolve_data("sample")
    assert train and test and {(x.path, x.frames) for x in train}.isdisjoint({(x.path, x.frames) for x in test})
    train, test = resolve_data(str(WALK_BVH), test_fraction=0.25)
    assert train[0].frames == (0.0, 0.75) and test[0].frames == (0.75, 1.0)
    flat = tmp_path / "flat"
    flat.mkdir()
    for f in sorted((SAMPLE / "expmap" / "train" / "running").glob("*.txt")):
        (flat / f.name).symlink_to(f)
    train, test = resolve_data(str(flat), test_fraction=0.4)
    assert [Path(x.path).name for x in test] == ["running_4.txt", "running_5.txt"] and len(train) == 3
    split = tmp_path / "split"
    (split / "train").mkdir(parents=True)
    (split / "test").mkdir()
    (split / "train" / "a.txt").symlink_to(WALK_TXT)
    (split / "test" / "b.txt").symlink_to(RUN_TXT)
    train, test = resolve_data(str(split))
    assert [Path(x.path).name for x in train] == ["a.txt"] and [Path(x.path).name for x in test] == ["b.txt"]
    odd = tmp_path / "odd.bvh"
    odd.write_text("HIERARCHY\nROOT Pelvis\n{\n OFFSET 0 0 0\n CHANNELS 3 Xrotation Yrotation Zrotation\n"
                   " End Site\n {\n OFFSET 0 1 0\n }\n}\nMOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0\n")
    with pytest.raises(BadInputError, match="skeleton not supported"):
        source_for_file(odd)


def _oracle(window):
    """A 'method' that returns the true transition of ``window`` (1, T + 4, P)."""
    def method(past, target, T):
        np.testing.assert_allclose(past, window[:, :2], atol=1e-9)
        np.testing.assert_allclose(target, window[:, -2:], atol=1e-9)
        return window[:, 2:-2]
    return method


def test_make_transition_round_trip():
    """spec/cli.md §7: window transform and its inverse are exact — an oracle method reproduces the truth."""
    from refimpl.tasks.transition_generate import make_transition
    from refimpl.protocols.transition import load_source, make_windows

    skel, clips = load_source(source_for_file(WALK_TXT))
    rot, pos = clips[0]
    s, T = 20, 30
    window = make_windows(rot[s - 1:s + T + 3], pos[s - 1:s + T + 3], length=T + 4)  # (1, T + 4, P)
    tr = make_transition(_oracle(window), skel, (rot, pos), s, (rot, pos), s + T + 1, T, frame_time=1 / 30,
                         context=5, same_clip=True)
    assert tr.truth is not None and (tr.start, tr.stop) == (5, 35)
    np.testing.assert_allclose(tr.motion.positions(), tr.truth.positions(), atol=1e-8)
    assert tr.error_cm() < 1e-8


def test_align_target_continues_the_source():
    """spec/cli.md §7: --align continue turns the target to the source's heading and keeps its height."""
    from refimpl.tasks.transition_generate import _align_target, _heading
    from refimpl.quat import quat_angle
    from refimpl.protocols.transition import load_source

    _, (src_clip, *_) = load_source(source_for_file(WALK_TXT))
    _, (tgt_clip, *_) = load_source(source_for_file(RUN_TXT))
    s, g, T = 30, 10, 30
    rot, pos = _align_target(*src_clip, s, *tgt_clip, g, T)
    assert float(quat_angle(_heading(rot[g, 0]), _heading(src_clip[0][s, 0]))) < 1e-9
    assert pos[g, 1] == pytest.approx(tgt_clip[1][g, 1])
    step = np.linalg.norm((pos[g] - src_clip[1][s])[[0, 2]])
    assert 0 < step < 60 * (T + 1)  # placed ahead of the source, at a walking-to-running distance
    # the target clip moved rigidly: distances between its frames are unchanged
    np.testing.assert_allclose(np.linalg.norm(np.diff(pos, axis=0), axis=1),
                               np.linalg.norm(np.diff(tgt_clip[1], axis=0), axis=1), atol=1e-9)


def test_with_end_sites_keeps_joints_and_round_trips(tmp_path):
    """spec/cli.md §7: End Sites are added below leaves; the original joints do not move; BVH round trip."""
    from refimpl.bvh import read_bvh
    from refimpl.bvh_write import write_bvh
    from refimpl.tasks.transition_generate import with_end_sites
    from refimpl.motion import Motion
    from refimpl.protocols.transition import load_source

    skel, clips = load_source(source_for_file(WALK_TXT))
    rot, pos = clips[0]
    m = Motion(skel, rot[:12], pos[:12], 1 / 30, "x")
    e = with_end_sites(m)
    assert e.num_joints == 27 and len(e.skeleton.end_sites) == 5
    assert {e.skeleton.names[j] for j in e.skeleton.end_sites} == {
        "LeftToeBase_end", "RightToeBase_end", "Head_end", "LeftHand_end", "RightHand_end"}
    np.testing.assert_allclose(e.positions()[:, :22], m.positions(), atol=1e-12)
    assert with_end_sites(e) is e
    write_bvh(tmp_path / "e.bvh", e)
    back = read_bvh(tmp_path / "e.bvh")  # joints in depth-first file order: compare by name
    order = [back.skeleton.index(n) for n in e.skeleton.names]
    np.testing.assert_allclose(back.positions()[:, order], e.positions(), atol=1e-3)


def test_blas_threads_limits_the_pool():
    """spec/cli.md §1: --blas-threads N limits OpenBLAS inside the command and restores it after."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    from refimpl.threads import blas_thread_pool

    before = [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    with blas_thread_pool(1):
        inside = [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    after = [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
    assert all(n == 1 for n in inside) and after == before
