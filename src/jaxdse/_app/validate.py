"""``jaxdse validate``: the planner's own model (the units' PSS/E records) against recordings,
ranked by sensitivity and calibrated within the engineer's bounds.

The file is a fleet file (``[case]``, ``[measurement]``, ``[channels]`` or ``[[unit]]``) with a
``[calibrate]`` table. Every plant of one unit is

1. played back (PSS/E PLBVFU1: the recorded terminal voltage imposed) with its .dyr records, on
   the fleet file's recording and on each recording of ``[calibrate] events`` (same channels):
   the *before* playback;
2. ranked: the normalised sensitivities of P and Q to each parameter of the set, and from the
   Fisher information each parameter's Cramer-Rao 95 % half-width and variance inflation;
   parameters these events cannot pin down within ``max_relative_ci`` stay at their .dyr value
   and the page says so;
3. calibrated: the identifiable ones by bounded Levenberg-Marquardt on all events jointly (the
   playback's own integrator settings), with 95 % intervals (Gauss-Newton: the residuals'
   long-run covariance, the imposed voltage's noise drawn again through the fitted model, the
   events' disagreement, and ``model_error``; see :mod:`jaxdse._dyr.calibrate`);
4. filed only where the events reject the .dyr value (outside its interval) and the joint
   error falls by more than the noise, and never when an event gets worse beyond the noise
   (:func:`~jaxdse._dyr.calibrate.calibrate_where_rejected`): the *after* playback.

Writes validate.json, report.html (with units/<name>.html and .png: P/f and Q/V overlays before
and after) and calibrated.dyr (only the changed records, PSS/E syntax).
"""

from __future__ import annotations

import dataclasses
import html
import json
import math
import sys
import time
from collections import Counter
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._core.front_end import front_end
from .._dyr.calibrate import (
    CalibrationSettings,
    ParameterSpec,
    calibrate_where_rejected,
    rank,
    stack_events,
)
from .._dyr.playback import PlaybackSettings, play_back
from .._dyr.records import GFM_MODELS
from .._io.errors import InputError
from .._io.measurement import condition, order_note
from .._io.psse import GOVERNOR_FIELDS, GOVERNOR_PARAMETERS, MACHINE_FIELDS
from .._io.psse_dyr import repair_comment
from .._io.readers import load_table
from .._models.exciters import _ATTRIBUTES as EXCITER_ATTRIBUTES
from .._models.exciters import EXCITER_FIELDS
from .._models.ibr import IBR_FIELDS, IBR_PARAMETERS, IBR_ROLES
from .._models.stabilisers import STABILISER_FIELDS
from .._version import __version__
from .dyr_fleet import plant_model, terminal_series
from .fleet_file import Fleet, FleetPlant, load_fleet
from .fleet_report import _page, repairs_box
from .progress import Progress

