"""Fuzz campaign for the math API (spec/robustness.md §8).

Calls every public function of ``refimpl.quat``, ``refimpl.rotations``, ``refimpl.dualquat``, ``refimpl.skeleton``,
``refimpl.current_dq`` and ``refimpl.mirroring`` (the ``Skeleton`` constructor and methods included) with hostile
arguments and checks the contract:

* the only exception that escapes is ``ValueError``;
* nothing takes longer than ``--limit`` seconds (1 s; a ``SIGALRM`` at 5 × the limit stops a real hang);
* a result computed from finite input is finite (every function documents a finite result or ``ValueError``);
* an argument holding NaN or inf is refused (``AcceptedNonFinite`` otherwise).

Families (one is drawn per case, then one target and, where it applies, one argument to spoil):

=============  ======================================================================================
``huge``       an array argument scaled to ~1e250 … 1.7e308 (whole array, one entry, or the largest float)
``tiny``       scaled to 1e-300 … 1e-308
``denormal``   scaled into the subnormal range (5e-324 … 1e-310)
``mixed``      every entry of random sign and magnitude 10^U(-320, 308)
``nonfinite``  one entry NaN, +inf or -inf
``dtype``      object, int64 (large values), bool, uint8, complex, string, bytes, None, datetime64, float16,
               float32, long double, a Python list of strings, a ragged list, a dict
``shape``      last axis one too long or short, 0-d, one axis dropped, an extra trailing axis
``empty``      a leading axis of length 0
``zero``       all-zero array (zero quaternions, zero DQ real parts, zero matrices)
``broadcast``  leading axes that do not broadcast with the other arguments
``scalar``     a non-array argument (order, eps, tolerances, parents, names, joints, axis, low/high, t)
               replaced by junk: None, NaN, inf, strings, floats, bools, huge ints, nested lists
=============  ======================================================================================

The cases are built by ``make_case(rng)`` from a ``random.Random`` (``tests/test_fuzz_math.py`` runs a few
hundred of them); ``run_case`` classifies one.

Usage::

    python -m tests.fuzz.math_api --cases 10000 [--seed 0] [--limit 1.0] [--out tests/fuzz/results/fuzz_math.json]

Prints a table of outcomes per family and per target, writes JSON (atomically), exits 1 on any failure.
"""
from __future__ import annotations

import argparse
import json
import math
import random
import signal
import sys
import time
import warnings
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

from refimpl import current_dq as CD  # noqa: E402
from refimpl import dualquat as DQ  # noqa: E402
from refimpl import mirroring as MI  # noqa: E402
from refimpl import quat as Q  # noqa: E402
from refimpl import rotations as R  # noqa: E402
from refimpl import skeleton as S  # noqa: E402
from refimpl.atomic import atomic_write_text  # noqa: E402

FAMILIES = ("huge", "tiny", "denormal", "mixed", "nonfinite", "dtype", "shape", "empty", "zero", "broadcast",
            "scalar")
PARENTS = [-1, 0, 1, 1, 3]
J = len(PARENTS)


# ------------------------------------------------------------------------------------------------------------
# valid arguments by kind: array kinds take the leading shape
# ------------------------------------------------------------------------------------------------------------

