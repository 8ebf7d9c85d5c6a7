"""Inverter-based resources: the WECC second-generation renewable models REGCA1 and REGCB1
(generator/converter), REECA1, REECB1 (photovoltaic) and REECCU1 (storage) (electrical
controls) and REPCA1 (plant controller), as PSS/E names them.

Conventions (every model):

* per unit on the machine base (MBASE); time in seconds; the current is aligned with the
  terminal voltage (REGCA1 has no PLL): active current Ip in phase with V, reactive current
  Iq positive when the plant *injects* reactive power (capacitive), so P = |V| Ip and
  Q = |V| Iq. The current out of the terminal in the network frame is (Ip - j Iq) V/|V|;
* flags (PSS/E ICONs: PFFLAG, VFLAG, QFLAG, PFLAG, PQFLAG, Lvplsw, VCFlag, RefFlag, Fflag,
  Tflag) are integer array leaves like the constants, and select their signal paths with
  ``jnp.where`` (units whose flags differ share one compiled program); a lag with T = 0 is a
  pass-through whose state is kept with zero derivative (one state layout under vmap);
  ``jnp.where``, never Python branching on values; non-windup limits block the derivative that
  would push further;
* the voltage-dip freeze (REECA1: |V| < Vdip or |V| > Vup) sets the derivatives of the frozen
  states to zero; it is a switch of the vector field, so a solver with adaptive steps locates
  it to its tolerance;
* ``initial_state`` gives the steady state that holds the power flow (P, Q at |V|) with no
  limit active and outside the dip band, and the references that hold it.

Sources: WECC REMTF, *WECC Second Generation Wind Turbine Models* (2014) and *Solar Photovoltaic
Power Plant Modeling and Validation Guideline* (REGC_A, REEC_A, REEC_B, REPC_A block diagrams),
the REGC_B specification and the *Battery Storage Dynamic Modeling Guideline* (REEC_C);
Siemens PTI, *PSS(R)E Model Library* (CON/ICON tables; the REGCB1 order as GridPACK's BSD-licensed
reader and InterPSS read it, the REECCU1 order as a psspy ``add_wind_model`` call writes it; the
OpenIPSL REECB1 model read for its VFLAG = 0 reference; no code taken); the model
equations as written out in the GridKit REECA notes (ORNL, BSD-3) and the Dynawo WECC parameter
records (MPL-2.0), read for the block order only (no code taken). ANDES (GPL) is used only as
an external reference simulator by ``experiments/andes_ibr``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._base.blocks import blocked as _blocked
from .._base.blocks import lag as _lag
from .._base.blocks import lead_lag as _lead_lag
from .._base.fields import (
    all_concrete,
    as_flag,
    as_float,
    check_flag,
    check_nonnegative,
    check_positive,
    check_that,
)
from .base import record_message

LVPL_OPEN_PU = 9999.0
"""The LVPL characteristic above its breakpoint (no limit), as PSS/E documents it [pu]."""
LVPL_RESET_S = 1e-3
"""REGCA1: an Ip state above a falling LVPL is brought to it with this time constant [s] (PSS/E
resets the state of a non-windup limit to the limit; an ODE relaxes it, fast against Tg)."""
TG_BYPASS_S = 0.01
"""REGCA1 with Tg = 0: the converter lag read as bypassed (a zero time constant is a
pass-through in PSS/E, and PowerWorld sets a time constant below its minimum to 0, e.g. WTGTRQ_A:
"If 0.0 < Tp < 0.125*Mult*TimeStep then Tp = 0.0", WebHelp "Pref Controller Model: WTGTRQ_A").
A pass-through here would close an algebraic loop (Ip -> Pe -> REECA1 -> Ipcmd -> Ip), so the lag is
kept at this time constant [s], fast against every control loop of the plant (a unit note says so)."""
IQR_ZERO_IS_OPEN = True
"""REGCA1 Iqrmax = 0 (or Iqrmin = 0) is read as *no* rate limit on Iq, not as Iq frozen: the
convention of PowerWorld's renewable models that a zero limit is ignored (WebHelp "Machine Model:
REGFM_A1": "Imax ... Zero means ignore Imax"). Read literally, a zero rate freezes Iq at its
start and the plant's reactive control does nothing; a unit note says how the value was read."""
V_FLOOR_PU = 0.01
"""Dividers by a filtered voltage use max(V, this) [pu] (as the WECC diagrams do)."""


def _as_bus(x):
    """Bus numbers as an integer array leaf (host side)."""
    return np.asarray(x, dtype=np.int64)


def deadband(x, lo, hi):
    """The WECC deadband with offset: 0 within [lo, hi], x - hi above, x - lo below."""
    return jnp.where(x > hi, x - hi, jnp.where(x < lo, x - lo, 0.0))


# --- REGCA1 -----------------------------------------------------------------------------------

class REGCA1(eqx.Module):
    """PSS/E REGCA1 (WECC REGC_A), the generator/converter interface.

    Block diagram (WECC REGC_A; PSS/E Model Library "REGCA1"):

        Iq  = 1/(1 + s Tg) Iqcmd, rate dIq/dt within [Iqrmin, Iqrmax]
        Ip  = 1/(1 + s Tg) Ipcmd, rate dIp/dt <= Rrpwr, upper limit LVPL(Vf) when Lvplsw = 1
        Vf  = 1/(1 + s Tfltr) |V|                               (LVPL voltage filter)
        LVPL(Vf) = 0 below Zerox, Lvpl1 (Vf - Zerox)/(Brkpt - Zerox) up to Brkpt, open above
        Ip_inj = Ip G(|V|), G = clip((|V| - Lvpnt0)/(Lvpnt1 - Lvpnt0), 0, 1)   (LVACM)
        Iq_inj = max(Iq - Khv (|V| - Volim), Iolim) while |V| > Volim, else Iq   (HVRCM)

    States: [Ip, Iq, Vf]. When LVPL falls below the Ip state, the output is LVPL at once and the
    state follows it within ``LVPL_RESET_S`` (the non-windup limit of a lag whose limit moves:
    PSS/E resets the state), so that Ip recovers from LVPL at the Rrpwr ramp after a dip. The
    rate limits act at all times. Accel (the network-solution acceleration of
    PSS/E's Norton source) has no role with the voltage imposed and is kept for the record.
    """

    lvplsw: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """Lvplsw (ICON): 1 the LVPL limit on Ip is active, 0 not."""
    t_g_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tg: converter time constant [s] (>= 0; 0: the converter's own lag bypassed, realised as
    :data:`TG_BYPASS_S`)."""
    rrpwr_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """Rrpwr: up ramp rate of the active current [pu/s] (> 0)."""
    brkpt_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.9)
    """Brkpt: LVPL breakpoint [pu voltage]."""
    zerox_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.4)
    """Zerox: LVPL zero crossing [pu voltage] (< Brkpt)."""
    lvpl1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.22)
    """Lvpl1: LVPL at the breakpoint [pu current]."""
    volim_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.2)
    """Volim: voltage above which the high-voltage reactive current management acts [pu]."""
    lvpnt1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.8)
    """Lvpnt1: LVACM upper voltage (full active current above) [pu]."""
    lvpnt0_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.4)
    """Lvpnt0: LVACM lower voltage (no active current below) [pu] (< Lvpnt1)."""
    iolim_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-1.3)
    """Iolim: floor of the reactive current under HVRCM [pu current] (<= 0)."""
    t_fltr_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tfltr: voltage filter of the LVPL [s] (0: none)."""
    khv: Float[Array, ""] = eqx.field(converter=as_float, default=0.7)
    """Khv: HVRCM gain [pu current / pu voltage]."""
    iqrmax_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=999.0)
    """Iqrmax: up rate of the reactive current [pu/s] (>= 0; 0: no limit)."""
    iqrmin_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-999.0)
    """Iqrmin: down rate of the reactive current [pu/s] (<= 0; 0: no limit)."""
    accel: Float[Array, ""] = eqx.field(converter=as_float, default=0.7)
    """Accel: PSS/E network acceleration factor [-] (unused here)."""

    n_states = 3

    def __check_init__(self):
        check_positive(self, "rrpwr_pu_s")
        check_nonnegative(self, "t_g_s", "t_fltr_s", "khv", "iqrmax_pu_s")
        if all_concrete(self.iqrmin_pu_s, self.zerox_pu, self.brkpt_pu, self.lvpnt0_pu,
                        self.lvpnt1_pu, self.iolim_pu):
            check_that(self, self.iqrmin_pu_s <= 0, f"Iqrmin must be <= 0, got {self.iqrmin_pu_s}")
            check_that(self, self.iolim_pu <= 0, f"Iolim must be <= 0, got {self.iolim_pu}")
            check_that(self, self.lvpnt1_pu > self.lvpnt0_pu,
                       f"Lvpnt1 ({self.lvpnt1_pu}) must be > Lvpnt0 ({self.lvpnt0_pu})")
            check_that(self, (self.lvplsw == 0) | (self.brkpt_pu > self.zerox_pu),
                           f"Brkpt ({self.brkpt_pu}) must be > Zerox ({self.zerox_pu})")

    def lvpl(self, vf):
        """The LVPL ceiling on Ip at filtered voltage ``vf`` [pu] (open when Lvplsw = 0)."""
        span = jnp.where(self.brkpt_pu > self.zerox_pu, self.brkpt_pu - self.zerox_pu, 1.0)
        ramp = self.lvpl1_pu * (vf - self.zerox_pu) / span
        lvpl = jnp.where(vf < self.zerox_pu, 0.0, jnp.where(vf < self.brkpt_pu, ramp, LVPL_OPEN_PU))
        return jnp.where(self.lvplsw != 0, lvpl, LVPL_OPEN_PU)

    def lvacm(self, vt):
        """The low-voltage active current management gain G(|V|) [-]."""
        return jnp.clip((vt - self.lvpnt0_pu) / (self.lvpnt1_pu - self.lvpnt0_pu), 0.0, 1.0)

    def injection(self, state, vt):
        """(Ip_inj, Iq_inj) [pu current]: the currents the converter injects at |V| = ``vt``."""
        ip = jnp.minimum(state[0], self.lvpl(state[2]))
        hv = self.khv * jnp.maximum(vt - self.volim_pu, 0.0)
        iq = jnp.where(vt > self.volim_pu, jnp.maximum(state[1] - hv, self.iolim_pu), state[1])
        return ip * self.lvacm(vt), iq

    def vector_field(self, state, vt, ipcmd, iqcmd):
        """d[Ip, Iq, Vf]/dt at |V| = ``vt`` [pu] with the commands Ipcmd, Iqcmd [pu]."""
        ip, iq, vf = state[0], state[1], state[2]
        ceiling = self.lvpl(vf)
        # the lag with its up rate, and the ceiling as a fast pull (continuous in Ip: no chattering
        # of a solver's steps between "blocked" and "reset" at the limit)
        t_g = jnp.where(self.t_g_s > 0, self.t_g_s, TG_BYPASS_S)
        d_ip = jnp.minimum(jnp.minimum((ipcmd - ip) / t_g, self.rrpwr_pu_s),
                           (ceiling - ip) / LVPL_RESET_S)
        # a rate limit of 0 is no limit (see IQR_ZERO_IS_OPEN)
        up = jnp.where(self.iqrmax_pu_s > 0, self.iqrmax_pu_s, jnp.inf)
        down = jnp.where(self.iqrmin_pu_s < 0, self.iqrmin_pu_s, -jnp.inf)
        d_iq = jnp.clip((iqcmd - iq) / t_g, down, up)
        _, d_vf = _lag(vt, vf, self.t_fltr_s)
        return jnp.stack([d_ip, d_iq, d_vf])

    def initial_state(self, vt, p, q):
        """(state, Ipcmd, Iqcmd): the steady state injecting P = ``p``, Q = ``q`` [pu] at |V| =
        ``vt`` (HVRCM inactive: |V| <= Volim; the LVACM gain divides Ip)."""
        ip = p / (vt * self.lvacm(vt))
        iq = q / vt
        return jnp.stack([ip, iq, jnp.asarray(vt, float) + 0.0 * ip]), ip, iq


