"""Type-3 wind mechanics (WTTQA1, WTPTA1, WTARA1, WTDTA1) carried by an :class:`IbrUnit`: the
steady state holds the power flow, a SciPy integration of the block diagrams written here from the
WECC Type 3 Phase II specification (not from the modules) matches a voltage step and a change of
the wind's power, and the Texas 7k records read into the models."""

from pathlib import Path

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxdse._dyr.ibr_unit import IbrUnit
from jaxdse._dyr.unit import UnitInputs
from jaxdse._models.ibr import (
    REECA1,
    REGCA1,
    WTARA1,
    WTDTA1,
    WTPTA1,
    WTTQA1,
    ibr_from_dyr,
    record_readings,
)

V0, ANG, P0, Q0 = 1.01, 0.25, 0.5, 0.1
G = dict(tg=0.02, trv=0.02, tp=0.05, tiq=0.02, tpord=0.05,                       # REGCA1, REECA1
         kpp=2.0, kip=0.5, tpt=0.05, twref=10.0,                                   # WTTQA1
         tab_p=(0.2, 0.4, 0.6, 0.8), tab_w=(0.7, 0.8, 0.9, 1.1),
         kiw=10.0, kpw=50.0, kic=5.0, kpc=2.0, kcc=0.1, tth=0.3, thmax=27.0, thmin=-10.0,  # WTPTA1
         rmax=10.0, rmin=-10.0,
         ka=0.007, th0=5.0,                                                        # WTARA1
         h=3.0, damp=0.5, htfrac=0.8, freq1=1.5, dshaft=1.0)                       # WTDTA1
WB = 2 * np.pi * 60.0


def _unit(drive=True, pflag=0):
    conv = REGCA1(t_g_s=G["tg"], lvplsw=0)
    elec = REECA1(qflag=0, vflag=0, pfflag=0, pflag=pflag, t_rv_s=G["trv"], t_p_s=G["tp"],
                  t_iq_s=G["tiq"], t_pord_s=G["tpord"], q_max_pu=1.0, q_min_pu=-1.0, p_max_pu=1.5,
                  vdip_pu=0.8, vup_pu=1.2)
    torque = WTTQA1(tflag=1, kpp=G["kpp"], kip=G["kip"], t_p_s=G["tpt"], t_wref_s=G["twref"],
                    te_max_pu=1.5, te_min_pu=0.0, table_p_pu=G["tab_p"], table_w_pu=G["tab_w"])
    pitch = WTPTA1(kiw=G["kiw"], kpw=G["kpw"], kic=G["kic"], kpc=G["kpc"], kcc=G["kcc"],
                   t_p_s=G["tth"], theta_max_deg=G["thmax"], theta_min_deg=G["thmin"],
                   r_theta_max_deg_s=G["rmax"], r_theta_min_deg_s=G["rmin"])
    aero = WTARA1(ka=G["ka"], theta0_deg=G["th0"])
    dt = WTDTA1(h_s=G["h"], damp=G["damp"], htfrac=G["htfrac"], freq1_hz=G["freq1"],
                dshaft=G["dshaft"]) if drive else None
    return IbrUnit(conv, elec, None, torque=torque, pitch=pitch, aero=aero, drive=dt)


def _inputs(v, f=0.0):
    return UnitInputs(jnp.asarray(v * np.cos(ANG)), jnp.asarray(v * np.sin(ANG)), jnp.asarray(f),
                      jnp.asarray(0.0))


def _start(unit):
    i = np.conj((P0 + 1j * Q0) / (V0 * np.exp(1j * ANG)))
    return unit.initial_state(_inputs(V0), i.real, i.imag)


@pytest.mark.parametrize("drive,pflag", [(True, 0), (True, 1), (False, 0)])
def test_wind_plant_starts_at_rest_and_stays_there(drive, pflag):
    unit = _unit(drive, pflag)
    y0, refs = _start(unit)
    u = _inputs(V0)
    assert float(jnp.max(jnp.abs(unit.vector_field(y0, u, refs)))) < 1e-12
    s = unit.signals(y0, u, refs)
    assert abs(float(s.p_pu) - P0) < 1e-12 and abs(float(s.q_pu) - Q0) < 1e-12
    # the rotor runs at the torque controller's table speed at P0, the pitch at WTARA1's Theta0
    assert abs(float(s.speed_pu) - np.interp(P0, G["tab_p"], G["tab_w"])) < 1e-12
    assert abs(float(s.p_mech_pu) - P0) < 1e-12
    assert unit.sizes == (3, 6, 0, 3, 3, 0, 3 if drive else 0)


