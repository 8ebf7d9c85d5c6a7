"""REECB1 (PV), REECCU1 (storage) and REGCB1 (converter with a voltage source behind ZSORCE), each
in a plant with REPCA1, against a plain SciPy integration of their block diagrams written here
from the WECC REEC_B / REEC_C / REGC_B specifications (scalar Python, not the modules): a voltage
step with a frequency ramp, and a deep voltage dip with the current limits, the VDL tables, the
converter's Imax and rate limits and the dip freezes active; a flat run stays flat (REECCU1's
state of charge moves by -P0 t / T and nothing else); the records read in PSS/E order.

Two plants, one compiled program each, shared by the three runs of each plant (one shape).
The largest differences are printed (``pytest -s``) and asserted below 1e-5 pu.
"""

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from jaxdse._dyr.ibr_unit import IbrUnit
from jaxdse._dyr.unit import UnitInputs
from jaxdse._models.ibr import REECB1, REECCU1, REGCA1, REGCB1, REPCA1, ibr_from_dyr

V0, P0, Q0, ANG = 1.01, 0.7, 0.1, 0.3
T_END = 3.0
TS = np.linspace(0.0, T_END, 301)
F_RATE = (0.1 / 60.0) / 0.5          # 0.1 Hz in 0.5 s [pu/s]

# (time, |V| increment) rows and (start, end, rate) frequency ramps: one shape for every run
RUNS = {
    "flat": (np.array([[0.2, 0.0], [0.4, 0.0]]), np.zeros((2, 3))),
    "step_ramp": (np.array([[0.2, -0.03], [1.5, 0.01]]),
                  np.array([[0.5, 1.0, F_RATE], [2.0, 2.5, -F_RATE]])),
    "dip": (np.array([[0.2, 0.5 - V0], [0.4, V0 - 0.5]]), np.zeros((2, 3))),
}

PLANT = dict(tfltr=0.02, kp=4.0, ki=8.0, tfv=0.1, tp=0.1, kpg=0.4, kig=3.0, tg=0.1, ddn=20.0,
             dup=10.0, fdb=0.0005)
ELEC = dict(trv=0.02, tp=0.05, kqp=0.5, kqi=2.0, kvp=1.5, kvi=20.0, tpord=0.05, qmax=1.0,
            qmin=-1.0, vmax=1.5, vmin=0.5, dbd=0.05, vdip=0.8, vup=1.2, kqv=4.0, iqh1=1.9,
            iql1=-1.9, dpmax=99.0, dpmin=-99.0, pmax=1.0)
PV = dict(ELEC, imax=1.1, pmin=0.0, pqflag=0)
BESS = dict(ELEC, imax=1.25, pmin=-0.8, pqflag=1, vq=[0.2, 0.5, 1.0, 1.5], iq=[0.9, 1.0, 1.2, 1.2],
            vp=[0.2, 0.5, 1.0, 1.5], ip=[0.5, 0.8, 1.2, 1.2], T=60.0, soc0=0.5, socmax=0.9,
            socmin=0.47)
GCA = dict(tg=0.02, rrpwr=10.0, lvpnt0=0.4, lvpnt1=0.8)
GCB = dict(tg=0.02, tfltr=0.02, iqrmax=20.0, iqrmin=-20.0, rrpwr=10.0, te=0.01, imax=1.2,
           z=0.01 + 0.25j)


def _plant_module():
    g = PLANT
    return REPCA1(refflag=1, vcflag=0, fflag=1, kc=0.0, t_fltr_s=g["tfltr"], kp=g["kp"], ki=g["ki"],
                  t_ft_s=0.0, t_fv_s=g["tfv"], t_p_s=g["tp"], kpg=g["kpg"], kig=g["kig"],
                  t_g_s=g["tg"], ddn_pu=g["ddn"], dup_pu=g["dup"], fdbd1_pu=-g["fdb"],
                  fdbd2_pu=g["fdb"], q_max_pu=1.0, q_min_pu=-1.0, e_max_pu=1.0, e_min_pu=-1.0,
                  fe_max_pu=1.0, fe_min_pu=-1.0)


