"""Ground-truth plant simulator (the paper's Fig. 1) producing substation PMU recordings.

Plant: 3rd-order flux-decay machine (``_machine``) with an SEXS exciter and the plant's
governor-turbine, the auxiliary load at the LV bus (``_mapping``'s causal model), the
tap-changing transformer and the HV line to the substation. Beyond the substation: a local
load and a Thevenin grid (voltage source behind a reactance) with ambient fluctuations of
frequency, voltage and load, plus scheduled events. All network equations are solved
exactly at every right-hand-side evaluation, so the recording and the true states are
consistent to round-off: the estimator's algebraic stages recover them exactly.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._core.algebraic import algebraic_observer
from .._base.fields import as_float
from .._core.integrate import Integrator, solve_interval
from .._core.machine import electrical_torque, field_voltage, swing_acceleration, transient_emf_rate
from .._core.mapping import (
    aux_current,
    line_to_grid,
    lv_current_from_machine,
    lv_currents,
    transformer_to_hv,
)
from .._core.plant import Plant
from .._core.recording import Recording
from .._core.sequence import phases_from_sequences


class Exciter(eqx.Module):
    """SEXS exciter: (1 + s TA)/(1 + s TB) * K/(1 + s TE), Ef in [e_min, e_max].

    Defaults are the SEXS data of the WECC 240-bus model (``shared/data/wecc240`` .dyr).
    """

    ta_tb: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    tb_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    k: Float[Array, ""] = eqx.field(converter=as_float, default=100.0)
    te_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    e_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    e_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)


class Event(NamedTuple):
    """A scheduled grid event.

    kind "load_step": the substation load steps up by ``size`` x machine rating (pf 0.95);
    "line_trip": the grid reactance is multiplied by ``size``;
    "frequency_drop": the grid frequency drops by ``size`` Hz and recovers with 30 s time constant.
    """

    time_s: float
    kind: Literal["load_step", "line_trip", "frequency_drop"]
    size: float


class Scenario(eqx.Module):
    """Operating point, grid, disturbances and PMU noise of one simulated recording."""

    duration_s: float = 600.0
    frame_rate_hz: float = 50.0
    p_pu: float = 0.818
    """Initial machine active power [pu, machine base]."""
    q_pu: float = 0.15
    """Initial machine reactive power [pu, machine base]."""
    v_t_pu: float = 1.0
    """Initial terminal voltage [pu]."""
    grid_x_pu: float = 0.01
    """Grid Thevenin reactance at the substation [pu, system base]."""
    load_p_pu: float = 3.0
    """Substation local load [pu, system base]."""
    load_q_pu: float = 0.5
    ambient_load_std: float = 0.03
    """Relative std of the substation load fluctuation (OU process)."""
    ambient_load_tau_s: float = 1.0
    ambient_freq_std_hz: float = 0.01
    """Std of the grid frequency fluctuation (OU process) [Hz]."""
    ambient_freq_tau_s: float = 5.0
    ambient_volt_std: float = 0.002
    """Relative std of the grid voltage fluctuation (OU process)."""
    ambient_volt_tau_s: float = 2.0
    events: tuple[Event, ...] = ()
    tve_percent: float = 0.05
    """Total vector error of the PMU phasors (rms) [%]."""
    freq_noise_hz: float = 0.0005
    """PMU frequency error std [Hz]."""
    unbalance: float = 0.005
    """Negative-sequence ratio of the three-phase output."""
    seed: int = 0


class Truth(eqx.Module):
    """True trajectories at the sample times [machine base]."""

    delta_rad: Float[Array, " T"]
    x2_rad_s: Float[Array, " T"]
    e_q1_pu: Float[Array, " T"]
    t_e_pu: Float[Array, " T"]
    t_m_pu: Float[Array, " T"]
    e_f_pu: Float[Array, " T"]
    v_t: Array
    """Terminal voltage phasor [pu]."""
    i_sg: Array
    """Machine current phasor [pu, system base]."""
    a1: Float[Array, ""]
    a2: Float[Array, ""]


class Simulation(eqx.Module):
    recording: Recording
    """Noisy positive-sequence PMU recording at the substation."""
    v_abc: Array
    """Three-phase voltage phasors [T, 3] (noisy, with unbalance) [pu]."""
    i_abc: Array
    truth: Truth
    clean: Recording
    """The same recording without PMU noise."""


class _GridInputs(NamedTuple):
    e_g: Array
    y_load: Array
    x_g: Array


def _thevenin(u: _GridInputs, plant: Plant):
    """E_th, Z_th with V_LV = E_th + Z_th I_LV seen from the LV bus into the network."""
    # Columns of the linear map (V_LV, I_LV) -> (V5, I5): images of (1, 0) and (0, 1).
    v5a, i5a = line_to_grid(*transformer_to_hv(1.0 + 0j, 0j, plant.transformer), plant.line)
    v5b, i5b = line_to_grid(*transformer_to_hv(0j, 1.0 + 0j, plant.transformer), plant.line)
    zg = 1j * u.x_g
    alpha = (1.0 + zg * u.y_load) * v5a - zg * i5a
    beta = (1.0 + zg * u.y_load) * v5b - zg * i5b
    return u.e_g / alpha, -beta / alpha


def _solve_network(delta, e_q1, u: _GridInputs, p_as_mean, plant: Plant, iterations: int = 8):
    """Terminal voltage and machine current (system base) for given rotor states."""
    m = plant.machine
    sc = plant.current_scale  # I_machine = I_system * sc
    e_th, z_th = _thevenin(u, plant)
    rot = jnp.exp(-1j * (delta - jnp.pi / 2))
    e_dq = e_th * rot
    r, x = jnp.real(z_th), jnp.imag(z_th)
    a = jnp.array([[-m.rs_pu - r / sc, m.xq_pu + x / sc], [-m.xd1_pu - x / sc, -m.rs_pu - r / sc]])

    def currents(i_as):
        rhs_c = e_dq - z_th * i_as * rot
        i_d, i_q = jnp.linalg.solve(a, jnp.stack([jnp.real(rhs_c), jnp.imag(rhs_c) - e_q1]))
        i_sg = (i_d + 1j * i_q) / rot / sc
        return e_th + z_th * (i_sg - i_as), i_sg, i_d, i_q

    # Fixed point on the (small) auxiliary current: contraction ~ |Z_th| |S_AS| / |V|^2.
    i_as = jax.lax.fori_loop(
        0, iterations, lambda _, i: aux_current(currents(i)[0], p_as_mean, plant.aux),
        aux_current(e_th, p_as_mean, plant.aux))
    return currents(i_as)


def _rhs(t, y, u: _GridInputs, args):
    plant, exc, v_ref, t_ref, p_as_mean = args
    m = plant.machine
    delta, x2, e_q1, x_ll, e_f = y[0], y[1], y[2], y[3], y[4]
    gov = y[5:]
    v_t, _, i_d, i_q = _solve_network(delta, e_q1, u, p_as_mean, plant)
    t_e = electrical_torque(e_q1, i_d, i_q, m)
    dw = x2 / m.omega_s
    t_m = plant.governor.torque(gov, dw)
    err = v_ref - jnp.abs(v_t)
    ll_out = exc.ta_tb * err + (1.0 - exc.ta_tb) * x_ll
    d_ef = (exc.k * ll_out - e_f) / exc.te_s
    d_ef = jnp.where(((e_f >= exc.e_max_pu) & (d_ef > 0)) | ((e_f <= exc.e_min_pu) & (d_ef < 0)),
                     0.0, d_ef)
    return jnp.concatenate([
        jnp.stack([
            x2,
            swing_acceleration(x2, t_m, t_e, m.a1, m.a2),
            transient_emf_rate(e_q1, i_d, e_f, m),
            (err - x_ll) / exc.tb_s,
            d_ef,
        ]),
        plant.governor.vector_field(gov, dw, t_ref),
    ])


def _ou(rng, n, dt, std, tau):
    """Ornstein-Uhlenbeck samples (exact discretisation), stationary start."""
    phi = np.exp(-dt / tau)
    noise = rng.standard_normal(n) * std * np.sqrt(1.0 - phi**2)
    out = np.empty(n)
    out[0] = rng.standard_normal() * std
    for k in range(1, n):
        out[k] = phi * out[k - 1] + noise[k]
    return out


def _lag(x, dt, tau):
    """First-order low-pass (exact for piecewise-constant input)."""
    phi = np.exp(-dt / tau)
    out = np.empty_like(x)
    out[0] = x[0]
    for k in range(1, x.shape[0]):
        out[k] = phi * out[k - 1] + (1.0 - phi) * x[k]
    return out


def _grid_signals(sc: Scenario, ts, plant: Plant, e_g0, y_load0):
    rng = np.random.default_rng(sc.seed)
    n, dt = ts.shape[0], 1.0 / sc.frame_rate_hz
    dfreq = _ou(rng, n, dt, sc.ambient_freq_std_hz, sc.ambient_freq_tau_s)
    # Load: OU smoothed by a 0.1 s first-order lag, so bus angles stay differentiable.
    dload = _lag(_ou(rng, n, dt, sc.ambient_load_std, sc.ambient_load_tau_s), dt, 0.1)
    dvolt = _ou(rng, n, dt, sc.ambient_volt_std, sc.ambient_volt_tau_s)
    dfreq -= dfreq[0]
    dload -= dload[0]
    dvolt -= dvolt[0]
    x_g = np.full(n, sc.grid_x_pu)
    y_step = np.zeros(n, dtype=complex)
    rating = float(plant.machine.s_rated_mva / plant.s_base_mva)
    for ev in sc.events:
        on = ts >= ev.time_s
        if ev.kind == "load_step":
            y_step += on * ev.size * rating * (0.95 - 1j * np.sqrt(1 - 0.95**2))
        elif ev.kind == "line_trip":
            x_g = np.where(on, x_g * ev.size, x_g)
        elif ev.kind == "frequency_drop":
            dfreq = dfreq - on * ev.size * np.exp(-np.maximum(ts - ev.time_s, 0.0) / 30.0)
        else:
            raise ValueError(f"unknown event kind {ev.kind!r}")
    theta_g = np.concatenate([[0.0], np.cumsum(np.pi * (dfreq[1:] + dfreq[:-1]) * dt)])
    e_g = e_g0 * (1.0 + dvolt) * np.exp(1j * theta_g)
    return _GridInputs(jnp.asarray(e_g), jnp.asarray(y_load0 * (1.0 + dload) + y_step),
                       jnp.asarray(x_g))


class _OperatingPoint(NamedTuple):
    """The scenario's load-flow data as arrays (traced: one compile for all scenarios)."""

    p_pu: Array
    q_pu: Array
    v_t_pu: Array
    grid_x_pu: Array
    load_p_pu: Array
    load_q_pu: Array


