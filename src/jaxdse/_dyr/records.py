"""A unit's .dyr model from its PSS/E records (host side, at the edge).

:func:`unit_model` reads a generator's machine, exciter, stabiliser and governor records into a
:class:`DyrUnit`. A unit that has a record of a model jaxdse does not simulate (or none of a
machine) gets no .dyr model: ``unit`` is None and ``missing`` says which record, so that the
caller falls back to the surrogate and says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import equinox as eqx
import jax.numpy as jnp

from .._io.psse import (
    PSSE_GOVERNOR_MODELS,
    DyrData,
    DyrRecord,
    RawCase,
    governor_module,
    record_label,
)
from .._models.exciters import EXCITERS, exciter_from_dyr
from .._models.ibr import (
    GFM_FILTER_FLOOR_S,
    IBR_MODELS,
    IBR_ROLES,
    ibr_from_dyr,
    record_readings,
    vdl_trailing_zeros,
)
from .._models.machines import MACHINES, machine_from_dyr
from .._models.stabilisers import STABILISERS, stabiliser_from_dyr
from .gfm_unit import GfmUnit
from .ibr_unit import IbrUnit
from .unit import DyrUnit

PSSE_MACHINE_MODELS = frozenset({
    "CGEN1", "FRECHG", "GENCLS", "GENDCO", "GENQEC", "GENROE", "GENROU", "GENSAE", "GENSAL",
    "GENTPF", "GENTPJ", "GENTRA"})
"""Synchronous machine models of the PSS/E model library (simulated or not)."""
PSSE_EXCITER_MODELS = frozenset({
    "AC7B", "AC8B", "BBSEX1", "BUDCZT", "CELIN", "DC3A", "EMAC1T", "ESAC1A", "ESAC2A", "ESAC3A",
    "ESAC4A", "ESAC5A", "ESAC6A", "ESAC8B", "ESDC1A", "ESDC2A", "ESST1A", "ESST2A", "ESST3A",
    "ESST4B", "ESST5B", "ESST6B", "ESST7B", "ESURRY", "EX2000", "EXAC1", "EXAC1A", "EXAC2",
    "EXAC3", "EXAC4", "EXBAS", "EXDC2", "EXELI", "EXNEBB", "EXNI", "EXPIC1", "EXST1", "EXST2",
    "EXST2A", "EXST3", "IEEET1", "IEEET2", "IEEET3", "IEEET4", "IEEET5", "IEEEX1", "IEEEX2",
    "IEEEX3", "IEEEX4", "IEET1A", "IEET1B", "IEET5A", "IEEX2A", "REXSYS", "SCRX", "SEXS",
    "ST5B", "ST6B", "ST7B", "URHIDT", "URST5T"})
"""Excitation-system models of the PSS/E model library (simulated or not)."""
PSSE_STABILISER_MODELS = frozenset({
    "BEPSST", "IEE2ST", "IEEEST", "IVOST", "OSTB2T", "OSTB5T", "PSS1A", "PSS2A", "PSS2B",
    "PSS2C", "PSS3B", "PSS4B", "PTIST1", "PTIST3", "ST2CUT", "STAB1", "STAB2A", "STAB3",
    "STAB4", "STABNI", "STBSVC"})
"""Stabiliser models of the PSS/E model library (simulated or not)."""
PSSE_IBR_MODELS: dict[str, str] = {
    "REGCA1": "converter", "REGCB1": "converter", "REGCC1": "converter", "REGFM_A1": "converter",
    "REGFM_B1": "converter", "REGFMA1": "converter", "REGFMB1U": "converter", "REGCV1": "converter",
    "REGCV2": "converter",
    "REECA1": "electrical", "REECB1": "electrical", "REECCU1": "electrical", "REECDU1": "electrical",
    "REPCA1": "plant", "REPCB1": "plant", "WTDTA1": "wind", "WTARA1": "wind", "WTPTA1": "wind",
    "WTTQA1": "wind"}
"""Inverter-based resource models (WECC second generation, grid-forming, type-3 wind; simulated
or not) and their role in a plant."""
GFM_MODELS = frozenset({"REGCV1", "REGCV2", "REGFM_A1", "REGFMA1", "REGFM_B1", "REGFMB1U"})
"""The grid-forming converters simulated (ANDES's virtual synchronous generators, with a virtual
inertia H = M/2; the WECC droop-controlled REGFM_A1, whose equivalent H is TPf / (2 mp); the WECC
virtual synchronous machine REGFM_B1, H a constant of its record): a
:class:`GfmUnit` each."""


@dataclass
class UnitModel:
    """One generator's .dyr model, or why it has none."""

    unit: DyrUnit | None
    models: dict[str, str] = field(default_factory=dict)
    """{"machine": "GENROU", "exciter": "SEXS", ...} of the records used."""
    missing: list[str] = field(default_factory=list)
    """Why the unit has no .dyr model (one line each); empty when ``unit`` is set."""
    notes: list[str] = field(default_factory=list)
    """What a reader should know about the model used (remote stabiliser inputs, ...)."""

    @property
    def structure(self) -> tuple[str, ...]:
        """The model names in a fixed order: units of one structure share one compiled call."""
        return tuple(self.models.get(k, "-") for k in ("machine", "exciter", "stabiliser", "governor"))


