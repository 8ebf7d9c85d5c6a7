"""``jaxdse run``: a validated config -> read every generator's recording -> estimate -> outputs."""

from __future__ import annotations

import sys
import time
from pathlib import Path

import equinox as eqx

from ._config import RunConfig
from ._estimate import estimate
from ._measurement import read_measurement
from ._report import format_table, plot_estimates, summary_entry, write_estimates_csv, write_summary

_estimate = eqx.filter_jit(estimate)  # one compile per recording length, kept across runs


class Progress:
    """A one-line progress bar on stderr (plain lines when stderr is not a terminal)."""

    def __init__(self, total: int, stream=sys.stderr, width: int = 28):
        self.total, self.done, self.stream, self.width = total, 0, stream, width
        self.t0 = time.perf_counter()
        self.tty = hasattr(stream, "isatty") and stream.isatty()

    def step(self, label: str):
        self.done = min(self.total, self.done + 1)
        frac = self.done / max(self.total, 1)
        bar = "#" * round(frac * self.width) + "-" * (self.width - round(frac * self.width))
        line = f"[{bar}] {self.done}/{self.total} {time.perf_counter() - self.t0:6.1f} s  {label}"
        if self.tty:
            self.stream.write("\r\033[K" + line + ("\n" if self.done == self.total else ""))
        else:
            self.stream.write(line + "\n")
        self.stream.flush()


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

