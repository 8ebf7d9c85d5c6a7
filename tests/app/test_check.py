"""``jaxdse check``: the no-disturbance check of every synchronous unit of a case.

A case of five units from the ANDES bench (ieee14) with three records made bad: an exciter with
an inverted limit (VIMAX below VIMIN), a governor whose VMAX lies below the unit's initial
valve position, and an exciter model jaxdse does not simulate (EXST2); and one made stiff (bus 8:
GENROU X''d = 0.005 pu, Xl = 0.1 pu, a fastest mode near -3200 1/s that the fixed Tsit5 step
cannot follow: run again with Kvaerno5, and passes). Eight more generator records, one of each
kind the check accounts for: a machine record of a model jaxdse does not know (GENSAL renamed
GENSAX), a governor record without a machine record, an out-of-service unit, a generator without
dynamic records, a static var compensator (CSVGN1), an inverter-based plant (REGCA1, REECA1,
REPCA1: checked, and passes), one whose converter model is not simulated (WT4G1: a unit, not
supported), a second record of one generator; and .dyr records of no generator (a bus not in the .raw, an ID not on its bus,
a USRBUS). Its check.json fields, the exit status, the console table; the case loader; the
limits found at the initial state. The three units that are simulated share one model
structure: one compile, and one more for Kvaerno5.
"""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import pytest

import jaxdse as jd

from jaxdse._app.check import load_case
from jaxdse._app.cli import main
from jaxdse._dyr.limits import Start, describe, exciter_crossings, governor_crossings
from jaxdse._models.base import ExciterInputs
from jaxdse._models.exciters import ESST4B
from jaxdse._models.governors import IEEEG1

BENCH = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench" / "data" / "ieee14"


def _case(tmp_path: Path, dyr_edit=lambda text: text, toml="", raw_edit=lambda text: text) -> Path:
    (tmp_path / "case.raw").write_text(raw_edit((BENCH / "ieee14.raw").read_text()))
    (tmp_path / "case.dyr").write_text(dyr_edit((BENCH / "ieee14.dyr").read_text()))
    path = tmp_path / "case.toml"
    path.write_text('[case]\nraw = "case.raw"\ndyr = "case.dyr"\n' + toml)
    return path


def _bad(text: str) -> str:
    """Bus 2: EXST1 -> EXST2 (not simulated); bus 3: ESST3A VIMAX -0.2 < VIMIN 0.2; bus 6:
    TGOV1 VMAX 0.25, VMIN 0 (its unit starts at PG/MBASE = 0.3)."""
    text = text.replace("2 'EXST1' 1 0.02 99 -99 0 0.02 50\n    0.02 9999 -9999 0 0.01 1 /",
                        "2 'EXST2' 1 0.02 50 0.02 9999 -9999 0 0.01 1 1 0.2 1 0.5 0.05 /")
    lines = text.splitlines()
    k = lines.index("3 'ESST3A' 1 0.02 0.2 -0.2 8 1 5")
    lines[k] = "3 'ESST3A' 1 0.02 -0.2 0.2 8 1 5"
    k = lines.index("6 'TGOV1' 1 0.05 0.05 1.05 0.3 1 2.1")
    lines[k] = "6 'TGOV1' 1 0.05 0.05 0.25 0.0 1 2.1"
    return _stiff("\n".join(lines) + "\n")


def _stiff(text: str, bus: int = 8) -> str:
    """Bus ``bus``'s GENROU with X''d = X''q = 0.005 pu and Xl = 0.1 pu (its fastest mode near
    -3200 1/s at rest; the fixed explicit step 1/120 s follows modes down to -400 1/s)."""
    lines = text.splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith(f"{bus} 'GENROU'"))
    cons = lines[k + 1].split()
    lines[k + 1] = "    " + " ".join(cons[:4] + ["0.005", "0.1"])
    return "\n".join(lines) + "\n"


GEN = "{bus}, '{id}', 10, 0, 10, -10, 1.0, 0, 100, 0, 0.3, 0, 0, 1, {stat}, 100, 50, 0, 1, 1\n"
EXTRA_GENERATORS = {(10, "1", 1): "GENSAX (renamed GENSAL): machine model unknown",
                    (11, "1", 1): "TGOV1 alone: no machine record",
                    (3, "2", 0): "out of service, with a machine record",
                    (4, "1", 1): "no dynamic records",
                    (5, "1", 1): "CSVGN1: not a generator",
                    (9, "1", 1): "REGCA1, REECA1, REPCA1: an inverter-based plant",
                    (13, "2", 1): "WT4G1: an inverter-based plant, model not simulated",
                    (12, "1", 1): "no dynamic records",
                    (12, "1", 1, "again"): "its second record: duplicate"}
