"""The fleet report: report.html (sortable table, overview figure, units to look at first),
report.md, and units/<name>.html per unit (playback figure, numbers, verdict in words).

Static HTML with PNG figures beside the pages (matplotlib); the only script is a few lines
that sort the table by a clicked column.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from .._core.verdict import NOTES, VERDICTS

COLOURS = {"identified": "#1a9850", "weakly identified": "#fdae61", "not identified": "#d73027",
           "failed": "#7f7f7f", "not applicable": "#bdbdbd"}
"""H's verdict -> colour (figures and table); "not applicable": an inverter-based plant."""
VALIDATION_COLOURS = {"pass": "#1a9850", "fail": "#d73027", "not judged": "#7f7f7f"}
D_COLOURS = {"identified": "#1a9850", "negative": "#8e44ad", "not identified": "#d73027",
             "failed": "#7f7f7f", "not applicable": "#bdbdbd"}
"""D's verdict -> colour."""
"""The model validation's result -> colour."""
MODEL_NAMES = {"dyr": "own .dyr records", "surrogate": "surrogate (P only)"}

CSS = """
body{font-family:system-ui,sans-serif;margin:1.5em auto;max-width:1150px;color:#222;padding:0 1em}
table{border-collapse:collapse;font-size:14px;margin:.5em 0}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0;cursor:pointer} td:first-child,th:first-child{text-align:left}
.v{color:#fff;padding:1px 6px;border-radius:3px;white-space:nowrap}
.fail{color:#b00;font-weight:bold} .pass{color:#070}
img{max-width:100%} .small{font-size:12px;color:#555}
.datawarn{border-left:4px solid #c80;background:#fff8e6;padding:.3em .8em;margin:.8em 0;font-size:13px}
"""

SORT_JS = """
document.querySelectorAll('table.sortable th').forEach(function (th, col) {
  th.title = 'click to sort';
  th.addEventListener('click', function () {
    var body = th.closest('table').tBodies[0], rows = Array.from(body.rows);
    var up = th.dataset.dir !== 'up'; th.dataset.dir = up ? 'up' : 'down';
    function key(r) { var c = r.cells[col], s = c.dataset.sort || c.textContent.trim();
      var x = parseFloat(s); return isNaN(x) ? s.toLowerCase() : x; }
    rows.sort(function (a, b) { var x = key(a), y = key(b);
      if (typeof x !== typeof y) { return typeof x === 'number' ? -1 : 1; }
      return (x < y ? -1 : x > y ? 1 : 0) * (up ? 1 : -1); });
    rows.forEach(function (r) { body.appendChild(r); });
  });
});
"""


INVERTER_TYPES = ("inverter-based", "grid-forming")
"""fleet.json's ``plant_type`` of the plants that get the inverter-based page (P/f and Q/V)."""


def write_report(out_dir: Path, doc: dict, traces: dict, figures: bool = True) -> None:
    """Write report.html, report.md, overview.png and units/<name>.html (+ .png)."""
    out_dir = Path(out_dir)
    (out_dir / "units").mkdir(parents=True, exist_ok=True)
    units = doc["units"]
    if figures:
        plot_overview(units, out_dir / "overview.png")
        playback = PlaybackFigure()
        try:
            for e in units:
                if e.get("plant_type") in INVERTER_TYPES:
                    ibr_figure(e, traces[e["name"]], out_dir / "units" / f"{e['name']}.png")
                else:
                    playback.draw_unit(e, traces[e["name"]], out_dir / "units" / f"{e['name']}.png")
        finally:
            playback.close()
    for e in units:
        page = ibr_unit_page if e.get("plant_type") in INVERTER_TYPES else unit_page
        (out_dir / "units" / f"{e['name']}.html").write_text(page(e, doc, figures))
    (out_dir / "report.html").write_text(fleet_page(doc, figures))
    (out_dir / "report.md").write_text(fleet_markdown(doc))


# --- figures ----------------------------------------------------------------------------------

