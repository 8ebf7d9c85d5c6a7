"""DREM parameter estimator and I&I speed observer (paper Sec. IV-B and Appendix B).

Swing equation (paper Eq. 5): d^2 delta/dt^2 = -a1 d delta/dt + a2 (Tm - Te). Filtering with

    F = l1 l2 l3 / ((s + l1)(s + l2)(s + l3))

gives the linear regression z = theta^T psi with theta = [a1, a2],

    z = F[s^2 delta],   psi = [-F[s delta], F[Tm - Te]]                         (App. Eq. 17)

The regressor is extended with H = K [1, c1 c2 s / ((s + c1)(s + c2))]^T    (Sec. IV-B.2)

    Z = H[z],  Psi = H[psi^T],  Delta = det Psi,  Zc = adj(Psi) Z = Delta theta   (Eq. 18-19)

and each parameter is updated by the scalar law (Eq. 20-21)

    d theta_j/dt = -gamma_j K_j Delta (Delta theta_j - Zc_j),
    K_j = Delta_ref^2 / mean(Delta^2), saturated smoothly to [eps, k_max],

with mean(Delta^2) an exponential moving mean over ``window_s``. The I&I observer (Lemma 2):

    dxI/dt = -(a1_hat + k)(xI + k delta) + a2_hat (Tm - Te),   x2_hat = xI + k delta.

All of it is one ODE, integrated with diffrax over the sample intervals (``_integrate``).
The error obeys theta_j - theta_hat_j = exp(-int gamma_j K_j Delta^2) (theta_j - theta_j(0))
for noise-free data; that exponent is integrated too and reported as the excitation
("log contraction"): it tells whether the data excited the estimator at all.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, Float

from .._models.governors import AbstractGovernor
from .._base.fields import as_float, check_positive
from .integrate import Integrator, Previous, integrate_sampled
from .metrics import smape_terms


class ObserverConfig(eqx.Module):
    """Tuning of the DREM estimator and the I&I observer. Defaults: the paper's Table I."""

    lambda1: Float[Array, ""] = eqx.field(converter=as_float, default=8.0)
    """Pole of the 3rd-order filter F [1/s]."""
    lambda2: Float[Array, ""] = eqx.field(converter=as_float, default=6.2)
    """Pole of F [1/s]."""
    lambda3: Float[Array, ""] = eqx.field(converter=as_float, default=7.4)
    """Pole of F [1/s]."""
    c1: Float[Array, ""] = eqx.field(converter=as_float, default=8.0)
    """Pole of the derivative branch of the regressor extension H [1/s]."""
    c2: Float[Array, ""] = eqx.field(converter=as_float, default=6.0)
    """Pole of the derivative branch of H [1/s]. (Table I also lists c3 = 7; H has no c3.)"""
    k_ext: Float[Array, ""] = eqx.field(converter=as_float, default=6.5)
    """Gain K of the regressor extension H [-]."""
    gamma1: Float[Array, ""] = eqx.field(converter=as_float, default=850.0)
    """Adaptation gain gamma_1 of a1."""
    gamma2: Float[Array, ""] = eqx.field(converter=as_float, default=850.0)
    """Adaptation gain gamma_2 of a2."""
    k_obs: Float[Array, ""] = eqx.field(converter=as_float, default=8.0)
    """I&I observer gain k [1/s]."""
    eps: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """Lower bound epsilon of the adaptive gain K_j [-]."""
    k_max: Float[Array, ""] = eqx.field(converter=as_float, default=100.0)
    """Upper bound of the adaptive gain K_j [-] (100 in the paper)."""
    window_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """Time constant of the moving mean of Delta^2 [s]."""
    delta_ref_sq: Float[Array, ""] = eqx.field(converter=as_float, default=3e-5)
    """Delta_ref^2 of the adaptive gain K_j = Delta_ref^2 / mean(Delta^2). The paper gives no
    value; 3e-5 makes gamma Delta_ref^2 ~ 0.026 1/s, i.e. about 90 s to converge on the demo,
    as in the paper. Scale it with gamma to trade convergence speed against noise."""
    a1_init: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """Initial estimate of a1 [1/s]."""
    a2_init: Float[Array, ""] = eqx.field(converter=as_float, default=40.0)
    """Initial estimate of a2 [rad/s^2 per pu]."""

    def __check_init__(self):
        check_positive(self, "lambda1", "lambda2", "lambda3", "c1", "c2", "k_ext", "gamma1",
                       "gamma2", "k_obs", "eps", "k_max", "window_s", "delta_ref_sq", "a2_init")


