"""refimpl's BVH reading + FK against an independent reading (tests/bvh_oracle.py), spec/data.md §2.1.

Every shared BVH file except the Bandai Namco set, and a deterministic subset (every 40th file, a few frames
each) of the Bandai Namco set; ``experiments/bvh_fk_check.py`` runs every frame of every file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from refimpl.bvh import read_bvh

import bvh_oracle  # noqa: E402  (tests/ is on sys.path under pytest's rootdir-relative imports)

ROOT = Path(__file__).resolve().parents[1]
SHARED_DATA = ROOT.parent / "shared" / "data"


def _files():
    if not SHARED_DATA.is_dir():
        return []
    bandai = sorted((SHARED_DATA / "bandai_namco_locomotion").glob("*.bvh"))[::40]
    other = sorted(p for p in SHARED_DATA.glob("*/*.bvh") if p.parent.name != "bandai_namco_locomotion")
    return other + bandai


def compare(path, frames, mode="auto"):
    """Max distance between refimpl's and the oracle's world positions over the joints refimpl keeps."""
    names, ref = bvh_oracle.world_positions(path, frames)
    motion = read_bvh(path, translations=mode)
    ours = motion.positions()[list(frames)]                               # (T', J', 3)
    idx = [names.index(n) for n in motion.skeleton.names]
    return float(np.max(np.abs(ours - ref[:, idx]))), len(idx), len(names)


@pytest.mark.parametrize("path", _files() or [pytest.param(None, marks=pytest.mark.skip("../shared absent"))],
                         ids=lambda p: p.name if p else "none")
def test_fk_matches_independent_reading(path):
    """Default reading (re-rooted and folded for Bandai Namco) and the raw one ("keep") both give the
    oracle's world positions of every joint they keep (1e-9 relative to the skeleton's size)."""
    frames = range(0, bvh_oracle.parse(path)[1].shape[0], 7)
    scale = 1e-9 * 300
    err, kept, total = compare(path, frames)
    assert err < scale, (path.name, err)
    err_keep, kept_keep, _ = compare(path, frames, "keep")
    assert err_keep < scale and kept_keep == total
    if path.parent.name == "bandai_namco_locomotion":
        assert kept == total - 1                                           # joint_Root removed, Hips the root


def test_oracle_replaces_offsets_small(tmp_path):
    """The oracle and refimpl agree on a hand file with 6 channels everywhere and translations that vary."""
    text = ("HIERARCHY\nROOT R\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\nJOINT A\n{\nOFFSET 1 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation "
            "Yrotation\nJOINT B\n{\nOFFSET 0 2 0\nCHANNELS 6 Xposition Yposition Zposition Xrotation Yrotation "
            "Zrotation\nEnd Site\n{\nOFFSET 0 1 0\n}\n}\n}\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n"
            "0 0 0 0 0 0 5 6 7 10 20 30 0 3 0 40 50 60\n"
            "0 0 0 0 0 0 5 6 8 -10 25 30 0 3.5 0 40 -50 60\n")
    path = tmp_path / "v.bvh"
    path.write_text(text)
    names, ref = bvh_oracle.world_positions(path)
    for mode in ("keep", "auto"):
        m = read_bvh(path, translations=mode)
        idx = [names.index(n) for n in m.skeleton.names]
        np.testing.assert_allclose(m.positions(), ref[:, idx], atol=1e-12)
    assert read_bvh(path, translations="keep").translated_joint_names == ("A", "B")
    auto = read_bvh(path)
    assert auto.skeleton.names[0] == "A" and auto.translated_joint_names == ("B",)
