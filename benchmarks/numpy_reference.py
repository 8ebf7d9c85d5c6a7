"""The DREM/I&I observer as a user would write it by hand: a plain NumPy loop.

Same equations as jaxdse's observer (paper Sec. IV-B, App. B) and the same discretisation as
``jaxdse.Integrator.fast()`` (one step per sample, inputs linear between samples: the
trapezoidal rule, with the linear decay -gamma_j K_j Delta^2 theta_j of the two parameter
states taken exactly), so that it is both the speed baseline of ``benchmarks/run.py`` and a
reference for the tests.
Its inputs (delta, Te, dw) come from the configuration-independent front end.
"""

from __future__ import annotations

import math

import numpy as np


def _softplus(x):
    return math.log1p(math.exp(-abs(x))) + max(x, 0.0)


def _phi1(x):
    """(1 - e^-x) / x, and its series near 0."""
    return 1.0 - 0.5 * x + x * x / 6.0 if abs(x) < 1e-4 else -math.expm1(-x) / x


def observer_loop(ts, delta, t_e, dw, x2_0, t_ref, cfg: dict, gov: dict) -> np.ndarray:
    """a2_hat, a1_hat per sample. ``cfg``: ObserverConfig fields; ``gov``: TGOV1 fields."""
    l1, l2, l3 = cfg["lambda1"], cfg["lambda2"], cfg["lambda3"]
    p0, p1, p2 = l1 * l2 * l3, l1 * l2 + l1 * l3 + l2 * l3, l1 + l2 + l3
    c1, c2, k, ko = cfg["c1"], cfg["c2"], cfg["k_ext"], cfg["k_obs"]
    cc = c1 * c2
    g = np.array([cfg["gamma1"], cfg["gamma2"]])
    lo, hi, lref = math.log(cfg["eps"]), math.log(cfg["k_max"]), math.log(cfg["delta_ref_sq"])
    r, t1, t2, t3 = gov["r_pu"], gov["t1_s"], gov["t2_s"], gov["t3_s"]
    dt_g, vmax, vmin, win = gov["dt_pu"], gov["v_max_pu"], gov["v_min_pu"], cfg["window_s"]

    def torque(valve, lag, w):
        return lag + (t2 / t3) * (valve - lag) - dt_g * w

    def rhs(s, d, te, w):
        fd, fu, hz, hp1, hp2 = s[0:3], s[3:6], s[6:8], s[8:10], s[10:12]
        mean, th, xi, valve, lag = s[12], s[13:15], s[15], s[16], s[17]
        u = torque(valve, lag, w) - te
        p11, p12, p21, p22 = -k * fd[1], k * fu[0], k * cc * hp1[1], k * cc * hp2[1]
        z1, z2 = k * fd[2], k * cc * hz[1]
        det = p11 * p22 - p12 * p21
        zc = np.array([p22 * z1 - p12 * z2, -p21 * z1 + p11 * z2])
        x = lref - math.log(mean)
        kg = math.exp(lo + (_softplus(8 * (x - lo)) - _softplus(8 * (x - hi))) / 8)
        rate = g * kg * det * det
        dv = (t_ref - w / r - valve) / t1
        if (valve >= vmax and dv > 0) or (valve <= vmin and dv < 0):
            dv = 0.0
        out = np.empty(20)
        out[0:3] = fd[1], fd[2], p0 * (d - fd[0]) - p1 * fd[1] - p2 * fd[2]
        out[3:6] = fu[1], fu[2], p0 * (u - fu[0]) - p1 * fu[1] - p2 * fu[2]
        for j, (w2, inp) in enumerate(((hz, fd[2]), (hp1, -fd[1]), (hp2, fu[0]))):
            out[6 + 2 * j: 8 + 2 * j] = w2[1], inp - (c1 + c2) * w2[1] - cc * w2[0]
        out[12] = (det * det - mean) / win
        out[13:15] = -rate * th + g * kg * det * zc
        out[15] = -(th[0] + ko) * (xi + ko * d) + th[1] * u
        out[16], out[17] = dv, (valve - lag) / t3
        out[18:20] = rate
        decay = np.zeros(20)
        decay[13:15] = rate
        return out, decay

    valve0 = min(max(t_ref - dw[0] / r, vmin), vmax)
    u0 = torque(valve0, valve0, dw[0]) - t_e[0]
    s = np.zeros(20)
    s[0], s[3], s[10], s[12] = delta[0], u0, u0 / cc, cfg["delta_ref_sq"]
    s[13], s[14], s[15], s[16], s[17] = cfg["a1_init"], cfg["a2_init"], x2_0 - ko * delta[0], valve0, valve0
    theta = np.empty((len(ts), 2))
    theta[0] = s[13:15]
    def advance(y, r, b, h):  # dy/dt = -r y + b over h, exactly for constant r and b
        out = y + b * h  # r = 0 but for the two parameter states
        for j in (13, 14):
            out[j] = y[j] * math.exp(-r[j] * h) + b[j] * h * _phi1(r[j] * h)
        return out

    for n in range(1, len(ts)):
        h = ts[n] - ts[n - 1]
        k1, r0 = rhs(s, delta[n - 1], t_e[n - 1], dw[n - 1])
        b0 = k1 + r0 * s
        pred = advance(s, r0, b0, h)
        k2, r1 = rhs(pred, delta[n], t_e[n], dw[n])
        b1 = k2 + r1 * pred
        s = advance(s, 0.5 * (r0 + r1), 0.5 * (b0 + b1), h)
        theta[n] = s[13:15]
    return theta
