"""PSS/E synchronous machine models GENROU, GENSAL, GENCLS, GENROE, GENSAE and GENTPJ driven by
an imposed terminal voltage.

Sources: Siemens PTI, *PSS(R)E Model Library*, "GENROU", "GENSAL", "GENCLS", "GENROE",
"GENSAE", "GENTPJ" block diagrams; the equations as written out in the BSD-licensed OpenIPSL
library (``OpenIPSL.Electrical.Machines.PSSE``), which is validated against PSS/E.

Conventions (machine base, network frame rotating at nominal speed):

* Park: ``v_d + j v_q = V e^{-j(delta - pi/2)}``, the rotor angle ``delta`` is the q-axis angle;
  the current ``I`` flows out of the machine.
* stator: ``v_d = -psi_q - Ra i_d``, ``v_q = psi_d - Ra i_q`` with ``psi_d = psi''_d - X'' i_d``,
  ``psi_q = -psi''_q - X'' i_q`` (X''_q = X''_d); speed voltages are taken at nominal speed, as
  PSS/E does for these models.
* swing: ``2H d(omega)/dt = Tm - Te - D (omega - 1)``, ``d(delta)/dt = omega_s (omega - 1)``; Tm is the
  mechanical torque [pu] (the governors' output), Te = psi_d i_q - psi_q i_d.
* saturation: PSS/E's quadratic ``S(x) = B (x - A)^2 / x`` (x > A) through S(1.0) and S(1.2), on
  |psi''| for GENROU (both axes, the q axis scaled by (Xq - Xl)/(Xd - Xl)) and on E'q for GENSAL;
  the exponential ``S(x) = B x^A`` through the same points for GENROE (as GENROU) and GENSAE
  (on |psi''|, both axes); GENTPJ's on the air-gap flux plus Kis |I| (see :class:`GENTPJ`).
"""

from __future__ import annotations

