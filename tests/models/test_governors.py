"""Tests of the IEEEG1, GAST, HYGOV and GGOV1 governor-turbine modules.

Each model is checked against an independent implementation written directly from the
PSS/E block diagram in plain Python floats (one block after another, limits as if-statements,
integrated with an explicit trapezoid (Heun) loop at a fine step), and, where the path is
linear, against ``scipy.signal`` transfer functions built from the diagram's blocks.
"""

import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import pytest
import scipy.signal as sig

from jaxdse import GAST, GGOV1, HYGOV, IEEEG1

T_M0 = 0.7
DT = 2e-3


# --- integration helpers ----------------------------------------------------------------------

def simulate(gov, x0, dw, t_ref, t_end, dt=DT):
    """RK4 with constant inputs; Tm at t = dt, 2 dt, ..., t_end."""
    tm, xf = _rk4(gov, jnp.asarray(x0, float), jnp.asarray(dw, float), jnp.asarray(t_ref, float),
                  int(round(t_end / dt)), dt)
    return np.asarray(tm), np.asarray(xf)


@functools.partial(jax.jit, static_argnames=("n", "dt"))
def _rk4(gov, x0, dw, t_ref, n, dt):
    """Compiled once per model structure: the parameters are traced leaves."""

    def f(x):
        return gov.vector_field(x, dw, t_ref)

    def step(x, _):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x, gov.torque(x, dw)

    xf, tm = jax.lax.scan(step, x0, None, length=n)
    return tm, xf


def heun(deriv, out, x0, t_end, dt, every):
    """Explicit trapezoid in plain Python; output sampled every ``every`` steps."""
    x = list(x0)
    n = int(round(t_end / dt))
    ys = []
    for k in range(1, n + 1):
        d1 = deriv(x)
        xp = [a + dt * b for a, b in zip(x, d1)]
        d2 = deriv(xp)
        x = [a + 0.5 * dt * (b + c) for a, b, c in zip(x, d1, d2)]
        if k % every == 0:
            ys.append(out(x))
    return np.asarray(ys)


def lag(u, x, t):
    """Block 1/(1+sT) as PSS/E draws it: (output, derivative); T = 0 passes through."""
    if t > 0:
        return x, (u - x) / t
    return u, 0.0


def hold(x, d, lo, hi):
    if (x >= hi and d > 0) or (x <= lo and d < 0):
        return 0.0
    return d


def clip(v, lo, hi):
    return min(max(v, lo), hi)


# --- reference models written from the block diagrams ---------------------------------------

def ref_ieeeg1(p, dw, po):
    def deriv(x):
        if p["T1"] > 0:
            ll = p["K"] * (x[0] + p["T2"] / p["T1"] * (dw - x[0]))
            dll = (dw - x[0]) / p["T1"]
        else:
            ll, dll = p["K"] * dw, 0.0
        rate = clip((po - ll - x[1]) / p["T3"], p["Uc"], p["Uo"])
        rate = hold(x[1], rate, p["PMIN"], p["PMAX"])
        inp, ds = clip(x[1], p["PMIN"], p["PMAX"]), []
        for k, t in zip(range(2, 6), ("T4", "T5", "T6", "T7")):
            inp, d = lag(inp, x[k], p[t])
            ds.append(d)
        return [dll, rate] + ds

    def out(x):
        inp, outs = clip(x[1], p["PMIN"], p["PMAX"]), []
        for k, t in zip(range(2, 6), ("T4", "T5", "T6", "T7")):
            inp, _ = lag(inp, x[k], p[t])
            outs.append(inp)
        return p["K1"] * outs[0] + p["K3"] * outs[1] + p["K5"] * outs[2] + p["K7"] * outs[3]

    return deriv, out


def ref_gast(p, dw, pref):
    def deriv(x):
        y2, d2 = lag(clip(x[0], p["VMIN"], p["VMAX"]), x[1], p["T2"])
        y3, d3 = lag(y2, x[2], p["T3"])
        lv = min(pref - dw / p["R"], p["AT"] + p["KT"] * (p["AT"] - y3))
        d1 = hold(x[0], (lv - x[0]) / p["T1"], p["VMIN"], p["VMAX"])
        return [d1, d2, d3]

    def out(x):
        return lag(clip(x[0], p["VMIN"], p["VMAX"]), x[1], p["T2"])[0] - p["DTURB"] * dw

    return deriv, out


