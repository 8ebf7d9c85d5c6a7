"""The PSS/E .raw layouts jaxdse reads: the sections of each revision in file order, and the
field names of each record it reads, per revision, in the order PSS/E writes them.

One parser (:mod:`.psse_raw`) reads every revision through these tables: a field is read by
name, so what a revision inserted, moved or appended is here and nowhere else.

Sources: the record layouts of Siemens PTI's *PSS(R)E Program Operation Manual* ("Power Flow
Raw Data File Contents", one per revision) as PSS/E itself writes them in the ``@!`` column
headers of its files: PSS/E 34.0 (the public test files of jbarberia/PSSE34to33) and PSS/E 35.1
(``case25_v35_savnwb.raw`` of NREL-Sienna/PowerSystemsTestData; ``tests/io/test_psse_raw.py``
compares both with these tables); cross-checked against the field orders of public readers:
pypowsybl's psse-model (revisions 32, 33, 35), PowerSystems.jl's ``pti.jl`` (33, 35), GridCal's
raw devices, and the revision 33/34 comparison in PowerFlowData.jl's issue 66. Revision 36: the
section list of a PSS/E 36.2-style file in InterPSS's regression tests. No code of theirs is
used.

What changed, revision by revision, in the records read here:

* 33 over 32: bus + NVHI, NVLO, EVHI, EVLO; load + INTRPT; transformer line 1 + VECGRP.
* 34 over 33: a system-wide data section (GENERAL, GAUSS, NEWTON, ADJUST, TYSL, SOLVER, RATING
  records) between the case identification and the buses, read past; load + DGENP, DGENQ,
  DGENF; generator + NREG at the end; branch: NAME after B, twelve ratings RATE1-RATE12 for
  RATEA-RATEC (STAT then follows GI, BI, GJ, BJ); a system switching device section after the
  branches; transformer line 1 + ZCOD; winding lines: twelve ratings per winding, NODn at the
  end; switched shunt + NREG at the end; a substation (node-breaker) section last.
* 35 over 34: load + LOADTYPE; generator: NREG moved after IREG, BASLOD after PB; winding
  lines: NODn moved after CONTn; switched shunt: ID after I, SWREG and NREG for SWREM, a
  status Sn before each block's Nn, Bn.
* 36 over 35, as far as public documentation goes: two more sections, voltage droop control
  data (after the fixed shunts) and switching device rating set data (after the generators),
  read past; the records read here keep the revision-35 fields. Fields revision 36 adds to them
  (e.g. load and machine names) are not documented where jaxdse could check their place: a
  revision-36 record with more fields than listed here is refused with a line naming the
  field (:data:`OPEN_ENDED`), rather than read by a guessed layout.

Node-breaker data (system switching devices, substations) and the other sections are read
past: jaxdse uses the bus-branch view (buses, branches, two-winding transformers).
"""

from __future__ import annotations

import re

SUPPORTED_RAW_REVISIONS = (32, 33, 34, 35, 36)

# --- sections, in file order --------------------------------------------------------------------

_TAIL = ("area", "two-terminal dc", "vsc dc line", "impedance correction", "multi-terminal dc",
         "multi-section line", "zone", "inter-area transfer", "owner", "facts device",
         "switched shunt", "gne device", "induction machine")
SECTIONS = {
    32: ("bus", "load", "fixed shunt", "generator", "branch", "transformer", *_TAIL),
    33: ("bus", "load", "fixed shunt", "generator", "branch", "transformer", *_TAIL),
    34: ("system-wide", "bus", "load", "fixed shunt", "generator", "branch",
         "system switching device", "transformer", *_TAIL, "substation"),
    35: ("system-wide", "bus", "load", "fixed shunt", "generator", "branch",
         "system switching device", "transformer", *_TAIL, "substation"),
    36: ("system-wide", "bus", "load", "fixed shunt", "voltage droop control", "generator",
         "switching device rating set", "branch", "system switching device", "transformer",
         *_TAIL, "substation"),
}
"""Sections of each revision. Each is closed by a record ``0`` (``0 / END OF ... DATA``); ``Q``
ends the data (the sections after it are empty). The substation section, last, nests its own
``0`` records and runs to ``Q`` or the end of the file."""
REQUIRED = ("bus", "load", "fixed shunt", "generator", "branch", "transformer")
"""Sections that must each be closed before the data end (the case jaxdse needs); a file may
end (with ``Q`` or not) anywhere after them."""
READ = frozenset({"system-wide", *REQUIRED, "system switching device", "switched shunt"})
"""Sections whose records are parsed; the others are counted and read past."""
NODE_BREAKER = frozenset({"system switching device", "substation", "switching device rating set"})
CHECKED = READ | {"voltage droop control", "switching device rating set"}
"""Sections whose ``0`` record's comment, when it names one of these, must name the section it
closes (a ``0`` record missing between two of them would shift records into the wrong one)."""