@dataclass
class IbrModel:
    """One inverter-based plant's .dyr model, or why it has none."""

    unit: IbrUnit | GfmUnit | None
    """The plant (grid-following: IbrUnit) or the grid-forming converter (GfmUnit)."""
    models: dict[str, str] = field(default_factory=dict)
    """{"converter": "REGCA1", "electrical": "REECA1", "plant": "REPCA1", "torque": "WTTQA1",
    ...} of the records used."""
    missing: list[str] = field(default_factory=list)
    """Why the plant has no .dyr model (one line each); empty when ``unit`` is set."""
    notes: list[str] = field(default_factory=list)
    """What a reader should know about the model used (measurements taken at the terminal, ...)."""

    @property
    def structure(self) -> tuple[str, ...]:
        """The model names in a fixed order (converter, electrical, plant, then a wind turbine's
        mechanics present): plants of one structure share one compiled call."""
        return (tuple(self.models.get(k, "-") for k in IbrUnit.PARTS[:3])
                + tuple(self.models[k] for k in IbrUnit.PARTS[3:] if k in self.models))


def is_ibr(dyr: DyrData, bus: int, machine_id: str) -> bool:
    """True when generator (``bus``, ``machine_id``) has an inverter-based resource record."""
    return any(r.model in PSSE_IBR_MODELS for r in dyr.unit_records(bus, machine_id))


