"""Algebraic observer for the rotor angle x1 and E'q = x3 (paper Lemma 1, derived afresh).

From the stator equations (see ``_machine``), with I = (Id + j Iq) e^{j(delta - pi/2)}:

    psi := (Rs + j xq) I + V = (E'q + (xq - x'd) Id) e^{j delta}

so delta = arg psi and E'q = |psi| - (xq - x'd) Id, for any Rs >= 0 and xq != x'd.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .machine import Machine, electrical_torque
from .signals import unwrap_continuing
from .xla import hoist


class AlgebraicStates(eqx.Module):
    """Observer output at every sample [machine base]."""

    delta_rad: Float[Array, " T"]
    """Rotor angle x1 in the nominal-frequency frame [rad], continuous."""
    e_q1_pu: Float[Array, " T"]
    """Quadrature-axis transient voltage E'q = x3 [pu]."""
    i_d_pu: Float[Array, " T"]
    i_q_pu: Float[Array, " T"]
    t_e_pu: Float[Array, " T"]
    """Air-gap torque Te [pu]."""


def algebraic_observer(v_t, i_t, theta_ref, machine: Machine, rel0=None) -> AlgebraicStates:
    """States from terminal phasors expressed in a frame rotated by ``theta_ref``.

    ``v_t`` and ``i_t`` [pu, machine base] are the terminal phasors multiplied by
    e^{-j theta_ref}; ``theta_ref`` [rad] is any continuous angle (jaxdse uses the measured
    voltage angle), so large angles never pass through ``arg`` and need no unwrapping.
    ``rel0``: when a stream continues, the angle delta - theta_ref at the first sample as the
    previous chunk unwrapped it (keeps the unwrapping continuous).
    """
    z_q, x_diff = hoist(machine.rs_pu + 1j * machine.xq_pu, machine.xq_pu - machine.xd1_pu)
    psi = z_q * i_t + v_t
    rel = unwrap_continuing(jnp.angle(psi), rel0)
    # Id + j Iq = j I e^{-j delta} with e^{j delta} = psi / |psi|: no trigonometry needed.
    psi_mag = jnp.sqrt(jnp.real(psi) ** 2 + jnp.imag(psi) ** 2)
    dq = 1j * i_t * jnp.conj(psi) * (1.0 / jnp.where(psi_mag > 0, psi_mag, 1.0))
    i_d, i_q = jnp.real(dq), jnp.imag(dq)
    e_q1 = psi_mag - x_diff * i_d
    return AlgebraicStates(
        delta_rad=theta_ref + rel,
        e_q1_pu=e_q1,
        i_d_pu=i_d,
        i_q_pu=i_q,
        t_e_pu=electrical_torque(e_q1, i_d, i_q, machine),
    )
