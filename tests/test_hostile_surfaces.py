"""Issue #28: hostile inputs on the surfaces QuaterNet, locomotion and acRNN added — one test per cause found at
36aec31 (each fails on that commit), plus the size bounds (refimpl/bounds.py) and the per-task checkpoint schemas
(each task's CHECKPOINT_SCHEMA, refimpl/checkpoint_fields.py). spec/cli.md §1.1, spec/robustness.md §9.1, §11.1."""
from __future__ import annotations

import copy

import numpy as np
import pytest

from refimpl.checkpoint import load_checkpoint
from refimpl.errors import BadInputError
from refimpl.services import load_trained
from tests.fuzz import campaign as fc
from tests.fuzz import surfaces as fs

pytest.importorskip("onnxruntime")


@pytest.fixture(scope="module")
def seeds(tmp_path_factory):
    """Tiny checkpoints of the six models and the exports of the new five (``fuzz_surfaces.make_seeds``)."""
    return fs.make_seeds(tmp_path_factory.mktemp("hostile_seeds"))


def _run(argv):
    return fs._main(argv)


def _crafted(seeds, tmp_path, model, **fields):
    arrays, meta = fc._inference_content(load_checkpoint(seeds[model]))
    meta = copy.deepcopy(meta)
    meta["model_config"].update(fields)
    path = tmp_path / f"{model}_crafted.npz"
    fc.write_crafted(path, arrays, meta)
    return path


def _one_error_line(err: str, command: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip() and not ln.startswith(("usage:", " ", "["))]
    prog = f"refimpl {command}" if command else "refimpl"
    assert len(lines) == 1 and lines[0].startswith(f"{prog}: error: "), err
    assert "Traceback" not in err and "Warning" not in err, err
    return lines[0]


# ---------------------------------------------------------------------------------------------------------------
# checkpoints: per-task schemas (silently wrong output, KeyError/TypeError)
# ---------------------------------------------------------------------------------------------------------------

def test_acrnn_labels_that_disagree_are_refused(seeds, tmp_path):
    """An Euler checkpoint relabelled ``positions`` (both 132 values per frame) loaded and generated positions
    decoded as another representation (exit 0); now the loader refuses it naming the fields."""
    path = _crafted(seeds, tmp_path, "acrnn", data_representation="positions")
    with pytest.raises(BadInputError, match="data_representation 'positions' does not match the variant 'euler'"):
        load_trained(path)
    code, err = _run(["generate", "--checkpoint", path, "--source", fs.SALSA, "--length", "3", "--out",
                      tmp_path / "o.bvh"])
    assert code == 3 and str(path) in _one_error_line(err, "generate")
    for fields in ({"row": "dq-all"}, {"variant": "positions"}, {"frame_size": 131}, {"representation": "ortho6d"}):
        with pytest.raises(BadInputError):
            load_trained(_crafted(seeds, tmp_path, "acrnn", **fields))


@pytest.mark.parametrize("model, fields, match", [
    ("quaternet-long", {"rig": "bogus"}, "model_config.rig"),
    ("quaternet-long", {"rig": "bandai_namco"}, "joints of the 'bandai_namco' rig"),
    ("pace", {"rig": "bogus"}, "model_config.rig"),
    ("quaternet-long", {"seed_clip": {"rotations": [[0.0]], "features": []}}, "seed_clip.rotations"),
    ("quaternet-long", {"skeleton": {"parents": [-1]}}, "model_config.skeleton"),
    ("acrnn", {"std": [0.0] * 132}, "model_config.std"),
    ("acrnn", {"mean": [0.0] * 5}, "model_config.mean"),
    ("acrnn", {"skeleton": "x"}, "model_config.skeleton"),
    ("quaternet", {"frame_time": 0}, "model_config.frame_time"),
    ("quaternet", {"dataset": "h36m"}, "num_joints 38 does not match the h36m skeleton's 32"),
    ("quaternet-cnn", {"fps": 25.0}, "does not match frame_time"),
])
def test_task_fields_with_bad_values_are_refused_at_the_file(seeds, tmp_path, model, fields, match):
    """Task fields were checked for presence only: ``rig = "bogus"`` ended as exit 1 ``KeyError: 'bogus'``,
    every ``std`` 0 as "seed: expected finite values"; now ``BadInputError`` naming the file and the field."""
    path = _crafted(seeds, tmp_path, model, **fields)
    with pytest.raises(BadInputError, match=match) as info:
        load_trained(path)
    assert str(path) in str(info.value)


