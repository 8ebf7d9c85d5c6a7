"""TOML run configuration: one file describes the measurement(s), the plant and the observer.

Sections (every key optional unless marked; see ``examples/*.toml`` for commented files)::

    [measurement]   file*, format, columns* (table), location, units, bases, direction, gaps
    [line]          Line fields            [transformer]  Transformer fields
    [aux]           AuxiliarySystem fields [machine]      Machine fields
    [governor]      model = "TGOV1" and its fields
    [observer]      ObserverConfig fields (paper Table I by default)
    [settings]      convergence and derivative settings; integrator = "adaptive" | "fast"
    [sweep]         for ``jaxdse sweep``: mode = "grid" | "random", draws, seed, chunk and
                    parameters = {name = [values...]} (grid) or {name = [low, high]} (random,
                    log-uniform); "gamma" sets gamma1 = gamma2
    [tune]          for ``jaxdse tune``: parameters (list), max_steps, max_factor, autodiff =
                    "auto" | "fwd" | "bwd" and weights = {x2, playback, parameter,
                    burn_in_s, band}; role "auto"
                    generators train, role "cross" generators are held out
    [identify]      enabled (true: the batch identification runs after the online estimator),
                    settle_s, governor_smoothing_hz, robust_iterations, huber_k, hac_window_s,
                    and the verdict's identified_ci, not_identified_ci, max_condition,
                    diverged_smape
    [output]        dir, figures, trajectories
    [[generator]]   name*, role, a2_reference, h_reference_s, and per-generator tables
                    measurement, line, transformer, aux, machine, governor that override the
                    sections above (one entry per generator; none means one generator)
    plant_defaults  "paper": fill the plant data the config leaves out with the paper's plant

No silent defaults for plant data: the sections the PMU location needs (machine and governor;
transformer and aux from the HV side; line from the substation) and the machine's rating
(s_rated_mva, v_rated_kv, f_nominal_hz) must be given, unless ``plant_defaults = "paper"``.
Keys left out of a given section take the documented defaults; ``summary.json`` lists them.

The file is validated on load: unknown keys, missing required values and impossible values
raise :class:`InputError` naming the key.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path

from .._core.drem import ObserverConfig
from .._core.governor import GAST, GGOV1, HYGOV, IEEEG1, TGOV1
from .._core.identify import IdentifySettings
from .._core.integrate import Integrator
from .._core.machine import Machine
from .._core.mapping import AuxiliarySystem, Line, Transformer
from .._core.plant import Plant
from .._core.settings import Settings
from .._core.verdict import VerdictSettings
from .._many.tune import AUTODIFF_MODES, TUNABLE, LossWeights
from .errors import InputError
from .measurement import CHOICE_KEYS, COLUMN_ROLES, UNIT_KEYS, MeasurementSpec, spec_value_error

PLANT_MODULES = {"line": Line, "transformer": Transformer, "aux": AuxiliarySystem, "machine": Machine}
GOVERNORS = {"TGOV1": TGOV1, "IEEEG1": IEEEG1, "GAST": GAST, "HYGOV": HYGOV, "GGOV1": GGOV1}
PLANT_SECTIONS = ("measurement", "line", "transformer", "aux", "machine", "governor")
SETTINGS_KEYS = {"derivative_half_width": int, "qss_window_s": float, "convergence_band": float,
                 "min_hold_s": float, "min_log_contraction": float, "offline_current_pu": float}
OUTPUT_KEYS = {"dir": str, "figures": bool, "trajectories": bool}
MACHINE_RATING_KEYS = ("s_rated_mva", "v_rated_kv", "f_nominal_hz")
ESTIMATED_MACHINE_KEYS = ("h_s", "d_pu_s")
"""Machine fields that the estimator never reads (it estimates them; the simulator uses them)."""
ROLES = ("auto", "cross", "estimate")


@dataclass(frozen=True)
class GeneratorRun:
    """One generator of a run: its measurement, its plant and what is known about it."""

    name: str
    role: str
    measurement: MeasurementSpec
    plant: Plant
    a2_reference: float | None = None
    h_reference_s: float | None = None
    defaults_used: tuple[str, ...] = ()
    """Plant values the config left out, taken from the defaults ("section.key")."""


@dataclass(frozen=True)
class RunConfig:
    """A validated configuration file."""

    path: Path
    generators: tuple[GeneratorRun, ...]
    observer: ObserverConfig
    settings: Settings
    out_dir: Path
    figures: bool = True
    trajectories: bool = True
    identify: IdentifySettings | None = IdentifySettings()
    """Batch identification after the online estimator; None: off ([identify] enabled = false)."""
    verdict: VerdictSettings = VerdictSettings()
    """Thresholds of the verdict."""
    sweep: dict = dataclasses.field(default_factory=dict)
    """Validated [sweep] table (see :func:`jaxdse.sweep_configs`)."""
    tune: dict = dataclasses.field(default_factory=dict)
    """Validated [tune] table."""


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


def load_config(path) -> RunConfig:
    """Read and validate a TOML configuration file (relative paths are relative to it)."""
    path = Path(path)
    data = read_toml(path)
    return parse_config(data, path)


def parse_config(data: dict, path: Path) -> RunConfig:
    """Validate a parsed TOML document (see the module docstring)."""
    allowed = set(PLANT_SECTIONS) | {"observer", "settings", "output", "generator", "sweep", "tune",
                                     "plant_defaults", "identify"}
    _no_unknown(path, data, allowed, "")
    paper = data.get("plant_defaults")
    if paper not in (None, "paper"):
        raise InputError(path, f"must be \"paper\" (the paper's 1100 MVA, 50 Hz plant fills what the "
                         f"config leaves out), got {paper!r}", key="plant_defaults")
    base = {s: _table(path, data, s, s) for s in PLANT_SECTIONS}
    gens = data.get("generator", [{}])
    if isinstance(gens, dict) or not isinstance(gens, list) or not gens:
        raise InputError(path, "must be an array of tables: [[generator]]", key="generator")

    observer = _module(path, ObserverConfig, _table(path, data, "observer", "observer"), "observer")
    settings = _settings(path, _table(path, data, "settings", "settings"))
    out = _table(path, data, "output", "output")
    _no_unknown(path, out, set(OUTPUT_KEYS), "output.")
    for k, typ in OUTPUT_KEYS.items():
        if k in out and not isinstance(out[k], typ):
            raise InputError(path, f"must be a {typ.__name__}", key=f"output.{k}")

    # The shared sections alone first, so that their errors name their own keys.
    for sec, cls in PLANT_MODULES.items():
        _module(path, cls, base[sec], sec)
    _governor(path, base["governor"], "")
    _measurement(path, base["measurement"], 50.0, "", partial=True)

    runs, names = [], set()
    for n, g in enumerate(gens):
        prefix = f"generator[{n}]." if "generator" in data else ""
        if not isinstance(g, dict):
            raise InputError(path, "must be a table", key=f"generator[{n}]")
        _no_unknown(path, g, set(PLANT_SECTIONS) | {"name", "role", "a2_reference", "h_reference_s"},
                    prefix)
        merged = {s: {**base[s], **_table(path, g, s, prefix + s)} for s in PLANT_SECTIONS}
        if "columns" in base["measurement"] and "columns" in g.get("measurement", {}):
            merged["measurement"]["columns"] = {**base["measurement"]["columns"],
                                                **g["measurement"]["columns"]}
        name = g.get("name", "generator" if len(gens) == 1 else None)
        if not isinstance(name, str) or not name.strip():
            raise InputError(path, "every [[generator]] needs a name (a string)", key=prefix + "name")
        if name in names:
            raise InputError(path, f"generator name {name!r} is used twice", key=prefix + "name")
        names.add(name)
        role = g.get("role", "estimate")
        if role not in ROLES:
            raise InputError(path, f"must be one of {', '.join(ROLES)}", key=prefix + "role")
        refs = {}
        for k in ("a2_reference", "h_reference_s"):
            if k in g:
                refs[k] = _positive_number(path, g[k], prefix + k)
        defaults = _plant_defaults(path, merged, prefix, paper == "paper")
        machine = _module(path, Machine, merged["machine"], "machine", prefix)
        plant = Plant(machine=machine,
                      line=_module(path, Line, merged["line"], "line", prefix),
                      transformer=_module(path, Transformer, merged["transformer"], "transformer", prefix),
                      aux=_module(path, AuxiliarySystem, merged["aux"], "aux", prefix),
                      governor=_governor(path, merged["governor"], prefix),
                      s_base_mva=merged["measurement"].get("s_base_mva", 100.0))
        spec = _measurement(path, merged["measurement"], float(machine.f_nominal_hz), prefix)
        runs.append(GeneratorRun(name=name, role=role, measurement=spec, plant=plant,
                                 defaults_used=defaults, **refs))
    out_dir = Path(out.get("dir", "jaxdse_out"))
    identify, verdict = _identify(path, _table(path, data, "identify", "identify"))
    return RunConfig(path=path, generators=tuple(runs), observer=observer, settings=settings,
                     identify=identify, verdict=verdict,
                     out_dir=out_dir if out_dir.is_absolute() else path.parent / out_dir,
                     figures=out.get("figures", True), trajectories=out.get("trajectories", True),
                     sweep=_sweep(path, _table(path, data, "sweep", "sweep"), observer),
                     tune=_tune(path, _table(path, data, "tune", "tune")))


def _sections_needed(location: str) -> tuple[str, ...]:
    """The plant sections that the mapping from ``location`` to the rotor reads."""
    return ("machine", "governor") + (("transformer", "aux") if location != "terminal" else ()) + \
        (("line",) if location == "substation" else ())


def _plant_defaults(path, merged: dict, prefix: str, paper: bool) -> tuple[str, ...]:
    """No silent defaults: every plant section the location needs, and the machine's rating,
    must be in the config unless it opts into the paper's plant. Returns what was defaulted."""
    location = merged["measurement"].get("location", "substation")
    needed = _sections_needed(location)
    if not paper:
        for sec in needed:
            if not merged[sec]:
                raise InputError(path, f"no [{sec}] section, which a PMU at location = {location!r} "
                                 "needs: jaxdse does not guess plant data; give it, or set "
                                 "plant_defaults = \"paper\" to use the paper's plant",
                                 key=prefix + sec)
        for k in MACHINE_RATING_KEYS:
            if k not in merged["machine"]:
                raise InputError(path, "is required: the machine's rating (s_rated_mva, "
                                 "v_rated_kv, f_nominal_hz) is never defaulted", key=f"{prefix}machine.{k}")
    used = []
    for sec in needed:
        cls = GOVERNORS.get(merged["governor"].get("model", "TGOV1")) if sec == "governor" \
            else PLANT_MODULES[sec]
        if cls is None:
            continue  # an unknown governor model: _governor names it
        used += [f"{sec}.{f.name}" for f in dataclasses.fields(cls)
                 if f.name not in merged[sec] and f.name not in ESTIMATED_MACHINE_KEYS]
    return tuple(used)