@eqx.filter_jit
def _initial_conditions(op: _OperatingPoint, plant: Plant, exc: Exciter):
    """Load flow: machine (P, Q, V_t) -> aux, transformer, line, load, grid source, states."""
    m = plant.machine
    scale = plant.current_scale
    v_t = op.v_t_pu + 0j
    i_sg = jnp.conj((op.p_pu + 1j * op.q_pu) / v_t) / scale
    i_lv, p_lv = lv_current_from_machine(v_t, i_sg, 0.0, 0, plant.aux)
    v5, i5 = line_to_grid(*transformer_to_hv(v_t, i_lv, plant.transformer), plant.line)
    y_load = (op.load_p_pu - 1j * op.load_q_pu) / jnp.abs(v5) ** 2
    e_g0 = v5 - 1j * op.grid_x_pu * (i5 - y_load * v5)
    alg = jax.tree_util.tree_map(lambda x: x[0], algebraic_observer(
        v_t[None], i_sg[None] * scale, jnp.zeros(1), m))
    delta, e_q1, i_d, t_e = alg.delta_rad, alg.e_q1_pu, alg.i_d_pu, alg.t_e_pu
    e_f = field_voltage(e_q1, 0.0, i_d, m)  # in equilibrium
    v_ref = jnp.abs(v_t) + e_f / exc.k
    t_ref = plant.governor.reference_from_steady(t_e, 0.0)
    gov0 = plant.governor.steady_state(t_ref, 0.0)
    y0 = jnp.concatenate([jnp.stack([delta, 0.0, e_q1, e_f / exc.k, e_f]), gov0])
    return y0, e_g0, y_load, v_ref, t_ref, p_lv


