"""Sensitivities, identifiability ranking and bounded calibration of a unit's .dyr parameters.

One residual function serves all three: the playback's P and Q against the measured ones, on
one or several events of the unit (vmapped, shared parameters), each channel divided by its
noise level. Then

* forward-mode autodiff gives the Jacobian J in the calibration coordinates, and the
  normalised sensitivities ``theta_j dy/dtheta_j`` [pu];
* the Fisher information F = J^T J ranks the parameters: eigenvectors, each parameter's
  variance inflation ``F_jj (F^-1)_jj`` and its Cramer-Rao 95 % half-width; a parameter whose
  half-width exceeds ``max_relative_ci`` cannot be identified from these events and is left at
  its .dyr value;
* optimistix's Levenberg-Marquardt fits the identifiable ones within the engineer's bounds, in
  log-logistic coordinates (positive parameters) or logistic ones (signed, e.g. D);
* the 95 % intervals come from the Gauss-Newton covariance at the solution, the sum of three
  parts (``A = J^T J``), and a model error:

  - the residuals': a sandwich ``A^-1 S A^-1``, ``S`` the long-run covariance of the scores
    ``J_t^T r_t`` (Bartlett weights, bandwidth from the residuals' lag-1 autocorrelation,
    Andrews 1991);
  - the imposed voltage's: its noise, estimated from the data, drawn ``input_draws`` times
    and played through the fitted model, each draw's residual change projected by one
    Gauss-Newton step. Noise on the imposed input moves the simulated P and Q as well as the
    measured ones (errors in variables); the residuals at the solution cannot show it;
  - the events' disagreement: a sandwich with the events as clusters (each event's score
    ``J_e^T r_e``; they sum to 0 at the solution), ``E/(E-1) A^-1 sum_e s_e s_e^T A^-1``: a
    model error that pulls each event's fit its own way.

  Measured on the ANDES bench (3 units, 9 noisy fits, 42 intervals): the residuals' part
  alone covered 45 %, with the voltage's 76 %, with all three 90 %. A model error
  (``model_error``, relative to the value) is added in quadrature to every half-width.

The eigen-decompositions and inverses of the small (p x p) matrices run on the host (NumPy).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .playback import PlaybackSettings, TerminalSeries, play_back, voltage_steps
from .unit import DyrUnit

Z95 = 1.959963984540054


@dataclasses.dataclass(frozen=True)
class ParameterSpec:
    """One calibratable parameter of a unit: where it sits and its bounds."""

    part: str
    """"machine", "exciter", "stabiliser" or "governor" of a :class:`~jaxdse._dyr.unit.DyrUnit`;
    "electrical" or "plant" (or another of ``IbrUnit.PARTS``) of an inverter-based plant's
    :class:`~jaxdse._dyr.ibr_unit.IbrUnit`."""
    field: str
    """Field of that module (e.g. ``h_s``)."""
    label: str
    """PSS/E name (e.g. ``H``), for tables and the calibrated .dyr."""
    lower: float
    upper: float
    positive: bool = True
    """Log-logistic coordinates (True) or logistic ones (a parameter that may be <= 0)."""

    def value(self, unit: DyrUnit):
        return getattr(getattr(unit, self.part), self.field)


@dataclasses.dataclass(frozen=True)
class CalibrationSettings:
    """How identifiability is judged and the fit is run."""

    max_relative_ci: float = 0.05
    """A parameter is identifiable when its Cramer-Rao 95 % half-width is below this fraction
    of its value (of its bound width for a parameter at 0). The bound is for noise alone; a
    model's error adds to it, so half of the 10 % that a calibrated value should be within
    (on the ANDES bench, parameters at +-7-10 % came back 10-13 % off, noise-free)."""
    noise_floor_pu: float = 1e-3
    """Lower bound of the noise level of P and Q [pu of MBASE] used for the ranking: a PMU's
    P and Q are not better than about 0.1 % (C37.118 TVE), whatever the data's smoothness."""
    rtol: float = 1e-6
    """Levenberg-Marquardt stops when both the step in the transformed coordinates (about the
    relative change of each parameter) and the change of the residuals are below
    ``atol + rtol |.|``. 1e-6 is four orders below the narrowest interval; tighter tolerances
    only add rejected steps at the loss's round-off (measured: 24 steps against 13)."""
    atol: float = 1e-6
    max_steps: int = 64
    input_draws: int = 32
    """Draws of the imposed voltage's noise for the input part of the intervals (0 or 1: none)."""
    model_error: float = 0.01
    """Relative error [-] that the playback of .dyr records carries against another simulator
    whatever the data, added in quadrature to the 95 % half-width of each parameter, relative to
    its value (a signed one too: a plant controller's droop Ddn = 20 is as uncertain as a gain;
    at D = 0 it adds nothing). 0.01: on the ANDES bench, noise-free
    calibrations put H within 0.63 % of the truth, and with noise the statistical intervals
    alone covered H in 78 % of 50 draws (all parameters 89.5 %); chosen on that bench."""
    seed: int = 0
    """Seed of those draws."""


