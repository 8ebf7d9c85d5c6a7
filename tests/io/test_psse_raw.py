"""Tests of the PSS/E .raw reader across revisions 32 to 36 (src/jaxdse/_io/psse_raw.py and its
layout tables, psse_raw_layouts.py).

* a revision-35 file written by PSS/E 35.1 (../shared/data/case25_v35): the counts of buses,
  loads, machines, branches, transformers and shunts against the file's own sections, counted
  here independently; its ``@!`` column headers against the revision-35 tables;
* revisions 34 and 35 of the WECC 240-bus case (revision 32), written by a small writer here
  from the documented layouts (:func:`write_revision`): the same buses, machines, branches,
  transformers (and loads, shunts) as the original, and the same fleet plants;
* hand-made cases: system-wide data, ``@!`` lines anywhere, node-breaker sections read past,
  revision 36 as far as documented, and the one-line errors.
"""
# ruff: noqa: E501  (PSS/E's long records and column headers)

import dataclasses
import re
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._io import psse
from jaxdse._io.psse_raw_layouts import LAYOUTS, transformer_layouts

ROOT = Path(__file__).resolve().parents[2]
SHARED = ROOT.parent / "shared" / "data"
CASE25 = SHARED / "case25_v35" / "case25_v35_savnwb.raw"
WECC = SHARED / "wecc240" / "240busWECC_2018_PSS32_fixed_shunts.raw"
OSL = ROOT / "experiments" / "naspi_osl_case1" / "fleet.toml"
needs_case25 = pytest.mark.skipif(not CASE25.exists(), reason="shared case25_v35 data absent")
needs_wecc = pytest.mark.skipif(not WECC.exists(), reason="shared WECC 240 data absent")


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text).lstrip("\n"))
    return p


def split(line: str) -> list[str]:
    """The fields of a .raw line (commas outside quotes; the data end at a '/' outside quotes),
    quotes kept, blanks kept as ''."""
    out, cur, quote = [], "", None
    for ch in line:
        if quote:
            cur += ch
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote, cur = ch, cur + ch
        elif ch == "/":
            break
        elif ch == ",":
            out.append(cur.strip())
            cur = ""
        else:
            cur += ch
    return [*out, cur.strip()]


# --- case25_v35: a file written by PSS/E 35.1 -------------------------------------------------

def _sections_of(path):
    """{section name from the '0 / END OF ... DATA' comment: (the @! header lines, the records)}
    of a PSS/E 35 file, counted here without the reader (the substation data nest '0' records:
    not needed)."""
    out, headers, records = {}, [], []
    lines = path.read_text(encoding="latin-1").splitlines()
    start = next(k for k, t in enumerate(lines) if not t.startswith("@!")) + 3
    for text in lines[start:]:
        if text.startswith("@!"):
            headers.append(text[2:])
        elif re.match(r"\s*0\s*/", text):
            name = re.search(r"END OF (.+?) DATA", text).group(1)
            out[name] = (headers, records)
            headers, records = [], []
        elif text.strip() and text.strip() != "Q":
            records.append(text)
    return out


@needs_case25
def test_case25_counts_against_its_own_sections():
    sections = _sections_of(CASE25)
    xfmr = sections["TRANSFORMER"][1]
    k, n2, n3 = 0, 0, 0
    while k < len(xfmr):                        # K = 0: four lines, else five
        three = split(xfmr[k])[2].strip() != "0"
        n3, n2, k = n3 + three, n2 + (not three), k + (5 if three else 4)
    expected = {name: len(sections[key][1]) for name, key in (
        ("buses", "BUS"), ("loads", "LOAD"), ("fixed_shunts", "FIXED SHUNT"),
        ("generators", "GENERATOR"), ("branches", "BRANCH"), ("switched_shunts", "SWITCHED SHUNT"))}
    r = psse.read_raw(CASE25)
    got = {name: len(getattr(r, name)) for name in expected}
    assert got == expected == {"buses": 25, "loads": 17, "fixed_shunts": 1, "generators": 42,
                               "branches": 33, "switched_shunts": 9}
    assert (len(r.transformers), r.n_three_winding) == (n2, n3) == (6, 1)
    assert r.n_switching_devices == len(sections["SYSTEM SWITCHING DEVICE"][1]) == 2
    assert (r.revision, r.sbase_mva, r.basfrq_hz) == (35, 100.0, 60.0)
    assert r.title == ("IEEE 25 BUS NETWORK", "N-1-1 ANALYSIS DEMONSTRATION")
    assert list(r.system_wide) == ["GENERAL", "GAUSS", "NEWTON", "ADJUST", "TYSL", "SOLVER", "RATING"]
    assert len(r.system_wide["RATING"]) == 12 and r.system_wide["RATING"][9] == ["10", "RATE10", "RATING SET 10"]
    assert len(r.notes) == 1 and "2 system switching device record(s) read past" in r.notes[0]
    assert "bus-branch view" in r.notes[0] and r.problems == []
    g = r.generator(101, "3")                   # NREG after IREG, BASLOD after PB
    assert (g.ireg, g.nreg, g.mbase_mva, g.zx_pu, g.stat, g.pt_mw, g.baslod) == (101, 0, 100.0, 0.181, 1, 80.0, 0)
    b = r.branches[0]
    assert (b.i, b.j, b.x_pu, b.rate_a_mva, b.ratings_mva, b.status) == (101, 102, 0.0139, 175.0, (175.0, 193.0, 200.0), 1)
    t = r.transformers[0]
    assert (t.i, t.j, t.windv1, t.cod1, t.cont1, t.nod1, t.rma1, t.ntp1, t.ratings1_mva) == \
        (103, 224, 1.0375, 1, 215, 0, 1.05, 17, (400.0, 510.0, 600.0))
    s = r.switched_shunts[3]                    # ID, SWREG/NREG, a status per block
    assert (s.bus, s.id, s.modsw, s.swreg, s.rmidnt, s.binit_mvar, s.blocks) == (103, "1", 4, 3005, "LINE1.  V DC", 0.0, ((1, 1, 33.35),))
    assert r.fixed_shunts[0].bl_mvar == -40.0


