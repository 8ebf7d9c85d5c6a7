"""PSS/E dynamic data (.dyr) reader for jaxdse.

Format (Siemens PTI, *PSS(R)E Program Operation Manual*, "Dynamics data file"): records
``IBUS 'MODEL' ID con con ... /``, free format, any number of lines per record, fields
separated by blanks or commas, the model name and the machine ID quoted or not; the ``/`` ends a
record and the rest of that line is a comment; ``@!`` lines are comments, and so is a line
that starts with ``/`` (an empty record, which PSS/E skips, with its comment). Numbers may be
Fortran-style (``0.5E-01``, ``1.D-2``).

A repair written by ``jaxdse check --repair`` travels in the file as such comment lines, one
per changed constant, before the record (:func:`repair_comment`, e.g. ``/ jaxdse repair: GMAX
of HYGOV bus 3105 id '1': 1 -> 2.247 (ACTIVSg2000_dynamics.dyr line 204): gate0 = ...``): PSS/E
skips them, and this reader attaches each to the record of the same model, bus and machine ID
(:attr:`DyrRecord.changes`), wherever in the file it stands. One that names no record of the
file is listed in ``problems``.

Readers work at the edge (plain Python, never inside jit). Every user mistake raises
:class:`InputError`, a one-line message naming the file, the line (``row``) and the record.
With ``strict=False`` (``jaxdse fleet``) a malformed record that can still be told apart (its
bus and machine ID read) is kept with its ``problem`` (the one-line message strict reading
would raise), so that only the units it belongs to are left out; records that cannot be
attributed are dropped and listed in ``problems`` of the file.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

from .errors import InputError
from .psse_common import is_comment, parse_number
from .psse_common import unquote as _unquote

# --- .dyr model tables ------------------------------------------------------------------------
# PSS/E names of the constants in PSS/E order (ICONs first where a model has them).

MACHINE_FIELDS = {
    "GENCLS": ("H", "D"),
    "GENSAL": ("T'do", "T''do", "T''qo", "H", "D", "Xd", "Xq", "X'd", "X''d", "Xl",
               "S(1.0)", "S(1.2)"),
    "GENROU": ("T'do", "T''do", "T'qo", "T''qo", "H", "D", "Xd", "Xq", "X'd", "X'q", "X''d",
               "Xl", "S(1.0)", "S(1.2)"),
    "GENTPJ": ("T'do", "T''do", "T'qo", "T''qo", "H", "D", "Xd", "Xq", "X'd", "X'q", "X''d",
               "Xl", "S(1.0)", "S(1.2)", "Kis"),
    "GENROE": ("T'do", "T''do", "T'qo", "T''qo", "H", "D", "Xd", "Xq", "X'd", "X'q", "X''d",
               "Xl", "S(1.0)", "S(1.2)"),
    "GENSAE": ("T'do", "T''do", "T''qo", "H", "D", "Xd", "Xq", "X'd", "X''d", "Xl",
               "S(1.0)", "S(1.2)"),
}
GOVERNOR_FIELDS = {
    "TGOV1": ("R", "T1", "VMAX", "VMIN", "T2", "T3", "Dt"),
    "IEEEG1": ("JBUS", "M", "K", "T1", "T2", "T3", "Uo", "Uc", "PMAX", "PMIN", "T4", "K1", "K2",
               "T5", "K3", "K4", "T6", "K5", "K6", "T7", "K7", "K8"),
    "GAST": ("R", "T1", "T2", "T3", "AT", "KT", "VMAX", "VMIN", "DTURB"),
    "HYGOV": ("R", "r", "Tr", "Tf", "Tg", "VELM", "GMAX", "GMIN", "TW", "At", "Dturb", "qNL"),
    "GGOV1": ("Rselect", "Flag", "R", "Tpelec", "maxerr", "minerr", "Kpgov", "Kigov", "Kdgov",
              "Tdgov", "Vmax", "Vmin", "Tact", "Kturb", "Wfnl", "Tb", "Tc", "Teng", "Tfload",
              "Kpload", "Kiload", "Ldref", "Dm", "Ropen", "Rclose", "Kimw", "Aset", "Ka", "Ta",
              "Trate", "db", "Tsa", "Tsb", "Rup", "Rdown"),
    "IEESGO": ("T1", "T2", "T3", "T4", "T5", "T6", "K1", "K2", "K3", "PMAX", "PMIN"),
    "WSIEG1": ("JBUS", "M", "K", "T1", "T2", "T3", "Uo", "Uc", "PMAX", "PMIN", "T4", "K1", "K2",
               "T5", "K3", "K4", "T6", "K5", "K6", "T7", "K7", "K8", "DB1", "ERR", "DB2", "GV1",
               "PGV1", "GV2", "PGV2", "GV3", "PGV3", "GV4", "PGV4", "GV5", "PGV5", "IBLOCK"),
}
OPTIONAL_TRAILING = {"GENTPJ": 1}
"""Models whose last constants may be omitted (GENTPJ's Kis; default 0)."""
GOVERNOR_PARAMETERS = {
    "TGOV1": {"r_pu": "R", "t1_s": "T1", "v_max_pu": "VMAX", "v_min_pu": "VMIN", "t2_s": "T2",
        "t3_s": "T3", "dt_pu": "Dt"},
    "IEEEG1": {"k": "K", "t1_s": "T1", "t2_s": "T2", "t3_s": "T3", "uo_pu_s": "Uo",
        "uc_pu_s": "Uc", "p_max_pu": "PMAX", "p_min_pu": "PMIN", "t4_s": "T4", "k1": "K1",
        "k2": "K2", "t5_s": "T5", "k3": "K3", "k4": "K4", "t6_s": "T6", "k5": "K5", "k6": "K6",
        "t7_s": "T7", "k7": "K7", "k8": "K8"},
    "GAST": {"r_pu": "R", "t1_s": "T1", "t2_s": "T2", "t3_s": "T3", "at_pu": "AT", "kt_pu": "KT",
        "v_max_pu": "VMAX", "v_min_pu": "VMIN", "dturb_pu": "DTURB"},
    "HYGOV": {"r_pu": "R", "r_temp_pu": "r", "tr_s": "Tr", "tf_s": "Tf", "tg_s": "Tg",
        "velm_pu_s": "VELM", "g_max_pu": "GMAX", "g_min_pu": "GMIN", "tw_s": "TW", "at_pu": "At",
        "dturb_pu": "Dturb", "q_nl_pu": "qNL"},
    "GGOV1": {"r_pu": "R", "t_pelec_s": "Tpelec", "maxerr_pu": "maxerr", "minerr_pu": "minerr",
        "kpgov": "Kpgov", "kigov": "Kigov", "kdgov": "Kdgov", "t_dgov_s": "Tdgov",
        "v_max_pu": "Vmax", "v_min_pu": "Vmin", "t_act_s": "Tact", "k_turb": "Kturb",
        "w_fnl_pu": "Wfnl", "t_b_s": "Tb", "t_c_s": "Tc", "t_eng_s": "Teng",
        "t_fload_s": "Tfload", "kpload": "Kpload", "kiload": "Kiload", "ldref_pu": "Ldref",
        "dm_pu": "Dm", "r_open_pu_s": "Ropen", "r_close_pu_s": "Rclose", "kimw": "Kimw",
        "aset_pu_s": "Aset", "ka": "Ka", "t_a_s": "Ta", "trate_mw": "Trate", "db_pu": "db",
        "t_sa_s": "Tsa", "t_sb_s": "Tsb", "rup_pu_s": "Rup", "rdown_pu_s": "Rdown"},
    "IEESGO": {"t1_s": "T1", "t2_s": "T2", "t3_s": "T3", "t4_s": "T4", "t5_s": "T5", "t6_s": "T6",
        "k1": "K1", "k2": "K2", "k3": "K3", "p_max_pu": "PMAX", "p_min_pu": "PMIN"},
    "WSIEG1": {"k": "K", "t1_s": "T1", "t2_s": "T2", "t3_s": "T3", "uo_pu_s": "Uo",
        "uc_pu_s": "Uc", "p_max_pu": "PMAX", "p_min_pu": "PMIN", "t4_s": "T4", "k1": "K1",
        "k2": "K2", "t5_s": "T5", "k3": "K3", "k4": "K4", "t6_s": "T6", "k5": "K5", "k6": "K6",
        "t7_s": "T7", "k7": "K7", "k8": "K8", "db1_pu": "DB1", "err_pu": "ERR", "db2_pu": "DB2",
        "gv1_pu": "GV1", "pgv1_pu": "PGV1", "gv2_pu": "GV2", "pgv2_pu": "PGV2", "gv3_pu": "GV3",
        "pgv3_pu": "PGV3", "gv4_pu": "GV4", "pgv4_pu": "PGV4", "gv5_pu": "GV5",
        "pgv5_pu": "PGV5", "iblock": "IBLOCK"},
}
"""Field of the governor module (``GOVERNORS[model]``) -> the PSS/E constant it takes; GGOV1's
Rselect and Flag (integers) and its base ratio are set apart."""
TYPED_MODELS = {**MACHINE_FIELDS, **GOVERNOR_FIELDS}
PSSE_GOVERNOR_MODELS = frozenset({
    "BBGOV1", "CRCMGV", "DEGOV", "DEGOV1", "GAST", "GAST2A", "GASTWD", "GGOV1", "GGOV2", "GGOV3",
    "GOVCT1", "GOVCT2", "H6E", "HYGOV", "HYGOV2", "HYGOVM", "HYGOVT", "HYGOVR", "IEEEG1",
    "IEEEG2", "IEEEG3", "IEESGO", "IVOGO", "PIDGOV", "TGOV1", "TGOV2", "TGOV3", "TGOV4",
    "TGOV5", "TURCZT", "TWDM1T", "TWDM2T", "URCSCT", "URGS3T", "WEHGOV", "WESGOV", "WPIDHY",
    "WSHYDD", "WSHYGP", "WSIEG1"})
"""Turbine-governor models of the PSS/E model library (typed or not): a unit whose governor
record is one jaxdse does not model runs with constant mechanical torque, and says so."""

# --- records ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class DyrChange:
    """One constant of a record changed by ``jaxdse check --repair``, as the repaired file
    states it in a ``/ jaxdse repair: ...`` comment line (:func:`repair_comment`)."""

    model: str
    bus: int
    id: str
    con: str
    """The constant's PSS/E name (e.g. "GMAX")."""
    old: float
    """Its value in the original record."""
    new: float
    """Its value in the repaired record."""
    origin: str
    """Where the original record stands, e.g. "case.dyr line 204"."""
    why: str
    """The limit crossed and the rule applied, one line."""
    line: int = 0
    """The comment's line in the file read (0: not read from a file)."""


REPAIR_TAG = "jaxdse repair:"
_REPAIR = re.compile(r"^\s*/\s*jaxdse repair:\s*(?P<con>\S+) of (?P<model>\S+) bus (?P<bus>-?\d+) "
                     r"id '(?P<id>[^']*)': (?P<old>\S+) -> (?P<new>\S+) \((?P<origin>[^)]*)\): "
                     r"(?P<why>.*?)\s*$")


def _num(x: float) -> str:
    return f"{x:.7g}"


def repair_comment(c: DyrChange) -> str:
    """The .dyr comment line that carries ``c`` (read back by :func:`read_dyr`)."""
    return (f"/ {REPAIR_TAG} {c.con} of {c.model} bus {c.bus} id '{c.id}': {_num(c.old)} -> "
            f"{_num(c.new)} ({c.origin}): {' '.join(c.why.split())}")


def _repair_of(text: str, line: int) -> DyrChange | None:
    m = _REPAIR.match(text)
    if m is None:
        return None
    try:
        old, new = parse_number(m["old"]), parse_number(m["new"])
    except ValueError:
        return None
    return DyrChange(model=m["model"].upper(), bus=int(m["bus"]), id=m["id"].strip(), con=m["con"],
                     old=old, new=new, origin=m["origin"], why=m["why"], line=line)


@dataclass(frozen=True)
class DyrRecord:
    """One .dyr record: ``bus 'MODEL' id constants /``.

    ``constants`` holds floats, or strings for non-numeric tokens of models read raw (e.g.
    REPCA1's quoted ICON). ``params`` names the constants in PSS/E order for typed models
    (machines GENCLS, GENSAL, GENROU, GENTPJ, GENROE, GENSAE and governors TGOV1, IEEEG1, GAST,
    HYGOV, GGOV1, IEESGO, WSIEG1)
    and is empty for the others.
    """

    model: str
    bus: int
    id: str
    constants: tuple
    line: int
    """1-based line number of the record's first line."""
    source: str = field(default="", repr=False)
    params: dict = field(default_factory=dict, repr=False)
    problem: str | None = field(default=None, repr=False)
    """Why the record cannot be used (the one-line message strict reading raises); only with
    ``read_dyr(..., strict=False)``. ``params`` then holds NaN for the unreadable constants
    (or is empty when their number is wrong)."""
    changes: tuple[DyrChange, ...] = field(default=(), repr=False)
    """The repairs the file records for this record (``/ jaxdse repair: ...`` comment lines,
    written by ``jaxdse check --repair``), in file order."""

    @property
    def kind(self) -> str:
        """"machine", "governor" or "other"."""
        if self.model in MACHINE_FIELDS:
            return "machine"
        return "governor" if self.model in GOVERNOR_FIELDS else "other"

    def __getitem__(self, name: str) -> float:
        return self.params[name]

    def error(self, message: str) -> InputError:
        """A one-line InputError about this record."""
        return InputError(self.source, f"{self.model} bus {self.bus} id {self.id!r}: {message}",
                             row=self.line)


@dataclass
class DyrData:
    """All records of a .dyr file, in file order."""

    source: str
    records: list[DyrRecord]
    empty_records: int = 0
    """Records with no content (a lone ``/``), skipped."""
    problems: list[str] = field(default_factory=list)
    """Records dropped because they cannot be attributed to a machine (no readable bus number,
    fewer than three fields): one line each; only with ``read_dyr(..., strict=False)``."""

    @property
    def counts(self) -> Counter:
        """Records per model name."""
        return Counter(r.model for r in self.records)

    @property
    def unknown_models(self) -> list[str]:
        """Models read and kept raw but not typed (exciters, stabilisers, renewables, ...):
        "read and kept, not needed" -- for a warning, never an error."""
        return sorted({r.model for r in self.records if r.model not in TYPED_MODELS})

    @property
    def machines(self) -> list[DyrRecord]:
        return [r for r in self.records if r.kind == "machine"]

    @property
    def governors(self) -> list[DyrRecord]:
        return [r for r in self.records if r.kind == "governor"]

    def of_model(self, model: str) -> list[DyrRecord]:
        return [r for r in self.records if r.model == model.upper()]

    def _find(self, bus: int, machine_id: str, kind: str) -> DyrRecord | None:
        mid = str(machine_id).strip().upper()
        hits = [r for r in self.records if r.kind == kind and r.bus == int(bus) and r.id.upper() == mid]
        if len(hits) > 1:
            raise hits[1].error(f"a second {kind} record for this machine "
                                f"(first {hits[0].model} at line {hits[0].line})")
        return hits[0] if hits else None

    def unit_records(self, bus: int, machine_id: str) -> list[DyrRecord]:
        """Every record of one machine (any model, duplicates too), in file order."""
        mid = str(machine_id).strip().upper()
        return [r for r in self.records if r.bus == int(bus) and r.id.upper() == mid]

    def machine(self, bus: int, machine_id: str) -> DyrRecord | None:
        """The machine record (GENCLS/GENSAL/GENROU/GENTPJ) of a generator, or None."""
        return self._find(bus, machine_id, "machine")

    def governor(self, bus: int, machine_id: str) -> DyrRecord | None:
        """The typed governor record of a generator, or None."""
        return self._find(bus, machine_id, "governor")


def merge_dyr(base: DyrData, *overrides: DyrData) -> DyrData:
    """``base`` with each record of ``overrides`` replacing the record of the same bus, machine
    ID and model (a calibrated .dyr holds only the changed records); new records are added."""
    records = list(base.records)
    for over in overrides:
        for rec in over.records:
            key = (rec.bus, rec.id.upper(), rec.model)
            hits = [k for k, r in enumerate(records) if (r.bus, r.id.upper(), r.model) == key]
            if hits:
                records[hits[0]] = rec
            else:
                records.append(rec)
    return DyrData(" + ".join([base.source, *(o.source for o in overrides)]), records,
                   base.empty_records + sum(o.empty_records for o in overrides),
                   [*base.problems, *(p for o in overrides for p in o.problems)])


# --- .dyr reader ------------------------------------------------------------------------------

def token_spans(text: str) -> tuple[list[tuple[int, int]], bool]:
    """(the (start, end) of each token of one line, ended): blanks/commas separate, quotes
    group, '/' ends. A quoted token's span includes its quotes."""
    out, i, n = [], 0, len(text)
    while i < n:
        ch = text[i]
        if ch in " \t,\r\n":
            i += 1
        elif ch == "/":
            return out, True
        elif ch in "'\"":
            j = text.find(ch, i + 1)
            if j < 0:
                raise ValueError(f"unclosed quote {ch} in {text.strip()!r}")
            out.append((i, j + 1))
            i = j + 1
        else:
            j = i
            while j < n and text[j] not in " \t,\r\n/'\"":
                j += 1
            out.append((i, j))
            i = j
    return out, False


def _tokens(text: str):
    """Split one line into (tokens, ended) (:func:`token_spans`). Quoted tokens keep their
    quotes so that callers can tell a string from a number."""
    spans, ended = token_spans(text)
    return [text[a:b] for a, b in spans], ended


def read_dyr(path, *, strict: bool = True) -> DyrData:
    """Read a PSS/E .dyr file: every record with its 1-based starting line.

    Typed models (:data:`TYPED_MODELS`) get named ``params`` and are checked: a wrong number
    of constants or a non-numeric constant raises :class:`InputError`. Other models
    are kept raw (see :attr:`DyrData.unknown_models`). A record left open at the end of the
    file is an error too. With ``strict=False`` these records are kept with their
    ``problem`` instead (see the module docstring); a missing file is still an error.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file does not exist")
    source = str(path)
    records, empty, problems, changes = [], 0, [], []
    tokens: list[str] = []
    start, broken = 0, None

    def close(problem):
        try:
            rec = _dyr_record(tokens, source, start, strict)
        except InputError as e:
            if strict:
                raise
            problems.append(str(e))
            return
        if problem is not None:         # the first thing wrong in reading order
            rec = replace(rec, problem=problem)
        records.append(rec)

    with open(path, encoding="latin-1") as f:
        for number, text in enumerate(f, start=1):
            if is_comment(text):
                continue
            if not tokens and text.lstrip().startswith("/"):
                change = _repair_of(text, number)
                if change is not None:
                    changes.append(change)
                elif text.lstrip()[1:].lstrip().startswith(REPAIR_TAG):
                    problems.append(str(InputError(source, f"a '{REPAIR_TAG}' comment not in the form "
                                                   "'/ jaxdse repair: CON of MODEL bus N id 'ID': OLD -> "
                                                   "NEW (ORIGIN): WHY': ignored", row=number)))
                if text.lstrip()[1:].strip():
                    continue                # a comment line (a lone '/' is an empty record)
            try:
                toks, ended = _tokens(text)
            except ValueError as e:
                if strict:
                    raise InputError(source, str(e), row=number) from None
                broken = broken or str(InputError(source, str(e), row=number))
                toks, ended = _tokens(text.replace("'", " ").replace('"', " "))
            if toks and not tokens:
                start = number
            tokens.extend(toks)
            if ended:
                if tokens:
                    close(broken)
                else:
                    empty += 1
                tokens, broken = [], None
    if tokens:
        err = InputError(source, f"record {' '.join(tokens[:2])} ... has no terminating '/' "
                         "before the end of the file", row=start)
        if strict:
            raise err
        close(broken or str(err))
    return DyrData(source=source, records=_attach(records, changes, source, problems),
                   empty_records=empty, problems=problems)


def _attach(records: list[DyrRecord], changes: list[DyrChange], source: str,
            problems: list[str]) -> list[DyrRecord]:
    """``records`` with each repair comment attached to the record it names (the first of
    that model, bus and ID); one that names none is listed in ``problems``."""
    if not changes:
        return records
    at = {}
    for k, r in enumerate(records):
        at.setdefault((r.model, r.bus, r.id.upper()), k)
    mine: dict[int, list[DyrChange]] = {}
    for c in changes:
        k = at.get((c.model, c.bus, c.id.upper()))
        if k is None:
            problems.append(str(InputError(source, f"a '{REPAIR_TAG}' comment for {c.model} bus {c.bus} "
                                           f"id {c.id!r}, a record not in this file: ignored", row=c.line)))
            continue
        mine.setdefault(k, []).append(c)
    return [replace(r, changes=(*r.changes, *mine[k])) if k in mine else r for k, r in enumerate(records)]


def _dyr_record(tokens: list[str], source: str, line: int, strict: bool = True) -> DyrRecord:
    if len(tokens) < 3:
        raise InputError(source, f"record {' '.join(tokens)!r} needs a bus number, a model "
                            "name and a machine ID", row=line)
    bus_tok, model, mid = tokens[0], _unquote(tokens[1]).upper(), _unquote(tokens[2])
    try:
        bus = int(parse_number(bus_tok))
        if bus != parse_number(bus_tok):
            raise ValueError
    except (ValueError, OverflowError):
        raise InputError(source, f"record for model {model}: the bus number is "
                            f"{bus_tok!r}, not an integer", row=line) from None
    problem = None

    def bad(message):
        nonlocal problem
        err = InputError(source, f"{model} bus {bus} id {mid!r}{message}", row=line)
        if strict:
            raise err
        problem = problem or str(err)

    values = []
    for k, tok in enumerate(tokens[3:]):
        if tok[:1] in "'\"":
            values.append(_unquote(tok))
            continue
        try:
            values.append(parse_number(tok))
        except ValueError:
            if model in TYPED_MODELS:
                names = TYPED_MODELS[model]
                name = names[k] if k < len(names) else f"#{k + 1}"
                bad(f": constant {k + 1} ({name}) is not a number: {tok!r}")
            values.append(tok)
    params = {}
    if model in TYPED_MODELS:
        names = TYPED_MODELS[model]
        n_min = len(names) - OPTIONAL_TRAILING.get(model, 0)
        if not n_min <= len(values) <= len(names):
            want = f"{len(names)}" if n_min == len(names) else f"{n_min} or {len(names)}"
            bad(f" has {len(values)} constants, expected {want} ({', '.join(names)})")
            return DyrRecord(model=model, bus=bus, id=mid, constants=tuple(values), line=line,
                             source=source, problem=problem)
        for k, name in enumerate(names):
            value = values[k] if k < len(values) else 0.0
            if isinstance(value, str):
                bad(f": constant {k + 1} ({name}) is not a number: {value!r}")
                value = math.nan
            params[name] = value
    return DyrRecord(model=model, bus=bus, id=mid, constants=tuple(values), line=line,
                     source=source, params=params, problem=problem)


__all__ = [
    "GOVERNOR_FIELDS", "GOVERNOR_PARAMETERS", "MACHINE_FIELDS", "OPTIONAL_TRAILING",
    "PSSE_GOVERNOR_MODELS", "REPAIR_TAG", "TYPED_MODELS", "DyrChange", "DyrData", "DyrRecord",
    "merge_dyr", "read_dyr", "repair_comment", "token_spans",
]
