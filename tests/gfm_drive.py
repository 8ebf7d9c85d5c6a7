"""The imposed terminal voltage of the grid-forming converters' block-diagram tests
(tests/models/test_regfm_a1.py, test_regfm_b1.py): steps of |V| and ramps of frequency at a
power-flow point, the module integrated by diffrax under it, and the same inputs for the SciPy
references written in each test."""

from __future__ import annotations

import math

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from jaxdse._models.ibr import GfmInputs

V0, P0, Q0, ANG = 1.01, 0.7, 0.1, 0.3
T_END = 3.0
TS = np.linspace(0.0, T_END, 301)
W0 = 2 * math.pi * 60.0
F_RATE = (0.1 / 60.0) / 0.5
"""0.1 Hz in 0.5 s [pu/s]."""


def runs(f_rate: float = F_RATE) -> dict:
    """(|V| steps as (time, increment) rows, frequency ramps as (start, end, rate) rows) per run:
    flat, a voltage step with a ramp there and back, a dip to 0.5 pu; one shape for every run."""
    return {
        "flat": (np.array([[0.2, 0.0], [0.4, 0.0]]), np.zeros((2, 3))),
        "step_ramp": (np.array([[0.2, -0.03], [1.5, 0.01]]),
                      np.array([[0.5, 1.0, f_rate], [2.0, 2.5, -f_rate]])),
        "dip": (np.array([[0.2, 0.5 - V0], [0.4, V0 - 0.5]]), np.zeros((2, 3))),
    }


def v_of(t, steps):
    return V0 + sum(dv for ts, dv in steps if t >= ts)


def theta_of(t, ramps):
    """The voltage angle [rad]: the integral of omega_0 times the ramps' frequency deviation."""
    out = ANG
    for a, b, r in ramps:
        if t > a:   # f = r (t - a) on [a, b], r (b - a) after
            tt = min(t, b) - a
            out += W0 * (0.5 * r * tt * tt + r * (b - a) * max(t - b, 0.0))
    return out


def initial_current():
    return np.conj((P0 + 1j * Q0) / (V0 * np.exp(1j * ANG)))


@eqx.filter_jit
def simulate(m, ts, v_steps, f_ramps):
    """(states, signals, y0) of converter ``m`` under the steps and ramps, from the power flow."""
    i = jnp.conj((P0 + 1j * Q0) / (V0 * jnp.exp(1j * ANG)))
    u0 = GfmInputs(jnp.asarray(V0 * math.cos(ANG)), jnp.asarray(V0 * math.sin(ANG)))
    y0, refs = m.initial_state(u0, i.real, i.imag)

    def u_of(t):
        v = V0 + jnp.sum(jnp.where(t >= v_steps[:, 0], v_steps[:, 1], 0.0))
        a, b, r = f_ramps[:, 0], f_ramps[:, 1], f_ramps[:, 2]
        tt = jnp.clip(t - a, 0.0, b - a)
        th = ANG + W0 * jnp.sum(0.5 * r * tt * tt + r * (b - a) * jnp.maximum(t - b, 0.0))
        return GfmInputs(v * jnp.cos(th), v * jnp.sin(th))

    term = diffrax.ODETerm(lambda t, y, _: m.vector_field(y, u_of(t), refs))
    jumps = jnp.concatenate([v_steps[:, 0], f_ramps[:, 0], f_ramps[:, 1]])
    control = diffrax.PIDController(rtol=1e-10, atol=1e-12, jump_ts=jumps)
    sol = diffrax.diffeqsolve(term, diffrax.Tsit5(), ts[0], ts[-1], 1e-4, y0, saveat=diffrax.SaveAt(ts=ts),
                              max_steps=1_000_000, stepsize_controller=control)
    sig = jax.vmap(lambda t, y: m.signals(y, u_of(t), refs))(ts, sol.ys)
    return sol.ys, sig, y0


def solve_pieces(rhs, x, steps, ramps):
    """solve_ivp (DOP853, rtol 1e-10) of ``rhs`` from ``x`` over TS, cut at every switching instant."""
    from scipy.integrate import solve_ivp

    cuts = sorted({0.0, T_END, *[s for s, _ in steps if 0 < s < T_END],
                   *[r for a, b, _ in ramps for r in (a, b) if 0 < r < T_END]})
    out = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        ts = TS[(TS >= a) & (TS < b)] if b < T_END else TS[TS >= a]
        sol = solve_ivp(rhs, (a, b), x, t_eval=np.r_[ts, b] if b < T_END else ts, method="DOP853",
                        rtol=1e-10, atol=1e-12, max_step=2e-3)
        out.append(sol.y[:, :len(ts)])
        x = sol.y[:, -1]
    return np.concatenate(out, axis=1).T


def nw(x, d, lo, hi):
    """A non-windup integrator: no motion beyond the limit its state sits on."""
    return 0.0 if (x >= hi and d > 0) or (x <= lo and d < 0) else d


def away(steps, ramps):
    """The frames more than 20 ms from a switching instant of the inputs."""
    instants = np.r_[steps[:, 0], ramps[:, 0], ramps[:, 1]]
    return np.all(np.abs(TS[:, None] - instants[None]) > 0.02, axis=1)