class REGCB1(eqx.Module):
    """PSS/E REGCB1 (WECC REGC_B), the generator/converter interface with its current control
    and a voltage source behind the source impedance.

    Block diagram (WECC REMTF, *REGC_B model specification*; PSS/E Model Library "REGCB1"):

        (Ipc, Iqc) = current limit of (Ipcmd, Iqcmd): PQFlag = 0 Iqc = clip(Iqcmd, -Imax, Imax),
                     Ipc within +-sqrt(Imax^2 - Iqc^2); PQFlag = 1 the other way round
        Vf  = 1/(1 + s Tfltr) |V|  (floor 0.01)
        RateFlag = 0: Ip = 1/(1 + s Tg) Ipc;      RateFlag = 1: Ip = [1/(1 + s Tg) (Ipc Vf)] / Vf
                      the rate of the lag within Rrpwr in the direction of the command's sign
        Iq  = 1/(1 + s Tg) Iqc, rate within [Iqrmin, Iqrmax]
        E   = 1/(1 + s Te) (V + Zs (Ip - j Iq)),   I_out = (E - V) / Zs   (terminal voltage frame)

    Zs = Re + j Xe is the generator's source impedance (the .raw ZSORCE on MBASE). With Te = 0
    or Zs = 0 the converter is the current source (Ip, Iq). States: [Ip (P when RateFlag = 1), Iq,
    Vf, Ed, Eq]; E is held in the frame of the terminal voltage (its angle's motion is not fed
    back into E). No LVPL, LVACM or HVRCM (REGC_B has none).
    """

    rateflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """RateFlag (ICON): 0 the Rrpwr rate acts on the active current, 1 on the active power."""
    pqflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """PQFlag (ICON): current limit priority, 0 reactive, 1 active."""
    t_g_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tg: current control time constant [s] (> 0)."""
    t_fltr_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tfltr: terminal voltage filter [s] (0: none)."""
    iqrmax_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=999.0)
    """Iqrmax: up rate of the reactive current [pu/s] (> 0)."""
    iqrmin_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-999.0)
    """Iqrmin: down rate of the reactive current [pu/s] (< 0)."""
    rrpwr_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """Rrpwr: ramp rate of the active current (or power) [pu/s] (> 0)."""
    t_e_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Te: voltage source time constant [s] (0: current source)."""
    i_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.6)
    """Imax: converter current limit [pu] (> 0)."""
    re_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Re: source resistance [pu on MBASE] (the generator's ZSORCE, not a CON)."""
    xe_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Xe: source reactance [pu on MBASE] (the generator's ZSORCE, not a CON)."""

    n_states = 5

    def __check_init__(self):
        check_flag(self, "rateflag", "pqflag")
        check_positive(self, "t_g_s", "rrpwr_pu_s", "iqrmax_pu_s", "i_max_pu")
        check_nonnegative(self, "t_fltr_s", "t_e_s")
        if all_concrete(self.iqrmin_pu_s):
            check_that(self, self.iqrmin_pu_s < 0, f"Iqrmin must be < 0, got {self.iqrmin_pu_s}")

    def _source(self):
        """(on, Zs): whether the voltage source lag acts, and Zs (1 where it does not)."""
        z = self.re_pu + 1j * self.xe_pu
        on = (self.t_e_s > 0) & (jnp.abs(z) > 1e-9)
        return on, jnp.where(on, z, 1.0 + 0j)

    def _currents(self, state):
        """(Ip, Iq) of the current control lags [pu]."""
        vf = jnp.maximum(state[2], V_FLOOR_PU)
        ip = jnp.where(self.rateflag != 0, state[0] / vf, state[0])
        return ip, state[1]

    def limit(self, ipcmd, iqcmd):
        """(Ipc, Iqc): the commands within Imax, by PQFlag's priority."""
        room = lambda x: jnp.sqrt(jnp.maximum(self.i_max_pu ** 2 - x ** 2, 0.0))  # noqa: E731
        ip_first = jnp.clip(ipcmd, -self.i_max_pu, self.i_max_pu)
        iq_first = jnp.clip(iqcmd, -self.i_max_pu, self.i_max_pu)
        p_pri = self.pqflag != 0
        return (jnp.where(p_pri, ip_first, jnp.clip(ipcmd, -room(iq_first), room(iq_first))),
                jnp.where(p_pri, jnp.clip(iqcmd, -room(ip_first), room(ip_first)), iq_first))

    def injection(self, state, vt):
        """(Ip_inj, Iq_inj) [pu current]: the currents the converter injects at |V| = ``vt``."""
        ip, iq = self._currents(state)
        on, z = self._source()
        i_out = (state[3] + 1j * state[4] - vt) / z
        return jnp.where(on, i_out.real, ip), jnp.where(on, -i_out.imag, iq)

    def vector_field(self, state, vt, ipcmd, iqcmd):
        """d[Ip, Iq, Vf, Ed, Eq]/dt at |V| = ``vt`` [pu] with the commands Ipcmd, Iqcmd [pu]."""
        ipc, iqc = self.limit(ipcmd, iqcmd)
        vf = jnp.maximum(state[2], V_FLOOR_PU)
        target = jnp.where(self.rateflag != 0, ipc * vf, ipc)
        d_ip = (target - state[0]) / self.t_g_s
        d_ip = jnp.where(target >= 0, jnp.minimum(d_ip, self.rrpwr_pu_s), jnp.maximum(d_ip, -self.rrpwr_pu_s))
        d_iq = jnp.clip((iqc - state[1]) / self.t_g_s, self.iqrmin_pu_s, self.iqrmax_pu_s)
        _, d_vf = _lag(vt, state[2], self.t_fltr_s)
        ip, iq = self._currents(state)
        on, z = self._source()
        e = vt + z * (ip - 1j * iq)
        te = jnp.where(on, self.t_e_s, 1.0)
        d_ed = jnp.where(on, (e.real - state[3]) / te, 0.0)
        d_eq = jnp.where(on, (e.imag - state[4]) / te, 0.0)
        return jnp.stack([d_ip, d_iq, d_vf, d_ed, d_eq])

    def initial_state(self, vt, p, q):
        """(state, Ipcmd, Iqcmd): the steady state injecting P = ``p``, Q = ``q`` [pu] at |V| =
        ``vt`` (|I| within Imax)."""
        vt = jnp.asarray(vt, float)
        ip, iq = p / vt, q / vt
        _, z = self._source()
        e = vt + z * (ip - 1j * iq)
        x_p = jnp.where(self.rateflag != 0, ip * vt, ip)
        return jnp.stack([x_p, iq, vt + 0.0 * ip, e.real, e.imag]), ip, iq


# --- REECA1 -----------------------------------------------------------------------------------

class ElectricalInputs(NamedTuple):
    """What the electrical controls see at one instant (machine base)."""

    vt_pu: Array
    """Terminal voltage magnitude [pu]."""
    p_pu: Array
    """Active power out of the terminal, Pe [pu]."""
    q_pu: Array
    """Reactive power out of the terminal, Qgen [pu]."""
    p_ref_pu: Array
    """Active power reference Pref [pu] (from the plant controller, or constant)."""
    q_ext_pu: Array
    """Reactive power reference Qext [pu] (from the plant controller, or constant)."""
    speed_pu: Array
    """Generator speed wg [pu] (PFLAG = 1 multiplies Pref by it; 1 for a plant without one)."""


class ElectricalReferences(NamedTuple):
    """The references of REECA1 that hold its initial steady state."""

    v_ref0_pu: Array
    """Vref0 [pu]: the record's, or |V| at the start where the record gives 0."""
    v_ref1_pu: Array
    """Vref1 [pu] (VFLAG = 0): the inner voltage loop's reference that holds the start."""
    pfaref_rad: Array
    """Power factor angle reference [rad] (PFFLAG = 1): atan(Q0/P0)."""


class _ElectricalControls(eqx.Module):
    """The REEC_A/B/C signal path shared by REECA1, REECB1 and REECCU1 (methods only; each model
    holds its own fields and says, through the hooks below, where it differs): the voltage
    filter and dip freeze, the Q and V PI loops, the Tiq lag, the power order and the current
    limit logic, as in :class:`REECA1`'s docstring. Hooks: ``_tables(vm)`` (VDL1, VDL2 ceilings),
    ``_v_alt(q_c, refs)`` (the inner loop's reference with VFLAG = 0), ``_p_in(u)`` (the power
    order's input), ``_ip_floor(ip_max)`` (the lower active current limit), ``_p_limits(state)``
    (the power order's limits), ``_extra(state, u)`` (derivatives of states after the six)."""

    def _freeze(self, vt):
        return (vt < self.vdip_pu) | (vt > self.vup_pu)

    def _ip_floor(self, ip_max):
        return jnp.zeros_like(ip_max)

    def _p_limits(self, state):
        return self.p_min_pu, self.p_max_pu

    def _extra(self, state, u: ElectricalInputs):
        return []

    def commands(self, state, u: ElectricalInputs, refs: ElectricalReferences):
        """(Ipcmd, Iqcmd, dip, internals): the current commands [pu] at ``state``; ``internals``
        (the PI errors and outputs) serve the vector field."""
        vm, pm, x_q, x_v, x_iq, pord = (state[k] for k in range(6))
        vm, _ = _lag(u.vt_pu, vm, self.t_rv_s)
        pm, _ = _lag(u.p_pu, pm, self.t_p_s)
        dip = self._freeze(u.vt_pu)
        v_safe = jnp.maximum(vm, V_FLOOR_PU)
        iqv = jnp.clip(self.kqv * deadband(refs.v_ref0_pu - vm, self.dbd1_pu, self.dbd2_pu),
                       self.iql1_pu, self.iqh1_pu)
        q_ref = jnp.where(self.pfflag != 0, pm * jnp.tan(refs.pfaref_rad), u.q_ext_pu)
        q_c = jnp.clip(q_ref, self.q_min_pu, self.q_max_pu)
        e_q = q_c - u.q_pu
        vq_raw = self.kqp * e_q + x_q
        vq = jnp.clip(vq_raw, self.v_min_pu, self.v_max_pu)
        v_sel = jnp.where(self.vflag != 0, vq, self._v_alt(q_c, refs))
        e_v = v_sel - vm
        iv0, _ = _lag(q_c / v_safe, x_iq, self.t_iq_s)
        p_lo, p_hi = self._p_limits(state)
        pord_out = jnp.clip(jnp.where(self.t_pord_s > 0, pord, self._p_in(u)), p_lo, p_hi)
        ip_raw = pord_out / v_safe
        vdl1, vdl2 = self._tables(vm)
        # PQFLAG = 1, active current first: Ipcmd within its ceiling, Iq within what is left
        p_pri = self.pqflag != 0
        ip_max_p = jnp.minimum(vdl2, self.i_max_pu)
        ipcmd_p = jnp.clip(ip_raw, self._ip_floor(ip_max_p), ip_max_p)
        iq_room = jnp.sqrt(jnp.maximum(self.i_max_pu ** 2 - ipcmd_p ** 2, 1e-12))
        iq_max = jnp.minimum(vdl1, jnp.where(p_pri, iq_room, self.i_max_pu))
        iqb_raw = self.kvp * e_v + x_v
        iqb = jnp.clip(iqb_raw, -iq_max, iq_max)
        iqcmd = jnp.clip(jnp.where(self.qflag != 0, iqb, iv0) + jnp.where(dip, iqv, 0.0), -iq_max, iq_max)
        # PQFLAG = 0, reactive current first: Ip within what Iqcmd leaves
        ip_max_q = jnp.minimum(vdl2, jnp.sqrt(jnp.maximum(self.i_max_pu ** 2 - iqcmd ** 2, 1e-12)))
        ipcmd = jnp.where(p_pri, ipcmd_p, jnp.clip(ip_raw, self._ip_floor(ip_max_q), ip_max_q))
        return ipcmd, iqcmd, dip, (q_c, e_q, vq_raw, e_v, iqb_raw, iq_max)

    def vector_field(self, state, u: ElectricalInputs, refs: ElectricalReferences):
        """d(state)/dt."""
        vm, pm, x_q, x_v, x_iq, pord = (state[k] for k in range(6))
        _, d_vm = _lag(u.vt_pu, vm, self.t_rv_s)
        _, d_pm = _lag(u.p_pu, pm, self.t_p_s)
        _, _, dip, (q_c, e_q, vq_raw, e_v, iqb_raw, iq_max) = self.commands(state, u, refs)
        run = 1.0 - dip.astype(state.dtype)
        d_q = run * _blocked(vq_raw, self.kqi * e_q, self.v_min_pu, self.v_max_pu)
        d_v = run * _blocked(iqb_raw, self.kvi * e_v, -iq_max, iq_max)
        v_safe = jnp.maximum(jnp.where(self.t_rv_s > 0, vm, u.vt_pu), V_FLOOR_PU)
        _, d_iq = _lag(q_c / v_safe, x_iq, self.t_iq_s)
        on = self.t_pord_s > 0
        p_lo, p_hi = self._p_limits(state)
        d_p = jnp.clip((self._p_in(u) - pord) / jnp.where(on, self.t_pord_s, 1.0),
                       self.dp_min_pu_s, self.dp_max_pu_s)
        d_p = jnp.where(on, _blocked(pord, d_p, p_lo, p_hi), 0.0)
        loops = self.qflag != 0                  # QFLAG = 0: the PI loops are not in the signal path
        d_q, d_v = jnp.where(loops, d_q, 0.0), jnp.where(loops, d_v, 0.0)
        return jnp.stack([d_vm, d_pm, d_q, d_v, run * d_iq, run * d_p, *self._extra(state, u)])

    def _extra_state(self, vt):
        return []

    def initial_state(self, vt, p, q, ipcmd, iqcmd):
        """(state, ElectricalReferences, Pref, Qext): the steady state that issues the commands
        ``ipcmd``, ``iqcmd`` [pu] at |V| = ``vt``, P = ``p``, Q = ``q``, and the references
        (Pref, and Qext for PFFLAG = 0) that hold it. Assumes no limit active, no dip."""
        vt = jnp.asarray(vt, float)
        v_ref0 = jnp.where(self.v_ref0_pu == 0.0, vt, self.v_ref0_pu)
        pfaref = jnp.where(self.pfflag != 0, jnp.arctan2(q, p), 0.0) + 0.0 * vt
        p_ref = ipcmd * vt                      # Pord = Ipcmd Vm: the order that gives Ipcmd
        q_ext = q
        q_c = jnp.clip(q, self.q_min_pu, self.q_max_pu)
        v_ref1 = self._v_ref1(vt, q_c)
        x_q = vt + 0.0 * q                      # PI_Q output = Vm (e_q = 0)
        x_v = iqcmd + 0.0 * vt                  # PI_V output = Iqcmd (e_v = 0)
        x_iq = q_c / jnp.maximum(vt, V_FLOOR_PU)
        pord = p_ref                            # speed 1 at the start (PFLAG = 1)
        state = jnp.stack([vt, jnp.asarray(p, float) + 0.0 * vt, x_q, x_v, x_iq, pord,
                           *self._extra_state(vt)])
        return state, ElectricalReferences(v_ref0, v_ref1, pfaref), p_ref, q_ext


class REECA1(_ElectricalControls):
    """PSS/E REECA1 (WECC REEC_A), the electrical controls of a renewable plant.

    Block diagram (WECC REEC_A; PSS/E Model Library "REECA1"), with Vt the terminal voltage:

        Vm   = 1/(1 + s Trv) Vt;   dip = Vt < Vdip or Vt > Vup      (the freeze, unfiltered Vt)
        Iqv  = clip(Kqv db(Vref0 - Vm, dbd1, dbd2), Iql1, Iqh1)       (added while dip only)
        Qref = Pm tan(pfaref) if PFFLAG else Qext;  Pm = 1/(1 + s Tp) Pe;  Qc = clip(Qref, Qmin, Qmax)
        Vq   = PI(Kqp, Kqi)[Qc - Qgen], limits [Vmin, Vmax], integrator frozen in a dip
        Vsel = Vq if VFLAG else Qc + Vref1
        Iqb  = PI(Kvp, Kvi)[Vsel - Vm], limits [-Iqmax, Iqmax], integrator frozen in a dip
        Iqv0 = 1/(1 + s Tiq) Qc / max(Vm, 0.01), frozen in a dip
        Iqcmd = clip((Iqb if QFLAG else Iqv0) + dip Iqv, -Iqmax, Iqmax)
        Pord = 1/(1 + s Tpord) (Pref wg^PFLAG), rate [dPmin, dPmax], limits [Pmin, Pmax], frozen
        Ipcmd = clip(Pord / max(Vm, 0.01), 0, Ipmax)
        PQFLAG = 0 (Q priority): Iqmax = min(VDL1(Vm), Imax), Ipmax = min(VDL2(Vm), sqrt(Imax^2 - Iqcmd^2))
        PQFLAG = 1 (P priority): Ipmax = min(VDL2(Vm), Imax), Iqmax = min(VDL1(Vm), sqrt(Imax^2 - Ipcmd^2))

    States: [Vm, Pm, PI_Q integrator, PI_V integrator, Iqv0 lag, Pord]. VDL1/VDL2 are the
    piecewise-linear tables (Vq1, Iq1) ... (Vq4, Iq4) and (Vp1, Ip1) ... (Vp4, Ip4), flat
    outside. Simplifications, stated: the post-dip hold timers Thld and Thld2 (and Iqfrz, the
    value held) are not modelled (the injection ends with the dip, Ipmax is not held); Vref1 is
    set by ``initial_state`` so that the start is at rest (the record's Vref1 is ignored); the
    voltage is the terminal's (the remote regulated bus ICON is recorded, not used).
    """

    pfflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """PFFLAG: 1 constant power factor (Qref = Pe tan(pfaref)), 0 Q from Qext."""
    vflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """VFLAG: 1 Q control (the PI_Q output is the voltage loop's reference), 0 voltage control."""
    qflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """QFLAG: 1 voltage/Q control through the PI loops, 0 constant Q (Iq = Qref/V)."""
    pflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """PFLAG: 1 Pref multiplied by the generator speed, 0 not."""
    pqflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """PQFLAG: current limit priority, 0 reactive, 1 active."""
    remote_bus: Int[Array, ""] = eqx.field(converter=_as_bus, default=0)
    """Regulated bus ICON (0: terminal); a nonzero one is taken at the terminal. An array leaf:
    plants of different regulated buses share one compiled program (as REECB1's)."""
    vdip_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.9)
    """Vdip: voltage below which the dip logic acts [pu]."""
    vup_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.1)
    """Vup: voltage above which the dip logic acts [pu] (> Vdip)."""
    t_rv_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Trv: terminal voltage filter [s] (0: none)."""
    dbd1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.05)
    """dbd1: lower edge of the voltage error deadband [pu] (<= 0)."""
    dbd2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """dbd2: upper edge of the voltage error deadband [pu] (>= 0)."""
    kqv: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """Kqv: reactive current injection gain in a dip [pu current / pu voltage]."""
    iqh1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.05)
    """Iqh1: upper limit of the injection [pu current]."""
    iql1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-1.05)
    """Iql1: lower limit of the injection [pu current]."""
    v_ref0_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Vref0: reference of the injection's voltage error [pu] (0: the initial |V|)."""
    iqfrz_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Iqfrz: injection held after a dip for Thld [pu current] (not modelled)."""
    thld_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Thld: hold time of the injection after a dip [s] (not modelled: 0)."""
    thld2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Thld2: hold time of Ipmax after a dip [s] (not modelled: 0)."""
    t_p_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Tp: electrical power filter [s] (0: none)."""
    q_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.436)
    """QMax: reactive power reference ceiling [pu]."""
    q_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.436)
    """QMin: reactive power reference floor [pu]."""
    v_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.1)
    """VMAX: upper limit of the PI_Q output [pu]."""
    v_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.9)
    """VMIN: lower limit of the PI_Q output [pu]."""
    kqp: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kqp: PI_Q proportional gain [pu/pu]."""
    kqi: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Kqi: PI_Q integral gain [pu/pu/s]."""
    kvp: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kvp: PI_V proportional gain [pu/pu]."""
    kvi: Float[Array, ""] = eqx.field(converter=as_float, default=40.0)
    """Kvi: PI_V integral gain [pu/pu/s]."""
    v_ref1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Vref1: the record's inner voltage reference [pu] (replaced by the initial one)."""
    t_iq_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tiq: reactive current command lag (QFLAG = 0) [s] (0: none)."""
    dp_max_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=99.0)
    """dPmax: up rate of the power order [pu/s] (> 0)."""
    dp_min_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-99.0)
    """dPmin: down rate of the power order [pu/s] (< 0)."""
    p_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """PMAX: power order ceiling [pu]."""
    p_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PMIN: power order floor [pu]."""
    i_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.7)
    """Imax: converter current limit [pu] (> 0)."""
    t_pord_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tpord: power order lag [s] (0: none)."""
    vdl1_v_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(0.2, 0.5, 1.0, 1.5))
    """Vq1..Vq4: voltages of the VDL1 table [pu] (increasing)."""
    vdl1_i_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(1.5, 1.5, 1.5, 1.5))
    """Iq1..Iq4: reactive current ceilings of the VDL1 table [pu]."""
    vdl2_v_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(0.2, 0.5, 1.0, 1.5))
    """Vp1..Vp4: voltages of the VDL2 table [pu] (increasing)."""
    vdl2_i_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(1.5, 1.5, 1.5, 1.5))
    """Ip1..Ip4: active current ceilings of the VDL2 table [pu]."""

    n_states = 6

    def __check_init__(self):
        check_flag(self, "pfflag", "vflag", "qflag", "pflag", "pqflag")
        check_positive(self, "dp_max_pu_s", "i_max_pu")
        check_nonnegative(self, "t_rv_s", "t_p_s", "t_iq_s", "t_pord_s", "kqi", "kvi",
                          "vdl1_i_pu", "vdl2_i_pu")
        if all_concrete(self.vdip_pu, self.vup_pu, self.dbd1_pu, self.dbd2_pu, self.q_max_pu,
                        self.v_max_pu, self.p_max_pu, self.dp_min_pu_s, self.vdl1_v_pu, self.vdl2_v_pu):
            check_that(self, self.vup_pu > self.vdip_pu,
                       f"Vup ({self.vup_pu}) must be > Vdip ({self.vdip_pu})")
            check_that(self, (self.dbd1_pu <= 0) & (self.dbd2_pu >= 0),
                       f"dbd1 ({self.dbd1_pu}) must be <= 0 <= dbd2 ({self.dbd2_pu})")
            check_that(self, self.q_max_pu >= self.q_min_pu,
                       f"QMax ({self.q_max_pu}) must be >= QMin ({self.q_min_pu})")
            check_that(self, self.v_max_pu >= self.v_min_pu,
                       f"VMAX ({self.v_max_pu}) must be >= VMIN ({self.v_min_pu})")
            check_that(self, self.p_max_pu >= self.p_min_pu,
                       f"PMAX ({self.p_max_pu}) must be >= PMIN ({self.p_min_pu})")
            check_that(self, self.dp_min_pu_s < 0, f"dPmin must be < 0, got {self.dp_min_pu_s}")
            for v, what in ((self.vdl1_v_pu, "Vq1..Vq4"), (self.vdl2_v_pu, "Vp1..Vp4")):
                check_that(self, np.all(np.diff(np.asarray(v)) > 0),
                           f"{what} must increase, got {np.asarray(v).tolist()}")

    def _tables(self, vm):
        return (jnp.interp(vm, self.vdl1_v_pu, self.vdl1_i_pu),
                jnp.interp(vm, self.vdl2_v_pu, self.vdl2_i_pu))

    def _v_alt(self, q_c, refs: ElectricalReferences):
        return q_c + refs.v_ref1_pu

    def power_order(self, state, u: ElectricalInputs):
        """Pord [pu]: the power order after its limits (the input itself when Tpord = 0)."""
        return jnp.clip(jnp.where(self.t_pord_s > 0, state[5], self._p_in(u)), self.p_min_pu, self.p_max_pu)

    def _p_in(self, u: ElectricalInputs):
        return jnp.where(self.pflag != 0, u.p_ref_pu * u.speed_pu, u.p_ref_pu)

    def _v_ref1(self, vt, q_c):
        return vt - q_c                         # VFLAG = 0: Vsel = Qc + Vref1 = Vm


class REECB1(_ElectricalControls):
    """PSS/E REECB1 (WECC REEC_B), the electrical controls of a photovoltaic plant.

    Block diagram (WECC REMTF, *Solar Photovoltaic Power Plant Modeling and Validation
    Guideline*, REEC_B; PSS/E Model Library "REECB1"): :class:`REECA1`'s signal path without its
    VDL tables, speed input (PFLAG) and post-dip hold timers, and with the voltage reference
    Vref0 serving the inner voltage loop when VFLAG = 0:

        Vsel = Vq if VFLAG else clip(Vref0, VMIN, VMAX)
        PQFLAG = 0: Iqmax = Imax, Ipmax = sqrt(Imax^2 - Iqcmd^2);  PQFLAG = 1: Ipmax = Imax,
        Iqmax = sqrt(Imax^2 - Ipcmd^2);  Ipcmd in [0, Ipmax], Iqcmd in [-Iqmax, Iqmax]

    and the rest as REECA1 (dip freeze of the PI integrators, of the Tiq lag and of the power
    order while Vt < Vdip or Vt > Vup; injection Kqv db(Vref0 - Vm) within [Iql1, Iqh1] during
    the dip). States: [Vm, Pm, PI_Q integrator, PI_V integrator, Iqv0 lag, Pord]. With VFLAG = 0
    the inner loop's reference is |V| at the start (``ElectricalReferences.v_ref1_pu``): a
    record's Vref0 that differs from it would move the start (the plant notes say so).
    """

    pfflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """PFFLAG: 1 constant power factor (Qref = Pe tan(pfaref)), 0 Q from Qext."""
    vflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """VFLAG: 1 Q control (the PI_Q output is the voltage loop's reference), 0 voltage control."""
    qflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """QFLAG: 1 voltage/Q control through the PI loops, 0 constant Q (Iq = Qref/V)."""
    pqflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """PQFLAG: current limit priority, 0 reactive, 1 active."""
    remote_bus: Int[Array, ""] = eqx.field(converter=_as_bus, default=0)
    """Regulated bus ICON (0: terminal); a nonzero one is taken at the terminal. An array leaf:
    plants of different regulated buses share one compiled program."""
    vdip_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.9)
    """Vdip: voltage below which the dip logic acts [pu]."""
    vup_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.1)
    """Vup: voltage above which the dip logic acts [pu] (> Vdip)."""
    t_rv_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Trv: terminal voltage filter [s] (0: none)."""
    dbd1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.05)
    """dbd1: lower edge of the voltage error deadband [pu] (<= 0)."""
    dbd2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """dbd2: upper edge of the voltage error deadband [pu] (>= 0)."""
    kqv: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """Kqv: reactive current injection gain in a dip [pu current / pu voltage]."""
    iqh1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.05)
    """Iqh1: upper limit of the injection [pu current]."""
    iql1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-1.05)
    """Iql1: lower limit of the injection [pu current]."""
    v_ref0_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Vref0: reference of the injection's voltage error [pu] (0: the initial |V|)."""
    t_p_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Tp: electrical power filter [s] (0: none)."""
    q_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.436)
    """QMax: reactive power reference ceiling [pu]."""
    q_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.436)
    """QMin: reactive power reference floor [pu]."""
    v_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.1)
    """VMAX: upper limit of the PI_Q output and of the VFLAG = 0 reference [pu]."""
    v_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.9)
    """VMIN: lower limit of the PI_Q output and of the VFLAG = 0 reference [pu]."""
    kqp: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kqp: PI_Q proportional gain [pu/pu]."""
    kqi: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Kqi: PI_Q integral gain [pu/pu/s]."""
    kvp: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kvp: PI_V proportional gain [pu/pu]."""
    kvi: Float[Array, ""] = eqx.field(converter=as_float, default=40.0)
    """Kvi: PI_V integral gain [pu/pu/s]."""
    t_iq_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tiq: reactive current command lag (QFLAG = 0) [s] (0: none)."""
    dp_max_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=99.0)
    """dPmax: up rate of the power order [pu/s] (> 0)."""
    dp_min_pu_s: Float[Array, ""] = eqx.field(converter=as_float, default=-99.0)
    """dPmin: down rate of the power order [pu/s] (< 0)."""
    p_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """PMAX: power order ceiling [pu]."""
    p_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """PMIN: power order floor [pu]."""
    i_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.7)
    """Imax: converter current limit [pu] (> 0)."""
    t_pord_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tpord: power order lag [s] (0: none)."""

    n_states = 6
    pflag = 0
    """No speed input (REEC_B): Pref reaches the power order as it is."""

    def __check_init__(self):
        check_flag(self, "pfflag", "vflag", "qflag", "pqflag")
        check_positive(self, "dp_max_pu_s", "i_max_pu")
        check_nonnegative(self, "t_rv_s", "t_p_s", "t_iq_s", "t_pord_s", "kqi", "kvi")
        if all_concrete(self.vdip_pu, self.vup_pu, self.dbd1_pu, self.dbd2_pu, self.q_max_pu,
                        self.v_max_pu, self.p_max_pu, self.dp_min_pu_s):
            check_that(self, self.vup_pu > self.vdip_pu,
                       f"Vup ({self.vup_pu}) must be > Vdip ({self.vdip_pu})")
            check_that(self, (self.dbd1_pu <= 0) & (self.dbd2_pu >= 0),
                       f"dbd1 ({self.dbd1_pu}) must be <= 0 <= dbd2 ({self.dbd2_pu})")
            check_that(self, self.q_max_pu >= self.q_min_pu,
                       f"QMax ({self.q_max_pu}) must be >= QMin ({self.q_min_pu})")
            check_that(self, self.v_max_pu >= self.v_min_pu,
                       f"VMAX ({self.v_max_pu}) must be >= VMIN ({self.v_min_pu})")
            check_that(self, self.p_max_pu >= self.p_min_pu,
                       f"PMAX ({self.p_max_pu}) must be >= PMIN ({self.p_min_pu})")
            check_that(self, self.dp_min_pu_s < 0, f"dPmin must be < 0, got {self.dp_min_pu_s}")

    def _tables(self, vm):
        return jnp.full_like(vm, VDL_OPEN_PU), jnp.full_like(vm, VDL_OPEN_PU)

    def _v_alt(self, q_c, refs: ElectricalReferences):
        return jnp.clip(refs.v_ref1_pu, self.v_min_pu, self.v_max_pu) + 0.0 * q_c

    def _p_in(self, u: ElectricalInputs):
        return u.p_ref_pu

    def _v_ref1(self, vt, q_c):
        return vt + 0.0 * q_c                   # VFLAG = 0: the inner loop holds |V| at the start


