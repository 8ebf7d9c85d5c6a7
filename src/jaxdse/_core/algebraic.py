"""Algebraic observer for the rotor angle x1 and E'q = x3 (paper Lemma 1, derived afresh).

From the stator equations (see ``machine``), with I = (Id + j Iq) e^{j(delta - pi/2)}:

    psi := (Rs + j xq) I + V = (E'q + (xq - x'd) Id) e^{j delta}

so delta = arg psi and E'q = |psi| - (xq - x'd) Id, for any Rs >= 0 and xq != x'd.

A round-rotor machine with q-axis rotor circuits (``Machine.q_axis``) adds a d-axis component
psi_d = E''d - (xq - X''q) Iq to psi during a swing, so that delta = arg psi +
arcsin(psi_d / |psi|). E''d comes from the PSS/E GENROU q-axis equations, linear in their two
states and driven by Iq; they are integrated exactly between samples (matrix exponential,
input linear in time), starting from equilibrium.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .lti import hold_discretisation, solve_2x2
from .machine import Machine, QAxisCircuits, electrical_torque
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
    q_state: Float[Array, "T 3"] | None = None
    """q-axis rotor states [E'd, psi'q] and Iq per sample (``Machine.q_axis`` only): what a
    stream carries from chunk to chunk."""


def algebraic_observer(v_t, i_t, theta_ref, machine: Machine, rel0=None, dt=None,
                       q_state0=None, q_disc=None) -> AlgebraicStates:
    """States from terminal phasors expressed in a frame rotated by ``theta_ref``.

    ``v_t`` and ``i_t`` [pu, machine base] are the terminal phasors multiplied by
    e^{-j theta_ref}; ``theta_ref`` [rad] is any continuous angle (jaxdse uses the measured
    voltage angle), so large angles never pass through ``arg`` and need no unwrapping.
    ``rel0``: when a stream continues, the angle delta - theta_ref at the first sample as the
    previous chunk unwrapped it (keeps the unwrapping continuous). ``dt`` [s] (the sample
    interval) and ``q_state0`` (the carried q-axis state) are used with ``machine.q_axis``;
    ``q_disc``: its :func:`q_axis_discretisation` at ``dt`` where already computed (a stream's
    chunks share it).
    """
    z_q, x_diff = hoist(machine.rs_pu + 1j * machine.xq_pu, machine.xq_pu - machine.xd1_pu)
    psi = z_q * i_t + v_t
    rel = unwrap_continuing(jnp.angle(psi), rel0)
    # Id + j Iq = j I e^{-j delta} with e^{j delta} = psi / |psi|: no trigonometry needed.
    psi_mag = jnp.sqrt(jnp.real(psi) ** 2 + jnp.imag(psi) ** 2)
    dq = 1j * i_t * jnp.conj(psi) * (1.0 / jnp.where(psi_mag > 0, psi_mag, 1.0))
    i_d, i_q = jnp.real(dq), jnp.imag(dq)
    e_q1 = psi_mag - x_diff * i_d
    q_state = None
    if machine.q_axis is not None:
        corr, q_state = q_axis_lag(dq, psi_mag, machine.q_axis, machine.xq_pu, dt, q_state0, disc=q_disc)
        rel = rel + corr
    return AlgebraicStates(
        delta_rad=theta_ref + rel,
        e_q1_pu=e_q1,
        i_d_pu=i_d,
        i_q_pu=i_q,
        t_e_pu=electrical_torque(e_q1, i_d, i_q, machine),
        q_state=q_state,
    )


def q_axis_discretisation(machine: Machine, dt):
    """(Phi, G0, G1) of the q-axis circuits of ``machine`` (``Machine.q_axis``) over a step ``dt``."""
    a, b, _ = machine.q_axis.state_space(machine.xq_pu)
    return hold_discretisation(a, b, dt)


def q_axis_lag(dq, psi_mag, q: QAxisCircuits, xq, dt, state0=None, iterations: int = 2, disc=None):
    """The angle delta - arg psi [rad] per sample, and the q-axis states [E'd, psi'q, Iq].

    ``dq`` = Id + j Iq in the frame of psi. The states move exactly between samples for an Iq
    linear in time (first-order hold); the Iq of a sample depends on its own correction, found
    by ``iterations`` fixed-point steps (the correction is small: one step is within 1e-6 rad).
    ``disc``: (Phi, G0, G1) over ``dt`` where already computed (:func:`q_axis_discretisation`).
    """
    a, b, c = q.state_space(xq)
    phi, g0, g1 = hold_discretisation(a, b, dt) if disc is None else disc
    gap = xq - q.xq2_pu

    def corrected(x_prev, iq_prev, k_dq, k_psi, corr):
        iq = jnp.imag(k_dq * jnp.exp(-1j * corr))
        x = phi @ x_prev + g0 * iq_prev + g1 * iq
        psi_d = c @ x - gap * iq
        return jnp.arcsin(jnp.clip(psi_d / k_psi, -1.0, 1.0)), x, iq

    def step(carry, k_in):
        x_prev, iq_prev, corr = carry
        for _ in range(iterations):
            corr, x, iq = corrected(x_prev, iq_prev, *k_in, corr)
        return (x, iq, corr), (corr, jnp.concatenate([x, iq[None]]))

    if state0 is None:  # equilibrium at the first sample: psi_d = 0, no correction
        iq0 = jnp.imag(dq[0])
        x0 = -solve_2x2(a, b * iq0)
        first = jnp.concatenate([x0, iq0[None]])
        corr0 = jnp.zeros((), dtype=psi_mag.dtype)
    else:
        first = state0
        corr0 = jnp.arcsin(jnp.clip((c @ state0[:2] - gap * state0[2]) / psi_mag[0], -1.0, 1.0))
    _, (corr, states) = jax.lax.scan(step, (first[:2], first[2], corr0), (dq[1:], psi_mag[1:]))
    return (jnp.concatenate([corr0[None], corr]), jnp.concatenate([first[None], states]))
