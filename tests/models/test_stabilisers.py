"""PSS/E stabilisers IEEEST and ST2CUT (src/jaxdse/_dyr/stabiliser.py).

The transfer functions the tests compare against are written here from the PSS/E block
diagrams, independently of the state-space realisation in the module.
"""

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdse._models.base import StabiliserInputs
from jaxdse._models.stabilisers import (
    IEEEST,
    ST2CUT,
    STABILISER_FIELDS,
    STABILISERS,
    stabiliser_from_dyr,
)

ROOT = Path(__file__).resolve().parents[2]
WECC_DYR = ROOT / "experiments/andes_bench/data/wecc/wecc.dyr"
WECC240_DYR = Path("/work/shared/data/wecc240/240busWECC_2018_PSS.dyr")

# Real records (ICONs then CONs, PSS/E order) from the data files above.
IEEEST_WECC = (3, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.75, 1, 4.2, -2, 0.1, -0.1, 0, 0)  # bus 3
IEEEST_WECC240 = (1, 0, 1.013, 0.013, 0, 0, 1.013, 0.113, 3.0, 0.02, 0, 0, 1.65, 1.65, 3.0,
                  0.1, -0.1, 0, 0)                                                   # bus 1333
ST2CUT_WECC_5 = (1, 0, 0, 0, 5.5, 0, 0.03, 0, 10, 10, 0.4, 0.04, 0, 0, 0, 0, 0.05, -0.05, 0, 0)
ST2CUT_WECC_29 = (3, 0, 0, 0, -3.5, 0, 0, 0, 1, 1, 0, 3, 0.08, 0.027, 0.08, 0.027, 0.1, -0.1,
                  0, 0)
ST2CUT_WECC_147 = (1, 0, 0, 0, 5, 0, 0.029, 0, 2.4, 2.4, 0.144, 0.04, 0.377, 0.105, 0, 0, 0.05,
                   -0.05, 0, 0)

# A 4th-order filter (complex poles in both sections), both lead-lags and the washout active.
IEEEST_FULL = dict(a1_s=0.1, a2_s2=0.005, a3_s=0.05, a4_s2=0.001, a5_s=0.02, a6_s2=0.001,
                   t1_s=0.3, t2_s=0.05, t3_s=0.2, t4_s=0.04, t5_s=2.0, t6_s=0.5, ks=5.0,
                   ls_max_pu=0.5, ls_min_pu=-0.5)
ST2CUT_FULL = dict(k1=10.0, k2=-0.5, t1_s=0.02, t2_s=0.05, t3_s=0.5, t4_s=0.5, t5_s=0.15,
                   t6_s=0.05, t7_s=0.15, t8_s=0.05, t9_s=0.1, t10_s=0.03, ls_max_pu=0.5,
                   ls_min_pu=-0.5)


def inputs(speed=0.003, freq=-0.002, pe=0.8, pa=0.05, vt=1.02, dvdt=0.01):
    return StabiliserInputs(*(jnp.asarray(v, dtype=float) for v in (speed, freq, pe, pa, vt, dvdt)))


def with_signal(inp, mode, value):
    """``inp`` with the member selected by input code ``mode`` replaced."""
    return inp._replace(**{inp._fields[mode - 1]: jnp.asarray(value, dtype=float)})


# --- analytic transfer functions (from the block diagrams) ------------------------------------

def _ll(s, lead, lag):
    return (1 + lead * s) / (1 + lag * s) if lag > 0 else 1.0


def ieeest_tf(m, s):
    """VSS/u of IEEEST (linear, limits inactive)."""
    f = lambda name: float(getattr(m, name))  # noqa: E731
    filt = (1 + f("a5_s") * s + f("a6_s2") * s**2) / (
        (1 + f("a1_s") * s + f("a2_s2") * s**2) * (1 + f("a3_s") * s + f("a4_s2") * s**2))
    wo = f("ks") * f("t5_s") * s / (1 + f("t6_s") * s) if f("t5_s") != 0 else f("ks")
    return filt * _ll(s, f("t1_s"), f("t2_s")) * _ll(s, f("t3_s"), f("t4_s")) * wo