class REECCU1(REECB1):
    """PSS/E REECCU1 (WECC REEC_C), the electrical controls of a battery energy storage plant.

    Block diagram (WECC REMTF, REEC_C in the *Battery Storage Dynamic Modeling Guideline*;
    PSS/E Model Library "REECCU1"): :class:`REECB1` with the VDL1/VDL2 tables of
    :class:`REECA1` on Iqmax and Ipmax, a negative active current allowed (charging: Ipcmd in
    [-Ipmax, Ipmax], PMIN < 0), and the state of charge

        d SOC/dt = -Pe / T,  SOC(0) = SOCini          (T: discharge time at 1 pu power [s])
        SOC >= SOCmax: the power order floor PMIN raised to 0 (no more charging)
        SOC <= SOCmin: the power order ceiling PMAX lowered to 0 (no more discharging)

    States: REECB1's six, then SOC [pu]. SOC is an integrator of the output power: it is at rest
    only at P = 0, so a held run at P0 != 0 lets it drift by -P0 t / T (P and Q stay held while
    SOC stays inside its limits). The auxiliary power input Paux is 0.
    """

    vdl1_v_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(0.2, 0.5, 1.0, 1.5))
    """Vq1..Vq4: voltages of the VDL1 table [pu] (increasing)."""
    vdl1_i_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(1.5, 1.5, 1.5, 1.5))
    """Iq1..Iq4: reactive current ceilings of the VDL1 table [pu]."""
    vdl2_v_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(0.2, 0.5, 1.0, 1.5))
    """Vp1..Vp4: voltages of the VDL2 table [pu] (increasing)."""
    vdl2_i_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(1.5, 1.5, 1.5, 1.5))
    """Ip1..Ip4: active current ceilings of the VDL2 table [pu]."""
    t_soc_s: Float[Array, ""] = eqx.field(converter=as_float, default=999.0)
    """T: discharge time of the battery at 1 pu power [s] (> 0)."""
    soc_ini_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """SOCini: initial state of charge [pu]."""
    soc_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.8)
    """SOCmax: state of charge above which charging stops [pu]."""
    soc_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """SOCmin: state of charge below which discharging stops [pu] (<= SOCmax)."""

    n_states = 7

    def __check_init__(self):
        check_positive(self, "t_soc_s")
        check_nonnegative(self, "vdl1_i_pu", "vdl2_i_pu")
        if all_concrete(self.soc_min_pu, self.soc_max_pu, self.vdl1_v_pu, self.vdl2_v_pu):
            check_that(self, self.soc_max_pu >= self.soc_min_pu,
                       f"SOCmax ({self.soc_max_pu}) must be >= SOCmin ({self.soc_min_pu})")
            for v, what in ((self.vdl1_v_pu, "Vq1..Vq4"), (self.vdl2_v_pu, "Vp1..Vp4")):
                check_that(self, np.all(np.diff(np.asarray(v)) > 0),
                           f"{what} must increase, got {np.asarray(v).tolist()}")

    def _tables(self, vm):
        return (jnp.interp(vm, self.vdl1_v_pu, self.vdl1_i_pu),
                jnp.interp(vm, self.vdl2_v_pu, self.vdl2_i_pu))

    def _ip_floor(self, ip_max):
        return -ip_max

    def _p_limits(self, state):
        soc = state[6]
        return (jnp.where(soc >= self.soc_max_pu, jnp.maximum(self.p_min_pu, 0.0), self.p_min_pu),
                jnp.where(soc <= self.soc_min_pu, jnp.minimum(self.p_max_pu, 0.0), self.p_max_pu))

    def _extra(self, state, u: ElectricalInputs):
        return [-u.p_pu / self.t_soc_s]

    def _extra_state(self, vt):
        return [self.soc_ini_pu + 0.0 * vt]


# --- REPCA1 -----------------------------------------------------------------------------------

class PlantInputs(NamedTuple):
    """What the plant controller measures (machine base; the branch is the unit's terminal)."""

    v_re_pu: Array
    v_im_pu: Array
    i_re_pu: Array
    """Branch current, real part [pu] (out of the unit, network frame)."""
    i_im_pu: Array
    p_pu: Array
    """Branch active power Pbranch [pu]."""
    q_pu: Array
    """Branch reactive power Qbranch [pu]."""
    freq_dev_pu: Array
    """Frequency deviation [pu]: Freq = 1 + this."""


class PlantReferences(NamedTuple):
    """The references of REPCA1 that hold its initial steady state."""

    v_ref_pu: Array
    """Vref [pu] (RefFlag = 1): the compensated voltage at the start."""
    q_ref_pu: Array
    """Qref [pu] (RefFlag = 0): Qbranch at the start."""
    p_ref_pu: Array
    """Plant_pref [pu]: Pbranch at the start."""


