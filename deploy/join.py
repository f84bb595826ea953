"""ONNX builder of the join option ``join="inertialize"`` (``refimpl/protocols/transition_join.py``, spec/qtg.md §7.4).

:func:`inertialize_joins` appends to a graph the computation of
:func:`refimpl.protocols.transition_join.inertialize_joins` on a generated transition ``poses (B, T, P)`` (raw
poses) and its context ``past``, ``target (B, 2, P)``: the offset between the past's continuation and the first
frame, and between the last frame and the target's backward continuation, each decayed by Bollo's clamped quintic
(:func:`refimpl.protocols.transition_baselines.quintic_inertialization`) over ``blend_frames`` frames. ``T``, the
frame time and the blend are constants of the graph (the rollout's ``T`` is fixed at export), so the sample times
and the reversal of time are constant tensors.

``atan2`` has no ONNX operator: :func:`_atan2` builds it from ``Atan`` and ``Where`` (numpy's values except for
signed zeros). A graph cannot raise: normalisations divide by ``max(|q|, 1e-8)`` as the NumPy function does.

Shape legend: B batch, K frames, P pose size (3 + 4 J), J joints, C channels (1 + J).
"""
from __future__ import annotations

import numpy as np
import onnx

from deploy.graph import GraphBuilder
from deploy.quat import quat_mul, quat_normalize

__all__ = ["inertialize_joins", "join_metadata"]

_TINY = 1e-12
_CONJ = np.array([1.0, -1.0, -1.0, -1.0])


def join_metadata(mode: str, T: int, frame_rate: float, blend_frames: int, in_graph: bool) -> dict:
    """The ``join`` metadata entry: mode, blend, and where it is applied (in this graph or as a post-process)."""
    where = ("in this graph: the output poses are already joined" if in_graph else
             "not in this graph (a per-frame model cannot know the last frame): after the T frames, apply "
             "refimpl.protocols.transition_join.inertialize_joins(past, poses, target, dt=1/frame_rate, blend_frames) "
             "(deploy.models.qtg_io.Runtime.transition does)")
    return {"mode": mode, "blend_frames": int(blend_frames), "frame_time": 1.0 / float(frame_rate),
            "transition_length": int(T), "applied": where,
            "definition": "spec/qtg.md 7.4: the offset of the past's continuation p_0 + (p_0 - p_-1) from frame 1, "
                          "and of the target's backward continuation g1 + (g1 - g2) from frame T, each carried away "
                          "by Bollo's clamped quintic (spec/qtg.md 7.1) over blend_frames frames"}


def _atan(g: GraphBuilder, x: str, *, name: str) -> str:
    """``Atan``; in a float64 graph through float32 (onnxruntime has no float64 ``Atan`` kernel; the angle then
    carries float32 rounding, ~1e-7 relative)."""
    if g.dtype != np.float64:
        return g.node("Atan", [x], name)
    x32 = g.node("Cast", [x], f"{name}.f32", to=onnx.TensorProto.FLOAT)
    return g.node("Cast", [g.node("Atan", [x32], f"{name}.atan32")], name, to=onnx.TensorProto.DOUBLE)


def _atan2(g: GraphBuilder, y: str, x: str, *, name: str) -> str:
    """``atan2(y, x)`` elementwise (same shapes)."""
    zero = g.scalar(0.0)
    x_pos = g.node("Greater", [x, zero], f"{name}.x_pos")
    x_neg = g.node("Less", [x, zero], f"{name}.x_neg")
    y_neg = g.node("Less", [y, zero], f"{name}.y_neg")
    safe = g.node("Where", [g.node("Equal", [x, zero], f"{name}.x0"), g.scalar(1.0), x], f"{name}.safe_x")
    base = _atan(g, g.node("Div", [y, safe], f"{name}.ratio"), name=f"{name}.atan")
    shift = g.node("Where", [y_neg, g.scalar(-np.pi), g.scalar(np.pi)], f"{name}.shift")      # x < 0: ±π
    left = g.node("Add", [base, shift], f"{name}.left")
    axis = g.node("Where", [y_neg, g.scalar(-np.pi / 2), g.scalar(np.pi / 2)], f"{name}.axis")  # x = 0: ±π/2
    y0 = g.node("Equal", [y, zero], f"{name}.y0")
    axis = g.node("Where", [y0, zero, axis], f"{name}.axis0")
    return g.node("Where", [x_pos, base, g.node("Where", [x_neg, left, axis], f"{name}.nonpos")], name)


