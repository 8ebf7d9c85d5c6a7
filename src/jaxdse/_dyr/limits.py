"""Which limit of a unit's records its initial operating point lies outside (host side).

A unit initialised from the power flow at its terminal must hold its field voltage EFD0 and its
mechanical torque TM0 with every limited signal of its exciter and governor inside its limits:
the models' ``initial_state`` solves the steady state as if no limit were active. Where the
data put a signal outside its limit (an exciter that cannot produce EFD0, a governor whose
maximum power is below PG), the unit cannot start steady, and the record is at fault, not the
simulation. :func:`initial_limit_findings` names the record, the signal with its value, and the
CON it crosses with its value, one line each, from the steady state the models computed.

The signals are read from each model's steady state (its state vector, in the layout its
``initial_state`` documents) and from the unit's initial EFD0, TM0, terminal voltage and field
current; the limits are the record's CONs as the model applies them (scaled by the terminal
voltage where the model library does so). A model without an entry here still gets the generic
finding of :func:`jaxdse._app.check` (its EFD or TM at the initial state differs from the power
flow's), without the CON named.

Each crossing of a limit that one CON of the record sets also says how the limit follows from
that CON (:class:`Fix`: the limit = scale·CON + offset at this operating point), so that
:mod:`jaxdse._dyr.repair` can move the CON to where the signal fits; a limit no CON sets (an
exciter's floor at 0) has none.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from .._io.measurement import MAX_LOADING, MAX_Q_LAGGING
from .._models.exciters.common import saturation_product


class Start(NamedTuple):
    """A unit's initial operating point, as numbers (machine base)."""

    efd0: float
    """Field voltage that holds the machine's steady state [pu]."""
    tm0: float
    """Mechanical torque that holds the speed [pu]."""
    vt: float
    """Terminal voltage magnitude [pu]."""
    ifd: float
    """Field current LadIfd [pu]."""
    vref: float
    """The exciter's voltage reference [pu]."""


class Fix(NamedTuple):
    """How a limit follows from one constant of the record, at the unit's operating point:
    limit = ``scale`` · CON + ``offset``."""

    con: str
    """The record's constant (PSS/E name, as in its CON table: "VRMAX", "Ldref")."""
    scale: float = 1.0
    offset: float = 0.0


class Crossing(NamedTuple):
    """A signal of the steady state outside one of its limits."""

    signal: str
    """The signal and how it follows from the operating point, e.g. "VM0 = EFD0/VB"."""
    value: float
    con: str
    """The limit as the record names it, e.g. "VMMAX" or "VT·VRMAX"."""
    bound: float
    side: str
    """"above" or "below"."""
    context: str = ""
    """The record's values the signal follows from, e.g. "VB = 0.9255 from KP = 1, ..."."""
    fix: Fix | None = None
    """The CON that sets the limit, and how (None: no CON sets it)."""


def _g(x: float) -> str:
    return f"{x:.4g}"


def _f(m, name: str) -> float:
    return float(np.asarray(getattr(m, name)))


def _within(out: list, signal: str, value: float, lo: tuple | None, hi: tuple | None,
            context: str = "") -> None:
    """Append a :class:`Crossing` where ``value`` lies outside [lo, hi] by more than round-off;
    ``lo``, ``hi``: (the limit as the record names it, its value[, :class:`Fix`]); without a
    Fix, a limit named by a CON alone (an upper-case name) is that CON, scale 1."""
    for bound, side in ((hi, "above"), (lo, "below")):
        if bound is None:
            continue
        con, b = bound[:2]
        fix = bound[2] if len(bound) > 2 else (Fix(con) if _is_con(con) else None)
        tol = 1e-9 * max(1.0, abs(b))
        if (side == "above" and value > b + tol) or (side == "below" and value < b - tol):
            out.append(Crossing(signal, value, con, b, side, context, fix))


def _is_con(name: str) -> bool:
    return name.replace("(", "").replace(")", "").isalnum() and not name[0].isdigit()


# --- exciters -----------------------------------------------------------------------------------

