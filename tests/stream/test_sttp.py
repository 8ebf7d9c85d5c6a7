"""STTP (IEEE 2664) for ``jaxdse monitor`` (jaxdse._stream.sttp, through the optional sttpapi),
on loopback only.

* without sttpapi, a monitor file that asks for STTP is refused in one line that names the extra
  (this test needs no sttpapi);
* the frame assembler: points in any order, on millisecond timestamps, a missing point, bad
  quality flags and an unknown signal become the frames the C37.118 path feeds;
* the reader thread on a recording served over STTP: the recording's phasors on consecutive
  grid points; a configuration change; a publisher that goes away, or none there, is reported
  and tried again;
* end to end: a recording served over STTP (:class:`~jaxdse._stream.sttp.SttpServer`), the
  monitor reading it and publishing its results over STTP; a subscriber receives H, its
  interval, D, AGE and STATE equal to updates.jsonl's, and the estimates cover the truth.
The STTP tests are skipped where sttpapi is absent. Every wait is bounded."""

import json
import math
import sys
import threading
import time

import jax
import numpy as np
import pytest
from builders import example_cut

from jaxdse._app.cli import main
from jaxdse._io.config import load_config
from jaxdse._io.errors import InputError
from jaxdse._stream import c37118 as c3
from jaxdse._stream import pmu_sim
from jaxdse._stream import sttp as js
from jaxdse._app.sources import load_monitor, load_source
from jaxdse._stream.monitor import Monitor
from jaxdse._stream.online import OnlineGroup

jax.config.update("jax_enable_x64", True)

H_TRUE = 6.18
ROWS = 1500  # 60 s at 25 frames/s


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    """The example run configuration on its first 60 s."""
    run = example_cut(tmp_path_factory.mktemp("sttp"), ROWS)
    load_config(run)
    return run


@pytest.fixture
def sttp_lib():
    return pytest.importorskip("sttp")


@pytest.mark.parametrize("text, key", [
    ('[stream]\nprotocol = "sttp"', "stream.protocol"),
    ('[publish]\nprotocol = "sttp"', "publish.protocol"),
])
def test_missing_extra_is_one_line(example, tmp_path, capsys, monkeypatch, text, key):
    monkeypatch.setitem(sys.modules, "sttp", None)          # import sttp raises ImportError
    (tmp_path / "m.toml").write_text(f'fleet = "{example}"\n{text}\n')
    with pytest.raises(InputError) as err:
        load_monitor(tmp_path / "m.toml")
    assert js.MISSING in str(err.value) and key in str(err.value) and "\n" not in str(err.value)
    capsys.readouterr()
    assert main(["monitor", str(tmp_path / "m.toml"), "--duration", "1"]) == 2
    out = capsys.readouterr().err.strip().splitlines()
    assert len(out) == 1 and "pip install jaxdse[sttp]" in out[0], out


class _M:
    """A measurement as sttpapi's subscriber hands it over."""

    def __init__(self, signalid, value, timestamp, flags=0):
        self.signalid, self.value, self.timestamp, self.flags = signalid, value, np.uint64(timestamp), flags


def test_assembler_makes_the_frames_of_the_grid():
    rate = 30
    ids = {(j, c): f"sig{j}{c}" for j in range(2) for c in range(len(js.CHANNELS))}
    asm = js.Assembler(["A", "B"], {v: k for k, v in ids.items()}, rate, hold=2)
    base = 1_700_000_000 * rate

    def points(idx, drop=(), bad=(), ms=False):
        t = js.ticks_of_index(idx, rate)
        if ms:                                                   # millisecond timestamps, truncated
            t = (t - js.UNIX_TICKS) // 10_000 * 10_000 + js.UNIX_TICKS
        vals = [230e3, 30.0, 500.0, -150.0, 50.01, 0]
        return [_M(ids[j, c], vals[c] + j, t, js.BADDATA if (j, c) in bad else 0)
                for j in range(2) for c in range(len(js.CHANNELS)) if (j, c) not in drop]

    first = points(base + 1, ms=True)[::-1]                      # any order
    frames = asm.add(first[:5])
    assert frames == []
    (f,) = asm.add(first[5:] + [_M("other", 1.0, js.ticks_of_index(base, rate))])
    assert c3.grid_index(f.soc, f.fracsec, js.TICKS_PER_S, rate) == base + 1
    a = f.arrays
    assert a.phasors[0, 0] == pytest.approx(230e3 * np.exp(1j * np.radians(30.0)))
    assert a.phasors[1, 1] == pytest.approx(501.0 * np.exp(1j * np.radians(-149.0)))
    assert list(a.freq) == [50.01, 51.01] and list(a.stat) == [0, 1]
    assert asm.counts["unknown_points"] == 1
    # a missing point (released once a frame 2 newer came) and a bad one
    assert asm.add(points(base + 2, drop=[(1, 0)], bad=[(0, 2)])) == []
    asm.add(points(base + 3))
    (f2,) = asm.add(points(base + 4)[:1])
    assert c3.grid_index(f2.soc, f2.fracsec, js.TICKS_PER_S, rate) == base + 2
    assert np.isnan(f2.arrays.phasors[1, 0]) and f2.arrays.stat[0] & 0xC000 == js.STAT_BAD_QUALITY
    assert asm.counts["incomplete_frames"] == 1 and asm.counts["bad_quality_points"] == 1
    # late points and off-grid ones are counted, not used
    off = js.ticks_of_index(base + 5, rate) + 5_000_000 // rate            # a quarter period off
    asm.add(points(base + 2)[:1] + [_M(ids[0, 0], 1.0, off)])
    assert asm.counts["late_points"] == 1 and asm.counts["points_off_grid"] == 1
    assert [c3.grid_index(x.soc, x.fracsec, js.TICKS_PER_S, rate) for x in asm.flush()] == [base + 4]


