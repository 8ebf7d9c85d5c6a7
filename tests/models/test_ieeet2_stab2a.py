"""PSS/E IEEET2 (exciter, src/jaxdse/_models/exciters/dc.py) and STAB2A (stabiliser,
src/jaxdse/_models/stabilisers.py), the two models of the Nordic 44 case.

ANDES (2.0) has neither model, so the independent reference is written here from the PSS/E
Model Library block diagrams, not from the modules:

* IEEET2: a plain NumPy right-hand side (VM lag, regulator KA/(1 + s TA) with non-windup limits
  as IEEE 421.5 Annex E draws them, the exciter TE dEFD/dt = VR - (KE + SE(EFD)) EFD with the
  quadratic saturation written anew, and the rate feedback s KF/((1 + s TF1)(1 + s TF2)) from
  VR as one ``scipy.signal.tf2ss`` realisation), integrated by ``solve_ivp`` like the module on
  a Vt step and ramp that drive VR to VRMAX and back; the linear part against
  ``scipy.signal.step`` of the diagram's transfer function (also with TA = 0, where the loop is
  algebraic);
* STAB2A: the diagram's blocks from PELEC to the output, each realised by ``tf2ss`` and
  connected in series and parallel as drawn, integrated by ``solve_ivp``, then clipped to
  +-HLIM, on a PELEC step and ramp that reach both limits.

Plus: the steady state holds and a 20 s run stays flat, the records of the Nordic 44 case
(inline below) parse in CON order, bad records are refused in one line naming the CON, the VR
limit check names VRMAX, and a GENROU + IEEET2 + STAB2A unit starts at rest.
"""

import cmath
import functools
import math

import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import pytest
import scipy.signal as sig
from scipy.integrate import solve_ivp

from jaxdse._dyr.limits import Start, describe, exciter_crossings
from jaxdse._dyr.unit import DyrUnit, UnitInputs
from jaxdse._models.base import ExciterInputs, StabiliserInputs
from jaxdse._models.exciters import EXCITER_FIELDS, EXCITERS, IEEET2, exciter_from_dyr
from jaxdse._models.machines import GENROU
from jaxdse._models.stabilisers import (
    STAB2A,
    STABILISER_FIELDS,
    STABILISER_ICONS,
    STABILISERS,
    stabiliser_from_dyr,
)

# Nordic 44 (N44_BC.dyr as ANDES 2.0 ships it), CONs after the machine ID
IEEET2_N44 = (0.0, 729.0, 0.04, 5.32, -4.05, 1.0, 0.44, 0.0667, 2.0, 0.44, 6.5, 0.054, 8.0, 0.202)
STAB2A_N44 = {"3000": (1.0, 2.0, 0.0, 2.0, 0.55, 1.0, 0.01, 0.03),
              "3115": (1.0, 4.5, 0.87, 2.0, 0.087, 1.0, 0.01, 0.04)}


# --- operating points ---------------------------------------------------------------------------

def exc_u(vt=1.02, angle=0.3, p=0.8, q=0.3, ifd=2.2, vs=0.0, vref=0.0, vt0=None):
    """[vt, v_re, v_im, i_re, i_im, ifd, vs, vref]: current from P, Q at ``vt0`` (default vt)."""
    v0 = (vt if vt0 is None else vt0) * cmath.exp(1j * angle)
    i = ((p + 1j * q) / v0).conjugate()
    v = vt * cmath.exp(1j * angle)
    return np.array([vt, v.real, v.imag, i.real, i.imag, ifd, vs, vref])


EFD0 = 2.2


# --- the modules through one jitted function per structure ---------------------------------------

@functools.cache
def _exc_compiled(treedef):
    def unpack(p, u):
        return jtu.tree_unflatten(treedef, list(p)), ExciterInputs(*(u[k] for k in range(7)))

    @jax.jit
    def rhs(p, x, u):
        m, inp = unpack(p, u)
        return m.vector_field(x, inp, u[7])

    @jax.jit
    def init(p, efd0, u):
        m, inp = unpack(p, u)
        return m.initial_state(efd0, inp)

    return rhs, init


def stab_inputs(pe, vt=1.0):
    z = jnp.zeros(())
    return StabiliserInputs(z, z, jnp.asarray(pe, float), z, jnp.asarray(vt, float), z)


