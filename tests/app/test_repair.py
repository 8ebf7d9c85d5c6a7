"""``jaxdse check --repair``: the repaired .dyr, its change table, and the repairs read back.

The case is ``test_check.py``'s (five ieee14 units, three records made bad), so the check's
compiled program is shared (one xdist work unit, ``tests/conftest.py``): bus 6's TGOV1 VMAX 0.25
lies below its initial valve position 0.3 (a crossed limit: repaired), bus 3's ESST3A has VIMAX
below VIMIN (values the model refuses: not repaired), bus 2's exciter is not simulated. Here bus
8's MBASE is also cut from 100 to 20 MVA in the .raw (PT = 50 MW, PG = 35 MW: ACTIVSg2000's hydro
units' mistake), which runs its TGOV1 past VMAX too: the repair is MBASE in a repaired.raw, and
the unit, checked again at the new base, needs no governor change. The repaired case is checked
again (buses 6 and 8 pass, their changes listed) and read by the fleet loader.
The rule's arithmetic, the reader's comment lines and the in-place edit of a multi-line,
comma-separated record are tested apart, without a simulation.
"""

import csv
import json
from pathlib import Path

import pytest

import jaxdse as jd
from jaxdse._app.cli import main
from jaxdse._app.fleet_file import load_fleet
from jaxdse._dyr.repair import (
    DIGITS,
    MARGIN,
    Change,
    Plan,
    _moved,
    _outward,
    carried_raw_lines,
    plan,
    repaired_dyr,
)

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "experiments" / "andes_bench" / "data" / "ieee14"


GEN8 = "8, '1', 35, 7.39639154, 10, -6, 1.03, 0, 100,"
"""Bus 8's generator record up to MBASE (line 38 of ieee14.raw)."""


def _bad(text: str) -> str:
    """As test_check.py's: bus 2 EXST1 -> EXST2; bus 3 ESST3A VIMAX -0.2 < VIMIN 0.2; bus 6
    TGOV1 VMAX 0.25 (its unit starts at PG/MBASE = 0.3)."""
    text = text.replace("2 'EXST1' 1 0.02 99 -99 0 0.02 50\n    0.02 9999 -9999 0 0.01 1 /",
                        "2 'EXST2' 1 0.02 50 0.02 9999 -9999 0 0.01 1 1 0.2 1 0.5 0.05 /")
    text = text.replace("3 'ESST3A' 1 0.02 0.2 -0.2 8 1 5", "3 'ESST3A' 1 0.02 -0.2 0.2 8 1 5")
    return text.replace("6 'TGOV1' 1 0.05 0.05 1.05 0.3 1 2.1", "6 'TGOV1' 1 0.05 0.05 0.25 0.0 1 2.1")