def ref_hygov(p, dw, nref):
    def deriv(x):
        c = clip(x[1], p["GMIN"], p["GMAX"])
        e = nref - dw - p["R"] * c
        d1 = (e - x[0]) / p["Tf"]
        vel = clip((x[0] + p["Tr"] * d1) / (p["r"] * p["Tr"]), -p["VELM"], p["VELM"])
        dc = hold(x[1], vel, p["GMIN"], p["GMAX"])
        g, dg = lag(c, x[2], p["Tg"])
        h = (x[3] / g) ** 2
        return [d1, dc, dg, (1.0 - h) / p["TW"]]

    def out(x):
        g = lag(clip(x[1], p["GMIN"], p["GMAX"]), x[2], p["Tg"])[0]
        h = (x[3] / g) ** 2
        return p["At"] * h * (x[3] - p["qNL"]) - p["Dturb"] * dw * g

    return deriv, out


def ref_ggov1(p, dw, pref):
    """GGOV1 as documented in governors.GGOV1 (states in the same order)."""
    ff = 1.0 + dw if p["Flag"] == 1 else 1.0
    damp = p["Dm"] * dw if p["Dm"] > 0 else 0.0
    tfac = (1.0 + dw) ** min(p["Dm"], 0.0)
    tlim = p["Ldref"] / p["Kturb"] + p["Wfnl"]

    def turbine(x):
        wf = x[4] * ff
        if p["Teng"] > 0:
            wfd, de = 2 * x[5] - wf, (wf - x[5]) / (p["Teng"] / 2)
        else:
            wfd, de = wf, 0.0
        pin = p["Kturb"] * (wfd - p["Wfnl"])
        if p["Tb"] > 0:
            pt, dt_ = x[6] + p["Tc"] / p["Tb"] * (pin - x[6]), (pin - x[6]) / p["Tb"]
        else:
            pt, dt_ = pin, 0.0
        return pt - damp, wf, de, dt_

    def deriv(x):
        pm, wf, de, dtb = turbine(x)
        pe, dpe = lag(pm, x[0], p["Tpelec"])
        fb = {1: pe, -1: x[3], -2: x[4]}[p["Rselect"]]
        err = clip(pref - dw - p["R"] * fb, p["minerr"], p["maxerr"])
        if p["Tdgov"] > 0:
            dd = (err - x[1]) / p["Tdgov"]
            der = dd
        else:
            dd = der = 0.0
        fsrn = p["Kpgov"] * err + x[2] + p["Kdgov"] * der
        if p["Tsb"] > 0:
            ys, ds = x[7] + p["Tsa"] / p["Tsb"] * (wf * tfac - x[7]), (wf * tfac - x[7]) / p["Tsb"]
        else:
            ys, ds = wf * tfac, 0.0
        texm, df = lag(ys, x[8], p["Tfload"])
        fsrt = p["Kpload"] * (tlim - texm) + x[9]
        if p["Ta"] > 0:
            acc = (dw - x[10]) / p["Ta"]
        else:
            acc = 0.0
        fsra = x[3] + p["Ka"] * p["DELT"] * (p["Aset"] - acc) if p["Ka"] > 0 else math.inf
        fsr = clip(min(fsrn, fsrt, fsra), p["Vmin"], p["Vmax"])
        kg = p["Kigov"] / p["Kpgov"] if p["Kpgov"] > 0 else 1.0 / p["DELT"]
        kl = p["Kiload"] / p["Kpload"] if p["Kpload"] > 0 else 1.0 / p["DELT"]
        di = p["Kigov"] * err + kg * (fsr - fsrn)
        dl = p["Kiload"] * (tlim - texm) + kl * (fsr - fsrt)
        ds3 = clip((fsr - x[4]) / p["Tact"], p["Rclose"], p["Ropen"])
        return [dpe, dd, di, (fsr - x[3]) / p["DELT"], ds3, de, dtb, ds, df, dl, acc]

    def out(x):
        return turbine(x)[0]

    return deriv, out


# --- parameter sets ---------------------------------------------------------------------------

