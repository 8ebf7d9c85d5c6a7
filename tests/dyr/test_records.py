"""Tests of ``unit_model`` (src/jaxdse/_dyr/records.py): a unit's .dyr model from its records.

A small .raw/.dyr pair is written in the layout of experiments/andes_bench/data/ieee14/ (PSS/E
revision 33, BASFRQ 50 Hz here) with one generator per case: a full GENROU + ESST3A + TGOV1
unit, an exciter model jaxdse does not simulate, an invalid GENROU, a unit without exciter, a
DC exciter with KE = 0 (and a stabiliser and IEEEG1), and an exciter without machine record.
"""

import math

import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._dyr.records import unit_model
from jaxdse._dyr.unit import UnitInputs
from jaxdse._models.exciters import ESST3A, IEEEX1, saturation_product
from jaxdse._models.governors import IEEEG1, TGOV1
from jaxdse._models.machines import GENROU
from jaxdse._models.stabilisers import IEEEST

RAW = """\
0, 100.00, 33, 0, 1, 50.00     / PSS(R)E 33 RAW, jaxdse tests/dyr/test_records.py
tiny case for unit_model
six generators on six buses
1, 'BUS1', 20, 3, 1, 1, 1, 1.03, 0.0, 1.1, 0.9, 1.1, 0.9
2, 'BUS2', 20, 2, 1, 1, 1, 1.02, -2.0, 1.1, 0.9, 1.1, 0.9
3, 'BUS3', 20, 2, 1, 1, 1, 1.01, -3.0, 1.1, 0.9, 1.1, 0.9
4, 'BUS4', 20, 2, 1, 1, 1, 1.00, -4.0, 1.1, 0.9, 1.1, 0.9
5, 'BUS5', 20, 2, 1, 1, 1, 1.02, -5.0, 1.1, 0.9, 1.1, 0.9
6, 'BUS6', 20, 2, 1, 1, 1, 1.02, -6.0, 1.1, 0.9, 1.1, 0.9
0 / End of Bus data, Begin Load data
0 / End of Load data, Begin Fixed shunt data
0 / End of Fixed shunt data, Begin Generator data
1, '1', 70, 20, 100, -50, 1.03, 0, 100, 0.003, 0.23, 0, 0, 1, 1, 100, 200, 50, 1, 1
2, '1', 40, 10, 50, -40, 1.02, 0, 100, 0, 0.28, 0, 0, 1, 1, 100, 50, 10, 1, 1
3, '1', 40, 10, 50, -10, 1.01, 0, 100, 0, 0.34, 0, 0, 1, 1, 100, 50, 10, 1, 1
4, '1', 30, 15, 40, -6, 1.00, 0, 50, 0, 0.28, 0, 0, 1, 1, 100, 50, 10, 1, 1
5, '1', 60, 25, 90, -6, 1.02, 0, 100, 0.002, 0.23, 0, 0, 1, 1, 100, 90, 10, 1, 1
6, '1', 35, 7, 10, -6, 1.02, 0, 100, 0, 0.34, 0, 0, 1, 1, 100, 50, 10, 1, 1
0 / End of Generator data, Begin Branch data
0 / End of Branch data, Begin Transformer data
0 / End of Transformer data
Q
"""

GENROU_1 = """1 'GENROU' 1 6.5 0.06 0.2 0.05 4 0
    1.8 1.75 0.6 0.8 0.23 0.15
    0.09 0.38 /"""