@pytest.fixture(scope="module")
def repaired(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("repair")
    raw = (BENCH / "ieee14.raw").read_text()
    assert raw.count(GEN8) == 1
    (tmp / "case.raw").write_text(raw.replace(GEN8, GEN8.replace(", 100,", ", 20,")))
    (tmp / "case.dyr").write_text(_bad((BENCH / "ieee14.dyr").read_text()))
    (tmp / "case.toml").write_text('[case]\nraw = "case.raw"\ndyr = "case.dyr"\n'
                                   '[playback]\nke_zero = "literal"\n')
    assert main(["check", str(tmp / "case.toml"), "--repair", "--out", str(tmp / "out")]) == 0
    assert main(["check", str(tmp / "out" / "repaired.toml"), "--out", str(tmp / "again")]) == 0
    return tmp


def test_the_change_table(repaired):
    from jaxdse._app.check import console_table

    doc = json.loads((repaired / "out" / "check.json").read_text())
    r = doc["repair"]
    assert r["units"] == 2 and len(r["changes"]) == 2
    assert r["checked_again_at_new_mbase"] == ["8_1"]
    base, c = r["changes"]
    assert (c["unit"], c["record"], c["file"], c["line"], c["con"], c["con_number"]) == \
        ("6_1", "TGOV1", "case.dyr", 28, "VMAX", 3)
    assert (c["old"], c["new"], c["bound"], c["side"]) == (0.25, 0.315, 0.25, "above")
    assert c["value"] == pytest.approx(0.3)        # TM0 = PG/MBASE
    assert "valve0 = TM0 = 0.3 above VMAX = 0.25" in c["why"]
    # the inverted limit is not a crossed limit: left, and said so; the unsupported model is no data problem
    assert [x["unit"] for x in r["not_repaired"]] == ["3_1"]
    assert "not a crossed limit" in r["not_repaired"][0]["why"] and "VIMAX" in r["not_repaired"][0]["why"]
    # bus 8: MBASE below its own PT and power flow; MBASE moved, its governor left alone
    assert (base["unit"], base["record"], base["file"], base["line"], base["con"], base["con_number"]) == \
        ("8_1", "generator", "case.raw", 38, "MBASE", 9)
    s0 = (35**2 + 7.39639154**2) ** 0.5
    assert (base["old"], base["new"], base["bound"]) == (20.0, 37.57, 20.0)
    assert base["value"] == pytest.approx(s0)
    assert base["new"] >= s0 * (1 + MARGIN) > base["new"] - 0.01
    assert base["why"].startswith("|S0| = |PG + jQG| = 35.77 above MBASE = 20 (PG = 35 MW, QG = 7.396 Mvar: "
                                  "1.79 x MBASE, flagged above 1.1 x); MBASE at least 37.56 puts it 5 % "
                                  "inside; "
                                  "its PT = 50 MW is 2.5 x MBASE; the case's other in-service generators "
                                  "have MBASE = 2 x PT (median)")
    (e8,) = [e for e in doc["units"] if e["name"] == "8_1"]
    assert e8["outcome"] == "data problem" and e8["reasons"][0].startswith(
        "generator on bus 8 id '1' (case.raw line 38): |S0| = |PG + jQG| = 35.77 above MBASE = 20")
    assert [lim["record"] for lim in e8["limits"]] == ["generator", "TGOV1"]
    rows = list(csv.DictReader((repaired / "out" / "repairs.csv").open()))
    assert [x["con"] for x in rows] == ["MBASE", "VMAX"] and float(rows[1]["new"]) == 0.315
    assert rows[1]["line"] == "28" and rows[1]["unit"] == "6_1" and rows[0]["record"] == "generator"
    lines = console_table(doc).splitlines()
    assert any(line.split() == ["6_1", "TGOV1", "case.dyr:28", "VMAX", "0.25", "0.315", *c["why"].split()]
               for line in lines)
    assert any(line.strip().startswith("not repaired: 3_1: not a crossed limit") for line in lines)
    page = (repaired / "out" / "check.html").read_text()
    assert "<h2>Repair</h2>" in page and "0.315" in page and "repaired.dyr" in page


def test_repaired_dyr_changes_one_token_and_reads_back(repaired):
    old = (repaired / "case.dyr").read_text().splitlines()
    new = (repaired / "out" / "repaired.dyr").read_text().splitlines()
    assert new[0].startswith("/ jaxdse check --repair: 1 constant(s) changed on 1 unit(s)")
    assert new[1].startswith("/ rule: ")
    body = [line for line in new[2:] if not line.startswith("/ jaxdse repair: ")]
    assert len(body) == len(old)
    assert [(a, b) for a, b in zip(old, body) if a != b] == \
        [("6 'TGOV1' 1 0.05 0.05 0.25 0.0 1 2.1", "6 'TGOV1' 1 0.05 0.05 0.315 0.0 1 2.1")]
    dyr = jd.read_dyr(repaired / "out" / "repaired.dyr")        # strict: a valid .dyr
    assert len(dyr.records) == len(jd.read_dyr(repaired / "case.dyr", strict=False).records)
    assert not dyr.problems
    (gov,) = [r for r in dyr.records if r.bus == 6 and r.model == "TGOV1"]
    assert gov["VMAX"] == 0.315
    (ch,) = gov.changes
    assert (ch.con, ch.old, ch.new, ch.origin) == ("VMAX", 0.25, 0.315, "case.dyr line 28")
    assert all(not r.changes for r in dyr.records if r is not gov)
    text = (repaired / "out" / "repaired.toml").read_text()
    assert 'dyr = "repaired.dyr"' in text and 'ke_zero = "literal"' in text
    assert 'raw = "repaired.raw"' in text


def test_repaired_raw_changes_one_field_and_reads_back(repaired):
    old = (repaired / "case.raw").read_text().splitlines()
    new = (repaired / "out" / "repaired.raw").read_text().splitlines()
    assert len(new) == len(old)
    ((a, b),) = [(a, b) for a, b in zip(old, new) if a != b]
    assert a.startswith(GEN8.replace(", 100,", ", 20,"))
    assert b.startswith(GEN8.replace(", 100,", ", 37.57,"))
    assert b.split(" / ")[0] == a.replace(", 20,", ", 37.57,", 1)
    raw = jd.read_raw(repaired / "out" / "repaired.raw")       # strict: a valid .raw
    g = raw.generator(8, "1")
    assert g.mbase_mva == 37.57 and g.pg_mw == 35.0 and g.pt_mw == 50.0
    (c,) = g.changes
    assert (c.con, c.old, c.new, c.origin) == ("MBASE", 20.0, 37.57, "case.raw line 38")
    assert all(not x.changes for x in raw.generators if x is not g)
    (line,) = carried_raw_lines(g)
    assert line.startswith("generator on bus 8 id '1' (.raw): MBASE 20 -> 37.57 by jaxdse check --repair "
                           "(was case.raw line 38): |S0| = |PG + jQG| = 35.77 above MBASE = 20")


def test_the_repaired_case_passes_and_lists_its_change(repaired):
    doc = json.loads((repaired / "again" / "check.json").read_text())
    units = {e["name"]: e for e in doc["units"]}
    assert units["6_1"]["outcome"] == "pass" and units["8_1"]["outcome"] == "pass"
    (c,) = units["6_1"]["repairs"]
    assert (c["record"], c["con"], c["old"], c["new"], c["holds_new"]) == ("TGOV1", "VMAX", 0.25, 0.315, True)
    (c,) = units["8_1"]["repairs"]
    assert (c["record"], c["con"], c["old"], c["new"], c["holds_new"]) == \
        ("generator", "MBASE", 20.0, 37.57, True)
    assert all(not e["repairs"] for n, e in units.items() if n not in ("6_1", "8_1"))
    s = doc["summary"]
    assert (s["pass"], s["data problem"], s["not supported"], s["fail"]) == (3, 1, 1, 0)
    assert doc["repaired_units"] == 2
    assert "Repaired records" in (repaired / "again" / "check.html").read_text()


def test_fleet_reads_the_repaired_case(repaired):
    """The fleet loader (``jaxdse fleet`` and ``jaxdse validate``) takes repaired.dyr as any
    .dyr, and the plant carries its change for its pages (a fleet run on repaired records is in
    test_dyr_playback.py)."""
    import pandas as pd

    df = pd.read_csv(BENCH / "line_trip.csv.gz")
    df[df["time_s"] <= 12.0].to_csv(repaired / "trip.csv", index=False)
    cols = ", ".join(f'{k} = "B6_G1/{v}"' for k, v in (("v_mag", "VM"), ("v_ang", "VA"), ("i_mag", "IM"),
                                                        ("i_ang", "IA")))
    (repaired / "fleet.toml").write_text(
        '[case]\nraw = "case.raw"\ndyr = "out/repaired.dyr"\n\n[measurement]\nfile = "trip.csv"\n'
        'location = "terminal"\nvoltage_unit = "pu"\ncurrent_unit = "pu"\nangle_unit = "deg"\n'
        f's_base_mva = 100.0\nmin_segment_s = 10.0\n\n[[unit]]\nname = "B6_G1"\nbus = 6\n'
        f'columns = {{time = "time_s", {cols}}}\n\n[playback]\nke_zero = "literal"\n')
    fleet = load_fleet(repaired / "fleet.toml")
    (p,) = fleet.plants
    (line,) = p.repairs
    assert line.startswith("TGOV1 on bus 6 id '1' (repaired.dyr line ")
    assert "VMAX 0.25 -> 0.315 by jaxdse check --repair (was case.dyr line 28)" in line


# --- the rule, the reader, the writer: no simulation ------------------------------------------

def test_the_rule_moves_the_limit_past_the_signal_by_the_margin():
    assert _outward(2.2463, up=True) == 2.247 and _outward(2.2463, up=False) == 2.246
    assert _outward(-0.123456, up=True) == -0.1234 and _outward(1.0, up=True) == 1.0
    # EFD0 = 3 above VT·VRMAX - KC·IFD0 (VT = 0.95, KC·IFD0 = 0.2): VRMAX = (3·1.05 + 0.2)/0.95
    lim = {"value": 3.0, "side": "above", "fix": {"con": "VRMAX", "scale": 0.95, "offset": -0.2}}
    target, con = _moved(lim)
    assert target == pytest.approx(3.0 * (1 + MARGIN))
    assert con == pytest.approx((3.15 + 0.2) / 0.95, rel=10 ** -(DIGITS - 1)) and con >= (3.15 + 0.2) / 0.95
    # below a lower limit near 0: at least 0.01 pu inside, the CON rounded down
    fix = {"con": "VMIN", "scale": 1.0, "offset": 0.0}
    target, con = _moved({"value": 0.05, "side": "below", "fix": fix})
    assert target == pytest.approx(0.04) and con == pytest.approx(0.04) and con <= 0.04
    assert _moved({"value": 1.0, "side": "below", "fix": None}) is None           # a floor at 0
    assert _moved({"value": 1.0, "side": "above", "fix": {"con": "VLR", "scale": 0.0, "offset": 1.0}}) is None


def test_a_dc_exciter_with_computed_limits_gets_both_written(tmp_path):
    """ESDC2A with VRMAX = 0 (PSS/E: VRMAX = (SE(E2) + KE)·E2, VRMIN = -VRMAX): VR0 above VT·VRMAX
    moves VRMAX, and VRMIN is written as the value the record stated."""
    rec = "7 'ESDC2A' 1 0.025 9.3 0.05 0.11 0.75 0 0 1 1 0 1 0 3 0.1 4 0.3 /\n"   # VRMAX (0.3 + 1)·4
    (tmp_path / "a.dyr").write_text(rec)
    dyr = jd.read_dyr(tmp_path / "a.dyr")
    lim = {"record": "ESDC2A", "line": 1, "signal": "VR0 = (KE + SE(EFD0))·EFD0", "value": 20.0,
           "con": "VT·VRMAX", "bound": 5.2, "side": "above",
           "fix": {"con": "VRMAX", "scale": 1.0, "offset": 0.0}}
    doc = {"units": [{"name": "7_1", "bus": 7, "id": "1", "outcome": "data problem", "limits": [lim],
                      "reasons": ["ESDC2A on bus 7 id '1' (a.dyr line 1): ...", "hence: ..."],
                      "numbers": {}}]}
    p = plan(doc, dyr, ke_zero="psse")
    assert [(c.con, c.old, c.new) for c in p.changes] == [("VRMAX", 0.0, 21.0),
                                                          ("VRMIN", 0.0, pytest.approx(-5.2))]
    assert "VRMAX = 0 in the record" in p.changes[1].why
    text, whole = repaired_dyr(p, [str(tmp_path / "a.dyr")])
    (tmp_path / "b.dyr").write_text(text)
    (r,) = jd.read_dyr(tmp_path / "b.dyr").records
    assert r.constants[5] == 21.0 and r.constants[6] == pytest.approx(-5.2) and len(r.changes) == 2
    # the other reading of VRMAX = 0 (ANDES's: no limit) leaves VRMIN alone
    assert [c.con for c in plan(doc, dyr, ke_zero="literal").changes] == ["VRMAX"]


def test_the_reader_attaches_repair_lines_and_the_writer_edits_in_place(tmp_path):
    """A wecc-style record (commas, an unquoted ID, two lines) edited in place; repair lines
    attached to the record they name wherever they stand; one naming no record, or not in the
    form, listed in ``problems``; '/' comment lines are not empty records."""
    text = ("/ a comment line\n"
            "1333, 'TGOV1', G , 0.05, 0.5,\n  0.9, 0.0, 1.0, 2.1, 0.0/ trailing\n"
            "/\n"
            "1334 'TGOV1' G 0.05 0.5 1.2 0.0 1.0 2.1 0.0 /\n")
    (tmp_path / "w.dyr").write_text(text)
    dyr = jd.read_dyr(tmp_path / "w.dyr")
    assert dyr.empty_records == 1 and [r.line for r in dyr.records] == [2, 5]
    first = dyr.records[0]
    p = Plan((Change("1333_G", first, "VMAX", 2, 0.9, 1.05, "valve0 = TM0 = 1 above VMAX = 0.9"),), ())
    out, whole = repaired_dyr(p, [str(tmp_path / "w.dyr")])
    assert whole and "  1.05, 0.0, 1.0, 2.1, 0.0/ trailing\n" in out
    assert out.endswith(text.splitlines()[-1] + "\n")
    out += "/ jaxdse repair: VMAX of TGOV1 bus 9 id '1': 1 -> 2 (w.dyr line 9): nowhere\n"
    out += "/ jaxdse repair: VMAX of something else\n"
    (tmp_path / "x.dyr").write_text(out)
    back = jd.read_dyr(tmp_path / "x.dyr")
    a, b = back.records
    assert a["VMAX"] == 1.05 and b["VMAX"] == 1.2 and not b.changes
    (c,) = a.changes
    assert (c.model, c.bus, c.id, c.con, c.old, c.new, c.origin) == ("TGOV1", 1333, "G", "VMAX", 0.9, 1.05,
                                                                    "w.dyr line 2")
    assert c.why == "valve0 = TM0 = 1 above VMAX = 0.9"
    assert len(back.problems) == 2 and "not in the form" in back.problems[0]
    assert "a record not in this file" in back.problems[1] and "\n" not in back.problems[1]
