"""A verdict per parameter: identified, weakly identified, not identified or failed.

H gets its own verdict from its own marginal 95 % interval and from what it rests on: the
same fit with D fixed at 0 and with the governor correction fixed at 0. If H moves outside
its interval under an alternative that the data cannot rule out (the coefficient's own 95 %
interval contains 0), H is downgraded and the reason names the assumption; an alternative
the data reject is no assumption. D and the
governor correction get their own verdicts, with the model-structure findings in words (a
3rd-order model lumps the excitation and stabiliser damping into D; a governor response far
from the .dyr model's). The unit's headline is H's verdict, because H is what the fleet report
files. A unit is never ``identified`` when H's interval is wider than ``identified_ci``
(+-10 %), when H <= 0, when H rests on an assumption the data cannot rule out, when its
estimator model was simplified by a fallback for its data and H's interval does not cover the
error that can cause (``Plant.h_model_error``), or when its playback diverges. A negative D
is D's finding (the 3rd-order model lumps the excitation and
stabiliser damping into it), not H's.

The verdicts are computed in JAX (integers and a bit set of reasons, so that they vmap over a
fleet) and spelled out at the edge (:func:`describe`).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array

from .estimate import Replay
from .identify import Z95, Identified
from .result import Estimate

VERDICTS = ("identified", "weakly identified", "not identified", "failed")
"""Verdict codes 0..3, from best to worst."""
D_VERDICTS = ("identified", "negative", "not identified", "failed")
"""D's verdict codes 0..3 (``Verdict.d_code``): ``negative`` is D < 0 with 95 % confidence
(its interval excludes 0 from below), a finding about the unit's response (see
:data:`D_MEANING`), not a weaker estimate."""
D_MEANING = (
    "D is the damping of the swing equation fitted to the recording (2H d(dw)/dt = Tm - Te - D dw, "
    "on the plant's MBASE): it lumps all the damping the recorded response shows beyond the "
    "modelled torques, that of the damper windings, the exciter and stabiliser, and the governor "
    "beyond its model. It is not the D constant of the machine records (PSS/E's D of GENROU, "
    "GENSAL, ..., the speed-deviation damping alone, often 0) and is no estimate of it; its 95 % "
    "interval covers the measurement noise only, not how D changes with the model.")
"""What the identified D is and is not, stated once for every report."""

REASONS = {
    # the unit failed: no parameter
    "offline": "the generator is offline (mean current below Settings.offline_current_pu)",
    "solver": "a solver failed (the online observer or the playback)",
    "not_finite": "the identification is not finite",
    "h_not_positive": "a2 <= 0: the recording gives no positive inertia",
    "playback_diverged": "the playback with the identified H diverges",
    # H (the headline)
    "interval_very_wide": "the 95 % interval of H is wider than the not-identified limit (or unbounded)",
    "interval_wide": "the 95 % interval of H is wider than the identified limit",
    "h_rests_on_damping": "H moves outside its interval when D is fixed at 0, which the data cannot rule "
                          "out: H rests on the fitted damping",
    "h_rests_on_governor": "H moves outside its interval without the governor correction, which the data "
                           "cannot rule out: H rests on correcting the governor model",
    "power_above_droop": "the measured power answers the frequency far more strongly than the governor's "
                         "droop allows: if the governor data are right, the power, and H with it, are "
                         "too large (a current logged as peak instead of RMS, a CT ratio)",
    "drem_contradicts": "the online (DREM) estimate converged more than the identified limit away from "
                        "the batch H",
    "model_simplified": "the estimator's model was simplified by a fallback for the plant's data (q-axis "
                        "circuits left out, or constant mechanical torque for a missing or unmodelled "
                        "governor; see the unit's fallbacks), and H's 95 % interval does not cover the "
                        "error that can cause",
    # D and the governor correction (their own verdicts; model-structure findings in words)
    "negative_damping": "D < 0 with 95 % confidence: the 3rd-order model lumps the excitation and "
                        "stabiliser damping into D",
    "d_interval_wide": "the 95 % interval of D is wider than its own value",
    "governor_model_off": "the data ask for a governor response far from the model's",
    # notes
    "drem_disagrees": "the online (DREM) estimate converged outside the 95 % interval",
    "drem_not_converged": "the online (DREM) estimate did not converge (no check of the batch value)",
}
"""Reason key -> its one-line explanation (bit k of ``Verdict.reasons`` is the k-th key)."""
_BIT = {name: 1 << k for k, name in enumerate(REASONS)}
_FAILED = ("offline", "solver", "not_finite", "h_not_positive", "playback_diverged")
_NOT_IDENTIFIED = ("interval_very_wide",)
_WEAK = ("interval_wide", "h_rests_on_damping", "h_rests_on_governor", "model_simplified",
         "power_above_droop")
FINDINGS = ("negative_damping", "d_interval_wide", "governor_model_off")
"""Reasons about D and the governor correction that set those parameters' verdicts, not H's.
A negative D reaches H's verdict through ``h_rests_on_damping`` and through the filter spread
of H's interval: on the ANDES fleets the one unit 14 % off (ieee14 line trip, D < 0) has a
filter spread of 7.5 %, so an interval of +-15 %."""
NOTES = ("drem_contradicts", "drem_disagrees", "drem_not_converged") + FINDINGS
"""Reasons that do not set the headline (H's) verdict. The online DREM/I&I estimate uses a
fraction of the recording's information (it adapts slowly, from its start); whether it
converged, and where, is reported beside the batch H, never held against it."""


class VerdictSettings(eqx.Module):
    """Thresholds of the verdict (static)."""

    identified_ci: float = eqx.field(static=True, default=0.10)
    """Largest relative half width of the 95 % interval of H for ``identified`` [-]."""
    not_identified_ci: float = eqx.field(static=True, default=0.5)
    """Relative half width beyond which H is ``not identified`` [-]."""
    diverged_smape: float = eqx.field(static=True, default=50.0)
    """Playback I_t sMAPE [%] above which the playback counts as diverged."""
    max_governor_gain_error: float = eqx.field(static=True, default=0.5)
    """Largest relative correction of the governor model's response [-]
    (``Identified.governor_gain_error``) for the governor correction's verdict ``identified``."""
    max_governor_excess: float = eqx.field(static=True, default=0.25)
    """Largest governor correction above the model's response (the measured power answering the
    frequency more strongly than the stated droop allows) with which H stays ``identified`` [-].
    H scales with the measured power, and so does this correction when the governor data are
    right: a current logged as peak instead of RMS gives +41 % (x1.414) at any load, where at
    part load every rating check passes. Real governors answer less than their droop (deadbands,
    limits), rarely more: on the ANDES bench the correction stays within -12 % and +17 %."""


class Verdict(eqx.Module):
    """The verdicts (indices into ``VERDICTS``) of H (the headline), D and the governor
    correction, and the reasons (bits, see ``REASONS``)."""

    code: Array
    """H's verdict: the unit's headline (H is what a fleet report files)."""
    reasons: Array
    d_code: Array
    """D's verdict (an index into ``D_VERDICTS``)."""
    governor_code: Array
    """The governor correction's verdict: ``identified`` when the .dyr governor needs no more
    than ``max_governor_gain_error`` of a correction; ``weakly identified`` beyond."""


def verdict(est: Estimate | None, ident: Identified, rep: Replay | None,
            settings: VerdictSettings = VerdictSettings(), h_model_error=0.0) -> Verdict:
    """The verdicts of one unit from its online estimate, its identification and its replay;
    ``h_model_error``: the relative error of H that a simplified estimator model can cause
    (``Plant.h_model_error``; inf: unknown), which H's interval must cover for ``identified``.
    ``est`` and ``rep`` None (a stream's windowed identification): the checks that need them
    are left out."""
    lo, hi = ident.h_ci95[0], ident.h_ci95[1]
    no = jnp.array(False)
    drem_h = jnp.nan if est is None else est.h_s
    converged, online = (no, ~no) if est is None else (est.converged, est.online)
    solver_ok = ~no if est is None else est.solver_ok
    rep_ok, smape_i = (~no, jnp.zeros(())) if rep is None else (rep.ok, rep.smape.i_t)

    def outside(h):
        return ~((h >= lo) & (h <= hi))

    d_lo, d_hi = ident.d_ci95[0], ident.d_ci95[1]
    flags = {
        "offline": ~online,
        "solver": ~(solver_ok & rep_ok),
        "not_finite": ~ident.ok,
        "h_not_positive": ~(ident.a2 > 0),
        "playback_diverged": ~(smape_i <= settings.diverged_smape),
        "interval_very_wide": ~(ident.relative_ci <= settings.not_identified_ci) | ~jnp.isfinite(hi),
        "interval_wide": ~(ident.relative_ci <= settings.identified_ci),
        # An alternative counts only where the data cannot rule it out (its coefficient within
        # 95 % of 0): where they ask for D or a correction with confidence, H rests on the data.
        "h_rests_on_damping": outside(ident.h_without_damping_s) & plausible_zero(ident, 0),
        "h_rests_on_governor": outside(ident.h_without_governor_correction_s) & plausible_zero(ident, 3),
        "power_above_droop": (ident.governor_gain_error > settings.max_governor_excess)
                             & ~plausible_zero(ident, 3),
        "drem_contradicts": converged & ~(jnp.abs(drem_h / ident.h_s - 1.0) <= settings.identified_ci),
        "model_simplified": (h_model_error > 0) & ~(ident.relative_ci >= h_model_error),
        "negative_damping": d_hi < 0,
        "d_interval_wide": ~(0.5 * (d_hi - d_lo) <= jnp.abs(ident.d_pu_s)),
        "governor_model_off": ~(jnp.abs(ident.governor_gain_error) <= settings.max_governor_gain_error),
        "drem_disagrees": converged & outside(drem_h),
        "drem_not_converged": (est is not None) & ~converged,
    }
    reasons = sum(jnp.where(flags[name], _BIT[name], 0) for name in REASONS)

    def any_of(names):
        return jnp.any(jnp.stack([flags[n] for n in names]))

    failed = any_of(_FAILED)
    code = jnp.where(failed, 3, jnp.where(any_of(_NOT_IDENTIFIED), 2, jnp.where(any_of(_WEAK), 1, 0)))
    d_code = jnp.where(failed, 3, jnp.where(flags["d_interval_wide"], 2,
                                            jnp.where(flags["negative_damping"], 1, 0)))
    gov_code = jnp.where(failed, 3, jnp.where(flags["governor_model_off"], 1, 0))
    return Verdict(code=code, reasons=jnp.asarray(reasons, dtype=jnp.int32), d_code=d_code,
                   governor_code=gov_code)


def plausible_zero(ident: Identified, k: int):
    """Coefficient ``k`` of (a1, a2, c, g) is within its 95 % interval of 0."""
    coef = (ident.a1, ident.a2, ident.t_m_offset_pu * ident.a2, ident.governor_gain_error * ident.a2)[k]
    return jnp.abs(coef) <= Z95 * jnp.sqrt(jnp.maximum(ident.covariance[k, k], 0.0))


def online_verdict(est: Estimate) -> Verdict:
    """The verdict of a unit without the batch identification: the online (DREM) estimate's
    convergence alone (``identified`` or ``not identified``)."""
    ok = est.converged & jnp.isfinite(est.a2) & (est.a2 > 0)
    failed = ~est.solver_ok | ~est.online
    bits = (jnp.where(~est.converged, _BIT["drem_not_converged"], 0)
            + jnp.where(~est.online, _BIT["offline"], 0) + jnp.where(~est.solver_ok, _BIT["solver"], 0))
    code = jnp.where(failed, 3, jnp.where(ok, 0, 2))
    return Verdict(code=code, reasons=jnp.asarray(bits, dtype=jnp.int32), d_code=code, governor_code=code)


def describe(v: Verdict) -> tuple[str, list[str]]:
    """The verdict word and the reason keys of one unit (host side)."""
    bits = int(v.reasons)
    return VERDICTS[int(v.code)], [name for name, b in _BIT.items() if bits & b]
