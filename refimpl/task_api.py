"""The task interface: what the services and the command line ask of a task (spec/architecture.md §tasks).

A task is a module (``refimpl/tasks/<name>.py``, registered in :data:`refimpl.registry.TASKS`) that provides
every member of :class:`Task`. The registry checks it (:func:`check_task`) when it first hands the module out,
so that ``refimpl/cli.py`` and ``refimpl/services.py`` call the members without asking which task they have:
they name no model and no task.

Shape legend: none (the members' arrays are the task's own; see each task module).
"""
from __future__ import annotations

from types import ModuleType
from typing import Any, Callable, Mapping, Protocol, runtime_checkable

__all__ = ["Task", "TASK_MEMBERS", "check_task"]


@runtime_checkable
class Task(Protocol):
    """The members of a task module (a module satisfies this protocol structurally).

    Attributes
    ----------
    NAME : str
        The task's name (its key in :data:`refimpl.registry.TASKS`, the recipes' ``TASK``).
    EVAL_SUMMARY : str
        One line for ``refimpl eval --help``: the protocol and the baselines.
    GENERATE_USAGE : str
        One usage line of ``refimpl generate`` for this task (``refimpl generate --help``, usage errors).
    CHECKPOINT_SCHEMA : refimpl.checkpoint_fields.TaskSchema
        What the task stores in a checkpoint and how it is checked (its paper's protocol's; every loader applies
        it, :func:`refimpl.checkpoint_schema.validate_checkpoint_config`).
    """

    NAME: str
    EVAL_SUMMARY: str
    GENERATE_USAGE: str
    CHECKPOINT_SCHEMA: Any

    def add_train_options(self, parser) -> None:
        """Add the task's ``refimpl train`` options to ``parser`` (an argument group of its own)."""

    def add_eval_options(self, parser) -> None:
        """Add the task's ``refimpl eval`` options."""

    def add_export_options(self, parser) -> None:
        """Add the task's ``refimpl export`` options."""

    def add_generate_options(self, parser) -> None:
        """Add the task's ``refimpl generate`` options."""

    def train_datasets(self, args) -> tuple:
        """``(train, held-out)`` datasets of ``refimpl train``'s options."""

    def import_datasets(self, args) -> tuple:
        """``(train, held-out)`` datasets for ``refimpl import``: what an imported checkpoint stores from the data
        (the same checkpoint as :meth:`train_datasets`' data gives), reading no more than it needs; the held-out
        one may be None."""

    def num_examples(self, dataset) -> int:
        """Training examples of a dataset (the epoch)."""

    def describe_data(self, train_ds, test_ds) -> str:
        """One line on the data."""

    def checkpoint_extra(self, train_ds) -> dict:
        """What a checkpoint stores beside the network for this task (statistics, rate, skeleton, ...)."""

    def check_checkpoint(self, model_config: Mapping, path) -> None:
        """Refuse (``BadInputError``) a checkpoint without what the task needs."""

    def trained_fields(self, model_config: Mapping, config) -> dict:
        """``{"fps": ..., "fields": {...}}``: the :class:`~refimpl.registry.TrainedModel` fields of this task
        (``fields`` is the task's own mapping)."""

    def onnx_method(self, runtime) -> Callable:
        """An exported model's runtime in the task's method interface."""

    def methods(self, networks: Mapping[str, Callable] | None = None, *, fps: float | None = None) -> dict:
        """``name -> method``: the networks' methods and the task's baselines."""

    def evaluate(self, test_ds, methods_by_name: Mapping[str, Callable]) -> Any:
        """The task's protocol on ``test_ds`` for every method."""

    def eval_command(self, args, model) -> int:
        """``refimpl eval`` (``model``: the loaded ``--checkpoint`` or None); returns the exit code."""

    def generate_command(self, args, model) -> int:
        """``refimpl generate`` (``model``: the loaded ``--checkpoint`` or None when ``--model`` chose the task);
        returns the exit code."""

    def export_options(self, args) -> dict:
        """The exporter's keyword arguments from ``refimpl export``'s task options."""

    def verify_inputs(self, args, model) -> tuple:
        """``(inputs, options)`` of ``refimpl export``'s onnxruntime-vs-NumPy check (``recipe.verify_onnx(model,
        runtime, *inputs, **options)``), drawn with ``args.seed``."""


#: The names a task module must define.
TASK_MEMBERS = tuple(sorted({*Task.__annotations__,
                             *(n for n, v in vars(Task).items() if callable(v) and not n.startswith("_"))}))


def check_task(module: ModuleType) -> ModuleType:
    """``module`` when it defines every member of :class:`Task`.

    Raises
    ------
    TypeError
        Naming the members it lacks.
    """
    missing = [n for n in TASK_MEMBERS if not hasattr(module, n)]
    if missing:
        raise TypeError(f"task module {module.__name__}: missing {missing} (refimpl.task_api.Task)")
    return module
