"""PSS/E machines GENROE, GENSAE and GENTPJ (src/jaxdse/_models/machines.py).

The reference each module is compared with is written here from the PSS/E model equations in
plain NumPy, in OpenIPSL's state variables and sign conventions (GENTPJ's q-axis flux has the
opposite sign of the module's; its algebraic loop saturation -> X''_sat -> currents is solved by
``scipy.optimize.fsolve`` at every evaluation), and integrated by ``scipy.integrate.solve_ivp``
at tight tolerances for a terminal-voltage step and a ramp, Efd and Tm held. The modules run
through a jitted RK4 (one compile per class; parameters are traced leaves).
"""

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import fsolve

from jaxdse._models.machines import (
    GENROE,
    GENROU,
    GENSAE,
    GENTPJ,
    MACHINES,
    exponential_saturation,
    machine_from_dyr,
    saturation,
    saturation_coefficients,
)

W_S = 2 * math.pi * 60.0
ROU = dict(td0_1_s=6.5, td0_2_s=0.06, tq0_1_s=0.2, tq0_2_s=0.05, h_s=4.0, d_pu=0.5, xd_pu=1.8,
           xq_pu=1.75, xd1_pu=0.6, xq1_pu=0.8, x2_pu=0.23, xl_pu=0.15)
SAL = dict(td0_1_s=5.0, td0_2_s=0.05, tq0_2_s=0.1, h_s=3.0, d_pu=0.5, xd_pu=1.1, xq_pu=0.7,
           xd1_pu=0.3, x2_pu=0.25, xl_pu=0.15)
OP = (1.02, 0.3, 0.8, 0.3)                 # |V|, angle [rad], P, Q (current out of the machine)
DT = 1e-3


def phasors(vm, ang, p, q):
    v = vm * np.exp(1j * ang)
    i = np.conj((p + 1j * q) / v)
    return v.real, v.imag, i.real, i.imag


# --- the modules: RK4 with V(t) = (vm0 + dvm + vm_rate t) e^{j (ang0 + ang_rate t)} ----------

@eqx.filter_jit
def _rest(m, vr, vi, ir, ii):
    ss = m.steady_state(vr, vi, ir, ii)
    return ss, m.vector_field(ss.state, vr, vi, ss.efd_pu, ss.tm_pu)


@eqx.filter_jit
def _run(m, x0, efd, tm, v_args, n, dt, sub):
    """``n`` RK4 steps of ``dt``, each in ``sub`` (traced) substeps."""
    vm0, dvm, vm_rate, ang0, ang_rate = v_args
    h = dt / sub

    def volt(t):
        vm = vm0 + dvm + vm_rate * t
        a = ang0 + ang_rate * t
        return vm * jnp.cos(a), vm * jnp.sin(a)

    def f(x, t):
        return m.vector_field(x, *volt(t), efd, tm)

    def rk4(j, carry):
        x, t = carry
        k1 = f(x, t)
        k2 = f(x + 0.5 * h * k1, t + 0.5 * h)
        k3 = f(x + 0.5 * h * k2, t + 0.5 * h)
        k4 = f(x + h * k3, t + h)
        return x + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4), t + h

    def body(carry, _):
        x, t = carry
        x, _ = jax.lax.fori_loop(0, sub, rk4, (x, t))
        out = m.terminal(x, *volt(t + dt))
        return (x, t + dt), (jnp.stack([out.p_pu, out.q_pu]), x)

    _, (pq, xs) = jax.lax.scan(body, (x0, jnp.zeros(())), None, length=n)
    return pq, xs


def fastest_s(m):
    """The machine's shortest short-circuit subtransient time constant [s]: T''d0 X''/X'd and
    T''q0 X''/X'q (X_q for GENSAE, which has no q-axis transient winding)."""
    xq1 = m.xq_pu if isinstance(m, GENSAE) else m.xq1_pu
    return min(float(m.td0_2_s * m.x2_pu / m.xd1_pu), float(m.tq0_2_s * m.x2_pu / xq1))


