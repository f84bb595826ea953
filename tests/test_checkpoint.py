"""Tests of refimpl.checkpoint (spec/optim.md §5): round trip, the documented checksum, corruption and truncation
refused with ValueError, no pickle, atomic writes, plain state dicts, parameter checks and generator state."""
from __future__ import annotations

import hashlib
import json
import os
import zipfile

import numpy as np
import pytest

import refimpl.checkpoint as ckpt
from refimpl.checkpoint import (
    check_params,
    load_checkpoint,
    load_state_dict_npz,
    rng_from_json,
    rng_state_to_json,
    save_checkpoint,
)


def _arrays():
    rng = np.random.default_rng(0)
    return {
        "rnn.weight_ih_l0": rng.standard_normal((6, 4)).astype(np.float32),
        "fc.bias": rng.standard_normal(3),
        "optim.step": np.array(7, dtype=np.int64),
        "optim.m.fc.bias": np.zeros(3),
        "mask": np.array([True, False, True]),
        "empty": np.zeros((0, 2)),
    }


def _small():
    """A small checkpoint payload (two members + meta + checksum) for the byte-by-byte damage tests."""
    return {"w": np.arange(6, dtype=np.float32).reshape(2, 3), "optim.step": np.array(3, dtype=np.int64)}


def _same(a, b):
    return set(a) == set(b) and all(a[k].dtype == b[k].dtype and a[k].shape == b[k].shape
                                    and np.array_equal(a[k], b[k]) for k in a)


def test_round_trip_and_plain_npz(tmp_path):
    """spec/optim.md §5.1: arrays (names, dtypes, shapes, values) and metadata survive; the file is a plain
    .npz readable with np.load(allow_pickle=False) whose __meta__ is JSON text."""
    path = tmp_path / "model.npz"
    meta = {"epoch": 12, "config": {"hidden": 1000, "betas": [0.9, 0.999]}, "name": "quaternet"}
    save_checkpoint(path, _arrays(), meta)
    arrays, got = load_checkpoint(path)
    assert _same(arrays, _arrays()) and got == meta
    with np.load(path, allow_pickle=False) as z:
        assert set(z.files) == set(_arrays()) | {"__meta__", "__checksum__"}
        assert json.loads(z["__meta__"].tobytes().decode("utf-8")) == meta
    save_checkpoint(str(path), _arrays())  # overwrite, str path, default meta
    assert load_checkpoint(path)[1] == {}
    if os.name == "posix":  # the usual permissions (0o666 & ~umask), not a temp file's 0o600
        umask = os.umask(0)
        os.umask(umask)
        assert os.stat(path).st_mode & 0o777 == 0o666 & ~umask


def test_checksum_follows_the_spec(tmp_path):
    """spec/optim.md §5.1: SHA-256 over sorted names of utf8(name)\\0 shape\\0 dtype.str\\0 C-order bytes,
    recomputed here independently from the stored members."""
    path = tmp_path / "c.npz"
    save_checkpoint(path, _arrays(), {"a": 1})
    with np.load(path, allow_pickle=False) as z:
        members = {k: z[k] for k in z.files}
    h = hashlib.sha256()
    for name in sorted(k for k in members if k != "__checksum__"):
        a = members[name]
        h.update(name.encode() + b"\0" + ",".join(map(str, a.shape)).encode() + b"\0" + a.dtype.str.encode()
                 + b"\0" + np.ascontiguousarray(a).tobytes())
    assert members["__checksum__"].tobytes() == h.digest()


def test_every_truncation_is_refused(tmp_path):
    """spec/optim.md §5.2: a file cut at any length raises ValueError (never a crash, never partial data)."""
    path = tmp_path / "t.npz"
    save_checkpoint(path, _small(), {"epoch": 1})
    data = path.read_bytes()
    bad = tmp_path / "bad.npz"
    for n in range(len(data)):
        bad.write_bytes(data[:n])
        with pytest.raises(ValueError):
            load_checkpoint(bad)


