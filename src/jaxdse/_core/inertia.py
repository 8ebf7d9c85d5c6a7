"""System inertia per area: the stored kinetic energy E = sum_i H_i S_i [MW s] of the online
units, with its 95 % interval, the measured share, the commitment figure and the rate of
change of frequency after a configured loss (host side, plain NumPy: a few thousand units).

Each unit contributes H_i S_i (H on its own rating S_i [MVA]), by where its H comes from
(``UnitInertia.source``):

* ``measured``: the identified H with its 95 % interval (a measured unit's estimate no older
  than ``stale_s``);
* ``model``: the H of its .dyr machine record (a grid-forming unit: its virtual H from the
  records), with the relative uncertainty ``model_uncertainty`` as the half-width of its 95 %
  interval (0.15: the true H within +-15 % of the filed one);
* ``model (stale)``: a measured unit whose last identification is older than ``stale_s``;
  ``model (no estimate)``: one that has none (not identified, or its window still filling);
  ``model (no interval)``: an identified H without an interval is not used; each on its
  model H, visibly (``units_stale`` counts them);
* ``ibr_following``: a grid-following converter: 0, no uncertainty;
* ``no H record``: an online unit whose H the case does not give (no machine record): 0 with
  no uncertainty, and counted apart (``units_without_h``): E is then a lower bound;
* ``offline``: not counted.

How the unit intervals combine (stated, and tested for coverage): each unit's interval is read
as that of a normal error, split where it is asymmetric: a lower half-width a_i = (H_i - lo_i)
S_i and an upper one b_i = (hi_i - H_i) S_i [MW s], each 1.96 sigma of its side.

* The measured units' errors are taken as shared (``measured_errors = "shared"``, the
  default): one estimator, one model structure and one disturbance move their estimates the
  same way (on the ANDES ieee14 line trip all five plants' H came out high, by 1 to 14 %, each
  within its own interval, and a sum in quadrature of their intervals missed the true E). Their
  half-widths add: A = sum a_i, B = sum b_i (measured units only). With ``"independent"``
  they add in quadrature like the model units'.
* The model units' errors are taken as independent (each unit filed on its own): their
  half-widths add in quadrature.
* The two groups are independent of each other: E's interval is
  [E - sqrt(A^2 + sum_model a_i^2), E + sqrt(B^2 + sum_model b_i^2)], the lower end clipped at 0.

For normal errors (split where asymmetric) that are fully shared among the measured units and
independent among the model units, this covers 95 % exactly (split: by the sign of the shared
error); tests/core/test_inertia.py measures it by Monte Carlo, and measures too that the sum in
quadrature covers far less when the measured errors are shared. Model errors shared among units
(filed H copied from one template) are not covered by it: they add linearly, not in quadrature.

The rate of change of frequency after the loss of ``largest_loss_mw`` is f0 dP / (2 E)
[Hz/s] (the swing equation of the area's units as one, before any governor acts; for an area,
as if it were islanded with the loss inside it); its interval is that expression at E's ends
(None above where E's lower end is 0). With E = 0 or no loss configured it is None, and
``rocof_reason`` says why.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

Z95 = 1.959963984540054
"""The standard normal's 97.5 % quantile: a 95 % interval is +-Z95 sigma."""
KINDS = ("synchronous", "grid_forming", "ibr_following", "no_h_record")
"""What a unit is: a synchronous machine, a grid-forming converter (virtual H), a
grid-following converter (no inertia) or an online unit without an H in the case."""
SOURCES = ("measured", "model", "model (stale)", "model (no estimate)", "model (no interval)", "ibr_following",
           "no H record", "offline")
"""Where a unit's contribution comes from (see the module docstring)."""
MEASURED_ERRORS = ("shared", "independent")


