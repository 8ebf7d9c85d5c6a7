"""The IEEE C37.118.2-2011 codec (jaxdse._stream.c37118): the standard's own Annex D frames
byte for byte; round trips of every configuration type and FORMAT against an independent
packer in this file (raw wire values -> bytes -> decoded engineering values -> the same
bytes); the STAT and time-quality words; the reporting grid; the incremental decoder
(chunks, garbage, a bad CRC, a corrupted FRAMESIZE, CFG-3 fragments, a configuration
change); and fuzzing (hypothesis: random bytes, random bodies with a valid CRC, mutated valid
frames; and a seeded NumPy run that counts what it rejects): a bad frame raises a
FrameError subclass or is counted, never another exception, and the decoder's buffer stays
bounded."""

import math
import struct

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from jaxdse._stream import c37118 as c3

FUZZ = settings(
    max_examples=1000, deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck)
)
"""Cheap examples (random bytes, random bodies behind a valid CRC)."""
ROUND = settings(FUZZ, max_examples=150)
"""Examples that draw a whole configuration and its data frame."""


def _name16(s):
    return s.encode().ljust(16, b" ").hex()


ANNEX_D1 = bytes.fromhex(  # Table D.1: data frame
    "AA01 0034 1E36 44853600 000041B1 0000 392B0000 E36ACE7C E36A3183 04440000 09C4 0000"
    " 42C80000 447A0000 461C4000 3C12 D43F".replace(" ", "")
)
ANNEX_D2 = bytes.fromhex(
    (  # Table D.2: CFG-2
        "AA31 01C6 1E36 448527F0 56071098 000F4240 0001"
        + _name16("Station A")
        + "1E36 0004 0004 0003 0001"
        + "".join(_name16(n) for n in ["VA", "VB", "VC", "I1", "ANALOG1", "ANALOG2", "ANALOG3"])
        + "".join(_name16(f"BREAKER {c} STATUS") for c in "123456789ABCDEFG")
        + "000DF847" * 3
        + "0100B2D0"
        + "00000001 01000001 02000001"
        + "0000FFFF"
        + "0000 0016 001E D5D1"
    ).replace(" ", "")
)
ANNEX_D3 = bytes.fromhex("AA41 0012 1E36 44856030 0F0BBFD0 0002 CE00".replace(" ", ""))  # Table D.3


# --- the standard's examples, CRC, STAT, time quality, grid ------------------------------------


def test_crc_is_the_standards():
    assert c3.crc_ccitt(b"123456789") == 0x29B1  # CRC-16/CCITT-FALSE check value
    for frame in (ANNEX_D1, ANNEX_D2, ANNEX_D3):
        assert c3.crc_ccitt(frame[:-2]) == int.from_bytes(frame[-2:], "big")


def test_annex_d_examples_decode_and_encode_byte_for_byte():
    cfg = c3.decode_frame(ANNEX_D2)
    assert isinstance(cfg, c3.ConfigFrame) and cfg.kind == c3.CFG2 and cfg.idcode == 7734
    assert (cfg.soc, cfg.fracsec, cfg.time_base, cfg.data_rate) == (1149577200, 463000, 1_000_000, 30)
    tq = c3.TimeQuality.from_byte(cfg.tq)  # "leap second pending, to be deleted, within 100 us"
    assert tq.leap_pending and tq.leap_delete and not tq.leap_occurred and tq.code == 6
    (s,) = cfg.stations
    assert (s.name, s.idcode, s.format, s.fnom_hz, s.cfgcnt) == ("Station A", 7734, 0x0004, 60, 22)
    assert not s.polar and not s.phasor_float and s.analog_float and not s.freq_float
    assert [p.name for p in s.phasors] == ["VA", "VB", "VC", "I1"]
    assert [p.current for p in s.phasors] == [False, False, False, True]
    assert [round(p.scale * 1e5) for p in s.phasors] == [915527, 915527, 915527, 45776]
    assert [(a.name, a.kind) for a in s.analogs] == [("ANALOG1", 0), ("ANALOG2", 1), ("ANALOG3", 2)]
    assert s.digitals[0].names[9] == "BREAKER A STATUS" and (s.digitals[0].normal, s.digitals[0].valid) == (
        0,
        0xFFFF,
    )
    data = c3.decode_frame(ANNEX_D1, cfg)
    (d,) = data.stations
    assert (data.soc, data.fracsec, d.stat) == (1149580800, 16817, 0)
    assert d.phasors[0] == pytest.approx(14635 * 9.15527)  # "133 987 V"
    assert abs(d.phasors[1]) == pytest.approx(134000, rel=2e-4)
    assert np.degrees(np.angle(d.phasors[1])) == pytest.approx(-120, abs=0.01)
    assert d.phasors[3] == pytest.approx(1092 * 0.45776)  # 500 A
    assert d.freq == pytest.approx(62.5) and d.dfreq == 0
    assert list(d.analogs) == [100.0, 1000.0, 10000.0] and list(d.digitals) == [0x3C12]
    cmd = c3.decode_frame(ANNEX_D3)
    assert cmd == c3.CommandFrame(7734, c3.CMD_ON, 1149591600, 0x0BBFD0, 0x0F)
    assert c3.encode(cfg) == ANNEX_D2 and c3.encode(data, cfg) == ANNEX_D1 and c3.encode(cmd) == ANNEX_D3


