"""Fuzzing the readers of untrusted files (spec/robustness.md §1).

The mutators and the case runner are those of ``tests/fuzz/readers.py`` (the ≥ 10,000-case campaign);
here hypothesis drives them for a few hundred cases, plus targeted tests of the cases the brief names
(deep nesting, huge declared counts, encodings, line endings, empty files) and of the known bugs.

Contract (spec/robustness.md §1): only ``ValueError`` (or ``OSError``) escapes a reader; memory is bounded by
the file size; nothing hangs; a malformed file is never accepted where the right answer is known, and a
neutral edit (CRLF, whitespace) never changes the result.

Known bugs in other modules are listed in ``KNOWN_FAILURES`` and each has a ``xfail(strict=True)`` test
below, so the hypothesis tests stay green while the bug exists and the xfail test turns red (XPASS) when it
is fixed (then remove both the marker and the ``KNOWN_FAILURES`` entry).
"""
from __future__ import annotations

import functools
import json
import os
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.fuzz import readers as F

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "refimpl" / "data" / "sample"



# (reader, exception type or failure name) -> reason; each entry has a strict xfail test in this file.
# None open: the checkpoint bugs B4 (a)-(f) and the ONNX truncated-metadata bug B5 of spec/robustness.md §7
# were fixed; their tests below now guard the fixes.
KNOWN_FAILURES: dict[tuple[str, str], str] = {}
# sub-kinds (strings chosen by the mutators) whose semantic failures are known bugs
KNOWN_SUBKINDS: dict[tuple[str, str], str] = {}


class HypothesisDrawer:
    """The drawer interface of tests/fuzz/readers.py on top of hypothesis' ``st.data()``."""

    def __init__(self, data):
        self.data = data
        self.chosen: list[str] = []

    def integer(self, lo, hi):
        return self.data.draw(st.integers(lo, hi))

    def choice(self, seq):
        v = self.data.draw(st.sampled_from(list(seq)))
        if isinstance(v, str):
            self.chosen.append(v)
        return v

    def binary(self, max_size):
        return self.data.draw(st.binary(max_size=max_size))

    def boolean(self):
        return self.data.draw(st.booleans())


@functools.lru_cache(maxsize=None)
def _targets():
    targets, skipped = F.build_targets(include_whole=False)
    return {t.name: t for t in targets}, skipped


@functools.lru_cache(maxsize=None)
def _reference(name: str, seed_name: str, tmpdir: str):
    t = _targets()[0][name]
    data = dict(t.seeds)[seed_name]
    path = Path(tmpdir) / f"input{t.suffix}"
    path.write_bytes(data)
    return t.call(str(path))


def _target(name):
    targets, skipped = _targets()
    if name not in targets:
        pytest.skip(f"reader {name} not available: {skipped.get(name)}")
    return targets[name]


@pytest.fixture(scope="module")
def fuzz_dir(tmp_path_factory) -> Path:
    """One directory per module for the fuzz cases (each case overwrites the same file)."""
    return tmp_path_factory.mktemp("fuzz")


def _fuzz_one(name, data, tmpdir: Path, exclude=(), check_memory=False):
    t = _target(name)
    d = HypothesisDrawer(data)
    seed_name, seed = d.choice(t.seeds)
    mutators = sorted(k for k in t.mutators if k not in exclude)
    mname = d.choice(mutators)
    payload, expectation = F.mutate(t, seed, mname, d)
    ref = (_reference(name, seed_name, str(tmpdir)) if expectation in ("same", "reject_or_same", "same_positions")
           else None)
    if check_memory and not tracemalloc.is_tracing():
        tracemalloc.start()
    try:
        out = F.run_case(t, payload, expectation, tmpdir / f"input{t.suffix}", ref, timeout=20.0,
                         check_memory=check_memory)
    finally:
        if check_memory:
            tracemalloc.stop()
    if out.failure is None:
        return
    if (name, out.failure) in KNOWN_FAILURES:
        return
    if any((name, c) in KNOWN_SUBKINDS for c in d.chosen):
        return
    raise AssertionError(f"{name}: mutator {mname!r} on seed {seed_name!r} (choices {d.chosen}): "
                         f"{out.failure}: {out.detail}\ninput ({len(payload)} bytes) starts {payload[:200]!r}")


