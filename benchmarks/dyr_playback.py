"""Cost of the .dyr playback and calibration (issue: the planner's own model).

    python benchmarks/dyr_playback.py

* playback: 32 units of one structure (the npcc bench's GENROU/IEEEX1/TGOV1 machines, each of
  their three 70 s events at 60 frames/s, tiled to 32), one ``eqx.filter_vmap(jd.play_back)``
  call, default settings (adaptive Tsit5 per frame); wall time of a second call (compile
  apart) per unit;
* calibration: one unit (npcc B50_G1) with H, the exciter gain and the droop planted wrong,
  ranked and calibrated on its three 70 s events jointly (``jd.rank`` + ``jd.calibrate``, the
  first step half a frame in the fit), wall time of a second run (compile apart) and of the first.

Writes ``dyr_playback`` into ``benchmarks/results.json``.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import pandas as pd  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent
BENCH = HERE.parent / "experiments" / "andes_bench"
sys.path.insert(0, str(BENCH))
from playback import series_of  # noqa: E402

EVENTS = ("line_trip", "load_step", "gen_trip")
BATCH = 32


def npcc_units():
    d = BENCH / "data" / "npcc"
    truth = json.loads((d / "truth.json").read_text())
    raw, dyr = jd.read_raw(d / "npcc.raw"), jd.read_dyr(d / "npcc.dyr")
    out = []
    for ev in EVENTS:
        df = pd.read_csv(d / f"{ev}.csv.gz")
        for m in truth["machines"]:
            um = jd.unit_model(dyr, raw, m["bus"], m["id"], ke_zero="literal")
            out.append((m, um, series_of(df, m["tag"], m["mbase_mva"]), ev))
    return out


def stack(trees):
    return jax.tree.map(lambda *x: jnp.stack(x), *trees)


def main() -> None:
    units = npcc_units()
    chosen = [units[k % len(units)] for k in range(BATCH)]
    batch = eqx.filter_jit(eqx.filter_vmap(jd.play_back, in_axes=(0, 0, None)))
    u, s = stack([c[1].unit for c in chosen]), stack([c[2] for c in chosen])
    t0 = time.perf_counter()
    jax.block_until_ready(batch(u, s, jd.PlaybackSettings()))
    first = time.perf_counter() - t0
    t0 = time.perf_counter()
    r = jax.block_until_ready(batch(u, s, jd.PlaybackSettings()))
    wall = time.perf_counter() - t0
    playback = {"units": BATCH, "event_s": float(s.t_s[0, -1] - s.t_s[0, 0]), "frames_per_s": 60,
                "first_call_s": round(first, 2), "wall_s": round(wall, 3),
                "per_unit_s": round(wall / BATCH, 4), "all_ok": bool(jnp.all(r.ok))}
    print("playback", playback, flush=True)

    m, um, _, _ = next(c for c in units if c[0]["tag"] == "B50_G1")
    events = jd.stack_events([c[2] for c in units if c[0]["tag"] == "B50_G1"])
    fit = jd.PlaybackSettings(substeps=2)
    specs = jd.parameter_specs(um.unit, um.models, jd.CalibrateOptions(), [])
    plant = {"H": 1.2, "KA": 0.7, "R": 1.3}
    wrong = jd.with_values(um.unit, [x for x in specs if x.label in plant],
                           [float(x.value(um.unit)) * plant[x.label] for x in specs if x.label in plant])
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        rk = jd.rank(wrong, specs, events, fit)
        free = [x for x, ok in zip(specs, rk.identifiable) if ok]
        res = jd.calibrate(wrong, free, events, fit)
        times.append(time.perf_counter() - t0)
    got = dict(zip(res.labels, res.values))
    calibration = {"unit": "npcc B50_G1", "events": len(EVENTS), "event_s": 70.0,
                   "parameters_ranked": [x.label for x in specs], "calibrated": res.labels,
                   "first_run_s": round(times[0], 1), "wall_s": round(times[1], 1),
                   "H_error_percent": 100 * (got["H"] - m["H_s_mbase"]) / m["H_s_mbase"],
                   "converged": res.converged}
    print("calibration", calibration, flush=True)
    path = HERE / "results.json"
    doc = json.loads(path.read_text()) if path.exists() else {}
    doc["dyr_playback"] = {"playback": playback, "calibration": calibration,
                           "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"}
    path.write_text(json.dumps(doc, indent=2) + "\n")


if __name__ == "__main__":
    main()