def test_every_flipped_byte_is_refused_or_harmless(tmp_path):
    """spec/optim.md §5.2: flipping any single byte either raises ValueError or (zip timestamps and other
    unchecked header fields) leaves the loaded arrays and metadata identical."""
    path = tmp_path / "f.npz"
    meta = {"epoch": 1}
    save_checkpoint(path, _small(), meta)
    data = path.read_bytes()
    bad = tmp_path / "bad.npz"
    refused = 0
    for i in range(len(data)):
        flipped = bytearray(data)
        flipped[i] ^= 0xFF
        bad.write_bytes(bytes(flipped))
        try:
            arrays, got = load_checkpoint(bad)
        except ValueError:
            refused += 1
            continue
        assert _same(arrays, _small()) and got == meta, f"byte {i}: corrupted data was accepted"
    assert refused > len(data) // 2


def test_checksum_catches_consistent_rewrite(tmp_path):
    """spec/optim.md §5.2: data changed with valid zip CRCs (a re-written member) fails the checksum."""
    path = tmp_path / "r.npz"
    save_checkpoint(path, _arrays(), {})
    with np.load(path, allow_pickle=False) as z:
        members = {k: z[k] for k in z.files}
    members["fc.bias"] = members["fc.bias"] + 1.0
    np.savez(tmp_path / "forged.npz", **members)
    with pytest.raises(ValueError, match="checksum"):
        load_checkpoint(tmp_path / "forged.npz")
    members.pop("__checksum__")
    np.savez(tmp_path / "nosum.npz", **members)
    with pytest.raises(ValueError, match="not a refimpl checkpoint"):
        load_checkpoint(tmp_path / "nosum.npz")


def test_object_arrays_and_bad_inputs_refused(tmp_path):
    """spec/optim.md §5.1-§5.2: object/string arrays cannot be saved; a pickled member is refused on load;
    reserved names and non-JSON metadata raise ValueError and write nothing."""
    path = tmp_path / "o.npz"
    for arrays, meta, msg in [({"x": np.array([1, "a"], dtype=object)}, {}, "pickle"),
                              ({"x": np.array(["ab"])}, {}, "pickle"),
                              ({"__meta__": np.zeros(2)}, {}, "reserved"),
                              ({"x": [1.0, 2.0]}, {}, "numpy array"),
                              ({"x": np.zeros(2)}, {"bad": float("nan")}, "meta"),
                              ({"x": np.zeros(2)}, {"bad": object()}, "meta")]:
        with pytest.raises(ValueError, match=msg):
            save_checkpoint(path, arrays, meta)
        assert not path.exists() and os.listdir(tmp_path) == []
    np.savez(tmp_path / "pickled.npz", x=np.array([{"a": 1}], dtype=object))  # pickled by NumPy, never loaded
    with pytest.raises(ValueError):
        load_state_dict_npz(tmp_path / "pickled.npz")
    with zipfile.ZipFile(tmp_path / "foreign.npz", "w") as zf:  # a zip whose member is not a .npy file
        zf.writestr("readme.txt", "hello")
    with pytest.raises(ValueError, match="not a .npy array"):
        load_state_dict_npz(tmp_path / "foreign.npz")
    (tmp_path / "junk.npz").write_bytes(b"not a zip file at all")
    with pytest.raises(ValueError):
        load_checkpoint(tmp_path / "junk.npz")
    with pytest.raises(FileNotFoundError):
        load_checkpoint(tmp_path / "missing.npz")


