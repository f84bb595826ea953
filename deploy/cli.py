"""Command line of the deployment path: ``python -m deploy {export, run, info} ...`` (``spec/deploy.md`` §8).

Every model goes through its entry of the exporter table ``deploy.models.EXPORTERS``; this module names none.

``export CHECKPOINT OUT_DIR``
    Read the checkpoint's model name (``refimpl train`` stores it; a plain state dict: ``--model``, default the
    first entry of the table, ``qtg``), map it to its exporter (the registry's ``ModelSpec.exporter``: ``pace`` →
    ``quaternet-long``) and export with that entry's ``export_checkpoint(entry, args)`` — or, for an entry
    without one, as ``refimpl export`` does (``deploy.models.run_commands.export_trained``). Files are validated
    and written atomically; their paths and sizes are printed.
``run MODEL_DIR INPUT OUTPUT``
    Open the folder's models with the runtime of the model named in their metadata
    (``deploy.models.runtime_for_dir``) and call the entry's ``run_command(runtime, args)``: the model's natural
    input (a BVH clip, an exp-map prefix, a seed take, ``.npy`` frames) to its natural output (BVH or ``.npy``).
``info MODEL.onnx`` | ``info MODEL_DIR``
    Validate a model (or every ``.onnx`` file of a folder, in name order) and print its inputs, outputs and
    metadata; a missing, empty or undecodable model is exit 3.
``web DIR [DIR ...] [--port N]``
    Serve the models of the folders in a web page on 127.0.0.1 (``deploy.serve``: onnxruntime-web and three.js,
    installed once with ``npm ci``).

Options of one model come from its entry (``add_export_options(group)``, ``add_run_options(group)``) and are
refused for another model. ``main(argv)`` returns the exit status: 0 success; 2 a bad option value or options
that do not fit the model (one line on stderr); 3 a missing or malformed input file; 1 a missing dependency.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

import numpy as np

__all__ = ["main"]


def _entries():
    """``[(name, entry module)]`` of the exporter table, in its order."""
    from deploy.models import EXPORTERS, exporter

    return [(name, exporter(name)) for name in EXPORTERS]


def _exporter_of_checkpoint(path, override: str | None) -> str:
    """The exporter key of the checkpoint's model (``--model`` overrides: a model or an exporter name)."""
    from deploy.models import EXPORTERS
    from refimpl.checkpoint import load_checkpoint
    from refimpl.registry import MODELS

    from refimpl.errors import existing_file

    existing_file(path)  # a regular file (not a FIFO or a device), else exit 3
    name = override
    if name is None:
        try:
            _, meta = load_checkpoint(path)
        except ValueError as exc:
            if "not a refimpl checkpoint" not in str(exc):
                raise _BadInput(str(exc)) from None
            return next(iter(EXPORTERS))          # a plain state dict: the table's first model (qtg)
        name = str(meta.get("model") or next(iter(EXPORTERS)))
    spec = MODELS.get(name)
    key = spec.exporter if spec is not None and spec.exporter is not None else name
    if key not in EXPORTERS:
        raise ValueError(f"model {name!r}: no exporter; known: {sorted(EXPORTERS)}")
    return key


class _BadInput(Exception):
    """A named input file is missing or malformed (exit 3)."""


def _check_foreign_options(args, chosen: str, owners: dict) -> None:
    """Options that only other models' entries take must be left at their defaults (``None``)."""
    for dest, (flag, models) in owners.items():
        if chosen not in models and getattr(args, dest, None) is not None:
            raise ValueError(f"{flag}: an option of {', '.join(sorted(models))}, not of {chosen}")


def _cmd_export(args) -> int:
    from deploy.models import exporter
    from deploy.models.run_commands import export_trained

    from refimpl.pretrained import resolve_checkpoint

    args.checkpoint = str(resolve_checkpoint(args.checkpoint))   # pretrained:<name> -> its verified file
    key = _exporter_of_checkpoint(args.checkpoint, args.model)
    _check_foreign_options(args, key, args._owners)
    entry = exporter(key)
    export = getattr(entry, "export_checkpoint", None)
    paths = export(entry, args) if export is not None else export_trained(entry, args)
    for role, p in paths.items():
        print(f"{role}: {p} ({p.stat().st_size / 1e6:.2f} MB)")
    return 0


