"""Governor-turbine models giving the mechanical torque Tm from a speed signal.

The paper uses 50Hertz's in-house power-control governor (its Fig. 2), which is not
published; jaxdse ships the standard PSS/E TGOV1 steam governor-turbine (Siemens PTI,
*PSS/E Model Library*, "TGOV1"; also IEEE PES-TR1, 2013). New models subclass
:class:`AbstractGovernor`.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .fields import as_float, check_nonnegative, check_positive


class AbstractGovernor(eqx.Module):
    """A governor-turbine: states driven by the speed deviation dw [pu] and a torque reference."""

    @abc.abstractmethod
    def steady_state(self, t_ref, dw):
        """State in equilibrium with reference ``t_ref`` [pu] and speed deviation ``dw`` [pu]."""

    @abc.abstractmethod
    def vector_field(self, state, dw, t_ref):
        """d(state)/dt."""

    @abc.abstractmethod
    def torque(self, state, dw):
        """Mechanical torque Tm [pu, machine base]."""

    @abc.abstractmethod
    def reference_from_steady(self, t_m, dw):
        """Torque reference T_ref that holds Tm = ``t_m`` at speed deviation ``dw`` in steady state."""


class TGOV1(AbstractGovernor):
    """PSS/E TGOV1: valve 1/(1 + s T1) with non-windup limits, turbine (1 + s T2)/(1 + s T3), Dt.

    Tm = LL[valve] - Dt dw, valve = clip((T_ref - dw/R) / (1 + s T1), v_min, v_max).
    """

    r_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Permanent droop R [pu speed / pu power]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """Valve time constant T1 [s]."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """Turbine lead time constant T2 [s]."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """Turbine lag (reheater) time constant T3 [s]."""
    dt_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Turbine damping Dt [pu power / pu speed]."""
    v_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.2)
    """Upper valve limit [pu]."""
    v_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Lower valve limit [pu]."""

    def __check_init__(self):
        check_positive(self, "r_pu", "t1_s", "t3_s")
        check_nonnegative(self, "t2_s", "dt_pu")

    def steady_state(self, t_ref, dw):
        valve = jnp.clip(t_ref - dw / self.r_pu, self.v_min_pu, self.v_max_pu)
        return jnp.stack([valve, valve])

    def vector_field(self, state, dw, t_ref):
        valve, lag = state[0], state[1]
        d_valve = (t_ref - dw / self.r_pu - valve) / self.t1_s
        blocked = ((valve >= self.v_max_pu) & (d_valve > 0)) | ((valve <= self.v_min_pu) & (d_valve < 0))
        return jnp.stack([jnp.where(blocked, 0.0, d_valve), (valve - lag) / self.t3_s])

    def torque(self, state, dw):
        valve, lag = state[0], state[1]
        return lag + (self.t2_s / self.t3_s) * (valve - lag) - self.dt_pu * dw

    def reference_from_steady(self, t_m, dw):
        return t_m + (1.0 / self.r_pu + self.dt_pu) * dw
