"""The one runner: many units (generators, recording segments, fleet plants) assessed at once.

Units are grouped by what one compiled function can share: a padded length (a few sizes per
octave), a PMU location and a plant structure. Each group is padded, stacked on the host,
and run through ``jit(vmap(assess))`` in chunks of a bounded size (memory: the bootstrap
holds ``bootstrap_draws`` front ends per unit), one chunk per CPU core at a time. The
results come back to the host once per chunk and are cut to each unit's own length and
shifted to its own start time. ``jaxdse run``, ``jaxdse fleet`` and ``jaxdse demo`` all
call :func:`assess_units`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import os
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import equinox as eqx
import jax
import jax.tree_util as jtu
import numpy as np
from jax._src import config as jax_config

from .._core.assess import Assessment, assess
from .._core.drem import ObserverConfig
from .._core.identify import IdentifySettings
from .._core.plant import Plant
from .._core.recording import Recording
from .._core.settings import Settings
from .._core.verdict import VerdictSettings
from .batch import pad_recording, stack
from .waits import Expired, Pool, Task

BUCKETS_PER_OCTAVE = 4
"""Recording lengths are padded up to one of 4 sizes per doubling (at most 19 % padding), so
that the units of a run share a few compiled shapes."""
RUN_BYTES = 3 * 2**30
"""Working memory [B] that the chunks on the pool of :func:`workers` threads may take
together; it sets the units per compiled call."""
BYTES_PER_SAMPLE = 8 * 80
"""Bytes per sample per front end held at once (~80 float64 arrays, measured on the bootstrap)."""
MAX_PLAYBACK_SUBSTEPS = 24
"""Adaptive playback steps per sample before a playback counts as diverged (the runner caps
``Integrator.max_substeps`` of the playback at it). Under vmap every unit waits for the
slowest, and a diverging playback would take the default 256 steps on every sample (the
ISO-NE run: 9.2 s against 1.9 s of run time); the units that follow their data need a few."""


@dataclasses.dataclass(frozen=True)
class _Plan:
    """One group of units: its padded length, its members (indices into the units), their
    stacked inputs (recordings, plants, a2 references) and the units per compiled call."""

    length: int
    members: list[int]
    inputs: tuple
    step: int


@dataclasses.dataclass(frozen=True)
class Unit:
    """One unit of work: a recording (segment) of one generator and its plant."""

    name: str
    recording: Recording
    plant: Plant
    t0_s: float = 0.0
    """Start time of the segment in the source file [s]; the results' time axes are shifted by it."""
    a2_reference: float | None = None
    """Known a2 [rad/s^2 per pu] (simulations), for the online estimate's convergence time."""


def bucket(n: int, minimum: int = 256) -> int:
    """The padded length for ``n`` samples: the next of 4 sizes per octave (>= ``minimum``)."""
    size = max(n, minimum)
    octave = 1 << (size - 1).bit_length() - 1
    for k in range(BUCKETS_PER_OCTAVE, 2 * BUCKETS_PER_OCTAVE + 1):
        if size <= octave * k // BUCKETS_PER_OCTAVE:
            return octave * k // BUCKETS_PER_OCTAVE
    return 2 * octave


def group_units(units: Sequence[Unit], size: int | None = None) -> dict[tuple, list[int]]:
    """Indices of ``units`` by (padded length, PMU location, plant structure); ``size`` pads
    every unit to one length instead (one compilation for a fleet)."""
    groups: dict = {}
    for k, u in enumerate(units):
        n = int(np.shape(u.recording.t_s)[0])
        key = (size or bucket(n), u.recording.location, jtu.tree_structure(u.plant))
        groups.setdefault(key, []).append(k)
    return groups