def _names(header: str) -> tuple:
    return tuple(re.sub(r"[\s']", "", f).upper() for f in header.split(",") if f.strip())


@needs_case25
def test_revision_35_tables_match_the_headers_pss_e_writes():
    sections = _sections_of(CASE25)
    for record, key in (("bus", "BUS"), ("load", "LOAD"), ("fixed shunt", "FIXED SHUNT"),
                        ("generator", "GENERATOR"), ("branch", "BRANCH"),
                        ("system switching device", "SYSTEM SWITCHING DEVICE"),
                        ("switched shunt", "SWITCHED SHUNT")):
        header = _names(sections[key][0][0])
        assert header == LAYOUTS[record][35], record
    lines = [_names(h) for h in sections["TRANSFORMER"][0]]
    assert tuple(lines) == transformer_layouts(35, three_winding=True)


PSSE34_HEADERS = {
    # The @! column headers PSS/E 34.0 writes (test files of the public jbarberia/PSSE34to33):
    # the POM's revision-34 fields NREG (generators, switched shunts) and NODn (windings) come
    # after them.
    "load": "I,'ID',STAT,AREA,ZONE,PL,QL,IP,IQ,YP,YQ,OWNER,SCALE,INTRPT,DGENP,DGENQ,DGENF",
    "generator": "I,'ID',PG,QG,QT,QB,VS,IREG,MBASE,ZR,ZX,RT,XT,GTAP,STAT,RMPCT,PT,PB,O1,F1,O2,F2,O3,F3,O4,F4,WMOD,WPF",
    "branch": "I,J,'CKT',R,X,B,'N A M E',RATE1,RATE2,RATE3,RATE4,RATE5,RATE6,RATE7,RATE8,RATE9,RATE10,RATE11,RATE12,GI,BI,GJ,BJ,STAT,MET,LEN,O1,F1,O2,F2,O3,F3,O4,F4",
    "transformer line 1": "I,J,K,'CKT',CW,CZ,CM,MAG1,MAG2,NMETR,'N A M E',STAT,O1,F1,O2,F2,O3,F3,O4,F4,'VECGRP',ZCOD",
    "switched shunt": "I,MODSW,ADJM,ST,VSWHI,VSWLO,SWREM,RMPCT,'RMIDNT',BINIT,N1,B1,N2,B2,N3,B3,N4,B4,N5,B5,N6,B6,N7,B7,N8,B8",
}


def test_revision_34_tables_match_the_headers_pss_e_34_writes():
    for record, header in PSSE34_HEADERS.items():
        names, table = _names(header), LAYOUTS[record][34]
        assert table[:len(names)] == names, record
        assert table[len(names):] == {"generator": ("NREG",), "switched shunt": ("NREG",)}.get(record, ()), record
    winding = "WINDV1,NOMV1,ANG1,RATE1-1,RATE1-2,RATE1-3,RATE1-4,RATE1-5,RATE1-6,RATE1-7,RATE1-8,RATE1-9,RATE1-10,RATE1-11,RATE1-12,COD1,CONT1,RMA1,RMI1,VMA1,VMI1,NTP1,TAB1,CR1,CX1,CNXA1"
    assert transformer_layouts(34, three_winding=False)[2] == (*_names(winding), "NOD1")


# --- a writer of revisions 34 and 35 from the documented layouts -------------------------------

