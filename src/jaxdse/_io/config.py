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
                    every IdentifySettings field (settle_s, bootstrap_draws, spread_scales,
                    output_error, ...) and every VerdictSettings field (identified_ci, ...),
                    typed from the field: integers, true/false, numbers, lists of numbers
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
raise :class:`InputError` naming the key. The sections a fleet file shares with it are
validated by ``schema``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import equinox as eqx

from .._core.drem import ObserverConfig
from .._core.identify import IdentifySettings
from .._core.machine import Machine
from .._core.mapping import AuxiliarySystem, Line, Transformer
from .._core.plant import Plant
from .._core.settings import Settings
from .._core.tuning import AUTODIFF_MODES, TUNABLE, LossWeights
from .._core.verdict import VerdictSettings
from .._models.governors import GOVERNORS
from .errors import InputError
from .measurement import MeasurementSpec
from .schema import (
    governor_section,
    identify_section,
    machine_checks,
    measurement_section,
    module_section,
    no_unknown,
    options,
    positive_number,
    read_toml,
    settings_section,
    subtable,
    typed_value,
)

PLANT_MODULES = {"line": Line, "transformer": Transformer, "aux": AuxiliarySystem, "machine": Machine}
PLANT_SECTIONS = ("measurement", "line", "transformer", "aux", "machine", "governor")
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
    notes: tuple[str, ...] = ()
    """Plant data used as given but outside their typical range (one line each, naming the key
    or record and the value): in ``data_quality["plant_data"]`` and the verdict's reasons."""


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


def load_config(path) -> RunConfig:
    """Read and validate a TOML configuration file (relative paths are relative to it)."""
    path = Path(path)
    data = read_toml(path)
    return parse_config(data, path)


def parse_config(data: dict, path: Path) -> RunConfig:
    """Validate a parsed TOML document (see the module docstring)."""
    allowed = set(PLANT_SECTIONS) | {"observer", "settings", "output", "generator", "sweep", "tune",
                                     "plant_defaults", "identify"}
    if "case" in data:
        raise InputError(path, "this is a fleet file (it names a PSS/E [case]): use `jaxdse fleet "
                         f"{path}`; `jaxdse run` reads a run configuration", key="case")
    no_unknown(path, data, allowed, "")
    paper = data.get("plant_defaults")
    if paper not in (None, "paper"):
        raise InputError(path, f"must be \"paper\" (the paper's 1100 MVA, 50 Hz plant fills what the "
                         f"config leaves out), got {paper!r}", key="plant_defaults")
    base = {s: subtable(path, data, s, s) for s in PLANT_SECTIONS}
    gens = data.get("generator", [{}])
    if isinstance(gens, dict) or not isinstance(gens, list) or not gens:
        raise InputError(path, "must be an array of tables: [[generator]]", key="generator")

    observer = module_section(path, ObserverConfig, subtable(path, data, "observer", "observer"),
                              "observer")
    settings = settings_section(path, subtable(path, data, "settings", "settings"))
    out = subtable(path, data, "output", "output")
    no_unknown(path, out, set(OUTPUT_KEYS), "output.")
    for k, typ in OUTPUT_KEYS.items():
        if k in out:
            typed_value(path, typ, out[k], f"output.{k}")

    # The shared sections alone first, so that their errors name their own keys.
    for sec, cls in PLANT_MODULES.items():
        module_section(path, cls, base[sec], sec)
    base_notes = machine_checks(path, base["machine"], "")
    governor_section(path, base["governor"], "")
    measurement_section(path, base["measurement"], 50.0, "", partial=True)

    runs, names = [], set()
    for n, g in enumerate(gens):
        prefix = f"generator[{n}]." if "generator" in data else ""
        if not isinstance(g, dict):
            raise InputError(path, "must be a table", key=f"generator[{n}]")
        no_unknown(path, g, set(PLANT_SECTIONS) | {"name", "role", "a2_reference", "h_reference_s"},
                   prefix)
        merged = {s: {**base[s], **subtable(path, g, s, prefix + s)} for s in PLANT_SECTIONS}
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
                refs[k] = positive_number(path, g[k], prefix + k)
        defaults = _plant_defaults(path, merged, prefix, paper == "paper")
        own = subtable(path, g, "machine", prefix + "machine")
        notes = [n for n in base_notes if n.split(":")[0].removeprefix("machine.") not in own] + \
            (machine_checks(path, own, prefix) if prefix else [])
        machine = module_section(path, Machine, merged["machine"], "machine", prefix)
        plant = Plant(machine=machine,
                      line=module_section(path, Line, merged["line"], "line", prefix),
                      transformer=module_section(path, Transformer, merged["transformer"], "transformer",
                                                 prefix),
                      aux=module_section(path, AuxiliarySystem, merged["aux"], "aux", prefix),
                      governor=governor_section(path, merged["governor"], prefix),
                      s_base_mva=merged["measurement"].get("s_base_mva", 100.0))
        spec = measurement_section(path, merged["measurement"], float(machine.f_nominal_hz), prefix)
        p_max, source = plant_p_max(plant, merged, merged["governor"].get("model", "TGOV1"), defaults,
                                    "aux" in _sections_needed(spec.location))
        spec = dataclasses.replace(spec, p_max_mw=p_max, p_max_source=source)
        runs.append(GeneratorRun(name=name, role=role, measurement=spec, plant=plant,
                                 defaults_used=defaults, notes=tuple(notes), **refs))
    out_dir = Path(out.get("dir", "jaxdse_out"))
    identify, verdict = identify_section(path, subtable(path, data, "identify", "identify"))
    return RunConfig(path=path, generators=tuple(runs), observer=observer, settings=settings,
                     identify=identify, verdict=verdict,
                     out_dir=out_dir if out_dir.is_absolute() else path.parent / out_dir,
                     figures=out.get("figures", True), trajectories=out.get("trajectories", True),
                     sweep=_sweep(path, subtable(path, data, "sweep", "sweep"), observer),
                     tune=_tune(path, subtable(path, data, "tune", "tune")))


