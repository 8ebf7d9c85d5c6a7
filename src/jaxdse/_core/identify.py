"""Batch identification of a1, a2 (H, D) from a whole recording, with 95 % intervals.

The paper's DREM/I&I estimator adapts online and slowly; it uses a fraction of the
information a recording holds. After it, :func:`identify` fits the same filtered swing
equation (paper App. Eq. 17, in the first-order form of Remark 2) to the whole recording at
once:

    F[s x2] = -a1 F[x2] + a2 F[Tm - Te] + c F[1] + g F[Tm - Tm(0)]

with F the paper's 3rd-order filter, x2 = 2 pi (f - f0) + d(delta - theta)/dt the measured
speed deviation (the derivatives F s and F s^2 taken exactly), Te the air-gap torque
(the front end) and Tm the governor model's torque. Two nuisance terms absorb what biases
H on real plants: ``c`` (= a2 times an offset of T_ref: its quasi-steady-state estimate is
off when the recording starts in a transient) and ``g`` (a2 times a gain error of the
governor's response). The regression is linear, so the solution is closed form:

* the filters are integrated exactly between samples (``lti``), with no step-size limit;
* the governor model is driven by the speed low-passed forwards and backwards at
  ``governor_smoothing_hz`` (2 Hz): governors do not respond in the electromechanical band,
  and the measurement noise of the speed would otherwise enter Tm amplified by 1/R and bias
  a2 towards zero (errors in the regressors);
* iteratively reweighted least squares with Huber weights: the instants after a switching
  (a line trip), when the 3rd-order model is furthest from a real machine, are downweighted;
* the interval has three parts, added in quadrature: the noise part (``noise_interval``);
  the
  filter spread (refits with F made slower and faster: a right model finds the same a2
  with any filter; a standard deviation, so 1.96 times it, from the refits that fit the swing
  equation at all); and ``model_error``, the 3rd-order model's error against real machines.

The noise part propagates white noise of the levels measured on the recording itself (second
differences of |V|, |I|, the angles and f) through the whole front end and the weighted fit:

* ``"bootstrap"`` (default): ``bootstrap_draws`` refits, vmapped, on the recording with
  white noise of those levels added once more, each refit the weighted least squares with
  the fit's Huber weights (a solve of the draw's own normal equations; no reweighting). Neither
  a first-order (delta-method) propagation nor a one-step refit (theta + A^-1 X_k^T W r_k with
  the fit's A) is a substitute: the noise of |V|, |I| and the angles enters the regressors and
  the left-hand side together (errors in variables, through the same filtered rotor angle),
  and its second-order terms in X_k^T W X_k and X_k^T W z_k cancel only in the full solve; on
  the ANDES bench the one-step form widened some intervals tenfold;
* ``"sandwich"``: the Newey-West sandwich of the residuals, whose Bartlett window
  ``hac_window_s`` covers the filtered residual's autocorrelation (no noise model).

With ``IdentifySettings(output_error=True)`` the equation-error fit is the start of an
output-error refinement: optimistix's Levenberg-Marquardt minimises the playback residual
(x2, I_t, P_t, Q_t, each over its noise level) over a1, a2, the torque offset and the
governor gain error, with forward-mode Jacobians through the playback, and the covariance is
the same sandwich on the Jacobian's scores. It is exact for a 3rd-order machine; against
6th-order (GENROU) machines it biases H (the playback's errors are the model's, not noise),
so it is off by default (see ``experiments/andes_bench``).

H = ws / (2 a2) and D = a1 / a2, with their 95 % intervals from the interval of a2 (a
monotone map) and the delta method for D. The information matrix, scaled to unit diagonal,
gives the condition number (on the host) that tells whether a2 is separable from the other
terms. The per-unit graph holds no LAPACK call (normal equations with an unrolled Cholesky,
Taylor matrix exponentials), so that it vmaps over a fleet.
"""

from __future__ import annotations

import dataclasses
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._models.governors import AbstractGovernor
from .drem import ObserverConfig
from .estimate import scaled_governor
from .front_end import FrontEnd, front_end, playback_inputs, reference_torque
from .lti import butterworth2, filter_states, hold_discretisation, lag_chain
from .machine import damping_from_a, inertia_from_a2
from .plant import Plant
from .playback import playback
from .recording import Recording
from .settings import Settings
from .signals import jumps

Z95 = 1.959963984540054
"""Two-sided 95 % quantile of the standard normal distribution."""
PARAMETERS = ("a1", "a2", "c", "g")
"""Coefficients of the regression: damping, inertia, torque offset, governor gain error."""


