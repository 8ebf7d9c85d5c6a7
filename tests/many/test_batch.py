"""Batched estimation: padding and masking, output selection, sharding, jax.distributed."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxdse as jd

FAST = jd.Settings(observer_integrator=jd.Integrator.fast(), playback_integrator=jd.Integrator.fast())
FINAL = jd.Settings(observer_integrator=jd.Integrator.fast(), playback_integrator=jd.Integrator.fast(),
                    keep="final")
SCALARS = ("a1", "a2", "h_s", "d_pu_s", "t_ref_pu", "convergence_time_s")


def _cut(rec, n):
    return jd.Recording(t_s=rec.t_s[:n], v_mag_pu=rec.v_mag_pu[:n], v_ang_rad=rec.v_ang_rad[:n],
                        i_mag_pu=rec.i_mag_pu[:n], i_ang_rad=rec.i_ang_rad[:n],
                        f_hz=None if rec.f_hz is None else rec.f_hz[:n], location=rec.location)


@pytest.fixture(scope="module")
def pair(ambient):
    """Two recordings of different lengths (120 s and 77.3 s)."""
    return [ambient.recording, _cut(ambient.recording, 3866)]


@pytest.mark.parametrize("settings", [FAST, FINAL], ids=["trajectories", "final"])
def test_padded_batch_equals_single_runs(pair, plant, settings):
    cfg = jd.ObserverConfig(gamma1=2000.0, gamma2=2000.0)
    batch = jd.estimate_batch(pair, plant, cfg, settings)
    for k, rec in enumerate(pair):
        one = jax.jit(jd.estimate, static_argnums=3)(rec, plant, cfg, settings)
        got = jd.select(batch, k)
        for name in SCALARS:
            np.testing.assert_allclose(getattr(got, name), getattr(one, name), rtol=1e-9, atol=1e-12,
                                       err_msg=name)
        for name in ("converged", "excited", "online", "torque_balanced", "solver_ok"):
            assert bool(getattr(got, name)) == bool(getattr(one, name)), name
        np.testing.assert_allclose(np.array(got.smape), np.array(one.smape), rtol=1e-9)
        n = one.a2_hat.shape[0]
        np.testing.assert_allclose(got.a2_hat[:n], one.a2_hat, rtol=1e-9, atol=1e-12)


def test_final_mode_matches_trajectories(ambient, plant, estimate_jit):
    """keep="final" stores no trajectory but gives the same estimates and playback scores."""
    rec, a2 = ambient.recording, ambient.truth.a2
    traj = jax.jit(jd.estimate, static_argnums=3)(rec, plant, jd.ObserverConfig(), FAST, None, a2)
    fin = jax.jit(jd.estimate, static_argnums=3)(rec, plant, jd.ObserverConfig(), FINAL, None, a2)
    assert fin.trajectories is None and fin.a2_hat.shape == (-(-rec.t_s.shape[0] // 50),)
    for name in ("a1", "a2", "h_s", "t_ref_pu"):
        np.testing.assert_allclose(getattr(fin, name), getattr(traj, name), rtol=1e-12)
    for name in ("x2_playback", "i_t", "p_t", "q_t"):
        np.testing.assert_allclose(getattr(fin.smape, name), getattr(traj.smape, name), rtol=1e-9)
    # Convergence is resolved to one block (50 samples = 1 s) in final mode.
    assert bool(fin.converged) and bool(traj.converged)
    assert 0.0 <= float(fin.convergence_time_s - traj.convergence_time_s) <= 1.0
    ends = np.minimum(np.arange(fin.a2_hat.shape[0]) * 50 + 49, rec.t_s.shape[0] - 1)
    np.testing.assert_allclose(fin.a2_hat, traj.a2_hat[ends], rtol=1e-12)


def test_config_sweep_axis(ambient, plant):
    """A stacked batch of configurations on one recording, in chunks with progress."""
    cfgs = [jd.ObserverConfig(gamma1=g, gamma2=g) for g in (500.0, 850.0, 1500.0, 3000.0, 6000.0)]
    seen = []
    out = jd.estimate_batch(ambient.recording, plant, cfgs, FINAL, chunk=2, progress=seen.append)
    assert out.a2.shape == (5,) and seen == [2, 4, 5]
    one = jax.jit(jd.estimate, static_argnums=3)(ambient.recording, plant, cfgs[3], FINAL)
    np.testing.assert_allclose(out.a2[3], one.a2, rtol=1e-12)
    with pytest.raises(ValueError, match="batch size"):
        jd.estimate_batch([ambient.recording] * 2, plant, cfgs, FINAL)


SCRIPT = textwrap.dedent("""
    import sys, json
    import jax
    jax.config.update("jax_enable_x64", True)
    if len(sys.argv) > 2:
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(coordinator_address="localhost:" + sys.argv[2], num_processes=2,
                                   process_id=int(sys.argv[1]))
    import jaxdse as jd
    plant = jd.Plant()
    rec = jd.simulate(plant, jd.Scenario(duration_s=40.0, seed=5)).recording
    cfgs = [jd.ObserverConfig(gamma1=g, gamma2=g) for g in (400.0, 900.0, 1600.0, 2500.0, 5000.0)]
    st = jd.Settings(observer_integrator=jd.Integrator.fast(), keep="final", playback=False)
    out = jd.estimate_batch(rec, plant, cfgs, st)
    print(json.dumps({"devices": len(jax.devices()), "a2": out.a2.tolist(), "a1": out.a1.tolist()}))
""")


def _run(args, env_extra, n=1):
    env = {**os.environ, "PYTHONPATH": str(Path(jd.__file__).parents[1]), **env_extra}
    procs = [subprocess.Popen([sys.executable, "-c", SCRIPT, *([str(k)] if n > 1 else []), *args],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
             for k in range(n)]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err[-2000:]
    import json
    return [json.loads(out.strip().splitlines()[-1]) for out, _ in outs]


def test_sharded_and_distributed_runs_equal_single_device():
    """2 forced CPU devices, and 2 processes joined by jax.distributed: same results."""
    single = _run([], {"XLA_FLAGS": ""})[0]
    sharded = _run([], {"XLA_FLAGS": "--xla_force_host_platform_device_count=2"})[0]
    port = str(20000 + os.getpid() % 20000)
    dist = _run([port], {"XLA_FLAGS": ""}, n=2)
    assert single["devices"] == 1 and sharded["devices"] == 2
    assert all(d["devices"] == 2 for d in dist)
    for other in (sharded, *dist):
        np.testing.assert_allclose(other["a2"], single["a2"], rtol=1e-12)
        np.testing.assert_allclose(other["a1"], single["a1"], rtol=1e-12)