def _elec_kwargs(e):
    return dict(qflag=1, vflag=1, pfflag=0, pqflag=e["pqflag"], t_rv_s=e["trv"], t_p_s=e["tp"],
                kqp=e["kqp"], kqi=e["kqi"], kvp=e["kvp"], kvi=e["kvi"], t_pord_s=e["tpord"],
                q_max_pu=e["qmax"], q_min_pu=e["qmin"], v_max_pu=e["vmax"], v_min_pu=e["vmin"],
                dbd1_pu=-e["dbd"], dbd2_pu=e["dbd"], vdip_pu=e["vdip"], vup_pu=e["vup"],
                kqv=e["kqv"], iqh1_pu=e["iqh1"], iql1_pu=e["iql1"], dp_max_pu_s=e["dpmax"],
                dp_min_pu_s=e["dpmin"], p_max_pu=e["pmax"], p_min_pu=e["pmin"], i_max_pu=e["imax"])


def _pv_unit():
    """REGCA1 (LVPL off, LVACM on) + REECB1 (Q priority) + REPCA1."""
    conv = REGCA1(lvplsw=0, t_g_s=GCA["tg"], rrpwr_pu_s=GCA["rrpwr"], lvpnt0_pu=GCA["lvpnt0"],
                  lvpnt1_pu=GCA["lvpnt1"])
    return IbrUnit(conv, REECB1(**_elec_kwargs(PV)), _plant_module())


def _bess_unit():
    """REGCB1 (RateFlag 1, Q priority, Te and ZSORCE) + REECCU1 (P priority, VDL tables, SOC) +
    REPCA1."""
    c = GCB
    conv = REGCB1(rateflag=1, pqflag=0, t_g_s=c["tg"], t_fltr_s=c["tfltr"], iqrmax_pu_s=c["iqrmax"],
                  iqrmin_pu_s=c["iqrmin"], rrpwr_pu_s=c["rrpwr"], t_e_s=c["te"], i_max_pu=c["imax"],
                  re_pu=c["z"].real, xe_pu=c["z"].imag)
    b = BESS
    elec = REECCU1(**_elec_kwargs(b), vdl1_v_pu=b["vq"], vdl1_i_pu=b["iq"], vdl2_v_pu=b["vp"],
                   vdl2_i_pu=b["ip"], t_soc_s=b["T"], soc_ini_pu=b["soc0"], soc_max_pu=b["socmax"],
                   soc_min_pu=b["socmin"])
    return IbrUnit(conv, elec, _plant_module())


def _inputs(v, f):
    return UnitInputs(v * jnp.cos(ANG), v * jnp.sin(ANG), f, jnp.zeros_like(v))


def _v_of(t, steps):
    return V0 + sum(dv for ts, dv in steps if t >= ts)


def _f_of(t, ramps):
    return sum(r * min(max(t - a, 0.0), b - a) for a, b, r in ramps)


@eqx.filter_jit
def _simulate(unit, ts, v_steps, f_ramps):
    i = jnp.conj((P0 + 1j * Q0) / (V0 * jnp.exp(1j * ANG)))
    y0, refs = unit.initial_state(_inputs(jnp.asarray(V0), jnp.asarray(0.0)), i.real, i.imag)

    def u_of(t):
        v = V0 + jnp.sum(jnp.where(t >= v_steps[:, 0], v_steps[:, 1], 0.0))
        f = jnp.sum(f_ramps[:, 2] * jnp.clip(t - f_ramps[:, 0], 0.0, f_ramps[:, 1] - f_ramps[:, 0]))
        return _inputs(v, f)

    term = diffrax.ODETerm(lambda t, y, _: unit.vector_field(y, u_of(t), refs))
    jumps = jnp.concatenate([v_steps[:, 0], f_ramps[:, 0], f_ramps[:, 1]])
    sol = diffrax.diffeqsolve(term, diffrax.Tsit5(), ts[0], ts[-1], 1e-3, y0,
                              saveat=diffrax.SaveAt(ts=ts), max_steps=200_000,
                              stepsize_controller=diffrax.PIDController(rtol=1e-10, atol=1e-12,
                                                                        jump_ts=jumps))
    sig = jax.vmap(lambda t, y: unit.signals(y, u_of(t), refs))(ts, sol.ys)
    return sol.ys, sig, y0


