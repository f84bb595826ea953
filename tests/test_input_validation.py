"""Bad input at public boundaries (spec/robustness.md §3).

Every public function (the modules' ``__all__`` and the package's top-level re-exports) that takes arrays must
raise ``ValueError`` naming the argument — with the expected and the actual shape for shape errors — when an
array argument has the wrong last-axis size, the wrong number of dimensions, NaN or inf, or a non-numeric
dtype. Never a crash deep in NumPy, never silently wrong output.

The probe is generic: for each function, valid arguments are built from the parameter names (a few
"profiles" of conventional names: ``q``, ``pred``, ``rotations``, ``parents``...; the first profile with which
the call succeeds is used), then each array argument in turn is spoiled. Backward functions are probed through
their forward partner's cache (their gradient argument: NaN, wrong shape). Functions of the core modules that
cannot be probed generically must be listed in ``NOT_PROBED`` with a reason, so a new public function cannot
slip through unnoticed. Targeted cases follow the generic ones.
"""
from __future__ import annotations

import importlib
import inspect
import re
import warnings

import numpy as np
import pytest

J = 4
PARENTS = [-1, 0, 1, 1]
_rng = np.random.default_rng(0)


def _uq(*shape):
    q = _rng.standard_normal(shape + (4,))
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _udq(*shape):
    from refimpl.dualquat import dq_from_quat_translation

    return dq_from_quat_translation(_uq(*shape), _rng.standard_normal(shape + (3,)))


def _rotmats(n):
    from refimpl.rotations import matrix_from_quat

    return matrix_from_quat(_uq(n))


def _homog(n):
    m = np.zeros((n, 4, 4))
    m[:, :3, :3] = _rotmats(n)
    m[:, :3, 3] = _rng.standard_normal((n, 3))
    m[:, 3, 3] = 1
    return m


# Profiles: parameter name -> factory. Tried in order; the first with which the call succeeds is used.
PROFILES = [
    ("math", {"q": lambda: _uq(3), "r": lambda: _uq(3), "q0": lambda: _uq(3), "q1": lambda: _uq(3),
              "v": lambda: _rng.standard_normal((3, 3)), "t": lambda: np.float64(0.3),
              "angles": lambda: _rng.uniform(-1, 1, (3, 3)), "order": lambda: "zyx", "m": lambda: _rotmats(3),
              "x": lambda: np.concatenate([_rotmats(3)[..., :, 0], _rotmats(3)[..., :, 1]], axis=-1),
              "a": lambda: _udq(3), "b": lambda: _udq(3), "p": lambda: _rng.standard_normal((3, 3)),
              "weights": lambda: _rng.uniform(0.1, 1, (3, 2)), "dqs": lambda: _udq(3, 2)}),
    ("math-4x4", {"m": lambda: _homog(3), "t": lambda: _rng.standard_normal((3, 3)), "q": lambda: _uq(3)}),
    ("rotation-losses", {"pred": lambda: _uq(2, J), "target": lambda: _uq(2, J), "raw": lambda: _uq(2, J) * 1.1,
                         "parents": lambda: PARENTS}),
    ("dq-losses", {"pred": lambda: _udq(2, J), "target": lambda: _udq(2, J), "raw": lambda: _udq(2, J) * 1.1,
                   "parents": lambda: PARENTS}),
    ("position-losses", {"pred": lambda: _rng.standard_normal((2, J, 3)),
                         "target": lambda: _rng.standard_normal((2, J, 3))}),
    ("fk-loss", {"pred_rotations": lambda: _uq(2, J), "pred_translations": lambda: _rng.standard_normal((2, 2)),
                 "target_positions": lambda: _rng.standard_normal((2, J, 3)),
                 "target_translations": lambda: _rng.standard_normal((2, 2)),
                 "offsets": lambda: _rng.standard_normal((J, 3)), "parents": lambda: PARENTS}),
    ("layers", {"q": lambda: _uq(2, J), "a": lambda: _uq(2, J), "b": lambda: _uq(2, J), "delta": lambda: _uq(2, J),
                "q_in": lambda: _uq(2, J), "dq": lambda: _udq(2, J) * 1.1}),
    ("dq-layers", {"delta": lambda: _udq(2, J) * 1.1, "d_in": lambda: _udq(2, J)}),
    ("kinematics", {"rotations": lambda: _uq(2, J), "root_positions": lambda: _rng.standard_normal((2, 3)),
                    "offsets": lambda: _rng.standard_normal((J, 3)), "parents": lambda: PARENTS,
                    "translations": lambda: _rng.standard_normal((2, J, 3)), "local_dqs": lambda: _udq(2, J),
                    "current_dqs": lambda: _udq(2, J), "dqs": lambda: _udq(2, J), "angle": lambda: np.array(0.3),
                    "rng": lambda: np.random.default_rng(0), "skeleton": lambda: _skeleton(),
                    "joints": lambda: [2]}),
    ("nn-linear", {"x": lambda: _rng.standard_normal((2, 3, 4)), "params": lambda: _nn_params("linear"),
                   "prefix": lambda: "fc"}),
    ("nn-conv", {"x": lambda: _rng.standard_normal((2, 6, 4)), "params": lambda: _nn_params("conv"),
                 "prefix": lambda: "conv"}),
    ("nn-gru", {"x": lambda: _rng.standard_normal((2, 3, 4)), "x_t": lambda: _rng.standard_normal((2, 4)),
                "h0": lambda: _rng.standard_normal((1, 2, 5)), "h": lambda: _rng.standard_normal((1, 2, 5)),
                "params": lambda: _nn_params("gru"), "prefix": lambda: "rnn"}),
    ("nn-lstm", {"x": lambda: _rng.standard_normal((2, 3, 4)), "x_t": lambda: _rng.standard_normal((2, 4)),
                 "state": lambda: (_rng.standard_normal((1, 2, 5)), _rng.standard_normal((1, 2, 5))),
                 "params": lambda: _nn_params("lstm"), "prefix": lambda: "rnn"}),
    ("features", {"frames": lambda: _rng.standard_normal((10, 5)), "mean": lambda: _rng.standard_normal(5),
                  "std": lambda: _rng.uniform(0.5, 2, 5), "array": lambda: _rng.standard_normal((10, 5)),
                  "length": lambda: 3}),
]