def simulate(m, dvm=0.0, vm_rate=0.0, ang_rate=0.0, t_end=5.0, dt=DT, op=OP):
    """RK4 with the step split so that it is at most the fastest time constant (RK4 is stable
    to |lambda h| < 2.78; a drawn machine's can be near 1 ms)."""
    vm, ang, p, q = op
    ss, _ = _rest(m, *phasors(vm, ang, p, q))
    v_args = jnp.asarray([vm, dvm, vm_rate, ang, ang_rate], float)
    sub = max(1, math.ceil(dt / fastest_s(m)))
    pq, xs = _run(m, ss.state, ss.efd_pu, ss.tm_pu, v_args, int(round(t_end / dt)),
                  jnp.asarray(dt, float), jnp.asarray(sub))
    return np.asarray(pq), np.asarray(xs), ss


# --- references: the model equations in OpenIPSL's variables -----------------------------------

def _dq(re, im, delta):
    s, c = math.sin(delta), math.cos(delta)
    return re * s - im * c, re * c + im * s


def _quad_sat(p):
    a, b = saturation_coefficients(p["s10"], p["s12"])
    a, b = float(a), float(b)
    return lambda x: b * (x - a) ** 2 / x if x > a else 0.0


def _exp_sat(p):
    s10, s12 = p["s10"], p["s12"]
    if s10 <= 0 or s12 <= 0:
        return lambda x: 0.0
    e = math.log(s12 / s10) / math.log(1.2)
    return lambda x: s10 * x ** e


def _stator(psippd, psippq, ud, uq, ra, xdpp, xqpp):
    """id, iq from ud = psi''q + X''q iq - Ra id, uq = psi''d - X''d id - Ra iq."""
    i_d, i_q = np.linalg.solve([[-ra, xqpp], [-xdpp, -ra]], [ud - psippq, uq - psippd])
    return i_d, i_q


def genroe_reference(p, sat, volt):
    """GENROU/GENROE equations; states [Epq, Epd, PSIkd, PSIkq, delta, w]; OpenIPSL's PSIppq."""
    xd, xq, xpd, xpq, xpp, xl = p["xd_pu"], p["xq_pu"], p["xd1_pu"], p["xq1_pu"], p["x2_pu"], p["xl_pu"]
    k1d = (xpd - xpp) * (xd - xpd) / (xpd - xl) ** 2
    k1q = (xpq - xpp) * (xq - xpq) / (xpq - xl) ** 2
    k3d, k4d = (xpp - xl) / (xpd - xl), (xpd - xpp) / (xpd - xl)
    k3q, k4q = (xpp - xl) / (xpq - xl), (xpq - xpp) / (xpq - xl)

    def parts(t, x, efd, tm):
        epq, epd, psikd, psikq, delta, w = x
        ud, uq = _dq(*volt(t), delta)
        psippd = epq * k3d + psikd * k4d
        psippq = epd * k3q + psikq * k4q
        i_d, i_q = _stator(psippd, psippq, ud, uq, p["ra_pu"], xpp, xpp)
        se = sat(math.hypot(psippd, psippq))
        xadifd = k1d * (epq - psikd - (xpd - xl) * i_d) + epq + i_d * (xd - xpd) + se * psippd
        xaqilq = (k1q * (epd - psikq + (xpq - xl) * i_q) + epd - i_q * (xq - xpq)
                  + se * psippq * (xq - xl) / (xd - xl))
        psid, psiq = psippd - xpp * i_d, -psippq - xpp * i_q
        te = psid * i_q - psiq * i_d
        dx = [(efd - xadifd) / p["td0_1_s"], -xaqilq / p["tq0_1_s"],
              (epq - psikd - (xpd - xl) * i_d) / p["td0_2_s"],
              (epd - psikq + (xpq - xl) * i_q) / p["tq0_2_s"],
              W_S * (w - 1.0), (tm - te - p["d_pu"] * (w - 1.0)) / (2 * p["h_s"])]
        return dx, (i_d, i_q, delta)

    def to_ref(x):           # module state [E'q, psi_kd, E'd, psi_kq, delta, w]
        return [x[0], x[2], x[1], x[3], x[4], x[5]]

    return parts, to_ref