def test_ticks_are_exact():
    for rate in (25, 30, 50, 60):
        for idx in (1_700_000_000 * rate, 1_700_000_000 * rate + rate - 1, 1_700_000_007 * rate + 7):
            assert js.grid_point(js.ticks_of_index(idx, rate), rate) == idx
    assert js.ticks_of_time(1_700_000_000.5) == js.UNIX_TICKS + 17_000_000_005_000_000
    assert abs(js.ticks_of_time(1_700_000_000 + 2 / 30) - js.ticks_of_index(1_700_000_000 * 30 + 2, 30)) <= 1


def test_reader_gives_the_recordings_frames(sttp_lib, example):
    """The reader alone (no estimator): its configuration names the served station (a unit
    with no points is left out), its frames carry the recording's phasors and frequency on
    consecutive grid points; a configuration change (new signal IDs) gives a new
    configuration and the frames go on; a publisher that goes away is reported and tried again."""
    import queue

    from jaxdse._stream.monitor import StreamSpec

    source = load_source(example)
    st = source.stations[0]
    q, stop, lines = queue.Queue(), threading.Event(), []
    server = js.SttpServer(source, port=0, speed=10.0)
    items = []

    def take(frames):
        deadline = time.monotonic() + 15
        while sum(isinstance(x[2], c3.DataFrame) for x in items) < frames and time.monotonic() < deadline:
            try:
                items.append(q.get(timeout=0.1))
            except queue.Empty:
                pass

    with server as (host, port):
        spec = StreamSpec(host=host, port=port, protocol="sttp", timeout_s=1.0)
        th = threading.Thread(target=js.reader, daemon=True,
                              args=(0, spec, q, stop, lines.append, None, ["unit1", "nobody"]))
        th.start()
        take(100)
        before = len(items)
        server.reconfigure()
        take(200)
    deadline = time.monotonic() + 10
    while not any(x[1] == "down" for x in items) and time.monotonic() < deadline:
        try:
            items.append(q.get(timeout=0.1))
        except queue.Empty:
            pass
    stop.set()
    th.join(timeout=5)
    assert not th.is_alive()
    kinds = [x[1] for x in items]
    assert kinds[:2] == ["frame", "up"] and "down" in kinds, kinds[:5]
    cfg = items[0][2]
    assert [s.name for s in cfg.stations] == ["unit1"] and cfg.rate_hz == 25 and cfg.stations[0].cfgcnt == 0
    configs = [x[2].stations[0].cfgcnt for x in items if isinstance(x[2], c3.ConfigFrame)]
    assert configs[0] == 0 and configs[-1] == 1 and set(configs) == {0, 1}
    assert sum(isinstance(x[2], c3.DataFrame) for x in items[before:]) >= 100    # the frames went on
    frames = [x[2] for x in items[:before] if isinstance(x[2], c3.DataFrame)]
    idx = [c3.grid_index(f.soc, f.fracsec, cfg.time_base, cfg.data_rate) for f in frames]
    assert len(frames) >= 100 and idx == list(range(idx[0], idx[0] + len(idx)))
    k0 = np.flatnonzero(st.present)[0]
    for n, f in enumerate(frames):
        a = f.arrays
        assert a.phasors[0, 0] == pytest.approx(st.v[k0 + n], rel=1e-6)        # float32 on the wire
        assert a.phasors[0, 1] == pytest.approx(st.i[k0 + n], rel=1e-6)
        assert a.freq[0] == pytest.approx(st.f[k0 + n], rel=1e-7) and a.stat[0] == 0
    assert any("configuration changed" in x for x in lines) and any("reconnecting" in x for x in lines)


def test_unreachable_sttp_stream_ends_cleanly(sttp_lib, example, tmp_path):
    (tmp_path / "m.toml").write_text(
        f'fleet = "{example}"\n[stream]\nprotocol = "sttp"\nport = 9\ntimeout_s = 0.5\n')
    lines = []
    t0 = time.monotonic()
    summary = Monitor(load_monitor(tmp_path / "m.toml"), tmp_path / "o", log=lines.append).run(duration_s=1.5)
    assert time.monotonic() - t0 < 6
    assert summary["updates"] == 0 and summary["streams"][0]["connect_failures"] >= 1
    assert any("cannot connect" in x and "reconnecting" in x for x in lines), lines


