import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._core.algebraic import algebraic_observer
from jaxdse._core.mapping import map_to_terminal


def _check(est, truth, tol=1e-9):
    delta = est.delta_rad + truth.delta_rad[0]
    assert float(jnp.max(jnp.abs(delta - truth.delta_rad))) < tol
    assert float(jnp.max(jnp.abs(est.e_q1_pu - truth.e_q1_pu))) < tol
    assert float(jnp.max(jnp.abs(est.t_e_pu - truth.t_e_pu))) < tol


@pytest.mark.parametrize("location", ["substation", "terminal"])
def test_recovers_simulator_states(ambient, plant, location):
    """Noise-free data: delta, E'q and Te to 1e-9 with Rs > 0 and xq != x'd."""
    assert float(plant.machine.rs_pu) > 0 and float(plant.machine.xq_pu) != float(plant.machine.xd1_pu)
    tr = ambient.truth
    if location == "substation":
        rec = ambient.clean
    else:
        v, i = tr.v_t, tr.i_sg
        theta = jnp.unwrap(jnp.angle(v))
        rec = jd.Recording(t_s=ambient.clean.t_s, v_mag_pu=jnp.abs(v), v_ang_rad=theta,
                           i_mag_pu=jnp.abs(i), i_ang_rad=jnp.unwrap(jnp.angle(i)),
                           f_hz=ambient.clean.f_hz, location="terminal")
    scale = plant.s_base_mva / plant.machine.s_rated_mva
    mapped = map_to_terminal(rec.v * jnp.exp(-1j * rec.v_ang_rad),
                                rec.i * jnp.exp(-1j * rec.v_ang_rad), plant.line,
                                plant.transformer, plant.aux, rec.location)
    alg = algebraic_observer(mapped.v_t, mapped.i_sg * scale, rec.v_ang_rad, plant.machine)
    alg = alg.__class__(delta_rad=alg.delta_rad - tr.delta_rad[0], e_q1_pu=alg.e_q1_pu,
                        i_d_pu=alg.i_d_pu, i_q_pu=alg.i_q_pu, t_e_pu=alg.t_e_pu)
    _check(alg, tr)


def test_paper_lemma1_formula(rng):
    """x3 = |psi| - (xq - x'd) cos(pi/2 - x1 + y4) y3 (paper Eq. 15) equals our E'q."""
    m = jd.Machine(rs_pu=0.02)
    v = jnp.asarray(np.exp(1j * rng.uniform(-1, 1, 20)))
    i = jnp.asarray(0.9 * np.exp(1j * rng.uniform(-1.5, 0, 20)))
    alg = algebraic_observer(v, i, jnp.zeros(20), m)
    psi = (m.rs_pu + 1j * m.xq_pu) * i + v
    x3 = jnp.abs(psi) - (m.xq_pu - m.xd1_pu) * jnp.cos(jnp.pi / 2 - alg.delta_rad + jnp.angle(i)) * jnp.abs(i)
    np.testing.assert_allclose(alg.e_q1_pu, x3, atol=1e-13)


def test_offline_generator_gives_finite_states():
    m = jd.Machine()
    alg = jax.jit(algebraic_observer)(jnp.ones(10) + 0j, jnp.zeros(10) + 0j, jnp.zeros(10), m)
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(alg))
    np.testing.assert_allclose(alg.t_e_pu, 0.0, atol=1e-15)
