"""Governor-turbine models giving the mechanical torque Tm from a speed signal.

The paper uses 50Hertz's in-house power-control governor (its Fig. 2), which is not
published; jaxdse ships the standard PSS/E models TGOV1 (steam), IEEEG1 (IEEE type 1
steam), GAST (gas turbine), HYGOV (hydro), GGOV1 (general purpose), IEESGO (IEEE standard
steam) and WSIEG1 (WECC's IEEEG1 with deadbands and valve characteristic) (Siemens PTI,
*PSS/E Model Library*; IEEE PES-TR1, 2013). New models subclass :class:`AbstractGovernor`.

Conventions of every model but TGOV1 (PSS/E behaviour):

* ``t_ref`` is the model's own reference input, as PSS/E names it: the load reference
  (IEEEG1 ``Po``, GAST and GGOV1 ``Pref``) or, for HYGOV, the speed reference ``Nref``;
  ``reference_from_steady`` finds it from the steady Tm. Speed deviations are in pu of
  nominal speed (``dw = x2 / w_s``); powers equal torques in pu.
* a first-order lag ``1/(1 + sT)`` with ``T = 0`` is a pass-through; a lead-lag
  ``(1 + sTa)/(1 + sTb)`` with ``Tb = 0`` is a pass-through. The state of a bypassed block
  is kept (zero derivative), so that one state layout serves every parameter set under vmap.
* non-windup limits block the derivative that would push a state further out (as TGOV1);
  downstream blocks see the state clipped to its limits.
* no Python branching on array values: ``jnp.where`` everywhere, with the denominators of
  bypassed blocks replaced by 1 so that neither value nor gradient is NaN.

Sources: Siemens PTI *PSS(R)E Model Library* (each model); IEEE PES-TR1 (2013); for the
structure only, the BSD-3 implementations PowerSimulationsDynamics.jl (GAST, HYGOV) and
OpenIPSL (IEEEG1, GAST, HYGOV, GGOV1), and PowerWorld's GGOV1 notes.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._base.blocks import blocked as _blocked
from .._base.blocks import lag as _lag
from .._base.blocks import lead_lag as _lead_lag
from .._base.blocks import safe as _safe
from .._base.blocks import washout as _washout
from .._base.fields import (
    all_concrete,
    as_flag,
    as_float,
    check_flag,
    check_nonnegative,
    check_positive,
    check_that,
    concrete,
)


class AbstractGovernor(eqx.Module):
    """A governor-turbine: states driven by the speed deviation dw [pu] and a torque reference."""

    @abc.abstractmethod
    def steady_state(self, t_ref, dw):
        """State in equilibrium with reference ``t_ref`` [pu] and speed deviation ``dw`` [pu]."""

    @abc.abstractmethod
    def vector_field(self, state, dw, t_ref):
        """d(state)/dt."""

    @abc.abstractmethod
    def torque(self, state, dw):
        """Mechanical torque Tm [pu, machine base]."""

    @abc.abstractmethod
    def reference_from_steady(self, t_m, dw):
        """Torque reference T_ref that holds Tm = ``t_m`` at speed deviation ``dw`` in steady state."""


class TGOV1(AbstractGovernor):
    """PSS/E TGOV1: valve 1/(1 + s T1) with non-windup limits, turbine (1 + s T2)/(1 + s T3), Dt.

    Tm = LL[valve] - Dt dw, valve = clip((T_ref - dw/R) / (1 + s T1), v_min, v_max).
    """

    r_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Permanent droop R [pu speed / pu power]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """Valve time constant T1 [s]."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """Turbine lead time constant T2 [s]."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """Turbine lag (reheater) time constant T3 [s]."""
    dt_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Turbine damping Dt [pu power / pu speed]."""
    v_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.2)
    """Upper valve limit [pu]."""
    v_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Lower valve limit [pu]."""

    def __check_init__(self):
        check_positive(self, "r_pu", "t1_s", "t3_s")
        check_nonnegative(self, "t2_s", "dt_pu")

    def steady_state(self, t_ref, dw):
        valve = jnp.clip(t_ref - dw / self.r_pu, self.v_min_pu, self.v_max_pu)
        return jnp.stack([valve, valve])

    def vector_field(self, state, dw, t_ref):
        valve, lag = state[0], state[1]
        d_valve = (t_ref - dw / self.r_pu - valve) / self.t1_s
        return jnp.stack([_blocked(valve, d_valve, self.v_min_pu, self.v_max_pu), (valve - lag) / self.t3_s])

    def torque(self, state, dw):
        valve, lag = state[0], state[1]
        return lag + (self.t2_s / self.t3_s) * (valve - lag) - self.dt_pu * dw

    def reference_from_steady(self, t_m, dw):
        return t_m + (1.0 / self.r_pu + self.dt_pu) * dw


HEAD_GATE_FLOOR = 1e-4
"""HYGOV: the gate opening in the head equation h = (q/g)^2 is floored at this value [pu]."""


# --- IEEEG1 -----------------------------------------------------------------------------------

class IEEEG1(AbstractGovernor):
    """PSS/E IEEEG1, the IEEE type 1 steam turbine-governor (single-shaft use).

    Block diagram (Siemens PTI *PSS/E Model Library*, "IEEEG1"; IEEE PES-TR1 2013, Fig. 2-2;
    IEEE Committee Report 1973/1991):

        LL   = K (1 + s T2)/(1 + s T1) dw                           (speed relay lead-lag)
        dGV  = clip((Po - LL - GV)/T3, Uc, Uo)                      (rate limits Uc < 0 < Uo)
        GV   = 1/s dGV, non-windup limits [PMIN, PMAX]              (valve position)
        x4 = GV/(1 + sT4), x5 = x4/(1 + sT5), x6 = x5/(1 + sT6), x7 = x6/(1 + sT7)
        Tm = PMECH_HP = K1 x4 + K3 x5 + K5 x6 + K7 x7

    States: [LL lead-lag state, GV, x4, x5, x6, x7]. ``t_ref`` is Po.

    Single shaft: the low-pressure shaft output PMECH_LP = K2 x4 + K4 x5 + K6 x6 + K8 x7 drives
    a second machine (ICONs JBUS, M) in a cross-compound unit; for one machine it is ignored
    (K2, K4, K6, K8 are kept as fields for the record only). For a tandem-compound unit the
    data put all fractions in K1, K3, K5, K7 (summing to 1). T1 = 0 makes the lead-lag a gain K
    (T2 ignored, PSS/E treats the block as bypassed); T4..T7 = 0 are pass-throughs.
    """

    k: Float[Array, ""] = eqx.field(converter=as_float, default=20.0)
    """K: governor gain, the reciprocal of the droop [pu power / pu speed]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T1: governor lag time constant [s] (0: no lead-lag)."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T2: governor lead time constant [s]."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """T3: valve positioner time constant [s] (> 0)."""
    uo_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Uo: maximum valve opening rate [pu/s] (> 0)."""
    uc_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-0.1)
    """Uc: maximum valve closing rate [pu/s] (< 0)."""
    p_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """PMAX: maximum valve opening [pu, machine base]."""
    p_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PMIN: minimum valve opening [pu, machine base]."""
    t4_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """T4: steam bowl (inlet) time constant [s]."""
    k1: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """K1: fraction of HP shaft power after the bowl (T4) [-]."""
    k2: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K2: fraction of LP shaft power after T4 [-] (ignored: single shaft)."""
    t5_s: Float[Array, ""] = eqx.field(converter=as_float, default=7.0)
    """T5: reheater time constant [s]."""
    k3: Float[Array, ""] = eqx.field(converter=as_float, default=0.4)
    """K3: fraction of HP shaft power after the reheater (T5) [-]."""
    k4: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K4: fraction of LP shaft power after T5 [-] (ignored: single shaft)."""
    t6_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.6)
    """T6: crossover time constant [s]."""
    k5: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """K5: fraction of HP shaft power after T6 [-]."""
    k6: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K6: fraction of LP shaft power after T6 [-] (ignored: single shaft)."""
    t7_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T7: double reheat time constant [s]."""
    k7: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K7: fraction of HP shaft power after T7 [-]."""
    k8: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K8: fraction of LP shaft power after T7 [-] (ignored: single shaft)."""

    def __check_init__(self):
        check_positive(self, "t3_s", "uo_pu_s")
        check_nonnegative(self, "k", "t1_s", "t2_s", "t4_s", "t5_s", "t6_s", "t7_s",
                          "k1", "k3", "k5", "k7")
        if all_concrete(self.uc_pu_s, self.p_max_pu, self.p_min_pu, self.k1, self.k3, self.k5, self.k7):
            check_that(self, self.uc_pu_s < 0, f"Uc must be < 0, got {self.uc_pu_s}")
            check_that(self, self.p_max_pu >= self.p_min_pu,
                   f"PMAX ({self.p_max_pu}) must be >= PMIN ({self.p_min_pu})")
            check_that(self, self.k_hp > 0, "K1 + K3 + K5 + K7 must be > 0 (single-shaft output)")

    @property
    def k_hp(self):
        """K1 + K3 + K5 + K7: the steady-state gain from valve position to Tm."""
        return self.k1 + self.k3 + self.k5 + self.k7

    def _speed_relay(self, x_ll, dw):
        y, d = _lead_lag(dw, x_ll, self.t2_s, self.t1_s)
        return self.k * y, d

    def _turbine(self, state):
        gv = jnp.clip(state[1], self.p_min_pu, self.p_max_pu)
        y4, d4 = _lag(gv, state[2], self.t4_s)
        y5, d5 = _lag(y4, state[3], self.t5_s)
        y6, d6 = _lag(y5, state[4], self.t6_s)
        y7, d7 = _lag(y6, state[5], self.t7_s)
        return (y4, y5, y6, y7), (d4, d5, d6, d7)

    def steady_state(self, t_ref, dw):
        gv = jnp.clip(t_ref - self.k * dw, self.p_min_pu, self.p_max_pu)
        return jnp.stack([jnp.asarray(dw, float) + 0.0 * gv, gv, gv, gv, gv, gv])

    def vector_field(self, state, dw, t_ref):
        ll, d_ll = self._speed_relay(state[0], dw)
        gv = state[1]
        d_gv = jnp.clip((t_ref - ll - gv) / self.t3_s, self.uc_pu_s, self.uo_pu_s)
        d_gv = _blocked(gv, d_gv, self.p_min_pu, self.p_max_pu)
        _, (d4, d5, d6, d7) = self._turbine(state)
        return jnp.stack([d_ll, d_gv, d4, d5, d6, d7])

    def torque(self, state, dw):
        (y4, y5, y6, y7), _ = self._turbine(state)
        return self.k1 * y4 + self.k3 * y5 + self.k5 * y6 + self.k7 * y7

    def reference_from_steady(self, t_m, dw):
        return t_m / self.k_hp + self.k * dw


