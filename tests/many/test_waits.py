"""Every wait bounded (``_many/waits.py``), and many small programs side by side on a loaded
machine (``jaxdse check``'s pattern: one vmapped, jitted program per group, compiled and run on
two threads, Jacobians out and eigenvalues on the host).

The stress test runs 16 small programs of the check's shape (a Tsit5-like scan and the Jacobian
of the vector field) on two worker threads while a busy loop runs on every core, under a
``faulthandler`` watchdog: a deadlock ends the process with every thread's traceback instead of
hanging the suite.
"""

import faulthandler
import os
import subprocess
import sys
import threading
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxdse._dyr.stiff import modes
from jaxdse._many.waits import Expired, Pool, Task, bounded, executing

WATCHDOG_S = 240


def test_a_task_past_its_limit_is_named_and_the_others_go_on():
    release = threading.Event()

    def compiled_then_stuck():
        time.sleep(0.05)
        executing()
        release.wait(30)   # a compiled run that does not return
        return "late"

    tasks = [Task("group A", 5.0, lambda: "a"), Task("group B (3 units)", 0.2, compiled_then_stuck, 5.0),
             Task("group C", 5.0, lambda: time.sleep(0.3) or "c"),
             Task("group D", 5.0, lambda: release.wait(30), 0.2)]   # stuck in its compile
    t0 = time.monotonic()
    got = dict(bounded(tasks, workers=2))
    release.set()
    assert time.monotonic() - t0 < 3
    assert got[0] == "a" and got[2] == "c"
    assert isinstance(got[1], Expired) and not got[1].compiling
    assert got[1].reason == "timed out after 0.2 s waiting for group B (3 units)"
    assert isinstance(got[3], Expired) and got[3].reason.endswith("group D to compile")


def test_a_task_error_reaches_the_caller_and_a_pool_polls():
    pool = Pool(2)
    pool.submit(Task("slow", 5.0, lambda: time.sleep(0.2) or 1))
    assert list(pool.results(block=False)) == []
    assert list(pool.results()) == [(0, 1)]
    try:
        list(bounded([Task("bad", 5.0, lambda: 1 / 0)]))
    except ZeroDivisionError:
        pass
    else:
        raise AssertionError("the task's error was swallowed")


def _program(n: int):
    """A check-like program for an n-state linear unit: a fixed-step scan, the Jacobian at the
    end; vmapped over 4 units."""
    a = -np.diag(np.arange(1.0, n + 1.0)) + 0.1 * np.triu(np.ones((n, n)), 1)

    def one(y0, k):
        f = lambda y: k * (jnp.asarray(a) @ y)   # noqa: E731

        def step(y, _):
            y = y + 0.01 * f(y)
            return y, y[0]

        y, ys = jax.lax.scan(step, y0, None, length=100)
        return ys, jax.jacfwd(f)(y)

    return jax.jit(jax.vmap(one)), a


def test_many_small_programs_on_two_threads_under_load():
    faulthandler.dump_traceback_later(WATCHDOG_S, exit=True)
    load = [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(os.cpu_count() or 2)]
    try:
        def group(n):
            fn, a = _program(n)
            args = (np.ones((4, n)), np.linspace(1.0, 2.0, 4))
            compiled = fn.lower(*args).compile()
            executing()
            ys, jac = jax.device_get(compiled(*args))
            return n, ys, [modes(j) for j in jac], a

        sizes = list(range(2, 18))
        tasks = [Task(f"program of {n} states", 60.0, lambda n=n: group(n), 120.0) for n in sizes]
        seen = []
        for _, value in bounded(tasks, workers=2):
            assert not isinstance(value, Expired), value.reason
            n, ys, found, a = value
            assert ys.shape == (4, 100) and np.all(np.isfinite(ys))
            for k, (largest, smallest) in zip(np.linspace(1.0, 2.0, 4), found):
                np.testing.assert_allclose([largest, smallest], [-k, -k * n], rtol=1e-9)
            seen.append(n)
        assert sorted(seen) == sizes
    finally:
        faulthandler.cancel_dump_traceback_later()
        for p in load:
            p.kill()
            p.wait()