_FUZZ_SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                                            HealthCheck.filter_too_much])


@settings(max_examples=150, **_FUZZ_SETTINGS)
@given(data=st.data())
def test_fuzz_bvh(fuzz_dir, data):
    """spec/robustness.md §1: read_bvh on mutated BVH files (truncations, bad numbers, counts, encodings, ...)."""
    _fuzz_one("bvh", data, fuzz_dir, exclude=("deep", "wide"))


@settings(max_examples=60, **_FUZZ_SETTINGS)
@given(data=st.data())
def test_fuzz_expmap_cmu(fuzz_dir, data):
    """spec/robustness.md §1: read_expmap(layout="cmu") on mutated exp-map files."""
    _fuzz_one("expmap-cmu", data, fuzz_dir)


@settings(max_examples=40, **_FUZZ_SETTINGS)
@given(data=st.data())
def test_fuzz_expmap_h36m(fuzz_dir, data):
    """spec/robustness.md §1: read_expmap(layout="h36m") on mutated exp-map files."""
    _fuzz_one("expmap-h36m", data, fuzz_dir)


@settings(max_examples=80, **_FUZZ_SETTINGS)
@given(data=st.data())
def test_fuzz_checkpoint(fuzz_dir, data):
    """spec/robustness.md §1: load_checkpoint on damaged, crafted and re-signed .npz files."""
    _fuzz_one("checkpoint", data, fuzz_dir)


@settings(max_examples=50, **_FUZZ_SETTINGS)
@given(data=st.data())
def test_fuzz_onnx(fuzz_dir, data):
    """spec/robustness.md §1, §6: deploy.runtime.load_model on damaged models and hostile metadata."""
    _fuzz_one("onnx", data, fuzz_dir)


# ------------------------------------------------------------------------------------------------------------
# targeted cases: text readers
# ------------------------------------------------------------------------------------------------------------

def _write(tmp_path, name, data: bytes) -> str:
    p = tmp_path / name
    p.write_bytes(data)
    return str(p)


def test_sample_files_parse():
    """spec/robustness.md §1: every embedded sample file is accepted (the seeds are valid)."""
    from refimpl.bvh import read_bvh
    from refimpl.expmap import read_expmap

    for p in sorted(SAMPLE.rglob("*.bvh"))[:2]:
        m = read_bvh(p)
        assert m.num_frames > 0 and np.all(np.isfinite(m.rotations))
    for p in sorted(SAMPLE.rglob("*.txt"))[:2]:
        m = read_expmap(p, layout="cmu")
        assert m.num_frames > 0


@pytest.mark.parametrize("depth", [500, 998])
def test_bvh_deep_nesting_no_recursion_error(tmp_path, depth):
    """spec/robustness.md §1: nesting up to MAX_DEPTH = 1000 levels parses without RecursionError."""
    from refimpl.bvh import read_bvh

    m = read_bvh(_write(tmp_path, "deep.bvh", F.deep_bvh(depth)))
    assert m.num_joints == depth + 2  # root + joints + End Site
    assert m.num_frames == 1


def test_bvh_deeper_than_the_limit_is_valueerror(tmp_path):
    """spec/robustness.md §1: 3000 nested JOINT blocks exceed MAX_DEPTH: ValueError naming the limit."""
    from refimpl.bvh import read_bvh

    with pytest.raises(ValueError, match="MAX_DEPTH = 1000"):
        read_bvh(_write(tmp_path, "deep.bvh", F.deep_bvh(3000)))


