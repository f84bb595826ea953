"""Issue #27's rough edges, each with a test that fails on the old behaviour: options checked before data is
read, the thread default, and the defects a newcomer hit (spec/cli.md)."""
from __future__ import annotations

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
