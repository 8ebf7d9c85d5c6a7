"""Fuzzing the PSS/E .raw reader (src/jaxdse/_io/psse_raw.py): small revision-35 and
revision-33 cases built here, damaged line by line, read strictly and leniently.

Damage: the file cut at a line (or inside one); a ``0 /`` record deleted; a quoted field
rewritten with commas, slashes and quotes; ``@!`` lines put anywhere; a field replaced by a
bad token; the revision changed. Property: the reader returns a case, or raises one
:class:`InputError` of one line naming the file, the line (``row``) and the record or
section; never another exception. ``@!`` lines alone change nothing; a quoted field rewritten
without its own quote character keeps every record. Through ``jaxdse fleet``: exit status 2
and one ``jaxdse: error:`` line, no traceback. The examples are derandomized and counted with
``hypothesis.event`` (``pytest --hypothesis-show-statistics`` prints the table).
"""
# ruff: noqa: E501  (PSS/E's long records)

import contextlib
import dataclasses
import io
import itertools
import re
import textwrap

import pytest
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

import jaxdse as jd
from jaxdse._app.cli import main
from jaxdse._io import psse

PHASES = (Phase.explicit, Phase.generate)
BASE35 = textwrap.dedent("""\
    @!IC,SBASE,REV,XFRRAT,NXFRAT,BASFRQ
    0,   100.00, 35,     0,     1, 60.00     / PSS(R)E-35.1    FUZZ BASE
    TITLE ONE, A/B
    TITLE TWO
    GENERAL, THRSHZ=0.0001, PQBRAK=0.7
    RATING, 1, "RATE1 ", "SET 1, NORMAL / SUMMER"
    0 / END OF SYSTEM-WIDE DATA, BEGIN BUS DATA
    @!   I,'NAME        ', BASKV, IDE,AREA,ZONE,OWNER, VM,        VA,    NVHI,   NVLO,   EVHI,   EVLO
         1,'HV BUS      ', 230.0000,3,   1,   1,   1,1.02000,   0.0000,1.10000,0.90000,1.10000,0.90000
         2,'GEN, A/B    ',  20.0000,2,   1,   1,   1,1.01000,   5.0000,1.10000,0.90000,1.10000,0.90000
         3,'LOAD        ', 230.0000,1,   1,   1,   1,1.00000,  -2.0000,1.10000,0.90000,1.10000,0.90000
    0 / END OF BUS DATA, BEGIN LOAD DATA
         3,'1 ',   1,   1,   1,   100.000,    20.000,     0.000,     0.000,     0.000,     0.000,   1,    1,  0,     0.000,     0.000,    0,'            '
    0 / END OF LOAD DATA, BEGIN FIXED SHUNT DATA
         3,'1 ',1,     0.000,    10.000
    0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA
         2,'1 ',   150.000,    10.000,   100.000,  -100.000,1.01000,     0,   0,   200.000, 3.00000E-3, 2.50000E-1, 0.00000E+0, 0.00000E+0,1.00000,1,  100.0,   180.000,     0.000, 0,   1,1.0000
         2,'2 ',    50.000,     5.000,    50.000,   -50.000,1.01000,     0,   0,    80.000, 0.00000E+0, 3.00000E-1, 0.00000E+0, 0.00000E+0,1.00000,1,  100.0,    70.000,     0.000, 0,   1,1.0000
    0 / END OF GENERATOR DATA, BEGIN BRANCH DATA
         1,     3,'1 ', 1.00000E-3, 1.00000E-2,   0.01000,'LINE 1-3, A/B                           ', 100.00,  110.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00, 0.00000, 0.00000, 0.00000, 0.00000,1,1,  0.00,   1,1.0000
    0 / END OF BRANCH DATA, BEGIN SYSTEM SWITCHING DEVICE DATA
       1,     3,'*1', 1.00000E-4,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,    1,    1,    2,    3,'BRK 1/3'
    0 / END OF SYSTEM SWITCHING DEVICE DATA, BEGIN TRANSFORMER DATA
         1,     2,     0,'1 ', 1, 1, 1, 0.00000E+00, 0.00000E+00,2,'GSU, 1/2                                ',1,   1,1.0000,   0,1.0000,   0,1.0000,   0,1.0000,'YNd1        ', 0
     2.00000E-3, 1.50000E-1,  100.00
    1.02500, 230.000,   0.000,  300.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00, 0,      0,   0,1.10000,0.90000,1.10000,0.90000,  33, 0,0.00000,0.00000, 0.000
    1.00000,  20.000
    0 / END OF TRANSFORMER DATA, BEGIN AREA DATA
       1,     0,    0.000,   10.000,'AREA, 1/A   '
    0 / END OF AREA DATA, BEGIN TWO-TERMINAL DC DATA
    0 / END OF TWO-TERMINAL DC DATA, BEGIN VSC DC LINE DATA
    0 / END OF VSC DC LINE DATA, BEGIN IMPEDANCE CORRECTION DATA
    0 / END OF IMPEDANCE CORRECTION DATA, BEGIN MULTI-TERMINAL DC DATA
    0 / END OF MULTI-TERMINAL DC DATA, BEGIN MULTI-SECTION LINE DATA
    0 / END OF MULTI-SECTION LINE DATA, BEGIN ZONE DATA
    0 / END OF ZONE DATA, BEGIN INTER-AREA TRANSFER DATA
    0 / END OF INTER-AREA TRANSFER DATA, BEGIN OWNER DATA
    0 / END OF OWNER DATA, BEGIN FACTS DEVICE DATA
    0 / END OF FACTS DEVICE DATA, BEGIN SWITCHED SHUNT DATA
         3,'1 ',   1,  0,  1,1.04500,0.95500,     3,   0, 100.0,'            ', 20.00, 1, 2,  10.00
    0 / END OF SWITCHED SHUNT DATA, BEGIN GNE DATA
    0 / END OF GNE DATA, BEGIN INDUCTION MACHINE DATA
    0 / END OF INDUCTION MACHINE DATA, BEGIN SUBSTATION DATA
    0 / END OF SUBSTATION DATA
    Q
    """)