def _sections_needed(location: str) -> tuple[str, ...]:
    """The plant sections that the mapping from ``location`` to the rotor reads."""
    return ("machine", "governor") + (("transformer", "aux") if location != "terminal" else ()) + \
        (("line",) if location == "substation" else ())


def _plant_defaults(path, merged: dict, prefix: str, paper: bool) -> tuple[str, ...]:
    """No silent defaults: every plant section the location needs, and the machine's rating,
    must be in the config unless it opts into the paper's plant. Returns what was defaulted."""
    location = merged["measurement"].get("location", "substation")
    needed = _sections_needed(location)
    if not paper:   # everything missing in one message, not one per run
        sections = [sec for sec in PLANT_SECTIONS if sec in needed and not merged[sec]]
        rating = [k for k in MACHINE_RATING_KEYS if merged["machine"] and k not in merged["machine"]]
        if len(sections) + len(rating) == 1 and rating:
            raise InputError(path, "is required: the machine's rating (s_rated_mva, v_rated_kv, "
                             "f_nominal_hz) is never defaulted", key=f"{prefix}machine.{rating[0]}")
        if sections or rating:
            what = []
            if sections:
                what.append(f"no {_listing([f'[{sec}]' for sec in sections])} "
                            f"section{'s' if len(sections) > 1 else ''}, which a PMU at location = "
                            f"{location!r} needs" + (f" (for {prefix.rstrip('.')})" if prefix else ""))
            if "machine" in sections:
                what.append("[machine] needs the machine's rating (s_rated_mva, v_rated_kv, "
                            "f_nominal_hz)")
            elif rating:
                what.append(f"no {_listing([f'{prefix}machine.{k}' for k in rating])} (the machine's "
                            "rating is never defaulted)")
            raise InputError(path, "; ".join(what) + ": jaxdse does not guess plant data; give them, "
                             "or set plant_defaults = \"paper\" to use the paper's plant",
                             key=prefix + sections[0] if len(sections) == 1 and not rating else None)
    used = []
    for sec in needed:
        cls = GOVERNORS.get(merged["governor"].get("model", "TGOV1")) if sec == "governor" \
            else PLANT_MODULES[sec]
        if cls is None:
            continue  # an unknown governor model: governor_section names it
        used += [f"{sec}.{f.name}" for f in dataclasses.fields(cls)
                 if f.name not in merged[sec] and f.name not in ESTIMATED_MACHINE_KEYS]
    return tuple(used)


