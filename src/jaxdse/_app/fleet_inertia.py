"""``jaxdse fleet`` with ``[inertia]``: the system inertia per area for the recording, from the
plants' identified H and every other unit of the case at its .dyr H (``inertia.csv``,
fleet.json's ``inertia`` and the figure ``inertia.png``).

From files it is one value per recording: each measured plant's whole-recording estimate (its
identified H and interval), the case's other units at the status the .raw (or the status CSV at
the recording's last sample) gives. A measured plant is online when its recorded current's mean
is above ``online_current_pu`` [pu of its rating]; an estimate that is not `identified` (weakly
identified included) leaves the plant on its model H (``model (no estimate)``).
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .._core.inertia import AreaInertia, UnitInertia, area_inertia
from .._dyr.inertia import area_list, case_units, inertia_units, measured_plant
from .fleet_file import Fleet, FleetPlant

USED_VERDICTS = ("identified",)
"""H verdicts whose estimate counts as measured (as in the monitor): a weakly identified H, whose
interval is wide, leaves the plant on its model H."""
CSV_FIELDS = ("area", "E_MWs", "E_ci95_low", "E_ci95_high", "E_measured_MWs", "measured_share",
              "E_commitment_MWs", "rocof_hz_per_s", "rocof_ci95_low", "rocof_ci95_high", "rocof_reason",
              "units_online", "units_measured", "units_stale", "units_without_h", "below_floor")


def fleet_inertia(fleet: Fleet, plants: list[FleetPlant], entries: list[dict], currents: dict,
                  t_end: float | None) -> tuple[list[AreaInertia], list[UnitInertia], list[str]]:
    """E per area and system for the recording (see the module docstring).

    Arguments:
        plants, entries: the plants estimated and their fleet.json entries (same order).
        currents: plant name -> mean recorded |I| [pu of its rating].
        t_end: the recording's last time [s] (the status CSV is read there)."""
    cfg = fleet.inertia
    case, notes = case_units(fleet.raw, fleet.dyr, cfg)
    measured, estimates, online = [], {}, {}
    for p, e in zip(plants, entries):
        measured.append(measured_plant(p.name, p.bus, [m.id for m in p.members], e["s_mva"], case, fleet.raw,
                                       cfg.areas))
        lo, hi = e["H_ci95"]
        if e["verdict"] in USED_VERDICTS and e["H_s"] is not None and lo is not None and hi is not None:
            estimates[p.name] = (e["H_s"], (lo, hi), 0.0)
        if p.name in currents:
            online[p.name] = bool(currents[p.name] > cfg.online_current_pu)
    units = inertia_units(case, measured, estimates, online, cfg.status, t_end)
    areas, contributions = area_inertia(units, cfg.settings(fleet.raw.basfrq_hz),
                                        area_list(fleet.raw, case, cfg.areas))
    return areas, contributions, notes


def inertia_document(fleet: Fleet, areas: list[AreaInertia], units: list[UnitInertia], notes: list[str]) -> dict:
    """fleet.json's ``inertia``."""
    cfg = fleet.inertia
    s = cfg.settings(fleet.raw.basfrq_hz)
    return {
        "method": "E = sum H S over the online units [MW s]: measured plants at their identified H (whole "
                  "recording), the case's other units at their .dyr H (model), grid-following converters at 0; "
                  "95 % interval: unit intervals as split-normal errors, the measured units' half-widths added "
                  "(shared errors; or in quadrature: measured_errors = independent), the model units' in "
                  "quadrature, the two in quadrature; rocof = f0 dP / (2 E)",
        "time_resolution": "one value per recording",
        "settings": {"areas": cfg.areas if isinstance(cfg.areas, str) else {k: list(v) for k, v in cfg.areas.items()},
                     "status": "raw" if cfg.status is None else cfg.status.source,
                     "model_uncertainty": s.model_uncertainty, "largest_loss_mw": s.largest_loss_mw,
                     "f0_hz": s.f0_hz, "stale_s": s.stale_s, "floor_MWs": s.floor_MWs,
                     "online_current_pu": cfg.online_current_pu, "measured_errors": s.measured_errors},
        "areas": [area_row(a) for a in areas],
        "units": [u._asdict() for u in units],
        "notes": notes,
    }


