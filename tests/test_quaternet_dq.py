"""QuaterNet with dual quaternions, short-term (spec/quaternet.md §9; Andreou et al. §6.2, §7.2, Table 2): the
DQ frames of the prediction task, the differentiable decode (Eq. 12) and the loss with its three gradient oracles,
the recipe (``--set representation=dual_quaternion``), the Table 2 horizons, and ``refimpl train / eval / export /
generate`` on the embedded CMU sample. Tiny sizes."""
from __future__ import annotations

import json

import numpy as np
import pytest

from refimpl import dq_prediction as dqp
from refimpl.cli import EXIT_OK, main
from refimpl.gradcheck import check_vjp, numerical_gradient
from refimpl.models import quaternet as net
from refimpl.models import quaternet_sequence
from refimpl.protocols import prediction as PP
from refimpl.rotations import quat_from_axis_angle
from refimpl.recipes import quaternet as rnn_recipe
from refimpl.services import load_trained
from refimpl.skeleton import Skeleton
from refimpl.current_dq import current_dq_from_local
from refimpl.tasks import prediction as pr
from refimpl.testing import TOL_ORT_STEP, assert_close
from refimpl.train import TrainContext

PARENTS = (-1, 0, 1, 0, 3)
TINY_DQ = ["--set", "hidden_size=8", "--set", "num_layers=1", "--set", "prefix_length=12",
           "--set", "target_length=4", "--set", "representation=dual_quaternion"]
WALK_TXT = pr.SAMPLE_EXPMAP_DIR / "test" / "walking" / "walking_1.txt"


def _skeleton():
    offsets = np.array([[0, 0, 0], [0, 1.5, 0], [0.3, 1.0, 0.2], [1.0, 0, 0], [0, -2.0, 0.5]])
    return Skeleton(names=tuple(f"j{i}" for i in range(5)), parents=PARENTS, offsets=offsets)


def _unit_dqs(rng, lead=(2, 3)):
    q = quat_from_axis_angle(rng.standard_normal(lead + (5, 3)))
    return current_dq_from_local(q, _skeleton().offsets, PARENTS), q  # (..., 5, 8), (..., 5, 4)


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def dq_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("qn_dq")
    assert main(["train", "--model", "quaternet", "--out", str(out), "--steps", "3", "--batch-size", "6",
                 "--progress-every", "1", "--checkpoint-every", "2", *TINY_DQ]) == EXIT_OK
    return out


# ---------------------------------------------------------------------------------------------- frames
def test_dq_frames_are_current_transforms_and_continuous():
    rng = np.random.default_rng(0)
    skel = _skeleton()
    rot = quat_from_axis_angle(np.cumsum(0.4 * rng.standard_normal((2, 30, 5, 3)), axis=1))  # (B, T, J, 4)
    rot *= np.where(rng.random((2, 30, 5, 1)) < 0.5, -1.0, 1.0)   # random signs: the frames must not care
    d = dqp.dq_frames_from_rotations(rot, skel)                     # (B, T, J, 8)
    assert d.shape == (2, 30, 5, 8)
    assert np.all(np.sum(d[:, 1:, :, :4] * d[:, :-1, :, :4], axis=-1) >= 0)   # antipodal continuity over time
    # the same transforms as Eq. 9-11 (each DQ up to its sign), translations = root-relative FK positions
    ref = current_dq_from_local(rot, skel.offsets, PARENTS)
    assert np.allclose(np.abs(np.sum(d * ref, axis=-1)), np.sum(ref * ref, axis=-1), atol=1e-12)
    from refimpl.dualquat import translation_from_dq
    pos = skel.forward_kinematics(rot, np.zeros((2, 30, 3)))
    assert_close(translation_from_dq(d), pos, rtol=0, atol=1e-12)
    back = dqp.rotations_from_dq_frames(d, PARENTS)                 # Eq. 12: the local rotations again
    assert np.allclose(np.abs(np.sum(back * rot, axis=-1)), 1.0, atol=1e-12)
    with pytest.raises(ValueError, match="5-joint"):
        dqp.dq_frames_from_rotations(rot[..., :4, :], skel)