DEFAULT_PARAMETERS = {
    "machine": (("h_s", "H"), ("d_pu", "D")),
    "SEXS": (("k", "K"), ("t_e_s", "TE")),
    "IEEEX1": (("ka", "KA"), ("t_a_s", "TA")),
    "EXDC2": (("ka", "KA"), ("t_a_s", "TA")),
    "ESDC2A": (("ka", "KA"), ("t_a_s", "TA")),
    "EXST1": (("ka", "KA"), ("t_a_s", "TA")),
    "ESST3A": (("ka", "KA"), ("t_m_s", "TM")),
    "TGOV1": (("r_pu", "R"), ("t1_s", "T1")),
    "IEEEG1": (("k", "K"), ("t3_s", "T3")),
    "GAST": (("r_pu", "R"), ("t1_s", "T1")),
    "HYGOV": (("r_pu", "R"), ("tg_s", "Tg")),
    "GGOV1": (("r_pu", "R"), ("t_act_s", "Tact")),
    "REECA1": (("kqv", "Kqv"),),
    "REECB1": (("kqv", "Kqv"),),
    "REECCU1": (("kqv", "Kqv"),),
    "REPCA1": (("kp", "Kp"), ("ki", "Ki"), ("ddn_pu", "Ddn"), ("dup_pu", "Dup")),
    "REGCV1": (("m_s", "M"), ("d_pu", "D")),
    "REGCV2": (("m_s", "M"), ("d_pu", "D")),
    "REGFM_A1": (("mp", "mp"), ("mq", "mq")),
    "REGFMA1": (("mp", "mp"), ("mq", "mq")),
    "REGFM_B1": (("h_s", "H"), ("mp", "mp"), ("mq", "mq")),
    "REGFMB1U": (("h_s", "H"), ("mp", "mp"), ("mq", "mq")),
}
"""The default parameter set per model: H and D, the exciter's main gain and time constant, the
governor's droop (IEEEG1: its gain K = 1/R) and main time constant; of an inverter-based plant
the gains an engineer tunes on site (its time constants are mostly below a frame period): the
electrical controls' voltage-dip reactive gain Kqv, the plant controller's voltage-loop PI gains
Kp, Ki and its frequency droops Ddn (over-frequency) and Dup (under-frequency); of a grid-forming
converter its virtual inertia M = 2H and damping D (REGCV1, REGCV2) or its P-f and Q-V droops mp, mq
(REGFM_A1), its H and droops (REGFM_B1)."""
IBR_PARTS = ("electrical", "plant")
"""The parts of an inverter-based plant (:class:`~jaxdse._dyr.ibr_unit.IbrUnit`) calibrated."""
GFM_PARTS = ("converter",)
"""... of a grid-forming converter (:class:`~jaxdse._dyr.gfm_unit.GfmUnit`)."""
MACHINE_PARTS = ("machine", "exciter", "governor")
DROOPS = ("Ddn", "Dup")
"""REPCA1's droops: 0 is a valid setting (no droop that way), bounded like D from 0."""
DROOP_BOUNDS = (0.0, 100.0)
"""Default bounds of Ddn and Dup [pu power / pu frequency] (100: a 1 % droop)."""
DIP_ONLY = {"Kqv": "it acts only while |V| is outside [Vdip, Vup] (a voltage dip or rise)"}
"""When a parameter moves the output at all, said with its reason when these events do not."""
D_BOUNDS = (0.0, 20.0)
"""Default bounds of D [pu torque / pu speed]: physical (D >= 0), and it may sit at 0 in the .dyr."""


# --- parameters -------------------------------------------------------------------------------

def parameter_specs(unit, models: dict, options, notes: list) -> list[ParameterSpec]:
    """The parameters to rank and calibrate, with their bounds (``options``: CalibrateOptions)."""
    out = []
    parts = (MACHINE_PARTS if "converter" not in models
             else GFM_PARTS if models["converter"] in GFM_MODELS else IBR_PARTS)
    for part in parts:
        model = models.get(part)
        table = DEFAULT_PARAMETERS.get("machine" if part == "machine" else model, ())
        for field, label in table:
            if options.parameters and label not in options.parameters:
                continue
            x = float(getattr(getattr(unit, part), field))
            lo_hi = options.bounds.get(label)
            if label == "D" or label in DROOPS:
                lo, hi = lo_hi or (D_BOUNDS if label == "D" else DROOP_BOUNDS)
                if not lo <= x <= hi:
                    notes.append(f"{label} = {x:g} lies outside its bounds [{lo:g}, {hi:g}]: "
                                 "not calibrated")
                    continue
                out.append(ParameterSpec(part, field, label, lo, hi, positive=False))
                continue
            if not x > 0:
                notes.append(f"{model} {label} = {x:g} in the record: not calibrated (a time "
                             "constant or gain at 0 switches a block off)")
                continue
            lo, hi = lo_hi or (x / options.bound_factor, x * options.bound_factor)
            if not lo < x < hi:
                notes.append(f"{label} = {x:g} lies outside its bounds [{lo:g}, {hi:g}]: "
                             "not calibrated")
                continue
            out.append(ParameterSpec(part, field, label, float(lo), float(hi)))
    return out


def explain(ranking, specs):
    """``ranking`` with the reason a parameter that these events leave at sensitivity 0 has
    none (:data:`DIP_ONLY`: Kqv without a voltage dip) added to its sentence."""
    return ranking._replace(reasons=[
        r + (f" ({DIP_ONLY[s.label]})" if s.label in DIP_ONLY and "sensitivity 0" in r else "")
        for r, s in zip(ranking.reasons, specs)])


