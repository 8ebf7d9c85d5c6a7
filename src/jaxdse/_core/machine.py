"""Third-order flux-decay synchronous machine: parameters and stator algebra.

Model (paper Eq. 1, Sauer & Pai Eq. 5.134-5.137), generator convention, machine base:

    dx1/dt = x2
    dx2/dt = ws/(2H) (Tm - Te - D x2)
    dx3/dt = (-x3 - (xd - x'd) Id + Ef) / T'd0

Stator equations in the rotor (d, q) frame, with (Vd + jVq) e^{j(delta - pi/2)} = V e^{j theta}:

    Vd = xq Iq - Rs Id
    Vq = E'q - Rs Iq - x'd Id

Solving for the currents gives (the paper prints ``+ Rs Vd`` in Id: a sign typo)

    Id = (xq (E'q - Vq) - Rs Vd) / (Rs^2 + x'd xq)
    Iq = (Rs (E'q - Vq) + x'd Vd) / (Rs^2 + x'd xq)

and the air-gap torque Te = Pt + Rs |I|^2 = E'q Iq + (xq - x'd) Id Iq (the paper prints
``E'q Id``: a typo). Torque equals power in pu because speed deviations are neglected.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._base.fields import as_float, check_nonnegative, check_positive, concrete
from .._models.machines import exponential_saturation, saturation, saturation_coefficients


class QAxisCircuits(eqx.Module):
    """The q-axis rotor circuits of a round-rotor machine (PSS/E GENROU, GENTPJ) [machine base].

    The 3rd-order model has none, so its rotor angle is arg(V + (Rs + j xq) I) at every
    instant. A real round-rotor machine has a q-axis field-and-damper pair (transient X'q,
    T'q0; subtransient X''q, T''q0): during a swing the flux they hold lags the q-axis current,
    and that angle is off the rotor angle by arcsin(psi_d / |psi|), with psi_d = E''d -
    (xq - X''q) Iq (zero in steady state without saturation). Given these data (the GENROU
    record of a .dyr), :func:`jaxdse.algebraic_observer` integrates the PSS/E GENROU q-axis
    equations driven by the observed Iq and removes that lag. On GENROU recordings of an
    independent simulator it cuts the rotor-angle error by a factor of 10-100
    (``experiments/andes_bench``).

    Saturation as in GENROU (GENROE: ``exponential``): S(|psi''|) adds S kq psi''q to the q-axis
    field current, kq = (xq - Xl)/(xd - Xl); |psi''| = |V + (Rs + j X'') I| is measured. With
    ``s10 = 0`` there is none (GENTPJ, whose saturation has another form, is used so).
    """

    xq1_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """q-axis transient reactance X'q [pu, machine base]."""
    xq2_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """q-axis subtransient reactance X''q (= X''d in GENROU) [pu, machine base]."""
    xl_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Stator leakage reactance Xl [pu, machine base]."""
    tq01_s: Float[Array, ""] = eqx.field(converter=as_float)
    """q-axis transient open-circuit time constant T'q0 [s]."""
    tq02_s: Float[Array, ""] = eqx.field(converter=as_float)
    """q-axis subtransient open-circuit time constant T''q0 [s]."""
    s10: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.0) of the machine record [pu]."""
    s12: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.2) of the machine record [pu]."""
    exponential: bool = eqx.field(static=True, default=False)
    """The saturation curve: PSS/E's quadratic B (x - A)^2 / x (GENROU) or B x^A (GENROE)."""

    def __check_init__(self):
        check_positive(self, "xq1_pu", "xq2_pu", "tq01_s", "tq02_s")
        check_nonnegative(self, "xl_pu", "s10", "s12")
        # Used as given wherever the equations can be evaluated: they divide by X'q - Xl only.
        # X''q below Xl (shipped cases have it; PSS/E warns and simulates it) or above X'q is
        # odd data, not a reason to drop the circuits (``jaxdse._io.psse.machine_warnings``).
        if concrete(self.xl_pu) and concrete(self.xq1_pu) and not bool(
                np.all(np.asarray(self.xl_pu) != np.asarray(self.xq1_pu))):
            raise ValueError(f"QAxisCircuits must have xq1_pu other than xl_pu (the equations divide "
                             f"by X'q - Xl), got {self.xl_pu}, {self.xq1_pu}")

    def state_space(self, xq):
        """(A, B, c): d[E'd, psi'q]/dt = A x + B Iq and E''d = c . x (PSS/E GENROU, unsaturated)."""
        x1, x2, xl, t1, t2 = self.xq1_pu, self.xq2_pu, self.xl_pu, self.tq01_s, self.tq02_s
        k = (x1 - x2) / (x1 - xl) ** 2
        a = jnp.stack([jnp.stack([(-1.0 - (xq - x1) * k) / t1, (xq - x1) * k / t1]),
                       jnp.stack([1.0 / t2, -1.0 / t2])])
        b = jnp.stack([(xq - x1) * (1.0 - k * (x1 - xl)) / t1, (x1 - xl) / t2])
        c = jnp.stack([(x2 - xl) / (x1 - xl), (x1 - x2) / (x1 - xl)])
        return a, b, c

    def saturation_input(self, xq, xd):
        """B_s: the saturation's term B_s S(|psi''|) E''d in d[E'd, psi'q]/dt (PSS/E GENROU)."""
        kq = (xq - self.xl_pu) / (xd - self.xl_pu)
        return jnp.stack([-kq / self.tq01_s, jnp.zeros_like(kq)])

    def saturation(self, psi2_mag):
        """S(|psi''|) of the record (0 where s10 = 0)."""
        if self.exponential:
            return exponential_saturation(psi2_mag, self.s10, self.s12)
        return saturation(psi2_mag, *saturation_coefficients(self.s10, self.s12))


