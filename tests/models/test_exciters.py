"""Tests of the PSS/E exciter modules SEXS, IEEEX1, EXDC2, ESDC2A, EXST1 and ESST3A.

* steady state: ``initial_state`` holds (d(state)/dt = 0, Efd = Efd0) at several operating
  points, for the example .dyr records and for variants that exercise every branch;
* small steps: the simulated response (RK4 on the module's vector field) equals the step
  response of the linear part built from the block diagram with ``scipy.signal``;
* limits: large steps drive the limited signal to its limit and the non-windup limits let go
  as soon as the error reverses; EXST1's, EXDC2's and ESDC2A's limits scale with Vt and Ifd;
* zero time constants: no NaN in value or gradient; vmap over stacked parameter sets equals a
  loop; ``exciter_from_dyr`` parses the records and refuses bad ones.
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

from jaxdse._models.base import ExciterInputs
from jaxdse._models.exciters import (
    ESDC2A,
    ESST3A,
    EXCITER_FIELDS,
    EXCITERS,
    EXDC2,
    EXST1,
    IEEEX1,
    SEXS,
    exciter_from_dyr,
    rectifier_fex,
    saturation,
)

RECORDS = {  # from the test data (PSS/E CON order)
    "ESST3A": "0.02 0.2 -0.2 8 1 5  20 0 99 -99 1 3.67  0.435 5.48 0.01 0.0098 3.86 3.33  0.4 99 0",
    "EXST1": "0.02 99 -99 0 0.02 50  0.02 9999 -9999 0 0.01 1",
    "IEEEX1": "0 50 0.06 0 0 1  -1 -0.02 0.5 0.08 1 0  2 0.0016 3 1.73",
    "EXDC2": "0 40 0.06 0 0 3.5  -3.5 1 0.8 0.03 1 0  2.4 0.03 5 0.5",
    "SEXS": "0.1 10 100 0.05 0 5",
}


def record(name):
    return exciter_from_dyr(name, [float(c) for c in RECORDS[name].split()])


def operating_point(vt, p, q, angle=0.3, ifd=2.0):
    """Inputs at terminal voltage ``vt`` delivering P + jQ (current out of the machine)."""
    v = vt * np.exp(1j * angle)
    i = np.conj((p + 1j * q) / v)
    vals = (vt, v.real, v.imag, i.real, i.imag, ifd, 0.0)
    return ExciterInputs(*(jnp.asarray(x, float) for x in vals))


OPS = [  # (efd0, inputs)
    (1.2, operating_point(1.0, 0.3, -0.1, ifd=1.25)),
    (2.1, operating_point(1.03, 0.8, 0.3, ifd=2.2)),
    (2.4, operating_point(0.97, 1.0, 0.5, angle=-0.4, ifd=2.6)),
]


def linear_dc(cls, **kw):
    base = dict(t_r_s=0.02, ka=40.0, t_a_s=0.05, t_b_s=1.0, t_c_s=0.5, vr_max_pu=10.0,
                vr_min_pu=-10.0, ke=1.0, t_e_s=0.5, kf=0.05, t_f_s=1.0, se1=0.0, se2=0.0)
    base.update(kw)
    return cls(**base)


def linear_esst3a(**kw):
    base = dict(t_r_s=0.02, vi_max_pu=1.0, vi_min_pu=-1.0, km=8.0, t_c_s=1.0, t_b_s=5.0, ka=20.0,
                t_a_s=0.05, vr_max_pu=99.0, vr_min_pu=-99.0, kg=1.0, kp=3.67, ki=0.435,
                vb_max_pu=10.0, kc=0.01, xl_pu=0.01, vg_max_pu=10.0,
                theta_p_rad=math.radians(3.33), t_m_s=0.4, vm_max_pu=99.0, vm_min_pu=-99.0)
    base.update(kw)
    return ESST3A(**base)


def linear_exst1(**kw):
    base = dict(t_r_s=0.02, vi_max_pu=1.0, vi_min_pu=-1.0, t_c_s=0.5, t_b_s=2.0, ka=80.0,
                t_a_s=0.05, vr_max_pu=10.0, vr_min_pu=-10.0, kc=0.1, kf=0.05, t_f_s=1.0)
    base.update(kw)
    return EXST1(**base)


ZERO_T = {  # every optional time constant 0 (the output block stays dynamic)
    "SEXS": SEXS(t_b_s=0.0),
    "IEEEX1": IEEEX1(t_r_s=0.0, t_a_s=0.0, t_b_s=0.0, t_c_s=0.0, t_f_s=0.0, ke=0.0),
    "EXDC2": EXDC2(t_r_s=0.0, t_a_s=0.0, t_b_s=0.0, t_c_s=0.0, t_f_s=0.0),
    "ESDC2A": ESDC2A(t_r_s=0.0, t_a_s=0.0, t_b_s=0.0, t_c_s=0.0, t_f_s=0.0, se1=0.0, se2=0.0),
    "EXST1": EXST1(t_r_s=0.0, t_b_s=0.0, t_c_s=0.0, t_f_s=0.0, kc=0.0),
    "ESST3A": ESST3A(t_r_s=0.0, t_b_s=0.0, t_c_s=0.0, t_a_s=0.0),
    "ESST3A-TM0": ESST3A(t_r_s=0.0, t_b_s=0.0, t_c_s=0.0, t_a_s=0.02, t_m_s=0.0, ki=0.0,
                         xl_pu=0.0),
}

STEADY_MODELS = {
    **{f"{name}-record": record(name) for name in RECORDS},
    **{f"{name}-default": cls() for name, cls in EXCITERS.items()},
    **{f"{name}-zeroT": m for name, m in ZERO_T.items()},
    "IEEEX1-KE0": IEEEX1(ke=0.0),
    "EXDC2-KE0": EXDC2(ke=0.0, t_r_s=0.02, t_b_s=0.5, t_c_s=0.2),
    "ESDC2A-KE0-sat": ESDC2A(ke=0.0, t_r_s=0.01, t_b_s=0.5, t_c_s=0.2),
    "ESST3A-VGlim": ESST3A(vg_max_pu=1.5),
    "ESST3A-VBlim": ESST3A(vb_max_pu=4.0),
    "ESST3A-TM0-VGlim": ESST3A(t_a_s=0.02, t_m_s=0.0, vg_max_pu=1.5),
    "ESST3A-linear": linear_esst3a(),
    "EXST1-linear": linear_exst1(),
}


# --- integration helper -----------------------------------------------------------------------

@functools.partial(jax.jit, static_argnames=("n", "dt"))
def _rk4(model, x0, inputs, vref, n, dt):
    """RK4 at constant inputs; (Efd, state) at t = dt, 2 dt, ..., n dt."""

    def f(x):
        return model.vector_field(x, inputs, vref)

    def step(x, _):
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        x = x + dt / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        return x, (model.efd(x, inputs, vref), x)

    _, (efd, xs) = jax.lax.scan(step, x0, None, length=n)
    return efd, xs


def simulate(model, x0, inputs, vref, t_end, dt=1e-3):
    """(Efd, states) at dt, 2 dt, ..., t_end <= 3 s: one compiled length serves every call."""
    n = int(round(t_end / dt))
    assert n <= 3000
    efd, xs = _rk4(model, jnp.asarray(x0, float), inputs, jnp.asarray(vref, float), 3000, dt)
    return np.asarray(efd)[:n], np.asarray(xs)[:n]


# --- shared nonlinear functions ---------------------------------------------------------------

def test_saturation_passes_through_its_points():
    for e1, se1, e2, se2 in [(2.0, 0.0016, 3.0, 1.73), (2.4, 0.03, 5.0, 0.5), (3.05, 0.279, 2.29, 0.117)]:
        assert float(saturation(e1, e1, se1, e2, se2)) == pytest.approx(se1, rel=1e-12)
        assert float(saturation(e2, e1, se1, e2, se2)) == pytest.approx(se2, rel=1e-12)
    # no saturation data, and below the knee: 0
    assert float(saturation(3.0, 2.0, 0.0, 3.0, 0.0)) == 0.0
    assert float(saturation(1.0, 2.0, 0.0016, 3.0, 1.73)) == 0.0
    assert float(saturation(-1.0, 2.4, 0.03, 5.0, 0.5)) == 0.0


def test_fex_is_the_annex_d_characteristic():
    i_n = jnp.linspace(-0.2, 1.2, 1401)
    f = np.asarray(rectifier_fex(i_n))
    ref = np.piecewise(np.asarray(i_n), [np.asarray(i_n) <= 0, (0 < i_n) & (i_n <= 0.433),
                                         (0.433 < i_n) & (i_n < 0.75), (0.75 <= i_n) & (i_n <= 1)],
                       [1.0, lambda x: 1 - 0.577 * x, lambda x: np.sqrt(0.75 - x * x),
                        lambda x: 1.732 * (1 - x), 0.0])
    np.testing.assert_allclose(f, ref, atol=1e-15)
    assert np.max(np.abs(np.diff(f))) < 2e-3  # continuous: no jump at the knots
    grad = jax.grad(rectifier_fex)
    for x in [-0.1, 0.0, 0.2, 0.433, 0.6, 0.75, 0.9, 1.0, 1.1]:
        assert np.isfinite(float(grad(jnp.asarray(x))))


# --- steady state -----------------------------------------------------------------------------

@pytest.mark.parametrize("name", list(STEADY_MODELS))
def test_initial_state_is_steady(name):
    model = STEADY_MODELS[name]
    for efd0, inputs in OPS:
        x0, vref = model.initial_state(efd0, inputs)
        assert x0.shape == (model.n_states,)
        d = np.asarray(model.vector_field(x0, inputs, vref))
        # residual: the rounding of Vref - Vt, amplified by KA/TA (KA = 300, TA = 0.01: ~7e-12)
        np.testing.assert_allclose(d, 0.0, atol=1e-11, err_msg=f"{name} at Efd0 = {efd0}")
        assert float(model.efd(x0, inputs, vref)) == pytest.approx(efd0, abs=1e-13)


def test_ke_zero_gives_vr_vrmax_over_ten():
    model = IEEEX1(ke=0.0, vr_max_pu=3.0)
    for efd0, inputs in OPS:
        x0, _ = model.initial_state(efd0, inputs)
        assert float(x0[2]) == pytest.approx(0.3, rel=1e-12)
        se = float(saturation(efd0, model.e1_pu, model.se1, model.e2_pu, model.se2))
        assert float(x0[5]) == pytest.approx(0.3 / efd0 - se, rel=1e-12)


def test_esst3a_power_source():
    """VE = |KP e^(j THETAP) V + j (KI + KP e^(j THETAP) XL) I| and the VBMAX limit."""
    model = record("ESST3A")
    _, inputs = OPS[1]
    v = complex(inputs.v_re_pu, inputs.v_im_pu)
    i = complex(inputs.i_re_pu, inputs.i_im_pu)
    kp = 3.67 * np.exp(1j * math.radians(3.33))
    ve = abs(kp * v + 1j * (0.435 + kp * 0.0098) * i)
    assert float(model.ve(inputs)) == pytest.approx(ve, rel=1e-13)
    i_n = 0.01 * float(inputs.ifd_pu) / ve
    assert float(model.vb(inputs)) == pytest.approx(min(ve * (1 - 0.577 * i_n), 5.48), rel=1e-13)
    assert float(eqx.tree_at(lambda m: m.vb_max_pu, model, 3.0).vb(inputs)) == 3.0


# --- small steps: the linear part ---------------------------------------------------------------

def _poly(*factors):
    out = np.array([1.0])
    for f in factors:
        out = np.polymul(out, f)
    return out


def _feedback(fn, fd, hn, hd):
    """F/(1 + F H) as (num, den)."""
    return _poly(fn, hd), np.polyadd(_poly(fd, hd), _poly(fn, hn))


def _lead_lag(tc, tb):
    return ([float(tc), 1.0], [float(tb), 1.0]) if tb > 0 else ([1.0], [1.0])


def transfer_to_efd(model, inputs):
    """dEfd/dVref of the model's linear part, from its block diagram (no limit active)."""
    f = lambda name: float(getattr(model, name))  # noqa: E731
    if isinstance(model, SEXS):
        lln, lld = _lead_lag(f("ta_tb") * f("t_b_s"), f("t_b_s"))
        return _poly(lln, [f("k")]), _poly(lld, [f("t_e_s"), 1.0])
    lln, lld = _lead_lag(f("t_c_s"), f("t_b_s"))
    if isinstance(model, (IEEEX1, EXDC2, ESDC2A)):
        fn = _poly(lln, [f("ka")])
        fd = _poly(lld, [f("t_a_s"), 1.0], [f("t_e_s"), f("ke")])
        return _feedback(fn, fd, [f("kf"), 0.0], [f("t_f_s"), 1.0])
    if isinstance(model, EXST1):
        fn, fd = _poly(lln, [f("ka")]), _poly(lld, [f("t_a_s"), 1.0])
        return _feedback(fn, fd, [f("kf"), 0.0], [f("t_f_s"), 1.0])
    vb = float(model.vb(inputs))
    num = _poly(lln, [f("ka") * vb * f("km")])
    den = _poly(lld, [f("t_a_s"), 1.0], [f("t_m_s"), 1.0 + f("km") * f("kg") * vb])
    return num, den


