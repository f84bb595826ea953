"""The deployment contract (spec/deploy.md §4, §8; deploy/README.md "The model contract").

* ``python -m deploy export`` and ``refimpl export`` of one ``refimpl train`` checkpoint give the same models on raw
  poses (both standardise with the root statistics the checkpoint stores);
* the metadata states the normalisation truthfully and names every quaternion slot (skeleton);
* a consumer written only from the metadata and deploy/README.md — onnxruntime and NumPy, none of refimpl's window
  or transition code — reproduces ``refimpl``'s transition
  (``refimpl.tasks.transition_generate.make_transition``) on a real CMU clip.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

import onnxruntime as ort  # noqa: E402

from deploy.cli import main as deploy_main  # noqa: E402
from refimpl.cli import EXIT_OK, main as refimpl_main  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
WALK_BVH = ROOT / "refimpl" / "data" / "sample" / "bvh" / "02_01.bvh"
TINY = ["--set", "encoder_sizes=16,8", "--set", "gru_hidden=8", "--set", "decoder_sizes=16"]
T = 10


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A ``refimpl train`` checkpoint (tiny QTG, a few steps on 02_01.bvh, T = 10): root statistics stored."""
    out = tmp_path_factory.mktemp("train")
    code = refimpl_main(["train", "--data", str(WALK_BVH), "--out", str(out), "--steps", "4", "--batch-size", "8",
                         "--stride", "8", "--test-fraction", "0.5", "--transition-length", str(T),
                         "--progress-every", "2", *TINY])
    assert code == EXIT_OK
    return out / "checkpoint.npz"


def _session(path):
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    return ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])


def _metadata(session) -> dict:
    """Every ``metadata_props`` entry as JSON, read through onnxruntime only."""
    return {k: json.loads(v) for k, v in session.get_modelmeta().custom_metadata_map.items()}


def test_deploy_export_equals_refimpl_export(checkpoint, tmp_path, capsys):
    """Issue 16: both export commands use the checkpoint's root statistics, so they agree on raw poses (the
    README's ``--compact int8`` line used to write ``normalization: null``)."""
    from refimpl.checkpoint import load_checkpoint

    a, b, c = tmp_path / "deploy", tmp_path / "refimpl", tmp_path / "int8"
    assert deploy_main(["export", str(checkpoint), str(a)]) == 0
    assert deploy_main(["export", str(checkpoint), str(c), "--compact", "int8"]) == 0
    assert refimpl_main(["export", "--checkpoint", str(checkpoint), "--out", str(b)]) == EXIT_OK
    _, meta = load_checkpoint(checkpoint)
    stored_mean, stored_std = meta["model_config"]["root_mean"], meta["model_config"]["root_std"]
    rng = np.random.default_rng(0)
    poses = np.zeros((4, 4, 91), np.float32)
    poses[..., :3] = np.asarray(stored_mean) + np.asarray(stored_std) * rng.standard_normal((4, 4, 3))
    q = rng.standard_normal((4, 4, 22, 4)) * 0.2 + np.array([1.0, 0, 0, 0])
    poses[..., 3:] = (q / np.linalg.norm(q, axis=-1, keepdims=True)).reshape(4, 4, 88)
    feeds = {"past": poses[:, :2], "target": poses[:, 2:]}
    outs = {}
    for name, d in (("deploy", a), ("refimpl", b), ("int8", c)):
        s = _session(d / "qtg_rollout.onnx")
        m = _metadata(s)
        assert m["normalization"]["in_graph"] is True and m["normalization"]["model_io"] == "raw"
        assert np.allclose(m["normalization"]["mean"][:3], stored_mean)
        assert np.allclose(m["normalization"]["std"][:3], stored_std)
        assert m["representation"]["fields"][0]["units"] == "cm"
        assert len(m["skeleton"]["names"]) == 22 and m["skeleton"]["names"][0] == "Hips"
        assert m["frame_rate"] == 30.0 and m["model"]["transition_length"] == T
        outs[name] = s.run(None, feeds)[0]
    assert np.abs(outs["deploy"] - outs["refimpl"]).max() < 1e-3          # cm / quaternion units, float32
    assert np.abs(outs["int8"][..., :3] - outs["refimpl"][..., :3]).max() < 2.0   # int8 weights: small drift
    capsys.readouterr()


