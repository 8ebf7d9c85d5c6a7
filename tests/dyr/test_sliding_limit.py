"""A PI that slides along its non-windup limit: REECA1's voltage PI during a fault (Tg = 0, QFLAG
= 1, Vdip below the dip, as a Texas 7k plant's records have it). Its integrator switches between
blocked and free at every trial step, so the adaptive step cannot pass the fault's frames; the
playback plays those intervals at a fixed step, says how many, and converges there (64 steps per
frame against 512)."""

import jax.numpy as jnp
import numpy as np
import pytest

from jaxdse._dyr.ibr_unit import IbrUnit
from jaxdse._dyr.playback import PlaybackSettings, TerminalSeries, play_back
from jaxdse._models.ibr import REECA1, REGCA1


def _unit():
    conv = REGCA1(t_g_s=0.0, rrpwr_pu_s=10.0, brkpt_pu=0.15, zerox_pu=0.06, lvpl1_pu=1.2,
                  lvpnt1_pu=0.1, lvpnt0_pu=-999.0, iolim_pu=-1.0, t_fltr_s=0.03, khv=1.0,
                  iqrmax_pu_s=106.0, iqrmin_pu_s=-106.0)
    elec = REECA1(pfflag=0, vflag=1, qflag=1, pflag=1, pqflag=0, vdip_pu=0.3, vup_pu=1.15,
                  t_rv_s=0.0, dbd1_pu=-0.05, dbd2_pu=0.05, kqv=0.0, iqh1_pu=1.05, iql1_pu=-1.05,
                  thld_s=0.05, t_p_s=0.0, q_max_pu=0.4, q_min_pu=-0.4, v_max_pu=1.1,
                  v_min_pu=0.9, kqp=0.1, kqi=1.0, kvp=1.5, kvi=55.0, t_iq_s=0.0, p_max_pu=1.0,
                  p_min_pu=0.0, i_max_pu=1.51, t_pord_s=0.066667,
                  vdl1_v_pu=[0.1, 0.8, 1.8, 2.8], vdl1_i_pu=[1.25] * 4,
                  vdl2_v_pu=[0.05, 0.2, 0.35, 0.7], vdl2_i_pu=[0.19, 0.6, 0.52, 0.99])
    return IbrUnit(conv, elec, None)


def _fault():
    """3 s at 30 frames/s: 0.495 pu for two frames from 1.5 s, then back above the start."""
    t = np.arange(91) / 30.0
    vm = np.where(t < 1.5, 1.0314, 1.0419 - 0.01 * (t - 1.6))
    vm[45:47] = 0.495
    va = 0.165 + np.where(t < 1.5, 0.0, 0.03 * np.sin(2 * np.pi * (t - 1.5)))
    s0 = 0.72 - 0.24j
    i0 = np.conj(s0 / (vm[0] * np.exp(1j * va[0]))) * np.ones_like(t)
    return TerminalSeries(*(jnp.asarray(a) for a in (t, vm, va, i0.real, i0.imag)))


@pytest.mark.slow
def test_the_fault_plays_back_at_the_fixed_step_and_converges():
    unit, series = _unit(), _fault()
    r = play_back(unit, series, PlaybackSettings())
    assert bool(r.ok) and 1 <= int(r.fixed_step_intervals) <= 10
    fine = play_back(unit, series, PlaybackSettings(fixed_substeps=512))
    assert bool(fine.ok) and int(fine.fixed_step_intervals) == int(r.fixed_step_intervals)
    # during the fault the plant injects reactive current at its limit; after it, the two agree
    assert float(np.max(r.q_pu[46:48])) > 0.3
    np.testing.assert_allclose(r.p_pu, fine.p_pu, atol=5e-4)   # 0.05 % of MBASE
    np.testing.assert_allclose(r.q_pu, fine.q_pu, atol=5e-4)   # 0.05 % of MBASE
