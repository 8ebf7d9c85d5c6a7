"""What the batch identification's interval costs, part by part, against dynamax's joint UKF.

    python benchmarks/identify_cost.py

``jd.identify`` on the recordings of ``benchmarks/run.py`` (the paper's plant, 60 s at 50
frames/s), batch 1024, with the interval built up one part at a time: the point estimate
(a2 alone), the Newey-West sandwich, the sandwich with the filter spread (two refits with F
made slower and faster), the parametric bootstrap with 8, 16 and 32 draws, and the default
(32 draws and the filter spread). dynamax's joint UKF (state and a1, a2) runs in the same
process as the yardstick. From the bootstrap rows, the cost of one draw per generator-sample
(least squares over the draw counts) and the time per generator-sample that an identification
may take to run at twice the joint UKF's speed.

Writes ``identify_cost`` into ``benchmarks/results.json`` (``run.py`` keeps it) and prints a
table.
"""

from __future__ import annotations

import json

import numpy as np
from run import HERE, dynamax_entry, identify_entry, recordings, ukf_inputs  # beside this script

import jaxdse as jd

BATCH = 1024
VARIANTS = {
    "point estimate (a2 only)": (jd.IdentifySettings(noise_interval="sandwich", spread_scales=()), False),
    "sandwich": (jd.IdentifySettings(noise_interval="sandwich", spread_scales=()), True),
    "sandwich + filter spread": (jd.IdentifySettings(noise_interval="sandwich"), True),
    "bootstrap 8 draws": (jd.IdentifySettings(bootstrap_draws=8, spread_scales=()), True),
    "bootstrap 16 draws": (jd.IdentifySettings(bootstrap_draws=16, spread_scales=()), True),
    "bootstrap 32 draws": (jd.IdentifySettings(bootstrap_draws=32, spread_scales=()), True),
    "default (bootstrap 32 draws + filter spread)": (jd.IdentifySettings(), True),
}


def main() -> None:
    plant = jd.Plant()
    sims = recordings(plant, 8, 60.0)
    joint = dynamax_entry(sims, plant, [ukf_inputs(s, plant) for s in sims], BATCH, True)
    ukf = joint["gen_samples_per_s"]
    print(f"dynamax joint UKF: {ukf / 1e3:,.0f} k gen-samples/s", flush=True)
    rows = {}
    for name, (ids, interval) in VARIANTS.items():
        e = identify_entry(sims, plant, BATCH, ids, interval)
        rate = e["gen_samples_per_s"]
        rows[name] = {"gen_samples_per_s": rate, "us_per_gen_sample": 1e6 / rate,
                      "ratio_to_joint_ukf": rate / ukf,
                      "a2_error_percent_median_abs": e["a2_error_percent_median_abs"]}
        print(f"{name}: {rows[name]['us_per_gen_sample']:.3f} us per gen-sample, "
              f"{rows[name]['ratio_to_joint_ukf']:.2f}x the joint UKF", flush=True)
    draws = np.array([8.0, 16.0, 32.0])
    cost = np.array([rows[f"bootstrap {int(d)} draws"]["us_per_gen_sample"] for d in draws])
    slope, intercept = np.polyfit(draws, cost, 1)
    out = {"batch": BATCH, "dynamax_joint_gen_samples_per_s": ukf,
           "us_per_gen_sample_at_2x_joint_ukf": 1e6 / (2.0 * ukf),
           "bootstrap_us_per_draw_and_gen_sample": float(slope),
           "bootstrap_fit_intercept_us": float(intercept), "variants": rows}
    path = HERE / "results.json"
    res = json.loads(path.read_text()) if path.exists() else {}
    res["identify_cost"] = out
    path.write_text(json.dumps(res, indent=2))
    print(f"one bootstrap draw: {slope:.3f} us per gen-sample; 2x the joint UKF leaves "
          f"{out['us_per_gen_sample_at_2x_joint_ukf']:.3f} us per gen-sample for the whole identification")


if __name__ == "__main__":
    main()
