"""Long recordings in chunks: bounded memory, same results as one call.

The recording stays on the host (NumPy, or a memory map); each chunk goes to the device
with ``derivative_half_width`` samples (at least 1) of halo on each side, so that the smoothed
derivatives equal those of the whole recording. What crosses a chunk boundary is carried:
the observer state and the previous sample (to integrate across the boundary), the running
mean of the auxiliary load and the unwrapping offsets (``StreamContext``), T_ref and the
initial angle (from the first chunk), and the per-block summaries of ``keep="final"``.
A second pass replays the event with the final a1, a2 when ``settings.playback``.

Chunks start every ``chunk_s``; a last chunk too short for a slice of its own (a
:class:`Recording` needs ``MIN_SLICE_SAMPLES``, halo included) joins the chunk before it, so
any split works.
"""

from __future__ import annotations

from collections.abc import Callable

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from .._core.drem import DremInputs, ObserverConfig, run_observer
from .._core.estimate import external_torque, playback_governor
from .._core.front_end import (
    FrontSums,
    front_end,
    front_sums,
    next_context,
    playback_inputs,
    reference_torque,
)
from .._core.integrate import Previous
from .._core.plant import Plant
from .._core.playback import playback
from .._core.recording import Recording, pad_end
from .._core.result import Estimate, build_estimate
from .._core.settings import Settings
from .batch import pad_recording

MIN_SLICE_SAMPLES = 8
"""The fewest samples a slice (a chunk with its halo) may have: :class:`Recording`'s minimum."""


def _chunk_bounds(total: int, chunk: int, halo: int) -> list[tuple[int, int]]:
    """(start, end) of each chunk: every ``chunk`` samples, a short last chunk merged into the
    one before it (its slice, ``halo`` samples before it included, would be too short)."""
    starts = list(range(0, total, chunk))
    if len(starts) > 1 and total - starts[-1] + halo < MIN_SLICE_SAMPLES:
        starts.pop()
    return [(s, e) for s, e in zip(starts, starts[1:] + [total])]


def _slice(rec: Recording, a: int, b: int, size: int) -> Recording:
    """Samples a:b, padded at the end to ``size`` (masked by n_samples)."""
    def cut(x):
        return None if x is None else np.asarray(x[a:b], dtype=np.float64)

    part = Recording(t_s=cut(rec.t_s), v_mag_pu=cut(rec.v_mag_pu), v_ang_rad=cut(rec.v_ang_rad),
                     i_mag_pu=cut(rec.i_mag_pu), i_ang_rad=cut(rec.i_ang_rad), f_hz=cut(rec.f_hz),
                     location=rec.location)
    return pad_recording(part, size)


def _crop(tree, start: int, size: int):
    return jtu.tree_map(lambda x: x[start:start + size], tree)


@eqx.filter_jit
def _observer_chunk(rec, plant, config, settings: Settings, ctx, carry, t_m, lead: int, size: int,
                    n_own, next_at):
    """Front end of one slice, then the observer over its own ``size`` samples after ``lead``."""
    fe = front_end(rec, plant, settings, ctx)
    ts = rec.t_s
    if carry is None:  # the first chunk: T_ref and the angle origin come from it
        t_ref, delta0 = reference_torque(ts, fe, plant.governor, settings), fe.alg.delta_rad[0]
        resume = None
    else:
        state, previous, t_ref, delta0 = carry
        resume = (state, previous)
    t_own, d_own, te_own, dw_own, x2_own, t_m_own = _crop(
        (ts, fe.alg.delta_rad - delta0, fe.alg.t_e_pu, fe.dw, fe.x2_meas, t_m),
        lead, size)
    inputs = DremInputs(d_own, te_own, dw_own, t_m_own)
    obs = run_observer(t_own, inputs, x2_own[0], t_ref, config, plant.governor,
                       settings.observer_integrator, settings.external_tm, x2_meas=x2_own, n_valid=n_own,
                       resume=resume, block=settings.block_samples)
    k = n_own - 1
    previous = Previous(t_own[k], jtu.tree_map(lambda x: x[k], inputs))
    sums = front_sums(fe, lead, lead + size)  # the slice's padding is masked by fe.valid
    return obs.segments, (obs.last, previous, t_ref, delta0), obs.ok, sums, next_context(fe, ctx, next_at)


