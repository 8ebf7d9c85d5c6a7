"""The bad-input table: realistic mistakes in a recording or its config, run through `jaxdse run`.

Every case starts from one clean recording (60 s at 25 frames/s, written as CSV with a TOML
config) and ends in exactly one of three outcomes:

* **error**: exit status 2 and ONE line on stderr that names the file (and the column, key or
  row where that makes sense);
* **handled**: exit status 0, a ``data_quality`` entry in summary.json that says what was
  handled, and H within 2 % of the clean run;
* **flagged**: exit status 0 and the flag in the recording's summary entry (a verdict reason or
  a ``data_quality`` note); an H more than 10 % off the clean run is never ``identified``.

Anything else fails, in particular an H more than 10 % off the clean run without a flag.
Cases run in-process and keep the recording's length (one padded shape), so the estimator
compiles once for the whole table.

    JAXDSE_BAD_INPUT_TABLE=/work/staging/bad_input_table.md pytest tests/app/test_bad_input.py

also writes the table as markdown (case, what was wrong, outcome, message or data_quality
entry, H and its error against the clean run).
"""

import contextlib
import io
import json
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from builders import COLS, run_toml

import jaxdse as jd
from jaxdse._app.cli import main

pytestmark = pytest.mark.slow

PLANT = """
[line]
x_pu = 0.005
b_pu = 0.02
[transformer]
x_hv_pu = 0.007
x_lv_pu = 0.007
[aux]
p_as_max_mw = 50.0
[machine]
s_rated_mva = 1100.0
v_rated_kv = 21.0
f_nominal_hz = 50.0
[governor]
model = "TGOV1"
"""
H_HANDLED = 0.02
"""Largest relative H error of a handled case against the clean run."""
H_WRONG = 0.10
"""A relative H error above this without a flag is a silent wrong result."""
CONJUGATE = ("swapping the angle columns conjugates S (P kept, Q negated): the data cannot tell; "
             "the verdict flags it")


@dataclass(frozen=True)
class Case:
    what: str
    expect: str
    """"error": words that the one-line message must hold; "handled": a data_quality path;
    "flagged": a path in the recording's summary entry."""
    check: tuple
    """error: substrings of the message; handled: (data_quality path, substring or None);
    flagged: (summary entry path, substring or None)."""
    cols: Callable | None = None
    """Clean columns -> damaged columns (written with jd.write_csv)."""
    text: Callable | None = None
    """Clean CSV text -> damaged text (str, or bytes written as they are)."""
    extra: str = ""
    """Lines added to [measurement]."""
    columns: dict | None = None
    """Column roles -> names, instead of COLS."""
    config: Callable | None = None
    """Config text -> damaged config text."""
    top: str = 'plant_defaults = "paper"'
    plant: str = ""
    file: str = "pmu.csv"
    recording: str = "clean"
    """"clean" (50 Hz, 25 frames/s), "us60" (60 Hz, 30 frames/s, same length) or "part60" (the
    clean plant at 60 % load)."""
    note: str | None = None
    """handled: words the console (stderr) must hold besides summary.json."""
    absent: tuple = ()
    """error: substrings the message must not hold (a hint for another config)."""
    known: str | None = None
    """Why the case ends in neither outcome yet (a strict xfail, listed in the table)."""


def error(what, *words, **kw):
    return Case(what, "error", words, **kw)


def handled(what, path, word=None, **kw):
    return Case(what, "handled", (path, word), **kw)


def flagged(what, path, word=None, **kw):
    return Case(what, "flagged", (path, word), **kw)


def edit(**changes):
    """Columns with some replaced by functions of the clean ones."""
    def apply(c):
        out = {k: v.copy() for k, v in c.items()}
        for name, fn in changes.items():
            out[name] = fn(c)
        return out
    return apply


def setat(name, index, value):
    def fn(c):
        x = c[name].copy()
        x[index] = value
        return x
    return fn


def rows(fn):
    """Columns with their rows re-indexed by ``fn(n, rng)``."""
    def apply(c):
        idx = fn(len(c["t"]), np.random.default_rng(0))
        return {k: v[idx] for k, v in c.items()}
    return apply