def test_bvh_deep_unclosed_is_valueerror(tmp_path):
    """spec/robustness.md §1: 5000 unclosed blocks: ValueError (truncated hierarchy), no RecursionError."""
    from refimpl.bvh import read_bvh

    with pytest.raises(ValueError):
        read_bvh(_write(tmp_path, "deep.bvh", F.deep_unclosed_bvh(5000)))


@pytest.mark.parametrize("frames", ["999999999999", "18446744073709551617", "100000000"])
def test_bvh_huge_declared_frames_bounded_memory(tmp_path, frames):
    """spec/robustness.md §1: ``Frames: 999999999999`` with one frame of data: ValueError, and the reader never
    allocates from the declared count (tracemalloc peak below 16 MB for a file of < 1 kB)."""
    from refimpl.bvh import read_bvh

    text = F.synthetic_bvh(1, 2).replace(b"Frames: 1", b"Frames: " + frames.encode())
    path = _write(tmp_path, "huge.bvh", text)
    tracemalloc.start()
    try:
        with pytest.raises(ValueError, match="Frames"):
            read_bvh(path)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 16 * 2**20, peak


@pytest.mark.parametrize("reader", ["bvh", "expmap"])
@pytest.mark.parametrize("content", [b"", b"   \n\t\n", b"\r\n\r\n", b"\x00" * 16, b"\xef\xbb\xbf"])
def test_empty_files_are_valueerror(tmp_path, reader, content):
    """spec/robustness.md §1: empty or whitespace-only files raise ValueError naming the file."""
    path = _write(tmp_path, "empty.txt", content)
    with pytest.raises(ValueError, match="empty"):
        _read(reader, path)


def _read(reader, path):
    from refimpl.bvh import read_bvh
    from refimpl.expmap import read_expmap

    return read_bvh(path) if reader == "bvh" else read_expmap(path, layout="cmu")


def _seed_bytes(reader):
    if reader == "bvh":
        return F._cut_bvh((SAMPLE / "bvh" / "02_01.bvh").read_bytes(), 4)
    return F._expmap_rows((SAMPLE / "expmap" / "test" / "walking" / "walking_1.txt").read_bytes(), 4)


@pytest.mark.parametrize("reader", ["bvh", "expmap"])
@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-32"])
def test_wide_encodings_are_valueerror(tmp_path, reader, encoding):
    """spec/robustness.md §1: UTF-16/32 files are refused with ValueError naming the file."""
    path = _write(tmp_path, "wide.txt", _seed_bytes(reader).decode("ascii").encode(encoding))
    with pytest.raises(ValueError, match="wide.txt"):
        _read(reader, path)


@pytest.mark.parametrize("reader", ["bvh", "expmap"])
@pytest.mark.parametrize("where", [0, 10, -3])
def test_nul_and_binary_bytes_are_valueerror(tmp_path, reader, where):
    """spec/robustness.md §1: NUL bytes or invalid UTF-8 inside a file give ValueError (never a crash)."""
    data = _seed_bytes(reader)
    for junk in (b"\x00", b"\xff\xfe", b"\x80"):
        path = _write(tmp_path, "junk.txt", data[:where] + junk + data[where:])
        with pytest.raises(ValueError):
            _read(reader, path)


@pytest.mark.parametrize("reader", ["bvh", "expmap"])
@pytest.mark.parametrize("ending", ["crlf", "cr", "mixed"])
def test_line_endings_do_not_matter(tmp_path, reader, ending):
    """spec/robustness.md §1: CRLF, CR-only and mixed line endings give exactly the LF result."""
    data = _seed_bytes(reader)
    lines = data.splitlines()
    if ending == "crlf":
        other = b"\r\n".join(lines) + b"\r\n"
    elif ending == "cr":
        other = b"\r".join(lines) + b"\r"
    else:
        other = b"".join(ln + (b"\r\n" if i % 2 else b"\n") for i, ln in enumerate(lines))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    ref = _read(reader, _write(tmp_path / "a", "m.txt", data))
    got = _read(reader, _write(tmp_path / "b", "m.txt", other))
    assert F.same_result(got, ref)


