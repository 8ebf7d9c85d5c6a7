"""Static (potential- and compound-source) exciters of IEEE Std 421.5 as PSS/E models: EXST1,
ESST1A, ESST3A, ESST4B, and the PI exciter EXPIC1 (shared conventions: :mod:`jaxdse._models.exciters`)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..._base.blocks import blocked, lag, lead_lag, nonwindup_lag, safe, washout
from ..._base.fields import all_concrete, as_flag, as_float, check_nonnegative, check_positive, check_that
from ..base import AbstractExciter, ExciterInputs
from .common import rectifier_fex, saturation_product

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

    def efd(self, state, inputs: ExciterInputs, vref):
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

    def efd(self, state, inputs: ExciterInputs, vref):
        vb = self.vb(inputs)
        vr = jnp.clip(state[2], self.vr_min_pu, self.vr_max_pu)  # TM = 0 needs TA > 0
        return vb * self._vm(state, vr, vb)



# --- shared pieces of ESST4B, ESST1A, EXPIC1 ----------------------------------------------------
#
# These models let Efd depend on Vref directly when the blocks between them are bypassed (TA = 0
# and a proportional path): ``efd(state, inputs, vref)`` evaluates that path with the Vref given.

def _icon(x):
    """An integer ICON from a .dyr number (1.0 -> 1) as an integer leaf; ValueError for a
    non-integer."""
    value = float(x)
    if not value.is_integer():
        raise ValueError(f"ICON must be an integer, got {x}")
    return as_flag(int(value))


def _pi_nonwindup(u, x, kp, ki, lo, hi):
    """PI block KP + KI/s with non-windup limits [lo, hi] (IEEE 421.5-2016, Annex E):
    (clipped output, dx/dt); the integrator stops while the output sits on a limit and the
    input would drive it further out."""
    v = kp * u + x
    dx = ki * u
    dx = jnp.where(((v >= hi) & (dx > 0)) | ((v <= lo) & (dx < 0)), 0.0, dx)
    return jnp.clip(v, lo, hi), dx


def _clipped_loop(a, k, g, b, lo1, hi1, lo2, hi2):
    """The solution w of w = clip(g·clip(a - k w, lo1, hi1) + b, lo2, hi2), for g, k >= 0.

    An algebraic loop through limits (a proportional path closed by a feedback k): the right
    side is non-increasing in w, so the solution is unique; nesting the clips gives
    w = clip(p - q w, L, H) with p = g a + b, q = g k, L = clip(g lo1 + b, lo2, hi2),
    H = clip(g hi1 + b, lo2, hi2), whose solution is clip(p/(1 + q), L, H). k = 0: the plain
    forward value."""
    lo = jnp.clip(g * lo1 + b, lo2, hi2)
    hi = jnp.clip(g * hi1 + b, lo2, hi2)
    return jnp.clip((g * a + b) / (1.0 + g * k), lo, hi)


def _source_voltage(kp, theta_p, ki, xl, inputs: ExciterInputs):
    """VE = |KP e^(j THETAP) VT + j (KI + KP e^(j THETAP) XL) IT| [pu] (IEEE 421.5 potential and
    compound source)."""
    kpr = kp * jnp.cos(theta_p)
    kpi = kp * jnp.sin(theta_p)
    vr_, vi_, ir_, ii_ = inputs.v_re_pu, inputs.v_im_pu, inputs.i_re_pu, inputs.i_im_pu
    c_re = -kpi * xl
    c_im = ki + kpr * xl
    re = kpr * vr_ - kpi * vi_ + c_re * ir_ - c_im * ii_
    im = kpr * vi_ + kpi * vr_ + c_re * ii_ + c_im * ir_
    s = re * re + im * im
    return jnp.where(s > 0, jnp.sqrt(jnp.where(s > 0, s, 1.0)), 0.0)


def _rectified(ve, kc, ifd):
    """VE·FEX(KC·IFD/VE) [pu] (0 for VE <= 0)."""
    on = ve > 0
    i_n = kc * ifd / jnp.where(on, ve, 1.0)
    return jnp.where(on, ve * rectifier_fex(i_n), 0.0)


# --- ESST4B -----------------------------------------------------------------------------------

class ESST4B(AbstractExciter):
    """PSS/E ESST4B, the IEEE Std 421.5-2005 type ST4B static exciter (PI regulators, bus- or
    compound-fed controlled rectifier).

    Block diagram (Siemens PTI *PSS/E Model Library*, "ESST4B"; IEEE Std 421.5-2005/2016 type
    ST4B/ST4C, without OEL; OpenIPSL ``ESST4B`` for the structure):

        VM_s = EC/(1 + s TR)
        VR   = (KPR + KIR/s)(Vref + VOTHSG - VM_s), non-windup limits [VRMIN, VRMAX]
        VA   = VR/(1 + s TA)
        VM   = (KPM + KIM/s)(VA - KG·EFD), non-windup limits [VMMIN, VMMAX]   (inner loop)
        VE   = |KP·VT + j (KI + KP·XL)·IT|, KP = KP e^(j THETAP)          (power source)
        VB   = min(VE·FEX(KC·IFD/VE), VBMAX),   EFD = VB·VM

    17 CONs: TR [s], KPR [pu], KIR [pu/s], VRMAX, VRMIN [pu], TA [s], KPM [pu], KIM [pu/s],
    VMMAX, VMMIN [pu], KG [pu], KP [pu], KI [pu], VBMAX [pu], KC [pu], XL [pu], THETAP [deg in
    the record, rad here]. KI and XL are on the machine base, as PSS/E applies them (ANDES 2.0
    applies them on the system base).

    The PI blocks' non-windup limits freeze their integrator while the output sits on a limit
    and the input pushes outward (IEEE 421.5-2016, Annex E). TR = 0 and TA = 0 bypass their lag
    (state kept, zero derivative); the inner loop through KG is algebraic and solved exactly
    (monotone: the clipped unlimited root). KIR = 0 or KIM = 0 leave a proportional path whose
    integrator holds its initial value. The steady state (as OpenIPSL's PSS/E ESST4B): both PI
    inputs 0, so Vref = EC, VR = VA = KG·EFD0 held by the outer integrator and VM = EFD0/VB by
    the inner one -- whatever the gains.

    States: [VM_s, outer integrator, VA, inner integrator]. Efd may depend on Vref directly
    (TA = 0): ``efd(state, inputs, vref)``.
    """

    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    kpr: Float[Array, ""] = eqx.field(converter=as_float, default=3.15)
    """KPR: voltage regulator proportional gain [pu/pu]."""
    kir: Float[Array, ""] = eqx.field(converter=as_float, default=3.15)
    """KIR: voltage regulator integral gain [pu/(pu s)]."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """VRMAX: upper limit of the voltage regulator output VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.87)
    """VRMIN: lower limit of the voltage regulator output VR [pu]."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """TA: firing circuit time constant [s] (0: pass-through)."""
    kpm: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KPM: inner loop (field) regulator proportional gain [pu/pu]."""
    kim: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KIM: inner loop regulator integral gain [pu/(pu s)]."""
    vm_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """VMMAX: upper limit of the inner loop output VM [pu]."""
    vm_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.87)
    """VMMIN: lower limit of the inner loop output VM [pu]."""
    kg: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KG: inner loop feedback gain [pu/pu]."""
    kp: Float[Array, ""] = eqx.field(converter=as_float, default=6.73)
    """KP: potential circuit gain magnitude [pu/pu]."""
    ki: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KI: compound circuit (current) gain [pu/pu], machine base."""
    vb_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=11.63)
    """VBMAX: maximum available exciter voltage VB [pu] (> 0)."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """KC: rectifier loading factor (commutating reactance) [pu]."""
    xl_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """XL: reactance associated with the potential source [pu], machine base."""
    theta_p_rad: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """THETAP: potential circuit phase angle [rad] (PSS/E data give degrees)."""

    def __check_init__(self):
        check_positive(self, "vb_max_pu")
        check_nonnegative(self, "t_r_s", "kpr", "kir", "t_a_s", "kpm", "kim", "kg", "kp", "ki",
                          "kc", "xl_pu")
        if all_concrete(self.vr_max_pu, self.vr_min_pu, self.vm_max_pu, self.vm_min_pu):
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")
            check_that(self, self.vm_max_pu >= self.vm_min_pu,
                       f"VMMAX ({self.vm_max_pu}) must be >= VMMIN ({self.vm_min_pu})")

    @property
    def n_states(self) -> int:
        return 4

    def vb(self, inputs: ExciterInputs):
        """VB = min(VE·FEX(KC·IFD/VE), VBMAX) [pu]: the available exciter voltage."""
        ve = _source_voltage(self.kp, self.theta_p_rad, self.ki, self.xl_pu, inputs)
        return jnp.minimum(_rectified(ve, self.kc, inputs.ifd_pu), self.vb_max_pu)

    def _chain(self, state, inputs: ExciterInputs, vref):
        vm_s, d_s = lag(inputs.vt_pu, state[0], self.t_r_s)
        vr, d_r = _pi_nonwindup(vref + inputs.vs_pu - vm_s, state[1], self.kpr, self.kir,
                                self.vr_min_pu, self.vr_max_pu)
        va, d_a = lag(vr, state[2], self.t_a_s)
        vb = self.vb(inputs)
        # VM = clip(KPM (VA - KG VB VM) + x_m): non-increasing in VM, the clipped unlimited root
        vm = jnp.clip((self.kpm * va + state[3]) / (1.0 + self.kpm * self.kg * vb),
                      self.vm_min_pu, self.vm_max_pu)
        efd = vb * vm
        _, d_m = _pi_nonwindup(va - self.kg * efd, state[3], self.kpm, self.kim,
                               self.vm_min_pu, self.vm_max_pu)
        return efd, jnp.stack([d_s, d_r, d_a, d_m])

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        vb = self.vb(inputs)
        vm0 = efd0 / jnp.where(vb > 0, vb, 1.0)
        vr0 = self.kg * efd0
        return jnp.stack([vt, vr0, vr0, vm0]), vt

    def vector_field(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[1]

    def efd(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[0]


# --- ESST1A -----------------------------------------------------------------------------------

class ESST1A(AbstractExciter):
    """PSS/E ESST1A, the IEEE Std 421.5-2005 type ST1A static (potential-source, controlled
    rectifier) exciter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "ESST1A"; IEEE Std 421.5-2005 type ST1A;
    OpenIPSL ``ESST1A`` and PowerSimulationsDynamics.jl ``ESST1A``, which agree, for the
    structure), without UEL and OEL:

        VM_s = EC/(1 + s TR)
        VI   = clip(Vref + [VOS = 1] VOTHSG - VM_s - VF, VIMIN, VIMAX)
        y    = (1 + s TC)/(1 + s TB) (1 + s TC1)/(1 + s TB1) VI
        VA   = KA/(1 + s TA) y, non-windup limits [VAMIN, VAMAX]
        VA'  = VA - KLR·max(IFD - ILR, 0) + [VOS = 2] VOTHSG      (field current limiter)
        EFD  = clip(VA', VT·VRMIN, VT·VRMAX - KC·IFD)
        VF   = s KF/(1 + s TF) VA'                                 (rate feedback)

    ICONs: UEL (1, 2, 3: where VUEL enters -- the summing junction, an HV gate before the lead-
    lags, or an HV gate on VA'; VUEL is absent here, so all three give the same model; the ICON
    is kept for the record) and VOS (1: VOTHSG at the voltage-error summing junction, the usual
    and default place; 2: VOTHSG added to VA'). 18 CONs: TR [s], VIMAX, VIMIN [pu], TC, TB,
    TC1, TB1 [s], KA [pu], TA [s], VAMAX, VAMIN [pu], VRMAX, VRMIN [pu/pu of VT], KC [pu],
    KF [pu], TF [s], KLR [pu], ILR [pu]. (ANDES 2.0's .dyr reader takes another order.)

    TR = 0, TB = 0, TB1 = 0 bypass their block (state kept, zero derivative); TF = 0 removes the
    rate feedback; TA = 0 makes the regulator the limited gain KA, and the loop closed by the
    rate feedback is then algebraic: solved exactly (the clipped unlimited root, see
    :func:`_clipped_loop`). Steady state: VA = EFD0 + KLR·max(IFD0 - ILR, 0) within its limits,
    VF = 0, Vref = EC + VA/KA.

    States: [VM_s, lead-lag 1, lead-lag 2, VA, rate feedback]. Efd may depend on Vref directly
    (TA = 0): ``efd(state, inputs, vref)``.
    """

    uel: Int[Array, ""] = eqx.field(converter=_icon, default=1)
    """UEL (ICON): input location of VUEL, 1-3 (VUEL absent: kept for the record)."""
    vos: Int[Array, ""] = eqx.field(converter=_icon, default=1)
    """VOS (ICON): input location of VOTHSG, 1 (summing junction) or 2 (added to VA')."""
    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    vi_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=999.0)
    """VIMAX: upper limit of the voltage error VI [pu]."""
    vi_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-999.0)
    """VIMIN: lower limit of the voltage error VI [pu]."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TC: lead time constant of the first lead-lag [s]."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TB: lag time constant of the first lead-lag [s] (0: pass-through)."""
    t_c1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TC1: lead time constant of the second lead-lag [s]."""
    t_b1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TB1: lag time constant of the second lead-lag [s] (0: pass-through)."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=210.0)
    """KA: voltage regulator gain [pu/pu] (> 0)."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TA: voltage regulator time constant [s] (0: limited gain KA)."""
    va_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=999.0)
    """VAMAX: upper limit of the regulator output VA [pu]."""
    va_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-999.0)
    """VAMIN: lower limit of the regulator output VA [pu]."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=6.43)
    """VRMAX: upper field voltage limit per unit of terminal voltage [pu/pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-6.0)
    """VRMIN: lower field voltage limit per unit of terminal voltage [pu/pu]."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.038)
    """KC: rectifier loading factor (commutating reactance) [pu]."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KF: rate feedback gain [pu/pu]."""
    t_f_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TF: rate feedback time constant [s] (0: no rate feedback)."""
    klr: Float[Array, ""] = eqx.field(converter=as_float, default=4.54)
    """KLR: field current limiter gain [pu/pu]."""
    ilr_pu: Float[Array, ""] = eqx.field(converter=as_float, default=4.4)
    """ILR: field current limiter pick-up [pu of LadIfd]."""

    def __check_init__(self):
        check_positive(self, "ka")
        check_nonnegative(self, "t_r_s", "t_c_s", "t_b_s", "t_c1_s", "t_b1_s", "t_a_s", "kc",
                          "kf", "t_f_s", "klr")
        check_that(self, jnp.isin(self.uel, jnp.asarray([1, 2, 3])), f"UEL must be 1, 2 or 3, got {self.uel}")
        check_that(self, jnp.isin(self.vos, jnp.asarray([1, 2])), f"VOS must be 1 or 2, got {self.vos}")
        if all_concrete(self.vi_max_pu, self.vi_min_pu, self.va_max_pu, self.va_min_pu,
                        self.vr_max_pu, self.vr_min_pu):
            check_that(self, self.vi_max_pu >= self.vi_min_pu,
                       f"VIMAX ({self.vi_max_pu}) must be >= VIMIN ({self.vi_min_pu})")
            check_that(self, self.va_max_pu >= self.va_min_pu,
                       f"VAMAX ({self.va_max_pu}) must be >= VAMIN ({self.va_min_pu})")
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")

    @property
    def n_states(self) -> int:
        return 5

    def _ilr(self, inputs: ExciterInputs):
        return self.klr * jnp.maximum(inputs.ifd_pu - self.ilr_pu, 0.0)

    def _chain(self, state, inputs: ExciterInputs, vref):
        vs1 = jnp.where(self.vos == 1, inputs.vs_pu, jnp.zeros_like(inputs.vs_pu))
        vs2 = jnp.where(self.vos == 2, inputs.vs_pu, jnp.zeros_like(inputs.vs_pu))
        vm_s, d_s = lag(inputs.vt_pu, state[0], self.t_r_s)
        offset = vs2 - self._ilr(inputs)  # VA' = VA + offset
        kf = jnp.where(self.t_f_s > 0, self.kf / safe(self.t_f_s), 0.0)  # VF = kf (VA' - x_f)
        c = vref + vs1 - vm_s
        # the regulator input path as a gain and an offset (lead-lags: y = g u + (1 - g) x)
        on1, on2 = self.t_b_s > 0, self.t_b1_s > 0
        g1 = jnp.where(on1, self.t_c_s / safe(self.t_b_s), 1.0)
        g2 = jnp.where(on2, self.t_c1_s / safe(self.t_b1_s), 1.0)
        b1 = jnp.where(on1, (1.0 - g1) * state[1], 0.0)
        b2 = jnp.where(on2, (1.0 - g2) * state[2], 0.0)
        va_alg = _clipped_loop(c + kf * (state[4] - offset), kf, self.ka * g1 * g2,
                               self.ka * (g2 * b1 + b2), self.vi_min_pu, self.vi_max_pu,
                               self.va_min_pu, self.va_max_pu)
        va = jnp.where(self.t_a_s > 0, jnp.clip(state[3], self.va_min_pu, self.va_max_pu), va_alg)
        va_sum = va + offset
        vi = jnp.clip(c - kf * (va_sum - state[4]), self.vi_min_pu, self.vi_max_pu)
        y1, d_1 = lead_lag(vi, state[1], self.t_c_s, self.t_b_s)
        y2, d_2 = lead_lag(y1, state[2], self.t_c1_s, self.t_b1_s)
        _, d_a = nonwindup_lag(y2, state[3], self.t_a_s, self.va_min_pu, self.va_max_pu,
                               gain=self.ka)
        d_f = jnp.where(self.t_f_s > 0, (va_sum - state[4]) / safe(self.t_f_s), 0.0)
        vt = inputs.vt_pu
        efd = jnp.clip(va_sum, vt * self.vr_min_pu, vt * self.vr_max_pu - self.kc * inputs.ifd_pu)
        return efd, jnp.stack([d_s, d_1, d_2, d_a, d_f])

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        va0 = efd0 + self._ilr(inputs)
        u0 = va0 / self.ka
        vref = vt + u0
        return jnp.stack([vt, u0, u0, va0, efd0]), vref

    def vector_field(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[1]

    def efd(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[0]


# --- EXPIC1 -----------------------------------------------------------------------------------

class EXPIC1(AbstractExciter):
    """PSS/E EXPIC1, the proportional/integral excitation system.

    Block diagram (Siemens PTI *PSS/E Model Library*, "EXPIC1"; PowerWorld's "Exciter EXPIC1"
    page for the CON list and limits; the structure as GridKit's EXPIC1 notes read that
    diagram), without UEL and OEL:

        VM_s = EC/(1 + s TR)
        VA   = KA (1 + s TA1)/s (Vref + VOTHSG - VM_s - VF), non-windup limits [VR2, VR1]
        VR   = clip((1 + s TA3)/((1 + s TA2)(1 + s TA4)) VA, VRMIN, VRMAX)
        VF   = s KF/((1 + s TF1)(1 + s TF2)) VR                          (rate feedback)
        VE   = |KP·VT + j KI·IT|,  VB = VE·FEX(KC·IFD/VE)  (KP = KI = 0: VB = 1)
        E0   = clip(VB·VR, EFDMIN, EFDMAX)
        TE dEFD/dt = E0 - (KE + SE(EFD)) EFD          (TE = 0: EFD = E0)

    24 CONs: TR [s], KA [pu/s], TA1 [s], VR1, VR2 [pu], TA2, TA3, TA4 [s], VRMAX, VRMIN [pu],
    KF [pu], TF1, TF2 [s], EFDMAX, EFDMIN [pu], KE [pu], TE [s], E1 [pu], SE(E1) [-], E2 [pu],
    SE(E2) [-], KP [pu], KI [pu], KC [pu]. The PI regulator has proportional gain KA·TA1 and
    integral gain KA; its non-windup limits freeze the integrator (IEEE 421.5-2016, Annex E).
    VRMAX/VRMIN and EFDMAX/EFDMIN clip the signal (no state is held there). The saturation is
    PSS/E's quadratic one (:func:`saturation_product`).

    Zero time constants bypass their block (state kept, zero derivative): TR, TA2, TA4 (TA3 then
    has no effect), TE. The rate feedback s KF/((1 + s TF1)(1 + s TF2)) needs TF1 > 0 or
    TF2 > 0 (both 0: no feedback); with one of them 0 it is a filtered derivative of VR whose
    loop through the PI's proportional path is algebraic: solved exactly (the clipped
    unlimited root). Steady state: VR = E0/VB with E0 = (KE + SE(EFD0)) EFD0 (EFD0 for TE = 0),
    the PI input 0 (Vref = EC), every filter at its input.

    States: [VM_s, PI integrator, TA2 lag, TA3/TA4 lead-lag, TF1 filter, TF2 filter, EFD]. Efd
    may depend on Vref directly (TE = 0): ``efd(state, inputs, vref)``.
    """

    t_r_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TR: voltage transducer time constant [s] (0: pass-through)."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=3.15)
    """KA: PI regulator (integral) gain [pu/(pu s)] (> 0)."""
    t_a1_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TA1: PI regulator lead time constant [s] (proportional gain KA·TA1)."""
    vr1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """VR1: upper limit of the PI output VA [pu]."""
    vr2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.87)
    """VR2: lower limit of the PI output VA [pu]."""
    t_a2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TA2: regulator lag time constant [s] (0: pass-through)."""
    t_a3_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TA3: regulator lead time constant [s]."""
    t_a4_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TA4: regulator lag time constant of the lead-lag [s] (0: pass-through)."""
    vr_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """VRMAX: upper limit of the regulator output VR [pu]."""
    vr_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.87)
    """VRMIN: lower limit of the regulator output VR [pu]."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KF: rate feedback gain [pu/pu]."""
    t_f1_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TF1: first rate feedback time constant [s]."""
    t_f2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TF2: second rate feedback time constant [s]."""
    efd_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=8.0)
    """EFDMAX: upper limit of the exciter input E0 [pu]."""
    efd_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.87)
    """EFDMIN: lower limit of the exciter input E0 [pu]."""
    ke: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KE: exciter field constant [pu]."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TE: exciter time constant [s] (0: EFD = E0)."""
    e1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """E1: first exciter voltage at which the saturation is given [pu]."""
    se1: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """SE(E1): saturation factor at E1 [-]."""
    e2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """E2: second exciter voltage at which the saturation is given [pu]."""
    se2: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """SE(E2): saturation factor at E2 [-]."""
    kp: Float[Array, ""] = eqx.field(converter=as_float, default=6.5)
    """KP: potential source gain [pu/pu]."""
    ki: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """KI: current source gain [pu/pu]."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.08)
    """KC: rectifier regulation factor [pu]."""

    def __check_init__(self):
        check_positive(self, "ka")
        check_nonnegative(self, "t_r_s", "t_a1_s", "t_a2_s", "t_a3_s", "t_a4_s", "kf", "t_f1_s",
                          "t_f2_s", "t_e_s", "e1_pu", "se1", "e2_pu", "se2", "kp", "ki", "kc")
        if all_concrete(self.vr1_pu, self.vr2_pu, self.vr_max_pu, self.vr_min_pu,
                        self.efd_max_pu, self.efd_min_pu):
            check_that(self, self.vr1_pu >= self.vr2_pu,
                       f"VR1 ({self.vr1_pu}) must be >= VR2 ({self.vr2_pu})")
            check_that(self, self.vr_max_pu >= self.vr_min_pu,
                       f"VRMAX ({self.vr_max_pu}) must be >= VRMIN ({self.vr_min_pu})")
            check_that(self, self.efd_max_pu >= self.efd_min_pu,
                       f"EFDMAX ({self.efd_max_pu}) must be >= EFDMIN ({self.efd_min_pu})")

    @property
    def n_states(self) -> int:
        return 7

    def vb(self, inputs: ExciterInputs):
        """VB = VE·FEX(KC·IFD/VE), VE = |KP·VT + j KI·IT| [pu]; 1 when KP = KI = 0."""
        ve = _source_voltage(self.kp, 0.0, self.ki, 0.0, inputs)
        return jnp.where((self.kp == 0) & (self.ki == 0), 1.0,
                         _rectified(ve, self.kc, inputs.ifd_pu))

    def _chain(self, state, inputs: ExciterInputs, vref):
        vm_s, d_s = lag(inputs.vt_pu, state[0], self.t_r_s)
        c = vref + inputs.vs_pu - vm_s
        # rate feedback VF = k VR + vf0 (k != 0: algebraic in VR, one of TF1, TF2 is 0)
        on1, on2 = self.t_f1_s > 0, self.t_f2_s > 0
        k = jnp.where(on1 & ~on2, self.kf / safe(self.t_f1_s),
                      jnp.where(~on1 & on2, self.kf / safe(self.t_f2_s), 0.0))
        vf0 = jnp.where(on1 & ~on2, -k * state[4],
                        jnp.where(~on1 & on2, -k * state[5], jnp.where(on1 & on2, state[5], 0.0)))
        # the filter as VR = clip(alpha VA + beta)
        on_a2, on_a4 = self.t_a2_s > 0, self.t_a4_s > 0
        r = jnp.where(on_a4, self.t_a3_s / safe(self.t_a4_s), 1.0)
        ll_of_state = jnp.where(on_a4, state[3] + r * (state[2] - state[3]), state[2])
        alpha = jnp.where(on_a2, 0.0, r)
        beta = jnp.where(on_a2, ll_of_state, jnp.where(on_a4, (1.0 - r) * state[3], 0.0))
        kp_pi = self.ka * self.t_a1_s
        vr = _clipped_loop(state[1] + kp_pi * (c - vf0), kp_pi * k, alpha, beta,
                           self.vr2_pu, self.vr1_pu, self.vr_min_pu, self.vr_max_pu)
        va, d_i = _pi_nonwindup(c - (k * vr + vf0), state[1], kp_pi, self.ka,
                                self.vr2_pu, self.vr1_pu)
        y2, d_2 = lag(va, state[2], self.t_a2_s)
        _, d_3 = lead_lag(y2, state[3], self.t_a3_s, self.t_a4_s)
        d_f1 = jnp.where(on1, (vr - state[4]) / safe(self.t_f1_s), 0.0)
        d_f2 = jnp.where(on1 & on2, (self.kf * d_f1 - state[5]) / safe(self.t_f2_s),
                         jnp.where(~on1 & on2, (vr - state[5]) / safe(self.t_f2_s), 0.0))
        e0 = jnp.clip(self.vb(inputs) * vr, self.efd_min_pu, self.efd_max_pu)
        on_e = self.t_e_s > 0
        x_e = state[6]
        vx = saturation_product(x_e, self.e1_pu, self.se1, self.e2_pu, self.se2)
        d_e = jnp.where(on_e, (e0 - self.ke * x_e - vx) / safe(self.t_e_s), 0.0)
        efd = jnp.where(on_e, x_e, e0)
        return efd, jnp.stack([d_s, d_i, d_2, d_3, d_f1, d_f2, d_e])

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        vx0 = saturation_product(efd0, self.e1_pu, self.se1, self.e2_pu, self.se2)
        e0 = jnp.where(self.t_e_s > 0, self.ke * efd0 + vx0, efd0)
        vb = self.vb(inputs)
        vr0 = e0 / jnp.where(vb > 0, vb, 1.0)
        x_f2 = jnp.where((self.t_f1_s > 0) | ~(self.t_f2_s > 0), 0.0, vr0)
        return jnp.stack([vt, vr0, vr0, vr0, vr0, x_f2, efd0]), vt

    def vector_field(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[1]

    def efd(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[0]


__all__ = ["ESST1A", "ESST3A", "ESST4B", "EXPIC1", "EXST1"]