@dataclasses.dataclass(frozen=True)
class InertiaSettings:
    """The numbers of ``[inertia]`` that the aggregation uses."""

    model_uncertainty: float = 0.15
    """Half-width of the 95 % interval of a filed (model) H, relative to it [-]."""
    largest_loss_mw: float | None = None
    """The largest credible loss dP [MW] for the rate of change of frequency (None: not computed)."""
    f0_hz: float = 50.0
    """Nominal frequency [Hz]."""
    stale_s: float = 30.0
    """A measured unit whose last identified H is older than this [s] falls back to its model H."""
    floor_MWs: float | None = None
    """E below this [MW s] raises the alarm (``below_floor``); None: no floor."""
    measured_errors: str = "shared"
    """How the measured units' intervals combine: "shared" (their half-widths add) or
    "independent" (in quadrature); see the module docstring."""

    def __post_init__(self):
        if self.measured_errors not in MEASURED_ERRORS:
            raise ValueError(f"measured_errors must be one of {', '.join(MEASURED_ERRORS)}, got "
                             f"{self.measured_errors!r}")
        if not (0 <= self.model_uncertainty < 1):
            raise ValueError(f"model_uncertainty must be >= 0 and < 1, got {self.model_uncertainty!r}")
        if self.largest_loss_mw is not None and not self.largest_loss_mw > 0:
            raise ValueError(f"largest_loss_mw must be > 0, got {self.largest_loss_mw!r}")
        if not self.f0_hz > 0:
            raise ValueError(f"f0_hz must be > 0, got {self.f0_hz!r}")
        if not self.stale_s >= 0:
            raise ValueError(f"stale_s must be >= 0, got {self.stale_s!r}")
        if self.floor_MWs is not None and not self.floor_MWs >= 0:
            raise ValueError(f"floor_MWs must be >= 0, got {self.floor_MWs!r}")


class InertiaUnit(NamedTuple):
    """One unit as the aggregation sees it."""

    name: str
    area: str
    s_mva: float
    """Rating S [MVA] (MBASE): the base of its H."""
    online: bool
    kind: str = "synchronous"
    """One of :data:`KINDS`."""
    h_model_s: float | None = None
    """H of its .dyr record [s on s_mva] (a grid-forming unit: its virtual H); None: none."""
    h_s: float | None = None
    """Identified H [s on s_mva] (None: not measured, or no estimate)."""
    h_ci95: tuple[float, float] | None = None
    """Its 95 % interval [s]."""
    age_s: float | None = None
    """Seconds since the window that identified ``h_s`` ended (0: this one; None: not measured)."""
    measured: bool = False
    """Whether the unit is measured (a unit of the fleet or the monitor)."""


class UnitInertia(NamedTuple):
    """One unit's contribution."""

    name: str
    area: str
    online: bool
    kind: str
    source: str
    """One of :data:`SOURCES`."""
    h_s: float | None
    """The H used [s]."""
    e_MWs: float
    """H S [MW s] (0 offline)."""
    e_lo_MWs: float
    """Lower end of the 95 % interval of ``e_MWs`` [MW s]."""
    e_hi_MWs: float
    e_commitment_MWs: float
    """The commitment figure's term: the model H times S, online units only [MW s]."""


class AreaInertia(NamedTuple):
    """E of one area (or ``"system"``)."""

    area: str
    E_MWs: float
    E_ci95: tuple[float, float]
    E_measured_MWs: float
    measured_share: float | None
    """E of the measured units / E (None where E = 0)."""
    E_commitment_MWs: float
    """Every online unit at its .dyr H [MW s]."""
    rocof_hz_per_s: float | None
    rocof_ci95: tuple[float | None, float | None] | None
    rocof_reason: str | None
    """Why the rate of change of frequency is None (else None)."""
    units_online: int
    units_measured: int
    """Online units whose measured H is used."""
    units_stale: int
    """Measured units on their model H (stale, no estimate, or no interval)."""
    units_without_h: int
    """Online units without an H in the case, counted at 0 (E is then a lower bound)."""
    below_floor: bool | None
    """E below ``floor_MWs`` (None: no floor configured)."""

    def line(self, t: float) -> dict:
        """The ``updates.jsonl`` line at time ``t`` [s since 1970]."""
        return {"t": t, "area": self.area, "E_MWs": self.E_MWs, "E_ci95": list(self.E_ci95),
                "measured_share": self.measured_share, "E_commitment_MWs": self.E_commitment_MWs,
                "rocof_hz_per_s": self.rocof_hz_per_s, "units_online": self.units_online,
                "units_measured": self.units_measured}


