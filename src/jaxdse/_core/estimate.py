"""``estimate``: the whole pipeline for one generator and one configuration, as one pure function.

recording -> positive-sequence phasors -> mapping to the terminal -> algebraic observer ->
governor Tm -> DREM/I&I observer -> Ef estimate and event playback -> metrics.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from .._models.governors import ScaledGovernor
from .drem import DremInputs, ObserverConfig, run_observer
from .front_end import FrontEnd, front_end, front_sums, playback_inputs, reference_torque
from .plant import Plant
from .playback import Playback, playback
from .recording import Recording
from .result import Estimate, Scores, Trajectories, build_estimate
from .settings import Settings


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
    fe = front_end(recording, plant, settings)
    return estimate_front(recording.t_s, fe, reference_torque(recording.t_s, fe, plant.governor, settings),
                          plant, config, settings, t_m, a2_reference)


def estimate_front(ts, fe: FrontEnd, t_ref, plant: Plant, config: ObserverConfig,
                   settings: Settings = Settings(), t_m=None, a2_reference=None) -> Estimate:
    """:func:`estimate` on a front end computed once (``front_end``) and its T_ref [pu]."""
    dt = ts[1] - ts[0]
    keep = settings.keep == "trajectories"
    delta0 = fe.alg.delta_rad[0]
    t_m_in = external_torque(t_m, ts, settings)
    inputs = DremInputs(fe.alg.delta_rad - delta0, fe.alg.t_e_pu, fe.dw, t_m_in)
    obs = run_observer(ts, inputs, fe.x2_meas[0], t_ref, config, plant.governor,
                       settings.observer_integrator, settings.external_tm, x2_meas=fe.x2_meas,
                       n_valid=fe.n, block=settings.block_samples, save_trajectory=keep)
    pb_in, y0, measured = playback_inputs(fe, t_m_in, delta0, t_ref, plant, settings, dt)
    pb, ok = None, obs.ok
    if settings.playback:
        pb = playback(ts, pb_in, y0, obs.last.theta[0], obs.last.theta[1], plant.machine,
                      settings.playback_integrator, playback_governor(plant, settings), t_ref,
                      measured=measured, n_valid=fe.n, block=settings.block_samples,
                      save_trajectory=keep)
        ok = ok & pb.ok
    traj = None
    if keep:
        s_t = fe.v_t * jnp.conj(fe.i_t)
        traj = Trajectories(
            delta_rad=inputs.delta, x2_hat_rad_s=obs.trajectory.x2_hat_rad_s,
            x2_meas_rad_s=fe.x2_meas, e_q1_pu=fe.alg.e_q1_pu, i_d_pu=fe.alg.i_d_pu,
            i_q_pu=fe.alg.i_q_pu, t_e_pu=fe.alg.t_e_pu, t_m_pu=obs.trajectory.t_m_pu,
            e_f_pu=pb_in.e_f, v_t_pu=pb_in.v_mag, theta_t_rad=pb_in.theta, i_t_pu=jnp.abs(fe.i_t),
            p_t_pu=jnp.real(s_t), q_t_pu=jnp.imag(s_t),
            delta_sq=obs.trajectory.delta_sq, log_contraction=obs.trajectory.log_contraction,
            playback=None if pb is None else pb.trajectory)
    return build_estimate(dt, fe.n, obs.segments, 1 if keep else settings.block_samples,
                          obs.last.theta, obs.last.log_contraction, ok,
                          None if pb is None else pb.segments, front_sums(fe), t_ref, plant.machine,
                          settings, a2_reference, traj)


def external_torque(t_m, ts, settings: Settings):
    """The ``t_m`` argument as an array when ``settings.external_tm``, else None (unused)."""
    if not settings.external_tm:
        return None
    if t_m is None:
        raise ValueError("Settings(external_tm=True) needs the t_m argument (Tm per sample)")
    return jnp.asarray(t_m, dtype=ts.dtype)


def scaled_governor(plant: Plant, t_m0, gain, offset) -> Plant:
    """``plant`` with its governor's response scaled by 1 + ``gain`` about its initial torque
    ``t_m0`` [pu] and shifted by ``offset`` [pu]."""
    gov = plant.governor
    return eqx.tree_at(lambda p: p.governor, plant, ScaledGovernor(gov, gain, t_m0, offset))


def playback_governor(plant: Plant, settings: Settings):
    """The governor the playback integrates (None: it uses the external Tm)."""
    return None if settings.external_tm else plant.governor


EQUILIBRIUM_S = 1.0
"""The replay starts at the equilibrium of the first second's power flow (its speed and E'q
the means over it), not at the first frame's noisy derivative."""


class Replay(eqx.Module):
    """The event playback with given parameters: scores against the measurements, trajectory."""

    smape: Scores
    """sMAPE [%] of the playback's x2, I_t, P_t, Q_t (``x2_observer`` is NaN: no observer runs)."""
    playback: Playback
    ok: Array


def replay(recording: Recording, plant: Plant, a1, a2, settings: Settings = Settings(),
           t_m_offset=0.0, governor_gain_error=0.0) -> Replay:
    """Play the event back with a1, a2 (e.g. those of :func:`jaxdse.identify`) and score it.

    The governor is ``plant.governor`` at its quasi-steady-state T_ref, its torque response
    scaled by 1 + ``governor_gain_error`` and shifted by ``t_m_offset`` [pu]
    (:class:`~jaxdse.ScaledGovernor`, as :func:`jaxdse.identify` fits them).
    """
    fe = front_end(recording, plant, settings)
    t_ref = reference_torque(recording.t_s, fe, plant.governor, settings)
    t_m0 = plant.governor.torque(plant.governor.steady_state(t_ref, fe.dw[0]), fe.dw[0])
    return replay_front(recording.t_s, fe, t_ref, t_m0, plant, a1, a2, settings, t_m_offset,
                        governor_gain_error)


def replay_front(ts, fe: FrontEnd, t_ref, t_m0, plant: Plant, a1, a2, settings: Settings,
                 t_m_offset=0.0, governor_gain_error=0.0) -> Replay:
    """:func:`replay` on a front end computed once, its T_ref and the governor's initial
    torque ``t_m0`` [pu] (those of the identification, whose corrections are relative to them)."""
    dt = ts[1] - ts[0]
    plant = scaled_governor(plant, t_m0, governor_gain_error, t_m_offset)
    pb_in, y0, measured = playback_inputs(fe, None, fe.alg.delta_rad[0], t_ref, plant,
                                          dataclasses.replace(settings, external_tm=False), dt,
                                          equilibrium_s=EQUILIBRIUM_S)
    pb = playback(ts, pb_in, y0, a1, a2, plant.machine, settings.playback_integrator, plant.governor,
                  t_ref, measured=measured, n_valid=fe.n, block=settings.block_samples,
                  save_trajectory=True)
    count = jnp.maximum(jnp.sum(fe.valid), 1)

    def score(s):
        return 100.0 * jnp.sum(s) / count

    nan = jnp.full((), jnp.nan, dtype=ts.dtype)
    seg = pb.segments
    return Replay(smape=Scores(x2_observer=nan, x2_playback=score(seg.x2), i_t=score(seg.i_t),
                               p_t=score(seg.p_t), q_t=score(seg.q_t)),
                  playback=pb.trajectory, ok=pb.ok)
