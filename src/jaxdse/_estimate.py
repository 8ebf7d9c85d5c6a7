"""``estimate``: the whole pipeline as one pure, jit/vmap/grad-compatible function.

recording -> positive-sequence phasors -> mapping to the terminal -> algebraic observer ->
governor Tm -> DREM/I&I observer -> Ef estimate and event playback -> metrics.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._algebraic import algebraic_observer
from ._drem import DremInputs, ObserverConfig, run_observer
from ._governor import TGOV1, AbstractGovernor
from ._integrate import Integrator
from ._machine import Machine, damping_from_a, inertia_from_a2
from ._mapping import AuxiliarySystem, Line, Transformer, map_to_terminal
from ._metrics import convergence_index, smape_percent
from ._playback import PlaybackInputs, estimate_field_voltage, playback
from ._recording import Recording
from ._signals import frequency_from_angle, measured_speed_deviation
from ._units import as_float, check_positive


class Plant(eqx.Module):
    """Everything between the PMU and the rotor: network, machine and governor-turbine."""

    machine: Machine = Machine()
    line: Line = Line()
    transformer: Transformer = Transformer()
    aux: AuxiliarySystem = AuxiliarySystem()
    governor: AbstractGovernor = TGOV1()
    s_base_mva: Float[Array, ""] = eqx.field(converter=as_float, default=100.0)
    """System base [MVA] of the network parameters and of the PMU phasors."""

    def __check_init__(self):
        check_positive(self, "s_base_mva")


class Settings(eqx.Module):
    """Static choices of the pipeline (never differentiated or vmapped)."""

    observer_integrator: Integrator = Integrator()
    playback_integrator: Integrator = Integrator(rtol=1e-6, atol=1e-9)
    derivative_half_width: int = eqx.field(static=True, default=5)
    """Half width (samples) of the least-squares derivative used for x2_meas, f and Ef."""
    qss_window_s: float = eqx.field(static=True, default=5.0)
    """Initial window over which T_ref is taken from the quasi-steady state [s]."""
    convergence_band: float = eqx.field(static=True, default=0.02)
    """a2_hat has converged once it stays within this relative band of the reference."""
    min_hold_s: float = eqx.field(static=True, default=30.0)
    """Without a known reference: a2_hat must stay in the band of its final value this long."""
    min_log_contraction: float = eqx.field(static=True, default=4.0)
    """Excitation needed: int gamma K Delta^2 dt >= this (error shrunk by e^-4 ~ 1/55)."""
    offline_current_pu: float = eqx.field(static=True, default=0.02)
    """Mean terminal current [pu, machine base] below which the generator counts as offline."""
    external_tm: bool = eqx.field(static=True, default=False)
    """Use the ``t_m`` argument of :func:`estimate` instead of the governor model."""


class Scores(NamedTuple):
    """sMAPE [%] against the mapped measurements (paper Tables II and III)."""

    x2_observer: Array
    x2_playback: Array
    i_t: Array
    p_t: Array
    q_t: Array


class Estimate(eqx.Module):
    """Trajectories (leading time axis), final estimates, flags and scores of one run."""

    time_s: Float[Array, " T"]
    delta_rad: Float[Array, " T"]
    """Rotor angle relative to its first sample [rad]."""
    x2_hat_rad_s: Float[Array, " T"]
    x2_meas_rad_s: Float[Array, " T"]
    e_q1_pu: Float[Array, " T"]
    i_d_pu: Float[Array, " T"]
    i_q_pu: Float[Array, " T"]
    a1_hat: Float[Array, " T"]
    a2_hat: Float[Array, " T"]
    t_e_pu: Float[Array, " T"]
    t_m_pu: Float[Array, " T"]
    e_f_pu: Float[Array, " T"]
    i_t_pu: Float[Array, " T"]
    p_t_pu: Float[Array, " T"]
    q_t_pu: Float[Array, " T"]
    x2_sim_rad_s: Float[Array, " T"]
    i_t_sim_pu: Float[Array, " T"]
    p_t_sim_pu: Float[Array, " T"]
    q_t_sim_pu: Float[Array, " T"]
    delta_sq: Float[Array, " T"]
    """Excitation Delta^2 of the extended regressor."""
    log_contraction: Float[Array, "T 2"]
    """int gamma_j K_j Delta^2 dt: the parameter error has shrunk by exp(-this)."""
    a1: Float[Array, ""]
    a2: Float[Array, ""]
    h_s: Float[Array, ""]
    d_pu_s: Float[Array, ""]
    t_ref_pu: Float[Array, ""]
    convergence_time_s: Float[Array, ""]
    """First time after which a2_hat stays in the band (NaN if not converged)."""
    converged: Array
    excited: Array
    online: Array
    solver_ok: Array
    torque_balanced: Array
    """Mean Tm - Te within 5 % of mean Te: the governor model can carry the load (else e.g. a
    valve limit below the output makes Tm saturate and a1, a2 meaningless)."""
    smape: Scores


def estimate(recording: Recording, plant: Plant, config: ObserverConfig,
             settings: Settings = Settings(), t_m=None, a2_reference=None) -> Estimate:
    """Estimate the states and a1, a2 (H, D) of one generator from one recording.

    Arguments:
        recording: positive-sequence PMU phasors [pu, system base] on a uniform grid.
        plant: network, machine and governor parameters.
        config: DREM/I&I tuning (paper Table I by default).
        settings: static choices (integration, derivative window, convergence criteria).
        t_m: mechanical torque [pu] per sample; used when ``settings.external_tm``.
        a2_reference: known a2, for the convergence time; else the final estimate is used.

    Returns:
        An :class:`Estimate`. Pure: ``jax.jit``, ``jax.vmap`` and ``jax.grad`` pass through.
    """
    m = plant.machine
    ts = recording.t_s
    dt = ts[1] - ts[0]
    hw = settings.derivative_half_width

    # Work in the frame of the measured voltage angle: no large angle ever enters arg().
    theta_ref = jnp.unwrap(recording.v_ang_rad)
    v_meas = recording.v_mag_pu + 0j
    i_meas = recording.i_mag_pu * jnp.exp(1j * (recording.i_ang_rad - theta_ref))
    mapped = map_to_terminal(v_meas, i_meas, plant.line, plant.transformer, plant.aux,
                             recording.location)
    v_t = mapped.v_t
    i_t = mapped.i_sg * (plant.s_base_mva / m.s_rated_mva)
    alg = algebraic_observer(v_t, i_t, theta_ref, m)

    f_hz = recording.f_hz
    if f_hz is None:
        f_hz = frequency_from_angle(theta_ref, dt, m.f_nominal_hz, hw)
    x2_meas = measured_speed_deviation(f_hz, alg.delta_rad, theta_ref, dt, m.f_nominal_hz, hw)
    # Governor input: rotor speed from the measured frequency (paper Remark 2), pu.
    dw = x2_meas / m.omega_s
    delta0 = alg.delta_rad[0]
    delta = alg.delta_rad - delta0

    qss = ts < ts[0] + settings.qss_window_s
    gov = plant.governor
    t_ref = jnp.sum(jnp.where(qss, gov.reference_from_steady(alg.t_e_pu, dw), 0.0)) / jnp.sum(qss)
    t_m_in = jnp.zeros_like(ts) if t_m is None else jnp.asarray(t_m, dtype=ts.dtype)
    traj = run_observer(ts, DremInputs(delta, alg.t_e_pu, dw, t_m_in), x2_meas[0], t_ref, config,
                        gov, settings.observer_integrator, settings.external_tm)
    a1_hat, a2_hat = traj.theta[:, 0], traj.theta[:, 1]
    a1, a2 = a1_hat[-1], a2_hat[-1]

    e_f = estimate_field_voltage(alg.e_q1_pu, alg.i_d_pu, dt, m, hw)
    theta_t = theta_ref + jnp.unwrap(jnp.angle(v_t)) - delta0
    sim = playback(ts, PlaybackInputs(jnp.abs(v_t), theta_t, e_f, traj.t_m_pu),
                   jnp.stack([0.0 * a1, x2_meas[0], alg.e_q1_pu[0]]), a1, a2, m,
                   settings.playback_integrator)

    s_t = v_t * jnp.conj(i_t)
    i_mag, p_t, q_t = jnp.abs(i_t), jnp.real(s_t), jnp.imag(s_t)

    online = jnp.mean(i_mag) > settings.offline_current_pu
    excited = traj.log_contraction[-1, 1] >= settings.min_log_contraction
    solver_ok = traj.solver_ok & sim.solver_ok
    torque_balanced = jnp.abs(jnp.mean(traj.t_m_pu - alg.t_e_pu)) <= 0.05 * jnp.maximum(
        jnp.abs(jnp.mean(alg.t_e_pu)), settings.offline_current_pu)
    n = ts.shape[0]
    if a2_reference is None:
        k_conv = convergence_index(a2_hat, a2, settings.convergence_band)
        held = ts[-1] - ts[jnp.minimum(k_conv, n - 1)] >= settings.min_hold_s
    else:
        k_conv = convergence_index(a2_hat, a2_reference, settings.convergence_band)
        held = k_conv < n
    converged = held & excited & online & solver_ok & torque_balanced
    t_conv = ts[jnp.minimum(k_conv, n - 1)] - ts[0]
    after = ts >= ts[0] + jnp.where(converged, t_conv, 0.0)
    t_conv = jnp.where(converged, t_conv, jnp.nan)

    scores = Scores(
        x2_observer=smape_percent(traj.x2_hat_rad_s, x2_meas, after),
        x2_playback=smape_percent(sim.x2_rad_s, x2_meas),
        i_t=smape_percent(sim.i_t_pu, i_mag),
        p_t=smape_percent(sim.p_t_pu, p_t),
        q_t=smape_percent(sim.q_t_pu, q_t),
    )
    return Estimate(
        time_s=ts - ts[0], delta_rad=delta, x2_hat_rad_s=traj.x2_hat_rad_s, x2_meas_rad_s=x2_meas,
        e_q1_pu=alg.e_q1_pu, i_d_pu=alg.i_d_pu, i_q_pu=alg.i_q_pu, a1_hat=a1_hat, a2_hat=a2_hat,
        t_e_pu=alg.t_e_pu, t_m_pu=traj.t_m_pu, e_f_pu=e_f, i_t_pu=i_mag, p_t_pu=p_t, q_t_pu=q_t,
        x2_sim_rad_s=sim.x2_rad_s, i_t_sim_pu=sim.i_t_pu, p_t_sim_pu=sim.p_t_pu,
        q_t_sim_pu=sim.q_t_pu, delta_sq=traj.delta_sq, log_contraction=traj.log_contraction,
        a1=a1, a2=a2, h_s=inertia_from_a2(a2, m.omega_s), d_pu_s=damping_from_a(a1, a2),
        t_ref_pu=t_ref, convergence_time_s=t_conv, converged=converged, excited=excited,
        online=online, solver_ok=solver_ok, torque_balanced=torque_balanced, smape=scores,
    )