def ibr_model(dyr: DyrData, bus: int, machine_id: str, raw: RawCase | None = None) -> IbrModel:
    """The :class:`IbrUnit` of generator (``bus``, ``machine_id``) from its converter (REGCA1,
    REGCB1), electrical control (REECA1, REECB1, REECCU1) and (optional) REPCA1 records, or why
    there is none (a record of a model not simulated, a second record of one role, a missing
    converter or electrical control, a record that does not read). REGCB1's source impedance is
    the generator's ZSORCE in ``raw`` (without ``raw``: none, a current source; noted)."""
    out = IbrModel(unit=None)
    parts: dict[str, object] = {}
    for rec in dyr.unit_records(bus, machine_id):
        role = IBR_ROLES.get(rec.model, PSSE_IBR_MODELS.get(rec.model))
        if role is None:
            out.notes.append(f"{record_label(rec)}: not an inverter-based resource model; left out")
            continue
        if role in out.models:
            out.missing.append(f"{record_label(rec)}: a second {role} record for this generator")
            continue
        out.models[role] = rec.model
        if rec.model not in IBR_MODELS:
            out.missing.append(f"{record_label(rec)}: model {rec.model} is not simulated "
                               f"({', '.join(IBR_MODELS)})")
            continue
        if rec.problem:
            out.missing.append(rec.problem)
            continue
        try:
            parts[role] = ibr_from_dyr(rec.model, rec.constants)
            out.notes.extend(record_readings(rec.model, rec.constants))
        except ValueError as err:
            out.missing.append(f"{record_label(rec)}: {str(err).splitlines()[0]}")
    for role in ("converter",):
        if role not in out.models:
            out.missing.append(f"generator {bus} {machine_id!r}: no {role} record "
                               f"({', '.join(m for m, r in IBR_ROLES.items() if r == role)})")
    mid = str(machine_id).strip().upper()
    g = None if raw is None else next(      # the generator record: its ZSORCE
        (x for x in raw.generators if x.bus == int(bus) and x.id.strip().upper() == mid), None)
    if not out.missing and out.models["converter"] == "REGCB1":
        conv = parts["converter"]
        if g is None:
            out.notes.append("REGCB1: no generator record for its source impedance ZSORCE: a current "
                             "source (Te not used)")
        else:
            parts["converter"] = eqx.tree_at(lambda c: (c.re_pu, c.xe_pu), conv,
                                             (jnp.asarray(float(g.zr_pu)), jnp.asarray(float(g.zx_pu))))
            if float(conv.t_e_s) > 0 and math.hypot(g.zr_pu, g.zx_pu) <= 1e-9:
                out.notes.append(f"REGCB1: Te = {float(conv.t_e_s):g} s with ZSORCE = 0: a current source "
                                 "(Te not used)")
    if not out.missing and out.models["converter"] in ("REGFM_A1", "REGFMA1", "REGFM_B1", "REGFMB1U"):
        name = out.models["converter"]
        if g is None:
            out.missing.append(f"generator {bus} {machine_id!r}: {name} is a voltage source behind the "
                               "generator's ZSORCE, and there is no .raw generator record to read it from")
        elif not g.zx_pu > 0:
            out.missing.append(f"generator {bus} {machine_id!r}: {name} needs a coupling reactance (the "
                               f"generator's ZSORCE X > 0 on MBASE), got ZX = {g.zx_pu:g}")
        else:
            parts["converter"] = eqx.tree_at(lambda c: (c.re_pu, c.xe_pu), parts["converter"],
                                             (jnp.asarray(float(g.zr_pu)), jnp.asarray(float(g.zx_pu))))
        for con, f in (("TPf", "t_pf_s"), ("TQf", "t_qf_s"), ("TVf", "t_vf_s"), ("TIf", "t_if_s")):
            conv = parts.get("converter")
            if not out.missing and hasattr(conv, f) and float(getattr(conv, f)) == 0:
                out.notes.append(f"{name}: {con} = 0 read as a {GFM_FILTER_FLOOR_S:g} s lag (a pass-through "
                                 "would close an algebraic loop through the source)")
    if not out.missing and out.models["converter"] in GFM_MODELS:
        # a grid-forming converter is a whole unit: its own controls, no REEC/REPC/wind records
        extra = [r for r in out.models if r != "converter"]
        if extra:
            out.missing.append(f"generator {bus} {machine_id!r}: {out.models['converter']} is a whole "
                               f"grid-forming converter; its {', '.join(out.models[r] for r in extra)} "
                               "record(s) have no place in it")
        else:
            out.unit = GfmUnit(parts["converter"])
        return out
    if not out.missing:
        out.unit = IbrUnit(converter=parts["converter"], electrical=parts.get("electrical"),
                           plant=parts.get("plant"), torque=parts.get("torque"),
                           pitch=parts.get("pitch"), aero=parts.get("aero"), drive=parts.get("drive"))
        wind = [k for k in ("torque", "pitch", "aero") if k in parts]
        if wind and "drive" not in parts:
            out.notes.append("no drive train record (WTDTA1): the rotor speed is held at its initial value "
                             + ("(WTTQA1's speed table at the initial power)" if "torque" in parts else "(1 pu)")
                             + "; " + ("WTPTA1 and WTARA1 then do not act on the electrical output"
                                       if "pitch" in parts or "aero" in parts else "the speed loop is open"))
        if "pitch" in parts and "aero" not in parts:
            out.notes.append("WTPTA1 without WTARA1: the pitch acts on no aerodynamic model")
        plant = parts.get("plant")
        if plant is not None and (int(plant.regulated_bus) not in (0, bus) or int(plant.branch[0]) != 0):
            out.notes.append(f"REPCA1: regulated bus {int(plant.regulated_bus)} and branch "
                             f"{int(plant.branch[0])}-{int(plant.branch[1])} taken at the terminal")
        elec = parts.get("electrical")
        name = out.models.get("electrical")
        if elec is None:
            out.notes.append("no electrical control record (REECA1, REECB1, REECCU1): Ipcmd and Iqcmd held "
                             "at their initial values (PSS/E holds the output of a controller the case does "
                             "not model)"
                             + ("; the plant controller's and the torque controller's Pref and Qext then act "
                                "on nothing" if "plant" in parts or "torque" in parts else ""))
        elif name == "REECA1" and (float(elec.thld_s) != 0.0 or float(elec.thld2_s) != 0.0):
            out.notes.append(f"REECA1: Thld = {float(elec.thld_s):g}, Thld2 = {float(elec.thld2_s):g}: "
                             "the post-dip hold timers are not modelled (taken as 0)")
        if elec is not None and name != "REECA1" and not elec.vflag and elec.qflag and float(elec.v_ref0_pu) != 0.0:
            out.notes.append(f"{name}: VFLAG = 0: its inner voltage loop holds |V| at the start (Vref0 = "
                             f"{float(elec.v_ref0_pu):g} serves the dip injection only)")
        if name == "REECCU1" and elec is not None:
            out.notes.append(f"REECCU1: the state of charge (SOCini = {float(elec.soc_ini_pu):g}) integrates "
                             "-Pe/T: it moves in a held run, P and Q do not")
        if elec is not None and name == "REECA1" and not elec.vflag and elec.qflag and float(elec.v_ref1_pu) != 0.0:
            out.notes.append(f"REECA1: Vref1 = {float(elec.v_ref1_pu):g} replaced by the value that "
                             "holds the initial state")
        if "plant" not in out.models and elec is not None:
            out.notes.append("no plant controller record: Pref and Qext held at their initial values")
        rec = next((r for r in dyr.unit_records(bus, machine_id) if r.model == out.models.get("electrical")),
                   None)
        tables = (vdl_trailing_zeros(rec.constants, rec.model)
                  if rec is not None and rec.model in ("REECA1", "REECCU1") else [])
        for table in tables:
            out.notes.append(f"{rec.model}: {table}: its trailing (0, 0) points read as unused, the last "
                             "used point held beyond them")
    return out