def test_stat_word_every_value_and_its_bits():
    for word in range(1 << 16):
        assert c3.Stat.from_word(word).word == word
    assert c3.Stat(data_error=c3.TEST_OR_ABSENT).word == 0x8000
    assert c3.Stat(data_error=c3.PMU_ERROR).word == 0xC000
    assert c3.Stat(data_error=c3.PMU_ERROR_NO_INFO).word == 0x4000
    bits = dict(sync_lost=13, by_arrival=12, trigger=11, config_change=10, data_modified=9)
    for name, bit in bits.items():
        assert c3.Stat(**{name: True}).word == 1 << bit
    assert c3.Stat(time_quality=5).word == 5 << 6 and c3.Stat(unlocked=3).word == 0x30
    assert c3.Stat(trigger_reason=0xF).word == 0xF
    assert c3.Stat().usable and not c3.Stat(sync_lost=True).usable and not c3.Stat(data_error=1).usable
    with pytest.raises(ValueError):
        _ = c3.Stat(time_quality=8).word


def test_time_quality_byte():
    for byte in range(128):
        assert c3.TimeQuality.from_byte(byte).byte == byte
    assert c3.TimeQuality(code=15).byte == 0x0F and c3.TimeQuality(leap_delete=True).byte == 0x40


@pytest.mark.parametrize("rate", [1, 10, 12, 15, 25, 30, 50, 60, 100, 120, 240])
def test_reporting_grid_is_exact(rate):
    for time_base in (1_000_000, 3_000_000, 16_777_215):
        for index in [*range(3 * rate), 1_700_000_000 * rate + 7, (2**32 - 1) * rate]:
            soc, frac = c3.grid_time(index, time_base, rate)
            assert frac < time_base
            assert c3.grid_index(soc, frac, time_base, rate) == index
            assert c3.grid_index(soc, frac + 1, time_base, rate) is None
    assert c3.grid_time(7, 1_000_000, 30) == (0, 233333)  # rounded half up
    assert c3.grid_index(10, 0, 1_000_000, -5) == 2 and c3.grid_index(11, 0, 1_000_000, -5) is None


# --- configurations and data frames from raw wire values --------------------------------------

F32 = st.floats(width=32, allow_nan=False, allow_infinity=False)
NAMES16 = ["", "V1", "I1", "Station A", "BREAKER 1 STATUS", " lead space", "0123456789abcdef"]
NAME16 = st.sampled_from(NAMES16)
NAME3 = st.sampled_from(NAMES16 + ["a name longer than sixteen bytes", "Gen ∠ 1 — Ærø", "x" * 255])
INT16 = st.integers(-32767, 32767)
SCALE32 = st.floats(2.0**-10, 2.0**10, width=32)
PI32 = float(np.nextafter(np.float32(np.pi), np.float32(0)))  # the largest float32 angle below pi
BIG32 = 2.0**100


