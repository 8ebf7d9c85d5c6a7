"""``estimate``: the whole pipeline as one pure, jit/vmap/grad-compatible function.

recording -> positive-sequence phasors -> mapping to the terminal -> algebraic observer ->
governor Tm -> DREM/I&I observer -> Ef estimate and event playback -> metrics.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from ._algebraic import AlgebraicStates, algebraic_observer
from ._drem import DremBlocks, DremInputs, DremState, DremTrajectory, ObserverConfig, run_observer
from ._governor import TGOV1, AbstractGovernor
from ._integrate import Integrator
from ._machine import Machine, damping_from_a, inertia_from_a2
from ._mapping import AuxiliarySystem, Line, Transformer, map_to_terminal
from ._metrics import smape_percent
from ._playback import PlaybackBlocks, PlaybackInputs, estimate_field_voltage, playback
from ._recording import Recording
from ._signals import frequency_from_angle, measured_speed_deviation, unwrap_continuing
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
    qss_window_s: float = eqx.field(static=True, default=30.0)
    """Initial window over which T_ref is taken from the quasi-steady state [s]. Its error
    falls as 1/window (the mean of the measured speed over a window is an angle difference
    over its length) and biases a1, a2: on the noisy synthetic recordings (P = 0.45 pu) a 5 s
    window left a2 up to 2.5 % off, 30 s within 0.6 % (experiments/tuning)."""
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
    keep: Literal["trajectories", "final"] = eqx.field(static=True, default="trajectories")
    """What the :class:`Estimate` holds: every trajectory, or (``"final"``) final values,
    flags and scores, with a1_hat and a2_hat only at the end of each block. "final" stores
    nothing per sample (large sweeps, long recordings); its convergence time then has the
    resolution of one block."""
    playback: bool = eqx.field(static=True, default=True)
    """Run the event playback (its sMAPE scores are NaN when False)."""
    block_samples: int = eqx.field(static=True, default=50)
    """Samples per block of the time loop: checkpointing (gradients) and ``keep="final"``."""

    def __check_init__(self):
        if self.keep not in ("trajectories", "final"):
            raise ValueError(f"Settings.keep must be 'trajectories' or 'final', got {self.keep!r}")
        if self.block_samples < 1:
            raise ValueError(f"Settings.block_samples must be >= 1, got {self.block_samples}")


class Scores(NamedTuple):
    """sMAPE [%] against the mapped measurements (paper Tables II and III)."""

    x2_observer: Array
    x2_playback: Array
    i_t: Array
    p_t: Array
    q_t: Array


class Estimate(eqx.Module):
    """Trajectories (leading time axis), final estimates, flags and scores of one run.

    With ``Settings(keep="final")`` the per-sample fields are None, and ``time_s``,
    ``a1_hat`` and ``a2_hat`` hold one value per block (at its last sample).
    """

    time_s: Float[Array, " T"]
    a1_hat: Float[Array, " T"]
    a2_hat: Float[Array, " T"]
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
    log_contraction_end: Float[Array, " 2"]
    """int gamma_j K_j Delta^2 dt over the recording: the parameter error shrank by exp(-this)."""
    delta_rad: Float[Array, " T"] | None = None
    """Rotor angle relative to its first sample [rad]."""
    x2_hat_rad_s: Float[Array, " T"] | None = None
    x2_meas_rad_s: Float[Array, " T"] | None = None
    e_q1_pu: Float[Array, " T"] | None = None
    i_d_pu: Float[Array, " T"] | None = None
    i_q_pu: Float[Array, " T"] | None = None
    t_e_pu: Float[Array, " T"] | None = None
    t_m_pu: Float[Array, " T"] | None = None
    e_f_pu: Float[Array, " T"] | None = None
    i_t_pu: Float[Array, " T"] | None = None
    p_t_pu: Float[Array, " T"] | None = None
    q_t_pu: Float[Array, " T"] | None = None
    x2_sim_rad_s: Float[Array, " T"] | None = None
    i_t_sim_pu: Float[Array, " T"] | None = None
    p_t_sim_pu: Float[Array, " T"] | None = None
    q_t_sim_pu: Float[Array, " T"] | None = None
    delta_sq: Float[Array, " T"] | None = None
    """Excitation Delta^2 of the extended regressor."""
    log_contraction: Float[Array, "T 2"] | None = None
    """int gamma_j K_j Delta^2 dt: the parameter error has shrunk by exp(-this)."""


class StreamContext(NamedTuple):
    """What a chunk of a stream needs from the samples before it (see ``_stream``)."""

    p_lv_sum: Array
    """Sum of P_LV over all samples before the chunk (running mean of the auxiliary load)."""
    p_lv_count: Array
    theta_ref0: Array
    """Unwrapped voltage angle at the chunk's first sample, as the previous chunk had it."""
    rel0: Array
    """Unwrapped delta - theta_ref at the first sample."""
    theta_t0: Array
    """Unwrapped terminal-voltage angle at the first sample."""


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
    dw: Array
    """x2_meas / w_s [pu], the governor input."""


