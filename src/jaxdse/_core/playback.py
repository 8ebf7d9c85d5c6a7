"""Event playback (paper Sec. V, step 2): re-simulate the machine with the estimated a1, a2.

The field voltage is estimated from the observed E'q (paper Sec. V):
Ef = T'd0 dE'q/dt + E'q + (xd - x'd) Id. The 3rd-order model (``machine``) is then driven
by the measured terminal voltage, Ef and Tm, and its x2, It, Pt and Qt are compared with the
measurements.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, Float

from .._models.governors import AbstractGovernor
from .integrate import Integrator, integrate_sampled
from .machine import (
    Machine,
    electrical_torque,
    field_voltage,
    stator_currents,
    swing_acceleration,
    terminal_dq,
    terminal_power,
    transient_emf_rate,
)
from .metrics import smape_terms
from .signals import smooth_derivative


def estimate_field_voltage(e_q1, i_d, dt, machine: Machine, half_width: int = 0, n=None):
    """Ef [pu] from the observed E'q and Id (paper Sec. V, step 2; see ``machine.field_voltage``)."""
    return field_voltage(e_q1, smooth_derivative(e_q1, dt, half_width, n), i_d, machine)


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


class PlaybackSegments(NamedTuple):
    """Per-segment sums of the sMAPE terms of the playback against the measurements."""

    x2: Array
    i_t: Array
    p_t: Array
    q_t: Array


class PlaybackSolution(eqx.Module):
    """What :func:`playback` returns, whatever it keeps."""

    segments: PlaybackSegments
    last: Array
    """State at the last valid sample (the carry of a stream)."""
    ok: Array
    trajectory: Playback | None
    """Every sample's output (``save_trajectory=True``), else None."""


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
        x2, swing_acceleration(x2, t_m, t_e, a1, a2), transient_emf_rate(e_q1, i_d, u.e_f, machine),
    ]), *d_gov])


def playback(ts, inputs: PlaybackInputs, y0, a1, a2, machine: Machine,
             integ: Integrator = Integrator(), gov: AbstractGovernor | None = None, t_ref=None, *,
             measured, n_valid=None, resume=None, block: int = 50,
             save_trajectory: bool = False) -> PlaybackSolution:
    """Simulate (delta, x2, E'q) from ``y0`` with parameters a1, a2 under the measured inputs.

    With a governor ``gov`` (reference ``t_ref``), Tm is integrated alongside from the
    measured speed and ``y0`` continues with the governor state; else ``inputs.t_m`` is used.

    Arguments:
        measured: the measured (x2, I_t, P_t, Q_t) per sample, for the sMAPE sums.
        n_valid, resume, block, save_trajectory: as in :func:`jaxdse.run_observer`.
    """
    args = (a1, a2, machine, gov, t_ref)
    y0, previous = (y0, None) if resume is None else resume

    def summarise(y, u, meas, val):
        sim = _outputs(y, u, machine)
        return PlaybackSegments(*(jnp.sum(jnp.where(val, smape_terms(a, b), 0.0))
                                  for a, b in zip(sim, meas)))

    out = integrate_sampled(_rhs, y0, ts, inputs, args, integ, n_valid=n_valid, previous=previous,
                            reduce=None if save_trajectory else summarise,
                            aux=None if save_trajectory else measured, block=block)
    if not save_trajectory:
        return PlaybackSolution(segments=out.ys, last=out.y_last, ok=out.ok, trajectory=None)
    valid = jnp.arange(ts.shape[0]) < (ts.shape[0] if n_valid is None else n_valid)
    segments = jax.vmap(summarise)(*jtu.tree_map(lambda x: x[:, None], (out.ys, inputs, measured, valid)))
    x2, i_t, p_t, q_t = _outputs(out.ys, inputs, machine)
    trajectory = Playback(delta_rad=out.ys[:, 0], x2_rad_s=x2, e_q1_pu=out.ys[:, 2], i_t_pu=i_t,
                          p_t_pu=p_t, q_t_pu=q_t)
    return PlaybackSolution(segments=segments, last=out.y_last, ok=out.ok, trajectory=trajectory)


def _outputs(y, u: PlaybackInputs, machine):
    """x2, |I_t|, P_t, Q_t of simulated states ``y`` [T, 3+]."""
    delta, x2, e_q1 = y[:, 0], y[:, 1], y[:, 2]
    v_d, v_q, i_d, i_q = _terminal(delta, e_q1, u.v_mag, u.theta, machine)
    p_t, q_t = terminal_power(v_d, v_q, i_d, i_q)
    return x2, jnp.hypot(i_d, i_q), p_t, q_t
