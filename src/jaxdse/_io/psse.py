"""PSS/E dynamic (.dyr) and power-flow (.raw, revisions 32 and 33) readers for jaxdse.

Readers work at the edge (plain Python + NumPy, never inside jit). Every user mistake raises
:class:`InputError`, a one-line message naming the file, the line (``row``) and what
is wrong. Converters turn the records into keyword arguments of :class:`jaxdse.Machine` and
:class:`jaxdse.Transformer` and into governor modules.

Formats (Siemens PTI, *PSS(R)E Program Operation Manual*, "Dynamics data file" and "Power
flow raw data file", revisions 32 and 33):

* ``.dyr``: records ``IBUS 'MODEL' ID con con ... /``, free format, any number of lines per
  record, fields separated by blanks or commas, the model name and the machine ID quoted or
  not; the ``/`` ends a record and the rest of that line is a comment; ``@!`` lines are
  comments. Numbers may be Fortran-style (``0.5E-01``, ``1.D-2``).
* ``.raw``: case identification (IC, SBASE, REV, XFRRAT, NXFRAT, BASFRQ / comment) and two
  title lines, then sections each closed by a record starting with ``0`` (``Q`` ends the
  data). Read here: buses, loads, generators, non-transformer branches and two-winding
  transformers (three-winding ones are skipped and counted). Layout differences of revision
  33 over 32 in these sections: the bus record adds NVHI, NVLO, EVHI, EVLO; the load record
  adds INTRPT; line 1 of a transformer adds VECGRP. The generator and branch records have the
  same leading fields in both (rev 34 inserts NREG after IREG, hence 34+ is refused). Fields
  are read by position; trailing fields may be omitted (PSS/E defaults) and extra trailing
  fields are ignored.

Both readers take ``strict``: by default a malformed record raises :class:`InputError`; with
``strict=False`` (``jaxdse fleet``) a malformed record that can still be told apart (its bus
and machine ID read) is kept with its ``problem`` (the one-line message strict reading would
raise), so that only the units it belongs to are left out; records that cannot be attributed
are dropped and listed in ``problems`` of the file.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

from .._models.governors import GOVERNORS, AbstractGovernor
from .errors import InputError

SUPPORTED_RAW_REVISIONS = (32, 33)
BIG_SHUNT_PU = 1e12
"""r_Fe and x_M [pu] standing for a zero magnetising admittance (Transformer needs > 0)."""
DEFAULT_TAP_STEP = 0.0125
"""Tap step used when the transformer record has no tap range (RMA1 = RMI1 or NTP1 < 2)."""
GENCLS_TD0_S = 1e6
"""T'do [s] for GENCLS (constant E' behind X'd): effectively infinite."""

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

_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eEdD][+-]?\d+)?$")


def parse_number(token: str) -> float:
    """A PSS/E number: Fortran exponents ``E``/``D`` (``1.D-2``), no NaN/Inf words."""
    if not _NUMBER.match(token):
        raise ValueError(token)
    return float(token.replace("D", "E").replace("d", "e"))