def front_end(recording: Recording, plant: Plant, settings: Settings = Settings(),
              context: StreamContext | None = None) -> FrontEnd:
    """Mapping to the terminal, algebraic observer and measured speed, for every sample."""
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
    i_t = mapped.i_sg * (plant.s_base_mva / m.s_rated_mva)
    alg = algebraic_observer(mapped.v_t, i_t, theta_ref, m, ctx.rel0)
    f_hz = recording.f_hz
    if f_hz is None:
        f_hz = frequency_from_angle(theta_ref, dt, m.f_nominal_hz, hw, n)
    x2_meas = measured_speed_deviation(f_hz, alg.delta_rad, theta_ref, dt, m.f_nominal_hz, hw, n)
    theta_t = theta_ref + unwrap_continuing(jnp.angle(mapped.v_t), None if context is None
                                            else ctx.theta_t0 - theta_ref[0])
    return FrontEnd(n=n, valid=jnp.arange(ts.shape[0]) < n, theta_ref=theta_ref, theta_t=theta_t,
                    v_t=mapped.v_t, i_t=i_t, p_lv=mapped.p_lv, alg=alg, x2_meas=x2_meas,
                    dw=x2_meas / m.omega_s)


def reference_torque(ts, fe: FrontEnd, gov: AbstractGovernor, settings: Settings):
    """T_ref from the quasi-steady state of the first ``qss_window_s`` (paper Sec. IV-A)."""
    qss = (ts < ts[0] + settings.qss_window_s) & fe.valid
    ref = gov.reference_from_steady(fe.alg.t_e_pu, fe.dw)
    return jnp.sum(jnp.where(qss, ref, 0.0)) / jnp.maximum(jnp.sum(qss), 1)


def estimate(recording: Recording, plant: Plant, config: ObserverConfig,
             settings: Settings = Settings(), t_m=None, a2_reference=None) -> Estimate:
    """Estimate the states and a1, a2 (H, D) of one generator from one recording.

    Arguments:
        recording: positive-sequence PMU phasors [pu, system base] on a uniform grid,
            possibly padded (``n_samples``).
        plant: network, machine and governor parameters.
        config: DREM/I&I tuning (paper Table I by default).
        settings: static choices (integration, derivative window, what to keep).
        t_m: mechanical torque [pu] per sample; used when ``settings.external_tm``.
        a2_reference: known a2, for the convergence time; else the final estimate is used.

    Returns:
        An :class:`Estimate`. Pure: ``jax.jit``, ``jax.vmap`` and ``jax.grad`` pass through;
        :func:`jaxdse.estimate_batch` runs batches of recordings and/or configurations.
    """
    ts = recording.t_s
    fe = front_end(recording, plant, settings)
    t_ref = reference_torque(ts, fe, plant.governor, settings)
    delta0 = fe.alg.delta_rad[0]
    t_m_in = _external_torque(t_m, ts, settings)
    inputs = DremInputs(fe.alg.delta_rad - delta0, fe.alg.t_e_pu, fe.dw, t_m_in)
    x2_0, block = fe.x2_meas[0], settings.block_samples
    obs = (ts, inputs, x2_0, t_ref, config, plant.governor, settings.observer_integrator,
           settings.external_tm)
    if settings.keep == "final":
        blocks, last, ok = run_observer(*obs, n_valid=fe.n, x2_meas=fe.x2_meas, block=block)
        pb_blocks = None
        if settings.playback:
            pb_in, y0, meas = playback_inputs(fe, t_m_in, delta0, t_ref, plant, settings,
                                              ts[1] - ts[0])
            pb_blocks, _, pb_ok = playback(ts, pb_in, y0, last.theta[0], last.theta[1],
                                           plant.machine, settings.playback_integrator,
                                           _playback_governor(plant, settings), t_ref,
                                           n_valid=fe.n, measured=meas, block=block)
            ok = ok & pb_ok
        return final_estimate(ts[1] - ts[0], fe.n, blocks, pb_blocks, last, ok,
                              front_sums(fe), t_ref, plant.machine, settings, a2_reference)
    traj = run_observer(*obs, n_valid=fe.n, block=block)
    return _trajectory_estimate(ts, fe, traj, t_ref, delta0, plant, settings, t_m_in, a2_reference)


