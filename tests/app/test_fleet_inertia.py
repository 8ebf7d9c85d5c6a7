"""``jaxdse fleet`` with ``[inertia]``: E per area for the recording (inertia.csv, fleet.json's
``inertia``, inertia.png), from hand-made plant estimates on the ANDES ieee14 case (two areas),
and the section's checks."""

import csv
import dataclasses
from pathlib import Path

import pytest

from jaxdse._app.cli import main
from jaxdse._app.fleet_file import load_fleet
from jaxdse._app.fleet_inertia import fleet_inertia, inertia_document, inertia_figure, write_inertia_csv
from jaxdse._io.errors import InputError
from jaxdse._io.inertia import InertiaConfig, inertia_section, read_unit_states

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "experiments" / "andes_bench"


@pytest.fixture(scope="module")
def ieee14():
    return load_fleet(BENCH / "fleet_ieee14.toml")


def _entry(name, h, ci, verdict="identified"):
    return {"name": name, "s_mva": 100.0, "H_s": h, "H_ci95": list(ci), "verdict": verdict}


def test_fleet_inertia_sums_measured_and_model_units(ieee14, tmp_path):
    """Areas 1 (buses 1, 2, 3) and 2 (6, 8), 100 MVA each, filed H 4, 6.5, 5, 5, 5 s. Measured:
    B1_G1 (H 4.2 [4.0, 4.5]) and B6_G1 (H 5.1 [4.9, 5.4]); B2_G1's estimate is not identified
    (its model H counts, marked stale); B3_G1 and B8_G1 are not in the estimated plants (model);
    the status CSV takes 8_1 offline before the recording ends; B6_G1's current is below the
    threshold: offline though its estimate exists."""
    (tmp_path / "status.csv").write_text("time_s,unit,online\n0,8_1,1\n5,8_1,0\n100,8_1,1\n")
    cfg = InertiaConfig(largest_loss_mw=100.0, floor_MWs=1000.0, model_uncertainty=0.1,
                        status=read_unit_states(tmp_path / "status.csv"))
    fl = dataclasses.replace(ieee14, inertia=cfg)
    plants = [p for p in fl.plants if p.name in ("B1_G1", "B2_G1", "B6_G1")]
    entries = [_entry("B1_G1", 4.2, (4.0, 4.5)), _entry("B2_G1", 9.0, (1.0, 20.0), "not identified"),
               _entry("B6_G1", 5.1, (4.9, 5.4))]
    currents = {"B1_G1": 0.8, "B2_G1": 0.5, "B6_G1": 0.01}
    areas, units, notes = fleet_inertia(fl, plants, entries, currents, t_end=10.0)
    a1, a2, system = areas
    assert [a.area for a in areas] == ["area 1", "area 2", "system"]
    assert a1.E_MWs == pytest.approx(420 + 650 + 500) and a1.E_measured_MWs == pytest.approx(420)
    assert a1.units_measured == 1 and a1.units_stale == 1 and a1.units_online == 3
    assert a1.E_commitment_MWs == pytest.approx(400 + 650 + 500)
    assert a1.E_ci95[0] == pytest.approx(1570 - (20**2 + 65**2 + 50**2) ** 0.5)
    assert a1.E_ci95[1] == pytest.approx(1570 + (30**2 + 65**2 + 50**2) ** 0.5)
    # area 2: B6_G1 offline by its current, 8_1 offline by the status CSV at t = 10 s
    assert a2.E_MWs == 0.0 and a2.units_online == 0 and a2.rocof_hz_per_s is None
    assert a2.rocof_reason == "no online unit"
    assert system.E_MWs == pytest.approx(1570) and system.below_floor is False
    assert system.rocof_hz_per_s == pytest.approx(60 * 100 / 2 / 1570)
    by = {u.name: u for u in units}
    assert by["B2_G1"].source == "model (no estimate)" and by["3_1"].source == "model"
    assert by["8_1"].source == "offline" and by["B6_G1"].source == "offline"
    # at the end of the status CSV (t = 200 s) 8_1 is online again
    areas, _, _ = fleet_inertia(fl, plants, entries, currents, t_end=200.0)
    assert areas[1].E_MWs == pytest.approx(500.0) and areas[1].units_online == 1
    doc = inertia_document(fl, areas, units, notes)
    assert doc["time_resolution"] == "one value per recording" and len(doc["areas"]) == 3
    assert set(doc["areas"][0]) >= {"area", "E_MWs", "E_ci95", "measured_share", "E_commitment_MWs",
                                    "rocof_hz_per_s", "units_online", "units_measured", "rocof_reason"}
    write_inertia_csv(tmp_path / "inertia.csv", areas)
    rows = list(csv.DictReader(open(tmp_path / "inertia.csv")))
    assert [r["area"] for r in rows] == ["area 1", "area 2", "system"]
    assert float(rows[0]["E_MWs"]) == pytest.approx(1570) and rows[1]["measured_share"] == "0"
    inertia_figure(tmp_path / "inertia.png", areas, 1000.0, "test")
    assert (tmp_path / "inertia.png").stat().st_size > 10_000