class IdentifySettings(eqx.Module):
    """Static choices of :func:`identify` (never differentiated or vmapped)."""

    settle_s: float = eqx.field(static=True, default=1.0)
    """Samples of the first ``settle_s`` [s] after the first full derivative window
    (``Settings.derivative_half_width``) are left out (the filters start from rest there)."""
    governor_smoothing_hz: float = eqx.field(static=True, default=2.0)
    """Cut-off [Hz] of the zero-phase low-pass of the speed that drives the governor model."""
    robust_iterations: int = eqx.field(static=True, default=10)
    """Reweighting steps of the Huber regression (0: ordinary least squares)."""
    huber_k: float = eqx.field(static=True, default=1.345)
    """Huber threshold in robust standard deviations (1.345: 95 % efficiency for Gaussian noise)."""
    hac_window_s: float = eqx.field(static=True, default=2.0)
    """Newey-West window of the residual autocorrelation [s]."""
    noise_interval: Literal["bootstrap", "sandwich"] = eqx.field(static=True, default="bootstrap")
    """How the noise part of the interval is found (see the module text)."""
    bootstrap_draws: int = eqx.field(static=True, default=32)
    """Noise draws of the parametric bootstrap (``noise_interval="bootstrap"``; at least 2)."""
    bootstrap_seed: int = eqx.field(static=True, default=0)
    """Seed of the bootstrap's noise (the result is a pure function of the recording)."""
    spread_scales: tuple[float, ...] = eqx.field(static=True, default=(0.5, 2.0))
    """The fit is repeated with the filter F's poles scaled by these factors; the largest
    change of a2 widens the interval (see ``Identified.filter_spread``). () turns it off."""
    model_error: float = eqx.field(static=True, default=0.02)
    """Relative error of a2 [-] that the 3rd-order swing model carries against a real (6th-order)
    machine whatever the data, added to the interval in quadrature. 0.02: on the ANDES bench's
    noise-free event recordings (GENROU machines, their own governors and exciters), the
    identified H lies within 2 % of the truth for most machines (``experiments/andes_bench``);
    without this term the intervals of strong events are narrower than that error."""
    output_error: bool = eqx.field(static=True, default=False)
    """Refine the equation-error fit by output error on the playback (see the module text)."""
    output_error_steps: int = eqx.field(static=True, default=50)
    """Largest number of Levenberg-Marquardt steps of the output-error refinement."""

    def __check_init__(self):
        if self.noise_interval not in ("bootstrap", "sandwich"):
            raise ValueError(f"IdentifySettings.noise_interval must be 'bootstrap' or 'sandwich', "
                             f"got {self.noise_interval!r}")
        if self.noise_interval == "bootstrap" and self.bootstrap_draws < 2:
            raise ValueError("IdentifySettings.bootstrap_draws must be >= 2 for the bootstrap "
                             f"(noise_interval='sandwich' needs none), got {self.bootstrap_draws}")


class Identified(eqx.Module):
    """The batch estimate of one recording: parameters, intervals and identifiability."""

    a1: Float[Array, ""]
    a2: Float[Array, ""]
    h_s: Float[Array, ""]
    """Inertia H [s] = ws / (2 a2)."""
    d_pu_s: Float[Array, ""]
    """Damping D [pu torque per rad/s] = a1 / a2."""
    h_ci95: Float[Array, " 2"]
    """95 % interval of H [s]; the upper end is +inf when the interval of a2 reaches zero."""
    d_ci95: Float[Array, " 2"]
    """95 % interval of D (delta method)."""
    se_a1: Float[Array, ""]
    se_a2: Float[Array, ""]
    covariance: Float[Array, "4 4"]
    """Covariance of (a1, a2, c, g) (``PARAMETERS``): over the bootstrap draws, or the sandwich."""
    noise_levels: Float[Array, " 5"]
    """Standard deviations of the white noise found on |V| and |I| (relative), on their angles
    [rad] and on f [Hz] (NaN without a frequency channel), from second differences."""
    t_m_offset_pu: Float[Array, ""]
    """c / a2: the constant offset of Tm that the data ask for [pu]."""
    governor_gain_error: Float[Array, ""]
    """g / a2: the relative error of the governor model's response [-]."""
    relative_ci: Float[Array, ""]
    """Half width of the 95 % interval of a2 over a2 (the relative uncertainty of H) [-]:
    ``relative_ci_noise``, ``Z95 * filter_spread`` and ``IdentifySettings.model_error`` added
    in quadrature."""
    relative_ci_noise: Float[Array, ""]
    """The part from the measurement noise: 1.96 se_a2 / a2 [-]."""
    filter_spread: Float[Array, ""]
    """Largest relative change of a2 when the filter F is made slower or faster
    (``IdentifySettings.spread_scales``) [-]. Were the model right, every filter would find
    the same a2 up to noise; a spread is model error (a 6th-order machine, a governor model
    that is off), which the residual's variance does not show. It enters the interval as a
    standard deviation (``Z95 * filter_spread``). Only refits that explain at least half of
    what the main fit explains count (``filter_spread_fits``)."""
    filter_spread_fits: Array
    """How many of the refits of ``spread_scales`` count in ``filter_spread`` [-]."""
    information: Float[Array, "4 4"]
    """Information matrix of (a1, a2, c, g), scaled to unit diagonal [-]; its condition number
    (:func:`condition_number`, on the host) tells whether a2 is separable from the others."""
    t_ref_pu: Float[Array, ""]
    """T_ref [pu] of the fit (the quasi-steady state's, shared with the online estimate and the
    replay): the offset ``t_m_offset_pu`` is relative to it."""
    t_m0_pu: Float[Array, ""]
    """The governor model's initial torque [pu]: ``governor_gain_error`` scales the response
    about it."""
    h_variance_inflation: Float[Array, ""]
    """Variance inflation of a2 [-]: how much the other parameters (D, the torque offset, the
    governor correction) widen H's interval through their correlation with it (1: not at all)."""
    h_without_damping_s: Float[Array, ""]
    """H [s] of the same fit with D fixed at 0. Outside H's interval: H rests on D."""
    h_without_governor_correction_s: Float[Array, ""]
    """H [s] of the same fit with the governor correction fixed at 0 (the .dyr governor as it
    is). Outside H's interval: H rests on correcting the governor model."""
    samples: Array
    """Samples used (valid, after ``settle_s``)."""
    ok: Array
    """All of the above is finite."""
    output_error: Array
    """The output-error refinement gave these values (False: the equation error did, because
    the refinement was off or did not converge)."""


def identify(recording: Recording, plant: Plant, config: ObserverConfig = ObserverConfig(),
             settings: Settings = Settings(), identify_settings: IdentifySettings = IdentifySettings(),
             ) -> Identified:
    """Fit a1, a2 (H, D) to the whole recording at once, with 95 % intervals.

    Arguments:
        recording, plant: as for :func:`jaxdse.estimate` (the same front end is used).
        config: the filter F is the observer's (lambda1-3, paper Table I).
        settings: the derivative window and the T_ref window of the front end; the playback
            integrator of the output-error refinement.
        identify_settings: settle time, governor smoothing, robust weights, HAC window,
            output-error refinement.

    Returns:
        An :class:`Identified`. Pure: jit, vmap (fleets, noise draws) and grad pass through.
    """
    fe, draws = front_ends(recording, plant, settings, identify_settings)
    return identify_front(recording, fe, reference_torque(recording.t_s, fe, plant.governor, settings),
                          plant, config, settings, identify_settings, draws)


