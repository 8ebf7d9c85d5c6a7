"""Batched estimation: padding and masking, output selection, sharding, jax.distributed."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import numpy as np
import pytest

import jaxdse as jd

FAST = jd.Settings.fast()
FINAL = jd.Settings.fast(keep="final")
SCALARS = ("a1", "a2", "h_s", "d_pu_s", "t_ref_pu", "convergence_time_s")


@pytest.fixture(scope="module")
def pair(ambient, short):
    """Two recordings of different lengths (120 s and 20 s)."""
    return [ambient.recording, short]


@pytest.mark.slow
@pytest.mark.parametrize("settings", [FAST, FINAL], ids=["trajectories", "final"])
def test_padded_batch_equals_single_runs(pair, plant, settings, estimate_jit):
    cfg = jd.ObserverConfig(gamma1=2000.0, gamma2=2000.0)
    batch = jd.estimate_batch(pair, plant, cfg, settings)
    for k, rec in enumerate(pair):
        one = estimate_jit(rec, plant, cfg, settings)
        got = jd.select(batch, k)
        for name in SCALARS:
            np.testing.assert_allclose(getattr(got, name), getattr(one, name), rtol=1e-9, atol=1e-12,
                                       err_msg=name)
        for name in ("converged", "excited", "online", "torque_balanced", "solver_ok"):
            assert bool(getattr(got, name)) == bool(getattr(one, name)), name
        np.testing.assert_allclose(np.array(got.smape), np.array(one.smape), rtol=1e-9)
        n = one.a2_hat.shape[0]
        np.testing.assert_allclose(got.a2_hat[:n], one.a2_hat, rtol=1e-9, atol=1e-12)


@pytest.mark.slow
def test_final_mode_matches_trajectories(ambient, plant, estimate_jit):
    """keep="final" stores no trajectory but gives the same estimates and playback scores
    (convergence against the final estimate: the compiled shapes of the padded-batch test)."""
    rec = ambient.recording
    traj = estimate_jit(rec, plant, jd.ObserverConfig(), FAST)
    fin = estimate_jit(rec, plant, jd.ObserverConfig(), FINAL)
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


@pytest.mark.slow
def test_config_sweep_axis(ambient, plant, estimate_jit):
    """A stacked batch of configurations on one recording, in chunks with progress."""
    cfgs = [jd.ObserverConfig(gamma1=g, gamma2=g) for g in (500.0, 850.0, 1500.0, 3000.0, 6000.0)]
    seen = []
    out = jd.estimate_batch(ambient.recording, plant, cfgs, FINAL, chunk=2, progress=seen.append)
    assert out.a2.shape == (5,) and seen == [2, 4, 5]
    one = estimate_jit(ambient.recording, plant, cfgs[3], FINAL)
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
                                   process_id=int(sys.argv[3]))
    import numpy as np
    import jaxdse as jd
    data = np.load(sys.argv[1])
    rec = jd.Recording(**{k: data[k] for k in data.files})
    cfgs = [jd.ObserverConfig(gamma1=g, gamma2=g) for g in (400.0, 900.0, 1600.0, 2500.0, 5000.0)]
    out = jd.estimate_batch(rec, jd.Plant(), cfgs, jd.Settings.fast(keep="final", playback=False))
    print(json.dumps({"devices": len(jax.devices()), "a2": out.a2.tolist(), "a1": out.a1.tolist()}))
""")
CONFIGS = (400.0, 900.0, 1600.0, 2500.0, 5000.0)
FLAGS = " ".join(f for f in os.environ.get("XLA_FLAGS", "").split() if "device_count" not in f)
"""This process's XLA flags (conftest's), less any device count."""


def _run(args, env_extra, n=1):
    # XLA's slow passes off, as in this process (conftest): the children compile, not compute.
    quick = str(jax.config.read("jax_disable_most_optimizations"))
    env = {**os.environ, "PYTHONPATH": str(Path(jd.__file__).parents[1]),
           "JAX_DISABLE_MOST_OPTIMIZATIONS": quick, **env_extra}
    procs = [subprocess.Popen([sys.executable, "-c", SCRIPT, *args, *([str(k)] if n > 1 else [])],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
             for k in range(n)]
    outs = [p.communicate(timeout=300) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err[-2000:]
    return [json.loads(out.strip().splitlines()[-1]) for out, _ in outs]


@pytest.mark.slow
def test_sharded_and_distributed_runs_equal_single_device(short, plant, tmp_path):
    """2 forced CPU devices, and 2 processes joined by jax.distributed: the same results as this
    process (1 device) on the same recording (read from a file, not simulated again)."""
    fields = ("t_s", "v_mag_pu", "v_ang_rad", "i_mag_pu", "i_ang_rad", "f_hz")
    np.savez(tmp_path / "rec.npz", **{k: np.asarray(getattr(short, k)) for k in fields})
    cfgs = [jd.ObserverConfig(gamma1=g, gamma2=g) for g in CONFIGS]
    single = jd.estimate_batch(short, plant, cfgs, jd.Settings.fast(keep="final", playback=False))
    assert len(jax.devices()) == 1
    two = f"{FLAGS} --xla_force_host_platform_device_count=2"
    sharded = _run([str(tmp_path / "rec.npz")], {"XLA_FLAGS": two})[0]
    port = str(20000 + os.getpid() % 20000)
    dist = _run([str(tmp_path / "rec.npz"), port], {"XLA_FLAGS": FLAGS}, n=2)
    assert sharded["devices"] == 2 and all(d["devices"] == 2 for d in dist)
    for other in (sharded, *dist):
        np.testing.assert_allclose(other["a2"], single.a2, rtol=1e-12)
        np.testing.assert_allclose(other["a1"], single.a1, rtol=1e-12)
