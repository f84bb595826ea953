"""Fuzz campaign for the file readers (spec/robustness.md §1).

Feeds malformed inputs to every reader of untrusted files and checks the robustness contract:

* the only exceptions that escape are ``ValueError`` (and its subclasses) and ``OSError``;
* nothing hangs (a per-case wall-clock limit, ``--timeout``);
* memory stays bounded by the file size (``tracemalloc`` peak ≤ ``MEM_FIXED + MEM_PER_BYTE · size``), so a
  declared count such as ``Frames: 999999999999`` is never used to allocate;
* where the right answer is known, it is checked: a mutation that must make the file invalid (a non-finite or
  non-numeric number, a truncation that removes data) must raise ``ValueError`` (failure type
  ``AcceptedMalformed`` otherwise), and a change that must not matter (CRLF or mixed line endings, extra
  whitespace) must give the same result as the original (``ChangedByNeutralEdit``); a returned float array
  must be finite (``NonFiniteOutput``).

Readers (each skipped when its module does not exist yet):

==============  =================================================================================
``bvh``         ``refimpl.bvh.read_bvh(path)``
``expmap-cmu``  ``refimpl.expmap.read_expmap(path, layout="cmu")``
``expmap-h36m`` ``refimpl.expmap.read_expmap(path, layout="h36m")``
``checkpoint``  ``refimpl.checkpoint.load_checkpoint(path)``
``onnx``        ``deploy.runtime``'s model loader (metadata parsed as data)
==============  =================================================================================

Seeds are the embedded sample (``refimpl/data/sample``: the real files cut to a few frames, plus a few
whole files) and small synthetic valid files. Mutations: truncation, bad numbers (``nan``, ``inf``,
``1e999``, ``-``, ``1.2.3`` ...), wrong counts (``Frames:``, ``CHANNELS``), deleted/duplicated lines and
tokens, unbalanced braces, deep nesting (thousands of nested ``JOINT`` blocks), huge declared frame counts,
binary junk, other encodings (latin-1, UTF-16, UTF-32, NUL bytes), CRLF / CR / mixed line endings, empty
and whitespace-only files, very long tokens; for binary containers also bit flips, corrupted ``.npy``
headers, object arrays, zip bombs, deeply nested JSON.

The mutation functions take a *drawer* (``integer(lo, hi)``, ``choice(seq)``, ``binary(n)``, ``boolean()``),
so ``tests/test_fuzz_readers.py`` drives the very same mutators from hypothesis and this script drives them
from a seeded ``random.Random``.

Usage::

    python -m tests.fuzz.readers --cases 10000 [--seed 0] [--timeout 10] \
        [--readers bvh,expmap-cmu,expmap-h36m,checkpoint,onnx] [--out tests/fuzz/results/fuzz_readers.json]

Prints a table of cases per reader and outcomes per exception type, writes JSON, exits 1 on any failure
(an exception other than ValueError/OSError, a hang, a memory blow-up or a wrong answer).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import random
import re
import signal
import sys
import tempfile
import time
import tracemalloc
import zipfile
from dataclasses import dataclass, fields, is_dataclass
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["RandomDrawer", "Target", "Outcome", "build_targets", "mutate", "run_case", "same_result", "campaign",
           "synthetic_bvh", "deep_bvh", "deep_unclosed_bvh", "synthetic_expmap", "onnx_seeds", "checkpoint_seeds",
           "BVH_MUTATORS", "EXPMAP_MUTATORS", "CHECKPOINT_MUTATORS", "ONNX_MUTATORS", "main"]

ROOT = Path(__file__).resolve().parents[2]

from refimpl.atomic import atomic_write_text  # noqa: E402

SAMPLE = ROOT / "refimpl" / "data" / "sample"

#: memory bound per case: fixed allowance + allowance per byte of input file
MEM_FIXED = 48 * 2**20
MEM_PER_BYTE = 64

ALLOWED = (ValueError, OSError)

#: a file that must be refused (expectation "reject") and is smaller than 16 MB is refused within this time
#: (issue #18: pathological hierarchies fail fast); measured with the memory tracer on, which slows parsing
SLOW_REJECT_SECONDS = 2.0


# ------------------------------------------------------------------------------------------------------------
# drawers: where the random choices come from
# ------------------------------------------------------------------------------------------------------------

class RandomDrawer:
    """Drawer backed by ``random.Random`` (the campaign)."""

    def __init__(self, rng: random.Random):
        self.rng = rng
        self.chosen: list[str] = []  # string choices of the current case (mutation sub-kinds), for the report

    def integer(self, lo: int, hi: int) -> int:
        return self.rng.randint(lo, hi)

    def choice(self, seq):
        v = seq[self.rng.randrange(len(seq))]
        if isinstance(v, str):
            self.chosen.append(v)
        return v

    def binary(self, max_size: int) -> bytes:
        n = self.rng.randint(0, max_size)
        return bytes(self.rng.getrandbits(8) for _ in range(n))

    def boolean(self) -> bool:
        return self.rng.random() < 0.5


# ------------------------------------------------------------------------------------------------------------
# seeds
# ------------------------------------------------------------------------------------------------------------

_NUM_RE = re.compile(rb"(?<![^\s,:])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![^\s,])")


def _cut_bvh(data: bytes, frames: int) -> bytes:
    """The real file ``data`` with only its first ``frames`` frames (``Frames:`` rewritten)."""
    m = re.search(rb"MOTION\s*\r?\n\s*Frames:\s*(\d+)\s*\r?\n\s*Frame Time:[^\n]*\n", data)
    if m is None:
        raise RuntimeError("sample BVH without a MOTION section")
    head = data[:m.start(1)] + str(frames).encode() + data[m.end(1):m.end()]
    rest = data[m.end():].splitlines(keepends=True)
    return head + b"".join(rest[:frames])


def synthetic_bvh(frames: int = 2, depth: int = 2, channels_order: str = "Zrotation Yrotation Xrotation",
                  newline: str = "\n") -> bytes:
    """A small valid BVH: a 6-channel root, a chain of ``depth`` joints, one End Site, ``frames`` frames."""
    lines = ["HIERARCHY", "ROOT Hips", "{", "  OFFSET 0.0 0.0 0.0",
             f"  CHANNELS 6 Xposition Yposition Zposition {channels_order}"]
    for i in range(depth):
        lines += [f"JOINT J{i}", "{", f"OFFSET 0.0 {1.0 + i * 0.5:.3f} 0.1", f"CHANNELS 3 {channels_order}"]
    lines += ["End Site", "{", "OFFSET 0.0 1.0 0.0", "}"]
    lines += ["}"] * depth
    lines += ["}", "MOTION", f"Frames: {frames}", "Frame Time: 0.0333333"]
    rng = random.Random(frames * 131 + depth)
    n = 6 + 3 * depth
    for _ in range(frames):
        lines.append(" ".join(f"{rng.uniform(-40, 40):.4f}" for _ in range(n)))
    return (newline.join(lines) + newline).encode()


_ZYX = "Zrotation Yrotation Xrotation"
_ROOT_HEAD = f"HIERARCHY\nROOT R\n{{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition {_ZYX}\n"


def deep_bvh(depth: int, frames: int = 1) -> bytes:
    """A valid BVH with ``depth`` nested JOINT blocks (one channel-bearing joint per level)."""
    parts = [_ROOT_HEAD]
    parts.append("".join(f"JOINT J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 {_ZYX}\n" for i in range(depth)))
    parts.append("End Site\n{\nOFFSET 0 1 0\n}\n")
    parts.append("}\n" * (depth + 1))
    n = 6 + 3 * depth
    parts.append(f"MOTION\nFrames: {frames}\nFrame Time: 0.01\n")
    parts.append(("0 " * n).rstrip() + "\n" * 1)
    if frames > 1:
        parts.append((("0 " * n).rstrip() + "\n") * (frames - 1))
    return "".join(parts).encode()


def deep_unclosed_bvh(depth: int) -> bytes:
    """``depth`` nested ``{`` with nothing closed (malformed)."""
    return ("HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n"
            + "JOINT J\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n" * depth).encode()


def _expmap_rows(data: bytes, rows: int) -> bytes:
    return b"".join(data.splitlines(keepends=True)[:rows])


def synthetic_expmap(rows: int, width: int, seed: int = 0) -> bytes:
    rng = random.Random(seed)
    return "".join(",".join(f"{rng.uniform(-3, 3):.6f}" for _ in range(width)) + "\n"
                   for _ in range(rows)).encode()


def bvh_seeds(include_whole: bool = True) -> list[tuple[str, bytes]]:
    seeds = []
    for rel in ("bvh/02_01.bvh", "bvh/01_01.bvh", "salsa/01.bvh"):
        p = SAMPLE / rel
        if p.is_file():
            data = p.read_bytes()
            seeds.append((f"{rel}[:3]", _cut_bvh(data, 3)))
            if include_whole and rel == "bvh/02_01.bvh":
                seeds.append((rel, data))
    seeds.append(("synthetic-zyx", synthetic_bvh(2, 2)))
    seeds.append(("synthetic-zxy-crlf", synthetic_bvh(3, 1, "Zrotation Xrotation Yrotation", "\r\n")))
    return seeds


def expmap_seeds(width: int) -> list[tuple[str, bytes]]:
    seeds = []
    if width == 117:
        for rel in ("expmap/test/walking/walking_1.txt", "expmap/train/running/running_1.txt"):
            p = SAMPLE / rel
            if p.is_file():
                seeds.append((f"{rel}[:4]", _expmap_rows(p.read_bytes(), 4)))
    seeds.append((f"synthetic-{width}", synthetic_expmap(3, width)))
    seeds.append((f"synthetic-{width}-1row", synthetic_expmap(1, width, seed=1)))
    return seeds


# ------------------------------------------------------------------------------------------------------------
# text mutators: (data, drawer) -> (bytes, expectation)
# expectation: "any" (only ValueError/OSError allowed), "reject" (must raise ValueError),
#              "same" (must parse and equal the seed's result)
# ------------------------------------------------------------------------------------------------------------

NONFINITE = ["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "+inf", "1e999", "-1e999", "1e309"]
NON_NUMBERS = ["-", "+", ".", "1.2.3", "--1", "1e", "e5", "abc", "0x10", "1..2", "1e5.5", "1-2", "'1'", "None",
               "\u00a0", "1\x00"]
LENIENT = ["1_0", "\u0661\u0662", "\uff11", "+1", "1E2", "0001", ".5", "5.", "-0", "1e-400"]  # any outcome acceptable


def _numbers(data: bytes) -> list[re.Match]:
    return list(_NUM_RE.finditer(data))


def m_truncate(data, d):
    cut = d.integer(0, max(len(data) - 1, 0))
    out = data[:cut]
    return out, _truncation_expectation(data, out)


def _truncation_expectation(full: bytes, cut: bytes) -> str:
    # The data is cut before the last number starts (whitespace only after it removed from consideration):
    # at least one value is missing, so the file must be rejected. Cuts inside the last number may still parse.
    nums = _numbers(full)
    if not nums:
        return "any"
    if len(cut) <= nums[-1].start():
        return "reject_if_bvh"
    return "any"


def m_truncate_line(data, d):
    lines = data.splitlines(keepends=True)
    k = d.integer(0, max(len(lines) - 1, 0))
    out = b"".join(lines[:k])
    return out, _truncation_expectation(data, out) if data[len(out):].strip() else "any"


def m_nonfinite(data, d):
    nums = _numbers(data)
    if not nums:
        return data, "any"
    m = d.choice(nums)
    return data[:m.start()] + d.choice(NONFINITE).encode() + data[m.end():], "reject"


def m_non_number(data, d):
    nums = _numbers(data)
    if not nums:
        return data, "any"
    m = d.choice(nums)
    return data[:m.start()] + d.choice(NON_NUMBERS).encode() + data[m.end():], "reject"


def m_lenient_number(data, d):
    nums = _numbers(data)
    if not nums:
        return data, "any"
    m = d.choice(nums)
    return data[:m.start()] + d.choice(LENIENT).encode() + data[m.end():], "any"


def m_delete_number(data, d):
    nums = _numbers(data)
    if not nums:
        return data, "any"
    m = d.choice(nums)
    return data[:m.start()] + data[m.end():], "reject"


def m_duplicate_number(data, d):
    nums = _numbers(data)
    if not nums:
        return data, "any"
    m = d.choice(nums)
    sep = b"," if data[m.end():m.end() + 1] == b"," else b" "
    return data[:m.end()] + sep + m.group() + data[m.end():], "reject"


def m_frames_count(data, d):
    m = re.search(rb"Frames:\s*(\S+)", data)
    if m is None:
        return data, "any"
    val = d.choice(["999999999999", "99999999999999999999999", "2147483648", "1000000", "0", "-1", "-3", "1e9",
                    "3.5", "", "abc", "nan", "0x10", "1000", "4", "2"])
    exp = "any" if val in ("0", "1000", "2", "4") else "reject"
    if val in ("1000", "4"):
        exp = "reject"  # more frames declared than present
    return data[:m.start(1)] + val.encode() + data[m.end(1):], exp


def m_channels_count(data, d):
    ms = list(re.finditer(rb"CHANNELS\s+(\d+)", data))
    if not ms:
        return data, "any"
    m = d.choice(ms)
    val = d.choice(["0", "-1", "2", "4", "7", "99999999999", "1e3", "", "x", "3.0"])
    return data[:m.start(1)] + val.encode() + data[m.end(1):], "reject"


def m_channel_name(data, d):
    ms = list(re.finditer(rb"[XYZ](?:rotation|position)", data))
    if not ms:
        return data, "any"
    m = d.choice(ms)
    val = d.choice([b"Wrotation", b"xrotation", b"Xscale", b"rotation", b"", b"Xposition Xposition"])
    return data[:m.start()] + val + data[m.end():], "any"


def m_frame_time(data, d):
    m = re.search(rb"Frame Time:\s*(\S+)", data)
    if m is None:
        return data, "any"
    val = d.choice(["0", "-0.01", "nan", "inf", "1e-320", "1e300", "", "x", "-", "1e999"])
    exp = "reject" if val in ("0", "-0.01", "nan", "inf", "", "x", "-", "1e999") else "any"
    return data[:m.start(1)] + val.encode() + data[m.end(1):], exp


def m_keyword(data, d):
    kws = [b"HIERARCHY", b"ROOT", b"JOINT", b"End Site", b"OFFSET", b"CHANNELS", b"MOTION", b"Frames:",
           b"Frame Time:", b"{", b"}"]
    present = [k for k in kws if k in data]
    if not present:
        return data, "any"
    k = d.choice(present)
    idx = [m.start() for m in re.finditer(re.escape(k), data)]
    i = d.choice(idx)
    rep = d.choice([b"", b"{", b"}", b"JOINT", b"End Site", b"ROOT", b"MOTION", k.lower(), k + k, b"OFFSET"])
    return data[:i] + rep + data[i + len(k):], "any"


def m_brace(data, d):
    pos = [m.start() for m in re.finditer(rb"[{}]", data)]
    if not pos:
        return data, "any"
    i = d.choice(pos)
    if d.boolean():
        return data[:i] + data[i + 1:], "reject"
    return data[:i] + data[i:i + 1] * 2 + data[i + 1:], "reject"


def m_delete_line(data, d):
    lines = data.splitlines(keepends=True)
    if not lines:
        return data, "any"
    k = d.integer(0, len(lines) - 1)
    return b"".join(lines[:k] + lines[k + 1:]), "reject_if_bvh" if lines[k].strip() else "any"


def m_duplicate_line(data, d):
    lines = data.splitlines(keepends=True)
    if not lines:
        return data, "any"
    k = d.integer(0, len(lines) - 1)
    return b"".join(lines[:k + 1] + [lines[k]] + lines[k + 1:]), "any"


def m_swap_lines(data, d):
    lines = data.splitlines(keepends=True)
    if len(lines) < 2:
        return data, "any"
    i, j = d.integer(0, len(lines) - 1), d.integer(0, len(lines) - 1)
    lines[i], lines[j] = lines[j], lines[i]
    return b"".join(lines), "any"


def m_insert_junk(data, d):
    i = d.integer(0, len(data))
    return data[:i] + d.binary(32) + data[i:], "any"


def m_overwrite_junk(data, d):
    if not data:
        return data, "any"
    i = d.integer(0, len(data) - 1)
    junk = d.binary(16)
    return data[:i] + junk + data[i + len(junk):], "any"


def m_bitflip(data, d):
    if not data:
        return data, "any"
    b = bytearray(data)
    for _ in range(d.integer(1, 8)):
        i = d.integer(0, len(b) - 1)
        b[i] ^= 1 << d.integer(0, 7)
    return bytes(b), "any"


def m_all_junk(data, d):
    return d.binary(512), "any"


def m_empty(data, d):
    return d.choice([b"", b" ", b"\n", b"\r\n\r\n", b"\t \n  \n", b"\x00", b"\xef\xbb\xbf", b"\xff\xfe"]), "reject"


def m_encoding(data, d):
    text = data.decode("utf-8", errors="replace")
    enc = d.choice(["utf-16", "utf-16-le", "utf-16-be", "utf-32", "utf-8-sig", "latin-1-names", "cp1252-names",
                    "nul-bytes", "nul-inside", "invalid-utf8", "surrogate-escape"])
    if enc == "latin-1-names":
        text = text.replace("Hips", "Hïpsé").replace("hip", "hïp").replace("J0", "Jö")
        return text.encode("latin-1", "replace"), "any"
    if enc == "cp1252-names":
        return text.replace("Hips", "Hips\u20ac").replace("J0", "J\u20ac").encode("cp1252", "replace"), "any"
    if enc == "nul-bytes":
        return b"\x00".join(data[i:i + 1] for i in range(len(data))), "reject" if len(data) > 1 else "any"
    if enc == "nul-inside":
        i = d.integer(0, len(data))
        return data[:i] + b"\x00" * d.integer(1, 4) + data[i:], "reject"
    if enc == "invalid-utf8":
        i = d.integer(0, len(data))
        return data[:i] + d.choice([b"\xff", b"\xc3\x28", b"\xed\xa0\x80", b"\xf8\x88\x80\x80\x80"]) + data[i:], "any"
    if enc == "surrogate-escape":
        return data + b"\x80", "any"
    return text.encode(enc), "any"


def m_line_endings(data, d):
    kind = d.choice(["crlf", "mixed", "trailing-newlines", "cr", "lfcr", "no-final-newline"])
    lines = data.splitlines()
    if kind == "crlf":
        return b"\r\n".join(lines) + b"\r\n", "same"
    if kind == "mixed":
        out = b""
        for ln in lines:
            out += ln + d.choice([b"\n", b"\r\n"])
        return out, "same"
    if kind == "trailing-newlines":
        return data + d.choice([b"\n", b"\n\n\n", b"\r\n\r\n", b"   \n"]), "same"
    if kind == "no-final-newline":
        return data.rstrip(b"\r\n"), "same"
    if kind == "cr":
        return b"\r".join(lines) + b"\r", "any"
    return b"\n\r".join(lines) + b"\n\r", "any"


def m_whitespace(data, d):
    """BVH only: the amount and kind of horizontal whitespace must not matter."""
    kind = d.choice(["tabs", "double-spaces", "leading", "trailing"])
    lines = data.splitlines(keepends=True)
    out = []
    for ln in lines:
        body, nl = ln.rstrip(b"\r\n"), ln[len(ln.rstrip(b"\r\n")):]
        if kind == "tabs":
            body = body.replace(b" ", b"\t")
        elif kind == "double-spaces":
            body = body.replace(b" ", b"  ")
        elif kind == "leading":
            body = b"  \t" + body.lstrip()
        else:
            body = body + b" \t "
        out.append(body + nl)
    return b"".join(out), "same"


def m_long_token(data, d):
    nums = _numbers(data)
    kind = d.choice(["digits", "inf-digits", "long-line", "long-name", "many-exponent"])
    if kind == "long-name":
        i = data.find(b"ROOT ")
        if i < 0:
            return data + b"x" * 100000, "any"
        return data[:i + 5] + b"N" * 100000 + data[i + 5:], "any"
    if not nums:
        return data + b"9" * 100000, "any"
    m = d.choice(nums)
    rep = {"digits": b"1" + b"0" * 400 + b".5",       # 1e400 written out: overflows to inf
           "inf-digits": b"9" * 5000,                 # also inf as float, too long for int()
           "long-line": b" ".join([b"0"] * 50000),    # wrong count
           "many-exponent": b"1e" + b"9" * 5000}[kind]
    exp = "reject" if kind in ("digits", "inf-digits", "many-exponent", "long-line") else "any"
    return data[:m.start()] + rep + data[m.end():], exp


def m_splice(data, d):
    lines = data.splitlines(keepends=True)
    if len(lines) < 2:
        return data, "any"
    i, j = sorted((d.integer(0, len(lines)), d.integer(0, len(lines))))
    return b"".join(lines[:i] + lines[j:] + lines[i:j]), "any"


def m_huge_frames_little_data(data, d):
    """``Frames: <huge>`` with at most one frame of data (must not allocate from the declared count)."""
    m = re.search(rb"Frames:\s*(\S+)\s*\r?\n[^\n]*\n", data)
    if m is None:
        return data, "any"
    val = d.choice([b"999999999999", b"100000000", b"2305843009213693951", b"18446744073709551617"])
    rest = data[m.end():].splitlines(keepends=True)[:d.integer(0, 1)]
    return data[:m.start(1)] + val + data[m.end(1):m.end()] + b"".join(rest), "reject"


def m_deep(data, d):
    if d.boolean():
        return deep_bvh(d.choice([500, 1500, 3000])), "ok"
    return deep_unclosed_bvh(d.choice([1000, 5000])), "reject"


def m_wide(data, d):
    """Many sibling joints (valid) or many End Sites under the root."""
    n = d.choice([200, 1000])
    body = "".join(f"JOINT S{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 {_ZYX}\nEnd Site\n{{\nOFFSET 0 1 0\n}}\n}}\n"
                   for i in range(n))
    text = (_ROOT_HEAD
            + body + "}\nMOTION\nFrames: 1\nFrame Time: 0.01\n" + " ".join(["0"] * (6 + 3 * n)) + "\n")
    return text.encode(), "ok"


def m_expmap_width(data, d):
    """Exp-map only: change a row's number of values or the separator."""
    lines = data.splitlines(keepends=True)
    if not lines:
        return data, "any"
    k = d.integer(0, len(lines) - 1)
    kind = d.choice(["drop-last", "add", "spaces", "semicolons", "tabs", "empty-field", "trailing-comma"])
    ln = lines[k]
    body, nl = ln.rstrip(b"\r\n"), ln[len(ln.rstrip(b"\r\n")):]
    if kind == "drop-last":
        body = body.rsplit(b",", 1)[0]
        exp = "reject"
    elif kind == "add":
        body = body + b",0.5"
        exp = "reject"
    elif kind == "spaces":
        body = body.replace(b",", b" ")
        exp = "any"
    elif kind == "semicolons":
        body = body.replace(b",", b";")
        exp = "reject"
    elif kind == "tabs":
        body = body.replace(b",", b"\t")
        exp = "any"
    elif kind == "empty-field":
        body = body.replace(b",", b",,", 1)
        exp = "any"  # the reader treats commas as whitespace (documented): ",," is accepted
    else:
        body = body + b","
        exp = "any"
    lines[k] = body + nl
    return b"".join(lines), exp


# --- families of issue #18 and #16: strict frame lines, NUL bytes, truncated rows, pathological hierarchies,
# --- Blender-style 6-channel files

def _data_line_indices(lines: list[bytes]) -> list[int]:
    """Indices of the frame lines: after ``Frame Time:`` in a BVH, every non-blank line in an exp-map file."""
    start = 0
    for i, ln in enumerate(lines):
        if ln.lstrip().lower().startswith(b"frame time"):
            start = i + 1
            break
    return [i for i in range(start, len(lines)) if lines[i].strip()]


def _split_values(body: bytes) -> list[re.Match]:
    return list(re.finditer(rb"[^\s,]+", body))


def m_move_value(data, d):
    """Move the last value of one frame line to the start of the next (total count unchanged): must be refused
    (each frame line holds exactly the declared number of values)."""
    lines = data.splitlines(keepends=True)
    rows = _data_line_indices(lines)
    if len(rows) < 2:
        return data, "any"
    k = d.integer(0, len(rows) - 2)
    a, b = rows[k], rows[k + 1]
    body, nl = lines[a].rstrip(b"\r\n"), lines[a][len(lines[a].rstrip(b"\r\n")):]
    vals = _split_values(body)
    if len(vals) < 2:
        return data, "any"
    last = vals[-1]
    sep = b"," if b"," in body else b" "
    lines[a] = body[:vals[-2].end()] + nl
    lines[b] = last.group() + sep + lines[b].lstrip(b" \t")
    if d.boolean():  # the other direction: first value of the next line appended to this one
        lines = data.splitlines(keepends=True)
        body_b = lines[b]
        vals_b = _split_values(body_b)
        first = vals_b[0]
        rest = body_b[first.end():].lstrip(b" \t,")
        lines[a] = body + sep + first.group() + nl
        lines[b] = rest
    return b"".join(lines), "reject"


def m_nul(data, d):
    """One NUL byte (or a few) anywhere: must be refused."""
    i = d.integer(0, len(data))
    return data[:i] + d.choice([b"\x00", b"\x00\x00", b"0\x00"]) + data[i:], "reject"


def m_truncate_row(data, d):
    """Cut inside a frame line, before its last value (the file ends there): must be refused."""
    lines = data.splitlines(keepends=True)
    rows = _data_line_indices(lines)
    if not rows:
        return data, "any"
    k = d.choice(rows)
    vals = _split_values(lines[k])
    if len(vals) < 2:
        return data, "any"
    cut = d.integer(vals[0].end(), vals[-1].start() - 1)  # at least the first value kept, the last one lost
    return b"".join(lines[:k]) + lines[k][:cut], "reject"


def pathological_bvh(kind: str, n: int) -> bytes:
    """Small but hostile hierarchies (issue #18): ``n`` siblings all named ``A``, ``n`` nested JOINT blocks
    (uniquely named or all ``A``), ``n`` same-named siblings each with an End Site, or ``n`` uniquely named
    siblings. Each must be refused (duplicate names, ``MAX_DEPTH``, ``MAX_JOINTS``) in bounded time."""
    head = _ROOT_HEAD
    if kind == "siblings-same-name":
        body = "JOINT A\n{\nOFFSET 0 1 0\n}\n" * n
    elif kind == "nested-same-name":
        body = "JOINT A\n{\nOFFSET 0 1 0\n" * n + "}\n" * n
    elif kind == "nested":
        body = "".join(f"JOINT A{i}\n{{\nOFFSET 0 1 0\n" for i in range(n)) + "}\n" * n
    elif kind == "siblings-end-sites":
        body = "JOINT A\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Yrotation Xrotation\nEnd Site\n{\nOFFSET 0 1 0\n}\n}\n" * n
    else:  # siblings-unique
        body = "".join(f"JOINT S{i}\n{{\nOFFSET 0 1 0\n}}\n" for i in range(n))
    return (head + body + "}\nMOTION\nFrames: 1\nFrame Time: 0.01\n0 0 0 0 0 0\n").encode()


def m_pathological(data, d):
    kind = d.choice(["siblings-same-name", "nested", "nested-same-name", "siblings-end-sites", "siblings-unique"])
    n = {"siblings-same-name": d.choice([120_000, 5_000]), "nested": d.choice([200_000, 20_000, 1_500]),
         "nested-same-name": d.choice([200_000, 20_000]),
         "siblings-end-sites": d.choice([12_000, 2_000]), "siblings-unique": d.choice([20_000, 12_000])}[kind]
    return pathological_bvh(kind, n), "reject"


def blender_style(data: bytes, noise: float, seed: int = 0) -> bytes | None:
    """The BVH ``data`` rewritten as Blender exports it: ``CHANNELS 6`` (position + rotation) on every joint
    with rotation channels only, the position channels holding the OFFSET plus uniform noise of amplitude
    ``noise`` (Blender's float noise). Same motion. None if ``data`` is not a valid BVH."""
    from refimpl.bvh import read_bvh_header

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "seed.bvh"
        path.write_bytes(data)
        try:
            header = read_bvh_header(path)
        except ValueError:
            return None
    rng = random.Random(seed)
    text = data.decode("utf-8-sig").replace("\r\n", "\n").replace("\r", "\n")
    lines = text.split("\n")
    chans = header.channels
    widen = [j for j, c in enumerate(chans) if j > 0 and c and all(x.endswith("rotation") for x in c)]
    # CHANNELS lines in file order correspond to the joints with channels, in joint order
    with_channels = [j for j, c in enumerate(chans) if c]
    k = 0
    for i, ln in enumerate(lines):
        m = re.match(r"(\s*)CHANNELS\s+(\d+)\s*(.*)$", ln, re.IGNORECASE)
        if m is None:
            continue
        if int(m.group(2)) == 0:
            continue
        j = with_channels[k]
        k += 1
        if j in widen:
            lines[i] = f"{m.group(1)}CHANNELS {int(m.group(2)) + 3} Xposition Yposition Zposition {m.group(3)}"
    start = next(i for i, ln in enumerate(lines) if ln.strip().lower().startswith("frame time")) + 1
    offsets = header.skeleton.offsets
    for i in range(start, len(lines)):
        vals = lines[i].split()
        if not vals:
            continue
        out, col = [], 0
        for j, c in enumerate(chans):
            if j in widen:
                out += [f"{v + rng.uniform(-noise, noise):.6f}" for v in offsets[j]]
            out += vals[col:col + len(c)]
            col += len(c)
        lines[i] = " ".join(out)
    return "\n".join(lines).encode()


def m_blender_style(data, d):
    """Blender-style 6-channel file of a valid seed: must read by default to the seed's world positions, with no
    per-frame translation left (the noise folded into the offsets)."""
    out = blender_style(data, d.choice([0.0, 1e-6, 1e-5]), d.integer(0, 1000))
    if out is None:
        return data, "any"
    return out, "same_positions"


TEXT_MUTATORS: dict[str, Callable] = {
    "truncate": m_truncate, "truncate-line": m_truncate_line, "nonfinite": m_nonfinite,
    "non-number": m_non_number, "lenient-number": m_lenient_number, "delete-number": m_delete_number,
    "duplicate-number": m_duplicate_number, "delete-line": m_delete_line, "duplicate-line": m_duplicate_line,
    "swap-lines": m_swap_lines, "insert-junk": m_insert_junk, "overwrite-junk": m_overwrite_junk,
    "bitflip": m_bitflip, "all-junk": m_all_junk, "empty": m_empty, "encoding": m_encoding,
    "line-endings": m_line_endings, "long-token": m_long_token, "splice": m_splice,
    "move-value": m_move_value, "nul": m_nul, "truncate-row": m_truncate_row,
}
BVH_MUTATORS: dict[str, Callable] = dict(TEXT_MUTATORS, **{
    "frames-count": m_frames_count, "channels-count": m_channels_count, "channel-name": m_channel_name,
    "frame-time": m_frame_time, "keyword": m_keyword, "brace": m_brace, "whitespace": m_whitespace,
    "huge-frames": m_huge_frames_little_data, "deep": m_deep, "wide": m_wide,
    "pathological": m_pathological, "blender-style": m_blender_style,
})
EXPMAP_MUTATORS: dict[str, Callable] = dict(TEXT_MUTATORS, **{"row-width": m_expmap_width})


# ------------------------------------------------------------------------------------------------------------
# binary containers: .npz checkpoints
# ------------------------------------------------------------------------------------------------------------

def _npy_bytes(header: dict | str, payload: bytes, version=(1, 0)) -> bytes:
    h = header if isinstance(header, str) else repr(header)
    h = h.encode("latin-1")
    pad = 64 - ((10 + len(h) + 1) % 64)
    h = h + b" " * pad + b"\n"
    return b"\x93NUMPY" + bytes(version) + len(h).to_bytes(2, "little") + h + payload


def _zip(members: dict[str, bytes], compress: bool = False) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED) as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def _unzip(data: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return {n: z.read(n) for n in z.namelist()}


def checkpoint_seeds() -> list[tuple[str, bytes]]:
    """Small valid checkpoints written by ``refimpl.checkpoint.save_checkpoint``."""
    from refimpl.checkpoint import save_checkpoint

    rng = np.random.default_rng(0)
    out = []
    with tempfile.TemporaryDirectory() as tmp:
        specs = [
            ("params", {"fc.weight": rng.standard_normal((3, 4)), "fc.bias": np.zeros(3)},
             {"model": "quaternet", "step": 7}),
            ("scalar+f32", {"a": np.array(1.5, dtype=np.float32), "b": np.arange(5, dtype=np.int64)},
             {"note": "x"}),
        ]
        for name, arrays, meta in specs:
            p = Path(tmp) / f"{name}.npz"
            save_checkpoint(p, arrays, meta)
            out.append((name, p.read_bytes()))
    return out


def m_npz_member_bytes(data, d):
    """Apply a text/binary mutation to one member of the zip (the checksum, if any, is then wrong)."""
    try:
        members = _unzip(data)
    except Exception:
        return data, "any"
    name = d.choice(sorted(members))
    sub = d.choice(["truncate", "bitflip", "overwrite-junk", "insert-junk", "empty"])
    new, _ = TEXT_MUTATORS[sub](members[name], d)
    if new == members[name]:
        return data, "any"
    members[name] = new
    return _zip(members), "reject"


def m_npz_header(data, d):
    """Replace one array with a crafted .npy: huge declared shape, object dtype, bad dict, big-endian ..."""
    try:
        members = _unzip(data)
    except Exception:
        return data, "any"
    arrays = [n for n in sorted(members) if n.endswith(".npy")]
    if not arrays:
        return data, "any"
    name = d.choice(arrays)
    kind = d.choice(["huge-shape", "large-shape", "huge-shape-2d", "object", "negative-shape", "bad-dict", "not-dict",
                     "unicode", "big-endian", "fortran", "void", "bad-magic", "version-3", "header-len"])
    payload = b"\x00" * 64
    if kind == "huge-shape":
        npy = _npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (10**12,)}, payload)
    elif kind == "large-shape":  # 1.6 GB declared, 64 bytes present: must not be allocated
        npy = _npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (2 * 10**8,)}, payload)
    elif kind == "huge-shape-2d":
        npy = _npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (2**31, 2**31)}, payload)
    elif kind == "object":
        npy = _npy_bytes({"descr": "|O", "fortran_order": False, "shape": (1,)},
                         b"\x80\x04\x95\x10\x00\x00\x00\x00\x00\x00\x00\x8c\x02os\x94.")
    elif kind == "negative-shape":
        npy = _npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (-1,)}, payload)
    elif kind == "bad-dict":
        npy = _npy_bytes("{'descr': '<f8', 'fortran_order': False, 'shape': (__import__('os'),)}", payload)
    elif kind == "not-dict":
        npy = _npy_bytes("[1, 2, 3]", payload)
    elif kind == "unicode":
        npy = _npy_bytes({"descr": "<U4", "fortran_order": False, "shape": (2,)}, "abcdefgh".encode("utf-32-le"))
    elif kind == "big-endian":
        npy = _npy_bytes({"descr": ">f8", "fortran_order": False, "shape": (8,)}, payload)
    elif kind == "fortran":
        npy = _npy_bytes({"descr": "<f8", "fortran_order": True, "shape": (2, 4)}, payload)
    elif kind == "void":
        npy = _npy_bytes({"descr": "|V8", "fortran_order": False, "shape": (8,)}, payload)
    elif kind == "bad-magic":
        npy = b"\x93NUMPX" + members[name][6:]
    elif kind == "version-3":
        npy = b"\x93NUMPY\x09\x00" + members[name][8:]
    else:
        npy = members[name][:8] + b"\xff\xff" + members[name][10:]
    members[name] = npy
    # huge/negative/bad headers, objects and wrong magic are malformed; a well-formed unexpected dtype may
    # fail the checksum or the dtype policy: either way it must be refused
    return _zip(members), "reject"


