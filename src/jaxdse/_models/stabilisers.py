"""PSS/E power system stabilisers IEEEST, ST2CUT, PSS2A, PSS2B and STAB2A: VOTHSG from one or
two input signals.

Conventions (every model, PSS/E behaviour where the library states it):

* the input signal is chosen by the ICON MODE from :class:`StabiliserInputs`:
  1 rotor speed deviation [pu], 2 bus frequency deviation [pu of nominal frequency, not Hz],
  3 electrical power PELEC [pu on MBASE, positive generating], 4 accelerating power
  PMECH - PELEC [pu on MBASE], 5 bus voltage magnitude [pu], 6 its time derivative [pu/s];
* the ICONs (input codes, remote buses) are integer leaves, not static fields: the input is
  chosen with ``jnp.where``, so units whose codes differ share one compiled program;
* a remote-bus ICON (busr != 0) is accepted and recorded (``remote_bus``), but the signal is
  taken at the machine terminal: :attr:`remote_input_at_terminal` tells the caller to say so;
* a lag ``1/(1 + sT)`` with T = 0 and a lead-lag ``(1 + sTa)/(1 + sTb)`` with Tb = 0 are
  pass-throughs whose state is kept with zero derivative (one state layout under vmap);
* the washout's numerator time constant (IEEEST T5, ST2CUT T3) = 0 bypasses the washout
  (gain 1, as the OPAL-RT ePHASORSIM emulation of the PSS/E models does); the rest output is
  then the limited DC gain times the input instead of 0. Its denominator (IEEEST T6, ST2CUT
  T4) must be > 0 (the PSS/E data sheets say "> 0"; a pure derivative is not realisable);
* the output limits LSMAX/LSMIN clip the (algebraic) washout output; the voltage cut-off then
  sets VOTHSG = 0 while |Vt| > VCU or |Vt| < VCL, where VCU = 0 (VCL = 0) means that side is
  not used ("if equal zero, ignored"). |Vt| is the terminal voltage (PSS/E compares the
  compensated voltage ECOMP, which equals |Vt| without load compensation);
* no Python branching on array values (``jnp.where``), bypassed denominators replaced by 1,
  so neither value nor gradient is NaN; parameters are validated when concrete only;
* PSS2A/PSS2B: a washout s TW/(1 + s TW) with TW = 0 is bypassed (gain 1), and the
  ramp-tracking filter keeps a fixed block of ``RTF_MAX_STAGES`` = 8 states (PSS/E's M N <= 8)
  with the unused stages held at zero derivative (see :class:`PSS2A`).

Sources: Siemens PTI, *PSS(R)E Model Library*, "IEEEST" and "ST2CUT" (block diagrams and
CON/ICON tables); IEEE Committee Report, "Excitation system models for power system stability
studies", IEEE Trans. PAS-100 (1981) (the IEEEST stabiliser); PowerWorld Simulator help,
"Stabilizer Model: ST2CUT" (ICON/CON list, input codes); for the structure only, the BSD-3
implementations OpenIPSL ``OpenIPSL.Electrical.Controls.PSSE.PSS.IEEEST``, GridPACK
``st2cut.cpp`` and the GridKit IEEEST notes, and OPAL-RT's ePHASORSIM Modelica library
(``OpalRT.Electrical.Control.Stabilizer.IEEEST/ST2CUT``, read for the block order and the
bypass conventions; no code taken). PSS2A/PSS2B: Siemens PTI, *PSS(R)E Model Library*,
"PSS2A", "PSS2B" (CON/ICON tables), IEEE Std 421.5-2016 (types PSS2A, PSS2B); the block order
cross-read in OpenIPSL ``PSS2A``/``PSS2B``/``RampTrackingFilter`` and PowerSystems.jl's
``PSS2B`` field list (BSD-3; no code taken).
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._base.blocks import lag as _lag
from .._base.blocks import lead_lag as _lead_lag
from .._base.blocks import safe as _safe
from .._base.fields import all_concrete, as_flag, as_float, check_nonnegative, check_that, concrete
from .base import AbstractStabiliser, StabiliserInputs, record_message

INPUT_MODES = {
    1: "rotor speed deviation [pu]",
    2: "bus frequency deviation [pu]",
    3: "electrical power [pu on MBASE]",
    4: "accelerating power Pm - Pe [pu on MBASE]",
    5: "bus voltage magnitude [pu]",
    6: "derivative of the bus voltage magnitude [pu/s]",
}
"""PSS/E stabiliser input codes (ICON MODE) -> signal; the field of :class:`StabiliserInputs`
with the same position (MODE 1 = ``speed_dev_pu`` ... MODE 6 = ``dvt_dt_pu_s``)."""


def _check_mode(module, name: str, mode, allow_zero: bool = False) -> None:
    lo = 0 if allow_zero else 1
    if concrete(mode) and not lo <= int(mode) <= 6:
        raise ValueError(f"{type(module).__name__}.{name} must be an input code {lo}..6, got {mode}")


def _check_bus(module, name: str, bus) -> None:
    if concrete(bus) and int(bus) < 0:
        raise ValueError(f"{type(module).__name__}.{name} must be a bus number >= 0, got {bus}")


def _signal(inputs: StabiliserInputs, mode):
    """The input selected by a PSS/E input code (0: no signal; the code is a leaf, so units
    whose codes differ share one compiled program)."""
    out = jnp.zeros_like(jnp.asarray(inputs.speed_dev_pu, dtype=float))
    for code, signal in enumerate(inputs, start=1):
        out = jnp.where(mode == code, jnp.asarray(signal, dtype=float), out)
    return out


def _nonzero(d):
    """A denominator that is ``d`` where ``d != 0`` and 1 elsewhere."""
    return jnp.where(d != 0, d, 1.0)


def _limit_and_cut(vss, vt, ls_max, ls_min, vcu, vcl):
    """Output limits, then the voltage cut-off (VCU/VCL = 0: that side not used)."""
    vss = jnp.clip(vss, ls_min, ls_max)
    cut = ((vcu != 0) & (vt > vcu)) | ((vcl != 0) & (vt < vcl))
    return jnp.where(cut, 0.0, vss)


def _washout(u, x, gain, t_num, t_den):
    """gain * s t_num/(1 + s t_den): (output, dx/dt). t_num = 0 (or t_den = 0): gain * u, dx = 0."""
    on = (t_num != 0) & (t_den > 0)
    d = jnp.where(on, (u - x) / _safe(t_den), 0.0)
    return jnp.where(on, gain * t_num * d, gain * u), d


def _check_common(module) -> None:
    if all_concrete(module.ls_max_pu, module.ls_min_pu):
        check_that(module, module.ls_max_pu >= module.ls_min_pu,
               f"LSMAX ({module.ls_max_pu}) must be >= LSMIN ({module.ls_min_pu})")
    if all_concrete(module.vcu_pu, module.vcl_pu):
        both = (module.vcu_pu != 0) & (module.vcl_pu != 0)
        check_that(module, ~both | (module.vcu_pu > module.vcl_pu),
               f"VCU ({module.vcu_pu}) must be > VCL ({module.vcl_pu}) when both are used")


# --- IEEEST -----------------------------------------------------------------------------------

class IEEEST(AbstractStabiliser):
    """PSS/E IEEEST, the IEEE (1981) stabiliser with a 4th-order filter.

    Block diagram (Siemens PTI *PSS/E Model Library*, "IEEEST"; IEEE Trans. PAS-100, 1981;
    same structure in OpenIPSL ``IEEEST`` and the GridKit IEEEST notes)::

        u   = input(MODE)
        F   = (1 + A5 s + A6 s^2) / ((1 + A1 s + A2 s^2)(1 + A3 s + A4 s^2))   u
        L   = (1 + s T1)/(1 + s T2) (1 + s T3)/(1 + s T4)                        F
        VSS = clip(KS s T5/(1 + s T6) L, LSMIN, LSMAX)
        VOTHSG = VSS, or 0 while Vt > VCU (VCU != 0) or Vt < VCL (VCL != 0)

    The filter is realised as one block in phase variables: with D(s) = 1 + d1 s + d2 s^2 +
    d3 s^3 + d4 s^4 the product of the two denominators and y = u/D(s), the states are
    [y, y', y'', y'''] and F u = y + A5 y' + A6 y''. Its order n is the highest nonzero d_k,
    so A2 = 0 or A4 = 0 lowers a section to first order and A1 = A2 = 0 (A3 = A4 = 0) removes
    it; the states above the order are kept with zero derivative. The filter must be proper
    (numerator order <= n): A6 != 0 needs n >= 2 and A5 != 0 needs n >= 1 (ValueError).

    States: [y, y', y'', y''', lead-lag 1, lead-lag 2, washout]. At constant input u the
    rest state is [u, 0, 0, 0, u, u, u] and the output 0 (KS T5 (1 - 1)/T6). T5 = 0 bypasses
    the washout (output clip(KS u)); T6 must be > 0.
    """

    mode: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """MODE: input signal code 1..6 (see :data:`INPUT_MODES`)."""
    remote_bus: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """busr: remote bus of the input signal (0: own bus); not modelled, the signal is local."""
    a1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """A1: first filter denominator, s coefficient [s] (>= 0)."""
    a2_s2: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """A2: first filter denominator, s^2 coefficient [s^2] (>= 0)."""
    a3_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """A3: second filter denominator, s coefficient [s] (>= 0)."""
    a4_s2: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """A4: second filter denominator, s^2 coefficient [s^2] (>= 0)."""
    a5_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """A5: filter numerator, s coefficient [s]."""
    a6_s2: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """A6: filter numerator, s^2 coefficient [s^2]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T1: first lead time constant [s]."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T2: first lag time constant [s] (0: lead-lag bypassed)."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T3: second lead time constant [s]."""
    t4_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T4: second lag time constant [s] (0: lead-lag bypassed)."""
    t5_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.65)
    """T5: washout numerator time constant [s] (0: washout bypassed)."""
    t6_s: Float[Array, ""] = eqx.field(converter=as_float, default=1.65)
    """T6: washout denominator time constant [s] (> 0)."""
    ks: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """KS: stabiliser gain [pu output / pu input]."""
    ls_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """LSMAX: maximum stabiliser output [pu]."""
    ls_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.1)
    """LSMIN: minimum stabiliser output [pu]."""
    vcu_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """VCU: output cut-off above this terminal voltage [pu] (0: not used)."""
    vcl_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """VCL: output cut-off below this terminal voltage [pu] (0: not used)."""

    def __check_init__(self):
        _check_mode(self, "mode", self.mode)
        _check_bus(self, "remote_bus", self.remote_bus)
        check_nonnegative(self, "a1_s", "a2_s2", "a3_s", "a4_s2", "t1_s", "t2_s", "t3_s",
                          "t4_s", "t5_s")
        if all_concrete(self.t5_s, self.t6_s):
            check_that(self, (self.t5_s == 0) | (self.t6_s > 0),
                   f"T6 must be > 0 (washout s T5/(1 + s T6)), got {self.t6_s}")
        if all_concrete(self.a1_s, self.a2_s2, self.a3_s, self.a4_s2, self.a5_s, self.a6_s2):
            n = int(self._filter_order())
            num = 2 if self.a6_s2 != 0 else (1 if self.a5_s != 0 else 0)
            check_that(self, num <= n,
                   f"filter (1 + A5 s + A6 s^2)/D(s) is improper: numerator order {num} > "
                   f"denominator order {n} (A1..A4 = {float(self.a1_s)}, {float(self.a2_s2)}, "
                   f"{float(self.a3_s)}, {float(self.a4_s2)})")
        _check_common(self)

    @property
    def n_states(self) -> int:
        return 7

    @property
    def remote_input_at_terminal(self) -> bool:
        """True when the record names a remote input bus (busr != 0) taken here at the terminal."""
        return bool(np.asarray(self.remote_bus) != 0)

    def _denominator(self):
        """d1..d4 of D(s) = (1 + A1 s + A2 s^2)(1 + A3 s + A4 s^2)."""
        a1, a2, a3, a4 = self.a1_s, self.a2_s2, self.a3_s, self.a4_s2
        return a1 + a3, a2 + a4 + a1 * a3, a1 * a4 + a2 * a3, a2 * a4

    def _filter_order(self):
        d1, d2, d3, d4 = self._denominator()
        return jnp.where(d4 != 0, 4, jnp.where(d3 != 0, 3, jnp.where(d2 != 0, 2,
                                                                     jnp.where(d1 != 0, 1, 0))))

    def _filter(self, z, u):
        """(filter output, dz/dt) of the phase-variable realisation, order n = 0..4."""
        d1, d2, d3, d4 = self._denominator()
        n = self._filter_order()
        r1 = u - z[0]
        r2 = r1 - d1 * z[1]
        r3 = r2 - d2 * z[2]
        r4 = r3 - d3 * z[3]
        top = (r1 / _nonzero(d1), r2 / _nonzero(d2), r3 / _nonzero(d3), r4 / _nonzero(d4))
        dz = [jnp.where(n > k + 1, z[k + 1], jnp.where(n == k + 1, top[k], 0.0)) for k in range(3)]
        dz.append(jnp.where(n == 4, top[3], 0.0))
        # y' = dz0 and y'' = dz1 (0 above the order: the proper-filter check makes A5/A6 0 there)
        y = jnp.where(n == 0, u, z[0])
        return y + self.a5_s * dz[0] + self.a6_s2 * dz[1], jnp.stack(dz)

    def _path(self, state, inputs):
        u = _signal(inputs, self.mode)
        f, dz = self._filter(state[0:4], u)
        y1, d1 = _lead_lag(f, state[4], self.t1_s, self.t2_s)
        y2, d2 = _lead_lag(y1, state[5], self.t3_s, self.t4_s)
        vss, d3 = _washout(y2, state[6], self.ks, self.t5_s, self.t6_s)
        return vss, jnp.concatenate([dz, jnp.stack([d1, d2, d3])])

    def initial_state(self, inputs: StabiliserInputs):
        u = _signal(inputs, self.mode)
        zero = jnp.zeros_like(u)
        return jnp.stack([u, zero, zero, zero, u, u, u])

    def vector_field(self, state, inputs: StabiliserInputs):
        return self._path(state, inputs)[1]

    def output(self, state, inputs: StabiliserInputs):
        vss, _ = self._path(state, inputs)
        return _limit_and_cut(vss, inputs.vt_pu, self.ls_max_pu, self.ls_min_pu,
                              self.vcu_pu, self.vcl_pu)


