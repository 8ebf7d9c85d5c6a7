"""Mapping substation PMU phasors to the machine terminal (paper Sec. III, Eqs. 8-13).

All phasors are complex, on the **system base**, in generator convention: every current
flows from the plant towards the grid. Stages, from the grid side to the machine:

1. HV line, pi model (series Z, total shunt Y), substation (bus 5) -> transformer HV side (bus 4).
2. Tap-changing transformer, T model: ideal tap n = (1 + tau) e^{j phi} on the HV side, then
   the HV winding (r_HV + j x_HV), the magnetising branch (r_Fe parallel j x_M) and the LV
   winding (r_LV + j x_LV) -> LV bus (bus 3).
3. Auxiliary system at the LV bus: P_AS = P_AS,max / (P_SG,max - P_AS,max) * mean(P_LV),
   Q_AS = P_AS tan(arccos pf); I_SG = I_LV + I_AS with I_AS = conj(S_AS / V_LV).

The running mean is the left-rectangle rule of the paper's (1/(t-t0)) int_{t0}^{t} P_LV:
the mean of the samples before the current one (the first sample uses itself). It is
causal, so the forward map (:func:`map_to_terminal`) and its inverse
(:func:`map_to_measurement`, used by the simulator) are exact inverses of each other.

Each stage is a linear two-port except the auxiliary load; the maps are equivariant under
a common rotation of all phasors, so callers may work in any rotating reference frame.
"""

from __future__ import annotations

from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Complex, Float

from .._base.fields import as_float, check_nonnegative, check_positive, concrete
from .xla import hoist

Location = Literal["substation", "hv", "terminal"]
LOCATIONS = ("substation", "hv", "terminal")


class Line(eqx.Module):
    """HV line between the transformer HV bus and the substation, pi model [pu, system base]."""

    r_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0005)
    """Series resistance [pu]."""
    x_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.005)
    """Series reactance [pu]."""
    g_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Total shunt conductance [pu]."""
    b_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Total shunt susceptance [pu] (half at each end)."""

    def __check_init__(self):
        check_nonnegative(self, "r_pu", "x_pu", "g_pu", "b_pu")

    @property
    def z(self):
        return self.r_pu + 1j * self.x_pu

    @property
    def y(self):
        return self.g_pu + 1j * self.b_pu


class Transformer(eqx.Module):
    """Step-up transformer, T model with ideal tap changer on the HV side [pu, system base]."""

    r_hv_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0002)
    """HV winding resistance r_Cu^HV [pu]."""
    x_hv_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.007)
    """HV leakage reactance x_sigma^HV [pu]."""
    r_lv_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0002)
    """LV winding resistance r_Cu^LV [pu]."""
    x_lv_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.007)
    """LV leakage reactance x_sigma^LV [pu]."""
    r_fe_pu: Float[Array, ""] = eqx.field(converter=as_float, default=500.0)
    """Iron-loss resistance r_Fe [pu] (parallel to x_M)."""
    x_m_pu: Float[Array, ""] = eqx.field(converter=as_float, default=200.0)
    """Magnetising reactance x_M [pu]."""
    tap_step: Float[Array, ""] = eqx.field(converter=as_float, default=0.0125)
    """Voltage change per tap step [pu of rated ratio]."""
    tap_position: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Tap position (signed number of steps); tau = tap_step * tap_position."""
    phase_shift_rad: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Phase shift phi of the ideal transformer [rad]."""

    def __check_init__(self):
        check_nonnegative(self, "r_hv_pu", "x_hv_pu", "r_lv_pu", "x_lv_pu", "tap_step")
        check_positive(self, "r_fe_pu", "x_m_pu")
        tau = self.tap_step * self.tap_position
        if concrete(tau) and not bool(jnp.all(jnp.abs(tau) < 0.5)):
            raise ValueError(f"Transformer tap out of range: tau = {tau} (|tau| must be < 0.5)")

    @property
    def ratio(self):
        """Complex ratio n = (1 + tau) e^{j phi} of the ideal tap transformer."""
        return (1.0 + self.tap_step * self.tap_position) * jnp.exp(1j * self.phase_shift_rad)

    @property
    def y_m(self):
        """Magnetising admittance 1/r_Fe + 1/(j x_M)."""
        return 1.0 / self.r_fe_pu - 1j / self.x_m_pu


