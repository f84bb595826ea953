"""``--blas-threads auto`` (refimpl/threads.py, spec/cli.md §1): the jiffies arithmetic on fake /proc readings,
the hysteresis, the fallback without /proc, the option's parsing, and training that changes the pool mid-run."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from refimpl import threads
from refimpl.cli import build_parser, main
from refimpl.threads import (AUTO, DROP_ABOVE, RAISE_BELOW, AutoThreads, blas_thread_pool, choose_threads,
                             other_cores, read_jiffies, threads_option)


def _proc(tmp_path, cpu_line: str, self_line: str):
    (tmp_path / "stat").write_text(cpu_line + "\ncpu0 1 2 3 4 5 6 7 8 0 0\nintr 123\n")
    (tmp_path / "self_stat").write_text(self_line + "\n")
    return str(tmp_path / "stat"), str(tmp_path / "self_stat")


def test_read_jiffies_sums_the_busy_fields_and_this_process_utime_stime(tmp_path):
    # user nice system idle iowait irq softirq steal guest guest_nice; the command name holds ") (" and spaces
    paths = _proc(tmp_path, "cpu  100 20 30 9999 500 4 5 6 70 0",
                  "1234 (py (x) 2) R 1 2 3 4 5 6 7 8 9 10 41 17 0 0 20 0 3 0 99 1 2")
    assert read_jiffies(*paths) == (100 + 20 + 30 + 4 + 5 + 6, 41 + 17)


def test_read_jiffies_is_none_without_proc(tmp_path):
    assert read_jiffies(str(tmp_path / "missing"), str(tmp_path / "missing2")) is None
    paths = _proc(tmp_path, "cpu  1 2", "1 (x) R 1")  # truncated lines
    assert read_jiffies(*paths) is None


def test_other_cores_subtracts_this_process_and_divides_by_wall_jiffies():
    # 2 s at 100 jiffies/s: the machine was busy 350 jiffies, this process 150 of them -> others 1 core
    assert other_cores((1000, 500), (1350, 650), 2.0, 100) == pytest.approx(1.0)
    assert other_cores((1000, 500), (1100, 600), 2.0, 100) == 0.0            # all of it was ours
    assert other_cores((1000, 500), (1100, 610), 2.0, 100) == 0.0            # rounding below 0 is clamped
    with pytest.raises(ValueError, match="positive"):
        other_cores((0, 0), (1, 0), 0.0, 100)


@pytest.mark.parametrize("others, current, want", [
    (0.0, 1, 2), (RAISE_BELOW - 0.01, 1, 2), (RAISE_BELOW, 1, 1), (0.45, 1, 1),  # up only when clearly idle
    (0.45, 2, 2), (DROP_ABOVE - 0.01, 2, 2), (DROP_ABOVE, 2, 1), (1.9, 2, 1),     # down only when clearly busy
])
def test_choose_threads_on_two_cores_has_hysteresis(others, current, want):
    assert choose_threads(others, current, 2) == want


def test_choose_threads_on_eight_cores_leaves_the_others_their_cores():
    assert choose_threads(0.0, 1, 8) == 8
    assert choose_threads(3.0, 1, 8) == 5         # 5 free: 3.0 < 8 - 5 + 0.3
    assert choose_threads(3.5, 5, 8) == 5         # kept: 3.5 < 8 - 5 + 0.6
    assert choose_threads(3.7, 5, 8) == 4
    assert choose_threads(20.0, 8, 8) == 1
    assert choose_threads(0.0, 1, 1) == 1


class _Fake:
    """A /proc reader and a clock: each step adds ``others`` cores of busy jiffies over ``dt`` seconds."""

    def __init__(self, dt=1.0, hz=100):
        self.t, self.busy, self.own, self.dt, self.hz, self.others = 0.0, 0, 0, dt, hz, 0.0

    def advance(self, others, own=0.5):
        self.t += self.dt
        self.busy += round((others + own) * self.dt * self.hz)
        self.own += round(own * self.dt * self.hz)

    def read(self):
        return self.busy, self.own


def test_auto_threads_follows_the_other_jobs_and_applies_only_changes():
    fake, applied = _Fake(), []
    auto = AutoThreads(applied.append, cores=2, read=fake.read, clock=lambda: fake.t, hz=100, every=2.0)
    assert auto.start(sleep=lambda s: fake.advance(0.0)) == 2 and auto.others == 0.0
    for others, want in [(1.0, 2), (1.0, 1), (0.5, 1), (0.5, 1), (0.0, 1), (0.1, 2), (0.1, 2)]:
        fake.advance(others)  # 1 s per poll: every other poll measures (the last 2 s)
        assert auto.poll() == want, (others, auto.others)
    assert applied == [2, 1, 2] and auto.applied == applied


def test_auto_threads_starts_at_one_beside_a_busy_core():
    fake, applied = _Fake(), []
    auto = AutoThreads(applied.append, cores=2, read=fake.read, clock=lambda: fake.t, hz=100)
    assert auto.start(sleep=lambda s: fake.advance(1.0)) == 1 and auto.others == pytest.approx(1.0)
    assert applied == [1]


def test_auto_threads_keeps_an_explicit_thread_count_of_the_environment(monkeypatch):
    fake = _Fake()
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    monkeypatch.setenv("MKL_NUM_THREADS", "x")  # not a number: ignored
    assert AutoThreads(print, read=fake.read).cores == 1
    monkeypatch.delenv("OPENBLAS_NUM_THREADS")
    monkeypatch.setattr(threads.os, "cpu_count", lambda: 8)
    auto = AutoThreads(print, read=fake.read, clock=lambda: fake.t, hz=100)
    assert auto.cores == 3 and auto.start(sleep=lambda s: fake.advance(0.0)) == 3


def test_auto_threads_without_proc_is_one_thread_for_good():
    applied, t = [], [0.0]
    auto = AutoThreads(applied.append, cores=8, read=lambda: None, clock=lambda: t[0], every=0.0)
    assert auto.start(sleep=pytest.fail) == 1
    t[0] = 100.0
    assert auto.poll() == 1 and applied == [1] and auto.others is None


@pytest.mark.parametrize("text, want", [("auto", AUTO), ("AUTO", AUTO), ("1", 1), ("2", 2), ("0", 0)])
def test_blas_threads_option_parses(text, want):
    assert threads_option(text) == want
    assert build_parser().parse_args(["--blas-threads", text, "info", "x"]).blas_threads == want


def test_blas_threads_default_is_auto_but_one_for_the_demo():
    """Every command defaults to auto; the demo to one thread (its README numbers on every machine), unless
    --blas-threads is given."""
    from refimpl.cli import blas_threads_for

    parser = build_parser()
    assert blas_threads_for(parser.parse_args(["info", "x"])) == AUTO
    assert blas_threads_for(parser.parse_args(["train", "--out", "r"])) == AUTO
    assert blas_threads_for(parser.parse_args(["demo"])) == 1
    assert blas_threads_for(parser.parse_args(["--blas-threads", "auto", "demo"])) == AUTO
    assert blas_threads_for(parser.parse_args(["--blas-threads", "2", "demo"])) == 2


@pytest.mark.parametrize("bad", ["-1", "1025", "two", "auto2", "1.5", ""])
def test_a_bad_blas_threads_is_exit_2(bad, capsys):
    assert main(["--blas-threads", bad, "info", "x.bvh"]) == 2
    err = capsys.readouterr().err
    assert "--blas-threads" in err and "'auto' or an integer in [0, 1024]" in err


def test_blas_thread_pool_sets_and_restores_the_pool(monkeypatch):
    threadpoolctl = pytest.importorskip("threadpoolctl")

    def blas():
        return [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]

    before = blas()
    with blas_thread_pool(2) as auto:
        assert auto is None and all(n == 2 for n in blas())
    assert blas() == before
    monkeypatch.setattr(threads, "read_jiffies", lambda: None)  # no /proc: auto is 1 thread
    with blas_thread_pool(AUTO) as auto:
        assert auto.threads == 1 and all(n == 1 for n in blas())
    assert blas() == before
    with blas_thread_pool(0) as auto:
        assert auto is None and blas() == before


def _losses(run) -> np.ndarray:
    with open(run / "loss.csv", newline="") as f:
        return np.array([float(r["loss"]) for r in csv.DictReader(f)])


def test_train_with_auto_switching_threads_gives_the_losses_of_one_thread(tmp_path, monkeypatch, capsys):
    """spec/cli.md §1: the count changes the BLAS pool, and the results only by float rounding."""
    pytest.importorskip("threadpoolctl")
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):  # they cap auto (next test)
        monkeypatch.delenv(name, raising=False)
    common = ["train", "--steps", "6", "--progress-every", "1"]  # the default network: BLAS calls big enough to split
    assert main(["--blas-threads", "1", *common, "--out", str(tmp_path / "one")]) == 0
    calls = iter(range(10**6))
    # every read alternates idle / two busy cores (jiffies far above the wall time): auto flips 2 -> 1 -> 2 ...
    monkeypatch.setattr(threads, "read_jiffies", lambda: (10**6 * (next(calls) % 2), 0))
    monkeypatch.setattr(threads, "POLL_SECONDS", 0.0)
    capsys.readouterr()
    assert main([*common, "--out", str(tmp_path / "auto")]) == 0
    out = capsys.readouterr().out
    assert "BLAS threads (auto): 1 -> 2 -> 1 -> 2" in out, out
    # float32 rounding: the split of a matrix product between threads may change the last bits (spec/cli.md §1)
    np.testing.assert_allclose(_losses(tmp_path / "auto"), _losses(tmp_path / "one"), rtol=1e-5)
