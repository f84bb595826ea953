"""The join option in the exported graphs (deploy/join.py, spec/qtg.md §7.4, spec/deploy.md §5): the rollout
graph exported with ``join="inertialize"`` equals NumPy's ``qtg_method`` + ``inertialize_joins``."""
from __future__ import annotations

import functools

import numpy as np
import pytest

from deploy.models.qtg import ROLLOUT_MODES, export_qtg_rollout
from deploy.models.qtg_compact import export_qtg_rollout_compact
from deploy.models.qtg_io import Runtime as QTGRuntime, export_dir as export_qtg_dir
from deploy.validate import run_onnxruntime, validate_model
from deploy.metadata import read_metadata
from refimpl.models.qtg import QTGConfig, init_params
from refimpl.recipes.qtg import qtg_method
from refimpl.protocols.transition_join import inertialize_joins, join_blend_frames, with_join

SMALL = QTGConfig(pose_size=91, encoder_sizes=(32, 16), gru_hidden=32, decoder_sizes=(32,), transition_length=30)


@functools.lru_cache(maxsize=None)
def _sample():
    from refimpl.tasks.transition import build_datasets

    train, test = build_datasets("sample", 30, 1, test_stride=16)
    return train, test


@functools.lru_cache(maxsize=None)
def _params(dtype=np.float64):
    return init_params(SMALL, np.random.default_rng(0), dtype=dtype)


def _numpy(dtype, past, target, T=30, blend=None):
    train, _ = _sample()
    net = qtg_method(_params(dtype), SMALL, train.root_mean, train.root_std)
    return with_join(net, "inertialize", blend_frames=blend)(past, target, T)


@pytest.mark.parametrize("mode", ROLLOUT_MODES)
def test_rollout_with_join_matches_numpy_on_real_windows(mode):
    """float64 graph (onnxruntime) against NumPy float64 on held-out windows of the sample: 1e-5."""
    train, test = _sample()
    past, _, target = test.context()
    m = export_qtg_rollout(_params(), SMALL, dtype=np.float64, mode=mode, normalization=(train.root_mean,
                                                                                        train.root_std),
                           join="inertialize")
    validate_model(m)
    got = run_onnxruntime(m, {"past": past, "target": target})[0]
    want = _numpy(np.float64, past, target)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)
    meta = read_metadata(m)
    assert meta["join"]["mode"] == "inertialize" and meta["join"]["blend_frames"] == join_blend_frames(30)
    assert meta["join"]["applied"].startswith("in this graph")


def test_rollout_with_join_float32_and_short_transitions():
    """float32 (graph and NumPy in float32) to float32 rounding; T = 1, 4 with other blends."""
    train, test = _sample()
    past, _, target = test.context()
    norm = (train.root_mean, train.root_std)
    m = export_qtg_rollout(_params(np.float32), SMALL, normalization=norm, join="inertialize")
    got = run_onnxruntime(m, {"past": past.astype(np.float32), "target": target.astype(np.float32)})[0]
    want = _numpy(np.float32, past, target)
    np.testing.assert_allclose(got[..., 3:], want[..., 3:], rtol=0, atol=1e-4)
    np.testing.assert_allclose(got[..., :3], want[..., :3], rtol=0, atol=5e-3)  # cm; float32 network rollout
    for T, blend in ((1, None), (4, None), (4, 3)):
        m = export_qtg_rollout(_params(), SMALL, T=T, dtype=np.float64, normalization=norm, join="inertialize",
                               join_blend_frames=blend)
        got = run_onnxruntime(m, {"past": past[:5], "target": target[:5]})[0]
        np.testing.assert_allclose(got, _numpy(np.float64, past[:5], target[:5], T, blend), rtol=0, atol=1e-5)


def test_the_join_subgraph_alone_on_random_poses():
    """The joined output minus the network: the graph's post-process equals inertialize_joins on the network's
    own (raw) frames, also for large offsets and rotations near pi."""
    rng = np.random.default_rng(3)
    past = rng.normal(size=(6, 2, 91))
    target = rng.normal(size=(6, 2, 91))
    past[..., :3] *= 50
    target[..., :3] *= 50
    m0 = export_qtg_rollout(_params(), SMALL, dtype=np.float64)
    m1 = export_qtg_rollout(_params(), SMALL, dtype=np.float64, join="inertialize")
    raw = run_onnxruntime(m0, {"past": past, "target": target})[0]
    got = run_onnxruntime(m1, {"past": past, "target": target})[0]
    np.testing.assert_allclose(got, inertialize_joins(past, raw, target), rtol=0, atol=1e-5)
    assert np.abs(got - raw).max() > 1.0  # the join did something


def test_compact_rollout_with_join():
    train, test = _sample()
    past, _, target = test.context()
    norm = (train.root_mean, train.root_std)
    plain = export_qtg_rollout_compact(_params(np.float32), SMALL, weights="float32", normalization=norm)
    joined = export_qtg_rollout_compact(_params(np.float32), SMALL, weights="float32", normalization=norm,
                                        join="inertialize")
    feeds = {"past": past.astype(np.float32), "target": target.astype(np.float32)}
    raw = run_onnxruntime(plain, feeds)[0].astype(np.float64)
    got = run_onnxruntime(joined, feeds)[0]
    np.testing.assert_allclose(got, inertialize_joins(past, raw, target), rtol=5e-5, atol=2e-4)  # float32
    assert read_metadata(joined)["join"]["mode"] == "inertialize"


def test_export_dir_and_runtime_step_path(tmp_path):
    """The folder's init/step metadata say where to apply the join; the runtime's step loop applies it, so both
    paths give the same transition."""
    train, test = _sample()
    past, _, target = test.context()
    past, target = past[:4], target[:4]
    export_qtg_dir(_params(), SMALL, tmp_path, dtype=np.float64, normalization=(train.root_mean, train.root_std),
                   join="inertialize")
    rt = QTGRuntime.from_dir(tmp_path)
    assert rt.step_model.metadata["join"]["applied"].startswith("not in this graph")
    a = rt.transition(past, target, use_rollout=True)
    b = rt.transition(past, target, use_rollout=False)
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-6)
    np.testing.assert_allclose(a, _numpy(np.float64, past, target), rtol=0, atol=1e-5)


def test_bad_join_options():
    train, _ = _sample()
    with pytest.raises(ValueError, match="join"):
        export_qtg_rollout(_params(), SMALL, join="smooth")
    with pytest.raises(ValueError, match="normalize_in_graph"):
        export_qtg_rollout(_params(), SMALL, normalization=(train.root_mean, train.root_std),
                           normalize_in_graph=False, join="inertialize")
    with pytest.raises(ValueError, match="join_blend_frames"):
        export_qtg_rollout(_params(), SMALL, join="inertialize", join_blend_frames=0)
    assert "join" not in read_metadata(export_qtg_rollout(_params(), SMALL, T=2))
