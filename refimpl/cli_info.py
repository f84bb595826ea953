"""``refimpl info FILE`` (spec/cli.md §2): what a BVH, exp-map text file, checkpoint ``.npz`` or ``.onnx`` model
holds — joints, frames, frame rate and channel layout of a motion file; parameters, shapes and metadata of a
checkpoint (validated against its schema first) or an ONNX model. The printing half of :mod:`refimpl.cli`.

Shape legend: T frames, J joints.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Mapping

import numpy as np

from refimpl.errors import DEPLOY_HINT, BadInputError, MissingDependency, existing_file, reading
from refimpl.files import read_bytes
from refimpl.pretrained import resolve_checkpoint
from refimpl.registry import MODELS, task_of
from refimpl.services import read_motion

__all__ = ["cmd_info"]


def _say(*parts) -> None:
    print(*parts, flush=True)


def _info_bvh(p: Path, args) -> None:
    from collections import Counter

    from refimpl.bvh import read_bvh, read_bvh_header

    with reading(p):
        header = read_bvh_header(p)
        motion = read_bvh(p, frame_time=None if args.fps is None else 1.0 / args.fps)
    skel = header.skeleton
    n_end = len(skel.end_sites)
    fps = motion.fps
    _say(f"file        {p}")
    _say("format      BVH")
    _say(f"joints      {skel.num_joints} ({skel.num_joints - n_end} joints + {n_end} End Sites), "
         f"root {skel.names[0]!r}")
    _say(f"frames      {motion.num_frames}")
    _say(f"frame time  {motion.frame_time:.7g} s ({fps:.6g} fps"
         + (", overridden by --fps" if args.fps else "") + f"), duration {motion.duration:.2f} s")
    _say(f"channels    {header.num_channels} per frame")
    groups = Counter(ch for ch in header.channels if ch)  # insertion order: the root's layout first
    for ch, count in groups.items():
        who = skel.names[header.channels.index(ch)] if count == 1 else f"{count} joints"
        _say(f"            {who}: {' '.join(ch)}")
    in_file = header.translated_joint_names
    _say(f"translations {len(in_file)} non-root joint(s) with position channels in the file"
         + (f": {', '.join(in_file[:8])}{' ...' if len(in_file) > 8 else ''}" if in_file else ""))
    if motion.skeleton.names[0] != skel.names[0]:
        _say(f"            re-rooted at {motion.skeleton.names[0]!r} (the motion is on a child of the static root "
             f"{skel.names[0]!r}; spec/data.md §2.1)")
    kept = motion.translated_joint_names
    if in_file:
        _say(f"            after reading: {', '.join(kept) if kept else 'none varying (folded into the offsets)'}")
    if motion.num_frames:  # a valid file may hold no frame at all
        pos = motion.positions()  # (T, J, 3)
        ext = pos.max(axis=(0, 1)) - pos.min(axis=(0, 1))
        _say(f"extent      x {ext[0]:.2f}  y {ext[1]:.2f}  z {ext[2]:.2f} (file units; root travel "
             f"{np.linalg.norm(motion.root_positions[-1] - motion.root_positions[0]):.2f})")
    _print_joints(skel, args)


def _print_joints(skel, args) -> None:
    if not args.joints:
        return
    depth = [0] * skel.num_joints
    for j in range(1, skel.num_joints):
        depth[j] = depth[int(skel.parents[j])] + 1
    ends = set(skel.end_sites)
    for j, name in enumerate(skel.names):
        off = np.asarray(skel.offsets[j])
        _say(f"  {j:3d} {'  ' * depth[j]}{name}{' (End Site)' if j in ends else ''}  "
             f"offset ({off[0]:.3f}, {off[1]:.3f}, {off[2]:.3f})")


def _info_expmap(p: Path, args) -> None:
    from refimpl.expmap import EXPMAP_LAYOUTS

    motion = read_motion(p, fps=args.fps, layout=args.layout)
    width = EXPMAP_LAYOUTS[args.layout][0]
    _say(f"file        {p}")
    _say(f"format      exp-map text, layout {args.layout!r} ({width} values per row = {width // 3} triplets)")
    _say(f"joints      {motion.num_joints} (built-in skeleton, {len(motion.skeleton.end_sites)} End Sites)")
    _say(f"frames      {motion.num_frames}")
    _say(f"frame time  {motion.frame_time:.7g} s ({motion.fps:.6g} fps, "
         + ("from --fps" if args.fps else "the layout's default; not stored in the file") + "), "
         f"duration {motion.duration:.2f} s")
    _print_joints(motion.skeleton, args)


def _shape_rows(arrays: Mapping[str, np.ndarray]) -> list[str]:
    width = max((len(k) for k in arrays), default=0)
    return [f"  {k.ljust(width)}  {str(tuple(v.shape)):>14}  {v.dtype}" for k, v in arrays.items()]


def _seconds(x) -> str:
    """``12.3 s`` for a number, else the stored value as text (metadata is data: never trusted to be a number)."""
    if isinstance(x, (int, float)) and not isinstance(x, bool):
        return f"{float(x):.1f} s"
    return f"{x!r:.40}"


def _config_summary(cfg: Mapping, width: int = 60, line_width: int = 100) -> list[str]:
    """The config as ``key=value`` pairs in lines of at most ``line_width`` characters; a value longer than
    ``width`` characters (statistics, skeletons) is summarised by its type and size."""
    parts = []
    for k in sorted(cfg):
        text = json.dumps(cfg[k])
        if len(text) > width:
            v = cfg[k]
            size = f"{len(v)} values" if isinstance(v, list) else f"{len(v)} keys" if isinstance(v, dict) else \
                f"{len(text)} characters"
            text = f"<{type(v).__name__}, {size}>"
        parts.append(f"{k}={text}")
    lines = [""]
    for part in parts:
        if lines[-1] and len(lines[-1]) + len(part) + 2 > line_width:
            lines.append("")
        lines[-1] += (", " if lines[-1] else "") + part
    return lines


def _info_npz(p: Path, args) -> None:
    from refimpl.checkpoint import load_checkpoint, load_state_dict_npz

    with reading(p):
        try:
            arrays, meta = load_checkpoint(p)
        except ValueError as exc:
            if "not a refimpl checkpoint" not in str(exc):
                raise
            arrays, meta = load_state_dict_npz(p), None
    training = meta is not None and meta.get("format") == "refimpl.train/1"
    if training:
        from refimpl.checkpoint_schema import validate_trained

        with reading(p):  # a training checkpoint must pass its schema (spec/robustness.md §9): exit 3 otherwise
            validate_trained(arrays, meta, MODELS, str(p), task_of=task_of)
    _say(f"file        {p}")
    if meta is None:
        n = sum(int(v.size) for v in arrays.values())
        _say(f"format      plain .npz state dict ({len(arrays)} arrays, {n:,} values)")
        for row in _shape_rows(arrays):
            _say(row)
        return
    params = {k[len("param."):]: v for k, v in arrays.items() if k.startswith("param.")}
    other = {k: v for k, v in arrays.items() if not k.startswith("param.")}
    _say(f"format      refimpl checkpoint ({meta.get('format', 'no format tag')}), checksum OK")
    if training:  # other metadata (any JSON object) is printed as it is, below
        cfg = dict(meta["model_config"])
        stats = {k: cfg.pop(k) for k in ("root_mean", "root_std") if k in cfg}
        _say(f"model       {meta['model']}")
        if isinstance(meta.get("imported"), dict):  # `refimpl import` (spec/import.md)
            imp = meta["imported"]
            _say(f"imported    from {imp.get('source')} ({imp.get('layout')} names, sha256 "
                 f"{str(imp.get('sha256'))[:16]}...), not trained here")
        _say(f"progress    step {meta.get('step')} of {meta.get('steps_target')}, epoch {meta.get('epoch')}, "
             f"trained for {_seconds(meta.get('elapsed_s', 0.0))}")
        for i, line in enumerate(_config_summary(cfg)):
            _say(("config      " if i == 0 else " " * 12) + line)
        if stats:
            _say(f"normalise   root mean {np.round(stats.get('root_mean', []), 3).tolist()} "
                 f"std {np.round(stats.get('root_std', []), 3).tolist()}")
        if meta.get("optim"):
            _say(f"optimiser   {json.dumps(meta['optim'], sort_keys=True)}, batch {meta.get('batch_size')}")
    else:
        _say(f"metadata    {json.dumps(meta, sort_keys=True)[:400]}")
    n = sum(int(v.size) for v in params.values())
    _say(f"parameters  {len(params)} arrays, {n:,} values")
    for row in _shape_rows(params):
        _say(row)
    if other:
        _say(f"other       {len(other)} arrays (optimiser state, sampler): "
             + ", ".join(sorted(other)[:6]) + (" ..." if len(other) > 6 else ""))


def _info_onnx(p: Path, args) -> None:
    try:
        import onnx
    except ImportError as exc:
        raise MissingDependency(f"reading .onnx files {DEPLOY_HINT}") from exc
    from collections import Counter

    with reading(p):
        try:
            model = onnx.load_model_from_string(read_bytes(p))  # a regular file, read to its size
        except Exception as exc:  # onnx raises DecodeError and others on garbage
            raise ValueError(f"not a readable ONNX model ({type(exc).__name__}: {exc})") from exc
    g = model.graph

    def dims(vi):
        t = vi.type.tensor_type
        shape = [d.dim_param or d.dim_value for d in t.shape.dim]
        return f"{vi.name} {shape} {onnx.TensorProto.DataType.Name(t.elem_type).lower()}"

    inits = {i.name for i in g.initializer}
    n_values = sum(int(np.prod(i.dims)) for i in g.initializer)
    ops = Counter(n.op_type for n in g.node)
    _say(f"file        {p}")
    _say(f"format      ONNX, IR version {model.ir_version}, opsets "
         + ", ".join(f"{o.domain or 'ai.onnx'} {o.version}" for o in model.opset_import)
         + (f", producer {model.producer_name} {model.producer_version}".rstrip() if model.producer_name else ""))
    _say(f"graph       {g.name!r}: {len(g.node)} nodes ({', '.join(f'{k} {v}' for k, v in ops.most_common(6))}"
         + (" ..." if len(ops) > 6 else "") + f"), {len(inits)} initializers, {n_values:,} values")
    for vi in g.input:
        if vi.name not in inits:
            _say(f"input       {dims(vi)}")
    for vi in g.output:
        _say(f"output      {dims(vi)}")
    for prop in model.metadata_props:
        if prop.key == "io":
            continue
        try:  # metadata is data of unknown shape: a value that does not fit the summary is printed as text
            value = json.loads(prop.value)
            if prop.key == "skeleton" and isinstance(value, dict):
                value = f"{len(value.get('names', []))} joints: " + ", ".join(value.get("names", [])[:6]) + " ..."
            elif prop.key == "normalization" and isinstance(value, dict):
                value = (f"in graph: {value.get('in_graph')}, root mean "
                         f"{np.round(np.asarray(value.get('mean', [])[:3], dtype=float), 3).tolist()}")
            text = value if isinstance(value, str) else json.dumps(value, sort_keys=True)
        except (ValueError, TypeError, RecursionError):
            text = prop.value
        _say(f"meta        {prop.key}: {text[:300]}")


def cmd_info(args) -> int:
    """``refimpl info FILE``."""
    p = existing_file(resolve_checkpoint(args.file))   # pretrained:<name> -> its verified model.npz
    kind = p.suffix.lower()
    handlers = {".bvh": _info_bvh, ".txt": _info_expmap, ".npz": _info_npz, ".onnx": _info_onnx}
    if kind not in handlers:
        raise BadInputError(f"{p}: unknown file type {p.suffix!r} (expected .bvh, .txt, .npz or .onnx)")
    handlers[kind](p, args)
    return 0


def cmd_pretrained(args) -> int:
    """``refimpl pretrained [NAME] [--json]``: the shipped models with their cards (:mod:`refimpl.pretrained`)."""
    from refimpl.pretrained import PREFIX, catalogue, find, roots

    if args.name:
        shipped = find(args.name[len(PREFIX):] if args.name.startswith(PREFIX) else args.name)
        if args.json:
            print(json.dumps(shipped.card, indent=1, sort_keys=True))
        else:
            card_md = shipped.folder / "card.md"
            print(card_md.read_text(encoding="utf-8") if card_md.is_file() else json.dumps(shipped.card, indent=1))
        return 0
    models = catalogue()
    if args.json:
        print(json.dumps({n: m.card for n, m in models.items()}, indent=1, sort_keys=True))
        return 0
    if not models:
        _say("no shipped model found in " + ", ".join(str(r) for r in roots())
             + " (they ship in the repository's pretrained/ folder: run from a clone, or set REFIMPL_PRETRAINED)")
        return 0
    width = max(len(n) for n in models) + len(PREFIX)
    for n, m in models.items():
        c = m.card
        weights = c["licence"]["weights"].split(":")[0] if isinstance(c.get("licence"), dict) else "?"
        _say(f"{PREFIX + n:<{width}}  {c['title']}")
        _say(f"{'':<{width}}  {c['parameters']:,} parameters, {c['size_bytes'] / 1e6:.1f} MB, weights {weights}; "
             f"{m.folder / 'card.md'}")
    _say("use one wherever a checkpoint is accepted, e.g. refimpl eval --checkpoint " + PREFIX + next(iter(models)))
    return 0
