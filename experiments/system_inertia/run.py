"""System inertia per area on the ANDES bench and OSL case 1 (`jaxdse fleet` with `[inertia]`).

    python experiments/system_inertia/run.py bench [CASE ...]   # ANDES ieee14, npcc: every event recording
    python experiments/system_inertia/run.py bench-ambient [CASE ...]   # their ambient recordings
    python experiments/system_inertia/run.py osl     # NASPI OSL contest case 1 (WECC 240)
    python experiments/system_inertia/run.py osl-live   # the same, from its stream, every second

bench: each fleet file of experiments/andes_bench (line trip, load step, generator trip) run
with an `[inertia]` section (a status CSV takes the tripped generator offline at 10 s). The
truth is sum H_true S over the online units: truth.json's H and MBASE for the recorded machines,
the .dyr H for the others (the .dyr is ANDES's own case, written from it: the same numbers).
Then the same units with a third of the measured ones treated as unmeasured (their .dyr H,
+-model_uncertainty), through `jd.area_inertia`: E's interval and the measured share against
the true share. Writes results.json (key "bench") and bench.png here.

osl: experiments/naspi_osl_case1/fleet.toml with `[inertia]`: per area and system E with its
interval, measured share and commitment figure, one value per recording (the fleet's
whole-recording estimates). Writes results.json (key "osl") and osl.png here.

osl-live: the same recording served as a C37.118 stream by `jaxdse pmu-sim` (real time, 90 s)
and read by `jaxdse monitor` with an empty `[inertia]` section and `window_s` 30: every area's
and the system's E each second of stream time, beside the commitment figure. Writes
results.json (key "osl_live") and osl_live.png here.
"""

import json
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent
BENCH = HERE.parent / "andes_bench"
OSL = HERE.parent / "naspi_osl_case1"
CASES = ("ieee14", "npcc")
EVENTS = {"line_trip": "", "load_step": "_load_step", "gen_trip": "_gen_trip", "ambient": ""}
"""Event -> the fleet file's suffix; ambient: the line trip's file on ambient.csv.gz (600 s at
30 frames/s, load noise only), run only when asked (``bench-ambient``)."""
TRIPPED = {"ieee14": "6_1", "npcc": "98_1"}   # the generator the gen_trip recordings trip at 10 s
UNMEASURED_EVERY = 3   # the measured units at positions 1, 4, 7, ... (sorted by name) become unmeasured


def fleet_with_inertia(src: Path, tmp: Path, inertia: str) -> Path:
    """The fleet file ``src`` with its relative paths made absolute and an ``[inertia]`` section."""
    text = src.read_text()
    text = re.sub(r'"(\.\./|data/)', lambda m: '"' + str(src.parent.resolve()) + "/" + m.group(1), text)
    out = tmp / src.name
    out.write_text(text + "\n[inertia]\n" + inertia)
    return out


