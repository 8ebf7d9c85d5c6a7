"""What the stream layer's threads share: the back-off between connection attempts, and waits
that end.

Every wait on a stream, a socket, a queue or a thread has a limit derived from the work (a
stream's ``timeout_s``, a poll period), and when it expires the caller is told what was waited
for: :func:`put` raises a ``TimeoutError`` that names the queue's consumer, :func:`join` logs the
thread it left behind. The C37.118 reader (``monitor``) and the STTP reader (``sttp``) both
stand above this module; neither imports the other's.
"""

from __future__ import annotations

import queue
import threading
import time

FIRST_BACKOFF_S = 0.5
MAX_BACKOFF_S = 10.0
READY_S = 600.0
"""A reader waits at most this long [s] for the main thread to take a stream's configuration
(and compile the estimators) before it turns data on."""


def wait_ready(ready, stop: threading.Event, log, k: int):
    """A reader's wait, before it turns its stream's data on, until ``ready.wait`` says the main
    thread has taken the configuration and compiled the estimators (None: no wait), the monitor
    stops, or ``READY_S`` passes (said in the log)."""
    deadline = time.monotonic() + READY_S
    while ready is not None and not ready.wait(0.2) and not stop.is_set():
        if time.monotonic() > deadline:
            log(f"stream {k}: the estimators were not ready {READY_S:g} s after the configuration came; "
                "data turned on anyway")
            return


class Backoff:
    """The wait before the next connection attempt [s]: 0.5 s, doubling to 10 s; back to 0.5 s
    once a connection is up."""

    def __init__(self, first_s: float = FIRST_BACKOFF_S, max_s: float = MAX_BACKOFF_S):
        self.first_s, self.max_s = first_s, max_s
        self.s = first_s

    def reset(self):
        self.s = self.first_s

    def wait(self, stop: threading.Event) -> float:
        """Wait the current back-off (or until ``stop``), double it; returns the time waited for."""
        s = self.s
        stop.wait(s)
        self.s = min(2.0 * s, self.max_s)
        return s


def put(out: queue.Queue, item, timeout_s: float, consumer: str):
    """``out.put(item)``, waiting at most ``timeout_s`` for room; TimeoutError naming
    ``consumer`` (who should have emptied the queue) when none came."""
    try:
        out.put(item, timeout=timeout_s)
    except queue.Full:
        raise TimeoutError(f"{consumer} took nothing from its queue of {out.maxsize} for "
                           f"{timeout_s:g} s") from None


def join(thread: threading.Thread, timeout_s: float, what: str, log) -> bool:
    """Join ``thread`` for at most ``timeout_s``; when it is still alive, log that it was left
    behind, naming ``what`` it was doing. True when it ended."""
    thread.join(timeout=timeout_s)
    if thread.is_alive():
        log(f"{thread.name} ({what}) did not end within {timeout_s:g} s: left behind")
        return False
    return True


def call(fn, timeout_s: float, what: str, log, name: str = "jaxdse-wait") -> bool:
    """``fn()`` in a thread, waited for at most ``timeout_s`` (for a library call that has no
    limit of its own, e.g. ``ThreadingHTTPServer.shutdown``); logs what was left behind."""
    thread = threading.Thread(target=fn, daemon=True, name=name)
    thread.start()
    return join(thread, timeout_s, what, log)


__all__ = ["Backoff", "FIRST_BACKOFF_S", "MAX_BACKOFF_S", "call", "join", "put"]