SOURCE_32 = {   # the revision-32 records of the WECC file, in PSS/E's order
    "BUS": "I,NAME,BASKV,IDE,AREA,ZONE,OWNER,VM,VA",
    "LOAD": "I,ID,STATUS,AREA,ZONE,PL,QL,IP,IQ,YP,YQ,OWNER,SCALE",
    "FIXED SHUNT": "I,ID,STATUS,GL,BL",
    "GENERATOR": "I,ID,PG,QG,QT,QB,VS,IREG,MBASE,ZR,ZX,RT,XT,GTAP,STAT,RMPCT,PT,PB,O1,F1,O2,F2,O3,F3,O4,F4,WMOD,WPF",
    "BRANCH": "I,J,CKT,R,X,B,RATEA,RATEB,RATEC,GI,BI,GJ,BJ,ST,MET,LEN,O1,F1,O2,F2,O3,F3,O4,F4",
    "TRANSFORMER 1": "I,J,K,CKT,CW,CZ,CM,MAG1,MAG2,NMETR,NAME,STAT,O1,F1,O2,F2,O3,F3,O4,F4",
    "TRANSFORMER 2": "R1-2,X1-2,SBASE1-2,R2-3,X2-3,SBASE2-3,R3-1,X3-1,SBASE3-1,VMSTAR,ANSTAR",
    "WINDING": "WINDV,NOMV,ANG,RATA,RATB,RATC,COD,CONT,RMA,RMI,VMA,VMI,NTP,TAB,CR,CX,CNXA",
    "SWITCHED SHUNT": "I,MODSW,ADJM,ST,VSWHI,VSWLO,SWREM,RMPCT,RMIDNT,BINIT," + ",".join(f"N{k},B{k}" for k in range(1, 9)),
}
_RATES = ",".join(f"RATE{k}" for k in range(1, 13))
_WRATES = ",".join(f"RATE-{k}" for k in range(1, 13))
TARGET = {      # revisions 34 and 35 (POM; as the @! headers PSS/E writes, NREG/NODn appended in 34)
    34: {
        "BUS": "I,NAME,BASKV,IDE,AREA,ZONE,OWNER,VM,VA,NVHI,NVLO,EVHI,EVLO",
        "LOAD": "I,ID,STAT,AREA,ZONE,PL,QL,IP,IQ,YP,YQ,OWNER,SCALE,INTRPT,DGENP,DGENQ,DGENF",
        "FIXED SHUNT": "I,ID,STATUS,GL,BL",
        "GENERATOR": "I,ID,PG,QG,QT,QB,VS,IREG,MBASE,ZR,ZX,RT,XT,GTAP,STAT,RMPCT,PT,PB,O1,F1,O2,F2,O3,F3,O4,F4,WMOD,WPF,NREG",
        "BRANCH": f"I,J,CKT,R,X,B,NAME,{_RATES},GI,BI,GJ,BJ,STAT,MET,LEN,O1,F1,O2,F2,O3,F3,O4,F4",
        "TRANSFORMER 1": "I,J,K,CKT,CW,CZ,CM,MAG1,MAG2,NMETR,NAME,STAT,O1,F1,O2,F2,O3,F3,O4,F4,VECGRP,ZCOD",
        "WINDING": f"WINDV,NOMV,ANG,{_WRATES},COD,CONT,RMA,RMI,VMA,VMI,NTP,TAB,CR,CX,CNXA,NOD",
        "SWITCHED SHUNT": "I,MODSW,ADJM,ST,VSWHI,VSWLO,SWREM,RMPCT,RMIDNT,BINIT," + ",".join(f"N{k},B{k}" for k in range(1, 9)) + ",NREG",
    },
    35: {
        "BUS": "I,NAME,BASKV,IDE,AREA,ZONE,OWNER,VM,VA,NVHI,NVLO,EVHI,EVLO",
        "LOAD": "I,ID,STAT,AREA,ZONE,PL,QL,IP,IQ,YP,YQ,OWNER,SCALE,INTRPT,DGENP,DGENQ,DGENF,LOADTYPE",
        "FIXED SHUNT": "I,ID,STATUS,GL,BL",
        "GENERATOR": "I,ID,PG,QG,QT,QB,VS,IREG,NREG,MBASE,ZR,ZX,RT,XT,GTAP,STAT,RMPCT,PT,PB,BASLOD,O1,F1,O2,F2,O3,F3,O4,F4,WMOD,WPF",
        "BRANCH": f"I,J,CKT,R,X,B,NAME,{_RATES},GI,BI,GJ,BJ,STAT,MET,LEN,O1,F1,O2,F2,O3,F3,O4,F4",
        "TRANSFORMER 1": "I,J,K,CKT,CW,CZ,CM,MAG1,MAG2,NMETR,NAME,STAT,O1,F1,O2,F2,O3,F3,O4,F4,VECGRP,ZCOD",
        "WINDING": f"WINDV,NOMV,ANG,{_WRATES},COD,CONT,NOD,RMA,RMI,VMA,VMI,NTP,TAB,CR,CX,CNXA",
        "SWITCHED SHUNT": "I,ID,MODSW,ADJM,ST,VSWHI,VSWLO,SWREG,NREG,RMPCT,RMIDNT,BINIT," + ",".join(f"S{k},N{k},B{k}" for k in range(1, 9)),
    },
}
RENAMED = {"RATEA": "RATE1", "RATEB": "RATE2", "RATEC": "RATE3", "ST": "STAT", "STATUS": "STAT",
           "RATA": "RATE-1", "RATB": "RATE-2", "RATC": "RATE-3", "SWREM": "SWREG"}