@pytest.mark.parametrize("where", ["write", "replace"])
def test_atomic_write_on_failure(tmp_path, monkeypatch, where):
    """spec/optim.md §5.3: a failure while writing (or at the rename) leaves the previous checkpoint intact and
    no temporary file behind."""
    path = tmp_path / "a.npz"
    save_checkpoint(path, {"x": np.ones(3)}, {"v": 1})
    before = path.read_bytes()
    calls = []

    def failing_write_array(fp, array, *args, **kwargs):
        calls.append(1)
        if len(calls) > 1:
            fp.write(b"partial")
            raise OSError("disk full (simulated)")
        return original_write(fp, array, *args, **kwargs)

    def failing_replace(src, dst):
        raise OSError("rename failed (simulated)")

    original_write = np.lib.format.write_array
    if where == "write":
        monkeypatch.setattr(np.lib.format, "write_array", failing_write_array)
    else:
        monkeypatch.setattr(ckpt.os, "replace", failing_replace)
    with pytest.raises(OSError, match="simulated"):
        save_checkpoint(path, {"x": np.zeros(3), "y": np.zeros(2)}, {"v": 2})
    assert path.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["a.npz"]
    monkeypatch.undo()
    assert load_checkpoint(path)[1] == {"v": 1}


def test_load_state_dict_npz(tmp_path):
    """spec/optim.md §5.4: a converted PyTorch state dict (np.savez of name -> array) loads unchanged; a refimpl
    checkpoint loads without its metadata; a damaged file raises ValueError."""
    sd = {"rnn.weight_ih_l0": np.ones((3, 2), np.float32), "h0": np.zeros((2, 1, 4))}
    np.savez(tmp_path / "sd.npz", **sd)
    assert _same(load_state_dict_npz(tmp_path / "sd.npz"), sd)
    save_checkpoint(tmp_path / "ck.npz", sd, {"epoch": 3})
    assert _same(load_state_dict_npz(tmp_path / "ck.npz"), sd)
    data = (tmp_path / "sd.npz").read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError):
        load_state_dict_npz(tmp_path / "cut.npz")


def test_check_params():
    """spec/optim.md §5.4: missing, unexpected, mis-shaped, non-float and non-finite entries are all named."""
    expected = {"fc.weight": (3, 4), "fc.bias": (3,), "h0": (2, 1, 5)}
    good = {k: np.zeros(s) for k, s in expected.items()}
    check_params(good, expected)
    bad = {"fc.weight": np.zeros((4, 3)), "fc.bias": np.array([0.0, np.nan, 1.0]), "extra": np.zeros(1)}
    with pytest.raises(ValueError) as e:
        check_params(bad, expected)
    msg = str(e.value)
    for part in ("missing keys ['h0']", "unexpected keys ['extra']", "'fc.weight': expected shape (3, 4), got (4, 3)",
                 "'fc.bias': contains NaN"):
        assert part in msg
    with pytest.raises(ValueError, match="floating"):
        check_params({"fc.bias": np.zeros(3, dtype=np.int64)}, {"fc.bias": (3,)})


@pytest.mark.parametrize("bit_generator", ["PCG64", "PCG64DXSM", "MT19937", "Philox", "SFC64"])
def test_rng_state_resumes_bit_for_bit(tmp_path, bit_generator):
    """spec/optim.md §5.5: a Generator's state stored as JSON in the metadata resumes the identical stream."""
    rng = np.random.Generator(getattr(np.random, bit_generator)(1234))
    rng.random(5)
    rng.standard_normal(3)
    save_checkpoint(tmp_path / "r.npz", {"x": np.zeros(1)}, {"rng": rng_state_to_json(rng)})
    resumed = rng_from_json(load_checkpoint(tmp_path / "r.npz")[1]["rng"])
    assert np.array_equal(rng.random(10), resumed.random(10))
    assert np.array_equal(rng.integers(0, 1000, 10), resumed.integers(0, 1000, 10))
    assert np.array_equal(rng.standard_normal(7), resumed.standard_normal(7))


def test_rng_json_validation():
    """spec/optim.md §5.5: malformed text or unknown bit generators raise ValueError."""
    with pytest.raises(ValueError):
        rng_from_json("{not json")
    with pytest.raises(ValueError, match="unknown bit generator"):
        rng_from_json(json.dumps({"bit_generator": "Evil", "state": {}}))
    with pytest.raises(ValueError):
        rng_from_json(json.dumps({"bit_generator": "PCG64", "state": {"state": "x"}}))
    with pytest.raises(ValueError, match="rng"):
        rng_state_to_json(np.random.RandomState(0))


