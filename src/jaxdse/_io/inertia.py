"""The ``[inertia]`` section of a fleet file (``jaxdse fleet``) or a monitor file (``jaxdse
monitor``), and the CSV of unit states it may name. An empty ``[inertia]`` turns the system
inertia on with every default (areas and status from the .raw)::

    [inertia]
    areas = "area"            # "area" | "zone" (the .raw's bus AREA or ZONE), or a table
                              #   {North = [101, 102], South = [201]} of buses per area name
    status = "raw"            # "raw" (the generators' STAT) or a CSV of unit states over time
                              #   (columns time_s, unit, online; unit "BUS_ID", e.g. "101_1")
    model_uncertainty = 0.15  # half-width of a filed H's 95 % interval, relative [-]
    measured_errors = "shared"  # measured units' intervals add ("shared") or in quadrature
                              #   ("independent"); see jaxdse._core.inertia
    largest_loss_mw = 1000.0  # the loss for the rate of change of frequency [MW] (none: not given)
    f0_hz = 50.0              # nominal frequency [Hz] (default: the .raw's BASFRQ)
    update_s = 1.0            # live: a line per area every this many seconds [s]
    stale_s = 30.0            # a measured unit's H older than this falls back to its model H [s]
    floor_MWs = 20000.0       # alarm below this E [MW s] (none: no floor)
    online_current_pu = 0.05  # live: a measured unit is online when its |I| is above [pu, MBASE]
    grid_forming = {"301_1" = 3.0}   # grid-forming units ("BUS_ID") and their virtual H [s]

Every key is checked on load; a wrong one raises a one-line :class:`InputError` naming the
file and the key.
"""

from __future__ import annotations

import bisect
import csv
import dataclasses
import math
from pathlib import Path

from .._core.inertia import MEASURED_ERRORS, InertiaSettings
from .errors import InputError
from .schema import no_unknown, positive_number, typed_value

KEYS = {"areas", "status", "model_uncertainty", "largest_loss_mw", "f0_hz", "update_s", "stale_s",
        "floor_MWs", "online_current_pu", "grid_forming", "measured_errors"}
STATUS_COLUMNS = ("time_s", "unit", "online")


@dataclasses.dataclass(frozen=True)
class UnitStates:
    """Units' online states over time (a status CSV): unit -> sorted (time_s, online)."""

    source: str
    states: dict

    def online(self, unit: str, t: float | None, default: bool) -> bool:
        """The state of ``unit`` at ``t`` [s]: the last row at or before ``t`` (None: the last
        row); ``default`` (the .raw's status) before the first row or for a unit not listed."""
        rows = self.states.get(unit)
        if not rows:
            return default
        if t is None:
            return rows[-1][1]
        k = bisect.bisect_right([r[0] for r in rows], t)
        return default if k == 0 else rows[k - 1][1]


@dataclasses.dataclass(frozen=True)
class InertiaConfig:
    """A validated ``[inertia]`` section."""

    areas: object = "area"
    """"area", "zone", or {area name: (bus, ...)}."""
    status: UnitStates | None = None
    """None: the .raw's status."""
    model_uncertainty: float = 0.15
    largest_loss_mw: float | None = None
    f0_hz: float | None = None
    """None: the case's nominal frequency."""
    update_s: float = 1.0
    stale_s: float = 30.0
    floor_MWs: float | None = None
    online_current_pu: float = 0.05
    """[pu on the unit's MBASE]"""
    grid_forming: dict = dataclasses.field(default_factory=dict)
    """"BUS_ID" -> virtual H [s]."""
    measured_errors: str = "shared"

    def settings(self, f0_hz: float) -> InertiaSettings:
        """The aggregation's numbers (``f0_hz``: the case's, unless the section gives one)."""
        return InertiaSettings(model_uncertainty=self.model_uncertainty, largest_loss_mw=self.largest_loss_mw,
                               f0_hz=self.f0_hz or f0_hz, stale_s=self.stale_s, floor_MWs=self.floor_MWs,
                               measured_errors=self.measured_errors)


