"""PSS/E readers and converters for jaxdse, one module per format (this module gathers them).

* :mod:`.psse_raw`: power-flow data (.raw), revisions 32 to 36, one parser reading every
  revision through the field tables of :mod:`.psse_raw_layouts` (where each revision's
  differences are listed);
* :mod:`.psse_dyr`: dynamic data (.dyr) and its model tables;
* :mod:`.psse_convert`: records to :class:`jaxdse.Machine` and :class:`jaxdse.Transformer`
  keyword arguments, governor modules, and the checks of a unit's data;
* :mod:`.psse_common`: numbers and strings as both formats write them.

Readers work at the edge (plain Python, never inside jit). Every user mistake raises
:class:`~jaxdse._io.errors.InputError`, a one-line message naming the file, the line
(``row``) and the record. Both readers take ``strict``: by default a malformed record raises;
with ``strict=False`` (``jaxdse fleet``) a malformed record that can still be told apart is
kept with its ``problem`` so that only the units it belongs to are left out, and what cannot
be attributed is listed in ``problems`` of the file.
"""

from __future__ import annotations

from .psse_common import parse_number
from .psse_convert import (
    BIG_SHUNT_PU,
    DEFAULT_TAP_STEP,
    GENCLS_TD0_S,
    ROUND_ROTOR,
    SALIENT_POLE,
    MachineTransientData,
    generator_label,
    governor_from_dyr,
    governor_module,
    load_unit,
    machine_kwargs,
    machine_problems,
    machine_warnings,
    q_axis_problems,
    record_label,
    transformer_kwargs,
    transformer_sides,
    transient_data,
)
from .psse_dyr import (
    GOVERNOR_FIELDS,
    GOVERNOR_PARAMETERS,
    MACHINE_FIELDS,
    OPTIONAL_TRAILING,
    PSSE_GOVERNOR_MODELS,
    TYPED_MODELS,
    DyrChange,
    DyrData,
    DyrRecord,
    merge_dyr,
    read_dyr,
    repair_comment,
)
from .psse_raw import (
    SUPPORTED_RAW_REVISIONS,
    RawBranch,
    RawBus,
    RawCase,
    RawChange,
    RawFixedShunt,
    RawGenerator,
    RawLoad,
    RawSwitchedShunt,
    RawTransformer,
    raw_repair_comment,
    read_raw,
)

__all__ = [
    "BIG_SHUNT_PU", "DEFAULT_TAP_STEP", "GENCLS_TD0_S", "GOVERNOR_FIELDS", "GOVERNOR_PARAMETERS",
    "ROUND_ROTOR", "SALIENT_POLE",
    "MACHINE_FIELDS", "OPTIONAL_TRAILING", "PSSE_GOVERNOR_MODELS", "SUPPORTED_RAW_REVISIONS",
    "TYPED_MODELS", "DyrChange", "DyrData", "DyrRecord", "MachineTransientData", "RawBranch", "RawBus",
    "RawCase", "RawChange", "RawFixedShunt", "RawGenerator", "RawLoad", "RawSwitchedShunt", "RawTransformer",
    "generator_label", "governor_from_dyr", "governor_module", "load_unit", "machine_kwargs",
    "machine_problems",
    "machine_warnings",
    "merge_dyr", "parse_number", "q_axis_problems", "read_dyr", "raw_repair_comment", "read_raw",
    "record_label",
    "repair_comment",
    "transformer_kwargs", "transformer_sides", "transient_data",
]
