"""PSS/E records (.dyr and .raw) to jaxdse: machine and transformer keyword arguments, governor
modules, and the checks that tell a usable unit from one the fleet leaves out.

Conventions are in each function's docstring; the readers are :mod:`.psse_dyr` and
:mod:`.psse_raw`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from .._models.base import record_message
from .._models.governors import GOVERNORS, AbstractGovernor
from .errors import InputError
from .psse_dyr import GOVERNOR_PARAMETERS, MACHINE_FIELDS, DyrData, DyrRecord
from .psse_raw import RawCase, RawGenerator, RawTransformer

BIG_SHUNT_PU = 1e12
"""r_Fe and x_M [pu] standing for a zero magnetising admittance (Transformer needs > 0)."""
DEFAULT_TAP_STEP = 0.0125
"""Tap step used when the transformer record has no tap range (RMA1 = RMI1 or NTP1 < 2)."""
GENCLS_TD0_S = 1e6
"""T'do [s] for GENCLS (constant E' behind X'd): effectively infinite."""


@dataclass(frozen=True)
class MachineTransientData:
    """Transient/subtransient data beyond jaxdse's third-order model (for a later model-
    mismatch correction). Reactances [pu, machine base], time constants [s]; None where the
    model has no such quantity (GENSAL has no q-axis transient circuit)."""

    model: str
    xq1_pu: float | None
    """X'q."""
    tq01_s: float | None
    """T'qo."""
    xd2_pu: float
    """X''d (= X''q in GENROU/GENSAL/GENTPJ)."""
    td02_s: float
    """T''do."""
    tq02_s: float
    """T''qo."""
    xl_pu: float
    """Xl, stator leakage."""
    s10: float = 0.0
    """S(1.0) of the record."""
    s12: float = 0.0
    """S(1.2) of the record."""


ROUND_ROTOR = ("GENROU", "GENROE", "GENTPJ")
"""Round-rotor machine models: q-axis transient and subtransient circuits (X''q = X''d)."""
SALIENT_POLE = ("GENSAL", "GENSAE")
"""Salient-pole machine models: no q-axis transient circuit."""


def machine_kwargs(gen_dyr_record: DyrRecord, raw_generator: RawGenerator, bus_kv: float,
                   f_nominal_hz: float) -> dict:
    """Keyword arguments of :class:`jaxdse.Machine` from a machine record and its generator.

    Conventions:

    * reactances and T'do from the .dyr record (PSS/E order); GENCLS has none: x'd is the
      .raw ZSORCE reactance ZX, xd = xq = x'd, T'do = ``GENCLS_TD0_S`` (constant E');
    * ``rs_pu`` = ZSORCE resistance ZR from the .raw (PSS/E keeps Ra there), on MBASE;
    * ``s_rated_mva`` = MBASE, ``v_rated_kv`` = the bus base voltage;
    * damping: PSS/E's D is pu power per pu speed deviation, 2H d(dw)/dt = Pm - Pe - D dw.
      jaxdse's ``d_pu_s`` multiplies x2 = w_s dw [rad/s] in dx2/dt = w_s/(2H)(Tm - Te - D x2),
      so ``d_pu_s = D / w_s`` with w_s = 2 pi f (then a1 = w_s d/(2H) = D/(2H)).
    """
    rec = gen_dyr_record
    if rec.kind != "machine":
        raise rec.error(f"is not a machine model ({', '.join(MACHINE_FIELDS)})")
    g = raw_generator
    if not g.mbase_mva > 0:
        raise InputError(g.source, f"generator {g.bus} {g.id!r}: MBASE is {g.mbase_mva} MVA; "
                            "it must be > 0", row=g.line)
    if not bus_kv > 0:
        raise InputError(g.source, f"generator {g.bus} {g.id!r}: bus base voltage is {bus_kv} kV; "
                            "it must be > 0", row=g.line)
    omega_s = 2.0 * math.pi * f_nominal_hz
    p = rec.params
    if rec.model == "GENCLS":
        xd1 = g.zx_pu
        xd = xq = xd1
        td0 = GENCLS_TD0_S
    else:
        xd, xd1, xq, td0 = p["Xd"], p["X'd"], p["Xq"], p["T'do"]
    return dict(xd_pu=xd, xd1_pu=xd1, xq_pu=xq, rs_pu=g.zr_pu, td01_s=td0, h_s=p["H"],
                d_pu_s=p["D"] / omega_s, s_rated_mva=g.mbase_mva, v_rated_kv=bus_kv,
                f_nominal_hz=f_nominal_hz)


