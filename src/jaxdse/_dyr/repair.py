"""Repairs of the limits that a unit's own power flow crosses (``jaxdse check --repair``).

``jaxdse check`` finds a unit whose initial operating point needs a signal of its exciter or
governor outside a limit of its record (:mod:`jaxdse._dyr.limits`: the signal, its value, the
limit and the CON that sets it). Such a unit cannot start at rest, so it gets no playback, no
validation, no calibration. PowerWorld moves such limits at initialisation and lists each
change; PSS/E warns and runs. This module makes the change a planner can file:

**The rule.** For each crossed limit that one constant of the record sets (its
:class:`~jaxdse._dyr.limits.Fix`: limit = scale·CON + offset at the unit's operating point), the
constant is moved, and only it, so that the signal lies :data:`MARGIN` (5 %) of its own
magnitude, at least :data:`MIN_MARGIN_PU` (0.01 pu), inside the limit; the new value is rounded
outward to :data:`DIGITS` (4) significant figures. E.g. HYGOV gate0 = 2.139 above GMAX = 1: GMAX
= 2.139 + 0.107 = 2.246 -> 2.247. Where two crossings move one constant, the farther wins.
Every other constant of every record is left as it is.

**A machine base below the unit's own power flow.** Where the generator's .raw record puts its
power-flow apparent power |PG + jQG| above 1.1 x its MBASE, or its lagging QG above 0.9 x MBASE
(the field-heating limit; :func:`~jaxdse._dyr.limits.rating_crossings`, the loadings at which
``jaxdse fleet`` refuses a recording), the records are per unit of a base below the machine's
rating (ACTIVSg2000's hydro units: PG = PT = 2.5 x MBASE, all its other units MBASE = 1.2 x PT):
TM0 = PG/MBASE runs the governor past its gate limit, and a recording of the unit, at 2.5 x its
stated rating, is refused by ``jaxdse fleet``. The repair is MBASE (the same rule: |S0| 5 %
inside MBASE, QG 5 % inside 0.9 x MBASE; the .raw's PT and the case's other generators' MBASE/PT
are quoted in the reason), written into a ``repaired.raw`` (the field replaced in
place, a ``/ jaxdse repair: ...`` comment at the end of the record's line); the records'
per-unit values are kept, read on the new base. The unit's exciter and governor limits are then
checked again at the new base (:func:`plan` lists it in :attr:`Plan.recheck`), and only what
they still cross there is repaired.

**The record's stated alternative.** A DC exciter (IEEEX1, IEEET1, EXDC2, ESDC1A, ESDC2A) with
VRMAX = 0 states its limits as computed (PSS/E: VRMAX = (SE(E2) + KE)·E2, VRMIN = -VRMAX).
Writing a VRMAX other than 0 ends that reading for both limits, so the other limit is written
out as the value the record stated (a change of its own in the table, the reason said).

**Not repaired** (listed with the reason, the unit stays a data problem): a unit with a data
problem other than a crossed limit (values refused by the model's checks, an unreadable
record, a machine that fails), and a crossing no constant sets (a DC exciter's or an
alternator's floor at 0).

The changes go into the .dyr as PSS/E comment lines (``/ jaxdse repair: ...``, read back by
:func:`jaxdse.read_dyr` onto :attr:`DyrRecord.changes`), one before the record per constant,
and the constant's token in the record is replaced in place: every other byte of the file is
kept. The functions here are pure: text in, text out.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from decimal import ROUND_CEILING, ROUND_FLOOR, Decimal
from pathlib import Path

import numpy as np

from .._io.psse import (
    GOVERNOR_FIELDS,
    MACHINE_FIELDS,
    DyrChange,
    DyrData,
    DyrRecord,
    RawCase,
    RawChange,
    RawGenerator,
    raw_repair_comment,
    record_label,
)
from .._io.psse_common import is_comment
from .._io.psse_dyr import repair_comment, token_spans
from .._io.psse_raw_layouts import layout
from .._models.exciters import EXCITER_FIELDS, exciter_from_dyr
from .limits import PT_UNSET_MW, rating_crossings

MARGIN = 0.05
"""The signal lies this fraction of its own magnitude inside the moved limit."""
MIN_MARGIN_PU = 0.01
"""... and at least this far [pu]."""
DIGITS = 4
"""The new value, rounded outward (away from the signal) to this many significant figures."""
RULE = (f"each crossed limit's constant moved so that the signal lies {100 * MARGIN:g} % of its value "
        f"(at least {MIN_MARGIN_PU:g} pu) inside it, rounded outward to {DIGITS} significant figures; "
        "nothing else changed")
DC_EXCITERS = frozenset({"IEEEX1", "IEEET1", "EXDC2", "ESDC1A", "ESDC2A"})
"""VRMAX = 0 in these records means: compute VRMAX and VRMIN (PSS/E)."""


@dataclass(frozen=True)
class Change:
    """One constant of one record, changed."""

    unit: str
    """The unit, "BUS_ID" as ``jaxdse check`` names it."""
    record: DyrRecord
    con: str
    """The constant's PSS/E name."""
    index: int
    """Its position among the record's constants (0 = the first after the machine ID)."""
    old: float
    new: float
    why: str
    signal: str = ""
    value: float = math.nan
    limit: str = ""
    bound: float = math.nan
    side: str = ""

    @property
    def origin(self) -> str:
        return f"{Path(self.record.source).name} line {self.record.line}"

    def as_dyr(self) -> DyrChange:
        r = self.record
        return DyrChange(model=r.model, bus=r.bus, id=r.id, con=self.con, old=self.old, new=self.new,
                         origin=self.origin, why=self.why)

    def row(self) -> dict:
        """The change as check.json and repairs.csv give it."""
        r = self.record
        return {"unit": self.unit, "bus": r.bus, "id": r.id, "record": r.model,
                "file": Path(r.source).name, "line": r.line, "con": self.con, "con_number": self.index + 1,
                "old": self.old, "new": self.new, "signal": self.signal, "value": self.value,
                "limit": self.limit, "bound": self.bound, "side": self.side, "why": self.why}


