"""``jaxdse check`` of photovoltaic and storage plants: the ieee14 bench case with three more
generators (PG 10 MW, QG 0 on MBASE 100 MVA, ZSORCE j0.3):

* bus 9: REGCA1 + REECB1 (local voltage control, VFLAG = 0, QFLAG = 1) + REPCA1 (Fflag = 1);
* bus 10: REGCB1 (Te = 0.01 s, a voltage source behind ZSORCE) + REECCU1 (P priority, VDL
  tables, SOCini 0.5) + REPCA1: its state of charge moves in the held run, the plant is at rest;
* bus 11: bus 10's records with SOCini at SOCmin while discharging: a data problem naming SOCmin;
* bus 12: SOCini 1e-4 above SOCmin: at P0 = 0.1 pu and T = 999 s it reaches SOCmin after 1 s, a
  data problem too (the plant cannot hold its power flow for the check's 21 s).

Checked like REECA1 plants (held 20 s, 2 % voltage step, 0.1 Hz frequency step); only these
four units (``only``): two compiled programs.
"""

from pathlib import Path

import pytest

from jaxdse._app.check import check_case, load_case

BENCH = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench" / "data" / "ieee14"
GEN = "{bus}, '1', 10, 0, 10, -10, 1.0, 0, 100, 0, 0.3, 0, 0, 1, 1, 100, 50, 0, 1, 1\n"
PLANT = ("'REPCA1' '1' 0 {bus} 7 '1' 0 1 1 0.02 18 5 0 0.075 0 0 0 0 0.1 -0.1 0 0 0.436 -0.436 0.1 0.05\n"
         "   0.25 0 0 999 -999 999 -999 0.1 20 0 /\n")
STORAGE = ("{bus} 'REGCB1' '1' 0 0 0.02 0.02 999 -999 10 0.01 1.3 /\n"
           "{bus} 'REECCU1' '1' 0 0 1 0 1 0.9 1.1 0.02 -0.05 0.05 2 1.05 -1.05 0 0.05 0.436 -0.436 1.1 0.9\n"
           "   0 0.1 0 40 0.02 99 -99 1 -1 1.7 0.02\n"
           "   0.2 1.5 0.5 1.5 1 1.5 1.5 1.5  0.2 1.5 0.5 1.5 1 1.5 1.5 1.5\n"
           "   999 {soc} 0.9 0.2 /\n")
RECORDS = ("9 'REGCA1' '1' 1 0.02 10 0.9 0.4 1.22 1.2 0.8 0.4 -1.3 0.02 0.7 999 -999 0.7 /\n"
           "9 'REECB1' '1' 0 0 0 1 0 0.9 1.1 0.02 -0.05 0.05 2 1.05 -1.05 0 0.05 0.436 -0.436 1.1 0.9\n"
           "   0 0.1 0 40 0.02 99 -99 1 0 1.7 0.02 /\n"
           + "9 " + PLANT.format(bus=9) + STORAGE.format(bus=10, soc=0.5) + "10 " + PLANT.format(bus=10)
           + STORAGE.format(bus=11, soc=0.2) + STORAGE.format(bus=12, soc=0.2001))


@pytest.fixture(scope="module")
def doc(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("check_pv")
    raw = (BENCH / "ieee14.raw").read_text()
    rows = "".join(GEN.format(bus=b) for b in (9, 10, 11, 12))
    end = "0 / End of Generator data"
    (tmp / "case.raw").write_text(raw.replace(end, rows + end))
    (tmp / "case.dyr").write_text((BENCH / "ieee14.dyr").read_text() + RECORDS)
    (tmp / "case.toml").write_text('[case]\nraw = "case.raw"\ndyr = "case.dyr"\n')
    out = check_case(load_case(tmp / "case.toml"), progress=False, only=["9_1", "10_1", "11_1", "12_1"])
    return {e["name"]: e for e in out["units"]}


@pytest.mark.slow
def test_a_pv_plant_is_checked(doc):
    plant = doc["9_1"]
    assert plant["category"] == "inverter-based" and plant["outcome"] == "pass", plant["reasons"]
    assert plant["models"] == {"converter": "REGCA1", "electrical": "REECB1", "plant": "REPCA1"}
    n = plant["numbers"]
    assert n["max_dxdt_t0"] < 1e-6 and abs(n["p_error_held_pu"]) < 1e-5 and abs(n["q_error_held_pu"]) < 1e-5
    assert n["fstep_p_change_pu"] < -1e-3              # over-frequency: P down by REPCA1's droop


@pytest.mark.slow
def test_a_storage_plant_is_checked(doc):
    plant = doc["10_1"]
    assert plant["outcome"] == "pass", plant["reasons"]
    assert plant["models"] == {"converter": "REGCB1", "electrical": "REECCU1", "plant": "REPCA1"}
    n = plant["numbers"]
    assert n["max_dxdt_t0"] < 1e-6 and abs(n["p_error_held_pu"]) < 1e-5 and abs(n["q_error_held_pu"]) < 1e-5
    assert n["fstep_p_change_pu"] < -1e-3
    assert any("state of charge" in note for note in plant["notes"])


@pytest.mark.slow
def test_a_storage_plant_at_its_soc_limit_is_a_data_problem(doc):
    plant = doc["11_1"]
    assert plant["outcome"] == "data problem"
    assert plant["records_at_fault"] == ["REECCU1"]
    assert "SOCini = 0.2 at or beyond SOCmin = 0.2 with P0 = 0.1 pu" in plant["reasons"][0]


@pytest.mark.slow
def test_a_storage_plant_that_empties_within_the_check_is_a_data_problem(doc):
    plant = doc["12_1"]
    assert plant["outcome"] == "data problem" and plant["records_at_fault"] == ["REECCU1"]
    assert "SOCini = 0.2001 reaches SOCmin = 0.2 after 0.999 s at P0 = 0.1 pu (T = 999 s" in plant["reasons"][0]
