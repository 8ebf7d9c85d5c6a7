"""``jaxdse fleet``: every plant of a PSS/E case against its PMU recordings, in one batched call.

A fleet file (TOML) names the PSS/E case (.raw and .dyr), the recording(s) and how each
plant's channels are found. Plant data come from the case: the in-service units with a
machine record on a bus form one plant, aggregated on the sum of their MBASE (reactances,
T'do and Rs MBASE-weighted; the reference H is the MBASE-weighted H of the machine records);
the governor is the :class:`WeightedGovernor` of the units' own governor records (TGOV1,
IEEEG1, GAST, HYGOV, GGOV1). Every plant gets the same governor slots (zero weight where a
plant has fewer units of a type), so that all plants share one pytree structure and run in
one compiled, vmapped call per recording length (as ``jaxdse run``).
"""

from __future__ import annotations

import csv
import dataclasses
import json
import re
import sys
import time
from collections import Counter
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

from .._core.drem import ObserverConfig
from .._core.governor import GAST, GGOV1, HYGOV, IEEEG1, TGOV1, WeightedGovernor
from .._core.machine import Machine, QAxisCircuits
from .._core.mapping import AuxiliarySystem, Transformer
from .._core.plant import Plant
from .._core.verdict import NOTES
from .._io.config import (
    GeneratorRun,
    _identify,
    _measurement,
    _module,
    _no_unknown,
    _settings,
    _table,
    read_toml,
)
from .._io.errors import InputError
from .._io.measurement import condition
from .._io.psse import (
    GOVERNOR_FIELDS,
    DyrData,
    RawCase,
    governor_from_dyr,
    machine_kwargs,
    read_dyr,
    read_raw,
    transformer_kwargs,
    transient_data,
)
from .._io.readers import load_table
from .._many.batch import estimate_batch, pad_recording, select, stack
from .._version import __version__
from .fleet_report import window_errors, write_report
from .progress import Progress
from .report import summary_entry
from .run import _assess, _cut, bucket, module_values, settings_values, sha256

LAYOUTS = ("per_machine", "step_up_branch")
"""How plants and their columns are found from [channels] (see ``FLEET_HELP`` in the CLI)."""
ROLES = ("time", "frequency", "v_mag", "v_ang", "i_mag", "i_ang")
GOVERNOR_TYPES = {"TGOV1": TGOV1, "IEEEG1": IEEEG1, "GAST": GAST, "HYGOV": HYGOV, "GGOV1": GGOV1}
CRITERIA = {"max_interval_percent": 10.0, "max_smape_i_t": 5.0, "max_smape_p_t": 5.0,
            "max_smape_q_t": 10.0}
"""[criteria] defaults: largest half width of H's 95 % interval [%] and largest playback
sMAPE [%] of I_t, P_t and Q_t for a unit to pass."""
MAX_SUBSTEPS = 24
"""Adaptive playback steps per sample before a playback counts as diverged. Under vmap every
member waits for the slowest, and a diverging playback would use the default 256 steps on
every sample; the members that follow their data need a few."""
TOP = {"case", "measurement", "channels", "unit", "observer", "settings", "identify", "criteria",
       "output"}


@dataclasses.dataclass(frozen=True)
class Member:
    """One unit (machine) of a plant: its records in the case."""

    id: str
    model: str
    mbase_mva: float
    h_s: float
    governor: str | None
    """Governor model of its .dyr record (None: no governor record; constant torque)."""


@dataclasses.dataclass(frozen=True)
class FleetPlant:
    """One plant of the fleet: its units, its columns and the :class:`GeneratorRun` built from them."""

    name: str
    bus: int
    members: tuple[Member, ...]
    others: tuple[str, ...]
    """In-service units on the bus without a machine record (renewables, ...)."""
    run: GeneratorRun


@dataclasses.dataclass(frozen=True)
class Fleet:
    """A validated fleet file: the case, the plants, and the estimator's settings."""

    path: Path
    raw: RawCase
    dyr: DyrData
    plants: tuple[FleetPlant, ...]
    skipped: tuple[dict, ...]
    observer: ObserverConfig
    settings: object
    identify: object
    verdict: object
    criteria: dict
    figures: bool = True