@functools.cache
def _stab_compiled(treedef):
    @jax.jit
    def rhs(p, x, pe):
        return jtu.tree_unflatten(treedef, list(p)).vector_field(x, stab_inputs(pe))

    @jax.jit
    def out(p, x, pe):
        return jtu.tree_unflatten(treedef, list(p)).output(x, stab_inputs(pe))

    @jax.jit
    def init(p, pe):
        return jtu.tree_unflatten(treedef, list(p)).initial_state(stab_inputs(pe))

    return rhs, out, init


def packed(model):
    leaves, treedef = jtu.tree_flatten(model)
    return np.array([float(x) for x in leaves]), treedef


def integrate(rhs, x0, t_eval, breaks=(), method="DOP853", rtol=1e-11, atol=1e-13):
    """States at ``t_eval``, integrating piecewise between the input's breakpoints."""
    t_eval = np.asarray(t_eval)
    edges = [0.0, *[b for b in breaks if 0 < b < t_eval[-1]], float(t_eval[-1])]
    x, out = np.asarray(x0, float), []
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        last = k == len(edges) - 2
        ts = t_eval[(t_eval >= a) & ((t_eval < b) | (last & (t_eval <= b)))]
        def seg(s, y, a=a, b=b):  # the input as on the open segment (a step at a or b not seen early)
            return rhs(min(max(s, a + 1e-12), b - 1e-12), y)

        sol = solve_ivp(seg, (a, b), x, method=method, rtol=rtol, atol=atol, dense_output=True)
        assert sol.success, sol.message
        out += [sol.sol(t) for t in ts]
        x = sol.y[:, -1]
    return np.asarray(out)


def step_ramp(x0, step, t_step, ramp, ramp_from, ramp_to):
    """x0, a step at ``t_step``, then a ramp of ``ramp`` over [ramp_from, ramp_to]; breakpoints."""
    def f(t):
        frac = min(max((t - ramp_from) / (ramp_to - ramp_from), 0.0), 1.0)
        return x0 + (step if t >= t_step else 0.0) + ramp * frac
    return f, (t_step, ramp_from, ramp_to)


# --- IEEET2: the reference from the diagram --------------------------------------------------------

def _se_x(x, e1, s1, e2, s2):
    """SE(x)·x of the PSS/E quadratic saturation through (E1, SE1), (E2, SE2): B (x - A)^2, x > A."""
    if not (s1 > 0 and s2 > 0):
        return 0.0
    a = math.sqrt(s1 * e1 / (s2 * e2))
    big_a = (a * e2 - e1) / (a - 1.0)
    big_b = s2 * e2 / (e2 - big_a) ** 2
    return big_b * (x - big_a) ** 2 if x > big_a and x > 0 else 0.0


class RefIEEET2:
    """IEEET2 from the PSS/E diagram (TA > 0, TR > 0); states [VM, VR, EFD, feedback (tf2ss)]."""

    def __init__(self, c):
        self.c = c
        num = [c["KF"], 0.0]
        den = np.polymul([c["TF1"], 1.0], [c["TF2"], 1.0])
        self.fa, self.fb, self.fc, self.fd = sig.tf2ss(num, den)

    def sat(self, efd):
        c = self.c
        return _se_x(efd, c["E1"], c["SE(E1)"], c["E2"], c["SE(E2)"])

    def rhs(self, x, vt, vref, vs=0.0):
        c = self.c
        vm, vr, efd, xf = x[0], x[1], x[2], x[3:]
        vf = float((self.fc @ xf)[0] + self.fd[0, 0] * vr)
        u = vref + vs - vm - vf
        d_vr = (c["KA"] * u - vr) / c["TA"]
        if (vr >= c["VRMAX"] and d_vr > 0) or (vr <= c["VRMIN"] and d_vr < 0):
            d_vr = 0.0  # non-windup (IEEE 421.5 Annex E)
        vr_out = min(max(vr, c["VRMIN"]), c["VRMAX"])
        d_efd = (vr_out - c["KE"] * efd - self.sat(efd)) / c["TE"]
        d_f = self.fa @ xf + self.fb[:, 0] * vr_out
        return np.concatenate([[(vt - vm) / c["TR"], d_vr, d_efd], d_f])

    def init(self, vt, efd0):
        c = self.c
        vr0 = c["KE"] * efd0 + self.sat(efd0)
        xf0 = -np.linalg.solve(self.fa, self.fb[:, 0]) * vr0
        return np.concatenate([[vt, vr0, efd0], xf0]), vt + vr0 / c["KA"]