def _quintic(g: GraphBuilder, x0: str, v0: str, t1: float, times: np.ndarray, *, name: str) -> str:
    """Clamped quintic ``x(t)`` of :func:`refimpl.protocols.transition_baselines.quintic_inertialization` for
    ``x0, v0 (B, C)`` at the constant ``times (K,)`` → ``(B, C, K)``."""
    s = g.scalar
    v0 = g.node("Min", [v0, s(0.0)], f"{name}.v0")                                      # never away from 0
    neg = g.node("Less", [v0, s(0.0)], f"{name}.v0_neg")
    v_safe = g.node("Where", [neg, v0, s(-1.0)], f"{name}.v_safe")
    stop = g.node("Div", [g.node("Mul", [x0, s(-5.0)], f"{name}.m5x0"), v_safe], f"{name}.stop")
    t1v = g.node("Where", [neg, g.node("Min", [stop, s(t1)], f"{name}.t1min"),
                           g.node("Add", [g.node("Mul", [x0, s(0.0)], f"{name}.zeros"), s(t1)], f"{name}.t1c")],
                 f"{name}.t1")                                                               # no overshoot
    active = g.node("And", [g.node("Greater", [x0, s(_TINY)], f"{name}.x_on"),
                            g.node("Greater", [t1v, s(_TINY)], f"{name}.t_on")], f"{name}.active")
    t = g.node("Where", [active, t1v, s(1.0)], f"{name}.t1s")
    t2 = g.node("Mul", [t, t], f"{name}.t2")
    t3 = g.node("Mul", [t2, t], f"{name}.t3")
    vt = g.node("Mul", [v0, t], f"{name}.vt")
    a0 = g.node("Max", [g.node("Div", [g.node("Sub", [g.node("Mul", [vt, s(-8.0)], f"{name}.m8vt"),
                                                      g.node("Mul", [x0, s(20.0)], f"{name}.x20")], f"{name}.a0n"),
                                       t2], f"{name}.a0r"), s(0.0)], f"{name}.a0")
    at2 = g.node("Mul", [a0, t2], f"{name}.at2")

    def lin(ca, cv, cx, tag):  # ca a0 t1² + cv v0 t1 + cx x0
        terms = [g.node("Mul", [at2, s(ca)], f"{name}.{tag}a"), g.node("Mul", [vt, s(cv)], f"{name}.{tag}v"),
                 g.node("Mul", [x0, s(cx)], f"{name}.{tag}x")]
        return g.node("Add", [g.node("Add", terms[:2], f"{name}.{tag}av"), terms[2]], f"{name}.{tag}")

    A = g.node("Div", [lin(-1.0, -6.0, -12.0, "A"), g.node("Mul", [g.node("Mul", [t3, t2], f"{name}.t5"), s(2.0)],
                                                           f"{name}.2t5")], f"{name}.Ac")
    B = g.node("Div", [lin(3.0, 16.0, 30.0, "B"), g.node("Mul", [g.node("Mul", [t2, t2], f"{name}.t4"), s(2.0)],
                                                         f"{name}.2t4")], f"{name}.Bc")
    C = g.node("Div", [lin(-3.0, -12.0, -20.0, "C"), g.node("Mul", [t3, s(2.0)], f"{name}.2t3")], f"{name}.Cc")
    e = lambda a, tag: g.node("Unsqueeze", [a, g.ints([-1])], f"{name}.{tag}_e")  # noqa: E731  (B, C, 1)
    tk = g.weight(f"{name}.times", times)                                                   # (K,)
    x = e(A, "A")
    for coef, tag in ((B, "B"), (C, "C"), (g.node("Mul", [a0, s(0.5)], f"{name}.half_a0"), "a"), (v0, "v"),
                      (x0, "x")):
        x = g.node("Add", [g.node("Mul", [x, tk], f"{name}.h{tag}"), e(coef, tag)], f"{name}.p{tag}")
    keep = g.node("And", [e(active, "on"), g.node("Less", [tk, e(t1v, "t1")], f"{name}.before")], f"{name}.keep")
    return g.node("Where", [keep, x, s(0.0)], name)                                        # (B, C, K)


def _conj(g, q, *, name):
    return g.node("Mul", [q, g.shared("const.join.conj", _CONJ)], name)


def _pick(g, x, index: int, *, name):
    """``x[:, index]`` (the axis removed)."""
    return g.node("Gather", [x, g.constant(f"{name}.i", np.array(index, dtype=np.int64))], name, axis=1)