# --- reading the fleet file -------------------------------------------------------------------

def load_fleet(path) -> Fleet:
    """Read and validate a fleet file, the PSS/E case it names and the recordings' headers."""
    path = Path(path)
    data = read_toml(path)
    _no_unknown(path, data, TOP, "")
    case = _table(path, data, "case", "case")
    _no_unknown(path, case, {"raw", "dyr"}, "case.")
    files = {}
    for k in ("raw", "dyr"):
        if not isinstance(case.get(k), str):
            raise InputError(path, f"the PSS/E .{k} file is required (a path, relative to this file)",
                             key=f"case.{k}")
        p = Path(case[k])
        files[k] = p if p.is_absolute() else path.parent / p
    raw, dyr = read_raw(files["raw"]), read_dyr(files["dyr"])
    meas = dict(_table(path, data, "measurement", "measurement"))
    if meas.get("location", "terminal") not in ("terminal", "hv"):
        raise InputError(path, "a fleet's PMUs are at the machine terminal or on the HV side of "
                         "the step-up transformer: use \"terminal\" or \"hv\" (the line to a "
                         "substation is not in the case)", key="measurement.location")
    meas.setdefault("location", "terminal")
    _measurement(path, {k: v for k, v in meas.items() if k != "columns"}, raw.basfrq_hz, "",
                 partial=True)
    out = _table(path, data, "output", "output")
    _no_unknown(path, out, {"figures"}, "output.")
    crit = _table(path, data, "criteria", "criteria")
    _no_unknown(path, crit, set(CRITERIA), "criteria.")
    criteria = {k: float(_positive(path, crit.get(k, v), f"criteria.{k}")) for k, v in CRITERIA.items()}
    table = load_table(_files(path, meas), meas.get("format"),
                       csv_options=_measurement(path, {**meas, "columns": {}}, raw.basfrq_hz, "").csv_options)
    if "unit" in data:
        found = _explicit_units(path, data["unit"], raw, dyr)
    else:
        found = _pattern_units(path, _table(path, data, "channels", "channels"), raw, dyr,
                               list(table.columns))
    plants, skipped = [], []
    for name, bus, ids, columns, direction in found:
        members, others = _members(raw, dyr, bus, ids)
        if not members:
            skipped.append({"name": name, "bus": bus, "reason": "no in-service unit with a machine "
                            "record (GENCLS, GENSAL, GENROU, GENTPJ) on this bus"})
            continue
        spec = _measurement(path, {**meas, "columns": columns,
                                   **({"current_direction": direction} if direction else {})},
                            raw.basfrq_hz, "")
        plants.append((name, bus, members, others, spec))
    if not plants:
        raise InputError(path, "no plant found: check [channels] (or [[unit]]) against the "
                         "recording's column names and the case's generators", key="channels")
    slots = _slots([_governor_sets(dyr, p[1], p[2]) for p in plants])
    built = tuple(FleetPlant(name, bus, tuple(members), tuple(others),
                             _generator_run(name, bus, members, spec, raw, dyr, slots))
                  for name, bus, members, others, spec in plants)
    identify, verdict = _identify(path, _table(path, data, "identify", "identify"))
    return Fleet(path=path, raw=raw, dyr=dyr, plants=built, skipped=tuple(skipped),
                 observer=_module(path, ObserverConfig, _table(path, data, "observer", "observer"),
                                  "observer"),
                 settings=_settings(path, _table(path, data, "settings", "settings")),
                 identify=identify, verdict=verdict, criteria=criteria,
                 figures=bool(out.get("figures", True)))


def _positive(path, value, key):
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        raise InputError(path, f"must be a number > 0, got {value!r}", key=key)
    return value


def _files(path: Path, meas: dict) -> list[str]:
    files = meas.get("file")
    files = files if isinstance(files, list) else [files]
    if not files or not all(isinstance(f, str) and f for f in files):
        raise InputError(path, "the recording file(s) are required", key="measurement.file")
    return [str(f if Path(f).is_absolute() else path.parent / f) for f in files]


