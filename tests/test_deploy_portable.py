"""The portable export target (``--target portable``, deploy/portable.py, spec/deploy.md §13; issue #33).

The models are the tiny trained ones of ``tests/test_deploy_every_model.py`` (its ``exported`` fixture: today's
target); each is exported again with ``--target portable``. Checked:

* the files, and that every portable graph uses only the operators of the Unity Inference Engine 2.2 table
  (``deploy/engines/``), opset 15, float32 / int64 / bool tensors, static shapes at batch 1, no recurrent node,
  no control flow and no subgraph;
* the metadata: as complete as today's (every key), ``io`` equal to the graph's shapes, the ``target`` entry
  (graphs, carried state that names real inputs and outputs with their shapes, the host loop);
* numerics on real frames of the embedded sample: every call of every portable graph equals the same call of
  today's graph (onnxruntime) and the ONNX reference evaluator within 1e-5; the host loops equal the NumPy
  networks; ``python -m deploy run`` and ``info`` on portable folders; the metadata-only consumers.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

import onnx  # noqa: E402

from deploy.cli import main as deploy_main  # noqa: E402
from deploy.portable import FORBIDDEN_OPERATORS, PORTABLE_OPSET, engine_problems, engine_table, operators  # noqa: E402
from deploy.runtime import DeployedModel  # noqa: E402
from refimpl.cli import EXIT_OK, main as refimpl_main  # noqa: E402
from tests.test_deploy_every_model import SALSA, WALK_BVH, WALK_TXT, exported  # noqa: E402,F401  (the fixture)

TOL = 1e-5
#: quaternet-dq's 5-step rollouts: each step decodes and re-normalises dual quaternions and feeds them back, which
#: amplifies float32 rounding step by step (measured on an AVX-512 machine: portable vs today's graph 5e-7 at the
#: first predicted frame, 1.9e-5 at the fifth; today's graph vs NumPy float64 2.7e-5 at the fifth); the first
#: frame is held to TOL.
DQ_ROLLOUT_TOL = 1e-4

PORTABLE_FILES = {"qtg": {"qtg_init.onnx", "qtg_step.onnx"},
                  "qtg-join": {"qtg_init.onnx", "qtg_step.onnx", "qtg_join.onnx"},
                  "quaternet": {"quaternet_init.onnx", "quaternet_step.onnx"},
                  "quaternet-dq": {"quaternet_init.onnx", "quaternet_step.onnx"},
                  "quaternet-cnn": {"quaternet-cnn_window.onnx"},
                  "acrnn": {"acrnn_step.onnx"},
                  "quaternet-long": {"quaternet-long_step.onnx", "quaternet-long_h0.npy", "quaternet-long_seed.npy"},
                  "pace": {"quaternet-long_pace_step.onnx", "quaternet-long_pace_h0.npy"}}


@pytest.fixture(scope="module")
def portable(exported, tmp_path_factory):
    """``{name: folder}``: every model through ``python -m deploy export --target portable``; QTG with the join
    through ``refimpl export --target portable --join inertialize`` (which checks onnxruntime against NumPy)."""
    root = tmp_path_factory.mktemp("portable")
    out = {}
    for name, (ck, _) in exported.items():
        assert deploy_main(["export", str(ck), str(root / name), "--target", "portable"]) == 0, name
        out[name] = root / name
    d = root / "qtg-join"
    assert refimpl_main(["export", "--checkpoint", str(exported["qtg"][0]), "--out", str(d), "--target", "portable",
                         "--join", "inertialize"]) == EXIT_OK
    out["qtg-join"] = d
    return out


def _meta(path) -> dict:
    return {p.key: json.loads(p.value) for p in onnx.load(str(path)).metadata_props}


def _shape(v) -> list:
    return [d.dim_param if d.dim_param else d.dim_value for d in v.type.tensor_type.shape.dim]


def test_files(portable):
    for name, folder in portable.items():
        assert {p.name for p in folder.iterdir()} == PORTABLE_FILES[name], name


def test_every_graph_fits_the_unity_table(portable):
    """Operators in the engine's table, opset <= its max (15), tensor types float32/int64/bool, static shapes at
    batch 1, none of GRU/LSTM/RNN/Scan/Loop/If, no subgraph."""
    table = engine_table("unity-inference-engine-2.2")
    assert table["max_opset"] == PORTABLE_OPSET and "GRU" in table["unsupported"] and "Scan" in table["unsupported"]
    seen = set()
    for folder in portable.values():
        for f in sorted(folder.glob("*.onnx")):
            m = onnx.load(str(f))
            ops = operators(m)
            seen |= ops
            assert not ops & set(FORBIDDEN_OPERATORS), f
            assert engine_problems(m) == [], (f, engine_problems(m))
            assert [(o.domain, o.version) for o in m.opset_import] == [("", PORTABLE_OPSET)], f
            for v in list(m.graph.input) + list(m.graph.output):
                assert all(isinstance(d, int) and d >= 1 for d in _shape(v)), (f, v.name, _shape(v))
    assert {"MatMul", "Sigmoid", "Tanh", "Split"} <= seen


def test_engine_problems_can_fail(exported):
    """The check refuses today's graphs (GRU, Scan, opset 17): the test above can fail."""
    m = onnx.load(str(exported["quaternet"][1] / "quaternet_predict.onnx"))
    problems = engine_problems(m)
    assert any("GRU" in p for p in problems) and any("opset 17" in p for p in problems)


