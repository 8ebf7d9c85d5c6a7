"""Tests of the PSS/E .dyr/.raw readers and the converters to jaxdse objects."""
# ruff: noqa: E501  (the hand-made .raw samples keep PSS/E's long records)

import cmath
import dataclasses
import math
import re
import textwrap
from pathlib import Path

import jax.numpy as jnp
import pytest

import jaxdse as jd
from jaxdse import GAST, GGOV1, HYGOV, IEEEG1
from jaxdse._core.mapping import transformer_to_hv, transformer_to_lv  # the maps the kwargs feed
from jaxdse._io import psse

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "wecc240"
DYR = DATA / "240busWECC_2018_PSS.dyr"
RAW = DATA / "240busWECC_2018_PSS32_fixed_shunts.raw"
needs_data = pytest.mark.skipif(not DYR.exists() or not RAW.exists(), reason="shared WECC data absent")


@pytest.fixture(scope="module")
def wecc_dyr():
    return psse.read_dyr(DYR)


@pytest.fixture(scope="module")
def wecc_raw():
    return psse.read_raw(RAW)


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text).lstrip("\n"))
    return p


# --- the shipped WECC 240 .dyr ----------------------------------------------------------------

@needs_data
def test_wecc_dyr_counts(wecc_dyr):
    counts = wecc_dyr.counts
    assert dict(counts) == {"GENROU": 109, "SEXS": 109, "GAST": 47, "TGOV1": 37, "HYGOV": 25,
                            "IEEEST": 10, "REECB1": 37, "REGCA1": 37, "REPCA1": 37}
    assert wecc_dyr.unknown_models == ["IEEEST", "REECB1", "REGCA1", "REPCA1", "SEXS"]
    assert wecc_dyr.empty_records == 24          # the lone '/' lines after each IEEEST
    assert len(wecc_dyr.machines) == 109 and len(wecc_dyr.governors) == 109


@needs_data
def test_wecc_dyr_records_field_by_field(wecc_dyr):
    genrou = wecc_dyr.machine(1032, "C")
    assert (genrou.model, genrou.line) == ("GENROU", 1)
    assert list(genrou.params.values()) == [6.0, 0.5, 1.0, 0.05, 2.41, 0.0, 1.4, 1.35, 0.3, 0.6,
                                            0.2, 0.1, 0.03, 0.4]
    assert genrou["X'd"] == 0.3 and genrou["H"] == 2.41
    tgov = wecc_dyr.governor(1032, "C")
    assert (tgov.model, tgov.line) == ("TGOV1", 6)
    assert tgov.params == {"R": 0.08, "T1": 2.0, "VMAX": 1.0, "VMIN": 0.0, "T2": 3.0, "T3": 15.0, "Dt": 0.4}
    gast = wecc_dyr.governor(1032, "G")
    assert (gast.model, gast.line) == ("GAST", 13)
    assert list(gast.constants) == [0.08, 0.3, 0.3, 3.0, 1.0, 2.0, 1.0, 0.0, 0.0]
    hygov = wecc_dyr.governor(1232, "H")
    assert (hygov.model, hygov.line) == ("HYGOV", 55)
    assert hygov.params == {"R": 0.05, "r": 0.075, "Tr": 12.0, "Tf": 0.5, "Tg": 20.5, "VELM": 0.1,
                            "GMAX": 1.0, "GMIN": 0.0, "TW": 15.0, "At": 1.5, "Dturb": 0.0, "qNL": 0.08}
    assert wecc_dyr.machine(8034, "H").line == 781
    assert wecc_dyr.governor(8034, "H").line == 786
    # raw records keep strings (REPCA1's quoted ICON) and comma-separated IEEEST
    repca = wecc_dyr.of_model("REPCA1")[0]
    assert repca.constants[3] == "0" and repca.params == {}
    ieeest = wecc_dyr.of_model("IEEEST")[0]
    assert (ieeest.bus, ieeest.id, ieeest.line) == (1333, "G", 1496)
    assert ieeest.constants[:4] == (1.0, 0.0, 1.013, 0.013) and len(ieeest.constants) == 19  # 2 ICONs + 17 CONs


@needs_data
def test_wecc_dyr_typed_records_match_file_text(wecc_dyr):
    """Every typed record re-read independently from the file text (regex, not the parser)."""
    lines = DYR.read_text(encoding="latin-1").splitlines()
    for rec in wecc_dyr.machines + wecc_dyr.governors:
        text, k = "", rec.line - 1
        while "/" not in text:
            text += " " + lines[k]
            k += 1
        body = text.split("/")[0]
        words = re.findall(r"'[^']*'|[^\s,']+", body)
        assert int(words[0]) == rec.bus and words[1].strip("'") == rec.model
        assert words[2].strip("'").strip() == rec.id
        assert [float(w) for w in words[3:]] == list(rec.params.values())


# --- the shipped WECC 240 .raw ----------------------------------------------------------------

