"""Nonlinear functions shared by the exciter models: PSS/E quadratic saturation, rectifier regulation."""

from __future__ import annotations

import jax.numpy as jnp


def nonzero(x):
    """A divisor that is ``x`` where ``x != 0`` and 1 elsewhere."""
    return jnp.where(x != 0, x, 1.0)


# --- shared nonlinear functions ---------------------------------------------------------------

def saturation_product(efd, e1, se1, e2, se2):
    """SE(EFD)·EFD of the PSS/E quadratic exciter saturation through (E1, SE(E1)), (E2, SE(E2)).

    PSS/E fits ``SE(x)·x = B (x - A)^2`` for ``x > A`` (0 below A and for ``x <= 0``), so that
    the curve passes through both points: with ``a = sqrt(SE1 E1/(SE2 E2))``,
    ``A = (a E2 - E1)/(a - 1)`` and ``B = SE2 E2 / (E2 - A)^2`` (OpenIPSL ``SE``). Data with
    SE1 = 0, SE2 = 0, E1 = E2 or SE1 E1 = SE2 E2 give no saturation.
    """
    ok = (se1 > 0) & (se2 > 0) & (e1 > 0) & (e2 > 0) & (e1 != e2)
    ratio = jnp.where(ok, se1 * e1 / jnp.where(ok, se2 * e2, 1.0), 4.0)
    a = jnp.sqrt(ratio)
    ok = ok & (jnp.abs(a - 1.0) > 1e-9)
    big_a = (a * e2 - e1) / jnp.where(ok, a - 1.0, 1.0)
    gap = jnp.where(ok, e2 - big_a, 1.0)
    big_b = jnp.where(ok, se2 * e2 / (gap * gap), 0.0)
    on = ok & (efd > big_a) & (efd > 0)
    d = jnp.where(on, efd - big_a, 0.0)
    return jnp.where(on, big_b * d * d, 0.0)


def saturation(efd, e1, se1, e2, se2):
    """SE(EFD) [-]: :func:`saturation_product` / EFD (0 for EFD <= 0)."""
    vx = saturation_product(efd, e1, se1, e2, se2)
    return jnp.where(efd > 0, vx / jnp.where(efd > 0, efd, 1.0), 0.0)


def rectifier_fex(i_n):
    """FEX(IN), the rectifier regulation characteristic (IEEE Std 421.5, Annex D).

    1 for IN <= 0; 1 - 0.577 IN up to 0.433; sqrt(0.75 - IN^2) up to 0.75; 1.732 (1 - IN) up
    to 1; 0 beyond.
    """
    mid = jnp.clip(i_n, 0.433, 0.75)
    return jnp.where(i_n <= 0.0, 1.0,
                     jnp.where(i_n <= 0.433, 1.0 - 0.577 * i_n,
                               jnp.where(i_n < 0.75, jnp.sqrt(0.75 - mid * mid),
                                         jnp.where(i_n <= 1.0, 1.732 * (1.0 - i_n), 0.0))))


__all__ = ["rectifier_fex", "saturation", "saturation_product"]
