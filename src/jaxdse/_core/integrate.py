"""Integrating sampled-input ODEs with diffrax: the time loop shared by every dynamic stage.

Inputs are known only at the PMU sample times and are linearly interpolated between them.
The loop is a ``lax.scan`` over the samples; each step is one ``diffeqsolve`` over one
sample interval (the inputs are affine inside it), or one call of the solver's ``step``
for fixed steps. The scan is nested: an outer scan over
blocks of ``block`` samples, each block (and each step within it) rematerialised in the
backward pass (``jax.checkpoint``), so reverse-mode memory grows with the number of blocks,
not with the number of solver stages. Per block, the caller either keeps every state or
reduces them to a small summary (``reduce``), so that long recordings and large sweeps need
not store trajectories. Samples after the valid ones (padding) hold the state. Only the inputs are
scanned over; the time, the sample index and the previous sample's inputs ride in the
carry, which saves a padded, transposed copy of each per vmapped batch.

Two step-size choices (measured in ``benchmarks/run.py``):

* adaptive (default): ``PIDController`` capped at the sample interval; an explicit solver
  shortens its steps automatically when the DREM update turns stiff (a large event);
* fixed: ``substeps`` steps of a cheap solver per interval -- the throughput path for
  sweeps, tuning and fleets, and a discrete map that is smooth in the parameters. Its
  default, :class:`Trapezoid`, is Heun's method written as a lean diffrax solver: diffrax's
  generic Runge-Kutta machinery (tableaus, stage buffers, FSAL and implicit-stage logic)
  doubles the cost of a 2-stage step on a 20-state field. A state whose derivative is
  linear in itself with a known decay rate (the DREM's theta: d theta/dt = -gamma K Delta^2
  theta + ...) moves by an exponential trapezoid step instead, exact for a constant rate: a
  line trip that makes gamma K Delta^2 dt ~ 36 per sample would throw explicit Heun far
  past its stability limit.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from equinox.internal import ω


class Trapezoid(diffrax.AbstractAdaptiveSolver):
    """Explicit trapezoidal rule (Heun's method, order 2, embedded Euler error estimate).

    Same steps as ``diffrax.Heun`` to round-off, at about half the cost per step.
    """

    term_structure = diffrax.AbstractTerm
    interpolation_cls = diffrax.LocalLinearInterpolation

    def order(self, terms):
        return 2

    def init(self, terms, t0, t1, y0, args):
        return None

    def step(self, terms, t0, t1, y0, args, solver_state, made_jump):
        control = terms.contr(t0, t1)
        k1 = terms.vf_prod(t0, y0, args, control)
        k2 = terms.vf_prod(t1, (y0**ω + k1**ω).ω, args, control)
        y1 = (y0**ω + 0.5 * (k1**ω + k2**ω)).ω
        y_error = (0.5 * (k2**ω - k1**ω)).ω
        return y1, y_error, dict(y0=y0, y1=y1), None, diffrax.RESULTS.successful

    def func(self, terms, t0, y0, args):
        return terms.vf(t0, y0, args)


class Integrator(eqx.Module):
    """Static integration settings (not differentiated, not vmapped)."""

    solver: diffrax.AbstractSolver = eqx.field(static=True, default_factory=diffrax.Tsit5)
    rtol: float = eqx.field(static=True, default=1e-6)
    atol: float = eqx.field(static=True, default=1e-8)
    max_substeps: int = eqx.field(static=True, default=256)
    """Most solver steps inside one sample interval before giving up (adaptive)."""
    adaptive: bool = eqx.field(static=True, default=True)
    """Adaptive steps (robust to stiff events). False: ``substeps`` fixed steps per interval,
    which makes the discrete map smooth in the parameters (finite-difference checks)."""
    substeps: int = eqx.field(static=True, default=1)
    """Fixed steps per sample interval when ``adaptive`` is False."""
    forward_mode: bool = eqx.field(static=True, default=False)
    """Adaptive steps differentiable in forward mode (``diffrax.ForwardMode``); the default
    adjoint (recursive checkpointing) supports reverse mode only."""
    min_substep: float = eqx.field(static=True, default=0.0)
    """Shortest adaptive step, as a fraction of the sample interval (0: none). A step the error
    control would cut below it is taken at it and accepted, as a fixed-step simulator takes it:
    a limiter that switches at every trial step (a governor valve sliding along its non-windup
    limit under a noisy speed) then costs 1/``min_substep`` steps instead of failing."""

    def controller(self, h):
        if self.min_substep > 0:
            return diffrax.PIDController(rtol=self.rtol, atol=self.atol, dtmax=h,
                                         dtmin=self.min_substep * h, force_dtmin=True)
        return diffrax.PIDController(rtol=self.rtol, atol=self.atol, dtmax=h)

    @classmethod
    def fast(cls, substeps: int = 1) -> Integrator:
        """Fixed-step Heun (:class:`Trapezoid`), exponential for stiff linear states: the
        throughput choice for sweeps, tuning and fleets."""
        return cls(solver=Trapezoid(), adaptive=False, substeps=substeps)


class Integrated(eqx.Module):
    """States at every sample (or per-block summaries) and solver diagnostics."""

    ys: object
    """States at every sample time (y0 first), or the stacked ``reduce`` outputs per block."""
    y_last: object
    """State at the last valid sample: the carry for the next chunk of a stream."""
    ok: jax.Array
    """True when every solve succeeded."""
    num_steps: jax.Array
    """Total accepted + rejected solver steps."""


class Previous(NamedTuple):
    """The sample before ``ts[0]`` when a stream continues: its time and inputs."""

    t: jax.Array
    inputs: object


def _lerp(u0, u1, w):
    return jtu.tree_map(lambda a, b: a + (b - a) * w, u0, u1)


def _phi1(x):
    """(1 - e^{-x}) / x, and 1 at x = 0 (smooth in x: its series near 0)."""
    small = jnp.abs(x) < 1e-4
    safe = jnp.where(small, 1.0, x)
    return jnp.where(small, 1.0 - 0.5 * x + x * x / 6.0, -jnp.expm1(-safe) / safe)


def exponential_trapezoid(f, rate, t0, t1, y0, args):
    """One step of the trapezoidal rule with the linear decay of each state taken exactly.

    With dy/dt = -r(t, y) y + b(t, y) (``rate`` gives r >= 0 per state, zero for the others):
    an exponential-Euler predictor, then y1 = y0 e^{-r h} + h b phi1(r h) with r and b the
    means of both ends. For r = 0 it is Heun's method; for any r h it stays between y0 and
    b/r (A-stable), so a huge adaptation gain cannot blow the fixed-step loop up.
    """
    h = t1 - t0
    tm = jtu.tree_map

    def advance(y, r, b):
        return tm(lambda y_, r_, b_: y_ * jnp.exp(-r_ * h) + b_ * h * _phi1(r_ * h), y, r, b)

    k1, r0 = f(t0, y0, args), rate(t0, y0, args)
    b0 = tm(lambda k, r, y: k + r * y, k1, r0, y0)
    pred = advance(y0, r0, b0)
    k2, r1 = f(t1, pred, args), rate(t1, pred, args)
    b1 = tm(lambda k, r, y: k + r * y, k2, r1, pred)
    return advance(y0, tm(lambda a, b: 0.5 * (a + b), r0, r1), tm(lambda a, b: 0.5 * (a + b), b0, b1))


def solve_interval(vector_field, y0, t0, t1, u0, u1, args, integ: Integrator, rate=None):
    """Integrate one sample interval [t0, t1] with the input interpolated from u0 to u1.

    ``rate(t, y, u, args)``: the linear decay rate of each state (a pytree like ``y``, zero
    where there is none); with fixed steps those states move by :func:`exponential_trapezoid`.
    Returns (y(t1), success flag, number of solver steps).
    """

    def f(t, y, a):
        return vector_field(t, y, _lerp(u0, u1, (t - t0) / (t1 - t0)), args)

    h = t1 - t0
    term = diffrax.ODETerm(f)
    if not integ.adaptive and rate is not None:
        def r(t, y, a):
            return rate(t, y, _lerp(u0, u1, (t - t0) / (t1 - t0)), args)

        step = h / integ.substeps
        y = y0
        for k in range(integ.substeps):
            y = exponential_trapezoid(f, r, t0 + k * step, t0 + (k + 1) * step, y, args)
        return y, jnp.asarray(True), jnp.asarray(integ.substeps)
    if not integ.adaptive:
        # Fixed steps: call the diffrax solver's step directly; a whole diffeqsolve (its loop,
        # controller and bookkeeping) per sample costs several times the arithmetic.
        step = h / integ.substeps
        state = integ.solver.init(term, t0, t0 + step, y0, args)
        y, ok = y0, True
        for k in range(integ.substeps):
            ta = t0 + k * step
            y, _, _, state, result = integ.solver.step(term, ta, ta + step, y, args, state,
                                                       made_jump=False)
            ok = ok & (result == diffrax.RESULTS.successful)
        return y, ok, jnp.asarray(integ.substeps)
    # In the interval's own time s = (t - t0) / h: diffeqsolve's t0, t1 and dt0 are then
    # constants, so its runtime check of their signs (an error_if: a host callback) folds away
    # when traced, and the compiled executable can be kept in JAX's persistent cache.
    def g(s, y, a):
        return jtu.tree_map(lambda d: h * d, vector_field(t0 + s * h, y, _lerp(u0, u1, s), args))

    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(g), integ.solver, 0.0, 1.0, 1.0, y0, stepsize_controller=integ.controller(1.0),
        saveat=diffrax.SaveAt(t1=True), max_steps=integ.max_substeps, throw=False,
        adjoint=diffrax.ForwardMode() if integ.forward_mode else diffrax.RecursiveCheckpointAdjoint(),
    )
    y1 = jtu.tree_map(lambda x: x[0], sol.ys)
    return y1, sol.result == diffrax.RESULTS.successful, sol.stats["num_steps"]


def _pad(x, n_pad):
    """Extend along axis 0 by repeating the last entry (finite, so gradients stay finite)."""
    return jnp.concatenate([x, jnp.repeat(x[-1:], n_pad, axis=0)]) if n_pad else x


def integrate_sampled(vector_field: Callable, y0, ts, inputs, args, integ: Integrator = Integrator(),
                      *, n_valid=None, previous: Previous | None = None, reduce: Callable | None = None,
                      aux=None, block: int = 64, rate: Callable | None = None) -> Integrated:
    """Solve dy/dt = vector_field(t, y, u(t), args) and return y at every time in ``ts``.

    Arguments:
        vector_field: pure function of (t, y, u, args).
        y0: state at ``ts[0]`` -- or, with ``previous``, at ``previous.t``.
        ts: sample times, uniform (only ``ts[0]`` and the step ``ts[1] - ts[0]`` are read).
        inputs: pytree of arrays with leading axis ``len(ts)``; u(t) interpolates it linearly.
        args: passed to ``vector_field``.
        integ: step-size and solver choice.
        n_valid: number of valid samples (may be traced); the samples after them are padding,
            where the state is held.
        previous: continue a stream: integrate from ``previous`` to ``ts[0]`` first.
        reduce: ``reduce(ys, inputs, aux, valid)`` maps one block of states (leading axis
            ``block``) to a summary; the result then holds the stacked summaries instead of
            the states.
        aux: per-sample pytree passed to ``reduce`` alongside the states.
        block: samples per block (checkpointing and reduction granularity).
        rate: ``rate(t, y, u, args)``, the linear decay rate per state, for the fixed-step
            exponential trapezoid (see :func:`solve_interval`).
    """
    n = ts.shape[0]
    n_valid = n if n_valid is None else n_valid
    t_first, dt = ts[0], ts[1] - ts[0]
    first_step = 0 if previous is not None else 1  # without one, the first sample only sets y0
    if previous is None:
        previous = Previous(t_first - dt, jtu.tree_map(lambda x: x[0], inputs))
    n_blocks = -(-n // block)
    xs = jtu.tree_map(lambda x: _pad(x, n_blocks * block - x.shape[0]).reshape(
        n_blocks, block, *x.shape[1:]), (inputs, aux))

    # Only the per-sample inputs are scanned over: the time, the index and the previous
    # sample's inputs ride in the carry (no time, mask or shifted copies of the inputs).
    def step(carry, u1):
        y, t0, u0, k = carry
        t1 = t_first + k * dt
        on = (k >= first_step) & (k < n_valid)
        y1, ok, steps = solve_interval(vector_field, y, t0, t1, u0, u1, args, integ, rate)
        y1 = jtu.tree_map(lambda new, old: jnp.where(on, new, old), y1, y)
        return (y1, t1, u1, k + 1), (y1, ok | ~on, jnp.where(on, steps, 0))

    # A block whose end state is not finite (e.g. an explicit step past its stability limit)
    # fails: the state holds its value from the block's start and ``ok`` reports it. Checked
    # once per block, not per step, which would halve the throughput of the fixed-step loop.
    # Reverse mode recomputes each block from its start, and within it each step from its
    # start (nested checkpoints): the backward pass stores one state per sample of one block
    # instead of every intermediate of every solver stage, and runs faster (value-and-grad of
    # the tuning loss on 4 recordings: 5.4 -> 5.0 times the forward pass).
    @jax.checkpoint
    def block_step(carry, x):
        u1, ax = x
        valid = carry[3] + jnp.arange(block) < n_valid
        new, (ys, ok, steps) = jax.lax.scan(jax.checkpoint(step, prevent_cse=False), carry, u1)
        finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(a)) for a in jtu.tree_leaves(new[0])]))
        y = jtu.tree_map(lambda a, b: jnp.where(finite, a, b), new[0], carry[0])
        out = ys if reduce is None else reduce(ys, u1, ax, valid)
        return (y, *new[1:]), (out, jnp.all(ok) & finite, jnp.sum(steps))

    carry0 = (y0, previous.t, previous.inputs, jnp.zeros((), dtype=jnp.int32))
    (y_last, *_), (out, ok, steps) = jax.lax.scan(block_step, carry0, xs)
    if reduce is None:
        out = jtu.tree_map(lambda a: a.reshape(n_blocks * block, *a.shape[2:])[:n], out)
    return Integrated(ys=out, y_last=y_last, ok=jnp.all(ok), num_steps=jnp.sum(steps))
