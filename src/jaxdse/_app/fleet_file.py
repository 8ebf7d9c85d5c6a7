"""The fleet file (TOML) of ``jaxdse fleet``: the PSS/E case, the recordings and how each
plant's channels are found ([channels] patterns or [[unit]] tables), validated on load.

Sections: [case] raw*, dyr*; [measurement] (as ``jaxdse run``'s, location "terminal" or
"hv"); [channels] or [[unit]]; [observer], [settings], [identify] (as ``jaxdse run``'s);
[criteria] the model validation's pass/fail limits; [output] figures; [inertia] the system
inertia per area (:mod:`jaxdse._io.inertia`).

A fleet never aborts for one unit: a plant whose case data are malformed, missing or
implausible, or whose recording lacks one of its columns, is listed in ``Fleet.skipped`` with
the reason (one line) and the others load; a plant that runs on a fallback lists it in
``FleetPlant.fallbacks``. Only a fleet file, a case or a recording that cannot be read at all,
or a fleet with no usable plant, raises :class:`InputError`.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

from .._core.drem import ObserverConfig
from .._core.identify import IdentifySettings
from .._core.settings import Settings
from .._core.verdict import VerdictSettings
from .._dyr.repair import carried_lines, carried_raw_lines
from .._dyr.records import ibr_model
from .._io.config import GeneratorRun
from .._io.errors import InputError
from .._io.inertia import InertiaConfig, inertia_section
from .._io.psse import DyrData, RawCase, merge_dyr, read_dyr, read_raw
from .._io.readers import load_table
from .._io.schema import (
    build,
    identify_section,
    measurement_section,
    module_section,
    no_unknown,
    options,
    read_toml,
    settings_section,
    subtable,
    typed_value,
)
from .dyr_fleet import CalibrateOptions, PlaybackOptions
from .fleet_plants import (
    Member,
    PlantUnits,
    generator_run,
    governor_sets,
    governor_slots,
    ibr_generator_run,
    ibr_members,
    plant_units,
)
from .windows import WindowCriteria

LAYOUTS = ("per_machine", "step_up_branch")
"""How plants and their columns are found from [channels] (see ``FLEET_HELP`` in the CLI)."""
ROLES = ("time", "frequency", "v_mag", "v_ang", "i_mag", "i_ang")
TOP = {"case", "measurement", "channels", "unit", "observer", "settings", "identify", "criteria",
       "output", "playback", "calibrate", "inertia"}


@dataclasses.dataclass(frozen=True)
class FleetPlant:
    """One plant of the fleet: its units, its columns and the :class:`GeneratorRun` built from them."""

    name: str
    bus: int
    members: tuple[Member, ...]
    others: tuple[str, ...]
    """In-service units on the bus without a machine record (renewables, ...)."""
    run: GeneratorRun
    fallbacks: tuple[str, ...] = ()
    """What the plant runs on instead of its case data, and the case records it ignores: one
    line each, naming the record and the values, e.g. "GENROU on bus 3 id '1' (case.dyr line
    7): X''d = 0.12 below Xl = 0.15: q-axis circuits left out (transient model)", "...: no
    governor record; constant mechanical torque", "...: a second machine record for this
    machine; the first (GENROU at line 7) is used". Empty for a plant that runs on its data."""
    data_warnings: tuple[str, ...] = ()
    """Odd values in the plant's records that are used as given (their equations can be
    evaluated), one line each naming the record and the values, e.g. "GENROU on bus 3 id '1'
    (case.dyr line 7): X''d = 0.12 below Xl = 0.15 (used as given; PSS/E warns and simulates
    it)". The fleet.json entry's ``data_warnings``; the unit page lists them."""
    repairs: tuple[str, ...] = ()
    """The changes ``jaxdse check --repair`` made to the plant's records (the .dyr's
    ``/ jaxdse repair:`` lines), one line each naming the record, the CON, the original and the
    repaired value and why. The fleet.json entry's ``repairs``; the unit page lists them."""
    ibr: bool = False
    """An inverter-based plant (its units' records REGCA1, REECA1, ...; no machine record): no
    rotor, so no H or D; validated by its own records' playback (P against frequency, Q against
    voltage)."""