def inertia_section(path, table) -> InertiaConfig:
    """Validate ``[inertia]`` of the file ``path`` (relative paths are relative to it)."""
    path = Path(path)
    if not isinstance(table, dict):
        raise InputError(path, "must be a table, e.g. [inertia]", key="inertia")
    no_unknown(path, table, KEYS, "inertia.")
    kw = {}
    areas = table.get("areas", "area")
    if isinstance(areas, dict):
        if not areas:
            raise InputError(path, "must name at least one area: {North = [101, 102], ...}", key="inertia.areas")
        seen = {}
        out = {}
        for name, buses in areas.items():
            key = f"inertia.areas.{name}"
            if not isinstance(buses, list) or not buses or not all(
                    isinstance(b, int) and not isinstance(b, bool) for b in buses):
                raise InputError(path, f"must be a non-empty list of bus numbers, got {buses!r}", key=key)
            for b in buses:
                if b in seen:
                    raise InputError(path, f"bus {b} is also in area {seen[b]!r}", key=key)
                seen[b] = name
            out[name] = tuple(buses)
        kw["areas"] = out
    elif areas in ("area", "zone"):
        kw["areas"] = areas
    else:
        raise InputError(path, f'must be "area", "zone" or a table of buses per area name, got {areas!r}',
                         key="inertia.areas")
    status = table.get("status", "raw")
    if status != "raw":
        name = typed_value(path, str, status, "inertia.status")
        f = Path(name) if Path(name).is_absolute() else path.parent / name
        if not f.is_file():
            raise InputError(path, f'must be "raw" or a CSV of unit states (time_s, unit, online); no such '
                             f"file: {f}", key="inertia.status")
        kw["status"] = read_unit_states(f)
    for k in ("largest_loss_mw", "f0_hz"):
        if k in table:
            kw[k] = positive_number(path, table[k], f"inertia.{k}")
    for k in ("update_s", "online_current_pu"):
        if k in table:
            kw[k] = positive_number(path, table[k], f"inertia.{k}")
    for k in ("stale_s", "floor_MWs"):
        if k in table:
            kw[k] = typed_value(path, float, table[k], f"inertia.{k}", 0)
    if "model_uncertainty" in table:
        u = typed_value(path, float, table["model_uncertainty"], "inertia.model_uncertainty", 0)
        if u >= 1:
            raise InputError(path, f"must be below 1 (a relative half-width: 0.15 is +-15 %), got {u!r}",
                             key="inertia.model_uncertainty")
        kw["model_uncertainty"] = u
    if "measured_errors" in table:
        if table["measured_errors"] not in MEASURED_ERRORS:
            raise InputError(path, f"must be one of {', '.join(map(repr, MEASURED_ERRORS))}, got "
                             f"{table['measured_errors']!r}", key="inertia.measured_errors")
        kw["measured_errors"] = table["measured_errors"]
    gfm = table.get("grid_forming", {})
    if not isinstance(gfm, dict):
        raise InputError(path, 'must be a table {"BUS_ID" = virtual H in s}', key="inertia.grid_forming")
    kw["grid_forming"] = {}
    for unit, h in gfm.items():
        if "_" not in unit or not unit.split("_", 1)[0].strip().isdigit():
            raise InputError(path, f'a unit is named "BUS_ID" (e.g. "301_1"), got {unit!r}',
                             key=f"inertia.grid_forming.{unit}")
        kw["grid_forming"][unit_name(int(unit.split("_", 1)[0]), unit.split("_", 1)[1])] = \
            positive_number(path, h, f"inertia.grid_forming.{unit}")
    return InertiaConfig(**kw)


def unit_name(bus: int, machine_id: str) -> str:
    """A case unit's name: "BUS_ID" (the ID stripped), as ``[channels]`` names a per-machine plant."""
    return f"{int(bus)}_{str(machine_id).strip()}"


def read_unit_states(path) -> UnitStates:
    """A CSV of unit states (columns time_s, unit "BUS_ID", online 1/0 or true/false; a row's
    state holds from its time to the unit's next row); a bad row raises a one-line
    :class:`InputError` naming it. time_s is the stream's time, seconds since 1970, for
    ``jaxdse monitor``; seconds from the recording's first sample for ``jaxdse fleet``."""
    path = Path(path)
    states: dict = {}
    with open(path, newline="") as fh:
        reader = csv.reader(fh)
        header = [h.strip() for h in next(reader, [])]
        for c in STATUS_COLUMNS:
            if c not in header:
                raise InputError(path, f"no column {c!r}: a unit-state CSV has columns time_s, unit, online",
                                 column=c)
        col = {c: header.index(c) for c in STATUS_COLUMNS}
        for n, row in enumerate(reader, start=2):
            if not row or all(not x.strip() for x in row):
                continue
            if len(row) < len(header):
                raise InputError(path, f"{len(row)} fields, the header has {len(header)}", row=n)
            try:
                t = float(row[col["time_s"]])
                if not math.isfinite(t):
                    raise ValueError
            except ValueError:
                raise InputError(path, f"not a finite number: {row[col['time_s']]!r}", column="time_s",
                                 row=n) from None
            word = row[col["online"]].strip().lower()
            if word not in ("1", "0", "true", "false"):
                raise InputError(path, f"must be 1, 0, true or false, got {row[col['online']]!r}", column="online",
                                 row=n)
            unit = row[col["unit"]].strip()
            if "_" not in unit or not unit.split("_", 1)[0].strip().isdigit():
                raise InputError(path, f'a unit is named "BUS_ID" (e.g. "101_1"), got {unit!r}', column="unit",
                                 row=n)
            unit = unit_name(int(unit.split("_", 1)[0]), unit.split("_", 1)[1])
            states.setdefault(unit, []).append((t, word in ("1", "true")))
    for rows in states.values():
        rows.sort(key=lambda r: r[0])
    return UnitStates(str(path), states)
