"""A fleet that never aborts: a small PSS/E case (.raw rev 33, .dyr, a recording's header)
built here, damaged record by record, read by ``load_fleet``.

Damage: perturbed, NaN, infinite, zero or negative values; inconsistent reactances; records
deleted, duplicated, renamed to models jaxdse does not know, cut short or run into the next;
unreadable bus numbers; generator and bus fields of the .raw; columns of the recording.
Property: ``load_fleet`` returns the plants and the skipped units, every unit of the case
being exactly one of the two (skipped: with a one-line reason), the units no damage touched
unchanged; or, when no unit at all is usable, it raises a one-line :class:`InputError`. The
examples are derandomized and counted with ``hypothesis.event``; the estimator is not run.
"""

import contextlib
import math
import re
import tempfile
from functools import cache
from pathlib import Path

import jax
import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

import jaxdse as jd
from jaxdse._app.fleet_file import load_fleet
from jaxdse._io import psse

BUSES = {1: ("HV", "230.0", 3), 2: ("G2", "20.0", 2), 3: ("G3", "20.0", 2), 4: ("G4", "13.8", 2),
         5: ("G5", "20.0", 2)}
GENERATORS = [  # I, ID, PG, MBASE, ZR, ZX
    ("2", "1", "150", "200.0", "0.003", "0.25"),
    ("3", "1", "80", "100.0", "0.002", "0.3"),
    ("4", "1", "60", "90.0", "0.0", "0.3"),
    ("5", "1", "40", "50.0", "0.0", "0.2"),
    ("5", "2", "70", "120.0", "0.001", "0.3"),
    ("5", "W", "20", "30.0", "0.0", "1.0"),      # a renewable: no machine record
]
MBASE, ZR, ZX, STAT = 8, 9, 10, 14
"""Field indices of the generator record."""
GENROU = "6.5 0.06 0.2 0.05 {h} 0 1.8 1.75 0.6 0.8 0.23 0.15 0.09 0.38"
DYR = [  # bus, model, id, constants
    ("2", "GENROU", "1", GENROU.format(h=4.0)),
    ("2", "TGOV1", "1", "0.05 0.05 1.05 0.3 1 2.1 0"),
    ("2", "SEXS", "1", "0.1 10 100 0.1 0 3"),
    ("3", "GENROU", "1", GENROU.format(h=6.5)),
    ("3", "GAST", "1", "0.05 0.4 0.1 3.0 0.9 2.0 1.0 -0.05 0.0"),
    ("4", "GENSAL", "1", "5.0 0.05 0.1 3.2 0.0 1.1 0.7 0.3 0.25 0.15 0.1 0.3"),
    ("4", "HYGOV", "1", "0.05 0.075 12 0.5 20.5 0.1 1.0 0.0 15 1.5 0 0.08"),
    ("5", "GENCLS", "1", "3.0 0.0"),                                   # no governor
    ("5", "GENROU", "2", GENROU.format(h=5.0)),
    ("5", "IEEEG1", "2", "0 0 20 0 0 0.1 0.1 -0.1 1 0 0.3 0.3 0 7 0.4 0 0.6 0.3 0 0 0 0"),
    ("5", "REGCA1", "W", "1 0.02 0.02 0.4 10 0.9 1.22 1.2 0.8 0.4 -1.3 0.02 0 -1.3"),
]
UNITS = [(int(g[0]), g[1]) for g in GENERATORS]
ROLES = {"frequency": "F", "v_mag": "VM", "v_ang": "VA", "i_mag": "IM", "i_ang": "IA"}
FLEET = """[case]
raw = "case.raw"
dyr = "case.dyr"

[measurement]
file = "rec.csv"
location = "terminal"
voltage_unit = "pu"
current_unit = "pu"
angle_unit = "deg"
s_base_mva = 100.0

[channels]
layout = "per_machine"
name = "B{bus}_G{id}"
time = "time_s"
""" + "".join(f'{r} = "B{{bus}}_G{{id}}/{c}"\n' for r, c in ROLES.items())


def name(unit) -> str:
    return f"B{unit[0]}_G{unit[1]}"


