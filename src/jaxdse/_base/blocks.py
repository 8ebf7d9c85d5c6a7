"""Transfer-function blocks shared by the standard models (governors, exciters, stabilisers).

Each block returns ``(output, d(state)/dt)`` for its one state, with no Python branching on
array values, so one state layout serves every parameter set under vmap:

* a lag ``1/(1 + sT)`` with ``T = 0`` and a lead-lag ``(1 + sTa)/(1 + sTb)`` with ``Tb = 0`` are
  pass-throughs whose state is kept with zero derivative (PSS/E treats a zero time constant so);
* denominators of bypassed blocks are replaced by 1, so that neither value nor gradient is NaN;
* non-windup limits (IEEE 421.5-2016, Annex E) block the derivative that would push the state
  further out, and the output is the state clipped to its limits.
"""

from __future__ import annotations

import jax.numpy as jnp


def safe(t):
    """A denominator that is ``t`` where ``t > 0`` and 1 elsewhere (bypassed blocks)."""
    return jnp.where(t > 0, t, 1.0)


def lag(u, x, t):
    """First-order lag 1/(1 + sT): (output, dx/dt). T = 0: pass-through, dx/dt = 0."""
    on = t > 0
    return jnp.where(on, x, u), jnp.where(on, (u - x) / safe(t), 0.0)


def lead_lag(u, x, t_lead, t_lag):
    """(1 + s t_lead)/(1 + s t_lag): (output, dx/dt). t_lag = 0: pass-through."""
    on = t_lag > 0
    ts = safe(t_lag)
    return (jnp.where(on, x + (t_lead / ts) * (u - x), u),
            jnp.where(on, (u - x) / ts, 0.0))


def washout(u, x, t):
    """s/(1 + sT) (a filtered derivative): (output, dx/dt). T = 0: output 0 (not realisable)."""
    on = t > 0
    d = jnp.where(on, (u - x) / safe(t), 0.0)
    return d, d


def blocked(x, dx, lo, hi):
    """Non-windup rule: no motion beyond a limit the state sits on."""
    return jnp.where(((x >= hi) & (dx > 0)) | ((x <= lo) & (dx < 0)), 0.0, dx)


def nonwindup_lag(u, x, t, lo, hi, gain=1.0):
    """K/(1 + sT) with non-windup limits [lo, hi] on its state (IEEE 421.5 Fig. E.5).

    Returns (clipped output, dx/dt). T = 0: output clip(K u), dx/dt = 0.
    """
    on = t > 0
    dx = jnp.where(on, blocked(x, (gain * u - x) / safe(t), lo, hi), 0.0)
    return jnp.clip(jnp.where(on, x, gain * u), lo, hi), dx


__all__ = ["blocked", "lag", "lead_lag", "nonwindup_lag", "safe", "washout"]
