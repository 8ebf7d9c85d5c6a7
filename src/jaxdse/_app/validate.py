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
3. calibrated: the identifiable ones by bounded Levenberg-Marquardt on all events jointly, with
   95 % intervals (Gauss-Newton: the residuals' long-run covariance, the imposed voltage's
   noise drawn again through the fitted model, the events' disagreement, and ``model_error``;
   see :mod:`jaxdse._dyr.calibrate`): the *after* playback.

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
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._core.front_end import front_end
from .._dyr.calibrate import (
    CalibrationSettings,
    ParameterSpec,
    calibrate,
    rank,
    stack_events,
)
from .._dyr.playback import PlaybackSettings, play_back
from .._io.errors import InputError
from .._io.measurement import condition
from .._io.psse import GOVERNOR_FIELDS, GOVERNOR_PARAMETERS, MACHINE_FIELDS
from .._io.readers import load_table
from .._models.exciters import _ATTRIBUTES as EXCITER_ATTRIBUTES
from .._models.exciters import EXCITER_FIELDS
from .._models.stabilisers import STABILISER_FIELDS
from .._version import __version__
from .dyr_fleet import plant_model, terminal_series
from .fleet_file import Fleet, FleetPlant, load_fleet
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
}
"""The default parameter set per model: H and D, the exciter's main gain and time constant, the
governor's droop (IEEEG1: its gain K = 1/R) and main time constant."""
D_BOUNDS = (-5.0, 20.0)
"""Default bounds of D [pu torque / pu speed]: it may sit at 0 in the .dyr."""


# --- parameters -------------------------------------------------------------------------------

def parameter_specs(unit, models: dict, options, notes: list) -> list[ParameterSpec]:
    """The parameters to rank and calibrate, with their bounds (``options``: CalibrateOptions)."""
    out = []
    for part in ("machine", "exciter", "governor"):
        model = models.get(part)
        table = DEFAULT_PARAMETERS.get("machine" if part == "machine" else model, ())
        for field, label in table:
            if options.parameters and label not in options.parameters:
                continue
            x = float(getattr(getattr(unit, part), field))
            lo_hi = options.bounds.get(label)
            if label == "D":
                lo, hi = lo_hi or D_BOUNDS
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


# --- events -----------------------------------------------------------------------------------

def _event_series(fleet: Fleet, p: FleetPlant, files: tuple, tables: dict):
    """The plant's TerminalSeries (machine base) from one recording (a file, or the files
    that share one time axis as [measurement] file lists them)."""
    spec = dataclasses.replace(p.run.measurement, file=tuple(files))
    if files not in tables:
        tables[files] = load_table(list(files), spec.format, csv_options=spec.csv_options,
                                   time_column=spec.columns.get("time"))
    segments, _ = condition(tables[files], spec, p.run.plant.machine)
    rec = segments[0][1]
    fe = jax.jit(front_end)(rec, p.run.plant, fleet.settings)
    s = fe.v_t * jnp.conj(fe.i_t)
    t = np.asarray(rec.t_s)
    return terminal_series(t - t[0], np.abs(np.asarray(fe.v_t)), np.asarray(fe.theta_t),
                           np.asarray(jnp.real(s)), np.asarray(jnp.imag(s)))