def _sexs(m, y, s: Start):
    out: list = []
    _within(out, "EFD0", s.efd0, ("EMIN", _f(m, "e_min_pu")), ("EMAX", _f(m, "e_max_pu")))
    return out


def _scrx(m, y, s: Start):
    out: list = []
    what = "EX0 = EFD0" if m.cswitch == 1 else "EX0 = EFD0/ET"
    _within(out, what, float(y[1]), ("EMIN", _f(m, "e_min_pu")), ("EMAX", _f(m, "e_max_pu")))
    return out


def _dc(scaled: bool, floor: bool):
    def check(m, y, s: Start):
        out: list = []
        k = s.vt if scaled else 1.0
        pre = "VT·" if scaled else ""
        _within(out, "VR0 = (KE + SE(EFD0))·EFD0", float(y[2]),
                (pre + "VRMIN", k * _f(m, "vr_min_pu"), Fix("VRMIN", k)),
                (pre + "VRMAX", k * _f(m, "vr_max_pu"), Fix("VRMAX", k)))
        if floor:
            _within(out, "EFD0", s.efd0, ("0 (the exciter's floor)", 0.0), None)
        return out
    return check


def _exst1(m, y, s: Start):
    out: list = []
    ka, kc = _f(m, "ka"), _f(m, "kc")
    _within(out, "VI0 = EFD0/KA", s.efd0 / ka, ("VIMIN", _f(m, "vi_min_pu")), ("VIMAX", _f(m, "vi_max_pu")))
    _within(out, "EFD0", s.efd0,
            ("VT·VRMIN - KC·IFD0", s.vt * _f(m, "vr_min_pu") - kc * s.ifd, Fix("VRMIN", s.vt, -kc * s.ifd)),
            ("VT·VRMAX - KC·IFD0", s.vt * _f(m, "vr_max_pu") - kc * s.ifd, Fix("VRMAX", s.vt, -kc * s.ifd)))
    return out


def _esst3a(m, y, s: Start):
    out: list = []
    _within(out, "VI0 = VR0/KA", float(y[1]), ("VIMIN", _f(m, "vi_min_pu")), ("VIMAX", _f(m, "vi_max_pu")))
    _within(out, "VR0", float(y[2]), ("VRMIN", _f(m, "vr_min_pu")), ("VRMAX", _f(m, "vr_max_pu")))
    _within(out, "VM0 = EFD0/VB", float(y[3]), ("VMMIN", _f(m, "vm_min_pu")), ("VMMAX", _f(m, "vm_max_pu")))
    return out


def _esst4b(m, y, s: Start):
    out: list = []
    _within(out, "VR0 = KG·EFD0", float(y[1]), ("VRMIN", _f(m, "vr_min_pu")), ("VRMAX", _f(m, "vr_max_pu")))
    vb = s.efd0 / float(y[3]) if float(y[3]) != 0 else float("nan")
    _within(out, "VM0 = EFD0/VB", float(y[3]), ("VMMIN", _f(m, "vm_min_pu")), ("VMMAX", _f(m, "vm_max_pu")),
            f"VB = {_g(vb)} from KP = {_g(_f(m, 'kp'))}, KI = {_g(_f(m, 'ki'))}, KC = {_g(_f(m, 'kc'))}, "
            f"VT = {_g(s.vt)}, IFD0 = {_g(s.ifd)}; VBMAX = {_g(_f(m, 'vb_max_pu'))}")
    return out


def _esst1a(m, y, s: Start):
    out: list = []
    va = float(y[3])
    _within(out, "VA0 = EFD0 + KLR·max(IFD0 - ILR, 0)", va, ("VAMIN", _f(m, "va_min_pu")),
            ("VAMAX", _f(m, "va_max_pu")))
    _within(out, "VI0 = VA0/KA", va / _f(m, "ka"), ("VIMIN", _f(m, "vi_min_pu")),
            ("VIMAX", _f(m, "vi_max_pu")))
    kc = _f(m, "kc")
    _within(out, "EFD0", s.efd0, ("VT·VRMIN", s.vt * _f(m, "vr_min_pu"), Fix("VRMIN", s.vt)),
            ("VT·VRMAX - KC·IFD0", s.vt * _f(m, "vr_max_pu") - kc * s.ifd, Fix("VRMAX", s.vt, -kc * s.ifd)))
    return out


