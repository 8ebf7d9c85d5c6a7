"""From a raw :class:`Table` to validated :class:`Recording` segments, with a data-quality report.

Applied at the edge, in NumPy, in this order:

1. pick the columns (positive-sequence magnitude/angle, or three-phase a/b/c magnitude/angle;
   optionally the frequency and a C37.118 STAT word or a data-valid flag); the columns the
   config does not map are ignored, whatever they hold, and listed (``unmapped_columns``);
2. time: seconds, milliseconds or timestamps (ISO 8601, or ``time_format``, in ``timezone``);
   rows with no time are dropped, out-of-order rows sorted, duplicated timestamps dropped
   (the first row is kept); a recording whose time goes back at more than
   ``MAX_OUT_OF_ORDER`` (1 %) of its steps is refused (rows running backwards or shuffled, or
   a time column that does not belong to them); the frame rate must lie in 1-240 frames/s;
3. units: voltage kV/V phase-to-phase or phase-to-ground or pu, current A/kA/pu, angles
   deg/rad, converted to pu of the system base (``s_base_mva``, ``v_base_kv`` phase-to-phase);
   three-phase -> positive sequence; current direction -> generator convention; frequency
   Hz/mHz/pu, absolute or as a deviation from nominal (``frequency_kind``) -> Hz;
4. plausibility of units and set-up, from medians and statistics of the whole recording:
   no stuck (constant) magnitude or frequency channel, voltage near 1 pu (which also tells
   phase-to-ground from phase-to-phase), current below 3x rating and not a power-carrying
   trickle (a unit or CT-ratio mistake), current within the machine's short-time capability
   (IEEE C50.13) and reactive power within its capability curve, no reversed power,
   active power within the plant's stated maximum (``p_max_mw``: a current logged as peak
   instead of RMS at part load passes every rating check but this one, or none),
   frequency near nominal and within a fraction of a hertz of its median, angle steps that
   fit the declared angle unit, the voltage-angle
   drift against f_nominal, the frame rate against f_nominal (without a frequency channel),
   and the PMU voltage base against the machine's rated voltage for the declared location;
5. screening: rows flagged invalid by the STAT word, samples outside physical ranges, stale
   frames (every frame of a run that repeats exactly in all phasor channels, in data whose
   frames otherwise change: ``REPEATS_RARE``), and spikes (a Hampel filter: deviation from a
   running median beyond ``SPIKE_SIGMAS`` robust standard deviations, in runs of at most
   ``SPIKE_MAX_SAMPLES`` that stand out from the curve of their neighbours) become missing; a
   spike in one phasor with the other off its median within a frame of any of its samples (a
   fault: the voltage dips, the current answers) is a disturbance and is kept whole;
6. gaps: missing samples form gaps; gaps up to ``max_gap_s`` are bridged by linear
   interpolation of magnitude and unwrapped angle, longer ones split the recording (or fail);
7. resampling onto a uniform grid (linear, angles unwrapped first).

Everything handled is reported in ``data_quality``; everything else is an :class:`InputError`.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .._core.machine import Machine
from .._core.mapping import LOCATIONS
from .._core.recording import Recording
from .._core.sequence import positive_sequence
from .errors import InputError
from .readers import FORMATS, CsvOptions, Table, load_table

MAX_OUT_OF_ORDER = 0.01
"""Largest fraction of a recording's steps (between successive distinct times, in file order)
that may go back in time: such rows are sorted and reported; more is refused (InputError)."""
VOLTAGE_UNITS = {"kv_ll": (1e3, False), "kv_ln": (1e3, True), "v_ll": (1.0, False),
                 "v_ln": (1.0, True), "pu": (None, False)}
"""unit -> (volts per unit, phase-to-ground?)."""
CURRENT_UNITS = {"a": 1.0, "ka": 1e3, "pu": None}
"""unit -> amperes per unit (None: per unit of the system base)."""
ANGLE_UNITS = {"deg": np.pi / 180, "rad": 1.0}
"""unit -> radians per unit."""
TIME_UNITS = ("s", "ms", "iso")
DIRECTIONS = ("out_of_plant", "into_plant")
GAP_POLICIES = ("split", "error")
POSITIVE = ("v_mag", "v_ang", "i_mag", "i_ang")
THREE_PHASE = tuple(f"{q}_{p}_{c}" for q in "vi" for c in ("mag", "ang") for p in "abc")
COLUMN_ROLES = ("time", "frequency", "stat", "valid") + POSITIVE + THREE_PHASE
FREQUENCY_UNITS = {"hz": 1.0, "mhz": 1e-3, "pu": None}
"""unit -> hertz per unit (None: per unit of f_nominal)."""
FREQUENCY_KINDS = ("absolute", "deviation")
"""The frequency channel holds the frequency itself, or its deviation from f_nominal."""
UNIT_KEYS = {"voltage_unit": ("kV_LL", "kV_LN", "V_LL", "V_LN", "pu"), "current_unit": ("A", "kA", "pu"),
             "angle_unit": ("deg", "rad"), "frequency_unit": ("Hz", "mHz", "pu")}
"""Unit keys of [measurement] -> the spellings users write (matched case-insensitively)."""
CHOICE_KEYS = {"format": FORMATS, "location": LOCATIONS, "current_direction": DIRECTIONS,
               "on_long_gap": GAP_POLICIES, "time_unit": TIME_UNITS, "frequency_kind": FREQUENCY_KINDS}
"""Keys of [measurement] that take one of a few words (matched exactly)."""

# Plausibility of units and set-up (whole recording).
PLAUSIBLE_VOLTAGE_PU = (0.76, 1.3)
"""Median voltage magnitude [pu of v_base_kv] outside this range: wrong unit or base. The
range is narrower than a factor sqrt 3, so phase-to-ground values declared phase-to-phase
(and the reverse) always fall outside it."""
MAX_CURRENT_PU_MACHINE = 3.0
"""Median current [pu of the machine rating] above this: wrong unit or base."""
MIN_CURRENT_PU_MACHINE = 0.01
"""Median current [pu of the machine rating] below which a current that still carries power
(power factor above ``MIN_POWER_FACTOR``) is a unit or CT-ratio mistake (kA read as A,
secondary amperes); an offline machine's current carries none."""
MIN_POWER_FACTOR = 0.5
"""Median P / |S| above which a small current is a real, scaled load current [-]."""
MAX_LOADING = 1.1
"""Median apparent power [pu of the machine rating] above which the operating point is not
plausible: a unit runs at its rating at most, plus what a cold day or a high voltage allows;
and the current [pu of the rating] above which short-time overload heating accumulates [-]."""
OVERLOAD_MIN_S = 1.0
"""Only currents above ``MAX_LOADING`` for this long around a sample heat the stator in the
short-time check: a spike or a fault clearing within a second is left to the screening [s]."""
SHORT_TIME_CAPABILITY_S = 41.4
"""IEEE C50.13 short-time armature current capability of round-rotor machines: (I^2 - 1) t
[pu^2 s] (10 s at 2.26, 30 s at 1.54, 60 s at 1.30, 120 s at 1.16 x rated current)."""
MAX_Q_LAGGING = 0.9
"""Median lagging reactive power [pu of the machine rating] above which the field would
overheat: the field-heating limit at P = 0 is 0.75-0.86 pu for x_d = 1-2.5 pu and a rated
power factor of 0.85 [-]."""
LEADING_Q_MARGIN = 1.25
"""Median leading reactive power below this x -V^2/x_d (the round-rotor steady-state stability
limit at P = 0) is outside the capability curve [-]."""
MIN_POWER_PU_MACHINE = -0.05
"""Median active power [pu of the machine rating] below this: the current is reversed."""
MAX_FREQUENCY_OFFSET = 0.1
"""Median frequency off nominal by more than this fraction of f_nominal [-]: not in Hz."""
MAX_FREQUENCY_SPREAD_HZ = 0.5
"""Median absolute deviation of the frequency channel from its median above this [Hz]: grids
stay within a fraction of a hertz, so the channel's unit is wrong (a deviation in mHz read as Hz)."""
TYPICAL_FREQUENCY_SPREAD_HZ = 0.005
"""A grid frequency's typical median absolute deviation from its median [Hz]: of the unit
declarations that fit a wrongly declared channel's median, the hint names the one whose
spread comes nearest to it."""
P_MAX_TOLERANCE = 0.05
"""Median active power above the plant's stated maximum (``MeasurementSpec.p_max_mw``) by more
than this fraction is refused: no turbine delivers more than its maximum [-]."""
P_MAX_RUN_TOLERANCE = 0.10
"""Active power above the stated maximum by more than this fraction ... [-]"""
P_MAX_RUN_S = 30.0
"""... for longer than this is refused too: a swing or an inertial response lasts seconds, the
turbine cannot follow beyond its maximum for longer [s]."""
PEAK_TO_RMS = float(np.sqrt(2.0))
"""Peak / RMS of a sine: a current logged as peak instead of RMS is this factor too large."""
FRAME_RATE_HZ = (1.0, 240.0)
"""Frame rates a PMU reports [frames/s]; outside: the time unit is wrong."""
SYSTEM_RATES_HZ = {50.0: (25.0, 50.0, 100.0), 60.0: (30.0, 60.0, 120.0)}
"""Reporting rates [frames/s] that IEEE C37.118 gives only one system frequency [Hz]; with no
frequency channel, such a rate is the only sign of a wrong f_nominal."""
MAX_ANGLE_DRIFT_HZ = 2.0
"""Mean rotation of the voltage angle against f_nominal above this [Hz]: wrong f_nominal or
angle unit (grids stay within a fraction of a hertz)."""
MAX_ANGLE_STEP_RAD = 1.0
"""Largest voltage-angle step between two frames after unwrapping [rad]: more is not physical
(60 degrees a frame); degrees read as radians make steps of 2 pi - 360 mod 2 pi = 1.86 rad."""
OUTLIER_SHARE = 0.01
"""Share of frames that the angle-unit checks leave to the spike screening (single bad
samples must not decide the unit) [-]."""
TERMINAL_BASE_RATIO = (0.75, 1.33)
"""PMU voltage base / machine rated voltage expected at location "terminal" [-]."""
HV_BASE_RATIO = 1.2
"""PMU voltage base / machine rated voltage above which the PMU is on the HV side [-]."""

