"""The fused dual-quaternion output kernel (refimpl/dq_output_fast.py) against its readable reference, the
composition of the public losses (refimpl/dq_output.py; spec/acrnn.md §3). Gradients of the public function: tests/test_acrnn.py (central
differences, vector-Jacobian identity, per-joint loop oracle)."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from refimpl import dq_output
from refimpl.dq_output import DQ_TERM_NAMES
from refimpl.dq_output_fast import _fused_forward, _sibling_rounds, dq_output_loss_backward, dq_output_loss_forward
from refimpl.dualquat import dq_normalize
from refimpl.strategies import skeleton_arrays
from refimpl.testing import assert_close

PARENTS = (-1, 0, 1, 1, 3, 0, 5, 5, 5, 8)   # several children per parent (three at joint 5), chains
ALL = {"reg": 0.01, "pos": 1 / 3, "offset": 1 / 3, "quat": 1.0, "quat_current": 0.5}
SUBSETS = [dict(c) for r in (1, 2, 5) for c in itertools.combinations(ALL.items(), r)]


def _inputs(rng, lead, parents, dtype=np.float64):
    raw = (0.5 + rng.random(lead + (len(parents), 1))) * rng.standard_normal(lead + (len(parents), 8))
    target = dq_normalize(rng.standard_normal(lead + (len(parents), 8)))
    return raw.astype(dtype), target.astype(dtype)


def _both(raw, target, parents, w):
    total, parts, cache = dq_output_loss_forward(raw, target, parents, w)
    rtotal, rparts, rcache = dq_output.dq_output_loss_forward(raw, target, parents, w, 1e-12)
    return (total, parts, dq_output_loss_backward(1.7, cache), cache[0]), \
        (rtotal, rparts, dq_output.dq_output_loss_backward(1.7, rcache))


@pytest.mark.parametrize("w", SUBSETS, ids=lambda w: "+".join(w))
def test_fused_equals_composed_float64(w):
    rng = np.random.default_rng(len(w) * 31 + sum(map(len, w)))
    raw, target = _inputs(rng, (3, 4), PARENTS)
    (total, parts, g, kind), (rtotal, rparts, rg) = _both(raw, target, PARENTS, w)
    assert kind == "fused"
    assert set(parts) == set(rparts) == set(w)
    for k in w:
        assert parts[k] == pytest.approx(rparts[k], rel=1e-12, abs=1e-15), k
    assert total == pytest.approx(rtotal, rel=1e-12)
    assert_close(g, rg, rtol=1e-10, atol=1e-13, name="draw")
    assert g.dtype == np.float64 and g.shape == raw.shape


@settings(max_examples=40, deadline=None)
@given(st.data())
def test_fused_equals_composed_on_random_skeletons(data):
    parents, _ = data.draw(skeleton_arrays(1, 9))
    lead = data.draw(st.sampled_from([(1,), (2,), (2, 3)]))
    w = data.draw(st.sampled_from(SUBSETS))
    rng = np.random.default_rng(data.draw(st.integers(0, 2 ** 31)))
    raw, target = _inputs(rng, lead, parents)
    (total, parts, g, kind), (rtotal, rparts, rg) = _both(raw, target, parents, w)
    assert kind == "fused"
    assert total == pytest.approx(rtotal, rel=1e-11, abs=1e-14)
    assert_close(g, rg, rtol=1e-9, atol=1e-12, name="draw")


def test_float32_stays_float32_and_matches_float64():
    rng = np.random.default_rng(3)
    raw, target = _inputs(rng, (4, 5), PARENTS)
    t64, p64, c64 = dq_output_loss_forward(raw, target, PARENTS, ALL)
    t32, p32, c32 = dq_output_loss_forward(raw.astype(np.float32), target.astype(np.float32), PARENTS, ALL)
    g32, g64 = dq_output_loss_backward(1.0, c32), dq_output_loss_backward(1.0, c64)
    assert c32[0] == "fused" and g32.dtype == np.float32
    assert t32 == pytest.approx(t64, rel=1e-5)
    assert_close(g32, g64, rtol=2e-3, atol=2e-6, name="draw float32")
    assert c32[1].dtype == np.float32                  # the cached gradient at dtotal = 1


def test_chunks_do_not_change_the_result():
    rng = np.random.default_rng(5)
    raw, target = _inputs(rng, (3, 7), PARENTS)        # 21 frames: chunks of 4 leave a remainder
    par = np.array(PARENTS)
    t1, p1, (_, g1) = _fused_forward(raw, target, par, ALL, 1e-12, chunk=1000)
    t4, p4, (_, g4) = _fused_forward(raw, target, par, ALL, 1e-12, chunk=4)
    assert t4 == pytest.approx(t1, rel=1e-14) and p4 == pytest.approx(p1, rel=1e-14)
    assert_close(g4, g1, rtol=1e-14, atol=1e-17, name="chunked draw")


def test_backward_is_linear_in_dtotal_and_checks_it():
    rng = np.random.default_rng(6)
    raw, target = _inputs(rng, (2,), PARENTS)
    _, _, cache = dq_output_loss_forward(raw, target, PARENTS, ALL)
    assert_close(dq_output_loss_backward(-2.5, cache), -2.5 * dq_output_loss_backward(1.0, cache), rtol=1e-15)
    with pytest.raises(ValueError, match="dtotal"):
        dq_output_loss_backward(float("nan"), cache)


def test_outside_the_ordinary_range_the_composition_is_used():
    rng = np.random.default_rng(4)
    raw, target = _inputs(rng, (2, 3), PARENTS)
    clamped = raw.copy()
    clamped[0, 1, 2, :4] = 0.0                            # |q_r| = 0 < eps: the clamp of Eq. 13
    huge = raw.copy()
    huge[1, 0, 4, 5] = 1e70                               # fourth powers overflow float64
    for x in (clamped, huge):
        total, parts, cache = dq_output_loss_forward(x, target, PARENTS, ALL)
        assert cache[0] == "composed"
        rtotal, _, rcache = dq_output.dq_output_loss_forward(x, target, PARENTS, ALL, 1e-12)
        assert total == rtotal
        np.testing.assert_array_equal(dq_output_loss_backward(1.0, cache),
                                      dq_output.dq_output_loss_backward(1.0, rcache))


def test_sibling_rounds_scatter_every_child_once_with_unique_parents():
    par = np.array(PARENTS)
    rounds = _sibling_rounds(par)
    children = np.concatenate([c for c, _ in rounds])
    assert sorted(children.tolist()) == list(range(1, len(PARENTS)))
    for c, p in rounds:
        assert len(set(p.tolist())) == len(p) and np.array_equal(par[c], p)
    assert len(rounds) == 3                               # joint 5 has three children
    assert _sibling_rounds(np.array([-1])) == []


def test_names_cover_every_term():
    assert set(ALL) == set(DQ_TERM_NAMES)
