"""The int8/int4-weight GRU step (``deploy.gru.gru_step(..., weights=...)``) and ``deploy.quantize.WeightMatmul``.

spec/deploy.md §2.3 (GRU step) and §5.4 (block-wise quantisation, ``com.microsoft.MatMulNBits``). The quantised
models are onnxruntime-only (the ONNX reference evaluator has no contrib operators), so onnxruntime is the only
runtime here; every model still passes ``validate_model`` (checker with full_check, strict shape inference).

Exactness: with ``accuracy_level = 1`` (float32 compute) the kernel multiplies by exactly the dequantised weights
(the third output of ``quantize_blocks``), so the step must equal ``refimpl.nn.gru.gru_step_forward`` run with
those weights to float32 tolerance; any gate-order, transpose or packing error breaks this. With the default
``accuracy_level = 4`` the activations are quantised to int8 as well; that step is compared with the float
weights within a measured bound (below).
"""
from __future__ import annotations

import numpy as np
import pytest

from deploy.graph import GraphBuilder
from deploy.gru import gru_step
from deploy.quantize import WEIGHT_FORMATS, WeightMatmul, quantize_blocks
from deploy.validate import run_onnxruntime, validate_model
from refimpl.nn.gru import gru_init, gru_step_forward
from refimpl.testing import TOL_ORT_STEP, assert_close

BITS = {"int8": 8, "int4": 4}
# Measured (seeds 0-19, I = 5, H ∈ {7, 40, 64}, L ∈ {2, 3}, B ∈ {1, 3}, PyTorch-style uniform(±1/√H) init,
# x ~ N(0, 1), h = tanh(N(0, 1)); the 2×1000 QuaterNet size gives the same figures): max |h_new − float| ≤ 5.3e-3
# (mean ≤ 9e-4) for int8, ≤ 5.9e-2 (mean ≤ 1.1e-2) for int4. Bounds: about 3× the measured values.
QUANT_BOUND = {"int8": (0.015, 0.003), "int4": (0.15, 0.03)}


def _f32_exact(a):
    """Values representable in float32 (so the float32 graph and the float64 reference see the same numbers)."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


def _params(rng, I, H, L):
    return {k: _f32_exact(v) for k, v in gru_init(rng, I, H, L, "gru").items()}


def _dequantized(params, bits, block_size=32):
    """The weights the kernel multiplies with: ``W = quantize_blocks(Wᵀ)[2]ᵀ``; biases unchanged."""
    return {k: quantize_blocks(v.T, bits, block_size)[2].T if ".weight_" in k else v for k, v in params.items()}


def _step_model(params, I, H, L, **kw):
    g = GraphBuilder("gru_step")
    x, h = g.input("x", ["B", I]), g.input("h", [L, "B", H])
    y, h_new = gru_step(g, x, h, params, "gru", name="gru", num_layers=L, **kw)
    g.output(y, "y", ["B", H])
    g.output(h_new, "h_new", [L, "B", H])
    model = g.model()
    validate_model(model)
    return model


def _inputs(rng, B, I, H, L):
    return _f32_exact(rng.normal(size=(B, I))), _f32_exact(np.tanh(rng.normal(size=(L, B, H))))


def _run(model, x, h):
    return run_onnxruntime(model, {"x": x.astype(np.float32), "h": h.astype(np.float32)})


@pytest.mark.parametrize("weights", ["int8", "int4"])
@pytest.mark.parametrize("H,L,B,block", [(7, 1, 1, 32), (7, 2, 3, 32), (40, 3, 1, 16), (64, 2, 3, 32),
                                         (64, 2, 1, 128)])
def test_quantized_step_equals_numpy_with_dequantized_weights(weights, H, L, B, block):
    """spec/deploy.md §2.3, §5.4: float32 compute (accuracy_level 1) reproduces gru_step_forward with the
    dequantised weights to float32 rounding: gate order r|z|n, transposes, packing, biases, stacking."""
    rng = np.random.default_rng(H * 10 + L)
    I = 5
    params = _params(rng, I, H, L)
    model = _step_model(params, I, H, L, weights=weights, block_size=block, accuracy_level=1)
    assert {o.domain: o.version for o in model.opset_import}["com.microsoft"] == 1
    x, h = _inputs(rng, B, I, H, L)
    y_ort, h_ort = _run(model, x, h)
    y, h_new, _ = gru_step_forward(x, h, _dequantized(params, BITS[weights], block), "gru", num_layers=L)
    assert_close(y_ort, y, **TOL_ORT_STEP, name=f"y {weights}")
    assert_close(h_ort, h_new, **TOL_ORT_STEP, name=f"h_new {weights}")
    # the comparison is sharp: the float weights differ from the dequantised ones by far more than the tolerance
    _, h_float, _ = gru_step_forward(x, h, params, "gru", num_layers=L)
    assert np.abs(h_float - h_new).max() > 20 * TOL_ORT_STEP["atol"]


@pytest.mark.parametrize("weights", ["int8", "int4"])
@pytest.mark.parametrize("H,L,B", [(7, 2, 3), (40, 3, 1), (64, 2, 3)])
def test_quantized_step_close_to_float_weights(weights, H, L, B):
    """spec/deploy.md §2.3: the deployed form (int8 activations, accuracy_level 4) against the float weights stays
    within the measured quantisation bound (QUANT_BOUND); int4 is coarser than int8."""
    rng = np.random.default_rng(100 + H)
    I = 5
    params = _params(rng, I, H, L)
    x, h = _inputs(rng, B, I, H, L)
    _, h_float, _ = gru_step_forward(x, h, params, "gru", num_layers=L)
    errs = {}
    for w in ("int8", "int4"):
        _, h_ort = _run(_step_model(params, I, H, L, weights=w), x, h)
        errs[w] = np.abs(h_ort - h_float)
    max_bound, mean_bound = QUANT_BOUND[weights]
    e = errs[weights]
    assert e.max() < max_bound and e.mean() < mean_bound, (e.max(), e.mean())
    assert errs["int4"].mean() > errs["int8"].mean()


def test_float32_weights_keep_the_fused_graph():
    """spec/deploy.md §2.3: weights="float32" (the default) is today's graph, byte for byte, fused and primitive."""
    rng = np.random.default_rng(1)
    I, H, L = 5, 7, 2
    params = _params(rng, I, H, L)
    for primitive in (False, True):
        models = []
        for kw in ({}, {"weights": "float32", "block_size": 64, "accuracy_level": 1}):
            g = GraphBuilder("s", primitive=primitive)
            x, h = g.input("x", ["B", I]), g.input("h", [L, "B", H])
            _, h_new = gru_step(g, x, h, params, "gru", name="gru", num_layers=L, **kw)
            g.output(h_new, "h_new", [L, "B", H])
            models.append(g.model().SerializeToString())
        assert models[0] == models[1]


