"""``jaxdse check`` of an inverter-based plant (REGCA1 or REGCB1 + REECA1, REECB1 or REECCU1, optional
REPCA1, optional type-3 wind mechanics WTTQA1, WTPTA1, WTARA1, WTDTA1): its records,
its runs and its judgement, beside the synchronous units of :mod:`jaxdse._app.check`.

Three runs with the terminal voltage imposed (as the playback drives a plant: the measured
voltage phasor and frequency), from the power flow at the terminal:

  held    voltage and frequency held: every state derivative at t = 0 below 1e-6, P and Q at
          20 s within 1e-5 pu of the power flow;
  vstep   |V| stepped by 2 % at 1 s, the voltage references (REECA1 Vref0/Vref1, REPCA1 Vref)
          moved with it (an imposed voltage leaves the voltage loops open: their integrators
          would otherwise wind up to a limit);
  fstep   the frequency stepped by 0.1 Hz at 1 s (the plant controller's droop and its P loop,
          Fflag = 1; no effect without a plant controller or with Fflag = 0).

The steps pass when they stay finite and settle, or are still settling at the end with every mode
of the linearisation there decaying (a plant controller's slow P loop, noted with its time
constant); the voltage step is not judged where REECA1's inner voltage loop closes only through
the network (QFLAG = 1 with VFLAG = 1, noted): over the last 5 s P and Q within 10 % of the
range they span after the step (at least 0.001 pu) of their final value, every state derivative
below 1e-2. A data problem is a record whose values cannot be simulated, or whose limits the
power flow crosses (P0 outside PMIN..PMAX, Q0 outside QMIN..QMAX, |I0| above IMAX or REGCB1's Imax,
VT outside VMIN..VMAX where REECB1/REECCU1 regulate it with VFLAG = 0, REECCU1's SOCini at SOCmin
while discharging or at SOCmax while charging, or reaching it within the runs at P0: the CON and
both values named). REECCU1's state of
charge integrates the output power: it is left out of the at-rest derivative and of the modes.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dyr.gfm_unit import GfmUnit
from .._dyr.ibr_unit import IbrUnit
from .._dyr.inventory import is_converter
from .._dyr.records import PSSE_IBR_MODELS, ibr_model
from .._dyr.stiff import modes
from .._dyr.unit import UnitInputs
from .._io.psse import DyrData, RawCase, RawGenerator, record_label
from .._models.ibr import IBR_MODELS, IBR_ROLES, REGFM_A1, REGFM_B1

IBR_KINDS = ("converter", "electrical", "plant")
"""The roles of a plant's records in the columns of the reports."""
WIND_KINDS = ("torque", "pitch", "aero", "drive")
"""The roles of a type-3 wind turbine's mechanics records (after :data:`IBR_KINDS` in a chain)."""
F_STEP_HZ = 0.1
"""The frequency step of the third run [Hz]."""


class IbrStatic(NamedTuple):
    models: dict
    records: dict
    unsupported: list
    problems: list
    model: object
    warnings: list