def test_zip_member_names_are_plain(tmp_path):
    """spec/optim.md §5.1: one stored (uncompressed) '<name>.npy' member per array, nothing else."""
    save_checkpoint(tmp_path / "z.npz", {"a.b": np.zeros(2)}, {})
    with zipfile.ZipFile(tmp_path / "z.npz") as zf:
        assert sorted(zf.namelist()) == ["__checksum__.npy", "__meta__.npy", "a.b.npy"]
        assert all(i.compress_type == zipfile.ZIP_STORED for i in zf.infolist())


def test_reader_matches_numpy_on_every_layout(tmp_path):
    """spec/optim.md §5.4: the bounded reader returns what np.load returns (values, dtype, shape, C/Fortran order)
    for plain, compressed, Fortran-ordered, big-endian, 0-d, empty, complex and .npy-version-2.0 members."""
    rng = np.random.default_rng(1)
    sd = {"w": rng.standard_normal((3, 4)), "f32": rng.standard_normal(5).astype(np.float32),
          "fortran": np.asfortranarray(rng.standard_normal((2, 3))), "big": np.arange(4, dtype=">f8"),
          "scalar": np.array(2.5), "empty": np.zeros((0, 3)), "c": np.array([1 + 2j]), "b": np.array([True]),
          "u8": np.arange(3, dtype=np.uint8), "big_block": np.zeros((300, 400))}
    np.savez(tmp_path / "plain.npz", **sd)
    np.savez_compressed(tmp_path / "packed.npz", **sd)
    for name in ("plain.npz", "packed.npz"):
        got = load_state_dict_npz(tmp_path / name)
        with np.load(tmp_path / name, allow_pickle=False) as z:
            ref = {k: z[k] for k in z.files}
        assert _same(got, ref) and _same(got, sd)
        assert got["fortran"].flags.f_contiguous and got["w"].flags.writeable
    import io
    buf = io.BytesIO()  # a version-2.0 header (written by NumPy for very long headers)
    np.lib.format.write_array_header_2_0(buf, np.lib.format.header_data_from_array_1_0(sd["w"]))
    with zipfile.ZipFile(tmp_path / "v2.npz", "w") as zf:
        zf.writestr("w.npy", buf.getvalue() + sd["w"].tobytes())
    assert _same(load_state_dict_npz(tmp_path / "v2.npz"), {"w": sd["w"]})


def _zip_members(path, members, compress=False):
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED) as zf:
        for name, data in members.items():
            zf.writestr(name, data)


