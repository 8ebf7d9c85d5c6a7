"""Interop: the codec's frames against an independent decoder, Wireshark's ``synphasor``
dissector. The test writes a pcap (Ethernet, IPv4, TCP on port 4712, each frame in segments of
at most 1400 bytes, one TCP conversation per configuration), runs ``tshark -T pdml`` on it
once, and checks, for every FORMAT combination (polar/rectangular x phasors, analogs,
FREQ/DFREQ each integer or float: 16) under CFG-2 and under CFG-3, and for a concentrator
carrying all 16 at once: every frame is dissected with a good checksum and no malformed field;
the configuration's fields are what was encoded; every data frame is dissected with that
configuration, and its STAT bits, phasors (the raw integers exactly, the scaled values to the
dissector's printed precision), FREQ, DFREQ, analogs and digital words equal the codec's
decoding; command, header and CFG-3 fragment frames are dissected with a good checksum.
Skipped only where tshark is absent (``apt-get install tshark``; CI installs it)."""

import math
import re
import shutil
import struct
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from jaxdse._stream import c37118 as c3

TSHARK = shutil.which("tshark")
pytestmark = pytest.mark.skipif(
    TSHARK is None, reason="tshark (Wireshark's synphasor dissector) is not installed"
)

SERVER, CLIENT = bytes([127, 0, 0, 1]), bytes([127, 0, 0, 2])
SEGMENT = 1400
ALLOWED_EXPERT = {"Data Error flag set", "PMU not sync flag set"}
"""Expert notes the dissector adds for STAT bits the frames set on purpose."""


# --- a minimal pcap writer ----------------------------------------------------------------------


def write_pcap(path, conversations):
    """``conversations``: [(client port, [(from_server, frame bytes), ...]), ...] as TCP streams to
    and from 127.0.0.1:4712, each opened with a handshake."""
    out = [struct.pack("<IHHiIII", 0xA1B2C3D4, 2, 4, 0, 0, 65535, 1)]  # pcap, Ethernet
    clock = [0]

    def packet(src, dst, sport, dport, seq, ack, flags, payload=b""):
        tcp = struct.pack(">HHIIBBHHH", sport, dport, seq, ack, 5 << 4, flags, 65535, 0, 0) + payload
        ip = struct.pack(">BBHHHBBH4s4s", 0x45, 0, 20 + len(tcp), 0, 0x4000, 64, 6, 0, src, dst)
        words = sum(struct.unpack(">10H", ip))
        while words >> 16:
            words = (words & 0xFFFF) + (words >> 16)
        ip = ip[:10] + struct.pack(">H", ~words & 0xFFFF) + ip[12:]
        frame = bytes(6) + bytes([2, 0, 0, 0, 0, 1]) + b"\x08\x00" + ip + tcp
        clock[0] += 1
        out.append(
            struct.pack(
                "<IIII", 1_700_000_000 + clock[0] // 1000, clock[0] % 1000 * 1000, len(frame), len(frame)
            )
            + frame
        )

    for port, frames in conversations:
        seq = {False: 1000, True: 5000}
        packet(CLIENT, SERVER, port, c3.TCP_PORT, seq[False], 0, 0x02)
        seq[False] += 1
        packet(SERVER, CLIENT, c3.TCP_PORT, port, seq[True], seq[False], 0x12)
        seq[True] += 1
        packet(CLIENT, SERVER, port, c3.TCP_PORT, seq[False], seq[True], 0x10)
        for from_server, data in frames:
            for i in range(0, len(data), SEGMENT):
                piece = data[i : i + SEGMENT]
                ends = (
                    (SERVER, CLIENT, c3.TCP_PORT, port)
                    if from_server
                    else (CLIENT, SERVER, port, c3.TCP_PORT)
                )
                packet(*ends, seq[from_server], seq[not from_server], 0x18, piece)
                seq[from_server] += len(piece)
    path.write_bytes(b"".join(out))


