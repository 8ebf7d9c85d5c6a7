"""PSS/E power-flow data (.raw) reader for jaxdse: revisions 32, 33, 34, 35 and 36.

Format (Siemens PTI, *PSS(R)E Program Operation Manual*, "Power flow raw data file"): the case
identification (IC, SBASE, REV, XFRRAT, NXFRAT, BASFRQ / comment) and two title lines; from
revision 34 a system-wide data section (GENERAL, GAUSS, NEWTON, ADJUST, TYSL, SOLVER, RATING
records, quoted strings; read past); then the data sections, each closed by a record ``0``
(``0 / END OF BUS DATA, BEGIN LOAD DATA``); ``Q`` ends the data. ``@!`` lines (the column
headers PSS/E 34 and later write before each section) are comments anywhere. Fields are
separated by commas (or blanks on a line without a comma), strings are in single or double
quotes and may hold commas and slashes, ``/`` outside quotes ends a line's data.

Read here: buses, loads, fixed shunts, generators, non-transformer branches, two-winding
transformers (three-winding ones are skipped and counted) and switched shunts; the system
switching devices (revision 34 on) and the substation data (node-breaker view) are counted and
read past, with a note: jaxdse uses the bus-branch view. Each record is read by field name
through the layout of its revision (:mod:`.psse_raw_layouts`, where each revision's
differences are listed); trailing fields may be omitted (PSS/E defaults), extra trailing
fields are ignored up to revision 35 and refused in revision 36 (its additions are not
documented where jaxdse can check them). The ``0`` record's comment, when it names the section
it closes, is checked against the revision's section list where both are sections jaxdse
parses, so that a missing ``0`` record there is reported where it is missing instead of
shifting every later record into the wrong section (elsewhere comments are not checked: PSS/E
reads by position, and some writers label the later sections one off).

Every error is an :class:`InputError`: one line naming the file, the line (``row``) and the
record. With ``strict=False`` (``jaxdse fleet``) a bus, generator or shunt record with an
unreadable field is kept with its ``problem`` (NaN in that field) or dropped when it cannot be
told apart, a bus defined twice keeps its first record; each is listed in
:attr:`RawCase.problems`, with the notes on what was read past.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from .errors import InputError
from .psse_common import is_comment, parse_number
from .psse_common import unquote as _unquote
from .psse_raw_layouts import (
    CHECKED,
    NODE_BREAKER,
    OPEN_ENDED,
    READ,
    REQUIRED,
    SECTIONS,
    SUPPORTED_RAW_REVISIONS,
    layout,
    section_named,
    transformer_layouts,
)

# --- records ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class RawBus:
    number: int
    name: str
    base_kv: float
    ide: int
    """Bus type: 1 load, 2 generator, 3 swing, 4 isolated."""
    area: int
    zone: int
    vm_pu: float
    va_deg: float
    line: int
    problem: str | None = field(default=None, repr=False)
    """Why the record cannot be used (``read_raw(..., strict=False)`` only; NaN fields)."""


@dataclass(frozen=True)
class RawLoad:
    bus: int
    id: str
    status: int
    area: int
    zone: int
    pl_mw: float
    """Constant-power active load [MW]."""
    ql_mvar: float
    """Constant-power reactive load [Mvar]."""
    ip_mw: float
    """Constant-current active load [MW at 1 pu voltage]."""
    iq_mvar: float
    """Constant-current reactive load [Mvar at 1 pu voltage]."""
    yp_mw: float
    """Constant-admittance active load [MW at 1 pu voltage]."""
    yq_mvar: float
    """Constant-admittance reactive load [Mvar at 1 pu voltage; PSS/E: < 0 inductive]."""
    line: int
    dgen_p_mw: float = 0.0
    """Distributed generation at the load, DGENP [MW] (revision 34 on)."""
    dgen_q_mvar: float = 0.0
    """DGENQ [Mvar] (revision 34 on)."""
    dgen_on: int = 0
    """DGENF, distributed generation on (1) or off (0) (revision 34 on)."""
    load_type: str = ""
    """LOADTYPE (revision 35 on)."""


@dataclass(frozen=True)
class RawFixedShunt:
    bus: int
    id: str
    status: int
    gl_mw: float
    """Active component [MW at 1 pu voltage]."""
    bl_mvar: float
    """Reactive component [Mvar at 1 pu voltage; > 0 capacitive]."""
    line: int


@dataclass(frozen=True)
class RawGenerator:
    """Generator record (MW, Mvar; ZSORCE = ZR + j ZX in pu on MBASE)."""

    bus: int
    id: str
    pg_mw: float
    qg_mvar: float
    qt_mvar: float
    qb_mvar: float
    vs_pu: float
    ireg: int
    mbase_mva: float
    zr_pu: float
    zx_pu: float
    rt_pu: float
    xt_pu: float
    gtap: float
    stat: int
    rmpct: float
    pt_mw: float
    pb_mw: float
    line: int
    source: str = field(default="", repr=False)
    problem: str | None = field(default=None, repr=False)
    """Why the record cannot be used (``read_raw(..., strict=False)`` only; NaN fields)."""
    nreg: int = 0
    """Node of the regulated bus in its substation (revision 34 on; 0: none)."""
    baslod: int = 0
    """Base-load flag (revision 35 on)."""
    changes: tuple = field(default=(), repr=False)
    """The record's repairs by ``jaxdse check --repair`` (:class:`RawChange`), read back from
    the ``/ jaxdse repair: ...`` comment at the end of its line (:func:`raw_repair_comment`)."""


@dataclass(frozen=True)
class RawChange:
    """One field of a .raw record changed by ``jaxdse check --repair`` (e.g. a generator's
    MBASE below its own maximum output), carried by the record's end-of-line comment."""

    con: str
    """The field's PSS/E name ("MBASE")."""
    old: float
    new: float
    origin: str
    """Where the original record stands, e.g. "case.raw line 120"."""
    why: str