def _pad(series_list):
    """Stack series of unequal length: pad with the last sample, weight 0 there."""
    n = max(int(s.t_s.shape[0]) for s in series_list)
    out, w = [], []
    for s in series_list:
        k = int(s.t_s.shape[0])
        dt = float(s.t_s[1] - s.t_s[0])
        t = np.concatenate([np.asarray(s.t_s), float(s.t_s[-1]) + dt * np.arange(1, n - k + 1)])
        pads = [np.concatenate([np.asarray(a), np.repeat(np.asarray(a)[-1:], n - k)]) for a in s[1:]]
        out.append(type(s)(jnp.asarray(t), *(jnp.asarray(a) for a in pads)))
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
    fit_settings = PlaybackSettings(substeps=opts.substeps, solver=fleet.playback.solver,
                                    input_filter_hz=opts.input_filter_hz)
    cal = CalibrationSettings(max_relative_ci=opts.max_relative_ci,
                              noise_floor_pu=opts.noise_floor_pu, model_error=opts.model_error)
    progress = Progress(len(fleet.plants), stream)
    tables, units, changed = {}, [], []
    for p in fleet.plants:
        entry = {"name": p.name, "bus": p.bus, "events": files}
        pm = plant_model(fleet.raw, fleet.dyr, p, fleet.playback)
        if len(pm.units) != 1 or pm.fallback:
            entry["skipped"] = pm.fallback or (f"{len(pm.units)} units behind one PMU: played back in "
                                               "`jaxdse fleet`, not calibrated (their shares are not "
                                               "measured)")
            units.append(entry)
            progress.step(f"{p.name}: skipped")
            continue
        um = pm.units[0]
        try:
            series = [_event_series(fleet, p, r, tables) for r in recordings]
        except InputError as err:
            entry["skipped"] = str(err)
            units.append(entry)
            progress.step(f"{p.name}: skipped")
            continue
        events = _pad(series)
        notes = list(um.notes)
        specs = parameter_specs(um.unit, um.models, opts, notes)
        ranking = rank(um.unit, specs, events, fit_settings, cal)
        free = [s for s, ok in zip(specs, ranking.identifiable) if ok]
        result = calibrate(um.unit, free, events, fit_settings, cal) if free else None
        after_unit = result.unit if result is not None else um.unit
        before = [jax.tree.map(np.asarray, jax.jit(play_back)(um.unit, s, playback)) for s in series]
        after = [jax.tree.map(np.asarray, jax.jit(play_back)(after_unit, s, playback)) for s in series]
        entry.update(_unit_entry(um, specs, ranking, result, series, before, after, p))
        entry["notes"] = notes
        units.append(entry)
        if result is not None:
            changed.append((p, um, free, result))
        plot_before_after(entry, series, before, after, out_dir / "units" / f"{p.name}.png")
        (out_dir / "units" / f"{p.name}.html").write_text(unit_page(entry))
        progress.step(f"{p.name}: " + ("calibrated" if result is not None else "nothing identifiable"))
    dyr_text = calibrated_dyr(fleet, changed)
    (out_dir / "calibrated.dyr").write_text(dyr_text)
    doc = {"jaxdse_version": __version__, "config": str(fleet.path), "events": files,
           "settings": {"playback_substeps": playback.substeps, "fit_substeps": fit_settings.substeps,
                        **dataclasses.asdict(opts)},
           "units": units, "wall_time_s": round(time.perf_counter() - t_start, 2)}
    (out_dir / "validate.json").write_text(json.dumps(doc, indent=1, default=_json) + "\n")
    (out_dir / "report.html").write_text(report_page(doc))
    n_cal = sum(1 for u in units if u.get("calibrated"))
    print(f"[jaxdse] {len(units)} plant(s), {n_cal} calibrated; wrote {out_dir}/report.html, "
          f"validate.json, calibrated.dyr in {doc['wall_time_s']:.1f} s", file=stream)
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


def _unit_entry(um, specs, ranking, result, series, before, after, p) -> dict:
    rows = []
    fitted = {} if result is None else dict(zip(result.labels, zip(result.values, result.ci95)))
    for j, s in enumerate(specs):
        row = {"parameter": s.label, "model": um.models[s.part], "dyr_value": float(s.value(um.unit)),
               "bounds": [s.lower, s.upper],
               "sensitivity_P_pu": float(ranking.sensitivity[j, 0]),
               "sensitivity_Q_pu": float(ranking.sensitivity[j, 1]),
               "relative_ci_percent_crlb": float(100 * ranking.relative_ci[j]),
               "variance_inflation": float(ranking.variance_inflation[j]),
               "identifiable": bool(ranking.identifiable[j]),
               "why_not": ranking.reasons[j] or None}
        if s.label in fitted:
            v, ci = fitted[s.label]
            row.update(calibrated_value=float(v), ci95=[float(ci[0]), float(ci[1])],
                       change_percent=float(100 * (v - row["dyr_value"]) / row["dyr_value"])
                       if row["dyr_value"] != 0 else None)
        rows.append(row)
    per_event = []
    for s, b, a in zip(series, before, after):
        p_meas, q_meas = _pq(s)
        per_event.append({
            "before_rms_percent_mbase": {"P_t": _rms(b.p_pu, p_meas), "Q_t": _rms(b.q_pu, q_meas)},
            "after_rms_percent_mbase": {"P_t": _rms(a.p_pu, p_meas), "Q_t": _rms(a.q_pu, q_meas)}})
    return {"models": um.models, "parameters": rows, "per_event": per_event,
            "calibrated": result is not None,
            "converged": None if result is None else result.converged,
            "residual_autocorrelation": None if result is None else result.autocorrelation,
            "residual_bandwidth_frames": None if result is None else result.bandwidth_frames,
            "voltage_noise": None if result is None else {
                "ln_v_sd": float(result.voltage_noise[0]), "angle_sd_rad": float(result.voltage_noise[1])},
            "eigenvalues": ranking.eigenvalues.tolist(),
            "not_identifiable": [r for r in ranking.reasons if r]}