LINEAR = {
    "SEXS": SEXS(ta_tb=0.2, t_b_s=2.0, k=50.0, t_e_s=0.1, e_min_pu=-10.0, e_max_pu=10.0),
    "SEXS-record": record("SEXS"),
    "IEEEX1": linear_dc(IEEEX1),
    "EXDC2": linear_dc(EXDC2, t_b_s=0.4, t_c_s=0.1),
    "ESDC2A": linear_dc(ESDC2A, ke=0.8, t_b_s=0.0, t_r_s=0.0),
    "EXST1": linear_exst1(),
    "EXST1-record": record("EXST1"),
    "ESST3A": linear_esst3a(),
    "ESST3A-record": record("ESST3A"),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(LINEAR))
@pytest.mark.parametrize("what", ["vref", "vs", "vt"])
def test_small_step_matches_linear_response(name, what):
    model = LINEAR[name]
    efd0, inputs = OPS[1]
    x0, vref = model.initial_state(efd0, inputs)
    delta = 0.004
    t_end, dt = 2.0, 1e-3
    if what == "vref":
        stepped, vref1 = inputs, vref + delta
    elif what == "vs":  # VOTHSG enters where Vref does
        stepped, vref1 = inputs._replace(vs_pu=jnp.asarray(delta)), vref
    else:  # only the sensed voltage moves (the power source of ESST3A stays put)
        stepped, vref1 = inputs._replace(vt_pu=inputs.vt_pu - delta), vref
    efd, _ = simulate(model, x0, stepped, vref1, t_end, dt)
    num, den = transfer_to_efd(model, inputs)
    t_r = float(getattr(model, "t_r_s", 0.0))
    if what == "vt" and t_r > 0:
        den = _poly(den, [t_r, 1.0])
    t = dt * np.arange(int(round(t_end / dt)) + 1)
    _, y = sig.step((num, den), T=t)
    expected = efd0 + delta * y[1:]
    assert np.max(np.abs(expected - efd0)) > 0.02  # the step is seen
    np.testing.assert_allclose(efd, expected, atol=1e-6, rtol=0)


