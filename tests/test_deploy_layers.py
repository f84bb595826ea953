"""Layer builders of ``deploy/`` against PyTorch golden vectors, the NumPy layers and the ONNX reference evaluator.

spec/deploy.md §2 (one builder per layer family). Every model built here goes through ``validate_model``
(checker with full_check, strict shape inference, IR version) and runs in onnxruntime (float32, and float64 for
the primitive forms) and in ``onnx.reference.ReferenceEvaluator`` (float64), at opsets 17 and 21.
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import load_golden
from deploy.activations import activation, leaky_relu
from deploy.conv1d import conv1d_causal
from deploy.graph import GraphBuilder
from deploy.gru import gru, gru_onnx_weights, gru_pair_unrolled, gru_step
from deploy.linear import linear
from deploy.lstm import lstm, lstm_onnx_weights, lstm_step
from deploy.recurrent import GRU_PERM, LSTM_PERM, reorder_gate_blocks, tiled_state
from deploy.validate import run_onnxruntime, run_reference, validate_model
from refimpl.nn.activations import leaky_relu_forward, relu_forward, sigmoid_forward, tanh_forward
from refimpl.nn.conv1d import conv1d_causal_forward, conv1d_init
from refimpl.nn.gru import gru_forward, gru_init, gru_step_forward
from refimpl.nn.linear import linear_forward, linear_init
from refimpl.nn.lstm import lstm_forward, lstm_init, lstm_step_forward
from refimpl.testing import TOL_EXACT, TOL_ORT_STEP, assert_close

OPSETS = (17, 21)
# (graph dtype, primitive): the float32 deployment form, its primitive fallback, and the float64 primitive form
FORMS = [(np.float32, False), (np.float32, True), (np.float64, True)]


def _tol(dtype):
    return TOL_ORT_STEP if dtype == np.float32 else TOL_EXACT


def _build(inputs, body, outputs, *, dtype=np.float32, opset=17, primitive=None):
    """A model from ``inputs`` [(name, shape)], ``body(g, *names) -> names`` and ``outputs`` [(name, shape)]."""
    g = GraphBuilder("t", dtype=dtype, opset=opset, primitive=primitive)
    names = [g.input(n, s) for n, s in inputs]
    outs = body(g, *names)
    outs = outs if isinstance(outs, tuple) else (outs,)
    for src, (n, s) in zip(outs, outputs):
        g.output(src, n, s)
    model = g.model()
    validate_model(model)
    return model


def _run_all(model, feeds, dtype):
    """onnxruntime outputs (graph dtype) and ReferenceEvaluator outputs (float64 feeds into a float64 copy)."""
    feeds_t = {k: np.asarray(v, dtype=dtype) for k, v in feeds.items()}
    return run_onnxruntime(model, feeds_t), run_reference(model, feeds_t)


def _f32_exact(a):
    """Values representable in float32 (so float32 and float64 runs see the same inputs)."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


# ---------------------------------------------------------------------------------------------------- linear
@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("dtype,primitive", FORMS)
@pytest.mark.parametrize("lead,rank2,bias", [((4,), True, True), ((2, 3), False, True), ((5,), False, False)])
def test_linear_matches_numpy(opset, dtype, primitive, lead, rank2, bias):
    """spec/deploy.md §2.1: Gemm (2-D) or MatMul + Add (any leading axes) equals refimpl linear_forward."""
    rng = np.random.default_rng(0)
    params = {k: _f32_exact(v) for k, v in linear_init(rng, 6, 5, "fc", bias=bias).items()}
    x = _f32_exact(rng.normal(size=lead + (6,)))
    lead_names = ["B"] + [int(d) for d in lead[1:]]
    model = _build([("x", lead_names + [6])], lambda g, x: linear(g, x, params, "fc", name="fc", rank2=rank2),
                   [("y", lead_names + [5])], dtype=dtype, opset=opset, primitive=primitive)
    ops = [n.op_type for n in model.graph.node]
    assert ops == (["Gemm"] if rank2 else ["MatMul", "Add"] if bias else ["MatMul"])
    expect, _ = linear_forward(x, params, "fc", bias=bias)
    (y_ort,), (y_ref,) = _run_all(model, {"x": x}, dtype)
    assert_close(y_ort, expect, **_tol(dtype), name="linear ort")
    assert_close(y_ref, expect, **_tol(dtype), name="linear reference")


