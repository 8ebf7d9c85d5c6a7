"""A grid-forming converter's virtual inertia in ``jaxdse fleet``: H = M/2 and D of its own record
(REGCV1, REGCV2) fitted to the plant's recording by the record's playback, with 95 % intervals
and a verdict on the machine's scale.

Why the playback and not the swing-equation estimator: REGCV1's d axis follows the terminal
voltage through its voltage PI, not a fixed internal voltage; with the virtual rotor taken as a
classical machine (:func:`~jaxdse._dyr.gfm_unit.classical_plant`) the estimator's verdict was
``failed`` on every recording of ``experiments/andes_gfm`` (H = 139, -29, -252 s against 4 s),
while the fit of M and D by the playback came within 0.9 % of H with intervals that cover
(``experiments/andes_gfm/results.json``).
"""

from __future__ import annotations

from .._core.verdict import VerdictSettings
from .._dyr.calibrate import CalibrationSettings, ParameterSpec, calibrate, stack_events
from .._dyr.gfm_unit import GfmUnit
from .._dyr.playback import PlaybackSettings
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


def virtual_inertia(front, dyr: DyrOutcome, playback: PlaybackSettings, opts) -> dict:
    """H, D, their intervals and H's verdict (fleet.json's fields) of the grid-forming converter
    of ``dyr`` from the recording ``front`` (an :class:`~jaxdse._app.fleet.IbrTerminal`), ``opts``
    the fleet's [calibrate] options (bounds, noise floor, model error)."""
    unit = dyr.model.units[0].unit
    m0, d0 = float(unit.converter.m_s), float(unit.converter.d_pu)
    m_lo, m_hi = opts.bounds.get("M", (m0 / opts.bound_factor, m0 * opts.bound_factor))
    d_lo, d_hi = opts.bounds.get("D", (0.0, max(D_UPPER, 4 * d0)))
    specs = [ParameterSpec("converter", "m_s", "M", float(m_lo), float(m_hi)),
             ParameterSpec("converter", "d_pu", "D", float(d_lo), float(d_hi), positive=False)]
    series = terminal_series(front.time_s, front.v_t_pu, front.theta_t_rad, front.p_t_pu, front.q_t_pu)
    cal = calibrate(unit, specs, stack_events([series]), playback,
                    CalibrationSettings(noise_floor_pu=opts.noise_floor_pu, model_error=opts.model_error))
    (m, d), ((lo, hi), (dlo, dhi)) = cal.values, cal.ci95
    half = (hi - lo) / 2 / m if m > 0 else float("inf")
    reasons = {}
    if not cal.converged:
        verdict = "not identified"
        reasons["fit_not_converged"] = "the fit of M and D to the recording did not converge"
    elif half <= IDENTIFIED_CI:
        verdict = "identified"
    else:
        verdict = "weakly identified" if half <= WEAK_CI else "not identified"
        reasons["interval_wide"] = (f"H's 95 % interval is +-{100 * half:.0f} % of H: the recording "
                                    "does not move the virtual rotor enough")
    miss = max(float(x) for x in cal.rms_after_pu)
    if cal.converged and miss > MISS_FLOORS * opts.noise_floor_pu and verdict == "identified":
        verdict = "weakly identified"
        reasons["playback_misses"] = (f"with M and D fitted the playback still misses the recording by "
                                      f"{100 * miss:.2g} % of MBASE (RMS): other constants of the record "
                                      "than M and D do not fit it")
    for bound, side in ((m_lo, "lower"), (m_hi, "upper")):
        if abs(m - bound) <= 1e-6 * max(abs(bound), 1.0):
            verdict = "not identified"
            reasons["at_bound"] = f"M sits on its {side} bound ({bound:g} s): the fit is not an estimate"
    return {"H_s": m / 2, "H_ci95": [lo / 2, hi / 2], "H_record_s": m0 / 2,
            "D": float(d), "D_ci95": [float(dlo), float(dhi)], "D_record": d0,
            "verdict": verdict, "reasons": reasons, "relative_ci_percent": 100 * half,
            "rms_before_pu": [float(x) for x in cal.rms_before_pu],
            "rms_after_pu": [float(x) for x in cal.rms_after_pu]}


__all__ = ["is_grid_forming", "unfitted", "virtual_inertia"]
