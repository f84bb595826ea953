"""Tasks: one module per task, the application layer of a paper's protocol (spec/architecture.md §tasks).

Each task module implements the task interface :class:`refimpl.task_api.Task` (its options of every command,
datasets of ``--data``, checkpoint facts, methods and baselines, ``eval_command``, ``generate_command``,
``export_options``, ``verify_inputs``) on top of its paper's protocol in :mod:`refimpl.protocols`:
``transition`` (QTG), ``prediction`` (QuaterNet short-term), ``synthesis`` (acRNN), ``locomotion`` (QuaterNet
long-term); ``transition_generate`` and ``locomotion_generate`` hold their generation (locomotion's options, files and
metrics; the walk of its two networks is :mod:`refimpl.models.quaternet_long_walk`). Import the task module
itself (``from refimpl.tasks import transition``); this package re-exports nothing.
"""