class Draws(NamedTuple):
    """The parametric bootstrap's noise draws of a recording (:func:`front_ends`)."""

    front_ends: FrontEnd
    """The front ends of the draws (leading axis: the draw)."""
    levels: Array
    """The noise levels added (``Identified.noise_levels``)."""


def front_ends(recording: Recording, plant: Plant, settings: Settings,
               identify_settings: IdentifySettings | None) -> tuple[FrontEnd, Draws | None]:
    """The recording's front end and, for the bootstrap, its noise draws (None without the
    bootstrap), from one vmapped front end: one copy of it in the compiled graph, however
    many draws."""
    s = identify_settings
    if s is None or s.noise_interval != "bootstrap":
        return front_end(recording, plant, settings), None
    ts = recording.t_s
    n = ts.shape[0] if recording.n_samples is None else recording.n_samples
    levels = noise_levels(recording, jnp.arange(ts.shape[0]) < n)

    def noisy(key):  # the recording with white noise of its own levels added once more
        # Each sample's noise from its own index: a padded recording gets the same draws.
        e = jax.vmap(lambda k: jax.random.normal(jax.random.fold_in(key, k), (5,), dtype=ts.dtype))(
            jnp.arange(ts.shape[0])).T
        return add_noise(recording, levels, e)

    keys = jax.random.split(jax.random.PRNGKey(s.bootstrap_seed), s.bootstrap_draws)
    recordings = jax.tree_util.tree_map(lambda x, xs: jnp.concatenate([x[None], xs]),
                                        recording, jax.vmap(noisy)(keys))
    fes = jax.vmap(lambda r: front_end(r, plant, settings))(recordings)
    return (jax.tree_util.tree_map(lambda x: x[0], fes),
            Draws(jax.tree_util.tree_map(lambda x: x[1:], fes), levels))


def identify_front(recording: Recording, fe: FrontEnd, t_ref, plant: Plant, config: ObserverConfig,
                   settings: Settings, identify_settings: IdentifySettings,
                   draws: Draws | None = None) -> Identified:
    """:func:`identify` on a front end computed once and its T_ref [pu], which the online
    estimate and the replay share; ``draws``: the bootstrap draws' front ends
    (:func:`front_ends`; needed for ``noise_interval="bootstrap"``)."""
    s = identify_settings
    if s.noise_interval == "bootstrap" and draws is None:
        raise ValueError("identify_front: the bootstrap needs its draws' front ends (front_ends())")
    ts = recording.t_s
    dt = ts[1] - ts[0]
    lead = max(settings.derivative_half_width, 1)      # the first sample with a full derivative window
    valid = fe.valid & (ts >= ts[min(lead, ts.shape[0] - 1)] + s.settle_s)
    window = jnp.maximum(jnp.round(s.hac_window_s / dt), 1.0).astype(jnp.int32)
    smoothing = hold_discretisation(*butterworth2(s.governor_smoothing_hz, ts.dtype), dt)
    poles = jnp.stack([config.lambda1, config.lambda2, config.lambda3])
    filters = {k: hold_discretisation(*lag_chain(k * poles), dt) for k in (1.0, *s.spread_scales)}
    # The regression's inputs of the recording and of the bootstrap's draws, vmapped (one copy).
    every = jax.tree_util.tree_map(lambda x, *xs: jnp.concatenate([jnp.asarray(x)[None], *xs]), fe,
                                   *(() if draws is None else (draws.front_ends,)))
    # The governor's input of each; its quiet stretch from the recording's, each bootstrap draw
    # its own mean over it.
    dws = jax.vmap(lambda f: governor_input(f, plant, smoothing, lead))(every)
    quiet = _quiet_samples(fe, dws[0], dt, min(lead, ts.shape[0] - 2),
                           jnp.round(settings.qss_window_s / dt))
    signals, t_m0 = jax.vmap(lambda f, dw: _signals(f, dw, recording, plant, t_ref, dt, lead,
                                                    quiet))(every, dws)
    signals, draw_signals, t_m0 = signals[0], signals[1:], t_m0[0]

    def fit(disc, sig):
        design, z = _regression(sig, disc)
        return design, z, _huber(design, z, valid, s.robust_iterations, s.huber_k)

    def explained(z, resid):  # the share of the filtered acceleration's variance the fit explains
        v = valid.astype(z.dtype)
        centred = z - jnp.sum(v * z) / jnp.maximum(jnp.sum(v), 1.0)
        return 1.0 - jnp.sum(v * resid**2) / jnp.maximum(jnp.sum(v * centred**2), 1e-300)

    # The main fit and the filter spread's refits (each its own Huber weights: the same weights
    # shift a2), vmapped over the filters: one copy of the fit in the compiled graph.
    stacked = jax.tree_util.tree_map(lambda *x: jnp.stack(x), *filters.values())
    designs, zs, (thetas, ws, slopes, resids) = jax.vmap(lambda d: fit(d, signals))(stacked)
    design, z, theta, weights, slope, resid = designs[0], zs[0], thetas[0], ws[0], slopes[0], resids[0]
    # What H rests on: the same weighted fit with D fixed at 0, and with the governor correction
    # fixed at 0 (a column dropped: its row and column of the normal matrix become the identity).
    normal, rhs = design.T @ (design * weights[:, None]), design.T @ (weights * z)
    a2_without = jnp.stack([_fit_without(normal, rhs, j)[1] for j in (0, 3)])
    cov, info = _sandwich(design * (weights * resid)[:, None], (design * slope[:, None]).T @ design, window)
    if s.spread_scales:
        share = jax.vmap(explained)(zs[1:], resids[1:])
        spread, spread_fits = refit_spread(theta[1], thetas[1:, 1], explained(z, resid), share)
    else:
        spread, spread_fits = jnp.zeros((), ts.dtype), jnp.zeros((), jnp.int32)
    levels = noise_levels(recording, fe.valid) if draws is None else draws.levels
    if s.noise_interval == "bootstrap":
        # Each draw's weighted fit (the fit's Huber weights), from its own normal equations.
        normal_k, rhs_k = weighted_normal_equations(draw_signals, filters[1.0], weights)
        cov = jnp.cov(jax.vmap(solve_spd)(normal_k, rhs_k), rowvar=False)
    ee = _result(theta, cov, info, plant.machine.omega_s, jnp.sum(valid), spread, spread_fits, levels,
                 jnp.array(False), s.model_error, t_ref, t_m0, a2_without)
    if not s.output_error:
        return ee
    oe = _output_error(ts, fe, t_ref, plant, settings, s, ee, valid, window, dt, levels)
    return jax.tree_util.tree_map(lambda a, b: jnp.where(oe.output_error, a, b), oe, ee)


