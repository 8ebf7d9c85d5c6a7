"""STTP (IEEE 2664) for ``jaxdse monitor``, through the optional package ``sttpapi`` (the Grid
Protection Alliance's MIT library, imported as ``sttp``): ``pip install jaxdse[sttp]``.

Nothing here imports ``sttp`` at module level: the package imports, and C37.118 works, without
it; a monitor file that asks for STTP without it is refused in one line (:func:`require`).

**Input** (``[[stream]] protocol = "sttp"``, :func:`reader`): one thread per stream subscribes to
an STTP publisher (TCP, default port 7165) and turns its measurements into the data frames that
the C37.118 path feeds, so that everything after it (grid placement, the reorder buffer,
screening, the units' estimators, the recording) is shared. Point tags, per station (the
unit's name, or its name in ``[stream.stations]``; matched without regard to case)::

    <station>:V1_MAG   positive-sequence voltage magnitude  (V phase to neutral, or pu: the
    <station>:V1_ANG   ... its angle [degrees]               units jaxdse pmu-sim serves, i.e.
    <station>:I1_MAG   positive-sequence current magnitude   pu where the measurement gives no
    <station>:I1_ANG   ... its angle [degrees]               v_base_kv; current out of the plant
                                                             unless current_direction says so)
    <station>:FREQ     frequency [Hz]                        (optional)
    <station>:STAT     the C37.118 STAT word of the station  (optional; 0 when absent)

The subscription asks for exactly these tags (``FILTER ActiveMeasurements WHERE PointTag IN
(...)``). A station is served when its publisher's metadata has the four phasor tags. The
reporting rate is the [[stream]]'s ``frame_rate_hz`` or, when that is 0, the stations' devices'
``FramesPerSecond`` in the metadata (a whole number of frames a second; sttpapi reads 30 where
the metadata gives none). Measurements come point by point, each with its own timestamp (100 ns
ticks): a timestamp within 1 ms of a point of the reporting grid is placed on it (publishers
that send millisecond timestamps), others are dropped and counted; the points of one grid point
make one frame, released when every subscribed point has come or when a frame ``reorder_s``
newer has (a missing V1 or I1 point makes that unit's sample unusable; a missing FREQ is derived
from the angle). A point whose STTP quality flags say bad data, bad time, over- or under-range,
or received as bad sets a data error in its station's STAT (the sample is not used; a bad FREQ
is only dropped). A new metadata set from the publisher (its configuration changed) that changes
the stations' points or the rate is a configuration change: the stations are re-mapped and their
estimators restarted, as for C37.118, and the reader connects again (:class:`_Resubscribe`). The
connection is made again with the monitor's back-off when it drops or stays silent
``timeout_s``.

**Output** (``[publish] protocol = "sttp"``, :class:`SttpPublisher`): an STTP publisher (default
port 7166, 127.0.0.1 unless ``host`` says otherwise: sttpapi's own ``start`` binds every
interface, so the listening socket is made here) with one device per unit and the measurements
``<unit>:H``, ``<unit>:H_LO``, ``<unit>:H_HI`` (the 95 % interval) [s], ``<unit>:D`` [pu torque
per rad/s], ``<unit>:AGE`` [s], ``<unit>:STATE`` (the verdict: 0 identified, 1 weakly
identified, 2 not excited, 3 failed) and ``<unit>:ALARM`` (1 while the unit's H alarm is on),
stamped with the window's last frame's time. With ``[inertia]``, one more device per area and
one for the system, ``E <area>`` (``E system``), with ``E <area>:E``, ``:E_LO``, ``:E_HI``
[MW s], ``:SHARE``, ``:E_COMMIT`` [MW s], ``:ROCOF`` [Hz/s], ``:ONLINE``, ``:MEASURED`` (the
updates.jsonl area line's fields, stamped with its time) and ``:ALARM`` (1 while E is below the
floor; ALARMLOW on ``E`` too). Their signal IDs are name-based UUIDs of the point
tags (the same every run); all carry STTP's CALCULATEDVALUE flag. Values are NaN, with STTP's
BADDATA flag, where the window did not identify H (not excited, failed); weakly identified ones
carry SUSPECTDATA; an H alarm sets ALARMLOW on H. STTP carries values as 32-bit floats. At most
16 subscribers; updates queue for a sending thread, and beyond 256 waiting (a subscriber that
does not read) they are dropped and counted.

:class:`SttpServer` serves a recording (:class:`~.pmu_sim.Source`) over STTP with the input's
point tags: a loopback STTP PMU for tests.
"""

from __future__ import annotations

