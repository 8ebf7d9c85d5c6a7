"""The front end: every configuration-independent, per-sample stage before the observer.

recording -> mapping to the terminal (paper Eqs. 8-13) -> algebraic observer (Lemma 1) ->
measured speed deviation (Remark 2) -> torque reference T_ref (Sec. IV-A) and the inputs of
the event playback. Also the sums over samples that the flags need.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._models.governors import AbstractGovernor
from .algebraic import AlgebraicStates, algebraic_observer
from .mapping import map_to_terminal
from .plant import Plant
from .playback import PlaybackInputs, estimate_field_voltage
from .recording import Recording
from .settings import Settings
from .signals import (
    angle_jumps,
    bridge,
    frequency_from_angle,
    jumps,
    measured_speed_deviation,
    unwrap_continuing,
)

PHASE_JUMP_RATIO, PHASE_JUMP_FACTOR = 4.0, 10.0
"""A jump of the measured voltage phasor (:func:`~jaxdse._core.signals.jumps`: over this many
times the curvature around it and times the median second difference) is a switching."""
PHASE_JUMP_GUARD = 2
"""Samples on each side of a switching over which the frequency channel is bridged."""


class StreamContext(NamedTuple):
    """What a chunk of a stream needs from the samples before it (see ``_many.stream``)."""

    p_lv_sum: Array
    """Sum of P_LV over all samples before the chunk (running mean of the auxiliary load)."""
    p_lv_count: Array
    theta_ref0: Array
    """Unwrapped voltage angle at the chunk's first sample, as the previous chunk had it."""
    rel0: Array
    """Unwrapped delta - theta_ref at the first sample."""
    theta_t0: Array
    """Unwrapped terminal-voltage angle at the first sample."""
    q_state0: Array | None = None
    """q-axis rotor states at the first sample (``Machine.q_axis`` only)."""
    theta_jump0: Array | float = 0.0
    """The voltage angle's switching jumps before the first sample, summed [rad]."""


class FrontEnd(NamedTuple):
    """The configuration-independent, per-sample part of the pipeline."""

    n: Array
    """Valid samples."""
    valid: Array
    theta_ref: Array
    """Unwrapped measured voltage angle: the frame of every phasor below [rad]."""
    theta_t: Array
    """Terminal voltage angle in the nominal frame [rad]."""
    v_t: Array
    """Terminal voltage in the theta_ref frame [pu, machine base = system base voltage]."""
    i_t: Array
    """Terminal current in the theta_ref frame [pu, machine base]."""
    p_lv: Array
    alg: AlgebraicStates
    x2_meas: Array
    """Measured speed deviation [rad/s] (paper Remark 2)."""
    f_hz: Array
    """Frequency of the measured bus [Hz]: the channel, or derived from its voltage angle;
    bridged across switchings."""
    theta_smooth: Array
    """theta_ref less its jumps at switchings [rad]: the angle whose rate 2 pi (f - f0) is."""
    dw: Array
    """x2_meas / w_s [pu], the governor input."""


def front_end(recording: Recording, plant: Plant, settings: Settings = Settings(),
              context: StreamContext | None = None, q_disc=None) -> FrontEnd:
    """Mapping to the terminal, algebraic observer and measured speed, for every sample
    (``q_disc``: :func:`~jaxdse._core.algebraic.q_axis_discretisation` at the recording's
    step, where a stream has it already)."""
    if not jax.config.jax_enable_x64:  # every entry point (estimate, identify, replay) passes here
        raise RuntimeError("jaxdse computes in float64 (a 600 s recording's time axis and the "
                           "angle differences lose digits in float32): call "
                           "jax.config.update('jax_enable_x64', True) first")
    m = plant.machine
    ts = recording.t_s
    dt = ts[1] - ts[0]
    hw = settings.derivative_half_width
    n = ts.shape[0] if recording.n_samples is None else recording.n_samples
    ctx = context or StreamContext(0.0, 0, None, None, None)

    # Work in the frame of the measured voltage angle: no large angle ever enters arg().
    theta_ref = unwrap_continuing(recording.v_ang_rad, ctx.theta_ref0)
    v_meas = recording.v_mag_pu + 0j
    # Materialised once (a barrier): XLA would otherwise recompute its sin and cos in each of
    # the fused loops of the mapping below.
    i_meas = jax.lax.optimization_barrier(
        recording.i_mag_pu * jnp.exp(1j * (recording.i_ang_rad - theta_ref)))
    mapped = map_to_terminal(v_meas, i_meas, plant.line, plant.transformer, plant.aux,
                             recording.location, ctx.p_lv_sum, ctx.p_lv_count)
    i_t = mapped.i_sg * plant.current_scale
    # Switchings: jumps of the measured voltage phasor. The rotor angle stays continuous, but
    # the bus angle jumps and a PMU's frequency spikes (a ramp in Remark 2's two terms, whose
    # areas need not cancel): x2 takes the angle less its jumps and the bridged channel. The
    # observer's q-axis circuits hold the new values over such an interval.
    switched = jumps(recording.v_mag_pu * jnp.exp(1j * theta_ref), PHASE_JUMP_RATIO, PHASE_JUMP_FACTOR, n)
    switched = switched & (jnp.arange(switched.shape[0]) < n - 1)
    theta_smooth = theta_ref - ctx.theta_jump0 - angle_jumps(theta_ref, switched)
    alg = algebraic_observer(mapped.v_t, i_t, theta_ref, m, ctx.rel0, dt, ctx.q_state0, q_disc, switched)
    f_hz = frequency_from_angle(theta_smooth, dt, m.f_nominal_hz, hw, n)
    if recording.f_hz is not None:  # the channel where it has a value, else the derived one
        f_hz = bridge(jnp.where(jnp.isnan(recording.f_hz), f_hz, recording.f_hz), switched, PHASE_JUMP_GUARD)
    x2_meas = measured_speed_deviation(f_hz, alg.delta_rad, theta_smooth, dt, m.f_nominal_hz, hw, n)
    theta_t = theta_ref + unwrap_continuing(jnp.angle(mapped.v_t), None if context is None
                                            else ctx.theta_t0 - theta_ref[0])
    return FrontEnd(n=n, valid=jnp.arange(ts.shape[0]) < n, theta_ref=theta_ref, theta_t=theta_t,
                    v_t=mapped.v_t, i_t=i_t, p_lv=mapped.p_lv, alg=alg, x2_meas=x2_meas, f_hz=f_hz,
                    theta_smooth=theta_smooth,
                    dw=x2_meas / m.omega_s)