RAW_REPAIR_TAG = "jaxdse repair:"
_RAW_REPAIR = re.compile(r"jaxdse repair:\s*(?P<con>\S+) (?P<old>\S+) -> (?P<new>\S+) "
                         r"\((?P<origin>[^)]*)\):\s*(?P<why>.*?)\s*$")


def raw_repair_comment(c: RawChange) -> str:
    """The end-of-line comment (after the record's data) that carries ``c`` (read back by
    :func:`read_raw` onto :attr:`RawGenerator.changes`); no '/' inside, as PSS/E ends the data
    at the first one."""
    why = " ".join(c.why.split()).replace("/", " per ")
    return f" / {RAW_REPAIR_TAG} {c.con} {c.old:.7g} -> {c.new:.7g} ({c.origin}): {why}"


def _raw_changes(comment: str) -> tuple:
    m = _RAW_REPAIR.search(comment or "")
    if m is None:
        return ()
    try:
        old, new = float(m["old"]), float(m["new"])
    except ValueError:
        return ()
    return (RawChange(m["con"], old, new, m["origin"], m["why"]),)


@dataclass(frozen=True)
class RawBranch:
    i: int
    j: int
    ckt: str
    r_pu: float
    x_pu: float
    b_pu: float
    rate_a_mva: float
    """First rating: RATEA (revisions 32, 33) or RATE1 (34 on)."""
    status: int
    line: int
    name: str = ""
    """NAME (revision 34 on)."""
    ratings_mva: tuple = ()
    """The ratings given (RATEA-RATEC, or RATE1-RATE12 from revision 34), trailing zeros (no
    rating) left out."""


@dataclass(frozen=True)
class RawTransformer:
    """Two-winding transformer (four lines; K = 0). Codes CW, CZ, CM as in PSS/E."""

    i: int
    j: int
    ckt: str
    cw: int
    cz: int
    cm: int
    mag1: float
    mag2: float
    nmetr: int
    name: str
    stat: int
    r12: float
    x12: float
    sbase12_mva: float
    windv1: float
    nomv1_kv: float
    ang1_deg: float
    cod1: int
    cont1: int
    rma1: float
    rmi1: float
    vma1: float
    vmi1: float
    ntp1: int
    windv2: float
    nomv2_kv: float
    line: int
    source: str = field(default="", repr=False)
    vecgrp: str = ""
    """Vector group (revision 33 on)."""
    zcod: int = 0
    """ZCOD, impedance adjustment code (revision 34 on)."""
    nod1: int = 0
    """Node of CONT1's bus in its substation (revision 34 on)."""
    ratings1_mva: tuple = ()
    """Winding-1 ratings (RATA1-RATC1, or RATE1-1 to RATE1-12 from revision 34), trailing zeros
    left out."""