def test_portable_model_refuses_what_it_cannot_make_portable():
    """``portable_model`` refuses a GRU node, another opset and a symbolic dimension without a size; it fixes the
    batch, records its axes and leaves the input model alone; ``check_target`` refuses an unknown target."""
    from deploy.graph import GraphBuilder
    from deploy.gru import gru_step
    from deploy.metadata import build_metadata, io_entries
    from deploy.portable import builder_options, check_target, is_portable, portable_model
    from refimpl.nn import gru_init

    params = gru_init(np.random.default_rng(0), input_size=3, hidden_size=4, num_layers=1, prefix="rnn")

    def model(**kw):
        g = GraphBuilder("t", **kw)
        x, h = g.input("x", ["B", 3]), g.input("h", [1, "B", 4])
        y, h_new = gru_step(g, x, h, params, "rnn", name="rnn")
        g.output(y, "y", ["B", 4])
        g.output(h_new, "h_new", [1, "B", 4])
        io = {"inputs": io_entries(("x", ["B", 3], "x"), ("h", [1, "B", 4], "h")),
              "outputs": io_entries(("y", ["B", 4], "y"), ("h_new", [1, "B", 4], "h"))}
        return g.model(metadata=build_metadata(g, name="t", role="step", config={}, io=io, representation={}))

    with pytest.raises(ValueError, match="forbidden"):
        portable_model(model(opset=PORTABLE_OPSET), host_loop={})              # fused GRU node
    with pytest.raises(ValueError, match="opset"):
        portable_model(model(primitive=True), host_loop={})                   # opset 17
    m = model(**builder_options())
    p = portable_model(m, host_loop={"loop": ["y, h = step(x, h)"]})
    meta = {q.key: json.loads(q.value) for q in p.metadata_props}
    assert is_portable(meta) and meta["target"]["batch_axes"] == {"x": 0, "h": 1, "y": 0, "h_new": 1}
    assert meta["io"]["inputs"][1]["shape"] == [1, 1, 4] and _shape(p.graph.input[1]) == [1, 1, 4]
    assert _shape(m.graph.input[1]) == [1, "B", 4] and not is_portable({})
    g = GraphBuilder("w", **builder_options())
    g.output(g.node("Relu", [g.input("x", ["B", "W"])], "r"), "y", ["B", "W"])
    with pytest.raises(ValueError, match="'W'"):
        portable_model(g.model(metadata={"io": {"inputs": [], "outputs": []}, "exporter": {}}), host_loop={})
    with pytest.raises(ValueError, match="target"):
        check_target("unity")