def ibr_static(raw: RawCase, dyr: DyrData, g: RawGenerator, horizon_s: float = 21.0) -> IbrStatic:
    """The plant's records by role, the ones jaxdse does not simulate, the value problems its
    models' checks find, and the limits its power flow crosses (one line each, naming the
    record and the CON); REECCU1's state of charge reaching its limit within ``horizon_s`` (the
    runs' length) at the power flow's P counts as crossing it."""
    recs = dyr.unit_records(g.bus, g.id)
    models: dict = dict.fromkeys(IBR_KINDS)
    records: dict = {}
    unsupported = []
    for r in recs:
        role = IBR_ROLES.get(r.model, PSSE_IBR_MODELS.get(r.model))
        if role is None and not is_converter(r.model):
            continue
        if role in IBR_KINDS + WIND_KINDS and role not in records:
            records[role], models[role] = r, r.model
        if r.model not in IBR_MODELS:
            what = {"wind": "type-3 wind turbine model", None: "converter model"}.get(role, f"{role} model")
            unsupported.append((r.model, f"{record_label(r)}: {what} {r.model} is not simulated by jaxdse "
                                         f"(inverter-based models simulated: {', '.join(IBR_MODELS)})"))
    um = ibr_model(dyr, g.bus, g.id, raw)
    problems = []
    for line in um.missing:
        if "is not simulated" in line:
            continue
        at = [r.model for r in recs if line.startswith(record_label(r))]
        problems.append((at[0] if at else None, line))
    if g.problem:
        problems.append(("generator", g.problem))
    if not (math.isfinite(g.mbase_mva) and g.mbase_mva > 0):
        problems.append(("generator", f"generator on bus {g.bus} id {g.id!r}: MBASE = {g.mbase_mva:g} "
                                      "must be > 0"))
    bus = raw.buses.get(g.bus)
    if bus is None or bus.problem or not (math.isfinite(bus.vm_pu) and bus.vm_pu > 0):
        problems.append(("bus", f"bus {g.bus} of the generator: no usable voltage VM"))
    elif isinstance(um.unit, IbrUnit) and not problems:
        problems += _crossings(um.unit, records, g, bus.vm_pu, horizon_s)
    elif (isinstance(um.unit, GfmUnit) and not problems
          and isinstance(um.unit.converter, (REGFM_A1, REGFM_B1))):
        problems += _gfm_crossings(um.unit.converter, records["converter"], g, bus)
    return IbrStatic(models, records, unsupported, problems, um, [])


def _crossings(unit: IbrUnit, records: dict, g: RawGenerator, vt: float, horizon_s: float = 21.0) -> list:
    """The limits of the records that the power flow crosses at the start."""
    p0, q0 = g.pg_mw / g.mbase_mva, g.qg_mvar / g.mbase_mva
    i0 = math.hypot(p0, q0) / vt
    where = (f"PG = {g.pg_mw:g} MW, QG = {g.qg_mvar:g} Mvar on MBASE = {g.mbase_mva:g} MVA, "
             f"VT = {vt:.4g} pu")
    out = []

    def cross(role, con, value, bound, side, signal):
        if (side == "above" and value > bound + 1e-9) or (side == "below" and value < bound - 1e-9):
            out.append((records[role].model,
                        f"{record_label(records[role])}: {signal} = {value:.4g} pu {side} {con} = {bound:.4g} "
                        f"({where}): the record's own limit does not let the plant hold its power flow"))

    e = unit.electrical
    if records["converter"].model == "REGCB1":
        cross("converter", "Imax", i0, float(unit.converter.i_max_pu), "above", "|I0|")
    if e is not None and records["electrical"].model != "REECA1" and e.qflag and not e.vflag:
        cross("electrical", "VMAX", vt, float(e.v_max_pu), "above", "VT")
        cross("electrical", "VMIN", vt, float(e.v_min_pu), "below", "VT")
    if e is not None and records["electrical"].model == "REECCU1":   # the power order limit the SOC sets at the start
        soc, lo, hi = float(e.soc_ini_pu), float(e.soc_min_pu), float(e.soc_max_pu)
        t_soc = float(e.t_soc_s)
        for bad, con, bound, what in ((p0 > 1e-9, "SOCmin", lo, "discharging, PMAX taken to 0"),
                                      (p0 < -1e-9, "SOCmax", hi, "charging, PMIN taken to 0")):
            if not bad:
                continue
            reach = (soc - bound) * t_soc / p0        # d SOC/dt = -P0/T
            head = f"{record_label(records['electrical'])}: SOCini = {soc:.4g}"
            if reach <= 0:
                out.append((records["electrical"].model,
                            f"{head} at or beyond {con} = {bound:.4g} with P0 = {p0:.4g} pu ({what}; {where}): "
                            "the record's own limit does not let the plant hold its power flow"))
            elif reach < horizon_s:
                out.append((records["electrical"].model,
                            f"{head} reaches {con} = {bound:.4g} after {reach:.3g} s at P0 = {p0:.4g} pu "
                            f"(T = {t_soc:g} s; {what}; {where}): the plant cannot hold its power flow "
                            f"for the {horizon_s:g} s of the check"))
    if e is not None:
        cross("electrical", "PMAX", p0, float(e.p_max_pu), "above", "P0")
        cross("electrical", "PMIN", p0, float(e.p_min_pu), "below", "P0")
        cross("electrical", "IMAX", i0, float(e.i_max_pu), "above", "|I0|")
    if e is not None and (e.qflag or not e.vflag):
        cross("electrical", "QMAX", q0, float(e.q_max_pu), "above", "Q0")
        cross("electrical", "QMIN", q0, float(e.q_min_pu), "below", "Q0")
    if unit.plant is not None:
        cross("plant", "QMAX", q0, float(unit.plant.q_max_pu), "above", "Qext0")
        cross("plant", "QMIN", q0, float(unit.plant.q_min_pu), "below", "Qext0")
        cross("plant", "PMAX", p0, float(unit.plant.p_max_pu), "above", "Pref0")
        cross("plant", "PMIN", p0, float(unit.plant.p_min_pu), "below", "Pref0")
    return out