def _spec_reference(v_of_t, dpm_of_t, t_end):
    """The chain integrated by solve_ivp from the block diagrams (WECC Type 3 Phase II; PSS/E
    REGCA1, REECA1 with QFLAG = PFFLAG = PFLAG = 0, WTTQA1 Tflag = 1, WTPTA1, WTARA1, WTDTA1), no
    limit reached. States: Ip, Iq, Vm, Iqlag, Pord, Pf, wref, xT, theta, xw, xc, wt, wg, twist."""
    g = G
    ht = g["htfrac"] * g["h"]
    hg = g["h"] - ht
    k_sh = 2 * ht * hg * (2 * np.pi * g["freq1"]) ** 2 / (g["h"] * WB)
    w0 = np.interp(P0, g["tab_p"], g["tab_w"])

    def rhs(t, x):
        ip, iq, vm, iql, pord, pf, wref, xt, th, xw, xc, wt, wg, tw = x
        v = v_of_t(t)
        pe = v * ip
        # torque controller: speed error -> PI -> torque; Pref = torque x generator speed
        tref = g["kpp"] * (wg - wref) + xt
        pref = tref * wg
        # electrical controls: constant Q (Iq = Qext/Vm, lagged), power order lag
        ipcmd, iqcmd = pord / vm, iql
        # pitch: speed PI on (wt - wref + Kcc eP), compensator PI on eP = Pord - Pord0
        ep = pord - P0
        ew = wt - wref + g["kcc"] * ep
        cmd = (g["kpw"] * ew + xw) + (g["kpc"] * ep + xc)
        dth = min(max((cmd - th) / g["tth"], g["rmin"]), g["rmax"])
        # aerodynamics and the two masses
        pm = P0 + dpm_of_t(t) - g["ka"] * th * (th - g["th0"])
        ts, td = k_sh * tw, g["dshaft"] * (wt - wg)
        return [(ipcmd - ip) / g["tg"], (iqcmd - iq) / g["tg"], (v - vm) / g["trv"],
                (Q0 / vm - iql) / g["tiq"], (pref - pord) / g["tpord"], (pe - pf) / g["tpt"],
                (np.interp(pf, g["tab_p"], g["tab_w"]) - wref) / g["twref"], g["kip"] * (wg - wref),
                dth, g["kiw"] * ew, g["kic"] * ep,
                (pm / wt - ts - td) / (2 * ht), (ts + td - pe / wg - g["damp"] * (wg - w0)) / (2 * hg),
                WB * (wt - wg)]

    x0 = [P0 / V0, Q0 / V0, V0, Q0 / V0, P0, P0, w0, P0 / w0, g["th0"], g["th0"], 0.0, w0, w0,
          (P0 / w0) / k_sh]
    ts = np.linspace(0.0, t_end, 301)
    sol = solve_ivp(rhs, (0.0, t_end), x0, t_eval=ts, method="LSODA", rtol=1e-10, atol=1e-12,
                    max_step=0.002)
    v = np.array([v_of_t(t) for t in ts])
    return ts, v * sol.y[0], sol.y[12], sol.y[8]


@eqx.filter_jit
def _simulate(unit, y0, refs, ts, v_step, pm_step):
    """diffrax over ``ts``: |V| and the wind's power (WTARA1's Pm0) stepped, each step (time,
    increment)."""
    def at(t):
        v = V0 + jnp.where(t >= v_step[0], v_step[1], 0.0)
        wind = refs.wind._replace(p_mech_pu=refs.wind.p_mech_pu + jnp.where(t >= pm_step[0], pm_step[1], 0.0))
        return _inputs(v), refs._replace(wind=wind)

    term = diffrax.ODETerm(lambda t, y, _: unit.vector_field(y, *at(t)))
    sol = diffrax.diffeqsolve(term, diffrax.Tsit5(), ts[0], ts[-1], 1e-3, y0,
                              saveat=diffrax.SaveAt(ts=ts), max_steps=200_000,
                              stepsize_controller=diffrax.PIDController(
                                  rtol=1e-10, atol=1e-12, jump_ts=jnp.stack([v_step[0], pm_step[0]])))
    sig = jax.vmap(lambda t, y: unit.signals(y, *at(t)))(ts, sol.ys)
    theta = jax.vmap(lambda y: unit.pitch.pitch(unit.split(y)["pitch"]))(sol.ys)
    return sig, theta


