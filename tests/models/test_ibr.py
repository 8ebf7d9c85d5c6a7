"""REGCA1 + REECA1 + REPCA1 composed in an :class:`IbrUnit`: the three references of every
model (STYLE 20): the steady state holds the power flow, a SciPy integration of the block
diagram written here (not from the module) matches a voltage step and a frequency step, and a
deep voltage dip reaches the current limit and freezes the controls."""

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxdse._dyr.ibr_unit import IbrUnit
from jaxdse._dyr.unit import UnitInputs
from jaxdse._models.ibr import REECA1, REGCA1, REPCA1, ibr_from_dyr


def _inputs(v, ang=0.2, f=0.0):
    return UnitInputs(jnp.asarray(v * np.cos(ang)), jnp.asarray(v * np.sin(ang)), jnp.asarray(f),
                      jnp.asarray(0.0))


def _current(v, ang, p, q):
    i = np.conj((p + 1j * q) / (v * np.exp(1j * ang)))
    return i.real, i.imag


@pytest.mark.parametrize("pf,vf,qf,pq,plant,p,q", [
    (0, 1, 1, 0, True, 0.8, 0.25),
    (0, 1, 1, 1, True, 0.5, -0.3),
    (0, 0, 1, 0, False, 0.9, -0.1),
    (1, 1, 0, 0, False, 0.6, 0.2),
    (1, 0, 1, 1, True, 0.7, -0.2),
    (0, 1, 0, 0, True, 0.3, 0.0),
])
def test_initial_state_is_at_rest(pf, vf, qf, pq, plant, p, q):
    unit = IbrUnit(REGCA1(), REECA1(pfflag=pf, vflag=vf, qflag=qf, pqflag=pq),
                   REPCA1(refflag=1 - pq, vcflag=pf) if plant else None)
    v, ang = 1.03, -0.4
    u = _inputs(v, ang)
    i_re, i_im = _current(v, ang, p, q)
    y0, refs = unit.initial_state(u, i_re, i_im)
    assert y0.shape == (unit.n_states,)
    d = unit.vector_field(y0, u, refs)
    assert float(jnp.max(jnp.abs(d))) < 1e-12
    s = unit.signals(y0, u, refs)
    np.testing.assert_allclose([s.p_pu, s.q_pu, s.i_re_pu, s.i_im_pu], [p, q, i_re, i_im],
                               atol=1e-12)
    assert not bool(s.dip)


# --- the SciPy reference: REPCA1 (RefFlag 1, Fflag 1) -> REECA1 (QFLAG 1, VFLAG 1) -> REGCA1 ---

P = dict(tg=0.02, trv=0.02, tp=0.05, kqp=0.5, kqi=2.0, kvp=1.5, kvi=20.0, tpord=0.05,
         tfltr=0.02, kp=4.0, ki=8.0, tfv=0.1, tpp=0.1, kpg=0.4, kig=3.0, tgp=0.1, ddn=20.0,
         dup=10.0, fdb=0.0005)
V0, P0, Q0 = 1.01, 0.7, 0.1


def _models():
    conv = REGCA1(t_g_s=P["tg"], lvplsw=0)
    elec = REECA1(qflag=1, vflag=1, pfflag=0, t_rv_s=P["trv"], t_p_s=P["tp"], kqp=P["kqp"],
                  kqi=P["kqi"], kvp=P["kvp"], kvi=P["kvi"], t_pord_s=P["tpord"], q_max_pu=1.0,
                  q_min_pu=-1.0, v_max_pu=1.5, v_min_pu=0.5, dbd1_pu=-0.05, dbd2_pu=0.05,
                  vdip_pu=0.8, vup_pu=1.2)
    plant = REPCA1(refflag=1, vcflag=0, fflag=1, kc=0.0, t_fltr_s=P["tfltr"], kp=P["kp"],
                   ki=P["ki"], t_ft_s=0.0, t_fv_s=P["tfv"], t_p_s=P["tpp"], kpg=P["kpg"],
                   kig=P["kig"], t_g_s=P["tgp"], ddn_pu=P["ddn"], dup_pu=P["dup"],
                   fdbd1_pu=-P["fdb"], fdbd2_pu=P["fdb"], q_max_pu=1.0, q_min_pu=-1.0,
                   e_max_pu=1.0, e_min_pu=-1.0, fe_max_pu=1.0, fe_min_pu=-1.0)
    return IbrUnit(conv, elec, plant)