def m_npz_structure(data, d):
    try:
        members = _unzip(data)
    except Exception:
        return data, "any"
    kind = d.choice(["drop-member", "add-member", "rename-member", "dup-name", "path-traversal", "compressed",
                     "zip-bomb", "not-zip", "nested-zip", "empty-zip"])
    names = sorted(members)
    if kind == "drop-member" and names:
        members.pop(d.choice(names))
        return _zip(members), "reject"
    if kind == "add-member":
        members["extra.npy"] = _npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (2,)}, b"\x00" * 16)
        return _zip(members), "reject"
    if kind == "rename-member" and names:
        n = d.choice(names)
        members["renamed_" + n] = members.pop(n)
        return _zip(members), "reject"
    if kind == "dup-name" and names:
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w") as z, contextlib.redirect_stderr(io.StringIO()):
            import warnings
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                for n, v in members.items():
                    z.writestr(n, v)
                n = d.choice(names)
                z.writestr(n, members[n][: len(members[n]) // 2])
        return buf.getvalue(), "any"
    if kind == "path-traversal" and names:
        n = d.choice(names)
        members["../" + n] = members.pop(n)
        return _zip(members), "reject"
    if kind == "compressed":
        return _zip(members, compress=True), "any"
    if kind == "zip-bomb" and names:
        n = d.choice(names)
        members[n] = _npy_bytes({"descr": "<f8", "fortran_order": False, "shape": (96 * 2**20 // 8,)},
                                b"\x00" * (96 * 2**20))  # 96 MB inflated from ~100 kB
        return _zip(members, compress=True), "reject"
    if kind == "not-zip":
        return b"PK\x03\x04" + d.binary(200), "reject"
    if kind == "nested-zip":
        return _zip({"inner.zip": data}), "reject"
    return _zip({}), "reject"


def m_npz_meta(data, d):
    """Rewrite text members (JSON metadata) with hostile content, leaving array members alone."""
    try:
        members = _unzip(data)
    except Exception:
        return data, "any"
    texts = [n for n in sorted(members) if not n.endswith(".npy") or b"<U" in members[n][:128]]
    if not texts:
        texts = sorted(members)
    name = d.choice(texts)
    val = d.choice([
        b"[" * 100000 + b"]" * 100000,                  # json.loads -> RecursionError unless guarded
        b'{"a":' * 50000 + b"1" + b"}" * 50000,
        b'"__import__(\'os\').system(\'echo pwned\')"',
        b"NaN", b"1e999", b"null", b"[]", b"{}", b'{"step": "7"}', b"\xff\xfe{}", b"",
        b'{"a": 1, "a": 2}',
    ])
    if name.endswith(".npy"):
        s = val.decode("latin-1")
        members[name] = _npy_bytes({"descr": f"<U{max(len(s), 1)}", "fortran_order": False, "shape": ()},
                                   s.encode("utf-32-le") or b"\x00" * 4)
    else:
        members[name] = val
    return _zip(members), "any"


def _documented_checksum(entries: dict) -> bytes:
    """SHA-256 as documented in refimpl/checkpoint.py (re-implemented here from the docstring)."""
    import hashlib

    h = hashlib.sha256()
    for name in sorted(entries):
        a = np.ascontiguousarray(entries[name])
        h.update(name.encode("utf-8") + b"\0")
        h.update(",".join(str(n) for n in a.shape).encode("ascii") + b"\0")
        h.update(a.dtype.str.encode("ascii") + b"\0")
        h.update(a.reshape(-1).view(np.uint8).tobytes() if a.size else b"")
    return h.digest()


def _resign(members: dict[str, bytes]) -> bytes:
    """Zip ``members`` with a correct ``__checksum__`` (so the loader's content checks are reached)."""
    members = {k: v for k, v in members.items() if k != "__checksum__.npy"}
    raw = _zip(members)
    with np.load(io.BytesIO(raw), allow_pickle=False) as z:
        entries = {k: z[k] for k in z.files}
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.frombuffer(_documented_checksum(entries), dtype=np.uint8).copy())
    members["__checksum__.npy"] = buf.getvalue()
    return _zip(members)


def _npy_of(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, a, allow_pickle=False)
    return buf.getvalue()


def m_npz_resigned(data, d):
    """Well-formed archives with a VALID checksum but hostile content: the loader's own checks must hold."""
    try:
        members = _unzip(data)
    except Exception:
        return data, "any"
    kind = d.choice(["deep-json-list", "deep-json-dict", "meta-list", "meta-string", "meta-nan", "meta-bad-utf8",
                     "meta-code", "unicode-array", "raw-member", "checksum-float", "meta-float-dtype",
                     "big-endian-array", "no-meta"])
    meta_text = None
    exp = "reject"
    if kind == "deep-json-list":
        meta_text = b"[" * 100000 + b"]" * 100000
    elif kind == "deep-json-dict":
        meta_text = b'{"a":' * 20000 + b"1" + b"}" * 20000
    elif kind == "meta-list":
        meta_text = b"[1, 2]"
    elif kind == "meta-string":
        meta_text = b'"x"'
    elif kind == "meta-nan":
        meta_text = b'{"loss": NaN}'        # the format says: no NaN/inf in the metadata
    elif kind == "meta-bad-utf8":
        meta_text = b'{"a": "\xff\xfe"}'
    elif kind == "meta-code":
        meta_text = json.dumps({"cmd": "__import__('os').system('echo pwned')"}).encode()
        exp = "any"                          # plain text in a dict: fine to load, must never run
    elif kind == "unicode-array":
        members["names.npy"] = _npy_of(np.array(["ab", "cd"]))
        exp = "any"
    elif kind == "raw-member":
        members["notes"] = b"raw bytes, not an .npy member"   # np.load returns bytes for such a member
    elif kind == "checksum-float":
        pass
    elif kind == "meta-float-dtype":
        members["__meta__.npy"] = _npy_of(np.frombuffer(b'{"a": 1}', dtype=np.uint8).astype(np.float64))
    elif kind == "big-endian-array":
        name = d.choice([n for n in sorted(members) if not n.startswith("__")] or ["__meta__.npy"])
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            key = name[:-4] if name.endswith(".npy") else name
            a = z[key] if key in z.files else np.zeros(2)
        members[name] = _npy_of(a.astype(a.dtype.newbyteorder(">")) if a.dtype.kind in "fiu" else a)
        exp = "any"
    elif kind == "no-meta":
        members.pop("__meta__.npy", None)
    if meta_text is not None:
        members["__meta__.npy"] = _npy_of(np.frombuffer(meta_text, dtype=np.uint8).copy())
    try:
        out = _resign(members)
    except Exception:
        return _zip(members), "any"
    if kind == "checksum-float":
        m2 = _unzip(out)
        arr = np.load(io.BytesIO(m2["__checksum__.npy"]), allow_pickle=False)
        m2["__checksum__.npy"] = _npy_of(arr.astype(np.float64))
        out = _zip(m2)
    return out, exp


CHECKPOINT_MUTATORS: dict[str, Callable] = {
    "truncate": lambda data, d: (data[:d.integer(0, max(len(data) - 1, 0))], "reject"),
    "bitflip": m_bitflip, "insert-junk": m_insert_junk, "overwrite-junk": m_overwrite_junk,
    "all-junk": lambda data, d: (d.binary(512), "reject"), "empty": lambda data, d: (b"", "reject"),
    "member-bytes": m_npz_member_bytes, "npy-header": m_npz_header, "zip-structure": m_npz_structure,
    "meta": m_npz_meta, "resigned": m_npz_resigned,
}


# ------------------------------------------------------------------------------------------------------------
# ONNX models (deploy.runtime's loader)
# ------------------------------------------------------------------------------------------------------------

def onnx_seeds() -> list[tuple[str, bytes]]:
    """A tiny exported QTG ``step`` model (deploy.models.qtg) and an Identity model carrying the same metadata."""
    import onnx
    from onnx import TensorProto, helper

    from deploy.models.qtg import export_qtg_step
    from refimpl.models.qtg import QTGConfig, init_params

    cfg = QTGConfig(pose_size=11, encoder_sizes=(8, 4), gru_hidden=6, decoder_sizes=(8,), transition_length=3)
    step = export_qtg_step(init_params(cfg, np.random.default_rng(0)), cfg)
    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, ["B", 4])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, ["B", 4])
    graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g", [x], [y])
    ident = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    for e in step.metadata_props:
        ident.metadata_props.add(key=e.key, value=e.value)
    onnx.checker.check_model(ident, full_check=True)
    return [("qtg_step", step.SerializeToString()), ("identity+meta", ident.SerializeToString())]


def m_onnx_meta(data, d):
    import onnx

    try:
        model = onnx.load_from_string(data)
    except Exception:
        return data, "any"
    hostile = [
        "__import__('os').system('echo pwned')", "eval('1+1')", "{{7*7}}", "${jndi:x}", "[" * 100000,
        '{"a":' * 50000 + "1" + "}" * 50000, "NaN", "1e999", "\x00", "'; DROP TABLE x; --", "",
        json.dumps({"__class__": "os.system", "args": ["x"]}), "ﬀ" * 10000,
    ]
    if model.metadata_props and d.boolean():
        e = d.choice(list(model.metadata_props))
        e.value = d.choice(hostile)
    else:
        e = model.metadata_props.add()
        e.key, e.value = d.choice(["refimpl", "config", "__import__", "x" * 1000, ""]), d.choice(hostile)
    return model.SerializeToString(), "any"


def m_onnx_graph(data, d):
    import onnx

    try:
        model = onnx.load_from_string(data)
    except Exception:
        return data, "any"
    kind = d.choice(["opset-999", "ir-999", "no-output", "bad-op", "domain", "dangling"])
    if kind == "opset-999":
        model.opset_import[0].version = 999
    elif kind == "ir-999":
        model.ir_version = 999
    elif kind == "no-output":
        del model.graph.output[:]
    elif kind == "bad-op":
        if model.graph.node:
            model.graph.node[0].op_type = "NoSuchOp"
    elif kind == "domain":
        if model.graph.node:
            model.graph.node[0].domain = "evil.domain"
    else:
        if model.graph.node:
            model.graph.node[0].input[0] = "does_not_exist"
    return model.SerializeToString(), "reject"


ONNX_MUTATORS: dict[str, Callable] = {
    "truncate": lambda data, d: (data[:d.integer(0, max(len(data) - 1, 0))], "reject"),
    "bitflip": m_bitflip, "insert-junk": m_insert_junk, "overwrite-junk": m_overwrite_junk,
    "all-junk": lambda data, d: (d.binary(512), "reject"), "empty": lambda data, d: (b"", "reject"),
    "metadata": m_onnx_meta, "graph": m_onnx_graph,
}


# ------------------------------------------------------------------------------------------------------------
# targets
# ------------------------------------------------------------------------------------------------------------

@dataclass
class Target:
    name: str
    suffix: str
    call: Callable[[str], object]
    seeds: list
    mutators: dict
    compare: bool = True  # whether "same" expectations can compare results
    checksummed: tuple = ()  # mutators after which an accepted file must load exactly as the seed


def _bvh_call(path):
    from refimpl.bvh import read_bvh

    return read_bvh(path)


def _expmap_call(layout):
    def call(path):
        from refimpl.expmap import read_expmap

        return read_expmap(path, layout=layout)
    return call


def _checkpoint_call(path):
    from refimpl.checkpoint import load_checkpoint

    return load_checkpoint(path)


def onnx_loader():
    """``deploy.runtime.load_model``."""
    from deploy.runtime import load_model

    return load_model


def _onnx_call(path):
    """Load (validation + metadata) and read what a consumer reads first: role, inputs, outputs."""
    model = onnx_loader()(path)
    _ = model.role
    return {"metadata": model.metadata, "inputs": model.inputs, "outputs": model.outputs}


def build_targets(include_whole: bool = True, only: set | None = None) -> tuple[list[Target], dict[str, str]]:
    """All targets whose modules import; the second value maps skipped targets to the reason."""
    targets, skipped = [], {}

    def add(name, fn):
        if only and name not in only:
            return
        try:
            t = fn()
            _ = t.call  # noqa
            targets.append(t)
        except Exception as e:  # module missing or seed creation failed
            skipped[name] = f"{type(e).__name__}: {e}"

    def bvh():
        import refimpl.bvh  # noqa: F401
        return Target("bvh", ".bvh", _bvh_call, bvh_seeds(include_whole), BVH_MUTATORS)

    def expmap(layout, width):
        def make():
            import refimpl.expmap  # noqa: F401
            return Target(f"expmap-{layout}", ".txt", _expmap_call(layout), expmap_seeds(width), EXPMAP_MUTATORS)
        return make

    def checkpoint():
        import refimpl.checkpoint  # noqa: F401
        return Target("checkpoint", ".npz", _checkpoint_call, checkpoint_seeds(), CHECKPOINT_MUTATORS,
                      checksummed=tuple(k for k in CHECKPOINT_MUTATORS if k != "resigned"))

    def onnx_t():
        onnx_loader()
        return Target("onnx", ".onnx", _onnx_call, onnx_seeds(), ONNX_MUTATORS, compare=False)

    add("bvh", bvh)
    add("expmap-cmu", expmap("cmu", 117))
    add("expmap-h36m", expmap("h36m", 99))
    add("checkpoint", checkpoint)
    add("onnx", onnx_t)
    return targets, skipped


def mutate(target: Target, seed: bytes, mutator: str, drawer) -> tuple[bytes, str]:
    """Apply ``target.mutators[mutator]``; an unchanged result cannot be expected to be rejected."""
    data, expectation = target.mutators[mutator](seed, drawer)
    if expectation == "ok":  # valid but unusual (deep, wide): a documented ValueError limit is fine
        expectation = "any"
    if data == seed and expectation.startswith("reject"):
        expectation = "any"
    if mutator in target.checksummed:
        expectation = "reject_or_same"  # the checksum: refused, or the content is exactly the original
    return data, expectation


# ------------------------------------------------------------------------------------------------------------
# running one case
# ------------------------------------------------------------------------------------------------------------

class CaseTimeout(BaseException):
    """Raised by the alarm handler when a case runs too long."""


def _alarm(signum, frame):
    raise CaseTimeout()


def _arrays(obj, depth=0):
    """All ndarrays reachable from obj through dataclasses, dicts, lists, tuples and simple objects."""
    if depth > 6:
        return
    if isinstance(obj, np.ndarray):
        yield obj
    elif is_dataclass(obj) and not isinstance(obj, type):
        for f in fields(obj):
            yield from _arrays(getattr(obj, f.name), depth + 1)
    elif isinstance(obj, dict):
        for v in obj.values():
            yield from _arrays(v, depth + 1)
    elif isinstance(obj, (list, tuple)):
        for v in obj:
            yield from _arrays(v, depth + 1)


def same_result(a, b, depth=0) -> bool:
    """Structural equality of reader results (arrays compared exactly, NaN-aware)."""
    if depth > 8:
        return True
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and bool(np.array_equal(a, b, equal_nan=a.dtype.kind == "f"))
    if is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(same_result(getattr(a, f.name), getattr(b, f.name), depth + 1)
                                          for f in fields(a))
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same_result(a[k], b[k], depth + 1) for k in a)
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(same_result(x, y, depth + 1) for x, y in zip(a, b))
    try:
        return bool(a == b)
    except Exception:
        return False