@dataclass(frozen=True)
class RawSwitchedShunt:
    """Switched shunt record (Mvar at 1 pu voltage, > 0 capacitive)."""

    bus: int
    id: str
    """ID (revision 35 on; "1" before)."""
    modsw: int
    adjm: int
    stat: int
    vswhi: float
    vswlo: float
    swreg: int
    """Regulated bus: SWREG (revision 35 on) or SWREM."""
    nreg: int
    rmpct: float
    rmidnt: str
    binit_mvar: float
    blocks: tuple
    """(status, steps, Mvar per step) of each block given; the status is 1 before revision 35."""
    line: int


@dataclass
class RawCase:
    """The sections of a .raw file that jaxdse needs."""

    source: str
    revision: int
    sbase_mva: float
    basfrq_hz: float
    ic: int
    title: tuple[str, str]
    buses: dict[int, RawBus]
    loads: list[RawLoad]
    generators: list[RawGenerator]
    branches: list[RawBranch]
    transformers: list[RawTransformer]
    """Two-winding transformers."""
    n_three_winding: int = 0
    """Three-winding transformers skipped (five lines each)."""
    problems: list[str] = field(default_factory=list)
    """Records dropped or not used, and what was read past (``read_raw(..., strict=False)``):
    one line each."""
    fixed_shunts: list[RawFixedShunt] = field(default_factory=list)
    switched_shunts: list[RawSwitchedShunt] = field(default_factory=list)
    system_wide: dict[str, list[list[str]]] = field(default_factory=dict)
    """System-wide data records (revision 34 on), read past: record name -> its records' fields
    after the name (``{"RATING": [["1", "RATE1", "RATING SET 1"], ...], ...}``)."""
    n_switching_devices: int = 0
    """System switching devices (revision 34 on), read past (node-breaker detail)."""
    section_records: dict[str, int] = field(default_factory=dict)
    """Records found in each section reached (a transformer counts its 4 or 5 lines)."""
    notes: list[str] = field(default_factory=list)
    """What was read past, one line each (node-breaker sections, revision-36 sections)."""

    def bus_kv(self, bus: int) -> float:
        """Base voltage [kV] of a bus; InputError for an unknown bus or a zero base."""
        b = self.buses.get(int(bus))
        if b is None:
            raise InputError(self.source, f"bus {bus} is not in the bus data")
        if b.problem is not None:
            raise InputError(self.source, f"bus {bus}: {b.problem}", row=b.line)
        if not (b.base_kv > 0 and math.isfinite(b.base_kv)):
            raise InputError(self.source, f"bus {bus} ({b.name}) has base voltage "
                                f"{b.base_kv} kV; it must be > 0", row=b.line)
        return b.base_kv

    def generator(self, bus: int, machine_id: str) -> RawGenerator:
        mid = str(machine_id).strip().upper()
        for g in self.generators:
            if g.bus == int(bus) and g.id.upper() == mid:
                return g
        raise InputError(self.source, f"no generator at bus {bus} with ID {machine_id!r}")

    def step_up_transformers(self, bus: int) -> list[RawTransformer]:
        """Two-winding transformers with one end at ``bus``, in file order."""
        return [t for t in self.transformers if int(bus) in (t.i, t.j)]

    def step_up_transformer(self, bus: int) -> RawTransformer | None:
        """The step-up transformer of a generator bus: the in-service two-winding transformer
        with one end at ``bus`` whose other end has the highest base voltage (file order
        breaks ties); None when there is none (the GSU may then be in the generator record's
        RT, XT, GTAP, or the unit is connected directly)."""
        found = [t for t in self.step_up_transformers(bus) if t.stat != 0]
        if not found:
            return None

        def other_kv(t):
            other = t.j if t.i == int(bus) else t.i
            b = self.buses.get(other)
            return b.base_kv if b is not None else -math.inf

        return max(found, key=other_kv)


# --- fields -------------------------------------------------------------------------------------

def _fields(text: str) -> tuple[list[str | None], str]:
    """(fields, comment) of one line: comma-separated fields (blank-separated when the line has
    no comma outside quotes), quotes kept, a '/' outside quotes ends the data and starts the
    comment. Blank fields are None. ValueError for a quote left open."""
    quote, cut = None, len(text)
    for k, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "/":
            cut = k
            break
    if quote:
        raise ValueError(f"unclosed quote {quote}")
    body = text[:cut]
    parts = _split_outside_quotes(body, "," if "," in _strip_quoted(body) else None)
    return [p.strip() or None for p in parts], text[cut + 1:]