def dissect(path) -> dict:
    """tshark's synphasor PDUs per client port, in order."""
    xml = subprocess.run(
        [TSHARK, "-r", str(path), "-d", f"tcp.port=={c3.TCP_PORT},synphasor", "-T", "pdml"],
        capture_output=True,
        check=True,
        timeout=120,
    ).stdout
    pdus: dict = {}
    for packet in ET.fromstring(xml).iter("packet"):
        assert packet.find(".//field[@name='_ws.malformed']") is None, "tshark: malformed packet"
        tcp = packet.find("proto[@name='tcp']")
        ports = [
            int(f.get("show")) for f in tcp.iter("field") if f.get("name") in ("tcp.srcport", "tcp.dstport")
        ]
        port = next(p for p in ports if p != c3.TCP_PORT)
        pdus.setdefault(port, []).extend(packet.findall("proto[@name='synphasor']"))
    return pdus


# --- what to send ---------------------------------------------------------------------------------


def station(fmt: int, kind: int, k: int = 0) -> c3.StationConfig:
    three = kind == c3.CFG3
    return c3.StationConfig(
        f"PMU {fmt:02d}" + (" with a long CFG-3 name" if three else ""),
        100 + k,
        (
            c3.PhasorChannel("V1", False, 10.0, 0.25 if three else 0.0),
            c3.PhasorChannel(
                "I1 phase A" if three else "I1", True, 0.1 if not three else 0.125, 0.0, 4, 0x0042, 7
            ),
        ),
        (
            c3.AnalogChannel("P MW", 1, 0.05),
            c3.AnalogChannel("Q Mvar", 2, 0.25 if three else 0.02, -1.5 if three else 0.0),
        ),
        (c3.DigitalWord(tuple(f"breaker {b}" for b in range(16)), 0x00F0, 0xFF0F),),
        polar=bool(fmt & 1),
        phasor_float=bool(fmt & 2),
        analog_float=bool(fmt & 4),
        freq_float=bool(fmt & 8),
        fnom_hz=(50, 60)[fmt % 2],
        cfgcnt=fmt * 3,
        latitude=47.25 if three else math.inf,
        longitude=-122.5 if three else math.inf,
        elevation=math.inf,
        service_class="MP"[fmt % 2],
        window_us=40_000,
        group_delay_us=-20_000,
        g_pmu_id=bytes(range(fmt, fmt + 16)),
    )


STATS = [0x0000, 0x2000 | 0x01C0, 0x0800 | 0x0005, 0x8000, 0x0400 | 0x0200 | 0x0030, 0xC000 | 0x1000 | 0x000F]


def data_frames(cfg, n=len(STATS)):
    """``n`` data frames: values that move, frame 3 absent (NaN, 0x8000), each STAT field set somewhere."""
    frames = []
    for j in range(n):
        stations = []
        for s in cfg.stations:
            fnom = s.fnom_hz
            z = np.array([230e3 * np.exp(1j * (0.4 * j - 1.3)), 1.1e3 * np.exp(1j * (2.9 - 1.1 * j))])
            an = np.array([512.25 - 40 * j, -37.5 + 3 * j])
            f, d = fnom + 0.0137 * (j - 2), 0.25 * (j - 3)
            if STATS[j] == 0x8000:
                z, an, f, d = np.full(2, complex(np.nan, np.nan)), np.full(2, np.nan), math.nan, math.nan
            stations.append(c3.StationData(STATS[j], z, f, d, an, np.array([0x3C12 + j])))
        soc, frac = c3.grid_time(1_700_000_000 * 50 + 7 + j, cfg.time_base, cfg.data_rate)
        frames.append(c3.DataFrame(cfg.idcode, tuple(stations), soc, frac, tq=(0, 0x4A, 0x0F, 0x31, 0, 0)[j]))
    return frames


# --- comparing --------------------------------------------------------------------------------