@needs_data
def test_wecc_raw(wecc_raw):
    r = wecc_raw
    assert (r.revision, r.sbase_mva, r.basfrq_hz, r.ic) == (32, 100.0, 60.0, 0)
    assert len(r.buses) == 243 and len(r.loads) == 139 and len(r.generators) == 146
    assert len(r.branches) == 329 and len(r.transformers) == 122 and r.n_three_winding == 0
    g = r.generator(1032, "C")
    assert (g.pg_mw, g.qg_mvar, g.mbase_mva, g.zr_pu, g.zx_pu, g.ireg, g.line) == \
        (712.0, -2.6, 873.0, 0.0, 0.2, 1002, 389)
    g = r.generator(8034, "H")
    assert (g.pg_mw, g.mbase_mva, g.stat, g.line) == (427.0, 544.0, 1, 534)
    b = r.buses[1001]
    assert (b.name, b.base_kv, b.ide, b.vm_pu, b.va_deg, b.line) == ("FOURCORN", 500.0, 1, 1.03399, 5.8113, 4)
    assert r.bus_kv(8034) == 20.0
    ld = r.loads[0]
    # WECC 240 loads are constant current (P) and constant admittance (Q): PL = QL = 0
    assert (ld.bus, ld.id, ld.status, ld.pl_mw, ld.ql_mvar, ld.ip_mw, ld.iq_mvar, ld.yp_mw, ld.yq_mvar) == \
        (1002, "1", 1, 0.0, 0.0, 223.71, 0.0, 0.0, 583.546)
    assert all(x.pl_mw == 0.0 and x.ql_mvar == 0.0 for x in r.loads)
    br = r.branches[0]
    assert (br.i, br.j, br.ckt, br.r_pu, br.x_pu, br.b_pu, br.status) == (1001, 1201, "1", 1.77e-3, 3.169e-2, 3.3446, 1)
    t = r.transformers[0]
    assert (t.i, t.j, t.ckt, t.cw, t.cz, t.cm, t.r12, t.x12, t.sbase12_mva, t.windv1, t.nomv1_kv,
            t.ntp1, t.windv2, t.nomv2_kv, t.line) == (1001, 1002, "1", 1, 1, 1, 1e-7, 1.1e-2, 100.0, 1.0,
                                                     500.0, 989, 1.0, 345.0, 866)
    assert sum(g.stat == 0 for g in r.generators) == 6


@needs_data
def test_wecc_every_synchronous_unit_converts(wecc_dyr, wecc_raw):
    n = 0
    for g in wecc_raw.generators:
        if wecc_dyr.machine(g.bus, g.id) is None:
            continue                                          # renewables (REGCA1): no machine
        kw, tr, gov, gsu = psse.load_unit(wecc_dyr, wecc_raw, g.bus, g.id)
        m = jd.Machine(**kw)
        assert float(m.s_rated_mva) == g.mbase_mva and float(m.v_rated_kv) == 20.0
        assert tr.xq1_pu == 0.6 and tr.xd2_pu == 0.2
        assert isinstance(gov, (jd.TGOV1, GAST, HYGOV))
        jd.Transformer(**gsu)
        n += 1
    assert n == 109
    gsu = wecc_raw.step_up_transformer(8034)
    assert (gsu.i, gsu.j, gsu.ckt) == (8004, 8034, "1")
    assert psse.transformer_sides(gsu, wecc_raw) == (8004, 8034)
    kw = psse.transformer_kwargs(gsu, wecc_raw)
    assert kw["x_hv_pu"] == pytest.approx(2.5e-4) and kw["tap_position"] == 0.0
    assert kw["r_fe_pu"] == psse.BIG_SHUNT_PU and kw["x_m_pu"] == psse.BIG_SHUNT_PU
    assert wecc_raw.step_up_transformer(1001) is not None     # a bus with two 500/345 kV units


# --- hand-made .dyr edge cases ----------------------------------------------------------------

EDGE_DYR = """
@! hand-made sample: comments, blank lines, unquoted names, D exponents
   101 'GENROU' 1   6.0  0.05  0.75 0.05
       4.0  0.0  1.8  1.7  0.3  0.55
       0.25 0.15  0.03 0.4 / comment after the slash, 'quotes' and / slashes

102 GENCLS 'G2' 3.5D0 1.D-2 /   unquoted model name, D exponents
103,'GAST','1', 0.05,0.4,0.1,3.0,0.9,2.0,1.0,-0.05,0.0/
104 TGOV1 A 0.05 0.5 1.0 0.0 2.1 7.0 0.0 / unquoted ID
105 'SEXS' 1 0.1 10 100 0.1 0 3 /
106 'REPCA1' 1 0 0 0 '0 ' 0 0 1 0.02 /
/
107 'IEEEG1' 1 0 0 20 0 0 0.1 0.1 -0.1 1 0 0.3 0.3 0 7 0.4 0 0.6 0.3 0 0 0 0 /
108 'GGOV1' 1 1 1 0.04 1 0.05 -0.05 10 2 0 1 1 0.15 0.5 1.5 0.2 0.1 0 0 3 2 0.67 1 0
  0.1 -0.1 0 0.01 10 0.1 0 0 4 5 99 -99 /
"""


def test_dyr_edge_cases(tmp_path):
    d = psse.read_dyr(write(tmp_path, "edge.dyr", EDGE_DYR))
    assert [r.model for r in d.records] == ["GENROU", "GENCLS", "GAST", "TGOV1", "SEXS", "REPCA1",
                                            "IEEEG1", "GGOV1"]
    assert [r.line for r in d.records] == [2, 6, 7, 8, 9, 10, 12, 13]
    g = d.machine(101, "1")
    assert list(g.params.values()) == [6.0, 0.05, 0.75, 0.05, 4.0, 0.0, 1.8, 1.7, 0.3, 0.55, 0.25, 0.15,
                                       0.03, 0.4]
    assert d.empty_records == 1
    assert d.machine(102, "G2").params == {"H": 3.5, "D": 0.01}
    assert d.governor(103, "1")["VMIN"] == -0.05
    assert d.governor(104, "A").params["T3"] == 7.0
    assert d.of_model("REPCA1")[0].constants[3] == "0"
    assert d.unknown_models == ["REPCA1", "SEXS"]
    ggov = d.governor(108, "1")
    assert ggov["Rselect"] == 1 and ggov["Rdown"] == -99 and len(ggov.params) == 35
    assert isinstance(psse.governor_from_dyr(ggov), GGOV1)
    ieeeg1 = psse.governor_from_dyr(d.governor(107, "1"))
    assert isinstance(ieeeg1, IEEEG1) and float(ieeeg1.k) == 20.0 and float(ieeeg1.t5_s) == 7.0


