"""Per-unit windowed identification of a live stream, on the host: frames in, updates out.

:class:`OnlineGroup` holds the units of one plant structure that report at one frame rate
(every unit of a fleet on one concentrator, or a part of it). Frames are pushed in grid order
(the monitor's reorder buffer sees to that), each with every unit's phasors in per unit, its
frequency and whether the unit's sample is usable (STAT and NaN screened by the caller). Per
unit, as the file readers do (``jaxdse._io.measurement``):

* a run of unusable or missing frames up to ``max_gap_s`` is bridged, once the next usable
  sample arrives, by linear interpolation of the magnitudes, the unwrapped angles and the
  frequency; a longer one ends the segment, and the unit's estimator restarts at the next
  usable sample (``Update.segment`` counts them);
* chunks of ``update_s`` start on the reporting grid (grid index a multiple of the chunk's
  samples), so that every unit of the group is ready at the same frame and one vmapped call
  (:func:`jaxdse._core.windowed.window_chunk`) serves them all; a restarted unit waits for the
  next chunk boundary;
* a segment's first chunk waits for the segment's first ``qss_window_s`` (at most
  ``window_s``: :meth:`~jaxdse._core.windowed.WindowSettings.start_samples`), which give T_ref
  and the governor's initial state; the same call gives the blocks of every chunk those samples
  hold (one front end and a loop over the chunks, not a call per chunk: at a start, every unit
  of every stream reaches it in the same second), and the chunks after them follow as the frames
  come;
* with ``defer`` (the live monitor), a start (no unit of the group has an estimate yet) and a
  few units (the small batch's) that restart while others of their group have estimates are
  background work: their chunks wait for :meth:`OnlineGroup.catch_up`, which the monitor calls
  when no frame is waiting, so that they delay neither the frames nor the estimates in
  service; a unit whose backlog reaches ``BACKGROUND_LAG_S`` is served with the frames again;
* with ``defer`` too, the programs are dispatched and not waited for: the window estimates'
  updates are read once computed (:meth:`OnlineGroup.collect` in the monitor's spare time, or
  by a push half an update after their dispatch), while the main thread goes on with the
  frames; at most ``MAX_PENDING`` wait unread.

Each chunk's block goes into its unit's ring of the window's blocks, in place; after it, a unit
whose window is full gets an :class:`Update` (H and D with their 95 % intervals and the verdict
of the window), from the window estimate, which runs only then. Three compiled programs per
group besides the pushes: a segment's first chunk, the chunks after it, and the window
estimate; each on the whole group and, for a chunk that few units are ready for (a restarted
unit; a late sample), on a small batch (:data:`SMALL_SHARE`).
"""

from __future__ import annotations

import collections
import dataclasses
import functools
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._core.algebraic import q_axis_discretisation
from .._core.drem import ObserverConfig
from .._core.identify import IdentifySettings
from .._core.plant import Plant
from .._core.recording import Recording
from .._core.settings import Settings
from .._core.verdict import VERDICTS, Verdict, VerdictSettings, describe, verdict
from .._core.windowed import Blocks, WindowSettings, halo, window_chunk, window_estimate
from .._many.batch import stack

WORDS = {"identified": "identified", "weakly identified": "weakly identified",
         "not identified": "not excited", "failed": "failed"}
"""The verdict of a window in the monitor's words: a window whose interval of H is too wide
to name a value did not excite H (ambient data), and gets no number."""


@dataclasses.dataclass(frozen=True)
class Update:
    """One unit's windowed estimate, at the end of a chunk."""

    t: float
    """Timestamp of the window's last sample [s since 1970]."""
    unit: str
    h_s: float | None
    """H [s]; None unless the window identifies it (``verdict`` identified or weakly)."""
    h_ci95: tuple[float, float] | None
    d_pu_s: float | None
    """D [pu torque per rad/s]; None with H."""
    d_ci95: tuple[float, float] | None
    verdict: str
    """identified, weakly identified, not excited or failed."""
    reasons: tuple[str, ...]
    age_s: float | None
    """Seconds since the last window that identified H ended (0 for this one; None: none yet)."""
    last_h_s: float | None
    """The H of that window [s]."""
    segment: int
    """Segments of this unit so far (a long gap starts a new one, and a new estimator)."""
    window_s: float
    samples: int

    def json(self) -> dict:
        return dataclasses.asdict(self)