def transient_data(gen_dyr_record: DyrRecord) -> MachineTransientData | None:
    """The transient q-axis and subtransient data of a round-rotor (GENROU, GENROE, GENTPJ) or
    salient-pole (GENSAL, GENSAE) record (None for GENCLS)."""
    rec = gen_dyr_record
    if rec.model == "GENCLS":
        return None
    if rec.kind != "machine":
        raise rec.error("is not a machine model")
    p = rec.params
    salient = rec.model in SALIENT_POLE
    return MachineTransientData(model=rec.model, xq1_pu=None if salient else p["X'q"],
                                tq01_s=None if salient else p["T'qo"], xd2_pu=p["X''d"],
                                td02_s=p["T''do"], tq02_s=p["T''qo"], xl_pu=p["Xl"],
                                s10=p["S(1.0)"], s12=p["S(1.2)"])


def _g(x) -> str:
    return f"{x:g}" if isinstance(x, (int, float)) else repr(x)


def record_label(record: DyrRecord) -> str:
    """``GENROU on bus 3 id '1' (case.dyr line 7)``: a record, for one-line messages."""
    return (f"{record.model} on bus {record.bus} id {record.id!r} "
            f"({Path(record.source).name or '.dyr'} line {record.line})")


def generator_label(generator: RawGenerator) -> str:
    """``generator on bus 3 id '1' (case.raw line 11)``."""
    return (f"generator on bus {generator.bus} id {generator.id!r} "
            f"({Path(generator.source).name or '.raw'} line {generator.line})")


def machine_problems(record: DyrRecord, generator: RawGenerator) -> list[str]:
    """What makes a machine record (GENCLS/GENSAL/GENROU/GENTPJ) and its .raw generator record
    unusable for :func:`machine_kwargs` and :class:`jaxdse.Machine`: one line each, naming the
    record and the values; empty when both are usable.

    Checked: the records read (``problem``); finite values; H, T'do, Xd, Xq, X'd > 0 (GENCLS:
    H > 0 and the ZSORCE reactance ZX > 0); D >= 0; X'd <= Xd; MBASE > 0; ZR >= 0. The q-axis
    circuits are checked apart (:func:`q_axis_problems`): jaxdse can do without them; odd
    values that can still be evaluated are :func:`machine_warnings`.
    """
    out = []
    g = generator
    if record.kind != "machine":
        return [f"{record_label(record)}: not a machine model ({', '.join(MACHINE_FIELDS)})"]
    if record.problem:
        out.append(record.problem)
    else:
        p = record.params
        where = record_label(record)
        positive = ("H",) if record.model == "GENCLS" else ("H", "T'do", "Xd", "Xq", "X'd")
        for name in positive:
            if not (math.isfinite(p[name]) and p[name] > 0):
                out.append(f"{where}: {name} = {_g(p[name])} must be > 0")
        if not (math.isfinite(p["D"]) and p["D"] >= 0):
            out.append(f"{where}: D = {_g(p['D'])} must be >= 0")
        if record.model != "GENCLS" and p["X'd"] > p["Xd"] > 0:
            xd1, xd = p["X'd"], p["Xd"]
            out.append(f"{where}: X'd = {_g(xd1)} above Xd = {_g(xd)}")
    if g.problem:
        out.append(g.problem)
        return out
    where = generator_label(g)
    if not (math.isfinite(g.mbase_mva) and g.mbase_mva > 0):
        out.append(f"{where}: MBASE = {_g(g.mbase_mva)} MVA must be > 0")
    if not (math.isfinite(g.zr_pu) and g.zr_pu >= 0):
        out.append(f"{where}: ZR (Ra) = {_g(g.zr_pu)} must be >= 0")
    if record.model == "GENCLS" and not (math.isfinite(g.zx_pu) and g.zx_pu > 0):
        out.append(f"{where}: ZX (X'd of GENCLS) = {_g(g.zx_pu)} must be > 0")
    return out