@pytest.mark.parametrize("L", [1, 2, 3])
def test_quantized_step_graph_structure(L):
    """gru_step Notes: 13 nodes per layer (2 MatMulNBits with their own bias input, 3 Split, element-wise), plus
    Split/Concat of the layer states (L > 1) and one Squeeze; no gate reordering, no float weight copies."""
    rng = np.random.default_rng(2)
    I, H = 5, 7
    model = _step_model(_params(rng, I, H, L), I, H, L, weights="int8")
    ops = [n.op_type for n in model.graph.node]
    assert len(ops) == 13 * L + 1 + (2 if L > 1 else 0)
    assert ops.count("MatMulNBits") == 2 * L and ops.count("Split") == 3 * L + (L > 1)
    assert all(len(n.input) == 6 for n in model.graph.node if n.op_type == "MatMulNBits")   # bias input used
    float_inits = [i.name for i in model.graph.initializer if i.data_type == 1 and len(i.dims) == 2]
    assert float_inits == []                                                          # weights only quantised
    names = {i.name for i in model.graph.initializer}
    assert {f"gru.l{L - 1}.ih.Wq8", f"gru.l{L - 1}.hh.scales", f"gru.l{L - 1}.hh.b"} <= names


def test_quantized_steps_share_weights():
    """spec/deploy.md §1: two chained steps with one wname share the quantised initializers and equal two
    NumPy steps (accuracy_level 1, dequantised weights)."""
    rng = np.random.default_rng(3)
    I, H, L, B = 5, 7, 2, 3
    params = _params(rng, I, H, L)
    g = GraphBuilder("two_steps")
    x, h = g.input("x", ["B", I]), g.input("h", [L, "B", H])
    _, h1 = gru_step(g, x, h, params, "gru", name="s0", wname="gru", num_layers=L, weights="int4",
                     accuracy_level=1)
    y2, h2 = gru_step(g, x, h1, params, "gru", name="s1", wname="gru", num_layers=L, weights="int4",
                      accuracy_level=1)
    g.output(h2, "h_new", [L, "B", H])
    model = g.model()
    validate_model(model)
    assert sum(i.name.endswith(".Wq4") for i in model.graph.initializer) == 2 * L
    xv, hv = _inputs(rng, B, I, H, L)
    (got,) = run_onnxruntime(model, {"x": xv.astype(np.float32), "h": hv.astype(np.float32)})
    deq = _dequantized(params, 4)
    _, ref, _ = gru_step_forward(xv, hv, deq, "gru", num_layers=L)
    _, ref, _ = gru_step_forward(xv, ref, deq, "gru", num_layers=L)
    assert_close(got, ref, **TOL_ORT_STEP, name="two steps")