# --- GAST -------------------------------------------------------------------------------------

class GAST(AbstractGovernor):
    """PSS/E GAST, the gas turbine-governor with a load (exhaust-temperature) limit.

    Block diagram (Siemens PTI *PSS/E Model Library*, "GAST"; IEEE PES-TR1 2013, Fig. 3-1;
    same structure in PowerSimulationsDynamics.jl ``GasTG`` and OpenIPSL ``GAST``):

        x_in = min(Pref - dw/R, AT + KT (AT - x3))                  (low-value select)
        x1   = x_in/(1 + s T1), non-windup limits [VMIN, VMAX]      (fuel valve)
        x2   = x1/(1 + s T2)                                        (fuel flow / combustion)
        x3   = x2/(1 + s T3)                                        (exhaust temperature)
        Tm   = x2 - DTURB dw

    States: [x1, x2, x3]. ``t_ref`` is Pref. The steady state is
    x1 = x2 = x3 = clip(min(Pref - dw/R, AT), VMIN, VMAX) (for KT >= 0 the load-limit branch
    is AT + KT (AT - x) >= x exactly when x <= AT). T2 = 0 or T3 = 0 is a pass-through.
    """

    r_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """R: permanent droop [pu speed / pu power]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.4)
    """T1: fuel valve time constant [s] (> 0)."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """T2: fuel system (combustion) time constant [s]."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """T3: load-limit (exhaust temperature measurement) time constant [s]."""
    at_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """AT: ambient temperature load limit [pu, machine base]."""
    kt_pu: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """KT: load-limit feedback gain [-]."""
    v_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """VMAX: maximum fuel valve opening [pu]."""
    v_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """VMIN: minimum fuel valve opening [pu]."""
    dturb_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """DTURB: turbine damping [pu power / pu speed]."""

    def __check_init__(self):
        check_positive(self, "r_pu", "t1_s")
        check_nonnegative(self, "t2_s", "t3_s", "kt_pu", "dturb_pu")
        if all_concrete(self.v_max_pu, self.v_min_pu):
            check_that(self, self.v_max_pu >= self.v_min_pu,
                   f"VMAX ({self.v_max_pu}) must be >= VMIN ({self.v_min_pu})")

    def steady_state(self, t_ref, dw):
        x = jnp.clip(jnp.minimum(t_ref - dw / self.r_pu, self.at_pu), self.v_min_pu, self.v_max_pu)
        return jnp.stack([x, x, x])

    def vector_field(self, state, dw, t_ref):
        x1 = state[0]
        y2, d2 = _lag(self._valve(state), state[1], self.t2_s)
        y3, d3 = _lag(y2, state[2], self.t3_s)
        x_in = jnp.minimum(t_ref - dw / self.r_pu, self.at_pu + self.kt_pu * (self.at_pu - y3))
        d1 = _blocked(x1, (x_in - x1) / self.t1_s, self.v_min_pu, self.v_max_pu)
        return jnp.stack([d1, d2, d3])

    def _valve(self, state):
        return jnp.clip(state[0], self.v_min_pu, self.v_max_pu)

    def torque(self, state, dw):
        y2, _ = _lag(self._valve(state), state[1], self.t2_s)
        return y2 - self.dturb_pu * dw

    def reference_from_steady(self, t_m, dw):
        return t_m + (1.0 / self.r_pu + self.dturb_pu) * dw


# --- HYGOV ------------------------------------------------------------------------------------

class HYGOV(AbstractGovernor):
    """PSS/E HYGOV, the hydro turbine-governor with a nonlinear (inelastic) water column.

    Block diagram (Siemens PTI *PSS/E Model Library*, "HYGOV"; IEEE PES-TR1 2013, Fig. 4-3;
    same structure in OpenIPSL ``HYGOV`` and PowerSimulationsDynamics.jl ``HydroTurbineGov``):

        e    = Nref - dw - R c                                      (permanent droop on c)
        x1   = e/(1 + s Tf)                                         (filter)
        v    = clip((1 + s Tr)/(r Tr) x1, -VELM, VELM)              (temporary droop, gate velocity)
        c    = 1/s v, non-windup limits [GMIN, GMAX]                (desired gate)
        g    = c/(1 + s Tg)                                         (gate servo)
        h    = (q/g)^2,  dq/dt = (1 - h)/TW                         (water column, head h0 = 1)
        Tm   = At h (q - qNL) - DTURB dw g

    States: [x1, c, g, q]. ``t_ref`` is the speed reference Nref = R c0 + dw0. The lead
    (1 + sTr) of the filtered error uses dx1/dt, so Tf > 0 is required (PSS/E needs it too).
    Tg = 0 makes the servo a pass-through (g = c); TW = 0 removes the water inertia (q = g,
    h = 1). Near a closed gate, g in h = (q/g)^2 is floored at ``HEAD_GATE_FLOOR`` (1e-4 pu)
    so the head and its gradient stay finite; above that floor the model is exact. (A
    steady state with the gate closed below the floor keeps q = 1e-4, h = 1.)
    """

    r_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """R: permanent droop [pu speed / pu gate]."""
    r_temp_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """r: temporary droop [pu speed / pu gate] (> 0)."""
    tr_s: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """Tr: governor (dashpot reset) time constant [s] (> 0)."""
    tf_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Tf: filter time constant [s] (> 0)."""
    tg_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """Tg: gate servo time constant [s]."""
    velm_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """VELM: gate velocity limit [pu/s] (> 0)."""
    g_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """GMAX: maximum gate opening [pu]."""
    g_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """GMIN: minimum gate opening [pu]."""
    tw_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """TW: water inertia time constant [s]."""
    at_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.2)
    """At: turbine gain [pu power / pu flow] (> 0)."""
    dturb_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """DTURB: turbine damping [pu power / (pu speed pu gate)]."""
    q_nl_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.08)
    """qNL: no-load water flow [pu]."""

    def __check_init__(self):
        check_positive(self, "r_pu", "r_temp_pu", "tr_s", "tf_s", "velm_pu_s", "at_pu")
        check_nonnegative(self, "tg_s", "tw_s", "dturb_pu", "q_nl_pu")
        if all_concrete(self.g_max_pu, self.g_min_pu):
            check_that(self, self.g_max_pu >= self.g_min_pu,
                   f"GMAX ({self.g_max_pu}) must be >= GMIN ({self.g_min_pu})")

    def _hydraulics(self, state):
        """(gate g, flow q, head h) from the states, bypassed blocks resolved."""
        g, d_g = _lag(jnp.clip(state[1], self.g_min_pu, self.g_max_pu), state[2], self.tg_s)
        q = jnp.where(self.tw_s > 0, state[3], g)
        h = (q / jnp.maximum(g, HEAD_GATE_FLOOR)) ** 2
        return g, q, h, d_g

    def steady_state(self, t_ref, dw):
        c = jnp.clip((t_ref - dw) / self.r_pu, self.g_min_pu, self.g_max_pu)
        x1 = t_ref - dw - self.r_pu * c
        return jnp.stack([x1, c, c, jnp.maximum(c, HEAD_GATE_FLOOR)])

    def vector_field(self, state, dw, t_ref):
        x1, c = state[0], state[1]
        e = t_ref - dw - self.r_pu * jnp.clip(c, self.g_min_pu, self.g_max_pu)
        d1 = (e - x1) / self.tf_s
        v = jnp.clip((x1 + self.tr_s * d1) / (self.r_temp_pu * self.tr_s), -self.velm_pu_s, self.velm_pu_s)
        d_c = _blocked(c, v, self.g_min_pu, self.g_max_pu)
        g, q, h, d_g = self._hydraulics(state)
        d_q = jnp.where(self.tw_s > 0, (1.0 - h) / _safe(self.tw_s), 0.0)
        return jnp.stack([d1, d_c, d_g, d_q])

    def torque(self, state, dw):
        g, q, h, _ = self._hydraulics(state)
        return self.at_pu * h * (q - self.q_nl_pu) - self.dturb_pu * dw * g

    def reference_from_steady(self, t_m, dw):
        g = (t_m + self.at_pu * self.q_nl_pu) / (self.at_pu - self.dturb_pu * dw)
        return self.r_pu * g + dw