def refit_spread(a2, a2_refits, explained, explained_refits):
    """The filter spread [-] (the largest relative change of a2 over the refits) and how many
    refits count in it.

    A refit that explains less than half of what the main fit explains (``explained``: the
    share of the filtered acceleration's variance) is no fit of the swing equation, and does
    not count: a filter band without the event (on OSL case 1 the slower filter's H is 5x off
    while it leaves as much residual as there is signal).
    """
    counts = explained_refits >= 0.5 * explained
    spread = jnp.max(jnp.where(counts, jnp.abs(a2_refits / a2 - 1.0), 0.0), initial=0.0)
    return spread, jnp.sum(counts).astype(jnp.int32)


def _fit_without(normal, rhs, j: int):
    """The weighted least-squares solution with coefficient ``j`` fixed at 0."""
    keep = jnp.arange(normal.shape[0]) != j
    mask = keep[:, None] & keep[None, :]
    return solve_spd(jnp.where(mask, normal, jnp.eye(normal.shape[0], dtype=normal.dtype)),
                     jnp.where(keep, rhs, 0.0))


def governor_input(fe: FrontEnd, plant: Plant, smoothing, lead: int):
    """The governor model's input [pu]: the measured speed deviation, held at its value at
    ``lead`` before it, low-passed forwards and backwards (zero phase) by ``smoothing``."""
    x2 = jnp.where(jnp.arange(fe.x2_meas.shape[0]) < lead, fe.x2_meas[lead], fe.x2_meas)
    x2 = filter_states(smoothing, x2)[:, 0]
    return filter_states(smoothing, x2, reverse=True)[:, 0] / plant.machine.omega_s


def _signals(fe: FrontEnd, dw, recording: Recording, plant: Plant, t_ref, dt, lead: int, quiet):
    """The unfiltered inputs of the regression: 2 pi (f - f0), delta - theta, Tm - Te, 1,
    Tm - Tm(0); and Tm(0) [pu]. theta is the bus angle less its jumps at switchings, and f
    the channel bridged across them (``FrontEnd.theta_smooth``): the pair's Remark-2 sum would
    otherwise carry the channel's spike there. The governor model, driven by ``dw`` (:func:`governor_input`),
    starts at :func:`governor_start` over the recording's ``quiet`` samples after ``lead``.

    Without a frequency channel, f would be the smoothed derivative of theta: then the bus
    term is 0 and the rotor term is delta itself (x2 = d delta/dt, differentiated exactly by
    the filter; the smoothing would bias H by ~2 %).

    The samples before ``lead`` (the derivative's half width: there x2 and a derived f are
    one-sided differences) are held at their value at ``lead``, so that the filters and the
    governor model start there, as the windowed fit's do at its first own sample. On
    NASPI OSL case 1, before the readers masked its 4 stale opening frames (every |V| steps by
    2 % at 0.133 s), the governor started from the edge's speed (-0.065 rad/s, 13 times the
    noise) and the filters from the stale Te (0.018 pu off): a slow HYGOV transient that the
    governor correction took (-45 %), and H of 4031_malin 5.6 % below the windowed fit's.
    """
    def held(x):
        return jnp.where(jnp.arange(x.shape[0]) < lead, x[lead], x)

    lead_ = min(lead, dw.shape[0] - 2)
    x0 = governor_start(plant.governor, fe, dw, dt, t_ref, lead_, quiet=quiet)
    t_m = held(jnp.pad(governor_torque(plant.governor, dw[lead_:], dt, t_ref, x0), (lead_, 0)))
    derived = True if recording.f_hz is None else jnp.all(jnp.isnan(recording.f_hz) | ~fe.valid)
    bus = jnp.where(derived, 0.0, 2.0 * jnp.pi * (held(fe.f_hz) - plant.machine.f_nominal_hz))
    rotor = held(jnp.where(derived, fe.alg.delta_rad, fe.alg.delta_rad - fe.theta_smooth))
    one = jnp.ones_like(bus)
    return jnp.stack([bus, rotor, t_m - held(fe.alg.t_e_pu), one, t_m - t_m[0]]), t_m[0]


def _regression(signals, discretisation):
    """(design matrix [T, 4], left-hand side z [T]) of the swing equation filtered by the
    3rd-order filter of ``discretisation`` (:func:`~jaxdse._core.lti.hold_discretisation` of
    its :func:`~jaxdse._core.lti.lag_chain`)."""
    states = jax.vmap(lambda u: filter_states(discretisation, u))(signals)  # [5, T, 3]
    row, z = _design_row(lambda signal, order: states[signal][:, order])
    return jnp.stack(row, axis=1), z


def _design_row(state):
    """The regressors [-F x2, F (Tm - Te), F 1, F (Tm - Tm(0))] and the left-hand side F s x2
    from ``state(signal, order)``, the filtered ``signal`` (0-4: bus, rotor, torque, one, gov;
    see :func:`_signals`) differentiated ``order`` times.

    x2 = 2 pi (f - f0) + d(delta - theta)/dt (Remark 2): the derivatives are the filter's own
    (exact), not the smoothed ones of the front end, which attenuate a 1.5 Hz swing by ~9 %.
    """
    fx2 = state(0, 0) + state(1, 1)
    return [-fx2, state(2, 0), state(3, 0), state(4, 0)], state(0, 1) + state(1, 2)