@dataclass(frozen=True)
class RawFieldChange:
    """One field of a generator's .raw record changed (MBASE)."""

    unit: str
    generator: RawGenerator
    con: str
    index: int
    """Its position in the record (0 = I, the bus)."""
    old: float
    new: float
    why: str
    signal: str = ""
    value: float = math.nan
    limit: str = ""
    bound: float = math.nan
    side: str = ""

    @property
    def origin(self) -> str:
        return f"{Path(self.generator.source).name} line {self.generator.line}"

    def as_raw(self) -> RawChange:
        return RawChange(self.con, self.old, self.new, self.origin, self.why)

    def row(self) -> dict:
        """The change as check.json and repairs.csv give it (record "generator")."""
        g = self.generator
        return {"unit": self.unit, "bus": g.bus, "id": g.id.strip(), "record": "generator",
                "file": Path(g.source).name, "line": g.line, "con": self.con, "con_number": self.index + 1,
                "old": self.old, "new": self.new, "signal": self.signal, "value": self.value,
                "limit": self.limit, "bound": self.bound, "side": self.side, "why": self.why}


@dataclass(frozen=True)
class Plan:
    """What ``--repair`` changes, and the data problems it leaves."""

    changes: tuple[Change, ...]
    not_repaired: tuple[dict, ...]
    """{"unit", "why"} of every data problem left as it is."""
    raw_changes: tuple[RawFieldChange, ...] = ()
    """Generators' MBASE changed (in repaired.raw)."""
    recheck: tuple[str, ...] = ()
    """Units whose MBASE changed: their other limits are to be checked again at the new base."""

    @property
    def units(self) -> list[str]:
        return list(dict.fromkeys([*(c.unit for c in self.raw_changes), *(c.unit for c in self.changes)]))

    def merged(self, other: "Plan") -> "Plan":
        """This plan with ``other``'s .dyr changes and leftovers of the units in
        :attr:`recheck` (``other``: the plan of their check at the new bases)."""
        mine = set(self.recheck)
        return Plan(self.changes + tuple(c for c in other.changes if c.unit in mine),
                    self.not_repaired + tuple(x for x in other.not_repaired if x["unit"] in mine),
                    self.raw_changes, self.recheck)


def con_names(record: DyrRecord) -> tuple[str, ...]:
    """The record's CON names in order ((): a model without a CON table here)."""
    for table in (EXCITER_FIELDS, GOVERNOR_FIELDS, MACHINE_FIELDS):
        if record.model in table:
            return table[record.model]
    return ()


