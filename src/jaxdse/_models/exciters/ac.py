"""Alternator-rectifier exciters of IEEE Std 421.5 as PSS/E models: ESAC1A, EXAC1, EXAC2, ESAC6A.

Shared conventions: :mod:`jaxdse._models.exciters`. All four share the exciter alternator with
its diode rectifier (Siemens PTI *PSS/E Model Library*; IEEE Std 421.5-2005, 6.1 and Annex D):

    TE dVE/dt = VR - VFE,  VE >= 0 (non-windup lower limit on the integrator)
    VFE = KD·IFD + (KE + SE(VE))·VE          (demagnetising feedback, field resistance, saturation)
    IN  = KC·IFD/VE,  EFD = VE·FEX(IN)       (rectifier regulation, Annex D)

with SE the PSS/E quadratic saturation through (E1, SE(E1)), (E2, SE(E2))
(:func:`~jaxdse._models.exciters.common.saturation_product`) and FEX
:func:`~jaxdse._models.exciters.common.rectifier_fex`. IFD is LadIfd (machine base, non-reciprocal).
VE = 0 gives EFD = 0. TE must be > 0 (the exciter produces EFD). In steady state the inverse
of EFD = VE·FEX(KC·IFD/VE) is closed form (VE·FEX is increasing in VE; one formula per branch
of FEX, the branch picked as the forward function picks it): :meth:`_ACExciter.ve_from_efd`.

Units: per unit on the machine base, seconds.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._base.blocks import blocked, lag, lead_lag, nonwindup_lag, safe, washout
from ..._base.fields import all_concrete, as_float, check_nonnegative, check_positive, check_that
from ..base import AbstractExciter, ExciterInputs
from .common import rectifier_fex, saturation_product

_VE = 3
"""Index of the exciter alternator voltage VE in every AC exciter's state."""


# --- the exciter alternator and its rectifier ----------------------------------------------------

