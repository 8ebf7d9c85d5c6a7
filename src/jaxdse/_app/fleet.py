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
import sys
import time
from collections import Counter
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from .._core.assess import Assessment
from .._core.mapping import map_to_terminal
from .._core.signals import frequency_from_angle
from .._core.verdict import D_MEANING, NOTES
from .._dyr.inventory import UNIT_CATEGORIES, inventory
from .._io.errors import InputError
from .._io.measurement import condition, order_note
from .._io.readers import load_table
from .._many.runner import Unit, assess_units, bucket, planned_calls
from .._version import __version__
from .dyr_fleet import SIMULATED_RECORDS, DyrOutcome, plant_model, play_back_plants, terminal_series
from .fleet_file import Fleet, FleetPlant, load_fleet
from .fleet_gfm import is_grid_forming, unfitted, virtual_inertia
from .fleet_inertia import fleet_inertia, inertia_document, inertia_figure, write_inertia_csv
from .fleet_plants import NO_ROTOR
from .fleet_report import write_report
from .progress import Progress
from .report import playback_traces, summary_entry
from .run import module_values, settings_values, sha256
from .windows import WindowCriteria, window_scores

# --- running ----------------------------------------------------------------------------------

def run_fleet(fleet: Fleet, out_dir: Path, stream=None) -> dict:
    """Estimate every plant of ``fleet``; write fleet.json, fleet.csv and the HTML report.

    Returns the fleet.json document. Raises :class:`InputError` when no plant's recording
    can be read (a plant whose recording alone is bad is listed under ``skipped``).
    """
    t_start = time.perf_counter()
    out_dir = Path(out_dir)
    stream = stream or sys.stderr
    for note in fleet.notes:
        print(f"jaxdse: note: {note}", file=stream)
    unknown = [m for m in fleet.dyr.unknown_models
               if fleet.playback.model != "dyr" or m not in SIMULATED_RECORDS]
    if unknown:
        print(f"jaxdse: note: {fleet.dyr.source}: models read but not used: {', '.join(unknown)}",
              file=stream)
    progress = Progress(2 * len(fleet.plants) + 1, stream)  # reads, calls (set below), units
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
        if note := order_note(quality):
            progress.note(f"jaxdse: note: {p.name}: {note}")
        progress.step(f"read {p.name}")
    if not units:
        raise first_error
    settings = dataclasses.replace(fleet.settings, keep="trajectories")
    # The swing-equation estimator runs on the synchronous plants only (an inverter-based plant
    # has no rotor: its recording is only mapped to its terminal, ``ibr_terminal``).
    machines = [u for u in units if not u[0].ibr]
    assessed = []
    progress.total = len(fleet.plants) + len(units)
    if machines:
        # One padded length for the whole fleet (the longest recording's): one compilation.
        size = bucket(max(int(np.shape(u[1].t_s)[0]) for u in machines))
        work = [Unit(p.name, rec, p.run.plant, t0) for p, rec, t0, _ in machines]
        progress.total += planned_calls(work, fleet.identify, size)
        assessed = assess_units(work, fleet.observer,
                                settings, fleet.identify, fleet.verdict, size=size,
                                progress=lambda line: progress.step(f"assessed {line}"))
    fronts = {u[0].name: (a if not u[0].ibr else ibr_terminal(u[1], u[0].run.plant, settings))
              for u, a in zip(machines + [u for u in units if u[0].ibr],
                              [*assessed, *(None for u in units if u[0].ibr)])}
    # Each plant's entry (its window criteria) as soon as its playback is done, while the
    # playbacks of other plants run.
    index = {u[0].name: k for k, u in enumerate(units)}
    done = {}
    for name, dyr in dyr_playbacks(fleet, [u[0] for u in units], [fronts[u[0].name] for u in units]):
        (p, _, _, quality), a = units[index[name]], fronts[name]
        if p.ibr:
            tr = ibr_traces(a, dyr)
            entry = ibr_entry(p, a, tr, quality, fleet.criteria, dyr)
            if is_grid_forming(dyr):
                progress.note(f"jaxdse: {p.name}: a grid-forming converter: fitting its virtual "
                              "inertia and damping to the recording")
                entry.update(gfm_entry(virtual_inertia(a, dyr, fleet.playback.settings, fleet.calibrate)))
            elif (several := unfitted(dyr)) is not None:
                entry.update(several)
            done[name] = (tr, entry)
        else:
            done[name] = (_traces(a.estimate, a.replay, dyr), fleet_entry(p, a, quality, fleet.criteria, dyr))
        progress.step(f"assessed {p.name}")
    entries, traces = [], {}
    for p, *_ in units:
        traces[p.name], entry = done[p.name]
        entries.append(entry)
        if entry["verdict"] not in ("identified", "not applicable"):
            why = "; ".join(v for key, v in entry["reasons"].items() if key not in NOTES) or "see fleet.json"
            print(f"jaxdse: warning: {p.name}: H {entry['verdict']}: {why}", file=stream)
        if (val := entry["validation"])["result"] != "pass":
            why = "; ".join(val["reasons"]) or "see fleet.json"
            print(f"jaxdse: warning: {p.name}: model validation ({MODEL_WORDS[val['model']]}) "
                  f"{val['result']}: {why}", file=stream)
    doc = fleet_document(fleet, entries, skipped, time.perf_counter() - t_start)
    out_dir.mkdir(parents=True, exist_ok=True)
    if fleet.inertia is not None:   # the synchronous plants' stored energy
        keep = [k for k, u in enumerate(units) if not u[0].ibr]
        doc["inertia"] = _inertia(fleet, [units[k] for k in keep], [entries[k] for k in keep],
                                  out_dir, stream)
    write_report(out_dir, doc, traces, figures=fleet.figures)
    doc["wall_time_s"] = round(time.perf_counter() - t_start, 2)
    (out_dir / "fleet.json").write_text(json.dumps(doc, indent=2) + "\n")
    write_fleet_csv(out_dir / "fleet.csv", entries)
    s = doc["summary"]
    a = doc["accounting"]["summary"]
    print(f"[jaxdse] {a['generator_records']} generator records in the case: {a['in_fleet']} in the "
          "fleet's plants, " + ", ".join(f"{a[k]} {k}" for k in FLEET_NOT_IN if a[k])
          + (f"; {a['dyr_records_orphaned']} orphaned .dyr record(s)" if a["dyr_records_orphaned"] else "")
          + " (fleet.json accounting)", file=stream)
    print(f"[jaxdse] {len(entries)} plant(s), {len(skipped)} skipped. H: {_counts(s['verdicts'])}; "
          f"median |H error| {_fmt(s['median_abs_H_error_percent']) or '–'} %. Model validation: "
          f"{_counts(s['validation'])} ({_counts(s['validation_models'], MODEL_WORDS)}). Wrote "
          f"{out_dir}/report.html, fleet.json, fleet.csv in {doc['wall_time_s']:.1f} s", file=stream)
    return doc


