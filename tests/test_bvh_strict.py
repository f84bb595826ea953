"""Strict readers (issue #18, spec/robustness.md §1, spec/data.md §2.3): one-line reproducers of each failure
family of the fuzz campaign (tests/fuzz/readers.py), and the documented limits.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from refimpl.bvh import MAX_DEPTH, MAX_FRAME_VALUES, MAX_JOINTS, read_bvh
from refimpl.expmap import read_expmap
from tests.fuzz import readers as F

ROOT = Path(__file__).resolve().parents[1]



BVH = ("HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation\n"
       "JOINT A\n{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Yrotation Xrotation\nEnd Site\n{\nOFFSET 0 1 0\n}\n}\n}\n"
       "MOTION\nFrames: 2\nFrame Time: 0.1\n1 2 3 4 5 6 7 8 9\n1 2 3 4 5 6 7 8 9\n")


def _w(tmp_path, text, name="f.bvh"):
    p = tmp_path / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    return p


def test_valid_small_file(tmp_path):
    assert read_bvh(_w(tmp_path, BVH)).num_frames == 2


# -- a value moved across frame lines (total count unchanged) ----------------------------------------------

def test_bvh_value_moved_to_next_line(tmp_path):
    with pytest.raises(ValueError, match=r"f\.bvh:19: frame 1: expected 9 numbers .*got 8"):
        read_bvh(_w(tmp_path, BVH.replace("7 8 9\n1 2", "7 8\n9 1 2")))


def test_bvh_value_moved_to_previous_line(tmp_path):
    with pytest.raises(ValueError, match=r"f\.bvh:19: frame 1: expected 9 numbers .*got 10"):
        read_bvh(_w(tmp_path, BVH.replace("7 8 9\n1 2", "7 8 9 1\n2")))


@pytest.mark.parametrize("layout,width", [("cmu", 117), ("h36m", 99)])
def test_expmap_value_moved_across_rows(tmp_path, layout, width):
    rows = [",".join(["0.1"] * width)] * 3
    rows[0] += ",0.1"
    rows[1] = ",".join(["0.1"] * (width - 1))
    with pytest.raises(ValueError, match=rf"e\.txt:1: row 1: expected {width} values, got {width + 1}"):
        read_expmap(_w(tmp_path, "\n".join(rows) + "\n", "e.txt"), layout=layout)


# -- NUL bytes ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("where", ["OFFSET 0 1", "Frame Time: 0.1", "4 5 6 7"])
def test_bvh_nul_byte(tmp_path, where):
    text = BVH.replace(where, where + "\x00", 1)
    line = text[:text.index("\x00")].count("\n") + 1
    with pytest.raises(ValueError, match=rf"f\.bvh:{line}: NUL byte"):
        read_bvh(_w(tmp_path, text))


def test_expmap_nul_byte(tmp_path):
    text = ",".join(["0.1"] * 117) + "\n" + ",".join(["0.1"] * 116) + ",0.1\x00\n"
    with pytest.raises(ValueError, match=r"e\.txt:2: NUL byte"):
        read_expmap(_w(tmp_path, text, "e.txt"))


# -- truncated rows ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("layout,width", [("cmu", 117), ("h36m", 99)])
def test_expmap_truncated_inside_last_row(tmp_path, layout, width):
    full = ",".join(["0.25"] * width)
    text = full + "\n" + full[:len(full) // 2]                             # the file ends inside row 2
    with pytest.raises(ValueError, match=rf"e\.txt:2: row 2: expected {width} values"):
        read_expmap(_w(tmp_path, text, "e.txt"), layout=layout)


def test_bvh_truncated_inside_last_row(tmp_path):
    with pytest.raises(ValueError, match=r"f\.bvh:20: frame 2: expected 9 numbers .*got 5"):
        read_bvh(_w(tmp_path, BVH[:-9]))


# -- pathological hierarchies: refused fast ----------------------------------------------------------------

LIMIT = rf":40002: more than MAX_JOINTS = {MAX_JOINTS} joints"  # the 10001st node line: counted before parsing


@pytest.mark.parametrize("kind,n,message", [
    ("siblings-same-name", 120_000, LIMIT),
    ("siblings-same-name", 5_000, r":10: duplicate joint name 'A' \(first on line 6\)"),
    ("nested-same-name", 200_000, r":30003: more than MAX_JOINTS"),
    ("nested-same-name", 5_000, r":9: duplicate joint name 'A'"),
    ("nested", 200_000, r":30003: more than MAX_JOINTS"),
    ("nested", 1_500, rf"nesting deeper than MAX_DEPTH = {MAX_DEPTH}"),
    ("siblings-end-sites", 12_000, r"more than MAX_JOINTS"),
    ("siblings-end-sites", 2_000, r":15: duplicate joint name 'A'"),
    ("siblings-unique", 12_000, LIMIT),
])
def test_pathological_hierarchies_fail_fast(tmp_path, kind, n, message):
    path = _w(tmp_path, F.pathological_bvh(kind, n))
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match=message):
        read_bvh(path)
    assert time.perf_counter() - t0 < 1.0


def test_limits_accept_up_to_the_limit(tmp_path):
    """MAX_DEPTH − 2 nested joints (plus ROOT and End Site) read; one more level is refused."""
    m = read_bvh(_w(tmp_path, F.deep_bvh(MAX_DEPTH - 2)))
    assert m.num_joints == MAX_DEPTH
    with pytest.raises(ValueError, match="MAX_DEPTH"):
        read_bvh(_w(tmp_path, F.deep_bvh(MAX_DEPTH - 1)))


def test_frame_values_limit(tmp_path):
    """frames × max(channels, 4 · joints) > MAX_FRAME_VALUES is refused before any array is built."""
    joints = 2000                                                          # no channels: "0" per frame line
    body = "".join(f"JOINT S{i}\n{{\nOFFSET 0 1 0\n}}\n" for i in range(joints))
    frames = MAX_FRAME_VALUES // (4 * (joints + 1)) + 1
    text = ("HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 1 Yrotation\n" + body + "}\nMOTION\n"
            f"Frames: {frames}\nFrame Time: 0.1\n" + "0\n" * frames)
    with pytest.raises(ValueError, match="MAX_FRAME_VALUES"):
        read_bvh(_w(tmp_path, text))


# -- Blender-style 6-channel files -------------------------------------------------------------------------

@pytest.mark.parametrize("noise", [0.0, 1e-5])
def test_blender_style_rewrite_reads_to_the_same_positions(tmp_path, noise):
    seed = F._cut_bvh((ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh").read_bytes(), 5)
    ref = read_bvh(_w(tmp_path, seed, "a.bvh"))
    six = read_bvh(_w(tmp_path, F.blender_style(seed, noise, seed=1), "b.bvh"))
    assert six.translated_joints == ()
    np.testing.assert_allclose(six.positions(), ref.positions(), atol=1e-4)
    assert len(read_bvh(tmp_path / "b.bvh", translations="keep").translated_joints) == 30
