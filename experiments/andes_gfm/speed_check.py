"""Is the speed the machine estimator derives from the terminal (the slope of arg(V + j x I))
REGCV1's virtual rotor speed? On the noise-free recordings, leaving out 0.1 s before to 0.5 s
after the switching: the RMS error of that speed against ANDES's virtual speed, and M, D of a
least-squares swing fit M dw/dt + D dw = Pref - Pe on it (and on ANDES's own speed). NumPy
only. Writes speed_check.json.

    python experiments/andes_gfm/speed_check.py
"""

import gzip
import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
EVENTS = ("line_trip", "load_step", "gen_trip")
REACTANCES_PU = (0.0, 0.2, 1.0, 5.0)


def read(name):
    with gzip.open(HERE / name, "rt") as fh:
        header = fh.readline().strip().split(",")
        body = np.loadtxt(fh, delimiter=",")
    return {k: body[:, j] for j, k in enumerate(header)}


def swing_fit(w, p, p_ref, dt, keep):
    a = np.column_stack([np.gradient(w, dt), w - 1.0])
    m, d = np.linalg.lstsq(a[keep], (p_ref - p)[keep], rcond=None)[0]
    return float(m), float(d)


def main():
    meta = json.loads((HERE / "truth.json").read_text())
    tag, f0, t_ev = meta["tag"], meta["f0_hz"], meta["integration"]["t_event_s"]
    out = {}
    for event in EVENTS:
        rec, truth = read(f"{event}.csv.gz"), read(f"{event}_truth.csv.gz")
        t = rec["time_s"]
        dt = t[1] - t[0]
        v = rec[f"{tag}/VM"] * np.exp(1j * np.deg2rad(rec[f"{tag}/VA"]))
        i = rec[f"{tag}/IM"] * np.exp(1j * np.deg2rad(rec[f"{tag}/IA"]))
        p = (v * np.conj(i)).real
        w = truth["omega_pu"]
        keep = (t < t_ev - 0.1) | (t > t_ev + 0.5)
        keep[0] = False
        row = {"andes_speed_fit_M_D": swing_fit(w, p, meta["initial"]["pref_pu"], dt, keep)}
        for x in REACTANCES_PU:
            we = 1.0 + np.gradient(np.unwrap(np.angle(v + 1j * x * i)), dt) / (2 * np.pi * f0)
            row[f"x={x:g}"] = {
                "rms_error_over_rms_deviation": float(np.sqrt(np.mean((we - w)[keep] ** 2))
                                                      / np.sqrt(np.mean((w - 1.0)[keep] ** 2))),
                "fit_M_D": swing_fit(we, p, meta["initial"]["pref_pu"], dt, keep)}
        out[event] = row
        print(event, json.dumps(row))
    (HERE / "speed_check.json").write_text(json.dumps(out, indent=2) + "\n")


if __name__ == "__main__":
    main()