IEEEG1_SETS = {
    "default": {},
    "leadlag_t7": dict(t1_s=0.5, t2_s=0.1, t7_s=0.4, k5=0.2, k7=0.1),
}
GAST_SETS = {
    "default": {},
    "wecc": dict(r_pu=0.08, t1_s=0.3, t2_s=0.3, t3_s=3.0, at_pu=1.0, kt_pu=2.0, v_max_pu=1.0,
                 v_min_pu=0.0, dturb_pu=0.0),
    "damped": dict(dturb_pu=0.5, t2_s=0.0),
}
HYGOV_SETS = {
    "default": {},
    "wecc": dict(r_pu=0.05, r_temp_pu=0.075, tr_s=12.0, tf_s=0.5, tg_s=20.5, velm_pu_s=0.1,
                 g_max_pu=1.0, g_min_pu=0.0, tw_s=15.0, at_pu=1.5, dturb_pu=0.0, q_nl_pu=0.08),
    "damped": dict(dturb_pu=0.5, tg_s=0.0),
}
GGOV1_SETS = {
    "default": {},
    "stroke_fb": dict(rselect=-2, flag=0, kdgov=1.0, t_dgov_s=0.5, t_c_s=0.05, t_eng_s=0.1),
    "fsr_fb": dict(rselect=-1, dm_pu=0.3, t_pelec_s=0.0, kpload=0.0, kiload=0.5),
    "dm_negative": dict(dm_pu=-0.5, t_sb_s=0.0, t_b_s=0.0, ka=0.0),
}
ALL = ([(IEEEG1, n, kw) for n, kw in IEEEG1_SETS.items()] + [(GAST, n, kw) for n, kw in GAST_SETS.items()]
       + [(HYGOV, n, kw) for n, kw in HYGOV_SETS.items()] + [(GGOV1, n, kw) for n, kw in GGOV1_SETS.items()])
IDS = [f"{c.__name__}-{n}" for c, n, _ in ALL]


def params_ieeeg1(g):
    return dict(K=float(g.k), T1=float(g.t1_s), T2=float(g.t2_s), T3=float(g.t3_s), Uo=float(g.uo_pu_s),
                Uc=float(g.uc_pu_s), PMAX=float(g.p_max_pu), PMIN=float(g.p_min_pu), T4=float(g.t4_s),
                T5=float(g.t5_s), T6=float(g.t6_s), T7=float(g.t7_s), K1=float(g.k1), K3=float(g.k3),
                K5=float(g.k5), K7=float(g.k7))


def params_gast(g):
    return dict(R=float(g.r_pu), T1=float(g.t1_s), T2=float(g.t2_s), T3=float(g.t3_s), AT=float(g.at_pu),
                KT=float(g.kt_pu), VMAX=float(g.v_max_pu), VMIN=float(g.v_min_pu), DTURB=float(g.dturb_pu))


def params_hygov(g):
    return dict(R=float(g.r_pu), r=float(g.r_temp_pu), Tr=float(g.tr_s), Tf=float(g.tf_s), Tg=float(g.tg_s),
                VELM=float(g.velm_pu_s), GMAX=float(g.g_max_pu), GMIN=float(g.g_min_pu), TW=float(g.tw_s),
                At=float(g.at_pu), Dturb=float(g.dturb_pu), qNL=float(g.q_nl_pu))


def params_ggov1(g):
    names = dict(R="r_pu", Tpelec="t_pelec_s", maxerr="maxerr_pu", minerr="minerr_pu", Kpgov="kpgov",
                 Kigov="kigov", Kdgov="kdgov", Tdgov="t_dgov_s", Vmax="v_max_pu", Vmin="v_min_pu",
                 Tact="t_act_s", Kturb="k_turb", Wfnl="w_fnl_pu", Tb="t_b_s", Tc="t_c_s", Teng="t_eng_s",
                 Tfload="t_fload_s", Kpload="kpload", Kiload="kiload", Ldref="ldref_pu", Dm="dm_pu",
                 Ropen="r_open_pu_s", Rclose="r_close_pu_s", Aset="aset_pu_s", Ka="ka", Ta="t_a_s",
                 Tsa="t_sa_s", Tsb="t_sb_s", DELT="delt_s")
    out = {k: float(getattr(g, v)) for k, v in names.items()}
    out.update(Rselect=int(g.rselect), Flag=int(g.flag))
    return out


REFS = {IEEEG1: (ref_ieeeg1, params_ieeeg1), GAST: (ref_gast, params_gast),
        HYGOV: (ref_hygov, params_hygov), GGOV1: (ref_ggov1, params_ggov1)}