def _g(x: float) -> str:
    return f"{x:.4g}"


def _outward(x: float, up: bool) -> float:
    """``x`` rounded to :data:`DIGITS` significant figures, up or down."""
    if x == 0 or not math.isfinite(x):
        return x
    d = Decimal(repr(x))
    q = Decimal(1).scaleb(d.adjusted() - DIGITS + 1)
    return float(d.quantize(q, rounding=ROUND_CEILING if up else ROUND_FLOOR))


def _moved(limit: dict) -> tuple[float, float] | None:
    """(the limit's new value, the CON's new value) that ``limit`` (a check.json crossing with
    its "fix") asks for, or None where no CON sets it or it cannot be inverted."""
    fix = limit.get("fix")
    if not fix:
        return None
    scale, offset, value = float(fix["scale"]), float(fix["offset"]), float(limit["value"])
    if not (math.isfinite(scale) and scale != 0 and math.isfinite(offset) and math.isfinite(value)):
        return None
    sign = 1.0 if limit["side"] == "above" else -1.0
    target = value + sign * max(MARGIN * abs(value), MIN_MARGIN_PU)
    con = (target - offset) / scale
    return target, _outward(con, up=(sign * scale) > 0)


def _base_change(e: dict, lims: list[dict], raw: RawCase | None) -> RawFieldChange | None:
    """The MBASE change of a unit whose power flow lies outside its MBASE's capability (the
    farther crossing), with the .raw's own evidence: PT against MBASE, and the case's other
    generators' MBASE/PT."""
    g = raw.generator(e["bus"], e["id"]) if raw is not None else None
    moves = [(lim, _moved(lim)) for lim in lims]
    moves = [(lim, m) for lim, m in moves if m is not None]
    if g is None or not moves:
        return None
    lim, (target, new) = max(moves, key=lambda x: x[1][1])
    pt = (f"; its PT = {_g(g.pt_mw)} MW is {g.pt_mw / g.mbase_mva:.3g} x MBASE"
          if 0 < g.pt_mw < PT_UNSET_MW and g.pt_mw > g.mbase_mva else "")
    others = [x.mbase_mva / x.pt_mw for x in raw.generators
              if x.stat == 1 and x is not g and 0 < x.pt_mw < PT_UNSET_MW and x.mbase_mva > 0
              and not rating_crossings(x.pg_mw, x.qg_mvar, x.mbase_mva)]
    usual = (f"; the case's other in-service generators have MBASE = {float(np.median(others)):.3g} x PT "
             "(median)" if others else "")
    fix = lim["fix"]
    why = (f"{lim['signal']} = {_g(lim['value'])} above {lim['con']} = {_g(lim['bound'])} "
           f"({lim['context']}); "
           f"MBASE at least {_g((target - float(fix['offset'])) / float(fix['scale']))} puts it "
           f"{100 * MARGIN:g} % inside{pt}{usual}; the records' per-unit values are kept, on the new base")
    names = layout("generator", raw.revision)
    return RawFieldChange(e["name"], g, "MBASE", names.index("MBASE"), float(g.mbase_mva), new, why,
                          lim["signal"], float(lim["value"]), lim["con"], float(lim["bound"]), lim["side"])