class DremInputs(NamedTuple):
    """Sampled inputs of the observer ODE."""

    delta: Array
    """Rotor angle relative to its first sample [rad]."""
    t_e: Array
    """Air-gap torque [pu]."""
    dw: Array
    """Measured rotor-speed deviation x2_meas / w_s [pu] driving the governor."""
    t_m: Array | None
    """External mechanical torque [pu] (``external_tm`` only; else None)."""


class DremState(NamedTuple):
    f_delta: Array
    """[F[delta], F[s delta], F[s^2 delta]]."""
    f_u: Array
    """[F[u], F[s u], F[s^2 u]] with u = Tm - Te."""
    h_z: Array
    """States of c1 c2 s/((s+c1)(s+c2)) driven by z."""
    h_psi1: Array
    h_psi2: Array
    mean_dsq: Array
    """Moving mean of Delta^2."""
    theta: Array
    """[a1_hat, a2_hat]."""
    x_i: Array
    """I&I observer state xI."""
    gov: Array
    """Governor-turbine states."""
    log_contraction: Array
    """int gamma_j K_j Delta^2 dt, j = 1, 2."""


class Regression(NamedTuple):
    delta_det: Array
    zc: Array
    k_gamma: Array


def _filter3_rhs(x, inp, cfg):
    l1, l2, l3 = cfg.lambda1, cfg.lambda2, cfg.lambda3
    p0, p1, p2 = l1 * l2 * l3, l1 * l2 + l1 * l3 + l2 * l3, l1 + l2 + l3
    return jnp.stack([x[1], x[2], p0 * (inp - x[0]) - p1 * x[1] - p2 * x[2]])


def _hd_rhs(w, inp, cfg):
    return jnp.stack([w[1], inp - (cfg.c1 + cfg.c2) * w[1] - cfg.c1 * cfg.c2 * w[0]])


def regression(s: DremState, cfg: ObserverConfig) -> Regression:
    """Delta = det Psi, Zc = adj(Psi) Z and the adaptive gain K_j from the filter states."""
    cc = cfg.c1 * cfg.c2
    z, psi1, psi2 = s.f_delta[..., 2], -s.f_delta[..., 1], s.f_u[..., 0]
    k = cfg.k_ext
    p11, p12, p21, p22 = k * psi1, k * psi2, k * cc * s.h_psi1[..., 1], k * cc * s.h_psi2[..., 1]
    z1, z2 = k * z, k * cc * s.h_z[..., 1]
    det = p11 * p22 - p12 * p21
    zc = jnp.stack([p22 * z1 - p12 * z2, -p21 * z1 + p11 * z2], axis=-1)
    return Regression(det, zc, adaptive_gain(s.mean_dsq, cfg))


def adaptive_gain(mean_dsq, cfg: ObserverConfig):
    """K_j = Delta_ref^2 / mean(Delta^2) saturated to [eps, k_max] (paper Eq. 21).

    The saturation is smooth, K = k_max ((s^8 + e^8) / (1 + s^8))^(1/8) with s = r / k_max,
    e = eps / k_max and r = Delta_ref^2 / mean(Delta^2): softplus corners of width ~1/8 in
    log K, so the estimator stays differentiable in every tuning parameter; away from the
    corners it equals the paper's hard clip. Powers of 2 and square roots only (no exp/log:
    this runs twice per step of the time loop).
    """
    # s <= 1e4: K = k_max to round-off there, and no overflow (or inf gradient) at mean = 0.
    s = cfg.delta_ref_sq / jnp.maximum(cfg.k_max * mean_dsq, 1e-4 * cfg.delta_ref_sq)
    e = cfg.eps / cfg.k_max
    s8, e8 = ((s * s) ** 2) ** 2, ((e * e) ** 2) ** 2
    return cfg.k_max * jnp.sqrt(jnp.sqrt(jnp.sqrt((s8 + e8) / (1.0 + s8))))


