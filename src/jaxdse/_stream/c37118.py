"""IEEE C37.118.2-2011 synchrophasor frames: encode and decode, byte for byte.

Clause numbers are the standard's (IEEE Std C37.118.2-2011):

* 6.2   every frame: SYNC, FRAMESIZE, IDCODE, SOC, FRACSEC (with its message time-quality
        byte, 6.2.2, Tables 3-4), ..., CHK, a CRC-CCITT (polynomial x^16 + x^12 + x^5 + 1,
        initial value 0xFFFF, no final mask; 6.2.1). Big-endian throughout. The frame types
        of Table 2: data (0), header (1), CFG-1 (2), CFG-2 (3), command (4), CFG-3 (5);
        CFG-3 is version 2, every other frame version 1 (6.2.1). Time = SOC + FRACSEC /
        TIME_BASE, SOC an unsigned 32-bit count of seconds since 1970 (UNIX time).
* 6.3   data frames (Tables 5-6): per station STAT, PHASORS, FREQ, DFREQ, ANALOG, DIGITAL in
        the FORMAT of its configuration: phasors polar or rectangular, 16-bit integer or
        32-bit float; analogs and FREQ/DFREQ integer or float, each on its own. Integer
        phasors are scaled by PHUNIT (CFG-1/2: 10^-5 V or A per bit) or PHSCALE (CFG-3:
        X' = Y Xm e^{j(phi - theta)}, Table 11); integer polar angles are radians x 10^4
        (+-31416). Integer FREQ is the deviation from FNOM in mHz; float FREQ is the frequency
        itself in Hz. DFREQ (ROCOF) is Hz/s x 100 as an integer and Hz/s as a float (the
        standard says "same as FREQ", so a float carries the value itself, as Wireshark reads
        it). Absent data (6.3.1): NaN in floats, 0x8000 in integers (rectangular: each part;
        polar: the angle). STAT (Table 6, 6.3.1, Table 7): :class:`Stat`.
* 6.4   configuration frames: CFG-1 and CFG-2 (Tables 8-9; the same layout, names 16 bytes,
        space padded), CFG-3 (Tables 10-12: names of 0-255 UTF-8 bytes after a length byte,
        PHSCALE and ANSCALE scaling, the PMU's position, service class, window and group
        delay; CONT_IDX: 0 the only frame, 1, 2, ... fragments in order, 0xFFFF the last).
        Integer analogs: ANSCALE X' = M X + B in CFG-3; in CFG-1/2 the ANUNIT's signed 24-bit
        word is "user defined scaling", read here as M in 10^-5 per bit, like PHUNIT.
* 6.5   header frames (Table 13): text.
* 6.6   command frames (Tables 14-15): CMD and, for the extended frame, its data.

Decoding is safe on a network: a frame is at most 65535 bytes (FRAMESIZE), every count is
checked against the bytes left before anything is allocated, and a frame that is not one is
rejected with a :class:`FrameError` subclass that says why (:class:`CrcError`,
:class:`LengthError`, :class:`FrameTypeError`, :class:`FieldError`, :class:`NoConfigError`;
``err.kind`` names it for a counter). :class:`StreamDecoder` takes a TCP byte stream in
pieces of any size, resynchronises on the next SYNC after garbage, reassembles CFG-3
fragments (bounded), and counts what it rejects.

Round trip: ``decode(encode(frame)) == frame`` for every frame whose values the format
represents (float32, or integers on the channel's scale), and ``encode(decode(b)) == b``
for every frame this module writes. The encoder writes integer polar angles within
+-31415 and float polar angles within [-pi, pi] as float32, so that decoding and
re-encoding gives the same bytes.
"""

from __future__ import annotations

import binascii
import functools
import math
import struct
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

# --- constants (6.2, Table 2; 6.6, Table 15; Annex E.2) --------------------------------------

SYNC_BYTE = 0xAA
DATA, HEADER, CFG1, CFG2, COMMAND, CFG3 = 0, 1, 2, 3, 4, 5
FRAME_TYPES = {DATA: "data", HEADER: "header", CFG1: "CFG-1", CFG2: "CFG-2", COMMAND: "command",
               CFG3: "CFG-3"}
VERSIONS = (1, 2)
"""SYNC versions read: 1 (IEEE Std C37.118-2005 frames) and 2 (C37.118.2-2011's CFG-3)."""
MAX_FRAME = 0xFFFF
COMMON = 14
"""SYNC, FRAMESIZE, IDCODE, SOC, FRACSEC: the bytes before each frame's own fields."""
CMD_OFF, CMD_ON, CMD_HEADER, CMD_CFG1, CMD_CFG2, CMD_CFG3, CMD_EXTENDED = 1, 2, 3, 4, 5, 6, 8
CFG_COMMANDS = {CMD_CFG1: CFG1, CMD_CFG2: CFG2, CMD_CFG3: CFG3}
TCP_PORT, UDP_PORT = 4712, 4713
CFG3_LAST = 0xFFFF
ABSENT = -32768
"""0x8000: absent integer data (6.3.1)."""
POLAR_ANGLE_MAX = 31416
"""Integer polar angles are radians x 10^4 within +-31416 (Table 6)."""
DEFAULT_TIME_BASE = 1_000_000


def crc_ccitt(data) -> int:
    """CRC-CCITT of 6.2.1: polynomial 0x1021, initial value 0xFFFF, no final mask (C speed)."""
    return binascii.crc_hqx(data, 0xFFFF)


# --- errors ----------------------------------------------------------------------------------

class FrameError(ValueError):
    """A received frame that is not a valid C37.118.2 frame; ``kind`` names it for a counter."""

    kind = "malformed"


class CrcError(FrameError):
    """The CHK word does not match the frame's CRC-CCITT."""

    kind = "crc"


class LengthError(FrameError):
    """FRAMESIZE, or a count inside the frame, does not fit the bytes there are."""

    kind = "length"


class FrameTypeError(FrameError):
    """No SYNC byte, an unknown frame type or version, or a reserved SYNC bit set."""

    kind = "type"


class FieldError(FrameError):
    """A field holds a value the standard rules out (TIME_BASE 0, FRACSEC >= TIME_BASE,
    DATA_RATE 0, reserved FORMAT/FNOM bits, an integer polar angle beyond +-31416, an
    infinite value, CFG-3 fragments out of order, ...)."""

    kind = "field"


class NoConfigError(FrameError):
    """A data frame whose stream (IDCODE) has no configuration yet."""

    kind = "no_config"


# --- STAT and time quality (6.3.1, Tables 6-7; 6.2.2, Tables 3-4) -----------------------------

GOOD, PMU_ERROR_NO_INFO, TEST_OR_ABSENT, PMU_ERROR = 0, 1, 2, 3
"""STAT bits 15-14, the data error field (Table 6)."""


