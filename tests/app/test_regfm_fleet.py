"""The WECC grid-forming inverters in a PSS/E case: the droop-controlled REGFM_A1 (PSS/E REGFMA1)
and the virtual synchronous machine REGFM_B1 (PSS/E REGFMB1U). Their records checked (their steps
judged: a source behind ZSORCE synchronises against the imposed voltage), their limits at the
power flow named, and in one ``jaxdse fleet`` run their inertia fitted to a recording by their
playback, with an interval and a verdict, and their playback validated: REGFM_A1's equivalent
swing equation (TPf, mp: H = TPf / (2 mp)), REGFM_B1's H and mp.

The recordings are round trips (each module's own playback under the ANDES bench's bus-8 voltage
of the stored line trip, ``experiments/andes_gfm``, with 0.1 % noise): ANDES has no REGFM model;
the modules are checked against their SciPy block diagrams in tests/models/test_regfm_a1.py and
test_regfm_b1.py. At 60 frames/s (the recording's rate); at 30 frames/s the same test took longer
(140 s against 118 s alone) and identified less (REGFM_A1's H +-58 %, REGFM_B1's -4.5 %).
"""

import gzip
import json
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._app.cli import main
from jaxdse._dyr.gfm_unit import GfmUnit
from jaxdse._dyr.playback import TerminalSeries, play_back

ROOT = Path(__file__).resolve().parents[2]
RAW = ROOT / "experiments" / "andes_bench" / "data" / "ieee14" / "ieee14.raw"
GFM = ROOT / "experiments" / "andes_gfm"
TRUE = dict(
    VFlag=1,
    QVFlag=0,
    TPf=0.02,
    TQf=0.02,
    TVf=0.02,
    Imax=2.0,
    Emax=1.3,
    Emin=0.0,
    Pmax=1.0,
    Pmin=0.0,
    Qmax=1.0,
    Qmin=-1.0,
    mp=0.01,
    mq=0.05,
    kppmax=0.01,
    kipmax=0.1,
    kpqmax=3.0,
    kiqmax=20.0,
    kpv=0.0,
    kiv=6.0,
)
H_TRUE = TRUE["TPf"] / (2 * TRUE["mp"])
TRUE_B1 = dict(
    wFlag=0,
    VdrpFlag=0,
    QVFlag=0,
    PQFlag=1,
    FFlag=1,
    ESFlag=1,
    mq=0.05,
    kpv=0.0,
    kiv=5.0,
    mp=0.02,
    Dwmax=0.05,
    Dwmin=-0.05,
    kpPLL=0.265,
    kiPLL=2.65,
    DwPLLmax=0.2,
    DwPLLmin=-0.2,
    Tp=0.0,
    H=2.0,
    D1=0.0,
    D2=100.0,
    wD=50.0,
    ImaxSS=1.0,
    kf=0.9,
    kI=2.0,
    ImaxF=1.5,
    TPf=0.02,
    TQf=0.02,
    TVf=0.02,
    TIf=0.02,
    Ke=1.0,
    VPLLfrz=0.05,
)
"""A grid-forming storage plant (ESFlag = 1). With ESFlag = 0 the angle's lower limit is 0: at bus 6
the line trip takes P to it, and the noisy voltage then switches the non-windup limit on and off
at every frame (a playback 14 times slower, and the fit of H and mp did not converge)."""
PLANTS = {
    8: ("REGFMA1", TRUE, 0.34, 0.35 + 0.0739639154j),
    6: ("REGFMB1U", TRUE_B1, 0.28, 0.30 + 0.2098659644j),
}
"""bus: (model, true constants, the .raw's ZSORCE X, the power flow's P + jQ on MBASE)"""


def _record(bus, model="REGFMA1", **change) -> str:
    c = {**(TRUE if model == "REGFMA1" else TRUE_B1), **change}
    return f" {bus} '{model}' '1' {' '.join(f'{c[k]:g}' for k in jd.IBR_FIELDS[model])} /\n"


