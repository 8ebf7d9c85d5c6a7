"""Linear time-invariant filters of sampled signals, integrated exactly between samples.

A state-space system dx/dt = A x + B u driven by a signal that is linear between samples
(first-order hold) moves exactly as x[k+1] = Phi x[k] + G0 u[k] + G1 u[k+1], with Phi, G0
and G1 from one matrix exponential. No step-size limit, no stiffness: the filters of the
batch identification (``identify``) and the q-axis observer use it.

Everything here is matrix products and elementwise arithmetic, with no LAPACK call (no LU,
no SVD), so that it batches cleanly under ``jax.vmap`` on every backend: the exponential is
a Taylor series after scaling and squaring, and the filters start from their closed-form
rest state.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

TAYLOR_TERMS = 18
"""Terms of the Taylor series of exp(M / 2^s), ||M / 2^s||_1 <= 1/2: the remainder is below
0.5^18 / 18! ~ 6e-22, far under float64's round-off."""
MAX_SQUARINGS = 48
"""Largest s (||M||_1 up to 2^47: a 1 ms step of a 1e11 rad/s pole)."""


def expm(m):
    """exp(m) of a small square matrix by scaling and squaring a Taylor series (no LAPACK).

    The number of squarings s = ceil(log2 ||m||_1) + 1 is traced, the loop is not: the
    squarings beyond s are masked, so that the graph has one static shape under vmap."""
    norm = jnp.max(jnp.sum(jnp.abs(m), axis=0))
    s = jnp.clip(jnp.ceil(jnp.log2(jnp.maximum(norm, 1e-300))) + 1.0, 0.0, MAX_SQUARINGS - 1)
    x = m * jnp.exp2(-s)
    eye = jnp.eye(m.shape[0], dtype=m.dtype)
    term, out = eye, eye
    for k in range(1, TAYLOR_TERMS + 1):
        term = term @ x / k
        out = out + term

    def square(k, e):
        return jnp.where(k < s, e @ e, e)

    return jax.lax.fori_loop(0, MAX_SQUARINGS, square, out)


def hold_discretisation(a, b, dt):
    """(Phi, G0, G1) of dx/dt = a x + b u with u linear over a step ``dt`` (``b`` a vector)."""
    n = a.shape[0]
    m = jnp.zeros((n + 2, n + 2), dtype=a.dtype)
    m = m.at[:n, :n].set(a * dt).at[:n, n].set(b * dt).at[n, n + 1].set(1.0)
    e = expm(m)
    phi, g1 = e[:n, :n], e[:n, n + 1]
    return phi, e[:n, n] - g1, g1


def solve_2x2(a, v):
    """a^-1 v for a 2x2 matrix, by Cramer's rule (no LAPACK call)."""
    det = a[0, 0] * a[1, 1] - a[0, 1] * a[1, 0]
    return jnp.stack([a[1, 1] * v[0] - a[0, 1] * v[1], a[0, 0] * v[1] - a[1, 0] * v[0]]) / det


def filter_states(discretisation, u, reverse: bool = False, x0=None):
    """States of a unit-DC-gain filter in companion form (states [y, y', ...], see
    :func:`lag_chain`) at every sample (time first), exact for piecewise-linear u.

    ``discretisation`` is :func:`hold_discretisation`'s (Phi, G0, G1), computed once per
    (poles, dt) and shared by every signal. The filter starts at rest at the first sample's
    value (as if u had been constant before): with a DC gain of 1 that is [u[0], 0, ...].
    ``reverse`` runs backwards in time (from the last sample), the second pass of a
    zero-phase filter. ``x0``: the state at the first sample (a stream's carried state) instead
    of rest.
    """
    phi, g0, g1 = discretisation
    u = u[::-1] if reverse else u
    if x0 is None:
        x0 = jnp.zeros(phi.shape[0], dtype=u.dtype).at[0].set(u[0])
    drive = g0[None, :] * u[:-1, None] + g1[None, :] * u[1:, None]  # [T-1, n], outside the loop

    def step(x, v):
        x = phi @ x + v  # faster than the elementwise form and than lax.associative_scan (2.4x)
        return x, x

    _, xs = jax.lax.scan(step, x0, drive)
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


def butterworth2(cutoff_hz, dtype=jnp.float64):
    """(a, b) of the 2nd-order Butterworth low-pass w^2 / (s^2 + sqrt 2 w s + w^2), companion form."""
    w = 2.0 * jnp.pi * cutoff_hz
    return (jnp.array([[0.0, 1.0], [-w * w, -jnp.sqrt(2.0) * w]], dtype=dtype),
            jnp.array([0.0, w * w], dtype=dtype))


def zero_phase_lowpass(u, dt, cutoff_hz):
    """``u`` low-passed forwards and backwards by a 2nd-order Butterworth (zero phase, 4th-order
    magnitude), each pass starting at rest at its first sample."""
    disc = hold_discretisation(*butterworth2(cutoff_hz, u.dtype), dt)
    y = filter_states(disc, u)[:, 0]
    return filter_states(disc, y, reverse=True)[:, 0]
