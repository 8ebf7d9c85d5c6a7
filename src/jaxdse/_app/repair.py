"""``jaxdse check --repair``: the repaired .dyr, its change table, and the repairs a case carries.

:func:`write_repair` turns a check's data problems into changes (:mod:`jaxdse._dyr.repair`:
the rule, what is and is not repaired) and writes, into the output folder:

* ``repaired.dyr`` -- the case's .dyr with each changed constant replaced in place and a
  ``/ jaxdse repair: ...`` comment line (PSS/E skips it) before its record; with several .dyr
  files in [case] dyr, only the changed records, to be read after them;
* ``repairs.csv`` -- one row per changed constant (unit, bus, id, record, file, line, CON, its
  number, old, new, the signal, its value, the limit, its value, the side, why);
* ``repaired.raw`` -- only where a generator's .raw data (its power flow |PG + jQG| or its
  maximum output PT) lie above 1.1 x its MBASE: the .raw with each such MBASE replaced in place
  and a ``/ jaxdse repair: MBASE ...`` comment at the end of the record's line; those units are
  then checked again on it (their exciter and governor limits at the new base), and only what
  they still cross is repaired in the .dyr;
* ``repaired.toml`` -- a case file with the .raw (repaired.raw where written) and the repaired
  .dyr (and the case's [playback]), for ``jaxdse check``, ``jaxdse fleet`` and ``jaxdse
  validate`` (a fleet file takes its [case] as it is).

check.json gets the section ``repair`` (the rule, the files, ``changes``: the rows of
repairs.csv, ``not_repaired``: {unit, why}); the console and check.html show the table.

A case whose records carry repairs (a repaired.dyr read back) lists them per unit
(:func:`attach_carried`: check.json's ``repairs`` of each unit, check.html), and so do the
unit pages of ``jaxdse fleet`` and ``jaxdse validate``.
"""

from __future__ import annotations

import dataclasses
import html
import json
import os
from collections.abc import Callable
from pathlib import Path

from .._dyr.repair import RULE, carried, carried_raw, changes_csv, plan, repaired_dyr, repaired_raw
from .._io.psse import read_raw
from .dyr_fleet import PlaybackOptions


def write_repair(case, doc: dict, out_dir: Path, recheck: Callable | None = None) -> dict:
    """Plan the repairs of ``doc`` (the check of ``case``), write the files into ``out_dir``;
    the ``repair`` section of check.json. ``recheck(case, names)``: the check.json document of
    the units ``names`` of ``case`` (``check_case(case, only=names)``), run on the case with the
    repaired .raw for the units whose MBASE changed."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    sources = case.dyr.source.split(" + ")
    p = plan(doc, case.dyr, ke_zero=case.playback.ke_zero, raw=case.raw)
    files = {"dyr": out_dir / "repaired.dyr", "csv": out_dir / "repairs.csv",
             "case": out_dir / "repaired.toml"}
    raw_file = case.raw.source
    rechecked = list(p.recheck) if recheck is not None else []
    if p.raw_changes:
        files["raw"] = raw_file = out_dir / "repaired.raw"
        with open(raw_file, "w", encoding="latin-1", newline="") as f:
            f.write(repaired_raw(p, case.raw.source))
        if p.recheck and recheck is not None:
            again = dataclasses.replace(case, raw=read_raw(raw_file, strict=False))
            p = p.merged(plan(recheck(again, p.recheck), case.dyr, ke_zero=case.playback.ke_zero,
                              raw=again.raw))
    text, whole = repaired_dyr(p, sources)
    with open(files["dyr"], "w", encoding="latin-1", newline="") as f:
        f.write(text)
    files["csv"].write_text(changes_csv(p))
    dyrs = ["repaired.dyr"] if whole else [_rel(s, out_dir) for s in sources] + ["repaired.dyr"]
    files["case"].write_text(_case_text(case, dyrs, out_dir, raw_file))
    return {"rule": RULE, "whole_file": whole,
            "files": {k: str(v) for k, v in files.items()},
            "units": len(p.units), "changes": [_finite(c.row()) for c in (*p.raw_changes, *p.changes)],
            "not_repaired": list(p.not_repaired), "checked_again_at_new_mbase": rechecked}


def _rel(path, start: Path) -> str:
    """``path`` relative to ``start`` where they share a folder below the root, else absolute."""
    a, b = Path(path).resolve(), start.resolve()
    try:
        if os.path.commonpath([a, b]) != a.anchor:
            return os.path.relpath(a, b)
    except ValueError:      # another drive
        pass
    return str(a)


def _case_text(case, dyrs: list[str], out_dir: Path, raw_file) -> str:
    pb = case.playback
    default = PlaybackOptions()
    playback = {k: getattr(pb, k) for k in ("solver", "substeps", "ke_zero")
                if getattr(pb, k) != getattr(default, k)}
    same = str(raw_file) == str(case.raw.source)
    lines = [f"# written by jaxdse check --repair of {case.path}: "
             f"{'the same .raw' if same else 'the repaired .raw'}, the repaired .dyr",
             "[case]", f"raw = {json.dumps(_rel(raw_file, out_dir) if same else Path(raw_file).name)}",
             f"dyr = {json.dumps(dyrs[0] if len(dyrs) == 1 else dyrs)}"]
    if playback:
        lines += ["", "[playback]"] + [f"{k} = {json.dumps(v)}" for k, v in playback.items()]
    return "\n".join(lines) + "\n"


def _finite(row: dict) -> dict:
    return {k: (None if isinstance(v, float) and v != v else v) for k, v in row.items()}


def attach_carried(doc: dict, dyr, raw=None) -> None:
    """Each unit's ``repairs``: the repairs its records carry (empty for most): its generator's
    .raw record's, then its .dyr records'; the summary's ``repaired_units``."""
    n = 0
    for e in doc["units"]:
        gens = [g for g in (raw.generators if raw is not None else ())
                if g.bus == e["bus"] and g.id.strip().upper() == str(e["id"]).upper()][:1]
        rows = [_finite(c) for g in gens for c in carried_raw(g)]
        rows += [_finite(c) for r in dyr.unit_records(e["bus"], e["id"]) for c in carried(r)]
        e["repairs"] = rows
        n += bool(rows)
    doc["repaired_units"] = n


