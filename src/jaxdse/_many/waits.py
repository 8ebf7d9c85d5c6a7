"""Work run side by side on threads, and every wait on it bounded (``../shared/STYLE.md`` 22).

:func:`bounded` runs tasks (compiled calls that block their thread until the result is ready) on
daemon threads, at most ``workers`` at once, and yields each result as it comes. Each task has
its own limit [s], counted from its start; a task still running at its limit is yielded as
:class:`Expired` (its thread is left behind: a thread blocked in XLA cannot be stopped, and a
daemon thread does not hold up the interpreter's exit) and the next task starts in its place.
So no caller waits for ever, whatever happens inside XLA.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any, NamedTuple


class Task(NamedTuple):
    """One piece of work: what it is (for the message on expiry), its limit [s], the call."""

    label: str
    limit_s: float
    call: Callable[[], Any]


class Expired(NamedTuple):
    """A task that did not finish within its limit."""

    label: str
    limit_s: float

    @property
    def reason(self) -> str:
        return f"timed out after {self.limit_s:.4g} s waiting for {self.label}"


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
        self._next = 0

    def submit(self, task: Task) -> int:
        self._tasks.append(task)
        self._fill()
        return len(self._tasks) - 1

    def _fill(self) -> None:
        while len(self._running) < self.workers and self._next < len(self._tasks):
            k, self._next = self._next, self._next + 1
            self._running[k] = time.monotonic()
            threading.Thread(target=self._body, args=(k,), name=f"jaxdse: {self._tasks[k].label}",
                             daemon=True).start()

    def _body(self, k: int) -> None:
        try:
            self._done.put((k, True, self._tasks[k].call()))
        except BaseException as err:  # noqa: BLE001 - handed to the caller
            self._done.put((k, False, err))

    def results(self, block: bool = True) -> Iterator[tuple[int, Any]]:
        while self._running:
            if block:
                deadline = min(t0 + self._tasks[k].limit_s for k, t0 in self._running.items())
                wait = max(deadline - time.monotonic(), 0.0)
            try:
                k, ok, value = self._done.get(timeout=wait) if block else self._done.get_nowait()
            except queue.Empty:
                now = time.monotonic()
                expired = [k for k, t0 in self._running.items() if t0 + self._tasks[k].limit_s <= now]
                for k in expired:
                    del self._running[k]
                    yield k, Expired(self._tasks[k].label, self._tasks[k].limit_s)
                self._fill()
                if not block and not expired:
                    return
                continue
            if k in self._running:   # else: the late result of an expired task, dropped
                del self._running[k]
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


__all__ = ["Expired", "Pool", "Task", "bounded"]