def _per_unit(chunk, recs, *batched):
    """``chunk(rec, *args)`` of every unit, vmapped over the units (``recs``' signals [U, T] and
    ``batched``) with the time axis ``recs.t_s`` [T] shared, not batched: the filters'
    discretisations (matrix exponentials of dt) are then computed once per call, not once per
    unit (at 966 units they were two thirds of a chunk's CPU time)."""
    ts = recs.t_s

    def one(v, va, im, ia, f, *args):
        rec = Recording(t_s=ts, v_mag_pu=v, v_ang_rad=va, i_mag_pu=im, i_ang_rad=ia, f_hz=f,
                        location=recs.location)
        return chunk(rec, *args)

    return jax.vmap(one)(recs.v_mag_pu, recs.v_ang_rad, recs.i_mag_pu, recs.i_ang_rad, recs.f_hz, *batched)


class _Static:
    """The non-array part of a call's arguments as a key of jax.jit's cache (its treedef and
    leaves, compared and hashed as eqx.filter_jit compares them)."""

    def __init__(self, tree):
        self.tree = tree
        leaves, self.treedef = jax.tree_util.tree_flatten(tree)
        self.key = (self.treedef, tuple(leaves))

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return isinstance(other, _Static) and self.key == other.key


def _dispatched(fun):
    """``fun`` compiled over the array leaves of its arguments, the rest static (as
    eqx.filter_jit), that returns once the call is dispatched: eqx.filter_jit waits for each
    result (to raise its runtime errors there), and the monitor's main thread then waited for
    every chunk (a start's first chunk, 1-2 s a group of 836 units, with the frames and the
    system inertia's lines queued behind it). The outputs' non-array leaves are kept from the
    trace. A runtime error is raised where the result is read (:meth:`OnlineGroup.collect`)."""
    rest = {}

    @functools.partial(jax.jit, static_argnums=0)
    def run(static, dynamic):
        arrays, rest[static] = eqx.partition(fun(*eqx.combine(dynamic, static.tree)), eqx.is_array)
        return arrays

    @functools.wraps(fun)
    def call(*args):
        dynamic, static = eqx.partition(args, eqx.is_array)
        key = _Static(static)
        arrays = run(key, dynamic)
        return eqx.combine(arrays, rest[key])

    return call


@_dispatched
def _first(recs, plants, q_disc, config, settings, ident, size, start, chunks):
    """A segment's first slice: the blocks of its first ``chunks`` chunks ([U, chunks, ...]) in one call."""
    return _per_unit(
        lambda r, p, q: window_chunk(r, p, config, settings, ident, None, size, start, q, chunks),
        recs, plants, q_disc)


@_dispatched
def _next(recs, plants, q_disc, carries, config, settings, ident, size):
    return _per_unit(lambda r, p, q, c: window_chunk(r, p, config, settings, ident, c, size, q_disc=q),
                     recs, plants, q_disc, carries)


@eqx.filter_jit
def _q_discs(plants, dt):
    """Each unit's q-axis discretisation at ``dt`` (None without ``Machine.q_axis``): once per group."""
    if plants.machine.q_axis is None:
        return None
    return jax.vmap(lambda m: q_axis_discretisation(m, dt))(plants.machine)


def _leading(mask, x):
    return mask.reshape((-1,) + (1,) * (x.ndim - 1))


@functools.partial(jax.jit, donate_argnums=0)
def _push(ring, pos, blocks, ready):
    """Each ready unit's block into its ring at ``pos`` [U] (``filled % blocks``), in place: the
    rings are donated (a copy of a thousand units' rings cost a chunk tens of milliseconds)."""
    units = jnp.arange(pos.shape[0])
    return jax.tree_util.tree_map(
        lambda r, b: r.at[units, pos].set(jnp.where(_leading(ready, b), b, r[units, pos])), ring, blocks)


