"""``jaxdse run``: a validated config -> read every generator's recording -> estimate -> outputs."""

from __future__ import annotations

import csv
import dataclasses
import json
import sys
import time
from pathlib import Path

import equinox as eqx
import numpy as np

from .._core.settings import Settings
from .._core.verdict import NOTES
from .._io.config import RunConfig
from .._io.errors import InputError
from .._io.measurement import order_note, read_measurement
from .._many.batch import estimate_batch
from .._many.runner import Unit, assess_units, planned_calls
from .._many.sweep import sweep_configs
from .._many.tune import TUNABLE, TUNE_SETTINGS, config_values, tune
from .._version import __version__
from .progress import Progress
from .report import format_table, plot_estimates, summary_entry, write_estimates_csv, write_summary


def run_config(cfg: RunConfig, out_dir: Path | None = None, stream=None) -> dict:
    """Estimate every generator of ``cfg``; write summary.json, CSVs and figures; return the summary.

    The online estimator runs first (one batched call per group of recordings that share a
    padded length, a PMU location and a plant structure), then the batch identification,
    the playback with the identified H, D and the verdict. Raises :class:`InputError` for bad
    input (before any output is written). Units that are not ``identified`` get a one-line
    warning on ``stream``.
    """
    out_dir = Path(out_dir) if out_dir is not None else cfg.out_dir
    stream = stream or sys.stderr   # the stderr of the moment (a caller may redirect it)
    t_start = time.perf_counter()
    units, gens, qualities = [], [], []
    for g in cfg.generators:
        segments, quality = read_measurement(g.measurement, g.plant.machine)
        if note := order_note(quality):
            print(f"jaxdse: note: {g.name}: {note}", file=stream)
        if g.notes:   # plant data outside their typical range, used as given
            quality["plant_data"] = list(g.notes)
        for k, (t0, rec) in enumerate(segments):
            units.append(Unit(g.name if len(segments) == 1 else f"{g.name}_part{k + 1}", rec, g.plant, t0,
                              g.a2_reference))
            gens.append(g)
            qualities.append(quality)
    progress = Progress(len(cfg.generators) + planned_calls(units, cfg.identify) + len(units), stream)
    for g in cfg.generators:
        progress.step(f"read {g.name}")
    settings = dataclasses.replace(cfg.settings, keep="trajectories")
    assessed = assess_units(units, cfg.observer, settings, cfg.identify, cfg.verdict,
                            progress=lambda line: progress.step(f"assessed {line}"))
    out_dir.mkdir(parents=True, exist_ok=True)
    entries, inputs = [], {}
    for u, g, quality, a in zip(units, gens, qualities, assessed):
        est, ident, rep = a.estimate, a.identified, a.replay
        entry = summary_entry(u.name, a, a2_reference=g.a2_reference, h_reference_s=g.h_reference_s)
        entries.append({"name": u.name, "role": g.role, "generator": g.name, **entry,
                        "segment_start_s": u.t0_s, "data_quality": quality})
        for f in g.measurement.file:
            inputs.setdefault(f, None)
        decisive = [k for k in entry["reasons"] if k not in NOTES]
        status = entry["verdict"] if not decisive else f"{entry['verdict']}: {decisive[0].replace('_', ' ')}"
        if g.notes:   # a note beside the verdict, not a reason of it
            entry["reasons"]["atypical_plant_data"] = "plant data outside the typical range, used as " \
                "given: " + "; ".join(g.notes)
        if entry["verdict"] != "identified":
            why = "; ".join(v for k, v in entry["reasons"].items() if k not in NOTES) or "see summary.json"
            print(f"jaxdse: warning: {u.name}: {entry['verdict']}: {why}", file=stream)
        if cfg.trajectories:
            write_estimates_csv(out_dir / f"estimates_{u.name}.csv", est, rep)
        if cfg.figures:
            plot_estimates(est, u.name, out_dir, float(u.plant.machine.omega_s), a2_reference=g.a2_reference,
                           ident=ident, rep=rep,
                           status=status)
        progress.step(f"wrote {u.name}")
    summary = {
        "source": f"jaxdse run {cfg.path}",
        "jaxdse_version": __version__,
        "config": {"file": str(cfg.path), "sha256": sha256(cfg.path)},
        "inputs": [{"file": f, "sha256": sha256(Path(f))} for f in inputs],
        "observer": module_values(cfg.observer),
        "settings": settings_values(cfg.settings),
        "identify": None if cfg.identify is None else module_values(cfg.identify),
        "verdict_thresholds": module_values(cfg.verdict),
        "plants": {g.name: {**module_values(g.plant), "defaults_used": list(g.defaults_used)}
                   for g in cfg.generators},
        "wall_time_s": round(time.perf_counter() - t_start, 2),
    }
    write_summary(out_dir / "summary.json", entries, summary)
    print(format_table(entries))
    print(f"[jaxdse] wrote {out_dir}/summary.json"
          + (", estimates_*.csv" if cfg.trajectories else "")
          + (" and figures" if cfg.figures else "") + f" in {time.perf_counter() - t_start:.1f} s",
          file=stream)
    return {"recordings": entries, **summary}