def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def plot_overview(units: list[dict], path: Path) -> None:
    """H with its 95 % interval per unit against the .dyr reference, coloured by verdict."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(max(7.0, 0.42 * len(units) + 2), 4.6))
    x = np.arange(len(units))
    for k, e in enumerate(units):
        if e["H_reference_s"] is None:   # an inverter-based plant: no H
            continue
        colour = COLOURS[e["verdict"]]
        h, (lo, hi) = e["H_s"], e["H_ci95"]
        if h is not None and math.isfinite(h):
            top = hi if hi is not None and math.isfinite(hi) else 3 * max(h, e["H_reference_s"])
            bottom = lo if lo is not None and math.isfinite(lo) else h
            ax.plot([k, k], [bottom, top], color=colour, lw=2.5, alpha=0.8)
            ax.plot(k, h, "o", color=colour, ms=6, mec="k", mew=0.5)
        ax.plot([k - 0.3, k + 0.3], [e["H_reference_s"]] * 2, color="k", lw=1.5)
    refs = [e["H_reference_s"] for e in units if e["H_reference_s"] is not None]
    ax.set_ylim(0, 2.2 * max(refs) if refs else 1.0)
    ax.set_xticks(x, [e["name"] for e in units], rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("inertia H [s, plant base]")
    ax.grid(axis="y", alpha=0.3)
    handles = [plt.Line2D([], [], color="k", lw=1.5, label="H of the PSS/E .dyr (reference)")]
    handles += [plt.Line2D([], [], color=COLOURS[v], marker="o", lw=2.5, mec="k", mew=0.5,
                           label=f"estimate with 95 % interval: {v}") for v in VERDICTS
                if any(e["verdict"] == v for e in units)]
    ax.legend(handles=handles, fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), ncol=2,
              frameon=False, title="Estimated inertia per unit against the model (off-scale "
              "intervals are clipped)", title_fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


class PlaybackFigure:
    """Measured against played-back x2, I_t, P_t and Q_t, each with the residual (replay minus
    measurement) in a panel below, the event window shaded where one was found: one figure
    whose lines are redrawn for each unit (a new figure's axes took ~40 % of its time)."""

    LABELS = {"x2": ("speed deviation\nx2", "rad/s"), "I_t": ("current I_t", "pu"),
              "P_t": ("active power\nP_t", "pu"), "Q_t": ("reactive power\nQ_t", "pu")}

    def __init__(self):
        plt = _plt()
        ratios = [3, 1] * len(self.LABELS)
        self.fig, axes = plt.subplots(2 * len(self.LABELS), 1, sharex=True, figsize=(9, 11),
                                      gridspec_kw={"height_ratios": ratios})
        self.axes = axes[0::2]
        self.res_axes = axes[1::2]
        self.lines, self.res_lines, self.spans = [], [], [None] * (2 * len(self.LABELS))
        for ax, rax, k in zip(self.axes, self.res_axes, self.LABELS):
            sim, = ax.plot([], [], lw=1.8, color="tab:red", alpha=0.55, label="simulated", zorder=2)
            meas, = ax.plot([], [], lw=0.8, color="k", label="measured", zorder=3)
            self.lines.append((meas, sim))
            res, = rax.plot([], [], lw=0.8, color="tab:red")
            rax.axhline(0.0, color="k", lw=0.5)
            self.res_lines.append(res)
            label, unit = self.LABELS[k]
            ax.set_ylabel(f"{label} [{unit}]", fontsize=8)
            rax.set_ylabel(f"sim − meas\n[{unit}]", fontsize=7)
            rax.tick_params(labelsize=7)
            for a in (ax, rax):
                a.grid(alpha=0.3)
        handles = [self.lines[0][0], self.lines[0][1]]
        self.legend = self.axes[0].legend(handles=handles, loc="upper right", fontsize=8)
        self.xlabel = self.res_axes[-1].set_xlabel("")
        self.title = self.fig.suptitle("", fontsize=9)
        # fixed margins: tight_layout measures every tick label and took 0.3 s of 0.4 s per unit
        self.fig.subplots_adjust(left=0.12, right=0.98, bottom=0.05, top=0.94, hspace=0.15)

    def draw(self, tr: dict, path: Path, title: str, sim_label: str, onset_s: float | None,
             event_s: float, xlim: tuple[float, float] | None = None) -> None:
        """Draw the traces ``tr`` ({"time_s": t, channel: (measured, simulated)}) and save the
        figure to ``path``; the event window [onset, onset + event_s] is shaded where an event
        was found (``onset_s`` not None), and the title says whether the recording is ambient.
        ``xlim``: only that time span (a zoom; the y-axes fit it)."""
        t = tr["time_s"]
        if xlim is not None:
            keep = (t >= xlim[0]) & (t <= xlim[1])
            tr = {k: v[keep] if k == "time_s" else (v[0][keep], v[1][keep]) for k, v in tr.items()}
            t = tr["time_s"]
        for j, k in enumerate(self.LABELS):
            meas, sim = tr[k]
            line_m, line_s = self.lines[j]
            line_m.set_data(t, meas)
            line_s.set_data(t, sim)
            self.res_lines[j].set_data(t, sim - meas)
            for i, ax in ((2 * j, self.axes[j]), (2 * j + 1, self.res_axes[j])):
                if self.spans[i] is not None:
                    self.spans[i].remove()
                self.spans[i] = (ax.axvspan(onset_s, onset_s + event_s, color="tab:blue", alpha=0.08)
                                 if onset_s is not None else None)
                ax.set_autoscaley_on(True)
                ax.relim()
                ax.autoscale_view()
                ax.set_xlim(float(t[0]), float(t[-1]))
            fin = meas[np.isfinite(meas)]
            if fin.size:
                lo, hi = float(fin.min()), float(fin.max())
                pad = 0.5 * max(hi - lo, 1e-6 * max(abs(hi), 1.0))
                sim_f = sim[np.isfinite(sim)]
                if sim_f.size and (sim_f.min() < lo - 4 * pad or sim_f.max() > hi + 4 * pad):
                    self.axes[j].set_ylim(lo - 4 * pad, hi + 4 * pad)
        self.legend.get_texts()[1].set_text(sim_label)
        self.xlabel.set_text("time [s] (shaded: event window)" if onset_s is not None
                             else "time [s] (ambient recording: no disturbance found, no event window)")
        head = "disturbance recording" if onset_s is not None else "ambient recording"
        self.title.set_text(f"{title}, {head}: measured and simulated")
        self.fig.savefig(path, dpi=90)

    def draw_unit(self, e: dict, tr: dict, path: Path) -> None:
        """A fleet unit's figure: its validation's event window, both results in the title."""
        val = e["validation"]
        pw = val["windows"] or {}
        event = (pw.get("windows") or {}).get("event", (0, 0))
        t = tr["time_s"]
        self.draw(tr, path, f"{e['name']} (H: {e['verdict']} · model validation, "
                  f"{MODEL_NAMES[val['model']]}: {val['result']})", _sim_label(e), pw.get("onset_s"),
                  (event[1] - event[0]) * (t[1] - t[0]))

    def close(self) -> None:
        _plt().close(self.fig)


# --- pages ------------------------------------------------------------------------------------

def _sim_label(e: dict) -> str:
    if e.get("playback_model") == "dyr":
        return "simulated (the unit's .dyr model, recorded voltage imposed)"
    return "simulated (3rd-order playback, identified H, D)"


def _playback_text(e: dict) -> str:
    """What the simulated traces are, and (for the .dyr model) which records and notes."""
    if e.get("playback_model") == "dyr":
        models = "; ".join("/".join(m.get(k, "-") for k in ("machine", "exciter", "stabiliser", "governor"))
                           for m in e.get("playback_models", []))
        notes = "".join(f"<li>{html.escape(n)}</li>" for n in e.get("playback_notes", []))
        sur = e.get("surrogate_playback_rms_percent_mbase") or {}
        return (f"<p class=\"small\">The simulated traces play the recorded terminal voltage into the "
                f"unit's own PSS/E records (machine/exciter/stabiliser/governor: {html.escape(models)}), "
                f"PSS/E PLBVFU1 convention, from the steady state of the first frames. The 3rd-order "
                f"surrogate with the identified H and D gave RMS errors of P {_f(sur.get('P_t'), '.2f')} %, "
                f"Q {_f(sur.get('Q_t'), '.2f')} % of MBASE.</p>"
                + (f"<ul class=\"small\">{notes}</ul>" if notes else ""))
    fb = e.get("playback_fallback")
    return ("<p class=\"small\">The simulated traces replay the recording's terminal voltage into the "
            "third-order machine with the identified H and D and the plant's governor model(s)."
            + (f" The .dyr model was asked for but not used: {html.escape(fb)}" if fb else "") + "</p>")


def _f(x, spec=".2f") -> str:
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else format(x, spec)


def repairs_box(lines: list[str]) -> str:
    """A unit page's list of the changes ``jaxdse check --repair`` made to its records."""
    if not lines:
        return ""
    return ('<div class="datawarn"><b>Repaired records</b> (changed by <code>jaxdse check --repair</code> '
            "so that the unit can start at rest; the model run here is the repaired one):<ul>"
            + "".join(f"<li>{html.escape(x)}</li>" for x in lines) + "</ul></div>")


def _ci(e) -> str:
    lo, hi = e["H_ci95"]
    return f"{_f(lo)} – {_f(hi) if hi is not None else '∞'}"


def _badge(verdict: str) -> str:
    return f'<span class="v" style="background:{COLOURS[verdict]}">{html.escape(verdict)}</span>'


def _decisive(e) -> list[str]:
    return [v for k, v in e["reasons"].items() if k not in NOTES]


def _page(title: str, body: str, script: bool = False) -> str:
    js = f"<script>{SORT_JS}</script>" if script else ""
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>{html.escape(title)}</title><style>{CSS}</style></head>\n<body>\n{body}\n{js}"
            "</body></html>\n")


