"""``jaxdse monitor``: per-unit H and D, with their intervals, from live C37.118.2 streams (or
STTP, IEEE 2664, with the optional extra ``jaxdse[sttp]``: :mod:`.sttp` turns its measurements
into the same frames).

The monitor file (TOML) names the plants (``fleet``: a fleet file or a run configuration, whose
units and measurement bases it takes) and the streams (``[[stream]]``: a PMU or a PDC each,
over TCP or UDP). One thread per stream connects, asks for the configuration (CFG-2), turns
data on and decodes; it reconnects with back-off (0.5 s doubling to 10 s) when the connection
drops or stays silent, so one stream's failure costs its units only. The main thread:

* places each data frame on the reporting grid by its timestamp (:func:`~.c37118.grid_index`;
  off-grid frames are dropped and counted), holds frames ``reorder_s`` in a reorder buffer and
  releases them in grid order (a frame later than that, or a repeat, is dropped and counted);
* maps each unit to its station (by name, or ``[stream.stations]``), converts its V1 and I1
  to per unit with the unit's own measurement bases (:func:`~.pmu_sim.served_units`) and
  screens it: a STAT data error (bits 15-14), lost sync (bit 13), NaN or a value outside the
  file readers' physical ranges makes the sample unusable, and so does a stale frame (both
  phasors repeat the unit's previous sample exactly, after a second of samples that change
  every frame but ``REPEATS_RARE`` of the time, as the file readers judge a whole recording);
* feeds the units' samples to :class:`~.online.OnlineGroup` (bridging short gaps, restarting a
  unit's estimator after a long one) and writes each update as a line of ``updates.jsonl``;
  the estimators' programs run while it goes on with the frames, and their updates are read
  once computed (:meth:`~.online.OnlineGroup.collect`);
* on a new configuration (CFGCNT or the layout changed, STAT bit 10's announcement done), re-maps
  the stations and restarts that stream's estimators, and says so;
* records every released frame as the monitor used it to ``recording_<k>.csv`` (per unit: V
  and I in pu and rad, f, STAT, NaN where unusable) with ``replay.toml``, which ``jaxdse run``
  reads back through the file readers and the same windowed identification: its last update
  equals the live one;
* raises an alarm when a unit's identified H falls below ``[alarm] h_below_s`` and clears it
  when H rises above that by ``hysteresis`` (a fraction), in the log and in ``updates.jsonl``;
* with ``[inertia]`` (in the monitor file, or else in the fleet file it names), writes the
  system inertia per area every ``[inertia] update_s`` of stream time as ``updates.jsonl``
  lines with an ``"area"`` (:mod:`.inertia`).
"""

from __future__ import annotations

import dataclasses
import json
import math
import queue
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import jax.tree_util as jtu
import numpy as np

from .._io.errors import InputError
from .._io.inertia import InertiaConfig, inertia_section
from .._io.measurement import MAX_CURRENT_SAMPLE_PU_MACHINE, REPEATS_RARE, VOLTAGE_RANGE_PU
from .._io.schema import no_unknown, read_toml, subtable, typed_value
from . import c37118 as c3
from .online import OnlineGroup, Update
from .pmu_sim import PmuClient, Units, served_units, short_names
from .waits import Backoff, call, join, put, wait_ready

FREQUENCY_RANGE_HZ = 5.0
"""A frequency this far from nominal is no measurement (the readers' ``MAX_FREQUENCY_SAMPLE_OFFSET_HZ``)."""
MAX_TIMINGS = 1_000_000
"""Per-frame processing times kept for the summary (a day at 60 frames/s is 5 million)."""
MAX_PENDING_FRAMES = 4096
"""Frames the reorder buffer holds at most (its ``reorder_s`` covers far fewer); also the used
grid slots remembered to tell a repeated frame from a late one."""
PROGRESS_S = 5.0
"""While a unit's window fills (no estimate yet), a line every this many seconds [s, wall]."""
GATE_S = 60.0
"""With several streams, a stream whose estimators are ready waits at most this long [s] for the
others' before it turns data on (:class:`_StartGate`)."""
QUEUE_SIZE = 100_000
"""Items (frames, counts, connection events) waiting for the main thread."""


@dataclasses.dataclass(frozen=True)
class StreamSpec:
    """One [[stream]] of the monitor file."""

    host: str = "127.0.0.1"
    port: int = c3.TCP_PORT
    idcode: int = 1
    protocol: str = "c37.118"
    transport: str = "tcp"
    reorder_s: float = 0.2
    """Frames are held this long [s of stream time] for late ones before they are used."""
    timeout_s: float = 5.0
    """A connection silent this long [s] is dropped and made again."""
    current_direction: str = "out_of_plant"
    """The direction of the streamed current I1: out of the plant (generator convention, as
    ``jaxdse pmu-sim`` serves it) or into it."""
    frequency: str = "stream"
    """"stream": the stations' FREQ; "angle": derived from the voltage angle as the estimator
    does for a recording without a frequency channel (FREQ is then not used: a PMU whose FREQ
    is itself a difference of the angle adds its smoothing; a central difference at 30
    frames/s moved H by +1 % on NASPI OSL case 1)."""
    stations: tuple[tuple[str, str], ...] = ()
    """(unit, station name) pairs; units not named are found by their name's first 16 characters."""
    frame_rate_hz: float = 0.0
    """STTP only: the reporting rate; 0: the stations' FramesPerSecond in the publisher's metadata."""


@dataclasses.dataclass(frozen=True)
class MonitorUnit:
    name: str
    run: object
    """The unit's :class:`~jaxdse._io.config.GeneratorRun` (plant, measurement spec)."""
    stream: int


@dataclasses.dataclass(frozen=True)
class MonitorConfig:
    path: Path
    source: Path
    streams: tuple[StreamSpec, ...]
    units: tuple[MonitorUnit, ...]
    update_s: float = 1.0
    window_s: float = 120.0
    h_below_s: float | None = None
    hysteresis: float = 0.05
    notes: tuple[str, ...] = ()
    publish: dict | None = None
    """[publish] host, port, idcode of the virtual PMU (None: not published)."""
    view: dict | None = None
    """[view] host, port of the live web page (None: no page)."""
    source_units: Units | None = None
    """The units of ``source`` and the estimator's settings it gives (:class:`~.pmu_sim.Units`)."""
    inertia: InertiaConfig | None = None
    """[inertia] of the monitor file (else of the fleet file); None: no system inertia."""
    record: bool = True
    """Write the stream as used (``recording_*.csv`` and ``replay.toml``) to the output folder.
    Formatting it costs about 0.5 us of CPU per value (a core of its own at 5,000 units and 30
    frames/s, 20 MB of text a second): ``record = false`` where the streams are archived
    elsewhere."""


STREAM_KEYS = {f.name for f in dataclasses.fields(StreamSpec)} | {"units"}
TOP_KEYS = {"fleet", "update_s", "window_s", "stream", "alarm", "tile", "publish", "view", "inertia",
            "record"}
PUBLISH_KEYS = {"protocol", "host", "port", "idcode"}