# --- the block diagrams, written out (WECC REPC_A -> REEC_B / REEC_C -> REGC_A / REGC_B) --------

def _db(x, lo, hi):
    return x - hi if x > hi else (x - lo if x < lo else 0.0)


def _clip(x, lo, hi):
    return min(max(x, lo), hi)


def _nw(raw, d, lo, hi):
    """A non-windup integrator: no motion beyond the limit its output sits on."""
    return 0.0 if (raw >= hi and d > 0) or (raw <= lo and d < 0) else d


def _reference(kind, steps, ramps):
    """P, Q out of the terminal (and the state of charge) at TS, by solve_ivp."""
    storage = kind == "bess"
    e = BESS if storage else PV
    g = PLANT
    ip0, iq0 = P0 / V0, Q0 / V0
    if storage:
        c = GCB
        z = c["z"]
        e0 = V0 + z * (ip0 - 1j * iq0)
        conv0 = [ip0 * V0, iq0, V0, e0.real, e0.imag]        # P (RateFlag 1), Iq, Vf, Ed, Eq
    else:
        c = GCA
        conv0 = [ip0, iq0]                                   # Ip, Iq
    elec0 = [V0, P0, V0, iq0, P0] + ([e["soc0"]] if storage else [])   # Vm, Pm, PI_Q, PI_V, Pord (SOC)
    plant0 = [V0, Q0, Q0, Q0, P0, P0, P0]                    # Vf, Qf, PI_Q, lag, Pf, PI_P, Pref lag
    nc, ne = len(conv0), len(elec0)

    def terminal(xc, v):
        """(P, Q, Ip, Iq) the converter delivers at |V| = v."""
        if storage:
            i = (xc[3] + 1j * xc[4] - v) / z                  # (E - V)/Zs, V along the real axis
            return v * i.real, -v * i.imag, xc[0] / max(xc[2], 0.01), xc[1]
        gain = _clip((v - c["lvpnt0"]) / (c["lvpnt1"] - c["lvpnt0"]), 0.0, 1.0)
        return v * xc[0] * gain, v * xc[1], xc[0], xc[1]

    def rhs(t, x):
        xc, xe, xp = x[:nc], x[nc:nc + ne], x[nc + ne:]
        v, f = _v_of(t, steps), _f_of(t, ramps)
        p, q, ip, iq = terminal(xc, v)
        # REPC_A: voltage loop to Qext, frequency droop and P loop to Pref
        err = _clip(_db(V0 - xp[0], 0.0, 0.0), -1.0, 1.0)
        q_raw = g["kp"] * err + xp[2]
        q_pi = _clip(q_raw, -1.0, 1.0)
        qext = xp[3]
        ef = _db(-f, -g["fdb"], g["fdb"])
        ep = _clip(P0 - xp[4] + min(g["ddn"] * ef, 0.0) + max(g["dup"] * ef, 0.0), -1.0, 1.0)
        p_pi = g["kpg"] * ep + xp[5]
        pref = xp[6]
        dplant = [(v - xp[0]) / g["tfltr"], (q - xp[1]) / g["tfltr"], _nw(q_raw, g["ki"] * err, -1, 1),
                  (q_pi - xp[3]) / g["tfv"], (p - xp[4]) / g["tp"], g["kig"] * ep,
                  (p_pi - xp[6]) / g["tg"]]
        # REEC_B / REEC_C
        vm, pm, xq, xv, pord = xe[:5]
        dip = v < e["vdip"] or v > e["vup"]
        iqinj = _clip(e["kqv"] * _db(V0 - vm, -e["dbd"], e["dbd"]), e["iql1"], e["iqh1"]) if dip else 0.0
        qc = _clip(qext, e["qmin"], e["qmax"])
        eq = qc - q
        vq_raw = e["kqp"] * eq + xq
        ev = _clip(vq_raw, e["vmin"], e["vmax"]) - vm
        pmin, pmax = e["pmin"], e["pmax"]
        if storage and xe[5] <= e["socmin"]:
            pmax = min(pmax, 0.0)
        if storage and xe[5] >= e["socmax"]:
            pmin = max(pmin, 0.0)
        ip_raw = _clip(pord, pmin, pmax) / max(vm, 0.01)
        vdl1 = np.interp(vm, e["vq"], e["iq"]) if storage else math.inf
        vdl2 = np.interp(vm, e["vp"], e["ip"]) if storage else math.inf
        if e["pqflag"]:
            ipmax = min(vdl2, e["imax"])
            ipcmd = _clip(ip_raw, -ipmax if storage else 0.0, ipmax)
            iqmax = min(vdl1, math.sqrt(max(e["imax"] ** 2 - ipcmd ** 2, 0.0)))
        else:
            iqmax = min(vdl1, e["imax"])
        iqb_raw = e["kvp"] * ev + xv
        iqcmd = _clip(_clip(iqb_raw, -iqmax, iqmax) + iqinj, -iqmax, iqmax)
        if not e["pqflag"]:
            ipmax = min(vdl2, math.sqrt(max(e["imax"] ** 2 - iqcmd ** 2, 0.0)))
            ipcmd = _clip(ip_raw, -ipmax if storage else 0.0, ipmax)
        run = 0.0 if dip else 1.0
        d_pord = _clip((pref - pord) / e["tpord"], e["dpmin"], e["dpmax"])
        delec = [(v - vm) / e["trv"], (p - pm) / e["tp"],
                 run * _nw(vq_raw, e["kqi"] * eq, e["vmin"], e["vmax"]),
                 run * _nw(iqb_raw, e["kvi"] * ev, -iqmax, iqmax),
                 run * _nw(pord, d_pord, pmin, pmax)]
        if storage:
            delec.append(-p / e["T"])
        # REGC_A / REGC_B
        if storage:
            imax = c["imax"]
            iqc = _clip(iqcmd, -imax, imax)                 # Q priority
            room = math.sqrt(max(imax ** 2 - iqc ** 2, 0.0))
            ipc = _clip(ipcmd, -room, room)
            vf = max(xc[2], 0.01)
            target = ipc * vf
            dp = (target - xc[0]) / c["tg"]
            dp = min(dp, c["rrpwr"]) if target >= 0 else max(dp, -c["rrpwr"])
            e_t = v + z * (ip - 1j * iq)
            dconv = [dp, _clip((iqc - xc[1]) / c["tg"], c["iqrmin"], c["iqrmax"]),
                     (v - xc[2]) / c["tfltr"], (e_t.real - xc[3]) / c["te"], (e_t.imag - xc[4]) / c["te"]]
        else:
            dconv = [min((ipcmd - xc[0]) / c["tg"], c["rrpwr"]), (iqcmd - xc[1]) / c["tg"]]
        return dconv + delec + dplant

    x = np.array(conv0 + elec0 + plant0, dtype=float)
    cuts = sorted({0.0, T_END, *[s for s, _ in steps if 0 < s < T_END]})
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):      # the voltage steps cut the integration
        ts = TS[(TS >= a) & (TS < b)] if b < T_END else TS[TS >= a]
        sol = solve_ivp(rhs, (a, b), x, t_eval=np.r_[ts, b] if b < T_END else ts, method="DOP853",
                        rtol=1e-10, atol=1e-12, max_step=5e-3)
        out.append(sol.y[:, :len(ts)])
        x = sol.y[:, -1]
    ys = np.concatenate(out, axis=1).T
    pq = np.array([terminal(y[:nc], _v_of(t, steps))[:2] for t, y in zip(TS, ys)])
    soc = ys[:, nc + 5] if storage else None
    return pq[:, 0], pq[:, 1], soc