def unit_inertia(u: InertiaUnit, settings: InertiaSettings) -> UnitInertia:
    """The contribution of one unit (see the module docstring)."""
    s = float(u.s_mva)
    model = None if u.h_model_s is None else float(u.h_model_s)
    if not u.online:
        return UnitInertia(u.name, u.area, False, u.kind, "offline", None, 0.0, 0.0, 0.0, 0.0)
    commitment = 0.0 if u.kind == "ibr_following" or model is None else model * s
    if u.kind == "ibr_following":
        return UnitInertia(u.name, u.area, True, u.kind, "ibr_following", 0.0, 0.0, 0.0, 0.0, 0.0)
    fresh = u.measured and u.h_s is not None and u.age_s is not None and u.age_s <= settings.stale_s
    if fresh and u.h_ci95 is not None:
        lo, hi = (float(x) for x in u.h_ci95)
        h = float(u.h_s)
        return UnitInertia(u.name, u.area, True, u.kind, "measured", h, h * s, min(lo, h) * s,
                           max(hi, h) * s, commitment)
    if model is None:
        return UnitInertia(u.name, u.area, True, "no_h_record" if not u.measured else u.kind,
                           "no H record", None, 0.0, 0.0, 0.0, 0.0)
    source = ("model" if not u.measured else "model (no interval)" if fresh
              else "model (no estimate)" if u.h_s is None or u.age_s is None else "model (stale)")
    e = model * s
    return UnitInertia(u.name, u.area, True, u.kind, source, model, e, e * (1 - settings.model_uncertainty),
                       e * (1 + settings.model_uncertainty), commitment)


def combine(contributions: list[UnitInertia], area: str, settings: InertiaSettings) -> AreaInertia:
    """E of ``contributions`` (one area's, or all) and its interval (see the module docstring)."""
    shared = settings.measured_errors == "shared"
    e = lo2 = hi2 = lo1 = hi1 = measured = commitment = 0.0
    online = n_measured = stale = without = 0
    for c in contributions:
        if not c.online:
            continue
        online += 1
        e += c.e_MWs
        if shared and c.source == "measured":
            lo1 += c.e_MWs - c.e_lo_MWs
            hi1 += c.e_hi_MWs - c.e_MWs
        else:
            lo2 += (c.e_MWs - c.e_lo_MWs) ** 2
            hi2 += (c.e_hi_MWs - c.e_MWs) ** 2
        commitment += c.e_commitment_MWs
        if c.source == "measured":
            n_measured += 1
            measured += c.e_MWs
        stale += c.source in ("model (stale)", "model (no estimate)", "model (no interval)")
        without += c.source == "no H record"
    return _area_row(area, e, math.sqrt(lo1 ** 2 + lo2), math.sqrt(hi1 ** 2 + hi2), measured, commitment,
                     online, n_measured, stale, without, settings)


def _area_row(area, e, lo, hi, measured, commitment, online, n_measured, stale, without,
              settings: InertiaSettings) -> AreaInertia:
    """An :class:`AreaInertia` from its sums; ``lo``, ``hi``: the interval's half-widths [MW s]."""
    e, measured, commitment = float(e), float(measured), float(commitment)
    ci = (max(0.0, e - float(lo)), e + float(hi))
    rocof, rocof_ci, why = None, None, None
    if settings.largest_loss_mw is None:
        why = "no largest_loss_mw configured"
    elif e <= 0:
        why = "no stored kinetic energy: no online unit with inertia" if online else "no online unit"
    else:
        k = settings.f0_hz * settings.largest_loss_mw / 2.0
        rocof = k / e
        rocof_ci = (k / ci[1], k / ci[0] if ci[0] > 0 else None)
    return AreaInertia(area=area, E_MWs=e, E_ci95=ci, E_measured_MWs=measured,
                       measured_share=measured / e if e > 0 else None, E_commitment_MWs=commitment,
                       rocof_hz_per_s=rocof, rocof_ci95=rocof_ci, rocof_reason=why, units_online=int(online),
                       units_measured=int(n_measured), units_stale=int(stale), units_without_h=int(without),
                       below_floor=None if settings.floor_MWs is None else e < settings.floor_MWs)