def st2cut_tf(m, s):
    """(VSS/u1, VSS/u2) of ST2CUT (linear, limits inactive)."""
    f = lambda name: float(getattr(m, name))  # noqa: E731
    rest = (f("t3_s") * s / (1 + f("t4_s") * s) * _ll(s, f("t5_s"), f("t6_s"))
            * _ll(s, f("t7_s"), f("t8_s")) * _ll(s, f("t9_s"), f("t10_s")))
    return f("k1") / (1 + f("t1_s") * s) * rest, f("k2") / (1 + f("t2_s") * s) * rest


@eqx.filter_jit
def _jacobians(m, inp, mode):
    x0 = m.initial_state(inp)
    u0 = inp[mode - 1]
    fx = lambda x, u: m.vector_field(x, with_signal(inp, mode, u))  # noqa: E731
    gx = lambda x, u: m.output(x, with_signal(inp, mode, u))  # noqa: E731
    return (jax.jacfwd(fx, 0)(x0, u0), jax.jacfwd(fx, 1)(x0, u0), jax.grad(gx, 0)(x0, u0),
            jax.grad(gx, 1)(x0, u0))


def linearisation(m, inp, mode):
    """A, B, C, D of the model about its rest state at ``inp`` for the input ``mode``."""
    a, b, c, d = _jacobians(m, inp, mode)
    return np.asarray(a), np.asarray(b), np.asarray(c), float(d)


def frequency_response(abcd, omegas):
    a, b, c, d = abcd
    n = a.shape[0]
    return np.array([c @ np.linalg.solve(1j * w * np.eye(n) - a, b) + d for w in omegas])


OMEGAS = np.logspace(-2, 2.5, 13)

IEEEST_CASES = {
    "full 4th order": IEEEST_FULL,
    "A4 = 0 (3rd order)": {**IEEEST_FULL, "a4_s2": 0.0},
    "A2 = A4 = 0": {**IEEEST_FULL, "a2_s2": 0.0, "a4_s2": 0.0, "a6_s2": 0.0},
    "second section removed": {**IEEEST_FULL, "a3_s": 0.0, "a4_s2": 0.0},
    "biproper 2nd order": {**IEEEST_FULL, "a2_s2": 0.0, "a3_s": 0.05, "a4_s2": 0.0},
    "wecc240 record": dict(zip(("a1_s", "a2_s2", "a3_s", "a4_s2", "a5_s", "a6_s2", "t1_s", "t2_s",
                                "t3_s", "t4_s", "t5_s", "t6_s", "ks"), IEEEST_WECC240[2:15])),
    "no filter, lead-lags bypassed": dict(t1_s=0.4, t5_s=1.0, t6_s=4.2, ks=-2.0),
    "washout bypassed (T5 = 0)": {**IEEEST_FULL, "t5_s": 0.0},
}

ST2CUT_CASES = {
    "full": ST2CUT_FULL,
    "gains only, lead-lags bypassed": {**ST2CUT_FULL, "t1_s": 0.0, "t2_s": 0.0, "t6_s": 0.0,
                                       "t8_s": 0.0, "t10_s": 0.0},
    "wecc bus 29": dict(zip(("k1", "k2", "t1_s", "t2_s", "t3_s", "t4_s", "t5_s", "t6_s", "t7_s",
                             "t8_s", "t9_s", "t10_s"), ST2CUT_WECC_29[4:16])),
}


@pytest.mark.parametrize("name", list(IEEEST_CASES))
def test_ieeest_linearisation_matches_block_diagram(name):
    m = IEEEST(mode=1, **IEEEST_CASES[name])
    inp = inputs(speed=0.0)
    got = frequency_response(linearisation(m, inp, 1), OMEGAS)
    want = np.array([ieeest_tf(m, 1j * w) for w in OMEGAS])
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * np.max(np.abs(want)))


@pytest.mark.parametrize("name", list(ST2CUT_CASES))
def test_st2cut_linearisation_matches_block_diagram(name):
    m = ST2CUT(mode=1, mode2=3, **ST2CUT_CASES[name])
    inp = inputs(speed=0.0)
    want1, want2 = np.array([st2cut_tf(m, 1j * w) for w in OMEGAS]).T
    for mode, want in ((1, want1), (3, want2)):
        got = frequency_response(linearisation(m, inp, mode), OMEGAS)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * np.max(np.abs(want)))


