"""The loopback PMU (jaxdse._stream.pmu_sim, ``jaxdse pmu-sim``) with its small client, on
127.0.0.1 only: a client connects, asks for CFG-2 (and CFG-1, CFG-3, the header), turns data
on, reads frames whose timestamps lie on the recording's grid and whose values are the
recording file's own, and turns data off; every injected fault shows up as the standard
says; a fleet file's plants are stations of one concentrator; UDP; and the command line,
which ends by itself (--duration). Every wait is bounded; the recording is the shipped
example's first 40 s."""

import math
import re
import subprocess
import sys
import time

import numpy as np
import pytest
from builders import example_cut

from jaxdse._app.sources import load_source
from jaxdse._stream import c37118 as c3
from jaxdse._stream import pmu_sim

ROOT = __import__("pathlib").Path(__file__).resolve().parents[2]
ROWS = 1000  # 40 s at 25 frames/s


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """The example run configuration on the first 40 s of its CSV: (config path, CSV columns)."""
    run = example_cut(tmp_path_factory.mktemp("pmu"), ROWS)
    return run, np.loadtxt(run.parent / "pmu.csv", delimiter=",", skiprows=1)


@pytest.fixture(scope="module")
def source(recording):
    return load_source(recording[0])


def _in_file(raw):
    """The CSV's own phasors in the served units: V phase to neutral [V] (V1_kV is kV_LL, base
    400 kV), I [A], angles in degrees, and the frequency [Hz]."""
    v = raw[:, 2] * 1e3 / math.sqrt(3) * np.exp(1j * np.radians(raw[:, 3]))
    i = raw[:, 4] * np.exp(1j * np.radians(raw[:, 5]))
    return v, i, raw[:, 1]


def test_loopback_client_reads_the_recording_on_its_grid(recording, source):
    v, i, f = _in_file(recording[1])
    server = pmu_sim.PmuServer(source, port=0, speed=40.0, start="recording", idcode=17)
    with server.serve_in_thread() as (host, port):
        assert host == "127.0.0.1"
        with pmu_sim.PmuClient(host, port, 17, timeout=5.0) as pmu:
            cfg = pmu.config(c3.CFG2)
            assert (cfg.idcode, cfg.data_rate, cfg.time_base) == (17, 25, 1_000_000)
            (st,) = cfg.stations
            assert (st.name, st.fnom_hz, [p.name for p in st.phasors]) == ("unit1", 50, ["V1", "I1"])
            assert pmu.config(c3.CFG1).stations == cfg.stations
            assert pmu.config(c3.CFG3).stations[0].name == "unit1"
            assert "V1 positive-sequence voltage [V, phase to neutral, RMS]" in pmu.header()
            pmu.start()
            frames = [x for x in pmu.frames(count=60, seconds=10) if isinstance(x, c3.DataFrame)]
            pmu.stop()
            # the frames in flight when 'off' arrived (how many depends on the machine's load),
            # then none: transmission stops within a bounded time
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline:
                late = [x for x in pmu.frames(seconds=0.5) if isinstance(x, c3.DataFrame)]
                if not late:
                    break
            assert not late
    assert len(frames) == 60
    index = [c3.grid_index(x.soc, x.fracsec, cfg.time_base, cfg.data_rate) for x in frames]
    assert None not in index and np.all(np.diff(index) == 1)  # on the grid, none missing
    k = np.array(index) - index[0]
    k0 = index[0] - source.first_index  # --start recording: the file's time column is the time
    assert 0 <= k0 < ROWS - 60
    got = np.array([x.stations[0].phasors for x in frames])
    assert np.allclose(got[:, 0], v[k0 + k], rtol=2e-7) and np.allclose(got[:, 1], i[k0 + k], rtol=2e-7)
    assert np.allclose([x.stations[0].freq for x in frames], f[k0 + k], rtol=1e-7)
    assert all(x.stations[0].stat == 0 for x in frames)
    assert pmu.decoder.counts["crc"] == pmu.decoder.counts["length"] == 0


