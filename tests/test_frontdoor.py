"""Issue #27's rough edges, each with a test that fails on the old behaviour: options checked before data is
read, the thread default, and the defects a newcomer hit (spec/cli.md)."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.cli import build_parser, main


@pytest.mark.parametrize("model", ["qtg", "quaternet", "quaternet-cnn", "acrnn", "quaternet-long", "pace"])
def test_a_set_typo_is_exit_2_before_the_data_is_read(model, tmp_path, capsys):
    # --data names a folder that does not exist: reading it first would be exit 3
    rc = main(["train", "--model", model, "--data", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o"),
               "--set", "hiden_size=3", "--steps", "1"])
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "--set 'hiden_size=3'" in err and "nowhere" not in err
    assert not (tmp_path / "o").exists()


def test_a_set_value_of_the_wrong_type_is_exit_2_before_the_data_is_read(tmp_path, capsys):
    rc = main(["train", "--model", "quaternet-long", "--data", str(tmp_path / "nowhere"),
               "--out", str(tmp_path / "o"), "--set", "hidden_size=big", "--steps", "1"])
    assert rc == 2 and "'big' is not a valid int" in capsys.readouterr().err


class _ClosedPipe:
    """A stdout whose reader has gone away (``| head`` after ten lines)."""

    def __init__(self, lines_before_close: int = 2):
        self.left = lines_before_close

    def write(self, text):
        if "\n" in text:
            self.left -= 1
        if self.left < 0:
            raise BrokenPipeError(32, "Broken pipe")
        return len(text)

    def flush(self):
        if self.left < 0:
            raise BrokenPipeError(32, "Broken pipe")


def test_deploy_info_into_a_closed_pipe_stops_quietly(monkeypatch, capsys, tmp_path):
    import deploy.cli
    import deploy.runtime

    class _Model:
        inputs = [("x", (1, 3), np.float32)] * 20
        outputs = [("y", (1, 3), np.float32)] * 20
        metadata = {f"k{i}": i for i in range(50)}

    deploy.cli._parser()  # imports every exporter's module first, so none of them binds the stand-in below
    monkeypatch.setattr(deploy.runtime, "load_model", lambda path: _Model())
    monkeypatch.setattr("sys.stdout", _ClosedPipe())
    (tmp_path / "model.onnx").write_bytes(b"")  # info checks that the file exists (#35) before loading it
    assert deploy.cli.main(["info", str(tmp_path / "model.onnx")]) == 1  # old: BrokenPipeError traceback


# ------------------------------------------------------------------------------------------------ the defects
import dataclasses  # noqa: E402
import os  # noqa: E402
from pathlib import Path  # noqa: E402

from refimpl.checkpoint import load_checkpoint, save_checkpoint  # noqa: E402
from refimpl.registry import MODELS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SALSA = ROOT / "refimpl" / "data" / "sample" / "salsa"
WALK = ROOT / "refimpl" / "data" / "sample" / "expmap" / "test" / "walking" / "walking_1.txt"
ACRNN = ["--model", "acrnn", "--data", "sample", "--set", "hidden_size=8", "--set", "num_layers=2",
         "--batch-size", "3", "--window-length", "12", "--progress-every", "1", "--dtype", "float64"]
QN = ["--model", "quaternet", "--set", "hidden_size=8", "--set", "num_layers=1", "--set", "prefix_length=12",
      "--set", "target_length=4", "--batch-size", "6", "--progress-every", "1"]
QTG = ["--set", "encoder_sizes=16", "--set", "gru_hidden=16", "--set", "decoder_sizes=16", "--batch-size", "4",
       "--progress-every", "1"]


@pytest.fixture(scope="module")
def acrnn_ckpt(tmp_path_factory):
    out = tmp_path_factory.mktemp("acrnn")
    assert main(["train", *ACRNN, "--out", str(out), "--steps", "2"]) == 0
    return out / "checkpoint.npz"


@pytest.fixture(scope="module")
def qn_ckpt(tmp_path_factory):
    out = tmp_path_factory.mktemp("qn")
    assert main(["train", *QN, "--out", str(out), "--steps", "2"]) == 0
    return out / "checkpoint.npz"


def _snapshot(folder: Path) -> dict:
    return {p.name: (p.stat().st_size, p.stat().st_mtime_ns) for p in sorted(folder.iterdir())}


def test_export_into_a_folder_of_another_models_files_writes_nothing(acrnn_ckpt, tmp_path, capsys):
    pytest.importorskip("onnxruntime")
    qtg = tmp_path / "qtg"
    assert main(["train", *QTG, "--out", str(qtg), "--steps", "1"]) == 0
    onnx_dir = tmp_path / "onnx"
    assert main(["export", "--checkpoint", str(qtg / "checkpoint.npz"), "--out", str(onnx_dir)]) == 0
    before = _snapshot(onnx_dir)
    capsys.readouterr()
    rc = main(["export", "--checkpoint", str(acrnn_ckpt), "--out", str(onnx_dir)])
    err = capsys.readouterr().err
    assert rc == 2 and "holds ONNX models of another network" in err and "qtg" in err
    assert _snapshot(onnx_dir) == before  # old: acrnn_*.onnx written beside qtg_*.onnx, then a failure


def test_demo_quick_does_not_replace_a_full_demo(tmp_path, capsys):
    out = tmp_path / "demo"
    (out / "train").mkdir(parents=True)
    save_checkpoint(out / "train" / "checkpoint.npz", {"param.w": np.zeros(3)},
                    {"format": "refimpl.train/1", "steps_target": 3000})
    rc = main(["demo", "--quick", "--out", str(out), "--no-onnx", "--no-render"])
    assert rc == 2 and "3000-step demo" in capsys.readouterr().err
    assert load_checkpoint(out / "train" / "checkpoint.npz")[1]["steps_target"] == 3000


def test_acrnn_eval_on_training_takes_warns(acrnn_ckpt, monkeypatch, capsys):
    import refimpl.cli as cli
    from refimpl.services import load_trained

    model = load_trained(acrnn_ckpt)
    # as if trained on ../shared/data, whose training takes include 16, the embedded sample's test take
    seen = dataclasses.replace(model, extra={**model.extra, "train_takes": ["01", "02", "03", "16", "17", "18"]})
    monkeypatch.setattr(cli, "load_trained", lambda path: seen)
    assert main(["eval", "--checkpoint", str(acrnn_ckpt)]) == 0
    err = capsys.readouterr().err
    assert "warning: take(s) 16 of --data sample were training takes" in err
    monkeypatch.setattr(cli, "load_trained", lambda path: model)  # trained on take 01: no warning
    assert main(["eval", "--checkpoint", str(acrnn_ckpt)]) == 0
    assert "warning" not in capsys.readouterr().err


def test_resume_reuses_the_stored_options(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", *ACRNN, "--out", str(out), "--steps", "2"]) == 0
    capsys.readouterr()
    assert main(["train", "--out", str(out), "--resume", "--steps", "3"]) == 0  # old: --model qtg, exit 3
    _, meta = load_checkpoint(out / "checkpoint.npz")
    assert meta["model"] == "acrnn" and meta["step"] == 3
    assert meta["train_config"]["run_options"]["set"] == ["hidden_size=8", "num_layers=2"]
    # a flag given again with the same value is fine; one with another value is refused, field by field
    assert main(["train", "--out", str(out), "--resume", "--steps", "4", "--set", "hidden_size=8"]) == 0
    capsys.readouterr()
    rc = main(["train", "--out", str(out), "--resume", "--steps", "5", "--set", "hidden_size=16", "--lr", "0.5"])
    cap = capsys.readouterr()
    assert rc == 2
    assert "--set hidden_size: the checkpoint has 8, the command line 16" in cap.err
    assert "--lr: the checkpoint has 0.0001, the command line 0.5" in cap.err  # #35: the default's value, not None
    assert "num_layers" not in cap.err and "mean" not in cap.err and len(cap.err) < 600
    assert "reading" not in cap.out  # before any data is read
    assert load_checkpoint(out / "checkpoint.npz")[1]["step"] == 4


def test_info_of_an_acrnn_checkpoint_has_short_lines(acrnn_ckpt, capsys):
    assert main(["info", str(acrnn_ckpt)]) == 0
    out = capsys.readouterr().out
    assert "mean=<list, " in out and "hidden_size=8" in out and "std=<list, " in out
    lines = out.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith("config"))
    block = [lines[i]] + [line for line in lines[i + 1:] if line.startswith(" " * 12)][:10]
    assert max(len(line) for line in block) <= 112  # old: one config line of thousands of characters
    assert max(len(line) for line in lines) < 250


def test_acrnn_generate_does_not_seed_with_the_reference_pose(acrnn_ckpt, tmp_path, capsys):
    from refimpl.bvh import read_bvh
    from refimpl.protocols import synthesis as SP

    out = tmp_path / "g.bvh"
    assert main(["generate", "--checkpoint", str(acrnn_ckpt), "--source", str(SALSA / "16.bvh"),
                 "--length", "3", "--out", str(out)]) == 0
    assert "(from frame 1 at 30 fps)" in capsys.readouterr().out
    m, src = read_bvh(out), SP.load_salsa_motion(SALSA / "16.bvh")
    idx = [list(m.skeleton.names).index(n) for n in src.skeleton.names]
    np.testing.assert_allclose(m.positions()[:10, idx], src.positions()[1:11] / SP.LENGTH_SCALE, atol=1e-3)


def test_train_out_defaults_to_the_models_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert build_parser().parse_args(["train"]).out is None
    assert main(["train", *ACRNN, "--steps", "1"]) == 0
    assert (tmp_path / "runs" / "acrnn" / "checkpoint.npz").is_file()  # old: runs/qtg
    assert not (tmp_path / "runs" / "qtg").exists()


def test_quaternet_png_carries_the_bvh_frame_numbers_and_a_title(qn_ckpt, tmp_path, monkeypatch, capsys):
    import refimpl.render_strip as render

    seen = {}

    def fake_strip(path, positions, parents, **kw):
        seen.update(kw, n=positions.shape[0])
        return Path(path)
    monkeypatch.setattr(render, "render_strip", fake_strip)
    assert main(["generate", "--checkpoint", str(qn_ckpt), "--source", str(WALK), "--source-frame", "40",
                 "--length", "6", "--out", str(tmp_path / "p.bvh"), "--png", str(tmp_path / "p.png")]) == 0
    out = capsys.readouterr().out
    start = int(out.split("predicted ")[1].split("..")[0])
    numbers = np.asarray(seen["frame_numbers"])  # old: not passed, panels numbered from 0
    assert numbers[seen["highlight"][0]] == start and numbers[-1] == start + 5
    assert seen["title"] and f"frames {start}-{start + 5} predicted" in seen["title"]


def test_model_option_disagreeing_with_the_checkpoint_is_refused(acrnn_ckpt, capsys):
    assert main(["eval", "--model", "quaternet", "--checkpoint", str(acrnn_ckpt)]) == 2
    assert "holds a acrnn model" in capsys.readouterr().err
    assert main(["generate", "--model", "quaternet", "--checkpoint", str(acrnn_ckpt),
                 "--source", str(SALSA / "16.bvh")]) == 2


def test_target_is_refused_by_a_prediction_model(qn_ckpt, tmp_path, capsys):
    rc = main(["generate", "--checkpoint", str(qn_ckpt), "--source", str(WALK), "--source-frame", "40",
               "--target", str(WALK), "--out", str(tmp_path / "p.bvh")])
    assert rc == 2 and "--target" in capsys.readouterr().err  # old: ignored, exit 0
    assert not (tmp_path / "p.bvh").exists()


@pytest.mark.parametrize("length", [["--steps", "0"], ["--epochs", "0"]])
def test_train_zero_steps_is_refused(tmp_path, capsys, length):
    assert main(["train", *ACRNN, "--out", str(tmp_path / "z"), *length]) == 2
    assert "nothing to train" in capsys.readouterr().err
    assert not (tmp_path / "z" / "checkpoint.npz").exists()


def test_top_level_help_names_every_model_and_task(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for name in MODELS:
        assert name in out
    assert "generate a transition between two clips" not in out  # old: generate and export described as QTG's
    assert "export a checkpoint of any model" in out
    from refimpl.registry import TASKS, task_of

    assert main(["generate", "--help"]) == 0
    usage = capsys.readouterr().out
    for name in TASKS:
        assert task_of(name).GENERATE_USAGE.split("[")[0].strip().split()[-1] in usage


def test_ci_runs_the_readmes_two_commands():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    block = readme.split("## The two commands", 1)[1].split("```bash", 1)[1].split("```", 1)[0]
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    assert 'python -m pip install -c constraints.txt -e ".[all]" && refimpl demo' in block
    assert "python -m pytest -q" in block
    for command in ('python -m pip install -c constraints.txt -e ".[all]"', "refimpl demo", "python -m pytest -q"):
        assert command in ci, command


def test_reconcile_fills_defaults_and_reports_only_differences():
    import argparse

    from refimpl.run_options import reconcile, run_options

    defaults = {"model": "qtg", "lr": None, "set": [], "seed": 0, "betas": None}
    args = argparse.Namespace(model="qtg", lr=None, set=["b=2"], seed=0, betas=None)
    stored = {"model": "acrnn", "lr": 0.001, "set": ["a=1", "b=2"], "seed": 3, "betas": [0.5, 0.9]}
    assert reconcile(args, stored, defaults) == []
    assert (args.model, args.lr, args.set, args.seed, args.betas) == ("acrnn", 0.001, ["a=1", "b=2"], 3, (0.5, 0.9))
    assert run_options(args, ["model", "betas", "missing"]) == {"model": "acrnn", "betas": [0.5, 0.9]}
    args = argparse.Namespace(model="acrnn", lr=0.01, set=["a=5", "b=2"], seed=0, betas=None)
    conflicts = reconcile(args, stored, defaults)
    assert sorted(conflicts) == ["--lr: the checkpoint has 0.001, the command line 0.01",
                                 "--set a: the checkpoint has 1, the command line 5"]
    assert args.lr == 0.01 and args.set == ["a=5", "b=2"]  # conflicting options are left as given


def test_check_overrides_needs_no_data():
    from refimpl.errors import UsageError
    from refimpl.models.qtg import QTGConfig
    from refimpl.options import check_overrides

    assert check_overrides(QTGConfig, ["gru_hidden=64", "encoder_sizes=8,4"]) == {"gru_hidden": 64,
                                                                                 "encoder_sizes": (8, 4)}
    for bad in (["gru_hiden=64"], ["gru_hidden=x"], ["gru_hidden"]):
        with pytest.raises(UsageError):
            check_overrides(QTGConfig, bad)
