"""Helpers for ``eqx.Module`` parameter fields: array conversion and validation at the edge."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def as_float(x):
    """Converter for ``eqx.field``: a JAX float array leaf (float64 when x64 is enabled)."""
    return jnp.asarray(x, dtype=float)


def as_flag(x):
    """Converter for ``eqx.field``: an integer array leaf for a switch between signal paths (a
    PSS/E ICON such as QFLAG). The paths are chosen with ``jnp.where``, so units whose switches
    differ have one pytree structure and share a compiled program under vmap."""
    return jnp.asarray(x, dtype=int)


def check_flag(module, *names: str, allowed=(0, 1)) -> None:
    """Raise ``ValueError`` for a concrete flag field whose value is not one of ``allowed``."""
    words = ", ".join(str(a) for a in allowed[:-1]) + f" or {allowed[-1]}"
    for name in names:
        value = getattr(module, name)
        if concrete(value) and not np.all(np.isin(np.asarray(value), allowed)):
            raise ValueError(f"{type(module).__name__}.{name} must be {words}, got {value}")


def concrete(value) -> bool:
    """True for a value known now (not a tracer inside jit/vmap/grad): only those are validated."""
    return not isinstance(value, jax.core.Tracer)


def check_positive(module, *names: str) -> None:
    """Raise ``ValueError`` for a concrete field that is not strictly positive.

    Traced values (inside jit/vmap/grad) are not checked: validation happens at the edge.
    """
    for name in names:
        value = getattr(module, name)
        if concrete(value) and np.any(~(np.asarray(value) > 0)):
            raise ValueError(f"{type(module).__name__}.{name} must be > 0, got {value}")


def check_nonnegative(module, *names: str) -> None:
    """Like :func:`check_positive` but admits zero."""
    for name in names:
        value = getattr(module, name)
        if concrete(value) and np.any(~(np.asarray(value) >= 0)):
            raise ValueError(f"{type(module).__name__}.{name} must be >= 0, got {value}")


def all_concrete(*values) -> bool:
    """True when every value is known now (a combination of fields is validated only then)."""
    return all(concrete(v) for v in values)


def check_that(module, ok, message: str) -> None:
    """``ValueError`` for a concrete parameter combination that is invalid (tracers pass)."""
    if concrete(ok) and not bool(np.all(np.asarray(ok))):
        raise ValueError(f"{type(module).__name__}: {message}")