def _param_names(path, names, key):
    allowed = set(ObserverConfig.__dataclass_fields__) | {"gamma"}
    for n in names:
        if n not in allowed:
            raise InputError(path, f"unknown observer parameter {n!r}; tunable: {', '.join(TUNABLE)}",
                             key=key)
    return names


def _identify(path, table: dict):
    """[identify]: enabled, the IdentifySettings fields and the VerdictSettings fields."""
    id_fields = {f.name for f in dataclasses.fields(IdentifySettings)}
    v_fields = {f.name for f in dataclasses.fields(VerdictSettings)}
    _no_unknown(path, table, id_fields | v_fields | {"enabled"}, "identify.")
    enabled = table.get("enabled", True)
    if not isinstance(enabled, bool):
        raise InputError(path, f"must be true or false, got {enabled!r}", key="identify.enabled")
    kw_id, kw_v = {}, {}
    for k, v in table.items():
        if k == "enabled":
            continue
        if k == "robust_iterations":
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise InputError(path, f"must be an integer >= 0, got {v!r}", key=f"identify.{k}")
            kw_id[k] = v
            continue
        (kw_id if k in id_fields else kw_v)[k] = _positive_number(path, v, f"identify.{k}")
    return (IdentifySettings(**kw_id) if enabled else None), VerdictSettings(**kw_v)