def load_monitor(path, units_of) -> MonitorConfig:
    """Read and check a monitor file (see ``MONITOR_HELP`` in the CLI).

    Arguments:
        path: the monitor file.
        units_of: ``units_of(source)`` gives the :class:`~.pmu_sim.Units` of the run
            configuration or fleet file that the monitor file names (``fleet``); the
            application layer passes ``jaxdse._app.sources.source_units`` (``jaxdse.load_monitor``
            is this function with it)."""
    path = Path(path)
    data = read_toml(path)
    no_unknown(path, data, TOP_KEYS, "")
    if "fleet" not in data:
        raise InputError(path, "no fleet: name the fleet file or run configuration of the plants, "
                         'e.g. fleet = "fleet.toml"', key="fleet")
    source = (path.parent / typed_value(path, str, data["fleet"], "fleet")).resolve()
    update_s = typed_value(path, float, data.get("update_s", 1.0), "update_s", 1e-3)
    window_s = typed_value(path, float, data.get("window_s", 120.0), "window_s", 1e-3)
    if window_s < update_s:
        raise InputError(path, f"window_s = {window_s} is shorter than update_s = {update_s}", key="window_s")
    alarm = subtable(path, data, "alarm", "alarm")
    inertia = inertia_section(path, data["inertia"]) if "inertia" in data else None
    publish = None
    if "publish" in data:
        pub = subtable(path, data, "publish", "publish")
        no_unknown(path, pub, PUBLISH_KEYS, "publish.")
        protocol = typed_value(path, str, pub.get("protocol", "c37.118"), "publish.protocol")
        if protocol not in ("c37.118", "sttp"):
            raise InputError(path, f"must be \"c37.118\" or \"sttp\", got {protocol!r}",
                             key="publish.protocol")
        if protocol == "sttp":
            from . import sttp

            sttp.require(path, "publish.protocol")
        default_port = 4713 if protocol == "c37.118" else sttp.PUBLISH_PORT
        publish = {"protocol": protocol,
                   "host": typed_value(path, str, pub.get("host", "127.0.0.1"), "publish.host"),
                   "port": typed_value(path, int, pub.get("port", default_port), "publish.port", 0),
                   "idcode": typed_value(path, int, pub.get("idcode", 7734), "publish.idcode", 1)}
    no_unknown(path, alarm, {"h_below_s", "hysteresis"}, "alarm.")
    view = None
    if "view" in data:
        v = subtable(path, data, "view", "view")
        no_unknown(path, v, {"host", "port"}, "view.")
        view = {"host": typed_value(path, str, v.get("host", "127.0.0.1"), "view.host"),
                "port": typed_value(path, int, v.get("port", 8050), "view.port", 0)}
    tables = data.get("stream", [{}])
    if isinstance(tables, dict):
        tables = [tables]
    est = units_of(source)
    runs, skipped = est.runs, est.skipped
    tile = typed_value(path, int, data.get("tile", 1), "tile", 1)
    runs = tiled(runs, tile)
    names = [n for n, _ in runs]
    streams, owner = [], {}
    for k, t in enumerate(tables):
        key = f"stream[{k}]." if len(tables) > 1 else "stream."
        no_unknown(path, t, STREAM_KEYS, key)
        kw = {}
        for f in dataclasses.fields(StreamSpec):
            if f.name in t and f.name != "stations":
                kw[f.name] = typed_value(path, type(f.default), t[f.name], key + f.name,
                                         0 if isinstance(f.default, (int, float)) else None)
        if kw.get("protocol", "c37.118") not in ("c37.118", "sttp"):
            raise InputError(path, f"must be \"c37.118\" or \"sttp\", got {kw['protocol']!r}", key=key + "protocol")
        if kw.get("protocol") == "sttp":
            from . import sttp

            sttp.require(path, key + "protocol")
            if kw.get("transport", "tcp") != "tcp":
                raise InputError(path, "STTP is read over TCP", key=key + "transport")
            kw.setdefault("port", sttp.DEFAULT_PORT)
        elif "frame_rate_hz" in kw:
            raise InputError(path, "is for STTP streams (C37.118 gives its rate in CFG-2)",
                             key=key + "frame_rate_hz")
        if kw.get("transport", "tcp") not in ("tcp", "udp"):
            raise InputError(path, f"must be \"tcp\" or \"udp\", got {kw['transport']!r}", key=key + "transport")
        if kw.get("frequency", "stream") not in ("stream", "angle"):
            raise InputError(path, "must be \"stream\" or \"angle\"", key=key + "frequency")
        if kw.get("current_direction", "out_of_plant") not in ("out_of_plant", "into_plant"):
            raise InputError(path, "must be \"out_of_plant\" or \"into_plant\"", key=key + "current_direction")
        stations = subtable(path, t, "stations", key + "stations")
        for unit in stations:
            if unit not in names:
                raise InputError(path, f"no unit {unit!r} in {source.name}", key=key + "stations." + unit)
        kw["stations"] = tuple((u, str(s)) for u, s in stations.items())
        listed = t.get("units", names if len(tables) == 1 else [])
        for unit in listed:
            if unit not in names:
                raise InputError(path, f"no unit {unit!r} in {source.name}", key=key + "units")
            owner.setdefault(unit, k)
        streams.append(StreamSpec(**kw))
    units = tuple(MonitorUnit(n, g, owner[n]) for n, g in runs if n in owner)
    notes = tuple(f"{n}: not monitored ({why})" for n, why in skipped) + tuple(
        f"{n}: in no [[stream]]'s units" for n in names if n not in owner)
    if not units:
        raise InputError(path, "no unit to monitor")
    if inertia is None and est.case is not None:
        inertia = est.case[3]
    return MonitorConfig(path, source, tuple(streams), units, update_s, window_s,
                         typed_value(path, float, alarm["h_below_s"], "alarm.h_below_s", 0)
                         if "h_below_s" in alarm else None,
                         typed_value(path, float, alarm.get("hysteresis", 0.05), "alarm.hysteresis", 0), notes,
                         publish, view, est, inertia,
                         typed_value(path, bool, data.get("record", True), "record"))


def tiled(runs: list, copies: int) -> list:
    """``runs`` repeated ``copies`` times, named as ``jaxdse pmu-sim --tile`` names its stations
    (``name~2``, ...): many units from a few plants, for capacity tests."""
    return [(n if k == 0 else f"{n}~{k + 1}", g) for k in range(copies) for n, g in runs]


# --- the connections -------------------------------------------------------------------------

class _StartGate:
    """When a stream's reader turns data on: once its own estimators are compiled and every
    stream's are (the main thread compiles one stream's programs after another; frames of a
    stream already on would queue behind the next one's compile: 32-41 s at 6 streams of 836
    units), or ``GATE_S`` after its own. A reconnection finds both set and starts at once."""

    def __init__(self, own: threading.Event, every: threading.Event, k: int, log):
        self.own, self.every, self.k, self.log = own, every, k, log
        self.since = None

    def wait(self, timeout: float) -> bool:
        if not self.own.wait(timeout):
            return False
        if self.every.is_set():
            return True
        if self.since is None:
            self.since = time.monotonic()
        if self.every.wait(timeout):
            return True
        if time.monotonic() - self.since > GATE_S:
            self.log(f"stream {self.k}: data turned on {GATE_S:g} s after its estimators were ready, "
                     "without waiting longer for the other streams'")
            self.every.set()
            return True
        return False



def _reader(k: int, spec: StreamSpec, out: queue.Queue, stop: threading.Event, log,
            ready: _StartGate | threading.Event | None = None):
    """One stream's thread: connect, ask for the configuration, read; reconnect with back-off.

    Puts (k, kind, x, arrival) on ``out``: "frame" (a configuration or data frame), "up",
    "down" and "refused" (text), "counts" (the decoder's counts); ``arrival``: time.monotonic()
    when the frame's bytes came. Data is turned on once ``ready.wait`` says so (the main thread has
    taken the configuration and compiled the estimators, this stream's and, through a
    :class:`_StartGate`, the others': no backlog of frames behind the compiler), or after
    ``READY_S``. Every wait ends: the connection's and each read's within
    ``timeout_s``, a full queue (the main thread took nothing) within ``timeout_s`` too."""
    backoff = Backoff()
    consumer = "the monitor's main thread"

    def send(kind, x, at=None):
        put(out, (k, kind, x, time.monotonic() if at is None else at), spec.timeout_s, consumer)

    while not stop.is_set():
        up = False
        try:
            with PmuClient(spec.host, spec.port, spec.idcode, timeout=spec.timeout_s,
                           udp=spec.transport == "udp") as pmu:
                send("frame", pmu.config(c3.CFG2))
                wait_ready(ready, stop, log, k)
                pmu.start()
                send("up", f"{spec.host}:{spec.port}")
                up = True
                backoff.reset()
                last = time.monotonic()
                while not stop.is_set():
                    frames = pmu.poll(0.2)
                    now = time.monotonic()
                    if frames:
                        last = now
                    elif now - last > spec.timeout_s:
                        raise TimeoutError(f"no frame for {spec.timeout_s:g} s")
                    for frame in frames:
                        if isinstance(frame, (c3.ConfigFrame, c3.DataFrame)):
                            send("frame", frame, now)
                    send("counts", decoder_counts(pmu.decoder.counts))
                try:
                    pmu.stop()
                except OSError:
                    pass
        except (OSError, ConnectionError, TimeoutError) as err:
            if stop.is_set():
                break
            try:
                send("down" if up else "refused", f"{err}")
            except TimeoutError as full:
                log(f"stream {k}: {full}")
            log(f"stream {k} ({spec.host}:{spec.port}): {err or type(err).__name__}; reconnecting in "
                f"{backoff.s:g} s")
            backoff.wait(stop)