def _vbadge(e: dict) -> str:
    val = e["validation"]
    return (f'<span class="v" style="background:{VALIDATION_COLOURS[val["result"]]}">'
            f'{html.escape(val["result"])}</span> <span class="small">{html.escape(MODEL_NAMES[val["model"]])}</span>')


def _attention(units: list[dict]) -> list[dict]:
    """Units to look at first: H not identified or the model validation not passed; worst of
    the two first (H's verdict, then the validation), then the largest |H error|."""
    todo = [e for e in units if e["verdict"] not in ("identified", "not applicable")
            or e["validation"]["result"] != "pass"]
    order = {"fail": 0, "not judged": 1, "pass": 2}
    return sorted(todo, key=lambda e: (-_rank(e["verdict"]), order[e["validation"]["result"]],
                                       -abs(e["H_error_percent"] or 0.0)))


def _rank(verdict: str) -> int:
    """H's verdict in order (``VERDICTS``), "not applicable" (no rotor) before all."""
    return VERDICTS.index(verdict) if verdict in VERDICTS else -1


def _mode(m: dict) -> str:
    if m is None or m.get("frequency_hz") is None:
        return "none"
    return f"{m['frequency_hz']:.2f} Hz, ζ {100 * m['damping_ratio']:.1f} %"


def _attention_line(e: dict) -> str:
    """H's verdict and the validation's result, each with its first reason."""
    parts = [f"H {_badge(e['verdict'])}" + (f" {html.escape(_decisive(e)[0])}" if _decisive(e) else "")]
    val = e["validation"]
    why = f" {html.escape(val['reasons'][0])}" if val["reasons"] else ""
    parts.append(f"model validation {_vbadge(e)}{why}")
    return " · ".join(parts)