def test_every_fault_shows_as_the_standard_says(source):
    rate = source.rate
    faults = [
        pmu_sim.Fault.parse(s)
        for s in (
            "stale@0.2+0.08",
            "error@0.4+0.2",
            "sync@0.8",
            "trigger=4@0.88",
            "time-quality=5@0.96",
            "absent@1.0+0.12",
            "clock=11@1.12",
            "drop@1.2+0.2",
            "late=0.2@1.6+0.08",
            "crc@1.8",
            "config-change=0.4@2.4",
            "disconnect@3.2",
        )
    ]
    server = pmu_sim.PmuServer(source, port=0, speed=20.0, start="now", faults=faults)
    t_wall = time.time()
    with server.serve_in_thread() as (host, port):
        with pmu_sim.PmuClient(host, port, 1, timeout=5.0) as pmu:
            pmu.config()
            pmu.start()
            seen = []
            for x in pmu.frames(seconds=8):  # ends at the disconnect
                if isinstance(x, c3.DataFrame):  # with the configuration it was decoded with
                    seen.append((x, pmu.decoder.config(1)))
            counts = dict(pmu.decoder.counts)
        # after the disconnect the stream goes on: a new client gets frames
        with pmu_sim.PmuClient(host, port, 1, timeout=5.0) as again:
            again.config()
            again.start()
            after = [x for x in again.frames(count=3, seconds=5) if isinstance(x, c3.DataFrame)]
    first = seen[0][0]
    t0 = c3.grid_index(first.soc, first.fracsec, 1_000_000, rate)
    assert abs(first.soc - t_wall) < 5  # --start now: the present, on the grid
    by_t = {}
    order = []
    for x, c in seen:
        n = c3.grid_index(x.soc, x.fracsec, c.time_base, rate)
        assert n is not None
        t = round((n - t0) / rate, 6)
        by_t[t] = (x, c)
        order.append(t)

    def stat(t):
        return c3.Stat.from_word(by_t[t][0].stations[0].stat)

    def phasors(t):
        return by_t[t][0].stations[0].phasors

    assert all(np.array_equal(phasors(0.16), phasors(t)) for t in (0.2, 0.24))   # stale: held
    assert not np.array_equal(phasors(0.16), phasors(0.28)) and stat(0.2) == c3.Stat()
    assert stat(0.0) == c3.Stat() and all(stat(t).data_error == c3.PMU_ERROR for t in (0.4, 0.44, 0.56))
    assert stat(0.6).data_error == 0 and stat(0.8).sync_lost and not stat(0.84).sync_lost
    assert stat(0.88).trigger and stat(0.88).trigger_reason == 4 and stat(0.96).time_quality == 5
    absent = by_t[1.04][0].stations[0]
    assert (
        stat(1.04).data_error == c3.TEST_OR_ABSENT
        and np.isnan(absent.phasors).all()
        and math.isnan(absent.freq)
    )
    assert by_t[1.12][0].tq == 11 and by_t[1.16][0].tq == 0
    assert not any(1.2 <= t < 1.4 for t in by_t) and 1.4 in by_t  # dropped
    late = [order.index(t) for t in (1.6, 1.64)]
    assert all(order.index(1.68) < j for j in late)  # late: after frames stamped later
    assert 1.8 not in by_t and counts["crc"] == 1  # the bad CRC: counted, not decoded
    assert all(stat(t).config_change for t in (2.0, 2.2, 2.36)) and not stat(1.96).config_change
    changed = [(t, c) for t, (x, c) in by_t.items() if t >= 2.4]
    assert changed and all(c.stations[0].cfgcnt == 1 and not c.stations[0].phasor_float for _, c in changed)
    assert not stat(changed[0][0]).config_change and counts["length"] >= 1
    assert (
        max(by_t) < 3.2
        and after
        and c3.grid_index(after[0].soc, after[0].fracsec, 1_000_000, rate) - t0 >= 3.2 * rate
    )
    assert server.stats["disconnects"] == 1 and server.stats["bad_crc"] == 1


def test_a_fleets_plants_are_stations_of_one_concentrator():
    src = load_source(ROOT / "experiments" / "andes_bench" / "fleet_ieee14.toml")
    assert [s.name for s in src.stations] == ["B1_G1", "B2_G1", "B3_G1", "B6_G1", "B8_G1"]
    assert src.rate == 60 and src.f_nominal_hz == 60 and src.stations[0].units == ("pu", "pu of 100 MVA")
    cfg = pmu_sim.stream_config(src, pmu_sim.Format.parse("int,rect"))
    assert len({s.idcode for s in cfg.stations}) == 5 and not cfg.stations[0].phasor_float
    rec = pmu_sim.pack_frames(src, cfg, 100, 101)
    frame = c3.decode_frame(
        c3.encode(c3.DataFrame(cfg.idcode, c3.DataLayout.of(cfg).unpack(rec.tobytes())), cfg), cfg
    )
    for s, sc, sd in zip(src.stations, cfg.stations, frame.stations):
        assert (
            abs(sd.phasors[0] - s.v[100]) <= sc.phasors[0].scale
            and abs(sd.phasors[1] - s.i[100]) <= sc.phasors[1].scale
        )
    tiled = pmu_sim.tile(src, 3)
    assert len(tiled.stations) == 15 and tiled.stations[5].name == "B1_G1~2"


def test_udp(source):
    server = pmu_sim.PmuServer(source, port=0, udp=True, speed=40.0, start="recording")
    with server.serve_in_thread() as (host, port):
        with pmu_sim.PmuClient(host, port, 1, timeout=5.0, udp=True) as pmu:
            assert pmu.config().stations[0].name == "unit1"
            pmu.start()
            frames = [x for x in pmu.frames(count=10, seconds=5) if isinstance(x, c3.DataFrame)]
            pmu.stop()
    assert len(frames) == 10


