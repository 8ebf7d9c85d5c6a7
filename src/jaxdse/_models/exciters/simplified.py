"""PSS/E SEXS, the simplified excitation system (see :mod:`jaxdse._models.exciters` for the shared conventions)."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..._core.blocks import lead_lag, nonwindup_lag
from ..._core.fields import all_concrete, as_float, check_nonnegative, check_positive, check_that
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

    def efd(self, state, inputs: ExciterInputs):
        return jnp.clip(state[1], self.e_min_pu, self.e_max_pu)


__all__ = ["SEXS"]