def droop_gain(gov, dw=0.0):
    """Steady-state dTm/d(dw) at fixed reference, by finite differences of the steady state."""
    tr = gov.reference_from_steady(T_M0, 0.0)
    h = 1e-6
    return float((gov.torque(gov.steady_state(tr, dw + h), dw + h)
                  - gov.torque(gov.steady_state(tr, dw - h), dw - h)) / (2 * h))


# --- equilibrium and round trip ---------------------------------------------------------------

@pytest.mark.parametrize("cls,name,kw", ALL, ids=IDS)
@pytest.mark.parametrize("dw", [0.0, -0.002, 0.001, 0.004])
def test_equilibrium_and_round_trip(cls, name, kw, dw):
    gov = cls(**kw)
    t_ref = gov.reference_from_steady(T_M0, dw)
    x = gov.steady_state(t_ref, dw)
    f = gov.vector_field(x, dw, t_ref)
    assert x.ndim == 1
    np.testing.assert_allclose(np.asarray(f), 0.0, atol=1e-12)
    np.testing.assert_allclose(float(gov.torque(x, dw)), T_M0, rtol=1e-12)
    # equilibrium also at a reference that drives the model onto a limit
    for tr in (t_ref + 0.8, t_ref - 0.8):
        xs = gov.steady_state(tr, dw)
        np.testing.assert_allclose(np.asarray(gov.vector_field(xs, dw, tr)), 0.0, atol=1e-12)


@pytest.mark.parametrize("cls,name,kw", ALL, ids=IDS)
def test_broadcasting_as_jaxdse_uses_it(cls, name, kw):
    """torque on (n_states, T) states and reference_from_steady on series (jaxdse's calls)."""
    gov = cls(**kw)
    dw = jnp.linspace(-0.003, 0.003, 7)
    t_m = jnp.linspace(0.5, 0.8, 7)
    refs = gov.reference_from_steady(t_m, dw)
    assert refs.shape == (7,)
    states = jax.vmap(gov.steady_state)(refs, dw)           # (T, n_states)
    tm = gov.torque(jnp.moveaxis(states, -1, 0), dw)         # jaxdse's _torque_series
    np.testing.assert_allclose(np.asarray(tm), np.asarray(t_m), rtol=1e-12)


def test_droop_final_values():
    """Steady-state droop: dTm/d(dw) = -1/R - Dt (TGOV1-like), -K K_hp (IEEEG1), HYGOV -At/R."""
    assert droop_gain(GAST()) == pytest.approx(-1 / 0.05, rel=1e-6)
    assert droop_gain(GAST(dturb_pu=0.5)) == pytest.approx(-1 / 0.05 - 0.5, rel=1e-6)
    assert droop_gain(IEEEG1()) == pytest.approx(-20.0, rel=1e-6)
    hy = HYGOV(dturb_pu=0.0)
    assert droop_gain(hy) == pytest.approx(-1.2 / 0.05, rel=1e-6)
    gg = GGOV1()
    assert droop_gain(gg) == pytest.approx(-1 / 0.04, rel=1e-6)      # Rselect = 1: Pe droop
    gg2 = GGOV1(rselect=-2, flag=0)
    assert droop_gain(gg2) == pytest.approx(-1.5 / 0.04, rel=1e-6)   # stroke droop x Kturb


# --- step responses against the block-diagram references ---------------------------------------

SCENARIOS = [("speed", -0.002), ("speed", 0.002), ("reference", 0.05)]


def _run_both(gov, kind, size, t_end):
    dw0 = 0.0
    tr0 = float(gov.reference_from_steady(T_M0, dw0))
    x0 = gov.steady_state(tr0, dw0)
    dw, tr = (size, tr0) if kind == "speed" else (dw0, tr0 + size)
    tm, _ = simulate(gov, x0, dw, tr, t_end)
    ref, getp = REFS[type(gov)]
    deriv, out = ref(getp(gov), dw, tr)
    tm_ref = heun(deriv, out, [float(v) for v in x0], t_end, DT / 2, 2)
    return tm, tm_ref, dw, tr