def merge_results(key: str, update) -> dict:
    """results.json's ``key`` replaced by ``update(old value or None)`` under a lock (parts run apart)."""
    import fcntl

    path = HERE / "results.json"
    with open(HERE / ".results.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        res = json.loads(path.read_text()) if path.exists() else {}
        res[key] = update(res.get(key))
        path.write_text(json.dumps(res, indent=2) + "\n")
    return res[key]


def true_h(case: str) -> dict:
    truth = json.loads((BENCH / "data" / case / "truth.json").read_text())
    out = {}
    for m in truth["machines"]:      # by the case's unit name "BUS_ID" and by the plant's tag
        out[f"{m['bus']}_{m['id']}"] = out[m["tag"]] = (m["H_s_mbase"], m["mbase_mva"])
    return out


def bench_run(case: str, event: str, suffix: str, tmp: Path) -> dict:
    inertia = ""
    if event == "gen_trip":
        status = tmp / f"{case}_status.csv"
        status.write_text(f"time_s,unit,online\n10.0,{TRIPPED[case]},0\n")
        inertia = f'status = "{status}"\n'
    toml = fleet_with_inertia(BENCH / f"fleet_{case}{suffix}.toml", tmp, inertia)
    if event == "ambient":
        toml.write_text(toml.read_text().replace("line_trip.csv.gz", "ambient.csv.gz"))
    out = tmp / f"{case}_{event}"
    t0 = time.perf_counter()
    plants = {u["name"]: u for u in jd.fleet(toml, out, stream=sys.stderr)}
    wall = time.perf_counter() - t0
    doc = json.loads((out / "fleet.json").read_text())["inertia"]
    truth = true_h(case)
    units = doc["units"]
    sys_row = next(a for a in doc["areas"] if a["area"] == "system")
    # truth: recorded machines from truth.json, the case's other units at their .dyr H (ANDES's own numbers)
    e_true = 0.0
    e_true_measured = 0.0
    e_measured = 0.0
    per_unit = []
    for u in units:
        if not u["online"]:
            continue
        name = u["name"]
        if name in truth:
            h, s = truth[name]
        else:
            h, s = u["h_s"], (u["e_commitment_MWs"] / u["h_s"] if u["h_s"] else 0.0)
        e_true += h * s
        if u["source"] == "measured":
            e_true_measured += h * s
            e_measured += u["e_MWs"]
            per_unit.append({"unit": name, "H_s": u["h_s"], "H_true_s": h, "S_MVA": s,
                             "error_percent": 100 * (u["h_s"] / h - 1),
                             "H_ci95": [u["e_lo_MWs"] / s, u["e_hi_MWs"] / s],
                             "covers": u["e_lo_MWs"] <= h * s <= u["e_hi_MWs"]})
    lo, hi = sys_row["E_ci95"]
    row = {"case": case, "event": event, "wall_s": wall,
           "E_MWs": sys_row["E_MWs"], "E_ci95": [lo, hi], "E_true_MWs": e_true,
           "E_error_percent": 100 * (sys_row["E_MWs"] / e_true - 1), "covers": lo <= e_true <= hi,
           "within_2pct": abs(sys_row["E_MWs"] / e_true - 1) <= 0.02,
           "E_measured_MWs": e_measured, "E_true_measured_MWs": e_true_measured,
           "E_measured_error_percent": 100 * (e_measured / e_true_measured - 1),
           "measured_share": sys_row["measured_share"], "E_commitment_MWs": sys_row["E_commitment_MWs"],
           "units_online": sys_row["units_online"], "units_measured": sys_row["units_measured"],
           "units": per_unit}
    row["third_unmeasured"] = third_unmeasured(units, plants, truth, doc["settings"], e_true)
    return row


def third_unmeasured(units: list, plants: dict, truth: dict, settings: dict, e_true: float) -> dict:
    """The same units, a third of the measured ones unmeasured (their .dyr H as model), through jd.area_inertia."""
    measured = sorted(u["name"] for u in units if u["source"] == "measured")
    dropped = set(measured[1::UNMEASURED_EVERY])
    rebuilt = []
    for u in units:
        s = u["e_commitment_MWs"] / u["h_s"] if (u["h_s"] and u["e_commitment_MWs"]) else 0.0
        if u["source"] == "measured":
            p = plants[u["name"]]
            s = truth[u["name"]][1] if u["name"] in truth else s
            h_model = p["H_reference_s"]
            keep = u["name"] not in dropped
            rebuilt.append(jd.InertiaUnit(name=u["name"], area=u["area"], s_mva=s, online=u["online"],
                                          h_model_s=h_model, h_s=p["H_s"] if keep else None,
                                          h_ci95=tuple(p["H_ci95"]) if keep else None, age_s=0.0 if keep else None,
                                          measured=keep))
        else:
            rebuilt.append(jd.InertiaUnit(name=u["name"], area=u["area"], s_mva=s, online=u["online"],
                                          kind=u["kind"], h_model_s=u["h_s"]))
    st = jd.InertiaSettings(model_uncertainty=settings["model_uncertainty"], f0_hz=settings["f0_hz"],
                            measured_errors=settings["measured_errors"])
    areas, _ = jd.area_inertia(rebuilt, st)
    row = areas[-1]
    share_true = sum(truth[n][0] * truth[n][1] for n in measured if n not in dropped) / e_true
    lo, hi = row.E_ci95
    return {"unmeasured": sorted(dropped), "E_MWs": row.E_MWs, "E_ci95": [lo, hi], "E_true_MWs": e_true,
            "E_error_percent": 100 * (row.E_MWs / e_true - 1), "covers": lo <= e_true <= hi,
            "measured_share": row.measured_share, "measured_share_true": share_true,
            "units_measured": row.units_measured}


def bench(cases=CASES, events=("line_trip", "load_step", "gen_trip")):
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            for event in events:
                suffix = EVENTS[event]
                rows.append(bench_run(case, event, suffix, Path(tmp)))
                r = rows[-1]
                print(f"[inertia] {case} {event}: E {r['E_MWs']:.1f} true {r['E_true_MWs']:.1f} "
                      f"({r['E_error_percent']:+.2f} %) covers {r['covers']}", file=sys.stderr)

    def update(old):
        done = {(r["case"], r["event"]) for r in rows}
        keep = [r for r in (old or {}).get("rows", []) if (r["case"], r["event"]) not in done]
        allrows = sorted(keep + rows, key=lambda r: (CASES.index(r["case"]), list(EVENTS).index(r["event"])))
        return {"command": "python experiments/system_inertia/run.py bench [CASE ...]",
                "recordings": len(allrows), "within_2pct": sum(r["within_2pct"] for r in allrows),
                "covers": sum(r["covers"] for r in allrows),
                "third_unmeasured_covers": sum(r["third_unmeasured"]["covers"] for r in allrows),
                "max_abs_share_error": max(abs(r["third_unmeasured"]["measured_share"]
                                               - r["third_unmeasured"]["measured_share_true"]) for r in allrows),
                "rows": allrows}

    res = merge_results("bench", update)
    bench_figure(res["rows"], HERE / "bench.png")


def bench_figure(rows: list, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.2))
    labels = []
    for i, r in enumerate(rows):
        for k, (key, color) in enumerate((("all", "C0"), ("third", "C1"))):
            v = r if key == "all" else r["third_unmeasured"]
            e, (lo, hi) = v["E_MWs"] / v["E_true_MWs"], v["E_ci95"]
            x = i + (k - 0.5) * 0.3
            ax.errorbar([x], [100 * (e - 1)], yerr=[[100 * (e - lo / v["E_true_MWs"])], [100 * (hi / v["E_true_MWs"] - e)]],
                        fmt="o", color=color, capsize=3, label=None if i else
                        ("every recorded unit measured" if key == "all" else "a third of them unmeasured (.dyr H)"))
        labels.append(f"{r['case']}\n{r['event']}")
    ax.axhline(0, color="k", lw=0.8)
    ax.axhspan(-2, 2, color="0.9", zorder=0, label="+-2 %")
    ax.set_xticks(range(len(rows)), labels, fontsize=8)
    ax.set_ylabel("system E - true E [% of true E]\n(95 % interval)")
    ax.set_title("ANDES bench: system stored kinetic energy from the units' own estimates")
    ax.legend(fontsize=8, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def osl():
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        toml = fleet_with_inertia(OSL / "fleet.toml", Path(tmp), "")
        out = Path(tmp) / "osl"
        plants = list(jd.fleet(toml, out, stream=sys.stderr))
        doc = json.loads((out / "fleet.json").read_text())["inertia"]
    areas = doc["areas"]
    res = {"command": "python experiments/system_inertia/run.py osl", "wall_s": time.perf_counter() - t0,
           "time_resolution": doc["time_resolution"], "plants": len(plants), "settings": doc["settings"],
           "areas": areas, "notes": doc["notes"],
           "sources": {s: sum(u["source"] == s for u in doc["units"]) for s in sorted({u["source"] for u in doc["units"]})}}
    merge_results("osl", lambda old: res)
    osl_figure(areas, HERE / "osl.png")


def osl_figure(areas: list, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(9, 4.5))
    x = np.arange(len(areas))
    e = np.array([a["E_MWs"] for a in areas]) / 1e3
    em = np.array([a["E_measured_MWs"] for a in areas]) / 1e3
    lo = np.array([a["E_ci95"][0] for a in areas]) / 1e3
    hi = np.array([a["E_ci95"][1] for a in areas]) / 1e3
    com = np.array([a["E_commitment_MWs"] for a in areas]) / 1e3
    ax.bar(x, em, color="C0", label="measured units (identified H)")
    ax.bar(x, e - em, bottom=em, color="C0", alpha=0.35, label="other units (.dyr H)")
    ax.errorbar(x, e, yerr=[e - lo, hi - e], fmt="none", color="k", capsize=4, label="E, 95 % interval")
    ax.scatter(x, com, marker="_", s=600, color="C3", zorder=3, label="commitment figure (.dyr H)")
    for i, a in enumerate(areas):
        ax.annotate(f"{e[i]:.0f} GW s\n{100 * a['measured_share']:.0f} % measured", (x[i], hi[i]),
                    textcoords="offset points", xytext=(0, 4), ha="center", fontsize=7)
    ax.set_xticks(x, [a["area"] for a in areas])
    ax.set_ylabel("stored kinetic energy E [GW s]")
    ax.set_title("OSL case 1 (WECC 240): E per area and system, one value for the recording")
    ax.legend(fontsize=8, loc="upper left")
    ax.set_ylim(0, 1.15 * hi.max())
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


JAXDSE = str(Path(sys.executable).parent / "jaxdse") if (Path(sys.executable).parent / "jaxdse").exists() \
    else (shutil.which("jaxdse") or "jaxdse")
"""The console script, beside this Python where it is installed there."""
LIVE_WINDOW_S = 30.0


def osl_live():
    """OSL case 1 through pmu-sim and the monitor (console scripts), E per second."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        fleet = fleet_with_inertia(OSL / "fleet.toml", tmp, "floor_MWs = 700000.0\nlargest_loss_mw = 2000.0\n")
        sim = subprocess.Popen([JAXDSE, "pmu-sim", str(fleet), "--port", "0"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
        try:
            m = re.search(r":(\d+) ", sim.stdout.readline())
            if not m:
                raise RuntimeError(f"pmu-sim did not start: {sim.stderr.read()}")
            cfg = tmp / "monitor.toml"
            cfg.write_text(f'fleet = "{fleet}"\nupdate_s = 1.0\nwindow_s = {LIVE_WINDOW_S}\n'
                           f'[stream]\nport = {m.group(1)}\ntimeout_s = 3.0\nfrequency = "angle"\n')
            out = tmp / "live"
            subprocess.run([JAXDSE, "monitor", str(cfg), "--out", str(out), "--duration", "100"], check=True,
                           stdout=subprocess.DEVNULL)
        finally:
            sim.terminate()
            sim.wait(timeout=30)
        lines = [json.loads(x) for x in (out / "updates.jsonl").read_text().splitlines()]
        summary = json.loads((out / "monitor.json").read_text())
        if len(sys.argv) > 2:   # keep the monitor's lines for a closer look
            shutil.copy(out / "updates.jsonl", sys.argv[2])
    rows = [x for x in lines if "E_MWs" in x]
    t_start = min(x["t"] for x in rows)
    for x in rows:
        x["t"] = round(x["t"] - t_start, 3)   # stream seconds from the first line
    areas = sorted({x["area"] for x in rows}, key=lambda a: (a == "system", a))
    per = {a: [x for x in rows if x["area"] == a] for a in areas}
    res = {"command": "python experiments/system_inertia/run.py osl-live", "wall_s": time.perf_counter() - t0,
           "window_s": LIVE_WINDOW_S, "lines": len(rows), "areas": areas,
           "first_t_s": min(x["t"] for x in rows), "last_t_s": max(x["t"] for x in rows),
           "series": {a: {"t_s": [x["t"] for x in v], "E_MWs": [round(x["E_MWs"], 1) for x in v],
                          "E_ci95": [[round(y, 1) for y in x["E_ci95"]] for x in v],
                          "measured_share": [round(x["measured_share"], 4) for x in v],
                          "units_measured": [x["units_measured"] for x in v]} for a, v in per.items()},
           "spacing_s": float(np.median(np.diff(sorted({x["t"] for x in rows})))),
           "inertia_delay_s": summary.get("inertia_delay_s"),
           "per_area": {a: {"updates": len(v), "E_MWs_median": float(np.median([x["E_MWs"] for x in v])),
                            "E_MWs_min": float(min(x["E_MWs"] for x in v)),
                            "E_MWs_max": float(max(x["E_MWs"] for x in v)),
                            "E_commitment_MWs": float(np.median([x["E_commitment_MWs"] for x in v])),
                            "measured_share_median": float(np.median([x["measured_share"] for x in v])),
                            "ci95_width_percent_median": float(np.median(
                                [100 * (x["E_ci95"][1] - x["E_ci95"][0]) / x["E_MWs"] for x in v])),
                            "units_online": int(np.median([x["units_online"] for x in v])),
                            "units_measured_median": int(np.median([x["units_measured"] for x in v])),
                            "rocof_hz_per_s_median": (None if v[0].get("rocof_hz_per_s") is None else
                                                      float(np.median([x["rocof_hz_per_s"] for x in v])))}
                        for a, v in per.items()}}
    merge_results("osl_live", lambda old: res)
    osl_live_figure(per, 700000.0, HERE / "osl_live.png")


def osl_live_figure(per: dict, floor: float, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    areas = list(per)
    fig, axes = plt.subplots(len(areas), 1, figsize=(9, 1.9 * len(areas) + 0.6), sharex=True, squeeze=False)
    for ax, a in zip(axes[:, 0], areas):
        v = per[a]
        t = np.array([x["t"] for x in v])
        e = np.array([x["E_MWs"] for x in v]) / 1e3
        lo = np.array([x["E_ci95"][0] for x in v]) / 1e3
        hi = np.array([x["E_ci95"][1] for x in v]) / 1e3
        com = np.array([x["E_commitment_MWs"] for x in v]) / 1e3
        ax.fill_between(t, lo, hi, color="C0", alpha=0.25, step="post", label="95 % interval")
        ax.step(t, e, where="post", color="C0", label="E (measured units: identified H)")
        ax.step(t, com, where="post", color="C3", ls="--", label="commitment figure (.dyr H)")
        if a == "system":
            floor_line = ax.axhline(floor / 1e3, color="k", ls=":",
                                    label=f"alarm floor {floor / 1e3:.0f} GW s")
            ax.legend(handles=[floor_line], fontsize=7, loc="center right")
        share = np.median([x["measured_share"] for x in v])
        ax.set_ylabel(f"{a}\nE [GW s]")
        ax.set_title(f"{a}: {int(np.median([x['units_online'] for x in v]))} units online, "
                     f"{100 * share:.0f} % of E measured", fontsize=8, loc="left")
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=7, loc="lower right", ncol=2)
    axes[-1, 0].set_xlabel("stream time from the first line [s] (measured units count once their 30 s window is full)")
    fig.suptitle("OSL case 1 (WECC 240) from its stream: stored kinetic energy per area, each second", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "osl":
        osl()
    elif len(sys.argv) > 1 and sys.argv[1] == "osl-live":
        osl_live()
    elif len(sys.argv) > 1 and sys.argv[1] == "bench-ambient":
        bench(tuple(sys.argv[2:]) or CASES, ("ambient",))
    else:
        bench(tuple(sys.argv[2:]) or CASES)