def test_deploy_loaders_raise_only_value_error(seeds, tmp_path):
    """The long-term deploy loader raised ``KeyError``/``TypeError``; every deploy loader now checks the config,
    the task fields and the parameters and raises ``ValueError``."""
    from deploy.models import acrnn_io, quaternet_io, quaternet_long_io

    arrays, meta = fc._inference_content(load_checkpoint(seeds["quaternet-long"]))
    for edit in ({"num_joints": "26"}, {"hidden_size": None}, {"rig": "bogus"}, {"controls_hidden": 1.5}):
        m = copy.deepcopy(meta)
        m["model_config"].update(edit)
        fc.write_crafted(tmp_path / "x.npz", arrays, m)
        with pytest.raises(ValueError):
            quaternet_long_io.load_checkpoint(tmp_path / "x.npz")
    m = copy.deepcopy(meta)
    del m["model_config"]["num_joints"]
    fc.write_crafted(tmp_path / "x.npz", arrays, m)
    with pytest.raises(ValueError, match="num_joints"):
        quaternet_long_io.load_checkpoint(tmp_path / "x.npz")
    with pytest.raises(ValueError, match="data_representation"):
        acrnn_io.load_checkpoint(_crafted(seeds, tmp_path, "acrnn", data_representation="positions"))
    with pytest.raises(ValueError, match="hidden_size"):
        quaternet_io.load_checkpoint(_crafted(seeds, tmp_path, "quaternet", hidden_size="8"))


def test_every_seed_checkpoint_passes_its_task_schema(seeds):
    """The schema accepts what training writes (all six models), and the deploy loaders accept it too."""
    from deploy.models import acrnn_io, quaternet_cnn_io, quaternet_io, quaternet_long_io

    for name in fs.TINY:
        assert load_trained(seeds[name]).spec.name == name
    acrnn_io.load_checkpoint(seeds["acrnn"])
    quaternet_io.load_checkpoint(seeds["quaternet"])
    quaternet_cnn_io.load_checkpoint(seeds["quaternet-cnn"])
    quaternet_long_io.load_checkpoint(seeds["quaternet-long"])
    quaternet_long_io.load_checkpoint(seeds["pace"])


# ---------------------------------------------------------------------------------------------------------------
# unbounded sizes: exit 2 when the options are parsed
# ---------------------------------------------------------------------------------------------------------------

SIZE_CASES = {  # each otherwise valid: only the size is wrong (at 36aec31: hang, memory, or exit 1)
    "seconds": lambda s, o: ["generate", "--model", "quaternet-long", "--checkpoint", s["quaternet-long"], "--pace",
                             s["pace"], "--out", o / "w.bvh", "--seconds", "1e20"],
    "length-quaternet": lambda s, o: ["generate", "--checkpoint", s["quaternet"], "--source", fs.WALK_TXT,
                                      "--source-frame", "20", "--out", o / "p.bvh", "--length", "10000000"],
    "length-acrnn": lambda s, o: ["generate", "--checkpoint", s["acrnn"], "--source", fs.SALSA, "--out", o / "a.bvh",
                                  "--length", "10000000"],
    "samples": lambda s, o: ["eval", "--checkpoint", s["quaternet"], "--samples-per-sequence", "999999999999"],
    "export-T": lambda s, o: ["export", "--checkpoint", s["qtg"], "--out", o / "onnx", "--no-verify",
                              "--transition-length", "100000"],
    "downsample": lambda s, o: ["train", *fs.TINY["quaternet"], "--out", o / "r", "--steps", "1", "--downsample",
                                "99999999999"],
    "loco-prefix": lambda s, o: ["train", *fs.TINY["quaternet-long"], "--out", o / "r", "--steps", "1",
                                 "--locomotion-prefix", "-5"],
    "pace-chunk": lambda s, o: ["train", *fs.TINY["pace"], "--out", o / "r", "--steps", "1", "--pace-chunk-length",
                                "10000000000"],
    "betas": lambda s, o: ["train", *fs.TINY["pace"], "--out", o / "r", "--steps", "1", "--betas", "1.5", "0.9"],
    "context": lambda s, o: ["generate", "--checkpoint", s["qtg"], "--source", fs.WALK_BVH, "--source-frame", "20",
                             "--length", "3", "--out", o / "t.bvh", "--context", "99999999"],
}


