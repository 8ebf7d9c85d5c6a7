"""The units of a PSS/E case for the system inertia (host side): each generator record of the
.raw with its area, its rating (MBASE) and its filed H (its .dyr machine record), by what it
is (:func:`~.inventory.inventory`'s categories):

* a synchronous unit (a machine record): H of the record, on MBASE;
* a grid-forming converter record (REGCV1, REGCV2, REGFM_A1, REGFM_B1): its virtual H from the
  record (M/2; the droop's equivalent TPf / (2 mp); REGFM_B1's H), or as ``[inertia] grid_forming`` names it;
* another converter-interfaced source (REGCA1, WT4G1, PVGU1, ...): grid-following, no inertia,
  unless ``[inertia] grid_forming`` names it with its virtual H;
* an online unit without a machine record jaxdse reads (no dynamic records, an unknown machine
  model, a machine's controls without the machine): counted with H unknown (0, and said);
* a static var compensator and a second record of the same machine: not units.

Its status is the .raw's STAT, or the status CSV's at the time asked.
"""

from __future__ import annotations

import dataclasses
import math

from .._core.inertia import InertiaUnit
from .._io.inertia import InertiaConfig, unit_name
from .._io.psse import DyrData, RawCase
from .._models.ibr import ibr_from_dyr
from .inventory import inventory, is_converter
from .records import GFM_MODELS, record_kind


@dataclasses.dataclass(frozen=True)
class CaseUnit:
    """One generator record of the case as the inertia counts it."""

    name: str
    """"BUS_ID"."""
    bus: int
    id: str
    area: str
    s_mva: float
    kind: str
    """One of :data:`jaxdse._core.inertia.KINDS`."""
    h_model_s: float | None
    in_service: bool
    """The .raw's STAT."""
    why: str
    """What it is, one line (the inventory's)."""

    def unit(self, online: bool, **measured) -> InertiaUnit:
        return InertiaUnit(self.name, self.area, self.s_mva, online, self.kind, self.h_model_s, **measured)


def area_of(raw: RawCase, bus: int, areas) -> str:
    """The area of ``bus``: "area N" / "zone N" from the .raw, or the configured name ("other"
    for a bus no configured area lists)."""
    if isinstance(areas, dict):
        for name, buses in areas.items():
            if bus in buses:
                return name
        return "other"
    b = raw.buses.get(int(bus))
    if b is None:
        return "other"
    return f"{areas} {b.area if areas == 'area' else b.zone}"


def case_units(raw: RawCase, dyr: DyrData, cfg: InertiaConfig) -> tuple[list[CaseUnit], list[str]]:
    """Every generator record of the case that is a unit, and notes (one line each: an H that
    cannot be read; the online records without an H, in one line)."""
    units, notes, without = [], [], {}
    for a in inventory(raw, dyr).generators:
        if a.category in ("not a generator", "duplicate"):
            continue
        g = a.generator
        name = unit_name(g.bus, g.id)
        s = g.mbase_mva if g.mbase_mva > 0 and math.isfinite(g.mbase_mva) else raw.sbase_mva
        if s != g.mbase_mva:
            notes.append(f"{name}: MBASE {g.mbase_mva:g} MVA is not a rating; the system base "
                         f"{raw.sbase_mva:g} MVA is used")
        machines = [r for r in a.records if record_kind(r) == "machine"]
        h = None
        gfm = [r for r in a.records if r.model in GFM_MODELS]
        if name in cfg.grid_forming:
            kind, h = "grid_forming", cfg.grid_forming[name]
        elif gfm:   # its record's virtual H (REGCV1: M/2; REGFM_A1: TPf / (2 mp); REGFM_B1: H)
            kind = "grid_forming"
            try:
                h = float(ibr_from_dyr(gfm[0].model, gfm[0].constants).h_s)
            except ValueError as err:
                notes.append(f"{name}: its {gfm[0].model} record (line {gfm[0].line}) does not read "
                             f"({str(err).splitlines()[0]}); counted at 0")
        elif machines:
            kind = "synchronous"
            value = machines[0].params.get("H")
            if isinstance(value, (int, float)) and math.isfinite(value) and value >= 0:
                h = float(value)
            else:
                notes.append(f"{name}: its {machines[0].model} record (line {machines[0].line}) has no readable "
                             "H; counted at 0")
        elif any(is_converter(r.model) for r in a.records):
            kind = "ibr_following"
        else:
            kind = "no_h_record"
            if g.stat == 1:
                without.setdefault(a.category, []).append(name)
        units.append(CaseUnit(name, g.bus, g.id.strip(), area_of(raw, g.bus, cfg.areas), float(s), kind, h,
                              g.stat == 1, a.why))
    if without:
        names = [n for group in without.values() for n in group]
        notes.append(f"{len(names)} online generator record(s) without an H in the case ("
                     + ", ".join(f"{category}: {len(group)}" for category, group in without.items())
                     + "), counted at H = 0 (E is a lower bound; name them in [inertia] grid_forming if "
                     f"they are grid-forming converters): {', '.join(names[:10])}"
                     + (f" and {len(names) - 10} more" if len(names) > 10 else ""))
    return units, notes


