"""The exporter-entry interface: what ``python -m deploy``, ``refimpl export`` and the services ask of an entry of
the exporter table (spec/architecture.md §deploy, spec/deploy.md §8).

An entry is a module (``deploy/models/<model>_io.py``, registered in :data:`deploy.models.EXPORTERS`) that defines
every required member of :class:`ExporterEntry` under the protocol's own name (no alias lines); the optional
command hooks (:data:`OPTIONAL_MEMBERS`) only when the model has them. :func:`deploy.models.exporter` checks an
entry with :func:`check_entry` when it first hands it out.

Shape legend: none (the members' arrays are the model's own; see each entry module).
"""
from __future__ import annotations

from types import ModuleType
from typing import Protocol, runtime_checkable

__all__ = ["ExporterEntry", "ENTRY_MEMBERS", "OPTIONAL_MEMBERS", "check_entry"]


@runtime_checkable
class ExporterEntry(Protocol):
    """The members of an exporter entry module (a module satisfies this protocol structurally).

    Attributes
    ----------
    Runtime : type
        Runs the exported files: ``Runtime.from_dir(directory, intra_op_threads=1)``.
    """

    Runtime: type

    def load_checkpoint(self, path) -> tuple:
        """``(params, config, meta)`` of a ``refimpl train`` checkpoint (or a state dict, where the model allows
        it), checked against the checkpoint schema (``ValueError`` naming the file and the field)."""

    def export_dir(self, params, config, out_dir, **options) -> dict:
        """Validated files written atomically into ``out_dir``; ``role -> Path``."""

    def run_command(self, runtime, args) -> int:
        """``python -m deploy run`` on the model's natural input (``deploy/cli.py``); returns the exit code."""


#: Hooks an entry may define (``python -m deploy``): ``export_checkpoint(entry, args) -> dict`` (without it,
#: ``refimpl export``'s export, :func:`deploy.models.run_commands.export_trained`), ``add_export_options(group)`` and
#: ``add_run_options(group)`` (the model's own options, refused for other models).
OPTIONAL_MEMBERS = ("add_export_options", "add_run_options", "export_checkpoint")

#: The names an entry module must define.
ENTRY_MEMBERS = tuple(sorted({*ExporterEntry.__annotations__,
                              *(n for n, v in vars(ExporterEntry).items() if callable(v) and not n.startswith("_"))}))


def check_entry(module: ModuleType) -> ModuleType:
    """``module`` when it defines every member of :class:`ExporterEntry` (callable; ``Runtime`` with a
    ``from_dir``) and its optional hooks are callable.

    Raises
    ------
    TypeError
        Naming the members it lacks or that are not callable.
    """
    missing = [n for n in ENTRY_MEMBERS if not callable(getattr(module, n, None))]
    if not missing and not callable(getattr(module.Runtime, "from_dir", None)):
        missing = ["Runtime.from_dir"]
    missing += [n for n in OPTIONAL_MEMBERS if hasattr(module, n) and not callable(getattr(module, n))]
    if missing:
        raise TypeError(f"exporter entry {module.__name__}: missing or not callable {missing} "
                        "(deploy.models.entry_api.ExporterEntry)")
    return module