class _ACExciter(AbstractExciter):
    """Common part of the AC exciters: the alternator VE, its feedback VFE, the rectifier.

    Subclasses give the regulator: ``_signals(state, inputs, vref)`` returns the derivatives of
    every state but VE, VR (the exciter field voltage after its limits) and VFE.
    """

    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.8)
    """TE: exciter (alternator field) time constant [s] (> 0)."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """KC: rectifier loading factor proportional to the commutating reactance [pu]."""
    kd: Float[Array, ""] = eqx.field(converter=as_float, default=0.38)
    """KD: demagnetising factor, a function of the exciter alternator reactances [pu]."""
    ke: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KE: exciter field resistance constant [pu] (used as it stands, also when 0)."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=4.18)
    """E1: first exciter voltage VE at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=3.14)
    """E2: second exciter voltage VE at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.03)
    """SE(E2): saturation factor at E2 [-]."""

    def __check_init__(self):  # equinox runs every class's __check_init__
        check_positive(self, "t_e_s")
        check_nonnegative(self, "t_r_s", "kc", "kd", "e1_pu", "se1", "e2_pu", "se2")

    @property
    def n_states(self) -> int:
        return 5

    # -- the alternator and rectifier --
    def vfe(self, ve, ifd):
        """VFE = KD·IFD + KE·VE + SE(VE)·VE [pu]: the exciter field current signal."""
        return self.kd * ifd + self.ke * ve + saturation_product(ve, self.e1_pu, self.se1,
                                                                 self.e2_pu, self.se2)

    def rectified(self, ve, ifd):
        """EFD = VE·FEX(KC·IFD/VE) [pu] (0 for VE <= 0)."""
        on = ve > 0
        i_n = self.kc * ifd / jnp.where(on, ve, 1.0)
        return jnp.where(on, ve * rectifier_fex(i_n), 0.0)

    def ve_from_efd(self, efd, ifd):
        """VE [pu] with VE·FEX(KC·IFD/VE) = EFD: the inverse of :meth:`rectified` for EFD >= 0.

        With a = KC·IFD: IN <= 0 gives VE = EFD; FEX = 1 - 0.577 IN gives VE = EFD + 0.577 a;
        FEX = sqrt(0.75 - IN^2) gives VE = sqrt((EFD^2 + a^2)/0.75); FEX = 1.732 (1 - IN) gives
        VE = EFD/1.732 + a. The first candidate whose IN lies in its own branch (tested as the
        forward function tests it) is the root: VE·FEX(a/VE) increases with VE.
        """
        efd = jnp.asarray(efd, float)
        a = self.kc * ifd
        pos = a > 0
        ve1 = efd + 0.577 * a
        ve2 = jnp.sqrt(jnp.where(pos, (efd * efd + a * a) / 0.75, 1.0))
        ve3 = efd / 1.732 + a
        in1 = a / jnp.where(ve1 > 0, ve1, 1.0)
        in2 = a / ve2
        return jnp.where(~pos, efd, jnp.where(in1 <= 0.433, ve1, jnp.where(in2 < 0.75, ve2, ve3)))

    def _exciter(self, x_ve, vr, ifd):
        """(VE clipped at 0, VFE, dVE/dt with the non-windup floor at 0)."""
        ve = jnp.maximum(x_ve, 0.0)
        vfe = self.vfe(ve, ifd)
        return ve, vfe, blocked(x_ve, (vr - vfe) / self.t_e_s, 0.0, jnp.inf)

    def _steady_exciter(self, efd0, inputs: ExciterInputs):
        """(VE0, VFE0): the alternator in steady state at EFD0 (VR0 = VFE0)."""
        ve0 = self.ve_from_efd(efd0, inputs.ifd_pu)
        return ve0, self.vfe(ve0, inputs.ifd_pu)

    # -- the regulator (model-specific) --
    def _signals(self, state, inputs: ExciterInputs, vref, vfe):
        """(derivatives of states 0, 1, 2, 4; VR) given VFE."""
        raise NotImplementedError

    def vr_vfe(self, state, inputs: ExciterInputs, vref):
        """(VR, VFE) [pu]: the exciter field voltage after the regulator's limits, and VFE."""
        ve = jnp.maximum(state[_VE], 0.0)
        vfe = self.vfe(ve, inputs.ifd_pu)
        _, vr = self._signals(state, inputs, vref, vfe)
        return vr, vfe

    def vector_field(self, state, inputs: ExciterInputs, vref):
        ve = jnp.maximum(state[_VE], 0.0)
        vfe = self.vfe(ve, inputs.ifd_pu)
        (d0, d1, d2, d4), vr = self._signals(state, inputs, vref, vfe)
        _, _, d_e = self._exciter(state[_VE], vr, inputs.ifd_pu)
        return jnp.stack([d0, d1, d2, d_e, d4])

    def efd(self, state, inputs: ExciterInputs, vref):
        return self.rectified(jnp.maximum(state[_VE], 0.0), inputs.ifd_pu)


# --- ESAC1A, EXAC1 ----------------------------------------------------------------------------