@dataclasses.dataclass(frozen=True)
class Fleet:
    """A validated fleet file: the case, the plants, and the estimator's settings."""

    path: Path
    raw: RawCase
    dyr: DyrData
    plants: tuple[FleetPlant, ...]
    skipped: tuple[dict, ...]
    observer: ObserverConfig
    settings: Settings
    identify: IdentifySettings | None
    verdict: VerdictSettings
    criteria: dict
    """[criteria]: the limits of the model validation (fleet.json "validation"), the
    :class:`~jaxdse._app.windows.WindowCriteria` as a dict; H's verdict has its own thresholds
    ([identify])."""
    figures: bool = True
    playback: PlaybackOptions = PlaybackOptions()
    """[playback]: the surrogate or the units' own .dyr models."""
    calibrate: CalibrateOptions = CalibrateOptions()
    """[calibrate]: events, parameters and bounds of ``jaxdse validate``."""
    inertia: InertiaConfig | None = None
    """[inertia]: the system inertia per area (None: not asked for)."""
    notes: tuple[str, ...] = ()
    """Records of the .raw/.dyr that were dropped or not used and belong to no plant (e.g. a
    .dyr record without a readable bus number): one line each."""


# --- reading the fleet file -------------------------------------------------------------------

def load_fleet(path) -> Fleet:
    """Read and validate a fleet file, the PSS/E case it names and the recordings' headers."""
    path = Path(path)
    data = read_toml(path)
    if "case" not in data:   # most likely a run configuration
        extra = sorted(set(data) - TOP)
        raise InputError(path, "no [case] naming the PSS/E .raw and .dyr: this is not a fleet file"
                         + (f" but a run configuration (it has {', '.join(extra)})" if extra else "")
                         + f"; use `jaxdse run {path}`, or add [case]", key="case")
    no_unknown(path, data, TOP, "")
    inertia = inertia_section(path, data["inertia"]) if "inertia" in data else None
    case = subtable(path, data, "case", "case")
    no_unknown(path, case, {"raw", "dyr", "q_axis_circuits"}, "case.")
    # false: the estimator leaves every GENROU/GENTPJ's q-axis circuits out (the transient model),
    # as it once did for records it could not order; for comparison (the verdict says so)
    q_axis = typed_value(path, bool, case.get("q_axis_circuits", True), "case.q_axis_circuits")
    files = {}
    for k in ("raw", "dyr"):
        value = case.get(k)
        names = value if k == "dyr" and isinstance(value, list) and value else [value]
        if not all(isinstance(n, str) and n for n in names):
            raise InputError(path, f"the PSS/E .{k} file is required (a path, relative to this file"
                             + ("; or a list of .dyr files, later records replacing earlier ones of "
                                "the same machine and model, e.g. a calibrated.dyr" if k == "dyr" else "")
                             + ")", key=f"case.{k}")
        files[k] = [Path(n) if Path(n).is_absolute() else path.parent / n for n in names]
    raw = read_raw(files["raw"][0], strict=False)
    dyr = merge_dyr(*(read_dyr(f, strict=False) for f in files["dyr"]))
    meas = dict(subtable(path, data, "measurement", "measurement"))
    if meas.get("location", "terminal") not in ("terminal", "hv"):
        raise InputError(path, "a fleet's PMUs are at the machine terminal or on the HV side of "
                         "the step-up transformer: use \"terminal\" or \"hv\" (the line to a "
                         "substation is not in the case)", key="measurement.location")
    meas.setdefault("location", "terminal")
    measurement_section(path, {k: v for k, v in meas.items() if k != "columns"}, raw.basfrq_hz, "",
                        partial=True)
    out = subtable(path, data, "output", "output")
    no_unknown(path, out, {"figures"}, "output.")
    figures = typed_value(path, bool, out.get("figures", True), "output.figures")
    criteria = dataclasses.asdict(WindowCriteria(**options(
        path, WindowCriteria, subtable(path, data, "criteria", "criteria"), "criteria.")))
    shared = measurement_section(path, {**meas, "columns": {}}, raw.basfrq_hz, "")
    table = load_table(list(shared.file), shared.format, csv_options=shared.csv_options)
    if "unit" in data:
        found, skipped = _explicit_units(path, data["unit"], raw, list(table.columns))
    else:
        found, skipped = _pattern_units(path, subtable(path, data, "channels", "channels"), raw,
                                        dyr, list(table.columns))
    candidates = []
    for name, bus, ids, columns, direction in found:
        units = plant_units(raw, dyr, bus, ids, q_axis_circuits=q_axis)
        why = units.skip_reason()
        ibr = ibr_members(raw, dyr, bus, ids) if not units.units and not units.problems else []
        if ibr:   # an inverter-based plant: its own records only (no rotor)
            missing = [line for m in ibr for line in ibr_model(dyr, bus, m.id, raw).missing
                       if "is not simulated" not in line]   # a model not simulated: the plant, not judged
            why = (None if not missing else "an inverter-based plant whose records cannot be played "
                   f"back ({missing[0]}) and which has no rotor to estimate")
        if why is None:
            try:
                spec = measurement_section(path, {**meas, "columns": columns,
                                                  **({"current_direction": direction} if direction else {})},
                                           raw.basfrq_hz, "")
            except InputError as e:
                why = str(e)
        if why is not None:
            skipped.append(_skip(name, bus, why, ids))
            continue
        candidates.append((name, bus, ibr or units, spec))
    slots = governor_slots([governor_sets(c[2].units) for c in candidates if isinstance(c[2], PlantUnits)])
    built = []
    for name, bus, units, spec in candidates:
        if not isinstance(units, PlantUnits):
            try:
                run = ibr_generator_run(name, bus, units, spec, raw, slots)
            except (InputError, ValueError, ArithmeticError) as e:
                skipped.append(_skip(name, bus, f"plant data: {e}", [m.id for m in units]))
                continue
            built.append(FleetPlant(name, bus, tuple(units), (), run, ibr=True,
                                    repairs=tuple(carried_lines(r for m in units
                                                                for r in dyr.unit_records(bus, m.id)))))
            continue
        try:
            run, notes = generator_run(name, bus, units.units, spec, raw, slots)
        except (InputError, ValueError, ArithmeticError) as e:   # a check missed: still one plant
            skipped.append(_skip(name, bus, f"plant data: {e}", [m.id for m in units.members]))
            continue
        built.append(FleetPlant(name, bus, tuple(units.members), tuple(units.others), run,
                                fallbacks=tuple(_one_line(n) for n in (*units.notes, *notes)),
                                data_warnings=tuple(_one_line(n) for n in units.data_warnings),
                                repairs=tuple([*(line for m in units.members
                                                 for line in carried_raw_lines(raw.generator(bus, m.id))),
                                               *carried_lines(r for m in units.members
                                                              for r in dyr.unit_records(bus, m.id))])))
    if not built:
        if skipped:
            first = skipped[0]
            raise InputError(path, f"no usable plant: all {len(skipped)} plant(s) found are skipped "
                             f"(first: {first['name']}: {first['reason']})")
        raise InputError(path, "no plant found: check [channels] (or [[unit]]) against the "
                         "recording's column names and the case's generators", key="channels")
    identify, verdict = identify_section(path, subtable(path, data, "identify", "identify"))
    playback = build(path, PlaybackOptions, options(
        path, PlaybackOptions, subtable(path, data, "playback", "playback"), "playback.", minimum=1),
        "playback")
    calibrate = calibrate_section(path, subtable(path, data, "calibrate", "calibrate"))
    return Fleet(path=path, raw=raw, dyr=dyr, plants=tuple(built), skipped=tuple(skipped),
                 observer=module_section(path, ObserverConfig,
                                         subtable(path, data, "observer", "observer"), "observer"),
                 settings=settings_section(path, subtable(path, data, "settings", "settings")),
                 identify=identify, verdict=verdict, criteria=criteria, figures=figures,
                 playback=playback, calibrate=calibrate,
                 inertia=inertia,
                 notes=tuple(_one_line(n) for n in (*raw.problems, *dyr.problems)))