NEW = {"NVHI": "1.1", "NVLO": "0.9", "EVHI": "1.1", "EVLO": "0.9", "INTRPT": "0", "DGENP": "0.0",
       "DGENQ": "0.0", "DGENF": "0", "LOADTYPE": "''", "NREG": "0", "BASLOD": "0", "NAME": "''",
       "VECGRP": "''", "ZCOD": "0", "NOD": "0", "ID": "'1'"}
SYSTEM_WIDE = [
    "GENERAL, THRSHZ=0.0001, PQBRAK=0.7, BLOWUP=5.0",
    "GAUSS, ITMX=100, ACCP=1.6, ACCQ=1.6, ACCM=1.0, TOL=0.0001",
    "NEWTON, ITMXN=20, ACCN=1.0, TOLN=0.1, VCTOLQ=0.1, VCTOLV=0.00001, DVLIM=0.99, NDVFCT=0.99",
    "ADJUST, ADJTHR=0.005, ACCTAP=1.0, TAPLIM=0.05, SWVBND=100.0, MXTPSS=99, MXSWIM=10",
    "TYSL, ITMXTY=20, ACCTY=1.0, TOLTY=0.00001",
    "SOLVER, FNSL, ACTAPS=0, AREAIN=0, PHSHFT=0, DCTAPS=1, SWSHNT=1, FLATST=0, VARLIM=99, NONDIV=0",
    *(f'RATING,{k:2d}, "RATE{k}", "RATING SET {k}, A/B"' for k in range(1, 13)),
]
SECTIONS_32 = ("BUS", "LOAD", "FIXED SHUNT", "GENERATOR", "BRANCH", "TRANSFORMER", "AREA",
               "TWO-TERMINAL DC", "VSC DC LINE", "IMPEDANCE CORRECTION", "MULTI-TERMINAL DC",
               "MULTI-SECTION LINE", "ZONE", "INTER-AREA TRANSFER", "OWNER", "FACTS DEVICE",
               "SWITCHED SHUNT", "GNE DEVICE")


def _convert(fields: list[str], source: str, target: str) -> list[str]:
    """A record from the source field names to the target's: by name, renamed fields kept, new
    ones at their documented default (a blank where the source leaves a field blank or out)."""
    src, names = source.split(","), target.split(",")
    value = {(n if n in names else RENAMED.get(n, n)): (fields[k] if k < len(fields) else "")
             for k, n in enumerate(src)}
    out = []
    for name in names:
        if name in value:
            out.append(value[name])
        elif re.fullmatch(r"RATE-?\d+", name):
            out.append("0.0")
        elif re.fullmatch(r"S\d", name):
            out.append("1")
        else:
            out.append(NEW[name])
    while out and out[-1] == "":
        out.pop()
    return out


def write_revision(path_32: Path, revision: int) -> str:
    """The revision-32 WECC 240 case at ``path_32`` written in ``revision`` (34 or 35)."""
    lines = path_32.read_text(encoding="latin-1").splitlines()
    case = split(lines[0])
    body = {name: [] for name in SECTIONS_32}
    k = 0
    for text in lines[3:]:
        if text.strip() == "Q":
            break
        if re.match(r"\s*0\s*/", text) or text.strip() == "0":
            k += 1
        else:
            body[SECTIONS_32[k]].append(text)
    t = TARGET[revision]
    out = ["@!IC,SBASE,REV,XFRRAT,NXFRAT,BASFRQ",
           f"{case[0]}, {case[1]}, {revision}, {case[3]}, {case[4]}, {case[5]}     / PSS(R)E-{revision} RAW written by the jaxdse tests from {path_32.name}",
           lines[1], lines[2],
           *[line for line in SYSTEM_WIDE if revision >= 35 or not line.startswith("SOLVER")],
           "0 / END OF SYSTEM-WIDE DATA, BEGIN BUS DATA"]

    def section(name, records, next_name, header=None):
        if header:
            out.append("@!" + header)
        out.extend(records)
        out.append(f"0 / END OF {name} DATA" + (f", BEGIN {next_name} DATA" if next_name else ""))

    def simple(name):
        return [",".join(_convert(split(r), SOURCE_32[name], t[name])) for r in body[name]]

    names = ["BUS", "LOAD", "FIXED SHUNT", "GENERATOR", "BRANCH"]
    for a, b in zip(names, [*names[1:], "SYSTEM SWITCHING DEVICE"]):
        section(a, simple(a), b, t[a])
    section("SYSTEM SWITCHING DEVICE", [], "TRANSFORMER", f"I,J,'CKT',X,{_RATES},STAT,NSTAT,MET,STYPE,'NAME'")
    xfmr, recs, k = [], body["TRANSFORMER"], 0
    while k < len(recs):
        first = split(recs[k])
        n = 5 if first[2].strip() != "0" else 4
        xfmr.append(",".join(_convert(first, SOURCE_32["TRANSFORMER 1"], t["TRANSFORMER 1"])))
        xfmr.append(recs[k + 1])
        for w in range(1, n - 1):
            fields = split(recs[k + 1 + w])
            if n == 4 and w == 2:                   # WINDV2, NOMV2 only
                xfmr.append(recs[k + 1 + w])
                continue
            xfmr.append(",".join(_convert(fields, SOURCE_32["WINDING"], t["WINDING"])))
        k += n
    section("TRANSFORMER", xfmr, "AREA", t["TRANSFORMER 1"])
    rest = SECTIONS_32[6:]
    for a, b in zip(rest, [*rest[1:], "INDUCTION MACHINE"]):
        records = body[a]
        if a == "SWITCHED SHUNT" and revision == 34:     # NREG after the blocks in use
            records = [",".join([*_convert(split(r), SOURCE_32[a], t[a].removesuffix(",NREG")), "0"])
                       for r in records]
        elif a == "SWITCHED SHUNT":
            records = [",".join(_convert(split(r), SOURCE_32[a], t[a])) for r in records]
        section(a, records, b, t.get(a))
    section("INDUCTION MACHINE", [], "SUBSTATION")
    section("SUBSTATION", [], None)
    return "\n".join([*out, "Q"]) + "\n"