def decoder_counts(counts) -> dict:
    """The C37.118 decoder's counts, each named for what it counts: ``frames_decoded`` (every
    frame decoded: configuration, data, header, command), ``bytes_skipped`` (garbage before a
    SYNC byte) and ``frames_rejected_<why>`` (crc, length, type, field, malformed, no_config:
    :class:`~.c37118.FrameError`'s kinds; not used)."""
    out = {"frames_decoded": int(counts.get("frames", 0)), "bytes_skipped": int(counts.get("skipped_bytes", 0))}
    out.update({f"frames_rejected_{kind}": int(n) for kind, n in sorted(counts.items())
                if kind not in ("frames", "skipped_bytes") and n})
    return out


# --- the units' estimators ---------------------------------------------------------------------

def unit_groups(units) -> list[list[int]]:
    """Indices of ``units`` (:class:`MonitorUnit`) by plant structure and PMU location: one
    :class:`OnlineGroup` (one vmapped program) each."""
    groups = defaultdict(list)
    for j, u in enumerate(units):
        groups[(jtu.tree_structure(u.run.plant), u.run.measurement.location)].append(j)
    return list(groups.values())


def make_groups(units, rate: float, cfg: MonitorConfig, est, with_frequency: bool = True,
                defer: bool = False) -> list[tuple[OnlineGroup, np.ndarray]]:
    """The :class:`OnlineGroup` of each group of ``units`` and the units' indices in it
    (``defer``: a restarted unit's chunks wait for :meth:`OnlineGroup.catch_up`)."""
    from .._core.windowed import WindowSettings

    window = WindowSettings(update_s=cfg.update_s, window_s=cfg.window_s)
    out = []
    for idx in unit_groups(units):
        us = [units[j] for j in idx]
        out.append((OnlineGroup([u.name for u in us], [u.run.plant for u in us],
                                [u.run.measurement.location for u in us], rate, window, est.observer,
                                est.settings, est.identify, est.verdict,
                                max_gap_s=min(u.run.measurement.max_gap_s for u in us),
                                with_frequency=with_frequency, defer=defer), np.asarray(idx)))
    return out


def screen(v, i, f, stat, specs_scale, f_nominal):
    """Per-unit pu samples -> (v, i, f, usable): STAT data error or lost sync (the readers'
    ``STAT_INVALID_BITS``), NaN, |V| or |I| outside the readers' physical ranges make a sample
    unusable; a frequency outside them is dropped (NaN: derived from the angle)."""
    vm, im = np.abs(v), np.abs(i)
    usable = ((np.asarray(stat, np.int64) & 0xE000) == 0) & np.isfinite(v) & np.isfinite(i) \
        & (vm >= VOLTAGE_RANGE_PU[0]) & (vm <= VOLTAGE_RANGE_PU[1]) \
        & ~(im * specs_scale > MAX_CURRENT_SAMPLE_PU_MACHINE)
    f = np.where(np.abs(f - f_nominal) <= FREQUENCY_RANGE_HZ, f, np.nan)
    return v, i, f, usable


def _layout(cfg: c3.ConfigFrame):
    """What a configuration change alters: rate, time base, stations, their channels and formats."""
    return (cfg.data_rate, cfg.time_base, tuple((s.name, s.idcode, s.cfgcnt, s.format, len(s.phasors))
                                                for s in cfg.stations))


COLUMNS = ("VM", "VA", "IM", "IA", "F", "STAT")
"""A unit's columns in a recording: |V| [pu], angle V [rad], |I| [pu], angle I [rad], f [Hz], STAT."""
COUNTS = {
    "data_frames": "data frames received with a configuration in force; each is then used, late, "
                   "repeated, off the grid or beyond the reorder buffer",
    "frames_used": "frames released to the estimators and the recording (one per grid slot)",
    "slots_without_frame": "grid slots between used frames that no frame filled before they were released "
                           "(dropped on the way, or later than reorder_s)",
    "late_frames": "frames that came after their grid slot was released (not used; the slot is also in "
                   "slots_without_frame)",
    "repeated_frames": "frames for a grid slot already held or used (not used)",
    "off_grid_frames": "frames whose timestamp is not on the reporting grid (not used)",
    "reorder_overflow_frames": f"frames that found the reorder buffer full ({MAX_PENDING_FRAMES} frames; not used)",
    "frames_before_config": "data frames before the stream's first configuration (not used)",
    "config_changes": "new configurations (CFGCNT or layout changed): stations re-mapped, estimators restarted",
    "disconnects": "connections that dropped or stayed silent timeout_s, and were made again",
    "connect_failures": "connection attempts that failed",
}
"""A stream's counters in monitor.json and the live view, and what each counts."""
DECODER_COUNTS = {
    "frames_decoded": "C37.118: frames the decoder decoded (configuration, data, header, command)",
    "bytes_skipped": "C37.118: bytes of garbage before a SYNC byte",
    "frames_rejected_<why>": "C37.118: frames the decoder rejected, by why (crc, length, type, field, "
                             "malformed, no_config); not used",
    "unknown_points, points_off_grid, late_points": "STTP: measurements not used (not subscribed, "
                                                     "timestamp off the grid, for a frame already released)",
    "bad_quality_points": "STTP: measurements whose quality flags set a data error in their station's STAT",
    "incomplete_frames": "STTP: frames released without every subscribed point",
    "inbox_overflow": "STTP: packets of measurements lost (the reader's inbox was full)",
}
"""What each stream's ``decoder`` counts in monitor.json (summed over its connections)."""
SUMMARY_KEYS = {
    "delay_s": "per update, from the window's last frame's timestamp to the update, in seconds of stream "
               "time (the stream's own clock, as its frames' timestamps and arrivals show it): the same at "
               "any --speed",
    "wall_delay_s": "the same delay in wall seconds (delay_s divided by the stream's pace)",
    "monitor_s": "per emission of updates, wall seconds from the newest frame's arrival to it (the main "
                 "thread's queue and processing): delay_s is the stream time from the window's end to the newest "
                 "frame (the estimate's own wait: its lookahead and the reorder buffer) plus this times the pace",
    "pace": "per stream, stream seconds per wall second (1 in real time; 5 for pmu-sim --speed 5)",
    "processing_ms_per_frame": "the main thread's time per data frame, its updates included [ms]",
    "processing_cpu_ms_per_frame": "the main thread's CPU time per data frame, its updates included [ms] "
                                   "(processing_ms_per_frame less the time other threads and processes "
                                   "held the cores)",
    "catch_up_s": "the main thread's seconds on restarted units' chunks, run while no frame waited (not in "
                  "processing_ms_per_frame)",
    "inertia_delay_s": "with [inertia], per set of area lines, stream seconds from the lines' time to their "
                       "emission (the area estimate holds each unit's latest update, itself delay_s after its "
                       "window's last frame)",
}
UNIT_COUNTS = {
    "unusable_samples": "per unit, samples not used: STAT data error or lost sync, NaN, or a value outside "
                        "the file readers' physical ranges",
    "stale_samples": "per unit, usable samples not used because both phasors repeat the previous sample "
                     "exactly (a PDC holding a lost PMU's last value)",
}


