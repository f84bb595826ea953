"""refimpl.safetensors: round trips, agreement with the ``safetensors`` package (skipped when absent), and
hand-built malformed files, each refused with a ValueError naming the problem."""
import json
import struct

import numpy as np
import pytest

from refimpl.safetensors import MAX_HEADER_BYTES, is_safetensors, read_safetensors, write_safetensors


def _tensors():
    rng = np.random.default_rng(0)
    return {"rnn.weight_ih_l0": rng.standard_normal((6, 4)).astype(np.float32),
            "fc.bias": rng.standard_normal(3),
            "h0": rng.standard_normal((2, 1, 3)).astype(np.float16),
            "count": np.array(7, dtype=np.int64),
            "mask": np.array([True, False, True]),
            "empty": np.zeros((0, 5), np.float32),
            "u": np.arange(5, dtype=np.uint16)}


def _raw(header: dict | bytes, data: bytes = b"", length: int | None = None) -> bytes:
    raw = header if isinstance(header, bytes) else json.dumps(header).encode()
    return struct.pack("<Q", len(raw) if length is None else length) + raw + data


def test_round_trip_every_dtype(tmp_path):
    t = _tensors()
    write_safetensors(tmp_path / "a.safetensors", t, {"format": "pt"})
    got, meta = read_safetensors(tmp_path / "a.safetensors")
    assert meta == {"format": "pt"}
    assert set(got) == set(t)
    for k, v in t.items():
        assert got[k].dtype == v.dtype and got[k].shape == v.shape
        np.testing.assert_array_equal(got[k], v)
    assert is_safetensors(tmp_path / "a.safetensors")
    np.savez(tmp_path / "b.npz", x=np.ones(2))
    assert not is_safetensors(tmp_path / "b.npz")


def test_header_is_padded_to_8_bytes(tmp_path):
    write_safetensors(tmp_path / "a.safetensors", {"x": np.ones(3, np.float32)})
    raw = (tmp_path / "a.safetensors").read_bytes()
    n = struct.unpack("<Q", raw[:8])[0]
    assert n % 8 == 0 and len(raw) == 8 + n + 12


def test_agrees_with_the_safetensors_package(tmp_path):
    st = pytest.importorskip("safetensors.numpy")
    t = {k: v for k, v in _tensors().items()}
    st.save_file(t, str(tmp_path / "theirs.safetensors"), metadata={"k": "v"})
    got, meta = read_safetensors(tmp_path / "theirs.safetensors")
    assert meta == {"k": "v"}
    for k, v in t.items():
        np.testing.assert_array_equal(got[k], v)
        assert got[k].dtype == v.dtype
    write_safetensors(tmp_path / "ours.safetensors", t, {"k": "v"})
    back = st.load_file(str(tmp_path / "ours.safetensors"))
    for k, v in t.items():
        np.testing.assert_array_equal(back[k], v)
        assert back[k].dtype == v.dtype


def test_bf16_is_read_exactly_into_float32(tmp_path):
    x = np.array([1.0, -2.5, 3.140625, 0.0], np.float32)          # exactly representable in bfloat16
    bf16 = (x.view(np.uint32) >> 16).astype("<u2").tobytes()
    path = tmp_path / "b.safetensors"
    path.write_bytes(_raw({"x": {"dtype": "BF16", "shape": [4], "data_offsets": [0, 8]}}, bf16))
    got, _ = read_safetensors(path)
    assert got["x"].dtype == np.float32
    np.testing.assert_array_equal(got["x"], x)
    torch = pytest.importorskip("torch")
    st = pytest.importorskip("safetensors.torch")
    st.save_file({"y": torch.tensor([0.5, -7.0, 1e-3]).to(torch.bfloat16)}, str(tmp_path / "t.safetensors"))
    got, _ = read_safetensors(tmp_path / "t.safetensors")
    np.testing.assert_array_equal(got["y"], torch.tensor([0.5, -7.0, 1e-3]).to(torch.bfloat16).float().numpy())


F4 = {"dtype": "F32", "shape": [2], "data_offsets": [0, 8]}


@pytest.mark.parametrize("content, message", [
    (b"\x01\x00", "too short"),
    (_raw({"x": F4}, b"\0" * 8, length=10_000), "beyond the end"),
    (_raw(b"{}", length=MAX_HEADER_BYTES + 1), "beyond the limit"),
    (_raw(b"[1, 2]"), "does not start with"),
    (_raw(b"{\"x\": "), "malformed header"),
    (_raw(b"{\xff}"), "not UTF-8"),
    (_raw(b'{"x": {"dtype": "F32", "shape": [1], "data_offsets": [0, 4]}, '
          b'"x": {"dtype": "F32", "shape": [1], "data_offsets": [4, 8]}}', b"\0" * 8), "twice"),
    (_raw({"x": [1, 2]}), "exactly dtype"),
    (_raw({"x": {**F4, "extra": 1}}, b"\0" * 8), "exactly dtype"),
    (_raw({"x": {**F4, "dtype": "F8_E4M3"}}, b"\0" * 8), "unsupported dtype"),
    (_raw({"x": {**F4, "dtype": "float32"}}, b"\0" * 8), "unsupported dtype"),
    (_raw({"x": {**F4, "shape": [-2]}}, b"\0" * 8), "non-negative integers"),
    (_raw({"x": {**F4, "shape": [2.0]}}, b"\0" * 8), "non-negative integers"),
    (_raw({"x": {**F4, "data_offsets": [8, 0]}}, b"\0" * 8), "begin <= end"),
    (_raw({"x": {**F4, "data_offsets": [0]}}, b"\0" * 8), "begin <= end"),
    (_raw({"x": {**F4, "shape": [3]}}, b"\0" * 8), "needs 12 bytes"),
    (_raw({"x": F4, "y": {**F4, "data_offsets": [4, 12]}}, b"\0" * 12), "overlaps"),
    (_raw({"x": {**F4, "data_offsets": [4, 12]}}, b"\0" * 12), "hole"),
    (_raw({"x": F4}, b"\0" * 6), "truncated or trailing"),
    (_raw({"x": F4}, b"\0" * 9), "truncated or trailing"),
    (_raw({"x": F4, "__metadata__": {"a": 1}}, b"\0" * 8), "object of strings"),
])
def test_malformed_files_are_refused(tmp_path, content, message):
    path = tmp_path / "bad.safetensors"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=message) as info:
        read_safetensors(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_writer_refuses_what_it_cannot_store(tmp_path):
    for bad in ({"": np.ones(1)}, {"__metadata__": np.ones(1)}, {"c": np.ones(2, complex)},
                {"o": np.array(["a"], dtype=object)}):
        with pytest.raises(ValueError):
            write_safetensors(tmp_path / "w.safetensors", bad)
    with pytest.raises(ValueError, match="metadata"):
        write_safetensors(tmp_path / "w.safetensors", {"x": np.ones(1)}, {"a": 1})
    assert not (tmp_path / "w.safetensors").exists()