@dataclass(frozen=True)
class Stat:
    """The STAT word of a station's data block (Table 6, 6.3.1)."""

    data_error: int = GOOD
    """Bits 15-14: 0 good; 1 PMU error, no information about data; 2 test mode or absent data
    inserted (do not use); 3 PMU error (do not use)."""
    sync_lost: bool = False
    """Bit 13: the PMU is not in sync with a UTC-traceable time source."""
    by_arrival: bool = False
    """Bit 12: data sorted by arrival, not by time stamp."""
    trigger: bool = False
    """Bit 11: PMU trigger detected."""
    config_change: bool = False
    """Bit 10: the configuration changes in a minute (cleared when it has)."""
    data_modified: bool = False
    """Bit 9: data modified by post-processing."""
    time_quality: int = 0
    """Bits 8-6: PMU_TQ (Table 7): 0 not used, 1 < 100 ns, ..., 6 < 10 ms, 7 > 10 ms or unknown."""
    unlocked: int = 0
    """Bits 5-4: unlocked time: 0 < 10 s, 1 10-100 s, 2 100-1000 s, 3 > 1000 s."""
    trigger_reason: int = 0
    """Bits 3-0: 0 manual, 1 magnitude low, 2 magnitude high, 3 phase-angle difference,
    4 frequency high or low, 5 df/dt high, 7 digital, 8-15 user defined."""

    @property
    def word(self) -> int:
        for name, top in (("data_error", 3), ("time_quality", 7), ("unlocked", 3), ("trigger_reason", 15)):
            if not 0 <= getattr(self, name) <= top:
                raise ValueError(f"Stat.{name} must lie in 0-{top}, got {getattr(self, name)}")
        return (self.data_error << 14 | self.sync_lost << 13 | self.by_arrival << 12 | self.trigger << 11
                | self.config_change << 10 | self.data_modified << 9 | self.time_quality << 6
                | self.unlocked << 4 | self.trigger_reason)

    @classmethod
    def from_word(cls, word: int) -> Stat:
        word = int(word)
        return cls(word >> 14 & 3, bool(word >> 13 & 1), bool(word >> 12 & 1), bool(word >> 11 & 1),
                   bool(word >> 10 & 1), bool(word >> 9 & 1), word >> 6 & 7, word >> 4 & 3, word & 15)

    @property
    def usable(self) -> bool:
        """Good data in sync: data error 00 and bit 13 clear."""
        return self.data_error == GOOD and not self.sync_lost


@dataclass(frozen=True)
class TimeQuality:
    """The message time-quality byte, bits 31-24 of FRACSEC (6.2.2, Tables 3-4)."""

    leap_delete: bool = False
    """Bit 6: leap second direction, 0 add, 1 delete."""
    leap_occurred: bool = False
    """Bit 5."""
    leap_pending: bool = False
    """Bit 4."""
    code: int = 0
    """Bits 3-0 (Table 4): 0 locked to UTC, 1-11 time within 10^(code-10) s, 15 clock failure."""

    @property
    def byte(self) -> int:
        if not 0 <= self.code <= 15:
            raise ValueError(f"TimeQuality.code must lie in 0-15, got {self.code}")
        return self.leap_delete << 6 | self.leap_occurred << 5 | self.leap_pending << 4 | self.code

    @classmethod
    def from_byte(cls, byte: int) -> TimeQuality:
        return cls(bool(byte >> 6 & 1), bool(byte >> 5 & 1), bool(byte >> 4 & 1), byte & 15)


# --- configuration (6.4) -----------------------------------------------------------------------

@dataclass(frozen=True)
class PhasorChannel:
    """One phasor channel: CHNAM and PHUNIT (CFG-1/2) or PHSCALE (CFG-3)."""

    name: str
    current: bool = False
    """PHUNIT's top byte (1: current, A) or PHSCALE bit 3 of the type byte; else voltage (V)."""
    scale: float = 1e-5
    """Engineering units per count of integer data: PHUNIT x 10^-5 (CFG-1/2, whole multiples of
    10^-5 up to 167.77215) or Y (CFG-3, a float32). Ignored for float data."""
    angle_offset: float = 0.0
    """CFG-3 theta [rad], subtracted from the angle of integer data (Table 11)."""
    component: int = 1
    """CFG-3 phasor component (Table 11): 0 zero, 1 positive, 2 negative sequence, 4-6 phase A-C."""
    modification: int = 0
    """CFG-3 data modification flags (Table 11)."""
    user_flags: int = 0
    """CFG-3 user-designated byte."""


@dataclass(frozen=True)
class AnalogChannel:
    """One analog channel: CHNAM and ANUNIT (CFG-1/2) or ANSCALE (CFG-3)."""

    name: str
    kind: int = 1
    """ANUNIT's top byte (CFG-1/2): 0 point on wave, 1 RMS, 2 peak, 65-255 user defined."""
    scale: float = 1e-5
    """M of integer data, X' = M X + B: ANUNIT's signed 24-bit word x 10^-5 (CFG-1/2) or a
    float32 (CFG-3). Ignored for float data."""
    offset: float = 0.0
    """B of integer data (CFG-3 only; 0 in CFG-1/2)."""


@dataclass(frozen=True)
class DigitalWord:
    """One 16-bit digital status word: 16 channel names (bit 0 first) and DIGUNIT's masks."""

    names: tuple[str, ...] = ("",) * 16
    normal: int = 0
    valid: int = 0xFFFF


@dataclass(frozen=True)
class StationConfig:
    """One PMU (station) of a configuration frame: fields 8-19 of Table 8 (9-27 of Table 10)."""

    name: str
    idcode: int
    phasors: tuple[PhasorChannel, ...] = ()
    analogs: tuple[AnalogChannel, ...] = ()
    digitals: tuple[DigitalWord, ...] = ()
    polar: bool = True
    phasor_float: bool = True
    analog_float: bool = True
    freq_float: bool = True
    fnom_hz: int = 50
    cfgcnt: int = 0
    # CFG-3 only (Table 11)
    g_pmu_id: bytes = bytes(16)
    latitude: float = math.inf
    """Degrees north, WGS 84; infinity: not given."""
    longitude: float = math.inf
    elevation: float = math.inf
    service_class: str = "M"
    window_us: int = 0
    group_delay_us: int = 0

    @property
    def format(self) -> int:
        """FORMAT word (Table 9)."""
        return self.freq_float << 3 | self.analog_float << 2 | self.phasor_float << 1 | self.polar

    @property
    def block_size(self) -> int:
        """Bytes of this station's block in a data frame (Table 5)."""
        return (2 + len(self.phasors) * (8 if self.phasor_float else 4) + (8 if self.freq_float else 4)
                + len(self.analogs) * (4 if self.analog_float else 2) + 2 * len(self.digitals))


@dataclass(frozen=True)
class ConfigFrame:
    """A configuration frame (6.4): CFG-1 (``kind`` 2), CFG-2 (3) or CFG-3 (5)."""

    idcode: int
    stations: tuple[StationConfig, ...]
    data_rate: int
    """Frames per second if > 0; seconds per frame if < 0 (Table 9)."""
    time_base: int = DEFAULT_TIME_BASE
    soc: int = 0
    fracsec: int = 0
    tq: int = 0
    kind: int = CFG2
    version: int | None = None
    """SYNC version; None: the standard's (2 for CFG-3, 1 for CFG-1/2)."""

    @property
    def rate_hz(self) -> float:
        return float(self.data_rate) if self.data_rate > 0 else -1.0 / self.data_rate

    @functools.cached_property
    def data_size(self) -> int:
        """FRAMESIZE of this configuration's data frames (once per configuration: checked on
        every data frame, and a sum over 800 stations cost 0.3 ms)."""
        return COMMON + sum(s.block_size for s in self.stations) + 2


# --- data, header and command frames (6.3, 6.5, 6.6) -----------------------------------------