def cons(model, name):
    from jaxdse._models.exciters import _ATTRIBUTES
    return {con: float(getattr(model, attr)) for con, attr in zip(EXCITER_FIELDS[name], _ATTRIBUTES[name])}


IEEET2_CASES = {
    "nordic44": exciter_from_dyr("IEEET2", (0.02,) + IEEET2_N44[1:]),  # TR 0 -> 0.02 (the reference's VM lag)
    "saturated": IEEET2(t_r_s=0.02, ka=50.0, t_a_s=0.05, vr_max_pu=3.2, vr_min_pu=-3.0, ke=0.9,
                        t_e_s=0.5, kf=0.04, t_f1_s=0.8, t_f2_s=0.3, e1_pu=1.8, se1=0.05,
                        e2_pu=2.6, se2=0.3),
}


@pytest.mark.parametrize("name", list(IEEET2_CASES))
def test_ieeet2_matches_scipy_reference_with_vr_limit(name):
    model = IEEET2_CASES[name]
    ref = RefIEEET2(cons(model, "IEEET2"))
    vt0 = 1.02
    p, treedef = packed(model)
    rhs, init = _exc_compiled(treedef)
    x0, vref = init(p, EFD0, exc_u(vt0))
    x0, vref = np.asarray(x0), float(vref)
    xr0, vref_r = ref.init(vt0, EFD0)
    assert vref == pytest.approx(vref_r, abs=1e-13)
    # Vt down 3 % at 0.5 s (VR to VRMAX), back up by a ramp over [2, 2.5] s (VR leaves it)
    vt, breaks = step_ramp(vt0, -0.03, 0.5, 0.05, 2.0, 2.5)
    t = np.linspace(0.0, 5.0, 501)
    xs = integrate(lambda s, x: np.asarray(rhs(p, x, exc_u(vt(s), vref=vref, vt0=vt0))), x0, t, breaks)
    xr = integrate(lambda s, x: ref.rhs(x, vt(s), vref_r), xr0, t, breaks)
    efd, efd_r = xs[:, 3], xr[:, 2]
    vr, vr_r = np.clip(xs[:, 2], model.vr_min_pu, model.vr_max_pu), np.clip(xr[:, 1], model.vr_min_pu,
                                                                           model.vr_max_pu)
    diff = max(float(np.max(np.abs(efd - efd_r))), float(np.max(np.abs(vr - vr_r))))
    print(f"\nIEEET2 {name}: EFD moves {np.ptp(efd):.3f} pu, VR at VRMAX for "
          f"{np.mean(vr >= float(model.vr_max_pu) - 1e-9) * 5.0:.2f} s; largest difference {diff:.1e} pu")
    assert np.any(vr >= float(model.vr_max_pu) - 1e-9)  # the limit is reached
    assert xs[:, 2].max() <= float(model.vr_max_pu) + 1e-6  # and holds (non-windup)
    assert vr[-1] < float(model.vr_max_pu) - 0.1  # and is left
    assert np.ptp(efd) > 0.1
    assert diff < 1e-7


def _poly(*factors):
    out = np.array([1.0])
    for f in factors:
        out = np.polymul(out, f)
    return out


def ieeet2_transfer(c):
    """dEFD/dVref of the linear diagram (no saturation, no limit), TR = 0."""
    fn, fd = [c["KF"], 0.0], _poly([c["TF1"], 1.0], [c["TF2"], 1.0])
    an, ad = [c["KA"]], [c["TA"], 1.0]
    vr_n, vr_d = _poly(an, fd), np.polyadd(_poly(ad, fd), _poly(an, fn))  # A/(1 + A F)
    return vr_n, _poly(vr_d, [c["TE"], c["KE"]])


LINEAR = {
    "TA>0": IEEET2(ka=40.0, t_a_s=0.05, vr_max_pu=50.0, vr_min_pu=-50.0, ke=1.0, t_e_s=0.5,
                   kf=0.06, t_f1_s=1.0, t_f2_s=0.2, se1=0.0, se2=0.0),
    "TA=0": IEEET2(ka=40.0, t_a_s=0.0, vr_max_pu=50.0, vr_min_pu=-50.0, ke=1.0, t_e_s=0.5,
                   kf=0.06, t_f1_s=1.0, t_f2_s=0.2, se1=0.0, se2=0.0),
    "TA=0, TF2=0": IEEET2(ka=40.0, t_a_s=0.0, vr_max_pu=50.0, vr_min_pu=-50.0, ke=1.0, t_e_s=0.5,
                          kf=0.06, t_f1_s=1.0, t_f2_s=0.0, se1=0.0, se2=0.0),
    "TF1=0": IEEET2(ka=40.0, t_a_s=0.05, vr_max_pu=50.0, vr_min_pu=-50.0, ke=1.0, t_e_s=0.5,
                    kf=0.06, t_f1_s=0.0, t_f2_s=0.7, se1=0.0, se2=0.0),
}


