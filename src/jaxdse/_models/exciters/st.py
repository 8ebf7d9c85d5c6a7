"""Static (potential- and compound-source) exciters of IEEE Std 421.5 as PSS/E models: EXST1, ESST3A (shared conventions: :mod:`jaxdse._models.exciters`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._core.blocks import blocked, lag, lead_lag, nonwindup_lag, safe, washout
from ..._core.fields import all_concrete, as_float, check_nonnegative, check_positive, check_that
from ..base import AbstractExciter, ExciterInputs
from .common import rectifier_fex

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


__all__ = ["ESST3A", "EXST1"]