# --- events -----------------------------------------------------------------------------------

def _event_series(fleet: Fleet, p: FleetPlant, files: tuple, tables: dict, note=lambda line: None):
    """The plant's TerminalSeries (machine base) from one recording (a file, or the files
    that share one time axis as [measurement] file lists them); ``note`` gets the line that
    says what the time handling changed (sorted rows, dropped repeats), if anything."""
    spec = dataclasses.replace(p.run.measurement, file=tuple(files))
    if files not in tables:
        tables[files] = load_table(list(files), spec.format, csv_options=spec.csv_options,
                                   time_column=spec.columns.get("time"))
    segments, quality = condition(tables[files], spec, p.run.plant.machine)
    if line := order_note(quality):
        note(f"jaxdse: note: {p.name}: {line}")
    rec = segments[0][1]
    fe = jax.jit(front_end)(rec, p.run.plant, fleet.settings)
    s = fe.v_t * jnp.conj(fe.i_t)
    t = np.asarray(rec.t_s)
    # the frequency channel as recorded (an inverter-based plant's input), else the front end's
    f_hz = np.asarray(fe.f_hz) if rec.f_hz is None else np.where(
        np.isnan(np.asarray(rec.f_hz)), np.asarray(fe.f_hz), np.asarray(rec.f_hz))
    f0 = float(p.run.plant.machine.f_nominal_hz)
    return terminal_series(t - t[0], np.abs(np.asarray(fe.v_t)), np.asarray(fe.theta_t),
                           np.asarray(jnp.real(s)), np.asarray(jnp.imag(s)), f_hz / f0 - 1.0)


def _pad(series_list):
    """Stack series of unequal length: pad with the last sample, weight 0 there."""
    n = max(int(s.t_s.shape[0]) for s in series_list)
    out, w = [], []
    for s in series_list:
        k = int(s.t_s.shape[0])
        dt = float(s.t_s[1] - s.t_s[0])
        t = np.concatenate([np.asarray(s.t_s), float(s.t_s[-1]) + dt * np.arange(1, n - k + 1)])
        pads = [None if a is None else jnp.asarray(np.concatenate(
            [np.asarray(a), np.repeat(np.asarray(a)[-1:], n - k)])) for a in s[1:]]
        out.append(type(s)(jnp.asarray(t), *pads))
        w.append(np.r_[np.ones(k), np.zeros(n - k)])
    return stack_events(out, np.stack(w))


# --- running ----------------------------------------------------------------------------------