# --- limits -----------------------------------------------------------------------------------

def test_sexs_nonwindup_limit():
    model = record("SEXS")  # K = 100, TE = 0.05, EMAX = 5
    efd0, inputs = OPS[1]
    x0, vref = model.initial_state(efd0, inputs)
    efd, xs = simulate(model, x0, inputs, vref + 0.5, 1.0)
    assert efd[-1] == 5.0 and xs[-1, 1] < 5.05  # windup would park the state near K·y = 7
    efd2, _ = simulate(model, xs[-1], inputs, vref - 0.5, 0.02)
    assert efd2[0] < 5.0 and efd2[-1] < 4.3  # leaves the limit at once
    efd3, xs3 = simulate(model, xs[-1], inputs, vref - 0.5, 1.0)
    assert efd3[-1] == 0.0 and xs3[-1, 1] > -0.05  # EMIN = 0


@pytest.mark.parametrize("cls", [IEEEX1, EXDC2, ESDC2A])
def test_dc_regulator_nonwindup_limit(cls):
    model = linear_dc(cls, vr_max_pu=3.0, vr_min_pu=-2.0, t_a_s=0.05, kf=0.0)
    efd0, inputs = OPS[0]
    inputs = inputs._replace(vt_pu=jnp.asarray(0.9))
    x0, vref = model.initial_state(efd0, inputs)
    scale = 0.9 if cls in (EXDC2, ESDC2A) else 1.0  # EXDC2, ESDC2A: limits times Vt
    _, xs = simulate(model, x0, inputs, vref + 0.5, 0.5)
    vr = xs[:, 2]
    # held at the limit (within the overshoot of the step that reached it); windup: KA·u ~ 20
    assert 3.0 * scale <= vr[-1] < 3.0 * scale + 0.4 and vr[-1] == vr[-100]
    d = model.vector_field(jnp.asarray(xs[-1]), inputs, vref + 0.5)  # the exciter sees the limit
    assert float(d[3]) == pytest.approx((3.0 * scale - xs[-1, 5] * xs[-1, 3]) / 0.5, rel=1e-12)
    _, xs2 = simulate(model, xs[-1], inputs, vref - 0.5, 0.02)
    assert xs2[0, 2] < vr[-1] and xs2[-1, 2] < 3.0 * scale - 0.5  # leaves at once


