import jax
import jax.numpy as jnp
import numpy as np

from jaxdse._core.signals import angle_jumps, bridge, jumps


def test_angle_jumps_take_out_a_step_and_nothing_else():
    """A bus angle turning at a steady 0.3 rad/s (a frequency offset) with a curvature, that jumps
    by 0.2 rad between samples 50 and 51: the jump is found there and only there, its size to
    the curvature's second-order term, and the angle less it is continuous."""
    t = np.arange(200) / 50.0
    theta = 0.3 * t + 0.01 * t**2 + np.where(np.arange(200) > 50, 0.2, 0.0)
    switched = jumps(jnp.exp(1j * jnp.asarray(theta)), 4.0, 10.0)
    assert np.flatnonzero(np.asarray(switched)).tolist() == [50]
    out = np.asarray(angle_jumps(jnp.asarray(theta), switched))
    assert np.all(out[:51] == 0.0)
    np.testing.assert_allclose(out[51:], 0.2, atol=1e-12)
    smooth = np.diff(theta - out)
    assert np.max(np.abs(np.diff(smooth))) < 1e-4
    assert np.all(np.asarray(angle_jumps(jnp.asarray(theta), jnp.zeros(199, bool))) == 0.0)


def test_bridge_replaces_the_guarded_samples_only():
    """A frequency channel with a spike at a switching (interval 50-51): within 2 samples of it
    the values lie on the line between its neighbours; everywhere else they are the input's,
    bit for bit, and nothing changes without a switching (also at the ends, and under jit)."""
    x = np.sin(np.arange(120) / 10.0)
    x[50] += 100.0
    switched = np.zeros(119, bool)
    switched[50] = True
    out = np.asarray(jax.jit(bridge, static_argnums=2)(jnp.asarray(x), jnp.asarray(switched), 2))
    keep = np.r_[0:48, 54:120]
    assert np.array_equal(out[keep], x[keep])
    np.testing.assert_allclose(out[48:54], x[47] + (np.arange(48, 54) - 47) / 7 * (x[54] - x[47]), atol=1e-15)
    assert np.array_equal(np.asarray(bridge(jnp.asarray(x), jnp.zeros(119, bool), 2)), x)
    edge = np.zeros(119, bool)
    edge[0] = True
    at_start = np.asarray(bridge(jnp.asarray(x), jnp.asarray(edge), 2))
    assert np.all(at_start[:4] == x[4]) and np.array_equal(at_start[4:], x[4:])