UNITS = {"pv": _pv_unit, "bess": _bess_unit}


@pytest.fixture(scope="module")
def runs():
    """Each plant's three runs (one compiled program per plant) and their SciPy references."""
    out = {}
    for kind, make in UNITS.items():
        unit = make()
        for name, (steps, ramps) in RUNS.items():
            ys, sig, y0 = _simulate(unit, jnp.asarray(TS), jnp.asarray(steps), jnp.asarray(ramps))
            ref = _reference(kind, steps, ramps) if name != "flat" else None
            out[kind, name] = (unit, np.asarray(ys), sig, np.asarray(y0), ref)
    return out


def _away(steps, ramps):
    """The frames more than 20 ms from a switching instant of the inputs."""
    instants = np.r_[steps[:, 0], ramps[:, 0], ramps[:, 1]]
    return np.all(np.abs(TS[:, None] - instants[None]) > 0.02, axis=1)


@pytest.mark.parametrize("kind", ["pv", "bess"])
@pytest.mark.parametrize("name", ["step_ramp", "dip"])
def test_matches_the_scipy_block_diagram(runs, kind, name):
    unit, ys, sig, _, (p_ref, q_ref, soc_ref) = runs[kind, name]
    away = _away(*RUNS[name])
    dp = np.max(np.abs(np.asarray(sig.p_pu) - p_ref)[away])
    dq = np.max(np.abs(np.asarray(sig.q_pu) - q_ref)[away])
    worst = max(dp, dq)
    if soc_ref is not None:
        k = unit.converter.n_states + 6
        worst = max(worst, np.max(np.abs(ys[:, k] - soc_ref)))
    print(f"\n{kind} {name}: largest difference from SciPy {worst:.2e} pu (P {dp:.2e}, Q {dq:.2e})")
    assert worst < 1e-5
    assert np.ptp(p_ref) > 0.01 and np.ptp(q_ref) > 0.02          # not a trivial response


