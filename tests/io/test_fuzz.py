"""Fuzzing (hypothesis): spikes, unit mistakes, NaN runs and time jitter injected into a CSV.

Every example ends in one of two outcomes: an InputError (exit status 2) with a one-line
message that names the file, or a result with a finite H, with the damage noted in
``data_quality`` or flagged by the verdict, and never an unflagged H more than 10 % off the
clean run. The examples are derandomized (the same ones every run) and counted with
``hypothesis.event``; the tests assert that some of them reached the estimator.
"""

import contextlib
import io
import itertools
import json
from collections import Counter

import numpy as np
import pytest
from builders import COLS, run_toml
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

import jaxdse as jd
from jaxdse._app.cli import main

PHASES = (Phase.explicit, Phase.generate, Phase.shrink)
"""No explain phase (it reruns a failing example hundreds of times)."""
H_WRONG = 0.10
"""A relative H error above this must be flagged (verdict other than "identified")."""
MAGNITUDE_SPIKES = (0.0, 0.3, 1.5, 3.0, 10.0, 1e3, 1e6, 1e30, -1.0)
"""Factors of a spiked magnitude sample."""
ANGLE_SPIKES = (30.0, 90.0, 180.0, -120.0)
"""Offsets of a spiked angle sample [deg]."""
FREQUENCY_SPIKES = (0.0, 45.0, 50.5, 60.0, 1e6, -50.0)
"""Values of a spiked frequency sample [Hz]."""
UNIT_MISTAKES = {
    "none": ({}, ""),
    "kV read as V": ({"VM": 1e3}, ""),
    "V read as kV": ({"VM": 1e-3}, ""),
    "phase-to-ground as phase-to-phase": ({"VM": 1 / np.sqrt(3)}, ""),
    "phase-to-phase as phase-to-ground": ({}, 'voltage_unit = "kV_LN"'),
    "kA read as A": ({"IM": 1e-3}, ""),
    "A read as kA": ({}, 'current_unit = "kA"'),
    "CT secondary amperes": ({"IM": 1 / 400}, ""),
    "ms read as s": ({"t": 1e3}, ""),
    "s read as ms": ({}, 'time_unit = "ms"'),
    "degrees read as radians": ({}, 'angle_unit = "rad"'),
    "radians read as degrees": ({"VA": np.pi / 180, "IA": np.pi / 180}, ""),
    "current into the plant": ({"IA": "flip"}, ""),
}
"""Name -> (column -> factor, or "flip": +180 degrees; a line added to [measurement])."""

damage = st.fixed_dictionaries({
    "spikes": st.lists(st.one_of(
        st.tuples(st.sampled_from(["VM", "IM"]), st.integers(0, 1500), st.integers(1, 3),
                  st.sampled_from(MAGNITUDE_SPIKES)),
        st.tuples(st.sampled_from(["VA", "IA"]), st.integers(0, 1500), st.integers(1, 3),
                  st.sampled_from(ANGLE_SPIKES)),
        st.tuples(st.just("f"), st.integers(0, 1500), st.integers(1, 3), st.sampled_from(FREQUENCY_SPIKES)),
    ), max_size=3),
    "nan_runs": st.lists(st.tuples(st.sampled_from(["f", "VM", "VA", "IM", "IA"]), st.integers(0, 1500),
                                   st.integers(1, 40)), max_size=3),
    "jitter": st.sampled_from([0.0, 0.0, 0.05, 0.2]),
    "unit": st.sampled_from(list(UNIT_MISTAKES)),
    "seed": st.integers(0, 2**16),
})


def damaged(columns, d):
    """The clean columns with the damage ``d`` and the [measurement] line of its unit mistake."""
    rng = np.random.default_rng(d["seed"])
    cols = {k: v.copy() for k, v in columns.items()}
    for name, start, length, x in d["spikes"]:
        part = cols[name][start:start + length]
        if name in ("VA", "IA"):
            part += x
        elif name == "f":
            part[:] = x
        else:
            part *= x
    for name, start, length in d["nan_runs"]:
        cols[name][start:start + length] = np.nan
    dt = float(np.median(np.diff(cols["t"])))
    cols["t"] = cols["t"] + d["jitter"] * dt * rng.uniform(-1, 1, cols["t"].size)
    factors, extra = UNIT_MISTAKES[d["unit"]]
    for name, k in factors.items():
        cols[name] = cols[name] + 180.0 if k == "flip" else cols[name] * k
    return cols, extra


def is_damaged(d) -> bool:
    return bool(d["spikes"] or d["nan_runs"] or d["jitter"] or d["unit"] != "none")


QUALITY_KEYS = ("rows_without_time", "out_of_order_rows", "duplicate_timestamps_dropped",
                "non_uniform_steps", "nan_samples", "bridged_gaps", "edge_rows_trimmed",
                "frequency_all_nan", "frequency_derived_in_long_gaps_s")