def cores() -> int:
    """CPU cores this process may run on (its affinity: ``taskset`` narrows it)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # no affinity on this platform
        return os.cpu_count() or 1


def workers(calls: int) -> int:
    """Compiled calls run at once: one per CPU core on CPU (each call runs its scans on about
    one core), one on other backends; at most ``calls``."""
    if jax.default_backend() != "cpu":
        return 1
    return max(1, min(calls, cores()))


def units_per_call(samples: int, identify_settings: IdentifySettings | None, units: int,
                   side_by_side: int = 1) -> int:
    """Units per compiled call of a group: as many as a share of ``RUN_BYTES`` holds, with
    ``side_by_side`` calls running at once; at most ``units``."""
    fronts = 2 + (identify_settings.bootstrap_draws if identify_settings is not None else 0)
    budget = RUN_BYTES // max(side_by_side, 1)
    return int(max(1, min(units, budget // (samples * fronts * BYTES_PER_SAMPLE))))


def planned_calls(units: Sequence[Unit], identify_settings: IdentifySettings | None, size: int | None = None,
                  chunk: int | None = None) -> int:
    """How many compiled calls :func:`assess_units` makes (for a progress bar's length)."""
    total = 0
    groups = group_units(units, size)
    side_by_side = _pool_size(groups)
    for (length, _, _), members in groups.items():
        step = chunk or units_per_call(length, identify_settings, len(members), side_by_side)
        total += -(-len(members) // step)
    return total


COMPILER_OPTIONS = {"xla_backend_optimization_level": 1, "xla_cpu_use_fusion_emitters": False}
"""XLA options of the pipeline's compile on CPU: LLVM at level 1 and XLA's classic emitters
instead of its MLIR fusion emitters compile it faster than XLA's defaults and run it as fast
(``benchmarks/compile_options.py``). Not applied under ``jax_disable_most_optimizations``."""


def _assess_vmapped(recs, plants, refs, config, settings, identify_settings, verdict_settings):
    return jax.vmap(lambda r, p, a: assess(r, p, config, settings, identify_settings, verdict_settings, a))(
        recs, plants, refs)


_assess_chunk = eqx.filter_jit(_assess_vmapped)
_JITTED: dict = {}


def _compiled_chunk(options: dict | None):
    """The jitted vmapped ``assess`` compiled with these XLA options; None: ``COMPILER_OPTIONS``
    on CPU, XLA's defaults under ``jax_disable_most_optimizations`` or on other backends."""
    if options is None:
        xla_defaults = jax.config.read("jax_disable_most_optimizations") or jax.default_backend() != "cpu"
        options = {} if xla_defaults else COMPILER_OPTIONS
    key = tuple(sorted(options.items()))
    if not key:
        return _assess_chunk
    if key not in _JITTED:
        _JITTED[key] = eqx.filter_jit(_assess_vmapped, compiler_options=dict(key))
    return _JITTED[key]


def assess_units(units: Sequence[Unit], config: ObserverConfig = ObserverConfig(),
                 settings: Settings = Settings(),
                 identify_settings: IdentifySettings | None = IdentifySettings(),
                 verdict_settings: VerdictSettings = VerdictSettings(), *, size: int | None = None,
                 chunk: int | None = None, compiler_options: dict | None = None,
                 progress: Callable[[str], None] | None = None) -> list[Assessment]:
    """:func:`jaxdse.assess` every unit, vmapped within groups; one :class:`Assessment` per
    unit, in order, with host (NumPy) arrays cut to the unit's length and time-shifted.

    Each group's function is compiled in the calling thread; the group's chunks then run side
    by side on a pool of threads (:func:`workers`), each taking ``RUN_BYTES`` divided by the
    number of workers.

    Arguments:
        units: the units; each has its own recording and plant.
        config, settings, identify_settings, verdict_settings: shared by all units
            (``identify_settings=None``: the online estimate and its playback only); an
            adaptive playback takes at most ``MAX_PLAYBACK_SUBSTEPS`` steps per sample.
        size: pad every recording to this many samples (default: per-group buckets).
        chunk: units per compiled call (default: what a worker's share of ``RUN_BYTES`` holds).
        compiler_options: XLA options of the compile (default: ``COMPILER_OPTIONS`` on CPU;
            ``{}``: XLA's defaults).
        progress: called with a line after each compiled call.
    """
    run = _compiled_chunk(compiler_options)
    playback = settings.playback_integrator
    if playback.adaptive and playback.max_substeps > MAX_PLAYBACK_SUBSTEPS:
        settings = dataclasses.replace(settings, playback_integrator=dataclasses.replace(
            playback, max_substeps=MAX_PLAYBACK_SUBSTEPS))
    out: list = [None] * len(units)
    groups = group_units(units, size)
    pool_size = _pool_size(groups)
    plans = []
    for (length, _, _), members in groups.items():
        recs = stack([pad_recording(units[k].recording, length, with_frequency=True) for k in members])
        plants = stack([units[k].plant for k in members])
        refs = np.array([np.nan if units[k].a2_reference is None else units[k].a2_reference
                         for k in members])
        step = chunk or units_per_call(length, identify_settings, len(members), pool_size)
        plans.append(_Plan(length, members, (recs, plants, refs), step))

    def chunk(plan: _Plan, start: int) -> tuple:
        # A short last chunk repeats its last member: one compiled shape per group.
        idx = np.minimum(np.arange(start, start + plan.step), len(plan.members) - 1)
        return tuple(jtu.tree_map(lambda x: np.asarray(x)[idx], a) for a in plan.inputs)

    def call(plan: _Plan, start: int, compiled) -> str:
        res = jax.device_get(compiled(*chunk(plan, start), config, settings, identify_settings,
                                      verdict_settings))
        for j in range(min(plan.step, len(plan.members) - start)):
            k = plan.members[start + j]
            out[k] = _cut_shift(jtu.tree_map(lambda x, j=j: x[j], res),
                                int(np.shape(units[k].recording.t_s)[0]), units[k].t0_s)
        return (f"{min(start + plan.step, len(plan.members))}/{len(plan.members)} unit(s) of "
                f"{plan.length} samples")

    report = progress or (lambda _: None)

    def reported(results) -> None:
        for _, value in results:
            if isinstance(value, Expired):
                raise TimeoutError(f"{value.reason}: the compiled run did not return")
            report(value)

    # With a thread-local JAX context (``with jax.default_device(...)``) the chunks run in the
    # calling thread (a new thread would not see it); else on daemon threads, each wait bounded.
    pool = Pool(pool_size) if pool_size > 1 or _same_context_in_threads() else None
    for plan in plans:
        # The group's program is traced and compiled in the calling thread (its JAX contexts
        # and logs apply); its chunks then run side by side on the pool, while the calling
        # thread goes on to compile the next group's.
        with _collector_paused():
            compiled = run.lower(*chunk(plan, 0), config, settings, identify_settings,
                                 verdict_settings).compile()
        for start in range(0, len(plan.members), plan.step):
            if pool is None:
                report(call(plan, start, compiled))
                continue
            pool.submit(Task(f"{min(plan.step, len(plan.members) - start)} unit(s) of {plan.length} "
                             f"samples (units {start + 1}-{min(start + plan.step, len(plan.members))} "
                             f"of {len(plan.members)} in their group)",
                             wait_limit_s(plan.step, plan.length, identify_settings),
                             lambda plan=plan, start=start, compiled=compiled: call(plan, start, compiled)))
        if pool is not None:
            reported(pool.results(block=False))
    if pool is not None:
        reported(pool.results())
    return out


WAIT_BASE_S = 300.0
"""The wait on one compiled call (compiled beforehand) of :func:`assess_units`: this much [s] ..."""
WAIT_PER_SAMPLE_S = 1e-4
"""... plus this much per sample of each front end of each unit of the call [s]: generous (a
stuck call is found out, not a slow one cut short)."""


def wait_limit_s(units: int, samples: int, identify_settings: IdentifySettings | None) -> float:
    """How long :func:`assess_units` waits for a call of ``units`` units of ``samples`` samples
    [s] before it gives up with a :class:`TimeoutError` naming it."""
    fronts = 2 + (identify_settings.bootstrap_draws if identify_settings is not None else 0)
    return WAIT_BASE_S + WAIT_PER_SAMPLE_S * units * samples * fronts


@contextlib.contextmanager
def _collector_paused():
    """Python's cyclic garbage collector off while a group's function is traced: tracing
    allocates ~0.3 M objects, and the collector's passes over them took ~0.5 s of a 3.3 s
    trace (the objects are freed by reference counting either way)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def _pool_size(groups: dict) -> int:
    """Threads of the pool for these groups (:func:`threads` of the largest group's units)."""
    return threads(max((len(m) for m in groups.values()), default=1))


def threads(calls: int) -> int:
    """Threads to run ``calls`` compiled calls on: :func:`workers`, 1 under a thread-local
    JAX context."""
    n = workers(calls)
    return n if n == 1 or _same_context_in_threads() else 1


def _same_context_in_threads() -> bool:
    """Whether a new thread sees the calling thread's JAX trace context (x64, default device,
    ...). A context manager (``with jax.default_device(...)``) holds in its own thread only:
    then every chunk runs in the calling thread."""
    context = getattr(jax_config, "trace_context", None)  # private: without it, no threads
    if context is None:
        return False
    here = context()
    with ThreadPoolExecutor(1) as pool:
        return pool.submit(context).result() == here


def _cut_shift(a: Assessment, n: int, t0: float) -> Assessment:
    """``a`` with every per-sample array cut to the first ``n`` samples and the estimate's
    time axis shifted by ``t0`` [s]."""
    def cut(x):
        return x[:n] if np.ndim(x) >= 1 and np.shape(x)[0] >= n and np.shape(x)[0] > 4 else x

    est = jtu.tree_map(cut, a.estimate)
    est = eqx.tree_at(lambda e: e.time_s, est, est.time_s + t0)
    rep = a.replay
    if rep is not None:
        rep = eqx.tree_at(lambda r: r.playback, rep, jtu.tree_map(cut, rep.playback))
    return dataclasses.replace(a, estimate=est, replay=rep)