def _external_torque(t_m, ts, settings: Settings):
    """The ``t_m`` argument as an array when ``settings.external_tm``, else None (unused)."""
    if not settings.external_tm:
        return None
    if t_m is None:
        raise ValueError("Settings(external_tm=True) needs the t_m argument (Tm per sample)")
    return jnp.asarray(t_m, dtype=ts.dtype)


def playback_inputs(fe: FrontEnd, t_m, delta0, t_ref, plant: Plant, settings: Settings, dt):
    """Inputs, initial state and measured outputs (x2, I_t, P_t, Q_t) of the event playback."""
    m = plant.machine
    e_f = estimate_field_voltage(fe.alg.e_q1_pu, fe.alg.i_d_pu, dt, m,
                                 settings.derivative_half_width, fe.n)
    inputs = PlaybackInputs(jnp.abs(fe.v_t), fe.theta_t - delta0, e_f, t_m, fe.dw)
    y0 = jnp.stack([0.0 * delta0, fe.x2_meas[0], fe.alg.e_q1_pu[0]])
    if not settings.external_tm:
        y0 = jnp.concatenate([y0, plant.governor.steady_state(t_ref, fe.dw[0])])
    s_t = fe.v_t * jnp.conj(fe.i_t)
    return inputs, y0, (fe.x2_meas, jnp.abs(fe.i_t), jnp.real(s_t), jnp.imag(s_t))


def _playback_governor(plant: Plant, settings: Settings):
    return None if settings.external_tm else plant.governor


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


def _flags(sums: FrontSums, torque_sum, log_contraction, settings: Settings):
    count = jnp.maximum(sums.count, 1)
    online = sums.i_mag / count > settings.offline_current_pu
    excited = log_contraction[1] >= settings.min_log_contraction
    torque_balanced = jnp.abs(torque_sum / count) <= 0.05 * jnp.maximum(
        jnp.abs(sums.t_e / count), settings.offline_current_pu)
    return online, excited, torque_balanced