# ---------------------------------------------------------------------------------------------- decode
def test_decode_forward_matches_loop_oracle():
    d, q = _unit_dqs(np.random.default_rng(1))
    loc, _ = dqp.local_rotations_from_dq_forward(d, PARENTS)
    assert_close(loc, dqp._local_rotations_from_dq_naive(d, PARENTS), rtol=0, atol=1e-14)
    assert np.allclose(np.abs(np.sum(loc * q, axis=-1)), 1.0, atol=1e-12)   # the local rotations (up to sign)


def test_decode_backward_three_oracles():
    rng = np.random.default_rng(2)
    d = rng.standard_normal((2, 3, 5, 8))   # any DQs: the decode is bilinear, no unit assumption in its Jacobian
    g = rng.standard_normal((2, 3, 5, 4))
    loc, cache = dqp.local_rotations_from_dq_forward(d, PARENTS)
    grad = dqp.local_rotations_from_dq_backward(g, cache)
    assert np.all(grad[..., 4:] == 0)   # only the real parts reach the local rotations
    # 1. loop oracle with explicit 4 x 4 Jacobians
    assert_close(grad, dqp._local_rotations_from_dq_backward_naive(g, d, PARENTS), rtol=0, atol=1e-13)
    # 2. central differences
    num = numerical_gradient(lambda: float(np.sum(dqp.local_rotations_from_dq_forward(d, PARENTS)[0] * g)), d)
    assert_close(num, grad, rtol=1e-7, atol=1e-8)
    # 3. vector-Jacobian identity
    check_vjp(lambda: dqp.local_rotations_from_dq_forward(d, PARENTS)[0], {"d": d},
              lambda ws: {"d": dqp.local_rotations_from_dq_backward(ws[0], cache)})
    with pytest.raises(ValueError, match="dlocal"):
        dqp.local_rotations_from_dq_backward(g[..., :3], cache)


# ---------------------------------------------------------------------------------------------- loss
@pytest.mark.parametrize("kind", ["euler", "quat"])
def test_loss_gradient_three_oracles(kind):
    rng = np.random.default_rng(3)
    pred, _ = _unit_dqs(rng)
    raw = pred + 0.3 * rng.standard_normal(pred.shape)
    _, target = _unit_dqs(rng)

    def total():
        return dqp.dq_rotation_loss_forward(pred, raw, target, PARENTS, kind=kind, reg_weight=0.37)[0]

    value, parts, cache = dqp.dq_rotation_loss_forward(pred, raw, target, PARENTS, kind=kind, reg_weight=0.37)
    assert np.isclose(value, parts["rot"] + 0.37 * parts["reg"]) and parts["reg"] > 0
    dpred, draw = dqp.dq_rotation_loss_backward(1.0, cache)
    # 1. central differences over every entry of both inputs
    assert_close(numerical_gradient(total, pred), dpred, rtol=1e-6, atol=1e-8)
    assert_close(numerical_gradient(total, raw), draw, rtol=1e-6, atol=1e-8)
    # 2. vector-Jacobian identity (a scalar output: <J v, w> = <v, J^T w>)
    check_vjp(lambda: np.array(total()), {"pred": pred, "raw": raw},
              lambda ws: dict(zip(("pred", "raw"), dqp.dq_rotation_loss_backward(float(ws[0]), cache))))
    # 3. loop oracle: the rotational term's gradient through the per-joint Jacobians of the decode
    from refimpl.losses import euler_l1_loss_backward, euler_l1_loss_forward, quat_loss_backward, quat_loss_forward
    loc = dqp._local_rotations_from_dq_naive(pred, PARENTS)
    fwd, bwd = (euler_l1_loss_forward, euler_l1_loss_backward) if kind == "euler" else (quat_loss_forward,
                                                                                       quat_loss_backward)
    v, c = fwd(loc, target)
    assert np.isclose(v, parts["rot"], rtol=1e-12)
    assert_close(dqp._local_rotations_from_dq_backward_naive(bwd(1.0, c), pred, PARENTS), dpred, rtol=0, atol=1e-13)


