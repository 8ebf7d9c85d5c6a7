"""Tuning: log-space transforms, the loss gradient against finite differences, vmap/grad
commutation, and the sweep/tune commands on the shipped example."""

import dataclasses
import json
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxdse as jd
from jaxdse import sweep_configs, tuning_loss
from jaxdse._app.cli import main
from jaxdse._core.tuning import TUNABLE
from jaxdse._many.tune import from_log, to_log

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


@pytest.fixture(scope="module")
def batch(short):
    return jd.stack_recordings([short])


def test_log_transform_round_trip():
    """to_log inverts from_log around a start, for configurations away from it."""
    start = jd.ObserverConfig()
    u = jnp.linspace(-1.5, 2.0, len(TUNABLE))
    cfg = from_log(u, start, max_factor=10.0)
    assert float(cfg.gamma1) != pytest.approx(float(start.gamma1), rel=1e-3)  # it moved
    np.testing.assert_allclose(to_log(cfg, start, max_factor=10.0), u, rtol=1e-12, atol=1e-12)
    back = from_log(to_log(cfg, start), start)
    for n in TUNABLE:
        assert float(getattr(back, n)) == pytest.approx(float(getattr(cfg, n)), rel=1e-12)
    np.testing.assert_array_equal(to_log(start), 0.0)  # the start is the origin
    far = from_log(jnp.full(len(TUNABLE), 50.0), start, max_factor=10.0)
    assert float(far.gamma1) <= 8500.0 + 1e-6  # bounded to max_factor


@pytest.fixture(scope="module")
def loss_at(batch, plant):
    """The tuning loss of the short recording (a2 known) as a function of the log coordinates,
    a point away from the start, and its compiled reverse-mode value-and-grad (shared by the
    tests below, which also take their loss values from it: each compilation costs ~10 s)."""
    start = jd.ObserverConfig()

    def f(u):
        return tuning_loss(from_log(u, start), batch, plant, a2_true=jnp.asarray([25.4]))

    return f, jnp.linspace(-0.2, 0.2, len(TUNABLE)), jax.jit(jax.value_and_grad(f))


@pytest.mark.slow
def test_loss_gradient_matches_finite_differences(loss_at):
    f, u0, vg = loss_at
    _, g = vg(u0)
    for k in range(len(TUNABLE)):
        e = jnp.zeros(len(TUNABLE)).at[k].set(1e-5)
        fd = (float(vg(u0 + e)[0]) - float(vg(u0 - e)[0])) / 2e-5
        assert abs(float(g[k]) - fd) <= 1e-4 * max(abs(fd), 1e-6), (TUNABLE[k], float(g[k]), fd)
    assert float(jnp.max(jnp.abs(g))) > 0


@pytest.mark.slow
def test_forward_mode_gradient_equals_reverse_mode(loss_at, batch, plant):
    f, u0, vg = loss_at
    v_rev, g_rev = vg(u0)
    v_fwd, g_fwd = jax.jit(jax.value_and_grad(jd.forward_mode(f)))(u0)
    assert float(v_fwd) == pytest.approx(float(v_rev), rel=1e-13)
    np.testing.assert_allclose(g_fwd, g_rev, rtol=1e-9, atol=1e-12 * float(jnp.max(jnp.abs(g_rev))))
    # optimistix linearises the objective: the linear map must be the gradient
    e = jnp.zeros(len(TUNABLE)).at[3].set(1.0)
    lin = jax.jit(lambda u, d: jax.linearize(jd.forward_mode(f), u)[1](d))(u0, e)
    assert float(lin) == pytest.approx(float(g_rev[3]), rel=1e-9)
    with pytest.raises(ValueError, match="autodiff"):
        jd.tune([batch], plant, autodiff="backward")


@pytest.mark.slow
def test_vmap_of_grad_equals_grad_per_member(loss_at):
    f, u0, vg = loss_at
    us = jnp.stack([u0, u0 + 0.1])
    batched = jax.jit(jax.vmap(jax.grad(f)))(us)
    for k in range(2):
        np.testing.assert_allclose(batched[k], vg(us[k])[1], rtol=1e-10, atol=1e-14)
    assert float(jnp.max(jnp.abs(batched[0] - batched[1]))) > 0  # the members differ
    # grad of a batched (summed) loss equals the sum of the per-member gradients
    total = jax.jit(jax.grad(lambda v: jnp.sum(jax.vmap(f)(v))))(us)
    np.testing.assert_allclose(total, batched, rtol=1e-10, atol=1e-14)


def test_sweep_configs_grid_and_random():
    cfgs, points = sweep_configs(jd.ObserverConfig(), {"gamma": [1.0, 2.0], "k_obs": [3.0, 4.0, 5.0]})
    assert len(points) == 6 and cfgs.gamma1.shape == (6,)
    np.testing.assert_array_equal(cfgs.gamma1, cfgs.gamma2)
    cfgs, points = sweep_configs(jd.ObserverConfig(), {"lambda1": [2.0, 20.0]}, "random", draws=50)
    assert np.all((cfgs.lambda1 >= 2.0) & (cfgs.lambda1 <= 20.0)) and len(points) == 50


def _example(tmp_path, replace=()):
    """The shipped sweep/tune example, smaller (4 configurations, 3 tuning steps), data in place."""
    text = (EXAMPLES / "sweep_tune.toml").read_text().replace('file = "data/', f'file = "{EXAMPLES}/data/')
    grid = "parameters = { gamma = [425.0, 850.0, 1700.0, 3400.0], lambda1 = [4.0, 8.0], k_obs = [4.0, 8.0] }"
    text = text.replace(grid, "parameters = { gamma = [425.0, 1700.0], k_obs = [4.0, 8.0] }")
    text = text.replace("max_steps = 8", "max_steps = 3")
    for a, b in replace:
        text = text.replace(a, b)
    path = tmp_path / "sweep_tune.toml"
    path.write_text(text)
    return path


@pytest.mark.slow
def test_sweep_and_tune_commands(tmp_path, capsys, plant):
    cfg = _example(tmp_path)
    assert main(["sweep", str(cfg), "--out", str(tmp_path)]) == 0
    rows = (tmp_path / "sweep.csv").read_text().splitlines()
    assert len(rows) == 1 + 4 * 2 and rows[0].startswith("generator,config,gamma,k_obs,a1,a2")
    assert main(["tune", str(cfg), "--out", str(tmp_path)]) == 0
    out = json.loads((tmp_path / "tune.json").read_text())
    assert out["heldout_loss_start"] is not None and out["steps"] == 3
    assert out["observer_tuned"] != out["observer_start"]  # BFGS moved
    # the reported loss is the loss of the reported configuration (recomputed independently)
    run = jd.load_config(cfg)
    train = [jd.read_measurement(g.measurement, g.plant.machine)[0][0][1]
             for g in run.generators if g.role == "auto"]
    tuned = dataclasses.replace(run.observer, **out["observer_tuned"])
    again = eqx.filter_jit(jd.tuning_loss)(tuned, jd.stack_recordings(train), run.generators[0].plant,
                           jd.Settings.fast(), jnp.asarray([25.4174]))
    assert float(again) == pytest.approx(out["loss_tuned"], rel=1e-9)
    assert out["loss_tuned"] < out["loss_start"]
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
