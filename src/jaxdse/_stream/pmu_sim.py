"""A loopback PMU (``jaxdse pmu-sim``) and a small client, over IEEE C37.118.2-2011.

The recording: a run configuration's [[generator]]s or a fleet file's plants, each read and
conditioned by jaxdse's own readers (``load_table``, ``condition``: units, gaps, screening),
so that the stream carries what ``jaxdse run`` or ``jaxdse fleet`` estimates from. Each
generator or plant is one station (PMU) of one concentrator stream (a PDC, 6.1): its
positive-sequence voltage ``V1`` and current ``I1`` (out of the plant) as phasors, FREQ
(measured, or derived from the voltage angle as a PMU does) and DFREQ. Phasors are in volts
(phase to neutral, RMS) and amperes where the measurement gives ``v_base_kv``, else in per
unit of the system base (:func:`served_units`; the header frame says which).

Timestamps lie on the reporting grid of the recording's time axis: frame k of a part is
stamped (SOC, FRACSEC) = :func:`~.c37118.grid_time` of grid index n0 + k at the recording's
frame rate, whole seconds shifted so that the stream starts now (``start="now"``), at the
recording's own time (``"recording"``) or at a given time. Parts between long gaps keep their
gap (no frames). A station without data at a frame (another plant's recording is longer) is
sent as absent data: NaN and STAT data error 10 (6.3.1). The whole recording is packed into
data blocks once, vectorised (it is in memory anyway, as for ``jaxdse run``); a frame then
costs its header and CRC. Read with float64 enabled (``jax_enable_x64``, as the CLI does), or
the recording is float32.

The server (asyncio, one thread) speaks the standard's command frames over TCP (6.6,
Table 15: data off, data on, send HDR, CFG-1, CFG-2, CFG-3; frames it does not understand
are silently discarded, 6.2) or UDP (Annex F.2.2), binds 127.0.0.1 unless told otherwise,
bounds its clients (16) and each client's send buffer (frames beyond it are dropped and
counted), and stops cleanly after ``duration`` seconds or at the recording's end.

Faults (:class:`Fault`, ``--fault KIND[=VALUE]@START[+DURATION][:STATION]``, times in
seconds of stream time from the first frame): every STAT state (``error``, ``pmu-error``,
``test``, ``absent``, ``sync``, ``sorting``, ``trigger[=REASON]``, ``config-bit``,
``modified``, ``time-quality[=CODE]``, ``unlocked[=CODE]``), the message time quality
(``clock[=CODE]``), dropped frames (``drop``), late frames (``late=SECONDS``: sent that much
later than due, so out of order), stale frames (``stale``: the values of the frame before
START repeated, with the timestamps and STAT running on, as a PDC that holds the last value
of a PMU it lost), a bad CRC (``crc``), a configuration change
(``config-change[=LEAD]``: STAT bit 10 for LEAD seconds, 60 by default, then a new
configuration with the phasor format switched between float and integer and CFGCNT + 1) and
a disconnect (``disconnect``: every client's connection closed).
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import heapq
import math
import re
import signal
import socket
import struct
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import NamedTuple

import numpy as np

from . import c37118 as c3
from .waits import join

MAX_CLIENTS = 16
SEND_BUFFER_BYTES = 1 << 20
"""A client's unsent bytes beyond which its data frames are dropped (and counted)."""
READ_CHUNK = 4096
DEFAULT_LEAD_S = 60.0
"""STAT bit 10 is set for a minute before a configuration change (6.3.1)."""
INT_HEADROOM = 1.25
"""Integer phasors: the scale puts the largest magnitude of the recording at 1/1.25 of 32767."""
UDP_MAX = 65507
MIN_STATION_BYTES = 14
"""The fewest bytes a station takes in a data frame (STAT 2, two integer phasors 8, integer FREQ
and DFREQ 4): more stations than FRAMESIZE (65535) allows at this size can never be served."""
RATE_TOLERANCE = 1e-3
"""A frame rate this close to a whole number of frames per second is that number: time columns
rounded to microseconds (0.033333 s) give 30.0003 frames/s over a short file."""


# --- the recording as stations on a frame grid ---------------------------------------------------

@dataclasses.dataclass
class Station:
    """One PMU station: its values at frames ``0 .. N-1`` of the source's grid."""

    name: str
    v: np.ndarray
    """Positive-sequence voltage [V phase-to-neutral RMS, or pu]; NaN where absent."""
    i: np.ndarray
    """Positive-sequence current out of the plant [A, or pu]."""
    f: np.ndarray
    """Frequency [Hz]."""
    rocof: np.ndarray
    """ROCOF [Hz/s]."""
    present: np.ndarray
    units: tuple[str, str]
    """Units of V1 and I1, as the header frame names them."""
    frequency: str
    """"measured" or "derived from the voltage angle"."""


@dataclasses.dataclass
class Source:
    """A recording as stations of one concentrator, on one frame grid."""

    path: Path
    stations: list[Station]
    rate: int
    """Frames per second."""
    first_index: int
    """Grid index (frames since 1970 at ``rate``) of frame 0 at the recording's own time."""
    f_nominal_hz: int
    notes: list[str]

    @property
    def frames(self) -> int:
        return int(self.stations[0].present.size)


def served_units(spec) -> tuple[float, float, str, str]:
    """(volts per pu, amperes per pu, unit of V1, unit of I1) of the phasors the simulator
    serves for a measurement ``spec``: V phase-to-neutral and A where ``v_base_kv`` is given,
    else per unit of the system base (a monitor divides by these to get per unit back)."""
    from .._io.measurement import current_base_a

    if spec.v_base_kv:
        amperes = float(current_base_a(spec.s_base_mva, spec.v_base_kv))
        return spec.v_base_kv * 1e3 / math.sqrt(3.0), amperes, "V", "A"
    return 1.0, 1.0, "pu", f"pu of {spec.s_base_mva:g} MVA"


