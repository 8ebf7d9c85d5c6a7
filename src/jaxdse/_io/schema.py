"""The TOML schema shared by ``jaxdse run``'s config (``config``) and ``jaxdse fleet``'s fleet
file (``jaxdse._app.fleet_file``): reading the file, and one validator per section that both
have ([measurement], [governor], [observer] and the plant modules, [settings], [identify]).

Every mistake raises a one-line :class:`InputError` naming the file and the key. Options of a
settings dataclass are typed from its fields (:func:`field_types`, :func:`typed_value`): an
``int`` field takes an integer, a ``bool`` field true or false, a ``float`` field any finite
number, a ``tuple[float, ...]`` field a list of numbers, a ``Literal``/``Enum`` field one of
its words; a field added to the dataclass is a TOML key without a change here.
"""

from __future__ import annotations

import dataclasses
import enum
import math
import re
import tomllib
import types
import typing
import zoneinfo
from pathlib import Path

from .._core.identify import IdentifySettings
from .._core.integrate import Integrator
from .._core.settings import Settings
from .._core.verdict import VerdictSettings
from .._models.governors import GOVERNORS
from .errors import InputError
from .measurement import CHOICE_KEYS, COLUMN_ROLES, UNIT_KEYS, MeasurementSpec, spec_value_error
from .readers import CsvOptions

SETTINGS_KEYS = ("derivative_half_width", "qss_window_s", "convergence_band", "min_hold_s",
                 "min_log_contraction", "offline_current_pu")
"""The :class:`Settings` fields that [settings] sets (beside integrator = "adaptive" | "fast")."""
TEXT_KEYS = ("delimiter", "quotechar", "time_format", "timezone")
"""Keys of [measurement] that take a non-empty string."""
BASE_KEYS = ("v_base_kv", "s_base_mva", "frame_rate_hz")
"""Keys of [measurement] that take a number > 0."""
PLANT_SPEC_FIELDS = {"f_nominal_hz", "csv_options", "p_max_mw", "p_max_source"}
"""Fields of :class:`MeasurementSpec` that are not [measurement] keys (plant data, or the CSV
keys gathered)."""

TYPICAL_MACHINE = {
    # PSS/E name: (low, high, unit, run-config key of [machine] or None, source)
    "Xd": (0.6, 2.5, "pu", "xd_pu", "IEEE Std 1110-2002 (as issue 32 quotes it); Kundur: hydro "
           "0.6-1.5, thermal 1.0-2.3"),
    "Xq": (0.4, 2.5, "pu", "xq_pu", "Kundur: hydro 0.4-1.0, thermal 1.0-2.3 (upper end as Xd)"),
    "X'd": (0.1, 0.5, "pu", "xd1_pu", "IEEE Std 1110-2002 (as issue 32 quotes it); Kundur: hydro "
            "0.2-0.5, thermal 0.15-0.4"),
    "X'q": (0.2, 1.0, "pu", None, "Kundur: thermal 0.3-1.0 (lower end widened to 0.2)"),
    "X''d": (0.1, 0.45, "pu", None, "Kundur: X''d 0.12-0.35, X''q 0.12-0.45 (GENROU's X''d is also "
             "its X''q; lower end 0.1)"),
    "Xl": (0.05, 0.35, "pu", None, "Kundur: 0.1-0.2 (widened to 0.05-0.35)"),
    "Ra": (0.0, 0.02, "pu", "rs_pu", "Kundur: hydro 0.002-0.02, thermal 0.0015-0.005"),
    "T'do": (1.5, 15.0, "s", "td01_s", "IEEE Std 1110-2002 2-15 s (as issue 32 quotes it); Kundur: "
             "hydro 1.5-9, thermal 3-10"),
    "T'qo": (0.2, 3.0, "s", None, "Kundur: thermal 0.5-2.0 (widened to 0.2-3)"),
    "T''qo": (0.01, 0.2, "s", None, "Kundur: hydro 0.01-0.09, thermal 0.02-0.05 (upper end 0.2)"),
}
"""Typical ranges of machine data on the machine base (P. Kundur, *Power System Stability and
Control*, 1994, Table 4.2, hydro and thermal units; IEEE Std 1110-2002 for Xd, X'd and T'do, as
issue 32 quotes it). A value outside is flagged (``data_quality``, the verdict's reasons, the
fleet unit's notes) and used as given; a value more than ``IMPLAUSIBLE_FACTOR`` x the upper end
is refused (a reactance in percent, a time constant in ms). Only data the estimator uses are
checked (T''do is not: the q-axis circuits and the flux-decay d axis do without it)."""
TYPICAL_SOURCE = "IEEE Std 1110; Kundur 1994, Table 4.2"
"""The source named in the flag of a value outside its typical range."""
IMPLAUSIBLE_FACTOR = 10.0
"""A machine value above this x its typical upper end is a unit mistake, refused [-]."""


