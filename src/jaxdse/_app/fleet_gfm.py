"""A grid-forming converter's virtual inertia in ``jaxdse fleet``: the constants of its own record
that set H and D fitted to the plant's recording by the record's playback, with 95 % intervals
and a verdict on the machine's scale: REGCV1, REGCV2 M and D (H = M/2); REGFM_A1 TPf and mp, the
power filter and droop of its equivalent swing equation TPf/mp d(dw)/dt = Pref - P - dw/mp (H =
TPf / (2 mp), D = 1/mp); REGFM_B1 H and mp (D = 1/mp + D1, its steady-state damping).

Why the playback and not the swing-equation estimator: REGCV1's d axis follows the terminal
voltage through its voltage PI, not a fixed internal voltage; with the virtual rotor taken as a
classical machine (:func:`~jaxdse._dyr.gfm_unit.classical_plant`) the estimator's verdict was
``failed`` on every recording of ``experiments/andes_gfm`` (H = 139, -29, -252 s against 4 s),
while the fit of M and D by the playback came within 0.9 % of H with intervals that cover
(``experiments/andes_gfm/results.json``).
"""

from __future__ import annotations

import math

from .._core.verdict import VerdictSettings
from .._dyr.calibrate import CalibrationSettings, ParameterSpec, calibrate, stack_events
from .._dyr.gfm_unit import GfmUnit
from .._dyr.playback import PlaybackSettings
from .._models.ibr import REGFM_A1, REGFM_B1
from .dyr_fleet import DyrOutcome, terminal_series

IDENTIFIED_CI = VerdictSettings().identified_ci
"""H is ``identified`` when the fit converged and its 95 % half-width is within this fraction of
H ..."""
WEAK_CI = VerdictSettings().not_identified_ci
"""... ``weakly identified`` within this fraction; else ``not identified`` (the machine
verdict's thresholds)."""
MISS_FLOORS = 5.0
"""H is at most ``weakly identified`` when the fitted playback misses P or Q by more than this
many noise floors (RMS): the record's other constants do not fit the recording."""
D_UPPER = 20.0
"""D's upper bound [pu power / pu speed] (or 4 times the record's D where that is larger)."""
BOX_Z = 2.2414 / 1.9600
"""REGFM_A1: each of TPf's and mp's 95 % half-widths is widened by z(0.9875)/z(0.975), so that
the box of the two (97.5 % each) holds both at 95 % at least (Bonferroni), and H = TPf / (2 mp)
and D = 1/mp taken over the box's corners are 95 % intervals at least."""
B1_MEANING = ("the virtual synchronous machine's swing equation 2H d(dwm)/dt = Pref - P - (1/mp) dwm "
              "- D1 dwm - D2 s/(s + wD) dwm: H [s on MBASE] and the P-f droop mp of the record fitted to "
              "the recording by its playback; D = 1/mp + D1 [pu power / pu speed] is its steady-state "
              "damping (D1 alone with FFlag = 0; the washout's D2 acts in transients only)")
B1_D_MEANING = ("D = FFlag/mp + D1 [pu power / pu speed]: the steady-state damping of the record's P-f droop "
                "and D1, from the fitted mp; the washout's transient damping D2 is not in it")
A1_D_MEANING = ("D = 1/mp [pu power / pu speed]: the damping of the droop's equivalent swing equation, from "
                "the fitted mp")
A1_MEANING = ("the droop's equivalent swing equation TPf/mp d(dw)/dt = Pref - P - dw/mp: H = TPf / (2 mp) "
              "[s on MBASE] and D = 1/mp [pu power / pu speed], from the record's P filter TPf and P-f droop "
              "mp fitted to the recording by its playback")


def is_grid_forming(dyr: DyrOutcome | None) -> bool:
    """True when the plant's .dyr playback is one grid-forming converter's."""
    return (dyr is not None and dyr.playback is not None and len(dyr.model.units) == 1
            and isinstance(dyr.model.units[0].unit, GfmUnit))


def unfitted(dyr: DyrOutcome | None) -> dict | None:
    """The H fields of a plant with grid-forming converters whose virtual inertia is not fitted
    (several units behind one PMU: their shares of P and Q are not measured); None when the
    plant has none or is fitted (:func:`is_grid_forming`)."""
    if dyr is None or is_grid_forming(dyr):
        return None
    n = sum(isinstance(u.unit, GfmUnit) for u in dyr.model.units)
    if n == 0:
        return None
    why = (f"{n} grid-forming converter(s) among {len(dyr.model.units)} units behind one PMU: their "
           "shares of P and Q are not measured, so no virtual H is fitted")
    return {"plant_type": "grid-forming", "verdict": "not identified", "reasons": {"several_units": why},
            "estimator": why}


def _box(cal, j):
    """Parameter ``j``'s interval widened to 97.5 % (:data:`BOX_Z`), within (0, inf)."""
    x, (lo, hi) = float(cal.values[j]), (float(c) for c in cal.ci95[j])
    return max(x - BOX_Z * (x - lo), 1e-12 * x), x + BOX_Z * (hi - x)