class StreamClock:
    """A stream's own clock, as its frames show it: the delay of an estimate is measured on it,
    in seconds of stream time, so that it means the same at any pace (``jaxdse pmu-sim --speed
    5`` sends a recording five times faster than its timestamps advance; a PDC replaying an
    archive may run slower or faster than real time).

    At wall time w (``time.monotonic()``) the stream's time is that of the newest frame
    received, t_n, plus the wall time since it arrived, w_n, at the stream's pace r (stream
    seconds per wall second, from the first frame of the connection to the newest):
    ``now(w) = t_n + (w - w_n) r``. The delay of an update for the window that ends at t is
    ``now(w) - t`` [s of stream time]; divided by r, the wall seconds it took. Neither needs
    the monitor's clock to agree with the stream's (a frame's transport from the PMU is not in
    it: at real time and with a synchronised clock, ``time.time() - t`` at a frame's arrival is
    that latency)."""

    MIN_SPAN_S = 0.1
    """Wall time from the first frame [s] before the pace is measured (1 until then)."""

    def __init__(self):
        self.first = self.newest = None
        self.pace_before = None

    def restart(self):
        """A new connection: the pace is measured again (the last one serves meanwhile)."""
        self.pace_before = self.pace or self.pace_before
        self.first = self.newest = None

    def frame(self, t: float, arrival: float):
        """A data frame stamped ``t`` [s since 1970] that arrived at ``arrival`` [monotonic s]."""
        if self.first is None:
            self.first = (t, arrival)
        if self.newest is None or t > self.newest[0]:
            self.newest = (t, arrival)

    @property
    def pace(self) -> float | None:
        """Stream seconds per wall second (None: not measured yet)."""
        if self.first is None or self.newest[1] - self.first[1] < self.MIN_SPAN_S:
            return self.pace_before
        return (self.newest[0] - self.first[0]) / (self.newest[1] - self.first[1])

    def since_newest(self, wall: float) -> float | None:
        """Wall seconds from the newest frame's arrival to ``wall`` (None: no frame yet)."""
        return None if self.newest is None else wall - self.newest[1]

    def now(self, wall: float) -> float | None:
        """The stream's time [s since 1970] at ``wall`` [monotonic s] (None: no frame yet)."""
        if self.newest is None:
            return None
        return self.newest[0] + (wall - self.newest[1]) * (self.pace or 1.0)