@functools.partial(jax.jit, donate_argnums=0)
def _push_first(ring, blocks, ready):
    """A segment's first blocks ([U, k, ...], k < the window's blocks) into the empty rings of
    the ready units, in place."""
    k = jax.tree_util.tree_leaves(blocks)[0].shape[1]
    return jax.tree_util.tree_map(lambda r, b: r.at[:, :k].set(jnp.where(_leading(ready, b), b, r[:, :k])),
                                  ring, blocks)


@_dispatched
def _estimates(ring, filled, carries, plants, ident, window, verdict_settings):
    """The window estimate and verdict of every unit from its ring (called once a unit's window
    is full: while every window fills, at a start, a chunk costs no estimate)."""
    n = window.blocks
    order = (filled[:, None] + jnp.arange(n)[None, :]) % n          # oldest first once full
    ordered = jax.tree_util.tree_map(lambda r: jnp.take_along_axis(
        r, order.reshape(order.shape + (1,) * (r.ndim - 2)), axis=1), ring)
    present = jnp.arange(n)[None, :] >= n - jnp.minimum(filled, n)[:, None]

    def one(b, p, plant, c):
        ident_ = window_estimate(b, p, plant, ident, window, c.t_ref, c.t_m0)
        return ident_, verdict(None, ident_, None, verdict_settings)

    return jax.vmap(one)(ordered, present, plants, carries)


SMALL_SHARE = 8
"""A chunk that only a few units of a group are ready for (a restarted unit's; a unit whose
sample came late) runs on a batch of ceil(U / SMALL_SHARE) rows, the ready units' (the first
repeated to fill it), gathered and scattered back, not on the group's whole batch: at 966 units
a restarted plant's 46 copies cost a 3.9 s whole-batch first chunk. Groups of ``MIN_SMALL``
units or more."""
MIN_SMALL = 16
MAX_PENDING = 12
"""Dispatched estimates of a group that the monitor may leave unread (:meth:`OnlineGroup.collect`)
before the next frame waits for the oldest."""
BACKGROUND_LAG_S = 30.0
"""The stream time a deferred unit's chunks may fall behind the frames [s] (buffer room:
5 x 8 bytes per unit and sample) before they run with the frames again: at a start of 4,788
units on 2 cores the last group's first chunk waits about 10 s for the five before it."""