PHASOR = re.compile(
    r'Phasor #\d+: "(?P<name>.*)", +(?P<mag>\S+?)(?P<unit>[VA]) ∠ *(?P<ang>\S+)° '
    r"alt +(?P<re>\S+?)\+j *(?P<im>\S+?)[VA](?:; unscaled: *(?P<u1>\S+), *(?P<u2>\S+))?$"
)


def fields(pdu, name):
    return [f for f in pdu.iter("field") if f.get("name") == name]


def one(pdu, name, attr="show"):
    (f,) = fields(pdu, name)
    return f.get(attr)


def near(a, b, tol):
    return (math.isnan(a) and math.isnan(b)) or abs(a - b) <= tol + 1e-9 * abs(b)


def check_common(pdu, raw: bytes, frame):
    assert one(pdu, "synphasor.checksum.status") == "1", "checksum not good"
    for expert in pdu.iter("field"):
        if expert.get("name") == "_ws.expert.message":
            assert expert.get("show") in ALLOWED_EXPERT, expert.get("show")
    assert int(one(pdu, "synphasor.frtype", "value"), 16) == raw[1] >> 4
    assert int(one(pdu, "synphasor.version", "value"), 16) == raw[1] & 15
    assert int(one(pdu, "synphasor.frsize")) == len(raw)
    assert int(one(pdu, "synphasor.idcode_stream_source")) == frame.idcode
    assert int(one(pdu, "synphasor.soc", "value"), 16) == frame.soc
    assert int(one(pdu, "synphasor.fracsec_raw")) == frame.fracsec
    tq = c3.TimeQuality.from_byte(frame.tq)
    assert int(one(pdu, "synphasor.timeqal.timequalindic", "value"), 16) == tq.code
    assert (
        one(pdu, "synphasor.timeqal.lsdir"),
        one(pdu, "synphasor.timeqal.lsocc"),
        one(pdu, "synphasor.timeqal.lspend"),
    ) == tuple(str(int(b)) for b in (tq.leap_delete, tq.leap_occurred, tq.leap_pending))


