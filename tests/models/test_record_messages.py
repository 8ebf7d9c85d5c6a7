"""Messages about a .dyr record name its PSS/E constants (T'do, TE, KS1, ...), never a module field.

Every model jaxdse simulates (the machine, exciter, stabiliser and governor registries): a valid
record, then each of its constants set to -1 in turn, read as the .dyr reader reads it
(``*_from_dyr``). Whatever a model's checks refuse is said in one line that starts with the model,
holds no field name of the module (``td0_1_s``, ``GENROU.td0_1_s``, ``TE (t_e_s)``) and names at
least one of the record's constants. Plain Python, no compilation.
"""

import dataclasses
import math
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from jaxdse._dyr.records import unit_model
from jaxdse._io.psse import (
    GOVERNOR_FIELDS,
    GOVERNOR_PARAMETERS,
    MACHINE_FIELDS,
    DyrRecord,
    governor_from_dyr,
    read_dyr,
    read_raw,
)
from jaxdse._models.exciters import EXCITER_FIELDS, EXCITERS, exciter_from_dyr
from jaxdse._models.exciters import _ATTRIBUTES as EXCITER_ATTRIBUTES
from jaxdse._models.governors import GOVERNORS
from jaxdse._models.machines import MACHINES, machine_from_dyr
from jaxdse._models.stabilisers import (
    STABILISER_FIELDS,
    STABILISER_PARAMETERS,
    STABILISERS,
    stabiliser_from_dyr,
)

BENCH = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench" / "data" / "ieee14"
# The ieee14 GENROU (bus 1) and a salient-pole machine, in PSS/E names.
ROU = {"T'do": 6.5, "T''do": 0.06, "T'qo": 0.2, "T''qo": 0.05, "H": 4.0, "D": 0.0, "Xd": 1.8, "Xq": 1.75,
       "X'd": 0.6, "X'q": 0.8, "X''d": 0.23, "Xl": 0.15, "S(1.0)": 0.09, "S(1.2)": 0.38, "Kis": 0.0}
SAL = {"T'do": 5.0, "T''do": 0.05, "T''qo": 0.1, "H": 3.0, "D": 0.5, "Xd": 1.1, "Xq": 0.7, "X'd": 0.3,
       "X''d": 0.25, "Xl": 0.15, "S(1.0)": 0.1, "S(1.2)": 0.3}


def _value(module, field):
    v = getattr(module, field)
    return float(np.asarray(v)) if not isinstance(v, int | bool) else int(v)


def _records():
    """(kind, model, CON names, constants, build(constants)) of every simulated model: the
    constants of its module's defaults (machines: the records above)."""
    out = []
    for model in MACHINES:
        base = SAL if model in ("GENSAL", "GENSAE") else ROU
        names = MACHINE_FIELDS[model]
        out.append(("machine", model, names, [base[n] for n in names],
                    lambda c, m=model, n=names: machine_from_dyr(m, dict(zip(n, c)), x_source_pu=0.3)))
    for model, cls in EXCITERS.items():
        default = cls()
        cons = [_value(default, f) for f in EXCITER_ATTRIBUTES[model]]
        cons = [math.degrees(v) if f == "theta_p_rad" else v for f, v in zip(EXCITER_ATTRIBUTES[model], cons)]
        out.append(("exciter", model, EXCITER_FIELDS[model], cons,
                    lambda c, m=model: exciter_from_dyr(m, c)))
    for model, cls in STABILISERS.items():
        default = cls()
        by_con = {con: _value(default, f) for f, con in STABILISER_PARAMETERS[model].items()}
        names = STABILISER_FIELDS[model]
        out.append(("stabiliser", model, names, [by_con[n] for n in names],
                    lambda c, m=model: stabiliser_from_dyr(m, c)))
    for model, cls in GOVERNORS.items():
        default = cls()
        by_con = {con: _value(default, f) for f, con in GOVERNOR_PARAMETERS[model].items()}
        by_con.update({"JBUS": 0.0, "M": 0.0, "Trate": 0.0})
        if model == "GGOV1":
            by_con.update(Rselect=float(default.rselect), Flag=float(default.flag))
        names = GOVERNOR_FIELDS[model]

        def build(c, m=model, n=names):
            rec = DyrRecord(m, 1, "1", tuple(c), 1, source="case.dyr", params=dict(zip(n, c)))
            return governor_from_dyr(rec, mbase_mva=100.0)
        out.append(("governor", model, names, [by_con[n] for n in names], build))
    return out