def _explicit_units(path, units, raw: RawCase, dyr: DyrData):
    """[[unit]] tables -> (name, bus, ids or None, columns, direction or None)."""
    if not isinstance(units, list):
        raise InputError(path, "must be an array of tables: [[unit]]", key="unit")
    out = []
    for n, u in enumerate(units):
        key = f"unit[{n}]."
        _no_unknown(path, u, {"name", "bus", "ids", "columns", "current_direction"}, key)
        if isinstance(u.get("bus"), bool) or not isinstance(u.get("bus"), int):
            raise InputError(path, "the generator bus number (an integer) is required", key=key + "bus")
        if u["bus"] not in raw.buses:
            raise InputError(path, f"bus {u['bus']} is not in {raw.source}", key=key + "bus")
        ids = u.get("ids")
        if ids is not None and (not isinstance(ids, list) or not all(isinstance(i, str) for i in ids)):
            raise InputError(path, "must be a list of machine IDs (strings)", key=key + "ids")
        if not isinstance(u.get("columns"), dict):
            raise InputError(path, "a table of columns {time, v_mag, v_ang, i_mag, i_ang} is required",
                             key=key + "columns")
        out.append((str(u.get("name", f"{u['bus']}_{raw.buses[u['bus']].name.split()[0].lower()}")),
                    u["bus"], ids, u["columns"], u.get("current_direction")))
    return out


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
    hits = [c for c in columns if _template(pattern, bound).match(c)]
    if len(hits) > 1:
        raise InputError(path, f"{role} pattern {pattern!r} matches {len(hits)} columns for "
                         f"{bound} (e.g. {hits[0]!r}, {hits[1]!r}); make it narrower",
                         key=f"channels.{role}")
    return hits[0] if hits else None


def _pattern_units(path, ch: dict, raw: RawCase, dyr: DyrData, columns: list[str]):
    """[channels] patterns -> (name, bus, ids, columns, direction) of every plant found."""
    _no_unknown(path, ch, {"layout", "name", "branch", *ROLES}, "channels.")
    layout = ch.get("layout")
    if layout not in LAYOUTS:
        raise InputError(path, f"must be one of {', '.join(LAYOUTS)}, got {layout!r}", key="channels.layout")
    for role in ("time", "v_mag", "v_ang", "i_mag", "i_ang"):
        if not isinstance(ch.get(role), str):
            raise InputError(path, "a column-name pattern is required", key=f"channels.{role}")
    if ch["time"] not in columns:
        raise InputError(path, f"no column named {ch['time']!r}", key="channels.time")
    units = [g for g in raw.generators if g.stat == 1 and dyr.machine(g.bus, g.id) is not None]
    out = []
    if layout == "per_machine":
        for g in units:
            bound = {"bus": g.bus, "id": g.id}
            cols = {r: _one(path, columns, ch[r], bound, r) for r in ROLES[1:] if r in ch}
            if any(cols[r] is None for r in ("v_mag", "v_ang", "i_mag", "i_ang")):
                continue
            name = ch.get("name", "{bus}_{id}").format(**bound)
            out.append((name, g.bus, [g.id], {"time": ch["time"], **cols}, None))
        return out
    branch = ch.get("branch")
    if not isinstance(branch, str) or "{from}" not in branch or "{to}" not in branch:
        raise InputError(path, "layout \"step_up_branch\" needs branch = a pattern with {from} and "
                         "{to}, e.g. \"{from}|*|{to}|*\"", key="channels.branch")
    for role in ("i_mag", "i_ang"):
        if "{branch}" not in ch[role]:
            raise InputError(path, "must contain {branch}, e.g. \"LinCurMag/{branch}\"",
                             key=f"channels.{role}")
    ends = {}
    for c in columns:
        m = _template(ch["i_mag"], {}).match(c)
        e = m and _template(branch, {}).match(m.group("branch"))
        if e:
            ends[m.group("branch")] = (int(e.group("from")), int(e.group("to")))
    for bus in sorted({g.bus for g in units}):
        bound = {"bus": bus}
        v = {r: _one(path, columns, ch[r], bound, r) for r in ("v_mag", "v_ang")}
        at = [(b, "out_of_plant" if f == bus else "into_plant")
              for b, (f, t) in ends.items() if bus in (f, t)]
        if v["v_mag"] is None or v["v_ang"] is None or len(at) != 1:
            continue
        b, direction = at[0]
        cols = {"time": ch["time"], **v,
                **{r: _one(path, columns, ch[r], {"branch": b}, r) for r in ("i_mag", "i_ang")}}
        if cols["i_ang"] is None:
            continue
        if "frequency" in ch:
            cols["frequency"] = _one(path, columns, ch["frequency"], bound, "frequency")
            if cols["frequency"] is None:
                del cols["frequency"]
        name = ch.get("name", "{bus}_{busname}").format(
            bus=bus, busname=raw.buses[bus].name.split()[0].lower())
        out.append((name, bus, None, cols, direction))
    return out


