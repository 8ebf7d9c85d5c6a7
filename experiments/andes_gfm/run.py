"""H and D of a grid-forming converter (ANDES REGCV1, a virtual synchronous generator) from its
terminal recordings (``generate.py``), two ways, with 95 % intervals and verdicts:

* ``estimator``: the machine estimator (``jd.assess_units``: identification, replay, verdict)
  with the virtual rotor as a classical machine (``jd.classical_plant``: xd = xq = x'd, Tm =
  Pref - kw dw);
* ``fleet``: ``jaxdse fleet`` (``jaxdse.fleet``) on the case with the converter's .dyr record
  (REGCV1 under ANDES's name, M planted at ``FLEET_M_FACTOR`` times the truth, so that the fit
  must move) and each noisy recording as a PMU CSV at the terminal; its fleet.json H, interval
  and verdict (the product's path: record reader, playback fit, verdict); also REGCV2 on its
  line trip (``regcv2/``);
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
import io
import json
import sys
import tempfile
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


def read(event: str, tag: str, folder: Path = HERE):
    with gzip.open(folder / f"{event}.csv.gz", "rt") as fh:
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


FLEET_M_FACTOR = 1.3
"""The record's M in the fleet runs, times the truth."""
CASE = HERE.parent / "andes_bench" / "data" / "ieee14"


def by_fleet(event, t, v, i, f, meta, truth, tmp: Path):
    """``jaxdse fleet`` on the bench case with the converter's record and the noisy recording."""
    # (REGCV2's record keeps REGCV1's Tc, which it does not use: ANDES's default)
    c = {"Tc": 0.01, **meta["constants"], "M": FLEET_M_FACTOR * meta["constants"]["M"]}
    model = meta["model"]
    (tmp / "case.raw").write_text((CASE / "ieee14.raw").read_text())
    (tmp / "case.dyr").write_text(f"8 '{model}' '1' {' '.join(f'{c[k]:g}' for k in jd.IBR_FIELDS[model])} /\n")
    tag = meta["tag"]
    cols = {"time_s": t, f"{tag}/F": f, f"{tag}/VM": np.abs(v), f"{tag}/VA": np.degrees(np.angle(v)),
            f"{tag}/IM": np.abs(i), f"{tag}/IA": np.degrees(np.angle(i))}
    np.savetxt(tmp / "rec.csv", np.column_stack(list(cols.values())), delimiter=",",
               header=",".join(cols), comments="", fmt="%.10g")
    (tmp / "fleet.toml").write_text(
        '[case]\nraw = "case.raw"\ndyr = "case.dyr"\n\n[measurement]\nfile = "rec.csv"\n'
        'location = "terminal"\nvoltage_unit = "pu"\ncurrent_unit = "pu"\nangle_unit = "deg"\n'
        's_base_mva = 100.0\nmin_segment_s = 5.0\n\n[playback]\nmodel = "dyr"\n\n[[unit]]\nname = "B8_VSG"\nbus = 8\n'
        + "columns = {" + ", ".join(f'{k} = "{tag}/{x}"' for k, x in (("frequency", "F"), ("v_mag", "VM"),
                                                                        ("v_ang", "VA"), ("i_mag", "IM"),
                                                                        ("i_ang", "IA")))
        + ', time = "time_s"}\n')
    (e,) = jd.fleet(tmp / "fleet.toml", tmp / "out", stream=io.StringIO())
    lo, hi = e["H_ci95"]
    return row("fleet", event if model == "REGCV1" else f"{event} ({model})", truth, e["H_s"], lo, hi,
               e["verdict"], list(e["reasons"].values()), d=e["D"], d_ci=e["D_ci95"],
               H_record_s=e["H_reference_s"])


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
    ap.add_argument("--methods", nargs="*", default=["estimator", "playback", "fleet"])
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
        if "fleet" in args.methods:
            with tempfile.TemporaryDirectory() as d:
                rows.append(by_fleet(event, t, v, i, f, meta, truth, Path(d)))
    if "fleet" in args.methods and "line_trip" in args.events:   # REGCV2, on its line trip
        meta2 = json.loads((HERE / "regcv2" / "truth.json").read_text())
        t, v, i, f = read("line_trip", meta2["tag"], HERE / "regcv2")
        v, i, f = noisy(t, v, i, f, seed=zlib.crc32(b"gfm/regcv2/line_trip"))
        truth2 = {"H_s": meta2["H_s"], "D_pu": meta2["D_pu"], "omega_s": 2 * np.pi * meta2["f0_hz"]}
        with tempfile.TemporaryDirectory() as d:
            rows.append(by_fleet("line_trip", t, v, i, f, meta2, truth2, Path(d)))
    if "estimator" in args.methods:
        rows = by_estimator(units, truth) + rows
    path = HERE / "results.json"
    if path.exists():  # keep the rows of the methods and events not rerun
        done = {(r["method"], r["event"]) for r in rows}
        rows = [r for r in json.loads(path.read_text())["units"]
                if (r["method"], r["event"]) not in done] + rows
        rows.sort(key=lambda r: (("estimator", "playback", "fleet").index(r["method"]),
                                 EVENTS.index(r["event"].split(" ")[0])))
    out = {"noise": {"tve_percent": TVE_PERCENT, "f_noise_hz": F_NOISE_HZ},
           "x_internal_pu": args.x_internal if args.x_internal is not None else meta["constants"]["xs"],
           "tolerance": TOLERANCE, "units": rows, "wall_s": time.perf_counter() - t0}
    path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"[gfm] wrote results.json in {out['wall_s']:.0f} s", file=sys.stderr)


if __name__ == "__main__":
    main()
