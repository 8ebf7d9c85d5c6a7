"""A grid-forming converter (ANDES REGCV1/REGCV2: a virtual synchronous generator; WECC REGFM_A1:
droop-controlled; WECC REGFM_B1: a virtual synchronous machine) as a unit,
driven as a machine's :class:`~jaxdse._dyr.unit.DyrUnit` and an inverter-based plant's
:class:`~jaxdse._dyr.ibr_unit.IbrUnit` are: the terminal voltage phasor imposed
(:class:`~jaxdse._dyr.unit.UnitInputs`; the frequency is not an input, the virtual rotor makes
its own). Its parameters sit under ``converter`` (so that :func:`~jaxdse._dyr.calibrate.calibrate`
fits them with ``ParameterSpec("converter", "m_s", "M", ...)``), and its classical-machine
equivalent for the estimator is :func:`classical_plant`.
"""

from __future__ import annotations

import math

import equinox as eqx
import numpy as np

from .._core.machine import Machine
from .._core.plant import Plant
from .._models.governors import TGOV1
from .._models.ibr import REGCV1, REGFM_A1, REGFM_B1, GfmReferences, GfmSignals
from .unit import UnitInputs


class GfmUnit(eqx.Module):
    """One grid-forming converter (machine base = the converter's Sn)."""

    converter: REGCV1 | REGFM_A1 | REGFM_B1

    PARTS = ("converter",)
    """The unit's one part (as :class:`~jaxdse._dyr.ibr_unit.IbrUnit` names its parts)."""

    @property
    def sizes(self) -> tuple[int, ...]:
        return (self.converter.n_states,)

    @property
    def at_rest(self) -> np.ndarray:
        """Every state is held by the steady state."""
        return np.ones(self.converter.n_states, bool)

    @property
    def omega_s_rad_s(self):
        return self.converter.omega_s_rad_s

    @property
    def n_states(self) -> int:
        return self.converter.n_states

    def signals(self, y, u: UnitInputs, refs: GfmReferences) -> GfmSignals:
        """The converter's outputs at state ``y``."""
        return self.converter.signals(y, u, refs)

    def vector_field(self, y, u: UnitInputs, refs: GfmReferences):
        """d(state)/dt."""
        return self.converter.vector_field(y, u, refs)

    def initial_state(self, u: UnitInputs, i_re, i_im):
        """(y0, references): the steady state delivering ``I`` at ``u``'s voltage."""
        return self.converter.initial_state(u, i_re, i_im)


NO_DROOP_R_PU = 1e3
"""The droop [pu speed / pu power] of the estimator's governor for a converter without a
frequency droop (kw = 0): Tm is then Pref to 1e-3 of dw. With R = 1e6 and T1 = T3 = 1e-3 s
every fit of experiments/andes_gfm came back NaN (solver failed); with R = 1e3 and 0.05 s
finite (which of the two mattered was not measured)."""
GOVERNOR_LAG_S = 0.05
"""T1 = T3 of that governor [s]: no lag worth speaking of against the swing (see
:data:`NO_DROOP_R_PU`)."""


def classical_plant(converter: REGCV1, s_rated_mva: float, v_rated_kv: float,
                    s_base_mva: float = 100.0, x_internal_pu: float | None = None) -> Plant:
    """The estimator's plant for a grid-forming converter: its virtual rotor as a classical
    machine (xd = xq = x'd = ``x_internal_pu``, default the converter's xs; the internal voltage
    behind it is held constant by a very slow T'do), Tm = Pref - kw dw (a TGOV1 with
    R = 1/kw, or :data:`NO_DROOP_R_PU` for kw = 0, and no lags worth speaking of), the PMU at
    the terminal (give the recording ``location="terminal"``).

    This fits a VSG whose internal voltage behind x turns with its virtual rotor: the estimator
    then sees the swing equation M dw/dt = Pref - Pe - D dw (H = M/2) with Pe the measured
    terminal power (not tested on such a model). It does not fit ANDES's REGCV1, whose d axis
    follows the terminal voltage through its voltage PI: on every recording of
    experiments/andes_gfm the estimator's verdict with this plant was ``failed`` (H = 139, -29,
    -252 s against 4 s); identify REGCV1 by its playback (:class:`GfmUnit` with
    :func:`~jaxdse._dyr.calibrate.calibrate`) instead.
    """
    x = float(converter.xs_pu) if x_internal_pu is None else float(x_internal_pu)
    f0 = float(converter.omega_s_rad_s) / (2 * math.pi)
    kw = float(converter.kw_pu)
    machine = Machine(xd_pu=x, xq_pu=x, xd1_pu=x, rs_pu=float(converter.ra_pu), td01_s=1e4,
                      s_rated_mva=s_rated_mva, v_rated_kv=v_rated_kv, f_nominal_hz=f0)
    gov = TGOV1(r_pu=1.0 / kw if kw > 0 else NO_DROOP_R_PU, t1_s=GOVERNOR_LAG_S, v_max_pu=1e3,
                v_min_pu=-1e3, t2_s=0.0, t3_s=GOVERNOR_LAG_S, dt_pu=0.0)
    return Plant(machine=machine, governor=gov, s_base_mva=s_base_mva)


__all__ = ["GOVERNOR_LAG_S", "GfmUnit", "NO_DROOP_R_PU", "classical_plant"]