def test_dyr_duplicate_machine_record_is_reported(tmp_path):
    p = write(tmp_path, "dup.dyr", "1 GENCLS 1 3 0 /\n1 'GENCLS' '1' 4 0 /\n")
    with pytest.raises(jd.InputError, match=r"dup.dyr, row 2: GENCLS bus 1 id '1': a second machine"):
        psse.read_dyr(p).machine(1, "1")


def test_dyr_wrong_constant_count_names_line_and_model(tmp_path):
    p = write(tmp_path, "bad.dyr", """
        1 'GENCLS' 1 3.0 0.0 /
        2 'TGOV1' 1 0.05 0.5 1.0
           0.0 2.1 7.0 /
        """)
    with pytest.raises(jd.InputError) as e:
        psse.read_dyr(p)
    msg = str(e.value)
    assert msg.startswith(f"{p}, row 2: TGOV1 bus 2 id '1' has 6 constants, expected 7")
    assert "\n" not in msg and "R, T1, VMAX, VMIN, T2, T3, Dt" in msg


def test_dyr_non_numeric_constant(tmp_path):
    p = tmp_path / "nan.dyr"
    p.write_text("\n\n5 'GAST' 1 0.05 0.4 0.1 3.0 0.9 2.0\n 1.0 x0.5 0.0 /\n")
    with pytest.raises(jd.InputError, match=r"nan.dyr, row 3: GAST bus 5 id '1': constant 8 \(VMIN\) "
                                            r"is not a number: 'x0.5'"):
        psse.read_dyr(p)
    p = write(tmp_path, "nan2.dyr", "5 'GENCLS' 1 'abc' 0 /\n")
    with pytest.raises(jd.InputError, match=r"row 1: GENCLS bus 5 id '1': constant 1 \(H\)"):
        psse.read_dyr(p)


def test_dyr_missing_terminator_and_bad_bus(tmp_path):
    p = write(tmp_path, "open.dyr", "1 'GENCLS' 1 3.0 0.0 /\n\n2 'GENCLS' 1 3.0\n 0.0\n")
    with pytest.raises(jd.InputError, match=r"open.dyr, row 3: record 2 'GENCLS' \.\.\. has no "
                                            r"terminating '/'"):
        psse.read_dyr(p)
    p = write(tmp_path, "bus.dyr", "ABC 'GENCLS' 1 3.0 0.0 /\n")
    with pytest.raises(jd.InputError, match=r"row 1: record for model GENCLS: the bus number is 'ABC'"):
        psse.read_dyr(p)
    with pytest.raises(jd.InputError, match="does not exist"):
        psse.read_dyr(tmp_path / "none.dyr")


def test_parse_number_fortran():
    assert psse.parse_number("0.5E-01") == 0.05
    assert psse.parse_number("1.D-2") == 0.01
    assert psse.parse_number("-.5d+1") == -5.0
    assert psse.parse_number("7") == 7.0
    for bad in ("nan", "inf", "1,0", "E5", "--1"):
        with pytest.raises(ValueError):
            psse.parse_number(bad)


# --- hand-made .raw: revision 33 and 32 -------------------------------------------------------

RAW33 = """
0,   100.00, 33, 0, 1, 50.00     / PSS(R)E-33.10    SAT, JAN 01 2022  12:00
HAND-MADE REVISION 33 SAMPLE, TITLE 1
TITLE 2 / WITH A SLASH, AND A COMMA
     1,'HV BUS      ', 400.0000,3,   1,   1,   1,1.02000,   0.0000,1.10000,0.90000,1.10000,0.90000
     2,'GEN, BUS    ',  21.0000,2,   1,   1,   1,1.01000,   5.0000,1.10000,0.90000,1.10000,0.90000
     3,'TER BUS     ',  10.5000,1,   1,   1,   1,1.00000,   4.0000,1.10000,0.90000,1.10000,0.90000
0 / END OF BUS DATA, BEGIN LOAD DATA
     1,'1 ',1,   1,   1,   300.000,   100.000,     0.000,     0.000,     0.000,     0.000,   1,1,0
0 / END OF LOAD DATA, BEGIN FIXED SHUNT DATA
0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA
     2,'G1',   800.000,   100.000,   400.000,  -300.000,1.01000,     0,  1000.000, 2.00000E-3, 3.00000E-1, 0.00000E+0, 0.00000E+0,1.00000,1,  100.0,   950.000,     0.000,   1,1.0000,   0,1.0000,   0,1.0000,   0,1.0000,0, 1.0000
0 / END OF GENERATOR DATA, BEGIN BRANCH DATA
     1,     3,'1 ', 1.00000E-3, 1.00000E-2,   0.01000,  100.00,  100.00,  100.00,  0.00000,  0.00000,  0.00000,  0.00000,1,1,   0.00,   1,1.0000
0 / END OF BRANCH DATA, BEGIN TRANSFORMER DATA
     1,     2,     3,'1 ',1,1,1, 0.00000E+0, 0.00000E+0,2,'3W          ',1,   1,1.0000,   0,1.0000,   0,1.0000,   0,1.0000,'YNyn0d1     '
 1.00000E-3, 5.00000E-2,   100.00, 1.00000E-3, 5.00000E-2,   100.00, 1.00000E-3, 5.00000E-2,   100.00,1.00000,   0.0000
1.00000,   0.000,   0.000,   100.00,   100.00,   100.00, 0,      0, 1.10000, 0.90000, 1.10000, 0.90000,  33, 0, 0.00000, 0.00000,  0.000
1.00000,   0.000,   0.000,   100.00,   100.00,   100.00, 0,      0, 1.10000, 0.90000, 1.10000, 0.90000,  33, 0, 0.00000, 0.00000,  0.000
1.00000,   0.000,   0.000,   100.00,   100.00,   100.00, 0,      0, 1.10000, 0.90000, 1.10000, 0.90000,  33, 0, 0.00000, 0.00000,  0.000
     1,     2,     0,'1 ',1,2,1, 1.00000E-3,-4.00000E-3,2,'GSU1        ',1,   1,1.0000,   0,1.0000,   0,1.0000,   0,1.0000,'YNd1        '
 2.00000E-3, 1.50000E-1,  1000.00
1.02500, 400.000,   0.000,  1000.00,  1000.00,  1000.00, 0,      0, 1.10000, 0.90000, 1.10000, 0.90000,  33, 0, 0.00000, 0.00000,  0.000
1.00000,  21.000
0 / END OF TRANSFORMER DATA, BEGIN AREA DATA
   1,     0,     0.000,    10.000,'AREA1       '
0 / END OF AREA DATA, BEGIN TWO-TERMINAL DC DATA
Q
"""


