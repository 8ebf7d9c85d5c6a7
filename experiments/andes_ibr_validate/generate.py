"""ANDES 2.0.0 recordings of an inverter-based plant with its plant controller ON (REGCA1 +
REECA1 + REPCA1) for ``jaxdse validate`` on IBR records (issue 44); ``run.py`` uses them.

Run with the separate ANDES venv (ANDES is GPL-3: an external simulator only, never imported by
``src/`` or ``tests/``):

    /work/andes-venv/bin/python experiments/andes_ibr_validate/generate.py

Case: ANDES's ``ieee14/ieee14_solar.xlsx`` (one PV plant at bus 8, MBASE = 100 MVA), the
REGCA1 and REECA1 constants of ``experiments/andes_ibr`` (see its notes; REECA1 Trv = 0) except
Iolim, and the case's REPCA1 switched ON with constants under which ANDES and the WECC REPC_A agree:

* VCFlag = 0 and Kc = 0: the controlled voltage is bus 8's own |V| (with VCFlag = 1 ANDES
  compensates with the monitored line's R and X when Rc and Xc are not given: bus 7's voltage);
* RefFlag = 1 (voltage control: Kp and Ki act when |V| moves), the voltage deadband 0
  (dbd1 = dbd2 = 0: the case's +-0.02 pu hides a line trip), Vfrz = 0 (ANDES holds the PI's
  *input* below Vfrz, the specification freezes the integrator), Tft = 0, Tfv = 0.05 s;
* Fflag = 1 and PLflag = 1 (ANDES's Pext is 0 with Fflag = 0: the droop never reaches REECA1's
  Pref, which is what experiments/andes_ibr saw; every flag is set before ANDES's setup, which
  caches its flag switches: set after it, the case's Fflag = 0 and VCFlag = 1 stay), the monitored line 8-7 (r = 0, bus 8 has no
  load: its flow is the plant's own P), Pmax/Pmin and femax/femin open (ANDES limits the
  *increment* by Pmin/Pmax), frequency deadband +-0.0002 pu, Ddn = Dup = 20;
* REGCA1 Iolim = -1.3 (ANDES floors Iq at Iolim at every voltage; the specification only above
  Volim: at 0 the plant could not absorb Q when the voltage loop asks for it).

Four events, 1 s after the start, recorded at bus 8, 100 frames/s for 6 s:

* ``linetrip``: line 7-9 opened (|V| moves: the voltage loop, Kp and Ki);
* ``loadstep``: 0.3 + j0.1 pu switched on at bus 9 (under-frequency: Dup);
* ``loadshed``: 0.3 + j0.1 pu switched off at bus 9 (over-frequency: Ddn);
* ``fault``: a 0.1 s fault at bus 9 (xf = 0.05 pu), |V| below Vdip: Kqv.

Written: ``<event>.csv.gz`` (t_s, v_pu, angle_rad, freq_dev_pu, p_pu, q_pu; P and Q out of the
terminal on MBASE; freq_dev_pu is bus 8's BusFreq, the frequency REPCA1 reads: a filtered
derivative of the angle that lags its slope by 0.1-0.2 s after an event, so a playback must take
the frequency channel, not the angle's slope: P RMS 0.05-0.09 % of MBASE against 0.21-0.25 %)
and ``plant.dyr`` (the three records in PSS/E CON order).
"""

from __future__ import annotations

import gzip
import os
import sys
from pathlib import Path

import andes
import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent / "andes_ibr"))
import generate as base  # noqa: E402

FRAME_S = 0.01
T_END_S = 6.0

REGCA1 = dict(base.REGCA1, Iolim=-1.3)
REECA1 = dict(base.REECA1)
REPCA1 = dict(IREG=0, FROM=0, TO=0, CKT="1", VCFlag=0, RefFlag=1, Fflag=1,
              Tfltr=0.02, Kp=2.0, Ki=4.0, Tft=0.0, Tfv=0.05, Vfrz=0.0, Rc=0.0, Xc=0.0, Kc=0.0,
              emax=999.0, emin=-999.0, dbd1=0.0, dbd2=0.0, Qmax=999.0, Qmin=-999.0,
              Kpg=1.0, Kig=2.0, Tp=0.02, fdbd1=-0.0002, fdbd2=0.0002, femax=999.0, femin=-999.0,
              Pmax=999.0, Pmin=-999.0, Tg=0.02, Ddn=20.0, Dup=20.0)
ANDES_ONLY = ("IREG", "FROM", "TO", "CKT", "Rc", "Xc")    # not set in ANDES (see above)