def machine_value_findings(values: dict) -> tuple[list[str], list[str]]:
    """Machine data (PSS/E names of :data:`TYPICAL_MACHINE` -> value on the machine base)
    against their typical ranges: (refused, flagged), one phrase each naming the quantity, the
    value, the range and the likely cause; the caller prefixes where the value came from."""
    refused, flagged = [], []
    for name, value in values.items():
        if name not in TYPICAL_MACHINE or value is None or not math.isfinite(value):
            continue
        lo, hi, unit = TYPICAL_MACHINE[name][:3]
        if lo <= value <= hi:
            continue
        if value > IMPLAUSIBLE_FACTOR * hi:
            factor, word = (100.0, "percent") if unit == "pu" else (1000.0, "milliseconds")
            fixed = value / factor
            guess = (f"looks like {word}: {value:g} -> {fixed:.3g} {unit}?" if lo / 2 <= fixed <= 2 * hi
                     else f"{word}, or another base?")
            refused.append(f"{name} = {value:g} {unit} is more than {IMPLAUSIBLE_FACTOR:g} x the typical "
                           f"upper end {hi:g} {unit}: {guess}")
        else:
            flagged.append(f"{name} = {value:g} {unit} is outside the typical {lo:g}-{hi:g} {unit} "
                           f"({TYPICAL_SOURCE}): used as given")
    return refused, flagged


def machine_checks(path, table: dict, prefix: str) -> list[str]:
    """[machine] of a run config against :data:`TYPICAL_MACHINE`: a value more than
    ``IMPLAUSIBLE_FACTOR`` x the typical range is an :class:`InputError` naming the key ("looks
    like percent: 180 -> 1.8 pu?"); the flags of values merely outside are returned, one line
    each, naming the key."""
    keys = {spec[3]: name for name, spec in TYPICAL_MACHINE.items() if spec[3]}
    flags = []
    for key, name in keys.items():
        if key not in table:
            continue
        refused, flagged = machine_value_findings({name: number(path, table[key], f"{prefix}machine.{key}")})
        if refused:
            raise InputError(path, refused[0], key=f"{prefix}machine.{key}")
        flags += [f"{prefix}machine.{key}: {f}" for f in flagged]
    return flags


def read_toml(path: Path) -> dict:
    """The TOML document at ``path``, or a one-line :class:`InputError` naming the file."""
    if not path.exists():
        raise InputError(path, "file does not exist")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise InputError(path, f"malformed TOML: {err}") from None
    except UnicodeDecodeError:
        raise InputError(path, "not a text file") from None


# --- single values ----------------------------------------------------------------------------

def subtable(path, data: dict, section: str, key: str) -> dict:
    """``data[section]`` (a table; {} when absent)."""
    value = data.get(section, {})
    if not isinstance(value, dict):
        raise InputError(path, "must be a table, e.g. [" + key + "]", key=key)
    return value