def _inertia(fleet: Fleet, units: list, entries: list[dict], out_dir: Path, stream) -> dict:
    """[inertia]: E per area for the recording; writes inertia.csv (and inertia.png)."""
    currents, t_end = {}, None
    for p, rec, t0, _ in units:
        scale = float(p.run.measurement.s_base_mva) / float(p.run.plant.machine.s_rated_mva)
        currents[p.name] = float(np.nanmean(np.asarray(rec.i_mag_pu))) * scale
        t = np.asarray(rec.t_s)
        end = float(t0) + float(t[-1] - t[0])
        t_end = end if t_end is None else max(t_end, end)
    areas, contributions, notes = fleet_inertia(fleet, [u[0] for u in units], entries, currents, t_end)
    for note in notes:
        print(f"jaxdse: note: inertia: {note}", file=stream)
    write_inertia_csv(out_dir / "inertia.csv", areas)
    doc = inertia_document(fleet, areas, contributions, notes)
    s = fleet.inertia.settings(fleet.raw.basfrq_hz)
    if fleet.figures:
        loss = "" if s.largest_loss_mw is None else f"; Hz/s: rate of change of frequency after losing " \
            f"{s.largest_loss_mw:g} MW"
        inertia_figure(out_dir / "inertia.png", areas, s.floor_MWs,
                       f"Stored kinetic energy per area, {Path(fleet.raw.source).name}, one value for the "
                       f"recording{loss}")
    system = areas[-1]
    share = "" if system.measured_share is None else f", {100 * system.measured_share:.0f} % measured"
    print(f"[jaxdse] inertia: system E {system.E_MWs / 1e3:.4g} GW s (95 % {system.E_ci95[0] / 1e3:.4g}-"
          f"{system.E_ci95[1] / 1e3:.4g}{share}; commitment {system.E_commitment_MWs / 1e3:.4g} GW s) in "
          f"{len(areas) - 1} area(s): {out_dir}/inertia.csv", file=stream)
    return doc