# --- ST2CUT -----------------------------------------------------------------------------------

class ST2CUT(AbstractStabiliser):
    """PSS/E ST2CUT, the two-input stabiliser with three lead-lags.

    Block diagram (Siemens PTI *PSS/E Model Library*, "ST2CUT"; PowerWorld "Stabilizer Model:
    ST2CUT"; same structure in GridPACK ``st2cut.cpp`` and OPAL-RT ePHASORSIM ``ST2CUT``)::

        s1  = K1/(1 + s T1) input(MODE),  s2 = K2/(1 + s T2) input(MODE2)  (MODE2 = 0: none)
        w   = s T3/(1 + s T4) (s1 + s2)
        L   = (1 + s T5)/(1 + s T6) (1 + s T7)/(1 + s T8) (1 + s T9)/(1 + s T10)  w
        VSS = clip(L, LSMIN, LSMAX)
        VOTHSG = VSS, or 0 while Vt > VCU (VCU != 0) or Vt < VCL (VCL != 0)

    States: [s1 lag, s2 lag, washout, lead-lag 1, lead-lag 2, lead-lag 3]. At constant inputs
    u1, u2 the rest state is [K1 u1, K2 u2, K1 u1 + K2 u2, 0, 0, 0] and the output 0. T1, T2 =
    0 make the input blocks gains; T6, T8, T10 = 0 bypass their lead-lags; T4 must be > 0 and
    T3 = 0 bypasses the washout (the PSS/E data sheet asks T3 > 0: ValueError when concrete).

    The cut-off compares the absolute terminal voltage with VCU/VCL, as IEEEST and GridPACK do
    (OPAL-RT's emulation compares it with VT0 + VCU, VT0 + VCL instead; the PSS/E text is not
    available here to settle it, and every record in our data sets VCU = VCL = 0).
    """

    mode: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """MODE (ICS1): first input signal code 1..6 (see :data:`INPUT_MODES`)."""
    remote_bus: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """busr (IB1): remote bus of the first input (0: own bus); not modelled."""
    mode2: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """MODE2 (ICS2): second input signal code 0..6 (0: no second input)."""
    remote_bus2: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """busr2 (IB2): remote bus of the second input (0: own bus); not modelled."""
    k1: Float[Array, ""] = eqx.field(converter=as_float, default=10.0)
    """K1: gain of the first input [pu output / pu input]."""
    k2: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """K2: gain of the second input [pu output / pu input]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T1: first input transducer time constant [s] (0: gain only)."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T2: second input transducer time constant [s] (0: gain only)."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """T3: washout numerator time constant [s] (> 0)."""
    t4_s: Float[Array, ""] = eqx.field(converter=as_float, default=3.0)
    """T4: washout denominator time constant [s] (> 0)."""
    t5_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.15)
    """T5: first lead time constant [s]."""
    t6_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """T6: first lag time constant [s] (0: bypassed)."""
    t7_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.15)
    """T7: second lead time constant [s]."""
    t8_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """T8: second lag time constant [s] (0: bypassed)."""
    t9_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T9: third lead time constant [s]."""
    t10_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T10: third lag time constant [s] (0: bypassed)."""
    ls_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.05)
    """LSMAX: maximum stabiliser output [pu]."""
    ls_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.05)
    """LSMIN: minimum stabiliser output [pu]."""
    vcu_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """VCU: output cut-off above this terminal voltage [pu] (0: not used)."""
    vcl_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """VCL: output cut-off below this terminal voltage [pu] (0: not used)."""

    def __check_init__(self):
        _check_mode(self, "mode", self.mode)
        _check_mode(self, "mode2", self.mode2, allow_zero=True)
        _check_bus(self, "remote_bus", self.remote_bus)
        _check_bus(self, "remote_bus2", self.remote_bus2)
        check_nonnegative(self, "t1_s", "t2_s", "t5_s", "t6_s", "t7_s", "t8_s", "t9_s", "t10_s")
        if all_concrete(self.t3_s, self.t4_s):
            check_that(self, self.t3_s > 0, f"T3 must be > 0 (washout s T3/(1 + s T4)), got {self.t3_s}")
            check_that(self, self.t4_s > 0, f"T4 must be > 0 (washout s T3/(1 + s T4)), got {self.t4_s}")
        _check_common(self)

    @property
    def n_states(self) -> int:
        return 6

    @property
    def remote_input_at_terminal(self) -> bool:
        """True when the record names a remote input bus (busr or busr2 != 0), taken here at the
        terminal."""
        return bool(np.asarray(self.remote_bus) != 0
                    or (np.asarray(self.mode2) != 0 and np.asarray(self.remote_bus2) != 0))

    def _path(self, state, inputs):
        u1, u2 = _signal(inputs, self.mode), _signal(inputs, self.mode2)
        s1, d1 = _lag(self.k1 * u1, state[0], self.t1_s)
        s2, d2 = _lag(self.k2 * u2, state[1], self.t2_s)
        w, d3 = _washout(s1 + s2, state[2], 1.0, self.t3_s, self.t4_s)
        y1, d4 = _lead_lag(w, state[3], self.t5_s, self.t6_s)
        y2, d5 = _lead_lag(y1, state[4], self.t7_s, self.t8_s)
        y3, d6 = _lead_lag(y2, state[5], self.t9_s, self.t10_s)
        return y3, jnp.stack([d1, d2, d3, d4, d5, d6])

    def initial_state(self, inputs: StabiliserInputs):
        s1 = self.k1 * _signal(inputs, self.mode)
        s2 = self.k2 * _signal(inputs, self.mode2)
        w = jnp.where((self.t3_s != 0) & (self.t4_s > 0), 0.0, s1 + s2)   # washout output
        return jnp.stack([s1, s2, s1 + s2, w, w, w])

    def vector_field(self, state, inputs: StabiliserInputs):
        return self._path(state, inputs)[1]

    def output(self, state, inputs: StabiliserInputs):
        vss, _ = self._path(state, inputs)
        return _limit_and_cut(vss, inputs.vt_pu, self.ls_max_pu, self.ls_min_pu,
                              self.vcu_pu, self.vcl_pu)


# --- PSS2A / PSS2B ----------------------------------------------------------------------------

RTF_MAX_STAGES = 8
"""Length of the ramp-tracking filter's state block in PSS2A/PSS2B: PSS/E allows M N <= 8
(the same bound in OpenIPSL and PowerSimulationsDynamics.jl); the block is this long for
every parameter set so that units with different M, N share one state layout under vmap."""


def _check_rtf_orders(module) -> None:
    if not all_concrete(module.m_rtf, module.n_rtf):
        return
    for name, v in (("M", module.m_rtf), ("N", module.n_rtf)):
        v = np.asarray(v)
        check_that(module, (v >= 0) & (v == np.round(v)),
                   f"ramp-tracking filter order {name} must be an integer >= 0, got {v}")
    mn = np.asarray(module.m_rtf) * np.asarray(module.n_rtf)
    check_that(module, mn <= RTF_MAX_STAGES,
               f"ramp-tracking filter M N = {mn} exceeds {RTF_MAX_STAGES} (PSS/E limit)")


def _ramp_tracking(u, x, m, n, t8, t9, steady):
    """[(1 + s T8)/(1 + s T9)^M]^N over the fixed block of ``RTF_MAX_STAGES`` states.

    Stage j < M N is active: the first stage of each of the N sections is the lead-lag
    (1 + s T8)/(1 + s T9), the other M - 1 are lags 1/(1 + s T9). Stages j >= M N pass their
    input through with zero derivative. M = 0, N = 0 or T9 = 0 make the filter a gain of 1.
    ``steady``: every stage's state set to its input (the rest state). Returns (output,
    d(state)/dt, state used)."""
    on = (m > 0) & (n > 0) & (t9 > 0)
    m_safe = jnp.where(m > 0, m, 1.0)
    y, ds, xs = u, [], []
    for j in range(RTF_MAX_STAGES):
        active = on & (j < m * n)
        lead = jnp.where(jnp.mod(float(j), m_safe) == 0, t8, 0.0)
        xj = y if steady else x[j]
        out, d = _lead_lag(y, xj, lead, t9)
        y = jnp.where(active, out, y)
        ds.append(jnp.where(active, d, 0.0))
        xs.append(xj)
    return y, ds, xs


class PSS2A(AbstractStabiliser):
    """PSS/E PSS2A, the IEEE dual-input stabiliser (IEEE Std 421.5-1992/2005/2016 type PSS2A).

    Block diagram (Siemens PTI *PSS/E Model Library*, "PSS2A"; IEEE Std 421.5-2016, type
    PSS2A dual-input stabilizer; same block order in OpenIPSL ``PSS2A`` and
    PowerSimulationsDynamics.jl ``PSS2A``)::

        y1 = 1/(1 + s T6) . s TW2/(1 + s TW2) . s TW1/(1 + s TW1) . input(ICS1)
        y2 = KS2/(1 + s T7) . s TW4/(1 + s TW4) . s TW3/(1 + s TW3) . input(ICS2)
        r  = [(1 + s T8)/(1 + s T9)^M]^N (y1 + KS3 y2)            (ramp-tracking filter)
        VST = clip(KS1 (1 + s T1)/(1 + s T2) (1 + s T3)/(1 + s T4) (r - y2), VSTMIN, VSTMAX)

    Typical use: ICS1 = 1 (speed), ICS2 = 3 (electrical power), KS3 = 1, KS2 = T7/(2H): the
    ``integral of accelerating power`` input; y1 + KS3 y2 is then a filtered mechanical power.

    States (16): [TW1, TW2, T6, TW3, TW4, T7 blocks, ramp-tracking filter (``RTF_MAX_STAGES``
    = 8, see :func:`_ramp_tracking`), lead-lag 1, lead-lag 2]. At constant inputs every
    state equals its block's input and, with the washouts in, the output is 0.

    Zero time constants (as PSS/E, without division by zero): a washout with TW = 0 is
    bypassed (gain 1; PSS/E's typical PSS2A data put TW4 = 0 for a single washout on input
    2); T6 = 0, T7 = 0 make those lags gains (1, KS2); T2 = 0, T4 = 0 bypass the lead-lags;
    M = 0, N = 0 or T9 = 0 bypass the ramp-tracking filter. The remote-bus ICONs are
    recorded and the inputs taken at the terminal (:attr:`remote_input_at_terminal`).

    M and N are kept as array leaves (integers stored as floats), not static fields: units
    with different filter orders share one state layout and one compiled program.

    Not taken from the diagram: OpenIPSL (Laera et al., 2022) reports that PSS/E v33's
    implementation realises the filter as N lead-lags followed by M lags; this module follows
    the documented [(1 + s T8)/(1 + s T9)^M]^N.
    """

    mode: Int[Array, ""] = eqx.field(converter=as_flag, default=1)
    """ICS1: first input signal code 1..6 (see :data:`INPUT_MODES`)."""
    remote_bus: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """REMBUS1: remote bus of the first input (0: own bus); not modelled."""
    mode2: Int[Array, ""] = eqx.field(converter=as_flag, default=3)
    """ICS2: second input signal code 0..6 (0: no second input)."""
    remote_bus2: Int[Array, ""] = eqx.field(converter=as_flag, default=0)
    """REMBUS2: remote bus of the second input (0: own bus); not modelled."""
    m_rtf: Float[Array, ""] = eqx.field(converter=as_float, default=5.0)
    """M: ramp-tracking filter denominator order (integer >= 0, M N <= 8)."""
    n_rtf: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """N: ramp-tracking filter order (integer >= 0, M N <= 8)."""
    tw1_s: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """TW1: first washout of input 1 [s] (0: bypassed)."""
    tw2_s: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """TW2: second washout of input 1 [s] (0: bypassed)."""
    t6_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T6: transducer lag of input 1 [s] (0: gain 1)."""
    tw3_s: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """TW3: first washout of input 2 [s] (0: bypassed)."""
    tw4_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """TW4: second washout of input 2 [s] (0: bypassed)."""
    t7_s: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """T7: transducer lag of input 2 [s] (0: gain KS2)."""
    ks2: Float[Array, ""] = eqx.field(converter=as_float, default=0.2)
    """KS2: gain of input 2 [pu/pu] (typically T7/(2H))."""
    ks3: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """KS3: gain of input 2 into the ramp-tracking filter [-]."""
    t8_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """T8: ramp-tracking filter lead [s]."""
    t9_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """T9: ramp-tracking filter lag [s] (0: filter bypassed)."""
    ks1: Float[Array, ""] = eqx.field(converter=as_float, default=12.0)
    """KS1: stabiliser gain [pu output / pu input]."""
    t1_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.12)
    """T1: first lead [s]."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """T2: first lag [s] (0: lead-lag bypassed)."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.12)
    """T3: second lead [s]."""
    t4_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.02)
    """T4: second lag [s] (0: lead-lag bypassed)."""
    vst_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.1)
    """VSTMAX: maximum stabiliser output [pu]."""
    vst_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.1)
    """VSTMIN: minimum stabiliser output [pu]."""

    def __check_init__(self):
        _check_mode(self, "mode", self.mode)
        _check_mode(self, "mode2", self.mode2, allow_zero=True)
        _check_bus(self, "remote_bus", self.remote_bus)
        _check_bus(self, "remote_bus2", self.remote_bus2)
        check_nonnegative(self, *self._time_constants())
        _check_rtf_orders(self)
        if all_concrete(self.vst_max_pu, self.vst_min_pu):
            check_that(self, self.vst_max_pu >= self.vst_min_pu,
                       f"VSTMAX ({self.vst_max_pu}) must be >= VSTMIN ({self.vst_min_pu})")

    def _time_constants(self):
        return ("tw1_s", "tw2_s", "t6_s", "tw3_s", "tw4_s", "t7_s", "t8_s", "t9_s", "t1_s",
                "t2_s", "t3_s", "t4_s")

    def _lead_lags(self):
        """(lead, lag) time constants of the output lead-lags in order."""
        return ((self.t1_s, self.t2_s), (self.t3_s, self.t4_s))

    @property
    def n_states(self) -> int:
        return 6 + RTF_MAX_STAGES + len(self._lead_lags())

    @property
    def remote_input_at_terminal(self) -> bool:
        """True when a record names a remote input bus, taken here at the terminal."""
        return bool(np.asarray(self.remote_bus) != 0
                    or (np.asarray(self.mode2) != 0 and np.asarray(self.remote_bus2) != 0))

    def _inputs(self, inputs):
        return _signal(inputs, self.mode), _signal(inputs, self.mode2)

    def _path(self, state, inputs, steady=False):
        """(VST before the output limit, d(state)/dt, the states used). ``steady``: every
        block's state set to its input (the rest state at these inputs)."""
        u1, u2 = self._inputs(inputs)
        xs, ds = [], []

        def block(fn, u, k, *args):
            x = u if steady else state[k]
            y, d = fn(u, x, *args)
            xs.append(x)
            ds.append(d)
            return y

        def wo(u, x, t):
            return _washout(u, x, 1.0, t, t)

        a = block(wo, u1, 0, self.tw1_s)
        a = block(wo, a, 1, self.tw2_s)
        y1 = block(_lag, a, 2, self.t6_s)
        b = block(wo, u2, 3, self.tw3_s)
        b = block(wo, b, 4, self.tw4_s)
        y2 = block(_lag, self.ks2 * b, 5, self.t7_s)
        r, d_r, x_r = _ramp_tracking(y1 + self.ks3 * y2, None if steady else state[6:6 + RTF_MAX_STAGES],
                                     self.m_rtf, self.n_rtf, self.t8_s, self.t9_s, steady)
        xs += x_r
        ds += d_r
        v = self.ks1 * (r - y2)
        for k, (ta, tb) in enumerate(self._lead_lags()):
            v = block(_lead_lag, v, 6 + RTF_MAX_STAGES + k, ta, tb)
        return v, jnp.stack(ds), jnp.stack(xs)

    def initial_state(self, inputs: StabiliserInputs):
        return self._path(None, inputs, steady=True)[2]

    def vector_field(self, state, inputs: StabiliserInputs):
        return self._path(state, inputs)[1]

    def output(self, state, inputs: StabiliserInputs):
        vst, _, _ = self._path(state, inputs)
        return jnp.clip(vst, self.vst_min_pu, self.vst_max_pu)