@dataclass(frozen=True, eq=False)
class StationData:
    """One station's block of a data frame (Tables 5-6), in engineering units."""

    stat: int = 0
    """The STAT word (:meth:`Stat.from_word` reads it)."""
    phasors: np.ndarray = field(default_factory=lambda: np.zeros(0, complex))
    """Complex phasors [V or A, RMS], NaN where absent."""
    freq: float = math.nan
    """Frequency [Hz] (integer FREQ is sent as the deviation from FNOM in mHz)."""
    dfreq: float = 0.0
    """ROCOF [Hz/s]."""
    analogs: np.ndarray = field(default_factory=lambda: np.zeros(0))
    digitals: np.ndarray = field(default_factory=lambda: np.zeros(0, np.uint16))

    def __eq__(self, other):
        if not isinstance(other, StationData):
            return NotImplemented
        return (self.stat == other.stat and _same(self.freq, other.freq) and _same(self.dfreq, other.dfreq)
                and all(np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True)
                        for a, b in ((self.phasors, other.phasors), (self.analogs, other.analogs),
                                     (self.digitals, other.digitals))))


def _same(a, b) -> bool:
    return a == b or (math.isnan(a) and math.isnan(b))


@dataclass(frozen=True, eq=False)
class StationArrays:
    """The station blocks of one data frame as arrays over its S stations (decoded in one
    vectorised pass where every station has the same FORMAT and channel counts, the usual
    concentrator). ``phasors``, ``analogs`` and ``digitals`` are [S, n] arrays, or, where the
    stations' counts differ, one array per station; either way ``phasors[k]`` is station k's."""

    stat: np.ndarray
    """[S] STAT words."""
    phasors: np.ndarray | tuple
    freq: np.ndarray
    """[S] Hz."""
    dfreq: np.ndarray
    """[S] Hz/s."""
    analogs: np.ndarray | tuple
    digitals: np.ndarray | tuple


class DataFrame:
    """A data frame (6.3): one :class:`StationData` per station of the configuration.

    A decoded frame holds its values as :class:`StationArrays` (``frame.arrays``: what a
    monitor of many stations reads) and builds the per-station ``stations`` on first use."""

    __slots__ = ("idcode", "soc", "fracsec", "tq", "version", "_stations", "_arrays")

    def __init__(self, idcode: int, stations=None, soc: int = 0, fracsec: int = 0, tq: int = 0,
                 version: int = 1, *, arrays: StationArrays | None = None):
        if stations is None and arrays is None:
            raise TypeError("DataFrame needs its stations (or their arrays)")
        self.idcode, self.soc, self.fracsec, self.tq, self.version = idcode, soc, fracsec, tq, version
        self._stations = None if stations is None else tuple(stations)
        self._arrays = arrays

    @property
    def stations(self) -> tuple[StationData, ...]:
        if self._stations is None:
            a = self._arrays
            self._stations = tuple(StationData(int(a.stat[k]), a.phasors[k], float(a.freq[k]),
                                               float(a.dfreq[k]), a.analogs[k], a.digitals[k])
                                   for k in range(len(a.stat)))
        return self._stations

    @property
    def arrays(self) -> StationArrays:
        if self._arrays is None:
            st = self._stations

            def stack(name, dtype):
                parts = [np.asarray(getattr(x, name), dtype) for x in st]
                return np.stack(parts) if len({p.shape for p in parts}) == 1 else tuple(parts)

            self._arrays = StationArrays(np.array([x.stat for x in st], np.uint16), stack("phasors", complex),
                                         np.array([x.freq for x in st], float),
                                         np.array([x.dfreq for x in st], float), stack("analogs", float),
                                         stack("digitals", np.uint16))
        return self._arrays

    def __eq__(self, other):
        if not isinstance(other, DataFrame):
            return NotImplemented
        return ((self.idcode, self.soc, self.fracsec, self.tq, self.version)
                == (other.idcode, other.soc, other.fracsec, other.tq, other.version)
                and self.stations == other.stations)

    __hash__ = None

    def __repr__(self):
        return (f"DataFrame(idcode={self.idcode}, soc={self.soc}, fracsec={self.fracsec}, tq={self.tq}, "
                f"version={self.version}, stations={len(self.stations)})")


@dataclass(frozen=True)
class HeaderFrame:
    """A header frame (6.5): human-readable text."""

    idcode: int
    text: str
    soc: int = 0
    fracsec: int = 0
    tq: int = 0
    version: int = 1


@dataclass(frozen=True)
class CommandFrame:
    """A command frame (6.6), sent to a PMU: CMD (Table 15) and the extended frame's data."""

    idcode: int
    cmd: int
    soc: int = 0
    fracsec: int = 0
    tq: int = 0
    extended: bytes = b""
    version: int = 1


@dataclass(frozen=True)
class Cfg3Fragment:
    """One frame of a CFG-3 sent in several (CONT_IDX 1, 2, ..., 0xFFFF; Table 11): its share
    of the fields after CONT_IDX. :class:`StreamDecoder` joins them."""

    idcode: int
    cont_idx: int
    payload: bytes
    soc: int = 0
    fracsec: int = 0
    tq: int = 0
    version: int = 2


Frame = DataFrame | ConfigFrame | HeaderFrame | CommandFrame | Cfg3Fragment


def frame_time(frame, time_base: int) -> float:
    """SOC + FRACSEC / TIME_BASE [s since 1970] (6.2.2)."""
    return frame.soc + frame.fracsec / time_base


def grid_index(soc: int, fracsec: int, time_base: int, data_rate: int) -> int | None:
    """The frame's index on the reporting grid (frames since 1970 at ``data_rate``), or None when
    its timestamp is off the grid. A grid point k is sent as SOC = k // rate and FRACSEC =
    round((k % rate) TIME_BASE / rate) (half up; exact when the rate divides TIME_BASE), and
    only that FRACSEC is on the grid: exact integer arithmetic, no float rounding."""
    if data_rate > 0:
        k = (2 * fracsec * data_rate + time_base) // (2 * time_base)
        return soc * data_rate + k if grid_fracsec(k, time_base, data_rate) == fracsec else None
    period = -data_rate
    return soc // period if fracsec == 0 and soc % period == 0 else None


def grid_fracsec(k_in_second: int, time_base: int, data_rate: int) -> int:
    """FRACSEC of the ``k_in_second``-th frame of a second: round(k TIME_BASE / rate), half up."""
    return (2 * k_in_second * time_base + data_rate) // (2 * data_rate)


def grid_time(index: int, time_base: int, data_rate: int) -> tuple[int, int]:
    """(SOC, FRACSEC) of grid point ``index`` (the inverse of :func:`grid_index`)."""
    if data_rate > 0:
        return index // data_rate, grid_fracsec(index % data_rate, time_base, data_rate)
    return index * -data_rate, 0


# --- encoding ----------------------------------------------------------------------------------

def _check_int(name, value, lo, hi):
    if not isinstance(value, (int, np.integer)) or isinstance(value, bool) or not lo <= value <= hi:
        raise ValueError(f"{name} must be an integer in {lo}-{hi}, got {value!r}")


def _frame(ftype: int, version: int, idcode: int, soc: int, fracsec: int, tq: int, body: bytes) -> bytes:
    _check_int("IDCODE", idcode, 0, 0xFFFF)
    _check_int("SOC", soc, 0, 0xFFFFFFFF)
    _check_int("FRACSEC", fracsec, 0, 0xFFFFFF)
    _check_int("time quality", tq, 0, 0xFF)
    _check_int("version", version, 1, 15)
    size = COMMON + len(body) + 2
    if size > MAX_FRAME:
        raise ValueError(f"a {FRAME_TYPES[ftype]} frame of {size} bytes exceeds FRAMESIZE's 65535"
                         + ("; send the CFG-3 in fragments (encode_cfg3_fragments)" if ftype == CFG3 else ""))
    head = struct.pack(">BBHHII", SYNC_BYTE, ftype << 4 | version, size, idcode, soc, tq << 24 | fracsec)
    out = head + body
    return out + struct.pack(">H", crc_ccitt(out))