@eqx.filter_jit
def _network_and_truth(plant: Plant, states, v_t, i_sg):
    """Substation phasors and the true trajectories from the integrated states."""
    m = plant.machine
    i_lv = lv_currents(v_t, i_sg, plant.aux)
    v5, i5 = line_to_grid(*transformer_to_hv(v_t, i_lv, plant.transformer), plant.line)
    delta, x2, e_q1, e_f = states[:, 0], states[:, 1], states[:, 2], states[:, 4]
    i_m = i_sg * plant.current_scale
    dq = i_m * jnp.exp(-1j * (delta - jnp.pi / 2))
    t_e = electrical_torque(e_q1, jnp.real(dq), jnp.imag(dq), m)
    t_m = jax.vmap(plant.governor.torque)(states[:, 5:], x2 / m.omega_s)
    truth = Truth(delta_rad=delta, x2_rad_s=x2, e_q1_pu=e_q1, t_e_pu=t_e, t_m_pu=t_m,
                  e_f_pu=e_f, v_t=v_t, i_sg=i_sg, a1=m.a1, a2=m.a2)
    return v5, i5, truth


def _frequency(theta, dt, f0):
    """Bus frequency from the unwrapped angle by a 4th-order central difference."""
    d = np.gradient(theta, dt)
    d[2:-2] = (theta[:-4] - 8 * theta[1:-3] + 8 * theta[3:-1] - theta[4:]) / (12 * dt)
    return f0 + d / (2 * np.pi)