# --- time domain: fixed-step RK4 against the analytic steady sinusoid -------------------------

def simulate(m, inputs_at, x0, dt, n_steps):
    """Classic RK4 with the inputs evaluated at the stage times; returns (t, output)."""

    def f(x, t):
        return m.vector_field(x, inputs_at(t))

    def step(x, k):
        t = k * dt
        k1 = f(x, t)
        k2 = f(x + 0.5 * dt * k1, t + 0.5 * dt)
        k3 = f(x + 0.5 * dt * k2, t + 0.5 * dt)
        k4 = f(x + dt * k3, t + dt)
        x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x, m.output(x, inputs_at(t + dt))

    _, y = jax.jit(lambda x: jax.lax.scan(step, x, jnp.arange(n_steps)))(x0)
    return dt * np.arange(1, n_steps + 1), np.asarray(y)


def test_ieeest_sinusoid_rk4_matches_transfer_function():
    m = IEEEST(mode=1, **IEEEST_FULL)
    w, a = 2 * np.pi * 1.2, 2e-4
    base = inputs(speed=0.0)
    at = lambda t: with_signal(base, 1, a * jnp.sin(w * t))  # noqa: E731
    t, y = simulate(m, at, m.initial_state(at(0.0)), 1e-3, 12_000)
    h = ieeest_tf(m, 1j * w)
    want = np.imag(a * h * np.exp(1j * w * t))
    tail = t > 10.0
    assert np.max(np.abs(y)) < float(m.ls_max_pu)           # linear: limits never reached
    assert np.max(np.abs(y[tail] - want[tail])) < 1e-5 * a * abs(h)


def test_st2cut_two_sinusoids_rk4_matches_transfer_function():
    m = ST2CUT(mode=1, mode2=3, **ST2CUT_FULL)
    w, a, b, p0 = 2 * np.pi * 0.7, 1e-3, 2e-2, 0.8
    base = inputs()

    def at(t):
        return with_signal(with_signal(base, 1, a * jnp.sin(w * t)), 3, p0 + b * jnp.cos(w * t))

    t, y = simulate(m, at, m.initial_state(at(0.0)), 1e-3, 12_000)
    h1, h2 = st2cut_tf(m, 1j * w)
    want = np.imag(a * h1 * np.exp(1j * w * t)) + np.real(b * h2 * np.exp(1j * w * t))
    tail = t > 10.0
    assert np.max(np.abs(y)) < float(m.ls_max_pu)
    assert np.max(np.abs(y[tail] - want[tail])) < 1e-5 * np.max(np.abs(want[tail]))


# --- steady state -----------------------------------------------------------------------------

STEADY_INPUTS = [inputs(), inputs(0.01, 0.004, 1.1, -0.2, 0.95, -0.03),
                 inputs(-0.02, -0.01, 0.0, 0.3, 1.1, 0.2)]


def _assert_rest(m, inp, selected):
    x0 = m.initial_state(inp)
    assert x0.shape == (m.n_states,)
    np.testing.assert_allclose(np.asarray(m.vector_field(x0, inp)), 0.0, atol=1e-14)
    assert abs(float(m.output(x0, inp))) < 1e-14
    # the rest state belongs to the selected inputs only: moving one of them moves the state,
    # moving any other input does not (the voltage enters only through the cut-off)
    for mode in range(1, 7):
        dx = m.vector_field(x0, with_signal(inp, mode, inp[mode - 1] + 0.1))
        if mode in selected:
            assert np.max(np.abs(np.asarray(dx))) > 1e-6, mode
        else:
            np.testing.assert_allclose(np.asarray(dx), 0.0, atol=1e-14)


@pytest.mark.slow
@pytest.mark.parametrize("mode", range(1, 7))
def test_ieeest_rest_state_every_mode(mode):
    for params in (IEEEST_FULL, IEEEST_CASES["wecc240 record"], IEEEST_CASES["A2 = A4 = 0"]):
        m = IEEEST(mode=mode, **params)
        for inp in STEADY_INPUTS:
            _assert_rest(m, inp, {mode})


