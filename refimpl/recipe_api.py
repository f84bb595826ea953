"""The recipe interface: what the registry, the services, the checkpoint schema and ``refimpl import`` ask of a
recipe (spec/architecture.md §recipes).

A recipe is a module (``refimpl/recipes/<model>.py``, registered in :data:`refimpl.registry.RECIPES`) that defines
every member of :class:`Recipe` and, when the model has them, the optional members of
:data:`OPTIONAL_MEMBERS`. The registry checks it (:func:`check_recipe`) and reads it once into a
:class:`~refimpl.registry.ModelSpec` (:func:`optional_members`): nobody else reads a recipe's names.

Shape legend: none (the members' arrays are the model's own; see each recipe).
"""
from __future__ import annotations

from types import ModuleType
from typing import Any, Callable, Protocol, runtime_checkable

__all__ = ["Recipe", "RECIPE_MEMBERS", "OPTIONAL_MEMBERS", "check_recipe", "optional_members"]


@runtime_checkable
class Recipe(Protocol):
    """The members every recipe module defines (a module satisfies this protocol structurally).

    Attributes
    ----------
    NAME : str
        ``--model`` value, stored in checkpoints.
    SUMMARY : str
        One line for ``refimpl train --help``.
    TASK : str
        Key of :data:`refimpl.registry.TASKS`.
    REPRESENTATIONS : tuple of str
        Pose representations it trains on (the first is the default).
    CONFIG_TYPE : type
        Frozen dataclass of the network's sizes (``--set field=value``).
    PAPER_OPTIM : refimpl.train.OptimConfig
        The paper's optimiser settings.
    PAPER_BATCH : int
        The paper's batch size.
    """

    NAME: str
    SUMMARY: str
    TASK: str
    REPRESENTATIONS: tuple
    CONFIG_TYPE: type
    PAPER_OPTIM: Any
    PAPER_BATCH: int

    def make_config(self, train_ds, overrides) -> Any:
        """The network's config from the training data and ``--set`` overrides."""

    def make_adapter(self, train_ds, val_ds, config, dtype, extra) -> Any:
        """The :class:`refimpl.train.ModelAdapter` of a run (``extra``: the task's checkpoint fields)."""

    def make_method(self, trained) -> Callable:
        """NumPy inference of a :class:`~refimpl.registry.TrainedModel` in its task's method interface."""


#: Optional members (the model has them or not) -> the value the registry uses without them:
#: ``EXPORTER`` (key of ``deploy.models.EXPORTERS``), ``export_inputs(trained) -> dict`` (the exporter's keyword
#: arguments), ``verify_onnx(trained, runtime, *inputs, **options) -> dict``, ``extra_methods(trained) -> dict``,
#: ``param_shapes(config) -> dict`` (the checkpoint schema's shapes; else the model module's), ``published_names(
#: config) -> dict`` (``refimpl import --layout published``), ``PUBLISHED_SETTINGS`` (the ``--set`` values of the
#: published layout), ``IMPORT_HINT`` (a hint of ``refimpl import``'s size errors).
OPTIONAL_MEMBERS: dict[str, Any] = {"EXPORTER": None, "export_inputs": None, "verify_onnx": None,
                                    "extra_methods": None, "param_shapes": None, "published_names": None,
                                    "PUBLISHED_SETTINGS": (), "IMPORT_HINT": ""}
_CALLABLE_OPTIONAL = ("export_inputs", "verify_onnx", "extra_methods", "param_shapes", "published_names")

#: The names a recipe module must define.
RECIPE_MEMBERS = tuple(sorted({*Recipe.__annotations__,
                               *(n for n, v in vars(Recipe).items() if callable(v) and not n.startswith("_"))}))


def check_recipe(module: ModuleType, task: str | None = None) -> ModuleType:
    """``module`` when it defines every member of :class:`Recipe` (functions callable), its optional functions are
    callable, and (given ``task``) its ``TASK`` is ``task``.

    Raises
    ------
    TypeError
        Naming the members it lacks or that are not callable.
    ValueError
        A recipe for another task than the one it is registered with.
    """
    functions = {n for n, v in vars(Recipe).items() if callable(v) and not n.startswith("_")}
    bad = [n for n in RECIPE_MEMBERS if not hasattr(module, n) or (n in functions and not callable(getattr(module, n)))]
    bad += [n for n in _CALLABLE_OPTIONAL if getattr(module, n, None) is not None and not callable(getattr(module, n))]
    if bad:
        raise TypeError(f"recipe module {module.__name__}: missing or not callable {bad} (refimpl.recipe_api.Recipe)")
    if task is not None and module.TASK != task:
        raise ValueError(f"registry: recipe {module.__name__} is for task {module.TASK!r}, registered as {task!r}")
    return module


def optional_members(module: ModuleType) -> dict[str, Any]:
    """``name -> value`` of every optional member (:data:`OPTIONAL_MEMBERS`), its default where the recipe has
    none."""
    return {n: getattr(module, n, default) for n, default in OPTIONAL_MEMBERS.items()}
