"""The orchestrating ``estimate``: robustness, invariances and JAX transforms."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd


def _finite(est):
    return all(bool(jnp.all(jnp.isfinite(x))) for x in
               (est.a1_hat, est.a2_hat, est.trajectories.x2_hat_rad_s,
                est.trajectories.playback.x2_rad_s, est.trajectories.t_m_pu, est.trajectories.e_f_pu))


@pytest.mark.slow
@pytest.mark.parametrize("event", [jd.Event(30.0, "load_step", 0.2), jd.Event(30.0, "line_trip", 3.0)])
def test_stiff_events_stay_stable(plant, estimate_jit, event):
    """A 20 % load step or a line trip with gamma = 850: no NaN/inf, no divergence."""
    sim = jd.simulate(plant, jd.Scenario(duration_s=60.0, seed=5, events=(event,)))
    est = estimate_jit(sim.recording, plant, jd.ObserverConfig(gamma1=850.0, gamma2=850.0),
                       jd.Settings(), None, sim.truth.a2)
    assert _finite(est) and bool(est.solver_ok)
    a2 = np.asarray(est.a2_hat)
    assert np.all(a2 > 0) and np.all(a2 < 3 * float(sim.truth.a2))
    assert abs(float(est.a2 - sim.truth.a2)) / float(sim.truth.a2) < 0.1


@pytest.mark.slow
def test_no_excitation_is_flagged(plant, estimate_jit):
    sc = jd.Scenario(duration_s=60.0, ambient_load_std=0.0, ambient_freq_std_hz=0.0,
                     ambient_volt_std=0.0, tve_percent=0.0, freq_noise_hz=0.0)
    sim = jd.simulate(plant, sc)
    # with a2 known, as the stiff-event runs above (one compiled shape for both)
    est = estimate_jit(sim.recording, plant, jd.ObserverConfig(), jd.Settings(), None, sim.truth.a2)
    assert _finite(est)
    assert not bool(est.excited) and not bool(est.converged)
    assert np.isnan(float(est.convergence_time_s))
    np.testing.assert_allclose(est.a2, jd.ObserverConfig().a2_init)  # untouched, not garbage


@pytest.mark.slow
def test_offline_generator_is_flagged(ambient, plant, estimate_jit):
    rec = ambient.recording
    rec = jd.Recording(t_s=rec.t_s, v_mag_pu=rec.v_mag_pu, v_ang_rad=rec.v_ang_rad,
                       i_mag_pu=jnp.zeros_like(rec.i_mag_pu), i_ang_rad=jnp.zeros_like(rec.t_s),
                       f_hz=rec.f_hz, location=rec.location)   # test_angle_offset_invariance's program
    est = estimate_jit(rec, plant, jd.ObserverConfig())
    assert _finite(est) and not bool(est.online) and not bool(est.converged)


@pytest.mark.slow
def test_angle_offset_invariance(ambient, plant, estimate_jit):
    """+1e4 rad on every measured angle changes the estimates by < 1e-6 relative."""
    rec = ambient.recording
    shifted = jd.Recording(t_s=rec.t_s, v_mag_pu=rec.v_mag_pu, v_ang_rad=rec.v_ang_rad + 1e4,
                           i_mag_pu=rec.i_mag_pu, i_ang_rad=rec.i_ang_rad + 1e4, f_hz=rec.f_hz)
    a = estimate_jit(rec, plant, jd.ObserverConfig())
    b = estimate_jit(shifted, plant, jd.ObserverConfig())
    for x, y in ((a.a1, b.a1), (a.a2, b.a2)):
        assert abs(float(x - y)) <= 1e-6 * abs(float(x))
    xa, xb = a.trajectories.x2_hat_rad_s, b.trajectories.x2_hat_rad_s
    scale = float(jnp.max(jnp.abs(xa)))
    assert float(jnp.max(jnp.abs(xa - xb))) <= 1e-6 * scale


@pytest.mark.slow
def test_frequency_from_voltage_angle(ambient, plant, estimate_jit):
    """Without a frequency channel, x2 is derived from the voltage angle and still estimates a2."""
    rec = ambient.clean
    nof = jd.Recording(t_s=rec.t_s, v_mag_pu=rec.v_mag_pu, v_ang_rad=rec.v_ang_rad,
                       i_mag_pu=rec.i_mag_pu, i_ang_rad=rec.i_ang_rad, f_hz=None)
    est = estimate_jit(nof, plant, jd.ObserverConfig())
    err = np.asarray(est.trajectories.x2_meas_rad_s - ambient.truth.x2_rad_s)[10:-10]
    assert np.sqrt(np.mean(err**2)) < 0.05 * np.std(np.asarray(ambient.truth.x2_rad_s))
    assert abs(float(est.a2 - ambient.truth.a2)) / float(ambient.truth.a2) < 0.03


FAST = jd.Settings.fast()


@pytest.mark.slow
def test_vmap_over_configurations(short, plant, estimate_jit):
    gammas = jnp.linspace(200.0, 1600.0, 8)
    cfgs = jax.vmap(lambda g: jd.ObserverConfig(gamma1=g, gamma2=g))(gammas)
    out = jax.jit(jax.vmap(jd.estimate, in_axes=(None, None, 0, None)))(short, plant, cfgs, FAST)
    assert out.a2.shape == (8,)
    single = estimate_jit(short, plant, jd.ObserverConfig(gamma1=gammas[3], gamma2=gammas[3]), FAST)
    np.testing.assert_allclose(out.a2[3], single.a2, rtol=1e-10)
    assert len(np.unique(np.round(np.asarray(out.a2), 8))) == 8  # the gammas made a difference


@pytest.mark.slow
def test_vmap_over_generators(short, plant, estimate_jit):
    """Plants that differ in what the estimator reads (xq: the rotor angle; the governor droop:
    Tm): each member equals its own single run, and the members differ."""
    plants = [jd.Plant(machine=jd.Machine(xq_pu=xq), governor=jd.TGOV1(r_pu=r))
              for xq, r in ((1.5, 0.04), (1.7, 0.05), (1.9, 0.06))]
    recs = jax.tree_util.tree_map(lambda x: jnp.stack([x] * 3), short)
    out = jax.jit(jax.vmap(jd.estimate, in_axes=(0, 0, None, None)))(recs, jd.stack(plants),
                                                                     jd.ObserverConfig(), FAST)
    assert out.a2.shape == (3,) and bool(jnp.all(jnp.isfinite(out.a2)))
    for k, p in enumerate(plants):
        single = estimate_jit(short, p, jd.ObserverConfig(), FAST)
        np.testing.assert_allclose(out.a2[k], single.a2, rtol=1e-10)
        np.testing.assert_allclose(out.t_ref_pu[k], single.t_ref_pu, rtol=1e-12)
    assert abs(float(out.a2[0] - out.a2[2])) > 1e-3 * abs(float(out.a2[1]))


@pytest.mark.slow
def test_gradients_match_finite_differences(short, plant):
    """d loss / d(gamma, lambda, c, K, xq, R) vs central differences on 20 s, float64. The
    plant parameters are ones the estimator reads (xq: rotor angle; R: the governor's Tm)."""
    # Fixed steps: the discrete map is then smooth in the parameters, so that central
    # differences are meaningful (adaptive step acceptance makes the loss jump by ~rtol).
    tight = FAST

    def loss(params):
        cfg = jd.ObserverConfig(gamma1=params["gamma"], gamma2=params["gamma"],
                                lambda1=params["lambda1"], c1=params["c1"], k_ext=params["k"])
        p = jd.Plant(machine=jd.Machine(xq_pu=params["xq"]), line=plant.line,
                     transformer=plant.transformer, aux=plant.aux, governor=jd.TGOV1(r_pu=params["r"]))
        est = jd.estimate(short, p, cfg, tight)
        tr = est.trajectories
        return est.a2 + jnp.mean((tr.x2_hat_rad_s - tr.x2_meas_rad_s) ** 2) * 1e3 + \
            jnp.mean(tr.playback.p_t_pu)

    params = {"gamma": 850.0, "lambda1": 8.0, "c1": 8.0, "k": 6.5, "xq": 1.7, "r": 0.05}
    params = {k: jnp.asarray(v) for k, v in params.items()}
    grads = jax.jit(jax.grad(loss))(params)
    f = jax.jit(loss)
    for name, g in grads.items():
        h = 1e-4 * float(params[name])
        up = dict(params, **{name: params[name] + h})
        dn = dict(params, **{name: params[name] - h})
        fd = (float(f(up)) - float(f(dn))) / (2 * h)
        assert abs(fd) > 1e-6, (name, fd)  # the parameter matters: the check can fail
        assert abs(float(g) - fd) <= 1e-4 * abs(fd), (name, float(g), fd)


def test_fixed_steps_are_stable_at_any_adaptation_gain(ambient, plant, estimate_jit):
    """gamma far past an explicit step's stability limit (gamma K Delta^2 dt >> 2): the
    exponential trapezoid takes the parameter states' decay exactly, so the fixed-step path
    stays finite and reports success; a2 lands near the truth (within 15 %: the gain is absurd,
    the estimate noisy)."""
    st = jd.Settings.fast(keep="final", playback=False)
    est = estimate_jit(ambient.recording, plant, jd.ObserverConfig(gamma1=1e9, gamma2=1e9), st)
    assert bool(est.solver_ok)
    assert abs(float(est.a2) / float(ambient.truth.a2) - 1) < 0.15, float(est.a2)


def test_unstable_fixed_steps_hold_last_finite_state_and_report_failure(ambient, plant, estimate_jit):
    """An I&I gain far past the explicit step's stability limit: no NaN comes out, solver_ok says so."""
    st = jd.Settings.fast(keep="final", playback=False)
    est = estimate_jit(ambient.recording, plant, jd.ObserverConfig(k_obs=1e9), st)
    assert not bool(est.solver_ok) and not bool(est.converged)
    assert np.all(np.isfinite([float(est.a1), float(est.a2)]))


def test_smape_of_nan_is_nan_not_zero():
    assert np.isnan(float(jd.smape_percent(jnp.array([np.nan, 1.0]), jnp.array([1.0, 1.0]))))
    assert float(jd.smape_percent(jnp.zeros(3), jnp.zeros(3))) == 0.0


def test_float32_use_fails_fast_with_a_clear_message(short, plant):
    jax.config.update("jax_enable_x64", False)
    try:
        with pytest.raises(RuntimeError, match="jax_enable_x64"):
            jd.estimate(short, plant, jd.ObserverConfig())
    finally:
        jax.config.update("jax_enable_x64", True)
