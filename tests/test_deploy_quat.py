"""Quaternion, dual-quaternion, forward-kinematics and standardisation builders (spec/deploy.md §3)."""
from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from deploy.features import destandardize, standardize
from deploy.graph import GraphBuilder
from deploy.kinematics import depth_levels, forward_kinematics
from deploy.quat import dq_normalize, quat_mul, quat_normalize, quat_rotate, quat_rotation_matrix
from deploy.validate import run_onnxruntime, run_reference, validate_model
from refimpl.dualquat import dq_normalize as np_dq_normalize
from refimpl.rotations import matrix_from_quat
from refimpl.quat import quat_mul as np_quat_mul
from refimpl.quat import quat_normalize as np_quat_normalize
from refimpl.quat import quat_rotate as np_quat_rotate
from refimpl.skeleton import Skeleton
from refimpl.skeletons import cmu_skeleton
from refimpl.strategies import quaternions, skeleton_arrays, small_shapes, translations, unit_quaternions
from refimpl.testing import TOL_EXACT, TOL_ORT_STEP, assert_close

OPSETS = (17, 21)


@functools.lru_cache(maxsize=None)
def _quat_model(opset: int, dtype_name: str):
    """One model with every quaternion builder; inputs broadcast over a symbolic leading axis N."""
    g = GraphBuilder("quat", dtype=np.dtype(dtype_name), opset=opset)
    a, b = g.input("a", ["N", 4]), g.input("b", ["N", 4])
    v, d = g.input("v", ["N", 3]), g.input("d", ["N", 8])
    g.output(quat_mul(g, a, b, name="mul"), "mul", ["N", 4])
    g.output(quat_rotate(g, a, v, name="rot"), "rot", ["N", 3])
    g.output(quat_normalize(g, a, name="qn"), "qn", ["N", 4])
    g.output(dq_normalize(g, d, name="dqn"), "dqn", ["N", 8])
    g.output(quat_rotation_matrix(g, a, name="R"), "R", ["N", 3, 3])
    model = g.model()
    validate_model(model)
    return model


def _expected(a, b, v, d):
    return [np_quat_mul(a, b), np_quat_rotate(a, v), np_quat_normalize(a), np_dq_normalize(d)]


@pytest.mark.parametrize("opset", OPSETS)
@settings(max_examples=15)
@given(data=st.data())
def test_quaternion_builders_match_numpy(opset, data):
    """spec/deploy.md §3.1-3.3: quat_mul, quat_rotate, quat_normalize, dq_normalize equal refimpl (non-unit input)."""
    n = data.draw(st.integers(1, 5))
    a = data.draw(quaternions((n,), 0.3, 3.0))
    b = data.draw(quaternions((n,), 0.3, 3.0))
    v = data.draw(translations((n,)))
    d = np.concatenate([data.draw(quaternions((n,), 0.3, 3.0)), data.draw(quaternions((n,), 0.0 + 1e-3, 3.0))], -1)
    expect = _expected(a, b, v, d)
    feeds = {"a": a, "b": b, "v": v, "d": d}
    f32 = {k: x.astype(np.float32) for k, x in feeds.items()}
    expect32 = _expected(*(f32[k].astype(np.float64) for k in ("a", "b", "v", "d")))
    for out, exp, key in zip(run_onnxruntime(_quat_model(opset, "float32"), f32), expect32, "mul rot qn dqn".split()):
        assert_close(out, exp, rtol=1e-4, atol=1e-5 * max(1.0, float(np.abs(exp).max())), name=f"{key} f32")
    for outs in (run_onnxruntime(_quat_model(opset, "float64"), feeds),
                 run_reference(_quat_model(opset, "float64"), feeds)):
        for out, exp, key in zip(outs, expect, "mul rot qn dqn".split()):
            assert_close(out, exp, rtol=1e-12, atol=1e-12, name=f"{key} f64")


@settings(max_examples=10)
@given(q=unit_quaternions((3,)))
def test_rotation_matrix_of_unit_quaternion(q):
    """spec/deploy.md §3.2: I + 2wK + 2K² is refimpl's matrix_from_quat for unit quaternions."""
    outs = run_onnxruntime(_quat_model(17, "float64"), {"a": q, "b": q, "v": q[:, :3], "d": np.concatenate([q, q], -1)})
    R = outs[4]                                                      # (3, 3, 3)
    assert_close(R, matrix_from_quat(q), rtol=0, atol=1e-13, name="R")


def test_quaternion_builders_are_coarse_and_broadcast():
    """spec/deploy.md §3.1: the Hamilton product is 5 nodes and broadcasts over leading axes like NumPy."""
    g = GraphBuilder("t", dtype=np.float64)
    a, b = g.input("a", ["B", 1, 4]), g.input("b", [1, "J", 4])
    out = quat_mul(g, a, b, name="m")
    assert len(g.nodes) == 5
    g.output(out, "m", ["B", "J", 4])
    rng = np.random.default_rng(0)
    qa, qb = rng.normal(size=(2, 1, 4)), rng.normal(size=(1, 3, 4))
    (m,) = run_onnxruntime(g.model(), {"a": qa, "b": qb})
    assert_close(m, np_quat_mul(qa, qb), **TOL_EXACT, name="broadcast")