def sha256(path: Path) -> str | None:
    """Hex SHA-256 of a file (None when it cannot be read)."""
    import hashlib

    try:
        with open(path, "rb") as fh:
            return hashlib.file_digest(fh, "sha256").hexdigest()
    except OSError:
        return None


def module_values(module) -> dict:
    """An eqx.Module as JSON-ready values: array leaves as numbers, sub-modules as dicts, the
    class name as "model"."""
    out = {"model": type(module).__name__}
    for f in dataclasses.fields(module):
        v = getattr(module, f.name)
        if isinstance(v, eqx.Module):
            out[f.name] = module_values(v)
        elif v is None or isinstance(v, bool | int | str):
            out[f.name] = v
        elif isinstance(v, float):
            out[f.name] = v
        else:
            try:
                out[f.name] = float(np.asarray(v))
            except (TypeError, ValueError):
                out[f.name] = str(v)
    return out


def settings_values(settings: Settings) -> dict:
    values = module_values(settings)
    for k in ("observer_integrator", "playback_integrator"):
        integ = getattr(settings, k)
        values[k] = {"solver": type(integ.solver).__name__, "adaptive": integ.adaptive,
                     "rtol": integ.rtol, "atol": integ.atol, "substeps": integ.substeps}
    return values


def _first_segment(g, stream):
    segments, _ = read_measurement(g.measurement, g.plant.machine)
    if len(segments) > 1:
        print(f"[jaxdse] {g.name}: {len(segments)} segments; using the first "
              f"({segments[0][1].t_s.shape[0]} samples)", file=stream)
    return segments[0][1]


def run_sweep(cfg: RunConfig, out_dir: Path | None = None, stream=sys.stderr) -> list[dict]:
    """``jaxdse sweep``: every configuration of [sweep] on every generator -> sweep.csv."""
    out_dir = Path(out_dir) if out_dir is not None else cfg.out_dir
    sw = cfg.sweep or {"mode": "grid", "parameters": {}, "draws": 1, "seed": 0, "chunk": 256}
    configs, points = sweep_configs(cfg.observer, sw["parameters"], sw["mode"], sw["draws"], sw["seed"])
    settings = dataclasses.replace(cfg.settings, keep="final")
    rows = []
    t0 = time.perf_counter()
    for g in cfg.generators:
        rec = _first_segment(g, stream)
        bar = Progress(len(points), stream)

        def tick(done, bar=bar, g=g):
            while bar.done < done:
                bar.step(f"{g.name}: {done}/{len(points)} configurations")

        est = estimate_batch(rec, g.plant, configs, settings, None, g.a2_reference,
                             chunk=sw["chunk"], progress=tick)
        for k, p in enumerate(points):
            rows.append({"generator": g.name, "config": k, **p,
                         "a1": est.a1[k], "a2": est.a2[k], "h_s": est.h_s[k], "d_pu_s": est.d_pu_s[k],
                         "convergence_time_s": est.convergence_time_s[k],
                         "converged": bool(est.converged[k]), "excited": bool(est.excited[k]),
                         "solver_ok": bool(est.solver_ok[k]),
                         **{f"smape_{n}": getattr(est.smape, n)[k] for n in est.smape._fields}})
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "sweep.csv"
    with open(path, "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (f"{float(v):.8g}" if isinstance(v, float | np.floating) else v)
                             for k, v in r.items()})
    print(f"[jaxdse] {len(points)} configurations x {len(cfg.generators)} generator(s) -> {path} "
          f"in {time.perf_counter() - t0:.1f} s", file=stream)
    return rows