@pytest.mark.parametrize("case", sorted(SIZE_CASES))
def test_sizes_beyond_the_bounds_are_usage_errors_at_parse_time(seeds, tmp_path, case):
    """``generate --seconds 1e20`` on a closed path, ``--length 10000000`` (QuaterNet, acRNN), ``eval
    --samples-per-sequence 999999999999``, ``export --transition-length 100000`` hung or exhausted memory; out-of-
    range ``--betas`` was exit 1. Now exit 2 when the options are parsed, before any file is read."""
    argv = SIZE_CASES[case](seeds, tmp_path)
    code, err = _run(argv)
    assert code == 2, err
    assert "argument --" in _one_error_line(err, argv[0])
    assert not any(tmp_path.iterdir())  # nothing written


def test_locomotion_values_are_checked_before_any_work(seeds, tmp_path):
    """``--path circle:r=1e5`` (5.6e7 spline points), ``circle:r=1e-12``, ``--seconds 0.01`` / ``0.04``,
    ``--speed 1e300`` failed deep in generation (exit 1, a NumPy warning, or exit 0 with "nan" statistics)."""
    base = ["generate", "--model", "quaternet-long", "--checkpoint", seeds["quaternet-long"], "--pace", seeds["pace"],
            "--out", tmp_path / "w.bvh"]
    for extra in (["--path", "circle:r=1e5"], ["--path", "circle:r=1e-12"], ["--seconds", "0.01"],
                  ["--seconds", "0.04"], ["--speed", "1e300"], ["--path", "figure8:size=1e9"],
                  ["--path", "line-turn:turn=1e300"]):
        code, err = _run([*base, *extra])
        assert code == 2, (extra, err)
        _one_error_line(err, "generate")
    assert not (tmp_path / "w.bvh").exists()
    code, err = _run([*base, "--seconds", "0.5", "--path", "circle:r=2"])
    assert code == 0, err


@pytest.mark.parametrize("item, field", [
    ("gru_hidden=1" + "0" * 22, "gru_hidden"), ("gru_layers=99999", "gru_layers"),
    ("encoder_sizes=" + ",".join(["8"] * 1500), "encoder_sizes"), ("gru_hidden=20000", "parameters"),
], ids=["huge-int", "layers", "1500-sizes", "parameters"])
def test_set_overrides_are_bounded(item, field, capsys, tmp_path):
    """``--set gru_hidden=10**22`` / ``gru_layers=9999...`` exhausted memory or hung; 1,500 encoder sizes
    trained a checkpoint the loader refuses (exit 0). Now exit 2 before anything is trained."""
    from refimpl.cli import main

    argv = ["train", "--out", str(tmp_path / "run"), "--steps", "1", "--data", str(fs.WALK_BVH), "--set", item]
    assert main(argv) == 2
    assert field in _one_error_line(capsys.readouterr().err, "train")
    assert not (tmp_path / "run" / "checkpoint.npz").exists()


def test_data_fixed_fields_cannot_be_overridden(tmp_path, capsys):
    from refimpl.cli import main

    assert main(["train", "--model", "pace", "--out", str(tmp_path / "p"), "--steps", "1", "--set",
                 "input_size=3"]) == 2
    assert "input_size" in _one_error_line(capsys.readouterr().err, "train")


def test_bounds_table_is_the_one_the_wrappers_use():
    """One table: the QTG runtime's bound is the table's, the options' types read the table."""
    from deploy.models.qtg_io import MAX_TRANSITION_FRAMES
    from refimpl import bounds

    assert MAX_TRANSITION_FRAMES == bounds.BOUNDS["transition_length"].hi == bounds.MAX_TRANSITION_FRAMES
    parse = bounds.bounded_int("frames")
    assert parse(str(bounds.MAX_FRAMES)) == bounds.MAX_FRAMES
    with pytest.raises(Exception, match="expected an integer"):
        parse(str(bounds.MAX_FRAMES + 1))
    for v in (True, 3.0, "3", None, np.float64(3), complex(3)):
        with pytest.raises(ValueError):
            bounds.check_count(v, "k")
    assert bounds.check_count(np.int64(5), "k") == 5 and bounds.check_count(np.array(5), "k") == 5
    assert bounds.check_number(2, "r", "path_metres") == 2.0
    for v in (float("nan"), True, "2", 1e9):
        with pytest.raises(ValueError):
            bounds.check_number(v, "r", "path_metres")


# ---------------------------------------------------------------------------------------------------------------
# runtime wrappers: refuse, don't coerce; bounded counts; ValueError only
# ---------------------------------------------------------------------------------------------------------------

