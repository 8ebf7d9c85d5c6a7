"""Tests of the PSS/E alternator-rectifier exciters ESAC1A, EXAC1, EXAC2 and ESAC6A.

* steady state: ``initial_state`` holds (every derivative < 1e-9, Efd = Efd0) at several
  operating points (the three branches of FEX), for ACTIVSg2000 records, the defaults, zero
  time constants and random plausible parameter sets (hypothesis), and a 20 s run at fixed
  inputs stays flat;
* an independent reference: ESAC1A and ESAC6A written here from the block diagrams (PSS/E
  Model Library; IEEE Std 421.5-2005 AC1A, AC6A) in plain Python, integrated with SciPy's
  ``solve_ivp`` as the module is (same method and tolerances), on a Vt step and a Vt ramp that
  drive the limits; the largest Efd difference is printed and asserted;
* with no saturation, KC = KD = 0 and wide limits, every model reduces to lags: its Vref step
  response equals the closed-form transfer function's (``scipy.signal``);
* limits: the regulator limits hold on a large step and the non-windup limits let go at once;
  VE stays >= 0; EXAC2's field current limiter (VLR) and ESAC6A's (VFELIM) take over; ESAC6A's
  VR limits scale with Vt;
* zero time constants: finite values and parameter gradients; vmap equals a loop;
  ``exciter_from_dyr`` reads records in CON order and refuses bad ones in one line.

The module's vector field is compiled once per model class (parameters passed as one array),
and every simulation here runs through SciPy.
"""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import pytest
import scipy.signal as sig
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from jaxdse._models.base import ExciterInputs
from jaxdse._models.exciters import (
    ESAC1A,
    ESAC6A,
    EXAC1,
    EXAC2,
    EXCITER_FIELDS,
    EXCITERS,
    exciter_from_dyr,
)

CLASSES = {"ESAC1A": ESAC1A, "EXAC1": EXAC1, "EXAC2": EXAC2, "ESAC6A": ESAC6A}

RECORDS = {  # ACTIVSg2000 (Texas A&M synthetic grid), PSS/E CON order
    "ESAC1A": "0.025 0 0 313.407 0.05 18.1925 -18.192499 1.0724 0.013 1 0.2 0.4 1 5.5999 0.191 "
              "7.4665 1.7186 9 -9",
    "EXAC1": "0 0 0 400 0.05 5.2477 -5.2477 1.1 0.035 1 0.2469 0.5 1 2.7077 0.0366 3.6102 0.1831",
    "EXAC2": "0.05 1 1 1000 0.05 11.153 -11.153 1 25.8638 -25.8638 0.55 4 0 0.49 1 0 0 1 10 "
             "3.2649 1.0907 4.3532 1.1359",
    "ESAC6A": "0 575.606 17.4788 3 0.1399 0.9 9.08 -9.08 9.08 -9.08 1 100 0 10 0 0 0 0 1 5.0009 "
              "0.1209 6.6679 0.806",
}


def record(name):
    return exciter_from_dyr(name, [float(c) for c in RECORDS[name].split()])


def inputs_at(vt, ifd, vs=0.0):
    """Exciter inputs at terminal voltage ``vt`` and field current ``ifd`` (the AC exciters read
    Vt, Ifd and VOTHSG; the phasors are a consistent 0.8 pu load at 0.3 rad)."""
    v = vt * np.exp(0.3j)
    i = np.conj(0.8 / v) if vt > 0 else 0.0j
    return ExciterInputs(*(jnp.asarray(x, float) for x in (vt, v.real, v.imag, i.real, i.imag,
                                                           ifd, vs)))


OPS = [  # (Efd0, Vt, Ifd): KC·Ifd/VE in each branch of FEX for KC = 0.2 ... 0.6
    (1.2, 1.0, 1.25),
    (2.4, 0.97, 2.6),
    (1.5, 1.03, 4.0),
    (0.6, 1.0, 3.5),
]

ZERO_T = {
    "ESAC1A": ESAC1A(t_r_s=0.0, t_b_s=0.0, t_c_s=0.0, t_a_s=0.0, t_f_s=0.0),
    "EXAC1": EXAC1(t_r_s=0.0, t_b_s=0.0, t_c_s=0.0, t_a_s=0.0, t_f_s=0.0, kc=0.0),
    "EXAC2": EXAC2(t_r_s=0.0, t_b_s=0.0, t_c_s=0.0, t_a_s=0.0, t_f_s=0.0),
    "ESAC6A": ESAC6A(t_r_s=0.0, t_a_s=0.0, t_k_s=0.0, t_b_s=0.0, t_c_s=0.0, t_h_s=0.0,
                     t_j_s=0.0, kd=0.0),
}

