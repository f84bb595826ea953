"""GraphBuilder, validation and metadata plumbing of ``deploy/`` (spec/deploy.md §1, §4, §6)."""
from __future__ import annotations

import json

import numpy as np
import onnx
import pytest

from deploy.graph import (IR_VERSION, MIN_OPSET, OPSET, GraphBuilder, check_model_strict, get_param,
                          ir_version_for, save_model)
from deploy.metadata import read_metadata, skeleton_metadata
from deploy.validate import MAX_IR_VERSION, run_onnxruntime, run_reference, validate_model
from refimpl.skeletons import cmu_skeleton


def _relu_model(opset=OPSET, **meta):
    g = GraphBuilder("t", opset=opset)
    x = g.input("x", ["B", 3])
    g.output(g.node("Relu", [x], "relu"), "y", ["B", 3])
    return g.model(metadata=meta or None)


def test_versions_are_explicit():
    """spec/deploy.md §1: opset 17 / IR 8 by default; other opsets get their minimal IR; never make_model defaults."""
    assert (OPSET, IR_VERSION, MIN_OPSET) == (17, 8, 15)
    assert ir_version_for(17) == 8 and ir_version_for(21) == 10
    m17, m21 = _relu_model(17), _relu_model(21)
    assert (m17.ir_version, [o.version for o in m17.opset_import]) == (8, [17])
    assert (m21.ir_version, [o.version for o in m21.opset_import]) == (10, [21])
    for m in (m17, m21):
        assert m.ir_version <= MAX_IR_VERSION
        validate_model(m)
        (y,) = run_onnxruntime(m, {"x": np.array([[-1.0, 0.0, 2.0]], np.float32)})
        assert y.tolist() == [[0.0, 0.0, 2.0]]
    with pytest.raises(ValueError, match="opset"):
        GraphBuilder("t", opset=14)
    with pytest.raises(ValueError, match="dtype"):
        GraphBuilder("t", dtype=np.float16)


def test_validate_model_rejects():
    """spec/deploy.md §6: too-new IR, non-ModelProto, outputs without a shape, no outputs: all ValueError."""
    m = _relu_model()
    m.ir_version = 14
    with pytest.raises(ValueError, match="ir_version"):
        validate_model(m)
    with pytest.raises(ValueError, match="ModelProto"):
        validate_model(b"not a model")
    bad = onnx.helper.make_model(
        onnx.helper.make_graph([onnx.helper.make_node("Relu", ["x"], ["y"])], "g",
                               [onnx.helper.make_tensor_value_info("x", onnx.TensorProto.FLOAT, None)],
                               [onnx.helper.make_tensor_value_info("y", onnx.TensorProto.FLOAT, None)]),
        opset_imports=[onnx.helper.make_opsetid("", 17)], ir_version=8)
    with pytest.raises(ValueError, match="shape"):
        validate_model(bad)
    no_out = _relu_model()
    del no_out.graph.output[:]
    with pytest.raises(ValueError, match="output"):
        validate_model(no_out)


def test_names_are_unique_and_constants_shared():
    """spec/deploy.md §1: duplicate names raise; value-named constants and equal weights are shared."""
    g = GraphBuilder("t")
    x = g.input("x", ["B", 2])
    assert g.ints([0, 1]) == g.ints([0, 1]) == "const.i64[0,1]"
    assert g.scalar(0.5) == g.scalar(0.5) == "const.f[0.5]"
    w1 = g.weight("fc.W", np.eye(2))
    assert g.weight("fc.W", np.eye(2)) == w1                      # same content: shared
    with pytest.raises(ValueError, match="different content"):
        g.weight("fc.W", np.zeros((2, 2)))
    g.node("MatMul", [x, w1], "mm")
    with pytest.raises(ValueError, match="already used"):
        g.node("Relu", [x], "mm")
    with pytest.raises(ValueError, match="already used"):
        g.input("x", [1])
    assert len(g.initializers) == 3                                # ints, scalar, weight