def _expic1(m, y, s: Start):
    out: list = []
    vr = float(y[1])
    _within(out, "VR0 = E0/VB", vr, ("VR2", _f(m, "vr2_pu")), ("VR1", _f(m, "vr1_pu")))
    _within(out, "VR0 = E0/VB", vr, ("VRMIN", _f(m, "vr_min_pu")), ("VRMAX", _f(m, "vr_max_pu")))
    if _f(m, "t_e_s") > 0:
        e0 = _f(m, "ke") * s.efd0 + float(saturation_product(
            s.efd0, _f(m, "e1_pu"), _f(m, "se1"), _f(m, "e2_pu"), _f(m, "se2")))
        what = "E0 = (KE + SE(EFD0))·EFD0"
    else:
        e0, what = s.efd0, "E0 = EFD0"
    _within(out, what, e0, ("EFDMIN", _f(m, "efd_min_pu")), ("EFDMAX", _f(m, "efd_max_pu")))
    return out


VFE = "VFE0 = KD·IFD0 + (KE + SE(VE0))·VE0"


def _vfe_context(m, s: Start, ve0: float) -> str:
    return f"KD = {_g(_f(m, 'kd'))}, IFD0 = {_g(s.ifd)}, KE = {_g(_f(m, 'ke'))}, VE0 = {_g(ve0)}"


def _ac_common(out, m, y, s: Start):
    _within(out, "VE0", float(y[3]), ("0 (the alternator's floor)", 0.0), None)


def _esac1a(m, y, s: Start):
    out: list = []
    vfe = float(y[4])
    ctx = _vfe_context(m, s, float(y[3]))
    _within(out, "VA0 = VR0 = " + VFE, vfe, ("VAMIN", _f(m, "va_min_pu")), ("VAMAX", _f(m, "va_max_pu")), ctx)
    _within(out, "VR0 = " + VFE, vfe, ("VRMIN", _f(m, "vr_min_pu")), ("VRMAX", _f(m, "vr_max_pu")), ctx)
    _ac_common(out, m, y, s)
    return out


def _exac1(m, y, s: Start):
    out: list = []
    _within(out, "VR0 = " + VFE, float(y[4]), ("VRMIN", _f(m, "vr_min_pu")), ("VRMAX", _f(m, "vr_max_pu")),
            _vfe_context(m, s, float(y[3])))
    _ac_common(out, m, y, s)
    return out


def _exac2(m, y, s: Start):
    out: list = []
    vfe, va = float(y[4]), float(y[2])
    _within(out, "VA0 = VFE0/KB + KH·VFE0", va, ("VAMIN", _f(m, "va_min_pu")), ("VAMAX", _f(m, "va_max_pu")))
    _within(out, "VR0 = " + VFE, vfe, ("VRMIN", _f(m, "vr_min_pu")), ("VRMAX", _f(m, "vr_max_pu")),
            _vfe_context(m, s, float(y[3])))
    kl = _f(m, "kl")
    vl = kl * (_f(m, "vlr_pu") - vfe)
    _within(out, "VA0 - KH·VFE0 (the regulator's path into the LV gate)", va - _f(m, "kh") * vfe,
            None, ("VL = KL·(VLR - VFE0), the field current limiter", vl, Fix("VLR", kl, -kl * vfe)))
    _ac_common(out, m, y, s)
    return out