import math
import queue
import socket
import threading
import time
import uuid
from collections import deque
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from .._io.errors import InputError
from . import c37118 as c3
from .publish import AREA_ANALOGS, area_station, area_values, published_values
from .waits import Backoff, join, put, wait_ready

DEFAULT_PORT = 7165
"""The input's default port (a [[stream]] with protocol = "sttp" and no port)."""
PUBLISH_PORT = 7166
"""The default port of ``[publish] protocol = "sttp"`` (beside an STTP input on 7165)."""
MISSING = 'protocol "sttp" needs the optional extra: pip install jaxdse[sttp]'
TICKS_PER_S = 10_000_000
UNIX_TICKS = 621_355_968_000_000_000
"""Ticks (100 ns since 0001-01-01) of 1970-01-01T00:00:00Z."""
VALUE_MASK = (1 << 62) - 1
"""A timestamp's ticks without its leap-second flags."""
GRID_TOLERANCE_TICKS = 10_000
"""A point within 1 ms of a grid point is on it."""
CHANNELS = ("V1_MAG", "V1_ANG", "I1_MAG", "I1_ANG", "FREQ", "STAT")
REQUIRED = 4
"""A station needs the first four channels (its V1 and I1)."""
SIGNAL_TYPES = ("VPHM", "VPHA", "IPHM", "IPHA", "FREQ", "FLAG")
OUTPUTS = ("H", "H_LO", "H_HI", "D", "AGE", "STATE", "ALARM")
STATE = {"identified": 0, "weakly identified": 1, "not excited": 2, "failed": 3}
MAX_CLIENTS = 16
MAX_QUEUED = 256
"""Updates (one list of measurements each) waiting for the publisher's sending thread."""
MAX_INBOX = 10_000
"""Packets of measurements waiting for a reader thread."""
MAX_PENDING = 4096
"""Frames a reader assembles at once."""
NAMESPACE = uuid.UUID("6f1f5b8e-4a43-5d2e-9a3e-6a7864736531")
"""Of the published signal IDs: uuid5(NAMESPACE, point tag)."""

# STTP StateFlags (sttp.transport.constants.StateFlags), as plain integers
BADDATA, SUSPECTDATA, OVERRANGE, UNDERRANGE, ALARMLOW = 0x1, 0x2, 0x4, 0x8, 0x20
RECEIVEDASBAD, CALCULATED, CALCULATIONERROR, BADTIME = 0x800, 0x1000, 0x2000, 0x10000
BAD_FLAGS = BADDATA | OVERRANGE | UNDERRANGE | RECEIVEDASBAD | BADTIME
STAT_BAD_QUALITY = c3.Stat(data_error=c3.PMU_ERROR_NO_INFO).word
"""STAT data error 01 (PMU error, no information about the data): a point with bad quality flags."""


def available() -> bool:
    """Whether ``sttpapi`` imports."""
    try:
        import sttp  # noqa: F401
    except ImportError:
        return False
    return True


def require(path, key: str):
    """Raise the one-line :class:`InputError` of a missing ``sttpapi``."""
    if not available():
        raise InputError(path, MISSING, key=key)


# --- time ------------------------------------------------------------------------------------------

def ticks_of_time(t: float) -> int:
    """STTP ticks of ``t`` [s since 1970] (integer arithmetic past the second: float64 ticks are
    not exact)."""
    soc = math.floor(t)
    return UNIX_TICKS + soc * TICKS_PER_S + min(round((t - soc) * TICKS_PER_S), TICKS_PER_S - 1)


def ticks_of_index(index: int, rate: int) -> int:
    """STTP ticks of grid point ``index`` at ``rate`` frames/s (C37.118's rounding of FRACSEC)."""
    soc, frac = c3.grid_time(index, TICKS_PER_S, rate)
    return UNIX_TICKS + soc * TICKS_PER_S + frac


def grid_point(ticks: int, rate: int) -> int | None:
    """The grid index within :data:`GRID_TOLERANCE_TICKS` of ``ticks``, or None."""
    t = (int(ticks) & VALUE_MASK) - UNIX_TICKS
    if t < 0:
        return None
    index = (2 * t * rate + TICKS_PER_S) // (2 * TICKS_PER_S)
    return index if abs(ticks_of_index(index, rate) - UNIX_TICKS - t) <= GRID_TOLERANCE_TICKS else None


# --- metadata --------------------------------------------------------------------------------------

def _template() -> str:
    """sttpapi's metadata template (its XML schema), without its commented example."""
    import sttp

    text = (Path(sttp.__file__).parent / "MetadataTemplate.xml").read_text()
    a, b = text.find("<!--"), text.find("-->")
    return text if a < 0 or b < 0 else text[:a] + text[b + 3:]