class Units(NamedTuple):
    """The units of a run configuration or a fleet file, with the estimator's settings it gives
    (read by the application layer, ``jaxdse._app.sources.source_units``)."""

    runs: list
    """(name, :class:`~jaxdse._io.config.GeneratorRun`) per unit."""
    skipped: list
    """(name, reason) of a fleet's plants left out."""
    observer: object
    settings: object
    identify: object
    verdict: object
    case: object = None
    """A fleet file's case for the system inertia: (RawCase, DyrData, {unit: (bus, machine IDs)},
    the fleet file's [inertia] or None); None for a run configuration."""


def load_source(path, units: Units) -> Source:
    """Read the recording(s) of a run configuration or a fleet file with jaxdse's readers.

    Arguments:
        path: the run configuration or fleet file (named in messages).
        units: its units (:class:`Units`, as ``jaxdse._app.sources.source_units`` reads them:
            the application layer resolves a fleet file, this layer only serves it).

    A unit whose recording cannot be conditioned is left out with a note when others remain
    (as ``jaxdse fleet`` does); with none left, the first error is raised (InputError)."""
    from .._io.errors import InputError
    from .._io.measurement import condition, order_note
    from .._io.readers import load_table

    path = Path(path)
    runs, skipped = units.runs, units.skipped
    notes = [f"{name}: not served ({reason})" for name, reason in skipped]
    parts, first_error = [], None
    for name, spec, machine in ((name, g.measurement, g.plant.machine) for name, g in runs):
        try:
            table = load_table(spec.file, spec.format, csv_options=spec.csv_options,
                               time_column=spec.columns.get("time"))
            segments, quality = condition(table, spec, machine)
            parts.append((name, spec, segments, quality, _first_time(table, spec, quality)))
            if note := order_note(quality):
                notes.append(f"{name}: {note}")
        except InputError as err:
            first_error = first_error or err
            notes.append(f"{name}: not served ({err})")
    if not parts:
        raise first_error
    rates = {round(q["frame_rate_hz"], 6) for _, _, _, q, _ in parts}
    if len(rates) > 1:
        raise InputError(path, f"the units' recordings have different frame rates ({sorted(rates)} "
                         "frames/s): one C37.118 stream has one DATA_RATE")
    rate_f = rates.pop()
    rate = round(rate_f)
    if abs(rate_f - rate) > RATE_TOLERANCE * rate_f or rate < 1:
        raise InputError(path, f"{rate_f:g} frames/s: C37.118 reports a whole number of frames a second")
    fnoms = {float(spec.f_nominal_hz) for _, spec, _, _, _ in parts}
    if len(fnoms) > 1 or not fnoms <= {50.0, 60.0}:
        raise InputError(path, f"nominal frequency {sorted(fnoms)} Hz: C37.118's FNOM is 50 or 60 Hz")
    fnom = int(fnoms.pop())
    placed = []
    for name, spec, segments, _, t_first in parts:
        for start_s, rec in segments:
            x = (t_first + start_s) * rate
            n0 = round(x)
            if abs(x - n0) > 1e-3:
                notes.append(f"{name}: the part at {start_s:g} s is shifted by {(n0 - x) / rate * 1e3:.3f} "
                             "ms onto the reporting grid")
            placed.append((name, spec, n0, rec))
    lo = min(p[2] for p in placed)
    hi = max(p[2] + int(np.shape(p[3].t_s)[0]) for p in placed)
    if lo < 0:
        raise InputError(path, "the recording's time axis starts before 1970 (SOC is unsigned): use "
                         "--start now or a time")
    n = hi - lo
    stations = []
    for name, spec, _, _, _ in parts:
        v_per_pu, i_per_pu, v_unit, i_unit = served_units(spec)
        st = Station(name, np.full(n, np.nan, complex), np.full(n, np.nan, complex), np.full(n, np.nan),
                     np.full(n, np.nan), np.zeros(n, bool), (v_unit, i_unit), "measured")
        for pname, _, n0, rec in placed:
            if pname != name:
                continue
            k = slice(n0 - lo, n0 - lo + int(np.shape(rec.t_s)[0]))
            v_ang = np.asarray(rec.v_ang_rad)
            st.v[k] = np.asarray(rec.v_mag_pu) * np.exp(1j * v_ang) * v_per_pu
            st.i[k] = np.asarray(rec.i_mag_pu) * np.exp(1j * np.asarray(rec.i_ang_rad)) * i_per_pu
            derived = fnom + np.gradient(v_ang) * rate / (2 * np.pi)
            f = derived if rec.f_hz is None else np.where(np.isfinite(rec.f_hz), rec.f_hz, derived)
            if rec.f_hz is None:
                st.frequency = "derived from the voltage angle"
            st.f[k] = f
            st.rocof[k] = np.gradient(f) * rate
            st.present[k] = True
        stations.append(st)
    return Source(path, stations, rate, lo, fnom, notes)


def _first_time(table, spec, quality) -> float:
    """The recording's first time [s since 1970]: its first ISO timestamp (UTC where it names no
    zone), or the smallest number of its time column read as seconds since 1970."""
    start = quality.get("start_time")
    if start:
        import pandas as pd

        ts = pd.Timestamp(start)
        if ts.tzinfo is None:
            ts = ts.tz_localize("UTC")
        return ts.timestamp()
    raw = table.column(spec.columns["time"], "time").astype(float)
    return float(np.nanmin(raw)) * (1e-3 if spec.time_unit == "ms" else 1.0)


def tile(source: Source, copies: int) -> Source:
    """The stations repeated ``copies`` times (names ``name~2``, ...): many units from a few
    plants, for capacity tests."""
    if copies <= 1:
        return source
    more = [dataclasses.replace(s, name=s.name if k == 0 else f"{s.name}~{k + 1}")
            for k in range(copies) for s in source.stations]
    return dataclasses.replace(source, stations=more)