def _raw_fields(text: str) -> list[str | None]:
    """The fields of one line (see :func:`_fields`)."""
    return _fields(text)[0]


def _strip_quoted(text: str) -> str:
    return re.sub(r"'[^']*'|\"[^\"]*\"", "", text)


def _split_outside_quotes(text: str, sep: str | None) -> list[str]:
    out, cur, quote = [], [], None
    for ch in text:
        if quote:
            cur.append(ch)
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
            cur.append(ch)
        elif (sep is None and ch in " \t") or ch == sep:
            if sep is not None or cur:
                out.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    if sep is not None or cur:
        out.append("".join(cur))
    return out


_REQUIRED = object()


class _Row:
    """Typed access by field name to one record (one line) read through its revision's layout,
    with PSS/E defaults and one-line errors."""

    def __init__(self, fields, names, source, line, what, lenient=False, revision=None):
        self.fields, self.names, self.source, self.line, self.what = fields, names, source, line, what
        self.lenient, self.problem = lenient, None
        if revision is not None and revision not in OPEN_ENDED:
            extra = [k for k in range(len(names), len(fields)) if fields[k] is not None]
            if extra:
                k = extra[0]
                after = f" after {names[-1]}" if names else ""
                raise InputError(source, f"{what}: field {k + 1} ({fields[k]}){after} is not in the "
                                 f"revision {revision} layout jaxdse knows ({', '.join(names)}); "
                                 "revision 36 adds fields whose place is not documented, so jaxdse "
                                 "refuses the record rather than guess", row=line)

    def _fail(self, message, fallback):
        """Raise the one-line error; leniently, note the first one and go on with ``fallback``."""
        err = InputError(self.source, f"{self.what}: {message}", row=self.line)
        if not self.lenient:
            raise err
        self.problem = self.problem or str(err)
        return fallback

    def _raw(self, name, default):
        k = self.names.index(name)
        tok = self.fields[k] if k < len(self.fields) else None
        if tok is None:
            if default is _REQUIRED:
                self._fail(f"field {k + 1} ({name}) is missing", None)
            return k, None
        return k, tok

    def has(self, name) -> bool:
        return name in self.names

    def num(self, name, default=_REQUIRED) -> float:
        k, tok = self._raw(name, default)
        if tok is None:
            return math.nan if default is _REQUIRED else default
        try:
            return parse_number(_unquote(tok))
        except ValueError:
            return self._fail(f"field {k + 1} ({name}) is not a number: {tok!r}", math.nan)

    def int(self, name, default=_REQUIRED) -> int:
        value = self.num(name, default)
        fallback = None if default is _REQUIRED else default
        if value is None or (self.lenient and not math.isfinite(value)):
            return fallback
        if not math.isfinite(value) or value != int(value):
            k = self.names.index(name)
            return self._fail(f"field {k + 1} ({name}) is not an integer: {value!r}", fallback)
        return int(value)

    def text(self, name, default=_REQUIRED) -> str:
        _, tok = self._raw(name, default)
        return default if tok is None else _unquote(tok)

    def ratings(self, names) -> tuple:
        """The ratings of ``names`` given, trailing zeros (no rating) left out."""
        values = [self.num(n, 0.0) for n in names if self.has(n)]
        while values and values[-1] == 0.0:
            values.pop()
        return tuple(values)


# --- sections -----------------------------------------------------------------------------------

def _is_q(stripped: str) -> bool:
    return stripped.upper().startswith("Q") and (len(stripped) == 1 or not stripped[1].isalnum())


def _is_zero_record(flds) -> bool:
    return bool(flds) and flds[0] == "0" and len([x for x in flds if x is not None]) == 1


def _starts_with_number(flds) -> bool:
    try:
        parse_number(flds[0] or "")
        return True
    except ValueError:
        return False


@dataclass
class _Sections:
    records: dict
    """Section -> [(line, fields)], for the sections read."""
    counts: dict
    """Section -> records found, for every section reached."""
    reached: int
    """Sections closed."""
    lines: dict
    """Section -> line of its first record."""
    comments: dict = field(default_factory=dict)
    """Line -> end-of-line comment, for the records whose comment carries a repair."""