DYR = f"""\
{GENROU_1}
1 'TGOV1' 1 0.05 0.05 1.05 0.3 1 2.1
    0 /
1 'ESST3A' 1 0.02 0.2 -0.2 8 1 5
    20 0 99 -99 1 3.67
    0.435 5.48 0.01 0.0098 3.86 3.33
    0.4 99 0 /
{GENROU_1.replace("1 'GENROU' 1", "2 'GENROU' 1")}
2 'EXELI' 1 0 400 0.02 0 0 14.5 -14.5 0.8 0.2 1 0.03 1 0.38 0.03 1 4.18 0.1 3.14 0.03 /
2 'TGOV1' 1 0.05 0.1 1.2 0 1 2.1
    0 /
3 'GENROU' 1 6.5 0.06 0.2 0.05 5 0
    1.8 1.75 0.6 0.8 0.7 0.15
    0.09 0.38 /
3 'TGOV1' 1 0.05 0.1 1.2 0 1 2.1
    0 /
4 'GENROU' 1 6.5 0.06 0.2 0.05 5 0
    1.8 1.75 0.6 0.8 0.28 0.15
    0.09 0.38 /
4 'TGOV1' 1 0.05 0.05 1.05 0.3 1 2.1
    0 /
5 'GENROU' 1 6.5 0.06 0.2 0.05 5 0
    1.8 1.75 0.6 0.8 0.23 0.15
    0.09 0.38 /
5 'IEEEX1' 1 0 50 0.06 0 0 7.3
    -7.3 0 0.5 0.08 1 0 2 0.0016 3 1.73 /
5 'IEEEST' 1 1 0 1.013 0.013 0 0 1.013 0.113 3.0 0.02 0 0 1.65 1.65 3.0 0.1 -0.1 0 0 /
5 'IEEEG1' 1 0 0 20 0 0 0.1 0.1 -0.1 1 0 0.3 0.3 0 7 0.4 0 0.6 0.3 0 0 0 0 /
6 'SEXS' 1 0.1 10 100 0.05 0 5 /
"""


def _line(start):
    """1-based line of the record that starts with ``start``."""
    return 1 + [k for k, t in enumerate(DYR.splitlines()) if t.startswith(start)][0]


LINE_EXELI = _line("2 'EXELI'")
LINE_GENROU_3 = _line("3 'GENROU'")


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    d = tmp_path_factory.mktemp("records")
    (d / "case.raw").write_text(RAW)
    (d / "case.dyr").write_text(DYR)
    return jd.read_dyr(d / "case.dyr"), jd.read_raw(d / "case.raw")


def test_case_reads(case):
    dyr, raw = case
    assert raw.basfrq_hz == 50.0 and len(raw.generators) == 6
    assert [r.model for r in dyr.records if r.line == LINE_EXELI] == ["EXELI"]
    assert [r.model for r in dyr.records if r.line == LINE_GENROU_3] == ["GENROU"]


def steady_check(dyr, raw, bus, unit):
    """initial_state at the .raw generator's operating point gives a zero vector field."""
    g = raw.generator(bus, "1")
    ang = math.radians(raw.buses[bus].va_deg)
    v = g.vs_pu * np.exp(1j * ang)
    i = np.conj((g.pg_mw + 1j * g.qg_mvar) / g.mbase_mva / v)
    u = UnitInputs(*(jnp.asarray(x, float) for x in (v.real, v.imag, 0.0, 0.0)))
    y0, refs = unit.initial_state(u, i.real, i.imag)
    np.testing.assert_allclose(unit.vector_field(y0, u, refs), 0.0, rtol=0, atol=1e-11)
    return unit.split(y0)


def test_full_unit_builds(case):
    dyr, raw = case
    um = unit_model(dyr, raw, 1, "1")
    assert um.missing == [] and um.unit is not None
    assert um.structure == ("GENROU", "ESST3A", "-", "TGOV1")
    assert um.models == {"machine": "GENROU", "governor": "TGOV1", "exciter": "ESST3A"}
    assert um.notes == []
    u = um.unit
    assert isinstance(u.machine, GENROU) and isinstance(u.exciter, ESST3A)
    assert isinstance(u.governor, TGOV1) and u.stabiliser is None
    assert float(u.machine.ra_pu) == 0.003                        # the .raw ZSORCE R
    assert float(u.machine.x2_pu) == 0.23 and float(u.machine.h_s) == 4.0
    np.testing.assert_allclose(u.machine.omega_s_rad_s, 2 * np.pi * 50.0)    # BASFRQ
    np.testing.assert_allclose(u.exciter.theta_p_rad, math.radians(3.33))   # degrees in .dyr
    assert float(u.governor.t3_s) == 2.1
    steady_check(dyr, raw, 1, u)