def fleet(path, out_dir, stream=None) -> list[dict]:
    """``jaxdse fleet`` from Python: one row (dict) per plant (``fleet.json["units"]``)."""
    return run_fleet(load_fleet(path), Path(out_dir), stream)["units"]


def dyr_playbacks(fleet: Fleet, plants: list[FleetPlant],
                  assessed) -> Iterator[tuple[str, DyrOutcome | None]]:
    """(plant name, DyrOutcome) for every plant as its .dyr playback is done (first the plants
    that play back the surrogate), when ``[playback] model = "dyr"``; else (name, None).
    ``assessed``: each plant's :class:`Assessment`, or an inverter-based plant's
    :class:`IbrTerminal`."""
    if fleet.playback.model != "dyr":
        yield from ((p.name, None) for p in plants)
        return
    jobs = {}
    for p, a in zip(plants, assessed):
        pm = plant_model(fleet.raw, fleet.dyr, p, fleet.playback)
        if pm.fallback:
            yield p.name, DyrOutcome(pm, None)
            continue
        if p.ibr:
            jobs[p.name] = (pm, terminal_series(a.time_s, a.v_t_pu, a.theta_t_rad, a.p_t_pu, a.q_t_pu,
                                                a.f_dev_hz / float(fleet.raw.basfrq_hz)))
            continue
        tr = a.estimate.trajectories
        jobs[p.name] = (pm, terminal_series(a.estimate.time_s, tr.v_t_pu, tr.theta_t_rad, tr.p_t_pu,
                                            tr.q_t_pu))
    for name, pb in play_back_plants(jobs, fleet.playback):
        yield name, DyrOutcome(jobs[name][0], pb)


def fleet_entry(p: FleetPlant, a: Assessment, quality: dict, criteria: dict,
                dyr: DyrOutcome | None = None) -> dict:
    """One unit of ``fleet.json``: the run summary entry plus the plant, the reference and the
    checks; with ``dyr`` (``[playback] model = "dyr"``), the playback is the .dyr model's."""
    href = p.run.h_reference_s
    ident = a.identified
    e = summary_entry(p.name, a, h_reference_s=href)
    h = e["H_s"]
    lo, hi = e["H_ci95"] or (None, None)
    ident_info = e.get("identification", {})
    half = ident_info.get("relative_ci_percent")
    smape = e["smape_percent"]
    traces = _traces(a.estimate, a.replay, dyr)
    m = p.run.plant.machine
    validation = validation_entry(traces, p, criteria, dyr)
    damping = damping_entry(e, p)
    entry = {
        "name": p.name, "bus": p.bus, "bus_kv": float(m.v_rated_kv), "s_mva": float(m.s_rated_mva),
        "H_s": h, "H_ci95": [lo, hi], "H_reference_s": href,
        "H_error_percent": None if h is None else 100.0 * (h - href) / href,
        "D": e["D"], "D_ci95": e["D_ci95"], "D_verdict": damping["verdict"], "damping": damping,
        "verdict": e["verdict"], "reasons": e["reasons"],
        "interval": {"relative_ci_percent": half,
                     "noise_percent": None if ident is None else _pct(ident.relative_ci_noise),
                     "filter_spread_percent": None if ident is None else _pct(ident.filter_spread),
                     "filter_refits_counted": None if ident is None else int(ident.filter_spread_fits),
                     "condition": ident_info.get("condition")},
        "validation": validation,
        "playback_smape_percent": {"I_t": smape["I_t"], "P_t": smape["P_t"]},
        "playback_rms_percent_mbase": _rms_percent(traces, p),
        "playback_model": validation["model"],
        **({} if dyr is None else dyr.entry(_rms_percent(_traces(a.estimate, a.replay), p))),
        # D's meaning is said once, in "damping"
        "parameters": {k: ({f: x for f, x in v.items() if f != "meaning"} if k == "D" else v)
                       for k, v in e["parameters"].items()},
        "units": [dataclasses.asdict(u) for u in p.members],
        "governor_models": sorted({u.governor or "none (constant torque)" for u in p.members}),
        "other_units_on_bus": list(p.others),
        "fallbacks": list(p.fallbacks),
        "data_warnings": [*p.data_warnings, *p.run.notes],   # records and plant data used as given
        "repairs": list(p.repairs),                          # jaxdse check --repair's changes
        "machine": module_values(m),
        "columns": dict(p.run.measurement.columns),
        "current_direction": p.run.measurement.current_direction,
        "location": p.run.measurement.location,
        "identification": ident_info, "online": e["online"], "t_ref_pu": e["t_ref_pu"],
        "n_samples": e["n_samples"], "duration_s": e["duration_s"], "data_quality": quality,
    }
    return entry


