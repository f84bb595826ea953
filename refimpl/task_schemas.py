"""The schema of what each task stores in a training checkpoint beside the network (spec/robustness.md §9.1).

:mod:`refimpl.checkpoint_schema` checks the network's config and parameters for every model; this module checks
the *task* fields the ``checkpoint_extra`` of each task writes — their types, ranges and shapes, and that the
labels agree with each other and with the frame size — so that a crafted or damaged checkpoint is refused at the
file (``ValueError`` naming the file and the field, exit 3 in ``refimpl``) instead of failing deep inside a command
(``KeyError: 'bogus'``) or, worse, decoding frames as another representation than the one they hold.

:func:`validate_task_checkpoint` is called by :func:`refimpl.checkpoint_schema.validate_trained` (every loader of
``refimpl`` and ``deploy``) and by :func:`refimpl.services.train_model` on the checkpoint a run is about to write,
so that training cannot write a file its own loader refuses.

=============== ===========================================================================================
task            fields (checked when the task writes them; ``required`` ones must be present)
=============== ===========================================================================================
``synthesis``   ``row`` a Table 1 row, ``representation`` = ``row``, ``variant`` = the row's variant,
                ``data_representation`` = the variant's representation (required), ``skeleton`` (required),
                ``frame_size`` = ``3 + D · J`` of that representation and the skeleton's J, ``mean``/``std``
                (required) ``frame_size`` finite numbers (``std`` in [1e-6, 1e6]), ``loss_weights`` finite
                numbers >= 0 by loss name, ``window_length`` / ``condition_length`` / ``ground_truth_length``
                positive integers, ``train_takes`` / ``test_takes`` lists of strings
``prediction``  ``dataset`` ``cmu`` or ``h36m`` (required), ``num_joints`` = the dataset skeleton's, ``frame_time``
                (required) seconds in [1e-4, 10] and ``fps`` = 1 / ``frame_time`` (0.1 %)
``locomotion``  ``rig`` ``cmu`` or ``bandai_namco`` and a ``skeleton`` with that rig's joints (both required),
                ``prefix`` / ``target``
                positive integers; the pose network: ``num_joints`` = the skeleton's J, ``seed_clip`` with
                ``rotations`` (S, J, 4) of non-zero quaternions and ``features`` (S, 8) finite, 1 <= S <= 1000
``transition``  ``root_mean`` / ``root_std`` (required; types in ``checkpoint_schema.TASK_FIELDS``)
=============== ===========================================================================================

A ``skeleton`` is an object with ``parents`` (ints, each parent before its child), ``offsets`` (J × 3 finite, at
most 1e6), ``names`` (J distinct non-empty strings) and optionally ``joints_left`` / ``joints_right``: exactly
what :class:`refimpl.skeleton.Skeleton` accepts. Every number at most :data:`MAX_TASK_ABS` in magnitude.
"""
from __future__ import annotations

import math
from typing import Callable, Mapping

import numpy as np

__all__ = ["MAX_TASK_ABS", "MAX_TASK_JOINTS", "validate_task_checkpoint", "TASK_CHECKS"]

#: Largest magnitude of a stored statistic, offset or seed value (the data of this project stay below ~10^4).
MAX_TASK_ABS = 1e6
#: Largest skeleton (joints) a task field may describe.
MAX_TASK_JOINTS = 1000
_MIN_STD = 1e-6


def _kind(v) -> str:
    return f"{type(v).__name__} ({v!r})" if len(repr(v)) <= 40 else type(v).__name__


def _is_int(v) -> bool:
    return isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_))


def _require(cfg: Mapping, keys, where: str, task: str) -> None:
    missing = [k for k in keys if k not in cfg]
    if missing:
        raise ValueError(f"{where}: the {task} checkpoint lacks {missing}; train it with `refimpl train`")


def _positive_int(cfg, key, where, hi=10**7):
    v = cfg[key]
    if not _is_int(v) or not 1 <= v <= hi:
        raise ValueError(f"{where}: model_config.{key}: expected an integer in [1, {hi}], got {_kind(v)}")
    return int(v)


def _numbers(value, name: str, shape: tuple, lo: float = -MAX_TASK_ABS, hi: float = MAX_TASK_ABS) -> np.ndarray:
    """A nested JSON list of finite numbers in ``[lo, hi]`` of ``shape`` (``None`` = any length) as float64."""
    def ok_leaf(x):
        return isinstance(x, (int, float)) and not isinstance(x, bool)
    try:
        a = np.asarray(value, dtype=object)
    except Exception:  # noqa: BLE001 - ragged lists
        a = None
    if a is None or a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
        raise ValueError(f"{name}: expected a list of numbers of shape {tuple('*' if s is None else s for s in shape)}"
                         f", got {_kind(value) if a is None else 'shape ' + str(a.shape)}")
    if not all(ok_leaf(x) for x in a.reshape(-1)):
        raise ValueError(f"{name}: expected numbers, got {_kind(next(x for x in a.reshape(-1) if not ok_leaf(x)))}")
    f = a.astype(np.float64)
    if not np.all(np.isfinite(f)) or (f.size and (f.min() < lo or f.max() > hi)):
        raise ValueError(f"{name}: expected finite numbers in [{lo:g}, {hi:g}]")
    return f


