"""Atomic writes (refimpl/atomic.py; spec/robustness.md): complete file or untouched target, no leftovers."""
import os

import pytest

from refimpl.atomic import atomic_path, atomic_write_bytes, atomic_write_text


def test_write_and_replace(tmp_path):
    p = tmp_path / "sub" / "a.txt"
    with pytest.raises(OSError):
        atomic_write_text(p, "no folder")
    atomic_write_text(p, "one\r\ntwo\n", make_parents=True)
    assert p.read_bytes() == b"one\r\ntwo\n"  # no newline translation
    atomic_write_bytes(p, b"\x00\x01")
    assert p.read_bytes() == b"\x00\x01"
    assert sorted(os.listdir(p.parent)) == ["a.txt"]


def test_failure_leaves_target_untouched_and_no_temp(tmp_path):
    p = tmp_path / "b.bin"
    p.write_bytes(b"old")
    with pytest.raises(RuntimeError):
        with atomic_path(p) as tmp:
            tmp.write_bytes(b"partial")
            raise RuntimeError("writer failed")
    assert p.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["b.bin"]


def test_temp_keeps_suffix_and_folder(tmp_path):
    p = tmp_path / "fig.png"
    with atomic_path(p) as tmp:
        assert tmp.parent == p.parent and tmp.suffix == ".png" and tmp.exists()
        tmp.write_bytes(b"png")
    assert p.read_bytes() == b"png"