# Screening of single samples.
VOLTAGE_RANGE_PU = (0.05, 2.0)
"""A voltage sample outside this range [pu] is not a measurement of a running machine."""
MAX_CURRENT_SAMPLE_PU_MACHINE = 10.0
"""A current sample above this [pu of the machine rating] exceeds any fault current."""
MAX_FREQUENCY_SAMPLE_OFFSET_HZ = 5.0
"""A frequency sample farther than this from f_nominal [Hz] is a measurement error."""
SPIKE_HALF_WIDTH = 5
"""Half width of the running median of the spike filter [samples]."""
SPIKE_SIGMAS = 8.0
"""Deviation from the running median, in robust standard deviations (1.4826 MAD), that makes a
sample a spike."""
SPIKE_FLOOR = {"magnitude": 0.02, "angle_rad": 0.05, "frequency_hz": 0.05}
"""Smallest deviation that can be a spike: relative for magnitudes [-], absolute for angles
[rad] and frequency [Hz] (noise-free data have a zero MAD)."""
SPIKE_MAX_SAMPLES = 3
"""Longest run of outlying samples that is a spike; longer runs are the signal (an event)."""
SPIKE_TREND = 4.0
"""A spike stands out from the line through the samples on either side of it by more than this
many times the curvature there (the second difference, times the run's length plus one,
squared): more than a smooth swing's crest does."""
REPEATS_RARE = 0.01
"""A frame that repeats the one before it exactly, in every phasor channel, is a stale frame
when repeats are this rare (a fraction of all pairs of valid frames) or rarer: noisy data
change every frame, so a repeat is a PDC holding its last value, or a simulator's frames before
its first solution (NASPI OSL case 1 opens with 4, |V| 2 % low). Noise-free or coarsely
quantised data repeat by nature and keep their repeats."""
STAT_INVALID_BITS = 0xE000
"""C37.118 STAT bits that make a frame invalid: data error (bits 15-14) and PMU sync error (13)."""


def spec_value_error(key: str, value) -> str | None:
    """Why ``value`` is not valid for the unit or choice key ``key`` of [measurement], or None."""
    if key in UNIT_KEYS:
        words = UNIT_KEYS[key]
        if isinstance(value, str) and value.lower() in {w.lower() for w in words}:
            return None
        return f"unknown unit {value!r}; use one of {', '.join(words)} (case-insensitive)"
    if value in CHOICE_KEYS[key]:
        return None
    return f"must be one of {', '.join(CHOICE_KEYS[key])}, got {value!r}"


def current_base_a(s_base_mva: float, v_base_kv: float) -> float:
    """Base current [A] of a three-phase system base S [MVA] at a phase-to-phase voltage [kV]."""
    return s_base_mva * 1e6 / (np.sqrt(3.0) * v_base_kv * 1e3)


def voltage_base_v(v_base_kv: float, unit: str) -> float:
    """Volts per pu for voltages written in ``unit`` (phase-to-ground units divide by sqrt 3)."""
    return v_base_kv * 1e3 / (np.sqrt(3.0) if VOLTAGE_UNITS[unit.lower()][1] else 1.0)


@dataclass(frozen=True)
class MeasurementSpec:
    """How to read one PMU recording: file, layout, columns, units, bases, direction, gaps."""

    file: tuple[str, ...]
    columns: dict
    """Role ("time", "frequency", "stat", "valid", "v_mag", ..., or "v_a_mag", ...) -> column
    name or 0-based number."""
    format: str | None = None
    location: str = "substation"
    voltage_unit: str = "kV_LL"
    current_unit: str = "A"
    angle_unit: str = "deg"
    time_unit: str = "s"
    """"s" or "ms" for numbers, "iso" for timestamps (text timestamps are read as such anyway)."""
    time_format: str | None = None
    """strftime format of text timestamps, e.g. "%m/%d/%Y %H:%M:%S.%f"; None: ISO 8601."""
    timezone: str | None = None
    """Time zone of timestamps that carry none (e.g. "UTC", "Europe/Berlin", "+01:00")."""
    frequency_unit: str = "Hz"
    """"Hz", "mHz" or "pu" (of f_nominal)."""
    frequency_kind: str = "absolute"
    """"absolute": the channel holds the frequency; "deviation": its deviation from f_nominal."""
    v_base_kv: float | None = None
    """Phase-to-phase base voltage at the PMU [kV]; needed unless voltages are in pu."""
    s_base_mva: float = 100.0
    current_direction: str = "out_of_plant"
    f_nominal_hz: float = 50.0
    frame_rate_hz: float | None = None
    """Output frame rate; None takes the median step of the file."""
    max_gap_s: float = 0.5
    on_long_gap: str = "split"
    min_segment_s: float = 30.0
    screen_samples: bool = True
    """Mask spikes and repeated frames (step 5); off for a recording already screened, such as
    the stream ``jaxdse monitor`` recorded as it used it."""
    csv_options: CsvOptions = CsvOptions()
    """How to read a CSV export (separator, decimal mark, missing-value words, rows to skip,
    units row); in TOML, these are keys of [measurement] itself (``delimiter = ";"``)."""
    p_max_mw: float | None = None
    """The plant's stated maximum active power [MW] (plant data, not a [measurement] key: the
    smallest of [aux] p_sg_max_mw, the governor's maximum and, in a fleet, the .raw PT of its
    units); a measured P above it is refused. None: not checked."""
    p_max_source: str = ""
    """Where ``p_max_mw`` comes from, for the message (e.g. "[aux] p_sg_max_mw")."""

    @property
    def three_phase(self) -> bool:
        return any(k in self.columns for k in THREE_PHASE)


def read_measurement(spec: MeasurementSpec, machine: Machine | None = None):
    """Read, validate, screen and condition one recording.

    Arguments:
        spec: the measurement description.
        machine: the machine behind the PMU: its rating and rated voltage make the plausibility
            checks of the current and of the PMU voltage base (None: not checked).

    Returns:
        ``(segments, quality)``: a list of ``(t0_s, Recording)`` (one per part between long
        gaps, longest first) and the ``data_quality`` report (a JSON-ready dict).
    """
    table = load_table(spec.file, spec.format, csv_options=spec.csv_options,
                       time_column=spec.columns.get("time"))
    return condition(table, spec, machine)