class Case:
    """The case as editable rows; ``write`` renders the .raw, .dyr, recording and fleet file."""

    def __init__(self):
        self.buses = {b: list(v) for b, v in BUSES.items()}
        self.gens = [[g[0], f"'{g[1]}'", g[2], "0", "99", "-99", "1.0", "0", g[3], g[4], g[5], "0",
                      "0", "1", "1"] for g in GENERATORS]
        self.gen_units = list(UNITS)
        self.dyr = [{"bus": b, "model": m, "id": i, "consts": c.split(), "end": "/", "unit": (int(b), i)}
                    for b, m, i, c in DYR]
        self.columns = [f"{name(u)}/{c}" for u in UNITS for c in ROLES.values()]

    def write(self, folder: Path) -> Path:
        raw = ["0, 100.0, 33, 0, 1, 60.0 / fuzzed case", "T1", "T2"]
        raw += [f"{b}, '{n}', {kv}, {ide}, 1, 1, 1, 1.0, 0.0" for b, (n, kv, ide) in self.buses.items()]
        raw += ["0 / END OF BUS DATA", "0 / END OF LOAD DATA", "0 / END OF FIXED SHUNT DATA"]
        raw += [", ".join(g) for g in self.gens]
        raw += ["0 / END OF GENERATOR DATA", "0 / END OF BRANCH DATA", "0 / END OF TRANSFORMER DATA", "Q"]
        (folder / "case.raw").write_text("\n".join(raw) + "\n")
        dyr = [f"{r['bus']} '{r['model']}' '{r['id']}' {' '.join(r['consts'])} {r['end']}" for r in self.dyr]
        (folder / "case.dyr").write_text("\n".join(dyr) + "\n")
        rows = [",".join(["time_s", *self.columns])]
        rows += [",".join([f"{0.02 * k:.2f}", *("1.0" for _ in self.columns)]) for k in range(5)]
        (folder / "rec.csv").write_text("\n".join(rows) + "\n")
        (folder / "fleet.toml").write_text(FLEET)
        return folder / "fleet.toml"

    def expected(self, folder: Path) -> set[str]:
        """The units of the (damaged) case that the recording has columns for: an in-service
        generator (or, without a generator record, a machine record) with any column."""
        dyr = psse.read_dyr(folder / "case.dyr", strict=False)
        out = set()
        for unit in UNITS:
            if not any(c.startswith(name(unit) + "/") and not c.endswith("/F") for c in self.columns):
                continue
            rows = [g for g, u in zip(self.gens, self.gen_units) if u == unit]
            if rows:
                if rows[0][STAT].strip() != "0":
                    out.add(name(unit))
            elif any(r.kind == "machine" for r in dyr.unit_records(*unit)):
                out.add(name(unit))
        return out


@cache
def baseline():
    with tempfile.TemporaryDirectory() as d:
        fl = load_fleet(Case().write(Path(d)))
    return {p.name: p for p in fl.plants}, {s["name"]: s for s in fl.skipped}


def lines_out(notes) -> list[str]:
    """Notes without their line numbers (deleting a record moves the ones after it)."""
    return [re.sub(r"line \d+", "line N", n) for n in notes]


def machine_leaves(p):
    return [np.asarray(x) for x in jax.tree_util.tree_leaves(p.run.plant.machine)]


def test_the_clean_case():
    plants, skipped = baseline()
    assert list(plants) == ["B2_G1", "B3_G1", "B4_G1", "B5_G1", "B5_G2"]
    assert list(skipped) == ["B5_GW"]
    # a converter record alone (no REECA1): an inverter-based plant that cannot be played back
    assert re.fullmatch(r"an inverter-based plant whose records cannot be played back \(REGCA1 on bus 5 id 'W' "
                        r"\(case.dyr line 11\): REGCA1: expected 15 values .*, got 14\) and which has no "
                        r"rotor to estimate", skipped["B5_GW"]["reason"]), skipped["B5_GW"]["reason"]
    assert plants["B5_G1"].fallbacks == ("GENCLS on bus 5 id '1' (case.dyr line 8): no governor record; "
                                         "constant mechanical torque",)
    assert all(p.fallbacks == () for n, p in plants.items() if n != "B5_G1")
    assert plants["B2_G1"].run.plant.machine.q_axis is not None
    assert plants["B4_G1"].run.plant.machine.q_axis is None           # GENSAL: none to begin with