def _rev32(text):
    """The rev-33 sample rewritten in rev-32 layout (no bus limits, INTRPT, VECGRP)."""
    out = []
    for line in textwrap.dedent(text).lstrip("\n").splitlines():
        if line.startswith("0,"):
            line = line.replace(" 33,", " 32,").replace("-33.10", "-32.00")
        elif re.match(r"\s+\d+,'[^']*', +\d+\.\d{4},", line):                 # bus
            line = ",".join(line.split(",")[:9])
        elif re.match(r"\s+1,'1 ',1,", line):                                # load
            line = ",".join(line.split(",")[:13])
        elif line.rstrip().endswith("'") and line.count(",") >= 20:
            line = line[:line.rindex(",")]                                    # transformer VECGRP
        out.append(line)
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("revision", [33, 32])
def test_raw_revisions(tmp_path, revision):
    text = RAW33 if revision == 33 else _rev32(RAW33)
    lines = textwrap.dedent(text).lstrip("\n").splitlines()
    n_bus, n_load = (13, 14) if revision == 33 else (9, 13)
    assert len(lines[3].split(",")) == n_bus and len(lines[7].split(",")) == n_load
    assert ("YNd1" in text) == (revision == 33)
    r = psse.read_raw(write(tmp_path, f"r{revision}.raw", text))
    assert (r.revision, r.sbase_mva, r.basfrq_hz) == (revision, 100.0, 50.0)
    assert r.title[1].startswith("TITLE 2 / WITH A SLASH")
    assert sorted(r.buses) == [1, 2, 3] and r.buses[2].name == "GEN, BUS" and r.buses[2].base_kv == 21.0
    assert r.buses[3].va_deg == 4.0
    assert len(r.loads) == 1 and r.loads[0].pl_mw == 300.0
    g = r.generator(2, "G1")
    assert (g.pg_mw, g.mbase_mva, g.zr_pu, g.zx_pu, g.pt_mw, g.line) == (800.0, 1000.0, 2e-3, 0.3, 950.0, 11)
    assert len(r.branches) == 1 and r.branches[0].b_pu == 0.01
    assert r.n_three_winding == 1 and len(r.transformers) == 1
    t = r.transformers[0]
    assert (t.i, t.j, t.cz, t.mag1, t.mag2, t.x12, t.sbase12_mva, t.windv1, t.nomv2_kv, t.line) == \
        (1, 2, 2, 1e-3, -4e-3, 0.15, 1000.0, 1.025, 21.0, 20)
    assert r.step_up_transformer(2) is t
    kw = psse.transformer_kwargs(t, r)
    assert kw["x_hv_pu"] == pytest.approx(0.5 * 0.15 * 100 / 1000)
    assert kw["tap_position"] == pytest.approx(0.025 / (0.2 / 32))


def test_raw_unsupported_revision_and_errors(tmp_path):
    for rev in ("37", "31"):
        p = write(tmp_path, f"r{rev}.raw", RAW33.replace(", 33, 0, 1", f", {rev}, 0, 1", 1))
        with pytest.raises(jd.InputError, match=rf"r{rev}.raw, row 1: case identification gives revision "
                                                rf"{rev}; only PSS/E raw revisions 32, 33, 34, 35 and 36 "
                                                "are supported$"):
            psse.read_raw(p)
    # revision only in the comment; BASFRQ absent -> 60 Hz
    p = write(tmp_path, "norev.raw", RAW33.replace("0,   100.00, 33, 0, 1, 50.00     / PSS(R)E-33.10",
                                                   "0,   100.00  / PSS(R)E-33.10"))
    r = psse.read_raw(p)
    assert (r.revision, r.basfrq_hz) == (33, 60.0)
    p = write(tmp_path, "norev2.raw", RAW33.replace("0,   100.00, 33, 0, 1, 50.00     / PSS(R)E-33.10",
                                                    "0,   100.00  / UNKNOWN PROGRAM"))
    with pytest.raises(jd.InputError, match="gives no revision number"):
        psse.read_raw(p)
    p = write(tmp_path, "badnum.raw", RAW33.replace("  1000.000, 2.00000E-3", "  1OOO.000, 2.00000E-3"))
    with pytest.raises(jd.InputError, match=r"badnum.raw, row 11: generator record: field 9 \(MBASE\) is "
                                            r"not a number: '1OOO.000'"):
        psse.read_raw(p)
    cut = "\n".join(textwrap.dedent(RAW33).lstrip("\n").splitlines()[:11]) + "\n"
    with pytest.raises(jd.InputError, match="the generator data section is not closed"):
        psse.read_raw(write(tmp_path, "cut.raw", cut))
    short = RAW33.replace("1.00000,  21.000\n0 / END OF TRANSFORMER", "0 / END OF TRANSFORMER")
    with pytest.raises(jd.InputError, match=r"row 20: transformer 1-2 needs 4 lines"):
        psse.read_raw(write(tmp_path, "short.raw", short))