def metadata_xml(devices: list[tuple[str, int]], points: list[tuple[str, str, uuid.UUID, str, str]]) -> str:
    """A metadata set: ``devices`` (acronym, frames per second) and ``points`` (device acronym,
    point tag, signal ID, signal type acronym, description)."""
    text = _template()
    rows = []
    for acronym, fps in devices:
        rows.append("<DeviceDetail>" + "".join(f"<{k}>{escape(str(v))}</{k}>" for k, v in (
            ("UniqueID", uuid.uuid5(NAMESPACE, "device:" + acronym)), ("IsConcentrator", "false"),
            ("Acronym", acronym), ("Name", acronym), ("AccessID", 0), ("ProtocolName", "STTP"),
            ("FramesPerSecond", fps), ("Enabled", "true"))) + "</DeviceDetail>")
    count = {}
    for device, tag, signal, kind, description in points:
        count[device] = count.get(device, 0) + 1
        rows.append("<MeasurementDetail>" + "".join(f"<{k}>{escape(str(v))}</{k}>" for k, v in (
            ("DeviceAcronym", device), ("ID", f"{device}:{count[device]}"), ("SignalID", signal),
            ("PointTag", tag), ("SignalReference", tag.replace(":", "-")), ("SignalAcronym", kind),
            ("Description", description), ("Internal", "true"), ("Enabled", "true")))
            + "</MeasurementDetail>")
    at = text.index("<SchemaVersion>")
    return text[:at] + "\n".join(rows) + "\n  " + text[at:]


def signal_id(tag: str) -> uuid.UUID:
    return uuid.uuid5(NAMESPACE, tag)


class _Listener:
    """An sttpapi ``Publisher`` that listens on one host (its own ``start`` binds every
    interface), with bounded clients, a sending thread and a bounded queue."""

    def __init__(self, xml: str, host: str, port: int, log, stats: dict):
        from sttp import Publisher
        from sttp.data.dataset import DataSet

        self.host, self.port, self.log, self.stats = host, port, log, stats
        self.pub = Publisher()
        self.pub.statusmessage_logger = None
        self.pub.errormessage_logger = self._error
        self.stats.setdefault("errors", 0)
        self.last_error = None
        self.pub.clientconnected_receiver = None
        self.pub.clientdisconnected_receiver = None
        self.pub.maximum_allowed_connections = MAX_CLIENTS
        dataset, err = DataSet.from_xml(xml)
        if err is not None:
            raise ValueError(f"STTP metadata: {err}")
        self.pub.define_metadata(dataset)
        self.queue: queue.Queue = queue.Queue(maxsize=MAX_QUEUED)
        self.sock = None
        self.bound = None
        self._sender = threading.Thread(target=self._send_loop, daemon=True, name="jaxdse-sttp-send")

    def _error(self, message):
        """sttpapi's publisher reports a client's failures (and its own) here: counted."""
        self.stats["errors"] += 1
        self.last_error = str(message)

    def start(self):
        dp = self.pub._datapublisher
        needed = ("_server_socket", "_accept_connections", "_started", "_stopped", "_shuttingdown", "_port")
        if not all(hasattr(dp, a) for a in needed):
            raise OSError("this sttpapi version cannot listen on one host: need sttpapi 0.7.6")
        ipv6 = ":" in self.host
        sock = socket.create_server((self.host, self.port),
                                    family=socket.AF_INET6 if ipv6 else socket.AF_INET)
        self.sock = sock
        dp._port = np.uint16(sock.getsockname()[1])
        dp._ipv6 = ipv6
        dp._server_socket = sock
        dp._started, dp._stopped, dp._shuttingdown = True, False, False
        dp._accept_thread = threading.Thread(target=dp._accept_connections, daemon=True,
                                             name="jaxdse-sttp-accept")
        dp._accept_thread.start()
        self._sender.start()
        self.bound = sock.getsockname()[:2]
        return self.bound

    def put(self, measurements) -> bool:
        try:
            self.queue.put_nowait(measurements)
        except queue.Full:
            self.stats["dropped_slow_client"] += 1
            return False
        return True

    def _send_loop(self):
        while True:
            ms = self.queue.get()
            if ms is None:
                return
            try:
                self.pub.publish_measurements(ms)
                self.stats["sent"] += len(ms)
            except Exception as err:  # noqa: BLE001 (a client's failure is not the monitor's)
                self.log(f"STTP publish: {err}")

    def stop(self):
        if self._sender.is_alive():
            try:
                self.queue.put(None, timeout=2.0)
            except queue.Full:
                self.log("STTP publish: the sending thread took no update for 2 s (a subscriber that "
                         "does not read?)")
            join(self._sender, 5.0, "sending the queued updates to the subscribers", self.log)
        dp = self.pub._datapublisher
        if self.sock is not None:
            dp._started, dp._shuttingdown = False, True     # the accepting thread ends ...
            try:
                self.sock.shutdown(socket.SHUT_RDWR)        # ... woken from accept()
            except OSError:
                pass
        self.pub.dispose()

    @property
    def clients(self) -> int:
        return len(self.pub.subscriber_connections)