@dataclass
class Outcome:
    kind: str              # "ok", or the exception type name
    failure: str | None    # None when the contract holds, else the failure type
    detail: str = ""
    peak: int = 0
    seconds: float = 0.0
    names_file: bool | None = None  # for ValueError: does the message name the file?


def run_case(target: Target, data: bytes, expectation: str, path: Path, reference=None,
             timeout: float = 10.0, check_memory: bool = True) -> Outcome:
    """Write ``data`` to ``path``, call the reader, classify what happened."""
    path.write_bytes(data)
    old = signal.signal(signal.SIGALRM, _alarm) if timeout else None
    if check_memory:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    result, exc = None, None
    try:
        if timeout:
            signal.setitimer(signal.ITIMER_REAL, timeout)
        try:
            result = target.call(str(path))
        finally:
            if timeout:
                signal.setitimer(signal.ITIMER_REAL, 0)
    except CaseTimeout:
        return Outcome("Timeout", "Timeout", f"> {timeout} s", 0, time.perf_counter() - t0)
    except BaseException as e:  # noqa: BLE001 - classifying is the point
        if isinstance(e, KeyboardInterrupt):
            raise
        exc = e
    finally:
        if old is not None:
            signal.signal(signal.SIGALRM, old)
    seconds = time.perf_counter() - t0
    peak = 0
    if check_memory:
        peak = max(tracemalloc.get_traced_memory()[1] - base, 0)
    limit = MEM_FIXED + MEM_PER_BYTE * len(data)
    if exc is not None:
        kind = type(exc).__name__
        msg = f"{kind}: {str(exc)[:300]}"
        if not isinstance(exc, ALLOWED):
            return Outcome(kind, kind, msg, peak, seconds)
        names_file = path.name in str(exc) if isinstance(exc, ValueError) else None
        if expectation == "reject" and seconds > SLOW_REJECT_SECONDS and len(data) < 16 * 2**20:
            return Outcome(kind, "SlowReject", f"{seconds:.2f} s > {SLOW_REJECT_SECONDS} s; {msg}", peak, seconds,
                           names_file)
        if check_memory and peak > limit:
            return Outcome(kind, "MemoryBound", f"peak {peak} B > {limit} B; {msg}", peak, seconds, names_file)
        return Outcome(kind, None, msg, peak, seconds, names_file)
    if check_memory and peak > limit:
        return Outcome("ok", "MemoryBound", f"peak {peak} B > {limit} B", peak, seconds)
    for a in _arrays(result):
        if a.dtype.kind in "fc" and not np.all(np.isfinite(a)):
            return Outcome("ok", "NonFiniteOutput", f"array of shape {a.shape} has non-finite values", peak, seconds)
    if expectation in ("reject", "reject_if_bvh"):
        if expectation == "reject" or target.name == "bvh":
            return Outcome("ok", "AcceptedMalformed", "a malformed file was accepted", peak, seconds)
    if expectation == "same" and target.compare and reference is not None and not same_result(result, reference):
        return Outcome("ok", "ChangedByNeutralEdit", "the result differs from the unmodified file's", peak, seconds)
    if expectation == "same_positions" and reference is not None:
        a, b = result.positions(), reference.positions()
        scale = max(1.0, float(np.max(np.abs(b)))) if b.size else 1.0
        left = getattr(result, "translated_joints", ())
        if left or a.shape != b.shape or not np.allclose(a, b, rtol=0, atol=1e-4 * scale):
            return Outcome("ok", "ChangedByNeutralEdit", "the Blender-style rewrite reads to other positions or "
                           f"keeps per-frame translations {left}", peak, seconds)
    if expectation == "reject_or_same" and reference is not None and not same_result(result, reference):
        return Outcome("ok", "AcceptedCorrupted", "a damaged file was accepted with content differing from the "
                       "original", peak, seconds)
    return Outcome("ok", None, "", peak, seconds)


