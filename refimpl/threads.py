"""``--blas-threads auto``: as many BLAS threads as the cores other jobs leave free (spec/cli.md §1).

Two BLAS threads are 1.35-1.72x faster than one on an idle 2-core machine, but 8-31x slower when other jobs share
the cores (``benchmarks/bench_thread_default.py``), so no fixed count suits both. :class:`AutoThreads` measures
what the *other* processes use over an interval of wall time,

    others = (Δ busy jiffies of the machine − Δ jiffies of this process) / (Δ wall seconds × jiffies per second)

(``/proc/stat``'s first line and ``/proc/self/stat``'s ``utime + stime``, all threads of this process; the
result is in cores), and keeps the BLAS pool at the cores they leave free, at least 1 and at most the machine's
cores, with hysteresis (:func:`choose_threads`). Without ``/proc`` (not Linux) it stays at 1 thread, the count
that cannot collapse. The application layer calls :meth:`AutoThreads.start` once before the work and
:meth:`AutoThreads.poll` as often as it likes (the training loop's per-step callback); a poll measures at most
every ``every`` seconds and touches the pool (threadpoolctl) only when the decision changes. Library code
(:mod:`refimpl.train`) knows nothing of this: it receives the poll as its ``callback``.

Shape legend: none (scalars only).
"""
from __future__ import annotations

import argparse
import contextlib
import os
import time
from typing import Callable, Iterator, Optional, Tuple

from refimpl.bounds import bounded_int

__all__ = ["AUTO", "RAISE_BELOW", "DROP_ABOVE", "POLL_SECONDS", "threads_option", "read_jiffies", "other_cores", "choose_threads",
           "AutoThreads", "blas_thread_pool"]

#: The ``--blas-threads`` value that selects :class:`AutoThreads` (the command line's default).
AUTO = "auto"
#: Hysteresis, in cores: a thread count above the current one is taken only when the other jobs leave its
#: cores free with this much to spare (others < cores − n + RAISE_BELOW) ...
RAISE_BELOW = 0.3
#: ... and the current count is kept until the others use more than this of its cores
#: (others > cores − n + DROP_ABOVE). On 2 cores: 2 threads when others < 0.3 core, back to 1 above 0.6.
DROP_ABOVE = 0.6

#: Least wall time in seconds between two measurements of :meth:`AutoThreads.poll`.
POLL_SECONDS = 2.0

_parse_count = bounded_int("threads")


def threads_option(text: str):
    """The argparse ``type`` of ``--blas-threads``: ``"auto"`` or an integer within ``BOUNDS["threads"]``.

    Raises
    ------
    argparse.ArgumentTypeError
        Anything else (exit 2 on the command line).
    """
    if text.strip().lower() == AUTO:
        return AUTO
    try:
        return _parse_count(text)
    except argparse.ArgumentTypeError as exc:
        raise argparse.ArgumentTypeError(f"expected 'auto' or {str(exc).removeprefix('expected ')}") from None


def read_jiffies(stat: str = "/proc/stat", self_stat: str = "/proc/self/stat") -> Optional[Tuple[int, int]]:
    """``(busy jiffies of the whole machine, jiffies of this process)`` since boot, or None without ``/proc``.

    Busy is user + nice + system + irq + softirq + steal of ``/proc/stat``'s ``cpu`` line (guest time is already
    inside user; idle and iowait are not busy). This process's jiffies are ``utime + stime`` of ``/proc/self/stat``
    (fields 14 and 15, all threads; the fields are counted after the command name, which may hold spaces).
    """
    try:
        with open(stat) as f:
            cpu = f.readline().split()
        with open(self_stat) as f:
            own = f.read().rpartition(")")[2].split()
        user, nice, system, _idle, _iowait, irq, softirq, steal = (int(v) for v in cpu[1:9])
        return user + nice + system + irq + softirq + steal, int(own[11]) + int(own[12])
    except (OSError, ValueError, IndexError):
        return None


def other_cores(before: Tuple[int, int], after: Tuple[int, int], seconds: float, hz: float) -> float:
    """Cores kept busy by other processes between two :func:`read_jiffies` readings ``seconds`` apart.

    ``(Δ machine busy − Δ own) / (seconds × hz)``, at least 0 (jiffy rounding can make it slightly negative).
    """
    if seconds <= 0:
        raise ValueError(f"seconds: expected a positive interval, got {seconds}")
    busy = (after[0] - before[0]) - (after[1] - before[1])
    return max(0.0, busy / (seconds * hz))


def choose_threads(others: float, current: int, cores: int) -> int:
    """The thread count for ``others`` busy cores of ``cores``, given the ``current`` count (hysteresis).

    The largest ``n`` in ``[1, cores]`` whose cores the others leave free with some to spare:
    ``others < cores − n + RAISE_BELOW`` for ``n`` above ``current``, ``others < cores − n + DROP_ABOVE`` for ``n``
    at or below it; 1 if none.
    """
    for n in range(max(1, cores), 1, -1):
        if others < cores - n + (RAISE_BELOW if n > current else DROP_ABOVE):
            return n
    return 1