IBR_SCOPE = ("MOD-026-2's two checks on the plant's own PSS/E records, the recorded voltage phasor "
             "and the frequency from its angle imposed: active power against frequency, reactive "
             "power against voltage")
IBR_CHANNELS = ("P_t", "Q_t")
"""An inverter-based plant's judged channels: it has no rotor speed."""


class IbrTerminal(NamedTuple):
    """An inverter-based plant's recording at its terminal (host arrays; pu on the plant's MBASE)."""

    time_s: np.ndarray
    v_t_pu: np.ndarray
    """|V| at the terminal."""
    theta_t_rad: np.ndarray
    """Terminal voltage angle in the nominal frame."""
    i_t_pu: np.ndarray
    p_t_pu: np.ndarray
    """Active power out of the terminal."""
    q_t_pu: np.ndarray
    f_dev_hz: np.ndarray
    """Frequency deviation of the terminal bus: the channel where it has a value, else the
    voltage angle's slope (as for a machine)."""


def ibr_terminal(rec, plant, settings) -> IbrTerminal:
    """The recording ``rec`` (conditioned, pu on the plant's MBASE) mapped to the plant's
    terminal as a machine's is (``map_to_terminal``: through the step-up transformer where the
    PMU is on its HV side), without the estimator."""
    t = np.asarray(rec.t_s)
    theta_ref = np.unwrap(np.asarray(rec.v_ang_rad))
    i = np.asarray(rec.i_mag_pu) * np.exp(1j * (np.asarray(rec.i_ang_rad) - theta_ref))
    mapped = map_to_terminal(jnp.asarray(np.asarray(rec.v_mag_pu) + 0j), jnp.asarray(i), plant.line,
                             plant.transformer, plant.aux, rec.location)
    v_t = np.asarray(mapped.v_t)
    i_t = np.asarray(mapped.i_sg) * float(plant.current_scale)
    s_t = v_t * np.conj(i_t)
    f0 = float(plant.machine.f_nominal_hz)
    f_hz = np.asarray(frequency_from_angle(jnp.asarray(theta_ref), t[1] - t[0], f0,
                                           settings.derivative_half_width))
    if rec.f_hz is not None:
        f_rec = np.asarray(rec.f_hz)
        f_hz = np.where(np.isnan(f_rec), f_hz, f_rec)
    return IbrTerminal(t - t[0], np.abs(v_t), theta_ref + np.unwrap(np.angle(v_t)), np.abs(i_t),
                       s_t.real, s_t.imag, f_hz - f0)


def ibr_traces(front: IbrTerminal, dyr: DyrOutcome | None) -> dict:
    """An inverter-based plant's measured and played-back traces (the unit page's P/f and Q/V
    panels): x2 is the recorded frequency deviation [rad/s] (nothing simulates it, as |V|,
    "V_t": the recorded voltage is imposed)."""
    nan = np.full_like(front.time_s, np.nan)
    pb = None if dyr is None else dyr.playback
    sim = {"P_t": nan, "Q_t": nan, "I_t": nan} if pb is None else {
        "P_t": np.asarray(pb.p_pu), "Q_t": np.asarray(pb.q_pu),
        "I_t": np.hypot(pb.p_pu, pb.q_pu) / np.where(front.v_t_pu > 0, front.v_t_pu, 1.0)}
    return {"time_s": front.time_s, "x2": (2 * np.pi * front.f_dev_hz, nan),
            "I_t": (front.i_t_pu, sim["I_t"]), "P_t": (front.p_t_pu, sim["P_t"]),
            "Q_t": (front.q_t_pu, sim["Q_t"]), "V_t": (front.v_t_pu, nan)}


