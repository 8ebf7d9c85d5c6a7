"""What tuning the observer may change and how its loss is weighted (plain settings, no JAX
computation): read by the TOML config at the edge and by the tuner in ``_many.tune``."""

from __future__ import annotations

import equinox as eqx

TUNABLE = ("lambda1", "lambda2", "lambda3", "c1", "c2", "k_ext", "gamma1", "gamma2", "k_obs")
"""Observer parameters that :func:`jaxdse.tune` adjusts by default (paper Table I)."""

AUTODIFF_MODES = ("auto", "fwd", "bwd")
"""How :func:`jaxdse.tune` takes the gradient: "auto", forward or reverse mode."""


class LossWeights(eqx.Module):
    """Weights of the three parts of :func:`jaxdse.tuning_loss` and the burn-in of the x2 part."""

    x2: float = 1.0
    playback: float = 1.0
    parameter: float = 1.0
    burn_in_s: float = 10.0
    band: float = 0.01
    """Band of the parameter part (relative): half the 2 % convergence band, for margin."""