# --- the stream's configuration ------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Format:
    """FORMAT of the served stations (Table 9): each part integer or float on its own."""

    polar: bool = True
    phasor_float: bool = True
    freq_float: bool = True
    analog_float: bool = True

    @classmethod
    def parse(cls, text: str) -> Format:
        """"float" (polar floats), "int", or comma-separated words: polar|rect,
        phasor=int|float, freq=int|float, analog=int|float (e.g. "rect,phasor=int,freq=int")."""
        out = dict(polar=True, phasor_float=True, freq_float=True, analog_float=True)
        for word in (w.strip().lower() for w in text.split(",") if w.strip()):
            if word in ("float", "int"):
                out.update(phasor_float=word == "float", freq_float=word == "float",
                           analog_float=word == "float")
            elif word in ("polar", "rect", "rectangular"):
                out["polar"] = word == "polar"
            elif re.fullmatch(r"(phasor|freq|analog)=(int|float)", word):
                key, kind = word.split("=")
                out[f"{key}_float"] = kind == "float"
            else:
                raise ValueError(f"unknown format word {word!r}: use float, int, polar, rect, "
                                 "phasor=int|float, freq=int|float, analog=int|float")
        return cls(**out)


def stream_config(source: Source, fmt: Format, *, idcode: int = 1, cfgcnt: int = 0,
                  time_base: int = c3.DEFAULT_TIME_BASE, kind: int = c3.CFG2) -> c3.ConfigFrame:
    """The configuration of the served stream: one station per unit, ``V1`` and ``I1``."""
    stations = []
    short = short_names([s.name for s in source.stations])
    for k, st in enumerate(source.stations):
        sid = idcode if len(source.stations) == 1 else (idcode + k) % 65534 + 1
        scales = [_scale(st.v), _scale(st.i)]
        stations.append(c3.StationConfig(
            st.name if kind == c3.CFG3 else short[k], sid,
            (c3.PhasorChannel("V1", False, scales[0]), c3.PhasorChannel("I1", True, scales[1])),
            polar=fmt.polar, phasor_float=fmt.phasor_float, analog_float=fmt.analog_float,
            freq_float=fmt.freq_float, fnom_hz=source.f_nominal_hz, cfgcnt=cfgcnt,
            g_pmu_id=_gpmu_id(st.name), window_us=0, group_delay_us=0))
    return c3.ConfigFrame(idcode, tuple(stations), source.rate, time_base, kind=kind)


def _scale(z) -> float:
    """PHUNIT scale [units per count]: a whole number of 10^-5 that fits the largest magnitude."""
    top = np.nanmax(np.abs(z)) if np.isfinite(z).any() else 1.0
    return max(1, math.ceil(top * INT_HEADROOM / 32767 * 1e5)) * 1e-5


def short_names(names) -> list[str]:
    """CFG-1/2 station names: 16 bytes; distinct where the long names' first 16 are not."""
    out, seen = [], set()
    for k, name in enumerate(names):
        short = name.encode("latin-1", "replace")[:16].decode("latin-1")
        if short in seen:
            tag = f"~{k + 1}"
            short = short[:16 - len(tag)] + tag
        seen.add(short)
        out.append(short)
    return out


def _gpmu_id(name: str) -> bytes:
    import hashlib

    return hashlib.md5(name.encode("utf-8")).digest()


def header_text(source: Source, config: c3.ConfigFrame) -> str:
    """The header frame (6.5): where the stream comes from and what its channels hold."""
    lines = [f"jaxdse pmu-sim: {source.path.name}, {len(source.stations)} station(s) at {source.rate} "
             f"frames/s, FNOM {source.f_nominal_hz} Hz"]
    for st, sc in zip(source.stations, config.stations):
        lines.append(f"{st.name} (IDCODE {sc.idcode}): V1 positive-sequence voltage [{st.units[0]}"
                     f"{', phase to neutral, RMS' if st.units[0] == 'V' else ''}], I1 positive-sequence "
                     f"current out of the plant [{st.units[1]}], FREQ {st.frequency}")
    return "\n".join(lines)


def pack_frames(source: Source, config: c3.ConfigFrame, lo: int = 0, hi: int | None = None) -> np.ndarray:
    """Data blocks of frames ``lo .. hi-1`` as records of the configuration's data layout (one
    vectorised call per station); absent data: NaN and STAT data error 10."""
    hi = source.frames if hi is None else hi
    layout = c3.DataLayout.of(config)
    rec = np.zeros(hi - lo, layout.dtype)
    for k, (st, sc) in enumerate(zip(source.stations, config.stations)):
        sl = slice(lo, hi)
        stat = np.where(st.present[sl], 0, c3.TEST_OR_ABSENT << 14)
        z = np.stack([st.v[sl], st.i[sl]], axis=1)
        f = st.f[sl]
        rocof = st.rocof[sl]
        if not sc.freq_float:  # what the integer fields can carry (a PMU saturates too)
            f = np.clip(f, sc.fnom_hz - 32.767, sc.fnom_hz + 32.767)
            rocof = np.clip(rocof, -327.67, 327.67)
        layout.fill(rec, k, stat, z, f, rocof)
    return rec


# --- faults --------------------------------------------------------------------------------------

STAT_FAULTS = {
    "error": (0xC000, c3.PMU_ERROR << 14), "pmu-error": (0xC000, c3.PMU_ERROR_NO_INFO << 14),
    "test": (0xC000, c3.TEST_OR_ABSENT << 14), "absent": (0xC000, c3.TEST_OR_ABSENT << 14),
    "sync": (1 << 13, 1 << 13), "sorting": (1 << 12, 1 << 12), "trigger": (0x080F, 1 << 11),
    "config-bit": (1 << 10, 1 << 10), "modified": (1 << 9, 1 << 9), "time-quality": (0x01C0, 7 << 6),
    "unlocked": (0x0030, 3 << 4),
}
"""STAT fault -> (bits cleared, bits set); VALUE replaces the code of trigger (reason),
time-quality and unlocked."""
STREAM_FAULTS = ("clock", "drop", "late", "stale", "crc", "config-change", "disconnect")
FAULTS = tuple(STAT_FAULTS) + STREAM_FAULTS


