"""Batches: many recordings and/or many configurations in one compiled, sharded call.

``estimate`` handles one generator and one configuration; here it is ``vmap``-ed over a
leading batch axis of whichever arguments carry one, and that axis is sharded over every
device of every process (``jax.sharding``; with ``jax.distributed`` across hosts).
Recordings of different lengths are padded at the end and masked (``Recording.n_samples``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.tree_util as jtu
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .._core.drem import ObserverConfig
from .._core.estimate import estimate
from .._core.plant import Plant
from .._core.recording import Recording, pad_end
from .._core.result import Estimate
from .._core.settings import Settings


def stack(modules: Sequence[eqx.Module]) -> eqx.Module:
    """Stack Modules of one structure (configurations, plants) along a new leading axis."""
    return jtu.tree_map(lambda *xs: np.stack([np.asarray(x) for x in xs]), *modules)


def stack_recordings(recordings: Sequence[Recording]) -> Recording:
    """Stack recordings of any lengths: pad each to the longest and record ``n_samples``.

    Padding continues the uniform time grid and repeats the last sample; every stage masks
    it, so each member's results equal those of its unpadded run.
    """
    if len({r.location for r in recordings}) != 1:
        raise ValueError("a batch of recordings must share one measurement location")
    size = max(int(np.shape(r.t_s)[0]) for r in recordings)
    with_f = any(r.f_hz is not None for r in recordings)
    return stack([pad_recording(r, size, with_f) for r in recordings])


def pad_recording(r: Recording, size: int, with_frequency: bool | None = None) -> Recording:
    """``r`` padded at the end to ``size`` samples (host arrays), with ``n_samples`` set.

    ``with_frequency=True`` gives a recording without a frequency channel an all-NaN one (the
    pipeline then derives f from the angle, as without a channel), so that recordings with and
    without one share one structure (one compilation); None keeps the recording's own choice.
    """
    def pad(x):
        return pad_end(x, size)

    f_hz = r.f_hz
    if f_hz is None and with_frequency:
        f_hz = np.full(np.shape(r.t_s), np.nan)
    return Recording(t_s=pad_end(r.t_s, size, time=True), v_mag_pu=pad(r.v_mag_pu),
                     v_ang_rad=pad(r.v_ang_rad), i_mag_pu=pad(r.i_mag_pu), i_ang_rad=pad(r.i_ang_rad),
                     f_hz=None if f_hz is None else pad(f_hz),
                     n_samples=np.asarray(np.shape(r.t_s)[0] if r.n_samples is None else r.n_samples),
                     location=r.location)


def batch_size(tree, *, recording: bool = False) -> int | None:
    """Leading batch size of a stacked argument, or None when it is a single one."""
    leaves = [np.shape(x) for x in jtu.tree_leaves(tree)]
    if not leaves:
        return None
    if recording:
        return leaves[0][0] if len(leaves[0]) == 2 else None
    ranks = {len(s) for s in leaves}
    if ranks == {0}:
        return None
    sizes = {s[0] for s in leaves if s}
    if 0 in ranks or len(sizes) != 1:
        raise ValueError("a batched Module needs a leading batch axis on every leaf; use jaxdse.stack")
    return sizes.pop()


_COMPILED: dict = {}


def _compiled(settings: Settings, axes: tuple, present: tuple, mesh: Mesh):
    """jit(shard_map(vmap(estimate))): each device runs its own slice of the batch, with no
    communication (the SPMD partitioner, left to itself, slows the vmapped time loop)."""
    key = (settings, axes, present, mesh)
    if key not in _COMPILED:
        def one(*args):
            full = iter(args)
            rec, plant, cfg, t_m, a2_ref = (next(full) if p else None for p in present)
            return estimate(rec, plant, cfg, settings, t_m, a2_ref)

        used = tuple(a for a, p in zip(axes, present) if p)
        specs = tuple(PartitionSpec("batch") if a == 0 else PartitionSpec() for a in used)
        local = jax.vmap(one, in_axes=used)
        _COMPILED[key] = jax.jit(jax.shard_map(local, mesh=mesh, in_specs=specs,
                                               out_specs=PartitionSpec("batch"), check_vma=False))
    return _COMPILED[key]


def _put(x, batched: bool, mesh: Mesh):
    """Place a host array on the mesh: split along the batch axis, or replicated."""
    x = np.asarray(x)
    sharding = NamedSharding(mesh, PartitionSpec("batch") if batched else PartitionSpec())
    return jax.make_array_from_callback(x.shape, sharding, lambda idx: x[idx])


def estimate_batch(recordings: Recording | Sequence[Recording], plant: Plant | Sequence[Plant],
                   config: ObserverConfig | Sequence[ObserverConfig], settings: Settings = Settings(),
                   t_m=None, a2_reference=None, *, chunk: int | None = None,
                   progress: Callable[[int], None] | None = None) -> Estimate:
    """Run :func:`estimate` over a batch in one compiled call per chunk.

    Any of ``recordings``, ``plant``, ``config`` (and ``t_m`` [B, T], ``a2_reference`` [B])
    may be a sequence or a stacked batch (leading axis B); the others are shared. All batched
    arguments must have the same B (they are zipped, not crossed).

    Arguments:
        settings: static choices; ``Settings(keep="final")`` keeps no per-sample arrays.
        chunk: at most this many batch members per compiled call (bounded memory, progress).
        progress: called with the number of members finished after each chunk.

    Returns:
        An :class:`Estimate` whose arrays (host NumPy) have a leading batch axis. The batch axis
        is sharded over all devices (``jax.devices()``: every local device, and every process
        after ``jax.distributed.initialize``); every process receives the whole result.
    """
    if isinstance(recordings, list | tuple):
        recordings = stack_recordings(recordings)
    if isinstance(plant, list | tuple):
        plant = stack(plant)
    if isinstance(config, list | tuple):
        config = stack(config)
    args = [recordings, plant, config, t_m, a2_reference]
    sizes = [batch_size(recordings, recording=True), batch_size(plant), batch_size(config),
             None if t_m is None or np.ndim(t_m) < 2 else np.shape(t_m)[0],
             None if a2_reference is None or np.ndim(a2_reference) == 0 else np.shape(a2_reference)[0]]
    found = {s for s in sizes if s is not None}
    if len(found) > 1:
        raise ValueError(f"batched arguments disagree on the batch size: {sorted(found)}")
    total = found.pop() if found else 1
    axes = tuple(None if s is None else 0 for s in sizes)
    if all(a is None for a in axes):  # a batch of one: give it a leading axis
        recordings = jtu.tree_map(lambda x: np.asarray(x)[None], recordings)
        args[0], axes = recordings, (0, *axes[1:])
    devices = jax.devices()
    mesh = Mesh(np.array(devices), ("batch",))
    present = tuple(a is not None for a in args)
    run = _compiled(settings, axes, present, mesh)
    step = min(chunk or total, total)
    step = -(-step // len(devices)) * len(devices)  # every device gets the same share
    parts = []
    for start in range(0, total, step):
        idx = np.minimum(np.arange(start, start + step), total - 1)  # pad with the last member
        part = [None if a is None else jtu.tree_map(
            lambda x, ax=ax: _put(np.asarray(x)[idx] if ax == 0 else x, ax == 0, mesh), a)
            for a, ax in zip(args, axes)]
        out = run(*(p for p in part if p is not None))
        if jax.process_count() > 1:
            out = multihost_utils.process_allgather(out, tiled=True)
        out = jtu.tree_map(lambda x: np.asarray(x)[: min(step, total - start)], out)
        parts.append(out)
        if progress is not None:
            progress(min(start + step, total))
    return jtu.tree_map(lambda *xs: np.concatenate(xs), *parts)


def select(batch, k: int):
    """Member ``k`` of a batched result or argument."""
    return jtu.tree_map(lambda x: x[k], batch)