def _npy(header, payload):
    h = (header if isinstance(header, str) else repr(header)).encode("latin-1")
    h += b" " * (64 - (10 + len(h) + 1) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(h).to_bytes(2, "little") + h + payload


@pytest.mark.parametrize("case", ["shape-larger", "shape-smaller", "negative", "unicode", "object", "structured",
                                  "not-npy", "duplicate", "unterminated", "version-3", "bomb"])
def test_hostile_members_are_refused_before_allocation(tmp_path, case):
    """spec/optim.md §5.4, spec/robustness.md §1 (bug B4): a header whose shape does not match the member's data,
    a dtype other than bool/int/float/complex, a member that is not .npy, duplicates, a cut-off header, an
    unsupported .npy version and content declared above 32 × the file size + 8 MiB are all ValueError naming
    the file; nothing is allocated from a declared size."""
    import tracemalloc

    f8 = {"descr": "<f8", "fortran_order": False}
    members = {
        "shape-larger": {"w.npy": _npy(dict(f8, shape=(10**15,)), b"\0" * 64)},
        "shape-smaller": {"w.npy": _npy(dict(f8, shape=(2,)), b"\0" * 64)},
        "negative": {"w.npy": _npy(dict(f8, shape=(-8,)), b"\0" * 64)},
        "unicode": {"w.npy": _npy({"descr": "<U2", "fortran_order": False, "shape": (1,)}, b"\0" * 8)},
        "object": {"w.npy": _npy({"descr": "|O", "fortran_order": False, "shape": (1,)}, b"\x80\x04N.")},
        "structured": {"w.npy": _npy({"descr": [("a", "<f8")], "fortran_order": False, "shape": (1,)}, b"\0" * 8)},
        "not-npy": {"w.txt": b"hello"},
        "duplicate": {"w.npy": _npy(dict(f8, shape=(1,)), b"\0" * 8)},
        "unterminated": {"w.npy": _npy("{'descr': '<f8', 'fortran_order': False, 'shape': (3,", b"\0" * 24)},
        "version-3": {"w.npy": b"\x93NUMPY\x03\x00" + _npy(dict(f8, shape=(1,)), b"\0" * 8)[8:]},
        "bomb": {"w.npy": _npy(dict(f8, shape=(2 * 2**20,)), b"\0" * (16 * 2**20))},
    }[case]
    path = tmp_path / f"{case}.npz"
    if case == "duplicate":
        with zipfile.ZipFile(path, "w") as zf:
            zf.writestr("w.npy", members["w.npy"])
            with pytest.warns(UserWarning):
                zf.writestr("w.npy", members["w.npy"])
    else:
        _zip_members(path, members, compress=case == "bomb")
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match=case + ".npz") as info:
            load_state_dict_npz(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 4 * 2**20, peak
    why = {"shape-larger": "declares shape", "shape-smaller": "declares shape", "negative": "negative",
           "unicode": "dtype", "object": "dtype", "structured": "dtype", "not-npy": "not a .npy",
           "duplicate": "twice", "unterminated": "TokenError", "version-3": "version", "bomb": "zip bomb"}[case]
    assert why in str(info.value), str(info.value)


def test_encrypted_flag_and_metadata_rules(tmp_path):
    """spec/optim.md §5.1 (bug B4): encrypted members, and re-signed metadata with NaN, Infinity, 1e999 or 100000
    nested brackets are refused with ValueError (the format's metadata is finite JSON)."""
    path = tmp_path / "e.npz"
    save_checkpoint(path, _small(), {"a": 1})
    data = bytearray(path.read_bytes())
    for sig, at in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):
        i = data.find(sig)
        while i >= 0:
            data[i + at] |= 1
            i = data.find(sig, i + 4)
    (tmp_path / "enc.npz").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="encrypted"):
        load_checkpoint(tmp_path / "enc.npz")
    for text in (b'{"loss": NaN}', b'{"loss": Infinity}', b'{"loss": -Infinity}', b'{"loss": 1e999}',
                 b"[" * 100000 + b"]" * 100000):
        arrays = dict(_small())
        arrays["__meta__"] = np.frombuffer(text, dtype=np.uint8).copy()
        arrays["__checksum__"] = np.frombuffer(ckpt._checksum(arrays), dtype=np.uint8).copy()
        ckpt._write_npz_atomic(str(tmp_path / "m.npz"), arrays)
        with pytest.raises(ValueError, match="metadata"):
            load_checkpoint(tmp_path / "m.npz")
    assert load_checkpoint(path)[1] == {"a": 1}


def test_compressed_zero_tensors_within_the_bound(tmp_path):
    """spec/optim.md §5.4: np.savez_compressed of a state dict with large all-zero tensors (compressing ~1000:1)
    still loads while the total stays under 32 × the file size + 8 MiB."""
    sd = {"w": np.random.default_rng(0).standard_normal((200, 50)), "m": np.zeros((1000, 500))}  # 4 MB of zeros
    np.savez_compressed(tmp_path / "z.npz", **sd)
    assert (tmp_path / "z.npz").stat().st_size < 200_000
    assert _same(load_state_dict_npz(tmp_path / "z.npz"), sd)