#: What the portable graphs use outside onnxruntime-web's WebGPU kernel table (deploy/engines/), by design:
#: Max and Min (primitive LeakyRelu, the eps of the normalisations, QTG's join), And (the join's masks).
WEBGPU_GAPS = {"Max", "Min", "And"}


def test_webgpu_table(portable):
    for folder in portable.values():
        for f in sorted(folder.glob("*.onnx")):
            gaps = {p.split()[1] for p in engine_problems(onnx.load(str(f)), "onnxruntime-web-webgpu")}
            assert gaps <= WEBGPU_GAPS, (f, gaps)


def test_metadata_is_as_complete_as_today(exported, portable):
    for name, folder in portable.items():
        today = exported["qtg" if name == "qtg-join" else name][1]
        for f in sorted(folder.glob("*.onnx")):
            m, meta = onnx.load(str(f)), _meta(f)
            counterpart = today / f.name
            if counterpart.is_file() and name != "qtg-join":   # (qtg-join: refimpl export, other extras)
                assert set(_meta(counterpart)) | {"target"} == set(meta), f
            for kind, values in (("inputs", m.graph.input), ("outputs", m.graph.output)):
                assert [(e["name"], e["shape"]) for e in meta["io"][kind]] == [(v.name, _shape(v)) for v in values]
            t = meta["target"]
            assert t["name"] == "portable" and t["opset"] == PORTABLE_OPSET and t["batch"] == 1
            assert meta["exporter"]["target"] == "portable" and meta["exporter"]["opset"] == PORTABLE_OPSET
            loop = t["host_loop"]
            assert loop["summary"] and loop["loop"] and set(loop["graphs"]) <= {p.name for p in folder.iterdir()}
            ins = {v.name: _shape(v) for v in m.graph.input}
            outs = {v.name: _shape(v) for v in m.graph.output}
            produced = {v.name: _shape(v) for g in loop["graphs"] for v in onnx.load(str(folder / g)).graph.output}
            read = [s for s in loop["state"] if s["input"] in ins]
            assert read or f.name not in loop["graphs"][-1:] or name.startswith("qtg"), f
            for s in read:                    # this graph reads the state: its shape, and where it comes back
                assert ins[s["input"]] == s["shape"], (f, s)
                assert s["output"] is None or produced.get(s["output"]) == s["shape"], (f, s)
                assert s["initial"]
            assert set(t["batch_axes"]) <= set(ins) | set(outs)


# ------------------------------------------------------------------------------------------------- numerics
class _Recorder:
    """Records the feeds of ``DeployedModel.run`` per graph name (the portable graphs' real inputs)."""

    def __init__(self, monkeypatch):
        self.calls: dict[str, list] = {}
        original = DeployedModel.run

        def run(model, feeds=None, **kw):
            given = {**dict(feeds or {}), **kw}
            out = original(model, given)
            batch1 = model._portable_batch(given) == 1      # (a batch is run sample by sample: those are recorded)
            if batch1 and len(self.calls.setdefault(model.metadata["model"]["role"], [])) < 4:
                self.calls[model.metadata["model"]["role"]].append(({k: np.asarray(v) for k, v in given.items()},
                                                                    out))
            return out
        monkeypatch.setattr(DeployedModel, "run", run)