@pytest.mark.parametrize("mode,mode2", [(1, 0), (2, 3), (3, 1), (4, 5), (5, 6), (6, 2), (1, 4)])
def test_st2cut_rest_state_every_mode(mode, mode2):
    for params in (ST2CUT_FULL, ST2CUT_CASES["wecc bus 29"]):
        kw = {**params, "k2": -0.5}                          # both gains nonzero
        m = ST2CUT(mode=mode, mode2=mode2, **kw)
        for inp in STEADY_INPUTS:
            _assert_rest(m, inp, {mode, mode2} - {0})


def test_ieeest_rest_state_closed_form():
    inp = inputs(speed=0.007)
    x0 = IEEEST(mode=1, **IEEEST_FULL).initial_state(inp)
    np.testing.assert_allclose(np.asarray(x0), [0.007, 0, 0, 0, 0.007, 0.007, 0.007])
    s = ST2CUT(mode=1, mode2=3, **ST2CUT_FULL)
    x0 = s.initial_state(inputs(speed=0.007, pe=0.8))
    np.testing.assert_allclose(np.asarray(x0), [0.07, -0.4, -0.33, 0, 0, 0], atol=1e-15)


def test_washout_bypass_rest_output_is_the_dc_gain():
    m = IEEEST(mode=1, **{**IEEEST_FULL, "t5_s": 0.0})       # output KS u at rest
    inp = inputs(speed=0.01)
    x0 = m.initial_state(inp)
    np.testing.assert_allclose(np.asarray(m.vector_field(x0, inp)), 0.0, atol=1e-14)
    assert float(m.output(x0, inp)) == pytest.approx(0.05)


# --- limits and voltage cut-off ---------------------------------------------------------------

def _unlimited(m):
    return eqx.tree_at(lambda q: (q.ls_max_pu, q.ls_min_pu), m, (jnp.asarray(1e9), jnp.asarray(-1e9)))


@pytest.mark.parametrize("cls,params,index", [(IEEEST, IEEEST_FULL, 6), (ST2CUT, ST2CUT_FULL, 2)])
def test_output_limits(cls, params, index):
    m = cls(mode=1, **{**params, "ls_max_pu": 0.08, "ls_min_pu": -0.03})
    free = _unlimited(m)
    inp = inputs()
    x0 = m.initial_state(inp)
    seen = set()
    for offset in np.linspace(-0.01, 0.01, 21):             # washout state moved off its rest
        x = x0.at[index].add(offset)
        y, y_free = float(m.output(x, inp)), float(free.output(x, inp))
        assert y == pytest.approx(min(max(y_free, -0.03), 0.08), abs=1e-15)
        seen.add("hi" if y_free > 0.08 else "lo" if y_free < -0.03 else "in")
        np.testing.assert_array_equal(m.vector_field(x, inp), free.vector_field(x, inp))
    # the offsets must reach both limits and the linear range for the test to mean something
    assert seen == {"hi", "lo", "in"}


def _direct_state(m, inp, level):
    """A state whose output (before the limits) is ``level`` (IEEEST: washout state moved)."""
    x0 = m.initial_state(inp)
    if isinstance(m, IEEEST):
        return x0.at[6].add(-level * float(m.t6_s) / (float(m.ks) * float(m.t5_s)))
    return x0.at[2].add(-level * float(m.t4_s) / float(m.t3_s))   # ST2CUT, lead-lags bypassed


@pytest.mark.parametrize("cls,params", [
    (IEEEST, dict(t5_s=1.0, t6_s=2.0, ks=4.0)),
    (ST2CUT, dict(k1=5.0, t3_s=2.0, t4_s=2.0, t6_s=0.0, t8_s=0.0, t10_s=0.0)),
])
def test_voltage_cut_off(cls, params):
    m = cls(mode=1, **params, ls_max_pu=0.1, ls_min_pu=-0.1, vcu_pu=1.1, vcl_pu=0.8)
    x = _direct_state(m, inputs(), 0.05)
    out = lambda model, vt: float(model.output(x, inputs(vt=vt)))  # noqa: E731
    assert out(m, 1.0) == pytest.approx(0.05, rel=1e-12)
    assert out(m, 1.15) == 0.0 and out(m, 0.75) == 0.0
    assert out(m, 1.099) == pytest.approx(0.05) and out(m, 0.801) == pytest.approx(0.05)
    no_upper = eqx.tree_at(lambda q: q.vcu_pu, m, jnp.asarray(0.0))
    no_lower = eqx.tree_at(lambda q: q.vcl_pu, m, jnp.asarray(0.0))
    assert out(no_upper, 5.0) == pytest.approx(0.05) and out(no_upper, 0.75) == 0.0
    assert out(no_lower, 0.0) == pytest.approx(0.05) and out(no_lower, 1.15) == 0.0


