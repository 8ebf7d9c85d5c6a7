"""XLA helpers for the per-sample loops."""

from __future__ import annotations

import jax


def hoist(*coefficients):
    """Materialise scalar coefficients once. Without this barrier XLA fuses their (complex
    exp, division) arithmetic into every per-sample loop and recomputes it per sample."""
    return jax.lax.optimization_barrier(coefficients)