class Events(NamedTuple):
    """Several recordings of one unit, stacked (same length; ``weight`` 0 on padding)."""

    series: TerminalSeries
    p_pu: jax.Array
    """Measured P [pu of MBASE], [E, T]."""
    q_pu: jax.Array
    """Measured Q [pu of MBASE], [E, T]."""
    weight: jax.Array
    """1 on valid frames, 0 on padding and on frames left out, [E, T]."""


def measured_pq(series: TerminalSeries):
    """P and Q out of the terminal from the series' V and I [pu]."""
    vr = series.v_mag_pu * jnp.cos(series.v_ang_rad)
    vi = series.v_mag_pu * jnp.sin(series.v_ang_rad)
    return vr * series.i_re_pu + vi * series.i_im_pu, vi * series.i_re_pu - vr * series.i_im_pu


STEP_FRAMES = 3
"""Frames after a switching step left out of the fit: inside one frame interval the machine's
fast (subtransient) response to a step is invisible to a playback from frames, so the first
frames after it carry an error that no parameter value explains (and that would pull H)."""


def stack_events(series_list, weights=None, step_frames: int = STEP_FRAMES) -> Events:
    """Stack terminal series of equal length into :class:`Events`; the ``step_frames`` frames
    after each voltage step (:func:`~jaxdse._dyr.playback.voltage_steps`) get weight 0."""
    series = jax.tree.map(lambda *x: jnp.stack(x), *series_list)
    p, q = jax.vmap(measured_pq)(series)
    w = jnp.ones_like(p) if weights is None else jnp.asarray(weights, dtype=p.dtype)
    if step_frames > 0:
        steps = jax.vmap(lambda s: voltage_steps(s, PlaybackSettings()))(series)
        after = jnp.pad(steps, ((0, 0), (1, 0)))            # frame k+1 follows interval k
        hit = jnp.zeros_like(after)
        for k in range(step_frames):
            hit = hit | jnp.pad(after, ((0, 0), (k, 0)))[:, :after.shape[1]]
        w = jnp.where(hit, 0.0, w)
    return Events(series, p, q, w)


def _white_sd(y, keep=None) -> float:
    """Robust standard deviation of the white noise on ``y`` [..., T]: 1.4826 MAD of its second
    differences / sqrt(6) (a smooth signal's second differences are ~0); ``keep`` selects the
    second differences counted (flattened). 0 when none is left."""
    d2 = np.diff(np.asarray(y), 2, axis=-1).ravel()
    d2 = d2 if keep is None else d2[keep]
    return 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0) if d2.size else 0.0


def noise_level(events: Events, floor: float) -> np.ndarray:
    """(sigma_P, sigma_Q) [pu]: :func:`_white_sd` of P and Q, floored."""
    return np.asarray([max(_white_sd(y), floor) for y in (events.p_pu, events.q_pu)])


def voltage_noise(events: Events) -> np.ndarray:
    """(sd of ln|V| [-], sd of the voltage angle [rad]) per frame: :func:`_white_sd` over the
    weighted (valid) frames."""
    w = np.asarray(events.weight) > 0
    inside = (w[..., 2:] & w[..., 1:-1] & w[..., :-2]).ravel()
    return np.asarray([_white_sd(np.log(np.asarray(events.series.v_mag_pu)), inside),
                       _white_sd(events.series.v_ang_rad, inside)])