def _listing(items: list[str]) -> str:
    """"a", "a and b", "a, b and c"."""
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def governor_max_pu(governor) -> float | None:
    """The governor-turbine's largest steady mechanical power [pu of the machine (plant) base]:
    its own steady state at full reference, as each model defines it (TGOV1 VMAX, IEEEG1 PMAX
    (K1 + K3 + K5 + K7), GAST min(VMAX, AT), HYGOV At (GMAX - qNL), GGOV1 Kturb (VMAX - Wfnl)
    within its load limit; a plant's units summed with their MBASE shares). None: no bound (a
    unit of the plant without a governor record holds its torque whatever it is)."""
    try:
        tm = float(_full_torque(governor))
    except (TypeError, ValueError):   # a batched or traced governor: not checked
        return None
    return tm if 0 < tm < FULL_REFERENCE / 10 else None


@eqx.filter_jit
def _full_torque(governor):
    """Compiled once per governor structure: op by op, the ~300 plants of ACTIVSg2000 took 8 s."""
    return governor.torque(governor.steady_state(FULL_REFERENCE, 0.0), 0.0)


FULL_REFERENCE = 1e3
"""A torque (or speed) reference far beyond any limit [pu]: the governor's steady state there
is its maximum."""


def plant_p_max(plant: Plant, merged: dict, governor_model: str, defaults: tuple[str, ...],
                aux_needed: bool) -> tuple[float | None, str]:
    """The plant's stated maximum active power [MW] and where it comes from: the smaller of
    [aux] p_sg_max_mw (where the config gives it, or plant_defaults = "paper" fills the [aux]
    the PMU location needs) and the governor's maximum on the machine rating."""
    found = []
    if "p_sg_max_mw" in merged["aux"] or (aux_needed and "aux.p_sg_max_mw" in defaults):
        found.append((float(plant.aux.p_sg_max_mw), "[aux] p_sg_max_mw" + (
            "" if "p_sg_max_mw" in merged["aux"] else ", the paper's plant (plant_defaults)")))
    gm = governor_max_pu(plant.governor)
    if gm is not None:
        s = float(plant.machine.s_rated_mva)
        found.append((gm * s, f"the {governor_model} governor's maximum, {gm:.3g} pu of "
                      f"machine.s_rated_mva = {s:g} MVA"))
    return min(found) if found else (None, "")


def _param_names(path, names, key):
    allowed = set(ObserverConfig.__dataclass_fields__) | {"gamma"}
    for n in names:
        if n not in allowed:
            raise InputError(path, f"unknown observer parameter {n!r}; tunable: {', '.join(TUNABLE)}",
                             key=key)
    return names


def _sweep(path, table: dict, observer: ObserverConfig) -> dict:
    no_unknown(path, table, {"mode", "draws", "seed", "chunk", "parameters"}, "sweep.")
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
        values = [positive_number(path, v, key) for v in values]
        if mode == "random" and (len(values) != 2 or values[0] > values[1]):
            raise InputError(path, "random mode takes [low, high]", key=key)
    out = {"mode": mode, "parameters": params}
    for k, default in (("draws", 64), ("seed", 0), ("chunk", 256)):
        out[k] = typed_value(path, int, table.get(k, default), f"sweep.{k}", minimum=0 if k == "seed" else 1)
    return out


def _tune(path, table: dict) -> dict:
    no_unknown(path, table, {"parameters", "max_steps", "max_factor", "weights", "autodiff"}, "tune.")
    names = table.get("parameters", list(TUNABLE))
    if not isinstance(names, list) or not names:
        raise InputError(path, "must be a non-empty list of names", key="tune.parameters")
    _param_names(path, names, "tune.parameters")
    steps = typed_value(path, int, table.get("max_steps", 30), "tune.max_steps", minimum=1)
    factor = positive_number(path, table.get("max_factor", 10.0), "tune.max_factor")
    if factor <= 1:
        raise InputError(path, "must be > 1", key="tune.max_factor")
    autodiff = table.get("autodiff", "auto")
    if autodiff not in AUTODIFF_MODES:
        raise InputError(path, f"must be one of {', '.join(AUTODIFF_MODES)}", key="tune.autodiff")
    weights = table.get("weights", {})
    if not isinstance(weights, dict):
        raise InputError(path, "must be a table", key="tune.weights")
    w = options(path, LossWeights, weights, "tune.weights.", minimum=None)
    names = [n for n in names if n != "gamma"] + (["gamma1", "gamma2"] if "gamma" in names else [])
    return {"parameters": names, "max_steps": steps, "max_factor": factor, "autodiff": autodiff,
            "weights": LossWeights(**w)}