# --- output: the monitor's results -------------------------------------------------------------------

class SttpPublisher:
    """The monitor's updates as STTP measurements (see the module docstring); the interface of
    :class:`~.publish.Publisher`: :meth:`start`, :meth:`publish` (any thread), :meth:`stop`."""

    def __init__(self, units: list[str], *, host: str = "127.0.0.1", port: int = PUBLISH_PORT,
                 idcode: int = 0, update_s: float = 1.0, f_nominal_hz: int = 50, log=None, areas=(),
                 floor_MWs: float | None = None):
        self.units, self.host, self.port, self.idcode = list(units), host, port, idcode
        self.floor_MWs = floor_MWs
        self.area_ids = {a: [signal_id(f"{area_station(a)}:{o}") for o in (*AREA_ANALOGS, "ALARM")] for a in areas}
        self.log = log or (lambda line: None)
        fps = max(1, round(1.0 / update_s))
        self.ids = {u: [signal_id(f"{u}:{o}") for o in OUTPUTS] for u in self.units}
        points = [(u, f"{u}:{o}", sid, "ALRM" if o == "ALARM" else "CALC", description)
                  for u in self.units
                  for o, sid, description in zip(OUTPUTS, self.ids[u], (
                      "inertia constant H [s]", "H, lower end of the 95 % interval [s]",
                      "H, upper end of the 95 % interval [s]", "damping D [pu torque per rad/s]",
                      "age of the last identified H [s]",
                      "verdict: 0 identified, 1 weakly identified, 2 not excited, 3 failed",
                      "1 while the H alarm is on"))]
        points += [(area_station(a), f"{area_station(a)}:{o}", sid, "ALRM" if o == "ALARM" else "CALC", description)
                   for a in self.area_ids
                   for o, sid, description in zip((*AREA_ANALOGS, "ALARM"), self.area_ids[a], (
                       "stored kinetic energy E [MW s]", "E, lower end of the 95 % interval [MW s]",
                       "E, upper end of the 95 % interval [MW s]", "measured share of E",
                       "commitment figure [MW s]", "rate of change of frequency after the largest loss [Hz/s]",
                       "units online", "units measured", "1 while E is below the floor"))]
        self.xml = metadata_xml([(u, fps) for u in self.units] + [(area_station(a), fps) for a in self.area_ids],
                                points)
        self.stats = {"frames": 0, "sent": 0, "dropped_slow_client": 0}
        self.bound = None
        self._listener = None

    def start(self):
        self._listener = _Listener(self.xml, self.host, self.port, self.log, self.stats)
        self.bound = self._listener.start()
        return self.bound

    def stop(self):
        if self._listener is not None:
            self._listener.stop()

    def measurements(self, t: float, updates, alarms: dict) -> list:
        """The STTP measurements of ``updates`` at ``t`` [s since 1970]."""
        from sttp.transport.measurement import Measurement

        ticks = np.uint64(ticks_of_time(t))
        out = []         # flags as np.uint32: sttpapi's TSSC encoder fails on a Python int >= 128
        for u in updates:
            ids = self.ids.get(u.unit)
            if ids is None:
                continue
            values = published_values(u)
            alarm = bool(alarms.get(u.unit, False))
            flags = CALCULATED | {"identified": 0, "weakly identified": SUSPECTDATA, "not excited": BADDATA,
                                  "failed": BADDATA | CALCULATIONERROR}[u.verdict]
            for k, v in enumerate(values):
                f = flags | (ALARMLOW if alarm and k == 0 else 0) | (BADDATA if v is None else 0)
                out.append(Measurement(ids[k], np.float64(math.nan if v is None else v), ticks, np.uint32(f)))
            out.append(Measurement(ids[5], np.float64(STATE[u.verdict]), ticks, np.uint32(CALCULATED)))
            out.append(Measurement(ids[6], np.float64(1.0 if alarm else 0.0), ticks, np.uint32(CALCULATED)))
        return out

    def inertia_measurements(self, t: float, lines: list[dict]) -> list:
        """The STTP measurements of the system inertia's ``lines`` at ``t`` [s since 1970]."""
        from sttp.transport.measurement import Measurement

        ticks = np.uint64(ticks_of_time(t))
        out = []
        for x in lines:
            ids = self.area_ids.get(x["area"])
            if ids is None:
                continue
            below = self.floor_MWs is not None and x["E_MWs"] < self.floor_MWs
            for k, v in enumerate(area_values(x)):
                f = CALCULATED | (ALARMLOW if below and k == 0 else 0) | (BADDATA if v is None else 0)
                out.append(Measurement(ids[k], np.float64(math.nan if v is None else v), ticks, np.uint32(f)))
            out.append(Measurement(ids[-1], np.float64(1.0 if below else 0.0), ticks, np.uint32(CALCULATED)))
        return out

    def publish_inertia(self, t: float, lines: list[dict]):
        """Queue the measurements of the system inertia's ``lines`` at ``t`` (thread-safe)."""
        self.stats["frames"] += 1
        if self._listener is not None:
            self._listener.put(self.inertia_measurements(t, lines))

    def publish(self, t: float, updates, alarms: dict):
        """Queue the measurements of ``updates`` at ``t`` for the subscribers (thread-safe)."""
        self.stats["frames"] += 1
        if self._listener is not None:
            self._listener.put(self.measurements(t, updates, alarms))


