"""H and D of a grid-forming converter (ANDES REGCV1, a virtual synchronous generator) from its
terminal recordings (``generate.py``), two ways, with 95 % intervals and verdicts:

* ``estimator``: the machine estimator (``jd.assess_units``: identification, replay, verdict)
  with the virtual rotor as a classical machine (``jd.classical_plant``: xd = xq = x'd, Tm =
  Pref - kw dw);
* ``playback``: the converter's own model played back with the recorded voltage imposed and
  M, D fitted to the recorded P and Q (``jd.calibrate`` on ``jd.GfmUnit``), the other constants
  from the record. Its verdict here: ``identified`` when the fit converged and H's 95 % interval
  is within +-10 % (the machine verdict's threshold), ``weakly identified`` within +-50 %, else
  ``not identified`` (the machine verdict's other checks, replay and D = 0, are not applied).

    python experiments/andes_gfm/run.py [--x-internal 0.2]

The recordings are noise-free; each gets PMU noise as the ANDES bench's (``run.py`` there:
0.05 % TVE on V and I, 1 mHz on f; one fixed seed per recording). Writes results.json.
"""

import argparse
import gzip
import json
import sys
import time
import zlib
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent
EVENTS = ("line_trip", "load_step", "gen_trip")
TVE_PERCENT = 0.05
F_NOISE_HZ = 1e-3
TOLERANCE = 0.02
"""The target: H within 2 % of the truth."""


def constants() -> dict:
    """The REGCV1 constants as generate.py gives them to ANDES (ANDES names)."""
    return json.loads((HERE / "truth.json").read_text())["constants"]


def read(event: str, tag: str):
    with gzip.open(HERE / f"{event}.csv.gz", "rt") as fh:
        header = fh.readline().strip().split(",")
        body = np.loadtxt(fh, delimiter=",")
    col = {name: body[:, k] for k, name in enumerate(header)}
    v = col[f"{tag}/VM"] * np.exp(1j * np.deg2rad(col[f"{tag}/VA"]))
    i = col[f"{tag}/IM"] * np.exp(1j * np.deg2rad(col[f"{tag}/IA"]))
    return col["time_s"], v, i, col[f"{tag}/F"]


def noisy(t, v, i, f, seed: int):
    rng = np.random.default_rng(seed)
    e = TVE_PERCENT / 100 / np.sqrt(2)
    v = v * (1 + e * (rng.standard_normal(t.size) + 1j * rng.standard_normal(t.size)))
    i = i * (1 + e * (rng.standard_normal(t.size) + 1j * rng.standard_normal(t.size)))
    return v, i, f + F_NOISE_HZ * rng.standard_normal(t.size)


def by_estimator(units, truth):
    assessed = jd.assess_units([u for u, _ in units], jd.ObserverConfig(),
                               jd.Settings(playback=False, keep="final"))
    rows = []
    for (_, event), a in zip(units, assessed):
        ident = a.identified
        word, reasons = jd.describe(a.verdict)
        lo, hi = (float(x) for x in ident.h_ci95)
        d_lo, d_hi = (float(x) for x in ident.d_ci95)
        rows.append(row("estimator", event, truth, float(ident.h_s), lo, hi, word, reasons,
                        d=float(ident.d_pu_s) * truth["omega_s"], d_ci=[d_lo * truth["omega_s"],
                                                                         d_hi * truth["omega_s"]]))
    return rows


def by_playback(event, series, unit, truth):
    specs = [jd.ParameterSpec("converter", "m_s", "M", 0.5, 100.0),
             jd.ParameterSpec("converter", "d_pu", "D", 0.0, 100.0, positive=False)]
    events = jd.stack_events([series])
    cal = jd.calibrate(unit, specs, events)
    m, d = cal.values
    (m_lo, m_hi), (d_lo, d_hi) = cal.ci95
    ok = cal.converged
    rel = (m_hi - m_lo) / 2 / m
    word = "identified" if ok and rel <= 0.10 else ("weakly identified" if ok and rel <= 0.5
                                                     else "not identified")
    return row("playback", event, truth, m / 2, m_lo / 2, m_hi / 2, word,
               [] if ok else ["the fit did not converge"], d=float(d), d_ci=[float(d_lo), float(d_hi)],
               rms_pq_pu=[float(x) for x in cal.rms_after_pu])