@pytest.mark.parametrize("name", list(LINEAR))
def test_ieeet2_small_step_matches_transfer_function(name):
    model, delta, vt0 = LINEAR[name], 0.004, 1.0
    c = cons(model, "IEEET2")
    p, treedef = packed(model)
    rhs, init = _exc_compiled(treedef)
    x0, vref = init(p, EFD0, exc_u(vt0))
    t = np.linspace(0.0, 2.0, 201)
    xs = integrate(lambda s, x: np.asarray(rhs(p, x, exc_u(vt0, vref=float(vref) + delta))), x0, t,
                   method="Radau", rtol=1e-10, atol=1e-12)
    _, y = sig.step(ieeet2_transfer(c), T=t)
    assert np.ptp(xs[:, 3]) > 0.05
    np.testing.assert_allclose(xs[:, 3], EFD0 + delta * y, atol=1e-7, rtol=0)


# --- IEEET2: steady state, flat run, limits ----------------------------------------------------------

IEEET2_STEADY = {
    "nordic44": exciter_from_dyr("IEEET2", IEEET2_N44),
    "KE=0 (PSS/E rule)": exciter_from_dyr("IEEET2", IEEET2_N44[:5] + (0.0,) + IEEET2_N44[6:]),
    "VRMAX=0 (computed)": exciter_from_dyr("IEEET2", IEEET2_N44[:3] + (0.0, 0.0) + IEEET2_N44[5:]),
    **{f"linear {k}": m for k, m in LINEAR.items()},
    **{k: m for k, m in IEEET2_CASES.items() if k != "nordic44"},
    "TF1=TF2=0": IEEET2(t_f1_s=0.0, t_f2_s=0.0, t_r_s=0.02),
}


@pytest.mark.parametrize("name", list(IEEET2_STEADY))
def test_ieeet2_initial_state_is_steady(name):
    model = IEEET2_STEADY[name]
    p, treedef = packed(model)
    rhs, init = _exc_compiled(treedef)
    for vt, efd0 in ((1.0, 1.6), (1.04, 2.6)):
        x0, vref = init(p, efd0, exc_u(vt))
        d = np.asarray(rhs(p, x0, exc_u(vt, vref=float(vref))))
        assert np.all(np.isfinite(np.asarray(x0))) and np.max(np.abs(d)) < 1e-9, (name, vt)
        assert float(model.efd(x0, None, vref)) == efd0


def test_ieeet2_flat_run_stays_flat():
    model = IEEET2_STEADY["nordic44"]
    p, treedef = packed(model)
    rhs, init = _exc_compiled(treedef)
    x0, vref = init(p, EFD0, exc_u(1.02))
    xs = integrate(lambda s, x: np.asarray(rhs(p, x, exc_u(1.02, vref=float(vref)))), x0,
                   np.linspace(0, 20, 41), method="Radau", rtol=1e-10, atol=1e-12)
    assert np.max(np.abs(xs - np.asarray(x0))) < 1e-8


