"""What `refimpl eval` scores for the transition task (spec/cli.md §5, issue 32 item 5): `--takes`, folders of
Bandai Namco takes (held-out side or whole), `train/` + `test/` folders of any rig, per style and kind."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from refimpl.cli import EXIT_OK, EXIT_USAGE, main
from refimpl.protocols.transition_locomotion import scored_takes

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh"
BN = ROOT.parent / "shared" / "data" / "bandai_namco_locomotion"
TINY = ["--set", "encoder_sizes=8,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=8"]


def _take(content, style, i):
    return Path(f"/x/dataset-2_{content}_{style}_{i:03d}.bvh")


def test_scored_takes_rule():
    both = [_take("walk", "active", i) for i in (1, 2, 3, 11, 12)]
    got, why = scored_takes(both)
    assert got == [_take("walk", "active", 1), _take("walk", "active", 11)] and "held-out" in why
    held = [_take("run", "old", 1), _take("run", "old", 21)]
    assert scored_takes(held)[0] == held and "all 2" in scored_takes(held)[1]
    new = [_take("run", "old", 2), _take("run", "old", 3)]
    assert scored_takes(new)[0] == new
    with pytest.raises(ValueError):
        scored_takes([])
    with pytest.raises(ValueError):
        scored_takes([Path("/x/other.bvh")])


@pytest.fixture(scope="module")
def cmu_model(tmp_path_factory):
    run = tmp_path_factory.mktemp("qtg")
    assert main(["--blas-threads", "1", "train", "--data", str(SAMPLE_BVH / "02_01.bvh"), "--steps", "2", *TINY,
                 "--out", str(run)]) == 0
    return run / "checkpoint.npz"


def test_takes_scores_exactly_the_files(cmu_model, tmp_path, capsys):
    out = tmp_path / "e.json"
    assert main(["eval", "--checkpoint", str(cmu_model), "--takes", str(SAMPLE_BVH / "01_01.bvh"), "--stride", "8",
                 "--json", str(out)]) == EXIT_OK
    err = capsys.readouterr().out
    assert "scoring the 1 files of --takes" in err
    res = json.loads(out.read_text())
    assert res["qtg"]["num_windows"] > 0 and "by_style" not in res["qtg"]      # CMU takes have no style
    assert main(["eval", "--checkpoint", str(cmu_model), "--takes", str(SAMPLE_BVH / "01_01.bvh"),
                 "--data", str(SAMPLE_BVH)]) == EXIT_USAGE


def test_train_test_folder_scores_test_only(cmu_model, tmp_path, capsys):
    """The `train/` files are not read: a broken file there does not matter."""
    (tmp_path / "train").mkdir()
    (tmp_path / "test").mkdir()
    (tmp_path / "train" / "broken.bvh").write_text("HIERARCHY nonsense")
    shutil.copy(SAMPLE_BVH / "01_01.bvh", tmp_path / "test")
    assert main(["eval", "--checkpoint", str(cmu_model), "--data", str(tmp_path), "--stride", "8"]) == EXIT_OK
    assert "files of" in capsys.readouterr().out


@pytest.mark.shared
def test_bandai_namco_folders(tmp_path, capsys):
    """A tiny QTG trained on a train/ + test/ folder of studio takes (the layout --help documents); a folder of
    only held-out takes is scored whole, per style and kind, the same numbers as --takes of the same files."""
    if not BN.is_dir():
        pytest.skip("../shared/data/bandai_namco_locomotion is absent")
    takes = sorted(BN.glob("dataset-2_walk_*_00[1-3].bvh"))[:3]
    layout = tmp_path / "layout"
    (layout / "train").mkdir(parents=True)
    (layout / "test").mkdir()
    shutil.copy(takes[1], layout / "train")
    shutil.copy(takes[2], layout / "train")
    shutil.copy(takes[0], layout / "test")
    run = tmp_path / "run"
    assert main(["--blas-threads", "1", "train", "--data", str(layout), "--steps", "2", "--stride", "16", *TINY,
                 "--out", str(run)]) == EXIT_OK
    held = tmp_path / "held"
    held.mkdir()
    for t in sorted(BN.glob("dataset-2_*_001.bvh"))[:2]:
        shutil.copy(t, held)
    ckpt = str(run / "checkpoint.npz")
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    capsys.readouterr()
    assert main(["eval", "--checkpoint", ckpt, "--data", str(held), "--stride", "8", "--json", str(a)]) == EXIT_OK
    text = capsys.readouterr().out
    assert "all 2 takes" in text and "By style" in text and "By kind" in text
    assert main(["eval", "--checkpoint", ckpt, "--takes", *map(str, sorted(held.iterdir())), "--stride", "8",
                 "--json", str(b)]) == EXIT_OK
    ra, rb = json.loads(a.read_text()), json.loads(b.read_text())
    assert ra == rb
    q = ra["qtg"]["quality"]
    assert set(ra["qtg"]["by_style"]) == set(q["by_style"]) and q["by_kind"]
    for v in q["by_style"].values():
        assert 0.0 <= v["contact_share"] <= 1.0 and v["num_windows"] > 0


def test_format_groups_and_check_groups():
    import numpy as np

    from refimpl.protocols.transition_metrics import check_groups
    from refimpl.protocols.transition_quality import format_groups

    q = {"skate_cm_s": 12.0, "contact_share": 0.5, "num_windows": 3, "ground_truth": {"skate_cm_s": 9.0,
                                                                                      "contact_share": 0.6}}
    res = {"m": {"mean_cm": 1.0, "by_label": {"a": 1.0}, "by_style": {"x": 2.5}, "quality": {"by_style": {"x": q}}}}
    (name, table), = format_groups(res)
    assert name == "style" and "2.50 | 12.0@0.50" in table and "9.0@0.60 [3]" in table
    assert check_groups({"g": ["a", "b"]}, 2)["g"].tolist() == ["a", "b"]
    with pytest.raises(ValueError, match="groups"):
        check_groups({"g": ["a"]}, 2)