def noted(quality) -> list[str]:
    """The data_quality entries that report damage (empty for a clean recording)."""
    out = [k for k in QUALITY_KEYS if quality.get(k)]
    return out + [f"screening.{k}" for k in quality["screening"] if k != "masked_samples"]


class Files:
    """A fresh file name per example (the readers cache files by path and mtime)."""

    def __init__(self, root):
        self.root, self.count = root, itertools.count()

    def write(self, cols, extra=""):
        k = next(self.count)
        jd.write_csv(self.root / f"pmu{k}.csv", cols)
        config = run_toml(f"pmu{k}.csv", extra='on_long_gap = "error"\n' + extra)
        (self.root / f"c{k}.toml").write_text(config)
        return self.root / f"pmu{k}.csv", self.root / f"c{k}.toml"


@pytest.fixture(scope="module")
def clean(pmu25, tmp_path_factory):
    spec = jd.MeasurementSpec(file=(), columns=COLS, v_base_kv=400.0)
    return jd.phasor_columns(pmu25.recording, spec), Files(tmp_path_factory.mktemp("fuzz"))


@pytest.mark.slow
@settings(max_examples=100, deadline=None, derandomize=True, database=None, phases=PHASES,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(d=damage)
def test_readers_end_in_an_error_or_noted_clean_segments(clean, d):
    columns, files = clean
    cols, extra = damaged(columns, d)
    csv, toml = files.write(cols, extra)
    try:
        g = jd.load_config(toml).generators[0]
        segments, quality = jd.read_measurement(g.measurement, g.plant.machine)
    except jd.InputError as err:
        assert "\n" not in str(err) and (csv.name in str(err) or toml.name in str(err)), str(err)
        event(f"InputError ({d['unit']})")
        return
    event(f"read ({d['unit']})")
    assert d["unit"] == "none", f"unit mistake {d['unit']!r} passed the readers"
    for _, rec in segments:
        for x in (rec.v_mag_pu, rec.v_ang_rad, rec.i_mag_pu, rec.i_ang_rad):
            assert np.all(np.isfinite(np.asarray(x)))
    if d["spikes"] or d["nan_runs"] or d["jitter"]:
        assert noted(quality), f"damage {d} left no data_quality note"


@pytest.mark.slow
def test_estimator_runs_end_in_one_of_two_outcomes(clean):
    """Through `jaxdse run` (readers, estimator, identification, verdict): exit 2 with one
    line, or exit 0 with a finite H, the damage noted or flagged, and no silent wrong H."""
    columns, files = clean
    counts = Counter()

    def run(cols, extra=""):
        csv, toml = files.write(cols, extra)
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            rc = main(["run", str(toml), "--out", str(files.root / "out")])
        summary = json.loads((files.root / "out" / "summary.json").read_text()) if rc == 0 else None
        return rc, err.getvalue(), csv, summary

    rc, err, _, s = run(columns)
    assert rc == 0, err
    h_clean = s["recordings"][0]["H_s"]

    @settings(max_examples=25, deadline=None, derandomize=True, database=None, phases=PHASES,
              suppress_health_check=[HealthCheck.too_slow])
    @given(d=damage)
    def check(d):
        rc, err, csv, summary = run(*damaged(columns, d))
        if rc == 2:
            lines = [ln for ln in err.splitlines() if ln.strip()]
            assert len(lines) == 1 and lines[0].startswith("jaxdse: error: "), err
            assert csv.name in lines[0] or ".toml" in lines[0], lines[0]
            event("exit 2: InputError")
            counts["error"] += 1
            return
        assert rc == 0, f"exit status {rc}: {err}"
        event("exit 0: reached the estimator")
        counts["estimator"] += 1
        entries = summary["recordings"]
        assert len(entries) == 1  # on_long_gap = "error": no split, one padded length
        e = entries[0]
        h, verdict = e["H_s"], e["verdict"]
        assert h is not None and np.isfinite(h), f"H = {h} ({verdict})"
        rel = abs(h / h_clean - 1)
        flagged = verdict != "identified"
        assert rel <= H_WRONG or flagged, f"silent wrong H {h:.4g} s (clean {h_clean:.4g} s) for {d}"
        if is_damaged(d):
            assert noted(e["data_quality"]) or flagged, f"damage {d} neither noted nor flagged"
        event(f"H error {'<= 2 %' if rel <= 0.02 else '<= 10 %' if rel <= H_WRONG else '> 10 %, flagged'}")
        counts["flagged" if flagged else "identified"] += 1

    check()
    print(dict(counts))
    assert counts["estimator"] >= 5 and counts["error"] >= 5, counts