# --- a recording served over STTP (a loopback STTP PMU, for tests) --------------------------------

class SttpServer:
    """Serves a :class:`~.pmu_sim.Source` over STTP with the input's point tags, frame by frame
    on its reporting grid, the first frame at the next whole second of the wall clock (as
    ``jaxdse pmu-sim`` does), ``speed`` times faster than real time, from the first subscription
    on (``on_request``; else at once); until the recording ends (or ``duration`` s, or
    :meth:`stop`; ``loop``: again and again)."""

    def __init__(self, source, *, host: str = "127.0.0.1", port: int = DEFAULT_PORT, speed: float = 1.0,
                 loop: bool = False, duration: float | None = None, on_request: bool = True, log=None):
        self.source, self.speed, self.loop, self.duration = source, speed, loop, duration
        self.on_request = on_request
        self.log = log or (lambda line: None)
        self.generation = 0
        self.ids, xml = self._metadata()
        self.stats = {"frames": 0, "sent": 0, "dropped_slow_client": 0}
        self._listener = _Listener(xml, host, port, self.log, self.stats)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="jaxdse-sttp-server")
        self.bound = None

    def _metadata(self):
        """The signal IDs of the stations' points (new ones for each generation) and the metadata."""
        src, gen = self.source, f"#{self.generation}" if self.generation else ""
        ids = {st.name: [signal_id(f"{st.name}:{c}{gen}") for c in CHANNELS] for st in src.stations}
        points = [(st.name, f"{st.name}:{c}", sid, kind, f"{st.name} {c}")
                  for st in src.stations for c, sid, kind in zip(CHANNELS, ids[st.name], SIGNAL_TYPES)]
        return ids, metadata_xml([(st.name, src.rate) for st in src.stations], points)

    def reconfigure(self):
        """New signal IDs for every point, announced to the subscribers: a configuration change
        (as when a publisher's configuration is edited)."""
        from sttp.data.dataset import DataSet

        self.generation += 1
        ids, xml = self._metadata()
        dataset, err = DataSet.from_xml(xml)
        if err is not None:
            raise ValueError(f"STTP metadata: {err}")
        self._listener.pub.define_metadata(dataset)
        self.ids = ids

    def start(self):
        self.bound = self._listener.start()
        self._thread.start()
        return self.bound

    def stop(self):
        self._stop.set()
        join(self._thread, 5.0, "serving the recording's frames", self.log)
        self._listener.stop()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def frame(self, k: int, index: int) -> list:
        """The measurements of frame ``k`` of the recording at grid ``index``."""
        from sttp.transport.measurement import Measurement

        ticks = np.uint64(ticks_of_index(index, self.source.rate))
        out = []
        for st in self.source.stations:
            ids = self.ids[st.name]
            if st.present[k]:
                values = (abs(st.v[k]), math.degrees(np.angle(st.v[k])), abs(st.i[k]),
                          math.degrees(np.angle(st.i[k])), st.f[k], 0.0)
            else:
                values = (math.nan,) * 5 + (float(c3.Stat(data_error=c3.TEST_OR_ABSENT).word),)
            out += [Measurement(sid, np.float64(v), ticks, np.uint32(0)) for sid, v in zip(ids, values)]
        return out

    def _run(self):
        src = self.source
        while self.on_request and not any(c.is_subscribed for c in self._listener.pub.subscriber_connections):
            if self._stop.wait(0.02):
                return
        wall0, mono0 = time.time(), time.monotonic()
        first_second = math.floor(wall0) + 1
        first = first_second * src.rate + src.first_index % src.rate     # the recording's phase in the second
        present = np.flatnonzero(np.any([st.present for st in src.stations], axis=0))
        n_pass = 0
        while not self._stop.is_set():
            for k in present:
                k = int(k)
                t_stream = (n_pass * src.frames + k) / src.rate
                if self.duration is not None and t_stream / self.speed > self.duration:
                    return
                wait = mono0 + t_stream / self.speed - time.monotonic()
                if wait > 0 and self._stop.wait(wait):
                    return
                if self._stop.is_set():
                    return
                self.stats["frames"] += 1
                self._listener.put(self.frame(k, first + n_pass * src.frames + k))
            n_pass += 1
            if not self.loop:
                return


