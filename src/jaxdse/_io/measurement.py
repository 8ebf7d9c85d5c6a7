"""From a raw :class:`Table` to validated :class:`Recording` segments, with a data-quality report.

Applied at the edge, in NumPy, in this order:

1. pick the columns (positive-sequence magnitude/angle, or three-phase a/b/c magnitude/angle);
2. time: seconds, milliseconds or ISO timestamps; rows with no time are dropped, out-of-order
   rows sorted, duplicated timestamps dropped (the first row is kept);
3. units: voltage kV/V phase-to-phase or phase-to-ground or pu, current A/kA/pu, angles deg/rad,
   converted to pu of the system base (``s_base_mva``, ``v_base_kv`` phase-to-phase);
   three-phase -> positive sequence; current direction -> generator convention (out of the plant);
4. gaps: samples with a NaN in any phasor channel and missing timestamps form gaps; gaps up to
   ``max_gap_s`` are bridged by linear interpolation of magnitude and unwrapped angle, longer
   ones split the recording (or fail);
5. resampling onto a uniform grid (linear, angles unwrapped first);
6. plausibility of units (voltage near 1 pu, current below 3x rating, frequency near nominal).

Everything handled is reported in ``data_quality``; everything else is an :class:`InputError`.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

import numpy as np

from .._core.mapping import LOCATIONS
from .._core.recording import Recording
from .._core.sequence import positive_sequence
from .errors import InputError
from .readers import FORMATS, Table, load_table

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
UNIT_KEYS = {"voltage_unit": ("kV_LL", "kV_LN", "V_LL", "V_LN", "pu"), "current_unit": ("A", "kA", "pu"),
             "angle_unit": ("deg", "rad"), "frequency_unit": ("Hz",)}
"""Unit keys of [measurement] -> the spellings users write (matched case-insensitively)."""
CHOICE_KEYS = {"format": FORMATS, "location": LOCATIONS, "current_direction": DIRECTIONS,
               "on_long_gap": GAP_POLICIES, "time_unit": TIME_UNITS}
"""Keys of [measurement] that take one of a few words (matched exactly)."""

# Plausibility of the units and bases: the median of each quantity over the recording.
PLAUSIBLE_VOLTAGE_PU = (0.5, 1.5)
"""Median voltage magnitude [pu of v_base_kv] outside this range: wrong unit or base."""
MAX_CURRENT_PU_MACHINE = 3.0
"""Median current [pu of the machine rating] above this: wrong unit or base."""
MIN_POWER_PU_MACHINE = -0.05
"""Median active power [pu of the machine rating] below this: the current is reversed."""
MAX_FREQUENCY_OFFSET = 0.1
"""Median frequency off nominal by more than this fraction of f_nominal [-]: not in Hz."""


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
POSITIVE = ("v_mag", "v_ang", "i_mag", "i_ang")
THREE_PHASE = tuple(f"{q}_{p}_{c}" for q in "vi" for c in ("mag", "ang") for p in "abc")
COLUMN_ROLES = ("time", "frequency") + POSITIVE + THREE_PHASE


@dataclass(frozen=True)
class MeasurementSpec:
    """How to read one PMU recording: file, columns, units, bases, direction and gap policy."""

    file: tuple[str, ...]
    columns: dict
    """Role ("time", "frequency", "v_mag", ..., or "v_a_mag", ...) -> column name or number."""
    format: str | None = None
    location: str = "substation"
    voltage_unit: str = "kV_LL"
    current_unit: str = "A"
    angle_unit: str = "deg"
    time_unit: str = "s"
    frequency_unit: str = "Hz"
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
    delimiter: str = ","
    quotechar: str = '"'

    @property
    def three_phase(self) -> bool:
        return any(k in self.columns for k in THREE_PHASE)


def read_measurement(spec: MeasurementSpec, s_rated_mva: float = 1e9):
    """Read, validate and condition one recording.

    Arguments:
        spec: the measurement description.
        s_rated_mva: machine rating, for the plausibility check of the current.

    Returns:
        ``(segments, quality)``: a list of ``(t0_s, Recording)`` (one per part between long
        gaps, longest first) and the ``data_quality`` report (a JSON-ready dict).
    """
    table = load_table(spec.file, spec.format, delimiter=spec.delimiter, quotechar=spec.quotechar,
                       time_column=spec.columns.get("time"))
    return condition(table, spec, s_rated_mva)


def condition(table: Table, spec: MeasurementSpec, s_rated_mva: float = 1e9):
    """:func:`read_measurement` after the file has been read (see the module docstring)."""
    src = table.source
    roles = _check_roles(spec, src)
    q: dict = {"file": src, "rows_read": 0}
    raw = {role: table.column(spec.columns[role], role) for role in roles}
    names = {role: str(spec.columns[role]) for role in roles}
    n_rows = len(raw["time"])
    q["rows_read"] = n_rows
    rownum = np.arange(n_rows) + table.first_row

    t, q["time_format"], q["start_time"] = _parse_time(raw.pop("time"), spec, src, names["time"],
                                                      table.first_row)
    for role, values in raw.items():
        if not np.any(np.isfinite(values)):
            if role == "frequency":
                continue
            raise InputError(src, "every value is NaN or empty", column=names[role],
                             row=f"{rownum[0]}-{rownum[-1]}")

    keep = np.isfinite(t)
    q["rows_without_time"] = int(np.sum(~keep))
    q["out_of_order_rows"] = int(np.sum(np.diff(t[keep]) < 0))
    order = np.flatnonzero(keep)[np.argsort(t[keep], kind="stable")]
    t = t[order]
    dup = np.concatenate([[False], np.diff(t) == 0])
    q["duplicate_timestamps_dropped"] = int(np.sum(dup))
    order, t = order[~dup], t[~dup]
    if t.size < 8:
        raise InputError(src, f"only {t.size} rows with a distinct time", column=names["time"])

    v, i = _phasors(raw, order, spec, src, names)
    f = raw["frequency"][order] if "frequency" in raw else None

    dt = 1.0 / spec.frame_rate_hz if spec.frame_rate_hz else float(np.median(np.diff(t)))
    steps = np.diff(t)
    q["frame_rate_hz"] = 1.0 / dt
    q["non_uniform_steps"] = int(np.sum(np.abs(steps - dt) > 1e-6 * dt))

    valid = np.isfinite(v) & np.isfinite(i)
    q["nan_samples"] = {names[r]: int(np.sum(~np.isfinite(raw[r][order]))) for r in raw
                        if np.any(~np.isfinite(raw[r][order]))}
    if not np.any(valid):
        raise InputError(src, "no row has all phasor channels", row=f"{rownum[0]}-{rownum[-1]}")
    tv, vv, iv, rows_v = t[valid], v[valid], i[valid], rownum[order][valid]
    # Unwrap on the valid samples only, then interpolate magnitude and angle.
    v_ang, i_ang = np.unwrap(np.angle(vv)), np.unwrap(np.angle(iv))
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
        culprit = _gap_culprit(raw, order, valid, tv[k], tv[k + 1], t, names)
        if spec.on_long_gap == "error":
            raise InputError(src, f"gap of {gap_len[k]:.3f} s from t = {tv[k] - t[0] + dt:.3f} s is "
                             f"longer than measurement.max_gap_s = {spec.max_gap_s} s",
                             column=culprit, row=int(rows_v[k] + 1))
    cuts = np.flatnonzero(long_gap) + 1
    q["split_at_gaps"] = [{"start_s": round(float(tv[c - 1] - t[0] + dt), 6),
                           "length_s": round(float(gap_len[c - 1]), 6), "row": int(rows_v[c - 1] + 1)}
                          for c in cuts]
    q["edge_rows_trimmed"] = int(np.flatnonzero(valid)[0] + (len(valid) - 1 - np.flatnonzero(valid)[-1]))

    freq_source = "measured" if f is not None and np.any(np.isfinite(f)) else "derived from voltage angle"
    if f is not None and not np.any(np.isfinite(f)):
        q["frequency_all_nan"] = True
    segments = []
    dropped = []
    for part in np.split(np.arange(tv.size), cuts):
        t_part = tv[part]
        n = int(np.floor((t_part[-1] - t_part[0]) / dt + 1e-6)) + 1
        if (n - 1) * dt < spec.min_segment_s:
            dropped.append({"start_s": round(float(t_part[0] - t[0]), 6),
                            "length_s": round(float((n - 1) * dt), 6)})
            continue
        grid = t_part[0] + dt * np.arange(n)
        rec_f = None
        if freq_source == "measured":
            ok = np.isfinite(f) & (t >= t_part[0]) & (t <= t_part[-1])
            t_ok = np.concatenate([[t_part[0]], t[ok], [t_part[-1]]])
            if ok.sum() > 1 and np.max(np.diff(t_ok)) <= spec.max_gap_s + dt * (1 + 1e-9):
                rec_f = np.interp(grid, t[ok], f[ok])
            else:
                q["frequency_derived_in_segments_with_long_gaps"] = True
        segments.append((float(t_part[0] - t[0]), Recording(
            t_s=grid - grid[0],
            v_mag_pu=np.interp(grid, t_part, np.abs(vv[part])),
            v_ang_rad=np.interp(grid, t_part, v_ang[part]),
            i_mag_pu=np.interp(grid, t_part, np.abs(iv[part])),
            i_ang_rad=np.interp(grid, t_part, i_ang[part]),
            f_hz=rec_f, location=spec.location)))
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
    q["frequency"] = (f"measured ({names['frequency']})" if freq_source == "measured"
                      else "derived from the voltage angle")
    _plausibility(np.abs(vv), iv, vv, f, spec, s_rated_mva, src, names, q)
    q["units"] = {"voltage": spec.voltage_unit, "current": spec.current_unit,
                  "angle": spec.angle_unit, "time": q.pop("time_format"),
                  "v_base_kv": spec.v_base_kv, "s_base_mva": spec.s_base_mva,
                  "current_direction": spec.current_direction}
    return segments, q


def _check_roles(spec: MeasurementSpec, src) -> list[str]:
    cols = spec.columns
    unknown = [k for k in cols if k not in COLUMN_ROLES]
    if unknown:
        raise InputError(src, f"unknown column role; use {', '.join(COLUMN_ROLES[:6])} or "
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
    return ["time"] + (["frequency"] if "frequency" in cols else []) + list(need)


def _parse_time(raw, spec: MeasurementSpec, src, name, first_row):
    if raw.dtype.kind in "fiu":
        if spec.time_unit == "iso":
            raise InputError(src, "time_unit is 'iso' but the column is numeric", column=name)
        scale = 1e-3 if spec.time_unit == "ms" else 1.0
        return raw.astype(float) * scale, spec.time_unit, None
    out = np.empty(raw.shape[0])
    start = None
    for k, s in enumerate(raw):
        if s in ("", "nan", "NaN"):
            out[k] = np.nan
            continue
        try:
            d = datetime.fromisoformat(s.replace("Z", "+00:00"))
        except ValueError:
            raise InputError(src, f"{s!r} is neither seconds nor an ISO 8601 timestamp",
                             column=name, row=k + first_row) from None
        if start is None:
            start = d
        try:
            out[k] = (d - start).total_seconds()
        except TypeError:
            raise InputError(src, "timestamps mix time zones and naive times",
                             column=name, row=k + first_row) from None
    return out, "iso", start.isoformat() if start else None


def _phasors(raw, order, spec: MeasurementSpec, src, names):
    """Positive-sequence V and I [pu, system base, generator convention] per kept row."""
    for key in ("voltage_unit", "current_unit", "angle_unit", "current_direction"):
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


def _gap_culprit(raw, order, valid, t_lo, t_hi, t, names) -> str:
    """Name the first phasor column that is NaN inside the gap, else the time column."""
    inside = (t > t_lo) & (t < t_hi) & ~valid
    for role in raw:
        if role != "frequency" and np.any(inside & ~np.isfinite(raw[role][order])):
            return names[role]
    return names["time"]


def _plausibility(v_mag, i, v, f, spec: MeasurementSpec, s_rated_mva, src, names, q):
    vm = float(np.median(v_mag))
    vname = names.get("v_mag", names.get("v_a_mag"))
    iname = names.get("i_mag", names.get("i_a_mag"))
    if not PLAUSIBLE_VOLTAGE_PU[0] <= vm <= PLAUSIBLE_VOLTAGE_PU[1]:
        raise InputError(src, f"median voltage is {vm:.4g} pu on v_base_kv = {spec.v_base_kv} kV: "
                         f"check measurement.voltage_unit ({spec.voltage_unit!r}) and v_base_kv",
                         column=vname)
    im = float(np.median(np.abs(i))) * spec.s_base_mva / s_rated_mva
    q["median_current_pu_machine"] = round(im, 6)
    if im > MAX_CURRENT_PU_MACHINE:
        raise InputError(src, f"median current is {im:.4g} pu of the machine rating: check "
                         f"measurement.current_unit ({spec.current_unit!r}) and the bases", column=iname)
    p = float(np.median(np.real(v * np.conj(i)))) * spec.s_base_mva / s_rated_mva
    q["median_p_pu_machine"] = round(p, 6)
    if p < MIN_POWER_PU_MACHINE:
        raise InputError(src, f"median active power is {p:.3g} pu (the plant absorbs power): if the "
                         "current is measured towards the plant set measurement.current_direction = "
                         "\"into_plant\"", column=iname)
    if f is not None and np.any(np.isfinite(f)):
        fm = float(np.nanmedian(f))
        if abs(fm - spec.f_nominal_hz) > MAX_FREQUENCY_OFFSET * spec.f_nominal_hz:
            raise InputError(src, f"median frequency is {fm:.4g} Hz but machine.f_nominal_hz is "
                             f"{spec.f_nominal_hz}: the channel must be in Hz", column=names["frequency"])


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