def check_config(pdu, cfg: c3.ConfigFrame):
    three = cfg.kind == c3.CFG3
    assert int(one(pdu, "synphasor.conf.timebase")) == cfg.time_base
    assert int(one(pdu, "synphasor.conf.numpmu")) == len(cfg.stations)
    assert int(one(pdu, "synphasor.rate_of_transmission")) == cfg.data_rate
    if three:
        assert int(one(pdu, "synphasor.conf.contindx")) == 0
    ss = cfg.stations
    fmt = [
        [int(f.get("value"), 16) for f in fields(pdu, f"synphasor.conf.{n}")]
        for n in ("dfreq_format", "analog_format", "phasor_format", "phasor_notation")
    ]
    assert [list(x) for x in zip(*fmt)] == [
        [s.freq_float, s.analog_float, s.phasor_float, s.polar] for s in ss
    ]
    assert [int(f.get("show")) for f in fields(pdu, "synphasor.idcode_data_source")] == [s.idcode for s in ss]
    assert [int(f.get("show")) for f in fields(pdu, "synphasor.num_phasors")] == [len(s.phasors) for s in ss]
    assert [int(f.get("show")) for f in fields(pdu, "synphasor.num_analog_values")] == [
        len(s.analogs) for s in ss
    ]
    assert [int(f.get("show")) for f in fields(pdu, "synphasor.num_digital_status_words")] == [
        len(s.digitals) for s in ss
    ]
    assert [int(f.get("value"), 16) for f in fields(pdu, "synphasor.conf.fnom")] == [
        s.fnom_hz == 50 for s in ss
    ]
    assert [int(f.get("show")) for f in fields(pdu, "synphasor.conf.cfgcnt")] == [s.cfgcnt for s in ss]
    names = [
        n
        for s in ss
        for n in [p.name for p in s.phasors]
        + [a.name for a in s.analogs]
        + [x for d in s.digitals for x in d.names]
    ]
    masks = [(d.normal, d.valid) for s in ss for d in s.digitals]
    got_masks = list(
        zip(
            [int(f.get("value"), 16) for f in fields(pdu, "synphasor.status_word_mask.normal_state")],
            [int(f.get("value"), 16) for f in fields(pdu, "synphasor.status_word_mask.valid_bits")],
        )
    )
    assert got_masks == masks
    phasors = [p for s in ss for p in s.phasors]
    analogs = [a for s in ss for a in s.analogs]
    if not three:
        assert [f.get("show").rstrip(" ") for f in fields(pdu, "synphasor.channel_name")] == names
        conv = [int(f.get("value"), 16) for f in fields(pdu, "synphasor.conversion_factor")]
        assert conv == [p.current << 24 | round(p.scale * 1e5) for p in phasors]
        an = [int(f.get("unmaskedvalue"), 16) for f in fields(pdu, "synphasor.factor_for_analog_value")]
        assert an == [a.kind << 24 | round(a.scale * 1e5) & 0xFFFFFF for a in analogs]
        return
    assert [f.get("show") for f in fields(pdu, "synphasor.station_name")] == [s.name for s in ss]
    assert [bytes.fromhex(f.get("value")) for f in fields(pdu, "synphasor.gpmuid")] == [
        s.g_pmu_id for s in ss
    ]
    assert [f.get("show") for f in fields(pdu, "synphasor.conf.chnam")] == names
    assert [int(f.get("value"), 16) for f in fields(pdu, "synphasor.conf.phasor_type")] == [
        p.current for p in phasors
    ]
    assert [int(f.get("value"), 16) for f in fields(pdu, "synphasor.conf.phasor_component")] == [
        p.component for p in phasors
    ]
    f32 = [
        ("phasor_scale_factor", [p.scale for p in phasors]),
        ("phasor_angle_offset", [p.angle_offset for p in phasors]),
        ("analog_scale_factor", [a.scale for a in analogs]),
        ("analog_offset", [a.offset for a in analogs]),
    ]
    for name, want in f32:
        got = [
            struct.unpack(">f", bytes.fromhex(f.get("value")))[0]
            for f in fields(pdu, f"synphasor.conf.{name}")
        ]
        assert got == [float(np.float32(x)) for x in want], name
    for name, attr in (
        ("pmu_latitude", "latitude"),
        ("pmu_longitude", "longitude"),
        ("pmu_elevation", "elevation"),
    ):
        got = [
            struct.unpack(">f", bytes.fromhex(f.get("value")))[0]
            for f in fields(pdu, f"synphasor.conf.{name}")
        ]
        assert got == [float(np.float32(getattr(s, attr))) for s in ss]
    assert [f.get("show") for f in fields(pdu, "synphasor.conf.svc_class")] == [
        {"M": "Monitoring", "P": "Protection"}[s.service_class] for s in ss
    ]
    assert [int(f.get("show")) % 2**32 for f in fields(pdu, "synphasor.conf.window")] == [
        s.window_us % 2**32 for s in ss
    ]
    assert [int(f.get("show")) % 2**32 for f in fields(pdu, "synphasor.conf.grp_dly")] == [
        s.group_delay_us % 2**32 for s in ss
    ]