def plan(doc: dict, dyr: DyrData, *, ke_zero: str = "psse", raw: RawCase | None = None) -> Plan:
    """The changes that let every repairable data problem of a check (``doc``, the check.json
    document of :func:`jaxdse._app.check.check_case` on ``dyr`` and ``raw``) start at rest. A unit
    whose .raw data lie above its MBASE gets the MBASE change alone, and is named in
    :attr:`Plan.recheck`: its other limits are to be checked at the new base."""
    changes: list[Change] = []
    raw_changes: list[RawFieldChange] = []
    recheck: list[str] = []
    left: list[dict] = []
    for e in doc["units"]:
        if e["outcome"] != "data problem":
            continue
        limits = e.get("limits") or []
        if not limits:      # the check names the crossed limits, one reason each, then "hence: ..."
            left.append({"unit": e["name"], "why": "not a crossed limit: " + e["reasons"][0]})
            continue
        base = [lim for lim in limits if lim["record"] == "generator"]
        if base:
            c = _base_change(e, base, raw)
            if c is None:
                left.append({"unit": e["name"], "why": f"generator: {base[0]['signal']} above "
                             "MBASE: the .raw record is not at hand to change"})
            else:
                raw_changes.append(c)
                recheck.append(e["name"])
            continue
        mine: dict[tuple, Change] = {}
        fixed = True
        for lim in limits:
            rec = _record(dyr, e, lim)
            moved = _moved(lim)
            names = con_names(rec) if rec is not None else ()
            con = (lim.get("fix") or {}).get("con")
            if rec is None or moved is None or con not in names:
                left.append({"unit": e["name"], "why": f"{lim['record']}: {lim['signal']} "
                             f"{lim['side']} {lim['con']}: no constant of the record sets this limit"})
                fixed = False
                break
            target, new = moved
            k = names.index(con)
            old = float(rec.constants[k])
            why = (f"{lim['signal']} = {_g(lim['value'])} {lim['side']} {lim['con']} = {_g(lim['bound'])}; "
                   f"{lim['con']} {'at least' if lim['side'] == 'above' else 'at most'} {_g(target)} puts the "
                   f"signal {100 * MARGIN:g} % inside it")
            tm0 = (e.get("numbers") or {}).get("tm0_pu")
            if rec.model in GOVERNOR_FIELDS and tm0 is not None and tm0 > 1.0:
                why += (f" (TM0 = PG/MBASE = {_g(tm0)}: PG is {100 * tm0:.0f} % of MBASE; an MBASE in the "
                        ".raw below the unit's rating gives this too)")
            c = Change(e["name"], rec, con, k, old, new, why, lim["signal"], float(lim["value"]),
                       lim["con"], float(lim["bound"]), lim["side"])
            key = (id(rec), k)
            if key not in mine or abs(new - old) > abs(mine[key].new - old):
                mine[key] = c
        if fixed:
            changes.extend(_dc_stated(list(mine.values()), ke_zero))
    return Plan(tuple(changes), tuple(left), tuple(raw_changes), tuple(recheck))


def _record(dyr: DyrData, e: dict, lim: dict) -> DyrRecord | None:
    for r in dyr.unit_records(e["bus"], e["id"]):
        if r.model == lim["record"] and r.line == lim["line"]:
            return r
    return None


def _dc_stated(changes: list[Change], ke_zero: str) -> list[Change]:
    """``changes`` with the other limit of a DC exciter whose VRMAX = 0 stated its limits as
    computed: written out as the value the record stated."""
    out = list(changes)
    for c in changes:
        r = c.record
        if r.model not in DC_EXCITERS or ke_zero != "psse" or c.con not in ("VRMAX", "VRMIN"):
            continue
        names = con_names(r)
        kmax, kmin = names.index("VRMAX"), names.index("VRMIN")
        if float(r.constants[kmax]) != 0.0:
            continue
        other = "VRMIN" if c.con == "VRMAX" else "VRMAX"
        if any(o.record is r and o.con == other for o in out):
            continue
        ex = exciter_from_dyr(r.model, r.constants, ke_zero="psse")
        value = float(ex.vr_min_pu if other == "VRMIN" else ex.vr_max_pu)
        k = kmin if other == "VRMIN" else kmax
        out.append(Change(c.unit, r, other, k, float(r.constants[k]), value,
                          f"VRMAX = 0 in the record: its limits computed, VRMAX = {_g(float(ex.vr_max_pu))}, "
                          f"VRMIN = {_g(float(ex.vr_min_pu))}; with {c.con} written out, {other} is "
                          "written as the value the record stated"))
    return out


# --- the repaired file ----------------------------------------------------------------------------

def _num(x: float) -> str:
    return f"{x:.7g}"


def _record_lines(lines: list[str], record: DyrRecord) -> tuple[int, list[tuple[int, int, int]]]:
    """(index of the record's last line, [(line index, start, end) of each of its tokens])."""
    spans, k = [], record.line - 1
    while k < len(lines):
        if not is_comment(lines[k]):
            toks, ended = token_spans(lines[k])
            spans.extend((k, a, b) for a, b in toks)
            if ended:
                return k, spans
        k += 1
    return len(lines) - 1, spans


