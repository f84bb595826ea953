"""``refimpl import`` and ``refimpl export-weights`` (spec/cli.md, spec/import.md): the argument parsers and the two
``cmd_*`` functions; the work is :mod:`refimpl.weights`.

* ``refimpl import WEIGHTS --model M [--layout published|refimpl] --out CKPT.npz [--data ...] [--set F=V]`` — a
  PyTorch state dict (``.npz``, ``.safetensors``; ``.pt`` with torch) → a refimpl checkpoint that ``eval``,
  ``generate``, ``export`` and ``info`` accept. The task's data (``--data``, default the embedded sample) gives the
  statistics and skeleton the checkpoint stores, as ``refimpl train`` would.
* ``refimpl export-weights CKPT.npz --out STATE.npz|STATE.safetensors [--layout published|refimpl]`` — the
  parameters of a refimpl checkpoint under PyTorch names (to fine-tune with PyTorch).

Exit codes as every command: 2 for a bad option (an unknown layout, ``--layout published`` for a model without
published code, an existing ``--out`` without ``--overwrite``), 3 for a bad input file (malformed, another
model's state dict, missing / unexpected / mis-shaped names). Nothing is written before the inputs are checked.
"""
from __future__ import annotations

from pathlib import Path

from refimpl.atomic import remove_stale_temp_files
from refimpl.errors import UsageError, existing_file, reading
from refimpl.options import add_data_options
from refimpl.registry import MODELS, TASKS, task_of

__all__ = ["add_parsers", "cmd_import", "cmd_export_weights"]


def _say(*parts) -> None:
    print(*parts, flush=True)


def _check_out(out: Path, overwrite: bool) -> None:
    if out.is_dir():
        raise UsageError(f"--out {out}: is a directory, expected a file name")
    if out.exists() and not overwrite:
        raise UsageError(f"--out {out} exists: pass --overwrite to replace it")
    remove_stale_temp_files(out)  # left by an import / export-weights killed while writing (refimpl.atomic)


def cmd_import(args) -> int:
    """``refimpl import``."""
    from refimpl.checkpoint import save_checkpoint
    from refimpl.weights import import_checkpoint, read_state_dict

    spec = MODELS[args.model]
    out = Path(args.out)
    if out.suffix.lower() != ".npz":
        raise UsageError(f"--out {out}: a refimpl checkpoint is a .npz file")
    _check_out(out, args.overwrite)
    if args.representation is not None and args.representation not in spec.representations:
        raise UsageError(f"--representation {args.representation!r}: model {spec.name!r} trains on "
                         f"{list(spec.representations)}")
    args.layout = _import_layout(spec, args.layout)  # an impossible layout is exit 2 before the data is read
    p = existing_file(args.weights)
    with reading(p):
        state = read_state_dict(p)
    train_ds, test_ds = task_of(spec).import_datasets(args)  # only what the checkpoint needs (spec/import.md §1)
    with reading(p):
        arrays, meta = import_checkpoint(spec, state, args.layout, train_ds, test_ds, overrides=args.set,
                                         dtype=args.dtype, source=p)
    save_checkpoint(out, arrays, meta)
    n = sum(int(a.size) for a in arrays.values())
    _say(f"imported {p} ({len(arrays)} tensors, {n:,} values, layout {args.layout}) as model {spec.name}")
    _say(f"checkpoint {out}  (next: refimpl info / eval / generate / export --checkpoint {out})")
    return 0


def _import_layout(spec, layout):
    """``--layout`` of ``refimpl import``: as given, or the model's default (published when the model has
    published code); ``published`` for a model without it is a UsageError."""
    has_published = spec.published_names is not None
    if layout is None:
        return "published" if has_published else "refimpl"
    if layout == "published" and not has_published:
        raise UsageError(f"--layout published: model {spec.name!r} has no published code to take names from; "
                         f"use --layout refimpl (spec/import.md)")
    return layout


def cmd_export_weights(args) -> int:
    """``refimpl export-weights``."""
    from refimpl.services import load_trained
    from refimpl.weights import export_state_dict, write_state_dict

    out = Path(args.out)
    if out.suffix.lower() not in (".npz", ".safetensors"):
        raise UsageError(f"--out {out}: expected a .npz or .safetensors file name")
    _check_out(out, args.overwrite)
    model = load_trained(args.checkpoint)
    state = export_state_dict(model, args.layout)
    write_state_dict(out, state, {"model": model.spec.name, "layout": args.layout, "format": "pt"})
    _say(f"wrote {len(state)} tensors of {model.spec.name} ({args.layout} names) to {out}")
    return 0


def add_parsers(sub) -> None:
    """Add ``import`` and ``export-weights`` to the ``refimpl`` sub-command parsers ``sub``."""
    from refimpl.weights import LAYOUTS

    p = sub.add_parser("import", help="a PyTorch state dict (.npz, .safetensors, .pt) -> a refimpl checkpoint",
                       description="Import weights trained elsewhere (the published code, or a PyTorch module with "
                                   "the documented names) as a checkpoint that eval, generate, export and info "
                                   "accept. The task's data (--data) gives the statistics and skeleton it stores. "
                                   "See spec/import.md.")
    p.add_argument("weights", help="state dict file: .npz (np.savez), .safetensors, or .pt/.pth/.bin (needs torch)")
    p.add_argument("--model", required=True, choices=sorted(MODELS), help="network the weights are for")
    p.add_argument("--layout", default=None, choices=LAYOUTS,
                   help="parameter names: 'published' (the published code's: QuaterNet, pace, acRNN lstm1..3; "
                        "acRNN then uses the published skewed stack) or 'refimpl' (this project's; default "
                        "published for a model with published code, refimpl for QTG and quaternet-cnn)")
    p.add_argument("--out", required=True, help="checkpoint to write (.npz)")
    p.add_argument("--representation", default=None, help="the task's representation / row (as for train)")
    add_data_options(p)
    for task_name in sorted(TASKS):
        task_of(task_name).add_train_options(p.add_argument_group(f"{task_name} task"))
    p.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                   help="config fields of the imported network, e.g. --set hidden_size=512 (after the layout's)")
    p.add_argument("--dtype", default=None, choices=("float32", "float64"),
                   help="parameter dtype (default: the state dict's)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    p.set_defaults(func=cmd_import)

    p = sub.add_parser("export-weights", help="a refimpl checkpoint -> a PyTorch-named .npz / .safetensors",
                       description="Write a checkpoint's parameters under PyTorch state-dict names (load with "
                                   "np.load or safetensors, then model.load_state_dict). See spec/import.md.")
    p.add_argument("checkpoint")
    p.add_argument("--out", required=True, help=".npz or .safetensors file to write")
    p.add_argument("--layout", default="published", choices=LAYOUTS,
                   help="names: 'published' (the published code's, default) or 'refimpl'")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    p.set_defaults(func=cmd_export_weights)
