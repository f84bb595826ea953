"""Arc-length parameterised 2-D polylines with tracks, for paths on the ground (spec/locomotion.md §2).

QuaterNet §3.7 represents a trajectory "as a piecewise linear spline with equal-length segments" and the pace
network recurs over its points (spec/locomotion.md §2). A :class:`Spline` is ``n`` points
``(x, y)`` on the ground plane (for this project's Y-up data: world ``(x, z)``), open or closed, with the
cumulative arc length at every point and named per-point *tracks*:

* ``"tangent"`` (circular, ``(n, 2)``): unit vector to the next point, ``p[i+1] - p[i]`` (wrapping when closed;
  an open curve's last point repeats the last segment's direction), normalised with ``+1e-9``.
* ``"turning_angle"`` (linear, ``(n, 1)``): the signed angle from ``tangent[i]`` to ``tangent[i+1]``,
  ``atan2(t0 × t1, t0 · t1)`` (wrapping when closed), positive for a counter-clockwise turn in the ``(x, y)`` plane. This is
  the reference code's ``"curvature"`` track, an angle per point; the pace network reads it.
* ``"curvature"`` (linear, ``(n, 1)``): signed curvature in 1/length, ``turning_angle[i] / ℓ_i`` with ``ℓ_i`` the
  mean of the two segments meeting at point ``i + 1`` (so a circle of radius r sampled anywhere gives ``±1/r``).
* user tracks: ``"linear"`` (interpolated linearly) or ``"circular"`` (2-D directions, interpolated by slerp).

:meth:`Spline.reparameterize` resamples at a density of ``ppu`` points per unit length; the new points are the
old curve sampled at equal arc-length steps, while the tangent / turning angle / curvature and the linear
tracks are computed from (or on) Gaussian-smoothed samples, σ = ``ppu · smoothing`` samples (the reference:
``ppu = 5``, ``smoothing = 1``). The Gaussian filter is :func:`gaussian_filter1d` (scipy's with
``truncate = 4``; mode ``"reflect"`` for open curves and ``"wrap"`` for closed ones).

Built-in paths: :func:`circle_path`, :func:`figure_eight_path`, :func:`line_with_turn_path`, and
:func:`read_path_csv` for a CSV file of points.

Shape legend: N points, M query distances, D track width (1 linear scalar, 2 directions).
"""
from __future__ import annotations

import math
import os
from typing import Mapping

import numpy as np

from refimpl.files import read_text

__all__ = [
    "Spline", "gaussian_filter1d", "circle_path", "figure_eight_path", "line_with_turn_path", "read_path_csv",
    "TANGENT_EPS", "SLERP_MIN_ANGLE",
]

#: Added to a norm before normalising a tangent (the reference's ``+1e-9``).
TANGENT_EPS = 1e-9
#: Below this angle (radians) between two directions, a circular track is interpolated linearly.
SLERP_MIN_ANGLE = 1e-3
_BUILTIN = ("tangent", "turning_angle", "curvature")
_KINDS = ("linear", "circular")


# --------------------------------------------------------------------------------------------------------------
# Gaussian smoothing (NumPy version of scipy.ndimage.gaussian_filter1d for the modes used here)
# --------------------------------------------------------------------------------------------------------------

def _gaussian_kernel(sigma: float, truncate: float) -> np.ndarray:
    radius = int(truncate * sigma + 0.5)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    w = np.exp(-0.5 * (x / sigma) ** 2)
    return w / w.sum()