class _Stream:
    """One stream's configuration, reorder buffer, estimators and recording."""

    def __init__(self, k: int, spec: StreamSpec, units: list[MonitorUnit], all_names: list[str],
                 cfg: MonitorConfig, est, out_dir: Path | None, log):
        self.k, self.spec, self.units, self.cfg, self.est, self.log = k, spec, units, cfg, est, log
        self.out_dir = out_dir
        short = dict(zip(all_names, short_names(all_names)))
        named = dict(spec.stations)
        self.wanted = [(named.get(u.name), u.name, short[u.name]) for u in units]
        scale = [served_units(u.run.measurement)[:2] for u in units]
        self.v_per_pu = np.array([s[0] for s in scale])
        self.i_per_pu = np.array([s[1] for s in scale]) * (-1.0 if spec.current_direction == "into_plant" else 1.0)
        self.machine_scale = np.array([u.run.measurement.s_base_mva / float(u.run.plant.machine.s_rated_mva)
                                       for u in units])
        self.f_nominal = np.array([float(u.run.measurement.f_nominal_hz) for u in units])
        self.config = None
        self.groups = []
        self.pos = np.full(len(units), -1)
        self.heap, self.held = [], set()
        self.used_recent, self.used_order = set(), []
        self.released = None
        self.newest = None
        self.parts = []
        self.file = None
        # every key from the start: the live view's thread copies the dict while this one counts
        self.counts = defaultdict(int, dict.fromkeys(COUNTS, 0))
        self.decoder_done = defaultdict(int)   # the reader's counts of the connections before this one
        self.decoder_now = {}                  # ... and of this one
        self.clock = StreamClock()
        self.tracker = None                     # the system inertia's (Monitor with [inertia])
        self.names = [u.name for u in units]
        self.ready = threading.Event()          # the configuration taken, the estimators compiled
        self.compile_s = 0.0                    # [s] the main thread spent compiling them
        self.unusable = np.zeros(len(units), np.int64)
        self.stale = np.zeros(len(units), np.int64)
        self._forget_samples()

    def _forget_samples(self):
        """Each unit's last sample and its history of repeats, from which a stale frame is told."""
        n = len(self.units)
        self.last_v, self.last_i = np.full(n, np.nan, complex), np.full(n, np.nan, complex)
        self.pairs, self.repeats = np.zeros(n, np.int64), np.zeros(n, np.int64)

    # configuration
    def on_config(self, frame: c3.ConfigFrame) -> list[Update]:
        if self.config is not None and _layout(frame) == _layout(self.config):
            return []
        out = self.release(everything=True) if self.config is not None else []
        old = self.config
        self.config = frame
        names = [s.name for s in frame.stations]
        self.pos = np.full(len(self.units), -1)
        self._forget_samples()
        missing = []
        for j, (given, full, short) in enumerate(self.wanted):
            for cand in (given,) if given else (full, short):
                if cand in names:
                    self.pos[j] = names.index(cand)
                    break
            else:
                missing.append(full)
        self.rate = frame.rate_hz
        self.reorder = max(0, math.ceil(self.spec.reorder_s * self.rate - 1e-9))
        self.groups = make_groups(self.units, self.rate, self.cfg, self.est, self.spec.frequency == "stream",
                                  defer=True)
        t0 = time.perf_counter()
        self.log(f"stream {self.k}: compiling the estimators' programs ({len(self.groups)} group(s): up to a "
                 "minute the first time, seconds from the compilation cache; data is turned on once they are "
                 "ready)")
        for group, _ in self.groups:      # the compiler now, while the window fills
            group.warm_up()
        self.compile_s += time.perf_counter() - t0
        self.log(f"stream {self.k}: the estimators' programs ready ({len(self.groups)} group(s), "
                 f"{time.perf_counter() - t0:.1f} s)")
        self.heap, self.held, self.released, self.newest = [], set(), None, None
        self.used_recent, self.used_order = set(), []
        self._new_part()
        mapped = int((self.pos >= 0).sum())
        if old is None:
            self.log(f"stream {self.k}: {len(names)} station(s) at {self.rate:g} frames/s; {mapped} of "
                     f"{len(self.units)} unit(s) mapped")
        else:
            self.counts["config_changes"] += 1
            self.log(f"stream {self.k}: the configuration changed (CFGCNT {old.stations[0].cfgcnt} -> "
                     f"{frame.stations[0].cfgcnt}): stations re-mapped ({mapped} unit(s)), their estimators "
                     "restarted")
        if missing:
            self.log(f"stream {self.k}: no station for {', '.join(missing)} (not estimated)")
        return out

    def decoder(self) -> dict:
        """The reader's counts over every connection so far (:data:`DECODER_COUNTS`)."""
        out = defaultdict(int, self.decoder_done)
        for name, n in self.decoder_now.items():
            out[name] += n
        return {name: int(n) for name, n in sorted(out.items()) if n}

    def progress(self) -> str | None:
        """What the stream's units wait for, while some have no estimate in their segment yet
        (None when every mapped unit has one)."""
        where = f"{self.spec.host}:{self.spec.port}"
        if self.config is None:
            fails = self.counts["connect_failures"]
            return (f"waiting for the configuration from {where}"
                    + (f" ({fails} failed connection attempt(s))" if fails else ""))
        if self.released is None and not self.heap:
            return f"connected to {where}; waiting for data frames"
        have, need, reason = [], [], None
        for group, members in self.groups:
            h, n = group.filling()
            mapped = self.pos[members] >= 0
            have += list(h[mapped & np.isfinite(n)])
            need += list(n[mapped & np.isfinite(n)])
            reason = reason or group.wait_reason()
        if not need:
            return None
        mapped = int((self.pos >= 0).sum())
        return (f"{len(need)} of {mapped} unit(s) filling their window: {min(have):.1f} of {max(need):.1f} s of "
                f"stream time (the first estimate needs {reason})")

    def _new_part(self):
        self.close()
        self.rows = []
        if self.out_dir is None or not self.cfg.record:
            return
        name = f"recording_{self.k}_{len(self.parts) + 1}.csv"
        self.parts.append({"file": name, "stream": self.k, "frame_rate_hz": self.rate, "index0": None,
                           "units": [u.name for u in self.units]})
        self.file = CsvRows(self.out_dir / name,
                            ["time_s"] + [f"{u.name}/{c}" for u in self.units for c in COLUMNS])

    # data
    def on_data(self, frame: c3.DataFrame) -> list[Update]:
        if self.config is None:
            self.counts["frames_before_config"] += 1
            return []
        self.counts["data_frames"] += 1
        idx = c3.grid_index(frame.soc, frame.fracsec, self.config.time_base, self.config.data_rate)
        if idx is None:
            self.counts["off_grid_frames"] += 1
            return []
        if idx in self.held or idx in self.used_recent:
            self.counts["repeated_frames"] += 1
            return []
        if self.released is not None and idx <= self.released:
            self.counts["late_frames"] += 1
            return []
        if len(self.held) >= MAX_PENDING_FRAMES:
            self.counts["reorder_overflow_frames"] += 1
            return []
        import heapq

        heapq.heappush(self.heap, (idx, id(frame), frame))
        self.held.add(idx)
        self.newest = idx if self.newest is None else max(self.newest, idx)
        return self.release()

    def release(self, everything: bool = False) -> list[Update]:
        import heapq

        out = []
        while self.heap and (everything or self.heap[0][0] <= self.newest - self.reorder):
            idx, _, frame = heapq.heappop(self.heap)
            self.held.discard(idx)
            if self.released is not None and idx > self.released + 1:
                self.counts["slots_without_frame"] += idx - self.released - 1
            self.released = idx
            self.counts["frames_used"] += 1
            self.used_recent.add(idx)
            self.used_order.append(idx)
            if len(self.used_order) > 2 * MAX_PENDING_FRAMES:     # the last MAX_PENDING_FRAMES kept
                for old in self.used_order[:-MAX_PENDING_FRAMES]:
                    self.used_recent.discard(old)
                del self.used_order[:-MAX_PENDING_FRAMES]
            out += self._use(idx, frame)
        return out

    def _use(self, idx: int, frame: c3.DataFrame) -> list[Update]:
        a = frame.arrays
        ph = a.phasors if isinstance(a.phasors, np.ndarray) else np.array(
            [np.concatenate([p[:2], np.full(max(0, 2 - len(p)), np.nan)]) for p in a.phasors])
        ok = self.pos >= 0
        p = np.where(ok, self.pos, 0)
        v = np.where(ok, ph[p, 0], np.nan) / self.v_per_pu
        i = np.where(ok, ph[p, 1], np.nan) / self.i_per_pu
        stat = np.where(ok, np.asarray(a.stat)[p], 0xFFFF)
        v, i, f, usable = screen(v, i, np.where(ok, np.asarray(a.freq, float)[p], np.nan), stat,
                                 self.machine_scale, self.f_nominal)
        self.unusable += ~usable & ok
        usable = usable & ~self._stale(v, i, usable)
        if self.spec.frequency != "stream":
            f = np.full_like(f, np.nan)
        vm, va, im, ia = np.abs(v), np.angle(v), np.abs(i), np.angle(i)
        if self.tracker is not None:
            self.tracker.samples(self.names, im * self.machine_scale, usable, idx / self.rate, key=self.k)
        if self.file is not None:
            part = self.parts[-1]
            if part["index0"] is None:
                part["index0"] = idx
            cols = np.stack([vm, va, im, ia, f, stat.astype(float)], axis=1)
            cols[~usable, :5] = np.nan
            self.rows.append(np.concatenate([[(idx - part["index0"]) / self.rate], cols.reshape(-1)]))
            if len(self.rows) >= self.rate:
                self._flush()
        out = []
        for group, members in self.groups:
            out += group.push(idx, vm[members], va[members], im[members], ia[members], f[members], usable[members])
        return out

    def behind(self) -> bool:
        """Whether deferred chunks (a start's, a restarted unit's) wait for :meth:`catch_up`."""
        return any(group.behind() for group, _ in self.groups)

    def catch_up(self, force: bool = False, idle: bool = True) -> list[Update]:
        """One deferred chunk of each unit of the first group that may run them
        (:meth:`can_catch_up`; ``force``: any that has them); the main thread's spare time, a
        group at a time, so that a frame waits for one group's call at most."""
        for group, _ in self.groups:
            if group.behind() and (force or self._may(group, idle)):
                return group.catch_up()
        return []

    def can_catch_up(self, idle: bool) -> bool:
        """Whether a group has deferred chunks and its previous chunk is computed; a segment's
        first chunk (30 s of samples, 1-2 s for 836 units) only while the computer is ``idle``
        (no group of any stream busy), so that a start's six do not queue at once."""
        return any(group.behind() and self._may(group, idle) for group, _ in self.groups)

    @staticmethod
    def _may(group, idle: bool) -> bool:
        return not group.busy() and (idle or not group.first_behind())

    def waiting(self) -> bool:
        """Whether dispatched estimates wait to be read (:meth:`collect`)."""
        return any(group.waiting() for group, _ in self.groups)

    def busy(self) -> bool:
        """Whether the computer works on a group's programs (:meth:`OnlineGroup.busy`)."""
        return any(group.busy() for group, _ in self.groups)

    def collect(self, wait: bool = False, most: int | None = None) -> list[Update]:
        """The updates of the groups' dispatched estimates that are done (``wait``: all; ``most``:
        of at most this many chunks, from the first groups that have them)."""
        out = []
        for group, _ in self.groups:
            if most is not None and most <= 0:
                break
            got = len(group.pending)
            out += group.collect(wait, most)
            most = None if most is None else most - (got - len(group.pending))
        return out

    def _stale(self, v, i, usable):
        """Samples that repeat the unit's previous one exactly in both phasors, where a second of
        its samples changed every frame but ``REPEATS_RARE`` of the time (counted)."""
        pair = usable & np.isfinite(self.last_v)
        same = pair & (v == self.last_v) & (i == self.last_i)
        stale = same & (self.pairs >= self.rate) & (self.repeats <= REPEATS_RARE * self.pairs)
        self.pairs += pair
        self.repeats += same
        self.stale += stale
        self.last_v, self.last_i = np.where(usable, v, np.nan), np.where(usable, i, np.nan)
        return stale

    def _flush(self):
        """Write the rows held (:class:`CsvRows`)."""
        if self.rows:
            self.file.write(np.stack(self.rows))
            self.rows = []

    def close(self):
        if self.file is not None:
            self._flush()
            self.file.close()
            self.file = None


ROWS_IN_A_PROCESS = 3000
"""A recording whose rows hold at least this many values is written by a process of its own
(:class:`CsvRows`)."""
_WRITER = """
import sys
import numpy as np
n = int(sys.argv[2])
fmt = ",".join(["%.17g"] * n) + "\\n"
with open(sys.argv[1], "a") as out:
    src = sys.stdin.buffer
    while True:
        head = src.read(8)
        if len(head) < 8:
            break
        rows = int.from_bytes(head, "little")
        block = np.frombuffer(src.read(8 * n * rows), np.float64).reshape(rows, n)
        out.write("".join(fmt % tuple(r) for r in block))
        out.flush()
"""


