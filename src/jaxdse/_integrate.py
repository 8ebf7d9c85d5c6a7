"""Integrating sampled-input ODEs with diffrax: the time loop shared by every dynamic stage.

Inputs are known only at the PMU sample times and are linearly interpolated between them.
Two schemes are offered (measured in ``benchmarks/integration_schemes.py``):

* ``"per_interval"`` -- ``lax.scan`` over the sample intervals, one adaptive ``diffeqsolve``
  per interval (inputs affine inside it). The default: it is the faster one.
* ``"single_solve"`` -- one ``diffeqsolve`` over the whole recording with a
  ``LinearInterpolation`` of the inputs, forced to step on every sample time.

Both use an adaptive step size controller capped at the sample interval, so an explicit
solver shortens its steps automatically when the DREM update turns stiff (a large event).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Literal

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu


class Integrator(eqx.Module):
    """Static integration settings (not differentiated, not vmapped)."""

    scheme: Literal["per_interval", "single_solve"] = eqx.field(static=True, default="per_interval")
    solver: diffrax.AbstractSolver = eqx.field(static=True, default_factory=diffrax.Tsit5)
    rtol: float = eqx.field(static=True, default=1e-6)
    atol: float = eqx.field(static=True, default=1e-8)
    max_substeps: int = eqx.field(static=True, default=256)
    """Most solver steps inside one sample interval (per_interval) before giving up."""
    adaptive: bool = eqx.field(static=True, default=True)
    """Adaptive steps (robust to stiff events). False: ``substeps`` fixed steps per interval,
    which makes the discrete map smooth in the parameters (finite-difference checks)."""
    substeps: int = eqx.field(static=True, default=1)
    """Fixed steps per sample interval when ``adaptive`` is False."""

    def controller(self, h):
        if self.adaptive:
            return diffrax.PIDController(rtol=self.rtol, atol=self.atol, dtmax=h)
        return diffrax.ConstantStepSize()


class Integrated(eqx.Module):
    """States at every sample time (y0 first) and solver diagnostics."""

    ys: object
    ok: jax.Array
    """True when every solve succeeded."""
    num_steps: jax.Array
    """Total accepted + rejected solver steps."""


def _lerp(u0, u1, w):
    return jtu.tree_map(lambda a, b: a + (b - a) * w, u0, u1)


def integrate_sampled(vector_field: Callable, y0, ts, inputs, args, integ: Integrator = Integrator()):
    """Solve dy/dt = vector_field(t, y, u(t), args) and return y at every time in ``ts``.

    ``inputs`` is a pytree of arrays with leading axis ``len(ts)``; u(t) interpolates it
    linearly. ``vector_field`` must be a pure function.
    """
    if integ.scheme == "per_interval":
        return _per_interval(vector_field, y0, ts, inputs, args, integ)
    if integ.scheme == "single_solve":
        return _single_solve(vector_field, y0, ts, inputs, args, integ)
    raise ValueError(f"unknown integration scheme {integ.scheme!r}")


def solve_interval(vector_field, y0, t0, t1, u0, u1, args, integ: Integrator):
    """Integrate one sample interval [t0, t1] with the input interpolated from u0 to u1.

    Returns (y(t1), success flag, number of solver steps).
    """

    def f(t, y, a):
        return vector_field(t, y, _lerp(u0, u1, (t - t0) / (t1 - t0)), args)

    h = t1 - t0
    dt0 = h if integ.adaptive else h / integ.substeps
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(f), integ.solver, t0, t1, dt0, y0,
        stepsize_controller=integ.controller(h),
        saveat=diffrax.SaveAt(t1=True), max_steps=integ.max_substeps, throw=False,
    )
    y1 = jtu.tree_map(lambda x: x[0], sol.ys)
    return y1, sol.result == diffrax.RESULTS.successful, sol.stats["num_steps"]


def _per_interval(vector_field, y0, ts, inputs, args, integ):
    def step(y, xs):
        y1, ok, steps = solve_interval(vector_field, y, *xs, args, integ)
        return y1, (y1, ok, steps)

    u0 = jtu.tree_map(lambda x: x[:-1], inputs)
    u1 = jtu.tree_map(lambda x: x[1:], inputs)
    _, (ys, ok, steps) = jax.lax.scan(step, y0, (ts[:-1], ts[1:], u0, u1))
    ys = jtu.tree_map(lambda a, b: jnp.concatenate([a[None], b]), y0, ys)
    return Integrated(ys=ys, ok=jnp.all(ok), num_steps=jnp.sum(steps))


def _single_solve(vector_field, y0, ts, inputs, args, integ):
    interp = diffrax.LinearInterpolation(ts=ts, ys=inputs)

    def f(t, y, a):
        return vector_field(t, y, interp.evaluate(t), a)

    h = ts[1] - ts[0]
    if integ.adaptive:
        controller = diffrax.ClipStepSizeController(integ.controller(h), step_ts=ts)
    else:
        controller = diffrax.StepTo(ts=jnp.linspace(ts[0], ts[-1], (ts.shape[0] - 1) * integ.substeps + 1))
    sol = diffrax.diffeqsolve(
        diffrax.ODETerm(f), integ.solver, ts[0], ts[-1], None if not integ.adaptive else h, y0, args=args,
        stepsize_controller=controller, saveat=diffrax.SaveAt(ts=ts),
        max_steps=4 * ts.shape[0] + 16 * integ.max_substeps, throw=False,
    )
    return Integrated(ys=sol.ys, ok=sol.result == diffrax.RESULTS.successful,
                      num_steps=sol.stats["num_steps"])