def condition(table: Table, spec: MeasurementSpec, machine: Machine | None = None):
    """:func:`read_measurement` after the file has been read (see the module docstring)."""
    src = table.source
    roles = _check_roles(spec, src)
    q: dict = {"file": src, "rows_read": 0}
    if table.notes:
        q["reader"] = dict(table.notes)
    raw = {role: table.column(spec.columns[role], role) for role in roles}
    names = {role: str(spec.columns[role]) for role in roles}
    q["unmapped_columns"] = _unmapped(table, [spec.columns[r] for r in roles])
    n_rows = len(raw["time"])
    q["rows_read"] = n_rows
    rownum = np.arange(n_rows) + table.first_row

    t, q["time_format"], q["start_time"] = _parse_time(raw.pop("time"), spec, src, names["time"],
                                                      table.first_row)
    for role, values in raw.items():
        if role in ("frequency", "stat", "valid"):
            continue
        if not np.any(np.isfinite(values)):
            raise InputError(src, "every value is NaN or empty", column=names[role],
                             row=f"{rownum[0]}-{rownum[-1]}")
    _check_stuck(raw, src, names)

    keep = np.isfinite(t)
    q["rows_without_time"] = int(np.sum(~keep))
    _check_time_order(t, keep, rownum, src, names["time"], q)
    order = np.flatnonzero(keep)[np.argsort(t[keep], kind="stable")]
    t = t[order]
    dup = np.concatenate([[False], np.diff(t) == 0])
    q["duplicate_timestamps_dropped"] = int(np.sum(dup))
    order, t = order[~dup], t[~dup]
    if order.size == n_rows and not q["out_of_order_rows"]:
        order = slice(None)  # the file as it is: views instead of copies (long files)
    if t.size < 8:
        raise InputError(src, f"only {t.size} rows with a distinct time", column=names["time"])
    rows = rownum[order]

    steps = np.diff(t)
    dt = 1.0 / spec.frame_rate_hz if spec.frame_rate_hz else _median_step(t, steps)
    _check_frame_rate(1.0 / dt, spec, src, names["time"])
    q["frame_rate_hz"] = 1.0 / dt
    q["non_uniform_steps"] = int(np.sum(np.abs(steps - dt) > 1e-6 * dt))

    v, i = _phasors(raw, order, spec, src, names)
    f = _frequency_hz(raw["frequency"][order], spec) if "frequency" in raw else None
    q["nan_samples"] = {names[r]: int(np.sum(~np.isfinite(raw[r][order]))) for r in raw
                        if r not in ("stat", "valid") and np.any(~np.isfinite(raw[r][order]))}
    if not np.any(np.isfinite(v) & np.isfinite(i)):
        raise InputError(src, "no row has all phasor channels", row=f"{rownum[0]}-{rownum[-1]}")
    _plausibility(v, i, f, t, rows, raw, order, spec, machine, src, names, q)
    v, i, f = _screen(v, i, f, t, raw, order, rows, spec, machine, names, q)
    segments = _segments(t, v, i, f, rows, raw, order, spec, src, names, q)
    q["units"] = {"voltage": spec.voltage_unit, "current": spec.current_unit,
                  "angle": spec.angle_unit, "time": q.pop("time_format"),
                  "frequency": (spec.frequency_unit if spec.frequency_kind == "absolute" else
                                f"deviation from {spec.f_nominal_hz:g} Hz in {spec.frequency_unit}")
                  if "frequency" in raw else None,
                  "v_base_kv": spec.v_base_kv, "s_base_mva": spec.s_base_mva,
                  "current_direction": spec.current_direction}
    return segments, q


UNMAPPED_LISTED = 20
"""The unmapped columns listed by name in ``data_quality`` (the rest are counted)."""


def _unmapped(table: Table, mapped) -> list[str]:
    """The columns of ``table`` that no role maps (by name or 0-based number): ignored, listed."""
    names = list(table.columns)
    used = {names[c] if isinstance(c, int) and not isinstance(c, bool) and 0 <= c < len(names)
            else str(c) for c in mapped}
    out = [n for n in names if n not in used]
    if len(out) > UNMAPPED_LISTED:
        out = out[:UNMAPPED_LISTED] + [f"... and {len(out) - UNMAPPED_LISTED} more"]
    return out


def _frequency_hz(values, spec: MeasurementSpec):
    """The frequency channel in Hz: its unit (Hz, mHz, pu of f_nominal) and kind (the frequency,
    or its deviation from f_nominal)."""
    scale = FREQUENCY_UNITS[spec.frequency_unit.lower()]
    f = np.asarray(values, dtype=float) * (spec.f_nominal_hz if scale is None else scale)
    return f + spec.f_nominal_hz if spec.frequency_kind == "deviation" else f


def _check_time_order(t, keep, rownum, src, name, q):
    """Count the rows where time goes backwards (``out_of_order_rows``: steps back between
    successive distinct times in file order; a repeat of an earlier time, a frame sent twice,
    is a duplicate, not a step back) and refuse a recording that is mostly out of order: more
    than ``MAX_OUT_OF_ORDER`` of its steps going back is no longer a few late frames or files
    joined in the wrong order but rows that run backwards, are shuffled, or a time column that
    does not belong to its rows, and sorting would estimate on a recording that never was."""
    tk, rk = t[keep], rownum[keep]
    _, first = np.unique(tk, return_index=True)
    first = np.sort(first)                      # the first row of each time, in file order
    back = np.flatnonzero(np.diff(tk[first]) < 0)
    q["out_of_order_rows"] = int(back.size)
    if back.size:
        q["out_of_order_first_row"] = int(rk[first[back[0] + 1]])
    steps = max(first.size - 1, 1)
    if back.size > MAX_OUT_OF_ORDER * steps:
        j, k = first[back[0]], first[back[0] + 1]
        raise InputError(src, f"time goes backwards at {back.size} of {steps} steps "
                         f"({100 * back.size / steps:.0f} %), the first from {tk[j]:g} s (row {rk[j]}) "
                         f"to {tk[k]:g} s: the rows run backwards, are shuffled, or the time column "
                         "does not belong to them; jaxdse sorts a recording only where at most "
                         f"{100 * MAX_OUT_OF_ORDER:g} % of the steps go back (late frames, files "
                         "joined out of order): if the rows are right, sort the file by time first",
                         column=name, row=int(rk[k]))


def order_note(q: dict) -> str | None:
    """The console line for what the time handling changed (sorted rows, dropped duplicates,
    rows without time), or None: summary.json has the counts, the console says it too."""
    parts = []
    if q.get("out_of_order_rows"):
        parts.append(f"{q['out_of_order_rows']} row(s) out of time order sorted (the first at row "
                     f"{q['out_of_order_first_row']})")
    if q.get("duplicate_timestamps_dropped"):
        parts.append(f"{q['duplicate_timestamps_dropped']} row(s) with a repeated time dropped "
                     "(the first kept)")
    if q.get("rows_without_time"):
        parts.append(f"{q['rows_without_time']} row(s) without a time dropped")
    return f"{q['file']}: " + "; ".join(parts) if parts else None


def _check_stuck(raw, src, names):
    """A magnitude or frequency channel with one value in every row is a stuck channel (a
    current of exactly 0 is an offline machine, reported downstream)."""
    for role, values in raw.items():
        if not (role == "frequency" or role.endswith("mag")):
            continue
        head = values[:1000][np.isfinite(values[:1000])]
        if head.size > 1 and np.any(head != head[0]):
            continue  # the usual case, decided on the first rows
        x = values[np.isfinite(values)]
        if x.size < 2 or np.any(x != x[0]) or (role.startswith("i_") and x[0] == 0):
            continue
        hint = ("; if the PMU does not compute frequency, leave measurement.columns.frequency out "
                "(jaxdse derives it from the voltage angle)" if role == "frequency" else "")
        raise InputError(src, f"holds one value ({x[0]:g}) in every row: a stuck channel{hint}",
                         column=names[role])


def _check_roles(spec: MeasurementSpec, src) -> list[str]:
    cols = spec.columns
    unknown = [k for k in cols if k not in COLUMN_ROLES]
    if unknown:
        raise InputError(src, f"unknown column role; use {', '.join(COLUMN_ROLES[:8])} or "
                         "v_a_mag ... i_c_ang", key=f"measurement.columns.{unknown[0]}")
    if "time" not in cols:
        raise InputError(src, "the time column is required", key="measurement.columns.time")
    need = THREE_PHASE if spec.three_phase else POSITIVE
    if spec.three_phase and any(k in cols for k in POSITIVE):
        raise InputError(src, "give either positive-sequence or three-phase columns, not both",
                         key="measurement.columns")
    missing = [k for k in need if k not in cols]
    if missing:
        raise InputError(src, "required column mapping is missing",
                         key=f"measurement.columns.{missing[0]}")
    if "stat" in cols and "valid" in cols:
        raise InputError(src, "give either a STAT column or a data-valid column, not both",
                         key="measurement.columns")
    extra = [r for r in ("frequency", "stat", "valid") if r in cols]
    return ["time"] + extra + list(need)


# --- time -------------------------------------------------------------------------------------