def test_esdc2a_efd_floor():
    model = linear_dc(ESDC2A, vr_min_pu=-5.0, kf=0.0)
    efd0, inputs = OPS[0]
    x0, vref = model.initial_state(efd0, inputs)
    efd, xs = simulate(model, x0, inputs, vref - 1.0, 3.0)
    assert efd.min() >= 0.0 and efd[-1] == 0.0 and xs[-1, 3] > -0.01
    efd2, xs2 = simulate(model, xs[-1], inputs, vref + 1.0, 0.3)
    k = int(np.argmax(xs2[:, 2] > 0.0))  # VR turns positive (it starts at Vt·VRMIN)
    assert 0 < k < 200 and efd2[k + 10] > 0.0 and efd2[-1] > 0.05  # EFD leaves the floor then
    # IEEEX1 and EXDC2 have no floor
    for cls in (IEEEX1, EXDC2):
        model1 = linear_dc(cls, vr_min_pu=-5.0, kf=0.0)
        x0, vref = model1.initial_state(efd0, inputs)
        efd, _ = simulate(model1, x0, inputs, vref - 1.0, 3.0)
        assert efd[-1] < -1.0, cls


def test_exst1_field_voltage_limits_follow_vt_and_ifd():
    model = linear_exst1(vr_max_pu=3.0, vr_min_pu=-1.0, kc=0.2)
    efd0, inputs = OPS[1]
    x0, vref = model.initial_state(efd0, inputs)
    efd, xs = simulate(model, x0, inputs, vref + 0.5, 1.0)
    hi = 3.0 * float(inputs.vt_pu) - 0.2 * float(inputs.ifd_pu)
    assert efd[-1] == pytest.approx(hi, abs=1e-14) and xs[-1, 2] > hi + 1.0  # windup: VR runs on
    moved = inputs._replace(vt_pu=jnp.asarray(0.9), ifd_pu=jnp.asarray(3.0))
    assert float(model.efd(jnp.asarray(xs[-1]), moved, vref)) == pytest.approx(3.0 * 0.9 - 0.2 * 3.0)
    efd, _ = simulate(model, x0, inputs, vref - 0.5, 1.0)
    lo = -1.0 * float(inputs.vt_pu) - 0.2 * float(inputs.ifd_pu)
    assert efd[-1] == pytest.approx(lo, abs=1e-14)