def run_validate(fleet: Fleet, out_dir: Path, stream=None) -> dict:
    """Validate and calibrate every one-unit plant of ``fleet``; write the outputs."""
    t_start = time.perf_counter()
    stream = stream or sys.stderr
    out_dir = Path(out_dir)
    (out_dir / "units").mkdir(parents=True, exist_ok=True)
    opts = fleet.calibrate
    recordings = [tuple(str(f) for f in fleet.plants[0].run.measurement.file)]
    recordings += [(str(e),) for e in opts.events]
    files = [" + ".join(r) for r in recordings]
    playback = PlaybackSettings(substeps=fleet.playback.substeps, solver=fleet.playback.solver)
    fit_settings = PlaybackSettings(substeps=playback.substeps, solver=playback.solver,
                                    input_filter_hz=opts.input_filter_hz)
    cal = CalibrationSettings(max_relative_ci=opts.max_relative_ci,
                              noise_floor_pu=opts.noise_floor_pu, model_error=opts.model_error)
    progress = Progress(len(fleet.plants) * (len(recordings) + 3), stream)
    tables, units, changed = {}, [], []
    for p in fleet.plants:
        entry = {"name": p.name, "bus": p.bus, "events": files}
        pm = plant_model(fleet.raw, fleet.dyr, p, fleet.playback)
        if len(pm.units) != 1 or pm.fallback:
            entry["skipped"] = pm.fallback or (f"{len(pm.units)} units behind one PMU: played back in "
                                               "`jaxdse fleet`, not calibrated (their shares are not "
                                               "measured)")
            units.append(entry)
            progress.done += len(recordings) + 2
            progress.step(f"{p.name}: skipped")
            print(f"jaxdse: warning: {p.name}: not validated: {entry['skipped']}", file=stream)
            continue
        um = pm.units[0]
        series = []
        try:
            for r in recordings:
                series.append(_event_series(fleet, p, r, tables, progress.note))
                progress.step(f"{p.name}: read {Path(r[0]).name}")
        except InputError as err:
            entry["skipped"] = str(err)
            units.append(entry)
            progress.done += len(recordings) + 2 - len(series)
            progress.step(f"{p.name}: skipped")
            print(f"jaxdse: warning: {p.name}: not validated: {err}", file=stream)
            continue
        events = _pad(series)
        notes = list(um.notes)
        specs = parameter_specs(um.unit, um.models, opts, notes)
        ranking = explain(rank(um.unit, specs, events, fit_settings, cal), specs)
        free = ranking.identifiable
        progress.step(f"{p.name}: ranked {len(specs)} parameter(s), {int(free.sum())} identifiable")
        decision = (calibrate_where_rejected(um.unit, specs, events, fit_settings, cal, free=free)
                    if free.any() else None)
        progress.step(f"{p.name}: " + ("nothing identifiable" if decision is None else
                                       f"changed {', '.join(decision.changed) or 'nothing'}"))
        after_unit = um.unit if decision is None else decision.unit
        before = [jax.tree.map(np.asarray, jax.jit(play_back)(um.unit, s, playback)) for s in series]
        after = [jax.tree.map(np.asarray, jax.jit(play_back)(after_unit, s, playback)) for s in series]
        entry.update(_unit_entry(um, specs, ranking, decision, series, before, after, p))
        entry["notes"] = notes
        entry["repairs"] = list(p.repairs)
        units.append(entry)
        if decision is not None and decision.changed:
            changed.append((p, um, decision))
        plot_before_after(entry, series, before, after, out_dir / "units" / f"{p.name}.png")
        (out_dir / "units" / f"{p.name}.html").write_text(unit_page(entry))
        progress.step(f"{p.name}: {entry['outcome']}")
        if entry["outcome"] != "consistent with the .dyr":
            print(f"jaxdse: {'warning' if entry['refused'] else 'note'}: {p.name}: {entry['outcome']}"
                  + (f": {entry['refused']}" if entry["refused"] else ""), file=stream)
    dyr_text = calibrated_dyr(fleet, changed)
    (out_dir / "calibrated.dyr").write_text(dyr_text)
    doc = {"jaxdse_version": __version__, "config": str(fleet.path), "events": files,
           "settings": {"playback_substeps": playback.substeps, "fit_substeps": fit_settings.substeps,
                        **dataclasses.asdict(opts)},
           "units": units, "wall_time_s": round(time.perf_counter() - t_start, 2)}
    (out_dir / "validate.json").write_text(json.dumps(doc, indent=1, default=_json) + "\n")
    (out_dir / "report.html").write_text(report_page(doc))
    outcomes = Counter(u.get("outcome", "skipped") for u in units)
    print(f"[jaxdse] {len(units)} plant(s): " + ", ".join(f"{k} {n}" for k, n in outcomes.items())
          + f"; wrote {out_dir}/report.html, validate.json, calibrated.dyr in {doc['wall_time_s']:.1f} s",
          file=stream)
    return doc