# --- one damage at a time: the reason or the note it gives -----------------------------------

def _const(case, k, field, value):
    rec = case.dyr[k]
    rec["consts"][psse.TYPED_MODELS[rec["model"]].index(field)] = value


DAMAGE = {
    # name: (edit, unit, expected: "skip", "note" or "run", text in the reason or the note)
    # odd but evaluable: used as given, with a data warning ("warn")
    "X''d below Xl": (lambda c: _const(c, 0, "X''d", "0.12"), "B2_G1", "warn",
                      "GENROU on bus 2 id '1' (case.dyr line 1): X''d = 0.12 below Xl = 0.15: "
                      "used as given"),
    "X''d equal to Xl": (lambda c: _const(c, 0, "X''d", "0.15"), "B2_G1", "warn",
                         "X''d = 0.15 equal to Xl"),
    "X''d above X'q": (lambda c: _const(c, 3, "X''d", "0.9"), "B3_G1", "warn",
                       "X''d (= X''q) = 0.9 above X'q = 0.8: used as given"),
    "X'q equal to Xl": (lambda c: _const(c, 0, "X'q", "0.15"), "B2_G1", "note",
                        "X'q = 0.15 equal to Xl: the q-axis equations divide by X'q - Xl: q-axis "
                        "circuits left out (transient model)"),
    "T''qo zero": (lambda c: _const(c, 8, "T''qo", "0"), "B5_G2", "note", "T''qo = 0 must be > 0"),
    "H zero": (lambda c: _const(c, 0, "H", "0"), "B2_G1", "skip",
               "GENROU on bus 2 id '1' (case.dyr line 1): H = 0 must be > 0"),
    "H NaN": (lambda c: _const(c, 3, "H", "NaN"), "B3_G1", "skip",
              "case.dyr, row 4: GENROU bus 3 id '1': constant 5 (H) is not a number: 'NaN'"),
    "Xd infinite": (lambda c: _const(c, 3, "Xd", "1e999"), "B3_G1", "skip", "Xd = inf must be > 0"),
    "D negative": (lambda c: _const(c, 7, "D", "-1"), "B5_G1", "skip", "D = -1 must be >= 0"),
    "X'd above Xd": (lambda c: _const(c, 5, "X'd", "1.5"), "B4_G1", "skip", "X'd = 1.5 above Xd = 1.1"),
    "too few constants": (lambda c: c.dyr[5]["consts"].pop(), "B4_G1", "skip",
                          "GENSAL bus 4 id '1' has 11 constants, expected 12"),
    "record runs into the next": (lambda c: c.dyr[0].update(end=""), "B2_G1", "skip",
                                  "GENROU bus 2 id '1' has 24 constants, expected 14"),
    "machine record missing": (lambda c: c.dyr.pop(3), "B3_G1", "skip",
                               "generator on bus 3 id '1' (case.raw line 13) has no machine record in "
                               "case.dyr (its records: GAST (line 4))"),
    "unknown machine model": (lambda c: c.dyr[5].update(model="GENQEC"), "B4_G1", "skip",
                              "its records: GENQEC (line 6), HYGOV (line 7)"),
    "unreadable bus number": (lambda c: c.dyr[5].update(bus="4x"), "B4_G1", "skip",
                              "has no machine record in case.dyr (its records: HYGOV (line 7))"),
    "machine record duplicated": (lambda c: c.dyr.append({**c.dyr[0], "consts": GENROU.format(h=9).split()}),
                                  "B2_G1", "note", "GENROU on bus 2 id '1' (case.dyr line 12): a second "
                                  "machine record for this machine; the first (GENROU at line 1) is used"),
    "governor missing": (lambda c: c.dyr.pop(4), "B3_G1", "note",
                         "GENROU on bus 3 id '1' (case.dyr line 4): no governor record; constant "
                         "mechanical torque"),
    "governor not modelled": (lambda c: c.dyr[1].update(model="IEEEG3"), "B2_G1", "note",
                              "IEEEG3 on bus 2 id '1' (case.dyr line 2): governor model not modelled by "
                              "jaxdse; constant mechanical torque"),
    "governor invalid": (lambda c: _const(c, 1, "T3", "0"), "B2_G1", "skip",
                         "case.dyr, row 2: TGOV1 bus 2 id '1': T3 must be > 0"),
    "MBASE NaN": (lambda c: c.gens[1].__setitem__(MBASE, "nan"), "B3_G1", "skip",
                  "case.raw, row 13: generator record: field 9 (MBASE) is not a number: 'nan'"),
    "MBASE zero": (lambda c: c.gens[1].__setitem__(MBASE, "0"), "B3_G1", "skip",
                   "generator on bus 3 id '1' (case.raw line 13): MBASE = 0 MVA must be > 0"),
    "ZR negative": (lambda c: c.gens[0].__setitem__(ZR, "-0.01"), "B2_G1", "skip",
                    "ZR (Ra) = -0.01 must be >= 0"),
    "GENCLS ZX zero": (lambda c: c.gens[3].__setitem__(ZX, "0"), "B5_G1", "skip",
                       "ZX (X'd of GENCLS) = 0 must be > 0"),
    "generator record missing": (lambda c: (c.gens.pop(2), c.gen_units.pop(2)), "B4_G1", "skip",
                                 "GENSAL on bus 4 id '1' (case.dyr line 6): no generator on bus 4 with "
                                 "ID '1'"),
    "bus base voltage zero": (lambda c: c.buses[4].__setitem__(1, "0"), "B4_G1", "skip",
                              "bus 4 (G4) has base voltage 0.0 kV; it must be > 0"),
    "column missing": (lambda c: c.columns.remove("B2_G1/IA"), "B2_G1", "skip",
                       "no column matches i_ang = 'B{bus}_G{id}/IA' for bus 2 id '1'"),
    "frequency column missing": (lambda c: c.columns.remove("B4_G1/F"), "B4_G1", "run", None),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_one_damaged_unit(tmp_path, damage):
    edit, unit, outcome, text = DAMAGE[damage]
    case = Case()
    edit(case)
    fl = load_fleet(case.write(tmp_path))
    plants, skipped = {p.name: p for p in fl.plants}, {s["name"]: s for s in fl.skipped}
    base_plants, base_skipped = baseline()
    assert set(plants) | set(skipped) == set(base_plants) | set(base_skipped)
    for other, p in base_plants.items():     # the other units are untouched
        if other != unit:
            assert other in plants and lines_out(plants[other].fallbacks) == lines_out(p.fallbacks)
            assert all(np.array_equal(a, b, equal_nan=True)
                       for a, b in zip(machine_leaves(plants[other]), machine_leaves(p)))
    if outcome == "skip":
        reason = skipped[unit]["reason"]
        assert text in reason and "\n" not in reason
    elif outcome == "run":           # the frequency is optional: derived from the voltage angle
        assert plants[unit].fallbacks == () and "frequency" not in plants[unit].run.measurement.columns
    elif outcome == "warn":          # used as given: no fallback, the q-axis circuits kept
        assert text in " | ".join(plants[unit].data_warnings)
        assert lines_out(plants[unit].fallbacks) == lines_out(base_plants[unit].fallbacks)
        assert plants[unit].run.plant.machine.q_axis is not None
    else:
        assert text in " | ".join(plants[unit].fallbacks)
        if "q-axis" in text:
            assert plants[unit].run.plant.machine.q_axis is None


def test_no_usable_unit_is_one_input_error(tmp_path):
    case = Case()
    for k in (0, 3, 5, 7, 8):            # every machine record: H = -1
        _const(case, k, "H", "-1")
    with pytest.raises(jd.InputError) as e:
        load_fleet(case.write(tmp_path))
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{tmp_path / 'fleet.toml'}: no usable plant: all 6 plant(s) "
                                              "found are skipped (first: B2_G1: GENROU on bus 2 id '1'")


