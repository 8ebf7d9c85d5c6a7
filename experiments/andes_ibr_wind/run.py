"""The type-3 wind plant of ``generate.py`` (REGCA1 + REECA1 + REPCA1 + WTDTA1 + WTARA1 + WTPTA1 +
WTTQA1, ANDES 2.0.0) played back by jaxdse: the ANDES table of the wind chain (issue 44).

    .venv/bin/python experiments/andes_ibr_wind/run.py

Each recording's terminal voltage phasor (|V| and angle of bus 8) is imposed on the plant that
``plant.dyr`` describes (``jaxdse.read_dyr`` -> ``jaxdse.ibr_model`` -> ``jaxdse.play_back``,
as a machine's records are played back; the frequency the plant sees is the recorded frequency
channel, which the plant does not use here: REPCA1's Fflag = 0), and its P and Q are compared
with ANDES's. Per event: the RMS error of P and of Q over the recording [% of MBASE]; the
largest error more than 50 ms from a switching instant (the event's: within the frame interval
that holds one, |V| jumps and the playback reconstructs the instant from the frames); the
largest error in the event window (from the event at 1 s to the end, switching instants
included); and the limits and freezes ANDES held in the event (``limits.json``, written by
generate.py from ANDES's own 1 ms steps). Targets (issue 44): median <= 0.1 % and every event
<= 0.5 % of MBASE (RMS).

Public API only. Writes results.json and results.md here.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd

import jaxdse

jax.config.update("jax_enable_x64", True)

HERE = Path(__file__).resolve().parent
EVENTS = ("linetrip", "loadstep", "fault", "dip")
SWITCHING_S = {"linetrip": (1.0,), "loadstep": (1.0,), "fault": (1.0, 1.1), "dip": (1.0, 1.1)}
"""The switching instants of generate.py's events [s]."""
T_EVENT_S = 1.0
AWAY_S = 0.05
TARGET_MEDIAN_PCT, TARGET_EVERY_PCT = 0.1, 0.5


def limits_reached(event: str) -> list[str]:
    """The limits and freezes ANDES held in ``event`` (``limits.json`` of generate.py: seconds at
    ANDES's own 1 ms steps, so that a limit held for a few ms between two frames counts)."""
    held = json.loads((HERE / "limits.json").read_text())[event]
    return [f"{name} ({s * 1e3:.1f} ms)" for name, s in held.items() if "[" not in name and s > 0]


def main():
    t0 = time.time()
    model = jaxdse.ibr_model(jaxdse.read_dyr(HERE / "plant.dyr"), 8, "1")
    assert model.unit is not None, model.missing
    unit = model.unit
    rows, traces = {}, {}
    for event in EVENTS:
        d = pd.read_csv(HERE / f"{event}.csv.gz")
        t, v, ang, f_dev, p, q = (d[c].to_numpy() for c in ("t_s", "v_pu", "angle_rad", "freq_dev_pu", "p_pu",
                                                                 "q_pu"))
        i = np.conj((p + 1j * q) / (v * np.exp(1j * ang)))
        series = jaxdse.TerminalSeries(*(jnp.asarray(x) for x in (t, v, ang, i.real, i.imag, f_dev)))
        r = jaxdse.play_back(unit, series)
        sp, sq = np.asarray(r.p_pu), np.asarray(r.q_pu)
        ep, eq = 100 * (sp - p), 100 * (sq - q)
        switching = np.asarray(SWITCHING_S[event])
        far = np.all(np.abs(t[:, None] - switching[None, :]) > AWAY_S + 1e-9, axis=1)
        window = t >= T_EVENT_S - 1e-9
        rows[event] = dict(
            ok=bool(r.ok), fixed_step_intervals=int(r.fixed_step_intervals),
            rms_p_pct=float(np.sqrt(np.mean(ep ** 2))), rms_q_pct=float(np.sqrt(np.mean(eq ** 2))),
            peak_away_p_pct=float(np.abs(ep[far]).max()), peak_away_q_pct=float(np.abs(eq[far]).max()),
            peak_window_p_pct=float(np.abs(ep[window]).max()),
            peak_window_q_pct=float(np.abs(eq[window]).max()),
            switchings_s=[round(float(s), 3) for s in switching],
            limits=limits_reached(event),
            v_min_andes_steps=json.loads((HERE / "limits.json").read_text())[event]["min |V| [pu]"],
            andes=dict(v_min=float(v.min()), v_max=float(v.max()), p_range=[float(p.min()), float(p.max())],
                       q_range=[float(q.min()), float(q.max())],
                       wg_range=[float(d["wg_pu"].min()), float(d["wg_pu"].max())],
                       theta_max_deg=float(d["theta_deg"].max()),
                       pm_range=[float(d["pm_pu"].min()), float(d["pm_pu"].max())],
                       freq_dev_range=[float(d["freq_dev_pu"].min()), float(d["freq_dev_pu"].max())]))
        traces[event] = (t, ep, eq)
        print(event, {k: rows[event][k] for k in ("ok", "rms_p_pct", "rms_q_pct", "peak_away_p_pct",
                                                   "peak_away_q_pct", "peak_window_p_pct",
                                                   "peak_window_q_pct")}, flush=True)
    rms = np.array([[rows[e]["rms_p_pct"], rows[e]["rms_q_pct"]] for e in EVENTS])
    worst_each = rms.max(axis=1)
    summary = dict(
        units=1, events=len(EVENTS), chain=model.structure,
        median_rms_p_pct=float(np.median(rms[:, 0])), median_rms_q_pct=float(np.median(rms[:, 1])),
        worst_rms_p_pct=float(rms[:, 0].max()), worst_rms_q_pct=float(rms[:, 1].max()),
        median_rms_pct=float(np.median(worst_each)), worst_rms_pct=float(worst_each.max()),
        worst_peak_away_pct=max(max(rows[e]["peak_away_p_pct"], rows[e]["peak_away_q_pct"]) for e in EVENTS),
        worst_peak_window_pct=max(max(rows[e]["peak_window_p_pct"], rows[e]["peak_window_q_pct"])
                                  for e in EVENTS),
        target_median_met=bool(np.median(worst_each) <= TARGET_MEDIAN_PCT),
        target_every_met=bool(worst_each.max() <= TARGET_EVERY_PCT),
        limits_reached_on=[e for e in EVENTS if rows[e]["limits"]],
        notes=model.notes, wall_s=round(time.time() - t0, 1))
    (HERE / "results.json").write_text(json.dumps(dict(summary=summary, events=rows), indent=1) + "\n")
    write_md(rows, summary)
    print(json.dumps(summary, indent=1))