def _check_calls(calls, portable_dir, today_dir, prefix):
    """Each recorded call of a portable graph: the ONNX reference evaluator and today's graph (same feeds, in
    onnxruntime) give the same outputs within TOL."""
    from onnx.reference import ReferenceEvaluator

    from deploy.runtime import load_model

    checked = 0
    for role, records in calls.items():
        f = portable_dir / f"{prefix}_{role}.onnx"
        ref = ReferenceEvaluator(onnx.load(str(f)))
        today = today_dir / f"{prefix}_{role}.onnx"
        other = load_model(today) if today.is_file() else None
        for feeds, out in records:
            feeds = {k: np.asarray(v, np.float32) for k, v in feeds.items()}
            names = [o.name for o in onnx.load(str(f)).graph.output]
            got = dict(zip(names, ref.run(None, feeds)))
            for k in out:
                assert np.abs(got[k] - out[k]).max() <= TOL, (role, k, "reference evaluator")
            if other is not None:
                o2 = other.run(feeds)
                for k in out:
                    assert np.abs(o2[k] - out[k]).max() <= TOL, (role, k, "today's graph")
            checked += 1
    assert checked >= 1
    return checked


def _numpy(ck):
    from refimpl.services import load_trained

    model = load_trained(ck)
    return model, model.spec.make_method(model)


def _qtg_windows(T):
    from refimpl.protocols.transition import TransitionSource, load_source, make_windows

    _, clips = load_source(TransitionSource(str(WALK_BVH), "cmu_bvh", 120.0, "walk"), fps=30)
    rot, pos = clips[0]
    w = np.concatenate([make_windows(rot[[s - 1, s, s + T + 1, s + T + 2]], pos[[s - 1, s, s + T + 1, s + T + 2]],
                                     length=4) for s in (20, 60)])
    return w[:, :2], w[:, 2:]                                                        # (2, 2, P) each, raw


def _unit(poses):
    """The output transform's last step: every quaternion of ``poses (..., 3 + 4J)`` divided by its norm."""
    q = poses[..., 3:].reshape(poses.shape[:-1] + (-1, 4))
    return np.concatenate([poses[..., :3], (q / np.linalg.norm(q, axis=-1, keepdims=True)).reshape(
        poses.shape[:-1] + (-1,))], axis=-1)


@pytest.mark.parametrize("name", ["qtg", "qtg-join"])
def test_qtg_numerics(exported, portable, monkeypatch, name):
    from deploy.models.qtg_io import Runtime as QTGRuntime
    from refimpl.protocols.transition_join import inertialize_joins

    ck, today = exported["qtg"]
    model, method = _numpy(ck)
    T = model.config.transition_length
    past, target = _qtg_windows(T)
    rec = _Recorder(monkeypatch)
    got = QTGRuntime.from_dir(portable[name]).transition(past, target)               # (2, T, P), host loop
    ref = np.asarray(method(past, target, T))
    if name == "qtg-join":
        meta = _meta(portable[name] / "qtg_join.onnx")["join"]
        ref = inertialize_joins(past, ref, target, dt=meta["frame_time"], blend_frames=meta["blend_frames"])
    assert got.shape == ref.shape and np.abs(_unit(got) - ref).max() <= 1e-4
    _check_calls(rec.calls, portable[name], today, "qtg")
    if name == "qtg":
        monkeypatch.undo()
        rollout = QTGRuntime.from_dir(today).transition(past, target)
        assert np.abs(got - rollout).max() <= TOL


def _method_of(runtime, ck):
    from refimpl.services import load_trained
    from refimpl.registry import task_of

    return task_of(load_trained(ck).spec).onnx_method(runtime)


def _prefix():
    from tests.test_deploy_consumers import _prefix as real_prefix

    return real_prefix()