def _uq(g, lead):
    q = g.standard_normal(lead + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _udq(g, lead):
    return DQ.dq_from_quat_translation(_uq(g, lead), g.standard_normal(lead + (3,)))


def _rot(g, lead):
    return R.matrix_from_quat(_uq(g, lead))


def _homog(g, lead):
    m = np.zeros(lead + (4, 4))
    m[..., :3, :3] = _rot(g, lead)
    m[..., :3, 3] = g.standard_normal(lead + (3,))
    m[..., 3, 3] = 1
    return m


ARRAY_KINDS = {  # kind -> (factory(g, lead), trailing shape)
    "q": (_uq, (4,)), "v": (lambda g, lead: g.standard_normal(lead + (3,)), (3,)),
    "dq": (_udq, (8,)), "m3": (_rot, (3, 3)), "m4": (_homog, (4, 4)),
    "x6": (lambda g, lead: np.concatenate([_rot(g, lead)[..., :, 0], _rot(g, lead)[..., :, 1]], axis=-1), (6,)),
    "t": (lambda g, lead: g.uniform(-0.5, 1.5, lead), ()),
    "qT": (lambda g, lead: _uq(g, (3,) + lead), (4,)), "dqT": (lambda g, lead: _udq(g, (3,) + lead), (8,)),
    "w": (lambda g, lead: g.uniform(0.1, 1, lead + (3,)), (3,)), "dqs": (lambda g, lead: _udq(g, lead + (3,)), (3, 8)),
    "rotJ": (lambda g, lead: _uq(g, lead + (J,)), (J, 4)), "dqJ": (lambda g, lead: _udq(g, lead + (J,)), (J, 8)),
    "offJ": (lambda g, lead: g.standard_normal((J, 3)), (J, 3)), "root": (lambda g, lead: g.standard_normal(lead + (3,)), (3,)),
    "angle": (lambda g, lead: g.uniform(-3, 3, lead), ()),
}

SCALAR_KINDS = {  # kind -> (valid value, junk values)
    "order": ("zyx", [None, 5, "abc", "xx", "", "zyxz", b"zyx", ["z", "y", "x"], np.array(["zyx"])]),
    "eps": (1e-9, [None, "1e-9", math.nan, math.inf, -1.0, [1e-9], np.array([1.0, 2.0]), 1j, True]),
    "atol": (1e-6, [None, "x", math.nan, -math.inf, -1.0, [1e-6], 1j, object()]),
    "parents": (PARENTS, [None, 5, "abc", [], [[-1, 0]], [-1, 0.5, 1, 1, 3], [-1, 0, 1, 1, 2 ** 70], [0, 0, 1, 1, 3],
                          [-1, -1, 1, 1, 3], [-1, 0, 1, 1], [-1, 0, 1, 1, 3, 4], [-1, 0, 5, 1, 3], [-1, "0", 1, 1, 3],
                          [-1, None, 1, 1, 3], [-1, True, 1, 1, 3], [-1, 0, 1, 1, math.nan], {"a": 1}]),
    "names": (None, [5, "abcde", ["a"] * J, ["a", "b", "c", "d", 5], ["a", "b", "", "d", "e"], [None] * J, {"x": 1},
                     [b"a", b"b", b"c", b"d", b"e"]]),
    "ends": ((), [5, "2", [None], [1.5], [math.inf], [math.nan], [0], [1], [J], [-1], [2 ** 70], [True], [[2]],
                 np.array([2.0])]),
    "pairs": (None, [5, "12", [None], [1.5], [math.inf], [J + 3], [-1], [2 ** 70], [True]]),
    "joints": ([2], [5, None, "joint_2", [None], [1.5], [math.inf], [math.nan], [0], [J], [-1], [2 ** 70], ["nope"],
                     [True], [[2]], np.array([2.5])]),
    "offmode": ("compose", [None, "x", 5, ["compose"], np.array(["drop", "drop"])]),
    "axis": ("x", [None, "w", 3, -1, 1.5, ["x"], b"x", True]),
    "lowhigh": (-1.0, [None, "a", math.nan, math.inf, -1e308, 1e308, 1j, [1.0], True]),
    "rng": (None, [None, 5, "rng", np.random.RandomState(0)]),
    "shape": ((2,), [None, "abc", -1, (-1,), (1.5,), 2 ** 70, (2 ** 40, 2 ** 40), (True,), [[2]], 1e3]),
    "dtype": (np.float64, [None, "foo", object, np.int64, complex, "U3", bool, 5]),
    "mirror_offsets": (False, [False]),
}


def _skeleton():
    return S.Skeleton(PARENTS, np.random.default_rng(1).standard_normal((J, 3)),
                      names=["Hips", "Spine", "Head", "LeftArm", "LeftHand"])


# ------------------------------------------------------------------------------------------------------------
# targets: name -> (callable, [(argument name, kind)], leading shapes broadcast jointly)
# ------------------------------------------------------------------------------------------------------------

def _targets():
    t = {}
    q1 = [("q", "q")]
    for n in ("quat_conj", "quat_inv", "quat_norm", "quat_exp", "quat_log", "quat_canonical", "quat_xyzw_from_wxyz",
              "quat_wxyz_from_xyzw", "quat_angle"):
        t[n] = (getattr(Q, n), q1)
    for n in ("axis_angle_from_quat", "matrix_from_quat"):
        t[n] = (getattr(R, n), q1)
    t["quat_normalize"] = (Q.quat_normalize, q1 + [("eps", "eps")])
    for n in ("quat_mul", "quat_dot"):
        t[n] = (getattr(Q, n), [("q", "q"), ("r", "q")])
    t["quat_angle(q,r)"] = (Q.quat_angle, [("q", "q"), ("r", "q")])
    t["quat_rotate"] = (Q.quat_rotate, [("q", "q"), ("v", "v")])
    t["quat_slerp"] = (Q.quat_slerp, [("q0", "q"), ("q1", "q"), ("t", "t")])
    t["quat_fix"] = (Q.quat_fix, [("q", "qT")])
    t["quat_from_axis_angle"] = (R.quat_from_axis_angle, [("v", "v")])
    t["quat_from_euler"] = (R.quat_from_euler, [("angles", "v"), ("order", "order")])
    t["matrix_from_euler"] = (R.matrix_from_euler, [("angles", "v"), ("order", "order")])
    t["euler_from_quat"] = (R.euler_from_quat, [("q", "q"), ("order", "order")])
    t["euler_from_matrix"] = (R.euler_from_matrix, [("m", "m3"), ("order", "order")])
    t["quat_from_matrix"] = (R.quat_from_matrix, [("m", "m3")])
    t["ortho6d_from_matrix"] = (R.ortho6d_from_matrix, [("m", "m3")])
    t["matrix_from_ortho6d"] = (R.matrix_from_ortho6d, [("x", "x6")])
    t["quat_identity"] = (Q.quat_identity, [("shape", "shape"), ("dtype", "dtype")])
    t["dq_identity"] = (DQ.dq_identity, [("shape", "shape"), ("dtype", "dtype")])
    a1 = [("a", "dq")]
    for n in ("dq_conj", "dq_conj_dual", "dq_conj_combined", "dq_inv", "dq_norm", "dq_normalize",
              "quat_translation_from_dq", "translation_from_dq", "matrix_from_dq"):
        t[n] = (getattr(DQ, n), a1)
    t["dq_is_unit"] = (DQ.dq_is_unit, a1 + [("atol_norm", "atol"), ("atol_dot", "atol")])
    t["dq_mul"] = (DQ.dq_mul, [("a", "dq"), ("b", "dq")])
    t["dq_from_quat_translation"] = (DQ.dq_from_quat_translation, [("q", "q"), ("t", "v")])
    t["dq_from_matrix"] = (DQ.dq_from_matrix, [("m", "m4")])
    t["dq_transform_point"] = (DQ.dq_transform_point, [("a", "dq"), ("p", "v")])
    t["dq_fix"] = (DQ.dq_fix, [("a", "dqT")])
    t["dq_sclerp"] = (DQ.dq_sclerp, [("a", "dq"), ("b", "dq"), ("t", "t")])
    t["dq_blend"] = (DQ.dq_blend, [("weights", "w"), ("dqs", "dqs")])
    t["Skeleton"] = (S.Skeleton, [("parents", "parents"), ("offsets", "offJ"), ("names", "names"),
                                  ("end_sites", "ends"), ("joints_left", "pairs"), ("joints_right", "pairs")])
    t["Skeleton.forward_kinematics"] = (lambda rotations, root_positions: _skeleton().forward_kinematics(
        rotations, root_positions), [("rotations", "rotJ"), ("root_positions", "root")])
    t["Skeleton.forward_kinematics_matrices"] = (lambda rotations, root_positions: _skeleton()
                                                 .forward_kinematics_matrices(rotations, root_positions),
                                                 [("rotations", "rotJ"), ("root_positions", "root")])
    t["Skeleton.world_rotations"] = (lambda rotations: _skeleton().world_rotations(rotations), [("rotations", "rotJ")])
    t["Skeleton.remove_joints"] = (lambda joints, offsets: _skeleton().remove_joints(joints, offsets),
                                   [("joints", "joints"), ("offsets", "offmode")])
    t["remove_joints"] = (lambda rotations, joints, offsets: S.remove_joints(_skeleton(), rotations, joints, offsets),
                          [("rotations", "rotJ"), ("joints", "joints"), ("offsets", "offmode")])
    t["current_dq_from_local"] = (CD.current_dq_from_local, [("rotations", "rotJ"), ("offsets", "offJ"),
                                                            ("parents", "parents")])
    t["local_from_current_dq"] = (CD.local_from_current_dq, [("dqs", "dqJ"), ("parents", "parents")])
    t["offsets_from_current_dq"] = (CD.offsets_from_current_dq, [("dqs", "dqJ"), ("parents", "parents")])
    t["positions_from_current_dq"] = (CD.positions_from_current_dq, [("dqs", "dqJ")])
    t["mirror"] = (lambda rotations, root_positions, axis, mirror_offsets: MI.mirror(
        _skeleton(), rotations, root_positions, axis, mirror_offsets),
        [("rotations", "rotJ"), ("root_positions", "root"), ("axis", "axis"), ("mirror_offsets", "mirror_offsets")])
    t["rotate_about_up"] = (MI.rotate_about_up, [("rotations", "rotJ"), ("root_positions", "root"),
                                                ("angle", "angle"), ("up", "axis")])
    t["random_rotate_about_up"] = (lambda rotations, root_positions, low, high: MI.random_rotate_about_up(
        rotations, root_positions, np.random.default_rng(0), low, high),
        [("rotations", "rotJ"), ("root_positions", "root"), ("low", "lowhigh"), ("high", "lowhigh")])
    return t


TARGETS = _targets()


# ------------------------------------------------------------------------------------------------------------
# cases
# ------------------------------------------------------------------------------------------------------------

def _valid(kind, g, lead):
    if kind in ARRAY_KINDS:
        return ARRAY_KINDS[kind][0](g, lead)
    value = SCALAR_KINDS[kind][0]
    if kind == "lowhigh":
        return value
    return value


def _spoil(arr, family, rng: random.Random, g):
    """A hostile version of a valid float64 array for one of the value/dtype/shape families."""
    a = np.array(arr, dtype=np.float64)
    if family == "huge":
        mode = rng.choice(["all", "one", "max"])
        s = 10.0 ** rng.uniform(250, 308)
        if mode == "all":
            return a * s / max(1.0, float(np.max(np.abs(a), initial=1.0)))
        if a.size:
            a.flat[rng.randrange(a.size)] = rng.choice([1, -1]) * (np.finfo(np.float64).max if mode == "max" else s)
        return a
    if family in ("tiny", "denormal"):
        s = 10.0 ** (rng.uniform(-308, -300) if family == "tiny" else rng.uniform(-323.3, -310))
        return a * s if rng.random() < 0.7 else np.where(g.random(a.shape) < 0.5, a * s, a)
    if family == "mixed":
        return np.where(g.random(a.shape) < 0.5, -1.0, 1.0) * 10.0 ** g.uniform(-320, 308, a.shape)
    if family == "nonfinite":
        if a.size == 0:
            return a
        a.flat[rng.randrange(a.size)] = rng.choice([math.nan, math.inf, -math.inf])
        return a
    if family == "zero":
        return np.zeros_like(a)
    if family == "empty":
        return a.reshape(-1)[:0].reshape((0,) + a.shape[1:]) if a.ndim else np.zeros((0,))
    if family == "shape":
        mode = rng.choice(["longer", "shorter", "0-d", "drop", "extra"])
        if mode == "0-d":
            return np.float64(0.5)
        if mode == "drop":
            return a[0] if a.ndim else a
        if mode == "extra":
            return a[..., None]
        if a.ndim == 0:
            return np.ones(2)
        n = a.shape[-1] + (1 if mode == "longer" else -1)
        out = np.zeros(a.shape[:-1] + (max(n, 0),))
        out[..., :min(n, a.shape[-1])] = a[..., :min(n, a.shape[-1])]
        return out
    if family == "dtype":
        mode = rng.choice(["object", "int64", "bool", "uint8", "complex", "str", "bytes", "None", "datetime",
                           "float16", "float32", "longdouble", "liststr", "ragged", "dict", "bigint"])
        if mode == "object":
            return a.astype(object)
        if mode == "int64":
            return (a * rng.choice([1, 1e6, 1e18])).astype(np.int64)
        if mode == "bool":
            return a > 0
        if mode == "uint8":
            return (np.abs(a) * 100).astype(np.uint8)
        if mode == "complex":
            return a + 1j
        if mode == "str":
            return a.astype(str)
        if mode == "bytes":
            return a.astype("S8")
        if mode == "None":
            return None
        if mode == "datetime":
            return np.zeros(a.shape, dtype="datetime64[s]")
        if mode in ("float16", "float32", "longdouble"):
            return a.astype(mode)
        if mode == "liststr":
            return [["a"] * (a.shape[-1] if a.ndim else 1)]
        if mode == "ragged":
            return [[1.0, 2.0], [1.0]]
        if mode == "dict":
            return {"q": a}
        return [[10 ** 400] * (a.shape[-1] if a.ndim else 1)]
    raise AssertionError(family)


def make_case(rng: random.Random, family: str | None = None, target: str | None = None):
    """``(target, family, spoiled argument, kwargs, finite_input)`` for one case drawn from ``rng``."""
    family = family or rng.choice(FAMILIES)
    names = sorted(TARGETS)
    if target is None:
        while True:
            target = rng.choice(names)
            kinds = [k for _, k in TARGETS[target][1]]
            n_arrays = sum(k in ARRAY_KINDS for k in kinds)
            if (n_arrays < len(kinds)) if family == "scalar" else n_arrays > 0:
                break
    fn, spec = TARGETS[target]
    g = np.random.default_rng(rng.getrandbits(32))
    lead = tuple(rng.randint(1, 3) for _ in range(rng.randint(0, 2)))
    kwargs = {name: _valid(kind, g, lead) for name, kind in spec}
    array_args = [name for name, kind in spec if kind in ARRAY_KINDS]
    scalar_args = [name for name, kind in spec if kind not in ARRAY_KINDS]
    finite = True
    spoiled = None
    if family == "scalar" or not array_args:
        if scalar_args:
            spoiled = rng.choice(scalar_args)
            kind = dict(spec)[spoiled]
            kwargs[spoiled] = rng.choice(SCALAR_KINDS[kind][1])
            finite = not (isinstance(kwargs[spoiled], float) and not math.isfinite(kwargs[spoiled]))
    elif family == "broadcast":
        spoiled = rng.choice(array_args)
        kind = dict(spec)[spoiled]
        if len(array_args) > 1 and kind not in ("offJ",):
            kwargs[spoiled] = ARRAY_KINDS[kind][0](g, (7,) + tuple(n + 4 for n in lead))
        else:
            kwargs[spoiled] = ARRAY_KINDS[kind][0](g, (7, 2))
    else:
        spoiled = rng.choice(array_args)
        kwargs[spoiled] = _spoil(kwargs[spoiled], family, rng, g)
        finite = family != "nonfinite"
    return target, family, spoiled, kwargs, finite


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang()


def _outputs(out):
    if isinstance(out, tuple):
        for o in out:
            yield from _outputs(o)
    elif isinstance(out, np.ndarray):
        yield out
    elif isinstance(out, (float, np.floating)):
        yield np.asarray(out)


def run_case(target: str, kwargs: dict, finite_input: bool, limit: float = 1.0) -> tuple[str, str]:
    """``(outcome, detail)``: outcome ``ok`` / ``ValueError`` or a failure type (``TypeError``, ``Slow``,
    ``Hang``, ``NonFiniteOutput``, ``AcceptedNonFinite``, ...)."""
    fn = TARGETS[target][0]
    use_alarm = hasattr(signal, "setitimer")
    if use_alarm:
        old = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, 5 * limit)
    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a NumPy RuntimeWarning escaping the API counts as a failure
            out = fn(**kwargs)
    except ValueError as exc:
        outcome, detail = "ValueError", str(exc)[:160]
    except _Hang:
        outcome, detail = "Hang", f"> {5 * limit} s"
    except Exception as exc:  # noqa: BLE001 - the campaign classifies every exception
        outcome, detail = type(exc).__name__, str(exc)[:160]
    else:
        outcome, detail = "ok", ""
        for o in _outputs(out):
            if o.dtype.kind == "f" and not np.isfinite(o).all():
                outcome, detail = ("NonFiniteOutput", f"shape {o.shape}") if finite_input else \
                    ("AcceptedNonFinite", "non-finite input accepted")
                break
            if o.dtype == object:
                outcome, detail = "ObjectOutput", f"shape {o.shape}"
                break
        if outcome == "ok" and not finite_input:
            outcome, detail = "AcceptedNonFinite", "non-finite input accepted"
    finally:
        if use_alarm:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
    elapsed = time.perf_counter() - t0
    if outcome in ("ok", "ValueError") and elapsed > limit:
        outcome, detail = "Slow", f"{elapsed:.2f} s"
    return outcome, detail


