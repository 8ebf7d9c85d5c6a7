"""ESST4B's outer PI regulator after a deep voltage dip: PSS/E's non-windup limits against ANDES's
tracking anti-windup, from the block diagram.

    python experiments/andes_bench/esst4b_pi.py   # before new_models.py, which reports it

IEEE Std 421.5-2005, 7.4 (type ST4B) and the PSS/E Model Library's ESST4B: the regulator
VR = (KPR + KIR/s)(Vref - VC) has *non-windup* limits [VRMIN, VRMAX]: while VR sits on a limit
and the input pushes it further, the integrator holds (IEEE 421.5 Annex E). ANDES 2.0 builds the
same block as a PI with *tracking* anti-windup (its ESST4B config ``ksr = 2``): the integrator
keeps running on KIR (u - ks (ys - y)), ys the unlimited sum and y the limited output, so that
it winds down towards the limit while the output is held there.

The unit's exciter is driven here by ANDES's own terminal voltage of the recording (``VM``,
``data/<case>/<event>.csv.gz``), through the sensor lag TR, with Vref and the integrator
started at ANDES's steady state; the outer PI is integrated by SciPy (``solve_ivp``, Radau)
both ways and compared with ANDES's recorded VR (``PI1_y`` in ``<event>_controls.csv.gz``).
With the terminal voltage imposed, the integrator has no feedback: the difference left at the
end of the limited stretch stays for the rest of the recording, and so does the EFD (VM = VR
here: KG = 0, KIM = 0) and the reactive power of a playback that follows PSS/E.

Writes esst4b_pi.json here (read by new_models.py). No ANDES import: only its recordings are read.
"""

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

HERE = Path(__file__).parent
DATA = HERE / "data"
T_EVENT_S = 10.0
KS_ANDES = 2.0  # ANDES 2.0 ESST4B config ksr (tracking gain of the outer PI)


def outer_pi(t, vt, p, scheme, vr0, ks=KS_ANDES):
    """VR at the frames t: VC = VT/(1 + s TR), u = Vref - VC (Vref = VT(0): steady state),
    VR = clip(KPR u + x, VRMIN, VRMAX). ``scheme`` "nonwindup": dx/dt = KIR u, held at 0 while
    VR is on a limit and u pushes outward; "tracking": dx/dt = KIR (u - ks (ys - VR))."""
    vref = vt[0]

    def f(tt, z):
        vc, x = z
        v = np.interp(tt, t, vt)
        u = vref - vc
        ys = p["KPR"] * u + x
        y = min(max(ys, p["VRMIN"]), p["VRMAX"])
        if scheme == "tracking":
            dx = p["KIR"] * (u - ks * (ys - y))
        else:
            dx = p["KIR"] * u
            if (ys >= p["VRMAX"] and dx > 0) or (ys <= p["VRMIN"] and dx < 0):
                dx = 0.0
        return [(v - vc) / p["TR"], dx]

    sol = solve_ivp(f, (t[0], t[-1]), [vt[0], vr0], method="Radau", t_eval=t, max_step=1 / 240,
                    rtol=1e-8, atol=1e-10)
    vc, x = sol.y
    return np.clip(p["KPR"] * (vref - vc) + x, p["VRMIN"], p["VRMAX"])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", nargs="+", default=["ieee14_lib", "npcc_lib", "wecc_lib"],
                    help="cases whose <event>_controls.csv.gz exists (others are named and skipped)")
    ap.add_argument("--event", default="fault")
    args = ap.parse_args()
    out = {"event": args.event, "ks_andes": KS_ANDES, "skipped": [], "units": {}}
    for case in args.case:
        d = DATA / case
        if not (d / f"{args.event}_controls.csv.gz").exists():
            out["skipped"].append(f"{case}: no {args.event}_controls.csv.gz (generate.py)")
            continue
        one_case(d, case, args.event, out)
    (HERE / "esst4b_pi.json").write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


def one_case(d, case, event, out):
    truth = json.loads((d / "truth.json").read_text())
    df = pd.read_csv(d / f"{event}.csv.gz")
    ctl = pd.read_csv(d / f"{event}_controls.csv.gz")
    t = df["time_s"].to_numpy()
    for m in truth["machines"]:
        if m["exciter"]["model"] != "ESST4B" or f"{m['tag']}/VM" not in df:
            continue
        if m.get("pss"):  # VOTHSG enters the regulator's input; the controls file does not hold it
            out["skipped"].append(f"{case} {m['tag']}: its stabiliser {m['pss']['model']}'s output "
                                  f"is not in {event}_controls.csv.gz")
            continue
        p = m["exciter"]["params_mbase_psse_order"]
        vt = df[f"{m['tag']}/VM"].to_numpy()
        vr_andes = ctl[f"{m['tag']}/ESST4B.PI1_y"].to_numpy()
        res = {}
        for scheme in ("nonwindup", "tracking"):
            vr = outer_pi(t, vt, p, scheme, vr_andes[0])
            after = t > T_EVENT_S
            res[scheme] = {"max_abs_err_vs_andes_pu": float(np.max(np.abs(vr - vr_andes))),
                           "rms_err_vs_andes_pu": float(np.sqrt(np.mean((vr - vr_andes)[after] ** 2))),
                           "final_vr_pu": float(vr[-1])}
        on_limit = np.isclose(vr_andes, p["VRMAX"]) | np.isclose(vr_andes, p["VRMIN"])
        res["andes_final_vr_pu"] = float(vr_andes[-1])
        res["andes_initial_vr_pu"] = float(vr_andes[0])
        res["andes_frames_on_a_vr_limit"] = int(on_limit.sum())
        out["units"][f"{case} {m['tag']}"] = res


if __name__ == "__main__":
    main()