def weighted_normal_equations(signals, discretisation, weights):
    """The weighted normal equations (X^T W X [D, 4, 4], X^T W z [D, 4]) of the regression of
    :func:`_regression` for ``D`` sets of its inputs (``signals``: [D, 5, T]) at once.

    The same filtering and products as ``_regression`` followed by ``X.T @ (X * w)``, fused
    into one loop over the samples that carries the filters' states and the sums: no filtered
    state is stored (the bootstrap's draws would otherwise write and read 15 filtered states
    per sample and draw), and the draws are the innermost axis of every operation.
    """
    phi, g0, g1 = discretisation
    n = phi.shape[0]
    u = jnp.moveaxis(signals, 0, -1)  # [5, T, D]
    x0 = [u[:, 0]] + [jnp.zeros_like(u[:, 0])] * (n - 1)  # filter state j: [5 signals, D]

    def add(sums, x, w):
        a, r = sums
        row, z = _design_row(lambda signal, order: x[order][signal])
        return ([[a[i][j] + w * row[i] * row[j] for j in range(4)] for i in range(4)],
                [r[i] + w * row[i] * z for i in range(4)])

    def step(carry, v):
        x, sums = carry
        u0, u1, w = v
        x = [sum(phi[i, j] * x[j] for j in range(n)) + g0[i] * u0 + g1[i] * u1 for i in range(n)]
        return (x, add(sums, x, w)), None

    zero = jnp.zeros(u.shape[-1], u.dtype)
    sums = add(([[zero] * 4 for _ in range(4)], [zero] * 4), x0, weights[0])
    (_, (a, r)), _ = jax.lax.scan(step, (x0, sums), (jnp.moveaxis(u[:, :-1], 1, 0),
                                                    jnp.moveaxis(u[:, 1:], 1, 0), weights[1:]))
    return (jnp.moveaxis(jnp.stack([jnp.stack(row) for row in a]), -1, 0),
            jnp.moveaxis(jnp.stack(r), -1, 0))


def _output_error(ts, fe: FrontEnd, t_ref, plant: Plant, settings: Settings, s: IdentifySettings,
                  start: Identified, valid, window, dt, levels) -> Identified:
    """Levenberg-Marquardt on the playback residual over p = (a1, ln(a2/a2_0), offset, gain)."""
    w_s = plant.machine.omega_s
    integ = settings.playback_integrator
    if integ.adaptive:  # forward-mode Jacobians through diffrax
        integ = dataclasses.replace(integ, forward_mode=True)
    inputs, y0, measured = playback_inputs(fe, None, fe.alg.delta_rad[0], t_ref, plant,
                                           dataclasses.replace(settings, external_tm=False), dt)
    meas = jnp.stack(measured)
    sigma = jax.vmap(lambda m: _noise_level(m, valid))(meas)
    usable = start.ok & (start.a2 > 0)
    a2_0 = jnp.where(usable, start.a2, inertia_from_a2(5.0, w_s))  # H = 5 s where EE failed
    p0 = jnp.where(usable, jnp.stack([start.a1, 0.0, start.t_m_offset_pu, start.governor_gain_error]),
                   jnp.zeros(4))

    def residual(p, _):
        pl = scaled_governor(plant, t_ref, start.t_m0_pu, p[3], p[2])
        pb = playback(ts, inputs, y0, p[0], a2_0 * jnp.exp(p[1]), pl.machine, integ, pl.governor,
                      t_ref, measured=measured, n_valid=fe.n, block=settings.block_samples,
                      save_trajectory=True)
        tr = pb.trajectory
        sim = jnp.stack([tr.x2_rad_s, tr.i_t_pu, tr.p_t_pu, tr.q_t_pu])
        r = (sim - meas) / sigma[:, None]
        # A diverged playback must look bad, not absent: non-finite residuals count as large.
        return jnp.where(valid, jnp.where(jnp.isfinite(r), r, 1e6), 0.0)

    solver = optx.LevenbergMarquardt(rtol=1e-5, atol=1e-8)
    sol = optx.least_squares(residual, solver, p0, max_steps=s.output_error_steps, throw=False)
    p = sol.value
    r = residual(p, None)
    jac = jax.jacfwd(residual)(p, None)  # [4 outputs, T, 4 parameters]
    a2 = a2_0 * jnp.exp(p[1])
    # p -> theta = (a1, a2, c = a2 offset, g = a2 gain): the covariance by the delta method.
    to_theta = jnp.array([[1.0, 0.0, 0.0, 0.0], [0.0, a2, 0.0, 0.0],
                          [0.0, a2 * p[2], a2, 0.0], [0.0, a2 * p[3], 0.0, a2]])
    cov_p, info = _sandwich(jnp.einsum("otp,ot->tp", jac, r), jnp.einsum("otp,otq->pq", jac, jac), window)
    theta = jnp.stack([p[0], a2, a2 * p[2], a2 * p[3]])
    converged = (sol.result == optx.RESULTS.successful) & usable
    # The alternatives stay the equation error's (H = ws / 2 a2 is its own inverse map).
    h_without = jnp.stack([start.h_without_damping_s, start.h_without_governor_correction_s])
    a2_without = inertia_from_a2(h_without, w_s)
    return _result(theta, to_theta @ cov_p @ to_theta.T, info, w_s, jnp.sum(valid), start.filter_spread,
                   start.filter_spread_fits, levels,
                   converged, s.model_error, t_ref, start.t_m0_pu, a2_without)