def test_areas_by_bus_list_and_zone(ieee14):
    cfg = InertiaConfig(areas={"west": (1, 2), "east": (3, 6)})
    fl = dataclasses.replace(ieee14, inertia=cfg)
    areas, units, _ = fleet_inertia(fl, [], [], {}, None)
    assert [a.area for a in areas] == ["west", "east", "other", "system"]
    assert [a.E_MWs for a in areas] == pytest.approx([1050, 1000, 500, 2550])   # all on the model
    assert areas[-1].measured_share == 0.0 and areas[-1].E_commitment_MWs == pytest.approx(2550)


@pytest.mark.parametrize("table, key", [
    ({"areas": "region"}, "inertia.areas"),
    ({"areas": {"north": [1, "2"]}}, "inertia.areas.north"),
    ({"areas": {"a": [1], "b": [1]}}, "inertia.areas.b"),
    ({"status": "nowhere.csv"}, "inertia.status"),
    ({"model_uncertainty": 1.5}, "inertia.model_uncertainty"),
    ({"model_uncertainty": -0.1}, "inertia.model_uncertainty"),
    ({"largest_loss_mw": 0}, "inertia.largest_loss_mw"),
    ({"f0_hz": "50"}, "inertia.f0_hz"),
    ({"update_s": -1}, "inertia.update_s"),
    ({"stale_s": -1}, "inertia.stale_s"),
    ({"floor_MWs": True}, "inertia.floor_MWs"),
    ({"online_current_pu": 0}, "inertia.online_current_pu"),
    ({"grid_forming": {"x": 3.0}}, "inertia.grid_forming.x"),
    ({"grid_forming": {"3_1": -3.0}}, "inertia.grid_forming.3_1"),
    ({"flor_MWs": 1.0}, "inertia.flor_MWs"),
    ({"measured_errors": "correlated"}, "inertia.measured_errors"),
])
def test_bad_inertia_keys_are_refused_in_one_line(tmp_path, table, key):
    with pytest.raises(InputError) as err:
        inertia_section(tmp_path / "f.toml", table)
    assert f"key '{key}'" in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize("text, where", [
    ("time_s,unit\n1,3_1\n", "column 'online'"),
    ("time_s,unit,online\nx,3_1,1\n", "row 2"),
    ("time_s,unit,online\n1,3_1,yes\n", "column 'online', row 2"),
    ("time_s,unit,online\n1,3_1,1\n2,G3,0\n", "column 'unit', row 3"),
])
def test_bad_status_csv_is_refused_in_one_line(tmp_path, text, where):
    (tmp_path / "s.csv").write_text(text)
    with pytest.raises(InputError) as err:
        read_unit_states(tmp_path / "s.csv")
    assert where in str(err.value) and "s.csv" in str(err.value) and "\n" not in str(err.value)


def test_cli_refuses_a_bad_inertia_section_with_exit_2(tmp_path, capsys):
    text = (BENCH / "fleet_ieee14.toml").read_text().replace('"data/', f'"{BENCH}/data/')
    (tmp_path / "f.toml").write_text(text + "\n[inertia]\nlargest_loss_mw = -5\n")
    assert main(["fleet", str(tmp_path / "f.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "inertia.largest_loss_mw" in err[0], err
    (tmp_path / "g.toml").write_text(text + "\n[inertia]\n")
    assert load_fleet(tmp_path / "g.toml").inertia == InertiaConfig()