class CsvRows:
    """A CSV file of float rows: a header, then each row in %.17g (every float64 reads back
    exactly; NaN as nan). Rows of ``ROWS_IN_A_PROCESS`` values or more are formatted by a child
    Python process (fed their bytes through a pipe): 0.5 us of CPU a value, at 5,000 units half
    a second for each second of frames, which would hold the monitor's main thread; the file is
    the same byte for byte. ``in_process``: force the one or the other (None: by the size)."""

    def __init__(self, path: Path, header: list[str], in_process: bool | None = None):
        import subprocess

        self.path, self.n = Path(path), len(header)
        self.path.write_text(",".join(header) + "\n")
        own = self.n >= ROWS_IN_A_PROCESS if in_process is None else not in_process
        self.proc = subprocess.Popen([sys.executable, "-c", _WRITER, str(self.path), str(self.n)],
                                     stdin=subprocess.PIPE) if own else None
        self.fmt = None if own else ",".join(["%.17g"] * self.n) + "\n"
        self.out = None if own else open(self.path, "a")

    def write(self, rows: np.ndarray):
        """Append ``rows`` [k, n] (float64)."""
        rows = np.ascontiguousarray(rows, np.float64)
        if rows.shape[1] != self.n:
            raise ValueError(f"CsvRows: rows of {rows.shape[1]} values, the header has {self.n}")
        if self.proc is None:
            self.out.write("".join(self.fmt % tuple(r) for r in rows))
        else:
            self.proc.stdin.write(rows.shape[0].to_bytes(8, "little") + rows.tobytes())
            self.proc.stdin.flush()

    def close(self):
        """The rows written to the file (waits for the writer process)."""
        if self.out is not None:
            self.out.close()
            self.out = None
        if self.proc is not None:
            self.proc.stdin.close()
            if self.proc.wait() != 0:
                raise OSError(f"writing {self.path} failed (exit status {self.proc.returncode})")
            self.proc = None


_encode = json.JSONEncoder(check_circular=False).encode
"""json.dumps's text for the flat lines of ``updates.jsonl``, without the check for cycles."""


def update_line(u: Update, alarm: bool, delay_s: float | None = None, wall_delay_s: float | None = None) -> dict:
    """One line of ``updates.jsonl``; ``delay_s``: from the window's last frame to this update,
    in seconds of stream time (:class:`StreamClock`); ``wall_delay_s``: the same in wall seconds."""
    line = {"t": u.t, "unit": u.unit, "H_s": u.h_s, "H_ci95": u.h_ci95, "D": u.d_pu_s, "D_ci95": u.d_ci95,
            "verdict": u.verdict, "reasons": list(u.reasons), "age_s": u.age_s, "last_H_s": u.last_h_s,
            "segment": u.segment, "window_s": u.window_s, "samples": u.samples, "alarm": alarm}
    if delay_s is not None:
        line["delay_s"] = round(delay_s, 6)
    if wall_delay_s is not None:
        line["wall_delay_s"] = round(wall_delay_s, 6)
    return line