def late(n, k, lag=3):
    """Row order with ``k`` frames, spread over the recording, each arriving ``lag`` rows late
    (one step back in time each)."""
    idx = list(range(n))
    for p in np.linspace(100, n - 100, k).astype(int):
        idx.insert(p + lag, idx.pop(p))
    return np.array(idx)


def resent(n, g, k, lag=5):
    """Row order with ``k`` frames sent again ``lag`` rows after their first copy."""
    idx = list(range(n))
    for p in sorted(g.choice(np.arange(50, n - 50), k, replace=False), reverse=True):
        idx.insert(p + lag + 1, p)
    return np.array(idx)


def cells(column, first, last, word):
    """CSV text with the cells of ``column`` in data rows first..last replaced by ``word``."""
    def apply(text):
        lines = text.split("\n")
        k = lines[0].split(",").index(column)
        for r in range(first + 1, last + 2):
            fields = lines[r].split(",")
            fields[k] = word
            lines[r] = ",".join(fields)
        return "\n".join(lines)
    return apply


def timestamps(fmt, tz_half=False):
    def apply(text):
        from datetime import datetime, timedelta

        start = datetime(2024, 3, 1, 11, 0, 0)
        lines = text.split("\n")
        for r in range(1, len(lines)):
            if lines[r]:
                t, rest = lines[r].split(",", 1)
                stamp = (start + timedelta(seconds=float(t))).strftime(fmt)
                if tz_half and r > len(lines) // 2:
                    stamp += "+00:00"
                lines[r] = f"{stamp},{rest}"
        return "\n".join(lines)
    return apply


def text_column(name, word):
    """CSV text with a column ``name`` of ``word`` in every data row (e.g. a PMU STAT column
    exported as text)."""
    def apply(text):
        lines = text.split("\n")
        return "\n".join(f"{ln},{name if r == 0 else word}" if ln else ln for r, ln in enumerate(lines))
    return apply