@pytest.mark.parametrize("dtype,primitive", FORMS)
def test_mlp_leaky005_golden(dtype, primitive):
    """spec/deploy.md §2.1-2.2: QuaterNet's controls block (Linear + LeakyReLU(0.05), twice) against PyTorch."""
    gold = load_golden("mlp_leaky005.npz")
    params = {k[len("param."):]: v for k, v in gold.items() if k.startswith("param.")}

    def body(g, x):
        h = leaky_relu(g, linear(g, x, params, "fc1", name="fc1", rank2=True), name="a1", alpha=0.05)
        return leaky_relu(g, linear(g, h, params, "fc2", name="fc2", rank2=True), name="a2", alpha=0.05)

    model = _build([("x", ["B", 6])], body, [("y", ["B", 30])], dtype=dtype, primitive=primitive)
    (y_ort,), (y_ref,) = _run_all(model, {"x": gold["in.x"]}, dtype)
    assert_close(y_ort, gold["out.y"], **_tol(dtype), name="mlp ort")
    assert_close(y_ref, gold["out.y"], **_tol(dtype), name="mlp reference")


# ----------------------------------------------------------------------------------------------- activations
@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("dtype,primitive", FORMS)
@pytest.mark.parametrize("kind", ["leaky_relu", "relu", "tanh", "sigmoid", "identity"])
def test_activations_match_numpy(opset, dtype, primitive, kind):
    """spec/deploy.md §2.2: every activation equals refimpl.nn.activations, zeros and large values included."""
    x = _f32_exact(np.concatenate([np.random.default_rng(1).normal(size=20) * 4, [0.0, -0.0, 30.0, -30.0]]))
    model = _build([("x", ["N"])], lambda g, x: activation(g, x, kind, name="act", alpha=0.2), [("y", ["N"])],
                   dtype=dtype, opset=opset, primitive=primitive)
    ref = {"leaky_relu": lambda v: leaky_relu_forward(v, 0.2)[0], "relu": lambda v: relu_forward(v)[0],
           "tanh": lambda v: tanh_forward(v)[0], "sigmoid": lambda v: sigmoid_forward(v)[0],
           "identity": lambda v: v}[kind]
    (y_ort,), (y_ref,) = _run_all(model, {"x": x}, dtype)
    assert_close(y_ort, ref(x), **_tol(dtype), name=f"{kind} ort")
    assert_close(y_ref, ref(x), **_tol(dtype), name=f"{kind} reference")


def test_leaky_relu_forms():
    """spec/deploy.md §2.2: fused LeakyRelu stores alpha as a float32 attribute; the primitive form is Max(x, αx)."""
    fused = GraphBuilder("t")
    leaky_relu(fused, fused.input("x", [3]), name="a", alpha=0.01)
    (node,) = fused.nodes
    assert node.op_type == "LeakyRelu" and node.attribute[0].f == np.float32(0.01)
    prim = GraphBuilder("t", dtype=np.float64)
    leaky_relu(prim, prim.input("x", [3]), name="a", alpha=0.01)
    assert [n.op_type for n in prim.nodes] == ["Mul", "Max"]
    with pytest.raises(ValueError, match="alpha"):
        leaky_relu(prim, "x", name="b", alpha=-1.0)
    with pytest.raises(ValueError, match="kind"):
        activation(prim, "x", "gelu", name="c")


