"""The one runner (``jd.assess_units``) and the vmapped per-unit assessment.

XLA's CPU runtime once deadlocked (every thread idle) on a vmapped identification whose graph
held LAPACK calls; the per-unit graph now holds none. The guard runs ``jit(vmap(assess))``
over 16 units with different plants under a watchdog (``faulthandler``): a deadlock ends the
test process with the threads' tracebacks after ``DEADLOCK_TIMEOUT_S``, so that it fails the
suite instead of hanging it.

Shapes shared with the rest of the suite (conftest): the units alone are ``assess_jit`` on
``cut25``'s 1251 samples; the runner's batches are `jaxdse run`'s (1536 samples, one unit; 1280
samples, two units, as its split-recording test).
"""

import faulthandler

import jax
import numpy as np
import pytest
from builders import TEST_BOOTSTRAP_DRAWS

import jaxdse as jd

DEADLOCK_TIMEOUT_S = 420
"""The watchdog's limit [s]: the guard takes about a minute on 2 busy cores, compiling included."""


@pytest.mark.slow
def test_vmapped_assess_over_16_plants_does_not_deadlock(cut25, assess_jit):
    plants = [jd.Plant(machine=jd.Machine(xd_pu=1.6 + 0.02 * k, xq_pu=1.5 + 0.01 * k, xd1_pu=0.3 + 0.005 * k),
                       governor=jd.TGOV1(r_pu=0.04 + 0.002 * k)) for k in range(16)]
    ids = jd.IdentifySettings(bootstrap_draws=TEST_BOOTSTRAP_DRAWS)
    run = jax.jit(jax.vmap(lambda r, p: jd.assess(r, p, jd.ObserverConfig(), jd.Settings(), ids)))
    faulthandler.dump_traceback_later(DEADLOCK_TIMEOUT_S, exit=True)
    try:
        out = run(jd.stack([cut25] * 16), jd.stack(plants))
        one = assess_jit(cut25, plants[7])
    finally:
        faulthandler.cancel_dump_traceback_later()
    h, ci = np.asarray(out.identified.h_s), np.asarray(out.identified.h_ci95)
    assert h.shape == (16,) and np.all(np.isfinite(h)) and np.all(np.isfinite(ci))
    assert len(set(np.round(h, 9))) > 1, "different plants must give different H"
    # The vmapped member equals the unit run alone (no batch-axis mix-up).
    np.testing.assert_allclose(h[7], float(one.identified.h_s), rtol=1e-9)
    np.testing.assert_allclose(ci[7], np.asarray(one.identified.h_ci95), rtol=1e-9)


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
