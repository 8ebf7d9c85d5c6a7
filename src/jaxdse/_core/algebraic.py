"""Algebraic observer for the rotor angle x1 and E'q = x3 (paper Lemma 1, derived afresh).

From the stator equations (see ``machine``), with I = (Id + j Iq) e^{j(delta - pi/2)}:

    psi := (Rs + j xq) I + V = (E'q + (xq - x'd) Id) e^{j delta}

so delta = arg psi and E'q = |psi| - (xq - x'd) Id, for any Rs >= 0 and xq != x'd.

A round-rotor machine with q-axis rotor circuits (``Machine.q_axis``) adds a d-axis component
psi_d = E''d - (xq - X''q) Iq to psi during a swing, so that delta = arg psi +
arcsin(psi_d / |psi|). E''d comes from the PSS/E GENROU q-axis equations, linear in their two
states and driven by Iq and by the saturation's S(|psi''|) E''d; they are integrated exactly
between samples (matrix exponential, inputs linear in time), starting from equilibrium. A
sample's Iq depends on its own angle correction: the two are solved together in closed form.
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
                       q_state0=None, q_disc=None, switched=None) -> AlgebraicStates:
    """States from terminal phasors expressed in a frame rotated by ``theta_ref``.

    ``v_t`` and ``i_t`` [pu, machine base] are the terminal phasors multiplied by
    e^{-j theta_ref}; ``theta_ref`` [rad] is any continuous angle (jaxdse uses the measured
    voltage angle), so large angles never pass through ``arg`` and need no unwrapping.
    ``rel0``: when a stream continues, the angle delta - theta_ref at the first sample as the
    previous chunk unwrapped it (keeps the unwrapping continuous). ``dt`` [s] (the sample
    interval) and ``q_state0`` (the carried q-axis state) are used with ``machine.q_axis``;
    ``q_disc``: its :func:`q_axis_discretisation` at ``dt`` where already computed (a stream's
    chunks share it). ``switched`` (per sample interval): a switching between the two samples
    (see :func:`q_axis_lag`).
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
        corr, q_state = q_axis_lag(dq, psi_mag, machine.q_axis, machine.xq_pu, machine.xd_pu, dt,
                                   q_state0, disc=q_disc, switched=switched)
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
    """(Phi, G0, G1, G0s, G1s) of the q-axis circuits of ``machine`` (``Machine.q_axis``) over
    a step ``dt``: Iq's and the saturation term's hold (:func:`q_axis_lag`)."""
    return _discretisation(machine.q_axis, machine.xq_pu, machine.xd_pu, dt)


def _discretisation(q: QAxisCircuits, xq, xd, dt):
    a, b, _ = q.state_space(xq)
    phi, g0, g1 = hold_discretisation(a, b, dt)
    _, g0s, g1s = hold_discretisation(a, q.saturation_input(xq, xd), dt)
    return phi, g0, g1, g0s, g1s


def _corrected(alpha, slope, k_dq, k_psi, ref):
    """(corr, Iq) with |psi| sin(corr) = alpha + slope Iq and Iq = Im(dq e^{-j corr}): linear in
    sin and cos of corr, so in closed form; of its two roots the one nearest ``ref``."""
    i_d, i_q = jnp.real(k_dq), jnp.imag(k_dq)
    big_a, big_b = k_psi + slope * i_d, -slope * i_q
    phase = jnp.arctan2(big_b, big_a)
    root = jnp.arcsin(jnp.clip(alpha / jnp.hypot(big_a, big_b), -1.0, 1.0))
    roots = jnp.angle(jnp.exp(1j * jnp.stack([root - phase, jnp.pi - root - phase])))
    corr = roots[jnp.argmin(jnp.abs(roots - ref))]
    return corr, i_q * jnp.cos(corr) - i_d * jnp.sin(corr)


def q_axis_lag(dq, psi_mag, q: QAxisCircuits, xq, xd, dt, state0=None, disc=None, switched=None):
    """The angle delta - arg psi [rad] per sample, and the q-axis states [E'd, psi'q, Iq].

    ``dq`` = Id + j Iq in the frame of psi. The states x move exactly between samples for
    inputs linear in time (first-order hold): Iq and u = S(|psi''|) E''d, E''d = c . x. At a
    sample, x = r + g1 Iq + g1s S u with u = c . x, and psi_d = |psi| sin(corr) = c . x -
    (xq - X''q) Iq, with Iq = Im(dq e^{-j corr}) depending on corr itself: linear in sin and
    cos of corr, so solved in closed form (the root nearest the previous sample's).
    ``disc``: :func:`q_axis_discretisation`'s tuple over ``dt`` where already computed.
    ``switched`` (per sample interval, True where the network switched between the two
    samples): the inputs hold their new values over that interval, as simulators record a
    switching (the sample at its instant shows the values before it); a ramp there would
    leave the angle off by several mrad for a few T''q0.
    """
    a, b, c = q.state_space(xq)
    bs = q.saturation_input(xq, xd)
    phi, g0, g1, g0s, g1s = _discretisation(q, xq, xd, dt) if disc is None else disc
    gap = xq - q.xq2_pu
    # |psi''| = |V + (Rs + j X'') I| = |psi - (xq - X''q) dq| in the frame of psi (frame-free)
    sat = q.saturation(jnp.abs(psi_mag - gap * dq))

    def step(carry, k_in):
        x_prev, iq_prev, s_prev, corr_prev = carry
        k_dq, k_psi, k_sat, k_switched = k_in
        held = k_switched.astype(x_prev.dtype)       # 1: the new values over the interval
        h0, h1 = g0 * (1.0 - held), g1 + g0 * held
        h0s, h1s = g0s * (1.0 - held), g1s + g0s * held
        r = phi @ x_prev + h0 * iq_prev + h0s * (s_prev * (c @ x_prev))
        den = 1.0 - k_sat * (c @ h1s)
        alpha, kappa = (c @ r) / den, (c @ h1) / den     # c . x = alpha + kappa Iq
        corr, iq = _corrected(alpha, kappa - gap, k_dq, k_psi, corr_prev)
        x = r + h1 * iq + h1s * (k_sat * (alpha + kappa * iq))
        return (x, iq, k_sat, corr), (corr, jnp.concatenate([x, iq[None]]))

    if state0 is None:  # equilibrium at the first sample: x = per_iq Iq
        per_iq = -solve_2x2(a + jnp.outer(bs, c) * sat[0], b)
        corr0, iq0 = _corrected(0.0, c @ per_iq - gap, dq[0], psi_mag[0], 0.0)
        first = jnp.concatenate([per_iq * iq0, iq0[None]])
    else:
        first = state0
        corr0 = jnp.arcsin(jnp.clip((c @ state0[:2] - gap * state0[2]) / psi_mag[0], -1.0, 1.0))
    if switched is None:
        switched = jnp.zeros(dq.shape[0] - 1, dtype=bool)
    _, (corr, states) = jax.lax.scan(step, (first[:2], first[2], sat[0], corr0),
                                     (dq[1:], psi_mag[1:], sat[1:], switched))
    return (jnp.concatenate([corr0[None], corr]), jnp.concatenate([first[None], states]))
