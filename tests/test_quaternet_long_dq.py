"""The long-term QuaterNet over dual quaternions (spec/locomotion.md §11; Andreou et al. §6.2, Appendix B): the
recipe's frames, its loss through the whole dual-quaternion output path and BPTT (three gradient oracles at tiny
sizes), decoding, generation, evaluation and export."""
from __future__ import annotations

import numpy as np

from refimpl.dualquat import dq_conj, dq_mul, dq_normalize, translation_from_dq
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.losses import WEIGHTS_QUATERNET_DQ
from refimpl.models import quaternet, quaternet_sequence
from refimpl.quat import quat_conj, quat_mul, quat_normalize
from refimpl.recipes import quaternet_long as recipe
from refimpl.models import quaternet_long_dq as dqr
from refimpl.skeleton import Skeleton
from refimpl.testing import TOL_FD


def _tiny(rng, J=3, B=2, P=3, T=4, mask=(True, False, False)):
    parents = [-1, 0, 1, 1][:J]
    sk = Skeleton(parents, rng.standard_normal((J, 3)))
    q = rng.standard_normal((B, P + T, J, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    feats = rng.standard_normal((B, P + T, 8))
    windows = np.concatenate([q.reshape(B, P + T, 4 * J), feats], -1)
    batch = {"inputs": dqr.dq_inputs(windows, sk), "target_translations": rng.standard_normal((B, T, 2)),
             "mask": np.array(mask, dtype=bool), "prefix": P}
    net = recipe.QuaterNetLongConfig(num_joints=J, hidden_size=4, controls_hidden=3,
                                     output="dual_quaternion").network()
    params = quaternet.init_params(net, rng)
    # a trained head is near unit DQs; scale the raw output so that L_reg and Eq. 13 are both exercised
    params["fc.bias"][:8 * J] += np.tile([0.8, 0.1, -0.2, 0.3, 0.2, -0.1, 0.3, 0.05], J)
    return batch, sk, net, params, windows


def test_config_and_network():
    cfg = recipe.QuaterNetLongConfig(num_joints=21, hidden_size=256, output="dual_quaternion")
    net = cfg.network()
    assert net.representation == "dual_quaternion" and not net.velocity
    assert (net.num_joints, net.num_outputs, net.num_controls) == (21, 2, 6)
    assert net.input_size == 8 * 21 + 8 and net.output_size == 8 * 21 + 2
    assert recipe.param_shapes(cfg)["fc.weight"] == (8 * 21 + 2, 256)


def test_dq_inputs_are_current_unit_continuous_dual_quaternions():
    """Frames carry C_j = C_p ⊗ (q_j | ½ (0, o_j) ⊗ q_j), C_0 = (q_0 | 0): unit, Eq. 8 translations = FK positions
    with the root at the origin, Eq. 12 gives back the local rotations (up to sign), consecutive real parts have
    a non-negative dot product, and the translations and controls are untouched."""
    rng = np.random.default_rng(0)
    batch, sk, net, _, windows = _tiny(rng, J=4)
    x = batch["inputs"]
    B, L, _ = x.shape
    J = 4
    dq = x[..., :8 * J].reshape(B, L, J, 8)
    assert np.allclose(np.linalg.norm(dq[..., :4], axis=-1), 1) and np.allclose(np.sum(dq[..., :4] * dq[..., 4:], -1), 0)
    q = windows[..., :4 * J].reshape(B, L, J, 4)
    assert np.allclose(translation_from_dq(dq), sk.forward_kinematics(q, np.zeros((B, L, 3))), atol=1e-12)
    dec = dqr.decode(dq, np.zeros((B, L, 2)), sk)
    assert np.allclose(np.abs(np.sum(dec["rotations"] * q, -1)), 1, atol=1e-12)
    assert np.all(np.sum(dq[:, 1:, :, :4] * dq[:, :-1, :, :4], -1) >= 0)
    assert np.array_equal(x[..., 8 * J:], windows[..., 4 * J:])
    # a loop oracle of Eq. 9-11 for one frame
    for j, p in enumerate(sk.parents):
        o = np.zeros(3) if p < 0 else sk.offsets[j]
        loc = np.concatenate([q[0, 0, j], 0.5 * quat_mul(np.concatenate([[0.0], o]), q[0, 0, j])])
        ref = loc if p < 0 else dq_mul(dq[0, 0, p], loc)
        assert np.allclose(ref, dq[0, 0, j], atol=1e-12) or np.allclose(ref, -dq[0, 0, j], atol=1e-12)


def test_loss_gradient_central_differences():
    """Every parameter array against float64 central differences through L_reg, Eq. 13, L_pos (Eq. 8),
    L_offset and L_quat (Eq. 12), the translation terms and BPTT through the fed-back (normalised) frames."""
    rng = np.random.default_rng(3)
    batch, sk, net, params, _ = _tiny(rng)
    _, grads = recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents, output="dual_quaternion")
    check_gradients(lambda: recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents,
                                                  output="dual_quaternion")[0], params, grads, **TOL_FD,
                    max_entries=24)