def _nn_params(kind):
    from refimpl.nn.conv1d import conv1d_init
    from refimpl.nn.gru import gru_init
    from refimpl.nn.linear import linear_init
    from refimpl.nn.lstm import lstm_init

    g = np.random.default_rng(1)
    return {"linear": lambda: linear_init(g, 4, 5, "fc"), "conv": lambda: conv1d_init(g, 4, 5, 3, "conv"),
            "gru": lambda: gru_init(g, 4, 5, 1, "rnn"), "lstm": lambda: lstm_init(g, 4, 5, 1, "rnn")}[kind]()


def _skeleton():
    from refimpl.skeleton import Skeleton

    return Skeleton(PARENTS, np.ones((J, 3)))

CORE_MODULES = ["refimpl.quat", "refimpl.dualquat", "refimpl.losses", "refimpl.nn.quat_layers",
                "refimpl.nn.kinematics_layers", "refimpl.skeleton", "refimpl.nn.linear", "refimpl.nn.activations",
                "refimpl.nn.conv1d", "refimpl.nn.gru", "refimpl.nn.lstm"]

# Public functions the generic probe does not handle, with the reason (targeted tests cover some).
NOT_PROBED = {
    "quat_identity": "takes a shape and a dtype, no array",
    "dq_identity": "takes a shape and a dtype, no array",
    "read_bvh": "file reader: tests/test_fuzz_readers.py",
    "read_bvh_header": "file reader: tests/test_fuzz_readers.py",
    "read_expmap": "file reader: tests/test_fuzz_readers.py",
    "load_checkpoint": "file reader: tests/test_fuzz_readers.py",
    "load_state_dict_npz": "file reader: tests/test_fuzz_readers.py",
    "write_bvh": "takes a Motion (validated by Motion: test_motion_validation)",
    "downsample": "takes a Motion (validated by Motion: test_motion_validation)",
    "fix_antipodal": "takes a Motion (validated by Motion: test_motion_validation)",
    "simplify_translations": "takes a Motion: tests/test_motion_translations.py",
    "reroot_at_child": "takes a Motion: tests/test_motion_translations.py",
    "fold_constant_translations": "takes a Motion: tests/test_motion_translations.py",
    "save_checkpoint": "dict arguments: test_checkpoint_save_validation",
    "check_params": "dict arguments: test_check_params_validation",
    "h36m_skeleton": "no arguments", "cmu_asf_skeleton": "no arguments", "cmu_skeleton": "no arguments",
    "quaternet_locomotion_skeleton": "no array arguments",
    "split_by_file": "a list of file names",
    "adam_step": "dict arguments: test_optimiser_validation",
    "clip_grad_norm": "dict arguments: test_optimiser_validation",
    "exponential_lr": "scalar arguments", "teacher_forcing_ratio": "scalar arguments",
    "scheduled_sampling_mask": "scalar arguments", "auto_conditioning_mask": "scalar arguments",
    "rng_from_json": "JSON text: test_rng_from_json_validation",
    "linear_init": "sizes and a Generator", "conv1d_init": "sizes and a Generator",
    "gru_init": "sizes and a Generator", "lstm_init": "sizes and a Generator",
}