# --- input: a reader thread ------------------------------------------------------------------------

class Assembler:
    """STTP measurements -> C37.118 data frames of the stations (see the module docstring)."""

    def __init__(self, stations: list[str], points: dict, rate: int, hold: int, cfgcnt: int = 0):
        """``points``: signal ID -> (station index, channel index); ``hold``: frames a partial
        frame waits for its points once a newer frame has come."""
        self.stations, self.points = list(stations), dict(points)
        self.rate, self.hold = int(rate), max(1, hold)
        self.expected = len(self.points)
        self.config = c3.ConfigFrame(0, tuple(
            c3.StationConfig(name, j + 1, (c3.PhasorChannel("V1"), c3.PhasorChannel("I1", current=True)),
                             cfgcnt=cfgcnt) for j, name in enumerate(self.stations)), self.rate, TICKS_PER_S)
        self.pending: dict[int, list] = {}
        self.done: set[int] = set()
        self.done_order: deque[int] = deque()
        self.newest = None
        self.counts = {"unknown_points": 0, "points_off_grid": 0, "late_points": 0, "bad_quality_points": 0,
                       "incomplete_frames": 0}

    def add(self, measurements) -> list[c3.DataFrame]:
        """Take a packet of measurements; returns the frames it completes or releases."""
        out = []
        n_st = len(self.stations)
        for m in measurements:
            where = self.points.get(m.signalid)
            if where is None:
                self.counts["unknown_points"] += 1
                continue
            idx = grid_point(int(m.timestamp), self.rate)
            if idx is None:
                self.counts["points_off_grid"] += 1
                continue
            if idx in self.done or (self.newest is not None and idx <= self.newest - MAX_PENDING):
                self.counts["late_points"] += 1
                continue
            fr = self.pending.get(idx)
            if fr is None:
                if len(self.pending) >= MAX_PENDING:
                    out.append(self._release(min(self.pending)))
                # values, bad quality per station, points seen, how many
                fr = self.pending[idx] = [np.full((n_st, len(CHANNELS)), np.nan), np.zeros(n_st, bool),
                                          np.zeros((n_st, len(CHANNELS)), bool), 0]
            j, c = where
            if not fr[2][j, c]:
                fr[2][j, c] = True
                fr[3] += 1
            value = float(m.value)
            if int(m.flags) & BAD_FLAGS:
                self.counts["bad_quality_points"] += 1
                if CHANNELS[c] != "FREQ":
                    fr[1][j] = True
                value = math.nan if CHANNELS[c] == "FREQ" else value
            fr[0][j, c] = value
            self.newest = idx if self.newest is None else max(self.newest, idx)
            if fr[3] >= self.expected:
                out.append(self._release(idx))
        if self.newest is not None:
            for idx in sorted(i for i in self.pending if i <= self.newest - self.hold):
                out.append(self._release(idx))
        return out

    def flush(self) -> list[c3.DataFrame]:
        """Every partial frame, in grid order."""
        return [self._release(idx) for idx in sorted(self.pending)]

    def _release(self, idx: int) -> c3.DataFrame:
        values, bad, _, n = self.pending.pop(idx)
        if n < self.expected:
            self.counts["incomplete_frames"] += 1
        self.done.add(idx)
        self.done_order.append(idx)
        if len(self.done_order) > MAX_PENDING:
            self.done.discard(self.done_order.popleft())
        stat = np.where(np.isnan(values[:, 5]), 0, np.nan_to_num(values[:, 5])).astype(np.int64) & 0xFFFF
        stat = np.where(bad, stat | STAT_BAD_QUALITY, stat).astype(np.uint16)
        ph = np.stack([values[:, 0] * np.exp(1j * np.radians(values[:, 1])),
                       values[:, 2] * np.exp(1j * np.radians(values[:, 3]))], axis=1)
        n_st = len(self.stations)
        arrays = c3.StationArrays(stat, ph, values[:, 4].copy(), np.zeros(n_st), np.zeros((n_st, 0)),
                                  np.zeros((n_st, 0), np.uint16))
        soc, frac = c3.grid_time(idx, TICKS_PER_S, self.rate)
        return c3.DataFrame(0, soc=soc, fracsec=frac, arrays=arrays)