def ibr_entry(p: FleetPlant, front: IbrTerminal, traces: dict, quality: dict, criteria: dict,
              dyr: DyrOutcome | None) -> dict:
    """An inverter-based plant's fleet.json entry: H and D ``not applicable`` (no rotor: the
    swing-equation estimator is not run on it), its own records' playback judged in MOD-026-2's
    terms (:func:`validation_entry`), the records played back in place of a machine's."""
    m = p.run.plant.machine
    validation = validation_entry(traces, p, criteria, dyr)
    out = {
        "name": p.name, "bus": p.bus, "bus_kv": float(m.v_rated_kv), "s_mva": float(m.s_rated_mva),
        "plant_type": "inverter-based",
        "estimator": NO_ROTOR + ": the swing-equation estimator (H, D) is not run on it",
        "H_s": None, "H_ci95": [None, None], "H_reference_s": None, "H_error_percent": None,
        "D": None, "D_ci95": None, "D_verdict": "not applicable",
        "damping": {"verdict": "not applicable", "reasons": [NO_ROTOR]},
        "verdict": "not applicable", "reasons": {"no_rotor": NO_ROTOR},
        "interval": {"relative_ci_percent": None, "noise_percent": None, "filter_spread_percent": None,
                     "filter_refits_counted": None, "condition": None},
        "validation": validation,
        "playback_smape_percent": {"I_t": None, "P_t": None},
        "playback_rms_percent_mbase": _rms_percent(traces, p),
        "playback_model": validation["model"],
        **({} if dyr is None else dyr.entry({})),
        "parameters": {},
        "units": [{**dataclasses.asdict(u), "h_s": None} for u in p.members],
        "governor_models": [], "other_units_on_bus": list(p.others), "fallbacks": list(p.fallbacks),
        "data_warnings": [*p.data_warnings, *p.run.notes], "repairs": list(p.repairs),
        "machine": None,
        "columns": dict(p.run.measurement.columns),
        "current_direction": p.run.measurement.current_direction,
        "location": p.run.measurement.location,
        "identification": {}, "online": {"H_s": None, "D": None}, "t_ref_pu": None,
        "n_samples": int(front.time_s.size), "duration_s": float(front.time_s[-1] - front.time_s[0]),
        "data_quality": quality,
    }
    out.pop("surrogate_playback_rms_percent_mbase", None)   # a machine's surrogate: not applicable
    return out


def gfm_entry(v: dict) -> dict:
    """The fleet.json fields of a grid-forming converter's virtual H and D (``virtual_inertia``)
    over an inverter-based plant's ``not applicable`` ones."""
    half = v["relative_ci_percent"]
    d_word = "negative" if v["D_ci95"][1] < 0 else "identified" if v["verdict"] == "identified" \
        else "not identified"
    return {
        "plant_type": "grid-forming",
        "estimator": ((v["meaning"] or "virtual rotor: H = M/2 and D of the converter's own record fitted to "
                       "the recording by its playback") + " (the swing-equation estimator is not run on it)"),
        "H_s": v["H_s"], "H_ci95": v["H_ci95"], "H_reference_s": v["H_record_s"],
        "H_error_percent": 100 * (v["H_s"] / v["H_record_s"] - 1),
        "D": v["D"], "D_ci95": v["D_ci95"], "D_record": v["D_record"],
        "D_verdict": d_word, "damping": {"verdict": d_word, "reasons": [v["d_meaning"] or GFM_D_MEANING]},
        "verdict": v["verdict"], "reasons": v["reasons"],
        "interval": {"relative_ci_percent": half, "noise_percent": None, "filter_spread_percent": None,
                     "filter_refits_counted": None, "condition": None},
        "virtual_inertia": v,
    }


GFM_D_MEANING = ("the converter's emulated damping D of its swing equation M d(dw)/dt = Pref - Pe "
                 "- D dw [pu power / pu speed], fitted with M: the record's D, not a lumped damping")


def damping_entry(e: dict, p: FleetPlant) -> dict:
    """The identified D, what it is and is not (``D_MEANING``), its own verdict (``D_VERDICTS``:
    ``negative`` where its 95 % interval excludes 0 from below) with its reason in words, the
    same D per pu speed, and beside it the machine records' D as filed (a different quantity)."""
    m = p.run.plant.machine
    w_s = float(m.omega_s)
    par = e["parameters"].get("D")
    verdict = par["verdict"] if par is not None else "not identified"
    why = ([e["reasons"][k] for k in par["reasons"] if k in e["reasons"]] if par is not None else
           ["the batch identification is off: only the online estimate, without an interval"])
    ci = e["D_ci95"]
    return {
        "meaning": D_MEANING,
        "verdict": verdict, "reasons": why,
        "D_pu_torque_per_rad_s": e["D"], "D_ci95_pu_torque_per_rad_s": ci,
        "D_pu_torque_per_pu_speed": None if e["D"] is None else e["D"] * w_s,
        "D_ci95_pu_torque_per_pu_speed": None if ci is None else [None if x is None else x * w_s for x in ci],
        "records_D_pu_torque_per_pu_speed": float(m.d_pu_s) * w_s,
        "records_D_is": "the MBASE-weighted D constant of the plant's machine records, as filed: "
                        "the record's value, not comparable with the identified D",
    }