class AuxiliarySystem(eqx.Module):
    """Auxiliary-system load of the power plant at the LV bus (paper Eq. 11)."""

    p_as_max_mw: Float[Array, ""] = eqx.field(converter=as_float, default=50.0)
    """Maximum auxiliary consumption P_AS,max [MW]."""
    p_sg_max_mw: Float[Array, ""] = eqx.field(converter=as_float, default=1000.0)
    """Maximum generation P_SG,max [MW]."""
    power_factor: Float[Array, ""] = eqx.field(converter=as_float, default=0.85)
    """Power factor of the auxiliary load (lagging) [-]."""

    def __check_init__(self):
        check_nonnegative(self, "p_as_max_mw")
        check_positive(self, "p_sg_max_mw", "power_factor")
        if concrete(self.power_factor) and not bool(jnp.all(self.power_factor <= 1.0)):
            raise ValueError(f"AuxiliarySystem.power_factor must be in (0, 1], got {self.power_factor}")

    @property
    def kappa(self):
        """P_AS / mean(P_LV) = P_AS,max / (P_SG,max - P_AS,max)."""
        return self.p_as_max_mw / (self.p_sg_max_mw - self.p_as_max_mw)

    @property
    def q_over_p(self):
        """Q_AS / P_AS = tan(arccos pf)."""
        return jnp.sqrt(1.0 - self.power_factor**2) / self.power_factor


class MappedPhasors(eqx.Module):
    """Phasors at the LV bus and the machine terminal [pu, system base]."""

    v_t: Complex[Array, " T"]
    """Terminal (= LV bus) voltage."""
    i_lv: Complex[Array, " T"]
    """Current from the LV bus into the transformer."""
    i_sg: Complex[Array, " T"]
    """Machine terminal current I_SG = I_LV + I_AS."""
    p_lv: Float[Array, " T"]
    """Active power at the LV bus, the input of the auxiliary load's running mean."""


# --- Two-port stages ------------------------------------------------------------------------

def line_to_plant(v5, i5, line: Line):
    """Substation (bus 5) -> transformer HV bus (bus 4), paper Eq. 8 with I5 = -I_PMU."""
    y_half, z = hoist(0.5 * line.y, line.z)
    i_series = i5 + y_half * v5
    v4 = v5 + z * i_series
    return v4, i_series + y_half * v4


def line_to_grid(v4, i4, line: Line):
    """Inverse of :func:`line_to_plant`."""
    i_series = i4 - 0.5 * line.y * v4
    v5 = v4 - line.z * i_series
    return v5, i_series - 0.5 * line.y * v5


def transformer_to_lv(v_hv, i_hv, tr: Transformer):
    """Transformer HV side -> LV bus (paper Eq. 9, derived for the generator convention)."""
    inv_n, conj_n, z_hv, y_m, z_lv = hoist(1.0 / tr.ratio, jnp.conj(tr.ratio), tr.r_hv_pu + 1j * tr.x_hv_pu,
                                           tr.y_m, tr.r_lv_pu + 1j * tr.x_lv_pu)
    v_inner, i_inner = v_hv * inv_n, i_hv * conj_n
    v_m = v_inner + z_hv * i_inner
    i_lv = i_inner + y_m * v_m
    return v_m + z_lv * i_lv, i_lv


def transformer_to_hv(v_lv, i_lv, tr: Transformer):
    """Inverse of :func:`transformer_to_lv`."""
    v_m = v_lv - (tr.r_lv_pu + 1j * tr.x_lv_pu) * i_lv
    i_inner = i_lv - tr.y_m * v_m
    v_inner = v_m - (tr.r_hv_pu + 1j * tr.x_hv_pu) * i_inner
    n = tr.ratio
    return n * v_inner, i_inner / jnp.conj(n)


def aux_current(v_lv, mean_p_lv, aux: AuxiliarySystem):
    """Current drawn by the auxiliary system, I_AS = conj(S_AS / V_LV) (paper Eqs. 11-12)."""
    kappa, q_over_p = hoist(aux.kappa, aux.q_over_p)
    s_as = kappa * mean_p_lv * (1.0 + 1j * q_over_p)
    return jnp.conj(s_as) * v_lv * (1.0 / (jnp.real(v_lv) ** 2 + jnp.imag(v_lv) ** 2))


