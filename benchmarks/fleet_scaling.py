"""Fleet scaling: wall time of ``jd.assess_units`` for 1, 10, 100 and 1000 units.

    python benchmarks/fleet_scaling.py [--sizes 1 10 100 1000]

Each unit is 90 s at 30 frames/s (2700 samples) with its own plant and recording: windows of
the ANDES bench's ambient recordings (every machine of ieee14, npcc and wecc; GENROU machines
with TGOV1 or IEEEG1 governors, ``experiments/andes_bench``), tiled to the fleet size with
the machine data perturbed (reactances and time constants +-5 %, governor droop +-10 %) and
fresh PMU noise per unit. The default pipeline of ``jaxdse run``/``fleet`` runs on each:
online estimate, identification with its bootstrap interval, replay and verdict. Wall time
includes compilation (a fresh process per size would add JAX's import, ~2 s, not counted).

Writes ``fleet_scaling`` into ``benchmarks/results.json`` (and prints it).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent
BENCH = HERE.parent / "experiments" / "andes_bench"
FRAME_RATE_HZ = 30.0
DURATION_S = 90.0


def _andes():
    """The ANDES bench's readers (``experiments/andes_bench/run.py``: plant data, noise)."""
    spec = importlib.util.spec_from_file_location("andes_bench_run", BENCH / "run.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def bases(andes):
    """(time, V, I, f, machine record, f0) of every 90 s window of every ambient recording."""
    out = []
    n = int(DURATION_S * FRAME_RATE_HZ)
    for case in andes.CASES:
        truth = json.loads((andes.DATA / case / "truth.json").read_text())
        machines = {m["tag"]: m for m in truth["machines"]}
        t, phasors = andes.read_scenario(case, "ambient")
        step = max(1, round(1.0 / (FRAME_RATE_HZ * (t[1] - t[0]))))
        t = t[::step]
        for tag, (v, i, f) in phasors.items():
            for start in range(0, t.size - n + 1, n):
                sel = slice(start, start + n)
                out.append((t[sel] - t[start], v[::step][sel], i[::step][sel], f[::step][sel],
                            machines[tag], truth["f0_hz"]))
    return out


def perturbed(plant: jd.Plant, rng) -> jd.Plant:
    """``plant`` with its machine's reactances and time constants scaled by 1 +- 5 % and its
    governor's droop by 1 +- 10 % (a distinct plant per unit, one structure per governor type)."""
    m = plant.machine

    def k(spread=0.05):
        return float(1.0 + rng.uniform(-spread, spread))

    q = m.q_axis
    sx = k()
    machine = jd.Machine(
        xd_pu=m.xd_pu * sx, xq_pu=m.xq_pu * sx, xd1_pu=m.xd1_pu * sx, rs_pu=m.rs_pu, td01_s=m.td01_s * k(),
        s_rated_mva=m.s_rated_mva, v_rated_kv=m.v_rated_kv, f_nominal_hz=m.f_nominal_hz,
        q_axis=jd.QAxisCircuits(xq1_pu=q.xq1_pu * sx, xq2_pu=q.xq2_pu * sx, xl_pu=q.xl_pu * sx,
                                tq01_s=q.tq01_s * k(), tq02_s=q.tq02_s * k()))
    gov = plant.governor
    gov = type(gov)(**{**{f: getattr(gov, f) for f in gov.__dataclass_fields__},
                       **({"r_pu": gov.r_pu * k(0.1)} if hasattr(gov, "r_pu") else {"k": gov.k * k(0.1)})})
    return jd.Plant(machine=machine, governor=gov)


def fleet_units(count: int, pool, andes, seed: int = 0) -> list[jd.Unit]:
    rng = np.random.default_rng(seed)
    units = []
    for k in range(count):
        t, v, i, f, m, f0 = pool[k % len(pool)]
        rec = andes.noisy(t, v, i, f, seed=seed * 100003 + k)
        units.append(jd.Unit(f"u{k}", rec, perturbed(andes.plant(m, f0), rng)))
    return units


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1, 10, 100, 1000])
    args = ap.parse_args()
    andes = _andes()
    pool = bases(andes)
    print(f"{len(pool)} distinct 90 s windows; {jax.device_count()} device(s)", flush=True)
    res = {}
    for n in args.sizes:
        units = fleet_units(n, pool, andes)
        t0 = time.perf_counter()
        out = jd.assess_units(units, jd.ObserverConfig(), jd.Settings(), jd.IdentifySettings(),
                              jd.VerdictSettings())
        wall = time.perf_counter() - t0
        h = np.array([float(a.identified.h_s) for a in out])
        res[str(n)] = {"wall_s": wall, "per_unit_s": wall / n, "units": n,
                       "samples_per_unit": int(DURATION_S * FRAME_RATE_HZ),
                       "finite_h": int(np.sum(np.isfinite(h)))}
        print(n, res[str(n)], flush=True)
    path = HERE / "results.json"
    doc = json.loads(path.read_text()) if path.exists() else {}
    doc["fleet_scaling"] = res
    doc["fleet_scaling_machine"] = f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores"
    path.write_text(json.dumps(doc, indent=2) + "\n")
    plot(res, HERE / "fleet_scaling.png")


def plot(res: dict, path: Path) -> None:
    """Wall time and per-unit cost against the number of units (log-log)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = np.array([v["units"] for v in res.values()])
    wall = np.array([v["wall_s"] for v in res.values()])
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.4))
    ax[0].loglog(n, wall, "o-")
    ax[0].set_xlabel("units in the fleet")
    ax[0].set_ylabel("wall time incl. compile [s]")
    ax[0].axhline(120.0, color="grey", ls=":", label="120 s")
    ax[0].legend()
    ax[1].loglog(n, wall / n, "o-", color="tab:green")
    ax[1].set_xlabel("units in the fleet")
    ax[1].set_ylabel("wall time per unit [s]")
    fig.suptitle(f"jd.assess_units, {DURATION_S:.0f} s at {FRAME_RATE_HZ:.0f} frames/s per unit (ANDES bench "
                 "windows, perturbed plants)", fontsize=9)
    for a in ax:
        a.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
