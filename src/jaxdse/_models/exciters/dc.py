"""DC-commutator exciters of IEEE Std 421.5 (DC1A, DC2A) and the 1968 IEEE type 1 as PSS/E models:
IEEEX1, IEEET1, EXDC2, ESDC1A, ESDC2A (shared conventions: :mod:`jaxdse._models.exciters`)."""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._base.blocks import blocked, lag, lead_lag, nonwindup_lag, safe, washout
from ..._base.fields import all_concrete, as_float, check_nonnegative, check_positive, check_that
from ..base import AbstractExciter, ExciterInputs
from .common import nonzero as _nonzero
from .common import saturation_product

# --- DC exciters: IEEEX1, EXDC2, ESDC2A -------------------------------------------------------

class _DCExciter(AbstractExciter):
    """Common part of the PSS/E DC commutator exciters IEEEX1, EXDC2 and ESDC2A.

        VM  = EC/(1 + s TR)
        u   = Vref + VOTHSG - VM - VF
        y   = (1 + s TC)/(1 + s TB) u
        VR  = KA/(1 + s TA) y, non-windup limits [VRMIN, VRMAX] (times EC for EXDC2, ESDC2A)
        TE dEFD/dt = VR - (KE + SE(EFD)) EFD                        (exciter)
        VF  = s KF/(1 + s TF1) EFD                                  (rate feedback)

    States: [VM, lead-lag state, VR, EFD, rate-feedback state, KE]. The last one is constant:
    it holds the KE in use. KE = 0 in the data is PSS/E's self-excited-exciter convention
    (``ke_zero = "psse"``): KE is then computed at initialisation so that VR = VRMAX/10 in the
    initial steady state, KE = VRMAX/(10 EFD0) - SE(EFD0) (PSS/E Program Application Guide
    vol. 2, 15.2.4, as implemented by OpenIPSL ``calculate_dc_exciter_params``). With
    ``ke_zero = "literal"`` KE = 0 is used as it stands, and a VRMAX of 0 in the record means
    no upper limit (:func:`exciter_from_dyr`): ANDES 2.0 reads its own .dyr so (on the bench's
    wecc units with KE = VRMAX = 0, the PSS/E rules give up to 0.52 % RMS error in Q against
    ANDES, the literal reading 0.0003-0.018 %).
    """

    ke_zero: Literal["psse", "literal"] = eqx.field(static=True, default="psse", kw_only=True)
    """How KE = 0 is read: PSS/E's self-excited rule, or literally."""

    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=40.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.04)
    """TA: voltage regulator time constant [s] (0: gain KA, limited)."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TC: lead time constant of the lead-lag [s]."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=7.3)
    """VRMAX: upper limit of the regulator output VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-7.3)
    """VRMIN: lower limit of the regulator output VR [pu]."""
    ke: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KE: exciter field constant [pu] (0: computed at initialisation, see the class notes)."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.8)
    """TE: exciter time constant [s] (> 0)."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.03)
    """KF: rate feedback gain [pu/pu]."""
    t_f_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TF1: rate feedback time constant [s] (0: no rate feedback)."""
    switch: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Switch: unused by PSS/E, kept for the record [-]."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=2.4)
    """E1: first exciter voltage at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.03)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """E2: second exciter voltage at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """SE(E2): saturation factor at E2 [-]."""

    def __check_init__(self):
        check_positive(self, "ka", "t_e_s")
        check_nonnegative(self, "t_r_s", "t_a_s", "t_b_s", "t_c_s", "kf", "t_f_s",
                          "e1_pu", "se1", "e2_pu", "se2")
        if all_concrete(self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                   f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    @property
    def n_states(self) -> int:
        return 6

    # -- model-specific pieces --
    def _vr_limits(self, inputs: ExciterInputs):
        return self.vr_min_pu, self.vr_max_pu

    def _efd_out(self, x_efd):
        return x_efd

    def _d_efd(self, x_efd, d):
        return d

    # -- common --
    def _vx(self, efd):
        return saturation_product(efd, self.e1_pu, self.se1, self.e2_pu, self.se2)

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        vx0 = self._vx(efd0)
        ke_auto = self.vr_max_pu / (10.0 * _nonzero(efd0)) - vx0 / _nonzero(efd0)
        ke = self.ke if self.ke_zero == "literal" else jnp.where(self.ke != 0, self.ke, ke_auto)
        vr0 = ke * efd0 + vx0
        u0 = vr0 / self.ka
        return jnp.stack([vt, u0, vr0, efd0, efd0, ke]), vt + u0

    def vector_field(self, state, inputs: ExciterInputs, vref):
        vm, d_m = lag(inputs.vt_pu, state[0], self.t_r_s)
        efd = self._efd_out(state[3])
        d_fb, d_f = washout(efd, state[4], self.t_f_s)
        u = vref + inputs.vs_pu - vm - self.kf * d_fb
        y, d_ll = lead_lag(u, state[1], self.t_c_s, self.t_b_s)
        lo, hi = self._vr_limits(inputs)
        vr, d_r = nonwindup_lag(y, state[2], self.t_a_s, lo, hi, gain=self.ka)
        d_e = self._d_efd(state[3], (vr - state[5] * efd - self._vx(efd)) / self.t_e_s)
        return jnp.stack([d_m, d_ll, d_r, d_e, d_f, jnp.zeros_like(d_e)])

    def efd(self, state, inputs: ExciterInputs, vref):
        return self._efd_out(state[3])


class IEEEX1(_DCExciter):
    """PSS/E IEEEX1: the 1979 IEEE Type 1 excitation system and the 1981 IEEE Type DC1.

    Block diagram (Siemens PTI *PSS/E Model Library*, "IEEEX1"; IEEE Std 421.5-2005 type
    DC1A, without UEL/OEL; OpenIPSL ``IEEEX1``): see :class:`_DCExciter` -- regulator
    limits [VRMIN, VRMAX] (non-windup), no limit on EFD. The PSS/E quadratic saturation
    (:func:`saturation_product`) and the KE = 0 rule apply.
    """


class EXDC2(_DCExciter):
    """PSS/E EXDC2: the 1981 IEEE type DC2 excitation system.

    Block diagram (Siemens PTI *PSS/E Model Library*, "EXDC2"; IEEE Committee Report,
    "Excitation system models for power system stability studies", IEEE Trans. PAS-100(2),
    1981, type DC2): as :class:`IEEEX1` (see :class:`_DCExciter`, the same 16 CONs) with the
    regulator supplied from the terminal, so its limits scale with the terminal voltage,
    [EC·VRMIN, EC·VRMAX] (non-windup). No limit on EFD (the floor at 0 is ESDC2A's). The
    PSS/E quadratic saturation and the KE = 0 rule apply.
    """

    def _vr_limits(self, inputs: ExciterInputs):
        return inputs.vt_pu * self.vr_min_pu, inputs.vt_pu * self.vr_max_pu


class ESDC2A(_DCExciter):
    """PSS/E ESDC2A: the IEEE Std 421.5-2005 type DC2A excitation system.

    Block diagram (Siemens PTI *PSS/E Model Library*, "ESDC2A"; IEEE Std 421.5-2005 type DC2A;
    OpenIPSL ``ESDC2A``): as :class:`IEEEX1` (see :class:`_DCExciter`) with the regulator
    limits scaled by the terminal voltage, [EC·VRMIN, EC·VRMAX] (non-windup), and EFD held
    at or above 0 (non-windup lower limit on the exciter integrator, as OpenIPSL's PSS/E
    ESDC2A; IEEE 421.5-2005 is ambiguous there). VUEL enters through an HV gate and is
    absent here (the gate passes the regulator path).
    """

    ka: Float[Array, ""] = eqx.field(converter=as_float, default=300.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """TA: voltage regulator time constant [s] (0: gain KA, limited)."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=4.95)
    """VRMAX: upper limit of VR per unit of terminal voltage [pu/pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-4.9)
    """VRMIN: lower limit of VR per unit of terminal voltage [pu/pu]."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.33)
    """TE: exciter time constant [s] (> 0)."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """KF: rate feedback gain [pu/pu]."""
    t_f_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.675)
    """TF1: rate feedback time constant [s] (0: no rate feedback)."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=3.05)
    """E1: first exciter voltage at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.279)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=2.29)
    """E2: second exciter voltage at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.117)
    """SE(E2): saturation factor at E2 [-]."""

    def _vr_limits(self, inputs: ExciterInputs):
        return inputs.vt_pu * self.vr_min_pu, inputs.vt_pu * self.vr_max_pu

    def _efd_out(self, x_efd):
        return jnp.maximum(x_efd, 0.0)

    def _d_efd(self, x_efd, d):
        return blocked(x_efd, d, 0.0, jnp.inf)


class IEEET1(_DCExciter):
    """PSS/E IEEET1: the 1968 IEEE Type 1 excitation system (DC commutator exciter).

    Block diagram (Siemens PTI *PSS/E Model Library*, "IEEET1"; IEEE Committee Report,
    "Computer representation of excitation systems", IEEE Trans. PAS-87(6), 1968, type 1;
    OpenIPSL ``IEEET1`` for the structure): :class:`_DCExciter` without the lead-lag,

        VM  = EC/(1 + s TR)
        VR  = KA/(1 + s TA) (Vref + VOTHSG - VM - VF), non-windup limits [VRMIN, VRMAX]
        TE dEFD/dt = VR - (KE + SE(EFD)) EFD,   VF = s KF/(1 + s TF) EFD

    14 CONs: TR, KA, TA, VRMAX, VRMIN, KE, TE, KF, TF, Switch, E1, SE(E1), E2, SE(E2) (units
    as :class:`_DCExciter`; Switch is not used by PSS/E and kept for the record). No limit on
    EFD. The PSS/E quadratic saturation, the KE = 0 rule (VR = VRMAX/10 at initialisation) and
    the VRMAX = 0 rule of :func:`~jaxdse._models.exciters.exciter_from_dyr` apply. ``t_b_s``
    and ``t_c_s`` exist only to share the DC layout: they must be 0.
    """

    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Not part of IEEET1 (no lead-lag): must be 0 [s]."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Not part of IEEET1 (no lead-lag): must be 0 [s]."""

    def __check_init__(self):
        if all_concrete(self.t_b_s, self.t_c_s):
            check_that(self, (self.t_b_s == 0) & (self.t_c_s == 0),
                       "IEEET1 has no lead-lag (t_b_s = t_c_s = 0)")


class ESDC1A(_DCExciter):
    """PSS/E ESDC1A: the IEEE Std 421.5-2005 type DC1A excitation system.

    Block diagram (Siemens PTI *PSS/E Model Library*, "ESDC1A", citing IEEE Std 421.5-2005
    type DC1A; OpenIPSL ``ESDC1A`` for the structure): :class:`_DCExciter` -- sensor lag TR,
    lead-lag (1 + s TC)/(1 + s TB), regulator KA/(1 + s TA) with non-windup limits
    [VRMIN, VRMAX] (not scaled by the terminal voltage, unlike ESDC2A), exciter
    TE dEFD/dt = VR - (KE + SE(EFD)) EFD with EFD held at or above 0 (non-windup lower limit
    on the exciter integrator, as OpenIPSL's PSS/E ESDC1A and :class:`ESDC2A`), rate feedback
    s KF/(1 + s TF1) from EFD. VUEL enters through an HV gate and is absent here.

    16 CONs, the order of :class:`IEEEX1`: TR, KA, TA, TB, TC, VRMAX, VRMIN, KE, TE, KF, TF1,
    Switch, E1, SE(E1), E2, SE(E2). The PSS/E quadratic saturation, the KE = 0 rule and the
    VRMAX = 0 rule apply (PSS/E's, not ANDES 2.0's: ANDES skips TR, keeps VR at 0 and reads
    KE = 0 literally).
    """

    ka: Float[Array, ""] = eqx.field(converter=as_float, default=400.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TA: voltage regulator time constant [s] (0: gain KA, limited)."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=9.0)
    """VRMAX: upper limit of the regulator output VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-5.43)
    """VRMIN: lower limit of the regulator output VR [pu]."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=5.25)
    """E1: first exciter voltage at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.03)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=7.0)
    """E2: second exciter voltage at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """SE(E2): saturation factor at E2 [-]."""

    def _efd_out(self, x_efd):
        return jnp.maximum(x_efd, 0.0)

    def _d_efd(self, x_efd, d):
        return blocked(x_efd, d, 0.0, jnp.inf)


class IEEET2(AbstractExciter):
    """PSS/E IEEET2: the 1968 IEEE Type 2 excitation system (rate feedback from the regulator).

    Block diagram (Siemens PTI *PSS/E Model Library*, "IEEET2"; IEEE Committee Report,
    "Computer representation of excitation systems", IEEE Trans. PAS-87(6), 1968, type 2;
    OpenIPSL ``IEEET2`` for the structure)::

        VM  = EC/(1 + s TR)
        VR  = KA/(1 + s TA) (Vref + VOTHSG - VM - VF), non-windup limits [VRMIN, VRMAX]
        TE dEFD/dt = VR - (KE + SE(EFD)) EFD
        VF  = s KF/((1 + s TF1)(1 + s TF2)) VR          (from VR, not from EFD as in IEEET1)

    14 CONs: TR, KA, TA, VRMAX, VRMIN, KE, TE, KF, TF1, TF2, E1, SE(E1), E2, SE(E2). No limit
    on EFD. The PSS/E quadratic saturation (:func:`saturation_product`), the KE = 0 rule
    (``ke_zero``, as :class:`IEEEX1`) and the VRMAX = 0 rule of
    :func:`~jaxdse._models.exciters.exciter_from_dyr` apply, as to the other DC exciters.

    Zero time constants: TR = 0 and TA = 0 bypass their lags (TA = 0: VR = clip(KA u)); the
    rate feedback needs TF1 > 0 or TF2 > 0 (both 0: no feedback); with one of them 0 it is the
    filtered derivative s KF/(1 + s T) of VR with the other one, and with TA = 0 its loop
    through the regulator is algebraic, solved exactly (VR = clip(KA (c - vf0)/(1 + KA KF/T))).

    States: [VM, TF1 filter, VR, EFD, TF2 filter, KE] (VR, EFD and KE where the other DC
    exciters hold them). At rest: VR0 = (KE + SE(EFD0)) EFD0, both filters at rest (the TF1
    filter at VR0, the TF2 filter at 0, or at VR0 when TF1 = 0), Vref = EC + VR0/KA.
    """

    ke_zero: Literal["psse", "literal"] = eqx.field(static=True, default="psse", kw_only=True)
    """How KE = 0 is read: PSS/E's self-excited rule, or literally."""

    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=200.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TA: voltage regulator time constant [s] (0: gain KA, limited)."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=6.0)
    """VRMAX: upper limit of the regulator output VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-6.0)
    """VRMIN: lower limit of the regulator output VR [pu]."""
    ke: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KE: exciter field constant [pu] (0: computed at initialisation, see :class:`IEEEX1`)."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """TE: exciter time constant [s] (> 0)."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """KF: rate feedback gain [pu/pu]."""
    t_f1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """TF1: first rate feedback time constant [s]."""
    t_f2_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TF2: second rate feedback time constant [s]."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=2.8)
    """E1: first exciter voltage at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.04)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=3.7)
    """E2: second exciter voltage at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.33)
    """SE(E2): saturation factor at E2 [-]."""

    def __check_init__(self):
        check_positive(self, "ka", "t_e_s")
        check_nonnegative(self, "t_r_s", "t_a_s", "kf", "t_f1_s", "t_f2_s", "e1_pu", "se1",
                          "e2_pu", "se2")
        if all_concrete(self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    @property
    def n_states(self) -> int:
        return 6

    def _vx(self, efd):
        return saturation_product(efd, self.e1_pu, self.se1, self.e2_pu, self.se2)

    def _feedback(self):
        """VF = k VR + vf0(state): (k, on1, on2); k != 0 when exactly one of TF1, TF2 is > 0."""
        on1, on2 = self.t_f1_s > 0, self.t_f2_s > 0
        k = jnp.where(on1 & ~on2, self.kf / safe(self.t_f1_s),
                      jnp.where(~on1 & on2, self.kf / safe(self.t_f2_s), 0.0))
        return k, on1, on2

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        vx0 = self._vx(efd0)
        ke_auto = self.vr_max_pu / (10.0 * _nonzero(efd0)) - vx0 / _nonzero(efd0)
        ke = self.ke if self.ke_zero == "literal" else jnp.where(self.ke != 0, self.ke, ke_auto)
        vr0 = ke * efd0 + vx0
        x_f2 = jnp.where((self.t_f1_s > 0) | ~(self.t_f2_s > 0), 0.0, vr0)
        return jnp.stack([vt, vr0, vr0, efd0, x_f2, ke]), vt + vr0 / self.ka

    def vector_field(self, state, inputs: ExciterInputs, vref):
        vm, d_m = lag(inputs.vt_pu, state[0], self.t_r_s)
        k, on1, on2 = self._feedback()
        vf0 = jnp.where(on1 & ~on2, -k * state[1],
                        jnp.where(~on1 & on2, -k * state[4], jnp.where(on1 & on2, state[4], 0.0)))
        c = vref + inputs.vs_pu - vm
        on_a = self.t_a_s > 0
        vr_alg = jnp.clip(self.ka * (c - vf0) / (1.0 + self.ka * k), self.vr_min_pu, self.vr_max_pu)
        vr_state = jnp.clip(state[2], self.vr_min_pu, self.vr_max_pu)
        vr = jnp.where(on_a, vr_state, vr_alg)
        u = c - (k * vr + vf0)
        d_r = jnp.where(on_a, blocked(state[2], (self.ka * u - state[2]) / safe(self.t_a_s),
                                      self.vr_min_pu, self.vr_max_pu), 0.0)
        d_f1 = jnp.where(on1, (vr - state[1]) / safe(self.t_f1_s), 0.0)
        d_f2 = jnp.where(on1 & on2, (self.kf * d_f1 - state[4]) / safe(self.t_f2_s),
                         jnp.where(~on1 & on2, (vr - state[4]) / safe(self.t_f2_s), 0.0))
        efd = state[3]
        d_e = (vr - state[5] * efd - self._vx(efd)) / self.t_e_s
        return jnp.stack([d_m, d_f1, d_r, d_e, d_f2, jnp.zeros_like(d_e)])

    def efd(self, state, inputs: ExciterInputs, vref):
        return state[3]


__all__ = ["ESDC1A", "ESDC2A", "EXDC2", "IEEEX1", "IEEET1", "IEEET2"]