class REPCA1(eqx.Module):
    """PSS/E REPCA1 (WECC REPC_A), the plant controller.

    Block diagram (WECC REPC_A; PSS/E Model Library "REPCA1"):

        Vc  = |V - (Rc + j Xc) I| if VCFlag else |V| + Kc Qbranch;   Vf = 1/(1 + s Tfltr) Vc
        Qf  = 1/(1 + s Tfltr) Qbranch
        e   = clip(db(Vref - Vf if RefFlag else Qref - Qf, dbd1, dbd2), emin, emax)
        Qpi = PI(Kp, Ki)[e], limits [Qmin, Qmax], integrator frozen while |V| < Vfrz
        Qext = (1 + s Tft)/(1 + s Tfv) Qpi
        Pf  = 1/(1 + s Tp) Pbranch;  ef = db(1 - Freq, fdbd1, fdbd2)
        ep  = clip(Plant_pref - Pf + min(Ddn ef, 0) + max(Dup ef, 0), femin, femax)
        Ppi = PI(Kpg, Kig)[ep], limits [Pmin, Pmax];  Pref = 1/(1 + s Tg) Ppi   (Fflag = 1)
        Pref = Plant_pref                                                       (Fflag = 0)

    States: [Vf, Qf, PI_Q integrator, lead-lag, Pf, PI_P integrator, Pref lag]. The regulated
    bus and the monitored branch (ICONs) are taken at the unit's terminal: the branch flow is the
    unit's own output (recorded in ``regulated_bus`` and ``branch``, not used).
    """

    vcflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """VCFlag: 1 line drop compensation (Rc, Xc), 0 reactive droop (Kc)."""
    refflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """RefFlag: 1 voltage control, 0 reactive power control."""
    fflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """Fflag: 1 active power control with frequency droop, 0 Pref held."""
    regulated_bus: Int[Array, ""] = eqx.field(converter=_as_bus, default=0)
    """IREG ICON: the regulated bus (0: terminal); taken at the terminal. An array leaf, not a
    static field: plants of different buses share one compiled program."""
    branch: Int[Array, " 2"] = eqx.field(converter=_as_bus, default=(0, 0))
    """(from bus, to bus) ICONs of the monitored branch; taken at the terminal."""
    t_fltr_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Tfltr: voltage and reactive power filter [s] (0: none)."""
    kp: Float[Array, ""] = eqx.field(converter=as_float, default=18.0)
    """Kp: PI_Q proportional gain [pu/pu]."""
    ki: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """Ki: PI_Q integral gain [pu/pu/s]."""
    t_ft_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Tft: lead time constant [s]."""
    t_fv_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.075)
    """Tfv: lag time constant [s] (0: no lead-lag)."""
    vfrz_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Vfrz: voltage below which the PI_Q integrator freezes [pu]."""
    rc_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Rc: line drop compensation resistance [pu]."""
    xc_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Xc: line drop compensation reactance [pu]."""
    kc: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kc: reactive droop gain [pu/pu]."""
    e_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """emax: upper limit of the error [pu]."""
    e_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.1)
    """emin: lower limit of the error [pu]."""
    dbd1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """dbd1: lower edge of the error deadband [pu] (<= 0)."""
    dbd2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """dbd2: upper edge of the error deadband [pu] (>= 0)."""
    q_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.436)
    """Qmax: PI_Q output ceiling [pu]."""
    q_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.436)
    """Qmin: PI_Q output floor [pu]."""
    kpg: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Kpg: PI_P proportional gain [pu/pu]."""
    kig: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Kig: PI_P integral gain [pu/pu/s]."""
    t_p_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.25)
    """Tp: active power filter [s] (0: none)."""
    fdbd1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """fdbd1: lower edge of the frequency deadband [pu] (<= 0)."""
    fdbd2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """fdbd2: upper edge of the frequency deadband [pu] (>= 0)."""
    fe_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=999.0)
    """femax: upper limit of the power error [pu]."""
    fe_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-999.0)
    """femin: lower limit of the power error [pu]."""
    p_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=999.0)
    """Pmax: PI_P output ceiling [pu]."""
    p_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-999.0)
    """Pmin: PI_P output floor [pu]."""
    t_g_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """Tg (Tlag): lag of the plant's Pref [s] (0: none)."""
    ddn_pu: Float[Array, ""] = eqx.field(converter=as_float, default=20.0)
    """Ddn: down-regulation droop (over-frequency) [pu power / pu frequency]."""
    dup_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Dup: up-regulation droop (under-frequency) [pu power / pu frequency]."""

    n_states = 7

    def __check_init__(self):
        check_flag(self, "vcflag", "refflag", "fflag")
        check_nonnegative(self, "t_fltr_s", "t_ft_s", "t_fv_s", "ki", "kig", "t_p_s", "t_g_s",
                          "ddn_pu", "dup_pu")
        if all_concrete(self.e_max_pu, self.q_max_pu, self.p_max_pu, self.fe_max_pu,
                        self.dbd1_pu, self.fdbd1_pu):
            check_that(self, self.e_max_pu >= self.e_min_pu,
                       f"emax ({self.e_max_pu}) must be >= emin ({self.e_min_pu})")
            check_that(self, self.q_max_pu >= self.q_min_pu,
                       f"Qmax ({self.q_max_pu}) must be >= Qmin ({self.q_min_pu})")
            check_that(self, self.p_max_pu >= self.p_min_pu,
                       f"Pmax ({self.p_max_pu}) must be >= Pmin ({self.p_min_pu})")
            check_that(self, self.fe_max_pu >= self.fe_min_pu,
                       f"femax ({self.fe_max_pu}) must be >= femin ({self.fe_min_pu})")
            check_that(self, (self.dbd1_pu <= 0) & (self.dbd2_pu >= 0),
                       f"dbd1 ({self.dbd1_pu}) must be <= 0 <= dbd2 ({self.dbd2_pu})")
            check_that(self, (self.fdbd1_pu <= 0) & (self.fdbd2_pu >= 0),
                       f"fdbd1 ({self.fdbd1_pu}) must be <= 0 <= fdbd2 ({self.fdbd2_pu})")

    def compensated_voltage(self, u: PlantInputs):
        """Vc [pu]: line drop compensation (VCFlag = 1) or reactive droop (VCFlag = 0)."""
        d_re = u.v_re_pu - (self.rc_pu * u.i_re_pu - self.xc_pu * u.i_im_pu)
        d_im = u.v_im_pu - (self.rc_pu * u.i_im_pu + self.xc_pu * u.i_re_pu)
        return jnp.where(self.vcflag != 0, jnp.hypot(d_re, d_im),
                         jnp.hypot(u.v_re_pu, u.v_im_pu) + self.kc * u.q_pu)

    def _internals(self, state, u: PlantInputs, refs: PlantReferences):
        vf, _ = _lag(self.compensated_voltage(u), state[0], self.t_fltr_s)
        qf, _ = _lag(u.q_pu, state[1], self.t_fltr_s)
        err = jnp.where(self.refflag != 0, refs.v_ref_pu - vf, refs.q_ref_pu - qf)
        e = jnp.clip(deadband(err, self.dbd1_pu, self.dbd2_pu), self.e_min_pu, self.e_max_pu)
        q_raw = self.kp * e + state[2]
        q_pi = jnp.clip(q_raw, self.q_min_pu, self.q_max_pu)
        pf, _ = _lag(u.p_pu, state[4], self.t_p_s)
        ef = deadband(-u.freq_dev_pu, self.fdbd1_pu, self.fdbd2_pu)
        droop = jnp.minimum(self.ddn_pu * ef, 0.0) + jnp.maximum(self.dup_pu * ef, 0.0)
        ep = jnp.clip(refs.p_ref_pu - pf + droop, self.fe_min_pu, self.fe_max_pu)
        p_raw = self.kpg * ep + state[5]
        p_pi = jnp.clip(p_raw, self.p_min_pu, self.p_max_pu)
        return e, q_raw, q_pi, ep, p_raw, p_pi

    def outputs(self, state, u: PlantInputs, refs: PlantReferences):
        """(Pref, Qext) [pu]: the references the plant sends to the electrical controls."""
        _, _, q_pi, _, _, p_pi = self._internals(state, u, refs)
        q_ext, _ = _lead_lag(q_pi, state[3], self.t_ft_s, self.t_fv_s)
        p_ref, _ = _lag(p_pi, state[6], self.t_g_s)
        return jnp.where(self.fflag != 0, p_ref, refs.p_ref_pu + 0.0 * p_ref), q_ext

    def vector_field(self, state, u: PlantInputs, refs: PlantReferences):
        """d(state)/dt."""
        _, d_vf = _lag(self.compensated_voltage(u), state[0], self.t_fltr_s)
        _, d_qf = _lag(u.q_pu, state[1], self.t_fltr_s)
        e, q_raw, q_pi, ep, p_raw, p_pi = self._internals(state, u, refs)
        run = jnp.hypot(u.v_re_pu, u.v_im_pu) >= self.vfrz_pu
        d_xq = jnp.where(run, _blocked(q_raw, self.ki * e, self.q_min_pu, self.q_max_pu), 0.0)
        _, d_ll = _lead_lag(q_pi, state[3], self.t_ft_s, self.t_fv_s)
        _, d_pf = _lag(u.p_pu, state[4], self.t_p_s)
        d_xp = _blocked(p_raw, self.kig * ep, self.p_min_pu, self.p_max_pu)
        _, d_lag = _lag(p_pi, state[6], self.t_g_s)
        d_pf, d_xp, d_lag = (jnp.where(self.fflag != 0, d, 0.0) for d in (d_pf, d_xp, d_lag))
        return jnp.stack([d_vf, d_qf, d_xq, d_ll, d_pf, d_xp, d_lag])

    def initial_state(self, u: PlantInputs, p_ref, q_ext):
        """(state, PlantReferences): the steady state sending ``p_ref`` and ``q_ext`` [pu] at
        the measurements ``u`` (frequency deviation 0, no limit active)."""
        vc = self.compensated_voltage(u)
        q = u.q_pu + 0.0 * vc
        state = jnp.stack([vc, q, q_ext + 0.0 * vc, q_ext + 0.0 * vc, u.p_pu + 0.0 * vc,
                           p_ref + 0.0 * vc, p_ref + 0.0 * vc])
        return state, PlantReferences(vc, q, u.p_pu + 0.0 * vc)


# --- type-3 wind mechanics: WTDTA1, WTARA1, WTPTA1, WTTQA1 ----------------------------------
#
# Sources: WECC REMTF, *WECC Type 3 Wind Turbine Generator Model - Phase II* (2014): WTGT_A
# (two-mass drive train), WTGAR_A (aerodynamics), WTGPT_A (pitch), WTGTRQ_A (torque); Siemens
# PTI, *PSS(R)E Model Library* (WTDTA1, WTARA1, WTPTA1, WTTQA1: CON/ICON order); PowerWorld
# WebHelp "WTGPT_A and WTPTA1", "WTGAR_A and WTARA1", "WTGTRQ_A and WTTQA1" (parameter lists);
# the GridKit wind notes (ORNL, BSD-3), read for the block order only. Departures of ANDES that
# are *not* followed: the torque PI acts on (wg - wref) (more torque when the rotor runs fast);
# the pitch controller's speed reference is the torque controller's, after it is set; Freq1 is
# in Hz.

class WTDTA1(eqx.Module):
    """PSS/E WTDTA1 (WECC WTGT_A), the two-mass drive train of a type-3 wind turbine.

        Ht = Htfrac H,  Hg = H - Ht,  Kshaft = 2 Ht Hg (2 pi Freq1)^2 / (H wb)
        2 Ht dwt/dt = Pm/wt - Ts - Dshaft (wt - wg)
        2 Hg dwg/dt = Ts + Dshaft (wt - wg) - Pe/wg - DAMP (wg - w0)
        dths/dt = wb (wt - wg),  Ts = Kshaft ths                 (wb = 2 pi 60 rad/s)

    States: [wt, wg, ths] (speeds in pu, shaft twist in rad). Htfrac = 0 (or Freq1 = 0): one
    mass of inertia H, wt = wg (the twist kept at zero derivative). DAMP acts on the generator's
    deviation from its initial speed w0 (a reference of the start; the speeds of a type-3 turbine
    start below 1 pu, on the torque controller's speed table).
    """

    h_s: Float[Array, ""] = eqx.field(converter=as_float, default=4.95)
    """H: total inertia [s] (> 0)."""
    damp: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """DAMP: damping [pu torque / pu speed] (>= 0)."""
    htfrac: Float[Array, ""] = eqx.field(converter=as_float, default=0.92)
    """Htfrac: turbine share of the inertia, Ht/H [-] (0 <= Htfrac < 1; 0: one mass)."""
    freq1_hz: Float[Array, ""] = eqx.field(converter=as_float, default=1.8)
    """Freq1: first shaft torsional resonance [Hz] (>= 0; 0: one mass)."""
    dshaft: Float[Array, ""] = eqx.field(converter=as_float, default=1.5)
    """Dshaft: shaft damping [pu torque / pu speed] (>= 0)."""
    omega_b_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * math.pi * 60.0)
    """Base angular frequency of the shaft twist [rad/s]."""

    n_states = 3

    def __check_init__(self):
        check_positive(self, "h_s")
        check_nonnegative(self, "damp", "htfrac", "freq1_hz", "dshaft")
        if all_concrete(self.htfrac):
            check_that(self, self.htfrac < 1, f"Htfrac must be < 1, got {self.htfrac}")

    def _two_mass(self):
        return (self.htfrac > 0) & (self.freq1_hz > 0)

    def _k_shaft(self):
        ht = self.htfrac * self.h_s
        hg = self.h_s - ht
        return 2 * ht * hg * (2 * jnp.pi * self.freq1_hz) ** 2 / (self.h_s * self.omega_b_rad_s)

    def speeds(self, state):
        """(wt, wg) [pu]."""
        return state[0], state[1]

    def vector_field(self, state, p_mech, p_elec, w0):
        """d[wt, wg, ths]/dt with the mechanical and electrical power ``p_mech``, ``p_elec`` [pu]
        and the initial speed ``w0`` [pu] (DAMP's reference)."""
        wt, wg, ths = state[0], state[1], state[2]
        tm = p_mech / jnp.maximum(wt, 0.01)
        te = p_elec / jnp.maximum(wg, 0.01)
        two = self._two_mass()
        ht = jnp.where(two, self.htfrac * self.h_s, 1.0)
        hg = jnp.where(two, self.h_s - ht, 1.0)
        ts = self._k_shaft() * ths
        td = self.dshaft * (wt - wg)
        d_wt2 = (tm - ts - td) / (2 * ht)
        d_wg2 = (ts + td - te - self.damp * (wg - w0)) / (2 * hg)
        d_one = (tm - te - self.damp * (wg - w0)) / (2 * self.h_s)
        d_ths = jnp.where(two, self.omega_b_rad_s * (wt - wg), 0.0)
        return jnp.stack([jnp.where(two, d_wt2, d_one), jnp.where(two, d_wg2, d_one), d_ths])

    def initial_state(self, w0, p0):
        """The state at speed ``w0`` [pu] carrying power ``p0`` [pu] (Pm = Pe = p0)."""
        w0 = jnp.asarray(w0, float)
        k = jnp.where(self._two_mass(), self._k_shaft(), 1.0)
        ths = jnp.where(self._two_mass(), (p0 / w0) / k, 0.0)
        return jnp.stack([w0, w0 + 0.0 * ths, ths])


class WTARA1(eqx.Module):
    """PSS/E WTARA1 (WECC WTGAR_A), the aerodynamic model (no state):

        Pm = Pm0 - Ka theta (theta - theta0)

    with theta the blade pitch [deg] and Pm0 the mechanical power at the start [pu].
    """

    ka: Float[Array, ""] = eqx.field(converter=as_float, default=0.007)
    """Ka: aerodynamic gain [pu power / deg^2] (> 0, PowerWorld: an error otherwise)."""
    theta0_deg: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Theta0: initial pitch angle [deg] (>= 0)."""

    n_states = 0

    def __check_init__(self):
        check_positive(self, "ka")
        check_nonnegative(self, "theta0_deg")

    def mechanical_power(self, theta_deg, p_m0):
        """Pm [pu] at pitch ``theta_deg`` [deg], with Pm0 = ``p_m0`` [pu]."""
        return p_m0 - self.ka * theta_deg * (theta_deg - self.theta0_deg)


class WTPTA1(eqx.Module):
    """PSS/E WTPTA1 (WECC WTGPT_A), the pitch controller:

        eP  = Pord - Pord0;   ew = wt - wref + Kcc eP
        thw = PI(Kpw, Kiw)[ew], limits [thetamin, thetamax] (non-windup)
        thc = PI(Kpc, Kic)[eP], limits [thetamin, thetamax] (non-windup)
        theta = 1/(1 + s Tp) (thw + thc), rate [Rthetamin, Rthetamax], limits [thetamin, thetamax]

    States: [theta, PI_w integrator, PI_c integrator] (degrees). At the start eP = ew = 0: the
    speed integrator holds the initial pitch (WTARA1's Theta0), the compensator's holds 0.
    """

    kiw: Float[Array, ""] = eqx.field(converter=as_float, default=25.0)
    """Kiw: speed PI integral gain [deg / pu speed / s]."""
    kpw: Float[Array, ""] = eqx.field(converter=as_float, default=150.0)
    """Kpw: speed PI proportional gain [deg / pu speed]."""
    kic: Float[Array, ""] = eqx.field(converter=as_float, default=30.0)
    """Kic: compensator PI integral gain [deg / pu power / s]."""
    kpc: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """Kpc: compensator PI proportional gain [deg / pu power]."""
    kcc: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Kcc: cross gain of the power error into the speed error [pu speed / pu power]."""
    t_p_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.3)
    """Tp: blade response time constant [s] (> 0)."""
    theta_max_deg: Float[Array, ""] = eqx.field(converter=as_float, default=27.0)
    """Thetamax: maximum pitch [deg]."""
    theta_min_deg: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Thetamin: minimum pitch [deg] (<= Thetamax)."""
    r_theta_max_deg_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """RThetamax: pitch rate ceiling [deg/s] (> 0)."""
    r_theta_min_deg_s: Float[Array, ""] = eqx.field(converter=as_float, default=-10.0)
    """RThetamin: pitch rate floor [deg/s] (< 0)."""

    n_states = 3

    def __check_init__(self):
        check_positive(self, "t_p_s", "r_theta_max_deg_s")
        check_nonnegative(self, "kiw", "kic")
        if all_concrete(self.theta_max_deg, self.theta_min_deg, self.r_theta_min_deg_s):
            check_that(self, self.theta_max_deg >= self.theta_min_deg,
                       f"Thetamax ({self.theta_max_deg}) must be >= Thetamin ({self.theta_min_deg})")
            check_that(self, self.r_theta_min_deg_s < 0,
                       f"RThetamin must be < 0, got {self.r_theta_min_deg_s}")

    def _internals(self, state, wt, w_ref, p_ord, p_ord0):
        e_p = p_ord - p_ord0
        e_w = wt - w_ref + self.kcc * e_p
        lo, hi = self.theta_min_deg, self.theta_max_deg
        w_raw = self.kpw * e_w + state[1]
        c_raw = self.kpc * e_p + state[2]
        cmd = jnp.clip(w_raw, lo, hi) + jnp.clip(c_raw, lo, hi)
        return e_w, e_p, w_raw, c_raw, cmd

    def pitch(self, state):
        """theta [deg]."""
        return jnp.clip(state[0], self.theta_min_deg, self.theta_max_deg)

    def vector_field(self, state, wt, w_ref, p_ord, p_ord0):
        """d(state)/dt at turbine speed ``wt`` and reference ``w_ref`` [pu], power order
        ``p_ord`` and its initial value ``p_ord0`` [pu]."""
        e_w, e_p, w_raw, c_raw, cmd = self._internals(state, wt, w_ref, p_ord, p_ord0)
        lo, hi = self.theta_min_deg, self.theta_max_deg
        d_th = jnp.clip((cmd - state[0]) / self.t_p_s, self.r_theta_min_deg_s, self.r_theta_max_deg_s)
        return jnp.stack([_blocked(state[0], d_th, lo, hi),
                          _blocked(w_raw, self.kiw * e_w, lo, hi),
                          _blocked(c_raw, self.kic * e_p, lo, hi)])

    def initial_state(self, theta0_deg):
        """The state at rest with pitch ``theta0_deg`` [deg]."""
        th = jnp.asarray(theta0_deg, float)
        return jnp.stack([th, th, 0.0 * th])


class WTTQA1(eqx.Module):
    """PSS/E WTTQA1 (WECC WTGTRQ_A), the torque controller of a type-3 wind turbine:

        Pm  = 1/(1 + s Tp) Pe;   wref = 1/(1 + s Twref) f(Pm)     (f: the (P1, spd1)..(P4, spd4)
                                                                   table, flat outside)
        Tflag = 1: eT = wg - wref;   Tflag = 0 or 2: eT = (Pref0 - Pm)/wg
        Tref = PI(Kpp, Kip)[eT], limits [Temin, Temax] (Tflag = 2: [Temin, Pref0/wg]; non-windup,
               integrator frozen in a dip)
        Pref = Tref wg   (to REECA1)

    States: [Pm, wref, PI integrator]. Pref0 is the plant controller's Pref (or the held initial
    power). TRATE (the turbine rating, 0: MBASE) must be 0.
    """

    tflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """Tflag (ICON): 1 speed control, 0 power (torque) control, 2 power control with the torque
    ceiling Pref0/wg (PowerWorld WebHelp "WTGTRQ_A": "2=Alternative with Pref0 feeding to Temax
    value")."""
    kpp: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """Kpp: PI proportional gain [pu torque / pu]."""
    kip: Float[Array, ""] = eqx.field(converter=as_float, default=0.6)
    """Kip: PI integral gain [pu torque / pu / s] (>= 0)."""
    t_p_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Tp: electrical power filter [s] (0: none)."""
    t_wref_s: Float[Array, ""] = eqx.field(converter=as_float, default=60.0)
    """Twref: speed reference filter [s] (0: none)."""
    te_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.2)
    """Temax: torque ceiling [pu]."""
    te_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Temin: torque floor [pu] (<= Temax)."""
    table_p_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(0.2, 0.4, 0.6, 0.8))
    """P1..P4: powers of the speed table [pu] (non-decreasing)."""
    table_w_pu: Float[Array, " 4"] = eqx.field(converter=as_float, default=(0.58, 0.72, 0.86, 1.2))
    """spd1..spd4: speeds of the speed table [pu] (> 0)."""
    trate_mw: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TRATE: turbine rating [MW] (0: MBASE; only 0 is simulated)."""

    n_states = 3

    def __check_init__(self):
        check_flag(self, "tflag", allowed=(0, 1, 2))
        check_nonnegative(self, "kip", "t_p_s", "t_wref_s")
        check_positive(self, "table_w_pu")
        if all_concrete(self.te_max_pu, self.te_min_pu, self.table_p_pu, self.trate_mw):
            check_that(self, self.te_max_pu >= self.te_min_pu,
                       f"Temax ({self.te_max_pu}) must be >= Temin ({self.te_min_pu})")
            check_that(self, np.all(np.diff(np.asarray(self.table_p_pu)) >= 0),
                       f"P1..P4 must not decrease, got {np.asarray(self.table_p_pu).tolist()}")
            # (ibr_from_dyr reads a record's points in order of P: see _read)
            check_that(self, self.trate_mw == 0,
                       f"TRATE = {self.trate_mw:g} MW: only TRATE = 0 (the machine base) is simulated")

    def speed_table(self, p):
        """f(P) [pu speed]: the speed reference at power ``p`` [pu]."""
        return jnp.interp(p, self.table_p_pu, self.table_w_pu)

    def _internals(self, state, p_elec, wg, p_ref0):
        pm, _ = _lag(p_elec, state[0], self.t_p_s)
        w_ref, _ = _lag(self.speed_table(pm), state[1], self.t_wref_s)
        e_t = jnp.where(self.tflag == 1, wg - w_ref, (p_ref0 - pm) / jnp.maximum(wg, 0.01))
        raw = self.kpp * e_t + state[2]
        return pm, w_ref, e_t, raw

    def _ceiling(self, wg, p_ref0):
        return jnp.where(self.tflag == 2, p_ref0 / jnp.maximum(wg, 0.01), self.te_max_pu)

    def outputs(self, state, p_elec, wg, p_ref0):
        """(Pref to REECA1 [pu], wref [pu])."""
        _, w_ref, _, raw = self._internals(state, p_elec, wg, p_ref0)
        return jnp.clip(raw, self.te_min_pu, self._ceiling(wg, p_ref0)) * wg, w_ref

    def vector_field(self, state, p_elec, wg, p_ref0, dip):
        """d(state)/dt at Pe = ``p_elec``, generator speed ``wg``, plant reference ``p_ref0``
        [pu]; the integrator is frozen while ``dip`` (REECA1's voltage-dip flag)."""
        pm, w_ref, e_t, raw = self._internals(state, p_elec, wg, p_ref0)
        _, d_pm = _lag(p_elec, state[0], self.t_p_s)
        _, d_w = _lag(self.speed_table(pm), state[1], self.t_wref_s)
        d_x = jnp.where(dip, 0.0, _blocked(raw, self.kip * e_t, self.te_min_pu, self._ceiling(wg, p_ref0)))
        return jnp.stack([d_pm, d_w, d_x])

    def initial_state(self, p0, p_ref_e):
        """(state, w0): the state at rest with Pe = ``p0`` and the Pref that REECA1 needs,
        ``p_ref_e`` [pu], and the rotor speed w0 = f(p0) [pu] that it holds (eT = 0)."""
        p0 = jnp.asarray(p0, float)
        w0 = self.speed_table(p0)
        return jnp.stack([p0, w0, p_ref_e / w0]), w0


# --- PSS/E records ----------------------------------------------------------------------------

# --- REGCV1 / REGCV2 (grid-forming) --------------------------------------------------------------

class GfmInputs(NamedTuple):
    """What a grid-forming converter sees at one instant (machine base, network frame)."""

    v_re_pu: Array
    """Terminal voltage, real part [pu] (frame rotating at nominal frequency)."""
    v_im_pu: Array
    """Terminal voltage, imaginary part [pu]."""


class GfmReferences(NamedTuple):
    """The set points that hold the initial steady state (constant during a playback)."""

    p_ref_pu: Array
    """Pref: active-power reference of the swing equation [pu on Sn] (ANDES: gammap p0s)."""
    q_ref_pu: Array
    """Qref: reactive-power reference of the Q-V droop [pu on Sn]."""
    v_ref_pu: Array
    """vref: terminal-voltage reference [pu] (ANDES: the static generator's set point)."""
    id0_pu: Array
    """Initial d-axis current [pu] (initial value of the vd PI's integrator)."""
    iq0_pu: Array
    """Initial q-axis current [pu] (initial value of the vq PI's integrator)."""


class GfmSignals(NamedTuple):
    """A grid-forming converter's outputs at one instant (machine base)."""

    i_re_pu: Array
    """Current out of the terminal, real part, network frame [pu]."""
    i_im_pu: Array
    p_pu: Array
    """Active power out of the terminal [pu] (Pe of the swing equation)."""
    q_pu: Array
    """Reactive power out of the terminal [pu]."""
    omega_pu: Array
    """Virtual rotor speed 1 + dw [pu]."""
    delta_rad: Array
    """Virtual rotor angle in the network frame [rad] (the d axis)."""
    vd_pu: Array
    vq_pu: Array
    id_pu: Array
    iq_pu: Array


class REGCV1(eqx.Module):
    """ANDES REGCV1: a voltage-source converter with virtual-synchronous-generator control
    (ANDES 2.0 model reference, ``andes/models/renewable/regcv1.py``; the names are ANDES's).

    Block diagram (per unit on Sn; rotor frame: V e^{-j delta} = vd + j vq, I e^{-j delta} =
    Id + j Iq, current out of the terminal):

        swing:     M d(dw)/dt = Pref - kw dw - Pe - D dw,   d(delta)/dt = omega_s dw,
                   Pe = vd Id + vq Iq,  Qe = vq Id - vd Iq   (terminal powers; no 1/omega)
        Q droop:   vref2 = vref + kv (Qref - Qe)
        outer PI:  Idref = PI(Kpvd, Kivd)(vd - vref2),  Iqref = PI(Kpvq, Kivq)(vq)
        inner PI:  udref = PI(KpId, KiId)(Id - Idref) + vd - xs Iqref,
                   uqref = PI(KpIq, KiIq)(Iq - Iqref) + vq + xs Idref
        modulator: ud = 1/(1 + s Tc) udref,  uq = 1/(1 + s Tc) uqref
        source:    ud + j uq = (vd + j vq) + (ra + j xs)(Id + j Iq)   (internal voltage behind
                   ra + j xs, which gives Id, Iq from the states and V)

    PI(kp, ki)(u) = kp u + x with dx/dt = ki u. States: [dw, delta, x_vd, x_vq, x_Id, x_Iq,
    ud, uq]. The swing equation's "rotor" is the virtual one: delta is the angle of the d axis,
    along the terminal voltage in steady state (vq = 0), not the angle of the internal voltage.
    REGCV2 (``inner = "lag"``) replaces the inner PI and the modulator with first-order lags of
    the current references: Id = 1/(1 + s Tid) Idref, Iq = 1/(1 + s Tiq) Iqref (states 6, 7 are
    then Id, Iq; x_Id, x_Iq stay at 0).
    """

    inner: str = eqx.field(static=True, default="pi")
    """"pi": REGCV1 (inner current PI + modulator lag); "lag": REGCV2 (current lags)."""
    m_s: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """M: emulated starting time M = 2H [s] (> 0)."""
    d_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """D: emulated damping [pu power / pu speed] (>= 0)."""
    kw_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """kw: frequency droop on active power, reciprocal of the droop [pu power / pu speed]."""
    kv_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """kv: reactive-power droop on the voltage reference [pu voltage / pu Q]."""
    ra_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """ra: resistance between the internal voltage and the terminal [pu on Sn]."""
    xs_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """xs: reactance between the internal voltage and the terminal [pu on Sn] (> 0)."""
    t_c_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """Tc: modulator (switching) lag [s] (REGCV1; > 0)."""
    kpvd: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """Kpvd: vd PI proportional gain [pu current / pu voltage]."""
    kivd: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Kivd: vd PI integral gain [pu current / (pu voltage s)]."""
    kpvq: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """Kpvq: vq PI proportional gain [pu current / pu voltage]."""
    kivq: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """Kivq: vq PI integral gain [pu current / (pu voltage s)]."""
    kpid: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """KpId: Id PI proportional gain [pu voltage / pu current] (REGCV1)."""
    kiid: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """KiId: Id PI integral gain [pu voltage / (pu current s)] (REGCV1)."""
    kpiq: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """KpIq: Iq PI proportional gain [pu voltage / pu current] (REGCV1)."""
    kiiq: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """KiIq: Iq PI integral gain [pu voltage / (pu current s)] (REGCV1)."""
    t_id_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """Tid: Id lag [s] (REGCV2; > 0)."""
    t_iq_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """Tiq: Iq lag [s] (REGCV2; > 0)."""
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * math.pi * 60.0)
    """Nominal angular frequency 2 pi fn [rad/s]."""

    n_states = 8
    angle_state = 1
    """Index of the virtual rotor's angle delta in the state [rad]."""
    judged_with_voltage_imposed = False
    """Against an imposed terminal voltage its d axis has no synchronising power (two modes at 0
    at rest): ``jaxdse check`` runs its steps without judging them."""

    def __check_init__(self):
        if self.inner not in ("pi", "lag"):
            raise ValueError(f"REGCV1.inner must be 'pi' or 'lag', got {self.inner!r}")
        check_positive(self, "m_s", "xs_pu", "t_c_s", "t_id_s", "t_iq_s", "omega_s_rad_s")
        check_nonnegative(self, "d_pu", "kw_pu", "kv_pu", "ra_pu")

    @property
    def h_s(self):
        """The emulated inertia constant H = M/2 [s]."""
        return self.m_s / 2

    def _rotor_frame(self, y, u: GfmInputs):
        c, s = jnp.cos(y[1]), jnp.sin(y[1])
        return u.v_re_pu * c + u.v_im_pu * s, u.v_im_pu * c - u.v_re_pu * s

    def _currents(self, y, vd, vq):
        if self.inner == "lag":
            return y[6], y[7]
        # (ra + j xs)(Id + j Iq) = (ud - vd) + j (uq - vq)
        a, b = y[6] - vd, y[7] - vq
        det = self.ra_pu**2 + self.xs_pu**2
        return (self.ra_pu * a + self.xs_pu * b) / det, (self.ra_pu * b - self.xs_pu * a) / det

    def signals(self, y, u: GfmInputs, refs: GfmReferences) -> GfmSignals:
        """The outputs at state ``y`` under terminal voltage ``u``."""
        vd, vq = self._rotor_frame(y, u)
        i_d, i_q = self._currents(y, vd, vq)
        c, s = jnp.cos(y[1]), jnp.sin(y[1])
        return GfmSignals(i_d * c - i_q * s, i_d * s + i_q * c, vd * i_d + vq * i_q,
                          vq * i_d - vd * i_q, 1.0 + y[0], y[1], vd, vq, i_d, i_q)

    def vector_field(self, y, u: GfmInputs, refs: GfmReferences):
        """d(state)/dt under terminal voltage ``u``."""
        sig = self.signals(y, u, refs)
        dw = y[0]
        vref2 = refs.v_ref_pu + self.kv_pu * (refs.q_ref_pu - sig.q_pu)
        e_vd, e_vq = sig.vd_pu - vref2, sig.vq_pu
        id_ref = self.kpvd * e_vd + y[2]
        iq_ref = self.kpvq * e_vq + y[3]
        d_dw = (refs.p_ref_pu - self.kw_pu * dw - sig.p_pu - self.d_pu * dw) / self.m_s
        d_delta = self.omega_s_rad_s * dw
        if self.inner == "lag":
            zero = jnp.zeros_like(dw)
            d_x, d_y = zero, zero
            d6 = (id_ref - sig.id_pu) / self.t_id_s
            d7 = (iq_ref - sig.iq_pu) / self.t_iq_s
        else:
            e_id, e_iq = sig.id_pu - id_ref, sig.iq_pu - iq_ref
            d_x, d_y = self.kiid * e_id, self.kiiq * e_iq
            udref = self.kpid * e_id + y[4] + sig.vd_pu - self.xs_pu * iq_ref
            uqref = self.kpiq * e_iq + y[5] + sig.vq_pu + self.xs_pu * id_ref
            d6 = (udref - y[6]) / self.t_c_s
            d7 = (uqref - y[7]) / self.t_c_s
        return jnp.stack([d_dw, d_delta, self.kivd * e_vd, self.kivq * e_vq, d_x, d_y, d6, d7])

    def initial_state(self, u: GfmInputs, i_re, i_im):
        """(state, references): the steady state that delivers current ``I`` (out of the
        terminal, network frame) at ``u``'s voltage: dw = 0, the d axis along V (vq = 0),
        Pref = P, Qref = Q, vref = |V| (as ANDES initialises from its power flow)."""
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        delta = jnp.arctan2(u.v_im_pu, u.v_re_pu)
        p = u.v_re_pu * i_re + u.v_im_pu * i_im
        q = u.v_im_pu * i_re - u.v_re_pu * i_im
        i_d, i_q = p / vt, -q / vt
        zero = jnp.zeros_like(vt)
        if self.inner == "lag":
            x_id, x_iq, s6, s7 = zero, zero, i_d, i_q
        else:
            # inner PI integrators: udref = ud with Id = Idref, Iq = Iqref
            x_id, x_iq = self.ra_pu * i_d, self.ra_pu * i_q
            s6 = vt + self.ra_pu * i_d - self.xs_pu * i_q
            s7 = self.ra_pu * i_q + self.xs_pu * i_d
        y0 = jnp.stack([zero, delta, i_d, i_q, x_id, x_iq, s6, s7])
        return y0, GfmReferences(p, q, vt, i_d, i_q)


# --- REGFM_A1 ---------------------------------------------------------------------------------

GFM_FILTER_FLOOR_S = 0.01
"""REGFM_A1: a measurement filter (TPf, TQf, TVf) of 0 is kept as a lag of this time constant [s].
A pass-through of Q would close an algebraic loop (E -> Q -> Vcmd -> E); PowerWorld likewise raises
a filter below Mult x its time step to that value (WebHelp "Machine Model: REGFM_A1")."""


def source_behind(e, delta, u: GfmInputs, re, xe, i_max, omega) -> GfmSignals:
    """A voltage source E at angle ``delta`` behind Re + j Xe against the terminal voltage ``u``:
    I = (E e^{j delta} - V) / (Re + j Xe), within the circular limit ``i_max`` that keeps its angle
    (0: none; the states are not reset), and the outputs in the frame of ``delta``."""
    c, s = jnp.cos(delta), jnp.sin(delta)
    z2 = re**2 + xe**2
    a, b = e * c - u.v_re_pu, e * s - u.v_im_pu
    i_re, i_im = (a * re + b * xe) / z2, (b * re - a * xe) / z2
    mag = jnp.hypot(i_re, i_im)
    over = (i_max > 0) & (mag > i_max)
    k = jnp.where(over, i_max / jnp.where(over, mag, 1.0), 1.0)
    i_re, i_im = k * i_re, k * i_im
    return GfmSignals(i_re, i_im, u.v_re_pu * i_re + u.v_im_pu * i_im, u.v_im_pu * i_re - u.v_re_pu * i_im,
                      omega, delta, u.v_re_pu * c + u.v_im_pu * s, u.v_im_pu * c - u.v_re_pu * s,
                      i_re * c + i_im * s, i_im * c - i_re * s)


class REGFM_A1(eqx.Module):
    """PSS/E REGFMA1 (WECC REGFM_A1): a droop-controlled grid-forming inverter, a voltage source
    E at angle delta behind the coupling impedance Re + j Xe (the generator's ZSORCE on MBASE).

    Block diagram (PNNL-35110, *Model Specification of Droop-Controlled, Grid-Forming Inverters
    (REGFM_A1)*, 2023; record order of the PSS/E Model Library as psspy writes it; per unit on
    MBASE, omega_0 = 2 pi f0):

        filters:   Pm = 1/(1 + s TPf) P,  Qm = 1/(1 + s TQf) Q,  Vm = 1/(1 + s TVf) |V|
        P limits:  dwPmax = min(0, kppmax (Pmax - Pm) + xPmax),  dxPmax/dt = kipmax (Pmax - Pm), xPmax <= 0
                   dwPmin = max(0, kppmax (Pmin - Pm) + xPmin),  dxPmin/dt = kipmax (Pmin - Pm), xPmin >= 0
        P-f droop: dw = mp (Pref - Pm) + dwPmax + dwPmin,  d(delta)/dt = omega_0 dw
        Q limits:  dVQmax, dVQmin as dwPmax, dwPmin with kpqmax, kiqmax, Qmax, Qmin, Qm
        Q-V droop: Vcmd = Vref + mq (Qref - Qm) + dVQmax + dVQmin
        voltage:   VFlag = 0: E = clip(Vcmd, Emin, Emax);
                   VFlag = 1: E = clip(kpv (Vcmd - Vm) + xE, Emin, Emax), dxE/dt = kiv (Vcmd - Vm)
                   (xE non-windup within [Emin, Emax])
        source:    I0 = (E e^{j delta} - V) / (Re + j Xe);  Imax > 0 and |I0| > Imax: I = Imax I0/|I0|
                   (the current's angle kept; the states are not reset), else I = I0

    P + jQ = V conj(I) with the limited current. QVFlag chooses which reference a plant controller
    moves (0: Qref, 1: Vref with Qref = 0); with both references held, as in a playback, the two
    are the same model. States: [delta, xE, Pm, Qm, Vm, xPmax, xPmin, xQmax, xQmin] (PowerWorld's
    order, angle first). Its equivalent swing equation (TPf dw/dt = mp (Pref - P) - dw, within the
    limits) has 2H = TPf / mp and D = 1 / mp on MBASE.
    """

    vflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """VFlag (ICON): 0 the droop sets E directly, 1 a PI on the terminal voltage sets E."""
    qvflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """QVFlag (ICON): the plant controller's input, 0 Qref, 1 Vref (no effect with both held)."""
    t_pf_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TPf: active-power measurement filter [s] (0: :data:`GFM_FILTER_FLOOR_S`)."""
    t_qf_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TQf: reactive-power measurement filter [s] (0: :data:`GFM_FILTER_FLOOR_S`)."""
    t_vf_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TVf: terminal-voltage measurement filter [s] (0: :data:`GFM_FILTER_FLOOR_S`)."""
    i_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """Imax: current limit [pu on MBASE] (0: none)."""
    e_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.2)
    """Emax: upper limit of the internal voltage [pu]."""
    e_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Emin: lower limit of the internal voltage [pu]."""
    p_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """Pmax: active-power limit of the overload controller [pu on MBASE]."""
    p_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Pmin: lower active-power limit [pu on MBASE] (negative for storage)."""
    q_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """Qmax: reactive-power limit of the overload controller [pu on MBASE]."""
    q_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-1.0)
    """Qmin: lower reactive-power limit [pu on MBASE]."""
    mp: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """mp: P-f droop [pu frequency / pu power] (> 0)."""
    mq: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """mq: Q-V droop [pu voltage / pu reactive power] (>= 0)."""
    kppmax: Float[Array, ""] = eqx.field(converter=as_float, default=0.01)
    """kppmax: proportional gain of the Pmax/Pmin controllers [pu frequency / pu power]."""
    kipmax: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """kipmax: integral gain of the Pmax/Pmin controllers [pu frequency / (pu power s)]."""
    kpqmax: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """kpqmax: proportional gain of the Qmax/Qmin controllers [pu voltage / pu reactive power]."""
    kiqmax: Float[Array, ""] = eqx.field(converter=as_float, default=20.0)
    """kiqmax: integral gain of the Qmax/Qmin controllers [pu voltage / (pu reactive power s)]."""
    kpv: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """kpv: voltage PI proportional gain [pu / pu] (VFlag = 1)."""
    kiv: Float[Array, ""] = eqx.field(converter=as_float, default=5.86)
    """kiv: voltage PI integral gain [pu / (pu s)] (> 0)."""
    re_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Re: coupling resistance [pu on MBASE] (the generator's ZSORCE, not a CON)."""
    xe_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.15)
    """Xe: coupling reactance [pu on MBASE] (the generator's ZSORCE, not a CON; > 0)."""
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * math.pi * 60.0)
    """Nominal angular frequency 2 pi f0 [rad/s]."""

    n_states = 9
    angle_state = 0
    """Index of the source's angle delta in the state [rad]."""
    judged_with_voltage_imposed = True
    """Against an imposed terminal voltage the source behind Xe synchronises (P turns with the
    angle difference), so ``jaxdse check`` judges its steps."""

    def __check_init__(self):
        check_flag(self, "vflag", "qvflag")
        check_positive(self, "mp", "kiv", "xe_pu", "omega_s_rad_s")
        check_nonnegative(self, "t_pf_s", "t_qf_s", "t_vf_s", "i_max_pu", "mq", "kppmax", "kipmax",
                          "kpqmax", "kiqmax", "kpv", "re_pu", "e_min_pu")
        if all_concrete(self.e_max_pu, self.e_min_pu, self.p_max_pu, self.p_min_pu, self.q_max_pu,
                        self.q_min_pu):
            check_that(self, self.e_max_pu > self.e_min_pu,
                       f"Emax must be > Emin, got {self.e_max_pu}, {self.e_min_pu}")
            check_that(self, self.p_max_pu > self.p_min_pu,
                       f"Pmax must be > Pmin, got {self.p_max_pu}, {self.p_min_pu}")
            check_that(self, self.q_max_pu > self.q_min_pu,
                       f"Qmax must be > Qmin, got {self.q_max_pu}, {self.q_min_pu}")

    @property
    def h_s(self):
        """The inertia of its equivalent swing equation, H = TPf / (2 mp) [s on MBASE]."""
        return self.t_pf_s / (2 * self.mp)

    def _filter(self, t):
        return jnp.maximum(t, GFM_FILTER_FLOOR_S)

    def _overload(self, err, x, kp):
        """(upper output <= 0, lower output >= 0) of the two limit PIs (err = (limit - measured))."""
        return jnp.minimum(0.0, kp * err[0] + x[0]), jnp.maximum(0.0, kp * err[1] + x[1])

    def _internal(self, y, refs: GfmReferences):
        """(dw, Vcmd, E): the droops' outputs at state ``y``."""
        pm, qm, vm = y[2], y[3], y[4]
        up, lo = self._overload((self.p_max_pu - pm, self.p_min_pu - pm), (y[5], y[6]), self.kppmax)
        dw = self.mp * (refs.p_ref_pu - pm) + up + lo
        qu, ql = self._overload((self.q_max_pu - qm, self.q_min_pu - qm), (y[7], y[8]), self.kpqmax)
        vcmd = refs.v_ref_pu + self.mq * (refs.q_ref_pu - qm) + qu + ql
        e = jnp.where(self.vflag != 0, self.kpv * (vcmd - vm) + y[1], vcmd)
        return dw, vcmd, jnp.clip(e, self.e_min_pu, self.e_max_pu)

    def signals(self, y, u: GfmInputs, refs: GfmReferences) -> GfmSignals:
        """The outputs at state ``y`` under terminal voltage ``u``."""
        dw, _, e = self._internal(y, refs)
        return source_behind(e, y[0], u, self.re_pu, self.xe_pu, self.i_max_pu, 1.0 + dw)

    def vector_field(self, y, u: GfmInputs, refs: GfmReferences):
        """d(state)/dt under terminal voltage ``u``."""
        sig = self.signals(y, u, refs)
        dw, vcmd, _ = self._internal(y, refs)
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        pm, qm, vm = y[2], y[3], y[4]
        d_xe = jnp.where(self.vflag != 0,
                         _blocked(y[1], self.kiv * (vcmd - vm), self.e_min_pu, self.e_max_pu), 0.0)
        big = jnp.inf
        return jnp.stack([
            self.omega_s_rad_s * dw, d_xe,
            (sig.p_pu - pm) / self._filter(self.t_pf_s), (sig.q_pu - qm) / self._filter(self.t_qf_s),
            (vt - vm) / self._filter(self.t_vf_s),
            _blocked(y[5], self.kipmax * (self.p_max_pu - pm), -big, 0.0),
            _blocked(y[6], self.kipmax * (self.p_min_pu - pm), 0.0, big),
            _blocked(y[7], self.kiqmax * (self.q_max_pu - qm), -big, 0.0),
            _blocked(y[8], self.kiqmax * (self.q_min_pu - qm), 0.0, big)])

    def initial_state(self, u: GfmInputs, i_re, i_im):
        """(state, references): the steady state that delivers current ``I`` (out of the terminal,
        network frame) at ``u``'s voltage: E e^{j delta} = V + (Re + j Xe) I, the filters at P, Q,
        |V|, the limit controllers at 0, Pref = P; QVFlag = 0: Qref = Q, Vref = Vcmd; QVFlag = 1:
        Qref = 0, Vref = Vcmd + mq Q (Vcmd = E with VFlag = 0, |V| with VFlag = 1)."""
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        e_re = u.v_re_pu + self.re_pu * i_re - self.xe_pu * i_im
        e_im = u.v_im_pu + self.re_pu * i_im + self.xe_pu * i_re
        e, delta = jnp.hypot(e_re, e_im), jnp.arctan2(e_im, e_re)
        p = u.v_re_pu * i_re + u.v_im_pu * i_im
        q = u.v_im_pu * i_re - u.v_re_pu * i_im
        vcmd = jnp.where(self.vflag != 0, vt, e)
        qv = self.qvflag != 0
        q_ref = jnp.where(qv, 0.0, q)
        v_ref = jnp.where(qv, vcmd + self.mq * q, vcmd)
        zero = jnp.zeros_like(vt)
        c, s = jnp.cos(delta), jnp.sin(delta)
        y0 = jnp.stack([delta, e, p, q, vt, zero, zero, zero, zero])
        return y0, GfmReferences(p, q_ref, v_ref, i_re * c + i_im * s, i_im * c - i_re * s)


