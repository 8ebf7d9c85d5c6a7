"""Interfaces of the standard models that a unit's .dyr records compose.

Conventions (all models):

* per unit on the machine base (MBASE, machine kV); time in seconds; angles in radians;
* the network frame rotates at nominal speed; a phasor ``v = v_re + j v_im`` is a pair of reals;
* the state of a model is a 1-D float array of fixed length (``n_states``), so that units of
  one structure stack under vmap; a model holds its parameters as array leaves and its
  structural choices (input modes, switches, PSS/E ICONs) as integer leaves that select a
  signal path with ``jnp.where``, so that units whose switches differ share one structure
  (and one compiled program);
* ``initial_state`` returns the steady state that holds the given operating point, and what
  reference the model needs to stay there (Vref of an exciter); ``vector_field`` returns
  d(state)/dt; outputs are separate methods so that the composed unit reads them in order.
"""

from __future__ import annotations

import abc
import re
from collections.abc import Mapping
from typing import NamedTuple

import equinox as eqx
from jaxtyping import Array, Float


class ExciterInputs(NamedTuple):
    """What an exciter sees at one instant (machine base)."""

    vt_pu: Float[Array, ""]
    """Terminal voltage magnitude |Vt| [pu]."""
    v_re_pu: Float[Array, ""]
    """Terminal voltage phasor, real part [pu] (network frame)."""
    v_im_pu: Float[Array, ""]
    """Terminal voltage phasor, imaginary part [pu]."""
    i_re_pu: Float[Array, ""]
    """Terminal current phasor out of the machine, real part [pu]."""
    i_im_pu: Float[Array, ""]
    """Terminal current phasor out of the machine, imaginary part [pu]."""
    ifd_pu: Float[Array, ""]
    """Field current LadIfd [pu, non-reciprocal base: Efd = LadIfd in steady state unsaturated]."""
    vs_pu: Float[Array, ""]
    """Stabiliser output VOTHSG [pu]."""


class StabiliserInputs(NamedTuple):
    """What a stabiliser may take as input (PSS/E ICON MODE 1-6), machine base."""

    speed_dev_pu: Float[Array, ""]
    """MODE 1: rotor speed deviation [pu]."""
    freq_dev_pu: Float[Array, ""]
    """MODE 2: bus frequency deviation [pu]."""
    p_elec_pu: Float[Array, ""]
    """MODE 3: electrical power [pu on MBASE]."""
    p_accel_pu: Float[Array, ""]
    """MODE 4: accelerating power Pm - Pe [pu on MBASE]."""
    vt_pu: Float[Array, ""]
    """MODE 5: bus voltage magnitude [pu]."""
    dvt_dt_pu_s: Float[Array, ""]
    """MODE 6: derivative of the bus voltage magnitude [pu/s]."""


class AbstractExciter(eqx.Module):
    """An excitation system: Efd from the terminal voltage, the field current and VOTHSG."""

    @property
    @abc.abstractmethod
    def n_states(self) -> int:
        """Length of the state vector."""

    @abc.abstractmethod
    def initial_state(self, efd0, inputs: ExciterInputs):
        """(state, vref): the steady state with field voltage ``efd0`` [pu] at ``inputs``
        (``vs_pu`` = 0), and the voltage reference Vref [pu] that holds it."""

    @abc.abstractmethod
    def vector_field(self, state, inputs: ExciterInputs, vref):
        """d(state)/dt."""

    @abc.abstractmethod
    def efd(self, state, inputs: ExciterInputs, vref):
        """Field voltage Efd [pu] at ``state`` with voltage reference ``vref`` [pu] (the one
        ``initial_state`` returned, or a moved one): a model whose Efd-producing block is
        bypassed (TA = 0, TE = 0) gives Efd as an algebraic function of Vref; the others
        ignore it."""


class AbstractStabiliser(eqx.Module):
    """A power system stabiliser: VOTHSG from one or two input signals."""

    @property
    @abc.abstractmethod
    def n_states(self) -> int:
        """Length of the state vector."""

    @abc.abstractmethod
    def initial_state(self, inputs: StabiliserInputs):
        """The steady state at constant ``inputs`` (output 0 in steady state for washout inputs)."""

    @abc.abstractmethod
    def vector_field(self, state, inputs: StabiliserInputs):
        """d(state)/dt."""

    @abc.abstractmethod
    def output(self, state, inputs: StabiliserInputs):
        """VOTHSG [pu], limited and voltage-cut-off as the model defines."""


def record_message(message: str, model: str, names: Mapping[str, str]) -> str:
    """A model's one-line ``ValueError`` message in the words of its PSS/E record: every field
    named as the record names it (``names``: field -> PSS/E constant, e.g. ``td0_1_s`` ->
    ``T'do``), and ``MODEL: `` in front. ``GENROU.td0_1_s must be > 0, got -1.0`` becomes
    ``GENROU: T'do must be > 0, got -1.0``; ``TE (t_e_s)`` becomes ``TE``."""
    text = str(message).splitlines()[0] if str(message) else "invalid constants"
    for field, con in sorted(names.items(), key=lambda kv: -len(kv[0])):
        text = text.replace(f"{con} ({field})", con)
        text = re.sub(rf"\b\w+\.{re.escape(field)}\b", lambda _m, c=con: c, text)
        if "_" in field or any(ch.isdigit() for ch in field):   # a field name, never a word
            text = re.sub(rf"(?<![\w'.]){re.escape(field)}\b", lambda _m, c=con: c, text)
    text = re.sub(rf"^{re.escape(model)}: ", "", text)
    return f"{model}: {text}"


__all__ = ["AbstractExciter", "AbstractStabiliser", "ExciterInputs", "StabiliserInputs",
           "record_message"]