# --- records ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class DyrRecord:
    """One .dyr record: ``bus 'MODEL' id constants /``.

    ``constants`` holds floats, or strings for non-numeric tokens of models read raw (e.g.
    REPCA1's quoted ICON). ``params`` names the constants in PSS/E order for typed models
    (machines GENCLS, GENSAL, GENROU, GENTPJ and governors TGOV1, IEEEG1, GAST, HYGOV, GGOV1)
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

def _tokens(text: str):
    """Split one line into (tokens, ended): blanks/commas separate, quotes group, '/' ends.

    Quoted tokens keep their quotes so that callers can tell a string from a number.
    """
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
            out.append(text[i:j + 1])
            i = j + 1
        else:
            j = i
            while j < n and text[j] not in " \t,\r\n/'\"":
                j += 1
            out.append(text[i:j])
            i = j
    return out, False


def _unquote(token: str) -> str:
    return token[1:-1].strip() if token[:1] in "'\"" else token.strip()


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
    records, empty, problems = [], 0, []
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
            if text.lstrip().startswith("@!"):
                continue
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
    return DyrData(source=source, records=records, empty_records=empty, problems=problems)


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


# --- .raw records -----------------------------------------------------------------------------

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


@dataclass(frozen=True)
class RawBranch:
    i: int
    j: int
    ckt: str
    r_pu: float
    x_pu: float
    b_pu: float
    rate_a_mva: float
    status: int
    line: int


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
    """Records dropped or not used (``read_raw(..., strict=False)``): one line each."""

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


# --- .raw reader ------------------------------------------------------------------------------

def _raw_fields(text: str) -> list[str | None]:
    """Comma-separated fields (blanks when a line has no comma), quotes kept, '/' ends."""
    cur, i, n, quote = [], 0, len(text), None
    while i < n:
        ch = text[i]
        if quote:
            cur.append(ch)
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
            cur.append(ch)
        elif ch == "/":
            break
        else:
            cur.append(ch)
        i += 1
    if quote:
        raise ValueError(f"unclosed quote {quote}")
    body = "".join(cur)
    parts = _split_outside_quotes(body, "," if "," in _strip_quoted(body) else None)
    return [p.strip() or None for p in parts]


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
    """Typed access to one record's fields with PSS/E defaults and one-line errors."""

    def __init__(self, fields, source, line, what, lenient=False):
        self.fields, self.source, self.line, self.what = fields, source, line, what
        self.lenient, self.problem = lenient, None

    def _fail(self, message, fallback):
        """Raise the one-line error; leniently, note the first one and go on with ``fallback``."""
        err = InputError(self.source, f"{self.what}: {message}", row=self.line)
        if not self.lenient:
            raise err
        self.problem = self.problem or str(err)
        return fallback

    def _raw(self, k, name, default):
        tok = self.fields[k] if k < len(self.fields) else None
        if tok is None:
            if default is _REQUIRED:
                self._fail(f"field {k + 1} ({name}) is missing", None)
            return None
        return tok

    def num(self, k, name, default=_REQUIRED) -> float:
        tok = self._raw(k, name, default)
        if tok is None:
            return math.nan if default is _REQUIRED else default
        try:
            return parse_number(_unquote(tok))
        except ValueError:
            return self._fail(f"field {k + 1} ({name}) is not a number: {tok!r}", math.nan)

    def int(self, k, name, default=_REQUIRED) -> int:
        value = self.num(k, name, default)
        fallback = None if default is _REQUIRED else default
        if value is None or (self.lenient and not math.isfinite(value)):
            return fallback
        if not math.isfinite(value) or value != int(value):
            return self._fail(f"field {k + 1} ({name}) is not an integer: {value!r}", fallback)
        return int(value)

    def text(self, k, name, default=_REQUIRED) -> str:
        tok = self._raw(k, name, default)
        return default if tok is None else _unquote(tok)


