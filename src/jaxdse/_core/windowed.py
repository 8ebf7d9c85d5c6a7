"""Windowed identification of a1, a2 (H, D) on a stream, from sufficient statistics.

:func:`~jaxdse._core.identify.identify` fits the filtered swing equation (paper App. Eq. 17)

    F[s x2] = -a1 F[x2] + a2 F[Tm - Te] + c F[1] + g F[Tm - Tm(0)]

to a whole recording. The filters are causal and LTI and the fit is linear, so on a stream
it runs chunk by chunk (:func:`window_chunk`): the front end with its :class:`StreamContext`,
the governor model and the filters F (the main one and the filter spread's, poles scaled by
``IdentifySettings.spread_scales``) carry their states from one chunk to the next, and each
chunk of ``update_s`` adds one block of sufficient statistics (:class:`Blocks`: X^T X, X^T z,
z^T z, sum z and the count). The estimate of the last ``window_s`` (:func:`window_estimate`)
is the solve of the sums over its blocks; its covariance is the Newey-West sandwich of the
blocks' scores g_b = X_b^T z_b - X_b^T X_b theta (Bartlett weights over the
``ceil(hac_window_s / update_s)`` neighbouring blocks that the residual's autocorrelation
reaches; with a small-sample correction for the number of blocks), so that the interval too
comes from the sums alone: no sample is stored, and the
cost per sample does not grow with the window.

Where it differs from the batch fit (each is what a causal, fixed-memory fit allows):

* the governor model's input, the speed low-passed forwards and backwards (zero phase) as in
  the batch fit, has its backward pass start ``lookahead_s`` after each chunk (at rest there),
  not at the recording's end: its start-up decays as exp(-0.71 w t) (1e-4 after 1 s at 2 Hz).
  A forward pass alone would delay the governor's response by ~0.1 s, which biased H by -4 %
  on NASPI OSL case 1's 1.15 Hz oscillation (hydro governors answer within it);
* ordinary least squares: Huber's weights need each sample's residual against the window's
  own solution, which sums cannot give;
* the noise part of the interval is the sandwich (no bootstrap: refits of noise draws need the
  window's samples); the filter spread and ``model_error`` enter as in the batch fit;
* T_ref is the first chunk's quasi-steady state (the offset term c absorbs its error);
* the filters start from rest at a segment's first sample, which ``settle_s`` leaves out.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .drem import ObserverConfig
from .front_end import StreamContext, front_end, next_context, reference_torque
from .identify import (
    Z95,
    Identified,
    IdentifySettings,
    _design_row,
    _fit_without,
    _heun,
    _result,
    governor_input,
    governor_start,
    refit_spread,
    solve_spd,
)
from .lti import butterworth2, filter_states, hold_discretisation, lag_chain
from .plant import Plant
from .recording import Recording
from .settings import Settings


class WindowSettings(eqx.Module):
    """How often the windowed estimate is refreshed and over how long a window (static)."""

    update_s: float = eqx.field(static=True, default=1.0)
    """Chunk length and refresh period [s]: one block of sufficient statistics per update."""
    window_s: float = eqx.field(static=True, default=120.0)
    """Length of the window the estimate is fitted on [s]: the last ``window_s / update_s``
    blocks. The first estimate of a segment comes once the window is full."""
    lookahead_s: float = eqx.field(static=True, default=1.0)
    """Samples after a chunk's own [s] that the backward pass of the governor input's low-pass
    sees (the estimate waits this long for them)."""

    def __check_init__(self):
        if not (self.update_s > 0 and self.window_s >= self.update_s):
            raise ValueError(f"need 0 < update_s <= window_s, got update_s = {self.update_s}, "
                             f"window_s = {self.window_s}")

    @property
    def blocks(self) -> int:
        """Blocks in one window."""
        return max(1, round(self.window_s / self.update_s))

    def chunk_samples(self, frame_rate_hz: float) -> int:
        """Samples in one chunk at ``frame_rate_hz``."""
        return max(1, round(self.update_s * frame_rate_hz))

    def tail_samples(self, frame_rate_hz: float, settings: Settings) -> int:
        """Samples of a chunk's slice after its own: the lookahead, at least the derivative halo."""
        return max(halo(settings), round(self.lookahead_s * frame_rate_hz))

    def start_samples(self, frame_rate_hz: float, settings: Settings) -> int:
        """Samples that a segment's first slice holds beyond a chunk's slice: its first
        ``qss_window_s`` (at most ``window_s``) after the halo, from which T_ref and the
        governor's initial state are taken (:func:`window_chunk`). The first chunk waits for them;
        the estimate waits for the full window anyway."""
        stretch = round(min(settings.qss_window_s, self.window_s) * frame_rate_hz)
        chunk = self.chunk_samples(frame_rate_hz) + self.tail_samples(frame_rate_hz, settings)
        return max(0, stretch - chunk)


