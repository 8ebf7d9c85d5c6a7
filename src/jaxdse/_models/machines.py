"""PSS/E synchronous machine models GENROU, GENSAL and GENCLS driven by an imposed terminal voltage.

Sources: Siemens PTI, *PSS(R)E Model Library*, "GENROU", "GENSAL", "GENCLS" block diagrams;
the equations as written out in the BSD-licensed OpenIPSL library
(``OpenIPSL.Electrical.Machines.PSSE``), which is validated against PSS/E.

Conventions (machine base, network frame rotating at nominal speed):

* Park: ``v_d + j v_q = V e^{-j(delta - pi/2)}``, the rotor angle ``delta`` is the q-axis angle;
  the current ``I`` flows out of the machine.
* stator: ``v_d = -psi_q - Ra i_d``, ``v_q = psi_d - Ra i_q`` with ``psi_d = psi''_d - X'' i_d``,
  ``psi_q = -psi''_q - X'' i_q`` (X''_q = X''_d); speed voltages are taken at nominal speed, as
  PSS/E does for these models.
* swing: ``2H d(omega)/dt = Tm - Te - D (omega - 1)``, ``d(delta)/dt = omega_s (omega - 1)``; Tm is the
  mechanical torque [pu] (the governors' output), Te = psi_d i_q - psi_q i_d.
* saturation: PSS/E's quadratic ``S(x) = B (x - A)^2 / x`` (x > A) through S(1.0) and S(1.2), on
  |psi''| for GENROU (both axes, the q axis scaled by (Xq - Xl)/(Xd - Xl)) and on E'q for GENSAL.
"""

from __future__ import annotations

import abc
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._core.fields import as_float, check_nonnegative, check_positive, concrete


class Terminal(NamedTuple):
    """The machine's electrical outputs at one instant (machine base, network frame)."""

    i_re_pu: Array
    i_im_pu: Array
    p_pu: Array
    """Active power out of the terminal [pu]."""
    q_pu: Array
    """Reactive power out of the terminal [pu]."""
    te_pu: Array
    """Air-gap torque [pu]."""
    ifd_pu: Array
    """Field current LadIfd [pu, non-reciprocal: Efd = LadIfd in unsaturated steady state]."""


class MachineSteady(NamedTuple):
    """A machine's steady state at an operating point, and what holds it there."""

    state: Array
    efd_pu: Array
    """Field voltage that holds the state [pu]."""
    tm_pu: Array
    """Mechanical torque that holds the speed [pu]."""


def saturation_coefficients(s10, s12):
    """(A, B) of PSS/E's quadratic saturation through S(1.0) = s10 and S(1.2) = s12.

    ``S(x) = B (x - A)^2 / x`` for ``x > A``; ``B = 0`` (no saturation) where s10 <= 0 or the two
    points do not define a quadratic (s12 * 1.2 <= s10).
    """
    on = (s10 > 0) & (1.2 * s12 > s10)
    a = jnp.sqrt(jnp.where(on, 1.2 * s12 / jnp.where(on, s10, 1.0), 4.0))
    big_a = (1.2 - a) / (1.0 - a)
    big_b = jnp.where(on, s10 / (1.0 - big_a) ** 2, 0.0)
    return jnp.where(on, big_a, 0.0), big_b


def saturation(x, big_a, big_b):
    """PSS/E quadratic saturation S(x) = B (x - A)^2 / x, 0 for x <= A."""
    xs = jnp.where(x > big_a, x, big_a + 1.0)
    return jnp.where(x > big_a, big_b * (xs - big_a) ** 2 / jnp.where(xs > 0, xs, 1.0), 0.0)


def to_dq(re, im, delta):
    """Network-frame phasor -> (d, q) components: d + j q = X e^{-j(delta - pi/2)}."""
    s, c = jnp.sin(delta), jnp.cos(delta)
    return re * s - im * c, re * c + im * s


def from_dq(d, q, delta):
    """(d, q) components -> network-frame phasor (re, im)."""
    s, c = jnp.sin(delta), jnp.cos(delta)
    return d * s + q * c, -d * c + q * s