_ALIASES = {
    "system wide": "system-wide", "fixed bus shunt": "fixed shunt",
    "non transformer branch": "branch", "nontransformer branch": "branch",
    "switching device": "system switching device",
    "area interchange": "area", "two terminal dc line": "two-terminal dc",
    "two terminal dc": "two-terminal dc", "vsc dc": "vsc dc line",
    "voltage source converter": "vsc dc line", "voltage source converter dc line": "vsc dc line",
    "impedance correction table": "impedance correction",
    "transformer impedance correction": "impedance correction",
    "multi terminal dc line": "multi-terminal dc", "multi terminal dc": "multi-terminal dc",
    "multi section line": "multi-section line", "multi section line grouping": "multi-section line",
    "inter area transfer": "inter-area transfer", "interarea transfer": "inter-area transfer",
    "facts control device": "facts device", "facts": "facts device", "gne": "gne device",
}
_KNOWN = {s for names in SECTIONS.values() for s in names}
_END_OF = re.compile(r"\bEND\s+OF\s+(.+?)\s+DATA\b", re.IGNORECASE)


def section_named(comment: str) -> str | None:
    """The section a ``0`` record's comment says it closes (``END OF LOAD DATA, BEGIN ...`` ->
    "load"); None when the comment names none jaxdse knows."""
    m = _END_OF.search(comment or "")
    if not m:
        return None
    words = " ".join(m.group(1).replace("-", " ").lower().split())
    name = _ALIASES.get(words, words)
    return name if name in _KNOWN else None


# --- records ------------------------------------------------------------------------------------

def _rates(prefix: str = "RATE", suffix: str = "") -> tuple[str, ...]:
    return tuple(f"{prefix}{k}{suffix}" for k in range(1, 13))


_OWNERS = ("O1", "F1", "O2", "F2", "O3", "F3", "O4", "F4")

BUS_32 = ("I", "NAME", "BASKV", "IDE", "AREA", "ZONE", "OWNER", "VM", "VA")
BUS_33 = (*BUS_32, "NVHI", "NVLO", "EVHI", "EVLO")

LOAD_32 = ("I", "ID", "STAT", "AREA", "ZONE", "PL", "QL", "IP", "IQ", "YP", "YQ", "OWNER",
           "SCALE")
LOAD_33 = (*LOAD_32, "INTRPT")
LOAD_34 = (*LOAD_33, "DGENP", "DGENQ", "DGENF")
LOAD_35 = (*LOAD_34, "LOADTYPE")

FIXED_SHUNT = ("I", "ID", "STATUS", "GL", "BL")

GENERATOR_32 = ("I", "ID", "PG", "QG", "QT", "QB", "VS", "IREG", "MBASE", "ZR", "ZX", "RT", "XT",
                "GTAP", "STAT", "RMPCT", "PT", "PB", *_OWNERS, "WMOD", "WPF")
GENERATOR_34 = (*GENERATOR_32, "NREG")
GENERATOR_35 = ("I", "ID", "PG", "QG", "QT", "QB", "VS", "IREG", "NREG", "MBASE", "ZR", "ZX",
                "RT", "XT", "GTAP", "STAT", "RMPCT", "PT", "PB", "BASLOD", *_OWNERS, "WMOD",
                "WPF")

BRANCH_32 = ("I", "J", "CKT", "R", "X", "B", "RATEA", "RATEB", "RATEC", "GI", "BI", "GJ", "BJ",
             "ST", "MET", "LEN", *_OWNERS)
BRANCH_34 = ("I", "J", "CKT", "R", "X", "B", "NAME", *_rates(), "GI", "BI", "GJ", "BJ", "STAT",
             "MET", "LEN", *_OWNERS)

SWITCHING_DEVICE_34 = ("I", "J", "CKT", "X", *_rates(), "STAT", "NSTAT", "MET", "STYPE", "NAME")

TRANSFORMER1_32 = ("I", "J", "K", "CKT", "CW", "CZ", "CM", "MAG1", "MAG2", "NMETR", "NAME",
                   "STAT", *_OWNERS)
TRANSFORMER1_33 = (*TRANSFORMER1_32, "VECGRP")
TRANSFORMER1_34 = (*TRANSFORMER1_33, "ZCOD")
TRANSFORMER2_2W = ("R1-2", "X1-2", "SBASE1-2")
TRANSFORMER2_3W = ("R1-2", "X1-2", "SBASE1-2", "R2-3", "X2-3", "SBASE2-3", "R3-1", "X3-1",
                   "SBASE3-1", "VMSTAR", "ANSTAR")


