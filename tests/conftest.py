import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxdse as jd  # noqa: E402


@pytest.fixture(scope="session")
def plant():
    return jd.Plant()


@pytest.fixture(scope="session")
def ambient(plant):
    """120 s of ambient excitation at 90 % of rating: noisy recording, clean twin and truth."""
    return jd.simulate(plant, jd.Scenario(duration_s=120.0, seed=3))


@pytest.fixture(scope="session")
def estimate_jit():
    return jax.jit(jd.estimate)


@pytest.fixture(scope="session")
def rng():
    return np.random.default_rng(1234)