def calibrate_section(path: Path, table: dict) -> CalibrateOptions:
    """[calibrate]: event files (relative to the fleet file), parameter names, bounds, numbers."""
    table = dict(table)
    events = table.pop("events", [])
    if not isinstance(events, list) or not all(isinstance(e, str) and e for e in events):
        raise InputError(path, "must be a list of recording files", key="calibrate.events")
    files = []
    for e in events:
        f = Path(e) if Path(e).is_absolute() else path.parent / e
        if not f.is_file():
            raise InputError(path, f"no such file: {f}", key="calibrate.events")
        files.append(str(f))
    names = table.pop("parameters", [])
    if not isinstance(names, list) or not all(isinstance(n, str) and n for n in names):
        raise InputError(path, "must be a list of PSS/E parameter names, e.g. [\"H\", \"KA\"]",
                         key="calibrate.parameters")
    bounds = table.pop("bounds", {})
    if not isinstance(bounds, dict):
        raise InputError(path, "must be a table {NAME = [lower, upper]}", key="calibrate.bounds")
    for k, b in bounds.items():
        if not (isinstance(b, list) and len(b) == 2 and all(isinstance(x, (int, float)) and
                                                            not isinstance(x, bool) for x in b)
                and b[0] < b[1]):
            raise InputError(path, f"must be [lower, upper] with lower < upper, got {b!r}",
                             key=f"calibrate.bounds.{k}")
    kw = options(path, CalibrateOptions, table, "calibrate.",
                 keys={"bound_factor", "max_relative_ci", "noise_floor_pu",
                       "input_filter_hz", "model_error"})
    return build(path, CalibrateOptions, {**kw, "events": tuple(files), "parameters": tuple(names),
                                          "bounds": {k: tuple(map(float, b)) for k, b in bounds.items()}},
                 "calibrate")


