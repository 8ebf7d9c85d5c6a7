"""PSS/E excitation-system models as equinox modules, by IEEE Std 421.5 type: ``dc`` (IEEEX1,
IEEET1, IEEET2, EXDC2, ESDC1A, ESDC2A), ``st`` (EXST1, ESST1A, ESST3A, ESST4B, EXPIC1),
``simplified`` (SEXS, SCRX), ``ac`` (ESAC1A, EXAC1,
EXAC2, ESAC6A); the registry of PSS/E names and CON orders, and :func:`exciter_from_dyr`, the
one place that reads a record into a module.

Every model subclasses :class:`~jaxdse._models.base.AbstractExciter` (machine base, per unit,
seconds). Conventions shared by all of them:

* the compensated voltage EC is the terminal voltage magnitude ``vt_pu`` (no load compensation
  here); VUEL and VOEL are absent (0, or an HV gate that never wins); VOTHSG is ``vs_pu``;
* a lag ``1/(1 + sT)`` with ``T = 0`` and a lead-lag ``(1 + sTC)/(1 + sTB)`` with ``TB = 0`` are
  pass-throughs whose state is kept with zero derivative (PSS/E convention), a rate feedback
  ``sKF/(1 + sTF)`` with ``TF = 0`` gives 0; so one state layout serves every parameter set
  under vmap, with ``jnp.where`` instead of Python branching on values, and denominators of
  bypassed blocks replaced by 1 (no NaN in value or gradient);
* non-windup limits (IEEE Std 421.5-2016, Annex E) block the derivative that would push the
  state further out; downstream blocks see the state clipped to its limits;
* ``efd(state, inputs, vref)`` gets the voltage reference: ESST4B, ESST1A, EXPIC1 and SCRX,
  whose real records bypass the block that produces Efd (TA = 0, TE = 0), give Efd as an
  algebraic function of Vref through it; the others ignore it, and require that block to be
  dynamic (SEXS TE > 0, EXST1 TA > 0, DC exciters TE > 0, ESST3A TA > 0 or TM > 0, AC exciters
  TE > 0; other records are refused with a ValueError);
* ``initial_state(efd0, inputs)`` solves the steady state in closed form with VOTHSG = 0
  (the DC exciters' saturation and ESST3A's rectifier loading need no iteration: Efd is given,
  and they are explicit functions of Efd and the inputs; the AC exciters' VE follows from Efd in
  closed form, one formula per branch of FEX). The operating point is assumed to lie
  within the limits (no limit is active in the returned steady state).

Sources: Siemens PTI, *PSS(R)E Model Library* (block diagram of each model, CON tables);
IEEE Std 421.5-2005/2016 *Recommended Practice for Excitation System Models for Power System
Stability Studies* (DC1A/DC2A, AC1A, AC6A, ST1A, ST3A, the rectifier regulation function FEX of Annex D,
non-windup limits of Annex E); for the structure only, the BSD-3 implementations OpenIPSL
(``OpenIPSL.Electrical.Controls.PSSE.ES``: SEXS, IEEEX1, ESDC2A, EXST1, the PSS/E quadratic
saturation ``NonElectrical.Functions.SE`` and the PSS/E DC exciter set-up
``calculate_dc_exciter_params``, citing the PSS/E Program Application Guide vol. 2, 15.2.4) and
PowerSimulationsDynamics.jl (SEXS, EXST1); PowerWorld's exciter pages for the parameter lists.
The AC types (:mod:`.ac`) also follow the 1981 IEEE Committee Report (AC1, AC2, IEEE Trans.
PAS-100(2)) and, for the structure, OpenIPSL's ESAC1A, EXAC1 and EXAC2.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

from ..base import AbstractExciter, record_message
from .ac import ESAC1A, ESAC6A, EXAC1, EXAC2
from .common import rectifier_fex, saturation, saturation_product
from .dc import ESDC1A, ESDC2A, EXDC2, IEEET1, IEEET2, IEEEX1
from .simplified import SCRX, SEXS
from .st import ESST1A, ESST3A, ESST4B, EXPIC1, EXST1

# --- PSS/E records ----------------------------------------------------------------------------

EXCITERS: dict[str, type[AbstractExciter]] = {
    "SEXS": SEXS, "IEEEX1": IEEEX1, "EXDC2": EXDC2, "ESDC2A": ESDC2A, "EXST1": EXST1, "ESST3A": ESST3A,
    "IEEET1": IEEET1, "IEEET2": IEEET2, "ESDC1A": ESDC1A, "ESST4B": ESST4B, "ESST1A": ESST1A, "SCRX": SCRX,
    "EXPIC1": EXPIC1,
    "ESAC1A": ESAC1A, "EXAC1": EXAC1, "EXAC2": EXAC2, "ESAC6A": ESAC6A}
"""The exciter models by their PSS/E name."""

_DC_CONS = ("TR", "KA", "TA", "TB", "TC", "VRMAX", "VRMIN", "KE", "TE", "KF", "TF1", "Switch",
            "E1", "SE(E1)", "E2", "SE(E2)")
_SAT_CONS = ("E1", "SE(E1)", "E2", "SE(E2)")
_SAT_FIELDS = ("e1_pu", "se1", "e2_pu", "se2")
_DC_FIELDS = ("t_r_s", "ka", "t_a_s", "t_b_s", "t_c_s", "vr_max_pu", "vr_min_pu", "ke", "t_e_s",
              "kf", "t_f_s", "switch", "e1_pu", "se1", "e2_pu", "se2")

EXCITER_FIELDS: dict[str, tuple[str, ...]] = {
    "SEXS": ("TA/TB", "TB", "K", "TE", "EMIN", "EMAX"),
    "IEEEX1": _DC_CONS,
    "EXDC2": _DC_CONS,
    "ESDC2A": _DC_CONS,
    "EXST1": ("TR", "VIMAX", "VIMIN", "TC", "TB", "KA", "TA", "VRMAX", "VRMIN", "KC", "KF", "TF"),
    "ESST3A": ("TR", "VIMAX", "VIMIN", "KM", "TC", "TB", "KA", "TA", "VRMAX", "VRMIN", "KG", "KP",
               "KI", "VBMAX", "KC", "XL", "VGMAX", "THETAP", "TM", "VMMAX", "VMMIN"),
    "IEEET1": ("TR", "KA", "TA", "VRMAX", "VRMIN", "KE", "TE", "KF", "TF", "Switch", "E1", "SE(E1)",
               "E2", "SE(E2)"),
    "IEEET2": ("TR", "KA", "TA", "VRMAX", "VRMIN", "KE", "TE", "KF", "TF1", "TF2", *_SAT_CONS),
    "ESDC1A": _DC_CONS,
    "ESST4B": ("TR", "KPR", "KIR", "VRMAX", "VRMIN", "TA", "KPM", "KIM", "VMMAX", "VMMIN", "KG", "KP",
               "KI", "VBMAX", "KC", "XL", "THETAP"),
    "ESST1A": ("UEL", "VOS", "TR", "VIMAX", "VIMIN", "TC", "TB", "TC1", "TB1", "KA", "TA", "VAMAX",
               "VAMIN", "VRMAX", "VRMIN", "KC", "KF", "TF", "KLR", "ILR"),
    "SCRX": ("TA/TB", "TB", "K", "TE", "EMIN", "EMAX", "CSWITCH", "rc/rfd"),
    "EXPIC1": ("TR", "KA", "TA1", "VR1", "VR2", "TA2", "TA3", "TA4", "VRMAX", "VRMIN", "KF", "TF1",
               "TF2", "EFDMAX", "EFDMIN", "KE", "TE", "E1", "SE(E1)", "E2", "SE(E2)", "KP", "KI", "KC"),
    "ESAC1A": ("TR", "TB", "TC", "KA", "TA", "VAMAX", "VAMIN", "TE", "KF", "TF", "KC", "KD", "KE",
               *_SAT_CONS, "VRMAX", "VRMIN"),
    "EXAC1": ("TR", "TB", "TC", "KA", "TA", "VRMAX", "VRMIN", "TE", "KF", "TF", "KC", "KD", "KE",
              *_SAT_CONS),
    "EXAC2": ("TR", "TB", "TC", "KA", "TA", "VAMAX", "VAMIN", "KB", "VRMAX", "VRMIN", "TE", "KL",
              "KH", "KF", "TF", "KC", "KD", "KE", "VLR", *_SAT_CONS),
    "ESAC6A": ("TR", "KA", "TA", "TK", "TB", "TC", "VAMAX", "VAMIN", "VRMAX", "VRMIN", "TE",
               "VFELIM", "KH", "VHMAX", "TH", "TJ", "KC", "KD", "KE", *_SAT_CONS),
}
"""PSS/E CON names of each exciter record, in PSS/E CON order (Siemens PTI, PSS/E Model Library)."""

_ATTRIBUTES: dict[str, tuple[str, ...]] = {
    "SEXS": ("ta_tb", "t_b_s", "k", "t_e_s", "e_min_pu", "e_max_pu"),
    "IEEEX1": _DC_FIELDS,
    "EXDC2": _DC_FIELDS,
    "ESDC2A": _DC_FIELDS,
    "EXST1": ("t_r_s", "vi_max_pu", "vi_min_pu", "t_c_s", "t_b_s", "ka", "t_a_s", "vr_max_pu",
              "vr_min_pu", "kc", "kf", "t_f_s"),
    "ESST3A": ("t_r_s", "vi_max_pu", "vi_min_pu", "km", "t_c_s", "t_b_s", "ka", "t_a_s",
               "vr_max_pu", "vr_min_pu", "kg", "kp", "ki", "vb_max_pu", "kc", "xl_pu",
               "vg_max_pu", "theta_p_rad", "t_m_s", "vm_max_pu", "vm_min_pu"),
    "IEEET1": ("t_r_s", "ka", "t_a_s", "vr_max_pu", "vr_min_pu", "ke", "t_e_s", "kf", "t_f_s",
               "switch", "e1_pu", "se1", "e2_pu", "se2"),
    "IEEET2": ("t_r_s", "ka", "t_a_s", "vr_max_pu", "vr_min_pu", "ke", "t_e_s", "kf", "t_f1_s",
               "t_f2_s", *_SAT_FIELDS),
    "ESDC1A": _DC_FIELDS,
    "ESST4B": ("t_r_s", "kpr", "kir", "vr_max_pu", "vr_min_pu", "t_a_s", "kpm", "kim", "vm_max_pu",
               "vm_min_pu", "kg", "kp", "ki", "vb_max_pu", "kc", "xl_pu", "theta_p_rad"),
    "ESST1A": ("uel", "vos", "t_r_s", "vi_max_pu", "vi_min_pu", "t_c_s", "t_b_s", "t_c1_s", "t_b1_s",
               "ka", "t_a_s", "va_max_pu", "va_min_pu", "vr_max_pu", "vr_min_pu", "kc", "kf", "t_f_s",
               "klr", "ilr_pu"),
    "SCRX": ("ta_tb", "t_b_s", "k", "t_e_s", "e_min_pu", "e_max_pu", "cswitch", "rc_rfd"),
    "EXPIC1": ("t_r_s", "ka", "t_a1_s", "vr1_pu", "vr2_pu", "t_a2_s", "t_a3_s", "t_a4_s", "vr_max_pu",
               "vr_min_pu", "kf", "t_f1_s", "t_f2_s", "efd_max_pu", "efd_min_pu", "ke", "t_e_s",
               "e1_pu", "se1", "e2_pu", "se2", "kp", "ki", "kc"),
    "ESAC1A": ("t_r_s", "t_b_s", "t_c_s", "ka", "t_a_s", "va_max_pu", "va_min_pu", "t_e_s", "kf",
               "t_f_s", "kc", "kd", "ke", *_SAT_FIELDS, "vr_max_pu", "vr_min_pu"),
    "EXAC1": ("t_r_s", "t_b_s", "t_c_s", "ka", "t_a_s", "vr_max_pu", "vr_min_pu", "t_e_s", "kf",
              "t_f_s", "kc", "kd", "ke", *_SAT_FIELDS),
    "EXAC2": ("t_r_s", "t_b_s", "t_c_s", "ka", "t_a_s", "va_max_pu", "va_min_pu", "kb",
              "vr_max_pu", "vr_min_pu", "t_e_s", "kl", "kh", "kf", "t_f_s", "kc", "kd", "ke",
              "vlr_pu", *_SAT_FIELDS),
    "ESAC6A": ("t_r_s", "ka", "t_a_s", "t_k_s", "t_b_s", "t_c_s", "va_max_pu", "va_min_pu",
               "vr_max_pu", "vr_min_pu", "t_e_s", "vfe_lim_pu", "kh", "vh_max_pu", "t_h_s",
               "t_j_s", "kc", "kd", "ke", *_SAT_FIELDS),
}


def exciter_from_dyr(model: str, constants: Sequence[float], *,
                     ke_zero: Literal["psse", "literal"] = "psse") -> AbstractExciter:
    """The exciter of a PSS/E .dyr record: ``model`` (e.g. ``"ESST3A"``) and its CONs in order.

    Conversions: ESST3A and ESST4B THETAP from degrees to radians. DC exciters (IEEEX1, IEEET1,
    IEEET2, EXDC2, ESDC1A, ESDC2A): VRMAX = 0
    is PSS/E's "compute the limits" entry, VRMAX = (SE(E2) + KE)·E2 for KE > 0 and SE(E2)·E2
    otherwise, VRMIN = -VRMAX (PSS/E Program Application Guide, as OpenIPSL implements it);
    KE = 0 is kept (KE then follows from the initial EFD, see :class:`IEEEX1`). With
    ``ke_zero = "literal"`` (ANDES's reading) neither rule applies: KE = 0 is 0 and VRMAX = 0
    means no upper limit.
    Raises ``ValueError`` (one line) for an unknown model, a wrong number of constants, a
    non-finite constant or invalid values.
    """
    name = str(model).strip().upper()
    if name not in EXCITERS:
        raise ValueError(f"unknown exciter model {model!r} (known: {', '.join(EXCITERS)})")
    cons = EXCITER_FIELDS[name]
    try:
        values = [float(c) for c in constants]
    except (TypeError, ValueError) as err:
        raise ValueError(f"{name}: constants must be numbers ({err})") from None
    if len(values) != len(cons):
        raise ValueError(f"{name}: expected {len(cons)} constants ({', '.join(cons)}), "
                         f"got {len(values)}")
    bad = [c for c, v in zip(cons, values) if not math.isfinite(v)]
    if bad:
        raise ValueError(f"{name}: non-finite constant(s) {', '.join(bad)}")
    kwargs = dict(zip(_ATTRIBUTES[name], values))
    if name in ("ESST3A", "ESST4B"):
        kwargs["theta_p_rad"] = math.radians(kwargs["theta_p_rad"])
    dc = name in ("IEEEX1", "IEEET1", "IEEET2", "EXDC2", "ESDC1A", "ESDC2A")
    if dc and kwargs["vr_max_pu"] == 0.0 and ke_zero == "literal":
        kwargs["vr_max_pu"] = math.inf
    elif dc and kwargs["vr_max_pu"] == 0.0:
        ke, se2, e2 = kwargs["ke"], kwargs["se2"], kwargs["e2_pu"]
        vr_max = (se2 + ke) * e2 if ke > 0 else se2 * e2
        kwargs["vr_max_pu"], kwargs["vr_min_pu"] = vr_max, -vr_max
    if dc:
        kwargs["ke_zero"] = ke_zero
    try:
        return EXCITERS[name](**kwargs)
    except ValueError as err:  # name the CONs as the record does
        raise ValueError(record_message(str(err), name, dict(zip(_ATTRIBUTES[name], cons)))) from None


__all__ = ["ESAC1A", "ESAC6A", "ESDC1A", "ESDC2A", "ESST1A", "ESST3A", "ESST4B", "EXAC1", "EXAC2",
           "EXCITERS", "EXCITER_FIELDS", "EXDC2", "EXPIC1", "EXST1", "IEEET1", "IEEET2", "IEEEX1", "SCRX",
           "SEXS", "exciter_from_dyr", "rectifier_fex", "saturation", "saturation_product"]