@eqx.filter_jit
def _playback_chunk(rec, plant, settings: Settings, ctx, carry, t_m, lead: int, size: int, n_own,
                    theta, t_ref, delta0):
    fe = front_end(rec, plant, settings, ctx)
    inputs, y0, measured = playback_inputs(fe, t_m, delta0, t_ref, plant, settings,
                                           rec.t_s[1] - rec.t_s[0])
    t_own, in_own, meas_own = _crop((rec.t_s, inputs, measured), lead, size)
    pb = playback(t_own, in_own, y0, theta[0], theta[1], plant.machine, settings.playback_integrator,
                  playback_governor(plant, settings), t_ref, measured=meas_own, n_valid=n_own,
                  resume=carry, block=settings.block_samples)
    k = n_own - 1
    return pb.segments, (pb.last, Previous(t_own[k], jtu.tree_map(lambda x: x[k], in_own))), pb.ok


def estimate_stream(recording: Recording, plant: Plant, config: ObserverConfig,
                    settings: Settings = Settings(keep="final"), t_m=None, a2_reference=None, *,
                    chunk_s: float = 600.0,
                    progress: Callable[[int, int], None] | None = None) -> Estimate:
    """:func:`jaxdse.estimate` with ``keep="final"``, chunk by chunk, in bounded memory.

    Arguments:
        recording: one recording; its arrays may be host NumPy arrays or memory maps.
        chunk_s: chunk length [s], rounded to whole blocks; at least ``qss_window_s``. A last
            chunk too short for a slice of its own joins the chunk before it.
        progress: called with (samples done, samples to do) after each chunk.

    Returns:
        The same :class:`Estimate` as ``estimate(recording, ..., settings)`` (to round-off).
    """
    if settings.keep != "final":
        raise ValueError("estimate_stream keeps final values only: use Settings(keep='final')")
    ts = np.asarray(recording.t_s)
    total, dt = ts.shape[0], float(ts[1] - ts[0])
    size_b = settings.block_samples
    # Halo: the derivative window, and at least the one neighbour of a central difference
    # (derivative_half_width = 0).
    hw = max(settings.derivative_half_width, 1)
    chunk = max(1, round(chunk_s / dt / size_b)) * size_b
    if chunk * dt < settings.qss_window_s or chunk <= 2 * hw + 1:
        raise ValueError(f"chunk_s = {chunk_s} s is shorter than qss_window_s or the derivative window")
    t_m_all = external_torque(t_m, ts, settings)
    bounds = _chunk_bounds(total, chunk, hw)
    work = total * (2 if settings.playback else 1)

    def pieces():
        for s, e in bounds:
            a, b = max(s - hw, 0), min(e + hw, total)
            lead = s - a
            # Own samples, whole blocks: ``chunk`` for every chunk but a merged last one, so
            # that all but the first and that one share one shape.
            own = max(chunk, -(-(e - s) // size_b) * size_b)
            size = own + lead + hw
            t_slice = None
            if t_m_all is not None:
                t_slice = jnp.asarray(pad_end(np.asarray(t_m_all[a:b]), size))
            yield s, e, a, lead, own, _slice(recording, a, b, size), t_slice

    blocks, sums, contexts, carry, ok, done = [], [], [], None, True, 0
    ctx = None
    for s, e, a, lead, own, rec, t_slice in pieces():
        contexts.append(ctx)
        out, carry, chunk_ok, chunk_sums, ctx = _observer_chunk(
            rec, plant, config, settings, ctx, carry, t_slice, lead, own, jnp.asarray(e - s),
            jnp.asarray(max(e - hw - a, 0)))
        blocks.append(jtu.tree_map(np.asarray, out))
        sums.append(chunk_sums)
        ok = ok & bool(chunk_ok)
        done += e - s
        if progress is not None:
            progress(done, work)
    last, _, t_ref, delta0 = carry
    n_blocks = -(-total // size_b)
    blocks = jtu.tree_map(lambda *x: jnp.asarray(np.concatenate(x)[:n_blocks]), *blocks)
    pb_blocks = None
    if settings.playback:
        pb, pb_carry = [], None
        for (s, e, a, lead, own, rec, t_slice), c in zip(pieces(), contexts):
            out, pb_carry, chunk_ok = _playback_chunk(rec, plant, settings, c, pb_carry, t_slice,
                                                      lead, own, jnp.asarray(e - s), last.theta,
                                                      t_ref, delta0)
            pb.append(jtu.tree_map(np.asarray, out))
            ok = ok & bool(chunk_ok)
            done += e - s
            if progress is not None:
                progress(done, work)
        pb_blocks = jtu.tree_map(lambda *x: jnp.asarray(np.concatenate(x)[:n_blocks]), *pb)
    total_sums = FrontSums(*(sum(getattr(x, f) for x in sums) for f in FrontSums._fields))
    return build_estimate(dt, total, blocks, size_b, last.theta, last.log_contraction, jnp.asarray(ok),
                          pb_blocks, total_sums, t_ref, plant.machine, settings, a2_reference)
