"""The system inertia per area published: C37.118 stations "E <area>" with their analogs (read
back by a client over TCP) and STTP devices "E <area>" (their measurements decoded back by the
point tags of the metadata)."""

import math
import time

import numpy as np
import pytest

from jaxdse._stream import c37118 as c3
from jaxdse._stream import pmu_sim
from jaxdse._stream.publish import AREA_ANALOGS, Publisher


def lines(t):
    return [{"t": t, "area": "North", "E_MWs": 14000.0, "E_ci95": [12500.0, 15600.0], "measured_share": 0.25,
             "E_commitment_MWs": 15000.0, "rocof_hz_per_s": None, "units_online": 8, "units_measured": 2},
            {"t": t, "area": "system", "E_MWs": 30000.0, "E_ci95": [28000.0, 32500.0], "measured_share": 0.5,
             "E_commitment_MWs": 31000.0, "rocof_hz_per_s": 0.8333, "units_online": 20, "units_measured": 10}]


def test_c37118_area_stations_read_back():
    pub = Publisher(["unit1"], port=0, idcode=91, areas=["North", "system"], floor_MWs=20000.0)
    host, port = pub.start()
    try:
        with pmu_sim.PmuClient(host, port, idcode=91, timeout=5.0) as client:
            cfg = client.config()
            cfg3 = client.config(c3.CFG3)
            client.start()
            time.sleep(0.3)
            pub.publish_inertia(1_700_000_000.5, lines(1_700_000_000.5))
            frames = [f for f in client.frames(seconds=1.5) if isinstance(f, c3.DataFrame)]
    finally:
        pub.stop()
    assert [s.name for s in cfg.stations] == ["unit1", "E North", "E system"]
    assert [s.name for s in cfg3.stations] == ["unit1", "E North", "E system"]
    assert [a.name for a in cfg.stations[2].analogs] == list(AREA_ANALOGS)
    (f,) = frames
    assert c3.frame_time(f, cfg.time_base) == pytest.approx(1_700_000_000.5)
    unit, north, system = f.stations
    assert c3.Stat.from_word(unit.stat).data_error == c3.TEST_OR_ABSENT       # the units: absent here
    # float32 on the wire
    np.testing.assert_allclose(system.analogs, [30000, 28000, 32500, 0.5, 31000, 0.8333, 20, 10], rtol=1e-6)
    assert math.isnan(north.analogs[5]) and north.analogs[0] == 14000.0      # no rocof: NaN
    assert c3.Stat.from_word(north.stat).trigger and not c3.Stat.from_word(system.stat).trigger  # below the floor


def test_sttp_area_measurements_decode_back():
    pytest.importorskip("sttp")
    from jaxdse._stream.sttp import ALARMLOW, BADDATA, SttpPublisher, signal_id

    pub = SttpPublisher(["unit1"], areas=["North", "system"], floor_MWs=20000.0)
    for tag in ("E North:E", "E system:E_LO", "E system:ROCOF", "E North:ALARM"):
        assert tag in pub.xml
    got = {m.signalid: m for m in pub.inertia_measurements(1_700_000_001.0, lines(1_700_000_001.0))}
    assert len(got) == 2 * (len(AREA_ANALOGS) + 1)

    def value(tag):
        return got[signal_id(tag)]

    assert value("E system:E").value == 30000.0 and value("E system:E_HI").value == 32500.0
    assert value("E system:MEASURED").value == 10 and value("E system:ALARM").value == 0.0
    assert value("E North:ALARM").value == 1.0 and int(value("E North:E").flags) & ALARMLOW
    assert math.isnan(value("E North:ROCOF").value) and int(value("E North:ROCOF").flags) & BADDATA
    assert all(int(m.timestamp) == int(value("E system:E").timestamp) for m in got.values())
