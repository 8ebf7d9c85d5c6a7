"""ANDES 2.0.0 reference recordings of a type-3 wind plant (REGCA1 + REECA1 + REPCA1 + WTDTA1 +
WTARA1 + WTPTA1 + WTTQA1) for ``run.py`` here (issue 44: the ANDES table of the wind chain).

Run with the separate ANDES venv (ANDES is GPL-3: an external simulator only, never imported by
``src/`` or ``tests/``):

    /work/andes-venv/bin/python experiments/andes_ibr_wind/generate.py [event ...]

Case: ANDES's ``ieee14/ieee14_wt3.xlsx`` (the type-3 wind plant at bus 8, MBASE = 100 MVA = the
system base, P0 = 0.35 pu; the case's own line 1-2 switching turned off). The case is built from
the xlsx and every constant below is set on the ANDES objects *before* its setup (ANDES caches
its flag switches at setup), not read from a .dyr: ANDES's .dyr reader fails on WTTQA1 records
(issue 44). ``plant.dyr`` is written from the same constants, in PSS/E CON/ICON order, for
``jaxdse.read_dyr`` / ``jaxdse.ibr_model``.

Events, 1 s after the start, recorded at the plant's terminal (bus 8), 100 frames/s for 8 s:

* ``linetrip``: line 7-9 opened for good (bus 8 moves in |V| and angle; REPCA1's voltage loop);
* ``loadstep``: 0.3 + j0.1 pu (a shunt at 1 pu voltage) switched on at bus 9 (frequency falls,
  |V| dips);
* ``fault``: a 0.1 s fault at bus 9 (xf = 0.05 pu): |V| at bus 8 falls to 0.37 pu (0.48 at the
  first frame), below Vdip: REECA1's voltage-dip freeze (Pord, the Tiq lag; the torque
  controller's integrator in the specification) and the Kqv injection act, Iqcmd reaches its
  ceiling Iqmax = Imax and, Q priority, Ipcmd its ceiling sqrt(Imax^2 - Iqcmd^2) for some ms,
  REGCA1's Ip sits on its LVPL for 88 ms; P collapses, the rotor speeds up by 1.4 %, the pitch
  leaves its floor (Thetamin = 0) through the speed PI and WTARA1 takes 1 % of MBASE off Pm;
* ``dip``: the same fault through xf = 0.3 pu (|V| 0.69..0.75 pu, below Vdip, no current limit).

``limits.json``: per event, the seconds each of these limits and freezes was held, taken from
ANDES's own 1 ms steps (a limit held between two frames counts).

Columns of ``<event>.csv.gz``: t_s, v_pu (|V| of bus 8), angle_rad, freq_dev_pu (ANDES's BusFreq
at bus 8 minus 1), p_pu, q_pu (out of the terminal, on MBASE), and the mechanics as truth:
wg_pu, wt_pu (generator and turbine speeds, WTDTA1), theta_deg (pitch, WTARA1), pm_pu
(aerodynamic power), pref_pu (the torque controller's Pref into REECA1), pord_pu (REECA1's Pord).
Each frame holds the last ANDES output at or before it (as ``experiments/andes_ibr``). ANDES's
step is 1 ms (TSTEP_S): at 2.5 ms (FRAME_S/4, the other benches) the dip's Q kept an offset of
0.09 % of MBASE after the event, about 0.06 % of it ANDES's own integration error (the same dip
at 0.25 ms steps and 1 ms frames: 0.0003 % against jaxdse; at 0.25 ms steps and 10 ms frames:
0.024 %, the frames' part, below).

Constants, by PSS/E name, and every choice made so that ANDES and the WECC specification agree
(judged by the specification; ANDES's departures are listed in issue 44 and were checked in its
source, ``andes/models/renewable/*.py``):

REGCA1, REECA1, REPCA1 (as ``experiments/andes_ibr`` and ``experiments/andes_ibr_validate``):

* REGCA1 Iolim = -1.3: ANDES floors Iq at Iolim at every voltage, the specification only above
  Volim (HVRCM); with REPCA1's voltage loop the plant must be able to absorb Q.
* REECA1 constant Q (PFFLAG = 0, VFLAG = 1, QFLAG = 0: Iq = Qext/Vm through Tiq; ANDES's REECA1
  with QFLAG = 1 does not start at rest), Trv = 0 (ANDES divides the power order by the
  unfiltered |V|, the specification by Vt_filt), Thld = Thld2 = 0 (the post-dip hold timers are
  not modelled in jaxdse), Vref0 = 1.03 written (ANDES does not read 0 as "the initial
  voltage"), VMAX/VMIN open.
* REECA1 QMax/QMin open (999): ANDES's constant-Q path (QFLAG = 0) divides its *unlimited* Q
  reference (PFsel) by |V| into the Tiq lag; the specification limits it to [QMin, QMax] first
  (as jaxdse). With QMax = 0.6 (the andes_ibr value) REPCA1's Qext passed 0.6 after the fault's
  clearing and ANDES's Q went to 0.79 pu where jaxdse's held at 0.6 |V|: 17 % of MBASE, 1.26 %
  RMS. Open, the limit is not reached in either.
* REECA1 Iqh1/Iql1 open (999): ANDES 2.0.0 declares them but never uses them (its Iqinj =
  Kqv db(Vref0 - Vm) is unlimited; only Iqmax limits Iqcmd), the specification clips the
  injection to [Iql1, Iqh1]. With Iqh1 = 1.05 the fault's first ms (|V| 0.37 pu: injection
  1.26 pu) differed by 1.4 % of MBASE in Q at the first frame (fault Q 0.094 % RMS; open:
  0.061 %). Open, Iqmax (= Imax, both) is the limit the fault reaches.
* REECA1 PFLAG = 0: ANDES's WTTQA1 overwrites REECA1's speed input with 1 + wg - f(Pm) ("this
  effectively sets PFLAG to 0", its docstring), so REECA1 multiplies Pref by nothing; with
  PFLAG = 0 the specification does the same. ANDES's REECA1 also filters Pref through a lag of
  its own (config ``tpfilt`` = 0.02 s) before Tpord, not in the specification; it is set to 0.
* REPCA1 as ``experiments/andes_ibr_validate`` (VCFlag = 0, Kc = 0: bus 8's own |V|; RefFlag = 1
  voltage control, deadbands 0, Vfrz = 0, Tft = 0) but Tfv = 0.02 s and Fflag = 0. Tfv: with
  0.05 s ANDES's Newton iteration fails after the fault's clearing (time step reduced to zero at
  1.153 s, as in experiments/andes_ibr_validate; REPCA1 off, or Kp = 0, Ki = 0, Vfrz = 0.7 or
  Tfv = 0.02 s each let it pass; Tfv changes no block's form). Fflag: with a torque
  controller the specification routes REPCA1's Pref into WTTQA1 as Pref0 (used by the power
  error of Tflag = 0 only; with Tflag = 1, speed control, not at all), while ANDES adds REPCA1's
  Pext to REECA1's Pref after the torque controller. With Fflag = 0 REPCA1 sends no power
  change in either (ANDES's Pext = 0), so the plant's P comes from the torque controller alone.

WTTQA1 (torque controller):

* Kip = 0.6 kept, although ANDES's WTTQA1 does not freeze its integrator in a voltage dip (its
  docstring: "PI state freeze following voltage dip has not been implemented"; the specification
  and jaxdse freeze it): the integral path and its sign are then compared on every event, and
  the fault leaves a P offset of about 0.03 % of MBASE that decays with the speed loop (with
  Kip = 0 in both, a trial at Ka = 0.007: 0.0006 % at 2 s against 0.031 %; fault P RMS 0.013 %
  against 0.021 %).
* Tflag = 1 in plant.dyr (speed control, eT = wg - wref, as jaxdse and the WECC WTGTRQ_A write
  it; PowerWorld WebHelp "WTGTRQ_A and WTTQA1": 0 = torque control, 1 = speed control, 2 = Pref0
  as Temax); ANDES numbers its switch the other way (its Tflag = 0 is the speed error) and, issue 44,
  its torque loop has the opposite sign: ANDES's speed error is wref - wg. ANDES is given
  Tflag = 0 and Kpp, Kip with their signs reversed (-3, -0.6), so that its PI acts as the
  specification's Kpp = 3, Kip = 0.6 (its PI, PIAWHardLimit, is linear in the gains; the
  anti-windup acts on the integrator's value whatever their sign).
* the speed table flat at 1.0 pu (spd1..spd4 = 1): ANDES's pitch controller takes as its speed
  reference a constant (wref0, taken when WTPTA1 initialises, before WTTQA1 sets the speed;
  issue 44), the specification the torque controller's filtered table output; with a flat table
  both are 1.0 at every power, and WTDTA1's w0 (ANDES's DAMP reference and default speed) is the
  rotor's initial speed.
* TRATE = 0 (MBASE; ANDES's Tn left empty: its RenGen's Sn = 100 MVA).

WTPTA1 (pitch controller):

* Kpc = Kic = Kcc = 0 (no power compensation): ANDES's compensator acts on Pord - Pref with
  Pref REECA1's present input (the torque controller's output, which the speed loop moves), the
  specification (and jaxdse) on Pord - Pord0; with the gains at 0 the pitch follows the speed
  error alone in both.
* Kpw = 0, Kiw = 25 (an integral speed loop): ANDES limits the PI's integrator *value* to
  [Thetamin, Thetamax] (anti-windup on the state), jaxdse blocks the integrator while the PI's
  output Kpw ew + x is beyond them; with Kpw = 0 the two are the same.
* Thetamin = 0, Theta0 = 0 (WTARA1): the pitch at rest on its floor (a turbine below rated
  wind); ANDES's WTARA1 mixes degrees and radians in theta0 (theta = rad(theta0) - theta0 +
  the pitch lag's output), which cancels only at theta0 = 0.

WTDTA1 (drive train): Freq1 = 1.5 Hz in plant.dyr (the specification's Hz); ANDES takes Freq1
in rad/s (its shaft stiffness uses Freq1^2 where the specification has (2 pi Freq1)^2), so it
is given 2 pi 1.5. DAMP = 0.5 acts on wg - w0 in both (w0 = 1 = the initial speed, above).

WTARA1: Ka = 1 pu/deg^2 (the case's own value; the typical 0.007 left the pitch's effect on Pm
at 1e-4 pu, so that the aerodynamics were not compared at all; with 1 the fault's 0.1 deg of
pitch takes 1 % of MBASE off Pm), Theta0 = 0 (above).

Residual, not a model difference: after each fault the playback's Q keeps an offset (0.044 % of
MBASE after ``fault``): REPCA1's voltage integrator, open loop under the imposed voltage,
integrates |V| across the two switching intervals, which the playback reconstructs from 10 ms
frames; the same fault recorded at 1 ms frames (a 3 s trial at Ka = 0.007) leaves 0.004 %, and
its largest Q error more than 50 ms after the clearing falls from 0.32 % to 0.20 %.
"""

