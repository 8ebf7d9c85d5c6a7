"""Plausibility against the plant's own data (issue 32, item 6): the measured active power against
the plant's stated maximum ([aux] p_sg_max_mw, the governor's maximum, a fleet unit's .raw PT),
and machine data against typical ranges (IEEE Std 1110, Kundur Table 4.2): a value ten times
the range (a reactance in percent) is refused naming the key, one merely outside is flagged."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

import jaxdse as jd
from jaxdse._app.fleet_file import load_fleet
from jaxdse._io.config import governor_max_pu, parse_config
from jaxdse._io.measurement import P_MAX_RUN_S, P_MAX_TOLERANCE
from jaxdse._io.schema import IMPLAUSIBLE_FACTOR, TYPICAL_MACHINE, machine_value_findings

RATE = 10.0                                       # frames/s
MACHINE = jd.Machine()                            # 1100 MVA
V_KV = 400.0
I_RATED_A = float(MACHINE.s_rated_mva) * 1e6 / (np.sqrt(3) * V_KV * 1e3)
COLUMNS = {"time": "t", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM", "i_ang": "IA"}
SPEC = jd.MeasurementSpec(file=(), columns=COLUMNS, v_base_kv=V_KV, s_base_mva=100.0, min_segment_s=20.0,
                          p_max_mw=1000.0, p_max_source="[aux] p_sg_max_mw")
BENCH = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench"


def table(s_pu, duration_s=300.0, seed=0) -> jd.Table:
    """A recording at 1 pu voltage whose complex power [pu of the 1100 MVA rating] is ``s_pu(t)``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration_s, 1.0 / RATE)
    s = np.broadcast_to(s_pu(t), t.shape) * (1 + 1e-3 * rng.standard_normal(t.size))
    va = 0.01 * np.cumsum(rng.standard_normal(t.size)) / RATE
    vm = V_KV * (1 + 1e-3 * rng.standard_normal(t.size))
    i = np.conj(s) * I_RATED_A
    return jd.Table(source="pmu.csv", first_row=2,
                    columns={"t": t, "VM": vm, "VA": va, "IM": np.abs(i), "IA": va + np.degrees(np.angle(i))})


def refused(tab, spec=SPEC) -> str:
    with pytest.raises(jd.InputError) as err:
        jd.condition(tab, spec, MACHINE)
    msg = str(err.value)
    assert msg.startswith("pmu.csv, column 'IM', row ") and "\n" not in msg
    return msg


# --- P against the plant's stated maximum ------------------------------------------------------

def test_peak_instead_of_rms_at_part_load_is_refused_against_the_stated_maximum():
    """60 % of the rating x1.414 = 0.85 pu: under the apparent-power and the capability checks,
    but 933 MW from a plant stated to deliver at most 800 MW: refused, with the numbers and the
    likely cause (/1.414 it would fit)."""
    s = np.sqrt(2) * (0.6 + 0.1j)
    jd.condition(table(lambda t: s), dataclasses.replace(SPEC, p_max_mw=None), MACHINE)
    spec = dataclasses.replace(SPEC, p_max_mw=800.0)
    msg = refused(table(lambda t: s), spec)
    assert "row 2-3001" in msg and "median active power is 933" in msg and "800 MW ([aux] p_sg_max_mw)" in msg
    assert "peak instead of RMS" in msg and "/ 1.414 = 660" in msg and "17 % above" in msg


def test_within_the_tolerance_passes_and_a_large_excess_names_a_ct_ratio():
    jd.condition(table(lambda t: (1000 * (1 + 0.8 * P_MAX_TOLERANCE) / 1100) + 0.1j), SPEC, MACHINE)
    msg = refused(table(lambda t: 1.05 + 0.1j), dataclasses.replace(SPEC, p_max_mw=500.0))
    assert "a CT ratio" in msg and "peak instead" not in msg


def test_a_sustained_run_above_the_maximum_is_refused_a_swing_passes():
    """The median under the maximum, but 1.08 pu (1188 MW, 1.13 x) for 60 s out of 300: refused,
    naming the run's rows; 20 s of it (a swing, an inertial response) passes."""
    def above(seconds):
        return lambda t: np.where((t >= 100.0) & (t < 100.0 + seconds), 1.08, 0.6) + 0.1j
    spec = dataclasses.replace(SPEC, p_max_mw=1050.0)
    jd.condition(table(above(P_MAX_RUN_S - 10)), spec, MACHINE)
    msg = refused(table(above(60.0)), spec)
    assert "active power stays at 1188 MW (median) for 59.9 s" in msg and "13 % above" in msg
    start, stop = (int(x) for x in msg.split("row ")[1].split(":")[0].split("-"))
    assert abs(start - (2 + 100 * RATE)) <= 1 and abs(stop - (2 + 160 * RATE)) <= 2


