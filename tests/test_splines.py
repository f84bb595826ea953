"""Splines (spec/locomotion.md §2): arc length, tangents, signed curvature, interpolation, reparameterisation."""
import math

import numpy as np
import pytest
from hypothesis import assume, given, strategies as st

from refimpl.splines import (Spline, circle_path, figure_eight_path, gaussian_filter1d, line_with_turn_path,
                             read_path_csv, _gaussian_filter1d_naive)
from refimpl.testing import assert_close


@pytest.mark.parametrize("radius", [2.0, 20.0])
def test_circle_length_and_curvature(radius):
    c = circle_path(radius, points_per_unit=20)
    n = c.num_points
    assert c.closed
    assert c.length == pytest.approx(2 * n * radius * math.sin(math.pi / n), rel=1e-12)  # the inscribed polygon
    assert c.length == pytest.approx(2 * math.pi * radius, rel=1e-3)
    assert_close(c.track("curvature")[:, 0], np.full(n, 1 / radius), rtol=1e-3)
    assert_close(c.track("turning_angle")[:, 0], np.full(n, 2 * math.pi / n), rtol=1e-9)
    cw = circle_path(radius, points_per_unit=20, clockwise=True)
    assert_close(cw.track("curvature")[:, 0], np.full(n, -1 / radius), rtol=1e-3)


def test_reparameterisation_keeps_length_and_curvature():
    c = circle_path(20.0, points_per_unit=2)
    r = c.reparameterize(5, 1)
    assert r.closed and r.num_points == math.ceil(c.length * 5)
    assert r.length == pytest.approx(c.length, rel=1e-3)
    assert_close(np.diff(r.distances), np.full(r.num_points - 1, r.length / r.num_points), rtol=1e-3)
    # smoothing with σ = 1 unit shrinks a circle of radius 20 by exp(-σ²/(2 r²)) ≈ 0.12 %
    assert_close(r.track("curvature")[:, 0], np.full(r.num_points, 1 / 20), rtol=3e-3)
    line = line_with_turn_path(10, 90, 5, 10, points_per_unit=3)
    rl = line.reparameterize(5, 1)
    assert not rl.closed
    assert line.length - 1 / 5 <= rl.length <= line.length + 1e-9  # open: arange(0, L, 1/ppu)
    assert_close(np.diff(rl.distances), np.full(rl.num_points - 1, 0.2), rtol=1e-2)


@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=3, max_size=20),
       st.booleans())
def test_tangent_unit_norm_and_arc_length(pts, closed):
    p = np.array(pts)
    seg = np.linalg.norm(np.diff(np.concatenate([p, p[:1]]) if closed else p, axis=0), axis=-1)
    assume(np.all(seg > 1e-3))
    s = Spline(p, closed)
    # unit up to the documented ``+1e-9`` added to the norm (the reference's): |‖t‖ − 1| ≤ 1e-9 / segment length
    assert_close(np.linalg.norm(s.track("tangent"), axis=-1), np.ones(len(p)), atol=1e-9 / seg.min() + 1e-12)
    assert s.length == pytest.approx(seg.sum(), rel=1e-12)
    assert np.all(np.abs(s.track("turning_angle")) <= math.pi + 1e-12)


def test_closed_versus_open():
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    op, cl = Spline(sq, closed=False), Spline(sq, closed=True)
    assert op.length == pytest.approx(3.0) and cl.length == pytest.approx(4.0)
    assert_close(cl.interpolate(4.5), [0.5, 0.0])        # wraps
    assert_close(cl.interpolate(3.5), [0.0, 0.5])        # closing segment
    assert_close(op.interpolate(3.5), [-0.5, 1.0])       # extrapolates the last segment
    assert_close(op.interpolate(-1.0), [-1.0, 0.0])      # and the first
    assert_close(cl.track("turning_angle")[:, 0], np.full(4, math.pi / 2))
    assert_close(op.track("tangent")[-1], [-1.0, 0.0])   # repeats the last segment
    assert_close(op.track("turning_angle")[:, 0], np.full(4, math.pi / 2))


