"""REGCA1 + REECA1 played back against ANDES 2.0.0 (the independent reference of STYLE 20).

The recordings (``experiments/andes_ibr/*.csv``, made by ``experiments/andes_ibr/generate.py``
with ANDES in its own venv) hold the PV plant's terminal voltage phasor and its P and Q on the
IEEE 14-bus case for a line trip, a load switched on and two 0.1 s faults that take |V| to 0.48
and 0.74 pu. The plant's records (``plant.dyr``, constant-Q electrical controls: QFLAG = 0) are read by
jaxdse's .dyr reader into an :class:`IbrUnit`, which ``play_back`` drives with the recorded
voltage (as a machine's records) and which must reproduce P and Q.

Measured (RMS over the 6 s, in % of MBASE): line trip P 0.0006, Q 0.0001; load switched on
P 0.0042, Q 0.0008; fault P 0.041, Q 0.143; the shallower dip (xf = 0.3 pu, |V| 0.74 pu, the
Kqv injection inside its limits) P 0.070, Q 0.268 (peaks away from the switching instants
0.011/0.001, 0.083/0.010, 0.032/0.152, 0.131/0.535), every RMS within the 0.5 % target. The
dip's peak is the tail of the switching interval's reconstruction (next point but one): 0.53 %
50 ms after each switching, decaying with Tiq (20 ms), 0.00 % at the end of the dip's 0.1 s,
where the injection Kqv (Vref0 - |V|) agrees exactly. Why the bench's REECA1 has Trv = 0:

* REEC_A divides the power order by the *filtered* voltage Vt_filt (Trv), so after the fault's
  clearing Ipcmd = Pord/Vm stays high while Vm recovers. ANDES 2.0.0 divides by the unfiltered
  |V|: with Trv = 0.02 s (the bench before 2026-11-29) jaxdse's P overshot to 0.44 pu for about
  30 ms where ANDES's stayed at 0.35, and the fault's P error was 0.60 % RMS; with jaxdse's
  divider changed to the unfiltered |V| (a trial, not kept) it fell to 0.020 %. jaxdse keeps the
  specification's Vt_filt (GridKit's REECA notes write it so too); the bench takes Trv = 0, under
  which the two agree (issue 44: "build the bench with parameters under which both agree").
* at each fault's two switching instants a 10 ms frame interval holds a jump of |V| (1.03 ->
  0.48 -> 1.10; 1.03 -> 0.74 -> 1.07) whose instant the playback reconstructs from the frames
  (the post-event curve extended back): within 50 ms of them the error is of that
  reconstruction, so the event-window bound is taken outside them.
* ANDES's REECA1 with QFLAG = 1 did not regulate (see the generator script): this bench runs
  with QFLAG = 0 and without a plant controller; REECA1's PI loops are compared with the SciPy
  block diagram in ``test_ibr.py``. REPCA1 is compared with ANDES on the bench of
  ``experiments/andes_ibr_validate`` (flags under which ANDES follows the specification: its
  generator script), driven by the recorded frequency (the last test here).
"""

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from jaxdse._dyr.ibr_unit import IbrUnit
from jaxdse._dyr.playback import TerminalSeries, play_back
from jaxdse._io.psse import read_dyr
from jaxdse._models.ibr import ibr_from_dyr

BENCH = Path(__file__).parents[2] / "experiments" / "andes_ibr"
EVENTS = ("linetrip", "loadstep", "fault", "dip")
TOLERANCES = {"linetrip": (0.001, 0.005), "loadstep": (0.001, 0.005), "fault": (0.002, 0.005),
              "dip": (0.004, 0.006)}
"""(RMS error of P and Q over the 6 s, largest error more than 50 ms from a switching instant)
[pu on MBASE], per event: within the 0.5 % target, with a margin over the measured errors
(module docstring)."""


def _unit():
    recs = {r.model: r for r in read_dyr(BENCH / "plant.dyr").records}
    return IbrUnit(ibr_from_dyr("REGCA1", recs["REGCA1"].constants),
                   ibr_from_dyr("REECA1", recs["REECA1"].constants))


@pytest.fixture(scope="module")
def played():
    """Each event through ``play_back`` (the machines' playback: per-frame Tsit5, a switching
    step kept a step, the recorded angle's slope as the frequency): one compiled program."""
    unit = _unit()
    out = {}
    for event in EVENTS:
        d = np.loadtxt(BENCH / f"{event}.csv", delimiter=",", skiprows=1)
        t, v, ang, _, p, q = d.T
        i = np.conj((p + 1j * q) / (v * np.exp(1j * ang)))
        r = play_back(unit, TerminalSeries(*(jnp.asarray(x) for x in (t, v, ang, i.real, i.imag))))
        out[event] = dict(t=t, v=v, p=p, q=q, sp=np.asarray(r.p_pu), sq=np.asarray(r.q_pu),
                          ok=bool(r.ok), omega=np.asarray(r.omega_pu))
    return out