class PSS2B(PSS2A):
    """PSS/E PSS2B, the IEEE dual-input stabiliser of IEEE Std 421.5-2005/2016 type PSS2B.

    PSS2A (see there) with the two input signals limited before their washouts and a third
    output lead-lag (Siemens PTI *PSS/E Model Library*, "PSS2B"; IEEE Std 421.5-2016 type
    PSS2B; same block order in OpenIPSL ``PSS2B`` and PowerSimulationsDynamics.jl)::

        u1 = clip(input(ICS1), VS1MIN, VS1MAX),  u2 = clip(input(ICS2), VS2MIN, VS2MAX)
        ... PSS2A path on u1, u2 ...
        VST = clip(... (1 + s T3)/(1 + s T4) (1 + s T10)/(1 + s T11) ..., VSTMIN, VSTMAX)

    States (17): PSS2A's 16 and the third lead-lag. T11 = 0 bypasses the third lead-lag.
    The input limits act on the raw signals (speed deviation in pu, PELEC in pu on MBASE).
    """

    t10_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T10: third lead [s]."""
    t11_s: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """T11: third lag [s] (0: lead-lag bypassed)."""
    vs1_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.08)
    """VS1MAX: upper limit of input 1 [pu]."""
    vs1_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-0.08)
    """VS1MIN: lower limit of input 1 [pu]."""
    vs2_max_pu: Float[Array, ""] = eqx.field(converter=as_float, default=1.25)
    """VS2MAX: upper limit of input 2 [pu]."""
    vs2_min_pu: Float[Array, ""] = eqx.field(converter=as_float, default=-1.25)
    """VS2MIN: lower limit of input 2 [pu]."""

    def __check_init__(self):   # PSS2A's checks run too (equinox runs each class's own)
        for hi, lo, name in ((self.vs1_max_pu, self.vs1_min_pu, "VS1"),
                             (self.vs2_max_pu, self.vs2_min_pu, "VS2")):
            if all_concrete(hi, lo):
                check_that(self, hi >= lo, f"{name}MAX ({hi}) must be >= {name}MIN ({lo})")

    def _time_constants(self):
        return super()._time_constants() + ("t10_s", "t11_s")

    def _lead_lags(self):
        return super()._lead_lags() + ((self.t10_s, self.t11_s),)

    def _inputs(self, inputs):
        u1, u2 = super()._inputs(inputs)
        return (jnp.clip(u1, self.vs1_min_pu, self.vs1_max_pu),
                jnp.clip(u2, self.vs2_min_pu, self.vs2_max_pu))


# --- STAB2A -----------------------------------------------------------------------------------

class STAB2A(AbstractStabiliser):
    """PSS/E STAB2A, the ASEA power-sensitive stabilising unit: VOTHSG from the electrical power.

    Block diagram (Siemens PTI *PSS/E Model Library*, "STAB2A"; the block order and the place
    of K2 cross-read in OpenIPSL ``OpenIPSL.Electrical.Controls.PSSE.PSS.STAB2A``, which cites
    the PSS/E manual, and the IEC 61970-302 ``PssSTAB2A`` parameter list; no code taken)::

        w1  = -K2 s T2/(1 + s T2) PELEC
        w2  =  K2 s T2/(1 + s T2) w1
        w3  =  K2 s T2/(1 + s T2) w2
        y   = K3/(1 + s T3) w3 + K4 w3
        VOTHSG = clip(K5/(1 + s T5) K5/(1 + s T5) y, -HLIM, HLIM)

    8 CONs (no ICON): K2 [-], T2 [s] (> 0), K3 [-], T3 [s], K4 [-], K5 [-], T5 [s], HLIM [pu]
    (>= 0). PELEC is the machine's electrical power [pu on MBASE, positive generating], the
    input that the other stabilisers take as MODE 3.

    The three washouts carry K2 each (an overall K2^3), as OpenIPSL draws them; the PSS/E text
    itself was not available here to settle whether K2 sits in the first washout only. Every
    STAB2A record in the public Nordic 44 case has K2 = 1, where both readings coincide.

    States: [w1 washout, w2 washout, w3 washout, K3 lag, first K5 lag, second K5 lag]. At
    constant PELEC = p0 the rest state is [p0, 0, 0, 0, 0, 0] and VOTHSG = 0. T3 = 0 and T5 = 0
    make their lags gains (state kept, zero derivative); T2 must be > 0 (T2 = 0 would make the
    output identically 0: ValueError when concrete). The output limit clips the last lag's
    output (no state is held).
    """

    k2: Float[Array, ""] = eqx.field(converter=as_float, default=1.0)
    """K2: gain of each of the three washouts [-]."""
    t2_s: Float[Array, ""] = eqx.field(converter=as_float, default=4.0)
    """T2: washout time constant [s] (> 0)."""
    k3: Float[Array, ""] = eqx.field(converter=as_float, default=0.25)
    """K3: gain of the low-pass branch [-]."""
    t3_s: Float[Array, ""] = eqx.field(converter=as_float, default=2.0)
    """T3: time constant of the low-pass branch [s] (0: gain K3)."""
    k4: Float[Array, ""] = eqx.field(converter=as_float, default=0.075)
    """K4: gain of the proportional branch [-]."""
    k5: Float[Array, ""] = eqx.field(converter=as_float, default=2.5)
    """K5: gain of each of the two output lags [-]."""
    t5_s: Float[Array, ""] = eqx.field(converter=as_float, default=4.5)
    """T5: time constant of each output lag [s] (0: gain K5)."""
    h_lim_pu: Float[Array, ""] = eqx.field(converter=as_float, default=0.5)
    """HLIM: output limit, VOTHSG within [-HLIM, HLIM] [pu] (>= 0)."""

    def __check_init__(self):
        check_nonnegative(self, "t3_s", "t5_s", "h_lim_pu")
        if all_concrete(self.t2_s):
            check_that(self, self.t2_s > 0,
                       f"T2 must be > 0 (washouts K2 s T2/(1 + s T2)), got {self.t2_s}")

    @property
    def n_states(self) -> int:
        return 6

    @property
    def remote_input_at_terminal(self) -> bool:
        """Always False: STAB2A takes the machine's own electrical power."""
        return False

    def _path(self, state, inputs):
        p = _signal(inputs, 3)
        w1, d1 = _washout(p, state[0], -self.k2, self.t2_s, self.t2_s)
        w2, d2 = _washout(w1, state[1], self.k2, self.t2_s, self.t2_s)
        w3, d3 = _washout(w2, state[2], self.k2, self.t2_s, self.t2_s)
        y3, d4 = _lag(self.k3 * w3, state[3], self.t3_s)
        a, d5 = _lag(self.k5 * (y3 + self.k4 * w3), state[4], self.t5_s)
        b, d6 = _lag(self.k5 * a, state[5], self.t5_s)
        return b, jnp.stack([d1, d2, d3, d4, d5, d6])

    def initial_state(self, inputs: StabiliserInputs):
        p = _signal(inputs, 3)
        zero = jnp.zeros_like(p)
        return jnp.stack([p, zero, zero, zero, zero, zero])

    def vector_field(self, state, inputs: StabiliserInputs):
        return self._path(state, inputs)[1]

    def output(self, state, inputs: StabiliserInputs):
        v, _ = self._path(state, inputs)
        return jnp.clip(v, -self.h_lim_pu, self.h_lim_pu)


