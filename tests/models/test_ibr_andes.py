"""REGCA1 + REECA1 played back against ANDES 2.0.0 (the independent reference of STYLE 20).

The recordings (``experiments/andes_ibr/*.csv``, made by ``experiments/andes_ibr/generate.py``
with ANDES in its own venv) hold the PV plant's terminal voltage phasor and its P and Q on the
IEEE 14-bus case for a line trip, a load switched on and a 0.1 s fault that takes |V| to 0.38
pu. The plant's records (``plant.dyr``, constant-Q electrical controls: QFLAG = 0) are read by
jaxdse's .dyr reader into an :class:`IbrUnit`, which ``play_back`` drives with the recorded
voltage (as a machine's records) and which must reproduce P and Q.

Measured (RMS over the 6 s, in % of MBASE): line trip P 0.009, Q 0.002; load switched on
P 0.034, Q 0.006; fault P 0.60, Q 0.12 (peaks away from the switching instants 0.08/0.01,
0.38/0.06, 1.41/0.57). The fault's P misses the 0.5 % target; the difference traces to the
block diagram:

* P after the fault: REEC_A divides the power order by the *filtered* voltage Vt_filt (Trv), so
  Ipcmd = Pord/Vm stays high while Vm recovers (0.02 s) and P overshoots to 0.44 pu for ~30 ms,
  where ANDES's P stays at 0.35. With jaxdse's divider changed to the unfiltered |V| (a trial,
  not kept) the fault's P error fell from 0.60 % to 0.020 % RMS (peak away from the switching
  1.41 % to 0.095 %): ANDES divides by the unfiltered voltage. jaxdse keeps the specification's
  Vt_filt (GridKit's REECA notes write it so too).
* at the fault's two switching instants a 10 ms frame interval holds a jump of |V| (1.03 -> 0.38
  -> 1.02) whose instant the playback reconstructs from the frames (the post-event curve
  extended back): within 50 ms of them the error is of that reconstruction, so the event-window
  bound is taken outside them.
* ANDES's REPCA1 regulates the far bus of its branch and its P output does not reach REECA1, and
  its REECA1 with QFLAG = 1 did not regulate (see the generator script): the bench runs without a
  plant controller and with QFLAG = 0; REPCA1 and the PI loops of REECA1 are compared with the
  SciPy block diagram in ``test_ibr.py``.
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
EVENTS = ("linetrip", "loadstep", "fault")
TOLERANCES = {"linetrip": (0.001, 0.005), "loadstep": (0.001, 0.005), "fault": (0.008, 0.02)}
"""(RMS error of P and Q over the 6 s, largest error more than 50 ms from a switching instant)
[pu on MBASE], per event: the 0.5 % target with margin for the line trip and the load; for
the fault the measured errors (module docstring) with a margin."""


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
