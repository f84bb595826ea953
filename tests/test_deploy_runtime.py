"""deploy.runtime (session settings, validated loading, metadata, QTGRuntime) and deploy.cli (spec/deploy.md §7-8)."""
from __future__ import annotations

import numpy as np
import onnx
import pytest

import refimpl
from deploy.cli import main
from deploy.graph import GraphBuilder, save_model
from deploy.models.qtg import export_qtg_init, export_qtg_rollout, export_qtg_step
from deploy.models.qtg_io import Runtime as QTGRuntime, export_dir as export_qtg_dir, load_checkpoint as load_qtg_checkpoint
from deploy.runtime import load_model, make_session, make_session_options
from refimpl.bvh import read_bvh
from refimpl.checkpoint import save_checkpoint
from refimpl.models.qtg import QTGConfig, init_params
from refimpl.models.qtg_fast import rollout_forward
from refimpl.testing import TOL_ORT_ROLLOUT, assert_close
from refimpl.protocols.transition import make_windows

SMALL = QTGConfig(pose_size=91, encoder_sizes=(16, 8), gru_hidden=12, decoder_sizes=(16,), transition_length=5)
SAMPLE_BVH = f"{refimpl.__path__[0]}/data/sample/bvh/02_01.bvh"


def _params(config=SMALL):
    return init_params(config, np.random.default_rng(0), dtype=np.float32)


def test_session_options():
    """spec/deploy.md §7: one intra-op thread by default, sequential, no spinning; bad values refused."""
    so = make_session_options()
    assert so.intra_op_num_threads == 1 and so.inter_op_num_threads == 1
    assert so.get_session_config_entry("session.intra_op.allow_spinning") == "0"
    assert make_session_options(2).intra_op_num_threads == 2
    for bad in (0, -1, 1.5):
        with pytest.raises(ValueError, match="intra_op_threads"):
            make_session_options(bad)
    with pytest.raises(ValueError, match="optimization"):
        make_session_options(optimization="fast")


def test_session_spinning_option():
    """spec/deploy.md §7: spinning=True allows the intra-op threads to spin; a session made with it runs."""
    so = make_session_options(2, spinning=True)
    assert so.get_session_config_entry("session.intra_op.allow_spinning") == "1"
    with pytest.raises(ValueError, match="spinning"):
        make_session_options(spinning="yes")
    s = make_session(export_qtg_step(_params(), SMALL), intra_op_threads=2, spinning=True)
    assert s.get_session_options().get_session_config_entry("session.intra_op.allow_spinning") == "1"
    dm = load_model(export_qtg_step(_params(), SMALL), intra_op_threads=2, spinning=True)
    assert dm.session.get_session_options().get_session_config_entry("session.intra_op.allow_spinning") == "1"


def test_load_model_validates_and_runs(tmp_path):
    """spec/deploy.md §7: load_model validates, decodes metadata and checks feeds (names, shapes, finiteness)."""
    path = tmp_path / "step.onnx"
    save_model(export_qtg_step(_params(), SMALL), path)
    m = load_model(path)
    assert m.role == "step" and m.metadata["model"]["config"]["gru_hidden"] == 12
    assert [n for n, _, _ in m.inputs] == ["pose", "latent_prev", "hidden", "target_latent"]
    B = 3
    feeds = {"pose": np.zeros((B, 91)), "latent_prev": np.zeros((B, 8)), "hidden": np.zeros((1, B, 12)),
             "target_latent": np.zeros((B, 2, 8))}
    out = m.run(feeds)                                                   # float64 feeds cast to float32
    assert out["pose_next"].shape == (B, 91) and out["hidden_next"].dtype == np.float32
    with pytest.raises(ValueError, match="missing"):
        m.run(pose=feeds["pose"])
    with pytest.raises(ValueError, match="unknown"):
        m.run(dict(feeds, extra=1))
    with pytest.raises(ValueError, match="latent_prev: expected shape"):
        m.run(dict(feeds, latent_prev=np.zeros((B, 9))))
    with pytest.raises(ValueError, match="NaN"):
        m.run(dict(feeds, pose=np.full((B, 91), np.nan)))


def test_load_model_refuses_bad_files(tmp_path):
    """spec/deploy.md §6-7: missing, garbage, checker-rejected and runtime-rejected models raise ValueError."""
    with pytest.raises(ValueError, match="no such file"):
        load_model(tmp_path / "absent.onnx")
    garbage = tmp_path / "garbage.onnx"
    garbage.write_bytes(b"\x08\x01garbage")
    with pytest.raises(ValueError):
        load_model(garbage)
    g = GraphBuilder("t")
    g.output(g.node("Relu", [g.input("x", [2])], "r"), "y", [2])
    bad_op = g.model()
    bad_op.graph.node[0].op_type = "NoSuchOp"
    with pytest.raises(ValueError, match="NoSuchOp"):
        load_model(bad_op)
    new_opset = g.model()
    new_opset.opset_import[0].version = 999
    with pytest.raises(ValueError):
        load_model(new_opset)
    with pytest.raises(ValueError, match="onnxruntime refused"):
        make_session(new_opset)