def test_wrappers_refuse_instead_of_coercing(seeds):
    w = fs._Wrappers(seeds)
    with pytest.raises(ValueError, match="k: expected an integer"):
        w.qn.predict(w.prefix, 10**9)          # hung
    with pytest.raises(ValueError, match="k: expected an integer"):
        w.cnn.predict(w.prefix, 3.5)           # truncated to 3
    with pytest.raises(ValueError, match="num_frames"):
        w.acrnn.generate(w.seed, 2.7)          # truncated to 2
    with pytest.raises(ValueError, match="num_frames"):
        w.acrnn.generate(w.seed, 10**9, use_generator=False)
    for spoil in ("str", "bool", "complex", "object", "bytes"):
        with pytest.raises(ValueError):
            w.qn.predict(fs._spoil(w.prefix, spoil), 3)
        with pytest.raises(ValueError):
            w.acrnn.generate(fs._spoil(w.seed, spoil), 2)
        with pytest.raises(ValueError):
            w.pace.pace(fs._spoil(w.pace_x, spoil))
    with pytest.raises(ValueError, match="every dimension"):
        w.qn.predict(w.prefix[:, :0], 2, use_graph=False)   # UnboundLocalError
    with pytest.raises(ValueError, match="seed"):
        w.acrnn.generate(w.seed[:, :0], 2, use_generator=False)  # UnboundLocalError
    with pytest.raises(ValueError, match="state"):
        w.acrnn.step(w.frame, None)                          # TypeError
    with pytest.raises(ValueError, match="batch"):
        w.long.initial_state(True)
    with pytest.raises(ValueError, match="prefix"):
        w.long.rollout(w.long_inputs, 9)                     # IndexError
    out = w.qn.predict(w.prefix.astype(np.float64), np.int64(2), use_graph=False)
    assert out.shape == (2, 2, 38, 4) and np.isfinite(out).all()


def test_qtg_runtime_with_a_list_as_config(seeds, tmp_path):
    """``QTGRuntime.transition`` raised ``AttributeError`` when the metadata's ``config`` was a list; since #36 the
    model is refused when it is loaded (``deploy.runtime``'s metadata checks), with ``ValueError`` naming the field."""
    import onnx

    from deploy.models.qtg_io import Runtime as QTGRuntime

    d = tmp_path / "qtg"
    d.mkdir()
    for f in seeds["onnx:qtg"].glob("*.onnx"):
        m = onnx.load(str(f))
        for p in m.metadata_props:
            if p.key == "model":
                import json
                v = json.loads(p.value)
                v["config"] = [1, 2]
                v.pop("transition_length", None)
                p.value = json.dumps(v)
        if not f.name.endswith("rollout.onnx"):
            onnx.save(m, str(d / f.name))
    with pytest.raises(ValueError, match=r"metadata\['model'\]\['config'\]: expected a JSON object"):
        QTGRuntime.from_dir(d)


# ---------------------------------------------------------------------------------------------------------------
# files named on the command line: exit 3 naming the file (and line)
# ---------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, where", [
    ("x,z\n0,0\n1,nan\n2,2\n", ":3:"), ("x,z\n0,0\n1,\n2,2\n", ":3:"), ("x;z\n0;0\n1;1\n", ""),
    ("0\n1\n2\n", ""), ("x,z\n0,0\n1e30,0\n2,2\n", "point 2"), ("x,z\n0,0\n3.5,1e300\n2,2\n", "too large"),
    (None, ""),
])
def test_bad_path_csv_is_exit_3_naming_the_file(seeds, tmp_path, text, where):
    """A bad path CSV (NaN, missing, ``;``, UTF-16, one column) exited 2, huge coordinates lost the file name."""
    p = tmp_path / "path.csv"
    p.write_bytes("x,z\n0,0\n1,1\n2,3\n".encode("utf-16") if text is None else text.encode())
    code, err = _run(["generate", "--model", "quaternet-long", "--checkpoint", seeds["quaternet-long"], "--pace",
                      seeds["pace"], "--seconds", "0.5", "--path", p, "--out", tmp_path / "w.bvh"])
    line = _one_error_line(err, "generate")
    assert code == 3 and str(p) in line and where in line, err


def test_onnx_folder_must_hold_the_commands_model(seeds, tmp_path):
    """``generate --backend onnx --onnx DIR`` did not check that DIR holds this model (``AttributeError``, or
    onnxruntime's shape error, exit 1)."""
    for other in ("quaternet-long", "qtg", "quaternet"):
        code, err = _run(["generate", "--checkpoint", seeds["acrnn"], "--backend", "onnx", "--onnx",
                          seeds[f"onnx:{other}"], "--source", fs.SALSA, "--length", "3", "--out", tmp_path / "o.bvh"])
        assert code == 3 and str(seeds[f"onnx:{other}"]) in _one_error_line(err, "generate"), err