def _members(raw: RawCase, dyr: DyrData, bus: int, ids) -> tuple[list[Member], list[str]]:
    members, others = [], []
    for g in raw.generators:
        if g.bus != bus or g.stat != 1 or (ids is not None and g.id not in ids):
            continue
        rec = dyr.machine(bus, g.id)
        if rec is None:
            others.append(g.id)
            continue
        gov = dyr.governor(bus, g.id)
        members.append(Member(id=g.id, model=rec.model, mbase_mva=g.mbase_mva, h_s=rec["H"],
                              governor=gov.model if gov is not None else None))
    return members, others


def _governor_sets(dyr: DyrData, bus: int, members: list[Member]) -> dict:
    """(model, constants) -> summed MBASE share of the plant's units with that governor record.

    Units whose governor records are equal share one model with their summed weight: the
    sum of equal models with the same input and loading is that model (exact, and fewer
    states to integrate)."""
    s = sum(m.mbase_mva for m in members)
    out: dict = {}
    for m in members:
        if m.governor is not None:
            key = (m.governor, dyr.governor(bus, m.id).constants)
            out[key] = out.get(key, 0.0) + m.mbase_mva / s
    return out


def _slots(sets: list[dict]) -> tuple[str, ...]:
    """The governor slots every plant gets: each type as often as the plant with most of it."""
    most = Counter()
    for found in sets:
        for model, n in Counter(model for model, _ in found).items():
            most[model] = max(most[model], n)
    return tuple(t for t in GOVERNOR_FIELDS for _ in range(most[t]))


def _generator_run(name, bus, members: list[Member], spec, raw: RawCase, dyr: DyrData,
                   slots: tuple[str, ...]) -> GeneratorRun:
    """The aggregated plant (machine, governor, step-up transformer) of ``members``."""
    kv = raw.bus_kv(bus)
    kws = [machine_kwargs(dyr.machine(bus, m.id), raw.generator(bus, m.id), kv, raw.basfrq_hz)
           for m in members]
    s = sum(m.mbase_mva for m in members)
    w = np.array([m.mbase_mva / s for m in members])

    def avg(k):
        return float(sum(wi * kw[k] for wi, kw in zip(w, kws)))

    # The q-axis circuits of round-rotor machines (GENROU: X''q = X''d): without them the
    # algebraic observer's delta lags a 6th-order machine's during a swing and biases H.
    tds = [transient_data(dyr.machine(bus, m.id)) for m in members]
    q_axis = None
    if all(td is not None and td.xq1_pu is not None for td in tds):
        def tavg(k):
            return float(sum(wi * getattr(td, k) for wi, td in zip(w, tds)))

        q_axis = QAxisCircuits(xq1_pu=tavg("xq1_pu"), xq2_pu=tavg("xd2_pu"), xl_pu=tavg("xl_pu"),
                               tq01_s=tavg("tq01_s"), tq02_s=tavg("tq02_s"))
    machine = Machine(xd_pu=avg("xd_pu"), xq_pu=avg("xq_pu"), xd1_pu=avg("xd1_pu"),
                      td01_s=avg("td01_s"), rs_pu=avg("rs_pu"), h_s=avg("h_s"), d_pu_s=avg("d_pu_s"),
                      s_rated_mva=s, v_rated_kv=kv, f_nominal_hz=raw.basfrq_hz, q_axis=q_axis)
    free, by_slot = list(slots), {}
    for (model, constants), weight in _governor_sets(dyr, bus, members).items():
        rec = next(dyr.governor(bus, m.id) for m in members if m.governor == model
                   and dyr.governor(bus, m.id).constants == constants)
        k = free.index(model)
        by_slot[k] = (governor_from_dyr(rec, mbase_mva=raw.generator(bus, rec.id).mbase_mva), weight)
        free[k] = None
    governor = WeightedGovernor(
        tuple(by_slot[k][0] if k in by_slot else GOVERNOR_TYPES[t]() for k, t in enumerate(slots)),
        [by_slot[k][1] if k in by_slot else 0.0 for k in range(len(slots))])
    plant = Plant(machine=machine, governor=governor, s_base_mva=spec.s_base_mva)
    if spec.location == "hv":
        gsu = raw.step_up_transformer(bus)
        if gsu is None:
            raise InputError(raw.source, f"plant {name}: no step-up transformer at bus {bus}, which "
                             "location = \"hv\" needs")
        plant = eqx.tree_at(lambda p: (p.transformer, p.aux), plant,
                            (Transformer(**transformer_kwargs(gsu, raw)), AuxiliarySystem(p_as_max_mw=0.0)))
    return GeneratorRun(name=name, role="estimate", measurement=spec, plant=plant,
                        h_reference_s=float(machine.h_s))