def _skeleton(value, where: str, want_sides: bool = False):
    """The stored skeleton as a :class:`~refimpl.skeleton.Skeleton` (what the task builds from it)."""
    from refimpl.skeleton import Skeleton

    name = f"{where}: model_config.skeleton"
    if not isinstance(value, Mapping):
        raise ValueError(f"{name}: expected a JSON object, got {_kind(value)}")
    _require(value, ("parents", "offsets", "names") + (("joints_left", "joints_right") if want_sides else ()),
             name, "skeleton of the")
    parents = value["parents"]
    if not isinstance(parents, list) or not 1 <= len(parents) <= MAX_TASK_JOINTS or \
            not all(_is_int(p) for p in parents):
        raise ValueError(f"{name}.parents: expected a list of 1 to {MAX_TASK_JOINTS} integers, got {_kind(parents)}")
    J = len(parents)
    offsets = _numbers(value["offsets"], f"{name}.offsets", (J, 3))
    names = value["names"]
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise ValueError(f"{name}.names: expected a list of {J} strings, got {_kind(names)}")
    sides = {}
    for k in ("joints_left", "joints_right"):
        if k in value:
            s = value[k]
            if not isinstance(s, list) or not all(_is_int(j) and 0 <= j < J for j in s):
                raise ValueError(f"{name}.{k}: expected a list of joint indices in [0, {J}), got {_kind(s)}")
            sides[k] = s
    try:
        return Skeleton(parents, offsets, names=names, **sides)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None


def _synthesis(cfg: Mapping, config, where: str, task_module=None) -> None:
    from refimpl.models import acrnn
    from refimpl.protocols.synthesis import TABLE1_ROWS as rows  # --representation value -> variant
    from refimpl.representations import REPRESENTATIONS, frame_size


    _require(cfg, ("mean", "std", "data_representation", "skeleton", "variant"), where, "synthesis")
    rep = cfg["data_representation"]
    if not isinstance(rep, str) or rep not in REPRESENTATIONS:
        raise ValueError(f"{where}: model_config.data_representation: expected one of {sorted(REPRESENTATIONS)}, "
                         f"got {_kind(rep)}")
    variant = cfg["variant"]
    if not isinstance(variant, str) or variant not in acrnn.VARIANTS:
        raise ValueError(f"{where}: model_config.variant: expected one of {sorted(acrnn.VARIANTS)}, got "
                         f"{_kind(variant)}")
    if acrnn.VARIANTS[variant].representation != rep:
        raise ValueError(f"{where}: model_config.data_representation {rep!r} does not match the variant "
                         f"{variant!r}, which trains on {acrnn.VARIANTS[variant].representation!r}")
    for key in ("row", "representation"):
        if key in cfg:
            row = cfg[key]
            if not isinstance(row, str) or row not in rows:
                raise ValueError(f"{where}: model_config.{key}: expected one of {list(rows)}, got {_kind(row)}")
            if rows[row] != variant:
                raise ValueError(f"{where}: model_config.{key} {row!r} is the variant {rows[row]!r}, but "
                                 f"model_config.variant is {variant!r}")
    if isinstance(cfg.get("row"), str) and isinstance(cfg.get("representation"), str) and \
            cfg["row"] != cfg["representation"]:
        raise ValueError(f"{where}: model_config.row {cfg['row']!r} differs from model_config.representation "
                         f"{cfg['representation']!r}")
    sk = _skeleton(cfg["skeleton"], where)
    F = frame_size(rep, sk.num_joints)
    got = getattr(config, "frame_size", cfg.get("frame_size"))
    if got != F:
        raise ValueError(f"{where}: model_config.frame_size {got!r} does not match {rep!r} frames of the "
                         f"{sk.num_joints}-joint skeleton (3 + {REPRESENTATIONS[rep].dim} x {sk.num_joints} = {F})")
    _numbers(cfg["mean"], f"{where}: model_config.mean", (F,))
    _numbers(cfg["std"], f"{where}: model_config.std", (F,), _MIN_STD, MAX_TASK_ABS)
    if "loss_weights" in cfg:
        w = cfg["loss_weights"]
        if not isinstance(w, Mapping) or not w or not all(
                isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                and 0 <= v <= MAX_TASK_ABS for k, v in w.items()):
            raise ValueError(f"{where}: model_config.loss_weights: expected an object of loss name -> finite weight "
                             f">= 0, got {_kind(w)}")
    for key in ("window_length", "condition_length", "ground_truth_length"):
        if key in cfg:
            _positive_int(cfg, key, where)
    for key in ("train_takes", "test_takes"):
        if key in cfg and (not isinstance(cfg[key], list) or not all(isinstance(t, str) for t in cfg[key])):
            raise ValueError(f"{where}: model_config.{key}: expected a list of take names, got {_kind(cfg[key])}")