def _edited(lines: list[str], changes: list[Change]) -> None:
    """Replace, in ``lines`` (one file's), each changed constant's token by its new value."""
    edits: dict[int, list[tuple[int, int, str]]] = {}
    for c in changes:
        _, spans = _record_lines(lines, c.record)
        k, a, b = spans[3 + c.index]                     # bus, model, ID, then the constants
        edits.setdefault(k, []).append((a, b, _num(c.new)))
    for k, es in edits.items():
        text = lines[k]
        for a, b, new in sorted(es, reverse=True):
            text = text[:a] + new + text[b:]
        lines[k] = text


def _newline(lines: list[str]) -> str:
    return "\r\n" if lines and lines[0].endswith("\r\n") else "\n"


def _read(source: str) -> list[str]:
    with open(source, encoding="latin-1", newline="") as f:
        return f.read().splitlines(keepends=True)


def header(p: Plan, what: str) -> list[str]:
    """The comment lines that open a repaired file."""
    units = len(dict.fromkeys(c.unit for c in p.changes))
    base = (f" (and {len(p.raw_changes)} generator MBASE value(s) in repaired.raw)" if p.raw_changes else "")
    return [f"/ jaxdse check --repair: {len(p.changes)} constant(s) changed on {units} unit(s){base}; "
            f"{what}",
            f"/ rule: {RULE}; each change is the '/ jaxdse repair:' line before its record"]


def repaired_dyr(p: Plan, sources: list[str]) -> tuple[str, bool]:
    """(the repaired .dyr text, whether it is whole). One source file: the file itself with the
    changed constants replaced in place and a comment line per change before its record (a
    whole .dyr, in place of the original). Several: only the changed records (an overlay, read
    after the others: ``[case] dyr = [..., "repaired.dyr"]``)."""
    by_source: dict[str, list[Change]] = {}
    for c in p.changes:
        by_source.setdefault(c.record.source, []).append(c)
    if len(sources) == 1:
        lines = _read(sources[0])
        nl = _newline(lines)
        _edited(lines, by_source.get(sources[0], []))
        before: dict[int, list[str]] = {}
        for c in by_source.get(sources[0], []):
            before.setdefault(c.record.line - 1, []).append(repair_comment(c.as_dyr()) + nl)
        out = [h + nl for h in header(p, f"every other line as in {Path(sources[0]).name}")]
        for k, line in enumerate(lines):
            out.extend(before.get(k, []))
            out.append(line)
        return "".join(out), True
    out = [h + "\n" for h in header(p, "only the changed records: read after " + ", ".join(
        Path(s).name for s in sources))]
    for source, cs in by_source.items():
        lines = _read(source)
        _edited(lines, cs)
        for rec in {id(c.record): c.record for c in cs}.values():
            out.extend(repair_comment(c.as_dyr()) + "\n" for c in cs if c.record is rec)
            last, _ = _record_lines(lines, rec)
            out.extend(line.rstrip("\r\n") + "\n" for line in lines[rec.line - 1:last + 1])
    return "".join(out), False


def _raw_spans(text: str) -> list[tuple[int, int]]:
    """(start, end) of each field of a .raw data line: comma-separated (blank-separated when no
    comma stands outside quotes), quotes kept, the data ending at a '/' outside quotes."""
    quote, cut = None, len(text)
    for k, ch in enumerate(text):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "/":
            cut = k
            break
    body = text[:cut]
    commas = [k for k, ch in enumerate(body) if ch == "," and not _quoted(body, k)]
    if commas:
        bounds = [-1, *commas, len(body)]
        parts = [(bounds[i] + 1, bounds[i + 1]) for i in range(len(bounds) - 1)]
    else:
        parts, k = [], 0
        while k < len(body):
            if body[k].isspace():
                k += 1
                continue
            a = k
            q = body[k] if body[k] in "'\"" else None
            k += 1
            while k < len(body) and (q and body[k] != q or not q and not body[k].isspace()):
                k += 1
            k += 1 if q else 0
            parts.append((a, k))
    out = []
    for a, b in parts:      # each field's text without its blanks
        while a < b and body[a].isspace():
            a += 1
        while b > a and body[b - 1].isspace():
            b -= 1
        out.append((a, b))
    return out


def _quoted(text: str, at: int) -> bool:
    quote = None
    for ch in text[:at]:
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
    return quote is not None


