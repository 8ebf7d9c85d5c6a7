import jax.numpy as jnp
import numpy as np

from jaxdse._core.metrics import rmse, settled_from, smape_percent


def test_smape_matches_paper_definition():
    z = np.array([1.0, 2.0, -1.0, 0.0])
    zh = np.array([1.1, 1.8, -1.0, 0.0])
    expect = 100 / 4 * (0.1 / 1.05 + 0.2 / 1.9 + 0 + 0)
    np.testing.assert_allclose(smape_percent(jnp.asarray(zh), jnp.asarray(z)), expect)
    np.testing.assert_allclose(
        smape_percent(jnp.asarray(zh), jnp.asarray(z), jnp.array([True, False, False, False])),
        100 * 0.1 / 1.05)


def test_rmse_and_settling_index():
    np.testing.assert_allclose(rmse(jnp.array([1.0, 3.0]), jnp.array([0.0, 0.0])), np.sqrt(5.0))
    traj = jnp.array([2.0, 1.5, 1.01, 0.9, 1.005, 0.999])
    assert int(settled_from(traj, traj, 1.0, 0.02)) == 4  # one sample per segment
    assert int(settled_from(jnp.array([1.0, 2.0]), jnp.array([1.0, 2.0]), 1.0, 0.02)) == 2
    # blocks of two samples: [min, max] per block; a block that straddles the band is outside
    lo, hi = jnp.array([1.5, 0.9, 0.999]), jnp.array([2.0, 1.01, 1.005])
    assert int(settled_from(lo, hi, 1.0, 0.02)) == 2
    # padding segments (lo = inf, hi = -inf) never count as outside
    assert int(settled_from(jnp.array([1.0, jnp.inf]), jnp.array([1.0, -jnp.inf]), 1.0, 0.02)) == 0