@pytest.mark.parametrize("event", EVENTS)
def test_p_and_q_follow_andes(played, event):
    r = played[event]
    assert r["ok"]
    ep, eq = r["sp"] - r["p"], r["sq"] - r["q"]
    rms_p, rms_q = np.sqrt(np.mean(ep ** 2)), np.sqrt(np.mean(eq ** 2))
    rms_tol, peak_tol = TOLERANCES[event]
    assert rms_p < rms_tol and rms_q < rms_tol, (rms_p, rms_q)
    # away from the switching instants (the input ramps over a frame interval there)
    switching = np.flatnonzero(np.abs(np.diff(r["v"])) > 0.05)
    far = np.all(np.abs(r["t"][:, None] - r["t"][switching][None, :]) > 0.05, axis=1) \
        if switching.size else np.ones_like(r["t"], bool)
    peak = max(np.max(np.abs(ep[far])), np.max(np.abs(eq[far])))
    assert peak < peak_tol, peak
    # the events move the plant: the comparison is not of two constants
    assert max(np.ptp(r["p"]), np.ptp(r["q"])) > 0.0005


def test_fault_takes_the_plant_through_the_dip_logic(played):
    r = played["fault"]
    during = (r["t"] > 1.0 + 1e-6) & (r["t"] < 1.1 - 1e-6)
    assert np.all(r["v"][during] < 0.8)                     # below Vdip: REECA1's dip logic
    # ANDES and jaxdse both inject reactive current in the dip (Q up from 0.07 to > 0.5 pu)
    assert r["q"][during].max() > 0.5 and r["sq"][during].max() > 0.5
    assert np.all(np.isnan(r["omega"]))                      # no rotor: not applicable


REPCA1_BENCH = Path(__file__).parents[2] / "experiments" / "andes_ibr_validate"


@pytest.mark.parametrize("event", ("linetrip", "loadstep", "loadshed"))
def test_the_plant_controller_follows_andes_on_the_recorded_frequency(event):
    """REGCA1 + REECA1 + REPCA1 (frequency droop Ddn = Dup = 20, voltage control): its frequency
    input is the recording's frequency channel (ANDES's BusFreq, which REPCA1 reads: a filtered
    derivative that lags the angle's slope by 0.1-0.2 s after the event). Measured: P RMS
    0.092 / 0.048 / 0.051 % of MBASE (with the angle's slope instead: 0.25 / 0.21 / 0.25 %),
    Q 0.004 / 0.032 / 0.033 %; the largest P error more than 50 ms after the switching 0.71 %
    (the line trip's frequency spike, sampled at the frames)."""
    import gzip
    recs = {r.model: r for r in read_dyr(REPCA1_BENCH / "plant.dyr").records}
    unit = IbrUnit(*(ibr_from_dyr(m, recs[m].constants) for m in ("REGCA1", "REECA1", "REPCA1")))
    with gzip.open(REPCA1_BENCH / f"{event}.csv.gz", "rt") as fh:
        t, v, ang, f_dev, p, q = np.loadtxt(fh, delimiter=",", skiprows=1).T
    i = np.conj((p + 1j * q) / (v * np.exp(1j * ang)))
    r = play_back(unit, TerminalSeries(*(jnp.asarray(x) for x in (t, v, ang, i.real, i.imag, f_dev))))
    assert bool(r.ok)
    ep, eq = np.asarray(r.p_pu) - p, np.asarray(r.q_pu) - q
    assert np.sqrt(np.mean(ep ** 2)) < 0.0012 and np.sqrt(np.mean(eq ** 2)) < 0.0005
    assert np.max(np.abs(ep[np.abs(t - 1.0) > 0.05])) < 0.01
    assert np.ptp(p) > 0.015                    # the droop moves P (by 2-8 % of MBASE)


WIND_BENCH = Path(__file__).parents[2] / "experiments" / "andes_ibr_wind"


def test_the_type3_wind_chain_follows_andes():
    """REGCA1 + REECA1 + REPCA1 + WTTQA1 + WTPTA1 + WTARA1 + WTDTA1 (the bench's generator script
    states the constants under which ANDES follows the WECC specification): measured RMS P / Q
    0.0002 / 0.0013 (line trip), 0.0013 / 0.0117 (load step), 0.031 / 0.061 (fault, through the
    dip freeze, Iqmax, Ipmax and LVPL, the pitch off its floor), 0.018 / 0.062 % of MBASE (dip)."""
    import pandas as pd

    from jaxdse import ibr_model
    model = ibr_model(read_dyr(WIND_BENCH / "plant.dyr"), 8, "1")
    assert model.unit is not None and model.unit.drive is not None and model.unit.pitch is not None
    for event in ("linetrip", "loadstep", "fault", "dip"):
        d = pd.read_csv(WIND_BENCH / f"{event}.csv.gz")
        t, v, ang, f_dev, p, q = (d[c].to_numpy() for c in ("t_s", "v_pu", "angle_rad", "freq_dev_pu",
                                                               "p_pu", "q_pu"))
        i = np.conj((p + 1j * q) / (v * np.exp(1j * ang)))
        series = TerminalSeries(*(jnp.asarray(x) for x in (t, v, ang, i.real, i.imag, f_dev)))
        r = play_back(model.unit, series)
        assert bool(r.ok), event
        rms = [np.sqrt(np.mean((np.asarray(a) - b) ** 2)) for a, b in ((r.p_pu, p), (r.q_pu, q))]
        assert max(rms) < 0.001, (event, rms)
        assert max(np.ptp(p), np.ptp(q)) > 0.01, event      # the event moves the plant