def test_root_statistics_options(checkpoint, tmp_path, capsys):
    """``--root-mean/--root-std`` that contradict the checkpoint's statistics are refused (exit 2)."""
    code = deploy_main(["export", str(checkpoint), str(tmp_path / "x"), "--root-mean", "0", "90", "0",
                        "--root-std", "30", "5", "30"])
    assert code == 2 and "differ from the statistics" in capsys.readouterr().err
    assert deploy_main(["export", str(checkpoint), str(tmp_path / "y"), "--root-mean", "0", "90", "0"]) == 2


def test_metadata_states_normalisation_truthfully():
    """spec/deploy.md §4: the root translation is described as centimetres (statistics in the graph) or as
    z-normalised (statistics outside the graph, or none recorded)."""
    from refimpl.models.qtg import QTGConfig, init_params
    from deploy.metadata import read_metadata
    from deploy.models.qtg import export_qtg_step

    cfg = QTGConfig(pose_size=91, encoder_sizes=(8,), gru_hidden=4, decoder_sizes=(8,), transition_length=3)
    params = init_params(cfg, np.random.default_rng(0), dtype=np.float32)
    stats = (np.array([1.0, 90.0, 2.0]), np.array([20.0, 4.0, 25.0]))
    raw = read_metadata(export_qtg_step(params, cfg, normalization=stats))
    outside = read_metadata(export_qtg_step(params, cfg, normalization=stats, normalize_in_graph=False))
    none = read_metadata(export_qtg_step(params, cfg, skeleton=False))
    assert raw["normalization"]["model_io"] == "raw" and "centimetres" in raw["representation"]["fields"][0]["meaning"]
    assert outside["normalization"]["model_io"] == "normalized" and not outside["normalization"]["in_graph"]
    assert "z-normalised" in outside["representation"]["fields"][0]["meaning"]
    assert none["normalization"] is None and "z-normalised" in none["representation"]["fields"][0]["meaning"]
    assert none["skeleton"] is None and raw["skeleton"]["units"] == "cm"
    for m in (raw, outside, none):
        assert "+y" in m["input_transform"]["summary"] and len(m["input_transform"]["steps"]) == 5
        assert m["output_transform"]["steps"]


# ------------------------------------------------------------------------------------------------ the consumer
# Written from deploy/README.md ("The model contract", "Building the inputs") and the metadata only.

def _qmul(a, b):
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def _conj(q):
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _rotate(q, v):
    """Vector part of q (0, v) conj(q)."""
    qv = np.concatenate([np.zeros(v.shape[:-1] + (1,)), v], axis=-1)
    return _qmul(_qmul(q, qv), _conj(q))[..., 1:]