def test_fault_and_format_words():
    assert pmu_sim.Fault.parse("late=0.5@40+1:unit1") == pmu_sim.Fault("late", 40.0, 1.0, 0.5, "unit1")
    assert pmu_sim.Fault.parse("error@3").stat_bits() == (0xC000, 0xC000)
    assert pmu_sim.Fault.parse("trigger=4@3").stat_bits() == (0x080F, 0x0804)
    for bad in ("error", "nope@1", "late@1", "time-quality=9@1", "error@x", "drop@-5+2", "drop@5+0",
                "late=-1@5+1", "late=0@5", "error=3@5", "drop@nan"):
        with pytest.raises(ValueError):
            pmu_sim.Fault.parse(bad)
    fmt = pmu_sim.Format.parse("rect,phasor=int,freq=int")
    assert (fmt.polar, fmt.phasor_float, fmt.freq_float, fmt.analog_float) == (False, False, False, True)
    with pytest.raises(ValueError):
        pmu_sim.Format.parse("double")


@pytest.mark.slow
def test_command_line_serves_and_ends_by_itself(recording):
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "jaxdse._app.cli",
            "pmu-sim",
            str(recording[0]),
            "--port",
            "0",
            "--speed",
            "20",
            "--duration",
            "1.5",
            "--format",
            "int,rect",
            "--idcode",
            "5",
            "--fault",
            "drop@0.2+0.2",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()  # printed once it listens (imports and reading first: seconds)
        m = re.match(r"pmu-sim listening on tcp 127\.0\.0\.1:(\d+) \(IDCODE 5, 1 station", line)
        assert m, (line, proc.stderr.read() if proc.poll() is not None else "")
        with pmu_sim.PmuClient("127.0.0.1", int(m.group(1)), 5, timeout=5.0) as pmu:
            cfg = pmu.config()
            assert not cfg.stations[0].phasor_float and not cfg.stations[0].polar
            pmu.start()
            frames = [x for x in pmu.frames(count=20, seconds=5) if isinstance(x, c3.DataFrame)]
        rc = proc.wait(timeout=20)
    finally:
        proc.kill()
    assert rc == 0 and len(frames) == 20
    n = [c3.grid_index(x.soc, x.fracsec, cfg.time_base, 25) for x in frames]
    assert n[5] - n[4] == 6  # 0.2 s dropped after the fifth frame
    assert "frames" in proc.stderr.read()


def test_command_line_refuses_bad_input_in_one_line(recording, capsys):
    from jaxdse._app.cli import main

    assert main(["pmu-sim", str(recording[0]), "--fault", "nope@1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("jaxdse: error: pmu-sim: fault 'nope@1': unknown kind") and err.count("\n") == 1


@pytest.mark.parametrize("args,words", [
    (["--fault", "drop@-5+2"], ["fault 'drop@-5+2'", "START", ">= 0"]),
    (["--fault", "drop@5+0"], ["fault 'drop@5+0'", "DURATION > 0"]),
    (["--fault", "error@1000+2"], ["--fault error@1000+2", "recording's end", "--loop"]),
    (["--speed", "0"], ["--speed 0"]), (["--speed", "inf"], ["--speed inf"]),
    (["--duration", "-1"], ["--duration -1"]), (["--port", "-1"], ["--port -1"]),
    (["--tile", "0"], ["--tile 0"]), (["--tile", "100000"], ["--tile 100000", "at most"]),
    (["--start", "-5"], ["--start", "SOC"]),
])
def test_out_of_range_options_and_faults_are_one_line(recording, capsys, args, words):
    from jaxdse._app.cli import main

    assert main(["pmu-sim", str(recording[0]), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("jaxdse: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    assert all(w in err for w in words), err


def test_loop_continues_the_grid_from_a_given_start(source):
    server = pmu_sim.PmuServer(source, port=0, speed=400.0, start=1_700_000_000.0, loop=True)
    with server.serve_in_thread() as (host, port):
        with pmu_sim.PmuClient(host, port, 1, timeout=5.0) as pmu:
            cfg = pmu.config()
            pmu.start()
            frames = [x for x in pmu.frames(count=ROWS + 20, seconds=10) if isinstance(x, c3.DataFrame)]
    n = np.array([c3.grid_index(x.soc, x.fracsec, cfg.time_base, 25) for x in frames])
    assert len(frames) == ROWS + 20 and frames[0].soc == 1_700_000_000 and np.all(np.diff(n) == 1)
    assert np.array_equal(frames[ROWS].stations[0].phasors, frames[0].stations[0].phasors)  # the second pass