def test_esst3a_inner_and_outer_nonwindup_limits():
    model = linear_esst3a(vm_max_pu=0.8, vm_min_pu=0.0, vr_max_pu=4.0, vr_min_pu=-4.0)
    efd0, inputs = OPS[1]
    vb = float(model.vb(inputs))
    x0, vref = model.initial_state(efd0, inputs)
    efd, xs = simulate(model, x0, inputs, vref + 0.5, 2.0)
    assert efd[-1] == pytest.approx(0.8 * vb, rel=1e-12)  # VM at VMMAX: EFD = VB VMMAX
    assert 0.8 <= xs[-1, 3] < 0.82 and 4.0 <= xs[-1, 2] < 4.1  # both held (step overshoot)
    efd2, xs2 = simulate(model, xs[-1], inputs, vref - 0.5, 0.2)
    assert xs2[0, 2] < xs[-1, 2] and xs2[20, 2] < 3.7  # VR leaves at once
    # VM leaves as soon as its demand KM (VR - VG) drops below VMMAX (windup: VM ~ KM VRMAX)
    demand = float(model.km) * (np.clip(xs2[:, 2], -4.0, 4.0) - np.minimum(efd2, 10.0))
    k = int(np.argmax(demand < 0.8))
    assert 0 < k < 150 and xs2[k + 3, 3] < 0.8 and efd2[k + 3] < 0.8 * vb
    efd3, _ = simulate(model, xs[-1], inputs, vref - 0.5, 3.0)
    assert efd3[-1] == pytest.approx(0.0, abs=1e-12)  # VMMIN = 0


