"""refimpl.progress: the one rule of the long steps' progress lines (stderr_line, Throttle)."""
from __future__ import annotations

import types

import refimpl.progress as progress
from refimpl.progress import PROGRESS_EVERY_S, Throttle, stderr_line


def test_stderr_line_goes_to_stderr(capsys):
    stderr_line("  read 3 of 9 files, 6 s")
    out = capsys.readouterr()
    assert out.out == "" and out.err == "  read 3 of 9 files, 6 s\n"


def test_throttle_is_due_every_interval_and_counts_from_the_start(monkeypatch):
    now = iter([100.0, 102.0, 105.5, 106.0, 111.0, 111.2])         # start, then one reading per due()
    monkeypatch.setattr(progress, "time", types.SimpleNamespace(perf_counter=lambda: next(now)))
    tick = Throttle()
    assert PROGRESS_EVERY_S == 5.0
    got = []
    for _ in range(5):
        got.append((tick.due(), tick.elapsed))
    assert got == [(False, 0.0), (True, 5.5), (False, 5.5), (True, 11.0), (False, 11.0)]


def test_a_negative_interval_is_always_due():
    tick = Throttle(-1.0)
    assert all(tick.due() for _ in range(3)) and tick.elapsed >= 0.0
