"""A grid-forming converter in a PSS/E case: its REGCV1 record (ANDES's parameter order, no PSS/E
record exists) read into a :class:`GfmUnit`, checked, and in ``jaxdse fleet`` its virtual
inertia H = M/2 and damping D fitted to the recording by the record's playback, with an interval
and a verdict, on the stored ANDES line trip (experiments/andes_gfm: REGCV1 at bus 8 of the ANDES
bench's IEEE 14 case, H = 4 s, D = 2)."""

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

import jaxdse as jd
from jaxdse._app.cli import main
from jaxdse._dyr.gfm_unit import GfmUnit
from jaxdse._dyr.records import ibr_model

ROOT = Path(__file__).resolve().parents[2]
GFM = ROOT / "experiments" / "andes_gfm"
CASE = ROOT / "experiments" / "andes_bench" / "data" / "ieee14"
META = json.loads((GFM / "truth.json").read_text())


def _record(**change) -> str:
    c = {**META["constants"], **change}
    return f"8 'REGCV1' '1' {' '.join(f'{c[k]:g}' for k in jd.IBR_FIELDS['REGCV1'])} /\n"


def test_the_record_reads_into_a_grid_forming_unit(tmp_path):
    path = tmp_path / "gfm.dyr"
    path.write_text(_record() + " 9 'REGCV2' '1' 0.01 0 0 6 1 0 0.25 0.5 0.02 0.5 0.02 0.02 0.03 /\n"
                    + " 10 'REGCV1' '1' 0.01 0 0 -6 1 0 0.2 0.5 0.02 0.5 0.02 0.2 0.01 0.2 0.01 /\n"
                    + " 11 'REGCV1' '1' 0.01 0 0 6 1 0 0.2 0.5 0.02 0.5 0.02 0.2 0.01 0.2 0.01 /\n"
                    + " 11 'WTARA1' '1' 0.007 0 /\n")
    dyr = jd.read_dyr(path)
    m = ibr_model(dyr, 8, "1")
    assert m.missing == [] and isinstance(m.unit, GfmUnit) and m.structure == ("REGCV1", "-", "-")
    ref = jd.gfm_from_andes("REGCV1", META["constants"])
    for f in ("m_s", "d_pu", "xs_pu", "t_c_s", "kpvd", "kiid"):
        assert float(getattr(m.unit.converter, f)) == float(getattr(ref, f))
    two = ibr_model(dyr, 9, "1").unit.converter
    assert two.inner == "lag" and float(two.t_iq_s) == 0.02 and float(two.t_id_s) == 0.03
    assert ibr_model(dyr, 10, "1").missing == [
        "REGCV1 on bus 10 id '1' (gfm.dyr line 3): REGCV1: M must be > 0, got -6.0"]
    (why,) = ibr_model(dyr, 11, "1").missing
    assert "REGCV1 is a whole grid-forming converter; its WTARA1 record(s) have no place in it" in why


def _case(tmp_path, m_s) -> Path:
    """The bench case's .raw, the converter's record alone (M = ``m_s``) as its .dyr (the other
    generators then have no dynamic records: ``check`` counts them so), and 10 s of the line trip."""
    (tmp_path / "case.raw").write_text((CASE / "ieee14.raw").read_text())
    (tmp_path / "case.dyr").write_text(_record(M=m_s))
    with gzip.open(GFM / "line_trip.csv.gz", "rt") as fh:
        lines = fh.read().splitlines()
    t = np.array([float(x.split(",", 1)[0]) for x in lines[1:]])
    keep = [lines[0]] + [x for x, s in zip(lines[1:], t) if 6.0 - 1e-9 <= s <= 16.0 + 1e-9]
    (tmp_path / "line_trip.csv").write_text("\n".join(keep) + "\n")
    tag = META["tag"]
    path = tmp_path / "fleet.toml"
    path.write_text(
        '[case]\nraw = "case.raw"\ndyr = "case.dyr"\n\n[measurement]\nfile = "line_trip.csv"\n'
        'location = "terminal"\nvoltage_unit = "pu"\ncurrent_unit = "pu"\nangle_unit = "deg"\n'
        's_base_mva = 100.0\nmin_segment_s = 5.0\n\n[playback]\nmodel = "dyr"\n\n[[unit]]\n'
        'name = "B8_VSG"\nbus = 8\n'
        f'columns = {{time = "time_s", frequency = "{tag}/F", v_mag = "{tag}/VM", v_ang = "{tag}/VA", '
        f'i_mag = "{tag}/IM", i_ang = "{tag}/IA"}}\n')
    return path