def _read_sections(data, source: str, revision: int, title_line: int) -> _Sections:
    """Group the data lines by section (the revision's list), checking the ``0`` records."""
    names = SECTIONS[revision]
    records = {n: [] for n in names if n in READ}
    counts, first, comments = {}, {}, {}
    k, last_line, ended_by_q = 0, title_line, False
    if names[0] == "system-wide":
        # A revision-34+ writer may omit the system-wide section: a first record that starts
        # with a number (a bus) then opens the bus data.
        for _, text in data:
            if not text.strip():
                continue
            try:
                flds, _ = _fields(text)
            except ValueError:
                break
            if any(flds) and not _is_zero_record(flds) and _starts_with_number(flds):
                counts["system-wide"] = 0
                k = 1
            break
    for line, text in data:
        stripped = text.strip()
        if not stripped:
            continue
        last_line = line
        if _is_q(stripped):
            ended_by_q = True
            break
        name = names[k] if k < len(names) else None
        if name is None:
            continue
        if name == "substation":            # nests its own '0' records; runs to Q or the end
            try:
                flds, _ = _fields(text)
            except ValueError:
                flds = [stripped]
            if not _is_zero_record(flds):
                counts[name] = counts.get(name, 0) + 1
                first.setdefault(name, line)
            continue
        try:
            flds, comment = _fields(text)
        except ValueError as e:
            if name in READ:
                raise InputError(source, f"{_label(name)}: {e}", row=line) from None
            counts[name] = counts.get(name, 0) + 1      # read past: its records are not parsed
            first.setdefault(name, line)
            continue
        if not any(flds):
            continue
        if _is_zero_record(flds):
            said = section_named(comment)
            if said != name and {said, name} <= CHECKED:
                raise InputError(source, f"the '0' record closing the {name} data says it ends the "
                                 f"{said} data: a section's '0' record is missing or extra, or the "
                                 f"comment is wrong (revision {revision}: {', '.join(names)})", row=line)
            counts.setdefault(name, 0)
            k += 1
            continue
        if name == "system-wide" and _starts_with_number(flds):
            raise InputError(source, f"system-wide data: record {_brief(flds)} starts with a number, "
                             "not a record name (GENERAL, GAUSS, NEWTON, ADJUST, TYSL, SOLVER, "
                             "RATING): the '0 / END OF SYSTEM-WIDE DATA' record is missing", row=line)
        counts[name] = counts.get(name, 0) + 1
        first.setdefault(name, line)
        if name in READ:
            records[name].append((line, flds))
            if comment and RAW_REPAIR_TAG in comment:
                comments[line] = comment
    required_end = max(names.index(n) for n in REQUIRED)
    if k <= required_end:
        how = "Q" if ended_by_q else "the end of the file"
        raise InputError(source, f"the {names[k]} data section is not closed by a '0' record "
                         f"before the end of the data ({how})", row=last_line)
    if k < len(names) and names[k] in READ and counts.get(names[k]) and not ended_by_q:
        raise InputError(source, f"the {names[k]} data section is not closed by a '0' record "
                         "before the end of the file (and no Q ends the data)", row=last_line)
    return _Sections(records, counts, k, first, comments)


def _label(name: str) -> str:
    return f"{name} data"


def _brief(flds) -> str:
    shown = ", ".join(f for f in flds[:3] if f is not None)
    return f"({shown}{', ...' if len(flds) > 3 else ''})"


# --- the reader ---------------------------------------------------------------------------------

