"""The planted event-window failure through the real replay (issue 19): a machine whose damping
D settles its own swing, recorded on a line trip by the project's simulator, replayed (the
recorded terminal |V| and angle imposed) with D scaled to 0. The replay rings where the
recording shows no oscillatory mode; the window criteria fail it while the whole-window
sMAPE of P stays under 5 %. The replay with the true D passes.
(``experiments/d_scaled_replay`` shows why a lightly damped recording cannot plant this: there
the imposed angle carries the swing whatever D.)"""

import equinox as eqx
import numpy as np
import pytest

import jaxdse as jd

D_TRUE = 1.0


@pytest.fixture(scope="module")
def line_trip():
    plant = eqx.tree_at(lambda p: p.machine.d_pu_s, jd.Plant(), D_TRUE)
    scenario = jd.Scenario(duration_s=30.0, seed=5, ambient_load_std=0.003, ambient_freq_std_hz=0.001,
                           ambient_volt_std=0.0002, events=(jd.Event(8.0, "line_trip", 3.0),))
    rec = jd.simulate(plant, scenario).recording
    est = jd.estimate(rec, plant, jd.ObserverConfig(), jd.Settings(playback=False))
    return rec, plant, np.asarray(est.time_s), np.asarray(est.trajectories.p_t_pu)


def judge(line_trip, d_scale):
    rec, plant, t, p_meas = line_trip
    m = plant.machine
    p = np.asarray(jd.replay(rec, plant, float(m.a1) * d_scale, float(m.a2)).playback.p_t_pu)
    smape = 100 * np.mean(np.abs(p - p_meas) / ((np.abs(p) + np.abs(p_meas)) / 2))
    return jd.window_scores(t, {"P_t": p_meas}, {"P_t": p}, {"P_t": 100.0}), smape


@pytest.mark.slow
def test_replay_with_the_true_damping_passes(line_trip):
    scores, smape = judge(line_trip, 1.0)
    assert scores.passed, scores.reasons
    assert smape < 2.0


@pytest.mark.slow
def test_replay_without_damping_rings_and_fails_despite_a_small_smape(line_trip):
    scores, smape = judge(line_trip, 0.0)
    assert smape < 5.0
    assert not scores.passed
    ev = scores.score("event", "P_t")
    assert not np.isfinite(ev.mode_measured.damping_ratio)          # the recording: no mode
    assert ev.mode_simulated.damping_ratio < 0.1                     # the replay: a lightly damped swing
    assert any(r.startswith("P_t:") and "oscillat" in r for r in scores.reasons), scores.reasons