def _environment_caps() -> list:
    caps = []
    for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        with contextlib.suppress(ValueError):
            caps.append(int(os.environ.get(name, "").split(",")[0]))
    return [c for c in caps if c >= 1]


class _BlasPool:
    """Sets NumPy's BLAS pool with threadpoolctl and restores the original count at the end (no-op without it)."""

    def __init__(self):
        try:
            from threadpoolctl import ThreadpoolController
            self._controller = ThreadpoolController()
        except ImportError:
            self._controller = None
        self._first = None

    def set(self, n: int) -> None:
        if self._controller is None:
            return
        limiter = self._controller.limit(limits=int(n), user_api="blas")
        self._first = self._first or limiter

    def restore(self) -> None:
        if self._first is not None:
            self._first.restore_original_limits()
            self._first = None


class AutoThreads:
    """Keeps the BLAS pool at the cores other processes leave free (module docstring).

    Parameters
    ----------
    apply : callable
        ``apply(n)`` sets the pool to ``n`` threads; called at :meth:`start` and whenever the decision changes.
    cores : int, optional
        Most threads to use (default ``os.cpu_count()``, capped by the smallest of ``OPENBLAS_NUM_THREADS``,
        ``OMP_NUM_THREADS``, ``MKL_NUM_THREADS`` that is set: an explicit setting in the environment is kept).
    read : callable, optional
        Returns ``(machine busy jiffies, own jiffies)`` or None (default :func:`read_jiffies`); None at the start
        means no ``/proc``: 1 thread for good.
    clock : callable
        Wall time in seconds (default ``time.monotonic``).
    hz : float, optional
        Jiffies per second (default ``os.sysconf("SC_CLK_TCK")``, else 100).
    every : float, optional
        Least wall time in seconds between two measurements of :meth:`poll` (default :data:`POLL_SECONDS`).

    Attributes
    ----------
    threads : int
        The current count (1 until :meth:`start`).
    others : float or None
        Cores the other processes used in the last measured interval (None before the first).
    applied : list of int
        The counts given to ``apply``, in order.
    """

    def __init__(self, apply: Callable[[int], None], *, cores: Optional[int] = None,
                 read: Optional[Callable[[], Optional[Tuple[int, int]]]] = None,
                 clock: Callable[[], float] = time.monotonic, hz: Optional[float] = None,
                 every: Optional[float] = None):
        self._apply, self.read, self.clock = apply, read or read_jiffies, clock
        self.every = float(POLL_SECONDS if every is None else every)
        self.cores = max(1, int(cores or min([os.cpu_count() or 1, *_environment_caps()])))
        if hz is None:
            try:
                hz = float(os.sysconf("SC_CLK_TCK"))
            except (AttributeError, ValueError, OSError):
                hz = 100.0
        self.hz = hz
        self.threads, self.others, self.applied = 1, None, []
        self._last = None  # (time, reading) of the last measurement

    def start(self, window: float = 0.1, sleep: Callable[[float], None] = time.sleep) -> int:
        """Measure over ``window`` seconds, set the pool and return its count (1 without ``/proc``)."""
        self._last = (self.clock(), self.read())
        if self._last[1] is None or self.cores == 1:
            self.apply(1)
            return 1
        sleep(window)
        self._measure(self.clock())
        self.apply(self.threads)
        return self.threads

    def poll(self, *_ignored) -> int:
        """Re-measure when ``every`` seconds have passed since the last measurement; returns the count.

        Accepts and ignores arguments, so it can be the training loop's per-step ``callback``.
        """
        if self._last is None or self._last[1] is None:
            return self.threads
        now = self.clock()
        if now - self._last[0] >= self.every:
            old = self.threads
            self._measure(now)
            if self.threads != old:
                self.apply(self.threads)
        return self.threads

    def apply(self, n: int) -> None:
        """Set the pool to ``n`` threads and record it in :attr:`applied`."""
        self._apply(n)
        self.applied.append(n)

    def _measure(self, now: float) -> None:
        then, before = self._last
        after = self.read()
        if after is None or now <= then:
            return
        self.others = other_cores(before, after, now - then, self.hz)
        self.threads = choose_threads(self.others, self.threads, self.cores)
        self._last = (now, after)


@contextlib.contextmanager
def blas_thread_pool(setting) -> Iterator[Optional[AutoThreads]]:
    """The BLAS pool for one command: ``"auto"`` (yields the started :class:`AutoThreads`), ``n`` threads, or the
    library default for 0/None (yields None); the original count is restored at the end."""
    if setting != AUTO and not setting:
        yield None
        return
    pool = _BlasPool()
    try:
        if setting == AUTO:
            auto = AutoThreads(pool.set)
            auto.start()
            yield auto
        else:
            pool.set(int(setting))
            yield None
    finally:
        pool.restore()
