import jax.numpy as jnp
import numpy as np

from jaxdse._metrics import convergence_index, rmse, smape_percent


def test_smape_matches_paper_definition():
    z = np.array([1.0, 2.0, -1.0, 0.0])
    zh = np.array([1.1, 1.8, -1.0, 0.0])
    expect = 100 / 4 * (0.1 / 1.05 + 0.2 / 1.9 + 0 + 0)
    np.testing.assert_allclose(smape_percent(jnp.asarray(zh), jnp.asarray(z)), expect)
    np.testing.assert_allclose(
        smape_percent(jnp.asarray(zh), jnp.asarray(z), jnp.array([True, False, False, False])),
        100 * 0.1 / 1.05)


def test_rmse_and_convergence_index():
    np.testing.assert_allclose(rmse(jnp.array([1.0, 3.0]), jnp.array([0.0, 0.0])), np.sqrt(5.0))
    traj = jnp.array([2.0, 1.5, 1.01, 0.9, 1.005, 0.999])
    assert int(convergence_index(traj, 1.0, 0.02)) == 4
    assert int(convergence_index(jnp.array([1.0, 2.0]), 1.0, 0.02)) == 2