def causal_mean(p, sum0=0.0, n0=0):
    """Mean of the samples before each one (the first sample uses itself), along axis 0.

    ``sum0`` and ``n0`` are the sum and count of earlier samples when a stream continues.
    """
    n = n0 + jnp.arange(p.shape[0], dtype=p.real.dtype)
    prev = sum0 + jnp.concatenate([jnp.zeros_like(p[:1]), jnp.cumsum(p)[:-1]])
    return jnp.where(n > 0, prev / jnp.maximum(n, 1.0), p)


# --- Whole maps -----------------------------------------------------------------------------

def map_to_terminal(v, i, line: Line, transformer: Transformer, aux: AuxiliarySystem,
                    location: Location = "substation", mean_sum0=0.0, mean_n0=0) -> MappedPhasors:
    """Measured phasors (V, I towards the grid) at ``location`` -> machine terminal.

    ``location`` (static) skips stages: "substation" maps through line, transformer and
    auxiliary load; "hv" through transformer and auxiliary load; "terminal" maps nothing
    (the measured current is then the machine current). ``mean_sum0`` and ``mean_n0``
    continue the running mean of P_LV of a stream (:func:`causal_mean`).
    """
    if location == "terminal":
        return MappedPhasors(v_t=v, i_lv=i, i_sg=i, p_lv=jnp.real(v * jnp.conj(i)))
    if location == "substation":
        v, i = line_to_plant(v, i, line)
    elif location != "hv":
        raise ValueError(f"unknown measurement location {location!r}; use one of {LOCATIONS}")
    v_lv, i_lv = transformer_to_lv(v, i, transformer)
    p_lv = jnp.real(v_lv * jnp.conj(i_lv))
    i_as = aux_current(v_lv, causal_mean(p_lv, mean_sum0, mean_n0), aux)
    return MappedPhasors(v_t=v_lv, i_lv=i_lv, i_sg=i_lv + i_as, p_lv=p_lv)


def lv_current_from_machine(v_t, i_sg, sum_p_lv, n, aux: AuxiliarySystem):
    """One step of the inverse auxiliary map: I_LV from I_SG given the past P_LV samples.

    ``sum_p_lv`` is the sum of the ``n`` previous LV active powers. For n = 0 the mean is the
    current sample, solved in closed form: P_LV = P_SG / (1 + kappa).
    """
    p_sg = jnp.real(v_t * jnp.conj(i_sg))
    mean = jnp.where(n > 0, sum_p_lv / jnp.maximum(n, 1), p_sg / (1.0 + aux.kappa))
    i_lv = i_sg - aux_current(v_t, mean, aux)
    return i_lv, jnp.real(v_t * jnp.conj(i_lv))


def lv_currents(v_t, i_sg, aux: AuxiliarySystem):
    """The inverse auxiliary map over a recording: I_LV per sample from the machine current
    I_SG, each sample's auxiliary load using the mean LV power of the samples before it."""

    def step(carry, x):
        sum_p, n = carry
        i_lv, p_lv = lv_current_from_machine(x[0], x[1], sum_p, n, aux)
        return (sum_p + p_lv, n + 1), i_lv

    zero = jnp.zeros((), dtype=jnp.real(v_t).dtype)
    return jax.lax.scan(step, (zero, zero), (v_t, i_sg))[1]


def map_to_measurement(v_t, i_sg, line: Line, transformer: Transformer, aux: AuxiliarySystem,
                       location: Location = "substation"):
    """Inverse of :func:`map_to_terminal`: machine terminal (V_t, I_SG) -> (V, I) at ``location``."""
    if location == "terminal":
        return v_t, i_sg
    if location not in LOCATIONS:
        raise ValueError(f"unknown measurement location {location!r}; use one of {LOCATIONS}")
    v, i = transformer_to_hv(v_t, lv_currents(v_t, i_sg, aux), transformer)
    if location == "substation":
        v, i = line_to_grid(v, i, line)
    return v, i
