"""``[playback] model = "dyr"`` in ``jaxdse fleet`` and ``jaxdse validate``: the units' own PSS/E
records against ANDES's recordings (an independent simulator), the fallback for a model jaxdse
does not simulate, and the calibrated.dyr round trip."""

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import jaxdse as jd
from jaxdse._app.cli import main

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "experiments" / "andes_bench" / "data" / "ieee14"
KEEP_S = 20.0
COLS = "time = \"time_s\", v_mag = \"{t}/VM\", v_ang = \"{t}/VA\", i_mag = \"{t}/IM\", i_ang = \"{t}/IA\""


def _trim(src: Path, dst: Path) -> str:
    df = pd.read_csv(src)
    df[df["time_s"] <= KEEP_S].to_csv(dst, index=False)
    return dst.name


def _case(tmp: Path, dyr_text: str, events=("line_trip",), tags=("B1_G1", "B2_G1")) -> Path:
    (tmp / "case.raw").write_text((DATA / "ieee14.raw").read_text())
    (tmp / "case.dyr").write_text(dyr_text)
    files = [_trim(DATA / f"{e}.csv.gz", tmp / f"{e}.csv") for e in events]
    units = "".join(f"\n[[unit]]\nname = \"{t}\"\nbus = {b}\ncolumns = {{{COLS.format(t=t)}}}\n"
                    for t, b in ((t, int(t[1:t.index("_")])) for t in tags))
    text = (f"[case]\nraw = \"case.raw\"\ndyr = \"case.dyr\"\n\n[measurement]\nfile = \"{files[0]}\"\n"
            "location = \"terminal\"\nvoltage_unit = \"pu\"\ncurrent_unit = \"pu\"\nangle_unit = \"deg\"\n"
            "s_base_mva = 100.0\nmin_segment_s = 10.0\n" + units
            + "\n[identify]\nenabled = false\n\n[playback]\nmodel = \"dyr\"\n"
            + ("substeps = 2\n" if len(files) > 1 else "")   # a calibration fits with these too: time
            + (f"\n[calibrate]\nevents = {json.dumps(files[1:])}\nparameters = [\"H\"]\n"
               if len(files) > 1 else ""))
    (tmp / "fleet.toml").write_text(text)
    return tmp / "fleet.toml"


def _stiff(text: str, bus: int) -> str:
    """Bus ``bus``'s GENROU with X''d = X''q = 0.005 pu and Xl = 0.1 pu."""
    lines = text.splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith(f"{bus} 'GENROU'"))
    lines[k + 1] = "    " + " ".join(lines[k + 1].split()[:4] + ["0.005", "0.1"])
    return "\n".join(lines) + "\n"


REPAIR = ("/ jaxdse repair: VMAX of TGOV1 bus 1 id '1': 0.9 -> 1.05 (ieee14.dyr line 4): valve0 = TM0 = 1 "
          "above VMAX = 0.9; VMAX at least 1.05 puts the signal 5 % inside it\n")


def _repaired(text: str) -> str:
    """B1_G1's TGOV1 as ``jaxdse check --repair`` leaves a record it changed: its comment line
    before it (the values are the case's)."""
    return text.replace("1 'TGOV1' 1 ", REPAIR + "1 'TGOV1' 1 ", 1)


@pytest.fixture(scope="module")
def fleet_run(tmp_path_factory):
    """One fleet run: B1_G1 with its own records (its governor's as repaired), B2_G1 with its
    exciter renamed to a model jaxdse does not simulate (EXELI, same constants), B3_G1 with a
    stiff GENROU (X''d = 0.005 pu, Xl = 0.1 pu: a fastest mode near -3000 1/s)."""
    tmp = tmp_path_factory.mktemp("dyr_fleet")
    text = _stiff(_repaired((DATA / "ieee14.dyr").read_text().replace("2 'EXST1'", "2 'EXELI'")), bus=3)
    path = _case(tmp, text, tags=("B1_G1", "B2_G1", "B3_G1"))
    assert main(["fleet", str(path), "--out", str(tmp / "out")]) == 0
    return tmp, json.loads((tmp / "out" / "fleet.json").read_text())


