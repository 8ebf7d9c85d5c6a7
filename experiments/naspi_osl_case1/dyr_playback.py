"""OSL case 1: the plants' own .dyr records played back, against the 3rd-order surrogate.

    python experiments/naspi_osl_case1/dyr_playback.py

Runs ``jaxdse fleet`` twice on the contest's recording: ``fleet.toml`` (the surrogate) and
``fleet_dyr.toml`` (``[playback] model = "dyr"``: each unit's GENROU, SEXS, IEEEST and
governor records, the recorded terminal voltage imposed). Per plant: the event-window RMS
errors of P and Q [% of MBASE], the whole-record RMS error of Q, and whether the plant passes
the windowed criteria; plants whose records include a model jaxdse does not simulate stay on
the surrogate and are marked. Writes dyr_playback.json and dyr_playback.md here.
"""

import json
import sys
import tempfile
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent


def event_rms(u: dict, channel: str):
    for sc in (u["validation"]["windows"] or {"scores": []})["scores"]:
        if sc["channel"] == channel and sc["window"] == "event":
            return sc["rms_error"]
    return None


def main():
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, name in (("surrogate", "fleet_surrogate.toml"), ("dyr", "fleet.toml")):
            runs[label] = {u["name"]: u for u in jd.fleet(HERE / name, Path(tmp) / label, stream=sys.stderr)}
    rows = []
    for name, s in runs["surrogate"].items():
        d = runs["dyr"][name]
        rows.append({"plant": name, "model": d["playback_model"], "fallback": d.get("playback_fallback"),
                     "records": d.get("playback_models"),
                     **{f"{lab}_event_rms_{ch}": event_rms(u, f"{ch}_t") for lab, u in (("surrogate", s), ("dyr", d))
                        for ch in ("P", "Q")},
                     "surrogate_rms_Q": s["playback_rms_percent_mbase"]["Q_t"],
                     "dyr_rms_Q": d["playback_rms_percent_mbase"]["Q_t"],
                     "surrogate_passes_windows": s["validation"]["result"] == "pass",
                     "dyr_passes_windows": d["validation"]["result"] == "pass",
                     "dyr_window_reasons": d["validation"]["reasons"]})
    on_dyr = [r for r in rows if r["model"] == "dyr"]
    summary = {
        "plants": len(rows), "on_dyr_model": len(on_dyr),
        "median_rms_Q_percent_mbase": {
            "surrogate": float(np.median([r["surrogate_rms_Q"] for r in on_dyr])) if on_dyr else None,
            "dyr": float(np.median([r["dyr_rms_Q"] for r in on_dyr])) if on_dyr else None},
        "pass_windows": {"surrogate": sum(r["surrogate_passes_windows"] for r in rows),
                         "dyr": sum(r["dyr_passes_windows"] for r in rows)},
    }
    doc = {"summary": summary, "rows": rows}
    (HERE / "dyr_playback.json").write_text(json.dumps(doc, indent=1) + "\n")
    (HERE / "dyr_playback.md").write_text(report(doc))
    print(json.dumps(summary, indent=1))


def report(doc) -> str:
    s = doc["summary"]

    def f(x):
        return "–" if x is None else f"{x:.3f}"

    out = ["# OSL case 1: the .dyr playback against the surrogate", "",
           "Written by `experiments/naspi_osl_case1/dyr_playback.py`. Errors in % of MBASE.", "",
           f"- plants: {s['plants']}, played back with their own .dyr records: {s['on_dyr_model']}",
           f"- median whole-record RMS error of Q (plants on the .dyr model): surrogate "
           f"{f(s['median_rms_Q_percent_mbase']['surrogate'])} %, .dyr {f(s['median_rms_Q_percent_mbase']['dyr'])} %",
           f"- plants passing the windowed criteria: surrogate {s['pass_windows']['surrogate']}, "
           f".dyr {s['pass_windows']['dyr']}", "",
           "| plant | playback | event P (surrogate) | event P (.dyr) | event Q (surrogate) | event Q (.dyr) "
           "| RMS Q (surrogate) | RMS Q (.dyr) | windows (surrogate / .dyr) |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in doc["rows"]:
        model = r["model"] if not r["fallback"] else f"surrogate ({r['fallback']})"
        out.append(f"| {r['plant']} | {model} | {f(r['surrogate_event_rms_P'])} | {f(r['dyr_event_rms_P'])} | "
                   f"{f(r['surrogate_event_rms_Q'])} | {f(r['dyr_event_rms_Q'])} | {f(r['surrogate_rms_Q'])} | "
                   f"{f(r['dyr_rms_Q'])} | {'pass' if r['surrogate_passes_windows'] else 'fail'} / "
                   f"{'pass' if r['dyr_passes_windows'] else 'fail'} |")
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    main()