# --- running ----------------------------------------------------------------------------------

def run_fleet(fleet: Fleet, out_dir: Path, stream=sys.stderr) -> dict:
    """Estimate every plant of ``fleet``; write fleet.json, fleet.csv and the HTML report.

    Returns the fleet.json document. Raises :class:`InputError` when no plant's recording
    can be read (a plant whose recording alone is bad is listed under ``skipped``).
    """
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    unknown = fleet.dyr.unknown_models
    if unknown:
        print(f"jaxdse: note: {fleet.dyr.source}: models read but not used: {', '.join(unknown)}",
              file=stream)
    progress = Progress(len(fleet.plants) + 2 + len(fleet.plants), stream)
    units, skipped, first_error = [], list(fleet.skipped), None
    for p in fleet.plants:
        spec = p.run.measurement
        try:
            table = load_table(spec.file, spec.format, csv_options=spec.csv_options,
                               time_column=spec.columns.get("time"))
            segments, quality = condition(table, spec, p.run.plant.machine)
        except InputError as err:
            first_error = first_error or err
            skipped.append({"name": p.name, "bus": p.bus, "reason": str(err)})
            progress.step(f"read {p.name}: skipped")
            continue
        quality["segments"] = len(segments)
        units.append((p, segments[0][1], segments[0][0], quality))
        progress.step(f"read {p.name}")
    if not units:
        raise first_error
    # One padded length for the whole fleet (the longest recording's): one compilation.
    size = bucket(max(int(np.shape(u[1].t_s)[0]) for u in units))
    groups: dict = {}
    for u in units:
        groups.setdefault((size, u[1].location, jax.tree_util.tree_structure(u[0].run.plant)), []).append(u)
    settings = dataclasses.replace(fleet.settings, keep="trajectories", playback=fleet.identify is None,
                                   playback_integrator=_capped(fleet.settings.playback_integrator))
    results = {}
    for (size, _, _), members in groups.items():
        recs = stack([pad_recording(u[1], size, with_frequency=True) for u in members])
        plants = stack([u[0].run.plant for u in members])
        est = estimate_batch(recs, plants, fleet.observer, settings, None, np.full(len(members), np.nan))
        progress.step(f"online estimate of {len(members)} plant(s), {size} samples")
        assessed = None
        if fleet.identify is not None:
            online = eqx.tree_at(lambda e: e.trajectories, est, None)
            assessed = jax.tree_util.tree_map(np.asarray, _assess(
                recs, plants, online, fleet.observer, settings, fleet.identify, fleet.verdict))
        progress.step(f"identification of {len(members)} plant(s)")
        for k, u in enumerate(members):
            results[u[0].name] = (est, assessed, k)
    entries, traces = [], {}
    for p, rec, t0, quality in units:
        est_b, assessed, k = results[p.name]
        n = int(np.shape(rec.t_s)[0])
        est = _cut(select(est_b, k), n)
        est = eqx.tree_at(lambda e: e.time_s, est, est.time_s + t0)
        ident = rep = verd = None
        if assessed is not None:
            ident, rep, verd = (select(x, k) for x in assessed)
            rep = eqx.tree_at(lambda r: r.playback, rep, _cut(rep.playback, n))
        traces[p.name] = _traces(est, rep)
        entry = fleet_entry(p, est, ident, rep, verd, quality, fleet.criteria)
        entry["window_errors"] = window_errors(traces[p.name])
        entries.append(entry)
        if entry["verdict"] != "identified":
            why = "; ".join(v for key, v in entry["reasons"].items() if key not in NOTES) or "see fleet.json"
            print(f"jaxdse: warning: {p.name}: {entry['verdict']}: {why}", file=stream)
        progress.step(f"assessed {p.name}")
    doc = fleet_document(fleet, entries, skipped, time.perf_counter() - t_start)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_report(out_dir, doc, traces, figures=fleet.figures)
    doc["wall_time_s"] = round(time.perf_counter() - t_start, 2)
    (out_dir / "fleet.json").write_text(json.dumps(doc, indent=2) + "\n")
    write_fleet_csv(out_dir / "fleet.csv", entries)
    s = doc["summary"]
    print(f"[jaxdse] {len(entries)} plant(s), {len(skipped)} skipped; median |H error| "
          f"{_fmt(s['median_abs_H_error_percent'])} %; verdicts {s['verdicts']}; wrote {out_dir}/"
          f"report.html, fleet.json, fleet.csv in {doc['wall_time_s']:.1f} s", file=stream)
    return doc


