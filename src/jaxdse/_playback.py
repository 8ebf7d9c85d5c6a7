"""Event playback (paper Sec. V, step 2): re-simulate the machine with the estimated a1, a2.

The field voltage is estimated from the observed E'q (paper Sec. V):
Ef = T'd0 dE'q/dt + E'q + (xd - x'd) Id. The 3rd-order model (``_machine``) is then driven
by the measured terminal voltage, Ef and Tm, and its x2, It, Pt and Qt are compared with the
measurements.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._integrate import Integrator, integrate_sampled
from ._machine import Machine, electrical_torque, stator_currents, terminal_dq, terminal_power
from ._signals import smooth_derivative


def estimate_field_voltage(e_q1, i_d, dt, machine: Machine, half_width: int = 0):
    """Ef = T'd0 dE'q/dt + E'q + (xd - x'd) Id [pu] (paper Sec. V, step 2)."""
    return (machine.td01_s * smooth_derivative(e_q1, dt, half_width) + e_q1
            + (machine.xd_pu - machine.xd1_pu) * i_d)


class PlaybackInputs(NamedTuple):
    v_mag: Array
    """Terminal voltage magnitude [pu]."""
    theta: Array
    """Terminal voltage angle, same frame as the rotor angle [rad]."""
    e_f: Array
    """Field voltage [pu]."""
    t_m: Array
    """Mechanical torque [pu]."""


class Playback(eqx.Module):
    """Simulated machine quantities at every sample [machine base]."""

    delta_rad: Float[Array, " T"]
    x2_rad_s: Float[Array, " T"]
    e_q1_pu: Float[Array, " T"]
    i_t_pu: Float[Array, " T"]
    p_t_pu: Float[Array, " T"]
    q_t_pu: Float[Array, " T"]
    solver_ok: Array


def _terminal(delta, e_q1, v_mag, theta, machine):
    v_d, v_q = terminal_dq(v_mag, theta, delta)
    i_d, i_q = stator_currents(e_q1, v_d, v_q, machine)
    return v_d, v_q, i_d, i_q


def _rhs(t, y, u: PlaybackInputs, args):
    a1, a2, machine = args
    delta, x2, e_q1 = y
    _, _, i_d, i_q = _terminal(delta, e_q1, u.v_mag, u.theta, machine)
    t_e = electrical_torque(e_q1, i_d, i_q, machine)
    return jnp.stack([
        x2,
        -a1 * x2 + a2 * (u.t_m - t_e),
        (-e_q1 - (machine.xd_pu - machine.xd1_pu) * i_d + u.e_f) / machine.td01_s,
    ])


def playback(ts, inputs: PlaybackInputs, y0, a1, a2, machine: Machine,
             integ: Integrator = Integrator()) -> Playback:
    """Simulate (delta, x2, E'q) from ``y0`` with parameters a1, a2 under the measured inputs."""
    out = integrate_sampled(_rhs, y0, ts, inputs, (a1, a2, machine), integ)
    delta, x2, e_q1 = out.ys[:, 0], out.ys[:, 1], out.ys[:, 2]
    v_d, v_q, i_d, i_q = _terminal(delta, e_q1, inputs.v_mag, inputs.theta, machine)
    p_t, q_t = terminal_power(v_d, v_q, i_d, i_q)
    return Playback(delta_rad=delta, x2_rad_s=x2, e_q1_pu=e_q1, i_t_pu=jnp.hypot(i_d, i_q),
                    p_t_pu=p_t, q_t_pu=q_t, solver_ok=out.ok)