def read_raw(path, *, strict: bool = True) -> RawCase:
    """Read a PSS/E .raw file of revision 32, 33, 34, 35 or 36 (other revisions: InputError).

    BASFRQ defaults to 60 Hz when the case line omits it (or gives 0). With ``strict=False``
    a bus, generator or shunt record with an unreadable field is kept with its ``problem``
    (NaN in that field) or dropped, a bus defined twice keeps its first record; each is listed
    in :attr:`RawCase.problems`, as are the notes on what was read past.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file does not exist")
    source = str(path)
    with open(path, encoding="latin-1") as f:
        lines = [(k, t.rstrip("\r\n")) for k, t in enumerate(f, start=1) if not is_comment(t)]
    if len(lines) < 3:
        raise InputError(source, "case identification: the file ends before the case line and the "
                         "two title lines a PSS/E raw file starts with",
                         row=lines[-1][0] if lines else 1)
    case_no, case_text = lines[0]
    try:
        head = _raw_fields(case_text)
    except ValueError as e:
        raise InputError(source, f"case identification: {e}", row=case_no) from None
    case_names = ("IC", "SBASE", "REV", "XFRRAT", "NXFRAT", "BASFRQ")
    row = _Row(head, case_names, source, case_no, "case identification")
    ic = row.int("IC", 0)
    sbase = row.num("SBASE", 100.0)
    rev = row.int("REV", None)
    if rev is None:
        m = re.search(r"PSS(?:\(R\)|/|\(TM\))?E[- ]?(\d+)", case_text.upper())
        rev = int(m.group(1)) if m else None
    if rev not in SUPPORTED_RAW_REVISIONS:
        found = "no revision number" if rev is None else f"revision {rev}"
        supported = ", ".join(map(str, SUPPORTED_RAW_REVISIONS[:-1])) + f" and {SUPPORTED_RAW_REVISIONS[-1]}"
        raise InputError(source, f"case identification gives {found}; only PSS/E raw "
                            f"revisions {supported} are supported", row=case_no)
    if not sbase > 0:
        raise InputError(source, f"SBASE must be > 0, got {sbase}", row=case_no)
    basfrq = row.num("BASFRQ", 60.0) or 60.0
    title = (lines[1][1], lines[2][1])

    sec = _read_sections(lines[3:], source, rev, lines[2][0])
    lenient = not strict
    problems, notes = [], []

    def rows(name, what, lenient_=False):
        names = layout(name, rev)
        for line, flds in sec.records.get(name, []):
            yield line, _Row(flds, names, source, line, what, lenient=lenient_, revision=rev)

    system_wide = {}
    for line, flds in sec.records.get("system-wide", []):
        key = _unquote(flds[0] or "").upper()
        system_wide.setdefault(key, []).append([_unquote(x) for x in flds[1:] if x is not None])

    buses = {}
    for line, r in rows("bus", "bus record", lenient):
        b = RawBus(number=r.int("I"), name=r.text("NAME", ""), base_kv=r.num("BASKV", 0.0),
                   ide=r.int("IDE", 1), area=r.int("AREA", 1), zone=r.int("ZONE", 1),
                   vm_pu=r.num("VM", 1.0), va_deg=r.num("VA", 0.0), line=line, problem=r.problem)
        if b.number is None:
            problems.append(f"{r.problem} (record dropped)")
            continue
        if b.number in buses:
            err = InputError(source, f"bus {b.number} is defined twice (first at line "
                             f"{buses[b.number].line})", row=line)
            if strict:
                raise err
            problems.append(f"{err} (the first is used)")
            continue
        if b.problem:
            problems.append(b.problem)
        buses[b.number] = b

    loads = []
    for line, r in rows("load", "load record"):
        loads.append(RawLoad(
            bus=r.int("I"), id=r.text("ID", "1"), status=r.int("STAT", 1), area=r.int("AREA", 0),
            zone=r.int("ZONE", 0), pl_mw=r.num("PL", 0.0), ql_mvar=r.num("QL", 0.0),
            ip_mw=r.num("IP", 0.0), iq_mvar=r.num("IQ", 0.0), yp_mw=r.num("YP", 0.0),
            yq_mvar=r.num("YQ", 0.0), line=line,
            dgen_p_mw=r.num("DGENP", 0.0) if r.has("DGENP") else 0.0,
            dgen_q_mvar=r.num("DGENQ", 0.0) if r.has("DGENQ") else 0.0,
            dgen_on=r.int("DGENF", 0) if r.has("DGENF") else 0,
            load_type=r.text("LOADTYPE", "") if r.has("LOADTYPE") else ""))

    fixed_shunts = []
    for line, r in rows("fixed shunt", "fixed shunt record", lenient):
        s = RawFixedShunt(bus=r.int("I"), id=r.text("ID", "1"), status=r.int("STATUS", 1),
                          gl_mw=r.num("GL", 0.0), bl_mvar=r.num("BL", 0.0), line=line)
        if r.problem:
            problems.append(f"{r.problem} (record dropped)")
            continue
        fixed_shunts.append(s)

    generators = []
    for line, r in rows("generator", "generator record", lenient):
        g = RawGenerator(
            bus=r.int("I"), id=r.text("ID", "1"), pg_mw=r.num("PG", 0.0), qg_mvar=r.num("QG", 0.0),
            qt_mvar=r.num("QT", 9999.0), qb_mvar=r.num("QB", -9999.0), vs_pu=r.num("VS", 1.0),
            ireg=r.int("IREG", 0), mbase_mva=r.num("MBASE", sbase), zr_pu=r.num("ZR", 0.0),
            zx_pu=r.num("ZX", 1.0), rt_pu=r.num("RT", 0.0), xt_pu=r.num("XT", 0.0),
            gtap=r.num("GTAP", 1.0), stat=r.int("STAT", 1), rmpct=r.num("RMPCT", 100.0),
            pt_mw=r.num("PT", 9999.0), pb_mw=r.num("PB", -9999.0), line=line, source=source,
            nreg=r.int("NREG", 0) if r.has("NREG") else 0,
            baslod=r.int("BASLOD", 0) if r.has("BASLOD") else 0, problem=r.problem,
            changes=_raw_changes(sec.comments.get(line, "")))
        if g.bus is None:
            problems.append(f"{r.problem} (record dropped)")
            continue
        if g.problem:
            problems.append(g.problem)
        generators.append(g)

    branches = []
    first_rate, status = ("RATEA", "ST") if rev <= 33 else ("RATE1", "STAT")
    rate_names = ("RATEA", "RATEB", "RATEC") if rev <= 33 else tuple(f"RATE{k}" for k in range(1, 13))
    for line, r in rows("branch", "branch record"):
        branches.append(RawBranch(
            i=r.int("I"), j=abs(r.int("J")), ckt=r.text("CKT", "1"), r_pu=r.num("R", 0.0),
            x_pu=r.num("X"), b_pu=r.num("B", 0.0), rate_a_mva=r.num(first_rate, 0.0),
            status=r.int(status, 1), line=line, name=r.text("NAME", "") if r.has("NAME") else "",
            ratings_mva=r.ratings(rate_names)))

    transformers, n3 = _read_transformers(sec.records["transformer"], source, sbase, rev)

    switched_shunts = []
    for line, r in rows("switched shunt", "switched shunt record", lenient):
        s = _switched_shunt(r, line, rev)
        if r.problem:
            problems.append(f"{r.problem} (record dropped)")
            continue
        switched_shunts.append(s)

    n_switching = sec.counts.get("system switching device", 0)
    for name in (*sorted(NODE_BREAKER), "voltage droop control"):
        n = sec.counts.get(name, 0)
        if n:
            what = ("node-breaker detail; jaxdse uses the bus-branch view" if name in NODE_BREAKER
                    else "not used by jaxdse")
            notes.append(f"{source}, row {sec.lines[name]}: {n} {name} record(s) read past ({what})")
    if not strict:
        problems.extend(notes)
    return RawCase(source=source, revision=rev, sbase_mva=sbase, basfrq_hz=basfrq, ic=ic, title=title,
                   buses=buses, loads=loads, generators=generators, branches=branches,
                   transformers=transformers, n_three_winding=n3, problems=problems,
                   fixed_shunts=fixed_shunts, switched_shunts=switched_shunts,
                   system_wide=system_wide, n_switching_devices=n_switching,
                   section_records=dict(sec.counts), notes=notes)


def _switched_shunt(r: _Row, line: int, rev: int) -> RawSwitchedShunt:
    ident = r.text("ID", "1") if r.has("ID") else "1"
    swreg = r.int("SWREG", 0) if r.has("SWREG") else r.int("SWREM", 0)
    start = r.names.index("BINIT") + 1
    tail = r.fields[start:]
    while tail and tail[-1] is None:
        tail = tail[:-1]
    width = 3 if rev >= 35 else 2
    nreg = r.int("NREG", 0) if rev >= 35 else 0
    if rev == 34 and len(tail) % 2 == 1:           # NREG after the blocks in use
        nreg = _int_field(r, start + len(tail) - 1, "NREG")
        tail = tail[:-1]
    blocks = []
    for b in range(min(-(-len(tail) // width), 8)):
        names = r.names[start + width * b:start + width * (b + 1)]
        status = r.int(names[0], 1) if width == 3 else 1
        steps, mvar = r.int(names[-2], 0), r.num(names[-1], 0.0)
        if steps:
            blocks.append((status, steps, mvar))
    return RawSwitchedShunt(bus=r.int("I"), id=ident, modsw=r.int("MODSW", 1), adjm=r.int("ADJM", 0),
                            stat=r.int("ST", 1), vswhi=r.num("VSWHI", 1.0), vswlo=r.num("VSWLO", 1.0),
                            swreg=swreg, nreg=nreg, rmpct=r.num("RMPCT", 100.0),
                            rmidnt=r.text("RMIDNT", ""), binit_mvar=r.num("BINIT", 0.0),
                            blocks=tuple(blocks), line=line)


def _int_field(r: _Row, k: int, name: str) -> int:
    """Field ``k`` of ``r`` read as integer ``name`` (a field the layout places elsewhere)."""
    shifted = _Row(r.fields[k:k + 1], (name,), r.source, r.line, r.what, lenient=r.lenient)
    value = shifted.int(name, 0)
    r.problem = r.problem or shifted.problem
    return value


def _read_transformers(records, source, sbase, rev):
    out, n3, k = [], 0, 0
    while k < len(records):
        line, f1 = records[k]
        r1 = _Row(f1, layout("transformer line 1", rev), source, line, "transformer record line 1",
                  revision=rev)
        i, j, kk = r1.int("I"), abs(r1.int("J")), abs(r1.int("K", 0))
        n_lines = 4 if kk == 0 else 5
        if k + n_lines > len(records):
            raise InputError(source, f"transformer {i}-{j}{'-' + str(kk) if kk else ''} needs "
                                f"{n_lines} lines, the section ends after {len(records) - k}", row=line)
        names = transformer_layouts(rev, kk != 0)
        label = f"transformer {i}-{j}{'-' + str(kk) if kk else ''}"
        rs = [r1] + [_Row(f, names[m], source, ln, f"{label} line {m + 1}", revision=rev)
                     for m, (ln, f) in enumerate(records[k + 1:k + n_lines], start=1)]
        if kk != 0:
            n3 += 1
            k += 5
            continue
        r2, r3, r4 = rs[1:]
        rate_names = ("RATA1", "RATB1", "RATC1") if rev <= 33 else tuple(f"RATE1-{m}" for m in range(1, 13))
        out.append(RawTransformer(
            i=i, j=j, ckt=r1.text("CKT", "1"), cw=r1.int("CW", 1), cz=r1.int("CZ", 1),
            cm=r1.int("CM", 1), mag1=r1.num("MAG1", 0.0), mag2=r1.num("MAG2", 0.0),
            nmetr=r1.int("NMETR", 2), name=r1.text("NAME", ""), stat=r1.int("STAT", 1),
            r12=r2.num("R1-2", 0.0), x12=r2.num("X1-2"), sbase12_mva=r2.num("SBASE1-2", sbase),
            windv1=r3.num("WINDV1", 1.0), nomv1_kv=r3.num("NOMV1", 0.0), ang1_deg=r3.num("ANG1", 0.0),
            cod1=r3.int("COD1", 0), cont1=r3.int("CONT1", 0), rma1=r3.num("RMA1", 1.1),
            rmi1=r3.num("RMI1", 0.9), vma1=r3.num("VMA1", 1.1), vmi1=r3.num("VMI1", 0.9),
            ntp1=r3.int("NTP1", 33), windv2=r4.num("WINDV2", 1.0), nomv2_kv=r4.num("NOMV2", 0.0),
            line=line, source=source,
            vecgrp=r1.text("VECGRP", "") if r1.has("VECGRP") else "",
            zcod=r1.int("ZCOD", 0) if r1.has("ZCOD") else 0,
            nod1=r3.int("NOD1", 0) if r3.has("NOD1") else 0,
            ratings1_mva=r3.ratings(rate_names)))
        k += 4
    return out, n3


__all__ = [
    "RAW_REPAIR_TAG", "SUPPORTED_RAW_REVISIONS", "RawBranch", "RawBus", "RawCase", "RawChange",
    "RawFixedShunt", "RawGenerator", "RawLoad", "RawSwitchedShunt", "RawTransformer", "raw_repair_comment",
    "read_raw",
]