RECORDS = _records()


def test_every_simulated_model_is_covered():
    assert {m for _, m, *_ in RECORDS} == {*MACHINES, *EXCITERS, *STABILISERS, *GOVERNORS}


@pytest.mark.parametrize("kind,model,names,cons,build", RECORDS, ids=[r[1] for r in RECORDS])
def test_refusals_name_the_psse_constants(kind, model, names, cons, build):
    build(list(cons))   # the record as it is: valid
    fields = {f.name for cls in (type(build(list(cons))),) for f in dataclasses.fields(cls)}
    internal = re.compile(r"(?<![\w'.(])(" + "|".join(sorted(map(re.escape, fields), key=len, reverse=True))
                          + r")(?![\w'(])")
    refused = 0
    for k in range(len(cons)):
        for bad in (-1.0,):
            c = list(cons)
            c[k] = bad
            try:
                build(c)
            except ValueError as err:
                refused += 1
                msg = str(err)
                assert "\n" not in msg
                text = msg.split("id '1': ", 1)[-1]   # a governor's: after the record's label
                assert text.startswith(f"{model}: ") or kind == "governor", msg
                found = [w for w in internal.findall(text) if "_" in w or any(ch.isdigit() for ch in w)
                         and w not in names]
                assert not found, f"{msg!r} names the field(s) {found}, not the record's constants"
                assert not re.search(rf"\b{model}\.\w", text), msg
                assert any(re.search(rf"(?<![\w']){re.escape(n)}(?![\w'])", text) for n in names), \
                    f"{msg!r} names none of {model}'s constants"
    assert refused, f"no value of {model} refused: the test checks nothing"


def test_negative_t_do_through_the_unit_reader(tmp_path):
    """The message `jaxdse check` and `fleet` show: the record, its line and T'do."""
    shutil.copy(BENCH / "ieee14.raw", tmp_path / "case.raw")
    text = (BENCH / "ieee14.dyr").read_text().replace("1 'GENROU' 1 6.5 ", "1 'GENROU' 1 -6.5 ", 1)
    text = text.replace("1 'TGOV1' 1 0.05 0.05", "1 'TGOV1' 1 0.05 -0.05", 1)
    exst1 = "2 'EXST1' 1 0.02 99 -99 0 0.02 50\n    "
    text = text.replace(exst1 + "0.02", exst1 + "-0.02", 1)
    (tmp_path / "case.dyr").write_text(text)
    dyr, raw = read_dyr(tmp_path / "case.dyr", strict=False), read_raw(tmp_path / "case.raw")
    one = unit_model(dyr, raw, 1, "1")
    assert one.unit is None
    assert one.missing[0] == ("GENROU on bus 1 id '1' (case.dyr line 1): GENROU: T'do must be > 0, "
                              "got -6.5"), one.missing
    assert one.missing[1] == "TGOV1 on bus 1 id '1' (case.dyr line 4): TGOV1: T1 must be > 0, got -0.05"
    two = unit_model(dyr, raw, 2, "1")
    assert two.missing == ["EXST1 on bus 2 id '1' (case.dyr line 15): EXST1: TA must be > 0, got -0.02"]
    for m in one.missing + two.missing:
        assert not re.search(r"\b[a-z]\w*_\w+", m.split(": ", 1)[1]), m