def test_fleet_dyr_playback_matches_andes(fleet_run):
    tmp, doc = fleet_run
    u = {e["name"]: e for e in doc["units"]}["B1_G1"]
    assert u["playback_model"] == "dyr"
    assert u["playback_models"] == [{"machine": "GENROU", "exciter": "ESST3A", "governor": "TGOV1"}]
    # ANDES's own P and Q, its terminal voltage imposed: far below the surrogate's error
    assert u["playback_rms_percent_mbase"]["P_t"] < 0.1
    assert u["playback_rms_percent_mbase"]["Q_t"] < 0.1
    assert u["surrogate_playback_rms_percent_mbase"]["Q_t"] > 3 * u["playback_rms_percent_mbase"]["Q_t"]
    assert u["validation"]["result"] == "pass" and u["validation"]["model"] == "dyr"
    page = (tmp / "out" / "units" / "B1_G1.html").read_text()
    assert "own PSS/E records" in page and "ESST3A" in page
    # the repaired record's change, on fleet.json and the page
    (line,) = u["repairs"]
    assert line.startswith("TGOV1 on bus 1 id '1' (case.dyr line 5): VMAX 0.9 -> 1.05 by jaxdse check "
                           "--repair")
    assert "Repaired records" in page and "VMAX 0.9 -&gt; 1.05" in page
    assert {e["name"]: e for e in doc["units"]}["B2_G1"]["repairs"] == []


def test_fleet_dyr_falls_back_for_an_unsimulated_model(fleet_run):
    tmp, doc = fleet_run
    u = {e["name"]: e for e in doc["units"]}["B2_G1"]
    assert u["playback_model"] == "surrogate"
    assert "EXELI" in u["playback_fallback"] and "not simulated" in u["playback_fallback"]
    assert "EXELI" in (tmp / "out" / "units" / "B2_G1.html").read_text()
    # the surrogate validates active power/frequency only, and says so
    assert u["validation"]["model"] == "surrogate" and u["validation"]["channels"] == ["P_t", "x2"]
    assert "reactive power/voltage is not validated" in u["validation"]["scope"]


def test_fleet_dyr_plays_a_stiff_record_back_with_kvaerno5(fleet_run):
    """Its own records, no setting changed: the unit the explicit step cannot follow is found from
    its modes at rest and played back with Kvaerno5, and the plant says so. (ANDES recorded B3_G1
    with its true X''d, 0.34 pu: the playback need not match the recording, only run.)"""
    tmp, doc = fleet_run
    u = {e["name"]: e for e in doc["units"]}
    assert u["B3_G1"]["playback_model"] == "dyr" and "playback_fallback" not in u["B3_G1"]
    stiff = [n for n in u["B3_G1"]["playback_notes"] if "stiff: fastest mode -" in n]
    assert len(stiff) == 1 and "Kvaerno5" in stiff[0], u["B3_G1"]["playback_notes"]
    assert all(np.isfinite(v) for v in u["B3_G1"]["playback_rms_percent_mbase"].values())
    assert not any("stiff" in n for n in u["B1_G1"]["playback_notes"])
    assert "Kvaerno5" in (tmp / "out" / "units" / "B3_G1.html").read_text()


