"""Readers and unit handling: every format and every unit/direction option, by round trip."""

from datetime import UTC, datetime

import numpy as np
import pytest
import scipy.io

import jaxdse as jd

COLS = {"time": "t", "frequency": "f", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM", "i_ang": "IA"}


def phasors(rec):
    v = np.asarray(rec.v_mag_pu) * np.exp(1j * np.asarray(rec.v_ang_rad))
    i = np.asarray(rec.i_mag_pu) * np.exp(1j * np.asarray(rec.i_ang_rad))
    return v, i


def assert_same(rec, back, atol=1e-9, rel=False):
    v0, i0 = phasors(rec)
    v1, i1 = phasors(back)
    scale_v, scale_i = (np.abs(v0), np.abs(i0)) if rel else (1.0, 1.0)
    assert np.max(np.abs(v1 - v0) / scale_v) < atol
    assert np.max(np.abs(i1 - i0) / scale_i) < atol
    np.testing.assert_allclose(np.asarray(back.t_s), np.asarray(rec.t_s) - float(rec.t_s[0]),
                               atol=1e-9)
    if rec.f_hz is not None and back.f_hz is not None:
        np.testing.assert_allclose(np.asarray(back.f_hz), np.asarray(rec.f_hz), atol=1e-9)


@pytest.fixture(scope="module")
def short(pmu25):
    return pmu25


@pytest.mark.slow
@pytest.mark.parametrize("vu, cu, au, direction, tu", [
    ("kV_LL", "A", "deg", "out_of_plant", "s"),
    ("kV_LN", "kA", "rad", "into_plant", "ms"),
    ("V_LL", "A", "deg", "into_plant", "s"),
    ("V_LN", "kA", "deg", "out_of_plant", "s"),
    ("pu", "pu", "rad", "out_of_plant", "s"),
])
def test_csv_round_trip_in_user_units(short, tmp_path, vu, cu, au, direction, tu):
    spec = jd.MeasurementSpec(file=(str(tmp_path / "x.csv"),), columns=COLS, voltage_unit=vu,
                              current_unit=cu, angle_unit=au, current_direction=direction,
                              time_unit=tu, v_base_kv=400.0, min_segment_s=10)
    cols = jd.phasor_columns(short.recording, spec)
    jd.write_csv(tmp_path / "x.csv", cols)
    (t0, back), = jd.read_measurement(spec, jd.Machine())[0]
    assert_same(short.recording, back)
    k = np.pi / 180 if au == "deg" else 1.0
    p_sign = np.sign(np.median(np.cos(k * (cols["IA"] - cols["VA"]))))
    assert p_sign == (-1 if direction == "into_plant" else 1)  # the file holds that direction


def test_csv_three_phase_iso_timestamps_keep_positive_sequence(short, tmp_path):
    names = {"time": "ts"} | {f"{q}_{p}_{c}": f"{q.upper()}{p}_{c}" for q in "vi" for p in "abc"
                              for c in ("mag", "ang")}
    spec = jd.MeasurementSpec(file=(str(tmp_path / "x.csv.gz"),), columns=names, voltage_unit="kV_LN",
                              current_unit="kA", time_unit="iso", v_base_kv=400.0, min_segment_s=10,
                              current_direction="into_plant")
    cols = jd.phasor_columns(short.recording, spec, short.v_abc, short.i_abc)
    jd.write_csv(tmp_path / "x.csv.gz", cols, time_column="ts",
                 start=datetime(2024, 1, 1, tzinfo=UTC))
    segs, q = jd.read_measurement(spec, jd.Machine())
    assert q["start_time"].startswith("2024-01-01T00:00:00")
    # Timestamps carry microseconds: the grid is exact to 1e-6 s, phasors to 1e-9 pu.
    rec = jd.Recording(t_s=short.recording.t_s, v_mag_pu=short.recording.v_mag_pu,
                       v_ang_rad=short.recording.v_ang_rad, i_mag_pu=short.recording.i_mag_pu,
                       i_ang_rad=short.recording.i_ang_rad)
    assert_same(rec, segs[0][1], atol=1e-9)
    assert q["frequency"] == "derived from the voltage angle"


@pytest.mark.parametrize("data_format", ["ASCII", "BINARY32"])
def test_comtrade_round_trip(short, tmp_path, data_format):
    spec = jd.MeasurementSpec(file=(str(tmp_path / "r.cfg"),), columns=COLS | {"time": "time"},
                              voltage_unit="kV_LN", current_unit="A", v_base_kv=400.0,
                              min_segment_s=10)
    cols = jd.phasor_columns(short.recording, spec)
    t = cols.pop("time")
    jd.write_comtrade(tmp_path / "r.cfg", t, cols, {"VM": "kV", "IM": "A"}, data_format=data_format)
    segs, q = jd.read_measurement(spec, jd.Machine())
    # int32 samples: ±180 degrees quantise to 7e-10 rad, i.e. 1e-9 relative to each phasor.
    assert_same(short.recording, segs[0][1], atol=1e-9, rel=True)
    table = jd.load_table(tmp_path / "r.cfg")
    assert table.units["VM"] == "kV"


def test_comtrade_secondary_values_are_scaled_to_primary(short, tmp_path):
    spec = jd.MeasurementSpec(file=(str(tmp_path / "s.cfg"),), columns=COLS | {"time": "time"},
                              voltage_unit="kV_LN", current_unit="A", v_base_kv=400.0, min_segment_s=10)
    cols = jd.phasor_columns(short.recording, spec)
    t = cols.pop("time")
    cols["IM"] = cols["IM"] / 400.0  # a 2000:5 CT: secondary amperes
    jd.write_comtrade(tmp_path / "s.cfg", t, cols, {})
    cfg = (tmp_path / "s.cfg").read_text().splitlines()
    k = next(n for n, line in enumerate(cfg) if ",IM," in line)
    cfg[k] = cfg[k][: -len("1,1,P")] + "2000,5,S"
    (tmp_path / "s.cfg").write_text("\r\n".join(cfg) + "\r\n")
    segs, _ = jd.read_measurement(spec, jd.Machine())
    assert_same(short.recording, segs[0][1], atol=1e-9, rel=True)


def test_mat_header_table_layout(short, tmp_path):
    spec = jd.MeasurementSpec(file=(str(tmp_path / "m.mat"),),
                              columns={"time": "Time/T", "frequency": "G1/F", "v_mag": "G1/VM",
                                       "v_ang": "G1/VA", "i_mag": "G1/IM", "i_ang": "G1/IA"},
                              voltage_unit="kV_LN", current_unit="A", v_base_kv=400.0, min_segment_s=10)
    cols = jd.phasor_columns(short.recording, spec)
    num = np.stack(list(cols.values()), axis=1)
    txt = np.empty((3, num.shape[1]), dtype=object)
    for c, name in enumerate(cols):
        label, qty = name.split("/")
        txt[:, c] = [label, qty, {"F": "HZ", "VM": "KV", "IM": "AMP"}.get(qty, "DEG")]
    scipy.io.savemat(tmp_path / "m.mat", {"num": num, "txt": txt})
    segs, _ = jd.read_measurement(spec, jd.Machine())
    assert_same(short.recording, segs[0][1])
    assert jd.load_table(tmp_path / "m.mat").units["G1/VM"] == "KV"


def test_mat_one_vector_per_channel(short, tmp_path):
    spec = jd.MeasurementSpec(file=(str(tmp_path / "v.mat"),), columns=COLS, voltage_unit="pu",
                              current_unit="pu", angle_unit="rad", min_segment_s=10)
    cols = jd.phasor_columns(short.recording, spec)
    scipy.io.savemat(tmp_path / "v.mat", {k: v[:, None] for k, v in cols.items()})
    segs, _ = jd.read_measurement(spec, jd.Machine())
    assert_same(short.recording, segs[0][1])


def test_whitespace_text_in_several_files(short, tmp_path):
    """The NASPI contest layout: quoted headers, space-aligned, magnitude and angle in two files."""
    rec = short.recording
    t = np.asarray(rec.t_s)
    def deg(x):
        return np.degrees(np.angle(np.exp(1j * np.asarray(x))))

    for fname, a, b in (("Mag.txt", rec.v_mag_pu, rec.i_mag_pu),
                        ("Ang.txt", deg(rec.v_ang_rad), deg(rec.i_ang_rad))):
        body = [f"{x:.17g}  {y:.17g}   {z:.17g}" for x, y, z in zip(t, np.asarray(a), np.asarray(b))]
        (tmp_path / fname).write_text("'Time' 'bus 1|A 20.0' 'br 1|A 20.0|2|B'\n" + "\n".join(body) + "\n")
    spec = jd.MeasurementSpec(file=(str(tmp_path / "Mag.txt"), str(tmp_path / "Ang.txt")),
                              columns={"time": "Mag/Time", "v_mag": "Mag/bus 1|A 20.0",
                                       "v_ang": "Ang/bus 1|A 20.0", "i_mag": "Mag/br 1|A 20.0|2|B",
                                       "i_ang": "Ang/br 1|A 20.0|2|B"},
                              voltage_unit="pu", current_unit="pu", location="terminal", min_segment_s=10,
                              csv_options=jd.CsvOptions(delimiter="whitespace", quotechar="'"))
    segs, _ = jd.read_measurement(spec, jd.Machine())
    assert_same(rec, segs[0][1])


def test_csv_nan_words_and_bad_numbers(tmp_path):
    (tmp_path / "a.csv").write_text("t,x\n0,1\n1,NaN\n2,\n3,n/a?\n")
    tab = jd.load_table(tmp_path / "a.csv")  # a column is refused only when it is asked for
    with pytest.raises(jd.InputError, match=r"a.csv, column 'x', row 5: value 'n/a\?' is not a number"):
        tab.column("x", "v_mag")
    with pytest.raises(jd.InputError, match=r"a.csv, column 'x', row 5: value 'n/a\?' is not a number"):
        tab.column(1, "v_mag")
    np.testing.assert_array_equal(tab.column("t", "time"), [0, 1, 2, 3])
    (tmp_path / "b.csv").write_text("t,x\n0,1\n1,NaN\n2,\n")
    tab = jd.load_table(tmp_path / "b.csv")
    assert np.isnan(tab.columns["x"][1:]).all()


def test_repeated_header_names_are_numbered_and_the_bare_name_refused(tmp_path):
    (tmp_path / "d.csv").write_text("t,x,x\n0,1,2\n1,3,4\n")
    tab = jd.load_table(tmp_path / "d.csv")
    np.testing.assert_array_equal(tab.column("x#2", "v_mag"), [2.0, 4.0])
    with pytest.raises(jd.InputError, match="column 'x': the header repeats 'x'"):
        tab.column("x", "v_mag")