V_STEP = (0.3, -0.03)      # |V| down 3 % at 0.3 s
PM_STEP = (1.0, 0.05)      # the wind's power up by 0.05 pu at 1 s


def test_voltage_step_and_wind_change_match_the_scipy_block_diagrams():
    unit = _unit()
    y0, refs = _start(unit)
    t_end = 6.0
    ts, p_ref, wg_ref, th_ref = _spec_reference(lambda t: V0 + (V_STEP[1] if t >= V_STEP[0] else 0.0),
                                                lambda t: PM_STEP[1] if t >= PM_STEP[0] else 0.0, t_end)
    sig, theta = _simulate(unit, y0, refs, jnp.asarray(ts), jnp.asarray(V_STEP), jnp.asarray(PM_STEP))
    # not trivial: the rotor accelerates, the pitch moves, the torque controller raises P
    assert np.ptp(wg_ref) > 1e-3 and np.ptp(th_ref) > 0.1 and p_ref[-1] - p_ref[0] > 0.01
    away = np.all(np.abs(ts[:, None] - np.array([V_STEP[0], PM_STEP[0]])[None]) > 0.02, axis=1)
    np.testing.assert_allclose(np.asarray(sig.p_pu)[away], p_ref[away], atol=1e-6)
    np.testing.assert_allclose(np.asarray(sig.speed_pu)[away], wg_ref[away], atol=1e-6)
    np.testing.assert_allclose(np.asarray(theta)[away], th_ref[away], atol=1e-5)


DYR7K = Path("/work/shared/data/texas7k/Texas7k_20210309_Dynamics.dyr")


@pytest.mark.skipif(not DYR7K.exists(), reason="Texas 7k case not present")
def test_texas7k_wind_records_read_into_the_models():
    from jaxdse._dyr.records import ibr_model
    from jaxdse._io.psse import read_dyr

    dyr = read_dyr(DYR7K)
    m = ibr_model(dyr, 120493, "1")
    assert m.unit is not None and not m.missing
    assert m.models == {"converter": "REGCA1", "electrical": "REECA1", "pitch": "WTPTA1",
                        "torque": "WTTQA1", "plant": "REPCA1", "aero": "WTARA1"}
    tq, pt, ar = m.unit.torque, m.unit.pitch, m.unit.aero
    # 120493 'WTTQA1' 1  1  0.5  2.5  0.066667  60  1.1  0  0.2  0.58  0.4  0.72  0.72  0.866  0.86  1  0
    assert tq.tflag == 1 and float(tq.kpp) == 0.5 and float(tq.kip) == 2.5 and float(tq.t_wref_s) == 60
    np.testing.assert_allclose(np.asarray(tq.table_p_pu), [0.2, 0.4, 0.72, 0.86])
    np.testing.assert_allclose(np.asarray(tq.table_w_pu), [0.58, 0.72, 0.866, 1.0])
    # 120493 'WTPTA1' 1  25  150  30  0  0  0.3  27  0  10  -10 ; 'WTARA1' 1  0.007  0
    assert (float(pt.kiw), float(pt.kpw), float(pt.kic), float(pt.theta_max_deg)) == (25, 150, 30, 27)
    assert float(pt.r_theta_min_deg_s) == -10 and float(ar.ka) == pytest.approx(0.007)
    assert any("no drive train record" in n for n in m.notes)
    # the readings of values the models would otherwise refuse (REGCA1 Iqrmax = Iqrmin = 0)
    m2 = ibr_model(dyr, 120490, "1")
    assert m2.unit is not None and float(m2.unit.converter.iqrmax_pu_s) == 0.0
    assert sum("read as no rate limit" in n for n in m2.notes) == 2


