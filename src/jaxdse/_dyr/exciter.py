"""PSS/E excitation-system models: SEXS, IEEEX1, EXDC2, ESDC2A, EXST1 and ESST3A as equinox modules.

Every model subclasses :class:`~jaxdse._dyr.base.AbstractExciter` (machine base, per unit,
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
* the block that produces Efd must be dynamic (SEXS TE > 0, EXST1 TA > 0, DC exciters TE > 0,
  ESST3A TA > 0 or TM > 0): with it bypassed, Efd would depend on Vref directly, and
  ``efd(state, inputs)`` does not see Vref. Such records are refused with a ValueError;
* ``initial_state(efd0, inputs)`` solves the steady state in closed form with VOTHSG = 0
  (the DC exciters' saturation and ESST3A's rectifier loading need no iteration: Efd is given,
  and they are explicit functions of Efd and the inputs). The operating point is assumed to lie
  within the limits (no limit is active in the returned steady state).

Sources: Siemens PTI, *PSS(R)E Model Library* (block diagram of each model, CON tables);
IEEE Std 421.5-2005/2016 *Recommended Practice for Excitation System Models for Power System
Stability Studies* (DC1A/DC2A, ST1A, ST3A, the rectifier regulation function FEX of Annex D,
non-windup limits of Annex E); for the structure only, the BSD-3 implementations OpenIPSL
(``OpenIPSL.Electrical.Controls.PSSE.ES``: SEXS, IEEEX1, ESDC2A, EXST1, the PSS/E quadratic
saturation ``NonElectrical.Functions.SE`` and the PSS/E DC exciter set-up
``calculate_dc_exciter_params``, citing the PSS/E Program Application Guide vol. 2, 15.2.4) and
PowerSimulationsDynamics.jl (SEXS, EXST1); PowerWorld's exciter pages for the parameter lists.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._core.blocks import blocked, lag, lead_lag, nonwindup_lag, safe, washout
from .._core.fields import all_concrete, as_float, check_nonnegative, check_positive, check_that
from .base import AbstractExciter, ExciterInputs


def _nonzero(x):
    """A divisor that is ``x`` where ``x != 0`` and 1 elsewhere."""
    return jnp.where(x != 0, x, 1.0)


# --- shared nonlinear functions ---------------------------------------------------------------

def saturation_product(efd, e1, se1, e2, se2):
    """SE(EFD)·EFD of the PSS/E quadratic exciter saturation through (E1, SE(E1)), (E2, SE(E2)).

    PSS/E fits ``SE(x)·x = B (x - A)^2`` for ``x > A`` (0 below A and for ``x <= 0``), so that
    the curve passes through both points: with ``a = sqrt(SE1 E1/(SE2 E2))``,
    ``A = (a E2 - E1)/(a - 1)`` and ``B = SE2 E2 / (E2 - A)^2`` (OpenIPSL ``SE``). Data with
    SE1 = 0, SE2 = 0, E1 = E2 or SE1 E1 = SE2 E2 give no saturation.
    """
    ok = (se1 > 0) & (se2 > 0) & (e1 > 0) & (e2 > 0) & (e1 != e2)
    ratio = jnp.where(ok, se1 * e1 / jnp.where(ok, se2 * e2, 1.0), 4.0)
    a = jnp.sqrt(ratio)
    ok = ok & (jnp.abs(a - 1.0) > 1e-9)
    big_a = (a * e2 - e1) / jnp.where(ok, a - 1.0, 1.0)
    gap = jnp.where(ok, e2 - big_a, 1.0)
    big_b = jnp.where(ok, se2 * e2 / (gap * gap), 0.0)
    on = ok & (efd > big_a) & (efd > 0)
    d = jnp.where(on, efd - big_a, 0.0)
    return jnp.where(on, big_b * d * d, 0.0)


def saturation(efd, e1, se1, e2, se2):
    """SE(EFD) [-]: :func:`saturation_product` / EFD (0 for EFD <= 0)."""
    vx = saturation_product(efd, e1, se1, e2, se2)
    return jnp.where(efd > 0, vx / jnp.where(efd > 0, efd, 1.0), 0.0)


def rectifier_fex(i_n):
    """FEX(IN), the rectifier regulation characteristic (IEEE Std 421.5, Annex D).

    1 for IN <= 0; 1 - 0.577 IN up to 0.433; sqrt(0.75 - IN^2) up to 0.75; 1.732 (1 - IN) up
    to 1; 0 beyond.
    """
    mid = jnp.clip(i_n, 0.433, 0.75)
    return jnp.where(i_n <= 0.0, 1.0,
                     jnp.where(i_n <= 0.433, 1.0 - 0.577 * i_n,
                               jnp.where(i_n < 0.75, jnp.sqrt(0.75 - mid * mid),
                                         jnp.where(i_n <= 1.0, 1.732 * (1.0 - i_n), 0.0))))


# --- SEXS -------------------------------------------------------------------------------------

class SEXS(AbstractExciter):
    """PSS/E SEXS, the simplified excitation system.

    Block diagram (Siemens PTI *PSS/E Model Library*, "SEXS"; OpenIPSL ``SEXS``,
    PowerSimulationsDynamics.jl ``SEXS``):

        u   = Vref + VOTHSG - EC
        y   = (1 + s TA)/(1 + s TB) u,  TA = (TA/TB)·TB             (lead-lag)
        EFD = K/(1 + s TE) y, non-windup limits [EMIN, EMAX]

    States: [lead-lag state, EFD]. TB = 0 makes the lead-lag a pass-through; TE must be > 0.
    """

    ta_tb: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """TA/TB: ratio of the lead to the lag time constant [-]."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    k: Float[Array, ""] = eqx.field(converter=as_float, default=100.0)
    """K: gain [pu/pu] (> 0)."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """TE: exciter time constant [s] (> 0)."""
    e_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """EMIN: lower limit of EFD [pu]."""
    e_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """EMAX: upper limit of EFD [pu]."""

    def __check_init__(self):
        check_positive(self, "k", "t_e_s")
        check_nonnegative(self, "ta_tb", "t_b_s")
        if all_concrete(self.e_max_pu, self.e_min_pu):
            check_that(self, self.e_max_pu >= self.e_min_pu,
                   f"EMAX ({self.e_max_pu}) must be >= EMIN ({self.e_min_pu})")

    @property
    def n_states(self) -> int:
        return 2

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        u0 = efd0 / self.k
        return jnp.stack([u0, efd0]), jnp.asarray(inputs.vt_pu, float) + u0

    def vector_field(self, state, inputs: ExciterInputs, vref):
        u = vref + inputs.vs_pu - inputs.vt_pu
        y, d_ll = lead_lag(u, state[0], self.ta_tb * self.t_b_s, self.t_b_s)
        _, d_e = nonwindup_lag(y, state[1], self.t_e_s, self.e_min_pu, self.e_max_pu, gain=self.k)
        return jnp.stack([d_ll, d_e])

    def efd(self, state, inputs: ExciterInputs):
        return jnp.clip(state[1], self.e_min_pu, self.e_max_pu)


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

    def efd(self, state, inputs: ExciterInputs):
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


# --- EXST1 ------------------------------------------------------------------------------------

class EXST1(AbstractExciter):
    """PSS/E EXST1, the 1981 IEEE type ST1 static (potential-source, controlled rectifier) exciter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "EXST1"; OpenIPSL ``EXST1`` and
    PowerSimulationsDynamics.jl ``EXST1``, which agree on it):

        VM  = EC/(1 + s TR)
        VI  = clip(Vref + VOTHSG - VM - VF, VIMIN, VIMAX)
        VR  = KA/(1 + s TA) (1 + s TC)/(1 + s TB) VI                (no limit on the state)
        EFD = clip(VR, EC·VRMIN - KC·IFD, EC·VRMAX - KC·IFD)       (field voltage limits)
        VF  = s KF/(1 + s TF) VR                                    (rate feedback)

    States: [VM, lead-lag state, VR, rate-feedback state]. The output limits act on EFD only:
    VR is not held (a windup limit), and the rate feedback sees VR, as in OpenIPSL and
    PowerSimulationsDynamics.jl. TA must be > 0 (EFD would otherwise depend on Vref directly).
    """

    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    vi_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """VIMAX: upper limit of the voltage error [pu]."""
    vi_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.2)
    """VIMIN: lower limit of the voltage error [pu]."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TC: lead time constant of the lead-lag [s]."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=80.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """TA: voltage regulator time constant [s] (> 0)."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=8.0)
    """VRMAX: upper field voltage limit per unit of terminal voltage [pu/pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-3.0)
    """VRMIN: lower field voltage limit per unit of terminal voltage [pu/pu]."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """KC: rectifier loading factor (commutating reactance) [pu]."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """KF: rate feedback gain [pu/pu]."""
    t_f_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TF: rate feedback time constant [s] (0: no rate feedback)."""

    def __check_init__(self):
        check_positive(self, "ka", "t_a_s")
        check_nonnegative(self, "t_r_s", "t_c_s", "t_b_s", "kc", "kf", "t_f_s")
        if all_concrete(self.vi_max_pu, self.vi_min_pu, self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.vi_max_pu >= self.vi_min_pu,
                   f"VIMAX ({self.vi_max_pu}) must be >= VIMIN ({self.vi_min_pu})")
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                   f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    @property
    def n_states(self) -> int:
        return 4

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        u0 = efd0 / self.ka
        return jnp.stack([vt, u0, efd0, efd0]), vt + u0

    def vector_field(self, state, inputs: ExciterInputs, vref):
        vm, d_m = lag(inputs.vt_pu, state[0], self.t_r_s)
        vr = state[2]
        d_fb, d_f = washout(vr, state[3], self.t_f_s)
        vi = jnp.clip(vref + inputs.vs_pu - vm - self.kf * d_fb, self.vi_min_pu, self.vi_max_pu)
        y, d_ll = lead_lag(vi, state[1], self.t_c_s, self.t_b_s)
        d_r = (self.ka * y - vr) / self.t_a_s
        return jnp.stack([d_m, d_ll, d_r, d_f])

    def efd(self, state, inputs: ExciterInputs):
        lo = inputs.vt_pu * self.vr_min_pu - self.kc * inputs.ifd_pu
        hi = inputs.vt_pu * self.vr_max_pu - self.kc * inputs.ifd_pu
        return jnp.clip(state[2], lo, hi)


