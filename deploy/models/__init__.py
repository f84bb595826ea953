"""Per-model exporters and runtimes, and the exporter table (spec/deploy.md §8, spec/architecture.md).

:data:`EXPORTERS` maps a model name (``ModelSpec.exporter`` of its recipe, and ``model.name`` in the metadata
of every file it exports) to its entry module, which implements :class:`deploy.models.entry_api.ExporterEntry`:

* ``load_checkpoint(path) -> (params, config, meta)`` — a ``refimpl train`` checkpoint or a state dict;
* ``export_dir(params, config, out_dir, **options) -> dict role -> Path`` — validated files written atomically;
* ``Runtime`` — a class with ``Runtime.from_dir(directory, intra_op_threads=1)`` that runs those files;
* ``run_command(runtime, args)`` — ``python -m deploy run`` on the model's natural input (``deploy/cli.py``);
* optionally ``export_checkpoint(entry, args)`` (``python -m deploy export``; without it, ``refimpl export``'s
  export: ``deploy.models.run_commands.export_trained``), ``add_export_options(group)`` and
  ``add_run_options(group)`` (the model's own command-line options, refused for other models).

:func:`exporter` imports an entry and checks it (:func:`deploy.models.entry_api.check_entry`); :func:`runtime_for_dir` opens a folder of exported models with the runtime
of the model named in their metadata. Adding a model: its graph builders in ``deploy/models/<name>.py``, its
entry module, and one line in :data:`EXPORTERS`.
"""
from __future__ import annotations

import importlib
from pathlib import Path

from deploy.models.entry_api import check_entry

__all__ = ["EXPORTERS", "exporter", "model_name_of_dir", "runtime_for_dir"]

#: Model name -> entry module (load_checkpoint, export_dir, Runtime).
EXPORTERS = {
    "qtg": "deploy.models.qtg_io",
    "quaternet": "deploy.models.quaternet_io",
    "quaternet-cnn": "deploy.models.quaternet_cnn_io",
    "acrnn": "deploy.models.acrnn_io",
    "quaternet-long": "deploy.models.quaternet_long_io",
}


def exporter(name: str):
    """The entry module of model ``name`` (:data:`EXPORTERS`), checked against the entry interface
    (:func:`deploy.models.entry_api.check_entry`); ``ValueError`` for an unknown name."""
    if name not in EXPORTERS:
        raise ValueError(f"model {name!r}: no exporter; known: {sorted(EXPORTERS)}")
    return check_entry(importlib.import_module(EXPORTERS[name]))


def model_name_of_dir(directory) -> str:
    """``metadata["model"]["name"]`` of the exported models in ``directory`` (``ValueError`` when there is none,
    or when they disagree)."""
    from deploy.metadata import read_metadata

    d = Path(directory)
    files = sorted(d.glob("*.onnx"))
    if not files:
        raise ValueError(f"directory: no .onnx models in {str(d)!r}")
    names = set()
    for f in files:
        model = read_metadata(str(f)).get("model")
        if isinstance(model, dict) and isinstance(model.get("name"), str):
            names.add(model["name"])
    if len(names) != 1:
        raise ValueError(f"directory {str(d)!r}: expected the models of one network, found names {sorted(names)}")
    return names.pop()


def runtime_for_dir(directory, *, intra_op_threads: int = 1):
    """The exported models of ``directory``, opened with their model's ``Runtime`` (named in their metadata)."""
    return exporter(model_name_of_dir(directory)).Runtime.from_dir(directory, intra_op_threads=intra_op_threads)
