"""Signal conditioning: smoothed derivatives, frequency and the "measured" speed deviation x2."""

from __future__ import annotations

import jax
import jax.numpy as jnp


def unwrap_continuing(angle, start=None):
    """``jnp.unwrap``, shifted by a multiple of 2 pi so that the first sample lies within pi
    of ``start`` (the value a previous chunk of a stream gave the same sample)."""
    out = jnp.unwrap(angle)
    if start is None:
        return out
    return out + 2.0 * jnp.pi * jnp.round((start - out[0]) / (2.0 * jnp.pi))


def smooth_derivative(x, dt, half_width: int = 0, n=None):
    """d/dt of a uniformly sampled signal.

    Least-squares slope over 2*half_width + 1 samples (the Savitzky-Golay first-derivative
    filter, polynomial order 1 or 2); ``half_width=0`` is the plain central difference.
    The first and last ``half_width`` samples use central/one-sided differences. ``n`` (may
    be traced) is the number of valid samples when ``x`` is padded at the end; the samples
    before it then get exactly the derivative of the unpadded signal.
    """
    size = x.shape[0]
    idx = jnp.arange(size)
    n = size if n is None else n
    ahead, behind = x[jnp.minimum(idx + 1, size - 1)], x[jnp.maximum(idx - 1, 0)]
    grad = jnp.where(idx == 0, (ahead - x) / dt,
                     jnp.where(idx == n - 1, (x - behind) / dt, (ahead - behind) / (2 * dt)))
    if half_width == 0:
        return grad
    # sum_k k x[i+k] / (dt sum_k k^2) as shifted slices: a convolution whose kernel depends on
    # a batched dt would become a grouped convolution under vmap, which is slow on CPU.
    padded = jnp.pad(x, half_width, mode="edge")
    ahead_k = [padded[half_width + k:half_width + k + size] for k in range(1, half_width + 1)]
    behind_k = [padded[half_width - k:half_width - k + size] for k in range(1, half_width + 1)]
    slope = sum(k * (a - b) for k, a, b in zip(range(1, half_width + 1), ahead_k, behind_k))
    interior = slope / (dt * 2 * sum(k * k for k in range(1, half_width + 1)))
    return jnp.where((idx >= half_width) & (idx < n - half_width), interior, grad)


def frequency_from_angle(theta, dt, f_nominal_hz, half_width: int = 0, n=None):
    """Bus frequency [Hz] from an unwrapped voltage angle measured against the nominal frame."""
    return f_nominal_hz + smooth_derivative(theta, dt, half_width, n) / (2.0 * jnp.pi)


def measured_speed_deviation(f_hz, delta, theta, dt, f_nominal_hz, half_width: int = 0, n=None):
    """x2 = 2 pi (f - f0) + d(delta - theta)/dt [rad/s] (paper Remark 2, both terms kept).

    ``f_hz`` is the frequency of the bus whose angle is ``theta``; ``delta`` is the rotor angle
    in the same frame.
    """
    return 2.0 * jnp.pi * (f_hz - f_nominal_hz) + smooth_derivative(delta - theta, dt, half_width, n)


def angle_jumps(theta, switched):
    """The jumps of an angle at its switchings, summed [rad] per sample: ``theta`` less them is
    continuous. ``switched`` (per sample interval, :func:`jumps`): the jump of an interval is
    its increment less the mean of the increments two intervals before and after it (a
    transition over two frames leaves its neighbour's increment out)."""
    inc = jnp.diff(theta)
    k = jnp.arange(inc.shape[0])
    smooth = (inc[jnp.maximum(k - 2, 0)] + inc[jnp.minimum(k + 2, inc.shape[0] - 1)]) / 2
    return jnp.concatenate([jnp.zeros(1, theta.dtype), jnp.cumsum(jnp.where(switched, inc - smooth, 0.0))])


def bridge(x, switched, reach: int):
    """``x`` interpolated linearly across the samples within ``reach`` of a switching
    (``switched`` per sample interval, :func:`jumps`; the samples k - reach to k + 1 + reach of
    the interval from k to k + 1); unchanged elsewhere. A PMU's frequency spikes where the
    angle it is derived from jumps."""
    size = x.shape[0]
    idx = jnp.arange(size)
    count = jnp.concatenate([jnp.zeros(1, jnp.int32), jnp.cumsum(switched.astype(jnp.int32))])
    guarded = (count[jnp.minimum(idx + reach + 1, size - 1)] - count[jnp.maximum(idx - reach - 1, 0)]) > 0
    before = jax.lax.cummax(jnp.where(guarded, -1, idx))
    after = jax.lax.cummin(jnp.where(guarded, size, idx), reverse=True)
    x_b, x_a = x[jnp.clip(before, 0, size - 1)], x[jnp.clip(after, 0, size - 1)]
    w = (idx - before) / jnp.maximum(after - before, 1)
    inside = jnp.where(before < 0, x_a, jnp.where(after >= size, x_b, x_b + w * (x_a - x_b)))
    return jnp.where(guarded & ((before >= 0) | (after < size)), inside, x)


def jumps(x, ratio, factor, n=None):
    """Per sample interval: True where ``x`` (real or complex) jumps between two samples (a
    switching event). A jump J between samples k and k+1 puts +J and -J into the second
    differences d2 = x(j+1) - 2 x(j) + x(j-1) at samples k and k+1; the jump |d2(k) - d2(k+1)| / 2
    must exceed ``ratio`` times the smooth curvature around it (|d2| at samples k-1 and k+2, and
    the part common to both, |d2(k) + d2(k+1)| / 2) and ``factor`` times the median |d2| (the
    noise). Second differences, not first: a steady frequency offset turns a phasor by the same
    angle each frame, and after a large event the phasor rotates fast while it jumps."""
    d2 = jnp.diff(x, 2)
    if n is not None:  # padded at the end: as if x had n samples
        d2 = jnp.where(jnp.arange(d2.shape[0]) < n - 2, d2, 0.0)
    p = jnp.pad(d2, 2)  # p[k + 1]: d2 at sample k (0 at the ends)
    k = jnp.arange(x.shape[0] - 1)
    a, b = p[k + 1], p[k + 2]
    jump = jnp.abs(a - b) / 2
    smooth = jnp.maximum(jnp.maximum(jnp.abs(p[k]), jnp.abs(p[k + 3])), jnp.abs(a + b) / 2)
    noise = (jnp.median(jnp.abs(d2)) if n is None else
             jnp.nanmedian(jnp.where(jnp.arange(d2.shape[0]) < n - 2, jnp.abs(d2), jnp.nan)))
    return (jump > ratio * smooth) & (jump > factor * noise)