# --- fuzzing ----------------------------------------------------------------------------------

FACTORS = (0.0, -1.0, 0.5, 0.9, 1.1, 2.0, 10.0, 1e-6, 1e6)
TOKENS = ("nan", "NaN", "inf", "1e999", "-1e999", "0", "-0", "-1", "-0.5", "1e-9", "1000", "x", "'7'")
PHASES = (Phase.explicit, Phase.generate, Phase.shrink)


@st.composite
def damages(draw):
    """A list of (kind, target, detail): at most 4 damages to the case."""
    rec, gen = st.integers(0, len(DYR) - 1), st.integers(0, len(GENERATORS) - 1)

    def kind(name, target, detail=st.none(), extra=st.none()):
        return st.tuples(st.just(name), target, detail, extra)

    one = st.one_of(
        kind("scale", rec, st.integers(0, 40), st.sampled_from(FACTORS)),
        kind("token", rec, st.integers(0, 40), st.sampled_from(TOKENS)),
        kind("inconsistent", st.sampled_from([0, 3, 8]),
             st.sampled_from(["X''d<Xl", "X''d=Xl", "X''d>X'q", "X'd>Xd", "X'q>Xq"])),
        kind("delete", rec),
        kind("duplicate", rec, st.sampled_from([1.0, 2.0, -1.0])),
        kind("rename", rec, st.sampled_from(["GENQEC", "GENTRA", "IEEEG3", "WSIEG1", "XYZ9", "GENROU",
                                             "GENCLS", "TGOV1", "GAST", "SEXS"])),
        kind("drop constant", rec),
        kind("extra constant", rec, st.sampled_from(["0", "x"])),
        kind("no terminator", rec),
        kind("bus number", rec, st.sampled_from(["x", "2.5", "nan"])),
        kind("generator field", gen, st.sampled_from([MBASE, ZR, ZX, 2]), st.sampled_from(TOKENS)),
        kind("generator status", gen, st.sampled_from(["0", "nan", "1.5"])),
        kind("delete generator", gen),
        kind("duplicate generator", gen, st.sampled_from(TOKENS)),
        kind("bus kV", st.integers(2, 5), st.sampled_from(["0", "-20", "nan", "1e999"])),
        kind("every H", st.just(0), st.sampled_from(["-1", "0", "nan", "2.0"])),
        kind("delete column", st.integers(0, len(UNITS) - 1), st.sampled_from([*ROLES, "all"])),
    )
    return draw(st.lists(one, min_size=0, max_size=4))