# ------------------------------------------------------------------------------------------------------- GRU
def test_gate_block_reorder():
    """spec/deploy.md §2.3-2.4: PyTorch r|z|n → ONNX z|r|h; i|f|g|o → i|o|f|c, for weights and biases."""
    blocks = np.repeat(np.arange(4.0), 2)[:, None] * np.ones((1, 3))     # (4·2, 3), block k filled with k
    assert reorder_gate_blocks(blocks, LSTM_PERM)[::2, 0].tolist() == [0, 3, 1, 2]
    assert reorder_gate_blocks(blocks[:6], GRU_PERM)[::2, 0].tolist() == [1, 0, 2]
    H = 2
    params = {"weight_ih_l0": np.arange(3 * H * 3.0).reshape(3 * H, 3), "weight_hh_l0": np.ones((3 * H, H)),
              "bias_ih_l0": np.arange(3 * H) + 0.0, "bias_hh_l0": np.arange(3 * H) + 10.0}
    w, r, b = gru_onnx_weights(params, "", 0)
    assert w.shape == (1, 3 * H, 3) and r.shape == (1, 3 * H, H) and b.shape == (1, 6 * H)
    assert np.array_equal(w[0, :H], params["weight_ih_l0"][H:2 * H])      # z block first
    assert np.array_equal(b[0], [2, 3, 0, 1, 4, 5, 12, 13, 10, 11, 14, 15])
    lp = {"weight_ih_l0": np.arange(8.0)[:, None], "weight_hh_l0": np.zeros((8, 2))}
    w, _, b = lstm_onnx_weights(lp, "", 0)
    assert w[0, :, 0].tolist() == [0, 1, 6, 7, 2, 3, 4, 5] and np.all(b == 0)  # missing biases are zeros


@pytest.mark.parametrize("dtype,primitive", FORMS)
@pytest.mark.parametrize("name,layers,bidir", [("gru_2layer.npz", 2, False), ("gru_bidirectional.npz", 1, True)])
def test_gru_golden(dtype, primitive, name, layers, bidir):
    """spec/deploy.md §2.3: the GRU builder (lbr = 1, z|r|h, transposes) reproduces PyTorch nn.GRU."""
    gold = load_golden(name)
    params = {k[len("param."):]: v for k, v in gold.items() if k.startswith("param.")}
    I, H, D = gold["in.x"].shape[-1], gold["in.h0"].shape[-1], 2 if bidir else 1
    model = _build([("x", ["B", "T", I]), ("h0", [layers * D, "B", H])],
                   lambda g, x, h0: gru(g, x, h0, params, "", name="gru", num_layers=layers, bidirectional=bidir),
                   [("y", ["B", "T", D * H]), ("h_n", [layers * D, "B", H])], dtype=dtype, primitive=primitive)
    assert any(n.op_type == ("Scan" if primitive else "GRU") for n in model.graph.node)
    ort_out, ref_out = _run_all(model, {"x": gold["in.x"], "h0": gold["in.h0"]}, dtype)
    for outs, who in ((ort_out, "ort"), (ref_out, "reference")):
        assert_close(outs[0], gold["out.y"], **_tol(dtype), name=f"gru y {who}")
        assert_close(outs[1], gold["out.h_n"], **_tol(dtype), name=f"gru h_n {who}")


@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("dtype,primitive", FORMS)
@pytest.mark.parametrize("bidir", [False, True])
def test_gru_matches_numpy(opset, dtype, primitive, bidir):
    """spec/deploy.md §2.3: sequence GRU (2 layers) equals refimpl gru_forward on random data."""
    rng = np.random.default_rng(2)
    B, T, I, H, L, D = 3, 5, 4, 6, 2, 2 if bidir else 1
    params = {k: _f32_exact(v) for k, v in gru_init(rng, I, H, L, "rnn", bidirectional=bidir).items()}
    x, h0 = _f32_exact(rng.normal(size=(B, T, I))), _f32_exact(rng.normal(size=(L * D, B, H)))
    model = _build([("x", ["B", "T", I]), ("h0", [L * D, "B", H])],
                   lambda g, x, h0: gru(g, x, h0, params, "rnn", name="enc.gru", num_layers=L, bidirectional=bidir),
                   [("y", ["B", "T", D * H]), ("h_n", [L * D, "B", H])], dtype=dtype, opset=opset,
                   primitive=primitive)
    y, h_n, _ = gru_forward(x, h0, params, "rnn", num_layers=L, bidirectional=bidir)
    ort_out, ref_out = _run_all(model, {"x": x, "h0": h0}, dtype)
    for outs, who in ((ort_out, "ort"), (ref_out, "reference")):
        assert_close(outs[0], y, **_tol(dtype), name=f"y {who}")
        assert_close(outs[1], h_n, **_tol(dtype), name=f"h_n {who}")