def _plain(records):
    """Records without the line (and file) they were read from."""
    return [dataclasses.replace(r, line=0, **({"source": ""} if hasattr(r, "source") else {}))
            for r in records]


@needs_wecc
@pytest.mark.parametrize("revision", [34, 35])
def test_wecc240_written_in_revision_34_and_35_reads_back_the_same(tmp_path, revision):
    text = write_revision(WECC, revision)
    path = tmp_path / f"wecc240_rev{revision}.raw"
    path.write_text(text, encoding="latin-1")
    old, new = psse.read_raw(WECC), psse.read_raw(path)
    assert (new.revision, old.revision) == (revision, 32)
    assert len(new.system_wide["RATING"]) == 12 and new.system_wide["RATING"][0][-1] == "RATING SET 1, A/B"
    assert _plain(new.buses.values()) == _plain(old.buses.values())
    assert len(new.generators) == 146 and _plain(new.generators) == _plain(old.generators)
    assert len(new.branches) == 329 and _plain(new.branches) == _plain(old.branches)
    assert len(new.transformers) == 122 and _plain(new.transformers) == _plain(old.transformers)
    assert _plain(new.loads) == _plain(old.loads)
    assert len(new.switched_shunts) == 7 and _plain(new.switched_shunts) == _plain(old.switched_shunts)
    assert (new.sbase_mva, new.basfrq_hz, new.title, new.notes) == (old.sbase_mva, old.basfrq_hz, old.title, [])
    assert text.count("\n@!") == 8 and "SOLVER" in text[:2000] if revision == 35 else "SOLVER" not in text


def _fleet_view(fleet, toml):
    """What the plants of a fleet are, with the names of the files and the lines left out."""
    def clean(text):
        text = str(text).replace(str(toml), "FLEET").replace(Path(fleet.raw.source).name, "RAW")
        return re.sub(r"\(\S+ line \d+\)", "(...)", text)

    plants = []
    for p in fleet.plants:
        m = dataclasses.asdict(p.run.measurement)
        m["file"] = tuple(str(Path(f).resolve()) for f in m["file"])
        leaves = jax.tree_util.tree_leaves(p.run.plant)
        plants.append((p.name, p.bus, p.members, p.others, [clean(f) for f in p.fallbacks],
                       {k: clean(v) if isinstance(v, str) else v for k, v in m.items()},
                       p.run.h_reference_s, p.run.a2_reference, p.run.defaults_used,
                       [np.asarray(x).tolist() if hasattr(x, "shape") else x for x in leaves]))
    return plants, [(s["name"], s["bus"], clean(s["reason"])) for s in fleet.skipped]


@needs_wecc
@pytest.mark.skipif(not (SHARED / "naspi_osl_2021").exists(), reason="shared NASPI data absent")
def test_fleet_on_the_converted_wecc240_has_the_same_plants(tmp_path):
    from jaxdse._app.fleet_file import load_fleet

    original = _fleet_view(load_fleet(OSL), OSL)
    assert len(original[0]) == 22
    fleet_text = OSL.read_text().replace('"../../../shared/', f'"{SHARED.parent}/')
    for revision in (34, 35):
        raw = tmp_path / f"wecc240_rev{revision}.raw"
        raw.write_text(write_revision(WECC, revision), encoding="latin-1")
        toml = tmp_path / f"fleet{revision}.toml"
        toml.write_text(fleet_text.replace(f'"{SHARED.parent}/data/wecc240/{WECC.name}"', f'"{raw}"'))
        fleet = load_fleet(toml)
        assert Path(fleet.raw.source) == raw and fleet.raw.revision == revision
        assert _fleet_view(fleet, toml) == original


# --- hand-made revision 34, 35 and 36 cases --------------------------------------------------