class Monitor:
    """The monitor of :func:`load_monitor`'s configuration (see the module docstring).

    ``progress_s``: while a unit's window fills, a line every this many wall seconds saying how
    far along it is and what its first estimate waits for."""

    def __init__(self, cfg: MonitorConfig, out_dir: Path | None = None, log=None, console=None,
                 progress_s: float = PROGRESS_S):
        if cfg.source_units is None:
            raise ValueError("MonitorConfig without its source_units: read the monitor file with "
                             "jaxdse.load_monitor")
        self.cfg = cfg
        self.out_dir = None if out_dir is None else Path(out_dir)
        if self.out_dir is not None:
            self.out_dir.mkdir(parents=True, exist_ok=True)
        self.log = log or (lambda line: print(f"jaxdse monitor: {line}", file=sys.stderr, flush=True))
        self.console = console
        self.progress_s = progress_s
        self.est = cfg.source_units
        names = [u.name for u in cfg.units]
        self.streams = [_Stream(k, spec, [u for u in cfg.units if u.stream == k], names, cfg, self.est,
                                self.out_dir, self.log) for k, spec in enumerate(cfg.streams)]
        self.all_ready = threading.Event()   # every stream's estimators compiled (_StartGate)
        self.alarms = {}
        self.inertia_alarms = {}   # area -> E below the floor
        self.inertia_delays = []   # [s of stream time] per inertia line set, from its time to its emission
        self.inertia_times = []    # ... and that time [s since 1970]
        self.updates = 0
        self.latest = {}
        self.delays = []         # [s of stream time] per update, from the window's last frame
        self.wall_delays = []    # the same [s of wall time]
        self.monitor_s = []      # [s of wall time] per emission, from the newest frame's arrival to it
        self._jsonl = None if self.out_dir is None else open(self.out_dir / "updates.jsonl", "w")
        self._next_report = None
        self.inertia = None
        if cfg.inertia is not None:
            from .inertia import tracker_for

            self.inertia = tracker_for(cfg.units, self.est, cfg.inertia, self.log)
            for s in self.streams:
                s.tracker = self.inertia
        self.publisher = None
        if cfg.publish is not None:
            opts = dict(cfg.publish)
            if opts.pop("protocol", "c37.118") == "sttp":
                from .sttp import SttpPublisher as Publisher
            else:
                from .publish import Publisher

            f_nom = round(float(cfg.units[0].run.measurement.f_nominal_hz))
            self.publisher = Publisher([u.name for u in cfg.units], update_s=cfg.update_s, f_nominal_hz=f_nom,
                                       log=self.log, **opts, **({} if self.inertia is None else {
                                           "areas": self.inertia.areas + ["system"],
                                           "floor_MWs": cfg.inertia.floor_MWs}))
        self.view = None
        if cfg.view is not None:
            from .view import LiveView

            self.view = LiveView([u.name for u in cfg.units], self._status, **cfg.view,
                                 floor_MWs=None if cfg.inertia is None else cfg.inertia.floor_MWs)
        self.processing = []     # seconds of the main thread per data frame (updates included)
        self.processing_cpu = []  # ... of its CPU time (the same without other processes' share of the cores)
        self.catch_up_s, self._next_catch_up = 0.0, 0   # restarted units' deferred chunks
        self._next_collect = 0

    def emit(self, updates: list[Update], stream: _Stream | None = None, timed: bool = True):
        """Log, record, publish and show ``updates`` of ``stream``; their delay is measured on the
        stream's clock (:class:`StreamClock`); ``timed``: count it in the summary (not for the
        last frames flushed at the stop, which waited for it)."""
        now = pace = None
        rows = []
        if stream is not None and updates:
            w = time.monotonic()
            now = stream.clock.now(w)
            pace = stream.clock.pace or 1.0
            if now is not None and timed:
                self.monitor_s.append(stream.clock.since_newest(w))
        for u in updates:
            if self.inertia is not None:
                self.inertia.update(u)
            alarm = self._alarm(u)
            delay = wall = None
            if now is not None:
                delay = now - u.t
                wall = delay / pace
                if timed:
                    self.delays.append(delay)
                    self.wall_delays.append(wall)
            self.updates += 1
            self.latest[u.unit] = u
            line = update_line(u, alarm, delay, wall)
            if self._jsonl is not None:
                rows.append(_encode(line))
            if self.view is not None:
                self.view.add(line)
        if rows:     # one write per call (a write per line: 6 % of the main thread at 4,788 units)
            self._jsonl.write("\n".join(rows) + "\n")
            self._jsonl.flush()
        if updates and self.publisher is not None:
            by_t = defaultdict(list)
            for u in updates:
                by_t[u.t].append(u)
            for t in sorted(by_t):
                self.publisher.publish(t, by_t[t], self.alarms)
        if updates:
            self._report(max(u.t for u in updates))

    def _alarm(self, u: Update) -> bool:
        on = self.alarms.get(u.unit, False)
        limit = self.cfg.h_below_s
        if limit is None or u.h_s is None:
            return on
        if not on and u.h_s < limit:
            on = True
            self.log(f"ALARM {u.unit}: H {u.h_s:.3g} s (95 % {u.h_ci95[0]:.3g}-{u.h_ci95[1]:.3g}) below "
                     f"{limit:g} s at {_utc(u.t)}")
        elif on and u.h_s > limit * (1.0 + self.cfg.hysteresis):
            on = False
            self.log(f"alarm cleared {u.unit}: H {u.h_s:.3g} s at {_utc(u.t)}")
        self.alarms[u.unit] = on
        return on

    def _report(self, t: float):
        every = max(self.cfg.update_s, 10.0)
        if self._next_report is not None and t < self._next_report:
            return
        self._next_report = (math.floor(t / every) + 1) * every
        words = defaultdict(int)
        for u in self.latest.values():
            words[u.verdict] += 1
        hs = [u.h_s for u in self.latest.values() if u.h_s is not None]
        slots = sum(s.counts["slots_without_frame"] for s in self.streams)
        late = sum(s.counts["late_frames"] for s in self.streams)
        recent = self.delays[-100:]
        line = (f"{_utc(t)}: {len(self.latest)} unit(s): " + ", ".join(f"{k} {v}" for k, v in sorted(words.items()))
                + (f"; median H {np.median(hs):.3g} s" if hs else "")
                + (f"; delay {np.median(recent):.2f} s of stream time" if recent else "")
                + f"; grid slots without a frame {slots}" + (f" ({late} frame(s) came late)" if late else ""))
        (self.console or self.log)(line)

    def _progress(self):
        """While a stream's units wait for their first estimate: a line per stream, how far
        along they are and what they wait for."""
        for s in self.streams:
            line = s.progress()
            if line:
                self.log(f"stream {s.k}: {line}")

    def run(self, duration_s: float | None = None) -> dict:
        """Monitor until ``duration_s`` seconds pass, not counting the compilation of the
        estimators at a stream's configuration (None: until interrupted); returns the summary."""
        q: queue.Queue = queue.Queue(maxsize=QUEUE_SIZE)
        stop = threading.Event()
        threads = []
        for k, s in enumerate(self.streams):
            target, args = _reader, (k, s.spec, q, stop, self.log,
                                     _StartGate(s.ready, self.all_ready, k, self.log))
            if s.spec.protocol == "sttp":
                from .sttp import reader as target

                args = args + ([given or full for given, full, _ in s.wanted],)
            threads.append(threading.Thread(target=target, args=args, daemon=True, name=f"jaxdse-stream-{k}"))
        for t in threads:
            t.start()
        if self.view is not None:
            host, port = self.view.start()
            self.log(f"live view on http://{host}:{port}/")
        if self.publisher is not None:
            host, port = self.publisher.start()
            if (self.cfg.publish or {}).get("protocol") == "sttp":
                self.log(f"publishing STTP on tcp {host}:{port} (point tags UNIT:H, UNIT:H_LO, ...)")
            else:
                self.log(f"publishing on tcp {host}:{port} (IDCODE {self.publisher.idcode}, one station per "
                         "unit)")
        t0 = time.monotonic()
        next_progress = t0 + self.progress_s
        try:
            while duration_s is None or time.monotonic() - t0 - sum(s.compile_s for s in self.streams) < duration_s:
                try:
                    self._handle(q.get_nowait())
                except queue.Empty:     # no frame waits: estimates done, deferred chunks, or wait for one
                    if not self._collect() and not self._catch_up():
                        try:
                            self._handle(q.get(timeout=0.01 if self._waiting() else 0.05))
                        except queue.Empty:
                            pass
                if time.monotonic() >= next_progress:
                    self._progress()
                    next_progress = time.monotonic() + self.progress_s
        except KeyboardInterrupt:
            self.log("interrupted")
        finally:
            stop.set()
            for s, t in zip(self.streams, threads):    # a reader's longest step: a connection or read, then a put
                join(t, 2.0 * s.spec.timeout_s + 1.0, f"reading stream {s.k} from {s.spec.host}:{s.spec.port}",
                     self.log)
            while True:    # what was received before the stop is used and recorded
                try:
                    self._handle(q.get_nowait())
                except queue.Empty:
                    break
            for s in self.streams:
                self.emit(s.release(everything=True), s, timed=False)
                while s.behind():
                    self.emit(s.catch_up(force=True), s, timed=False)
                self.emit(s.collect(wait=True), s, timed=False)
                s.close()
            if self._jsonl is not None:
                self._jsonl.close()
            if self.publisher is not None:
                self.publisher.stop()
            if self.view is not None:
                call(self.view.stop, 5.0, "stopping the live view's web server", self.log)
        return self._finish(time.monotonic() - t0)

    def _waiting(self) -> bool:
        return any(s.waiting() or s.busy() for s in self.streams)

    def _collect(self) -> bool:
        """The updates of one chunk's estimates that are done (dispatched with a frame or a
        catch-up, computed while the main thread went on with the frames), on the next stream
        that has them; whether there were any. The main thread's spare time, one chunk at a
        time: the frames, and the system inertia's lines, wait for one chunk's updates at most."""
        n = len(self.streams)
        for j in range(n):
            s = self.streams[(self._next_collect + j) % n]
            if s.waiting():
                updates = s.collect(most=1)
                if updates:
                    self._next_collect = (s.k + 1) % n
                    self.emit(updates, s)
                    return True
        return False

    def _catch_up(self) -> bool:
        """One round of deferred chunks on the next stream that has them, of a group whose
        previous chunk is computed (a chunk per group in the computer's queue, and a segment's
        first only in an empty one: the CPU client runs a bounded number of dispatched programs,
        and a dispatch beyond it waits, with the frames, for the oldest); whether there was one."""
        n = len(self.streams)
        idle = not any(s.busy() for s in self.streams)
        for j in range(n):
            s = self.streams[(self._next_catch_up + j) % n]
            if s.can_catch_up(idle):
                t0 = time.perf_counter()
                self.emit(s.catch_up(idle=idle), s)
                self.catch_up_s += time.perf_counter() - t0
                self._next_catch_up = (s.k + 1) % n
                return True
        return False

    def _handle(self, item):
        k, kind, x, arrival = item
        s = self.streams[k]
        if kind == "frame":
            t0, c0 = time.perf_counter(), time.thread_time()
            if isinstance(x, c3.ConfigFrame):
                self.emit(s.on_config(x), s)
                s.ready.set()
                if all(t.ready.is_set() for t in self.streams):
                    self.all_ready.set()
            else:
                if s.config is not None:
                    s.clock.frame(c3.frame_time(x, s.config.time_base), arrival)
                self.emit(s.on_data(x), s)
                if self.inertia is not None and s.released is not None:
                    self._inertia_lines(self.inertia.tick(s.released / s.rate), s)
            if isinstance(x, c3.DataFrame) and len(self.processing) < MAX_TIMINGS:
                self.processing.append(time.perf_counter() - t0)
                self.processing_cpu.append(time.thread_time() - c0)
        elif kind == "counts":
            s.decoder_now = x
        elif kind == "down":
            s.counts["disconnects"] += 1
        elif kind == "refused":
            s.counts["connect_failures"] += 1
        elif kind == "up":
            for name, n in s.decoder_now.items():       # the last connection's counts, kept
                s.decoder_done[name] += n
            s.decoder_now = {}
            s.clock.restart()
            if s.counts["disconnects"] + s.counts["connect_failures"]:
                self.log(f"stream {k}: reconnected to {x}")

    def _inertia_lines(self, lines: list[dict], stream: _Stream | None = None):
        """The system inertia's lines to ``updates.jsonl``; the floor's alarm in the log; the
        delay from a line's time to its emission on ``stream``'s clock (``inertia_delay_s``)."""
        if not lines:
            return
        if stream is not None and len(self.inertia_delays) < MAX_TIMINGS:
            now = stream.clock.now(time.monotonic())
            if now is not None:
                times = sorted({x["t"] for x in lines})
                self.inertia_delays.extend(now - t for t in times)
                self.inertia_times.extend(times)
        if self._jsonl is not None:
            self._jsonl.write("".join(json.dumps(x) + "\n" for x in lines))
            self._jsonl.flush()
        if self.view is not None:
            self.view.add_inertia(lines)
        if self.publisher is not None:
            by_t = defaultdict(list)
            for x in lines:
                by_t[x["t"]].append(x)
            for t in sorted(by_t):
                self.publisher.publish_inertia(t, by_t[t])
        floor = self.cfg.inertia.floor_MWs
        for a in self.inertia.latest:
            was = self.inertia_alarms.get(a.area, False)
            if a.below_floor and not was:
                self.log(f"ALARM inertia {a.area}: E {a.E_MWs / 1e3:.4g} GW s below the floor {floor / 1e3:g} GW s "
                         f"at {_utc(lines[0]['t'])}")
            elif was and not a.below_floor:
                self.log(f"alarm cleared inertia {a.area}: E {a.E_MWs / 1e3:.4g} GW s at {_utc(lines[0]['t'])}")
            self.inertia_alarms[a.area] = bool(a.below_floor)

    def _delays(self, recent: int | None = None) -> dict:
        """The delays from a frame's timestamp to its estimate: in stream time and in wall time."""
        out = {}
        for key, d in (("delay_s", self.delays), ("wall_delay_s", self.wall_delays),
                       ("monitor_s", self.monitor_s)):
            d = np.asarray(d if recent is None else d[-recent:])
            out[key] = None if d.size == 0 else {"median": float(np.median(d)), "p99": float(np.quantile(d, 0.99)),
                                                 "max": float(d.max())}
        return out

    def _status(self) -> dict:
        """The streams' counts and the recent delay, for the live view (its thread)."""
        return {"streams": [{"stream": s.k, "host": s.spec.host, "port": s.spec.port, "pace": s.clock.pace,
                             **dict(s.counts)} for s in self.streams],
                **self._delays(recent=2000)}

    def _finish(self, wall_s: float) -> dict:
        summary = {
            "wall_s": round(wall_s, 3), "updates": self.updates,
            **self._delays(),
            "processing_ms_per_frame": _percentiles(1e3 * np.asarray(self.processing)),
            "processing_cpu_ms_per_frame": _percentiles(1e3 * np.asarray(self.processing_cpu)),
            "catch_up_s": round(self.catch_up_s, 3),
            "streams": [{"stream": s.k, "host": s.spec.host, "port": s.spec.port, "pace": s.clock.pace,
                         **dict(s.counts), "decoder": s.decoder(),
                         "unusable_samples": {u.name: int(n) for u, n in zip(s.units, s.unusable) if n},
                         "stale_samples": {u.name: int(n) for u, n in zip(s.units, s.stale) if n}}
                        for s in self.streams],
            "published": None if self.publisher is None else dict(self.publisher.stats),
            "latest": {name: update_line(u, self.alarms.get(name, False)) for name, u in self.latest.items()},
            "inertia_delay_s": None if not self.inertia_delays else {
                "median": float(np.median(self.inertia_delays)), "p99": float(np.quantile(self.inertia_delays, 0.99)),
                "max": float(np.max(self.inertia_delays))},
            "inertia": None if self.inertia is None else [
                {**a.line(None), "rocof_ci95": a.rocof_ci95, "rocof_reason": a.rocof_reason,
                 "units_stale": a.units_stale, "units_without_h": a.units_without_h, "below_floor": a.below_floor}
                for a in self.inertia.latest],
            "notes": list(self.cfg.notes),
            "counters": {**SUMMARY_KEYS, **COUNTS, **UNIT_COUNTS, "decoder": DECODER_COUNTS},
        }
        if self.out_dir is not None:
            parts = [p for s in self.streams for p in s.parts if p["index0"] is not None]
            if self.cfg.record:
                (self.out_dir / "replay.toml").write_text(replay_toml(self.cfg, parts))
            (self.out_dir / "monitor.json").write_text(json.dumps(summary, indent=1))
        return summary