@st.composite
def stations(draw, kind):
    three = kind == c3.CFG3
    name = draw(NAME3 if three else NAME16)
    chan = NAME3 if three else NAME16
    nph, nan, ndg = draw(st.integers(0, 3)), draw(st.integers(0, 2)), draw(st.integers(0, 1))
    phasors = []
    for _ in range(nph):
        if three:
            phasors.append(
                c3.PhasorChannel(
                    draw(chan),
                    draw(st.booleans()),
                    draw(SCALE32),
                    draw(st.sampled_from([0.0, 0.5, -1.25])),
                    draw(st.integers(0, 7)),
                    draw(st.integers(0, 0xFFFF)),
                    draw(st.integers(0, 255)),
                )
            )
        else:
            phasors.append(
                c3.PhasorChannel(draw(chan), draw(st.booleans()), draw(st.integers(1, 0xFFFFFF)) * 1e-5)
            )
    analogs = []
    for _ in range(nan):
        if three:
            analogs.append(
                c3.AnalogChannel(draw(chan), 1, draw(SCALE32), draw(st.floats(-1e3, 1e3, width=32)))
            )
        else:
            raw = draw(st.integers(-0x800000, 0x7FFFFF).filter(bool))
            analogs.append(c3.AnalogChannel(draw(chan), draw(st.integers(0, 255)), raw * 1e-5))
    digitals = [
        c3.DigitalWord(
            tuple(f"{draw(chan)[:12]}{b}" for b in range(16)),
            draw(st.integers(0, 0xFFFF)),
            draw(st.integers(0, 0xFFFF)),
        )
        for _ in range(ndg)
    ]
    flags = [draw(st.booleans()) for _ in range(4)]
    extra = {}
    if three:
        pos = st.one_of(F32, st.just(math.inf))
        extra = dict(
            g_pmu_id=draw(st.binary(min_size=16, max_size=16)),
            latitude=draw(pos),
            longitude=draw(pos),
            elevation=draw(pos),
            service_class=draw(st.sampled_from("MP")),
            window_us=draw(st.integers(-(2**31), 2**31 - 1)),
            group_delay_us=draw(st.integers(-(2**31), 2**31 - 1)),
        )
    return c3.StationConfig(
        name,
        draw(st.integers(0, 0xFFFF)),
        tuple(phasors),
        tuple(analogs),
        tuple(digitals),
        *flags,
        draw(st.sampled_from([50, 60])),
        draw(st.integers(0, 0xFFFF)),
        **extra,
    )


@st.composite
def configs(draw):
    kind = draw(st.sampled_from([c3.CFG1, c3.CFG2, c3.CFG3]))
    time_base = draw(st.integers(1, 0xFFFFFF))
    return c3.ConfigFrame(
        draw(st.integers(0, 0xFFFF)),
        tuple(draw(st.lists(stations(kind), min_size=1, max_size=3))),
        draw(st.integers(-32767, 32767).filter(bool)),
        time_base,
        draw(st.integers(0, 2**32 - 1)),
        draw(st.integers(0, time_base - 1)),
        draw(st.integers(0, 255)),
        kind,
    )


@st.composite
def raw_blocks(draw, cfg):
    """Raw wire values of one data frame, canonical (what the encoder writes)."""
    blocks = []
    for s in cfg.stations:
        ph = []
        for _ in s.phasors:
            if draw(st.integers(0, 9)) == 0:
                ph.append(("absent",))
            elif s.phasor_float and s.polar:
                mag = draw(st.floats(0, BIG32, width=32))
                ph.append((mag, draw(st.floats(-PI32, PI32, width=32)) + 0.0 if mag else 0.0))  # no -0.0
            elif s.phasor_float:
                ph.append(
                    (draw(st.floats(-BIG32, BIG32, width=32)), draw(st.floats(-BIG32, BIG32, width=32)))
                )
            elif s.polar:
                mag = draw(st.integers(0, 0xFFFF))
                ph.append((mag, draw(st.integers(-31415, 31415)) if mag else 0))
            else:
                ph.append((draw(INT16), draw(INT16)))
        if s.freq_float:
            fr = [draw(st.one_of(st.floats(-1e6, 1e6, width=32), st.just(math.nan))) for _ in range(2)]
        else:
            fr = [draw(st.one_of(INT16, st.just(c3.ABSENT))) for _ in range(2)]
        if s.analog_float:
            an = [draw(st.one_of(F32, st.just(math.nan))) for _ in s.analogs]
        else:
            an = [draw(st.one_of(INT16, st.just(c3.ABSENT))) for _ in s.analogs]
        blocks.append(
            (draw(st.integers(0, 0xFFFF)), ph, fr, an, [draw(st.integers(0, 0xFFFF)) for _ in s.digitals])
        )
    return blocks