STEADY_MODELS = {
    **{f"{n}-record": record(n) for n in RECORDS},
    **{f"{n}-default": cls() for n, cls in CLASSES.items()},
    **{f"{n}-zeroT": m for n, m in ZERO_T.items()},
    "ESAC1A-KC0.6": ESAC1A(kc=0.6, t_b_s=1.0, t_c_s=0.3, t_r_s=0.02),
    "EXAC2-KH0": EXAC2(kh=0.0, kb=1.0, kl=4.0, vlr_pu=14.0),
    "ESAC6A-VH-active": ESAC6A(vfe_lim_pu=2.0, kh=0.5),  # VH0 = KH (VFE0 - VFELIM) > 0
    "ESAC6A-TK": ESAC6A(t_k_s=3.0, t_a_s=17.0),
}


# --- the module, integrated by SciPy ------------------------------------------------------------

_COMPILED = {}


def module_rhs(model):
    """(f, p): ``f(p, x, u)`` -> (dx/dt, Efd) with u = [Vt, Ifd, VOTHSG, Vref], compiled once
    per model class (the parameters travel as one array p)."""
    leaves, treedef = jtu.tree_flatten(model)
    if treedef not in _COMPILED:
        def f(p, x, u):
            m = jtu.tree_unflatten(treedef, list(p))
            zero = 0.0 * u[0]  # the AC exciters read Vt, Ifd and VOTHSG only
            inputs = ExciterInputs(u[0], u[0], zero, zero, zero, u[1], u[2])
            return m.vector_field(x, inputs, u[3]), m.efd(x, inputs, u[3])

        _COMPILED[treedef] = jax.jit(f)
    return _COMPILED[treedef], np.array([float(v) for v in leaves])


def run(rhs, x0, t_end, t_eval, breaks=(), rtol=1e-10, atol=1e-12, method="DOP853"):
    """Integrate ``rhs(t, x)`` over [0, t_end], restarting at ``breaks`` (kinks of the
    inputs): the states at ``t_eval``."""
    edges = [0.0, *breaks, t_end]
    xs, x = [], np.asarray(x0, float)
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        last = k == len(edges) - 2
        sel = t_eval[(t_eval >= a) & ((t_eval < b) | last)]
        points = np.union1d(sel, [b])
        sol = solve_ivp(rhs, (a, b), x, method=method, rtol=rtol, atol=atol, t_eval=points)
        assert sol.success, sol.message
        xs.append(sol.y.T[np.isin(points, sel)])
        x = sol.y[:, -1]
    return np.vstack(xs)


def simulate(model, x0, vref, u_of_t, t_end, t_eval, **kw):
    """(Efd, states) of the module at ``t_eval``; ``u_of_t(t)`` -> (Vt, Ifd, VOTHSG, dVref)."""
    f, p = module_rhs(model)

    def u(t):
        vt, ifd, vs, dvref = u_of_t(t)
        return np.array([vt, ifd, vs, vref + dvref])

    xs = run(lambda t, x: np.asarray(f(p, x, u(t))[0]), x0, t_end, t_eval, **kw)
    efd = np.array([float(f(p, x, u(t))[1]) for t, x in zip(t_eval, xs)])
    return efd, xs


def steady(model, efd0, vt, ifd):
    x0, vref = model.initial_state(efd0, inputs_at(vt, ifd))
    return np.asarray(x0), float(vref)


# --- the independent reference: block diagrams written out -------------------------------------

def fex(i_n):
    """Rectifier regulation, IEEE Std 421.5-2005 Annex D."""
    if i_n <= 0.0:
        return 1.0
    if i_n <= 0.433:
        return 1.0 - 0.577 * i_n
    if i_n < 0.75:
        return math.sqrt(0.75 - i_n * i_n)
    if i_n <= 1.0:
        return 1.732 * (1.0 - i_n)
    return 0.0


def sat_times_v(v, e1, s1, e2, s2):
    """PSS/E quadratic saturation: SE(V)·V = B (V - A)^2 for V > A, through both points."""
    if s1 <= 0 or s2 <= 0 or v <= 0:
        return 0.0
    r = math.sqrt(e1 * s1 / (e2 * s2))  # = (E1 - A)/(E2 - A)
    a = (e1 - r * e2) / (1.0 - r)
    b = e2 * s2 / (e2 - a) ** 2
    return b * (v - a) ** 2 if v > a else 0.0


def hold(x, dx, lo, hi):
    """A state on a non-windup limit does not move further out."""
    return 0.0 if (x >= hi and dx > 0) or (x <= lo and dx < 0) else dx


