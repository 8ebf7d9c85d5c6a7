"""The one runner (``jd.assess_units``): grouping, padding, cutting and shifting. The guard
against a deadlock of ``jit(vmap(assess))`` over 16 different plants is
``tests/app/test_compiles.py``'s.

Shapes shared with the rest of the suite (conftest): the units alone are ``assess_jit`` on
``cut25``'s 1251 samples; the runner's batches are `jaxdse run`'s (1536 samples, one unit; 1280
samples, two units, as its split-recording test).
"""

import os

import numpy as np
import pytest
from builders import TEST_BOOTSTRAP_DRAWS

import jaxdse as jd


@pytest.mark.slow
def test_runner_groups_pads_cuts_and_shifts(pmu25, cut25, plant, assess_jit):
    """Units of two lengths and two plants: each result is cut to its own length, shifted to
    its own start, and equals the unit assessed alone (padding is masked)."""
    full, cut = pmu25.recording, cut25
    other = jd.Plant(governor=jd.TGOV1(r_pu=0.06))
    ids = jd.IdentifySettings(bootstrap_draws=TEST_BOOTSTRAP_DRAWS)
    units = [jd.Unit("a", full, plant), jd.Unit("b", cut, other, t0_s=100.0), jd.Unit("c", cut, plant)]
    seen = []
    out = jd.assess_units(units, jd.ObserverConfig(), jd.Settings(), ids, progress=seen.append)
    assert len(out) == 3 and seen
    assert out[0].estimate.time_s.shape == (1501,) and out[1].estimate.time_s.shape == (1251,)
    assert out[1].replay.playback.p_t_pu.shape == (1251,)
    np.testing.assert_allclose(out[1].estimate.time_s[0], 100.0 + float(cut.t_s[0]))
    alone = assess_jit(cut, other)
    np.testing.assert_allclose(out[1].identified.h_s, alone.identified.h_s, rtol=1e-7)
    np.testing.assert_allclose(out[1].identified.h_ci95, alone.identified.h_ci95, rtol=1e-6)
    assert int(out[1].verdict.code) == int(alone.verdict.code)
    assert out[1].identified.h_s != out[2].identified.h_s  # its own plant, not its neighbour's


def test_compiler_options_follow_the_optimisation_setting():
    """On CPU the pipeline compiles with ``COMPILER_OPTIONS`` (benchmarks/compile_options.py),
    except under ``jax_disable_most_optimizations`` (the suite's setting) or with ``{}``
    (XLA's defaults); ``jaxdse run``'s optimised ISO-NE session run is the end-to-end check."""
    import jax

    from jaxdse._many import runner

    before = jax.config.read("jax_disable_most_optimizations")
    try:
        jax.config.update("jax_disable_most_optimizations", True)
        assert runner._compiled_chunk(None) is runner._assess_chunk
        jax.config.update("jax_disable_most_optimizations", False)
        chunk = runner._compiled_chunk(None)
        assert chunk is not runner._assess_chunk and chunk is runner._compiled_chunk(None)
        assert runner._compiled_chunk({}) is runner._assess_chunk
    finally:
        jax.config.update("jax_disable_most_optimizations", before)


@pytest.mark.slow
def test_chunks_on_the_thread_pool_equal_the_units_alone(cut25, plant, assess_jit):
    """Three units in chunks of two: the program compiles in the calling thread, the chunks
    run on the pool (with two or more cores; in the calling thread on one core); every unit
    equals itself assessed alone, in order."""
    from jaxdse._many import runner

    other = jd.Plant(governor=jd.TGOV1(r_pu=0.05))
    ids = jd.IdentifySettings(bootstrap_draws=TEST_BOOTSTRAP_DRAWS)
    plants = [plant, other, jd.Plant(governor=jd.TGOV1(r_pu=0.045))]
    units = [jd.Unit(f"u{k}", cut25, p) for k, p in enumerate(plants)]
    out = jd.assess_units(units, jd.ObserverConfig(), jd.Settings(), ids, chunk=2)
    for u, a in zip(units, out):
        alone = assess_jit(cut25, u.plant)
        np.testing.assert_allclose(a.identified.h_s, alone.identified.h_s, rtol=1e-7)
    assert runner.workers(2) == min(2, runner.cores())
    assert runner.cores() <= (os.cpu_count() or 1)


def test_a_thread_local_jax_context_keeps_every_chunk_in_the_calling_thread():
    """``with jax.default_device(...)`` holds in its own thread only: the pool is not used."""
    import jax

    from jaxdse._many import runner

    assert runner._same_context_in_threads()
    with jax.default_device(jax.devices()[0]):
        assert not runner._same_context_in_threads()