class _AC1(_ACExciter):
    """Common part of ESAC1A and EXAC1 (the type AC1 regulator; the limits are the subclasses')."""

    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TC: lead time constant of the lead-lag [s]."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=400.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TA: voltage regulator time constant [s] (0: gain KA, limited)."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.03)
    """KF: rate feedback gain [pu/pu]."""
    t_f_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TF: rate feedback time constant [s] (0: no rate feedback)."""

    def __check_init__(self):
        check_positive(self, "ka")
        check_nonnegative(self, "t_b_s", "t_c_s", "t_a_s", "kf", "t_f_s")

    def _regulator(self, y, x):
        """(VR, d(state 2)/dt) from the lead-lag output y."""
        raise NotImplementedError

    def _signals(self, state, inputs: ExciterInputs, vref, vfe):
        vc, d_c = lag(inputs.vt_pu, state[0], self.t_r_s)
        d_fb, d_f = washout(vfe, state[4], self.t_f_s)
        u = vref + inputs.vs_pu - vc - self.kf * d_fb
        y, d_ll = lead_lag(u, state[1], self.t_c_s, self.t_b_s)
        vr, d_a = self._regulator(y, state[2])
        return (d_c, d_ll, d_a, d_f), vr

    def initial_state(self, efd0, inputs: ExciterInputs):
        vt = jnp.asarray(inputs.vt_pu, float)
        ve0, vfe0 = self._steady_exciter(efd0, inputs)
        u0 = vfe0 / self.ka  # VA0 = VR0 = VFE0 (no limit active), VF0 = 0
        return jnp.stack([vt, u0, vfe0, ve0, vfe0]), vt + u0


class ESAC1A(_AC1):
    """PSS/E ESAC1A: the IEEE Std 421.5-2005 type AC1A alternator-rectifier exciter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "ESAC1A"; IEEE Std 421.5-2005, 6.1,
    Fig. 6-1; OpenIPSL ``ESAC1A`` for the structure), without UEL/OEL (their HV and LV gates
    pass the regulator):

        VC  = EC/(1 + s TR)
        VF  = s KF/(1 + s TF) VFE                                    (rate feedback)
        u   = Vref + VOTHSG - VC - VF
        VA  = KA/(1 + s TA) (1 + s TC)/(1 + s TB) u, non-windup limits [VAMIN, VAMAX]
        VR  = clip(VA, VRMIN, VRMAX)
        TE dVE/dt = VR - VFE, VE >= 0;  VFE, EFD: see :mod:`jaxdse._models.exciters.ac`

    States: [VC, lead-lag state, VA, VE, rate-feedback state]. PSS/E CON order: TR, TB, TC, KA,
    TA, VAMAX, VAMIN, TE, KF, TF, KC, KD, KE, E1, SE(E1), E2, SE(E2), VRMAX, VRMIN. Unlike ANDES
    2.0, the rate feedback VF is fed back and the VR limits apply.
    """

    va_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=14.5)
    """VAMAX: upper limit of the regulator output VA [pu]."""
    va_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-14.5)
    """VAMIN: lower limit of the regulator output VA [pu]."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=6.03)
    """VRMAX: upper limit of the exciter field voltage VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-5.43)
    """VRMIN: lower limit of the exciter field voltage VR [pu]."""

    def __check_init__(self):
        if all_concrete(self.va_max_pu, self.va_min_pu, self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.va_max_pu >= self.va_min_pu,
                       f"VAMAX ({self.va_max_pu}) must be >= VAMIN ({self.va_min_pu})")
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    def _regulator(self, y, x):
        va, d_a = nonwindup_lag(y, x, self.t_a_s, self.va_min_pu, self.va_max_pu, gain=self.ka)
        return jnp.clip(va, self.vr_min_pu, self.vr_max_pu), d_a


class EXAC1(_AC1):
    """PSS/E EXAC1: the 1981 IEEE type AC1 alternator-rectifier exciter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "EXAC1"; IEEE Committee Report,
    "Excitation system models for power system stability studies", IEEE Trans. PAS-100(2),
    1981, type AC1; OpenIPSL ``EXAC1`` for the structure): as :class:`ESAC1A` with one limit
    on the regulator, VR = KA/(1 + s TA) (1 + s TC)/(1 + s TB) u with non-windup limits
    [VRMIN, VRMAX] (no VA limits). VE >= 0 (non-windup), rate feedback from VFE.

    States: [VC, lead-lag state, VR, VE, rate-feedback state]. PSS/E CON order: TR, TB, TC, KA,
    TA, VRMAX, VRMIN, TE, KF, TF, KC, KD, KE, E1, SE(E1), E2, SE(E2). The sensor lag TR is
    simulated (ANDES 2.0 skips it).
    """

    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=7.3)
    """VRMAX: upper limit of the regulator output VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-6.6)
    """VRMIN: lower limit of the regulator output VR [pu]."""

    def __check_init__(self):
        if all_concrete(self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    def _regulator(self, y, x):
        return nonwindup_lag(y, x, self.t_a_s, self.vr_min_pu, self.vr_max_pu, gain=self.ka)


# --- EXAC2 ------------------------------------------------------------------------------------

class EXAC2(_ACExciter):
    """PSS/E EXAC2: the 1981 IEEE type AC2 high-initial-response alternator-rectifier exciter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "EXAC2"; IEEE Trans. PAS-100(2), 1981,
    type AC2; OpenIPSL ``EXAC2`` for the structure):

        VC  = EC/(1 + s TR)
        VF  = s KF/(1 + s TF) VFE                                    (rate feedback)
        u   = Vref + VOTHSG - VC - VF
        VA  = KA/(1 + s TA) (1 + s TC)/(1 + s TB) u, non-windup limits [VAMIN, VAMAX]
        VH  = KH·VFE                                                (field current feedback)
        VL  = KL·(VLR - VFE)                                        (field current limiter)
        VR  = clip(KB·min(VA - VH, VL), VRMIN, VRMAX)               (LV gate, then KB)
        TE dVE/dt = VR - VFE, VE >= 0;  VFE, EFD: see :mod:`jaxdse._models.exciters.ac`

    States: [VC, lead-lag state, VA, VE, rate-feedback state]. PSS/E CON order: TR, TB, TC, KA,
    TA, VAMAX, VAMIN, KB, VRMAX, VRMIN, TE, KL, KH, KF, TF, KC, KD, KE, VLR, E1, SE(E1), E2,
    SE(E2). The initial state assumes the LV gate passes VA - VH: VA0 = VFE0/KB + KH·VFE0 (KH,
    not KL as ANDES 2.0 has it); TR is simulated.
    """

    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TC: lead time constant of the lead-lag [s]."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=400.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """TA: voltage regulator time constant [s] (0: gain KA, limited)."""
    va_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=8.0)
    """VAMAX: upper limit of the regulator output VA [pu]."""
    va_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-8.0)
    """VAMIN: lower limit of the regulator output VA [pu]."""
    kb: Float[Array, ""] = eqx.field(converter=as_float, default=25.0)
    """KB: second stage regulator gain [pu/pu] (> 0)."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=105.0)
    """VRMAX: upper limit of the exciter field voltage VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-95.0)
    """VRMIN: lower limit of the exciter field voltage VR [pu]."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.6)
    """TE: exciter (alternator field) time constant [s] (> 0)."""
    kl: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KL: gain of the exciter field current limiter [pu/pu]."""
    kh: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KH: exciter field current feedback gain [pu/pu]."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.03)
    """KF: rate feedback gain [pu/pu]."""
    t_f_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TF: rate feedback time constant [s] (0: no rate feedback)."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.28)
    """KC: rectifier loading factor proportional to the commutating reactance [pu]."""
    kd: Float[Array, ""] = eqx.field(converter=as_float, default=0.35)
    """KD: demagnetising factor, a function of the exciter alternator reactances [pu]."""
    vlr_pu: Float[Array, ""] = eqx.field(converter=as_float, default=4.4)
    """VLR: exciter field current limit reference, on the VFE scale [pu]."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=4.4)
    """E1: first exciter voltage VE at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.037)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=3.3)
    """E2: second exciter voltage VE at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.012)
    """SE(E2): saturation factor at E2 [-]."""

    def __check_init__(self):
        check_positive(self, "ka", "kb")
        check_nonnegative(self, "t_b_s", "t_c_s", "t_a_s", "kf", "t_f_s", "kl", "kh")
        if all_concrete(self.va_max_pu, self.va_min_pu, self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.va_max_pu >= self.va_min_pu,
                       f"VAMAX ({self.va_max_pu}) must be >= VAMIN ({self.va_min_pu})")
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    def _signals(self, state, inputs: ExciterInputs, vref, vfe):
        vc, d_c = lag(inputs.vt_pu, state[0], self.t_r_s)
        d_fb, d_f = washout(vfe, state[4], self.t_f_s)
        u = vref + inputs.vs_pu - vc - self.kf * d_fb
        y, d_ll = lead_lag(u, state[1], self.t_c_s, self.t_b_s)
        va, d_a = nonwindup_lag(y, state[2], self.t_a_s, self.va_min_pu, self.va_max_pu,
                                gain=self.ka)
        gate = jnp.minimum(va - self.kh * vfe, self.kl * (self.vlr_pu - vfe))
        vr = jnp.clip(self.kb * gate, self.vr_min_pu, self.vr_max_pu)
        return (d_c, d_ll, d_a, d_f), vr

    def initial_state(self, efd0, inputs: ExciterInputs):
        vt = jnp.asarray(inputs.vt_pu, float)
        ve0, vfe0 = self._steady_exciter(efd0, inputs)
        va0 = vfe0 / self.kb + self.kh * vfe0
        u0 = va0 / self.ka
        return jnp.stack([vt, u0, va0, ve0, vfe0]), vt + u0


