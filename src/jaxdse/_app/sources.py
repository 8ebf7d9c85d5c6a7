"""The units of a run configuration or a fleet file, for the stream layer (``jaxdse pmu-sim``,
``jaxdse monitor``).

A fleet file is read by this layer (:func:`~.fleet_file.load_fleet`: the .raw, the .dyr and
the plants' recordings); the stream layer below takes the units it needs as arguments
(:class:`~jaxdse._stream.pmu_sim.Units`, or a function of a path that gives them) and never
imports this one. The public names :func:`load_monitor`, :func:`replay_recording` and
:func:`load_source` are the stream layer's, with the units resolved here.
"""

from __future__ import annotations

from pathlib import Path

from .._stream import monitor as _monitor
from .._stream import pmu_sim as _pmu_sim
from .._stream.pmu_sim import Units


def source_units(path) -> Units:
    """The units of a run configuration (its [[generator]]s) or a fleet file (its plants),
    with the estimator's settings it gives."""
    from .._core.identify import IdentifySettings
    from .._io.config import load_config
    from .._io.schema import read_toml

    path = Path(path)
    if "case" in read_toml(path):
        from .fleet_file import load_fleet

        fleet = load_fleet(path)
        return Units([(p.name, p.run) for p in fleet.plants], [(s["name"], s["reason"]) for s in fleet.skipped],
                     fleet.observer, fleet.settings, fleet.identify or IdentifySettings(), fleet.verdict,
                     (fleet.raw, fleet.dyr, {p.name: (p.bus, tuple(m.id for m in p.members)) for p in fleet.plants},
                      fleet.inertia))
    cfg = load_config(path)
    return Units([(g.name, g) for g in cfg.generators], [], cfg.observer, cfg.settings,
                 cfg.identify or IdentifySettings(), cfg.verdict)


def load_source(path) -> _pmu_sim.Source:
    """The recording(s) of a run configuration or fleet file as ``jaxdse pmu-sim`` serves them
    (:func:`jaxdse._stream.pmu_sim.load_source`)."""
    return _pmu_sim.load_source(path, source_units(path))


def load_monitor(path) -> _monitor.MonitorConfig:
    """Read and check a monitor file (``jaxdse monitor --help``); its ``fleet`` is read here."""
    return _monitor.load_monitor(path, source_units)


def replay_recording(path, out_dir: Path | None = None, log=None) -> list[dict]:
    """``jaxdse run REPLAY.toml``: the stream a monitor recorded, through the file readers and
    the same windowed identification (:func:`jaxdse._stream.monitor.replay_recording`)."""
    return _monitor.replay_recording(path, source_units, out_dir, log)


__all__ = ["load_monitor", "load_source", "replay_recording", "source_units"]
