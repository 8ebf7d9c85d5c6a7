"""``jaxdse run``: a validated config -> read every generator's recording -> estimate -> outputs."""

from __future__ import annotations

import csv
import dataclasses
import json
import sys
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np

from .._core.estimate import estimate
from .._io.config import RunConfig
from .._io.errors import InputError
from .._io.measurement import read_measurement
from .._many.batch import estimate_batch
from .._many.sweep import sweep_configs
from .._many.tune import TUNABLE, TUNE_SETTINGS, config_values, tune
from .progress import Progress
from .report import format_table, plot_estimates, summary_entry, write_estimates_csv, write_summary

_estimate = eqx.filter_jit(estimate)  # one compile per recording length, kept across runs


def run_config(cfg: RunConfig, out_dir: Path | None = None, stream=sys.stderr) -> dict:
    """Estimate every generator of ``cfg``; write summary.json, CSVs and figures; return the summary.

    Raises :class:`InputError` for bad input (before any output is written).
    """
    out_dir = Path(out_dir) if out_dir is not None else cfg.out_dir
    t_start = time.perf_counter()
    progress = Progress(2 * len(cfg.generators), stream)
    loaded = []
    for g in cfg.generators:
        segments, quality = read_measurement(g.measurement, float(g.plant.machine.s_rated_mva))
        loaded.append((g, segments, quality))
        progress.step(f"read {g.name} ({quality['rows_read']} rows, {len(segments)} segment(s))")

    out_dir.mkdir(parents=True, exist_ok=True)
    entries = []
    for g, segments, quality in loaded:
        for k, (t0, rec) in enumerate(segments):
            name = g.name if len(segments) == 1 else f"{g.name}_part{k + 1}"
            est = _estimate(rec, g.plant, cfg.observer, cfg.settings, None, g.a2_reference)
            est = eqx.tree_at(lambda e: e.time_s, est, est.time_s + t0)
            entry = summary_entry(name, est, a2_reference=g.a2_reference,
                                  h_reference_s=g.h_reference_s)
            entries.append({"name": name, "role": g.role, "generator": g.name, **entry,
                            "segment_start_s": t0, "data_quality": quality})
            if cfg.trajectories:
                write_estimates_csv(out_dir / f"estimates_{name}.csv", est)
            if cfg.figures:
                plot_estimates(est, name, out_dir, a2_reference=g.a2_reference)
        progress.step(f"estimated and wrote {g.name}")

    summary = {
        "source": f"jaxdse run {cfg.path}",
        "observer": {k: float(getattr(cfg.observer, k)) for k in cfg.observer.__dataclass_fields__},
        "wall_time_s": round(time.perf_counter() - t_start, 2),
    }
    write_summary(out_dir / "summary.json", entries, summary)
    print(format_table(entries))
    print(f"[jaxdse] wrote {out_dir}/summary.json"
          + (", estimates_*.csv" if cfg.trajectories else "")
          + (" and figures" if cfg.figures else "") + f" in {time.perf_counter() - t_start:.1f} s",
          file=stream)
    return {"recordings": entries, **summary}



def _first_segment(g, stream):
    segments, _ = read_measurement(g.measurement, float(g.plant.machine.s_rated_mva))
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


def _same_plant(a, b) -> bool:
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    return ta == tb and all(np.array_equal(x, y) for x, y in zip(la, lb))


def run_tune(cfg: RunConfig, out_dir: Path | None = None, stream=sys.stderr) -> dict:
    """``jaxdse tune``: tune on role "auto" generators, score held-out role "cross" ones."""
    out_dir = Path(out_dir) if out_dir is not None else cfg.out_dir
    tn = cfg.tune or {}
    train = [g for g in cfg.generators if g.role == "auto"]
    held = [g for g in cfg.generators if g.role == "cross"]
    if not train:
        raise InputError(cfg.path, "jaxdse tune needs at least one [[generator]] with role = 'auto'",
                         key="generator")
    if not all(_same_plant(g.plant, train[0].plant) for g in train + held):
        raise InputError(cfg.path, "jaxdse tune needs one plant for all generators "
                         "(per-generator plant overrides are not supported)", key="generator")

    def truths(gs):
        refs = [g.a2_reference for g in gs]
        return None if any(r is None for r in refs) else refs

    bar = Progress(tn.get("max_steps", 30), stream)
    kwargs = {k: tn[k] for k in ("max_steps", "max_factor", "autodiff", "weights") if k in tn}
    t0 = time.perf_counter()
    res = tune([_first_segment(g, stream) for g in train], train[0].plant, cfg.observer, truths(train),
               heldout=[_first_segment(g, stream) for g in held], heldout_a2_true=truths(held),
               names=tn.get("parameters", TUNABLE), settings=dataclasses.replace(
                   TUNE_SETTINGS, derivative_half_width=cfg.settings.derivative_half_width,
                   qss_window_s=cfg.settings.qss_window_s),
               progress=lambda k, f: bar.step(f"step {k}: loss {f:.5g}"), **kwargs)
    values = config_values(res.config, list(cfg.observer.__dataclass_fields__))
    summary = {"source": f"jaxdse tune {cfg.path}", "train": [g.name for g in train],
               "heldout": [g.name for g in held], "steps": res.steps,
               "loss_start": res.loss_start, "loss_tuned": res.loss_tuned,
               "heldout_loss_start": res.heldout_loss_start, "heldout_loss_tuned": res.heldout_loss_tuned,
               "history": list(res.history), "observer_start": config_values(cfg.observer, list(values)),
               "observer_tuned": values, "wall_time_s": round(time.perf_counter() - t0, 1)}
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "tune.json").write_text(json.dumps(summary, indent=2))
    (out_dir / "tuned_observer.toml").write_text(
        f"# jaxdse tune {cfg.path.name}: training loss {res.loss_start:.5g} -> {res.loss_tuned:.5g}\n"
        "[observer]\n" + "".join(f"{k} = {v!r}\n" for k, v in values.items()))
    held_txt = ("" if res.heldout_loss_start is None else
                f"; held-out loss {res.heldout_loss_start:.5g} -> {res.heldout_loss_tuned:.5g}")
    print(f"[jaxdse] training loss {res.loss_start:.5g} -> {res.loss_tuned:.5g}{held_txt}; wrote "
          f"{out_dir}/tune.json and tuned_observer.toml (paste its [observer] into your config)",
          file=stream)
    return summary