def read_raw(path, *, strict: bool = True) -> RawCase:
    """Read a PSS/E .raw file of revision 32 or 33 (other revisions: InputError).

    BASFRQ defaults to 60 Hz when the case line omits it (or gives 0). With ``strict=False``
    a bus or generator record with an unreadable field is kept with its ``problem`` (NaN in
    that field), a bus defined twice keeps its first record, and a record without a readable
    bus number is dropped; each is listed in :attr:`RawCase.problems`.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file does not exist")
    source = str(path)
    with open(path, encoding="latin-1") as f:
        lines = [(k, t.rstrip("\r\n")) for k, t in enumerate(f, start=1) if not t.lstrip().startswith("@!")]
    if len(lines) < 3:
        raise InputError(source, "is too short for a PSS/E raw file (case line and two titles)")
    case_no, case_text = lines[0]
    try:
        head = _raw_fields(case_text)
    except ValueError as e:
        raise InputError(source, f"case identification: {e}", row=case_no) from None
    row = _Row(head, source, case_no, "case identification")
    ic = row.int(0, "IC", 0)
    sbase = row.num(1, "SBASE", 100.0)
    rev = row.int(2, "REV", None)
    if rev is None:
        m = re.search(r"PSS(?:\(R\)|/|\(TM\))?E[- ]?(\d+)", case_text.upper())
        rev = int(m.group(1)) if m else None
    if rev not in SUPPORTED_RAW_REVISIONS:
        found = "no revision number" if rev is None else f"revision {rev}"
        raise InputError(source, f"case identification gives {found}; only PSS/E raw "
                            f"revisions {' and '.join(map(str, SUPPORTED_RAW_REVISIONS))} are "
                            "supported", row=case_no)
    if not sbase > 0:
        raise InputError(source, f"SBASE must be > 0, got {sbase}", row=case_no)
    basfrq = row.num(5, "BASFRQ", 60.0) or 60.0
    title = (lines[1][1], lines[2][1])

    sections = _raw_sections(lines[3:], source)
    buses, problems = {}, []
    for line, flds in _section(sections, 0):
        r = _Row(flds, source, line, "bus record", lenient=not strict)
        b = RawBus(number=r.int(0, "I"), name=r.text(1, "NAME", ""), base_kv=r.num(2, "BASKV", 0.0),
                   ide=r.int(3, "IDE", 1), area=r.int(4, "AREA", 1), zone=r.int(5, "ZONE", 1),
                   vm_pu=r.num(7, "VM", 1.0), va_deg=r.num(8, "VA", 0.0), line=line,
                   problem=r.problem)
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
    for line, flds in _section(sections, 1):
        r = _Row(flds, source, line, "load record")
        loads.append(RawLoad(bus=r.int(0, "I"), id=r.text(1, "ID", "1"), status=r.int(2, "STATUS", 1),
                             area=r.int(3, "AREA", 0), zone=r.int(4, "ZONE", 0),
                             pl_mw=r.num(5, "PL", 0.0), ql_mvar=r.num(6, "QL", 0.0),
                             ip_mw=r.num(7, "IP", 0.0), iq_mvar=r.num(8, "IQ", 0.0),
                             yp_mw=r.num(9, "YP", 0.0), yq_mvar=r.num(10, "YQ", 0.0), line=line))
    generators = []
    for line, flds in _section(sections, 3):
        r = _Row(flds, source, line, "generator record", lenient=not strict)
        g = RawGenerator(
            bus=r.int(0, "I"), id=r.text(1, "ID", "1"), pg_mw=r.num(2, "PG", 0.0),
            qg_mvar=r.num(3, "QG", 0.0), qt_mvar=r.num(4, "QT", 9999.0), qb_mvar=r.num(5, "QB", -9999.0),
            vs_pu=r.num(6, "VS", 1.0), ireg=r.int(7, "IREG", 0), mbase_mva=r.num(8, "MBASE", sbase),
            zr_pu=r.num(9, "ZR", 0.0), zx_pu=r.num(10, "ZX", 1.0), rt_pu=r.num(11, "RT", 0.0),
            xt_pu=r.num(12, "XT", 0.0), gtap=r.num(13, "GTAP", 1.0), stat=r.int(14, "STAT", 1),
            rmpct=r.num(15, "RMPCT", 100.0), pt_mw=r.num(16, "PT", 9999.0), pb_mw=r.num(17, "PB", -9999.0),
            line=line, source=source, problem=r.problem)
        if g.bus is None:
            problems.append(f"{r.problem} (record dropped)")
            continue
        if g.problem:
            problems.append(g.problem)
        generators.append(g)
    branches = []
    for line, flds in _section(sections, 4):
        r = _Row(flds, source, line, "branch record")
        branches.append(RawBranch(i=r.int(0, "I"), j=abs(r.int(1, "J")), ckt=r.text(2, "CKT", "1"),
                                  r_pu=r.num(3, "R", 0.0), x_pu=r.num(4, "X"), b_pu=r.num(5, "B", 0.0),
                                  rate_a_mva=r.num(6, "RATEA", 0.0), status=r.int(13, "ST", 1),
                                  line=line))
    transformers, n3 = _read_transformers(_section(sections, 5), source, sbase)
    return RawCase(source=source, revision=rev, sbase_mva=sbase, basfrq_hz=basfrq, ic=ic, title=title,
                   buses=buses, loads=loads, generators=generators, branches=branches,
                   transformers=transformers, n_three_winding=n3, problems=problems)


_SECTION_NAMES = ("bus", "load", "fixed shunt", "generator", "branch", "transformer")


def _raw_sections(lines, source):
    """Records (line, fields) of the first six sections; later sections are not parsed."""
    sections, current = [], []
    for line, text in lines:
        stripped = text.strip()
        if stripped.upper().startswith("Q") and (len(stripped) == 1 or not stripped[1].isalnum()):
            break
        try:
            flds = _raw_fields(text)
        except ValueError as e:
            raise InputError(source, f"{_section_label(len(sections))}: {e}", row=line) from None
        if not any(flds):
            continue
        if flds[0] == "0" and len([x for x in flds if x is not None]) == 1:
            sections.append(current)
            current = []
            if len(sections) == len(_SECTION_NAMES):
                return sections
            continue
        current.append((line, flds))
    sections.append(current)
    if len(sections) < len(_SECTION_NAMES):
        missing = _SECTION_NAMES[len(sections) - 1]
        raise InputError(source, f"the {missing} data section is not closed by a '0' record "
                            "before the end of the data", row=lines[-1][0] if lines else None)
    return sections


def _section_label(k):
    return f"{_SECTION_NAMES[k]} data" if k < len(_SECTION_NAMES) else "data"


def _section(sections, k):
    return sections[k] if k < len(sections) else []


def _read_transformers(records, source, sbase):
    out, n3, k = [], 0, 0
    while k < len(records):
        line, f1 = records[k]
        r1 = _Row(f1, source, line, "transformer record line 1")
        i, j, kk = r1.int(0, "I"), abs(r1.int(1, "J")), abs(r1.int(2, "K", 0))
        n_lines = 4 if kk == 0 else 5
        if k + n_lines > len(records):
            raise InputError(source, f"transformer {i}-{j}{'-' + str(kk) if kk else ''} needs "
                                f"{n_lines} lines, the section ends after {len(records) - k}", row=line)
        if kk != 0:
            n3 += 1
            k += 5
            continue
        (l2, f2), (l3, f3), (l4, f4) = records[k + 1:k + 4]
        r2 = _Row(f2, source, l2, f"transformer {i}-{j} line 2")
        r3 = _Row(f3, source, l3, f"transformer {i}-{j} line 3")
        r4 = _Row(f4, source, l4, f"transformer {i}-{j} line 4")
        out.append(RawTransformer(
            i=i, j=j, ckt=r1.text(3, "CKT", "1"), cw=r1.int(4, "CW", 1), cz=r1.int(5, "CZ", 1),
            cm=r1.int(6, "CM", 1), mag1=r1.num(7, "MAG1", 0.0), mag2=r1.num(8, "MAG2", 0.0),
            nmetr=r1.int(9, "NMETR", 2), name=r1.text(10, "NAME", ""), stat=r1.int(11, "STAT", 1),
            r12=r2.num(0, "R1-2", 0.0), x12=r2.num(1, "X1-2"), sbase12_mva=r2.num(2, "SBASE1-2", sbase),
            windv1=r3.num(0, "WINDV1", 1.0), nomv1_kv=r3.num(1, "NOMV1", 0.0),
            ang1_deg=r3.num(2, "ANG1", 0.0),
            cod1=r3.int(6, "COD1", 0), cont1=r3.int(7, "CONT1", 0), rma1=r3.num(8, "RMA1", 1.1),
            rmi1=r3.num(9, "RMI1", 0.9), vma1=r3.num(10, "VMA1", 1.1), vmi1=r3.num(11, "VMI1", 0.9),
            ntp1=r3.int(12, "NTP1", 33), windv2=r4.num(0, "WINDV2", 1.0), nomv2_kv=r4.num(1, "NOMV2", 0.0),
            line=line, source=source))
        k += 4
    return out, n3


# --- converters -------------------------------------------------------------------------------

@dataclass(frozen=True)
class MachineTransientData:
    """Transient/subtransient data beyond jaxdse's third-order model (for a later model-
    mismatch correction). Reactances [pu, machine base], time constants [s]; None where the
    model has no such quantity (GENSAL has no q-axis transient circuit)."""

    model: str
    xq1_pu: float | None
    """X'q."""
    tq01_s: float | None
    """T'qo."""
    xd2_pu: float
    """X''d (= X''q in GENROU/GENSAL/GENTPJ)."""
    td02_s: float
    """T''do."""
    tq02_s: float
    """T''qo."""
    xl_pu: float
    """Xl, stator leakage."""