RAW35 = """
@!IC,SBASE,REV,XFRRAT,NXFRAT,BASFRQ
0,   100.00, 35,     0,     1, 50.00     / PSS(R)E-35.3    HAND-MADE
TITLE, WITH A COMMA / AND A SLASH
@! a comment between the title lines
SECOND TITLE
GENERAL, THRSHZ=0.0001, PQBRAK=0.7, BLOWUP=5.0
@! a comment in the system-wide data
RATING, 1, "RATE1 ", "SET 1, NORMAL / SUMMER"
0 / END OF SYSTEM-WIDE DATA, BEGIN BUS DATA
@!   I,'NAME        ', BASKV, IDE,AREA,ZONE,OWNER, VM,        VA,    NVHI,   NVLO,   EVHI,   EVLO
     1,'HV, BUS/1   ', 400.0000,3,   1,   1,   1,1.02000,   0.0000,1.10000,0.90000,1.10000,0.90000
     2,'GEN BUS     ',  21.0000,2,   1,   1,   1,1.01000,   5.0000,1.10000,0.90000,1.10000,0.90000
0 / END OF BUS DATA, BEGIN LOAD DATA
     1,'1 ',   1,   1,   1,   300.000,   100.000,     0.000,     0.000,     0.000,     0.000,   1,    1,  0,    10.000,     2.000,    1,'IND, A/B    '
0 / END OF LOAD DATA, BEGIN FIXED SHUNT DATA
     1,'1 ',1,     0.000,   -40.000
0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA
     2,'G1',   800.000,   100.000,   400.000,  -300.000,1.01000,     2,   7,  1000.000, 2.00000E-3, 3.00000E-1, 0.00000E+0, 0.00000E+0,1.00000,1,  100.0,   950.000,     0.000, 1,   1,1.0000,   0,1.0000,   0,1.0000,   0,1.0000,0, 1.0000
0 / END OF GENERATOR DATA, BEGIN BRANCH DATA
     1,     2,'1 ', 1.00000E-3, 1.00000E-2,   0.01000,'LINE 1-2, "A"/B                         ', 100.00,  110.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00, 0.00000, 0.00000, 0.00000, 0.00000,0,1,  0.00,   1,1.0000
0 / END OF BRANCH DATA, BEGIN SYSTEM SWITCHING DEVICE DATA
   1,     2,'*1', 1.00000E-4,1206.00,1106.00,1006.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,   0.00,    1,    1,    2,    3,'BREAKER, 1/2'
0 / END OF SYSTEM SWITCHING DEVICE DATA, BEGIN TRANSFORMER DATA
     1,     2,     0,'1 ', 1, 2, 1, 1.00000E-3,-4.00000E-3,2,'GSU1                                    ',1,   1,1.0000,   0,1.0000,   0,1.0000,   0,1.0000,'YNd1        ', 0
 2.00000E-3, 1.50000E-1,  1000.00
@! a comment inside a transformer record
1.02500, 400.000,   0.000, 1000.00, 1100.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00,    0.00, 0,      0,   4,1.10000,0.90000,1.10000,0.90000,  33, 0,0.00000,0.00000, 0.000
1.00000,  21.000
0 / END OF TRANSFORMER DATA, BEGIN AREA DATA
   1,     0,    0.000,   10.000,'AREA 1, A/B '
0 / END OF AREA DATA, BEGIN TWO-TERMINAL DC DATA
0 / END OF TWO-TERMINAL DC DATA, BEGIN VSC DC LINE DATA
0 / END OF VSC DC LINE DATA, BEGIN IMPEDANCE CORRECTION DATA
 1, -30.00,1.10000,0.00000,   0.00,1.00000,0.00000
      30.00,1.11000,0.00000,   0.00,0.00000,0.00000
0 / END OF IMPEDANCE CORRECTION DATA, BEGIN MULTI-TERMINAL DC DATA
0 / END OF MULTI-TERMINAL DC DATA, BEGIN MULTI-SECTION LINE DATA
0 / END OF MULTI-SECTION LINE DATA, BEGIN ZONE DATA
0 / END OF ZONE DATA, BEGIN INTER-AREA TRANSFER DATA
0 / END OF INTER-AREA TRANSFER DATA, BEGIN OWNER DATA
0 / END OF OWNER DATA, BEGIN FACTS DEVICE DATA
0 / END OF FACTS DEVICE DATA, BEGIN SWITCHED SHUNT DATA
     2,'SH',   1,  0,  1,1.04500,0.95500,     1,   0, 100.0,'            ',-115.00, 1, 1, -15.00, 0, 2,  -5.00
0 / END OF SWITCHED SHUNT DATA, BEGIN GNE DATA
0 / END OF GNE DATA, BEGIN INDUCTION MACHINE DATA
0 / END OF INDUCTION MACHINE DATA, BEGIN SUBSTATION DATA
   1,'SUB 1', 40.0, -100.0, 0
@! substation node data
   1,'NODE 1', 1, 1
0 / END OF SUBSTATION NODE DATA, BEGIN SUBSTATION SWITCHING DEVICE DATA
0 / END OF SUBSTATION SWITCHING DEVICE DATA, BEGIN SUBSTATION EQUIPMENT TERMINAL DATA
0 / END OF SUBSTATION EQUIPMENT TERMINAL DATA
0 / END OF SUBSTATION DATA
Q
"""


