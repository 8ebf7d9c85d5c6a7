"""The adaptive sampled integration at a switching surface (``Integrator.min_substep``)."""

import jax.numpy as jnp
import numpy as np

from jaxdse._core.integrate import Integrator, integrate_sampled


def _sliding(integ):
    """dy/dt = -sign(y): y reaches 0 at t = 0.01 s and then slides along it, as a governor valve
    at its non-windup limit does under a noisy speed (every trial step across 0 is in error)."""
    ts = jnp.arange(50) * 0.02
    return integrate_sampled(lambda t, y, u, a: -jnp.sign(y), jnp.array([0.01]), ts,
                             jnp.zeros(50), None, integ)


def test_a_sliding_limit_is_stepped_through_at_the_shortest_step():
    capped = dict(rtol=1e-6, atol=1e-9, max_substeps=24)
    stuck = _sliding(Integrator(**capped))
    assert not bool(stuck.ok)                      # without a shortest step: the cap is reached
    out = _sliding(Integrator(**capped, min_substep=1 / 16))
    assert bool(out.ok)
    y = np.asarray(out.ys[:, 0])
    np.testing.assert_allclose(y[0], 0.01)
    assert np.all(np.abs(y[1:]) <= 0.02 / 16 + 1e-12)   # within one shortest step of the surface
    assert int(out.num_steps) <= 49 * 24


def test_the_playback_default_takes_a_shortest_step_and_the_observer_none():
    from jaxdse import Settings
    assert Settings().playback_integrator.min_substep == 1 / 16
    assert Settings().observer_integrator.min_substep == 0.0