def _sweep(path, table: dict, observer: ObserverConfig) -> dict:
    _no_unknown(path, table, {"mode", "draws", "seed", "chunk", "parameters"}, "sweep.")
    mode = table.get("mode", "grid")
    if mode not in ("grid", "random"):
        raise InputError(path, "must be 'grid' or 'random'", key="sweep.mode")
    params = table.get("parameters", {})
    if not isinstance(params, dict):
        raise InputError(path, "must be a table {name = [values]}", key="sweep.parameters")
    _param_names(path, list(params), "sweep.parameters")
    for name, values in params.items():
        key = f"sweep.parameters.{name}"
        if not isinstance(values, list) or not values:
            raise InputError(path, "must be a non-empty list of numbers", key=key)
        values = [_positive_number(path, v, key) for v in values]
        if mode == "random" and (len(values) != 2 or values[0] > values[1]):
            raise InputError(path, "random mode takes [low, high]", key=key)
    out = {"mode": mode, "parameters": params}
    for k, default in (("draws", 64), ("seed", 0), ("chunk", 256)):
        v = table.get(k, default)
        if isinstance(v, bool) or not isinstance(v, int) or v < (0 if k == "seed" else 1):
            raise InputError(path, "must be a positive integer", key=f"sweep.{k}")
        out[k] = v
    return out


