"""Per-unit bases and small helpers shared by every stage.

Per-unit convention (stated once, used everywhere):

* **Machine base** -- the machine's rated apparent power ``Machine.s_rated_mva`` and rated
  terminal voltage ``Machine.v_rated_kv``. All machine reactances, the stator resistance,
  torques and the terminal current seen by the observer are on this base.
* **System base** -- ``Plant.s_base_mva`` (100 MVA by default) with the nominal voltage of
  each bus as voltage base. The line, the transformer, the auxiliary load and every PMU
  phasor are on this base. The LV-bus voltage base equals the machine's rated voltage, so a
  voltage in pu is the same number on both bases; a current converts with
  ``i_machine = i_system * s_base_mva / s_rated_mva``.
* Angles are in rad, time in s, frequency in Hz, speed deviation ``x2`` in rad/s.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def as_float(x):
    """Converter for ``eqx.field``: a JAX float array leaf (float64 when x64 is enabled)."""
    return jnp.asarray(x, dtype=float)


def check_positive(module, *names: str) -> None:
    """Raise ``ValueError`` for a concrete field that is not strictly positive.

    Traced values (inside jit/vmap/grad) are not checked: validation happens at the edge.
    """
    for name in names:
        value = getattr(module, name)
        if isinstance(value, jax.core.Tracer):
            continue
        if np.any(~(np.asarray(value) > 0)):
            raise ValueError(f"{type(module).__name__}.{name} must be > 0, got {value}")


def check_nonnegative(module, *names: str) -> None:
    """Like :func:`check_positive` but admits zero."""
    for name in names:
        value = getattr(module, name)
        if isinstance(value, jax.core.Tracer):
            continue
        if np.any(~(np.asarray(value) >= 0)):
            raise ValueError(f"{type(module).__name__}.{name} must be >= 0, got {value}")