from __future__ import annotations

import gzip
import json
import math
import os
import sys
from pathlib import Path

import andes
import numpy as np

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent / "andes_ibr"))
import generate as base  # noqa: E402  (experiments/andes_ibr: its events and setter)

FRAME_S = 0.01
T_END_S = 8.0
TSTEP_S = 0.001

# PSS/E CON/ICON order of each record (jaxdse.IBR_FIELDS); values for plant.dyr and ANDES.
REGCA1 = dict(Lvplsw=1, Tg=0.02, Rrpwr=10.0, Brkpt=0.9, Zerox=0.4, Lvpl1=1.22, Volim=1.2,
              Lvpnt1=0.8, Lvpnt0=0.4, Iolim=-1.3, Tfltr=0.02, Khv=0.7, Iqrmax=999.0,
              Iqrmin=-999.0, Accel=0.7)
REECA1 = dict(IREG=0, PFFLAG=0, VFLAG=1, QFLAG=0, PFLAG=0, PQFLAG=0, Vdip=0.8, Vup=1.2, Trv=0.0,
              dbd1=-0.02, dbd2=0.02, Kqv=2.0, Iqh1=999.0, Iql1=-999.0, Vref0=1.03, Iqfrz=0.0,
              Thld=0.0, Thld2=0.0, Tp=0.02, QMax=999.0, QMin=-999.0, VMAX=999.0, VMIN=-999.0, Kqp=1.0,
              Kqi=0.1, Kvp=2.0, Kvi=20.0, Vref1=1.03, Tiq=0.02, dPmax=99.0, dPmin=-99.0,
              PMAX=1.0, PMIN=0.0, Imax=1.3, Tpord=0.02,
              Vq1=0.2, Iq1=1.3, Vq2=0.4, Iq2=1.3, Vq3=0.8, Iq3=1.3, Vq4=1.0, Iq4=1.3,
              Vp1=0.2, Ip1=1.3, Vp2=0.4, Ip2=1.3, Vp3=0.8, Ip3=1.3, Vp4=1.0, Ip4=1.3)