import abc
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .._base.fields import as_float, check_nonnegative, check_positive, concrete
from .base import record_message


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

    Records are used as given wherever the equations can be evaluated: X'd, X'q and Xd other
    than Xl (the denominators), time constants and X''d > 0. The usual order Xl < X''d < X'd
    <= Xd, X''d < X'q <= Xq is not required: PSS/E warns about records outside it (shipped
    cases have X''d below Xl) and simulates them, and so does this model.

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
            ok = ((self.xd1_pu != self.xl_pu) & (self.xq1_pu != self.xl_pu) & (self.xd_pu != self.xl_pu))
            _check_order(self, ok, "needs X'd, X'q and Xd other than Xl (the equations divide by "
                         "X'd - Xl, X'q - Xl and Xd - Xl)")

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

    def _saturation(self, x):
        """S(x): PSS/E's quadratic saturation through S(1.0) and S(1.2)."""
        a, b = saturation_coefficients(self.s10, self.s12)
        return saturation(x, a, b)

    def _sat(self, psi2d, psi2q):
        return self._saturation(jnp.sqrt(psi2d ** 2 + psi2q ** 2))

    def steady_state(self, v_re, v_im, i_re, i_im) -> MachineSteady:
        ra, x2, xl = self.ra_pu, self.x2_pu, self.xl_pu
        _, _, _, _, kq = self._k()
        # |psi''| is frame-free: V + (Ra + jX'') I; the q axis in steady state is then linear.
        sat = self._saturation(jnp.hypot(v_re + ra * i_re - x2 * i_im, v_im + ra * i_im + x2 * i_re))
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
    of E'q on the d axis only (PSS/E Model Library, GENSAL). As :class:`GENROU`, records are used
    as given where the equations can be evaluated (X'd other than Xl).

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
            _check_order(self, self.xd1_pu != self.xl_pu,
                         "needs X'd other than Xl (the equations divide by X'd - Xl)")

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


def exponential_saturation(x, s10, s12):
    """PSS/E's exponential saturation S(x) = B x^A through S(1.0) = s10 and S(1.2) = s12:
    B = s10, A = ln(s12/s10)/ln(1.2). 0 where s10 <= 0 or s12 <= 0 (no saturation data).

    ``x`` is floored at 1e-6 inside the power so that value and gradient stay finite at 0."""
    on = (s10 > 0) & (s12 > 0)
    a = jnp.log(jnp.where(on, s12, 1.0) / jnp.where(on, s10, 1.0)) / jnp.log(1.2)
    xs = jnp.maximum(x, 1e-6)
    return jnp.where(on, s10 * jnp.exp(a * jnp.log(xs)), 0.0)


class GENROE(GENROU):
    """PSS/E GENROE: GENROU with exponential saturation (PSS/E Model Library, GENROE).

    The same round-rotor equations, states and saturation input as :class:`GENROU` (|psi''| on
    both axes, the q axis scaled by (Xq - Xl)/(Xd - Xl)); the saturation function is
    S(psi'') = B psi''^A through S(1.0) and S(1.2) (:func:`exponential_saturation`) instead
    of the quadratic one. With S(1.0) = 0 (or S(1.2) = 0) it is GENROU unsaturated. The same
    structure in OpenIPSL ``GENROE`` (BSD-3, validated against PSS/E).

    States: E'q, psi_kd, E'd, psi_kq, delta, omega (machine base pu, seconds).
    """

    def _saturation(self, x):
        return exponential_saturation(x, self.s10, self.s12)


class GENSAE(AbstractMachine):
    """PSS/E GENSAE: salient pole, two d-axis and one q-axis rotor circuit, exponential
    saturation (PSS/E Model Library, GENSAE).

    GENSAL's circuits (:class:`GENSAL`), but the saturation S(|psi''|) = B |psi''|^A
    (:func:`exponential_saturation`) is a function of the subtransient flux magnitude, as
    GENROE's, and acts on both axes: d axis ``LadIfd += S psi''_d``; q axis
    ``T''qo dpsi''_q/dt = -psi''_q + (Xq - X'') i_q - (Xq - Xl)/(Xd - Xl) S psi''_q``. (The
    same formulation in OpenIPSL ``GENSAE``, validated against PSS/E; GENSAL saturates
    E'q on the d axis only.) As :class:`GENSAL`, records are used as given where the
    equations can be evaluated (X'd and Xd other than Xl).

    States: E'q, psi_kd, psi''q, delta, omega (machine base pu, seconds).
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
            ok = (self.xd1_pu != self.xl_pu) & (self.xd_pu != self.xl_pu)
            _check_order(self, ok, "needs X'd and Xd other than Xl (the equations divide by "
                         "X'd - Xl and Xd - Xl)")

    @property
    def n_states(self) -> int:
        return 5

    def _k(self):
        xl, x2 = self.xl_pu, self.x2_pu
        k3d = (x2 - xl) / (self.xd1_pu - xl)
        k1d = (self.xd1_pu - x2) * (self.xd_pu - self.xd1_pu) / (self.xd1_pu - xl) ** 2
        kq = (self.xq_pu - xl) / (self.xd_pu - xl)
        return k1d, k3d, kq

    def _saturation(self, x):
        return exponential_saturation(x, self.s10, self.s12)

    def steady_state(self, v_re, v_im, i_re, i_im) -> MachineSteady:
        ra, x2, xl = self.ra_pu, self.x2_pu, self.xl_pu
        _, _, kq = self._k()
        sat = self._saturation(jnp.hypot(v_re + ra * i_re - x2 * i_im, v_im + ra * i_im + x2 * i_re))
        xq_sat = x2 + (self.xq_pu - x2) / (1.0 + kq * sat)
        delta = jnp.arctan2(v_im + ra * i_im + xq_sat * i_re, v_re + ra * i_re - xq_sat * i_im)
        vd, vq = to_dq(v_re, v_im, delta)
        i_d, i_q = to_dq(i_re, i_im, delta)
        psi2d = vq + ra * i_q + x2 * i_d
        psi2q = vd + ra * i_d - x2 * i_q
        e1q = psi2d + (self.xd1_pu - x2) * i_d
        psi_kd = e1q - (self.xd1_pu - xl) * i_d
        efd = e1q + (self.xd_pu - self.xd1_pu) * i_d + sat * psi2d
        te = (psi2d - x2 * i_d) * i_q + (psi2q + x2 * i_q) * i_d
        return MachineSteady(jnp.stack([e1q, psi_kd, psi2q, delta, jnp.ones_like(delta)]), efd, te)

    def _fluxes(self, state):
        _, k3d, _ = self._k()
        return k3d * state[0] + (1.0 - k3d) * state[1], state[2]

    def terminal(self, state, v_re, v_im) -> Terminal:
        ra, x2 = self.ra_pu, self.x2_pu
        e1q, psi_kd, delta = state[0], state[1], state[3]
        k1d, _, _ = self._k()
        psi2d, psi2q = self._fluxes(state)
        i_d, i_q, te = _stator(psi2d, psi2q, *to_dq(v_re, v_im, delta), ra, x2)
        sat = self._saturation(jnp.hypot(psi2d, psi2q))
        ifd = (k1d * (e1q - psi_kd - (self.xd1_pu - self.xl_pu) * i_d) + e1q
               + (self.xd_pu - self.xd1_pu) * i_d + sat * psi2d)
        i_re, i_im = from_dq(i_d, i_q, delta)
        p, q = _powers(v_re, v_im, i_re, i_im)
        return Terminal(i_re, i_im, p, q, te, ifd)

    def flux_field(self, state, v_re, v_im, out: Terminal, efd):
        e1q, psi_kd, delta = state[0], state[1], state[3]
        i_d, i_q = to_dq(out.i_re_pu, out.i_im_pu, delta)
        _, _, kq = self._k()
        psi2d, psi2q = self._fluxes(state)
        sat = self._saturation(jnp.hypot(psi2d, psi2q))
        return jnp.stack([
            (efd - out.ifd_pu) / self.td0_1_s,
            (e1q - psi_kd - (self.xd1_pu - self.xl_pu) * i_d) / self.td0_2_s,
            (-psi2q * (1.0 + kq * sat) + (self.xq_pu - self.x2_pu) * i_q) / self.tq0_2_s,
        ])


GENTPJ_NEWTON_STEPS = 4
"""GENTPJ: Newton steps on the saturation S (after one fixed-point step) that resolve the
algebraic loop currents -> air-gap flux -> S -> saturated X'' -> currents."""


class GENTPJ(AbstractMachine):
    """WECC's GENTPJ (PSS/E Model Library, "GENTPJ"; WECC type J generator): a round-rotor
    machine whose saturation scales the rotor-circuit equations and the subtransient
    reactances, driven by the air-gap flux plus Kis times the stator current.

    Saturation (PSS/E quadratic S through S(1.0), S(1.2), :func:`saturation_coefficients`)::

        psi_ag = |V + (Ra + j Xl) I|               (air-gap flux, the voltage behind Xl)
        S      = S(psi_ag + Kis |I|)
        Sat_d  = 1 + S,   Sat_q = 1 + (Xq/Xd) S
        X''d_sat = (X''d - Xl)/Sat_d + Xl,   X''q_sat = (X''d - Xl)/Sat_q + Xl

    Rotor (states E'q, E'd, psi''d, psi''q; stator psi_d = psi''d - X''d_sat i_d, psi_q =
    -psi''q - X''q_sat i_q, v_d = -psi_q - Ra i_d, v_q = psi_d - Ra i_q)::

        T'do  dE'q/dt   = Efd - LadIfd,  LadIfd = Sat_d [E'q + (Xd - X'd)(E'q - psi''d)/(X'd - X''d)]
        T'qo  dE'd/dt   = -Sat_q [E'd + (Xq - X'q)(E'd - psi''q)/(X'q - X''d)]
        T''do dpsi''d/dt = Sat_d (E'q - psi''d) - (X'd - X''d) i_d
        T''qo dpsi''q/dt = Sat_q (E'd - psi''q) + (X'q - X''d) i_q

    This is the formulation of OpenIPSL ``GENTPJ`` (validated against PSS/E and PowerWorld),
    re-derived in jaxdse's sign convention (psi''q here is -PSIppq there). With Kis = 0 it
    is GENTPF. The saturation depends on the currents, which depend on the saturated X'':
    the algebraic loop is solved in :meth:`terminal` by one fixed-point step and
    ``GENTPJ_NEWTON_STEPS`` Newton steps on S (unrolled, vmappable; differentiated through
    the last step only, by the implicit function theorem). The
    PSS/E record has one X''d (X''q = X''d); Kis may be omitted (0). Records are used as
    given where the equations can be evaluated (X'd and X'q other than X''d).

    States: E'q, E'd, psi''d, psi''q, delta, omega (machine base pu, seconds).
    """

    td0_1_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T'do [s]."""
    td0_2_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T''do [s]."""
    tq0_1_s: Float[Array, ""] = eqx.field(converter=as_float)
    """T'qo [s]."""
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
    xq1_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """X'q [pu]."""
    x2_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """X''d = X''q (unsaturated) [pu]."""
    xl_pu: Float[Array, ""] = eqx.field(converter=as_float)
    """Leakage reactance Xl [pu]."""
    s10: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.0) [pu]."""
    s12: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Saturation S(1.2) [pu]."""
    kis: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kis: stator-current multiplier of the saturation input [pu flux / pu current]."""
    ra_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Armature resistance Ra [pu]."""
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * jnp.pi * 60.0)
    """Nominal electrical angular speed [rad/s]."""

    def __check_init__(self):
        check_positive(self, "td0_1_s", "td0_2_s", "tq0_1_s", "tq0_2_s", "h_s", "xd_pu", "xq_pu",
                       "xd1_pu", "xq1_pu", "x2_pu", "omega_s_rad_s")
        check_nonnegative(self, "xl_pu", "s10", "s12", "ra_pu", "kis")
        if concrete(self.xd1_pu) and concrete(self.x2_pu) and concrete(self.xq1_pu):
            ok = (self.xd1_pu != self.x2_pu) & (self.xq1_pu != self.x2_pu)
            _check_order(self, ok, "needs X'd and X'q other than X''d (the equations divide by "
                         "X'd - X''d and X'q - X''d)")

    @property
    def n_states(self) -> int:
        return 6

    def _s(self, psi_ag, i_mag):
        a, b = saturation_coefficients(self.s10, self.s12)
        return saturation(psi_ag + self.kis * i_mag, a, b)

    def _sats(self, s):
        """(Sat_d, Sat_q, X''d_sat, X''q_sat) for the saturation S."""
        sat_d, sat_q = 1.0 + s, 1.0 + (self.xq_pu / self.xd_pu) * s
        x2l = self.x2_pu - self.xl_pu
        return sat_d, sat_q, x2l / sat_d + self.xl_pu, x2l / sat_q + self.xl_pu

    def _currents(self, s, psi2d, psi2q, vd, vq):
        """(i_d, i_q, psi_ag) behind the saturated X'' for saturation S = s."""
        ra, xl = self.ra_pu, self.xl_pu
        _, _, xds, xqs = self._sats(s)
        a, b = vd - psi2q, vq - psi2d
        det = ra ** 2 + xds * xqs
        i_d = (-ra * a - xqs * b) / det
        i_q = (xds * a - ra * b) / det
        psi_ag = jnp.hypot(vq + ra * i_q + xl * i_d, vd + ra * i_d - xl * i_q)
        return i_d, i_q, psi_ag

    def _solve_saturation(self, psi2d, psi2q, vd, vq):
        def residual(s):
            i_d, i_q, psi_ag = self._currents(s, psi2d, psi2q, vd, vq)
            return s - self._s(psi_ag, jnp.hypot(i_d, i_q))

        def newton(s):
            r, dr = jax.jvp(residual, (s,), (jnp.ones_like(s),))
            return s - r / jnp.where(jnp.abs(dr) > 1e-3, dr, 1.0), r, dr

        s = jnp.zeros_like(psi2d)
        s = s - residual(s)                                   # one fixed-point step
        for _ in range(GENTPJ_NEWTON_STEPS - 1):
            s = newton(s)[0]
        # derivatives by the implicit function theorem: the iterations are constants to
        # autodiff and the last Newton step carries ds = -dr/(dr/ds) (a small program to
        # differentiate; the value is that of one more Newton step)
        s = jax.lax.stop_gradient(s)
        r, dr = jax.jvp(residual, (s,), (jnp.ones_like(s),))
        return s - r / jax.lax.stop_gradient(jnp.where(jnp.abs(dr) > 1e-3, dr, 1.0))

    def steady_state(self, v_re, v_im, i_re, i_im) -> MachineSteady:
        ra, xl = self.ra_pu, self.xl_pu
        # the air-gap flux and |I| are frame-free: S, Sat_d, Sat_q and the X''_sat follow directly
        psi_ag = jnp.hypot(v_re + ra * i_re - xl * i_im, v_im + ra * i_im + xl * i_re)
        s = self._s(psi_ag, jnp.hypot(i_re, i_im))
        sat_d, sat_q, xds, xqs = self._sats(s)
        xq_eff = xl + (self.xq_pu - xl) / sat_q          # steady q-axis reactance
        delta = jnp.arctan2(v_im + ra * i_im + xq_eff * i_re, v_re + ra * i_re - xq_eff * i_im)
        vd, vq = to_dq(v_re, v_im, delta)
        i_d, i_q = to_dq(i_re, i_im, delta)
        psi2d = vq + ra * i_q + xds * i_d
        psi2q = vd + ra * i_d - xqs * i_q
        e1q = psi2d + (self.xd1_pu - self.x2_pu) * i_d / sat_d
        e1d = psi2q - (self.xq1_pu - self.x2_pu) * i_q / sat_q
        efd = sat_d * e1q + (self.xd_pu - self.xd1_pu) * i_d
        te = (psi2d - xds * i_d) * i_q + (psi2q + xqs * i_q) * i_d
        state = jnp.stack([e1q, e1d, psi2d, psi2q, delta, jnp.ones_like(delta)])
        return MachineSteady(state, efd, te)

    def _ifd(self, e1q, psi2d, sat_d):
        return sat_d * (e1q + (self.xd_pu - self.xd1_pu) * (e1q - psi2d) / (self.xd1_pu - self.x2_pu))

    def terminal(self, state, v_re, v_im) -> Terminal:
        e1q, psi2d, psi2q, delta = state[0], state[2], state[3], state[4]
        vd, vq = to_dq(v_re, v_im, delta)
        s = self._solve_saturation(psi2d, psi2q, vd, vq)
        sat_d, _, xds, xqs = self._sats(s)
        i_d, i_q, _ = self._currents(s, psi2d, psi2q, vd, vq)
        te = (psi2d - xds * i_d) * i_q + (psi2q + xqs * i_q) * i_d
        i_re, i_im = from_dq(i_d, i_q, delta)
        p, q = _powers(v_re, v_im, i_re, i_im)
        return Terminal(i_re, i_im, p, q, te, self._ifd(e1q, psi2d, sat_d))

    def flux_field(self, state, v_re, v_im, out: Terminal, efd):
        e1q, e1d, psi2d, psi2q, delta = state[0], state[1], state[2], state[3], state[4]
        ra, xl, x2 = self.ra_pu, self.xl_pu, self.x2_pu
        i_re, i_im = out.i_re_pu, out.i_im_pu
        psi_ag = jnp.hypot(v_re + ra * i_re - xl * i_im, v_im + ra * i_im + xl * i_re)
        sat_d, sat_q, _, _ = self._sats(self._s(psi_ag, jnp.hypot(i_re, i_im)))
        i_d, i_q = to_dq(i_re, i_im, delta)
        ed1 = e1d + (self.xq_pu - self.xq1_pu) * (e1d - psi2q) / (self.xq1_pu - x2)
        return jnp.stack([
            (efd - out.ifd_pu) / self.td0_1_s,
            -sat_q * ed1 / self.tq0_1_s,
            (sat_d * (e1q - psi2d) - (self.xd1_pu - x2) * i_d) / self.td0_2_s,
            (sat_q * (e1d - psi2q) + (self.xq1_pu - x2) * i_q) / self.tq0_2_s,
        ])