def _parse_time(raw, spec: MeasurementSpec, src, name, first_row):
    """Seconds since the first row, the time format used, and the start time (ISO) if known."""
    if raw.dtype.kind in "fiu":
        if spec.time_unit == "iso" or spec.time_format:
            raise InputError(src, "the time column holds numbers, not timestamps: set "
                             "measurement.time_unit = \"s\" or \"ms\"", column=name)
        scale = 1e-3 if spec.time_unit == "ms" else 1.0
        return raw.astype(float) * scale, spec.time_unit, None
    import pandas as pd

    text = pd.Series(raw, dtype=object)
    blank = text.isin(("", "nan", "NaN", "NaT"))
    fmt = spec.time_format or "ISO8601"
    try:
        parsed = pd.to_datetime(text.where(~blank), format=fmt, errors="coerce")
    except ValueError as err:  # several time zones in one column
        if any(w in str(err).lower() for w in ("mixed", "time zone", "timezone", "offset")):
            raise InputError(src, "timestamps mix time zones and naive times", column=name) from None
        raise InputError(src, f"timestamps cannot be read with format {fmt!r} ({err})",
                         column=name) from None
    if parsed.dtype == object:
        raise InputError(src, "timestamps mix time zones and naive times", column=name)
    bad = parsed.isna() & ~blank
    if bad.any():
        k = int(np.flatnonzero(bad.to_numpy())[0])
        cell = str(text.iloc[k])
        hint = _time_format_hint(cell, spec.time_format)
        what = "an ISO 8601 timestamp" if spec.time_format is None else f"a timestamp in {fmt!r}"
        raise InputError(src, f"{cell!r} is neither seconds nor {what}{hint}", column=name,
                         row=k + first_row)
    zone = parsed.dt.tz
    if zone is None and spec.timezone:
        try:
            parsed = parsed.dt.tz_localize(_zone(spec.timezone), ambiguous="raise",
                                           nonexistent="raise")
        except Exception as err:  # noqa: BLE001 (pandas raises several types here)
            raise InputError(src, f"timestamps cannot be placed in time zone {spec.timezone!r} "
                             f"({str(err).splitlines()[0]})", key="measurement.timezone") from None
    ok = parsed.notna().to_numpy()
    seconds = np.full(len(parsed), np.nan)
    if ok.any():
        first = parsed[ok].iloc[0]
        seconds[ok] = (parsed[ok] - first).dt.total_seconds().to_numpy()
        start = first.isoformat()
    else:
        start = None
    label = "iso" if spec.time_format is None else f"timestamps {spec.time_format}"
    if zone is None and not spec.timezone:
        label += " (no time zone)"
    return seconds, label, start


_TWELVE_HOUR = re.compile(r"\d\s*([AaPp])\.?[Mm]\.?\s*$")


def _time_format_hint(cell: str, time_format: str | None) -> str:
    """What to set for a timestamp ``cell`` that does not parse: a time_format that fits the
    cell's layout (day/month order, fractions, a 12-hour clock with AM/PM), or nothing."""
    twelve = bool(_TWELVE_HOUR.search(cell.strip()))
    if time_format is not None:
        if twelve and "%p" not in time_format:
            fixed = time_format.replace("%H", "%I") + ("" if "%p" in time_format else " %p")
            return (f"; the timestamps use a 12-hour clock (AM/PM): use %I for the hour and %p, "
                    f"e.g. time_format = {fixed!r}")
        return ""
    clock = "%I:%M:%S" if twelve else "%H:%M:%S"
    frac = ".%f" if re.search(r":\d{2}[.,]\d", cell) else ""
    ampm = " %p" if twelve else ""
    if "/" in cell:
        example = f"%m/%d/%Y {clock}{frac}{ampm}"
        return (f"; set measurement.time_format, e.g. {example!r} (or %d/%m/%Y: day first)"
                + ("; a 12-hour clock (AM/PM) needs %I and %p, not %H" if twelve else ""))
    if twelve:
        date = "%Y-%m-%d " if re.match(r"\d{4}-\d{2}-\d{2}", cell) else ""
        return (f"; the timestamps use a 12-hour clock (AM/PM): set measurement.time_format with "
                f"%I and %p, e.g. {date + clock + frac + ampm!r}")
    return "; set measurement.time_format (strftime codes) for other layouts"


def _zone(name: str):
    """A time zone: an IANA name, "UTC", or a fixed offset "+hh:mm"."""
    import datetime as _dt
    import re

    m = re.fullmatch(r"([+-])(\d{2}):?(\d{2})", name.strip())
    if m:
        sign = 1 if m.group(1) == "+" else -1
        return _dt.timezone(sign * _dt.timedelta(hours=int(m.group(2)), minutes=int(m.group(3))))
    return name


def _check_system_rate(rate, spec: MeasurementSpec, src, name):
    """Without a frequency channel: a reporting rate of the other system frequency (30 frames/s
    with f_nominal 50 Hz, 25 frames/s with 60 Hz) means a wrong machine.f_nominal_hz."""
    for f_sys, rates in SYSTEM_RATES_HZ.items():
        if f_sys != spec.f_nominal_hz and any(abs(rate / r - 1) < 1e-3 for r in rates):
            raise InputError(src, f"{rate:.4g} frames/s is a reporting rate of {f_sys:g} Hz systems "
                             f"but machine.f_nominal_hz = {spec.f_nominal_hz:g} and no frequency "
                             f"channel tells otherwise: set machine.f_nominal_hz = {f_sys:g}, or map "
                             "the frequency column (measurement.columns.frequency)", column=name)


def _median_step(t, steps) -> float:
    """The median time step, refined to span / (whole number of steps) when the span is one
    (the times of a long file are rounded: a grid of the median step would drift off them)."""
    dt = float(np.median(steps))
    k = round((t[-1] - t[0]) / dt)
    return (t[-1] - t[0]) / k if abs((t[-1] - t[0]) / dt - k) < 1e-3 else dt


def _check_frame_rate(rate, spec: MeasurementSpec, src, name):
    lo, hi = FRAME_RATE_HZ
    if lo <= rate <= hi:
        return
    hint = ""
    if spec.time_unit == "s" and rate < lo and lo <= rate * 1e3 <= hi:
        hint = ": the time looks like milliseconds; set measurement.time_unit = \"ms\""
    elif spec.time_unit == "ms" and rate > hi and lo <= rate / 1e3 <= hi:
        hint = ": the time looks like seconds; set measurement.time_unit = \"s\""
    elif spec.frame_rate_hz:
        hint = ": check measurement.frame_rate_hz"
    else:
        hint = f": check measurement.time_unit ({spec.time_unit!r})"
    raise InputError(src, f"the median time step gives {rate:.4g} frames/s, outside the "
                     f"{lo:g}-{hi:g} frames/s that PMUs report{hint}", column=name)


# --- units ------------------------------------------------------------------------------------

def _phasors(raw, order, spec: MeasurementSpec, src, names):
    """Positive-sequence V and I [pu, system base, generator convention] per kept row."""
    for key in ("voltage_unit", "current_unit", "angle_unit", "current_direction", "frequency_unit",
                "frequency_kind"):
        problem = spec_value_error(key, getattr(spec, key))
        if problem:
            raise InputError(src, problem, key=f"measurement.{key}")
    vu, cu, au = spec.voltage_unit.lower(), spec.current_unit.lower(), spec.angle_unit.lower()
    if (vu != "pu" or cu != "pu") and not spec.v_base_kv:
        raise InputError(src, "v_base_kv (phase-to-phase) is needed to convert to per unit",
                         key="measurement.v_base_kv")
    ang = ANGLE_UNITS[au]

    def phasor(mag, arg):
        return raw[mag][order] * np.exp(1j * ang * raw[arg][order])

    if spec.three_phase:
        v, i = (np.asarray(positive_sequence(np.stack(
            [phasor(f"{q}_{p}_mag", f"{q}_{p}_ang") for p in "abc"], axis=-1))) for q in "vi")
    else:
        v, i = phasor("v_mag", "v_ang"), phasor("i_mag", "i_ang")

    if VOLTAGE_UNITS[vu][0] is not None:
        v = v * VOLTAGE_UNITS[vu][0] / voltage_base_v(spec.v_base_kv, vu)
    if CURRENT_UNITS[cu] is not None:
        i = i * CURRENT_UNITS[cu] / current_base_a(spec.s_base_mva, spec.v_base_kv)
    if spec.current_direction == "into_plant":
        i = -i
    return v, i


def _machine_scale(spec: MeasurementSpec, machine: Machine | None) -> float | None:
    """pu of the machine rating per pu of the system base, if the machine is known."""
    return None if machine is None else spec.s_base_mva / float(machine.s_rated_mva)