@pytest.mark.slow
@pytest.mark.parametrize("factor", [1.5])
def test_fleet_identifies_the_virtual_inertia(tmp_path, factor):
    """H planted 50 % high in the record: the fleet's fit finds the truth within 2 %, its interval
    covers it and excludes the record's value, the verdict is identified; the page says what it is."""
    path = _case(tmp_path, factor * META["constants"]["M"])
    assert main(["check", str(path), "--out", str(tmp_path / "check")]) == 0
    checked = json.loads((tmp_path / "check" / "check.json").read_text())
    (u,) = checked["units"]
    assert u["outcome"] == "pass" and "virtual synchronous generator" in " ".join(u["notes"]), u
    assert main(["fleet", str(path), "--out", str(tmp_path / "out")]) == 0
    (e,) = json.loads((tmp_path / "out" / "fleet.json").read_text())["units"]
    h_true = META["H_s"]
    assert e["plant_type"] == "grid-forming" and e["verdict"] == "identified", e["reasons"]
    assert abs(e["H_s"] / h_true - 1) < 0.02
    assert e["H_ci95"][0] <= h_true <= e["H_ci95"][1] < factor * h_true
    assert e["H_reference_s"] == pytest.approx(factor * h_true)
    assert e["D_ci95"][0] <= META["D_pu"] + 0.1 and META["D_pu"] - 0.1 <= e["D_ci95"][1]
    page = (tmp_path / "out" / "units" / "B8_VSG.html").read_text()
    assert "virtual inertia H = M/2" in page and "the record&#x27;s D, not a lumped damping" in page


def test_several_converters_behind_one_pmu_are_said_not_fitted():
    """Two grid-forming converters on one bus: their shares are not measured, so no virtual H is
    fitted, and fleet.json and the page say why (never the grid-following "no rotor")."""
    import numpy as np

    from jaxdse._app.dyr_fleet import DyrOutcome, PlantModel, PlantPlayback
    from jaxdse._app.fleet_gfm import unfitted
    from jaxdse._app.fleet_report import ibr_unit_page
    from jaxdse._dyr.records import IbrModel

    one = IbrModel(GfmUnit(jd.gfm_from_andes("REGCV1", META["constants"])), {"converter": "REGCV1"})
    pb = PlantPlayback(np.zeros(3), np.zeros(3), np.zeros(3), True)
    assert unfitted(DyrOutcome(PlantModel([one], np.ones(1), np.ones(1), np.ones(1)), pb)) is None
    two = DyrOutcome(PlantModel([one, one], np.ones(2), np.ones(2) / 2, np.ones(2) / 2), pb)
    fields = unfitted(two)
    assert fields["plant_type"] == "grid-forming" and fields["verdict"] == "not identified"
    assert "2 grid-forming converter(s) among 2 units" in fields["reasons"]["several_units"]
    e = {"name": "B8", "bus": 8, "bus_kv": 1.0, "s_mva": 200.0, "units": [], "location": "terminal",
         "validation": {"result": "not judged", "reasons": [], "windows": None, "scope": "P/f, Q/V",
                        "model": "dyr"},
         "playback_rms_percent_mbase": {"P_t": None, "Q_t": None}, **fields}
    page = ibr_unit_page(e, {"jaxdse_version": "x", "config": {"file": "f", "sha256": "0"}}, False)
    assert "shares of P and Q are not measured" in page and "no rotor" not in page