# ------------------------------------------------------------------------------------------------------------
# campaign
# ------------------------------------------------------------------------------------------------------------

def campaign(n_cases: int, seed: int = 0, timeout: float = 10.0, only: set | None = None,
             check_memory: bool = True, log=print) -> dict:
    targets, skipped = build_targets(include_whole=True, only=only)
    if not targets:
        raise SystemExit(f"no reader available: {skipped}")
    rng = random.Random(seed)
    drawer = RandomDrawer(rng)
    stats = {t.name: {"cases": 0, "outcomes": {}, "failures": {}, "by_mutator": {}, "max_seconds": 0.0,
                      "max_peak_bytes": 0, "valueerrors_naming_file": 0, "valueerrors": 0} for t in targets}
    examples: list[dict] = []
    if check_memory:
        tracemalloc.start()
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fuzz_readers_") as tmp:
        tmp = Path(tmp)
        # reference results of the unmodified seeds (must all load)
        refs = {}
        for t in targets:
            for sname, sdata in t.seeds:
                path = tmp / f"input{t.suffix}"  # the same file name as the cases (readers name motions by stem)
                out = run_case(t, sdata, "ok", path, timeout=timeout * 3, check_memory=False)
                if out.failure or out.kind != "ok":
                    stats[t.name]["failures"]["SeedRejected"] = stats[t.name]["failures"].get("SeedRejected", 0) + 1
                    examples.append({"reader": t.name, "mutator": "seed", "seed_file": sname,
                                     "failure": "SeedRejected", "detail": out.detail})
                    refs[(t.name, sname)] = None
                else:
                    try:
                        refs[(t.name, sname)] = t.call(str(path))
                    except Exception:
                        refs[(t.name, sname)] = None
        for i in range(n_cases):
            t = targets[i % len(targets)]
            drawer.chosen = []
            sname, sdata = drawer.choice(t.seeds)
            mname = drawer.choice(sorted(t.mutators))
            data, expectation = mutate(t, sdata, mname, drawer)
            out = run_case(t, data, expectation, tmp / f"input{t.suffix}", refs.get((t.name, sname)),
                           timeout=timeout, check_memory=check_memory)
            s = stats[t.name]
            s["cases"] += 1
            s["outcomes"][out.kind] = s["outcomes"].get(out.kind, 0) + 1
            bm = s["by_mutator"].setdefault(mname, {"cases": 0, "failures": 0})
            bm["cases"] += 1
            s["max_seconds"] = max(s["max_seconds"], out.seconds)
            if out.kind != "MemoryError":  # a refused huge allocation is counted by tracemalloc: not a peak
                s["max_peak_bytes"] = max(s["max_peak_bytes"], out.peak)
            if out.names_file is not None:
                s["valueerrors"] += 1
                s["valueerrors_naming_file"] += int(out.names_file)
            if out.failure:
                s["failures"][out.failure] = s["failures"].get(out.failure, 0) + 1
                key = f"{out.failure} <- {mname}/{'/'.join(drawer.chosen[1:3]) or '-'}"
                s.setdefault("failure_sources", {})[key] = s.setdefault("failure_sources", {}).get(key, 0) + 1
                bm["failures"] += 1
                if sum(1 for e in examples if e["reader"] == t.name and e["failure"] == out.failure) < 5:
                    examples.append({"reader": t.name, "mutator": mname, "seed_file": sname, "case": i,
                                     "choices": drawer.chosen[1:], "failure": out.failure,
                                     "detail": out.detail[:500],
                                     "input_head": data[:200].decode("latin-1"), "input_size": len(data)})
            if log and (i + 1) % 1000 == 0:
                log(f"  {i + 1} cases, {time.perf_counter() - t_start:.0f} s")
    if check_memory:
        tracemalloc.stop()
    total_failures = sum(sum(s["failures"].values()) for s in stats.values())
    return {"cases": n_cases, "seed": seed, "timeout_s": timeout, "memory_bound": {"fixed_bytes": MEM_FIXED,
            "per_input_byte": MEM_PER_BYTE}, "seconds": round(time.perf_counter() - t_start, 1),
            "readers": stats, "skipped_readers": skipped, "failures": total_failures, "examples": examples}


