"""``assess``: one unit's whole job as one pure function, on one front end.

recording -> front end and T_ref (once) -> online DREM/I&I estimate -> batch identification
-> replay with the identified parameters -> verdict. The runner (``_many/runner.py``) vmaps
it over the units of a fleet or a run.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx

from .drem import ObserverConfig
from .estimate import Replay, estimate_front, replay_front
from .front_end import reference_torque
from .identify import Identified, IdentifySettings, front_ends, identify_front
from .plant import Plant
from .recording import Recording
from .result import Estimate
from .settings import Settings
from .verdict import Verdict, VerdictSettings, online_verdict, verdict


class Assessment(eqx.Module):
    """Everything one unit's run produced (arrays in JAX or, after the runner, on the host)."""

    estimate: Estimate
    """The online DREM/I&I estimate (its own playback only when identification is off)."""
    identified: Identified | None
    """The batch identification (None when it is off)."""
    replay: Replay | None
    """The playback with the identified parameters (None when identification is off)."""
    verdict: Verdict
    """The verdicts (without identification: the online estimate's convergence alone)."""


def assess(recording: Recording, plant: Plant, config: ObserverConfig = ObserverConfig(),
           settings: Settings = Settings(), identify_settings: IdentifySettings | None = IdentifySettings(),
           verdict_settings: VerdictSettings = VerdictSettings(), a2_reference=None) -> Assessment:
    """The online estimate, the batch identification, the replay with the identified H, D and
    the verdict of one unit, from one front end and one T_ref.

    With identification (``identify_settings`` not None) the online estimator's own playback
    is not run (the replay is the one shown). Pure: jit and vmap (fleets, noise draws) pass
    through; :func:`jaxdse.assess_units` runs many units.
    """
    ts = recording.t_s
    fe, draws = front_ends(recording, plant, settings, identify_settings)
    t_ref = reference_torque(ts, fe, plant.governor, settings)
    if identify_settings is None:
        est = estimate_front(ts, fe, t_ref, plant, config, settings, None, a2_reference)
        return Assessment(est, None, None, online_verdict(est))
    online = estimate_front(ts, fe, t_ref, plant, config, dataclasses.replace(settings, playback=False),
                            None, a2_reference)
    ident = identify_front(recording, fe, t_ref, plant, config, settings, identify_settings, draws)
    rep = replay_front(ts, fe, t_ref, ident.t_m0_pu, plant, ident.a1, ident.a2, settings,
                       ident.t_m_offset_pu, ident.governor_gain_error)
    return Assessment(online, ident, rep, verdict(online, ident, rep, verdict_settings, plant.h_model_error))