def test_ieeet2_regulator_limit_holds_and_lets_go():
    model = IEEET2(ka=40.0, t_a_s=0.05, vr_max_pu=3.0, vr_min_pu=-2.0, ke=1.0, t_e_s=0.5, kf=0.04,
                   t_f1_s=1.0, t_f2_s=0.2, se1=0.0, se2=0.0)
    p, treedef = packed(model)
    rhs, init = _exc_compiled(treedef)
    x0, vref = init(p, 1.5, exc_u(1.0))
    up = integrate(lambda s, x: np.asarray(rhs(p, x, exc_u(1.0, vref=float(vref) + 0.5))), x0,
                   np.linspace(0, 2.0, 21), method="Radau", rtol=1e-9, atol=1e-11)
    assert 3.0 <= up[-1, 2] < 3.0 + 1e-6  # held at VRMAX (windup: KA u ~ 20)
    assert 3.0 - 0.05 < up[-1, 3] < 3.0  # EFD -> VRMAX/KE (TE = 0.5 s)
    down = integrate(lambda s, x: np.asarray(rhs(p, x, exc_u(1.0, vref=float(vref) - 0.5))), up[-1],
                     np.linspace(0, 0.1, 11), method="Radau", rtol=1e-9, atol=1e-11)
    assert down[5, 2] < 2.0  # leaves at once
    low = integrate(lambda s, x: np.asarray(rhs(p, x, exc_u(1.0, vref=float(vref) - 0.5))), up[-1],
                    np.linspace(0, 3.0, 11), method="Radau", rtol=1e-9, atol=1e-11)
    assert -2.0 - 1e-6 < low[-1, 2] <= -2.0 and low[-1, 3] < -1.0  # VRMIN, no floor on EFD


def test_ieeet2_limit_check_names_vrmax():
    model = exciter_from_dyr("IEEET2", IEEET2_N44)
    p, treedef = packed(model)
    _, init = _exc_compiled(treedef)
    x0, vref = init(p, 6.0, exc_u(1.0))  # VR0 = (KE + SE(6)) 6 = 6.134 > VRMAX = 5.32
    found = exciter_crossings("IEEET2", model, np.asarray(x0), Start(6.0, 1.0, 1.0, 2.0, float(vref)))
    assert len(found) == 1 and found[0].con == "VRMAX" and found[0].side == "above"
    assert describe(found[0]).startswith("VR0 = (KE + SE(EFD0))·EFD0 = 6.134 above VRMAX = 5.32")
    x0, vref = init(p, EFD0, exc_u(1.0))
    assert exciter_crossings("IEEET2", model, np.asarray(x0), Start(EFD0, 1.0, 1.0, 2.0, float(vref))) == []


# --- STAB2A --------------------------------------------------------------------------------------------

def _block(num, den):
    """State space (A, B, C, D) of one block num/den (polynomials in s) as the diagram draws it."""
    if len(den) == 1 or den[0] == 0 or not np.any(num):
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[num[-1] / den[-1]]])
    return sig.tf2ss(num, den)


def _series(*systems):
    """The blocks one after the other (the first gets the input)."""
    a, b, c, d = systems[0]
    for a2, b2, c2, d2 in systems[1:]:
        n1, n2 = a.shape[0], a2.shape[0]
        a = np.block([[a, np.zeros((n1, n2))], [b2 @ c, a2]])
        b = np.vstack([b, b2 @ d])
        c = np.hstack([d2 @ c, c2])
        d = d2 @ d
    return a, b, c, d


def _sum(s1, s2):
    """s1 + s2 (same input)."""
    (a1, b1, c1, d1), (a2, b2, c2, d2) = s1, s2
    n1, n2 = a1.shape[0], a2.shape[0]
    a = np.block([[a1, np.zeros((n1, n2))], [np.zeros((n2, n1)), a2]])
    return a, np.vstack([b1, b2]), np.hstack([c1, c2]), d1 + d2


def stab2a_system(k2, t2, k3, t3, k4, k5, t5):
    """VOTHSG/PELEC before the limit, block by block from the diagram: -K2 s T2/(1 + s T2), then
    K2 s T2/(1 + s T2) twice, K3/(1 + s T3) + K4, K5/(1 + s T5) twice."""
    return _series(_block([-k2 * t2, 0.0], [t2, 1.0]), _block([k2 * t2, 0.0], [t2, 1.0]),
                   _block([k2 * t2, 0.0], [t2, 1.0]), _sum(_block([k3], [t3, 1.0]), _block([k4], [1.0])),
                   _block([k5], [t5, 1.0]), _block([k5], [t5, 1.0]))


STAB2A_CASES = {  # (module, PELEC step at 0.5 s, ramp over [3, 4] s)
    "nordic44-3115": (stabiliser_from_dyr("STAB2A", STAB2A_N44["3115"]), 0.3, -0.5),
    "nordic44-3000": (stabiliser_from_dyr("STAB2A", STAB2A_N44["3000"]), 0.06, -0.3),
    "K2 != 1": (STAB2A(k2=1.3, t2_s=1.5, k3=0.4, t3_s=0.5, k4=0.1, k5=2.0, t5_s=0.05, h_lim_pu=0.1),
                0.08, -0.1),
}