def test_hand_made_revision_35(tmp_path):
    r = psse.read_raw(write(tmp_path, "r35.raw", RAW35))
    assert (r.revision, r.basfrq_hz, r.title) == (35, 50.0, ("TITLE, WITH A COMMA / AND A SLASH", "SECOND TITLE"))
    assert r.system_wide == {"GENERAL": [["THRSHZ=0.0001", "PQBRAK=0.7", "BLOWUP=5.0"]],
                             "RATING": [["1", "RATE1", "SET 1, NORMAL / SUMMER"]]}
    assert r.buses[1].name == "HV, BUS/1" and r.buses[2].va_deg == 5.0
    ld = r.loads[0]
    assert (ld.pl_mw, ld.dgen_p_mw, ld.dgen_q_mvar, ld.dgen_on, ld.load_type) == (300.0, 10.0, 2.0, 1, "IND, A/B")
    g = r.generator(2, "G1")
    assert (g.ireg, g.nreg, g.mbase_mva, g.zx_pu, g.pt_mw, g.baslod, g.line) == (2, 7, 1000.0, 0.3, 950.0, 1, 18)
    b = r.branches[0]
    assert (b.name, b.ratings_mva, b.status) == ('LINE 1-2, "A"/B', (100.0, 110.0), 0)
    t = r.transformers[0]
    assert (t.cz, t.vecgrp, t.zcod, t.nod1, t.rma1, t.ntp1, t.windv2, t.nomv2_kv, t.ratings1_mva) == \
        (2, "YNd1", 0, 4, 1.1, 33, 1.0, 21.0, (1000.0, 1100.0))
    assert r.step_up_transformer(2) is t
    s = r.switched_shunts[0]
    assert (s.id, s.swreg, s.binit_mvar, s.blocks) == ("SH", 1, -115.0, ((1, 1, -15.0), (0, 2, -5.0)))
    assert r.n_switching_devices == 1 and r.section_records["substation"] == 2
    why = "read past (node-breaker detail; jaxdse uses the bus-branch view)"
    assert r.notes == [f"{tmp_path / 'r35.raw'}, row 47: 2 substation record(s) {why}",
                       f"{tmp_path / 'r35.raw'}, row 22: 1 system switching device record(s) {why}"]
    assert r.problems == [] and psse.read_raw(tmp_path / "r35.raw", strict=False).problems == r.notes


def _rev34(text):
    """RAW35 in revision 34: generator NREG at the end and no BASLOD, no LOADTYPE, winding NOD1
    at the end, switched shunts without ID, block status and SWREG/NREG (NREG at the end)."""
    out = []
    for line in textwrap.dedent(text).lstrip("\n").splitlines():
        f = split(line)
        if line.startswith("0,"):
            line = line.replace(" 35,", " 34,")
        elif line.startswith("     2,'G1'"):
            f = [*f[:8], *f[9:19], *f[20:], f[8]]           # NREG to the end, no BASLOD
            line = ",".join(f)
        elif line.startswith("     1,'1 ',   1,"):
            line = ",".join(f[:-1])                           # no LOADTYPE
        elif line.startswith("1.02500"):
            line = ",".join([*f[:17], *f[18:], f[17]])        # NOD1 to the end
        elif line.startswith("     2,'SH'"):
            blocks = [x for k, x in enumerate(f[12:]) if k % 3]
            line = ",".join([f[0], *f[2:7], f[7], *f[9:12], *blocks, f[8]])
        out.append(line)
    return "\n".join(out) + "\n"


def test_hand_made_revision_34(tmp_path):
    r35 = psse.read_raw(write(tmp_path, "r35.raw", RAW35))
    r = psse.read_raw(write(tmp_path, "r34.raw", _rev34(RAW35)))
    assert r.revision == 34
    assert _plain(r.generators) == [dataclasses.replace(g, baslod=0) for g in _plain(r35.generators)]
    assert _plain(r.transformers) == _plain(r35.transformers)
    assert _plain(r.branches) == _plain(r35.branches) and _plain(r.buses.values()) == _plain(r35.buses.values())
    assert _plain(r.loads) == [dataclasses.replace(ld, load_type="") for ld in _plain(r35.loads)]
    s = r.switched_shunts[0]
    assert (s.id, s.swreg, s.nreg, s.blocks) == ("1", 1, 0, ((1, 1, -15.0), (1, 2, -5.0)))


def _rev36(text, *, droop="", rating_sets=""):
    """RAW35 in revision 36: the voltage droop control and switching device rating set sections."""
    text = textwrap.dedent(text).lstrip("\n").replace(" 35,     0,", " 36,     0,")
    text = text.replace("0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA",
                        "0 / END OF FIXED SHUNT DATA, BEGIN VOLTAGE DROOP CONTROL DATA\n" + droop
                        + "0 / END OF VOLTAGE DROOP CONTROL DATA, BEGIN GENERATOR DATA")
    return text.replace("0 / END OF GENERATOR DATA, BEGIN BRANCH DATA",
                        "0 / END OF GENERATOR DATA, BEGIN SWITCHING DEVICE RATING SET DATA\n" + rating_sets
                        + "0 / END OF SWITCHING DEVICE RATING SET DATA, BEGIN BRANCH DATA")


