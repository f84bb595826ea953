"""Recipes: one module per network, the glue between a model module, a task and the trainer
(spec/architecture.md §recipes): its ``ModelAdapter``, its config from a dataset and ``--set`` overrides, its
NumPy inference method and the name of its exporter in ``deploy``'s table.

Recipes: ``qtg``, ``quaternet`` (short-term, quaternions or dual quaternions), ``quaternet_cnn``,
``quaternet_long`` (the long-term pose network and its ablations) with ``quaternet_long_dq`` (its dual-quaternion
output), ``pace`` and ``acrnn``. Import the recipe module itself; this package re-exports nothing.
"""