def q_axis_problems(record: DyrRecord) -> list[str]:
    """Why the q-axis circuits of a GENROU/GENTPJ record cannot be evaluated by
    :class:`jaxdse.QAxisCircuits`: a value not finite, T'qo, T''qo, X'q or X''d not > 0, Xl < 0,
    X'q equal to Xl (the equations divide by X'q - Xl), or equations that diverge with these
    values and Xq (the trace of their state matrix not negative; its determinant is always
    positive): one line each, naming the record and the values; empty when usable (and for
    models without these circuits). Odd but usable values (X''d below Xl, above X'q, X'q above
    Xq) are no problem: :func:`machine_warnings` lists them and the circuits are used as given.
    """
    if record.model not in ROUND_ROTOR or record.problem:
        return []
    p, where, out = record.params, record_label(record), []
    names = ("X'q", "X''d", "Xl", "Xq", "T'qo", "T''qo")
    bad = [n for n in names if not math.isfinite(p[n])]
    if bad:
        return [f"{where}: {', '.join(f'{n} = {_g(p[n])}' for n in bad)} not finite"]
    for name in ("T'qo", "T''qo", "X'q", "X''d"):
        if not p[name] > 0:
            out.append(f"{where}: {name} = {_g(p[name])} must be > 0")
    xd2, xq1, xl, xq, t1, t2 = p["X''d"], p["X'q"], p["Xl"], p["Xq"], p["T'qo"], p["T''qo"]
    if xl < 0:
        out.append(f"{where}: Xl = {_g(xl)} must be >= 0")
    if xq1 == xl:
        out.append(f"{where}: X'q = {_g(xq1)} equal to Xl: the q-axis equations divide by X'q - Xl")
    elif not out and (1.0 + (xq - xq1) * (xq1 - xd2) / (xq1 - xl) ** 2) / t1 + 1.0 / t2 <= 0:
        out.append(f"{where}: the q-axis equations diverge with X'q = {_g(xq1)}, X''d = {_g(xd2)}, "
                   f"Xl = {_g(xl)}, Xq = {_g(xq)}, T'qo = {_g(t1)}, T''qo = {_g(t2)}")
    return out


def machine_warnings(record: DyrRecord) -> list[str]:
    """Odd values of a GENROU/GENTPJ/GENSAL record that jaxdse uses as given, because its
    equations can be evaluated (PSS/E warns about such records and simulates them): X''d below
    or equal to Xl, X''d not below X'd, X''d (= X''q) above X'q, X'q above Xq (round rotor),
    X''d not below Xq (GENSAL). One line each, naming the record and the values; empty for a
    record in the usual order Xl < X''d < X'd, X''d <= X'q <= Xq, and for a record with a
    problem or a value not finite (those are :func:`machine_problems`)."""
    if record.model not in ROUND_ROTOR + SALIENT_POLE or record.problem:
        return []
    p, where = record.params, record_label(record)
    round_rotor = record.model != "GENSAL"
    names = ("X''d", "Xl", "X'd", "Xq") + (("X'q",) if round_rotor else ())
    if not all(math.isfinite(p[n]) for n in names):
        return []
    xd2, xl, xd1, xq = p["X''d"], p["Xl"], p["X'd"], p["Xq"]
    odd = []
    if xd2 < xl:
        odd.append(f"X''d = {_g(xd2)} below Xl = {_g(xl)}")
    elif xd2 == xl:
        odd.append(f"X''d = {_g(xd2)} equal to Xl")
    if xd2 >= xd1:
        odd.append(f"X''d = {_g(xd2)} not below X'd = {_g(xd1)}")
    if round_rotor:
        xq1 = p["X'q"]
        if xd2 > xq1:
            odd.append(f"X''d (= X''q) = {_g(xd2)} above X'q = {_g(xq1)}")
        if xq1 > xq:
            odd.append(f"X'q = {_g(xq1)} above Xq = {_g(xq)}")
    elif xd2 >= xq:
        odd.append(f"X''d = {_g(xd2)} not below Xq = {_g(xq)}")
    return [f"{where}: {o}: used as given (PSS/E warns about such records and simulates them)"
            for o in odd]