@pytest.mark.parametrize("name", list(STAB2A_CASES))
def test_stab2a_matches_scipy_reference_with_limit(name):
    model, step, ramp = STAB2A_CASES[name]
    f = {k: float(getattr(model, k)) for k in ("k2", "t2_s", "k3", "t3_s", "k4", "k5", "t5_s", "h_lim_pu")}
    a, b, c, d = stab2a_system(*(f[k] for k in ("k2", "t2_s", "k3", "t3_s", "k4", "k5", "t5_s")))
    p0 = 0.7
    pe, breaks = step_ramp(p0, step, 0.5, ramp, 3.0, 4.0)
    t = np.linspace(0.0, 8.0, 801)
    xr0 = -np.linalg.solve(a, b[:, 0]) * p0
    tol = dict(method="LSODA", rtol=1e-12, atol=1e-14)  # stiff (T5 = 0.01 s): DOP853 drifts ~1e-7
    xr = integrate(lambda s, x: a @ x + b[:, 0] * pe(s), xr0, t, breaks, **tol)
    y_ref = np.clip(xr @ c[0] + d[0, 0] * np.array([pe(s) for s in t]), -f["h_lim_pu"], f["h_lim_pu"])
    p, treedef = packed(model)
    rhs, out, init = _stab_compiled(treedef)
    x0 = np.asarray(init(p, p0))
    assert float(out(p, x0, p0)) == 0.0 and np.max(np.abs(np.asarray(rhs(p, x0, p0)))) == 0.0
    xs = integrate(lambda s, x: np.asarray(rhs(p, x, pe(s))), x0, t, breaks, **tol)
    y = np.array([float(out(p, x, pe(s))) for x, s in zip(xs, t)])
    diff = float(np.max(np.abs(y - y_ref)))
    at_limit = np.abs(y) >= f["h_lim_pu"] - 1e-12
    print(f"\nSTAB2A {name}: VOTHSG spans {np.ptp(y):.4f} pu, at +-HLIM for {np.mean(at_limit) * 8:.2f} s; "
          f"largest difference {diff:.1e} pu")
    assert np.any(y >= f["h_lim_pu"] - 1e-12) and np.any(y <= -f["h_lim_pu"] + 1e-12)  # both limits
    assert np.max(np.abs(y)) <= f["h_lim_pu"]  # and they hold
    assert diff < 1e-10


def test_stab2a_flat_run_and_zero_time_constants():
    for model in (stabiliser_from_dyr("STAB2A", STAB2A_N44["3115"]),
                  STAB2A(t3_s=0.0, t5_s=0.0)):  # T3 = T5 = 0: gains K3, K5
        p, treedef = packed(model)
        rhs, out, init = _stab_compiled(treedef)
        x0 = np.asarray(init(p, 0.9))
        xs = integrate(lambda s, x: np.asarray(rhs(p, x, 0.9)), x0, np.linspace(0, 20, 21))
        assert np.max(np.abs(xs - x0)) < 1e-12 and abs(float(out(p, xs[-1], 0.9))) < 1e-12
    # T3 = T5 = 0: right after a PELEC step of dp the output is -K2^3 (K3 + K4) K5^2 dp
    model = STAB2A(k2=1.1, k3=0.3, t3_s=0.0, k4=0.05, k5=1.5, t5_s=0.0, h_lim_pu=1.0)
    p, treedef = packed(model)
    _, out, init = _stab_compiled(treedef)
    x0 = np.asarray(init(p, 0.9))
    assert float(out(p, x0, 0.95)) == pytest.approx(-1.1**3 * 0.35 * 1.5**2 * 0.05, rel=1e-12)


# --- records ---------------------------------------------------------------------------------------------