def pack_data(cfg, blocks, soc, fracsec):
    """An independent packer of a data frame (Tables 5-6) from raw wire values."""
    body = b""
    for s, (stat, ph, fr, an, dg) in zip(cfg.stations, blocks):
        body += struct.pack(">H", stat)
        for p in ph:
            if s.phasor_float:
                body += struct.pack(">ff", math.nan, math.nan) if p == ("absent",) else struct.pack(">ff", *p)
            elif s.polar:
                body += struct.pack(">Hh", 0x8000, -32768) if p == ("absent",) else struct.pack(">Hh", *p)
            else:
                body += struct.pack(">hh", -32768, -32768) if p == ("absent",) else struct.pack(">hh", *p)
        body += struct.pack(">ff" if s.freq_float else ">hh", *fr)
        body += b"".join(struct.pack(">f" if s.analog_float else ">h", x) for x in an)
        body += b"".join(struct.pack(">H", x) for x in dg)
    head = struct.pack(">BBHHII", 0xAA, 0x01, 14 + len(body) + 2, cfg.idcode, soc, fracsec)
    frame = head + body
    return frame + struct.pack(">H", c3.crc_ccitt(frame))


def expected_values(cfg, blocks):
    """Engineering values of raw wire values, as the standard defines them (6.3, Table 11)."""
    out = []
    for s, (stat, ph, fr, an, dg) in zip(cfg.stations, blocks):
        z = []
        for p, ch in zip(ph, s.phasors):
            theta = ch.angle_offset if cfg.kind == c3.CFG3 else 0.0
            if p == ("absent",):
                z.append(complex(math.nan, math.nan))
            elif s.phasor_float:
                z.append(p[0] * np.exp(1j * p[1]) if s.polar else complex(p[0], p[1]))
            elif s.polar:
                z.append(p[0] * ch.scale * np.exp(1j * (p[1] * 1e-4 - theta)))
            else:
                z.append(complex(p[0] * ch.scale, p[1] * ch.scale) * np.exp(-1j * theta))
        if s.freq_float:
            f, d = fr
        else:
            f = math.nan if fr[0] == c3.ABSENT else s.fnom_hz + fr[0] * 1e-3
            d = math.nan if fr[1] == c3.ABSENT else fr[1] * 1e-2
        a = [
            x if s.analog_float else (math.nan if x == c3.ABSENT else x * ch.scale + ch.offset)
            for x, ch in zip(an, s.analogs)
        ]
        out.append((stat, z, f, d, a, dg))
    return out


@ROUND
@given(st.data())
def test_round_trip_every_configuration_type_and_format(data):
    cfg = data.draw(configs())
    wire = c3.encode(cfg)
    assert c3.decode_frame(wire) == cfg  # values, names, scales, flags, CFG-3's extras
    assert c3.encode(c3.decode_frame(wire)) == wire
    blocks = data.draw(raw_blocks(cfg))
    frac = data.draw(st.integers(0, cfg.time_base - 1))
    raw = pack_data(cfg, blocks, data.draw(st.integers(0, 2**32 - 1)), frac)
    frame = c3.decode_frame(raw, cfg)
    for sd, (stat, z, f, d, a, dg) in zip(frame.stations, expected_values(cfg, blocks)):
        assert sd.stat == stat and list(sd.digitals) == dg
        np.testing.assert_allclose(sd.phasors, np.array(z, complex), rtol=1e-12, atol=0)
        np.testing.assert_allclose([sd.freq, sd.dfreq, *sd.analogs], [f, d, *a], rtol=1e-12, atol=0)
    assert c3.encode(frame, cfg) == raw  # the encoder inverts the decoder exactly
    assert c3.decode_frame(c3.encode(frame, cfg), cfg) == frame