def test_gru_step_rejects_bad_weights_arguments():
    """gru_step Raises: unknown weights format; int8 in a primitive or float64 graph; bad block/accuracy."""
    rng = np.random.default_rng(4)
    I, H, L = 5, 7, 2
    params = _params(rng, I, H, L)

    def build(weights, dtype=np.float32, primitive=None, p=params, **kw):
        g = GraphBuilder("s", dtype=dtype, primitive=primitive)
        x, h = g.input("x", ["B", I]), g.input("h", [L, "B", H])
        return gru_step(g, x, h, p, "gru", name="gru", num_layers=L, weights=weights, **kw)

    for bad in ("fp16", "INT8", None, 8):
        with pytest.raises(ValueError, match="weights"):
            build(bad)
    with pytest.raises(ValueError, match="primitive"):
        build("int8", primitive=True)
    with pytest.raises(ValueError, match="float32"):
        build("int4", dtype=np.float64)
    with pytest.raises(ValueError, match="block_size"):
        build("int8", block_size=24)
    with pytest.raises(ValueError, match="accuracy_level"):
        build("int8", accuracy_level=2)
    with pytest.raises(ValueError, match="weight_hh"):
        build("int8", p={**params, "gru.weight_hh_l1": np.zeros((3 * H, H + 1))})


# ------------------------------------------------------------------------------------------- WeightMatmul
@pytest.mark.parametrize("fmt", WEIGHT_FORMATS)
def test_weight_matmul_forms(fmt):
    """deploy.quantize.WeightMatmul: x @ W with no bias, a constant bias (the kernel's bias input: one node) and a
    computed bias (an extra Add); exact against the dequantised W at accuracy_level 1."""
    rng = np.random.default_rng(5)
    K, N, B = 45, 6, 3
    w, b = _f32_exact(rng.normal(size=(K, N))), _f32_exact(rng.normal(size=N))
    g = GraphBuilder("mm")
    x, c = g.input("x", ["B", K]), g.input("c", ["B", N])
    W = WeightMatmul(g, fmt, accuracy_level=1)
    for out, bias in (("plain", None), ("const", b), ("tensor", c)):
        g.output(W.matmul(x, w, "w", f"mm_{out}", bias=bias), out, ["B", N])
    model = g.model()
    validate_model(model)
    ops = [n.op_type for n in model.graph.node]
    assert ops == (["MatMul", "Gemm", "Gemm"] if fmt == "float32" else ["MatMulNBits"] * 3 + ["Add"])
    xv, cv = _f32_exact(rng.normal(size=(B, K))), _f32_exact(rng.normal(size=(B, N)))
    plain, const, tensor = run_onnxruntime(model, {"x": xv.astype(np.float32), "c": cv.astype(np.float32)})
    wq = w if fmt == "float32" else quantize_blocks(w, BITS[fmt])[2]
    assert_close(plain, xv @ wq, **TOL_ORT_STEP, name="plain")
    assert_close(const, xv @ wq + b, **TOL_ORT_STEP, name="const bias")
    assert_close(tensor, xv @ wq + cv, **TOL_ORT_STEP, name="tensor bias")


def test_weight_matmul_rejects_bad_arguments():
    """deploy.quantize.WeightMatmul Raises."""
    g = GraphBuilder("mm")
    for kw, match in (({"fmt": "fp8"}, "fmt"), ({"fmt": "int8", "block_size": 8}, "block_size"),
                      ({"fmt": "int8", "block_size": 48}, "block_size"),
                      ({"fmt": "int4", "accuracy_level": 0}, "accuracy_level")):
        with pytest.raises(ValueError, match=match):
            WeightMatmul(g, **kw)
    with pytest.raises(ValueError, match="float32"):
        WeightMatmul(GraphBuilder("mm64", dtype=np.float64), "int8")
    WeightMatmul(GraphBuilder("mm64", dtype=np.float64), "float32")          # float weights in any graph dtype