class AbstractMachine(eqx.Module):
    """A synchronous machine whose last two states are (delta [rad], omega [pu]); subclasses
    have the fields ``h_s``, ``d_pu`` and ``omega_s_rad_s``."""

    @property
    @abc.abstractmethod
    def n_states(self) -> int:
        """Length of the state vector, rotor angle and speed last."""

    @abc.abstractmethod
    def steady_state(self, v_re, v_im, i_re, i_im) -> MachineSteady:
        """The steady state that delivers current ``I`` at terminal voltage ``V``."""

    @abc.abstractmethod
    def terminal(self, state, v_re, v_im) -> Terminal:
        """Currents, powers, torque and field current at terminal voltage ``V``."""

    @abc.abstractmethod
    def flux_field(self, state, v_re, v_im, out: Terminal, efd):
        """Derivatives of the flux states (all states but delta and omega)."""

    def vector_field(self, state, v_re, v_im, efd, tm):
        """d(state)/dt at terminal voltage V, field voltage ``efd`` and mechanical torque ``tm``."""
        out = self.terminal(state, v_re, v_im)
        omega = state[-1]
        d_omega = (tm - out.te_pu - self.d_pu * (omega - 1.0)) / (2.0 * self.h_s)
        d_delta = self.omega_s_rad_s * (omega - 1.0)
        return jnp.concatenate([self.flux_field(state, v_re, v_im, out, efd),
                                jnp.stack([d_delta, d_omega])])


def _powers(v_re, v_im, i_re, i_im):
    return v_re * i_re + v_im * i_im, v_im * i_re - v_re * i_im


def _stator(psi2d, psi2q, vd, vq, ra, x2):
    """(i_d, i_q, Te) behind the subtransient flux: (psi''_q + j psi''_d) - (vd + j vq) =
    (Ra + jX'') (id + j iq); Te = psi_d i_q - psi_q i_d."""
    ed, eq = psi2q - vd, psi2d - vq
    den = ra ** 2 + x2 ** 2
    i_d = (ra * ed + x2 * eq) / den
    i_q = (ra * eq - x2 * ed) / den
    return i_d, i_q, (psi2d - x2 * i_d) * i_q + (psi2q + x2 * i_q) * i_d


def _check_order(module, ok, message):
    if all(concrete(v) for v in (ok,)) and not bool(jnp.all(ok)):
        raise ValueError(f"{type(module).__name__}: {message}")