def _scipy_reference(v_of_t, f_of_t, t_end):
    """The block diagram integrated by solve_ivp: states [Ip, Iq, Vm, Pm, PI_Q, PI_V, Pord,
    Vf, PIq, LL, Pf, PIp, Plag] (REGCA1, REECA1, REPCA1), every limit far away."""
    g = P
    ip0, iq0 = P0 / V0, Q0 / V0

    def db(x, lo, hi):
        return x - hi if x > hi else (x - lo if x < lo else 0.0)

    def rhs(t, x):
        ip, iq, vm, pm, xq, xv, pord, vf, xqp, ll, pf, xp, plag = x
        v, f = v_of_t(t), f_of_t(t)
        p, q = v * ip, v * iq
        # plant controller: voltage loop and frequency droop
        e = V0 - vf
        qext = ll
        ef = db(-f, -g["fdb"], g["fdb"])
        ep = P0 - pf + g["ddn"] * min(ef, 0.0) + g["dup"] * max(ef, 0.0)
        pref = plag
        # electrical controls: PI_Q -> PI_V; power order
        eq = qext - q
        ev = (g["kqp"] * eq + xq) - vm
        iqcmd = g["kvp"] * ev + xv
        ipcmd = pord / vm
        return [(ipcmd - ip) / g["tg"], (iqcmd - iq) / g["tg"], (v - vm) / g["trv"],
                (p - pm) / g["tp"], g["kqi"] * eq, g["kvi"] * ev, (pref - pord) / g["tpord"],
                (v - vf) / g["tfltr"], g["ki"] * e, (g["kp"] * e + xqp - ll) / g["tfv"],
                (p - pf) / g["tpp"], g["kig"] * ep, (g["kpg"] * ep + xp - plag) / g["tgp"]]

    x0 = [ip0, iq0, V0, P0, V0, iq0, P0, V0, Q0, Q0, P0, P0, P0]
    ts = np.linspace(0.0, t_end, 201)
    sol = solve_ivp(rhs, (0.0, t_end), x0, t_eval=ts, method="LSODA", rtol=1e-10, atol=1e-12,
                    max_step=0.002)
    return ts, np.array([v_of_t(t) for t in ts]) * sol.y[0], np.array([v_of_t(t) for t in ts]) * sol.y[1]


@eqx.filter_jit
def _simulate(unit, y0, refs, ts, v_steps, f_steps):
    """diffrax over ``ts`` with |V| and the frequency deviation piecewise constant: each
    ``*_steps`` row is (time, value after it)."""
    def u_of(t):
        v = V0 + jnp.sum(jnp.where(t >= v_steps[:, 0], v_steps[:, 1], 0.0))
        f = jnp.sum(jnp.where(t >= f_steps[:, 0], f_steps[:, 1], 0.0))
        return _inputs(v, 0.3, f)

    term = diffrax.ODETerm(lambda t, y, _: unit.vector_field(y, u_of(t), refs))
    jumps = jnp.concatenate([v_steps[:, 0], f_steps[:, 0]])
    sol = diffrax.diffeqsolve(term, diffrax.Tsit5(), ts[0], ts[-1], 1e-3, y0,
                              saveat=diffrax.SaveAt(ts=ts), max_steps=100_000,
                              stepsize_controller=diffrax.PIDController(rtol=1e-9, atol=1e-11,
                                                                        jump_ts=jumps))
    sig = jax.vmap(lambda t, y: unit.signals(y, u_of(t), refs))(ts, sol.ys)
    return sol.ys, sig


def _start(unit):
    u = _inputs(V0, 0.3)
    i_re, i_im = _current(V0, 0.3, P0, Q0)
    return unit.initial_state(u, i_re, i_im)


# steps: (time, increment); increments sum (dV down 3 %, back up 1 %; frequency up 0.1 Hz at 60 Hz)
V_STEPS = np.array([[0.2, -0.03], [1.5, 0.01]])
F_STEPS = np.array([[0.5, 0.1 / 60.0], [2.0, -0.1 / 60.0]])


