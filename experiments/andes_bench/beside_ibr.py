"""H of the synchronous machines beside inverter-based plants (issue 44, "machines beside
inverters"): the ANDES bench's ieee14 and its three derived cases whose bus-8 machine is an
inverter-based plant (``generate.py``: ieee14_solar, ieee14_wt3, ieee14_vsg), the same three
events, the four machines of buses 1, 2, 3 and 6 scored as ``run.py`` scores them (its noise,
plant data from truth.json, default configuration).

    python experiments/andes_bench/beside_ibr.py

Writes beside_ibr.json and beside_ibr.md here.
"""

import json
import sys
import time
import zlib
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE))
import run as bench  # noqa: E402  (the bench's plant data, noise and settings)

CASES = {"ieee14": "none (the bench's ieee14: a GENROU at bus 8)",
         "ieee14_solar": "PV plant (REGCA1 + REECA1 + REPCA1) at bus 8",
         "ieee14_wt3": "type-3 wind plant (REGCA1 + REECA1 + REPCA1 + WTDTA1/WTARA1/WTPTA1/WTTQA1) at bus 8",
         "ieee14_vsg": "virtual synchronous generator (REGCV1, H = 4 s) at bus 8"}
EVENTS = ("line_trip", "load_step", "gen_trip")
MACHINES = ("B1_G1", "B2_G1", "B3_G1", "B6_G1")


def main():
    t_start = time.perf_counter()
    units, meta = [], []
    for case in CASES:
        truth = json.loads((bench.DATA / case / "truth.json").read_text())
        f0 = truth["f0_hz"]
        machines = {m["tag"]: m for m in truth["machines"]}
        for ev in EVENTS:
            t, phasors = bench.read_scenario(case, ev)
            for tag in MACHINES:
                if tag not in phasors:   # the tripped unit of gen_trip
                    continue
                v, i, f = phasors[tag]
                rec = bench.noisy(t, v, i, f, seed=zlib.crc32(f"{case}/{ev}/{tag}".encode()))
                units.append(jd.Unit(f"{case}/{ev}/{tag}", rec, bench.plant(machines[tag], f0)))
                meta.append((case, ev, tag, machines[tag]["H_s_mbase"]))
    assessed = jd.assess_units(units, jd.ObserverConfig(), bench.SETTINGS,
                               progress=lambda line: print(f"[beside] {line}", file=sys.stderr, flush=True))
    rows = []
    for (case, ev, tag, h_true), a in zip(meta, assessed):
        ident = a.identified
        word, reasons = jd.describe(a.verdict)
        lo, hi = (float(x) for x in ident.h_ci95)
        rows.append({"case": case, "event": ev, "machine": tag, "H_true_s": h_true, "H_s": float(ident.h_s),
                     "H_ci95": [lo, hi], "H_error_percent": 100 * (float(ident.h_s) / h_true - 1),
                     "covers": bool(lo <= h_true <= hi), "verdict": word, "reasons": reasons})
    res = {"noise": {"tve_percent": bench.TVE_PERCENT, "f_noise_hz": bench.F_NOISE_HZ},
           "cases": {c: {"inverter_plant": d, **summary([r for r in rows if r["case"] == c])}
                     for c, d in CASES.items()},
           "with_inverters": summary([r for r in rows if r["case"] != "ieee14"]),
           "units": rows, "wall_s": time.perf_counter() - t_start}
    (HERE / "beside_ibr.json").write_text(json.dumps(res, indent=2) + "\n")
    (HERE / "beside_ibr.md").write_text(report(res))
    print(f"[beside] wrote {HERE}/beside_ibr.md in {res['wall_s']:.0f} s", file=sys.stderr)


def summary(rows) -> dict:
    err = np.array([abs(r["H_error_percent"]) for r in rows])
    ident = [r for r in rows if r["verdict"] == "identified"]
    line = [abs(r["H_error_percent"]) for r in rows if r["event"] == "line_trip"]
    return {"recordings": len(rows), "within_2pct": float(np.mean(err <= 2)),
            "within_5pct": float(np.mean(err <= 5)), "line_trip_within_2pct": float(np.mean(np.array(line) <= 2)),
            "identified": len(ident),
            "identified_over_10pct_off": sum(abs(r["H_error_percent"]) > 10 for r in ident),
            "identified_interval_misses": sum(not r["covers"] for r in ident),
            "failed": [f"{r['case']}/{r['event']}/{r['machine']}: {', '.join(r['reasons'])}"
                       for r in rows if r["verdict"] == "failed"],
            "interval_covers": float(np.mean([r["covers"] for r in rows]))}


def report(res) -> str:
    s = res["with_inverters"]
    lines = [
        "# H of the machines beside inverter-based plants (ANDES bench, ieee14)",
        "",
        f"`python experiments/andes_bench/beside_ibr.py` ({res['wall_s']:.0f} s). The bench's ieee14 and three "
        "derived cases whose bus-8 machine is an inverter-based plant (`generate.py`), the line trip (1-2), the "
        f"load step and the generator trip; the machines of buses 1, 2, 3 and 6, with {res['noise']['tve_percent']} % "
        "TVE of PMU noise, scored as `run.py` scores them.",
        "",
        f"With inverters: H within 2 % on {100 * s['within_2pct']:.0f} % of {s['recordings']} machine-recordings "
        f"(line trips {100 * s['line_trip_within_2pct']:.0f} %), within 5 % on {100 * s['within_5pct']:.0f} %; "
        f"{s['identified_over_10pct_off']} `identified` more than 10 % off; {s['identified_interval_misses']} "
        "`identified` whose interval misses the truth; "
        f"{len(s['failed'])} `failed`{': ' + '; '.join(s['failed']) if s['failed'] else ''}.",
        "",
        "| case | inverter-based plant | recordings | within 2 % | line trips within 2 % | within 5 % | "
        "identified | identified > 10 % off | identified, interval misses |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for c, d in res["cases"].items():
        lines.append(f"| {c} | {d['inverter_plant']} | {d['recordings']} | {100 * d['within_2pct']:.0f} % | "
                     f"{100 * d['line_trip_within_2pct']:.0f} % | {100 * d['within_5pct']:.0f} % | {d['identified']} | "
                     f"{d['identified_over_10pct_off']} | {d['identified_interval_misses']} |")
    lines += ["", "| case | event | machine | H true [s] | H [s] | 95 % interval [s] | error [%] | verdict |",
              "|---|---|---|---|---|---|---|---|"]
    for r in res["units"]:
        lines.append(f"| {r['case']} | {r['event']} | {r['machine']} | {r['H_true_s']:.3f} | {r['H_s']:.3f} | "
                     f"{r['H_ci95'][0]:.3f}-{r['H_ci95'][1]:.3f} | {r['H_error_percent']:+.1f} | {r['verdict']} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
