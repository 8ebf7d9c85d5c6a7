"""The system inertia, live (jaxdse._stream.inertia, ``jaxdse monitor`` with ``[inertia]``): the
tracker on hand-made updates and samples, and the monitor end to end on loopback with a unit
dropped from the stream mid-run."""

import json
import types

import pytest
from builders import example_cut

from jaxdse._core.inertia import InertiaSettings
from jaxdse._dyr.inertia import CaseUnit, MeasuredPlant
from jaxdse._stream.inertia import InertiaTracker

KEYS = ["t", "area", "E_MWs", "E_ci95", "measured_share", "E_commitment_MWs", "rocof_hz_per_s",
        "units_online", "units_measured"]


def _update(unit, t, h, ci, verdict=None):
    verdict = verdict or ("identified" if h is not None else "not excited")
    return types.SimpleNamespace(unit=unit, t=t, h_s=h, h_ci95=ci, verdict=verdict)


def test_tracker_lines_online_by_current_and_stale_fallback():
    """Two measured plants (area A) and a case unit (area B): a line per area and the system
    every update_s; a plant whose current falls below the threshold goes offline; a plant whose
    samples stop keeps its case status and, once its H is older than stale_s, its model H."""
    case = [CaseUnit("1_1", 1, "1", "A", 100.0, "synchronous", 5.0, True, ""),
            CaseUnit("2_1", 2, "1", "A", 200.0, "synchronous", 4.0, True, ""),
            CaseUnit("3_1", 3, "1", "B", 300.0, "synchronous", 3.0, True, "")]
    plants = [MeasuredPlant("p1", "A", 100.0, 5.0, ("1_1",)), MeasuredPlant("p2", "A", 200.0, 4.0, ("2_1",))]
    tr = InertiaTracker(case, plants, InertiaSettings(stale_s=5.0, largest_loss_mw=100.0, f0_hz=50.0),
                        ["A", "B"], update_s=1.0, online_current_pu=0.05)
    assert tr.tick(99.5) == []                                  # the first call sets the grid
    tr.update(_update("p1", 99.0, 5.5, (5.0, 6.0)))
    tr.update(_update("p2", 99.0, 4.2, (4.0, 4.4)))
    tr.update(_update("p2", 99.0, None, None))                  # not identified: the last one stays
    tr.update(_update("p2", 99.0, 9.0, (4.0, 20.0), "weakly identified"))   # a wide interval: nor does it move E
    tr.samples(["p1", "p2"], [0.8, 0.7], [True, True], 99.9)
    lines = tr.tick(100.0)
    assert [x["area"] for x in lines] == ["A", "B", "system"] and all(list(x) == KEYS for x in lines)
    a, b, system = lines
    assert a["t"] == 100.0 and a["E_MWs"] == pytest.approx(550 + 840) and a["measured_share"] == 1.0
    assert a["units_online"] == 2 and a["units_measured"] == 2 and a["E_commitment_MWs"] == pytest.approx(1300)
    assert b["E_MWs"] == pytest.approx(900) and b["measured_share"] == 0.0
    assert system["rocof_hz_per_s"] == pytest.approx(50 * 100 / 2 / 2290)
    assert tr.tick(100.5) == []                                 # not due yet
    tr.samples(["p1", "p2"], [0.01, float("nan")], [True, False], 100.9)   # p1 stopped; p2's sample unusable
    a = tr.tick(101.0)[0]
    assert a["units_online"] == 1 and a["E_MWs"] == pytest.approx(840)      # p2 still measured
    assert tr.tick(104.5)[0]["units_measured"] == 1                          # p2's H 5 s old: not yet stale
    a = tr.tick(105.5)[0]                                                    # 6 s old: stale
    assert a["t"] == 105.0 and a["units_measured"] == 0 and a["E_MWs"] == pytest.approx(800)
    assert a["measured_share"] == 0.0


@pytest.fixture(scope="module")
def run_config(tmp_path_factory):
    return example_cut(tmp_path_factory.mktemp("inertia_live"), 3000)


