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

from ._governor import AbstractGovernor
from ._integrate import Integrator, integrate_sampled
from ._machine import Machine, electrical_torque, stator_currents, terminal_dq, terminal_power
from ._metrics import smape_terms
from ._signals import smooth_derivative


def estimate_field_voltage(e_q1, i_d, dt, machine: Machine, half_width: int = 0, n=None):
    """Ef = T'd0 dE'q/dt + E'q + (xd - x'd) Id [pu] (paper Sec. V, step 2)."""
    return (machine.td01_s * smooth_derivative(e_q1, dt, half_width, n) + e_q1
            + (machine.xd_pu - machine.xd1_pu) * i_d)


class PlaybackInputs(NamedTuple):
    v_mag: Array
    """Terminal voltage magnitude [pu]."""
    theta: Array
    """Terminal voltage angle, same frame as the rotor angle [rad]."""
    e_f: Array
    """Field voltage [pu]."""
    t_m: Array | None
    """External mechanical torque [pu] (when no governor is given; else None)."""
    dw: Array
    """Measured speed deviation [pu] driving the governor."""


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
    a1, a2, machine, gov, t_ref = args
    delta, x2, e_q1 = y[0], y[1], y[2]
    t_m = u.t_m if gov is None else gov.torque(y[3:], u.dw)
    _, _, i_d, i_q = _terminal(delta, e_q1, u.v_mag, u.theta, machine)
    t_e = electrical_torque(e_q1, i_d, i_q, machine)
    d_gov = [] if gov is None else [gov.vector_field(y[3:], u.dw, t_ref)]
    return jnp.concatenate([jnp.stack([
        x2,
        -a1 * x2 + a2 * (t_m - t_e),
        (-e_q1 - (machine.xd_pu - machine.xd1_pu) * i_d + u.e_f) / machine.td01_s,
    ]), *d_gov])


class PlaybackBlocks(NamedTuple):
    """Per-block sums of the sMAPE terms of the playback (``keep="final"``)."""

    x2: Array
    i_t: Array
    p_t: Array
    q_t: Array


def playback(ts, inputs: PlaybackInputs, y0, a1, a2, machine: Machine,
             integ: Integrator = Integrator(), gov: AbstractGovernor | None = None, t_ref=None, *,
             n_valid=None, resume=None, measured=None,
             block: int = 50) -> Playback | tuple[PlaybackBlocks, Array, Array]:
    """Simulate (delta, x2, E'q) from ``y0`` with parameters a1, a2 under the measured inputs.

    With a governor ``gov`` (reference ``t_ref``), Tm is integrated alongside from the
    measured speed and ``y0`` continues with the governor state; else ``inputs.t_m`` is used.

    ``n_valid`` and ``resume`` (state, previous sample) as in :func:`jaxdse.run_observer`.
    Given ``measured`` = (x2, I_t, P_t, Q_t) per sample, only per-block sums of the sMAPE
    terms are kept and ``(PlaybackBlocks, last state, solver ok)`` is returned.
    """
    args = (a1, a2, machine, gov, t_ref)
    y0, previous = (y0, None) if resume is None else resume
    if measured is not None:
        def reduce(y, u, meas, val):
            sim = _outputs(y, u, machine)
            sums = [jnp.sum(jnp.where(val, smape_terms(a, b), 0.0)) for a, b in zip(sim, meas)]
            return PlaybackBlocks(*sums)

        out = integrate_sampled(_rhs, y0, ts, inputs, args, integ, n_valid=n_valid, previous=previous,
                                reduce=reduce, aux=measured, block=block)
        return out.ys, out.y_last, out.ok
    out = integrate_sampled(_rhs, y0, ts, inputs, args, integ, n_valid=n_valid, previous=previous,
                            block=block)
    x2, i_t, p_t, q_t = _outputs(out.ys, inputs, machine)
    return Playback(delta_rad=out.ys[:, 0], x2_rad_s=x2, e_q1_pu=out.ys[:, 2], i_t_pu=i_t,
                    p_t_pu=p_t, q_t_pu=q_t, solver_ok=out.ok)


def _outputs(y, u: PlaybackInputs, machine):
    """x2, |I_t|, P_t, Q_t of simulated states ``y`` [T, 3]."""
    delta, x2, e_q1 = y[:, 0], y[:, 1], y[:, 2]
    v_d, v_q, i_d, i_q = _terminal(delta, e_q1, u.v_mag, u.theta, machine)
    p_t, q_t = terminal_power(v_d, v_q, i_d, i_q)
    return x2, jnp.hypot(i_d, i_q), p_t, q_t