@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("dtype,primitive", FORMS)
def test_gru_step_matches_numpy(opset, dtype, primitive):
    """spec/deploy.md §2.3: one step of a 2-layer GRU equals refimpl gru_step_forward."""
    rng = np.random.default_rng(3)
    B, I, H, L = 2, 4, 5, 2
    params = {k: _f32_exact(v) for k, v in gru_init(rng, I, H, L, "gru").items()}
    x, h = _f32_exact(rng.normal(size=(B, I))), _f32_exact(rng.normal(size=(L, B, H)))
    model = _build([("x", ["B", I]), ("h", [L, "B", H])],
                   lambda g, x, h: gru_step(g, x, h, params, "gru", name="gru", num_layers=L),
                   [("y", ["B", H]), ("h_new", [L, "B", H])], dtype=dtype, opset=opset, primitive=primitive)
    y, h_new, _ = gru_step_forward(x, h, params, "gru", num_layers=L)
    ort_out, ref_out = _run_all(model, {"x": x, "h": h}, dtype)
    for outs, who in ((ort_out, "ort"), (ref_out, "reference")):
        assert_close(outs[0], y, **_tol(dtype), name=f"y {who}")
        assert_close(outs[1], h_new, **_tol(dtype), name=f"h_new {who}")


@pytest.mark.parametrize("dtype,primitive", [(np.float32, "recurrent"), (np.float64, True)])
@pytest.mark.parametrize("K", [1, 4])
def test_gru_pair_unrolled_matches_numpy(dtype, primitive, K):
    """spec/deploy.md §13: two one-layer GRUs on their own sequences, advanced together in one unrolled graph
    (block-diagonal weights, state [h_a | h_b]), equal refimpl gru_forward of each (batch 2, time-major y);
    no Scan, no GRU node."""
    from deploy.portable import operators

    rng = np.random.default_rng(7)
    B, I, H = 2, 3, 5
    params = {}
    for prefix in ("a", "b"):
        params.update({k: _f32_exact(v) for k, v in gru_init(rng, I, H, 1, prefix).items()})
    feeds = {n: _f32_exact(rng.normal(size=s)) for n, s in (("xa", (B, K, I)), ("ha", (1, B, H)),
                                                          ("xb", (B, K, I)), ("hb", (1, B, H)))}
    model = _build([("xa", ["B", K, I]), ("ha", [1, "B", H]), ("xb", ["B", K, I]), ("hb", [1, "B", H])],
                   lambda g, xa, ha, xb, hb: gru_pair_unrolled(g, (xa, xb), (ha, hb), params, ("a", "b"),
                                                               name="pair", steps=K),
                   [("y", [K * B, 2 * H]), ("ha_n", [1, "B", H]), ("hb_n", [1, "B", H])], dtype=dtype, opset=15,
                   primitive=primitive)
    assert not operators(model) & {"GRU", "Scan", "Loop"}
    ya, ha_n, _ = gru_forward(feeds["xa"], feeds["ha"], params, "a", num_layers=1)     # (B, K, H), (1, B, H)
    yb, hb_n, _ = gru_forward(feeds["xb"], feeds["hb"], params, "b", num_layers=1)
    y = np.concatenate([ya, yb], axis=-1).transpose(1, 0, 2).reshape(K * B, 2 * H)
    for outs, who in zip(_run_all(model, feeds, dtype), ("ort", "reference")):
        assert_close(outs[0], y, **_tol(dtype), name=f"y {who}")
        assert_close(outs[1], ha_n, **_tol(dtype), name=f"h_a {who}")
        assert_close(outs[2], hb_n, **_tol(dtype), name=f"h_b {who}")
    with pytest.raises(ValueError, match="steps"):
        gru_pair_unrolled(GraphBuilder("t"), ("x", "x"), ("h", "h"), params, ("a", "b"), name="p", steps=0)
    with pytest.raises(ValueError, match="differ"):
        other = {**params, **{k.replace("a.", "c.", 1): v for k, v in
                              gru_init(rng, I, H + 1, 1, "a").items()}}
        gru_pair_unrolled(GraphBuilder("t"), ("x", "x"), ("h", "h"), other, ("a", "c"), name="p", steps=2)