# (function name, argument) whose last axis may have any size (the last-axis probe does not apply)
_ELEMENTWISE = ("relu_forward", "leaky_relu_forward", "tanh_forward", "sigmoid_forward")
LAST_AXIS_FREE = {("windows", "array"), ("feature_statistics", "frames"), ("normalize_features", "frames"),
                  ("denormalize_features", "frames")} | {(f, "x") for f in _ELEMENTWISE}
# (function name, argument) for which a 0-d value is valid (elementwise functions)
NDIM_FREE = {(f, "x") for f in _ELEMENTWISE}
# functions that take arrays of any dtype and values (structural: views, windows): only shape probes apply
VALUE_FREE = {"windows"}

_NON_ARRAY = {"order", "parents", "eps", "atol_norm", "atol_dot", "up_axis", "skeleton", "joints", "rng",
              "length", "params", "prefix", "state"}


def _public_functions(modname):
    try:
        mod = importlib.import_module(modname)
    except ImportError:
        return []
    out = []
    for name in getattr(mod, "__all__", []):
        obj = getattr(mod, name, None)
        if inspect.isfunction(obj):
            out.append((name, obj))
    return out


def _top_level_functions():
    """Functions re-exported by ``refimpl/__init__.py`` (when the lead adds them) not already in CORE_MODULES."""
    import refimpl

    core = {id(f) for m in CORE_MODULES for _, f in _public_functions(m)}
    out = []
    for name in getattr(refimpl, "__all__", []):
        obj = getattr(refimpl, name, None)
        if inspect.isfunction(obj) and id(obj) not in core and not name.endswith("_backward"):
            out.append((name, obj))
    return out


def _required_params(fn):
    sig = inspect.signature(fn)
    return [p for p in sig.parameters.values()
            if p.default is inspect.Parameter.empty and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]


def _valid_args(fn):
    """(profile name, kwargs) with which ``fn`` runs, or None."""
    names = [p.name for p in _required_params(fn)]
    if not names:
        return None
    for pname, prof in PROFILES:
        if not all(n in prof for n in names):
            continue
        kwargs = {n: prof[n]() for n in names}
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                fn(**kwargs)
        except Exception:
            continue
        return pname, kwargs
    return None


def _collect():
    """All (qualified name, function, kwargs) the generic probe can call, and the names it could not."""
    cases, missing = [], []
    seen = set()
    funcs = [(m, n, f) for m in CORE_MODULES for n, f in _public_functions(m)]
    funcs += [("refimpl", n, f) for n, f in _top_level_functions()]
    for modname, name, fn in funcs:
        if id(fn) in seen:
            continue
        seen.add(id(fn))
        if name.endswith("_backward"):
            continue
        found = _valid_args(fn)
        if found is None:
            missing.append(f"{modname}.{name}")
            continue
        cases.append((f"{modname}.{name}", fn, found[1]))
    return cases, missing


CASES, MISSING = _collect()


