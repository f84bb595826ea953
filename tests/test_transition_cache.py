"""The transition task's takes through the data cache (refimpl/protocols/transition_cache.py, spec/data.md §7).

The synthetic tests (a fake reader over small files) always run; the ones on real Bandai Namco takes copy a few of
``../shared/data/bandai_namco_locomotion`` and are skipped when it is absent.
"""
from __future__ import annotations

import os
import shutil
import types
from pathlib import Path

import numpy as np
import pytest

from refimpl.cli import main
from refimpl.protocols import transition_locomotion as tl
from refimpl.protocols.transition import TransitionSource
from refimpl.protocols.transition_cache import (cached_loader, decode_takes, encode_takes, load_takes, loader_version,
                                                takes_key)
from refimpl.skeleton import Skeleton

from conftest import SHARED_DATA

BN = SHARED_DATA / "bandai_namco_locomotion"
TINY = ["--set", "encoder_sizes=8,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=8"]


def _skeleton(rng, J=5) -> Skeleton:
    return Skeleton([-1, 0, 1, 0, 3][:J], rng.standard_normal((J, 3)), names=[f"j{i}" for i in range(J)],
                    end_sites=[2], joints_left=[1], joints_right=[3])


def _fake_reader(rng):
    """A reader over tiny files: (skeleton, clips) from the file's bytes (two clips for files named *2*)."""
    skels = [_skeleton(rng), _skeleton(rng)]
    calls = []

    def read(source, fps=30.0):
        calls.append(source.path)
        n = len(Path(source.path).read_bytes())
        k = 2 if "2" in Path(source.path).name else 1
        clips = [(np.full((n + p, 5, 4), float(n)), np.full((n + p, 3), -float(p))) for p in range(k)]
        return skels[n % 2], clips

    return read, calls


def _sources(tmp_path, names=("a1", "b2", "c3")):
    out = []
    for i, name in enumerate(names):
        p = tmp_path / f"{name}.bvh"
        p.write_text("x" * (3 + i))
        out.append(TransitionSource(str(p), "fake", 30.0, name))
    return out


def _same(a, b):
    assert len(a) == len(b)
    for (sa, ca), (sb, cb) in zip(a, b):
        assert sa == sb and len(ca) == len(cb)
        for (ra, pa), (rb, pb) in zip(ca, cb):
            assert ra.dtype == rb.dtype and np.array_equal(ra, rb) and np.array_equal(pa, pb)


def test_encode_decode_round_trip():
    rng = np.random.default_rng(0)
    s1, s2 = _skeleton(rng), _skeleton(rng)
    loaded = [(s1, [(rng.standard_normal((4, 5, 4)), rng.standard_normal((4, 3)))]),
              (s2, [(rng.standard_normal((2, 5, 4)), rng.standard_normal((2, 3))),
                    (rng.standard_normal((3, 5, 4)), rng.standard_normal((3, 3)))]),
              (s1, [])]
    arrays, meta = encode_takes(loaded)
    assert meta == {"sources": 3, "skeletons": 2}
    assert all(a.dtype != object for a in arrays.values())
    _same(decode_takes(arrays, meta), loaded)
    with pytest.raises(ValueError, match="add up"):
        decode_takes({**arrays, "clip_lengths": arrays["clip_lengths"] + 1}, meta)


def test_second_load_does_not_read_and_order_does_not_matter(tmp_path):
    read, calls = _fake_reader(np.random.default_rng(1))
    srcs = _sources(tmp_path)
    first = load_takes(srcs, read, folder=tmp_path / "cache")
    assert len(calls) == 3

    def refuse(source, fps=30.0):
        raise AssertionError("the reader ran although the cache holds these takes")

    refuse.__module__ = read.__module__  # the same loader version
    _same(load_takes(srcs, refuse, folder=tmp_path / "cache"), first)
    _same(load_takes(srcs[::-1], refuse, folder=tmp_path / "cache"), first[::-1])
    assert takes_key(srcs, read, 30.0) == takes_key(srcs[::-1], read, 30.0)
    assert takes_key(srcs, read, 30.0) != takes_key(srcs, read, 15.0)
    assert len(list((tmp_path / "cache").glob("transition-takes-*.npz"))) == 1