@pytest.mark.parametrize("model,values,message", [
    ("WTTQA1", "1 0.5 2.5 0.07 60 1.1 0 0.2 0.58 0.4 0.72 0.72 0.866 0.86 1 50",
     "WTTQA1: TRATE = 50 MW: only TRATE = 0 (the machine base) is simulated"),
    ("WTTQA1", "3 0.5 2.5 0.07 60 1.1 0 0.2 0.58 0.4 0.72 0.72 0.866 0.86 1 0",
     "WTTQA1: Tflag must be 0, 1 or 2, got 3"),
    ("WTPTA1", "25 150 30 0 0 0.3 27 0 10 5", "WTPTA1: RThetamin must be < 0, got 5.0"),
    ("WTDTA1", "5 0 1.2 1.8 1.5", "WTDTA1: Htfrac must be < 1, got 1.2"),
    ("WTARA1", "0 0", "WTARA1: Ka must be > 0, got 0.0"),
])
def test_bad_wind_records_are_refused_in_psse_words(model, values, message):
    with pytest.raises(ValueError) as err:
        ibr_from_dyr(model, values.split())
    assert str(err.value) == message


def test_deadband_of_the_wrong_sign_is_read_as_its_magnitude():
    # Texas 7k 150531 'REPCA1' (dbd1 = 0.03, dbd2 = 0)
    rec = ("150531 0 0 0 1 1 0 0.066667 18 5 0 0.15 -1 0 0 0 999 -999 0.03 0 0.47 -0.47 0.1 0.05 "
           "0.25 0 0 999 -999 999 -999 0.1 20 0").split()
    plant = ibr_from_dyr("REPCA1", rec)
    assert float(plant.dbd1_pu) == pytest.approx(-0.03) and float(plant.dbd2_pu) == 0.0
    assert record_readings("REPCA1", rec) == [
        "REPCA1: dbd1 = 0.03 read as -0.03 (a deadband edge of the wrong sign: dbd1 <= 0 <= dbd2)"]


def test_tflag_2_and_a_table_out_of_order_start_at_rest():
    # Texas 7k 190149 'WTTQA1' (Tflag = 2) with 150502's table (P1 = 0.504 > P2 = 0.4)
    rec = "2 0.6 3 0.066667 30 1.2 0.08 0.504 0.58 0.4 0.74 0.76 0.869 0.905 1 0".split()
    torque = ibr_from_dyr("WTTQA1", rec)
    np.testing.assert_allclose(np.asarray(torque.table_p_pu), [0.4, 0.504, 0.76, 0.905])
    np.testing.assert_allclose(np.asarray(torque.table_w_pu), [0.74, 0.58, 0.869, 1.0])
    assert "read in order of P" in record_readings("WTTQA1", rec)[0]
    unit = _unit()
    unit = IbrUnit(unit.converter, unit.electrical, None, torque=torque, pitch=unit.pitch, aero=unit.aero,
                   drive=unit.drive)
    y0, refs = _start(unit)
    assert float(jnp.max(jnp.abs(unit.vector_field(y0, _inputs(V0), refs)))) < 1e-12
    # Tflag = 2: the torque ceiling is Pref0/wg, so more power asked by the plant raises it
    s = unit.signals(y0, _inputs(V0), refs)
    assert abs(float(s.p_ref_pu) - P0) < 1e-12


def test_converter_without_electrical_controls_holds_its_commands():
    unit = IbrUnit(REGCA1(t_g_s=0.02, lvplsw=0), None)
    y0, refs = _start(unit)
    assert unit.sizes == (3, 0, 0, 0, 0, 0, 0)
    assert float(jnp.max(jnp.abs(unit.vector_field(y0, _inputs(V0), refs)))) < 1e-12
    # the currents stay put when |V| steps: P and Q scale with |V|
    s = unit.signals(y0, _inputs(1.02 * V0), refs)
    assert abs(float(s.p_pu) - 1.02 * P0) < 1e-12 and abs(float(s.q_pu) - 1.02 * Q0) < 1e-12
    assert float(jnp.max(jnp.abs(unit.vector_field(y0, _inputs(1.02 * V0), refs)[:2]))) < 1e-12
