"""Paste the measured figures into README.md from the results files (never typed by hand).

    python experiments/readme_results.py           # rewrite the block in README.md
    python experiments/readme_results.py --check   # exit 1 if README.md is out of date (CI)

The block lies between the markers ``<!-- results:begin -->`` and ``<!-- results:end -->``.
"""

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"



def _interconnection(r: dict) -> str:
    """The sentence of the whole-interconnection case (``--only interconnection``)."""
    st = r.get("steady") or {}
    cpu = r.get("processing_cpu_ms_per_frame") or {}
    off = r.get("backlog_worked_off_after_s")
    text = (f" A whole interconnection: {r['units']} units on {r['streams']} streams at "
            f"{r['frames_per_s']} frames/s for {r['seconds']:g} s with [inertia], recording off: the "
            "start's backlog (every unit's first chunk in the same second, run between frames) "
            "worked off (the median delay of the unit updates under 2.5 s from then on) "
            + ("not within the run" if off is None else f"{off:g} s after the first update"))
    if st:
        d = st["delay_s"]
        text += (f"; from then on ({st['updates']} updates over {st['stream_s']:g} s) delay from a "
                 f"window's last frame to its unit's estimate median {d['median']:.2f} s, 99 % "
                 f"{d['p99']:.2f} s, max {d['max']:.2f} s")
    if r.get("steady_inertia_delay_s"):
        d = r["steady_inertia_delay_s"]
        text += (f"; the area estimates {d['median']:.2f} s median, 99 % {d['p99']:.2f} s, max "
                 f"{d['max']:.2f} s after their time")
        whole = r.get("inertia_delay_s")
        if whole:
            text += f" (over the whole run, the start included: 99 % {whole['p99']:.1f} s)"
    if r.get("catch_up_s") is not None:
        text += f"; the start's and restarted units' chunks run between frames: {r['catch_up_s']:.1f} s"
    p = r["processing_ms_per_frame"]
    text += f"; processing per frame median {p['median']:.2f} ms, 99 % {p['p99']:.1f} ms"
    if cpu:
        text += f" (CPU {cpu['median']:.2f} / {cpu['p99']:.1f} ms)"
    return text + f"; peak memory {r['peak_rss_mib']:.0f} MiB."


def _second_run(rows: list, mon: dict) -> str:
    """The capacity part's run of the whole-interconnection case, when it holds one (the same case run
    after the smaller configurations, in the same process), beside the part of its own."""
    big = [r for r in rows if r["units"] > 1000]
    if not big or "interconnection" not in mon:
        return ""
    r, whole, steady = big[0], big[0].get("inertia_delay_s") or {}, big[0].get("steady_inertia_delay_s") or {}
    off = r.get("backlog_worked_off_after_s")
    nan = float("nan")
    return (" The same case run again as the capacity part's last configuration, after the six smaller "
            "ones in the same process: the start worked off "
            f"{'not within the run' if off is None else f'{off:g} s'} after the first update; the area "
            f"estimates 99 % {whole.get('p99', nan):.1f} s over the whole run "
            f"({steady.get('p99', nan):.2f} s after the start); busy fraction "
            f"{r['busy_fraction']:.2f}; peak memory {r['peak_rss_mib']:.0f} MiB.")


def load(rel: str):
    path = ROOT / rel
    return json.loads(path.read_text()) if path.exists() else None


