"""The system inertia, live (``jaxdse monitor`` with ``[inertia]``): every ``update_s`` of stream
time, E per area and for the system from the monitored units' latest identified H and the
case's other units at their .dyr H (:mod:`jaxdse._core.inertia`), as ``updates.jsonl`` lines
``{"t", "area", "E_MWs", "E_ci95", "measured_share", "E_commitment_MWs", "rocof_hz_per_s",
"units_online", "units_measured"}``.

A monitored unit is online while its latest usable sample (no older than ``stale_s``) shows a
current above ``online_current_pu`` [pu of its rating]; without such a sample (dropped from the
stream, or unusable) its case status decides. Its measured H is the latest window whose verdict
is ``identified`` (a weakly identified H, whose interval is wide, does not move E: on OSL case
1 one 13 GVA plant's weakly identified H of 6.7-13 s against 4.3 s moved its area's E by a
third), while no older than ``stale_s``; after that, or before its first, its model H
(``units_stale`` counts it), until it is identified again.
"""

from __future__ import annotations

import math

import numpy as np

from .._core.inertia import AreaInertia, InertiaSettings, UnitTable, table_inertia
from .._dyr.inertia import CaseUnit, MeasuredPlant


class InertiaTracker:
    """The live state of :mod:`.inertia` (host side, the monitor's main thread): the units as
    arrays (:class:`~jaxdse._core.inertia.UnitTable`), the monitored plants first, then the
    case's units that no plant stands for; each update and each frame changes a few entries,
    each line set is one vectorised sum.

    Arguments:
        case: the case's units (:func:`jaxdse._dyr.inertia.case_units`; [] without a case).
        plants: the monitored units as :class:`~jaxdse._dyr.inertia.MeasuredPlant`.
        settings: the aggregation's numbers.
        areas: the areas to report, in order.
        update_s: stream seconds between lines.
        online_current_pu: the online threshold [pu of the unit's rating].
        states: a status CSV (:class:`~jaxdse._io.inertia.UnitStates`) or None (the .raw's)."""

    def __init__(self, case: list[CaseUnit], plants: list[MeasuredPlant], settings: InertiaSettings,
                 areas: list[str], update_s: float, online_current_pu: float, states=None):
        self.case, self.plants, self.settings = case, plants, settings
        self.update_s, self.threshold, self.states = update_s, online_current_pu, states
        taken = {n for p in plants for n in p.members}
        self.others = [u for u in case if u.name not in taken]
        self.by_case = {u.name: u for u in case}
        self.areas = list(areas)
        for a in [p.area for p in plants] + [u.area for u in self.others]:
            if a not in self.areas:
                self.areas.append(a)
        n_p = len(plants)
        self.index = {p.name: k for k, p in enumerate(plants)}
        self.table = UnitTable(
            area=np.array([self.areas.index(a) for a in [p.area for p in plants] + [u.area for u in self.others]],
                          int),
            s_mva=np.array([p.s_mva for p in plants] + [u.s_mva for u in self.others], float),
            online=np.zeros(n_p + len(self.others), bool),
            ibr_following=np.array([False] * n_p + [u.kind == "ibr_following" for u in self.others], bool),
            h_model_s=np.array([np.nan if x.h_model_s is None else x.h_model_s for x in [*plants, *self.others]],
                               float),
            measured=np.arange(n_p + len(self.others)) < n_p,
            h_s=np.full(n_p + len(self.others), np.nan), h_lo_s=np.full(n_p + len(self.others), np.nan),
            h_hi_s=np.full(n_p + len(self.others), np.nan), age_s=np.full(n_p + len(self.others), np.inf))
        self.t_identified = np.full(n_p, -np.inf)      # stream time of each plant's window that gave its H
        self.streams: dict = {}    # key -> [plant indices, |I| [pu of rating], t] of the latest usable samples
        self.next_t: float | None = None
        self.latest: list[AreaInertia] = []
        self.raw_status: np.ndarray | None = None

    def update(self, u) -> None:
        """A unit's windowed estimate (:class:`~.online.Update`)."""
        k = self.index.get(u.unit)
        if k is not None and u.verdict == "identified" and u.h_s is not None and u.h_ci95 is not None:
            self.table.h_s[k], (self.table.h_lo_s[k], self.table.h_hi_s[k]) = u.h_s, u.h_ci95
            self.t_identified[k] = u.t

    def samples(self, names, current_pu, usable, t: float, key=None) -> None:
        """The units' samples at stream time ``t`` [s]: |I| on their rating [pu], usable or not
        (``key``: the stream's, whose units are always ``names``; default: the names)."""
        key = tuple(names) if key is None else key
        st = self.streams.get(key)
        if st is None:
            st = self.streams[key] = [np.array([self.index.get(n, -1) for n in names], int),
                                      np.full(len(names), np.nan), np.full(len(names), -np.inf)]
        current = np.asarray(current_pu, float)
        ok = np.asarray(usable, bool) & np.isfinite(current)
        st[1] = np.where(ok, current, st[1])
        st[2] = np.where(ok, t, st[2])

    def tick(self, t: float) -> list[dict]:
        """The lines due at stream time ``t`` [s]: one set (areas, then the system) at each
        multiple of ``update_s`` reached since the last call (the latest one only, after a gap)."""
        k = math.floor(t / self.update_s + 1e-9)
        if self.next_t is None:
            self.next_t = (k + 1) * self.update_s
            return []
        if t + 1e-9 < self.next_t:
            return []
        at = k * self.update_s
        self.next_t = (k + 1) * self.update_s
        self.latest = self.at(at)
        return [a.line(at) for a in self.latest]

    def _status(self, u: CaseUnit, t: float) -> bool:
        return u.in_service if self.states is None else self.states.online(u.name, t, u.in_service)

    def _case_status(self, t: float) -> np.ndarray:
        """Every unit's status by the case (a plant: any of its case units'; the .raw's STAT
        or the status CSV's at ``t``)."""
        out = []
        for p in self.plants:
            mine = [self.by_case[n] for n in p.members if n in self.by_case]
            out.append(any(self._status(u, t) for u in mine) if mine else True)
        return np.array(out + [self._status(u, t) for u in self.others], bool)

    def at(self, t: float) -> list[AreaInertia]:
        """E per area and system at stream time ``t``."""
        n_p = len(self.plants)
        if self.states is not None or self.raw_status is None:   # the .raw's: once
            status = self._case_status(t)
            if self.states is None:
                self.raw_status = status
        online = self.table.online
        online[:] = self.raw_status if self.states is None else status
        for idx, current, ts in self.streams.values():
            fresh = (t - ts <= self.settings.stale_s) & (idx >= 0)
            online[idx[fresh]] = current[fresh] > self.threshold
        self.table.age_s[:n_p] = t - self.t_identified
        return table_inertia(self.table, self.areas, self.settings)


