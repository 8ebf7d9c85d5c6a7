"""Every generator record of a PSS/E case and every .dyr record, accounted for (host side).

:func:`inventory` puts each generator record of the .raw in exactly one category, with a
one-line reason, so that a check or a fleet can say what became of each:

* ``synchronous`` -- in service, with a machine record (a synchronous unit);
* ``machine model unknown`` -- in service, with .dyr records none of which is a machine, a
  converter or a static var compensator model jaxdse knows, and at least one record whose
  model jaxdse does not know (e.g. a renamed GENSAL): a unit, ``not supported``, naming it;
* ``no machine record`` -- in service, with exciter, stabiliser or governor records but no
  machine record: a unit whose records are incomplete (a data problem);
* ``out of service`` -- status 0 (with or without dynamic records);
* ``no dynamic records`` -- in service, no .dyr record on its bus and ID;
* ``inverter-based`` -- in service, a converter-interfaced plant (REGCA1, REGCB1, REECA1,
  REECB1, REECCU1, REPCA1, WT4G1, PVGU1, ...): a unit of the check, ``not supported`` where a record's model is not
  simulated (named);
* ``not a generator`` -- in service, a generator-data record whose dynamic record is a static
  var compensator or STATCOM (CSVGN1, CSTATT, SVSMO1, ...): not a generator;
* ``duplicate`` -- a second generator record for the same bus and ID (the first is used).

The .dyr records not attached to a generator record of the .raw are listed too: ``orphaned``
(a generator model on a bus, or with an ID, the .raw does not have) or ``bus level`` (a model of
a bus or a plant, not of one machine: USRBUS), and the records the reader could not attribute
(``DyrData.problems``).
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path

from .._io.psse import DyrData, DyrRecord, RawCase, RawGenerator, generator_label, record_label
from .records import record_kind

GENERATOR_CATEGORIES = ("synchronous", "inverter-based", "machine model unknown", "no machine record",
                        "out of service", "no dynamic records", "not a generator", "duplicate")
"""The categories of a .raw generator record, in the order of the reports."""
UNIT_CATEGORIES = ("synchronous", "inverter-based", "machine model unknown", "no machine record")
"""The categories whose in-service records are units of ``jaxdse check``."""
SVC_MODELS = frozenset({
    "ABBSVC1", "CHSVCT", "CSTATT", "CSTCNT", "CSVGN1", "CSVGN3", "CSVGN4", "CSVGN5", "CSVGN6",
    "SVCALS", "SVSMO1", "SVSMO2", "SVSMO3", "SVSMO1U1", "SVSMO2U1", "SVSMO3U1"})
"""Static var compensator and STATCOM models of the PSS/E library (and the WECC generic
ones), whose records sit on a generator-data record of the .raw."""
CONVERTER_PREFIXES = ("REGC", "REEC", "REPC", "REGF", "WT1", "WT2", "WT3", "WT4", "WTDTA", "WTARA",
                      "WTARV", "WTPTA", "WTTQA", "WTGTA", "WTGAR", "WTGPT", "WTGQ", "WTGT", "PVGU",
                      "PVEU", "PVD1", "DERA", "DER_A", "GEWT", "GEPV", "ESD1")
"""Name prefixes of converter-interfaced source models (WECC renewable, wind, PV, DER)."""
BUS_MODELS = frozenset({"USRBUS"})
"""Models of a bus or a plant (their third field is a model name, not a machine ID)."""


def is_converter(model: str) -> bool:
    """Whether ``model`` is a converter-interfaced source model (its name)."""
    return model.upper().startswith(CONVERTER_PREFIXES)


@dataclasses.dataclass(frozen=True)
class GeneratorAccount:
    """One generator record of the .raw and what it is."""

    generator: RawGenerator
    category: str
    """One of :data:`GENERATOR_CATEGORIES`."""
    records: tuple[DyrRecord, ...]
    """Its .dyr records (bus and ID), in file order."""
    why: str
    """One line: what it is and why it is (not) a unit."""
    has_machine: bool = False
    """Whether a machine record is among ``records`` (an out-of-service unit checked with
    ``--out-of-service``)."""

    @property
    def models(self) -> list[str]:
        return [r.model for r in self.records]

    def as_dict(self) -> dict:
        g = self.generator
        return {"bus": g.bus, "id": g.id.strip(), "line": g.line, "in_service": g.stat == 1,
                "category": self.category, "models": self.models, "why": self.why}


@dataclasses.dataclass(frozen=True)
class RecordAccount:
    """A .dyr record attached to no generator record of the .raw."""

    record: DyrRecord
    category: str
    """``orphaned`` or ``bus level``."""
    why: str

    def as_dict(self) -> dict:
        r = self.record
        return {"model": r.model, "line": r.line, "bus": r.bus, "id": r.id,
                "category": self.category, "why": self.why}


@dataclasses.dataclass(frozen=True)
class Inventory:
    """Every generator record of the .raw, and the .dyr records of no generator."""

    raw_source: str
    generators: tuple[GeneratorAccount, ...]
    records: tuple[RecordAccount, ...]
    unreadable: tuple[str, ...]
    """.dyr records dropped by the reader (no readable bus number): one line each."""

    def counts(self) -> dict:
        """Generator records per category (every category, 0 included)."""
        c = Counter(a.category for a in self.generators)
        return {k: c.get(k, 0) for k in GENERATOR_CATEGORIES}

    def units(self, *, out_of_service: bool = False) -> list[GeneratorAccount]:
        """The generator records that are units of ``jaxdse check``: in service and in
        :data:`UNIT_CATEGORIES`; with ``out_of_service``, those out of service with a machine
        record too."""
        return [a for a in self.generators if a.category in UNIT_CATEGORIES
                or (out_of_service and a.category == "out of service" and a.has_machine)]

    def summary(self) -> dict:
        """The counts for a JSON summary: generator records of the .raw by category (they add
        up to ``generator_records``), out-of-service records with a machine record, and the .dyr
        records of no generator."""
        rec = Counter(r.category for r in self.records)
        return {"generator_records": len(self.generators), **self.counts(),
                "out_of_service_with_machine_record": sum(
                    a.category == "out of service" and a.has_machine for a in self.generators),
                "dyr_records_orphaned": rec.get("orphaned", 0),
                "dyr_records_bus_level": rec.get("bus level", 0),
                "dyr_records_unreadable": len(self.unreadable)}


def inventory(raw: RawCase, dyr: DyrData) -> Inventory:
    """Account for every generator record of ``raw`` and every record of ``dyr`` (see the
    module docstring)."""
    by_key: dict = {}
    for r in dyr.records:
        by_key.setdefault((r.bus, r.id.strip().upper()), []).append(r)
    gens, first = [], {}
    for g in raw.generators:
        key = (g.bus, g.id.strip().upper())
        recs = tuple(by_key.get(key, ()))
        if key in first:
            gens.append(GeneratorAccount(g, "duplicate", recs, f"{generator_label(g)}: a second "
                                         f"generator record for this machine; the first (line "
                                         f"{first[key].line}) is used"))
            continue
        first[key] = g
        gens.append(_account(g, recs))
    keys = {(g.bus, g.id.strip().upper()) for g in raw.generators}
    name = Path(raw.source).name or ".raw"
    records = []
    for r in dyr.records:
        if (r.bus, r.id.strip().upper()) in keys:
            continue
        if r.model in BUS_MODELS:
            where = f"{Path(r.source).name or '.dyr'} line {r.line}"
            records.append(RecordAccount(r, "bus level", f"{r.model} {r.id!r} on bus {r.bus} ({where}): a "
                                         "model of the bus or plant, not of one machine; not used"))
        elif r.bus not in raw.buses:
            records.append(RecordAccount(r, "orphaned", f"{record_label(r)}: bus {r.bus} is not in "
                                         f"{name}; not used"))
        else:
            records.append(RecordAccount(r, "orphaned", f"{record_label(r)}: no generator with ID "
                                         f"{r.id!r} on bus {r.bus} in {name}; not used"))
    return Inventory(str(raw.source), tuple(gens), tuple(records), tuple(dyr.problems))


def _account(g: RawGenerator, recs: tuple[DyrRecord, ...]) -> GeneratorAccount:
    kinds = [record_kind(r) for r in recs]
    machine = "machine" in kinds
    svc = [r.model for r in recs if r.model in SVC_MODELS]
    conv = [r.model for r in recs if is_converter(r.model)]
    unknown = [r for r, k in zip(recs, kinds) if k == "other" and r.model not in SVC_MODELS
               and not is_converter(r.model)]
    label = generator_label(g)
    has = ", ".join(f"{r.model} (line {r.line})" for r in recs)
    if machine:
        role, why = "synchronous", f"{label}: a synchronous unit ({has})"
    elif not recs:
        role, why = "no dynamic records", f"{label}: no record in the .dyr on its bus and ID"
    elif svc:
        role, why = "not a generator", (f"{label}: a static var compensator or STATCOM "
                                        f"({', '.join(svc)}), not a generator")
    elif conv:
        role, why = "inverter-based", f"{label}: an inverter-based plant ({', '.join(conv)})"
    elif unknown:
        role, why = "machine model unknown", (
            f"{label}: no machine record jaxdse knows; "
            + ", ".join(f"{record_label(r)}: model {r.model} unknown to jaxdse" for r in unknown))
    else:
        role, why = "no machine record", f"{label}: records of a machine ({has}) but no machine record"
    if g.stat != 1:
        return GeneratorAccount(g, "out of service", recs, f"{label}: out of service (status "
                                f"{g.stat}); " + (f"its records: {has}" if recs else "no dynamic records"),
                                has_machine=machine)
    return GeneratorAccount(g, role, recs, why, has_machine=machine)


__all__ = ["BUS_MODELS", "GENERATOR_CATEGORIES", "SVC_MODELS", "UNIT_CATEGORIES", "GeneratorAccount",
           "Inventory", "RecordAccount", "inventory", "is_converter"]
