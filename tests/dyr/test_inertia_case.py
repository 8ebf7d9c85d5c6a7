"""The case's units for the system inertia (jaxdse._dyr.inertia): the ANDES ieee14 case with
three more generator records on bus 3 (a converter, one without dynamic records, one named
grid-forming) and one out of service with its machine record."""

from pathlib import Path

import pytest

from jaxdse._core.inertia import InertiaSettings, area_inertia
from jaxdse._dyr.inertia import area_list, case_units, inertia_units
from jaxdse._io.inertia import InertiaConfig, read_unit_states
from jaxdse._io.psse import read_dyr, read_raw

DATA = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench" / "data" / "ieee14"
GEN3 = "3, '1', 40, 12.59713327, 15, -10, 1.01, 0, 100, 0, 0.34,"


@pytest.fixture
def case(tmp_path):
    raw = (DATA / "ieee14.raw").read_text()
    line = next(x for x in raw.splitlines() if x.startswith(GEN3))
    extra = [line.replace("3, '1',", f"3, '{i}',", 1).replace(", 100, 0, 0.34,", f", {m}, 0, 0.34,", 1)
             for i, m in (("2", "50"), ("3", "80"), ("4", "20"))]
    off = line.replace("3, '1',", "3, '5',", 1)
    fields = off.split(",")
    fields[14] = " 0"                                   # STAT (the 15th field) out of service
    raw = raw.replace(line, "\n".join([line, *extra, ",".join(fields)]))
    (tmp_path / "c.raw").write_text(raw)
    dyr = (DATA / "ieee14.dyr").read_text() + (
        "3 'REGCA1' 2 0 0.02 0.9 1.22 1.2 0.8 0.4 -1.3 0.02 0 0 -0.1 0.1 10 -10 /\n"
        "3 'REGCA1' 4 0 0.02 0.9 1.22 1.2 0.8 0.4 -1.3 0.02 0 0 -0.1 0.1 10 -10 /\n"
        "3 'GENCLS' 5 3.0 0 /\n")
    (tmp_path / "c.dyr").write_text(dyr)
    return read_raw(tmp_path / "c.raw", strict=False), read_dyr(tmp_path / "c.dyr", strict=False)


def test_case_units_by_kind(case, tmp_path):
    raw, dyr = case
    units, notes = case_units(raw, dyr, InertiaConfig(grid_forming={"3_4": 2.5}))
    by = {u.name: u for u in units}
    assert set(by) == {"1_1", "2_1", "3_1", "6_1", "8_1", "3_2", "3_3", "3_4", "3_5"}
    assert (by["3_1"].kind, by["3_1"].h_model_s, by["3_1"].s_mva, by["3_1"].area) == ("synchronous", 5.0, 100.0,
                                                                                         "area 1")
    assert by["3_2"].kind == "ibr_following" and by["3_2"].s_mva == 50.0
    assert by["3_3"].kind == "no_h_record" and by["3_3"].h_model_s is None
    assert (by["3_4"].kind, by["3_4"].h_model_s) == ("grid_forming", 2.5)
    assert (by["3_5"].kind, by["3_5"].h_model_s, by["3_5"].in_service) == ("synchronous", 3.0, False)
    assert notes == ["1 online generator record(s) without an H in the case (no dynamic records: 1), counted "
                     "at H = 0 (E is a lower bound; name them in [inertia] grid_forming if they are grid-forming "
                     "converters): 3_3"]
    assert area_list(raw, units, "area") == ["area 1", "area 2"]
    rows, terms = area_inertia(inertia_units(units, [], {}, {}), InertiaSettings(), area_list(raw, units, "area"))
    system = rows[-1]
    # 2550 (the five machines) + 2.5 * 20 (grid-forming); 3_5 offline; 3_2 at 0; 3_3 unknown, at 0
    assert system.E_MWs == pytest.approx(2600.0) and system.units_online == 8 and system.units_without_h == 1
    # a status CSV brings 3_5 online
    (tmp_path / "s.csv").write_text("time_s,unit,online\n0,3_5,1\n")
    rows, _ = area_inertia(inertia_units(units, [], {}, {}, read_unit_states(tmp_path / "s.csv"), 10.0),
                           InertiaSettings(), ["area 1", "area 2"])
    assert rows[-1].E_MWs == pytest.approx(2600.0 + 300.0) and rows[-1].units_online == 9


def test_a_grid_forming_record_counts_at_its_virtual_h(case, tmp_path):
    """A REGFMA1 record (droop: H = TPf / (2 mp)) and a REGCV1 record (H = M/2) are grid-forming
    units at their records' virtual H, without naming them in [inertia] grid_forming."""
    raw, _ = case
    dyr = (DATA / "ieee14.dyr").read_text() + (
        "3 'REGFMA1' 2 1 0 0.03 0.02 0.02 2.0 1.3 0.0 1.0 0.0 1.0 -1.0 0.01 0.05 0.01 0.1 3.0 20.0 "
        "0.0 6.0 /\n"
        "3 'REGCV1' 4 0.01 0 0 6 1 0 0.2 0.5 0.02 0.5 0.02 0.2 0.01 0.2 0.01 /\n")
    (tmp_path / "g.dyr").write_text(dyr)
    units, _ = case_units(raw, read_dyr(tmp_path / "g.dyr", strict=False), InertiaConfig())
    by = {u.name: u for u in units}
    assert (by["3_2"].kind, by["3_2"].h_model_s) == ("grid_forming", pytest.approx(0.03 / (2 * 0.01)))
    assert (by["3_4"].kind, by["3_4"].h_model_s) == ("grid_forming", pytest.approx(3.0))