# --- GGOV1 ------------------------------------------------------------------------------------

class GGOV1(AbstractGovernor):
    """PSS/E GGOV1, the GE general-purpose governor-turbine (gas, combined-cycle, diesel, ...).

    Block diagram: Siemens PTI *PSS/E Model Library*, "GGOV1" (GE General Governor/Turbine
    Model); IEEE PES-TR1 2013, Sec. 3.1.2.3 and its GGOV1 figure; PowerWorld "GGOV1" notes;
    cross-checked against OpenIPSL ``GGOV1`` (BSD-3, verified against PSS/E). All signals are
    on the governor base (Trate when > 0, else the machine base; ``base_ratio`` = Trate/MBASE
    converts Tm and Pelec); ``t_ref`` is Pref.

    Governor (PID with droop feedback selected by Rselect)::

        Pe_m  = Pelec/(1 + s Tpelec)
        fb    = Pe_m (Rselect = 1) | FSR (-1, requested stroke) | valve stroke s3 (-2)
        err   = clip(Pref - dw - R fb, minerr, maxerr)
        FSRN  = Kpgov err + xi + Kdgov s/(1 + s Tdgov) err
        dxi/dt = Kigov err + (Kigov/Kpgov)(FSR - FSRN)          (integral with reset tracking)

    Load (exhaust temperature) limiter::

        texm  = [wf (1 + dw)^min(Dm, 0)] (1 + s Tsa)/(1 + s Tsb) / (1 + s Tfload)
        tlim  = Ldref/Kturb + Wfnl
        FSRT  = Kpload (tlim - texm) + xl
        dxl/dt = Kiload (tlim - texm) + (Kiload/Kpload)(FSR - FSRT)

    Acceleration limiter (PSS/E's discrete form ``FSRA = FSR(t - DELT) + Ka DELT (Aset - a)``)::

        a     = s/(1 + s Ta) dw
        FSRA  = q + Ka DELT (Aset - a),   dq/dt = (FSR - q)/DELT    (q: FSR one step back)

    Low-value select and turbine::

        FSR   = clip(min(FSRN, FSRT, FSRA), Vmin, Vmax)
        ds3/dt = clip((FSR - s3)/Tact, Rclose, Ropen)               (valve stroke s3)
        wf    = s3 (1 + dw if Flag = 1 else 1)                      (fuel flow)
        Pm    = (1 + s Tc)/(1 + s Tb) [Kturb (e^{-s Teng} wf - Wfnl)] - Dm dw (Dm > 0)
        Tm    = base_ratio Pm

    States: [Pe_m, derivative filter, xi, q, s3, Teng Pade state, turbine lead-lag,
    temperature lead-lag, Tfload lag, xl, acceleration filter].

    Simplifications and assumptions (explicit):

    * Pelec, the measured electrical power, is not an input of jaxdse's governor interface:
      ``vector_field`` takes it as the optional keyword ``p_elec`` [pu, machine base] and
      otherwise uses the model's own Pm (exact in the steady state, where Pelec = Pm).
    * The supervisory load controller (Kimw, Pmwset, +-1.1 R limits) is not represented
      (its state is 0): its reset time 1/Kimw is typically >= 100 s.
    * The deadband db is treated as zero; Rup/Rdown (load-limit ramp) are ignored (PowerWorld
      does the same); the fuel-flow transport delay e^{-s Teng} is the first-order Pade
      approximation (1 - s Teng/2)/(1 + s Teng/2) (exact at Teng = 0).
    * The integrators of the governor PI and of the load-limiter PI track the low-value-select
      output with the reset time constant Kp/Ki (GE's external reset feedback; PowerWorld's
      check "Kpgov/Kigov < time step" refers to it), which is their anti-windup. With Kp = 0
      the tracking time constant is DELT instead.
    * The acceleration limiter's one-step memory of FSR is a lag of time constant DELT
      (``delt_s``, PSS/E's integration step, default 1/2 cycle at 60 Hz). It is a fast state:
      explicit fixed-step integrators need steps below ~2 DELT, adaptive ones shorten theirs.
      In the steady state (a = 0, Aset >= 0) the limiter never binds. Like PSS/E's discrete
      form it also bounds the rate of rise of FSR by Ka (Aset - a) (0.1 pu/s for Ka = 10,
      Aset = 0.01). Ka = 0 disables the limiter (FSRA = +inf); read literally the discrete
      form would then never let FSR rise.
    * Dm > 0: Pm decreases by Dm dw. Dm < 0: the engine power does not depend on speed but the
      temperature signal is scaled by (1 + dw)^Dm (lower allowed fuel at low speed).
    * Rselect = 0 (isochronous) is refused: with no droop the steady state does not determine
      the load from (Pref, dw), which jaxdse's governor interface needs.
    """

    rselect: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """Rselect (ICON): droop feedback, 1 electrical power, -1 governor output (requested
    stroke FSR), -2 fuel valve stroke; 0 (isochronous) is not supported."""
    flag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """Flag (ICON): 1 fuel flow proportional to speed (wf = s3 (1 + dw)), 0 independent of speed."""
    r_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.04)
    """R: permanent droop [pu speed / pu power (or pu stroke)] (> 0)."""
    t_pelec_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """Tpelec: electrical power transducer time constant [s]."""
    maxerr_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """maxerr: maximum speed error signal [pu]."""
    minerr_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.05)
    """minerr: minimum speed error signal [pu]."""
    kpgov: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """Kpgov: governor proportional gain [pu/pu]."""
    kigov: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """Kigov: governor integral gain [pu/pu/s]."""
    kdgov: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kdgov: governor derivative gain [pu s/pu]."""
    t_dgov_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """Tdgov: governor derivative filter time constant [s] (0: derivative off)."""
    v_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """Vmax: maximum valve position (FSR) [pu]."""
    v_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.15)
    """Vmin: minimum valve position (FSR) [pu]."""
    t_act_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """Tact: actuator time constant [s] (> 0)."""
    k_turb: Float[Array, ""] = eqx.field(converter=as_float, default=1.5)
    """Kturb: turbine gain [pu power / pu fuel] (> 0)."""
    w_fnl_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """Wfnl: no-load fuel flow [pu]."""
    t_b_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Tb: turbine lag time constant [s] (0: lead-lag bypassed)."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Tc: turbine lead time constant [s]."""
    t_eng_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Teng: transport lag of the engine (diesel) [s] (Pade (1,1) approximation)."""
    t_fload_s: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """Tfload: load limiter time constant [s]."""
    kpload: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """Kpload: load limiter proportional gain [pu/pu]."""
    kiload: Float[Array, ""] = eqx.field(converter=as_float, default=0.67)
    """Kiload: load limiter integral gain [pu/pu/s]."""
    ldref_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """Ldref: load limiter reference [pu power, governor base]."""
    dm_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Dm: speed sensitivity [pu power / pu speed] (> 0 damping, < 0 exponent of the fuel limit)."""
    r_open_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Ropen: maximum valve opening rate [pu/s] (> 0)."""
    r_close_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-0.1)
    """Rclose: maximum valve closing rate [pu/s] (< 0)."""
    kimw: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kimw: supervisory load controller gain [1/s] (kept; the loop is not represented)."""
    aset_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """Aset: acceleration limiter set point [pu speed / s] (>= 0)."""
    ka: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """Ka: acceleration limiter gain [pu/(pu/s)]."""
    t_a_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Ta: acceleration limiter (derivative filter) time constant [s] (0: acceleration 0)."""
    trate_mw: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Trate: turbine rating [MW] (0: machine base); kept, see ``base_ratio``."""
    db_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """db: speed governor deadband [pu] (kept; treated as zero)."""
    t_sa_s: Float[Array, ""] = eqx.field(converter=as_float, default=4.0)
    """Tsa: temperature detection lead time constant [s]."""
    t_sb_s: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """Tsb: temperature detection lag time constant [s] (0: bypassed)."""
    rup_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=99.0)
    """Rup: maximum rate of load limit increase [pu/s] (kept; ignored)."""
    rdown_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-99.0)
    """Rdown: maximum rate of load limit decrease [pu/s] (kept; ignored)."""
    delt_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.0 / 120.0)
    """DELT: PSS/E integration step used by the acceleration limiter [s] (> 0)."""
    base_ratio: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """Trate / MBASE (1 when Trate = 0): Tm = base_ratio Pm, Pelec_gov = Pelec / base_ratio."""

    def __check_init__(self):
        if concrete(self.rselect) and int(self.rselect) not in (1, -1, -2):
            raise ValueError(f"GGOV1.rselect must be 1, -1 or -2, got {self.rselect}"
                             + (" (isochronous governors have no droop steady state)"
                                if int(self.rselect) == 0 else ""))
        check_flag(self, "flag")
        check_positive(self, "r_pu", "t_act_s", "k_turb", "r_open_pu_s", "delt_s", "base_ratio")
        check_nonnegative(self, "t_pelec_s", "kpgov", "kigov", "kdgov", "t_dgov_s", "t_b_s", "t_c_s",
                          "t_eng_s", "t_fload_s", "kpload", "kiload", "kimw", "aset_pu_s", "ka",
                          "t_a_s", "t_sa_s", "t_sb_s")
        if all_concrete(self.r_close_pu_s, self.v_max_pu, self.v_min_pu, self.maxerr_pu, self.minerr_pu):
            check_that(self, self.r_close_pu_s < 0, f"Rclose must be < 0, got {self.r_close_pu_s}")
            check_that(self, self.v_max_pu >= self.v_min_pu,
                   f"Vmax ({self.v_max_pu}) must be >= Vmin ({self.v_min_pu})")
            check_that(self, self.maxerr_pu >= self.minerr_pu,
                   f"maxerr ({self.maxerr_pu}) must be >= minerr ({self.minerr_pu})")

    # -- algebraic pieces --
    def _speed_factor(self, dw):
        return jnp.where(self.flag == 1, 1.0 + dw, jnp.ones_like(jnp.asarray(dw, float)))

    def _damping(self, dw):
        return jnp.where(self.dm_pu > 0, self.dm_pu * dw, 0.0)

    def _temp_factor(self, dw):
        return jnp.power(1.0 + dw, jnp.minimum(self.dm_pu, 0.0))

    @property
    def _tlim(self):
        return self.ldref_pu / self.k_turb + self.w_fnl_pu

    def _turbine(self, state, dw):
        """(Pm on the governor base, fuel flow wf, d(Pade)/dt, d(lead-lag)/dt)."""
        wf = state[4] * self._speed_factor(dw)
        on = self.t_eng_s > 0
        wf_d = jnp.where(on, 2.0 * state[5] - wf, wf)
        d_e = jnp.where(on, (wf - state[5]) / (0.5 * _safe(self.t_eng_s)), 0.0)
        p_t, d_t = _lead_lag(self.k_turb * (wf_d - self.w_fnl_pu), state[6], self.t_c_s, self.t_b_s)
        return p_t - self._damping(dw), wf, d_e, d_t

    def _tracking_rate(self, kp, ki):
        """Reset-tracking rate of a PI integrator: Ki/Kp, or 1/DELT when Kp = 0."""
        return jnp.where(kp > 0, ki / _safe(kp), 1.0 / self.delt_s)

    def steady_state(self, t_ref, dw):
        ff, damp = self._speed_factor(dw), self._damping(dw)
        electrical = self.rselect == 1      # the droop on Pelec; else on the valve (FSR)
        f_gov = jnp.where(electrical, (((t_ref - dw) / self.r_pu + damp) / self.k_turb + self.w_fnl_pu) / ff,
                          (t_ref - dw) / self.r_pu)
        f_load = self._tlim / (ff * self._temp_factor(dw))
        fsr = jnp.clip(jnp.minimum(f_gov, f_load), self.v_min_pu, self.v_max_pu)
        wf = fsr * ff
        p_t = self.k_turb * (wf - self.w_fnl_pu)
        pe = p_t - damp
        fb = jnp.where(electrical, pe, fsr)
        err = jnp.clip(t_ref - dw - self.r_pu * fb, self.minerr_pu, self.maxerr_pu)
        k_g = self._tracking_rate(self.kpgov, self.kigov)
        xi = fsr - self.kpgov * err + jnp.where(k_g > 0, self.kigov * err / _safe(k_g), 0.0)
        texm = wf * self._temp_factor(dw)
        e_l = self._tlim - texm
        k_l = self._tracking_rate(self.kpload, self.kiload)
        xl = fsr - self.kpload * e_l + jnp.where(k_l > 0, self.kiload * e_l / _safe(k_l), 0.0)
        dw = jnp.asarray(dw, float) + 0.0 * fsr
        return jnp.stack([pe, err, xi, fsr, fsr, wf, p_t, texm, texm, xl, dw])

    def vector_field(self, state, dw, t_ref, p_elec=None):
        pm, wf, d_e, d_t = self._turbine(state, dw)
        p_el = pm if p_elec is None else p_elec / self.base_ratio
        pe_m, d_pe = _lag(p_el, state[0], self.t_pelec_s)
        q, s3 = state[3], state[4]
        fb = jnp.where(self.rselect == 1, pe_m, jnp.where(self.rselect == -1, q, s3))
        err = jnp.clip(t_ref - dw - self.r_pu * fb, self.minerr_pu, self.maxerr_pu)
        deriv, d_d = _washout(err, state[1], self.t_dgov_s)
        fsrn = self.kpgov * err + state[2] + self.kdgov * deriv
        # load limiter
        y_s, d_s = _lead_lag(wf * self._temp_factor(dw), state[7], self.t_sa_s, self.t_sb_s)
        texm, d_f = _lag(y_s, state[8], self.t_fload_s)
        e_l = self._tlim - texm
        fsrt = self.kpload * e_l + state[9]
        # acceleration limiter
        accel, d_a = _washout(dw, state[10], self.t_a_s)
        fsra = jnp.where(self.ka > 0, q + self.ka * self.delt_s * (self.aset_pu_s - accel), jnp.inf)
        fsr = jnp.clip(jnp.minimum(jnp.minimum(fsrn, fsrt), fsra), self.v_min_pu, self.v_max_pu)
        d_q = (fsr - q) / self.delt_s
        d_i = self.kigov * err + self._tracking_rate(self.kpgov, self.kigov) * (fsr - fsrn)
        d_l = self.kiload * e_l + self._tracking_rate(self.kpload, self.kiload) * (fsr - fsrt)
        d_s3 = jnp.clip((fsr - s3) / self.t_act_s, self.r_close_pu_s, self.r_open_pu_s)
        return jnp.stack([d_pe, d_d, d_i, d_q, d_s3, d_e, d_t, d_s, d_f, d_l, d_a])

    def torque(self, state, dw):
        return self.base_ratio * self._turbine(state, dw)[0]

    def reference_from_steady(self, t_m, dw):
        pm = t_m / self.base_ratio
        fsr = ((pm + self._damping(dw)) / self.k_turb + self.w_fnl_pu) / self._speed_factor(dw)
        return self.r_pu * jnp.where(self.rselect == 1, pm, fsr) + dw


