"""refimpl.allocator: glibc keeps freed memory for the next step (spec/cli.md §1, ``--malloc``)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from refimpl import cli
from refimpl.allocator import MMAP_THRESHOLD_MAX, _glibc, retain_freed_memory

ROOT = Path(__file__).resolve().parents[1]
WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"

# A training step's pattern: ten 3 MB arrays allocated, touched and freed, five times; the page faults of the
# last repetitions, before and after retain_freed_memory(), printed by a fresh process.
_PROBE = textwrap.dedent("""
    import resource, sys
    import numpy as np
    from refimpl.allocator import retain_freed_memory

    def faults():
        r = resource.getrusage(resource.RUSAGE_SELF)
        return r.ru_minflt + r.ru_majflt

    def steps(n):
        for _ in range(n):
            arrays = [np.ones(750_000, np.float32) for _ in range(10)]
            del arrays

    steps(2)
    f0 = faults(); steps(5); before = faults() - f0
    ok = retain_freed_memory()
    steps(2)
    f0 = faults(); steps(5); after = faults() - f0
    print(before, after, ok)
""")


@pytest.mark.skipif(_glibc() is None, reason="needs glibc (mallopt)")
def test_retain_freed_memory_removes_the_page_faults_of_repeated_steps():
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, check=True, cwd=ROOT)
    before, after, ok = out.stdout.split()
    before, after = int(before), int(after)
    assert ok == "True"
    # glibc's defaults return the 30 MB to the system after every step: ≈ 7,300 faults per step (4 KiB pages)
    assert before > 5 * 3000, before
    assert after < before / 50, (before, after)


@pytest.mark.skipif(_glibc() is None, reason="needs glibc (mallopt)")
def test_retain_freed_memory_accepts_the_bounds():
    assert retain_freed_memory(MMAP_THRESHOLD_MAX, 2 ** 31 - 1) is True
    assert retain_freed_memory() is True


@pytest.mark.parametrize("kwargs", [
    {"mmap_threshold": -1}, {"mmap_threshold": MMAP_THRESHOLD_MAX + 1}, {"trim_threshold": 2 ** 31},
    {"trim_threshold": -5}, {"mmap_threshold": 1.5}, {"trim_threshold": True}, {"mmap_threshold": "32"},
])
def test_retain_freed_memory_rejects_bad_thresholds(kwargs):
    with pytest.raises(ValueError, match="threshold"):
        retain_freed_memory(**kwargs)


def test_non_glibc_platform_changes_nothing(monkeypatch):
    monkeypatch.setattr(sys, "platform", "darwin")
    assert _glibc() is None
    assert retain_freed_memory() is False


@pytest.mark.parametrize("argv, calls", [([], 1), (["--malloc", "retain"], 1), (["--malloc", "system"], 0)])
def test_cli_applies_the_setting_unless_system(monkeypatch, capsys, argv, calls):
    seen = []
    monkeypatch.setattr(cli, "retain_freed_memory", lambda: seen.append(1) or True)
    assert cli.main(argv + ["info", str(WALK_BVH)]) == 0
    assert len(seen) == calls
    assert "joints" in capsys.readouterr().out.lower()


def test_cli_rejects_unknown_malloc_mode(capsys):
    assert cli.main(["--malloc", "jemalloc", "info", str(WALK_BVH)]) == 2
    assert "invalid choice" in capsys.readouterr().err