def _gfm_crossings(conv: REGFM_A1 | REGFM_B1, rec, g: RawGenerator, bus) -> list:
    """The limits of a REGFM_A1 or REGFM_B1 record that its power flow crosses at the start.
    REGFM_A1: P, Q within the overload controllers' Pmin..Pmax, Qmin..Qmax; |I0| within Imax; the
    internal voltage E0 behind ZSORCE within Emin..Emax. REGFM_B1: |I0| within ImaxSS (and its
    priority axis within kf ImaxSS); the angle of E0 from V within dmax = asin(XL ImaxSS); P0 >= 0
    without ESFlag."""
    p0, q0 = g.pg_mw / g.mbase_mva, g.qg_mvar / g.mbase_mva
    v = bus.vm_pu * complex(math.cos(math.radians(bus.va_deg)), math.sin(math.radians(bus.va_deg)))
    i0 = ((p0 + 1j * q0) / v).conjugate()
    e0 = abs(v + complex(float(conv.re_pu), float(conv.xe_pu)) * i0)
    where = (f"PG = {g.pg_mw:g} MW, QG = {g.qg_mvar:g} Mvar on MBASE = {g.mbase_mva:g} MVA, "
             f"VT = {bus.vm_pu:.4g} pu")
    if isinstance(conv, REGFM_B1):
        i_ss, xl = float(conv.i_max_ss_pu), float(conv.xe_pu)
        e = v + complex(float(conv.re_pu), xl) * i0
        angle = math.atan2((e / v).imag, (e / v).real)
        i_pll = i0 * v.conjugate() / abs(v)          # Id - j Iq in the voltage's frame
        prio, axis = (i_pll.real, "Id0") if int(conv.pqflag) else (-i_pll.imag, "Iq0")
        checks = [("|I0|", abs(i0), "ImaxSS", i_ss, "above"),
                  (axis, abs(prio), "kf ImaxSS", float(conv.kf) * i_ss, "above"),
                  ("dIT0", angle, "dmax = asin(XL ImaxSS)", math.asin(min(xl * i_ss, 1.0)), "above")]
        if not int(conv.esflag):
            checks.append(("P0", p0, "0 (ESFlag = 0: a generator)", 0.0, "below"))
    else:
        checks = [(s, x, con, float(getattr(conv, f)), side) for s, x, con, f, side in (
            ("P0", p0, "Pmax", "p_max_pu", "above"), ("P0", p0, "Pmin", "p_min_pu", "below"),
            ("Q0", q0, "Qmax", "q_max_pu", "above"), ("Q0", q0, "Qmin", "q_min_pu", "below"),
            ("E0", e0, "Emax", "e_max_pu", "above"), ("E0", e0, "Emin", "e_min_pu", "below"))]
        if float(conv.i_max_pu) > 0:
            checks.append(("|I0|", abs(i0), "Imax", float(conv.i_max_pu), "above"))
    return [(rec.model, f"{record_label(rec)}: {signal} = {value:.4g} pu {side} {con} = {bound:.4g} "
                        f"({where}): the record's own limit does not let the plant hold its power flow")
            for signal, value, con, bound, side in checks
            if (side == "above" and value > bound + 1e-9) or (side == "below" and value < bound - 1e-9)]