class Reference:
    """The exciter alternator common to the AC types, and each regulator, from the diagrams."""

    def __init__(self, kind, **p):
        self.kind, self.p = kind, p

    def vfe(self, ve, ifd):
        p = self.p
        return p["kd"] * ifd + p["ke"] * ve + sat_times_v(ve, p["e1_pu"], p["se1"], p["e2_pu"],
                                                          p["se2"])

    def efd(self, x, ifd):
        ve = max(x[3], 0.0)
        return ve * fex(self.p["kc"] * ifd / ve) if ve > 0 else 0.0

    def rhs(self, x, vt, ifd, vref, vs=0.0, signals=False):
        """dx/dt; with ``signals``, (dx/dt, VR, VH) (VH = 0 for ESAC1A)."""
        p = self.p
        vh = 0.0
        ve = max(x[3], 0.0)
        vfe = self.vfe(ve, ifd)
        d = [0.0] * 5
        d[0] = (vt - x[0]) / p["t_r_s"]
        if self.kind == "ESAC1A":
            d[4] = (vfe - x[4]) / p["t_f_s"]
            err = vref + vs - x[0] - p["kf"] * d[4]
            d[1] = (err - x[1]) / p["t_b_s"]
            y = x[1] + p["t_c_s"] * d[1]
            d[2] = hold(x[2], (p["ka"] * y - x[2]) / p["t_a_s"], p["va_min_pu"], p["va_max_pu"])
            va = min(max(x[2], p["va_min_pu"]), p["va_max_pu"])
            vr = min(max(va, p["vr_min_pu"]), p["vr_max_pu"])
        else:  # ESAC6A
            target = p["ka"] * (vref + vs - x[0])  # KA (1 + s TK)/(1 + s TA), state x[1]
            d[1] = hold(x[1], (target - x[1]) / p["t_a_s"], p["va_min_pu"], p["va_max_pu"])
            va = x[1] + p["t_k_s"] / p["t_a_s"] * (target - x[1])
            va = min(max(va, p["va_min_pu"]), p["va_max_pu"])
            d[2] = (va - x[2]) / p["t_b_s"]
            y = x[2] + p["t_c_s"] * d[2]
            d[4] = (vfe - p["vfe_lim_pu"] - x[4]) / p["t_h_s"]
            vh = min(max(p["kh"] * (x[4] + p["t_j_s"] * d[4]), 0.0), p["vh_max_pu"])
            vr = min(max(y - vh, vt * p["vr_min_pu"]), vt * p["vr_max_pu"])
        d[3] = hold(x[3], (vr - vfe) / p["t_e_s"], 0.0, math.inf)
        return (d, vr, vh) if signals else d

    def initial(self, efd0, vt, ifd):
        """Steady state: VE from Efd0 by bisection on VE·FEX(KC·Ifd/VE) (increasing in VE)."""
        p = self.p
        ve = brentq(lambda v: v * fex(p["kc"] * ifd / v) - efd0, 1e-9, efd0 + 2 * p["kc"] * ifd
                    + 1.0, xtol=1e-15, rtol=1e-15)
        vfe = self.vfe(ve, ifd)
        if self.kind == "ESAC1A":
            return [vt, vfe / p["ka"], vfe, ve, vfe], vt + vfe / p["ka"]
        h = vfe - p["vfe_lim_pu"]
        va = vfe + min(max(p["kh"] * h, 0.0), p["vh_max_pu"])
        return [vt, va, va, ve, h], vt + va / p["ka"]


REF_PARAMS = {
    "ESAC1A": dict(t_r_s=0.02, t_b_s=0.5, t_c_s=0.2, ka=400.0, t_a_s=0.02, va_max_pu=8.0,
                   va_min_pu=-8.0, t_e_s=0.8, kf=0.03, t_f_s=1.0, kc=0.55, kd=0.38, ke=1.0,
                   e1_pu=4.18, se1=0.1, e2_pu=3.14, se2=0.03, vr_max_pu=6.03, vr_min_pu=-5.43),
    "ESAC6A": dict(t_r_s=0.02, ka=536.0, t_a_s=0.086, t_k_s=0.18, t_b_s=2.0, t_c_s=1.0,
                   va_max_pu=20.0, va_min_pu=-20.0, vr_max_pu=10.0, vr_min_pu=-8.0, t_e_s=1.0,
                   vfe_lim_pu=5.9, kh=20.0, vh_max_pu=3.0, t_h_s=0.08, t_j_s=0.02, kc=0.35,
                   kd=0.5, ke=1.6, e1_pu=7.4, se1=0.214, e2_pu=5.55, se2=0.044),
}
REF_OP = (2.4, 0.97, 2.6)  # Efd0, Vt0, Ifd (held)
SCENARIOS = {  # Vt(t): a step, and a ramp that stops
    "step": (lambda t: REF_OP[1] - 0.03, (), 5.0),
    "ramp": (lambda t: REF_OP[1] + 0.08 * min(t, 1.0), (1.0,), 4.0),
}