def test_a_flat_run_stays_flat(runs):
    """Nothing imposed changes: P and Q stay at the power flow; REECCU1's SOC alone moves, by
    exactly -P0 t / T (an integrator of the output), until it reaches SOCmin (at 2.57 s here),
    where the discharge stops."""
    t_min = (BESS["soc0"] - BESS["socmin"]) * BESS["T"] / P0
    for kind in UNITS:
        unit, ys, sig, y0, _ = runs[kind, "flat"]
        held = TS < (t_min - 0.01 if kind == "bess" else np.inf)
        assert np.max(np.abs(np.asarray(sig.p_pu)[held] - P0)) < 1e-10
        assert np.max(np.abs(np.asarray(sig.q_pu)[held] - Q0)) < 1e-10
        rest = unit.at_rest
        assert np.max(np.abs(ys[held][:, rest] - y0[rest])) < 1e-10
        if kind == "bess":
            soc = ys[:, ~rest][:, 0]
            np.testing.assert_allclose(soc[held], BESS["soc0"] - P0 * TS[held] / BESS["T"], atol=1e-10)
            # the power order's lag lets it pass SOCmin by a little (0.35e-3 here), then P is 0
            assert float(sig.p_pu[-1]) < 1e-6 and BESS["socmin"] - 1e-3 < soc[-1] < BESS["socmin"]