REPCA1 = dict(IREG=0, FROM=0, TO=0, CKT="1", VCFlag=0, RefFlag=1, Fflag=0,
              Tfltr=0.02, Kp=2.0, Ki=4.0, Tft=0.0, Tfv=0.02, Vfrz=0.0, Rc=0.0, Xc=0.0, Kc=0.0,
              emax=999.0, emin=-999.0, dbd1=0.0, dbd2=0.0, Qmax=999.0, Qmin=-999.0,
              Kpg=1.0, Kig=2.0, Tp=0.02, fdbd1=-0.0002, fdbd2=0.0002, femax=999.0, femin=-999.0,
              Pmax=999.0, Pmin=-999.0, Tg=0.02, Ddn=20.0, Dup=20.0)
WTDTA1 = dict(H=4.0, DAMP=0.5, Htfrac=0.8, Freq1=1.5, Dshaft=1.0)
WTARA1 = dict(Ka=1.0, Theta0=0.0)
WTPTA1 = dict(Kiw=25.0, Kpw=0.0, Kic=0.0, Kpc=0.0, Kcc=0.0, Tp=0.3, Thetamax=27.0, Thetamin=0.0,
              RThetamax=10.0, RThetamin=-10.0)
WTTQA1 = dict(Tflag=1, Kpp=3.0, Kip=0.6, Tp=0.05, Twref=30.0, Temax=1.2, Temin=0.0,
              p1=0.2, spd1=1.0, p2=0.4, spd2=1.0, p3=0.6, spd3=1.0, p4=0.8, spd4=1.0, TRATE=0.0)