def repaired_raw(p: Plan, source: str) -> str:
    """The repaired .raw text: ``source`` with each changed field replaced in place and the
    change as a comment at the end of the record's line (``/ jaxdse repair: MBASE ...``, read back
    onto :attr:`RawGenerator.changes`); every other byte kept."""
    lines = _read(source)
    for c in p.raw_changes:
        k = c.generator.line - 1
        text = lines[k]
        body = text.rstrip("\r\n")
        end = text[len(body):]
        a, b = _raw_spans(body)[c.index]
        body = body[:a] + _num(c.new) + body[b:]
        lines[k] = body + raw_repair_comment(c.as_raw()) + end
    return "".join(lines)


CSV_COLUMNS = ("unit", "bus", "id", "record", "file", "line", "con", "con_number", "old", "new",
               "signal", "value", "limit", "bound", "side", "why")


def changes_csv(p: Plan) -> str:
    """repairs.csv: one row per changed constant (:attr:`Change.row`)."""
    f = io.StringIO()
    w = csv.DictWriter(f, fieldnames=CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for c in (*p.raw_changes, *p.changes):
        w.writerow({k: (_num(v) if isinstance(v, float) and math.isfinite(v) else
                        "" if isinstance(v, float) else v) for k, v in c.row().items()})
    return f.getvalue()


# --- a repaired record, read back -------------------------------------------------------------------

def carried(record: DyrRecord) -> list[dict]:
    """The repairs a record carries (its file's ``/ jaxdse repair:`` lines), each with whether
    the record still holds the repaired value ("current": the value it holds now)."""
    names = con_names(record)
    out = []
    for c in record.changes:
        now = (float(record.constants[names.index(c.con)])
               if c.con in names and names.index(c.con) < len(record.constants)
               and isinstance(record.constants[names.index(c.con)], float) else math.nan)
        held = math.isfinite(now) and math.isclose(now, c.new, rel_tol=1e-6, abs_tol=1e-12)
        out.append({"record": record.model, "bus": record.bus, "id": record.id,
                    "file": Path(record.source).name, "line": record.line, "con": c.con,
                    "old": c.old, "new": c.new, "origin": c.origin, "why": c.why,
                    "current": now if math.isfinite(now) else None, "holds_new": held})
    return out


def carried_raw(g: RawGenerator) -> list[dict]:
    """The repairs a generator's .raw record carries (its line's ``/ jaxdse repair:`` comment),
    as :func:`carried` gives a record's."""
    out = []
    for c in g.changes:
        now = float(g.mbase_mva) if c.con == "MBASE" else math.nan
        held = math.isfinite(now) and math.isclose(now, c.new, rel_tol=1e-6, abs_tol=1e-12)
        out.append({"record": "generator", "bus": g.bus, "id": g.id.strip(), "file": Path(g.source).name,
                    "line": g.line, "con": c.con, "old": c.old, "new": c.new, "origin": c.origin,
                    "why": c.why, "current": now if math.isfinite(now) else None, "holds_new": held})
    return out


def carried_raw_lines(g: RawGenerator) -> list[str]:
    """One line per repair a generator's .raw record carries, for a unit's page."""
    out = []
    for c in carried_raw(g):
        stale = "" if c["holds_new"] else f" (the record now holds {c['current']}, not the repaired value)"
        out.append(f"generator on bus {g.bus} id {g.id.strip()!r} (.raw): {c['con']} {_num(c['old'])} -> "
                   f"{_num(c['new'])} by jaxdse check --repair (was {c['origin']}): {c['why']}{stale}")
    return out


def carried_lines(records) -> list[str]:
    """One line per repair that ``records`` carry, for a unit's page."""
    out = []
    for r in records:
        for c in carried(r):
            stale = ("" if c["holds_new"] else
                     f" (the record now holds {c['current'] if c['current'] is not None else 'no number'}, "
                     "not the repaired value)")
            out.append(f"{record_label(r)}: {c['con']} {_num(c['old'])} -> {_num(c['new'])} by jaxdse check "
                       f"--repair (was {c['origin']}): {c['why']}{stale}")
    return out


__all__ = ["DIGITS", "MARGIN", "MIN_MARGIN_PU", "RULE", "Change", "Plan", "RawFieldChange", "carried",
           "carried_lines", "carried_raw", "carried_raw_lines", "changes_csv", "con_names", "header", "plan",
           "repaired_dyr", "repaired_raw"]