def _capped(integ):
    return dataclasses.replace(integ, max_substeps=min(integ.max_substeps, MAX_SUBSTEPS)) \
        if integ.adaptive else integ


def fleet(path, out_dir, stream=sys.stderr) -> list[dict]:
    """``jaxdse fleet`` from Python: one row (dict) per plant (``fleet.json["units"]``)."""
    return run_fleet(load_fleet(path), Path(out_dir), stream)["units"]


def fleet_entry(p: FleetPlant, est, ident, rep, verd, quality: dict, criteria: dict) -> dict:
    """One unit of ``fleet.json``: the run summary entry plus the plant, the reference and the checks."""
    href = p.run.h_reference_s
    e = summary_entry(p.name, est, ident, rep, verd, h_reference_s=href)
    h = e["H_s"]
    lo, hi = e["H_ci95"] or (None, None)
    ident_info = e.get("identification", {})
    half = ident_info.get("relative_ci_percent")
    smape = e["smape_percent"]
    checks = {
        "interval": _check(half, criteria["max_interval_percent"], "half width of H's 95 % interval [%]"),
        "I_t": _check(smape["I_t"], criteria["max_smape_i_t"], "playback sMAPE of I_t [%]"),
        "P_t": _check(smape["P_t"], criteria["max_smape_p_t"], "playback sMAPE of P_t [%]"),
        "Q_t": _check(smape["Q_t"], criteria["max_smape_q_t"], "playback sMAPE of Q_t [%]"),
    }
    m = p.run.plant.machine
    return {
        "name": p.name, "bus": p.bus, "bus_kv": float(m.v_rated_kv), "s_mva": float(m.s_rated_mva),
        "H_s": h, "H_ci95": [lo, hi], "H_reference_s": href,
        "H_error_percent": None if h is None else 100.0 * (h - href) / href,
        "D": e["D"], "D_ci95": e["D_ci95"], "verdict": e["verdict"], "reasons": e["reasons"],
        "interval": {"relative_ci_percent": half,
                     "noise_percent": None if ident is None else _pct(ident.relative_ci_noise),
                     "filter_spread_percent": None if ident is None else _pct(ident.filter_spread),
                     "condition": ident_info.get("condition")},
        "playback_smape_percent": {"x2": smape["x2_playback"], "I_t": smape["I_t"],
                                   "P_t": smape["P_t"], "Q_t": smape["Q_t"]},
        "criteria": checks, "passes": all(c["pass"] for c in checks.values()),
        "units": [dataclasses.asdict(u) for u in p.members],
        "governor_models": sorted({u.governor or "none (constant torque)" for u in p.members}),
        "other_units_on_bus": list(p.others),
        "machine": module_values(m),
        "columns": dict(p.run.measurement.columns),
        "current_direction": p.run.measurement.current_direction,
        "location": p.run.measurement.location,
        "identification": ident_info, "online": e["online"], "t_ref_pu": e["t_ref_pu"],
        "n_samples": e["n_samples"], "duration_s": e["duration_s"], "data_quality": quality,
    }


