import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._core.mapping import (
    line_to_grid,
    line_to_plant,
    map_to_measurement,
    map_to_terminal,
    transformer_to_hv,
    transformer_to_lv,
)


def _random_phasors(rng, n=200):
    v = (1 + 0.05 * rng.standard_normal(n)) * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    i = (8 + rng.standard_normal(n)) * np.exp(1j * rng.uniform(-np.pi, np.pi, n))
    return jnp.asarray(v), jnp.asarray(i)


def _rel(a, b):
    return float(jnp.max(jnp.abs(a - b)) / jnp.max(jnp.abs(b)))


def test_line_matches_paper_eq8(rng):
    line = jd.Line(r_pu=0.002, x_pu=0.02, b_pu=0.3)
    v5, i5 = _random_phasors(rng)
    v4, i4 = line_to_plant(v5, i5, line)
    z, y, i_pmu = line.z, line.y, -i5  # the paper's I_PMU flows towards the plant
    assert _rel(v4, (1 + z * y / 2) * v5 - z * i_pmu) < 1e-12
    # The paper's I_HV flows from the transformer into the line: our generator convention.
    assert _rel(i4, (y + z * y**2 / 4) * v5 - (1 + z * y / 2) * i_pmu) < 1e-12


def test_transformer_matches_paper_eq9(rng):
    tr = jd.Transformer(tap_position=3.0, phase_shift_rad=0.1, r_fe_pu=300.0, x_m_pu=80.0)
    v_hv, i_hv = _random_phasors(rng)
    v_lv, i_lv = transformer_to_lv(v_hv, i_hv, tr)
    tau, phi = 3.0 * tr.tap_step, 0.1
    zm_inv = (tr.r_fe_pu + 1j * tr.x_m_pu) / (1j * tr.r_fe_pu * tr.x_m_pu)
    z_hv, z_lv = tr.r_hv_pu + 1j * tr.x_hv_pu, tr.r_lv_pu + 1j * tr.x_lv_pu
    # Paper Eq. 9 as printed: e^{-j phi} multiplies both the voltage and the current terms.
    i_in = i_hv * (1 + tau) * np.exp(-1j * phi)
    v_in = v_hv / (1 + tau) * np.exp(-1j * phi)
    i_ref = i_in + (v_in + i_in * z_hv) * zm_inv
    assert _rel(i_lv, i_ref) < 1e-12
    assert _rel(v_lv, i_lv * z_lv + v_in + i_in * z_hv) < 1e-12


def test_two_port_inverses(rng):
    line, tr = jd.Line(b_pu=0.2), jd.Transformer(tap_position=-4.0, phase_shift_rad=0.3)
    v, i = _random_phasors(rng)
    assert _rel(line_to_grid(*line_to_plant(v, i, line), line)[1], i) < 1e-12
    back = transformer_to_hv(*transformer_to_lv(v, i, tr), tr)
    assert _rel(back[0], v) < 1e-12 and _rel(back[1], i) < 1e-12


@pytest.mark.parametrize("location", ["substation", "hv", "terminal"])
def test_full_map_round_trip(rng, location):
    line, tr, aux = jd.Line(b_pu=0.2), jd.Transformer(tap_position=2.0, phase_shift_rad=0.05), \
        jd.AuxiliarySystem(p_as_max_mw=80.0)
    n = 300
    v_t = (1 + 0.02 * rng.standard_normal(n)) * np.exp(1j * 0.1 * rng.standard_normal(n))
    i_sg = (8 + 0.5 * rng.standard_normal(n)) * np.exp(1j * (-0.2 + 0.1 * rng.standard_normal(n)))
    v, i = map_to_measurement(jnp.asarray(v_t), jnp.asarray(i_sg), line, tr, aux, location)
    mapped = map_to_terminal(v, i, line, tr, aux, location)
    assert _rel(mapped.v_t, v_t) < 1e-9
    assert _rel(mapped.i_sg, i_sg) < 1e-9


def test_aux_power_follows_running_mean(rng):
    aux = jd.AuxiliarySystem(p_as_max_mw=50.0, p_sg_max_mw=1000.0, power_factor=0.8)
    tr, line = jd.Transformer(), jd.Line()
    v_t = jnp.ones(50) + 0j
    i_sg = jnp.full(50, 9.0 + 0j)
    v, i = map_to_measurement(v_t, i_sg, line, tr, aux, "hv")
    mapped = map_to_terminal(v, i, line, tr, aux, "hv")
    s_as = v_t * jnp.conj(mapped.i_sg - mapped.i_lv)
    p_lv = jnp.real(v_t * jnp.conj(mapped.i_lv))
    # Constant generation: P_AS = kappa * P_LV, Q_AS = P_AS tan(arccos 0.8), drawn by the load.
    kappa = 50.0 / 950.0
    np.testing.assert_allclose(jnp.real(s_as), kappa * p_lv, rtol=1e-12)
    np.testing.assert_allclose(jnp.imag(s_as), kappa * p_lv * 0.75, rtol=1e-12)


def test_invalid_parameters_rejected():
    with pytest.raises(ValueError, match="tap out of range"):
        jd.Transformer(tap_position=100.0)
    with pytest.raises(ValueError, match="x_pu"):
        jd.Line(x_pu=-0.1)
    with pytest.raises(ValueError, match="power_factor"):
        jd.AuxiliarySystem(power_factor=1.5)