def fleet_page(doc: dict, figures: bool) -> str:
    units, s = doc["units"], doc["summary"]
    order = {"pass": 0, "not judged": 1, "fail": 2}
    rows = []
    for e in units:
        err = e["H_error_percent"]
        val = e["validation"]
        rows.append(
            f"<tr><td><a href=\"units/{html.escape(e['name'])}.html\">{html.escape(e['name'])}</a></td>"
            f"<td>{e['bus']}</td><td>{e['s_mva']:.0f}</td>"
            f"<td>{html.escape('/'.join(m['model'] for m in e['units'][:1]))} ×{len(e['units'])}</td>"
            f"<td>{html.escape(', '.join(e['governor_models']))}</td>"
            f"<td>{_f(e['H_s'])}</td><td data-sort=\"{_f(e['interval']['relative_ci_percent'], '.3f')}\">"
            f"{_ci(e)}</td><td>{_f(e['H_reference_s'])}</td>"
            f"<td data-sort=\"{_f(abs(err) if err is not None else None, '.3f')}\">"
            f"{_f(err, '+.1f')}</td>"
            f"<td data-sort=\"{_rank(e['verdict'])}\">{_badge(e['verdict'])}</td>"
            f"<td>{_dbadge(e['D_verdict']) if e.get('D_verdict') else '–'}</td>"
            f"<td data-sort=\"{order[val['result']]}\">{_vbadge(e)}</td></tr>")
    todo = _attention(units)
    attention = "".join(
        f"<li><a href=\"units/{html.escape(e['name'])}.html\">{html.escape(e['name'])}</a>: "
        f"{_attention_line(e)}</li>" for e in todo[:10]) \
        or "<li>none: H is identified and the model validation passes for every unit</li>"
    if len(todo) > 10:
        attention += f"<li>… and {len(todo) - 10} more (sort the table below)</li>"
    skipped = "".join(f"<li>{html.escape(str(k['name']))} (bus {k['bus']}): {html.escape(k['reason'])}</li>"
                      for k in doc["skipped"])
    crit = doc["criteria"]
    median = s["median_abs_H_error_percent"]
    models = ", ".join(f"{MODEL_NAMES[m]} {n}" for m, n in s["validation_models"].items())
    results = ", ".join(f'<span class="v" style="background:{VALIDATION_COLOURS[r]}">{r}</span> {n}'
                        for r, n in s["validation"].items())
    body = f"""
<h1>Fleet: inertia from PMU recordings and model validation</h1>
<p class="small">{html.escape(doc['source'])} · jaxdse {html.escape(doc['jaxdse_version'])} ·
case {html.escape(Path(doc['case']['raw']).name)} (rev {doc['case']['raw_revision']}) and
{html.escape(Path(doc['case']['dyr']).name)} · {doc['wall_time_s']:.0f} s</p>
<p><b>{s['units']}</b> units estimated ({s['skipped']} skipped). Two separate results per unit:</p>
<ul>
<li><b>Inertia H</b> (what the recording says about H): {', '.join(f'{_badge(v)} {n}' for v, n in s['verdicts'].items())}.
Median |H − H<sub>.dyr</sub>|: <b>{_f(median, '.1f')} %</b>; {s['within_10_percent']} of {s['units']} within 10 %.
Identified although more than 10 % off the model: {len(s['identified_outside_10_percent'])}{
html.escape(' (' + ', '.join(s['identified_outside_10_percent']) + ')') if s['identified_outside_10_percent'] else ''}.</li>
{_damping_line(s)}
<li><b>Model validation</b> (NERC MOD-026-2: the played-back model against the recorded response):
{results}; played back with {html.escape(models)}.</li>
</ul>
<h2>Look at these first</h2>
<ul>{attention}</ul>
<h2>Estimated H against the model</h2>
{'<img src="overview.png" alt="estimated H with intervals against the .dyr H">' * figures}
<p class="small">Dots: the batch estimate of H (s, on the plant's summed MBASE); bars: its 95 %
interval; black dashes: the MBASE-weighted H of the plant's machine records in the .dyr.
Colour = H's verdict: green identified (95 % interval within ±10 %), orange weakly identified
(an estimate, not tight enough to file), red not identified (the data cannot tell H apart),
grey failed. H's verdict says nothing about the model validation, and the other way round.</p>
<h2>All units</h2>
<p class="small">Click a column heading to sort. <b>Model validation</b> in the terms of NERC
MOD-026-2: the simulated response to the disturbance must match the recorded one, active
power/frequency and reactive power/voltage; the Transmission Planner sets the acceptance
criteria ([criteria] of the fleet file). The model played back is the unit's own .dyr records
(the recorded terminal voltage imposed) wherever jaxdse simulates every one of them; otherwise
the 3rd-order surrogate with the identified H and D, which validates active power/frequency
only. Criteria: in the event window ({crit['event_s']:g} s from the onset), the replay's peak
deviation of P and Q within {crit['min_peak_ratio']:g}-{crit['max_peak_ratio']:g}x the measured
one; the measurement's dominant electromechanical mode and the replay's mode nearest to it in
frequency: damped at least {crit['min_damping_ratio_fraction']:g}x as much and within
{100 * crit['max_mode_frequency_error']:g} % of its frequency; RMS error of P ≤
{crit['max_rms_percent_mbase_p']:g} % and of Q ≤ {crit['max_rms_percent_mbase_q']:g} % of MBASE
in each window; no more than {crit['max_post_oscillation_ratio']:g}x the measured oscillation
after the event window. A recording without a disturbance is not judged. A whole-record
average (sMAPE) is reported, never judged.</p>
<table class="sortable"><thead><tr><th>unit</th><th>bus</th><th>MVA</th><th>machine model</th>
<th>governor(s)</th><th>H [s]</th><th>95 % interval [s]</th><th>.dyr H [s]</th><th>difference [%]</th>
<th>H's verdict</th><th>D's verdict</th><th>model validation</th></tr></thead><tbody>
{''.join(rows)}
</tbody></table>
{f'<h2>Skipped</h2><ul>{skipped}</ul>' if skipped else ''}
{accounting_section(doc)}
<p class="small">Also: <a href="fleet.json">fleet.json</a> (every number), <a href="fleet.csv">fleet.csv</a>,
<a href="report.md">report.md</a>.</p>
"""
    return _page("Fleet: inertia and model validation", body, script=True)


def accounting_section(doc: dict) -> str:
    """Every generator record of the case: the counts (they add up to the .raw's), each one not
    in the fleet with its reason, and the .dyr records of no generator."""
    acc = doc.get("accounting")
    if acc is None:
        return ""
    a = acc["summary"]
    items = [f"<li><b>{a['in_fleet']}</b> units of the plants estimated above</li>"]
    items += [f"<li><b>{a[k]}</b> {html.escape(w)}</li>" for k, w in acc["categories"].items() if a[k]]
    return (f"<h2>Every generator record of the case</h2><p>{html.escape(Path(doc['case']['raw']).name)} "
            f"has <b>{a['generator_records']}</b> generator records:</p><ul>{''.join(items)}</ul>"
            + record_tables(acc["generators_not_in_fleet"], "not in the fleet", acc["dyr_records_not_used"],
                            "", acc["dyr_records_unreadable"]))