def check_data(pdu, raw: bytes, cfg: c3.ConfigFrame, frame: c3.DataFrame):
    assert fields(pdu, "synphasor.data.conf_frame"), "dissected without its configuration"
    rec = np.frombuffer(raw[14:-2], c3.DataLayout.of(cfg).dtype)[0]
    stat_fields = [
        fields(pdu, f"synphasor.data.{n}")
        for n in (
            "status",
            "sync",
            "sorting",
            "trigger",
            "CFGchange",
            "data_modified",
            "pmu_tq",
            "t_unlock",
            "trigger_reason",
        )
    ]
    phasors = [PHASOR.match(f.get("showname")) for f in fields(pdu, "synphasor.phasor")]
    assert all(phasors), [f.get("showname") for f in fields(pdu, "synphasor.phasor")]
    analogs = fields(pdu, "synphasor.analog_value")
    digitals = fields(pdu, "synphasor.digital_status_word")
    ff = iter(fields(pdu, "synphasor.actual_frequency_value"))  # the stations with float FREQ
    fi = iter(fields(pdu, "synphasor.frequency_deviation_from_nominal"))  # with integer FREQ
    fd = fields(pdu, "synphasor.rate_change_frequency")
    ip = ia = 0
    for k, (s, sd) in enumerate(zip(cfg.stations, frame.stations)):
        st = c3.Stat.from_word(sd.stat)
        got = [int(x[k].get("value"), 16) for x in stat_fields]
        assert got == [
            st.data_error,
            st.sync_lost,
            st.by_arrival,
            st.trigger,
            st.config_change,
            st.data_modified,
            st.time_quality,
            st.unlocked,
            st.trigger_reason,
        ], (k, hex(sd.stat))
        for j, (ch, z) in enumerate(zip(s.phasors, sd.phasors)):
            m = phasors[ip]
            ip += 1
            assert m["name"].rstrip(" ") == ch.name and m["unit"] == ("A" if ch.current else "V"), m[0]
            assert near(float(m["mag"]), abs(z), 6e-4) and near(float(m["re"]), z.real, 6e-4), (m[0], z)
            assert near(float(m["im"]), z.imag, 6e-4), (m[0], z)
            if not math.isnan(abs(z)) and abs(z) > 1e-2:
                dang = (float(m["ang"]) - np.degrees(np.angle(z)) + 180) % 360 - 180
                assert abs(dang) <= 6e-4
            if not s.phasor_float:
                u = rec[f"{k}p"][j]
                want = [float(u["a"]), float(u["b"])]
                if s.polar and want[1] == c3.ABSENT or not s.polar and c3.ABSENT in want:
                    want = [math.nan if (s.polar or w == c3.ABSENT) else w for w in want]
                assert [float(m["u1"]), float(m["u2"])] == pytest.approx(want, nan_ok=True)
        if s.freq_float:
            f_t = struct.unpack(">f", bytes.fromhex(next(ff).get("value")))[0]
            assert near(f_t, sd.freq, 0), (f_t, sd.freq)
            d_t = struct.unpack(">f", bytes.fromhex(fd[k].get("value")))[0]
        else:
            # integer 0x8000 is absent data (6.3.1): the dissector prints it as a number
            mhz = int(next(fi).get("show"))
            assert mhz == int(rec[f"{k}f"]), mhz
            assert near(s.fnom_hz + mhz / 1000, sd.freq, 1e-9) or (mhz == c3.ABSENT and math.isnan(sd.freq))
            d_t = float(fd[k].get("show"))
            if int(rec[f"{k}d"]) == c3.ABSENT:
                assert d_t == c3.ABSENT / 100 and math.isnan(sd.dfreq)
                d_t = math.nan
        assert near(d_t, sd.dfreq, 1e-6), (d_t, sd.dfreq)
        for j, (ch, x) in enumerate(zip(s.analogs, sd.analogs)):
            text = analogs[ia].get("showname")
            ia += 1
            assert text.startswith(f'Analog value #{j + 1}: "{ch.name}'), text
            value = text.split('", ', 1)[1]
            absent = not s.analog_float and int(rec[f"{k}a"][j]) == c3.ABSENT
            assert not absent or math.isnan(x)
            if not s.analog_float and cfg.kind != c3.CFG3:  # CFG-2: the raw count and ANUNIT
                count = int(value.split(" ")[0])
                assert count == int(rec[f"{k}a"][j]) and (absent or near(count * ch.scale, x, 1e-9)), (
                    text,
                    x,
                )
            elif not absent:
                assert near(float(value), x, 6e-4 + 1e-6 * abs(x)), (text, x)
        assert [int(d.get("show"), 16) for d in digitals[k : k + 1]] == list(sd.digitals)


