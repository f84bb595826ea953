"""The long-term QuaterNet over dual quaternions (spec/locomotion.md §11; Andreou et al. §6.2, Appendix B): the
recipe's frames, its loss through the whole dual-quaternion output path and BPTT (three gradient oracles at tiny
sizes), decoding, generation, evaluation and export."""
from __future__ import annotations

import numpy as np

from refimpl.dualquat import dq_conj, dq_mul, dq_normalize, translation_from_dq
from refimpl.gradcheck import check_gradients, check_vjp
from refimpl.losses import WEIGHTS_QUATERNET_DQ
from refimpl.models import quaternet
from refimpl.quat import quat_conj, quat_mul, quat_normalize
from refimpl.recipes import quaternet_long as recipe
from refimpl.recipes import quaternet_long_dq as dqr
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
    oracle of the network (``quaternet._backward_per_step``, no vectorised prefix) fed the same cotangents (the
    loss's ``dpre`` and only translation cotangents in ``dy``)."""
    from refimpl.dq_output import dq_output_loss_backward, dq_output_loss_forward
    rng = np.random.default_rng(5)
    batch, sk, net, params, _ = _tiny(rng, mask=(False, True, False))
    value, grads = recipe.loss_and_grads(params, batch, net, sk.offsets, sk.parents, output="dual_quaternion")
    x, P = batch["inputs"], batch["prefix"]
    B, L, _ = x.shape
    T, J = L - P, net.num_joints
    y, pre, _ = quaternet.forward(params, x[:, :P], x[:, P:], batch["mask"], net)
    target = x[:, P:, :8 * J].reshape(B, T, J, 8)
    dtr = y[..., 8 * J:] - batch["target_translations"]
    assert np.isclose(value, _loop_loss(pre.reshape(B, T, J, 8), y[..., :8 * J].reshape(B, T, J, 8), target, dtr,
                                        sk.parents), rtol=1e-12)
    _, _, dc = dq_output_loss_forward(pre.reshape(B, T, J, 8), target, sk.parents, dict(WEIGHTS_QUATERNET_DQ))
    dpre = dq_output_loss_backward(1.0, dc).reshape(B, T, 8 * J)
    dy = np.zeros_like(y)
    dy[..., 8 * J:] = np.sign(dtr) / (B * T)
    slow, _, _ = quaternet._backward_per_step(dy, dpre, params, x[:, :P], x[:, P:], batch["mask"], net)
    assert set(slow) == set(grads)
    for k in grads:
        assert np.allclose(grads[k], slow[k], rtol=1e-10, atol=1e-13), k
