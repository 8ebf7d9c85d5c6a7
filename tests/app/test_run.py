"""`jaxdse run` end to end: example configs, and every kind of bad input (handled or exit 2)."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from builders import COLS, run_toml

import jaxdse as jd
from jaxdse._app.cli import main

ROOT = Path(__file__).resolve().parents[2]


def config_text(extra: str = "") -> str:
    """The run config of these tests: kV (ph-ph) and A, figures off."""
    return run_toml(extra=f'voltage_unit = "kV_LL"\ncurrent_unit = "A"\n{extra}', output="figures = false")


@pytest.fixture(scope="module")
def base_columns(pmu25):
    spec = jd.MeasurementSpec(file=(), columns=COLS, v_base_kv=400.0)
    return jd.phasor_columns(pmu25.recording, spec)


def run(tmp_path, columns, extra="", config=None, capsys=None):
    jd.write_csv(tmp_path / "pmu.csv", columns)
    (tmp_path / "c.toml").write_text(config if config is not None else config_text(extra))
    rc = main(["run", str(tmp_path / "c.toml"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err if capsys else ""
    summary = (json.loads((tmp_path / "out" / "summary.json").read_text())
               if rc == 0 else None)
    return rc, err, summary


def one_line_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.startswith("jaxdse: error:")]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def assert_clean_estimates(summary):
    for e in summary["recordings"]:
        assert e["online"]["flags"]["finite"]
        for k in ("a1", "a2", "H_s", "D"):
            assert e[k] is not None and np.isfinite(e[k])


def test_clean_csv_runs_and_reports_quality(tmp_path, base_columns, capsys):
    rc, err, s = run(tmp_path, base_columns, capsys=capsys)
    assert rc == 0, err
    dq = s["recordings"][0]["data_quality"]
    assert dq["rows_read"] == 1501 and dq["bridged_gaps"] == [] and not dq["resampled"]
    assert_clean_estimates(s)
    assert (tmp_path / "out" / "estimates_generator.csv").exists()


def test_missing_column(tmp_path, base_columns, capsys):
    cols = {k: v for k, v in base_columns.items() if k != "IM"}
    rc, err, _ = run(tmp_path, cols, capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and "pmu.csv" in line and "'IM'" in line


def test_wrong_unit_string(tmp_path, base_columns, capsys):
    rc, err, _ = run(tmp_path, base_columns, config=config_text("").replace('"kV_LL"', '"kW"'),
                     capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and "c.toml" in line and "measurement.voltage_unit" in line and "'kW'" in line


def test_unit_off_by_1000_is_caught(tmp_path, base_columns, capsys):
    rc, err, _ = run(tmp_path, base_columns, config=config_text("").replace('"kV_LL"', '"V_LL"'),
                     capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and "pmu.csv" in line and "'VM'" in line and "voltage_unit" in line


def test_all_nan_channel(tmp_path, base_columns, capsys):
    cols = dict(base_columns, VA=np.full_like(base_columns["VA"], np.nan))
    rc, err, _ = run(tmp_path, cols, capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and "column 'VA'" in line and "row 2-1502" in line and "NaN" in line


def test_all_nan_frequency_falls_back_to_the_angle(tmp_path, base_columns, capsys):
    cols = dict(base_columns, f=np.full_like(base_columns["f"], np.nan))
    rc, err, s = run(tmp_path, cols, capsys=capsys)
    assert rc == 0, err
    dq = s["recordings"][0]["data_quality"]
    assert dq["frequency_all_nan"] and dq["frequency"] == "derived from the voltage angle"
    assert_clean_estimates(s)


def test_short_nan_gap_is_bridged_and_reported(tmp_path, base_columns, capsys):
    cols = {k: v.copy() for k, v in base_columns.items()}
    cols["IM"][500:505] = np.nan  # 0.2 s
    rc, err, s = run(tmp_path, cols, capsys=capsys)
    assert rc == 0, err
    gaps = s["recordings"][0]["data_quality"]["bridged_gaps"]
    assert len(gaps) == 1 and gaps[0]["length_s"] == pytest.approx(0.2) and gaps[0]["row"] == 502
    assert_clean_estimates(s)


@pytest.fixture(scope="module")
def long_columns(ambient):
    """52 s at 50 frames/s (2600 rows): with 2 s cut out of the middle, two parts of 1250
    samples, the shape (2 x 1280 padded) that the runner's test compiles too."""
    spec = jd.MeasurementSpec(file=(), columns=COLS, v_base_kv=400.0)
    return {k: v[:2600] for k, v in jd.phasor_columns(ambient.recording, spec).items()}