def machine_kwargs(gen_dyr_record: DyrRecord, raw_generator: RawGenerator, bus_kv: float,
                   f_nominal_hz: float) -> dict:
    """Keyword arguments of :class:`jaxdse.Machine` from a machine record and its generator.

    Conventions:

    * reactances and T'do from the .dyr record (PSS/E order); GENCLS has none: x'd is the
      .raw ZSORCE reactance ZX, xd = xq = x'd, T'do = ``GENCLS_TD0_S`` (constant E');
    * ``rs_pu`` = ZSORCE resistance ZR from the .raw (PSS/E keeps Ra there), on MBASE;
    * ``s_rated_mva`` = MBASE, ``v_rated_kv`` = the bus base voltage;
    * damping: PSS/E's D is pu power per pu speed deviation, 2H d(dw)/dt = Pm - Pe - D dw.
      jaxdse's ``d_pu_s`` multiplies x2 = w_s dw [rad/s] in dx2/dt = w_s/(2H)(Tm - Te - D x2),
      so ``d_pu_s = D / w_s`` with w_s = 2 pi f (then a1 = w_s d/(2H) = D/(2H)).
    """
    rec = gen_dyr_record
    if rec.kind != "machine":
        raise rec.error(f"is not a machine model ({', '.join(MACHINE_FIELDS)})")
    g = raw_generator
    if not g.mbase_mva > 0:
        raise InputError(g.source, f"generator {g.bus} {g.id!r}: MBASE is {g.mbase_mva} MVA; "
                            "it must be > 0", row=g.line)
    if not bus_kv > 0:
        raise InputError(g.source, f"generator {g.bus} {g.id!r}: bus base voltage is {bus_kv} kV; "
                            "it must be > 0", row=g.line)
    omega_s = 2.0 * math.pi * f_nominal_hz
    p = rec.params
    if rec.model == "GENCLS":
        xd1 = g.zx_pu
        xd = xq = xd1
        td0 = GENCLS_TD0_S
    else:
        xd, xd1, xq, td0 = p["Xd"], p["X'd"], p["Xq"], p["T'do"]
    return dict(xd_pu=xd, xd1_pu=xd1, xq_pu=xq, rs_pu=g.zr_pu, td01_s=td0, h_s=p["H"],
                d_pu_s=p["D"] / omega_s, s_rated_mva=g.mbase_mva, v_rated_kv=bus_kv,
                f_nominal_hz=f_nominal_hz)