WINDOW_CHANNELS = ("P_t", "Q_t", "x2")
"""Channels scored by window: P and Q in % of MBASE, judged; the speed deviation reported (in %
of synchronous speed), not judged (:data:`DYR_JUDGED`)."""
DYR_JUDGED = ("P_t", "Q_t")
"""The channels that judge the .dyr playback. The "measured" speed deviation is not a
measurement: it is derived from the PMU's voltage and current through the 3rd-order algebraic
observer (the surrogate's rotor angle, differentiated), which a fault's voltage-angle jump and the
subtransient windings throw about; the .dyr model's rotor speed is another quantity. On
ACTIVSg2000's generated recordings (``benchmarks/real_case_fleet.py``: the units' own records
played back against a recording of themselves) the derived speed peaked at 1.8-6.8 % of
synchronous speed after a fault, the true rotors at 0.3-0.9 %, and its window tests failed 7 of
317 true models. The surrogate is that same 3rd-order model, so its x2 is judged."""
SURROGATE_CHANNELS = ("P_t", "x2")
"""The surrogate's channels: its field voltage is estimated from the recording, so its Q is
not an exciter's response and is not judged."""
VALIDATION_RESULTS = ("pass", "fail", "not judged")


def validation_entry(traces: dict, p: FleetPlant, criteria: dict, dyr: DyrOutcome | None) -> dict:
    """The model validation of one unit (NERC MOD-026-2: the played-back response against the
    recorded one, by window), apart from H's verdict: ``result`` ("pass", "fail", "not
    judged": no disturbance), ``model`` ("dyr": the unit's own records; "surrogate": the
    3rd-order model with the identified H and D, asked for or the fallback), ``scope``,
    ``reasons`` (why it fails or is not judged) and the window ``scores``."""
    own = dyr is not None and dyr.playback is not None
    if p.ibr:
        return _ibr_validation(traces, p, criteria, dyr)
    channels = WINDOW_CHANNELS if own else SURROGATE_CHANNELS
    measured, replayed = ({k: traces[k][j] for k in channels} for j in (0, 1))
    reasons: list[str] = []
    if own and not dyr.playback.ok:
        scores = None
        reasons.append("the .dyr playback did not reach the end (solver failure or non-finite states)")
    else:
        scores = window_scores(traces["time_s"], measured, replayed, _channel_scale(p),
                               window_criteria(criteria), judged=DYR_JUDGED if own else channels)
        reasons += scores.reasons
    if scores is not None and scores.onset_s is None:
        result = "not judged"
    else:
        result = "pass" if not reasons else "fail"
    if own:
        scope = "active power/frequency and reactive power/voltage, the unit's own PSS/E records"
    else:
        why = (dyr.model.fallback if dyr is not None and dyr.model.fallback
               else "the surrogate was asked for ([playback] model = \"surrogate\")")
        scope = ("active power/frequency only: the 3rd-order surrogate with the identified H and D, "
                 "not the unit's filed model; its field voltage is estimated from the recording, so "
                 f"reactive power/voltage is not validated ({why})")
    return {"result": result, "model": "dyr" if own else "surrogate", "scope": scope,
            "reasons": reasons, "channels": list(channels),
            "judged_channels": list(DYR_JUDGED if own else channels),
            "windows": None if scores is None else scores.as_dict()}


def _ibr_validation(traces: dict, p: FleetPlant, criteria: dict, dyr: DyrOutcome | None) -> dict:
    """An inverter-based plant's validation: P and Q of its own records' playback by window
    (``IBR_SCOPE``); not judged where its records are not played back (the surrogate is a
    machine's, and does not apply)."""
    scores, reasons = None, []
    if dyr is None:
        reasons.append("an inverter-based plant is validated with its own records only "
                       "([playback] model = \"dyr\"); the surrogate is a synchronous machine's")
    elif dyr.playback is None:
        reasons.append(dyr.model.fallback)
    elif not dyr.playback.ok:
        reasons.append("the .dyr playback did not reach the end (solver failure or non-finite states)")
    else:
        measured, replayed = ({k: traces[k][j] for k in IBR_CHANNELS} for j in (0, 1))
        scores = window_scores(traces["time_s"], measured, replayed, _channel_scale(p),
                               window_criteria(criteria))
        reasons += scores.reasons
    played = scores is not None
    result = ("not judged" if not played or scores.onset_s is None else "pass" if not reasons else "fail")
    return {"result": result, "model": "dyr", "scope": IBR_SCOPE + ("" if played else " (not played back)"),
            "reasons": reasons, "channels": list(IBR_CHANNELS), "judged_channels": list(IBR_CHANNELS),
            "windows": None if scores is None else scores.as_dict()}