@pytest.mark.slow
@pytest.mark.parametrize("cls,name,kw", ALL, ids=IDS)
@pytest.mark.parametrize("kind,size", SCENARIOS)
def test_step_matches_block_diagram(cls, name, kw, kind, size):
    gov = cls(**kw)
    t_end = 60.0 if name == "wecc" and cls is HYGOV else 20.0
    tm, tm_ref, dw, tr = _run_both(gov, kind, size, t_end)
    final = float(gov.torque(gov.steady_state(tr, dw), dw))
    scale = abs(final - T_M0)
    assert scale > 1e-4
    assert np.max(np.abs(tm - tm_ref)) < 1e-3 * scale
    assert np.all(np.isfinite(tm))


@pytest.mark.parametrize("cls,name,kw", ALL, ids=IDS)
def test_settles_to_droop_final_value(cls, name, kw):
    gov = cls(**kw)
    if cls is HYGOV and name == "wecc":
        pytest.skip("TW = 15 s, Tg = 20.5 s: settles over minutes (checked in the step test)")
    dw = -0.002
    tr0 = float(gov.reference_from_steady(T_M0, 0.0))
    tm, _ = simulate(gov, gov.steady_state(tr0, 0.0), dw, tr0, 400.0, dt=1e-2)   # HYGOV: r Tr / R = 30 s
    final = float(gov.torque(gov.steady_state(tr0, dw), dw))
    assert final > T_M0                       # a speed drop raises the power
    assert abs(tm[-1] - final) < 2e-3 * abs(final - T_M0)


def test_ieeeg1_linear_path_matches_transfer_function():
    """Small speed step (no rate or position limit): scipy.signal of the diagram's blocks."""
    gov = IEEEG1(t1_s=0.5, t2_s=0.1, t7_s=0.4, k5=0.2, k7=0.1)
    p = params_ieeeg1(gov)
    dw = -2e-4
    assert abs(p["K"] * dw / p["T3"]) < p["Uo"]
    tr0 = float(gov.reference_from_steady(T_M0, 0.0))
    tm, _ = simulate(gov, gov.steady_state(tr0, 0.0), dw, tr0, 30.0)
    # turbine: sum_i K_i / prod_{j <= i} (1 + s T_j) over one common denominator
    lags = [np.array([p[t], 1.0]) for t in ("T4", "T5", "T6", "T7")]
    gains = [p[k] for k in ("K1", "K3", "K5", "K7")]
    den_turbine = np.array([1.0])
    for lag_ in lags:
        den_turbine = np.polymul(den_turbine, lag_)
    num_turbine = np.array([0.0])
    for i, k in enumerate(gains):
        term = np.array([k])
        for lag_ in lags[i + 1:]:
            term = np.polymul(term, lag_)
        num_turbine = np.polyadd(num_turbine, term)
    num = np.polymul(np.polymul([-p["K"] * p["T2"], -p["K"]], [1.0]), np.trim_zeros(num_turbine, "f"))
    den = np.polymul(np.polymul([p["T1"], 1.0], [p["T3"], 1.0]), den_turbine)
    tf = sig.lti(num, den)
    t = DT * np.arange(len(tm) + 1)
    _, y, _ = sig.lsim(tf, U=np.full_like(t, dw), T=t)
    np.testing.assert_allclose(tm - T_M0, y[1:], atol=1e-3 * abs(p["K"] * dw))


def test_gast_linear_path_matches_transfer_function():
    gov = GAST(dturb_pu=0.3)
    p = params_gast(gov)
    dw = -0.002
    tr0 = float(gov.reference_from_steady(T_M0, 0.0))
    tm, _ = simulate(gov, gov.steady_state(tr0, 0.0), dw, tr0, 20.0)
    tf = sig.lti([-1.0 / p["R"]], np.polymul([p["T1"], 1.0], [p["T2"], 1.0]))
    t = DT * np.arange(len(tm) + 1)
    _, y, _ = sig.lsim(tf, U=np.full_like(t, dw), T=t)
    np.testing.assert_allclose(tm - T_M0, y[1:] - p["DTURB"] * dw, atol=1e-3 * abs(dw / p["R"]))


# --- limits -----------------------------------------------------------------------------------