# --- IEESGO -----------------------------------------------------------------------------------

class IEESGO(AbstractGovernor):
    """PSS/E IEESGO, the IEEE standard steam turbine-governor (IEEE Committee Report, 1973).

    Block diagram (Siemens PTI *PSS/E Model Library*, "IEESGO"; IEEE Committee Report,
    "Dynamic models for steam and hydro turbines in power system studies", IEEE Trans.
    PAS-92 (1973); the same structure in the BSD-licensed STEPS ``IEESGO``)::

        g    = K1 (1 + s T2)/(1 + s T1) . 1/(1 + s T3) dw             (governor)
        p    = clip(P0 - g, PMIN, PMAX)                               (static limit)
        x4   = p/(1 + s T4)                                           (HP section)
        x5   = K2 x4/(1 + s T5)                                       (reheater / IP section)
        x6   = K3 x5/(1 + s T6)                                       (LP section)
        Tm   = PMECH = (1 - K2) x4 + (1 - K3) x5 + x6

    so that the steady state is Tm = clip(P0 - K1 dw, PMIN, PMAX) (the fractions sum to 1).
    States: [lead-lag (T1), lag (T3), x4, x5/K2, x6/K3] (the last two hold their lag's
    state before the gain). ``t_ref`` is P0 [pu, machine base].

    K1 is the governor gain (1/droop) on the machine base, as PSS/E applies it (ANDES 2.0
    applies it on the system base). Zero time constants, as PSS/E: T1 = 0 makes the lead-lag
    a gain K1 (T2 ignored); T3, T5, T6 = 0 make their lags pass-throughs. T4 must be > 0:
    with T4 = 0 Tm would follow P0 algebraically, and jaxdse's governor interface computes
    Tm from the state and the speed alone (``torque(state, dw)``); ValueError. The limit
    acts on the algebraic signal after the summing junction, so no state winds up.
    """

    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T1: controller lag [s] (0: lead-lag bypassed)."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T2: controller lead compensation [s]."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """T3: governor lag [s] (0: pass-through)."""
    t4_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """T4: steam inlet delay [s] (0: pass-through)."""
    t5_s: Float[Array, ""] = eqx.field(converter=as_float, default=7.0)
    """T5: reheater delay [s] (0: pass-through)."""
    t6_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.6)
    """T6: IP-LP turbine and crossover delay [s] (0: pass-through)."""
    k1: Float[Array, ""] = eqx.field(converter=as_float, default=20.0)
    """K1: 1/(pu regulation) [pu power / pu speed], machine base."""
    k2: Float[Array, ""] = eqx.field(converter=as_float, default=0.7)
    """K2: fraction [-] (the power after T4 is 1 - K2)."""
    k3: Float[Array, ""] = eqx.field(converter=as_float, default=0.43)
    """K3: fraction [-]."""
    p_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """PMAX: upper power limit [pu, machine base]."""
    p_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PMIN: lower power limit [pu, machine base]."""

    def __check_init__(self):
        check_positive(self, "t4_s")
        check_nonnegative(self, "t1_s", "t2_s", "t3_s", "t5_s", "t6_s", "k1")
        if all_concrete(self.p_max_pu, self.p_min_pu):
            check_that(self, self.p_max_pu >= self.p_min_pu,
                       f"PMAX ({self.p_max_pu}) must be >= PMIN ({self.p_min_pu})")

    def _turbine(self, state):
        """((1 - K2) x4, (1 - K3) x5, x6) and the derivatives of the T5 and T6 lags."""
        x4 = state[2]
        y5, d5 = _lag(x4, state[3], self.t5_s)
        x5 = self.k2 * y5
        y6, d6 = _lag(x5, state[4], self.t6_s)
        return x4, x5, self.k3 * y6, d5, d6

    def steady_state(self, t_ref, dw):
        dw = jnp.asarray(dw, float)
        p = jnp.clip(t_ref - self.k1 * dw, self.p_min_pu, self.p_max_pu)
        return jnp.stack([dw + 0.0 * p, self.k1 * dw + 0.0 * p, p, p, self.k2 * p])

    def vector_field(self, state, dw, t_ref):
        g, d1 = _lead_lag(dw, state[0], self.t2_s, self.t1_s)
        g, d2 = _lag(self.k1 * g, state[1], self.t3_s)
        p = jnp.clip(t_ref - g, self.p_min_pu, self.p_max_pu)
        d4 = (p - state[2]) / self.t4_s
        _, _, _, d5, d6 = self._turbine(state)
        return jnp.stack([d1, d2, d4, d5, d6])

    def torque(self, state, dw):
        x4, x5, x6, _, _ = self._turbine(state)
        return (1.0 - self.k2) * x4 + (1.0 - self.k3) * x5 + x6

    def reference_from_steady(self, t_m, dw):
        return t_m + self.k1 * dw


# --- WSIEG1 -----------------------------------------------------------------------------------

def _piecewise_linear(x, xs, ys):
    """The polyline through (xs[k], ys[k]) (xs non-decreasing), extended linearly beyond its end
    segments; a segment of zero width has slope 0."""
    k = jnp.clip(jnp.searchsorted(xs, x, side="right") - 1, 0, xs.shape[-1] - 2)
    x0, x1, y0, y1 = xs[k], xs[k + 1], ys[k], ys[k + 1]
    dx = x1 - x0
    slope = jnp.where(dx != 0, (y1 - y0) / jnp.where(dx != 0, dx, 1.0), 0.0)
    return y0 + slope * (x - x0)


def _deadband(u, db):
    """Intentional deadband without memory: 0 within +-db, u -+ db outside (db = 0: u)."""
    return jnp.where(u > db, u - db, jnp.where(u < -db, u + db, 0.0))


class WSIEG1(AbstractGovernor):
    """PSS/E WSIEG1, WECC's modified IEEE type 1 steam turbine-governor (IEEEG1 with deadbands,
    a nonlinear gate-valve characteristic and governor blocking), single-shaft use.

    Block diagram (Siemens PTI *PSS/E Model Library*, "WSIEG1"; IEEEG1 as in :class:`IEEEG1`;
    the block order and the CON list cross-read in OpenIPSL ``WSIEG1`` and GridPACK
    ``wsieg1``, BSD-3)::

        e    = deadband(dw, DB1)                                      (intentional deadband)
        LL   = K (1 + s T2)/(1 + s T1) e                              (speed relay)
        dGV  = clip((Po - LL - GVb)/T3, Uc, Uo),  GV = 1/s dGV in [PMIN', PMAX'] (non-windup)
        GVb  = backlash(GV, DB2)                                      (unintentional deadband)
        PGV  = the polyline through (GV1, PGV1) ... (GV5, PGV5) at GVb (nonlinear valve gain)
        x4 = PGV/(1 + sT4), x5 = x4/(1 + sT5), x6 = x5/(1 + sT6), x7 = x6/(1 + sT7)
        Tm   = PMECH_HP = K1 x4 + K3 x5 + K5 x6 + K7 x7

    States (7): [LL lead-lag, GV, GVb, x4, x5, x6, x7]. ``t_ref`` is Po, the load reference
    in valve position units (at nominal speed the steady valve position is Po).

    Conventions and simplifications (explicit):

    * DB1 is a memoryless deadband on the speed deviation [pu]; ERR, PSS/E's intentional
      deadband hysteresis, is kept as a field but not represented (no memory state).
    * DB2 is a backlash of half-width DB2 on the valve position (as OpenIPSL's WSIEG1):
      GVb follows GV only while GV pushes against an edge of the band |GV - GVb| <= DB2,
      realised as dGVb/dt = dGV/dt there and 0 elsewhere, plus (distance outside the
      band)/T3, which is 0 on the exact solution and returns GVb to the band edge where a
      discrete integration step overshot it; DB2 = 0: GVb = GV. The valve position feeds
      back after the backlash (as in OpenIPSL), so GV settles DB2 beyond GVb.
    * The valve characteristic is used when any of GV1..GV5, PGV1..PGV5 is nonzero (GV1 <
      GV2 < ... < GV5 and PGV non-decreasing required), extended linearly beyond its end
      points; all zero: PGV = GV.
    * IBLOCK: 0 no blocking; 1: PMIN = 0 is replaced by Po (the initial valve position,
      governor cannot lower the valve); 2: PMAX = 0 is replaced by Po (cannot raise it);
      3: both, each where it is 0. OpenIPSL uses the initial power PMECH0/(K1+K3+K5+K7)
      instead, which equals Po when the valve characteristic is the identity.
    * Single shaft, as :class:`IEEEG1`: the LP output (K2, K4, K6, K8) is kept for the record.
      T1 = 0 makes the speed relay the gain K; T4..T7 = 0 are pass-throughs; T3 must be > 0.
    """

    k: Float[Array, ""] = eqx.field(converter=as_float, default=20.0)
    """K: governor gain, 1/droop [pu valve / pu speed]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T1: speed relay lag [s] (0: gain K only)."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T2: speed relay lead [s]."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """T3: valve positioner time constant [s] (> 0)."""
    uo_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Uo: maximum valve opening rate [pu/s] (> 0)."""
    uc_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-0.1)
    """Uc: maximum valve closing rate [pu/s] (< 0)."""
    p_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """PMAX: maximum valve position [pu] (0 with IBLOCK 2 or 3: the initial position)."""
    p_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PMIN: minimum valve position [pu] (0 with IBLOCK 1 or 3: the initial position)."""
    t4_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """T4: steam bowl time constant [s]."""
    k1: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """K1: HP fraction after T4 [-]."""
    k2: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K2: LP fraction after T4 [-] (ignored: single shaft)."""
    t5_s: Float[Array, ""] = eqx.field(converter=as_float, default=7.0)
    """T5: reheater time constant [s]."""
    k3: Float[Array, ""] = eqx.field(converter=as_float, default=0.4)
    """K3: HP fraction after T5 [-]."""
    k4: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K4: LP fraction after T5 [-] (ignored)."""
    t6_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.6)
    """T6: crossover time constant [s]."""
    k5: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """K5: HP fraction after T6 [-]."""
    k6: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K6: LP fraction after T6 [-] (ignored)."""
    t7_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T7: double reheat time constant [s]."""
    k7: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K7: HP fraction after T7 [-]."""
    k8: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K8: LP fraction after T7 [-] (ignored)."""
    db1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """DB1: intentional deadband on the speed deviation [pu] (>= 0)."""
    err_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """ERR: intentional deadband hysteresis [pu] (kept; not represented)."""
    db2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """DB2: unintentional deadband (backlash half-width) on the valve position [pu] (>= 0)."""
    gv1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """GV1: valve position of point 1 [pu]."""
    pgv1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PGV1: flow (power) at GV1 [pu]."""
    gv2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """GV2 [pu]."""
    pgv2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PGV2 [pu]."""
    gv3_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """GV3 [pu]."""
    pgv3_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PGV3 [pu]."""
    gv4_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """GV4 [pu]."""
    pgv4_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PGV4 [pu]."""
    gv5_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """GV5 [pu]."""
    pgv5_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PGV5 [pu]."""
    iblock: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """IBLOCK: governor blocking 0..3 (an integer kept as an array leaf, see above)."""

    def __check_init__(self):
        check_positive(self, "t3_s", "uo_pu_s")
        check_nonnegative(self, "k", "t1_s", "t2_s", "t4_s", "t5_s", "t6_s", "t7_s", "k1", "k3",
                          "k5", "k7", "db1_pu", "err_pu", "db2_pu")
        if all_concrete(self.uc_pu_s, self.p_max_pu, self.p_min_pu, self.k1, self.k3, self.k5,
                        self.k7, self.iblock):
            check_that(self, self.uc_pu_s < 0, f"Uc must be < 0, got {self.uc_pu_s}")
            check_that(self, self.p_max_pu >= self.p_min_pu,
                       f"PMAX ({self.p_max_pu}) must be >= PMIN ({self.p_min_pu})")
            check_that(self, self.k1 + self.k3 + self.k5 + self.k7 > 0,
                       "K1 + K3 + K5 + K7 must be > 0 (single-shaft output)")
            ib = np.asarray(self.iblock)
            check_that(self, np.isin(ib, (0.0, 1.0, 2.0, 3.0)),
                       f"IBLOCK must be 0, 1, 2 or 3, got {ib}")
        gv, pgv = self._table()
        if all_concrete(gv, pgv):
            gv, pgv = np.asarray(gv), np.asarray(pgv)
            used = np.any(gv != 0, axis=-1) | np.any(pgv != 0, axis=-1)
            check_that(self, ~used | np.all(np.diff(gv, axis=-1) > 0, axis=-1),
                       f"GV1 < GV2 < ... < GV5 required for the valve characteristic, got {gv}")
            check_that(self, ~used | np.all(np.diff(pgv, axis=-1) >= 0, axis=-1),
                       f"PGV1 <= PGV2 <= ... <= PGV5 required, got {pgv}")

    @property
    def k_hp(self):
        """K1 + K3 + K5 + K7: the steady-state gain from PGV to Tm."""
        return self.k1 + self.k3 + self.k5 + self.k7

    def _table(self):
        gv = jnp.stack([self.gv1_pu, self.gv2_pu, self.gv3_pu, self.gv4_pu, self.gv5_pu], axis=-1)
        pgv = jnp.stack([self.pgv1_pu, self.pgv2_pu, self.pgv3_pu, self.pgv4_pu, self.pgv5_pu],
                        axis=-1)
        return gv, pgv

    def _table_used(self):
        gv, pgv = self._table()
        return jnp.any(gv != 0) | jnp.any(pgv != 0)

    def flow(self, gv):
        """The nonlinear valve characteristic PGV(GV) [pu] (identity when not given)."""
        xs, ys = self._table()
        return jnp.where(self._table_used(), _piecewise_linear(gv, xs, ys), gv)

    def valve_for_flow(self, pgv):
        """GV that gives the flow ``pgv`` (the inverse of :meth:`flow`)."""
        xs, ys = self._table()
        return jnp.where(self._table_used(), _piecewise_linear(pgv, ys, xs), pgv)

    def _limits(self, t_ref):
        """(PMIN', PMAX') after IBLOCK: a zero limit blocked at Po."""
        lo_blk = ((self.iblock == 1) | (self.iblock == 3)) & (self.p_min_pu == 0)
        hi_blk = ((self.iblock == 2) | (self.iblock == 3)) & (self.p_max_pu == 0)
        return jnp.where(lo_blk, t_ref, self.p_min_pu), jnp.where(hi_blk, t_ref, self.p_max_pu)

    def _valve_out(self, state):
        """GVb: the valve position after the backlash, GV seen clipped to PMIN/PMAX (a limit
        blocked at Po by IBLOCK is held by the non-windup rule alone: ``torque`` has no Po)."""
        lo = jnp.where(((self.iblock == 1) | (self.iblock == 3)) & (self.p_min_pu == 0),
                       -jnp.inf, self.p_min_pu)
        hi = jnp.where(((self.iblock == 2) | (self.iblock == 3)) & (self.p_max_pu == 0),
                       jnp.inf, self.p_max_pu)
        return jnp.where(self.db2_pu > 0, state[2], jnp.clip(state[1], lo, hi))

    def _turbine(self, state):
        y4, d4 = _lag(self.flow(self._valve_out(state)), state[3], self.t4_s)
        y5, d5 = _lag(y4, state[4], self.t5_s)
        y6, d6 = _lag(y5, state[5], self.t6_s)
        y7, d7 = _lag(y6, state[6], self.t7_s)
        return (y4, y5, y6, y7), (d4, d5, d6, d7)

    def steady_state(self, t_ref, dw):
        e = _deadband(jnp.asarray(dw, float), self.db1_pu)
        lo, hi = self._limits(t_ref)
        gv = jnp.clip(t_ref - self.k * e, lo, hi)
        p = self.flow(gv)
        return jnp.stack([e + 0.0 * gv, gv, gv, p, p, p, p])

    def vector_field(self, state, dw, t_ref):
        e = _deadband(dw, self.db1_pu)
        y, d_ll = _lead_lag(e, state[0], self.t2_s, self.t1_s)
        gv, gvb = state[1], self._valve_out(state)
        lo, hi = self._limits(t_ref)
        d_gv = jnp.clip((t_ref - self.k * y - gvb) / self.t3_s, self.uc_pu_s, self.uo_pu_s)
        d_gv = _blocked(gv, d_gv, lo, hi)
        gap = gv - state[2]
        engaged = ((gap >= self.db2_pu) & (d_gv > 0)) | ((gap <= -self.db2_pu) & (d_gv < 0))
        # exact backlash: GVb moves with GV at an edge of the band; the second term (0 on the
        # exact solution) returns GVb to the band edge where a discrete step overshot it
        excess = gap - jnp.clip(gap, -self.db2_pu, self.db2_pu)
        d_gvb = jnp.where(engaged | (self.db2_pu <= 0), d_gv, 0.0) + excess / self.t3_s
        _, (d4, d5, d6, d7) = self._turbine(state)
        return jnp.stack([d_ll, d_gv, d_gvb, d4, d5, d6, d7])

    def torque(self, state, dw):
        (y4, y5, y6, y7), _ = self._turbine(state)
        return self.k1 * y4 + self.k3 * y5 + self.k5 * y6 + self.k7 * y7

    def reference_from_steady(self, t_m, dw):
        gv = self.valve_for_flow(t_m / self.k_hp)
        return gv + self.k * _deadband(jnp.asarray(dw, float), self.db1_pu)


GOVERNORS: dict[str, type[AbstractGovernor]] = {
    "TGOV1": TGOV1, "IEEEG1": IEEEG1, "GAST": GAST, "HYGOV": HYGOV, "GGOV1": GGOV1,
    "IEESGO": IEESGO, "WSIEG1": WSIEG1}
"""The governor models by their PSS/E name: TOML ``[governor] model``, .dyr records and the
fleet's governor slots (in this order)."""


