"""The networks the application knows: model name -> recipe and task (spec/architecture.md §adding a model).

Adding a model is one line in :data:`RECIPES` (its recipe module and its task); the recipe module
(``refimpl/recipes/<name>.py``) implements the recipe interface (:class:`refimpl.recipe_api.Recipe`), checked and
read once by :meth:`ModelSpec.from_recipe`. Recipes are imported when this module is; a task module (:data:`TASKS`) when :func:`task_of` first hands it out, checked against the task
interface (:class:`refimpl.task_api.Task`).
"""
from __future__ import annotations

import dataclasses
import importlib
from types import ModuleType
from typing import Any, Callable

from refimpl.recipe_api import check_recipe, optional_members
from refimpl.task_api import check_task

__all__ = ["RECIPES", "TASKS", "DEFAULT_MODEL", "ModelSpec", "TrainedModel", "MODELS", "task_of", "generate_usage",
           "require_source"]

#: Model name -> (recipe module, task). One line per model.
RECIPES = {
    "qtg": ("refimpl.recipes.qtg", "transition"),
    "quaternet": ("refimpl.recipes.quaternet", "prediction"),
    "quaternet-cnn": ("refimpl.recipes.quaternet_cnn", "prediction"),
    "acrnn": ("refimpl.recipes.acrnn", "synthesis"),
    "quaternet-long": ("refimpl.recipes.quaternet_long", "locomotion"),
    "pace": ("refimpl.recipes.pace", "locomotion"),
}

#: Task name -> task module (``refimpl/tasks/<name>.py``).
TASKS = {
    "transition": "refimpl.tasks.transition",
    "prediction": "refimpl.tasks.prediction",
    "synthesis": "refimpl.tasks.synthesis",
    "locomotion": "refimpl.tasks.locomotion",
}

#: The model of ``refimpl train`` / ``eval`` / ``generate`` when neither ``--model`` nor a checkpoint names one.
DEFAULT_MODEL = "qtg"


@dataclasses.dataclass(frozen=True)
class ModelSpec:
    """How the application trains, runs and exports one network (an entry of :data:`MODELS`), read from its
    recipe module.

    Attributes
    ----------
    name : str
        ``--model`` value, stored in checkpoints (the recipe's ``NAME``).
    summary : str
    task : str
        Key of :data:`TASKS` (the recipe's ``TASK``; the data, protocol, baselines and generation it uses).
    representations : tuple of str
        Pose representations it trains on (``--representation``); the first is the default.
    config_type : type
        Frozen dataclass of the network's sizes (``--set field=value`` overrides a field).
    make_config : callable ``(train_ds, overrides) -> config``
    make_adapter : callable ``(train_ds, val_ds, config, dtype, extra) -> ModelAdapter``
        ``extra`` (dict) goes into the checkpoint's model config (the task's statistics, the representation).
    make_method : callable ``TrainedModel -> f(...)``
        NumPy inference in the task's interface (transition: ``f(past, target, T) -> poses``, un-normalised).
    optim : OptimConfig
        The paper's optimiser settings (``refimpl train``'s defaults for this model).
    batch_size : int
        The paper's batch size (``refimpl train``'s default; the recipe's ``PAPER_BATCH``).
    exporter : str or None
        Key of its exporter in ``deploy.models.EXPORTERS``; None when it has none.
    export_inputs : callable ``TrainedModel -> dict`` or None
        The exporter's keyword arguments for a trained model (normalisation, metadata, T).
    verify_onnx : callable ``(TrainedModel, runtime, *inputs, **options) -> dict`` or None
        onnxruntime against the NumPy model (``refimpl export``'s check).
    extra_methods : callable ``TrainedModel -> dict`` or None
        More methods of the network for its task's evaluation (a DQ model's positions read from the DQs).
    param_shapes : callable ``config -> dict`` or None
        Name -> shape of the parameters (the checkpoint schema's; None: the model module's).
    published_names : callable ``config -> dict`` or None
        The published code's parameter names (``refimpl import --layout published``); None without published code.
    published_settings : tuple of str
        ``--set`` values of the published layout (acRNN's skewed stack).
    import_hint : str
        A hint for ``refimpl import``'s size errors.
    recipe : module
    """

    name: str
    summary: str
    task: str
    representations: tuple
    config_type: type
    make_config: Callable
    make_adapter: Callable
    make_method: Callable
    optim: Any = None
    batch_size: int = 32
    exporter: str | None = None
    export_inputs: Callable | None = None
    verify_onnx: Callable | None = None
    extra_methods: Callable | None = None
    param_shapes: Callable | None = None
    published_names: Callable | None = None
    published_settings: tuple = ()
    import_hint: str = ""
    recipe: ModuleType | None = None

    @classmethod
    def from_recipe(cls, recipe: ModuleType, task: str) -> "ModelSpec":
        """The spec of ``recipe`` (checked: :func:`refimpl.recipe_api.check_recipe`): the members of
        :class:`refimpl.recipe_api.Recipe` and its optional members (:data:`refimpl.recipe_api.OPTIONAL_MEMBERS`)."""
        check_recipe(recipe, task)
        opt = optional_members(recipe)
        optional = {"exporter": opt["EXPORTER"], "published_settings": tuple(opt["PUBLISHED_SETTINGS"]),
                    "import_hint": str(opt["IMPORT_HINT"])}
        optional.update({n: opt[n] for n in ("export_inputs", "verify_onnx", "extra_methods", "param_shapes",
                                             "published_names")})
        return cls(name=recipe.NAME, summary=recipe.SUMMARY, task=task, representations=tuple(recipe.REPRESENTATIONS),
                   config_type=recipe.CONFIG_TYPE, make_config=recipe.make_config, make_adapter=recipe.make_adapter,
                   make_method=recipe.make_method, optim=recipe.PAPER_OPTIM, batch_size=int(recipe.PAPER_BATCH),
                   recipe=recipe, **optional)


