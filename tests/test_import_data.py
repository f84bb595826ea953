"""``refimpl import`` reads only the data it needs (spec/import.md §1; issue 35): the prediction task parses one
training file (the longest) instead of the whole Human3.6M / CMU folder, and the checkpoint is the same."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from refimpl.cli import build_parser, main
from refimpl.protocols import prediction_data as PD
from refimpl.registry import MODELS, task_of
from refimpl.weights import import_checkpoint, layout_names

from conftest import SHARED_DATA


def _write_h36m(path, rows: int, seed: int, blank_lines: int = 0):
    values = np.random.default_rng(seed).normal(scale=0.3, size=(rows, 99))
    lines = [",".join(f"{v:.6f}" for v in r) for r in values]
    for k in range(blank_lines):
        lines.insert(1 + k, "  ")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n\n")


@pytest.fixture
def h36m(tmp_path):
    """Training subjects S1, S7 (several actions, S7 eating the longest), test subject S5 (both sub-sequences)."""
    root = tmp_path / "h36m"
    lengths = {("S1", "walking_1"): 150, ("S1", "walking_2"): 140, ("S1", "eating_1"): 160,
               ("S7", "walking_1"): 150, ("S7", "eating_2"): 190, ("S7", "smoking_1"): 120,
               ("S5", "walking_1"): 200, ("S5", "walking_2"): 230}
    for i, ((subject, name), rows) in enumerate(lengths.items()):
        # a file with many blank lines has more lines than S7/eating_2 has rows, but fewer rows
        _write_h36m(root / subject / f"{name}.txt", rows, i, blank_lines=60 if name == "walking_2" else 0)
    return root


def _counting_reader(monkeypatch):
    calls = []
    real = PD.read_expmap

    def read(path, *a, **k):
        calls.append(str(path))
        return real(path, *a, **k)

    monkeypatch.setattr(PD, "read_expmap", read)
    return calls


def test_longest_file_is_the_one_with_most_rows(tmp_path):
    files = []
    for i, (rows, blanks, crlf) in enumerate([(5, 0, False), (7, 9, False), (7, 0, True), (6, 3, False)]):
        p = tmp_path / f"f{i}.txt"
        lines = ["1 2 3"] * rows
        lines[1:1] = [" , "] * blanks                       # blank once commas are spaces
        p.write_bytes(("\r\n" if crlf else "\n").join(lines).encode() + b"\n \n")
        files.append(p)
    assert [PD.expmap_rows(p) for p in files] == [5, 7, 7, 6]
    assert PD.longest_file(files) == 1                      # the first of the two with 7 rows
    assert PD.longest_file(files[2:]) == 0
    with pytest.raises(ValueError):
        PD.longest_file([])


def test_expmap_rows_is_what_the_reader_reads(tmp_path):
    p = tmp_path / "x.txt"
    _write_h36m(p, 37, 0, blank_lines=4)
    assert PD.expmap_rows(p) == PD.read_expmap(p, layout="h36m").num_frames == 37


def test_longest_training_only_parses_one_file_with_every_name_checked(h36m, monkeypatch):
    calls = _counting_reader(monkeypatch)
    data = PD.load_h36m(h36m, longest_training_only=True)
    assert calls == [str(h36m / "S7" / "eating_2.txt")]
    assert [s.key for s in data.train] == ["S7/eating_2_d0", "S7/eating_2_d1"] and data.test == ()
    (h36m / "S1" / "dancing_1.txt").write_text("1\n")
    with pytest.raises(ValueError, match="dancing_1"):
        PD.load_h36m(h36m, longest_training_only=True)


def _h36m_state(data, seed=0):
    spec = MODELS["quaternet"]
    config = spec.make_config(data, ("hidden_size=8",))
    rng = np.random.default_rng(seed)
    return {n: rng.uniform(-0.3, 0.3, s).astype(np.float32)
            for n, s in layout_names(spec, config, "published").values()}


def test_import_parses_one_file_and_writes_the_same_checkpoint(h36m, tmp_path, monkeypatch):
    """`refimpl import` of QuaterNet weights on an H3.6M folder parses one of its 8 files; the checkpoint equals
    the one made from the whole folder (train_datasets), array for array and in its metadata."""
    spec = MODELS["quaternet"]
    args = build_parser().parse_args(["import", "w.npz", "--model", "quaternet", "--out", "c.npz",
                                      "--data", str(h36m)])
    full, _ = task_of(spec).train_datasets(args)
    state = _h36m_state(full)
    np.savez(tmp_path / "w.npz", **state)
    calls = _counting_reader(monkeypatch)
    assert main(["--blas-threads", "1", "import", str(tmp_path / "w.npz"), "--model", "quaternet", "--data",
                 str(h36m), "--set", "hidden_size=8", "--out", str(tmp_path / "c.npz")]) == 0
    assert len(calls) == 1
    few, _ = task_of(spec).import_datasets(args)
    a1, m1 = import_checkpoint(spec, state, "published", full, full, overrides=["hidden_size=8"],
                               source=tmp_path / "w.npz")
    a2, m2 = import_checkpoint(spec, state, "published", few, few, overrides=["hidden_size=8"],
                               source=tmp_path / "w.npz")
    assert m1 == m2 and a1.keys() == a2.keys() and all(np.array_equal(a1[k], a2[k]) for k in a1)


def test_import_refuses_data_without_a_window_as_the_whole_folder_would(h36m):
    """The recipe's check (a training window must fit) sees the longest sequence either way: same message."""
    spec = MODELS["quaternet"]
    args = build_parser().parse_args(["import", "w.npz", "--model", "quaternet", "--out", "c.npz",
                                      "--data", str(h36m)])
    full, _ = task_of(spec).train_datasets(args)
    few, _ = task_of(spec).import_datasets(args)
    state = _h36m_state(full)
    errors = []
    for data in (full, few):
        with pytest.raises(ValueError) as exc:
            import_checkpoint(spec, state, "published", data, data, overrides=["hidden_size=8",
                                                                                "prefix_length=90"])
        errors.append(str(exc.value))
    assert errors[0] == errors[1] and "longest 95" in errors[0]