MACHINES = {"GENROU": GENROU, "GENSAL": GENSAL, "GENCLS": GENCLS, "GENROE": GENROE,
            "GENSAE": GENSAE, "GENTPJ": GENTPJ}


MACHINE_PARAMETERS = {
    "td0_1_s": "T'do", "td0_2_s": "T''do", "tq0_1_s": "T'qo", "tq0_2_s": "T''qo", "h_s": "H",
    "d_pu": "D", "xd_pu": "Xd", "xq_pu": "Xq", "xd1_pu": "X'd", "xq1_pu": "X'q", "x2_pu": "X''d",
    "xl_pu": "Xl", "s10": "S(1.0)", "s12": "S(1.2)", "kis": "Kis", "ra_pu": "ZSORCE R (.raw)",
    "x1_pu": "ZSORCE X (.raw)", "omega_s_rad_s": "BASFRQ (.raw)"}
"""Field of the machine modules -> the PSS/E constant (or .raw value) it takes, for messages."""


def machine_from_dyr(model: str, params: dict, *, ra_pu: float = 0.0, x_source_pu: float | None = None,
                     f_nominal_hz: float = 60.0) -> AbstractMachine:
    """The machine module of a GENROU, GENSAL, GENCLS, GENROE, GENSAE or GENTPJ record
    (``params``: PSS/E names, as :class:`jaxdse.DyrRecord` holds them; GENTPJ's Kis may be
    absent: 0); ``ra_pu``, ``x_source_pu``: the .raw ZSORCE. Invalid values raise a one-line
    ``ValueError`` naming the PSS/E constants (``GENROU: T'do must be > 0, got -1.0``)."""
    w = 2 * jnp.pi * f_nominal_hz
    p = params
    if model == "GENCLS":
        if x_source_pu is None or not x_source_pu > 0:
            raise ValueError("GENCLS needs the source reactance ZSORCE X > 0 from the .raw")
        return _from_record(GENCLS, model, h_s=p["H"], d_pu=p["D"], x1_pu=x_source_pu, ra_pu=ra_pu,
                            omega_s_rad_s=w)
    if model not in MACHINES:
        raise ValueError(f"{model} is not a supported machine model ({', '.join(MACHINES)})")
    common = dict(td0_1_s=p["T'do"], td0_2_s=p["T''do"], tq0_2_s=p["T''qo"], h_s=p["H"], d_pu=p["D"],
                  xd_pu=p["Xd"], xq_pu=p["Xq"], xd1_pu=p["X'd"], x2_pu=p["X''d"], xl_pu=p["Xl"],
                  s10=p["S(1.0)"], s12=p["S(1.2)"], ra_pu=ra_pu, omega_s_rad_s=w)
    if model in ("GENROU", "GENROE", "GENTPJ"):     # round rotor: a q-axis transient circuit too
        extra = {"kis": p.get("Kis", 0.0)} if model == "GENTPJ" else {}
        return _from_record(MACHINES[model], model, tq0_1_s=p["T'qo"], xq1_pu=p["X'q"], **common, **extra)
    return _from_record(MACHINES[model], model, **common)    # salient pole: GENSAL, GENSAE


def _from_record(cls, model: str, **kwargs):
    try:
        return cls(**kwargs)
    except ValueError as err:
        raise ValueError(record_message(str(err), model, MACHINE_PARAMETERS)) from None


__all__ = ["GENCLS", "GENROE", "GENROU", "GENSAE", "GENSAL", "GENTPJ", "MACHINES", "MACHINE_PARAMETERS",
           "AbstractMachine",
           "MachineSteady", "Terminal", "exponential_saturation", "from_dq", "machine_from_dyr",
           "saturation", "saturation_coefficients", "to_dq"]