def test_voltage_and_frequency_steps_match_the_scipy_block_diagram():
    unit = _models()
    y0, refs = _start(unit)
    t_end = 3.0

    def v_of_t(t):
        return V0 + sum(dv for ts, dv in V_STEPS if t >= ts)

    def f_of_t(t):
        return sum(df for ts, df in F_STEPS if t >= ts)

    ts, p_ref, q_ref = _scipy_reference(v_of_t, f_of_t, t_end)
    _, sig = _simulate(unit, y0, refs, jnp.asarray(ts), jnp.asarray(V_STEPS), jnp.asarray(F_STEPS))
    # the responses are not trivial: Q moves by several % and P by the droop
    assert np.ptp(q_ref) > 0.05 and np.ptp(p_ref) > 0.01
    # the solvers' step positions differ at the switching instants: compare away from them
    away = np.all(np.abs(ts[:, None] - np.r_[V_STEPS[:, 0], F_STEPS[:, 0]][None]) > 0.02, axis=1)
    np.testing.assert_allclose(np.asarray(sig.p_pu)[away], p_ref[away], atol=2e-6)
    np.testing.assert_allclose(np.asarray(sig.q_pu)[away], q_ref[away], atol=2e-6)


def test_deep_dip_reaches_the_current_limit_and_freezes_the_controls():
    unit = _models()
    unit = eqx.tree_at(lambda m: (m.electrical.kqv, m.electrical.i_max_pu),
                       unit, (jnp.asarray(4.0, dtype=float), jnp.asarray(1.1, dtype=float)))
    y0, refs = _start(unit)
    ts = jnp.linspace(0.0, 0.6, 201)                              # the shapes of the step test
    v_steps = jnp.asarray([[0.2, 0.55 - V0], [0.4, V0 - 0.55]])   # |V| = 0.55 for 0.2 s
    ys, sig = _simulate(unit, y0, refs, ts, v_steps, jnp.zeros((2, 2)))
    t = np.asarray(ts)
    inside = (t > 0.2 + 1e-6) & (t < 0.4 - 1e-6)
    outside = (t < 0.2 - 1e-6) | (t > 0.4 + 1e-6)
    assert np.all(np.asarray(sig.dip)[inside]) and not np.any(np.asarray(sig.dip)[outside])
    # the injection Kqv (Vref0 - Vm - dbd2) asks 4 (1.01 - 0.55 - 0.05) = 1.64 > Imax: the
    # reactive command sits on Iqmax = Imax (Q priority) once Vm has fallen
    late = (t > 0.3) & (t < 0.4 - 1e-6)
    np.testing.assert_allclose(np.asarray(sig.iqcmd_pu)[late], 1.1, atol=1e-12)
    # ... and the active command on sqrt(Imax^2 - Iqcmd^2) = 0
    assert np.all(np.asarray(sig.ipcmd_pu)[late] <= 1e-6)
    # the PI integrators of REECA1 (states 3 + 2, 3 + 3) and the power order (3 + 5) are frozen
    sizes = unit.sizes
    frozen = [sizes[0] + 2, sizes[0] + 3, sizes[0] + 5]
    k0, k1 = np.searchsorted(t, 0.21), np.searchsorted(t, 0.4 - 1e-6) - 1
    np.testing.assert_allclose(np.asarray(ys)[k0:k1 + 1][:, frozen],
                               np.repeat(np.asarray(ys)[k0:k0 + 1][:, frozen], k1 - k0 + 1, 0),
                               atol=1e-12)
    # REPCA1's PI_P has no freeze (WECC REPC_A): it winds up on P0 - Pf during the dip, so after
    # the dip the power order rises to REECA1's PMAX (1.0) and P sits on it
    after = t > 0.5
    assert np.all(np.asarray(sig.p_pu)[after] <= 1.0 + 1e-6)
    assert float(sig.p_pu[-1]) > 0.99


def test_lvpl_and_lvacm_limit_the_active_current():
    conv = REGCA1(lvplsw=1, zerox_pu=0.4, brkpt_pu=0.9, lvpl1_pu=1.22, lvpnt0_pu=0.4, lvpnt1_pu=0.8)
    # LVPL: 0 below Zerox, linear to Lvpl1 at Brkpt, open above
    np.testing.assert_allclose(conv.lvpl(jnp.asarray([0.3, 0.65, 0.95])), [0.0, 0.61, 9999.0])
    # LVACM scales the injected Ip between Lvpnt0 and Lvpnt1
    state = jnp.asarray([0.9, 0.2, 0.95])
    ip, iq = conv.injection(state, jnp.asarray(0.6))
    np.testing.assert_allclose([ip, iq], [0.9 * 0.5, 0.2])
    # Ip above a fallen LVPL: the output is LVPL and the state moves down to it
    state = jnp.asarray([0.9, 0.2, 0.65])
    ip, _ = conv.injection(state, jnp.asarray(1.0))
    assert float(ip) == pytest.approx(0.61)
    d = conv.vector_field(state, jnp.asarray(1.0), jnp.asarray(1.0), jnp.asarray(0.2))
    assert float(d[0]) < 0


