"""Inputs as real exports come (issue 32, item 7): columns nobody maps are ignored whatever they
hold and listed; a frequency channel logged as a deviation from nominal is declared with its
unit; a config without plant data names every missing section at once; the hints answer the
config they were given (current_direction already "into_plant", a 12-hour clock)."""

from pathlib import Path

import numpy as np
import pytest

import jaxdse as jd
from jaxdse._io.config import parse_config
from jaxdse._io.measurement import _time_format_hint

COLUMNS = {"time": "t", "frequency": "f", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM", "i_ang": "IA"}
SPEC = jd.MeasurementSpec(file=(), columns=COLUMNS, v_base_kv=400.0, min_segment_s=10.0)


@pytest.fixture(scope="module")
def cols():
    """A short clean recording (20 s at 25 frames/s) as CSV columns."""
    sim = jd.simulate(jd.Plant(), jd.Scenario(duration_s=20.0, frame_rate_hz=25.0, seed=2))
    return jd.phasor_columns(sim.recording, SPEC)


def write(path: Path, cols: dict, extra: dict | None = None) -> Path:
    """``cols`` as CSV, plus text columns ``extra`` (name -> cell text, or a list of cells)."""
    names = list(cols) + list(extra or {})
    n = len(next(iter(cols.values())))
    lines = [",".join(names)]
    for k in range(n):
        cells = [f"{cols[c][k]:.10g}" for c in cols]
        cells += [v if isinstance(v, str) else v[k] for v in (extra or {}).values()]
        lines.append(",".join(cells))
    path.write_text("\n".join(lines) + "\n")
    return path


def read(path: Path, **spec):
    s = jd.MeasurementSpec(**{**SPEC.__dict__, "file": (str(path),), **spec})
    return jd.read_measurement(s, jd.Machine())


# --- unmapped columns ---------------------------------------------------------------------------

@pytest.mark.slow
def test_unmapped_text_columns_are_ignored_and_listed(tmp_path, cols):
    """A PMU STAT column of '0x0000' text and a status column of words, neither mapped: the run
    reads as without them and lists them (today's abort: "value 'OK' is not a number")."""
    path = write(tmp_path / "pmu.csv", cols, {"STAT": "0x0000", "Status": "OK", "Station": "SUB 1"})
    segs, q = read(path)
    ref, _ = read(write(tmp_path / "ref.csv", cols))
    np.testing.assert_array_equal(segs[0][1].v_mag_pu, ref[0][1].v_mag_pu)
    assert q["unmapped_columns"] == ["STAT", "Status", "Station"]
    assert read(write(tmp_path / "plain.csv", cols))[1]["unmapped_columns"] == []


def test_a_mapped_text_column_is_refused_with_its_row(tmp_path, cols):
    status = ["OK"] * len(cols["t"])
    path = write(tmp_path / "pmu.csv", {k: v for k, v in cols.items() if k != "f"}, {"f": status})
    with pytest.raises(jd.InputError, match=r"pmu.csv, column 'f', row 2: value 'OK' is not a number"):
        read(path)
    segs, q = read(path, columns={k: v for k, v in COLUMNS.items() if k != "frequency"})
    assert q["unmapped_columns"] == ["f"] and segs[0][1].f_hz is None


def test_hexadecimal_stat_words_are_read_as_numbers(tmp_path, cols):
    words = ["0x8000" if 100 <= k < 103 else "0x0000" for k in range(len(cols["t"]))]
    path = write(tmp_path / "pmu.csv", cols, {"STAT": words})
    tab = jd.load_table(path)
    assert tab.columns["STAT"][100] == 0x8000 and tab.columns["STAT"][0] == 0
    _, q = read(path, columns=dict(COLUMNS, stat="STAT"))
    assert q["screening"]["stat_invalid"]["STAT"] == {"samples": 3, "first_row": 102}
    assert q["unmapped_columns"] == []


def test_unreadable_column_of_one_of_several_files_names_that_file(tmp_path):
    (tmp_path / "a.csv").write_text("t,x\n0,1\n1,2\n")
    (tmp_path / "b.csv").write_text("t,y\n0,1\n1,n/a?\n")
    tab = jd.load_table([tmp_path / "a.csv", tmp_path / "b.csv"])
    np.testing.assert_array_equal(tab.column("a/x", "v_mag"), [1, 2])
    with pytest.raises(jd.InputError, match=r"b.csv, column 'y', row 3: value 'n/a\?' is not a number"):
        tab.column("b/y", "v_mag")


# --- the frequency as a deviation ------------------------------------------------------------------

@pytest.mark.parametrize("kind, unit, convert", [
    ("absolute", "Hz", lambda f: f),
    ("absolute", "pu", lambda f: f / 50.0),
    ("deviation", "Hz", lambda f: f - 50.0),
    ("deviation", "mHz", lambda f: (f - 50.0) * 1e3),
    ("deviation", "pu", lambda f: f / 50.0 - 1.0),
])
def test_frequency_kinds_and_units(tmp_path, cols, kind, unit, convert):
    path = write(tmp_path / "pmu.csv", dict(cols, f=convert(cols["f"])))
    segs, q = read(path, frequency_kind=kind, frequency_unit=unit)
    np.testing.assert_allclose(segs[0][1].f_hz, cols["f"], rtol=0, atol=1e-6)
    assert q["units"]["frequency"] == (unit if kind == "absolute" else f"deviation from 50 Hz in {unit}")


@pytest.mark.parametrize("kind, unit, convert, hint", [
    ("absolute", "Hz", lambda f: (f - 50.0) * 1e3, 'frequency_kind = "deviation" and frequency_unit = "mHz"'),
    ("absolute", "Hz", lambda f: f - 50.0, 'frequency_kind = "deviation" and frequency_unit = "Hz"'),
    ("deviation", "Hz", lambda f: f, "leave measurement.frequency_kind out"),
    ("absolute", "Hz", lambda f: f / 50.0, "frequency itself in pu"),
])
def test_a_wrong_frequency_declaration_names_the_right_one(tmp_path, cols, kind, unit, convert, hint):
    path = write(tmp_path / "pmu.csv", dict(cols, f=convert(cols["f"])))
    with pytest.raises(jd.InputError, match="pmu.csv, column 'f': median frequency") as err:
        read(path, frequency_kind=kind, frequency_unit=unit)
    assert hint in str(err.value)


def test_a_deviation_in_mhz_read_as_hz_that_averages_to_nominal_is_refused(tmp_path, cols):
    """Deviations of +-20 mHz around 0 read as Hz: the median lies at nominal, the spread not."""
    dev = 20.0 * np.sin(np.arange(len(cols["t"])) / 5.0)
    path = write(tmp_path / "pmu.csv", dict(cols, f=dev))
    with pytest.raises(jd.InputError, match=r"column 'f': the frequency strays 1\d.\d* Hz from its median "
                       r".*a deviation in mHz\? set measurement.frequency_unit = \"mHz\""):
        read(path, frequency_kind="deviation")
    segs, _ = read(path, frequency_kind="deviation", frequency_unit="mHz")
    np.testing.assert_allclose(segs[0][1].f_hz, 50.0 + dev * 1e-3)


def plant_config(**measurement) -> dict:
    return {"plant_defaults": "paper",
            "measurement": {"file": "pmu.csv", "columns": dict(COLUMNS), "v_base_kv": 400.0, **measurement}}


def test_frequency_keys_in_the_config(tmp_path):
    g = parse_config(plant_config(frequency_kind="deviation", frequency_unit="mhz"), tmp_path / "c.toml")
    assert (g.generators[0].measurement.frequency_kind, g.generators[0].measurement.frequency_unit) == \
        ("deviation", "mhz")
    with pytest.raises(jd.InputError, match="key 'measurement.frequency_kind': must be one of absolute, "
                       "deviation, got 'delta'"):
        parse_config(plant_config(frequency_kind="delta"), tmp_path / "c.toml")
    with pytest.raises(jd.InputError, match="key 'measurement.frequency_unit': unknown unit 'kHz'; use one "
                       "of Hz, mHz, pu"):
        parse_config(plant_config(frequency_unit="kHz"), tmp_path / "c.toml")


# --- every missing plant section in one message ----------------------------------------------------

def test_every_missing_plant_section_in_one_message(tmp_path):
    m = {"file": "pmu.csv", "columns": dict(COLUMNS), "v_base_kv": 400.0}
    with pytest.raises(jd.InputError) as err:
        parse_config({"measurement": m}, tmp_path / "c.toml")
    msg = str(err.value)
    assert "no [line], [transformer], [aux], [machine] and [governor] sections, which a PMU at location = " \
           "'substation' needs" in msg and "s_rated_mva, v_rated_kv, f_nominal_hz" in msg
    assert "plant_defaults = \"paper\"" in msg and "\n" not in msg
    with pytest.raises(jd.InputError) as err:   # a [machine] without its rating, no [governor]
        parse_config({"measurement": dict(m, location="terminal", v_base_kv=21.0), "machine": {"xd_pu": 1.8}},
                     tmp_path / "c.toml")
    assert "no [governor] section" in str(err.value)
    assert "no machine.s_rated_mva, machine.v_rated_kv and machine.f_nominal_hz" in str(err.value)
    with pytest.raises(jd.InputError, match="key 'governor': no \\[governor\\] section"):
        parse_config({"measurement": dict(m, location="terminal", v_base_kv=21.0),
                      "machine": {"s_rated_mva": 1100.0, "v_rated_kv": 21.0, "f_nominal_hz": 50.0}},
                     tmp_path / "c.toml")


# --- hints right for the config they answer ----------------------------------------------------------

def test_negative_power_hint_knows_the_declared_direction(tmp_path, cols):
    reversed_ = dict(cols, IA=cols["IA"] + 180.0)
    with pytest.raises(jd.InputError) as err:
        read(write(tmp_path / "a.csv", reversed_))
    assert 'set measurement.current_direction = "into_plant"' in str(err.value)
    with pytest.raises(jd.InputError) as err:
        read(write(tmp_path / "b.csv", cols), current_direction="into_plant")
    msg = str(err.value)
    assert 'current_direction = "into_plant" already set' in msg and "CT polarity" in msg
    assert 'set measurement.current_direction = "into_plant"' not in msg


@pytest.mark.parametrize("cell, time_format, hint", [
    ("03/01/2024 11:00:00.040 AM", None, "'%m/%d/%Y %I:%M:%S.%f %p'"),
    ("03/01/2024 1:00:00 PM", None, "'%m/%d/%Y %I:%M:%S %p'"),
    ("2024-03-01 11:00:00.04 pm", None, "'%Y-%m-%d %I:%M:%S.%f %p'"),
    ("03/01/2024 11:00:00.040", None, "'%m/%d/%Y %H:%M:%S.%f'"),
    ("03/01/2024 11:00:00.040 AM", "%m/%d/%Y %H:%M:%S.%f", "time_format = '%m/%d/%Y %I:%M:%S.%f %p'"),
])
def test_time_format_hint_fits_the_clock(cell, time_format, hint):
    text = _time_format_hint(cell, time_format)
    assert hint in text
    if "M" in cell[-2:].upper() and time_format is None:
        assert "%H:" not in text


def test_a_twelve_hour_clock_reads_with_its_format(tmp_path, cols):
    from datetime import datetime, timedelta

    start = datetime(2024, 3, 1, 12, 59, 50)   # across noon: 12:59:59 PM, 01:00:00 PM
    stamps = [(start + timedelta(seconds=float(t))).strftime("%m/%d/%Y %I:%M:%S.%f %p") for t in cols["t"]]
    path = write(tmp_path / "pmu.csv", {k: v for k, v in cols.items() if k != "t"}, {"t": stamps})
    with pytest.raises(jd.InputError, match="%I:%M:%S.%f %p"):
        read(path)
    segs, q = read(path, time_format="%m/%d/%Y %I:%M:%S.%f %p")
    np.testing.assert_allclose(segs[0][1].t_s, cols["t"] - cols["t"][0], atol=1e-6)