# --- plausibility (whole recording) ------------------------------------------------------------

def _plausibility(v, i, f, t, rows, raw, order, spec: MeasurementSpec, machine, src, names, q):
    fin = np.isfinite(v) & np.isfinite(i)
    vm = float(np.median(np.abs(v[fin])))
    vname = names.get("v_mag", names.get("v_a_mag"))
    iname = names.get("i_mag", names.get("i_a_mag"))
    aname = names.get("v_ang", names.get("v_a_ang"))
    if not PLAUSIBLE_VOLTAGE_PU[0] <= vm <= PLAUSIBLE_VOLTAGE_PU[1]:
        lo, hi = PLAUSIBLE_VOLTAGE_PU
        vu = spec.voltage_unit
        hint = ""
        if vu.lower().endswith("_ll") and lo <= vm * np.sqrt(3) <= hi:
            hint = f": the values look phase-to-ground, set voltage_unit = \"{vu[:-3]}_LN\""
        elif vu.lower().endswith("_ln") and lo <= vm / np.sqrt(3) <= hi:
            hint = f": the values look phase-to-phase, set voltage_unit = \"{vu[:-3]}_LL\""
        raise InputError(src, f"median voltage is {vm:.4g} pu on v_base_kv = {spec.v_base_kv} kV: "
                         f"check measurement.voltage_unit ({vu!r}) and v_base_kv{hint}",
                         column=vname)
    scale = _machine_scale(spec, machine)
    if scale is not None:
        im = float(np.median(np.abs(i[fin]))) * scale
        q["median_current_pu_machine"] = round(im, 6)
        if im > MAX_CURRENT_PU_MACHINE:
            raise InputError(src, f"median current is {im:.4g} pu of the machine rating: check "
                             f"measurement.current_unit ({spec.current_unit!r}) and the bases", column=iname)
        s = v * np.conj(i)
        p = float(np.median(s[fin].real)) * scale
        q["median_p_pu_machine"] = round(p, 6)
        s_mag = float(np.median(np.abs(s[fin]))) * scale
        if 0 < im < MIN_CURRENT_PU_MACHINE and p > MIN_POWER_FACTOR * s_mag:
            raise InputError(src, f"median current is {im:.3g} pu of the machine rating yet carries "
                             f"power at power factor {p / s_mag:.2f}: a scale mistake; check "
                             f"measurement.current_unit ({spec.current_unit!r}: kA?), a CT ratio "
                             "(secondary amperes?) and the bases", column=iname)
        if p < MIN_POWER_PU_MACHINE:
            if spec.current_direction == "into_plant":
                hint = ("with measurement.current_direction = \"into_plant\" already set: check "
                        "the CT polarity (does the current flow out of the plant after all? then "
                        "leave current_direction out) and the current angle column (the voltage's "
                        "angle mapped twice, a 180 degree reference)")
            else:
                hint = ("if the current is measured towards the plant set "
                        "measurement.current_direction = \"into_plant\"")
            raise InputError(src, f"median active power is {p:.3g} pu (the plant absorbs power): "
                             + hint, column=iname, row=f"{rows[0]}-{rows[-1]}")
        _check_rating(np.abs(i) * scale, s * scale, vm, t, fin, rows, spec, machine, src, iname)
        _check_voltage_base(spec, machine, src, vname)
    if f is not None and np.any(np.isfinite(f)):
        _check_frequency(f, spec, src, names["frequency"])
    else:
        _check_system_rate(1.0 / np.median(np.diff(t)), spec, src, names["time"])
    _check_angles(v, t, f, raw, order, spec, src, aname, q)


def _check_frequency(f, spec: MeasurementSpec, src, fname):
    """The frequency channel [Hz, after its declared unit and kind] near nominal, and within a
    fraction of a hertz of its median; the hint names the kind or unit the values look like."""
    f0, fm = spec.f_nominal_hz, float(np.nanmedian(f))
    declared = (f"frequency_kind = {spec.frequency_kind!r}, frequency_unit = {spec.frequency_unit!r}")
    if abs(fm - f0) > MAX_FREQUENCY_OFFSET * f0:
        # The declarations that put the median near nominal; of those, the one whose spread is
        # most like a grid's (TYPICAL_FREQUENCY_SPREAD_HZ): a small median fits several units.
        scale = FREQUENCY_UNITS[spec.frequency_unit.lower()] or f0
        channel = (f - (f0 if spec.frequency_kind == "deviation" else 0.0)) / scale
        fits = []
        for k in FREQUENCY_KINDS:
            for u in UNIT_KEYS["frequency_unit"]:
                alt = channel * (FREQUENCY_UNITS[u.lower()] or f0) + (f0 if k == "deviation" else 0.0)
                m = float(np.nanmedian(alt))
                if abs(m - f0) <= MAX_FREQUENCY_OFFSET * f0:
                    spread = max(float(np.nanmedian(np.abs(alt - m))), 1e-12)
                    fits.append((abs(np.log(spread / TYPICAL_FREQUENCY_SPREAD_HZ)), k, u))
        if fits:
            _, k, u = min(fits)
            what = {"absolute": "the frequency itself", "deviation": "a deviation from nominal"}[k]
            hint = (f"; the values look like {what} in {u}: " + (
                f"leave measurement.frequency_kind out (frequency_unit = \"{u}\")" if k == "absolute" else
                f"set measurement.frequency_kind = \"deviation\" and frequency_unit = \"{u}\""))
        else:
            hint = "; check machine.f_nominal_hz, and measurement.frequency_unit"
        raise InputError(src, f"median frequency is {fm:.4g} Hz ({declared}) but "
                         f"machine.f_nominal_hz is {f0:g}{hint}", column=fname)
    spread = float(np.nanmedian(np.abs(f - fm)))
    if spread > MAX_FREQUENCY_SPREAD_HZ:
        hint = (": a deviation in mHz? set measurement.frequency_unit = \"mHz\""
                if spec.frequency_unit.lower() != "mhz" and spread * 1e-3 < MAX_FREQUENCY_SPREAD_HZ
                else ": check measurement.frequency_unit")
        raise InputError(src, f"the frequency strays {spread:.3g} Hz from its median {fm:.5g} Hz "
                         f"(median absolute deviation; {declared}); grids stay within a fraction of "
                         f"a hertz{hint}", column=fname)