def _consumer_transition(model_path, frames_rot, frames_pos):
    """Inputs from 4 world-space frames (p_-1, p_0, g1, g2) -> generated world-space frames, the metadata's way.

    frames_rot (4, J, 4) local unit quaternions in skeleton.names order, frames_pos (4, 3) root positions, cm.
    """
    session = _session(model_path)
    meta = _metadata(session)
    rot, pos = np.array(frames_rot, np.float64), np.array(frames_pos, np.float64)
    # input_transform step 1: heading of the first frame's root rotation about +y
    w, y = rot[0, 0, 0], rot[0, 0, 2]
    n = np.hypot(w, y)
    h = np.array([w / n, 0.0, y / n, 0.0]) if n > 1e-9 else np.array([1.0, 0, 0, 0])
    # step 2: root relative to the first frame, heading removed
    root = _rotate(_conj(h)[None], pos - pos[0])                           # (4, 3)
    # step 3: root rotation
    rot[:, 0] = _qmul(_conj(h)[None], rot[:, 0])
    # step 4: signs
    rot[0] = np.where(rot[0, :, :1] < 0, -rot[0], rot[0])
    for k in range(1, len(rot)):
        dot = np.sum(rot[k] * rot[k - 1], axis=-1, keepdims=True)
        rot[k] = np.where(dot < 0, -rot[k], rot[k])
    # step 5: flatten; normalise when the graph does not
    poses = np.concatenate([root, rot.reshape(len(rot), -1)], axis=-1)    # (4, P)
    norm = meta["normalization"]
    if norm is not None and not norm["in_graph"]:
        poses = (poses - np.array(norm["mean"])) / np.array(norm["std"])
    out = session.run(["poses"], {"past": poses[None, :2].astype(np.float32),
                                  "target": poses[None, 2:].astype(np.float32)})[0][0].astype(np.float64)
    # output_transform
    if norm is not None and not norm["in_graph"]:
        out = out * np.array(norm["std"]) + np.array(norm["mean"])
    J = len(meta["skeleton"]["names"])
    world_root = _rotate(h[None], out[:, :3]) + pos[0]                    # (T, 3)
    q = out[:, 3:].reshape(len(out), J, 4)
    q[:, 0] = _qmul(h[None], q[:, 0])
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    return world_root, q, meta


@pytest.mark.parametrize("in_graph", [True, False])
def test_consumer_from_metadata_reproduces_refimpl_transition(checkpoint, tmp_path, in_graph):
    """A consumer that knows only the metadata and deploy/README.md reproduces ``refimpl``'s transition
    (``make_transition`` with the NumPy network) on the real CMU clip 02_01.bvh, in world coordinates."""
    from refimpl.recipes.qtg import pose_normalization
    from refimpl.services import load_trained
    from refimpl.tasks.transition_generate import make_transition
    from refimpl.protocols.transition import TransitionSource, load_source
    from deploy.graph import save_model
    from deploy.models.qtg import export_qtg_rollout

    model = load_trained(checkpoint)
    path = tmp_path / "qtg_rollout.onnx"
    save_model(export_qtg_rollout(model.params, model.config, T=T, normalization=pose_normalization(model),
                                  normalize_in_graph=in_graph, frame_rate=model.fps), path)
    meta = _metadata(_session(path))
    # the data: the clip at the model's frame rate, joints reordered by the metadata's names
    skel, clips = load_source(TransitionSource(str(WALK_BVH), "cmu_bvh", 120.0, "walk"), fps=meta["frame_rate"])
    rot, pos = clips[0]
    order = [list(skel.names).index(name) for name in meta["skeleton"]["names"]]
    assert order == list(range(22)) and meta["skeleton"]["parents"] == [int(p) for p in skel.parents]
    rot = rot[:, order]
    s = 40
    g = s + T + 1
    idx = [s - 1, s, g, g + 1]
    got_root, got_rot, _ = _consumer_transition(path, rot[idx], pos[idx])

    ref = make_transition(model.spec.make_method(model), skel, (rot, pos), s, (rot, pos), g, T,
                          frame_time=1.0 / meta["frame_rate"], context=1, align="none", same_clip=True)
    ref_rot = np.asarray(ref.motion.rotations)[ref.start:ref.stop]
    ref_pos = np.asarray(ref.motion.root_positions)[ref.start:ref.stop]
    assert got_root.shape == ref_pos.shape == (T, 3)
    assert np.abs(got_root - ref_pos).max() < 1e-2                                  # cm, float32 graph
    dots = np.abs(np.sum(got_rot * ref_rot, axis=-1))                               # q and -q: one rotation
    assert np.all(dots > 1 - 1e-5)
    # and the joint positions agree (forward kinematics with the metadata's skeleton == refimpl's)
    fk_ref = ref.motion.positions()[ref.start:ref.stop]
    from refimpl.skeleton import Skeleton

    mskel = Skeleton(meta["skeleton"]["parents"], np.array(meta["skeleton"]["offsets"]),
                     names=meta["skeleton"]["names"])
    fk_got = mskel.forward_kinematics(got_rot, got_root)
    assert np.abs(fk_got - fk_ref).max() < 0.05                                     # cm