def _array_args(kwargs):
    return [k for k, v in kwargs.items() if k not in _NON_ARRAY and isinstance(v, np.ndarray)]


# (qualified name, argument or "*", probe) -> reason: known gaps in other modules (strict xfail).
# Fixed since (the tests now guard them): B7 0-d pred/target in quat/dq_pos/dq_offset losses (IndexError),
# B8 NaN/inf upstream gradients in the quaternion/kinematics layers, B9 array dvalue (TypeError), B10
# normalize_features/denormalize_features without finiteness/dtype checks, B11 a wrong x/h0 feature size in the
# GRU/LSTM reported as a parameter shape, B12 the unchecked kernels matmul_wt/sigmoid in __all__ (now private),
# B13 NaN/inf upstream gradients in the linear, activation, conv1d, GRU and LSTM backwards (spec/robustness.md §7).
KNOWN: dict = {}


def _probe_ids(probe):
    out = []
    for qual, fn, kwargs in CASES:
        short = qual.rsplit(".", 1)[1]
        for arg in _array_args(kwargs):
            if probe == "last" and (short, arg) in LAST_AXIS_FREE:
                continue
            if probe == "ndim" and (short, arg) in NDIM_FREE:
                continue
            if probe in ("finite", "dtype") and short in VALUE_FREE:
                continue
            if probe == "finite":
                for value in (np.nan, np.inf, -np.inf):
                    reason = KNOWN.get((qual, arg, probe))
                    marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
                    out.append(pytest.param(qual, arg, value, id=f"{qual}:{arg}:{value}", marks=marks))
                continue
            reason = KNOWN.get((qual, arg, probe))
            marks = [pytest.mark.xfail(strict=True, reason=reason)] if reason else []
            out.append(pytest.param(qual, arg, id=f"{qual}:{arg}", marks=marks))
    return out


def _call(qual, **override):
    fn, kwargs = next((f, k) for q, f, k in CASES if q == qual)
    kw = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in kwargs.items()}
    kw.update(override)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return fn(**kw)


def _names_arg(msg: str, arg: str) -> bool:
    return re.search(rf"(?<![A-Za-z0-9_]){re.escape(arg)}(?![A-Za-z0-9_])", msg) is not None


def _original(qual, arg):
    return next(k for q, f, k in CASES if q == qual)[arg]


def test_every_public_function_is_probed():
    """spec/robustness.md §3: each public function (core modules and top-level re-exports) is probed or listed in
    NOT_PROBED with a reason."""
    unexplained = [q for q in MISSING if q.rsplit(".", 1)[1] not in NOT_PROBED]
    stale = [n for n in NOT_PROBED if not any(q.rsplit(".", 1)[1] == n for q in MISSING)]
    assert not unexplained, f"no valid arguments could be built for {unexplained}: add a profile or NOT_PROBED"
    assert not stale, f"NOT_PROBED entries that are probed now or no longer exist: {stale}"
    assert len(CASES) >= 60, len(CASES)


@pytest.mark.parametrize("qual,arg", _probe_ids("last"))
def test_wrong_last_axis(qual, arg):
    """spec/robustness.md §3: an array with one extra entry on its last axis → ValueError naming the argument,
    the expected and the actual shape."""
    x = _original(qual, arg)
    if x.ndim == 0:
        pytest.skip("scalar argument")
    bad = np.concatenate([x, x[..., :1]], axis=-1)
    with pytest.raises(ValueError) as info:
        _call(qual, **{arg: bad})
    msg = str(info.value)
    assert _names_arg(msg, arg) or _names_arg(msg, arg.rstrip("s")), msg
    assert str(bad.shape) in msg or str(tuple(bad.shape[-1:])) in msg or str(bad.shape[-1]) in msg, msg
    assert "expect" in msg.lower(), msg


@pytest.mark.parametrize("qual,arg,value", _probe_ids("finite"))
def test_non_finite(qual, arg, value):
    """spec/robustness.md §3: NaN or ±inf in any array argument → ValueError naming it."""
    x = np.array(_original(qual, arg), dtype=np.float64)
    x.reshape(-1)[-1] = value
    with pytest.raises(ValueError) as info:
        _call(qual, **{arg: x})
    assert _names_arg(str(info.value), arg), str(info.value)