def transformer_sides(raw_transformer: RawTransformer, raw_case: RawCase) -> tuple[int, int]:
    """(HV bus, LV bus): the end with the higher bus base voltage is HV (winding 1 on a tie)."""
    t = raw_transformer
    kv_i, kv_j = raw_case.bus_kv(t.i), raw_case.bus_kv(t.j)
    return (t.i, t.j) if kv_i >= kv_j else (t.j, t.i)


def _winding_ratio(cw, windv, nomv, vbase):
    """Off-nominal ratio in pu of the bus base voltage (PSS/E CW = 1, 2, 3)."""
    nom = nomv if nomv > 0 else vbase
    return {1: windv, 2: windv / vbase, 3: windv * nom / vbase}[cw]


def transformer_kwargs(raw_transformer: RawTransformer, raw_case: RawCase) -> dict:
    """Keyword arguments of :class:`jaxdse.Transformer` (T model, system base, tap on HV).

    PSS/E two-winding model (system base, bus base voltages): bus I, magnetising admittance
    Ym = G + jB at bus I, ideal transformer t1 e^{j ANG1} : 1, series impedance Z, ideal
    1 : t2, bus J. Conversions:

    * ratios t1, t2 in pu of the bus base voltages from WINDV1/2 by CW (1: pu of bus base;
      2: kV, divided by the bus base kV; 3: pu of NOMV, times NOMV/bus base; NOMV = 0 means the
      bus base);
    * Z on the system base by CZ (1: as given; 2: times SBASE/SBASE1-2; 3: R1-2 is the load
      loss in W, R = P/SBASE1-2 on the winding base, X = sqrt(|Z|^2 - R^2), then times
      SBASE/SBASE1-2);
    * Ym on the system base by CM (1: G = MAG1, B = MAG2 as given; 2: MAG1 = no-load loss [W],
      MAG2 = exciting current [pu of SBASE1-2 at NOMV1]: G = P0/SBASE (V_b/V_nom)^2,
      |Y| = I0 SBASE1-2/SBASE (V_b/V_nom)^2, B = -sqrt(|Y|^2 - G^2));
    * HV side = the bus with the higher base voltage. With I on the HV side, referring the
      circuit to bus J: n = t1 e^{j ANG1}/t2, z = Z t2^2, Ym moves inside the ideal
      transformer as Ym |n|^2. With J on the HV side, referring to bus I: n = t2/(t1 e^{j ANG1}),
      z = Z t1^2, Ym stays (it is on the LV terminal);
    * z is split evenly between the HV and LV windings; the magnetising branch, at a winding
      terminal in PSS/E, sits at the T-model midpoint (a second-order change, |Ym z|/2);
    * r_Fe = 1/G and x_M = 1/|B| (PSS/E enters B < 0 for an inductive branch; the sign is
      dropped); a zero G or B becomes ``BIG_SHUNT_PU`` (an open circuit);
    * tau = |n| - 1 is kept exactly: ``tap_step`` is the winding-1 tap step
      (RMA1 - RMI1)/(NTP1 - 1) in pu of n (``DEFAULT_TAP_STEP`` without a range) and
      ``tap_position`` = tau / tap_step (fractional when the ratio is off-step);
    * ``phase_shift_rad`` = arg(n).
    """
    t, case = raw_transformer, raw_case
    src = t.source or case.source

    def bad(msg):
        return InputError(src, f"transformer {t.i}-{t.j} {t.ckt!r}: {msg}", row=t.line)

    if t.cw not in (1, 2, 3) or t.cz not in (1, 2, 3) or t.cm not in (1, 2):
        raise bad(f"unknown code CW={t.cw}, CZ={t.cz} or CM={t.cm} (CW, CZ in 1..3, CM in 1..2)")
    vb_i, vb_j = case.bus_kv(t.i), case.bus_kv(t.j)
    s_sys = case.sbase_mva
    s_w = t.sbase12_mva
    if t.cz != 1 or t.cm == 2:
        if not s_w > 0:
            raise bad(f"SBASE1-2 is {s_w} MVA with CZ={t.cz}, CM={t.cm}; it must be > 0")
    t1 = _winding_ratio(t.cw, t.windv1, t.nomv1_kv, vb_i)
    t2 = _winding_ratio(t.cw, t.windv2, t.nomv2_kv, vb_j)
    if not (t1 > 0 and t2 > 0):
        raise bad(f"winding ratios must be > 0, got t1={t1}, t2={t2}")
    # series impedance on the system base
    if t.cz == 1:
        r, x = t.r12, t.x12
    elif t.cz == 2:
        r, x = t.r12 * s_sys / s_w, t.x12 * s_sys / s_w
    else:
        r_w = t.r12 / 1e6 / s_w
        if abs(t.x12) < r_w:
            raise bad(f"CZ=3: |Z| = {t.x12} is smaller than R = {r_w} from the load loss")
        r, x = r_w * s_sys / s_w, math.copysign(math.sqrt(t.x12**2 - r_w**2), t.x12) * s_sys / s_w
    # magnetising admittance on the system base, at bus I
    if t.cm == 1:
        g_m, b_m = t.mag1, t.mag2
    else:
        v_nom = t.nomv1_kv if t.nomv1_kv > 0 else vb_i
        scale = (vb_i / v_nom) ** 2
        g_m = t.mag1 / 1e6 / s_sys * scale
        y_abs = t.mag2 * s_w / s_sys * scale
        if y_abs < g_m:
            raise bad(f"CM=2: exciting current {t.mag2} pu gives |Y| = {y_abs} < G = {g_m}")
        b_m = -math.sqrt(y_abs**2 - g_m**2)
    theta = math.radians(t.ang1_deg)
    hv_is_i = vb_i >= vb_j
    if hv_is_i:
        n_abs, phi = t1 / t2, theta
        z_scale, y_scale = t2**2, n_abs**2
        step = _tap_range_step(t, vb_i) / t2
    else:
        n_abs, phi = t2 / t1, -theta
        z_scale, y_scale = t1**2, 1.0
        step = _tap_range_step(t, vb_i) * t2 / t1**2
    if r < 0 or x < 0:
        raise bad(f"negative series impedance R={r}, X={x} cannot be a jaxdse Transformer")
    g_m, b_m = g_m * y_scale, abs(b_m) * y_scale
    tau = n_abs - 1.0
    if not step > 0:
        step = DEFAULT_TAP_STEP
    z_r, z_x = r * z_scale, x * z_scale
    return dict(r_hv_pu=0.5 * z_r, x_hv_pu=0.5 * z_x, r_lv_pu=0.5 * z_r, x_lv_pu=0.5 * z_x,
                r_fe_pu=1.0 / g_m if g_m > 0 else BIG_SHUNT_PU,
                x_m_pu=1.0 / b_m if b_m > 0 else BIG_SHUNT_PU,
                tap_step=step, tap_position=tau / step, phase_shift_rad=phi)