def test_loss_checks_and_zero_reg_on_unit_heads():
    rng = np.random.default_rng(4)
    pred, target = _unit_dqs(rng)
    _, parts, _ = dqp.dq_rotation_loss_forward(pred, pred, target, PARENTS)
    assert parts["reg"] < 1e-28 and parts["rot"] < 1e-6   # own decode: the target rotations, L_reg = 0 on unit DQs
    with pytest.raises(ValueError, match="kind"):
        dqp.dq_rotation_loss_forward(pred, pred, target, PARENTS, kind="mse")
    with pytest.raises(ValueError, match="reg_weight"):
        dqp.dq_rotation_loss_forward(pred, pred, target, PARENTS, reg_weight=-1)
    with pytest.raises(ValueError, match="shapes"):
        dqp.dq_rotation_loss_forward(pred, pred, pred, PARENTS)


@pytest.mark.parametrize("velocity", [True, False])
def test_full_loss_gradient_through_the_network(velocity):
    """The recipe's loss (decode + Euler L1 + 0.01 L_reg) back through the whole unrolled DQ network
    (scheduled sampling, fed-back predictions), against central differences on parameter entries."""
    rng = np.random.default_rng(5)
    cfg = rnn_recipe.ShortTermConfig(num_joints=5, hidden_size=4, num_layers=1, prefix_length=3, target_length=3,
                                     velocity=velocity, representation="dual_quaternion")
    ncfg = cfg.network
    params = net.init_params(ncfg, rng)
    q = quat_from_axis_angle(np.cumsum(0.3 * rng.standard_normal((2, 6, 5, 3)), axis=1))
    x = dqp.dq_frames_from_rotations(q, _skeleton()).reshape(2, 6, 40)
    mask = np.array([True, False])

    def loss():
        y, pre, _ = quaternet_sequence.forward(params, x[:, :3], x[:, 3:], mask, ncfg)
        return rnn_recipe.dq_loss_terms(y, pre, q[:, 3:], cfg, PARENTS)[1]

    y, pre, cache = quaternet_sequence.forward(params, x[:, :3], x[:, 3:], mask, ncfg)
    _, total, dy, dpre = rnn_recipe.dq_loss_terms(y, pre, q[:, 3:], cfg, PARENTS)
    assert np.isclose(total, loss())
    grads = quaternet_sequence.backward(dy, dpre, cache)
    for name in ("fc.weight", "fc.bias", "rnn.weight_ih_l0", "rnn.weight_hh_l0", "h0"):
        idx = rng.choice(params[name].size, size=min(12, params[name].size), replace=False)
        num = numerical_gradient(loss, params[name], indices=idx)
        assert_close(num.reshape(-1)[idx], grads[name].reshape(-1)[idx], rtol=1e-5, atol=1e-8, name=name)


# ---------------------------------------------------------------------------------------------- recipe
def test_config_representation_and_legacy_name():
    c = rnn_recipe.ShortTermConfig(representation="dual_quaternion")
    assert c.dual and c.network.joint_width == 8 and c.network.representation == "dual_quaternion"
    assert rnn_recipe.ShortTermConfig(representation="quat").representation == "quaternion"   # old checkpoints
    with pytest.raises(ValueError, match="representation"):
        rnn_recipe.ShortTermConfig(representation="euler")