@pytest.mark.slow
def test_two_second_gap_splits_the_recording(tmp_path, long_columns, capsys):
    cols = {k: np.delete(v, np.s_[1250:1350]) for k, v in long_columns.items()}  # 2 s missing
    rc, err, s = run(tmp_path, cols, capsys=capsys)
    assert rc == 0, err
    names = [e["name"] for e in s["recordings"]]
    assert names == ["generator_part1", "generator_part2"]
    dq = s["recordings"][0]["data_quality"]
    assert dq["split_at_gaps"][0]["length_s"] == pytest.approx(2.0)
    assert_clean_estimates(s)


def test_two_second_gap_with_on_long_gap_error(tmp_path, base_columns, capsys):
    cols = {k: v.copy() for k, v in base_columns.items()}
    cols["VM"][700:750] = np.nan
    rc, err, _ = run(tmp_path, cols, extra='on_long_gap = "error"', capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and "column 'VM'" in line and "row 702" in line and "max_gap_s" in line


def test_duplicated_and_late_timestamps(tmp_path, base_columns, capsys):
    """40 frames sent again 5 rows later and 12 frames 3 rows late (0.8 % of the steps go back):
    sorted, the repeats dropped, said on the console, and the estimate is the clean one."""
    rc, _, clean = run(tmp_path / "a", base_columns, capsys=capsys) if (tmp_path / "a").mkdir() is None \
        else None
    rng = np.random.default_rng(0)
    idx = list(range(1501))
    for p in np.linspace(100, 1400, 12).astype(int):
        idx.insert(p + 3, idx.pop(p))
    for p in sorted(rng.choice(np.arange(50, 1450), 40, replace=False), reverse=True):
        idx.insert(p + 6, idx[p])
    cols = {k: v[np.array(idx)] for k, v in base_columns.items()}
    (tmp_path / "b").mkdir()
    rc, err, s = run(tmp_path / "b", cols, capsys=capsys)
    assert rc == 0, err
    dq = s["recordings"][0]["data_quality"]
    assert dq["duplicate_timestamps_dropped"] == 40 and dq["out_of_order_rows"] == 12
    assert "12 row(s) out of time order sorted" in err and "40 row(s) with a repeated time dropped" in err
    e0, e1 = clean["recordings"][0], s["recordings"][0]
    assert e1["a2"] == pytest.approx(e0["a2"], rel=1e-9) and e1["H_s"] == pytest.approx(e0["H_s"], rel=1e-9)


def test_wrapped_and_unwrapped_angles_give_the_same_result(tmp_path, base_columns, capsys):
    cols = dict(base_columns, VA=base_columns["VA"] + 360.0 * (np.arange(1501) // 100),
                IA=base_columns["IA"] + 360.0 * (np.arange(1501) // 100))
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    _, _, wrapped = run(tmp_path / "a", base_columns, capsys=capsys)
    rc, err, shifted = run(tmp_path / "b", cols, capsys=capsys)
    assert rc == 0, err
    assert wrapped["recordings"][0]["data_quality"]["angle_wraps_unwrapped"] > 0
    assert shifted["recordings"][0]["a2"] == pytest.approx(wrapped["recordings"][0]["a2"], rel=1e-6)


def test_zero_current_is_reported_offline(tmp_path, base_columns, capsys):
    cols = dict(base_columns, IM=np.zeros_like(base_columns["IM"]))
    rc, err, s = run(tmp_path, cols, capsys=capsys)
    assert rc == 0, err
    e = s["recordings"][0]
    assert e["data_quality"]["median_current_pu_machine"] == 0.0
    o = e["online"]
    assert not o["flags"]["online"] and not o["converged"] and e["verdict"] == "failed"
    assert "not online" in o["not_converged_reason"] and o["convergence_time_s"] is None
    assert "offline" in e["reasons"]
    assert_clean_estimates(s)


def test_malformed_toml(tmp_path, base_columns, capsys):
    rc, err, _ = run(tmp_path, base_columns, config="[measurement\nfile = 1", capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and "c.toml" in line and "malformed TOML" in line and "line 1" in line


def test_unknown_key(tmp_path, base_columns, capsys):
    rc, err, _ = run(tmp_path, base_columns, config=config_text("v_base_kw = 3"),
                     capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and "key 'measurement.v_base_kw'" in line and "v_base_kv" in line


@pytest.mark.parametrize("section, key, value, words", [
    ("line", "x_pu", -0.1, "must be >= 0"),
    ("transformer", "tap_position", 80, "tap"),
    ("machine", "xd1_pu", "'0.3'", "must be a number"),
    ("observer", "gamma1", 0, "must be > 0"),
])
def test_impossible_values_name_the_key(tmp_path, base_columns, capsys, section, key, value, words):
    cfg = config_text("") + f"\n[{section}]\n{key} = {value}\n"
    rc, err, _ = run(tmp_path, base_columns, config=cfg, capsys=capsys)
    line = one_line_error(err)
    assert rc == 2 and f"key '{section}.{key}'" in line and words in line


def test_file_that_does_not_exist(tmp_path, capsys):
    rc = main(["run", str(tmp_path / "nope.toml")])
    line = one_line_error(capsys.readouterr().err)
    assert rc == 2 and "nope.toml" in line and "does not exist" in line
    (tmp_path / "c.toml").write_text(config_text(""))
    rc = main(["run", str(tmp_path / "c.toml")])
    line = one_line_error(capsys.readouterr().err)
    assert rc == 2 and "pmu.csv" in line and "does not exist" in line


@pytest.mark.slow
@pytest.mark.parametrize("name", ["csv_positive_sequence", "csv_three_phase", "comtrade"])
def test_shipped_example_configs_run(tmp_path, name, capsys):
    shutil.copytree(ROOT / "examples", tmp_path / "examples")
    rc = main(["run", str(tmp_path / "examples" / f"{name}.toml"), "--out", str(tmp_path / "o")])
    out = capsys.readouterr()
    assert rc == 0, out.err
    s = json.loads((tmp_path / "o" / "summary.json").read_text())
    e = s["recordings"][0]
    assert e["verdict"] == "identified" and abs(e["a2_error_percent"]) < 3
    assert e["smape_percent"]["P_t"] < 1 and e["smape_percent"]["I_t"] < 1
    for fig in ("convergence", "x2", "playback"):
        assert (tmp_path / "o" / f"{fig}_{e['name']}.png").exists()


@pytest.mark.slow
def test_isone_config_estimates_all_three_generators(isone_run):
    """`jaxdse run examples/isone_mat.toml` (the session's run, conftest ``isone_run``;
    test_isone checks its numbers against the checked-in results)."""
    rc, err, s = isone_run
    assert rc == 0, err
    assert [e["generator"] for e in s["recordings"]] == ["sub6_gen1", "sub7_gen2", "sub8_gen1"]
    for e in s["recordings"]:
        assert e["online"]["flags"]["finite"] and e["a2"] is not None and e["H_s"] is not None
        assert e["smape_percent"]["P_t"] is not None and e["smape_percent"]["I_t"] is not None


def test_run_help_teaches(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    out = capsys.readouterr().out
    assert "summary.json" in out and "example" in out and "Exit status" in out