# --- converters -------------------------------------------------------------------------------

def _case(tmp_path, xfmr_lines, kv_i=230.0, kv_j=20.0, sbase=100.0):
    text = f"""
    0, {sbase}, 33, 0, 1, 60.0 / test
    T1
    T2
    1,'I', {kv_i},1,1,1,1,1.0,0.0
    2,'J', {kv_j},2,1,1,1,1.0,0.0
    0 / END OF BUS DATA
    0 / END OF LOAD DATA
    0 / END OF FIXED SHUNT DATA
    2,'1', 100.0, 0.0, 99, -99, 1.0, 0, 200.0, 0.003, 0.25, 0, 0, 1, 1
    0 / END OF GENERATOR DATA
    0 / END OF BRANCH DATA
    {xfmr_lines}
    0 / END OF TRANSFORMER DATA
    Q
    """
    text = "\n".join(s.strip() for s in textwrap.dedent(text).strip().splitlines()) + "\n"
    return psse.read_raw(write(tmp_path, "c.raw", text))


def _xfmr(cw=1, cz=1, cm=1, mag1=0.0, mag2=0.0, r=0.002, x=0.1, s12=100.0, w1=1.025, nom1=0.0, ang=0.0,
          rma=1.1, rmi=0.9, ntp=33, w2=1.0, nom2=0.0, i=1, j=2, cod=1):
    return (f"{i},{j},0,'1 ',{cw},{cz},{cm},{mag1},{mag2},2,'X',1\n{r},{x},{s12}\n"
            f"{w1},{nom1},{ang},100,100,100,{cod},0,{rma},{rmi},1.1,0.9,{ntp},0,0,0,0\n{w2},{nom2}")


def _psse_two_port(t):
    """PSS/E circuit straight from the data (CW=1, CZ=1, CM=1), bus I -> bus J.

    Bus I (V_I, I_I into the transformer), shunt Ym at I, ideal t1 e^{j ANG1} : 1, series Z,
    ideal 1 : t2, bus J; returns (V_J, I_J) with I_J flowing out of the transformer into J.
    """
    t1 = t.windv1 * cmath.exp(1j * math.radians(t.ang1_deg))
    z, ym = complex(t.r12, t.x12), complex(t.mag1, t.mag2)

    def f(v_i, i_i):
        i_a = (i_i - ym * v_i) * t1.conjugate()
        v_b = v_i / t1 - z * i_a
        return v_b * t.windv2, i_a / t.windv2

    return f


def test_transformer_kwargs_hand_computed_cw1_cz1_cm1(tmp_path):
    case = _case(tmp_path, _xfmr(mag1=0.001, mag2=-0.004))
    t = case.transformers[0]
    kw = psse.transformer_kwargs(t, case)
    n2 = 1.025 ** 2
    assert kw["r_hv_pu"] == pytest.approx(0.001) and kw["x_hv_pu"] == pytest.approx(0.05)
    assert kw["r_lv_pu"] == pytest.approx(0.001) and kw["x_lv_pu"] == pytest.approx(0.05)
    assert kw["r_fe_pu"] == pytest.approx(1 / (0.001 * n2)) and kw["x_m_pu"] == pytest.approx(1 / (0.004 * n2))
    assert kw["tap_step"] == pytest.approx(0.2 / 32) and kw["tap_position"] == pytest.approx(4.0)
    assert kw["phase_shift_rad"] == 0.0
    tr = jd.Transformer(**kw)
    assert complex(tr.ratio) == pytest.approx(1.025)


@pytest.mark.parametrize("hv_is_i", [True, False])
@pytest.mark.parametrize("ang", [0.0, 30.0])
def test_transformer_matches_psse_circuit_without_magnetising(tmp_path, hv_is_i, ang):
    """jaxdse's map through the converted T model equals the PSS/E circuit (Ym = 0, exact)."""
    kv_i, kv_j = (230.0, 20.0) if hv_is_i else (20.0, 230.0)
    case = _case(tmp_path, _xfmr(w1=1.04, w2=0.98, ang=ang), kv_i=kv_i, kv_j=kv_j)
    t = case.transformers[0]
    kw = psse.transformer_kwargs(t, case)
    assert kw["phase_shift_rad"] == pytest.approx(math.radians(ang) * (1 if hv_is_i else -1))
    tr = jd.Transformer(**kw)
    f = _psse_two_port(t)
    v_i, i_i = 1.02 * cmath.exp(0.3j), 0.8 * cmath.exp(-0.2j)
    v_j, i_j = f(v_i, i_i)
    # jaxdse's generator convention: currents flow from the plant (LV) towards the grid (HV)
    if hv_is_i:   # HV = I: i_hv = -I_I (out of the transformer into bus I), i_lv = -i_J
        v_lv, i_lv = transformer_to_lv(jnp.array([v_i]), jnp.array([-i_i]), tr)
        assert complex(v_lv[0]) == pytest.approx(v_j, abs=1e-9)
        assert complex(i_lv[0]) == pytest.approx(-i_j, abs=1e-9)
    else:         # HV = J: LV (bus I) -> HV (bus J)
        v_hv, i_hv = transformer_to_hv(jnp.array([v_i]), jnp.array([i_i]), tr)
        assert complex(v_hv[0]) == pytest.approx(v_j, abs=1e-9)
        assert complex(i_hv[0]) == pytest.approx(i_j, abs=1e-9)