class IbrLane(NamedTuple):
    """One run of one plant: the power flow at its terminal, the voltage step (fraction of |V|)
    and the frequency step [pu of nominal]."""

    v_re: jax.Array
    v_im: jax.Array
    i_re: jax.Array
    i_im: jax.Array
    v_step: jax.Array
    f_step: jax.Array


class IbrResult(NamedTuple):
    dy0: jax.Array
    y0: jax.Array
    p_t0: jax.Array
    q_t0: jax.Array
    p: jax.Array
    q: jax.Array
    dy_end: jax.Array
    jac_t0: jax.Array
    jac_end: jax.Array
    ok: jax.Array


def lanes(raw: RawCase, g: RawGenerator, v_step: float) -> list[IbrLane]:
    """The held, voltage-step and frequency-step runs of generator ``g``."""
    b = raw.buses[g.bus]
    v = b.vm_pu * complex(math.cos(math.radians(b.va_deg)), math.sin(math.radians(b.va_deg)))
    i = ((g.pg_mw + 1j * g.qg_mvar) / g.mbase_mva / v).conjugate()
    df = F_STEP_HZ / raw.basfrq_hz
    return [IbrLane(*(jnp.asarray(float(x)) for x in (v.real, v.imag, i.real, i.imag, dv, f)))
            for dv, f in ((0.0, 0.0), (v_step, 0.0), (0.0, df))]


def _one(unit: IbrUnit, lane: IbrLane, run) -> IbrResult:
    from .check import _integrate

    zero = jnp.zeros_like(lane.v_re)
    u0 = UnitInputs(lane.v_re, lane.v_im, zero, zero)
    y0, refs = unit.initial_state(u0, lane.i_re, lane.i_im)
    dy0 = unit.vector_field(y0, u0, refs)
    rest = np.flatnonzero(unit.at_rest)   # the modes of the states a steady state holds (not REECCU1's SOC)
    jac0 = jax.jacfwd(lambda y: unit.vector_field(y, u0, refs))(y0)[rest][:, rest]
    s0 = unit.signals(y0, u0, refs)
    v0 = jnp.hypot(lane.v_re, lane.v_im)

    def at(t):   # the steps just after step_at_s; the voltage references move with |V|
        on = t > run.step_at_s
        k = 1.0 + jnp.where(on, lane.v_step, 0.0)
        dv = jnp.where(on, lane.v_step * v0, 0.0)
        u = UnitInputs(lane.v_re * k, lane.v_im * k, jnp.where(on, lane.f_step, 0.0), zero)
        if isinstance(unit, GfmUnit):   # its own rotor makes its frequency: the step turns the phasor
            turn = unit.omega_s_rad_s * jnp.where(on, lane.f_step * (t - run.step_at_s), 0.0)
            c, s = jnp.cos(turn), jnp.sin(turn)
            u = u._replace(v_re_pu=u.v_re_pu * c - u.v_im_pu * s, v_im_pu=u.v_re_pu * s + u.v_im_pu * c)
            return u, refs._replace(v_ref_pu=refs.v_ref_pu + dv)
        e = refs.electrical._replace(v_ref0_pu=refs.electrical.v_ref0_pu + dv,
                                     v_ref1_pu=refs.electrical.v_ref1_pu + dv)
        p = refs.plant._replace(v_ref_pu=refs.plant.v_ref_pu + dv)
        return u, refs._replace(electrical=e, plant=p)

    def rhs(t, y, args):
        return unit.vector_field(y, *at(t))

    n = int(round(run.end_s * run.frame_hz)) + 1
    ts = np.arange(n) / run.frame_hz
    ys, solved = _integrate(rhs, y0, run, n)

    def outputs(t, y):
        s = unit.signals(y, *at(t))
        return s.p_pu, s.q_pu

    p, q = jax.vmap(outputs)(jnp.asarray(ts), ys)
    ok = solved & jnp.all(jnp.isfinite(ys))
    y_end = jnp.where(ok, ys[-1], y0)
    dy_end = rhs(run.end_s, y_end, None)
    jac_end = jax.jacfwd(lambda y: rhs(run.end_s, y, None))(y_end)[rest][:, rest]
    return IbrResult(dy0, y0, s0.p_pu, s0.q_pu, p, q, dy_end, jac0, jac_end, ok)