def filter_expression(stations: list[str]) -> str:
    """The subscription of the stations' point tags (no ';': sttpapi's publisher splits its
    connection string there)."""
    tags = [f"{s}:{c}".replace("'", "''") for s in stations for c in CHANNELS]
    return "FILTER ActiveMeasurements WHERE PointTag IN (" + ", ".join(f"'{t}'" for t in tags) + ")"


def mapping(records, stations: list[str], rate_hz: float):
    """From the publisher's measurement records: (stations served, signal ID -> (station,
    channel), frames per second); raises ValueError when the rate is unknown or not whole."""
    by_tag = {}
    for r in records:
        if r.pointtag:
            by_tag.setdefault(str(r.pointtag).upper(), r)
    served, points, rates = [], {}, set()
    for name in dict.fromkeys(stations):
        found = [by_tag.get(f"{name}:{c}".upper()) for c in CHANNELS]
        if any(r is None for r in found[:REQUIRED]):
            continue
        j = len(served)
        served.append(name)
        for c, r in enumerate(found):
            if r is not None:
                points[r.signalid] = (j, c)
        device = getattr(found[0], "device", None)
        if device is not None and getattr(device, "framespersecond", None):
            rates.add(int(device.framespersecond))
    if rate_hz > 0:
        rate = rate_hz
    elif len(rates) == 1:
        rate = rates.pop()
    elif not served:
        rate = 1
    else:
        raise ValueError("the stations' devices give no single FramesPerSecond "
                         f"({sorted(rates) or 'none'}): set the stream's frame_rate_hz")
    if abs(rate - round(rate)) > 1e-9 or round(rate) < 1:
        raise ValueError(f"frame_rate_hz = {rate:g}: a whole number of frames a second")
    return served, points, int(round(rate))


def reader(k: int, spec, out: queue.Queue, stop: threading.Event, log, ready, stations: list[str]):
    """One STTP stream's thread (the C37.118 reader's contract): puts (k, "frame", ConfigFrame
    or DataFrame, arrival), (k, "up" / "down" / "refused", text, arrival) and (k, "counts",
    dict, arrival) on ``out`` (``arrival``: ``time.monotonic()`` when the frame was complete);
    ``stations``: the station names to subscribe to. As for C37.118, the subscription (the data)
    starts once ``ready.wait`` says so (None: at once), or ``READY_S`` after the metadata came:
    a publisher does not wait for a subscriber whose main thread compiles."""
    backoff = Backoff()
    state = {"cfgcnt": -1, "layout": None}
    while not stop.is_set():
        session = _Session(k, spec, out, stations, state, ready, log)
        try:
            session.run(stop)
        except _Resubscribe:
            _close(session, log)
            log(f"stream {k} (STTP {spec.host}:{spec.port}): the publisher's configuration changed; "
                "connecting again")
            continue
        except (OSError, ConnectionError, TimeoutError, ValueError) as err:
            _close(session, log)
            if stop.is_set():
                break
            try:
                session.put("down" if session.up else "refused", f"{err}")
            except TimeoutError as full:
                log(f"stream {k}: {full}")
            if session.up:
                backoff.reset()
            log(f"stream {k} (STTP {spec.host}:{spec.port}): {err or type(err).__name__}; reconnecting in "
                f"{backoff.s:g} s")
            backoff.wait(stop)
            continue
        _close(session, log)


def _close(session, log):
    """Close a session; what it still hands over waits at most the stream's timeout_s."""
    try:
        session.close()
    except TimeoutError as err:
        log(f"stream {session.k}: the last frames of the connection were lost: {err}")


class _Resubscribe(Exception):
    """A configuration change within a connection: the reader connects again. (sttpapi 0.7.6's
    publisher keeps its TSSC compression state across a new subscription of the same client,
    whose subscriber starts a new one: no measurement is decoded after it; a new connection
    starts both afresh.)"""


