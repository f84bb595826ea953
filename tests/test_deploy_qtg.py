"""QTG export: init, step and rollout models against refimpl.models.qtg (spec/deploy.md §5).

Every model passes validate_model (checker full_check, strict shape inference, IR <= 13), runs in onnxruntime
(float32; float64 primitive form) and in the ONNX reference evaluator, at opsets 17 and 21, and agrees with the
NumPy model within refimpl.testing's float32 tolerances (TOL_ORT_STEP per step, TOL_ORT_ROLLOUT per rollout).
"""
from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from deploy.metadata import FORMAT, read_metadata
from deploy.models.qtg import ROLLOUT_MODES, export_qtg_init, export_qtg_rollout, export_qtg_step
from deploy.models.qtg_io import Runtime as QTGRuntime
from deploy.validate import run_onnxruntime, run_reference, validate_model
from refimpl.models.qtg import QTGConfig, QTGState, init_params, init_state, step
from refimpl.models.qtg_fast import rollout_forward
from refimpl.skeletons import cmu_skeleton
from refimpl.testing import TOL_EXACT, TOL_ORT_ROLLOUT, TOL_ORT_STEP, assert_close
from refimpl.protocols.transition import TransitionSource, load_source, make_windows, normalize_poses

SMALL = QTGConfig(pose_size=11, encoder_sizes=(9, 6), gru_hidden=5, gru_layers=2, decoder_sizes=(8,),
                  negative_slope=0.05, transition_length=6)
OPSETS = (17, 21)


@functools.lru_cache(maxsize=None)
def _params(config: QTGConfig = SMALL, seed: int = 0):
    """float32-representable float64 parameters (so float32 and float64 runs use identical weights)."""
    p = init_params(config, np.random.default_rng(seed))
    return {k: v.astype(np.float32).astype(np.float64) for k, v in p.items()}


def _context(config: QTGConfig, B: int, seed: int = 1):
    rng = np.random.default_rng(seed)
    past = rng.normal(size=(B, 2, config.pose_size)).astype(np.float32).astype(np.float64)
    target = rng.normal(size=(B, 2, config.pose_size)).astype(np.float32).astype(np.float64)
    return past, target


def _tol(dtype, rollout=False):
    if dtype == np.float64:
        return TOL_EXACT
    return TOL_ORT_ROLLOUT if rollout else TOL_ORT_STEP


def _cast(feeds, dtype):
    return {k: np.asarray(v, dtype=dtype) for k, v in feeds.items()}


@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_init_and_step_match_numpy(opset, dtype):
    """spec/deploy.md §5.1: init = init_state; one step = refimpl.models.qtg.step, for a 2-layer GRU."""
    params = _params()
    past, target = _context(SMALL, 3)
    m_init = export_qtg_init(params, SMALL, dtype=dtype, opset=opset)
    m_step = export_qtg_step(params, SMALL, dtype=dtype, opset=opset)
    for m in (m_init, m_step):
        validate_model(m)
        assert m.opset_import[0].version == opset and m.ir_version <= 13
    state, tl = init_state(params, past, target, SMALL)
    feeds = _cast({"past": past, "target": target}, dtype)
    for lp, pose, hid, tl_out in (run_onnxruntime(m_init, feeds), run_reference(m_init, feeds)):
        assert_close(lp, state.latent_prev, **_tol(dtype), name="latent_prev")
        assert_close(pose, state.pose, **_tol(dtype), name="pose")
        assert np.all(hid == 0) and hid.shape == (SMALL.gru_layers, 3, SMALL.gru_hidden)
        assert_close(tl_out, tl, **_tol(dtype), name="target_latent")
    # a mid-transition state with non-zero hidden
    rng = np.random.default_rng(5)
    state = QTGState(state.latent_prev, state.pose, rng.normal(size=state.hidden.shape) * 0.5)
    pose_next, new = step(params, state, tl, SMALL)
    feeds = _cast({"pose": state.pose, "latent_prev": state.latent_prev, "hidden": state.hidden,
                   "target_latent": tl}, dtype)
    for outs in (run_onnxruntime(m_step, feeds), run_reference(m_step, feeds)):
        assert_close(outs[0], pose_next, **_tol(dtype), name="pose_next")
        assert_close(outs[1], new.latent_prev, **_tol(dtype), name="latent_prev_next")
        assert_close(outs[2], new.hidden, **_tol(dtype), name="hidden_next")


