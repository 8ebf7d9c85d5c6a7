"""Signal conditioning: smoothed derivatives, frequency and the "measured" speed deviation x2."""

from __future__ import annotations

import jax.numpy as jnp


def smooth_derivative(x, dt, half_width: int = 0):
    """d/dt of a uniformly sampled signal.

    Least-squares slope over 2*half_width + 1 samples (the Savitzky-Golay first-derivative
    filter, polynomial order 1 or 2); ``half_width=0`` is the plain central difference.
    The first and last ``half_width`` samples use central/one-sided differences.
    """
    grad = jnp.gradient(x, dt)
    if half_width == 0:
        return grad
    k = jnp.arange(-half_width, half_width + 1, dtype=x.dtype)
    weights = k / (dt * jnp.sum(k**2))
    interior = jnp.convolve(x, weights[::-1], mode="valid")
    return jnp.concatenate([grad[:half_width], interior, grad[-half_width:]])


def frequency_from_angle(theta, dt, f_nominal_hz, half_width: int = 0):
    """Bus frequency [Hz] from an unwrapped voltage angle measured against the nominal frame."""
    return f_nominal_hz + smooth_derivative(theta, dt, half_width) / (2.0 * jnp.pi)


def measured_speed_deviation(f_hz, delta, theta, dt, f_nominal_hz, half_width: int = 0):
    """x2 = 2 pi (f - f0) + d(delta - theta)/dt [rad/s] (paper Remark 2, both terms kept).

    ``f_hz`` is the frequency of the bus whose angle is ``theta``; ``delta`` is the rotor angle
    in the same frame.
    """
    return 2.0 * jnp.pi * (f_hz - f_nominal_hz) + smooth_derivative(delta - theta, dt, half_width)