def test_the_dip_reaches_the_limits_and_freezes(runs):
    """|V| = 0.5 for 0.2 s: the current limits bind (PV: Iqcmd on Imax, Ipcmd on the room left,
    Q priority; storage: Ipcmd on VDL2(Vm), Iqcmd on the room left, P priority; REGCB1's own
    Imax and its Iq rate) and the PI integrators and the power order stay frozen."""
    t = TS
    late = (t > 0.3) & (t < 0.4 - 1e-6)
    unit, ys, sig, _, _ = runs["pv", "dip"]
    np.testing.assert_allclose(np.asarray(sig.iqcmd_pu)[late], PV["imax"], atol=1e-9)
    assert np.all(np.asarray(sig.ipcmd_pu)[late] <= 1e-6 + 1e-12)   # the room sqrt(max(., 1e-12))
    assert np.all(np.asarray(sig.dip)[late])
    unit, ys, sig, _, _ = runs["bess", "dip"]
    ipcmd, iqcmd = np.asarray(sig.ipcmd_pu)[late], np.asarray(sig.iqcmd_pu)[late]
    vm = ys[late, unit.converter.n_states]
    np.testing.assert_allclose(ipcmd, np.interp(vm, BESS["vp"], BESS["ip"]), atol=1e-9)
    np.testing.assert_allclose(iqcmd, np.minimum(np.interp(vm, BESS["vq"], BESS["iq"]),
                                                 np.sqrt(BESS["imax"] ** 2 - ipcmd ** 2)), atol=1e-9)
    ipc, iqc = unit.converter.limit(jnp.asarray(ipcmd), jnp.asarray(iqcmd))
    assert np.all(np.asarray(ipc) < ipcmd - 0.05)                   # REGCB1's Imax cuts Ip further
    d_iq = np.diff(ys[:, 1]) / np.diff(t)
    assert GCB["iqrmax"] - 1.0 < np.max(np.abs(d_iq)) <= GCB["iqrmax"] + 1e-6   # its Iq rate limit binds
    for kind in UNITS:
        unit, ys, _, _, _ = runs[kind, "dip"]
        k0, k1 = np.searchsorted(t, 0.21), np.searchsorted(t, 0.4 - 1e-6) - 1
        frozen = [unit.converter.n_states + k for k in (2, 3, 5)]
        np.testing.assert_allclose(ys[k0:k1 + 1][:, frozen], np.repeat(ys[k0:k0 + 1][:, frozen],
                                                                       k1 - k0 + 1, 0), atol=1e-12)


def test_the_state_of_charge_limit_stops_the_discharge(runs):
    """REECCU1: once SOC falls to SOCmin the power order ceiling is 0, and P falls to 0."""
    unit, ys, sig, _, (_, _, soc_ref) = runs["bess", "step_ramp"]
    soc = ys[:, unit.converter.n_states + 6]
    hit = np.argmax(soc <= BESS["socmin"])
    assert 0 < hit and TS[hit] < 2.8
    assert abs(float(sig.p_pu[-1])) < 0.02 < float(sig.p_pu[hit - 5])


DYR = """
 9 'REGCB1' '1' 1 0 0.02 0.02 20 -20 10 0.01 1.2 /
 9 'REECB1' '1' 0 0 1 1 0 0.8 1.2 0.02 -0.05 0.05 4 1.9 -1.9 0 0.05 1 -1 1.5 0.5 0.5 2 1.5 20
   0.02 99 -99 1 0 1.1 0.05 /
 9 'REECCU1' '1' 0 0 1 1 1 0.8 1.2 0.02 -0.05 0.05 4 1.9 -1.9 0 0.05 1 -1 1.5 0.5 0.5 2 1.5 20
   0.02 99 -99 1 -0.8 1.25 0.05  0.2 0.9 0.5 1 1 1.2 1.5 1.2  0.2 0.5 0.5 0.8 1 1.2 1.5 1.2
   60 0.5 0.9 0.47 /
"""