# --- REGFM_B1 ---------------------------------------------------------------------------------

LIMIT_RESET_S = 1e-3
"""REGFM_B1: a state outside a limit that moved past it (the angle limits dITmax, dITmin; E's
limits Emin, Emax) is brought to it with this time constant [s] (a non-windup state sits on its
limit; an ODE relaxes it, fast against every loop of the model)."""


class REGFM_B1(eqx.Module):
    """PSS/E REGFMB1U (WECC REGFM_B1): a grid-forming inverter with virtual-synchronous-machine
    control, a voltage source E at angle delta_VSM behind Re + j XL (the generator's ZSORCE on
    MBASE).

    Block diagram (NREL/TP-5D00-90260, *Virtual Synchronous Machine Grid-Forming Inverter Model
    Specification (REGFM_B1)*, 2024, as implementations that cite it write it out; CON order of
    the PSS/E Model Library as psspy writes it; per unit on MBASE, omega_0 = 2 pi f0; the PLL
    frame: V e^{-j dPLL} = VdPLL + j VqPLL, I e^{-j dPLL} = Id - j Iq, Iq > 0 injecting vars):

        filters:  Pinv, Qinv, Vinv, Idinv, Iqinv = 1/(1 + s T) of P, Q, |V|, Id, Iq (TPf, TQf,
                  TVf, TIf, TIf)
        PLL:      VqPLL = |V| sin(theta - dPLL); below VPLLfrz both states frozen;
                  dwPLL = clip(kpPLL VqPLL + xPLL, DwPLLmin, DwPLLmax), dxPLL/dt = kiPLL VqPLL,
                  d(dPLL)/dt = omega_0 dwPLL
        swing:    2H d(dwm)/dt = Pref + FFlag dP - Pinv - D1 dwm - D2 (dwm - xD), within
                  [Dwmin, Dwmax] (non-windup); dxD/dt = wD (dwm - xD);
                  dP = -(1/mp) 1/(1 + s Tp) (dwm, or dwPLL with wFlag = 1)
        angle:    d(dIT)/dt = omega_0 (dwm - dwPLL) within [dITmin, dITmax] (non-windup);
                  delta_VSM = dPLL + dIT
        limits:   PQFlag = 1: IdmaxSS = kf ImaxSS, IqmaxSS = sqrt(ImaxSS^2 - Idinv^2);
                  PQFlag = 0: IqmaxSS = kf ImaxSS, IdmaxSS = sqrt(ImaxSS^2 - Iqinv^2);
                  Emax, Emin = sqrt((Vinv +- IqmaxSS XL)^2 + (Idinv XL)^2);
                  dmax = asin(XL ImaxSS); d(dITmax)/dt = kI (IdmaxSS - Idinv) in [0, dmax];
                  d(dITmin)/dt = kI (-Ke IdmaxSS - Idinv) in [-dmax, 0] (ESFlag = 1; 0 without)
        Q-V:      Vcmd = Vref + mq (Qref - Qinv) (VdrpFlag = 0 or QVFlag = 0), Vref - mq Iqinv
                  (current droop); E = clip(kpv (Vcmd - Vinv) + xV, Emin, Emax), dxV/dt = kiv
                  (Vcmd - Vinv), non-windup within [Emin, Emax]
        source:   I0 = (E e^{j delta_VSM} - V) / (Re + j XL); |I0| > ImaxF: I = ImaxF I0/|I0|

    States: [Pinv, Qinv, Vinv, Idinv, Iqinv, xPLL, dPLL, xTp, xD, dwm, dIT, dITmax, dITmin, xV].
    A filter time constant of 0 (TPf, TQf, TVf, TIf) is kept as a :data:`GFM_FILTER_FLOOR_S`
    lag (a pass-through closes algebraic loops through the source); Tp = 0 is a pass-through.
    """

    wflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """wFlag (ICON): the droop's speed, 0 the VSM's dwm, 1 the PLL's dwPLL."""
    vdrpflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """VdrpFlag (ICON): 0 Q-V droop, 1 current droop (with QVFlag = 1)."""
    qvflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """QVFlag (ICON): the plant controller's input, 0 Qref, 1 Vref."""
    pqflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """PQFlag (ICON): steady-state current priority, 0 reactive, 1 active."""
    fflag: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """FFlag (ICON): 1 the P-f droop acts, 0 not."""
    esflag: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """ESFlag (ICON): 1 storage (negative angle and current allowed), 0 a generator."""
    mq: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """mq: Q-V droop [pu/pu] (a virtual impedance with VdrpFlag = 1)."""
    kpv: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """kpv: voltage PI proportional gain [pu/pu]."""
    kiv: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """kiv: voltage PI integral gain [pu/(pu s)] (> 0)."""
    mp: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """mp: P-f droop [pu speed / pu power] (> 0)."""
    dw_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """Dwmax: upper limit of dwm [pu] (>= 0)."""
    dw_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.05)
    """Dwmin: lower limit of dwm [pu] (<= 0)."""
    kp_pll: Float[Array, ""] = eqx.field(converter=as_float, default=0.265)
    """kpPLL: PLL proportional gain [pu speed / pu voltage]."""
    ki_pll: Float[Array, ""] = eqx.field(converter=as_float, default=2.65)
    """kiPLL: PLL integral gain [pu speed / (pu voltage s)] (> 0)."""
    dw_pll_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """DwPLLmax: PLL output upper limit [pu] (>= 0)."""
    dw_pll_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.2)
    """DwPLLmin: PLL output lower limit [pu] (<= 0)."""
    t_p_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Tp: lag of the droop's speed [s] (0: none)."""
    h_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """H: virtual inertia constant [s on MBASE] (> 0)."""
    d1_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """D1: steady-state damping [pu power / pu speed] (>= 0)."""
    d2_pu: Float[Array, ""] = eqx.field(converter=as_float, default=100.0)
    """D2: transient damping (through the washout) [pu power / pu speed] (>= 0)."""
    w_d_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=50.0)
    """wD: washout corner [rad/s] (> 0)."""
    i_max_ss_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """ImaxSS: steady-state current limit [pu] (> 0; XL ImaxSS < 1)."""
    kf: Float[Array, ""] = eqx.field(converter=as_float, default=0.9)
    """kf: share of ImaxSS for the priority axis [-] (0 < kf <= 1)."""
    k_i: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """kI: gain of the angle-limit integrators [rad / (pu current s)] (> 0)."""
    i_max_f_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.5)
    """ImaxF: transient (fault) current limit [pu] (> 0: ignored at <= 0)."""
    t_pf_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TPf: P filter [s]."""
    t_qf_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TQf: Q filter [s]."""
    t_vf_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TVf: |V| filter [s]."""
    t_if_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """TIf: current filter [s]."""
    ke: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Ke: negative-current limit as a share of IdmaxSS [-] (storage; 0 <= Ke <= 1)."""
    v_pll_frz_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """VPLLfrz: |V| below which the PLL freezes [pu]."""
    re_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Re: coupling resistance [pu on MBASE] (the generator's ZSORCE, not a CON)."""
    xe_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """XL: coupling reactance [pu on MBASE] (the generator's ZSORCE, not a CON; > 0)."""
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * math.pi * 60.0)
    """Nominal angular frequency 2 pi f0 [rad/s]."""

    n_states = 14
    angle_state = 6
    """Index of the PLL's angle, which turns with the imposed phasor [rad]."""
    judged_with_voltage_imposed = True
    """Against an imposed terminal voltage the source behind XL synchronises (P turns with dIT),
    so ``jaxdse check`` judges its steps."""

    def __check_init__(self):
        check_flag(self, "wflag", "vdrpflag", "qvflag", "pqflag", "fflag", "esflag")
        check_positive(self, "kiv", "mp", "ki_pll", "h_s", "w_d_rad_s", "i_max_ss_pu", "kf", "k_i", "xe_pu",
                       "omega_s_rad_s")
        check_nonnegative(self, "mq", "kpv", "kp_pll", "dw_max_pu", "dw_pll_max_pu", "t_p_s", "d1_pu",
                          "d2_pu", "t_pf_s", "t_qf_s", "t_vf_s", "t_if_s", "ke", "re_pu", "v_pll_frz_pu")
        if all_concrete(self.dw_min_pu, self.dw_pll_min_pu, self.kf, self.xe_pu, self.i_max_ss_pu, self.ke):
            check_that(self, self.dw_min_pu <= 0, f"Dwmin must be <= 0, got {self.dw_min_pu}")
            check_that(self, self.dw_pll_min_pu <= 0, f"DwPLLmin must be <= 0, got {self.dw_pll_min_pu}")
            check_that(self, self.kf <= 1, f"kf must be <= 1, got {self.kf}")
            check_that(self, self.ke <= 1, f"Ke must be <= 1, got {self.ke}")
            check_that(self, self.xe_pu * self.i_max_ss_pu < 1,
                       f"XL ImaxSS must be < 1 (dmax = asin(XL ImaxSS)), got {self.xe_pu * self.i_max_ss_pu}")

    def _f(self, t):
        return jnp.maximum(t, GFM_FILTER_FLOOR_S)

    def _limits(self, y):
        """(IdmaxSS, Emin, Emax, dmax) from the filtered current and voltage."""
        vinv, idinv, iqinv = y[2], y[3], y[4]
        room = lambda x: jnp.sqrt(jnp.maximum(self.i_max_ss_pu**2 - x**2, 0.0))  # noqa: E731
        p_pri = self.pqflag != 0
        id_max = jnp.where(p_pri, self.kf * self.i_max_ss_pu, room(iqinv))
        iq_max = jnp.where(p_pri, room(idinv), self.kf * self.i_max_ss_pu)
        xl = self.xe_pu
        e_max = jnp.hypot(vinv + iq_max * xl, idinv * xl)
        e_min = jnp.hypot(vinv - iq_max * xl, idinv * xl)
        return id_max, e_min, e_max, jnp.arcsin(jnp.minimum(xl * self.i_max_ss_pu, 1.0))

    def _pll(self, y, u):
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        vq = u.v_im_pu * jnp.cos(y[6]) - u.v_re_pu * jnp.sin(y[6])     # |V| sin(theta - dPLL)
        dw = jnp.clip(self.kp_pll * vq + y[5], self.dw_pll_min_pu, self.dw_pll_max_pu)
        return vt, vq, dw

    def _command(self, y, refs: GfmReferences):
        """(Vcmd, E) of the Q-V loop."""
        _, e_min, e_max, _ = self._limits(y)
        droop = (self.vdrpflag != 0) & (self.qvflag != 0)
        vcmd = jnp.where(droop, refs.v_ref_pu - self.mq * y[4],
                         refs.v_ref_pu + self.mq * (refs.q_ref_pu - y[1]))
        return vcmd, jnp.clip(self.kpv * (vcmd - y[2]) + y[13], e_min, e_max)

    def _angle(self, y):
        lo = jnp.where(self.esflag != 0, y[12], 0.0)
        return y[6] + jnp.clip(y[10], lo, y[11])

    def signals(self, y, u: GfmInputs, refs: GfmReferences) -> GfmSignals:
        """The outputs at state ``y`` under terminal voltage ``u``."""
        _, e = self._command(y, refs)
        return source_behind(e, self._angle(y), u, self.re_pu, self.xe_pu, self.i_max_f_pu, 1.0 + y[9])

    def vector_field(self, y, u: GfmInputs, refs: GfmReferences):
        """d(state)/dt under terminal voltage ``u``."""
        sig = self.signals(y, u, refs)
        vt, vq_pll, dw_pll = self._pll(y, u)
        c, s = jnp.cos(y[6]), jnp.sin(y[6])
        i_d = sig.i_re_pu * c + sig.i_im_pu * s            # the current in the PLL frame
        i_q = -(sig.i_im_pu * c - sig.i_re_pu * s)
        frz = vt < self.v_pll_frz_pu
        sel = jnp.where(self.wflag != 0, dw_pll, y[9])
        droop_w, d_tp = _lag(sel, y[7], self.t_p_s)
        d_p = jnp.where(self.fflag != 0, -droop_w / self.mp, 0.0)
        pd2 = self.d2_pu * (y[9] - y[8])
        d_dwm = _blocked(y[9], (refs.p_ref_pu + d_p - y[0] - self.d1_pu * y[9] - pd2) / (2 * self.h_s),
                         self.dw_min_pu, self.dw_max_pu)
        id_max, e_min, e_max, dmax = self._limits(y)
        lo = jnp.where(self.esflag != 0, y[12], 0.0)
        d_it = self.omega_s_rad_s * (y[9] - dw_pll)
        d_it = jnp.where(y[10] > y[11], (y[11] - y[10]) / LIMIT_RESET_S, jnp.where(
            y[10] < lo, (lo - y[10]) / LIMIT_RESET_S, _blocked(y[10], d_it, lo, y[11])))
        d_max = _blocked(y[11], self.k_i * (id_max - y[3]), 0.0, dmax)
        d_max = jnp.where(y[11] > dmax, (dmax - y[11]) / LIMIT_RESET_S, d_max)
        d_min = _blocked(y[12], self.k_i * (-self.ke * id_max - y[3]), -dmax, 0.0)
        d_min = jnp.where(self.esflag != 0,
                          jnp.where(y[12] < -dmax, (-dmax - y[12]) / LIMIT_RESET_S, d_min), 0.0)
        vcmd, _ = self._command(y, refs)
        d_xv = _blocked(y[13], self.kiv * (vcmd - y[2]), e_min, e_max)
        d_xv = jnp.where(y[13] > e_max, (e_max - y[13]) / LIMIT_RESET_S,
                         jnp.where(y[13] < e_min, (e_min - y[13]) / LIMIT_RESET_S, d_xv))
        return jnp.stack([
            (sig.p_pu - y[0]) / self._f(self.t_pf_s), (sig.q_pu - y[1]) / self._f(self.t_qf_s),
            (vt - y[2]) / self._f(self.t_vf_s), (i_d - y[3]) / self._f(self.t_if_s),
            (i_q - y[4]) / self._f(self.t_if_s),
            jnp.where(frz, 0.0, self.ki_pll * vq_pll), jnp.where(frz, 0.0, self.omega_s_rad_s * dw_pll),
            d_tp, self.w_d_rad_s * (y[9] - y[8]), d_dwm, d_it, d_max, d_min, d_xv])

    def initial_state(self, u: GfmInputs, i_re, i_im):
        """(state, references): the steady state that delivers current ``I`` (out of the terminal,
        network frame) at ``u``'s voltage: E e^{j delta_VSM} = V + (Re + j XL) I, the PLL on V's
        angle, dwm = 0, the angle limits at +-dmax (dITmin at 0 without ESFlag), Pref = P;
        QVFlag = 0: Qref = Q, Vref = |V|; QVFlag = 1: Qref = 0, Vref = |V| + mq Q (current
        droop: |V| + mq Iq)."""
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        theta = jnp.arctan2(u.v_im_pu, u.v_re_pu)
        e_re = u.v_re_pu + self.re_pu * i_re - self.xe_pu * i_im
        e_im = u.v_im_pu + self.re_pu * i_im + self.xe_pu * i_re
        e, delta = jnp.hypot(e_re, e_im), jnp.arctan2(e_im, e_re)
        p = u.v_re_pu * i_re + u.v_im_pu * i_im
        q = u.v_im_pu * i_re - u.v_re_pu * i_im
        c, s = jnp.cos(theta), jnp.sin(theta)
        i_d, i_q = i_re * c + i_im * s, -(i_im * c - i_re * s)
        d_it = jnp.arctan2(jnp.sin(delta - theta), jnp.cos(delta - theta))
        dmax = jnp.arcsin(jnp.minimum(self.xe_pu * self.i_max_ss_pu, 1.0))
        zero = jnp.zeros_like(vt)
        qv, droop = self.qvflag != 0, (self.vdrpflag != 0) & (self.qvflag != 0)
        q_ref = jnp.where(qv, 0.0, q)
        v_ref = jnp.where(droop, vt + self.mq * i_q, jnp.where(qv, vt + self.mq * q, vt))
        y0 = jnp.stack([p, q, vt, i_d, i_q, zero, theta, zero, zero, zero, d_it, dmax + zero,
                        jnp.where(self.esflag != 0, -dmax, 0.0) + zero, e])
        cd, sd = jnp.cos(delta), jnp.sin(delta)
        return y0, GfmReferences(p, q_ref, v_ref, i_re * cd + i_im * sd, i_im * cd - i_re * sd)