def _esac6a(m, y, s: Start):
    out: list = []
    va = float(y[1])
    vfe = float(y[4]) + _f(m, "vfe_lim_pu")
    _within(out, "VA0 = VFE0 + VH0", va, ("VAMIN", _f(m, "va_min_pu")), ("VAMAX", _f(m, "va_max_pu")))
    _within(out, "VR0 = " + VFE, vfe, ("VT·VRMIN", s.vt * _f(m, "vr_min_pu"), Fix("VRMIN", s.vt)),
            ("VT·VRMAX", s.vt * _f(m, "vr_max_pu"), Fix("VRMAX", s.vt)), _vfe_context(m, s, float(y[3])))
    _ac_common(out, m, y, s)
    return out


EXCITER_LIMITS: dict[str, Callable] = {
    "SEXS": _sexs, "SCRX": _scrx,
    "IEEEX1": _dc(False, False), "IEEET1": _dc(False, False), "IEEET2": _dc(False, False),
    "ESDC1A": _dc(False, True),
    "EXDC2": _dc(True, False), "ESDC2A": _dc(True, True),
    "EXST1": _exst1, "ESST3A": _esst3a, "ESST4B": _esst4b, "ESST1A": _esst1a, "EXPIC1": _expic1,
    "ESAC1A": _esac1a, "EXAC1": _exac1, "EXAC2": _exac2, "ESAC6A": _esac6a,
}
"""PSS/E exciter name -> (module, its steady state, :class:`Start`) -> [:class:`Crossing`]."""


# --- governors ----------------------------------------------------------------------------------

def _tgov1(m, s: Start):
    out: list = []
    _within(out, "valve0 = TM0", s.tm0, ("VMIN", _f(m, "v_min_pu")), ("VMAX", _f(m, "v_max_pu")))
    return out


def _ieeeg1(m, s: Start):
    out: list = []
    k = _f(m, "k1") + _f(m, "k3") + _f(m, "k5") + _f(m, "k7")
    _within(out, "GV0 = TM0/(K1 + K3 + K5 + K7)", s.tm0 / k, ("PMIN", _f(m, "p_min_pu")),
            ("PMAX", _f(m, "p_max_pu")), f"K1 + K3 + K5 + K7 = {_g(k)}")
    return out


def _gast(m, s: Start):
    out: list = []
    _within(out, "valve0 = TM0", s.tm0, ("VMIN", _f(m, "v_min_pu")), ("VMAX", _f(m, "v_max_pu")))
    _within(out, "valve0 = TM0", s.tm0, None, ("AT (the load limit)", _f(m, "at_pu"), Fix("AT")))
    return out


def _hygov(m, s: Start):
    out: list = []
    at, qnl = _f(m, "at_pu"), _f(m, "q_nl_pu")
    _within(out, "gate0 = TM0/At + qNL", s.tm0 / at + qnl, ("GMIN", _f(m, "g_min_pu")),
            ("GMAX", _f(m, "g_max_pu")), f"At = {_g(at)}, qNL = {_g(qnl)}")
    return out


def _ggov1(m, s: Start):
    out: list = []
    kt, wfnl, ratio = _f(m, "k_turb"), _f(m, "w_fnl_pu"), _f(m, "base_ratio")
    base = f", Trate/MBASE = {_g(ratio)}" if ratio != 1.0 else ""
    fsr = s.tm0 / ratio / kt + wfnl
    what = "FSR0 = TM0/Kturb + Wfnl" if ratio == 1.0 else "FSR0 = TM0/(Trate/MBASE)/Kturb + Wfnl"
    ctx = f"Kturb = {_g(kt)}, Wfnl = {_g(wfnl)}{base}"
    _within(out, what, fsr, ("Vmin", _f(m, "v_min_pu")), ("Vmax", _f(m, "v_max_pu")), ctx)
    _within(out, what, fsr, None, ("Ldref/Kturb + Wfnl (the load limiter)", _f(m, "ldref_pu") / kt + wfnl,
                                    Fix("Ldref", 1.0 / kt, wfnl)), ctx + f", Ldref = {_g(_f(m, 'ldref_pu'))}")
    return out


def _ieesgo(m, s: Start):
    out: list = []
    _within(out, "P0 = TM0", s.tm0, ("PMIN", _f(m, "p_min_pu")), ("PMAX", _f(m, "p_max_pu")))
    return out


