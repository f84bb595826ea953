"""The networks the application knows: model name -> recipe and task (spec/architecture.md §adding a model).

Adding a model is one line in :data:`RECIPES` (its recipe module and its task); the recipe module
(``refimpl/recipes/<name>.py``) provides the names :meth:`ModelSpec.from_recipe` reads. Recipes and tasks are
imported when this module is.
"""
from __future__ import annotations

import dataclasses
import importlib
from types import ModuleType
from typing import Any, Callable

import numpy as np

__all__ = ["RECIPES", "TASKS", "ModelSpec", "TrainedModel", "MODELS", "task_of"]

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
    exporter : str or None
        Key of its exporter in ``deploy.models.EXPORTERS``; None when it has none.
    export_inputs : callable ``TrainedModel -> dict`` or None
        The exporter's keyword arguments for a trained model (normalisation, metadata, T).
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
    exporter: str | None = None
    export_inputs: Callable | None = None
    recipe: ModuleType | None = None

    @classmethod
    def from_recipe(cls, recipe: ModuleType, task: str) -> "ModelSpec":
        """The spec of ``recipe`` (``NAME``, ``SUMMARY``, ``TASK``, ``REPRESENTATIONS``, ``CONFIG_TYPE``,
        ``PAPER_OPTIM``, ``EXPORTER``, ``make_config``, ``make_adapter``, ``make_method``, ``export_inputs``)."""
        if recipe.TASK != task:
            raise ValueError(f"registry: recipe {recipe.__name__} is for task {recipe.TASK!r}, registered as {task!r}")
        return cls(name=recipe.NAME, summary=recipe.SUMMARY, task=task, representations=tuple(recipe.REPRESENTATIONS),
                   config_type=recipe.CONFIG_TYPE, make_config=recipe.make_config, make_adapter=recipe.make_adapter,
                   make_method=recipe.make_method, optim=recipe.PAPER_OPTIM,
                   exporter=getattr(recipe, "EXPORTER", None), export_inputs=getattr(recipe, "export_inputs", None),
                   recipe=recipe)


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
    root_mean, root_std : ndarray (3,) or None
        Transition task: root-translation statistics of the training windows (the network's input
        normalisation). None for other tasks.
    fps : float or None
        Frame rate of the training data, when the task stores it.
    transition_length : int or None
        Transition task: T the network was trained for.

    The task module fills the optional fields (``trained_fields(model_config, config)``).
    """

    spec: ModelSpec
    config: Any
    params: dict
    meta: dict = dataclasses.field(default_factory=dict)
    path: str = ""
    extra: dict = dataclasses.field(default_factory=dict)
    root_mean: np.ndarray | None = None
    root_std: np.ndarray | None = None
    fps: float | None = None
    transition_length: int | None = None

    @property
    def pose_normalization(self) -> tuple[np.ndarray, np.ndarray]:
        """Transition task: ``(mean (P,), std (P,))`` over the whole pose vector: root statistics, then 0 / 1 for
        quaternions."""
        from refimpl.protocols.transition import pose_statistics

        if self.root_mean is None:
            raise ValueError(f"model {self.spec.name!r} has no pose normalisation (not a transition model)")
        return pose_statistics(self.root_mean, self.root_std, self.config.pose_size)


def task_of(spec_or_name) -> ModuleType:
    """The task module of a :class:`ModelSpec` or of a task name."""
    name = spec_or_name.task if isinstance(spec_or_name, ModelSpec) else spec_or_name
    return importlib.import_module(TASKS[name])


#: Networks the application knows, by ``--model`` name.
MODELS: dict[str, ModelSpec] = {name: ModelSpec.from_recipe(importlib.import_module(recipe), task)
                                for name, (recipe, task) in RECIPES.items()}