@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("mode", ROLLOUT_MODES)
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_rollout_matches_numpy(opset, mode, dtype):
    """spec/deploy.md §5.2: the whole transition in one graph (unrolled / Loop / Scan) = rollout_forward."""
    params = _params()
    past, target = _context(SMALL, 4)
    model = export_qtg_rollout(params, SMALL, mode=mode, dtype=dtype, opset=opset)
    validate_model(model)
    ops = {n.op_type for n in model.graph.node}
    assert {"unrolled": "GRU" if dtype == np.float32 else "Sigmoid", "loop": "Loop", "scan": "Scan"}[mode] in ops
    expect, _ = rollout_forward(params, past, target, config=SMALL)
    feeds = _cast({"past": past, "target": target}, dtype)
    for (poses,), who in ((run_onnxruntime(model, feeds), "ort"), (run_reference(model, feeds), "reference")):
        assert poses.shape == (4, SMALL.transition_length, SMALL.pose_size)
        assert_close(poses, expect, **_tol(dtype, rollout=True), name=f"{mode} {who}")


def test_step_loop_equals_rollout_and_runtime():
    """spec/deploy.md §5.2, §7: init + host loop over step = rollout model (QTGRuntime both ways), any batch."""
    params = _params()
    kw = dict(normalization=(np.array([1.0, -2.0, 0.5]), np.array([2.0, 3.0, 0.25])))
    rt = QTGRuntime(export_qtg_init(params, SMALL, **kw), export_qtg_step(params, SMALL, **kw),
                    export_qtg_rollout(params, SMALL, **kw))
    for B in (1, 5):
        past, target = _context(SMALL, B, seed=B)
        in_graph = rt.transition(past, target)
        host = rt.transition(past, target, use_rollout=False)
        assert in_graph.shape == host.shape == (B, SMALL.transition_length, SMALL.pose_size)
        assert_close(host, in_graph, **TOL_ORT_STEP, name="host loop vs rollout")
    longer = rt.transition(past, target, T=SMALL.transition_length + 3)   # host loop for another length
    assert longer.shape[1] == SMALL.transition_length + 3
    assert_close(longer[:, :SMALL.transition_length], host, rtol=0, atol=0, name="prefix")
    with pytest.raises(ValueError, match="T"):
        QTGRuntime(rollout=export_qtg_rollout(params, SMALL)).transition(past, target, T=3)