# --- bypassed blocks: values and gradients ----------------------------------------------------

BYPASS_IEEEST = {
    "everything bypassed": dict(t5_s=1.0, t6_s=2.0, ks=4.0),
    "A2 = A4 = 0": dict(a1_s=0.2, a3_s=0.1, a5_s=0.05, t1_s=0.3, t5_s=1.0, t6_s=2.0, ks=4.0),
    "washout bypassed": dict(a1_s=0.2, a2_s2=0.01, t5_s=0.0, t6_s=2.0, ks=4.0),
}
BYPASS_ST2CUT = {
    "everything bypassed": dict(k1=5.0, k2=2.0, t1_s=0.0, t2_s=0.0, t5_s=0.3, t6_s=0.0,
                                t7_s=0.2, t8_s=0.0, t9_s=0.1, t10_s=0.0),
}


def _loss(model, state, inp):
    return jnp.sum(model.vector_field(state, inp) ** 2) + model.output(state, inp)


def _loss_and_grads(m, x, inp):
    return _loss(m, x, inp), eqx.filter_grad(_loss)(m, x, inp), jax.grad(_loss, 1)(m, x, inp)


def _grads_finite(m, x, inp):
    value, g_model, g_state = _loss_and_grads(m, x, inp)
    leaves = jax.tree_util.tree_leaves(eqx.filter(g_model, eqx.is_array))
    assert len(leaves) > 10
    assert all(np.all(np.isfinite(np.asarray(v))) for v in leaves)
    assert np.all(np.isfinite(np.asarray(g_state)))
    assert np.isfinite(float(value))


@pytest.mark.parametrize("name", list(BYPASS_IEEEST))
def test_ieeest_bypassed_no_nan(name):
    m = IEEEST(mode=3, **BYPASS_IEEEST[name])
    inp = inputs(pe=0.8)
    x = m.initial_state(inputs(pe=0.78)) + 0.01
    _grads_finite(m, x, inp)


def test_ieeest_everything_bypassed_is_gain_and_washout():
    m = IEEEST(mode=3, **BYPASS_IEEEST["everything bypassed"], ls_max_pu=9.0, ls_min_pu=-9.0)
    x = jnp.array([0.3, 0.1, 0.2, 0.4, 0.5, 0.6, 0.75])
    inp = inputs(pe=0.8)
    assert float(m.output(x, inp)) == pytest.approx(4.0 * 1.0 / 2.0 * (0.8 - 0.75))
    np.testing.assert_allclose(np.asarray(m.vector_field(x, inp)), [0, 0, 0, 0, 0, 0, 0.025])


def test_st2cut_bypassed_no_nan_and_values():
    m = ST2CUT(mode=1, mode2=3, **BYPASS_ST2CUT["everything bypassed"], ls_max_pu=9.0,
               ls_min_pu=-9.0)
    inp = inputs(speed=0.01, pe=0.8)
    x = m.initial_state(inputs(speed=0.0, pe=0.8)) + 0.01
    _grads_finite(m, x, inp)
    # lags bypassed: the washout sees K1 u1 + K2 u2 = 0.05 + 1.6 at once; lead-lags pass through
    assert float(m.output(x, inp)) == pytest.approx(3.0 / 3.0 * (1.65 - float(x[2])))


