"""Every generator plant of the 2021 IEEE-NASPI oscillation contest, case 1 (simulated WECC 240-bus).

    python experiments/naspi_osl_case1/run.py

Each 20 kV bus with a step-up branch is one aggregated plant: its bus voltage and branch
current are the terminal phasors (30 frames/s, 90 s, no frequency channel). Plant data are
the WECC 240-bus PSS/E files in ../shared/data/wecc240 (the contest changed dispatch and
topology, so they are an approximate reference). The estimated H is compared with the
aggregate of the .dyr GENROU inertias on the summed machine base. Writes results.md/json here.
"""

import json
import re
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent
SHARED = HERE.parents[2] / "shared" / "data"
CASE = SHARED / "naspi_osl_2021" / "case1"
WECC = SHARED / "wecc240"


def raw_generators(path):
    """PSS/E v32 .raw generator records: (bus, id) -> (PG MW, MBASE MVA, in service)."""
    lines = path.read_text(errors="replace").splitlines()
    start = next(k for k, ln in enumerate(lines) if "Begin Generator data" in ln) + 1
    gens = {}
    for ln in lines[start:]:
        if ln.strip().startswith("0 /") or ln.strip() == "0":
            break
        f = [x.strip().strip("'").strip() for x in ln.split(",")]
        gens[(int(f[0]), f[1])] = (float(f[2]), float(f[8]), int(f[14]) == 1)
    return gens


def dyr_records(path):
    """PSS/E .dyr records: (bus, model, id) -> list of constants."""
    recs = {}
    for rec in path.read_text(errors="replace").split("/"):
        tok = rec.split()
        if len(tok) < 3:
            continue
        m = re.match(r"'(\w+)'", tok[1])
        if not m:
            continue
        try:
            recs[(int(tok[0]), m.group(1), tok[2].strip("'"))] = [float(x) for x in tok[3:]]
        except ValueError:  # models with text constants (not used here)
            continue
    return recs


def plants():
    """The 20 kV plants: bus, name, branch column, direction, units and their .dyr data."""
    header = (CASE / "LinCurMag.txt").read_text().splitlines()[0]
    branches = [b.strip() for b in re.findall(r"'([^']*)'", header)[1:]]
    bus_header = [b.strip() for b in
                  re.findall(r"'([^']*)'", (CASE / "BusVolMag.txt").read_text().splitlines()[0])[1:]]
    gens, dyr = raw_generators(next(WECC.glob("*.raw"))), dyr_records(next(WECC.glob("*.dyr")))
    out = []
    for br in branches:
        parts = br.split("|")
        ends = [(int(parts[0]), parts[1]), (int(parts[2]), parts[3])]
        gen_end = [k for k, (_, name) in enumerate(ends) if name.strip().endswith(" 20.0")]
        if len(gen_end) != 1:
            continue
        bus, name = ends[gen_end[0]]
        bus_col = next((c for c in bus_header if c.startswith(f"{bus}|")), None)
        if bus_col is None:
            print(f"[naspi] bus {bus} {name.strip()} has no voltage channel: skipped", file=sys.stderr)
            continue
        units = []
        for (b, uid), (pg, mbase, on) in gens.items():
            g = dyr.get((b, "GENROU", uid))
            if b != bus or not on or g is None:
                continue
            gov = next(((m, v) for (bb, m, ii), v in dyr.items()
                        if bb == bus and ii == uid and m in ("TGOV1", "GAST", "HYGOV")), (None, None))
            units.append({"id": uid, "pg_mw": pg, "mbase_mva": mbase, "genrou": g, "governor": gov})
        others = [uid for (b, uid), (pg, _, on) in gens.items()
                  if b == bus and on and (b, "GENROU", uid) not in dyr]
        if units:
            out.append({"bus": bus, "name": name.strip(), "bus_column": bus_col, "branch": br,
                        "direction": "out_of_plant" if gen_end[0] == 0 else "into_plant",
                        "units": units, "non_synchronous_units": others})
    return out


def plant_config(p) -> dict:
    """A jaxdse [[generator]] table: the units aggregated on their summed base."""
    s = sum(u["mbase_mva"] for u in p["units"])
    w = [u["mbase_mva"] / s for u in p["units"]]
    g = [u["genrou"] for u in p["units"]]  # T'do T''do T'qo T''qo H D Xd Xq X'd X'q X''d Xl ...

    def avg(k):
        return float(sum(wi * gi[k] for wi, gi in zip(w, g)))

    tgov = next((u["governor"][1] for u in p["units"] if u["governor"][0] == "TGOV1"), None)
    governor = ({"r_pu": tgov[0], "t1_s": tgov[1], "v_max_pu": tgov[2], "v_min_pu": tgov[3],
                 "t2_s": tgov[4], "t3_s": tgov[5], "dt_pu": tgov[6]} if tgov else {})
    return {
        "name": f"{p['bus']}_{p['name'].split()[0].lower()}",
        "role": "estimate",
        "h_reference_s": avg(4),
        "machine": {"s_rated_mva": s, "xd_pu": avg(6), "xq_pu": avg(7), "xd1_pu": avg(8),
                    "td01_s": avg(0), "rs_pu": 0.0, "f_nominal_hz": 60.0, "v_rated_kv": 20.0},
        "governor": governor,
        "measurement": {
            "current_direction": p["direction"],
            "columns": {"time": "BusVolMag/Time", "v_mag": f"BusVolMag/{p['bus_column']}",
                        "v_ang": f"BusVolAng/{p['bus_column']}", "i_mag": f"LinCurMag/{p['branch']}",
                        "i_ang": f"LinCurAng/{p['branch']}"}},
    }