@pytest.mark.parametrize("qual,arg", _probe_ids("ndim"))
def test_wrong_ndim(qual, arg):
    """spec/robustness.md §3: a 0-d array where an array with an object axis is expected → ValueError."""
    x = _original(qual, arg)
    if x.ndim == 0:
        pytest.skip("scalar argument")
    with pytest.raises(ValueError) as info:
        _call(qual, **{arg: np.float64(0.5)})
    assert _names_arg(str(info.value), arg), str(info.value)


@pytest.mark.parametrize("qual,arg", _probe_ids("dtype"))
def test_non_numeric_dtype(qual, arg):
    """spec/robustness.md §3: strings or objects where numbers are expected → ValueError (not TypeError)."""
    x = _original(qual, arg)
    bad = np.full(x.shape, "a") if x.ndim else np.array("a")
    with pytest.raises(ValueError):
        _call(qual, **{arg: bad})


# --------------------------------------------------------------------------------------------------------------
# backward functions: the gradient argument
# --------------------------------------------------------------------------------------------------------------

def _backward_cases(probe):
    """(forward qualname, backward) pairs."""
    out = []
    for modname in CORE_MODULES:
        funcs = dict(_public_functions(modname))
        for name, bwd in funcs.items():
            if not name.endswith("_backward"):
                continue
            fwd_name = name[: -len("_backward")] + "_forward"
            qual = f"{modname}.{fwd_name}"
            if not any(q == qual for q, _, _ in CASES):
                continue
            out.append(pytest.param(qual, bwd, id=f"{modname}.{name}"))
    return out


def _call_backward(bwd, grad, cache):
    """``bwd(grad, None, ..., cache)``: recurrent backwards take ``dh_n``/``dstate`` (None allowed) in between."""
    n = len(_required_params(bwd))
    return bwd(grad, *([None] * (n - 2)), cache)


def _forward_out(qual):
    res = _call(qual)
    *outs, cache = res
    return outs, cache


@pytest.mark.parametrize("fwd,bwd", _backward_cases("nan"))
def test_backward_gradient_nan(fwd, bwd):
    """spec/robustness.md §3: a NaN upstream gradient (dvalue / dy) → ValueError naming it."""
    outs, cache = _forward_out(fwd)
    grad_name = _required_params(bwd)[0].name
    y = outs[0]
    bad = np.float64("nan") if np.ndim(y) == 0 else np.full(np.shape(y), np.nan)
    with pytest.raises(ValueError) as info:
        _call_backward(bwd, bad, cache)
    assert _names_arg(str(info.value), grad_name), str(info.value)


@pytest.mark.parametrize("fwd,bwd", _backward_cases("shape"))
def test_backward_gradient_wrong_shape(fwd, bwd):
    """spec/robustness.md §3: an upstream gradient whose shape differs from the forward output → ValueError."""
    outs, cache = _forward_out(fwd)
    y = outs[0]
    if np.ndim(y) == 0:
        bad = np.ones(3)  # a loss's dvalue must be a scalar
    else:
        bad = np.ones(np.shape(y)[:-1] + (np.shape(y)[-1] + 1,))
    with pytest.raises(ValueError):
        _call_backward(bwd, bad, cache)


# --------------------------------------------------------------------------------------------------------------
# targeted cases
# --------------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("order", ["xyzx", "xx", "xxy", "abc", "", 3, None, "zyz "])
def test_bad_euler_order(order):
    """spec/robustness.md §3: an invalid Euler order → ValueError naming ``order``."""
    from refimpl.rotations import euler_from_quat, quat_from_euler

    with pytest.raises(ValueError, match="order"):
        quat_from_euler(np.zeros(3), order)
    with pytest.raises(ValueError, match="order"):
        euler_from_quat(np.array([1.0, 0, 0, 0]), order)


@pytest.mark.parametrize("parents", [[0, 0, 1, 1], [-1, 2, 1, 1], [-1, 0, 1], [-1, 0, -1, 1], [-1, 0, 1, 9],
                                     [[-1, 0, 1, 1]], [-1.5, 0, 1, 1]])
