"""Every model the registry exports goes through ``python -m deploy`` (spec/deploy.md §8, §4; issue #24).

* ``export`` / ``run`` / ``info`` for qtg, quaternet (quaternion and dual-quaternion), quaternet-cnn, acrnn,
  quaternet-long and pace, through the one exporter table, with the same files as ``refimpl export``;
* bad invocations: one line on stderr, exit 2 (an option of another model, a bad value) or 3 (missing files);
* every graph's metadata: the ``io`` shapes are the graph's own declared shapes, the representation's size is the
  frame axis, joint data carries a skeleton with units, named extra files exist;
* QuaterNet's sign rule: flipping two joints' quaternions in a prefix leaves the ONNX prediction unchanged, and
  the exported predictor equals the NumPy predictor (which canonicalises) on real frames;
* acRNN's generated BVH keeps the take's centimetres.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

import onnx  # noqa: E402

from deploy.cli import main as deploy_main  # noqa: E402
from refimpl.cli import EXIT_OK, main as refimpl_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "refimpl" / "data" / "sample"
WALK_BVH = SAMPLE / "bvh" / "02_01.bvh"
WALK_TXT = SAMPLE / "expmap" / "test" / "walking" / "walking_1.txt"
SALSA = SAMPLE / "salsa" / "01.bvh"

COMMON = ["--progress-every", "1", "--checkpoint-every", "100"]
TRAIN = {
    "qtg": ["--model", "qtg", "--steps", "3", "--batch-size", "8", "--stride", "8", "--test-fraction", "0.5",
            "--transition-length", "10", "--set", "encoder_sizes=16,8", "--set", "gru_hidden=8",
            "--set", "decoder_sizes=16"],
    "quaternet": ["--model", "quaternet", "--steps", "3", "--batch-size", "6", "--set", "hidden_size=8",
                  "--set", "num_layers=1", "--set", "prefix_length=12", "--set", "target_length=4"],
    "quaternet-dq": ["--model", "quaternet", "--steps", "3", "--batch-size", "6", "--set", "hidden_size=8",
                     "--set", "num_layers=1", "--set", "prefix_length=12", "--set", "target_length=4",
                     "--set", "representation=dual_quaternion"],
    "quaternet-cnn": ["--model", "quaternet-cnn", "--steps", "3", "--batch-size", "6", "--set", "channels=8",
                      "--set", "kernel_sizes=2,2,2", "--set", "dilations=1,2,4", "--set", "skips=0:1",
                      "--set", "prefix_length=8", "--set", "target_length=4"],
    "acrnn": ["--model", "acrnn", "--data", "sample", "--set", "hidden_size=8", "--set", "num_layers=2",
              "--batch-size", "3", "--window-length", "12", "--steps", "3"],
    "quaternet-long": ["--model", "quaternet-long", "--data", "sample", "--set", "hidden_size=8",
                       "--locomotion-prefix", "6", "--locomotion-target", "8", "--batch-size", "4", "--steps", "2"],
    "pace": ["--model", "pace", "--data", "sample", "--steps", "2", "--batch-size", "4", "--pace-chunk-length", "60"],
}


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """``{name: (checkpoint, folder written by python -m deploy export)}`` of tiny trained models."""
    root = tmp_path_factory.mktemp("every_model")
    out = {}
    for name, argv in TRAIN.items():
        run = root / name
        assert refimpl_main(["--blas-threads", "1", "train", *argv, *COMMON, "--out", str(run)]) == EXIT_OK
        assert deploy_main(["export", str(run / "checkpoint.npz"), str(root / f"onnx_{name}")]) == 0
        out[name] = (run / "checkpoint.npz", root / f"onnx_{name}")
    return out


FILES = {"qtg": {"qtg_init.onnx", "qtg_step.onnx", "qtg_rollout.onnx"},
         "quaternet": {"quaternet_init.onnx", "quaternet_step.onnx", "quaternet_predict.onnx"},
         "quaternet-dq": {"quaternet_init.onnx", "quaternet_step.onnx", "quaternet_predict.onnx"},
         "quaternet-cnn": {"quaternet-cnn_window.onnx"},
         "acrnn": {"acrnn_step.onnx", "acrnn_generate.onnx"},
         "quaternet-long": {"quaternet-long_step.onnx", "quaternet-long_h0.npy", "quaternet-long_seed.npy"},
         "pace": {"quaternet-long_pace.onnx"}}


def _graph_shape(value_info) -> list:
    return [d.dim_param if d.dim_param else d.dim_value for d in value_info.type.tensor_type.shape.dim]


def _meta(path) -> dict:
    return {p.key: json.loads(p.value) for p in onnx.load(str(path)).metadata_props}


def test_deploy_export_writes_what_refimpl_export_writes(exported, tmp_path):
    """Same files as ``refimpl export``, and the same graphs (initializers equal)."""
    for name, (ck, folder) in exported.items():
        assert {p.name for p in folder.iterdir()} == FILES[name], name
        ref = tmp_path / name
        assert refimpl_main(["export", "--checkpoint", str(ck), "--out", str(ref), "--no-verify"]) == EXIT_OK
        assert {p.name for p in ref.iterdir()} == FILES[name], name
        if name == "qtg":   # its rollout is a Scan here, unrolled there: equal outputs, test_deploy_contract.py
            continue
        for f in folder.glob("*.onnx"):
            a, b = onnx.load(str(f)), onnx.load(str(ref / f.name))
            wa = {i.name: onnx.numpy_helper.to_array(i) for i in a.graph.initializer}
            wb = {i.name: onnx.numpy_helper.to_array(i) for i in b.graph.initializer}
            assert wa.keys() == wb.keys(), f
            assert all(np.array_equal(wa[k], wb[k]) for k in wa), f


@pytest.mark.parametrize("name", sorted(TRAIN))
def test_metadata_shapes_are_the_graphs(exported, name):
    """Every graph's ``io`` entries are its declared inputs and outputs, in order, with the same shapes; the
    representation's size is the frame axis; joint data has a skeleton with units; named files exist."""
    folder = exported[name][1]
    for f in sorted(folder.glob("*.onnx")):
        m = onnx.load(str(f))
        meta = _meta(f)
        for kind, values in (("inputs", m.graph.input), ("outputs", m.graph.output)):
            declared = [(e["name"], e["shape"]) for e in meta["io"][kind]]
            actual = [(v.name, _graph_shape(v)) for v in values]
            assert declared == actual, (f.name, kind)
            assert all(isinstance(e["meaning"], str) and e["meaning"] for e in meta["io"][kind])
        rep = meta["representation"]
        assert rep.get("name") and rep.get("units") is not None or rep.get("fields"), f.name
        if "size" in rep and meta["model"]["role"] not in ("init", "pace"):
            sizes = {_graph_shape(v)[-1] for v in m.graph.input if v.type.tensor_type.shape.dim}
            assert rep["size"] in sizes, (f.name, rep["size"], sizes)
        if meta["model"]["role"] != "pace":
            sk = meta["skeleton"]
            assert sk is not None and sk.get("units"), f.name
            assert len(sk["names"]) == len(sk["parents"]) == len(sk["offsets"]), f.name
            joints = next(fd["joints"] for fd in rep["fields"] if "joints" in fd) if "fields" in rep and any(
                "joints" in fd for fd in rep["fields"]) else rep.get("num_joints")
            if joints is not None:
                assert len(sk["names"]) == joints, f.name
        for key in ("input_transform", "output_transform"):
            if name != "qtg" or key in meta:
                assert isinstance(meta[key], dict) and meta[key]["summary"], (f.name, key)
        for key in ("initial_state", "seed_clip"):
            state = meta.get(key)
            if isinstance(state, dict):
                arr = np.load(folder / state["file"], allow_pickle=False)
                assert list(arr.shape) == state["shape"] and arr.dtype.name == state["dtype"]