def _check_rating(i_pu, s_pu, v_pu, t, fin, rows, spec: MeasurementSpec, machine: Machine, src, iname):
    """The current and the reactive power against what the machine can carry (issue-19 item 4).

    * The operating point: median apparent power above ``MAX_LOADING`` x the rating.
    * Armature current [pu of the rating] beyond IEEE C50.13's short-time capability: runs above
      ``MAX_LOADING`` accumulate (I^2 - 1) dt; more than ``SHORT_TIME_CAPABILITY_S`` is
      a current no stator carries (1.16 x rating for 120 s, 1.30 x for 60 s, 2.26 x for 10 s).
      A fault or a swing of a few seconds passes.
    * Median reactive power beyond the capability curve: lagging above ``MAX_Q_LAGGING`` of
      the rating (the field-heating limit at zero active power, for any rated power factor of
      0.85 or more), or leading below ``LEADING_Q_MARGIN`` x the steady-state stability limit
      -V^2/x_d.

    Either means a wrong current or voltage scale or angle reference (a CT ratio, peak instead of
    RMS, a base, a phase mapping), or a wrong rating: refused, with the numbers.
    """
    rating = float(machine.s_rated_mva)
    fix = (f"check measurement.current_unit ({spec.current_unit!r}), a CT ratio (peak instead of "
           f"RMS?), the bases and machine.s_rated_mva ({rating:g} MVA)")
    load = float(np.median(np.abs(s_pu[fin])))
    if load > MAX_LOADING:
        raise InputError(src, f"median apparent power is {load:.3g} pu of the rating ({load * rating:.4g} "
                         f"of {rating:g} MVA), above {MAX_LOADING:g} x: no machine runs so far above its "
                         "rating as an operating point; " + fix + " (or does the measured current "
                         "include units outside this rating?)", column=iname)
    over = fin & (i_pu > MAX_LOADING)
    half = max(int(round(OVERLOAD_MIN_S / 2 / np.median(np.diff(t)))), 1)
    count = np.concatenate([[0], np.cumsum(over)])
    lo, hi = np.clip(np.arange(t.size) - half, 0, t.size), np.clip(np.arange(t.size) + half + 1, 0, t.size)
    over &= (count[hi] - count[lo]) == hi - lo  # above for OVERLOAD_MIN_S around: no spike, no fault
    if np.any(over):  # (I^2 - 1) t accumulated over each run above the margin
        inc = np.where(over, (np.where(fin, i_pu, 0.0) ** 2 - 1.0) * np.diff(t, prepend=t[0]), 0.0)
        heat = np.cumsum(inc)
        first = np.maximum.accumulate(np.where(over & ~np.roll(over, 1), np.arange(t.size), 0))
        excess = np.where(over, heat - heat[first] + inc[first], 0.0)
        b = int(np.argmax(excess))
        a = int(first[b])
        if excess[b] > SHORT_TIME_CAPABILITY_S:
            raise InputError(src, f"the current stays above the machine's short-time capability: "
                             f"{float(np.mean(i_pu[a:b + 1])):.3g} pu of the rating on average (peak "
                             f"{float(np.max(i_pu[a:b + 1])):.3g}) for {t[b] - t[a]:.3g} s; IEEE C50.13 "
                             f"allows (I^2 - 1) t = {SHORT_TIME_CAPABILITY_S:g} s, this run has "
                             f"{excess[b]:.3g} s; " + fix, column=iname, row=f"{rows[a]}-{rows[b]}")
    if spec.p_max_mw:
        _check_p_max(s_pu.real * rating, t, fin, rows, spec, rating, src, iname)
    q_pu = float(np.median(s_pu[fin].imag))
    q_min = -LEADING_Q_MARGIN * v_pu**2 / float(machine.xd_pu)
    if q_pu > MAX_Q_LAGGING or q_pu < q_min:
        side = (f"above {MAX_Q_LAGGING:g} pu, the field-heating limit" if q_pu > 0 else
                f"below {q_min:.3g} pu, {LEADING_Q_MARGIN:g} x the steady-state stability limit "
                f"-V^2/x_d (x_d = {float(machine.xd_pu):g} pu)")
        p_pu = float(np.median(s_pu[fin].real))
        raise InputError(src, f"median reactive power is {q_pu:.3g} pu of the rating ({side}) at "
                         f"P = {p_pu:.3g} pu, power factor {p_pu / np.hypot(p_pu, q_pu):.2f}: outside "
                         "the machine's capability; check the current angle reference (phase "
                         "mapping, a transformer's 30 degree shift) and " + fix.removeprefix("check "),
                         column=iname)


def _check_p_max(p_mw, t, fin, rows, spec: MeasurementSpec, rating: float, src, iname):
    """The measured active power against the plant's stated maximum (``spec.p_max_mw``): the
    median over the record above it by more than ``P_MAX_TOLERANCE``, or a run above it by more
    than ``P_MAX_RUN_TOLERANCE`` for longer than ``P_MAX_RUN_S``, is refused with the numbers and
    the likely cause. A current logged as peak instead of RMS (x1.414) at part load stays under
    every rating check of the machine; against what the turbine can deliver it does not."""
    p_max = float(spec.p_max_mw)
    source = f" ({spec.p_max_source})" if spec.p_max_source else ""
    med = float(np.median(p_mw[fin]))
    where, what = f"{rows[0]}-{rows[-1]}", f"median active power is {med:.4g} MW"
    value = med
    if med <= p_max * (1 + P_MAX_TOLERANCE):
        above = fin & (p_mw > p_max * (1 + P_MAX_RUN_TOLERANCE))
        starts, stops = _runs(above)
        if not starts.size:
            return
        long = np.argmax(t[stops - 1] - t[starts])
        a, b = int(starts[long]), int(stops[long]) - 1
        if t[b] - t[a] <= P_MAX_RUN_S:
            return
        value = float(np.median(p_mw[a:b + 1]))
        where = f"{rows[a]}-{rows[b]}"
        what = f"active power stays at {value:.4g} MW (median) for {t[b] - t[a]:.3g} s"
    cause = (f"the current logged as peak instead of RMS (x{PEAK_TO_RMS:.3f}: {value:.4g} / "
             f"{PEAK_TO_RMS:.3f} = {value / PEAK_TO_RMS:.4g} MW)" if value / PEAK_TO_RMS <= p_max
             else "a CT ratio")
    raise InputError(src, f"{what} ({value / rating:.3g} pu of the {rating:g} MVA rating), "
                     f"{100 * (value / p_max - 1):.0f} % above the plant's stated maximum of "
                     f"{p_max:.4g} MW{source}: no turbine delivers more than its maximum; likely "
                     f"{cause}, else the bases or the current unit: check "
                     f"measurement.current_unit ({spec.current_unit!r}), the CT ratio and the "
                     "plant's maximum", column=iname, row=where)


def _check_voltage_base(spec: MeasurementSpec, machine: Machine, src, vname):
    """The PMU voltage base against the machine's rated voltage for the declared location."""
    if not spec.v_base_kv:
        return  # voltages in pu: the base is not stated, nothing to compare
    ratio = spec.v_base_kv / float(machine.v_rated_kv)
    rated = f"machine.v_rated_kv = {float(machine.v_rated_kv):g} kV"
    if spec.location == "terminal" and not TERMINAL_BASE_RATIO[0] <= ratio <= TERMINAL_BASE_RATIO[1]:
        raise InputError(src, f"location = \"terminal\" but v_base_kv = {spec.v_base_kv:g} kV and "
                         f"{rated}: a PMU on the HV side needs location = \"hv\" or \"substation\"",
                         key="measurement.location")
    if spec.location != "terminal" and ratio < HV_BASE_RATIO:
        raise InputError(src, f"location = {spec.location!r} but v_base_kv = {spec.v_base_kv:g} kV is "
                         f"the machine's voltage ({rated}): at the terminal, set location = \"terminal\"",
                         key="measurement.location")


def _check_angles(v, t, f, raw, order, spec: MeasurementSpec, src, aname, q):
    """Angle steps and drift against the declared angle unit and f_nominal."""
    fin = np.isfinite(v)
    tv, ang = t[fin], _unwrap(np.angle(v[fin]))
    if tv.size < 3:
        return
    step = np.abs(np.diff(ang))
    contiguous = np.diff(tv) < 1.5 * np.median(np.diff(tv))
    raw_ang = np.asarray(raw[_angle_role(raw)][order], dtype=float)[fin]
    raw_steps = np.abs(np.diff(raw_ang))
    unit = spec.angle_unit.lower()
    if unit == "rad" and (np.any(np.abs(raw_steps - 360.0) < 10.0)
                          or np.mean(step[contiguous] > MAX_ANGLE_STEP_RAD) > OUTLIER_SHARE):
        k = int(np.argmax(np.where(contiguous, step, 0)))
        raise InputError(src, f"the voltage angle jumps by {raw_steps[k]:.4g} between rows (as "
                         "radians, not physical): the angles look like degrees; set "
                         "measurement.angle_unit = \"deg\"", column=aname)
    if unit == "deg" and np.mean(np.abs(raw_ang) <= np.pi + 1e-3) >= 1 - OUTLIER_SHARE and \
            np.any(np.abs(raw_steps - 2 * np.pi) < 0.2):
        raise InputError(src, "the voltage angle stays within +-3.14 and wraps at +-pi: the angles "
                         "look like radians; set measurement.angle_unit = \"rad\"", column=aname)
    if contiguous.any():
        rate = float(np.median(np.diff(ang)[contiguous] / np.diff(tv)[contiguous])) / (2 * np.pi)
        q["voltage_angle_drift_hz"] = round(rate, 6)
        if abs(rate) > MAX_ANGLE_DRIFT_HZ:
            raise InputError(src, f"the voltage angle turns at {rate:.3g} Hz against the nominal "
                             f"frequency {spec.f_nominal_hz:g} Hz (grids stay within a fraction of a "
                             "hertz): check machine.f_nominal_hz and measurement.angle_unit",
                             column=aname)


def _angle_role(raw) -> str:
    return "v_ang" if "v_ang" in raw else "v_a_ang"


# --- screening (single samples) ----------------------------------------------------------------