def _tap_range_step(t: RawTransformer, vb_i: float) -> float:
    """Winding-1 tap step in pu of the bus-I base voltage (0 when there is no range)."""
    if t.ntp1 < 2 or not t.rma1 > t.rmi1:
        return 0.0
    if abs(t.cod1) in (3, 5):   # phase-shift control: RMA1/RMI1 are angles, not ratios
        return 0.0
    step = (t.rma1 - t.rmi1) / (t.ntp1 - 1)
    return _winding_ratio(t.cw, step, t.nomv1_kv, vb_i)


def governor_from_dyr(record: DyrRecord, *, mbase_mva: float | None = None) -> AbstractGovernor:
    """The governor module of a TGOV1, IEEEG1, GAST, HYGOV or GGOV1 record.

    ``mbase_mva`` (the machine's MBASE) is used by GGOV1 when Trate > 0 (its signals are then
    on the Trate base: ``base_ratio`` = Trate/MBASE). Invalid parameters (e.g. a zero time
    constant PSS/E does not allow) raise :class:`InputError` naming the record and the CON.
    """
    try:
        return governor_module(record, mbase_mva=mbase_mva)
    except ValueError as e:
        raise record.error(str(e).removeprefix(f"{record.model}: ")) from None


def governor_module(record: DyrRecord, *, mbase_mva: float | None = None) -> AbstractGovernor:
    """:func:`governor_from_dyr` raising a plain one-line ``ValueError`` that starts with the
    model and names its CONs (``TGOV1: T1 must be > 0, got -0.05``), for a caller that labels
    the record itself."""
    model = GOVERNORS.get(record.model)
    if model is None:
        raise ValueError(f"{record.model} is not a supported governor model ({', '.join(GOVERNORS)})")
    p = record.params
    kwargs = {f: p[name] for f, name in GOVERNOR_PARAMETERS[record.model].items()}
    try:
        if record.model == "GGOV1":
            ratio = 1.0
            if p["Trate"] > 0:
                if mbase_mva is None or not mbase_mva > 0:
                    raise ValueError("Trate > 0 needs the machine's MBASE (mbase_mva=...)")
                ratio = p["Trate"] / mbase_mva
            kwargs.update(rselect=int(p["Rselect"]), flag=int(p["Flag"]), base_ratio=ratio)
        return model(**kwargs)
    except ValueError as e:  # name the CONs as the record does
        names = {**GOVERNOR_PARAMETERS[record.model], "rselect": "Rselect", "flag": "Flag",
                 "base_ratio": "Trate/MBASE"}
        raise ValueError(record_message(str(e), record.model, names)) from None