NO_CASE_AREA = "monitored units"
"""The one area of a monitor whose units come from a run configuration (no case)."""


def tracker_for(units, est, inertia, log) -> InertiaTracker:
    """The :class:`InertiaTracker` of a monitor's ``units`` (:class:`~.monitor.MonitorUnit`),
    the source's :class:`~.pmu_sim.Units` ``est`` and its [inertia] ``inertia``; the case's
    notes (units counted without H, ...) go to ``log``."""
    from .._dyr.inertia import area_list, case_units, measured_plant

    plants = []
    if est.case is not None:
        raw, dyr, members, _ = est.case
        case, notes = case_units(raw, dyr, inertia)
        for note in notes:
            log(f"inertia: {note}")
        f0 = raw.basfrq_hz
        areas = area_list(raw, case, inertia.areas)
    else:
        raw, members, case = None, {}, []
        f0 = float(units[0].run.measurement.f_nominal_hz)
        areas = [NO_CASE_AREA]
    for u in units:
        s = float(u.run.plant.machine.s_rated_mva)
        base = u.name.split("~")[0]
        if base in members and base == u.name:
            bus, ids = members[base]
            plants.append(measured_plant(u.name, bus, ids, s, case, raw, inertia.areas, u.run.h_reference_s))
        elif base in members:   # a tiled copy (capacity tests): the original's area and H, no case unit
            p = measured_plant(u.name, *members[base], s, case, raw, inertia.areas, u.run.h_reference_s)
            plants.append(MeasuredPlant(u.name, p.area, s, p.h_model_s, ()))
        else:
            plants.append(MeasuredPlant(u.name, NO_CASE_AREA, s, u.run.h_reference_s, ()))
    return InertiaTracker(case, plants, inertia.settings(f0), areas, inertia.update_s,
                          inertia.online_current_pu, inertia.status)