def test_governor_maximum_as_each_model_defines_it():
    """The steady state at full reference: TGOV1 VMAX, IEEEG1 PMAX, GAST min(VMAX, AT), HYGOV
    At (GMAX - qNL), GGOV1 Kturb (VMAX - Wfnl) within its load limit; a plant with a unit
    without a governor (constant torque) has none."""
    assert governor_max_pu(jd.TGOV1(v_max_pu=0.95)) == pytest.approx(0.95)
    assert governor_max_pu(jd.IEEEG1(p_max_pu=0.9)) == pytest.approx(0.9)
    assert governor_max_pu(jd.GAST(v_max_pu=1.1, at_pu=0.9)) == pytest.approx(0.9)
    assert governor_max_pu(jd.HYGOV(g_max_pu=1.0, at_pu=1.2, q_nl_pu=0.08)) == pytest.approx(1.104)
    assert governor_max_pu(jd.GGOV1()) == pytest.approx(1.0)
    both = jd.WeightedGovernor((jd.TGOV1(v_max_pu=1.0), jd.GAST(v_max_pu=1.2, at_pu=1.2)), [0.5, 0.5])
    assert governor_max_pu(both) == pytest.approx(1.1)
    assert governor_max_pu(jd.WeightedGovernor((jd.TGOV1(),), [0.5])) is None


def config(**sections) -> dict:
    return {"plant_defaults": "paper", "measurement": {"file": "pmu.csv", "columns": dict(COLUMNS),
                                                      "v_base_kv": V_KV}, **sections}


def test_a_run_config_states_its_maximum():
    """[aux] p_sg_max_mw (stated, or the paper's plant's where [aux] is needed), the governor's
    maximum on the rating: the smaller goes with the measurement, naming its source."""
    g = parse_config(config(), Path("c.toml")).generators[0]
    assert g.measurement.p_max_mw == 1000.0 and "p_sg_max_mw, the paper's plant" in g.measurement.p_max_source
    g = parse_config(config(aux={"p_sg_max_mw": 900.0}), Path("c.toml")).generators[0]
    assert (g.measurement.p_max_mw, g.measurement.p_max_source) == (900.0, "[aux] p_sg_max_mw")
    g = parse_config(config(governor={"model": "TGOV1", "v_max_pu": 0.8}), Path("c.toml")).generators[0]
    assert g.measurement.p_max_mw == pytest.approx(880.0)
    assert g.measurement.p_max_source == \
        "the TGOV1 governor's maximum, 0.8 pu of machine.s_rated_mva = 1100 MVA"
    terminal = config(governor={"model": "IEEEG1"})
    terminal["measurement"] |= {"location": "terminal", "v_base_kv": 21.0}
    g = parse_config(terminal, Path("c.toml")).generators[0]   # no [aux] at the terminal
    assert g.measurement.p_max_mw == pytest.approx(1100.0) and "IEEEG1" in g.measurement.p_max_source


def test_the_maximum_is_no_measurement_key(tmp_path):
    data = config()
    data["measurement"]["p_max_mw"] = 5.0
    with pytest.raises(jd.InputError, match="key 'measurement.p_max_mw': unknown key"):
        parse_config(data, tmp_path / "c.toml")


# --- machine data against typical ranges --------------------------------------------------------

def test_typical_ranges_table():
    for name, (lo, hi, unit, key, source) in TYPICAL_MACHINE.items():
        assert 0 <= lo < hi and unit in ("pu", "s") and source
        assert key is None or key in {f for f in jd.Machine.__dataclass_fields__}
    assert TYPICAL_MACHINE["Xd"][:2] == (0.6, 2.5) and TYPICAL_MACHINE["X'd"][:2] == (0.1, 0.5)


@pytest.mark.parametrize("key, value, words", [
    ("xd_pu", 180.0, "key 'machine.xd_pu': Xd = 180 pu is more than 10 x the typical upper end 2.5 pu: "
                     "looks like percent: 180 -> 1.8 pu?"),
    ("xd1_pu", 30.0, "key 'machine.xd1_pu': X'd = 30 pu .* looks like percent: 30 -> 0.3 pu\\?"),
    ("rs_pu", 0.3, "key 'machine.rs_pu': Ra = 0.3 pu .* looks like percent: 0.3 -> 0.003 pu\\?"),
    ("td01_s", 8000.0, "key 'machine.td01_s': T'do = 8000 s .* looks like milliseconds: 8000 -> 8 s\\?"),
])
def test_percent_refused_at_config_load_naming_the_key(tmp_path, key, value, words):
    with pytest.raises(jd.InputError, match=words):
        parse_config(config(machine={key: value}), tmp_path / "c.toml")


