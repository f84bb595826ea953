"""Tests of refimpl.datacache and refimpl.tasks.locomotion_cache: hit, miss, invalidation, corruption, no pickle,
and the cached locomotion sequences equal to freshly read ones (spec/data.md §7)."""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from refimpl import datacache
from refimpl.datacache import cache_dir, cached, entry_path, fingerprint, load_entry, save_entry
from refimpl.protocols import locomotion_data as loco
from refimpl.protocols.locomotion import build_dataset
from refimpl.protocols.locomotion_cache import decode_sequences, encode_sequences, load_sequences, loader_version
from refimpl.protocols.transition import SAMPLE_DIR

EXPMAP = Path(SAMPLE_DIR) / "expmap"


def test_cache_dir_follows_the_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("REFIMPL_CACHE", str(tmp_path / "c"))
    assert cache_dir() == tmp_path / "c"
    for off in ("off", "0", ""):
        monkeypatch.setenv("REFIMPL_CACHE", off)
        assert cache_dir() is None and entry_path("x", "ab" * 32) is None
    monkeypatch.delenv("REFIMPL_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "refimpl"


def test_fingerprint_changes_with_each_input(tmp_path):
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("1 2 3")
    b.write_text("4 5 6")
    base = fingerprint([a, b], name="n", version=1, options={"o": 1})
    assert base == fingerprint([a, b], name="n", version=1, options={"o": 1})
    assert base != fingerprint([b, a], name="n", version=1, options={"o": 1})
    assert base != fingerprint([a], name="n", version=1, options={"o": 1})
    assert base != fingerprint([a, b], name="n", version=2, options={"o": 1})
    assert base != fingerprint([a, b], name="n", version=1, options={"o": 2})
    assert base != fingerprint([a, b], name="m", version=1, options={"o": 1})
    a.write_text("1 2 3 4")  # size
    assert base != fingerprint([a, b], name="n", version=1, options={"o": 1})
    a.write_text("1 2 3")
    st = a.stat()
    os.utime(a, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))  # same size, newer mtime
    assert base != fingerprint([a, b], name="n", version=1, options={"o": 1})
    with pytest.raises(OSError):
        fingerprint([tmp_path / "missing"], name="n", version=1)


def test_save_and_load_round_trip_without_pickle(tmp_path):
    arrays = {"x": np.arange(12.0).reshape(3, 4), "n": np.array(["a", "bc"]), "i": np.array([1, 2], np.int64)}
    path = save_entry("t", "k" * 64, arrays, {"rig": "r"}, folder=tmp_path)
    assert path.is_file() and path.parent == tmp_path
    with np.load(path, allow_pickle=False) as z:  # readable without pickle
        assert set(z.files) == {"x", "n", "i", "__meta__", "__checksum__"}
    got, meta, status = load_entry("t", "k" * 64, folder=tmp_path)
    assert status == "hit" and meta == {"rig": "r"}
    for k in arrays:
        np.testing.assert_array_equal(got[k], arrays[k])
    assert load_entry("t", "j" * 64, folder=tmp_path)[2] == "miss"
    with pytest.raises(ValueError, match="object"):
        save_entry("t", "k" * 64, {"o": np.array([{}, 1], dtype=object)}, folder=tmp_path)


def test_an_entry_under_another_key_is_not_used(tmp_path):
    p = save_entry("t", "a" * 64, {"x": np.zeros(3)}, folder=tmp_path)
    other = entry_path("t", "a" * 24 + "b" * 40, tmp_path)  # same file name, different full key
    assert other == p
    assert load_entry("t", "a" * 24 + "b" * 40, folder=tmp_path)[2].startswith("corrupt")


def _counting_build(value):
    calls = []

    def build():
        calls.append(1)
        return value
    return build, calls


def _enc(v):
    return {"v": np.asarray(v)}, {}


def _dec(a, m):
    return a["v"].copy()


def test_cached_miss_then_hit(tmp_path):
    build, calls = _counting_build(np.arange(5.0))
    msgs = []
    first = cached("t", "c" * 64, build, _enc, _dec, folder=tmp_path, progress=msgs.append)
    second = cached("t", "c" * 64, build, _enc, _dec, folder=tmp_path, progress=msgs.append)
    assert len(calls) == 1
    np.testing.assert_array_equal(first, second)
    assert "cached as" in msgs[0] and "loaded from the cache" in msgs[1]