# --- .dyr records -----------------------------------------------------------------------------

STABILISER_FIELDS = {
    "IEEEST": ("MODE", "busr", "A1", "A2", "A3", "A4", "A5", "A6", "T1", "T2", "T3", "T4", "T5",
               "T6", "KS", "LSMAX", "LSMIN", "VCU", "VCL"),
    "ST2CUT": ("MODE", "busr", "MODE2", "busr2", "K1", "K2", "T1", "T2", "T3", "T4", "T5", "T6",
               "T7", "T8", "T9", "T10", "LSMAX", "LSMIN", "VCU", "VCL"),
    "PSS2A": ("ICS1", "REMBUS1", "ICS2", "REMBUS2", "M", "N", "TW1", "TW2", "T6", "TW3", "TW4",
              "T7", "KS2", "KS3", "T8", "T9", "KS1", "T1", "T2", "T3", "T4", "VSTMAX", "VSTMIN"),
    "PSS2B": ("ICS1", "REMBUS1", "ICS2", "REMBUS2", "M", "N", "TW1", "TW2", "T6", "TW3", "TW4",
              "T7", "KS2", "KS3", "T8", "T9", "KS1", "T1", "T2", "T3", "T4", "T10", "T11",
              "VS1MAX", "VS1MIN", "VS2MAX", "VS2MIN", "VSTMAX", "VSTMIN"),
    "STAB2A": ("K2", "T2", "K3", "T3", "K4", "K5", "T5", "HLIM"),
}
"""PSS/E names of each stabiliser record's constants in PSS/E order, ICONs first."""