@pytest.mark.parametrize("scenario", list(SCENARIOS))
@pytest.mark.parametrize("name", list(REF_PARAMS))
def test_matches_independent_scipy_reference(name, scenario):
    params = REF_PARAMS[name]
    model, ref = CLASSES[name](**params), Reference(name, **params)
    efd0, vt0, ifd = REF_OP
    x0, vref = steady(model, efd0, vt0, ifd)
    r0, rvref = ref.initial(efd0, vt0, ifd)
    np.testing.assert_allclose(x0, r0, rtol=1e-11, atol=1e-11)
    assert vref == pytest.approx(rvref, abs=1e-12)
    vt_of_t, breaks, t_end = SCENARIOS[scenario]
    t = np.linspace(0.0, t_end, 1001)
    efd, _ = simulate(model, x0, vref, lambda s: (vt_of_t(s), ifd, 0.0, 0.0), t_end, t,
                      breaks=breaks)
    ys = run(lambda s, x: ref.rhs(x, vt_of_t(s), ifd, rvref), r0, t_end, t, breaks=breaks)
    efd_ref = np.array([ref.efd(x, ifd) for x in ys])
    diff = float(np.max(np.abs(efd - efd_ref)))
    print(f"{name} {scenario}: Efd {efd_ref.min():.3f} .. {efd_ref.max():.3f} pu, "
          f"max |Efd - reference| = {diff:.2e} pu")
    assert diff < 1e-6
    # the excursion reaches the limits: VR at VRMAX (step) or VRMIN (ramp, then VE at 0)
    vr, vh = np.array([ref.rhs(x, vt_of_t(s), ifd, rvref, signals=True)[1:]
                       for s, x in zip(t, ys)]).T
    scale = vt_of_t(t_end) if name == "ESAC6A" else 1.0
    if scenario == "step":
        assert np.max(vr) == pytest.approx(scale * params["vr_max_pu"], rel=1e-12)
        assert np.max(ys[:, 2 if name == "ESAC1A" else 1]) >= params["va_max_pu"]
    else:
        assert np.min(vr) == pytest.approx(scale * params["vr_min_pu"], rel=1e-12)
        assert np.min(efd_ref) == 0.0 and np.min(ys[:, 3]) > -1e-9
    if name == "ESAC6A":  # the field current limiter went through 0 < VH < VHMAX
        assert 0.0 < vh[0] < 3.0 and (np.max(vh) == 3.0 if scenario == "step" else
                                      np.min(vh) == 0.0)


# --- steady state -------------------------------------------------------------------------------

@pytest.mark.parametrize("name", list(STEADY_MODELS))
def test_initial_state_is_steady(name):
    model = STEADY_MODELS[name]
    f, p = module_rhs(model)
    for efd0, vt, ifd in OPS:
        x0, vref = steady(model, efd0, vt, ifd)
        assert x0.shape == (model.n_states,)
        d, efd = f(p, x0, np.array([vt, ifd, 0.0, vref]))
        assert np.max(np.abs(np.asarray(d))) < 1e-9, (name, efd0, np.asarray(d))
        assert float(efd) == pytest.approx(efd0, abs=1e-12)


def test_ve_from_efd_inverts_the_rectifier_on_every_branch():
    model = ESAC1A(kc=1.0)
    seen = set()
    for efd in [0.0, 0.05, 0.3, 0.57, 0.6, 1.0, 1.7, 1.74, 2.5, 5.0]:
        ifd = 1.0
        ve = float(model.ve_from_efd(efd, ifd))
        i_n = ifd / ve
        seen.add(0 if i_n <= 0.433 else 1 if i_n < 0.75 else 2)
        assert float(model.rectified(jnp.asarray(ve), ifd)) == pytest.approx(efd, abs=1e-13)
        assert ve * fex(i_n) == pytest.approx(efd, abs=1e-13)
    assert seen == {0, 1, 2}
    assert float(ESAC1A(kc=0.0).ve_from_efd(2.0, 3.0)) == 2.0  # FEX = 1
    assert float(model.rectified(jnp.asarray(0.0), 1.0)) == 0.0