def test_transformer_kwargs_cw2_cz2_cm2_hv_on_j(tmp_path):
    """Winding 1 on the 20 kV generator bus, kV ratios, winding-base impedance, W/I0 magnetising."""
    case = _case(tmp_path, _xfmr(cw=2, cz=2, cm=2, mag1=250000.0, mag2=0.005, r=0.003, x=0.15, s12=500.0,
                                 w1=20.5, nom1=20.0, w2=230.0, nom2=230.0, rma=22.0, rmi=18.0, ntp=17),
                 kv_i=20.0, kv_j=230.0)
    t = case.transformers[0]
    assert psse.transformer_sides(t, case) == (2, 1)
    kw = psse.transformer_kwargs(t, case)
    t1 = 20.5 / 20.0
    z_r, z_x = 0.003 * 100 / 500 * t1**2, 0.15 * 100 / 500 * t1**2
    assert kw["r_hv_pu"] == pytest.approx(z_r / 2) and kw["x_lv_pu"] == pytest.approx(z_x / 2)
    g = 0.25 / 100.0
    y = 0.005 * 500 / 100
    assert kw["r_fe_pu"] == pytest.approx(1 / g)
    assert kw["x_m_pu"] == pytest.approx(1 / math.sqrt(y**2 - g**2))
    step = 0.25 / 20.0 / t1**2
    assert kw["tap_step"] == pytest.approx(step)
    assert kw["tap_position"] == pytest.approx((1 / t1 - 1) / step)
    assert complex(jd.Transformer(**kw).ratio) == pytest.approx(1 / t1)


def test_transformer_kwargs_cz3_cw3_and_zero_shunt(tmp_path):
    case = _case(tmp_path, _xfmr(cw=3, cz=3, r=1.5e6, x=0.15, s12=500.0, w1=1.0, nom1=241.5, w2=1.0, nom2=20.0))
    kw = psse.transformer_kwargs(case.transformers[0], case)
    r_w = 1.5 / 500
    x_w = math.sqrt(0.15**2 - r_w**2)
    assert 2 * kw["r_hv_pu"] == pytest.approx(r_w * 100 / 500)
    assert 2 * kw["x_hv_pu"] == pytest.approx(x_w * 100 / 500)
    assert jd.Transformer(**kw).ratio == pytest.approx(241.5 / 230.0)
    assert kw["r_fe_pu"] == psse.BIG_SHUNT_PU and kw["x_m_pu"] == psse.BIG_SHUNT_PU


def test_transformer_bad_code(tmp_path):
    case = _case(tmp_path, _xfmr(cz=4))
    with pytest.raises(jd.InputError, match=r"c.raw, row 12: transformer 1-2 '1': unknown code"):
        psse.transformer_kwargs(case.transformers[0], case)


