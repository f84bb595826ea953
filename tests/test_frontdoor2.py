"""Issue #35's rough edges, each with a test that fails on the old behaviour (4f4f4ef): options where users put
them, ``train --resume`` with the run's stored options and budget, and the messages a newcomer hit
(spec/cli.md)."""
from __future__ import annotations

from pathlib import Path

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