def window_criteria(criteria: dict) -> WindowCriteria:
    """The window thresholds of a fleet's [criteria]."""
    names = {f.name for f in dataclasses.fields(WindowCriteria)}
    return WindowCriteria(**{k: v for k, v in criteria.items() if k in names})


def _channel_scale(p: FleetPlant) -> dict:
    """pu (machine base) -> % of MBASE for P and Q; rad/s -> % of synchronous speed for x2."""
    return {"P_t": 100.0, "Q_t": 100.0, "x2": 100.0 / float(p.run.plant.machine.omega_s)}


def _rms_percent(traces: dict, p: FleetPlant) -> dict:
    """Whole-record RMS error of the replay's P and Q [% of MBASE] (signals that cross zero are
    never scored by sMAPE)."""
    scale = _channel_scale(p)
    out = {}
    for k in ("P_t", "Q_t"):
        e = traces[k][1] - traces[k][0]
        e = e[np.isfinite(e)]
        out[k] = float(scale[k] * np.sqrt(np.mean(e**2))) if e.size else None
    return out


def _pct(x):
    v = float(np.asarray(x))
    return 100.0 * v if np.isfinite(v) else None


def _traces(est, rep, dyr: DyrOutcome | None = None) -> dict:
    """Measured and played-back x2, I_t, P_t, Q_t for the unit page (host arrays): the
    surrogate's playback, or the .dyr model's where ``dyr`` has one."""
    out = playback_traces(est, rep)
    if dyr is not None and dyr.playback is not None:
        d = dyr.playback
        v = np.asarray(est.trajectories.v_t_pu)
        i_t = np.hypot(d.p_pu, d.q_pu) / np.where(v > 0, v, 1.0)
        for k, sim in (("x2", d.x2_rad_s), ("I_t", i_t), ("P_t", d.p_pu), ("Q_t", d.q_pu)):
            out[k] = (out[k][0], np.asarray(sim))
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
                   [fleet.raw.source, *fleet.dyr.source.split(" + "), *inputs]],
        "summary": {
            "units": len(entries), "skipped": len(skipped),
            "median_abs_H_error_percent": float(np.median(errs)) if errs.size else None,
            "within_10_percent": int(np.sum(errs <= 10.0)),
            "identified_outside_10_percent": [e["name"] for e in entries if e["verdict"] == "identified"
                                              and e["H_error_percent"] is not None
                                              and abs(e["H_error_percent"]) > 10.0],
            "verdicts": dict(Counter(e["verdict"] for e in entries)),
            "D_verdicts": dict(Counter(e["D_verdict"] for e in entries)),
            "validation": {r: n for r in VALIDATION_RESULTS
                           if (n := sum(e["validation"]["result"] == r for e in entries))},
            "validation_models": dict(Counter(e["validation"]["model"] for e in entries)),
        },
        "accounting": fleet_accounting(fleet, skipped),
        "units": entries, "skipped": skipped, "notes": list(fleet.notes),
        "criteria": fleet.criteria,
        "observer": module_values(fleet.observer), "settings": settings_values(fleet.settings),
        "identify": None if fleet.identify is None else module_values(fleet.identify),
        "verdict_thresholds": module_values(fleet.verdict),
        "wall_time_s": round(wall_s, 2),
    }


FLEET_NOT_IN = {
    "on a plant's bus": "on a plant's bus without a machine record jaxdse knows: its current is in "
                        "the plant's recorded current, not estimated",
    "skipped": "in a plant the fleet skipped (see skipped)",
    "not recorded": "not in the fleet file: no plant of [channels] or [[unit]] found a recording of it",
    "out of service": "out of service",
    "no dynamic records": "in service without dynamic records",
    "not a generator": "not generators: static var compensators or STATCOMs in the generator data",
    "duplicate": "second generator records for the same bus and ID (the first is used)",
}
"""What became of the case's generator records that are not units of a plant, in words."""