def transient_data(gen_dyr_record: DyrRecord) -> MachineTransientData | None:
    """The GENROU/GENTPJ/GENSAL transient q-axis and subtransient data (None for GENCLS)."""
    rec = gen_dyr_record
    if rec.model == "GENCLS":
        return None
    if rec.kind != "machine":
        raise rec.error("is not a machine model")
    p = rec.params
    salient = rec.model == "GENSAL"
    return MachineTransientData(model=rec.model, xq1_pu=None if salient else p["X'q"],
                                tq01_s=None if salient else p["T'qo"], xd2_pu=p["X''d"],
                                td02_s=p["T''do"], tq02_s=p["T''qo"], xl_pu=p["Xl"])


def _g(x) -> str:
    return f"{x:g}" if isinstance(x, (int, float)) else repr(x)


def record_label(record: DyrRecord) -> str:
    """``GENROU on bus 3 id '1' (case.dyr line 7)``: a record, for one-line messages."""
    return (f"{record.model} on bus {record.bus} id {record.id!r} "
            f"({Path(record.source).name or '.dyr'} line {record.line})")


def generator_label(generator: RawGenerator) -> str:
    """``generator on bus 3 id '1' (case.raw line 11)``."""
    return (f"generator on bus {generator.bus} id {generator.id!r} "
            f"({Path(generator.source).name or '.raw'} line {generator.line})")


def machine_problems(record: DyrRecord, generator: RawGenerator) -> list[str]:
    """What makes a machine record (GENCLS/GENSAL/GENROU/GENTPJ) and its .raw generator record
    unusable for :func:`machine_kwargs` and :class:`jaxdse.Machine`: one line each, naming the
    record and the values; empty when both are usable.

    Checked: the records read (``problem``); finite values; H, T'do, Xd, Xq, X'd > 0 (GENCLS:
    H > 0 and the ZSORCE reactance ZX > 0); D >= 0; X'd <= Xd; MBASE > 0; ZR >= 0. The q-axis
    circuits are checked apart (:func:`q_axis_problems`): jaxdse can do without them.
    """
    out = []
    g = generator
    if record.kind != "machine":
        return [f"{record_label(record)}: not a machine model ({', '.join(MACHINE_FIELDS)})"]
    if record.problem:
        out.append(record.problem)
    else:
        p = record.params
        where = record_label(record)
        positive = ("H",) if record.model == "GENCLS" else ("H", "T'do", "Xd", "Xq", "X'd")
        for name in positive:
            if not (math.isfinite(p[name]) and p[name] > 0):
                out.append(f"{where}: {name} = {_g(p[name])} must be > 0")
        if not (math.isfinite(p["D"]) and p["D"] >= 0):
            out.append(f"{where}: D = {_g(p['D'])} must be >= 0")
        if record.model != "GENCLS" and p["X'd"] > p["Xd"] > 0:
            xd1, xd = p["X'd"], p["Xd"]
            out.append(f"{where}: X'd = {_g(xd1)} above Xd = {_g(xd)}")
    if g.problem:
        out.append(g.problem)
        return out
    where = generator_label(g)
    if not (math.isfinite(g.mbase_mva) and g.mbase_mva > 0):
        out.append(f"{where}: MBASE = {_g(g.mbase_mva)} MVA must be > 0")
    if not (math.isfinite(g.zr_pu) and g.zr_pu >= 0):
        out.append(f"{where}: ZR (Ra) = {_g(g.zr_pu)} must be >= 0")
    if record.model == "GENCLS" and not (math.isfinite(g.zx_pu) and g.zx_pu > 0):
        out.append(f"{where}: ZX (X'd of GENCLS) = {_g(g.zx_pu)} must be > 0")
    return out