def touched(case: Case, damages) -> set:
    """Damage the case; the units whose data that touched."""
    out = set()
    for d in damages:
        out |= apply(case, d)
    for rec, after in zip(case.dyr, case.dyr[1:]):
        if not rec["end"]:
            out.add(after["unit"])          # a record without '/' swallows the next one
    return out


def apply(case: Case, damage) -> set:
    """Damage the case; the units whose data it touched directly."""
    kind, k, a, b = damage
    if kind in ("generator field", "generator status", "delete generator", "duplicate generator"):
        if not case.gens:
            return set()
        k %= len(case.gens)
        unit = case.gen_units[k]
        if kind == "generator field":
            case.gens[k][a] = b
        elif kind == "generator status":
            case.gens[k][STAT] = a
        elif kind == "delete generator":
            case.gens.pop(k)
            case.gen_units.pop(k)
        else:
            case.gens.append([*case.gens[k][:MBASE], a, *case.gens[k][MBASE + 1:]])
            case.gen_units.append(unit)
        return {unit}
    if kind == "every H":
        for rec in case.dyr:
            if rec["model"] in psse.MACHINE_FIELDS and len(rec["consts"]) > 4:
                rec["consts"][psse.MACHINE_FIELDS[rec["model"]].index("H")] = a
        return {r["unit"] for r in case.dyr}
    if kind == "bus kV":
        case.buses[k][1] = a
        return {u for u in UNITS if u[0] == k}
    if kind == "delete column":
        unit = UNITS[k]
        roles = list(ROLES) if a == "all" else [a]
        case.columns = [c for c in case.columns if c not in {f"{name(unit)}/{ROLES[r]}" for r in roles}]
        return {unit}
    if not case.dyr:
        return set()
    k %= len(case.dyr)
    rec = case.dyr[k]
    touched = {rec["unit"]}
    if kind == "scale" or kind == "token":
        if rec["consts"]:
            j = a % len(rec["consts"])
            if kind == "token":
                rec["consts"][j] = b
            else:
                with contextlib.suppress(ValueError):      # a token already damaged stays
                    rec["consts"][j] = repr(float(rec["consts"][j]) * b)
    elif kind == "inconsistent":
        if rec["model"] in ("GENROU", "GENTPJ"):
            names = psse.TYPED_MODELS[rec["model"]]
            if len(rec["consts"]) == len(names):
                c = dict(zip(names, rec["consts"]))
                edit = {"X''d<Xl": {"X''d": "0.1", "Xl": "0.15"}, "X''d=Xl": {"X''d": c["Xl"]},
                        "X''d>X'q": {"X''d": "0.95"}, "X'd>Xd": {"X'd": "2.5"}, "X'q>Xq": {"X'q": "1.9"}}[a]
                rec["consts"] = [edit.get(n, v) for n, v in zip(names, rec["consts"])]
    elif kind == "delete":
        case.dyr.pop(k)
    elif kind == "duplicate":
        copy = {**rec, "consts": list(rec["consts"])}
        if copy["consts"]:
            with contextlib.suppress(ValueError):
                copy["consts"][0] = repr(float(copy["consts"][0]) * a)
        case.dyr.append(copy)
    elif kind == "rename":
        rec["model"] = a
    elif kind == "drop constant":
        if rec["consts"]:
            rec["consts"].pop()
    elif kind == "extra constant":
        rec["consts"].append(a)
    elif kind == "no terminator":       # runs into the next record (see ``touched``)
        rec["end"] = ""
    elif kind == "bus number":
        rec["bus"] = a
    return touched