def test_changed_added_or_removed_file_reads_again(tmp_path):
    read, calls = _fake_reader(np.random.default_rng(2))
    srcs = _sources(tmp_path)
    cache = tmp_path / "cache"
    load_takes(srcs, read, folder=cache)
    calls.clear()
    st = os.stat(srcs[1].path)
    os.utime(srcs[1].path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))   # only the mtime changes
    load_takes(srcs, read, folder=cache)
    assert len(calls) == 3
    calls.clear()
    load_takes(srcs[:2], read, folder=cache)                                    # another list: another entry
    assert len(calls) == 2
    Path(srcs[0].path).write_text("changed content")
    got = load_takes(srcs, read, folder=cache)
    assert got[0][1][0][0][0, 0, 0] == len("changed content")


def test_damaged_entry_is_rebuilt_and_listed_by_refimpl_cache(tmp_path):
    from refimpl.cache_cli import cache_entries

    read, calls = _fake_reader(np.random.default_rng(4))
    srcs, cache = _sources(tmp_path), tmp_path / "cache"
    first = load_takes(srcs, read, folder=cache)
    (entry,) = cache_entries(cache)
    assert entry.name.startswith("transition-takes-")
    entry.write_bytes(entry.read_bytes()[: entry.stat().st_size // 2])
    calls.clear()
    notes = []
    _same(load_takes(srcs, read, folder=cache, progress=notes.append), first)
    assert len(calls) == 3 and any("cache entry ignored" in n for n in notes)
    calls.clear()
    load_takes(srcs, read, folder=cache)
    assert calls == []                                                          # rewritten whole


def test_cached_loader_answers_only_its_sources(tmp_path):
    read, _ = _fake_reader(np.random.default_rng(3))
    train, test = _sources(tmp_path, ("a1", "b2")), _sources(tmp_path, ("t1",))
    load = cached_loader((train, test), read, folder=tmp_path / "cache")
    assert np.array_equal(load(test[0])[1][0][0], read(test[0])[1][0][0])
    with pytest.raises(ValueError, match="fps"):
        load(train[0], fps=15.0)
    with pytest.raises(KeyError):
        load(TransitionSource(str(tmp_path / "other.bvh"), "fake", 30.0, "x"))
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 2     # one entry per side


def test_loader_version_follows_the_reader_module():
    assert loader_version(tl.load_bandai_namco_source) == loader_version(tl.load_bandai_namco_source)
    assert loader_version(tl.load_bandai_namco_source) != loader_version(_fake_reader)


# ---- real takes ----

@pytest.fixture()
def takes(tmp_path) -> Path:
    if not BN.is_dir():
        pytest.skip("../shared/data/bandai_namco_locomotion is absent")
    out = tmp_path / "bn"
    out.mkdir()
    for name in ("walk_normal", "run_elderly"):
        for i in (1, 2):
            shutil.copy(BN / f"dataset-2_{name}_{i:03d}.bvh", out)
    return out


def _no_parsing(monkeypatch):
    def refuse(*a, **k):
        raise AssertionError("a BVH file was parsed although the cache holds it")

    monkeypatch.setattr(tl, "load_bandai_namco", refuse)


def test_second_build_parses_no_bvh_and_equals_the_uncached(takes, tmp_path, monkeypatch):
    monkeypatch.setenv("REFIMPL_CACHE", "off")
    ref_train, ref_test = tl.build_datasets(takes, T=20, stride=8)
    monkeypatch.setenv("REFIMPL_CACHE", str(tmp_path / "cache"))
    lines = []
    tl.build_datasets(takes, T=20, stride=8, progress=lines.append)
    assert sum("cached as" in line for line in lines) == 2
    _no_parsing(monkeypatch)
    lines.clear()
    train, test = tl.build_datasets(takes, T=20, stride=8, progress=lines.append)
    assert sum("loaded from the cache" in line for line in lines) == 2
    for a, b in ((train, ref_train), (test, ref_test)):
        assert np.array_equal(a.poses, b.poses) and np.array_equal(a.skeleton_index, b.skeleton_index)
        assert a.skeletons == b.skeletons and np.array_equal(a.root_mean, b.root_mean)
    held = tl.heldout_dataset(takes, train.root_mean, train.root_std, T=20, stride=8)
    assert np.array_equal(held.poses, test.poses)


def test_eval_reads_only_the_heldout_entry(takes, tmp_path, monkeypatch, capsys):
    """After training, `refimpl eval` on the folder parses no BVH and loads only the held-out takes' entry."""
    monkeypatch.setenv("REFIMPL_CACHE", str(tmp_path / "cache"))
    run = tmp_path / "run"
    assert main(["--blas-threads", "1", "train", "--model", "qtg", "--data", str(takes), "--steps", "1",
                 "--stride", "16", "--transition-length", "10", *TINY, "--out", str(run)]) == 0
    _no_parsing(monkeypatch)
    import refimpl.datacache as dc

    loaded = []
    real = dc.read_npz
    monkeypatch.setattr(dc, "read_npz", lambda path, **k: loaded.append(path) or real(path, **k))
    capsys.readouterr()
    assert main(["eval", "--checkpoint", str(run / "checkpoint.npz"), "--data", str(takes), "--stride", "8"]) == 0
    assert "the 2 held-out takes" in capsys.readouterr().out
    assert len(loaded) == 1
    assert len(real(loaded[0], kinds="biufcUS", allow_compressed=False)["clips_per_source"]) == 2


# ---- progress of the long steps (issue 35) ----

def test_evaluation_reports_progress_and_keeps_the_methods(monkeypatch, capsys):
    """A slow evaluation says which method and measure it has reached; the numbers are the same; a method's
    ``needs_skeleton`` survives the wrapping."""
    from refimpl.tasks import transition_report as task

    def f(past, target, T, **kw):
        return np.repeat(past[:, -1:], T, axis=1)

    g = lambda past, target, T, skeleton=None: f(past, target, T)  # noqa: E731
    g.needs_skeleton = True
    clock = task._Clock(every_s=-1.0)
    wrapped = clock.wrap({"hold": f, "feet": g}, "error")
    assert wrapped["feet"].needs_skeleton and not wrapped["hold"].needs_skeleton
    past = np.zeros((2, 2, 7))
    assert np.array_equal(wrapped["hold"](past, past, 3), f(past, past, 3))
    assert wrapped["feet"](past, past, 3, skeleton=None).shape == (2, 3, 7)
    err = capsys.readouterr().err
    assert "evaluating: hold (error)" in err and "evaluating: feet (error)" in err
    quiet = task._Clock()                                   # a quick evaluation prints nothing
    quiet.wrap({"hold": f}, "error")["hold"](past, past, 3)
    assert capsys.readouterr().err == ""


def test_locomotion_reading_reports_progress_by_time(tmp_path, monkeypatch):
    """The locomotion reader reports every ~5 s (not every 100 files: the held-out 95 said nothing)."""
    import refimpl.progress
    import refimpl.protocols.locomotion as loco
    from refimpl.tasks.locomotion import resolve_files

    monkeypatch.setenv("REFIMPL_CACHE", "off")
    ticks = iter(np.arange(0.0, 1000.0, 6.0))
    monkeypatch.setattr(refimpl.progress, "time", types.SimpleNamespace(perf_counter=lambda: float(next(ticks))))
    kind, train, _ = resolve_files("sample")
    lines = []
    loco.build_dataset(kind, train[:3], prefix=5, target=5, progress=lines.append)
    assert lines == [f"  loaded {i}/3 files, {6 * i:.0f} s" for i in (1, 2, 3)]
