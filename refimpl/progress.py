"""Progress of the long-running steps (spec/cli.md: a line on stderr at most every ~5 s of a step over ~10 s).

* :func:`stderr_line` — print one progress line to stderr at once (the default ``progress`` of every command);
* :class:`Throttle` — ``due()`` at most every ``every_s`` seconds, ``elapsed`` since the start: the one rule
  behind the data reads, evaluations, training and GIF frames that report while they work.
"""
from __future__ import annotations

import sys
import time

__all__ = ["PROGRESS_EVERY_S", "stderr_line", "Throttle"]

#: Seconds between two progress lines of one step.
PROGRESS_EVERY_S = 5.0


def stderr_line(line: str) -> None:
    """Print ``line`` to stderr and flush (progress goes to stderr, results to stdout)."""
    print(line, file=sys.stderr, flush=True)


class Throttle:
    """When a long loop should report: ``due()`` is true once ``every_s`` seconds have passed since the start or
    since the last true answer; ``elapsed`` is the time from the start to that answer.

    Parameters
    ----------
    every_s : float
        Seconds between reports (a negative value: every call is due).

    Examples
    --------
    >>> tick = Throttle()
    >>> for i, f in enumerate(files, 1):          # doctest: +SKIP
    ...     read(f)
    ...     if tick.due():
    ...         progress(f"read {i} of {len(files)}, {tick.elapsed:.0f} s")
    """

    def __init__(self, every_s: float = PROGRESS_EVERY_S):
        self.every_s = float(every_s)
        self.t0 = self.last = time.perf_counter()

    def due(self) -> bool:
        """True (and the clock restarted) when ``every_s`` seconds have passed since the last report."""
        now = time.perf_counter()
        if now - self.last > self.every_s:
            self.last = now
            return True
        return False

    @property
    def elapsed(self) -> float:
        """Seconds from the start to the last report."""
        return self.last - self.t0