def _json(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


def _rms(a, b) -> float:
    e = np.asarray(a) - np.asarray(b)
    return float(100 * np.sqrt(np.mean(e ** 2)))


def _unit_entry(um, specs, ranking, decision, series, before, after, p) -> dict:
    rows = []
    fits = {}
    if decision is not None:
        for fit in (decision.first_fit, decision.fit):      # the final fit wins for its parameters
            if fit is not None:
                fits.update(zip(fit.labels, zip(fit.values, fit.ci95)))
    for j, s in enumerate(specs):
        x0 = float(s.value(um.unit))
        row = {"parameter": s.label, "model": um.models[s.part], "dyr_value": x0,
               "bounds": [s.lower, s.upper],
               "sensitivity_P_pu": float(ranking.sensitivity[j, 0]),
               "sensitivity_Q_pu": float(ranking.sensitivity[j, 1]),
               "relative_ci_percent_crlb": float(100 * ranking.relative_ci[j]),
               "variance_inflation": float(ranking.variance_inflation[j]),
               "identifiable": bool(ranking.identifiable[j]),
               "why_not": ranking.reasons[j] or None,
               "status": "not identifiable: .dyr kept" if not ranking.identifiable[j] else
               decision.status.get(s.label, "consistent with the .dyr"),
               "filed_value": x0}
        if s.label in fits:
            v, ci = fits[s.label]
            row.update(calibrated_value=float(v), ci95=[float(ci[0]), float(ci[1])],
                       change_percent=float(100 * (v - x0) / x0) if x0 != 0 else None)
            if row["status"] == "changed":
                row["filed_value"] = float(v)
        rows.append(row)
    per_event = []
    noise = None if decision is None else decision.threshold
    for e, (s, b, a) in enumerate(zip(series, before, after)):
        p_meas, q_meas = _pq(s)
        ev = {"before_rms_percent_mbase": {"P_t": _rms(b.p_pu, p_meas), "Q_t": _rms(b.q_pu, q_meas)},
              "after_rms_percent_mbase": {"P_t": _rms(a.p_pu, p_meas), "Q_t": _rms(a.q_pu, q_meas)}}
        if decision is not None:
            cb, ca = float(decision.cost_before[e]), float(decision.cost_after[e])
            ev.update(cost_before=cb, cost_after=ca, worse_beyond_noise=ca - cb > noise)
        per_event.append(ev)
    fit = None if decision is None else decision.fit
    if decision is None:
        outcome = "nothing identifiable"
    elif decision.refused:
        outcome = "calibration refused"
    elif decision.changed:
        outcome = "changed " + ", ".join(decision.changed)
    else:
        outcome = "consistent with the .dyr"
    return {"models": um.models, "parameters": rows, "per_event": per_event,
            "outcome": outcome, "refused": None if decision is None else decision.refused,
            "noise_threshold": noise,
            "calibrated": bool(decision is not None and decision.changed),
            "converged": None if fit is None else fit.converged,
            "residual_autocorrelation": None if fit is None else fit.autocorrelation,
            "residual_bandwidth_frames": None if fit is None else fit.bandwidth_frames,
            "voltage_noise": None if fit is None else {
                "ln_v_sd": float(fit.voltage_noise[0]), "angle_sd_rad": float(fit.voltage_noise[1])},
            "eigenvalues": ranking.eigenvalues.tolist(),
            "not_identifiable": [r for r in ranking.reasons if r]}


def _pq(s):
    vr = np.asarray(s.v_mag_pu) * np.cos(np.asarray(s.v_ang_rad))
    vi = np.asarray(s.v_mag_pu) * np.sin(np.asarray(s.v_ang_rad))
    ir, ii = np.asarray(s.i_re_pu), np.asarray(s.i_im_pu)
    return vr * ir + vi * ii, vi * ir - vr * ii


# --- calibrated.dyr ---------------------------------------------------------------------------

def _con_index(record_model: str, part: str, field: str) -> int:
    """Position of a module field among the record's constants (an IBR record's: its ICONs
    then CONs, as :func:`jaxdse.ibr_from_dyr` reads them)."""
    if record_model in IBR_PARAMETERS:
        return IBR_FIELDS[record_model].index(IBR_PARAMETERS[record_model][field])
    if part == "machine":
        names = MACHINE_FIELDS[record_model]
        return names.index({"h_s": "H", "d_pu": "D"}[field])
    if part == "exciter":
        return EXCITER_ATTRIBUTES[record_model].index(field)
    if part == "stabiliser":
        raise KeyError(f"stabiliser {record_model} fields are not calibrated ({STABILISER_FIELDS})")
    return GOVERNOR_FIELDS[record_model].index(GOVERNOR_PARAMETERS[record_model][field])


def _fmt(x) -> str:
    return f"{x:.6g}" if isinstance(x, float) and math.isfinite(x) else str(x)


def calibrated_dyr(fleet: Fleet, changed) -> str:
    """The changed records in PSS/E .dyr syntax (read back by :func:`jaxdse.read_dyr`): only the
    parameters a :class:`~jaxdse._dyr.calibrate.Decision` changed."""
    lines = [f"@! jaxdse {__version__} calibrated records: {fleet.path.name}; unchanged records are "
             "not repeated"]
    for p, um, decision in changed:
        recs = {r.kind if r.kind != "other" else _part_of(r.model): r
                for r in fleet.dyr.unit_records(p.bus, um_id(p))}
        if p.ibr:
            recs = {IBR_ROLES[r.model]: r for r in fleet.dyr.unit_records(p.bus, um_id(p))
                    if r.model in IBR_ROLES}
        fit = decision.fit
        specs = {s.label: s for s in fit.specs}
        for part in (GFM_PARTS + IBR_PARTS if p.ibr else MACHINE_PARTS):
            mine = [(specs[lab], float(v)) for lab, v in zip(fit.labels, fit.values)
                    if lab in decision.changed and specs[lab].part == part]
            if not mine or part not in recs:
                continue
            rec = recs[part]
            cons = list(rec.constants)
            for s, v in mine:
                k = _con_index(rec.model, part, s.field)
                if part == "exciter" and rec.model == "ESST3A" and s.field == "theta_p_rad":
                    v = math.degrees(v)
                cons[k] = float(v)
            body = " ".join(_fmt(c) if isinstance(c, float) else str(c) for c in cons)
            lines.extend(repair_comment(c) for c in rec.changes)   # a repaired record stays so
            lines.append(f"{rec.bus} '{rec.model}' {rec.id} {body} /")
    return "\n".join(lines) + "\n"


def um_id(p: FleetPlant) -> str:
    return p.members[0].id


def _part_of(model: str) -> str:
    return "exciter" if model in EXCITER_FIELDS else ("stabiliser" if model in STABILISER_FIELDS else "other")


# --- pages ------------------------------------------------------------------------------------

def plot_before_after(e: dict, series, before, after, path: Path) -> None:
    """Per event (columns): P and Q, measured against the .dyr model (before) and the filed one
    (after), each with its residual panel, and the imposed |V| and frequency."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(series)
    ratios = [3, 1.2, 3, 1.2, 2, 2]
    fig, axes = plt.subplots(6, n, figsize=(5.4 * n, 12), sharex="col", squeeze=False,
                             gridspec_kw={"height_ratios": ratios})
    same = not e.get("calibrated")
    for j, (s, b, a) in enumerate(zip(series, before, after)):
        t = np.asarray(s.t_s)
        p, q = _pq(s)
        th = np.unwrap(np.asarray(s.v_ang_rad))
        f_dev = np.gradient(th, t) / (2 * np.pi)
        for i, (label, meas, bef, aft) in enumerate((("P [pu]", p, b.p_pu, a.p_pu),
                                                     ("Q [pu]", q, b.q_pu, a.q_pu))):
            ax, rax = axes[2 * i, j], axes[2 * i + 1, j]
            ax.plot(t, bef, color="tab:orange", lw=1.8, alpha=0.6, label=".dyr model (before)")
            if not same:
                ax.plot(t, aft, color="tab:blue", lw=1.0, ls="--", label="calibrated (after)")
            ax.plot(t, meas, color="k", lw=0.8, label="measured")
            rax.plot(t, bef - meas, color="tab:orange", lw=0.8, label="before")
            if not same:
                rax.plot(t, aft - meas, color="tab:blue", lw=0.8, ls="--", label="after")
            rax.axhline(0.0, color="k", lw=0.5)
            ax.set_ylabel(label)
            rax.set_ylabel("model − meas. [pu]", fontsize=8)
        for i, (label, y) in ((4, ("|V| [pu] (imposed)", np.asarray(s.v_mag_pu))),
                              (5, ("f − f0 [Hz] (imposed)", f_dev))):
            axes[i, j].plot(t, y, color="k", lw=0.8)
            axes[i, j].set_ylabel(label, fontsize=9)
        for ax in axes[:, j]:
            ax.grid(alpha=0.3)
        axes[0, j].set_title(f"event {j + 1}: {Path(e['events'][j]).name}", fontsize=9)
        axes[-1, j].set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8)
    axes[1, 0].legend(fontsize=7)
    what = "unchanged: the .dyr model is filed as it is" if same else "before and after calibration"
    fig.suptitle(f"{e['name']}: the unit's .dyr model against the recordings, {what} "
                 f"({e['outcome']})", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _f(x, spec=".4g") -> str:
    return "–" if x is None else format(x, spec)


OUTCOME_COLOURS = {"consistent with the .dyr": "#1a9850", "calibration refused": "#d73027",
                   "nothing identifiable": "#7f7f7f"}


def _outcome_badge(outcome: str) -> str:
    colour = OUTCOME_COLOURS.get(outcome, "#fdae61")          # "changed ...": orange
    return f'<span class="v" style="background:{colour}">{html.escape(outcome)}</span>'


def unit_page(e: dict) -> str:
    rows = "".join(
        f"<tr><td>{r['model']} {r['parameter']}</td><td>{_f(r['dyr_value'])}</td>"
        f"<td>{_f(r['sensitivity_P_pu'], '.3g')}</td><td>{_f(r['sensitivity_Q_pu'], '.3g')}</td>"
        f"<td>±{_f(r['relative_ci_percent_crlb'], '.2g')} %</td>"
        f"<td>{_f(r['variance_inflation'], '.3g')}</td>"
        f"<td>{'yes' if r['identifiable'] else 'no'}</td>"
        f"<td>{_f(r.get('calibrated_value'))}</td>"
        f"<td>{' – '.join(_f(x) for x in r['ci95']) if r.get('ci95') else '–'}</td>"
        f"<td>{_f(r['filed_value'])}</td><td>{html.escape(r['status'])}</td></tr>"
        for r in sorted(e["parameters"], key=lambda r: r["relative_ci_percent_crlb"]))
    ev = "".join(
        f"<tr><td>{j + 1}: {html.escape(Path(f).name)}</td>"
        + "".join(f"<td>{_f(x[w][c], '.3g')}</td>"
                  for c in ("P_t", "Q_t") for w in ("before_rms_percent_mbase", "after_rms_percent_mbase"))
        + (f"<td class=\"{'fail' if x.get('worse_beyond_noise') else 'pass'}\">"
           f"{_f(x.get('cost_before'), '.3g')} → {_f(x.get('cost_after'), '.3g')}</td>")
        + "</tr>"
        for j, (f, x) in enumerate(zip(e["events"], e["per_event"])))
    why = "".join(f"<li>{html.escape(w)}</li>" for w in e["not_identifiable"]) or "<li>none</li>"
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in e.get("notes", []))
    parts = (("converter", "electrical", "plant") if "converter" in e["models"]
             else ("machine", "exciter", "stabiliser", "governor"))
    models = " / ".join(e["models"].get(k, "-") for k in parts)
    words = {
        "consistent with the .dyr": "The events do not reject the .dyr values: every identifiable "
                                    "parameter's .dyr value lies inside its 95 % interval, or the fit "
                                    "improves the error by no more than the noise. calibrated.dyr holds "
                                    "nothing for this unit.",
        "calibration refused": "The events ask for a change, but it would make an event worse beyond "
                               "the noise: a model error, not a better value. Nothing was filed.",
        "nothing identifiable": "These events identify none of the parameters; nothing was calibrated.",
    }.get(e["outcome"], "The events reject the .dyr values of the parameters marked \"changed\" (outside "
                        "their 95 % intervals), the joint error falls by more than the noise, and no "
                        "event gets worse beyond it: calibrated.dyr holds the new values.")
    refused = f"<p class=\"fail\">{html.escape(e['refused'])}</p>" if e.get("refused") else ""
    body = f"""<p><a href="../report.html">← all units</a></p>
<h1>{html.escape(e['name'])}: {_outcome_badge(e['outcome'])}</h1>
<p>Records: {html.escape(models)}. NERC MOD-026-2 model validation: the recorded terminal voltage
and frequency are imposed on the unit's own model; its active and reactive power are compared
with the recording (the Transmission Planner sets the acceptance criteria).</p>
{repairs_box(e.get("repairs") or [])}
<p>{words}</p>{refused}
<img src="{html.escape(e['name'])}.png" alt="P and Q with residuals, V, f: measured, before and after">
<h2>Playback error by event</h2>
<p class="small">RMS error in % of MBASE; normalised cost: squared residuals of P and Q over
their noise level, summed over the frames (the noise alone moves it by about
{_f(e.get('noise_threshold'), '.3g')}; red: worse beyond that).</p>
<table><tr><th>event</th><th>P before</th><th>P after</th><th>Q before</th><th>Q after</th>
<th>normalised cost before → after</th></tr>{ev}</table>
<h2>Sensitivity ranking and calibration</h2>
<p class="small">Sensitivity: RMS over the events of x·dP/dx and x·dQ/dx [pu]. Cramér-Rao
half-width: how tightly these events can fix the parameter (95 %), all parameters free;
variance inflation: how much the others blur it. Fitted: the bounded least-squares value and
its 95 % interval; filed: what calibrated.dyr holds (the .dyr value unless changed).</p>
<table><tr><th>parameter</th><th>.dyr</th><th>sens. P</th><th>sens. Q</th><th>CRLB half-width</th>
<th>variance inflation</th><th>identifiable</th><th>fitted</th><th>95 % interval</th>
<th>filed</th><th>status</th></tr>{rows}</table>
<p>Not identifiable from these events (left at the .dyr value):</p><ul>{why}</ul>
{f'<p>Notes:</p><ul>{notes}</ul>' if notes else ''}
"""
    return _page(f"{e['name']}: {e['outcome']}", body)


def report_page(doc: dict) -> str:
    rows = []
    for u in doc["units"]:
        if "skipped" in u:
            rows.append(f"<tr><td>{html.escape(u['name'])}</td>"
                        f"<td colspan=5>skipped: {html.escape(u['skipped'])}</td></tr>")
            continue
        b = np.median([x["before_rms_percent_mbase"]["Q_t"] for x in u["per_event"]])
        a = np.median([x["after_rms_percent_mbase"]["Q_t"] for x in u["per_event"]])
        cal = ", ".join(f"{r['parameter']} {_f(r['dyr_value'])}→{_f(r['filed_value'])}"
                        for r in u["parameters"] if r["status"] == "changed")
        name = html.escape(u["name"])
        rows.append(f"<tr><td><a href=\"units/{name}.html\">{name}</a></td>"
                    f"<td>{_outcome_badge(u['outcome'])}</td>"
                    f"<td>{b:.3g}</td><td>{a:.3g}</td><td>{html.escape(cal or '–')}</td>"
                    f"<td>{len(u['not_identifiable'])}</td></tr>")
    body = f"""<h1>Model validation and calibration</h1>
<p class="small">{html.escape(doc['config'])}; events: {html.escape(', '.join(Path(e).name for e in doc['events']))};
jaxdse {html.escape(doc['jaxdse_version'])}; {doc['wall_time_s']:.0f} s. The changed records are in
<a href="calibrated.dyr">calibrated.dyr</a>: a parameter changes only where the events reject its
.dyr value and the joint error falls by more than the noise, and never when an event gets worse.</p>
<table class="sortable"><thead><tr><th>unit</th><th>outcome</th><th>Q RMS error before [% MBASE, median over events]</th>
<th>after</th><th>changed</th><th>parameters not identifiable</th></tr></thead><tbody>{''.join(rows)}</tbody></table>
"""
    return _page("jaxdse validate", body, script=True)


def validate(path, out_dir, stream=None) -> dict:
    """``jaxdse validate`` from Python: the validate.json document."""
    fleet = load_fleet(path)
    if fleet.playback.model != "dyr":
        fleet = dataclasses.replace(fleet, playback=dataclasses.replace(fleet.playback, model="dyr"))
    return run_validate(fleet, Path(out_dir), stream)


__all__ = ["DEFAULT_PARAMETERS", "calibrated_dyr", "explain", "parameter_specs", "run_validate", "validate"]