def _pq(s):
    vr = np.asarray(s.v_mag_pu) * np.cos(np.asarray(s.v_ang_rad))
    vi = np.asarray(s.v_mag_pu) * np.sin(np.asarray(s.v_ang_rad))
    ir, ii = np.asarray(s.i_re_pu), np.asarray(s.i_im_pu)
    return vr * ir + vi * ii, vi * ir - vr * ii


# --- calibrated.dyr ---------------------------------------------------------------------------

def _con_index(record_model: str, part: str, field: str) -> int:
    """Position of a module field among the record's constants."""
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
    """The changed records in PSS/E .dyr syntax (read back by :func:`jaxdse.read_dyr`)."""
    lines = [f"@! jaxdse {__version__} calibrated records: {fleet.path.name}; unchanged records are "
             "not repeated"]
    for p, um, specs, result in changed:
        recs = {r.kind if r.kind != "other" else _part_of(r.model): r
                for r in fleet.dyr.unit_records(p.bus, um_id(p))}
        for part in ("machine", "exciter", "governor"):
            mine = [(s, v) for s, v in zip(specs, result.values) if s.part == part]
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
            lines.append(f"{rec.bus} '{rec.model}' {rec.id} {body} /")
    return "\n".join(lines) + "\n"


def um_id(p: FleetPlant) -> str:
    return p.members[0].id


def _part_of(model: str) -> str:
    return "exciter" if model in EXCITER_FIELDS else ("stabiliser" if model in STABILISER_FIELDS else "other")


# --- pages ------------------------------------------------------------------------------------

def plot_before_after(e: dict, series, before, after, path: Path) -> None:
    """P/f and Q/V overlays: measured, the .dyr model (before) and the calibrated one (after)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    n = len(series)
    fig, axes = plt.subplots(4, n, figsize=(5.2 * n, 9), sharex="col", squeeze=False)
    for j, (s, b, a) in enumerate(zip(series, before, after)):
        t = np.asarray(s.t_s)
        p, q = _pq(s)
        th = np.unwrap(np.asarray(s.v_ang_rad))
        f_dev = np.gradient(th, t) / (2 * np.pi)
        rows = [("P [pu]", p, b.p_pu, a.p_pu), ("Q [pu]", q, b.q_pu, a.q_pu),
                ("|V| [pu] (imposed)", np.asarray(s.v_mag_pu), None, None),
                ("f - f0 [Hz] (imposed)", f_dev, None, None)]
        for i, (label, meas, bef, aft) in enumerate(rows):
            ax = axes[i, j]
            ax.plot(t, meas, color="k", lw=1.0, label="measured")
            if bef is not None:
                ax.plot(t, bef, color="tab:orange", lw=0.9, label=".dyr model (before)")
                ax.plot(t, aft, color="tab:blue", lw=0.9, ls="--", label="calibrated (after)")
            ax.set_ylabel(label)
            ax.grid(alpha=0.3)
        axes[0, j].set_title(Path(e["events"][j]).name, fontsize=9)
        axes[-1, j].set_xlabel("time [s]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"{e['name']}: the unit's .dyr model before and after calibration")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


STYLE = ("body{font-family:sans-serif;max-width:1200px;margin:auto}"
         "td,th{padding:2px 8px;border-bottom:1px solid #ddd}")


def _f(x, spec=".4g") -> str:
    return "–" if x is None else format(x, spec)


def unit_page(e: dict) -> str:
    rows = "".join(
        f"<tr><td>{r['model']} {r['parameter']}</td><td>{_f(r['dyr_value'])}</td>"
        f"<td>{_f(r['sensitivity_P_pu'], '.3g')}</td><td>{_f(r['sensitivity_Q_pu'], '.3g')}</td>"
        f"<td>±{_f(r['relative_ci_percent_crlb'], '.2g')} %</td>"
        f"<td>{_f(r['variance_inflation'], '.3g')}</td>"
        f"<td>{'yes' if r['identifiable'] else 'no'}</td>"
        f"<td>{_f(r.get('calibrated_value'))}</td>"
        f"<td>{' – '.join(_f(x) for x in r['ci95']) if r.get('ci95') else '–'}</td>"
        f"<td>{_f(r.get('change_percent'), '+.1f')}</td></tr>"
        for r in sorted(e["parameters"], key=lambda r: r["relative_ci_percent_crlb"]))
    ev = "".join(
        f"<tr><td>{html.escape(Path(f).name)}</td>"
        + "".join(f"<td>{_f(x[w][c], '.3f')}</td>"
                  for w in ("before_rms_percent_mbase", "after_rms_percent_mbase") for c in ("P_t", "Q_t"))
        + "</tr>"
        for f, x in zip(e["events"], e["per_event"]))
    why = "".join(f"<li>{html.escape(w)}</li>" for w in e["not_identifiable"]) or "<li>none</li>"
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in e.get("notes", []))
    models = " / ".join(e["models"].get(k, "-") for k in ("machine", "exciter", "stabiliser", "governor"))
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>{html.escape(e['name'])}</title>
<style>{STYLE}</style>
</head><body><p><a href="../report.html">← all units</a></p>
<h1>{html.escape(e['name'])}: model validation and calibration</h1>
<p>Records: {html.escape(models)}. MOD-026-2 model validation: the recorded terminal voltage and
frequency are imposed on the unit's own model; its active and reactive power are compared with
the recording (the Transmission Planner sets the acceptance criteria).</p>
<img src="{html.escape(e['name'])}.png" alt="P, Q, V, f: measured, before and after" style="max-width:100%">
<h2>Playback error by event [% of MBASE, RMS]</h2>
<table><tr><th>event</th><th>P before</th><th>Q before</th><th>P after</th><th>Q after</th></tr>{ev}</table>
<h2>Sensitivity ranking and calibration</h2>
<p>Sensitivity: RMS over the events of x·dP/dx and x·dQ/dx [pu]. Cramér-Rao half-width: how
tightly these events can fix the parameter (95 %), all parameters free; variance inflation:
how much the others blur it. Parameters above ±{_f(100 * 0.1, '.0f')} % are not calibrated.</p>
<table><tr><th>parameter</th><th>.dyr</th><th>sens. P</th><th>sens. Q</th><th>CRLB half-width</th>
<th>variance inflation</th><th>identifiable</th><th>calibrated</th><th>95 % interval</th>
<th>change [%]</th></tr>{rows}</table>
<p>Not identifiable from these events (left at the .dyr value):</p><ul>{why}</ul>
{f'<p>Notes:</p><ul>{notes}</ul>' if notes else ''}
</body></html>
"""