LOAD = dict(bus=9, Vn=138.0, g=0.3, b=-0.1)
EVENTS = {
    "linetrip": [("Toggle", dict(model="Line", dev="Line_11", t=1.0))],
    "loadstep": [("Shunt", dict(idx="Shunt_step", u=0, **LOAD)),
                 ("Toggle", dict(model="Shunt", dev="Shunt_step", t=1.0))],
    "loadshed": [("Shunt", dict(idx="Shunt_step", u=1, **LOAD)),
                 ("Toggle", dict(model="Shunt", dev="Shunt_step", t=1.0))],
    "fault": [("Fault", dict(bus=9, tf=1.0, tc=1.1, xf=0.05, rf=0.0))],
}


def _set(ss, model: str, values: dict, skip=()):
    mdl = getattr(ss, model)
    idx = mdl.idx.v[0]
    for name, value in values.items():
        if name in skip or name == "IREG":
            continue
        if name not in mdl.params:
            raise KeyError(f"{model}.{name} not in ANDES's parameters")
        mdl.set(name, idx, float(value), base="device")


def simulate(event: str):
    case = os.path.join(os.path.dirname(andes.__file__), "cases/ieee14/ieee14_solar.xlsx")
    ss = andes.load(case, setup=False, no_output=True, default_config=True)
    for model, kw in EVENTS[event]:
        ss.add(model, kw)
    # before setup: ANDES caches its flag switches (Switcher cache=True) at setup, so a flag
    # set after it is ignored (the case's Fflag = 0 and VCFlag = 1 would stay in force)
    _set(ss, "REGCA1", REGCA1)
    _set(ss, "REECA1", REECA1)
    _set(ss, "REPCA1", dict(REPCA1, PLflag=1.0), skip=ANDES_ONLY)
    ss.setup()
    for idx in list(ss.Toggle.idx.v):
        if idx in ("Toggler_1", "Toggler_2"):      # the case's own line 1-2 switching: off
            ss.Toggle.set("t", idx, 1e3, base="device")
    assert ss.REPCA1.line.v[0] == "Line_20" and ss.REPCA1.u.v[0] == 1
    ss.PFlow.run()
    ss.TDS.config.tf = T_END_S
    # h = 0.625 ms: ANDES's trapezoid applies a switching over its first step, so its integrators
    # see h/2 of the old voltage; at h = 2.5 ms REPCA1's PI (Ki = 4) kept a steady 3e-4 pu of Q
    # from it after the load step (6e-5 at 0.625 ms), which pulled the calibrated Kp 1.6 % low
    ss.TDS.config.tstep = FRAME_S / 16
    ss.TDS.config.no_tqdm = True
    ss.TDS.run()
    r = ss.REPCA1
    assert r.SWF.s1[0] == 1 and r.SWVC.s0[0] == 1 and r.SWPL.s1[0] == 1 and r.SWRef.s1[0] == 1
    t = np.asarray(ss.dae.ts.t)
    bus = ss.Bus.idx2uid(8)
    v = ss.dae.ts.y[:, ss.Bus.v.a[bus]]
    a = ss.dae.ts.y[:, ss.Bus.a.a[bus]]
    bf = [k for k, b in enumerate(ss.BusFreq.bus.v) if b == 8][0]
    f = ss.dae.ts.y[:, ss.BusFreq.f.a[bf]]
    p = ss.dae.ts.y[:, ss.REGCA1.Pe.a[0]]
    q = ss.dae.ts.y[:, ss.REGCA1.Qe.a[0]]
    grid = np.round(np.arange(0.0, T_END_S + 1e-9, FRAME_S), 6)
    k = np.searchsorted(t, grid + 1e-9, side="right") - 1     # as experiments/andes_ibr
    return grid, v[k], a[k], f[k] - 1.0, p[k], q[k]


def dyr_text() -> str:
    def fmt(x):
        return f"'{x}'" if isinstance(x, str) else f"{x:g}"
    return "".join(f"8 '{name}' '1' " + " ".join(fmt(v) for v in rec.values()) + " /\n"
                   for name, rec in (("REGCA1", REGCA1), ("REECA1", REECA1), ("REPCA1", REPCA1)))


def main():
    andes.config_logger(stream_level=40)
    (HERE / "plant.dyr").write_text(dyr_text())
    for event in (sys.argv[1:] or EVENTS):
        t, v, a, f, p, q = simulate(event)
        data = np.column_stack([t, v, a, f, p, q])
        with gzip.open(HERE / f"{event}.csv.gz", "wt") as fh:
            np.savetxt(fh, data, delimiter=",", fmt="%.9g",
                       header="t_s,v_pu,angle_rad,freq_dev_pu,p_pu,q_pu", comments="")
        print(event, f"|V| {v.min():.4f}..{v.max():.4f}  P {p.min():.4f}..{p.max():.4f}  "
              f"Q {q.min():.4f}..{q.max():.4f}  f-1 {f.min():.2e}..{f.max():.2e}", flush=True)


if __name__ == "__main__":
    main()