def no_unknown(path, table: dict, allowed, prefix: str) -> None:
    """Refuse a key of ``table`` that is not in ``allowed``, with the nearest allowed one."""
    for k in table:
        if k not in allowed:
            near = sorted(a for a in allowed if a[:3] == k[:3])
            hint = f"; did you mean {near[0]!r}?" if near else f"; allowed: {', '.join(sorted(allowed))}"
            raise InputError(path, "unknown key" + hint, key=prefix + k)


def number(path, value, key) -> float:
    """A finite number (an integer or a float; not a boolean)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(path, f"must be a number, got {value!r}", key=key)
    if not math.isfinite(value):
        raise InputError(path, f"must be finite, got {value!r}", key=key)
    return float(value)


def positive_number(path, value, key) -> float:
    x = number(path, value, key)
    if x <= 0:
        raise InputError(path, f"must be > 0, got {value!r}", key=key)
    return x


def reason(err: Exception) -> str:
    """"Line.r_pu must be >= 0, got -1" -> "must be >= 0, got -1" (the key is named apart)."""
    msg = str(err)
    return "must " + msg.split(" must ", 1)[1] if " must " in msg else msg


# --- typed options of a settings dataclass ----------------------------------------------------

def field_types(cls) -> dict[str, object]:
    """Field name -> type of the dataclass ``cls``: its annotation, resolved, or else the type
    of its default."""
    try:
        hints = typing.get_type_hints(cls)
    except (NameError, TypeError):
        hints = {}
    return {f.name: hints.get(f.name, object if f.default is dataclasses.MISSING else type(f.default))
            for f in dataclasses.fields(cls)}


def _describe(hint) -> str:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Literal:
        return "one of " + ", ".join(map(repr, args))
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        return "one of " + ", ".join(repr(m.name) for m in hint)
    if origin is tuple:
        plural = {bool: "booleans", int: "integers", float: "numbers", str: "strings"}
        return "a list of " + (plural.get(args[0], "values") if args else "values")
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(
        hint, getattr(hint, "__name__", str(hint)))


def typed_value(path, hint, value, key: str, minimum: float | None = None):
    """``value`` as TOML gives it, checked and converted to the type ``hint``; numbers (and the
    numbers of a list) must be >= ``minimum`` unless it is None."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):   # X | None: TOML has no None
        choices = [a for a in args if a is not type(None)]
        for a in choices[:-1]:
            try:
                return typed_value(path, a, value, key, minimum)
            except InputError:
                pass
        return typed_value(path, choices[-1], value, key, minimum)
    if origin is typing.Literal:
        for w in args:
            if type(value) is type(w) and value == w:
                return w
        raise InputError(path, f"must be {_describe(hint)}, got {value!r}", key=key)
    if isinstance(hint, type) and issubclass(hint, enum.Enum):
        for m in hint:
            if not isinstance(value, bool) and value in (m.name, m.value):
                return m
        raise InputError(path, f"must be {_describe(hint)}, got {value!r}", key=key)
    bound = "" if minimum is None else f" >= {minimum:g}"
    if hint is bool:
        if not isinstance(value, bool):
            raise InputError(path, f"must be true or false, got {value!r}", key=key)
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int) or \
                (minimum is not None and value < minimum):
            raise InputError(path, f"must be an integer{bound}, got {value!r}", key=key)
        return value
    if hint is float:
        x = number(path, value, key)
        if minimum is not None and x < minimum:
            raise InputError(path, f"must be{bound}, got {value!r}", key=key)
        return x
    if hint is str:
        if not isinstance(value, str) or not value:
            raise InputError(path, f"must be a non-empty string, got {value!r}", key=key)
        return value
    if origin is tuple:
        items = [args[0]] * len(value) if isinstance(value, list) and len(args) == 2 and \
            args[1] is Ellipsis else list(args)
        if not isinstance(value, list) or len(items) != len(value):
            size = "" if len(args) == 2 and args[1] is Ellipsis else f" of {len(args)}"
            raise InputError(path, f"must be {_describe(hint)}{bound}{size}, got {value!r}", key=key)
        return tuple(typed_value(path, t, v, f"{key}[{n}]", minimum)
                     for n, (t, v) in enumerate(zip(items, value)))
    raise InputError(path, f"cannot be set from TOML (a {_describe(hint)})", key=key)