def test_hvrcm_absorbs_above_volim():
    conv = REGCA1(volim_pu=1.2, khv=0.7, iolim_pu=-1.3)
    _, iq = conv.injection(jnp.asarray([0.5, 0.1, 1.25]), jnp.asarray(1.25))
    assert float(iq) == pytest.approx(0.1 - 0.7 * 0.05)
    _, iq = conv.injection(jnp.asarray([0.5, 0.1, 1.25]), jnp.asarray(4.0))
    assert float(iq) == pytest.approx(-1.3)


DYR = """
 8 'REGCA1' '1' 1 0.02 10 0.9 0.4 1.22 1.2 0.8 0.4 -1.3 0.02 0.7 999 -999 0.7 /
 8 'REECA1' '1' 0 0 1 1 0 0 0.9 1.1 0.02 -0.05 0.05 2 1.05 -1.05 0 0 0 0 0.05 0.436 -0.436
   1.1 0.9 0 0.1 0 40 0 0.02 99 -99 1 0 1.7 0.02
   0.2 1.5 0.5 1.5 1 1.5 1.5 1.5  0.2 1.5 0.5 1.5 1 1.5 1.5 1.5 /
 8 'REPCA1' '1' 0 8 7 '1' 0 1 1 0.02 18 5 0 0.075 0 0 0 0 0.1 -0.1 0 0 0.436 -0.436 0.1 0.05
   0.25 0 0 999 -999 999 -999 0.1 20 0 /
"""


def test_dyr_records_read_into_the_models(tmp_path):
    from jaxdse._io.psse import read_dyr
    path = tmp_path / "ibr.dyr"
    path.write_text(DYR)
    recs = {r.model: r for r in read_dyr(path).records}
    conv = ibr_from_dyr("REGCA1", recs["REGCA1"].constants)
    elec = ibr_from_dyr("REECA1", recs["REECA1"].constants)
    plant = ibr_from_dyr("REPCA1", recs["REPCA1"].constants)
    assert conv.lvplsw == 1 and float(conv.iolim_pu) == -1.3 and float(conv.accel) == 0.7
    assert (elec.pfflag, elec.vflag, elec.qflag, elec.pflag, elec.pqflag) == (0, 1, 1, 0, 0)
    assert float(elec.kvi) == 40.0 and float(elec.i_max_pu) == 1.7
    np.testing.assert_allclose(elec.vdl1_v_pu, [0.2, 0.5, 1.0, 1.5])
    assert (plant.vcflag, plant.refflag, plant.fflag, plant.branch.tolist()) == (0, 1, 1, [8, 7])
    assert float(plant.kp) == 18.0 and float(plant.ddn_pu) == 20.0 and float(plant.t_g_s) == 0.1
    unit = IbrUnit(conv, elec, plant)
    u = _inputs(1.02)
    y0, refs = unit.initial_state(u, *_current(1.02, 0.2, 0.5, 0.1))
    assert float(jnp.max(jnp.abs(unit.vector_field(y0, u, refs)))) < 1e-12


@pytest.mark.parametrize("model,k,value,message", [
    ("REGCA1", 1, -0.02, "REGCA1: Tg must be >= 0, got -0.02"),
    ("REECA1", 2, 2, "REECA1: VFLAG must be 0 or 1, got 2"),
    ("REECA1", 7, 0.85, "REECA1: Vup (0.85) must be > Vdip (0.9)"),
    ("REPCA1", 23, -0.1, "REPCA1: Kig must be >= 0, got -0.1"),
    ("REPCA1", 4, 1.5, "REPCA1: ICON VCFlag must be an integer, got 1.5"),
])
def test_bad_records_are_refused_in_psse_words(tmp_path, model, k, value, message):
    from jaxdse._io.psse import read_dyr
    path = tmp_path / "ibr.dyr"
    path.write_text(DYR)
    rec = {r.model: r for r in read_dyr(path).records}[model]
    values = list(rec.constants)
    values[k] = value
    with pytest.raises(ValueError) as err:
        ibr_from_dyr(model, values)
    assert str(err.value) == message
    with pytest.raises(ValueError, match="expected 15 values"):
        ibr_from_dyr("REGCA1", [1.0] * 14)