def _vector_field(external_tm: bool):
    def rhs(t, s: DremState, u: DremInputs, args):
        cfg, gov, t_ref = args
        t_m = u.t_m if external_tm else gov.torque(s.gov, u.dw)
        torque = t_m - u.t_e
        reg = regression(s, cfg)
        gamma = jnp.stack([cfg.gamma1, cfg.gamma2])
        rate = gamma * reg.k_gamma * reg.delta_det**2
        return DremState(
            f_delta=_filter3_rhs(s.f_delta, u.delta, cfg),
            f_u=_filter3_rhs(s.f_u, torque, cfg),
            h_z=_hd_rhs(s.h_z, s.f_delta[2], cfg),
            h_psi1=_hd_rhs(s.h_psi1, -s.f_delta[1], cfg),
            h_psi2=_hd_rhs(s.h_psi2, s.f_u[0], cfg),
            mean_dsq=(reg.delta_det**2 - s.mean_dsq) / cfg.window_s,
            theta=-rate * s.theta + gamma * reg.k_gamma * reg.delta_det * reg.zc,
            x_i=-(s.theta[0] + cfg.k_obs) * (s.x_i + cfg.k_obs * u.delta) + s.theta[1] * torque,
            gov=gov.vector_field(s.gov, u.dw, t_ref),
            log_contraction=rate,
        )

    return rhs


def _theta_rate(t, s: DremState, u: DremInputs, args):
    """The linear decay rate of each state: gamma_j K_j Delta^2 for theta, zero elsewhere."""
    cfg = args[0]
    reg = regression(s, cfg)
    rate = jnp.stack([cfg.gamma1, cfg.gamma2]) * reg.k_gamma * reg.delta_det**2
    zero = jtu.tree_map(jnp.zeros_like, s)
    return zero._replace(theta=rate)


class DremTrajectory(eqx.Module):
    """Observer output at every sample."""

    theta: Float[Array, "T 2"]
    """[a1_hat, a2_hat]."""
    x2_hat_rad_s: Float[Array, " T"]
    t_m_pu: Float[Array, " T"]
    delta_sq: Float[Array, " T"]
    """Delta^2, the excitation of the extended regressor."""
    k_gamma: Float[Array, " T"]
    log_contraction: Float[Array, "T 2"]
    """int gamma_j K_j Delta^2 dt: the parameter error has shrunk by exp(-this)."""


class DremSegments(NamedTuple):
    """Per-segment summaries of the observer: what the final report needs. A segment is a
    block of ``block`` samples, or one sample when the trajectory is kept."""

    theta_end: Array
    """[a1_hat, a2_hat] at the last sample of each segment."""
    a2_min: Array
    """Smallest a2_hat in the segment (+inf for a segment of padding)."""
    a2_max: Array
    x2_smape_sum: Array
    """Sum of the sMAPE terms of x2_hat against x2_meas (paper Eq. 23)."""
    torque_sum: Array
    """Sum of Tm - Te."""
    count: Array
    """Valid samples in the segment."""


class ObserverSolution(eqx.Module):
    """What :func:`run_observer` returns, whatever it keeps."""

    segments: DremSegments
    last: DremState
    """State at the last valid sample: the carry for the next chunk of a stream."""
    ok: Array
    """True when every solver step succeeded and every block stayed finite."""
    num_steps: Array
    trajectory: DremTrajectory | None
    """Every sample's output (``save_trajectory=True``), else None."""


