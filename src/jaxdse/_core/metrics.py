"""Accuracy metrics: sMAPE (paper Eq. 23), RMSE, parameter errors and the settling index."""

from __future__ import annotations

import jax.numpy as jnp


def smape_terms(estimate, measured):
    """|z_hat - z| / (0.5 (|z_hat| + |z|)) per sample; 0 where both are exactly zero, NaN
    where either is NaN (a failed simulation must not score as a perfect one)."""
    num = jnp.abs(estimate - measured)
    den = 0.5 * (jnp.abs(estimate) + jnp.abs(measured))
    return jnp.where(den == 0, 0.0, num / jnp.where(den == 0, 1.0, den))


def smape_percent(estimate, measured, mask=None):
    """sMAPE = 100%/M sum |z_hat - z| / (0.5 (|z_hat| + |z|)) (paper Eq. 23).

    Terms where both values are exactly zero count as zero error. ``mask`` selects samples.
    Note: for a signal that crosses zero (such as x2) sMAPE is dominated by the crossings.
    """
    term = smape_terms(estimate, measured)
    if mask is None:
        return 100.0 * jnp.mean(term)
    return 100.0 * jnp.sum(jnp.where(mask, term, 0.0)) / jnp.maximum(jnp.sum(mask), 1)


def rmse(estimate, measured, mask=None):
    """Root-mean-square error, over ``mask`` if given."""
    sq = (estimate - measured) ** 2
    if mask is None:
        return jnp.sqrt(jnp.mean(sq))
    return jnp.sqrt(jnp.sum(jnp.where(mask, sq, 0.0)) / jnp.maximum(jnp.sum(mask), 1))


def relative_error(estimate, reference):
    """(estimate - reference) / |reference|."""
    return (estimate - reference) / jnp.abs(reference)


def settled_from(lo, hi, target, band):
    """Index of the first segment after which every segment lies in the band.

    A segment (one sample, or a block of samples) spans [``lo``, ``hi``] (for padding,
    lo = +inf and hi = -inf: never outside); the band is target +- band |target|. Returns
    the number of segments when the last one is outside.
    """
    tol = band * jnp.abs(target)
    outside = (hi > target + tol) | (lo < target - tol)
    return jnp.max(jnp.where(outside, jnp.arange(lo.shape[0]), -1)) + 1