def _g(x) -> str:
    return "-" if x is None else f"{x:.7g}"


def repair_console(doc: dict) -> list[str]:
    """The console lines: the change table of ``--repair``, or how many units run on
    repaired records."""
    out = []
    r = doc.get("repair")
    if r is not None:
        out += ["", f"repair ({r['rule']}): {len(r['changes'])} constant(s) of {r['units']} unit(s)"]
        if r["changes"]:
            rows = [(c["unit"], c["record"], f"{c['file']}:{c['line']}", c["con"], _g(c["old"]), _g(c["new"]),
                     c["why"]) for c in r["changes"]]
            heads = ("unit", "record", "line", "CON", "old", "new", "why")
            w = [max(len(x[k]) for x in [heads, *rows]) for k in range(6)]
            for x in [heads, *rows]:
                out.append("  " + "  ".join(f"{x[k]:<{w[k]}}" for k in range(6)) + "  " + x[6])
        for x in r["not_repaired"]:
            out.append(f"  not repaired: {x['unit']}: {x['why']}")
    n = doc.get("repaired_units", 0)
    if n:
        out += ["", f"{n} unit(s) run on repaired records (jaxdse check --repair; each change in "
                "check.json's \"repairs\" of the unit and on check.html)"]
    return out


def repair_html(doc: dict) -> str:
    """check.html's sections: the change table of ``--repair``; the repairs the records carry."""
    parts = []
    r = doc.get("repair")
    if r is not None:
        rows = "".join(
            f"<tr><td>{html.escape(c['unit'])}</td><td>{html.escape(c['record'])}</td>"
            f"<td>{html.escape(c['file'])} {c['line']}</td><td>{html.escape(c['con'])}</td>"
            f"<td>{_g(c['old'])}</td><td>{_g(c['new'])}</td>"
            f"<td style=\"text-align:left\" class=\"small\">{html.escape(c['why'])}</td></tr>"
            for c in r["changes"])
        left = "".join(f"<li>{html.escape(x['unit'])}: {html.escape(x['why'])}</li>"
                       for x in r["not_repaired"])
        parts.append(
            f"<h2>Repair</h2><p>{len(r['changes'])} constant(s) of {r['units']} unit(s) changed, written to "
            f"{html.escape(Path(r['files']['dyr']).name)}"
            + (f" and {html.escape(Path(r['files']['raw']).name)} (generators' MBASE)" if "raw" in r["files"]
               else "") + " (the changes also in "
            f"{html.escape(Path(r['files']['csv']).name)}; the case with the repaired records: "
            f"{html.escape(Path(r['files']['case']).name)}). Rule: {html.escape(r['rule'])}.</p>"
            "<table class=\"sortable\"><thead><tr><th>unit</th><th>record</th><th>.dyr line</th><th>CON</th>"
            f"<th>old</th><th>new</th><th>why</th></tr></thead><tbody>{rows}</tbody></table>"
            + (f"<p>Not repaired:</p><ul>{left}</ul>" if left else ""))
    carried_rows = "".join(
        f"<tr><td>{html.escape(e['name'])}</td><td>{html.escape(c['record'])}</td>"
        f"<td>{html.escape(c['file'])} {c['line']}</td><td>{html.escape(c['con'])}</td>"
        f"<td>{_g(c['old'])}</td><td>{_g(c['new'])}"
        f"{'' if c['holds_new'] else ' (now ' + _g(c['current']) + ')'}"
        f"</td><td style=\"text-align:left\" class=\"small\">{html.escape(c['why'])}</td></tr>"
        for e in doc["units"] for c in e.get("repairs", []))
    if carried_rows:
        parts.append(
            f"<h2>Repaired records</h2><p>{doc.get('repaired_units', 0)} unit(s) run on records changed by "
            "<code>jaxdse check --repair</code> (the '/ jaxdse repair:' lines of the .dyr):</p>"
            "<table class=\"sortable\"><thead><tr><th>unit</th><th>record</th><th>.dyr line</th><th>CON</th>"
            "<th>original</th><th>repaired</th><th>why</th></tr></thead>"
            f"<tbody>{carried_rows}</tbody></table>")
    return "\n".join(parts)


__all__ = ["attach_carried", "repair_console", "repair_html", "write_repair"]