def write_md(rows: dict, s: dict):
    lines = [
        "# Type-3 wind plant against ANDES 2.0.0 (bench experiments/andes_ibr_wind)", "",
        "Made by `.venv/bin/python experiments/andes_ibr_wind/run.py` from the recordings of "
        "`/work/andes-venv/bin/python experiments/andes_ibr_wind/generate.py` (its docstring: "
        "the case, the events and every constant chosen so that ANDES and the WECC specification "
        "agree).", "",
        f"Chain: {' + '.join(s['chain'])}; 1 unit, {s['events']} events, 100 frames/s for 8 s. "
        "Errors in % of MBASE (100 MVA). *away*: the largest error more than 50 ms from a "
        "switching instant; *window*: the largest error from the event (1 s) to the end.", "",
        "| event | RMS P | RMS Q | peak away P | peak away Q | peak window P | peak window Q | "
        "limits and freezes reached (ANDES) |",
        "|---|---|---|---|---|---|---|---|"]
    for e, r in rows.items():
        lines.append(f"| {e} | {r['rms_p_pct']:.4f} | {r['rms_q_pct']:.4f} | {r['peak_away_p_pct']:.4f} | "
                     f"{r['peak_away_q_pct']:.4f} | {r['peak_window_p_pct']:.4f} | "
                     f"{r['peak_window_q_pct']:.4f} | {'; '.join(r['limits']) or '-'} |")
    lines += [
        f"| **median** | {s['median_rms_p_pct']:.4f} | {s['median_rms_q_pct']:.4f} | | | | | |",
        f"| **worst** | {s['worst_rms_p_pct']:.4f} | {s['worst_rms_q_pct']:.4f} | "
        f"{s['worst_peak_away_pct']:.4f} (P or Q) | | {s['worst_peak_window_pct']:.4f} (P or Q) | | |", "",
        f"Targets: median RMS <= {TARGET_MEDIAN_PCT} % ({s['median_rms_pct']:.4f} %, the larger of P "
        f"and Q per event: {'met' if s['target_median_met'] else 'NOT met'}); every event <= "
        f"{TARGET_EVERY_PCT} % ({s['worst_rms_pct']:.4f} %: "
        f"{'met' if s['target_every_met'] else 'NOT met'}).", "",
        "ANDES's recordings (the plant moved):", "",
        "| event | V min..max | P range | Q range | wg range | pitch max [deg] | Pm range | f-1 range |",
        "|---|---|---|---|---|---|---|---|"]
    for e, r in rows.items():
        a = r["andes"]
        rng = {k: f"{a[k][0]:.5f}..{a[k][1]:.5f}" for k in ("p_range", "q_range", "wg_range")}
        lines.append(f"| {e} | {a['v_min']:.3f}..{a['v_max']:.3f} | {rng['p_range']} | {rng['q_range']} | "
                     f"{rng['wg_range']} | "
                     f"{a['theta_max_deg']:.4f} | {a['pm_range'][0]:.4f}..{a['pm_range'][1]:.4f} | "
                     f"{a['freq_dev_range'][0]:.2e}..{a['freq_dev_range'][1]:.2e} |")
    lines += [
        "", "V min..max: at the frames; at ANDES's own 1 ms steps the minimum is "
        + ", ".join(f"{e} {r['v_min_andes_steps']:.3f}" for e, r in rows.items()) + " pu.", "",
        "Notes (diagnosed in generate.py's docstring, where the trials are described):", "",
        "* the *window* peaks are the frames right after a switching: within a frame interval that "
        "holds one, |V| jumps and the playback reconstructs the instant and the fast transient "
        "after it from the frames;",
        "* the fault's *away* peak in Q (0.43 % at 1.16 s, 60 ms after the clearing, on a "
        "0.48 % bump at 1.14 s) and its later Q offset (0.044 %) come mostly from that "
        "reconstruction: REPCA1's voltage integrator, open loop under the imposed voltage, "
        "integrates it; the same fault recorded at 1 ms frames (a trial over 3 s, with Ka = 0.007) "
        "leaves 0.20 % and 0.004 %;",
        "* the fault's P offset after the event (about 0.03 %) is ANDES's WTTQA1, which does not "
        "freeze its integrator in a voltage dip as the specification does (with Kip = 0 in both, "
        "a trial with Ka = 0.007: 0.0006 % at 2 s against 0.031 %).",
    ]
    if s["notes"]:
        lines += ["", "jaxdse's notes on the records: " + "; ".join(s["notes"])]
    (HERE / "results.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
