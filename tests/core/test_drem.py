"""Filters of the DREM estimator against their transfer functions; regression identity."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._core import drem
from jaxdse._core.drem import _filter3_rhs, _hd_rhs
from jaxdse._core.integrate import Trapezoid, integrate_sampled

TIGHT = jd.Integrator(rtol=1e-12, atol=1e-14, max_substeps=4096)


def _step(rhs, n_states, ts, cfg):
    return integrate_sampled(lambda t, x, u, a: rhs(x, u, cfg), jnp.zeros(n_states), ts,
                             jnp.ones_like(ts), None, TIGHT).ys


def test_third_order_filter_step_response():
    """y = F[1], y' = F[s 1], y'' = F[s^2 1] for F = l1 l2 l3/((s+l1)(s+l2)(s+l3))."""
    cfg = jd.ObserverConfig()
    ts = jnp.linspace(0.0, 3.0, 301)
    ys = _step(_filter3_rhs, 3, ts, cfg)
    lam = np.array([8.0, 6.2, 7.4])
    p0 = lam.prod()
    t = np.asarray(ts)[:, None]
    res = np.array([p0 / (-li * np.prod([lj - li for lj in lam if lj != li])) for li in lam])
    y = 1.0 + (res * np.exp(-lam * t)).sum(1)
    dy = (-lam * res * np.exp(-lam * t)).sum(1)
    ddy = (lam**2 * res * np.exp(-lam * t)).sum(1)
    np.testing.assert_allclose(ys[:, 0], y, atol=1e-6)
    np.testing.assert_allclose(ys[:, 1], dy, atol=1e-6 * np.abs(dy).max())
    np.testing.assert_allclose(ys[:, 2], ddy, atol=1e-6 * np.abs(ddy).max())


def test_derivative_branch_step_response():
    """c1 c2 s/((s+c1)(s+c2)) step response = c1 c2/(c2 - c1) (e^{-c1 t} - e^{-c2 t})."""
    cfg = jd.ObserverConfig()
    ts = jnp.linspace(0.0, 3.0, 301)
    ws = _step(_hd_rhs, 2, ts, cfg)
    c1, c2, t = 8.0, 6.0, np.asarray(ts)
    np.testing.assert_allclose(c1 * c2 * ws[:, 1], c1 * c2 / (c2 - c1) * (np.exp(-c1 * t) - np.exp(-c2 * t)),
                               atol=1e-6)


def test_derivative_branch_sine_response():
    """Steady-state sine response magnitude and phase equal |H(jw)|, arg H(jw)."""
    cfg = jd.ObserverConfig()
    w = 3.0
    ts = jnp.linspace(0.0, 12.0, 6001)
    u = jnp.sin(w * ts)
    ws = integrate_sampled(lambda t, x, ui, a: _hd_rhs(x, jnp.sin(w * t), cfg), jnp.zeros(2), ts, u,
                           None, TIGHT).ys
    out = 48.0 * ws[:, 1]
    h = 48.0 * 1j * w / ((1j * w + 8.0) * (1j * w + 6.0))
    expect = np.abs(h) * np.sin(w * np.asarray(ts) + np.angle(h))
    late = np.asarray(ts) > 8.0
    np.testing.assert_allclose(np.asarray(out)[late], expect[late], atol=1e-6)


@pytest.mark.slow
def test_noise_free_accuracy_with_true_tm(ambient, plant, estimate_jit):
    """Ambient excitation, true Tm, no noise: a2 within 1 %, x2 RMSE < 2 % of its std."""
    tr = ambient.truth
    est = estimate_jit(ambient.clean, plant, jd.ObserverConfig(), jd.Settings(external_tm=True),
                       tr.t_m_pu, tr.a2)
    assert abs(float(est.a2 - tr.a2)) / float(tr.a2) < 0.01
    assert bool(est.converged)
    after = np.asarray(est.time_s) >= float(est.convergence_time_s)
    err = np.asarray(est.trajectories.x2_hat_rad_s - tr.x2_rad_s)[after]
    assert np.sqrt(np.mean(err**2)) < 0.02 * np.std(np.asarray(tr.x2_rad_s))


@pytest.mark.slow
def test_regression_identity_holds_on_truth(ambient, plant):
    """Zc = Delta * theta along a noise-free trajectory once filter transients have decayed."""
    tr = ambient.truth
    cfg = jd.ObserverConfig(gamma1=1e-9, gamma2=1e-9)  # freeze theta; we only need the filters
    ts = ambient.clean.t_s
    inputs = drem.DremInputs(tr.delta_rad - tr.delta_rad[0], tr.t_e_pu,
                                 tr.x2_rad_s / plant.machine.omega_s, tr.t_m_pu)
    s0 = drem.initial_state(jax.tree_util.tree_map(lambda x: x[0], inputs), 0.0, 0.0, cfg,
                                plant.governor, True)
    rhs = drem._vector_field(True)
    ys = integrate_sampled(rhs, s0, ts, inputs, (cfg, plant.governor, 0.0), TIGHT).ys
    reg = drem.regression(ys, cfg)
    late = np.asarray(ts) > 20.0
    theta = np.array([float(tr.a1), float(tr.a2)])
    lhs = np.asarray(reg.zc)[late]
    rhs_ = np.asarray(reg.delta_det)[late, None] * theta
    # Inputs are sampled at 50 Hz and interpolated linearly: agreement to discretisation error.
    assert np.max(np.abs(lhs - rhs_)) < 1e-3 * np.max(np.abs(rhs_))


def test_trapezoid_equals_diffrax_heun():
    """The lean solver takes the same steps as diffrax.Heun: fixed and adaptive."""
    import diffrax

    term = diffrax.ODETerm(lambda t, y, a: {"x": -y["x"] * jnp.sin(t) + y["v"], "v": -4.0 * y["x"]})
    y0 = {"x": jnp.array(1.0), "v": jnp.array(0.3)}
    for ctrl in (diffrax.ConstantStepSize(), diffrax.PIDController(rtol=1e-5, atol=1e-7)):
        sols = [diffrax.diffeqsolve(term, s, 0.0, 5.0, 0.05, y0, stepsize_controller=ctrl)
                for s in (Trapezoid(), diffrax.Heun())]
        assert int(sols[0].stats["num_steps"]) == int(sols[1].stats["num_steps"])
        for k in y0:
            np.testing.assert_allclose(sols[0].ys[k], sols[1].ys[k], rtol=1e-12, atol=1e-14)


def test_adaptive_gain_is_the_log_space_softplus_clip():
    """K = exp(log eps + (softplus(8 (x - log eps)) - softplus(8 (x - log k_max))) / 8) with
    x = log(Delta_ref^2 / mean): the square-root form equals it, and is finite at mean = 0."""
    cfg = jd.ObserverConfig()
    mean = jnp.geomspace(1e-300, 1e10, 3000)
    x = jnp.log(cfg.delta_ref_sq / mean)
    lo, hi = jnp.log(cfg.eps), jnp.log(cfg.k_max)
    sp = jax.nn.softplus
    ref = jnp.exp(lo + (sp(8 * (x - lo)) - sp(8 * (x - hi))) / 8)
    np.testing.assert_allclose(drem.adaptive_gain(mean, cfg), ref, rtol=1e-12)
    assert float(drem.adaptive_gain(0.0, cfg)) == float(cfg.k_max)
    assert np.isfinite(float(jax.grad(drem.adaptive_gain)(0.0, cfg)))
