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

from .._io.psse import GOVERNOR_FIELDS, MACHINE_FIELDS, DyrChange, DyrData, DyrRecord, record_label
from .._io.psse_common import is_comment
from .._io.psse_dyr import repair_comment, token_spans
from .._models.exciters import EXCITER_FIELDS, exciter_from_dyr

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
class Plan:
    """What ``--repair`` changes, and the data problems it leaves."""

    changes: tuple[Change, ...]
    not_repaired: tuple[dict, ...]
    """{"unit", "why"} of every data problem left as it is."""

    @property
    def units(self) -> list[str]:
        return list(dict.fromkeys(c.unit for c in self.changes))


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


def plan(doc: dict, dyr: DyrData, *, ke_zero: str = "psse") -> Plan:
    """The changes that let every repairable data problem of a check (``doc``, the check.json
    document of :func:`jaxdse._app.check.check_case` on ``dyr``) start at rest."""
    changes: list[Change] = []
    left: list[dict] = []
    for e in doc["units"]:
        if e["outcome"] != "data problem":
            continue
        limits = e.get("limits") or []
        if not limits:      # the check names the crossed limits, one reason each, then "hence: ..."
            left.append({"unit": e["name"], "why": "not a crossed limit: " + e["reasons"][0]})
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
    return Plan(tuple(changes), tuple(left))


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
    return [f"/ jaxdse check --repair: {len(p.changes)} constant(s) changed on {len(p.units)} unit(s); "
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


CSV_COLUMNS = ("unit", "bus", "id", "record", "file", "line", "con", "con_number", "old", "new",
               "signal", "value", "limit", "bound", "side", "why")


def changes_csv(p: Plan) -> str:
    """repairs.csv: one row per changed constant (:attr:`Change.row`)."""
    f = io.StringIO()
    w = csv.DictWriter(f, fieldnames=CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for c in p.changes:
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


__all__ = ["DIGITS", "MARGIN", "MIN_MARGIN_PU", "RULE", "Change", "Plan", "carried", "carried_lines",
           "changes_csv", "con_names", "header", "plan", "repaired_dyr"]
