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
* the interval has three parts, added in quadrature: the noise part, from a parametric
  bootstrap (``bootstrap_draws`` refits, vmapped, on the recording with white noise of the
  levels measured on it added once more; with 0 draws, the Newey-West sandwich, whose
  Bartlett window ``hac_window_s`` covers the filtered residual's autocorrelation); the
  filter spread (refits with F made slower and faster: a right model finds the same a2
  with any filter); and ``model_error``, the 3rd-order model's error against real machines.

With ``IdentifySettings(output_error=True)`` the equation-error fit is the start of an
output-error refinement: optimistix's Levenberg-Marquardt minimises the playback residual
(x2, I_t, P_t, Q_t, each over its noise level) over a1, a2, the torque offset and the
governor gain error, with forward-mode Jacobians through the playback, and the covariance is
the same sandwich on the Jacobian's scores. It is exact for a 3rd-order machine; against
6th-order (GENROU) machines it biases H (the playback's errors are the model's, not noise),
so it is off by default (see ``experiments/andes_bench``).

H = ws / (2 a2) and D = a1 / a2, with their 95 % intervals from the interval of a2 (a
monotone map) and the delta method for D. The information matrix, scaled to unit diagonal,
gives the condition number that tells whether a2 is separable from the other terms.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Float

from .drem import ObserverConfig
from .estimate import scaled_governor
from .front_end import FrontEnd, front_end, playback_inputs, reference_torque
from .governor import AbstractGovernor
from .lti import filter_states, lag_chain, zero_phase_lowpass
from .machine import damping_from_a, inertia_from_a2
from .plant import Plant
from .playback import playback
from .recording import Recording
from .settings import Settings

Z95 = 1.959963984540054
"""Two-sided 95 % quantile of the standard normal distribution."""
PARAMETERS = ("a1", "a2", "c", "g")
"""Coefficients of the regression: damping, inertia, torque offset, governor gain error."""


class IdentifySettings(eqx.Module):
    """Static choices of :func:`identify` (never differentiated or vmapped)."""

    settle_s: float = eqx.field(static=True, default=1.0)
    """Samples of the first ``settle_s`` [s] are left out (the filters start from rest)."""
    governor_smoothing_hz: float = eqx.field(static=True, default=2.0)
    """Cut-off [Hz] of the zero-phase low-pass of the speed that drives the governor model."""
    robust_iterations: int = eqx.field(static=True, default=10)
    """Reweighting steps of the Huber regression (0: ordinary least squares)."""
    huber_k: float = eqx.field(static=True, default=1.345)
    """Huber threshold in robust standard deviations (1.345: 95 % efficiency for Gaussian noise)."""
    hac_window_s: float = eqx.field(static=True, default=2.0)
    """Newey-West window of the residual autocorrelation [s]."""
    bootstrap_draws: int = eqx.field(static=True, default=32)
    """Noise draws of the parametric bootstrap that gives the noise part of the interval
    (0: the Newey-West sandwich instead)."""
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
    ``relative_ci_noise``, ``filter_spread`` and ``IdentifySettings.model_error`` added in
    quadrature."""
    relative_ci_noise: Float[Array, ""]
    """The part from the measurement noise: 1.96 se_a2 / a2 [-]."""
    filter_spread: Float[Array, ""]
    """Largest relative change of a2 when the filter F is made slower or faster
    (``IdentifySettings.spread_scales``) [-]. Were the model right, every filter would find
    the same a2 up to noise; a spread is model error (a 6th-order machine, a governor model
    that is off), which the residual's variance does not show."""
    condition: Float[Array, ""]
    """Condition number of the information matrix scaled to unit diagonal [-]."""
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
    s = identify_settings
    ts = recording.t_s
    dt = ts[1] - ts[0]
    fe = front_end(recording, plant, settings)
    valid = fe.valid & (ts >= ts[0] + s.settle_s)
    window = jnp.maximum(jnp.round(s.hac_window_s / dt), 1.0).astype(jnp.int32)
    signals = _signals(ts, fe, recording, plant, settings, s, dt)

    def fit(scale):
        poles = scale * jnp.stack([config.lambda1, config.lambda2, config.lambda3])
        design, z = _regression(signals, poles, dt)
        return design, _huber(design, z, valid, s.robust_iterations, s.huber_k)

    design, (theta, weights, slope, resid) = fit(1.0)
    cov, info = _sandwich(design * (weights * resid)[:, None], (design * slope[:, None]).T @ design, window)
    others = jnp.stack([fit(k)[1][0][1] for k in s.spread_scales]) if s.spread_scales else theta[1:2]
    spread = jnp.max(jnp.abs(others / theta[1] - 1.0))
    levels = noise_levels(recording, fe.valid)
    if s.bootstrap_draws:
        def draw(key):
            noisy = add_noise(recording, levels, key)
            fe_k = front_end(noisy, plant, settings)
            poles = jnp.stack([config.lambda1, config.lambda2, config.lambda3])
            design_k, z_k = _regression(_signals(ts, fe_k, noisy, plant, settings, s, dt), poles, dt)
            return _huber(design_k, z_k, valid, s.robust_iterations, s.huber_k)[0]

        keys = jax.random.split(jax.random.PRNGKey(s.bootstrap_seed), s.bootstrap_draws)
        cov = jnp.cov(jax.vmap(draw)(keys), rowvar=False)
    ee = _result(theta, cov, info, plant.machine.omega_s, jnp.sum(valid), spread, levels, jnp.array(False),
                 s.model_error)
    if not s.output_error:
        return ee
    oe = _output_error(ts, fe, plant, settings, s, ee, valid, window, dt, spread, levels)
    return jax.tree_util.tree_map(lambda a, b: jnp.where(oe.output_error, a, b), oe, ee)


def _signals(ts, fe: FrontEnd, recording: Recording, plant: Plant, settings: Settings,
             s: IdentifySettings, dt):
    """The unfiltered inputs of the regression: 2 pi (f - f0), delta - theta, Tm - Te, 1, Tm - Tm(0).

    Without a frequency channel, f would be the smoothed derivative of theta: then the bus
    term is 0 and the rotor term is delta itself (x2 = d delta/dt, differentiated exactly by
    the filter; the smoothing would bias H by ~2 %).
    """
    dw = zero_phase_lowpass(fe.x2_meas, dt, s.governor_smoothing_hz) / plant.machine.omega_s
    t_ref = reference_torque(ts, fe._replace(dw=dw), plant.governor, settings)
    t_m = governor_torque(plant.governor, dw, dt, t_ref)
    derived = True if recording.f_hz is None else jnp.all(jnp.isnan(recording.f_hz) | ~fe.valid)
    bus = jnp.where(derived, 0.0, 2.0 * jnp.pi * (fe.f_hz - plant.machine.f_nominal_hz))
    rotor = jnp.where(derived, fe.alg.delta_rad, fe.alg.delta_rad - fe.theta_ref)
    return jnp.stack([bus, rotor, t_m - fe.alg.t_e_pu, jnp.ones_like(ts), t_m - t_m[0]])


def _regression(signals, poles, dt):
    """(design matrix [T, 4], left-hand side z [T]) of the swing equation filtered by the
    3rd-order filter with ``poles`` [rad/s]."""
    a, b = lag_chain(poles)
    bus, rotor, torque, one, gov = jax.vmap(lambda u: filter_states(a, b, u, dt))(signals)
    # x2 = 2 pi (f - f0) + d(delta - theta)/dt (Remark 2): the derivatives are the filter's own
    # (exact), not the smoothed ones of the front end, which attenuate a 1.5 Hz swing by ~9 %.
    fx2, fsx2 = bus[:, 0] + rotor[:, 1], bus[:, 1] + rotor[:, 2]
    return jnp.stack([-fx2, torque[:, 0], one[:, 0], gov[:, 0]], axis=1), fsx2


def _output_error(ts, fe: FrontEnd, plant: Plant, settings: Settings, s: IdentifySettings,
                  start: Identified, valid, window, dt, spread, levels) -> Identified:
    """Levenberg-Marquardt on the playback residual over p = (a1, ln(a2/a2_0), offset, gain)."""
    w_s = plant.machine.omega_s
    integ = settings.playback_integrator
    if integ.adaptive:  # forward-mode Jacobians through diffrax
        integ = dataclasses.replace(integ, forward_mode=True)
    t_ref = reference_torque(ts, fe, plant.governor, settings)
    inputs, y0, measured = playback_inputs(fe, None, fe.alg.delta_rad[0], t_ref, plant,
                                           dataclasses.replace(settings, external_tm=False), dt)
    meas = jnp.stack(measured)
    sigma = jax.vmap(lambda m: _noise_level(m, valid))(meas)
    usable = start.ok & (start.a2 > 0)
    a2_0 = jnp.where(usable, start.a2, inertia_from_a2(5.0, w_s))  # H = 5 s where EE failed
    p0 = jnp.where(usable, jnp.stack([start.a1, 0.0, start.t_m_offset_pu, start.governor_gain_error]),
                   jnp.zeros(4))

    def residual(p, _):
        pl = scaled_governor(plant, t_ref, fe.dw[0], p[3], p[2])
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
    return _result(theta, to_theta @ cov_p @ to_theta.T, info, w_s, jnp.sum(valid), spread, levels,
                   converged, s.model_error)


def noise_levels(recording: Recording, valid) -> Array:
    """White-noise standard deviations of a recording's channels (see ``Identified.noise_levels``):
    the MAD of the second differences / sqrt 6, which a smooth signal barely touches."""
    def level(x):
        d2 = x[2:] - 2.0 * x[1:-1] + x[:-2]
        ok = valid[2:] & jnp.isfinite(d2)
        med = _masked_median(d2, ok)
        return jnp.where(jnp.any(ok), 1.4826 * _masked_median(jnp.abs(d2 - med), ok) / jnp.sqrt(6.0),
                         jnp.nan)

    f = recording.f_hz if recording.f_hz is not None else jnp.full_like(recording.t_s, jnp.nan)
    return jnp.stack([level(jnp.log(recording.v_mag_pu)), level(recording.v_ang_rad),
                      level(jnp.log(recording.i_mag_pu)), level(recording.i_ang_rad), level(f)])


def add_noise(recording: Recording, levels, key) -> Recording:
    """``recording`` with white Gaussian noise of ``levels`` added once more (the bootstrap's draw)."""
    e = jax.random.normal(key, (5,) + recording.t_s.shape, dtype=recording.t_s.dtype)
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
    med = _masked_median(d, ok)
    return jnp.maximum(1.4826 * _masked_median(jnp.abs(d - med), ok) / jnp.sqrt(2.0), 1e-12)


def governor_torque(gov: AbstractGovernor, dw, dt, t_ref):
    """Tm [pu] of the governor model driven by ``dw`` [pu], from equilibrium (Heun steps, one
    per sample; the governors are slow next to a PMU's frame rate)."""
    def step(x, d):
        d0, d1 = d
        k1 = gov.vector_field(x, d0, t_ref)
        k2 = gov.vector_field(x + dt * k1, d1, t_ref)
        x = x + 0.5 * dt * (k1 + k2)
        return x, gov.torque(x, d1)

    x0 = gov.steady_state(t_ref, dw[0])
    _, tm = jax.lax.scan(step, x0, (dw[:-1], dw[1:]))
    return jnp.concatenate([gov.torque(x0, dw[0])[None], tm])


def _huber(x, y, valid, iterations, k):
    """Huber regression by iteratively reweighted least squares (scale: MAD of the residual).

    Returns (theta, psi(r) / r, psi'(r), r) at the solution: the weights of the sandwich's
    scores and of its information matrix (with the IRLS weights in the information matrix
    instead of psi', the downweighted samples would still count as information, and the
    interval would come out too narrow).
    """
    def solve(w):
        w = jnp.where(valid, w, 0.0)
        xw = x * w[:, None]
        # Columns scaled to unit norm first: a2's regressor and the constant differ by 1e3.
        scale = jnp.sqrt(jnp.sum(xw * x, axis=0)) + 1e-300
        xs = x / scale[None, :]
        theta_s = jnp.linalg.lstsq(xs * jnp.sqrt(w)[:, None], y * jnp.sqrt(w), rcond=None)[0]
        return theta_s / scale

    def weights(theta):
        r = y - x @ theta
        med = _masked_median(r, valid)
        sigma = 1.4826 * _masked_median(jnp.abs(r - med), valid)
        u = jnp.abs(r) / (k * jnp.maximum(sigma, 1e-300))
        return jnp.where(u <= 1.0, 1.0, 1.0 / u), u <= 1.0, r

    w = jnp.ones_like(y)
    w, _ = jax.lax.scan(lambda w, _: (weights(solve(w))[0], None), w, None, length=iterations)
    theta = solve(w)
    w, inside, r = weights(theta)
    if iterations == 0:  # ordinary least squares
        w, inside = jnp.ones_like(y), jnp.ones_like(y, dtype=bool)
    return theta, jnp.where(valid, w, 0.0), jnp.where(valid & inside, 1.0, 0.0), r


def _masked_median(x, mask):
    """Median of ``x[mask]`` with a static shape (masked entries sorted to the end)."""
    n = jnp.sum(mask)
    xs = jnp.sort(jnp.where(mask, x, jnp.inf))
    lo = xs[jnp.maximum((n - 1) // 2, 0)]
    hi = xs[jnp.maximum(n // 2, 0)]
    return 0.5 * (lo + hi)


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
    bread = jnp.linalg.pinv(info)
    return bread @ meat @ bread, info


def _result(theta, cov, info, w_s, samples, spread, levels, output_error, model_error) -> Identified:
    a1, a2, c, g = theta[0], theta[1], theta[2], theta[3]
    se = jnp.sqrt(jnp.maximum(jnp.diag(cov), 0.0))
    half = jnp.sqrt((Z95 * se[1]) ** 2 + (spread**2 + model_error**2) * a2**2)
    lo2, hi2 = a2 - half, a2 + half
    h_lo = inertia_from_a2(hi2, w_s)
    h_hi = jnp.where(lo2 > 0, inertia_from_a2(jnp.maximum(lo2, 1e-300), w_s), jnp.inf)
    # D = a1 / a2: gradient (1/a2, -a1/a2^2) on the (a1, a2) block.
    grad = jnp.stack([1.0 / a2, -a1 / a2**2])
    se_d = jnp.sqrt(jnp.maximum(grad @ cov[:2, :2] @ grad, 0.0))
    d = damping_from_a(a1, a2)
    diag = jnp.sqrt(jnp.maximum(jnp.diag(info), 1e-300))
    eig = jnp.linalg.eigvalsh(info / jnp.outer(diag, diag))
    condition = eig[-1] / jnp.maximum(eig[0], 1e-300)
    values = (a1, a2, inertia_from_a2(a2, w_s), d, se[0], se[1], c / a2, g / a2, spread)
    ok = jnp.all(jnp.isfinite(jnp.stack(values))) & jnp.all(jnp.isfinite(cov))
    return Identified(
        a1=a1, a2=a2, h_s=inertia_from_a2(a2, w_s), d_pu_s=d,
        h_ci95=jnp.stack([h_lo, h_hi]), d_ci95=jnp.stack([d - Z95 * se_d, d + Z95 * se_d]),
        se_a1=se[0], se_a2=se[1], covariance=cov, t_m_offset_pu=c / a2,
        governor_gain_error=g / a2, relative_ci=half / jnp.abs(a2),
        relative_ci_noise=Z95 * se[1] / jnp.abs(a2), filter_spread=spread, condition=condition,
        noise_levels=levels, samples=samples, ok=ok, output_error=output_error,
    )