def _one_line(text) -> str:
    return " ".join(str(text).split())


def _skip(name, bus, reason, ids=None) -> dict:
    """A ``skipped`` entry: {"name", "bus", "reason"}, the reason on one line; ``ids``: the
    machine IDs of the plant where it names them (absent: every unit on the bus)."""
    out = {"name": name, "bus": bus, "reason": _one_line(reason) or "unknown"}
    return out if ids is None else {**out, "ids": [str(i).strip() for i in ids]}


def _explicit_units(path, units, raw: RawCase, columns: list[str]):
    """[[unit]] tables -> ([(name, bus, ids or None, columns, direction or None)], skipped):
    a unit on a bus the case lacks, or naming a column the recording lacks, is skipped."""
    if not isinstance(units, list):
        raise InputError(path, "must be an array of tables: [[unit]]", key="unit")
    out, skipped = [], []
    for n, u in enumerate(units):
        key = f"unit[{n}]."
        if not isinstance(u, dict):
            raise InputError(path, "must be a table", key=f"unit[{n}]")
        no_unknown(path, u, {"name", "bus", "ids", "columns", "current_direction"}, key)
        if isinstance(u.get("bus"), bool) or not isinstance(u.get("bus"), int):
            raise InputError(path, "the generator bus number (an integer) is required", key=key + "bus")
        ids = u.get("ids")
        if ids is not None and (not isinstance(ids, list) or not all(isinstance(i, str) for i in ids)):
            raise InputError(path, "must be a list of machine IDs (strings)", key=key + "ids")
        if not isinstance(u.get("columns"), dict):
            raise InputError(path, "a table of columns {time, v_mag, v_ang, i_mag, i_ang} is required",
                             key=key + "columns")
        bus = u["bus"]
        if bus not in raw.buses:
            skipped.append(_skip(str(u.get("name", bus)), bus, f"bus {bus} is not in {raw.source}"))
            continue
        name = str(u.get("name", f"{bus}_{(raw.buses[bus].name.split() or [str(bus)])[0].lower()}"))
        absent = [f"{role} = {c!r}" for role, c in u["columns"].items()
                  if isinstance(c, str) and c not in columns]
        if absent:
            skipped.append(_skip(name, bus, f"{path}, key '{key}columns': not in the recording: "
                                 + ", ".join(absent)))
            continue
        out.append((name, bus, ids, u["columns"], u.get("current_direction")))
    return out, skipped