RECORDS = (("REGCA1", REGCA1), ("REECA1", REECA1), ("REPCA1", REPCA1), ("WTDTA1", WTDTA1),
           ("WTARA1", WTARA1), ("WTPTA1", WTPTA1), ("WTTQA1", WTTQA1))


def andes_values() -> dict[str, dict[str, float]]:
    """The constants under ANDES's parameter names, with its departures mapped (docstring)."""
    repca1 = {k: v for k, v in REPCA1.items() if k not in ("IREG", "FROM", "TO", "CKT", "Rc", "Xc")}
    return {
        "REGCA1": dict(REGCA1),
        "REECA1": {k: v for k, v in REECA1.items() if k != "IREG"},
        "REPCA1": dict(repca1, PLflag=1.0),
        "WTDTA1": dict(WTDTA1, Freq1=2 * math.pi * WTDTA1["Freq1"], w0=1.0),     # rad/s
        "WTARA1": dict(Ka=WTARA1["Ka"], theta0=WTARA1["Theta0"]),
        "WTPTA1": dict(Kiw=WTPTA1["Kiw"], Kpw=WTPTA1["Kpw"], Kic=WTPTA1["Kic"], Kpc=WTPTA1["Kpc"],
                       Kcc=WTPTA1["Kcc"], Tp=WTPTA1["Tp"], thmax=WTPTA1["Thetamax"],
                       thmin=WTPTA1["Thetamin"], dthmax=WTPTA1["RThetamax"],
                       dthmin=WTPTA1["RThetamin"]),
        "WTTQA1": dict(Tflag=1.0 - WTTQA1["Tflag"], Kpp=-WTTQA1["Kpp"], Kip=-WTTQA1["Kip"],
                       Tp=WTTQA1["Tp"], Twref=WTTQA1["Twref"], Temax=WTTQA1["Temax"],
                       Temin=WTTQA1["Temin"],
                       **{f"p{k}": WTTQA1[f"p{k}"] for k in range(1, 5)},
                       **{f"sp{k}": WTTQA1[f"spd{k}"] for k in range(1, 5)}),
    }


EVENTS = base.EVENTS       # the PV bench's four events (line 7-9, the bus-9 shunt, the two faults)
_set = base._set           # a record's constants set on the ANDES device, by PSS/E name