def _describe(kwargs):
    out = {}
    for k, v in kwargs.items():
        if isinstance(v, np.ndarray):
            flat = v.reshape(-1)[:4]
            out[k] = f"ndarray {v.dtype} {v.shape} {flat.tolist()!r:.80}"
        else:
            out[k] = repr(v)[:80]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=10000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--limit", type=float, default=1.0, help="seconds per case (slower = failure)")
    ap.add_argument("--out", default=str(ROOT / "tests" / "fuzz" / "results" / "fuzz_math.json"))
    args = ap.parse_args(argv)
    rng = random.Random(args.seed)
    by_family = defaultdict(Counter)
    by_target = defaultdict(Counter)
    failures = Counter()
    examples = defaultdict(list)
    slowest = (0.0, "")
    t_start = time.perf_counter()
    for i in range(args.cases):
        target, family, spoiled, kwargs, finite = make_case(rng)
        t0 = time.perf_counter()
        outcome, detail = run_case(target, kwargs, finite, args.limit)
        dt = time.perf_counter() - t0
        if dt > slowest[0]:
            slowest = (dt, target)
        by_family[family][outcome] += 1
        by_target[target][outcome] += 1
        if outcome not in ("ok", "ValueError"):
            failures[outcome] += 1
            if len(examples[outcome]) < 5:
                examples[outcome].append({"case": i, "target": target, "family": family, "argument": spoiled,
                                          "detail": detail, "kwargs": _describe(kwargs)})
        if (i + 1) % 1000 == 0:
            print(f"  {i + 1}/{args.cases} cases, {sum(failures.values())} failures", file=sys.stderr, flush=True)
    total = time.perf_counter() - t_start
    print(f"\nfuzz_math: {args.cases} cases, seed {args.seed}, {total:.1f} s, slowest case {slowest[0] * 1e3:.1f} ms "
          f"({slowest[1]})\n")
    print(f"{'family':<11} {'cases':>6} {'ok':>6} {'ValueError':>10} {'failures':>8}")
    for fam in FAMILIES:
        c = by_family[fam]
        n = sum(c.values())
        print(f"{fam:<11} {n:>6} {c['ok']:>6} {c['ValueError']:>10} {n - c['ok'] - c['ValueError']:>8}")
    print(f"\n{'target':<36} {'cases':>6} {'ok':>6} {'ValueError':>10} {'failures':>8}")
    for tg in sorted(by_target):
        c = by_target[tg]
        n = sum(c.values())
        print(f"{tg:<36} {n:>6} {c['ok']:>6} {c['ValueError']:>10} {n - c['ok'] - c['ValueError']:>8}")
    print("\nfailures by type:", dict(failures) or "none")
    result = {"cases": args.cases, "seed": args.seed, "limit_s": args.limit, "seconds": round(total, 2),
              "slowest_case_s": round(slowest[0], 4), "slowest_target": slowest[1],
              "failures": sum(failures.values()), "failures_by_type": dict(failures),
              "by_family": {k: dict(v) for k, v in by_family.items()},
              "by_target": {k: dict(v) for k, v in by_target.items()}, "examples": dict(examples),
              "numpy": np.__version__}
    atomic_write_text(args.out, json.dumps(result, indent=1, sort_keys=True) + "\n", make_parents=True)
    print(f"wrote {args.out}")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
