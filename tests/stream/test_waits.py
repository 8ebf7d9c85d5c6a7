"""jaxdse._stream.waits: every wait ends within its limit, and says what it waited for."""

import queue
import threading
import time

import pytest

from jaxdse._stream.waits import Backoff, call, join, put


def test_put_on_a_full_queue_ends_and_names_the_consumer():
    q = queue.Queue(maxsize=1)
    put(q, 1, 0.05, "the main thread")
    t0 = time.monotonic()
    with pytest.raises(TimeoutError, match="the main thread took nothing from its queue of 1 for 0.05 s"):
        put(q, 2, 0.05, "the main thread")
    assert time.monotonic() - t0 < 1.0


def test_join_and_call_leave_a_stuck_thread_behind_with_a_word():
    release = threading.Event()
    lines = []
    th = threading.Thread(target=release.wait, args=(10.0,), daemon=True, name="stuck")
    th.start()
    t0 = time.monotonic()
    assert not join(th, 0.05, "reading stream 0", lines.append)
    assert not call(lambda: release.wait(10.0), 0.05, "stopping the web server", lines.append, name="stopper")
    assert time.monotonic() - t0 < 1.0
    assert lines == ["stuck (reading stream 0) did not end within 0.05 s: left behind",
                     "stopper (stopping the web server) did not end within 0.05 s: left behind"]
    release.set()
    assert join(th, 5.0, "reading stream 0", lines.append) and len(lines) == 2


def test_backoff_doubles_to_its_limit_and_resets():
    stop = threading.Event()
    stop.set()                                  # no real waiting
    b = Backoff(0.5, 10.0)
    assert [b.wait(stop) for _ in range(7)] == [0.5, 1.0, 2.0, 4.0, 8.0, 10.0, 10.0]
    b.reset()
    assert b.s == 0.5