def _params_vector_fn(params, batch, sk, net):
    return lambda: recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents, output="dual_quaternion")[0]


def test_loss_gradient_vjp_identity():
    """<J v, w> = <v, Jᵀ w> with every parameter array moved together (one directional derivative), two masks."""
    for mask in ((True, False, False), (False, False, False)):
        rng = np.random.default_rng(11)
        batch, sk, net, params, _ = _tiny(rng, mask=mask)
        _, grads = recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents, output="dual_quaternion")
        check_vjp(_params_vector_fn(params, batch, sk, net), params,
                  lambda ws: {k: ws[0] * g for k, g in grads.items()}, rtol=1e-6, atol=1e-9)


def _loop_loss(pre, y, target, dtr, parents):
    """Slow loop oracle of the loss value, per (b, t, j), from the public dual-quaternion functions only."""
    B, T, J, _ = pre.shape
    reg = pos = off = rot = 0.0
    for b in range(B):
        for t in range(T):
            u = [dq_normalize(pre[b, t, j]) for j in range(J)]
            for j in range(J):
                assert np.allclose(u[j], y[b, t, j], atol=1e-12)   # the model's head is the same Eq. 13
                r = pre[b, t, j]
                reg += (r[:4] @ r[:4] - 1.0) ** 2 + (r[:4] @ r[4:]) ** 2
                pos += np.linalg.norm(translation_from_dq(u[j]) - translation_from_dq(target[b, t, j]))
                p = parents[j]
                if p < 0:  # L_offset: the root's offset is 0 by definition (nn.kinematics_layers)
                    lp = lt = np.array([1.0, 0, 0, 0, 0, 0, 0, 0])
                    ql, qt = quat_normalize(u[j][:4]), quat_normalize(target[b, t, j][:4])
                else:
                    lp = dq_mul(dq_conj(u[p]), u[j])
                    lt = dq_mul(dq_conj(target[b, t, p]), target[b, t, j])
                    ql = quat_normalize(quat_mul(quat_conj(u[p][:4]), u[j][:4]))
                    qt = quat_normalize(quat_mul(quat_conj(target[b, t, p][:4]), target[b, t, j][:4]))
                off += np.linalg.norm(translation_from_dq(lp) - translation_from_dq(lt))
                rot += abs(1.0 - ql @ qt)
    n = B * T * J
    w = WEIGHTS_QUATERNET_DQ
    return (w["reg"] * reg + w["pos"] * pos + w["offset"] * off + w["quat"] * rot) / n + np.abs(dtr).mean((0, 1)).sum()