def test_acrnn_metadata_names_the_slots(exported):
    meta = _meta(exported["acrnn"][1] / "acrnn_generate.onnx")
    rep, sk = meta["representation"], meta["skeleton"]
    assert rep["units"] == "m" and sk["units"] == "m" and len(sk["names"]) == 43
    outs = {e["name"]: e for e in meta["io"]["outputs"]}
    assert outs["positions"]["shape"][-2:] == [43, 3] and "metres" in outs["positions"]["meaning"]
    assert "dual quaternion" in outs["joints"]["meaning"]


def test_dual_quaternion_metadata_says_dual_quaternions(exported):
    for f in ("quaternet_step.onnx", "quaternet_predict.onnx"):
        meta = _meta(exported["quaternet-dq"][1] / f)
        text = json.dumps(meta["io"])
        assert "dual quaternion" in text and "unit quaternions (4J)" not in text
        assert meta["representation"]["name"] == "quaternet_dq_frame"
        assert any("current dual quaternions" in s for s in meta["input_transform"]["steps"])


@pytest.mark.parametrize("name", sorted(TRAIN))
def test_run_every_model(exported, tmp_path, name, capsys):
    folder = exported[name][1]
    if name == "qtg":
        argv = [str(WALK_BVH), str(tmp_path / "out.bvh"), "--start", "20"]
    elif name.startswith("quaternet") and name != "quaternet-long":
        argv = [str(WALK_TXT), str(tmp_path / "out.bvh"), "--start", "30", "--frames", "6"]
    elif name == "acrnn":
        argv = [str(SALSA), str(tmp_path / "out.bvh"), "--frames", "12"]
    else:
        meta = _meta(next(folder.glob("*.onnx")))
        F = meta["io"]["inputs"][0]["shape"][-1]
        x = np.random.default_rng(0).standard_normal((2, 9, F)).astype(np.float32)
        np.save(tmp_path / "in.npy", x)
        argv = [str(tmp_path / "in.npy"), str(tmp_path / "out.npy"), "--start", "4"]
    assert deploy_main(["run", str(folder), *argv]) == 0, capsys.readouterr().err
    assert "wrote" in capsys.readouterr().out
    for f in folder.glob("*.onnx"):
        assert deploy_main(["info", str(f)]) == 0
        assert "input_transform" in capsys.readouterr().out