def test_tiled_state_keeps_batch_symbolic():
    """spec/deploy.md §2.3: a learned initial state (L, H) is expanded to (L, B, H) for any batch size."""
    state = np.arange(6.0).reshape(2, 3)
    model = _build([("x", ["B", 4])], lambda g, x: tiled_state(g, state, x, name="h0"), [("h0", [2, "B", 3])])
    for B in (1, 5):
        (h0,) = run_onnxruntime(model, {"x": np.zeros((B, 4), np.float32)})
        assert_close(h0, np.broadcast_to(state[:, None], (2, B, 3)), **TOL_EXACT, name="tiled")
    with pytest.raises(ValueError, match="state"):
        tiled_state(GraphBuilder("t"), np.zeros((2, 2, 3)), "x", name="bad")


# ------------------------------------------------------------------------------------------------------ LSTM
@pytest.mark.parametrize("dtype,primitive", FORMS)
def test_lstm_golden(dtype, primitive):
    """spec/deploy.md §2.4: the LSTM builder (i|o|f|c, two bias halves) reproduces PyTorch nn.LSTM (3 layers)."""
    gold = load_golden("lstm_3layer.npz")
    params = {k[len("param."):]: v for k, v in gold.items() if k.startswith("param.")}
    L, H, I = 3, gold["in.h0"].shape[-1], gold["in.x"].shape[-1]
    model = _build([("x", ["B", "T", I]), ("h0", [L, "B", H]), ("c0", [L, "B", H])],
                   lambda g, x, h0, c0: lstm(g, x, h0, c0, params, "", name="lstm", num_layers=L),
                   [("y", ["B", "T", H]), ("h_n", [L, "B", H]), ("c_n", [L, "B", H])], dtype=dtype,
                   primitive=primitive)
    feeds = {"x": gold["in.x"], "h0": gold["in.h0"], "c0": gold["in.c0"]}
    for outs, who in zip(_run_all(model, feeds, dtype), ("ort", "reference")):
        for out, key in zip(outs, ("out.y", "out.h_n", "out.c_n")):
            assert_close(out, gold[key], **_tol(dtype), name=f"{key} {who}")


@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("dtype,primitive", FORMS)
@pytest.mark.parametrize("skewed", [False, True])
def test_lstm_matches_numpy(opset, dtype, primitive, skewed):
    """spec/deploy.md §2.4: sequence and step LSTM (3 layers, ordinary and acRNN-skewed) equal refimpl.nn.lstm."""
    rng = np.random.default_rng(4)
    B, T, I, H, L = 2, 5, 3, 4, 3
    params = {k: _f32_exact(v) for k, v in lstm_init(rng, I, H, L, "rnn").items()}
    x = _f32_exact(rng.normal(size=(B, T, I)))
    h0, c0 = _f32_exact(rng.normal(size=(L, B, H))), _f32_exact(rng.normal(size=(L, B, H)))
    seq = _build([("x", ["B", "T", I]), ("h0", [L, "B", H]), ("c0", [L, "B", H])],
                 lambda g, x, h0, c0: lstm(g, x, h0, c0, params, "rnn", name="rnn", num_layers=L, skewed=skewed),
                 [("y", ["B", "T", H]), ("h_n", [L, "B", H]), ("c_n", [L, "B", H])], dtype=dtype, opset=opset,
                 primitive=primitive)
    y, (h_n, c_n), _ = lstm_forward(x, (h0, c0), params, "rnn", num_layers=L, skewed=skewed)
    for outs, who in zip(_run_all(seq, {"x": x, "h0": h0, "c0": c0}, dtype), ("ort", "reference")):
        for out, exp, key in zip(outs, (y, h_n, c_n), ("y", "h_n", "c_n")):
            assert_close(out, exp, **_tol(dtype), name=f"{key} {who}")
    step = _build([("x", ["B", I]), ("h", [L, "B", H]), ("c", [L, "B", H])],
                  lambda g, x, h, c: lstm_step(g, x, h, c, params, "rnn", name="rnn", num_layers=L, skewed=skewed),
                  [("y", ["B", H]), ("h_new", [L, "B", H]), ("c_new", [L, "B", H])], dtype=dtype, opset=opset,
                  primitive=primitive)
    y1, (h1, c1), _ = lstm_step_forward(x[:, 0], (h0, c0), params, "rnn", num_layers=L, skewed=skewed)
    for outs, who in zip(_run_all(step, {"x": x[:, 0], "h": h0, "c": c0}, dtype), ("ort", "reference")):
        for out, exp, key in zip(outs, (y1, h1, c1), ("y", "h_new", "c_new")):
            assert_close(out, exp, **_tol(dtype), name=f"step {key} {who}")


