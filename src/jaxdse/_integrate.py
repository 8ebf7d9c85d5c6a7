"""Integrating sampled-input ODEs with diffrax: the time loop shared by every dynamic stage.

Inputs are known only at the PMU sample times and are linearly interpolated between them.
The loop is a ``lax.scan`` over the samples; each step is one ``diffeqsolve`` over one
sample interval (the inputs are affine inside it). The scan is nested: an outer scan over
blocks of ``block`` samples, each block rematerialised in the backward pass
(``jax.checkpoint``), so reverse-mode memory grows with the number of blocks, not with the
number of solver stages. Per block, the caller either keeps every state or reduces them to
a small summary (``reduce``), so that long recordings and large sweeps need not store
trajectories. Samples marked invalid (padding) hold the state.

Two step-size choices (measured in ``benchmarks/run.py``):

* adaptive (default): ``PIDController`` capped at the sample interval; an explicit solver
  shortens its steps automatically when the DREM update turns stiff (a large event);
* fixed: ``substeps`` steps of a cheap solver (e.g. Heun) per interval -- the throughput
  path for sweeps, tuning and fleets, and a discrete map that is smooth in the parameters.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu


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

    def controller(self, h):
        return diffrax.PIDController(rtol=self.rtol, atol=self.atol, dtmax=h)

    @classmethod
    def fast(cls, substeps: int = 1) -> Integrator:
        """Fixed-step Heun: the throughput choice for sweeps, tuning and fleets."""
        return cls(solver=diffrax.Heun(), adaptive=False, substeps=substeps)


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


def solve_interval(vector_field, y0, t0, t1, u0, u1, args, integ: Integrator):
    """Integrate one sample interval [t0, t1] with the input interpolated from u0 to u1.

    Returns (y(t1), success flag, number of solver steps).
    """

    def f(t, y, a):
        return vector_field(t, y, _lerp(u0, u1, (t - t0) / (t1 - t0)), args)

    h = t1 - t0
    term = diffrax.ODETerm(f)
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
    sol = diffrax.diffeqsolve(
        term, integ.solver, t0, t1, h, y0, stepsize_controller=integ.controller(h),
        saveat=diffrax.SaveAt(t1=True), max_steps=integ.max_substeps, throw=False,
    )
    y1 = jtu.tree_map(lambda x: x[0], sol.ys)
    return y1, sol.result == diffrax.RESULTS.successful, sol.stats["num_steps"]


def _pad(x, n_pad):
    """Extend along axis 0 by repeating the last entry (finite, so gradients stay finite)."""
    return jnp.concatenate([x, jnp.repeat(x[-1:], n_pad, axis=0)]) if n_pad else x


def integrate_sampled(vector_field: Callable, y0, ts, inputs, args, integ: Integrator = Integrator(),
                      *, valid=None, previous: Previous | None = None, reduce: Callable | None = None,
                      aux=None, block: int = 64) -> Integrated:
    """Solve dy/dt = vector_field(t, y, u(t), args) and return y at every time in ``ts``.

    Arguments:
        vector_field: pure function of (t, y, u, args).
        y0: state at ``ts[0]`` -- or, with ``previous``, at ``previous.t``.
        ts: sample times, uniform.
        inputs: pytree of arrays with leading axis ``len(ts)``; u(t) interpolates it linearly.
        args: passed to ``vector_field``.
        integ: step-size and solver choice.
        valid: bool per sample; the state is held where False (padding at the end).
        previous: continue a stream: integrate from ``previous`` to ``ts[0]`` first.
        reduce: ``reduce(ys, inputs, aux, valid)`` maps one block of states (leading axis
            ``block``) to a summary; the result then holds the stacked summaries instead of
            the states.
        aux: per-sample pytree passed to ``reduce`` alongside the states.
        block: samples per block (checkpointing and reduction granularity).
    """
    n = ts.shape[0]
    valid = jnp.ones(n, dtype=bool) if valid is None else valid
    if previous is None:
        dt = ts[1] - ts[0]
        t_prev = jnp.concatenate([ts[:1] - dt, ts[:-1]])
        u_prev = jtu.tree_map(lambda x: jnp.concatenate([x[:1], x[:-1]]), inputs)
        step_on = valid & (jnp.arange(n) > 0)
    else:
        t_prev = jnp.concatenate([previous.t[None], ts[:-1]])
        u_prev = jtu.tree_map(lambda p, x: jnp.concatenate([p[None], x[:-1]]), previous.inputs, inputs)
        step_on = valid
    n_blocks = -(-n // block)
    n_pad = n_blocks * block - n
    off = jnp.zeros(n_pad, dtype=bool)  # padded samples never step and are never valid
    step_on, valid = jnp.concatenate([step_on, off]), jnp.concatenate([valid, off])
    # Padded times continue the grid, so that no interval is empty (finite gradients).
    if n_pad:
        t_ext = ts[-1] + (ts[-1] - ts[-2]) * jnp.arange(1, n_pad + 1, dtype=ts.dtype)
        t_prev, ts = jnp.concatenate([t_prev, ts[-1:], t_ext[:-1]]), jnp.concatenate([ts, t_ext])
    xs = jtu.tree_map(lambda x: _pad(x, n_blocks * block - x.shape[0]).reshape(
        n_blocks, block, *x.shape[1:]), (t_prev, ts, u_prev, inputs, step_on, valid, aux))

    def step(y, x):
        t0, t1, u0, u1, on = x
        y1, ok, steps = solve_interval(vector_field, y, t0, t1, u0, u1, args, integ)
        y1 = jtu.tree_map(lambda new, old: jnp.where(on, new, old), y1, y)
        return y1, (y1, ok | ~on, jnp.where(on, steps, 0))

    @jax.checkpoint
    def block_step(y, x):
        t0, t1, u0, u1, on, val, ax = x
        y, (ys, ok, steps) = jax.lax.scan(step, y, (t0, t1, u0, u1, on))
        out = ys if reduce is None else reduce(ys, u1, ax, val)
        return y, (out, jnp.all(ok), jnp.sum(steps))

    y_last, (out, ok, steps) = jax.lax.scan(block_step, y0, xs)
    if reduce is None:
        out = jtu.tree_map(lambda a: a.reshape(n_blocks * block, *a.shape[2:])[:n], out)
    return Integrated(ys=out, y_last=y_last, ok=jnp.all(ok), num_steps=jnp.sum(steps))