REGCV1_FIELDS: dict[str, str] = {
    "M": "m_s", "D": "d_pu", "kw": "kw_pu", "kv": "kv_pu", "ra": "ra_pu", "xs": "xs_pu",
    "Tc": "t_c_s", "Kpvd": "kpvd", "Kivd": "kivd", "Kpvq": "kpvq", "Kivq": "kivq",
    "KpId": "kpid", "KiId": "kiid", "KpIq": "kpiq", "KiIq": "kiiq", "Tid": "t_id_s",
    "Tiq": "t_iq_s"}
"""ANDES parameter name -> REGCV1 field (REGCV2 adds Tid, Tiq and has no KpId..KiIq, Tc)."""


def gfm_from_andes(model: str, params: dict, fn_hz: float = 60.0) -> REGCV1:
    """The module of an ANDES grid-forming record (``model`` REGCV1 or REGCV2) from its
    parameters by ANDES name (on the device base Sn; ``Sn``, ``fn``, ``gammap``, ``gammaq``,
    ``bus``, ``gen``, ``idx``, ``u`` are read elsewhere or ignored). Unknown names raise a
    one-line ValueError."""
    name = str(model).strip().upper()
    if name not in ("REGCV1", "REGCV2"):
        raise ValueError(f"{model!r} is not a supported grid-forming model (REGCV1, REGCV2)")
    kwargs = {}
    for key, value in params.items():
        if key in ("Sn", "fn", "gammap", "gammaq", "bus", "gen", "idx", "u", "name", "coi2"):
            continue
        if key not in REGCV1_FIELDS:
            raise ValueError(f"{name}: unknown parameter {key!r} ({', '.join(REGCV1_FIELDS)})")
        kwargs[REGCV1_FIELDS[key]] = float(value)
    fn = float(params.get("fn", fn_hz))
    return REGCV1(inner="lag" if name == "REGCV2" else "pi", omega_s_rad_s=2 * math.pi * fn, **kwargs)