def _template(text: str, bound: dict) -> re.Pattern:
    """A column-name pattern: ``*`` matches any text, ``{key}`` the value in ``bound`` (or,
    unbound, captures it: digits for bus numbers, any text otherwise)."""
    out = []
    for part in re.split(r"(\{\w+\}|\*)", text):
        if part == "*":
            out.append(".*?")
        elif re.fullmatch(r"\{\w+\}", part):
            key = part[1:-1]
            if key in bound:
                out.append(re.escape(str(bound[key])))
            else:
                out.append(rf"(?P<{key}>\d+)" if key in ("bus", "from", "to") else rf"(?P<{key}>.+?)")
        else:
            out.append(re.escape(part))
    return re.compile(r"\s*" + "".join(out) + r"\s*\Z")


def _one(path, columns, pattern: str, bound: dict, role: str) -> str | None:
    rx = _template(pattern, bound)      # built once: a case of 432 machines has ~1200 columns
    hits = [c for c in columns if rx.match(c)]
    if len(hits) > 1:
        raise InputError(path, f"{role} pattern {pattern!r} matches {len(hits)} columns for "
                         f"{bound} (e.g. {hits[0]!r}, {hits[1]!r}); make it narrower",
                         key=f"channels.{role}")
    return hits[0] if hits else None


def _name(path, ch: dict, default: str, **bound) -> str:
    try:
        return ch.get("name", default).format(**bound)
    except (KeyError, IndexError, ValueError) as e:
        raise InputError(path, f"cannot fill the name pattern ({type(e).__name__}: {e}); it may "
                         f"use {', '.join('{' + k + '}' for k in bound)}", key="channels.name") from None


def _machine_units(raw: RawCase, dyr: DyrData) -> list[tuple[int, str]]:
    """(bus, ID) of every machine of the case, once: the in-service generators, then the .dyr
    machine records without a generator record (a unit the case half describes)."""
    out, seen = [], set()
    for g in raw.generators:
        key = (g.bus, g.id.strip().upper())
        if g.stat == 1 and key not in seen:
            out.append((g.bus, g.id))
        seen.add(key)
    for r in dyr.records:
        key = (r.bus, r.id.upper())
        if r.kind == "machine" and key not in seen:
            out.append((r.bus, r.id))
            seen.add(key)
    return out