def long_run_covariance(scores: np.ndarray, lag1: float, frames: float) -> tuple[np.ndarray, int]:
    """(S, bandwidth): the long-run covariance of per-frame scores [E, T, p] summed over events,
    with Bartlett weights up to the bandwidth that Andrews (1991) gives for an AR(1) of lag-1
    autocorrelation ``lag1`` over ``frames`` frames."""
    alpha = 4 * lag1**2 / ((1 - lag1) ** 2 * (1 + lag1) ** 2)
    n_t = scores.shape[1]
    bandwidth = int(min(n_t - 1, np.ceil(1.1447 * (alpha * frames) ** (1 / 3))))
    s = np.einsum("etp,etq->pq", scores, scores)
    for lag in range(1, bandwidth + 1):
        g = np.einsum("etp,etq->pq", scores[:, lag:], scores[:, :-lag])
        s += (1 - lag / (bandwidth + 1)) * (g + g.T)
    return s, bandwidth


# --- coordinates -----------------------------------------------------------------------------

AT_BOUND = 1e-6
"""A fitted value within this fraction of its bounds' span (in the fit's coordinates) of a bound
sits on it."""


def _unit_position(x, spec: ParameterSpec) -> float:
    """Where ``x`` lies between the bounds, 0 to 1 (log scale for a positive parameter)."""
    if spec.positive:
        lo, hi = np.log(spec.lower), np.log(spec.upper)
        return float((np.log(x) - lo) / (hi - lo))
    return float((x - spec.lower) / (spec.upper - spec.lower))


def _to_z(x, spec: ParameterSpec):
    u = np.clip(_unit_position(x, spec), 1e-9, 1 - 1e-9)
    return float(np.log(u) - np.log1p(-u))


def _from_z(z, positive: bool, lower, upper):
    """The parameter at coordinate ``z`` between ``lower`` and ``upper`` (traced: a unit's bounds
    are its own values' multiples, and other units of its model chain share the program)."""
    u = jax.nn.sigmoid(z)
    if positive:
        lo, hi = jnp.log(lower), jnp.log(upper)
        return jnp.exp(lo + (hi - lo) * u)
    return lower + (upper - lower) * u


def _traced(specs) -> tuple:
    """``specs`` as the compiled programs see them: where each parameter sits, not its bounds
    (those are passed as arrays), so that the units of one model chain share every program."""
    return tuple(dataclasses.replace(s, lower=0.0, upper=0.0) for s in specs)


def _bounds(specs):
    """(lower, upper) of ``specs`` as arrays."""
    return (jnp.asarray([s.lower for s in specs], dtype=float),
            jnp.asarray([s.upper for s in specs], dtype=float))


def with_values(unit: DyrUnit, specs, values) -> DyrUnit:
    """``unit`` with the parameters of ``specs`` set to ``values``."""
    def where(u):
        return [getattr(getattr(u, s.part), s.field) for s in specs]
    return eqx.tree_at(where, unit, [jnp.asarray(v, dtype=float) for v in values])


def _scale(spec: ParameterSpec, x0: float) -> float:
    """What a relative change means for a parameter: its value, or its bound width at 0 (or
    within ``AT_BOUND`` of the span from 0: the fit's value of a parameter pressed onto a bound at
    0 is ~1e-9 of the span, and relative to it the interval would vanish)."""
    span = spec.upper - spec.lower
    return abs(x0) if abs(x0) > AT_BOUND * span else span


# --- residuals -------------------------------------------------------------------------------

def residuals(values, unit: DyrUnit, specs, events: Events, sigma, settings: PlaybackSettings):
    """Weighted playback residuals, flattened: [(P_sim - P)/sigma_P, (Q_sim - Q)/sigma_Q] per
    event and frame (padding weighted 0). Non-finite playbacks give a large finite residual."""
    u = with_values(unit, specs, values)

    def one(series, p, q, w):
        r = play_back(u, series, settings)
        rp = (r.p_pu - p) / sigma[0]
        rq = (r.q_pu - q) / sigma[1]
        out = jnp.concatenate([w * rp, w * rq])
        return jnp.where(jnp.isfinite(out), out, 1e3)

    return jax.vmap(one)(events.series, events.p_pu, events.q_pu, events.weight).ravel()


# --- ranking ---------------------------------------------------------------------------------