def test_bad_invocations(exported, tmp_path, capsys):
    """One line on stderr; 2 for options, 3 for files."""
    ck, folder = exported["quaternet"]
    cases = [(["export", str(ck), str(tmp_path / "x"), "--compact", "int8"], 2, "--compact"),
             (["run", str(folder), str(WALK_TXT), str(tmp_path / "x.bvh"), "--joints", "salsa"], 2, "--joints"),
             (["export", str(ck), str(tmp_path / "x"), "--model", "nonsense"], 2, "nonsense"),
             (["export", str(tmp_path / "absent.npz"), str(tmp_path / "x")], 3, "absent"),
             (["run", str(tmp_path / "absent"), str(WALK_TXT), str(tmp_path / "x.bvh")], 3, "absent"),
             (["run", str(folder), str(tmp_path / "absent.txt"), str(tmp_path / "x.bvh")], 3, "absent"),
             (["run", str(exported["quaternet-long"][1]), str(WALK_TXT), str(tmp_path / "x.npy")], 3, "npy")]
    for argv, code, word in cases:
        assert deploy_main(argv) == code, argv
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and word in err and "Traceback" not in err, (argv, err)


def _prefix(rng):
    from refimpl.tasks import prediction

    rot = prediction.load_clip(WALK_TXT, "cmu", 1.0 / 60.0)                       # real CMU frames, (F, J, 4)
    starts = rng.integers(0, len(rot) - 12, size=3)
    return np.stack([rot[s:s + 12] for s in starts])                               # (3, 12, J, 4)