def gaussian_filter1d(x, sigma: float, axis: int = 0, mode: str = "reflect", truncate: float = 4.0) -> np.ndarray:
    """Gaussian smoothing along one axis (``scipy.ndimage.gaussian_filter1d`` for ``order=0``).

    Weights ``exp(-k² / (2σ²))`` for ``|k| <= radius = int(truncate·σ + 0.5)``, normalised to sum 1.

    Parameters
    ----------
    x : array_like (..., N, ...), float
    sigma : float >= 0
        Standard deviation in samples; 0 returns a float64 copy.
    axis : int
    mode : {"reflect", "wrap"}
        ``"reflect"``: ``d c b a | a b c d | d c b a`` (scipy's ``reflect``, NumPy's ``symmetric``);
        ``"wrap"``: periodic (closed curves).
    truncate : float > 0

    Returns
    -------
    ndarray, shape of ``x``, float64.
    """
    a = np.asarray(x, dtype=np.float64)
    if not (math.isfinite(float(sigma)) and sigma >= 0):
        raise ValueError(f"sigma: expected a finite number >= 0, got {sigma!r}")
    if mode not in ("reflect", "wrap"):
        raise ValueError(f"mode: expected 'reflect' or 'wrap', got {mode!r}")
    if not (math.isfinite(float(truncate)) and truncate > 0):
        raise ValueError(f"truncate: expected a positive number, got {truncate!r}")
    if sigma == 0 or a.shape[axis] == 0:
        return a.copy()
    w = _gaussian_kernel(float(sigma), float(truncate))
    radius = (w.size - 1) // 2
    moved = np.moveaxis(a, axis, -1)                                        # (..., N)
    pad = [(0, 0)] * (moved.ndim - 1) + [(radius, radius)]
    padded = np.pad(moved, pad, mode="symmetric" if mode == "reflect" else "wrap")
    win = np.lib.stride_tricks.sliding_window_view(padded, w.size, axis=-1)  # (..., N, K)
    out = win @ w[::-1]                                                     # (..., N)
    return np.moveaxis(out, -1, axis)


def _gaussian_filter1d_naive(x: np.ndarray, sigma: float, mode: str = "reflect", truncate: float = 4.0):
    """Loop oracle for :func:`gaussian_filter1d` along axis 0 (index reflection / wrap done by hand)."""
    w = _gaussian_kernel(sigma, truncate)
    radius = (w.size - 1) // 2
    n = x.shape[0]
    out = np.zeros(x.shape, dtype=np.float64)
    for i in range(n):
        for k in range(-radius, radius + 1):
            j = i + k
            if mode == "wrap":
                j %= n
            else:
                period = 2 * n
                j %= period
                if j >= n:
                    j = period - 1 - j
            out[i] = out[i] + w[k + radius] * x[j]
    return out


# --------------------------------------------------------------------------------------------------------------
# geometry kernels
# --------------------------------------------------------------------------------------------------------------

def _segments(points: np.ndarray, closed: bool) -> np.ndarray:
    """Segment vectors (S, 2): ``p[i+1] - p[i]``, plus ``p[0] - p[-1]`` when closed."""
    nxt = np.roll(points, -1, axis=0) if closed else points[1:]
    return nxt - (points if closed else points[:-1])


def _tangents(points: np.ndarray, closed: bool) -> np.ndarray:
    seg = _segments(points, closed)                                         # (S, 2)
    if not closed:
        seg = np.concatenate([seg, seg[-1:]], axis=0)                       # (N, 2)
    return seg / (np.linalg.norm(seg, axis=-1, keepdims=True) + TANGENT_EPS)