class _Session:
    """One connection of :func:`reader`: the subscriber's callbacks put what they get in a
    bounded inbox, which the reader's thread empties."""

    def __init__(self, k, spec, out, stations, state, ready=None, log=print):
        from sttp import Subscriber

        self.k, self.spec, self.out, self.stations, self.state = k, spec, out, stations, state
        self.ready, self.log = ready, log
        self.inbox: queue.Queue = queue.Queue(maxsize=MAX_INBOX)
        self.lost = {"inbox_overflow": 0}
        self.errors: list[str] = []
        self.up = False
        self.asm: Assembler | None = None
        sub = self.sub = Subscriber()
        sub.statusmessage_logger = None
        sub.errormessage_logger = self._error
        sub.connectionestablished_receiver = None
        sub.connectionterminated_receiver = lambda: self._put(("down", None))
        sub.metadatanotification_receiver = lambda _dataset: self._put(("meta", None))
        sub.configurationchanged_receiver = sub.request_metadata     # then "meta", and a new subscription
        sub.set_newmeasurements_receiver(lambda ms: self._put(("data", ms)))

    def _error(self, message):
        lines = str(message).strip().splitlines()
        if lines:
            self.errors = self.errors[-9:] + [lines[0]]

    def _put(self, item):
        try:
            self.inbox.put_nowait(item)
        except queue.Full:
            self.lost["inbox_overflow"] += 1

    def put(self, kind: str, x):
        """(k, kind, x, arrival) on the monitor's queue, waiting at most the stream's timeout_s."""
        put(self.out, (self.k, kind, x, time.monotonic()), self.spec.timeout_s, "the monitor's main thread")

    def _frames(self, frames):
        for frame in frames:
            self.put("frame", frame)

    def run(self, stop: threading.Event):
        from sttp.config import Config
        from sttp.settings import Settings

        spec = self.spec
        # the subscription's settings, needed before the connection (without them no measurement
        # comes, tested); the subscription itself is sent below, once the estimators are ready
        self.sub.subscribe(filter_expression(self.stations), Settings())
        # one try (the reader backs off itself); retryinterval > 0: with 0, sttpapi 0.7.6's connector
        # resets its count of tries before each one and never gives up
        config = Config(maxretries=1, retryinterval=0.01, autoreconnect=False, socket_timeout=spec.timeout_s,
                        autosubscribe=False)        # subscribed below, once the estimators are ready
        err = self.sub.connect(f"{spec.host}:{spec.port}", config)
        if err is not None or not self.sub.connected:
            raise ConnectionError(f"cannot connect ({err or 'not connected'})")
        last = reported = time.monotonic()
        subscribed = False
        while not stop.is_set():
            try:
                kind, x = self.inbox.get(timeout=0.2)
            except queue.Empty:
                kind = x = None
            now = time.monotonic()
            if kind == "meta":
                self._metadata()
                if not subscribed:
                    wait_ready(self.ready, stop, self.log, self.k)
                    self.sub.subscribe(filter_expression(self.stations), Settings())
                    subscribed = True
                last = now = time.monotonic()
            elif kind == "data":
                last = now
                if self.asm is not None:
                    self._frames(self.asm.add(x))
            elif kind == "down":
                raise ConnectionError(self.errors[-1] if self.errors else
                                      "the publisher closed the connection")
            elif self.asm is not None and self.asm.pending and now - last > max(0.2, spec.reorder_s):
                self._frames(self.asm.flush())        # the stream paused: what came is used
            if now - last > spec.timeout_s:
                raise TimeoutError(f"no measurement for {spec.timeout_s:g} s")
            if self.asm is not None and now - reported > 0.2:
                self.put("counts", {**self.asm.counts, **self.lost})
                reported = now

    def _metadata(self):
        """(Re)map the stations from the publisher's metadata: a new configuration where the
        stations, their points or the rate changed."""
        served, points, rate = mapping(self.sub.metadatacache.measurement_records, self.stations,
                                       self.spec.frame_rate_hz)
        hold = math.ceil(self.spec.reorder_s * rate - 1e-9)
        layout = (served, sorted((str(a), b) for a, b in points.items()), rate)
        if self.asm is not None and layout == self.state["layout"]:
            return
        if layout != self.state["layout"]:
            self.state["cfgcnt"] += 1
            self.state["layout"] = layout
        new = Assembler(served, points, rate, hold, self.state["cfgcnt"])
        if self.asm is not None:               # a change within this connection
            self._frames(self.asm.flush())
            self.put("counts", {**self.asm.counts, **self.lost})
            self.asm = None
            self.put("frame", new.config)
            raise _Resubscribe()
        self.asm = new
        self.put("frame", self.asm.config)
        if not self.up:
            self.put("up", f"{self.spec.host}:{self.spec.port}")
            self.up = True

    def close(self):
        if self.asm is not None:
            self._frames(self.asm.flush())
            self.put("counts", {**self.asm.counts, **self.lost})
            self.asm = None
        self.sub.dispose()
