"""The monitor's results as a C37.118.2 stream (a "virtual PMU") that any PDC or historian takes.

One station per unit (its name, first 16 characters in CFG-1/2, whole in CFG-3), no phasors,
FREQ at nominal, and float analogs: ``H`` [s], ``H_LO`` and ``H_HI`` (the 95 % interval), ``D``
[pu torque per rad/s] and ``AGE`` [s] (:class:`~.online.Update`). One data frame per update,
stamped with the window's last frame's time (the reporting rate is 1 / ``update_s``). STAT:

* bits 15-14: 00 for a window that identifies H (``identified``, ``weakly identified``: the
  analogs hold it); 01 (no information about the data, analogs NaN) for ``not excited``; 11 (an
  error, NaN) for ``failed``; 10 (absent, NaN) for a unit without an update in this frame;
* bit 11 (trigger) with reason 8 (user defined) while the unit's H alarm is on.

With ``[inertia]``, one more station per area and one for the system, named ``E <area>``
(``E system``), after the units', with the float analogs of ``AREA_ANALOGS``: ``E``, ``E_LO``,
``E_HI`` [MW s] (E and its 95 % interval), ``SHARE`` (the measured share), ``E_COMMIT`` [MW s]
(the commitment figure), ``ROCOF`` [Hz/s] (NaN where none), ``ONLINE`` and ``MEASURED`` (unit
counts). Their values come in data frames of their own, stamped with the inertia line's time (every
``[inertia] update_s`` of stream time), in which the units' stations are absent (and the area
stations are absent in the units' frames); bit 11 (trigger, reason 8) while E is below the floor.

The server (asyncio, one thread) answers the standard's commands over TCP (CFG-1/2/3, header,
data on and off), binds 127.0.0.1 unless told otherwise, serves at most 16 clients and drops
(and counts) the frames of a client whose unsent data exceed 1 MiB.
"""

from __future__ import annotations

import asyncio
import math
import threading
import time

import numpy as np

from . import c37118 as c3
from .online import Update
from .pmu_sim import SEND_BUFFER_BYTES, serve_client, short_names
from .waits import join

ANALOGS = ("H", "H_LO", "H_HI", "D", "AGE")
AREA_ANALOGS = ("E", "E_LO", "E_HI", "SHARE", "E_COMMIT", "ROCOF", "ONLINE", "MEASURED")
"""A system inertia station's analogs (an updates.jsonl area line's fields)."""
ALARM_TRIGGER_REASON = 8
DATA_ERROR = {"identified": c3.GOOD, "weakly identified": c3.GOOD, "not excited": c3.PMU_ERROR_NO_INFO,
              "failed": c3.PMU_ERROR}


def published_values(u: Update) -> list:
    """The values of ``ANALOGS`` for update ``u`` (None where the window named no H)."""
    if u.h_s is None:
        return [None] * len(ANALOGS)
    return [u.h_s, *(u.h_ci95 or (None, None)), u.d_pu_s, u.age_s]


def area_station(area: str) -> str:
    """The station (C37.118) or device (STTP) of an area's system inertia."""
    return f"E {area}"


def area_values(line: dict) -> list:
    """The values of ``AREA_ANALOGS`` for an updates.jsonl area line (None: none)."""
    return [line["E_MWs"], *line["E_ci95"], line["measured_share"], line["E_commitment_MWs"],
            line["rocof_hz_per_s"], line["units_online"], line["units_measured"]]


