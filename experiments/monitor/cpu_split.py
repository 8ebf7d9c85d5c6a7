"""CPU per stream-second of ``jaxdse monitor``, split by part (issue 45), without sockets.

    python experiments/monitor/cpu_split.py --tile 46 --seconds 20

OSL case 1 tiled ``--tile`` times (22 plants a copy; 1034_sjuan is refused by the readers, so
20 served stations a copy) as ``jaxdse pmu-sim`` packs it: the data frames' bytes are made
beforehand, then fed to the C37.118 decoder and the monitor's main-thread handler in this one
thread, at full speed, with ``[inertia]``. The first ``window_s`` + 5 s of stream fill the
windows (not counted); then each part's CPU time (``time.process_time``: every thread of the
process, XLA's included; the compiled calls are waited for inside their part) is summed over
``--seconds`` of stream time and divided by it:

* decode: ``StreamDecoder.feed`` of each frame's bytes (the reader thread's work);
* buffering: the reorder buffer, the screening, the recording's rows and the estimators' sample
  buffers (the main thread's handling of a frame less the parts below);
* front end: the chunk programs (front end, governor, filters, the block's sums);
* window estimate: the ring of blocks, the window's solve, its sandwich and verdicts;
* updates: the estimate's fields to the host and the :class:`~jaxdse._stream.online.Update`s;
* inertia: the area aggregation (``InertiaTracker.tick`` and its samples and updates);
* output: ``Monitor.emit`` less the inertia's updates (``updates.jsonl``, alarms, report).

Also per function: calls per stream second and CPU ms per call (``calls_per_stream_s``). The
recording's CSV rows are formatted by a writer process (not counted). Measured on a shared
2-core machine (load 3-5), 966 served stations (tile 46), stream seconds 35-55 (the 46 copies of
7031_coloeast, absent for the recording's first 16 s, restart and catch up in them): 0.855
CPU-s per stream second before the chunk programs shared the time axis and ran few units on a
small batch, 0.217 after; 10 s at 2,394 served (tile 114, no restart): 0.51.
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402
from jaxdse._app.sources import source_units  # noqa: E402
from jaxdse._stream import c37118 as c3  # noqa: E402
from jaxdse._stream import inertia as inertia_mod  # noqa: E402
from jaxdse._stream import monitor as mon_mod  # noqa: E402
from jaxdse._stream import online  # noqa: E402
from jaxdse._stream import pmu_sim  # noqa: E402

HERE = Path(__file__).resolve().parent
OSL = HERE.parents[1] / "experiments" / "naspi_osl_case1" / "fleet.toml"

SPENT: dict[str, float] = defaultdict(float)
CALLS: dict[str, list] = defaultdict(lambda: [0, 0.0])
_STACK: list[list[float]] = []


def timed(part: str, fn, block: bool = False):
    """``fn`` with its CPU time charged to ``part`` (and not to the part that called it)."""

    def wrapper(*args, **kwargs):
        _STACK.append([0.0])
        c0 = time.process_time()
        out = fn(*args, **kwargs)
        if block:
            out = jax.block_until_ready(out)
        spent = time.process_time() - c0
        inner = _STACK.pop()[0]
        SPENT[part] += spent - inner
        CALLS[fn.__name__][0] += 1
        CALLS[fn.__name__][1] += spent - inner
        if _STACK:
            _STACK[-1][0] += spent
        return out

    return wrapper


def instrument():
    online._first = timed("front end", online._first, block=True)
    online._next = timed("front end", online._next, block=True)
    online._where = timed("front end", online._where, block=True)
    online._absorb = timed("window estimate", online._absorb, block=True)
    online.OnlineGroup._updates = timed("updates", online.OnlineGroup._updates)
    T = inertia_mod.InertiaTracker
    T.tick, T.samples, T.update = (timed("inertia", T.tick), timed("inertia", T.samples),
                                   timed("inertia", T.update))
    mon_mod.Monitor.emit = timed("output", mon_mod.Monitor.emit)
    mon_mod.Monitor._inertia_lines = timed("output", mon_mod.Monitor._inertia_lines)
    mon_mod.Monitor._handle = timed("buffering", mon_mod.Monitor._handle)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tile", type=int, default=46)
    ap.add_argument("--seconds", type=float, default=20.0, help="stream seconds measured")
    ap.add_argument("--window", type=float, default=30.0)
    ap.add_argument("--json", help="write the result here too")
    args = ap.parse_args()

    units = source_units(OSL)
    source = pmu_sim.tile(pmu_sim.load_source(OSL, units), args.tile)
    server = pmu_sim.PmuServer(source)
    config = server.configs[0]
    fill = args.window + 5.0
    n_frames = round((fill + args.seconds) * source.rate)
    t0_index = (1_800_000_000 * source.rate)    # a whole second: chunks start on the grid
    frames = [server._frame_bytes(k % source.frames, t0_index + k, k / source.rate)[0] for k in range(n_frames)]

    work = Path(tempfile.mkdtemp(prefix="cpu_split_"))
    toml = work / "monitor.toml"
    toml.write_text(f'fleet = "{OSL}"\nupdate_s = 1.0\nwindow_s = {args.window}\ntile = {args.tile}\n'
                    '[inertia]\n[stream]\nport = 1\nfrequency = "angle"\n')
    monitor = jd.Monitor(jd.load_monitor(toml), work / "live", log=lambda x: None, console=lambda x: None)
    served = len(source.stations)
    instrument()
    decoder = c3.StreamDecoder()
    decode = timed("decode", decoder.feed)
    decoder._remember(config)   # CFG-2 holds at most ~930 stations (FRAMESIZE); the data frames more
    cfg = config
    c0 = time.perf_counter()
    monitor._handle((0, "frame", cfg, time.monotonic()))
    compile_s = time.perf_counter() - c0
    n_fill = round(fill * source.rate)
    for k, data in enumerate(frames):
        if k == n_fill:
            SPENT.clear()
            CALLS.clear()
            p0, w0 = time.process_time(), time.perf_counter()
        for frame in decode(data):
            monitor._handle((0, "frame", frame, time.monotonic()))
    cpu, wall = time.process_time() - p0, time.perf_counter() - w0
    for s in monitor.streams:
        s.close()
    per_s = {k: v / args.seconds for k, v in sorted(SPENT.items(), key=lambda kv: -kv[1])}
    out = {"units": len(monitor.cfg.units), "stations_served": served, "groups": len(monitor.streams[0].groups),
           "stream_s": args.seconds, "window_s": args.window, "compile_s": round(compile_s, 1),
           "cpu_s_per_stream_s": round(cpu / args.seconds, 4), "wall_s_per_stream_s": round(wall / args.seconds, 4),
           "parts_cpu_s_per_stream_s": {k: round(v, 4) for k, v in per_s.items()},
           "calls_per_stream_s": {k: [round(n / args.seconds, 2), round(1e3 * t / max(n, 1), 2)]
                                  for k, (n, t) in sorted(CALLS.items())},
           "updates": monitor.updates,
           "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1)}
    print(json.dumps(out, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