class Ranking(NamedTuple):
    """Identifiability of each parameter from the given events (host arrays)."""

    labels: list
    sensitivity: np.ndarray
    """RMS over frames of the normalised sensitivities of P and Q, ``x_j dP/dx_j`` [pu], [p, 2]."""
    relative_ci: np.ndarray
    """Cramer-Rao 95 % half-width / scale of each parameter [-]."""
    variance_inflation: np.ndarray
    """F_jj (F^-1)_jj [-]: how much the other parameters blur this one."""
    eigenvalues: np.ndarray
    eigenvectors: np.ndarray
    """Columns: directions in normalised parameter space, largest eigenvalue first."""
    identifiable: np.ndarray
    reasons: list
    """One sentence per parameter that the events cannot identify (empty string otherwise)."""


@eqx.filter_jit
def _residual_jacobian(t, x0, scale, unit, specs, events, sigma, settings):
    def f(t):
        return residuals(x0 + t * scale, unit, specs, events, sigma, settings)
    return f(t), jax.jacfwd(f)(t)


def jacobian(unit: DyrUnit, specs, events: Events, sigma, settings: PlaybackSettings):
    """(residual, J, scale) at the unit's own values; J in normalised coordinates
    (``x_j d r / d x_j``, or the bound width for a parameter at 0)."""
    specs = tuple(specs)
    x0 = np.array([float(s.value(unit)) for s in specs])
    scale = np.array([_scale(s, v) for s, v in zip(specs, x0)])
    r, jac = _residual_jacobian(jnp.zeros(len(specs)), jnp.asarray(x0), jnp.asarray(scale), unit,
                                _traced(specs), events, jnp.asarray(sigma), settings)
    return np.asarray(r), np.asarray(jac), scale


def rank(unit: DyrUnit, specs, events: Events, settings: PlaybackSettings = PlaybackSettings(),
         cal: CalibrationSettings = CalibrationSettings()) -> Ranking:
    """Sensitivities and identifiability of ``specs`` from ``events`` (at the .dyr values)."""
    sigma = noise_level(events, cal.noise_floor_pu)
    _, jac, _ = jacobian(unit, specs, events, sigma, settings)
    n_ev, n_t = events.p_pu.shape
    jr = jac.reshape(n_ev, 2, n_t, len(specs))
    w = np.asarray(events.weight)
    n_valid = max(float(w.sum()), 1.0)
    sens = np.sqrt(np.einsum("ectp,et->pc", jr ** 2, w) / n_valid) * sigma[None, :]
    fisher = jac.T @ jac
    lam, vec = np.linalg.eigh(fisher)
    order = np.argsort(lam)[::-1]
    lam, vec = lam[order], vec[:, order]
    cov = np.linalg.pinv(fisher, rcond=1e-14)
    rel = Z95 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    vif = np.diag(fisher) * np.diag(cov)
    # a parameter that moves neither P nor Q in these events (an IBR gain on a path that they
    # never switch in) has a zero column: the pseudo-inverse would give it a zero variance
    diag = np.diag(fisher)
    dead = ~(diag > 1e-12 * np.max(diag, initial=0.0))
    ok = (rel < cal.max_relative_ci) & ~dead
    reasons = []
    labels = [s.label for s in specs]
    for j, s in enumerate(specs):
        if ok[j]:
            reasons.append("")
            continue
        if dead[j]:
            reasons.append(f"{s.part} {s.label}: these events do not move P or Q with it (sensitivity 0); "
                           "left at its .dyr value")
            continue
        partner = ""
        if vif[j] > 10:
            corr = cov[j] / np.sqrt(np.maximum(np.diag(cov) * cov[j, j], 1e-300))
            k = int(np.argmax(np.where(np.arange(len(specs)) == j, 0.0, np.abs(corr))))
            partner = f"; it trades off against {labels[k]} (correlation {corr[k]:+.2f})"
        reasons.append(f"{s.part} {s.label}: these events fix it only to +-{100 * rel[j]:.0f} % "
                       f"(95 %, variance inflation {vif[j]:.0f}){partner}; left at its .dyr value")
    return Ranking(labels, sens, rel, vif, lam, vec, ok, reasons)


# --- calibration -----------------------------------------------------------------------------