class GENROU(AbstractMachine):
    """PSS/E GENROU: round rotor, two d-axis and two q-axis rotor circuits, quadratic saturation
    on the subtransient flux on both axes (PSS/E Model Library, GENROU).

    States: E'q, psi_kd, E'd, psi_kq, delta, omega.
    """

    td0_1_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T'do: d-axis transient open-circuit time constant [s]."""
    td0_2_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T''do: d-axis subtransient open-circuit time constant [s]."""
    tq0_1_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T'qo: q-axis transient open-circuit time constant [s]."""
    tq0_2_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T''qo: q-axis subtransient open-circuit time constant [s]."""
    h_s: Float[Array, ""] = eqx.field(converter=as_float)
    """Inertia constant H [MW s / MVA]."""
    d_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Damping D [pu torque / pu speed]."""
    xd_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Xd [pu]."""
    xq_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Xq [pu]."""
    xd1_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """X'd [pu]."""
    xq1_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """X'q [pu]."""
    x2_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """X''d = X''q [pu]."""
    xl_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Leakage reactance Xl [pu]."""
    s10: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.0) [pu]."""
    s12: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.2) [pu]."""
    ra_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Armature resistance Ra [pu] (the .raw ZSORCE's R)."""
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * jnp.pi * 60.0)
    """Nominal electrical angular speed [rad/s]."""

    def __check_init__(self):
        check_positive(self, "td0_1_s", "td0_2_s", "tq0_1_s", "tq0_2_s", "h_s", "xd_pu", "xq_pu",
                       "xd1_pu", "xq1_pu", "x2_pu", "omega_s_rad_s")
        check_nonnegative(self, "xl_pu", "s10", "s12", "ra_pu")
        if concrete(self.xd_pu) and concrete(self.xl_pu):
            ok = ((self.xl_pu < self.x2_pu) & (self.x2_pu < self.xd1_pu) & (self.xd1_pu <= self.xd_pu)
                  & (self.x2_pu < self.xq1_pu) & (self.xq1_pu <= self.xq_pu))
            _check_order(self, ok, "needs Xl < X''d < X'd <= Xd and X''d < X'q <= Xq")

    @property
    def n_states(self) -> int:
        return 6

    def _k(self):
        xl, x2 = self.xl_pu, self.x2_pu
        k3d = (x2 - xl) / (self.xd1_pu - xl)
        k3q = (x2 - xl) / (self.xq1_pu - xl)
        k1d = (self.xd1_pu - x2) * (self.xd_pu - self.xd1_pu) / (self.xd1_pu - xl) ** 2
        k1q = (self.xq1_pu - x2) * (self.xq_pu - self.xq1_pu) / (self.xq1_pu - xl) ** 2
        kq = (self.xq_pu - xl) / (self.xd_pu - xl)
        return k1d, k3d, k1q, k3q, kq

    def _sat(self, psi2d, psi2q):
        a, b = saturation_coefficients(self.s10, self.s12)
        return saturation(jnp.sqrt(psi2d ** 2 + psi2q ** 2), a, b)

    def steady_state(self, v_re, v_im, i_re, i_im) -> MachineSteady:
        ra, x2, xl = self.ra_pu, self.x2_pu, self.xl_pu
        _, _, _, _, kq = self._k()
        # |psi''| is frame-free: V + (Ra + jX'') I; the q axis in steady state is then linear.
        a, b = saturation_coefficients(self.s10, self.s12)
        sat = saturation(jnp.hypot(v_re + ra * i_re - x2 * i_im, v_im + ra * i_im + x2 * i_re), a, b)
        xq_sat = x2 + (self.xq_pu - x2) / (1.0 + sat * kq)
        delta = jnp.arctan2(v_im + ra * i_im + xq_sat * i_re, v_re + ra * i_re - xq_sat * i_im)
        vd, vq = to_dq(v_re, v_im, delta)
        i_d, i_q = to_dq(i_re, i_im, delta)
        psi2d = vq + ra * i_q + x2 * i_d
        psi2q = vd + ra * i_d - x2 * i_q
        e1q = psi2d + (self.xd1_pu - x2) * i_d
        psi_kd = e1q - (self.xd1_pu - xl) * i_d
        e1d = psi2q - (self.xq1_pu - x2) * i_q
        psi_kq = e1d + (self.xq1_pu - xl) * i_q
        efd = e1q + (self.xd_pu - self.xd1_pu) * i_d + sat * psi2d
        te = (psi2d - x2 * i_d) * i_q + (psi2q + x2 * i_q) * i_d
        state = jnp.stack([e1q, psi_kd, e1d, psi_kq, delta, jnp.ones_like(delta)])
        return MachineSteady(state, efd, te)

    def _fluxes(self, state):
        e1q, psi_kd, e1d, psi_kq = state[0], state[1], state[2], state[3]
        _, k3d, _, k3q, _ = self._k()
        psi2d = k3d * e1q + (1.0 - k3d) * psi_kd
        psi2q = k3q * e1d + (1.0 - k3q) * psi_kq
        return psi2d, psi2q

    def terminal(self, state, v_re, v_im) -> Terminal:
        ra, x2 = self.ra_pu, self.x2_pu
        delta = state[4]
        psi2d, psi2q = self._fluxes(state)
        i_d, i_q, te = _stator(psi2d, psi2q, *to_dq(v_re, v_im, delta), ra, x2)
        e1q, psi_kd = state[0], state[1]
        k1d, _, _, _, _ = self._k()
        sat = self._sat(psi2d, psi2q)
        ifd = (k1d * (e1q - psi_kd - (self.xd1_pu - self.xl_pu) * i_d) + e1q
               + (self.xd_pu - self.xd1_pu) * i_d + sat * psi2d)
        i_re, i_im = from_dq(i_d, i_q, delta)
        p, q = _powers(v_re, v_im, i_re, i_im)
        return Terminal(i_re, i_im, p, q, te, ifd)

    def flux_field(self, state, v_re, v_im, out: Terminal, efd):
        e1q, psi_kd, e1d, psi_kq, delta = state[0], state[1], state[2], state[3], state[4]
        i_d, i_q = to_dq(out.i_re_pu, out.i_im_pu, delta)
        _, _, k1q, _, kq = self._k()
        psi2d, psi2q = self._fluxes(state)
        sat = self._sat(psi2d, psi2q)
        xl = self.xl_pu
        xaq_ilq = (k1q * (e1d - psi_kq + (self.xq1_pu - xl) * i_q) + e1d
                   - (self.xq_pu - self.xq1_pu) * i_q + sat * kq * psi2q)
        return jnp.stack([
            (efd - out.ifd_pu) / self.td0_1_s,
            (e1q - psi_kd - (self.xd1_pu - xl) * i_d) / self.td0_2_s,
            -xaq_ilq / self.tq0_1_s,
            (e1d - psi_kq + (self.xq1_pu - xl) * i_q) / self.tq0_2_s,
        ])