def noise_levels(recording: Recording, valid) -> Array:
    """White-noise standard deviations of a recording's channels (see ``Identified.noise_levels``):
    the MAD of the second differences / sqrt 6, which a smooth signal barely touches."""
    def level(x):
        d2 = x[2:] - 2.0 * x[1:-1] + x[:-2]
        ok = valid[2:] & jnp.isfinite(d2)
        med = masked_median(d2, ok)
        return jnp.where(jnp.any(ok), 1.4826 * masked_median(jnp.abs(d2 - med), ok) / jnp.sqrt(6.0),
                         jnp.nan)

    f = recording.f_hz if recording.f_hz is not None else jnp.full_like(recording.t_s, jnp.nan)
    return jax.vmap(level)(jnp.stack([jnp.log(recording.v_mag_pu), recording.v_ang_rad,
                                      jnp.log(recording.i_mag_pu), recording.i_ang_rad, f]))


def add_noise(recording: Recording, levels, e) -> Recording:
    """``recording`` with white noise ``levels`` * ``e`` added once more (``e``: [5, T], standard
    normal for a bootstrap draw; the channels as ``Identified.noise_levels``)."""
    lv = jnp.where(jnp.isfinite(levels), levels, 0.0)
    fields = [recording.v_mag_pu * jnp.exp(lv[0] * e[0]), recording.v_ang_rad + lv[1] * e[1],
              recording.i_mag_pu * jnp.exp(lv[2] * e[2]), recording.i_ang_rad + lv[3] * e[3]]
    out = eqx.tree_at(lambda r: (r.v_mag_pu, r.v_ang_rad, r.i_mag_pu, r.i_ang_rad), recording, tuple(fields))
    if recording.f_hz is not None:
        out = eqx.tree_at(lambda r: r.f_hz, out, recording.f_hz + lv[4] * e[4])
    return out


def _noise_level(x, valid):
    """Robust standard deviation of white noise on ``x``: the MAD of its first differences / sqrt 2."""
    d = jnp.diff(x, prepend=x[:1])
    ok = valid & jnp.roll(valid, 1)
    med = masked_median(d, ok)
    return jnp.maximum(1.4826 * masked_median(jnp.abs(d - med), ok) / jnp.sqrt(2.0), 1e-12)


START_JUMP_RATIO, START_JUMP_FACTOR = 4.0, 10.0
"""A jump of the terminal voltage or power phasor between two samples (:func:`jumps`) this many
times larger than the smooth curvature around it and than the median second difference (the
.dyr playback's switching-step criterion) ends the stretch that starts the governor model
(:func:`governor_start`)."""
START_BASE_S, START_MEAN_S = 2.0, 1.0
"""So does a departure of the speed's trailing ``START_MEAN_S`` mean from the mean of the
stretch's first ``START_BASE_S`` [s] ..."""
START_SIGMAS, START_DEPARTURE_PU = 6.0, 1e-4
"""... by more than ``START_SIGMAS`` standard errors of the noise, ``START_SIGMAS`` standard
deviations of the trailing means within the base, and ``START_DEPARTURE_PU`` [pu] of speed
(6 mHz at 60 Hz). On the ANDES bench an event moves the speed by 6e-4 to 4e-3 pu within a
second, while on NASPI OSL case 1 the ambient speed stays within 4.3e-5 pu of its first 2 s
over 30 s, and on ANDES's 10 min ambient recordings departs by 1e-4 after 13 s."""


def _quiet_samples(fe: FrontEnd, dw, dt, start: int, samples):
    """Samples from ``start`` to the first switching event (:data:`START_JUMP_RATIO`) or speed
    departure (:data:`START_SIGMAS`), at most ``samples`` and at least 1."""
    n = dw.shape[0] - start
    j = jnp.arange(n)
    hit = jumps(fe.v_t[start:], START_JUMP_RATIO, START_JUMP_FACTOR) \
        | jumps(fe.v_t[start:] * jnp.conj(fe.i_t[start:]), START_JUMP_RATIO, START_JUMP_FACTOR)
    quiet = jnp.min(jnp.where(hit, j[:-1] + 1, n))
    x = dw[start:]
    n0 = jnp.clip(jnp.round(START_BASE_S / dt), 1.0, n)
    m = jnp.clip(jnp.round(START_MEAN_S / dt), 1.0, n0)
    base = jnp.sum(jnp.where(j < n0, x, 0.0)) / n0
    cum = jnp.concatenate([jnp.zeros(1, x.dtype), jnp.cumsum(x - base)])
    lag = jnp.maximum(j + 1 - m, 0).astype(int)
    mean = (cum[j + 1] - cum[lag]) / (j + 1 - lag)                  # trailing, up to m samples
    inside = (j >= m - 1) & (j < n0)
    spread = jnp.sqrt(jnp.sum(jnp.where(inside, mean**2, 0.0)) / jnp.maximum(jnp.sum(inside), 1))
    noise = 1.4826 * jnp.median(jnp.abs(jnp.diff(x, 2))) / jnp.sqrt(6.0)
    tol = jnp.maximum(START_SIGMAS * jnp.maximum(noise * jnp.sqrt(1.0 / m + 1.0 / n0), spread),
                      START_DEPARTURE_PU)
    off = (jnp.abs(mean) > tol) & (j >= n0)
    quiet = jnp.minimum(quiet, jnp.min(jnp.where(off, j - m + 1, n)))
    return jnp.maximum(jnp.minimum(quiet, samples), 1)


def _heun(gov: AbstractGovernor, dt, t_ref):
    """One Heun step of the governor over a sample interval, inputs (dw at its start, at its end)."""
    def step(x, d):
        d0, d1 = d
        k1 = gov.vector_field(x, d0, t_ref)
        k2 = gov.vector_field(x + dt * k1, d1, t_ref)
        return x + 0.5 * dt * (k1 + k2)
    return step