def test_loss_and_grads_against_the_slow_loop_oracles():
    """The value equals a per-(b, t, j) loop over the public DQ functions; the gradients equal the per-step
    oracle of the network (``quaternet_sequence._backward_per_step``, no vectorised prefix) fed the same cotangents (the
    loss's ``dpre`` and only translation cotangents in ``dy``)."""
    from refimpl.dq_output import dq_output_loss_backward, dq_output_loss_forward
    rng = np.random.default_rng(5)
    batch, sk, net, params, _ = _tiny(rng, mask=(False, True, False))
    value, grads = recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents, output="dual_quaternion")
    x, P = batch["inputs"], batch["prefix"]
    B, L, _ = x.shape
    T, J = L - P, net.num_joints
    y, pre, _ = quaternet_sequence.forward(params, x[:, :P], x[:, P:], batch["mask"], net)
    target = x[:, P:, :8 * J].reshape(B, T, J, 8)
    dtr = y[..., 8 * J:] - batch["target_translations"]
    assert np.isclose(value, _loop_loss(pre.reshape(B, T, J, 8), y[..., :8 * J].reshape(B, T, J, 8), target, dtr,
                                        sk.parents), rtol=1e-12)
    _, _, dc = dq_output_loss_forward(pre.reshape(B, T, J, 8), target, sk.parents, dict(WEIGHTS_QUATERNET_DQ))
    dpre = dq_output_loss_backward(1.0, dc).reshape(B, T, 8 * J)
    dy = np.zeros_like(y)
    dy[..., 8 * J:] = np.sign(dtr) / (B * T)
    slow, _, _ = quaternet_sequence._backward_per_step(dy, dpre, params, x[:, :P], x[:, P:], batch["mask"], net)
    assert set(slow) == set(grads)
    for k in grads:
        assert np.allclose(grads[k], slow[k], rtol=1e-10, atol=1e-13), k


# ----------------------------------------------------------------------------------------------------------------
# through the application: train, eval, generate, export (tiny sizes on the embedded CMU sample)
# ----------------------------------------------------------------------------------------------------------------

import json  # noqa: E402
from pathlib import Path  # noqa: E402

import pytest  # noqa: E402

from refimpl.bvh import read_bvh  # noqa: E402
from refimpl.cli import main  # noqa: E402
from refimpl.tasks import locomotion as L  # noqa: E402
from refimpl.protocols import locomotion as LP
from refimpl.tasks import locomotion_generate as G  # noqa: E402