def _plausible(draw, name):
    """Random plausible parameters of ``name`` and an operating point, with the limits placed
    around the steady state (a fraction of it to twice it beyond)."""
    tc = st.one_of(st.just(0.0), st.floats(0.01, 0.5))
    kw = dict(t_r_s=draw(st.one_of(st.just(0.0), st.floats(0.005, 0.05))),
              t_e_s=draw(st.floats(0.1, 2.0)), kc=draw(st.floats(0.0, 0.6)),
              kd=draw(st.floats(0.0, 2.0)), ke=draw(st.floats(0.3, 1.6)),
              e2_pu=draw(st.floats(2.0, 8.0)), se2=draw(st.floats(0.0, 1.5)))
    kw["e1_pu"] = 0.75 * kw["e2_pu"]
    kw["se1"] = kw["se2"] * draw(st.floats(0.05, 0.6))
    kw["ka"] = draw(st.floats(10.0, 1000.0))
    tb = draw(st.one_of(st.just(0.0), st.floats(0.05, 10.0)))
    kw.update(t_b_s=tb, t_c_s=tb * draw(st.floats(0.0, 1.0)))
    if name == "ESAC6A":
        kw.update(t_a_s=draw(tc), t_k_s=draw(st.floats(0.0, 1.0)), t_h_s=draw(tc),
                  t_j_s=draw(st.floats(0.0, 0.1)), kh=draw(st.floats(0.0, 50.0)),
                  vfe_lim_pu=draw(st.floats(0.0, 20.0)))
    else:
        kw.update(t_a_s=draw(tc), kf=draw(st.floats(0.0, 0.1)),
                  t_f_s=draw(st.one_of(st.just(0.0), st.floats(0.3, 2.0))))
    if name == "EXAC2":
        kw.update(kb=draw(st.floats(1.0, 30.0)), kh=draw(st.floats(0.0, 1.0)),
                  kl=draw(st.floats(0.5, 10.0)))
    efd0, vt = draw(st.floats(0.5, 4.0)), draw(st.floats(0.9, 1.1))
    ifd = efd0 * draw(st.floats(0.9, 2.0))
    wide = CLASSES[name](**kw, **({"vlr_pu": 1e3} if name == "EXAC2" else {}),
                         **({"vh_max_pu": 1e3} if name == "ESAC6A" else {}))
    x0, _ = wide.initial_state(efd0, inputs_at(vt, ifd))
    vfe0 = float(wide.vfe(x0[3], ifd))
    m = draw(st.floats(0.05, 2.0))  # margin to the limits, relative
    va0 = float(x0[2] if name != "ESAC6A" else x0[1])
    top = lambda v: abs(v) * (1.0 + m) + 0.1  # noqa: E731
    lims = dict(vr_max_pu=top(vfe0), vr_min_pu=-top(vfe0))
    if name == "ESAC6A":
        vh0 = va0 - vfe0
        lims = dict(vr_max_pu=top(vfe0) / vt, vr_min_pu=-top(vfe0) / vt, va_max_pu=top(va0),
                    va_min_pu=-top(va0), vh_max_pu=vh0 * (1.0 + m) + 0.1)
    elif name != "EXAC1":
        lims.update(va_max_pu=top(va0), va_min_pu=-top(va0))
    if name == "EXAC2":  # the field current limiter above VFE0
        lims.update(vlr_pu=vfe0 + (va0 - kw["kh"] * vfe0) / kw["kl"] * (1.0 + m) + 0.1)
    return CLASSES[name](**kw, **lims), efd0, vt, ifd