BASE33 = textwrap.dedent("""\
    0,   100.00, 33,     0,     1, 60.00     / PSS(R)E-33.10    FUZZ BASE
    TITLE ONE
    TITLE TWO, 'QUOTED'
         1,'HV BUS      ', 230.0000,3,   1,   1,   1,1.02000,   0.0000,1.10000,0.90000,1.10000,0.90000
         2,'GEN, A/B    ',  20.0000,2,   1,   1,   1,1.01000,   5.0000,1.10000,0.90000,1.10000,0.90000
    0 / END OF BUS DATA, BEGIN LOAD DATA
         1,'1 ',1,   1,   1,   100.000,    20.000,     0.000,     0.000,     0.000,     0.000,   1,1,0
    0 / END OF LOAD DATA, BEGIN FIXED SHUNT DATA
    0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA
         2,'1 ',   150.000,    10.000,   100.000,  -100.000,1.01000,     0,   200.000, 3.00000E-3, 2.50000E-1, 0.00000E+0, 0.00000E+0,1.00000,1,  100.0,   180.000,     0.000,   1,1.0000
    0 / END OF GENERATOR DATA, BEGIN BRANCH DATA
    0 / END OF BRANCH DATA, BEGIN TRANSFORMER DATA
         1,     2,     0,'1 ',1,1,1, 0.00000E+0, 0.00000E+0,2,'GSU, 1/2    ',1,   1,1.0000,   0,1.0000,   0,1.0000,   0,1.0000,'YNd1        '
     2.00000E-3, 1.50000E-1,   100.00
    1.02500, 230.000,   0.000,   300.00,   300.00,   300.00, 0,      0, 1.10000, 0.90000, 1.10000, 0.90000,  33, 0, 0.00000, 0.00000,  0.000
    1.00000,  20.000
    0 / END OF TRANSFORMER DATA, BEGIN AREA DATA
    0 / END OF AREA DATA, BEGIN TWO-TERMINAL DC DATA
    Q
    """)