def interop(tmp_path) -> list[dict]:
    """Every conversation's frames through tshark; one row per FORMAT combination and
    configuration type (plus the concentrator, commands and fragments), with any error."""
    plans = []  # (label, fmt, kind, [(from_server, bytes, frame, cfg or None)])
    for kind in (c3.CFG2, c3.CFG3):
        for fmt in range(16):
            cfg = c3.ConfigFrame(
                40 + fmt, (station(fmt, kind),), 50, soc=1_700_000_000, fracsec=123_456, tq=0x5A, kind=kind
            )
            cfg = c3.decode_frame(c3.encode(cfg))  # CFG-3 scales as float32, the values data decode with
            plans.append(
                (
                    f"FORMAT 0x{fmt:X}",
                    fmt,
                    kind,
                    [(True, c3.encode(cfg), cfg, None)]
                    + [(True, c3.encode(f, cfg), f, cfg) for f in data_frames(cfg)],
                )
            )
        cfg = c3.decode_frame(
            c3.encode(
                c3.ConfigFrame(
                    7, tuple(station(f, kind, f) for f in range(16)), 60, kind=kind, soc=1_700_000_001
                )
            )
        )
        plans.append(
            (
                "all 16 in one concentrator",
                None,
                kind,
                [(True, c3.encode(cfg), cfg, None)]
                + [(True, c3.encode(f, cfg), f, cfg) for f in data_frames(cfg)],
            )
        )
    commands = [c3.CommandFrame(7, cmd, 1_700_000_002, 10, 0) for cmd in (1, 2, 3, 4, 5, 6, 0x0100)]
    commands.append(c3.CommandFrame(7, 8, extended=b"\x00\x01\x02\x03"))
    plans.append(
        (
            "commands and header",
            None,
            None,
            [(False, c3.encode(c), c, None) for c in commands]
            + [(True, c3.encode(c3.HeaderFrame(7, "jaxdse pmu-sim test header")), None, None)],
        )
    )
    big = c3.ConfigFrame(9, tuple(station(f, c3.CFG3, f) for f in range(16)), 50, kind=c3.CFG3)
    plans.append(
        (
            "CFG-3 in fragments",
            None,
            c3.CFG3,
            [(True, b, None, None) for b in c3.encode_cfg3_fragments(big, 700)],
        )
    )
    conversations = [
        (40000 + i, [(srv, raw) for srv, raw, _, _ in frames]) for i, (_, _, _, frames) in enumerate(plans)
    ]
    pcap = tmp_path / "c37118.pcap"
    write_pcap(pcap, conversations)
    pdus = dissect(pcap)
    rows = []
    for i, (label, fmt, kind, frames) in enumerate(plans):
        got = pdus.get(40000 + i, [])
        row = {
            "label": label,
            "fmt": fmt,
            "kind": {None: "-", c3.CFG2: "CFG-2", c3.CFG3: "CFG-3"}[kind],
            "frames": len(frames),
            "dissected": len(got),
            "error": None,
        }
        try:
            assert len(got) == len(frames), f"{len(got)} PDUs for {len(frames)} frames"
            for pdu, (_, raw, frame, cfg) in zip(got, frames):
                if frame is None:  # the header, the CFG-3 fragments
                    assert one(pdu, "synphasor.checksum.status") == "1"
                    continue
                check_common(pdu, raw, frame)
                if isinstance(frame, c3.ConfigFrame):
                    check_config(pdu, frame)
                elif isinstance(frame, c3.DataFrame):  # tshark's values against the codec's decoding
                    check_data(pdu, raw, cfg, c3.decode_frame(raw, cfg))
                else:
                    assert int(one(pdu, "synphasor.command", "value"), 16) == frame.cmd
        except AssertionError as err:
            import traceback

            row["error"] = f"line {traceback.extract_tb(err.__traceback__)[-1].lineno}: {err}"[:300]
        rows.append(row)
    return rows


def test_tshark_dissects_every_format_combination(tmp_path):
    rows = interop(tmp_path)
    assert len([r for r in rows if r["fmt"] is not None]) == 32
    bad = [r for r in rows if r["error"]]
    assert not bad, bad