def test_normalization_in_graph_and_metadata():
    """spec/deploy.md §4-5: with statistics the graphs take raw poses; metadata carries config, layout, stats."""
    config = QTGConfig(pose_size=3 + 4 * 31, encoder_sizes=(16, 8), gru_hidden=8, decoder_sizes=(16,),
                       transition_length=4)
    params = _params(config)
    root_mean, root_std = np.array([10.0, 90.0, -5.0]), np.array([30.0, 4.0, 25.0])
    skel = cmu_skeleton()
    past, target = _context(config, 2)
    past[..., :3] = past[..., :3] * root_std + root_mean                  # raw root translation
    target[..., :3] = target[..., :3] * root_std + root_mean
    model = export_qtg_rollout(params, config, normalization=(root_mean, root_std), skeleton=skel,
                               frame_rate=30.0, metadata={"dataset": "unit test"})
    validate_model(model)
    normed, _ = rollout_forward(params, normalize_poses(past, root_mean, root_std),
                                normalize_poses(target, root_mean, root_std), config=config)
    expect = normed.copy()
    expect[..., :3] = normed[..., :3] * root_std + root_mean
    (poses,) = run_onnxruntime(model, _cast({"past": past, "target": target}, np.float32))
    assert_close(poses, expect, rtol=1e-3, atol=1e-3, name="raw-space rollout")
    meta = read_metadata(model)
    assert meta["format"] == FORMAT and meta["model"]["role"] == "rollout"
    assert QTGConfig(**meta["model"]["config"]) == config and meta["model"]["transition_length"] == 4
    assert meta["normalization"]["in_graph"] is True
    assert np.array_equal(meta["normalization"]["mean"][:3], root_mean) and meta["normalization"]["std"][3:] == [1.0] * 124
    assert meta["skeleton"]["parents"] == list(skel.parents) and len(meta["skeleton"]["names"]) == 31
    assert meta["representation"]["fields"][1]["joints"] == 31 and meta["frame_rate"] == 30.0
    assert meta["dataset"] == "unit test" and "Geleijn" in meta["source_paper"]
    assert [e["name"] for e in meta["io"]["inputs"]] == ["past", "target"]
    assert meta["exporter"]["opset"] == 17 and meta["exporter"]["dtype"] == "float32"
    no_graph = export_qtg_step(params, config, normalization=(root_mean, root_std), normalize_in_graph=False)
    assert read_metadata(no_graph)["normalization"]["in_graph"] is False
    assert not any("pose_norm" in t.name for t in no_graph.graph.initializer)


def test_export_is_deterministic_and_shares_weights():
    """spec/deploy.md §1, §5.2: same weights → identical bytes; the unrolled rollout stores each weight once."""
    params = _params()
    a = export_qtg_rollout(params, SMALL).SerializeToString()
    b = export_qtg_rollout(dict(reversed(list(params.items()))), SMALL).SerializeToString()
    assert a == b
    model = export_qtg_rollout(params, SMALL)
    n_weights = sum(int(np.prod(t.dims)) for t in model.graph.initializer if t.data_type == 1)
    n_params = sum(v.size for v in params.values())
    assert n_params <= n_weights < n_params + 200                  # weights once (+ small constants)


def test_paper_size_rollout_float32():
    """spec/deploy.md §5.2: the default (paper-size) QTG, 30 frames, unrolled float32 graph vs NumPy float64."""
    config = QTGConfig()
    params = _params(config)
    past, target = _context(config, 2)
    model = export_qtg_rollout(params, config)
    validate_model(model)
    expect, _ = rollout_forward(params, past, target, config=config)
    (poses,) = run_onnxruntime(model, _cast({"past": past, "target": target}, np.float32))
    assert_close(poses, expect, **TOL_ORT_ROLLOUT, name="paper-size rollout")


def test_real_cmu_transition_windows():
    """spec/deploy.md §5.3: real CMU windows (embedded sample 02_01, 30 fps, root-relative) through the export."""
    import refimpl

    path = f"{refimpl.__path__[0]}/data/sample/bvh/02_01.bvh"
    skel, clips = load_source(TransitionSource(path, "cmu_bvh", 120.0, "walk"))
    rot, pos = clips[0]
    windows = make_windows(rot, pos, length=34, stride=20)[:4]           # (4, 34, 91)
    root = windows[..., :3].reshape(-1, 3)
    mean, std = root.mean(0), root.std(0) + 1e-6
    config = QTGConfig()
    params = _params(config, seed=3)
    rt = QTGRuntime(export_qtg_init(params, config, normalization=(mean, std), skeleton=skel),
                    export_qtg_step(params, config, normalization=(mean, std), skeleton=skel),
                    export_qtg_rollout(params, config, normalization=(mean, std), skeleton=skel))
    past, target = windows[:, :2], windows[:, -2:]
    normed, _ = rollout_forward(params, normalize_poses(past, mean, std), normalize_poses(target, mean, std),
                                config=config)
    expect = normed.copy()
    expect[..., :3] = normed[..., :3] * std + mean
    got = rt.transition(past, target)
    assert_close(got, expect, rtol=1e-3, atol=1e-3 * float(np.abs(expect).max()), name="CMU rollout")
    host = rt.transition(past, target, use_rollout=False)
    assert_close(host, got, rtol=1e-3, atol=1e-3 * float(np.abs(expect).max()), name="CMU host loop")


