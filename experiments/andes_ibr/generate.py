"""ANDES 2.0.0 reference recordings of an inverter-based plant (REGCA1 + REECA1) for
``tests/models/test_ibr_andes.py``.

Run with the separate ANDES venv (ANDES is GPL-3: it is used here as an external simulator only,
never imported by ``src/`` or ``tests/``):

    /work/andes-venv/bin/python experiments/andes_ibr/generate.py

Case: ANDES's ``ieee14/ieee14_solar.xlsx`` (one PV plant at bus 8, MBASE = 100 MVA = system
base; its REPCA1 switched off, see below), with the plant's constants changed to a set under
which ANDES and the WECC specification agree (each choice below says why). Three events, 1 s
after the start:

* ``linetrip``: line 7-9 opened for good (the plant's bus moves in voltage and angle);
* ``loadstep``: a load of 0.3 + j0.1 pu (at 1 pu voltage, a shunt) switched on at bus 9 (a load
  switched off raised |V| so that the plant absorbed Q, and ANDES's REGCA1 floors the reactive
  current at Iolim at every voltage, not only above Volim as the specification's HVRCM does);
* ``fault``: a 0.1 s fault at bus 9 (xf = 0.05 pu) that takes the plant's terminal voltage below
  Vdip, so that the voltage-dip freeze and the Kqv injection act; the injection reaches its
  limit Iqh1 (Kqv (Vref0 - |V|) > 1.05 pu), so the recording holds Kqv only where |V| jumps;
* ``dip``: the same fault through xf = 0.3 pu, a shallower dip (|V| to 0.74 pu, below Vdip):
  the injection stays inside its limits for Kqv up to 1.3 times the bench's, so that
  ``experiments/andes_ibr_validate/run.py andes_ibr`` can find a planted Kqv x1.3.

Recorded at the plant's terminal (bus 8), 100 frames/s for 6 s: |V| [pu], its angle [rad], the
frequency deviation of bus 8 (ANDES's BusFreq output minus 1; unused by the plant without
REPCA1) [pu], and the plant's
P and Q out of the terminal [pu on MBASE]. Written: ``<event>.csv`` and ``plant.dyr`` (the
REGCA1 and REECA1 records in PSS/E CON order, for ``jaxdse.ibr_from_dyr``).
"""

from __future__ import annotations

import os
from pathlib import Path

import andes
import numpy as np

HERE = Path(__file__).parent
FRAME_S = 0.01
T_END_S = 6.0

# Bench constants, by PSS/E name. Changes from the ANDES case, and why:
REGCA1 = dict(Lvplsw=1, Tg=0.02, Rrpwr=10.0, Brkpt=0.9, Zerox=0.4, Lvpl1=1.22, Volim=1.2,
              Lvpnt1=0.8, Lvpnt0=0.4, Iolim=0.0, Tfltr=0.02, Khv=0.7, Iqrmax=999.0,
              Iqrmin=-999.0, Accel=0.7)
# REECA1: constant Q (PFFLAG = 0, VFLAG = 1, QFLAG = 0: Iq = Qext/Vm through Tiq). QFLAG = 1 was
# tried: with VFLAG = 0, Kvp = 2, Kvi = 20, ANDES's Q did not move on the line trip (0.0736 to
# 0.0740 pu while |V| fell by 1.2 %; a PI_V on Vref1 - Vm would raise it), and issue 44 records
# that ANDES's REECA1 with QFLAG = 1 does not start at rest; the voltage loops are compared with
# the SciPy block diagram instead (tests/models/test_ibr.py). Trv = 0: ANDES divides the power
# order by the unfiltered |V| where the specification divides by Vt_filt (with Trv = 0.02 s the
# fault's P differed by 0.60 % of MBASE RMS; tests/models/test_ibr_andes.py). Thld and Thld2 = 0 (the post-dip
# hold timers are not modelled in jaxdse); Vref0 = 1.03 written (ANDES does not read 0 as "the
# initial voltage"); VMAX/VMIN open (ANDES initialises its PI_Q at 0 when it is out of the path).
REECA1 = dict(IREG=0, PFFLAG=0, VFLAG=1, QFLAG=0, PFLAG=0, PQFLAG=0, Vdip=0.8, Vup=1.2, Trv=0.0,
              dbd1=-0.02, dbd2=0.02, Kqv=2.0, Iqh1=1.05, Iql1=-1.05, Vref0=1.03, Iqfrz=0.0,
              Thld=0.0, Thld2=0.0, Tp=0.02, QMax=0.6, QMin=-0.6, VMAX=999.0, VMIN=-999.0, Kqp=1.0,
              Kqi=0.1, Kvp=2.0, Kvi=20.0, Vref1=1.03, Tiq=0.02, dPmax=99.0, dPmin=-99.0,
              PMAX=1.0, PMIN=0.0, Imax=1.3, Tpord=0.02,
              Vq1=0.2, Iq1=1.3, Vq2=0.4, Iq2=1.3, Vq3=0.8, Iq3=1.3, Vq4=1.0, Iq4=1.3,
              Vp1=0.2, Ip1=1.3, Vp2=0.4, Ip2=1.3, Vp3=0.8, Ip3=1.3, Vp4=1.0, Ip4=1.3)
