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
        return f"timed out after {self.limit_s:.0f} s waiting for {self.label}"


def bounded(tasks: Sequence[Task], workers: int = 1, *, threads: bool = True) -> Iterator[tuple[int, Any]]:
    """(index, result or :class:`Expired`) of every task, in the order they finish; a task's
    exception is raised here. ``workers`` tasks run at once, each on its own daemon thread.
    ``threads=False``: in the calling thread, one after the other, without a limit (for a
    caller under a thread-local JAX context, ``with jax.default_device(...)``, which a new
    thread would not see)."""
    if not threads:
        for k, task in enumerate(tasks):
            yield k, task.call()
        return
    done: queue.Queue = queue.Queue()
    running: dict[int, float] = {}
    waiting = iter(range(len(tasks)))

    def start(k: int) -> None:
        def body():
            try:
                done.put((k, True, tasks[k].call()))
            except BaseException as err:  # noqa: BLE001 - handed to the caller
                done.put((k, False, err))

        running[k] = time.monotonic()
        threading.Thread(target=body, name=f"jaxdse: {tasks[k].label}", daemon=True).start()

    def fill() -> None:
        while len(running) < max(workers, 1):
            k = next(waiting, None)
            if k is None:
                return
            start(k)

    fill()
    while running:
        deadline = min(t0 + tasks[k].limit_s for k, t0 in running.items())
        try:
            k, ok, value = done.get(timeout=max(deadline - time.monotonic(), 0.0))
        except queue.Empty:
            now = time.monotonic()
            for k in [k for k, t0 in running.items() if t0 + tasks[k].limit_s <= now]:
                del running[k]
                yield k, Expired(tasks[k].label, tasks[k].limit_s)
        else:
            if k in running:   # else: the late result of an expired task, dropped
                del running[k]
                if not ok:
                    raise value
                yield k, value
        fill()


__all__ = ["Expired", "Task", "bounded"]
