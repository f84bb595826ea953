"""Tasks: one module per task (its data options, dataset building, protocol and metrics, baselines and
generation), used by the registry, the services and the command line (spec/architecture.md §tasks).

``transition`` (QTG's: 2 past + 2 target poses -> T frames) today; ``prediction``, ``locomotion`` and
``synthesis`` next. Import the task module itself (``from refimpl.tasks import transition``); this package
re-exports nothing.
"""