class Blocks(NamedTuple):
    """Sufficient statistics of one chunk (leading axes: blocks, then filters where shown)."""

    normal: Array
    """X^T X [filters, 4, 4] (the main filter F first, then the spread's)."""
    rhs: Array
    """X^T z [filters, 4]."""
    zz: Array
    """z^T z [filters]."""
    z: Array
    """sum z [filters]."""
    count: Array
    """Samples that entered [-]."""


class Carry(NamedTuple):
    """What one chunk of a segment hands to the next."""

    context: StreamContext
    """The front end's context at the next slice's first sample."""
    filters: Array
    """States of the filters F [filters, 5 signals, 3] at the last own sample."""
    signals: Array
    """The regression's inputs at the last own sample [5]."""
    smooth: Array
    """State of the governor input's low-pass [2] at the last own sample."""
    x2: Array
    """The measured speed deviation at the last own sample [rad/s]."""
    governor: object
    """The governor model's state at the last own sample."""
    dw: Array
    """The governor's (low-passed) input at the last own sample [pu]."""
    t_ref: Array
    """T_ref of the segment [pu]."""
    t_m0: Array
    """The governor model's torque at the segment's first sample [pu]."""
    elapsed: Array
    """Samples of the segment processed so far."""


def _filters(config: ObserverConfig, s: IdentifySettings, dt):
    poles = jnp.stack([config.lambda1, config.lambda2, config.lambda3])
    discs = [hold_discretisation(*lag_chain(k * poles), dt) for k in (1.0, *s.spread_scales)]
    return jax.tree_util.tree_map(lambda *x: jnp.stack(x), *discs)


def halo(settings: Settings) -> int:
    """Samples of a chunk's slice before and after its own: the derivative window (at least 1)."""
    return max(settings.derivative_half_width, 1)