def test_records_read_in_psse_order(tmp_path):
    from jaxdse._io.psse import read_dyr
    path = tmp_path / "pv.dyr"
    path.write_text(DYR)
    recs = {r.model: r for r in read_dyr(path).records}
    conv = ibr_from_dyr("REGCB1", recs["REGCB1"].constants)
    assert (conv.rateflag, conv.pqflag) == (1, 0)
    cons = (conv.t_g_s, conv.t_fltr_s, conv.iqrmax_pu_s, conv.iqrmin_pu_s, conv.rrpwr_pu_s, conv.t_e_s,
            conv.i_max_pu)
    assert [float(x) for x in cons] == [0.02, 0.02, 20, -20, 10, 0.01, 1.2]
    pv = ibr_from_dyr("REECB1", recs["REECB1"].constants)
    assert (pv.pfflag, pv.vflag, pv.qflag, pv.pqflag) == (0, 1, 1, 0)
    assert float(pv.kqv) == 4 and float(pv.kvi) == 20 and float(pv.i_max_pu) == 1.1
    assert float(pv.t_pord_s) == 0.05 and float(pv.p_min_pu) == 0.0
    other = list(recs["REECB1"].constants)
    other[0] = "1234"                    # IREG: an array leaf, one structure whatever the bus
    remote = ibr_from_dyr("REECB1", other)
    assert int(remote.remote_bus) == 1234
    assert jax.tree_util.tree_structure(remote) == jax.tree_util.tree_structure(pv)
    bess = ibr_from_dyr("REECCU1", recs["REECCU1"].constants)
    assert bess.pqflag == 1 and float(bess.p_min_pu) == -0.8 and float(bess.i_max_pu) == 1.25
    np.testing.assert_allclose(bess.vdl2_i_pu, BESS["ip"])
    soc = (bess.t_soc_s, bess.soc_ini_pu, bess.soc_max_pu, bess.soc_min_pu)
    assert [float(x) for x in soc] == [60, 0.5, 0.9, 0.47]
    bad = list(recs["REECCU1"].constants)
    bad[-1] = 0.95
    with pytest.raises(ValueError, match=r"^REECCU1: SOCmax \(0.9\) must be >= SOCmin \(0.95\)$"):
        ibr_from_dyr("REECCU1", bad)
    bad = list(recs["REGCB1"].constants)
    bad[0] = 2
    with pytest.raises(ValueError, match="^REGCB1: RateFlag must be 0 or 1, got 2$"):
        ibr_from_dyr("REGCB1", bad)
    with pytest.raises(ValueError, match="REECB1: expected 30 values"):
        ibr_from_dyr("REECB1", [1.0] * 29)


def test_other_combinations_start_at_rest():
    """The combinations the runs above do not use (REGCB1 with REECA1, REGCA1 with REECCU1, REECB1
    with VFLAG = 0 or PFFLAG = 1, with and without REPCA1): each builds and its initial state
    holds the power flow with every derivative zero (REECCU1's SOC: -P0/T). Eager, nothing compiled."""
    from jaxdse._models.ibr import REECA1

    v, ang, p, q = 1.03, -0.4, 0.6, 0.2
    u = UnitInputs(jnp.asarray(v * np.cos(ang)), jnp.asarray(v * np.sin(ang)), jnp.asarray(0.0),
                   jnp.asarray(0.0))
    i = np.conj((p + 1j * q) / (v * np.exp(1j * ang)))
    gcb = REGCB1(rateflag=1, pqflag=1, t_e_s=0.01, re_pu=0.01, xe_pu=0.2)
    for conv, elec, plant in ((gcb, REECA1(qflag=1), REPCA1()), (REGCA1(), REECCU1(qflag=1, pqflag=1), None),
                              (gcb, REECB1(qflag=1, vflag=0), None), (REGCA1(), REECB1(pfflag=1), REPCA1())):
        unit = IbrUnit(conv, elec, plant)
        y0, refs = unit.initial_state(u, i.real, i.imag)
        d = np.asarray(unit.vector_field(y0, u, refs))
        s = unit.signals(y0, u, refs)
        assert np.max(np.abs(d[unit.at_rest])) < 1e-12
        assert np.allclose(d[~unit.at_rest], -p / float(getattr(elec, "t_soc_s", np.nan)), atol=1e-15)
        assert abs(float(s.p_pu) - p) < 1e-12 and abs(float(s.q_pu) - q) < 1e-12