class GENSAL(AbstractMachine):
    """PSS/E GENSAL: salient pole, two d-axis and one q-axis rotor circuit, quadratic saturation
    of E'q on the d axis only (PSS/E Model Library, GENSAL).

    States: E'q, psi_kd, psi''q, delta, omega.
    """

    td0_1_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T'do [s]."""
    td0_2_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T''do [s]."""
    tq0_2_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T''qo [s]."""
    h_s: Float[Array, ""] = eqx.field(converter=as_float)
    """Inertia constant H [MW s / MVA]."""
    d_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Damping D [pu torque / pu speed]."""
    xd_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Xd [pu]."""
    xq_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Xq [pu]."""
    xd1_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """X'd [pu]."""
    x2_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """X''d = X''q [pu]."""
    xl_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Leakage reactance Xl [pu]."""
    s10: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.0) [pu]."""
    s12: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.2) [pu]."""
    ra_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Armature resistance Ra [pu]."""
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * jnp.pi * 60.0)
    """Nominal electrical angular speed [rad/s]."""

    def __check_init__(self):
        check_positive(self, "td0_1_s", "td0_2_s", "tq0_2_s", "h_s", "xd_pu", "xq_pu", "xd1_pu",
                       "x2_pu", "omega_s_rad_s")
        check_nonnegative(self, "xl_pu", "s10", "s12", "ra_pu")
        if concrete(self.xd_pu) and concrete(self.xl_pu):
            ok = ((self.xl_pu < self.x2_pu) & (self.x2_pu < self.xd1_pu) & (self.xd1_pu <= self.xd_pu)
                  & (self.x2_pu < self.xq_pu))
            _check_order(self, ok, "needs Xl < X''d < X'd <= Xd and X''d < Xq")

    @property
    def n_states(self) -> int:
        return 5

    def _k(self):
        xl, x2 = self.xl_pu, self.x2_pu
        k3d = (x2 - xl) / (self.xd1_pu - xl)
        k1d = (self.xd1_pu - x2) * (self.xd_pu - self.xd1_pu) / (self.xd1_pu - xl) ** 2
        return k1d, k3d

    def _sat(self, e1q):
        a, b = saturation_coefficients(self.s10, self.s12)
        return saturation(e1q, a, b)

    def steady_state(self, v_re, v_im, i_re, i_im) -> MachineSteady:
        ra, x2, xl = self.ra_pu, self.x2_pu, self.xl_pu
        delta = jnp.arctan2(v_im + ra * i_im + self.xq_pu * i_re, v_re + ra * i_re - self.xq_pu * i_im)
        vd, vq = to_dq(v_re, v_im, delta)
        i_d, i_q = to_dq(i_re, i_im, delta)
        psi2d = vq + ra * i_q + x2 * i_d
        psi2q = vd + ra * i_d - x2 * i_q
        e1q = psi2d + (self.xd1_pu - x2) * i_d
        psi_kd = e1q - (self.xd1_pu - xl) * i_d
        efd = e1q * (1.0 + self._sat(e1q)) + (self.xd_pu - self.xd1_pu) * i_d
        te = (psi2d - x2 * i_d) * i_q + (psi2q + x2 * i_q) * i_d
        return MachineSteady(jnp.stack([e1q, psi_kd, psi2q, delta, jnp.ones_like(delta)]), efd, te)

    def terminal(self, state, v_re, v_im) -> Terminal:
        ra, x2 = self.ra_pu, self.x2_pu
        e1q, psi_kd, psi2q, delta = state[0], state[1], state[2], state[3]
        k1d, k3d = self._k()
        psi2d = k3d * e1q + (1.0 - k3d) * psi_kd
        i_d, i_q, te = _stator(psi2d, psi2q, *to_dq(v_re, v_im, delta), ra, x2)
        ifd = (k1d * (e1q - psi_kd - (self.xd1_pu - self.xl_pu) * i_d)
               + (self.xd_pu - self.xd1_pu) * i_d + (1.0 + self._sat(e1q)) * e1q)
        i_re, i_im = from_dq(i_d, i_q, delta)
        p, q = _powers(v_re, v_im, i_re, i_im)
        return Terminal(i_re, i_im, p, q, te, ifd)

    def flux_field(self, state, v_re, v_im, out: Terminal, efd):
        e1q, psi_kd, psi2q, delta = state[0], state[1], state[2], state[3]
        i_d, i_q = to_dq(out.i_re_pu, out.i_im_pu, delta)
        return jnp.stack([
            (efd - out.ifd_pu) / self.td0_1_s,
            (e1q - psi_kd - (self.xd1_pu - self.xl_pu) * i_d) / self.td0_2_s,
            (-psi2q + (self.xq_pu - self.x2_pu) * i_q) / self.tq0_2_s,
        ])