@pytest.mark.parametrize("name", ["quaternet", "quaternet-dq", "quaternet-cnn"])
def test_prediction_numerics(exported, portable, monkeypatch, name):
    from refimpl.services import onnx_method

    ck, today = exported[name]
    _, method = _numpy(ck)
    x = _prefix()                                                                    # (3, 12, J, 4) real frames
    rec = _Recorder(monkeypatch)
    got = onnx_method(portable[name])(x, 5)              # the prediction task's ONNX method: the host loop
    ref = method(x, 5)
    # the DQ network is sensitive to float32 rounding (test_deploy_consumers.py): NumPy's float32 and float64
    # differ by ~1e-3 in its decoded rotations; the portable graph equals today's graph within TOL below
    assert np.abs(got - ref).max() <= (5e-3 if name == "quaternet-dq" else 1e-4)
    prefix = "quaternet-cnn" if name == "quaternet-cnn" else "quaternet"
    _check_calls(rec.calls, portable[name], today, prefix)
    monkeypatch.undo()
    from deploy.models import runtime_for_dir

    rt = runtime_for_dir(today)
    rt.predict_model = None                              # today's init + step loop (not its predict graph)
    today_got = _method_of(rt, ck)(x, 5)
    assert np.abs(got[:, 0] - today_got[:, 0]).max() <= TOL                 # one step: the graphs' numerics
    assert np.abs(got - today_got).max() <= (DQ_ROLLOUT_TOL if name == "quaternet-dq" else TOL)


def test_acrnn_numerics(exported, portable, monkeypatch):
    from deploy.models import runtime_for_dir
    from refimpl.protocols import synthesis

    ck, today = exported["acrnn"]
    model, method = _numpy(ck)
    frames = synthesis.motion_to_frames(model.extra["data_representation"], synthesis.load_salsa_motion(SALSA))
    seed = np.stack([frames[1:11], frames[30:40]])                                   # (2, 10, F) raw, metres
    rec = _Recorder(monkeypatch)
    got = runtime_for_dir(portable["acrnn"]).generate(seed, 12)
    ref = np.asarray(method(seed, 12), np.float64)
    assert np.all(np.abs(got - ref) <= 1e-4 * np.maximum(1.0, np.abs(ref)))
    _check_calls(rec.calls, portable["acrnn"], today, "acrnn")
    monkeypatch.undo()
    assert np.all(np.abs(got - runtime_for_dir(today).generate(seed, 12)) <= TOL * np.maximum(1.0, np.abs(ref)))


def test_long_term_numerics(exported, portable, monkeypatch):
    from deploy.models import runtime_for_dir
    from refimpl.protocols.locomotion import evaluation_windows
    from refimpl.tasks import locomotion

    ck, today = exported["quaternet-long"]
    model, method = _numpy(ck)
    ds = locomotion.load_eval_data("sample", model.extra)
    inputs, _, _ = evaluation_windows(ds)
    x = np.asarray(inputs[:2])
    rec = _Recorder(monkeypatch)
    rot, tr = runtime_for_dir(portable["quaternet-long"]).rollout(x, ds.prefix)
    r_rot, r_tr = method(x, ds.prefix)
    assert np.abs(rot - r_rot).max() <= 1e-3 and np.abs(tr - r_tr).max() <= 1e-3
    _check_calls(rec.calls, portable["quaternet-long"], today, "quaternet-long")
    monkeypatch.undo()
    t_rot, t_tr = runtime_for_dir(today).rollout(x, ds.prefix)
    assert np.abs(rot - t_rot).max() <= TOL and np.abs(tr - t_tr).max() <= TOL


def test_pace_numerics(exported, portable, monkeypatch):
    """The pace network's host loop (both directions, K points per call) equals today's bidirectional graph
    and NumPy; each call equals the reference evaluator."""
    from deploy.models import runtime_for_dir
    from refimpl.splines import circle_path

    ck, today = exported["pace"]
    _, method = _numpy(ck)
    sp = circle_path(6.0).reparameterize(5.0, 1.0)
    x = np.stack([sp.track("turning_angle")[:, 0], np.full(len(sp.track("turning_angle")), 0.5)], -1)[None]
    rec = _Recorder(monkeypatch)
    got = runtime_for_dir(portable["pace"]).pace(x)
    monkeypatch.undo()
    assert np.abs(got - runtime_for_dir(today).pace(x)).max() <= TOL
    ref = method(circle_path(6.0), 0.5)
    assert np.abs(np.maximum(got[0, :, 0], 0.1) - ref.track("amplitude")[:, 0]).max() <= TOL
    _check_calls(rec.calls, portable["pace"], today, "quaternet-long")