def _tune(path, table: dict) -> dict:
    _no_unknown(path, table, {"parameters", "max_steps", "max_factor", "weights", "autodiff"}, "tune.")
    names = table.get("parameters", list(TUNABLE))
    if not isinstance(names, list) or not names:
        raise InputError(path, "must be a non-empty list of names", key="tune.parameters")
    _param_names(path, names, "tune.parameters")
    steps = table.get("max_steps", 30)
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise InputError(path, "must be a positive integer", key="tune.max_steps")
    factor = _positive_number(path, table.get("max_factor", 10.0), "tune.max_factor")
    if factor <= 1:
        raise InputError(path, "must be > 1", key="tune.max_factor")
    autodiff = table.get("autodiff", "auto")
    if autodiff not in AUTODIFF_MODES:
        raise InputError(path, f"must be one of {', '.join(AUTODIFF_MODES)}", key="tune.autodiff")
    weights = table.get("weights", {})
    if not isinstance(weights, dict):
        raise InputError(path, "must be a table", key="tune.weights")
    _no_unknown(path, weights, set(LossWeights.__dataclass_fields__), "tune.weights.")
    w = {k: _number(path, v, f"tune.weights.{k}") for k, v in weights.items()}
    names = [n for n in names if n != "gamma"] + (["gamma1", "gamma2"] if "gamma" in names else [])
    return {"parameters": names, "max_steps": steps, "max_factor": factor, "autodiff": autodiff,
            "weights": LossWeights(**w)}


def _table(path, data, section, key) -> dict:
    value = data.get(section, {})
    if not isinstance(value, dict):
        raise InputError(path, "must be a table, e.g. [" + key + "]", key=key)
    return value


def _no_unknown(path, table: dict, allowed: set, prefix: str):
    for k in table:
        if k not in allowed:
            near = sorted(a for a in allowed if a[:3] == k[:3])
            hint = f"; did you mean {near[0]!r}?" if near else f"; allowed: {', '.join(sorted(allowed))}"
            raise InputError(path, "unknown key" + hint, key=prefix + k)


def _number(path, value, key) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InputError(path, f"must be a number, got {value!r}", key=key)
    if not math.isfinite(value):
        raise InputError(path, f"must be finite, got {value!r}", key=key)
    return float(value)


def _positive_number(path, value, key) -> float:
    x = _number(path, value, key)
    if x <= 0:
        raise InputError(path, f"must be > 0, got {value!r}", key=key)
    return x


def _module(path, cls, table: dict, section: str, prefix: str = ""):
    """Build an eqx.Module from a table, naming the offending key on any error."""
    fields = [f.name for f in dataclasses.fields(cls)]
    _no_unknown(path, table, set(fields), prefix + section + ".")
    kwargs = {k: _number(path, v, f"{prefix}{section}.{k}") for k, v in table.items()}
    for k, v in kwargs.items():
        try:
            cls(**{k: v})
        except ValueError as err:
            raise InputError(path, _reason(err), key=f"{prefix}{section}.{k}") from None
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise InputError(path, _reason(err), key=f"{prefix}{section}") from None