class Calibration(NamedTuple):
    """The fitted parameters with intervals (host values)."""

    labels: list
    dyr_values: np.ndarray
    values: np.ndarray
    ci95: np.ndarray
    """[p, 2] lower and upper 95 % bounds."""
    rms_before_pu: np.ndarray
    """RMS error of (P, Q) over all events at the .dyr values [pu]."""
    rms_after_pu: np.ndarray
    autocorrelation: float
    """Lag-1 autocorrelation of the residuals at the solution [-]."""
    bandwidth_frames: int
    """Bartlett bandwidth of the residuals' long-run covariance [frames]."""
    voltage_noise: np.ndarray
    """(sd of ln|V|, sd of the angle [rad]) drawn for the input part of the intervals."""
    converged: bool
    unit: DyrUnit
    specs: tuple
    """The :class:`ParameterSpec` of each fitted parameter (``labels`` order)."""


def _values(z, specs, x0, free, lower, upper):
    """The parameters at ``z``: the free ones from their coordinates, the others held at ``x0``
    (exactly: the coordinates' round trip is not)."""
    return jnp.where(free, jnp.stack([_from_z(z[j], s.positive, lower[j], upper[j])
                                      for j, s in enumerate(specs)]), x0)


def _fit_residuals(z, args):
    unit, specs, events, sigma, settings, x0, free, lower, upper = args
    return residuals(_values(z, specs, x0, free, lower, upper), unit, specs, events, sigma, settings)


@eqx.filter_jit
def _input_noise_residuals(values, unit, specs, events: Events, sigma, settings, eps):
    """:func:`residuals` with the imposed voltage (and the measured P and Q through it)
    perturbed by each draw of ``eps`` [draws, E, T, 2] (ln|V| and angle)."""
    def one(e):
        s = events.series
        series = s._replace(v_mag_pu=s.v_mag_pu * jnp.exp(e[..., 0]), v_ang_rad=s.v_ang_rad + e[..., 1])
        p, q = jax.vmap(measured_pq)(series)
        return residuals(values, unit, specs, Events(series, p, q, events.weight), sigma, settings)
    return jax.vmap(one)(eps)


def calibrate(unit: DyrUnit, specs, events: Events, settings: PlaybackSettings = PlaybackSettings(),
              cal: CalibrationSettings = CalibrationSettings(), free=None) -> Calibration:
    """Bounded output-error fit to ``events``, with intervals, of the parameters of ``specs``
    that ``free`` marks (bools over ``specs``; all by default); the others stay at the unit's
    values. Every traced program (the fit, the Jacobian, the input draws) depends on ``specs``,
    not on ``free``: fits of other subsets of the same ``specs`` reuse them."""
    sigma = noise_level(events, cal.noise_floor_pu)
    specs = tuple(specs)
    free = np.ones(len(specs), bool) if free is None else np.asarray(free, bool)
    x_all = np.array([float(s.value(unit)) for s in specs])
    z0 = jnp.asarray([_to_z(v, s) for v, s in zip(x_all, specs)])
    solver = optx.LevenbergMarquardt(rtol=cal.rtol, atol=cal.atol)
    lower, upper = _bounds(specs)
    sol = optx.least_squares(_fit_residuals, solver, z0,
                             args=(unit, _traced(specs), events, jnp.asarray(sigma), settings,
                                   jnp.asarray(x_all), jnp.asarray(free), lower, upper),
                             max_steps=cal.max_steps, throw=False)
    x_fit = np.asarray(_values(sol.value, specs, x_all, free, lower, upper))
    fitted = with_values(unit, specs, x_fit)
    r, jac, scale = jacobian(fitted, specs, events, sigma, settings)
    jac, scale = jac[:, free], scale[free]
    x0, x = x_all[free], x_fit[free]
    n_ev, n_t = events.p_pu.shape
    p = len(x)
    a_inv = np.linalg.pinv(jac.T @ jac, rcond=1e-14)
    # the residuals' part: a sandwich with their long-run covariance (P and Q rows per frame)
    res = r.reshape(n_ev, 2, n_t)
    num, den = np.sum(res[..., 1:] * res[..., :-1]), np.sum(res ** 2)
    rho = float(np.clip(num / den, 0.0, 0.999)) if den > 0 else 0.0
    scores = np.einsum("ectp,ect->etp", jac.reshape(n_ev, 2, n_t, p), res)
    frames = float(np.asarray(events.weight).sum()) / n_ev
    s_long, bandwidth = long_run_covariance(scores, rho, frames)
    cov = a_inv @ s_long @ a_inv
    # the events' disagreement: events as clusters
    if n_ev > 1:
        s_ev = np.einsum("etp->ep", scores)
        cov = cov + n_ev / (n_ev - 1) * a_inv @ (s_ev.T @ s_ev) @ a_inv
    # the imposed voltage's part: its noise drawn again, one Gauss-Newton step per draw
    v_noise = voltage_noise(events)
    if cal.input_draws > 1:
        rng = np.random.default_rng(cal.seed)
        eps = rng.standard_normal((cal.input_draws, n_ev, n_t, 2)) * v_noise
        r_draws = np.asarray(_input_noise_residuals(jnp.asarray(x_fit), fitted, _traced(specs), events,
                                                    jnp.asarray(sigma), settings, jnp.asarray(eps)))
        steps = -(r_draws - r[None]) @ jac @ a_inv.T
        cov = cov + np.cov(steps, rowvar=False).reshape(p, p)
    specs = tuple(s for s, f in zip(specs, free) if f)
    half = Z95 * np.sqrt(np.maximum(np.diag(cov), 0.0)) * scale
    half = np.hypot(half, cal.model_error * np.abs(x))
    lower, upper = (np.array([getattr(s, k) for s in specs]) for k in ("lower", "upper"))
    ci = np.stack([np.maximum(x - half, lower), np.minimum(x + half, upper)], axis=1)  # within the bounds
    # A value the fit pushed onto a bound: the data ask for beyond it, so the bound itself lies
    # in the interval (one-sided), and a .dyr value at the bound (D = 0) is not rejected.
    u = np.array([_unit_position(float(v), spec) for v, spec in zip(x, specs)])
    ci[u <= AT_BOUND, 0] = lower[u <= AT_BOUND]
    ci[u >= 1.0 - AT_BOUND, 1] = upper[u >= 1.0 - AT_BOUND]
    sd = jnp.asarray(sigma)
    return Calibration([s.label for s in specs], x0, x, ci, np.asarray(_rms_pq(unit, events, sd, settings)),
                       np.asarray(_rms_pq(fitted, events, sd, settings)), rho, bandwidth, v_noise,
                       bool(sol.result == optx.RESULTS.successful), fitted, specs)