def test_every_format_combination_round_trips_values():
    """Values -> bytes -> the values as the format represents them, for all 16 FORMATs."""
    rng = np.random.default_rng(7)
    z = np.array([230e3 * np.exp(0.3j), 1.2e3 * np.exp(-2.9j), complex(np.nan, np.nan)])
    for fmt in range(16):
        s = c3.StationConfig(
            "S",
            3,
            (c3.PhasorChannel("V", False, 10.0), c3.PhasorChannel("I", True, 0.1), c3.PhasorChannel("X")),
            (c3.AnalogChannel("P", 1, 0.01),),
            polar=bool(fmt & 1),
            phasor_float=bool(fmt & 2),
            analog_float=bool(fmt & 4),
            freq_float=bool(fmt & 8),
            fnom_hz=60,
        )
        cfg = c3.ConfigFrame(3, (s,), 60)
        frame = c3.DataFrame(
            3,
            (c3.StationData(0x8000, z, 60.0123, -1.25, np.array([123.45])),),
            1_700_000_000,
            int(rng.integers(0, 1_000_000)),
        )
        back = c3.decode_frame(c3.encode(frame, cfg), cfg).stations[0]
        tol = 1e-6 if fmt & 2 else 0.5 * 10.0 * 1.01
        assert np.allclose(back.phasors[:2], z[:2], rtol=1e-6, atol=tol) and np.isnan(back.phasors[2])
        assert back.freq == pytest.approx(60.0123, abs=1e-5 if fmt & 8 else 5e-4)
        assert back.dfreq == pytest.approx(-1.25) and back.analogs[0] == pytest.approx(123.45, abs=5e-3)
        assert c3.encode(c3.decode_frame(c3.encode(frame, cfg), cfg), cfg) == c3.encode(frame, cfg)


def test_encoder_refuses_what_the_format_cannot_carry():
    s = c3.StationConfig("S", 1, (c3.PhasorChannel("V", scale=1e-5),), phasor_float=False, freq_float=False)
    cfg = c3.ConfigFrame(1, (s,), 50)
    for sd in (
        c3.StationData(0, np.array([1.0 + 0j]), 50.0, 0.0),  # 100000 counts
        c3.StationData(0, np.array([0.1 + 0j]), 90.0, 0.0),  # FREQ 40 Hz off
        c3.StationData(0, np.array([0.1 + 0j]), 50.0, 400.0),
    ):  # DFREQ x 100 beyond 16 bits
        with pytest.raises(ValueError, match="16-bit"):
            c3.encode(c3.DataFrame(1, (sd,)), cfg)
    with pytest.raises(ValueError, match="16 bytes"):
        c3.encode(c3.ConfigFrame(1, (c3.StationConfig("a name of twenty one", 1),), 50))
    with pytest.raises(ValueError, match="FRACSEC"):
        c3.encode(
            c3.DataFrame(1, (c3.StationData(),), fracsec=1_000_000),
            c3.ConfigFrame(1, (c3.StationConfig("S", 1),), 50),
        )
    big = c3.ConfigFrame(
        1,
        tuple(
            c3.StationConfig(f"station number {k}" * 4, k, (c3.PhasorChannel("V" * 30),)) for k in range(600)
        ),
        50,
        kind=c3.CFG3,
    )
    with pytest.raises(ValueError, match="fragments"):
        c3.encode(big)