def options(path, cls, table: dict, prefix: str, *, keys=None, minimum: float | None = 0) -> dict:
    """Keyword arguments of the dataclass ``cls`` from a TOML table, each typed from its field
    (``keys``: the fields allowed; default all). Numbers must be >= ``minimum``: settings are
    counts, durations, seeds and thresholds."""
    hints = field_types(cls)
    no_unknown(path, table, set(hints) if keys is None else set(keys), prefix)
    return {k: typed_value(path, hints[k], v, prefix + k, minimum) for k, v in table.items()}


def build(path, cls, kwargs: dict, key: str):
    """``cls(**kwargs)``, its own checks' ValueError as an InputError naming ``key``."""
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise InputError(path, reason(err), key=key) from None


# --- sections ---------------------------------------------------------------------------------

def module_section(path, cls, table: dict, section: str, prefix: str = ""):
    """An eqx.Module of numbers (a plant module, ObserverConfig) from a table, naming the
    offending key on any error."""
    fields = [f.name for f in dataclasses.fields(cls)]
    no_unknown(path, table, set(fields), prefix + section + ".")
    kwargs = {k: number(path, v, f"{prefix}{section}.{k}") for k, v in table.items()}
    for k, v in kwargs.items():
        build(path, cls, {k: v}, f"{prefix}{section}.{k}")
    return build(path, cls, kwargs, prefix + section)


def governor_section(path, table: dict, prefix: str):
    """[governor]: model = one of :data:`GOVERNORS` (default TGOV1) and its fields."""
    table = dict(table)
    model = table.pop("model", "TGOV1")
    if model not in GOVERNORS:
        raise InputError(path, f"unknown governor model {model!r}; available: {', '.join(GOVERNORS)}",
                         key=prefix + "governor.model")
    return module_section(path, GOVERNORS[model], table, "governor", prefix)


def settings_section(path, table: dict) -> Settings:
    """[settings]: integrator = "adaptive" | "fast" and the ``SETTINGS_KEYS`` of :class:`Settings`."""
    no_unknown(path, table, {*SETTINGS_KEYS, "integrator"}, "settings.")
    table = dict(table)
    integ = table.pop("integrator", "adaptive")
    if integ not in ("adaptive", "fast"):
        raise InputError(path, "must be 'adaptive' (Tsit5) or 'fast' (Heun, one step per sample)",
                         key="settings.integrator")
    kwargs = options(path, Settings, table, "settings.", keys=SETTINGS_KEYS)
    if kwargs.get("derivative_half_width", 1) < 1:
        raise InputError(path, f"must be an integer >= 1, got {kwargs['derivative_half_width']!r}",
                         key="settings.derivative_half_width")
    if integ == "fast":
        kwargs["observer_integrator"] = kwargs["playback_integrator"] = Integrator.fast()
    return dataclasses.replace(Settings(), **kwargs)


def identify_section(path, table: dict) -> tuple[IdentifySettings | None, VerdictSettings]:
    """[identify]: enabled, and every field of :class:`IdentifySettings` and :class:`VerdictSettings`."""
    id_types, v_types = field_types(IdentifySettings), field_types(VerdictSettings)
    no_unknown(path, table, set(id_types) | set(v_types) | {"enabled"}, "identify.")
    enabled = typed_value(path, bool, table.get("enabled", True), "identify.enabled")
    kw_id = options(path, IdentifySettings, {k: v for k, v in table.items() if k in id_types},
                    "identify.")
    kw_v = options(path, VerdictSettings, {k: v for k, v in table.items() if k in v_types},
                   "identify.")
    return (build(path, IdentifySettings, kw_id, "identify") if enabled else None), \
        build(path, VerdictSettings, kw_v, "identify")