def _runs(mask):
    """(start, stop) index pairs of the runs of True in ``mask``."""
    d = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def _spikes(x, floor):
    """(moved, spikes) of ``x``.

    Outliers deviate from a running median by more than ``SPIKE_SIGMAS`` robust standard
    deviations (and ``floor``) (Hampel). Spikes are the runs of at most ``SPIKE_MAX_SAMPLES``
    outliers that also stand out from the line through the samples on either side by
    ``SPIKE_TREND`` times the curvature there: the crest of a swing sampled a few times per
    period leaves an 11-sample median far behind (a 1.75 Hz swing at 30 frames/s), but not the
    curve its neighbours draw. ``moved`` marks the outliers and both samples of a jump (a step
    beyond ``SPIKE_SIGMAS`` times the running median of the sample-to-sample changes: a
    switching event, which a running median of the values does not flag)."""
    from scipy.ndimage import median_filter

    fin = np.isfinite(x)
    none = np.zeros(x.shape, bool)
    if fin.sum() < 2 * SPIKE_HALF_WIDTH + 1:
        return none, none
    idx = np.arange(x.size)
    xf = x if fin.all() else np.where(fin, x, np.interp(idx, idx[fin], x[fin]))
    hw, size = SPIKE_HALF_WIDTH, 2 * SPIKE_HALF_WIDTH + 1
    med = median_filter(_extend(xf, hw), size=size, mode="nearest")[hw:-hw]
    dev = np.abs(xf - med)
    mad = median_filter(dev, size=size, mode="mirror")
    outliers = fin & (dev > np.maximum(SPIKE_SIGMAS * 1.4826 * mad, floor))
    spikes = outliers.copy()
    n = x.size
    for a, b in zip(*_runs(outliers)):
        if b - a > SPIKE_MAX_SAMPLES:
            spikes[a:b] = False
        elif a >= 3 and b + 3 <= n:   # at the edges the Hampel test alone decides
            lo, hi = xf[a - 1], xf[b]
            line = lo + (hi - lo) * (np.arange(a, b) - (a - 1)) / (b - a + 1)
            curve = max(abs(xf[a - 1] - 2 * xf[a - 2] + xf[a - 3]),
                        abs(xf[b] - 2 * xf[b + 1] + xf[b + 2]))
            spikes[a:b] = np.max(np.abs(xf[a:b] - line)) > SPIKE_TREND * curve * (b - a + 1) ** 2
    step = np.abs(np.diff(xf))
    usual = median_filter(step, size=size, mode="nearest")
    jump = fin[1:] & fin[:-1] & (step > SPIKE_SIGMAS * 1.4826 * usual)
    moved = outliers.copy()
    moved[1:] |= jump
    moved[:-1] |= jump
    return moved, spikes


def _answered(spikes, other):
    """The runs of ``spikes`` that ``other`` (the other phasor's outliers) meets within a frame
    of any of their samples, whole."""
    near = _within_a_frame(other)
    keep = np.zeros(spikes.shape, bool)
    for a, b in zip(*_runs(spikes)):
        keep[a:b] = near[a:b].any()
    return keep


def _within_a_frame(mask):
    """``mask`` widened by one sample on each side."""
    out = mask.copy()
    out[1:] |= mask[:-1]
    out[:-1] |= mask[1:]
    return out


def _extend(x, hw):
    """``x`` with ``hw`` samples added at each end on a robust (Theil-Sen) line through its
    first and last ``2 hw + 1`` samples: the running median then follows a trend up to the
    edges (a ramp gives no deviation) and a spike in the first or last samples stands out."""
    m = 2 * hw + 1
    k = np.arange(m)
    a, b = np.triu_indices(m, 1)

    def line(y, at):
        slope = np.median((y[b] - y[a]) / (b - a))
        return np.median(y - slope * k) + slope * at

    return np.concatenate([line(x[:m], np.arange(-hw, 0)), x, line(x[-m:], np.arange(m, m + hw))])


def _screen(v, i, f, t, raw, order, rows, spec: MeasurementSpec, machine, names, q):
    """Mask invalid rows, out-of-range samples and spikes (they become gaps); report them."""
    report = {}

    def note(kind, column, mask):
        if mask.any():
            k = int(np.flatnonzero(mask)[0])
            report.setdefault(kind, {})[column] = {"samples": int(mask.sum()), "first_row": int(rows[k])}

    bad_v = np.zeros(v.shape, bool)
    bad_i = np.zeros(i.shape, bool)
    if "stat" in raw:
        word = np.nan_to_num(raw["stat"][order], nan=0xFFFF).astype(np.int64)
        invalid = (word & STAT_INVALID_BITS) != 0
        note("stat_invalid", names["stat"], invalid)
        bad_v |= invalid
        bad_i |= invalid
    if "valid" in raw:
        flag = raw["valid"][order]
        invalid = ~(np.isfinite(flag) & (flag != 0))
        note("flagged_invalid", names["valid"], invalid)
        bad_v |= invalid
        bad_i |= invalid
    vname = names.get("v_mag", names.get("v_a_mag"))
    iname = names.get("i_mag", names.get("i_a_mag"))
    vm, im = np.abs(v), np.abs(i)
    out_v = np.isfinite(vm) & ((vm < VOLTAGE_RANGE_PU[0]) | (vm > VOLTAGE_RANGE_PU[1]))
    note("out_of_range", vname, out_v)
    bad_v |= out_v
    scale = _machine_scale(spec, machine)
    if scale is not None:
        out_i = np.isfinite(im) & (im * scale > MAX_CURRENT_SAMPLE_PU_MACHINE)
        note("out_of_range", iname, out_i)
        bad_i |= out_i
    ok_v, ok_i = np.isfinite(v) & ~bad_v, np.isfinite(i) & ~bad_i
    stale = _stale(v, i, ok_v & ok_i) if spec.screen_samples else np.zeros(v.shape, bool)
    note("stale_frames", f"{vname}, {iname}", stale)
    bad_v |= stale
    bad_i |= stale
    ok_v &= ~stale
    ok_i &= ~stale
    # Spikes in magnitude and (detrended) angle of each phasor; one in the voltage and the
    # current at once is a disturbance of the plant, not a measurement error.
    if spec.screen_samples:
        (ov, sv), (ova, sva) = _spikes(np.where(ok_v, vm, np.nan), SPIKE_FLOOR["magnitude"]
                                       * np.nanmedian(vm[ok_v])), \
            _spikes(_unwrapped(v, ok_v), SPIKE_FLOOR["angle_rad"])
        (oi, si), (oia, sia) = _spikes(np.where(ok_i, im, np.nan), SPIKE_FLOOR["magnitude"]
                                       * np.nanmedian(im[ok_i])), \
            _spikes(_unwrapped(i, ok_i), SPIKE_FLOOR["angle_rad"])
        sv, si = sv | sva, si | sia
        # the other phasor an outlier too, within a frame of any sample of the run (any run
        # length: a fault's current stays off after the voltage dip): a disturbance of the
        # plant, kept whole. Sample by sample, a 3-frame fault dip lost its last frame: the
        # machine's fault current decays within the dip back inside the Hampel band that the
        # fault itself widens (ACTIVSg2000's generated recordings: 30 % dips bridged at 88 %)
        both = _answered(sv, oi | oia) | _answered(si, ov | ova)
    else:
        sv = si = both = np.zeros(v.shape, bool)
    note("spikes", vname, sv & ~both)
    note("spikes", iname, si & ~both)
    bad_v |= sv & ~both
    bad_i |= si & ~both
    if f is not None:
        fname = names["frequency"]
        out_f = np.isfinite(f) & (np.abs(f - spec.f_nominal_hz) > MAX_FREQUENCY_SAMPLE_OFFSET_HZ)
        note("out_of_range", fname, out_f)
        f = np.where(out_f, np.nan, f)
        f = np.where(stale, np.nan, f)
        sf = _spikes(f, SPIKE_FLOOR["frequency_hz"])[1] if spec.screen_samples else np.zeros(f.shape, bool)
        note("spikes", fname, sf)
        f = np.where(sf, np.nan, f)
    bad = bad_v | bad_i
    report["masked_samples"] = int(bad.sum())
    q["screening"] = report
    return np.where(bad, np.nan, v), np.where(bad, np.nan, i), f


def _stale(v, i, ok):
    """Every frame of a run that repeats exactly in both phasors, when such repeats are rare
    (``REPEATS_RARE``); all frames of the run, as which of them (if any) is genuine is unknown."""
    same = ok[1:] & ok[:-1] & (v[1:] == v[:-1]) & (i[1:] == i[:-1])
    out = np.zeros(v.shape, bool)
    pairs = int(np.sum(ok[1:] & ok[:-1]))
    if not same.any() or same.sum() > REPEATS_RARE * pairs:
        return out
    out[1:] |= same
    out[:-1] |= same
    return out


def _unwrap(a):
    """np.unwrap for 1-d angles [rad], in fewer passes (whole multiples of 2 pi are removed)."""
    out = a.copy()
    if a.size > 1:
        out[1:] -= 2 * np.pi * np.cumsum(np.round(np.diff(a) / (2 * np.pi)))
    return out


