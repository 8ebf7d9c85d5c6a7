import jax.numpy as jnp
import numpy as np

import jaxdse as jd
from jaxdse._core.sequence import phases_from_sequences, positive_sequence, sequence_components


def test_fortescue_round_trip(rng):
    x = rng.standard_normal((100, 3)) + 1j * rng.standard_normal((100, 3))
    x0, x1, x2 = sequence_components(jnp.asarray(x))
    np.testing.assert_allclose(phases_from_sequences(x0, x1, x2), x, atol=1e-13)
    np.testing.assert_allclose(positive_sequence(jnp.asarray(x)), x1, atol=1e-13)


def test_balanced_set_is_pure_positive_sequence():
    a = np.exp(2j * np.pi / 3)
    v1 = 1.02 * np.exp(0.3j)
    abc = jnp.asarray([[v1, v1 * a**2, v1 * a]])
    x0, x1, x2 = sequence_components(abc)
    assert abs(complex(x1[0]) - v1) < 1e-14 and abs(complex(x0[0])) < 1e-14
    assert abs(complex(x2[0])) < 1e-14


def test_three_phase_recording_keeps_positive_sequence(ambient):
    rec = jd.recording_from_three_phase(ambient.recording.t_s, ambient.v_abc, ambient.i_abc,
                                        ambient.recording.f_hz)
    np.testing.assert_allclose(rec.v_mag_pu, ambient.recording.v_mag_pu, rtol=1e-12)
    np.testing.assert_allclose(rec.i_ang_rad, ambient.recording.i_ang_rad, atol=1e-12)