_BATCH: list = []


def batch_jit():
    """The jitted, vmapped :func:`_one` (made once)."""
    if not _BATCH:
        _BATCH.append(eqx.filter_jit(eqx.filter_vmap(_one, in_axes=(0, 0, None))))
    return _BATCH[0]


def at(r: IbrResult, j: int) -> dict:
    """Lane ``j`` of ``r`` (host arrays) with its modes (host NumPy)."""
    out = {f: np.asarray(getattr(r, f)[j]) for f in r._fields}
    out["growth_end"], out["fastest_end"] = modes(out["jac_end"])
    out["fastest_t0"] = modes(out["jac_t0"])[1]
    return out


def _state_name(unit: IbrUnit, models: dict, k: int) -> str:
    start = 0
    for kind, n in zip(unit.PARTS, unit.sizes):
        if k < start + n:
            return f"{models.get(kind)} state {k - start + 1} of {n}"
        start += n
    return f"state {k}"


OPEN_LOOP_NOTE = ("REECA1/REECB1/REECCU1 QFLAG = 1 with VFLAG = 1: its Q loop sets a voltage command "
                  "that its inner "
                  "voltage loop reaches through the network; with the terminal voltage imposed that loop is "
                  "open (two integrators in series, undamped), so the voltage step is run but not judged")


GFM_NOTE = ("a virtual synchronous generator (REGCV1, REGCV2) sets its angle and voltage through the "
            "network: "
            "with its terminal voltage imposed its virtual rotor has no synchronising power (two modes at "
            "0 at rest), so the voltage and frequency steps are run but not judged (the held run is)")