def record_tables(generators: list[dict], left_out: str, records: list[dict], counts: str,
                  unreadable: list[str]) -> str:
    """The generator records left out (``left_out``: in words) with their reasons, the .dyr
    records of no generator (``counts``: their categories in words), the unreadable ones."""
    rows = "".join(
        f"<tr><td>{r['bus']}</td><td>{html.escape(r['id'])}</td><td>{r['line']}</td>"
        f"<td>{html.escape(r['category'])}</td><td>{html.escape(' '.join(r['models']) or '–')}</td>"
        f"<td style=\"text-align:left\" class=\"small\">{html.escape(r['why'])}</td></tr>"
        for r in generators)
    recs = "".join(
        f"<tr><td>{html.escape(r['model'])}</td><td>{r['line']}</td><td>{r['bus']}</td>"
        f"<td>{html.escape(r['id'])}</td><td>{html.escape(r['category'])}</td>"
        f"<td style=\"text-align:left\" class=\"small\">{html.escape(r['why'])}</td></tr>"
        for r in records)
    bad = "".join(f"<li>{html.escape(x)}</li>" for x in unreadable)
    return ((f"<details><summary>The {len(generators)} generator records {left_out}, and why</summary>"
             "<table class=\"sortable\"><thead><tr><th>bus</th><th>id</th><th>.raw line</th>"
             f"<th>category</th><th>.dyr records</th><th>why</th></tr></thead><tbody>{rows}</tbody>"
             "</table></details>" if rows else "")
            + (f"<p>.dyr records of no generator in the .raw (not used): {len(records)}{counts}</p>"
               "<table class=\"sortable\"><thead><tr><th>record</th><th>.dyr line</th><th>bus</th>"
               f"<th>id</th><th>category</th><th>why</th></tr></thead><tbody>{recs}</tbody></table>"
               if recs else "<p>Every .dyr record belongs to a generator record of the .raw.</p>")
            + (f"<p>.dyr records the reader could not attribute (not used):</p><ul>{bad}</ul>"
               if bad else ""))


def _damping_line(s: dict) -> str:
    if not s.get("D_verdicts"):
        return ""
    return ("<li><b>Damping D</b> of the swing equation (all the damping the recording shows, lumped; "
            "not the machine records' D): "
            + ", ".join(f"{_dbadge(v)} {n}" for v, n in s["D_verdicts"].items())
            + ".</li>")


