"""An inverter-based plant's .dyr model: converter (REGCA1 or REGCB1), electrical controls
(REECA1, REECB1 or REECCU1) and an optional plant controller (REPCA1), driven as a machine's :class:`~jaxdse._dyr.unit.DyrUnit` is:
the terminal voltage phasor and the frequency deviation imposed (:class:`UnitInputs`).

The state is one flat vector ``[converter | electrical | plant]``. Signal flow at one instant:
converter states and |V| -> injected currents -> P, Q; plant controller (P, Q, V, I, frequency)
-> Pref, Qext; electrical controls -> Ipcmd, Iqcmd -> converter. Every signal is an explicit
function of the states and the inputs (no algebraic loop). Without a plant controller, Pref and
Qext are held at their initial values (as PSS/E does for a REECA1 without REPCA1).
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
    ElectricalInputs,
    ElectricalReferences,
    PlantInputs,
    PlantReferences,
)
from .unit import UnitInputs


class IbrReferences(NamedTuple):
    """The references that hold the initial steady state (constant during a playback)."""

    p_ref_pu: Array
    """Pref of the electrical controls [pu] (held without a plant controller)."""
    q_ext_pu: Array
    """Qext of the electrical controls [pu] (held without a plant controller)."""
    electrical: ElectricalReferences
    plant: PlantReferences
    """The plant controller's references (zeros without one)."""


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


class IbrUnit(eqx.Module):
    """One inverter-based plant as its PSS/E records describe it (machine base)."""

    converter: REGCA1 | REGCB1
    electrical: REECA1 | REECB1 | REECCU1
    plant: REPCA1 | None = None
    omega_s_rad_s: Float[Array, ""] = eqx.field(converter=as_float, default=2 * jnp.pi * 60.0)
    """Nominal angular frequency [rad/s]: a playback turns the recorded angle's slope into the
    frequency deviation with it (as for a machine)."""

    @property
    def sizes(self) -> tuple[int, int, int]:
        """States of converter, electrical controls and plant controller."""
        return (self.converter.n_states, self.electrical.n_states,
                0 if self.plant is None else self.plant.n_states)

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

    def split(self, y):
        """(converter, electrical, plant) parts of the flat state."""
        a, b, _ = self.sizes
        return y[:a], y[a:a + b], y[a + b:]

    @staticmethod
    def _currents(u: UnitInputs, ip, iq):
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        c, s = u.v_re_pu / vt, u.v_im_pu / vt
        # I = (Ip - j Iq) V/|V|: S = V conj(I) = |V| (Ip + j Iq)
        return vt, ip * c + iq * s, ip * s - iq * c

    def signals(self, y, u: UnitInputs, refs: IbrReferences) -> IbrSignals:
        """The plant's outputs at state ``y``."""
        y_c, y_e, y_p = self.split(y)
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        ip, iq = self.converter.injection(y_c, vt)
        vt, i_re, i_im = self._currents(u, ip, iq)
        p, q = vt * ip, vt * iq
        if self.plant is None:
            p_ref, q_ext = refs.p_ref_pu, refs.q_ext_pu
        else:
            p_ref, q_ext = self.plant.outputs(y_p, self._plant_inputs(u, i_re, i_im, p, q), refs.plant)
        e_in = ElectricalInputs(vt, p, q, p_ref, q_ext, jnp.ones_like(vt))
        ipcmd, iqcmd, dip, _ = self.electrical.commands(y_e, e_in, refs.electrical)
        return IbrSignals(i_re, i_im, p, q, ip, iq, ipcmd, iqcmd, p_ref, q_ext, dip)

    @staticmethod
    def _plant_inputs(u: UnitInputs, i_re, i_im, p, q):
        return PlantInputs(u.v_re_pu, u.v_im_pu, i_re, i_im, p, q, u.freq_dev_pu)

    def vector_field(self, y, u: UnitInputs, refs: IbrReferences):
        """d(state)/dt."""
        y_c, y_e, y_p = self.split(y)
        s = self.signals(y, u, refs)
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        e_in = ElectricalInputs(vt, s.p_pu, s.q_pu, s.p_ref_pu, s.q_ext_pu, jnp.ones_like(vt))
        parts = [self.converter.vector_field(y_c, vt, s.ipcmd_pu, s.iqcmd_pu),
                 self.electrical.vector_field(y_e, e_in, refs.electrical)]
        if self.plant is not None:
            parts.append(self.plant.vector_field(
                y_p, self._plant_inputs(u, s.i_re_pu, s.i_im_pu, s.p_pu, s.q_pu), refs.plant))
        return jnp.concatenate(parts)

    def initial_state(self, u: UnitInputs, i_re, i_im):
        """(y0, references): the steady state that delivers current ``I`` (out of the terminal,
        network frame) at ``u``'s voltage (frequency deviation taken as 0)."""
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        # S = V conj(I)
        p = u.v_re_pu * i_re + u.v_im_pu * i_im
        q = u.v_im_pu * i_re - u.v_re_pu * i_im
        y_c, ipcmd, iqcmd = self.converter.initial_state(vt, p, q)
        y_e, e_refs, p_ref, q_ext = self.electrical.initial_state(vt, p, q, ipcmd, iqcmd)
        parts = [y_c, y_e]
        zero = jnp.zeros_like(vt)
        p_refs = PlantReferences(zero, zero, zero)
        if self.plant is not None:
            u0 = u._replace(freq_dev_pu=zero)
            y_p, p_refs = self.plant.initial_state(self._plant_inputs(u0, i_re, i_im, p, q), p_ref, q_ext)
            parts.append(y_p)
        return jnp.concatenate(parts), IbrReferences(p_ref, q_ext, e_refs, p_refs)


__all__ = ["IbrReferences", "IbrSignals", "IbrUnit"]