def _signed_angle(t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """Signed angle from 2-D vectors t0 to t1 (counter-clockwise positive), shape (...,)."""
    cross = t0[..., 0] * t1[..., 1] - t0[..., 1] * t1[..., 0]
    dot = t0[..., 0] * t1[..., 0] + t0[..., 1] * t1[..., 1]
    return np.arctan2(cross, dot)


def _turning(points: np.ndarray, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """Per point: turning angle from tangent i to tangent i+1 and the curvature (angle / mean segment length)."""
    n = points.shape[0]
    seg_len = np.linalg.norm(_segments(points, closed), axis=-1)           # (S,)
    tan = _tangents(points, closed)                                         # (N, 2)
    if closed:
        ang = _signed_angle(tan, np.roll(tan, -1, axis=0))                 # (N,)
        ell = 0.5 * (seg_len + np.roll(seg_len, -1))                        # segments i and i+1
    else:
        if n < 3:
            return np.zeros(n), np.zeros(n)
        inner = _signed_angle(tan[:n - 2], tan[1:n - 1])                    # at points 1..n-2, (N-2,)
        ang = np.concatenate([inner, inner[-1:], inner[-1:]])               # last two repeat the last turn
        ell_in = 0.5 * (seg_len[:-1] + seg_len[1:])                         # (N-2,)
        ell = np.concatenate([ell_in, ell_in[-1:], ell_in[-1:]])
    curv = ang / np.maximum(ell, TANGENT_EPS)
    return ang, curv


# --------------------------------------------------------------------------------------------------------------
# Spline
# --------------------------------------------------------------------------------------------------------------

def _check_points(points, name="points") -> np.ndarray:
    p = np.array(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ValueError(f"{name}: expected shape (N, 2), got {p.shape}")
    if p.shape[0] < 2:
        raise ValueError(f"{name}: expected at least 2 points, got {p.shape[0]}")
    if not np.all(np.isfinite(p)):
        raise ValueError(f"{name}: expected finite values, got NaN or inf")
    return p


class Spline:
    """A piecewise-linear 2-D curve parameterised by arc length, with per-point tracks.

    Parameters
    ----------
    points : array_like (N, 2)
        N >= 2 points (N >= 3 when closed); consecutive points must differ (zero-length segments are refused).
    closed : bool
        Closed curves have a last segment from ``points[-1]`` back to ``points[0]``.
    tracks : mapping name -> (values (N, D) or (N,), kind), optional
        Extra tracks; ``kind`` is ``"linear"`` or ``"circular"`` (2-D directions). The built-in tracks
        (``tangent``, ``turning_angle``, ``curvature``) may be given to override the values computed from
        ``points`` (:meth:`reparameterize` does this with the smoothed ones).

    Attributes
    ----------
    points : (N, 2) float64, read-only
    closed : bool
    segment_lengths : (S,) with S = N (closed) or N - 1 (open)
    distances : (N,) arc length at each point (``distances[0] = 0``)
    length : float, total length (closed curves include the closing segment)
    """

    def __init__(self, points, closed: bool = False, tracks: Mapping[str, tuple] | None = None):
        p = _check_points(points)
        closed = bool(closed)
        if closed and p.shape[0] < 3:
            raise ValueError(f"points: a closed curve needs at least 3 points, got {p.shape[0]}")
        with np.errstate(over="ignore", invalid="ignore"):
            seg_len = np.linalg.norm(_segments(p, closed), axis=-1)        # (S,)
            total = float(np.sum(seg_len))
        if not math.isfinite(total):
            raise ValueError("points: the coordinates are too large (the path's length overflows)")
        if np.any(seg_len <= 0):
            k = int(np.flatnonzero(seg_len <= 0)[0])
            raise ValueError(f"points: segment {k} has zero length (points {k} and {(k + 1) % p.shape[0]} coincide)")
        dist = np.concatenate([[0.0], np.cumsum(seg_len)])                 # (S+1,)
        self._points = p
        self._closed = closed
        self._seg_len = seg_len
        self._cum = dist
        self._tracks: dict[str, tuple[np.ndarray, str]] = {}
        ang, curv = _turning(p, closed)
        self._tracks["tangent"] = (_tangents(p, closed), "circular")
        self._tracks["turning_angle"] = (ang[:, None], "linear")
        self._tracks["curvature"] = (curv[:, None], "linear")
        for name, spec in (tracks or {}).items():
            self._set_track(name, spec)
        for a in (self._points, self._seg_len, self._cum):
            a.flags.writeable = False

    def _set_track(self, name, spec):
        if not isinstance(name, str) or not name:
            raise ValueError(f"tracks: expected non-empty str names, got {name!r}")
        try:
            values, kind = spec
        except (TypeError, ValueError):
            raise ValueError(f"tracks[{name!r}]: expected a pair (values, kind)") from None
        if kind not in _KINDS:
            raise ValueError(f"tracks[{name!r}]: kind must be 'linear' or 'circular', got {kind!r}")
        v = np.array(values, dtype=np.float64)
        if v.ndim == 1:
            v = v[:, None]
        n = self._points.shape[0]
        if v.ndim != 2 or v.shape[0] != n:
            raise ValueError(f"tracks[{name!r}]: expected shape ({n}, D) or ({n},), got {np.shape(values)}")
        if kind == "circular" and v.shape[1] != 2:
            raise ValueError(f"tracks[{name!r}]: a circular track holds 2-D directions (N, 2), got {v.shape}")
        if name in _BUILTIN and (kind != self._tracks[name][1] or v.shape[1] != self._tracks[name][0].shape[1]):
            raise ValueError(f"tracks[{name!r}]: a built-in track keeps its kind and width "
                             f"({self._tracks[name][1]}, {self._tracks[name][0].shape[1]})")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"tracks[{name!r}]: expected finite values")
        v.flags.writeable = False
        self._tracks[name] = (v, kind)

    # -- attributes ---------------------------------------------------------------------------------------------
    points = property(lambda self: self._points, doc="(N, 2) points, read-only.")
    closed = property(lambda self: self._closed, doc="True for a closed curve.")
    segment_lengths = property(lambda self: self._seg_len, doc="(S,) segment lengths.")

    @property
    def distances(self) -> np.ndarray:
        """(N,) arc length at each point."""
        return self._cum[:self._points.shape[0]]

    @property
    def length(self) -> float:
        """Total arc length."""
        return float(self._cum[-1])

    @property
    def num_points(self) -> int:
        return int(self._points.shape[0])

    @property
    def track_names(self) -> tuple[str, ...]:
        return tuple(self._tracks)

    def track(self, name: str) -> np.ndarray:
        """Per-point values of a track, ``(N, D)`` (read-only)."""
        if name not in self._tracks:
            raise ValueError(f"name: no track {name!r}; tracks are {list(self._tracks)}")
        return self._tracks[name][0]

    def track_kind(self, name: str) -> str:
        self.track(name)
        return self._tracks[name][1]

    def with_tracks(self, **tracks) -> "Spline":
        """A new spline with the same points and extra (or replaced) tracks ``name=(values, kind)``."""
        all_tracks = {k: v for k, v in self._tracks.items() if k not in _BUILTIN}
        all_tracks.update(tracks)
        sp = Spline(self._points, self._closed, all_tracks)
        for name in _BUILTIN:  # keep overridden built-ins unless replaced
            if name not in tracks:
                sp._tracks[name] = self._tracks[name]
        return sp

    def __repr__(self) -> str:
        return (f"Spline(num_points={self.num_points}, closed={self._closed}, length={self.length:.6g}, "
                f"tracks={list(self._tracks)})")

    # -- interpolation ------------------------------------------------------------------------------------------
    def _locate(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Segment index i, end index j and fraction t for distances d (M,)."""
        n = self._points.shape[0]
        if self._closed:
            d = np.mod(d, self.length)
            i = np.clip(np.searchsorted(self._cum, d, side="right") - 1, 0, n - 1)
            j = (i + 1) % n
        else:
            i = np.clip(np.searchsorted(self._cum, d, side="right") - 1, 0, n - 2)
            j = i + 1
        t = (d - self._cum[i]) / self._seg_len[i]
        return i, j, t

    def interpolate(self, distance, track: str | None = None) -> np.ndarray:
        """Values at arc-length ``distance``: points (no track) or a track.

        Closed curves wrap ``distance`` modulo the length; open curves extrapolate linearly beyond their ends.
        Linear tracks and points are interpolated linearly; circular tracks by slerp of the two unit directions
        (linearly when their angle is below :data:`SLERP_MIN_ANGLE`; the angle comes from the normalised dot
        product clipped to [-1, 1]).

        Parameters
        ----------
        distance : float or array_like (...)
        track : str, optional

        Returns
        -------
        ndarray (..., 2) for points, (..., D) for a track.
        """
        d = np.asarray(distance, dtype=np.float64)
        if not np.all(np.isfinite(d)):
            raise ValueError("distance: expected finite values")
        shape = d.shape
        i, j, t = self._locate(d.reshape(-1))
        if track is None:
            v, kind = self._points, "linear"
        else:
            v, kind = self.track(track), self._tracks[track][1]
        a, b = v[i], v[j]                                                   # (M, D)
        tt = t[:, None]
        if kind == "linear":
            out = a + tt * (b - a)
        else:
            out = _slerp2(a, b, tt)
        return out.reshape(*shape, v.shape[1])

    # -- resampling ---------------------------------------------------------------------------------------------
    def reparameterize(self, points_per_unit: float = 5.0, smoothing: float = 1.0) -> "Spline":
        """Resample at ``points_per_unit`` points per unit of length (equal-length steps), with smoothing.

        Sample distances: closed, ``linspace(0, L, ceil(L·ppu), endpoint=False)``; open, ``arange(0, L, 1/ppu)``
        (the reference's choice: an open curve loses its last ``< 1/ppu`` of length). The new points are the
        curve at those distances (unsmoothed); ``tangent``, ``turning_angle`` and ``curvature`` are computed from
        the points Gaussian-smoothed with σ = ``ppu · smoothing`` samples; other linear tracks are resampled and
        smoothed the same way; circular tracks are resampled only.

        Parameters
        ----------
        points_per_unit : float > 0
        smoothing : float >= 0
            In length units (σ in samples is ``points_per_unit · smoothing``); 0 disables smoothing.

        Returns
        -------
        Spline
        """
        ppu = float(points_per_unit)
        if not (math.isfinite(ppu) and ppu > 0):
            raise ValueError(f"points_per_unit: expected a positive number, got {points_per_unit!r}")
        if not (math.isfinite(float(smoothing)) and smoothing >= 0):
            raise ValueError(f"smoothing: expected a number >= 0, got {smoothing!r}")
        length = self.length
        if self._closed:
            d = np.linspace(0.0, length, int(math.ceil(length * ppu)), endpoint=False)
        else:
            d = np.arange(0.0, length, 1.0 / ppu)
        minimum = 3 if self._closed else 2
        if d.size < minimum:
            raise ValueError(f"points_per_unit: {ppu} gives {d.size} samples on a curve of length {length:.6g}; "
                             f"at least {minimum} are needed")
        mode = "wrap" if self._closed else "reflect"
        sigma = ppu * float(smoothing)
        new_pts = self.interpolate(d)                                       # (M, 2)
        smooth_pts = gaussian_filter1d(new_pts, sigma, axis=0, mode=mode)
        ang, curv = _turning(smooth_pts, self._closed)
        tracks = {"tangent": (_tangents(smooth_pts, self._closed), "circular"),
                  "turning_angle": (ang, "linear"), "curvature": (curv, "linear")}
        for name, (_, kind) in self._tracks.items():
            if name in _BUILTIN:
                continue
            vals = self.interpolate(d, name)
            if kind == "linear":
                vals = gaussian_filter1d(vals, sigma, axis=0, mode=mode)
            tracks[name] = (vals, kind)
        return Spline(new_pts, self._closed, tracks)


def _slerp2(a: np.ndarray, b: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Slerp between 2-D directions a, b (M, 2) at fractions t (M, 1); lerp where the angle is tiny."""
    na = np.linalg.norm(a, axis=-1, keepdims=True)
    nb = np.linalg.norm(b, axis=-1, keepdims=True)
    cos = np.clip(np.sum(a * b, axis=-1, keepdims=True) / np.maximum(na * nb, 1e-300), -1.0, 1.0)
    omega = np.arccos(cos)                                                  # (M, 1)
    lerp = a + t * (b - a)
    small = omega < SLERP_MIN_ANGLE
    s = np.where(small, 1.0, np.sin(omega))
    slerp = (np.sin((1 - t) * omega) * a + np.sin(t * omega) * b) / s
    return np.where(small, lerp, slerp)


# --------------------------------------------------------------------------------------------------------------
# built-in paths
# --------------------------------------------------------------------------------------------------------------

def _positive(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected a positive number, got {value!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name}: expected a positive number, got {value!r}")
    return v


def circle_path(radius: float, points_per_unit: float = 5.0, clockwise: bool = False,
                center=(0.0, 0.0)) -> Spline:
    """Closed circle of ``radius`` starting at ``center + (radius, 0)``, ``ceil(2πr·ppu)`` points (at least 8).

    Counter-clockwise (curvature ``+1/r``) unless ``clockwise`` (``-1/r``).
    """
    r = _positive(radius, "radius")
    ppu = _positive(points_per_unit, "points_per_unit")
    n = max(8, int(math.ceil(2 * math.pi * r * ppu)))
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    if clockwise:
        a = -a
    c = np.asarray(center, dtype=np.float64).reshape(2)
    return Spline(c + r * np.stack([np.cos(a), np.sin(a)], axis=-1), closed=True)


def figure_eight_path(size: float, num_points: int = 400) -> Spline:
    """Closed figure eight (lemniscate of Gerono) ``(size·sin s, size·sin s cos s)``, ``s ∈ [0, 2π)``.

    Width ``2·size``, height ``size``; it crosses itself at the origin, turning left on one lobe and right on the
    other.
    """
    a = _positive(size, "size")
    if isinstance(num_points, bool) or not isinstance(num_points, (int, np.integer)) or num_points < 8:
        raise ValueError(f"num_points: expected an int >= 8, got {num_points!r}")
    s = np.linspace(0.0, 2 * math.pi, int(num_points), endpoint=False)
    return Spline(np.stack([a * np.sin(s), a * np.sin(s) * np.cos(s)], axis=-1), closed=True)


def line_with_turn_path(length_before: float, turn_degrees: float, radius: float, length_after: float,
                        points_per_unit: float = 5.0) -> Spline:
    """Open path: a straight line along +x, a circular arc of ``radius`` turning by ``turn_degrees``
    (positive = left, counter-clockwise), then a straight line; sampled at about ``points_per_unit``.
    """
    l1 = _positive(length_before, "length_before")
    l2 = _positive(length_after, "length_after")
    r = _positive(radius, "radius")
    ppu = _positive(points_per_unit, "points_per_unit")
    turn = math.radians(float(turn_degrees))
    if not math.isfinite(turn) or abs(turn) >= 2 * math.pi:
        raise ValueError(f"turn_degrees: expected a finite angle in (-360, 360), got {turn_degrees!r}")
    step = 1.0 / ppu
    xs = np.arange(0.0, l1, step)
    first = np.stack([xs, np.zeros_like(xs)], axis=-1)
    sign = 1.0 if turn >= 0 else -1.0
    centre = np.array([l1, sign * r])
    arc_len = abs(turn) * r
    m = max(1, int(math.ceil(arc_len / step)))
    phi = np.linspace(0.0, abs(turn), m, endpoint=False)
    # start angle of the radius vector (from the centre to the start point) is -90° (left turn) or +90° (right)
    start = -sign * math.pi / 2
    arc = centre + r * np.stack([np.cos(start + sign * phi), np.sin(start + sign * phi)], axis=-1)
    end_angle = start + sign * abs(turn)
    end = centre + r * np.array([math.cos(end_angle), math.sin(end_angle)])
    direction = np.array([math.cos(turn), math.sin(turn)])
    k = np.arange(0.0, l2 + 0.5 * step, step)
    second = end + k[:, None] * direction
    pts = np.concatenate([first, arc if turn != 0 else np.empty((0, 2)), second], axis=0)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(pts, axis=0), axis=-1) > 1e-12])
    return Spline(pts[keep], closed=False)


def read_path_csv(path, closed: bool = False) -> Spline:
    """Read a path from a CSV file of 2-D points, one ``x,y`` pair per line.

    Blank lines and lines starting with ``#`` are skipped; a first line that is not numeric is taken as a header.

    Raises
    ------
    ValueError
        ``"<file>:<line>: ..."`` for a row without exactly two finite numbers; too few points; repeated
        consecutive points.
    """
    where = os.fspath(path)
    try:
        text = read_text(path)
    except UnicodeDecodeError as exc:
        raise ValueError(f"{where}: not a UTF-8/ASCII text file ({exc})") from None
    rows = []
    first_data = True
    for k, line in enumerate(text.replace("\r\n", "\n").replace("\r", "\n").split("\n"), start=1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = [c.strip() for c in s.split(",")]
        try:
            vals = [float(c) for c in parts]
        except ValueError:
            if first_data and not any(_is_number(c) for c in parts):
                first_data = False
                continue  # header
            raise ValueError(f"{where}:{k}: expected two numbers 'x,y', got {s[:60]!r}") from None
        first_data = False
        if len(vals) != 2:
            raise ValueError(f"{where}:{k}: expected two numbers 'x,y', got {len(vals)} values")
        if not all(math.isfinite(v) for v in vals):
            raise ValueError(f"{where}:{k}: expected finite numbers, got {s[:60]!r}")
        rows.append(vals)
    if len(rows) < (3 if closed else 2):
        raise ValueError(f"{where}: expected at least {3 if closed else 2} points, got {len(rows)}")
    try:
        return Spline(np.array(rows), closed=closed)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None


def _is_number(text: str) -> bool:
    try:
        float(text)
        return True
    except ValueError:
        return False