def q_axis_problems(record: DyrRecord) -> list[str]:
    """Why the q-axis circuits of a GENROU/GENTPJ record cannot be used by
    :class:`jaxdse.QAxisCircuits` (X''q = X''d must lie in (Xl, X'q], X'q <= Xq, Xl >= 0, T'qo
    and T''qo > 0, all finite): one line each, naming the record and the values; empty when usable
    (and for models without these circuits)."""
    if record.model not in ("GENROU", "GENTPJ") or record.problem:
        return []
    p, where, out = record.params, record_label(record), []
    names = ("X'q", "X''d", "Xl", "T'qo", "T''qo")
    bad = [n for n in names if not math.isfinite(p[n])]
    if bad:
        return [f"{where}: {', '.join(f'{n} = {_g(p[n])}' for n in bad)} not finite"]
    for name in ("T'qo", "T''qo", "X'q"):
        if not p[name] > 0:
            out.append(f"{where}: {name} = {_g(p[name])} must be > 0")
    if p["Xl"] < 0:
        out.append(f"{where}: Xl = {_g(p['Xl'])} must be >= 0")
    xd2, xq1, xl = p["X''d"], p["X'q"], p["Xl"]
    if xd2 < xl:
        out.append(f"{where}: X''d = {_g(xd2)} below Xl = {_g(xl)}")
    elif xd2 == xl:
        out.append(f"{where}: X''d = {_g(xd2)} not above Xl = {_g(xl)}")
    if xd2 > xq1 > 0:
        out.append(f"{where}: X''d (= X''q) = {_g(xd2)} above X'q = {_g(xq1)}")
    if xq1 > p["Xq"] > 0:
        out.append(f"{where}: X'q = {_g(xq1)} above Xq = {_g(p['Xq'])}")
    return out


def transformer_sides(raw_transformer: RawTransformer, raw_case: RawCase) -> tuple[int, int]:
    """(HV bus, LV bus): the end with the higher bus base voltage is HV (winding 1 on a tie)."""
    t = raw_transformer
    kv_i, kv_j = raw_case.bus_kv(t.i), raw_case.bus_kv(t.j)
    return (t.i, t.j) if kv_i >= kv_j else (t.j, t.i)


def _winding_ratio(cw, windv, nomv, vbase):
    """Off-nominal ratio in pu of the bus base voltage (PSS/E CW = 1, 2, 3)."""
    nom = nomv if nomv > 0 else vbase
    return {1: windv, 2: windv / vbase, 3: windv * nom / vbase}[cw]