@pytest.mark.slow
def test_monitor_writes_inertia_lines_and_survives_a_dropped_unit(run_config, tmp_path):
    """Two stations (``tile = 2``: the example's unit, 1100 MVA, H 6.18 s, twice), read as
    two streams of one unit each from one server (the shapes of test_monitor.py's
    test_one_streams_failure_costs_its_units_only: compiled once in a run); from 40 s of stream
    time the second station's data are absent (STAT "test or absent", no phasors). Every update_s of stream time a line for the one area of a run
    configuration and one for the system; once the second unit's last H is stale_s old it
    counts at its model H (h_reference_s): the measured share falls from 1 to 1/2, E moves
    less than its interval from one line to the next, the truth stays inside, nothing crashes.
    Below the floor (20 GW s) the log says so once per area."""
    from jaxdse._app.sources import load_monitor, load_source
    from jaxdse._stream import pmu_sim
    from jaxdse._stream.monitor import Monitor

    source = pmu_sim.tile(load_source(run_config), 2)
    server = pmu_sim.PmuServer(source, port=0, speed=20.0, faults=[pmu_sim.Fault.parse("absent@40+1000:unit1~2")])
    with server.serve_in_thread() as (host, port):
        (tmp_path / "m.toml").write_text(
            f'fleet = "{run_config}"\nwindow_s = 10.0\ntile = 2\n'
            "[inertia]\nlargest_loss_mw = 1000.0\nstale_s = 5.0\nupdate_s = 2.0\nfloor_MWs = 20000.0\n"
            f'[[stream]]\nhost = "{host}"\nport = {port}\nunits = ["unit1"]\n'
            f'[[stream]]\nhost = "{host}"\nport = {port}\nunits = ["unit1~2"]\n[view]\nport = 0\n')
        log = []
        mon = Monitor(load_monitor(tmp_path / "m.toml"), tmp_path / "o", log=log.append)
        summary = mon.run(6.5)
    lines = [json.loads(x) for x in (tmp_path / "o" / "updates.jsonl").read_text().splitlines()]
    system = [x for x in lines if x.get("area") == "system"]
    area = [x for x in lines if x.get("area") == "monitored units"]
    assert system and len(area) == len(system) and all(list(x) == KEYS for x in system)
    assert all(abs(x["t"] / 2.0 - round(x["t"] / 2.0)) < 1e-6 for x in system)
    # the two streams' windows fill one after the other; once both units are measured, the
    # count only falls (the second unit's data absent from 40 s, its H stale 5 s later)
    first = next(k for k, x in enumerate(system) if x["units_measured"] == 2)
    after = [x["units_measured"] for x in system[first:]]
    assert after == sorted(after, reverse=True) and after[-1] == 1 and after.count(1) >= 5, after
    assert all(x["measured_share"] == 1.0 for x in system if x["units_measured"] == 2)
    assert all(0.45 < x["measured_share"] < 0.55 for x in system if x["units_measured"] == 1)
    truth = 2 * 6.18 * 1100.0
    for prev, x in zip(system, system[1:]):
        assert x["units_online"] == 2 and x["E_commitment_MWs"] == pytest.approx(truth)
        lo, hi = prev["E_ci95"]
        assert lo <= x["E_MWs"] <= hi, (prev, x)                 # no jump beyond the interval
        assert x["E_ci95"][0] <= truth <= x["E_ci95"][1]
        assert x["rocof_hz_per_s"] == pytest.approx(50 * 1000 / 2 / x["E_MWs"])
    assert summary["inertia"][-1]["area"] == "system" and summary["inertia"][-1]["below_floor"] is True
    # lines emitted once the stream's time passes theirs (stream seconds: at 20x the compile's
    # wall seconds are hundreds of them here, as for the units' delay_s)
    d = summary["inertia_delay_s"]
    assert 0 <= d["median"] <= d["p99"] <= d["max"], d
    alarms = [x for x in log if x.startswith("ALARM inertia")]          # once per area, not every line
    assert len(alarms) == 2 and "below the floor 20 GW s" in alarms[-1] and "system" in alarms[-1]
    # the live page's panel holds the same lines, the floor and the alarm state
    panel = mon.view.state()["inertia"]
    assert panel["floor_MWs"] == 20000.0 and [a["area"] for a in panel["areas"]] == ["monitored units", "system"]
    view_system = panel["areas"][1]
    assert [p["E"] for p in view_system["history"]] == [x["E_MWs"] for x in system]
    assert view_system["latest"]["below_floor"] is True


def test_tracker_of_a_fleet_file_takes_the_case():
    """A monitor of the ANDES ieee14 fleet (two areas): its plants stand for their case units
    (not counted twice), the case gives the areas, MBASE and filed H; a tiled copy of a plant
    is an extra unit in the original's area."""
    from pathlib import Path

    from jaxdse._app.sources import source_units
    from jaxdse._io.inertia import InertiaConfig
    from jaxdse._stream.inertia import tracker_for
    from jaxdse._stream.monitor import MonitorUnit

    bench = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench" / "fleet_ieee14.toml"
    est = source_units(bench)
    runs = dict(est.runs)
    units = [MonitorUnit("B1_G1", runs["B1_G1"], 0), MonitorUnit("B6_G1", runs["B6_G1"], 0),
             MonitorUnit("B6_G1~2", runs["B6_G1"], 0)]
    notes = []
    tr = tracker_for(units, est, InertiaConfig(largest_loss_mw=100.0), notes.append)
    assert tr.areas == ["area 1", "area 2"] and tr.settings.f0_hz == 60.0 and notes == []
    assert [(p.name, p.area, p.h_model_s, p.members) for p in tr.plants] == [
        ("B1_G1", "area 1", 4.0, ("1_1",)), ("B6_G1", "area 2", 5.0, ("6_1",)), ("B6_G1~2", "area 2", 5.0, ())]
    tr.update(_update("B1_G1", 10.0, 4.4, (4.2, 4.6)))
    a1, a2, system = tr.at(12.0)
    # area 1: B1_G1 measured 440 + 2_1 650 + 3_1 500; area 2: B6_G1 and its copy 500 each + 8_1 500
    assert a1.E_MWs == pytest.approx(1590) and a1.units_online == 3 and a1.units_measured == 1
    assert a2.E_MWs == pytest.approx(1500) and a2.units_online == 3 and a2.units_stale == 2
    assert system.E_commitment_MWs == pytest.approx(400 + 650 + 500 + 1500)