def governor_start(gov: AbstractGovernor, fe: FrontEnd, dw, dt, t_ref, start: int, samples=None,
                   quiet=None):
    """The governor model's state at sample ``start``: its equilibrium for the mean speed of the
    quiet stretch that follows (up to the first event, :func:`_quiet_samples`; at most
    ``samples``, T_ref's quasi-steady window; or ``quiet`` samples, where already known).

    Not the equilibrium of the first sample's speed: the governor's state carries the speed's
    past, which ambient wander and oscillations leave near their mean, while one sample sits off
    it. On NASPI OSL case 1 (a forced oscillation over ambient load noise, no event), the
    governor of 3933_tesla started from a sample 1.5 mHz off the mean; Tm crept by 3.7e-4 pu over
    the record, the governor correction took it (-55 to -79 %), and H came out 3.51-3.55 or 3.67 s
    depending on the sample the fit started at. Before an event a constant speed gives the
    equilibrium of that speed (noise-free truth is kept). (Driving the governor over the stretch
    backwards in time, to weigh the speed by the governor's own memory, gave the same H on
    OSL case 1 but doubles the phase error under an oscillation.)
    """
    if quiet is None:
        quiet = _quiet_samples(fe, dw, dt, start, samples)
    use = fe.valid[start:] & (jnp.arange(dw.shape[0] - start) < quiet)
    mean = jnp.sum(jnp.where(use, dw[start:], 0.0)) / jnp.maximum(jnp.sum(use), 1)
    return gov.steady_state(t_ref, mean)


def governor_torque(gov: AbstractGovernor, dw, dt, t_ref, x0=None):
    """Tm [pu] of the governor model driven by ``dw`` [pu], from the state ``x0`` (default: the
    equilibrium for ``dw[0]``; :func:`governor_start`) (Heun steps, one per sample; the
    governors are slow next to a PMU's frame rate)."""
    step = _heun(gov, dt, t_ref)

    def scan_step(x, d):
        x = step(x, d)
        return x, gov.torque(x, d[1])

    x0 = gov.steady_state(t_ref, dw[0]) if x0 is None else x0
    _, tm = jax.lax.scan(scan_step, x0, (dw[:-1], dw[1:]))
    return jnp.concatenate([gov.torque(x0, dw[0])[None], tm])


SCALE_UPDATES = 3
"""Reweighting steps of the Huber fit that re-estimate the residual's scale (MAD); the later
steps keep the last one (the scale settles in ~2 steps; each estimate costs two medians)."""


def _huber(x, y, valid, iterations, k):
    """Huber regression by iteratively reweighted least squares (scale: MAD of the residual,
    re-estimated in the first ``SCALE_UPDATES`` steps, then held).

    Returns (theta, psi(r) / r, psi'(r), r) at the solution: the weights of the sandwich's
    scores and of its information matrix (with the IRLS weights in the information matrix
    instead of psi', the downweighted samples would still count as information, and the
    interval would come out too narrow).
    """
    def solve(w):
        w = jnp.where(valid, w, 0.0)
        return solve_spd(x.T @ (x * w[:, None]), x.T @ (w * y))

    def scale(r):
        med = masked_median(r, valid)
        return 1.4826 * masked_median(jnp.abs(r - med), valid)

    def weights(r, sigma):
        u = jnp.abs(r) / (k * jnp.maximum(sigma, 1e-300))
        return jnp.where(u <= 1.0, 1.0, 1.0 / u), u <= 1.0

    def update(w, _):  # a step that re-estimates the scale
        r = y - x @ solve(w)
        sigma = scale(r)
        return weights(r, sigma)[0], sigma

    w, sigmas = jax.lax.scan(update, jnp.ones_like(y), None, length=min(iterations, SCALE_UPDATES))
    sigma = sigmas[-1] if iterations else jnp.ones((), y.dtype)
    w, _ = jax.lax.scan(lambda w, _: (weights(y - x @ solve(w), sigma)[0], None), w, None,
                        length=max(iterations - SCALE_UPDATES, 0))
    theta = solve(w)
    r = y - x @ theta
    w, inside = weights(r, sigma)
    if iterations == 0:  # ordinary least squares
        w, inside = jnp.ones_like(y), jnp.ones_like(y, dtype=bool)
    return theta, jnp.where(valid, w, 0.0), jnp.where(valid & inside, 1.0, 0.0), r


PIVOT_FLOOR = 1e-14
"""Smallest pivot of the unit-diagonal Cholesky factorisation [-]: a direction of the
information matrix below it (a condition number above ~1e14) gets a variance of ~1e14 times
its scale instead of a division by zero, so that its interval comes out unbounded, not NaN."""


def solve_spd(a, b):
    """a^-1 b for a small symmetric positive (semi-)definite ``a`` [p, p] (b: [p] or [p, k]):
    scaled to unit diagonal, then an unrolled Cholesky factorisation and two triangular
    solves. No LAPACK call, so it batches cleanly under vmap (p = 4 here). In float64 it keeps
    about 8 digits at a condition number of 1e8; data worse than that cannot identify H."""
    p = a.shape[0]
    d = jnp.sqrt(jnp.maximum(jnp.diag(a), 1e-300))
    a = a / jnp.outer(d, d)
    rhs = b / (d[:, None] if b.ndim == 2 else d)
    low = [[None] * p for _ in range(p)]
    for j in range(p):
        pivot = a[j, j] - sum((low[j][k] ** 2 for k in range(j)), 0.0)
        low[j][j] = jnp.sqrt(jnp.maximum(pivot, PIVOT_FLOOR))
        for i in range(j + 1, p):
            low[i][j] = (a[i, j] - sum((low[i][k] * low[j][k] for k in range(j)), 0.0)) / low[j][j]
    z = [None] * p
    for i in range(p):
        z[i] = (rhs[i] - sum((low[i][k] * z[k] for k in range(i)), 0.0)) / low[i][i]
    out = [None] * p
    for i in reversed(range(p)):
        out[i] = (z[i] - sum((low[k][i] * out[k] for k in range(i + 1, p)), 0.0)) / low[i][i]
    out = jnp.stack(out)
    return out / (d[:, None] if b.ndim == 2 else d)


