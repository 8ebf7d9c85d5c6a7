import jax.numpy as jnp
import numpy as np

import jaxdse as jd
from jaxdse._core.machine import electrical_torque, stator_currents, terminal_power


def test_stator_equations_and_torque(rng):
    """Id, Iq solve Vd = xq Iq - Rs Id, Vq = E'q - Rs Iq - x'd Id; Te = P + Rs I^2."""
    m = jd.Machine(rs_pu=0.01, xq_pu=1.6, xd1_pu=0.25)
    e_q1, v_d, v_q = 1.1 + 0.1 * rng.random(50), 0.6 * rng.random(50), 0.8 + 0.1 * rng.random(50)
    i_d, i_q = stator_currents(e_q1, v_d, v_q, m)
    np.testing.assert_allclose(v_d, m.xq_pu * i_q - m.rs_pu * i_d, atol=1e-14)
    np.testing.assert_allclose(v_q, e_q1 - m.rs_pu * i_q - m.xd1_pu * i_d, atol=1e-14)
    p, _ = terminal_power(v_d, v_q, i_d, i_q)
    te = electrical_torque(e_q1, i_d, i_q, m)
    np.testing.assert_allclose(te, p + m.rs_pu * (i_d**2 + i_q**2), rtol=1e-13)
    # The paper's printed E'q Id differs: the typo is real.
    assert np.max(np.abs(te - (e_q1 * i_d + (m.xq_pu - m.xd1_pu) * i_d * i_q))) > 1e-2


def test_a1_a2_definitions():
    m = jd.Machine(h_s=5.0, d_pu_s=0.02, f_nominal_hz=60.0)
    ws = 2 * jnp.pi * 60.0
    np.testing.assert_allclose(m.a2, ws / 10.0)
    np.testing.assert_allclose(m.a1, ws * 0.02 / 10.0)
