"""The test suite's share of the math API fuzz campaign (spec/robustness.md §8; tests/fuzz/math_api.py).

Every public function of ``refimpl.quat``, ``refimpl.dualquat`` and ``refimpl.skeleton`` gets hostile
arguments (huge, tiny, subnormal, NaN/inf, wrong dtypes and shapes, empty and zero arrays, broadcasting
mismatches, junk scalars): only ``ValueError`` may escape, no NumPy warning, nothing slower than 1 s, and a
result from finite input is finite. Targeted regressions for what the campaign found follow.
"""
from __future__ import annotations

import random

import numpy as np
import pytest

from refimpl import dualquat as DQ
from refimpl import mirroring as MI
from refimpl import quat as Q
from refimpl import rotations as R
from refimpl import skeleton as S
from tests.fuzz import math_api



@pytest.mark.parametrize("family", math_api.FAMILIES)
def test_campaign_share(family):
    """30 seeded cases per family (330 in all): no failure of the contract."""
    rng = random.Random(f"test-{family}")
    bad = []
    for _ in range(30):
        target, fam, arg, kwargs, finite = math_api.make_case(rng, family=family)
        outcome, detail = math_api.run_case(target, kwargs, finite)
        if outcome not in ("ok", "ValueError"):
            bad.append((target, arg, outcome, detail))
    assert not bad, bad


def test_every_target_is_reached():
    """Each target of the campaign runs with its valid arguments (so the hostile cases test something)."""
    for target in math_api.TARGETS:
        rng = random.Random(target)
        fn, spec = math_api.TARGETS[target]
        g = np.random.default_rng(0)
        kwargs = {name: math_api._valid(kind, g, (2,)) for name, kind in spec}
        assert math_api.run_case(target, kwargs, True)[0] == "ok", target


def test_campaign_detects_failures():
    """The classifier is not vacuous: a TypeError, a NaN result and an accepted NaN are failures."""
    def raises_type_error(q):
        raise TypeError("x")

    math_api.TARGETS["_probe_type"] = (raises_type_error, [("q", "q")])
    math_api.TARGETS["_probe_nan"] = (lambda q: np.full(4, np.nan), [("q", "q")])
    math_api.TARGETS["_probe_id"] = (lambda q: np.asarray(q), [("q", "q")])
    try:
        assert math_api.run_case("_probe_type", {"q": np.ones(4)}, True)[0] == "TypeError"
        assert math_api.run_case("_probe_nan", {"q": np.ones(4)}, True)[0] == "NonFiniteOutput"
        assert math_api.run_case("_probe_id", {"q": np.array([np.nan, 0, 0, 1])}, False)[0] == "AcceptedNonFinite"
    finally:
        for k in ("_probe_type", "_probe_nan", "_probe_id"):
            math_api.TARGETS.pop(k)


# ---------------------------------------------------------------------------------------------------------------
# targeted regressions (issue 18)
# ---------------------------------------------------------------------------------------------------------------

HUGE = np.array([1e308, 1e308, 1e308, 1e308])


@pytest.mark.parametrize("fn", [Q.quat_norm, Q.quat_exp, Q.quat_mul.__wrapped__ and (lambda q: Q.quat_mul(q, q)),
                                DQ.dq_inv, DQ.dq_normalize])
def test_huge_inputs_give_finite_result_or_value_error(fn):
    arg = HUGE if fn not in (DQ.dq_inv, DQ.dq_normalize) else np.concatenate([HUGE, HUGE])
    with np.errstate(all="raise"):  # nothing escapes as a floating-point error either
        try:
            out = fn(arg)
        except ValueError:
            return
    assert all(np.isfinite(o).all() for o in (out if isinstance(out, tuple) else (out,)))


def test_quat_norm_beyond_range_is_value_error():
    with pytest.raises(ValueError, match="not representable"):
        Q.quat_norm(HUGE)
    assert Q.quat_norm(np.array([1e308, 0, 0, 0])) == 1e308


@pytest.mark.parametrize("dtype", [np.longdouble, np.float16, np.float32])
def test_other_float_dtypes_do_not_overflow_the_rescaling(dtype):
    """B14: prescaled built 2.0 ** 4096 for long double (OverflowError)."""
    q = np.array([3.0, 4.0, 0.0, 0.0], dtype=dtype)
    big = q * np.asarray(np.finfo(dtype).max / 8, dtype=dtype)
    for fn in (Q.quat_normalize, R.matrix_from_quat, Q.quat_log, R.axis_angle_from_quat, Q.quat_angle):
        out = fn(big)
        assert out.dtype == dtype and np.isfinite(out).all()
    np.testing.assert_allclose(Q.quat_normalize(big).astype(np.float64), [0.6, 0.8, 0, 0], rtol=2e-3)


@pytest.mark.parametrize("scale", [1.0, 1e10, 1e100, 1e300, 1.7e308])
def test_quat_from_axis_angle_finite_unit_for_any_finite_vector(scale):
    """Every finite v: a finite unit quaternion (θ/2 never overflows; cos/sin reduce it modulo 2π). Beyond
    θ ~ 2^53 the float θ is coarser than a turn, so only finiteness and the norm are specified there."""
    v = np.array([[1.0, -0.9, 0.5], [1e-3, 0, 0], [1.0, 1.0, 1.0], [-1.0, 1.0, 1.0]]) * scale
    q = R.quat_from_axis_angle(v)
    assert np.isfinite(q).all()
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1, atol=1e-12)