# --- ESST3A -----------------------------------------------------------------------------------

class ESST3A(AbstractExciter):
    """PSS/E ESST3A, the IEEE Std 421.5-2005 type ST3A static exciter (compound source, inner loop).

    Block diagram (Siemens PTI *PSS/E Model Library*, "ESST3A"; IEEE Std 421.5-2005 type ST3A,
    without UEL):

        VM_s = EC/(1 + s TR)
        VI   = clip(Vref + VOTHSG - VM_s, VIMIN, VIMAX)
        VR   = KA/(1 + s TA) (1 + s TC)/(1 + s TB) VI, non-windup limits [VRMIN, VRMAX]
        VM   = KM/(1 + s TM) (VR - VG), non-windup limits [VMMIN, VMMAX]   (inner field loop)
        VG   = min(KG·EFD, VGMAX)
        VE   = |KP·VT + j (KI + KP·XL)·IT|, KP = KP e^(j THETAP)           (power source)
        IN   = KC·IFD/VE,  VB = min(VE·FEX(IN), VBMAX)                      (rectifier)
        EFD  = VB·VM

    States: [VM_s, lead-lag state, VR, VM]. TA = 0 makes the regulator a limited gain KA;
    TM = 0 makes the inner loop algebraic, solved exactly (the loop VM = KM (VR - VG(VB·VM))
    is monotone in VM, so its solution is the unlimited root, clipped to [VMMIN, VMMAX]).
    TA and TM may not both be 0. VE <= 0 gives VB = 0.
    """

    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    vi_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """VIMAX: upper limit of the voltage error [pu]."""
    vi_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.2)
    """VIMIN: lower limit of the voltage error [pu]."""
    km: Float[Array, ""] = eqx.field(converter=as_float, default=7.93)
    """KM: forward gain of the inner loop field regulator [pu/pu] (> 0)."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TC: lead time constant of the lead-lag [s]."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=200.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TA: voltage regulator time constant [s] (0: limited gain KA)."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """VRMAX: upper limit of the regulator output VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-10.0)
    """VRMIN: lower limit of the regulator output VR [pu]."""
    kg: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KG: feedback gain of the inner loop field regulator [pu/pu]."""
    kp: Float[Array, ""] = eqx.field(converter=as_float, default=6.15)
    """KP: potential circuit gain magnitude [pu/pu]."""
    ki: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KI: potential circuit (current) gain [pu/pu]."""
    vb_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=6.9)
    """VBMAX: maximum available exciter voltage VB [pu] (> 0)."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """KC: rectifier loading factor (commutating reactance) [pu]."""
    xl_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.081)
    """XL: reactance associated with the potential source [pu]."""
    vg_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=5.8)
    """VGMAX: maximum inner loop feedback voltage VG [pu]."""
    theta_p_rad: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """THETAP: potential circuit phase angle [rad] (PSS/E data give degrees)."""
    t_m_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.4)
    """TM: time constant of the inner loop field regulator [s] (0: algebraic loop)."""
    vm_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """VMMAX: upper limit of the inner loop output VM [pu]."""
    vm_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """VMMIN: lower limit of the inner loop output VM [pu]."""

    def __check_init__(self):
        check_positive(self, "km", "ka", "vb_max_pu")
        check_nonnegative(self, "t_r_s", "t_c_s", "t_b_s", "t_a_s", "kg", "kp", "ki", "kc",
                          "xl_pu", "t_m_s")
        if all_concrete(self.vi_max_pu, self.vi_min_pu, self.vr_max_pu, self.vr_min_pu,
                     self.vm_max_pu, self.vm_min_pu, self.t_a_s, self.t_m_s):
            check_that(self, self.vi_max_pu >= self.vi_min_pu,
                   f"VIMAX ({self.vi_max_pu}) must be >= VIMIN ({self.vi_min_pu})")
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                   f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")
            check_that(self, self.vm_max_pu >= self.vm_min_pu,
                   f"VMMAX ({self.vm_max_pu}) must be >= VMMIN ({self.vm_min_pu})")
            check_that(self, (self.t_a_s > 0) | (self.t_m_s > 0),
                   "TA and TM may not both be 0 (EFD would depend on Vref directly)")

    @property
    def n_states(self) -> int:
        return 4

    def ve(self, inputs: ExciterInputs):
        """VE = |KP e^(j THETAP) VT + j (KI + KP e^(j THETAP) XL) IT| [pu]."""
        kpr = self.kp * jnp.cos(self.theta_p_rad)
        kpi = self.kp * jnp.sin(self.theta_p_rad)
        vr_, vi_, ir_, ii_ = inputs.v_re_pu, inputs.v_im_pu, inputs.i_re_pu, inputs.i_im_pu
        c_re = -kpi * self.xl_pu
        c_im = self.ki + kpr * self.xl_pu
        re = kpr * vr_ - kpi * vi_ + c_re * ir_ - c_im * ii_
        im = kpr * vi_ + kpi * vr_ + c_re * ii_ + c_im * ir_
        s = re * re + im * im
        return jnp.where(s > 0, jnp.sqrt(jnp.where(s > 0, s, 1.0)), 0.0)

    def vb(self, inputs: ExciterInputs):
        """VB = min(VE·FEX(KC·IFD/VE), VBMAX) [pu]: the available exciter voltage."""
        ve = self.ve(inputs)
        on = ve > 0
        i_n = self.kc * inputs.ifd_pu / jnp.where(on, ve, 1.0)
        return jnp.where(on, jnp.minimum(ve * rectifier_fex(i_n), self.vb_max_pu), 0.0)

    def _vm_algebraic(self, vr, vb):
        """VM of the inner loop with TM = 0: VM = clip(KM (VR - min(KG VB VM, VGMAX)))."""
        r1 = self.km * vr / (1.0 + self.km * self.kg * vb)
        r = jnp.where(self.kg * vb * r1 <= self.vg_max_pu, r1, self.km * (vr - self.vg_max_pu))
        return jnp.clip(r, self.vm_min_pu, self.vm_max_pu)

    def _vm(self, state, vr, vb):
        return jnp.where(self.t_m_s > 0, jnp.clip(state[3], self.vm_min_pu, self.vm_max_pu),
                         self._vm_algebraic(vr, vb))

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        vb = self.vb(inputs)
        vm0 = efd0 / jnp.where(vb > 0, vb, 1.0)
        vr0 = vm0 / self.km + jnp.minimum(self.kg * efd0, self.vg_max_pu)
        u0 = vr0 / self.ka
        return jnp.stack([vt, u0, vr0, vm0]), vt + u0

    def vector_field(self, state, inputs: ExciterInputs, vref):
        vm_s, d_s = lag(inputs.vt_pu, state[0], self.t_r_s)
        vi = jnp.clip(vref + inputs.vs_pu - vm_s, self.vi_min_pu, self.vi_max_pu)
        y, d_ll = lead_lag(vi, state[1], self.t_c_s, self.t_b_s)
        vr, d_r = nonwindup_lag(y, state[2], self.t_a_s, self.vr_min_pu, self.vr_max_pu,
                                gain=self.ka)
        vb = self.vb(inputs)
        vm = self._vm(state, vr, vb)
        vg = jnp.minimum(self.kg * vb * vm, self.vg_max_pu)
        on = self.t_m_s > 0
        d_m = jnp.where(on, blocked(state[3], (self.km * (vr - vg) - state[3]) / safe(self.t_m_s),
                                    self.vm_min_pu, self.vm_max_pu), 0.0)
        return jnp.stack([d_s, d_ll, d_r, d_m])

    def efd(self, state, inputs: ExciterInputs):
        vb = self.vb(inputs)
        vr = jnp.clip(state[2], self.vr_min_pu, self.vr_max_pu)  # TM = 0 needs TA > 0
        return vb * self._vm(state, vr, vb)


# --- PSS/E records ----------------------------------------------------------------------------

EXCITERS: dict[str, type[AbstractExciter]] = {
    "SEXS": SEXS, "IEEEX1": IEEEX1, "EXDC2": EXDC2, "ESDC2A": ESDC2A, "EXST1": EXST1, "ESST3A": ESST3A}
"""The exciter models by their PSS/E name."""

_DC_CONS = ("TR", "KA", "TA", "TB", "TC", "VRMAX", "VRMIN", "KE", "TE", "KF", "TF1", "Switch",
            "E1", "SE(E1)", "E2", "SE(E2)")
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
}


def exciter_from_dyr(model: str, constants: Sequence[float], *,
                     ke_zero: Literal["psse", "literal"] = "psse") -> AbstractExciter:
    """The exciter of a PSS/E .dyr record: ``model`` (e.g. ``"ESST3A"``) and its CONs in order.

    Conversions: ESST3A THETAP from degrees to radians. DC exciters (IEEEX1, EXDC2, ESDC2A): VRMAX = 0
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
    if name == "ESST3A":
        kwargs["theta_p_rad"] = math.radians(kwargs["theta_p_rad"])
    dc = name in ("IEEEX1", "EXDC2", "ESDC2A")
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
    except ValueError as err:
        message = str(err).splitlines()[0] if str(err) else "invalid constants"
        for con, attribute in zip(cons, _ATTRIBUTES[name]):  # name the CON as the record does
            message = message.replace(f"{name}.{attribute} ", f"{name}: {con} ({attribute}) ")
        raise ValueError(message if message.startswith(name) else f"{name}: {message}") from None


__all__ = ["ESDC2A", "ESST3A", "EXCITERS", "EXCITER_FIELDS", "EXDC2", "EXST1", "IEEEX1", "SEXS",
           "exciter_from_dyr", "rectifier_fex", "saturation", "saturation_product"]
