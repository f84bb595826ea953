"""Issue #35's rough edges, each with a test that fails on the old behaviour (4f4f4ef): options where users put
them, ``train --resume`` with the run's stored options and budget, and the messages a newcomer hit
(spec/cli.md)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint
from refimpl.cli import build_parser, main
from refimpl.train_files import load_state, save_state

ROOT = Path(__file__).resolve().parents[1]
WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
QTG = ["--data", str(WALK_BVH), "--batch-size", "8", "--test-fraction", "0.5", "--set", "encoder_sizes=16,8",
       "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]


@pytest.mark.parametrize("argv", [["train", "--steps", "1", "--blas-threads", "1"],
                                  ["--blas-threads", "2", "train", "--blas-threads", "1"],
                                  ["eval", "--blas-threads", "1", "--traceback", "--malloc", "system"]])
def test_global_options_after_the_command(argv):
    args = build_parser().parse_args(argv)  # old: "unrecognized arguments: --blas-threads 1", exit 2
    assert args.blas_threads == 1


def test_a_global_option_before_the_command_is_kept():
    args = build_parser().parse_args(["--blas-threads", "2", "--traceback", "info", "x.bvh"])
    assert args.blas_threads == 2 and args.traceback is True and args.malloc == "retain"


def test_a_typo_shows_the_commands_usage(capsys):
    assert main(["train", "--modle", "qtg"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("usage: refimpl train") and "refimpl train: error: unrecognized arguments: --modle" in err


@pytest.fixture()
def qtg_run(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", *QTG, "--stride", "8", "--out", str(out), "--steps", "2", "--checkpoint-every", "1",
                 "--progress-every", "1", "--validate-every", "1"]) == 0
    capsys.readouterr()
    return out


def test_resume_restores_the_stride_and_the_intervals(qtg_run, capsys):
    # old: the default --stride 4 gave another number of windows, and the sampler refused the checkpoint
    assert main(["train", "--out", str(qtg_run), "--resume", "--steps", "3"]) == 0
    cap = capsys.readouterr()
    meta = load_checkpoint(qtg_run / "checkpoint.npz")[1]
    assert meta["step"] == 3 and meta["train_config"]["run_options"]["stride"] == 8
    tc = meta["train_config"]
    assert (tc["checkpoint_every"], tc["progress_every"], tc["validate_every"]) == (1, 1, 1)  # old: 500, 50, None
    assert cap.err.count("it/s") >= 1
    assert len((qtg_run / "loss_val.csv").read_text().splitlines()) == 4  # header + steps 1, 2, 3


def test_resume_without_steps_goes_to_the_stored_budget_and_a_finished_run_is_refused(qtg_run, capsys):
    rc = main(["train", "--out", str(qtg_run), "--resume"])  # old: trained on to the default 10 epochs
    cap = capsys.readouterr()
    assert rc == 2, cap.err
    assert "is at step 2 of a 2-step budget: nothing to train (pass --steps N with N > 2" in cap.err
    assert len(cap.err.strip().splitlines()) == 1 and "reading" not in cap.out
    assert load_checkpoint(qtg_run / "checkpoint.npz")[1]["step"] == 2


def test_resume_of_an_interrupted_run_goes_to_its_budget(qtg_run, capsys):
    params, opt, perm, meta = load_state(qtg_run / "checkpoint.npz")
    meta["train_config"]["steps"] = 4  # as a 4-step run stopped at step 2 stores it
    save_state(qtg_run / "checkpoint.npz", params, opt, perm, meta)
    assert main(["train", "--out", str(qtg_run), "--resume"]) == 0
    assert load_checkpoint(qtg_run / "checkpoint.npz")[1]["step"] == 4


def test_a_differing_option_names_the_defaults_value(qtg_run, capsys):
    rc = main(["train", "--out", str(qtg_run), "--resume", "--steps", "3", "--lr", "0.5", "--stride", "2"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "--lr: the checkpoint has 0.0001, the command line 0.5" in err  # old: "the checkpoint has None"
    assert "--stride: the checkpoint has 8, the command line 2" in err


def test_an_old_checkpoint_without_the_new_fields_still_resumes(qtg_run, capsys):
    params, opt, perm, meta = load_state(qtg_run / "checkpoint.npz")
    stored = meta["train_config"]["run_options"]
    for name in ("stride", "fps", "test_fraction"):
        del stored[name]
    stored["lr"] = stored["betas"] = None  # as checkpoints before #35 held them
    save_state(qtg_run / "checkpoint.npz", params, opt, perm, meta)
    rc = main(["train", "--out", str(qtg_run), "--resume", "--steps", "3", "--lr", "0.5"])
    assert rc == 2 and "--lr: the checkpoint has 0.0001, the command line 0.5" in capsys.readouterr().err
    # the flags as given fill what the checkpoint lacks (here the run's own)
    assert main(["train", "--out", str(qtg_run), "--resume", "--steps", "3", "--stride", "8", "--test-fraction", "0.5"]) == 0
    assert load_checkpoint(qtg_run / "checkpoint.npz")[1]["step"] == 3


# ------------------------------------------------------------------------------------------------------------
# refimpl import: the layout before the data; the joint-count hint


def test_import_qtg_with_the_published_layout_is_refused_before_the_data_is_read(tmp_path, capsys):
    np.savez(tmp_path / "w.npz", x=np.zeros(2, np.float32))
    rc = main(["import", str(tmp_path / "w.npz"), "--model", "qtg", "--layout", "published", "--data",
               str(tmp_path / "nowhere"), "--out", str(tmp_path / "c.npz")])
    err = capsys.readouterr().err
    assert rc == 2 and "no published code" in err and "nowhere" not in err  # old: read the data first


def test_import_qtg_defaults_to_the_refimpl_layout(tmp_path, capsys):
    np.savez(tmp_path / "w.npz", x=np.zeros(2, np.float32))  # not QTG's names: a bad input file, exit 3
    rc = main(["import", str(tmp_path / "w.npz"), "--model", "qtg", "--out", str(tmp_path / "c.npz"),
               "--data", str(WALK_BVH)])
    err = capsys.readouterr().err
    assert rc == 3 and "layout 'refimpl'" in err  # old: exit 2, "--layout published: ... no published code"


def test_import_with_the_right_names_and_another_skeleton_names_the_joint_count(tmp_path, capsys):
    from refimpl.registry import MODELS, task_of
    from refimpl.weights import layout_names

    spec = MODELS["quaternet"]
    # the published names, with the input and output sizes of another skeleton than the sample's
    args = build_parser().parse_args(["train", "--model", "quaternet", "--set", "hidden_size=8"])
    train_ds, _ = task_of(spec).train_datasets(args)
    config = spec.make_config(train_ds, ("hidden_size=8",))
    rng = np.random.default_rng(0)
    state = {n: rng.uniform(-0.1, 0.1, tuple(d - 20 if d > 100 else d for d in s)).astype(np.float32)
             for n, s in layout_names(spec, config, "published").values()}
    np.savez(tmp_path / "w.npz", **state)
    rc = main(["import", str(tmp_path / "w.npz"), "--model", "quaternet", "--set", "hidden_size=8",
               "--out", str(tmp_path / "c.npz")])
    err = capsys.readouterr().err
    assert rc == 3, err
    assert "joint count of --data's skeleton" in err and "names of --layout refimpl" not in err  # old: the hint
    assert "other layer sizes: --set one of" in err


# ------------------------------------------------------------------------------------------------------------
# python -m deploy: info of a folder, exit 3 for a missing or undecodable model, messages of run


def test_deploy_info_of_a_folder_a_missing_and_an_undecodable_model(qtg_run, tmp_path, capsys):
    from deploy.cli import main as deploy_main

    models = tmp_path / "models"
    assert deploy_main(["export", str(qtg_run / "checkpoint.npz"), str(models)]) == 0
    capsys.readouterr()
    assert deploy_main(["info", str(models)]) == 0  # old: "model: no such file 'models'", exit 2
    out = capsys.readouterr().out
    assert "== qtg_init.onnx ==" in out and "== qtg_rollout.onnx ==" in out and out.count("inputs:") >= 3
    assert deploy_main(["info", str(tmp_path / "none.onnx")]) == 3  # old: 2
    (tmp_path / "junk.onnx").write_bytes(b"\x00not a model" * 10)
    assert deploy_main(["info", str(tmp_path / "junk.onnx")]) == 3  # old: 2
    err = capsys.readouterr().err
    assert "none.onnx: no such file" in err and "junk.onnx" in err and "ONNX model" in err
    (tmp_path / "empty").mkdir()
    assert deploy_main(["info", str(tmp_path / "empty")]) == 3


def test_a_quaternet_start_out_of_range_names_start():
    from refimpl.errors import UsageError
    from refimpl.skeletons import cmu_skeleton
    from refimpl.tasks.prediction import make_prediction

    rot = np.tile(np.array([1.0, 0, 0, 0]), (60, 38, 1))
    with pytest.raises(UsageError, match=r"^--start must lie in \[49, 59\]"):  # old: "--source-frame"
        make_prediction(lambda p, k: None, rot, 30, 50, 10, skeleton=cmu_skeleton(), frame_time=0.04, option="--start")


def test_the_short_walk_warning_names_the_default_length_when_seconds_was_not_given():
    from types import SimpleNamespace

    from refimpl.tasks.locomotion import short_walk_warning

    walk = SimpleNamespace(motion=SimpleNamespace(num_frames=100))
    assert "--seconds 10 asked for 300 frames" in short_walk_warning(walk, 10.0)
    text = short_walk_warning(walk, 10.0, given=False)
    assert "--seconds" not in text and "the default length (10 s) is 300 frames" in text  # old: "--seconds 10"


def test_foot_skating_without_a_contact_is_said_not_nan():
    from refimpl.tasks.locomotion import skating_phrase
    from refimpl.tasks.locomotion_generate import foot_skating

    flying = np.zeros((20, 3, 3))
    flying[:, 2, 1] = np.linspace(0.0, 10.0, 20)  # the foot only rises: at most one frame near its lowest height
    skate = foot_skating(flying, [2])
    assert not np.isfinite(skate["speed_cm_s"])
    text = skating_phrase(skate)
    assert "nan" not in text and "no foot in contact" in text  # old: "foot skating nan cm/s"
    assert skating_phrase({"speed_cm_s": 3.25, "contact_fraction": 0.41}) == \
        "foot skating 3.2 cm/s in contact (41 % of foot-frames)"


def test_refimpl_cache_lists_and_clears_only_its_entries(tmp_path, monkeypatch, capsys):
    from refimpl.datacache import save_entry

    monkeypatch.setenv("REFIMPL_CACHE", str(tmp_path / "c"))
    save_entry("loco", "ab" * 32, {"x": np.zeros((100, 3))})
    (tmp_path / "c" / "notes.txt").write_text("mine")
    assert main(["cache"]) == 0  # old: not a command (exit 2)
    out = capsys.readouterr().out
    assert "1 entries" in out and f"loco-{'ab' * 12}.npz" in out
    assert main(["cache", "--clear"]) == 0
    assert "cleared: 1 entries" in capsys.readouterr().out
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == ["notes.txt"]
    monkeypatch.setenv("REFIMPL_CACHE", "off")
    assert main(["cache"]) == 0 and "off" in capsys.readouterr().out


# ------------------------------------------------------------------------------------------------------------
# progress on the steps of a minute: the locomotion files read for transitions, GIF frames, acRNN's seeds


class _Clock:
    """A perf_counter that advances 6 s per call: every progress check is due."""

    def __init__(self):
        self.t = 0.0

    def perf_counter(self):
        self.t += 6.0
        return self.t


def test_reading_the_locomotion_files_reports_progress():
    from refimpl.protocols.transition_cache import _read_all

    lines = []
    got = _read_all(range(3), lambda src, **kw: (src, kw), 30, lines.append, every_s=-1.0)
    assert got == [(i, {"fps": 30}) for i in range(3)]
    assert lines[0].strip().startswith("read 1 of 3 files") and lines[-1].strip().startswith("read 3 of 3 files")


def test_a_gif_reports_progress(tmp_path, monkeypatch):
    pytest.importorskip("matplotlib")
    import refimpl.progress
    import refimpl.render as render

    monkeypatch.setattr(refimpl.progress, "time", _Clock())
    pos = np.zeros((4, 2, 3))
    pos[:, 1, 1] = 1.0
    lines = []
    render.render_gif(tmp_path / "a.gif", pos, np.array([-1, 0]), progress=lines.append)
    assert lines and lines[0].startswith("a.gif: frame ") and "of 4" in lines[0]  # old: no progress at all


def test_the_acrnn_evaluation_reports_progress(monkeypatch):
    import refimpl.progress
    from refimpl.tasks import synthesis

    monkeypatch.setattr(refimpl.progress, "time", _Clock())
    monkeypatch.setattr(synthesis, "evaluate_generator",
                        lambda gen, data, max_seeds, progress: (progress("64/128 seeds, 6 s"), {"num_seeds": 128})[1])
    lines = []
    out = synthesis.evaluate(None, {"network": None, "hold": None}, progress=lines.append)
    assert set(out) == {"network", "hold"}
    assert lines[0] == "evaluating network (1 of 2) ..." and "  network: 64/128 seeds, 6 s" in lines
    assert any(line.startswith("  hold: 128 seeds in") for line in lines)