@pytest.mark.slow
def test_validate_recovers_planted_h_and_round_trips(tmp_path):
    """H planted 15 % high in the .dyr: the calibration on two events brings it back to the
    ANDES value, calibrated.dyr reads back, and a fleet run on [case.dyr, calibrated.dyr]
    reproduces the calibrated playback. B2_G1's exciter is a model jaxdse does not simulate
    (as in ``fleet_run``, whose compiled shapes the round trip shares): it is skipped."""
    truth = json.loads((DATA / "truth.json").read_text())
    h_true = next(m["H_s_mbase"] for m in truth["machines"] if m["tag"] == "B1_G1")
    text = _repaired((DATA / "ieee14.dyr").read_text().replace("2 'EXST1'", "2 'EXELI'"))
    first = text.index("1 'GENROU'")
    rec = text[first:text.index("/", first)]
    cons = rec.split()
    cons[7] = f"{1.15 * h_true:g}"         # bus 'GENROU' id T'do T''do T'qo T''qo H ...
    text = text.replace(rec, " ".join(cons) + " ")
    path = _case(tmp_path, text, events=("line_trip", "load_step"))
    assert main(["validate", str(path), "--out", str(tmp_path / "val")]) == 0
    doc = json.loads((tmp_path / "val" / "validate.json").read_text())
    u = {e["name"]: e for e in doc["units"]}
    assert "EXELI" in u["B2_G1"]["skipped"] and "parameters" not in u["B2_G1"]
    b1 = {p["parameter"]: p for p in u["B1_G1"]["parameters"]}
    assert b1["H"]["identifiable"]
    assert b1["H"]["calibrated_value"] == pytest.approx(h_true, rel=0.01)
    assert b1["H"]["ci95"][0] <= b1["H"]["calibrated_value"] <= b1["H"]["ci95"][1]
    # the interval's input part drew the recorded voltage's noise (ANDES's is round-off)
    noise = u["B1_G1"]["voltage_noise"]
    assert 0 <= noise["ln_v_sd"] < 1e-4 and 0 <= noise["angle_sd_rad"] < 1e-4
    assert u["B1_G1"]["residual_bandwidth_frames"] >= 0
    after = u["B1_G1"]["per_event"][0]["after_rms_percent_mbase"]
    before = u["B1_G1"]["per_event"][0]["before_rms_percent_mbase"]
    assert after["P_t"] < 0.5 * before["P_t"]
    # a calibration never makes the model worse: H (rejected) changed, nothing else; no event
    # worse; D at its physical bound or above
    assert b1["H"]["status"] == "changed" and not (b1["H"]["ci95"][0] <= 1.15 * h_true <= b1["H"]["ci95"][1])
    assert all(p["status"] != "changed" for k, p in b1.items() if k != "H")
    assert all(p["filed_value"] == p["dyr_value"] for k, p in b1.items() if k != "H")
    assert all(not ev["worse_beyond_noise"] for ev in u["B1_G1"]["per_event"])
    assert u["B1_G1"]["outcome"] == "changed H"
    assert len(u["B1_G1"]["repairs"]) == 1 and "VMAX 0.9 -> 1.05" in u["B1_G1"]["repairs"][0]
    assert "Repaired records" in (tmp_path / "val" / "units" / "B1_G1.html").read_text()
    cal = jd.read_dyr(tmp_path / "val" / "calibrated.dyr")
    genrou = [r for r in cal.records if r.model == "GENROU" and r.bus == 1]
    assert len(genrou) == 1 and genrou[0]["H"] == pytest.approx(b1["H"]["calibrated_value"], rel=1e-5)
    assert genrou[0]["D"] == 0.0
    # the round trip: the fleet on the case plus the calibrated records
    fleet_text = path.read_text().replace('dyr = "case.dyr"', 'dyr = ["case.dyr", "val/calibrated.dyr"]')
    (tmp_path / "again.toml").write_text(fleet_text)
    assert main(["fleet", str(tmp_path / "again.toml"), "--out", str(tmp_path / "again")]) == 0
    again = {e["name"]: e for e in json.loads((tmp_path / "again" / "fleet.json").read_text())["units"]}
    rms = again["B1_G1"]["playback_rms_percent_mbase"]
    assert rms["P_t"] == pytest.approx(after["P_t"], rel=1e-3, abs=1e-5)
    assert rms["Q_t"] == pytest.approx(after["Q_t"], rel=1e-3, abs=1e-5)
    assert np.isfinite(rms["P_t"])


@pytest.mark.parametrize("table, key", [({"input_filter_hz": -1.0}, "calibrate.input_filter_hz"),
                                        ({"max_relative_ci": 0.0}, "calibrate"),
                                        ({"input_draws": 8}, "calibrate.input_draws")])
def test_calibrate_section_refuses_bad_settings(tmp_path, table, key):
    from jaxdse._app.fleet_file import calibrate_section
    from jaxdse._io.errors import InputError

    with pytest.raises(InputError, match=f"key '{key}'") as info:
        calibrate_section(tmp_path / "fleet.toml", table)
    assert "\n" not in str(info.value)
    ok = calibrate_section(tmp_path / "fleet.toml", {"input_filter_hz": 5.0})
    assert ok.input_filter_hz == 5.0 and ok.max_relative_ci == 0.05