# --- ESAC6A -----------------------------------------------------------------------------------

class ESAC6A(_ACExciter):
    """PSS/E ESAC6A: the IEEE Std 421.5-2005 type AC6A alternator-rectifier exciter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "ESAC6A"; IEEE Std 421.5-2005, 6.6,
    Fig. 6-6), without UEL:

        VC  = EC/(1 + s TR)
        u   = Vref + VOTHSG - VC
        VA  = KA (1 + s TK)/(1 + s TA) u, limits [VAMIN, VAMAX]
        y   = (1 + s TC)/(1 + s TB) VA
        VH  = clip(KH (1 + s TJ)/(1 + s TH) (VFE - VFELIM), 0, VHMAX)  (field current limiter)
        VR  = clip(y - VH, VT·VRMIN, VT·VRMAX)                          (supplied from VT)
        TE dVE/dt = VR - VFE, VE >= 0;  VFE, EFD: see :mod:`jaxdse._models.exciters.ac`

    States: [VC, VA lag state, lead-lag state, VE, VH lead-lag state]. No rate feedback. The
    VA limits are non-windup on the lag state x of KA u (x is held at the limit it reaches;
    the output x + TK/TA (KA u - x) is clipped), which is 421.5 Annex E's non-windup lag for
    TK = 0; TA = 0 makes VA the gain KA, limited (TK is then unused). The VH and VR limits are
    static (they clip an output). PSS/E CON order: TR, KA, TA, TK, TB, TC, VAMAX, VAMIN, VRMAX,
    VRMIN, TE, VFELIM, KH, VHMAX, TH, TJ, KC, KD, KE, E1, SE(E1), E2, SE(E2).
    """

    ka: Float[Array, ""] = eqx.field(converter=as_float, default=536.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.086)
    """TA: voltage regulator lag time constant [s] (0: gain KA, limited)."""
    t_k_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.18)
    """TK: voltage regulator lead time constant [s]."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=9.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """TC: lead time constant of the lead-lag [s]."""
    va_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=75.0)
    """VAMAX: upper limit of the regulator output VA [pu]."""
    va_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-75.0)
    """VAMIN: lower limit of the regulator output VA [pu]."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=44.0)
    """VRMAX: upper limit of VR per unit of terminal voltage [pu/pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-36.0)
    """VRMIN: lower limit of VR per unit of terminal voltage [pu/pu]."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TE: exciter (alternator field) time constant [s] (> 0)."""
    vfe_lim_pu: Float[Array, ""] = eqx.field(converter=as_float, default=19.0)
    """VFELIM: exciter field current limit reference, on the VFE scale [pu]."""
    kh: Float[Array, ""] = eqx.field(converter=as_float, default=92.0)
    """KH: exciter field current limiter gain [pu/pu]."""
    vh_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=75.0)
    """VHMAX: upper limit of the limiter output VH [pu] (the lower limit is 0)."""
    t_h_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.08)
    """TH: lag time constant of the field current limiter [s] (0: pass-through)."""
    t_j_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TJ: lead time constant of the field current limiter [s]."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.173)
    """KC: rectifier loading factor proportional to the commutating reactance [pu]."""
    kd: Float[Array, ""] = eqx.field(converter=as_float, default=1.91)
    """KD: demagnetising factor, a function of the exciter alternator reactances [pu]."""
    ke: Float[Array, ""] = eqx.field(converter=as_float, default=1.6)
    """KE: exciter field resistance constant [pu] (used as it stands, also when 0)."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=7.4)
    """E1: first exciter voltage VE at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.214)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=5.55)
    """E2: second exciter voltage VE at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.044)
    """SE(E2): saturation factor at E2 [-]."""

    def __check_init__(self):
        check_positive(self, "ka")
        check_nonnegative(self, "t_a_s", "t_k_s", "t_b_s", "t_c_s", "kh", "vh_max_pu", "t_h_s",
                          "t_j_s")
        if all_concrete(self.va_max_pu, self.va_min_pu, self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.va_max_pu >= self.va_min_pu,
                       f"VAMAX ({self.va_max_pu}) must be >= VAMIN ({self.va_min_pu})")
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    def _va(self, u, x):
        """KA (1 + s TK)/(1 + s TA) u with limits [VAMIN, VAMAX]: (VA, dx/dt)."""
        on = self.t_a_s > 0
        ts = safe(self.t_a_s)
        target = self.ka * u
        out = jnp.where(on, x + (self.t_k_s / ts) * (target - x), target)
        dx = jnp.where(on, blocked(x, (target - x) / ts, self.va_min_pu, self.va_max_pu), 0.0)
        return jnp.clip(out, self.va_min_pu, self.va_max_pu), dx

    def _vh(self, vfe, x):
        """VH = clip(KH (1 + s TJ)/(1 + s TH) (VFE - VFELIM), 0, VHMAX): (VH, dx/dt)."""
        h, d_h = lead_lag(vfe - self.vfe_lim_pu, x, self.t_j_s, self.t_h_s)
        return jnp.clip(self.kh * h, 0.0, self.vh_max_pu), d_h

    def _signals(self, state, inputs: ExciterInputs, vref, vfe):
        vc, d_c = lag(inputs.vt_pu, state[0], self.t_r_s)
        va, d_a = self._va(vref + inputs.vs_pu - vc, state[1])
        y, d_ll = lead_lag(va, state[2], self.t_c_s, self.t_b_s)
        vh, d_h = self._vh(vfe, state[4])
        vr = jnp.clip(y - vh, inputs.vt_pu * self.vr_min_pu, inputs.vt_pu * self.vr_max_pu)
        return (d_c, d_a, d_ll, d_h), vr

    def initial_state(self, efd0, inputs: ExciterInputs):
        vt = jnp.asarray(inputs.vt_pu, float)
        ve0, vfe0 = self._steady_exciter(efd0, inputs)
        h0 = vfe0 - self.vfe_lim_pu
        va0 = vfe0 + jnp.clip(self.kh * h0, 0.0, self.vh_max_pu)  # VR0 = VFE0 = y0 - VH0
        u0 = va0 / self.ka
        return jnp.stack([vt, va0, va0, ve0, h0]), vt + u0


__all__ = ["ESAC1A", "ESAC6A", "EXAC1", "EXAC2"]
