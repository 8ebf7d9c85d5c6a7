"""The plant between the PMU and the rotor: network, machine and governor-turbine.

Per-unit convention (stated once, used everywhere):

* **Machine base** -- the machine's rated apparent power ``Machine.s_rated_mva`` and rated
  terminal voltage ``Machine.v_rated_kv``. All machine reactances, the stator resistance,
  torques and the terminal current seen by the observer are on this base.
* **System base** -- ``Plant.s_base_mva`` (100 MVA by default) with the nominal voltage of
  each bus as voltage base. The line, the transformer, the auxiliary load and every PMU
  phasor are on this base. The LV-bus voltage base equals the machine's rated voltage, so a
  voltage in pu is the same number on both bases; a current converts with
  ``i_machine = i_system * s_base_mva / s_rated_mva``.
* Angles are in rad, time in s, frequency in Hz, speed deviation ``x2`` in rad/s.
"""

from __future__ import annotations

import equinox as eqx
from jaxtyping import Array, Float

from .._models.governors import TGOV1, AbstractGovernor
from .._base.fields import as_float, check_nonnegative, check_positive
from .machine import Machine
from .mapping import AuxiliarySystem, Line, Transformer


class Plant(eqx.Module):
    """Everything between the PMU and the rotor: network, machine and governor-turbine.

    The defaults are the paper's plant (1100 MVA, 21 kV, 50 Hz machine; TGOV1 governor).
    """

    machine: Machine = Machine()
    line: Line = Line()
    transformer: Transformer = Transformer()
    aux: AuxiliarySystem = AuxiliarySystem()
    governor: AbstractGovernor = TGOV1()
    s_base_mva: Float[Array, ""] = eqx.field(converter=as_float, default=100.0)
    """System base [MVA] of the network parameters and of the PMU phasors."""
    h_model_error: Float[Array, ""] = eqx.field(converter=as_float, default=0.0)
    """Relative error of H [-] that a simplification of this estimator model can cause: a
    fallback taken for the plant's data (q-axis circuits left out, constant mechanical torque
    for a governor record that is missing or not modelled); ``inf`` where its size is not
    known, 0 for a plant modelled from its data. H's verdict is at best ``weakly identified``
    unless H's 95 % interval covers it (:mod:`jaxdse._core.verdict`, ``model_simplified``)."""

    def __check_init__(self):
        check_positive(self, "s_base_mva")
        check_nonnegative(self, "h_model_error")

    @property
    def current_scale(self):
        """i_machine / i_system = s_base_mva / s_rated_mva."""
        return self.s_base_mva / self.machine.s_rated_mva