def test_a_case_records_build_the_plant_or_say_why_not(tmp_path):
    from jaxdse._dyr.records import ibr_model, is_ibr
    from jaxdse._io.psse import read_dyr
    path = tmp_path / "case.dyr"
    regca1 = DYR.strip().splitlines()[0].replace("8 'REGCA1'", "9 'REGCA1'")
    path.write_text(DYR + "\n" + regca1 + "\n 9 'REECB1' '1' 0 0 1 1 0 0.9 1.1 0.02 -0.05 0.05 2 1.05"
                    " -1.05 0 0.05 0.436 -0.436 1.1 0.9 0 0.1 0 40 0.02 99 -99 1 0 1.7 0.02 /\n"
                    + DYR.strip().splitlines()[0].replace("8 'REGCA1'", "10 'REGCA1'") + "\n"
                    " 11 'GENCLS' '1' 3.0 0.0 /\n")
    dyr = read_dyr(path)
    full = ibr_model(dyr, 8, "1")
    assert full.missing == [] and isinstance(full.unit, IbrUnit)
    assert full.structure == ("REGCA1", "REECA1", "REPCA1")
    assert any("taken at the terminal" in n for n in full.notes)
    assert not any("Thld" in n for n in full.notes)
    b = ibr_model(dyr, 9, "1")   # REECB1 (PV) is simulated: the plant builds, without a plant controller
    assert b.missing == [] and b.structure[:3] == ("REGCA1", "REECB1", "-")
    alone = ibr_model(dyr, 10, "1")     # REGCA1 alone: its commands held (PSS/E's missing controller)
    assert alone.unit is not None and alone.unit.electrical is None
    assert any("Ipcmd and Iqcmd held at their initial values" in n for n in alone.notes)
    assert is_ibr(dyr, 8, "1") and not is_ibr(dyr, 11, "1")


def test_vdl_tables_with_trailing_zero_points():
    """A REECA1 record whose VDL tables use fewer than four points, the rest written (0, 0) (as
    the Texas 7k case writes them): the used points kept, the last held beyond them; a table of
    no used point is no limit; the plant's notes say so."""
    from jaxdse._models.ibr import VDL_OPEN_PU, vdl_points, vdl_trailing_zeros

    assert vdl_points([0.1, 0.9, 0, 0], [1.25, 1.25, 0, 0]) == ([0.1, 0.9, 1.9, 2.9], [1.25, 1.25, 1.25, 1.25])
    assert vdl_points([0, 0, 0, 0], [0, 0, 0, 0]) == ([0.0, 1.0, 2.0, 3.0], [VDL_OPEN_PU] * 4)
    assert vdl_points([0.2, 0.5, 1, 1.5], [1, 1, 1, 1]) == ([0.2, 0.5, 1.0, 1.5], [1.0, 1.0, 1.0, 1.0])
    rec = DYR.strip().splitlines()
    head = " ".join(" ".join(rec[1:3]).split())      # the REECA1 values before its VDL tables
    text = head + " 0.1 1.25 0.9 1.25 0 0 0 0  0 0 0 0 0 0 0 0 /"
    values = text.split()[3:-1]
    elec = ibr_from_dyr("REECA1", values)
    assert np.asarray(elec.vdl1_v_pu).tolist() == [0.1, 0.9, 1.9, 2.9]
    assert float(elec.vdl2_i_pu[0]) == VDL_OPEN_PU
    assert vdl_trailing_zeros(values) == ["VDL1 (2 points used)", "VDL2 (0 points used: no limit)"]
    with pytest.raises(ValueError, match="Vq1..Vq4 must increase"):
        ibr_from_dyr("REECA1", head.split()[3:] + "0.5 1 0.2 1 0 0 0 0 0 0 0 0 0 0 0 0".split())


def test_plants_on_different_buses_share_one_structure():
    """REPCA1's bus ICONs and REECA1's IREG are array leaves: two plants that differ only in their regulated bus
    and branch have one tree structure (one compiled program for a case's plants)."""
    rec = " ".join(DYR.strip().splitlines()[4:6]).split()[3:-1]
    other = list(rec)
    other[0], other[1], other[2] = "120489", "120489", "120490"
    a, b = ibr_from_dyr("REPCA1", rec), ibr_from_dyr("REPCA1", other)
    assert int(b.regulated_bus) == 120489 and b.branch.tolist() == [120489, 120490]
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    # REECA1's IREG too (as REECB1's)
    elec = " ".join(DYR.strip().splitlines()[1:4]).split()[3:-1]
    remote = ["120489", *elec[1:]]
    e_a, e_b = ibr_from_dyr("REECA1", elec), ibr_from_dyr("REECA1", remote)
    assert int(e_b.remote_bus) == 120489
    assert jax.tree_util.tree_structure(e_a) == jax.tree_util.tree_structure(e_b)
