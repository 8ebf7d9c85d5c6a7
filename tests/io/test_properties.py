"""Property-based tests (hypothesis): random NaN patterns, timestamp jitter and duplicates.

Readers either return clean, uniform, finite recordings with the damage reported, or raise a
one-line InputError; the estimator never returns an unflagged NaN.
"""

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import jaxdse as jd
from jaxdse._app.report import summary_entry

COLS = {"time": "t", "frequency": "f", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM", "i_ang": "IA"}
N_EST = 1400
OUTCOMES = {"readers": {"clean": 0, "refused": 0}, "estimator": {"estimated": 0, "skipped": 0}}
"""Examples per outcome: the checks must have seen examples that reached them (a reader that
refused everything, or recordings always too short, would otherwise pass)."""


@pytest.fixture(scope="module")
def base(pmu25):
    spec = jd.MeasurementSpec(file=(), columns=COLS, v_base_kv=400.0, min_segment_s=20.0)
    return spec, jd.phasor_columns(pmu25.recording, spec)


damage = st.fixed_dictionaries({
    "nan_runs": st.lists(st.tuples(st.sampled_from(["f", "VM", "VA", "IM", "IA"]),
                                   st.integers(0, 1500), st.integers(1, 60)), max_size=6),
    "jitter": st.floats(0.0, 0.3),
    "duplicates": st.integers(0, 30),
    "shuffle": st.booleans(),
    "seed": st.integers(0, 2**16),
})


def damaged_table(columns, d) -> jd.Table:
    rng = np.random.default_rng(d["seed"])
    cols = {k: v.copy() for k, v in columns.items()}
    n = cols["t"].size
    cols["t"] = cols["t"] + d["jitter"] * 0.04 * rng.uniform(-1, 1, n)
    for name, start, length in d["nan_runs"]:
        cols[name][start:start + length] = np.nan
    idx = np.concatenate([np.arange(n), rng.integers(0, n, d["duplicates"])])
    if d["shuffle"]:
        rng.shuffle(idx)
    return jd.Table(source="damaged.csv", columns={k: v[idx] for k, v in cols.items()}, first_row=2)


def check_segments(segments, quality, spec):
    assert segments, "an empty result must be an InputError"
    for _, rec in segments:
        t = np.asarray(rec.t_s)
        steps = np.diff(t)
        assert np.all(steps > 0) and np.allclose(steps, steps[0], rtol=1e-6)
        assert t[-1] >= spec.min_segment_s - 1e-9
        for x in (rec.v_mag_pu, rec.v_ang_rad, rec.i_mag_pu, rec.i_ang_rad):
            assert np.all(np.isfinite(np.asarray(x)))
        if rec.f_hz is not None:  # NaN only where the channel has a long gap (derived there)
            assert not np.any(np.isinf(np.asarray(rec.f_hz)))
        assert np.max(np.abs(np.diff(np.asarray(rec.v_ang_rad)))) < np.pi  # unwrapped
    assert quality["segments"][0]["samples"] == max(int(r.t_s.shape[0]) for _, r in segments)


@settings(max_examples=60, deadline=None, derandomize=True,  # the same 60 damages every run: at
          suppress_health_check=[HealthCheck.function_scoped_fixture])  # random, 12 of 60 clean
@given(d=damage)                                                        # (a shuffle is refused)
def test_readers_never_return_garbage(base, d):
    spec, columns = base
    table = damaged_table(columns, d)
    try:
        segments, quality = jd.condition(table, spec, jd.Machine())
    except jd.InputError as err:
        msg = str(err)
        assert "damaged.csv" in msg and "\n" not in msg
        OUTCOMES["readers"]["refused"] += 1
        event("refused with an InputError")
        return
    OUTCOMES["readers"]["clean"] += 1
    event("read into a clean recording")
    check_segments(segments, quality, spec)
    assert quality["duplicate_timestamps_dropped"] >= 0
    if d["duplicates"] and d["jitter"] == 0:
        assert quality["duplicate_timestamps_dropped"] > 0


@pytest.mark.slow
@settings(max_examples=12, deadline=None, derandomize=True,  # the same 12 damages every run
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(d=damage)
def test_estimator_never_returns_an_unflagged_nan(base, plant, estimate_jit, d):
    spec, columns = base
    try:
        segments, _ = jd.condition(damaged_table(columns, d), spec, jd.Machine())
    except jd.InputError:
        OUTCOMES["estimator"]["skipped"] += 1
        return
    rec = segments[0][1]
    if rec.t_s.shape[0] < N_EST:
        OUTCOMES["estimator"]["skipped"] += 1
        return
    OUTCOMES["estimator"]["estimated"] += 1
    event("reached the estimator")
    rec = jax.tree_util.tree_map(lambda x: x[:N_EST], rec)
    est = estimate_jit(rec, plant, jd.ObserverConfig())
    entry = summary_entry("p", est)
    tr = est.trajectories
    finite = all(np.all(np.isfinite(np.asarray(x))) for x in (
        est.a1_hat, est.a2_hat, tr.x2_hat_rad_s, tr.playback.x2_rad_s, tr.e_f_pu, tr.t_m_pu))
    assert entry["online"]["flags"]["finite"] == finite
    if not finite:
        assert not entry["online"]["converged"] and entry["verdict"] != "identified"
    else:
        assert all(entry[k] is not None for k in ("a1", "a2", "H_s", "D"))


@pytest.mark.parametrize("test, outcome", [("readers", "clean"), ("estimator", "estimated")])
def test_examples_reached_the_checks(test, outcome):
    """Runs after the property tests above (file order): most examples must get past the
    readers, and some must reach the estimator."""
    total = sum(OUTCOMES[test].values())
    if total == 0:
        pytest.skip(f"the {test} property test did not run in this session")
    assert OUTCOMES[test][outcome] >= max(1, total // 4), OUTCOMES[test]