def _check_timezone(path, name: str, key: str) -> None:
    if re.fullmatch(r"[+-]\d{2}:?\d{2}", name.strip()) or name.upper() == "UTC":
        return
    try:
        zoneinfo.ZoneInfo(name)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        raise InputError(path, f"unknown time zone {name!r}; use an IANA name such as "
                         "\"Europe/Berlin\", \"UTC\" or an offset \"+01:00\"", key=key) from None


def measurement_section(path, table: dict, f_nominal_hz: float, prefix: str,
                        partial: bool = False) -> MeasurementSpec | None:
    """Validate a [measurement] table (its CSV keys go to :class:`CsvOptions`); ``partial``
    checks keys and values but not completeness (and returns None)."""
    key = prefix + "measurement."
    csv_keys = {f.name for f in dataclasses.fields(CsvOptions)}
    hints = {**field_types(MeasurementSpec), **field_types(CsvOptions)}
    no_unknown(path, table, set(hints) - PLANT_SPEC_FIELDS, key)
    if partial:
        table = {"file": "-", "columns": {}, **table}
    if "file" not in table:
        raise InputError(path, "the recording file is required", key=key + "file")
    if "columns" not in table or not isinstance(table["columns"], dict):
        raise InputError(path, "a [measurement.columns] table is required", key=key + "columns")
    files = table["file"] if isinstance(table["file"], list) else [table["file"]]
    if not files or not all(isinstance(f, str) and f for f in files):
        raise InputError(path, "must be a file name or a list of file names", key=key + "file")
    files = tuple(str(p if Path(p).is_absolute() else path.parent / p) for p in files)
    columns = dict(table["columns"])
    for role, col in columns.items():
        if role not in COLUMN_ROLES:
            raise InputError(path, "unknown column role; use time, frequency, v_mag, v_ang, i_mag, "
                             "i_ang or v_a_mag ... i_c_ang", key=f"{key}columns.{role}")
        if isinstance(col, bool) or not isinstance(col, (str, int)):
            raise InputError(path, "must be a column name or a 0-based column number",
                             key=f"{key}columns.{role}")
    kwargs = {"file": files, "columns": columns, "f_nominal_hz": f_nominal_hz}
    for k, v in table.items():
        if k in ("file", "columns"):
            continue
        if k in CHOICE_KEYS or k in UNIT_KEYS:
            problem = spec_value_error(k, v)
            if problem:
                raise InputError(path, problem, key=key + k)
            kwargs[k] = v
        elif k in TEXT_KEYS:
            kwargs[k] = typed_value(path, str, v, key + k)
            if k == "time_format" and "%" not in v:
                raise InputError(path, f"must use strftime codes such as %Y-%m-%d %H:%M:%S.%f, got {v!r}",
                                 key=key + k)
            if k == "timezone":
                _check_timezone(path, v, key + k)
        elif k == "decimal":
            if v not in (".", ","):
                raise InputError(path, f"must be \".\" or \",\", got {v!r}", key=key + k)
            kwargs[k] = v
        elif k == "na_values":
            if not isinstance(v, list) or not all(isinstance(w, str) for w in v):
                raise InputError(path, "must be a list of words, e.g. [\"n/a\", \"---\"]", key=key + k)
            kwargs[k] = tuple(v)
        elif k in BASE_KEYS:
            kwargs[k] = positive_number(path, v, key + k)
        else:   # skip_rows, units_row, max_gap_s, min_segment_s, and any field added later
            kwargs[k] = typed_value(path, hints[k], v, key + k, minimum=0)
    if partial:
        return None
    csv = CsvOptions(**{k: kwargs.pop(k) for k in csv_keys if k in kwargs})
    return MeasurementSpec(**kwargs, csv_options=csv)