STABILISER_ICONS = {"IEEEST": ("MODE", "busr"), "ST2CUT": ("MODE", "busr", "MODE2", "busr2"),
                    "PSS2A": ("ICS1", "REMBUS1", "ICS2", "REMBUS2", "M", "N"),
                    "PSS2B": ("ICS1", "REMBUS1", "ICS2", "REMBUS2", "M", "N"), "STAB2A": ()}
"""The integer constants (ICONs) of each record."""

_PSS2A_PARAMETERS = {
    "mode": "ICS1", "remote_bus": "REMBUS1", "mode2": "ICS2", "remote_bus2": "REMBUS2",
    "m_rtf": "M", "n_rtf": "N", "tw1_s": "TW1", "tw2_s": "TW2", "t6_s": "T6", "tw3_s": "TW3",
    "tw4_s": "TW4", "t7_s": "T7", "ks2": "KS2", "ks3": "KS3", "t8_s": "T8", "t9_s": "T9",
    "ks1": "KS1", "t1_s": "T1", "t2_s": "T2", "t3_s": "T3", "t4_s": "T4",
    "vst_max_pu": "VSTMAX", "vst_min_pu": "VSTMIN"}

STABILISER_PARAMETERS = {
    "IEEEST": {"mode": "MODE", "remote_bus": "busr", "a1_s": "A1", "a2_s2": "A2", "a3_s": "A3",
               "a4_s2": "A4", "a5_s": "A5", "a6_s2": "A6", "t1_s": "T1", "t2_s": "T2",
               "t3_s": "T3", "t4_s": "T4", "t5_s": "T5", "t6_s": "T6", "ks": "KS",
               "ls_max_pu": "LSMAX", "ls_min_pu": "LSMIN", "vcu_pu": "VCU", "vcl_pu": "VCL"},
    "ST2CUT": {"mode": "MODE", "remote_bus": "busr", "mode2": "MODE2", "remote_bus2": "busr2",
               "k1": "K1", "k2": "K2", "t1_s": "T1", "t2_s": "T2", "t3_s": "T3", "t4_s": "T4",
               "t5_s": "T5", "t6_s": "T6", "t7_s": "T7", "t8_s": "T8", "t9_s": "T9",
               "t10_s": "T10", "ls_max_pu": "LSMAX", "ls_min_pu": "LSMIN", "vcu_pu": "VCU",
               "vcl_pu": "VCL"},
    "PSS2A": _PSS2A_PARAMETERS,
    "PSS2B": {**_PSS2A_PARAMETERS, "t10_s": "T10", "t11_s": "T11", "vs1_max_pu": "VS1MAX",
              "vs1_min_pu": "VS1MIN", "vs2_max_pu": "VS2MAX", "vs2_min_pu": "VS2MIN"},
    "STAB2A": {"k2": "K2", "t2_s": "T2", "k3": "K3", "t3_s": "T3", "k4": "K4", "k5": "K5",
               "t5_s": "T5", "h_lim_pu": "HLIM"},
}
"""Field of the stabiliser module (``STABILISERS[model]``) -> the PSS/E constant it takes."""