MEDIAN_BISECTIONS = 52
"""Halvings of the data's range in :func:`masked_median` (2^-52: float64's resolution)."""


def masked_median(x, mask):
    """Median of ``x[mask]`` with a static shape (NaN when nothing is masked in).

    By bisection on the value, not by sorting: each step counts the samples below the
    midpoint of the two middle order statistics' brackets, and the last step takes the
    largest sample within each bracket, so the result is exact (sorting a recording costs
    ~10x more on CPU, and the Huber fit takes two medians per reweighting step)."""
    n = jnp.sum(mask)
    ranks = jnp.stack([(n - 1) // 2, n // 2]) + 1  # the two middle order statistics, 1-based
    lo0 = jnp.min(jnp.where(mask, x, jnp.inf))
    hi0 = jnp.max(jnp.where(mask, x, -jnp.inf))
    init = (jnp.full(2, lo0), jnp.full(2, hi0))

    def halve(_, bracket):
        lo, hi = bracket  # invariant: count(x <= hi) >= rank; count(x <= lo) < rank unless lo = min
        mid = 0.5 * (lo + hi)
        count = jnp.sum(mask[None, :] & (x[None, :] <= mid[:, None]), axis=1)
        above = count >= ranks
        return jnp.where(above, lo, mid), jnp.where(above, mid, hi)

    _, hi = jax.lax.fori_loop(0, MEDIAN_BISECTIONS, halve, init)
    stats = jnp.max(jnp.where(mask[None, :] & (x[None, :] <= hi[:, None]), x[None, :], -jnp.inf), axis=1)
    return jnp.where(n > 0, 0.5 * (stats[0] + stats[1]), jnp.nan)


def _sandwich(scores, info, window):
    """Newey-West sandwich covariance from the per-sample scores [T, p] and the information
    matrix [p, p] of a (weighted, linearised) least-squares fit, Bartlett kernel.

    sum_|l|<=L (1 - |l|/(L+1)) Gamma(l) is computed as the mean outer product of the sums of the
    scores over sliding blocks of L+1 samples (cumulative sums: O(n p^2), any L, even traced).
    """
    g = scores
    csum = jnp.concatenate([jnp.zeros_like(g[:1]), jnp.cumsum(g, axis=0)])
    n = g.shape[0]
    start = jnp.arange(-n, n)  # blocks before the record are empty: no contribution
    blocks = csum[jnp.clip(start + window + 1, 0, n)] - csum[jnp.clip(start, 0, n)]
    meat = blocks.T @ blocks / (window + 1.0)
    bread = solve_spd(info, jnp.eye(info.shape[0], dtype=info.dtype))
    return bread @ meat @ bread, info


def _result(theta, cov, info, w_s, samples, spread, spread_fits, levels, output_error, model_error,
            t_ref, t_m0, a2_without) -> Identified:
    a1, a2, c, g = theta[0], theta[1], theta[2], theta[3]
    se = jnp.sqrt(jnp.maximum(jnp.diag(cov), 0.0))
    # The spread is one draw of how a2 depends on the filter (a standard deviation, not a bound):
    # its 95 % part is Z95 times it.
    half = jnp.sqrt((Z95 * se[1]) ** 2 + ((Z95 * spread) ** 2 + model_error**2) * a2**2)
    lo2, hi2 = a2 - half, a2 + half
    h_lo = inertia_from_a2(hi2, w_s)
    h_hi = jnp.where(lo2 > 0, inertia_from_a2(jnp.maximum(lo2, 1e-300), w_s), jnp.inf)
    # D = a1 / a2: gradient (1/a2, -a1/a2^2) on the (a1, a2) block.
    grad = jnp.stack([1.0 / a2, -a1 / a2**2])
    se_d = jnp.sqrt(jnp.maximum(grad @ cov[:2, :2] @ grad, 0.0))
    d = damping_from_a(a1, a2)
    diag = jnp.sqrt(jnp.maximum(jnp.diag(info), 1e-300))
    scaled = info / jnp.outer(diag, diag)
    # Variance inflation of a2: its variance against the one it would have were the other
    # regressors orthogonal to it (the (2, 2) element of the inverse of the scaled information).
    vif = solve_spd(scaled, jnp.eye(4, dtype=scaled.dtype))[1, 1]
    h_without = inertia_from_a2(a2_without, w_s)
    values = (a1, a2, inertia_from_a2(a2, w_s), d, se[0], se[1], c / a2, g / a2, spread)
    ok = jnp.all(jnp.isfinite(jnp.stack(values))) & jnp.all(jnp.isfinite(cov))
    return Identified(
        a1=a1, a2=a2, h_s=inertia_from_a2(a2, w_s), d_pu_s=d,
        h_ci95=jnp.stack([h_lo, h_hi]), d_ci95=jnp.stack([d - Z95 * se_d, d + Z95 * se_d]),
        se_a1=se[0], se_a2=se[1], covariance=cov, t_m_offset_pu=c / a2,
        governor_gain_error=g / a2, relative_ci=half / jnp.abs(a2),
        relative_ci_noise=Z95 * se[1] / jnp.abs(a2), filter_spread=spread, filter_spread_fits=spread_fits,
        information=scaled, t_ref_pu=t_ref, t_m0_pu=t_m0, h_variance_inflation=vif,
        h_without_damping_s=h_without[0], h_without_governor_correction_s=h_without[1],
        noise_levels=levels, samples=samples, ok=ok, output_error=output_error,
    )


def condition_number(information) -> float:
    """Condition number of an :attr:`Identified.information` matrix (host side, NumPy)."""
    m = np.asarray(information, dtype=float)
    if not np.all(np.isfinite(m)):        # a failed solve: eigvalsh would raise LinAlgError
        return float("nan")
    try:
        eig = np.linalg.eigvalsh(m)
    except np.linalg.LinAlgError:
        return float("nan")
    return float(eig[-1] / max(eig[0], 1e-300)) if np.all(np.isfinite(eig)) else float("nan")
