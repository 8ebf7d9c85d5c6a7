"""An inverter-based plant's .dyr model: converter (REGCA1 or REGCB1), electrical controls
(REECA1, REECB1 or REECCU1), an optional plant controller (REPCA1) and, for a type-3 wind turbine, its optional mechanics (torque
controller WTTQA1, pitch controller WTPTA1, aerodynamics WTARA1, drive train WTDTA1), driven as a
machine's :class:`~jaxdse._dyr.unit.DyrUnit` is: the terminal voltage phasor and the frequency
deviation imposed (:class:`UnitInputs`).

The state is one flat vector ``[converter | electrical | plant | torque | pitch | drive]`` (a part
absent from the records has no state). Signal flow at one instant: converter states and |V| ->
injected currents -> P, Q; drive train -> turbine and generator speeds wt, wg; plant controller
(P, Q, V, I, frequency) -> Pref, Qext; torque controller (Pe, wg, the plant's Pref) -> the Pref
of the electrical controls, and the speed reference wref; electrical controls (Pref, with wg
where PFLAG = 1) -> Ipcmd, Iqcmd -> converter; pitch controller (wt, wref, the power order) ->
pitch -> aerodynamics -> Pm -> drive train. Every signal is an explicit function of the states
and the inputs (no algebraic loop). Without a plant controller, Pref and Qext are held at their
initial values (as PSS/E does for a REECA1 without REPCA1). Without a drive train record the
rotor speed is held at its initial value (the torque controller's speed table at the initial
power, 1 pu without a torque controller): the mechanics left (pitch, aerodynamics) then have no
path back to the electrical output.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._base.fields import as_float
from .._models.ibr import (
    REECA1,
    REECB1,
    REECCU1,
    REGCA1,
    REGCB1,
    REPCA1,
    WTARA1,
    WTDTA1,
    WTPTA1,
    WTTQA1,
    ElectricalInputs,
    ElectricalReferences,
    PlantInputs,
    PlantReferences,
)
from .unit import UnitInputs


class WindReferences(NamedTuple):
    """The references of a wind turbine's mechanics (zeros and 1 pu speed without them)."""

    speed_pu: Array
    """w0: the rotor speed at the start [pu] (held without a drive train)."""
    p_mech_pu: Array
    """Pm0: the aerodynamic power at the start [pu] (= P0)."""
    p_ord_pu: Array
    """Pord0: REECA1's power order at the start [pu] (the pitch compensator's reference)."""
    theta0_deg: Array
    """The pitch at the start [deg] (WTARA1's Theta0, 0 without it)."""


class IbrReferences(NamedTuple):
    """The references that hold the initial steady state (constant during a playback)."""

    p_ref_pu: Array
    """Pref of the electrical controls [pu] (held without a plant controller)."""
    q_ext_pu: Array
    """Qext of the electrical controls [pu] (held without a plant controller)."""
    electrical: ElectricalReferences
    """The electrical controls' references (zeros without them)."""
    ipcmd_pu: Array
    """Ipcmd at the start [pu] (held without electrical controls)."""
    iqcmd_pu: Array
    """Iqcmd at the start [pu] (held without electrical controls)."""
    plant: PlantReferences
    """The plant controller's references (zeros without one)."""
    wind: WindReferences


class IbrSignals(NamedTuple):
    """The plant's outputs at one instant (machine base, network frame)."""

    i_re_pu: Array
    """Current out of the terminal, real part [pu]."""
    i_im_pu: Array
    p_pu: Array
    """Active power out of the terminal [pu]."""
    q_pu: Array
    """Reactive power out of the terminal [pu]."""
    ip_pu: Array
    """Injected active current [pu]."""
    iq_pu: Array
    """Injected reactive current [pu] (positive: capacitive)."""
    ipcmd_pu: Array
    iqcmd_pu: Array
    p_ref_pu: Array
    """Pref reaching the electrical controls [pu]."""
    q_ext_pu: Array
    """Qext reaching the electrical controls [pu]."""
    dip: Array
    """True while the electrical controls' voltage-dip logic freezes them."""
    speed_pu: Array
    """Generator speed wg [pu] (1 without wind mechanics)."""
    p_mech_pu: Array
    """Aerodynamic power Pm [pu] (P without an aerodynamic model)."""