SMALL = ["--data", "sample", "--set", "hidden_size=8", "--set", "output=dual_quaternion", "--locomotion-prefix", "6",
         "--locomotion-target", "8", "--batch-size", "4", "--progress-every", "1", "--checkpoint-every", "1"]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A tiny dual-quaternion quaternet-long checkpoint and a tiny pace checkpoint (``refimpl train``)."""
    out = tmp_path_factory.mktemp("loco_dq")
    assert main(["train", "--model", "quaternet-long", *SMALL, "--out", str(out / "pose"), "--steps", "2",
                 "--validate-every", "2"]) == 0
    assert main(["train", "--model", "pace", "--data", "sample", "--out", str(out / "pace"), "--steps", "2",
                 "--batch-size", "4", "--pace-chunk-length", "60"]) == 0
    return out


def test_training_validation_reports_both_position_readings(trained):
    head, row = (trained / "pose" / "loss_val.csv").read_text().splitlines()[:2]
    assert head == "step,val_position,val_velocity,val_position_dq"
    assert all(float(v) > 0 for v in row.split(",")[1:])


def test_eval_prints_fk_and_dq_positions_against_zero_velocity(trained, capsys, tmp_path):
    """``refimpl eval`` of a DQ checkpoint: FK of the decoded rotations (``quaternet-long``), the DQs' own
    positions (``quaternet-long_dq_positions``) and zero velocity; the DQ method equals Eq. 8 on the rollout."""
    from refimpl.services import load_trained
    ckpt = trained / "pose" / "checkpoint.npz"
    capsys.readouterr()
    assert main(["eval", "--checkpoint", str(ckpt), "--data", "sample", "--json", str(tmp_path / "e.json")]) == 0
    printed = capsys.readouterr().out
    assert "quaternet-long_dq_positions" in printed and "zero_velocity" in printed
    got = json.loads((tmp_path / "e.json").read_text())
    assert set(got) == {"quaternet-long", "quaternet-long_dq_positions", "zero_velocity"}
    model = load_trained(ckpt)
    ds = L.load_eval_data("sample", model.extra)
    inputs, tpos, _ = LP.evaluation_windows(ds)
    sk = L.skeleton_of(model.extra)
    dq, tr = dqr.rollout(model.params, model.config.network(), inputs, ds.prefix, sk)
    dec = dqr.decode(dq, tr, sk)
    perr, _ = LP.position_errors(sk, dec["dq_positions"], tr, tpos)
    np.testing.assert_allclose(got["quaternet-long_dq_positions"]["position"], perr, rtol=1e-6)
    perr, _ = LP.position_errors(sk, dec["fk_positions"], tr, tpos)
    np.testing.assert_allclose(got["quaternet-long"]["position"], perr, rtol=1e-6)


def test_generate_writes_bvh_of_the_decoded_rotations(trained, tmp_path, capsys):
    """``refimpl generate`` with a DQ checkpoint: the BVH holds the rotations decoded current → local (Eq. 12),
    FK bone lengths exact; the printout reports the DQ-vs-FK position gap and the DQ bone-length drift."""
    from refimpl.services import load_trained
    from refimpl.tasks.locomotion import walk_from_checkpoints
    out = tmp_path / "walk.bvh"
    assert main(["generate", "--model", "quaternet-long", "--checkpoint", str(trained / "pose" / "checkpoint.npz"),
                 "--pace", str(trained / "pace" / "checkpoint.npz"), "--path", "circle:r=2", "--speed", "walk",
                 "--seconds", "2", "--out", str(out)]) == 0
    assert read_bvh(out).num_frames == 60
    text = capsys.readouterr().out
    assert "DQ bone-length drift" in text and "vs FK of the decoded rotations" in text
    walk = walk_from_checkpoints(load_trained(trained / "pose" / "checkpoint.npz"),
                                 load_trained(trained / "pace" / "checkpoint.npz"), "circle:r=2", "walk", 1.0)
    m = walk.motion
    assert walk.dq_positions.shape == (m.num_frames, m.num_joints, 3)
    assert G.bone_length_drift(m) < 1e-9
    # an untrained network's DQ positions are not FK-consistent (root translation and bone lengths are free)
    assert np.all(np.isfinite(walk.dq_positions)) and not np.allclose(walk.dq_positions, m.positions(), atol=1e-3)
    drift = G.dq_bone_length_drift(walk.dq_positions, m.skeleton)
    assert drift["max"] >= drift["mean"] > 0


def test_dq_bone_length_drift_is_zero_on_fk_positions():
    rng = np.random.default_rng(2)
    sk = Skeleton([-1, 0, 1, 1], rng.standard_normal((4, 3)))
    q = rng.standard_normal((5, 4, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    p = sk.forward_kinematics(q, rng.standard_normal((5, 3)))
    assert G.dq_bone_length_drift(p, sk)["max"] < 1e-12
    p[:, 2] += 0.5 * np.array([1.0, 0, 0])
    assert G.dq_bone_length_drift(p, sk)["max"] > 0.1


@pytest.mark.parametrize("dq_scale", [None, "0.056444"])
def test_deploy_run_walks_a_dq_export_like_refimpl_generate(trained, tmp_path, dq_scale):
    """``python -m deploy run`` with an exported DQ step (the seed turned into current DQs with the metadata's
    ``dq_scale``, the outputs decoded with Eq. 12) against ``refimpl generate`` on the same checkpoints."""
    pytest.importorskip("onnxruntime")
    from deploy.cli import main as deploy_main
    pose = trained / "pose" / "checkpoint.npz"
    if dq_scale is not None:  # DQ translations in metres: the walk must read dq_scale from the metadata
        assert main(["train", "--model", "quaternet-long", *SMALL, "--set", f"dq_scale={dq_scale}", "--steps", "1",
                     "--out", str(tmp_path / "pose_m")]) == 0
        pose = tmp_path / "pose_m" / "checkpoint.npz"
    for ck, folder in ((pose, "long"), (trained / "pace" / "checkpoint.npz", "pace")):
        assert deploy_main(["export", str(ck), str(tmp_path / folder)]) == 0
    assert main(["generate", "--model", "quaternet-long", "--checkpoint", str(pose),
                 "--pace", str(trained / "pace" / "checkpoint.npz"), "--path", "circle:r=2", "--seconds", "1.5",
                 "--out", str(tmp_path / "ref.bvh")]) == 0
    assert deploy_main(["run", str(tmp_path / "long"), "circle:r=2", str(tmp_path / "walk.bvh"), "--pace",
                        str(tmp_path / "pace"), "--seconds", "1.5"]) == 0
    ref, got = read_bvh(tmp_path / "ref.bvh"), read_bvh(tmp_path / "walk.bvh")
    assert got.num_frames == ref.num_frames == 45
    scale = np.abs(ref.positions()).max()
    assert np.abs(got.positions() - ref.positions()).max() <= 1e-4 * scale


def test_export_step_with_eq13_in_the_graph(trained, tmp_path):
    """The exported DQ step (Eq. 13 per joint in the graph) against NumPy over 5 chained steps from h0; its
    outputs are unit dual quaternions; the task's ONNX rollout refuses a DQ step model (it takes DQ frames)."""
    pytest.importorskip("onnxruntime")
    from refimpl.services import export_onnx, load_trained, verify_onnx
    pose = load_trained(trained / "pose" / "checkpoint.npz")
    assert set(export_onnx(pose, tmp_path)) == {"step", "h0", "seed"}
    check = verify_onnx(pose, tmp_path, seed=1)
    assert check["ok"] and check["step"] < 1e-4
    from deploy.models import runtime_for_dir
    rt = runtime_for_dir(tmp_path)
    net = pose.config.network()
    y, _ = rt.step(np.random.default_rng(0).standard_normal((3, net.input_size)).astype(np.float32))
    dq = np.asarray(y[:, :net.rotation_size], np.float64).reshape(3, net.num_joints, 8)
    assert np.allclose(np.linalg.norm(dq[..., :4], axis=-1), 1, atol=1e-5)
    assert np.allclose(np.sum(dq[..., :4] * dq[..., 4:], -1), 0, atol=1e-5)
    assert rt.step_model.metadata["representation"]["kind"] == "quaternet_long_dq"
    with pytest.raises(ValueError, match="dual-quaternion"):
        rt.rollout(np.zeros((1, 3, net.input_size), np.float32), 2)