def transformer_kwargs(raw_transformer: RawTransformer, raw_case: RawCase) -> dict:
    """Keyword arguments of :class:`jaxdse.Transformer` (T model, system base, tap on HV).

    PSS/E two-winding model (system base, bus base voltages): bus I, magnetising admittance
    Ym = G + jB at bus I, ideal transformer t1 e^{j ANG1} : 1, series impedance Z, ideal
    1 : t2, bus J. Conversions:

    * ratios t1, t2 in pu of the bus base voltages from WINDV1/2 by CW (1: pu of bus base;
      2: kV, divided by the bus base kV; 3: pu of NOMV, times NOMV/bus base; NOMV = 0 means the
      bus base);
    * Z on the system base by CZ (1: as given; 2: times SBASE/SBASE1-2; 3: R1-2 is the load
      loss in W, R = P/SBASE1-2 on the winding base, X = sqrt(|Z|^2 - R^2), then times
      SBASE/SBASE1-2);
    * Ym on the system base by CM (1: G = MAG1, B = MAG2 as given; 2: MAG1 = no-load loss [W],
      MAG2 = exciting current [pu of SBASE1-2 at NOMV1]: G = P0/SBASE (V_b/V_nom)^2,
      |Y| = I0 SBASE1-2/SBASE (V_b/V_nom)^2, B = -sqrt(|Y|^2 - G^2));
    * HV side = the bus with the higher base voltage. With I on the HV side, referring the
      circuit to bus J: n = t1 e^{j ANG1}/t2, z = Z t2^2, Ym moves inside the ideal
      transformer as Ym |n|^2. With J on the HV side, referring to bus I: n = t2/(t1 e^{j ANG1}),
      z = Z t1^2, Ym stays (it is on the LV terminal);
    * z is split evenly between the HV and LV windings; the magnetising branch, at a winding
      terminal in PSS/E, sits at the T-model midpoint (a second-order change, |Ym z|/2);
    * r_Fe = 1/G and x_M = 1/|B| (PSS/E enters B < 0 for an inductive branch; the sign is
      dropped); a zero G or B becomes ``BIG_SHUNT_PU`` (an open circuit);
    * tau = |n| - 1 is kept exactly: ``tap_step`` is the winding-1 tap step
      (RMA1 - RMI1)/(NTP1 - 1) in pu of n (``DEFAULT_TAP_STEP`` without a range) and
      ``tap_position`` = tau / tap_step (fractional when the ratio is off-step);
    * ``phase_shift_rad`` = arg(n).
    """
    t, case = raw_transformer, raw_case
    src = t.source or case.source

    def bad(msg):
        return InputError(src, f"transformer {t.i}-{t.j} {t.ckt!r}: {msg}", row=t.line)

    if t.cw not in (1, 2, 3) or t.cz not in (1, 2, 3) or t.cm not in (1, 2):
        raise bad(f"unknown code CW={t.cw}, CZ={t.cz} or CM={t.cm} (CW, CZ in 1..3, CM in 1..2)")
    vb_i, vb_j = case.bus_kv(t.i), case.bus_kv(t.j)
    s_sys = case.sbase_mva
    s_w = t.sbase12_mva
    if t.cz != 1 or t.cm == 2:
        if not s_w > 0:
            raise bad(f"SBASE1-2 is {s_w} MVA with CZ={t.cz}, CM={t.cm}; it must be > 0")
    t1 = _winding_ratio(t.cw, t.windv1, t.nomv1_kv, vb_i)
    t2 = _winding_ratio(t.cw, t.windv2, t.nomv2_kv, vb_j)
    if not (t1 > 0 and t2 > 0):
        raise bad(f"winding ratios must be > 0, got t1={t1}, t2={t2}")
    # series impedance on the system base
    if t.cz == 1:
        r, x = t.r12, t.x12
    elif t.cz == 2:
        r, x = t.r12 * s_sys / s_w, t.x12 * s_sys / s_w
    else:
        r_w = t.r12 / 1e6 / s_w
        if abs(t.x12) < r_w:
            raise bad(f"CZ=3: |Z| = {t.x12} is smaller than R = {r_w} from the load loss")
        r, x = r_w * s_sys / s_w, math.copysign(math.sqrt(t.x12**2 - r_w**2), t.x12) * s_sys / s_w
    # magnetising admittance on the system base, at bus I
    if t.cm == 1:
        g_m, b_m = t.mag1, t.mag2
    else:
        v_nom = t.nomv1_kv if t.nomv1_kv > 0 else vb_i
        scale = (vb_i / v_nom) ** 2
        g_m = t.mag1 / 1e6 / s_sys * scale
        y_abs = t.mag2 * s_w / s_sys * scale
        if y_abs < g_m:
            raise bad(f"CM=2: exciting current {t.mag2} pu gives |Y| = {y_abs} < G = {g_m}")
        b_m = -math.sqrt(y_abs**2 - g_m**2)
    theta = math.radians(t.ang1_deg)
    hv_is_i = vb_i >= vb_j
    if hv_is_i:
        n_abs, phi = t1 / t2, theta
        z_scale, y_scale = t2**2, n_abs**2
        step = _tap_range_step(t, vb_i) / t2
    else:
        n_abs, phi = t2 / t1, -theta
        z_scale, y_scale = t1**2, 1.0
        step = _tap_range_step(t, vb_i) * t2 / t1**2
    if r < 0 or x < 0:
        raise bad(f"negative series impedance R={r}, X={x} cannot be a jaxdse Transformer")
    g_m, b_m = g_m * y_scale, abs(b_m) * y_scale
    tau = n_abs - 1.0
    if not step > 0:
        step = DEFAULT_TAP_STEP
    z_r, z_x = r * z_scale, x * z_scale
    return dict(r_hv_pu=0.5 * z_r, x_hv_pu=0.5 * z_x, r_lv_pu=0.5 * z_r, x_lv_pu=0.5 * z_x,
                r_fe_pu=1.0 / g_m if g_m > 0 else BIG_SHUNT_PU,
                x_m_pu=1.0 / b_m if b_m > 0 else BIG_SHUNT_PU,
                tap_step=step, tap_position=tau / step, phase_shift_rad=phi)