REASONS = {
    "must be > 0": "a value must be > 0", "must be >= 0": "a value must be >= 0",
    "is not a number": "not a number", "constants, expected": "wrong number of constants",
    "no machine record": "no machine record", "no column matches": "a column missing",
    "base voltage": "bus base voltage", "no generator": "no generator record",
    "above Xd": "X'd above Xd", "is not an integer": "not an integer",
    "no terminating": "no terminating '/'", "must be >=": "a value out of range",
}


def _reason_kind(reason: str) -> str:
    return next((v for k, v in REASONS.items() if k in reason), "other")


@settings(max_examples=50, deadline=None, derandomize=True, database=None, phases=PHASES,
          suppress_health_check=[HealthCheck.too_slow])
@given(ds=damages())
def test_fuzzed_case_never_aborts_the_fleet(ds):
    case = Case()
    hit = touched(case, ds)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        cfg = case.write(folder)
        expected = case.expected(folder)
        try:
            fl = load_fleet(cfg)
        except jd.InputError as e:
            msg = str(e)
            assert "\n" not in msg and ": no usable plant: all " in msg, msg
            event("load_fleet: InputError, no usable plant")
            return
    plants, skipped = [p.name for p in fl.plants], [s["name"] for s in fl.skipped]
    assert len(set(plants)) == len(plants) and len(set(skipped)) == len(skipped)
    assert not set(plants) & set(skipped)
    assert set(plants) | set(skipped) == expected, (plants, skipped, expected)
    base_plants, base_skipped = baseline()
    more = [s for s in fl.skipped if s["name"] not in base_skipped]
    event(f"load_fleet: {len(fl.plants)} plant(s), {len(more)} skipped beyond the clean case's")
    for s in fl.skipped:
        assert isinstance(s["reason"], str) and s["reason"].strip() and "\n" not in s["reason"]
        assert s["bus"] == int(s["name"][1:s["name"].index("_")])
    for s in more:
        event(f"skipped: {_reason_kind(s['reason'])}")
    for p in fl.plants:
        leaves = machine_leaves(p)
        assert all(np.all(np.isfinite(x)) for x in leaves)
        assert all(n.strip() and "\n" not in n for n in p.fallbacks)
        unit = (p.bus, p.name.split("_G", 1)[1])
        if unit not in hit:
            base = base_plants[p.name]
            assert lines_out(p.fallbacks) == lines_out(base.fallbacks)
            assert all(np.array_equal(a, b) for a, b in zip(leaves, machine_leaves(base)))
        elif p.fallbacks != base_plants.get(p.name, p).fallbacks:
            event("plant: runs on a fallback (noted)")
        assert math.isfinite(p.run.h_reference_s) and p.run.h_reference_s > 0
    for u in UNITS:
        if u not in hit and name(u) in base_plants:
            assert name(u) in plants, (name(u), fl.skipped)
    assert all("\n" not in n for n in fl.notes)
    if fl.notes:
        event("case: records dropped (Fleet.notes)")