def test_damaged_onnx_in_a_model_folder_is_exit_3(seeds, tmp_path):
    """A damaged ``.onnx`` escaped as protobuf's ``DecodeError``."""
    import random

    from deploy.metadata import read_metadata

    for seed in range(6):
        d = tmp_path / f"d{seed}"
        fs._damaged_onnx_dir(seeds["onnx:quaternet"], d, random.Random(seed))
        code, err = _run(["generate", "--checkpoint", seeds["quaternet"], "--backend", "onnx", "--onnx", d,
                          "--source", fs.WALK_TXT, "--source-frame", "20", "--length", "3", "--out", tmp_path / "o.bvh"])
        assert code in (0, 3), err
        if code:
            _one_error_line(err, "generate")
    bad = tmp_path / "junk.onnx"
    bad.write_bytes(b"\x0a\xff\xff\xff\xff\x0f")
    with pytest.raises(ValueError, match="not a readable ONNX model"):
        read_metadata(str(bad))


def test_expmap_folder_without_training_sequences_is_exit_3(tmp_path):
    root = tmp_path / "cmu"
    (root / "train").mkdir(parents=True)
    (root / "test").mkdir()
    (root / "test" / "walking_1.txt").write_bytes(fs.WALK_TXT.read_bytes())
    code, err = _run(["train", *fs.TINY["quaternet"], "--data", root, "--out", tmp_path / "run", "--steps", "1"])
    assert code == 3 and str(root) in _one_error_line(err, "train"), err


def test_info_on_a_zero_frame_bvh_and_odd_onnx_metadata(seeds, tmp_path):
    """Left from before: ``refimpl info`` on a valid 0-frame BVH exited 1 (max of an empty array), on an ``.onnx``
    with deeply nested or mistyped metadata exited 1 (plain ``json.loads``, ``TypeError``)."""
    import random

    text = fs.WALK_BVH.read_text()
    p = tmp_path / "empty.bvh"
    p.write_text(text[:text.index("MOTION")] + "MOTION\nFrames: 0\nFrame Time: 0.008333\n")
    code, err = _run(["info", p])
    assert code == 0, err
    src = sorted(seeds["onnx:acrnn"].glob("*.onnx"))[0]
    for seed in range(12):
        q = tmp_path / f"m{seed}.onnx"
        fs._odd_metadata_onnx(src, q, random.Random(seed))
        code, err = _run(["info", q])
        assert code in (0, 3), err
        if code:
            assert str(q) in _one_error_line(err, "info")


# ---------------------------------------------------------------------------------------------------------------
# training never writes what the loader refuses
# ---------------------------------------------------------------------------------------------------------------

def test_diverging_run_names_the_step_and_leaves_a_loadable_checkpoint(tmp_path):
    """``--lr 1e30 --checkpoint-every 1`` left a step-1 checkpoint of 1e30 weights that info/eval/--resume
    refused; a diverging run ended with "pred: contains NaN or inf" naming neither step nor divergence."""
    run = tmp_path / "run"
    code, err = _run(["train", *fs.TINY["quaternet"], "--out", run, "--steps", "4", "--checkpoint-every", "1",
                      "--lr", "1e30"])
    line = _one_error_line(err, "train")
    assert code == 1 and "diverged at step 1" in line, err
    if (run / "checkpoint.npz").exists():
        load_trained(run / "checkpoint.npz")


def test_a_layer_refusing_non_finite_values_is_reported_as_divergence(tmp_path):
    """A ValueError about non-finite values from the forward pass after an update is the divergence, with the
    step (the first step's is a data problem and stays a ValueError)."""
    from refimpl.train import ModelAdapter, OptimConfig, TrainConfig, TrainingDiverged, train

    calls = [0]

    def loss(p, b):
        calls[0] += 1
        if calls[0] == 3:
            raise ValueError("pred: contains NaN or inf")
        return 1.0, {"w": np.ones(2)}

    adapter = ModelAdapter(name="toy", num_examples=2, init_params=lambda g: {"w": np.zeros(2)},
                           get_batch=lambda idx, ctx: idx, loss_and_grads=loss)
    cfg = TrainConfig(steps=5, batch_size=2, checkpoint_path=str(tmp_path / "c.npz"), checkpoint_every=1)
    with pytest.raises(TrainingDiverged, match="diverged at step 3 .*pred: contains NaN or inf.*step 2"):
        train(adapter, OptimConfig(lr=1e-3), cfg, progress=None)
    assert load_checkpoint(tmp_path / "c.npz")[1]["step"] == 2