def _winding(n: int, revision: int) -> tuple[str, ...]:
    """Line of winding ``n`` (1, 2, 3; line 3 onwards of a transformer record)."""
    head = (f"WINDV{n}", f"NOMV{n}", f"ANG{n}")
    control = tuple(f"{x}{n}" for x in ("RMA", "RMI", "VMA", "VMI", "NTP", "TAB", "CR", "CX",
                                        "CNXA"))
    if revision <= 33:
        return (*head, f"RATA{n}", f"RATB{n}", f"RATC{n}", f"COD{n}", f"CONT{n}", *control)
    rates = _rates(f"RATE{n}-")
    if revision == 34:
        return (*head, *rates, f"COD{n}", f"CONT{n}", *control, f"NOD{n}")
    return (*head, *rates, f"COD{n}", f"CONT{n}", f"NOD{n}", *control)


WINDING2_2W = ("WINDV2", "NOMV2")
"""Last line of a two-winding transformer: PSS/E writes only these two fields."""

_BLOCKS_NB = tuple(f"{x}{k}" for k in range(1, 9) for x in ("N", "B"))
_BLOCKS_SNB = tuple(f"{x}{k}" for k in range(1, 9) for x in ("S", "N", "B"))
SWITCHED_SHUNT_32 = ("I", "MODSW", "ADJM", "ST", "VSWHI", "VSWLO", "SWREM", "RMPCT", "RMIDNT",
                     "BINIT", *_BLOCKS_NB)
SWITCHED_SHUNT_34 = (*SWITCHED_SHUNT_32, "NREG")
"""Revision 34 appends NREG after the blocks in use (``N8, B8`` when all eight are)."""
SWITCHED_SHUNT_35 = ("I", "ID", "MODSW", "ADJM", "ST", "VSWHI", "VSWLO", "SWREG", "NREG",
                     "RMPCT", "RMIDNT", "BINIT", *_BLOCKS_SNB)

SYSTEM_WIDE_RECORDS = ("GENERAL", "GAUSS", "NEWTON", "ADJUST", "TYSL", "SOLVER", "RATING")
"""Records of the system-wide data section (revision 34 on), read past; any record starting
with a name is taken as one, a record starting with a number is an error (the section's ``0``
record is missing)."""


def _by_revision(r32, r33, r34, r35):
    return {32: r32, 33: r33, 34: r34, 35: r35, 36: r35}


LAYOUTS = {
    "bus": _by_revision(BUS_32, BUS_33, BUS_33, BUS_33),
    "load": _by_revision(LOAD_32, LOAD_33, LOAD_34, LOAD_35),
    "fixed shunt": _by_revision(FIXED_SHUNT, FIXED_SHUNT, FIXED_SHUNT, FIXED_SHUNT),
    "generator": _by_revision(GENERATOR_32, GENERATOR_32, GENERATOR_34, GENERATOR_35),
    "branch": _by_revision(BRANCH_32, BRANCH_32, BRANCH_34, BRANCH_34),
    "system switching device": _by_revision((), (), SWITCHING_DEVICE_34, SWITCHING_DEVICE_34),
    "transformer line 1": _by_revision(TRANSFORMER1_32, TRANSFORMER1_33, TRANSFORMER1_34,
                                       TRANSFORMER1_34),
    "switched shunt": _by_revision(SWITCHED_SHUNT_32, SWITCHED_SHUNT_32, SWITCHED_SHUNT_34,
                                   SWITCHED_SHUNT_35),
}
"""Record -> revision -> field names. Transformer lines 2 on: :func:`transformer_layouts`."""

OPEN_ENDED = frozenset({32, 33, 34, 35})
"""Revisions whose records may carry fields after those listed (ignored, as PSS/E's own later
revisions append fields); in revision 36 such a field is refused (see the module docstring)."""


def transformer_layouts(revision: int, three_winding: bool) -> tuple[tuple[str, ...], ...]:
    """The field names of each line of a transformer record (4 lines, or 5 with a third
    winding)."""
    line1 = LAYOUTS["transformer line 1"][revision]
    rev = 35 if revision == 36 else revision
    if three_winding:
        return (line1, TRANSFORMER2_3W, _winding(1, rev), _winding(2, rev), _winding(3, rev))
    # PSS/E writes R1-2, X1-2, SBASE1-2 and WINDV2, NOMV2 (TRANSFORMER2_2W, WINDING2_2W); some
    # writers fill the lines out: the fields after those are in the same places.
    return (line1, TRANSFORMER2_3W, _winding(1, rev), _winding(2, rev))


def layout(record: str, revision: int) -> tuple[str, ...]:
    """Field names of ``record`` ("bus", "load", ...) in ``revision``."""
    return LAYOUTS[record][revision]


__all__ = [
    "CHECKED", "LAYOUTS", "NODE_BREAKER", "OPEN_ENDED", "READ", "REQUIRED", "SECTIONS",
    "SUPPORTED_RAW_REVISIONS", "SYSTEM_WIDE_RECORDS", "layout", "section_named",
    "transformer_layouts",
]