def truncate_last_line(text):
    body = text.rstrip("\n")
    last = body.rfind("\n")
    return body[: last + 1 + (len(body) - last) // 2]


def latin1_header(text):
    return text.replace("VA", "VA_\u00b0", 1).encode("latin-1")


CASES = {
    # --- the table ----------------------------------------------------------------
    "current_spike_1e6_A": handled("one current sample of 1e6 A", "screening.out_of_range.IM",
                                   cols=edit(IM=setat("IM", 700, 1e6))),
    "voltage_sample_1e30_kV": handled("one voltage sample of 1e30 kV", "screening.out_of_range.VM",
                                      cols=edit(VM=setat("VM", 700, 1e30))),
    "ms_declared_s": error("time in ms, time_unit = \"s\"", "pmu.csv", "column 't'", "milliseconds",
                           cols=edit(t=lambda c: c["t"] * 1e3)),
    "degrees_declared_rad": error("angles in degrees, angle_unit = \"rad\"", "pmu.csv", "column 'VA'",
                                  "degrees", extra='angle_unit = "rad"'),
    "60hz_data_f_nominal_50": error("60 Hz data (30 frames/s, no frequency channel), the paper's "
                                    "50 Hz machine", "pmu.csv", "column 't'", "60 Hz",
                                    "f_nominal_hz", recording="us60",
                                    cols=lambda c: {k: v for k, v in c.items() if k != "f"},
                                    columns={k: v for k, v in COLS.items() if k != "frequency"}),
    "60hz_data_f_nominal_left_out": error("60 Hz data, [machine] without f_nominal_hz", "c.toml",
                                          "key 'machine.f_nominal_hz'", "required", top="",
                                          recording="us60",
                                          plant=PLANT.replace("f_nominal_hz = 50.0\n", "")),
    "substation_declared_terminal": error("400 kV substation data, location = \"terminal\"", "pmu.csv",
                                          "key 'measurement.location'", "v_rated_kv",
                                          extra='location = "terminal"'),
    "no_machine_section": error("no [machine] section, no plant_defaults", "c.toml", "key 'machine'",
                                "plant_defaults", top="",
                                plant=PLANT.split("[machine]")[0] + "[governor]\nmodel = \"TGOV1\"\n"),
    # --- export layouts -------------------------------------------------------------------
    "utf8_bom": handled("UTF-8 byte-order mark (Excel \"CSV UTF-8\")", "reader.byte_order_mark",
                        text=lambda s: "\ufeff" + s),
    "semicolons": handled("semicolon separators", "reader.separator", "semicolon",
                          text=lambda s: s.replace(",", ";")),
    "decimal_commas": handled("decimal commas, semicolon separators", "reader.decimal", "comma",
                              text=lambda s: s.replace(",", ";").replace(".", ",")),
    "tabs": handled("tab separators", "reader.separator", "tab", text=lambda s: s.replace(",", "\t")),
    "units_row": handled("a units row under the header", "reader.units_row",
                         text=lambda s: s.replace("\n", "\ns,Hz,kV,deg,A,deg\n", 1)),
    "na_cells": handled("\"n/a\" in three current cells", "nan_samples.IM",
                        text=cells("IM", 600, 602, "n/a")),
    "us_timestamps": error("03/01/2024 11:00:00.000 timestamps, no time_format", "pmu.csv", "column 't'",
                           "row 2", "time_format", text=timestamps("%m/%d/%Y %H:%M:%S.%f")),
    "us_timestamps_with_format": handled("03/01/2024 11:00:00.000 timestamps with time_format",
                                         "units.time", "%m/%d/%Y", text=timestamps("%m/%d/%Y %H:%M:%S.%f"),
                                         extra='time_format = "%m/%d/%Y %H:%M:%S.%f"'),
    "iso_timestamps": handled("ISO 8601 timestamps without a zone", "units.time", "no time zone",
                              text=timestamps("%Y-%m-%dT%H:%M:%S.%f")),
    "mixed_time_zones": error("timestamps with and without a UTC offset", "pmu.csv", "column 't'",
                              "time zone", text=timestamps("%Y-%m-%dT%H:%M:%S.%f", tz_half=True)),
    "comment_lines": handled("two '#' comment lines before the header", "reader.skipped_lines",
                             text=lambda s: "# PMU export\n# station SUB1\n" + s),
    "metadata_lines": error("two metadata lines before the header, no skip_rows", "pmu.csv", "skip_rows",
                            text=lambda s: "Station: SUB1\nExported: 2024-03-01\n" + s),
    "metadata_lines_skip_rows": handled("two metadata lines, skip_rows = 2", "reader.skipped_lines",
                                        text=lambda s: "Station: SUB1\nExported: 2024-03-01\n" + s,
                                        extra="skip_rows = 2"),
    "windows_line_ends": handled("CRLF line ends", "reader.line_ends", "CRLF",
                                 text=lambda s: s.replace("\n", "\r\n")),
    "trailing_empty_columns": handled("every line ends in ',,'", "reader.empty_columns",
                                      text=lambda s: s.replace("\n", ",,\n")),
    "truncated_last_line": handled("the file ends in the middle of its last line", "edge_rows_trimmed",
                                   text=truncate_last_line),
    "latin1_header": handled("latin-1 header with a degree sign", "reader.encoding", "latin-1",
                             text=latin1_header, columns=dict(COLS, v_ang="VA_\u00b0")),
    "extra_field": error("one row with an extra field", "pmu.csv", "row 502", "fields",
                         text=cells("IA", 500, 500, "-9.2,1")),
    "text_cell": error("\"ERR\" in a current cell", "pmu.csv", "column 'IM'", "row 802", "na_values",
                       text=cells("IM", 800, 800, "ERR")),
    "text_cell_na_values": handled("\"ERR\" in a current cell, na_values = [\"ERR\"]", "nan_samples.IM",
                                   text=cells("IM", 800, 800, "ERR"), extra='na_values = ["ERR"]'),
    "repeated_header": error("the header names VA twice", "pmu.csv", "column 'VA'", "repeats",
                             text=lambda s: s.replace(",IA", ",VA", 1), columns=dict(COLS, i_ang=5)),
    "column_name_case": error("config names column 'vm', the file 'VM'", "pmu.csv", "column 'vm'",
                              "did you mean 'VM'", columns=dict(COLS, v_mag="vm")),
    "missing_column": error("no current magnitude column", "pmu.csv", "'IM'",
                            cols=lambda c: {k: v for k, v in c.items() if k != "IM"}),
    "empty_file": error("an empty file", "pmu.csv", "empty", text=lambda s: ""),
    "header_only": error("a header and no rows", "pmu.csv", "no data rows",
                         text=lambda s: s.split("\n", 1)[0] + "\n"),
    "excel_file": error("an .xlsx file", "pmu.xlsx", "format", file="pmu.xlsx"),
    "file_missing": error("the recording file does not exist", "nope.csv", "does not exist",
                          config=lambda s: s.replace("pmu.csv", "nope.csv")),
    # --- data problems ------------------------------------------------------------------
    "nan_run_0.2s": handled("5 NaN voltage samples (0.2 s)", "bridged_gaps",
                            cols=edit(VM=setat("VM", slice(500, 505), np.nan))),
    "nan_run_2s_on_long_gap_error": error("2 s of NaN voltage, on_long_gap = \"error\"", "pmu.csv",
                                          "column 'VM'", "row 702", "max_gap_s",
                                          cols=edit(VM=setat("VM", slice(700, 750), np.nan)),
                                          extra='on_long_gap = "error"'),
    "missing_frames_0.4s": handled("10 frames missing (0.4 s)", "bridged_gaps",
                                   cols=rows(lambda n, g: np.delete(np.arange(n), np.s_[700:710]))),
    "rows_without_time": handled("3 rows with an empty time cell", "rows_without_time",
                                 cols=edit(t=setat("t", slice(300, 303), np.nan))),
    "duplicated_rows": handled("40 rows repeated", "duplicate_timestamps_dropped",
                               cols=rows(lambda n, g: np.sort(np.concatenate([np.arange(n),
                                                                              g.integers(0, n, 40)])))),
    "late_frames": handled("10 frames each 3 rows late (0.7 % of the steps go back)", "out_of_order_rows",
                           cols=rows(lambda n, g: late(n, 10)), note="10 row(s) out of time order sorted"),
    "late_frames_2_percent": error("30 frames each 3 rows late (2 % of the steps go back)", "pmu.csv",
                                   "column 't'", "row 105", "30 of 1500 steps", "at most 1 %",
                                   cols=rows(lambda n, g: late(n, 30))),
    "resent_frames": handled("40 frames sent again 5 rows later", "duplicate_timestamps_dropped",
                             cols=rows(lambda n, g: resent(n, g, 40)),
                             note="40 row(s) with a repeated time dropped"),
    "shuffled_rows": error("rows in random order", "pmu.csv", "column 't'", "time goes backwards",
                           cols=rows(lambda n, g: g.permutation(n))),
    "reversed_rows": error("rows in descending time", "pmu.csv", "column 't'", "row 3",
                           "1500 of 1500 steps", cols=rows(lambda n, g: np.arange(n)[::-1])),
    "time_column_reversed": error("the time column runs backwards, the rows forwards", "pmu.csv",
                                  "column 't'", "row 3", "time goes backwards", "the time column does not "
                                  "belong to them", cols=edit(t=lambda c: c["t"][::-1])),
    "time_jitter_2ms": handled("timestamps jitter by up to 2 ms", "non_uniform_steps",
                               cols=edit(t=lambda c: c["t"] + 2e-3 * np.random.default_rng(1).uniform(
                                   -1, 1, c["t"].size))),
    "stuck_voltage": error("the voltage magnitude holds one value (a stuck channel)", "pmu.csv",
                           "column 'VM'", "one value", cols=edit(VM=lambda c: np.full_like(c["VM"], 400.0))),
    "stuck_frequency": error("the frequency channel reports 50.000 Hz throughout", "pmu.csv",
                             "column 'f'", "one value", "leave measurement.columns.frequency out",
                             cols=edit(f=lambda c: np.full_like(c["f"], 50.0))),
    "all_nan_frequency": handled("the frequency channel is empty", "frequency_all_nan",
                                 cols=edit(f=lambda c: np.full_like(c["f"], np.nan))),
    "all_nan_angle": error("the voltage angle column is empty", "pmu.csv", "column 'VA'", "row 2-1502",
                           cols=edit(VA=lambda c: np.full_like(c["VA"], np.nan))),
    "swapped_magnitudes": error("voltage and current magnitude columns swapped", "pmu.csv",
                                "column 'IM'", "median voltage", columns=dict(COLS, v_mag="IM", i_mag="VM")),
    "swapped_angles": error("voltage and current angle columns swapped", "pmu.csv", "column 'IA'",
                            columns=dict(COLS, v_ang="IA", i_ang="VA"), known=CONJUGATE),
    "kA_declared_A": error("current in kA, current_unit = \"A\"", "pmu.csv", "column 'IM'",
                           "current_unit", cols=edit(IM=lambda c: c["IM"] / 1e3)),
    "A_declared_kA": error("current in A, current_unit = \"kA\"", "pmu.csv", "column 'IM'",
                           "current_unit", extra='current_unit = "kA"'),
    "ct_secondary_amperes": error("current in CT secondary amperes (2000:5)", "pmu.csv", "column 'IM'",
                                  "current_unit", cols=edit(IM=lambda c: c["IM"] / 400.0)),
    "current_ct_ratio_1.5x": error("current 1.5x too large (a 3000:5 CT read as 2000:5)", "pmu.csv",
                                   "column 'IM'", "median apparent power", "a CT ratio",
                                   cols=edit(IM=lambda c: c["IM"] * 1.5)),
    "phase_to_ground_declared_ll": error("phase-to-ground kV, voltage_unit = \"kV_LL\"", "pmu.csv",
                                         "column 'VM'", "kV_LN",
                                         cols=edit(VM=lambda c: c["VM"] / np.sqrt(3))),
    "phase_to_phase_declared_ln": error("phase-to-phase kV, voltage_unit = \"kV_LN\"", "pmu.csv",
                                        "column 'VM'", "voltage_unit", extra='voltage_unit = "kV_LN"'),
    "volts_declared_kV": error("voltage in V, voltage_unit = \"kV_LL\"", "pmu.csv", "column 'VM'",
                               "voltage_unit", cols=edit(VM=lambda c: c["VM"] * 1e3)),
    "pt_secondary_volts": error("voltage in PT secondary volts (110 V)", "pmu.csv", "column 'VM'",
                                "voltage_unit", cols=edit(VM=lambda c: c["VM"] * 110.0 / 400e3 * 1e-3)),
    "current_into_plant": error("current measured into the plant, direction not declared", "pmu.csv",
                                "column 'IM'", "into_plant", cols=edit(IA=lambda c: c["IA"] + 180.0)),
    "radians_declared_deg": error("angles in radians, angle_unit = \"deg\"", "pmu.csv", "column 'VA'",
                                  "radians", cols=edit(VA=lambda c: np.radians(c["VA"]),
                                                       IA=lambda c: np.radians(c["IA"]))),
    "frequency_deviation_mHz": error("frequency column holds the deviation in mHz", "pmu.csv",
                                     "column 'f'", "median frequency",
                                     cols=edit(f=lambda c: (c["f"] - 50.0) * 1e3)),
    "frequency_sample_zero": handled("one frequency sample of 0 Hz", "screening.out_of_range.f",
                                     cols=edit(f=setat("f", 900, 0.0))),
    "angle_spike": handled("one voltage angle sample off by 90 degrees", "screening.spikes.VM",
                           cols=edit(VA=lambda c: c["VA"] + 90.0 * (np.arange(c["VA"].size) == 900))),
    "angle_spike_radians": handled("radian angles (declared), one voltage angle sample off by 2 rad",
                                   "screening.spikes.VM", extra='angle_unit = "rad"',
                                   cols=edit(VA=lambda c: np.radians(c["VA"]) + 2 * (np.arange(1501) == 900),
                                             IA=lambda c: np.radians(c["IA"]))),
    "spike_at_first_row": handled("the first voltage sample is 30 % of the others", "screening.spikes.VM",
                                  cols=edit(VM=setat("VM", 0, 120.0))),
    "current_dropout": handled("two current samples of 0 A", "screening.spikes.IM",
                               cols=edit(IM=setat("IM", slice(900, 902), 0.0))),
    "stat_invalid": handled("C37.118 STAT marks 5 frames invalid (data error)",
                            "screening.stat_invalid.STAT", columns=dict(COLS, stat="STAT"),
                            cols=lambda c: dict(c, STAT=0x8000 * ((np.arange(c["t"].size) // 5) == 80))),
    "data_valid_flag": handled("a data-valid column marks 5 frames invalid",
                               "screening.flagged_invalid.valid", columns=dict(COLS, valid="valid"),
                               cols=lambda c: dict(c, valid=1.0 * ((np.arange(c["t"].size) // 5) != 80))),
    "s_declared_ms": error("time in s, time_unit = \"ms\"", "pmu.csv", "column 't'", "seconds",
                           extra='time_unit = "ms"'),
    # --- plausibility against the plant's stated maximum and typical machine data (issue 32)
    "current_peak_full_load": error("current logged as peak instead of RMS (x1.414) at 77 % load",
                                    "pmu.csv", "column 'IM'", "row 2-1502", "p_sg_max_mw",
                                    "peak instead of RMS", cols=edit(IM=lambda c: c["IM"] * np.sqrt(2))),
    "current_peak_part_load": flagged("current logged as peak instead of RMS (x1.414) at 60 % load "
                                      "(0.85 pu: under every rating check)", "reasons.power_above_droop",
                                      "peak instead of RMS", recording="part60",
                                      cols=edit(IM=lambda c: c["IM"] * np.sqrt(2))),
    "reactance_percent": error("machine.xd_pu = 180 (percent)", "c.toml", "key 'machine.xd_pu'",
                               "looks like percent: 180 -> 1.8 pu?", plant="[machine]\nxd_pu = 180.0\n"),
    "resistance_percent": error("machine.rs_pu = 0.3 (percent)", "c.toml", "key 'machine.rs_pu'",
                                "looks like percent", plant="[machine]\nrs_pu = 0.3\n"),
    "reactance_atypical": flagged("machine.xd1_pu = 0.6, outside the typical 0.1-0.5 pu",
                                  "data_quality.plant_data", "X'd = 0.6", plant="[machine]\nxd1_pu = 0.6\n"),
    # --- inputs as real exports come (issue 32) ----------------------------------------------
    "stat_text_column": handled("an unmapped STAT column holding '0x0000' text", "unmapped_columns",
                                "STAT", text=text_column("STAT", "0x0000")),
    "status_word_column": handled("an unmapped column of words ('OK')", "unmapped_columns", "Status",
                                  text=text_column("Status", "OK")),
    "stat_hex_mapped": handled("C37.118 STAT as hexadecimal text, 5 frames '0x8000' (data error)",
                               "screening.stat_invalid.STAT", columns=dict(COLS, stat="STAT"),
                               text=lambda s: cells("STAT", 400, 404, "0x8000")(
                                   text_column("STAT", "0x0000")(s))),
    "frequency_deviation_declared": handled("frequency column holds the deviation in mHz, "
                                            "frequency_kind = \"deviation\", frequency_unit = \"mHz\"",
                                            "units.frequency", "deviation",
                                            cols=edit(f=lambda c: (c["f"] - 50.0) * 1e3),
                                            extra='frequency_kind = "deviation"\nfrequency_unit = "mHz"'),
    "frequency_deviation_pu_declared": handled("frequency column holds the deviation in pu, declared",
                                               "units.frequency", "in pu",
                                               cols=edit(f=lambda c: c["f"] / 50.0 - 1.0),
                                               extra='frequency_kind = "deviation"\nfrequency_unit = "pu"'),
    "frequency_deviation_mHz_declared_Hz": error("deviation in mHz, frequency_kind = \"deviation\" in Hz",
                                                 "pmu.csv", "column 'f'", "frequency_unit = \"mHz\"",
                                                 cols=edit(f=lambda c: (c["f"] - 50.0) * 1e3),
                                                 extra='frequency_kind = "deviation"'),
    "frequency_absolute_declared_deviation": error("frequency in Hz, frequency_kind = \"deviation\"",
                                                   "pmu.csv", "column 'f'",
                                                   "leave measurement.frequency_kind out",
                                                   extra='frequency_kind = "deviation"'),
    "no_plant_data": error("no plant section at all, no plant_defaults", "c.toml", "[line], [transformer], "
                           "[aux], [machine] and [governor] sections", "s_rated_mva", top=""),
    "into_plant_declared_reversed": error("current_direction = \"into_plant\" set, the current flows out",
                                          "pmu.csv", "column 'IM'", "already set", "CT polarity",
                                          extra='current_direction = "into_plant"',
                                          absent=('set measurement.current_direction = "into_plant"',)),
    "12_hour_clock": error("03/01/2024 11:00:00.000 AM timestamps, no time_format", "pmu.csv", "column 't'",
                           "row 2", "%I:%M:%S.%f %p", text=timestamps("%m/%d/%Y %I:%M:%S.%f %p"),
                           absent=("%H:%M",)),
    "12_hour_clock_format_H": error("AM/PM timestamps, time_format with %H", "pmu.csv", "column 't'",
                                    "12-hour clock", "%m/%d/%Y %I:%M:%S.%f %p",
                                    text=timestamps("%m/%d/%Y %I:%M:%S.%f %p"),
                                    extra='time_format = "%m/%d/%Y %H:%M:%S.%f"'),
    "12_hour_clock_with_format": handled("AM/PM timestamps, time_format with %I and %p", "units.time",
                                         "%p", text=timestamps("%m/%d/%Y %I:%M:%S.%f %p"),
                                         extra='time_format = "%m/%d/%Y %I:%M:%S.%f %p"'),
    # --- config mistakes ------------------------------------------------------------------
    "unit_typo": error("voltage_unit = \"kW\"", "c.toml", "key 'measurement.voltage_unit'", "'kW'",
                       extra='voltage_unit = "kW"'),
    "key_typo": error("v_base_kw instead of v_base_kv", "c.toml", "key 'measurement.v_base_kw'",
                      "v_base_kv", extra="v_base_kw = 3"),
    "no_v_base": error("no v_base_kv for kV data", "key 'measurement.v_base_kv'",
                       config=lambda s: s.replace("v_base_kv = 400.0\n", "")),
    "malformed_toml": error("a malformed TOML file", "c.toml", "malformed TOML",
                            config=lambda s: "[measurement\n" + s),
}


@pytest.fixture(scope="module")
def recordings(pmu25):
    """Clean columns: the 50 Hz one and a 60 Hz one of the same length (50 s at 30 frames/s)."""
    spec = jd.MeasurementSpec(file=(), columns=COLS, v_base_kv=400.0)
    us = jd.simulate(jd.Plant(machine=jd.Machine(f_nominal_hz=60.0)),
                     jd.Scenario(duration_s=50.0, frame_rate_hz=30.0, seed=8))
    part = jd.simulate(jd.Plant(), jd.Scenario(duration_s=60.0, frame_rate_hz=25.0, seed=8, p_pu=0.6))
    out = {"clean": jd.phasor_columns(pmu25.recording, spec), "us60": jd.phasor_columns(us.recording, spec),
           "part60": jd.phasor_columns(part.recording, spec)}
    assert {len(c["t"]) for c in out.values()} == {1501}
    return out


def run_case(tmp: Path, case: Case, recordings):
    """Write the case's file and config, run `jaxdse run`: (exit status, stderr, summary)."""
    clean = recordings[case.recording]
    cols = case.cols(clean) if case.cols else clean
    jd.write_csv(tmp / case.file, cols)
    if case.text:
        text = case.text((tmp / case.file).read_text())
        (tmp / case.file).write_bytes(text if isinstance(text, bytes) else text.encode())
    config = run_toml(case.file, top=case.top, extra=case.extra, columns=case.columns or COLS,
                      plant=case.plant)
    (tmp / "c.toml").write_text(case.config(config) if case.config else config, encoding="utf-8")
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = main(["run", str(tmp / "c.toml"), "--out", str(tmp / "out")])
    err = err.getvalue()
    summary = json.loads((tmp / "out" / "summary.json").read_text()) if rc == 0 else None
    return rc, err, summary


def lookup(tree, path):
    for key in path.split("."):
        if not isinstance(tree, dict) or key not in tree:
            return None
        tree = tree[key]
    return tree


def outcome(rc, err, summary, h_clean):
    """("error", the message, None) or ("handled", the recording's summary entry, its H)."""
    if rc == 2:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert "Traceback" not in err and len(lines) == 1, f"not one line:\n{err}"
        assert lines[0].startswith("jaxdse: error: "), err
        return "error", lines[0].removeprefix("jaxdse: error: "), None
    assert rc == 0, f"exit status {rc}:\n{err}"
    (entry,) = summary["recordings"]
    h = entry["H_s"]
    assert h is not None and np.isfinite(h), f"H = {h} with exit 0 (verdict {entry['verdict']})"
    return "handled", entry, h


def judge_h(h, verdict, h_clean):
    """Exit 0: H within 2 % of the clean run; never more than 10 % off unflagged."""
    rel = abs(h / h_clean - 1)
    assert not (rel > H_WRONG and verdict == "identified"), \
        f"silent wrong H: {h:.4g} s against {h_clean:.4g} s, verdict identified"
    assert rel <= H_HANDLED, \
        f"exit 0 with H {h:.4g} s, {100 * rel:.2f} % off the clean run (verdict {verdict})"


@pytest.fixture(scope="module")
def clean_run(tmp_path_factory, recordings):
    rc, err, summary = run_case(tmp_path_factory.mktemp("clean"), Case("clean", "handled", ()), recordings)
    assert rc == 0, err
    (entry,) = summary["recordings"]
    assert entry["verdict"] == "identified"
    return entry


TABLE: dict[str, tuple] = {}


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason=c.known))
                                  if c.known else n for n, c in CASES.items()])
def test_bad_input(name, tmp_path, recordings, clean_run):
    case = CASES[name]
    rc, err, summary = run_case(tmp_path, case, recordings)
    kind, result, h = outcome(rc, err, summary, clean_run["H_s"])
    if kind == "error":
        TABLE[name] = (case.what, "exit 2", result.replace(f"{tmp_path}/", ""), None, case.known)
        assert case.expect == "error", f"expected {case.check[0]} to be {case.expect}, got: {result}"
        missing = [w for w in case.check if w not in result]
        assert not missing, f"{result!r} lacks {missing}"
        wrong = [w for w in case.absent if w in result]
        assert not wrong, f"{result!r} holds {wrong}, a hint for another config"
        return
    path, word = case.check
    if case.expect == "flagged":
        note = lookup(result, path)
        TABLE[name] = (case.what, f"exit 0, {result['verdict']} (flagged)",
                       f"`{path}`: {json.dumps(note)}" if note is not None else "", h, case.known)
        rel = abs(h / clean_run["H_s"] - 1)
        assert not (rel > H_WRONG and result["verdict"] == "identified"), \
            f"silent wrong H: {h:.4g} s against {clean_run['H_s']:.4g} s, verdict identified"
        assert note not in (None, 0, "", [], {}), f"no {path!r} in the summary entry: {result}"
        assert lookup(clean_run, path) is None, f"{path!r} is in the clean run too"
        if word is not None:
            assert word in str(note), f"{path} = {note!r} lacks {word!r}"
        return
    note = lookup(result["data_quality"], path) if case.expect == "handled" else None
    TABLE[name] = (case.what, f"exit 0, {result['verdict']}",
                   f"`{path}`: {json.dumps(note)}" if note is not None else "", h, case.known)
    assert case.expect == "handled", f"expected an error naming {case.check}, got exit 0"
    judge_h(h, result["verdict"], clean_run["H_s"])
    assert note not in (None, 0, "", [], {}), f"data_quality has no {path!r}: {result['data_quality']}"
    assert note != lookup(clean_run["data_quality"], path), f"{path!r} is the same in the clean run"
    if word is not None:
        assert word in str(note), f"{path} = {note!r} lacks {word!r}"
    if case.note is not None:
        assert case.note in err, f"the console does not say {case.note!r}:\n{err}"


def test_table_has_enough_cases():
    assert len(CASES) >= 30
    assert {c.expect for c in CASES.values()} == {"error", "handled", "flagged"}


@pytest.fixture(scope="module", autouse=True)
def markdown_table(clean_run):
    """With JAXDSE_BAD_INPUT_TABLE set, write the table as markdown when the module is done."""
    yield
    path = os.environ.get("JAXDSE_BAD_INPUT_TABLE")
    if not path:
        return
    h0 = clean_run["H_s"]
    lines = [f"Clean run: H = {h0:.4f} s, verdict {clean_run['verdict']}. {len(TABLE)} cases.", "",
             "| case | what was wrong | outcome | message / data_quality entry | H [s] | H error |",
             "|---|---|---|---|---|---|"]
    for name, (what, kind, detail, h, known) in TABLE.items():
        detail = detail if len(detail) < 400 else detail[:397] + "..."
        if known:
            kind = f"**neither** ({known})"
        h_txt = "" if h is None else f"{h:.4f}"
        e_txt = "" if h is None else f"{100 * (h / h0 - 1):+.2f} %"
        lines.append(f"| {name} | {what} | {kind} | {detail.replace('|', '/')} | {h_txt} | {e_txt} |")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text("\n".join(lines) + "\n")