def block() -> str:
    out = []
    bench = load("experiments/andes_bench/results.json")
    if bench:
        out.append(
            f"- **Independent simulator** (`experiments/andes_bench/results.md`, `python "
            f"experiments/andes_bench/run.py`): ANDES GENROU machines of `ieee14`, `npcc` and `wecc` "
            f"with their own governors and exciters, PMU noise {bench['noise']['tve_percent']} % TVE. "
            "Event recordings: H within 5 % of the truth for "
            f"{100 * bench['event_within_5pct_fraction']:.1f} % of {bench['event_units']} recordings; "
            "10-minute ambient recordings: within 10 % for "
            f"{100 * bench['ambient_within_10pct_fraction']:.1f} % of {bench['ambient_units']}. The 95 % "
            f"interval contains the true H in {100 * bench['ci95_coverage']:.1f} % of "
            f"{bench['ci95_coverage_draws']} noisy identifications ({bench['ci95_coverage_machines']} "
            f"machines). Units `identified` with an H error above 10 %: {bench['false_identified']}. "
            f"Of the event recordings within 5 % of the truth, {bench['sharpness']['events']['identified']} of "
            f"{bench['sharpness']['events']['within_5pct']} are `identified` (all recordings: "
            f"{bench['sharpness']['all']['identified']} of {bench['sharpness']['all']['within_5pct']}).")
    bi = load("experiments/andes_bench/beside_ibr.json")
    if bi:
        w, c = bi["with_inverters"], bi["cases"]["ieee14"]
        out.append(
            f"- **Machines beside inverter-based plants** (`experiments/andes_bench/beside_ibr.md`, `python "
            f"experiments/andes_bench/beside_ibr.py`): ieee14 with a PV plant, a type-3 wind plant or a "
            f"virtual synchronous generator in place of its bus-8 machine (ANDES), three events: the four "
            f"machines' H within 2 % of the truth on {100 * w['within_2pct']:.0f} % of {w['recordings']} "
            f"recordings (line trips {100 * w['line_trip_within_2pct']:.0f} %), within 5 % on "
            f"{100 * w['within_5pct']:.0f} %; `identified` more than 10 % off: {w['identified_over_10pct_off']}; "
            f"`identified` with an interval that misses the truth: {w['identified_interval_misses']}; `failed` "
            f"(the replay's solver at the batch's step cap): {len(w.get('failed', []))}. Without "
            f"the inverter plant: {100 * c['within_2pct']:.0f} %, {100 * c['line_trip_within_2pct']:.0f} %, "
            f"{100 * c['within_5pct']:.0f} % of {c['recordings']}.")
    acc = load("experiments/ibr_accuracy/results.json")
    if acc:
        def chain(c):
            lim = f", limits or freezes reached on {c['limits_reached']}" if c["limits_reached"] else ""
            return (f"{c['chain']}: {c['recordings']} recordings, median {c['median_rms_p_pct']:.3f} / "
                    f"{c['median_rms_q_pct']:.3f}, worst {c['worst_rms_p_pct']:.3f} / "
                    f"{c['worst_rms_q_pct']:.3f}{lim}")
        out.append(
            "- **Inverter-based model chains against ANDES** (`experiments/ibr_accuracy/results.md`, `python "
            "experiments/ibr_accuracy/run.py`; the benches' own `generate.py` say which constants make "
            "ANDES follow the WECC specification): each chain's records played back with ANDES's terminal "
            "voltage and frequency channel imposed, RMS error of P / Q in % of MBASE, median and worst over "
            "its recordings: " + "; ".join(chain(c) for c in acc["chains"])
            + ". Every chain within 0.1 % (median) and 0.5 % (each recording): "
            f"{'yes' if acc['all_meet'] else 'no'}.")
    iv = [load(f"experiments/andes_ibr_validate/{f}.json")
          for f in ("results_andes_ibr", "results", "results_model_error_0.02")]
    if all(iv):
        def planted(doc):
            return "; ".join(f"{r['model']} {r['parameter']} x{r['factor']:g}: {r['calibrated_value']:.4g} against "
                             f"{r['truth']:.4g} ({r['error_percent']:+.2f} %, truth in the interval: "
                             f"{'yes' if r['truth_in_ci'] else 'no'}, other parameters changed: "
                             f"{', '.join(r['unplanted_changed']) or 'none'})" for r in doc["planted"])
        out.append(
            "- **`jaxdse validate` on inverter-based plants** (`experiments/andes_ibr_validate/results*.md`, "
            "`python experiments/andes_ibr_validate/run.py [andes_ibr] [--model-error=0.02]`): the true records "
            f"pass on {100 * iv[0]['pass_rate']:.0f} % (REPCA1 off) and {100 * iv[1]['pass_rate']:.0f} % "
            f"(REPCA1 on) of the recordings. Planted errors, REPCA1 off: {planted(iv[0])}. REPCA1 on, the "
            f"default model error: {planted(iv[1])}. With `model_error` {iv[2]['model_error']:g}: "
            f"{planted(iv[2])}."
            + ("" if not (w := load("experiments/andes_ibr_validate/results_andes_ibr_wind.json")) else
               f" Type-3 wind (`andes_ibr_wind`): the true records pass on {100 * w['pass_rate']:.0f} % of "
               f"{len(w['per_recording'])} recordings; {planted(w)}.")
            + ("" if not (g := load("experiments/andes_ibr_validate/results_andes_gfm.json")) else
               f" Grid-forming REGCV1 (`andes_gfm`): the true records pass on {100 * g['pass_rate']:.0f} % "
               "of "
               f"{len(g['per_recording'])} recordings; {planted(g)}."))
    pb = load("experiments/andes_bench/playback.json")
    if pb:
        s = pb["summary"]
        out.append(
            f"- **.dyr playback against ANDES** (`experiments/andes_bench/playback.md`, `python "
            f"experiments/andes_bench/playback.py`): {s['played_back']} machine-recordings (ieee14, npcc, "
            f"wecc and two npcc cases derived by generate.py, npcc_exdc2 and npcc_xd2_below_xl; line "
            f"trip, load step, gen trip), each unit's own records with ANDES's terminal voltage "
            f"imposed: median RMS error P {s['median_rms_P_percent_mbase']:.4f} %, Q "
            f"{s['median_rms_Q_percent_mbase']:.4f} % of MBASE, largest P {s['max_rms_P_percent_mbase']:.3f} %, "
            f"Q {s['max_rms_Q_percent_mbase']:.3f} %; event-window peak error within 10 % of the measured "
            f"peak deviation for {s['event_peak_within_10_percent']}; rotor angle within 0.5 deg for "
            f"{s['angle_within_0.5_deg']}.")
    rag = load("experiments/andes_bench/records_as_given.json")
    if rag:
        e2, nsf = rag["exdc2"]["npcc_exdc2"], rag["exdc2"]["without_speed_factor"]
        given, off = (rag["summary"][k] for k in ("X''d below Xl, records as given",
                                                  "X''d below Xl, q-axis circuits forced off"))
        clean = rag["summary"]["clean npcc (records in order)"]
        out.append(
            f"- **Records used as given** (`experiments/andes_bench/records_as_given.md`, `python "
            f"experiments/andes_bench/records_as_given.py`): npcc re-simulated with X''d = Xl/2 on every "
            f"GENROU, {given['machine_recordings']} machine-recordings: median |H error| "
            f"{given['median_abs_H_error_percent']:.2f} % (largest {given['max_abs_H_error_percent']:.2f} %) "
            f"against {clean['median_abs_H_error_percent']:.2f} % ({clean['max_abs_H_error_percent']:.2f} %) "
            f"on the clean case, {given['played_back_with_own_records']} played back with their own records; "
            f"with the q-axis circuits forced off, median {off['median_abs_H_error_percent']:.2f} % (largest "
            f"{off['max_abs_H_error_percent']:.2f} %), `identified` {off['verdicts']['identified']}, "
            f"`identified` more than 10 % off {off['identified_more_than_10_percent_off']}. EXDC2 (npcc's "
            f"exciters swapped): RMS error P median {e2['median_rms_P_percent_mbase']:.4f} %, Q "
            f"{e2['median_rms_Q_percent_mbase']:.4f} % (largest {e2['max_rms_Q_percent_mbase']:.3f} %, "
            f"ANDES's speed factor on EFD); against ANDES's IEEEX1 (its EXDC2 without that factor) Q median "
            f"{nsf['median_rms_Q_percent_mbase']:.4f} %, largest {nsf['max_rms_Q_percent_mbase']:.3f} %.")
    DEPARTURES = {  # the departures that new_models.py traces (its traces()), in short
        "ESST4B": "ANDES's PI regulators track instead of holding at the non-windup limits of IEEE "
                  "421.5 and PSS/E, `esst4b_pi.py`",
        "ESDC1A": "ANDES simulates ESDC2A, whose VR limits scale with VT",
        "EXAC1": "ANDES's trapezoid step over-integrates the alternator voltage VE while its "
                 "anti-windup limiter pegs VR at VRMAX, `exac1_ve.py`"}
    nm = load("experiments/andes_bench/new_models.json")
    if nm:
        s = nm["summary"]
        out.append(
            f"- **The PSS/E library models of real cases against ANDES** (`experiments/andes_bench/new_models.md`, "
            f"`python experiments/andes_bench/new_models.py`): {', '.join(nm['by_model'])} on "
            f"{s['units']} units ({s['machine_recordings']} machine-recordings, "
            f"{', '.join(e.replace('_', ' ') for e in nm.get('by_event', {})) or 'line trip and load step'}): "
            f"median RMS error P {s['median_rms_P_percent_mbase']:.4f} %, Q "
            f"{s['median_rms_Q_percent_mbase']:.4f} % of MBASE, largest P {s['max_rms_P_percent_mbase']:.3f} %, "
            f"Q {s['max_rms_Q_percent_mbase']:.3f} %"
            + "".join(f"; {e.replace('_', ' ')}: largest P {v['max_rms_P_percent_mbase']:.3f} %, Q "
                      f"{v['max_rms_Q_percent_mbase']:.3f} % ({v['within_target']} of {v['recordings']} "
                      f"within 0.5 %, exciter limits reached in {v['exciter_limit_reached']})"
                      for e, v in nm.get("by_event", {}).items())
            + f"; event-window peak error within 10 % for {s['event_peak_within_10_percent']}; "
            f"{s['models_meeting_targets']} of {len(nm['by_model'])} models meet the targets"
            + (f" (not simulated: {', '.join(s['not_simulated'])})" if s.get("not_simulated") else "")
            + (f". Units beyond 0.5 % of MBASE: {s['beyond_0.5_percent']}, traced to a named departure "
               f"of ANDES from the PSS/E library: {s['beyond_0.5_percent_traced']} ("
               + "; ".join(f"{x}: {DEPARTURES[x]}" for x in sorted({t["exciter"] for t in nm["beyond_target"]
                                                                     if t["traced"]}))
               + "); each unit, its departure and the evidence in `new_models.md`"
               if "beyond_0.5_percent" in s and s["beyond_0.5_percent"] else "") + ".")
    fr = load("experiments/andes_bench/fleet_results.json")
    if fr:
        rows = fr["rows"]
        own = [r for r in rows if r["validation_model"] == "dyr"]
        out.append(
            f"- **Model validation of the ANDES bench** (`experiments/andes_bench/fleet_results.md`, `jaxdse "
            f"fleet` on the nine bench fleets, whose .dyr is the truth): played back with each unit's own "
            f"records for {len(own)} of {len(rows)} machine-recordings; "
            f"{sum(r['validation'] == 'pass' for r in own)} pass the window criteria, "
            f"{sum(r['validation'] == 'fail' for r in own)} fail (false alarms on a true model), "
            f"{sum(r['validation'] == 'not judged' for r in own)} not judged.")
    cal = load("experiments/andes_bench/calibration.json")
    if cal:
        s = cal["summary"]
        out.append(
            f"- **Calibration of planted .dyr errors** (`experiments/andes_bench/calibration.md`): "
            f"{s['machines']} machines, H, exciter gain and droop planted wrong, three events jointly: "
            f"H within 1 % for {s['H_within_1_percent_noise_free']}, every identifiable parameter within "
            f"10 % for {s['identifiable_within_10_percent']}"
            + (f", every identifiable planted error changed (and filed) for {s['planted_identifiable_changed']}, "
               f"parameters changed that were not planted: {s['changed_not_planted']}"
               if "changed_not_planted" in s else "")
            + "; 95 % intervals cover the truth in "
            f"{s['coverage_percent_all']:.1f} % of {s['noisy_draws']} noisy draws over {s['noisy_machines']} "
            f"machines (H: "
            f"{s['coverage_percent_H']:.1f} %)"
            + (f"; one noise-free calibration (ranking, joint fit, refit of the rejected ones) "
               f"{s['median_wall_s_per_calibration']:.0f} s, median" if "median_wall_s_per_calibration" in s
               else "") + ".")
    osl = load("experiments/naspi_osl_case1/dyr_playback.json")
    if osl:
        s = osl["summary"]
        out.append(
            f"- **OSL case 1, .dyr against surrogate playback** (`experiments/naspi_osl_case1/dyr_playback.md`): "
            f"median RMS error of Q {s['median_rms_Q_percent_mbase']['dyr']:.2f} % of MBASE with the "
            f".dyr records, {s['median_rms_Q_percent_mbase']['surrogate']:.2f} % with the surrogate; "
            f"plants whose model validation passes the window criteria: {s['pass_windows']['dyr']} (.dyr), "
            f"{s['pass_windows']['surrogate']} (surrogate, P only) of {s['plants']}.")
    naspi = load("experiments/naspi_osl_case1/results.json")
    if naspi:
        rows = [r for r in naspi["plants"] if r.get("H_s") is not None]
        errs = sorted(abs(r["H_error_percent"]) for r in rows)
        med = (errs[(len(errs) - 1) // 2] + errs[len(errs) // 2]) / 2
        false_id = sum(r["verdict"] == "identified" and abs(r["H_error_percent"]) > 10 for r in rows)
        verdicts = ", ".join(f"{v} {n}" for v, n in _count(r["verdict"] for r in rows).items())
        good = [r for r in rows if abs(r["H_error_percent"]) <= 5]
        out.append(
            f"- **NASPI 2021 contest, case 1** (`experiments/naspi_osl_case1/results.md`): {len(rows)} "
            f"plants of the WECC 240-bus model against the .dyr aggregate: median |H error| {med:.1f} %; "
            f"verdicts: {verdicts}; `identified` with an error above 10 %: {false_id}; of the "
            f"{len(good)} plants within 5 %, {sum(r['verdict'] == 'identified' for r in good)} are `identified`.")
    isone = load("experiments/isone_real/results.json")
    if isone:
        parts = [f"{e['name']} H {e['H_s']:.2f} s ({e['verdict']}), replay I_t/P_t sMAPE "
                 f"{e['smape_percent']['I_t']:.2f}/{e['smape_percent']['P_t']:.2f} %"
                 for e in isone["recordings"]]
        out.append("- **REAL ISO-NE recording** (`experiments/isone_real/results.md`, no ground truth): "
                   + "; ".join(parts) + ".")
    core = load("experiments/core_accuracy/results.json")
    if core:
        worst = max(abs(r["a2_error_percent"]) for r in core)
        out.append(f"- **Own simulator** (`experiments/core_accuracy/results.md`): online DREM a2 error at "
                   f"most {worst:.2f} % over {len(core)} recordings (noise-free and noisy).")
    mon = load("experiments/monitor/results.json")
    if mon and all(k in mon for k in ("osl", "npcc", "faults", "capacity")):
        o, n, c = mon["osl"], mon["npcc"], mon["capacity"]["rows"]
        keep = [r for r in c if r["keeps_up"]]
        wrong = sum(len(r["identified_more_than_10_percent_off_dyr"]) for r in mon["faults"]["runs"])
        windows = {(o["unit"], o["t_s"]) for r in mon["faults"]["runs"] for o in r["identified_more_than_10_percent_off_dyr"]}
        ups = sum(r["updates"] for r in mon["faults"]["runs"])
        big = max(c, key=lambda r: (r["frames_per_s"], r["units"]))
        out.append(
            f"- **Live monitor on loopback** (`experiments/monitor/results.md`, `python experiments/monitor/run.py`, "
            f"{mon['machine']}): `jaxdse pmu-sim` serving OSL case 1 ({o['units']} plants, window 60 s): first "
            f"estimate {o['timing']['first_estimate_after_s']['min']:.1f} s after the first frame, then every "
            f"{o['timing']['update_spacing_s']['max']:g} s; {o['within_batch_interval']} of {o['named']} updates "
            f"naming an H within the batch run's interval, {o['overlapping_batch_interval']} with an interval "
            f"overlapping it, the .dyr H inside {o['dyr_in_interval']}; ANDES npcc "
            f"line trip ({n['units']} units, 60 frames/s): ANDES's H inside {n['truth_in_interval']} of "
            f"{n['named']}; the recording replayed by `jaxdse run`: H within "
            f"{max(o['replay']['largest_relative_difference_H'], n['replay']['largest_relative_difference_H']):.0e}"
            f" (relative); {len(mon['faults']['runs'])} runs with injected faults (window 20 s): `identified` more than "
            f"10 % off the .dyr H in {wrong} of {ups} updates"
            + (f" ({len(windows)} distinct window(s))" if windows else "") + ". Delay from a frame's "
            f"timestamp to its estimate (OSL, real time): median {o['delay_s']['median']:.2f} s, 99 % "
            f"{o['delay_s']['p99']:.2f} s. Capacity: {big['units']} units at {big['frames_per_s']} frames/s "
            f"{'keep' if big['keeps_up'] else 'do not keep'} up (processing {big['processing_ms_per_frame']['median']:.1f}"
            f" ms per frame, median, against a {big['frame_period_ms']:.1f} ms period; delay 99 % "
            f"{big['delay_s']['p99']:.2f} s); {len(keep)} of {len(c)} configurations keep up."
            + ("" if "speed" not in mon else
               " README's example at `--speed` 1 and 5: delay median "
               + " and ".join(f"{r['delay_s']['median']:.3f} s" for r in mon["speed"]["rows"])
               + ", 99 % " + " and ".join(f"{r['delay_s']['p99']:.3f} s" for r in mon["speed"]["rows"])
               + f" of stream time (differences {mon['speed']['difference_s']['median']:.3f} s and "
               f"{mon['speed']['difference_s']['p99']:.3f} s).")
            + ("" if "interconnection" not in mon else _interconnection(mon["interconnection"]["rows"][0]))
            + _second_run(c, mon))

    tb = load("benchmarks/results.json")
    if tb:
        tp = tb["throughput_gen_samples_per_s"]
        joint = tb["ukf"]["dynamax_joint"]
        line = (f"- **Speed** (`benchmarks/results.md`, `python benchmarks/run.py`, {tb['machine']}): the "
                f"online pipeline at batch 1024 runs {tp['1024'] / 1e6:.2f} M generator-samples/s, "
                f"{tp['1024'] / tb['ukf']['dynamax_state']['gen_samples_per_s']:.1f}x dynamax's UKF; "
                f"dynamax's joint UKF (state and a1, a2) {joint['gen_samples_per_s'] / 1e3:,.0f} k with a "
                f"median a2 error of {joint['a2_error_percent_median_abs']:.2f} %")
        for name, v in tb.get("identify", {}).items():
            line += (f"; `identify` ({name}) {v['gen_samples_per_s'] / 1e3:,.0f} k "
                     f"({v['gen_samples_per_s'] / joint['gen_samples_per_s']:.2f}x the joint UKF), median a2 "
                     f"error {v['a2_error_percent_median_abs']:.3f} %")
        out.append(line + f". Peak memory {tb['peak_rss_gib_1h_x1024']:.2f} GiB for 1 h x 1024 "
                   f"configurations, {tb['peak_rss_gib_24h_chunked']:.2f} GiB for a 24 h recording streamed.")
        ic = tb.get("identify_cost")
        if ic:
            parts = "; ".join(f"{name} {r['us_per_gen_sample']:.2f} ({r['ratio_to_joint_ukf']:.2f}x)"
                              for name, r in ic["variants"].items())
            out.append(
                "- **What the interval costs** (`benchmarks/identify_cost.py`, batch "
                f"{ic['batch']}, dynamax's joint UKF {ic['dynamax_joint_gen_samples_per_s'] / 1e3:,.0f} k "
                f"generator-samples/s in the same run), in microseconds per generator-sample: {parts}. "
                f"One bootstrap draw costs {ic['bootstrap_us_per_draw_and_gen_sample']:.3f}; running at "
                f"twice the joint UKF's speed leaves {ic['us_per_gen_sample_at_2x_joint_ukf']:.2f} for the "
                "whole identification.")
        dp = tb.get("dyr_playback")
        if dp:
            out.append(f"- **.dyr playback cost** (`benchmarks/dyr_playback.py`): a 70 s event at 60 frames/s "
                       f"in a vmapped batch of {dp['playback']['units']} units, "
                       f"{dp['playback']['per_unit_s']:.3f} s per unit (compile apart; first call "
                       f"{dp['playback']['first_call_s']:.1f} s); a 3-event ranking and calibration of one "
                       f"unit {dp['calibration']['wall_s']:.0f} s (first run {dp['calibration']['first_run_s']:.0f} s).")
        rc = tb.get("real_case_fleet")
        if rc:
            progs = rc["programs"]
            left = (len(rc["units_left_out"]), len(rc["units_not_flat_or_failed"]),
                    len(rc.get("fleet_skipped", [])))
            out.append(
                f"- **A real case end to end** (`{rc['command']}`, {rc['machine']}, load average "
                f"{rc['load_average_at_start'][0]:.1f} at the start): `jaxdse fleet` with the .dyr playback "
                f"on ACTIVSg2000, {rc['units_run']} of its {rc['synchronous_units']} synchronous units "
                f"({left[0]} not simulated, {left[1]} not holding their power flow, {left[2]} skipped by the "
                f"fleet's plausibility checks), each with its own "
                f"records and a {rc['recording']['event_s']:.0f} s event at "
                f"{rc['recording']['frames_per_s']:.0f} frames/s ({rc['recording']['tve_percent']} % TVE): "
                f"{rc['cold']['wall_s']:.0f} s cold, {rc['warm']['wall_s']:.0f} s warm (persistent "
                f"cache; {rc['per_unit_s']['warm']:.2f} s per unit); {progs['playback']} playback "
                f"programs for {rc['model_chains']} model chains, {progs['assessment']} of the "
                f"assessment; {rc['played_back_with_own_records']} units played back with their own records; "
                f"the validation of these true models: pass {rc['validation']['pass']}, fail "
                f"{rc['validation']['fail']} (median RMS error of Q "
                f"{rc['median_rms_percent_mbase']['Q_t']:.2f} % of MBASE).")
        rr = tb.get("real_case_fleet_repaired")
        if rr:
            out.append(
                f"- **The repaired case end to end** (`{rr['command']}`, load average "
                f"{rr['load_average_at_start'][0]:.1f} at the start): ACTIVSg2000 after `jaxdse check --repair` "
                f"(repaired.raw and repaired.dyr): {rr['units_run']} of its {rr['synchronous_units']} "
                f"synchronous units run, {rr['played_back_with_own_records']} played back with their own "
                f"records; the validation of these true models: pass {rr['validation'].get('pass', 0)}, fail "
                f"{rr['validation'].get('fail', 0)} (median RMS error of P "
                f"{rr['median_rms_percent_mbase']['P_t']:.2f} %, Q {rr['median_rms_percent_mbase']['Q_t']:.2f} "
                f"% of MBASE); {rr['cold']['wall_s']:.0f} s cold, {rr['warm']['wall_s']:.0f} s warm.")
        rt = tb.get("real_case_fleet_texas7k")
        if rt:
            cats = rt["by_category"]
            sy, ib = cats["synchronous"], cats["inverter-based"]

            def verdicts(c):
                return ", ".join(f"{k} {v}" for k, v in sorted(c["validation"].items()))
            out.append(
                f"- **Texas 7k end to end, inverter-based plants included** (`{rt['command']}`, load average "
                f"{rt['load_average_at_start'][0]:.1f} at the start): {rt['synchronous_units']} synchronous "
                f"units and {rt['inverter_based_plants']} inverter-based plants in service, "
                f"{len(rt['units_left_out'])} not simulated, {len(rt['units_not_flat_or_failed'])} not holding "
                f"their power flow or not played to the end when the recordings were made, "
                f"{len(rt.get('fleet_skipped', []))} skipped by the fleet; {rt['units_run']} run through "
                f"`jaxdse fleet`, each with its own records and a {rt['recording']['event_s']:.0f} s event: "
                f"{rt['cold']['wall_s']:.0f} s cold, {rt['warm']['wall_s']:.0f} s warm (goal "
                f"{rt['goal_s']['cold']} and {rt['goal_s']['warm']} s). Synchronous: {sy['units']} units, "
                f"{verdicts(sy)} (median RMS error of P {sy['median_rms_percent_mbase']['P_t']:.2f} %, Q "
                f"{sy['median_rms_percent_mbase']['Q_t']:.2f} % of MBASE); inverter-based: {ib['units']} plants, "
                f"{verdicts(ib)} (P {ib['median_rms_percent_mbase']['P_t']:.2f} %, Q "
                f"{ib['median_rms_percent_mbase']['Q_t']:.2f} %).")
        cs = tb.get("check_stress")
        if cs:
            parts = []
            for name, c in cs["cases"].items():
                walls = ", ".join(f"{r['wall_s']:.0f}" for r in c["runs"])
                parts.append(f"{name}: {c['runs_done']} runs, {c['hangs']} hung, outcomes equal in every run: "
                             f"{'yes' if c['outcomes_equal_to_first'] else 'no'}, wall s {walls}")
            out.append(f"- **`jaxdse check` back to back under load** (`benchmarks/check_stress.py`, "
                       f"{cs['load_processes']} busy processes beside it, a run over {cs['limit_s']:.0f} s counted "
                       f"as hung): " + "; ".join(parts) + ".")
        fs = tb.get("fleet_scaling")
        if fs:
            out.append("- **Fleet scaling** (`benchmarks/fleet_scaling.py`, `jd.assess_units`, 90 s at 30 frames/s "
                       "per unit, compile included): " + "; ".join(
                           f"{k} unit(s) {v['wall_s']:.1f} s ({v['per_unit_s']:.3f} s per unit)"
                           for k, v in fs.items()) + ".\n\n  ![fleet scaling](benchmarks/fleet_scaling.png)")
    co = load("benchmarks/compile_options.json")
    if co:
        parts = [f"{k.split('x')[0]} units x {k.split('x')[1]} samples: compile "
                 f"{r['jaxdse']['compile_s']:.1f} s against {r['xla_defaults']['compile_s']:.1f} s, "
                 f"run {r['jaxdse']['run_s']:.2f} s against "
                 f"{r['xla_defaults']['run_s']:.2f} s" for k, r in co["sizes"].items()]
        worst = max(r["h_max_abs_difference_s"] for r in co["sizes"].values())
        out.append("- **Compile options** (`benchmarks/compile_options.py`, `jd.assess_units`, a fresh "
                   "process each; compile = first call minus second, tracing included): the pipeline "
                   "compiled with jaxdse's XLA options (LLVM level 1, XLA's classic emitters) against "
                   "XLA's defaults: "
                   + "; ".join(parts) + f"; H agrees within {worst:.0e} s.")
    sp = load("benchmarks/suite_profile.json")
    if sp:
        q, a = sp["tiers"].get("quick"), sp["tiers"].get("all")
        parts = []
        if q:
            parts.append(f"README's test command (the tests not marked `slow`): "
                         f"{q['totals']['tests']} tests, {q['elapsed_s']:.0f} s elapsed "
                         f"(pytest exit {q['pytest_exit']})")
        if a:
            t = a["totals"]
            top = ", ".join(f"`{f['file'].split('/')[-1]}` {f['wall_s']:.0f} s" for f in a["files"][:4])
            parts.append(f"the whole suite (`python -m pytest -q tests -m ''`): {t['tests']} tests, "
                         f"{a['elapsed_s']:.0f} s elapsed (pytest exit {a['pytest_exit']}), "
                         f"{t['cpu_s']:.0f} s of CPU in the tests, of which XLA's backend compile "
                         f"{100 * t['compile_share']:.0f} %, tracing {100 * t['trace_share']:.0f} % "
                         f"and lowering {100 * t['lower_share']:.0f} % "
                         f"({t['compiles']} compilations); the longest files: {top}; tests not marked `slow` "
                         f"that took {sp['slow_s']:g} s or more: {len(a['unmarked_over_s'])}")
        out.append(f"- **The suite's time** (`benchmarks/suite_profile.py`, {sp['machine']}, JAX's compile "
                   f"events per test): " + "; ".join(parts) + ".")
    read = load("benchmarks/read_24h.json")
    if read:
        out.append(f"- **Reading** a 24 h, 50 frames/s CSV (`benchmarks/read_24h.py`): "
                   f"{read['read_s']:.1f} s, peak memory {read['peak_rss_mib']:.0f} MiB.")
    tune = load("experiments/tuning/results.json")
    if tune:
        h = tune["heldout"]
        out.append(f"- **Tuning** (`experiments/tuning/results.md`): median convergence on held-out "
                   f"recordings {h['default (Table I)']['median_convergence_time_s']:.0f} s -> "
                   f"{h['tuned']['median_convergence_time_s']:.0f} s "
                   f"({tune['median_convergence_speedup']:.1f}x).")
    checks = [(name, load(f"experiments/{folder}/check.json"))
              for name, folder in (("ACTIVSg2000", "activsg2000"), ("Texas 7k", "texas7k"),
                                   ("Nordic 44 (ANDES's case)", "nordic44"))]
    parts = []
    for name, doc in checks:
        if doc is None:
            continue
        c, a = doc["summary"], doc["summary"].get("accounting")
        text = (f"{name}: {c['pass']} of {c['units']} units pass, {c['data problem']} data problem, "
                f"{c['not supported']} not supported, {c['fail']} fail")
        if a:
            left = ", ".join(f"{a[k]} {k}" for k in ("out of service", "no dynamic records", "converter",
                                                    "not a generator", "duplicate") if a.get(k))
            by = ", ".join(f"{n} {k}" for k, n in a.get("checked_by_category", {}).items())
            text += f" (of {a['generator_records']} generator records: {a['checked']} checked" + \
                (f" ({by})" if by else "") + (f", {left}" if left else "") + ")"
        parts.append(text)
    fixed = load("experiments/activsg2000/repaired/check.json")
    repairs = ROOT / "experiments/activsg2000/repairs.csv"
    if fixed and repairs.exists():
        n = len(repairs.read_text().splitlines()) - 1
        parts.append(f"ACTIVSg2000 with `--repair`: {n} constants changed (`experiments/activsg2000/repairs.csv`), "
                     f"then {fixed['summary']['pass']} of {fixed['summary']['units']} pass")
    if parts:
        out.append("- **Case checks** (`jaxdse check`, `experiments/*/check.json`): " + "; ".join(parts) + ".")
    si = load("experiments/system_inertia/results.json")
    if si and si.get("bench"):
        b = si["bench"]
        rows = "; ".join(f"{r['case']} {r['event'].replace('_', ' ')} {r['E_error_percent']:+.2f} % "
                         f"(measured part {r['E_measured_error_percent']:+.2f} %, "
                         f"{'covered' if r['covers'] else 'not covered'})" for r in b["rows"])
        text = (f"- **System inertia** (`experiments/system_inertia/results.json`, `{b['command']}`): the ANDES "
                f"bench, every unit measured: system E within 2 % of sum H_true S on {b['within_2pct']} of "
                f"{b['recordings']} recordings, the 95 % interval covering on {b['covers']} ({rows}); a third "
                f"of the units unmeasured: covering on {b['third_unmeasured_covers']}, measured share off by at "
                f"most {100 * b['max_abs_share_error']:.1f} points")
        o = si.get("osl")
        if o:
            sys_row = next((a for a in o["areas"] if a["area"] == "system"), None)
            if sys_row:
                text += (f"; OSL case 1 (one value per recording): system E {sys_row['E_MWs'] / 1e3:.1f} GW s "
                         f"[{sys_row['E_ci95'][0] / 1e3:.1f}, {sys_row['E_ci95'][1] / 1e3:.1f}], "
                         f"{100 * sys_row['measured_share']:.0f} % measured, commitment figure "
                         f"{sys_row['E_commitment_MWs'] / 1e3:.1f} GW s")
        live = si.get("osl_live")
        if live:
            sy = live["per_area"]["system"]
            text += (f"; OSL case 1 from its stream (`{live['command']}`, `osl_live.png`): {len(live['areas'])} "
                     f"lines every {live['spacing_s']:g} s of stream time ({sy['updates']} per area), system E "
                     f"{sy['E_MWs_min'] / 1e3:.1f}-{sy['E_MWs_max'] / 1e3:.1f} GW s beside the commitment figure "
                     f"{sy['E_commitment_MWs'] / 1e3:.1f} GW s, interval width {sy['ci95_width_percent_median']:.1f} % "
                     f"(median), {100 * sy['measured_share_median']:.0f} % measured (median); delay from a line's "
                     f"time to its emission median {live['inertia_delay_s']['median']:.2f} s, 99 % "
                     f"{live['inertia_delay_s']['p99']:.2f} s")
        out.append(text + ".")
    return "\n".join(out)


def _count(words):
    counts = {}
    for w in words:
        counts[w] = counts.get(w, 0) + 1
    return counts


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="exit 1 if README.md is out of date")
    args = ap.parse_args()
    text = README.read_text()
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    new = f"{head}{BEGIN}\n{block()}\n{END}{tail}"
    if args.check:
        if new != text:
            sys.exit("README.md's measured results are out of date: run python experiments/readme_results.py")
        return
    README.write_text(new)


if __name__ == "__main__":
    main()