def _wsieg1(m, s: Start):
    out: list = []
    gv = float(np.asarray(m.valve_for_flow(s.tm0 / float(np.asarray(m.k_hp)))))
    _within(out, "GV0 (valve for the flow TM0/(K1 + K3 + K5 + K7))", gv, ("PMIN", _f(m, "p_min_pu")),
            ("PMAX", _f(m, "p_max_pu")))
    return out


GOVERNOR_LIMITS: dict[str, Callable] = {
    "TGOV1": _tgov1, "IEEEG1": _ieeeg1, "GAST": _gast, "HYGOV": _hygov, "GGOV1": _ggov1,
    "IEESGO": _ieesgo, "WSIEG1": _wsieg1,
}
"""PSS/E governor name -> (module, :class:`Start`) -> [:class:`Crossing`]."""


def describe(crossing: Crossing) -> str:
    """"VM0 = EFD0/VB = 1.421 above VMMAX = 1"."""
    c = crossing
    return (f"{c.signal} = {_g(c.value)} {c.side} {c.con} = {_g(c.bound)}"
            + (f" ({c.context})" if c.context else ""))


PT_UNSET_MW = 9999.0
"""PSS/E's default PT [MW]: at or above it, the .raw states no maximum output."""


def rating_crossings(pg_mw: float, qg_mvar: float, mbase_mva: float) -> list[Crossing]:
    """The generator's power flow outside the capability its .raw MBASE gives it: the apparent
    power |PG + jQG| above ``MAX_LOADING`` x MBASE, or the lagging QG above ``MAX_Q_LAGGING`` x
    MBASE (the field-heating limit): where ``jaxdse fleet`` refuses a recording of the unit (no
    machine runs so far above its rating). MBASE is the base its dynamic records are per unit
    of, so records set up for the unit's real rating read as a machine run beyond it (TM0 =
    PG/MBASE; a governor's gate and an exciter's field voltage past their limits). The fix is the
    base itself (:class:`Fix` "MBASE"; the apparent power is held within MBASE itself, the margin
    ``MAX_LOADING`` only flags), the records' per-unit values kept."""
    if not (mbase_mva > 0 and math.isfinite(mbase_mva)):
        return []
    out = []
    s0 = math.hypot(pg_mw, qg_mvar)
    if math.isfinite(s0) and s0 > MAX_LOADING * mbase_mva:
        out.append(Crossing("|S0| = |PG + jQG|", s0, "MBASE", mbase_mva, "above",
                            f"PG = {_g(pg_mw)} MW, QG = {_g(qg_mvar)} Mvar: {s0 / mbase_mva:.3g} x MBASE, "
                            f"flagged above {MAX_LOADING:g} x", Fix("MBASE")))
    if math.isfinite(qg_mvar) and qg_mvar > MAX_Q_LAGGING * mbase_mva:
        out.append(Crossing("QG", qg_mvar, f"{MAX_Q_LAGGING:g}·MBASE", MAX_Q_LAGGING * mbase_mva, "above",
                            f"the field-heating limit at P = 0; PG = {_g(pg_mw)} MW",
                            Fix("MBASE", MAX_Q_LAGGING)))
    return out


def exciter_crossings(model: str, module, state, start: Start) -> list[Crossing]:
    """The exciter's steady-state signals outside their limits ([] for a model not listed)."""
    f = EXCITER_LIMITS.get(model)
    if f is None or not all(math.isfinite(float(x)) for x in np.asarray(state)):
        return []
    return f(module, np.asarray(state, float), start)


def governor_crossings(model: str, module, start: Start) -> list[Crossing]:
    """The governor's steady-state signals outside their limits ([] for a model not listed)."""
    f = GOVERNOR_LIMITS.get(model)
    return [] if f is None else f(module, start)


__all__ = ["EXCITER_LIMITS", "GOVERNOR_LIMITS", "PT_UNSET_MW", "Crossing", "Fix", "Start", "describe",
           "exciter_crossings", "governor_crossings", "rating_crossings"]