def next_context(fe: FrontEnd, ctx: StreamContext | None, at) -> StreamContext:
    """The context of a slice of a stream that starts at local sample ``at`` of the slice
    whose front end is ``fe`` (``ctx``: that slice's own context, None for a stream's first)."""
    before = jnp.arange(fe.p_lv.shape[0]) < at
    p_sum, p_count = (0.0, 0) if ctx is None else (ctx.p_lv_sum, ctx.p_lv_count)
    return StreamContext(p_sum + jnp.sum(jnp.where(before, fe.p_lv, 0.0)), p_count + at,
                         fe.theta_ref[at], (fe.alg.delta_rad - fe.theta_ref)[at], fe.theta_t[at],
                         None if fe.alg.q_state is None else fe.alg.q_state[at],
                         (fe.theta_ref - fe.theta_smooth)[at])


def reference_torque(ts, fe: FrontEnd, gov: AbstractGovernor, settings: Settings):
    """T_ref from the quasi-steady state of the first ``qss_window_s`` (paper Sec. IV-A)."""
    qss = (ts < ts[0] + settings.qss_window_s) & fe.valid
    ref = gov.reference_from_steady(fe.alg.t_e_pu, fe.dw)
    return jnp.sum(jnp.where(qss, ref, 0.0)) / jnp.maximum(jnp.sum(qss), 1)


def playback_inputs(fe: FrontEnd, t_m, delta0, t_ref, plant: Plant, settings: Settings, dt,
                    equilibrium_s: float = 0.0):
    """Inputs, initial state and measured outputs (x2, I_t, P_t, Q_t) of the event playback.

    ``equilibrium_s`` > 0 starts the machine at the equilibrium of the first frames' power flow:
    the load angle, the speed deviation and E'q are their means over the first
    ``equilibrium_s`` [s] (a single frame carries the noise and the derivative's edge), the
    governor at its steady state there.
    """
    m = plant.machine
    e_f = estimate_field_voltage(fe.alg.e_q1_pu, fe.alg.i_d_pu, dt, m,
                                 settings.derivative_half_width, fe.n)
    x2_0, e_q1_0 = fe.x2_meas[0], fe.alg.e_q1_pu[0]
    if equilibrium_s > 0:
        first = fe.valid & (jnp.arange(fe.valid.shape[0]) * dt < equilibrium_s)
        count = jnp.maximum(jnp.sum(first), 1)

        def mean(x):
            return jnp.sum(jnp.where(first, x, 0.0)) / count

        x2_0, e_q1_0 = mean(fe.x2_meas), mean(fe.alg.e_q1_pu)
        # the rotor's angle to the terminal voltage (the load angle) of the first frames
        delta0 = fe.theta_t[0] + mean(fe.alg.delta_rad - fe.theta_t)
    inputs = PlaybackInputs(jnp.abs(fe.v_t), fe.theta_t - delta0, e_f, t_m, fe.dw)
    y0 = jnp.stack([0.0 * delta0, x2_0, e_q1_0])
    if not settings.external_tm:
        y0 = jnp.concatenate([y0, plant.governor.steady_state(t_ref, x2_0 / m.omega_s)])
    s_t = fe.v_t * jnp.conj(fe.i_t)
    return inputs, y0, (fe.x2_meas, jnp.abs(fe.i_t), jnp.real(s_t), jnp.imag(s_t))


class FrontSums(NamedTuple):
    """Sums over the valid samples that the flags need (added up chunk by chunk in a stream)."""

    i_mag: Array
    t_e: Array
    count: Array


def front_sums(fe: FrontEnd, start: int = 0, stop: int | None = None) -> FrontSums:
    """Sums over samples ``start:stop`` (a chunk without its halo)."""
    sel = fe.valid[start:stop]
    return FrontSums(jnp.sum(jnp.where(sel, jnp.abs(fe.i_t[start:stop]), 0.0)),
                     jnp.sum(jnp.where(sel, fe.alg.t_e_pu[start:stop], 0.0)), jnp.sum(sel))