def row(method, event, truth, h, lo, hi, word, reasons, d, d_ci, **extra):
    h_true, d_true = truth["H_s"], truth["D_pu"]
    r = {"method": method, "event": event, "H_true_s": h_true, "H_s": h, "H_ci95": [lo, hi],
         "H_error_percent": 100 * (h / h_true - 1), "covers": bool(lo <= h_true <= hi),
         "within_2pct": bool(abs(h / h_true - 1) <= TOLERANCE), "verdict": word,
         "reasons": reasons, "D_true_pu": d_true, "D_pu": d, "D_ci95": d_ci,
         "D_covers": bool(d_ci[0] <= d_true <= d_ci[1]), **extra}
    print(f"[gfm] {method:9s} {event:9s} H {h:.3f} ({lo:.3f}-{hi:.3f}) true {h_true:.3f} "
          f"({r['H_error_percent']:+.2f} %) D {d:.3f} ({d_ci[0]:.3f}-{d_ci[1]:.3f}) true {d_true:.3f} "
          f"{word}", file=sys.stderr, flush=True)
    return r


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--x-internal", type=float, default=None,
                    help="reactance of the classical machine [pu] (default: the converter's xs)")
    ap.add_argument("--events", nargs="*", default=list(EVENTS))
    ap.add_argument("--methods", nargs="*", default=["estimator", "playback"])
    args = ap.parse_args()
    t0 = time.perf_counter()
    meta = json.loads((HERE / "truth.json").read_text())
    conv = jd.gfm_from_andes(meta["model"], meta["constants"])
    truth = {"H_s": meta["H_s"], "D_pu": meta["D_pu"], "omega_s": 2 * np.pi * meta["f0_hz"]}
    plant = jd.classical_plant(conv, s_rated_mva=meta["constants"]["Sn"], v_rated_kv=1.0,
                               s_base_mva=meta["system_base_mva"], x_internal_pu=args.x_internal)
    units, rows = [], []
    for event in args.events:
        t, v, i, f = read(event, meta["tag"])
        v, i, f = noisy(t, v, i, f, seed=zlib.crc32(f"gfm/{event}".encode()))
        rec = jd.Recording(t_s=t, v_mag_pu=np.abs(v), v_ang_rad=np.unwrap(np.angle(v)),
                           i_mag_pu=np.abs(i), i_ang_rad=np.unwrap(np.angle(i)), f_hz=f,
                           location="terminal")
        units.append((jd.Unit(f"gfm/{event}", rec, plant), event))
        if "playback" in args.methods:
            series = jd.TerminalSeries(jnp.asarray(t), jnp.abs(v), jnp.unwrap(jnp.angle(v)),
                                       jnp.real(i), jnp.imag(i))
            rows.append(by_playback(event, series, jd.GfmUnit(conv), truth))
    if "estimator" in args.methods:
        rows = by_estimator(units, truth) + rows
    path = HERE / "results.json"
    if path.exists():  # keep the rows of the methods and events not rerun
        done = {(r["method"], r["event"]) for r in rows}
        rows = [r for r in json.loads(path.read_text())["units"]
                if (r["method"], r["event"]) not in done] + rows
        rows.sort(key=lambda r: (r["method"] != "estimator", EVENTS.index(r["event"])))
    out = {"noise": {"tve_percent": TVE_PERCENT, "f_noise_hz": F_NOISE_HZ},
           "x_internal_pu": args.x_internal if args.x_internal is not None else meta["constants"]["xs"],
           "tolerance": TOLERANCE, "units": rows, "wall_s": time.perf_counter() - t0}
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"[gfm] wrote results.json in {out['wall_s']:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