class Machine(eqx.Module):
    """Synchronous-machine parameters (reactances on the machine base)."""

    xd_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.8)
    """Direct-axis synchronous reactance x_d [pu, machine base]."""
    xd1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """Direct-axis transient reactance x'_d [pu, machine base]."""
    xq_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.7)
    """Quadrature-axis reactance x_q [pu, machine base]."""
    rs_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.003)
    """Stator resistance R_s [pu, machine base]."""
    td01_s: Float[Array, ""] = eqx.field(converter=as_float, default=8.0)
    """Direct-axis transient open-circuit time constant T'_d0 [s]."""
    h_s: Float[Array, ""] = eqx.field(converter=as_float, default=6.18)
    """Inertia constant H [s] (MW s / MVA on the machine base)."""
    d_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """Damping D [pu torque per rad/s of speed deviation x2] (paper Eq. 1)."""
    s_rated_mva: Float[Array, ""] = eqx.field(converter=as_float, default=1100.0)
    """Rated apparent power: the machine base [MVA]."""
    v_rated_kv: Float[Array, ""] = eqx.field(converter=as_float, default=21.0)
    """Rated terminal voltage (phase-to-phase) [kV]; equals the LV-bus voltage base."""
    f_nominal_hz: Float[Array, ""] = eqx.field(converter=as_float, default=50.0)
    """Nominal system frequency [Hz] (50 or 60)."""
    q_axis: QAxisCircuits | None = None
    """q-axis rotor circuits (round-rotor machines); None: the paper's 3rd-order machine."""

    def __check_init__(self):
        check_positive(self, "xd_pu", "xd1_pu", "xq_pu", "td01_s", "h_s", "s_rated_mva",
                       "v_rated_kv", "f_nominal_hz")
        check_nonnegative(self, "rs_pu", "d_pu_s")

    @property
    def omega_s(self) -> Float[Array, ""]:
        """Synchronous speed w_s [rad/s]."""
        return 2.0 * jnp.pi * self.f_nominal_hz

    @property
    def a1(self) -> Float[Array, ""]:
        """a1 = w_s D / (2H) [1/s] (paper Eq. 4)."""
        return self.omega_s * self.d_pu_s / (2.0 * self.h_s)

    @property
    def a2(self) -> Float[Array, ""]:
        """a2 = w_s / (2H) [rad/s^2 per pu torque] (paper Eq. 4)."""
        return self.omega_s / (2.0 * self.h_s)


def swing_acceleration(x2, t_m, t_e, a1, a2):
    """dx2/dt = -a1 x2 + a2 (Tm - Te) [rad/s^2] (paper Eq. 5)."""
    return -a1 * x2 + a2 * (t_m - t_e)


def transient_emf_rate(e_q1, i_d, e_f, m: Machine):
    """dE'q/dt = (-E'q - (xd - x'd) Id + Ef) / T'd0 [pu/s] (paper Eq. 1, third row)."""
    return (-e_q1 - (m.xd_pu - m.xd1_pu) * i_d + e_f) / m.td01_s


def field_voltage(e_q1, de_q1_dt, i_d, m: Machine):
    """Ef = T'd0 dE'q/dt + E'q + (xd - x'd) Id [pu]: :func:`transient_emf_rate` solved for Ef."""
    return m.td01_s * de_q1_dt + e_q1 + (m.xd_pu - m.xd1_pu) * i_d


def inertia_from_a2(a2, omega_s):
    """H [s] from a2 = w_s/(2H)."""
    return omega_s / (2.0 * a2)


def damping_from_a(a1, a2):
    """D [pu torque per rad/s] from a1 = w_s D/(2H) and a2 = w_s/(2H)."""
    return a1 / a2


def terminal_dq(v_mag, theta, delta):
    """Terminal voltage in the rotor frame: Vd = V sin(delta - theta), Vq = V cos(delta - theta)."""
    return v_mag * jnp.sin(delta - theta), v_mag * jnp.cos(delta - theta)


def stator_currents(e_q1, v_d, v_q, m: Machine):
    """(Id, Iq) [pu, machine base] from E'q and the terminal voltage in the rotor frame."""
    det = m.rs_pu**2 + m.xd1_pu * m.xq_pu
    i_d = (m.xq_pu * (e_q1 - v_q) - m.rs_pu * v_d) / det
    i_q = (m.rs_pu * (e_q1 - v_q) + m.xd1_pu * v_d) / det
    return i_d, i_q


def electrical_torque(e_q1, i_d, i_q, m: Machine):
    """Air-gap torque Te = E'q Iq + (xq - x'd) Id Iq [pu, machine base]."""
    return e_q1 * i_q + (m.xq_pu - m.xd1_pu) * i_d * i_q


def terminal_power(v_d, v_q, i_d, i_q):
    """Terminal (P, Q) delivered by the machine [pu, machine base]."""
    return v_d * i_d + v_q * i_q, v_q * i_d - v_d * i_q