def test_revision_36_as_far_as_documented(tmp_path):
    r35 = psse.read_raw(write(tmp_path, "r35.raw", RAW35))
    r = psse.read_raw(write(tmp_path, "r36.raw", _rev36(RAW35, droop="   2,'G1', 1, 2, 0.05, 1.1, 0.9\n",
                                                        rating_sets="   1,'SET 1', 100.0\n")))
    assert r.revision == 36
    assert _plain(r.generators) == _plain(r35.generators) and _plain(r.transformers) == _plain(r35.transformers)
    assert _plain(r.branches) == _plain(r35.branches) and _plain(r.switched_shunts) == _plain(r35.switched_shunts)
    assert any("1 voltage droop control record(s) read past (not used by jaxdse)" in n for n in r.notes)
    assert any("1 switching device rating set record(s) read past" in n for n in r.notes)
    # a field revision 36 adds where jaxdse cannot check its place: refused, named
    named = _rev36(RAW35).replace("'IND, A/B    '", "'IND, A/B    ','LOAD NAME'")
    with pytest.raises(jd.InputError, match=r"r36n.raw, row 14: load record: field 19 \('LOAD NAME'\) after "
                                            r"LOADTYPE is not in the revision 36 layout jaxdse knows \(I, ID, "
                                            r".*\); revision 36 adds fields whose place is not documented"):
        psse.read_raw(write(tmp_path, "r36n.raw", named))
    # the same extra field in revision 35 is an ignored trailing field, as before
    assert len(psse.read_raw(write(tmp_path, "r35n.raw", RAW35.replace(
        "'IND, A/B    '", "'IND, A/B    ','LOAD NAME'"))).loads) == 1
    # a revision-35 layout labelled 36 (no droop section): the '0' records' comments tell
    wrong = textwrap.dedent(RAW35).lstrip("\n").replace(" 35,     0,", " 36,     0,")
    with pytest.raises(jd.InputError, match=r"r36w.raw, row 19: the '0' record closing the voltage droop control data says "
                                            r"it ends the generator data"):
        psse.read_raw(write(tmp_path, "r36w.raw", wrong))


def test_system_wide_data_missing_or_unclosed(tmp_path):
    text = textwrap.dedent(RAW35).lstrip("\n")
    no_section = re.sub(r"GENERAL.*?0 / END OF SYSTEM-WIDE DATA, BEGIN BUS DATA\n", "", text, flags=re.S)
    r = psse.read_raw(write(tmp_path, "nosw.raw", no_section))      # a writer that leaves it out
    assert r.system_wide == {} and len(r.buses) == 2 and len(r.generators) == 1
    unclosed = text.replace("0 / END OF SYSTEM-WIDE DATA, BEGIN BUS DATA\n", "")
    with pytest.raises(jd.InputError, match=r"unclosed.raw, row 10: system-wide data: record \(1, 'HV, BUS/1   ', "
                                            r"400.0000, ...\) starts with a number, not a record name .*: the "
                                            r"'0 / END OF SYSTEM-WIDE DATA' record is missing$"):
        psse.read_raw(write(tmp_path, "unclosed.raw", unclosed))


def test_missing_terminators_and_truncation(tmp_path):
    text = textwrap.dedent(RAW35).lstrip("\n")
    no_fixed_end = text.replace("0 / END OF FIXED SHUNT DATA, BEGIN GENERATOR DATA\n", "")
    with pytest.raises(jd.InputError, match=r"a.raw, row 18: the '0' record closing the fixed shunt data says it "
                                            r"ends the generator data: a section's '0' record is missing"):
        psse.read_raw(write(tmp_path, "a.raw", no_fixed_end))
    cut = "\n".join(text.splitlines()[:18]) + "\n"
    with pytest.raises(jd.InputError, match=r"cut.raw, row 18: the generator data section is not closed by a "
                                            r"'0' record before the end of the data \(the end of the file\)$"):
        psse.read_raw(write(tmp_path, "cut.raw", cut))
    shunt_cut = text[:text.index("0 / END OF SWITCHED SHUNT DATA")]
    with pytest.raises(jd.InputError, match=r"the switched shunt data section is not closed by a '0' record "
                                            r"before the end of the file \(and no Q ends the data\)$"):
        psse.read_raw(write(tmp_path, "sc.raw", shunt_cut))
    # Q ends the data: the sections after it are empty
    q = text[:text.index("0 / END OF AREA DATA")] + "Q\n"
    assert len(psse.read_raw(write(tmp_path, "q.raw", q)).switched_shunts) == 0
    # an unclosed quote in a section read past is read past; in one read, refused
    past = text.replace("'AREA 1, A/B '", "'AREA 1, A/B ")
    assert len(psse.read_raw(write(tmp_path, "p.raw", past)).switched_shunts) == 1
    with pytest.raises(jd.InputError, match=r"row 12: bus data: unclosed quote '$"):
        psse.read_raw(write(tmp_path, "b.raw", text.replace("'GEN BUS     '", "'GEN BUS     ")))