def area_row(a: AreaInertia) -> dict:
    """One area's entry: the updates.jsonl fields and the rest of :class:`AreaInertia`."""
    return {**{k: v for k, v in a.line(None).items() if k != "t"}, "E_measured_MWs": a.E_measured_MWs,
            "rocof_ci95": None if a.rocof_ci95 is None else list(a.rocof_ci95), "rocof_reason": a.rocof_reason,
            "units_stale": a.units_stale, "units_without_h": a.units_without_h, "below_floor": a.below_floor}


def write_inertia_csv(path: Path, areas: list[AreaInertia]) -> None:
    def f(x):
        return "" if x is None else (format(x, ".6g") if isinstance(x, float) else str(x))

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_FIELDS)
        for a in areas:
            rc = a.rocof_ci95 or (None, None)
            w.writerow([a.area, f(a.E_MWs), f(a.E_ci95[0]), f(a.E_ci95[1]), f(a.E_measured_MWs),
                        f(a.measured_share), f(a.E_commitment_MWs), f(a.rocof_hz_per_s), f(rc[0]), f(rc[1]),
                        a.rocof_reason or "", a.units_online, a.units_measured, a.units_stale, a.units_without_h,
                        "" if a.below_floor is None else str(a.below_floor).lower()])


def inertia_figure(path: Path, areas: list[AreaInertia], floor_MWs: float | None, title: str) -> None:
    """Per area and for the system: a bar of E split into its measured part (dark) and its model
    part (light), the 95 % interval as a whisker, the commitment figure as a marker and the
    floor as a line; in GW s so that a control room reads it."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [a.area for a in areas]
    x = np.arange(len(areas))
    g = 1e-3    # MW s -> GW s
    meas = np.array([a.E_measured_MWs for a in areas]) * g
    total = np.array([a.E_MWs for a in areas]) * g
    lo = np.array([a.E_ci95[0] for a in areas]) * g
    hi = np.array([a.E_ci95[1] for a in areas]) * g
    com = np.array([a.E_commitment_MWs for a in areas]) * g
    import textwrap

    fig, ax = plt.subplots(figsize=(max(7.0, 1.1 * len(areas) + 3), 6.0))
    ax.bar(x, meas, color="#1f4e79", label="measured units (identified H)")
    ax.bar(x, total - meas, bottom=meas, color="#9dc3e6", label="other online units (H from the model records)")
    ax.errorbar(x, total, yerr=[total - lo, hi - total], fmt="none", ecolor="black", capsize=6,
                label="95 % interval of the stored energy")
    ax.plot(x + 0.3, com, "D", color="#c00000", markersize=7,
            label="commitment figure (every online unit at its model H)")
    if floor_MWs is not None:
        ax.axhline(floor_MWs * g, color="#c00000", linestyle="--", label=f"floor {floor_MWs * g:g} GW s (alarm below)")
    for k, a in enumerate(areas):
        share = "" if a.measured_share is None else f"{100 * a.measured_share:.0f} % measured"
        rocof = "" if a.rocof_hz_per_s is None else f"\n{a.rocof_hz_per_s:.3g} Hz/s"
        ax.annotate(f"{share}{rocof}", (k, max(hi[k], com[k])), textcoords="offset points", xytext=(0, 4), ha="center",
                    fontsize=8)
    ax.set_xticks(x, [n if n != "system" else "whole system" for n in names])
    ax.set_ylabel("stored kinetic energy E = sum of H x MVA  [GW s]")
    ax.set_title("\n".join(textwrap.wrap(title, 90)), fontsize=10)
    ax.set_ylim(0, max(1e-9, float(max(hi.max(initial=0), com.max(initial=0)))) * 1.25)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=2, frameon=False)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