@pytest.mark.parametrize("token", ["nan", "inf", "-inf", "1e999", "-", "1.2.3", "NaN", "+", "0x10"])
@pytest.mark.parametrize("reader", ["bvh", "expmap"])
def test_bad_numbers_in_data_are_valueerror_with_line(tmp_path, reader, token):
    """spec/robustness.md §1: a non-finite or non-numeric value in the data: ValueError '<file>:<line>: ...'."""
    data = _seed_bytes(reader)
    lines = data.splitlines(keepends=True)
    k = len(lines) - 2  # a data line
    sep = b" " if reader == "bvh" else b","
    toks = lines[k].rstrip(b"\r\n").split(sep)
    toks[3] = token.encode()
    lines[k] = sep.join(toks) + b"\n"
    path = _write(tmp_path, "bad.txt", b"".join(lines))
    with pytest.raises(ValueError, match=rf"bad\.txt:{k + 1}:"):
        _read(reader, path)


@pytest.mark.parametrize("reader", ["bvh", "expmap"])
def test_missing_path_and_directory(tmp_path, reader):
    """spec/robustness.md §1: a missing file or a directory raises ValueError or OSError (nothing else)."""
    for path in (str(tmp_path / "does_not_exist.txt"), str(tmp_path)):
        with pytest.raises((ValueError, OSError)):
            _read(reader, path)


def test_bvh_truncation_at_every_line(tmp_path):
    """spec/robustness.md §1: a BVH cut after any complete line (before its last value) is refused."""
    from refimpl.bvh import read_bvh

    data = F.synthetic_bvh(2, 2)
    lines = data.splitlines(keepends=True)
    for k in range(len(lines)):
        path = _write(tmp_path, "cut.bvh", b"".join(lines[:k]))
        with pytest.raises(ValueError):
            read_bvh(path)


# ------------------------------------------------------------------------------------------------------------
# targeted cases: checkpoints
# ------------------------------------------------------------------------------------------------------------

def _ckpt(tmp_path):
    from refimpl.checkpoint import save_checkpoint

    p = tmp_path / "c.npz"
    save_checkpoint(p, {"w": np.arange(6.0).reshape(2, 3), "b": np.zeros(3, np.float32)}, {"step": 3})
    return p