def test_bad_arguments():
    """spec/deploy.md §5: bad parameters, lengths, modes and statistics raise ValueError."""
    params = _params()
    with pytest.raises(ValueError, match="gru.weight_hh_l1"):
        export_qtg_step({k: v for k, v in params.items() if k != "gru.weight_hh_l1"}, SMALL)
    with pytest.raises(ValueError, match="expected shape"):
        export_qtg_step(dict(params, **{"vel.bias": np.zeros(3)}), SMALL)
    with pytest.raises(ValueError, match="finite"):
        export_qtg_step(dict(params, **{"vel.bias": np.full(6, np.nan)}), SMALL)
    with pytest.raises(ValueError, match="T"):
        export_qtg_rollout(params, SMALL, T=0)
    with pytest.raises(ValueError, match="mode"):
        export_qtg_rollout(params, SMALL, mode="while")
    with pytest.raises(ValueError, match="normalization"):
        export_qtg_init(params, SMALL, normalization=(np.zeros(4), np.ones(4)))
    with pytest.raises(ValueError, match="normalization"):
        export_qtg_init(params, SMALL, normalization=(np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError, match="config"):
        export_qtg_init(params, config={"pose_size": 11})


# ------------------------------------------------------------------------------------------ compact variant
@pytest.mark.parametrize("bits,block", [(8, 32), (4, 32), (8, 16)])
def test_quantize_blocks_layout_and_kernel(bits, block):
    """spec/deploy.md §5.4: block-wise symmetric quantisation; onnxruntime's MatMulNBits reads our packing."""
    from deploy.graph import GraphBuilder
    from deploy.quantize import quantize_blocks

    rng = np.random.default_rng(bits)
    K, N = 91, 24                                                    # K not a multiple of the block size
    w = rng.normal(size=(K, N))
    packed, scales, deq = quantize_blocks(w, bits, block)
    kb = -(-K // block)
    assert packed.dtype == np.uint8 and packed.shape == (N, kb, block * bits // 8) and scales.shape == (N * kb,)
    step = np.repeat(scales.reshape(N, kb), block, axis=1)[:, :K].T     # (K, N) scale of each weight
    assert np.all(np.abs(deq - w) <= step / 2 * (1 + 1e-6))
    g = GraphBuilder("t")
    x = g.input("x", ["B", K])
    y = g.node("MatMulNBits", [x, g.constant("Wq", packed), g.constant("s", scales)], "mm", domain="com.microsoft",
               K=K, N=N, bits=bits, block_size=block, accuracy_level=4)
    g.output(y, "y", ["B", N])
    model = g.model()
    assert {o.domain: o.version for o in model.opset_import} == {"": 17, "com.microsoft": 1}
    validate_model(model)
    xv = rng.normal(size=(3, K)).astype(np.float32)
    (out,) = run_onnxruntime(model, {"x": xv})
    expect = xv.astype(np.float64) @ deq
    assert np.abs(out - expect).max() < 0.03 * np.abs(expect).max()   # int8 activations (accuracy_level 4)
    with pytest.raises(ValueError, match="bits"):
        quantize_blocks(w, 2)


# the TINY configurations of the compact variant: 1 / 2 GRU layers, 0 / 1 decoder hidden layers, 1 / 2 encoder layers
TINY = {f"L{L}_dec{len(d)}_enc{len(e)}": dataclasses.replace(SMALL, gru_layers=L, decoder_sizes=d, encoder_sizes=e)
        for L, d, e in ((1, (), (6,)), (1, (8,), (9, 6)), (2, (), (9, 6)), (2, (8,), (9, 6)))}


def _compact_numpy(params, config, past, target, T, mat=lambda w: w):
    """float64 NumPy of the compact graph's arithmetic (spec/deploy.md §5.4), every weight matrix through ``mat``
    (identity: exact algebra; ``quantize_blocks(w)[2]``: the weights an int8/int4 graph multiplies with)."""
    from deploy.models.qtg_compact import _prepare

    prep, H, L = _prepare(params, config), config.gru_hidden, config.gru_layers
    p, n_enc, n_dec = prep["p"], len(config.encoder_sizes), len(config.decoder_sizes) + 1

    def mlp(x, prefix, n, last_linear, first_bias=None):
        for i in range(n):
            b = first_bias if (i == 0 and first_bias is not None) else p[f"{prefix}.{i}.bias"]
            x = x @ mat(p[f"{prefix}.{i}.weight"].T) + b
            if not (last_linear and i == n - 1):
                x = np.where(x > 0, x, config.negative_slope * x)
        return x

    def sigmoid(a):
        return 1.0 / (1.0 + np.exp(-a))

    z_prev, z, e1, e2 = mlp(np.concatenate([past, target], axis=1), "enc", n_enc, False).transpose(1, 0, 2)
    k = np.concatenate([e1, e2], axis=-1) @ mat(prep["target"]) + prep["target_b"]      # (B, 3H)
    s = [np.zeros((past.shape[0], H))] * L
    poses = []
    for t in range(T):
        if t:
            z_prev, z = z, mlp(poses[-1], "enc", n_enc, False)
        x = np.concatenate([z_prev, z], axis=-1) @ mat(prep["pair"]) + k                 # layer 0 input term
        for layer in range(L):
            w, b = mat(prep["state"][layer]), prep["state_b"][layer]
            gh = s[layer] @ w[:, :3 * H] + b[:3 * H]                                      # W_hh s + [0, 0, b_hn]
            r, u = sigmoid(x[:, :H] + gh[:, :H]), sigmoid(x[:, H:2 * H] + gh[:, H:2 * H])
            n = np.tanh(x[:, 2 * H:] + r * gh[:, 2 * H:])
            s[layer] = n + u * (s[layer] - n)
            x = s[layer] @ w[:, 3 * H:] + b[3 * H:]                     # input term of layer + 1, or W_v s
        poses.append(mlp(z + x, "dec", n_dec, True, first_bias=prep["dec0_b"]))
    return np.stack(poses, axis=1)                                                        # (B, T, P)


def _compact(params, config, **kw):
    from deploy.models.qtg_compact import export_qtg_rollout_compact

    model = export_qtg_rollout_compact(params, config, **kw)
    validate_model(model)
    return model


@pytest.mark.parametrize("T", [1, 6])
@pytest.mark.parametrize("name", sorted(TINY))
def test_compact_float32_matches_rollout_forward(name, T):
    """spec/deploy.md §5.4, spec/qtg.md §6: the rearranged weights (pair product, fused state products, folded
    biases, batched init encoder) are exact in float64 NumPy, and the float32 graph (onnxruntime and the ONNX
    reference evaluator) equals rollout_forward within TOL_ORT_ROLLOUT, for 1/2 GRU layers, 0/1 decoder hidden
    layers, T = 1 (step 0 is also the last step) and T = 6."""
    config = TINY[name]
    params = _params(config)
    past, target = _context(config, 3)
    expect, _ = rollout_forward(params, past, target, config=config, T=T)
    assert_close(_compact_numpy(params, config, past, target, T), expect, **TOL_EXACT, name="rearranged algebra")
    model = _compact(params, config, weights="float32", T=T)
    assert "MatMulNBits" not in {n.op_type for n in model.graph.node}
    feeds = _cast({"past": past, "target": target}, np.float32)
    for (poses,), who in ((run_onnxruntime(model, feeds), "ort"), (run_reference(model, feeds), "reference")):
        assert poses.shape == (3, T, config.pose_size)
        assert_close(poses, expect, **TOL_ORT_ROLLOUT, name=f"compact float32 {who}")


@pytest.mark.parametrize("weights", ["int8", "int4"])
@pytest.mark.parametrize("name", sorted(TINY))
def test_compact_quantized_equals_numpy_with_dequantized_weights(name, weights, monkeypatch):
    """spec/deploy.md §5.4: with float32 compute (MatMulNBits accuracy_level 1) the int8/int4 graph equals the
    rearranged NumPy rollout with the dequantised matrices to float32 rounding — which matrices are quantised,
    their layout and biases; the deployed int8-activation form (accuracy_level 4) stays close to it."""
    import deploy.models.qtg_compact as qc
    from deploy.quantize import WeightMatmul, quantize_blocks

    config = TINY[name]
    params = _params(config)
    past, target = _context(config, 3)
    bits = {"int8": 8, "int4": 4}[weights]
    expect = _compact_numpy(params, config, past, target, config.transition_length,
                            mat=lambda w: quantize_blocks(w, bits)[2])
    feeds = _cast({"past": past, "target": target}, np.float32)
    deployed = _compact(params, config, weights=weights)
    monkeypatch.setattr(qc, "WeightMatmul", functools.partial(WeightMatmul, accuracy_level=1))
    (poses,) = run_onnxruntime(_compact(params, config, weights=weights), feeds)
    # float32 rounding only (observed <= 1e-7), so the one-step tolerance; sharp: the float weights fail it
    assert_close(poses, expect, **TOL_ORT_STEP, name=f"compact {weights}, float32 compute")
    float_poses, _ = rollout_forward(params, past, target, config=config)
    with pytest.raises(AssertionError):
        assert_close(float_poses, expect, **TOL_ORT_STEP)
    (poses4,) = run_onnxruntime(deployed, feeds)
    assert 0 < np.abs(poses4 - expect).max() < 0.02 * np.abs(expect).max()


@pytest.mark.parametrize("name", sorted(TINY))
def test_compact_graph_structure(name):
    """spec/deploy.md §5.4 (regression guard): per middle step n_enc + 1 + L + n_dec matrix products reading
    macs_per_frame − 3ZH weights, and the element-wise nodes of the fused structure; step 0 has no encoder pass,
    the last step multiplies the top state by W_v only."""
    from collections import Counter

    from refimpl.models.qtg import macs_per_frame

    config = TINY[name]
    params = _params(config)
    n_enc, n_dec, L = len(config.encoder_sizes), len(config.decoder_sizes) + 1, config.gru_layers
    Z, H = config.latent_size, config.gru_hidden
    for weights in ("float32", "int8"):
        model = _compact(params, config, weights=weights)
        dims = {t.name: list(t.dims) for t in model.graph.initializer}

        def step_nodes(t):
            return [n for n in model.graph.node if n.name.startswith(f"t{t:03d}.")]

        def weights_read(nodes):  # K·N of every product
            total = 0
            for n in nodes:
                if n.op_type == "MatMulNBits":
                    a = {x.name: x.i for x in n.attribute}
                    total += a["K"] * a["N"]
                elif n.op_type in ("Gemm", "MatMul"):
                    total += int(np.prod(dims[n.input[1]]))
            return total

        mid = step_nodes(2)
        mm = "MatMulNBits" if weights == "int8" else "Gemm"
        expect = {mm: n_enc + 1 + L + n_dec, "LeakyRelu": n_enc + n_dec - 1, "Concat": 1, "Split": 1 + 2 * L,
                  "Add": (weights == "int8") + 3 * L + 1, "Mul": 2 * L, "Sub": L, "Sigmoid": L, "Tanh": L}
        assert Counter(n.op_type for n in mid) == expect, weights
        assert weights_read(mid) == macs_per_frame(config) - 3 * Z * H
        first, last = step_nodes(0), step_nodes(config.transition_length - 1)
        assert not [n for n in first if n.name.startswith(("t000.enc", "t000.pair"))]
        assert Counter(n.op_type for n in first)[mm] == 1 + L + n_dec
        assert weights_read(last) == weights_read(mid) - L * 3 * H * H       # no W_hh products after the last step


def test_compact_default_size_node_count():
    """spec/deploy.md §5.4: the default QTG has 23 nodes per middle step with int8 weights (6 MatMulNBits), 22 with
    float32 weights (6 Gemm) — against 25 (8 products) before the fused structure."""
    config = QTGConfig()
    params = _params(config)
    for weights, total in (("int8", 23), ("float32", 22)):
        model = _compact(params, config, weights=weights)
        ops = [n.op_type for n in model.graph.node if n.name.startswith("t010.")]
        assert len(ops) == total and ops.count("MatMulNBits" if weights == "int8" else "Gemm") == 6, ops


@pytest.mark.parametrize("opset", OPSETS)
@pytest.mark.parametrize("weights,max_err", [("float32", None), ("int8", 0.02), ("int4", 0.1)])
def test_compact_rollout(opset, weights, max_err):
    """spec/deploy.md §5.4: the rearranged rollout equals rollout_forward (float32) or stays close (int8, int4),
    with raw poses in and out (normalisation in the graph), and keeps the rollout model's I/O and metadata."""
    config = QTGConfig(pose_size=11, encoder_sizes=(40, 24), gru_hidden=32, decoder_sizes=(40,),
                       transition_length=8)
    params = _params(config)
    past, target = _context(config, 3)
    stats = (np.array([1.0, -2.0, 0.5]), np.array([2.0, 3.0, 0.25]))
    model = _compact(params, config, weights=weights, normalization=stats, opset=opset, skeleton=cmu_skeleton())
    assert model.opset_import[0].version == opset
    # same contract as export_qtg_rollout: inputs, outputs, metadata (but the variant)
    plain = export_qtg_rollout(params, config, normalization=stats, opset=opset, skeleton=cmu_skeleton())
    assert [str(v) for v in model.graph.input] == [str(v) for v in plain.graph.input]
    assert [str(v) for v in model.graph.output] == [str(v) for v in plain.graph.output]
    meta, plain_meta = read_metadata(model), read_metadata(plain)
    assert meta["exporter"].pop("variant") == f"compact.{weights}" and plain_meta["exporter"].pop("variant")
    assert meta == plain_meta
    raw = lambda p: p * np.r_[stats[1], np.ones(8)] + np.r_[stats[0], np.zeros(8)]  # noqa: E731
    expect, _ = rollout_forward(params, past, target, config=config)
    feeds = _cast({"past": raw(past), "target": raw(target)}, np.float32)
    (poses,) = run_onnxruntime(model, feeds)
    got = (poses - np.r_[stats[0], np.zeros(8)]) / np.r_[stats[1], np.ones(8)]
    if max_err is None:
        assert_close(got, expect, **TOL_ORT_ROLLOUT, name="compact float32")
        (ref,) = run_reference(model, feeds)
        assert_close(ref, poses, **TOL_ORT_ROLLOUT, name="compact reference evaluator")
    else:
        err = np.abs(got - expect)
        assert err.max() < max_err and err.mean() < max_err / 5, (err.max(), err.mean())


def test_compact_bad_arguments():
    """spec/deploy.md §5.4: bad weights format, length, parameters raise ValueError."""
    from deploy.models.qtg_compact import export_qtg_rollout_compact

    params = _params()
    with pytest.raises(ValueError, match="weights"):
        export_qtg_rollout_compact(params, SMALL, weights="fp16")
    for T in (0, 2.5):
        with pytest.raises(ValueError, match="T"):
            export_qtg_rollout_compact(params, SMALL, T=T)
    with pytest.raises(ValueError, match="gru.weight_hh_l1"):
        export_qtg_rollout_compact({k: v for k, v in params.items() if k != "gru.weight_hh_l1"}, SMALL)
    with pytest.raises(ValueError, match="normalization"):
        export_qtg_rollout_compact(params, SMALL, normalization=(np.zeros(3), np.zeros(3)))