def unit_page(e: dict, doc: dict, figures: bool) -> str:
    name = html.escape(e["name"])
    # D's findings are said in D's own section (damping_section)
    decisive = _decisive(e)
    notes = [v for k, v in e["reasons"].items()
             if k in NOTES and k not in ("negative_damping", "d_interval_wide")]
    fallbacks = ("<p><b>Plant data fallbacks</b> (the .dyr records as read, and what jaxdse did):</p><ul>"
                 + "".join(f"<li>{html.escape(f)}</li>" for f in e.get("fallbacks", [])) + "</ul>"
                 if e.get("fallbacks") else "")
    warnings = e.get("data_warnings") or []
    data_warnings = ('<div class="datawarn"><b>Data warnings</b> (odd values in the records, used as '
                     "given: their equations can be evaluated, as PSS/E simulates them):<ul>"
                     + "".join(f"<li>{html.escape(w)}</li>" for w in warnings) + "</ul></div>"
                     if warnings else "")
    repaired = repairs_box(e.get("repairs") or [])
    why = {"identified": "The recording determines H to within ±10 % at 95 % confidence.",
           "weakly identified": "An estimate is given, but it is not tight enough to file as identified:",
           "not identified": "The recording does not tell H apart; the number is not usable:",
           "failed": "The estimate failed:"}[e["verdict"]]
    reasons = "".join(f"<li>{html.escape(r)}</li>" for r in decisive)
    note_list = "".join(f"<li>{html.escape(r)}</li>" for r in notes)
    it = e["interval"]
    numbers = [("H [s]", _f(e["H_s"], ".3f")), ("95 % interval of H [s]", _ci(e)),
               ("H of the .dyr (MBASE-weighted) [s]", _f(e["H_reference_s"], ".3f")),
               ("difference [%]", _f(e["H_error_percent"], "+.1f")),
               ("interval half width [%]", _f(it["relative_ci_percent"], ".1f")),
               ("  of which measurement noise [%]", _f(it["noise_percent"], ".1f")),
               ("  model error: filter spread, enters as 1.96x [%]", _f(it["filter_spread_percent"], ".1f")),
               ("  refits with a slower/faster filter that fit (counted in the spread)",
                _f(it.get("filter_refits_counted"), "d")),
               ("condition number", _f(it["condition"], ".3g")),
               ("online DREM/I&I H [s]", _f(e["online"]["H_s"], ".3f")),
               ("torque offset the data ask for [pu]", _f(e["identification"].get("t_m_offset_pu"), ".4f")),
               ("governor gain error [-]", _f(e["identification"].get("governor_gain_error"), ".3f"))]
    num_rows = "".join(f"<tr><td>{k if '<sub>' in k else html.escape(k)}</td><td>{v}</td></tr>"
                       for k, v in numbers)
    val = e["validation"]
    pw = val["windows"] or {"onset_s": None, "scores": []}
    val_text = {"pass": "The played-back model follows the recorded response within the criteria.",
                "fail": "The played-back model does not follow the recorded response:",
                "not judged": "Not judged:"}[val["result"]]
    val_reasons = "".join(f"<li>{html.escape(r)}</li>" for r in val["reasons"])
    onset = (f"Event onset {_f(pw['onset_s'], '.2f')} s." if pw["onset_s"] is not None
             else "No disturbance found in the recording: an ambient recording, nothing judged by window.")
    win_rows = "".join(
        f"<tr><td>{sc['window']}</td><td>{sc['channel']}</td>"
        f"<td>{_f(sc['peak_deviation_measured'], '.3g')}</td>"
        f"<td>{_f(sc['peak_deviation_simulated'], '.3g')}</td>"
        f"<td>{_f(sc['rms_error'], '.3g')}</td><td>{_f(sc['aligned_rms_error'], '.3g')} "
        f"({_f(sc['shift_s'], '+.2f')} s)</td>"
        f"<td>{_mode(sc['mode_measured'])}</td><td>{_mode(sc['mode_simulated'])}</td></tr>"
        for sc in pw["scores"])
    unit_rows = "".join(
        f"<tr><td>{html.escape(m['id'])}</td><td>{m['model']}</td><td>{m['mbase_mva']:g}</td>"
        f"<td>{m['h_s']:g}</td><td>{html.escape(m['governor'] or 'none (constant torque)')}</td></tr>"
        for m in e["units"])
    q = e["data_quality"]
    quality = (f"{q.get('rows_read')} rows read at {_f(q.get('frame_rate_hz'), '.3g')} frames/s; "
               f"{len(q.get('bridged_gaps', []))} gap(s) bridged; {q.get('segments', 1)} segment(s), the "
               f"longest used; NaN samples: {sum((q.get('nan_samples') or {}).values())}")
    others = (f"<p><b>Other units on this bus</b> (no machine record, e.g. renewables; their current is "
              f"in the measured current and biases H): {html.escape(', '.join(e['other_units_on_bus']))}</p>"
              if e["other_units_on_bus"] else "")
    inputs = "".join(f"<li>{html.escape(i['file'])}: sha256 {i['sha256']}</li>" for i in doc["inputs"])
    cols = "".join(f"<li>{k}: <code>{html.escape(str(v))}</code></li>" for k, v in e["columns"].items())
    body = f"""
<p><a href="../report.html">← fleet</a></p>
<h1>{name}: H {_badge(e['verdict'])} · model validation {_vbadge(e)}</h1>
<p>Bus {e['bus']} ({e['bus_kv']:g} kV), {e['s_mva']:.0f} MVA, {len(e['units'])} unit(s);
governor model(s): {html.escape(', '.join(e['governor_models']))}; PMU at the
{'machine terminal' if e['location'] == 'terminal' else 'HV side of the step-up transformer'}.</p>
{data_warnings}
{repaired}
<p>Two separate results: what the recording says about the inertia H, and whether the
played-back model matches the recorded response. Neither implies the other.</p>
<h2>Inertia H: {_badge(e['verdict'])}</h2><p>{why}</p>{f'<ul>{reasons}</ul>' if reasons else ''}
{f'<p>Notes (do not change the verdict):</p><ul>{note_list}</ul>' if note_list else ''}
<h2>Model validation: {_vbadge(e)}</h2>
<p>{val_text}</p>{f'<ul>{val_reasons}</ul>' if val_reasons else ''}
<p class="small">What was validated: {html.escape(val['scope'])}.</p>
{f'<img src="{name}.png" alt="measured and simulated x2, I_t, P_t, Q_t with residuals">' * figures}
{_playback_text(e)}
<h3>By window</h3>
<p class="small">{onset} Deviations and errors in % of MBASE (x2: % of synchronous speed); peak
deviation from each trace's own pre-event value; the aligned error is the RMS error at the
best shift of the replay; modes (frequency, damping ratio) by the matrix pencil method in the
event window: the measurement's dominant electromechanical mode and the replay's mode nearest
to it. Whole-record RMS error: P {_f(e['playback_rms_percent_mbase']['P_t'], '.3g')} %, Q
{_f(e['playback_rms_percent_mbase']['Q_t'], '.3g')} % of MBASE.</p>
<table><tr><th>window</th><th>signal</th><th>peak dev. measured</th><th>peak dev. replay</th>
<th>RMS error</th><th>aligned RMS error (shift)</th><th>mode measured</th><th>mode replay</th></tr>
{win_rows}</table>
<h2>Numbers of the H estimate</h2><table>{num_rows}</table>
{damping_section(e)}
<h2>Plant (from the PSS/E case)</h2>
{fallbacks}
<table><tr><th>unit ID</th><th>model</th><th>MBASE [MVA]</th><th>H [s]</th><th>governor</th></tr>
{unit_rows}</table>
{others}
<h2>Data</h2><p>{html.escape(quality)}</p><ul>{cols}</ul>
<h2>Provenance</h2><p class="small">jaxdse {html.escape(doc['jaxdse_version'])}; fleet file
{html.escape(doc['config']['file'])} (sha256 {doc['config']['sha256']})</p><ul class="small">{inputs}</ul>
"""
    return _page(f"{e['name']}: H {e['verdict']}, model validation {val['result']}", body)


def _dbadge(verdict: str) -> str:
    return f'<span class="v" style="background:{D_COLOURS[verdict]}">{html.escape(verdict)}</span>'


D_WORDS = {
    "identified": "The recording determines the swing equation's D: its 95 % interval is narrower "
                  "than D itself.",
    "negative": "D < 0 with 95 % confidence: the swing equation needs negative damping to follow "
                "the recording. A finding about the unit's response (its excitation and stabiliser "
                "take away more damping than the damper windings add, as the swing equation sees "
                "them), worth a look at their tuning; not a negative D in the machine record.",
    "not identified": "The recording does not determine D: its 95 % interval is wider than D itself.",
    "failed": "The estimate failed: no D.",
}
"""D's verdict in words, on the unit page."""