def simulate(event: str, values: dict | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """One event's recording at the frames, and the limits and freezes ANDES held (seconds at its
    own steps) (``values``: ANDES's constants, default :func:`andes_values`)."""
    case = os.path.join(os.path.dirname(andes.__file__), "cases/ieee14/ieee14_wt3.xlsx")
    ss = andes.load(case, setup=False, no_output=True, default_config=True)
    for model, kw in EVENTS[event]:
        ss.add(model, kw)
    for model, vals in (values or andes_values()).items():   # before setup (flags are cached there)
        _set(ss, model, vals)
    ss.REECA1.pfilt.T.v = 0.0      # no Pref lag of ANDES's own (config tpfilt, read into Tf at setup)
    ss.setup()
    for idx in list(ss.Toggle.idx.v):
        if idx in ("Toggler_1", "Toggler_2"):          # the case's own line 1-2 switching: off
            ss.Toggle.set("t", idx, 1e3, base="device")
    assert ss.REPCA1.line.v[0] == "Line_20"
    ss.PFlow.run()
    ss.TDS.config.tf = T_END_S
    ss.TDS.config.tstep = TSTEP_S
    ss.TDS.config.no_tqdm = True
    ss.TDS.run()
    r, q = ss.REPCA1, ss.WTTQA1
    assert r.SWF.s0[0] == 1 and r.SWVC.s0[0] == 1 and r.SWRef.s1[0] == 1
    assert q.SWT.s0[0] == 1 and ss.REECA1.SWP.s0[0] == 1
    assert ss.dae.Tf[ss.REECA1.pfilt_y.a[0]] == 0.0
    t = np.asarray(ss.dae.ts.t)
    assert np.all(np.diff(t) >= 0)
    assert t[-1] > T_END_S - 1e-6, f"{event}: ANDES stopped at {t[-1]:.3f} s"
    y, x = ss.dae.ts.y, ss.dae.ts.x
    bus = ss.Bus.idx2uid(8)
    bf = [k for k, b in enumerate(ss.BusFreq.bus.v) if b == 8][0]
    cols = {
        "v_pu": y[:, ss.Bus.v.a[bus]], "angle_rad": y[:, ss.Bus.a.a[bus]],
        "freq_dev_pu": y[:, ss.BusFreq.f.a[bf]] - 1.0,
        "p_pu": y[:, ss.REGCA1.Pe.a[0]], "q_pu": y[:, ss.REGCA1.Qe.a[0]],
        "wg_pu": x[:, ss.WTDTA1.s2_y.a[0]], "wt_pu": x[:, ss.WTDTA1.s1_y.a[0]],
        "theta_deg": y[:, ss.WTARA1.theta.a[0]], "pm_pu": y[:, ss.WTDTA1.Pm.a[0]],
        "pref_pu": y[:, ss.REECA1.Pref.a[0]], "pord_pu": x[:, ss.REECA1.s5_y.a[0]],
    }
    dt = np.diff(t, append=t[-1])

    def seconds(mask):
        return round(float(np.sum(dt[mask])), 4)

    ree, reg, pt = ss.REECA1, ss.REGCA1, ss.WTPTA1
    iq_in, iq_max = y[:, ree.IqHL_x.a[0]], y[:, ree.Iqmax.a[0]]
    ip_in, ip_max = y[:, ree.IpHL_x.a[0]], y[:, ree.Ipmax.a[0]]
    theta = x[:, pt.LG_y.a[0]]
    limits = {       # seconds each limit or freeze held, at ANDES's own steps
        "REECA1 voltage-dip freeze (V < Vdip)": seconds(cols["v_pu"] < REECA1["Vdip"]),
        "REECA1 Iqcmd on its ceiling Iqmax": seconds(np.abs(iq_in) > iq_max + 1e-6),
        "REECA1 Ipcmd on its ceiling Ipmax": seconds(ip_in > ip_max + 1e-6),
        "REGCA1 Ip on LVPL": seconds(y[:, reg.LVPL_y.a[0]] < x[:, reg.S1_y.a[0]] - 1e-6),
        "WTPTA1 pitch off its floor Thetamin (> 0.001 deg)": seconds(theta > WTPTA1["Thetamin"] + 1e-3),
        "WTPTA1 pitch rate on RThetamax": seconds(np.gradient(theta, t) > WTPTA1["RThetamax"] - 1e-3),
    }
    limits["min |V| [pu]"] = round(float(cols["v_pu"].min()), 4)
    limits["max pitch [deg]"] = round(float(theta.max()), 4)
    grid = np.round(np.arange(0.0, T_END_S + 1e-9, FRAME_S), 6)
    # the value at each frame: the last output at or before it (ANDES writes both sides of an
    # event at the same time; the frame after the switching takes the post-switching one)
    k = np.searchsorted(t, grid + 1e-9, side="right") - 1
    return {"t_s": grid, **{c: v[k] for c, v in cols.items()}}, limits


def dyr_text() -> str:
    def fmt(x):
        return f"'{x}'" if isinstance(x, str) else f"{x:g}"
    return "".join(f"8 '{name}' '1' " + " ".join(fmt(v) for v in rec.values()) + " /\n"
                   for name, rec in RECORDS)


def main():
    andes.config_logger(stream_level=40)
    (HERE / "plant.dyr").write_text(dyr_text())
    path = HERE / "limits.json"
    reached = json.loads(path.read_text()) if path.exists() else {}
    for event in (sys.argv[1:] or EVENTS):
        d, reached[event] = simulate(event)
        path.write_text(json.dumps({e: reached[e] for e in EVENTS if e in reached}, indent=1) + "\n")
        with gzip.open(HERE / f"{event}.csv.gz", "wt") as fh:
            np.savetxt(fh, np.column_stack(list(d.values())), delimiter=",", fmt="%.9g",
                       header=",".join(d), comments="")
        print(event, " ".join(f"{c} {v.min():.4f}..{v.max():.4f}" for c, v in d.items()
                              if c not in ("t_s", "angle_rad")), flush=True)


if __name__ == "__main__":
    main()