def test_records_parse_in_con_order():
    assert EXCITERS["IEEET2"] is IEEET2 and STABILISERS["STAB2A"] is STAB2A
    assert EXCITER_FIELDS["IEEET2"] == ("TR", "KA", "TA", "VRMAX", "VRMIN", "KE", "TE", "KF", "TF1",
                                        "TF2", "E1", "SE(E1)", "E2", "SE(E2)")
    assert STABILISER_FIELDS["STAB2A"] == ("K2", "T2", "K3", "T3", "K4", "K5", "T5", "HLIM")
    assert STABILISER_ICONS["STAB2A"] == ()
    m = exciter_from_dyr("IEEET2", IEEET2_N44)
    assert (float(m.t_r_s), float(m.ka), float(m.t_a_s), float(m.vr_max_pu), float(m.vr_min_pu),
            float(m.ke), float(m.t_e_s), float(m.kf), float(m.t_f1_s), float(m.t_f2_s), float(m.e1_pu),
            float(m.se1), float(m.e2_pu), float(m.se2)) == IEEET2_N44
    assert m.ke_zero == "psse"
    vr = exciter_from_dyr("IEEET2", IEEET2_N44[:3] + (0.0, 0.0) + IEEET2_N44[5:])
    assert float(vr.vr_max_pu) == pytest.approx((0.202 + 1.0) * 8.0) == -float(vr.vr_min_pu)
    s = stabiliser_from_dyr("STAB2A", STAB2A_N44["3115"])
    assert (float(s.k2), float(s.t2_s), float(s.k3), float(s.t3_s), float(s.k4), float(s.k5),
            float(s.t5_s), float(s.h_lim_pu)) == STAB2A_N44["3115"]
    assert s.remote_input_at_terminal is False and s.n_states == 6


@pytest.mark.parametrize("model, constants, match", [
    ("IEEET2", IEEET2_N44[:-1], "expected 14 constants"),
    ("IEEET2", IEEET2_N44[:6] + (0.0,) + IEEET2_N44[7:], "IEEET2: TE must be > 0"),
    ("IEEET2", IEEET2_N44[:8] + (-1.0,) + IEEET2_N44[9:], "IEEET2: TF1 must be >= 0"),
    ("IEEET2", IEEET2_N44[:3] + (-5.0, 5.0) + IEEET2_N44[5:], "VRMAX"),
    ("STAB2A", STAB2A_N44["3115"][:-1], "expected 8 constants"),
    ("STAB2A", (1.0, 0.0) + STAB2A_N44["3115"][2:], "T2 must be > 0"),
    ("STAB2A", STAB2A_N44["3115"][:7] + (-0.04,), "STAB2A: HLIM must be >= 0"),
    ("STAB2A", STAB2A_N44["3115"][:6] + (float("nan"), 0.04), "not finite"),
])
def test_bad_records_are_refused_in_one_line(model, constants, match):
    read = exciter_from_dyr if model == "IEEET2" else stabiliser_from_dyr
    with pytest.raises(ValueError, match=match) as e:
        read(model, list(constants))
    assert "\n" not in str(e.value)


def test_unit_with_ieeet2_and_stab2a_starts_at_rest():
    """A Nordic 44 style unit (GENROU + IEEET2 + STAB2A): the composed steady state holds, and a
    voltage dip moves the stabiliser through PELEC."""
    machine = GENROU(td0_1_s=7.0, td0_2_s=0.05, tq0_1_s=1.5, tq0_2_s=0.05, h_s=6.0, d_pu=0.0,
                     xd_pu=2.2, xq_pu=2.0, xd1_pu=0.3, xq1_pu=0.4, x2_pu=0.2, xl_pu=0.15)
    unit = DyrUnit(machine=machine, exciter=exciter_from_dyr("IEEET2", IEEET2_N44),
                   stabiliser=stabiliser_from_dyr("STAB2A", STAB2A_N44["3000"]))
    v = 1.01 * cmath.exp(0.25j)
    i = ((0.85 + 0.2j) / v).conjugate()
    z = jnp.asarray(0.0)
    u = UnitInputs(jnp.asarray(v.real), jnp.asarray(v.imag), z, z)
    y0, refs = unit.initial_state(u, jnp.asarray(i.real), jnp.asarray(i.imag))
    assert float(jnp.max(jnp.abs(unit.vector_field(y0, u, refs)))) < 1e-9
    y_s = unit.split(y0)[2]
    assert float(y_s[0]) == pytest.approx(0.85, abs=1e-9)  # the first washout holds PELEC
    dip = u._replace(v_re_pu=u.v_re_pu * 0.95, v_im_pu=u.v_im_pu * 0.95)
    out, _, _, vs = unit.signals(y0, dip, refs)
    assert float(out.p_pu) < 0.85 - 0.01 and float(vs) == 0.0  # VOTHSG: the K5 lags' state
    d_s = unit.split(unit.vector_field(y0, dip, refs))[2]
    assert float(d_s[4]) > 0.0  # PELEC falls: -K2 washout > 0 drives the first K5 lag up