def test_bad_parents(parents):
    """spec/robustness.md §3: malformed parent lists (no root, cycles, forward references, wrong length) →
    ValueError naming ``parents``, in every function that takes them."""
    from refimpl.losses import dq_offset_loss_forward
    from refimpl.nn.kinematics_layers import forward_kinematics_forward
    from refimpl.current_dq import current_dq_from_local

    calls = [lambda: current_dq_from_local(_uq(2, J), np.ones((J, 3)), parents),
             lambda: forward_kinematics_forward(_uq(2, J), np.zeros((2, 3)), np.ones((J, 3)), parents),
             lambda: dq_offset_loss_forward(_udq(2, J), _udq(2, J), parents)]
    for c in calls:
        with pytest.raises(ValueError) as info:
            c()
        if len(np.ravel(parents)) == J:  # a length mismatch may be reported on the array instead
            assert "parents" in str(info.value), str(info.value)


def test_matrix_not_a_rotation():
    """spec/robustness.md §3: a scaled, sheared or reflecting matrix → ValueError naming ``m`` (no silent
    quaternion of a non-rotation)."""
    from refimpl.dualquat import dq_from_matrix
    from refimpl.rotations import euler_from_matrix, quat_from_matrix

    for m in (2 * np.eye(3), np.diag([1.0, 1, -1]), np.array([[1.0, 0.1, 0], [0, 1, 0], [0, 0, 1]])):
        with pytest.raises(ValueError, match=r"\bm\b"):
            quat_from_matrix(m)
        with pytest.raises(ValueError, match=r"\bm\b"):
            euler_from_matrix(m, "zyx")
        h = np.eye(4)
        h[:3, :3] = m
        with pytest.raises(ValueError, match=r"\bm\b"):
            dq_from_matrix(h)


def test_broadcast_mismatch_names_arguments():
    """spec/robustness.md §3: leading axes that do not broadcast → ValueError, not a NumPy traceback."""
    from refimpl.dualquat import dq_from_quat_translation, dq_mul
    from refimpl.quat import quat_mul, quat_rotate

    for call in (lambda: quat_mul(_uq(3), _uq(4)), lambda: quat_rotate(_uq(3), np.ones((4, 3))),
                 lambda: dq_mul(_udq(3), _udq(2)), lambda: dq_from_quat_translation(_uq(3), np.ones((2, 3)))):
        with pytest.raises(ValueError):
            call()


def test_skeleton_constructor_validation():
    """spec/robustness.md §3: Skeleton refuses bad offsets (shape, NaN) and names, naming the argument."""
    from refimpl.skeleton import Skeleton

    with pytest.raises(ValueError, match="offsets"):
        Skeleton(PARENTS, np.ones((J, 4)))
    with pytest.raises(ValueError, match="offsets"):
        Skeleton(PARENTS, np.full((J, 3), np.nan))
    with pytest.raises(ValueError, match="names"):
        Skeleton(PARENTS, np.ones((J, 3)), names=["a", "a", "b", "c"])
    with pytest.raises(ValueError, match="parents"):
        Skeleton([0, 0, 1, 1], np.ones((J, 3)))


def test_rotate_about_up_validation():
    """spec/robustness.md §3: rotate_about_up / random_rotate_about_up validate their arrays."""
    from refimpl.mirroring import random_rotate_about_up, rotate_about_up

    rot, pos = _uq(5, J), np.zeros((5, 3))
    with pytest.raises(ValueError):
        rotate_about_up(rot, pos, np.nan)
    with pytest.raises(ValueError):
        rotate_about_up(rot[..., :3], pos, 0.1)
    with pytest.raises(ValueError):
        random_rotate_about_up(rot, np.zeros((5, 4)), np.random.default_rng(0))