def test_pace_chunk_boundaries(exported, portable, monkeypatch):
    """Paths of 1, K - 1, K, K + 1 and 3K + 1 points (K points per call, from the metadata): the portable host
    loop equals today's bidirectional graph and the NumPy network (``refimpl.models.pace.forward``) within 1e-5
    on real pace inputs (a circle's turning angles, repeated); the four calls of the 3K + 1 path (the last one
    padded with K - 1 zeros) equal the reference evaluator; a chunk's last point changes none of the outputs
    before it in either direction (causal: the zero padding cannot change a real output)."""
    from deploy.models import runtime_for_dir
    from refimpl.models import pace
    from refimpl.splines import circle_path

    ck, today = exported["pace"]
    model, _ = _numpy(ck)
    params = {k: np.asarray(v, np.float64) for k, v in model.params.items()}
    rt, rt_today = runtime_for_dir(portable["pace"]), runtime_for_dir(today)
    K = int(rt.pace_step_model.metadata["points_per_call"])
    shapes = {i["name"]: i["shape"] for i in rt.pace_step_model.metadata["io"]["inputs"]}
    assert K > 1 and shapes["x_forward"] == shapes["x_backward"] == [1, K, 2]
    angle = circle_path(6.0).reparameterize(5.0, 1.0).track("turning_angle")[:, 0]
    x_all = np.stack([np.resize(angle, 3 * K + 1), np.linspace(0.3, 0.9, 3 * K + 1)], -1)[None].astype(np.float32)
    for n in (1, K - 1, K, K + 1, 3 * K + 1):
        x = x_all[:, :n]
        rec = _Recorder(monkeypatch)
        got = rt.pace(x)
        monkeypatch.undo()
        ref, _ = pace.forward(params, model.config, x.astype(np.float64))
        assert got.shape == (1, n, 4)
        assert np.abs(got - rt_today.pace(x)).max() <= TOL, n
        assert np.abs(got - ref).max() <= TOL, n
        assert len(rec.calls["pace_step"]) == -(-n // K)
    assert _check_calls(rec.calls, portable["pace"], today, "quaternet-long") == 4
    step, h0 = rt.pace_step_model, rt.pace_h0
    feeds = {"x_forward": x_all[:, :K], "h_forward": h0[0:1], "x_backward": x_all[:, K:2 * K], "h_backward": h0[1:2]}
    other = {**feeds, "x_forward": feeds["x_forward"].copy(), "x_backward": feeds["x_backward"].copy()}
    other["x_forward"][:, -1], other["x_backward"][:, -1] = 5.0, -5.0     # the last point of each direction
    a, b = step.run(feeds), step.run(other)
    for k in ("y_forward", "y_backward"):
        assert np.array_equal(a[k][:, :K - 1], b[k][:, :K - 1]) and not np.allclose(a[k][:, -1], b[k][:, -1]), k


# ----------------------------------------------------------------------------------------- command line
def test_deploy_run_and_info_on_portable_folders(exported, portable, tmp_path, capsys):
    assert deploy_main(["run", str(portable["qtg-join"]), str(WALK_BVH), str(tmp_path / "t.bvh"), "--start", "40"]) == 0
    assert deploy_main(["run", str(portable["quaternet"]), str(WALK_TXT), str(tmp_path / "q.npy"), "--start", "30",
                        "--frames", "4"]) == 0
    assert np.load(tmp_path / "q.npy").shape[0] == 4
    assert deploy_main(["run", str(portable["quaternet-cnn"]), str(WALK_TXT), str(tmp_path / "c.bvh"),
                        "--start", "30", "--frames", "4"]) == 0
    assert deploy_main(["run", str(portable["acrnn"]), str(SALSA), str(tmp_path / "a.npy"), "--frames", "6"]) == 0
    assert deploy_main(["run", str(portable["quaternet-long"]), "circle:r=3", str(tmp_path / "w.npy"),
                        "--pace", str(portable["pace"]), "--seconds", "1"]) == 0
    today_walk = tmp_path / "w_today.npy"
    assert deploy_main(["run", str(exported["quaternet-long"][1]), "circle:r=3", str(today_walk),
                        "--pace", str(exported["pace"][1]), "--seconds", "1"]) == 0
    a, b = np.load(tmp_path / "w.npy"), np.load(today_walk)
    assert a.shape == b.shape and np.abs(a - b).max() <= 1e-4
    capsys.readouterr()
    assert deploy_main(["info", str(portable["qtg"] / "qtg_step.onnx")]) == 0
    text = capsys.readouterr().out
    assert '"name": "portable"' in text and "hidden (2, 1," in text or "hidden (" in text


def test_portable_window_needs_the_receptive_field(portable):
    from deploy.models import runtime_for_dir

    rt = runtime_for_dir(portable["quaternet-cnn"])
    short = _prefix()[:1, :rt.receptive_field - 1]
    with pytest.raises(ValueError, match="at least"):
        rt.predict(short, 2)


def test_default_target_is_unchanged(exported, tmp_path):
    """``--target default`` writes exactly what no option writes."""
    ck = exported["quaternet"][0]
    assert deploy_main(["export", str(ck), str(tmp_path / "a")]) == 0
    assert deploy_main(["export", str(ck), str(tmp_path / "b"), "--target", "default"]) == 0
    for f in (tmp_path / "a").iterdir():
        assert f.read_bytes() == (tmp_path / "b" / f.name).read_bytes()


def test_bad_target_and_portable_compact(exported, tmp_path, capsys):
    ck = exported["qtg"][0]
    with pytest.raises(SystemExit) as e:
        deploy_main(["export", str(ck), str(tmp_path / "x"), "--target", "unity"])
    assert e.value.code == 2
    assert deploy_main(["export", str(ck), str(tmp_path / "y"), "--target", "portable", "--compact", "int8"]) == 2
    assert "portable" in capsys.readouterr().err


# -------------------------------------------------------------------------------------------- consumers
def test_consumers_on_portable_graphs(exported, portable):
    """The metadata-only consumers (tests/consumers/) on the portable graphs, one sequence per call (batch 1)."""
    from tests.consumers import acrnn, quaternet, quaternet_cnn, quaternet_dq, quaternet_long

    x = _prefix()
    for name, mod in (("quaternet", quaternet), ("quaternet-cnn", quaternet_cnn)):
        _, method = _numpy(exported[name][0])
        got = np.concatenate([mod.predict(portable[name], x[b:b + 1], 5) for b in range(len(x))])
        assert np.abs(got - method(x, 5)).max() <= 1e-4, name
    _, method = _numpy(exported["quaternet-dq"][0])
    got = np.concatenate([quaternet_dq.predict_steps(portable["quaternet-dq"], x[b:b + 1], 5) for b in range(len(x))])
    today = quaternet_dq.predict_steps(exported["quaternet-dq"][1], x, 5)
    assert np.abs(got[:, 0] - today[:, 0]).max() <= TOL and np.abs(got - today).max() <= DQ_ROLLOUT_TOL
    assert np.abs(got - method(x, 5)).max() <= 5e-3
    from refimpl.protocols.locomotion import evaluation_windows
    from refimpl.tasks import locomotion

    model, method = _numpy(exported["quaternet-long"][0])
    ds = locomotion.load_eval_data("sample", model.extra)
    w = np.asarray(evaluation_windows(ds)[0][:2])
    rot, tr = method(w, ds.prefix)
    ref = np.concatenate([np.asarray(rot).reshape(rot.shape[0], rot.shape[1], -1), tr], axis=-1)
    got = np.concatenate([quaternet_long.rollout(portable["quaternet-long"], w[b:b + 1], ds.prefix) for b in range(2)])
    assert got.shape == ref.shape and np.abs(got - ref).max() <= 1e-3
    from refimpl.protocols import synthesis

    model, method = _numpy(exported["acrnn"][0])
    frames = synthesis.motion_to_frames(model.extra["data_representation"], synthesis.load_salsa_motion(SALSA))
    seed = frames[None, 1:11]
    ref = np.asarray(method(seed, 8), np.float64)
    assert np.all(np.abs(acrnn.generate_loop(portable["acrnn"], seed, 8) - ref) <= 1e-4 * np.maximum(1, np.abs(ref)))


def test_pace_consumer_on_portable_graph(exported, portable):
    """The metadata-only pace consumer (tests/consumers/quaternet_long.py: pace_steps, K from the metadata) equals
    today's consumer and the NumPy pace tracks, on a path of several chunks and on paths of 1, K - 1, K and
    K + 1 points (the head of a figure-8's inputs)."""
    from tests.consumers import quaternet_long
    from refimpl.splines import circle_path, figure_eight_path

    _, pace_method = _numpy(exported["pace"][0])
    path = circle_path(6.0)
    sp = path.reparameterize(5.0, 1.0)
    K = _meta(portable["pace"] / "quaternet-long_pace_step.onnx")["points_per_call"]
    assert len(sp.track("turning_angle")) > 2 * K                  # several chunks, the last one padded
    got = quaternet_long.pace_steps(portable["pace"], sp.track("turning_angle")[:, 0], 0.5, sp.track("tangent"))
    ref = pace_method(path, 0.5)
    assert np.abs(got["amplitude"] - ref.track("amplitude")[:, 0]).max() <= 1e-5
    assert np.abs(got["facing"] - ref.track("direction")).max() <= 1e-5
    f8 = figure_eight_path(8.0).reparameterize(5.0, 1.0)
    angle, tangent = f8.track("turning_angle")[:, 0], f8.track("tangent")
    for n in (1, K - 1, K, K + 1):
        got = quaternet_long.pace_steps(portable["pace"], angle[:n], 0.7, tangent[:n])
        today = quaternet_long.pace(exported["pace"][1], angle[:n], 0.7, tangent[:n])
        for k in ("amplitude", "frequency", "facing"):
            assert got[k].shape[0] == n and np.abs(got[k] - today[k]).max() <= 1e-5, (n, k)


def test_bench_portable_helpers():
    """benchmarks/bench_portable.py's importable pieces (no timing asserted): both targets of a tiny model, one
    per-frame call each, a row with the ratio, and the table."""
    import importlib.util

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_portable.py"
    spec = importlib.util.spec_from_file_location("bench_portable", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    result = bench.bench(rounds=2, min_time=0.001, quick=True, models=("quaternet", "pace"), pace_chunks=(3,))
    assert set(result["rows"]) == {"quaternet.frame", "pace.point", "pace.point_n1000"}
    assert all(r["ratio_median"] > 0 and r["ratio_paired"] > 0 for r in result["rows"].values())
    assert set(result["pace_chunks"]["3"]) == {"point", "point_n1000", "call", "nodes", "bytes"}
    assert len(result["env"]["load_average_before"]) == 3
    for bad in ("0", "4096"):                          # refused before anything is exported or timed
        with pytest.raises(SystemExit) as e:
            bench.main(["--pace-chunks", bad, "--out", "/nonexistent/x.json"])
        assert e.value.code == 2
    params, cfg, _ = bench.make_model("pace", quick=True)
    from deploy.models.quaternet_long import export_pace, export_pace_step
    from deploy.portable import builder_options
    from deploy.session import make_session
    x = np.random.default_rng(0).normal(size=(11, 2)).astype(np.float32)
    y = bench.pace_host_loop(make_session(export_pace_step(params, cfg, points=4, **builder_options())),
                             np.asarray(params["h0"], np.float32).reshape(2, 1, -1), x, 4)
    assert np.abs(y - make_session(export_pace(params, cfg)).run(None, {"x": x[None]})[0][0]).max() <= TOL
    assert "quaternet.frame" in bench.table(result)