def test_ieeeg1_hits_rate_and_position_limits():
    gov = IEEEG1()
    tr0 = float(gov.reference_from_steady(T_M0, 0.0))
    x0 = gov.steady_state(tr0, 0.0)
    tm, xf = simulate(gov, x0, -0.05, tr0, 60.0)     # asks for 0.7 + 20 * 0.05 = 1.7 > PMAX
    tm_ref = heun(*ref_ieeeg1(params_ieeeg1(gov), -0.05, tr0), [float(v) for v in x0], 60.0, DT / 2, 2)
    np.testing.assert_allclose(tm, tm_ref, atol=1e-4)
    gv = xf[1]
    assert 1.0 <= gv <= 1.0 + 0.1 * DT                              # PMAX (+ < one RK4 step), no windup
    assert tm[-1] == pytest.approx(0.3 + 0.4 + 0.3, abs=2e-4)       # K_hp PMAX (T5 = 7 s tail)
    # valve opens at Uo = 0.1 pu/s: 0.3 pu takes 3 s
    x_mid = simulate(gov, x0, -0.05, tr0, 1.0)[1]
    assert x_mid[1] == pytest.approx(0.7 + 0.1 * 1.0, abs=1e-9)


def test_gast_load_limit_and_vmax():
    gov = GAST(at_pu=0.9, kt_pu=2.0, v_max_pu=1.2)
    tr0 = float(gov.reference_from_steady(T_M0, 0.0))
    x0 = gov.steady_state(tr0, 0.0)
    tm, xf = simulate(gov, x0, 0.0, tr0 + 0.5, 40.0)           # asks for 1.2 > AT = 0.9
    tm_ref = heun(*ref_gast(params_gast(gov), 0.0, tr0 + 0.5), [float(v) for v in x0], 40.0, DT / 2, 2)
    np.testing.assert_allclose(tm, tm_ref, atol=1e-4)
    assert tm[-1] == pytest.approx(0.9, abs=2e-3)              # held at the ambient load limit
    assert np.max(tm) > 0.9                                     # overshoot before T3 catches up
    gov2 = GAST(at_pu=1.5, v_max_pu=1.0)
    tm2, xf2 = simulate(gov2, gov2.steady_state(tr0, 0.0), 0.0, tr0 + 0.5, 20.0)
    assert 1.0 <= xf2[0] <= 1.0 + DT                            # valve at VMAX, not wound up
    assert tm2[-1] == pytest.approx(1.0, abs=1e-3)


def test_hygov_gate_and_velocity_limits():
    gov = HYGOV(g_max_pu=0.9, velm_pu_s=0.02)
    tr0 = float(gov.reference_from_steady(T_M0, 0.0))
    x0 = gov.steady_state(tr0, 0.0)
    tm, xf = simulate(gov, x0, -0.05, tr0, 40.0)
    tm_ref = heun(*ref_hygov(params_hygov(gov), -0.05, tr0), [float(v) for v in x0], 40.0, DT / 2, 2)
    np.testing.assert_allclose(tm, tm_ref, atol=1e-4)
    assert 0.9 <= xf[1] <= 0.9 + 0.02 * DT                       # desired gate at GMAX
    c1 = simulate(gov, x0, -0.05, tr0, 1.0)[1][1]
    assert c1 - float(x0[1]) == pytest.approx(0.02 * 1.0, abs=1e-9)   # VELM
    final = float(gov.torque(gov.steady_state(tr0, -0.05), -0.05))
    assert tm[-1] == pytest.approx(final, abs=1e-3)


def test_hygov_closed_gate_is_finite():
    gov = HYGOV()
    x = jnp.array([0.0, 0.0, 0.0, 0.05])
    f = gov.vector_field(x, 0.0, 0.0)
    g = jax.grad(lambda s: gov.torque(s, 0.0) + jnp.sum(gov.vector_field(s, 0.0, 0.0)))(x)
    assert np.all(np.isfinite(np.asarray(f))) and np.all(np.isfinite(np.asarray(g)))