def _subscribe(host, port, expression, got, errors):
    from sttp import Subscriber
    from sttp.config import Config
    from sttp.settings import Settings

    sub = Subscriber()
    sub.statusmessage_logger = None
    sub.errormessage_logger = errors.append
    sub.connectionestablished_receiver = None
    sub.connectionterminated_receiver = None
    sub.set_newmeasurements_receiver(got.extend)
    sub.subscribe(expression, Settings())
    config = Config(maxretries=1, retryinterval=0.01, autoreconnect=False)     # 0: see sttp.py
    assert sub.connect(f"{host}:{port}", config) is None
    return sub


@pytest.mark.slow
def test_monitor_reads_and_publishes_sttp(sttp_lib, example, tmp_path, monkeypatch):
    """The example served over STTP at 20x; the monitor reads it (STTP in) and publishes its
    updates (STTP out); a subscriber of the published point tags gets updates.jsonl's values.
    The estimators' compile is made 4 s longer than the whole stream (3 s at 20x): the data is
    subscribed to once they are ready, so no frame is lost behind the compiler (before, a slow
    compile on a loaded machine lost the stream's first seconds and the window never filled)."""
    warm_up = OnlineGroup.warm_up

    def slow_warm_up(group):
        warm_up(group)
        time.sleep(4.0)

    monkeypatch.setattr(OnlineGroup, "warm_up", slow_warm_up)
    source = load_source(example)
    server = js.SttpServer(source, port=0, speed=20.0)
    with server as (host, port):
        (tmp_path / "mon.toml").write_text(
            f'fleet = "{example}"\nwindow_s = 20.0\n[stream]\nprotocol = "sttp"\nhost = "{host}"\n'
            f'port = {port}\ntimeout_s = 2.0\n[publish]\nprotocol = "sttp"\nport = 0\n')
        cfg = load_monitor(tmp_path / "mon.toml")
        assert cfg.streams[0].protocol == "sttp"
        lines = []
        mon = Monitor(cfg, tmp_path / "live", log=lines.append)
        th = threading.Thread(target=mon.run, args=(5.0,), daemon=True)
        th.start()
        deadline = time.monotonic() + 10
        while mon.publisher.bound is None and time.monotonic() < deadline:
            time.sleep(0.02)
        got, errors = [], []
        tags = ", ".join(f"'unit1:{o}'" for o in js.OUTPUTS)
        sub = _subscribe(*mon.publisher.bound, f"FILTER ActiveMeasurements WHERE PointTag IN ({tags})",
                         got, errors)
        th.join(timeout=30)
        time.sleep(0.3)
        records = {m.signalid: m for m in sub.metadatacache.measurement_records}
        sub.dispose()
    assert not th.is_alive()
    assert any("publishing STTP" in x for x in lines), lines
    live = [json.loads(x) for x in (tmp_path / "live" / "updates.jsonl").read_text().splitlines()]
    summary = json.loads((tmp_path / "live" / "monitor.json").read_text())
    st = summary["streams"][0]
    assert st["data_frames"] == ROWS and st["slots_without_frame"] == st["disconnects"] == 0, st
    assert st["off_grid_frames"] == 0 and st["late_frames"] == st["repeated_frames"] == 0
    assert not st["decoder"].get("points_off_grid") and not st["unusable_samples"]
    assert len(live) >= 5, (lines, summary)
    for x in live:
        assert x["verdict"] in ("identified", "weakly identified"), x
        assert x["H_ci95"][0] <= H_TRUE <= x["H_ci95"][1], x
    # what the subscriber received: per update t, the values of unit1's tags
    by_t = {}
    for m in got:
        tag = records[m.signalid].pointtag
        t = (int(m.timestamp) - js.UNIX_TICKS) / js.TICKS_PER_S
        by_t.setdefault(round(t, 6), {})[tag.split(":")[1]] = float(m.value)
    assert by_t, (errors, summary["published"])
    matched = 0
    for x in live:
        y = by_t.get(round(x["t"], 6))
        if y is None:
            continue                                   # before the subscription took
        matched += 1
        assert y["H"] == pytest.approx(x["H_s"], rel=1e-6)          # float32 on the wire
        assert y["H_LO"] == pytest.approx(x["H_ci95"][0], rel=1e-6)
        assert y["H_HI"] == pytest.approx(x["H_ci95"][1], rel=1e-6)
        assert y["D"] == pytest.approx(x["D"], rel=1e-6, abs=1e-6)
        age = math.nan if x["age_s"] is None else x["age_s"]           # never identified yet: NaN
        assert y["AGE"] == pytest.approx(age, nan_ok=True), (y, x)
        assert y["STATE"] == js.STATE[x["verdict"]] and y["ALARM"] == 0.0
    assert matched == len(by_t) and matched >= max(3, len(live) - 1)
    assert not math.isnan(by_t[max(by_t)]["H"])
