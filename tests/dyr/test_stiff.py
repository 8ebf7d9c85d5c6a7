"""The LAPACK-free LU of the implicit solver (``jaxdse._dyr.stiff``) against NumPy's solve."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxdse._dyr.stiff import _factor, _solve


@pytest.mark.parametrize("n", [1, 2, 13])
def test_lu_solves_like_numpy_with_pivoting(n):
    rng = np.random.default_rng(n)
    a = rng.normal(size=(4, n, n))
    if n > 1:
        a[:, 0, 0] = 0.0          # a zero leading pivot: needs the row exchange
    b = rng.normal(size=(4, n))
    x = jax.jit(jax.vmap(lambda a, b: _solve(*_factor(a), b)))(jnp.asarray(a), jnp.asarray(b))
    np.testing.assert_allclose(np.asarray(x), np.linalg.solve(a, b[..., None])[..., 0], rtol=1e-10, atol=1e-12)