def test_lstm_rejects_skewed_bidirectional():
    """spec/deploy.md §2.4: the skew is defined for unidirectional stacks only."""
    with pytest.raises(ValueError, match="skewed"):
        lstm(GraphBuilder("t"), "x", "h", "c", {}, "", name="l", bidirectional=True, skewed=True)


# ---------------------------------------------------------------------------------------------------- Conv1d
@pytest.mark.parametrize("dtype,primitive", FORMS)
@pytest.mark.parametrize("name", ["conv1d_causal_k2_d1.npz", "conv1d_causal_k2_d4.npz", "conv1d_causal_k3_d2.npz"])
def test_conv1d_golden(dtype, primitive, name):
    """spec/deploy.md §2.5: causal dilated Conv (pads [(K−1)d, 0]) reproduces PyTorch Conv1d on left-padded input."""
    gold = load_golden(name)
    params = {k[len("param."):]: v for k, v in gold.items() if k.startswith("param.")}
    d = int(gold["meta.dilation"])
    model = _build([("x", ["B", "T", 3])], lambda g, x: conv1d_causal(g, x, params, "", name="conv", dilation=d),
                   [("y", ["B", "T", 4])], dtype=dtype, primitive=primitive)
    assert any(n.op_type == ("MatMul" if primitive else "Conv") for n in model.graph.node)
    for out, who in zip(_run_all(model, {"x": gold["in.x"]}, dtype), ("ort", "reference")):
        assert_close(out[0], gold["out.y"], **_tol(dtype), name=f"conv {who}")


@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("dtype,primitive", FORMS)
@pytest.mark.parametrize("K,d", [(1, 1), (3, 1), (2, 3)])
def test_conv1d_matches_numpy_and_is_causal(opset, dtype, primitive, K, d):
    """spec/deploy.md §2.5: equals refimpl conv1d_causal_forward; perturbing x[t0] leaves y[:t0] bit-identical."""
    rng = np.random.default_rng(5)
    params = {k: _f32_exact(v) for k, v in conv1d_init(rng, 3, 4, K, "c").items()}
    x = _f32_exact(rng.normal(size=(2, 9, 3)))
    model = _build([("x", ["B", "T", 3])], lambda g, x: conv1d_causal(g, x, params, "c", name="c", dilation=d),
                   [("y", ["B", "T", 4])], dtype=dtype, opset=opset, primitive=primitive)
    y, _ = conv1d_causal_forward(x, params, "c", dilation=d)
    (y_ort,), (y_ref,) = _run_all(model, {"x": x}, dtype)
    assert_close(y_ort, y, **_tol(dtype), name="conv ort")
    assert_close(y_ref, y, **_tol(dtype), name="conv reference")
    x2 = x.copy()
    x2[:, 6] += 1.0
    (y2,) = run_onnxruntime(model, {"x": x2.astype(dtype)})
    assert np.array_equal(y2[:, :6], y_ort[:, :6]) and not np.allclose(y2[:, 6], y_ort[:, 6])


def test_builders_reject_bad_parameters():
    """spec/deploy.md §2: wrong parameter shapes or missing entries raise ValueError naming the entry."""
    g = GraphBuilder("t")
    with pytest.raises(ValueError, match="fc.weight"):
        linear(g, "x", {}, "fc", name="fc")
    with pytest.raises(ValueError, match="F_out, F_in"):
        linear(g, "x", {"fc.weight": np.zeros(3)}, "fc", name="fc")
    with pytest.raises(ValueError, match="fc.bias"):
        linear(g, "x", {"fc.weight": np.zeros((2, 3)), "fc.bias": np.zeros(3)}, "fc", name="fc")
    with pytest.raises(ValueError, match="C_out, C_in, K"):
        conv1d_causal(g, "x", {"c.weight": np.zeros((2, 3))}, "c", name="c")
    with pytest.raises(ValueError, match="dilation"):
        conv1d_causal(g, "x", {"c.weight": np.zeros((2, 3, 2))}, "c", name="c", dilation=0)
    bad = {"weight_ih_l0": np.zeros((6, 3)), "weight_hh_l0": np.zeros((6, 3))}
    with pytest.raises(ValueError, match="layer 0"):
        gru(g, "x", "h", bad, "", name="gru")