@dataclasses.dataclass(frozen=True)
class Fault:
    """One injected fault: ``KIND[=VALUE]@START[+DURATION][:STATION]`` (seconds of stream time)."""

    kind: str
    start_s: float
    duration_s: float = 0.0
    """0: the one frame at ``start_s``."""
    value: float | None = None
    station: str | None = None
    text: str = dataclasses.field(default="", compare=False)
    """As written on the command line (for messages)."""

    @classmethod
    def parse(cls, text: str) -> Fault:
        m = re.fullmatch(r"\s*([a-z-]+)(?:=([-+0-9.eE]+))?@([0-9.eE+-]+?)(?:\+([0-9.eE]+))?(?::(.+))?\s*",
                         text)
        if not m:
            raise ValueError(f"fault {text!r}: write KIND[=VALUE]@START[+DURATION][:STATION], e.g. "
                             "error@10+5, drop@30+2, late=0.5@40+1, crc@50, config-change@60, disconnect@70")
        kind, value, start, dur, station = m.groups()
        if kind not in FAULTS:
            raise ValueError(f"fault {text!r}: unknown kind {kind!r}; one of {', '.join(FAULTS)}")
        if kind == "late" and value is None:
            raise ValueError(f"fault {text!r}: late needs its delay, e.g. late=0.5@40+1")
        value_f = float(value) if value is not None else None
        limits = {"trigger": 15, "time-quality": 7, "unlocked": 3, "clock": 15}
        if kind in limits and value_f is not None and not (value_f.is_integer()
                                                             and 0 <= value_f <= limits[kind]):
            raise ValueError(f"fault {text!r}: {kind}'s code is a whole number 0-{limits[kind]}")
        try:
            start_s, duration_s = float(start), float(dur) if dur is not None else 0.0
        except ValueError:
            raise ValueError(f"fault {text!r}: START and DURATION are seconds, e.g. drop@30+2") from None
        if not (math.isfinite(start_s) and start_s >= 0):
            raise ValueError(f"fault {text!r}: starts at {start:s} s; START is seconds of stream time "
                             "from the first frame, >= 0")
        if dur is not None and not (math.isfinite(duration_s) and duration_s > 0):
            raise ValueError(f"fault {text!r}: lasts {dur} s; give DURATION > 0, or leave +DURATION "
                             "out for the one frame at START")
        if kind == "late" and not (math.isfinite(value_f) and value_f > 0):
            raise ValueError(f"fault {text!r}: late={value}: the delay is seconds > 0")
        if value is not None and kind not in (*limits, "late", "config-change"):
            raise ValueError(f"fault {text!r}: {kind} takes no value (write {kind}@{start}...)")
        if kind == "config-change" and value_f is not None and not (math.isfinite(value_f) and value_f >= 0):
            raise ValueError(f"fault {text!r}: config-change={value}: the lead is seconds >= 0")
        return cls(kind, start_s, duration_s, value_f, station, text.strip())

    def covers(self, t: float, half_frame: float) -> bool:
        if self.duration_s <= 0:
            return abs(t - self.start_s) <= half_frame
        return self.start_s - 1e-9 <= t < self.start_s + self.duration_s - 1e-9

    def stat_bits(self) -> tuple[int, int]:
        clear, bits = STAT_FAULTS[self.kind]
        if self.value is not None:
            code = int(self.value)
            bits = {"trigger": 1 << 11 | code, "time-quality": code << 6,
                    "unlocked": code << 4}.get(self.kind, bits)
        return clear, bits


# --- the server -----------------------------------------------------------------------------------

class _Client:
    """One TCP connection or UDP address."""

    def __init__(self, writer=None, addr=None):
        self.writer, self.addr = writer, addr
        self.on = False
        self.sent = self.dropped = 0


async def answer_commands(reader, writer, answer):
    """Read a TCP client's frames until it closes, writing ``answer(frame)``'s frames back (a
    PMU's command handling, 6.6); a connection error ends it quietly."""
    decoder = c3.StreamDecoder(max_streams=4)
    try:
        while True:
            data = await reader.read(READ_CHUNK)
            if not data:
                break
            for frame in decoder.feed(data):
                for out in answer(frame):
                    writer.write(out)
            await writer.drain()
    except (ConnectionError, OSError):
        pass


async def serve_client(clients: list, reader, writer, command) -> bool:
    """One TCP client of a server that takes at most ``MAX_CLIENTS``: listed in ``clients`` while
    connected, its commands answered by ``command(client, frame)``. False (the connection closed
    at once) when the server is full."""
    if len(clients) >= MAX_CLIENTS:
        writer.close()
        return False
    client = _Client(writer=writer)
    clients.append(client)
    try:
        await answer_commands(reader, writer, lambda frame: command(client, frame))
    finally:
        if client in clients:
            clients.remove(client)
        writer.close()
    return True


