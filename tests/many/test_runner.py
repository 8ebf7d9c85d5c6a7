"""The one runner (``jd.assess_units``) and the vmapped per-unit assessment.

XLA's CPU runtime once deadlocked (every thread idle) on a vmapped identification whose graph
held LAPACK calls; the per-unit graph now holds none. The guard runs ``jit(vmap(assess))``
over 16 units with different plants in a subprocess with a timeout, so that a deadlock fails
the suite instead of hanging it.
"""

import json
import os
import subprocess
import sys

import jax
import numpy as np
import pytest

import jaxdse as jd

VMAP_16 = r"""
import json, sys
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxdse as jd

sim = jd.simulate(jd.Plant(), jd.Scenario(duration_s=24.0, frame_rate_hz=25.0, seed=5))
plants = [jd.Plant(machine=jd.Machine(xd_pu=1.6 + 0.02 * k, xq_pu=1.5 + 0.01 * k, xd1_pu=0.3 + 0.005 * k),
                   governor=jd.TGOV1(r_pu=0.04 + 0.002 * k)) for k in range(16)]
recs = jd.stack([sim.recording] * 16)
run = jax.jit(jax.vmap(lambda r, p: jd.assess(r, p, jd.ObserverConfig(), jd.Settings(keep="final"),
                                              jd.IdentifySettings(bootstrap_draws=4))))
out = run(recs, jd.stack(plants))
one = jax.jit(lambda r, p: jd.assess(r, p, jd.ObserverConfig(), jd.Settings(keep="final"),
                                     jd.IdentifySettings(bootstrap_draws=4)))(sim.recording, plants[7])
print(json.dumps({"h": np.asarray(out.identified.h_s).tolist(),
                  "ci": np.asarray(out.identified.h_ci95).tolist(),
                  "code": np.asarray(out.verdict.code).tolist(),
                  "h7": float(one.identified.h_s), "ci7": np.asarray(one.identified.h_ci95).tolist()}))
"""


@pytest.mark.slow
def test_vmapped_assess_over_16_plants_does_not_deadlock():
    out = subprocess.run([sys.executable, "-c", VMAP_16], capture_output=True, text=True, timeout=420,
                         env=dict(os.environ))
    assert out.returncode == 0, out.stderr[-3000:]
    res = json.loads(out.stdout.strip().splitlines()[-1])
    h = np.array(res["h"])
    assert h.shape == (16,) and np.all(np.isfinite(h)) and np.all(np.isfinite(res["ci"]))
    assert len(set(np.round(h, 9))) > 1, "different plants must give different H"
    # The vmapped member equals the unit run alone (no batch-axis mix-up).
    np.testing.assert_allclose(h[7], res["h7"], rtol=1e-9)
    np.testing.assert_allclose(res["ci"][7], res["ci7"], rtol=1e-9)


@pytest.fixture(scope="module")
def two_lengths(pmu25):
    rec = pmu25.recording
    cut = jax.tree_util.tree_map(lambda x: x[:1251], rec)
    return rec, cut


def test_runner_groups_pads_cuts_and_shifts(two_lengths, plant):
    """Units of two lengths and two plants: each result is cut to its own length, shifted to
    its own start, and equals the unit assessed alone (padding is masked)."""
    full, cut = two_lengths
    other = jd.Plant(governor=jd.TGOV1(r_pu=0.06))
    ids = jd.IdentifySettings(bootstrap_draws=4)
    units = [jd.Unit("a", full, plant), jd.Unit("b", cut, other, t0_s=100.0), jd.Unit("c", cut, plant)]
    seen = []
    out = jd.assess_units(units, jd.ObserverConfig(), jd.Settings(), ids, progress=seen.append)
    assert len(out) == 3 and seen
    assert out[0].estimate.time_s.shape == (1501,) and out[1].estimate.time_s.shape == (1251,)
    assert out[1].replay.playback.p_t_pu.shape == (1251,)
    np.testing.assert_allclose(out[1].estimate.time_s[0], 100.0 + float(cut.t_s[0]))
    alone = jax.jit(lambda r, p: jd.assess(r, p, jd.ObserverConfig(), jd.Settings(), ids))(cut, other)
    np.testing.assert_allclose(out[1].identified.h_s, alone.identified.h_s, rtol=1e-7)
    np.testing.assert_allclose(out[1].identified.h_ci95, alone.identified.h_ci95, rtol=1e-6)
    assert int(out[1].verdict.code) == int(alone.verdict.code)
    assert out[1].identified.h_s != out[2].identified.h_s  # its own plant, not its neighbour's