def run_tune(cfg: RunConfig, out_dir: Path | None = None, stream=sys.stderr) -> dict:
    """``jaxdse tune``: tune on role "auto" generators, score held-out role "cross" ones.

    Each generator keeps its own plant (vmapped). The tuned values are recommended only if
    they lower the held-out loss (the training loss when nothing is held out); otherwise
    tuned_observer.toml keeps the start (paper Table I or the config's [observer]) and says why.
    Raises FloatingPointError if a loss is not finite (the CLI exits 1)."""
    out_dir = Path(out_dir) if out_dir is not None else cfg.out_dir
    tn = cfg.tune or {}
    train = [g for g in cfg.generators if g.role == "auto"]
    held = [g for g in cfg.generators if g.role == "cross"]
    if not train:
        raise InputError(cfg.path, "jaxdse tune needs at least one [[generator]] with role = 'auto'",
                         key="generator")

    def truths(gs):
        refs = [g.a2_reference for g in gs]
        return None if any(r is None for r in refs) else refs

    bar = Progress(tn.get("max_steps", 30), stream)
    kwargs = {k: tn[k] for k in ("max_steps", "max_factor", "autodiff", "weights") if k in tn}
    t0 = time.perf_counter()
    res = tune([_first_segment(g, stream) for g in train], [g.plant for g in train], cfg.observer,
               truths(train), heldout=[_first_segment(g, stream) for g in held],
               heldout_a2_true=truths(held), heldout_plant=[g.plant for g in held] or None,
               names=tn.get("parameters", TUNABLE), settings=dataclasses.replace(
                   TUNE_SETTINGS, derivative_half_width=cfg.settings.derivative_half_width,
                   qss_window_s=cfg.settings.qss_window_s),
               progress=lambda k, f: bar.step(f"step {k}: loss {f:.5g}"), **kwargs)
    names = list(cfg.observer.__dataclass_fields__)
    tuned = config_values(res.config, names)
    start = config_values(cfg.observer, names)
    judged_on = "held-out" if held else "training"
    summary = {"source": f"jaxdse tune {cfg.path}", "train": [g.name for g in train],
               "heldout": [g.name for g in held], "steps": res.steps,
               "loss_start": res.loss_start, "loss_tuned": res.loss_tuned,
               "heldout_loss_start": res.heldout_loss_start, "heldout_loss_tuned": res.heldout_loss_tuned,
               "improved": res.improved, "judged_on": judged_on,
               "history": list(res.history), "observer_start": start,
               "observer_tuned": tuned, "observer_recommended": tuned if res.improved else start,
               "wall_time_s": round(time.perf_counter() - t0, 1)}
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "tune.json").write_text(json.dumps(summary, indent=2))
    held_txt = ("" if res.heldout_loss_start is None else
                f"; held-out loss {res.heldout_loss_start:.5g} -> {res.heldout_loss_tuned:.5g}")
    losses = f"training loss {res.loss_start:.5g} -> {res.loss_tuned:.5g}{held_txt}"
    if res.improved:
        header = f"# jaxdse tune {cfg.path.name}: {losses}\n"
        advice = "paste its [observer] into your config"
    else:
        header = (f"# jaxdse tune {cfg.path.name}: {losses}\n# the {judged_on} loss got worse: "
                  "these are the START values, unchanged (tune.json keeps the tuned ones)\n")
        advice = (f"the {judged_on} loss got WORSE, so it keeps the start values: "
                  "do not use the tuned ones")
    (out_dir / "tuned_observer.toml").write_text(
        header + "[observer]\n"
        + "".join(f"{k} = {v!r}\n" for k, v in summary["observer_recommended"].items()))
    print(f"[jaxdse] {losses}; wrote {out_dir}/tune.json and tuned_observer.toml ({advice})", file=stream)
    return summary