def initial_state(inputs0: DremInputs, x2_0, t_ref, cfg: ObserverConfig, gov: AbstractGovernor,
                  external_tm: bool) -> DremState:
    """Filters at rest at the first sample, theta at its initial guess, x2_hat(0) = x2_0."""
    gov0 = gov.steady_state(t_ref, inputs0.dw)
    t_m0 = inputs0.t_m if external_tm else gov.torque(gov0, inputs0.dw)
    u0 = t_m0 - inputs0.t_e
    zero2 = jnp.zeros(2, dtype=u0.dtype)
    return DremState(
        f_delta=jnp.stack([inputs0.delta, 0.0 * u0, 0.0 * u0]),
        f_u=jnp.stack([u0, 0.0 * u0, 0.0 * u0]),
        h_z=zero2,
        h_psi1=zero2,
        h_psi2=jnp.stack([u0 / (cfg.c1 * cfg.c2), 0.0 * u0]),
        mean_dsq=cfg.delta_ref_sq,
        theta=jnp.stack([cfg.a1_init, cfg.a2_init]),
        x_i=x2_0 - cfg.k_obs * inputs0.delta,
        gov=gov0,
        log_contraction=zero2,
    )


def run_observer(ts, inputs: DremInputs, x2_0, t_ref, cfg: ObserverConfig, gov: AbstractGovernor,
                 integ: Integrator = Integrator(), external_tm: bool = False, *, x2_meas,
                 n_valid=None, resume: tuple[DremState, Previous] | None = None, block: int = 50,
                 save_trajectory: bool = False) -> ObserverSolution:
    """Integrate the DREM estimator and the I&I observer over a recording.

    Arguments:
        ts, inputs: sample times and the sampled inputs.
        x2_0, t_ref: initial speed deviation [rad/s] and governor reference [pu].
        x2_meas: measured x2 per sample [rad/s] (for the sMAPE of x2_hat).
        n_valid: valid samples (may be traced); the state is held on the padding after them.
        resume: (state, previous sample) to continue a stream instead of starting at rest.
        block: samples per block (checkpointing, and the segments when no trajectory is kept).
        save_trajectory: keep every sample's output; the segments are then single samples.
    """
    if resume is None:
        first = jtu.tree_map(lambda x: x[0], inputs)
        y0, previous = initial_state(first, x2_0, t_ref, cfg, gov, external_tm), None
    else:
        y0, previous = resume
    args = (cfg, gov, t_ref)
    field = _vector_field(external_tm)

    def t_m_of(s: DremState, u: DremInputs):
        return u.t_m if external_tm else gov.torque(jnp.moveaxis(s.gov, -1, 0), u.dw)

    def summarise(s: DremState, u: DremInputs, x2m, val):
        """The segment summary of states ``s`` (leading axis: the segment's samples)."""
        a2 = s.theta[:, 1]
        x2_hat = s.x_i + cfg.k_obs * u.delta
        return DremSegments(
            theta_end=s.theta[-1],
            a2_min=jnp.min(jnp.where(val, a2, jnp.inf)),
            a2_max=jnp.max(jnp.where(val, a2, -jnp.inf)),
            x2_smape_sum=jnp.sum(jnp.where(val, smape_terms(x2_hat, x2m), 0.0)),
            torque_sum=jnp.sum(jnp.where(val, t_m_of(s, u) - u.t_e, 0.0)),
            count=jnp.sum(val),
        )

    out = integrate_sampled(field, y0, ts, inputs, args, integ, n_valid=n_valid, previous=previous,
                            reduce=None if save_trajectory else summarise,
                            aux=None if save_trajectory else x2_meas, block=block, rate=_theta_rate)
    if not save_trajectory:
        return ObserverSolution(segments=out.ys, last=out.y_last, ok=out.ok, num_steps=out.num_steps,
                                trajectory=None)
    s: DremState = out.ys
    valid = jnp.arange(ts.shape[0]) < (ts.shape[0] if n_valid is None else n_valid)
    segments = jax.vmap(summarise)(*jtu.tree_map(lambda x: x[:, None], (s, inputs, x2_meas, valid)))
    reg = regression(s, cfg)
    trajectory = DremTrajectory(theta=s.theta, x2_hat_rad_s=s.x_i + cfg.k_obs * inputs.delta,
                                t_m_pu=t_m_of(s, inputs), delta_sq=reg.delta_det**2,
                                k_gamma=reg.k_gamma, log_contraction=s.log_contraction)
    return ObserverSolution(segments=segments, last=out.y_last, ok=out.ok, num_steps=out.num_steps,
                            trajectory=trajectory)
