"""spec/cli.md §exit codes, spec/robustness.md §9: damaged or crafted input files on the command line give exit 3
and one clear line on stderr, never a traceback or raw exception text.

Checkpoints: empty, truncated, bit-flipped, junk, and crafted (re-signed) ones given to ``train --resume``,
``export``, ``eval``, ``info``, ``generate``. Exported models whose metadata frame rate is 0 or whose fields have the
wrong type given to ``generate --backend onnx``.
"""
from __future__ import annotations

import copy
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint, save_checkpoint
from refimpl.cli import EXIT_BAD_INPUT, EXIT_OK, main

ROOT = Path(__file__).resolve().parents[1]
WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
TINY = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]
TRAIN = ["--data", str(WALK_BVH), "--batch-size", "8", "--stride", "8", "--test-fraction", "0.5",
         "--progress-every", "1", *TINY]
RAW_TEXT = ("dictionary update sequence", "has no attribute", "object is not", "unhashable", "Traceback",
            "unsupported operand", "not subscriptable", "division by zero")


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    out = tmp_path_factory.mktemp("faults")
    assert main(["train", "--out", str(out), "--steps", "2", *TRAIN]) == EXIT_OK
    return out


def _damaged(good: Path, kind: str, dst: Path) -> Path:
    data = good.read_bytes()
    arrays, meta = load_checkpoint(good)
    if kind == "empty":
        dst.write_bytes(b"")
    elif kind == "truncated":
        dst.write_bytes(data[: len(data) // 2])
    elif kind == "bitflip":
        b = bytearray(data)
        b[len(b) // 3] ^= 0x10
        dst.write_bytes(bytes(b))
    elif kind == "junk":
        dst.write_bytes(os.urandom(2000))
    elif kind == "text":
        dst.write_text("not a checkpoint\n")
    else:  # crafted: the content edited, the checksum recomputed
        arrays, meta = copy.deepcopy(arrays), copy.deepcopy(meta)
        if kind == "config-list":
            meta["model_config"] = ["gru_hidden", "8"]
        elif kind == "config-bool":
            meta["model_config"] = True
        elif kind == "fps-0":
            meta["model_config"]["fps"] = 0
        elif kind == "root-std-0":
            meta["model_config"]["root_std"] = [0.0, 0.0, 0.0]
        elif kind == "layers-bool":
            meta["model_config"]["gru_layers"] = True
        elif kind == "param-nan":
            arrays["param.vel.bias"] = np.full_like(arrays["param.vel.bias"], np.nan)
        elif kind == "param-missing":
            del arrays["param.vel.weight"]
        elif kind == "optim-nan":
            arrays["optim.v.vel.bias"] = np.full_like(arrays["optim.v.vel.bias"], np.nan)
        elif kind == "meta-step":
            meta["step"] = "two"
        save_checkpoint(dst, arrays, meta)
    return dst


KINDS = ["empty", "truncated", "bitflip", "junk", "text", "config-list", "config-bool", "fps-0", "root-std-0",
         "layers-bool", "param-nan", "param-missing"]


def _one_clear_line(err: str, command: str):
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"refimpl {command}: error: "), err
    for raw in RAW_TEXT:
        assert raw not in err, err


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("command", ["info", "export", "eval", "generate", "train"])
def test_damaged_checkpoint_exit_3(capsys, trained, tmp_path, kind, command):
    """Every command that reads a checkpoint: exit 3, one line naming the file, nothing written."""
    if command == "train":
        out = tmp_path / "run"
        out.mkdir()
        bad = _damaged(trained / "checkpoint.npz", kind, out / "checkpoint.npz")
        before = bad.read_bytes()
        argv = ["train", "--out", str(out), "--steps", "4", "--resume", *TRAIN]
    else:
        bad = _damaged(trained / "checkpoint.npz", kind, tmp_path / "bad.npz")
        before = bad.read_bytes()
        argv = {"info": ["info", bad],
                "export": ["export", "--checkpoint", bad, "--out", tmp_path / "onnx"],
                "eval": ["eval", "--checkpoint", bad, "--data", WALK_BVH],
                "generate": ["generate", "--source", WALK_BVH, "--source-frame", "20", "--checkpoint", bad,
                             "--out", tmp_path / "t.bvh"]}[command]
    capsys.readouterr()
    code = main([str(a) for a in argv])
    out_text, err = capsys.readouterr()
    assert code == EXIT_BAD_INPUT, (code, err)
    _one_clear_line(err, command)
    assert str(bad) in err
    assert bad.read_bytes() == before
    assert not (tmp_path / "onnx").exists() and not (tmp_path / "t.bvh").exists()


@pytest.mark.parametrize("kind", ["optim-nan", "meta-step"])
def test_resume_refuses_bad_training_state(capsys, trained, tmp_path, kind):
    """Resume-only state (Adam moments, counters) that fails its schema: the trainer refuses it with one line."""
    out = tmp_path / "run"
    out.mkdir()
    bad = _damaged(trained / "checkpoint.npz", kind, out / "checkpoint.npz")
    before = bad.read_bytes()
    code = main(["train", "--out", str(out), "--steps", "4", "--resume", *TRAIN])
    _, err = capsys.readouterr()
    assert code == EXIT_BAD_INPUT, err
    _one_clear_line(err, "train")
    assert ("optim.v.vel.bias" if kind == "optim-nan" else "step") in err
    assert bad.read_bytes() == before


def test_subprocess_damaged_checkpoint_no_traceback(trained, tmp_path):
    """The real process: exit 3, stderr exactly one line, no traceback, no warnings."""
    bad = _damaged(trained / "checkpoint.npz", "config-list", tmp_path / "bad.npz")
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run([sys.executable, "-m", "refimpl", "export", "--checkpoint", str(bad)], capture_output=True,
                       text=True, env=env, timeout=120)
    assert r.returncode == EXIT_BAD_INPUT, r.stderr
    _one_clear_line(r.stderr, "export")
    assert "model_config" in r.stderr


@pytest.fixture(scope="module")
def exported(trained, tmp_path_factory):
    pytest.importorskip("onnxruntime")
    out = tmp_path_factory.mktemp("onnx")
    assert main(["export", "--checkpoint", str(trained / "checkpoint.npz"), "--out", str(out), "--no-verify",
                 "--transition-length", "6"]) == EXIT_OK
    return out


def _edit_metadata(src: Path, dst: Path, edit) -> Path:
    import onnx

    shutil.copytree(src, dst)
    for f in dst.glob("*.onnx"):
        m = onnx.load(str(f))
        props = {p.key: p.value for p in m.metadata_props}
        edit(props)
        del m.metadata_props[:]
        for k, v in props.items():
            m.metadata_props.add(key=k, value=v)
        onnx.save(m, str(f))
    return dst


def _set(key, value):
    def edit(props):
        props[key] = json.dumps(value)
    return edit


def _set_model(key, value):
    def edit(props):
        model = json.loads(props["model"])
        model[key] = value
        props["model"] = json.dumps(model)
    return edit


ONNX_CASES = {
    "frame_rate 0": _set("frame_rate", 0),
    "frame_rate negative": _set("frame_rate", -30.0),
    "frame_rate string": _set("frame_rate", "30"),
    "frame_rate bool": _set("frame_rate", True),
    "frame_rate list": _set("frame_rate", [30]),
    "frame_rate huge int": _set("frame_rate", 10**400),
    "model list": _set("model", ["qtg"]),
    "model string": _set("model", "qtg"),
    "T string": _set_model("transition_length", "6"),
    "T 0": _set_model("transition_length", 0),
    "T huge": _set_model("transition_length", 10**12),
}


@pytest.mark.parametrize("case", sorted(ONNX_CASES))
def test_generate_onnx_bad_metadata_exit_3(capsys, exported, tmp_path, case):
    """``generate --backend onnx`` with a frame rate of 0 or wrong-typed metadata: exit 3, one line."""
    d = _edit_metadata(exported, tmp_path / "models", ONNX_CASES[case])
    code = main(["generate", "--backend", "onnx", "--onnx", str(d), "--source", str(WALK_BVH), "--source-frame",
                 "20", "--out", str(tmp_path / "t.bvh")])
    _, err = capsys.readouterr()
    assert code == EXIT_BAD_INPUT, (code, err)
    _one_clear_line(err, "generate")
    assert not (tmp_path / "t.bvh").exists()


def test_generate_onnx_good_metadata_still_works(capsys, exported, tmp_path):
    """The unedited export generates (the checks refuse only bad metadata)."""
    code = main(["generate", "--backend", "onnx", "--onnx", str(exported), "--source", str(WALK_BVH),
                 "--source-frame", "20", "--out", str(tmp_path / "t.bvh")])
    _, err = capsys.readouterr()
    assert code == EXIT_OK, err
    assert (tmp_path / "t.bvh").is_file()