def test_stations_decode_in_one_pass_as_one_by_one():
    """A concentrator whose stations share FORMAT and counts decodes as one record array; the
    result equals the per-station decoding, and ``arrays`` equals ``stations``."""
    cfg = _stream_config()
    raw = c3.encode(_data(cfg, 3), cfg)
    fast = c3.DataLayout(cfg)
    slow = c3.DataLayout(cfg)
    slow.uniform = False
    assert fast.uniform
    a, b = fast.arrays(raw[14:-2]), slow.arrays(raw[14:-2])
    for name in ("stat", "phasors", "freq", "dfreq", "analogs", "digitals"):
        assert np.array_equal(np.asarray(getattr(a, name)), np.asarray(getattr(b, name)), equal_nan=True), (
            name
        )
    frame = c3.decode_frame(raw, cfg)
    assert frame.stations == c3.DataFrame(7, arrays=b).stations
    assert np.array_equal(frame.arrays.phasors[1], frame.stations[1].phasors)


def test_polar_edges_come_back_as_sent():
    """A float polar angle of pi (float32 above pi) and an integer one of 31416 come back on the
    same side; the encoder writes within [-pi, pi] and +-31415."""
    for float_ph in (True, False):
        s = c3.StationConfig("S", 1, (c3.PhasorChannel("V", scale=1e-3),), phasor_float=float_ph)
        cfg = c3.ConfigFrame(1, (s,), 50)
        once = c3.encode(c3.DataFrame(1, (c3.StationData(0, np.array([-1.0 + 0j]), 50.0),)), cfg)
        again = c3.encode(c3.decode_frame(once, cfg), cfg)
        assert once == again


# --- fragments and the incremental decoder ------------------------------------------------------


def _stream_config(kind=c3.CFG2, cfgcnt=0, phasor_float=False):
    s = tuple(
        c3.StationConfig(
            f"PMU {k}",
            10 + k,
            (c3.PhasorChannel("V1", False, 10.0), c3.PhasorChannel("I1", True, 0.1)),
            (c3.AnalogChannel("P"),),
            (c3.DigitalWord(tuple("abcdefghijklmnop")),),
            phasor_float=phasor_float,
            cfgcnt=cfgcnt,
        )
        for k in range(3)
    )
    return c3.ConfigFrame(7, s, 50, kind=kind)


def _data(cfg, k):
    z = np.array([230e3 * np.exp(1j * k / 10), 1e3 * np.exp(1j * (k / 10 - 0.2))])
    sds = tuple(
        c3.StationData(0, z, 50 + k * 1e-3, 0.01 * k, np.array([float(k)]), np.array([k]))
        for _ in cfg.stations
    )
    soc, frac = c3.grid_time(1_700_000_000 * 50 + k, cfg.time_base, cfg.data_rate)
    return c3.DataFrame(7, sds, soc, frac)


def test_cfg3_fragments_join_in_order_only():
    cfg = c3.decode_frame(c3.encode(dataclasses_replace_names(_stream_config(c3.CFG3))))  # float32 scales
    parts = c3.encode_cfg3_fragments(cfg, 120)
    assert len(parts) >= 4 and all(len(p) <= 120 for p in parts)
    frags = [c3.decode_frame(p) for p in parts]
    assert [f.cont_idx for f in frags] == [*range(1, len(frags)), 0xFFFF]
    assert c3.join_cfg3(frags) == cfg
    dec = c3.StreamDecoder()
    assert dec.feed(b"".join(parts)) == [cfg]
    assert dec.feed(b"".join(parts[:2] + parts[3:])) == [] and dec.counts["field"] == len(parts) - 3
    assert c3.encode_cfg3_fragments(cfg) == [c3.encode(cfg)]  # one frame where it fits: CONT_IDX 0
    with pytest.raises(c3.FieldError):
        c3.join_cfg3(frags[::-1])


def dataclasses_replace_names(cfg):
    import dataclasses

    return dataclasses.replace(
        cfg,
        stations=tuple(dataclasses.replace(s, name=f"{s.name}, a long UTF-8 name ∠") for s in cfg.stations),
    )