@pytest.mark.slow
def test_check_judges_its_steps_and_names_its_limits(tmp_path):
    """REGFM_A1 on bus 8 passes (held run, voltage step and frequency step judged; P answers +0.1
    Hz by -0.1/60/mp pu); bus 6's Pmax below its power flow is a data problem naming Pmax; bus 3
    with ZSORCE X = 0 has no coupling reactance, named. REGFM_B1 on bus 2 passes (P answers by
    -(1/mp + D1) 0.1/60 pu); on bus 1 (0.81 pu) its ImaxSS of 0.5 is crossed, named."""
    raw = RAW.read_text().replace(
        "3, '1', 40, 12.59713327, 15, -10, 1.01, 0, 100, 0, 0.34,",
        "3, '1', 40, 12.59713327, 15, -10, 1.01, 0, 100, 0, 0,",
    )
    (tmp_path / "case.raw").write_text(raw)
    (tmp_path / "case.dyr").write_text(
        _record(8)
        + _record(6, Pmax=0.25)
        + _record(3)
        + _record(2, "REGFMB1U")
        + _record(1, "REGFMB1U", ImaxSS=0.5)
    )
    (tmp_path / "check.toml").write_text('[case]\nraw = "case.raw"\ndyr = "case.dyr"\n')
    main(["check", str(tmp_path / "check.toml"), "--out", str(tmp_path / "check")])
    units = {u["bus"]: u for u in json.loads((tmp_path / "check" / "check.json").read_text())["units"]}
    ok = units[8]
    assert ok["outcome"] == "pass" and ok["notes"] == [], ok
    assert ok["numbers"]["fstep_p_change_pu"] == pytest.approx(-0.1 / 60 / TRUE["mp"], rel=1e-6)
    assert ok["numbers"]["vstep_max_dxdt_end"] < 1e-6
    assert units[6]["outcome"] == "data problem"
    assert "P0 = 0.3 pu above Pmax = 0.25" in " ".join(units[6]["reasons"])
    assert units[3]["outcome"] == "data problem"
    assert "ZSORCE X > 0" in " ".join(units[3]["reasons"])
    assert units[2]["outcome"] == "pass" and units[2]["notes"] == [], units[2]
    assert units[2]["numbers"]["fstep_p_change_pu"] == pytest.approx(-0.1 / 60 / TRUE_B1["mp"], rel=1e-4)
    assert units[1]["outcome"] == "data problem"
    assert "above ImaxSS = 0.5" in " ".join(units[1]["reasons"])


def _recording(path: Path) -> dict:
    """8 s of the line trip's bus-8 voltage imposed on each plant's true record (a round trip), P
    and Q out as its terminal current, 0.1 % noise on every phasor; one CSV, a column set per bus.
    Returns each plant's swing of P."""
    with gzip.open(GFM / "line_trip.csv.gz", "rt") as fh:
        header = fh.readline().strip().split(",")
        body = np.loadtxt(fh, delimiter=",")
    d = {k: body[:, j] for j, k in enumerate(header)}
    keep = (d["time_s"] >= 7.0 - 1e-9) & (d["time_s"] <= 15.0 + 1e-9)
    t, vm, va = d["time_s"][keep], d["B8_VSG/VM"][keep], np.deg2rad(d["B8_VSG/VA"][keep])
    n, v = len(t), vm * np.exp(1j * va)
    rng = np.random.default_rng(5)
    cols, swing = {"time_s": [f"{a:.6f}" for a in t]}, {}
    for bus, (model, true, zx, s0) in PLANTS.items():
        conv = jd.ibr_from_dyr(model, [true[k] for k in jd.IBR_FIELDS[model]])
        conv = eqx.tree_at(lambda c: c.xe_pu, conv, jnp.asarray(zx))
        i0 = np.conj(s0 / v[0])
        r = play_back(
            GfmUnit(conv),
            TerminalSeries(
                jnp.asarray(t),
                jnp.asarray(vm),
                jnp.asarray(np.unwrap(va)),
                jnp.full(n, i0.real),
                jnp.full(n, i0.imag),
            ),
        )
        assert bool(r.ok)
        i = np.conj((np.asarray(r.p_pu) + 1j * np.asarray(r.q_pu)) / v)
        vn, i_n = (
            x * (1 + 1e-3 * rng.standard_normal(n)) * np.exp(1e-3j * rng.standard_normal(n)) for x in (v, i)
        )
        for key, x in (
            ("VM", np.abs(vn)),
            ("VA", np.degrees(np.angle(vn))),
            ("IM", np.abs(i_n)),
            ("IA", np.degrees(np.angle(i_n))),
        ):
            cols[f"B{bus}/{key}"] = [f"{a:.8f}" for a in x]
        swing[bus] = float(np.ptp(np.asarray(r.p_pu)))
    path.write_text(",".join(cols) + "\n" + "\n".join(",".join(row) for row in zip(*cols.values())) + "\n")
    return swing