def test_machine_kwargs_and_damping_convention(tmp_path):
    dyr = psse.read_dyr(write(tmp_path, "m.dyr", """
        2 'GENROU' 1 6.5 0.03 0.9 0.05 4.0 2.0 1.8 1.7 0.3 0.55 0.25 0.15 0.03 0.4 /
        2 'GENCLS' 2 3.0 1.0 /
        2 'GENSAL' 3 5.0 0.05 0.1 3.2 0.0 1.1 0.7 0.3 0.25 0.15 0.1 0.3 /
        2 'GENTPJ' 4 6.5 0.03 0.9 0.05 4.0 0.0 1.8 1.7 0.3 0.55 0.25 0.15 0.03 0.4 /
        2 'GENSAE' 5 5.0 0.05 0.1 3.2 0.0 1.1 0.7 0.3 0.25 0.15 0.1 0.3 /
        2 'GENROE' 6 6.5 0.03 0.9 0.05 4.0 2.0 1.8 1.7 0.3 0.55 0.25 0.15 0.03 0.4 /
        """))
    gen = psse.RawGenerator(bus=2, id="1", pg_mw=100, qg_mvar=0, qt_mvar=99, qb_mvar=-99, vs_pu=1,
                            ireg=0, mbase_mva=200.0, zr_pu=0.003, zx_pu=0.25, rt_pu=0, xt_pu=0,
                            gtap=1, stat=1, rmpct=100, pt_mw=999, pb_mw=-999, line=9, source="g.raw")
    kw = psse.machine_kwargs(dyr.machine(2, "1"), gen, 21.0, 60.0)
    assert kw == dict(xd_pu=1.8, xd1_pu=0.3, xq_pu=1.7, rs_pu=0.003, td01_s=6.5, h_s=4.0,
                      d_pu_s=2.0 / (2 * math.pi * 60.0), s_rated_mva=200.0, v_rated_kv=21.0, f_nominal_hz=60.0)
    m = jd.Machine(**kw)
    # PSS/E: 2H d(dw_pu)/dt = Pm - Pe - D dw_pu;  jaxdse: dx2/dt = ws/(2H)(Tm - Te - d x2), x2 = ws dw_pu
    dw_pu, tm, te = 0.003, 0.8, 0.75
    psse_rate = (tm - te - 2.0 * dw_pu) / (2 * 4.0)
    jaxdse_rate = float(m.omega_s / (2 * m.h_s) * (tm - te - m.d_pu_s * m.omega_s * dw_pu))
    assert jaxdse_rate == pytest.approx(float(m.omega_s) * psse_rate)
    assert float(m.a1) == pytest.approx(2.0 / (2 * 4.0))
    tr = psse.transient_data(dyr.machine(2, "1"))
    assert (tr.xq1_pu, tr.tq01_s, tr.xd2_pu, tr.td02_s, tr.tq02_s, tr.xl_pu) == (0.55, 0.9, 0.25, 0.03, 0.05, 0.15)
    # GENCLS: X'd from ZSORCE, xd = xq = x'd
    kw = psse.machine_kwargs(dyr.machine(2, "2"), gen, 21.0, 50.0)
    assert kw["xd_pu"] == kw["xq_pu"] == kw["xd1_pu"] == 0.25 and kw["td01_s"] == psse.GENCLS_TD0_S
    assert kw["d_pu_s"] == pytest.approx(1.0 / (2 * math.pi * 50))
    assert psse.transient_data(dyr.machine(2, "2")) is None
    jd.Machine(**kw)
    sal = psse.transient_data(dyr.machine(2, "3"))
    assert sal.xq1_pu is None and sal.tq01_s is None and sal.xd2_pu == 0.25 and sal.tq02_s == 0.1
    # the exponential-saturation variants read as their quadratic twins
    assert psse.transient_data(dyr.machine(2, "5")) == dataclasses.replace(sal, model="GENSAE")
    roe = psse.transient_data(dyr.machine(2, "6"))
    assert roe.xq1_pu == tr.xq1_pu and roe.tq01_s == tr.tq01_s and not psse.q_axis_problems(dyr.machine(2, "6"))
    tpj = dyr.machine(2, "4")
    assert tpj["Kis"] == 0.0                          # GENTPJ: Kis may be omitted
    jd.Machine(**psse.machine_kwargs(tpj, gen, 21.0, 60.0))
    bad = psse.RawGenerator(**{**gen.__dict__, "mbase_mva": 0.0})
    with pytest.raises(jd.InputError, match=r"g.raw, row 9: generator 2 '1': MBASE is 0.0 MVA"):
        psse.machine_kwargs(dyr.machine(2, "1"), bad, 21.0, 60.0)


def test_governor_from_dyr(tmp_path):
    dyr = psse.read_dyr(write(tmp_path, "g.dyr", """
        1 'TGOV1' 1 0.05 0.5 1.0 0.0 2.1 7.0 0.1 /
        1 'GAST' 2 0.08 0.3 0.3 3.0 1.0 2.0 1.0 0.0 0.2 /
        1 'HYGOV' 3 0.05 0.075 12 0.5 20.5 0.1 1.0 0.0 15 1.5 0 0.08 /
        1 'TGOV1' 4 0.05 0.5 1.0 0.0 2.1 0.0 0.1 /
        1 'GGOV1' 5 -1 0 0.04 1 0.05 -0.05 10 2 0 1 1 0.15 0.5 1.5 0.2 0.1 0 0 3 2 0.67 1 0
          0.1 -0.1 0 0.01 10 0.1 150.0 0 4 5 99 -99 /
        """))
    t = psse.governor_from_dyr(dyr.governor(1, "1"))
    assert isinstance(t, jd.TGOV1)
    assert (float(t.r_pu), float(t.t1_s), float(t.v_max_pu), float(t.v_min_pu), float(t.t2_s),
            float(t.t3_s), float(t.dt_pu)) == (0.05, 0.5, 1.0, 0.0, 2.1, 7.0, 0.1)
    g = psse.governor_from_dyr(dyr.governor(1, "2"))
    assert isinstance(g, GAST) and float(g.dturb_pu) == 0.2 and float(g.kt_pu) == 2.0
    h = psse.governor_from_dyr(dyr.governor(1, "3"))
    assert isinstance(h, HYGOV) and float(h.tg_s) == 20.5 and float(h.r_temp_pu) == 0.075
    with pytest.raises(jd.InputError, match=r"g.dyr, row 4: TGOV1 bus 1 id '4': T3 must be > 0"):
        psse.governor_from_dyr(dyr.governor(1, "4"))
    with pytest.raises(jd.InputError, match=r"row 5: GGOV1 bus 1 id '5': Trate > 0 needs the machine's MBASE"):
        psse.governor_from_dyr(dyr.governor(1, "5"))
    gg = psse.governor_from_dyr(dyr.governor(1, "5"), mbase_mva=200.0)
    assert gg.rselect == -1 and gg.flag == 0 and float(gg.base_ratio) == 0.75
    tr = gg.reference_from_steady(0.6, 0.0)
    assert float(gg.torque(gg.steady_state(tr, 0.0), 0.0)) == pytest.approx(0.6)
    with pytest.raises(jd.InputError, match="not a supported governor"):
        psse.governor_from_dyr(psse.read_dyr(write(tmp_path, "s.dyr", "1 SEXS 1 0.1 10 100 0.1 0 3 /\n")).records[0])