def encode(frame: Frame, config: ConfigFrame | None = None) -> bytes:
    """The bytes of ``frame``; a :class:`DataFrame` needs its ``config``. Raises ValueError for
    a value the format cannot carry (an integer out of range, a name too long, a frame beyond
    65535 bytes)."""
    if isinstance(frame, DataFrame):
        if config is None:
            raise ValueError("encoding a data frame needs its configuration")
        if frame.fracsec >= config.time_base:
            raise ValueError(f"FRACSEC {frame.fracsec} must be below TIME_BASE {config.time_base}")
        layout = DataLayout.of(config)
        return _frame(DATA, frame.version, frame.idcode, frame.soc, frame.fracsec, frame.tq,
                      layout.pack_one(frame.stations))
    if isinstance(frame, ConfigFrame):
        version = frame.version or (2 if frame.kind == CFG3 else 1)
        return _frame(frame.kind, version, frame.idcode, frame.soc, frame.fracsec, frame.tq,
                      (b"\0\0" if frame.kind == CFG3 else b"") + _config_body(frame))
    if isinstance(frame, HeaderFrame):
        return _frame(HEADER, frame.version, frame.idcode, frame.soc, frame.fracsec, frame.tq,
                      frame.text.encode("latin-1"))
    if isinstance(frame, CommandFrame):
        _check_int("CMD", frame.cmd, 0, 0xFFFF)
        return _frame(COMMAND, frame.version, frame.idcode, frame.soc, frame.fracsec, frame.tq,
                      struct.pack(">H", frame.cmd) + bytes(frame.extended))
    if isinstance(frame, Cfg3Fragment):
        _check_int("CONT_IDX", frame.cont_idx, 1, 0xFFFF)
        return _frame(CFG3, frame.version, frame.idcode, frame.soc, frame.fracsec, frame.tq,
                      struct.pack(">H", frame.cont_idx) + frame.payload)
    raise TypeError(f"not a C37.118 frame: {type(frame).__name__}")


def encode_cfg3_fragments(config: ConfigFrame, max_frame: int = MAX_FRAME) -> list[bytes]:
    """A CFG-3 as one frame (CONT_IDX 0) if it fits ``max_frame`` bytes, else as fragments of at
    most ``max_frame`` bytes: CONT_IDX 1, 2, ..., and 0xFFFF for the last (Table 11), each with
    the common header and its share of the fields after CONT_IDX, in order."""
    if config.kind != CFG3:
        raise ValueError("only a CFG-3 is sent in fragments")
    body = _config_body(config)
    room = max_frame - COMMON - 2 - 2
    if room < 1:
        raise ValueError(f"max_frame = {max_frame} leaves no room for data")
    version = config.version or 2
    if len(body) <= room:
        return [_frame(CFG3, version, config.idcode, config.soc, config.fracsec, config.tq, b"\0\0" + body)]
    pieces = [body[i:i + room] for i in range(0, len(body), room)]
    if len(pieces) >= CFG3_LAST:
        raise ValueError("a CFG-3 of more than 65534 fragments")
    return [encode(Cfg3Fragment(config.idcode, CFG3_LAST if k == len(pieces) else k, p, config.soc,
                                config.fracsec, config.tq, version), None)
            for k, p in enumerate(pieces, 1)]


def _name16(name: str, what: str) -> bytes:
    raw = name.encode("latin-1")
    if len(raw) > 16:
        raise ValueError(f"{what} {name!r} is longer than the 16 bytes of CFG-1/2 (CFG-3 takes 255)")
    return raw.ljust(16, b" ")


def _name3(name: str, what: str) -> bytes:
    raw = name.encode("utf-8", "surrogateescape")
    if len(raw) > 255:
        raise ValueError(f"{what} {name!r} is longer than CFG-3's 255 bytes")
    return bytes([len(raw)]) + raw


def _config_body(cfg: ConfigFrame) -> bytes:
    """The fields after the common header (and after CONT_IDX for CFG-3), through DATA_RATE."""
    if cfg.kind not in (CFG1, CFG2, CFG3):
        raise ValueError(f"ConfigFrame.kind must be CFG1 (2), CFG2 (3) or CFG3 (5), got {cfg.kind}")
    _check_int("TIME_BASE", cfg.time_base, 1, 0xFFFFFF)
    _check_int("DATA_RATE", cfg.data_rate, -32767, 32767)
    if cfg.data_rate == 0:
        raise ValueError("DATA_RATE must not be 0")
    if not 1 <= len(cfg.stations) <= 0xFFFF:
        raise ValueError(f"a configuration needs 1-65535 stations, got {len(cfg.stations)}")
    if cfg.fracsec >= cfg.time_base:
        raise ValueError(f"FRACSEC {cfg.fracsec} must be below TIME_BASE {cfg.time_base}")
    parts = [struct.pack(">IH", cfg.time_base, len(cfg.stations))]
    three = cfg.kind == CFG3
    for st in cfg.stations:
        _check_int("station IDCODE", st.idcode, 0, 0xFFFF)
        _check_int("CFGCNT", st.cfgcnt, 0, 0xFFFF)
        if st.fnom_hz not in (50, 60):
            raise ValueError(f"FNOM is 50 or 60 Hz, got {st.fnom_hz}")
        counts = struct.pack(">HHHH", st.format, len(st.phasors), len(st.analogs), len(st.digitals))
        names = [p.name for p in st.phasors] + [a.name for a in st.analogs] + \
            [n for d in st.digitals for n in _sixteen(d.names)]
        if three:
            if len(st.g_pmu_id) != 16:
                raise ValueError("G_PMU_ID is 16 bytes")
            if len(st.service_class.encode("latin-1")) != 1:
                raise ValueError("SVC_CLASS is one ASCII character (M or P)")
            parts += [_name3(st.name, "station name"), struct.pack(">H", st.idcode), bytes(st.g_pmu_id),
                      counts, *(_name3(n, "channel name") for n in names)]
            for p in st.phasors:
                _check_int("phasor component", p.component, 0, 7)
                _check_int("modification flags", p.modification, 0, 0xFFFF)
                _check_int("user flags", p.user_flags, 0, 0xFF)
                parts.append(struct.pack(">HBBff", p.modification, p.current << 3 | p.component, p.user_flags,
                                         p.scale, p.angle_offset))
            parts += [struct.pack(">ff", a.scale, a.offset) for a in st.analogs]
        else:
            parts += [_name16(st.name, "station name"), struct.pack(">H", st.idcode), counts,
                      *(_name16(n, "channel name") for n in names)]
            for p in st.phasors:
                raw = round(p.scale * 1e5)
                _check_int("PHUNIT (phasor scale x 10^5)", raw, 0, 0xFFFFFF)
                parts.append(struct.pack(">I", p.current << 24 | raw))
            for a in st.analogs:
                _check_int("ANUNIT type", a.kind, 0, 0xFF)
                raw = round(a.scale * 1e5)
                _check_int("ANUNIT (analog scale x 10^5)", raw, -0x800000, 0x7FFFFF)
                if a.offset:
                    raise ValueError(f"analog {a.name!r}: an offset needs CFG-3 (ANSCALE)")
                parts.append(struct.pack(">I", a.kind << 24 | raw & 0xFFFFFF))
        for d in st.digitals:
            parts.append(struct.pack(">HH", d.normal, d.valid))
        if three:
            parts.append(struct.pack(">fffcii", st.latitude, st.longitude, st.elevation,
                                     st.service_class.encode("latin-1"), st.window_us, st.group_delay_us))
        parts.append(struct.pack(">HH", 1 if st.fnom_hz == 50 else 0, st.cfgcnt))
    parts.append(struct.pack(">h", cfg.data_rate))
    return b"".join(parts)