def _tap_range_step(t: RawTransformer, vb_i: float) -> float:
    """Winding-1 tap step in pu of the bus-I base voltage (0 when there is no range)."""
    if t.ntp1 < 2 or not t.rma1 > t.rmi1:
        return 0.0
    if abs(t.cod1) in (3, 5):   # phase-shift control: RMA1/RMI1 are angles, not ratios
        return 0.0
    step = (t.rma1 - t.rmi1) / (t.ntp1 - 1)
    return _winding_ratio(t.cw, step, t.nomv1_kv, vb_i)


def governor_from_dyr(record: DyrRecord, *, mbase_mva: float | None = None) -> AbstractGovernor:
    """The governor module of a TGOV1, IEEEG1, GAST, HYGOV or GGOV1 record.

    ``mbase_mva`` (the machine's MBASE) is used by GGOV1 when Trate > 0 (its signals are then
    on the Trate base: ``base_ratio`` = Trate/MBASE). Invalid parameters (e.g. a zero time
    constant PSS/E does not allow) raise :class:`InputError` naming the record.
    """
    model = GOVERNORS.get(record.model)
    if model is None:
        raise record.error(f"is not a supported governor model ({', '.join(GOVERNORS)})")
    p = record.params
    kwargs = {f: p[name] for f, name in GOVERNOR_PARAMETERS[record.model].items()}
    try:
        if record.model == "GGOV1":
            ratio = 1.0
            if p["Trate"] > 0:
                if mbase_mva is None or not mbase_mva > 0:
                    raise ValueError("Trate > 0 needs the machine's MBASE (mbase_mva=...)")
                ratio = p["Trate"] / mbase_mva
            kwargs.update(rselect=int(p["Rselect"]), flag=int(p["Flag"]), base_ratio=ratio)
        return model(**kwargs)
    except ValueError as e:
        raise record.error(str(e)) from None


def load_unit(dyr: DyrData, raw: RawCase, bus: int, machine_id: str):
    """Convenience: (Machine kwargs, transient data, governor or None, GSU kwargs or None)
    of one generator, with the nominal frequency from the .raw BASFRQ."""
    rec = dyr.machine(bus, machine_id)
    if rec is None:
        raise InputError(dyr.source, f"no machine record for bus {bus} id {machine_id!r}")
    gen = raw.generator(bus, machine_id)
    kw = machine_kwargs(rec, gen, raw.bus_kv(bus), raw.basfrq_hz)
    gov_rec = dyr.governor(bus, machine_id)
    gov = governor_from_dyr(gov_rec, mbase_mva=gen.mbase_mva) if gov_rec is not None else None
    gsu = raw.step_up_transformer(bus)
    return kw, transient_data(rec), gov, (transformer_kwargs(gsu, raw) if gsu is not None else None)


__all__ = [
    "BIG_SHUNT_PU", "DEFAULT_TAP_STEP", "GENCLS_TD0_S", "GOVERNOR_FIELDS", "GOVERNOR_PARAMETERS",
    "MACHINE_FIELDS", "PSSE_GOVERNOR_MODELS", "SUPPORTED_RAW_REVISIONS", "TYPED_MODELS",
    "DyrData", "DyrRecord",
    "MachineTransientData", "RawBranch", "RawBus", "RawCase", "RawGenerator", "RawLoad",
    "RawTransformer", "generator_label", "governor_from_dyr", "load_unit", "machine_kwargs",
    "machine_problems", "merge_dyr", "parse_number", "q_axis_problems", "read_dyr", "read_raw",
    "record_label", "transformer_kwargs", "transformer_sides", "transient_data",
]