class UnitTable(NamedTuple):
    """The units as arrays, one entry each (a live monitor's thousands, every second): the
    same fields as :class:`InertiaUnit`, NaN where a value is absent."""

    area: np.ndarray
    """Index into the area names [int]."""
    s_mva: np.ndarray
    online: np.ndarray
    """[bool]"""
    ibr_following: np.ndarray
    """[bool] a grid-following converter (kind ``ibr_following``)."""
    h_model_s: np.ndarray
    """NaN: no filed H."""
    measured: np.ndarray
    """[bool]"""
    h_s: np.ndarray
    """NaN: no estimate."""
    h_lo_s: np.ndarray
    h_hi_s: np.ndarray
    """The estimate's 95 % interval (NaN: none)."""
    age_s: np.ndarray
    """inf: no estimate."""


def table_inertia(t: UnitTable, areas: list[str], settings: InertiaSettings) -> list[AreaInertia]:
    """:func:`area_inertia`'s areas (then the system's) for units as arrays: the same rules,
    vectorised (tests/core/test_inertia.py compares the two)."""
    s = np.asarray(t.s_mva, float)
    on = np.asarray(t.online, bool) & ~np.asarray(t.ibr_following, bool)
    fresh = np.asarray(t.measured, bool) & np.isfinite(t.h_s) & (np.asarray(t.age_s) <= settings.stale_s)
    meas = on & fresh & np.isfinite(t.h_lo_s) & np.isfinite(t.h_hi_s)
    has_model = np.isfinite(t.h_model_s)
    model = on & ~meas & has_model
    h_meas = np.where(meas, t.h_s, 0.0)
    e = np.where(meas, h_meas, np.where(model, t.h_model_s, 0.0)) * s
    u = settings.model_uncertainty
    lo = np.where(meas, (h_meas - np.minimum(np.where(meas, t.h_lo_s, 0.0), h_meas)) * s, e * u * model)
    hi = np.where(meas, (np.maximum(np.where(meas, t.h_hi_s, 0.0), h_meas) - h_meas) * s, e * u * model)
    linear = meas if settings.measured_errors == "shared" else np.zeros_like(meas)
    columns = (e, lo * linear, lo ** 2 * ~linear, hi * linear, hi ** 2 * ~linear, e * meas,
               np.where(on & has_model, np.where(has_model, t.h_model_s, 0.0) * s, 0.0),
               np.asarray(t.online, bool), meas, on & np.asarray(t.measured, bool) & ~meas & has_model,
               on & ~meas & ~has_model)
    idx = np.asarray(t.area, int)
    per_area = np.stack([np.bincount(idx, weights=np.asarray(c, float), minlength=len(areas)) for c in columns])
    total = per_area.sum(axis=1)
    rows = []
    for name, (e_a, lo1, lo2, hi1, hi2, m, com, n_on, n_m, n_st, n_wo) in zip(
            [*areas, "system"], [*per_area.T, total]):
        rows.append(_area_row(name, e_a, math.sqrt(lo1 ** 2 + lo2), math.sqrt(hi1 ** 2 + hi2), m, com,
                              round(n_on), round(n_m), round(n_st), round(n_wo), settings))
    return rows


def area_inertia(units: list[InertiaUnit], settings: InertiaSettings,
                 areas: list[str] | None = None) -> tuple[list[AreaInertia], list[UnitInertia]]:
    """E per area and for the system (the last row, ``"system"``), and each unit's contribution.

    Arguments:
        units: every unit of the case (online or not), the measured ones with their estimates.
        settings: the numbers of ``[inertia]``.
        areas: the areas to report, in order (an area without units gets E = 0); default:
            the units' areas in order of first appearance.

    Returns:
        (one :class:`AreaInertia` per area then the system's, one :class:`UnitInertia` per unit)."""
    contributions = [unit_inertia(u, settings) for u in units]
    by_area: dict = {a: [] for a in (areas or ())}
    for c in contributions:
        by_area.setdefault(c.area, []).append(c)
    rows = [combine(members, a, settings) for a, members in by_area.items()]
    return rows + [combine(contributions, "system", settings)], contributions
