"""ANDES 2.0.0 recordings of a grid-forming converter (REGCV1, a virtual synchronous generator) in
the IEEE 14-bus case, for ``experiments/andes_gfm/run.py`` and ``tests/models/test_regcv1.py``.

Run with the separate ANDES venv (ANDES is GPL-3: it is used here as an external simulator only,
never imported by ``src/`` or ``tests/``)::

    /work/andes-venv/bin/python experiments/andes_gfm/generate.py
    # REGCV2 (a check of jaxdse's REGCV2; the line trip only, 20 s):
    /work/andes-venv/bin/python experiments/andes_gfm/generate.py --model REGCV2 \
        --out experiments/andes_gfm/regcv2 --events line_trip --t-end 20

Case: the ANDES bench's ieee14 (``experiments/andes_bench/data/ieee14/ieee14.raw`` and its .dyr,
which that bench wrote from ANDES's ``ieee14_full.xlsx``) with the synchronous unit at bus 8
(GENROU + TGOV1 + ESST3A, P = 0.35 pu) left out and a REGCV1 put in its place on the same
static generator (so the power flow is unchanged). ANDES's .dyr reader has no REGCV1 record;
the converter is added through ANDES's Python API. Its constants (``REGCV1`` below) are
ANDES's defaults except M, D and xs; kw = kv = 0, so the active-power reference is constant
(no droop) and the swing equation is ANDES's

    M d(dw)/dt = Pref - Pe - D dw,   d(delta)/dt = 2 pi fn dw,

with Pe the converter's terminal active power (system base = MBASE = 100 MVA).

Events, at ``T_EVENT`` = 10 s of a 40 s run (h = 1/240 s, recorded at 60 frames/s):

* ``line_trip``: the branch 7-9 opened for good (the converter's neighbourhood);
* ``load_step``: a constant-impedance load of 0.15 pu (at 1 pu voltage) switched on at bus 9;
* ``gen_trip``: the synchronous unit at bus 6 (GENROU, P = 0.30 pu) disconnected.

Written here, per event: ``<event>.csv.gz`` (columns as the ANDES bench's: ``time_s``,
``B8_VSG/F`` [Hz], ``/VM`` [pu], ``/VA`` [deg, wrapped], ``/IM`` [pu system base], ``/IA`` [deg],
current out of the converter) and ``<event>_truth.csv.gz`` (virtual rotor angle ``delta_rad``,
speed ``omega_pu``, ``pe_pu`` and ``pref_pu``), and ``truth.json`` (the REGCV1 constants with
their units, H = M/2, D, events, conventions).
"""

from __future__ import annotations

import gzip
import io
import json
from pathlib import Path

import andes
import numpy as np

HERE = Path(__file__).resolve().parent
BENCH = HERE.parent / "andes_bench" / "data" / "ieee14"
STEP_RATE = 240
FPS = 60
T_EVENT = 10.0
T_END = 40.0
BUS = 8
TAG = "B8_VSG"

# ANDES defaults except M, D, xs (meaning and units as ANDES's REGCV1Data states them)
REGCV1 = dict(Sn=100.0, fn=60.0, Tc=0.01, kw=0.0, kv=0.0, M=8.0, D=2.0, ra=0.0, xs=0.2,
              Kpvd=0.5, Kivd=0.02, Kpvq=0.5, Kivq=0.02, KpId=0.2, KiId=0.01, KpIq=0.2, KiIq=0.01)
UNITS = dict(Sn="MVA", fn="Hz", Tc="s (lag of the modulated voltage)",
             kw="pu power / pu speed (reciprocal of droop)", kv="pu voltage / pu Q",
             M="s (M = 2H)", D="pu power / pu speed", ra="pu on Sn", xs="pu on Sn",
             Kpvd="pu current / pu voltage", Kivd="pu current / (pu voltage s)",
             Kpvq="pu current / pu voltage", Kivq="pu current / (pu voltage s)",
             KpId="pu voltage / pu current", KiId="pu voltage / (pu current s)",
             KpIq="pu voltage / pu current", KiIq="pu voltage / (pu current s)")
LOAD_STEP_PU = 0.15
REGCV2_LAGS = dict(Tid=0.01, Tiq=0.01)
"""REGCV2 (``--model REGCV2``, a check of jaxdse's REGCV2, written to ``--out``): ANDES's
default current lags [s]; its other constants are REGCV1's without Tc and the inner PI."""


