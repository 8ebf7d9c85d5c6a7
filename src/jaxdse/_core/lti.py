"""Linear time-invariant filters of sampled signals, integrated exactly between samples.

A state-space system dx/dt = A x + B u driven by a signal that is linear between samples
(first-order hold) moves exactly as x[k+1] = Phi x[k] + G0 u[k] + G1 u[k+1], with Phi, G0
and G1 from one matrix exponential. No step-size limit, no stiffness: the filters of the
batch identification (``identify``) and the q-axis observer use it.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl


def hold_discretisation(a, b, dt):
    """(Phi, G0, G1) of dx/dt = a x + b u with u linear over a step ``dt`` (``b`` a vector)."""
    n = a.shape[0]
    m = jnp.zeros((n + 2, n + 2), dtype=a.dtype)
    m = m.at[:n, :n].set(a * dt).at[:n, n].set(b * dt).at[n, n + 1].set(1.0)
    e = jsl.expm(m)
    phi, g1 = e[:n, :n], e[:n, n + 1]
    return phi, e[:n, n] - g1, g1


def filter_states(a, b, u, dt, x0=None, reverse: bool = False):
    """States of dx/dt = a x + b u at every sample (time first), exact for piecewise-linear u.

    Starts at rest at the first sample's value (x0 = -a^{-1} b u[0], i.e. as if u had been
    constant before), or at ``x0``. ``reverse`` runs backwards in time (from the last sample),
    the second pass of a zero-phase filter.
    """
    phi, g0, g1 = hold_discretisation(a, b, dt)
    u = u[::-1] if reverse else u
    if x0 is None:
        x0 = -jnp.linalg.solve(a, b * u[0])

    def step(carry, u1):
        x, u0 = carry
        x = phi @ x + g0 * u0 + g1 * u1
        return (x, u1), x

    _, xs = jax.lax.scan(step, (x0, u[0]), u[1:])
    xs = jnp.concatenate([x0[None], xs])
    return xs[::-1] if reverse else xs


def lag_chain(poles):
    """(a, b) of prod p_k / (s + p_k) in companion form: states [y, y', y'', ...] of the output."""
    coeffs = jnp.poly(-jnp.asarray(poles))  # s^n + c1 s^(n-1) + ... + cn
    n = coeffs.shape[0] - 1
    gain = jnp.prod(jnp.asarray(poles))
    a = jnp.zeros((n, n), dtype=coeffs.dtype).at[jnp.arange(n - 1), jnp.arange(1, n)].set(1.0)
    a = a.at[n - 1].set(-coeffs[1:][::-1])
    b = jnp.zeros(n, dtype=coeffs.dtype).at[n - 1].set(gain)
    return a, b


def zero_phase_lowpass(u, dt, cutoff_hz):
    """``u`` low-passed forwards and backwards by a 2nd-order Butterworth (zero phase, 4th-order
    magnitude), each pass starting at rest at its first sample."""
    w = 2.0 * jnp.pi * cutoff_hz
    a = jnp.array([[0.0, 1.0], [-w * w, -jnp.sqrt(2.0) * w]], dtype=u.dtype)
    b = jnp.array([0.0, w * w], dtype=u.dtype)
    y = filter_states(a, b, u, dt)[:, 0]
    return filter_states(a, b, y, dt, reverse=True)[:, 0]
