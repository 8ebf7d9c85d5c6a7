"""Per-interval solves inside lax.scan vs one diffeqsolve stepping to the sample times.

Same recording (600 s, 50 frames/s, noisy), same tolerances. Reports compile and run time
of the full ``estimate`` and the largest difference of the a2 trajectories. Writes
benchmarks/integration_schemes.md.

    python benchmarks/integration_schemes.py
"""

from __future__ import annotations

import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402
from jaxdse._demo import demo_scenarios  # noqa: E402


def main() -> None:
    plant = jd.Plant()
    sim = jd.simulate(plant, demo_scenarios()["auto"])
    rows, a2 = [], {}
    for scheme in ("per_interval", "single_solve"):
        st = jd.Settings(observer_integrator=jd.Integrator(scheme=scheme),
                         playback_integrator=jd.Integrator(scheme=scheme, rtol=1e-6, atol=1e-9))
        f = jax.jit(jd.estimate)
        t0 = time.perf_counter()
        est = f(sim.recording, plant, jd.ObserverConfig(), st)
        est.a2.block_until_ready()
        first = time.perf_counter() - t0
        runs = []
        for _ in range(3):
            t0 = time.perf_counter()
            est = f(sim.recording, plant, jd.ObserverConfig(), st)
            est.a2.block_until_ready()
            runs.append(time.perf_counter() - t0)
        a2[scheme] = np.asarray(est.a2_hat)
        run = min(runs)
        rows.append((scheme, first - run, run, est.time_s.shape[0] / run, float(est.a2)))
        print(rows[-1], flush=True)
    diff = float(np.max(np.abs(a2["per_interval"] - a2["single_solve"])))
    lines = ["| scheme | compile s | run s | samples/s | final a2 |", "|---|---|---|---|---|"]
    lines += [f"| {r[0]} | {r[1]:.2f} | {r[2]:.3f} | {r[3]:.0f} | {r[4]:.6f} |" for r in rows]
    text = ("# Integration schemes (full `estimate`, 600 s at 50 frames/s, 2-core CPU)\n\n"
            + "\n".join(lines) + f"\n\nmax |a2_hat difference| over the run: {diff:.2e}\n")
    Path(__file__).with_suffix(".md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