@pytest.mark.parametrize("key,value", [("model", "[1, 2]"), ("model", "NaN"), ("normalization", "1e999"),
                                       ("frame_rate", "\"30\""), ("skeleton", "[" * 5000 + "]" * 5000)])
def test_metadata_of_wrong_type_or_not_json(key, value):
    """spec/deploy.md §4, §7: metadata must be strict JSON of the documented type; else ValueError naming the key."""
    m = export_qtg_step(_params(), SMALL)
    for e in m.metadata_props:
        if e.key == key:
            e.value = value
    with pytest.raises(ValueError, match=key):
        load_model(m)


def test_qtg_runtime_roles_and_directory(tmp_path):
    """spec/deploy.md §7: QTGRuntime checks each model's role and loads qtg_*.onnx from a directory."""
    params = _params()
    with pytest.raises(ValueError, match="role"):
        QTGRuntime(step=export_qtg_init(params, SMALL))
    with pytest.raises(ValueError, match="no qtg_"):
        QTGRuntime.from_dir(tmp_path)
    save_model(export_qtg_rollout(params, SMALL), tmp_path / "qtg_rollout.onnx")
    rt = QTGRuntime.from_dir(tmp_path)
    assert rt.init_model is None and rt.rollout_model.role == "rollout"
    with pytest.raises(ValueError, match="init"):
        rt.start(np.zeros((1, 2, 91)), np.zeros((1, 2, 91)))
    with pytest.raises(ValueError, match="step"):
        rt.step({})