def test_zero_washout_denominator_under_tracing_gives_no_nan():
    # T6 = 0 is refused when concrete; one slipped in by tree_at (as under vmap/grad) is finite
    m = eqx.tree_at(lambda q: q.t6_s, IEEEST(mode=1, **IEEEST_FULL), jnp.asarray(0.0))
    s = eqx.tree_at(lambda q: (q.t3_s, q.t4_s), ST2CUT(mode=1, **ST2CUT_FULL),
                    (jnp.asarray(0.0), jnp.asarray(0.0)))
    for model in (m, s):
        _grads_finite(model, model.initial_state(inputs()) + 0.01, inputs())
        # the washout is then bypassed: still a rest state, with the DC gain at the output
        x0 = model.initial_state(inputs())
        np.testing.assert_allclose(np.asarray(model.vector_field(x0, inputs())), 0.0, atol=1e-14)
    assert float(s.output(s.initial_state(inputs()), inputs())) == pytest.approx(0.03)


# --- vmap -------------------------------------------------------------------------------------

def _stack(models):
    return jax.tree.map(lambda *xs: jnp.stack(xs), *models)


@pytest.mark.parametrize("cls,param_sets", [
    (IEEEST, [IEEEST_FULL, IEEEST_CASES["A2 = A4 = 0"], IEEEST_CASES["wecc240 record"],
              BYPASS_IEEEST["everything bypassed"]]),
    (ST2CUT, [ST2CUT_FULL, ST2CUT_CASES["wecc bus 29"], BYPASS_ST2CUT["everything bypassed"]]),
])
def test_vmap_over_parameter_sets_equals_loop(cls, param_sets):
    models = [cls(mode=1, **p) for p in param_sets]
    rng = np.random.default_rng(0)
    inps = [inputs(*rng.normal(0, 0.05, 4), 1.0 + rng.normal(0, 0.02), rng.normal(0, 0.05))
            for _ in models]
    states = [m.initial_state(i) + jnp.asarray(rng.normal(0, 0.01, m.n_states))
              for m, i in zip(models, inps)]
    stacked, inp_b, x_b = _stack(models), _stack(inps), jnp.stack(states)
    x0_v = jax.vmap(lambda m, i: m.initial_state(i))(stacked, inp_b)
    f_v = jax.vmap(lambda m, x, i: m.vector_field(x, i))(stacked, x_b, inp_b)
    y_v = jax.vmap(lambda m, x, i: m.output(x, i))(stacked, x_b, inp_b)
    for k, (m, x, i) in enumerate(zip(models, states, inps)):
        np.testing.assert_allclose(np.asarray(x0_v[k]), np.asarray(m.initial_state(i)), rtol=1e-14)
        np.testing.assert_allclose(np.asarray(f_v[k]), np.asarray(m.vector_field(x, i)),
                                   rtol=1e-12, atol=1e-15)
        assert float(y_v[k]) == pytest.approx(float(m.output(x, i)), rel=1e-12, abs=1e-15)


# --- .dyr records -----------------------------------------------------------------------------

def test_field_tables_follow_psse_order():
    assert STABILISER_FIELDS["IEEEST"][:2] == ("MODE", "busr")
    assert len(STABILISER_FIELDS["IEEEST"]) == 2 + 17
    assert STABILISER_FIELDS["ST2CUT"][:4] == ("MODE", "busr", "MODE2", "busr2")
    assert len(STABILISER_FIELDS["ST2CUT"]) == 4 + 16
    assert set(STABILISERS) == set(STABILISER_FIELDS)


def test_from_dyr_maps_the_constants():
    m = stabiliser_from_dyr("IEEEST", IEEEST_WECC240)
    assert isinstance(m, IEEEST) and m.mode == 1 and not m.remote_input_at_terminal
    got = [float(getattr(m, f)) for f in ("a1_s", "a2_s2", "a5_s", "a6_s2", "t1_s", "t2_s",
                                          "t5_s", "t6_s", "ks", "ls_max_pu", "ls_min_pu")]
    assert got == [1.013, 0.013, 1.013, 0.113, 3.0, 0.02, 1.65, 1.65, 3.0, 0.1, -0.1]
    m = stabiliser_from_dyr("IEEEST", IEEEST_WECC)
    assert m.mode == 3 and float(m.t4_s) == 0.75 and float(m.t6_s) == 4.2 and float(m.ks) == -2
    s = stabiliser_from_dyr("ST2CUT", ST2CUT_WECC_29)
    assert isinstance(s, ST2CUT) and (s.mode, s.mode2) == (3, 0)
    got = [float(getattr(s, f)) for f in ("k1", "k2", "t3_s", "t4_s", "t5_s", "t6_s", "t7_s",
                                          "t8_s", "t9_s", "t10_s", "ls_max_pu", "ls_min_pu")]
    assert got == [-3.5, 0.0, 1.0, 1.0, 0.0, 3.0, 0.08, 0.027, 0.08, 0.027, 0.1, -0.1]
    remote = stabiliser_from_dyr("ST2CUT", (1, 0, 3, 1234) + ST2CUT_WECC_147[4:])
    assert remote.remote_bus2 == 1234 and remote.remote_input_at_terminal