def _carry_offset(g: GraphBuilder, prev: str, frames: str, K: int, J: int, dt: float, t1: float, *,
                  name: str) -> str:
    """:func:`refimpl.protocols.transition_join.carry_offset`: ``prev (B, 2, P)``, ``frames (B, K, P)`` →
    ``(B, K, P)``."""
    P = 3 + 4 * J
    s = g.scalar

    def split(x, tag, lead):  # root (..., 3), unit quaternions (..., J, 4)
        root = g.node("Slice", [x, g.ints([0]), g.ints([3]), g.ints([-1])], f"{name}.{tag}_root")
        q = g.node("Slice", [x, g.ints([3]), g.ints([P]), g.ints([-1])], f"{name}.{tag}_qflat")
        q = g.node("Reshape", [q, g.ints([0] * lead + [J, 4])], f"{name}.{tag}_q")
        return root, quat_normalize(g, q, name=f"{name}.{tag}_qn")

    r_m1, q_m1 = split(_pick(g, prev, 0, name=f"{name}.pm1"), "m1", 1)                     # (B, 3), (B, J, 4)
    r_0, q_0 = split(_pick(g, prev, 1, name=f"{name}.p0"), "p0", 1)
    r_g, q_g = split(frames, "g", 2)                                                       # (B, K, 3), (B, K, J, 4)
    k2 = min(1, K - 1)
    r_g1, q_g1 = _pick(g, r_g, 0, name=f"{name}.rg1"), _pick(g, q_g, 0, name=f"{name}.qg1")
    r_g2, q_g2 = _pick(g, r_g, k2, name=f"{name}.rg2"), _pick(g, q_g, k2, name=f"{name}.qg2")

    # root
    two = s(2.0)
    off = g.node("Sub", [g.node("Sub", [g.node("Mul", [r_0, two], f"{name}.2r0"), r_m1], f"{name}.cont"), r_g1],
                 f"{name}.off")                                                            # (B, 3)
    x0 = g.node("Sqrt", [g.reduce("ReduceSumSquare", off, [-1], f"{name}.off2")], f"{name}.x0")  # (B, 1)
    axis = g.node("Div", [off, g.node("Where", [g.node("Greater", [x0, s(_TINY)], f"{name}.x0_on"), x0, s(1.0)],
                                      f"{name}.x0s")], f"{name}.axis")                     # (B, 3)
    g0 = g.node("Sub", [g.node("Mul", [r_g1, two], f"{name}.2rg1"), r_g2], f"{name}.rg0")
    xm1 = g.reduce("ReduceSum", g.node("Mul", [g.node("Sub", [r_0, g0], f"{name}.dm1r"), axis], f"{name}.pm1r"),
                   [-1], f"{name}.xm1")                                                    # (B, 1)

    # rotations
    cont = quat_mul(g, quat_mul(g, q_0, _conj(g, q_m1, name=f"{name}.cm1"), name=f"{name}.w0"), q_0,
                    name=f"{name}.qc")                                                     # (B, J, 4)
    gq0 = quat_mul(g, quat_mul(g, q_g1, _conj(g, q_g2, name=f"{name}.cg2"), name=f"{name}.wg"), q_g1,
                   name=f"{name}.qg0")
    d0 = quat_mul(g, cont, _conj(g, q_g1, name=f"{name}.cg1"), name=f"{name}.d0raw")
    w0 = g.node("Slice", [d0, g.ints([0]), g.ints([1]), g.ints([-1])], f"{name}.d0w")      # (B, J, 1)
    d0 = g.node("Where", [g.node("Less", [w0, s(0.0)], f"{name}.d0neg"), g.node("Neg", [d0], f"{name}.d0n"), d0],
                f"{name}.d0")
    dm1 = quat_mul(g, q_0, _conj(g, gq0, name=f"{name}.cg0"), name=f"{name}.dm1raw")
    dot = g.reduce("ReduceSum", g.node("Mul", [dm1, d0], f"{name}.dd"), [-1], f"{name}.dot")
    dm1 = g.node("Where", [g.node("Less", [dot, s(0.0)], f"{name}.dm1neg"), g.node("Neg", [dm1], f"{name}.dm1n"),
                           dm1], f"{name}.dm1")

    def wv(q, tag):  # w (B, J) and vector (B, J, 3)
        w = g.node("Slice", [q, g.ints([0]), g.ints([1]), g.ints([-1])], f"{name}.{tag}_w1")
        return (g.node("Squeeze", [w, g.ints([-1])], f"{name}.{tag}_w"),
                g.node("Slice", [q, g.ints([1]), g.ints([4]), g.ints([-1])], f"{name}.{tag}_v"))

    w0, v0 = wv(d0, "d0")
    wm1, vm1 = wv(dm1, "dm1")
    s0 = g.node("Sqrt", [g.reduce("ReduceSumSquare", v0, [-1], f"{name}.s02", keepdims=False)], f"{name}.s0")
    raxis = g.node("Div", [v0, g.node("Unsqueeze", [g.node("Where", [g.node("Greater", [s0, s(_TINY)],
                                                                              f"{name}.s0_on"), s0, s(1.0)],
                                                            f"{name}.s0s"), g.ints([-1])], f"{name}.s0e")],
                   f"{name}.raxis")                                                        # (B, J, 3)
    a0 = g.node("Mul", [_atan2(g, s0, w0, name=f"{name}.at0"), two], f"{name}.a0")        # (B, J)
    ym1 = g.reduce("ReduceSum", g.node("Mul", [vm1, raxis], f"{name}.vr"), [-1], f"{name}.ym1", keepdims=False)
    am1 = g.node("Mul", [_atan2(g, ym1, wm1, name=f"{name}.atm1"), two], f"{name}.am1")

    mag0 = g.node("Concat", [x0, a0], f"{name}.mag0", axis=1)                              # (B, C)
    magm1 = g.node("Concat", [xm1, am1], f"{name}.magm1", axis=1)
    vel = g.node("Div", [g.node("Sub", [mag0, magm1], f"{name}.dmag"), s(dt)], f"{name}.vel")
    x = _quintic(g, mag0, vel, t1, dt * np.arange(K), name=f"{name}.quintic")              # (B, C, K)

    xr = g.node("Unsqueeze", [_pick(g, x, 0, name=f"{name}.xroot"), g.ints([-1])], f"{name}.xr")  # (B, K, 1)
    root = g.node("Add", [r_g, g.node("Mul", [xr, g.node("Unsqueeze", [axis, g.ints([1])], f"{name}.axis_e")],
                                      f"{name}.rmove")], f"{name}.root")                   # (B, K, 3)
    ang = g.node("Slice", [x, g.ints([1]), g.ints([1 + J]), g.ints([1])], f"{name}.xang")  # (B, J, K)
    half = g.node("Unsqueeze", [g.node("Mul", [g.node("Transpose", [ang], f"{name}.angt", perm=[0, 2, 1]), s(0.5)],
                                       f"{name}.half0"), g.ints([-1])], f"{name}.half")    # (B, K, J, 1)
    vec = g.node("Mul", [g.node("Sin", [half], f"{name}.sin"), g.node("Unsqueeze", [raxis, g.ints([1])],
                                                                       f"{name}.raxis_e")], f"{name}.qvec")
    qoff = g.node("Concat", [g.node("Cos", [half], f"{name}.cos"), vec], f"{name}.qoff", axis=-1)  # (B, K, J, 4)
    quats = quat_mul(g, qoff, q_g, name=f"{name}.quats")                                   # (B, K, J, 4)
    flat = g.node("Reshape", [quats, g.ints([0, 0, 4 * J])], f"{name}.qflat_out")
    return g.node("Concat", [root, flat], name, axis=-1)                                   # (B, K, P)