@settings(max_examples=10, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
@pytest.mark.parametrize("name", list(CLASSES))
def test_random_parameter_sets_are_steady_and_stay_flat(name, data):
    model, efd0, vt, ifd = _plausible(data.draw, name)
    x0, vref = steady(model, efd0, vt, ifd)
    f, p = module_rhs(model)
    u = np.array([vt, ifd, 0.0, vref])
    d, efd = f(p, x0, u)
    assert np.max(np.abs(np.asarray(d))) < 1e-9 and float(efd) == pytest.approx(efd0, abs=1e-12)
    t = np.linspace(0.0, 20.0, 21)
    xs = run(lambda s, x: np.asarray(f(p, x, u)[0]), x0, 20.0, t, rtol=1e-9, atol=1e-12,
             method="LSODA")
    assert np.max(np.abs(xs - x0)) < 1e-6
    assert abs(float(f(p, xs[-1], u)[1]) - efd0) < 1e-6


# --- reduced to lags: closed form -----------------------------------------------------------------

def _poly(*factors):
    out = np.array([1.0])
    for f in factors:
        out = np.polymul(out, f)
    return out


LINEAR_COMMON = dict(t_r_s=0.02, t_b_s=1.0, t_c_s=0.4, ka=200.0, t_a_s=0.05, kc=0.0, kd=0.0,
                     se1=0.0, se2=0.0)
LINEAR = {  # no saturation, KC = KD = 0 (FEX = 1, VFE = KE VE), limits out of reach
    "ESAC1A": ESAC1A(**LINEAR_COMMON, va_max_pu=99.0, va_min_pu=-99.0, vr_max_pu=99.0,
                     vr_min_pu=-99.0, t_e_s=0.8, kf=0.03, t_f_s=1.0, ke=1.0),
    "EXAC1": EXAC1(**LINEAR_COMMON, vr_max_pu=99.0, vr_min_pu=-99.0, t_e_s=0.5, kf=0.05,
                   t_f_s=0.7, ke=0.8),
    "EXAC2": EXAC2(**LINEAR_COMMON, va_max_pu=99.0, va_min_pu=-99.0, kb=25.0, vr_max_pu=999.0,
                   vr_min_pu=-999.0, t_e_s=0.6, kl=1.0, kh=0.5, kf=0.03, t_f_s=1.0, ke=1.0,
                   vlr_pu=1e4),
    "ESAC6A": ESAC6A(t_r_s=0.02, ka=100.0, t_a_s=0.1, t_k_s=0.05, t_b_s=2.0, t_c_s=1.0,
                     va_max_pu=99.0, va_min_pu=-99.0, vr_max_pu=99.0, vr_min_pu=-99.0, t_e_s=1.0,
                     kh=0.0, kc=0.0, kd=0.0, ke=1.6, se1=0.0, se2=0.0),
}


def transfer_vref_to_efd(name, m):
    """dEfd/dVref as (num, den), from the block diagram reduced to lags."""
    f = lambda a: float(getattr(m, a))  # noqa: E731
    ll = ([f("t_c_s"), 1.0], [f("t_b_s"), 1.0])
    if name == "ESAC6A":
        return (_poly([f("ka") * f("t_k_s"), f("ka")], ll[0]),
                _poly([f("t_a_s"), 1.0], ll[1], [f("t_e_s"), f("ke")]))
    exciter = [f("t_e_s"), f("ke")]
    gain = f("ka")
    if name == "EXAC2":  # VR = KB (VA - KH KE VE)
        exciter, gain = [f("t_e_s"), f("ke") * (1.0 + f("kb") * f("kh"))], gain * f("kb")
    fn, fd = _poly([gain], ll[0]), _poly([f("t_a_s"), 1.0], ll[1], exciter)
    hn, hd = [f("kf") * f("ke"), 0.0], [f("t_f_s"), 1.0]  # rate feedback from VFE = KE VE
    return _poly(fn, hd), np.polyadd(_poly(fd, hd), _poly(fn, hn))


@pytest.mark.parametrize("name", list(LINEAR))
def test_reduces_to_lags(name):
    model = LINEAR[name]
    efd0, vt, ifd = OPS[1]
    x0, vref = steady(model, efd0, vt, ifd)
    assert float(model.ve_from_efd(efd0, ifd)) == efd0  # FEX = 1
    delta, t = 0.01, np.linspace(0.0, 3.0, 601)
    efd, _ = simulate(model, x0, vref, lambda s: (vt, ifd, 0.0, delta), 3.0, t)
    _, y = sig.step(transfer_vref_to_efd(name, model), T=t)
    assert np.max(np.abs(efd - efd0)) > 0.05  # the step is seen
    np.testing.assert_allclose(efd, efd0 + delta * y, atol=1e-7, rtol=0)


# --- limits -----------------------------------------------------------------------------------

LOOSE = dict(rtol=1e-9, atol=1e-11, method="RK45")


def hold_then(model, x0, vref, dvref, t_end, vt=0.97, ifd=2.6, n=101):
    t = np.linspace(0.0, t_end, n)
    return simulate(model, x0, vref, lambda s: (vt, ifd, 0.0, dvref), t_end, t, **LOOSE)


def vr_vfe(model, x, vref, vt=0.97, ifd=2.6):
    return tuple(float(v) for v in model.vr_vfe(jnp.asarray(x), inputs_at(vt, ifd), vref))


@pytest.mark.parametrize("cls", [ESAC1A, EXAC1])
def test_ac1_regulator_limits_and_exciter_floor(cls):
    params = dict(REF_PARAMS["ESAC1A"])
    if cls is EXAC1:
        params = {k: v for k, v in params.items() if not k.startswith("va_")}
    model = cls(**params)
    x0, vref = steady(model, *REF_OP)
    top = 8.0 if cls is ESAC1A else 6.03  # the state 2 limit: VAMAX, or VRMAX for EXAC1
    _, xs = hold_then(model, x0, vref, 0.5, 1.0)
    assert top <= xs[-1, 2] < top + 1e-4  # held at its limit, within a step (windup: KA·u ~ 200)
    vr, vfe = vr_vfe(model, xs[-1], vref + 0.5)
    assert vr == 6.03  # VRMAX reaches the exciter
    d = model.vector_field(jnp.asarray(xs[-1]), inputs_at(0.97, 2.6), vref + 0.5)
    assert float(d[3]) == pytest.approx((6.03 - vfe) / 0.8, rel=1e-12)
    _, xs2 = hold_then(model, xs[-1], vref, -2.0, 0.05, n=11)  # KA·y < 0 at once
    assert xs2[1, 2] < top - 1.0  # non-windup: leaves the limit at once (windup: at ~KA·u)
    efd3, xs3 = hold_then(model, xs[-1], vref, -0.5, 3.0)
    assert vr_vfe(model, xs3[-1], vref - 0.5)[0] == -5.43  # VRMIN
    assert xs3[:, 3].min() > -1e-9 and efd3.min() >= 0.0 and efd3[-1] == 0.0  # VE >= 0
    efd4, _ = hold_then(model, xs3[-1], vref, 2.0, 0.3, n=31)
    assert efd4[-1] > 0.2  # VE leaves its floor as soon as VR > VFE


def test_exac2_field_current_limiter_takes_over():
    base = EXAC2(kl=10.0)
    efd0, vt, ifd = REF_OP
    vfe0 = float(base.vfe(base.ve_from_efd(efd0, ifd), ifd))
    model = eqx.tree_at(lambda m: m.vlr_pu, base, jnp.asarray(vfe0 + 0.5))
    x0, vref = steady(model, efd0, vt, ifd)
    _, xs = hold_then(model, x0, vref, 0.3, 8.0)
    vr, vfe = vr_vfe(model, xs[-1], vref + 0.3)
    kbkl = 25.0 * 10.0
    assert vfe == pytest.approx(kbkl * (vfe0 + 0.5) / (1.0 + kbkl), abs=1e-6)  # VR = KB KL (VLR - VFE)
    assert vr == pytest.approx(vfe, abs=1e-4) and vr < 105.0  # TE dVE/dt = VR - VFE ~ 0
    assert 8.0 <= xs[-1, 2] < 8.0 + 1e-4  # VA held at VAMAX meanwhile (non-windup)
    _, xs2 = hold_then(model, xs[-1], vref, 0.0, 3.0)  # back to the set point: the VA path again
    vr2, vfe2 = vr_vfe(model, xs2[-1], vref)
    assert xs2[-1, 2] - 1.0 * vfe2 < 10.0 * (vfe0 + 0.5 - vfe2)  # VA - KH VFE < VL
    assert vr2 == pytest.approx(25.0 * (xs2[-1, 2] - vfe2), rel=1e-12) and vfe2 < vfe - 0.1


def test_esac6a_limits():
    efd0, vt, ifd = REF_OP
    model = ESAC6A(kh=0.0, t_b_s=0.5, t_c_s=0.2, va_max_pu=20.0, va_min_pu=-20.0, vr_max_pu=9.0)
    x0, vref = steady(model, efd0, vt, ifd)
    _, xs = hold_then(model, x0, vref, 0.5, 2.0)
    assert 20.0 <= xs[-1, 1] < 20.0 + 1e-4  # VA's lag state held at VAMAX
    for v in (0.9, 0.97, 1.05):  # VR's limits follow Vt
        assert vr_vfe(model, xs[-1], vref + 0.5, vt=v)[0] == pytest.approx(9.0 * v, rel=1e-14)
    _, xs2 = hold_then(model, xs[-1], vref, -2.0, 0.05, n=11)
    assert xs2[1, 1] < 19.0  # lets go at once
    # the field current limiter: VA at VAMAX, VR = VA - KH (VFE - VFELIM) = VFE
    vfe0 = float(model.vfe(model.ve_from_efd(efd0, ifd), ifd))
    limited = ESAC6A(vfe_lim_pu=vfe0 + 0.3, t_b_s=0.2, t_c_s=0.1)  # KH = 92, VAMAX = 75
    x0, vref = steady(limited, efd0, vt, ifd)
    _, xs = hold_then(limited, x0, vref, 0.2, 6.0)
    vr, vfe = vr_vfe(limited, xs[-1], vref + 0.2)
    assert vfe == pytest.approx((75.0 + 92.0 * (vfe0 + 0.3)) / 93.0, abs=1e-6)
    assert vr == pytest.approx(vfe, abs=1e-4)


# --- zero time constants, gradients, vmap -------------------------------------------------------

@eqx.filter_jit
@eqx.filter_value_and_grad
def _loss(model, efd0, inputs):
    """Initial state, an Euler step after a step in Vref and Vt, Efd and the derivatives."""
    x, vref = model.initial_state(efd0, inputs)
    stepped = inputs._replace(vt_pu=inputs.vt_pu - 0.01)
    d = model.vector_field(x, stepped, vref + 0.02)
    x = x + 0.01 * d
    return (vref + jnp.sum(d) + jnp.sum(model.vector_field(x, stepped, vref))
            + model.efd(x, stepped, vref + 0.02))


@pytest.mark.slow
@pytest.mark.parametrize("name", list(ZERO_T))
def test_zero_time_constants_no_nan(name):
    model = ZERO_T[name]
    for efd0, vt, ifd in OPS[1:3]:
        value, grads = _loss(model, jnp.asarray(efd0), inputs_at(vt, ifd))
        assert np.isfinite(float(value))
        leaves = jtu.tree_leaves(grads)
        assert leaves and all(bool(jnp.all(jnp.isfinite(g))) for g in leaves)
        assert sum(float(jnp.abs(g)) > 0 for g in leaves) >= 4
    # a dead exciter (VE = 0) and a terminal at 0: EFD = 0, gradients finite
    x0, vref = model.initial_state(1.0, inputs_at(1.0, 1.0))
    dead = inputs_at(0.0, 1.0)

    def f(m):
        x = x0.at[3].set(0.0)
        return m.efd(x, dead, vref) + jnp.sum(m.vector_field(x, dead, vref))

    assert float(model.efd(x0.at[3].set(0.0), dead, vref)) == 0.0
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in jtu.tree_leaves(eqx.filter_grad(f)(model)))