def gensae_reference(p, sat, volt):
    """GENSAE: states [Epq, PSIkd, PSIppq, delta, w]; saturation on |psi''|, both axes."""
    xd, xq, xpd, xpp, xl = p["xd_pu"], p["xq_pu"], p["xd1_pu"], p["x2_pu"], p["xl_pu"]
    k1d = (xpd - xpp) * (xd - xpd) / (xpd - xl) ** 2
    k3d, k4d = (xpp - xl) / (xpd - xl), (xpd - xpp) / (xpd - xl)

    def parts(t, x, efd, tm):
        epq, psikd, psippq, delta, w = x
        ud, uq = _dq(*volt(t), delta)
        psippd = epq * k3d + psikd * k4d
        i_d, i_q = _stator(psippd, psippq, ud, uq, p["ra_pu"], xpp, xpp)
        se = sat(math.hypot(psippd, psippq))
        xadifd = epq + k1d * (epq - psikd - (xpd - xl) * i_d) + (xd - xpd) * i_d + se * psippd
        psid, psiq = psippd - xpp * i_d, -psippq - xpp * i_q
        te = psid * i_q - psiq * i_d
        dx = [(efd - xadifd) / p["td0_1_s"], (epq - psikd - (xpd - xl) * i_d) / p["td0_2_s"],
              (-psippq + (xq - xpp) * i_q - psippq * (xq - xl) / (xd - xl) * se) / p["tq0_2_s"],
              W_S * (w - 1.0), (tm - te - p["d_pu"] * (w - 1.0)) / (2 * p["h_s"])]
        return dx, (i_d, i_q, delta)

    return parts, lambda x: list(x)


def gentpj_reference(p, sat, volt):
    """GENTPJ in OpenIPSL's form: states [Epq, Epd, PSIppd, PSIppq, delta, w] with
    psi_q = PSIppq - X''q_sat iq (PSIppq = -psi''q of the module); the saturation loop solved
    by fsolve on (id, iq)."""
    xd, xq, xpd, xpq, xpp, xl, ra, kis = (p["xd_pu"], p["xq_pu"], p["xd1_pu"], p["xq1_pu"],
                                          p["x2_pu"], p["xl_pu"], p["ra_pu"], p["kis"])

    def sats(ud, uq, i_d, i_q):
        psi_ag = math.hypot(uq + i_q * ra + i_d * xl, ud + i_d * ra - i_q * xl)
        s = sat(psi_ag + kis * math.hypot(i_d, i_q))
        return 1.0 + s, 1.0 + (xq / xd) * s

    def parts(t, x, efd, tm):
        epq, epd, psippd, psippq, delta, w = x
        ud, uq = _dq(*volt(t), delta)

        def resid(i):
            dsat, qsat = sats(ud, uq, *i)
            xdps, xqps = (xpp - xl) / dsat + xl, (xpp - xl) / qsat + xl
            psid, psiq = psippd - xdps * i[0], psippq - xqps * i[1]
            return [ud - (-psiq - ra * i[0]), uq - (psid - ra * i[1])]

        guess = _stator(psippd, -psippq, ud, uq, ra, xpp, xpp)
        with warnings.catch_warnings():          # "no further improvement": at round-off
            warnings.simplefilter("ignore", RuntimeWarning)
            i_d, i_q = fsolve(resid, guess, xtol=1e-14)
        assert max(abs(r) for r in resid([i_d, i_q])) < 1e-13
        dsat, qsat = sats(ud, uq, i_d, i_q)
        xdps, xqps = (xpp - xl) / dsat + xl, (xpp - xl) / qsat + xl
        eq1 = (-psippd * (xd - xpd) + epq * (xd - xpp)) / (xpd - xpp)
        ed1 = (psippq * (xq - xpq) + epd * (xq - xpp)) / (xpq - xpp)
        eq2 = (psippd - epq + i_d * (xpd - xpp) / dsat) * (xd - xpp) / (xpd - xpp)
        ed2 = -(epd + psippq) * (xq - xpp) / (xpq - xpp) - i_q * (xq - xpp) / qsat
        psid, psiq = psippd - xdps * i_d, psippq - xqps * i_q
        te = psid * i_q - psiq * i_d
        dx = [(efd - dsat * eq1) / p["td0_1_s"], -qsat * ed1 / p["tq0_1_s"],
              -dsat * (xpd - xpp) / (xd - xpp) * eq2 / p["td0_2_s"],
              qsat * (xpq - xpp) / (xq - xpp) * ed2 / p["tq0_2_s"],
              W_S * (w - 1.0), (tm - te - p["d_pu"] * (w - 1.0)) / (2 * p["h_s"])]
        return dx, (i_d, i_q, delta)

    def to_ref(x):           # module state [E'q, E'd, psi''d, psi''q, delta, w]
        return [x[0], x[1], x[2], -x[3], x[4], x[5]]

    return parts, to_ref