def test_adapter_draws_the_same_windows_as_the_quaternion_twin():
    data = pr.resolve_data("sample")
    sets = ["hidden_size=4", "num_layers=1", "prefix_length=6", "target_length=3"]
    cq = rnn_recipe.make_config(data, sets)
    cd = rnn_recipe.make_config(data, sets + ["representation=dual_quaternion"])
    aq = rnn_recipe.make_adapter(data, None, cq, np.float64, {"representation": "quat"})
    ad = rnn_recipe.make_adapter(data, None, cd, np.float64, {"representation": "quat"})
    assert ad.config["representation"] == "dual_quaternion" and aq.config["representation"] == "quaternion"
    ctx = lambda: TrainContext(rng=np.random.default_rng(5), step=0, epoch=200)  # noqa: E731
    xq, tq, mq = aq.get_batch(np.arange(4), ctx())
    xd, td, md = ad.get_batch(np.arange(4), ctx())
    assert xd.shape == (4, 9, 8 * 38) and np.array_equal(td, tq) and np.array_equal(md, mq)
    rot = xq.reshape(4, 9, 38, 4)
    dec = dqp.rotations_from_dq_frames(xd.reshape(4, 9, 38, 8), data.skeleton.parents)
    assert np.allclose(np.abs(np.sum(dec * rot, axis=-1)), 1.0, atol=1e-9)   # the same frames, as current DQs
    loss, grads = ad.loss_and_grads(ad.init_params(np.random.default_rng(0)), (xd, td, md))
    assert np.isfinite(loss) and grads["fc.weight"].shape == (8 * 38, 4)


def test_method_decodes_to_local_quaternions():
    data = pr.resolve_data("sample")
    cfg = rnn_recipe.make_config(data, ["hidden_size=4", "num_layers=1", "representation=dual_quaternion"])
    params = net.init_params(cfg.network, np.random.default_rng(0))
    with pytest.raises(ValueError, match="skeleton"):
        rnn_recipe.predictor(params, cfg)
    method = rnn_recipe.predictor(params, cfg, data.skeleton)
    prefix = data.test[0].rotations[None, :20]
    out = method(prefix, 5)
    assert out.shape == (1, 5, 38, 4) and np.allclose(np.linalg.norm(out, axis=-1), 1.0)
    d = dqp.dq_frames_from_rotations(PP.canonical_prefix(prefix), data.skeleton).reshape(1, 20, -1)
    y = net.predict(params, d, 5, cfg.network).reshape(1, 5, 38, 8)
    assert np.allclose(np.abs(np.sum(out * dqp.rotations_from_dq_frames(y, data.skeleton.parents), -1)), 1.0)


# ---------------------------------------------------------------------------------------------- protocol
def test_table2_protocol_at_the_real_frame_rate():
    data = pr.resolve_data("sample")   # 60 fps, test running 81 frames, walking 179
    p = PP.table2_protocol(data)
    assert p.round_horizons and np.isclose(p.frame_ms, 1000 / 60)
    assert p.horizons_ms == (80, 160, 320, 400)        # running: 81 − 50 − 1 = 30 frames at most
    assert p.horizon_frames == (4, 9, 18, 23) and p.target_length == 24
    assert np.allclose(p.horizon_times_ms, (250 / 3, 500 / 3, 950 / 3, 400))
    w = PP.table2_protocol(data, "dense", actions=["walking"])
    assert w.horizons_ms == (80, 160, 320, 400, 600, 800, 1000, 2000) and w.target_length == 120
    assert w.samples_per_sequence == 128
    with pytest.raises(ValueError, match="frames leave at most"):
        PP.table2_protocol(data, prefix_length=80)
    with pytest.raises(ValueError, match="no test sequence"):
        PP.table2_protocol(data, actions=["jumping"])
    with pytest.raises(ValueError, match="beyond"):
        PP.Protocol("x", 1, target_length=4, horizons_ms=(100,), frame_ms=20.0, round_horizons=True)
    assert pr.eval_protocol("cmu", "standard", horizons="table2", data=data) == p
    with pytest.raises(ValueError, match="data"):
        pr.eval_protocol("cmu", horizons="table2")
    # the baselines on it: the first columns are the zero-velocity error at frames 5, 10, 19, 24
    res = PP.evaluate(PP.zero_velocity, data, w, actions=["walking"])
    prefix, target, _ = PP.evaluation_windows(data, "walking", w)
    ref = PP.euler_errors(PP.zero_velocity(prefix, 120), target).mean(axis=0)
    assert_close(np.array(res.actions["walking"]), ref[list(w.horizon_frames)], rtol=1e-12)
    assert PP.results_to_dict(res)["horizon_times_ms"][-1] == pytest.approx(2000)