def load_unit(dyr: DyrData, raw: RawCase, bus: int, machine_id: str):
    """Convenience: (Machine kwargs, transient data, governor or None, GSU kwargs or None)
    of one generator, with the nominal frequency from the .raw BASFRQ."""
    rec = dyr.machine(bus, machine_id)
    if rec is None:
        raise InputError(dyr.source, f"no machine record for bus {bus} id {machine_id!r}")
    gen = raw.generator(bus, machine_id)
    kw = machine_kwargs(rec, gen, raw.bus_kv(bus), raw.basfrq_hz)
    gov_rec = dyr.governor(bus, machine_id)
    gov = governor_from_dyr(gov_rec, mbase_mva=gen.mbase_mva) if gov_rec is not None else None
    gsu = raw.step_up_transformer(bus)
    return kw, transient_data(rec), gov, (transformer_kwargs(gsu, raw) if gsu is not None else None)

__all__ = [
    "BIG_SHUNT_PU", "DEFAULT_TAP_STEP", "GENCLS_TD0_S", "ROUND_ROTOR", "SALIENT_POLE",
    "MachineTransientData", "generator_label",
    "governor_from_dyr", "governor_module", "load_unit", "machine_kwargs", "machine_problems",
    "machine_warnings",
    "q_axis_problems",
    "record_label", "transformer_kwargs", "transformer_sides", "transient_data",
]