def test_interpolation_of_linear_and_circular_tracks():
    s = Spline([[0.0, 0.0], [2.0, 0.0], [4.0, 0.0]],
               tracks={"speed": ([0.0, 1.0, 3.0], "linear"), "dir": ([[1.0, 0.0], [0.0, 1.0], [-1, 0]], "circular")})
    assert_close(s.interpolate([1.0, 3.0], "speed"), [[0.5], [2.0]])
    mid = s.interpolate(1.0, "dir")
    assert_close(mid, [math.sqrt(0.5), math.sqrt(0.5)])  # slerp keeps unit length (lerp would give 0.707/..)
    assert_close(s.interpolate(0.5, "dir"), [math.cos(math.pi / 8), math.sin(math.pi / 8)])
    assert s.track_kind("dir") == "circular"
    r = s.reparameterize(2, 0)
    assert set(r.track_names) == {"tangent", "turning_angle", "curvature", "speed", "dir"}
    assert_close(r.track("speed")[:, 0], [0.0, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 2.5])


def test_gaussian_filter_matches_loop_oracle_and_scipy():
    x = np.random.default_rng(0).standard_normal((30, 2))
    for mode in ("reflect", "wrap"):
        for sigma in (0.7, 5.0):
            assert_close(gaussian_filter1d(x, sigma, mode=mode), _gaussian_filter1d_naive(x, sigma, mode), atol=1e-13)
    short = x[:4]
    assert_close(gaussian_filter1d(short, 5.0), _gaussian_filter1d_naive(short, 5.0), atol=1e-13)
    assert_close(gaussian_filter1d(x, 0.0), x)
    ndimage = pytest.importorskip("scipy.ndimage")
    assert_close(gaussian_filter1d(x, 5.0), ndimage.gaussian_filter1d(x, 5.0, axis=0), atol=1e-13)
    assert_close(gaussian_filter1d(x, 2.0, mode="wrap"), ndimage.gaussian_filter1d(x, 2.0, axis=0, mode="wrap"),
                 atol=1e-13)


def test_builtin_paths():
    turn = line_with_turn_path(10, 90, 5, 10, points_per_unit=10)
    assert turn.length == pytest.approx(20 + 5 * math.pi / 2, abs=0.2)
    assert_close(turn.points[-1], [15.0, 15.0], atol=1e-9)
    assert turn.track("curvature").max() == pytest.approx(1 / 5, rel=1e-2)
    right = line_with_turn_path(10, -45, 5, 10)
    assert right.track("curvature").min() == pytest.approx(-1 / 5, rel=1e-2)
    eight = figure_eight_path(10)
    k = eight.track("curvature")[:, 0]
    assert eight.closed and k.max() > 0.1 and k.min() < -0.1   # turns both ways
    assert abs(eight.track("turning_angle").sum()) < 1e-9  # total turning of a figure eight is zero
    with pytest.raises(ValueError, match="radius"):
        circle_path(-1.0)


def test_read_path_csv(tmp_path):
    good = tmp_path / "p.csv"
    good.write_text("x,y\n0,0\n1,0\n\n# comment\n1,1\n")
    s = read_path_csv(good)
    assert s.num_points == 3 and s.length == pytest.approx(2.0)
    assert read_path_csv(good, closed=True).length == pytest.approx(2 + math.sqrt(2))
    for text, match in (("0,0\n1,0,3\n", ":2:"), ("0,0\n1,abc\n", ":2:"), ("0,0\n1,nan\n", ":2:"),
                        ("0,0\n", "at least"), ("0,0\n0,0\n", "zero length")):
        bad = tmp_path / "bad.csv"
        bad.write_text(text)
        with pytest.raises(ValueError, match=match):
            read_path_csv(bad)


def test_spline_errors():
    with pytest.raises(ValueError, match="shape"):
        Spline(np.zeros((3, 3)))
    with pytest.raises(ValueError, match="at least 3"):
        Spline([[0.0, 0], [1, 0]], closed=True)
    with pytest.raises(ValueError, match="kind"):
        Spline([[0.0, 0], [1, 0]], tracks={"a": ([1, 2], "cubic")})
    with pytest.raises(ValueError, match="no track"):
        Spline([[0.0, 0], [1, 0]]).track("speed")
