"""The exact LTI filters (``_core/lti.py``) and the LAPACK-free linear algebra of ``identify``."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from jaxdse._core.identify import masked_median, solve_spd
from jaxdse._core.lti import (
    butterworth2,
    expm,
    filter_states,
    hold_discretisation,
    lag_chain,
    solve_2x2,
    zero_phase_lowpass,
)


@pytest.mark.parametrize("scale", [0.0, 1e-3, 1.0, 30.0, 2e3])
def test_expm_matches_scipy(scale, rng):
    m = rng.normal(size=(5, 5)) * scale
    want = scipy.linalg.expm(m - 3.0 * scale * np.eye(5))  # a decaying (filter-like) matrix
    got = np.asarray(expm(jnp.asarray(m - 3.0 * scale * np.eye(5))))
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-13 * np.max(np.abs(want)))


def test_hold_discretisation_is_exact_for_a_ramp():
    """dx/dt = -p x + p u with u = t from x(0) = 0: x(t) = t - (1 - e^{-pt})/p."""
    p, dt = 3.0, 0.1
    phi, g0, g1 = hold_discretisation(jnp.array([[-p]]), jnp.array([p]), dt)
    x = phi[0, 0] * 0.0 + g0[0] * 0.0 + g1[0] * dt
    np.testing.assert_allclose(x, dt - (1.0 - np.exp(-p * dt)) / p, rtol=1e-13)


def test_filter_states_match_scipy_lsim_and_start_at_rest(rng):
    """The 3rd-order lag chain of identify against scipy's first-order-hold simulation, from
    the rest state at the first sample (DC gain 1: [u0, 0, 0])."""
    poles = jnp.array([4.0, 7.0, 11.0])
    a, b = lag_chain(poles)
    dt, n = 0.02, 400
    t = np.arange(n) * dt
    u = 0.7 + np.sin(2.0 * t) + 0.1 * rng.normal(size=n)
    got = np.asarray(filter_states(hold_discretisation(a, b, dt), jnp.asarray(u)))
    x0 = np.array([u[0], 0.0, 0.0])
    np.testing.assert_allclose(np.asarray(a) @ x0 + np.asarray(b) * u[0], 0.0, atol=1e-12)  # at rest
    _, y, xs = scipy.signal.lsim((np.asarray(a), np.asarray(b)[:, None], np.eye(3), np.zeros((3, 1))),
                                 u, t, X0=x0, interp=True)
    np.testing.assert_allclose(got, xs, rtol=1e-8, atol=1e-10)
    # reverse runs the same filter backwards in time
    back = np.asarray(filter_states(hold_discretisation(a, b, dt), jnp.asarray(u), reverse=True))
    ref = np.asarray(filter_states(hold_discretisation(a, b, dt), jnp.asarray(u[::-1])))[::-1]
    np.testing.assert_allclose(back, ref, rtol=1e-14)


def test_zero_phase_lowpass_passes_slow_and_stops_fast_signals():
    dt = 0.02
    t = np.arange(3000) * dt
    slow, fast = np.sin(2 * np.pi * 0.2 * t), np.sin(2 * np.pi * 15.0 * t)
    y = np.asarray(zero_phase_lowpass(jnp.asarray(slow + fast), dt, 2.0))
    mid = slice(500, 2500)
    np.testing.assert_allclose(y[mid], slow[mid], atol=2e-3)  # unit gain, no phase lag
    a, b = butterworth2(2.0)
    np.testing.assert_allclose(-np.asarray(a)[1, 0], np.asarray(b)[1])  # DC gain 1


def test_solve_spd_and_2x2(rng):
    x = rng.normal(size=(200, 4)) * np.array([1.0, 1e3, 1e-2, 10.0])
    a = x.T @ x
    b = rng.normal(size=4)
    np.testing.assert_allclose(solve_spd(jnp.asarray(a), jnp.asarray(b)), np.linalg.solve(a, b), rtol=1e-8)
    inv = np.asarray(solve_spd(jnp.asarray(a), jnp.eye(4)))
    np.testing.assert_allclose(inv @ a, np.eye(4), atol=1e-8)
    # singular: finite, huge along the null direction, never NaN
    sing = np.asarray(solve_spd(jnp.asarray(np.outer(b, b)), jnp.eye(4)))
    assert np.all(np.isfinite(sing)) and np.max(np.abs(sing)) > 1e10
    m = rng.normal(size=(2, 2))
    v = rng.normal(size=2)
    np.testing.assert_allclose(solve_2x2(jnp.asarray(m), jnp.asarray(v)), np.linalg.solve(m, v), rtol=1e-12)


def test_masked_median_is_exact(rng):
    for n in (1, 2, 3, 10, 1001, 3000):
        x = rng.normal(size=n) * rng.choice([1e-6, 1.0, 1e6])
        mask = rng.random(n) < 0.7
        mask[0] = True
        assert float(masked_median(jnp.asarray(x), jnp.asarray(mask))) == np.median(x[mask])
    assert np.isnan(float(masked_median(jnp.ones(5), jnp.zeros(5, dtype=bool))))
    assert float(masked_median(jnp.array([1.0, 2.0, 2.0, 2.0, 5.0]), jnp.ones(5, dtype=bool))) == 2.0


@pytest.mark.slow
def test_no_lapack_call_in_the_identification_graph(short, plant):
    """The per-unit identification holds no LAPACK custom call (they batch badly under vmap and
    once deadlocked XLA's CPU runtime)."""
    import jaxdse as jd

    text = jax.jit(jax.vmap(lambda r: jd.identify(r, plant).h_ci95)).lower(
        jax.tree_util.tree_map(lambda x: np.stack([x, x]), short)).as_text()
    for call in ("lapack", "getrf", "gesdd", "syevd", "potrf", "geqrf"):
        assert call not in text.lower(), call