def _unwrapped(x, ok):
    """Unwrapped angle of the samples ``ok`` (NaN elsewhere)."""
    out = np.full(x.shape, np.nan)
    out[ok] = _unwrap(np.angle(x[ok]))
    return out


# --- gaps, splitting, resampling --------------------------------------------------------------

def _segments(t, v, i, f, rows, raw, order, spec: MeasurementSpec, src, names, q):
    dt = 1.0 / q["frame_rate_hz"]
    valid = np.isfinite(v) & np.isfinite(i)
    if not np.any(valid):
        raise InputError(src, "no row has all phasor channels after screening",
                         row=f"{rows[0]}-{rows[-1]}")
    tv, vv, iv, rows_v = t[valid], v[valid], i[valid], rows[valid]
    # Unwrap on the valid samples only, then interpolate magnitude and angle.
    v_ang, i_ang = _unwrap(np.angle(vv)), _unwrap(np.angle(iv))
    q["angle_wraps_unwrapped"] = int(np.sum(np.abs(np.diff(np.angle(vv))) > np.pi)
                                     + np.sum(np.abs(np.diff(np.angle(iv))) > np.pi))
    gap_len = np.diff(tv) - dt
    is_gap = gap_len > 0.5 * dt
    long_gap = gap_len > spec.max_gap_s + 1e-9 * dt
    q["bridged_gaps"] = [{"start_s": round(float(tv[k] - t[0] + dt), 6),
                          "length_s": round(float(gap_len[k]), 6), "row": int(rows_v[k] + 1)}
                         for k in np.flatnonzero(is_gap & ~long_gap)]
    if np.any(long_gap):
        k = int(np.flatnonzero(long_gap)[0])
        if spec.on_long_gap == "error":
            culprit = _gap_culprit(raw, order, valid, tv[k], tv[k + 1], t, names)
            raise InputError(src, f"gap of {gap_len[k]:.3f} s from t = {tv[k] - t[0] + dt:.3f} s is "
                             f"longer than measurement.max_gap_s = {spec.max_gap_s} s",
                             column=culprit, row=int(rows_v[k] + 1))
    cuts = np.flatnonzero(long_gap) + 1
    q["split_at_gaps"] = [{"start_s": round(float(tv[c - 1] - t[0] + dt), 6),
                           "length_s": round(float(gap_len[c - 1]), 6), "row": int(rows_v[c - 1] + 1)}
                          for c in cuts]
    q["edge_rows_trimmed"] = int(np.flatnonzero(valid)[0] + (len(valid) - 1 - np.flatnonzero(valid)[-1]))
    measured_f = f is not None and np.any(np.isfinite(f))
    if f is not None and not measured_f:
        q["frequency_all_nan"] = True
    q["frequency"] = (f"measured ({names['frequency']})" if measured_f
                      else "derived from the voltage angle")
    segments, dropped = [], []
    for part in np.split(np.arange(tv.size), cuts):
        t_part = tv[part]
        n = int(np.floor((t_part[-1] - t_part[0]) / dt + 1e-3)) + 1  # rounding of long files
        if (n - 1) * dt < spec.min_segment_s:
            dropped.append({"start_s": round(float(t_part[0] - t[0]), 6),
                            "length_s": round(float((n - 1) * dt), 6)})
            continue
        grid = t_part[0] + dt * np.arange(n)
        exact = _on_grid(grid, t_part, dt)  # a uniform file, the common case: no interpolation

        def on_grid(x, exact=exact, grid=grid, t_part=t_part):
            return x if exact else np.interp(grid, t_part, x)

        segments.append((float(t_part[0] - t[0]), Recording(
            t_s=grid - grid[0],
            v_mag_pu=on_grid(np.abs(vv[part])), v_ang_rad=on_grid(v_ang[part]),
            i_mag_pu=on_grid(np.abs(iv[part])), i_ang_rad=on_grid(i_ang[part]),
            f_hz=_frequency_on(grid, t, f, spec.max_gap_s, dt, q) if measured_f else None,
            location=spec.location)))
    q["segments_dropped_short"] = dropped
    if not segments:
        raise InputError(src, f"no part of the recording is at least measurement.min_segment_s = "
                         f"{spec.min_segment_s} s long between gaps longer than max_gap_s = "
                         f"{spec.max_gap_s} s", column=names["v_mag" if "v_mag" in names else "v_a_mag"])
    segments.sort(key=lambda s: -s[1].t_s.shape[0])
    q["segments"] = [{"start_s": round(s0, 6), "duration_s": round(float(r.t_s[-1]), 6),
                      "samples": int(r.t_s.shape[0])} for s0, r in segments]
    q["resampled"] = bool(q["non_uniform_steps"] or q["duplicate_timestamps_dropped"]
                          or q["out_of_order_rows"] or q["bridged_gaps"])
    return segments


def _on_grid(grid, t, dt) -> bool:
    """Are the times ``t`` the points of ``grid`` (to 1e-6 of a step)?"""
    return t.size == grid.size and bool(np.max(np.abs(t - grid)) <= 1e-6 * dt)


def _frequency_on(grid, t, f, max_gap_s, dt, q):
    """The frequency channel on ``grid``: interpolated across gaps up to ``max_gap_s``, NaN in
    longer ones (the pipeline then derives f from the voltage angle there)."""
    ok = np.isfinite(f)
    if ok.all() and _on_grid(grid, t, dt):
        return f
    t_ok, f_ok = t[ok], f[ok]
    j = np.clip(np.searchsorted(t_ok, grid), 0, t_ok.size - 1)
    before = t_ok[np.maximum(j - 1, 0)]
    span = np.where(t_ok[j] == grid, 0.0, t_ok[j] - before)
    far = (span > max_gap_s + dt * (1 + 1e-9)) | (grid < t_ok[0]) | (grid > t_ok[-1])
    if far.any():
        q["frequency_derived_in_long_gaps_s"] = round(float(far.sum() * dt), 6)
    return np.where(far, np.nan, np.interp(grid, t_ok, f_ok))


def _gap_culprit(raw, order, valid, t_lo, t_hi, t, names) -> str:
    """Name the first phasor column that is NaN inside the gap, else the time column."""
    inside = (t > t_lo) & (t < t_hi) & ~valid
    for role in raw:
        if role not in ("frequency", "stat", "valid") and np.any(inside & ~np.isfinite(raw[role][order])):
            return names[role]
    return names["time"]


def phasor_columns(rec: Recording, spec: MeasurementSpec, v_abc=None, i_abc=None) -> dict[str, np.ndarray]:
    """Inverse of :func:`condition`'s unit handling: a Recording (or three-phase phasors in pu)
    -> columns in the units of ``spec``; used to write test and example files."""
    vu, cu = spec.voltage_unit.lower(), spec.current_unit.lower()
    v_scale = VOLTAGE_UNITS[vu][0]
    v_pu_to_unit = 1.0 if v_scale is None else voltage_base_v(spec.v_base_kv, vu) / v_scale
    i_pu_to_unit = 1.0 if CURRENT_UNITS[cu] is None else \
        current_base_a(spec.s_base_mva, spec.v_base_kv) / CURRENT_UNITS[cu]
    sign = -1.0 if spec.current_direction == "into_plant" else 1.0
    ang = ANGLE_UNITS[spec.angle_unit.lower()]
    t = np.asarray(rec.t_s)
    cols = {spec.columns["time"]: t * (1e3 if spec.time_unit == "ms" else 1.0)}
    if "frequency" in spec.columns and rec.f_hz is not None:
        cols[spec.columns["frequency"]] = np.asarray(rec.f_hz)

    def wrap(x):
        return np.angle(np.exp(1j * x)) / ang

    if v_abc is None:
        v = np.asarray(rec.v_mag_pu) * v_pu_to_unit
        i = np.asarray(rec.i_mag_pu) * i_pu_to_unit
        cols[spec.columns["v_mag"]], cols[spec.columns["v_ang"]] = v, wrap(np.asarray(rec.v_ang_rad))
        cols[spec.columns["i_mag"]] = i
        cols[spec.columns["i_ang"]] = wrap(np.asarray(rec.i_ang_rad) + (np.pi if sign < 0 else 0.0))
        return cols
    for qn, x, scale, s in (("v", np.asarray(v_abc), v_pu_to_unit, 1.0),
                            ("i", np.asarray(i_abc), i_pu_to_unit, sign)):
        for k, p in enumerate("abc"):
            cols[spec.columns[f"{qn}_{p}_mag"]] = np.abs(x[:, k]) * scale
            cols[spec.columns[f"{qn}_{p}_ang"]] = wrap(np.angle(s * x[:, k]))
    return cols