def reference_pq(m, kind, ss, dvm=0.0, vm_rate=0.0, ang_rate=0.0, t_end=5.0, op=OP):
    vm0, ang0 = op[0], op[1]

    def volt(t):
        vm, a = vm0 + dvm + vm_rate * t, ang0 + ang_rate * t
        return vm * math.cos(a), vm * math.sin(a)

    p = {f: float(getattr(m, f)) for f in m.__dataclass_fields__}
    build = {"GENROE": (genroe_reference, _exp_sat), "GENROU": (genroe_reference, _quad_sat),
             "GENSAE": (gensae_reference, _exp_sat), "GENTPJ": (gentpj_reference, _quad_sat)}
    ref, satf = build[kind]
    parts, to_ref = ref(p, satf(p), volt)
    efd, tm = float(ss.efd_pu), float(ss.tm_pu)
    x0 = to_ref([float(v) for v in ss.state])
    # the module's steady state is a rest point of the reference equations too
    d0, _ = parts(0.0, x0, efd, tm) if (dvm == 0 and vm_rate == 0 and ang_rate == 0) else (
        [0.0], None)
    assert max(abs(v) for v in d0) < 1e-9
    t_eval = DT * np.arange(1, int(round(t_end / DT)) + 1)
    sol = solve_ivp(lambda t, x: parts(t, x, efd, tm)[0], (0.0, t_end), x0, t_eval=t_eval,
                    method="LSODA", rtol=1e-10, atol=1e-12, max_step=0.01)
    assert sol.success
    out = []
    for k, t in enumerate(t_eval):
        _, (i_d, i_q, delta) = parts(t, sol.y[:, k], efd, tm)
        vr, vi = volt(t)
        s_, c_ = math.sin(delta), math.cos(delta)
        ir, ii = i_d * s_ + i_q * c_, -i_d * c_ + i_q * s_
        out.append((vr * ir + vi * ii, vi * ir - vr * ii))
    return np.array(out)


# --- (1) steady state and flat runs -----------------------------------------------------------

@st.composite
def machines(draw, cls):
    xl = draw(st.floats(0.05, 0.2))
    x2 = xl + draw(st.floats(0.03, 0.2))
    xd1 = x2 + draw(st.floats(0.05, 0.4))
    xd = xd1 + draw(st.floats(0.3, 1.5))
    s10 = draw(st.one_of(st.just(0.0), st.floats(0.02, 0.2)))
    kw = dict(td0_1_s=draw(st.floats(2, 10)), td0_2_s=draw(st.floats(0.02, 0.1)),
              tq0_2_s=draw(st.floats(0.02, 0.2)), h_s=draw(st.floats(2, 8)),
              d_pu=draw(st.floats(0, 2)), xd_pu=xd, xd1_pu=xd1, x2_pu=x2, xl_pu=xl, s10=s10,
              s12=s10 * draw(st.floats(1.5, 5.0)), ra_pu=draw(st.floats(0, 0.01)))
    if cls is GENSAE:
        kw["xq_pu"] = x2 + draw(st.floats(0.2, 1.0))
    else:
        xq1 = x2 + draw(st.floats(0.05, 0.6))
        kw.update(xq1_pu=xq1, xq_pu=xq1 + draw(st.floats(0.1, 1.2)),
                  tq0_1_s=draw(st.floats(0.3, 2.0)))
    if cls is GENTPJ:
        kw["kis"] = draw(st.floats(0, 0.1))
    return cls(**kw)


@pytest.mark.slow
@pytest.mark.parametrize("cls", [GENROE, GENSAE, GENTPJ])
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_steady_state_holds_and_a_flat_run_stays_flat(cls, data):
    m = data.draw(machines(cls))
    op = (data.draw(st.floats(0.95, 1.05)), data.draw(st.floats(-0.5, 0.5)),
          data.draw(st.floats(-0.2, 1.0)), data.draw(st.floats(-0.4, 0.6)))
    vr, vi, ir, ii = phasors(*op)
    ss, f0 = _rest(m, vr, vi, ir, ii)
    assert float(jnp.max(jnp.abs(f0))) < 1e-9
    out = m.terminal(ss.state, vr, vi)
    assert abs(float(out.i_re_pu) - ir) < 1e-9 and abs(float(out.i_im_pu) - ii) < 1e-9
    _, xs, _ = simulate(m, t_end=20.0, dt=0.01, op=op)
    assert np.max(np.abs(xs - np.asarray(ss.state)[None, :])) < 1e-6


