"""``jaxdse monitor`` end to end on loopback (issue 35): ``jaxdse pmu-sim`` serves a recording
as a live C37.118.2 stream, the monitor estimates every unit's H every second.

    python experiments/monitor/run.py                  # everything, about 15 minutes on 2 cores
    python experiments/monitor/run.py --only osl npcc  # some parts

Parts (each a ``jaxdse pmu-sim`` process, the monitor in this process through the public API):

* ``osl``: NASPI OSL contest case 1 (22 plants of the WECC 240 case, 90 s at 30 frames/s, a
  forced oscillation), in real time, ``window_s`` 60: per unit, every update that names an H
  against the batch fleet run's interval (``experiments/naspi_osl_case1/results.json``): its
  point within it, its interval overlapping it; the time of the first estimate and the spacing
  of the others; then the recording through ``jaxdse run replay.toml``: the largest difference
  from the live updates; and replayed with an 87 s window, so that each unit's last update rests
  on the samples of the batch run: its H against the batch interval;
* ``npcc``: the ANDES npcc line trip (10 units, 70 s at 60 frames/s, the trip at 10 s), in real
  time, ``window_s`` 60: against ``experiments/andes_bench/fleet_results.json``'s batch
  intervals and ANDES's H; replay as above;
* ``ambient``: the ANDES npcc ambient recording (600 s at 30 frames/s, load noise only) at 10x,
  the default ``window_s`` 120: what the verdicts say when nothing excites H;
* ``faults``: OSL case 1 at 2x, ``window_s`` 20, with the faults of ``FAULTS``, one kind at a
  time where it restarts the estimators: per fault what the monitor counted and did, the
  median H of the last update before and of the first after it, and any update that names an H
  whose interval misses the batch interval;
* ``speed``: README's example (``examples/csv_positive_sequence.toml``, ``window_s`` 60) served
  at ``--speed`` 1 (100 s) and 5 (70 s): the delay of the updates in stream seconds, median and
  99th percentile, and their difference between the two speeds;
* ``capacity``: 1, 22 and 506 units at 30 frames/s (OSL, tiled 23x) and 1, 20 and 500 at 60
  frames/s (npcc, tiled 2x and 50x), then 5,016 at 30 frames/s (OSL tiled 228x on 6 streams,
  with [inertia]: ``INTERCONNECTION``), real time for ``CAPACITY_S`` seconds, ``window_s`` 30:
  the main thread's processing time per frame against the frame period, and the delay from a
  frame's timestamp to its estimate (median, 99th percentile, largest). A run keeps up when
  its delay stays bounded (the largest within ``KEEP_UP_DELAY_S``; the last frames, flushed
  when the monitor stops, are not counted);
* ``interconnection``: the 5,016-unit row of ``capacity`` alone (6 pmu-sim servers and the
  monitor share the machine's cores), run ``INTERCONNECTION_S`` seconds: the start's backlog
  and the delays after it, apart (``_start_and_steady``).

Writes results.json, results.md and live_view.png (the live view during the ``osl`` part, by
headless Chromium where it is installed) beside this file.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import shutil
import subprocess
import tempfile
import sys
import threading
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
OSL = ROOT / "experiments" / "naspi_osl_case1" / "fleet.toml"
JAXDSE = str(Path(sys.executable).parent / "jaxdse") if (Path(sys.executable).parent / "jaxdse").exists() \
    else (shutil.which("jaxdse") or "jaxdse")
"""The console script (``pip install jaxdse``), beside this Python where it is installed there."""
NPCC = ROOT / "experiments" / "andes_bench" / "fleet_npcc.toml"
CAPACITY_S = 45.0
ONE_UNIT = {30: "1232_navajo", 60: "B50_G1"}
WARM_UP_S = 35.0
"""The first run of each capacity case compiles its programs (the jit cache is the process's):
it must reach a segment's first chunk, which waits for the first min(30 s, window_s) of the
stream (T_ref and the governor's start), 30 s here."""
KEEP_UP_DELAY_S = 5.0
FAULTS = (
    ("drop@25+0.3", "10 frames dropped (bridged)"),
    ("error@30+0.2", "STAT data error 11 for 0.2 s"),
    ("crc@35+0.2", "bad CRC for 0.2 s"),
    ("late=0.15@40+0.3", "frames 0.15 s late"),
    ("sync@45+0.3", "STAT sync lost for 0.3 s"),
    ("time-quality@50+2", "STAT time quality 7 for 2 s (usable)"),
    ("trigger@52+1", "STAT trigger bit (usable)"),
    ("stale@55+0.3", "the frame before 55 s repeated for 0.3 s (stale, bridged)"),
)
RESTARTING = (
    ("drop@30+2", "2 s of frames dropped (a long gap)"),
    ("absent@30+1", "absent data (STAT 10, NaN) for 1 s"),
    ("config-change=2@30", "a configuration change (phasors float <-> integer)"),
    ("disconnect@30", "the connection closed"),
)


def serve(fleet: Path, *args: str) -> tuple[subprocess.Popen, int]:
    """``jaxdse pmu-sim FLEET --port 0 ARGS``; returns the process and its port."""
    # stderr to a file, never a pipe that nobody reads: a full pipe would stop the server
    err = tempfile.TemporaryFile("w+")
    proc = subprocess.Popen([JAXDSE, "pmu-sim", str(fleet), "--port", "0", *args], stdout=subprocess.PIPE,
                            stderr=err, text=True)
    line = proc.stdout.readline()
    m = re.search(r":(\d+) ", line)
    if not m:
        proc.kill()
        err.seek(0)
        raise RuntimeError(f"pmu-sim did not start: {line}{err.read()}")
    return proc, int(m.group(1))


def stop(procs):
    """Terminate the servers; one that has not ended 60 s later is killed."""
    for proc in procs:
        proc.terminate()
    for proc in procs:
        try:
            proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def monitor(fleet: Path, port: int, out: Path, seconds: float, window_s: float, tile: int = 1,
            screenshot_at: float | None = None) -> dict:
    out.mkdir(parents=True, exist_ok=True)
    cfg = out / "monitor.toml"
    cfg.write_text(f'fleet = "{fleet}"\nupdate_s = 1.0\nwindow_s = {window_s}\ntile = {tile}\n'
                   f"[stream]\nport = {port}\ntimeout_s = 3.0\nfrequency = \"{frequency(fleet)}\"\n"
                   + ("[view]\nport = 0\n" if screenshot_at is not None else ""))
    lines = []
    mon = jd.Monitor(jd.load_monitor(cfg), out / "live", log=lines.append, console=lambda x: None)
    if screenshot_at is not None:
        threading.Thread(target=screenshot, args=(mon, screenshot_at, HERE / "live_view.png"), daemon=True).start()
    summary = mon.run(seconds)
    summary["log"] = lines
    summary["updates_list"] = [json.loads(x) for x in (out / "live" / "updates.jsonl").read_text().splitlines()]
    return summary


def screenshot(mon, at: float, path: Path):
    """The live view as headless Chromium shows it, ``at`` seconds after the stream's data was
    turned on (its estimators compiled: tens of seconds on a cold cache, which ``Monitor.run``'s
    duration does not count either)."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which("google-chrome")
    mon.all_ready.wait(600.0)
    t0 = time.monotonic()
    while mon.view.bound is None and time.monotonic() - t0 < 30:
        time.sleep(0.1)
    time.sleep(max(0.0, at - (time.monotonic() - t0)))
    if browser and mon.view.bound:
        subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--window-size=1400,1250",
                        "--virtual-time-budget=3000", f"--screenshot={path}",
                        "http://{}:{}/".format(*mon.view.bound)], capture_output=True, timeout=120)


def frequency(fleet: Path) -> str:
    """OSL case 1 has no frequency channel: pmu-sim's FREQ is a central difference of the angle,
    so the monitor derives it as the batch run does ("angle"); the ANDES recordings carry the
    bus frequency ("stream")."""
    return "angle" if "naspi" in str(fleet) else "stream"


def run_part(fleet, out, seconds, window_s, *sim_args, tile=1, screenshot_at=None):
    proc, port = serve(fleet, *sim_args)
    try:
        return monitor(fleet, port, out, seconds, window_s, tile, screenshot_at)
    finally:
        stop([proc])


def against_batch(updates, batch: dict) -> dict:
    """Per unit: updates that name an H, how many of them lie within the batch interval, and how
    many have an interval that overlaps it."""
    per = {}
    for u in updates:
        if u["H_s"] is None:
            continue
        lo, hi = batch[u["unit"]]
        p = per.setdefault(u["unit"], {"named": 0, "within_batch_interval": 0, "overlapping_batch_interval": 0,
                                       "last_H_s": None})
        p["named"] += 1
        p["within_batch_interval"] += bool(lo <= u["H_s"] <= hi)
        p["overlapping_batch_interval"] += bool(u["H_ci95"][0] <= hi and u["H_ci95"][1] >= lo)
        p["last_H_s"], p["last_ci95"], p["last_verdict"] = u["H_s"], u["H_ci95"], u["verdict"]
    return per


def whole_recording(out: Path, batch: dict, updates, seconds: float) -> dict:
    """The like-for-like check: the recorded stream replayed (``jd.replay_recording``, equal to
    the live run) with a window as long as the recording (``seconds``, whole updates), so that
    each unit's last update rests on the samples the batch run used. Per unit that the live run
    identified: that update's H against the batch interval."""
    import tomllib

    live = out / "live"
    text = (out / "monitor.toml").read_text()
    long = out / "whole"
    long.mkdir(exist_ok=True)
    (long / "monitor.toml").write_text(re.sub(r"window_s = [\d.]+", f"window_s = {seconds:.1f}", text))
    rp = (live / "replay.toml").read_text()
    first = tomllib.loads(rp)["replay"]["part"][0]["file"]
    (long / "replay.toml").write_text(rp.replace(str(out / "monitor.toml"), str(long / "monitor.toml"))
                                      .replace(f'"{first}"', f'"{live / first}"'))
    last = {}
    for u in jd.replay_recording(long / "replay.toml"):
        if u["H_s"] is not None:
            last[u["unit"]] = u
    identified = {u["unit"] for u in updates if u["verdict"] == "identified"}
    rows = {name: {"H_s": u["H_s"], "H_ci95": u["H_ci95"], "verdict": u["verdict"], "batch_ci95": batch[name],
                   "within": batch[name][0] <= u["H_s"] <= batch[name][1]}
            for name, u in sorted(last.items()) if name in identified}
    return {"window_s": seconds, "units": len(rows), "within_batch_interval": sum(r["within"] for r in rows.values()),
            "per_unit": rows}


def replay_difference(out: Path, live) -> dict:
    again = jd.replay_recording(out / "live" / "replay.toml", out / "replayed")
    # unit by unit: the live monitor runs a start's chunks between frames, a group at a time, so
    # the units of one timestamp may come in another order than the replay's
    by = {(x["unit"], x["t"]): x for x in live}
    same_t = sorted((x["unit"], x["t"]) for x in again) == sorted(by)
    pairs = [(a, by[(a["unit"], a["t"])]) for a in again if (a["unit"], a["t"]) in by]
    diffs = [abs(a["H_s"] / b["H_s"] - 1) for a, b in pairs if a["H_s"] and b["H_s"]]
    cis = [abs(a["H_ci95"][k] / b["H_ci95"][k] - 1) for a, b in pairs
           if a["H_ci95"] and b["H_ci95"] for k in (0, 1) if np.isfinite(b["H_ci95"][k])]
    return {"updates": len(again), "same_timestamps": same_t,
            "largest_relative_difference_H": max(diffs, default=0.0),
            "largest_relative_difference_interval": max(cis, default=0.0)}


def timing(updates, window_s: float, t_first_frame: float) -> dict:
    by = {}
    for u in updates:
        by.setdefault(u["unit"], []).append(u["t"])
    first = [min(t) - t_first_frame for t in by.values()]
    steps = np.concatenate([np.diff(sorted(t)) for t in by.values()])
    return {"first_estimate_after_s": {"min": float(min(first)), "max": float(max(first))},
            "update_spacing_s": {"min": float(steps.min()), "max": float(steps.max())} if steps.size else None,
            "window_s": window_s}


def first_frame_time(out: Path) -> float:
    import tomllib

    part = tomllib.loads((out / "live" / "replay.toml").read_text())["replay"]["part"][0]
    return part["index0"] / part["frame_rate_hz"]


def verdicts(updates) -> dict:
    out = {}
    for u in updates:
        out[u["verdict"]] = out.get(u["verdict"], 0) + 1
    return out


def end_to_end(s, folder, batch, reference, reference_key):
    """A real-time part's summary: its updates against the batch intervals and a reference H."""
    ups = s["updates_list"]
    per = against_batch(ups, batch)
    return per, {
        "units": len(s["latest"]), "updates": len(ups), "verdicts": verdicts(ups),
        "timing": timing(ups, 60.0, first_frame_time(folder)),
        "units_naming_H": len(per), "named": sum(p["named"] for p in per.values()),
        "within_batch_interval": sum(p["within_batch_interval"] for p in per.values()),
        "overlapping_batch_interval": sum(p["overlapping_batch_interval"] for p in per.values()),
        reference_key: sum(1 for u in ups if u["H_s"] is not None
                           and u["H_ci95"][0] <= reference[u["unit"]] <= u["H_ci95"][1]),
        "per_unit": per, "delay_s": s["delay_s"], "processing_ms_per_frame": s["processing_ms_per_frame"],
        "replay": replay_difference(folder, ups), "streams": s["streams"]}


def part_osl(work):
    plants = json.loads((ROOT / "experiments" / "naspi_osl_case1" / "results.json").read_text())["plants"]
    batch = {p["name"]: p["H_ci95"] for p in plants}
    dyr = {p["name"]: p["H_reference_s"] for p in plants}
    s = run_part(OSL, work / "osl", 95.0, 60.0, screenshot_at=88.0)
    _, out = end_to_end(s, work / "osl", batch, dyr, "dyr_in_interval")
    return {**out, "whole_recording": whole_recording(work / "osl", batch, s["updates_list"], 87.0), "log": s["log"]}


def part_npcc(work):
    rows = json.loads((ROOT / "experiments" / "andes_bench" / "fleet_results.json").read_text())["rows"]
    batch = {r["unit"]: r["H_ci95"] for r in rows if r["case"] == "npcc" and r["event"] == "line_trip"}
    truth = {r["unit"]: r["H_reference_s"] for r in rows if r["case"] == "npcc" and r["event"] == "line_trip"}
    s = run_part(NPCC, work / "npcc", 75.0, 60.0)
    per, out = end_to_end(s, work / "npcc", batch, truth, "truth_in_interval")
    for name, p in per.items():
        p["H_andes_s"] = truth[name]
    return out


def part_ambient(work):
    fleet = work / "ambient_fleet.toml"
    fleet.write_text(NPCC.read_text().replace('"data/npcc', f'"{NPCC.parent}/data/npcc')
                     .replace("line_trip.csv.gz", "ambient.csv.gz"))
    s = run_part(fleet, work / "ambient", 65.0, 120.0, "--speed", "10")
    ups = s["updates_list"]
    truth = {m["tag"]: m["H_s_mbase"] for m in json.loads(
        (NPCC.parent / "data" / "npcc" / "truth.json").read_text())["machines"]}
    named = [u for u in ups if u["H_s"] is not None]
    return {"units": len(s["latest"]), "updates": len(ups), "verdicts": verdicts(ups),
            "named_truth_in_interval": sum(u["H_ci95"][0] <= truth[u["unit"]] <= u["H_ci95"][1] for u in named),
            "named": len(named)}


def _fault_rows(s, batch, dyr, faults, t0):
    ups = s["updates_list"]
    rows = []
    for spec, what in faults:
        start = float(re.search(r"@([\d.]+)", spec).group(1))
        dur = float(m.group(1)) if (m := re.search(r"\+([\d.]+)", spec)) else 0.0
        before = [u for u in ups if u["t"] - t0 < start and u["H_s"] is not None]
        after = [u for u in ups if u["t"] - t0 > start + dur + 1.0 and u["H_s"] is not None]
        last_before = {u["unit"]: u["H_s"] for u in before}
        first_after = {}
        for u in after:
            first_after.setdefault(u["unit"], u)
        rows.append({"fault": spec, "what": what,
                     "H_median_before_s": float(np.median(list(last_before.values()))) if last_before else None,
                     "H_median_after_s": float(np.median([u["H_s"] for u in first_after.values()]))
                     if first_after else None,
                     "first_estimate_after_fault_s": min((u["t"] - t0 - start for u in first_after.values()),
                                                         default=None)})
    wrong = [u for u in ups if u["H_s"] is not None and u["verdict"] == "identified"
             and (u["H_ci95"][1] < batch[u["unit"]][0] or u["H_ci95"][0] > batch[u["unit"]][1])]
    off = [{"unit": u["unit"], "t_s": round(u["t"] - t0, 3), "H_s": u["H_s"], "H_ci95": u["H_ci95"],
            "H_dyr_s": dyr[u["unit"]]} for u in ups
           if u["H_s"] is not None and u["verdict"] == "identified" and abs(u["H_s"] / dyr[u["unit"]] - 1) > 0.1]
    return rows, wrong, off


def part_faults(work):
    plants = json.loads((ROOT / "experiments" / "naspi_osl_case1" / "results.json").read_text())["plants"]
    batch = {p["name"]: p["H_ci95"] for p in plants}
    dyr = {p["name"]: p["H_reference_s"] for p in plants}
    out = {"runs": []}
    runs = [("minor", FAULTS)] + [(spec.split("@")[0].split("=")[0], ((spec, what),)) for spec, what in RESTARTING]
    for name, faults in runs:
        args = ["--speed", "2"] + [a for spec, _ in faults for a in ("--fault", spec)]
        s = run_part(OSL, work / f"faults_{name}", 50.0, 20.0, *args)
        t0 = first_frame_time(work / f"faults_{name}")
        rows, wrong, off = _fault_rows(s, batch, dyr, faults, t0)
        st = s["streams"][0]
        out["runs"].append({"run": name, "faults": rows, "updates": len(s["updates_list"]),
                            "verdicts": verdicts(s["updates_list"]),
                            "identified_outside_batch_interval": len(wrong),
                            "identified_more_than_10_percent_off_dyr": off,
                            "counts": {k: st.get(k, 0) for k in ("data_frames", "frames_used", "slots_without_frame",
                                                                 "late_frames", "repeated_frames", "off_grid_frames",
                                                                 "config_changes", "disconnects", "connect_failures")},
                            "decoder": st.get("decoder", {}),
                            "unusable_samples": sum(st.get("unusable_samples", {}).values()),
                            "stale_samples": sum(st.get("stale_samples", {}).values()),
                            "restarts": max((u["segment"] for u in s["updates_list"]), default=0) - 1,
                            "log": [x for x in s["log"] if "stream" in x]})
    return out


def part_capacity(work):
    rows = []
    for fleet, rate, tiles, units in ((OSL, 30, (1, 1, 23), (1, 22, 506)), (NPCC, 60, (1, 2, 50), (1, 20, 500))):
        for tile, n in zip(tiles, units):
            out = work / f"capacity_{rate}_{n}"
            out.mkdir(parents=True, exist_ok=True)
            cfg = out / "monitor.toml"
            text = (f'fleet = "{fleet}"\nupdate_s = 1.0\nwindow_s = 30.0\ntile = {tile}\n[stream]\ntimeout_s = 3.0\n'
                    f'frequency = "{frequency(fleet)}"\n')
            cfg.write_text(text)
            if n == 1:   # a unit whose recording is served (OSL case 1's first plant is refused as implausible)
                text += f"units = {json.dumps([ONE_UNIT[rate]])}\n"
            for seconds in (WARM_UP_S, CAPACITY_S):    # the first compiles (the jit cache is the process's)
                proc, port = serve(fleet, "--tile", str(tile), "--duration", str(seconds))
                try:
                    cfg.write_text(text + f"port = {port}\n")
                    t = time.perf_counter()
                    s = jd.Monitor(jd.load_monitor(cfg), out / "live", log=lambda x: None,
                                   console=lambda x: None).run(seconds + 3.0)
                    wall = time.perf_counter() - t
                finally:
                    stop([proc])
            rows.append(_capacity_row(s, rate, n, 1, wall))
    rows.append(_capacity_interconnection(work))
    return {"rows": rows, "seconds": CAPACITY_S, "keep_up_delay_s": KEEP_UP_DELAY_S}


def _capacity_row(s: dict, rate: int, n: int, streams: int, wall: float, cpu_s: float | None = None) -> dict:
    p = s["processing_ms_per_frame"] or {}
    d = s["delay_s"] or {}
    return {"frames_per_s": rate, "units": len(s["latest"]) if s["latest"] else n, "units_served": n,
            "streams": streams, "frame_period_ms": 1e3 / rate, "processing_ms_per_frame": p,
            "processing_cpu_ms_per_frame": s.get("processing_cpu_ms_per_frame"), "delay_s": d,
            "inertia_delay_s": s.get("inertia_delay_s"), "updates": s["updates"], "wall_s": round(wall, 1),
            "process_cpu_s": None if cpu_s is None else round(cpu_s, 1),
            "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0, 1),
            # frames of every stream, and the restarted units' chunks run between them
            "catch_up_s": s.get("catch_up_s"),
            "busy_fraction": (p.get("mean", np.nan) * rate * streams / 1e3 + s.get("catch_up_s", 0.0) / wall
                              if p else None),
            "keeps_up": bool(d) and d.get("max", np.inf) <= KEEP_UP_DELAY_S}


INTERCONNECTION = (6, 38)
"""The whole-interconnection case (issue 45): OSL case 1's 22 plants tiled 228 times (5,016
units, 4,560 served: 1034_sjuan is refused by the readers), at 30 frames/s, with [inertia]
(every area's E each second), over 6 concentrator streams of 38 copies each. One C37.118.2
stream cannot carry them: a data frame is at most 65,535 bytes (FRAMESIZE) and a station takes
at least 14 (26 as pmu-sim serves it, polar floats), and CFG-2, about 70 bytes a station,
holds at most about 930 stations."""


INTERCONNECTION_S = 240.0
"""The interconnection's measured run [s]: long enough to see the monitor after its start. The
start is the expensive part: each unit's first chunk processes the segment's first 30 s at once
(T_ref, the governor's start), and every unit of every stream reaches it in the same second.
``--loop`` joins OSL case 1's end (90 s) to its start: 7031_coloeast's copies (its recording has
1,440 samples the readers refuse) restart their segments at each junction, the others go on
(measured at tile 1 over 400 s of stream)."""
STEADY_DELAY_S = 2.5
"""The median delay of a set of unit updates [s] below which the monitor has worked off its
start (``_start_and_steady``): in service it is about 1.5 s (a chunk's update waits for its 1 s
lookahead), and a start's backlog holds it above 10 s."""


def _start_and_steady(updates: Path, inertia_times=(), inertia_delays=()) -> dict:
    """From ``updates.jsonl``: when the start's backlog was worked off (in seconds after the
    first update: the first set of unit updates, one per stream time, from which the median
    delay of every set of a tenth of the units or more stays under ``STEADY_DELAY_S``; a later
    restart's few units, deferred, do not count as the start's), and the delays of the unit
    updates from then on (median, 99 %, max) and their number; the updates before it are the
    start's. With the monitor's area lines (their times and delays, in emission order): the
    delays of those from then on (``steady_inertia_delay_s``)."""
    rows = [x for x in map(json.loads, updates.read_text().splitlines()) if "unit" in x and "delay_s" in x]
    if not rows:
        return {}
    t0 = rows[0]["t"]
    sets: dict = {}
    for x in rows:
        sets.setdefault(x["t"], []).append(x["delay_s"])
    times = sorted(sets)
    most = max(len(v) for v in sets.values())
    late = [t for t in times if len(sets[t]) >= 0.1 * most and np.median(sets[t]) >= STEADY_DELAY_S]
    after = [t for t in times if not late or t > late[-1]]
    if not after:
        return {"backlog_worked_off_after_s": None, "updates_in_start": len(rows)}
    start = after[0]
    d = np.array([x["delay_s"] for x in rows if x["t"] >= start])
    out = {"backlog_worked_off_after_s": round(start - t0, 3), "updates_in_start": len(rows) - int(d.size),
           "steady": {"updates": int(d.size), "stream_s": round(times[-1] - start, 3), "delay_s": _stats(d)}}
    area = np.array([dt for t, dt in zip(inertia_times, inertia_delays) if t >= start])
    if area.size:
        out["steady_inertia_delay_s"] = {**_stats(area), "line_sets": int(area.size)}
    return out


def _stats(d: np.ndarray) -> dict:
    return {"median": float(np.median(d)), "p99": float(np.quantile(d, 0.99)), "max": float(d.max())}


def interconnection_toml(bases: list[str], ports: list[int], per: int) -> str:
    """The monitor file of ``_capacity_interconnection``: stream k (on ``ports[k]``) carries
    copies k per + 1 .. k per + per of the plants ``bases``, as stations of the names
    ``jaxdse pmu-sim --tile per`` gives them (copy 1 as the plant, copy c as ``name~c``)."""
    text = (f'fleet = "{OSL}"\nupdate_s = 1.0\nwindow_s = 30.0\ntile = {len(ports) * per}\nrecord = false\n'
            '[inertia]\n')
    for k, port in enumerate(ports):
        units, stations = [], {}
        for c in range(per):
            for b in bases:
                name = b if k * per + c == 0 else f"{b}~{k * per + c + 1}"
                units.append(name)
                stations[name] = b if c == 0 else f"{b}~{c + 1}"
        text += (f"[[stream]]\nport = {port}\ntimeout_s = 3.0\nfrequency = \"angle\"\n"
                 f"units = {json.dumps(units)}\nstations = {{"
                 + ", ".join(f"{json.dumps(u)} = {json.dumps(st)}" for u, st in stations.items()) + "}\n")
    return text


def _capacity_interconnection(work) -> dict:
    """5,016 units on 6 streams (``INTERCONNECTION``), real time, with [inertia]: each
    ``jaxdse pmu-sim --tile 38`` serves stations ``name``, ``name~2`` .. ``name~38``; stream k's
    units are copies 38 k + 1 .. 38 k + 38, mapped to them by ``[stream.stations]``. The row
    adds the main thread's CPU time per frame, the process's CPU time during the run, the delay
    from a frame to the area estimate (``inertia_delay_s``) and the peak resident memory of this
    process (``ru_maxrss``: the monitor runs in it; the largest case runs last)."""
    streams, per = INTERCONNECTION
    tile = streams * per
    out = work / f"capacity_30_{22 * tile}"
    out.mkdir(parents=True, exist_ok=True)
    cfg = out / "monitor.toml"
    cfg.write_text(f'fleet = "{OSL}"\n')
    bases = [u.name for u in jd.load_monitor(cfg).units]
    for seconds in (WARM_UP_S, INTERCONNECTION_S):    # the first compiles (the jit cache is the process's)
        procs = []
        try:
            ports = []
            for _ in range(streams):
                proc, port = serve(OSL, "--tile", str(per), "--loop", "--duration", str(seconds + 300.0))
                procs.append(proc)
                ports.append(port)
            cfg.write_text(interconnection_toml(bases, ports, per))
            t, c0 = time.perf_counter(), time.process_time()
            mon = jd.Monitor(jd.load_monitor(cfg), out / "live", log=lambda x: None, console=lambda x: None)
            s = mon.run(seconds + 3.0)
            wall, cpu = time.perf_counter() - t, time.process_time() - c0
        finally:
            stop(procs)
    return {**_capacity_row(s, 30, 22 * tile, streams, wall, cpu), "seconds": INTERCONNECTION_S,
            **_start_and_steady(out / "live" / "updates.jsonl", mon.inertia_times, mon.inertia_delays)}


EXAMPLE = ROOT / "examples" / "csv_positive_sequence.toml"
SPEEDS = ((1, 100.0), (5, 70.0))
"""README's example (``examples/monitor.toml``'s fleet, ``window_s`` 60) at ``--speed`` 1 and 5, and
the monitor's ``--duration`` [wall s] of each."""


def part_speed(work):
    """The delay of the updates, in stream seconds, in real time and five times faster: the
    same (the estimate's own wait plus the monitor's work times the pace)."""
    rows = []
    for speed, seconds in SPEEDS:
        s = run_part(EXAMPLE, work / f"speed_{speed}", seconds, 60.0, "--speed", str(speed))
        d, w = s["delay_s"] or {}, s.get("wall_delay_s") or {}
        rows.append({"speed": speed, "monitor_duration_s": seconds, "updates": s["updates"],
                     "delay_s": d, "wall_delay_s": w})
    one, five = rows
    diff = {k: abs(five["delay_s"][k] - one["delay_s"][k]) for k in ("median", "p99")}
    return {"rows": rows, "difference_s": diff,
            "positive": all(r["delay_s"].get("median", -1) > 0 for r in rows)}


PARTS = {"osl": part_osl, "speed": part_speed, "npcc": part_npcc, "ambient": part_ambient, "faults": part_faults,
         "capacity": part_capacity,
         "interconnection": lambda work: {"rows": [_capacity_interconnection(work)], "seconds": INTERCONNECTION_S}}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=list(PARTS), default=list(PARTS))
    ap.add_argument("--work", default=str(HERE / "work"), help="folder for the runs' outputs")
    args = ap.parse_args()
    work = Path(args.work)
    path = HERE / "results.json"
    doc = json.loads(path.read_text()) if path.exists() else {}
    doc["machine"] = f"{platform.machine()}, {os.cpu_count()} cores"
    for name in args.only:
        t = time.perf_counter()
        print(f"{name} ...", flush=True)
        doc[name] = PARTS[name](work)
        doc[name]["wall_s"] = round(time.perf_counter() - t, 1)
        path.write_text(json.dumps(doc, indent=1, default=float) + "\n")
    (HERE / "results.md").write_text(report(doc))


def _f(x, fmt=".3g"):
    return "-" if x is None else format(x, fmt)


def report(doc) -> str:
    lines = ["# jaxdse monitor end to end on loopback", "", "Written by `experiments/monitor/run.py` "
             f"({doc.get('machine', '')}).", ""]
    for key, title in (("osl", "NASPI OSL case 1, 22 plants, 30 frames/s, real time, window 60 s"),
                       ("npcc", "ANDES npcc line trip, 10 units, 60 frames/s, real time, window 60 s")):
        r = doc.get(key)
        if not r:
            continue
        t = r["timing"]
        lines += [f"## {title}", "",
                  f"- updates: {r['updates']} ({', '.join(f'{k} {v}' for k, v in r['verdicts'].items())}); "
                  f"first estimate {t['first_estimate_after_s']['min']:.2f}-{t['first_estimate_after_s']['max']:.2f} s "
                  f"after the first frame, then every {_f(t['update_spacing_s'] and t['update_spacing_s']['min'])}-"
                  f"{_f(t['update_spacing_s'] and t['update_spacing_s']['max'])} s",
                  f"- units naming an H: {r['units_naming_H']} of {r['units']}; updates naming an H within the batch "
                  f"run's 95 % interval: {r['within_batch_interval']} of {r['named']}"
                  + (f"; whose interval overlaps it: {r['overlapping_batch_interval']}"
                     if "overlapping_batch_interval" in r else "")
                  + (f"; ANDES's H inside the update's interval: {r['truth_in_interval']} of {r['named']}"
                     if "truth_in_interval" in r else "")
                  + (f"; the .dyr H inside the update's interval: {r['dyr_in_interval']} of {r['named']}"
                     if "dyr_in_interval" in r else ""),
                  f"- delay from a frame's timestamp to its estimate: median {_f(r['delay_s']['median'])} s, "
                  f"99 % {_f(r['delay_s']['p99'])} s",
                  f"- replay (`jaxdse run replay.toml`): {r['replay']['updates']} updates, same timestamps: "
                  f"{r['replay']['same_timestamps']}, largest relative difference of H "
                  f"{r['replay']['largest_relative_difference_H']:.1e}, of its interval "
                  f"{r['replay']['largest_relative_difference_interval']:.1e}"]
        w = r.get("whole_recording")
        if w:
            off = [f"{k} {v['H_s']:.3f} s (batch {v['batch_ci95'][0]:.3f}-{v['batch_ci95'][1]:.3f})"
                   for k, v in w["per_unit"].items() if not v["within"]]
            lines.append(f"- the same stream replayed with a {w['window_s']:g} s window (the whole recording, as "
                         f"the batch run): the last update of {w['within_batch_interval']} of the {w['units']} units "
                         f"the live run identified lies within the batch interval"
                         + (f"; not: {', '.join(off)}" if off else ""))
        lines.append("")
    a = doc.get("ambient")
    if a:
        lines += ["## ANDES npcc ambient, 10 units, 30 frames/s at 10x, window 120 s", "",
                  f"- updates: {a['updates']} ({', '.join(f'{k} {v}' for k, v in a['verdicts'].items())}); "
                  f"of those naming an H, ANDES's H inside the interval: {a['named_truth_in_interval']} of {a['named']}",
                  ""]
    f = doc.get("faults")
    if f:
        lines += ["## Faults (OSL case 1 at 2x, window 20 s)", "",
                  "| run | fault | what | H median before [s] | after [s] | first estimate after [s] |",
                  "|---|---|---|---|---|---|"]
        for run in f["runs"]:
            for row in run["faults"]:
                lines.append(f"| {run['run']} | `{row['fault']}` | {row['what']} | {_f(row['H_median_before_s'])} | "
                             f"{_f(row['H_median_after_s'])} | {_f(row['first_estimate_after_fault_s'], '.1f')} |")
        lines += ["", "| run | updates | verdicts | identified, interval outside the batch interval | identified "
                  "more than 10 % off the .dyr H | counts | decoder | unusable / stale samples | restarts |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for run in f["runs"]:
            off = run["identified_more_than_10_percent_off_dyr"]
            lines.append(f"| {run['run']} | {run['updates']} | {run['verdicts']} | "
                         f"{run['identified_outside_batch_interval']} | {len(off)}"
                         + "".join(f" ({o['unit']} at {o['t_s']:.0f} s: {o['H_s']:.3f} s, .dyr {o['H_dyr_s']:.3f} s)"
                                   for o in off[:2])
                         + f" | {run['counts']} | {run.get('decoder', run.get('decoder_rejected'))} | {run['unusable_samples']} / "
                         f"{run.get('stale_samples', 0)} | "
                         f"{run['restarts']} |")
        lines.append("")
    sp = doc.get("speed")
    if sp:
        lines += ["## The delay at `--speed` 1 and 5 (README's example, window 60 s)", "",
                  "| speed | monitor [s] | updates | delay median / 99 % [s of stream time] | wall delay median [s] |",
                  "|---|---|---|---|---|"]
        for r in sp["rows"]:
            d, w = r["delay_s"] or {}, r["wall_delay_s"] or {}
            lines.append(f"| {r['speed']} | {r['monitor_duration_s']:g} | {r['updates']} | {_f(d.get('median'), '.3f')} / "
                         f"{_f(d.get('p99'), '.3f')} | {_f(w.get('median'), '.3f')} |")
        lines += ["", f"Difference between the speeds: median {sp['difference_s']['median']:.3f} s, 99 % "
                  f"{sp['difference_s']['p99']:.3f} s; every delay positive: {sp['positive']}.", ""]
    for key, title in (("capacity", "Latency and capacity"),
                       ("interconnection", "A whole interconnection (`--only interconnection`)")):
        c = doc.get(key)
        if c:
            lines += _capacity_table(c, title)
    return "\n".join(lines)


def _capacity_table(c, title) -> list[str]:
    lines = [f"## {title} (real time, window 30 s)", "",
             "| frames/s | units | streams | run [s] | frame period [ms] | processing per frame median / 99 % [ms] | "
             "CPU per frame median / 99 % [ms] | busy fraction | delay median / 99 % / max [s] | "
             "area estimate delay median / 99 % [s] | peak memory [MiB] | keeps up |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in c["rows"]:
        p, d = r["processing_ms_per_frame"] or {}, r["delay_s"] or {}
        cpu, e = r.get("processing_cpu_ms_per_frame") or {}, r.get("inertia_delay_s") or {}
        lines.append(f"| {r['frames_per_s']} | {r['units']} | {r.get('streams', 1)} | {r.get('seconds', c['seconds']):g} | "
                     f"{r['frame_period_ms']:.1f} | "
                     f"{_f(p.get('median'))} / {_f(p.get('p99'))} | {_f(cpu.get('median'))} / {_f(cpu.get('p99'))} | "
                     f"{_f(r['busy_fraction'], '.2f')} | "
                     f"{_f(d.get('median'))} / {_f(d.get('p99'))} / {_f(d.get('max'))} | "
                     f"{_f(e.get('median'))} / {_f(e.get('p99'))} | {_f(r.get('peak_rss_mib'), '.0f')} | "
                     f"{r['keeps_up']} |")
    lines.append("")
    for r in c["rows"]:
        if "backlog_worked_off_after_s" in r:
            st = r.get("steady")
            lines.append(f"{r['units']} units: the start's backlog (every unit's first chunk in the same second) "
                         + ("was not worked off in the run" if st is None else
                            f"was worked off {r['backlog_worked_off_after_s']:g} s after the first update "
                            f"({r['updates_in_start']} updates before it); from then on, {st['updates']} updates "
                            f"over {st['stream_s']:g} s: delay median {_f(st['delay_s']['median'])} s, 99 % "
                            f"{_f(st['delay_s']['p99'])} s, max {_f(st['delay_s']['max'])} s")
                         + _area_delays(r.get("steady_inertia_delay_s"))
                         + ".")
            lines.append("")
    return lines


def _area_delays(d: dict | None) -> str:
    if not d:
        return ""
    return (f"; the area estimates {_f(d['median'])} s median, 99 % {_f(d['p99'])} s, max {_f(d['max'])} s "
            "after their time")


if __name__ == "__main__":
    main()
