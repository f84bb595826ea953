"""Recipes: one module per network, the glue between a model module, a task and the trainer
(spec/architecture.md §recipes): its ``ModelAdapter``, its config from a dataset and ``--set`` overrides, its
NumPy inference method and the name of its exporter in ``deploy``'s table.

``qtg`` today; ``quaternet``, ``pace``, ``acrnn`` next. Import the recipe module itself; this package re-exports
nothing.
"""