class Publisher:
    """Serves the monitor's updates (see the module docstring); :meth:`publish` from any thread."""

    def __init__(self, units: list[str], *, host: str = "127.0.0.1", port: int = 4713, idcode: int = 7734,
                 update_s: float = 1.0, f_nominal_hz: int = 50, log=None, areas=(), floor_MWs: float | None = None):
        self.units, self.host, self.port, self.idcode = list(units), host, port, idcode
        self.areas, self.floor_MWs = list(areas), floor_MWs
        self.log = log or (lambda line: None)
        rate = 1.0 / update_s
        data_rate = round(rate) if rate >= 1 else -round(update_s)
        self.names = self.units + [area_station(a) for a in self.areas]
        short = short_names(self.names)
        self.stations = tuple(c3.StationConfig(
            short[k], (idcode + k) % 65534 + 1, (),
            tuple(c3.AnalogChannel(a, 1) for a in (ANALOGS if k < len(self.units) else AREA_ANALOGS)),
            polar=True, phasor_float=True, analog_float=True, freq_float=True, fnom_hz=f_nominal_hz)
            for k in range(len(self.names)))
        self.config = c3.ConfigFrame(idcode, self.stations, data_rate)
        if self.config.data_size > c3.MAX_FRAME:
            raise ValueError(f"{len(self.units)} units make frames beyond C37.118's 65535 bytes")
        self.index = {u: k for k, u in enumerate(self.units)}
        self.f_nominal = float(f_nominal_hz)
        self.clients: list = []
        self.stats = {"frames": 0, "sent": 0, "dropped_slow_client": 0, "commands": 0}
        self.bound = None
        self._loop = None
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._main, daemon=True, name="jaxdse-publish")

    def start(self, timeout: float = 10.0):
        self._thread.start()
        if not self._ready.wait(timeout) or self.bound is None:
            raise OSError(f"cannot listen on {self.host}:{self.port}")
        return self.bound

    def stop(self):
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._loop.stop)
        join(self._thread, 5.0, f"serving the results on {self.host}:{self.port}", self.log)

    def _main(self):
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            server = loop.run_until_complete(asyncio.start_server(self._serve, self.host, self.port))
            self.bound = server.sockets[0].getsockname()[:2]
        except OSError as err:
            self.log(f"publish: {err}")
            self._ready.set()
            return
        self._ready.set()
        try:
            loop.run_forever()
        finally:
            server.close()
            for c in self.clients:
                c.writer.close()
            loop.close()

    async def _serve(self, reader, writer):
        await serve_client(self.clients, reader, writer, self._command)

    def _command(self, client, frame) -> list[bytes]:
        if not isinstance(frame, c3.CommandFrame) or frame.idcode != self.idcode:
            return []
        self.stats["commands"] += 1
        now = time.time()
        soc, frac = int(now), int((now % 1) * self.config.time_base)
        if frame.cmd == c3.CMD_ON:
            client.on = True
        elif frame.cmd == c3.CMD_OFF:
            client.on = False
        elif frame.cmd == c3.CMD_HEADER:
            return [c3.encode(c3.HeaderFrame(self.idcode, "jaxdse monitor: per unit H, its 95 % interval "
                                             "(H_LO, H_HI) [s], D [pu torque per rad/s] and the estimate's AGE "
                                             "[s]; STAT 01: not excited, 11: failed, trigger: H alarm", soc, frac))]
        elif frame.cmd in c3.CFG_COMMANDS:
            kind = c3.CFG_COMMANDS[frame.cmd]
            cfg = c3.ConfigFrame(self.idcode, self.stations, self.config.data_rate, kind=kind, soc=soc,
                                 fracsec=frac)
            if kind == c3.CFG3:
                import dataclasses

                cfg = dataclasses.replace(cfg, stations=tuple(
                    dataclasses.replace(s, name=u) for s, u in zip(self.stations, self.names)))
                return c3.encode_cfg3_fragments(cfg)
            return [c3.encode(cfg)]
        return []

    def frame(self, t: float, updates: list[Update], alarms: dict) -> bytes:
        """The data frame of the updates at time ``t`` [s since 1970]."""
        blocks = self._absent()
        for u in updates:
            k = self.index.get(u.unit)
            if k is None:
                continue
            values = published_values(u)
            alarm = bool(alarms.get(u.unit, False))
            stat = c3.Stat(data_error=DATA_ERROR[u.verdict], trigger=alarm,
                           trigger_reason=ALARM_TRIGGER_REASON if alarm else 0).word
            blocks[k] = c3.StationData(stat=stat, freq=self.f_nominal,
                                       analogs=np.array([math.nan if v is None else v for v in values], float))
        return self._encode(t, blocks)

    def inertia_frame(self, t: float, lines: list[dict]) -> bytes:
        """The data frame of the system inertia's lines at ``t`` [s since 1970] (one per area)."""
        blocks = self._absent()
        for x in lines:
            if x["area"] not in self.areas:
                continue
            below = self.floor_MWs is not None and x["E_MWs"] < self.floor_MWs
            stat = c3.Stat(data_error=c3.GOOD, trigger=below, trigger_reason=ALARM_TRIGGER_REASON if below else 0).word
            blocks[len(self.units) + self.areas.index(x["area"])] = c3.StationData(
                stat=stat, freq=self.f_nominal,
                analogs=np.array([math.nan if v is None else v for v in area_values(x)], float))
        return self._encode(t, blocks)

    def _absent(self) -> list:
        return [c3.StationData(stat=c3.Stat(data_error=c3.TEST_OR_ABSENT).word, freq=self.f_nominal,
                               analogs=np.full(len(s.analogs), np.nan)) for s in self.stations]

    def _encode(self, t: float, blocks: list) -> bytes:
        soc = int(math.floor(t))
        frac = min(int(round((t - soc) * self.config.time_base)), self.config.time_base - 1)
        return c3.encode(c3.DataFrame(self.idcode, blocks, soc, frac), self.config)

    def publish(self, t: float, updates: list[Update], alarms: dict):
        """Send the frame of ``updates`` at ``t`` to every client with data on (thread-safe)."""
        self._queue(self.frame(t, updates, alarms))

    def publish_inertia(self, t: float, lines: list[dict]):
        """Send the frame of the system inertia's ``lines`` at ``t`` (thread-safe)."""
        self._queue(self.inertia_frame(t, lines))

    def _queue(self, data: bytes):
        self.stats["frames"] += 1
        if self._loop is not None:
            self._loop.call_soon_threadsafe(self._send, data)

    def _send(self, data: bytes):
        for c in self.clients:
            if not c.on:
                continue
            if c.writer.transport.get_write_buffer_size() > SEND_BUFFER_BYTES:
                self.stats["dropped_slow_client"] += 1
                continue
            c.writer.write(data)
            self.stats["sent"] += 1
