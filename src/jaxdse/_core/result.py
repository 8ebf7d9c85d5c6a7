"""The :class:`Estimate` of one run and the one function that builds it.

Every run -- one-shot, batched or streamed, keeping trajectories or only final values --
ends in :func:`build_estimate`: per-segment summaries of the observer and the playback (a
segment is a block of samples, or a single sample when trajectories are kept), the sums
the flags need, and optionally the trajectories. Convergence and the scores are computed
from the segments by one function each, so every path reports them the same way.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from .drem import DremSegments
from .front_end import FrontSums
from .machine import Machine, damping_from_a, inertia_from_a2
from .metrics import settled_from
from .playback import Playback, PlaybackSegments
from .settings import Settings


class Scores(NamedTuple):
    """sMAPE [%] against the mapped measurements (paper Tables II and III)."""

    x2_observer: Array
    x2_playback: Array
    i_t: Array
    p_t: Array
    q_t: Array


class Trajectories(eqx.Module):
    """Every sample of one run [machine base], time first (``Settings(keep="trajectories")``)."""

    delta_rad: Float[Array, " T"]
    """Rotor angle relative to its first sample [rad]."""
    x2_hat_rad_s: Float[Array, " T"]
    """I&I observer's speed deviation [rad/s]."""
    x2_meas_rad_s: Float[Array, " T"]
    """Measured speed deviation (paper Remark 2) [rad/s]."""
    e_q1_pu: Float[Array, " T"]
    i_d_pu: Float[Array, " T"]
    i_q_pu: Float[Array, " T"]
    t_e_pu: Float[Array, " T"]
    t_m_pu: Float[Array, " T"]
    e_f_pu: Float[Array, " T"]
    """Estimated field voltage [pu] (paper Sec. V, step 2)."""
    v_t_pu: Float[Array, " T"]
    """Terminal voltage magnitude [pu]."""
    theta_t_rad: Float[Array, " T"]
    """Terminal voltage angle in the frame of ``delta_rad`` [rad]."""
    i_t_pu: Float[Array, " T"]
    p_t_pu: Float[Array, " T"]
    q_t_pu: Float[Array, " T"]
    delta_sq: Float[Array, " T"]
    """Excitation Delta^2 of the extended regressor."""
    log_contraction: Float[Array, "T 2"]
    """int gamma_j K_j Delta^2 dt: the parameter error has shrunk by exp(-this)."""
    playback: Playback | None
    """The event playback (None with ``Settings(playback=False)``)."""


class Estimate(eqx.Module):
    """Final estimates, flags and scores of one run, and what ``Settings.keep`` asked for.

    ``time_s``, ``a1_hat`` and ``a2_hat`` hold one value per segment: per sample with
    ``keep="trajectories"``, per block (at its last sample) with ``keep="final"``.
    """

    time_s: Float[Array, " S"]
    a1_hat: Float[Array, " S"]
    a2_hat: Float[Array, " S"]
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
    """Mean Tm - Te within ``Settings.torque_balance_tolerance`` of mean Te: the governor model
    can carry the load (else e.g. a valve limit below the output makes Tm saturate and a1, a2
    meaningless)."""
    smape: Scores
    log_contraction_end: Float[Array, " 2"]
    """int gamma_j K_j Delta^2 dt over the recording: the parameter error shrank by exp(-this)."""
    trajectories: Trajectories | None = None
    """Every sample (``keep="trajectories"``), else None."""


def build_estimate(dt, n, segments: DremSegments, segment_samples: int, theta_last, log_contraction,
                   ok, playback: PlaybackSegments | None, sums: FrontSums, t_ref, machine: Machine,
                   settings: Settings, a2_reference=None,
                   trajectories: Trajectories | None = None) -> Estimate:
    """The :class:`Estimate` from per-segment summaries of ``segment_samples`` samples each.

    a2_hat has converged at the start of the first segment after which every segment lies
    in the band (:func:`settled_from`); with a known reference it is its band, else the band
    of the final value, held for ``min_hold_s``.
    """
    a1, a2 = theta_last[0], theta_last[1]
    n_seg = segments.count.shape[0]
    start = jnp.arange(n_seg) * segment_samples
    # A reference of NaN (a batch whose other members know theirs) counts as none.
    known = jnp.isfinite(jnp.nan if a2_reference is None else a2_reference)
    target = jnp.where(known, jnp.nan if a2_reference is None else a2_reference, a2)
    k_conv = settled_from(segments.a2_min, segments.a2_max, target, settings.convergence_band)
    n_valid_seg = -(-n // segment_samples)
    t_conv = jnp.minimum(start[jnp.minimum(k_conv, n_seg - 1)], n - 1) * dt
    held = k_conv < n_valid_seg
    held = held & (known | ((n - 1) * dt - t_conv >= settings.min_hold_s))
    count = jnp.maximum(sums.count, 1)
    online = sums.i_mag / count > settings.offline_current_pu
    excited = log_contraction[1] >= settings.min_log_contraction
    torque_balanced = jnp.abs(jnp.sum(segments.torque_sum) / count) <= (
        settings.torque_balance_tolerance * jnp.maximum(jnp.abs(sums.t_e / count),
                                                        settings.offline_current_pu))
    converged = held & excited & online & ok & torque_balanced
    after = jnp.where(converged, jnp.arange(n_seg) >= k_conv, True)

    def score(term_sums, mask=True):
        mask = mask & (segments.count > 0)
        total = jnp.sum(jnp.where(mask, term_sums, 0.0))
        return 100.0 * total / jnp.maximum(jnp.sum(jnp.where(mask, segments.count, 0)), 1)

    nan = jnp.full((), jnp.nan, dtype=a2.dtype)
    scores = Scores(x2_observer=score(segments.x2_smape_sum, after),
                    x2_playback=nan if playback is None else score(playback.x2),
                    i_t=nan if playback is None else score(playback.i_t),
                    p_t=nan if playback is None else score(playback.p_t),
                    q_t=nan if playback is None else score(playback.q_t))
    return Estimate(
        time_s=jnp.minimum(start + segment_samples - 1, n - 1) * dt,
        a1_hat=segments.theta_end[:, 0], a2_hat=segments.theta_end[:, 1], a1=a1, a2=a2,
        h_s=inertia_from_a2(a2, machine.omega_s), d_pu_s=damping_from_a(a1, a2), t_ref_pu=t_ref,
        convergence_time_s=jnp.where(converged, t_conv, jnp.nan), converged=converged,
        excited=excited, online=online, solver_ok=ok, torque_balanced=torque_balanced,
        smape=scores, log_contraction_end=log_contraction, trajectories=trajectories,
    )
