"""PSS/E SEXS, the simplified excitation system, and SCRX, the bus- or solid-fed static exciter
(see :mod:`jaxdse._models.exciters` for the shared conventions)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..._base.blocks import lead_lag, nonwindup_lag
from ..._base.fields import all_concrete, as_flag, as_float, check_nonnegative, check_positive, check_that
from ..base import AbstractExciter, ExciterInputs

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

    def efd(self, state, inputs: ExciterInputs, vref):
        return jnp.clip(state[1], self.e_min_pu, self.e_max_pu)


# --- SCRX -------------------------------------------------------------------------------------

def _switch(x):
    """CSWITCH from a .dyr number: 0 or 1 (ValueError otherwise), as an integer leaf."""
    value = float(x)
    if value not in (0.0, 1.0):
        raise ValueError(f"CSWITCH must be 0 or 1, got {x}")
    return as_flag(int(value))


class SCRX(AbstractExciter):
    """PSS/E SCRX, the bus-fed or solid-fed static (SCR bridge) exciter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "SCRX"; OpenIPSL ``SCRX`` and
    PowerSimulationsDynamics.jl ``SCRX``, which agree, for the structure):

        u   = Vref + VOTHSG - EC
        y   = (1 + s TA)/(1 + s TB) u,  TA = (TA/TB)·TB             (lead-lag)
        EX  = K/(1 + s TE) y, non-windup limits [EMIN, EMAX]
        VEX = EX·ET (CSWITCH = 0, bus fed) or EX (CSWITCH = 1, solid fed)
        EFD = VEX, except -rc/rfd·IFD when IFD < 0 and rc/rfd > 0        (negative current)

    8 CONs: TA/TB [-], TB [s], K [pu], TE [s], EMIN, EMAX [pu], CSWITCH (0 or 1), rc/rfd [-]
    (ratio of the field discharge resistance to the field winding resistance; 0: the bridge
    carries negative field current). TB = 0 bypasses the lead-lag; TE = 0 makes the output the
    limited gain K (state kept, zero derivative), so that EFD depends on Vref directly
    (``efd(state, inputs, vref)``). Steady state: EX = EFD0/ET (bus fed) or EFD0, within
    [EMIN, EMAX], with IFD >= 0.

    States: [lead-lag state, EX].
    """

    ta_tb: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """TA/TB: ratio of the lead to the lag time constant [-]."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """TB: lag time constant of the lead-lag [s] (0: pass-through)."""
    k: Float[Array, ""] = eqx.field(converter=as_float, default=200.0)
    """K: gain [pu/pu] (> 0)."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TE: time constant of the gain block [s] (0: limited gain K)."""
    e_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """EMIN: lower limit of EX [pu]."""
    e_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """EMAX: upper limit of EX [pu]."""
    cswitch: Int[Array, ""] = eqx.field(converter=_switch, default=0)
    """CSWITCH: 0 bus fed (EX times the terminal voltage), 1 solid fed."""
    rc_rfd: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """rc/rfd: field discharge to field winding resistance ratio [-] (0: negative current)."""

    def __check_init__(self):
        check_positive(self, "k")
        check_nonnegative(self, "ta_tb", "t_b_s", "t_e_s", "rc_rfd")
        if all_concrete(self.e_max_pu, self.e_min_pu):
            check_that(self, self.e_max_pu >= self.e_min_pu,
                       f"EMAX ({self.e_max_pu}) must be >= EMIN ({self.e_min_pu})")

    @property
    def n_states(self) -> int:
        return 2

    def _source(self, inputs: ExciterInputs):
        return jnp.where(self.cswitch == 0, inputs.vt_pu, jnp.ones_like(inputs.vt_pu))

    def initial_state(self, efd0, inputs: ExciterInputs):
        efd0 = jnp.asarray(efd0, float)
        vt = jnp.asarray(inputs.vt_pu, float)
        src = self._source(inputs)
        ex0 = efd0 / jnp.where(src != 0, src, 1.0)
        u0 = ex0 / self.k
        return jnp.stack([u0, ex0]), vt + u0

    def _chain(self, state, inputs: ExciterInputs, vref):
        u = vref + inputs.vs_pu - inputs.vt_pu
        y, d_ll = lead_lag(u, state[0], self.ta_tb * self.t_b_s, self.t_b_s)
        ex, d_e = nonwindup_lag(y, state[1], self.t_e_s, self.e_min_pu, self.e_max_pu, gain=self.k)
        crowbar = (self.rc_rfd > 0) & (inputs.ifd_pu < 0)
        efd = jnp.where(crowbar, -self.rc_rfd * inputs.ifd_pu, ex * self._source(inputs))
        return efd, jnp.stack([d_ll, d_e])

    def vector_field(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[1]

    def efd(self, state, inputs: ExciterInputs, vref):
        return self._chain(state, inputs, vref)[0]


__all__ = ["SCRX", "SEXS"]