def inertialize_joins(g: GraphBuilder, past: str, poses: str, target: str, T: int, P: int, frame_rate: float,
                      blend_frames: int, *, name: str = "join") -> str:
    """Append ``join="inertialize"`` to a graph: ``past (B, 2, P)``, ``poses (B, T, P)`` (raw),
    ``target (B, 2, P)`` → joined poses ``(B, T, P)`` with unit quaternions.

    Parameters
    ----------
    T, P : int
        Frames (fixed) and pose size.
    frame_rate : float
        Frames per second (``dt = 1 / frame_rate``).
    blend_frames : int
        Frames of each blend (:func:`refimpl.protocols.transition_join.join_blend_frames`).
    """
    if (P - 3) % 4 or P < 7:
        raise ValueError(f"P: expected a pose size 3 + 4 J, got {P}")
    dt = 1.0 / float(frame_rate)
    t1 = blend_frames * dt
    J = (P - 3) // 4
    start = _carry_offset(g, past, poses, T, J, dt, t1, name=f"{name}.start")
    rev = g.constant(f"{name}.reverse", np.arange(T - 1, -1, -1, dtype=np.int64))
    back = g.constant(f"{name}.target_reverse", np.array([1, 0], dtype=np.int64))
    end = _carry_offset(g, g.node("Gather", [target, back], f"{name}.target_rev", axis=1),
                        g.node("Gather", [start, rev], f"{name}.start_rev", axis=1), T, J, dt, t1, name=f"{name}.end")
    return g.node("Gather", [end, rev], name, axis=1)