def test_outside_the_typical_range_is_flagged_not_refused():
    g = parse_config(config(machine={"xd_pu": 3.0, "td01_s": 20.0, "xq_pu": 1.7}),
                     Path("c.toml")).generators[0]
    assert len(g.notes) == 2
    assert g.notes[0].startswith("machine.xd_pu: Xd = 3 pu is outside the typical 0.6-2.5 pu (IEEE Std 1110")
    assert g.notes[1].startswith("machine.td01_s: T'do = 20 s is outside the typical 1.5-15 s")
    assert all(n.endswith("used as given") for n in g.notes)
    assert parse_config(config(), Path("c.toml")).generators[0].notes == ()


def test_findings_by_psse_name():
    refused_, flagged = machine_value_findings({"Xd": 1.8, "X''d": 0.05, "Xl": 0.4, "T'qo": 0.5, "H": 1e3,
                                                "X'q": IMPLAUSIBLE_FACTOR * 1.0 + 1, "Ra": float("nan")})
    assert flagged == ["X''d = 0.05 pu is outside the typical 0.1-0.45 pu (IEEE Std 1110; Kundur 1994, "
                       "Table 4.2): used as given", flagged[1]] and flagged[1].startswith("Xl = 0.4 pu")
    assert len(refused_) == 1 and refused_[0].startswith("X'q = 11 pu is more than 10 x")


# --- a fleet: the unit's own PT and records ---------------------------------------------------

def ieee14(tmp_path, dyr=None, raw=None) -> Path:
    """The bench ieee14 fleet in ``tmp_path`` with its .dyr/.raw after ``dyr``/``raw``."""
    data = BENCH / "data" / "ieee14"
    for name, edit in (("ieee14.dyr", dyr), ("ieee14.raw", raw)):
        text = (data / name).read_text()
        (tmp_path / name).write_text(edit(text) if edit else text)
    text = (BENCH / "fleet_ieee14.toml").read_text().replace('"data/ieee14/ieee14.', '"ieee14.')
    (tmp_path / "fleet.toml").write_text(text.replace('"data/', f'"{BENCH}/data/'))
    return tmp_path / "fleet.toml"


def read(plant):
    spec = plant.run.measurement
    return jd.condition(jd.load_table(spec.file, spec.format, csv_options=spec.csv_options,
                                      time_column=spec.columns.get("time")), spec, plant.run.plant.machine)


def test_fleet_unit_in_percent_is_skipped_the_others_run(tmp_path):
    genrou_b3 = "3 'GENROU' 1 6.5 0.06 0.2 0.05 5 0\n    1.8 1.75"
    cfg = ieee14(tmp_path, dyr=lambda s: s.replace(genrou_b3, genrou_b3.replace("1.8 1.75", "180 1.75")))
    fl = load_fleet(cfg)
    (bad,) = fl.skipped
    assert bad["name"] == "B3_G1"
    assert "GENROU on bus 3 id '1' (ieee14.dyr line 17): Xd = 180 pu" in bad["reason"]
    assert "looks like percent: 180 -> 1.8 pu?" in bad["reason"]
    assert [p.name for p in fl.plants] == ["B1_G1", "B2_G1", "B6_G1", "B8_G1"]
    b1 = fl.plants[0]   # X'd = 0.6 in every ieee14 record: flagged in the plant's notes
    assert any("X'd = 0.6 pu is outside the typical 0.1-0.5 pu" in n for n in b1.run.notes)


def test_fleet_recording_above_the_units_pt_is_refused(tmp_path):
    """B1's recording carries 81.7 MW; its .raw PT says 60: refused (run_fleet lists the plant
    under "skipped" with this line), the other plants read."""
    gen1 = "1, '1', 81.42721424, -21.6171034, 100, -50, 1.03, 0, 100, 0, 0.23, 0, 0, 1, 1, 100, 200,"
    fl = load_fleet(ieee14(tmp_path, raw=lambda s: s.replace(gen1, gen1.replace("100, 200,", "100, 60,"))))
    b1 = fl.plants[0]
    assert b1.run.measurement.p_max_mw == 60.0
    assert b1.run.measurement.p_max_source == "the PT of its unit in ieee14.raw"
    with pytest.raises(jd.InputError, match=r"column 'B1_G1/IM', row 2-\d+: median active power is 81.72 MW "
                       r".*36 % above the plant's stated maximum of 60 MW \(the PT of its unit in "
                       r"ieee14.raw\)"):
        read(b1)
    for p in fl.plants[1:]:
        assert p.run.measurement.p_max_mw > 0
        read(p)