@pytest.mark.parametrize("name", list(CLASSES))
def test_vmap_over_parameter_sets_equals_loop(name):
    models = [CLASSES[name](), record(name), ZERO_T[name], LINEAR[name]]
    stacked = jtu.tree_map(lambda *xs: jnp.stack(xs), *models)
    inputs = inputs_at(0.97, 2.6)

    def one(m):
        x0, vref = m.initial_state(2.4, inputs)
        x = x0 * (1.0 + 0.01 * jnp.arange(m.n_states)) + 0.003
        return x0, vref, m.vector_field(x, inputs, vref + 0.01), m.efd(x, inputs, vref + 0.01)

    batched = jax.jit(jax.vmap(one))(stacked)
    for k, m in enumerate(models):
        for b, r in zip(batched, one(m)):
            np.testing.assert_allclose(np.asarray(b[k]), np.asarray(r), rtol=1e-13, atol=1e-13)


# --- PSS/E records ----------------------------------------------------------------------------

def test_records_parse_in_con_order():
    for name in RECORDS:
        model = record(name)
        assert type(model) is EXCITERS[name] and name in EXCITER_FIELDS
        assert len(RECORDS[name].split()) == len(EXCITER_FIELDS[name])
    m = record("ESAC1A")
    assert (float(m.t_r_s), float(m.ka), float(m.va_max_pu), float(m.t_e_s)) == \
        (0.025, 313.407, 18.1925, 1.0724)
    assert (float(m.kc), float(m.kd), float(m.se2), float(m.vr_max_pu), float(m.vr_min_pu)) == \
        (0.2, 0.4, 1.7186, 9.0, -9.0)
    m = record("EXAC1")
    assert (float(m.vr_max_pu), float(m.t_e_s), float(m.kf), float(m.kc), float(m.e2_pu)) == \
        (5.2477, 1.1, 0.035, 0.2469, 3.6102)
    m = record("EXAC2")
    assert (float(m.kb), float(m.vr_max_pu), float(m.t_e_s), float(m.kl), float(m.kh)) == \
        (1.0, 25.8638, 0.55, 4.0, 0.0)
    assert (float(m.kf), float(m.t_f_s), float(m.ke), float(m.vlr_pu), float(m.se1)) == \
        (0.49, 1.0, 1.0, 10.0, 1.0907)
    m = record("ESAC6A")
    assert (float(m.ka), float(m.t_a_s), float(m.t_k_s), float(m.t_b_s), float(m.t_c_s)) == \
        (575.606, 17.4788, 3.0, 0.1399, 0.9)
    assert (float(m.vfe_lim_pu), float(m.kh), float(m.vh_max_pu), float(m.ke), float(m.se2)) == \
        (100.0, 0.0, 10.0, 1.0, 0.806)