class GENCLS(AbstractMachine):
    """PSS/E GENCLS: constant voltage E' behind X'd (the .raw ZSORCE), swing equation only
    (PSS/E Model Library, GENCLS). States: E'q (constant), delta, omega."""

    h_s: Float[Array, ""] = eqx.field(converter=as_float)
    """Inertia constant H [MW s / MVA]."""
    d_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Damping D [pu torque / pu speed]."""
    x1_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Source reactance X'd [pu] (ZSORCE X)."""
    ra_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Source resistance [pu] (ZSORCE R)."""
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * jnp.pi * 60.0)
    """Nominal electrical angular speed [rad/s]."""

    def __check_init__(self):
        check_positive(self, "h_s", "x1_pu", "omega_s_rad_s")
        check_nonnegative(self, "ra_pu")

    @property
    def n_states(self) -> int:
        return 3

    def steady_state(self, v_re, v_im, i_re, i_im) -> MachineSteady:
        e_re = v_re + self.ra_pu * i_re - self.x1_pu * i_im
        e_im = v_im + self.ra_pu * i_im + self.x1_pu * i_re
        delta = jnp.arctan2(e_im, e_re)
        e = jnp.hypot(e_re, e_im)
        p, _ = _powers(v_re, v_im, i_re, i_im)
        te = p + self.ra_pu * (i_re ** 2 + i_im ** 2)
        return MachineSteady(jnp.stack([e, delta, jnp.ones_like(delta)]), e, te)

    def terminal(self, state, v_re, v_im) -> Terminal:
        e, delta = state[0], state[1]
        e_re, e_im = e * jnp.cos(delta), e * jnp.sin(delta)
        den = self.ra_pu ** 2 + self.x1_pu ** 2
        dr, di = e_re - v_re, e_im - v_im
        i_re = (self.ra_pu * dr + self.x1_pu * di) / den
        i_im = (self.ra_pu * di - self.x1_pu * dr) / den
        p, q = _powers(v_re, v_im, i_re, i_im)
        te = e_re * i_re + e_im * i_im
        return Terminal(i_re, i_im, p, q, te, e)

    def flux_field(self, state, v_re, v_im, out: Terminal, efd):
        return jnp.zeros((1,), dtype=state.dtype)


MACHINES = {"GENROU": GENROU, "GENSAL": GENSAL, "GENCLS": GENCLS}


def machine_from_dyr(model: str, params: dict, *, ra_pu: float = 0.0, x_source_pu: float | None = None,
                     f_nominal_hz: float = 60.0) -> AbstractMachine:
    """The machine module of a GENROU, GENSAL or GENCLS record (``params``: PSS/E names, as
    :class:`jaxdse.DyrRecord` holds them); ``ra_pu``, ``x_source_pu``: the .raw ZSORCE."""
    w = 2 * jnp.pi * f_nominal_hz
    p = params
    if model == "GENROU":
        return GENROU(td0_1_s=p["T'do"], td0_2_s=p["T''do"], tq0_1_s=p["T'qo"], tq0_2_s=p["T''qo"],
                      h_s=p["H"], d_pu=p["D"], xd_pu=p["Xd"], xq_pu=p["Xq"], xd1_pu=p["X'd"],
                      xq1_pu=p["X'q"], x2_pu=p["X''d"], xl_pu=p["Xl"], s10=p["S(1.0)"],
                      s12=p["S(1.2)"], ra_pu=ra_pu, omega_s_rad_s=w)
    if model == "GENSAL":
        return GENSAL(td0_1_s=p["T'do"], td0_2_s=p["T''do"], tq0_2_s=p["T''qo"], h_s=p["H"],
                      d_pu=p["D"], xd_pu=p["Xd"], xq_pu=p["Xq"], xd1_pu=p["X'd"], x2_pu=p["X''d"],
                      xl_pu=p["Xl"], s10=p["S(1.0)"], s12=p["S(1.2)"], ra_pu=ra_pu, omega_s_rad_s=w)
    if model == "GENCLS":
        if x_source_pu is None or not x_source_pu > 0:
            raise ValueError("GENCLS needs the source reactance ZSORCE X > 0 from the .raw")
        return GENCLS(h_s=p["H"], d_pu=p["D"], x1_pu=x_source_pu, ra_pu=ra_pu, omega_s_rad_s=w)
    raise ValueError(f"{model} is not a supported machine model ({', '.join(MACHINES)})")


__all__ = ["GENCLS", "GENROU", "GENSAL", "MACHINES", "AbstractMachine", "MachineSteady", "Terminal",
           "from_dq", "machine_from_dyr", "saturation", "saturation_coefficients", "to_dq"]