def final_estimate(dt, n, blocks: DremBlocks, pb: PlaybackBlocks | None, last: DremState, ok,
                   sums: FrontSums, t_ref, machine: Machine, settings: Settings,
                   a2_reference=None) -> Estimate:
    """The ``keep="final"`` :class:`Estimate` from per-block summaries (one-shot or stream).

    Convergence is resolved to blocks: a2_hat has converged at the start of the first block
    after which every block's min and max lie in the band.
    """
    a1, a2 = last.theta[0], last.theta[1]
    size = settings.block_samples
    n_blocks = blocks.count.shape[0]
    start = jnp.arange(n_blocks) * size
    target = a2 if a2_reference is None else a2_reference
    tol = settings.convergence_band * jnp.abs(target)
    outside = (blocks.a2_max > target + tol) | (blocks.a2_min < target - tol)
    k_conv = jnp.max(jnp.where(outside, jnp.arange(n_blocks), -1)) + 1
    n_valid_blocks = -(-n // size)
    t_end = (n - 1) * dt
    t_conv = jnp.minimum(start[jnp.minimum(k_conv, n_blocks - 1)], n - 1) * dt
    if a2_reference is None:
        held = (k_conv < n_valid_blocks) & (t_end - t_conv >= settings.min_hold_s)
    else:
        held = k_conv < n_valid_blocks
    online, excited, torque_balanced = _flags(sums, jnp.sum(blocks.torque_sum), last.log_contraction,
                                              settings)
    converged = held & excited & online & ok & torque_balanced
    after = jnp.where(converged, jnp.arange(n_blocks) >= k_conv, True)

    def score(term_sums, mask=True):
        mask = mask & (blocks.count > 0)
        total = jnp.sum(jnp.where(mask, term_sums, 0.0))
        return 100.0 * total / jnp.maximum(jnp.sum(jnp.where(mask, blocks.count, 0)), 1)

    nan = jnp.full((), jnp.nan, dtype=a2.dtype)
    scores = Scores(x2_observer=score(blocks.x2_smape_sum, after),
                    x2_playback=nan if pb is None else score(pb.x2),
                    i_t=nan if pb is None else score(pb.i_t),
                    p_t=nan if pb is None else score(pb.p_t),
                    q_t=nan if pb is None else score(pb.q_t))
    return Estimate(
        time_s=jnp.minimum(start + size - 1, n - 1) * dt, a1_hat=blocks.theta_end[:, 0],
        a2_hat=blocks.theta_end[:, 1], a1=a1, a2=a2, h_s=inertia_from_a2(a2, machine.omega_s),
        d_pu_s=damping_from_a(a1, a2), t_ref_pu=t_ref,
        convergence_time_s=jnp.where(converged, t_conv, jnp.nan), converged=converged,
        excited=excited, online=online, solver_ok=ok, torque_balanced=torque_balanced,
        smape=scores, log_contraction_end=last.log_contraction,
    )


def _trajectory_estimate(ts, fe: FrontEnd, traj: DremTrajectory, t_ref, delta0, plant: Plant,
                         settings: Settings, t_m, a2_reference) -> Estimate:
    m, n, valid = plant.machine, fe.n, fe.valid
    a1, a2 = traj.last.theta[0], traj.last.theta[1]
    a2_hat = traj.theta[:, 1]
    if settings.playback:
        pb_in, y0, _ = playback_inputs(fe, t_m, delta0, t_ref, plant, settings, ts[1] - ts[0])
        sim = playback(ts, pb_in, y0, a1, a2, m, settings.playback_integrator,
                       _playback_governor(plant, settings), t_ref, n_valid=n,
                       block=settings.block_samples)
        e_f, sim_ok = pb_in.e_f, sim.solver_ok
    else:
        sim = e_f = None
        sim_ok = True
    s_t = fe.v_t * jnp.conj(fe.i_t)
    i_mag, p_t, q_t = jnp.abs(fe.i_t), jnp.real(s_t), jnp.imag(s_t)
    torque_sum = jnp.sum(jnp.where(valid, traj.t_m_pu - fe.alg.t_e_pu, 0.0))
    online, excited, torque_balanced = _flags(front_sums(fe), torque_sum,
                                              traj.last.log_contraction, settings)
    solver_ok = traj.solver_ok & sim_ok
    target = a2 if a2_reference is None else a2_reference
    outside = valid & (jnp.abs(a2_hat - target) > settings.convergence_band * jnp.abs(target))
    k_conv = jnp.max(jnp.where(outside, jnp.arange(ts.shape[0]), -1)) + 1
    t_conv = ts[jnp.minimum(k_conv, n - 1)] - ts[0]
    if a2_reference is None:
        held = (k_conv < n) & (ts[n - 1] - ts[0] - t_conv >= settings.min_hold_s)
    else:
        held = k_conv < n
    converged = held & excited & online & solver_ok & torque_balanced
    after = valid & (ts >= ts[0] + jnp.where(converged, t_conv, 0.0))
    nan = jnp.full((), jnp.nan, dtype=a2.dtype)
    scores = Scores(
        x2_observer=smape_percent(traj.x2_hat_rad_s, fe.x2_meas, after),
        x2_playback=nan if sim is None else smape_percent(sim.x2_rad_s, fe.x2_meas, valid),
        i_t=nan if sim is None else smape_percent(sim.i_t_pu, i_mag, valid),
        p_t=nan if sim is None else smape_percent(sim.p_t_pu, p_t, valid),
        q_t=nan if sim is None else smape_percent(sim.q_t_pu, q_t, valid),
    )
    return Estimate(
        time_s=ts - ts[0], a1_hat=traj.theta[:, 0], a2_hat=a2_hat, a1=a1, a2=a2,
        h_s=inertia_from_a2(a2, m.omega_s), d_pu_s=damping_from_a(a1, a2), t_ref_pu=t_ref,
        convergence_time_s=jnp.where(converged, t_conv, jnp.nan), converged=converged,
        excited=excited, online=online, solver_ok=solver_ok, torque_balanced=torque_balanced,
        smape=scores, log_contraction_end=traj.last.log_contraction,
        delta_rad=fe.alg.delta_rad - delta0, x2_hat_rad_s=traj.x2_hat_rad_s,
        x2_meas_rad_s=fe.x2_meas, e_q1_pu=fe.alg.e_q1_pu, i_d_pu=fe.alg.i_d_pu,
        i_q_pu=fe.alg.i_q_pu, t_e_pu=fe.alg.t_e_pu, t_m_pu=traj.t_m_pu, e_f_pu=e_f,
        i_t_pu=i_mag, p_t_pu=p_t, q_t_pu=q_t,
        x2_sim_rad_s=None if sim is None else sim.x2_rad_s,
        i_t_sim_pu=None if sim is None else sim.i_t_pu,
        p_t_sim_pu=None if sim is None else sim.p_t_pu,
        q_t_sim_pu=None if sim is None else sim.q_t_pu,
        delta_sq=traj.delta_sq, log_contraction=traj.log_contraction,
    )