def test_import_on_the_cmu_folder_parses_one_file(tmp_path, monkeypatch):
    root = SHARED_DATA / "dmgnn_cmu_expmap"
    if not root.is_dir():
        pytest.skip("../shared/data/dmgnn_cmu_expmap is absent")
    spec = MODELS["quaternet"]
    args = build_parser().parse_args(["import", "w.npz", "--model", "quaternet", "--out", "c.npz",
                                      "--data", str(root)])
    full, _ = task_of(spec).train_datasets(args)
    np.savez(tmp_path / "w.npz", **_h36m_state(full))
    calls = _counting_reader(monkeypatch)
    assert main(["--blas-threads", "1", "import", str(tmp_path / "w.npz"), "--model", "quaternet", "--data",
                 str(root), "--set", "hidden_size=8", "--out", str(tmp_path / "c.npz")]) == 0
    assert len(calls) == 1


@pytest.mark.parametrize("model", ["qtg", "quaternet-long", "pace", "acrnn", "quaternet", "quaternet-cnn"])
def test_every_task_imports_the_same_checkpoint_from_its_import_data(model):
    """import_datasets (no held-out side for QTG and the long-term models) gives the checkpoint train_datasets
    gives, on the embedded sample."""
    spec = MODELS[model]
    layout = "published" if spec.published_names is not None else "refimpl"
    args = build_parser().parse_args(["import", "w.npz", "--model", model, "--out", "c.npz"])
    task = task_of(spec)
    train, test = task.train_datasets(args)
    settings = spec.published_settings if layout == "published" else ()
    config = spec.make_config(train, (*settings,))
    rng = np.random.default_rng(0)
    state = {n: rng.uniform(-0.3, 0.3, s).astype(np.float32) for n, s in layout_names(spec, config, layout).values()}
    a1, m1 = import_checkpoint(spec, state, layout, train, test)
    a2, m2 = import_checkpoint(spec, state, layout, *task.import_datasets(args))
    assert m1 == m2 and a1.keys() == a2.keys() and all(np.array_equal(a1[k], a2[k]) for k in a1)


def test_qtg_import_on_bandai_namco_takes_reads_only_the_training_takes(tmp_path, monkeypatch):
    import shutil

    from refimpl.protocols import transition_locomotion as tl

    bn = SHARED_DATA / "bandai_namco_locomotion"
    if not bn.is_dir():
        pytest.skip("../shared/data/bandai_namco_locomotion is absent")
    folder = tmp_path / "bn"
    folder.mkdir()
    for i in (1, 2, 3):
        shutil.copy(bn / f"dataset-2_walk_normal_{i:03d}.bvh", folder)
    monkeypatch.setenv("REFIMPL_CACHE", "off")
    read = []
    real = tl.load_bandai_namco
    monkeypatch.setattr(tl, "load_bandai_namco", lambda path, *a, **k: read.append(path) or real(path, *a, **k))
    args = build_parser().parse_args(["import", "w.npz", "--model", "qtg", "--out", "c.npz", "--data", str(folder)])
    train, test = task_of(MODELS["qtg"]).import_datasets(args)
    assert test is None and sorted(Path(p).name for p in read) == ["dataset-2_walk_normal_002.bvh",
                                                                    "dataset-2_walk_normal_003.bvh"]
    full, _ = task_of(MODELS["qtg"]).train_datasets(args)
    assert np.array_equal(full.root_mean, train.root_mean) and np.array_equal(full.poses, train.poses)