def window_chunk(rec: Recording, plant: Plant, config: ObserverConfig, settings: Settings,
                 identify_settings: IdentifySettings, carry: Carry | None, size: int,
                 start: int = 0, q_disc=None, chunks: int = 1) -> tuple[Blocks, Carry]:
    """One chunk of a stream (or ``chunks`` in a row): its block of sufficient statistics and
    the carry to the next.

    Arguments:
        rec: the slice: :func:`halo` samples (the derivative window), the chunk's ``size`` own
            samples, then the tail (:meth:`WindowSettings.tail_samples`: the lookahead), then,
            at a segment's first chunk, ``start`` more samples. The next chunk's slice starts
            where this one's own samples end, less the halo: chunk k of a segment owns samples
            ``halo + k * size`` to ``halo + (k + 1) * size``.
        carry: the previous chunk's; None at a segment's first chunk: the filters and the
            governor start there; T_ref is the quasi-steady mean over the slice's first
            ``qss_window_s``, and the governor's state comes from the slice's quiet part
            (:func:`~jaxdse._core.identify.governor_start`), as the batch fit's do.
        start: see ``rec`` (:meth:`WindowSettings.start_samples`; 0 with a carry).
        chunks: consecutive chunks that the slice's samples hold (static; a segment's first
            slice holds ``1 + start // size``): one pass over them gives the blocks and the
            carry of as many calls, one chunk each (each chunk's lookahead pass included), and
            every field of the blocks then has a leading axis of ``chunks``. 1: no such axis.
        q_disc: the q-axis circuits' discretisation at the stream's step
            (:func:`~jaxdse._core.algebraic.q_axis_discretisation`), computed once for a
            stream; None: here (``plant.machine.q_axis`` only).

    Pure: jit and vmap (over the units of a fleet) pass through.
    """
    s = identify_settings
    m = plant.machine
    ctx = None if carry is None else carry.context
    fe = front_end(rec, plant, settings, ctx, q_disc)
    ts = rec.t_s
    dt = ts[1] - ts[0]
    lead = halo(settings)
    own = chunks * size
    tail = ts.shape[0] - start - lead - size
    if own + tail > ts.shape[0] - lead:
        raise ValueError(f"window_chunk: {chunks} chunks of {size} samples need {lead + own + tail} samples, "
                         f"the slice has {ts.shape[0]}")

    gov = plant.governor
    smoothing = hold_discretisation(*butterworth2(s.governor_smoothing_hz, ts.dtype), dt)
    discs = _filters(config, s, dt)
    derived = rec.f_hz is None
    bus_all = jnp.zeros_like(ts) if derived else 2.0 * jnp.pi * (fe.f_hz - m.f_nominal_hz)
    rotor_all = fe.alg.delta_rad if derived else fe.alg.delta_rad - fe.theta_smooth
    if carry is None:   # at rest at the segment's first own sample
        t_ref = reference_torque(ts, fe, gov, settings)   # the batch fit's, as far as the slice goes
        dw_start = governor_input(fe, plant, smoothing, lead)   # the batch fit's, over the slice
        gov0 = governor_start(gov, fe, dw_start, dt, t_ref, lead, ts.shape[0])
        t_m0 = gov.torque(gov0, dw_start[lead])
        x2_0 = fe.x2_meas[lead]
        state = (jnp.stack([x2_0, 0.0]), x2_0, gov0, dw_start[lead], None, None, jnp.zeros((), jnp.int32))
    else:
        t_ref, t_m0 = carry.t_ref, carry.t_m0
        state = (carry.smooth, carry.x2, carry.governor, carry.dw, carry.filters, carry.signals,
                 carry.elapsed)

    def heun(x, d):   # governor_torque's step, from a carried state
        x = _heun(gov, dt, t_ref)(x, d)
        return x, (x, gov.torque(x, d[1]))

    def one_filter(disc, x0_f, u_all):
        states = jax.vmap(lambda uu, xx: filter_states(disc, uu, x0=xx)[1:])(u_all, x0_f)  # [5, size, 3]
        row, z = _design_row(lambda signal, order: states[signal][:, order])
        return jnp.stack(row, axis=1), z, states[:, -1]   # [5, 3] at the last own sample

    def chunk(state, k, first: bool):
        """Chunk k of the slice: its block, and the state at its last own sample."""
        smooth0, x2_prev, gov0, dw_prev, x0, u_prev, elapsed = state
        at = lead + k * size

        def cut(x):
            return jax.lax.dynamic_slice_in_dim(x, at, size)

        te, x2 = cut(fe.alg.t_e_pu), cut(fe.x2_meas)
        x2_ahead = jax.lax.dynamic_slice_in_dim(fe.x2_meas, at, size + tail)   # own samples and the lookahead
        smooth = filter_states(smoothing, jnp.concatenate([x2_prev[None], x2_ahead]), x0=smooth0)[1:]
        dw = filter_states(smoothing, smooth[:, 0], reverse=True)[:size, 0] / m.omega_s
        if first:   # gov0 is the state at the first own sample, as in the batch fit
            _, (states, t_m) = jax.lax.scan(heun, gov0, (dw[:-1], dw[1:]))
            gov_states = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), gov0, states)
            t_m = jnp.concatenate([gov.torque(gov0, dw[0])[None], t_m])
        else:
            _, (gov_states, t_m) = jax.lax.scan(heun, gov0, (jnp.concatenate([dw_prev[None], dw[:-1]]), dw))
        u = jnp.stack([cut(bus_all), cut(rotor_all), t_m - te, jnp.ones_like(te), t_m - t_m0])   # [5, size]
        if first:
            u_prev = u[:, 0]
            x0 = jnp.zeros((discs[0].shape[0], 5, 3), u.dtype).at[:, :, 0].set(u_prev)
        u_all = jnp.concatenate([u_prev[:, None], u], axis=1)
        designs, zs, last = jax.vmap(one_filter, in_axes=(0, 0, None))(discs, x0, u_all)
        w = ((elapsed + jnp.arange(size)) * dt >= s.settle_s).astype(u.dtype)
        block = Blocks(normal=jnp.einsum("ftp,ftq,t->fpq", designs, designs, w),
                       rhs=jnp.einsum("ftp,ft,t->fp", designs, zs, w),
                       zz=jnp.einsum("ft,ft,t->f", zs, zs, w), z=jnp.einsum("ft,t->f", zs, w),
                       count=jnp.sum(w))
        gov_last = jax.tree_util.tree_map(lambda x: x[-1], gov_states)
        return (smooth[size - 1], x2[-1], gov_last, dw[-1], last, u[:, -1], elapsed + size), block

    state, blocks = chunk(state, 0, carry is None)
    if chunks > 1:   # the others in a loop: a chunk's arrays at a time, however long the slice
        state, rest = jax.lax.scan(lambda st, k: chunk(st, k, False), state, jnp.arange(1, chunks))
        blocks = jax.tree_util.tree_map(lambda a, b: jnp.concatenate([a[None], b]), blocks, rest)
    smooth, x2, governor, dw, filters, signals, elapsed = state
    new = Carry(context=next_context(fe, ctx, own), filters=filters, signals=signals, smooth=smooth, x2=x2,
                governor=governor, dw=dw, t_ref=t_ref, t_m0=t_m0, elapsed=elapsed)
    return blocks, new