def area_list(raw: RawCase, units: list[CaseUnit], areas) -> list[str]:
    """The areas to report, in order: the configured names, or the .raw's areas (zones) that
    hold a unit, by number; "other" last where a unit is in none."""
    if isinstance(areas, dict):
        names = list(areas)
    else:
        nums = sorted({int(u.area.split()[1]) for u in units if u.area != "other"})
        names = [f"{areas} {n}" for n in nums]
    return names + (["other"] if any(u.area == "other" for u in units) else [])


@dataclasses.dataclass(frozen=True)
class MeasuredPlant:
    """A measured plant (a unit of the fleet or the monitor): the case units it stands for."""

    name: str
    area: str
    s_mva: float
    """Its rating [MVA] (the plant's machine base: its units' MBASE summed)."""
    h_model_s: float | None
    """Its units' filed H, as one on ``s_mva``: sum H_i MBASE_i / s_mva [s]."""
    members: tuple[str, ...] = ()
    """Its case units ("BUS_ID"): not counted again."""


def measured_plant(name: str, bus: int, ids, s_mva: float, case: list[CaseUnit], raw: RawCase | None,
                   areas, h_fallback_s: float | None = None) -> MeasuredPlant:
    """The :class:`MeasuredPlant` of a plant on ``bus`` with machine IDs ``ids`` (its case
    units' filed H; ``h_fallback_s`` where the case has none of them)."""
    names = tuple(unit_name(bus, i) for i in ids)
    by = {u.name: u for u in case}
    mine = [by[n] for n in names if n in by]
    if mine and all(u.h_model_s is not None for u in mine):
        h = sum(u.h_model_s * u.s_mva for u in mine) / s_mva
    else:
        h = h_fallback_s
    area = mine[0].area if mine else (area_of(raw, bus, areas) if raw is not None else "system")
    return MeasuredPlant(name, area, float(s_mva), h, names)


def inertia_units(case: list[CaseUnit], plants: list[MeasuredPlant], estimates: dict, online: dict,
                  states=None, t: float | None = None) -> list[InertiaUnit]:
    """The units for :func:`jaxdse._core.inertia.area_inertia`: every measured plant with its
    estimate, then every case unit no measured plant stands for.

    Arguments:
        estimates: plant name -> (H [s], (lo, hi) or None, age [s]) of its latest identified H
            (absent: none yet).
        online: plant name -> whether its current is above the threshold (absent: unknown,
            its case units' status decides).
        states: a :class:`~jaxdse._io.inertia.UnitStates` (None: the .raw's STAT); ``t`` the
            time to read it at [s] (None: its last rows)."""
    def status(u: CaseUnit) -> bool:
        return u.in_service if states is None else states.online(u.name, t, u.in_service)

    by = {u.name: u for u in case}
    out, taken = [], set()
    for p in plants:
        taken.update(p.members)
        on = online.get(p.name)
        if on is None:
            on = any(status(by[n]) for n in p.members if n in by) if any(n in by for n in p.members) else True
        h, ci, age = estimates.get(p.name, (None, None, None))
        out.append(InertiaUnit(p.name, p.area, p.s_mva, bool(on), "synchronous", p.h_model_s, h_s=h,
                               h_ci95=None if ci is None else tuple(ci), age_s=age, measured=True))
    out += [u.unit(status(u)) for u in case if u.name not in taken]
    return out
