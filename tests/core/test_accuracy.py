"""Accuracy with default PMU noise and governor Tm, default configuration (demo recordings)."""

import jax
import numpy as np
import pytest

import jaxdse as jd


@pytest.mark.parametrize("name,limit", [("auto", 0.03), ("cross", 0.05)])
def test_a2_error_with_noise(plant, name, limit):
    sim = jd.simulate(plant, jd.demo_scenarios()[name])
    est = jax.jit(jd.estimate)(sim.recording, plant, jd.ObserverConfig(), jd.Settings(), None,
                               sim.truth.a2)
    err = abs(float(est.a2 - sim.truth.a2)) / float(sim.truth.a2)
    assert err < limit, err
    assert bool(est.converged) and np.isfinite(float(est.convergence_time_s))