def test_a_stiff_salient_machine_stays_flat():
    """A drawn GENSAE whose q-axis short-circuit time constant is 2.6 ms: flat for 20 s (the
    fixed 10 ms RK4 step it first ran with diverged, 2026-11-27)."""
    m = GENSAE(td0_1_s=2.0, td0_2_s=0.0625, tq0_2_s=0.03125, h_s=2.0, d_pu=0.0,
               xd_pu=1.33984375, xq_pu=1.08984375, xd1_pu=0.33984375, x2_pu=0.08984375,
               xl_pu=0.05859375)
    op = (1.0, 0.0, 1.0, 0.0)
    _, xs, ss = simulate(m, t_end=20.0, dt=0.01, op=op)
    assert np.max(np.abs(xs - np.asarray(ss.state)[None, :])) < 1e-6


# --- (2) against the references: voltage step and ramp -----------------------------------------

MODELS = {
    "GENROE": GENROE(**ROU, s10=0.09, s12=0.38, ra_pu=0.005),
    "GENSAE": GENSAE(**SAL, s10=0.1, s12=0.3, ra_pu=0.005),
    "GENTPJ": GENTPJ(**ROU, s10=0.09, s12=0.38, kis=0.06, ra_pu=0.005),
}
DISTURBANCES = {"voltage step -3 %": dict(dvm=-0.03),
                "voltage ramp and angle ramp": dict(vm_rate=-0.01, ang_rate=0.3)}
MAX_DIFF = {}


@pytest.mark.parametrize("kind", list(MODELS))
@pytest.mark.parametrize("dist", list(DISTURBANCES))
def test_matches_reference_equations(kind, dist):
    m = MODELS[kind]
    kw = DISTURBANCES[dist]
    pq, _, ss = simulate(m, t_end=4.0, **kw)
    ref = reference_pq(m, kind, ss, t_end=4.0, **kw)
    swing = np.max(np.abs(ref - ref[0]), axis=0)
    diff = np.max(np.abs(pq - ref))
    MAX_DIFF[(kind, dist)] = diff
    print(f"{kind} {dist}: max |PQ - reference| = {diff:.2e} pu (swing P {swing[0]:.3f}, "
          f"Q {swing[1]:.3f})")
    assert np.min(swing) > 1e-3
    assert diff < 1e-6


def test_genroe_without_saturation_is_genrou():
    a, _, _ = simulate(GENROE(**ROU, ra_pu=0.005), dvm=-0.03, t_end=2.0)
    b, _, _ = simulate(GENROU(**ROU, ra_pu=0.005), dvm=-0.03, t_end=2.0)
    assert np.max(np.abs(a - b)) < 1e-13            # two compiled programs: rounding only
    # with the same S(1.0), S(1.2) the two saturation curves differ between the points
    c, _, _ = simulate(GENROE(**ROU, s10=0.09, s12=0.38), dvm=-0.03, t_end=2.0)
    d, _, _ = simulate(GENROU(**ROU, s10=0.09, s12=0.38), dvm=-0.03, t_end=2.0)
    assert np.max(np.abs(c - d)) > 1e-4


# --- (3) closed forms ------------------------------------------------------------------------

def test_exponential_saturation_closed_form():
    s10, s12 = 0.09, 0.38
    a = math.log(s12 / s10) / math.log(1.2)
    for x in (0.5, 0.9, 1.0, 1.1, 1.2, 1.4):
        assert float(exponential_saturation(x, s10, s12)) == pytest.approx(s10 * x ** a, rel=1e-13)
    assert float(exponential_saturation(1.2, s10, s12)) == pytest.approx(s12, rel=1e-13)
    assert float(exponential_saturation(1.1, 0.0, 0.3)) == 0.0
    g = jax.grad(lambda x: exponential_saturation(x, s10, s12))(0.0)
    assert np.isfinite(float(g))