def report_page(doc: dict) -> str:
    rows = []
    for u in doc["units"]:
        if "skipped" in u:
            rows.append(f"<tr><td>{html.escape(u['name'])}</td>"
                        f"<td colspan=4>skipped: {html.escape(u['skipped'])}</td></tr>")
            continue
        b = np.median([x["before_rms_percent_mbase"]["Q_t"] for x in u["per_event"]])
        a = np.median([x["after_rms_percent_mbase"]["Q_t"] for x in u["per_event"]])
        cal = ", ".join(f"{r['parameter']} {_f(r['dyr_value'])}→{_f(r['calibrated_value'])}"
                        for r in u["parameters"] if r.get("calibrated_value") is not None)
        name = html.escape(u["name"])
        rows.append(f"<tr><td><a href=\"units/{name}.html\">{name}</a></td>"
                    f"<td>{b:.3f}</td><td>{a:.3f}</td><td>{html.escape(cal or 'nothing identifiable')}</td>"
                    f"<td>{len(u['not_identifiable'])}</td></tr>")
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>jaxdse validate</title>
<style>{STYLE}</style>
</head><body><h1>Model validation and calibration</h1>
<p>{html.escape(doc['config'])}; events: {html.escape(', '.join(Path(e).name for e in doc['events']))};
jaxdse {html.escape(doc['jaxdse_version'])}; {doc['wall_time_s']} s. The changed records are in
<a href="calibrated.dyr">calibrated.dyr</a>.</p>
<table><tr><th>unit</th><th>Q RMS error before [% MBASE, median over events]</th><th>after</th>
<th>calibrated</th><th>parameters not identifiable</th></tr>{''.join(rows)}</table></body></html>
"""


def validate(path, out_dir, stream=None) -> dict:
    """``jaxdse validate`` from Python: the validate.json document."""
    fleet = load_fleet(path)
    if fleet.playback.model != "dyr":
        fleet = dataclasses.replace(fleet, playback=dataclasses.replace(fleet.playback, model="dyr"))
    return run_validate(fleet, Path(out_dir), stream)


__all__ = ["DEFAULT_PARAMETERS", "calibrated_dyr", "parameter_specs", "run_validate", "validate"]