# ---------------------------------------------------------------------------------------------- commands
def test_train_eval_generate_export_dq(capsys, dq_run, tmp_path):
    model = load_trained(dq_run / "checkpoint.npz")
    assert model.config.dual and model.extra["representation"] == "dual_quaternion"
    js = tmp_path / "r.json"
    code, out, _ = _run(capsys, "eval", "--checkpoint", dq_run / "checkpoint.npz", "--horizons", "table2",
                        "--actions", "walking", "--json", js)
    assert code == EXIT_OK and "80 ms = frame 5 (83 ms)" in out
    doc = json.loads(js.read_text())
    assert [d["method"] for d in doc][-1] == "quaternet" and doc[-1]["horizons_ms"][-1] == 2000
    assert list(doc[-1]["actions"]) == ["walking"]
    code, out, _ = _run(capsys, "generate", "--checkpoint", dq_run / "checkpoint.npz", "--source", WALK_TXT,
                        "--source-frame", "60", "--length", "6", "--out", tmp_path / "p.bvh")
    assert code == EXIT_OK and (tmp_path / "p.bvh").is_file() and "Euler-angle error" in out
    onnx_dir = tmp_path / "onnx"
    code, out, _ = _run(capsys, "export", "--checkpoint", dq_run / "checkpoint.npz", "--out", onnx_dir)
    assert code == EXIT_OK and "step_loop" in out
    from deploy.models import runtime_for_dir
    rt = runtime_for_dir(onnx_dir)
    assert rt.step_model.metadata["representation"]["name"] == "quaternet_dq_frame"
    x = rnn_recipe.network_frames(model, pr.check_prefixes(model, np.random.default_rng(0), 3))
    x0 = x[:, 0].reshape(3, -1).astype(np.float32)
    h = net.init_state(model.params, 3, model.config.network)
    y, hn = net.step(model.params, h, x0, model.config.network)
    got = rt.step(x0, h)
    assert np.allclose(got[0], y, rtol=TOL_ORT_STEP["rtol"], atol=TOL_ORT_STEP["atol"] * np.abs(y).max())
    assert np.allclose(got[1], hn, **TOL_ORT_STEP)
    code, out, _ = _run(capsys, "eval", "--checkpoint", dq_run / "checkpoint.npz", "--onnx", onnx_dir,
                        "--actions", "walking", "--json", js)
    doc = {d["method"]: d for d in json.loads(js.read_text())}
    assert code == EXIT_OK and set(doc) >= {"quaternet", "quaternet_onnx"}
    # the ONNX method feeds the raw prefix (no canonicalisation), the NumPy one the canonical one: the same
    # rotations, float32 against float32 (the later frames of this barely trained network drift apart, and one
    # Euler branch change costs ~2π, so only the first horizons are compared)
    assert np.allclose(doc["quaternet_onnx"]["average"][:3], doc["quaternet"]["average"][:3], rtol=1e-3)


def test_deploy_dq_mul_matches_numpy():
    from deploy.graph import GraphBuilder
    from deploy.models.quaternet_dq import dq_mul
    from deploy.validate import run_reference

    from refimpl.dualquat import dq_mul as np_dq_mul

    g = GraphBuilder("dqmul", dtype=np.float64)
    a, b = g.input("a", ["N", 8]), g.input("b", ["N", 8])
    g.output(dq_mul(g, a, b, name="m"), "y", ["N", 8])
    rng = np.random.default_rng(6)
    av, bv = rng.standard_normal((7, 8)), rng.standard_normal((7, 8))
    got = run_reference(g.model(), {"a": av, "b": bv})[0]
    assert_close(got, np_dq_mul(av, bv), rtol=1e-12, atol=1e-12)