def fleet_accounting(fleet: Fleet, skipped: list[dict]) -> dict:
    """Every generator record of the case: ``in_fleet`` (a unit of a plant estimated) and each
    category not in the fleet (:data:`FLEET_NOT_IN`), adding up to
    ``generator_records``; every one not in the fleet listed with its reason, and the .dyr
    records of no generator."""
    inv = inventory(fleet.raw, fleet.dyr)
    member = {(p.bus, m.id.strip().upper()): p.name for p in fleet.plants for m in p.members}
    beside = {(p.bus, o.strip().upper()): p.name for p in fleet.plants for o in p.others}
    skipped_at = {}
    for k in skipped:   # a plant's IDs where it names them, else every unit on its bus
        for i in k.get("ids") or [None]:
            skipped_at.setdefault((k["bus"], None if i is None else i.strip().upper()), k)
    rows, in_fleet = [], 0
    for a in inv.generators:
        g = a.generator
        key = (g.bus, g.id.strip().upper())
        row = a.as_dict()
        if a.category in UNIT_CATEGORIES or key in member:   # an inverter-based plant's too
            if key in member:
                in_fleet += 1
                continue
            if key in beside:
                row.update(category="on a plant's bus", plant=beside[key],
                           why=f"{a.why}; on the bus of plant {beside[key]} without a machine record "
                               "jaxdse knows: its current is in the plant's recorded current")
            elif (k := skipped_at.get(key, skipped_at.get((g.bus, None)))) is not None:
                row.update(category="skipped", plant=k["name"],
                           why=f"plant {k['name']} skipped: {k['reason']}")
            else:
                row.update(category="not recorded",
                           why=f"{a.why}; no plant of the fleet file found a recording of it")
        rows.append(row)
    counts = Counter(r["category"] for r in rows)
    out = {"generator_records": len(inv.generators),
           "in_fleet": in_fleet,
           **{k: counts.get(k, 0) for k in FLEET_NOT_IN}}
    if out["in_fleet"] + sum(out[k] for k in FLEET_NOT_IN) != out["generator_records"]:  # a bug, not data
        raise AssertionError(f"generator records not accounted for: {out}")
    s = inv.summary()
    out.update({k: s[k] for k in ("dyr_records_orphaned", "dyr_records_bus_level", "dyr_records_unreadable")})
    return {"summary": out, "categories": dict(FLEET_NOT_IN), "generators_not_in_fleet": rows,
            "dyr_records_not_used": [r.as_dict() for r in inv.records],
            "dyr_records_unreadable": list(inv.unreadable)}


CSV_FIELDS = ("name", "bus", "s_mva", "governor_models", "H_s", "H_ci95_low", "H_ci95_high",
              "H_reference_s", "H_error_percent", "D", "D_verdict", "verdict", "reasons", "smape_I_t",
              "smape_P_t",
              "rms_P_percent_mbase", "rms_Q_percent_mbase", "validation", "validation_model")


def write_fleet_csv(path: Path, entries: list[dict]) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_FIELDS)
        for e in entries:
            s, rms = e["playback_smape_percent"], e["playback_rms_percent_mbase"]
            w.writerow([e["name"], e["bus"], f"{e['s_mva']:.6g}", "/".join(e["governor_models"]),
                        _fmt(e["H_s"], ".6g"), _fmt(e["H_ci95"][0], ".6g"), _fmt(e["H_ci95"][1], ".6g"),
                        _fmt(e["H_reference_s"], ".6g"), _fmt(e["H_error_percent"], ".4g"),
                        _fmt(e["D"], ".6g"), e["D_verdict"], e["verdict"], ";".join(e["reasons"]),
                        _fmt(s["I_t"], ".4g"), _fmt(s["P_t"], ".4g"), _fmt(rms["P_t"], ".4g"),
                        _fmt(rms["Q_t"], ".4g"), e["validation"]["result"], e["validation"]["model"]])


MODEL_WORDS = {"dyr": "own records", "surrogate": "surrogate"}


def _counts(counts: dict, words: dict | None = None) -> str:
    """{"identified": 9, "weakly identified": 1} -> "identified 9, weakly identified 1"."""
    return ", ".join(f"{(words or {}).get(k, k)} {n}" for k, n in counts.items()) or "none"


def _fmt(x, spec=".1f") -> str:
    return "" if x is None else format(x, spec)