def test_sign_flips_do_not_change_the_onnx_prediction(exported):
    """Issue #24: two joints' quaternions negated in the prefix (the same rotations) used to change the ONNX
    prediction by up to 180°; the predict graph now canonicalises, like the NumPy predictor."""
    import onnxruntime as ort

    from refimpl.services import load_trained

    ck, folder = exported["quaternet"]
    s = ort.InferenceSession(str(folder / "quaternet_predict.onnx"), providers=["CPUExecutionProvider"])
    x = _prefix(np.random.default_rng(0))
    B, P, J, _ = x.shape
    flipped = x.copy()
    flipped[:, :5, 3] *= -1
    flipped[:, 7:, 11] *= -1
    a = s.run(None, {"prefix": x.reshape(B, P, -1).astype(np.float32)})[0]
    b = s.run(None, {"prefix": flipped.reshape(B, P, -1).astype(np.float32)})[0]
    assert np.abs(a - b).max() <= 1e-5
    model = load_trained(ck)
    k = a.shape[1]
    ref = model.spec.make_method(model)(flipped, k).reshape(B, k, -1)              # NumPy: canonical prefix
    assert np.abs(a - ref).max() <= 1e-4


def test_sign_rule_numpy_and_graph_match_the_euler_round_trip():
    """The rule without Euler angles equals refimpl's canonical_prefix (Euler round trip + quat_fix)."""
    import onnxruntime as ort

    from deploy.graph import GraphBuilder
    from deploy.models.quaternet_sign import canonical_signs, canonical_signs_graph
    from refimpl.protocols.prediction import canonical_prefix

    rng = np.random.default_rng(1)
    q = rng.standard_normal((40, 6, 5, 4)) * rng.choice([-1.0, 1.0], size=(40, 6, 5, 1))
    q[:4, :, :, 1:] = 0.0                                   # identities and their negations
    q[4:8, 0] = [np.cos(np.pi / 4), 0, np.sin(np.pi / 4), 0]   # gimbal lock (90° about y)
    ref = canonical_prefix(q)
    assert np.abs(canonical_signs(q) - ref).max() <= 1e-12
    g = GraphBuilder("canon")
    x = g.input("x", ["B", "P", 20])
    g.output(canonical_signs_graph(g, x, 5), "y", ["B", "P", 20])
    s = ort.InferenceSession(g.model().SerializeToString(), providers=["CPUExecutionProvider"])
    got = s.run(None, {"x": q.reshape(40, 6, 20).astype(np.float32)})[0].reshape(q.shape)
    assert np.abs(got - ref).max() <= 1e-6
    one = s.run(None, {"x": q[:, :1].reshape(40, 1, 20).astype(np.float32)})[0].reshape(40, 1, 5, 4)
    assert np.abs(one - canonical_prefix(q[:, :1])).max() <= 1e-6


def test_acrnn_bvh_keeps_the_take_units(exported, tmp_path):
    """``refimpl generate --model acrnn`` and ``python -m deploy run`` write the take's centimetres, and both seed
    from frame 1 by default (frame 0 of a salsa take is its reference T-pose)."""
    from refimpl.bvh import read_bvh

    ck, folder = exported["acrnn"]
    a, b = tmp_path / "numpy.bvh", tmp_path / "onnx.bvh"
    assert refimpl_main(["generate", "--model", "acrnn", "--checkpoint", str(ck), "--source", str(SALSA),
                         "--length", "12", "--out", str(a)]) == EXIT_OK
    assert deploy_main(["run", str(folder), str(SALSA), str(b), "--frames", "12"]) == 0
    src = read_bvh(SALSA)
    for path in (a, b):
        m = read_bvh(path)
        j = m.skeleton.names.index(src.skeleton.names[2])
        assert np.allclose(m.skeleton.offsets[j], src.skeleton.offsets[j], atol=1e-3)
        assert np.allclose(m.root_positions[0], src.root_positions[2], atol=1.0)  # seed frame 1 (30 fps) = frame 2 (60 fps)