@dataclasses.dataclass(frozen=True)
class TrainedModel:
    """A trained network read from a ``refimpl train`` checkpoint, ready for inference.

    Attributes
    ----------
    spec : ModelSpec
    config : the model's config dataclass
    params : dict name -> ndarray
    meta : dict
        The checkpoint's metadata.
    path : str
    extra : dict
        The checkpoint's whole model config (the network's fields and what its task stored beside them:
        statistics, representation, frame rate), for tasks and recipes that need more than the fields below.
    fps : float or None
        Frame rate of the training data, when the task stores it.
    fields : dict
        The task's own fields (transition: ``root_mean``, ``root_std`` (3,) and ``transition_length``).

    The task module fills ``fps`` and ``fields`` (``trained_fields(model_config, config)``).
    """

    spec: ModelSpec
    config: Any
    params: dict
    meta: dict = dataclasses.field(default_factory=dict)
    path: str = ""
    extra: dict = dataclasses.field(default_factory=dict)
    fps: float | None = None
    fields: dict = dataclasses.field(default_factory=dict)


def task_of(spec_or_name) -> ModuleType:
    """The task module of a :class:`ModelSpec` or of a task name, checked against the task interface
    (:func:`refimpl.task_api.check_task`)."""
    name = spec_or_name.task if isinstance(spec_or_name, ModelSpec) else spec_or_name
    return check_task(importlib.import_module(TASKS[name]))


def generate_usage() -> str:
    """The usage lines of ``refimpl generate``, one per task (``GENERATE_USAGE``)."""
    lines = [task_of(name).GENERATE_USAGE for name in TASKS]
    return "usage: " + "\n       ".join(lines)


def require_source(args) -> None:
    """``refimpl generate``'s ``--source`` check for the tasks that read one (UsageError with the usage lines)."""
    if args.source is None:
        from refimpl.errors import UsageError

        raise UsageError("the following argument is required: --source (the prefix, seed or source clip)\n"
                         + generate_usage())


#: Networks the application knows, by ``--model`` name.
MODELS: dict[str, ModelSpec] = {name: ModelSpec.from_recipe(importlib.import_module(recipe), task)
                                for name, (recipe, task) in RECIPES.items()}