@pytest.mark.parametrize("model,constants", [
    ("IEEEST", IEEEST_WECC), ("IEEEST", IEEEST_WECC240), ("ST2CUT", ST2CUT_WECC_5),
    ("ST2CUT", ST2CUT_WECC_29), ("ST2CUT", ST2CUT_WECC_147)])
def test_real_records_rest_at_zero_output(model, constants):
    m = stabiliser_from_dyr(model, constants)
    inp = inputs()
    x0 = m.initial_state(inp)
    np.testing.assert_allclose(np.asarray(m.vector_field(x0, inp)), 0.0, atol=1e-14)
    assert float(m.output(x0, inp)) == 0.0


@pytest.mark.parametrize("path", [WECC_DYR, WECC240_DYR], ids=["wecc", "wecc240"])
def test_every_record_of_the_data_files(path):
    if not path.exists():
        pytest.skip(f"{path} not present")
    from jaxdse._io.psse import read_dyr

    records = [r for r in read_dyr(str(path)).records if r.model in STABILISERS]
    assert records
    for r in records:
        m = stabiliser_from_dyr(r.model, r.constants)
        assert isinstance(m, STABILISERS[r.model])
        x0 = m.initial_state(inputs())
        assert x0.shape == (m.n_states,)


BAD = [
    ("PSS3B", IEEEST_WECC, "not a supported stabiliser"),
    ("IEEEST", IEEEST_WECC[:-1], "expected 19 constants"),
    ("IEEEST", IEEEST_WECC + (0,), "expected 19 constants"),
    ("ST2CUT", ST2CUT_WECC_5[:-2], "expected 20 constants"),
    ("IEEEST", (1.5,) + IEEEST_WECC[1:], "ICON MODE must be an integer"),
    ("IEEEST", (7,) + IEEEST_WECC[1:], "IEEEST: MODE must be an input code 1..6"),
    ("IEEEST", (0,) + IEEEST_WECC[1:], "IEEEST: MODE must be an input code 1..6"),
    ("ST2CUT", (1, 0, 9, 0) + ST2CUT_WECC_5[4:], "ST2CUT: MODE2 must be an input code 0..6"),
    ("IEEEST", (1, -5) + IEEEST_WECC[2:], "IEEEST: busr must be a bus number"),
    ("IEEEST", IEEEST_WECC[:13] + (0.0,) + IEEEST_WECC[14:], "T6 must be > 0"),
    ("IEEEST", IEEEST_WECC[:15] + (-0.1, 0.1, 0, 0), "LSMAX"),
    ("IEEEST", IEEEST_WECC[:9] + (-0.1,) + IEEEST_WECC[10:], "IEEEST: T2 must be >= 0"),
    ("IEEEST", IEEEST_WECC[:7] + (0.1,) + IEEEST_WECC[8:], "improper"),
    ("IEEEST", IEEEST_WECC[:17] + (0.9, 1.1), "VCU"),
    ("IEEEST", IEEEST_WECC[:5] + (float("nan"),) + IEEEST_WECC[6:], "not finite"),
    ("ST2CUT", ST2CUT_WECC_5[:8] + (0.0,) + ST2CUT_WECC_5[9:], "T3 must be > 0"),
    ("ST2CUT", ST2CUT_WECC_5[:9] + (0.0,) + ST2CUT_WECC_5[10:], "T4 must be > 0"),
]


@pytest.mark.parametrize("model,constants,message", BAD, ids=[b[2] for b in BAD])
def test_from_dyr_rejects_invalid_records(model, constants, message):
    with pytest.raises(ValueError, match=message) as e:
        stabiliser_from_dyr(model, constants)
    assert "\n" not in str(e.value)