def test_esst3a_tm_zero_solves_the_inner_loop():
    model = linear_esst3a(t_m_s=0.0, vg_max_pu=1.5, vm_max_pu=2.0, vm_min_pu=0.0)
    efd0, inputs = OPS[1]
    x0, vref = model.initial_state(efd0, inputs)
    vb = float(model.vb(inputs))
    for vr in [0.5, 1.6, 1.9, 3.0, -1.0]:
        x = x0.at[2].set(vr)
        efd = float(model.efd(x, inputs, vref))
        vm = efd / vb
        vg = min(float(model.kg) * efd, 1.5)
        target = min(max(float(model.km) * (vr - vg), 0.0), 2.0)
        assert vm == pytest.approx(target, abs=1e-12)
        assert 0.0 <= vm <= 2.0


# --- zero time constants: values and gradients --------------------------------------------------

@eqx.filter_value_and_grad
def _loss(model, efd0, inputs):
    """Initial state, an Euler step after a step in Vref and Vt, Efd and the derivatives."""
    x, vref = model.initial_state(efd0, inputs)
    stepped = inputs._replace(vt_pu=inputs.vt_pu - 0.01)
    d = model.vector_field(x, stepped, vref + 0.02)
    x = x + 0.01 * d
    return (vref + jnp.sum(d) + jnp.sum(model.vector_field(x, stepped, vref))
            + model.efd(x, stepped, vref + 0.02))


@pytest.mark.parametrize("name", list(ZERO_T))
def test_zero_time_constants_no_nan(name):
    model = ZERO_T[name]
    efd0, inputs = OPS[2]
    value, grads = _loss(model, jnp.asarray(efd0), inputs)
    assert np.isfinite(float(value))
    leaves = jtu.tree_leaves(grads)
    assert leaves and all(bool(jnp.all(jnp.isfinite(g))) for g in leaves)
    assert any(float(jnp.abs(g)) > 0 for g in leaves)


def test_esst3a_without_source_voltage():
    """A bolted terminal fault (V = I = 0): VE = 0, VB = 0, EFD = 0; no NaN in the gradient."""
    model = record("ESST3A")
    efd0, inputs = OPS[1]
    x0, vref = model.initial_state(efd0, inputs)
    dead = inputs._replace(vt_pu=jnp.asarray(0.0), v_re_pu=jnp.asarray(0.0),
                           v_im_pu=jnp.asarray(0.0), i_re_pu=jnp.asarray(0.0),
                           i_im_pu=jnp.asarray(0.0))
    assert float(model.vb(dead)) == 0.0 and float(model.efd(x0, dead, vref)) == 0.0

    def f(m):
        return m.efd(x0, dead, vref) + jnp.sum(m.vector_field(x0, dead, vref))

    leaves = jtu.tree_leaves(eqx.filter_grad(f)(model))
    assert all(bool(jnp.all(jnp.isfinite(g))) for g in leaves)


# --- vmap -------------------------------------------------------------------------------------

BATCHES = {
    "SEXS": [SEXS(), record("SEXS"), ZERO_T["SEXS"]],
    "IEEEX1": [IEEEX1(), record("IEEEX1"), ZERO_T["IEEEX1"], IEEEX1(ke=0.0)],
    "EXDC2": [EXDC2(), record("EXDC2"), ZERO_T["EXDC2"], EXDC2(ke=0.0)],
    "ESDC2A": [ESDC2A(), ZERO_T["ESDC2A"], linear_dc(ESDC2A)],
    "EXST1": [EXST1(), record("EXST1"), ZERO_T["EXST1"]],
    "ESST3A": [ESST3A(), record("ESST3A"), ZERO_T["ESST3A"], ZERO_T["ESST3A-TM0"],
               ESST3A(vb_max_pu=4.0)],
}


@pytest.mark.parametrize("name", list(BATCHES))
def test_vmap_over_parameter_sets_equals_loop(name):
    models = BATCHES[name]
    stacked = jtu.tree_map(lambda *xs: jnp.stack(xs), *models)
    efd0, inputs = OPS[1]

    def run(m):
        x0, vref = m.initial_state(efd0, inputs)
        x = x0 * (1.0 + 0.01 * jnp.arange(m.n_states)) + 0.003
        return x0, vref, m.vector_field(x, inputs, vref + 0.01), m.efd(x, inputs, vref + 0.01)

    batched = jax.jit(jax.vmap(run))(stacked)
    single = jax.jit(run)
    for k, m in enumerate(models):
        for b, r in zip(batched, single(m)):
            np.testing.assert_allclose(np.asarray(b[k]), np.asarray(r), rtol=1e-13, atol=1e-13)