def damping_section(e: dict) -> str:
    """The unit page's section on D: its own verdict, what it is and is not (stated once), the
    identified value per rad/s and per pu speed, and the machine records' D beside it."""
    d = e.get("damping")
    if d is None:
        return ""
    ci = d["D_ci95_pu_torque_per_rad_s"] or [None, None]
    ci_pu = d["D_ci95_pu_torque_per_pu_speed"] or [None, None]
    # the verdict in words; its numbers are in the table (fleet.json "damping" has the reasons)
    return f"""<h2>Damping D of the swing equation: {_dbadge(d['verdict'])}</h2>
<p>{html.escape(D_WORDS[d['verdict']])}</p>
<p><b>What this D is:</b> {html.escape(d['meaning'])}</p>
<table><tr><th></th><th>value</th><th>95 % interval (measurement noise only)</th></tr>
<tr><td>identified D [pu torque / (rad/s)]</td><td>{_f(d['D_pu_torque_per_rad_s'], '.4g')}</td>
<td>{' – '.join(_f(x, '.4g') for x in ci)}</td></tr>
<tr><td>identified D·ω<sub>s</sub> [pu torque / pu speed]</td>
<td>{_f(d['D_pu_torque_per_pu_speed'], '.4g')}</td>
<td>{' – '.join(_f(x, '.4g') for x in ci_pu)}</td></tr>
<tr><td>for comparison only: D of the machine record(s) as filed (MBASE-weighted) [pu torque / pu speed]</td>
<td>{_f(d['records_D_pu_torque_per_pu_speed'], '.4g')}</td>
<td>– (the record's value, not an estimate)</td></tr>
</table>"""