class ScaledGovernor(AbstractGovernor):
    """``base`` with its torque response scaled and shifted:
    Tm = Tm0 + (1 + gain)(Tm_base - Tm0) + offset.

    The identification (``identify``) estimates ``gain``, the relative error of the governor
    model's response, and replays the event with it.
    """

    base: AbstractGovernor
    gain: Array | float = 0.0
    """Relative error of the response [-] (0: the base model)."""
    t_m0: Array | float = 0.0
    """Torque about which the response is scaled [pu]."""
    offset: Array | float = 0.0
    """Constant torque added [pu]."""

    def steady_state(self, t_ref, dw):
        return self.base.steady_state(t_ref, dw)

    def vector_field(self, state, dw, t_ref):
        return self.base.vector_field(state, dw, t_ref)

    def torque(self, state, dw):
        return self.t_m0 + (1.0 + self.gain) * (self.base.torque(state, dw) - self.t_m0) + self.offset

    def reference_from_steady(self, t_m, dw):
        base = self.t_m0 + (t_m - self.offset - self.t_m0) / (1.0 + self.gain)
        return self.base.reference_from_steady(base, dw)


# --- WeightedGovernor -------------------------------------------------------------------------

class WeightedGovernor(AbstractGovernor):
    """The governors of the units of an aggregated plant, summed with the units' MBASE shares.

        Tm = sum_k w_k Tm_k(state_k, dw) + (1 - sum_k w_k) T_ref        [pu, plant base]

    ``w_k`` = MBASE_k / sum of MBASE over the plant's units [-]; the remainder 1 - sum w_k is
    the share of units without a governor, whose torque stays at the reference. ``t_ref`` is
    the plant's torque at nominal speed in steady state [pu, plant base]; every unit runs at
    the same loading in pu of its own base, so unit k gets the reference that holds
    Tm_k = t_ref at dw = 0 (``reference_from_steady`` of its own model).

    States: the units' states one after the other, then the constant share (held at t_ref).
    A unit with weight 0 changes nothing: a fleet pads every plant to the same tuple of
    models (e.g. one TGOV1, GAST and HYGOV slot each) so that all plants share one pytree
    structure and vmap over one compiled call.
    """

    governors: tuple[AbstractGovernor, ...]
    """One governor model per unit (or per padded slot)."""
    weights: Float[Array, " k"] = eqx.field(converter=as_float)
    """MBASE share of each unit in the plant [-] (>= 0, sum <= 1)."""

    def __check_init__(self):
        if len(self.governors) != np.shape(self.weights)[-1]:
            raise ValueError(f"WeightedGovernor: {len(self.governors)} governors but "
                             f"{np.shape(self.weights)[-1]} weights")
        check_nonnegative(self, "weights")
        if concrete(self.weights):
            check_that(self, np.sum(np.asarray(self.weights), axis=-1) <= 1.0 + 1e-9,
                   f"weights must sum to <= 1, got {np.asarray(self.weights)}")

    def _sizes(self):
        return [jnp.shape(g.steady_state(1.0, 0.0))[0] for g in self.governors]

    def _parts(self, state):
        out, k = [], 0
        for n in self._sizes():
            out.append(state[k:k + n])
            k += n
        return out, state[k]

    def _refs(self, t_ref):
        return [g.reference_from_steady(t_ref, 0.0) for g in self.governors]

    def steady_state(self, t_ref, dw):
        parts = [g.steady_state(r, dw) for g, r in zip(self.governors, self._refs(t_ref))]
        const = jnp.asarray(t_ref, float) + 0.0 * jnp.asarray(dw, float)
        return jnp.concatenate(parts + [const[None]])

    def vector_field(self, state, dw, t_ref):
        parts, const = self._parts(state)
        d = [g.vector_field(x, dw, r) for g, x, r in zip(self.governors, parts, self._refs(t_ref))]
        return jnp.concatenate(d + [jnp.zeros_like(const)[None]])

    def torque(self, state, dw):
        parts, const = self._parts(state)
        total = (1.0 - jnp.sum(self.weights)) * const
        for k, (g, x) in enumerate(zip(self.governors, parts)):
            total = total + self.weights[k] * g.torque(x, dw)
        return total

    def _steady_torque(self, t_ref, dw):
        """``torque(steady_state(t_ref, dw), dw)``, slot by slot: the same arithmetic without the
        stacked state vector (elementwise over a recording's samples, stacking and splitting it
        cost a segment's first windowed chunk 1.4 s of its 2.2 s at 836 units)."""
        total = (1.0 - jnp.sum(self.weights)) * t_ref
        for k, (g, r) in enumerate(zip(self.governors, self._refs(t_ref))):
            total = total + self.weights[k] * g.torque(g.steady_state(r, dw), dw)
        return total

    def reference_from_steady(self, t_m, dw):
        # T such that the steady torque at dw is t_m: T <- T + (t_m - Tm(T)), three times (the
        # map has slope 1 at dw = 0 and within the limits, so one step is nearly exact).
        t_ref = t_m
        for _ in range(3):
            t_ref = t_ref + (t_m - self._steady_torque(t_ref, dw))
        return t_ref