# --- the decision: change only what the events reject ------------------------------------------

@eqx.filter_jit
def _errors(unit, events: Events, sigma, settings):
    """One playback of every event: per event, the sum of squared noise-normalised residuals
    of P and Q [-], [E]; and the RMS error of (P, Q) over all events [pu], [2]."""
    def one(series, p, q, w):
        r = play_back(unit, series, settings)
        ep, eq = r.p_pu - p, r.q_pu - q
        c = w * ((ep / sigma[0]) ** 2 + (eq / sigma[1]) ** 2)
        return jnp.sum(jnp.where(jnp.isfinite(c), c, 1e6)), jnp.stack([jnp.sum(w * ep ** 2),
                                                                       jnp.sum(w * eq ** 2)])
    cost, sq = jax.vmap(one)(events.series, events.p_pu, events.q_pu, events.weight)
    return cost, jnp.sqrt(sq.sum(0) / jnp.maximum(jnp.sum(events.weight), 1.0))


def _event_costs(unit, events: Events, sigma, settings):
    """Per event, the sum of squared noise-normalised residuals of P and Q [-], [E]."""
    return _errors(unit, events, sigma, settings)[0]


def _rms_pq(unit, events: Events, sigma, settings):
    """The RMS error of (P, Q) over all events [pu], [2]."""
    return _errors(unit, events, sigma, settings)[1]


def noise_threshold(k: int, lag1: float, level: float = 0.95) -> float:
    """The change of the normalised cost that noise alone gives, freeing ``k`` parameters: the
    ``level`` quantile of chi-square with k degrees of freedom (a likelihood-ratio test), times
    the long-run variance factor (1 + rho)/(1 - rho) of residuals with lag-1 autocorrelation
    ``lag1`` (white: 1)."""
    from scipy.stats import chi2

    rho = float(np.clip(lag1, 0.0, 0.99))
    return float(chi2.ppf(level, max(k, 1))) * (1.0 + rho) / (1.0 - rho)