def _allowed_kind(kind: str) -> str:
    """Bucket an outcome kind: "ok", "ValueError" (incl. subclasses), "OSError" (incl. subclasses) or "other"."""
    import builtins

    exc = getattr(builtins, kind, None)
    if kind == "ok":
        return "ok"
    if kind in ("UnicodeDecodeError", "JSONDecodeError") or (isinstance(exc, type) and issubclass(exc, ValueError)):
        return "ValueError"
    if isinstance(exc, type) and issubclass(exc, OSError):
        return "OSError"
    return "other"


def _table(head, rows):
    widths = [max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(head)]
    lines = ["  ".join(h.rjust(w) for h, w in zip(head, widths))]
    lines += ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in rows]
    return "\n".join(lines)


def print_table(res: dict) -> None:
    """Table 1: cases per reader by outcome; table 2: failures per exception/failure type and reader."""
    rows = []
    for name, s in res["readers"].items():
        buckets = {"ok": 0, "ValueError": 0, "OSError": 0, "other": 0}
        for kind, n in s["outcomes"].items():
            buckets[_allowed_kind(kind)] += n
        rows.append([name, str(s["cases"]), str(buckets["ok"]), str(buckets["ValueError"]), str(buckets["OSError"]),
                     str(buckets["other"]), str(sum(s["failures"].values())), f"{s['max_seconds']:.2f}",
                     f"{s['max_peak_bytes'] / 2**20:.1f}", f"{s['valueerrors_naming_file']}/{s['valueerrors']}"])
    print(_table(["reader", "cases", "accepted", "ValueError", "OSError", "other exc", "failures", "max s",
                  "max MB", "ValueError names file"], rows))
    fails = sorted({k for s in res["readers"].values() for k in s["failures"]})
    if fails:
        names = list(res["readers"])
        rows = [[f] + [str(res["readers"][n]["failures"].get(f, 0)) for n in names]
                + [str(sum(res["readers"][n]["failures"].get(f, 0) for n in names))] for f in fails]
        print()
        print(_table(["failure type"] + names + ["total"], rows))
    for k, v in res["skipped_readers"].items():
        print(f"skipped {k}: {v}")
    print(f"total: {res['cases']} cases in {res['seconds']} s, {res['failures']} failures")
    shown = set()
    for e in res["examples"]:
        key = (e["reader"], e["failure"])
        if key in shown:
            continue
        shown.add(key)
        detail = e["detail"][:160].replace("\n", " ")
        print(f"  e.g. [{e['reader']}/{e['mutator']}/{e.get('seed_file')}] {e['failure']}: {detail}")


def _write_json_atomic(path: Path, obj) -> None:
    atomic_write_text(path, json.dumps(obj, indent=1, sort_keys=True), make_parents=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=10000, help="number of fuzz cases (spread over the readers)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--timeout", type=float, default=10.0, help="per-case wall-clock limit in seconds")
    ap.add_argument("--readers", default="", help="comma-separated subset (bvh,expmap-cmu,expmap-h36m,checkpoint,onnx)")
    ap.add_argument("--no-memory", action="store_true", help="skip the tracemalloc memory bound (faster)")
    ap.add_argument("--out", default=str(ROOT / "tests" / "fuzz" / "results" / "fuzz_readers.json"))
    args = ap.parse_args(argv)
    only = {s.strip() for s in args.readers.split(",") if s.strip()} or None
    res = campaign(args.cases, args.seed, args.timeout, only, check_memory=not args.no_memory)
    print_table(res)
    _write_json_atomic(Path(args.out), res)
    print(f"wrote {args.out}")
    return 1 if res["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