def _dyr_without_bus(bus: int) -> Path:
    """The bench's .dyr with the records of ``bus`` left out (written to a temporary file)."""
    records = [r for r in (BENCH / "ieee14.dyr").read_text().split("/") if r.strip()]
    kept = [r for r in records if int(r.split()[0]) != bus]
    out = Path("/tmp") / f"andes_gfm_ieee14_no{bus}.dyr"
    out.write_text("/".join(kept) + "/\n")
    return out


def _branch(ss, a: int, b: int) -> str:
    for idx, b1, b2 in zip(ss.Line.idx.v, ss.Line.bus1.v, ss.Line.bus2.v):
        if {int(b1), int(b2)} == {a, b}:
            return idx
    raise KeyError((a, b))


def simulate(event: str, model: str = "REGCV1", t_end: float = T_END):
    ss = andes.load(str(BENCH / "ieee14.raw"), addfile=str(_dyr_without_bus(BUS)), setup=False,
                    no_output=True, default_config=True)
    gen = [g for g, b in zip(ss.PV.idx.v, ss.PV.bus.v) if int(b) == BUS][0]
    params = dict(REGCV1)
    if model == "REGCV2":  # current lags instead of the inner PI and the modulator
        for k in ("Tc", "KpId", "KiId", "KpIq", "KiIq"):
            params.pop(k)
        params.update(REGCV2_LAGS)
    ss.add(model, dict(idx="VSG_8", bus=BUS, gen=gen, **params))
    detail = {}
    if event == "line_trip":
        line = _branch(ss, 7, 9)
        ss.add("Toggle", dict(model="Line", dev=line, t=T_EVENT))
        detail = {"branch": [7, 9], "andes_idx": line}
    elif event == "load_step":
        ss.add("Shunt", dict(idx="Shunt_step", bus=9, Vn=float(ss.Bus.Vn.v[ss.Bus.idx2uid(9)]),
                             g=LOAD_STEP_PU, b=0.0, u=0))
        ss.add("Toggle", dict(model="Shunt", dev="Shunt_step", t=T_EVENT))
        detail = {"bus": 9, "g_pu": LOAD_STEP_PU}
    elif event == "gen_trip":
        g6 = [g for g, b in zip(ss.GENROU.idx.v, ss.GENROU.bus.v) if int(b) == 6][0]
        ss.add("Toggle", dict(model="GENROU", dev=g6, t=T_EVENT))
        detail = {"bus": 6, "andes_idx": g6}
    ss.setup()
    if not ss.PFlow.run():
        raise RuntimeError("power flow did not converge")
    ss.TDS.config.tf = t_end
    ss.TDS.config.tstep = 1.0 / STEP_RATE
    ss.TDS.config.no_tqdm = True
    ss.TDS.config.criteria = 0
    if not ss.TDS.run():
        raise RuntimeError(f"{event}: ANDES TDS did not finish")
    t = np.asarray(ss.dae.ts.t)
    b = ss.Bus.idx2uid(BUS)
    r = getattr(ss, model)
    y, x = ss.dae.ts.y, ss.dae.ts.x
    # the value at each step: the last output at or before it (ANDES writes both sides of an
    # event at the same time; the step after the switching takes the post-switching one)
    steps = np.round(np.arange(0.0, t_end + 1e-9, 1.0 / STEP_RATE), 9)
    k = np.searchsorted(t, steps + 1e-9, side="right") - 1
    v, a = y[k, ss.Bus.v.a[b]], y[k, ss.Bus.a.a[b]]
    pe, qe = y[k, r.Pe.a[0]], y[k, r.Qe.a[0]]
    vc = v * np.exp(1j * a)
    cur = np.conj((pe + 1j * qe) / vc)
    f = REGCV1["fn"] + np.gradient(a, 1.0 / STEP_RATE) / (2 * np.pi)
    f[1:] = REGCV1["fn"] + (np.roll(a, -1) - np.roll(a, 1))[1:] / (2 / STEP_RATE) / (2 * np.pi)
    f[-1] = f[-2]
    # a central difference across the switching straddles it: the frame at the event keeps the
    # pre-event frequency (the angle steps at the event)
    ke = int(round(T_EVENT * STEP_RATE))
    f[ke] = f[ke - 1]
    frames = np.arange(0, steps.size, STEP_RATE // FPS)
    rec = {"time_s": steps[frames], f"{TAG}/F": f[frames], f"{TAG}/VM": v[frames],
           f"{TAG}/VA": np.rad2deg(np.angle(vc[frames])), f"{TAG}/IM": np.abs(cur[frames]),
           f"{TAG}/IA": np.rad2deg(np.angle(cur[frames]))}
    truth = {"time_s": steps[frames], "delta_rad": x[k, r.delta.a[0]][frames],
             "omega_pu": 1.0 + x[k, r.dw.a[0]][frames], "pe_pu": pe[frames],
             "pref_pu": y[k, r.Pref2.a[0]][frames]}
    pref0 = float(r.Pref.v[0])
    q0 = float(r.Qref.v[0])
    return rec, truth, detail, pref0, q0, float(r.vref.v[0])


def _write_gz(path: Path, cols: dict):
    names = list(cols)
    data = np.column_stack([cols[n] for n in names])
    buf = io.StringIO()
    np.savetxt(buf, data, delimiter=",", fmt="%.10g", header=",".join(names), comments="")
    with open(path, "wb") as fh, gzip.GzipFile(fileobj=fh, mode="wb", mtime=0) as gz:
        gz.write(buf.getvalue().encode())


def main():
    import argparse
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default="REGCV1", choices=("REGCV1", "REGCV2"))
    ap.add_argument("--out", type=Path, default=HERE)
    ap.add_argument("--events", nargs="*", default=["line_trip", "load_step", "gen_trip"])
    ap.add_argument("--t-end", type=float, default=T_END)
    args = ap.parse_args()
    andes.config_logger(stream_level=40)
    args.out.mkdir(parents=True, exist_ok=True)
    truth = {"generator": "experiments/andes_gfm/generate.py", "andes_version": andes.__version__,
             "case": "ANDES bench ieee14 (.raw/.dyr) without the bus-8 GENROU/TGOV1/ESST3A, "
                     f"{args.model} at bus 8 on the same static generator",
             "system_base_mva": 100.0, "f0_hz": REGCV1["fn"], "tag": TAG, "bus": BUS,
             "model": "REGCV1", "constants": REGCV1, "units": UNITS,
             "H_s": REGCV1["M"] / 2, "D_pu": REGCV1["D"],
             "swing_equation": "M d(dw)/dt = Pref - kw dw - Pe - D dw, d(delta)/dt = 2 pi fn dw "
                               "(powers on Sn, no 1/omega factor)",
             "conventions": {"F": "bus frequency [Hz] = f0 + (d theta/dt)/(2 pi), central difference "
                                  "over +-1 step (the event frame keeps the pre-event value)",
                             "IM_IA": "converter output current conj((Pe + jQe)/V), out of the "
                                      "converter, system base"},
             "integration": {"step_s": 1.0 / STEP_RATE, "fps": FPS, "t_event_s": T_EVENT,
                             "t_end_s": T_END},
             "events": {}}
    if args.model == "REGCV2":
        truth["model"] = "REGCV2"
        truth["constants"] = {**{k: v for k, v in REGCV1.items()
                                 if k not in ("Tc", "KpId", "KiId", "KpIq", "KiIq")}, **REGCV2_LAGS}
    truth["integration"]["t_end_s"] = args.t_end
    for event in args.events:
        rec, tr, detail, pref0, q0, vref = simulate(event, args.model, args.t_end)
        _write_gz(args.out / f"{event}.csv.gz", rec)
        _write_gz(args.out / f"{event}_truth.csv.gz", tr)
        truth["events"][event] = detail
        truth["initial"] = {"pref_pu": pref0, "qref_pu": q0, "vref_pu": vref}
        w = tr["omega_pu"]
        print(event, f"omega {w.min():.5f}..{w.max():.5f}  Pe {tr['pe_pu'].min():.4f}.."
                     f"{tr['pe_pu'].max():.4f}  |V| {rec[TAG + '/VM'].min():.4f}..{rec[TAG + '/VM'].max():.4f}")
    (args.out / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