class IbrUnit(eqx.Module):
    """One inverter-based plant as its PSS/E records describe it (machine base)."""

    converter: REGCA1 | REGCB1
    electrical: REECA1 | REECB1 | REECCU1 | None
    """None: no electrical control record; Ipcmd and Iqcmd held at their initial values (PSS/E
    holds the output of a controller the case does not model, as an Efd without exciter)."""
    plant: REPCA1 | None = None
    torque: WTTQA1 | None = None
    pitch: WTPTA1 | None = None
    aero: WTARA1 | None = None
    drive: WTDTA1 | None = None
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * jnp.pi * 60.0)
    """Nominal angular frequency [rad/s]: a playback turns the recorded angle's slope into the
    frequency deviation with it (as for a machine)."""

    PARTS = ("converter", "electrical", "plant", "torque", "pitch", "aero", "drive")
    """The parts in the order of the flat state."""

    @property
    def sizes(self) -> tuple[int, ...]:
        """States of each part of :data:`PARTS` (0 for a part absent)."""
        return tuple(0 if getattr(self, k) is None else getattr(self, k).n_states for k in self.PARTS)

    @property
    def n_states(self) -> int:
        return sum(self.sizes)

    @property
    def at_rest(self) -> np.ndarray:
        """Which states a steady state holds still (host bool array): all but REECCU1's state
        of charge, which integrates the output power (at rest only at P = 0)."""
        mask = np.ones(self.n_states, dtype=bool)
        if isinstance(self.electrical, REECCU1):
            mask[self.converter.n_states + 6] = False
        return mask

    def split(self, y) -> dict:
        """The flat state's part of each of :data:`PARTS`."""
        out, start = {}, 0
        for k, n in zip(self.PARTS, self.sizes):
            out[k] = y[start:start + n]
            start += n
        return out

    @staticmethod
    def _currents(u: UnitInputs, ip, iq):
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        c, s = u.v_re_pu / vt, u.v_im_pu / vt
        # I = (Ip - j Iq) V/|V|: S = V conj(I) = |V| (Ip + j Iq)
        return vt, ip * c + iq * s, ip * s - iq * c

    def _speeds(self, ys: dict, refs: IbrReferences):
        if self.drive is None:
            w = refs.wind.speed_pu
            return w, w
        return self.drive.speeds(ys["drive"])

    def _flow(self, y, u: UnitInputs, refs: IbrReferences):
        """Every signal at one instant (the dict of :meth:`signals` and the parts' inputs)."""
        ys = self.split(y)
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        ip, iq = self.converter.injection(ys["converter"], vt)
        vt, i_re, i_im = self._currents(u, ip, iq)
        p, q = vt * ip, vt * iq
        wt, wg = self._speeds(ys, refs)
        if self.plant is None:
            p_plant, q_ext = refs.p_ref_pu, refs.q_ext_pu
        else:
            p_plant, q_ext = self.plant.outputs(ys["plant"], self._plant_inputs(u, i_re, i_im, p, q),
                                                refs.plant)
        w_ref = wg
        p_ref = p_plant
        if self.torque is not None:
            p_ref, w_ref = self.torque.outputs(ys["torque"], p, wg, p_plant)
        e_in = ElectricalInputs(vt, p, q, p_ref, q_ext, wg + 0.0 * vt)
        if self.electrical is None:
            ipcmd, iqcmd, dip = refs.ipcmd_pu + 0.0 * vt, refs.iqcmd_pu + 0.0 * vt, vt < 0.0
        else:
            ipcmd, iqcmd, dip, _ = self.electrical.commands(ys["electrical"], e_in, refs.electrical)
        theta = refs.wind.theta0_deg
        if self.pitch is not None:
            theta = self.pitch.pitch(ys["pitch"])
        p_mech = p
        if self.aero is not None:
            p_mech = self.aero.mechanical_power(theta, refs.wind.p_mech_pu)
        sig = IbrSignals(i_re, i_im, p, q, ip, iq, ipcmd, iqcmd, p_ref, q_ext, dip, wg + 0.0 * vt,
                         p_mech + 0.0 * vt)
        return sig, ys, e_in, dict(wt=wt, wg=wg, w_ref=w_ref, p_plant=p_plant)

    def signals(self, y, u: UnitInputs, refs: IbrReferences) -> IbrSignals:
        """The plant's outputs at state ``y``."""
        return self._flow(y, u, refs)[0]

    @staticmethod
    def _plant_inputs(u: UnitInputs, i_re, i_im, p, q):
        return PlantInputs(u.v_re_pu, u.v_im_pu, i_re, i_im, p, q, u.freq_dev_pu)

    def vector_field(self, y, u: UnitInputs, refs: IbrReferences):
        """d(state)/dt."""
        s, ys, e_in, w = self._flow(y, u, refs)
        vt = e_in.vt_pu
        parts = [self.converter.vector_field(ys["converter"], vt, s.ipcmd_pu, s.iqcmd_pu)]
        if self.electrical is not None:
            parts.append(self.electrical.vector_field(ys["electrical"], e_in, refs.electrical))
        if self.plant is not None:
            parts.append(self.plant.vector_field(
                ys["plant"], self._plant_inputs(u, s.i_re_pu, s.i_im_pu, s.p_pu, s.q_pu), refs.plant))
        if self.torque is not None:
            parts.append(self.torque.vector_field(ys["torque"], s.p_pu, w["wg"], w["p_plant"], s.dip))
        if self.pitch is not None:
            p_ord = (refs.wind.p_ord_pu if self.electrical is None
                     else self.electrical.power_order(ys["electrical"], e_in))
            parts.append(self.pitch.vector_field(ys["pitch"], w["wt"], w["w_ref"], p_ord,
                                                 refs.wind.p_ord_pu))
        if self.drive is not None:
            parts.append(self.drive.vector_field(ys["drive"], s.p_mech_pu, s.p_pu, refs.wind.speed_pu))
        return jnp.concatenate(parts)

    def initial_state(self, u: UnitInputs, i_re, i_im):
        """(y0, references): the steady state that delivers current ``I`` (out of the terminal,
        network frame) at ``u``'s voltage (frequency deviation taken as 0)."""
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        # S = V conj(I)
        p = u.v_re_pu * i_re + u.v_im_pu * i_im
        q = u.v_im_pu * i_re - u.v_re_pu * i_im
        y_c, ipcmd, iqcmd = self.converter.initial_state(vt, p, q)
        if self.electrical is None:
            zero = jnp.zeros_like(vt)
            y_e, e_refs = zero[None][:0], ElectricalReferences(zero, zero, zero)
            p_ref, q_ext = ipcmd * vt, q + 0.0 * vt
        else:
            y_e, e_refs, p_ref, q_ext = self.electrical.initial_state(vt, p, q, ipcmd, iqcmd)
        p_ord0 = p_ref                            # REECA1's Pord at the start (speed w0 included)
        one = jnp.ones_like(vt)
        w0 = one
        y_t = None
        if self.torque is not None:
            # PFLAG = 1: REECA1 multiplies Pref by wg, so the torque controller sends Pord0/w0
            w0 = self.torque.speed_table(p) + 0.0 * vt
            p_ref = jnp.where(self._pflag, p_ref / w0, p_ref)
            y_t, _ = self.torque.initial_state(p, p_ref)
        theta0 = jnp.zeros_like(vt) if self.aero is None else self.aero.theta0_deg + 0.0 * vt
        parts = [y_c, y_e]
        zero = jnp.zeros_like(vt)
        p_refs = PlantReferences(zero, zero, zero)
        # the plant controller's Pref: the held initial power of the torque controller (Tflag = 0),
        # else the Pref of REECA1 itself
        p_plant = p + 0.0 * vt if self.torque is not None else p_ref
        if self.plant is not None:
            u0 = u._replace(freq_dev_pu=zero)
            y_p, p_refs = self.plant.initial_state(self._plant_inputs(u0, i_re, i_im, p, q), p_plant, q_ext)
            parts.append(y_p)
        if y_t is not None:
            parts.append(y_t)
        if self.pitch is not None:
            parts.append(self.pitch.initial_state(theta0))
        if self.drive is not None:
            parts.append(self.drive.initial_state(w0, p))
        wind = WindReferences(w0, p + 0.0 * vt, p_ord0 + 0.0 * vt, theta0)
        return jnp.concatenate(parts), IbrReferences(p_plant, q_ext, e_refs, ipcmd + 0.0 * vt,
                                                     iqcmd + 0.0 * vt, p_refs, wind)

    @property
    def _pflag(self):
        """PFLAG = 1 (a boolean array: the flag is a leaf, not part of the structure)."""
        return jnp.asarray(False) if self.electrical is None else self.electrical.pflag != 0


__all__ = ["IbrReferences", "IbrSignals", "IbrUnit", "WindReferences"]
