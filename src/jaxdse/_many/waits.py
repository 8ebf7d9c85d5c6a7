"""Work run side by side on threads, and every wait on it bounded (``../shared/STYLE.md`` 22).

:func:`bounded` runs tasks (compiled calls that block their thread until the result is ready) on
daemon threads, at most ``workers`` at once, and yields each result as it comes. Each task has
its own limit [s], counted from its start; a task still running at its limit is yielded as
:class:`Expired` (its thread is left behind: a thread blocked in XLA cannot be stopped, and a
daemon thread does not hold up the interpreter's exit) and the next task starts in its place.
So no caller waits for ever, whatever happens inside XLA.

A task that compiles its program first gets ``compile_limit_s`` for that (a compile always ends,
but takes minutes on a loaded machine); it calls :func:`executing` when its program starts to
run, and from then on its own ``limit_s``, derived from its work, applies.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any, NamedTuple


COMPILE_LIMIT_S = 1800.0
"""The wait on one program's compile [s]: a compile always ends, but Kvaerno5's took 41 s of CPU
and 143 s of wall time on 2 cores loaded 7-fold (a unit of GENROU ESST3A TGOV1), Tsit5's 6 s
and 22 s."""


class Task(NamedTuple):
    """One piece of work: what it is (for the message on expiry), its limit [s], the call."""

    label: str
    limit_s: float
    call: Callable[[], Any]
    compile_limit_s: float | None = None
    """With a limit here, ``limit_s`` counts from the task's call to :func:`executing`; until
    then, this one (from its start)."""


_HERE = threading.local()


def executing() -> None:
    """Called by a task of a :class:`Pool` when its compiled program starts to run: its
    ``limit_s`` counts from now (nothing outside a pool's thread)."""
    mark = getattr(_HERE, "mark", None)
    if mark is not None:
        mark()


class Expired(NamedTuple):
    """A task that did not finish within its limit."""

    label: str
    limit_s: float
    compiling: bool = False

    @property
    def reason(self) -> str:
        what = " to compile" if self.compiling else ""
        return f"timed out after {self.limit_s:.4g} s waiting for {self.label}{what}"


class Pool:
    """Tasks on daemon threads, ``workers`` at once, every wait on them bounded by the task's
    limit (counted from its start). :meth:`submit` queues a task; :meth:`results` yields
    (ticket, result or :class:`Expired`) as tasks finish: those finished so far (``block=False``)
    or all of them; a task's exception is raised there."""

    def __init__(self, workers: int = 1):
        self.workers = max(workers, 1)
        self._done: queue.Queue = queue.Queue()
        self._tasks: list[Task] = []
        self._running: dict[int, float] = {}
        """ticket -> when its current limit runs out (time.monotonic)"""
        self._compiling: set[int] = set()
        self._lock = threading.Lock()
        self._next = 0

    def submit(self, task: Task) -> int:
        self._tasks.append(task)
        self._fill()
        return len(self._tasks) - 1

    def _fill(self) -> None:
        while len(self._running) < self.workers and self._next < len(self._tasks):
            k, self._next = self._next, self._next + 1
            task = self._tasks[k]
            with self._lock:
                if task.compile_limit_s is None:
                    self._running[k] = time.monotonic() + task.limit_s
                else:
                    self._running[k] = time.monotonic() + task.compile_limit_s
                    self._compiling.add(k)
            threading.Thread(target=self._body, args=(k,), name=f"jaxdse: {self._tasks[k].label}",
                             daemon=True).start()

    def _mark(self, k: int) -> None:
        with self._lock:
            if k in self._running and k in self._compiling:
                self._compiling.discard(k)
                self._running[k] = time.monotonic() + self._tasks[k].limit_s
        self._done.put(None)   # the waiting thread takes the new deadline

    def _body(self, k: int) -> None:
        _HERE.mark = lambda: self._mark(k)
        try:
            self._done.put((k, True, self._tasks[k].call()))
        except BaseException as err:  # noqa: BLE001 - handed to the caller
            self._done.put((k, False, err))

    def results(self, block: bool = True) -> Iterator[tuple[int, Any]]:
        while self._running:
            if block:
                with self._lock:
                    wait = max(min(self._running.values()) - time.monotonic(), 0.0)
            try:
                item = self._done.get(timeout=wait) if block else self._done.get_nowait()
            except queue.Empty:
                item = None
            if item is None:
                now = time.monotonic()
                with self._lock:
                    expired = [k for k, end in self._running.items() if end <= now]
                    for k in expired:
                        del self._running[k]
                for k in expired:
                    task, compiling = self._tasks[k], k in self._compiling
                    yield k, Expired(task.label, task.compile_limit_s if compiling else task.limit_s,
                                     compiling)
                self._fill()
                if not block and not expired and self._done.empty():
                    return
                continue
            k, ok, value = item
            with self._lock:
                late = self._running.pop(k, None) is None   # the result of an expired task: dropped
            if not late:
                self._fill()
                if not ok:
                    raise value
                yield k, value


def bounded(tasks: Sequence[Task], workers: int = 1, *, threads: bool = True) -> Iterator[tuple[int, Any]]:
    """(index, result or :class:`Expired`) of every task, in the order they finish (a
    :class:`Pool` of ``workers``); a task's exception is raised here. ``threads=False``: in the
    calling thread, one after the other, without a limit (for a caller under a thread-local JAX
    context, ``with jax.default_device(...)``, which a new thread would not see)."""
    if not threads:
        for k, task in enumerate(tasks):
            yield k, task.call()
        return
    pool = Pool(workers)
    for task in tasks:
        pool.submit(task)
    yield from pool.results()


__all__ = ["COMPILE_LIMIT_S", "Expired", "Pool", "Task", "bounded", "executing"]
