"""Tuning: log-space transforms, the loss gradient against finite differences, vmap/grad
commutation, and the sweep/tune commands on the shipped example."""

import json
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse import TUNABLE, from_log, sweep_configs, to_log, tuning_loss
from jaxdse._app.cli import main

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def short(ambient):
    n = 1000  # 20 s
    r = ambient.recording
    cut = jd.Recording(t_s=r.t_s[:n], v_mag_pu=r.v_mag_pu[:n], v_ang_rad=r.v_ang_rad[:n],
                       i_mag_pu=r.i_mag_pu[:n], i_ang_rad=r.i_ang_rad[:n], f_hz=r.f_hz[:n])
    return jd.stack_recordings([cut])


def test_log_transform_round_trip():
    start = jd.ObserverConfig()
    same = from_log(to_log(start), start)
    for n in TUNABLE:
        assert float(getattr(same, n)) == pytest.approx(float(getattr(start, n)), rel=1e-14)
    far = from_log(jnp.full(len(TUNABLE), 50.0), start, max_factor=10.0)
    assert float(far.gamma1) <= 8500.0 + 1e-6  # bounded to max_factor


@pytest.fixture(scope="module")
def loss_at(short, plant):
    """The tuning loss of the short recording (a2 known) as a function of the log coordinates,
    and a point away from the start."""
    start = jd.ObserverConfig()

    def f(u):
        return tuning_loss(from_log(u, start), short, plant, a2_true=jnp.asarray([25.4]))

    return f, jnp.linspace(-0.2, 0.2, len(TUNABLE))


def test_loss_gradient_matches_finite_differences(loss_at):
    f, u0 = loss_at
    g = jax.jit(jax.grad(f))(u0)
    fj = jax.jit(f)
    for k in range(len(TUNABLE)):
        e = jnp.zeros(len(TUNABLE)).at[k].set(1e-5)
        fd = (float(fj(u0 + e)) - float(fj(u0 - e))) / 2e-5
        assert abs(float(g[k]) - fd) <= 1e-4 * max(abs(fd), 1e-6), (TUNABLE[k], float(g[k]), fd)
    assert float(jnp.max(jnp.abs(g))) > 0


def test_forward_mode_gradient_equals_reverse_mode(loss_at, short, plant):
    f, u0 = loss_at
    v_rev, g_rev = jax.jit(jax.value_and_grad(f))(u0)
    v_fwd, g_fwd = jax.jit(jax.value_and_grad(jd.forward_mode(f)))(u0)
    assert float(v_fwd) == pytest.approx(float(v_rev), rel=1e-13)
    np.testing.assert_allclose(g_fwd, g_rev, rtol=1e-9, atol=1e-12 * float(jnp.max(jnp.abs(g_rev))))
    # optimistix linearises the objective: the linear map must be the gradient
    _, lin = jax.linearize(jd.forward_mode(f), u0)
    e = jnp.zeros(len(TUNABLE)).at[3].set(1.0)
    assert float(lin(e)) == pytest.approx(float(g_rev[3]), rel=1e-9)
    with pytest.raises(ValueError, match="autodiff"):
        jd.tune([short], plant, autodiff="backward")


def test_vmap_of_grad_equals_grad_per_member(short, plant):
    start = jd.ObserverConfig()
    us = jnp.stack([jnp.zeros(len(TUNABLE)), jnp.full(len(TUNABLE), 0.1)])

    def f(u):
        return tuning_loss(from_log(u, start), short, plant)

    batched = jax.jit(jax.vmap(jax.grad(f)))(us)
    for k in range(2):
        np.testing.assert_allclose(batched[k], jax.jit(jax.grad(f))(us[k]), rtol=1e-10, atol=1e-14)
    # grad of a batched (summed) loss equals the sum of the per-member gradients
    total = jax.jit(jax.grad(lambda v: jnp.sum(jax.vmap(f)(v))))(us)
    np.testing.assert_allclose(total, batched, rtol=1e-10, atol=1e-14)


def test_sweep_configs_grid_and_random():
    cfgs, points = sweep_configs(jd.ObserverConfig(), {"gamma": [1.0, 2.0], "k_obs": [3.0, 4.0, 5.0]})
    assert len(points) == 6 and cfgs.gamma1.shape == (6,)
    np.testing.assert_array_equal(cfgs.gamma1, cfgs.gamma2)
    cfgs, points = sweep_configs(jd.ObserverConfig(), {"lambda1": [2.0, 20.0]}, "random", draws=50)
    assert np.all((cfgs.lambda1 >= 2.0) & (cfgs.lambda1 <= 20.0)) and len(points) == 50


def test_sweep_and_tune_commands(tmp_path, capsys):
    assert main(["sweep", str(EXAMPLES / "sweep_tune.toml"), "--out", str(tmp_path)]) == 0
    rows = (tmp_path / "sweep.csv").read_text().splitlines()
    assert len(rows) == 1 + 16 * 2 and rows[0].startswith("generator,config,gamma,lambda1,k_obs,a1,a2")
    assert main(["tune", str(EXAMPLES / "sweep_tune.toml"), "--out", str(tmp_path)]) == 0
    out = json.loads((tmp_path / "tune.json").read_text())
    assert out["loss_tuned"] <= out["loss_start"] and out["heldout_loss_start"] is not None
    assert "[observer]" in (tmp_path / "tuned_observer.toml").read_text()


def test_sweep_config_errors(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    text = (EXAMPLES / "sweep_tune.toml").read_text().replace("k_obs = [4.0, 8.0]", "kobs = [4.0]")
    bad.write_text(text.replace('file = "data/', f'file = "{EXAMPLES}/data/'))
    assert main(["sweep", str(bad)]) == 2
    assert "sweep.parameters" in capsys.readouterr().err
    text = (EXAMPLES / "sweep_tune.toml").read_text().replace('autodiff = "auto"', 'autodiff = "rev"')
    bad.write_text(text.replace('file = "data/', f'file = "{EXAMPLES}/data/'))
    assert main(["tune", str(bad)]) == 2
    assert "tune.autodiff" in capsys.readouterr().err
