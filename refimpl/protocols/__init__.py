"""Protocols: per paper, its data, windows, metrics and baselines, below the application (spec/architecture.md).

One module (or a few, to stay under ~600 lines) per paper's task: ``transition`` (QTG), ``prediction``
(QuaterNet short-term), ``locomotion`` (QuaterNet long-term), ``synthesis`` (acRNN). They know no network and
no command line; the task modules of :mod:`refimpl.tasks` build on them. Import the module itself
(``from refimpl.protocols import transition``); this package re-exports nothing.
"""