def test_stream_decoder_chunks_garbage_crc_and_configuration_change():
    cfg = _stream_config()
    frames = [c3.encode(_data(cfg, k), cfg) for k in range(40)]
    stream = c3.encode(cfg) + b"".join(frames) + c3.encode(c3.HeaderFrame(7, "header"))
    whole = c3.StreamDecoder().feed(stream)
    assert len(whole) == 42 and whole[1] == _data(cfg, 0)
    for size in (1, 7, 100, 5000):
        dec = c3.StreamDecoder()
        got = [f for i in range(0, len(stream), size) for f in dec.feed(stream[i : i + size])]
        assert got == whole and not dec.buf and sum(v for k, v in dec.counts.items() if k != "frames") == 0
    # data before its configuration, garbage, a bad CRC, a FRAMESIZE corrupted upwards
    bad_crc = bytearray(frames[5])
    bad_crc[20] ^= 0x40
    big = bytearray(frames[9])
    big[2:4] = (4000).to_bytes(2, "big")
    mess = (
        frames[0]
        + b"\x00\xaa\x01junk"
        + c3.encode(cfg)
        + b"".join(frames[1:5])
        + bytes(bad_crc)
        + b"".join(frames[6:9])
        + bytes(big)
        + b"".join(frames[10:])
        + bytes(4000)
    )
    dec = c3.StreamDecoder()
    got = [f for i in range(0, len(mess), 333) for f in dec.feed(mess[i : i + 333])]
    data = [f for f in got if isinstance(f, c3.DataFrame)]
    assert data == [c3.decode_frame(frames[k], cfg) for k in range(1, 40) if k not in (5, 9)]
    # one each: the data frame before the configuration, the bad CRC; the false SYNC in the junk
    # and the FRAMESIZE of 4000 wait for bytes until a valid frame shows they are not frames
    assert (dec.counts["no_config"], dec.counts["crc"], dec.counts["length"]) == (1, 1, 2)
    assert dec.counts["skipped_bytes"] == 1 + 4000  # the 0x00 before the junk, the zeros at the end
    # a new configuration (CFGCNT 1, float phasors): old-layout frames no longer fit, new ones decode
    new = _stream_config(cfgcnt=1, phasor_float=True)
    dec.feed(c3.encode(new))
    assert dec.config(7) == new
    assert dec.feed(frames[0]) == [] and dec.counts["length"] == 3
    assert dec.feed(c3.encode(_data(new, 3), new)) == [c3.decode_frame(c3.encode(_data(new, 3), new), new)]


# --- fuzzing -------------------------------------------------------------------------------------


def _try(raw, cfg=None):
    """Decode; a frame that decodes must encode and decode again (values a peer can be sent)."""
    try:
        frame = c3.decode_frame(raw, cfg)
    except c3.FrameError as err:
        return err.kind
    if isinstance(frame, c3.DataFrame):
        assert c3.decode_frame(c3.encode(frame, cfg), cfg) is not None
    elif not isinstance(frame, c3.Cfg3Fragment):
        assert c3.decode_frame(c3.encode(frame)) is not None
    return "frame"


@FUZZ
@given(st.binary(max_size=400))
def test_fuzz_random_bytes(raw):
    assert _try(raw, _stream_config()) in ("frame", "length", "type", "crc", "field", "no_config")
    dec = c3.StreamDecoder()
    dec.feed(raw)
    assert len(dec.buf) <= len(raw)


@pytest.mark.slow
@FUZZ
@given(st.integers(0, 7), st.integers(0, 15), st.integers(0, 0xFFFF), st.binary(max_size=600))
def test_fuzz_random_bodies_with_a_valid_crc(ftype, version, idcode, body):
    """Past the CRC: every field of every frame type with random contents."""
    head = struct.pack(">BBHH", 0xAA, ftype << 4 | version, 14 + len(body) + 2, idcode) + bytes(8)
    frame = (head + body)[: 14 + len(body)]
    frame += struct.pack(">H", c3.crc_ccitt(frame))
    cfg = _stream_config()
    kind = _try(frame, cfg if idcode == 7 else None)
    assert kind in ("frame", "length", "type", "field", "no_config")