def test_gentpj_saturation_input_is_air_gap_flux_plus_kis_current():
    """At rest: Sat_d - 1 = S(|V + (Ra + jXl) I| + Kis |I|), the field voltage Sat_d E'q +
    (Xd - X'd) i_d; with Kis = 0 and no saturation the steady state is GENROU's (same Efd)."""
    m = MODELS["GENTPJ"]
    vr, vi, ir, ii = phasors(*OP)
    ss, _ = _rest(m, vr, vi, ir, ii)
    v, i = complex(vr, vi), complex(ir, ii)
    x = abs(v + complex(m.ra_pu, m.xl_pu) * i) + float(m.kis) * abs(i)
    a, b = saturation_coefficients(m.s10, m.s12)
    s = float(saturation(x, a, b))
    sat_d = 1.0 + s
    delta = float(ss.state[4])
    i_d = ir * math.sin(delta) - ii * math.cos(delta)
    assert float(ss.efd_pu) == pytest.approx(sat_d * float(ss.state[0]) + (1.8 - 0.6) * i_d,
                                             rel=1e-12)
    flat_tpj, _ = _rest(GENTPJ(**ROU), vr, vi, ir, ii)
    flat_rou, _ = _rest(GENROU(**ROU), vr, vi, ir, ii)
    assert float(flat_tpj.efd_pu) == pytest.approx(float(flat_rou.efd_pu), rel=1e-12)
    assert float(flat_tpj.state[4]) == pytest.approx(float(flat_rou.state[4]), rel=1e-12)


# --- (5) zero and invalid constants: refused in one line; gradients finite ---------------------

@pytest.mark.parametrize("cls,kw,message", [
    (GENROE, dict(ROU, td0_1_s=0.0), "td0_1_s must be > 0"),
    (GENSAE, dict(SAL, tq0_2_s=0.0), "tq0_2_s must be > 0"),
    (GENTPJ, dict(ROU, td0_2_s=0.0), "td0_2_s must be > 0"),
    (GENTPJ, dict(ROU, xd1_pu=0.23), "X'd and X'q other than X''d"),
    (GENSAE, dict(SAL, xd1_pu=0.15), "X'd and Xd other than Xl"),
    (GENTPJ, dict(ROU, kis=-0.1), "kis must be >= 0"),
])
def test_invalid_constants_are_refused_in_one_line(cls, kw, message):
    with pytest.raises(ValueError, match=message) as e:
        cls(**kw)
    assert "\n" not in str(e.value)


@pytest.mark.slow
@pytest.mark.parametrize("kind", list(MODELS))
def test_gradients_are_finite(kind):
    vr, vi, ir, ii = phasors(*OP)

    def loss(m):
        ss = m.steady_state(vr, vi, ir, ii)
        x1 = ss.state + 0.01 * m.vector_field(ss.state, 0.98 * vr, 0.98 * vi, ss.efd_pu, ss.tm_pu)
        return m.terminal(x1, vr, vi).p_pu + jnp.sum(m.vector_field(x1, vr, vi, ss.efd_pu, ss.tm_pu))

    grad = eqx.filter_jit(eqx.filter_grad(loss))
    grads = jax.tree_util.tree_leaves(grad(MODELS[kind]))
    assert all(np.all(np.isfinite(np.asarray(g))) for g in grads)
    unsat = {"GENROE": GENROE(**ROU), "GENSAE": GENSAE(**SAL), "GENTPJ": GENTPJ(**ROU)}[kind]
    grads = jax.tree_util.tree_leaves(grad(unsat))                      # S(1.0) = 0
    assert all(np.all(np.isfinite(np.asarray(g))) for g in grads)


def test_gentpj_derivative_through_the_saturation_loop_matches_finite_differences():
    m = MODELS["GENTPJ"]
    vr, vi, ir, ii = phasors(*OP)
    x = m.steady_state(vr, vi, ir, ii).state + jnp.asarray([0.01, -0.01, 0.005, 0.0, 0.02, 0.0])

    def p_of(kis, s12):
        mm = eqx.tree_at(lambda z: (z.kis, z.s12), m, (kis, s12))
        return mm.terminal(x, 0.97 * vr, 0.97 * vi).p_pu

    g = jax.jit(jax.grad(p_of, argnums=(0, 1)))(m.kis, m.s12)
    h = 1e-6
    fd = [(p_of(m.kis + h, m.s12) - p_of(m.kis - h, m.s12)) / (2 * h),
          (p_of(m.kis, m.s12 + h) - p_of(m.kis, m.s12 - h)) / (2 * h)]
    for a, b in zip(g, fd):
        assert abs(float(a)) > 1e-4
        assert float(a) == pytest.approx(float(b), rel=1e-6)