def virtual_inertia(front, dyr: DyrOutcome, playback: PlaybackSettings, opts) -> dict:
    """H, D, their intervals and H's verdict (fleet.json's fields) of the grid-forming converter
    of ``dyr`` from the recording ``front`` (an :class:`~jaxdse._app.fleet.IbrTerminal`), ``opts``
    the fleet's [calibrate] options (bounds, noise floor, model error)."""
    unit = dyr.model.units[0].unit
    conv = unit.converter
    droop = isinstance(conv, REGFM_A1)
    vsm = isinstance(conv, REGFM_B1)
    if vsm or droop:   # (field, label) of the two constants fitted, both positive, bounds x/f..x*f
        fitted = (("h_s", "H"), ("mp", "mp")) if vsm else (("t_pf_s", "TPf"), ("mp", "mp"))
        x0, y0 = (float(getattr(conv, f)) for f, _ in fitted)
        labels = tuple(lab for _, lab in fitted)
        specs = [ParameterSpec("converter", f, lab, *map(float, opts.bounds.get(
                     lab, (x / opts.bound_factor, x * opts.bound_factor))))
                 for (f, lab), x in zip(fitted, (x0, y0))]
    else:
        x0, y0 = float(conv.m_s), float(conv.d_pu)
        labels = ("M", "D")
        m_lo, m_hi = opts.bounds.get("M", (x0 / opts.bound_factor, x0 * opts.bound_factor))
        d_lo, d_hi = opts.bounds.get("D", (0.0, max(D_UPPER, 4 * y0)))
        specs = [ParameterSpec("converter", "m_s", "M", float(m_lo), float(m_hi)),
                 ParameterSpec("converter", "d_pu", "D", float(d_lo), float(d_hi), positive=False)]
    series = terminal_series(front.time_s, front.v_t_pu, front.theta_t_rad, front.p_t_pu, front.q_t_pu)
    cal = calibrate(unit, specs, stack_events([series]), playback,
                    CalibrationSettings(noise_floor_pu=opts.noise_floor_pu, model_error=opts.model_error))
    x, y = (float(v) for v in cal.values)
    if vsm:   # H is a constant of the record; D the steady-state FFlag/mp + D1
        (lo, hi), (yl, yh) = (float(c) for c in cal.ci95[0]), (float(c) for c in cal.ci95[1])
        h, h0 = x, x0
        k, d1 = float(int(conv.fflag) != 0), float(conv.d1_pu)
        d, (dlo, dhi), d0 = k / y + d1, (k / yh + d1, k / yl + d1), k / y0 + d1
    elif droop:
        (xl, xh), (yl, yh) = _box(cal, 0), _box(cal, 1)
        h, (lo, hi), h0 = x / (2 * y), (xl / (2 * yh), xh / (2 * yl)), x0 / (2 * y0)
        d, (dlo, dhi), d0 = 1 / y, (1 / yh, 1 / yl), 1 / y0
    else:
        (ml, mh), (dlo, dhi) = cal.ci95
        h, (lo, hi), h0 = x / 2, (float(ml) / 2, float(mh) / 2), x0 / 2
        d, (dlo, dhi), d0 = y, (float(dlo), float(dhi)), y0
    half = (hi - lo) / 2 / h if h > 0 and math.isfinite(hi - lo) else float("inf")
    reasons = {}
    if not cal.converged:
        verdict = "not identified"
        reasons["fit_not_converged"] = (f"the fit of {labels[0]} and {labels[1]} to the recording did not "
                                        "converge")
    elif half <= IDENTIFIED_CI:
        verdict = "identified"
    else:
        verdict = "weakly identified" if half <= WEAK_CI else "not identified"
        reasons["interval_wide"] = (f"H's 95 % interval is +-{100 * half:.0f} % of H: the recording "
                                    "does not move the virtual rotor enough")
    miss = max(float(v) for v in cal.rms_after_pu)
    if cal.converged and miss > MISS_FLOORS * opts.noise_floor_pu and verdict == "identified":
        verdict = "weakly identified"
        reasons["playback_misses"] = (f"with {labels[0]} and {labels[1]} fitted the playback still misses "
                                      f"the recording by {100 * miss:.2g} % of MBASE (RMS): other constants "
                                      f"of the record than {labels[0]} and {labels[1]} do not fit it")
    for spec, value in zip(specs if (droop or vsm) else specs[:1], (x, y)):
        for bound, side in ((spec.lower, "lower"), (spec.upper, "upper")):
            if abs(value - bound) <= 1e-6 * max(abs(bound), 1.0):
                verdict = "not identified"
                reasons["at_bound"] = (f"{spec.label} sits on its {side} bound ({bound:g}): the fit is not "
                                       "an estimate")
    return {"H_s": h, "H_ci95": [lo, hi], "H_record_s": h0,
            "D": d, "D_ci95": [dlo, dhi], "D_record": d0,
            "fitted": {lab: {"value": float(v), "ci95": [float(c) for c in ci], "record": r}
                       for lab, v, ci, r in zip(labels, cal.values, cal.ci95, (x0, y0))},
            "meaning": A1_MEANING if droop else B1_MEANING if vsm else None,
            "d_meaning": A1_D_MEANING if droop else B1_D_MEANING if vsm else None,
            "verdict": verdict, "reasons": reasons, "relative_ci_percent": 100 * half,
            "rms_before_pu": [float(v) for v in cal.rms_before_pu],
            "rms_after_pu": [float(v) for v in cal.rms_after_pu]}


__all__ = ["is_grid_forming", "unfitted", "virtual_inertia"]