def test_normalisations_guard_zero():
    """spec/deploy.md §3.3: a zero quaternion or zero real part gives 0 (divided by eps), never NaN."""
    z4, z8 = np.zeros((1, 4)), np.zeros((1, 8))
    z8[0, 5] = 1.0
    outs = run_onnxruntime(_quat_model(17, "float64"), {"a": z4, "b": z4, "v": z4[:, :3], "d": z8})
    assert np.all(outs[2] == 0) and np.all(np.isfinite(outs[3]))


# ------------------------------------------------------------------------------------------------ kinematics
def _fk_model(parents, offsets, dtype=np.float64, opset=17, rotations=False):
    g = GraphBuilder("fk", dtype=dtype, opset=opset)
    J = len(parents)
    q, r = g.input("q", ["B", "T", J, 4]), g.input("root", ["B", "T", 3])
    outs = forward_kinematics(g, q, r, parents, offsets, name="fk", return_rotations=rotations)
    outs = outs if isinstance(outs, tuple) else (outs,)
    g.output(outs[0], "positions", ["B", "T", J, 3])
    if rotations:
        g.output(outs[1], "rotations", ["B", "T", J, 4])
    model = g.model()
    validate_model(model)
    return model


@settings(max_examples=20)
@given(skel=skeleton_arrays(1, 9), lead=small_shapes(2, 2, min_dims=2), data=st.data())
def test_forward_kinematics_random_skeletons(skel, lead, data):
    """spec/deploy.md §3.4: depth-level FK equals Skeleton.forward_kinematics on random trees (ORT f64 + reference)."""
    parents, offsets = skel
    J = len(parents)
    q = data.draw(unit_quaternions(lead + (J,)))
    root = data.draw(translations(lead))
    expect = Skeleton(parents, offsets).forward_kinematics(q, root)
    model = _fk_model(parents, offsets)
    for (pos,) in (run_onnxruntime(model, {"q": q, "root": root}), run_reference(model, {"q": q, "root": root})):
        assert_close(pos, expect, rtol=1e-12, atol=1e-11, name="fk")


@pytest.mark.parametrize("opset", OPSETS)
def test_forward_kinematics_cmu_float32(opset):
    """spec/deploy.md §3.4: float32 FK of the 31-joint CMU skeleton; world rotations too; node count by depth."""
    skel = cmu_skeleton()
    rng = np.random.default_rng(1)
    q = np_quat_normalize(rng.normal(size=(2, 3, skel.num_joints, 4)))
    root = rng.normal(size=(2, 3, 3)) * 10
    model = _fk_model(skel.parents, skel.offsets, np.float32, opset, rotations=True)
    assert len(model.graph.node) < 25 * len(depth_levels(skel.parents))
    pos, rot = run_onnxruntime(model, {"q": q.astype(np.float32), "root": root.astype(np.float32)})
    q32, r32 = q.astype(np.float32).astype(np.float64), root.astype(np.float32).astype(np.float64)
    scale = float(np.abs(skel.offsets).sum())
    assert_close(pos, skel.forward_kinematics(q32, r32), rtol=1e-4, atol=1e-5 * scale, name="fk f32")
    assert_close(rot, skel.world_rotations(q32), **TOL_ORT_STEP, name="world rotations")


def test_depth_levels_and_bad_skeletons():
    """spec/deploy.md §3.4: levels group joints by depth; invalid parent lists raise ValueError."""
    assert depth_levels([-1, 0, 1, 0, 3]) == [[0], [1, 3], [2, 4]]
    for bad in ([0, 0], [-1, 1], [-1, 0, 3]):
        with pytest.raises(ValueError, match="parent"):
            depth_levels(bad)
    with pytest.raises(ValueError, match="offsets"):
        forward_kinematics(GraphBuilder("t"), "q", "r", [-1, 0], np.zeros((3, 3)), name="fk")


# ------------------------------------------------------------------------------------------- standardisation
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_standardize_roundtrip(dtype):
    """spec/deploy.md §3.5: (x − mean)/std and z·std + mean as NumPy computes them (float64 bit-identical)."""
    rng = np.random.default_rng(2)
    mean, std = rng.normal(size=5), rng.uniform(0.5, 2, size=5)
    g = GraphBuilder("t", dtype=dtype)
    x = g.input("x", ["B", 5])
    z = standardize(g, x, mean, std, name="z")
    g.output(z, "z", ["B", 5])
    g.output(destandardize(g, z, mean, std, name="x_back", wname="z"), "x_back", ["B", 5])
    model = g.model()
    validate_model(model)
    assert len(model.graph.initializer) == 2                      # mean and std shared by both directions
    xv = rng.normal(size=(3, 5)).astype(dtype)
    z_out, x_back = run_onnxruntime(model, {"x": xv})
    m, s = mean.astype(dtype), std.astype(dtype)
    if dtype == np.float64:
        assert np.array_equal(z_out, (xv - m) / s) and np.array_equal(x_back, z_out * s + m)
    assert_close(x_back, xv, **TOL_ORT_STEP, name="roundtrip")
    for bad in ((mean, -std), (mean[:3], std), (mean * np.nan, std)):
        with pytest.raises(ValueError, match="mean|std"):
            standardize(GraphBuilder("t"), "x", *bad, name="z")