@pytest.mark.slow
def test_ggov1_vmax_and_load_limiter():
    gov = GGOV1(ldref_pu=0.9, v_max_pu=1.0)
    tr0 = float(gov.reference_from_steady(T_M0, 0.0))
    x0 = gov.steady_state(tr0, 0.0)
    tm, xf = simulate(gov, x0, 0.0, tr0 + 0.02, 80.0)          # asks for 0.7 + 0.02/0.04 = 1.2
    tm_ref = heun(*ref_ggov1(params_ggov1(gov), 0.0, tr0 + 0.02), [float(v) for v in x0], 80.0, DT / 2, 2)
    np.testing.assert_allclose(tm, tm_ref, atol=1e-4)
    assert tm[-1] == pytest.approx(0.9, abs=2e-3)              # load limiter: Pm -> Ldref
    gov2 = GGOV1(ldref_pu=2.0, v_max_pu=0.8)
    tm2, xf2 = simulate(gov2, gov2.steady_state(tr0, 0.0), 0.0, tr0 + 0.02, 40.0)
    assert xf2[4] == pytest.approx(0.8, abs=1e-9)               # valve stroke at Vmax
    assert tm2[-1] == pytest.approx(1.5 * (0.8 - 0.2), abs=1e-3)
    # the governor integrator tracks FSR (no windup): back below the limit quickly
    tm3, _ = simulate(gov2, xf2, 0.0, tr0, 60.0)                  # PI + droop: ~8 s time constant
    assert tm3[-1] == pytest.approx(T_M0, abs=2e-3)


def test_ggov1_acceleration_limiter_limits_rise_rate():
    """FSR rises at most at Ka (Aset - accel) per second (PSS/E's discrete accel limiter)."""
    gov = GGOV1(aset_pu_s=0.01, ka=10.0, r_open_pu_s=10.0, t_act_s=0.05, ldref_pu=5.0)
    tr0 = float(gov.reference_from_steady(0.3, 0.0))
    x0 = gov.steady_state(tr0, 0.0)
    _, x1 = simulate(gov, x0, 0.0, tr0 + 0.02, 1.0, dt=1e-3)
    assert float(x1[3] - x0[3]) == pytest.approx(0.1 * 1.0, rel=0.05)


def test_invalid_parameters():
    with pytest.raises(ValueError, match="Uc"):
        IEEEG1(uc_pu_s=0.1)
    with pytest.raises(ValueError, match="t3_s"):
        IEEEG1(t3_s=0.0)
    with pytest.raises(ValueError, match="r_pu"):
        GAST(r_pu=0.0)
    with pytest.raises(ValueError, match="tf_s"):
        HYGOV(tf_s=0.0)
    with pytest.raises(ValueError, match="isochronous"):
        GGOV1(rselect=0)
    with pytest.raises(ValueError, match="Rclose"):
        GGOV1(r_close_pu_s=0.1)


# --- transformations --------------------------------------------------------------------------

def _loss(g):
    """Tm after 50 explicit steps from the steady state, as a function of the parameters."""
    tr = g.reference_from_steady(T_M0, 0.0)
    x = g.steady_state(tr, 0.0)
    x = jax.lax.fori_loop(0, 50, lambda _, x: x + 0.01 * g.vector_field(x, -0.002, tr), x)
    return g.torque(x, -0.002)


_jit_value_and_grad = eqx.filter_jit(eqx.filter_value_and_grad(_loss))
"""Compiled once per model structure (the parameters are traced leaves)."""


@pytest.mark.parametrize("cls,name,kw", ALL, ids=IDS)
def test_jit_and_grad(cls, name, kw):
    value, grads = _jit_value_and_grad(cls(**kw))
    leaves = jtu.tree_leaves(eqx.filter(grads, eqx.is_inexact_array))
    assert np.isfinite(float(value))
    assert all(np.all(np.isfinite(np.asarray(v))) for v in leaves)
    assert any(float(jnp.abs(v)) > 0 for v in leaves)


@pytest.mark.parametrize("cls,field_name,values", [
    (IEEEG1, "t4_s", [0.2, 0.3, 0.5]), (GAST, "r_pu", [0.04, 0.05, 0.08]),
    (HYGOV, "tw_s", [0.8, 1.0, 2.0]), (GGOV1, "kpgov", [5.0, 10.0, 20.0])])
def test_vmap_over_parameter_batch(cls, field_name, values):
    govs = [cls(**{field_name: v}) for v in values]
    batch = jtu.tree_map(lambda *xs: jnp.stack(xs), *govs)

    def one(g):
        tr = g.reference_from_steady(T_M0, 0.0)
        x = g.steady_state(tr, 0.0)
        x = jax.lax.fori_loop(0, 20, lambda _, x: x + 0.01 * g.vector_field(x, -0.002, tr), x)
        return g.torque(x, -0.002)

    out = jax.vmap(one)(batch)
    expected = np.array([float(one(g)) for g in govs])
    np.testing.assert_allclose(np.asarray(out), expected, rtol=1e-12)
    assert len(set(np.round(expected, 12))) == len(values)
