"""Tests of the PSS/E machine modules GENROU, GENSAL and GENCLS (src/jaxdse/_dyr/machine.py).

* steady state: ``steady_state`` then ``terminal`` gives back the current it was asked for,
  Te = Tm (= P + Ra |I|^2) and a zero vector field, at lagging, leading and motoring operating
  points, with and without saturation and armature resistance;
* the Park transforms, the quadratic saturation through S(1.0) and S(1.2), the checks of the
  reactance orders, vmap over stacked parameters and forward-mode derivatives;
* a physics check of GENROU that does not go through ``steady_state`` alone: a torque step at
  constant terminal voltage settles where Te = Tm, at the steady state with the same Efd, and
  the rotor swings at the frequency the synchronising torque coefficient predicts.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import fsolve

from jaxdse._models.machines import (
    GENCLS,
    GENROU,
    GENSAL,
    from_dq,
    machine_from_dyr,
    saturation,
    saturation_coefficients,
    to_dq,
)

# The ieee14 GENROU of experiments/andes_bench/data/ieee14/ieee14.dyr (bus 1).
ROU = dict(td0_1_s=6.5, td0_2_s=0.06, tq0_1_s=0.2, tq0_2_s=0.05, h_s=4.0, d_pu=0.0, xd_pu=1.8,
           xq_pu=1.75, xd1_pu=0.6, xq1_pu=0.8, x2_pu=0.23, xl_pu=0.15)
SAL = dict(td0_1_s=5.0, td0_2_s=0.05, tq0_2_s=0.1, h_s=3.0, d_pu=0.5, xd_pu=1.1, xq_pu=0.7,
           xd1_pu=0.3, x2_pu=0.25, xl_pu=0.15)

MACHINES = {
    "GENROU": GENROU(**ROU),
    "GENROU saturated": GENROU(**ROU, s10=0.09, s12=0.38),
    "GENROU saturated, Ra > 0": GENROU(**ROU, s10=0.09, s12=0.38, ra_pu=0.01),
    "GENSAL": GENSAL(**SAL),
    "GENSAL saturated, Ra > 0": GENSAL(**SAL, s10=0.1, s12=0.3, ra_pu=0.005),
    "GENCLS": GENCLS(h_s=5.0, d_pu=1.0, x1_pu=0.3),
    "GENCLS, Ra > 0": GENCLS(h_s=5.0, d_pu=1.0, x1_pu=0.3, ra_pu=0.01),
}

OPERATING_POINTS = {  # (|V|, angle [rad], P, Q), current out of the machine
    "lagging": (1.0, 0.3, 0.8, 0.3),
    "leading": (1.03, -0.2, 0.5, -0.2),
    "motoring": (0.98, 0.1, -0.3, 0.1),
}


def phasors(vm, ang, p, q):
    """(v_re, v_im, i_re, i_im) of |V| at ``ang`` delivering P + jQ."""
    v = vm * np.exp(1j * ang)
    i = np.conj((p + 1j * q) / v)
    return v.real, v.imag, i.real, i.imag


@pytest.mark.parametrize("op", list(OPERATING_POINTS))
@pytest.mark.parametrize("name", list(MACHINES))
def test_steady_state_holds(name, op):
    m = MACHINES[name]
    vm, ang, p, q = OPERATING_POINTS[op]
    v_re, v_im, i_re, i_im = phasors(vm, ang, p, q)
    st = m.steady_state(v_re, v_im, i_re, i_im)
    assert st.state.shape == (m.n_states,)
    assert float(st.state[-1]) == 1.0
    out = m.terminal(st.state, v_re, v_im)
    np.testing.assert_allclose([out.i_re_pu, out.i_im_pu], [i_re, i_im], rtol=0, atol=1e-12)
    np.testing.assert_allclose([out.p_pu, out.q_pu], [p, q], rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.te_pu, st.tm_pu, rtol=0, atol=1e-12)
    # Te = air-gap power at nominal speed = P + Ra |I|^2: independent of the model's internals.
    np.testing.assert_allclose(st.tm_pu, p + float(m.ra_pu) * (i_re ** 2 + i_im ** 2),
                               rtol=0, atol=1e-12)
    f = m.vector_field(st.state, v_re, v_im, st.efd_pu, st.tm_pu)
    assert f.shape == (m.n_states,)
    np.testing.assert_allclose(f, 0.0, rtol=0, atol=1e-12)


def test_steady_field_voltage_sees_saturation_and_resistance():
    v_re, v_im, i_re, i_im = phasors(*OPERATING_POINTS["lagging"])
    efd = {k: float(MACHINES[k].steady_state(v_re, v_im, i_re, i_im).efd_pu) for k in MACHINES}
    assert efd["GENROU saturated"] > efd["GENROU"] + 0.05
    assert efd["GENROU saturated, Ra > 0"] != efd["GENROU saturated"]
    # unsaturated, Ra = 0, Xd ~ Xq: Efd ~ |V + jXq I| (round rotor)
    e = abs(complex(v_re, v_im) + 1j * ROU["xq_pu"] * complex(i_re, i_im))
    assert abs(efd["GENROU"] - e) < 0.1


def test_park_round_trip(rng):
    re, im, delta = rng.normal(size=(3, 50))
    delta = 10 * delta
    d, q = to_dq(re, im, delta)
    back = from_dq(d, q, delta)
    np.testing.assert_allclose(back, [re, im], rtol=0, atol=1e-14)
    # d + j q = X e^{-j (delta - pi/2)}: magnitude kept, q axis along delta
    np.testing.assert_allclose(np.asarray(d) + 1j * np.asarray(q),
                               (re + 1j * im) * np.exp(-1j * (delta - np.pi / 2)), atol=1e-14)
    d, q = to_dq(np.cos(0.7), np.sin(0.7), 0.7)
    np.testing.assert_allclose([d, q], [0.0, 1.0], atol=1e-15)


def test_saturation_through_its_two_points():
    a, b = saturation_coefficients(0.09, 0.38)
    assert 0.0 < float(a) < 1.0 and float(b) > 0.0
    np.testing.assert_allclose(saturation(jnp.asarray(1.0), a, b), 0.09, rtol=1e-14)
    np.testing.assert_allclose(saturation(jnp.asarray(1.2), a, b), 0.38, rtol=1e-14)
    assert float(saturation(jnp.asarray(0.5 * float(a)), a, b)) == 0.0
    x = jnp.linspace(0.0, 2.0, 41)
    s = saturation(x, a, b)
    assert bool(jnp.all(jnp.diff(s) >= 0))
    grad = jax.jit(jax.vmap(jax.grad(lambda y: saturation(y, a, b))))(x)
    assert bool(jnp.all(jnp.isfinite(grad)))


@pytest.mark.parametrize("s12", [0.0, 0.38])
def test_no_saturation_when_s10_is_zero(s12):
    a, b = saturation_coefficients(0.0, s12)
    assert float(b) == 0.0
    np.testing.assert_array_equal(saturation(jnp.linspace(0.0, 3.0, 31), a, b), 0.0)
    v_re, v_im, i_re, i_im = phasors(*OPERATING_POINTS["lagging"])
    plain = GENROU(**ROU).steady_state(v_re, v_im, i_re, i_im)
    zero = GENROU(**ROU, s10=0.0, s12=s12).steady_state(v_re, v_im, i_re, i_im)
    np.testing.assert_array_equal(zero.state, plain.state)
    assert float(zero.efd_pu) == float(plain.efd_pu)


@pytest.mark.parametrize("change", [
    dict(xd1_pu=0.15),               # X'd = Xl: k3d = (X''d - Xl)/(X'd - Xl)
    dict(xq1_pu=0.15),               # X'q = Xl
    dict(xd_pu=0.15, xd1_pu=0.14),   # Xd = Xl: kq = (Xq - Xl)/(Xd - Xl)
])
def test_genrou_refuses_what_its_equations_cannot_evaluate(change):
    with pytest.raises(ValueError, match="GENROU: needs X'd, X'q and Xd other than Xl"):
        GENROU(**{**ROU, **change})


def test_gensal_refuses_what_its_equations_cannot_evaluate():
    with pytest.raises(ValueError, match="GENSAL: needs X'd other than Xl"):
        GENSAL(**{**SAL, "xd1_pu": 0.15})


# Records outside the usual order Xl < X''d < X'd <= Xd, X''d < X'q <= Xq, as PSS/E simulates them
# (with a warning): the ANDES IEEE 39-bus case ships 9 of its 10 GENROU with X''d below Xl.
ODD = {
    "GENROU X''d below Xl (IEEE 39 bus 30: 0.0079 against 0.125)": (GENROU, {**ROU, "x2_pu": 0.02}),
    "GENROU X''d = Xl": (GENROU, {**ROU, "x2_pu": 0.15}),
    "GENROU X''d above X'q": (GENROU, {**ROU, "x2_pu": 0.7, "xq1_pu": 0.65}),
    "GENSAL X''d below Xl": (GENSAL, {**SAL, "x2_pu": 0.05}),
}


@pytest.mark.parametrize("name", list(ODD))
def test_odd_records_start_flat_and_run_without_nan(name):
    """Used as given: the steady state is an equilibrium (zero vector field) and a 20 s
    response to a terminal-voltage dip of 5 % for 0.1 s (Efd, Tm held) stays finite, returns to
    the same state and swings no further than the ordinary record does."""
    cls, kw = ODD[name]
    m = cls(**kw, s10=0.09, s12=0.38)
    v_re, v_im, i_re, i_im = phasors(1.0, 0.2, 0.8, 0.3)
    st = m.steady_state(v_re, v_im, i_re, i_im)
    out = m.terminal(st.state, v_re, v_im)
    np.testing.assert_allclose([out.p_pu, out.q_pu], [0.8, 0.3], rtol=0, atol=1e-12)
    np.testing.assert_allclose(m.vector_field(st.state, v_re, v_im, st.efd_pu, st.tm_pu), 0.0,
                               rtol=0, atol=1e-12)
    dt, n = 0.001, 20000

    def f(y, k):
        dip = jnp.where((k * dt >= 1.0) & (k * dt < 1.1), 0.95, 1.0)
        return m.vector_field(y, dip * v_re, dip * v_im, st.efd_pu, st.tm_pu)

    def step(y, k):
        k1 = f(y, k)
        k2 = f(y + 0.5 * dt * k1, k)
        k3 = f(y + 0.5 * dt * k2, k)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + f(y + dt * k3, k))
        return y, y[-1]

    y_end, omega = jax.jit(lambda y: jax.lax.scan(step, y, jnp.arange(n)))(st.state)
    assert np.all(np.isfinite(np.asarray(omega))) and np.all(np.isfinite(np.asarray(y_end)))
    assert 0 < np.max(np.abs(np.asarray(omega) - 1.0)) < 0.01
    np.testing.assert_allclose(y_end, st.state, rtol=0, atol=1e-4)


def test_gencls_and_machine_from_dyr_refuse_bad_source_reactance():
    with pytest.raises(ValueError):
        GENCLS(h_s=5.0, d_pu=0.0, x1_pu=0.0)
    with pytest.raises(ValueError, match="ZSORCE"):
        machine_from_dyr("GENCLS", {"H": 5.0, "D": 0.0})
    with pytest.raises(ValueError, match="not a supported machine"):
        machine_from_dyr("GENQEC", {})


def test_machine_from_dyr_maps_names():
    p = {"T'do": 6.5, "T''do": 0.06, "T'qo": 0.2, "T''qo": 0.05, "H": 4.0, "D": 0.0, "Xd": 1.8,
         "Xq": 1.75, "X'd": 0.6, "X'q": 0.8, "X''d": 0.23, "Xl": 0.15, "S(1.0)": 0.09,
         "S(1.2)": 0.38}
    m = machine_from_dyr("GENROU", p, ra_pu=0.01, f_nominal_hz=50.0)
    expected = GENROU(**ROU, s10=0.09, s12=0.38, ra_pu=0.01, omega_s_rad_s=2 * np.pi * 50.0)
    for a, b in zip(jax.tree_util.tree_leaves(m), jax.tree_util.tree_leaves(expected)):
        assert float(a) == float(b)


def _stack(*modules):
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *modules)


@pytest.mark.parametrize("kind", ["GENROU", "GENSAL", "GENCLS"])
def test_vmap_over_stacked_parameters_equals_loop(kind):
    if kind == "GENROU":
        ms = [GENROU(**ROU, s10=0.09, s12=0.38), GENROU(**{**ROU, "h_s": 6.0, "x2_pu": 0.2}),
              GENROU(**ROU, s10=0.05, s12=0.2, ra_pu=0.003)]
    elif kind == "GENSAL":
        ms = [GENSAL(**SAL), GENSAL(**{**SAL, "xq_pu": 0.9}, s10=0.1, s12=0.3),
              GENSAL(**SAL, ra_pu=0.01)]
    else:
        ms = [GENCLS(h_s=5.0, d_pu=1.0, x1_pu=0.3), GENCLS(h_s=3.0, d_pu=0.0, x1_pu=0.25),
              GENCLS(h_s=4.0, d_pu=2.0, x1_pu=0.4, ra_pu=0.01)]
    ops = np.array([phasors(*OPERATING_POINTS[k]) for k in OPERATING_POINTS])

    def run(m, op):
        st = m.steady_state(*op)
        y = st.state.at[-2].add(0.1).at[-1].add(1e-3)     # away from the steady state
        out = m.terminal(y, op[0], op[1])
        return (st.state, st.efd_pu, st.tm_pu, out.p_pu, out.q_pu, out.ifd_pu,
                m.vector_field(y, op[0], op[1], st.efd_pu, st.tm_pu))

    batched = jax.vmap(run)(_stack(*ms), jnp.asarray(ops))
    for k, m in enumerate(ms):
        single = run(m, jnp.asarray(ops[k]))
        for a, b in zip(batched, single):
            np.testing.assert_allclose(a[k], b, rtol=1e-13, atol=1e-14)


def _rk4(f, y, dt, n):
    def step(y, _):
        k1 = f(y)
        k2 = f(y + 0.5 * dt * k1)
        k3 = f(y + 0.5 * dt * k2)
        k4 = f(y + dt * k3)
        y = y + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return y, y
    return jax.lax.scan(step, y, None, length=n)


def test_jacfwd_of_power_wrt_parameters_is_finite():
    v_re, v_im, i_re, i_im = phasors(*OPERATING_POINTS["lagging"])
    names = ("h_s", "xd_pu", "xq_pu", "xd1_pu", "xq1_pu", "x2_pu")

    def p_after_swing(theta):
        m = GENROU(**{**ROU, **dict(zip(names, theta))}, s10=0.09, s12=0.38, ra_pu=0.002)
        st = m.steady_state(v_re, v_im, i_re, i_im)
        y0 = st.state.at[4].add(0.05)

        def f(y):
            return m.vector_field(y, v_re, v_im, st.efd_pu, st.tm_pu)

        y, _ = _rk4(f, y0, 0.005, 40)
        return m.terminal(y, v_re, v_im).p_pu

    theta = jnp.asarray([ROU[k] for k in names])
    jac = np.asarray(jax.jit(jax.jacfwd(p_after_swing))(theta))
    assert jac.shape == (len(names),)
    assert np.all(np.isfinite(jac))
    assert abs(jac[0]) > 1e-4      # 0.2 s after a kick, P depends on H
    # and it is the derivative: central differences agree
    fn = jax.jit(p_after_swing)
    for j in range(len(names)):
        h = 1e-6 * float(theta[j])
        fd = (float(fn(theta.at[j].add(h))) - float(fn(theta.at[j].add(-h)))) / (2 * h)
        np.testing.assert_allclose(jac[j], fd, rtol=1e-5, atol=1e-8)


# --- physics check: a torque step at constant terminal voltage ------------------------------

def test_genrou_torque_step_settles_and_swings_at_synchronising_frequency():
    """GENROU on an infinite bus at its terminal, Efd held, Tm stepped by +0.05 pu.

    (1) it settles where Te = Tm, at omega = 1 and at the steady state of the same Efd and the
    new Tm (found by root-finding on ``steady_state``, not by the simulation);
    (2) it swings at f = sqrt(omega_s Ks / (2H)) / (2 pi), Ks = dTe/d(delta) by finite
    differences of ``terminal``. Which fluxes are held for Ks matters: the swing (~1.3 Hz here)
    is slow against the damper windings and the q-axis circuits (T''do X''d/X'd ~ 0.02 s,
    T'qo X'q/Xq ~ 0.09 s at constant voltage) and fast against the field (T'do X'd/Xd ~ 2 s).
    Ks is therefore taken with E'q held and the other three flux states at their quasi-steady
    values (their derivatives zero at each delta): the transient synchronising coefficient.
    With all four fluxes held (the subtransient coefficient) the prediction is 2.3 Hz, 76 % off.
    The dampers also add damping torque (damping ratio ~0.24 here) and their lag, so the
    formula remains approximate: 1.23 Hz predicted against 1.33 Hz simulated (8 %); the test
    asks for 10 %.
    """
    m = GENROU(**ROU, s10=0.09, s12=0.38)
    v_re, v_im, i_re, i_im = phasors(1.0, 0.0, 0.7, 0.2)
    st = m.steady_state(v_re, v_im, i_re, i_im)
    efd, tm = st.efd_pu, st.tm_pu + 0.05
    dt, n = 0.005, 6000                                   # 30 s, RK4

    def f(y):
        return m.vector_field(y, v_re, v_im, efd, tm)

    y_end, ys = jax.jit(lambda y: _rk4(f, y, dt, n))(st.state)
    te = np.asarray(jax.vmap(lambda y: m.terminal(y, v_re, v_im).te_pu)(ys))
    t = dt * np.arange(1, n + 1)

    # (1) settled
    assert abs(float(y_end[5]) - 1.0) < 1e-8
    assert abs(te[-1] - float(tm)) < 1e-6
    assert float(y_end[4]) > float(st.state[4]) + 0.02       # the rotor advanced

    @jax.jit
    def mismatch(i):
        s = m.steady_state(v_re, v_im, i[0], i[1])
        return jnp.stack([s.efd_pu - efd, s.tm_pu - tm])

    i_new = fsolve(mismatch, [i_re, i_im], xtol=1e-14)
    target = m.steady_state(v_re, v_im, *i_new)
    np.testing.assert_allclose(y_end, target.state, rtol=0, atol=1e-5)

    # (2) swing frequency: accelerating torque Tm - Te crosses zero twice per period
    early = t < 4.0
    acc = float(tm) - te[early]
    crossings = t[early][1:][np.diff(np.sign(acc)) != 0]
    assert len(crossings) >= 6
    f_sim = 1.0 / (2.0 * np.mean(np.diff(crossings[:6])))

    @jax.jit
    def fast(x, d_delta):
        """d/dt of psi_kd, E'd, psi_kq (set to x) at delta + d_delta, E'q held."""
        y = st.state.at[4].add(d_delta).at[1:4].set(x)
        out = m.terminal(y, v_re, v_im)
        return m.flux_field(y, v_re, v_im, out, st.efd_pu)[1:4], out.te_pu

    def te_at(d_delta):
        """Te at delta + d_delta with E'q held and the fast fluxes at rest."""
        x = fsolve(lambda x: np.asarray(fast(x, d_delta)[0]), np.asarray(st.state[1:4]),
                   xtol=1e-14)
        return float(fast(x, d_delta)[1])

    h = 1e-4
    ks = (te_at(h) - te_at(-h)) / (2 * h)
    f_pred = np.sqrt(float(m.omega_s_rad_s) * ks / (2 * float(m.h_s))) / (2 * np.pi)
    assert 0.5 < f_sim < 3.0
    assert abs(f_pred / f_sim - 1.0) < 0.10, (f_pred, f_sim)