BASES = {"rev35": BASE35, "rev33": BASE33}
TEXT = "AB ,/'\"0-@!"
"""Characters a rewritten quoted field is drawn from: commas, slashes, both quotes, '0', '@!'."""
TOKENS = ["", "X", "1.5.2", "nan", "inf", "'Q'", "-1", "1E400", "0", "2.5", "'A,B/C'", "1D-2"]


def damages():
    line = st.integers(0, 70)
    return st.lists(st.one_of(
        st.tuples(st.just("truncate"), line, st.one_of(st.none(), st.integers(0, 120))),
        st.tuples(st.just("drop 0 record"), st.integers(0, 25)),
        st.tuples(st.just("quoted field"), st.integers(0, 40), st.text(TEXT, max_size=8)),
        st.tuples(st.just("@! line"), line, st.text(TEXT, max_size=10)),
        st.tuples(st.just("bad field"), st.integers(0, 40), st.integers(0, 30), st.sampled_from(TOKENS)),
        st.tuples(st.just("revision"), st.sampled_from([0, 30, 31, 32, 34, 36, 37, 99])),
    ), min_size=1, max_size=3)


_QUOTED = re.compile(r"'[^']*'|\"[^\"]*\"")


def damage(text: str, ds) -> tuple[str, bool]:
    """(the damaged text, whether the damage keeps every record: only @! lines, and quoted
    fields rewritten without their own quote character)."""
    lines = text.splitlines()
    harmless = True
    for d in ds:
        kind = d[0]
        if kind == "truncate":
            k = min(d[1], len(lines))
            lines = lines[:k] + ([lines[k][:d[2]]] if d[2] is not None and k < len(lines) else [])
            harmless = False
        elif kind == "drop 0 record":
            zeros = [k for k, t in enumerate(lines) if re.match(r"\s*0\s*/", t)]
            if zeros:
                del lines[zeros[d[1] % len(zeros)]]
                harmless = False
        elif kind == "quoted field":
            spans = [(k, m) for k, t in enumerate(lines) if not t.startswith("@!")
                     for m in _QUOTED.finditer(t)]
            if spans:
                k, m = spans[d[1] % len(spans)]
                q = m.group()[0]
                lines[k] = lines[k][:m.start()] + q + d[2] + q + lines[k][m.end():]
                harmless = harmless and q not in d[2] and k >= 3
        elif kind == "@! line":
            lines.insert(min(d[1], len(lines)), "@!" + d[2])
        elif kind == "bad field":
            data = [k for k, t in enumerate(lines) if k > 0 and "," in t and not t.startswith("@!")]
            if data:
                k = data[d[1] % len(data)]
                f = lines[k].split(",")
                f[d[2] % len(f)] = d[3]
                lines[k] = ",".join(f)
                harmless = False
        elif kind == "revision":
            k = next((k for k, t in enumerate(lines) if not t.startswith("@!")), None)
            if k is not None:
                lines[k] = re.sub(r"^(\s*\d+,\s*[\d.]+,\s*)\d+", rf"\g<1>{d[1]}", lines[k])
                harmless = False
    return "\n".join(lines) + "\n", harmless


def _content(case):
    def plain(records):
        return [dataclasses.replace(r, line=0, **({"source": ""} if hasattr(r, "source") else {}))
                for r in records]
    return (plain(case.buses.values()), plain(case.loads), plain(case.generators), plain(case.branches),
            plain(case.transformers), plain(case.fixed_shunts), plain(case.switched_shunts),
            case.revision, case.system_wide)


RECORD = re.compile(r"record|data|case identification|transformer \d|bus \d|revision|section")
COUNTER = itertools.count()