# --- (6) records -------------------------------------------------------------------------------

ROU_CONS = (6.5, 0.06, 0.2, 0.05, 4.0, 0.5, 1.8, 1.75, 0.6, 0.8, 0.23, 0.15, 0.09, 0.38)
SAL_CONS = (5.0, 0.05, 0.1, 3.0, 0.5, 1.1, 0.7, 0.3, 0.25, 0.15, 0.1, 0.3)
ROU_NAMES = ("td0_1_s", "td0_2_s", "tq0_1_s", "tq0_2_s", "h_s", "d_pu", "xd_pu", "xq_pu",
             "xd1_pu", "xq1_pu", "x2_pu", "xl_pu", "s10", "s12")
SAL_NAMES = ("td0_1_s", "td0_2_s", "tq0_2_s", "h_s", "d_pu", "xd_pu", "xq_pu", "xd1_pu",
             "x2_pu", "xl_pu", "s10", "s12")


def _dyr(tmp_path, lines):
    from jaxdse._io.psse import read_dyr

    path = tmp_path / "m.dyr"
    path.write_text("".join(lines))
    return read_dyr(str(path))


def _line(bus, model, cons):
    return f"{bus} '{model}' 1 " + " ".join(f"{c:g}" for c in cons) + " /\n"


def test_records_in_con_order(tmp_path):
    from jaxdse._io.psse import MACHINE_FIELDS

    if "GENROE" not in MACHINE_FIELDS:
        pytest.skip("the .dyr reader's machine table does not have GENROE/GENSAE yet")
    dyr = _dyr(tmp_path, [_line(1, "GENROE", ROU_CONS), _line(2, "GENSAE", SAL_CONS),
                          _line(3, "GENTPJ", ROU_CONS + (0.06,)), _line(4, "GENTPJ", ROU_CONS)])
    ms = [machine_from_dyr(r.model, r.params, ra_pu=0.005) for r in dyr.records]
    assert [type(m) for m in ms] == [GENROE, GENSAE, GENTPJ, GENTPJ]
    for m, names, cons in zip(ms, (ROU_NAMES, SAL_NAMES, ROU_NAMES, ROU_NAMES),
                              (ROU_CONS, SAL_CONS, ROU_CONS, ROU_CONS)):
        assert [float(getattr(m, f)) for f in names] == list(cons)
        assert float(m.ra_pu) == 0.005
    assert float(ms[2].kis) == 0.06 and float(ms[3].kis) == 0.0      # Kis may be omitted
    assert all(MACHINES[k] is c for k, c in (("GENROE", GENROE), ("GENSAE", GENSAE),
                                              ("GENTPJ", GENTPJ)))


@pytest.mark.parametrize("model,cons,message", [
    ("GENROE", ROU_CONS[:-1], "13 constants, expected 14"),
    ("GENSAE", SAL_CONS + (0.1,), "13 constants, expected 12"),
    ("GENTPJ", ROU_CONS + (0.1, 0.2), "16 constants, expected 14 or 15"),
])
def test_bad_record_lengths_are_refused_in_one_line(tmp_path, model, cons, message):
    from jaxdse._io.psse import MACHINE_FIELDS

    if model not in MACHINE_FIELDS:
        pytest.skip("the .dyr reader's machine table does not have GENROE/GENSAE yet")
    with pytest.raises(ValueError, match=message) as e:
        _dyr(tmp_path, [_line(1, model, cons)])
    assert "\n" not in str(e.value)


def test_bad_record_values_are_refused(tmp_path):
    from jaxdse._io.psse import MACHINE_FIELDS

    if "GENROE" not in MACHINE_FIELDS:
        pytest.skip("the .dyr reader's machine table does not have GENROE/GENSAE yet")
    bad = list(ROU_CONS)
    bad[0] = 0.0                                                       # T'do = 0
    rec = _dyr(tmp_path, [_line(1, "GENTPJ", bad)]).records[0]
    with pytest.raises(ValueError, match="GENTPJ: T'do must be > 0") as e:
        machine_from_dyr(rec.model, rec.params)
    assert "\n" not in str(e.value)