def _cmd_run(args) -> int:
    from deploy.models import exporter, model_name_of_dir, runtime_for_dir
    from refimpl.errors import existing_file, reading

    from pathlib import Path

    if not Path(args.model_dir).is_dir():
        raise _BadInput(f"{args.model_dir}: no such folder of exported models")
    if Path(args.input).suffix.lower() in _FILE_INPUTS:
        existing_file(args.input)  # a regular file, else exit 3 before any model is opened
    with reading(args.model_dir):  # the folder's models are input files: damage is exit 3
        name = model_name_of_dir(args.model_dir)
    _check_foreign_options(args, name, args._owners)
    entry = exporter(name)
    with reading(args.model_dir):
        runtime = runtime_for_dir(args.model_dir, intra_op_threads=args.threads)
    return int(entry.run_command(runtime, args))


#: Suffixes of ``run``'s INPUT that name a file (a path of quaternet-long may be a built-in path's text).
_FILE_INPUTS = (".bvh", ".txt", ".npy", ".csv")


def _cmd_info(args) -> int:
    """``info FILE.onnx`` or ``info DIR``: the contract of one model, or of every ``.onnx`` file in a folder (in
    name order, each under a ``== name ==`` line). A missing, empty or undecodable model is exit 3."""
    from pathlib import Path

    path = Path(args.model)
    if path.is_dir():
        files = sorted(path.glob("*.onnx"))
        if not files:
            raise _BadInput(f"{path}: a folder without .onnx files")
        for k, file in enumerate(files):
            print(f"{'' if k == 0 else chr(10)}== {file.name} ==")
            _print_contract(_load_for_info(file))
        return 0
    _print_contract(_load_for_info(path))
    return 0


def _load_for_info(path):
    """The :class:`deploy.runtime.DeployedModel` of ``path``; a file that is missing or cannot be read as a valid
    ONNX model is :class:`_BadInput` (exit 3)."""
    from refimpl.errors import BadInputError, MissingDependency, reading

    from deploy.runtime import load_model

    if not path.exists():
        raise _BadInput(f"{path}: no such file")
    try:
        with reading(path):  # a regular file read with refimpl.files; metadata types and fields checked: exit 3
            return load_model(path)
    except (MissingDependency, BrokenPipeError, BadInputError):
        raise
    except Exception as exc:  # noqa: BLE001 - whatever the decoder or the checker says: the file is bad
        raise _BadInput(f"{path}: not a valid ONNX model ({' '.join(str(exc).split())[:300]})") from None


def _print_contract(m) -> None:
    for title, entries in (("inputs", m.inputs), ("outputs", m.outputs)):
        print(f"{title}:")
        for n, shape, t in entries:
            print(f"  {n} {tuple(shape)} {None if t is None else np.dtype(t).name}")
    print("metadata:")
    for key, value in sorted(m.metadata.items()):
        if key == "skeleton" and value is not None:
            value = {"joints": len(value["names"]), "names": value["names"], "units": value.get("units")}
        elif key == "normalization" and value is not None:
            value = {"in_graph": value["in_graph"], "model_io": value.get("model_io"),
                     "mean[:3]": value["mean"][:3], "std[:3]": value["std"][:3]}
        elif key in ("input_transform", "output_transform") and isinstance(value, dict):
            print(f"  {key}: {value.get('summary', '')}")
            for step in value.get("steps", []):
                print(f"    {step}")
            continue
        elif key == "io":
            continue
        print(f"  {key}: {json.dumps(value)}")


def _cmd_web(args) -> int:
    from deploy.serve import main_web

    return main_web(args)


def _add_model_options(sub, hook: str, owners: dict) -> None:
    """Each entry's ``hook(group)`` options (a function shared by several entries is called once), recorded in
    ``owners``: dest -> (flag, set of the models that take it)."""
    users: dict = {}
    for name, entry in _entries():
        add = getattr(entry, hook, None)
        if add is not None:
            users.setdefault(add, []).append(name)
    for add, names in users.items():
        group = sub.add_argument_group(f"{', '.join(names)} options")
        before = len(group._group_actions)
        add(group)
        for action in group._group_actions[before:]:
            flag, models = owners.get(action.dest, (action.option_strings[0], set()))
            owners[action.dest] = (flag, models | set(names))