class PmuServer:
    """Serves a :class:`Source` as one C37.118.2 stream (see the module docstring).

    ``await server.run()`` until the recording ends (without ``loop``), ``duration`` seconds
    pass or :meth:`stop` is called; :meth:`serve_in_thread` runs it beside a test."""

    def __init__(self, source: Source, *, host: str = "127.0.0.1", port: int = c3.TCP_PORT,
                 udp: bool = False, idcode: int = 1, fmt: Format = Format(), speed: float = 1.0,
                 loop: bool = False, duration: float | None = None, faults=(), start: str | float = "now",
                 on_request: bool = True, time_base: int = c3.DEFAULT_TIME_BASE, log=None):
        if not speed > 0:
            raise ValueError("speed must be positive")
        self.source, self.host, self.port, self.udp = source, host, port, udp
        self.idcode, self.fmt, self.speed, self.loop, self.duration = idcode, fmt, speed, loop, duration
        self.faults = tuple(faults)
        self.start, self.on_request, self.time_base = start, on_request, time_base
        self.log = log or (lambda line: None)
        for f in self.faults:
            if f.station is not None and f.station not in [s.name for s in source.stations]:
                raise ValueError(f"fault {f.kind}@{f.start_s:g}: no station {f.station!r}")
        self.configs = [stream_config(source, fmt, idcode=idcode, time_base=time_base)]
        self._names = [s.name for s in source.stations]
        if self.configs[0].data_size > c3.MAX_FRAME:
            raise ValueError(f"{len(source.stations)} stations make data frames of "
                             f"{self.configs[0].data_size} bytes, beyond FRAMESIZE's 65535: serve fewer")
        self.config_now = 0
        self.records = [pack_frames(source, self.configs[0])]
        self.clients: list[_Client] = []
        self.stats = {"frames": 0, "sent": 0, "dropped_by_fault": 0, "late": 0, "bad_crc": 0,
                      "dropped_slow_client": 0, "commands": 0, "disconnects": 0, "refused_clients": 0}
        self.bound: tuple[str, int] | None = None
        self._started = None
        self._stopping = None
        self._udp_transport = None
        self._ready = threading.Event()
        self._loop = None

    # configuration changes
    def _changed_config(self) -> int:
        """The configuration after a config-change fault: phasor format float <-> int, CFGCNT + 1."""
        old = self.configs[-1]
        fmt = dataclasses.replace(self.fmt, phasor_float=not old.stations[0].phasor_float)
        cfg = stream_config(self.source, fmt, idcode=self.idcode, cfgcnt=len(self.configs),
                            time_base=self.time_base)
        self.configs.append(cfg)
        self.records.append(pack_frames(self.source, cfg))
        return len(self.configs) - 1

    def config_frame(self, kind: int, now: float | None = None) -> list[bytes]:
        """The current configuration as CFG-1, CFG-2 or CFG-3 (full station names; in fragments
        where it exceeds a frame), stamped with the time of sending (6.2)."""
        soc, frac = self._wall_stamp(now)
        cfg = dataclasses.replace(self.configs[self.config_now], kind=kind, soc=soc, fracsec=frac)
        if kind == c3.CFG3:
            cfg = dataclasses.replace(cfg, stations=tuple(
                dataclasses.replace(sc, name=st.name) for sc, st in zip(cfg.stations, self.source.stations)))
            return c3.encode_cfg3_fragments(cfg, UDP_MAX if self.udp else c3.MAX_FRAME)
        return [c3.encode(cfg)]

    def header_frame(self) -> bytes:
        soc, frac = self._wall_stamp()
        return c3.encode(c3.HeaderFrame(self.idcode, header_text(self.source, self.configs[self.config_now]),
                                        soc, frac))

    def _wall_stamp(self, now=None) -> tuple[int, int]:
        now = time.time() if now is None else now
        soc = int(now)
        return soc, min(int((now - soc) * self.time_base), self.time_base - 1)

    # commands (6.6, Table 15)
    def _command(self, client: _Client, frame) -> list[bytes]:
        if not isinstance(frame, c3.CommandFrame) or frame.idcode != self.idcode:
            return []  # not understood, or another stream's: silently discarded (6.2)
        self.stats["commands"] += 1
        if frame.cmd == c3.CMD_OFF:
            client.on = False
        elif frame.cmd == c3.CMD_ON:
            client.on = True
            if self._started is not None and not self._started.is_set():
                self._started.set()
        elif frame.cmd == c3.CMD_HEADER:
            return [self.header_frame()]
        elif frame.cmd in c3.CFG_COMMANDS:
            try:
                return self.config_frame(c3.CFG_COMMANDS[frame.cmd])
            except ValueError as err:  # a CFG-1/2 of too many stations: CFG-3 only (fragments)
                self.log(f"cannot send {c3.FRAME_TYPES[c3.CFG_COMMANDS[frame.cmd]]}: {err}")
        return []

    async def _serve_tcp(self, reader, writer):
        if not await serve_client(self.clients, reader, writer, self._command):
            self.stats["refused_clients"] += 1

    class _Udp(asyncio.DatagramProtocol):
        def __init__(self, server):
            self.server = server
            self.decoder = c3.StreamDecoder(max_streams=4)

        def datagram_received(self, data, addr):
            server = self.server
            client = next((c for c in server.clients if c.addr == addr), None)
            if client is None:
                if len(server.clients) >= MAX_CLIENTS:
                    server.stats["refused_clients"] += 1
                    return
                client = _Client(addr=addr)
                server.clients.append(client)
            frame = self.decoder.feed_datagram(data)
            for out in server._command(client, frame):
                server._udp_transport.sendto(out, addr)

    def _send(self, data: bytes):
        for client in list(self.clients):
            if not client.on:
                continue
            if client.writer is not None:
                transport = client.writer.transport
                if transport.is_closing():
                    continue
                if transport.get_write_buffer_size() > SEND_BUFFER_BYTES:
                    client.dropped += 1
                    self.stats["dropped_slow_client"] += 1
                    continue
                client.writer.write(data)
            else:
                self._udp_transport.sendto(data, client.addr)
            client.sent += 1
            self.stats["sent"] += 1

    def _disconnect(self):
        self.stats["disconnects"] += 1
        for client in list(self.clients):
            if client.writer is not None:
                client.writer.transport.abort()
            self.clients.remove(client)

    # the clock
    def _offset(self, now: float) -> int:
        """Frames from the recording's grid index to the stream's."""
        src = self.source
        if self.start == "recording":
            return 0
        if self.start == "now":
            first_second = math.floor(now) + 1
            phase = src.first_index % src.rate
            return first_second * src.rate + phase - src.first_index
        return round(float(self.start) * src.rate) - src.first_index

    def _frame_bytes(self, k: int, index: int, t_stream: float, cfg_bit: bool = False):
        """Frame ``k`` of the recording at grid ``index``: its bytes (None: dropped) and the delay
        [s] a late-frame fault gives it; ``cfg_bit``: STAT bit 10 (a configuration change comes)."""
        half = 0.5 / self.source.rate
        tq, delay, bad_crc = 0, 0.0, False
        if not cfg_bit and not any(f.covers(t_stream, half) for f in self.faults):
            # the recorded bytes as they are: a structured record's copy and tobytes() go field by
            # field (5 per station: 2.3 ms a frame at 836 stations against 0.14 ms, most of a server's CPU)
            block = self.records[self.config_now]
            return self._framed(index, block.view(np.uint8).reshape(block.shape[0], -1)[k].tobytes(), tq,
                                bad_crc), delay
        rec = self.records[self.config_now][k:k + 1].copy()
        names = self._names
        if cfg_bit:
            for j in range(len(names)):
                rec[f"{j}s"] |= 1 << 10
        for f in self.faults:
            if not f.covers(t_stream, half):
                continue
            if f.kind in STAT_FAULTS:
                clear, bits = f.stat_bits()
                for j, name in enumerate(names):
                    if f.station in (None, name):
                        rec[f"{j}s"] = rec[f"{j}s"] & (0xFFFF & ~clear) | bits
                        if f.kind == "absent":
                            _absent(rec, j, self.configs[self.config_now].stations[j])
            elif f.kind == "clock":
                tq = int(f.value if f.value is not None else 15)
            elif f.kind == "stale":
                before = k - round((t_stream - f.start_s) * self.source.rate) - 1   # the frame before START
                held = self.records[self.config_now][max(before, 0)]
                for j, name in enumerate(names):
                    if f.station in (None, name):
                        for field in rec.dtype.names:
                            if field.startswith(f"{j}") and field[len(str(j)):] in ("p", "a", "f", "d"):
                                rec[field] = held[field]
            elif f.kind == "drop":
                self.stats["dropped_by_fault"] += 1
                return None, 0.0
            elif f.kind == "late":
                delay = max(delay, float(f.value))
            elif f.kind == "crc":
                bad_crc = True
        return self._framed(index, rec.tobytes(), tq, bad_crc), delay

    def _framed(self, index: int, data, tq: int, bad_crc: bool) -> bytes:
        """A data frame at grid ``index`` around the data block ``data`` (bytes)."""
        soc, frac = c3.grid_time(index, self.time_base, self.source.rate)
        head = struct.pack(">BBHHII", c3.SYNC_BYTE, c3.DATA << 4 | 1, c3.COMMON + len(data) + 2,
                           self.idcode, soc, tq << 24 | frac)
        body = head + data
        crc = c3.crc_ccitt(body) ^ (0xFFFF if bad_crc else 0)
        if bad_crc:
            self.stats["bad_crc"] += 1
        return body + struct.pack(">H", crc)

    async def _produce(self):
        loop = asyncio.get_running_loop()
        if self.on_request:
            await self._started.wait()
        src = self.source
        wall0, mono0 = time.time(), loop.time()
        first = src.first_index + self._offset(wall0)
        # in real time from now, a frame leaves when its timestamp comes; else paced from the first
        lead = first / src.rate - wall0 if self.start == "now" and self.speed == 1.0 else 0.0
        changes = sorted(f.start_s for f in self.faults if f.kind == "config-change")
        announce = [(f.start_s - (DEFAULT_LEAD_S if f.value is None else f.value), f.start_s)
                    for f in self.faults if f.kind == "config-change"]
        disconnects = sorted(f.start_s for f in self.faults if f.kind == "disconnect")
        present = np.any([st.present for st in src.stations], axis=0)
        late: list = []
        n_pass = 0
        while True:
            for k in np.flatnonzero(present):  # a gap in every recording: no frame
                k = int(k)
                t_stream = (n_pass * src.frames + k) / src.rate
                while changes and t_stream >= changes[0] - 1e-9:
                    changes.pop(0)
                    self.config_now = self._changed_config()
                    self.log(f"configuration change at {t_stream:g} s (CFGCNT {self.config_now})")
                while disconnects and t_stream >= disconnects[0] - 1e-9:
                    disconnects.pop(0)
                    self._disconnect()
                    self.log(f"disconnect at {t_stream:g} s")
                due = mono0 + lead + t_stream / self.speed
                await self._flush_late(late, due)
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                cfg_bit = any(a - 1e-9 <= t_stream < b - 1e-9 for a, b in announce)
                data, delay = self._frame_bytes(k, first + n_pass * src.frames + k, t_stream, cfg_bit)
                if data is None:
                    continue
                self.stats["frames"] += 1
                if delay > 0:
                    self.stats["late"] += 1
                    heapq.heappush(late, (due + delay / self.speed, self.stats["frames"], data))
                else:
                    self._send(data)
            n_pass += 1
            if not self.loop:
                break
        await self._flush_late(late, math.inf)

    async def _flush_late(self, late, until):
        loop = asyncio.get_running_loop()
        while late and late[0][0] <= until:
            due, _, data = heapq.heappop(late)
            wait = due - loop.time()
            if wait > 0:
                await asyncio.sleep(wait)
            self._send(data)

    async def run(self) -> dict:
        """Serve until the recording ends (no ``loop``), ``duration`` passes or :meth:`stop`."""
        self._loop = asyncio.get_running_loop()
        self._started = asyncio.Event()
        self._stopping = asyncio.Event()
        if not self.on_request:
            self._started.set()
        if self.udp:
            transport, _ = await self._loop.create_datagram_endpoint(lambda: self._Udp(self),
                                                                     local_addr=(self.host, self.port))
            self._udp_transport = transport
            server = None
            self.bound = transport.get_extra_info("sockname")[:2]
        else:
            server = await asyncio.start_server(self._serve_tcp, self.host, self.port, limit=1 << 16)
            self.bound = server.sockets[0].getsockname()[:2]
        self._ready.set()
        producer = asyncio.ensure_future(self._produce())
        stopper = asyncio.ensure_future(self._stopping.wait())
        timer = asyncio.ensure_future(asyncio.sleep(self.duration if self.duration is not None else 1e9))
        try:
            await asyncio.wait({producer, stopper, timer}, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for task in (producer, stopper, timer):
                task.cancel()
            await asyncio.sleep(0)
            for client in list(self.clients):
                if client.writer is not None:
                    with contextlib.suppress(Exception):
                        await asyncio.wait_for(client.writer.drain(), 1.0)
                    client.writer.close()
            self.clients.clear()
            if server is not None:
                server.close()
                with contextlib.suppress(Exception):
                    await asyncio.wait_for(server.wait_closed(), 1.0)
            if self._udp_transport is not None:
                self._udp_transport.close()
        if producer.done() and not producer.cancelled() and producer.exception() is not None:
            raise producer.exception()
        return self.stats

    def stop(self):
        """Stop a running server (from any thread)."""
        if self._loop is not None and self._stopping is not None:
            with contextlib.suppress(RuntimeError):  # the loop has ended already
                self._loop.call_soon_threadsafe(self._stopping.set)

    @contextlib.contextmanager
    def serve_in_thread(self, timeout: float = 10.0):
        """Run the server in a background thread; yields (host, port); stops it on exit."""
        result = {}

        def main():
            try:
                result["stats"] = asyncio.run(self.run())
            except BaseException as err:  # noqa: BLE001 (handed to the caller)
                result["error"] = err
                self._ready.set()

        thread = threading.Thread(target=main, name="pmu-sim", daemon=True)
        thread.start()
        if not self._ready.wait(timeout) or "error" in result:
            raise RuntimeError(f"pmu-sim did not start: {result.get('error')}")
        try:
            yield self.bound
        finally:
            self.stop()
            join(thread, timeout, f"serving {self.source.path.name} on {self.host}:{self.port}", self.log)
        if "error" in result:
            raise result["error"]


def _absent(rec, j, sc: c3.StationConfig):
    """Station ``j``'s values of a packed record as absent data (6.3.1)."""
    if sc.phasors:
        ph = rec[f"{j}p"]
        if sc.phasor_float:
            ph["a"], ph["b"] = np.nan, np.nan
        else:
            ph["a"], ph["b"] = (0x8000, c3.ABSENT) if sc.polar else (c3.ABSENT, c3.ABSENT)
    for f in ("f", "d"):
        rec[f"{j}{f}"] = np.nan if sc.freq_float else c3.ABSENT


# --- the client --------------------------------------------------------------------------------

class PmuClient:
    """A small blocking client of a C37.118.2 PMU or PDC (TCP, or UDP with ``udp=True``).

    ``with PmuClient(host, port, idcode) as pmu: cfg = pmu.config(); pmu.start();
    for frame in pmu.frames(count=100): ...; pmu.stop()``. Every wait is bounded by
    ``timeout`` seconds; what the decoder rejects is in ``pmu.decoder.counts``, and the
    configuration in force in ``pmu.decoder.config(idcode)``. When data frames stop fitting
    the configuration (it changed, 6.3.1 STAT bit 10), the client asks for it again, once,
    and decodes with the new one from its arrival."""

    def __init__(self, host: str = "127.0.0.1", port: int = c3.TCP_PORT, idcode: int = 1, *,
                 timeout: float = 5.0, udp: bool = False):
        self.idcode, self.timeout, self.udp = idcode, timeout, udp
        self.address = (host, port)
        self.decoder = c3.StreamDecoder(max_streams=4)
        self.pending: deque = deque(maxlen=4096)
        self._config_cmd = None
        self._misfits = 0
        if udp:
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self.sock.connect(self.address)
        else:
            self.sock = socket.create_connection(self.address, timeout=timeout)
        self.sock.settimeout(timeout)
        self.closed = False

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        if not self.closed:
            self.closed = True
            self.sock.close()

    def command(self, cmd: int):
        now = time.time()
        self.sock.sendall(c3.encode(c3.CommandFrame(self.idcode, cmd, int(now))))

    def start(self):
        self.command(c3.CMD_ON)

    def stop(self):
        self.command(c3.CMD_OFF)

    def config(self, kind: int = c3.CFG2) -> c3.ConfigFrame:
        """Request CFG-1, CFG-2 or CFG-3 (``kind`` c37118.CFG1/CFG2/CFG3) and wait for it; data
        frames that arrive meanwhile are kept for :meth:`frames`."""
        cmd = {c3.CFG1: c3.CMD_CFG1, c3.CFG2: c3.CMD_CFG2, c3.CFG3: c3.CMD_CFG3}[kind]
        self._config_cmd = cmd
        self.command(cmd)
        got = self._wait(lambda f: isinstance(f, c3.ConfigFrame) and f.kind == kind)
        return got

    def header(self) -> str:
        self.command(c3.CMD_HEADER)
        return self._wait(lambda f: isinstance(f, c3.HeaderFrame)).text

    def _wait(self, want):
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            for frame in self._receive(deadline):
                if want(frame):
                    return frame
                self.pending.append(frame)
        raise TimeoutError(f"no answer from {self.address[0]}:{self.address[1]} within {self.timeout} s")

    def _receive(self, deadline: float) -> list:
        self.sock.settimeout(max(0.01, min(self.timeout, deadline - time.monotonic())))
        try:
            data = self.sock.recv(1 << 16)
        except TimeoutError:
            return []
        if not data:
            raise ConnectionError("the PMU closed the connection")
        if self.udp:
            frame = self.decoder.feed_datagram(data)
            frames = [] if frame is None else [frame]
        else:
            frames = self.decoder.feed(data)
        misfits = self.decoder.counts["length"] + self.decoder.counts["no_config"]
        if misfits > self._misfits and self._config_cmd is not None:
            self.command(self._config_cmd)  # the layout changed: ask again, once until it comes
            self._config_cmd, self._asked = None, self._config_cmd
        self._misfits = misfits
        if any(isinstance(f, c3.ConfigFrame) for f in frames) and self._config_cmd is None:
            self._config_cmd = getattr(self, "_asked", None)
        return frames

    def poll(self, seconds: float) -> list:
        """The frames that are pending or arrive within ``seconds`` (returns at the first
        arrival); ConnectionError when the PMU closed the connection."""
        out = list(self.pending)
        self.pending.clear()
        deadline = time.monotonic() + seconds
        while not out and time.monotonic() < deadline:
            out += self._receive(deadline)
        return out

    def frames(self, count: int | None = None, seconds: float | None = None):
        """Yield received frames (data frames, and any configuration or header frame), until
        ``count`` data frames, ``seconds`` seconds (default: ``timeout``) or the connection's end."""
        deadline = time.monotonic() + (self.timeout if seconds is None else seconds)
        n = 0
        while self.pending:
            frame = self.pending.popleft()
            n += isinstance(frame, c3.DataFrame)
            yield frame
            if count is not None and n >= count:
                return
        while time.monotonic() < deadline:
            try:
                got = self._receive(deadline)
            except ConnectionError:
                return
            for j, frame in enumerate(got):
                n += isinstance(frame, c3.DataFrame)
                yield frame
                if count is not None and n >= count:
                    self.pending.extend(got[j + 1:])
                    return


# --- the command line ----------------------------------------------------------------------------

def main(args, units_of, stream=None) -> int:
    """``jaxdse pmu-sim``: see ``PMU_SIM_HELP`` in the CLI; ``units_of(path)``: the
    :class:`Units` of a run configuration or fleet file (passed in by the CLI)."""
    stream = stream or sys.stderr

    def log(line):
        print(f"jaxdse pmu-sim: {line}", file=stream, flush=True)

    from .._io.errors import InputError

    try:
        faults = [Fault.parse(text) for text in args.fault or ()]
        fmt = Format.parse(args.format)
    except ValueError as err:
        raise InputError("pmu-sim", str(err)) from None
    for name, value, ok, what in (
            ("--speed", args.speed, math.isfinite(args.speed) and args.speed > 0, "a number > 0"),
            ("--tile", args.tile, args.tile >= 1, "a whole number >= 1"),
            ("--port", args.port, 0 <= args.port <= 65535, "0-65535 (0: any free port)"),
            ("--idcode", args.idcode, 1 <= args.idcode <= 65534, "1-65534 (C37.118 IDCODE)"),
            ("--time-base", args.time_base, 1 <= args.time_base <= 0xFFFFFF, "1-16777215 (24 bits)"),
            ("--duration", args.duration, args.duration is None
             or (math.isfinite(args.duration) and args.duration > 0), "seconds > 0")):
        if not ok:
            raise InputError("pmu-sim", f"{name} {value}: out of range; give {what}")
    source = load_source(args.recording, units_of(args.recording))
    if len(source.stations) * args.tile * MIN_STATION_BYTES > c3.MAX_FRAME:
        raise InputError("pmu-sim", f"--tile {args.tile}: {len(source.stations) * args.tile} stations "
                         f"cannot fit one data frame (at least {MIN_STATION_BYTES} bytes each, "
                         f"FRAMESIZE at most {c3.MAX_FRAME}); give at most "
                         f"{c3.MAX_FRAME // (MIN_STATION_BYTES * len(source.stations))}")
    source = tile(source, args.tile)
    for note in source.notes:
        log(f"note: {note}")
    start = args.start
    if start not in ("now", "recording"):
        start = _parse_start(start)
    end_s = source.frames / source.rate
    for f in faults:
        if f.station is not None and f.station not in [s.name for s in source.stations]:
            raise InputError("pmu-sim", f"--fault {f.kind}@{f.start_s:g}: no station {f.station!r}; "
                             f"the stations: {', '.join(s.name for s in source.stations)}")
        if not args.loop and f.start_s >= end_s:
            raise InputError("pmu-sim", f"--fault {f.text}: starts at {f.start_s:g} s, at or after the "
                             f"recording's end ({end_s:g} s of stream time); without --loop the stream "
                             "ends there")
    try:
        server = PmuServer(source, host=args.host, port=args.port, udp=args.udp, idcode=args.idcode, fmt=fmt,
                           speed=args.speed, loop=args.loop, duration=args.duration, faults=faults,
                           start=start, on_request=not args.free_run, time_base=args.time_base, log=log)
    except ValueError as err:
        raise InputError(args.recording, str(err)) from None

    async def go():
        loop = asyncio.get_running_loop()
        for sig in (signal.SIGINT, signal.SIGTERM):  # a clean stop: connections closed, counts logged
            with contextlib.suppress(NotImplementedError, RuntimeError, ValueError):
                loop.add_signal_handler(sig, server.stop)
        task = asyncio.ensure_future(server.run())
        while server.bound is None and not task.done():
            await asyncio.sleep(0.01)
        if server.bound is not None:
            host, port = server.bound
            print(f"pmu-sim listening on {'udp' if args.udp else 'tcp'} {host}:{port} (IDCODE "
                  f"{args.idcode}, {len(source.stations)} station(s), {source.rate} frames/s, "
                  f"{source.frames} frames)", flush=True)
        return await task

    try:
        asyncio.run(go())
    except KeyboardInterrupt:
        log("interrupted")
    log(", ".join(f"{k.replace('_', ' ')} {v}" for k, v in server.stats.items()))
    return 0


def _parse_start(text: str) -> float:
    from .._io.errors import InputError

    try:
        soc = float(int(text))
    except ValueError:
        pass
    else:
        if not 0 <= soc < 2 ** 32:
            raise InputError("--start", f"{text}: seconds since 1970 (C37.118 SOC) lie in 0-{2 ** 32 - 1}")
        return soc
    import pandas as pd

    try:
        ts = pd.Timestamp(text)
    except ValueError:
        raise InputError("--start", f"{text!r} is neither now, recording, a SOC nor an ISO 8601 time"
                         ) from None
    return (ts.tz_localize("UTC") if ts.tzinfo is None else ts).timestamp()
