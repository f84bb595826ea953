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