def judge(st: IbrStatic, g: RawGenerator, held: dict, steps: tuple[dict, dict], spec
          ) -> tuple[str, list[str], dict, list[str]]:
    """(outcome, reasons, numbers, notes) of a plant that was simulated."""
    unit, models = st.model.unit, st.models
    p0, q0 = g.pg_mw / g.mbase_mva, g.qg_mvar / g.mbase_mva
    kh = int(round(spec.held_s * spec.frame_hz))
    dy0 = np.where(unit.at_rest, np.abs(held["dy0"]), 0.0)   # REECCU1's SOC integrates P: not at rest
    k0 = int(np.argmax(dy0)) if dy0.size else 0
    numbers = {"max_dxdt_t0": float(np.max(dy0)) if dy0.size else 0.0,
               "max_dxdt_t0_state": _state_name(unit, models, k0),
               "p_error_t0_pu": float(held["p_t0"] - p0), "q_error_t0_pu": float(held["q_t0"] - q0),
               "p_error_held_pu": float(held["p"][kh] - p0), "q_error_held_pu": float(held["q"][kh] - q0)}
    fails = []
    if not (numbers["max_dxdt_t0"] < spec.max_derivative):
        fails.append(f"not steady at t = 0: |d(state)/dt| = {numbers['max_dxdt_t0']:.3g} "
                     f"({numbers['max_dxdt_t0_state']}) above {spec.max_derivative:g}")
    if not (abs(numbers["p_error_t0_pu"]) < spec.max_derivative
            and abs(numbers["q_error_t0_pu"]) < spec.max_derivative):
        fails.append(f"the initial state injects P, Q off the power flow by {numbers['p_error_t0_pu']:.3g}, "
                     f"{numbers['q_error_t0_pu']:.3g} pu: a limit binds at the start")
    if not bool(held["ok"]):
        fails.append("held run: the solver did not reach the end (or states became non-finite)")
    elif not (abs(numbers["p_error_held_pu"]) < spec.max_pq_error
              and abs(numbers["q_error_held_pu"]) < spec.max_pq_error):
        fails.append(f"held run: P, Q at {spec.held_s:g} s differ from the power flow by "
                     f"{numbers['p_error_held_pu']:.3g}, {numbers['q_error_held_pu']:.3g} pu "
                     f"(limit {spec.max_pq_error:g})")
    if fails:
        return "fail", fails, numbers, []
    elec = getattr(unit, "electrical", None)   # (none in a grid-forming converter)
    open_loop = elec is not None and bool(elec.qflag) and bool(elec.vflag)
    gfm = isinstance(unit, GfmUnit) and not unit.converter.judged_with_voltage_imposed
    notes = [OPEN_LOOP_NOTE] if open_loop else [GFM_NOTE] if gfm else []
    t = np.arange(len(held["p"])) / spec.frame_hz
    after = t > spec.step_at_s
    win = t >= t[-1] - spec.settle_window_s - 1e-9
    why = []
    for label, r in ((f"the {100 * spec.step:g} % voltage step", steps[0]),
                     (f"the {F_STEP_HZ:g} Hz frequency step", steps[1])):
        key = "vstep" if "voltage" in label else "fstep"
        if not bool(r["ok"]):
            why.append(f"{label}: the solver did not reach the end (or states became non-finite)")
            continue
        moves = []
        if (key == "vstep" and open_loop) or gfm:
            continue
        for name, x in (("P", np.asarray(r["p"], float)), ("Q", np.asarray(r["q"], float))):
            seen = np.concatenate([x[:1], x[after]])
            span = float(np.max(seen) - np.min(seen))
            band = max(spec.settle_fraction * span, spec.settle_floor_pu)
            spread = float(np.max(np.abs(x[win] - x[-1])))
            numbers[f"{key}_{name.lower()}_change_pu"] = float(x[-1] - x[0])
            numbers[f"{key}_{name.lower()}_final_spread_pu"] = spread
            if spread > band:
                moves.append(f"{name} moves by {spread:.3g} pu over the last {spec.settle_window_s:g} s "
                             f"(band {band:.3g} pu)")
        d_end = np.array(r["dy_end"], float)
        if key == "fstep" and isinstance(unit, GfmUnit):   # its angle turns with the imposed phasor
            d_end[unit.converter.angle_state] -= 2 * math.pi * F_STEP_HZ
        dy_end = np.where(unit.at_rest, np.abs(d_end), 0.0)
        numbers[f"{key}_max_dxdt_end"] = float(np.max(dy_end)) if dy_end.size else 0.0
        if numbers[f"{key}_max_dxdt_end"] > spec.settle_derivative:
            k = int(np.argmax(dy_end))
            moves.append(f"|d(state)/dt| = {numbers[f'{key}_max_dxdt_end']:.3g} at {t[-1]:g} s "
                         f"({_state_name(unit, models, k)}; limit {spec.settle_derivative:g})")
        growth = float(r["growth_end"])
        numbers[f"{key}_growth_rate_end_per_s"] = growth if math.isfinite(growth) else None
        if moves and math.isfinite(growth) and growth < 0:   # slow, and every mode decays
            notes.append(f"{label}: still settling at {t[-1]:g} s (" + "; ".join(moves) + f"); linearised "
                         f"there every mode decays, the slowest with a time constant of {-1.0 / growth:.3g} s")
        elif moves:
            grows = (f" (linearised at {t[-1]:g} s, a mode grows at {growth:.3g} 1/s)"
                     if math.isfinite(growth) and growth > 0 else "")
            why.append(f"{label}: not settled {t[-1] - spec.step_at_s:g} s after it: " + "; ".join(moves) + grows)
    if why:
        return "fail", why, numbers, notes
    return "pass", [], numbers, notes


__all__ = ["F_STEP_HZ", "IBR_KINDS", "WIND_KINDS", "IbrLane", "IbrResult", "IbrStatic", "at", "batch_jit", "ibr_static",
           "judge", "lanes"]