def _reason(err: Exception) -> str:
    """"Line.r_pu must be >= 0, got -1" -> "must be >= 0, got -1" (the key is named apart)."""
    msg = str(err)
    return "must " + msg.split(" must ", 1)[1] if " must " in msg else msg


def _governor(path, table: dict, prefix: str):
    table = dict(table)
    model = table.pop("model", "TGOV1")
    if model not in GOVERNORS:
        raise InputError(path, f"unknown governor model {model!r}; available: {', '.join(GOVERNORS)}",
                         key=prefix + "governor.model")
    return _module(path, GOVERNORS[model], table, "governor", prefix)


def _check_timezone(path, name: str, key: str) -> None:
    import re
    import zoneinfo

    if re.fullmatch(r"[+-]\d{2}:?\d{2}", name.strip()) or name.upper() == "UTC":
        return
    try:
        zoneinfo.ZoneInfo(name)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        raise InputError(path, f"unknown time zone {name!r}; use an IANA name such as "
                         "\"Europe/Berlin\", \"UTC\" or an offset \"+01:00\"", key=key) from None


def _settings(path, table: dict) -> Settings:
    _no_unknown(path, table, set(SETTINGS_KEYS) | {"integrator"}, "settings.")
    kwargs = {}
    table = dict(table)
    integ = table.pop("integrator", "adaptive")
    if integ not in ("adaptive", "fast"):
        raise InputError(path, "must be 'adaptive' (Tsit5) or 'fast' (Heun, one step per sample)",
                         key="settings.integrator")
    if integ == "fast":
        kwargs["observer_integrator"] = kwargs["playback_integrator"] = Integrator.fast()
    for k, v in table.items():
        if SETTINGS_KEYS[k] is int:
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise InputError(path, f"must be a positive integer, got {v!r}", key=f"settings.{k}")
            kwargs[k] = v
        else:
            kwargs[k] = _number(path, v, f"settings.{k}")
            if kwargs[k] < 0:
                raise InputError(path, f"must be >= 0, got {v!r}", key=f"settings.{k}")
    return dataclasses.replace(Settings(), **kwargs)


def _measurement(path, table: dict, f_nominal_hz: float, prefix: str,
                 partial: bool = False) -> MeasurementSpec | None:
    """Validate a [measurement] table; ``partial`` checks keys and values but not completeness."""
    key = prefix + "measurement."
    fields = {f.name: f for f in dataclasses.fields(MeasurementSpec)}
    allowed = set(fields) - {"f_nominal_hz"}
    _no_unknown(path, table, allowed, key)
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
        elif k in ("delimiter", "quotechar", "time_format", "timezone"):
            if not isinstance(v, str) or not v:
                raise InputError(path, f"must be a non-empty string, got {v!r}", key=key + k)
            if k == "time_format" and "%" not in v:
                raise InputError(path, f"must use strftime codes such as %Y-%m-%d %H:%M:%S.%f, got {v!r}",
                                 key=key + k)
            if k == "timezone":
                _check_timezone(path, v, key + k)
            kwargs[k] = v
        elif k == "decimal":
            if v not in (".", ","):
                raise InputError(path, f"must be \".\" or \",\", got {v!r}", key=key + k)
            kwargs[k] = v
        elif k == "na_values":
            if not isinstance(v, list) or not all(isinstance(w, str) for w in v):
                raise InputError(path, "must be a list of words, e.g. [\"n/a\", \"---\"]", key=key + k)
            kwargs[k] = tuple(v)
        elif k == "skip_rows":
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise InputError(path, f"must be an integer >= 0, got {v!r}", key=key + k)
            kwargs[k] = v
        elif k == "units_row":
            if not isinstance(v, bool):
                raise InputError(path, f"must be true or false, got {v!r}", key=key + k)
            kwargs[k] = v
        elif k in ("max_gap_s", "min_segment_s"):
            kwargs[k] = _number(path, v, key + k)
            if kwargs[k] < 0:
                raise InputError(path, f"must be >= 0, got {v!r}", key=key + k)
        else:  # v_base_kv, s_base_mva, frame_rate_hz
            kwargs[k] = _positive_number(path, v, key + k)
    return None if partial else MeasurementSpec(**kwargs)