def test_dq_scale_changes_the_unit_not_the_motion_or_the_loss():
    """``dq_scale`` s: the DQs' dual parts are s × those of the data's units, the decoded rotations and positions
    are the same, and L_pos, L_offset (divided by s) and L_quat of a prediction scaled the same way are equal."""
    from refimpl.dq_output import dq_output_loss_forward
    rng = np.random.default_rng(4)
    _, sk, _, _, windows = _tiny(rng, J=4)
    s = 0.056444
    a, b = dqr.dq_inputs(windows, sk), dqr.dq_inputs(windows, sk, s)
    J = 4
    da, db = (x[..., :8 * J].reshape(x.shape[:2] + (J, 8)) for x in (a, b))
    assert np.allclose(db[..., :4], da[..., :4]) and np.allclose(db[..., 4:], s * da[..., 4:])
    tr = rng.standard_normal(da.shape[:2] + (2,))
    ra, rb = dqr.decode(da, tr, sk), dqr.decode(db, tr, sk, s)
    for k in ra:
        assert np.allclose(ra[k], rb[k], atol=1e-10), k
    pred = da + 0.05 * rng.standard_normal(da.shape)
    pred_s = pred.copy()
    pred_s[..., 4:] *= s
    w = {"pos": 1.0, "offset": 1.0, "quat": 1.0}
    va, _, _ = dq_output_loss_forward(pred, da, sk.parents, w)
    vb, _, _ = dq_output_loss_forward(pred_s, db, sk.parents, {"pos": 1 / s, "offset": 1 / s, "quat": 1.0})
    assert np.isclose(va, vb, rtol=1e-10)
    with np.testing.assert_raises(ValueError):
        recipe.QuaterNetLongConfig(num_joints=4, output="dual_quaternion", dq_scale=0.0)


def test_loss_gradient_central_differences_with_a_dq_scale():
    rng = np.random.default_rng(8)
    batch, sk, net, params, windows = _tiny(rng)
    batch["inputs"] = dqr.dq_inputs(windows, sk, 0.1)
    kw = dict(output="dual_quaternion", dq_scale=0.1)
    _, grads = recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents, **kw)
    check_gradients(lambda: recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents, **kw)[0], params,
                    grads, **TOL_FD, max_entries=12)