IBR_MODELS: dict[str, type[eqx.Module]] = {"REGCA1": REGCA1, "REGCB1": REGCB1, "REECA1": REECA1,
                                            "REECB1": REECB1, "REECCU1": REECCU1, "REPCA1": REPCA1,
                                            "WTDTA1": WTDTA1, "WTARA1": WTARA1, "WTPTA1": WTPTA1,
                                            "WTTQA1": WTTQA1, "REGCV1": REGCV1, "REGCV2": REGCV1,
                                            "REGFM_A1": REGFM_A1, "REGFMA1": REGFM_A1,
                                            "REGFM_B1": REGFM_B1, "REGFMB1U": REGFM_B1}
"""The inverter-based resource models by their PSS/E name (ANDES's for the grid-forming REGCV1
and REGCV2: one module, ``inner`` "pi" or "lag"; REGFM_A1 and REGFM_B1 as WECC, PowerWorld
and PSLF name them, REGFMA1 and REGFMB1U as PSS/E does; the record is PSS/E's in either case)."""

IBR_ROLES: dict[str, str] = {"REGCA1": "converter", "REGCB1": "converter", "REECA1": "electrical",
                             "REECB1": "electrical", "REECCU1": "electrical", "REPCA1": "plant",
                             "WTDTA1": "drive", "WTARA1": "aero", "WTPTA1": "pitch", "WTTQA1": "torque",
                             "REGCV1": "converter", "REGCV2": "converter", "REGFM_A1": "converter",
                             "REGFMA1": "converter", "REGFM_B1": "converter", "REGFMB1U": "converter"}
"""What each model is in a plant: the converter, its electrical controls, the plant controller,
and a type-3 wind turbine's drive train, aerodynamics, pitch and torque controllers."""

_WT_TABLE = ("p1", "spd1", "p2", "spd2", "p3", "spd3", "p4", "spd4")

_VDL = ("Vq1", "Iq1", "Vq2", "Iq2", "Vq3", "Iq3", "Vq4", "Iq4",
        "Vp1", "Ip1", "Vp2", "Ip2", "Vp3", "Ip3", "Vp4", "Ip4")

_REECB1_FIELDS = ("IREG", "PFFLAG", "VFLAG", "QFLAG", "PQFLAG",
                  "Vdip", "Vup", "Trv", "dbd1", "dbd2", "Kqv", "Iqh1", "Iql1", "Vref0", "Tp", "QMax",
                  "QMin", "VMAX", "VMIN", "Kqp", "Kqi", "Kvp", "Kvi", "Tiq", "dPmax", "dPmin", "PMAX",
                  "PMIN", "Imax", "Tpord")

_GFM_FIELDS = ("Tc", "kw", "kv", "M", "D", "ra", "xs", "Kpvd", "Kivd", "Kpvq", "Kivq")

_REGFM_A1_FIELDS = ("VFlag", "QVFlag", "TPf", "TQf", "TVf", "Imax", "Emax", "Emin", "Pmax", "Pmin", "Qmax",
                    "Qmin", "mp", "mq", "kppmax", "kipmax", "kpqmax", "kiqmax", "kpv", "kiv")
_REGFM_A1_PARAMS = ("vflag", "qvflag", "t_pf_s", "t_qf_s", "t_vf_s", "i_max_pu", "e_max_pu", "e_min_pu",
                    "p_max_pu", "p_min_pu", "q_max_pu", "q_min_pu", "mp", "mq", "kppmax", "kipmax",
                    "kpqmax", "kiqmax", "kpv", "kiv")
_REGFM_B1_FIELDS = ("wFlag", "VdrpFlag", "QVFlag", "PQFlag", "FFlag", "ESFlag", "mq", "kpv", "kiv", "mp",
                    "Dwmax", "Dwmin", "kpPLL", "kiPLL", "DwPLLmax", "DwPLLmin", "Tp", "H", "D1", "D2", "wD",
                    "ImaxSS", "kf", "kI", "ImaxF", "TPf", "TQf", "TVf", "TIf", "Ke", "VPLLfrz")
_REGFM_B1_PARAMS = ("wflag", "vdrpflag", "qvflag", "pqflag", "fflag", "esflag", "mq", "kpv", "kiv", "mp",
                    "dw_max_pu", "dw_min_pu", "kp_pll", "ki_pll", "dw_pll_max_pu", "dw_pll_min_pu", "t_p_s",
                    "h_s", "d1_pu", "d2_pu", "w_d_rad_s", "i_max_ss_pu", "kf", "k_i", "i_max_f_pu", "t_pf_s",
                    "t_qf_s", "t_vf_s", "t_if_s", "ke", "v_pll_frz_pu")