# --- PSS/E records ----------------------------------------------------------------------------

def test_records_parse():
    assert set(EXCITER_FIELDS) == set(EXCITERS)
    for name in RECORDS:
        model = record(name)
        assert type(model) is EXCITERS[name]
        assert len(RECORDS[name].split()) == len(EXCITER_FIELDS[name])
    esst3a = record("ESST3A")
    assert float(esst3a.theta_p_rad) == pytest.approx(math.radians(3.33))
    assert float(esst3a.km) == 8.0 and float(esst3a.vm_min_pu) == 0.0
    ieeex1 = record("IEEEX1")
    assert float(ieeex1.ke) == -0.02 and float(ieeex1.t_r_s) == 0.0 and float(ieeex1.se2) == 1.73
    assert float(record("SEXS").ta_tb) == 0.1
    assert float(record("EXST1").kf) == 0.01
    exdc2 = record("EXDC2")
    assert float(exdc2.vr_max_pu) == 3.5 and float(exdc2.ke) == 1.0 and exdc2.ke_zero == "psse"


def test_dc_vrmax_zero_is_computed():
    cons = [float(c) for c in RECORDS["IEEEX1"].split()]
    cons[5] = 0.0  # VRMAX; KE = -0.02 <= 0: VRMAX = SE(E2)·E2
    model = exciter_from_dyr("IEEEX1", cons)
    assert float(model.vr_max_pu) == pytest.approx(1.73 * 3.0)
    assert float(model.vr_min_pu) == pytest.approx(-1.73 * 3.0)
    cons[7] = 1.0  # KE > 0: (SE(E2) + KE)·E2
    assert float(exciter_from_dyr("ESDC2A", cons).vr_max_pu) == pytest.approx(2.73 * 3.0)
    assert float(exciter_from_dyr("EXDC2", cons).vr_max_pu) == pytest.approx(2.73 * 3.0)


@pytest.mark.parametrize("model, cons, match", [
    ("SEXS", [0.1, 10, 100, 0.05, 0], "expected 6 constants"),
    ("SEXS", [0.1, 10, 100, 0.05, 0, 5, 1], "expected 6 constants"),
    ("SEXS", [0.1, 10, 100, -0.05, 0, 5], r"TE must be > 0"),
    ("SEXS", [0.1, 10, 100, 0.0, 0, 5], r"TE must be > 0"),
    ("SEXS", [0.1, 10, 100, 0.05, 5, 0], "EMAX"),
    ("SEXS", [0.1, 10, float("nan"), 0.05, 0, 5], "non-finite"),
    ("IEEEX1", [0, 50, 0.06, 0, 0, 1, -1, -0.02, -0.5, 0.08, 1, 0, 2, 0.0016, 3, 1.73],
     r"TE must be > 0"),
    ("ESDC2A", [0, 50, 0.06, 0, 0, -1, 1, 1, 0.5, 0.08, 1, 0, 2, 0.0016, 3, 1.73], "VRMAX"),
    ("EXDC2", [0, 50, 0.06, 0, 0, 1, -1, 1, 0.5, 0.08, 1, 0, 2, 0.0016, 3], "expected 16 constants"),
    ("EXST1", [0.02, 99, -99, 0, 0.02, 50, 0, 9999, -9999, 0, 0.01, 1], r"TA must be > 0"),
    ("EXST1", [0.02, 99, -99, 0, 0.02, 50, 0.02, 9999, -9999, 0, 0.01, -1], r"TF must be >= 0"),
    ("ESST3A", [0.02, 0.2, -0.2, 8, 1, 5, 20, 0, 99, -99, 1, 3.67, 0.435, 5.48, 0.01, 0.0098,
                3.86, 3.33, 0.0, 99, 0], "TA and TM"),
    ("ESST3A", [0.02] * 20, "expected 21 constants"),
    ("EXAC9", [1.0], "unknown exciter model"),
])
def test_exciter_from_dyr_refuses(model, cons, match):
    with pytest.raises(ValueError, match=match) as info:
        exciter_from_dyr(model, cons)
    assert "\n" not in str(info.value)
