"""One honest verdict per unit: identified, weakly identified, not identified or failed.

The verdict is computed in JAX (an integer and a bit set of reasons, so that it vmaps over
a fleet) and spelled out at the edge (:func:`describe`). It rests on the batch
identification's 95 % interval and information matrix, not on the online estimator's
convergence, and a unit is never ``identified`` when its interval is wider than
``identified_ci`` (+-10 %), when H <= 0, or when its playback diverges.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from .drem import ObserverConfig
from .estimate import Replay, replay
from .identify import Identified, IdentifySettings, identify
from .plant import Plant
from .recording import Recording
from .result import Estimate
from .settings import Settings

VERDICTS = ("identified", "weakly identified", "not identified", "failed")
"""Verdict codes 0..3, from best to worst."""

REASONS = {
    "offline": "the generator is offline (mean current below Settings.offline_current_pu)",
    "solver": "a solver failed (the online observer or the playback)",
    "not_finite": "the identification is not finite",
    "h_not_positive": "a2 <= 0: the recording gives no positive inertia",
    "playback_diverged": "the playback with the identified H diverges",
    "interval_very_wide": "the 95 % interval of H is wider than the not-identified limit (or unbounded)",
    "ill_conditioned": "inertia cannot be told apart from damping or the governor in these data",
    "interval_wide": "the 95 % interval of H is wider than +-10 %",
    "drem_contradicts": "the online (DREM) estimate converged more than 10 % away from the batch H",
    "negative_damping": "D < 0 with 95 % confidence: an oscillation source, or the governor model is off",
    "governor_model_off": "the data ask for a governor response more than 50 % off the model's",
    "drem_disagrees": "the online (DREM) estimate converged outside the 95 % interval",
    "drem_not_converged": "the online (DREM) estimate did not converge (no check of the batch value)",
}
"""Reason key -> its one-line explanation (bit k of ``Verdict.reasons`` is the k-th key)."""
_BIT = {name: 1 << k for k, name in enumerate(REASONS)}
_FAILED = ("offline", "solver", "not_finite", "h_not_positive", "playback_diverged")
_NOT_IDENTIFIED = ("interval_very_wide", "ill_conditioned")
_WEAK = ("interval_wide", "drem_contradicts", "negative_damping", "governor_model_off")
NOTES = ("drem_disagrees", "drem_not_converged")
"""Reasons that inform but do not set the verdict."""


class VerdictSettings(eqx.Module):
    """Thresholds of the verdict (static)."""

    identified_ci: float = eqx.field(static=True, default=0.10)
    """Largest relative half width of the 95 % interval of H for ``identified`` [-]."""
    not_identified_ci: float = eqx.field(static=True, default=0.5)
    """Relative half width beyond which H is ``not identified`` [-]."""
    max_condition: float = eqx.field(static=True, default=1e8)
    """Largest condition number of the scaled information matrix [-]."""
    diverged_smape: float = eqx.field(static=True, default=50.0)
    """Playback I_t sMAPE [%] above which the playback counts as diverged."""
    max_governor_gain_error: float = eqx.field(static=True, default=0.5)
    """Largest relative correction of the governor model's response for ``identified`` [-]
    (``Identified.governor_gain_error``): beyond it H rests on a governor model the data contradict."""


class Verdict(eqx.Module):
    """The verdict (index into ``VERDICTS``) and the reasons (bits, see ``REASONS``)."""

    code: Array
    reasons: Array


def verdict(est: Estimate, ident: Identified, rep: Replay,
            settings: VerdictSettings = VerdictSettings()) -> Verdict:
    """The verdict of one unit from its online estimate, its identification and its replay."""
    lo, hi = ident.h_ci95[0], ident.h_ci95[1]
    drem_h = est.h_s
    flags = {
        "offline": ~est.online,
        "solver": ~(est.solver_ok & rep.ok),
        "not_finite": ~ident.ok,
        "h_not_positive": ~(ident.a2 > 0),
        "playback_diverged": ~(rep.smape.i_t <= settings.diverged_smape),
        "interval_very_wide": ~(ident.relative_ci <= settings.not_identified_ci) | ~jnp.isfinite(hi),
        "ill_conditioned": ~(ident.condition <= settings.max_condition),
        "interval_wide": ~(ident.relative_ci <= settings.identified_ci),
        "drem_contradicts": est.converged & ~(jnp.abs(drem_h / ident.h_s - 1.0) <= settings.identified_ci),
        "drem_disagrees": est.converged & ((drem_h < lo) | (drem_h > hi)),
        "negative_damping": ident.d_ci95[1] < 0,
        "governor_model_off": ~(jnp.abs(ident.governor_gain_error) <= settings.max_governor_gain_error),
        "drem_not_converged": ~est.converged,
    }
    reasons = sum(jnp.where(flags[name], _BIT[name], 0) for name in REASONS)

    def any_of(names):
        return jnp.any(jnp.stack([flags[n] for n in names]))

    code = jnp.where(any_of(_FAILED), 3, jnp.where(any_of(_NOT_IDENTIFIED), 2,
                                                    jnp.where(any_of(_WEAK), 1, 0)))
    return Verdict(code=code, reasons=jnp.asarray(reasons, dtype=jnp.int32))


def describe(v: Verdict) -> tuple[str, list[str]]:
    """The verdict word and the reason keys of one unit (host side)."""
    bits = int(v.reasons)
    return VERDICTS[int(v.code)], [name for name, b in _BIT.items() if bits & b]


def assess(recording: Recording, plant: Plant, online: Estimate, config: ObserverConfig = ObserverConfig(),
           settings: Settings = Settings(), identify_settings: IdentifySettings = IdentifySettings(),
           verdict_settings: VerdictSettings = VerdictSettings()) -> tuple[Identified, Replay, Verdict]:
    """After the online estimate ``online`` (:func:`jaxdse.estimate`, trajectories not needed):
    the batch identification, the playback with the identified parameters, and the verdict.
    Pure; vmap it over a fleet or over noise draws."""
    ident = identify(recording, plant, config, settings, identify_settings)
    rep = replay(recording, plant, ident.a1, ident.a2, settings, ident.t_m_offset_pu,
                 ident.governor_gain_error)
    return ident, rep, verdict(online, ident, rep, verdict_settings)
