"""A unit's .dyr model: the composition of its machine, exciter, stabiliser and governor.

The state is one flat vector ``[machine | exciter | stabiliser | governor]``; a missing exciter
holds Efd at its initial value, a missing governor holds Tm (as PSS/E does for a machine
without those records). Signal flow at one instant, terminal voltage imposed:
machine currents -> stabiliser VOTHSG -> exciter Efd -> machine fluxes; speed -> governor Tm.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array

from .._models.base import AbstractExciter, AbstractStabiliser, ExciterInputs, StabiliserInputs
from .._models.governors import GGOV1, AbstractGovernor
from .._models.machines import AbstractMachine, Terminal


class UnitReferences(NamedTuple):
    """The references that hold the initial steady state (constant during a playback)."""

    efd0_pu: Array
    """Initial field voltage [pu]; Efd of a unit without exciter."""
    tm0_pu: Array
    """Initial mechanical torque [pu]; Tm of a unit without governor."""
    vref_pu: Array
    """Exciter voltage reference [pu] (0 without exciter)."""
    t_ref_pu: Array
    """Governor reference [pu] (``tm0`` without governor)."""


class UnitInputs(NamedTuple):
    """The imposed terminal quantities at one instant (machine base, network frame)."""

    v_re_pu: Array
    v_im_pu: Array
    freq_dev_pu: Array
    """Bus frequency deviation [pu]: d(angle)/dt / omega_s."""
    dvt_dt_pu_s: Array
    """d|V|/dt [pu/s]."""


class DyrUnit(eqx.Module):
    """One generating unit as its PSS/E records describe it (machine base)."""

    machine: AbstractMachine
    exciter: AbstractExciter | None = None
    stabiliser: AbstractStabiliser | None = None
    governor: AbstractGovernor | None = None

    @property
    def sizes(self) -> tuple[int, int, int, int]:
        """States of machine, exciter, stabiliser and governor."""
        n_gov = 0 if self.governor is None else jax.eval_shape(
            lambda g: g.steady_state(jnp.asarray(1.0), jnp.asarray(0.0)), self.governor).shape[-1]
        return (self.machine.n_states, 0 if self.exciter is None else self.exciter.n_states,
                0 if self.stabiliser is None else self.stabiliser.n_states, n_gov)

    def split(self, y):
        """(machine, exciter, stabiliser, governor) parts of the flat state."""
        out, k = [], 0
        for n in self.sizes:
            out.append(y[k:k + n])
            k += n
        return tuple(out)

    def _stab_inputs(self, y_m, out: Terminal, u: UnitInputs, tm):
        vt = jnp.hypot(u.v_re_pu, u.v_im_pu)
        return StabiliserInputs(speed_dev_pu=y_m[-1] - 1.0, freq_dev_pu=u.freq_dev_pu,
                                p_elec_pu=out.p_pu, p_accel_pu=tm - out.te_pu, vt_pu=vt,
                                dvt_dt_pu_s=u.dvt_dt_pu_s)

    def _exc_inputs(self, out: Terminal, u: UnitInputs, vs):
        return ExciterInputs(vt_pu=jnp.hypot(u.v_re_pu, u.v_im_pu), v_re_pu=u.v_re_pu,
                             v_im_pu=u.v_im_pu, i_re_pu=out.i_re_pu, i_im_pu=out.i_im_pu,
                             ifd_pu=out.ifd_pu, vs_pu=vs)

    def _tm(self, y_g, y_m, refs: UnitReferences):
        if self.governor is None:
            return refs.tm0_pu
        return self.governor.torque(y_g, y_m[-1] - 1.0)

    def signals(self, y, u: UnitInputs, refs: UnitReferences):
        """(terminal outputs, Efd, Tm, VOTHSG) at state ``y``."""
        y_m, y_e, y_s, y_g = self.split(y)
        out = self.machine.terminal(y_m, u.v_re_pu, u.v_im_pu)
        tm = self._tm(y_g, y_m, refs)
        vs = (jnp.zeros_like(tm) if self.stabiliser is None
              else self.stabiliser.output(y_s, self._stab_inputs(y_m, out, u, tm)))
        efd = (refs.efd0_pu if self.exciter is None
               else self.exciter.efd(y_e, self._exc_inputs(out, u, vs), refs.vref_pu))
        return out, efd, tm, vs

    def vector_field(self, y, u: UnitInputs, refs: UnitReferences):
        """d(state)/dt."""
        y_m, y_e, y_s, y_g = self.split(y)
        out, efd, tm, vs = self.signals(y, u, refs)
        parts = [self.machine.vector_field(y_m, u.v_re_pu, u.v_im_pu, efd, tm)]
        if self.exciter is not None:
            parts.append(self.exciter.vector_field(y_e, self._exc_inputs(out, u, vs), refs.vref_pu))
        if self.stabiliser is not None:
            parts.append(self.stabiliser.vector_field(y_s, self._stab_inputs(y_m, out, u, tm)))
        if self.governor is not None:
            dw = y_m[-1] - 1.0
            if isinstance(self.governor, GGOV1):
                parts.append(self.governor.vector_field(y_g, dw, refs.t_ref_pu, p_elec=out.p_pu))
            else:
                parts.append(self.governor.vector_field(y_g, dw, refs.t_ref_pu))
        return jnp.concatenate(parts)

    def initial_state(self, u: UnitInputs, i_re, i_im):
        """(y0, references): the steady state that delivers current ``I`` at ``u``'s voltage."""
        ms = self.machine.steady_state(u.v_re_pu, u.v_im_pu, i_re, i_im)
        parts = [ms.state]
        vref = jnp.zeros_like(ms.efd_pu)
        out = self.machine.terminal(ms.state, u.v_re_pu, u.v_im_pu)
        t_ref = ms.tm_pu
        if self.governor is not None:
            t_ref = self.governor.reference_from_steady(ms.tm_pu, jnp.zeros_like(ms.tm_pu))
        if self.exciter is not None:
            y_e, vref = self.exciter.initial_state(ms.efd_pu, self._exc_inputs(out, u, jnp.zeros_like(vref)))
            parts.append(y_e)
        if self.stabiliser is not None:
            parts.append(self.stabiliser.initial_state(self._stab_inputs(ms.state, out, u, ms.tm_pu)))
        if self.governor is not None:
            parts.append(self.governor.steady_state(t_ref, jnp.zeros_like(t_ref)))
        return jnp.concatenate(parts), UnitReferences(ms.efd_pu, ms.tm_pu, vref, t_ref)


__all__ = ["DyrUnit", "UnitInputs", "UnitReferences"]