def _cons(name, **changes):
    cons = [float(c) for c in RECORDS[name].split()]
    for con, value in changes.items():
        cons[EXCITER_FIELDS[name].index(con)] = value
    return cons


@pytest.mark.parametrize("name, cons, match", [
    ("ESAC1A", _cons("ESAC1A")[:-1], "expected 19 constants"),
    ("EXAC1", [*_cons("EXAC1"), 1.0], "expected 17 constants"),
    ("EXAC2", _cons("EXAC2")[:20], "expected 23 constants"),
    ("ESAC6A", _cons("ESAC6A", KH=float("nan")), "non-finite constant"),
    ("ESAC1A", _cons("ESAC1A", TE=0.0), r"TE must be > 0"),
    ("EXAC1", _cons("EXAC1", TA=-0.1), r"TA must be >= 0"),
    ("EXAC2", _cons("EXAC2", KB=0.0), r"KB must be > 0"),
    ("ESAC6A", _cons("ESAC6A", KA=0.0), r"KA must be > 0"),
    ("ESAC1A", _cons("ESAC1A", VRMAX=-10.0), "VRMAX"),
    ("ESAC6A", _cons("ESAC6A", VAMAX=-10.0), "VAMAX"),
    ("ESAC6A", _cons("ESAC6A", KC=-0.1), r"KC must be >= 0"),
])
def test_exciter_from_dyr_refuses(name, cons, match):
    with pytest.raises(ValueError, match=match) as info:
        exciter_from_dyr(name, cons)
    assert "\n" not in str(info.value) and str(info.value).startswith(name)