def fleet_markdown(doc: dict) -> str:
    s = doc["summary"]
    lines = [f"# Fleet: {doc['source']}", "",
             f"{s['units']} units, {s['skipped']} skipped. H: "
             + ", ".join(f"{v} {n}" for v, n in s["verdicts"].items())
             + f"; median |H error| {_f(s['median_abs_H_error_percent'], '.1f')} %. Model validation: "
             + ", ".join(f"{r} {n}" for r, n in s["validation"].items())
             + " (" + ", ".join(f"{MODEL_NAMES[m]} {n}" for m, n in s["validation_models"].items()) + ").", "",
             "| unit | MVA | governor(s) | H [s] | 95 % interval [s] | .dyr H [s] | error [%] | H's verdict "
             "| model validation | model played back |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for e in doc["units"]:
        lines.append(f"| {e['name']} | {e['s_mva']:.0f} | {'/'.join(e['governor_models'])} | "
                     f"{_f(e['H_s'])} | "
                     f"{_ci(e)} | {_f(e['H_reference_s'])} | {_f(e['H_error_percent'], '+.1f')} | "
                     f"{e['verdict']} | {e['validation']['result']} | {MODEL_NAMES[e['validation']['model']]} |")
    return "\n".join(lines) + "\n"


# --- inverter-based plants ----------------------------------------------------------------------

def ibr_figure(e: dict, tr: dict, path: Path) -> list[str]:
    """An inverter-based plant's P/f and Q/V panels (MOD-026-2's two checks): P measured and
    played back with the recorded frequency deviation on the right axis; Q measured and played
    back with the recorded |V| on the right axis; each with its residual below. Returns the
    axes' labels (y of each axis, then x)."""
    plt = _plt()
    t = tr["time_s"]
    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(9, 8), gridspec_kw={"height_ratios": [3, 1, 3, 1]})
    f_dev_hz = np.asarray(tr["x2"][0]) / (2 * np.pi)
    panels = (("P_t", "active power P [pu of MBASE]", f_dev_hz, "recorded frequency deviation [Hz]"),
              ("Q_t", "reactive power Q [pu of MBASE]", np.asarray(tr["V_t"][0]),
               "recorded terminal |V| [pu]"))
    for j, (k, ylabel, other, other_label) in enumerate(panels):
        ax, rax = axes[2 * j], axes[2 * j + 1]
        meas, sim = (np.asarray(x) for x in tr[k])
        ax.plot(t, sim, lw=1.8, color="tab:red", alpha=0.55, label="played back (own records)")
        ax.plot(t, meas, lw=0.8, color="k", label="measured")
        ax.set_ylabel(ylabel, fontsize=8)
        right = ax.twinx()
        right.plot(t, other, lw=0.8, color="tab:blue", ls="--", label=other_label.split(" [")[0])
        right.set_ylabel(other_label, fontsize=8, color="tab:blue")
        right.tick_params(labelsize=7, colors="tab:blue")
        ax.legend(handles=[*ax.get_lines(), *right.get_lines()], fontsize=7, loc="upper right")
        rax.plot(t, sim - meas, lw=0.8, color="tab:red")
        rax.axhline(0.0, color="k", lw=0.5)
        rax.set_ylabel("played − meas.\n[pu of MBASE]", fontsize=7)
        for a in (ax, rax):
            a.grid(alpha=0.3)
            a.tick_params(labelsize=7)
    axes[-1].set_xlabel("time [s]")
    val = e["validation"]
    fig.suptitle(f"{e['name']}: {_kind(e)}, P against frequency and Q against voltage "
                 f"(model validation: {val['result']})", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    labels = [a.get_ylabel() for a in fig.axes] + [axes[-1].get_xlabel()]
    plt.close(fig)
    return labels


def _kind(e: dict) -> str:
    """What the plant is, in the page's and the figure's titles."""
    return "grid-forming converter" if e.get("plant_type") == "grid-forming" else "inverter-based plant"


def _virtual_inertia(e: dict) -> str:
    """A grid-forming converter's virtual H and D (fleet.json's ``virtual_inertia``) in words."""
    v = e["virtual_inertia"]
    reasons = "".join(f"<li>{html.escape(r)}</li>" for r in e["reasons"].values())
    fitted = ", ".join(v.get("fitted") or ("M", "D"))
    fit = v.get("fitted") or {}
    h_label = ("equivalent inertia H = TPf/(2 mp) [s]" if "TPf" in fit
               else "virtual inertia H [s]" if "H" in fit else "virtual inertia H = M/2 [s]")
    return f"""<p>{html.escape(e['estimator'])}.</p>
<table><tr><td>{h_label}</td><td>{_f(v['H_s'], '.3f')}</td></tr>
<tr><td>95 % interval [s]</td><td>{_f(v['H_ci95'][0], '.3f')} – {_f(v['H_ci95'][1], '.3f')}
 (±{_f(v['relative_ci_percent'], '.1f')} %)</td></tr>
<tr><td>H in the record [s]</td><td>{_f(v['H_record_s'], '.3f')}</td></tr>
<tr><td>damping D [pu power / pu speed]</td><td>{_f(v['D'], '.3f')} ({_f(v['D_ci95'][0], '.3f')} –
 {_f(v['D_ci95'][1], '.3f')}); in the record {_f(v['D_record'], '.3f')}</td></tr>
<tr><td>playback RMS error [% MBASE], the record's {fitted} → fitted</td><td>
 P {_f(100 * v['rms_before_pu'][0], '.3g')} → {_f(100 * v['rms_after_pu'][0], '.3g')},
 Q {_f(100 * v['rms_before_pu'][1], '.3g')} → {_f(100 * v['rms_after_pu'][1], '.3g')}</td></tr>
</table>{f'<ul>{reasons}</ul>' if reasons else ''}
<p class="small">{html.escape(e['damping']['reasons'][0])}.</p>"""


def ibr_unit_page(e: dict, doc: dict, figures: bool) -> str:
    """An inverter-based plant's page: no H or D (no rotor), the validation in MOD-026-2's
    terms (P/f and Q/V panels, the window scores), the records played back and their notes."""
    name = html.escape(e["name"])
    val = e["validation"]
    pw = val["windows"] or {"onset_s": None, "scores": []}
    val_text = {"pass": "The played-back records follow the recorded response within the criteria.",
                "fail": "The played-back records do not follow the recorded response:",
                "not judged": "Not judged:"}[val["result"]]
    val_reasons = "".join(f"<li>{html.escape(r)}</li>" for r in val["reasons"])
    win_rows = "".join(
        f"<tr><td>{sc['window']}</td><td>{sc['channel']}</td>"
        f"<td>{_f(sc['peak_deviation_measured'], '.3g')}</td>"
        f"<td>{_f(sc['peak_deviation_simulated'], '.3g')}</td>"
        f"<td>{_f(sc['rms_error'], '.3g')}</td></tr>" for sc in pw["scores"])
    models = "".join(
        f"<tr><td>{html.escape(m['id'])}</td><td>{m['mbase_mva']:g}</td>"
        + "".join(f"<td>{html.escape(pm.get(k, '–'))}</td>" for k in ("converter", "electrical", "plant"))
        + "</tr>" for m, pm in zip(e["units"], e.get("playback_models") or [{}] * len(e["units"])))
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in e.get("playback_notes", []))
    fb = e.get("playback_fallback")
    rms = e["playback_rms_percent_mbase"]
    img = (f'<img src="{name}.png" alt="P with the frequency deviation and Q with |V|, measured and '
           'played back, with residuals">') if figures else ""
    body = f"""
<p><a href="../report.html">← fleet</a></p>
<h1>{name}: {_kind(e)} · model validation {_vbadge(e)}</h1>
<p>Bus {e['bus']} ({e['bus_kv']:g} kV), {e['s_mva']:.0f} MVA, {len(e['units'])} unit(s); PMU at the
{'plant terminal' if e['location'] == 'terminal' else 'HV side of the step-up transformer'}.</p>
{repairs_box(e.get("repairs") or [])}
<h2>Inertia H and damping D: {_badge(e['verdict'])}</h2>
{_virtual_inertia(e) if 'virtual_inertia' in e else
 f"<p>{html.escape(e['reasons']['several_units'])}.</p>" if 'several_units' in e['reasons'] else
 f"<p>{html.escape(e['reasons'].get('no_rotor', ''))}: the swing-equation estimator does not apply.</p>"}
<h2>Model validation: {_vbadge(e)}</h2>
<p>{val_text}</p>{f'<ul>{val_reasons}</ul>' if val_reasons else ''}
<p class="small">What was validated: {html.escape(val['scope'])}.</p>
{img}
<p class="small">Whole-record RMS error of the playback: P {_f(rms['P_t'], '.3g')} %,
Q {_f(rms['Q_t'], '.3g')} % of MBASE.{f' Not played back: {html.escape(fb)}' if fb else ''}</p>
<h3>By window</h3>
<p class="small">Event onset {_f(pw['onset_s'], '.2f')} s. Deviations and errors in % of MBASE.</p>
<table><tr><th>window</th><th>signal</th><th>peak dev. measured</th><th>peak dev. played back</th>
<th>RMS error</th></tr>{win_rows}</table>
<h2>Records played back</h2>
<table><tr><th>unit ID</th><th>MBASE [MVA]</th><th>converter</th><th>electrical controls</th>
<th>plant controller</th></tr>{models}</table>
{f'<p>Notes:</p><ul class="small">{notes}</ul>' if notes else ''}
<h2>Provenance</h2><p class="small">jaxdse {html.escape(doc['jaxdse_version'])}; fleet file
{html.escape(doc['config']['file'])} (sha256 {doc['config']['sha256']})</p>
"""
    return _page(f"{e['name']}: {_kind(e)}, model validation {val['result']}", body)