@ROUND
@given(st.data())
def test_fuzz_mutated_valid_frames(data):
    cfg = data.draw(configs())
    blocks = data.draw(raw_blocks(cfg))
    pool = [
        c3.encode(cfg),
        pack_data(cfg, blocks, 5, 0),
        c3.encode(c3.CommandFrame(cfg.idcode, data.draw(st.integers(0, 0xFFFF)), extended=b"xy")),
        c3.encode(c3.HeaderFrame(cfg.idcode, "text")),
    ]
    raw = bytearray(data.draw(st.sampled_from(pool)))
    for _ in range(data.draw(st.integers(1, 4))):
        op = data.draw(st.sampled_from(["flip", "cut", "grow", "size"]))
        if op == "flip" and raw:
            i = data.draw(st.integers(0, len(raw) - 1))
            raw[i] ^= data.draw(st.integers(1, 255))
        elif op == "cut":
            del raw[data.draw(st.integers(0, len(raw))) :]
        elif op == "grow":
            raw += data.draw(st.binary(min_size=1, max_size=40))
        elif op == "size" and len(raw) >= 4:
            raw[2:4] = data.draw(st.integers(0, 0xFFFF)).to_bytes(2, "big")
    if data.draw(st.booleans()) and len(raw) >= 16:  # fix the CRC: reach the fields behind it
        raw[2:4] = len(raw).to_bytes(2, "big")
        raw[-2:] = c3.crc_ccitt(bytes(raw[:-2])).to_bytes(2, "big")
    assert _try(bytes(raw), cfg) in ("frame", "length", "type", "crc", "field", "no_config")


def fuzz_stream(n_frames: int, seed: int = 0):
    """A seeded run for the record: valid frames, each mutated with probability 1/2 (flips,
    cuts, growth, FRAMESIZE, half of them with a fixed CRC), with garbage between, fed in random
    chunks. Returns (frames tried, mutated, decoded, counts, largest buffer)."""
    rng = np.random.default_rng(seed)
    cfg = _stream_config()
    valid = [c3.encode(cfg)] + [c3.encode(_data(cfg, k % 200), cfg) for k in range(200)]
    dec = c3.StreamDecoder()
    dec.feed(valid[0])
    pieces, mutated = [], 0
    for _ in range(n_frames):
        raw = bytearray(valid[int(rng.integers(1, len(valid)))])
        if rng.random() < 0.5:
            mutated += 1
            op = rng.integers(0, 4)
            if op == 0:
                for i in rng.integers(0, len(raw), size=int(rng.integers(1, 4))):
                    raw[int(i)] ^= int(rng.integers(1, 256))
            elif op == 1:
                del raw[int(rng.integers(0, len(raw))) :]
            elif op == 2:
                raw[2:4] = int(rng.integers(0, 0x10000)).to_bytes(2, "big")
            else:
                raw += rng.integers(0, 256, size=int(rng.integers(1, 50))).astype(np.uint8).tobytes()
            if rng.random() < 0.5 and len(raw) >= 16:
                raw[2:4] = len(raw).to_bytes(2, "big")
                raw[-2:] = c3.crc_ccitt(bytes(raw[:-2])).to_bytes(2, "big")
        pieces.append(bytes(raw))
        if rng.random() < 0.1:
            pieces.append(rng.integers(0, 256, size=int(rng.integers(1, 64))).astype(np.uint8).tobytes())
    stream = b"".join(pieces) + bytes(70000)
    decoded, largest, i = 0, 0, 0
    while i < len(stream):
        n = int(rng.integers(1, 3000))
        decoded += sum(isinstance(f, c3.DataFrame) for f in dec.feed(stream[i : i + n]))
        largest = max(largest, len(dec.buf))
        i += n
    return n_frames, mutated, decoded, dec.counts, largest


def test_fuzz_stream_counts_and_bounded_memory():
    tried, mutated, decoded, counts, largest = fuzz_stream(3000)
    assert decoded >= tried - mutated  # every untouched frame comes through (the CRC catches the rest)
    assert decoded <= tried
    assert counts["crc"] + counts["length"] + counts["field"] > 0.3 * mutated
    assert largest <= c3.MAX_FRAME
