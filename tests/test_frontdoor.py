"""Issue #27's rough edges, each with a test that fails on the old behaviour: options checked before data is
read, the thread default, and the defects a newcomer hit (spec/cli.md)."""
from __future__ import annotations

import numpy as np
import pytest

from refimpl.cli import build_parser, main


def test_blas_threads_default_is_one():
    # spec/cli.md §1: two threads collapse when other jobs share the cores (benchmarks/bench_thread_default.py)
    assert build_parser().get_default("blas_threads") == 1


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


def test_deploy_info_into_a_closed_pipe_stops_quietly(monkeypatch, capsys):
    import deploy.cli
    import deploy.runtime

    class _Model:
        inputs = [("x", (1, 3), np.float32)] * 20
        outputs = [("y", (1, 3), np.float32)] * 20
        metadata = {f"k{i}": i for i in range(50)}

    monkeypatch.setattr(deploy.runtime, "load_model", lambda path: _Model())
    monkeypatch.setattr("sys.stdout", _ClosedPipe())
    assert deploy.cli.main(["info", "model.onnx"]) == 1  # old: BrokenPipeError traceback