def simulate(plant: Plant, scenario: Scenario, exciter: Exciter = Exciter(),
             integrator: Integrator = Integrator(rtol=1e-8, atol=1e-10, max_substeps=1024),
             ) -> Simulation:
    """Simulate the plant and return a substation PMU recording with its ground truth."""
    sc = scenario
    n = int(round(sc.duration_s * sc.frame_rate_hz)) + 1
    ts_np = np.arange(n) / sc.frame_rate_hz
    op = _OperatingPoint(*(jnp.asarray(float(x)) for x in (
        sc.p_pu, sc.q_pu, sc.v_t_pu, sc.grid_x_pu, sc.load_p_pu, sc.load_q_pu)))
    y0, e_g0, y_load0, v_ref, t_ref, p_lv0 = _initial_conditions(op, plant, exciter)
    grid = _grid_signals(sc, ts_np, plant, complex(e_g0), complex(y_load0))
    states, v_t, i_sg, ok = _run(plant, exciter, v_ref, t_ref, y0, p_lv0, jnp.asarray(ts_np), grid,
                                 integrator)
    if not bool(ok):
        raise RuntimeError("plant simulation failed (solver step limit); check the scenario")
    v5, i5, truth = _network_and_truth(plant, states, v_t, i_sg)
    return _measure(sc, ts_np, np.asarray(v5), np.asarray(i5), float(plant.machine.f_nominal_hz), truth)


@eqx.filter_jit
def _run(plant, exc, v_ref, t_ref, y0, p_lv0, ts, grid: _GridInputs, integ: Integrator):
    """Sample-by-sample integration; the aux load uses the mean LV power of past samples."""

    def lv_power(v_t, i_sg, mean):
        return jnp.real(v_t * jnp.conj(i_sg - aux_current(v_t, mean, plant.aux)))

    # Sample 0: the causal mean is P_LV(0) itself, known from the load flow.
    v0, i0, _, _ = _solve_network(y0[0], y0[2], jax.tree_util.tree_map(lambda x: x[0], grid),
                                  p_lv0, plant)

    def step(carry, xs):
        y, sum_p, k = carry
        t0, t1, u0, u1 = xs
        mean = sum_p / k  # mean LV power of samples 0..k-1, used for sample k
        y1, ok, _ = solve_interval(_rhs, y, t0, t1, u0, u1, (plant, exc, v_ref, t_ref, mean), integ)
        v1, i1, _, _ = _solve_network(y1[0], y1[2], u1, mean, plant)
        return (y1, sum_p + lv_power(v1, i1, mean), k + 1), (y1, v1, i1, ok)

    u0 = jax.tree_util.tree_map(lambda x: x[:-1], grid)
    u1 = jax.tree_util.tree_map(lambda x: x[1:], grid)
    init = (y0, lv_power(v0, i0, p_lv0), jnp.asarray(1.0))
    _, (ys, vs, iss, oks) = jax.lax.scan(step, init, (ts[:-1], ts[1:], u0, u1))
    states = jnp.concatenate([y0[None], ys])
    return states, jnp.concatenate([v0[None], vs]), jnp.concatenate([i0[None], iss]), jnp.all(oks)


def _measure(sc: Scenario, ts, v5, i5, f0, truth: Truth) -> Simulation:
    """PMU: positive sequence at the substation with TVE noise, frequency, three phases."""
    rng = np.random.default_rng(sc.seed + 1_000_003)
    n = ts.shape[0]
    theta = np.unwrap(np.angle(v5))
    f_true = _frequency(theta, 1.0 / sc.frame_rate_hz, f0)

    def noisy(x):
        std = sc.tve_percent / 100.0 / np.sqrt(2.0) * np.abs(x)
        return x + std * (rng.standard_normal(n) + 1j * rng.standard_normal(n))

    v_n, i_n = noisy(v5), noisy(i5)
    f_n = f_true + sc.freq_noise_hz * rng.standard_normal(n)
    neg = sc.unbalance * np.exp(1j * rng.uniform(0, 2 * np.pi))
    v_abc = phases_from_sequences(0 * v_n, v_n, neg * v_n)
    i_abc = phases_from_sequences(0 * i_n, i_n, neg * i_n)

    def rec(v, i, f):
        return Recording(t_s=ts, v_mag_pu=np.abs(v), v_ang_rad=np.unwrap(np.angle(v)),
                         i_mag_pu=np.abs(i), i_ang_rad=np.unwrap(np.angle(i)), f_hz=f,
                         location="substation")

    return Simulation(recording=rec(v_n, i_n, f_n), v_abc=v_abc, i_abc=i_abc, truth=truth,
                      clean=rec(v5, i5, f_true))