def test_subgraph_constants_live_in_the_outer_graph():
    """spec/deploy.md §1: Loop/Scan bodies read initializers from the outer scope (never body initializers)."""
    g = GraphBuilder("t")
    body = g.subgraph("body")
    w = body.weight("w", np.ones(2))
    assert w in {t.name for t in g.initializers} and not body.initializers
    assert body.is_initializer("w") and g.is_initializer("w") and not g.is_initializer("x")
    with pytest.raises(ValueError, match="already used"):
        body.input("w", [2])                                       # would shadow the outer name
    body.input("b_in", [2])
    with pytest.raises(ValueError, match="already used"):
        g.input("b_in", [2])                                       # the outer graph cannot reuse a body name
    with pytest.raises(ValueError, match="subgraph"):
        body.model()


def test_output_renames_or_adds_identity():
    """spec/deploy.md §1: an output takes over its producer's name; a graph input as output goes through Identity."""
    g = GraphBuilder("t")
    x = g.input("x", ["B", 2])
    r = g.node("Relu", [x], "relu")
    g.node("Neg", [r], "neg")
    g.output(r, "y", ["B", 2])
    g.output(x, "x_copy", ["B", 2])
    ops = [(n.op_type, list(n.input), list(n.output)) for n in g.nodes]
    assert ops[0] == ("Relu", ["x"], ["y"]) and ops[1] == ("Neg", ["y"], ["neg"])
    assert ops[2] == ("Identity", ["x"], ["x_copy"])
    validate_model(g.model())


@pytest.mark.parametrize("opset", [17, 18, 21])
def test_reduce_axes_attribute_or_input(opset):
    """spec/deploy.md §1: Reduce* take axes as an attribute before opset 18 and as an input from 18 (ReduceSum: 13)."""
    g = GraphBuilder("t", opset=opset)
    x = g.input("x", ["B", 4])
    g.output(g.reduce("ReduceSumSquare", x, [-1], "ss"), "ss", ["B", 1])
    g.output(g.reduce("ReduceSum", x, [-1], "s", keepdims=False), "s", ["B"])
    m = g.model()
    validate_model(m)
    x_val = np.arange(8, dtype=np.float32).reshape(2, 4)
    for outs in (run_onnxruntime(m, {"x": x_val}), run_reference(m, {"x": x_val})):
        assert np.allclose(outs[0][:, 0], (x_val ** 2).sum(-1)) and np.allclose(outs[1], x_val.sum(-1))


def test_metadata_is_json_and_bytes_are_deterministic(tmp_path):
    """spec/deploy.md §4: metadata values are JSON strings (sorted keys); the same build gives identical bytes."""
    skel = cmu_skeleton()
    meta = {"skeleton": skeleton_metadata(skel), "frame_rate": 30.0, "b": [1, 2]}
    m1, m2 = _relu_model(**meta), _relu_model(**meta)
    assert m1.SerializeToString() == m2.SerializeToString()
    assert [p.key for p in m1.metadata_props] == sorted(meta)
    for p in m1.metadata_props:
        json.loads(p.value)
    back = read_metadata(m1)
    assert back["skeleton"]["parents"] == [int(p) for p in skel.parents]
    assert np.array_equal(np.array(back["skeleton"]["offsets"]), skel.offsets)
    path = tmp_path / "m.onnx"
    save_model(m1, path)
    assert path.read_bytes() == m1.SerializeToString()
    assert read_metadata(str(path)) == back and read_metadata(m1.SerializeToString()) == back
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".tmp")]
    m1.metadata_props.add(key="broken", value="{not json")
    with pytest.raises(ValueError, match="broken"):
        read_metadata(m1)
    with pytest.raises(ValueError, match="NaN|JSON|Out of range"):
        _relu_model(bad=float("nan"))


def test_get_param_and_check_model_strict():
    """spec/deploy.md §1: get_param names the missing entry; check_model_strict returns inferred shapes."""
    assert get_param({"a.w": np.ones(2)}, "a", "w").shape == (2,)
    assert get_param({"w": np.ones(2)}, "", "w").shape == (2,)
    with pytest.raises(ValueError, match="'a.b'"):
        get_param({"a.w": 1}, "a", "b")
    inferred = check_model_strict(_relu_model())
    assert inferred.graph.output[0].type.tensor_type.shape.dim[0].dim_param == "B"