def _pct(x):
    v = float(np.asarray(x))
    return 100.0 * v if np.isfinite(v) else None


def _check(value, limit, what):
    return {"value": value, "limit": limit, "what": what,
            "pass": value is not None and value <= limit}


def _traces(est, rep) -> dict:
    """Measured and played-back x2, I_t, P_t, Q_t for the unit page (host arrays)."""
    tr = est.trajectories
    pb = rep.playback if rep is not None else tr.playback
    out = {"time_s": np.asarray(est.time_s)}
    for k, meas, sim in (("x2", tr.x2_meas_rad_s, pb.x2_rad_s), ("I_t", tr.i_t_pu, pb.i_t_pu),
                         ("P_t", tr.p_t_pu, pb.p_t_pu), ("Q_t", tr.q_t_pu, pb.q_t_pu)):
        out[k] = (np.asarray(meas), np.asarray(sim))
    return out


def fleet_document(fleet: Fleet, entries: list[dict], skipped: list[dict], wall_s: float) -> dict:
    """fleet.json: the units, the skipped plants, the fleet summary and the provenance."""
    errs = np.array([abs(e["H_error_percent"]) for e in entries if e["H_error_percent"] is not None])
    inputs = sorted({f for p in fleet.plants for f in p.run.measurement.file})
    return {
        "source": f"jaxdse fleet {fleet.path}",
        "jaxdse_version": __version__,
        "config": {"file": str(fleet.path), "sha256": sha256(fleet.path)},
        "case": {"raw": fleet.raw.source, "raw_revision": fleet.raw.revision,
                 "dyr": fleet.dyr.source, "dyr_models": dict(fleet.dyr.counts),
                 "dyr_models_not_used": fleet.dyr.unknown_models},
        "inputs": [{"file": f, "sha256": sha256(Path(f))} for f in
                   [fleet.raw.source, fleet.dyr.source, *inputs]],
        "summary": {
            "units": len(entries), "skipped": len(skipped),
            "median_abs_H_error_percent": float(np.median(errs)) if errs.size else None,
            "within_10_percent": int(np.sum(errs <= 10.0)),
            "identified_outside_10_percent": [e["name"] for e in entries if e["verdict"] == "identified"
                                              and e["H_error_percent"] is not None
                                              and abs(e["H_error_percent"]) > 10.0],
            "verdicts": dict(Counter(e["verdict"] for e in entries)),
        },
        "units": entries, "skipped": skipped,
        "criteria": fleet.criteria,
        "observer": module_values(fleet.observer), "settings": settings_values(fleet.settings),
        "identify": None if fleet.identify is None else module_values(fleet.identify),
        "verdict_thresholds": module_values(fleet.verdict),
        "wall_time_s": round(wall_s, 2),
    }


CSV_FIELDS = ("name", "bus", "s_mva", "governor_models", "H_s", "H_ci95_low", "H_ci95_high",
              "H_reference_s", "H_error_percent", "D", "verdict", "reasons", "smape_I_t", "smape_P_t",
              "smape_x2", "passes")


def write_fleet_csv(path: Path, entries: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_FIELDS)
        for e in entries:
            s = e["playback_smape_percent"]
            w.writerow([e["name"], e["bus"], f"{e['s_mva']:.6g}", "/".join(e["governor_models"]),
                        _fmt(e["H_s"], ".6g"), _fmt(e["H_ci95"][0], ".6g"), _fmt(e["H_ci95"][1], ".6g"),
                        _fmt(e["H_reference_s"], ".6g"), _fmt(e["H_error_percent"], ".4g"),
                        _fmt(e["D"], ".6g"), e["verdict"], ";".join(e["reasons"]),
                        _fmt(s["I_t"], ".4g"), _fmt(s["P_t"], ".4g"), _fmt(s["x2"], ".4g"), e["passes"]])


def _fmt(x, spec=".1f") -> str:
    return "" if x is None else format(x, spec)