IBR_FIELDS: dict[str, tuple[str, ...]] = {
    "REGCA1": ("Lvplsw", "Tg", "Rrpwr", "Brkpt", "Zerox", "Lvpl1", "Volim", "Lvpnt1", "Lvpnt0",
               "Iolim", "Tfltr", "Khv", "Iqrmax", "Iqrmin", "Accel"),
    "REECA1": ("IREG", "PFFLAG", "VFLAG", "QFLAG", "PFLAG", "PQFLAG",
               "Vdip", "Vup", "Trv", "dbd1", "dbd2", "Kqv", "Iqh1", "Iql1", "Vref0", "Iqfrz",
               "Thld", "Thld2", "Tp", "QMax", "QMin", "VMAX", "VMIN", "Kqp", "Kqi", "Kvp", "Kvi",
               "Vref1", "Tiq", "dPmax", "dPmin", "PMAX", "PMIN", "Imax", "Tpord", *_VDL),
    "REPCA1": ("IREG", "FROM", "TO", "CKT", "VCFlag", "RefFlag", "Fflag",
               "Tfltr", "Kp", "Ki", "Tft", "Tfv", "Vfrz", "Rc", "Xc", "Kc", "emax", "emin",
               "dbd1", "dbd2", "Qmax", "Qmin", "Kpg", "Kig", "Tp", "fdbd1", "fdbd2", "femax",
               "femin", "Pmax", "Pmin", "Tg", "Ddn", "Dup"),
    "REGCB1": ("RateFlag", "PQFlag", "Tg", "Tfltr", "Iqrmax", "Iqrmin", "Rrpwr", "Te", "Imax"),
    "REECB1": _REECB1_FIELDS,
    "REECCU1": (*_REECB1_FIELDS, *_VDL, "T", "SOCini", "SOCmax", "SOCmin"),
    "WTDTA1": ("H", "DAMP", "Htfrac", "Freq1", "Dshaft"),
    "WTARA1": ("Ka", "Theta0"),
    "WTPTA1": ("Kiw", "Kpw", "Kic", "Kpc", "Kcc", "Tp", "Thetamax", "Thetamin", "RThetamax",
               "RThetamin"),
    "WTTQA1": ("Tflag", "Kpp", "Kip", "Tp", "Twref", "Temax", "Temin", *_WT_TABLE, "TRATE"),
    "REGCV1": _GFM_FIELDS + ("KpId", "KiId", "KpIq", "KiIq"),
    "REGCV2": _GFM_FIELDS + ("Tiq", "Tid"),
    "REGFM_A1": _REGFM_A1_FIELDS,
    "REGFMA1": _REGFM_A1_FIELDS,
    "REGFM_B1": _REGFM_B1_FIELDS,
    "REGFMB1U": _REGFM_B1_FIELDS,
}
"""PSS/E names of each record's values after ``bus 'MODEL' id``, ICONs first, in PSS/E order
(Siemens PTI, PSS/E Model Library). REGCV1 and REGCV2 have no PSS/E record: theirs is ANDES's
parameter order, without Sn (the generator's MBASE), fn (the system's) and gammap, gammaq (the
static generator's shares, 1 for a converter of its own)."""

IBR_ICONS: dict[str, tuple[str, ...]] = {
    "REGCA1": ("Lvplsw",), "REECA1": ("IREG", "PFFLAG", "VFLAG", "QFLAG", "PFLAG", "PQFLAG"),
    "REPCA1": ("IREG", "FROM", "TO", "CKT", "VCFlag", "RefFlag", "Fflag"),
    "REGCB1": ("RateFlag", "PQFlag"), "REECB1": _REECB1_FIELDS[:5], "REECCU1": _REECB1_FIELDS[:5],
    "WTDTA1": (), "WTARA1": (), "WTPTA1": (), "WTTQA1": ("Tflag",), "REGCV1": (), "REGCV2": (),
    "REGFM_A1": ("VFlag", "QVFlag"), "REGFMA1": ("VFlag", "QVFlag"),
    "REGFM_B1": _REGFM_B1_FIELDS[:6], "REGFMB1U": _REGFM_B1_FIELDS[:6]}
"""The integer ICONs of each record (REPCA1's CKT is a circuit identifier, kept as text)."""

_REECB1_PARAMS = ("remote_bus", "pfflag", "vflag", "qflag", "pqflag", "vdip_pu", "vup_pu", "t_rv_s",
                  "dbd1_pu", "dbd2_pu", "kqv", "iqh1_pu", "iql1_pu", "v_ref0_pu", "t_p_s", "q_max_pu",
                  "q_min_pu", "v_max_pu", "v_min_pu", "kqp", "kqi", "kvp", "kvi", "t_iq_s",
                  "dp_max_pu_s", "dp_min_pu_s", "p_max_pu", "p_min_pu", "i_max_pu", "t_pord_s")

IBR_PARAMETERS: dict[str, dict[str, str]] = {
    "REGCA1": dict(zip(("lvplsw", "t_g_s", "rrpwr_pu_s", "brkpt_pu", "zerox_pu", "lvpl1_pu",
                        "volim_pu", "lvpnt1_pu", "lvpnt0_pu", "iolim_pu", "t_fltr_s", "khv",
                        "iqrmax_pu_s", "iqrmin_pu_s", "accel"), IBR_FIELDS["REGCA1"])),
    "REECA1": dict(zip(("remote_bus", "pfflag", "vflag", "qflag", "pflag", "pqflag", "vdip_pu",
                        "vup_pu", "t_rv_s", "dbd1_pu", "dbd2_pu", "kqv", "iqh1_pu", "iql1_pu",
                        "v_ref0_pu", "iqfrz_pu", "thld_s", "thld2_s", "t_p_s", "q_max_pu",
                        "q_min_pu", "v_max_pu", "v_min_pu", "kqp", "kqi", "kvp", "kvi",
                        "v_ref1_pu", "t_iq_s", "dp_max_pu_s", "dp_min_pu_s", "p_max_pu",
                        "p_min_pu", "i_max_pu", "t_pord_s"), IBR_FIELDS["REECA1"][:35])),
    "REPCA1": dict(zip(("regulated_bus", "vcflag", "refflag", "fflag", "t_fltr_s", "kp", "ki",
                        "t_ft_s", "t_fv_s", "vfrz_pu", "rc_pu", "xc_pu", "kc", "e_max_pu",
                        "e_min_pu", "dbd1_pu", "dbd2_pu", "q_max_pu", "q_min_pu", "kpg", "kig",
                        "t_p_s", "fdbd1_pu", "fdbd2_pu", "fe_max_pu", "fe_min_pu", "p_max_pu",
                        "p_min_pu", "t_g_s", "ddn_pu", "dup_pu"),
                       ("IREG", "VCFlag", "RefFlag", "Fflag", *IBR_FIELDS["REPCA1"][7:]))),
    "REGCB1": dict(zip(("rateflag", "pqflag", "t_g_s", "t_fltr_s", "iqrmax_pu_s", "iqrmin_pu_s",
                        "rrpwr_pu_s", "t_e_s", "i_max_pu"), IBR_FIELDS["REGCB1"])),
    "REECB1": dict(zip(_REECB1_PARAMS, _REECB1_FIELDS)),
    "REECCU1": dict(zip((*_REECB1_PARAMS, "t_soc_s", "soc_ini_pu", "soc_max_pu", "soc_min_pu"),
                        (*_REECB1_FIELDS, "T", "SOCini", "SOCmax", "SOCmin"))),
    "WTDTA1": dict(zip(("h_s", "damp", "htfrac", "freq1_hz", "dshaft"), IBR_FIELDS["WTDTA1"])),
    "WTARA1": dict(zip(("ka", "theta0_deg"), IBR_FIELDS["WTARA1"])),
    "WTPTA1": dict(zip(("kiw", "kpw", "kic", "kpc", "kcc", "t_p_s", "theta_max_deg", "theta_min_deg",
                        "r_theta_max_deg_s", "r_theta_min_deg_s"), IBR_FIELDS["WTPTA1"])),
    "WTTQA1": dict(zip(("tflag", "kpp", "kip", "t_p_s", "t_wref_s", "te_max_pu", "te_min_pu", "trate_mw"),
                       ("Tflag", "Kpp", "Kip", "Tp", "Twref", "Temax", "Temin", "TRATE"))),
    "REGCV1": {f: c for c, f in REGCV1_FIELDS.items() if c in IBR_FIELDS["REGCV1"]},
    "REGCV2": {f: c for c, f in REGCV1_FIELDS.items() if c in IBR_FIELDS["REGCV2"]},
    "REGFM_A1": dict(zip(_REGFM_A1_PARAMS, _REGFM_A1_FIELDS)),
    "REGFMA1": dict(zip(_REGFM_A1_PARAMS, _REGFM_A1_FIELDS)),
    "REGFM_B1": dict(zip(_REGFM_B1_PARAMS, _REGFM_B1_FIELDS)),
    "REGFMB1U": dict(zip(_REGFM_B1_PARAMS, _REGFM_B1_FIELDS)),
}
"""Field -> PSS/E name of each model (for the record messages and a written-back record)."""


VDL_OPEN_PU = 1e3
"""The current ceiling [pu] of a VDL table whose points are all (0, 0): no table (Imax limits)."""


def vdl_points(v, i) -> tuple[list[float], list[float]]:
    """A REECA1 VDL table's four points with its trailing (0, 0) pairs read as unused, as case
    files write a table of fewer points: the last used point is held beyond it (flat, as the
    table is beyond its ends); a table of no used point is no limit (:data:`VDL_OPEN_PU`)."""
    v, i = [float(x) for x in v], [float(x) for x in i]
    n = len(v)
    while n > 0 and v[n - 1] == 0.0 and i[n - 1] == 0.0:
        n -= 1
    if n == 0:
        return [0.0, 1.0, 2.0, 3.0], [VDL_OPEN_PU] * 4
    return (v[:n] + [v[n - 1] + k for k in range(1, 5 - n)], i[:n] + [i[n - 1]] * (4 - n))


def vdl_trailing_zeros(constants: Sequence, model: str = "REECA1") -> list[str]:
    """Which of a REECA1 (or REECCU1) record's VDL tables (its values after ``bus 'REECA1' id``) end in
    (0, 0) pairs that :func:`vdl_points` reads as unused: "VDL1 (2 points used)", ..."""
    names = IBR_FIELDS[model]
    out = []
    try:
        vals = {c: float(x) for c, x in zip(names, constants) if c in _VDL}
    except (TypeError, ValueError):
        return out
    for label, keys in (("VDL1", _VDL[:8]), ("VDL2", _VDL[8:])):
        pairs = [(vals.get(keys[k], 1.0), vals.get(keys[k + 1], 1.0)) for k in range(0, 8, 2)]
        n = 4
        while n > 0 and pairs[n - 1] == (0.0, 0.0):
            n -= 1
        if n < 4:
            out.append(f"{label} ({n} point{'s' if n != 1 else ''} used" + (": no limit)" if n == 0 else ")"))
    return out


_DEADBANDS = {"REECA1": (("dbd1", "dbd2"),), "REPCA1": (("dbd1", "dbd2"), ("fdbd1", "fdbd2"))}


def _read(name: str, values: dict) -> list[str]:
    """How values that the models' own checks would refuse are read (``values`` changed in
    place), one note each. A deadband edge of the wrong sign (REPCA1 dbd1 = 0.03 with dbd2 = 0,
    as Texas 7k writes it) is read as its magnitude on the side it names: taken literally the
    error is -0.03 at rest and no initial state holds. PowerWorld corrects limits entered with
    the wrong sign in the same way (WebHelp "Stabilizer Model: WTGPT_A and WTPTA1": "If
    RThetaMin > 0 then change sign to negative")."""
    notes = []
    for lo, hi in _DEADBANDS.get(name, ()):
        for con, wrong, fix in ((lo, values.get(lo, 0.0) > 0, -values.get(lo, 0.0)),
                                (hi, values.get(hi, 0.0) < 0, -values.get(hi, 0.0))):
            if wrong:
                notes.append(f"{name}: {con} = {values[con]:g} read as {fix:g} (a deadband edge of the "
                             f"wrong sign: {lo} <= 0 <= {hi})")
                values[con] = fix
    if name == "WTTQA1" and all(c in values for c in _WT_TABLE):
        ps = [values[c] for c in _WT_TABLE[0::2]]
        if any(b < a for a, b in zip(ps, ps[1:])):
            notes.append(f"WTTQA1: the speed table's powers P1..P4 = {', '.join(f'{p:g}' for p in ps)} do not "
                         "increase: its (P, speed) points read in order of P (a table is a function of P; "
                         "taken as written it has none)")
    if name == "REGCA1":
        if values.get("Tg") == 0:
            notes.append(f"REGCA1: Tg = 0 read as the converter lag bypassed (kept as a {TG_BYPASS_S:g} s lag: "
                         "a pass-through would close an algebraic loop)")
        for con in ("Iqrmax", "Iqrmin"):
            if values.get(con) == 0:
                notes.append(f"REGCA1: {con} = 0 read as no rate limit on Iq (read literally, Iq could not move)")
    return notes


def record_readings(model: str, constants: Sequence) -> list[str]:
    """The notes of :func:`ibr_from_dyr`'s readings of a record (empty when it reads as written
    or does not read at all)."""
    name = str(model).strip().upper()
    names = IBR_FIELDS.get(name, ())
    try:
        values = {c: float(x) for c, x in zip(names, constants) if c != "CKT"}
    except (TypeError, ValueError):
        return []
    return _read(name, values)


def ibr_from_dyr(model: str, constants: Sequence) -> eqx.Module:
    """The module of an inverter-based resource's .dyr record: ``model`` (one of
    :data:`IBR_MODELS`) and its values after ``bus 'MODEL' id``, ICONs then CONs in PSS/E order
    (:data:`IBR_FIELDS`). Raises a one-line ValueError for an unknown model, a wrong number of
    values, a non-number, a non-integer ICON or invalid constants (named as the record names
    them)."""
    name = str(model).strip().upper()
    names = IBR_FIELDS.get(name)
    if names is None:
        raise ValueError(f"{model!r} is not a supported inverter-based model ({', '.join(IBR_MODELS)})")
    if len(constants) != len(names):
        raise ValueError(f"{name}: expected {len(names)} values ({' '.join(names)}), got {len(constants)}")
    values: dict[str, object] = {}
    for con, value in zip(names, constants):
        if con == "CKT":
            values[con] = str(value).strip()
            continue
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{name}: {con} is not a number: {value!r}") from None
        if not math.isfinite(x):
            raise ValueError(f"{name}: {con} is not finite: {value!r}")
        if con in IBR_ICONS[name]:
            if x != round(x):
                raise ValueError(f"{name}: ICON {con} must be an integer, got {value!r}")
            x = int(round(x))
        values[con] = x
    _read(name, values)
    fields = IBR_PARAMETERS[name]
    kwargs = {f: values[con] for f, con in fields.items()}
    if name in ("REECA1", "REECCU1"):
        tail = [values[c] for c in _VDL]
        v1, i1 = vdl_points(tail[0:8:2], tail[1:8:2])
        v2, i2 = vdl_points(tail[8:16:2], tail[9:16:2])
        kwargs.update(vdl1_v_pu=v1, vdl1_i_pu=i1, vdl2_v_pu=v2, vdl2_i_pu=i2)
    if name == "WTTQA1":
        points = sorted(zip([values[c] for c in _WT_TABLE[0::2]], [values[c] for c in _WT_TABLE[1::2]]),
                        key=lambda pw: pw[0])      # in order of P (see _read)
        kwargs.update(table_p_pu=[p for p, _ in points], table_w_pu=[w for _, w in points])
    if name == "REPCA1":
        kwargs["branch"] = (int(values["FROM"]), int(values["TO"]))
    if name in ("REGCV1", "REGCV2"):
        kwargs["inner"] = "lag" if name == "REGCV2" else "pi"
    try:
        return IBR_MODELS[name](**kwargs)
    except ValueError as err:  # name the CONs as the record does
        msg = str(err)
        for f, con in (("vflag", "VFLAG"), ("qflag", "QFLAG"), ("pfflag", "PFFLAG"),
                       ("pflag", "PFLAG"), ("pqflag", "PQFLAG" if name != "REGCB1" else "PQFlag"),
                       ("rateflag", "RateFlag"), ("vcflag", "VCFlag"),
                       ("refflag", "RefFlag"), ("fflag", "Fflag"), ("tflag", "Tflag")):
            msg = msg.replace(f"{name}.{f} ", f"{fields.get(f, con)} ")
        raise ValueError(record_message(msg, name, fields)) from None


__all__ = ["GfmInputs", "GfmReferences", "GfmSignals", "IQR_ZERO_IS_OPEN", "REECB1", "REECCU1", "REGCB1",
           "GFM_FILTER_FLOOR_S", "LIMIT_RESET_S", "REGCV1", "REGFM_A1", "REGFM_B1",
           "REGCV1_FIELDS", "TG_BYPASS_S", "gfm_from_andes", "record_readings", "VDL_OPEN_PU",
           "vdl_points", "vdl_trailing_zeros", "IBR_FIELDS", "IBR_ICONS", "IBR_MODELS", "IBR_PARAMETERS",
           "IBR_ROLES", "LVPL_OPEN_PU",
           "LVPL_RESET_S",
           "REECA1", "REGCA1", "REPCA1", "V_FLOOR_PU", "WTARA1", "WTDTA1", "WTPTA1", "WTTQA1", "ElectricalInputs", "ElectricalReferences",
           "PlantInputs", "PlantReferences", "deadband", "ibr_from_dyr"]
