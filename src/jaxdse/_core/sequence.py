"""Symmetrical components (Fortescue): keep the positive sequence of three-phase phasors."""

from __future__ import annotations

import jax.numpy as jnp

A = jnp.exp(2j * jnp.pi / 3)
"""Fortescue operator a = e^{j 2 pi / 3}."""


def positive_sequence(abc):
    """Positive-sequence phasor X1 = (Xa + a Xb + a^2 Xc) / 3 of phasors ``abc[..., 3]``."""
    return (abc[..., 0] + A * abc[..., 1] + A**2 * abc[..., 2]) / 3.0


def sequence_components(abc):
    """(zero, positive, negative) sequence phasors of ``abc[..., 3]``."""
    xa, xb, xc = abc[..., 0], abc[..., 1], abc[..., 2]
    return ((xa + xb + xc) / 3.0, (xa + A * xb + A**2 * xc) / 3.0, (xa + A**2 * xb + A * xc) / 3.0)


def phases_from_sequences(x0, x1, x2):
    """Phase phasors ``[..., 3]`` (a, b, c) from zero, positive and negative sequences."""
    return jnp.stack([x0 + x1 + x2, x0 + A**2 * x1 + A * x2, x0 + A * x1 + A**2 * x2], axis=-1)