def test_cli_export_run_info(tmp_path, capsys):
    """spec/deploy.md §8: export a checkpoint, generate a transition inside a BVH clip, print the contract."""
    params = _params()
    ck = tmp_path / "ck.npz"
    save_checkpoint(ck, {f"param.{k}": v for k, v in params.items()},
                    {"model_config": dict(SMALL.to_dict(), dtype="float32")})
    loaded, cfg, _ = load_qtg_checkpoint(ck)
    assert cfg == SMALL and set(loaded) == set(params)
    out = tmp_path / "models"
    assert main(["export", str(ck), str(out), "--root-mean", "0", "90", "0", "--root-std", "30", "5", "30",
                 "--skeleton-bvh", SAMPLE_BVH]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["qtg_init.onnx", "qtg_rollout.onnx", "qtg_step.onnx"]
    assert load_model(out / "qtg_rollout.onnx").metadata["skeleton"]["names"][0] == "Hips"
    bvh = tmp_path / "out.bvh"
    assert main(["run", str(out), SAMPLE_BVH, str(bvh), "--start", "10"]) == 0
    motion = read_bvh(bvh)
    assert motion.num_joints == 22 and abs(motion.fps - 30) < 0.01
    assert "generated frames 10..14" in capsys.readouterr().out
    assert main(["info", str(out / "qtg_step.onnx")]) == 0
    printed = capsys.readouterr().out
    assert "hidden_next" in printed and '"model_io": "raw"' in printed and "input_transform: 4 context" in printed
    assert main(["run", str(out), SAMPLE_BVH, str(bvh), "--start", "1"]) == 2
    assert "--start" in capsys.readouterr().err
    assert main(["export", str(tmp_path / "absent.npz"), str(out)]) == 3   # a missing input file (spec/deploy.md §8)
    assert main(["export", str(ck), str(out), "--root-mean", "0", "0", "0"]) == 2


def test_cli_run_reads_only_the_context_frames(tmp_path, capsys):
    """spec/deploy.md §8: ``run`` builds its inputs from frames S−2, S−1, S+T, S+T+1 only (the metadata's
    input_transform): changing the frames it replaces does not change the generated ones."""
    from refimpl.bvh_write import write_bvh
    from refimpl.motion import Motion

    out = tmp_path / "models"
    export_qtg_dir(_params(), SMALL, out, normalization=(np.array([0.0, 0, 0]), np.array([30.0, 10, 30])))
    motion = read_bvh(SAMPLE_BVH)
    rot = np.array(motion.rotations)
    a, b = tmp_path / "a.bvh", tmp_path / "b.bvh"
    write_bvh(a, motion)
    rot[40:60] = rot[0]                                 # 120 fps frames 40..59 = 30 fps frames 10..14
    write_bvh(b, Motion(motion.skeleton, rot, motion.root_positions, motion.frame_time, motion.name))
    results = []
    for src in (a, b):
        dst = tmp_path / f"out_{src.stem}.bvh"
        assert main(["run", str(out), str(src), str(dst), "--start", "10"]) == 0
        results.append(read_bvh(dst).positions()[10:15])
    capsys.readouterr()
    np.testing.assert_array_equal(results[0], results[1])


def test_export_dir_matches_numpy(tmp_path):
    """spec/deploy.md §8: the exported directory reproduces rollout_forward (normalised pose space)."""
    params = _params()
    paths = export_qtg_dir(params, SMALL, tmp_path)
    rng = np.random.default_rng(3)
    past, target = rng.normal(size=(2, 2, 91)).astype(np.float32), rng.normal(size=(2, 2, 91)).astype(np.float32)
    rt = QTGRuntime.from_dir(tmp_path)
    expect, _ = rollout_forward(params, past, target, config=SMALL)
    assert_close(rt.transition(past, target), expect, **TOL_ORT_ROLLOUT, name="exported dir")
    assert all(onnx.load(str(p)).ir_version == 8 for p in paths.values())


def test_export_dir_compact(tmp_path, capsys):
    """spec/deploy.md §8: ``--compact`` writes the compact rollout (same contract; int8 via MatMulNBits) and the
    runtime uses it; float32 compact reproduces rollout_forward; bad combinations are refused."""
    params = _params()
    rng = np.random.default_rng(4)
    past, target = rng.normal(size=(2, 2, 91)).astype(np.float32), rng.normal(size=(2, 2, 91)).astype(np.float32)
    expect, _ = rollout_forward(params, past, target, config=SMALL)
    export_qtg_dir(params, SMALL, tmp_path / "f32", compact="float32")
    assert_close(QTGRuntime.from_dir(tmp_path / "f32").transition(past, target), expect, **TOL_ORT_ROLLOUT,
                 name="compact float32")
    ck = tmp_path / "ck.npz"
    save_checkpoint(ck, {f"param.{k}": v for k, v in params.items()},
                    {"model_config": dict(SMALL.to_dict(), dtype="float32")})
    assert main(["export", str(ck), str(tmp_path / "i8"), "--compact", "int8"]) == 0
    rollout = onnx.load(str(tmp_path / "i8" / "qtg_rollout.onnx"))
    assert any(n.op_type == "MatMulNBits" for n in rollout.graph.node)
    assert load_model(tmp_path / "i8" / "qtg_rollout.onnx").metadata["exporter"]["variant"] == "compact.int8"
    got = QTGRuntime.from_dir(tmp_path / "i8").transition(past, target)
    assert got.shape == expect.shape and np.all(np.isfinite(got))
    assert 0 < np.abs(got - expect).max() < 0.05 * np.abs(expect).max()   # quantised: close, not equal
    with pytest.raises(ValueError, match="compact"):
        export_qtg_dir(params, SMALL, tmp_path / "bad", compact="int2")
    with pytest.raises(ValueError, match="float32 graph"):
        export_qtg_dir(params, SMALL, tmp_path / "bad", compact="int8", dtype=np.float64)
    capsys.readouterr()


def test_to_world_inverts_make_windows():
    """spec/deploy.md §8: window_to_world (deploy run, refimpl generate) undoes make_windows' transform exactly."""
    from refimpl.quat import quat_normalize
    from refimpl.protocols.transition import CMU_22_JOINTS, heading_from_root, subset_22, window_to_world

    motion = read_bvh(SAMPLE_BVH)
    skel, rot = subset_22(motion.skeleton, np.asarray(motion.rotations)[::4], CMU_22_JOINTS)
    pos = np.asarray(motion.root_positions)[::4]
    w = make_windows(rot[20:29], pos[20:29], length=9)[0]                # (9, 91)
    new_pos, new_rot = window_to_world(w, heading_from_root(rot[20, 0]), pos[20])
    assert_close(skel.forward_kinematics(new_rot, new_pos), skel.forward_kinematics(rot[20:29], pos[20:29]),
                 rtol=0, atol=1e-9, name="positions")
    assert np.allclose(np.abs(np.sum(quat_normalize(new_rot) * rot[20:29], -1)), 1.0)


def test_truncated_metadata_is_refused():
    """spec/deploy.md §7: a model carrying some of the documented metadata keys must carry all of them (a file cut
    inside its trailing metadata would otherwise load with keys silently missing)."""
    m = export_qtg_step(_params(), SMALL)
    keep = list(m.metadata_props)[:3]
    del m.metadata_props[:]
    for e in keep:
        m.metadata_props.add(key=e.key, value=e.value)
    with pytest.raises(ValueError, match="missing"):
        load_model(m)
    del m.metadata_props[:]
    assert load_model(m).metadata == {} and load_model(m).role is None   # a foreign model without metadata loads
