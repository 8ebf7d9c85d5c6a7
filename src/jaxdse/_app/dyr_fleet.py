"""The .dyr playback of a fleet's plants (``[playback] model = "dyr"``).

Each unit of a plant gets its own :class:`~jaxdse._dyr.unit.DyrUnit` from its records; the
plant's terminal voltage (as the front end mapped it) is imposed on every unit, each unit
starts from its share of the plant's measured P and Q (shares of the .raw PG and QG, or of
MBASE where those are zero), and the plant's simulated P and Q are the sum. A plant with a
unit whose records include a model jaxdse does not simulate plays back the surrogate, and
its page says which record. Units of one model structure and length share one compiled,
vmapped program, in calls of at most :data:`CHUNK_UNITS` units.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Literal, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dyr.playback import (
    PlaybackSettings,
    TerminalSeries,
    initial_operating_point,
    play_back,
    steady_start,
)
from .._dyr.gfm_unit import GfmUnit
from .._dyr.records import UnitModel, ibr_model, unit_model
from .._dyr.stiff import modes, stiff_note, too_stiff
from .._dyr.unit import UnitInputs
from .._many import programs
from .._many.runner import _same_context_in_threads, threads
from .._many.waits import COMPILE_LIMIT_S, Expired, Task, bounded
from .._models.exciters import EXCITERS
from .._models.ibr import IBR_MODELS
from .._models.stabilisers import STABILISERS

PLAYBACK_MODELS = ("surrogate", "dyr")
SIMULATED_RECORDS = frozenset({*EXCITERS, *STABILISERS, *IBR_MODELS})
"""Record models that the .dyr playback simulates beyond the machines and governors (the
inverter-based plants' included)."""


@dataclasses.dataclass(frozen=True)
class PlaybackOptions:
    """[playback]: which model plays the recording back, and how it is integrated."""

    model: Literal["surrogate", "dyr"] = "dyr"
    """"dyr" (the unit's own PSS/E records: machine, exciter, stabiliser, governor; the
    surrogate where a record's model is not simulated, named on the unit's page) or
    "surrogate" (the 3rd-order model with the identified H, D and estimated Ef: validates
    active power/frequency only)."""
    solver: Literal["tsit5", "kvaerno5"] = "tsit5"
    """"tsit5" (explicit, adaptive per frame) or "kvaerno5" (implicit, adaptive) for the .dyr
    model (:class:`~jaxdse.PlaybackSettings`). With "tsit5", a unit whose fastest mode at its
    initial state an explicit step of 1/substeps of a frame cannot follow (``jaxdse._dyr.stiff``)
    is integrated with Kvaerno5, and its notes say so."""
    substeps: int = 4
    """The first step of each frame is 1/substeps of it ("tsit5")."""
    ke_zero: Literal["psse", "literal"] = "psse"
    """A DC exciter's (IEEEX1, EXDC2, ESDC2A) KE = 0: PSS/E's self-excited rule (KE computed so that
    VR = VRMAX/10 initially) or literally 0 (as ANDES reads it)."""

    def __post_init__(self):
        if self.model not in PLAYBACK_MODELS:
            raise ValueError(f"model must be one of {PLAYBACK_MODELS}, got {self.model!r}")
        if self.solver not in ("tsit5", "kvaerno5"):
            raise ValueError(f"solver must be \"tsit5\" or \"kvaerno5\", got {self.solver!r}")
        if self.substeps < 1:
            raise ValueError(f"substeps must be >= 1, got {self.substeps}")

    @property
    def settings(self) -> PlaybackSettings:
        return PlaybackSettings(solver=self.solver, substeps=self.substeps)


@dataclasses.dataclass(frozen=True)
class CalibrateOptions:
    """[calibrate] (``jaxdse validate``): the events, the parameters and their bounds."""

    events: tuple[str, ...] = ()
    """More recordings of the same plants (same columns as [measurement]), paths relative to
    the file: all events are fitted jointly."""
    parameters: tuple[str, ...] = ()
    """PSS/E names of the parameters to rank and calibrate (e.g. ["H", "KA", "R"]); empty: H, D,
    the exciter's main gain and time constant, the governor's droop and main time constant."""
    bounds: dict = dataclasses.field(default_factory=dict)
    """{PSS/E name: [lower, upper]}: the engineer's bounds; others get the physical ones
    [x/4, 4x] (time constants and gains keep their sign) and D [0, 20]."""
    bound_factor: float = 4.0
    """Default bounds of a positive parameter: [x / factor, x * factor]."""
    max_relative_ci: float = 0.05
    """A parameter is calibrated only if the events fix it within this fraction (95 %
    Cramer-Rao half-width for the noise alone; a model's error comes on top)."""
    noise_floor_pu: float = 1e-3
    """Smallest noise level of P and Q assumed in the ranking [pu of MBASE]."""
    model_error: float = 0.01
    """Relative error of the .dyr playback against the plant [-], added in quadrature to each
    parameter's 95 % half-width (see ``jaxdse.CalibrationSettings``)."""
    input_filter_hz: float = 0.0
    """Inside the fit, low-pass the imposed |V| and angle at this cut-off [Hz] (zero phase,
    detected switching steps kept sharp; 0: off). Noise on the recorded voltage drives the
    model and biases the fit (H by 1.5-3 % on two ANDES units at 0.05 % TVE), which 5 Hz
    removes; but a voltage-angle jump that the step detector misses is smeared (npcc B21_G1:
    H -3 % noise-free), so it is off unless asked for. The before/after playbacks use the
    recorded voltage as it is."""

    def __post_init__(self):
        for k, b in self.bounds.items():
            if len(b) != 2 or not b[0] < b[1]:
                raise ValueError(f"bounds.{k} must be [lower, upper] with lower < upper, got {b}")
        if not 0 < self.max_relative_ci:
            raise ValueError("max_relative_ci must be > 0")
        if self.bound_factor <= 1:
            raise ValueError("bound_factor must be > 1")
        if not self.input_filter_hz >= 0:
            raise ValueError("input_filter_hz must be >= 0 (0: off)")


@dataclasses.dataclass
class PlantModel:
    """The .dyr models of one plant's units, or why the plant plays back the surrogate."""

    units: list[UnitModel]
    mbase_mva: np.ndarray
    share_p: np.ndarray
    share_q: np.ndarray
    fallback: str | None = None

    @property
    def models(self) -> list[dict]:
        return [u.models for u in self.units]

    @property
    def notes(self) -> list[str]:
        return [n for u in self.units for n in u.notes]


def _shares(x: np.ndarray, mbase: np.ndarray) -> np.ndarray:
    total = float(np.sum(x))
    if np.all(np.isfinite(x)) and abs(total) > 1e-3 * float(np.sum(mbase)):
        return x / total
    return mbase / np.sum(mbase)


def plant_model(raw, dyr, plant, options: PlaybackOptions = PlaybackOptions()) -> PlantModel:
    """The :class:`PlantModel` of a fleet plant (host side): its units' machine records, or an
    inverter-based plant's own records (:func:`~jaxdse._dyr.records.ibr_model`; without a model
    for each unit the plant is not played back, ``fallback`` says why)."""
    if plant.ibr:
        units = [ibr_model(dyr, plant.bus, m.id, raw) for m in plant.members]
        w_s = 2 * np.pi * raw.basfrq_hz
        for u in units:
            if isinstance(u.unit, GfmUnit):   # the converter holds its nominal frequency
                u.unit = eqx.tree_at(lambda x: x.converter.omega_s_rad_s, u.unit, jnp.asarray(w_s))
            elif u.unit is not None:
                u.unit = eqx.tree_at(lambda x: x.omega_s_rad_s, u.unit, jnp.asarray(w_s))
    else:
        units = [unit_model(dyr, raw, plant.bus, m.id, ke_zero=options.ke_zero) for m in plant.members]
    gens = [raw.generator(plant.bus, m.id) for m in plant.members]
    mbase = np.array([g.mbase_mva for g in gens])
    out = PlantModel(units, mbase, _shares(np.array([g.pg_mw for g in gens]), mbase),
                     _shares(np.array([g.qg_mvar for g in gens]), mbase))
    missing = [line for u in units for line in u.missing]
    if missing:
        out.fallback = ("not played back: " if plant.ibr else "surrogate played back: ") + "; ".join(missing)
    return out


def terminal_series(t_s, v_mag, v_ang, p, q, f_dev=None) -> TerminalSeries:
    """A TerminalSeries from |V|, its angle (nominal frame), P, Q out of the terminal and the
    recorded frequency deviation [pu] (None or NaN: none recorded; always an array here, so that
    the series of one fleet share a structure)."""
    v_mag, v_ang, p, q = (np.asarray(a, dtype=float) for a in (v_mag, v_ang, p, q))
    i = (p - 1j * q) * np.exp(1j * v_ang) / np.where(v_mag > 0, v_mag, 1.0)
    f_dev = np.full_like(v_mag, np.nan) if f_dev is None else np.asarray(f_dev, dtype=float)
    return TerminalSeries(*(jnp.asarray(a) for a in (t_s, v_mag, v_ang, i.real, i.imag, f_dev)))


class _Played(NamedTuple):
    """What a plant's playback takes from each unit's :class:`PlaybackResult` (host arrays)."""

    p_pu: np.ndarray
    q_pu: np.ndarray
    omega_pu: np.ndarray
    ok: np.ndarray
    fixed: np.ndarray
    """Frame intervals played at the fixed step (:class:`PlaybackSettings` ``fixed_substeps``)."""


def _batch(units, series, settings):
    """The units' playbacks (one program per structure and length; :mod:`programs`): vmapped,
    or with Kvaerno5 one unit after another (``lax.map``: each takes its own adaptive steps, and
    batching its nested Newton loops would double the tracing)."""
    if settings.solver == "kvaerno5":
        dyn, static = eqx.partition((units, series), eqx.is_array)
        r = jax.lax.map(lambda d: play_back(*eqx.combine(d, static), settings), dyn)
    else:
        r = eqx.filter_vmap(play_back, in_axes=(0, 0, None))(units, series, settings)
    return r.p_pu, r.q_pu, r.omega_pu, r.ok, r.fixed_step_intervals


def _operating_points(series, settings):
    """Each recording's initial operating point (as :func:`play_back` starts from it), flat:
    the UnitInputs' fields, I_re, I_im. One program per recording length, whatever the units'
    structures."""
    u0, i_re, i_im = eqx.filter_vmap(
        lambda s: initial_operating_point(steady_start(s, settings), settings))(series)
    return (*u0, i_re, i_im)


def _start(unit, u0, i_re, i_im):
    """d(vector field)/d(state) at the unit's initial state: its modes, computed on the host,
    tell whether the explicit step can follow it."""
    u0 = UnitInputs(*u0)
    y0, refs = unit.initial_state(u0, i_re, i_im)
    return jax.jacfwd(lambda y: unit.vector_field(y, u0, refs))(y0)


def _starts(units, u0, i_re, i_im):
    """The Jacobians of a group of one structure (a small program: the operating points, with
    their medians over the recording, come from :func:`_operating_points`; in one program with
    them, 8.4 s to compile for GENROU + IEEEX1 + IEEEST + IEEEG1 against 3.8 + 1.8 s apart, the
    1.8 s shared by every structure)."""
    return (eqx.filter_vmap(_start)(units, u0, i_re, i_im),)


CHUNK_UNITS = 8
"""Units per playback call at most: a structure's units beyond it run in chunks of this size
(the last padded: one program per structure). Under vmap an adaptive solve moves in lockstep
and a frame interval that one unit passes only at the fixed step costs every unit of its call
(Texas 7k: 87 type-3 wind plants in one call took 302 s of a 438 s warm run)."""

WAIT_BASE_S = 60.0
"""The wait on one call of the playback, once compiled: this much [s] ..."""
WAIT_PER_UNIT_FRAME_S = 2e-3
"""... plus this much per unit and frame [s]: generous (an adaptive playback takes a few steps
per frame; a stuck call is found out, not a slow one cut short)."""


def wait_limit_s(units: int, frames: int) -> float:
    """How long the playback waits for a call of ``units`` units of ``frames`` frames [s]."""
    return WAIT_BASE_S + WAIT_PER_UNIT_FRAME_S * units * frames


def _stack(trees):
    return jax.tree.map(lambda *x: jnp.stack(x), *trees)


def _icons(unit) -> tuple:
    """The unit's integer leaves (its records' ICONs, flags): units alike in them tend to take
    their steps alike, so they share a chunk."""
    return tuple(int(v) for x in jax.tree.leaves(unit)
                 if jnp.issubdtype(jnp.asarray(x).dtype, jnp.integer) for v in np.ravel(x))


def _chunks(items: list, size: int | None = None) -> list:
    """``items`` (of one structure) in chunks of at most ``size``, ordered by their ICONs, the
    last padded with its last item to ``size`` when there is more than one chunk; each chunk
    is (the items to stack, how many of them are real). ``size``: :data:`CHUNK_UNITS`."""
    size = CHUNK_UNITS if size is None else size
    if len(items) <= size:
        return [(items, len(items))]
    items = sorted(items, key=lambda it: _icons(it[2]))
    out = []
    for k in range(0, len(items), size):
        part = items[k:k + size]
        out.append((part + [part[-1]] * (size - len(part)), len(part)))
    return out


@dataclasses.dataclass
class PlantPlayback:
    """A plant's .dyr playback on the plant base (MBASE sum)."""

    p_pu: np.ndarray
    q_pu: np.ndarray
    x2_rad_s: np.ndarray
    """MBASE-weighted rotor speed deviation [rad/s]."""
    ok: bool
    notes: list = dataclasses.field(default_factory=list)
    """What the playback of the plant's units adds to their records' notes (a stiff unit
    integrated with Kvaerno5; a call that did not return within its limit)."""


@dataclasses.dataclass
class DyrOutcome:
    """A plant's .dyr playback, or why it played back the surrogate (``playback`` None)."""

    model: PlantModel
    playback: PlantPlayback | None

    def entry(self, surrogate_rms: dict) -> dict:
        """The fleet.json fields of the .dyr playback."""
        notes = self.model.notes + ([] if self.playback is None else self.playback.notes)
        out = {"playback_models": self.model.models, "playback_notes": notes,
               "surrogate_playback_rms_percent_mbase": surrogate_rms}
        if self.playback is None:
            out["playback_fallback"] = self.model.fallback
        elif not self.playback.ok and any(n.startswith("timed out") for n in self.playback.notes):
            out["playback_fallback"] = next(n for n in self.playback.notes if n.startswith("timed out"))
        elif not self.playback.ok:
            out["playback_fallback"] = ("the .dyr playback did not reach the end (solver failure "
                                        "or non-finite states)")
        return out


def play_back_plants(jobs: dict, options: PlaybackOptions) -> Iterator[tuple[str, PlantPlayback]]:
    """Play back every plant of ``jobs`` = {name: (PlantModel, TerminalSeries on the plant
    base)}; yields (name, PlantPlayback) as each plant's units are done. Units of one structure
    and length share a program; the calls trace, compile and run side by side on the cores (a call
    blocks its thread until its result is ready), the largest first, so that the caller's work
    on the plants done overlaps the calls still running; a structure with more than
    :data:`CHUNK_UNITS` units runs in calls of that many (one program). With ``solver = "tsit5"``, each unit's
    modes at its initial state are computed first (the Jacobians from one call per group, the
    eigenvalues on the host), and a unit the explicit step cannot follow is played back with
    Kvaerno5 (noted). Every wait is bounded (:func:`wait_limit_s`): a call that does not return
    in time leaves its units not ``ok``, the reason in the plant's notes."""
    flat = []
    for name, (pm, series) in jobs.items():
        m_total = float(np.sum(pm.mbase_mva))
        vr = np.asarray(series.v_mag_pu) * np.cos(np.asarray(series.v_ang_rad))
        vi = np.asarray(series.v_mag_pu) * np.sin(np.asarray(series.v_ang_rad))
        p = vr * np.asarray(series.i_re_pu) + vi * np.asarray(series.i_im_pu)
        q = vi * np.asarray(series.i_re_pu) - vr * np.asarray(series.i_im_pu)
        for k, um in enumerate(pm.units):
            scale = m_total / pm.mbase_mva[k]
            s = terminal_series(series.t_s, series.v_mag_pu, series.v_ang_rad,
                                p * pm.share_p[k] * scale, q * pm.share_q[k] * scale, series.f_dev_pu)
            flat.append((name, k, um.unit, s))
    in_threads = _same_context_in_threads()

    def grouped(items, key=lambda it: ()):
        groups: dict = {}
        for it in items:
            groups.setdefault((jax.tree_util.tree_structure(it[2]), int(it[3].t_s.shape[0]), key(it)),
                              []).append(it)
        return sorted(groups.values(), key=len, reverse=True)

    def label(items, settings):
        return (f"the .dyr playback of {len(items)} unit(s) of {int(items[0][3].t_s.shape[0])} frames "
                f"({settings.solver}; plants {', '.join(dict.fromkeys(it[0] for it in items))})")

    settings = options.settings
    notes: dict = {name: [] for name in jobs}
    stiff = set()
    if settings.solver == "tsit5":
        # each unit's modes at its initial state (Jacobians from the compiled call, eigenvalues
        # here): a unit the explicit step cannot follow is played back with Kvaerno5
        lengths: dict = {}
        for it in flat:
            lengths.setdefault(int(it[3].t_s.shape[0]), []).append(it)
        lengths = list(lengths.values())
        tasks = [Task(f"the initial operating points of {len(items)} recording(s) of "
                      f"{int(items[0][3].t_s.shape[0])} frames",
                      wait_limit_s(len(items), int(items[0][3].t_s.shape[0])),
                      lambda items=items: programs.call("_operating_points", _operating_points,
                                                        _stack([it[3] for it in items]), settings),
                      COMPILE_LIMIT_S) for items in lengths]
        start = {}
        for i, ops in bounded(tasks, threads(len(lengths)), threads=in_threads):
            if isinstance(ops, Expired):
                continue   # the playback itself is bounded and marked below
            ops = jax.device_get(ops)
            for j, it in enumerate(lengths[i]):
                start[(it[0], it[1])] = (tuple(a[j] for a in ops[:-2]), ops[-2][j], ops[-1][j])
        order = [[it for it in items if (it[0], it[1]) in start] for items in grouped(flat)]
        order = [items for items in order if items]
        tasks = [Task(label(items, settings) + ": its initial state",
                      wait_limit_s(len(items), 1),
                      lambda items=items: programs.call(
                          "_starts", _starts, _stack([it[2] for it in items]),
                          *(_stack([start[(it[0], it[1])][c] for it in items]) for c in range(3)))[0],
                      COMPILE_LIMIT_S) for items in order]
        for i, jac in bounded(tasks, threads(len(order)), threads=in_threads):
            if isinstance(jac, Expired):
                continue   # the playback itself is bounded and marked below
            jac = np.asarray(jax.device_get(jac))
            for j, (name, k, unit, series) in enumerate(order[i]):
                fastest = modes(jac[j])[1]
                dt = float(series.t_s[1] - series.t_s[0])
                if too_stiff(fastest, dt / settings.substeps):
                    stiff.add((name, k))
                    models = jobs[name][0].units[k].models
                    notes[name].append(f"unit {k + 1} ({models.get('machine', models.get('converter'))}): "
                                       + stiff_note(fastest, dt / settings.substeps, "Tsit5"))
    implicit = dataclasses.replace(options, solver="kvaerno5").settings
    calls = [c for items in grouped(flat, key=lambda it: (it[0], it[1]) in stiff) for c in _chunks(items)]
    order = [items[:n] for items, n in calls]

    def run(items):
        how = implicit if (items[0][0], items[0][1]) in stiff else settings
        units, series = _stack([it[2] for it in items]), _stack([it[3] for it in items])
        return _Played(*jax.device_get(programs.call("_batch", _batch, units, series, how)))

    tasks = [Task(label(items[:n], implicit if (items[0][0], items[0][1]) in stiff else settings),
                  wait_limit_s(len(items), int(items[0][3].t_s.shape[0])), lambda items=items: run(items),
                  COMPILE_LIMIT_S) for items, n in calls]
    results: dict = {}
    left = {name: len(pm.units) for name, (pm, _) in jobs.items()}
    for i, res in bounded(tasks, threads(len(order)), threads=in_threads):
        for j, (name, k, _, series) in enumerate(order[i]):
            if isinstance(res, Expired):
                nan = np.full(np.shape(series.t_s), np.nan)
                results[(name, k)] = _Played(nan, nan, nan, np.asarray(False), np.asarray(0))
                notes[name].append(f"unit {k + 1}: {res.reason}")
            else:
                results[(name, k)] = played = jax.tree.map(lambda a, j=j: a[j], res)
                if int(played.fixed) > 0:
                    notes[name].append(_fixed_step_note(k, jobs[name][0].units[k].models,
                                                       int(played.fixed), settings.fixed_substeps))
            left[name] -= 1
            if not left[name]:
                pm = jobs[name][0]
                pb = _plant_playback(pm, [results.pop((name, i)) for i in range(len(pm.units))])
                pb.notes = notes[name]
                yield name, pb


def _fixed_step_note(k: int, models: dict, intervals: int, substeps: int) -> str:
    """The note of a unit whose playback took the fixed step over ``intervals`` frame intervals."""
    name = models.get("machine", models.get("converter"))
    return (f"unit {k + 1} ({name}): {intervals} frame interval(s) played at a fixed step of "
            f"1/{substeps} frame, where the adaptive step could not pass a limit that switches at "
            f"every step (a PI sliding along its non-windup limit)")


def _plant_playback(pm: PlantModel, rs: list) -> PlantPlayback:
    """The plant's playback: its units' (:class:`_Played`) MBASE-weighted sum."""
    w = pm.mbase_mva / np.sum(pm.mbase_mva)
    unit = pm.units[0].unit
    omega_s = float(unit.machine.omega_s_rad_s if hasattr(unit, "machine") else unit.omega_s_rad_s)
    return PlantPlayback(p_pu=sum(wk * r.p_pu for wk, r in zip(w, rs)),
                         q_pu=sum(wk * r.q_pu for wk, r in zip(w, rs)),
                         x2_rad_s=sum(wk * (r.omega_pu - 1.0) for wk, r in zip(w, rs)) * omega_s,
                         ok=all(bool(r.ok) for r in rs))


__all__ = ["PLAYBACK_MODELS", "SIMULATED_RECORDS", "CalibrateOptions", "DyrOutcome", "PlantModel",
           "PlantPlayback", "PlaybackOptions", "plant_model", "play_back_plants", "terminal_series"]