def test_checkpoint_truncations_and_flips(tmp_path):
    """spec/robustness.md §1, §5: every truncation and a sweep of single-byte flips of a checkpoint are refused
    with ValueError (zip structure, CRC or SHA-256 checksum)."""
    from refimpl.checkpoint import load_checkpoint

    data = _ckpt(tmp_path).read_bytes()
    bad = tmp_path / "bad.npz"
    for cut in list(range(0, len(data), max(1, len(data) // 97))) + [len(data) - 1]:
        bad.write_bytes(data[:cut])
        with pytest.raises(ValueError):
            load_checkpoint(bad)
    for i in range(0, len(data), 7):
        b = bytearray(data)
        b[i] ^= 0x10
        bad.write_bytes(bytes(b))
        try:
            arrays, meta = load_checkpoint(bad)
        except ValueError:
            continue
        # a flip in bytes that carry no content (zip timestamps and version fields, .npy header padding)
        # may load: then the content must be intact
        assert np.array_equal(arrays["w"], np.arange(6.0).reshape(2, 3)) and meta == {"step": 3}


def test_checkpoint_object_array_is_refused(tmp_path):
    """spec/robustness.md §4: an object (pickled) member is refused without unpickling."""
    from refimpl.checkpoint import load_checkpoint

    members = F._unzip(_ckpt(tmp_path).read_bytes())
    members["w.npy"] = F._npy_bytes({"descr": "|O", "fortran_order": False, "shape": (1,)}, b"\x80\x04N.")
    p = tmp_path / "o.npz"
    p.write_bytes(F._zip(members))
    with pytest.raises(ValueError):
        load_checkpoint(p)


def _resigned(tmp_path, kind):
    class Pick(F.RandomDrawer):
        def __init__(self):
            import random

            super().__init__(random.Random(0))

        def choice(self, seq):
            return kind if kind in seq else seq[0]

    data, _ = F.m_npz_resigned(_ckpt(tmp_path).read_bytes(), Pick())
    p = tmp_path / f"{kind}.npz"
    p.write_bytes(data)
    return p


def test_checkpoint_resigned_hostile_metadata_is_plain_data(tmp_path):
    """spec/robustness.md §4, §6: metadata is JSON data: a code-looking string is returned verbatim, unexecuted."""
    from refimpl.checkpoint import load_checkpoint

    _, meta = load_checkpoint(_resigned(tmp_path, "meta-code"))
    assert meta == {"cmd": "__import__('os').system('echo pwned')"}


@pytest.mark.parametrize("kind", ["meta-list", "meta-string", "meta-bad-utf8", "checksum-float", "no-meta",
                                  "meta-float-dtype"])
def test_checkpoint_resigned_malformed_is_valueerror(tmp_path, kind):
    """spec/robustness.md §1: well-checksummed but malformed checkpoints are refused with ValueError."""
    from refimpl.checkpoint import load_checkpoint

    with pytest.raises(ValueError):
        load_checkpoint(_resigned(tmp_path, kind))


@pytest.mark.parametrize("kind", ["deep-json-list", "deep-json-dict"])
def test_checkpoint_deeply_nested_metadata(tmp_path, kind):
    """spec/robustness.md §1: deeply nested JSON metadata (valid checksum) is refused with ValueError."""
    from refimpl.checkpoint import load_checkpoint

    with pytest.raises(ValueError):
        load_checkpoint(_resigned(tmp_path, kind))


def test_checkpoint_huge_declared_shape(tmp_path):
    """spec/robustness.md §1: a .npy header declaring far more data than the member holds: ValueError, and
    memory stays bounded (nothing allocated from the declared shape)."""
    from refimpl.checkpoint import load_checkpoint

    members = F._unzip(_ckpt(tmp_path).read_bytes())
    p = tmp_path / "h.npz"
    for shape in ((10**12,), (2 * 10**8,)):
        members["w.npy"] = F._npy_bytes({"descr": "<f8", "fortran_order": False, "shape": shape}, b"\0" * 64)
        p.write_bytes(F._zip(members))
        tracemalloc.start()
        try:
            with pytest.raises(ValueError):
                load_checkpoint(p)
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        assert peak < 64 * 2**20, f"peak {peak} bytes for a {p.stat().st_size}-byte file"


def test_checkpoint_corrupt_checksum_member(tmp_path):
    """spec/robustness.md §1: a damaged __checksum__ member is refused with ValueError."""
    from refimpl.checkpoint import load_checkpoint

    members = F._unzip(_ckpt(tmp_path).read_bytes())
    members["__checksum__.npy"] = b"\x93NUMPX" + members["__checksum__.npy"][6:]
    p = tmp_path / "c2.npz"
    p.write_bytes(F._zip(members))
    with pytest.raises(ValueError):
        load_checkpoint(p)


def test_checkpoint_unterminated_npy_header(tmp_path):
    """spec/robustness.md §1: a .npy member with a cut-off header dict is refused with ValueError."""
    from refimpl.checkpoint import load_checkpoint

    members = F._unzip(_ckpt(tmp_path).read_bytes())
    members["w.npy"] = F._npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (3,", b"\0" * 24)
    p = tmp_path / "t.npz"
    p.write_bytes(F._zip(members))
    with pytest.raises(ValueError):
        load_checkpoint(p)


def test_checkpoint_encrypted_flag(tmp_path):
    """spec/robustness.md §1: a zip member flagged as encrypted (one flipped bit) is refused with ValueError."""
    from refimpl.checkpoint import load_checkpoint

    b = bytearray(_ckpt(tmp_path).read_bytes())
    for sig, flag_at in ((b"PK\x03\x04", 6), (b"PK\x01\x02", 8)):  # local headers, central directory
        i = b.find(sig)
        while i >= 0:
            b[i + flag_at] |= 1
            i = b.find(sig, i + 4)
    p = tmp_path / "enc.npz"
    p.write_bytes(bytes(b))
    with pytest.raises(ValueError):
        load_checkpoint(p)


def test_checkpoint_non_npy_member_is_refused(tmp_path):
    """spec/robustness.md §1: every returned value is an ndarray; anything else in the archive is refused."""
    from refimpl.checkpoint import load_checkpoint

    with pytest.raises(ValueError):
        load_checkpoint(_resigned(tmp_path, "raw-member"))


def test_checkpoint_nan_in_metadata_is_refused(tmp_path):
    """spec/robustness.md §1: metadata with NaN (not valid JSON, refused on save) is refused on load."""
    from refimpl.checkpoint import load_checkpoint

    with pytest.raises(ValueError):
        load_checkpoint(_resigned(tmp_path, "meta-nan"))


def test_checkpoint_zip_bomb_memory(tmp_path):
    """spec/robustness.md §1: memory stays bounded by a multiple of the file size (compressed members)."""
    from refimpl.checkpoint import load_checkpoint

    members = F._unzip(_ckpt(tmp_path).read_bytes())
    members["w.npy"] = F._npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (5 * 2**20,)},
                                    b"\0" * (40 * 2**20))
    p = tmp_path / "bomb.npz"
    p.write_bytes(F._zip(members, compress=True))
    size = p.stat().st_size
    tracemalloc.start()
    try:
        try:
            load_checkpoint(p)
        except ValueError:
            pass
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak <= 16 * 2**20 + 64 * size, f"peak {peak} bytes for a {size}-byte file"


# ------------------------------------------------------------------------------------------------------------
# targeted cases: ONNX models (deploy.runtime)
# ------------------------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def _onnx_seed():
    pytest.importorskip("onnxruntime")
    return dict(F.onnx_seeds())["identity+meta"]


def _onnx_with_meta(tmp_path, key, value, name="m.onnx"):
    import onnx

    model = onnx.load_from_string(_onnx_seed())
    for e in model.metadata_props:
        if e.key == key:
            e.value = value
            break
    else:
        model.metadata_props.add(key=key, value=value)
    p = tmp_path / name
    p.write_bytes(model.SerializeToString())
    return p


@pytest.mark.parametrize("payload", [
    "__import__('pathlib').Path({sentinel!r}).touch()",
    "exec(\"open({sentinel!r}, 'w').close()\")",
    "{{7*7}}", "${{jndi:ldap://x}}", "'; DROP TABLE x; --",
])
def test_onnx_metadata_strings_are_plain_text(tmp_path, payload):
    """spec/robustness.md §6: metadata values are JSON data: code-looking strings come back verbatim as str and
    are never executed (a sentinel file they would create stays absent)."""
    from deploy.runtime import load_model

    sentinel = str(tmp_path / "pwned")
    text = payload.format(sentinel=sentinel)
    p = _onnx_with_meta(tmp_path, "source_paper", json.dumps(text))
    p2 = _onnx_with_meta(tmp_path, "x-extra", json.dumps({"cmd": text}), name="m2.onnx")
    m = load_model(p)
    assert m.metadata["source_paper"] == text
    assert load_model(p2).metadata["x-extra"] == {"cmd": text}
    assert not os.path.exists(sentinel)


def test_onnx_metadata_not_json_is_valueerror(tmp_path):
    """spec/robustness.md §6: a metadata value that is not JSON (e.g. bare code) is refused, naming the key."""
    from deploy.runtime import load_model

    p = _onnx_with_meta(tmp_path, "source_paper", "__import__('os').system('x')")
    with pytest.raises(ValueError, match="source_paper"):
        load_model(p)


@pytest.mark.parametrize("cut", [0, 1, 17, -1])
def test_onnx_truncated_or_empty_is_valueerror(tmp_path, cut):
    """spec/robustness.md §1, §6: truncated or empty model files are refused with ValueError."""
    from deploy.runtime import load_model

    data = _onnx_seed()
    p = tmp_path / "t.onnx"
    p.write_bytes(data[:cut] if cut >= 0 else data[:len(data) // 2])
    with pytest.raises(ValueError):
        load_model(p)


def test_onnx_model_is_checked_before_use(tmp_path):
    """spec/robustness.md §6: a model that fails onnx.checker is refused before a session is created."""
    import onnx

    from deploy.runtime import load_model

    model = onnx.load_from_string(_onnx_seed())
    model.graph.node[0].op_type = "NoSuchOp"
    p = tmp_path / "bad.onnx"
    p.write_bytes(model.SerializeToString())
    with pytest.raises(Exception) as info:
        load_model(p)
    assert "NoSuchOp" in str(info.value)


@pytest.mark.parametrize("kind", ["bad-op", "domain", "dangling"])
def test_onnx_checker_rejection_is_valueerror(tmp_path, kind):
    """spec/robustness.md §6: every refusal of a model file is a ValueError."""
    from deploy.runtime import load_model

    class Pick(F.RandomDrawer):
        def __init__(self):
            import random

            super().__init__(random.Random(0))

        def choice(self, seq):
            return kind if kind in seq else seq[0]

    data, _ = F.m_onnx_graph(_onnx_seed(), Pick())
    p = tmp_path / "g.onnx"
    p.write_bytes(data)
    with pytest.raises(ValueError):
        load_model(p)


def test_onnx_runtime_rejection_is_valueerror(tmp_path):
    """spec/robustness.md §6: an opset newer than onnxruntime supports is refused with ValueError."""
    import onnx

    from deploy.runtime import load_model

    model = onnx.load_from_string(_onnx_seed())
    model.opset_import[0].version = 999
    p = tmp_path / "o.onnx"
    p.write_bytes(model.SerializeToString())
    with pytest.raises(ValueError):
        load_model(p)


def test_onnx_deeply_nested_metadata(tmp_path):
    """spec/robustness.md §6: deeply nested JSON in metadata is refused with ValueError."""
    from deploy.runtime import load_model

    p = _onnx_with_meta(tmp_path, "normalization", "[" * 100000 + "]" * 100000)
    with pytest.raises(ValueError):
        load_model(p)


@pytest.mark.parametrize("value", ["[1, 2]", "42", "\"step\"", "NaN"])
def test_onnx_metadata_of_wrong_type(tmp_path, value):
    """spec/robustness.md §6: metadata of the wrong JSON type is refused (ValueError) or ignored, never a crash."""
    from deploy.runtime import load_model

    p = _onnx_with_meta(tmp_path, "model", value)
    try:
        m = load_model(p)
    except ValueError:
        return
    assert m.role is None


def test_onnx_truncated_metadata_is_refused(tmp_path):
    """spec/robustness.md §1, §6: a model file cut inside its metadata is refused (the metadata contract of
    deploy/metadata.py: format, model, io, ... must be present), not loaded with keys missing."""
    import onnx

    from deploy.runtime import load_model

    full = _onnx_seed()
    model = onnx.load_from_string(full)
    keep = list(model.metadata_props)[:3]  # exporter, format, frame_rate
    del model.metadata_props[:]
    for e in keep:
        model.metadata_props.add(key=e.key, value=e.value)
    prefix = model.SerializeToString()
    assert full.startswith(prefix)  # the truncated file is exactly this prefix of the real one
    p = tmp_path / "cut.onnx"
    p.write_bytes(prefix)
    with pytest.raises(ValueError):
        load_model(p)