def _t975(dof):
    """Student's t 97.5 % quantile for ``dof`` degrees of freedom (Cornish-Fisher expansion to
    1/dof^3: within 1 % of the exact value at 3 degrees of freedom, 0.1 % from 5)."""
    z = Z95
    g1 = (z**3 + z) / 4.0
    g2 = (5 * z**5 + 16 * z**3 + 3 * z) / 96.0
    g3 = (3 * z**7 + 19 * z**5 + 17 * z**3 - 15 * z) / 384.0
    return z + g1 / dof + g2 / dof**2 + g3 / dof**3


def window_estimate(blocks: Blocks, present, plant: Plant, identify_settings: IdentifySettings,
                    window: WindowSettings, t_ref, t_m0) -> Identified:
    """The estimate of a window from its blocks, oldest first (``present``: [blocks] which of
    them hold a chunk), with ``t_ref`` and ``t_m0`` of the segment (:class:`Carry`).

    The same :class:`Identified` as the batch fit's, with its noise part from the blocks'
    sandwich and ``noise_levels`` NaN (not measured on a stream). Pure: jit and vmap pass through.
    """
    s = identify_settings
    w = present.astype(blocks.zz.dtype)
    tot = jax.tree_util.tree_map(lambda x: jnp.einsum("b...,b->...", x, w), blocks)
    thetas = jax.vmap(solve_spd)(tot.normal, tot.rhs)                    # [filters, 4]
    theta, info = thetas[0], tot.normal[0]
    rss = (tot.zz - 2.0 * jnp.sum(thetas * tot.rhs, axis=1)
           + jnp.einsum("fp,fpq,fq->f", thetas, tot.normal, thetas))
    tss = tot.zz - tot.z**2 / jnp.maximum(tot.count, 1.0)
    explained = 1.0 - rss / jnp.maximum(tss, 1e-300)
    g = (blocks.rhs[:, 0] - jnp.einsum("bpq,q->bp", blocks.normal[:, 0], theta)) * w[:, None]
    lags = math.ceil(s.hac_window_s / window.update_s)
    meat = g.T @ g
    for lag in range(1, min(lags, window.blocks - 1) + 1):
        cross = g[lag:].T @ g[:-lag]
        meat = meat + (1.0 - lag / (lags + 1.0)) * (cross + cross.T)
    bread = solve_spd(info, jnp.eye(4, dtype=info.dtype))
    # Few blocks: the meat is estimated from B block scores with 4 coefficients fitted; widen by
    # B / (B - 4) and by Student's t over the normal quantile (B - 4 degrees of freedom), so that
    # a short window's interval is not the large-sample one (x1.21 at 20 blocks, x1.06 at 60).
    b = jnp.sum(w)
    dof = jnp.maximum(b - 4.0, 1.0)
    meat = meat * (b / dof) * (_t975(dof) / Z95) ** 2
    a2_without = jnp.stack([_fit_without(info, tot.rhs[0], j)[1] for j in (0, 3)])
    if s.spread_scales:
        spread, fits = refit_spread(theta[1], thetas[1:, 1], explained[0], explained[1:])
    else:
        spread, fits = jnp.zeros((), info.dtype), jnp.zeros((), jnp.int32)
    return _result(theta, bread @ meat @ bread, info, plant.machine.omega_s, tot.count, spread, fits,
                   jnp.full(5, jnp.nan, info.dtype), jnp.array(False), s.model_error, t_ref, t_m0,
                   a2_without)