def _percentiles(x: np.ndarray) -> dict | None:
    if x.size == 0:
        return None
    return {"frames": int(x.size), "median": float(np.median(x)), "p99": float(np.quantile(x, 0.99)),
            "mean": float(x.mean()), "max": float(x.max())}


def _utc(t: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(t)) + f".{int(round((t % 1) * 1000)) % 1000:03d} UTC"


# --- the recording, read back --------------------------------------------------------------------

def replay_toml(cfg: MonitorConfig, parts: list[dict]) -> str:
    """The file that ``jaxdse run`` reads to replay the recorded stream."""
    lines = ["# The stream as the monitor used it; replay it with", "#   jaxdse run replay.toml --out DIR",
             "# (the same windowed identification, from the file readers: its updates.jsonl equals the "
             "live one's)", "", "[replay]", f"monitor = {json.dumps(str(cfg.path))}", ""]
    for p in parts:
        lines += ["[[replay.part]]", f"file = {json.dumps(p['file'])}", f"stream = {p['stream']}",
                  f"frame_rate_hz = {p['frame_rate_hz']!r}", f"index0 = {p['index0']}",
                  f"units = {json.dumps(p['units'])}", ""]
    return "\n".join(lines)


def replay_recording(path, units_of, out_dir: Path | None = None, log=None) -> list[dict]:
    """``jaxdse run REPLAY.toml``: the recorded stream through the file readers and the same
    windowed identification; writes ``updates.jsonl`` to ``out_dir`` and returns its lines.
    ``units_of``: as for :func:`load_monitor`."""
    from .._io.measurement import read_measurement

    path = Path(path)
    data = read_toml(path)
    rp = subtable(path, data, "replay", "replay")
    cfg = load_monitor(Path(rp["monitor"]), units_of)
    est = cfg.source_units
    by_name = {u.name: u for u in cfg.units}
    lines = []
    for k, part in enumerate(rp.get("part", [])):
        units = [by_name[n] for n in part["units"]]
        rate = float(part["frame_rate_hz"])
        series = []
        for u in units:
            spec = dataclasses.replace(
                u.run.measurement, file=(str(path.parent / part["file"]),), format="csv",
                columns={"time": "time_s", "v_mag": f"{u.name}/VM", "v_ang": f"{u.name}/VA",
                         "i_mag": f"{u.name}/IM", "i_ang": f"{u.name}/IA", "frequency": f"{u.name}/F",
                         "stat": f"{u.name}/STAT"},
                voltage_unit="pu", current_unit="pu", angle_unit="rad", time_unit="s", time_format=None,
                timezone=None, frequency_unit="Hz", frequency_kind="absolute", v_base_kv=None,
                current_direction="out_of_plant", frame_rate_hz=rate, on_long_gap="split", screen_samples=False,
                min_segment_s=0.0, csv_options=dataclasses.replace(u.run.measurement.csv_options, delimiter=","))
            try:
                segments, _ = read_measurement(spec, u.run.plant.machine)
            except InputError as err:
                (log or print)(f"{u.name}: not replayed ({err})")
                segments = []
            series.append([(int(part["index0"]) + round(t0 * rate), r) for t0, r in segments])
        starts = [i0 for s in series for i0, _ in s]
        if not starts:
            continue
        lo = min(starts)
        hi = max(i0 + int(np.shape(r.t_s)[0]) for s in series for i0, r in s)
        table = np.full((5, len(units), hi - lo), np.nan)
        usable = np.zeros((len(units), hi - lo), bool)
        for j, s in enumerate(series):
            for i0, r in s:
                sl = slice(i0 - lo, i0 - lo + int(np.shape(r.t_s)[0]))
                f = np.full(np.shape(r.t_s), np.nan) if r.f_hz is None else np.asarray(r.f_hz)
                table[:, j, sl] = [np.asarray(r.v_mag_pu), np.asarray(r.v_ang_rad), np.asarray(r.i_mag_pu),
                                   np.asarray(r.i_ang_rad), f]
                usable[j, sl] = True
        groups = make_groups(units, rate, cfg, est, cfg.streams[int(part["stream"])].frequency == "stream")
        for c in range(hi - lo):
            for group, members in groups:
                for u in group.push(lo + c, *table[:, members, c], usable[members, c]):
                    lines.append(update_line(u, False))
    if out_dir is not None:
        out_dir = Path(out_dir)
        out_dir.mkdir(parents=True, exist_ok=True)
        (out_dir / "updates.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    return lines
