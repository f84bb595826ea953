"""Metadata-only consumers (``tests/consumers/``: NumPy + onnxruntime, written from the models' metadata and
deploy/README.md) reproduce every exported model's NumPy network on real frames (issue #24, spec/deploy.md §4).

The models are the tiny trained ones of ``tests/test_deploy_every_model.py`` (its ``exported`` fixture); inputs
come from the embedded sample (CMU exp-map walking, the salsa takes, the locomotion clips) and are prepared with
``refimpl``; the consumers themselves import neither ``refimpl`` nor ``deploy`` (checked).
"""
from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from tests.test_deploy_every_model import SALSA, WALK_TXT, exported  # noqa: E402,F401  (the fixture)

CONSUMERS = Path(__file__).resolve().parent / "consumers"


def test_consumers_import_only_numpy_and_onnxruntime():
    allowed = {"numpy", "onnxruntime", "json", "pathlib", "__future__", "tests"}
    files = sorted(CONSUMERS.glob("*.py"))
    assert len(files) >= 6
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            names = ([a.name for a in node.names] if isinstance(node, ast.Import) else
                     [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for n in names:
                top = n.split(".")[0]
                assert top in allowed, (f.name, n)
                assert top != "tests" or n.startswith("tests.consumers"), (f.name, n)


def _prefix(J_flip=(3, 11)):
    from refimpl.tasks import prediction

    rot = prediction.load_clip(WALK_TXT, "cmu", 1.0 / 60.0)                         # (F, J, 4), real frames
    x = np.stack([rot[s:s + 12] for s in (0, 40, 90)])                              # (3, 12, J, 4)
    x[:, :6, J_flip[0]] *= -1                                                       # the same rotations
    x[1:, :, J_flip[1]] *= -1
    return x


def _numpy(ck):
    from refimpl.services import load_trained

    model = load_trained(ck)
    return model, model.spec.make_method(model)


@pytest.mark.parametrize("name", ["quaternet", "quaternet-cnn"])
def test_prediction_consumers(exported, name):
    from tests.consumers import quaternet, quaternet_cnn

    ck, folder = exported[name]
    _, method = _numpy(ck)
    x = _prefix()
    ref = method(x, 7)                                                              # (3, 7, J, 4), canonical
    got = (quaternet if name == "quaternet" else quaternet_cnn).predict(folder, x, 7)
    assert np.abs(got - ref).max() <= 1e-4
    if name == "quaternet":
        graph = quaternet.predict_graph(folder, x)
        k = graph.shape[1]
        assert np.abs(graph - method(x, k)).max() <= 1e-4


def test_acrnn_consumer(exported):
    from refimpl.protocols import synthesis
    from tests.consumers import acrnn

    ck, folder = exported["acrnn"]
    model, method = _numpy(ck)
    frames = synthesis.motion_to_frames(model.extra["data_representation"], synthesis.load_salsa_motion(SALSA))
    seed = np.stack([frames[0:10], frames[30:40]])                                  # (2, 10, F) raw, metres
    ref = np.asarray(method(seed, 15), np.float64)                                   # (2, 15, F)
    scale = np.maximum(1.0, np.abs(ref))
    assert np.all(np.abs(acrnn.generate_loop(folder, seed, 15) - ref) <= 1e-4 * scale)
    out = acrnn.generate(folder, seed, 15)
    assert np.all(np.abs(out["frames"] - ref) <= 1e-4 * scale)
    hip = acrnn.hip_positions(ref[0].astype(np.float64))
    assert np.allclose(hip[1, [0, 2]] - hip[0, [0, 2]], ref[0, 0, [0, 2]])


def test_long_term_consumer(exported):
    from refimpl.protocols.locomotion import evaluation_windows
    from refimpl.tasks import locomotion
    from tests.consumers import quaternet_long

    ck, folder = exported["quaternet-long"]
    model, method = _numpy(ck)
    ds = locomotion.load_eval_data("sample", model.extra)
    inputs, _, _ = evaluation_windows(ds)
    x = np.asarray(inputs[:3])                                                       # real frames and controls
    rot, tr = method(x, ds.prefix)
    ref = np.concatenate([np.asarray(rot).reshape(rot.shape[0], rot.shape[1], -1), tr], axis=-1)
    got = quaternet_long.rollout(folder, x, ds.prefix)
    assert got.shape == ref.shape and np.abs(got - ref).max() <= 1e-3


def test_pace_consumer(exported):
    from refimpl.splines import circle_path
    from tests.consumers import quaternet_long

    ck, folder = exported["pace"]
    _, method = _numpy(ck)
    path = circle_path(6.0)
    ref = method(path, 0.5)
    sp = path.reparameterize(5.0, 1.0)
    got = quaternet_long.pace(folder, sp.track("turning_angle")[:, 0], 0.5, sp.track("tangent"))
    assert np.abs(got["amplitude"] - ref.track("amplitude")[:, 0]).max() <= 1e-5
    assert np.abs(got["frequency"] - ref.track("frequency")[:, 0]).max() <= 1e-5
    assert np.abs(got["facing"] - ref.track("direction")).max() <= 1e-5


def test_walked_path_consumer(exported):
    """The long-term step fed by the controls of a walk along a circle (pace tracks of the NumPy pace network,
    the checkpoint's real seed clip): the same rotations and root heights as ``generate_walk``."""
    from refimpl.models import pace
    from refimpl.services import load_trained
    from refimpl.splines import circle_path
    from refimpl.models import quaternet_long_walk as W
    from refimpl.protocols.locomotion_data import FPS
    from refimpl.tasks.locomotion import skeleton_of
    from tests.consumers import quaternet_long

    pose, pm = load_trained(exported["quaternet-long"][0]), load_trained(exported["pace"][0])
    seed = pose.extra["seed_clip"]
    rot, feats = np.asarray(seed["rotations"]), np.asarray(seed["features"])
    path = circle_path(6.0)
    net = pose.config.network()
    w = W.generate_walk(pose.params, net, pm.params, pm.config, skeleton_of(pose.extra), rot, feats, path, 0.5, 20,
                        fps=FPS)
    tracks = pace.predict(pm.params, pm.config, path, 0.5)
    rot_a, feats_a = W.align_seed(rot, feats, tracks.interpolate(0.0, "direction"))
    frames = np.concatenate([rot_a.reshape(len(rot_a), -1), feats_a], axis=1)          # (P, 4J + 8)
    got = quaternet_long.walk(exported["quaternet-long"][1], frames, w.controls)
    R = 4 * net.num_joints
    assert got.shape[0] == w.motion.num_frames == 20
    assert np.abs(got[:, :R].reshape(20, -1, 4) - w.motion.rotations).max() <= 1e-4
    assert np.abs(got[:, R + 1] - w.motion.root_positions[:, 1]).max() <= 1e-4


def test_dual_quaternion_consumer(exported):
    """The dual-quaternion QuaterNet from its metadata: sign rule, current DQs from the skeleton, decoding."""
    from tests.consumers import quaternet_dq

    from refimpl.dq_prediction import dq_frames_from_rotations
    from refimpl.protocols.prediction import canonical_prefix
    from refimpl.protocols.prediction_data import skeleton_of
    from tests.consumers.common import metadata, session

    ck, folder = exported["quaternet-dq"]
    _, method = _numpy(ck)
    x = _prefix()
    sk = metadata(session(folder / "quaternet_predict.onnx"))["skeleton"]
    mine = quaternet_dq.current_dqs(quaternet_dq.canonical(x), sk["parents"], np.asarray(sk["offsets"]))
    assert np.abs(mine - dq_frames_from_rotations(canonical_prefix(x), skeleton_of("cmu"))).max() <= 1e-12
    got = quaternet_dq.predict(folder, x)
    ref = method(x, got.shape[1])
    # the DQ network is sensitive to float32 rounding (its dual parts carry translations of ~8 CMU units): NumPy
    # float32 and float64 differ by ~1e-3 in the decoded rotations too
    assert np.abs(got - ref).max() <= 5e-3