def test_quat_from_axis_angle_unchanged_for_usual_inputs():
    v = np.random.default_rng(3).standard_normal((50, 3)) * 5
    half = np.linalg.norm(v, axis=-1) / 2
    np.testing.assert_allclose(R.quat_from_axis_angle(v)[:, 0], np.cos(half), atol=1e-15)


@pytest.mark.parametrize("u", [1e10, 1e200, 1e308])
def test_quat_exp_finite_for_huge_vector_part(u):
    q = np.array([0.3, u, -u, 0.0])
    out = Q.quat_exp(q)
    assert np.isfinite(out).all()
    np.testing.assert_allclose(np.linalg.norm(out), np.exp(0.3), rtol=1e-12)


def test_quat_exp_vector_part_beyond_float_range_is_value_error():
    with pytest.raises(ValueError, match="not representable"):
        Q.quat_exp([0.3, 1.7e308, -1.7e308, 0.0])  # |u| = 2.4e308


def test_quat_exp_overflowing_real_part_is_value_error():
    with pytest.raises(ValueError, match="not representable"):
        Q.quat_exp([710.0, 0, 0, 0])
    np.testing.assert_allclose(Q.quat_exp([709.0, 0, 0, 0])[0], np.exp(709.0))


@pytest.mark.parametrize("bad", [np.eye(3, dtype=object), np.eye(3, dtype=np.int64) * 2, np.eye(3).astype(complex),
                                 np.full((3, 3), "a"), None, np.eye(3) * 1e200, np.eye(3, dtype=np.float16),
                                 np.eye(3, dtype=np.longdouble)])
def test_check_rotation_matrix_only_value_error(bad):
    """`check_rotation_matrix` on object/integer/complex/string/huge input: ValueError, never TypeError;
    float16 and long double identities are accepted (no LAPACK)."""
    if isinstance(bad, np.ndarray) and bad.dtype.kind == "f" and np.max(bad) == 1:
        R.check_rotation_matrix(bad, "m")
        assert R.quat_from_matrix(bad).dtype == bad.dtype
        return
    with pytest.raises(ValueError):
        R.check_rotation_matrix(bad, "m")
    with pytest.raises(ValueError):
        R.quat_from_matrix(bad)


@pytest.mark.parametrize("kwargs", [dict(names=5), dict(names="abcd"), dict(end_sites=5), dict(end_sites=[None]),
                                    dict(end_sites=[1.5]), dict(end_sites=[float("inf")]), dict(end_sites=[True]),
                                    dict(joints_left=[1.5], joints_right=[2]), dict(joints_left=5, joints_right=[2]),
                                    dict(joints_left=[None], joints_right=[2]), dict(parents=None),
                                    dict(parents="abc"), dict(offsets=None), dict(offsets=[[1, 2], [3]])])
def test_skeleton_wrong_typed_arguments(kwargs):
    args = dict(parents=[-1, 0, 1, 1], offsets=np.ones((4, 3)))
    args.update(kwargs)
    with pytest.raises(ValueError):
        S.Skeleton(**args)


@pytest.mark.parametrize("joints", [5, None, "joint_2", [None], [1.5], [float("inf")], [True], [[2]], [2 ** 70]])
def test_remove_joints_wrong_typed_joints(joints):
    skel = S.Skeleton([-1, 0, 1, 1], np.ones((4, 3)))
    with pytest.raises(ValueError):
        S.remove_joints(skel, None, joints)
    with pytest.raises(ValueError):
        skel.remove_joints(joints)
    assert skel.remove_joints(["joint_2"]).num_joints == 3  # names still work


@pytest.mark.parametrize("low, high", [(None, 1.0), ("a", 1.0), (np.nan, 1.0), (-1e308, 1e308), (2.0, 1.0)])
def test_random_rotate_about_up_bad_range(low, high):
    rot = Q.quat_identity((2, 3))
    with pytest.raises(ValueError):
        MI.random_rotate_about_up(rot, np.zeros((2, 3)), np.random.default_rng(0), low, high)


def test_forward_kinematics_overflow_is_value_error():
    skel = S.Skeleton([-1, 0, 1], np.array([[0, 0, 0], [1e308, 0, 0], [1e308, 0, 0]]))
    with pytest.raises(ValueError, match="not representable"):
        skel.forward_kinematics(Q.quat_identity((3,)), np.zeros(3))


@pytest.mark.parametrize("eps", [None, "1e-9", np.nan, -1.0, [1e-9], True])
def test_quat_normalize_bad_eps(eps):
    with pytest.raises(ValueError, match="eps"):
        Q.quat_normalize(np.ones(4), eps)


@pytest.mark.parametrize("shape, dtype", [("abc", np.float64), (-1, np.float64), ((1.5,), np.float64),
                                          ((2 ** 40, 2 ** 40), np.float64), ((2,), object), ((2,), "foo"),
                                          ((2,), np.int64)])
def test_identity_bad_shape_or_dtype(shape, dtype):
    for fn in (Q.quat_identity, DQ.dq_identity):
        with pytest.raises(ValueError):
            fn(shape, dtype)


def test_depth_levels_long_chain_is_fast():
    """A chain of 20,000 joints: the depth grouping is O(J log J) (it was O(J · depth))."""
    import time

    parents = [-1] + list(range(19999))
    t0 = time.perf_counter()
    levels = S.depth_levels(np.array(parents))
    assert len(levels) == 19999 and time.perf_counter() - t0 < 1.0