def test_lenient_reading_keeps_bad_records_with_their_problem(tmp_path):
    """strict=False (jaxdse fleet): a malformed record of a machine stays, with the message
    strict reading raises, so that only its unit is left out; one that names no machine is
    dropped and listed; good records read as in strict mode."""
    text = """
        1 'GENCLS' 1 3.0 0.0 /
        2 'GENCLS' 1 nan 0.0 /
        3 'TGOV1' 1 0.05 0.5 1.0 /
        4x 'GENCLS' 1 3.0 0.0 /
        5 'GENCLS' 1 'abc 0.0 /
        6 'GENCLS' 1 2.0
        """
    p = write(tmp_path, "l.dyr", text)
    with pytest.raises(jd.InputError, match="constant 1 \\(H\\) is not a number: 'nan'"):
        psse.read_dyr(p)
    d = psse.read_dyr(p, strict=False)
    assert [(r.bus, r.model) for r in d.records] == [(1, "GENCLS"), (2, "GENCLS"), (3, "TGOV1"),
                                                     (5, "GENCLS"), (6, "GENCLS")]
    assert d.records[0].problem is None and d.records[0].params == {"H": 3.0, "D": 0.0}
    assert d.records[1].problem == f"{p}, row 2: GENCLS bus 2 id '1': constant 1 (H) is not a number: 'nan'"
    assert math.isnan(d.records[1]["H"])
    assert "TGOV1 bus 3 id '1' has 3 constants, expected 7" in d.records[2].problem
    assert "unclosed quote" in d.records[3].problem
    assert "has no terminating '/'" in d.records[4].problem
    assert d.problems == [f"{p}, row 4: record for model GENCLS: the bus number is '4x', not an integer"]
    assert [r.model for r in d.unit_records(2, "1")] == ["GENCLS"]


def test_q_axis_problems_are_what_cannot_be_evaluated(tmp_path):
    """The q-axis circuits fall back only where their equations cannot be evaluated (a time
    constant not > 0, X'q equal to Xl, diverging); odd orders are warnings, one line each."""
    base = "2 'GENROU' 1 6.5 0.03 {tq1} 0.05 4.0 2.0 1.8 {xq} 0.3 {xq1} {xd2} {xl} 0.03 0.4 /"
    ok = dict(tq1=0.9, xq=1.7, xq1=0.55, xd2=0.25, xl=0.15)

    def rec(**kw):
        return psse.read_dyr(write(tmp_path, "q.dyr", base.format(**{**ok, **kw}))).machine(2, "1")

    where = "GENROU on bus 2 id '1' (q.dyr line 1): "
    assert psse.q_axis_problems(rec()) == [] and psse.machine_warnings(rec()) == []
    assert psse.q_axis_problems(rec(tq1=0)) == [where + "T'qo = 0 must be > 0"]
    assert psse.q_axis_problems(rec(xq1=0.15)) == [
        where + "X'q = 0.15 equal to Xl: the q-axis equations divide by X'q - Xl"]
    # X''d far above X'q: the state matrix's trace turns positive
    assert "the q-axis equations diverge" in psse.q_axis_problems(rec(xd2=5.0))[0]
    odd = rec(xd2=0.6, xq1=0.5, xq=0.45)
    assert psse.q_axis_problems(odd) == []
    assert [w.split(": ")[1] for w in psse.machine_warnings(odd)] == [
        "X''d = 0.6 not below X'd = 0.3", "X''d (= X''q) = 0.6 above X'q = 0.5", "X'q = 0.5 above Xq = 0.45"]
    assert [w.split(": ")[1] for w in psse.machine_warnings(rec(xd2=0.15))] == ["X''d = 0.15 equal to Xl"]


def test_lenient_raw_and_plant_data_checks(tmp_path):
    text = _rev32(RAW33).replace("  1000.000, 2.00000E-3", "  nan, 2.00000E-3")
    text = text.replace("     3,'TER BUS     ',  10.5000", "     3,'TER BUS     ',  10.5000\n     3,'AGAIN',  10.5")
    p = write(tmp_path, "l.raw", text)
    with pytest.raises(jd.InputError, match="row 7: bus 3 is defined twice \\(first at line 6\\)"):
        psse.read_raw(p)
    r = psse.read_raw(p, strict=False)
    g = r.generator(2, "G1")
    assert math.isnan(g.mbase_mva) and g.pg_mw == 800.0 and "field 9 (MBASE)" in g.problem
    assert r.buses[3].name == "TER BUS" and any("bus 3 is defined twice" in x for x in r.problems)
    dyr = psse.read_dyr(write(tmp_path, "c.dyr", """
        2 'GENROU' G1 6.5 0.03 0.9 0.05 4.0 2.0 1.8 1.7 0.3 0.55 0.12 0.15 0.03 0.4 /
        2 'GENSAL' G2 5.0 0.05 0.1 -3.2 0.0 1.1 0.7 1.3 0.25 0.15 0.1 0.3 /
        """))
    rou = dyr.machine(2, "G1")
    # X''d below Xl: odd but evaluable, so used as given with a data warning, not a problem
    assert psse.q_axis_problems(rou) == []
    assert psse.machine_warnings(rou) == [
        "GENROU on bus 2 id 'G1' (c.dyr line 1): X''d = 0.12 below Xl = 0.15: used as given (PSS/E "
        "warns about such records and simulates them)"]
    assert psse.machine_problems(rou, g) == [g.problem]
    good = psse.read_raw(write(tmp_path, "g.raw", _rev32(RAW33))).generator(2, "G1")
    assert psse.machine_problems(rou, good) == []
    assert psse.machine_problems(dyr.machine(2, "G2"), good) == [
        "GENSAL on bus 2 id 'G2' (c.dyr line 2): H = -3.2 must be > 0",
        "GENSAL on bus 2 id 'G2' (c.dyr line 2): X'd = 1.3 above Xd = 1.1"]
