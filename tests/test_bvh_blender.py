"""BVH reading against Blender (spec/data.md §2.1): a Blender-exported file opens with the default options, and,
where Blender is installed, our world positions equal those of Blender's own importer.

The Blender runs (``blender -b --python tests/blender_bvh.py``) are skipped cleanly when ``blender`` is not on
the PATH (or ``../shared`` is absent for the Bandai Namco files).
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from refimpl.bvh import read_bvh, read_bvh_header

ROOT = Path(__file__).resolve().parents[1]
BLENDER_SAMPLE = ROOT / "tests" / "data" / "blender" / "02_01_blender.bvh"
CMU = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
BANDAI = ROOT.parent / "shared" / "data" / "bandai_namco_locomotion"


def _cut(src: Path, dst: Path, first: int, count: int) -> Path:
    """Frames ``first .. first + count - 1`` of ``src`` (``Frames:`` rewritten)."""
    text = src.read_text()
    head, rest = re.split(r"(?m)^\s*MOTION\s*$", text, maxsplit=1)
    lines = rest.strip("\n").split("\n")
    dst.write_text(head + "MOTION\n" + f"Frames: {count}\n" + lines[1] + "\n"
                   + "\n".join(lines[2 + first:2 + first + count]) + "\n")
    return dst


def test_blender_exported_file_opens_by_default():
    """Blender's export (6 channels on unconnected joints, translations with ~1e-6 noise) reads by default:
    the noise is folded into the offsets (no per-frame translations left) and the positions are those of
    the original frames 1-20 of 02_01 within the 6 printed decimals and Blender's float32."""
    header = read_bvh_header(BLENDER_SAMPLE)
    six = [header.skeleton.names[j] for j, c in enumerate(header.channels) if len(c) == 6]
    assert len(six) > 1 and "LHipJoint" in six
    m = read_bvh(BLENDER_SAMPLE)
    assert m.translated_joints == () and m.num_frames == 20
    assert read_bvh(BLENDER_SAMPLE, translations="keep").translated_joint_names == tuple(six[1:])
    assert header.translated_joint_names == tuple(six[1:])
    orig = read_bvh(CMU)
    idx = [m.skeleton.names.index(n) for n in orig.skeleton.names]
    err = np.abs(m.positions()[:, idx] - orig.positions()[1:21])
    assert err.max() < 1e-4, err.max()
    # strict reading refuses nothing here either: the only translations were constant
    assert read_bvh(BLENDER_SAMPLE, translations="rotations").translated_joints == ()


def _blender_heads(tmp_path: Path, path: Path, export: Path | None = None):
    out = tmp_path / (path.stem + ".json")
    cmd = ["blender", "-b", "--factory-startup", "--python", str(ROOT / "tests" / "blender_bvh.py"), "--",
           str(path), str(out)] + ([str(export)] if export else [])
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0 and out.is_file(), proc.stdout[-2000:] + proc.stderr[-2000:]
    d = json.loads(out.read_text())
    return d["names"], np.array(d["heads"])                                # (T, J, 3)


def _compare(path: Path, names, heads) -> float:
    worst = 0.0
    for mode in ("auto", "keep"):
        m = read_bvh(path, translations=mode)
        ours = m.positions()
        common = [n for n in names if n in m.skeleton.names]
        assert len(common) >= len(names) - 1                                # at most the removed static root
        a = ours[:, [m.skeleton.index(n) for n in common]]
        b = heads[:, [names.index(n) for n in common]]
        assert a.shape == b.shape
        worst = max(worst, float(np.max(np.abs(a - b))))
    return worst


@pytest.mark.skipif(shutil.which("blender") is None, reason="blender is not installed")
def test_positions_match_blender_importer(tmp_path):
    """Blender's importer (float32) and ours agree to 1e-4 (cm or CMU units) on a CMU cut, the
    Blender-exported sample and (with ../shared) two Bandai Namco files; Blender re-exports our reading."""
    files = [_cut(CMU, tmp_path / "cmu_cut.bvh", 1, 20), BLENDER_SAMPLE]
    if BANDAI.is_dir():
        files += [_cut(BANDAI / "dataset-2_walk_normal_001.bvh", tmp_path / "bandai_walk.bvh", 0, 40),
                  _cut(BANDAI / "dataset-2_run_active_048.bvh", tmp_path / "bandai_run.bvh", 0, 40)]
    for k, f in enumerate(files):
        export = tmp_path / f"export_{k}.bvh"
        names, heads = _blender_heads(tmp_path, f, export)
        assert heads.shape[0] == read_bvh_header(f).num_frames
        assert _compare(f, names, heads) < 1e-4 * max(1.0, float(np.abs(heads).max())), f.name
        # Blender's export of each file opens by default and gives the same positions
        again = read_bvh(export)
        ref = read_bvh(f, translations="keep")
        common = [n for n in again.skeleton.names if n in ref.skeleton.names]
        a = again.positions()[:, [again.skeleton.index(n) for n in common]]
        b = ref.positions()[:, [ref.skeleton.index(n) for n in common]]
        assert np.abs(a - b).max() < 1e-3 * max(1.0, float(np.abs(b).max())), f.name