def _prediction(cfg: Mapping, config, where: str, task_module=None) -> None:
    from refimpl.skeletons import cmu_asf_skeleton, h36m_skeleton

    _require(cfg, ("dataset", "frame_time"), where, "prediction")  # both read by eval, generate and export
    dataset = cfg["dataset"]
    if dataset not in ("cmu", "h36m"):
        raise ValueError(f"{where}: model_config.dataset: expected 'cmu' or 'h36m', got {_kind(dataset)}")
    J = (cmu_asf_skeleton() if dataset == "cmu" else h36m_skeleton()).num_joints
    got = getattr(config, "num_joints", cfg.get("num_joints"))
    if got is not None and got != J:
        raise ValueError(f"{where}: model_config.num_joints {got!r} does not match the {dataset} skeleton's {J}")
    if "frame_time" in cfg:
        ft = cfg["frame_time"]
        if not isinstance(ft, (int, float)) or isinstance(ft, bool) or not (math.isfinite(ft) and 1e-4 <= ft <= 10):
            raise ValueError(f"{where}: model_config.frame_time: expected seconds in [1e-4, 10], got {_kind(ft)}")
        fps = cfg.get("fps")
        if isinstance(fps, (int, float)) and not isinstance(fps, bool) and abs(fps * ft - 1) > 1e-3:
            raise ValueError(f"{where}: model_config.fps {fps!r} does not match frame_time {ft!r} (1 / frame_time)")


def _locomotion(cfg: Mapping, config, where: str, task_module=None) -> None:
    from refimpl.protocols.locomotion_data import BANDAI_NAMCO_RIG, CMU_RIG

    _require(cfg, ("skeleton", "rig"), where, "locomotion")
    rigs = {r.name: r for r in (CMU_RIG, BANDAI_NAMCO_RIG)}
    if not isinstance(cfg["rig"], str) or cfg["rig"] not in rigs:
        raise ValueError(f"{where}: model_config.rig: expected one of {list(rigs)}, got {_kind(cfg['rig'])}")
    sk = _skeleton(cfg["skeleton"], where, want_sides=True)
    keep = set(rigs[cfg["rig"]].keep)
    if keep != set(sk.names):
        raise ValueError(f"{where}: model_config.skeleton does not have the joints of the {cfg['rig']!r} rig "
                         f"(missing {sorted(keep - set(sk.names))[:4]}, extra {sorted(set(sk.names) - keep)[:4]})")
    for key in ("prefix", "target"):
        if key in cfg:
            _positive_int(cfg, key, where)
    J = getattr(config, "num_joints", None)
    if J is None:  # the pace network stores the rig and skeleton only
        return
    if J != sk.num_joints:
        raise ValueError(f"{where}: model_config.num_joints {J!r} does not match the stored skeleton's "
                         f"{sk.num_joints} joints")
    _require(cfg, ("seed_clip",), where, "quaternet-long")
    seed = cfg["seed_clip"]
    if not isinstance(seed, Mapping) or "rotations" not in seed or "features" not in seed:
        raise ValueError(f"{where}: model_config.seed_clip: expected an object with rotations and features, got "
                         f"{_kind(seed)}")
    rot = _numbers(seed["rotations"], f"{where}: model_config.seed_clip.rotations", (None, J, 4))
    feat = _numbers(seed["features"], f"{where}: model_config.seed_clip.features", (rot.shape[0], 8))
    if not 1 <= rot.shape[0] <= 1000:
        raise ValueError(f"{where}: model_config.seed_clip: expected 1 to 1000 frames, got {rot.shape[0]}")
    norms = np.linalg.norm(rot, axis=-1)
    if not np.all((norms > 0.5) & (norms < 2.0)):
        raise ValueError(f"{where}: model_config.seed_clip.rotations: expected unit quaternions, got norms from "
                         f"{norms.min():.3g} to {norms.max():.3g}")
    del feat


def _transition(cfg: Mapping, config, where: str, task_module=None) -> None:
    if "root_mean" not in cfg or "root_std" not in cfg:
        raise ValueError(f"{where}: the checkpoint has no normalisation statistics (root_mean/root_std); train it "
                         "with `refimpl train`")


#: task name -> ``check(model_config, config, where)`` raising ValueError.
TASK_CHECKS: dict[str, Callable] = {"synthesis": _synthesis, "prediction": _prediction, "locomotion": _locomotion,
                                    "transition": _transition}


def validate_task_checkpoint(task: str, model_config: Mapping, config, where: str = "checkpoint",
                             task_module=None) -> None:
    """Check the task fields of a checkpoint's ``model_config`` against ``config`` (the validated network
    config); ``ValueError`` naming ``where`` and the field. Unknown tasks are not checked.

    ``task_module`` (the task's module, when the caller has it) is passed on to the check; the tables the checks
    use (Table 1 rows, locomotion rigs) come from :mod:`refimpl.protocols`, so ``deploy``'s loaders check as
    much as ``refimpl``'s."""
    check = TASK_CHECKS.get(task)
    if check is not None:
        check(model_config, config, where, task_module)
