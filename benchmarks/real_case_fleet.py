"""Scale on a real case (issues 33, 44): every in-service unit of ACTIVSg2000 (or of another
case: the Texas 7k case's synchronous and inverter-based plants), ``jaxdse fleet`` with the
.dyr playback, end to end.

    python benchmarks/real_case_fleet.py                 # every unit (about 5 minutes on 2 cores)
    python benchmarks/real_case_fleet.py --units 26      # a quick run: 2 units of each chain
    python benchmarks/real_case_fleet.py --no-write      # measure, leave results.json alone
    jaxdse check experiments/activsg2000/case.toml --repair --out rep/
    python benchmarks/real_case_fleet.py --raw rep/repaired.raw --dyr rep/repaired.dyr  # repaired
    python benchmarks/real_case_fleet.py --texas7k       # the Texas 7k case, inverter plants too

1. Read ACTIVSg2000 (``../shared/data/activsg2000``, or ``--case DIR``; ``--dyr FILE`` and
   ``--raw FILE``: another .dyr and .raw, e.g. the ``repaired.dyr`` and ``repaired.raw`` of
   ``jaxdse check --repair``) with ``jd.read_raw`` /
   ``jd.read_dyr``; every in-service generator with a machine record is a synchronous unit,
   one with a converter record (REGCA1, REGCB1) an inverter-based plant. ``jd.unit_model`` (or
   ``jd.ibr_model``) builds its model from its own records; a unit whose model cannot be built
   (a model not simulated, a data problem) is listed with the reason and left out, as ``jaxdse
   check`` does; so is a unit that does not hold its power-flow P and Q (within
   ``FLAT_TOL_PU``) over the recording's undisturbed first seconds (check's held-voltage run).
   Generators without any record (ACTIVSg2000's wind and solar plants) are counted apart.
2. A 70 s event recording per unit at ``--fps`` frames/s (30: a common PMU reporting rate): a
   terminal-voltage disturbance drawn per unit from a seed, played into the unit's own model
   (``jd.play_back``, adaptive Tsit5 at rtol 1e-9: tighter than the fleet's 1e-7) from the .raw power flow at
   its terminal, vmapped per model chain (an inverter-based plant sees the angle's slope as
   its frequency deviation). Two kinds (3 in 5 the first):
   * a nearby fault cleared after 3-6 cycles: |V| dips to 25-75 % with an angle jump, then the
     post-fault network (a line out): a step of |V| (-3 to +0.5 %) and of the angle (2-10 deg
     either way) with an electromechanical swing (0.6-1.8 Hz, damping ratio 5-15 %, 2-8 deg);
   * a line trip: the same step and swing, smaller (1-5 deg), no dip;
   both with a slow system-frequency excursion (0-40 mHz) in the angle. The |V| step does not
   last: the unit's own regulator takes it back, as ``dv (1 - x/tau) e^(-x/tau)`` (x the time
   since the event, tau 0.5-2 s): a small overshoot, and no integral of the error left. The
   imposed voltage leaves the regulator's loop open (as in ``jaxdse check``), so a held step
   winds a regulator with integral action or high gain to its ceiling: in the first full run
   B1050_G1 (ESST4B) went from Efd 1.91 to 5.16 pu and Q from -0.04 to 1.56 pu of MBASE (|S|
   1.77 pu), and 220 units were refused by the fleet's rating check; in the grid that Q would
   raise the voltage back. A fault's dip still leaves some wind-up, most where it stays inside
   the regulator's limits: over the full run Q ends at most 0.37 pu of MBASE above where it
   started (B7135_G1, ESST4B, a dip to 75 %), 0.1 pu at the 95th percentile.
   PMU noise as ``experiments/andes_bench/calibration.py``'s ``noisy``: 0.05 % TVE, complex
   Gaussian on the voltage and the current phasors. CSV (time_s, |V| pu, angle deg, |I| pu on
   100 MVA, angle deg) in a temporary folder, one file; the fleet file beside it
   (``[channels] layout = "per_machine"``, ``[playback]`` left at its default ``model = "dyr"``).
3. ``jaxdse fleet FLEET.toml --out DIR`` (``jd.fleet``, with the console script's float64 and
   persistent compilation cache, set through ``jax.config``) in a fresh process, twice: cold
   (an empty persistent compilation cache in a temporary folder) and warm (the same cache,
   second run). Wall time is the process's, from start to exit (Python and JAX start-up
   included). Inside, ``jax.monitoring`` counts the compiled programs by function (the
   playback: ``_batch`` of ``_app/dyr_fleet.py``, compiled as ``call_exported``; the assessment:
   ``_assess_vmapped``) with
   their trace, lowering and compile seconds; programs under 0.1 s (small array ops) are
   counted apart.

Writes ``real_case_fleet`` (with ``--dyr`` or ``--raw``: ``real_case_fleet_repaired``; ``--key``) into
``benchmarks/results.json`` (other keys kept). Only the public API (``import jaxdse as jd``) is used.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import Counter, defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
CASE = ROOT.parent / "shared" / "data" / "activsg2000"
RAW, DYR = "ACTIVSg2000.RAW", "ACTIVSg2000_dynamics.dyr"
TEXAS7K = ROOT.parent / "shared" / "data" / "texas7k"
TEXAS7K_RAW, TEXAS7K_DYR = "Texas7k_20210309.raw", "Texas7k_20210309_Dynamics.dyr"
TVE_PERCENT = 0.05
EVENT_S = 70.0
PLAYBACK_FN, ASSESS_FN = "_batch", "_assess_vmapped"
EXPORTED = {"call_exported": PLAYBACK_FN, "call": PLAYBACK_FN}
"""The playback's programs are exported (``_many/programs.py``): traced as ``_batch`` where the
cache holds none yet, compiled under the name of the exported program's call (``call`` in JAX
0.10: there the count includes the initial-state programs, ``_starts``)."""
SMALL_COMPILE_S = 0.1
FLAT_TOL_PU = 1e-4
"""Largest |P - P0|, |Q - Q0| before the event [pu of MBASE]: a unit beyond it is left out."""


# --- the child: one `jaxdse fleet` run, instrumented ------------------------------------------

def child(fleet_file: str, out_dir: str, stats_file: str) -> None:
    t_start = time.perf_counter()
    import jax
    from jax import monitoring

    durations: list = []
    events: Counter = Counter()
    monitoring.register_event_duration_secs_listener(
        lambda ev, d, **kw: durations.append((ev, kw.get("fun_name", ""), d)))
    monitoring.register_event_listener(lambda ev, **kw: events.update([ev]))
    # as the `jaxdse` console script sets them: float64, the persistent cache in JAXDSE_CACHE_DIR
    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_compilation_cache_dir", os.environ["JAXDSE_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)
    import jaxdse as jd

    t0 = time.perf_counter()
    jd.fleet(fleet_file, out_dir)
    rc = 0
    wall_main = time.perf_counter() - t0
    Path(stats_file).write_text(json.dumps({
        "rc": rc, "main_s": wall_main, "in_process_s": time.perf_counter() - t_start,
        "durations": durations, "events": dict(events)}))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


def compile_summary(durations: list) -> dict:
    """Per function: programs compiled (backend compile events; with a warm cache these are
    cache loads) and seconds of tracing, lowering and compiling."""
    by = defaultdict(lambda: {"programs": 0, "trace_s": 0.0, "lower_s": 0.0, "compile_s": 0.0})
    for ev, fn, d in durations:
        name = fn.removeprefix("jit(").removesuffix(")").removeprefix("jit_")
        name = EXPORTED.get(name, name)
        if ev.endswith("backend_compile_duration"):
            by[name]["programs"] += 1
            by[name]["compile_s"] += d
            by[name].setdefault("each_s", []).append(round(d, 2))
        elif ev.endswith("jaxpr_trace_duration"):
            by[name]["trace_s"] += d
        elif ev.endswith("jaxpr_to_mlir_module_duration"):
            by[name]["lower_s"] += d
    big = {k: v for k, v in by.items() if v["compile_s"] >= SMALL_COMPILE_S or k in (PLAYBACK_FN, ASSESS_FN)}
    small = [v for k, v in by.items() if k not in big]
    out = {k: {"programs": v["programs"], "trace_s": round(v["trace_s"], 2),
               "lower_s": round(v["lower_s"], 2), "compile_s": round(v["compile_s"], 2),
               **({"each_compile_s": v["each_s"]} if "each_s" in v and len(v["each_s"]) > 1 else {})}
           for k, v in sorted(big.items(), key=lambda kv: -kv[1]["compile_s"])}
    out["(small programs)"] = {"programs": sum(v["programs"] for v in small),
                               "trace_s": round(sum(v["trace_s"] for v in small), 2),
                               "lower_s": round(sum(v["lower_s"] for v in small), 2),
                               "compile_s": round(sum(v["compile_s"] for v in small), 2)}
    return out


def run_fleet(fleet_file: Path, out_dir: Path, cache_dir: str) -> dict:
    env = {**os.environ, "JAXDSE_CACHE_DIR": cache_dir}
    stats_file = out_dir.with_suffix(".stats.json")
    t0 = time.perf_counter()
    proc = subprocess.run([sys.executable, __file__, "--child", str(fleet_file), str(out_dir),
                           str(stats_file)], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0 or not stats_file.exists():
        sys.exit(f"jaxdse fleet failed ({proc.returncode}):\n{proc.stderr[-4000:]}")
    stats = json.loads(stats_file.read_text())
    doc = json.loads((out_dir / "fleet.json").read_text())
    return {"wall_s": wall, "stats": stats, "doc": doc, "stderr": proc.stderr}


# --- the recordings ---------------------------------------------------------------------------

def case_units(raw, dyr, jd):
    """(built [(gen, UnitModel or IbrModel)], left out [{name, bus, id, category, models,
    reasons}], no records count)."""
    built, left, bare = [], [], 0
    seen = set()
    for g in raw.generators:
        key = (g.bus, g.id.strip().upper())
        if g.stat != 1 or key in seen:
            continue
        seen.add(key)
        um = jd.unit_model(dyr, raw, g.bus, g.id)
        category = "synchronous"
        if "machine" not in um.models:
            um = jd.ibr_model(dyr, g.bus, g.id, raw)
            category = "inverter-based"
            if "converter" not in um.models:
                bare += 1                           # no machine or converter record
                continue
        if um.unit is None:
            left.append({"name": f"B{g.bus}_G{g.id.strip()}", "bus": g.bus, "id": g.id.strip(),
                         "category": category, "models": um.models, "reasons": list(um.missing)})
            continue
        built.append((g, um))
    return built, left, bare


def is_ibr_model(um) -> bool:
    return "converter" in um.models


def choose(built, n: int | None):
    """All units, or ``n`` of them taken round-robin over the model chains (every chain first)."""
    if n is None or n >= len(built):
        return list(built)
    chains = defaultdict(list)
    for b in built:
        chains[b[1].structure].append(b)
    order = sorted(chains.values(), key=len, reverse=True)
    out, k = [], 0
    while len(out) < n:
        for c in order:
            if k < len(c) and len(out) < n:
                out.append(c[k])
        k += 1
    return out


def disturbance(rng, t, v0: float, a0: float):
    """|V| [pu] and angle [rad] of one terminal: a cleared fault or a line trip (see the module)."""
    import numpy as np

    fault = rng.random() < 0.6
    te = rng.uniform(8.0, 14.0)
    f_sw, zeta = rng.uniform(0.6, 1.8), rng.uniform(0.05, 0.15)
    w = 2 * np.pi * f_sw
    wd = w * np.sqrt(1 - zeta**2)
    sign = rng.choice([-1.0, 1.0])
    step_deg = sign * (rng.uniform(2.0, 10.0) if fault else rng.uniform(1.0, 5.0))
    swing_deg = rng.uniform(2.0, 8.0) if fault else rng.uniform(1.0, 4.0)
    dv = rng.uniform(-0.03, 0.005)
    tau_v = rng.uniform(0.5, 2.0)
    dv_swing = rng.uniform(0.002, 0.01)
    df_hz = rng.uniform(0.0, 0.04)
    clear = te + rng.integers(3, 7) / 60.0
    after = t >= clear
    x = np.where(after, t - clear, 0.0)
    decay = np.exp(-zeta * w * x)
    ang = a0 + after * np.deg2rad(step_deg + swing_deg * decay * np.sin(wd * x))
    # the unit's regulator restores its terminal voltage: the step recovers through a small
    # overshoot that leaves no integral of the error (a PI regulator's integrator returns)
    recover = (1 - x / tau_v) * np.exp(-x / tau_v)
    vm = v0 + after * (dv * recover + dv_swing * decay * np.sin(wd * x + rng.uniform(0, np.pi)))
    # a slow system-frequency excursion after the event: dips, partly recovers
    f_dev = -df_hz * after * (1 - np.exp(-x / 2.0)) * (0.4 + 0.6 * np.exp(-x / 15.0))
    ang = ang + 2 * np.pi * np.concatenate([[0.0], np.cumsum(f_dev[1:] * np.diff(t))])
    if fault:
        during = (t >= te) & (t < clear)
        vm = np.where(during, v0 * rng.uniform(0.25, 0.75), vm)
        ang = np.where(during, a0 + np.deg2rad(rng.uniform(-15.0, 10.0)), ang)
    return vm, ang, {"kind": "fault cleared" if fault else "line trip", "t_event_s": round(te, 3),
                     "clear_s": round(clear - te, 4) if fault else None, "angle_step_deg": step_deg,
                     "swing_hz": f_sw, "damping_ratio": zeta}


def noisy(rng, v, i):
    """0.05 % TVE: complex Gaussian relative errors on the phasors (calibration.py's ``noisy``)."""
    import numpy as np

    sd = TVE_PERCENT / 100 / np.sqrt(2)
    n = v.shape[0]
    v = v * (1 + sd * (rng.standard_normal(n) + 1j * rng.standard_normal(n)))
    i = i * (1 + sd * (rng.standard_normal(n) + 1j * rng.standard_normal(n)))
    return v, i


def make_recordings(chosen, raw, fps: float, seed: int, jd):
    """Per unit: (column dict, event info) and per chain the generation's timing."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp
    import numpy as np

    t = np.arange(int(round(EVENT_S * fps)) + 1) / fps
    series, info = [], []
    for k, (g, um) in enumerate(chosen):
        rng = np.random.default_rng([seed, g.bus, k])
        b = raw.buses[g.bus]
        v0, a0 = b.vm_pu, np.deg2rad(b.va_deg)
        vm, va, ev = disturbance(rng, t, v0, a0)
        s0 = (g.pg_mw + 1j * g.qg_mvar) / g.mbase_mva           # machine base
        i0 = np.conj(s0 / (v0 * np.exp(1j * a0))) * np.ones_like(t)
        series.append(jd.TerminalSeries(*(jnp.asarray(a) for a in (t, vm, va, i0.real, i0.imag))))
        info.append(ev)
    gen = eqx.filter_jit(eqx.filter_vmap(jd.play_back, in_axes=(0, 0, None)))
    settings = jd.PlaybackSettings(rtol=1e-9, atol=1e-11)
    groups = defaultdict(list)   # one call per model chain and pytree structure (an IBR's flags)
    for k, (_, um) in enumerate(chosen):
        groups[(um.structure, jax.tree_util.tree_structure(um.unit))].append(k)
    results, timing = {}, defaultdict(lambda: {"units": 0, "calls": 0, "wall_s": 0.0})
    for (chain, _), idx in groups.items():
        t0 = time.perf_counter()
        units = jax.tree.map(lambda *x: jnp.stack(x), *[chosen[k][1].unit for k in idx])
        ser = jax.tree.map(lambda *x: jnp.stack(x), *[series[k] for k in idx])
        res = jax.device_get(gen(units, ser, settings))
        tm = timing["/".join(chain)]
        tm["units"] += len(idx)
        tm["calls"] += 1
        tm["wall_s"] = round(tm["wall_s"] + time.perf_counter() - t0, 2)
        for j, k in enumerate(idx):
            results[k] = (np.asarray(res.p_pu[j]), np.asarray(res.q_pu[j]), bool(res.ok[j]))
    cols, failed = {"time_s": t}, []
    for k, (g, um) in enumerate(chosen):
        p, q, ok = results[k]
        tag = f"B{g.bus}_G{g.id.strip()}"
        if not (ok and np.all(np.isfinite(p)) and np.all(np.isfinite(q))):
            failed.append({"name": tag, "models": um.models,
                           "reason": "the generating playback did not reach the end"})
            continue
        # The no-disturbance screen (as `jaxdse check`'s held-voltage run): before the event the
        # unit must hold its power-flow P and Q.
        pre = t < info[k]["t_event_s"] - 0.05
        p0, q0 = g.pg_mw / g.mbase_mva, g.qg_mvar / g.mbase_mva
        drift = max(np.max(np.abs(p[pre] - p0)), np.max(np.abs(q[pre] - q0)))
        if drift > FLAT_TOL_PU:
            failed.append({"name": tag, "models": um.models, "reason": (
                f"does not hold its power-flow operating point with the terminal voltage held: "
                f"P {p0:.4f} -> {p[pre][-1]:.4f}, Q {q0:.4f} -> {q[pre][-1]:.4f} pu of MBASE "
                f"({g.mbase_mva:g} MVA) in {t[pre][-1]:.1f} s")})
            continue
        s = series[k]
        v = np.asarray(s.v_mag_pu) * np.exp(1j * np.asarray(s.v_ang_rad))
        i = np.conj((p + 1j * q) / v) * (g.mbase_mva / raw.sbase_mva)   # pu on the system base
        v, i = noisy(np.random.default_rng([seed, g.bus, k, 1]), v, i)
        cols[f"{tag}/VM"] = np.abs(v)
        cols[f"{tag}/VA"] = np.rad2deg(np.angle(v))
        cols[f"{tag}/IM"] = np.abs(i)
        cols[f"{tag}/IA"] = np.rad2deg(np.angle(i))
        info[k]["name"] = tag
    return cols, [i for k, i in enumerate(info) if "name" in i], failed, dict(timing)


FLEET_TOML = """# written by benchmarks/real_case_fleet.py: {name}, one 70 s event per unit
[case]
raw = {raw!r}
dyr = {dyr!r}

[measurement]
file = "events.csv"
location = "terminal"
voltage_unit = "pu"
current_unit = "pu"
angle_unit = "deg"
s_base_mva = {sbase}

[channels]
layout = "per_machine"
name = "B{{bus}}_G{{id}}"
time = "time_s"
v_mag = "B{{bus}}_G{{id}}/VM"
v_ang = "B{{bus}}_G{{id}}/VA"
i_mag = "B{{bus}}_G{{id}}/IM"
i_ang = "B{{bus}}_G{{id}}/IA"

[output]
figures = false
"""


def by_category(units: list, np) -> dict:
    """Per category (synchronous, inverter-based): units, played back on their own records,
    validation results, median RMS error of P and Q [% of MBASE]."""
    out = {}
    for cat in ("synchronous", "inverter-based"):
        us = [u for u in units if (u.get("plant_type") == "inverter-based") == (cat == "inverter-based")]
        own = [u for u in us if u["validation"]["model"] == "dyr"]
        out[cat] = {"units": len(us), "played_back_with_own_records": len(own),
                    "validation": dict(Counter(u["validation"]["result"] for u in us)),
                    "median_rms_percent_mbase": {
                        k: float(np.median([u["playback_rms_percent_mbase"][k] for u in own
                                            if u["playback_rms_percent_mbase"][k] is not None] or [np.nan]))
                        for k in ("P_t", "Q_t")}}
    return out


# --- main ---------------------------------------------------------------------------------------

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--units", type=int, default=None, help="units to run (default: all)")
    ap.add_argument("--fps", type=float, default=30.0, help="frames per second (default 30)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--case", type=Path, default=CASE, help="folder with ACTIVSg2000.RAW and .dyr")
    ap.add_argument("--dyr", type=Path, default=None,
                    help="a .dyr to use instead of the case's (e.g. repaired.dyr of `jaxdse check --repair`)")
    ap.add_argument("--raw", type=Path, default=None,
                    help="a .raw to use instead of the case's (e.g. repaired.raw of `jaxdse check --repair`)")
    ap.add_argument("--key", default=None, help="results.json key (default: real_case_fleet, with --dyr "
                    "real_case_fleet_repaired)")
    ap.add_argument("--texas7k", action="store_true", help="the Texas 7k case (../shared/data/texas7k): its "
                    "synchronous and inverter-based plants; results key real_case_fleet_texas7k")
    ap.add_argument("--keep", type=Path, default=None, help="keep the recordings and reports here")
    ap.add_argument("--no-write", action="store_true", help="leave benchmarks/results.json alone")
    args = ap.parse_args()
    load = os.getloadavg()
    t_all = time.perf_counter()
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np
    import pandas as pd

    import jaxdse as jd

    if args.texas7k:
        name = "Texas 7k (Texas A&M synthetic, 2021-03-09, rev 33 .raw + .dyr)"
        dyr_file, raw_file = args.dyr or TEXAS7K / TEXAS7K_DYR, args.raw or TEXAS7K / TEXAS7K_RAW
    else:
        name = "ACTIVSg2000 (rev 33 .raw + .dyr)"
        dyr_file, raw_file = args.dyr or args.case / DYR, args.raw or args.case / RAW
    raw = jd.read_raw(raw_file, strict=False)
    dyr = jd.read_dyr(dyr_file, strict=False)
    repaired = sorted({f"B{r.bus}_G{r.id}" for r in dyr.records if r.changes}
                      | {f"B{g.bus}_G{g.id.strip()}" for g in raw.generators if g.changes})
    built, left, bare = case_units(raw, dyr, jd)
    chosen = choose(built, args.units)
    chains = Counter("/".join(b[1].structure) for b in chosen)
    n_ibr = sum(is_ibr_model(um) for _, um in built) + sum(x["category"] == "inverter-based" for x in left)
    print(f"{len(built) + len(left) - n_ibr} synchronous units and {n_ibr} inverter-based plants "
          f"({len(left)} left out), {bare} generators without records; running {len(chosen)} units of "
          f"{len(chains)} chains", flush=True)
    for x in left:
        print(f"  left out: {x['name']}: {'; '.join(x['reasons'])}")
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="jaxdse_real_case_"))
    work.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    cols, events, failed, gen_timing = make_recordings(chosen, raw, args.fps, args.seed, jd)
    gen_s = time.perf_counter() - t0
    pd.DataFrame(cols).to_csv(work / "events.csv", index=False, float_format="%.8g")
    (work / "fleet.toml").write_text(FLEET_TOML.format(name=name.split(" (")[0],
        raw=str(Path(raw_file).resolve()), dyr=str(dyr_file.resolve()), sbase=raw.sbase_mva))
    print(f"recordings: {len(events)} units in {gen_s:.1f} s ({len(failed)} failed), "
          f"{(work / 'events.csv').stat().st_size / 1e6:.0f} MB CSV in {work}", flush=True)

    cache = tempfile.mkdtemp(prefix="jaxdse_cache_")
    runs = {}
    for label in ("cold", "warm"):
        load_before = os.getloadavg()
        r = run_fleet(work / "fleet.toml", work / f"out_{label}", cache)
        runs[label] = r
        print(f"{label}: {r['wall_s']:.1f} s (load before {load_before[0]:.2f})", flush=True)
        print(json.dumps(compile_summary(r["stats"]["durations"]), indent=1), flush=True)

    doc = runs["warm"]["doc"]
    units = doc["units"]
    played = sum(u["validation"]["model"] == "dyr" for u in units)
    n = len(units)
    cold, warm = runs["cold"], runs["warm"]
    cs_cold, cs_warm = (compile_summary(r["stats"]["durations"]) for r in (cold, warm))
    chain_names = sorted(chains)
    result = {
        "command": "python benchmarks/real_case_fleet.py" + (" --texas7k" if args.texas7k else "")
                   + (f" --units {args.units}" if args.units else "")
                   + (f" --raw {args.raw}" if args.raw else "") + (f" --dyr {args.dyr}" if args.dyr else ""),
        "case": name + (f", .raw {Path(raw_file).name}" if args.raw else "")
                + (f", .dyr {dyr_file.name}" if args.dyr else ""),
        "synchronous_units": len(built) + len(left) - n_ibr,
        "inverter_based_plants": n_ibr,
        "units_on_repaired_records": len(repaired),
        "units_on_repaired_records_run": sum(f"B{g.bus}_G{g.id.strip()}" in repaired for g, _ in chosen),
        "units_left_out": left,
        "generators_without_records": bare,
        "units_run": n, "units_not_flat_or_failed": failed,
        "flat_tolerance_pu": FLAT_TOL_PU, "fleet_skipped": doc["skipped"],
        "played_back_with_own_records": played,
        "model_chains": len(chain_names), "chains": dict(sorted(chains.items(), key=lambda kv: -kv[1])),
        "recording": {"event_s": EVENT_S, "frames_per_s": args.fps, "tve_percent": TVE_PERCENT,
                      "kinds": dict(Counter(e["kind"] for e in events)), "seed": args.seed,
                      "generation_s": round(gen_s, 1), "generation_by_chain": gen_timing},
        "cold": {"wall_s": round(cold["wall_s"], 1), "fleet_json_wall_s": cold["doc"]["wall_time_s"],
                 "compiled": cs_cold, "cache_events": cold["stats"]["events"]},
        "warm": {"wall_s": round(warm["wall_s"], 1), "fleet_json_wall_s": warm["doc"]["wall_time_s"],
                 "compiled": cs_warm, "cache_events": warm["stats"]["events"]},
        "programs": {"playback": cs_cold.get(PLAYBACK_FN, {}).get("programs", 0),
                     "assessment": cs_cold.get(ASSESS_FN, {}).get("programs", 0)},
        "per_unit_s": {"cold": round(cold["wall_s"] / n, 3), "warm": round(warm["wall_s"] / n, 3)},
        "goal_s": {"cold": 300, "warm": 150} if args.texas7k else {"cold": 180, "warm": 90},
        "validation": doc["summary"]["validation"], "verdicts": doc["summary"]["verdicts"],
        "median_rms_percent_mbase": {
            k: float(np.median([u["playback_rms_percent_mbase"][k] for u in units
                                if u["validation"]["model"] == "dyr"
                                and u["playback_rms_percent_mbase"][k] is not None] or [np.nan]))
            for k in ("P_t", "Q_t")},
        "by_category": by_category(units, np),
        "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
        "load_average_at_start": [round(x, 2) for x in load],
        "jax": jax.__version__,
        "total_s": round(time.perf_counter() - t_all, 1),
    }
    print(json.dumps({k: v for k, v in result.items() if k not in ("units_left_out",)}, indent=1))
    if not args.no_write:
        path = HERE / "results.json"
        doc = json.loads(path.read_text()) if path.exists() else {}
        doc[args.key or ("real_case_fleet_texas7k" if args.texas7k else "real_case_fleet_repaired"
                     if args.dyr or args.raw else "real_case_fleet")] = result
        path.write_text(json.dumps(doc, indent=2) + "\n")


if __name__ == "__main__":
    if len(sys.argv) == 5 and sys.argv[1] == "--child":
        child(*sys.argv[2:])
    else:
        main()