def check_error(err: Exception, path) -> str:
    """The error is one line naming the file, a line and a record; its kind for the table."""
    text = str(err)
    assert "\n" not in text, text
    assert text.startswith(f"{path}, row "), text
    assert RECORD.search(text), text
    for key, kind in KINDS.items():
        if key in text:
            return kind
    return "other"


KINDS = {
    "says it ends": "a '0' record's comment names another section",
    "starts with a number": "system-wide section not closed",
    "not closed": "a section not closed",
    "unclosed quote": "unclosed quote",
    "needs 4 lines": "transformer cut short", "needs 5 lines": "transformer cut short",
    "defined twice": "bus defined twice",
    "ends before": "no case line and titles",
    "revision 36 adds": "undocumented revision-36 field",
    "only PSS/E raw revisions": "unsupported revision",
    "is not a number": "field not a number", "is not an integer": "field not an integer",
    "is missing": "required field missing", "SBASE": "SBASE not > 0",
}


@settings(max_examples=300, deadline=None, derandomize=True, database=None, phases=PHASES,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(base=st.sampled_from(sorted(BASES)), ds=damages(), strict=st.booleans())
def test_damaged_raw_reads_or_fails_in_one_line(tmp_path, base, ds, strict):
    text, harmless = damage(BASES[base], ds)
    path = tmp_path / f"case{next(COUNTER)}.raw"
    path.write_text(text, encoding="latin-1")
    kinds = "+".join(sorted({d[0] for d in ds}))
    try:
        case = psse.read_raw(path, strict=strict)
    except jd.InputError as err:
        event(f"{kinds}: InputError ({check_error(err, path)})")
        assert not harmless, f"{ds}: {err}"
        return
    event(f"{kinds}: read")
    if harmless:
        clean = psse.read_raw(tmp_path / _write_clean(tmp_path, base))
        if "quoted field" in kinds:
            assert [len(x) if isinstance(x, list) else x for x in _content(case)[:7]] == \
                [len(x) for x in _content(clean)[:7]]
        else:
            assert _content(case) == _content(clean)


def _write_clean(tmp_path, base):
    name = f"clean_{base}.raw"
    if not (tmp_path / name).exists():
        (tmp_path / name).write_text(BASES[base], encoding="latin-1")
    return name


@pytest.mark.parametrize("cut", [
    lambda t: t.replace("0 / END OF BUS DATA, BEGIN LOAD DATA\n", ""),
    lambda t: t.replace("'GEN, A/B    '", "'GEN, A/B    "),
    lambda t: t.replace("0 / END OF SYSTEM-WIDE DATA, BEGIN BUS DATA\n", ""),
    lambda t: t[:t.index("0 / END OF GENERATOR DATA")],
    lambda t: t.replace(" 35,", " 37,", 1),
    lambda t: t.replace("'            '\n", "'            ','NAME'\n", 1).replace(" 35,", " 36,", 1),
], ids=["bus 0 record", "open quote", "system-wide 0 record", "cut", "revision 37", "revision 36 field"])
def test_fleet_exits_2_with_one_line(tmp_path, cut):
    (tmp_path / "case.raw").write_text(cut(BASE35))
    (tmp_path / "case.dyr").write_text("2 'GENROU' 1 6.5 0.06 0.2 0.05 4.0 0 1.8 1.75 0.6 0.8 0.23 0.15 0.09 0.38 /\n")
    (tmp_path / "fleet.toml").write_text('[case]\nraw = "case.raw"\ndyr = "case.dyr"\n[measurement]\nfile = "x.csv"\n')
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["fleet", str(tmp_path / "fleet.toml"), "--out", str(tmp_path / "out")])
    lines = err.getvalue().splitlines()
    assert rc == 2 and len(lines) == 1 and "Traceback" not in err.getvalue(), err.getvalue()
    assert lines[0].startswith(f"jaxdse: error: {tmp_path / 'case.raw'}, row "), lines[0]