EXTRA_RECORDS = """10 'GENSAX' 1 5 0.05 0.1 3 0 1.8 1.7 0.3 0.2 0.15 0.1 0.3 /
10 'SEXS' 1 0.1 10 100 0.1 0 3 /
11 'TGOV1' 1 0.05 0.05 1.05 0.3 1 2.1 0 /
3 'GENROU' 2 6.5 0.06 0.2 0.05 5 0 1.8 1.75 0.6 0.8 0.34 0.15 0.09 0.38 /
5 'CSVGN1' 1 5 0.1 0.05 100 0.01 1 0 100 /
9 'REGCA1' '1' 1 0.02 10 0.9 0.4 1.22 1.2 0.8 0.4 -1.3 0.02 0.7 999 -999 0.7 /
9 'REECA1' '1' 0 0 1 0 0 0 0.9 1.1 0.02 -0.05 0.05 2 1.05 -1.05 0 0 0 0 0.05 0.436 -0.436
   1.1 0.9 0 0.1 0 40 0 0.02 99 -99 1 0 1.7 0.02
   0.2 1.5 0.5 1.5 1 1.5 1.5 1.5  0.2 1.5 0.5 1.5 1 1.5 1.5 1.5 /
9 'REPCA1' '1' 0 9 7 '1' 0 1 1 0.02 18 5 0 0.075 0 0 0 0 0.1 -0.1 0 0 0.436 -0.436 0.1 0.05
   0.25 0 0 999 -999 999 -999 0.1 20 0 /
13 'WT4G1' 2 0.02 0.5 0.9 1.11 1.2 2 2 0.02 /
99 'GENROU' 1 6.5 0.06 0.2 0.05 5 0 1.8 1.75 0.6 0.8 0.34 0.15 0.09 0.38 /
13 'GENROU' 7 6.5 0.06 0.2 0.05 5 0 1.8 1.75 0.6 0.8 0.34 0.15 0.09 0.38 /
14 'USRBUS' 'PLNTBU1' 504 0 7 28 7 15 14 13 14 '1' 0 1 /
"""


def _more(text: str) -> str:
    """The nine generator records of ``EXTRA_GENERATORS`` after the five of the case."""
    rows = "".join(GEN.format(bus=k[0], id=k[1], stat=k[2]) for k in EXTRA_GENERATORS)
    return text.replace("0 / End of Generator data", rows + "0 / End of Generator data")