def main():
    if not CASE.exists():
        sys.exit(f"the shared NASPI data are not at {CASE}")
    t0 = time.perf_counter()
    ps = plants()
    doc = {
        "measurement": {"file": [str(CASE / f) for f in ("BusVolMag.txt", "BusVolAng.txt",
                                                         "LinCurMag.txt", "LinCurAng.txt")],
                        "format": "csv", "delimiter": "whitespace", "quotechar": "'",
                        "location": "terminal", "voltage_unit": "pu", "current_unit": "pu",
                        "angle_unit": "deg", "s_base_mva": 100.0, "min_segment_s": 30.0},
        "generator": [plant_config(p) for p in ps],
    }
    cfg = jd.parse_config(doc, HERE / "generated.toml")
    run = jax.jit(jd.estimate)
    rows = []
    for p, g in zip(ps, cfg.generators):
        try:
            segments, quality = jd.read_measurement(g.measurement, float(g.plant.machine.s_rated_mva))
        except jd.InputError as err:
            rows.append({"name": g.name, "error": str(err)})
            print(f"[naspi] {g.name}: {err}", file=sys.stderr)
            continue
        rec = segments[0][1]
        est = run(rec, g.plant, cfg.observer, cfg.settings)
        e = jd.summary_entry(g.name, est, h_reference_s=g.h_reference_s)
        e.update({"bus": p["bus"], "s_mva": float(g.plant.machine.s_rated_mva),
                  "units": [u["id"] for u in p["units"]],
                  "governor": sorted({u["governor"][0] or "none" for u in p["units"]}),
                  "non_synchronous_units": p["non_synchronous_units"],
                  "p_pu": quality["median_p_pu_machine"], "segments": len(segments),
                  "bridged_gaps": len(quality["bridged_gaps"]),
                  "H_error_percent": (100 * (e["H_s"] - g.h_reference_s) / g.h_reference_s
                                      if e["H_s"] is not None else None)})
        rows.append(e)
        print(f"[naspi] {g.name}: H {e['H_s']:.2f} s vs .dyr {g.h_reference_s:.2f} s", file=sys.stderr)
    (HERE / "results.json").write_text(json.dumps({"plants": rows}, indent=2) + "\n")
    (HERE / "results.md").write_text(report(rows, time.perf_counter() - t0))
    print(f"[naspi] wrote {HERE}/results.md in {time.perf_counter() - t0:.1f} s", file=sys.stderr)


def report(rows, wall_s):
    def f(x, fmt=".2f"):
        return "n/a" if x is None else format(x, fmt)

    ok = [r for r in rows if "error" not in r and r["H_s"] is not None]
    errs = np.array([abs(r["H_error_percent"]) for r in ok])
    lines = [
        "# NASPI 2021 oscillation contest, case 1: H of every plant vs the WECC 240-bus .dyr",
        "",
        f"Generated by `python experiments/naspi_osl_case1/run.py` ({wall_s:.0f} s, 2-core CPU).",
        "",
        "Data: 2021 IEEE-NASPI Oscillation Source Location contest, case 1 (Maslennikov & Wang, "
        "IEEE PES GM 2022), WECC 240-bus model simulated in TSAT, 90 s at 30 frames/s with a "
        "forced oscillation and random load fluctuation. Reference H: the GENROU inertias of the "
        "in-service synchronous units on each 20 kV bus in `240busWECC_2018_PSS.dyr`/`.raw` "
        "(NREL-Sienna/PowerSimulationsDynamics.jl test data), aggregated on the summed machine "
        "base. The contest changed dispatch and topology and added stabilisers, so the "
        "reference is approximate, not exact truth.",
        "",
        "Set-up: PMU at the machine terminal (location = terminal), frequency derived from the "
        "voltage angle, reactances and T'd0 from GENROU (base-weighted), TGOV1 data where the "
        "plant has TGOV1, jaxdse's default TGOV1 otherwise (GAST and HYGOV are not modelled), "
        "observer at the paper's Table I values, no tuning.",
        "",
        "| plant | S [MVA] | P [pu] | governor(s) | other units | H .dyr [s] | H est [s] | error [%] | "
        "excitation ∫γKΔ² | converged | sMAPE I_t [%] | P_t [%] | Q_t [%] |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['name']} | | | | | | input error: {r['error']} | | | | | | |")
            continue
        s = r["smape_percent"]
        lines.append(
            f"| {r['name']} | {r['s_mva']:.0f} | {f(r['p_pu'], '.3f')} | {'/'.join(r['governor'])} | "
            f"{','.join(r['non_synchronous_units']) or '-'} | {r['H_reference_s']:.2f} | {f(r['H_s'])} | "
            f"{f(r['H_error_percent'], '.1f')} | {f(r['flags']['log_contraction_a2'], '.1f')} | "
            f"{'yes' if r['converged'] else 'no: ' + r.get('not_converged_reason', '')} | "
            f"{f(s['I_t'])} | {f(s['P_t'])} | {f(s['Q_t'])} |")
    if errs.size:
        lines += ["", f"Over {errs.size} plants: median |H error| {np.median(errs):.1f} %, "
                  f"{int(np.sum(errs < 10))} within 10 %, {int(np.sum(errs < 25))} within 25 %."]
    h0 = 2 * np.pi * 60 / (2 * float(jd.ObserverConfig().a2_init))
    lines += ["", f"The observer starts from a2_init = {float(jd.ObserverConfig().a2_init):g}, i.e. "
              f"H = {h0:.2f} s at 60 Hz. The parameter error shrinks by exp(-∫γKΔ²): below about "
              "4 (the `excited` threshold) a 90 s recording has not moved the estimate far from "
              "that guess, so such H values are not identified by these data.",
              "", "\"other units\": in-service units on the same bus without a GENROU record "
              "(renewables); their current is in the measured branch current, which biases H.", ""]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