@pytest.mark.slow
def test_fleet_fits_the_inertia_and_validates_the_playback(tmp_path):
    """REGFM_A1 with TPf planted 50 % high (H 1.5 s against 1 s): the fit's H interval covers the
    truth and excludes the record's value, mp within 2 %. REGFM_B1 with H planted 30 % high (2.6 s
    against 2 s): H within 2 % of the truth, identified, the interval covering it; mp within 2 %.
    The validation of the records as filed passes REGFM_A1 (TPf barely shows in P) and fails REGFM_B1
    on P (its H 30 % off does); fleet.json and the pages say what H is."""
    assert min(_recording(tmp_path / "rec.csv").values()) > 0.1  # the event moves P
    (tmp_path / "case.raw").write_text(RAW.read_text())
    (tmp_path / "case.dyr").write_text(_record(8, TPf=1.5 * TRUE["TPf"]) + _record(6, "REGFMB1U", H=2.6))
    units = "".join(
        f'[[unit]]\nname = "B{b}_GFM"\nbus = {b}\ncolumns = {{time = "time_s", v_mag = "B{b}/VM", '
        f'v_ang = "B{b}/VA", i_mag = "B{b}/IM", i_ang = "B{b}/IA"}}\n\n'
        for b in PLANTS
    )
    (tmp_path / "fleet.toml").write_text(
        '[case]\nraw = "case.raw"\ndyr = "case.dyr"\n\n[measurement]\nfile = "rec.csv"\n'
        'location = "terminal"\nvoltage_unit = "pu"\ncurrent_unit = "pu"\nangle_unit = "deg"\n'
        's_base_mva = 100.0\nmin_segment_s = 5.0\n\n[playback]\nmodel = "dyr"\n\n' + units
    )
    assert main(["fleet", str(tmp_path / "fleet.toml"), "--out", str(tmp_path / "out")]) == 0
    by = {e["name"]: e for e in json.loads((tmp_path / "out" / "fleet.json").read_text())["units"]}
    for e in by.values():
        assert e["plant_type"] == "grid-forming"
        assert e["virtual_inertia"]["fitted"]["mp"]["value"] == pytest.approx(
            0.01 if e["bus"] == 8 else 0.02, rel=0.02
        )
    a1, b1 = by["B8_GFM"], by["B6_GFM"]
    assert a1["validation"]["result"] == "pass", a1["validation"]  # TPf barely shows in P
    assert b1["validation"]["result"] == "fail"  # H 30 % off does
    assert b1["validation"]["reasons"][0].startswith("P_t: RMS error"), b1["validation"]
    lo, hi = a1["H_ci95"]
    assert lo <= H_TRUE <= hi < 1.5 * H_TRUE, (a1["H_s"], a1["H_ci95"])
    assert a1["H_reference_s"] == pytest.approx(1.5 * H_TRUE)
    assert a1["D_ci95"][0] <= 1 / TRUE["mp"] <= a1["D_ci95"][1]
    assert a1["verdict"] in ("identified", "weakly identified"), a1["reasons"]
    assert b1["verdict"] == "identified" and b1["H_s"] == pytest.approx(2.0, rel=0.02), b1["reasons"]
    assert b1["H_ci95"][0] <= 2.0 <= b1["H_ci95"][1] < 2.6 and b1["H_reference_s"] == pytest.approx(2.6)
    page = (tmp_path / "out" / "units" / "B8_GFM.html").read_text()
    assert "equivalent inertia H = TPf/(2 mp)" in page and "TPf, mp → fitted" in page
    page = (tmp_path / "out" / "units" / "B6_GFM.html").read_text()
    assert "virtual inertia H [s]" in page and "H, mp → fitted" in page


def test_validate_calibrates_the_grid_forming_constants_and_writes_them_back(tmp_path):
    """``jaxdse validate``'s parameters of a REGFM_A1 (mp, mq) and a REGFM_B1 (H, mp, mq), and
    calibrated.dyr writes a changed one into its slot of the PSS/E record (read back). Measured
    with the CLI on the round trip above (mp x1.3 on REGFM_A1, H x1.3 on REGFM_B1): both found and
    calibrated within 0.1 % and 2 % (recorded in the closing note; 3 min, not run here)."""
    from types import SimpleNamespace

    from jaxdse._app.dyr_fleet import CalibrateOptions
    from jaxdse._app.validate import calibrated_dyr, parameter_specs
    from jaxdse._dyr.records import ibr_model

    (tmp_path / "case.dyr").write_text(_record(8) + _record(6, "REGFMB1U"))
    (tmp_path / "case.raw").write_text(RAW.read_text())
    dyr, raw = jd.read_dyr(tmp_path / "case.dyr"), jd.read_raw(tmp_path / "case.raw")
    labels = {}
    for bus, model in ((8, "REGFMA1"), (6, "REGFMB1U")):
        um = ibr_model(dyr, bus, "1", raw)
        specs = parameter_specs(um.unit, um.models, CalibrateOptions(), [])
        labels[model] = [(s.part, s.label) for s in specs]
    assert labels == {"REGFMA1": [("converter", "mp"), ("converter", "mq")],
                      "REGFMB1U": [("converter", "H"), ("converter", "mp"), ("converter", "mq")]}
    h = next(s for s in specs if s.label == "H")
    fit = SimpleNamespace(specs=(h,), labels=["H"], values=[1.9636])
    plant = SimpleNamespace(bus=6, ibr=True, members=[SimpleNamespace(id="1")])
    fleet = SimpleNamespace(path=tmp_path / "fleet.toml", dyr=dyr)
    text = calibrated_dyr(fleet, [(plant, None, SimpleNamespace(fit=fit, changed={"H"}))])
    (tmp_path / "cal.dyr").write_text(text)
    (rec,) = jd.read_dyr(tmp_path / "cal.dyr").unit_records(6, "1")
    assert rec.model == "REGFMB1U" and float(jd.ibr_from_dyr(rec.model, rec.constants).h_s) == 1.9636