def test_motion_validation():
    """spec/robustness.md §3: Motion refuses NaN, non-unit rotations, shape mismatches and bad frame times."""
    from refimpl.motion import Motion
    from refimpl.skeleton import Skeleton

    skel = Skeleton(PARENTS, np.ones((J, 3)))
    ok = dict(skeleton=skel, rotations=_uq(5, J), root_positions=np.zeros((5, 3)), frame_time=0.01)
    Motion(**ok)
    for k, v in (("rotations", _uq(5, J) * 2), ("rotations", _uq(5, J + 1)), ("root_positions", np.zeros((4, 3))),
                 ("root_positions", np.full((5, 3), np.inf)), ("frame_time", 0.0), ("frame_time", float("nan"))):
        with pytest.raises(ValueError, match=k):
            Motion(**dict(ok, **{k: v}))


def test_checkpoint_save_validation(tmp_path):
    """spec/robustness.md §3, §4: save_checkpoint refuses object arrays, reserved names, non-JSON metadata, NaN
    in metadata; nothing is written then."""
    from refimpl.checkpoint import save_checkpoint

    p = tmp_path / "c.npz"
    bad = [({"a": np.array([object()])}, {}), ({"__meta__": np.zeros(1)}, {}), ({"a": np.zeros(1)}, {"x": object()}),
           ({"a": np.zeros(1)}, {"x": float("nan")}), ({"a": [1, 2]}, {}), ({"": np.zeros(1)}, {})]
    for arrays, meta in bad:
        with pytest.raises(ValueError):
            save_checkpoint(p, arrays, meta)
        assert not p.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary file left behind


def test_deployed_model_run_validation(tmp_path):
    """spec/robustness.md §3: DeployedModel.run refuses missing/unknown inputs, wrong ranks, NaN."""
    pytest.importorskip("onnxruntime")
    from onnx import TensorProto, helper

    from deploy.runtime import load_model

    x = helper.make_tensor_value_info("x", TensorProto.FLOAT, ["B", 4])
    y = helper.make_tensor_value_info("y", TensorProto.FLOAT, ["B", 4])
    model = helper.make_model(helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g", [x], [y]),
                              opset_imports=[helper.make_opsetid("", 17)], ir_version=8)
    p = tmp_path / "m.onnx"
    p.write_bytes(model.SerializeToString())
    m = load_model(p)
    assert np.array_equal(m.run(x=np.ones((2, 4)))["y"], np.ones((2, 4), np.float32))
    for feeds in ({}, {"x": np.ones((2, 4)), "z": np.ones(1)}, {"x": np.ones((2, 5))}, {"x": np.ones(4)},
                  {"x": np.full((2, 4), np.nan)}):
        with pytest.raises(ValueError):
            m.run(feeds)


def test_check_params_validation():
    """spec/robustness.md §3: check_params lists missing, unexpected, mis-shaped and non-finite entries."""
    from refimpl.checkpoint import check_params

    check_params({"w": np.zeros((2, 3))}, {"w": (2, 3)})
    for params in ({}, {"w": np.zeros((2, 3)), "x": np.zeros(1)}, {"w": np.zeros((3, 2))},
                   {"w": np.full((2, 3), np.nan)}, {"w": np.zeros((2, 3), dtype=np.int64)}):
        with pytest.raises(ValueError, match="w|x"):
            check_params(params, {"w": (2, 3)})


def test_optimiser_validation():
    """spec/robustness.md §3: the optimiser refuses mismatched gradient dicts and shapes."""
    from refimpl.optim import adam_init, adam_step, clip_grad_norm

    params = {"w": np.ones((2, 3))}
    state = adam_init(params)
    for grads in ({}, {"w": np.ones((3, 2))}, {"w": np.ones((2, 3)), "x": np.ones(1)}):
        with pytest.raises(ValueError):
            adam_step(dict(params), grads, state, 1e-3)
    with pytest.raises(ValueError):
        clip_grad_norm({"w": np.ones(3)}, -1.0)


def test_rng_from_json_validation():
    """spec/robustness.md §3, §4: generator state text is parsed as JSON data; malformed text → ValueError."""
    from refimpl.checkpoint import rng_from_json, rng_state_to_json

    ok = rng_state_to_json(np.random.default_rng(1))
    assert rng_from_json(ok).random() == np.random.default_rng(1).random()
    for text in ("", "{", "[]", '{"bit_generator": "os.system"}', '{"bit_generator": "PCG64"}', "null"):
        with pytest.raises(ValueError):
            rng_from_json(text)