class OnlineGroup:
    """The windowed identification of units of one plant structure at one frame rate."""

    def __init__(self, names: Sequence[str], plants: Sequence[Plant], locations: Sequence[str],
                 frame_rate_hz: float, window: WindowSettings = WindowSettings(),
                 config: ObserverConfig = ObserverConfig(), settings: Settings = Settings(),
                 identify_settings: IdentifySettings = IdentifySettings(),
                 verdict_settings: VerdictSettings = VerdictSettings(), max_gap_s: float = 0.5,
                 with_frequency: bool = True, defer: bool = False):
        if len({str(loc) for loc in locations}) != 1:
            raise ValueError("OnlineGroup: one PMU location per group")
        self.names = list(names)
        self.u = len(self.names)
        self.plants = stack(list(plants))
        self.location = locations[0]
        self.rate = float(frame_rate_hz)
        self.dt = 1.0 / self.rate
        self.window, self.config, self.settings = window, config, settings
        self.ident, self.verdict_settings = identify_settings, verdict_settings
        self.size = window.chunk_samples(self.rate)
        self.halo = halo(settings)
        self.tail = window.tail_samples(self.rate, settings)
        self.start = window.start_samples(self.rate, settings)
        self.max_gap = int(math.floor(max_gap_s * self.rate + 1e-6))
        self.with_frequency = with_frequency
        self.span = self.halo + self.size + self.tail
        # the chunks that a segment's first slice holds (fewer than a window's: no estimate yet)
        self.first_chunks = max(1, min(1 + self.start // self.size, self.window.blocks - 1))
        self.defer = defer
        self.lag = int(round(BACKGROUND_LAG_S * self.rate)) if defer else 0
        self.capacity = self.span + self.start + self.size + self.max_gap + 2 + self.lag
        self.buf = np.full((5, self.u, self.capacity), np.nan)
        self.base = None                 # grid index of buffer column 0
        self.last_valid = np.full(self.u, -1, np.int64)   # grid index of each unit's last usable sample
        self.slice_start = np.full(self.u, -1, np.int64)  # grid index of the next slice (-1: none yet)
        self.seg_start = np.full(self.u, -1, np.int64)
        self.segment = np.zeros(self.u, np.int64)
        self.started = np.zeros(self.u, bool)             # the segment's first chunk is done
        self.small = -(-self.u // SMALL_SHARE) if self.u >= MIN_SMALL else 0   # rows of the few-units batch
        self.q_disc = _q_discs(self.plants, self.dt)   # the slices' step: t_s = arange(span) dt
        self.carries = None
        self.ring = None
        self.filled = np.zeros(self.u, np.int32)   # blocks in each ring (host: a restart is no device op)
        self.last_h = [None] * self.u
        self.last_h_t = [None] * self.u
        self.pending = collections.deque()   # with defer: dispatched estimates not yet read (collect)
        self.computing = None                # an output of the latest chunk dispatched

    # --- samples ---------------------------------------------------------------------------

    def push(self, index: int, v_mag, v_ang, i_mag, i_ang, f_hz, usable) -> list[Update]:
        """One frame at grid ``index`` (increasing): per unit [U] arrays in pu, rad and Hz, and
        whether its sample is usable. Returns the updates of the chunks it completes."""
        if self.base is None:
            self.base = index
        out = []
        # a unit whose gap outgrows max_gap leaves the buffer's keeping: its deferred chunks
        # (those its samples before the gap complete) run now, not at its restart
        while (self._ready()[0] & (self.last_valid < index - self.max_gap - 1)).any():
            out += self._chunks(defer=False)
        self._make_room(index)
        col = index - self.base
        values = np.stack([np.asarray(v_mag, float), np.asarray(v_ang, float), np.asarray(i_mag, float),
                           np.asarray(i_ang, float), np.asarray(f_hz, float)])
        usable = np.asarray(usable, bool) & np.all(np.isfinite(values[:4]), axis=0)
        self.buf[:, :, col] = np.where(usable[None], values, np.nan)
        gap = index - self.last_valid - 1
        bridge = usable & (self.last_valid >= 0) & (gap > 0) & (gap <= self.max_gap)
        for u in np.flatnonzero(bridge):
            self._bridge(u, self.last_valid[u] - self.base, col)
        restart = usable & ((self.last_valid < 0) | (gap > self.max_gap))
        if restart.any():
            self._restart(np.flatnonzero(restart), index)
        self.last_valid = np.where(usable, index, self.last_valid)
        return out + self._chunks() + self.collect(most=0, late_from=index - self.size // 2)

    def _make_room(self, index: int):
        col = index - self.base
        if col < self.capacity:
            return
        # Units in a gap longer than max_gap restart at their next sample: their slices are void.
        live = (self.slice_start >= 0) & (self.last_valid >= index - self.max_gap - 1)
        keep_from = min([index - self.max_gap - 1, *self.slice_start[live].tolist()])
        shift = keep_from - self.base
        if shift <= 0 or index - keep_from >= self.capacity:
            raise RuntimeError("OnlineGroup: buffer too small")   # not reached: capacity covers a slice
        self.buf[:, :, :-shift] = self.buf[:, :, shift:]
        self.buf[:, :, -shift:] = np.nan
        self.base += shift

    def _bridge(self, u: int, a: int, b: int):
        """Linear interpolation of unit ``u`` between its usable columns a and b."""
        w = (np.arange(a + 1, b) - a) / (b - a)
        x = self.buf[:, u]
        for ch in range(5):
            lo, hi = x[ch, a], x[ch, b]
            if ch in (1, 3):    # angles: b's within pi of a's
                hi = lo + math.remainder(hi - lo, 2.0 * math.pi)
            x[ch, a + 1:b] = lo + (hi - lo) * w

    def _restart(self, units: np.ndarray, index: int):
        """A new segment for ``units`` (indices) from grid ``index``: their first slice starts at
        the next chunk boundary of the grid (host arrays only: an eager device scatter was compiled
        anew for each number of units restarting at once, seconds on a loaded machine)."""
        self.segment[units] += 1
        self.seg_start[units] = index
        self.slice_start[units] = -(-index // self.size) * self.size
        self.started[units] = False
        self.filled[units] = 0

    def warm_up(self):
        """Run the group's programs once on a flat batch (1 pu, the nominal frequency), on the
        whole group and on the few-units batch (``SMALL_SHARE``), and drop the results: the
        compiler's time is spent now, while the window fills, and not at the segment's first
        chunk, where frames would queue behind it (10 s on a loaded 2-core machine: at 5x real
        time, 50 s of stream). The group's state is not touched."""
        def flat(span, n):
            one = np.ones((n, span))
            f_nom = np.asarray(self.plants.machine.f_nominal_hz, float).reshape(-1, 1)[:n]
            return Recording(t_s=np.arange(span) * self.dt, v_mag_pu=one, v_ang_rad=0.0 * one,
                             i_mag_pu=0.5 * one, i_ang_rad=-0.1 * one,
                             f_hz=one * f_nom if self.with_frequency else None, location=self.location)

        def programs(n, plants, q_disc):
            first, carries = _first(flat(self.span + self.start, n), plants, q_disc, self.config,
                                    self.settings, self.ident, self.size, self.start, self.first_chunks)
            jax.block_until_ready(_initial(first, carries, True, self.window.blocks, self.u, n == self.u))
            blocks, carries = _next(flat(self.span, n), plants, q_disc, carries, self.config, self.settings,
                                    self.ident, self.size)
            ring = _empty_ring(blocks, self.window.blocks)
            if n == self.u:
                _where(jnp.ones(n, bool), carries, carries)
            ring = _push_first(ring, first, jnp.ones(n, bool))
            ring = _push(ring, jnp.zeros(n, np.int32), blocks, jnp.ones(n, bool))
            jax.block_until_ready(_estimates(ring, jnp.zeros(n, np.int32), carries, plants, self.ident,
                                             self.window, self.verdict_settings))
            return carries, ring

        carries, ring = programs(self.u, self.plants, self.q_disc)
        if self.small:
            rows = np.zeros(self.small, np.int64)
            small = programs(self.small, *_take((self.plants, self.q_disc), rows))
            _take(carries, rows), _take(ring, rows)
            jax.block_until_ready(_put((carries, ring), rows, small))

    # --- progress ----------------------------------------------------------------------------

    def first_update_samples(self) -> int:
        """Samples from a segment's first chunk boundary to its first update: the first chunk's
        slice (with T_ref's stretch), then chunks until the window is full, each with its tail."""
        return max(self.span + self.start, (self.window.blocks - 1) * self.size + self.span)

    def filling(self) -> tuple[np.ndarray, np.ndarray]:
        """Per unit, while its window fills (no update yet in its segment): the stream time its
        segment holds [s] and the stream time its first update needs [s], both from the
        segment's first sample; NaN for units whose window is full."""
        seen = self.seg_start >= 0
        first_slice = -(-self.seg_start // self.size) * self.size
        have = np.where(seen, self.last_valid - self.seg_start + 1, 0)
        need = np.where(seen, first_slice - self.seg_start, 0) + self.first_update_samples()
        full = np.asarray(self.filled) >= self.window.blocks
        return (np.where(full, np.nan, have / self.rate).astype(float),
                np.where(full, np.nan, need / self.rate).astype(float))

    def wait_reason(self) -> str:
        """What a segment's first update waits for, in words."""
        stretch = (self.start + self.size + self.tail) / self.rate
        return (f"T_ref and the governor's start from the segment's first {stretch:g} s, then a full "
                f"{self.window.window_s:g} s window and the {self.tail / self.rate:g} s after it")

    # --- chunks ------------------------------------------------------------------------------

    def _slices(self, units, span):
        starts = self.slice_start[units] - self.base
        if units.size == self.u and np.all(units == np.arange(self.u)) and np.all(starts == starts[0]):
            x = self.buf[:, :, starts[0]:starts[0] + span].copy()    # every unit at one column: a block copy
        else:
            x = self.buf[:, units[:, None], starts[:, None] + np.arange(span)[None, :]]   # [5, k, span]
        t = np.arange(span) * self.dt
        f = x[4] if self.with_frequency else None
        return Recording(t_s=t, v_mag_pu=x[0], v_ang_rad=x[1],
                         i_mag_pu=x[2], i_ang_rad=x[3], f_hz=f, location=self.location)

    def _batch(self, rows, which, span):
        """The slices of the units ``rows`` (a batch), cut from the host buffer; rows not in
        ``which`` repeat the first that is (NumPy indexing: a Recording's fields are already JAX
        arrays, and an eager gather on each cost about 7 ms per update on a loaded 2-core
        machine)."""
        return self._slices(np.where(which, rows, rows[np.argmax(which)]), span)

    def _ready(self):
        span = np.where(self.started, self.span, self.span + self.start)   # a first slice: longer
        return (self.slice_start >= 0) & (self.last_valid >= self.slice_start + span - 1), span

    def behind(self) -> bool:
        """Whether chunks are ready that no push ran (deferred ones)."""
        return bool(self._ready()[0].any())

    def catch_up(self) -> list[Update]:
        """One chunk of every unit whose chunk is ready, deferred ones included."""
        return self._chunks(defer=False) + self.collect()

    def first_behind(self) -> bool:
        """Whether a segment's first chunk is ready and not run (deferred)."""
        ready, _ = self._ready()
        return bool((ready & ~self.started).any())

    def waiting(self) -> bool:
        """Whether estimates were dispatched that :meth:`collect` has not read yet."""
        return bool(self.pending)

    def busy(self) -> bool:
        """Whether the computer still works on this group's latest chunk or estimate (the
        monitor gives a group its next deferred chunk only then)."""
        return (self.computing is not None and not self.computing.is_ready()) or any(
            not ready() for ready, *_ in self.pending)

    def collect(self, wait: bool = False, most: int | None = None, late_from: int | None = None) -> list[Update]:
        """The updates of the dispatched estimates that are done, oldest first: of ``most`` of
        them (None: all), and besides of those dispatched at grid index ``late_from`` or before
        (a push reads only those dispatched half an update ago, so that a frame does not wait
        while a thousand updates are written, unless no spare time came for them); with
        ``wait`` of all, waiting for each; beyond ``MAX_PENDING`` the oldest is waited for (the
        frames must not run ahead of the computer without bound)."""
        out = []
        while self.pending:
            ready, sent = self.pending[0][:2]
            forced = wait or len(self.pending) > MAX_PENDING
            late = late_from is not None and sent <= late_from
            if not forced and (((most is not None and most <= 0) and not late) or not ready()):
                break
            out += self._read(*self.pending.popleft()[2:])
            most = None if most is None else most - 1
        return out

    def _chunks(self, defer: bool | None = None) -> list[Update]:
        ready, span = self._ready()
        if (self.defer if defer is None else defer) and ready.any():
            # background, up to the lag: a few units in a new segment (the small batch's) while
            # others are in service, and every unit's while none is (a start: every unit of every
            # stream reaches its first chunk in the same second, and the frames and the system
            # inertia's lines would wait behind them); a larger restart runs with the frames
            filling = self.filled < self.window.blocks
            behind = self.last_valid - (self.slice_start + span - 1)
            later = ready & filling & (behind < self.lag)
            if filling.all() or later.sum() <= self.small:
                ready &= ~later
            # in service but a chunk or more behind (after a start): its catch-up is background
            # too, or every frame would run a chunk of them (30 a second, each ~0.1 s at 836 units)
            ready &= ~(~filling & (behind >= self.size) & (behind < self.lag))
        if not ready.any():
            return []
        t_end = (self.slice_start + self.halo + self.size - 1) / self.rate
        # a segment's first chunks, then the others: each set on the whole batch or the small one
        jobs = [j for j in (self._run(ready & ~self.started), self._run(ready & self.started)) if j]
        first = ready & ~self.started
        self.started |= ready
        step = np.where(first, self.first_chunks, 1) * self.size
        self.slice_start = np.where(ready, self.slice_start + step, self.slice_start)
        if not jobs:
            return []
        entry = (jobs, t_end, self.segment.copy())
        if not self.defer:
            return self._read(*entry)
        done = [jax.tree_util.tree_leaves(j[3])[-1] for j in jobs]
        sent = int(self.last_valid.max())
        self.pending.append((lambda: all(x.is_ready() for x in done), sent, *entry))
        return []

    def _read(self, jobs, t_end, segment) -> list[Update]:
        """The updates of ``jobs`` (``_run``'s), sorted by unit."""
        out = []
        for units, pos, idents, verdicts in jobs:
            out += zip(units.tolist(), self._updates(units, pos, idents, verdicts, t_end, segment))
        return [u for _, u in sorted(out, key=lambda x: x[0])]

    def _run(self, ready):
        """The chunks of the units ``ready`` (all of them a segment's first chunk, or none): their
        blocks into their rings, then the estimates of those whose window is full, dispatched:
        (their units, their rows in the estimates, the estimates, the verdicts), or None."""
        units = np.flatnonzero(ready)
        if units.size == 0:
            return None
        first = not self.started[units[0]]
        whole = not (self.small and units.size <= self.small)
        rows = np.arange(self.u) if whole else np.resize(units, self.small)   # the batch's units
        plants, q_disc = (self.plants, self.q_disc) if whole else _take((self.plants, self.q_disc), rows)
        if first:
            recs = self._batch(rows, ready[rows], self.span + self.start)
            blocks, carries = _first(recs, plants, q_disc, self.config, self.settings, self.ident, self.size,
                                     self.start, self.first_chunks)
        else:
            recs = self._batch(rows, ready[rows], self.span)
            blocks, carries = _next(recs, plants, q_disc, self.carries if whole else _take(self.carries, rows),
                                    self.config, self.settings, self.ident, self.size)
        self.computing = jax.tree_util.tree_leaves(blocks)[-1]
        if self.carries is None:     # every row from the first ready unit's until its own chunk
            self.carries, self.ring = _initial(blocks, carries, first, self.window.blocks, self.u, whole)
        n = self.window.blocks
        if whole:
            self.carries = _where(jnp.asarray(ready), carries, self.carries)
            if first:
                self.ring = _push_first(self.ring, blocks, jnp.asarray(ready))
            else:
                self.ring = _push(self.ring, jnp.asarray(self.filled % n), blocks, jnp.asarray(ready))
            self.filled = np.where(ready, self.first_chunks if first else self.filled + 1,
                                   self.filled).astype(np.int32)
            ring, filled, carries, pos = self.ring, self.filled, self.carries, units
        else:     # every row is ready (a row given twice: the same values)
            ring, ones = _take(self.ring, rows), jnp.ones(rows.size, bool)
            if first:
                ring = _push_first(ring, blocks, ones)
            else:
                ring = _push(ring, jnp.asarray(self.filled[rows] % n), blocks, ones)
            self.filled[rows] = self.first_chunks if first else self.filled[rows] + 1
            filled = self.filled[rows]
            self.carries, self.ring = _put((self.carries, self.ring), rows, (carries, ring))
            pos = np.arange(units.size)      # np.resize put the ready units first
        done = self.filled[units] >= n
        if not done.any():
            return None
        idents, verdicts = _estimates(ring, jnp.asarray(filled), carries, plants,
                                      self.ident, self.window, self.verdict_settings)
        return units[done], pos[done], idents, verdicts

    def _updates(self, units, pos, idents, verdicts, t_end, segment) -> list[Update]:
        """The :class:`Update` of each unit in ``units``, whose estimate is row ``pos`` of
        ``idents`` and ``verdicts``: the fields it needs are taken to the host once for the
        group, as Python numbers (a per-unit slice of the whole estimate cost about 0.1 ms per
        unit, a tenth of a second per frame at a thousand units)."""
        if units.size == 0:
            return []
        h, h_ci, d, d_ci, samples, codes, bits = (np.asarray(x)[pos].tolist() for x in (
            idents.h_s, idents.h_ci95, idents.d_pu_s, idents.d_ci95, idents.samples, verdicts.code,
            verdicts.reasons))
        words = {}
        out = []
        window_s = self.window.window_s     # once: an equinox field read, 1-5 us, was a quarter of this loop
        for k, u in enumerate(units.tolist()):
            key = (codes[k], bits[k])
            if key not in words:
                word, reasons = describe(Verdict(code=codes[k], reasons=bits[k], d_code=0, governor_code=0))
                words[key] = (WORDS[word], tuple(reasons))
            word, reasons = words[key]
            t = float(t_end[u])
            named = word in ("identified", "weakly identified")
            if word == "identified":
                self.last_h[u], self.last_h_t[u] = float(h[k]), t
            out.append(Update(
                t=t, unit=self.names[u],
                h_s=float(h[k]) if named else None,
                h_ci95=(float(h_ci[k][0]), float(h_ci[k][1])) if named else None,
                d_pu_s=float(d[k]) if named else None,
                d_ci95=(float(d_ci[k][0]), float(d_ci[k][1])) if named else None,
                verdict=word, reasons=reasons,
                age_s=None if self.last_h_t[u] is None else round(t - self.last_h_t[u], 9),
                last_h_s=self.last_h[u], segment=int(segment[u]), window_s=window_s,
                samples=int(samples[k])))
        return out


def _empty_ring(blocks, n):
    """A ring of ``n`` empty blocks per unit, shaped after ``blocks`` [U, ...]."""
    return jax.tree_util.tree_map(lambda b: jnp.zeros((b.shape[0], n) + b.shape[1:], b.dtype), blocks)


@functools.partial(jax.jit, static_argnums=(2, 3, 4, 5))
def _initial(blocks, carries, first, n, u, whole):
    """A group's carries and empty rings ([u] rows) from its first chunk's ``blocks`` and
    ``carries`` (a segment's first: [rows, k, ...]; ``whole``: of the whole group, else every row
    the first's), in one compiled call (eager, the slices compiled at the first chunk, ~1 s)."""
    one = jax.tree_util.tree_map(lambda b: b[:, 0], blocks) if first else blocks
    rows = jnp.arange(u) if whole else jnp.zeros(u, int)
    return jax.tree_util.tree_map(lambda x: x[rows], (carries, _empty_ring(one, n)))


@jax.jit
def _take(tree, rows):
    """Rows ``rows`` of every leaf (leading axis: units)."""
    return jax.tree_util.tree_map(lambda x: x[rows], tree)


@functools.partial(jax.jit, donate_argnums=0)
def _put(tree, rows, values):
    """``tree`` with its rows ``rows`` set to ``values`` (a row given twice: the same values); the
    group's state is donated and updated in place, not copied whole for a few rows."""
    return jax.tree_util.tree_map(lambda x, v: x.at[rows].set(v), tree, values)


@jax.jit
def _where(mask, a, b):
    """Per unit (leading axis): a where ``mask``, else b (one compiled call for the whole
    pytree: eager, each leaf was a dispatch of its own)."""
    return jax.tree_util.tree_map(
        lambda x, y: jnp.where(mask.reshape((-1,) + (1,) * (jnp.ndim(x) - 1)), x, y), a, b)


def verdict_words() -> tuple[str, ...]:
    """The verdicts an :class:`Update` can carry, best first."""
    return tuple(WORDS[v] for v in VERDICTS)


__all__ = ["Blocks", "OnlineGroup", "Update", "verdict_words"]