def record_kind(record: DyrRecord) -> str:
    """"machine", "exciter", "stabiliser", "governor" or "other": what a record models, by its
    PSS/E name (a model of the PSS/E library jaxdse does not simulate included)."""
    if record.model in PSSE_MACHINE_MODELS or record.model in MACHINES or record.kind == "machine":
        return "machine"
    if record.model in PSSE_EXCITER_MODELS or record.model in EXCITERS:
        return "exciter"
    if record.model in PSSE_STABILISER_MODELS or record.model in STABILISERS:
        return "stabiliser"
    if record.model in PSSE_GOVERNOR_MODELS or record.kind == "governor":
        return "governor"
    return "other"


def unit_model(dyr: DyrData, raw: RawCase, bus: int, machine_id: str, *,
               ke_zero: Literal["psse", "literal"] = "psse") -> UnitModel:
    """The :class:`DyrUnit` of generator (``bus``, ``machine_id``) from its records;
    ``ke_zero``: how a DC exciter's KE = 0 is read (see :class:`jaxdse.IEEEX1`)."""
    gen = raw.generator(bus, machine_id)
    out = UnitModel(unit=None)
    parts: dict[str, object] = {}
    for rec in dyr.unit_records(bus, machine_id):
        kind = record_kind(rec)
        if kind == "other":
            out.notes.append(f"{record_label(rec)}: not a machine, exciter, stabiliser or governor "
                             "model; left out of the playback")
            continue
        if kind in parts or kind in out.models:
            out.missing.append(f"{record_label(rec)}: a second {kind} record for this machine")
            continue
        out.models[kind] = rec.model
        if rec.problem:
            out.missing.append(rec.problem)
            continue
        try:
            if kind == "machine":
                if rec.model not in MACHINES:
                    raise ValueError(f"machine model {rec.model} is not simulated "
                                     f"({', '.join(MACHINES)})")
                parts[kind] = machine_from_dyr(rec.model, rec.params, ra_pu=gen.zr_pu,
                                               x_source_pu=gen.zx_pu, f_nominal_hz=raw.basfrq_hz)
            elif kind == "exciter":
                if rec.model not in EXCITERS:
                    raise ValueError(f"exciter model {rec.model} is not simulated "
                                     f"({', '.join(EXCITERS)})")
                parts[kind] = exciter_from_dyr(rec.model, rec.constants, ke_zero=ke_zero)
            elif kind == "stabiliser":
                if rec.model not in STABILISERS:
                    raise ValueError(f"stabiliser model {rec.model} is not simulated "
                                     f"({', '.join(STABILISERS)})")
                stab = stabiliser_from_dyr(rec.model, rec.constants)
                if stab.remote_input_at_terminal:
                    out.notes.append(f"{record_label(rec)}: remote-bus input taken at the terminal")
                parts[kind] = stab
            else:
                parts[kind] = governor_module(rec, mbase_mva=gen.mbase_mva)
        except (ValueError, KeyError, TypeError) as err:
            msg = str(err).splitlines()[0] if str(err) else type(err).__name__
            out.missing.append(f"{record_label(rec)}: {msg}")
    if "machine" not in out.models:
        out.missing.append(f"generator {bus} {machine_id!r}: no machine record")
    if not out.missing:
        out.unit = DyrUnit(machine=parts["machine"], exciter=parts.get("exciter"),
                           stabiliser=parts.get("stabiliser"), governor=parts.get("governor"))
        for kind in ("exciter", "governor"):
            if kind not in out.models:
                out.notes.append(f"no {kind} record: {'Efd' if kind == 'exciter' else 'Tm'} "
                                 "held at its initial value")
    return out


__all__ = ["PSSE_EXCITER_MODELS", "PSSE_IBR_MODELS", "PSSE_MACHINE_MODELS", "PSSE_STABILISER_MODELS",
           "IbrModel", "UnitModel", "ibr_model", "is_ibr", "record_kind", "unit_model"]