STABILISERS = {"IEEEST": IEEEST, "ST2CUT": ST2CUT, "PSS2A": PSS2A, "PSS2B": PSS2B, "STAB2A": STAB2A}


def stabiliser_from_dyr(model: str, constants: Sequence[float]) -> AbstractStabiliser:
    """The stabiliser module of a .dyr record: ``constants`` are its ICONs then CONs in PSS/E
    order (:data:`STABILISER_FIELDS`). Raises a one-line ValueError for an unknown model, a
    wrong number of constants, a non-integer or out-of-range ICON, or invalid parameters."""
    names = STABILISER_FIELDS.get(model)
    if names is None:
        raise ValueError(f"{model!r} is not a supported stabiliser model ({', '.join(STABILISERS)})")
    if len(constants) != len(names):
        raise ValueError(f"{model}: expected {len(names)} constants ({' '.join(names)}), "
                         f"got {len(constants)}")
    values = {}
    for name, value in zip(names, constants):
        try:
            x = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{model}: {name} is not a number: {value!r}") from None
        if not np.isfinite(x):
            raise ValueError(f"{model}: {name} is not finite: {value!r}")
        if name in STABILISER_ICONS[model]:
            if x != round(x):
                raise ValueError(f"{model}: ICON {name} must be an integer, got {value!r}")
            x = int(round(x))
        values[name] = x
    kwargs = {f: values[name] for f, name in STABILISER_PARAMETERS[model].items()}
    try:
        return STABILISERS[model](**kwargs)
    except ValueError as err:  # name the CONs as the record does
        raise ValueError(record_message(str(err), model, STABILISER_PARAMETERS[model])) from None


__all__ = ["IEEEST", "INPUT_MODES", "PSS2A", "PSS2B", "RTF_MAX_STAGES", "ST2CUT", "STAB2A", "STABILISERS",
           "STABILISER_FIELDS", "STABILISER_ICONS", "STABILISER_PARAMETERS", "stabiliser_from_dyr"]