# REPCA1 is switched off (u = 0), found while building this bench:
# * ANDES 2.0.0's REPCA1 measures the far bus of its branch (bus 7 of line 8-7: its Vref and
#   Vcomp came out 1.0225, bus 7's voltage, with busr = 8 set or not), and the branch flow there;
# * its active power output does not reach REECA1's Pref (on the line trip its Pref lag output
#   moved by -0.010 pu through the droop while REECA1's Pref stayed at 0.35).
# So REPCA1 is compared with the SciPy block diagram only (tests/models/test_ibr.py).

EVENTS = {
    "linetrip": [("Toggle", dict(model="Line", dev="Line_11", t=1.0))],
    "loadstep": [("Shunt", dict(idx="Shunt_step", bus=9, Vn=138.0, g=0.3, b=-0.1, u=0)),
                 ("Toggle", dict(model="Shunt", dev="Shunt_step", t=1.0))],
    "fault": [("Fault", dict(bus=9, tf=1.0, tc=1.1, xf=0.05, rf=0.0))],
    "dip": [("Fault", dict(bus=9, tf=1.0, tc=1.1, xf=0.3, rf=0.0))],
}


def _set(ss, model: str, values: dict):
    mdl = getattr(ss, model)
    idx = mdl.idx.v[0]
    for name, value in values.items():
        if name == "IREG":
            continue
        if name in mdl.params:
            mdl.set(name, idx, float(value), base="device")
        else:
            raise KeyError(f"{model}.{name} not in ANDES's parameters")


def simulate(event: str):
    case = os.path.join(os.path.dirname(andes.__file__), "cases/ieee14/ieee14_solar.xlsx")
    ss = andes.load(case, setup=False, no_output=True, default_config=True)
    for model, kw in EVENTS[event]:
        ss.add(model, kw)
    ss.setup()
    ss.REPCA1.set("u", ss.REPCA1.idx.v[0], 0, base="device")    # see REPCA1 above
    for idx in list(ss.Toggle.idx.v):
        if idx in ("Toggler_1", "Toggler_2"):      # the case's own line 1-2 switching: off
            ss.Toggle.alter("t", idx, 1e3)
    _set(ss, "REGCA1", REGCA1)
    _set(ss, "REECA1", REECA1)
    ss.PFlow.run()
    ss.TDS.config.tf = T_END_S
    ss.TDS.config.tstep = FRAME_S / 4
    ss.TDS.config.no_tqdm = True
    ss.TDS.run()
    t = np.asarray(ss.dae.ts.t)
    bus = ss.Bus.idx2uid(8)
    v = ss.dae.ts.y[:, ss.Bus.v.a[bus]]
    a = ss.dae.ts.y[:, ss.Bus.a.a[bus]]
    bf = [k for k, b in enumerate(ss.BusFreq.bus.v) if b == 8][0]
    f = ss.dae.ts.y[:, ss.BusFreq.f.a[bf]]
    p = ss.dae.ts.y[:, ss.REGCA1.Pe.a[0]]
    q = ss.dae.ts.y[:, ss.REGCA1.Qe.a[0]]
    grid = np.round(np.arange(0.0, T_END_S + 1e-9, FRAME_S), 6)
    # the value at each frame: the last output at or before it (ANDES writes both sides of an
    # event at the same time; the frame after the switching takes the post-switching one)
    k = np.searchsorted(t, grid + 1e-9, side="right") - 1
    return grid, v[k], a[k], f[k] - 1.0, p[k], q[k]


def dyr_text() -> str:
    def fmt(x):
        return f"'{x}'" if isinstance(x, str) else f"{x:g}"
    lines = []
    for name, rec in (("REGCA1", REGCA1), ("REECA1", REECA1)):
        lines.append(f"8 '{name}' '1' " + " ".join(fmt(v) for v in rec.values()) + " /")
    return "\n".join(lines) + "\n"


def main():
    andes.config_logger(stream_level=40)
    (HERE / "plant.dyr").write_text(dyr_text())
    for event in EVENTS:
        t, v, a, f, p, q = simulate(event)
        data = np.column_stack([t, v, a, f, p, q])
        np.savetxt(HERE / f"{event}.csv", data, delimiter=",", fmt="%.9g",
                   header="t_s,v_pu,angle_rad,freq_dev_pu,p_pu,q_pu", comments="")
        print(event, f"|V| {v.min():.3f}..{v.max():.3f}  P {p.min():.4f}..{p.max():.4f}  "
              f"Q {q.min():.4f}..{q.max():.4f}  f-1 {f.min():.2e}..{f.max():.2e}")


if __name__ == "__main__":
    main()