class Decision(NamedTuple):
    """What a calibration may change in the .dyr, and why (host values)."""

    unit: DyrUnit
    """The unit to file: the .dyr one with only the changed parameters replaced."""
    changed: list
    """Labels of the parameters changed."""
    status: dict
    """Label -> "changed" or "consistent with the .dyr" (its value inside the 95 % interval of
    the fit, or the fit's gain within the noise) or "kept: ..." (refused, see ``refused``)."""
    fit: Calibration | None
    """The fit of the changed parameters (or the last fit tried)."""
    first_fit: Calibration | None
    """The fit of every identifiable parameter (whose intervals say which are rejected)."""
    cost_before: np.ndarray
    """Per event, the noise-normalised squared error at the .dyr values [-]."""
    cost_after: np.ndarray
    """The same for ``unit`` [-]."""
    threshold: float
    """The cost change that noise alone gives for the parameters changed [-]."""
    refused: str | None
    """Why a calibration that the events ask for was not written (an event gets worse)."""


def calibrate_where_rejected(unit: DyrUnit, specs, events: Events,
                             settings: PlaybackSettings = PlaybackSettings(),
                             cal: CalibrationSettings = CalibrationSettings(), free=None) -> Decision:
    """Calibrate, then change only what the events reject, never making an event worse.

    1. fit the parameters of ``specs`` that ``free`` marks (the identifiable ones; all by
       default); a parameter whose .dyr value lies inside its 95 % interval is consistent
       with the .dyr and is put back; the others are fitted again alone, until every one left
       is rejected (each fit reuses the first one's programs, see :func:`calibrate`);
    2. the change is kept only if the joint cost (squared residuals over the noise level, all
       events) falls by more than noise alone would give (:func:`noise_threshold`);
    3. it is refused if any event's cost rises by more than that: a fit that trades one event
       against another is a model error, not a better value.
    """
    specs = tuple(specs)
    mask = np.ones(len(specs), bool) if free is None else np.array(free, bool)
    sigma = jnp.asarray(noise_level(events, cal.noise_floor_pu))
    before = np.asarray(_event_costs(unit, events, sigma, settings))
    status = {s.label: "consistent with the .dyr" for s, f in zip(specs, mask) if f}
    first, fit = None, None
    while mask.any():
        fit = calibrate(unit, specs, events, settings, cal, free=mask)
        first = first or fit
        inside = np.array([ci[0] <= x0 <= ci[1] for x0, ci in zip(fit.dyr_values, fit.ci95)])
        if not inside.any():
            break
        mask[np.flatnonzero(mask)[inside]] = False
    free = [s for s, f in zip(specs, mask) if f]
    if not free:
        return Decision(unit, [], status, fit, first, before, before, noise_threshold(0, 0.0), None)
    after = np.asarray(_event_costs(fit.unit, events, sigma, settings))
    threshold = noise_threshold(len(free), fit.autocorrelation)
    gain = float(before.sum() - after.sum())
    if gain <= threshold:
        for s in free:
            status[s.label] = ("consistent with the .dyr: the fit improves the joint error by "
                               f"{gain:.3g}, within the noise ({threshold:.3g})")
        return Decision(unit, [], status, fit, first, before, before, threshold, None)
    worse = [e for e in range(len(before)) if after[e] - before[e] > threshold]
    if worse:
        why = (f"the fit of {', '.join(s.label for s in free)} makes event(s) "
               f"{', '.join(str(e + 1) for e in worse)} worse beyond the noise (normalised cost "
               + "; ".join(f"{before[e]:.3g} -> {after[e]:.3g}" for e in worse)
               + f", noise {threshold:.3g}): a model error, not a better value; .dyr kept")
        for s in free:
            status[s.label] = "kept: calibration refused"
        return Decision(unit, [], status, fit, first, before, before, threshold, why)
    for s in free:
        status[s.label] = "changed"
    return Decision(fit.unit, [s.label for s in free], status, fit, first, before, after, threshold, None)


__all__ = ["Calibration", "CalibrationSettings", "Decision", "Events", "ParameterSpec", "Ranking",
           "calibrate", "calibrate_where_rejected", "noise_threshold",
           "jacobian", "long_run_covariance", "measured_pq", "noise_level", "rank", "residuals",
           "stack_events", "voltage_noise", "with_values"]