def _parser():
    from refimpl.bounds import bounded_float, bounded_int  # the bounds of refimpl's options (spec/cli.md §1.1)

    p = argparse.ArgumentParser(prog="python -m deploy",
                                description="Export trained networks to ONNX and run exported models (the exporter "
                                            "and the runtime are chosen by the model named in the checkpoint or in "
                                            "the files' metadata: deploy.models.EXPORTERS).")
    sub = p.add_subparsers(dest="command", required=True)
    e = sub.add_parser("export", help="export a checkpoint to ONNX with its model's exporter")
    e.add_argument("checkpoint")
    e.add_argument("out_dir")
    e.add_argument("--model", default=None, help="model or exporter name (default: the model named in the "
                                                  "checkpoint; a plain state dict: qtg)")
    e.add_argument("--opset", type=int, default=None)  # checked by the exporter (deploy.graph)
    e.add_argument("--dtype", choices=("float32", "float64"), default="float32")
    e.add_argument("--mode", choices=("scan", "loop", "unrolled"), default=None,
                   help="form of a whole-sequence graph (qtg's rollout; default: the model's)")
    e.add_argument("--frames", type=bounded_int("frames"), default=None, help="frames of a fixed-length graph (qtg: T of the "
                                                             "rollout, quaternet: k of the predictor)")
    e.add_argument("--target", choices=("default", "portable"), default="default",
                   help="default: today's graphs (onnxruntime); portable: per-call graphs at opset 15, batch 1, "
                        "primitive operators, the host loop in the metadata (Unity Inference Engine, other "
                        "runtimes; deploy/README.md)")
    export_owners: dict = {}
    _add_model_options(e, "add_export_options", export_owners)
    e.set_defaults(func=_cmd_export, _owners=export_owners)
    r = sub.add_parser("run", help="run exported models on the model's natural input (BVH, exp-map, .npy)")
    r.add_argument("model_dir")
    r.add_argument("input")
    r.add_argument("output")
    r.add_argument("--start", type=bounded_int("frame_index"), default=None,
                   help="qtg: first generated frame (required); quaternet: last prefix frame (default: the "
                        "clip's last); acrnn: first seed frame (default 1: frame 0 is the T-pose); quaternet-long: prefix length P")
    r.add_argument("--frames", type=bounded_int("frames"), default=None,
                   help="frames to generate (default: the model's)")
    r.add_argument("--fps", type=bounded_float("fps"), default=None,
                   help="qtg: frame rate of the transition (default 30)")
    r.add_argument("--threads", type=bounded_int("ort_threads"), default=1, help="onnxruntime threads")
    run_owners: dict = {}
    _add_model_options(r, "add_run_options", run_owners)
    r.set_defaults(func=_cmd_run, _owners=run_owners)
    i = sub.add_parser("info", help="validate a model (or every .onnx file of a folder) and print its contract")
    i.add_argument("model", help="an .onnx file or a folder of exported models")
    i.set_defaults(func=_cmd_info, _owners={})
    w = sub.add_parser("web", help="serve the models of folders in a web page on 127.0.0.1 (onnxruntime-web)")
    w.add_argument("folders", nargs="+", metavar="DIR", help="folders written by python -m deploy export")
    w.add_argument("--port", type=int, default=8000, help="port on 127.0.0.1 (default 8000; 0: any free port)")
    w.set_defaults(func=_cmd_web, _owners={})
    return p


def main(argv=None) -> int:
    """Entry point; returns 0 on success, 2 on a bad option value, 3 on a bad input file (message on stderr), 1
    quietly when stdout is closed early (`... | head`)."""
    from refimpl.errors import BadInputError, MissingDependency, UsageError

    args = _parser().parse_args(argv)
    try:
        rc = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, not in the interpreter's exit
        return rc
    except BrokenPipeError:  # the reader went away (`python -m deploy info m.onnx | head`): stop quietly
        _discard_stdout()
        return 1
    except (BadInputError, _BadInput, FileNotFoundError, IsADirectoryError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 3
    except (UsageError, ValueError, KeyError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except MissingDependency as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1


def _discard_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not raise again."""
    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):
        pass