@pytest.fixture(scope="module")
def checked(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("check")
    case = _case(tmp, lambda t: _bad(t) + EXTRA_RECORDS, '[playback]\nke_zero = "literal"\n', _more)
    return main(["check", str(case), "--out", str(tmp / "out")]), tmp / "out"


@pytest.mark.slow
def test_outcomes_reasons_and_json(checked):
    rc, out = checked
    assert rc == 0  # whatever the outcomes
    doc = json.loads((out / "check.json").read_text())
    units = {e["name"]: e for e in doc["units"]}
    assert set(units) == {"1_1", "2_1", "3_1", "6_1", "8_1", "10_1", "11_1", "9_1", "13_2"}
    for e in doc["units"]:
        assert {"name", "bus", "id", "models", "outcome", "reasons"} <= set(e)
        assert set(e["models"]) == ({"converter", "electrical", "plant"} if e["category"] == "inverter-based"
                                    else {"machine", "exciter", "stabiliser", "governor"})
        assert e["outcome"] in ("pass", "data problem", "not supported", "fail")
        assert isinstance(e["reasons"], list) and all(isinstance(r, str) for r in e["reasons"])
    assert units["1_1"]["models"] == {"machine": "GENROU", "exciter": "ESST3A", "stabiliser": None,
                                      "governor": "TGOV1"}
    assert [units[n]["outcome"] for n in ("1_1", "8_1")] == ["pass", "pass"]
    # the stiff record: found from its modes, integrated with Kvaerno5, said so; no setting changed
    assert units["8_1"]["solver"] == "kvaerno5" and "solver" not in units["1_1"]
    stiff = [n for n in units["8_1"]["notes"] if n.startswith("stiff: fastest mode -")]
    assert len(stiff) == 1 and "Kvaerno5" in stiff[0], units["8_1"]["notes"]
    assert -4000 < float(stiff[0].split()[3]) < -1000
    assert not any(n.startswith("stiff") for n in units["1_1"]["notes"])
    assert units["1_1"]["reasons"] == [] and units["1_1"]["numbers"]["max_dxdt_t0"] < 1e-6
    assert abs(units["1_1"]["numbers"]["p_error_held_pu"]) < 1e-5
    # the unsupported model, named
    assert units["2_1"]["outcome"] == "not supported"
    assert units["2_1"]["models"]["exciter"] == "EXST2"
    assert "EXST2" in units["2_1"]["reasons"][0] and "not simulated" in units["2_1"]["reasons"][0]
    # the inverted limit: the record, the CON and both values
    bad = units["3_1"]
    assert bad["outcome"] == "data problem"
    assert "ESST3A on bus 3 id '1'" in bad["reasons"][0] and "line" in bad["reasons"][0]
    assert "VIMAX" in bad["reasons"][0] and "-0.2" in bad["reasons"][0] and "VIMIN" in bad["reasons"][0]
    # the initial state outside a limit: the signal, its value, the CON and its value
    low = units["6_1"]
    assert low["outcome"] == "data problem"
    assert low["reasons"][0].startswith("TGOV1 on bus 6 id '1'")
    assert "valve0 = TM0 = 0.3 above VMAX = 0.25" in low["reasons"][0]
    assert low["limits"][0]["con"] == "VMAX" and low["limits"][0]["bound"] == 0.25
    assert any(r.startswith("hence: not steady at t = 0") for r in low["reasons"])
    s = doc["summary"]
    assert (s["units"], s["pass"], s["data problem"], s["not supported"], s["fail"]) == (9, 3, 3, 3, 0)
    assert s["not_supported_models"] == {"EXST2": 1, "GENSAX": 1, "WT4G1": 1}
    assert s["data_problems"]["TGOV1 VMAX (valve0 above)"] == 1
    assert s["compiled_programs"] == 3  # the simulated machines share one structure; + Kvaerno5; the plant
    page = (out / "check.html").read_text()
    assert "sortable" in page and "EXST2" in page and "data problem" in page


@pytest.mark.slow
def test_an_inverter_based_plant_is_checked(checked):
    """Bus 9's REGCA1 + REECA1 (QFLAG = 0) + REPCA1 (Fflag = 1, droop Ddn = 20): steady at rest, settles after
    the 2 % voltage step (Q answers) and the 0.1 Hz step (P falls by the droop); bus 13's WT4G1 is
    a unit, not supported, named."""
    _, out = checked
    doc = json.loads((out / "check.json").read_text())
    units = {e["name"]: e for e in doc["units"]}
    plant = units["9_1"]
    assert plant["category"] == "inverter-based" and plant["outcome"] == "pass", plant["reasons"]
    assert plant["models"] == {"converter": "REGCA1", "electrical": "REECA1", "plant": "REPCA1"}
    n = plant["numbers"]
    assert n["max_dxdt_t0"] < 1e-6 and abs(n["p_error_held_pu"]) < 1e-5 and abs(n["q_error_held_pu"]) < 1e-5
    assert abs(n["vstep_q_change_pu"]) > 1e-3          # the voltage step moves Q
    assert n["fstep_p_change_pu"] < -1e-3              # over-frequency: P down by the droop
    assert any("taken at the terminal" in note for note in plant["notes"])
    wind = units["13_2"]
    assert wind["outcome"] == "not supported" and wind["not_simulated"] == ["WT4G1"]
    assert "WT4G1" in wind["reasons"][0] and "not simulated" in wind["reasons"][0]


def test_every_record_accounted_for(checked):
    """Each generator record of the .raw in one category, the sums equal to the .raw's count;
    the unknown machine model a unit, not supported, naming it; the orphaned records listed."""
    _, out = checked
    doc = json.loads((out / "check.json").read_text())
    a = doc["summary"]["accounting"]
    assert a["generator_records"] == 5 + len(EXTRA_GENERATORS) == 14
    assert a["checked"] == 9 and a["checked_by_category"] == {
        "synchronous": 5, "inverter-based": 2, "machine model unknown": 1, "no machine record": 1}
    assert (a["out of service"], a["no dynamic records"], a["not a generator"],
            a["duplicate"]) == (1, 2, 1, 1)
    assert a["checked"] + sum(a[k] for k in ("out of service", "no dynamic records",
                                             "not a generator", "duplicate")) == 14
    units = {e["name"]: e for e in doc["units"]}
    unknown = units["10_1"]
    assert unknown["outcome"] == "not supported" and unknown["category"] == "machine model unknown"
    assert unknown["not_simulated"] == ["GENSAX"]
    assert "model GENSAX is unknown to jaxdse" in unknown["reasons"][0]
    alone = units["11_1"]
    assert alone["outcome"] == "data problem" and "no machine record" in alone["reasons"][0]
    assert "TGOV1 (line" in alone["reasons"][0]
    assert doc["summary"]["data_problems"]["no machine record"] == 1
    rows = {(r["bus"], r["id"], r["category"]) for r in doc["not_checked"]}
    assert rows == {(3, "2", "out of service"), (4, "1", "no dynamic records"),
                    (12, "1", "no dynamic records"), (12, "1", "duplicate"),
                    (5, "1", "not a generator")}
    assert all(r["why"] and r["line"] > 0 for r in doc["not_checked"])
    recs = {(r["model"], r["bus"], r["id"]): r for r in doc["dyr_records_not_used"]}
    assert set(recs) == {("GENROU", 99, "1"), ("GENROU", 13, "7"), ("USRBUS", 14, "PLNTBU1")}
    assert recs[("GENROU", 99, "1")]["category"] == "orphaned" and recs[("GENROU", 99, "1")]["line"] > 0
    assert recs[("USRBUS", 14, "PLNTBU1")]["category"] == "bus level"
    assert (a["dyr_records_orphaned"], a["dyr_records_bus_level"]) == (2, 1)
    page = (out / "check.html").read_text()
    assert "Every generator record of case.raw: <b>14</b>" in page and "CSVGN1" in page
    assert "bus 99 is not in case.raw" in page


def test_out_of_service_units_checked_when_asked(tmp_path):
    """``--out-of-service``: the out-of-service unit with a machine record becomes a unit; the
    accounting still adds up (no simulation: the inventory alone)."""
    from jaxdse._dyr.inventory import inventory

    case = load_case(_case(tmp_path, lambda t: t + EXTRA_RECORDS, raw_edit=_more))
    inv = inventory(case.raw, case.dyr)
    keys = [(a.generator.bus, a.generator.id) for a in inv.units(out_of_service=True)]
    assert (3, "2") in keys and (3, "2") not in [(a.generator.bus, a.generator.id) for a in inv.units()]
    assert len(inv.units(out_of_service=True)) == len(inv.units()) + 1 == 10
    assert sum(inv.counts().values()) == len(case.raw.generators) == 14


def test_console_table(checked):
    from jaxdse._app.check import console_table

    _, out = checked
    text = console_table(json.loads((out / "check.json").read_text()))
    lines = text.splitlines()
    assert "14 generator record(s), 9 unit(s) checked" in lines[0]
    assert any(line.split()[:6] == ["GENROU", "ESST3A", "-", "TGOV1", "4", "2"] for line in lines)
    assert any(line.strip().startswith("2_1") and "not supported" in line for line in lines)
    assert any(line.strip().startswith("6_1") and "VMAX" in line for line in lines)
    assert lines[-1].startswith("3 pass (33.3 %), 3 data problem, 3 not supported, 0 fail, of 9")
    assert lines[1].split()[:2] == ["9", "checked"] and "2 machine model unknown" not in lines[1]
    assert "5 synchronous, 2 inverter-based, 1 machine model unknown, 1 no machine record" in lines[1]
    said = {line.split()[1]: int(line.split()[0]) for line in lines[2:6]}
    assert said == {"out": 1, "in": 2, "not": 1, "second": 1}
    assert any(line.split()[:5] == ["REGCA1", "REECA1", "REPCA1", "1", "1"] for line in lines)
    assert any(line.strip().startswith("13_2") and "WT4G1" in line and "not supported" in line
               for line in lines)
    assert any("in service without dynamic records" in line and line.endswith(": 4 '1', 12 '1'")
               for line in lines)
    assert any("not generators" in line and "5 '1' CSVGN1" in line for line in lines)
    assert any("orphaned" in line for line in lines)
    assert any("GENROU on bus 99 id '1'" in line and "bus 99 is not in case.raw" in line for line in lines)
    assert any("GENROU on bus 13 id '7'" in line and "no generator with ID '7' on bus 13" in line
               for line in lines)


@pytest.mark.parametrize("what", ["missing", "no_case", "unknown", "malformed", "no_machine", "no_file"])
def test_unreadable_input_is_exit_2_with_one_line(tmp_path, capsys, what):
    path = _case(tmp_path)
    if what == "missing":
        path = tmp_path / "nope.toml"
    elif what == "no_case":
        path.write_text('[playback]\nsolver = "tsit5"\n')
    elif what == "unknown":
        path.write_text(path.read_text() + "[speling]\nx = 1\n")
    elif what == "malformed":
        path.write_text("[case\n")
    elif what == "no_machine":
        (tmp_path / "case.dyr").write_text("1 'TGOV1' 1 0.05 0.05 1.05 0.3 1 2.1 0 /\n")
    else:
        (tmp_path / "case.raw").unlink()
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("jaxdse: error:") and "\n" not in err


def test_loader_takes_a_case_alone_or_a_fleet_file(tmp_path):
    case = load_case(_case(tmp_path, toml='[playback]\nsolver = "kvaerno5"\nsubsteps = 2\n'))
    assert case.playback.solver == "kvaerno5" and case.playback.substeps == 2
    assert len(case.raw.generators) == 5 and case.dyr.machines
    fleet = load_case(BENCH.parents[1] / "fleet_ieee14.toml")  # [measurement] etc. not read
    assert fleet.playback.ke_zero == "literal"


def test_help_teaches(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["check", "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    for word in ("CASE.toml", "data problem", "not supported", "check.json", "--out", "Exit status"):
        assert word in text


# --- the limits of the initial state ----------------------------------------------------------

def test_exciter_and_governor_limits_at_the_initial_state():
    """ESST4B with a weak potential source (KP = 1): EFD0 = 1.3 needs VM0 = EFD0/VB above VMMAX;
    IEEEG1 with K1 + K3 + K5 + K7 = 0.5: TM0 = 0.6 needs GV0 = 1.2 above PMAX = 1."""
    inputs = ExciterInputs(*(jnp.asarray(x) for x in (1.0, 1.0, 0.0, 0.6, -0.1, 1.3, 0.0)))
    model = ESST4B(kp=1.0, ki=0.0, kc=0.1, vm_max_pu=1.0)
    state, vref = model.initial_state(1.3, inputs)
    start = Start(efd0=1.3, tm0=0.6, vt=1.0, ifd=1.3, vref=float(vref))
    crossings = exciter_crossings("ESST4B", model, state, start)
    assert [(c.con, c.side) for c in crossings] == [("VMMAX", "above")]
    vb = float(model.vb(inputs))
    assert crossings[0].value == pytest.approx(1.3 / vb) and vb < 1.3
    assert describe(crossings[0]).startswith(f"VM0 = EFD0/VB = {1.3 / vb:.4g} above VMMAX = 1 (VB = ")
    assert exciter_crossings("ESST4B", ESST4B(kp=6.0), ESST4B(kp=6.0).initial_state(1.3, inputs)[0],
                             start) == []
    gov = IEEEG1(k1=0.3, k3=0.2, k5=0.0, k7=0.0, p_max_pu=1.0)
    (c,) = governor_crossings("IEEEG1", gov, start)
    assert (c.con, c.value, c.bound, c.side) == ("PMAX", pytest.approx(1.2), 1.0, "above")
    assert "K1 + K3 + K5 + K7 = 0.5" in describe(c)
    assert exciter_crossings("NOTAMODEL", model, state, start) == []


def test_a_group_past_its_limit_is_marked_and_the_check_goes_on(tmp_path, monkeypatch):
    """A run limit of 0 s: the group's compiled run cannot return in time; its units are `fail`
    with what was waited for, the others keep their outcomes, and the check ends."""
    import jaxdse._app.check as check

    monkeypatch.setattr(check, "WAIT_BASE_S", 0.0)
    monkeypatch.setattr(check, "WAIT_PER_LANE_STEP_S", 0.0)
    case = load_case(_case(tmp_path, _bad, '[playback]\nke_zero = "literal"\n'))
    doc = check.check_case(case, progress=False)
    units = {e["name"]: e for e in doc["units"]}
    assert [units[n]["outcome"] for n in ("2_1", "3_1")] == ["not supported", "data problem"]
    for n in ("1_1", "6_1", "8_1"):
        assert units[n]["outcome"] == "fail"
        assert units[n]["reasons"][0].startswith("timed out after 0 s waiting for group GENROU ESST3A - "
                                                 "TGOV1 (3 unit(s), tsit5)"), units[n]["reasons"]


@pytest.mark.slow
def test_no_lapack_call_in_the_check_programs():
    """The check's vmapped programs hold no LAPACK custom call: with one (``eigvals`` of the
    Jacobian, Kvaerno5's LU) inside, two groups run side by side wedged XLA's CPU runtime (both
    threads in BlockUntilReady, every XLA thread idle): Nordic 44 with a warm compilation cache
    hung in 10 of 11 runs of the old code, and in 0 of 8 of this one. The eigenvalues are taken
    on the host; the implicit solver's Newton steps use a plain-arithmetic LU (``jaxdse._dyr.stiff``)."""
    from jaxdse._app import check as ck
    from jaxdse._io.psse import read_dyr, read_raw

    raw, dyr = read_raw(BENCH / "ieee14.raw"), read_dyr(BENCH / "ieee14.dyr")
    g = next(g for g in raw.generators if g.bus == 1)
    unit = jd.unit_model(dyr, raw, g.bus, g.id).unit
    whole = ck._batch_jit().lower(ck._stack([unit]), ck._stack([ck._lane(raw, g, 0.0)]),
                                  ck._Run(end_s=2.0)).as_text()
    implicit = ck._Run(solver="kvaerno5", end_s=0.2)
    stiff = jax.jit(jax.vmap(lambda y: ck._integrate(lambda t, x, a: -3000.0 * x + jnp.sin(x), y,
                                                     implicit, 4)[0])).lower(jnp.ones((2, 3))).as_text()
    for text in (whole, stiff):
        for call in ("lapack", "getrf", "geev", "gesdd", "trsm"):
            assert call not in text.lower(), call


def test_an_open_or_slow_loop_of_a_plant_is_said_not_failed(tmp_path):
    """The judgement of a plant's steps (host side, on made-up runs): REECA1 QFLAG = 1 with
    VFLAG = 1 leaves its voltage loop open under an imposed voltage: the voltage step is not
    judged, and a note says why; a step still moving at the end whose modes there all decay is a
    note with its time constant; one with a growing mode fails."""
    import numpy as np

    from jaxdse._app import check_ibr
    from jaxdse._app.check import SPEC
    from jaxdse._io.psse import read_dyr, read_raw

    dyr = (BENCH / "ieee14.dyr").read_text()
    extra = EXTRA_RECORDS.split("9 'REPCA1'")[0].split("9 'REGCA1'")[1]
    (tmp_path / "c.dyr").write_text(dyr + "9 'REGCA1'" + extra.replace("'1' 0 0 1 0 0 0", "'1' 0 0 1 1 0 0"))
    (tmp_path / "c.raw").write_text(_more((BENCH / "ieee14.raw").read_text()))
    raw, recs = read_raw(tmp_path / "c.raw"), read_dyr(tmp_path / "c.dyr")
    g = raw.generator(9, "1")
    st = check_ibr.ibr_static(raw, recs, g)
    assert st.model.unit is not None and st.model.unit.electrical.qflag == 1 and st.model.unit.electrical.vflag == 1
    n = int(round(SPEC.end_s * SPEC.frame_hz)) + 1
    p0, q0 = g.pg_mw / g.mbase_mva, g.qg_mvar / g.mbase_mva
    m = st.model.unit.n_states    # one derivative per state, as a run gives them
    flat = {"dy0": np.zeros(m), "p_t0": p0, "q_t0": q0, "p": np.full(n, p0), "q": np.full(n, q0), "ok": True,
            "dy_end": np.zeros(m), "growth_end": -1.0}
    swinging = {**flat, "q": q0 + 0.5 * np.sin(2.0 * np.arange(n) / SPEC.frame_hz), "growth_end": 0.0}
    slow = {**flat, "p": p0 - 0.03 * (1 - np.exp(-np.arange(n) / SPEC.frame_hz / 20.0)), "growth_end": -0.05}
    outcome, reasons, _, notes = check_ibr.judge(st, g, flat, (swinging, slow), SPEC)
    assert outcome == "pass", reasons
    assert notes[0] == check_ibr.OPEN_LOOP_NOTE
    assert "still settling" in notes[1] and "time constant of 20 s" in notes[1]
    outcome, reasons, _, _ = check_ibr.judge(st, g, flat, (swinging, {**slow, "growth_end": 0.3}), SPEC)
    assert outcome == "fail" and "frequency step: not settled" in reasons[0] and "grows at 0.3" in reasons[0]