def _sixteen(names) -> tuple[str, ...]:
    names = tuple(names)
    if len(names) != 16:
        raise ValueError(f"a digital status word has 16 channel names, got {len(names)}")
    return names


# --- the data block layout: one NumPy record per frame ------------------------------------------

class DataLayout:
    """The data frame of a configuration as a NumPy structured dtype (Table 5): decodes and
    encodes one frame, or many at once (the simulator packs a whole recording in one call).

    Per station ``k``: ``{k}s`` STAT, ``{k}p`` phasors (two parts each), ``{k}f`` FREQ,
    ``{k}d`` DFREQ, ``{k}a`` analogs, ``{k}g`` digitals."""

    _cache: dict = {}

    def __init__(self, config: ConfigFrame):
        self.config = config
        fields = []
        for k, st in enumerate(config.stations):
            fields.append((f"{k}s", ">u2"))
            if st.phasors:
                part = (">f4", ">f4") if st.phasor_float else (">u2", ">i2") if st.polar else (">i2", ">i2")
                fields.append((f"{k}p", [("a", part[0]), ("b", part[1])], (len(st.phasors),)))
            fr = ">f4" if st.freq_float else ">i2"
            fields += [(f"{k}f", fr), (f"{k}d", fr)]
            if st.analogs:
                fields.append((f"{k}a", ">f4" if st.analog_float else ">i2", (len(st.analogs),)))
            if st.digitals:
                fields.append((f"{k}g", ">u2", (len(st.digitals),)))
        self.dtype = np.dtype(fields)
        ss = config.stations
        self.scales = [np.array([p.scale for p in st.phasors]) for st in ss]
        self.offsets = [np.array([p.angle_offset for p in st.phasors]) if config.kind == CFG3
                        else np.zeros(len(st.phasors)) for st in ss]
        self.an_scales = [np.array([a.scale for a in st.analogs]) for st in ss]
        self.an_offsets = [np.array([a.offset for a in st.analogs]) for st in ss]

        def shape(st):
            return (st.format, len(st.phasors), len(st.analogs), len(st.digitals))

        self.uniform = all(shape(st) == shape(ss[0]) for st in ss)
        """Every station has the same FORMAT and counts: one record type, decoded for all at once."""
        if self.uniform:
            self.block = np.dtype([(name[1:], self.dtype.fields[name][0])
                                   for name in self.dtype.names[:len(self.dtype.names) // len(ss)]])
            self.matrix = tuple(np.array(x).reshape(len(ss), -1) for x in
                                (self.scales, self.offsets, self.an_scales, self.an_offsets))
            self.fnoms = np.array([st.fnom_hz for st in ss], float)

    @classmethod
    def of(cls, config: ConfigFrame) -> DataLayout:
        """The layout of ``config``, built once per configuration (a small cache)."""
        key = id(config)
        hit = cls._cache.get(key)
        if hit is None or hit.config is not config:
            if len(cls._cache) > 64:
                cls._cache.clear()
            hit = cls._cache[key] = cls(config)
        return hit

    # decoding
    def arrays(self, payload) -> StationArrays:
        """The station blocks of one data frame's bytes after the common header, before CHK.
        Raises :class:`FieldError` for an infinite value, an integer polar angle beyond +-31416
        or a negative float polar magnitude."""
        ss = self.config.stations
        if self.uniform:
            rec = np.frombuffer(payload, self.block)
            scales, offsets, an_scales, an_offsets = self.matrix
            v = _values(ss[0], rec["p"] if ss[0].phasors else None, rec["f"], rec["d"],
                        rec["a"] if ss[0].analogs else None, scales, offsets, self.fnoms, an_scales,
                        an_offsets)
            dg = rec["g"].astype(np.uint16) if ss[0].digitals else np.zeros((len(ss), 0), np.uint16)
            return StationArrays(rec["s"].astype(np.uint16), v[0], v[1], v[2], v[3], dg)
        rec = np.frombuffer(payload, self.dtype, count=1)
        per = [self.values(rec, k) for k in range(len(ss))]
        return StationArrays(np.array([rec[f"{k}s"][0] for k in range(len(ss))], np.uint16),
                             tuple(p[0][0] for p in per), np.array([p[1][0] for p in per]),
                             np.array([p[2][0] for p in per]), tuple(p[3][0] for p in per),
                             tuple(rec[f"{k}g"][0].astype(np.uint16) if st.digitals
                                   else np.zeros(0, np.uint16) for k, st in enumerate(ss)))

    def unpack(self, payload) -> tuple[StationData, ...]:
        """The stations of one data frame's bytes after the common header, before CHK."""
        return DataFrame(0, arrays=self.arrays(payload)).stations

    def values(self, rec: np.ndarray, k: int):
        """Station ``k``'s values in engineering units from records ``rec`` (N frames of this
        layout): (phasors [N, P] complex, freq [N] Hz, dfreq [N] Hz/s, analogs [N, A]); NaN
        where absent."""
        st = self.config.stations[k]
        return _values(st, rec[f"{k}p"] if st.phasors else None, rec[f"{k}f"], rec[f"{k}d"],
                       rec[f"{k}a"] if st.analogs else None, self.scales[k], self.offsets[k], st.fnom_hz,
                       self.an_scales[k], self.an_offsets[k])

    # encoding
    def pack_one(self, stations) -> bytes:
        stations = tuple(stations)
        if len(stations) != len(self.config.stations):
            raise ValueError(f"the configuration has {len(self.config.stations)} stations, the frame "
                             f"{len(stations)}")
        rec = np.zeros(1, self.dtype)
        for k, sd in enumerate(stations):
            self.fill(rec, k, np.array([sd.stat]), np.asarray(sd.phasors, complex)[None],
                      np.array([sd.freq], float), np.array([sd.dfreq], float),
                      np.asarray(sd.analogs, float)[None], np.asarray(sd.digitals)[None])
        return rec.tobytes()

    def fill(self, rec, k, stat, phasors, freq, dfreq, analogs=None, digitals=None):
        """Write station ``k`` of records ``rec`` (N frames) from engineering values: stat [N],
        phasors [N, P] complex, freq [N] Hz, dfreq [N] Hz/s, analogs [N, A], digitals [N, D]."""
        st = self.config.stations[k]
        name = f"station {st.name!r}"
        stat = np.asarray(stat)
        if ((stat < 0) | (stat > 0xFFFF)).any():
            raise ValueError(f"{name}: STAT must lie in 0-65535")
        rec[f"{k}s"] = stat
        if st.phasors:
            z = np.asarray(phasors, complex)
            if z.shape[-1] != len(st.phasors):
                raise ValueError(f"{name}: {len(st.phasors)} phasors configured, {z.shape[-1]} given")
            out = rec[f"{k}p"]
            if st.phasor_float:
                if st.polar:
                    out["a"] = np.abs(z)
                    out["b"] = _float32_angle(np.angle(z))
                else:
                    out["a"], out["b"] = z.real, z.imag
            else:
                turn = self.offsets[k]
                if st.polar:
                    mag = _integer(np.abs(z) / self.scales[k], 0, 0xFFFF, f"{name}: a phasor magnitude")
                    ang = np.angle(z * np.exp(1j * turn)) * 1e4
                    ang = np.clip(np.round(np.nan_to_num(ang)), -POLAR_ANGLE_MAX + 1, POLAR_ANGLE_MAX - 1)
                    absent = np.isnan(z)
                    out["a"] = np.where(absent, -ABSENT, mag)
                    out["b"] = np.where(absent, ABSENT, ang).astype(np.int16)
                else:
                    zz = z * np.exp(1j * turn) if turn.any() else z
                    out["a"] = _integer(zz.real / self.scales[k], -32767, 32767, f"{name}: a real part")
                    out["b"] = _integer(zz.imag / self.scales[k], -32767, 32767, f"{name}: an imaginary part")
        if st.freq_float:
            rec[f"{k}f"], rec[f"{k}d"] = freq, dfreq
        else:
            rec[f"{k}f"] = _integer((np.asarray(freq, float) - st.fnom_hz) * 1e3, -32767, 32767,
                                    f"{name}: FREQ (deviation from {st.fnom_hz} Hz in mHz)")
            rec[f"{k}d"] = _integer(np.asarray(dfreq, float) * 1e2, -32767, 32767,
                                    f"{name}: DFREQ (Hz/s x 100)")
        if st.analogs:
            an = np.asarray(analogs, float)
            if an.shape[-1] != len(st.analogs):
                raise ValueError(f"{name}: {len(st.analogs)} analogs configured, {an.shape[-1]} given")
            if st.analog_float:
                rec[f"{k}a"] = an
            else:
                m = np.array([x.scale for x in st.analogs])
                off = np.array([x.offset for x in st.analogs])
                rec[f"{k}a"] = _integer((an - off) / m, -32767, 32767, f"{name}: an analog value")
        if st.digitals:
            dg = np.asarray(digitals)
            if dg.shape[-1] != len(st.digitals):
                raise ValueError(f"{name}: {len(st.digitals)} digital words configured, {dg.shape[-1]} given")
            rec[f"{k}g"] = dg


def _complex(re, im):
    """re + j im, keeping the sign of a zero part (``re + 1j * im`` loses it)."""
    z = np.empty(np.broadcast_shapes(np.shape(re), np.shape(im)), complex)
    z.real, z.imag = re, im
    return z


def _values(st: StationConfig, ph, f, d, an, scales, offsets, fnom, an_scales, an_offsets):
    """Engineering values of raw data-block fields of the FORMAT of ``st`` (leading dimensions
    broadcast: N frames of one station, or S stations of one frame): (phasors [.., P] complex,
    freq, dfreq, analogs [.., A]); NaN where absent (6.3.1)."""
    n = f.shape
    name = f"station {st.name!r}"
    if ph is not None:
        a, b = ph["a"].astype(float), ph["b"].astype(float)
        if st.phasor_float:
            if np.isinf(a).any() or np.isinf(b).any():
                raise FieldError(f"{name}: an infinite phasor value")
            if st.polar:
                if (a < 0).any():
                    raise FieldError(f"{name}: a negative phasor magnitude")
                z = a * np.exp(1j * b)
            else:
                z = _complex(a, b)
        elif st.polar:
            absent = b == ABSENT
            if (np.abs(b[~absent]) > POLAR_ANGLE_MAX).any():
                raise FieldError(f"{name}: a polar angle beyond +-{POLAR_ANGLE_MAX} (radians x 10^4)")
            z = a * scales * np.exp(1j * (b * 1e-4 - offsets))
            z[absent] = complex(np.nan, np.nan)
        else:
            z = _complex(np.where(a == ABSENT, np.nan, a) * scales, np.where(b == ABSENT, np.nan, b) * scales)
            if np.any(offsets):  # turned: one absent part makes the phasor absent
                z = np.where(np.isnan(z), complex(np.nan, np.nan), z * np.exp(-1j * offsets))
    else:
        z = np.zeros((*n, 0), complex)
    f, d = f.astype(float), d.astype(float)
    if st.freq_float:
        if np.isinf(f).any() or np.isinf(d).any():
            raise FieldError(f"{name}: an infinite FREQ or DFREQ")
    else:
        f = np.where(f == ABSENT, np.nan, fnom + f * 1e-3)
        d = np.where(d == ABSENT, np.nan, d * 1e-2)
    if an is not None:
        an = an.astype(float)
        if st.analog_float:
            if np.isinf(an).any():
                raise FieldError(f"{name}: an infinite analog value")
        else:
            an = np.where(an == ABSENT, np.nan, an * an_scales + an_offsets)
    else:
        an = np.zeros((*n, 0))
    return z, f, d, an


def _float32_angle(theta):
    """Angles as float32 within [-pi, pi]: float32(pi) lies above pi, and would come back as -pi."""
    a = np.asarray(theta, np.float32)
    top = np.nextafter(np.float32(np.pi), np.float32(0))
    return np.clip(a, -top, top) + np.float32(0)  # and -0.0 as 0.0: exp(-0j) loses the sign


def _integer(x, lo, hi, what):
    """Round to integers in [lo, hi], NaN -> 0x8000 (absent); ValueError beyond the range."""
    x = np.asarray(x, float)
    r = np.round(np.where(np.isnan(x), 0.0, x))
    if ((r < lo) | (r > hi)).any():
        worst = x.flat[np.argmax(np.abs(np.where(np.isnan(x), 0, x)))]
        raise ValueError(f"{what} of {worst:g} counts does not fit a 16-bit integer ({lo} to {hi}); "
                         "use a larger scale or the float format")
    return np.where(np.isnan(x), ABSENT, r).astype(np.int64)


# --- decoding ----------------------------------------------------------------------------------

class _Reader:
    """A cursor over a frame's bytes that raises :class:`LengthError` instead of reading past them."""

    __slots__ = ("buf", "pos", "end")

    def __init__(self, buf, pos, end):
        self.buf, self.pos, self.end = buf, pos, end

    def need(self, n, what):
        if n > self.end - self.pos:
            raise LengthError(f"{what} needs {n} bytes, the frame has {self.end - self.pos} left")

    def take(self, n, what="a field") -> bytes:
        self.need(n, what)
        out = bytes(self.buf[self.pos:self.pos + n])
        self.pos += n
        return out

    def unpack(self, fmt, what="a field"):
        n = struct.calcsize(fmt)
        self.need(n, what)
        out = struct.unpack_from(fmt, self.buf, self.pos)
        self.pos += n
        return out

    def name3(self, what) -> str:
        (n,) = self.unpack(">B", what)
        return self.take(n, what).decode("utf-8", errors="surrogateescape")


def decode_frame(buf, config: ConfigFrame | None = None) -> Frame:
    """One whole frame (SYNC through CHK) -> a frame object. A data frame needs the ``config``
    of its stream. Raises a :class:`FrameError` subclass for anything that is not a valid frame."""
    buf = memoryview(bytes(buf)) if not isinstance(buf, (bytes, memoryview)) else memoryview(buf)
    n = len(buf)
    if n < COMMON + 2:
        raise LengthError(f"{n} bytes: shorter than the {COMMON + 2} of the smallest frame")
    if buf[0] != SYNC_BYTE:
        raise FrameTypeError(f"no SYNC: first byte 0x{buf[0]:02X}, not 0xAA")
    ftype, version = buf[1] >> 4, buf[1] & 0xF
    if ftype > CFG3:
        raise FrameTypeError(f"unknown frame type {ftype}"
                             + (" (SYNC bit 7 is reserved)" if ftype > 7 else ""))
    if version not in VERSIONS:
        raise FrameTypeError(f"unknown version {version} of a {FRAME_TYPES[ftype]} frame")
    size, idcode, soc, fq = struct.unpack_from(">HHII", buf, 2)
    if size != n:
        raise LengthError(f"FRAMESIZE {size} but {n} bytes")
    (chk,) = struct.unpack_from(">H", buf, n - 2)
    if crc_ccitt(buf[:n - 2]) != chk:
        raise CrcError(f"{FRAME_TYPES[ftype]} frame: CHK 0x{chk:04X}, CRC 0x{crc_ccitt(buf[:n - 2]):04X}")
    tq, fracsec = fq >> 24, fq & 0xFFFFFF
    r = _Reader(buf, COMMON, n - 2)
    if ftype == DATA:
        return _decode_data(buf, r, config, version, idcode, soc, fracsec, tq)
    if ftype == HEADER:
        return HeaderFrame(idcode, r.take(r.end - r.pos).decode("latin-1"), soc, fracsec, tq, version)
    if ftype == COMMAND:
        (cmd,) = r.unpack(">H", "CMD")
        return CommandFrame(idcode, cmd, soc, fracsec, tq, r.take(r.end - r.pos), version)
    if ftype == CFG3:
        (cont,) = r.unpack(">H", "CONT_IDX")
        if cont:
            if r.end == r.pos:
                raise LengthError("an empty CFG-3 fragment")
            return Cfg3Fragment(idcode, cont, r.take(r.end - r.pos), soc, fracsec, tq, version)
    return _decode_config(r, ftype, version, idcode, soc, fracsec, tq)


def _decode_data(buf, r, config, version, idcode, soc, fracsec, tq) -> DataFrame:
    if config is None or config.idcode != idcode:
        raise NoConfigError(f"a data frame of stream {idcode} without its configuration")
    if len(buf) != config.data_size:
        raise LengthError(f"data frame of {len(buf)} bytes; its configuration (CFGCNT "
                          f"{config.stations[0].cfgcnt}) gives {config.data_size}")
    if fracsec >= config.time_base:
        raise FieldError(f"FRACSEC {fracsec} is not below TIME_BASE {config.time_base}")
    arrays = DataLayout.of(config).arrays(buf[COMMON:len(buf) - 2])
    return DataFrame(idcode, None, soc, fracsec, tq, version, arrays=arrays)


def _decode_config(r: _Reader, ftype, version, idcode, soc, fracsec, tq) -> ConfigFrame:
    three = ftype == CFG3
    tb_word, num_pmu = r.unpack(">IH", "TIME_BASE and NUM_PMU")
    if tb_word >> 24:
        raise FieldError(f"TIME_BASE flags 0x{tb_word >> 24:02X} are reserved")
    time_base = tb_word & 0xFFFFFF
    if time_base == 0:
        raise FieldError("TIME_BASE is 0")
    if fracsec >= time_base:
        raise FieldError(f"FRACSEC {fracsec} is not below TIME_BASE {time_base}")
    if num_pmu == 0:
        raise FieldError("NUM_PMU is 0")
    stations = []
    for k in range(num_pmu):
        r.need(52 if three else 30, f"station {k + 1} of {num_pmu}")  # its fixed fields
        if three:
            name = r.name3("a station name")
            sid, = r.unpack(">H")
            gid = r.take(16, "G_PMU_ID")
        else:
            name = _text16(r.take(16, "STN"))
            sid, = r.unpack(">H")
            gid = bytes(16)
        fmt, nph, nan, ndg = r.unpack(">HHHH", "FORMAT and counts")
        if fmt >> 4:
            raise FieldError(f"station {name!r}: FORMAT bits 15-4 are unused, got 0x{fmt:04X}")
        nnames = nph + nan + 16 * ndg
        r.need(nnames * (1 if three else 16) + (12 * nph + 8 * nan if three else 4 * (nph + nan)) + 4 * ndg,
               f"station {name!r}: {nph} phasors, {nan} analogs, {ndg} digital words")
        names = [r.name3("a channel name") if three else _text16(r.take(16)) for _ in range(nnames)]
        phasors, analogs, digitals = [], [], []
        for i in range(nph):
            if three:
                mod, kind, user, y, theta = r.unpack(">HBBff", "PHSCALE")
                if kind >> 4:
                    raise FieldError(f"phasor {names[i]!r}: PHSCALE type bits 7-4 are reserved")
                phasors.append(PhasorChannel(names[i], bool(kind >> 3 & 1), y, theta, kind & 7, mod, user))
            else:
                (word,) = r.unpack(">I", "PHUNIT")
                if word >> 24 > 1:
                    raise FieldError(f"phasor {names[i]!r}: PHUNIT type {word >> 24} is neither 0 (V) "
                                     "nor 1 (A)")
                phasors.append(PhasorChannel(names[i], bool(word >> 24), (word & 0xFFFFFF) * 1e-5))
        for i in range(nan):
            nm = names[nph + i]
            if three:
                m, b = r.unpack(">ff", "ANSCALE")
                analogs.append(AnalogChannel(nm, 1, m, b))
            else:
                (word,) = r.unpack(">I", "ANUNIT")
                raw = word & 0xFFFFFF
                analogs.append(AnalogChannel(nm, word >> 24, (raw - (raw >> 23 << 24)) * 1e-5))
        for i in range(ndg):
            normal, valid = r.unpack(">HH", "DIGUNIT")
            lo = nph + nan + 16 * i
            digitals.append(DigitalWord(tuple(names[lo:lo + 16]), normal, valid))
        extra = {}
        if three:
            lat, lon, elev, svc, window, delay = r.unpack(">fffcii", "PMU position, class, window")
            if any(math.isnan(x) for x in (lat, lon, elev)):
                raise FieldError(f"station {name!r}: a NaN position (unspecified is infinity)")
            extra = dict(g_pmu_id=gid, latitude=lat, longitude=lon, elevation=elev,
                         service_class=svc.decode("latin-1"), window_us=window, group_delay_us=delay)
        fnom, cfgcnt = r.unpack(">HH", "FNOM and CFGCNT")
        if fnom >> 1:
            raise FieldError(f"station {name!r}: FNOM bits 15-1 are reserved, got 0x{fnom:04X}")
        stations.append(StationConfig(name, sid, tuple(phasors), tuple(analogs), tuple(digitals),
                                      bool(fmt & 1), bool(fmt & 2), bool(fmt & 4), bool(fmt & 8),
                                      50 if fnom & 1 else 60, cfgcnt, **extra))
    (rate,) = r.unpack(">h", "DATA_RATE")
    if rate == 0:
        raise FieldError("DATA_RATE is 0")
    if r.pos != r.end:
        raise LengthError(f"{r.end - r.pos} bytes after DATA_RATE")
    cfg = ConfigFrame(idcode, tuple(stations), rate, time_base, soc, fracsec, tq, ftype,
                      None if version == (2 if three else 1) else version)
    if cfg.data_size > MAX_FRAME:
        raise FieldError(f"its data frames would be {cfg.data_size} bytes, beyond FRAMESIZE's 65535")
    return cfg


def _text16(raw: bytes) -> str:
    return raw.decode("latin-1").rstrip(" ")


def join_cfg3(fragments) -> ConfigFrame:
    """A CFG-3 from its fragments (CONT_IDX 1, 2, ..., 0xFFFF, in order)."""
    fragments = list(fragments)
    for k, f in enumerate(fragments, 1):
        want = CFG3_LAST if k == len(fragments) else k
        if f.cont_idx != want:
            raise FieldError(f"CFG-3 fragment {k} has CONT_IDX {f.cont_idx}, expected {want}")
    first = fragments[0]
    payload = b"".join(f.payload for f in fragments)
    cfg = _decode_config(_Reader(memoryview(payload), 0, len(payload)), CFG3, first.version, first.idcode,
                         first.soc, first.fracsec, first.tq)
    return cfg


# --- the incremental decoder ------------------------------------------------------------------

class StreamDecoder:
    """Frames from a byte stream that arrives in pieces (TCP), or one datagram at a time (UDP).

    ``feed(data)`` returns the frames completed by ``data``; what is rejected is counted in
    ``counts`` (by :attr:`FrameError.kind`, plus ``"skipped_bytes"`` of garbage before a SYNC)
    and the last one kept in ``last_error``. Configuration frames are kept per stream IDCODE
    (at most ``max_streams``) and decode that stream's data frames; CFG-3 fragments are joined
    (at most ``max_cfg3_bytes`` in all). Memory is bounded: the buffer never holds more than
    two frames (2 x 65535 bytes) plus the piece being fed.

    A frame with a bad CRC is dropped whole (and counted once) where a valid frame follows it;
    else (its FRAMESIZE may be what is corrupted) the decoder steps one byte and searches for
    the next SYNC, counting each candidate that fails."""

    def __init__(self, *, max_streams: int = 64, max_cfg3_bytes: int = 1 << 22):
        self.buf = bytearray()
        self.configs: dict[int, ConfigFrame] = {}
        self.counts: Counter = Counter()
        self.last_error: FrameError | None = None
        self.max_streams = max_streams
        self.max_cfg3_bytes = max_cfg3_bytes
        self._fragments: dict[int, list[Cfg3Fragment]] = {}

    def config(self, idcode: int | None = None) -> ConfigFrame | None:
        """The latest configuration of stream ``idcode`` (None: of the only stream seen)."""
        if idcode is None:
            return next(iter(self.configs.values())) if len(self.configs) == 1 else None
        return self.configs.get(idcode)

    def feed(self, data) -> list[Frame]:
        self.buf += data
        out: list[Frame] = []
        buf = self.buf
        start = 0
        while True:
            i = buf.find(SYNC_BYTE, start)
            if i < 0:
                self._skip(len(buf) - start)
                start = len(buf)
                break
            self._skip(i - start)
            start = i
            if len(buf) - start < 4:
                break
            if buf[start + 1] >> 4 > CFG3 or buf[start + 1] & 0xF not in VERSIONS:
                self._skip(1)
                start += 1
                continue
            size = buf[start + 2] << 8 | buf[start + 3]
            if size < COMMON + 2:
                self._skip(1)
                start += 1
                continue
            if len(buf) - start < size:
                # incomplete: wait, unless a whole valid frame lies within the bytes it claims
                # (its FRAMESIZE is garbage, or a false SYNC): then resume there
                j = _next_valid(buf, start + 1)
                if j is None:
                    break
                self._reject(LengthError(f"FRAMESIZE {size}: a valid frame starts {j - start} bytes in"))
                start = j
                continue
            frame = bytes(buf[start:start + size])
            if not _crc_ok(frame):
                # a corrupted frame, or a corrupted FRAMESIZE: drop the whole frame only where a
                # whole valid frame follows it; else step one byte and search for the next SYNC
                follows = _valid_at(buf, start + size)
                if follows is None:
                    break  # wait for the next frame to tell
                self._reject(CrcError(f"{FRAME_TYPES.get(buf[start + 1] >> 4, '?')} frame: bad CRC"))
                start = start + size if follows else start + 1
                continue
            try:
                got = self._one(frame)
            except FrameError as err:  # the CRC holds, so the frame's bounds do: drop it whole
                self._reject(err)
                start += size
                continue
            start += size
            if got is not None:
                out.append(got)
        del buf[:start]
        return out

    def feed_datagram(self, data) -> Frame | None:
        """One UDP datagram, one frame: decoded, or counted and None."""
        try:
            return self._one(bytes(data))
        except FrameError as err:
            self._reject(err)
            return None

    def _one(self, frame: bytes) -> Frame | None:
        idcode = frame[4] << 8 | frame[5] if len(frame) >= 6 else -1
        got = decode_frame(frame, self.configs.get(idcode))
        if isinstance(got, Cfg3Fragment):
            return self._fragment(got)
        if isinstance(got, ConfigFrame):
            self._remember(got)
        self.counts["frames"] += 1
        return got

    def _fragment(self, frag: Cfg3Fragment) -> ConfigFrame | None:
        parts = self._fragments.setdefault(frag.idcode, [])
        expected = len(parts) + 1
        in_order = frag.cont_idx == expected or (frag.cont_idx == CFG3_LAST and parts)
        if not in_order or (parts and (parts[0].soc, parts[0].fracsec) != (frag.soc, frag.fracsec)):
            self._fragments.pop(frag.idcode, None)
            raise FieldError(f"CFG-3 fragment CONT_IDX {frag.cont_idx} out of order (expected {expected})")
        parts.append(frag)
        if sum(len(p.payload) for p in parts) > self.max_cfg3_bytes:
            self._fragments.pop(frag.idcode, None)
            raise LengthError(f"CFG-3 fragments beyond {self.max_cfg3_bytes} bytes")
        if frag.cont_idx != CFG3_LAST:
            return None
        del self._fragments[frag.idcode]
        cfg = join_cfg3(parts)
        self._remember(cfg)
        self.counts["frames"] += 1
        return cfg

    def _remember(self, cfg: ConfigFrame):
        if cfg.idcode not in self.configs and len(self.configs) >= self.max_streams:
            self.configs.pop(next(iter(self.configs)))
        self.configs[cfg.idcode] = cfg

    def _reject(self, err: FrameError):
        self.counts[err.kind] += 1
        self.last_error = err

    def _skip(self, n: int):
        if n > 0:
            self.counts["skipped_bytes"] += n


def _crc_ok(frame: bytes) -> bool:
    return crc_ccitt(frame[:-2]) == (frame[-2] << 8 | frame[-1])


def _next_valid(buf, lo: int) -> int | None:
    """The first position from ``lo`` where a whole frame with a valid CRC starts, or None."""
    i = buf.find(SYNC_BYTE, lo)
    while i >= 0:
        if _valid_at(buf, i):
            return i
        i = buf.find(SYNC_BYTE, i + 1)
    return None


def _valid_at(buf, i: int) -> bool | None:
    """Does a frame with a valid CRC start at ``buf[i]``? None: not enough bytes to tell."""
    if len(buf) - i < 4:
        return None if buf[i:i + 1] in (b"", bytes([SYNC_BYTE])) else False
    if buf[i] != SYNC_BYTE or buf[i + 1] >> 4 > CFG3 or buf[i + 1] & 0xF not in VERSIONS:
        return False
    size = buf[i + 2] << 8 | buf[i + 3]
    if size < COMMON + 2:
        return False
    if len(buf) - i < size:
        return None
    return _crc_ok(bytes(buf[i:i + size]))