def _pattern_units(path, ch: dict, raw: RawCase, dyr: DyrData, columns: list[str]):
    """[channels] patterns -> ([(name, bus, ids, columns, direction)] of every plant found,
    skipped): a unit whose columns are found in part (or ambiguously) is skipped with the
    reason; one whose columns are all absent is not recorded and is left out."""
    no_unknown(path, ch, {"layout", "name", "branch", *ROLES}, "channels.")
    layout = ch.get("layout")
    if layout not in LAYOUTS:
        raise InputError(path, f"must be one of {', '.join(LAYOUTS)}, got {layout!r}", key="channels.layout")
    for role in ("time", "v_mag", "v_ang", "i_mag", "i_ang"):
        if not isinstance(ch.get(role), str):
            raise InputError(path, "a column-name pattern is required", key=f"channels.{role}")
    if ch["time"] not in columns:
        raise InputError(path, f"no column named {ch['time']!r}", key="channels.time")
    out, skipped = [], []
    required = ("v_mag", "v_ang", "i_mag", "i_ang")
    if layout == "per_machine":
        for bus, gid in _machine_units(raw, dyr):
            bound = {"bus": bus, "id": gid}
            name = _name(path, ch, "{bus}_{id}", **bound)
            try:
                cols = {r: _one(path, columns, ch[r], bound, r) for r in ROLES[1:] if r in ch}
            except InputError as e:
                skipped.append(_skip(name, bus, str(e), [gid]))
                continue
            missing = [r for r in required if cols[r] is None]
            if len(missing) == len(required):
                continue                                       # not recorded
            if missing:
                skipped.append(_skip(name, bus, f"{path}: no column matches "
                                     + ", ".join(f"{r} = {ch[r]!r}" for r in missing)
                                     + f" for bus {bus} id {gid!r}", [gid]))
                continue
            if cols.get("frequency", "") is None:
                del cols["frequency"]                          # optional: from the angle
            out.append((name, bus, [gid], {"time": ch["time"], **cols}, None))
        return out, skipped
    branch = ch.get("branch")
    if not isinstance(branch, str) or "{from}" not in branch or "{to}" not in branch:
        raise InputError(path, "layout \"step_up_branch\" needs branch = a pattern with {from} and "
                         "{to}, e.g. \"{from}|*|{to}|*\"", key="channels.branch")
    for role in ("i_mag", "i_ang"):
        if "{branch}" not in ch[role]:
            raise InputError(path, "must contain {branch}, e.g. \"LinCurMag/{branch}\"",
                             key=f"channels.{role}")
    ends = {}
    current, ends_rx = _template(ch["i_mag"], {}), _template(branch, {})
    for c in columns:
        m = current.match(c)
        e = m and ends_rx.match(m.group("branch"))
        if e:
            ends[m.group("branch")] = (int(e.group("from")), int(e.group("to")))
    buses = {b for b, gid in _machine_units(raw, dyr)
             if any(r.kind == "machine" for r in dyr.unit_records(b, gid))}
    for bus in sorted(buses):
        bound = {"bus": bus}
        name = _name(path, ch, "{bus}_{busname}", bus=bus, busname=(
            raw.buses[bus].name.split() or [str(bus)])[0].lower() if bus in raw.buses else str(bus))
        at = [(b, "out_of_plant" if f == bus else "into_plant")
              for b, (f, t) in ends.items() if bus in (f, t)]
        try:
            v = {r: _one(path, columns, ch[r], bound, r) for r in ("v_mag", "v_ang")}
            if not at or (v["v_mag"] is None and v["v_ang"] is None and len(at) > 1):
                continue                                       # not recorded (or not as a plant)
            if len(at) > 1:
                raise InputError(path, f"{len(at)} branches at bus {bus} in the recording "
                                 f"({', '.join(repr(b) for b, _ in at[:3])}); a plant needs one "
                                 "step-up branch (use [[unit]] tables)", key="channels.branch")
            b, direction = at[0]
            cols = {"time": ch["time"], **v,
                    **{r: _one(path, columns, ch[r], {"branch": b}, r) for r in ("i_mag", "i_ang")}}
            missing = [r for r in required if cols[r] is None]
            if missing:
                raise InputError(path, "no column matches " + ", ".join(
                    f"{r} = {ch[r]!r}" for r in missing) + f" for bus {bus} (branch {b!r})",
                    key="channels")
            if "frequency" in ch:
                cols["frequency"] = _one(path, columns, ch["frequency"], bound, "frequency")
                if cols["frequency"] is None:
                    del cols["frequency"]
        except InputError as e:
            skipped.append(_skip(name, bus, str(e)))
            continue
        out.append((name, bus, None, cols, direction))
    return out, skipped