@pytest.mark.parametrize("damage", ["garbage", "truncate", "flip"])
def test_a_corrupted_entry_is_ignored_and_rebuilt(tmp_path, damage):
    value = np.linspace(0.0, 1.0, 4000)
    build, calls = _counting_build(value)
    cached("t", "d" * 64, build, _enc, _dec, folder=tmp_path)
    path = entry_path("t", "d" * 64, tmp_path)
    raw = bytearray(path.read_bytes())
    if damage == "garbage":
        raw = bytearray(b"not a zip file at all")
    elif damage == "truncate":
        raw = raw[: len(raw) // 2]
    else:  # one byte inside the stored array: the zip is intact (stored, no CRC check by numpy), the checksum not
        i = raw.find(np.float64(value[2000]).tobytes())
        assert i > 0
        raw[i] ^= 0x01
    path.write_bytes(bytes(raw))
    status = load_entry("t", "d" * 64, folder=tmp_path)[2]
    assert status.startswith("corrupt")
    msgs = []
    got = cached("t", "d" * 64, build, _enc, _dec, folder=tmp_path, progress=msgs.append)
    assert len(calls) == 2 and "ignored" in msgs[0]
    np.testing.assert_array_equal(got, value)
    assert load_entry("t", "d" * 64, folder=tmp_path)[2] == "hit"  # rewritten


def test_cache_off_writes_nothing(tmp_path, monkeypatch):
    monkeypatch.setenv("REFIMPL_CACHE", "off")
    build, calls = _counting_build(np.zeros(2))
    cached("t", "e" * 64, build, _enc, _dec)
    cached("t", "e" * 64, build, _enc, _dec)
    assert len(calls) == 2


# ---------------------------------------------------------------------------------------------- locomotion


@pytest.fixture()
def small_folder(tmp_path):
    """Three embedded CMU exp-map files in a folder of their own (so their mtimes can change)."""
    src = sorted(EXPMAP.rglob("*.txt"))[:3]
    out = tmp_path / "data"
    out.mkdir()
    for p in src:
        shutil.copy(p, out / f"{len(list(out.iterdir()))}_{p.name}")
    return sorted(str(p) for p in out.glob("*.txt"))


def _fresh(files, mirror=True):
    seqs = []
    for f in files:
        m = loco.load_cmu_expmap(f)
        seqs.extend(loco.build_sequences(m, loco.CMU_RIG, mirror=mirror, source=Path(f).stem))
    return seqs, loco.CMU_RIG


def _assert_same(a, b):
    assert [s.name for s in a] == [s.name for s in b] and [s.source for s in a] == [s.source for s in b]
    for x, y in zip(a, b):
        for f in ("rotations", "trajectory", "positions_world", "positions_local", "phase", "features"):
            np.testing.assert_array_equal(getattr(x, f), getattr(y, f))
        assert x.skeleton.names == y.skeleton.names and x.skeleton.end_sites == y.skeleton.end_sites
        np.testing.assert_array_equal(x.skeleton.offsets, y.skeleton.offsets)
        np.testing.assert_array_equal(x.skeleton.parents, y.skeleton.parents)
        assert x.skeleton.joints_left == y.skeleton.joints_left


def test_encode_decode_sequences_is_exact(small_folder):
    seqs, rig = _fresh(small_folder)
    arrays, meta = encode_sequences((seqs, rig))
    back, rig2 = decode_sequences(arrays, meta, loco.LocomotionSequence, (loco.CMU_RIG, loco.BANDAI_NAMCO_RIG))
    assert rig2 is rig and meta["skeletons"] == 1
    _assert_same(back, seqs)


def test_locomotion_cache_hit_miss_and_invalidation(small_folder, tmp_path):
    folder = tmp_path / "cache"
    calls = []

    def read(mirror=True):
        calls.append(1)
        return _fresh(small_folder, mirror)

    def load(files, build, mirror=True):
        return load_sequences(files, build, sequence_type=loco.LocomotionSequence, rigs=(loco.CMU_RIG,),
                              options=dict(kind="cmu_expmap", mirror=mirror), folder=folder)

    first, _ = load(small_folder, read)
    second, _ = load(small_folder, read)
    assert len(calls) == 1
    _assert_same(second, first)
    # options are part of the key
    load(small_folder, lambda: read(False), mirror=False)
    assert len(calls) == 2
    # a touched file invalidates the entry
    st = os.stat(small_folder[0])
    os.utime(small_folder[0], ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    load(small_folder, read)
    assert len(calls) == 3
    # a file fewer is another key
    load(small_folder[:2], lambda: _fresh(small_folder[:2]))
    third, _ = load(small_folder, read)
    assert len(calls) == 3
    _assert_same(third, first)


def test_loader_version_hashes_the_loader_source(monkeypatch):
    v = loader_version(loco.LocomotionSequence)
    assert v == loader_version(loco.LocomotionSequence) and len(v) == 64
    import refimpl.protocols.locomotion_cache as lc

    monkeypatch.setattr(lc, "LOADER_VERSION", lc.LOADER_VERSION + 1)
    assert loader_version(loco.LocomotionSequence) != v


def test_build_dataset_through_the_cache_equals_a_fresh_read(small_folder, monkeypatch, tmp_path):
    monkeypatch.setenv("REFIMPL_CACHE", "off")
    fresh = build_dataset("cmu_expmap", small_folder, prefix=5, target=5)
    monkeypatch.setenv("REFIMPL_CACHE", str(tmp_path / "c"))
    build_dataset("cmu_expmap", small_folder, prefix=5, target=5)
    assert len(list((tmp_path / "c").glob("*.npz"))) == 1
    cached_ds = build_dataset("cmu_expmap", small_folder, prefix=5, target=5)
    _assert_same(cached_ds.sequences, fresh.sequences)
    assert cached_ds.rig is fresh.rig and cached_ds.files == fresh.files
    assert datacache.__all__  # public names exist


def test_pace_data_through_the_cache_equals_a_fresh_computation(small_folder, monkeypatch, tmp_path):
    monkeypatch.setenv("REFIMPL_CACHE", str(tmp_path / "c"))
    ds = build_dataset("cmu_expmap", small_folder, prefix=5, target=5)
    assert ds.cache_key
    first = ds.pace_data()
    assert len(list((tmp_path / "c").glob("locomotion-pace-*.npz"))) == 1
    import refimpl.protocols.locomotion as L

    monkeypatch.setattr(L, "pace_training_data", lambda spline: (_ for _ in ()).throw(AssertionError("rebuilt")))
    second = ds.pace_data()  # from the cache: the patched builder is not called
    assert len(second) == len(first) > 0
    for (a, b), (c, d) in zip(first, second):
        np.testing.assert_array_equal(a, c)
        np.testing.assert_array_equal(b, d)