def test_unsupported_exciter_model_leaves_the_unit_out(case):
    dyr, raw = case
    um = unit_model(dyr, raw, 2, "1")
    assert um.unit is None
    assert um.models["exciter"] == "EXELI"
    assert len(um.missing) == 1
    line = um.missing[0]
    assert "EXELI" in line and f"line {LINE_EXELI}" in line and "not simulated" in line


def test_odd_genrou_is_used_as_given_and_an_unevaluable_one_refused(case, tmp_path):
    """Bus 3's X''d = 0.7 lies above X'd = 0.6: odd, but the GENROU equations can be evaluated
    (PSS/E warns and simulates it), so the unit plays back as given and starts steady. With
    X'd = Xl the equations divide by zero: refused, naming the record."""
    dyr, raw = case
    um = unit_model(dyr, raw, 3, "1")
    assert um.unit is not None and um.missing == []
    steady_check(dyr, raw, 3, um.unit)
    (tmp_path / "bad.dyr").write_text(DYR.replace("1.8 1.75 0.6 0.8 0.7 0.15", "1.8 1.75 0.15 0.8 0.1 0.15"))
    um = unit_model(jd.read_dyr(tmp_path / "bad.dyr"), raw, 3, "1")
    assert um.unit is None and len(um.missing) == 1
    line = um.missing[0]
    assert line.startswith(f"GENROU on bus 3 id '1' (bad.dyr line {LINE_GENROU_3})")
    assert "X'd" in line and "Xl" in line


def test_unit_without_exciter_record_builds_with_a_note(case):
    dyr, raw = case
    um = unit_model(dyr, raw, 4, "1")
    assert um.unit is not None and um.missing == []
    assert um.structure == ("GENROU", "-", "-", "TGOV1")
    assert um.unit.exciter is None
    assert any(n.startswith("no exciter record") for n in um.notes), um.notes
    assert not any("governor" in n for n in um.notes)
    steady_check(dyr, raw, 4, um.unit)


def test_exciter_without_machine_record(case):
    dyr, raw = case
    um = unit_model(dyr, raw, 6, "1")
    assert um.unit is None
    assert any("no machine record" in m for m in um.missing), um.missing


def test_ke_zero_reading_changes_the_dc_exciter(case):
    dyr, raw = case
    psse = unit_model(dyr, raw, 5, "1")
    literal = unit_model(dyr, raw, 5, "1", ke_zero="literal")
    for um in (psse, literal):
        assert um.missing == []
        assert um.structure == ("GENROU", "IEEEX1", "IEEEST", "IEEEG1")
        assert isinstance(um.unit.exciter, IEEEX1) and isinstance(um.unit.stabiliser, IEEEST)
        assert isinstance(um.unit.governor, IEEEG1)
    assert psse.unit.exciter.ke_zero == "psse" and literal.unit.exciter.ke_zero == "literal"
    assert float(psse.unit.exciter.ke) == 0.0 == float(literal.unit.exciter.ke)
    _, y_e_psse, _, _ = steady_check(dyr, raw, 5, psse.unit)
    y_m, y_e_lit, _, _ = steady_check(dyr, raw, 5, literal.unit)
    assert float(y_e_lit[5]) == 0.0                                 # KE = 0 as it stands
    efd0 = float(y_e_psse[3])
    ex = psse.unit.exciter
    vx = float(saturation_product(efd0, ex.e1_pu, ex.se1, ex.e2_pu, ex.se2))
    # PSS/E: KE such that VR = VRMAX / 10 in the initial steady state
    np.testing.assert_allclose(y_e_psse[5], 7.3 / (10 * efd0) - vx / efd0, rtol=1e-12)
    np.testing.assert_allclose(y_e_psse[2], 0.73, rtol=1e-12)
    assert abs(float(y_e_psse[5])) > 0.1
    np.testing.assert_allclose(y_e_lit[3], efd0, rtol=1e-14)        # same machine steady state
