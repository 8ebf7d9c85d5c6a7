"""``jaxdse check CASE.toml``: the no-disturbance check of every unit of a PSS/E case (synchronous
machines here; inverter-based plants in :mod:`jaxdse._app.check_ibr`).

Every in-service generator of the .raw with a machine record in the .dyr (a synchronous unit)
gets its own :class:`~jaxdse._dyr.unit.DyrUnit` from its records (machine, exciter, stabiliser,
governor), is initialised from the power flow at its terminal (the .raw PG and QG on MBASE, the
bus voltage VM and VA) and is simulated twice with the terminal voltage imposed, as the .dyr
playback imposes a recording (PSS/E PLBVFU1):

* **held** -- the voltage held for :attr:`CheckSpec.end_s`: every state derivative at t = 0
  below ``max_derivative`` (pu/s, rad/s) and P, Q at ``held_s`` within ``max_pq_error`` of the
  power flow;
* **step** -- the voltage magnitude stepped by ``step`` (2 %) at ``step_at_s``, the voltage
  reference Vref moved with it (Vref + 2 % of the initial |V|). The imposed terminal voltage
  leaves every voltage regulator's loop open; with Vref held, a regulator with integral action
  would integrate the 2 % error until its limit and the unit would slip poles (seen on
  ACTIVSg2000's ESST4B and EXPIC1 units): an artefact of the imposed voltage, not of the data.
  Moving Vref with the voltage makes the step a new operating point every regulator can hold,
  and exercises the machine, the stabiliser (through the exciter) and the governor. The unit
  must stay **bounded** (the solver reaches the end with finite states, the speed within
  ``max_speed_dev`` of nominal, the rotor angle within ``max_angle_swing_rad`` of where it
  started: no pole slipped) and be **settled** at the end (:attr:`CheckSpec.end_s`, 20 s after
  the step): over the last ``settle_window_s`` (5 s), P and Q each stay within a band of their
  final value, the band being ``settle_fraction`` (10 %) of the range that quantity spans
  after the step, but at least ``settle_floor_pu`` (0.001 pu); the speed within
  ``settle_speed_pu`` of nominal; every state derivative at the end below
  ``settle_derivative``. The largest real part of the eigenvalues of the unit linearised at the
  end is reported beside (``step_growth_rate_end_per_s``: the time constant of the slowest mode
  left, or the rate of a growing one) but does not decide: with the regulator's loop open, an
  exciter whose field integrates (a DC exciter with KE = 0 read literally) is neutral, and
  grows or decays at a few 0.01/s, which says nothing about the data.

  Why this band, and why not a grid behind a reactance: with the terminal voltage imposed the
  regulator cannot act on the field, and a machine at constant field voltage has a slow field
  mode (time constants of ~10 s on ACTIVSg2000's GENROU units, from the eigenvalues of the
  linearised unit: a real mode, not an oscillation) that a 2 % band would call unsettled at
  20 s. Closing the loop through an infinite bus behind a reactance Xe was tried: its verdicts
  depend on Xe (WECC bench units whose stabiliser destabilises the exciter mode at Xe = 0.2 pu
  settle at 0.5 pu and others the other way round), so the check keeps the playback's
  convention, where the verdict depends on the unit's records alone.

Every generator record of the .raw is accounted for (:func:`accounting`, from
:func:`~jaxdse._dyr.inventory.inventory`): the units (a machine record; records of a model
jaxdse does not know, ``not supported`` naming it; exciter, stabiliser or governor records
without a machine record, a ``data problem``) and, each with its reason, those not checked
(out of service, no dynamic records, not a generator: SVC/STATCOM,
duplicated); the .dyr records of no generator are listed (orphaned, bus level).

Outcome per unit: ``"pass"``; ``"data problem"`` (a record jaxdse simulates but whose values
cannot be simulated -- an inverted limit, a negative time constant, both named by the model's
own checks -- or whose initial operating point lies outside a limit of the record, found by
evaluating the initial state against the limits, :mod:`jaxdse._dyr.limits`: the record, the
signal with its value and the CON with its value are named); ``"not supported"`` (a record of a
model jaxdse does not simulate, named); ``"fail"`` (every record simulated and every value
check passed, but the unit does not start steady or does not settle: the reasons give the
numbers; a model limitation, an unstable tuning, or a jaxdse bug). Units of one model
structure run in one vmapped, jitted call, with no LAPACK call inside (the modes are taken on
the host); a unit whose fastest mode at rest the fixed explicit step cannot follow is run again
with Kvaerno5 and noted (:mod:`jaxdse._dyr.stiff`), so a stiff record is never a data problem.
Every wait on a group is bounded (:mod:`jaxdse._many.waits`). With ``repair``, each data
problem that is a crossed limit gets the smallest change of its CON (:mod:`jaxdse._dyr.repair`,
written out by :mod:`jaxdse._app.repair`).
"""

from __future__ import annotations

import dataclasses
import html
import json
import math
import time
from collections import Counter
from collections.abc import Callable, Collection
from pathlib import Path
from typing import NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._dyr.gfm_unit import GfmUnit
from .._dyr.ibr_unit import IbrUnit
from .._dyr.inventory import GENERATOR_CATEGORIES, Inventory, inventory
from .._dyr.limits import Start, describe, exciter_crossings, governor_crossings, rating_crossings
from .._dyr.records import UnitModel, record_kind, unit_model
from .._dyr.stiff import EXPLICIT_LIMIT, kvaerno5, modes, stiff_note, too_stiff
from .._dyr.unit import DyrUnit, UnitInputs
from .._io.errors import InputError
from .._io.psse import (
    GOVERNOR_FIELDS,
    MACHINE_FIELDS,
    DyrData,
    DyrRecord,
    RawCase,
    RawGenerator,
    machine_warnings,
    merge_dyr,
    read_dyr,
    read_raw,
    record_label,
)
from .._io.schema import build, no_unknown, options, read_toml, subtable
from .._many.runner import _same_context_in_threads, threads
from .._many.waits import COMPILE_LIMIT_S, Expired, Task, bounded, executing
from .._models.exciters import EXCITERS
from .._models.governors import GOVERNORS
from .._models.machines import MACHINES
from .._models.stabilisers import STABILISERS
from .._version import __version__
from . import check_ibr
from .dyr_fleet import PlaybackOptions
from .fleet_file import TOP
from .progress import Progress
from .repair import attach_carried, repair_console, repair_html, write_repair

INVERTER_UNITS = (IbrUnit, GfmUnit)
"""The units checked as inverter-based plants (held, voltage step, frequency step)."""

OUTCOMES = ("pass", "data problem", "not supported", "fail")
"""The outcomes of a unit, in the order of the summary."""
KINDS = ("machine", "exciter", "stabiliser", "governor")
OUTCOME_COLOURS = {"pass": "#1a9850", "data problem": "#d73027", "not supported": "#7f7f7f",
                   "fail": "#fdae61"}


@dataclasses.dataclass(frozen=True)
class CheckSpec:
    """The runs of the check and what passes (documented in the module docstring)."""

    frame_hz: float = 30.0
    """Output frames per second; the fixed integration step is 1/(frame_hz · substeps)."""
    end_s: float = 21.0
    """Length of both runs [s]."""
    held_s: float = 20.0
    """P and Q of the held run are compared with the power flow at this time [s]."""
    step_at_s: float = 1.0
    """Time of the voltage step [s]."""
    step: float = 0.02
    """The voltage step, a fraction of the initial |V| (Vref moves by the same amount)."""
    max_derivative: float = 1e-6
    """Largest |d(state)/dt| at t = 0 [pu/s or rad/s]."""
    max_pq_error: float = 1e-5
    """Largest |P - P0|, |Q - Q0| of the held run at ``held_s`` [pu on MBASE]."""
    max_speed_dev: float = 0.05
    """Bounded: |speed - 1| at most this [pu] throughout the step run."""
    max_angle_swing_rad: float = math.pi
    """Bounded: the rotor angle within this of its initial value [rad] (no pole slipped)."""
    settle_window_s: float = 5.0
    """Settled: judged over the last stretch of the step run [s]."""
    settle_fraction: float = 0.1
    """Settled: band of P and Q around their final value, a fraction of the range each spans
    after the step."""
    settle_floor_pu: float = 1e-3
    """Settled: the band is at least this [pu on MBASE]."""
    settle_speed_pu: float = 1e-4
    """Settled: |speed - 1| at most this over the window [pu]."""
    settle_derivative: float = 1e-2
    """Settled: every |d(state)/dt| at the end at most this [pu/s or rad/s]."""


SPEC = CheckSpec()


# --- the case file --------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class CaseFile:
    """A case file: the PSS/E case of a fleet file's [case], and its [playback] options."""

    path: Path
    raw: RawCase
    dyr: DyrData
    playback: PlaybackOptions = PlaybackOptions()


def load_case(path) -> CaseFile:
    """Read a case file: [case] raw, dyr (a path or a list of paths, relative to the file);
    optionally [playback] solver, substeps, ke_zero. The other sections of a fleet file are
    allowed and not read (a fleet file serves as it is)."""
    path = Path(path)
    data = read_toml(path)
    if "case" not in data:
        raise InputError(path, "no [case] naming the PSS/E .raw and .dyr: add [case] raw = "
                         "\"case.raw\", dyr = \"case.dyr\"", key="case")
    no_unknown(path, data, TOP, "")
    case = subtable(path, data, "case", "case")
    no_unknown(path, case, {"raw", "dyr", "q_axis_circuits"}, "case.")
    files = {}
    for k in ("raw", "dyr"):
        value = case.get(k)
        names = value if k == "dyr" and isinstance(value, list) and value else [value]
        if not all(isinstance(n, str) and n for n in names):
            raise InputError(path, f"the PSS/E .{k} file is required (a path, relative to this file"
                             + ("; or a list of .dyr files, later records replacing earlier ones"
                                if k == "dyr" else "") + ")", key=f"case.{k}")
        files[k] = [Path(n) if Path(n).is_absolute() else path.parent / n for n in names]
        for f in files[k]:
            if not f.is_file():
                raise InputError(path, f"no such file: {f}", key=f"case.{k}")
    raw = read_raw(files["raw"][0], strict=False)
    dyr = merge_dyr(*(read_dyr(f, strict=False) for f in files["dyr"]))
    playback = build(path, PlaybackOptions, options(
        path, PlaybackOptions, subtable(path, data, "playback", "playback"), "playback.", minimum=1),
        "playback")
    return CaseFile(path=path, raw=raw, dyr=dyr, playback=playback)


# --- the units and their records --------------------------------------------------------------------

def synchronous_units(raw: RawCase, dyr: DyrData, *, out_of_service: bool = False
                      ) -> tuple[list[RawGenerator], int]:
    """The units of the check, in .raw order (the first of duplicated records): the in-service
    generators with a machine record, or with .dyr records of a machine model jaxdse does not
    know, or with exciter/stabiliser/governor records and no machine record (the categories
    ``UNIT_CATEGORIES`` of :func:`~jaxdse._dyr.inventory.inventory`); with ``out_of_service``
    those out of service with a machine record too. And the number of those out of service with
    a machine record."""
    inv = inventory(raw, dyr)
    return ([a.generator for a in inv.units(out_of_service=out_of_service)],
            inv.summary()["out_of_service_with_machine_record"])


def _simulated(kind: str, model: str) -> bool:
    if kind == "machine":
        return model in MACHINES and model in MACHINE_FIELDS
    if kind == "exciter":
        return model in EXCITERS
    if kind == "stabiliser":
        return model in STABILISERS
    if kind == "governor":
        return model in GOVERNORS and model in GOVERNOR_FIELDS
    return False


class _Static(NamedTuple):
    models: dict
    records: dict
    unsupported: list
    problems: list
    """(model of the record at fault or None, line), each line naming the record."""
    model: UnitModel
    warnings: list
    """Odd machine values used as given (:func:`machine_warnings`): a data problem where the
    unit then fails, a note where it passes."""


def _static(raw: RawCase, dyr: DyrData, g: RawGenerator, ke_zero: str) -> _Static:
    """The unit's records by kind, the ones jaxdse does not simulate, and the value problems
    that its models' own checks find (one line each, naming the record)."""
    recs = dyr.unit_records(g.bus, g.id)
    models: dict = dict.fromkeys(KINDS)
    records: dict = {}
    unsupported, skip = [], set()
    no_machine = not any(record_kind(r) == "machine" for r in recs)
    for r in recs:
        kind = record_kind(r)
        if kind in records:
            continue
        if kind != "other":
            records[kind], models[kind] = r, r.model
        if not _simulated(kind, r.model):
            skip.add(record_label(r))
            if kind == "other" and no_machine:
                unsupported.append((r.model, f"{record_label(r)}: model {r.model} is unknown to jaxdse "
                                             "(not a machine, exciter, stabiliser or governor model it "
                                             "knows), and the generator has no machine record it knows"))
                continue
            what = kind if kind != "other" else "record (not a machine, exciter, stabiliser or governor)"
            unsupported.append((r.model, f"{record_label(r)}: {what} model {r.model} is not simulated "
                                         "by jaxdse"))
    um = unit_model(dyr, raw, g.bus, g.id, ke_zero=ke_zero)
    problems = []
    for line in um.missing:
        if line.endswith(": no machine record"):
            if not unsupported:   # an unknown model already says so
                has = ", ".join(f"{r.model} (line {r.line})" for r in recs)
                problems.append(("no machine record", f"{line} (its records: {has})"))
            continue
        if not any(line.startswith(s) for s in skip):
            at = [r.model for r in recs if line.startswith(record_label(r))]
            problems.append((at[0] if at else None, line))
    if g.problem:
        problems.append(("generator", g.problem))
    for name, value in (("MBASE", g.mbase_mva), ("PG", g.pg_mw), ("QG", g.qg_mvar)):
        if not (math.isfinite(value) and (value > 0 or name != "MBASE")):
            must = " must be > 0" if name == "MBASE" else ""
            problems.append(("generator", f"generator on bus {g.bus} id {g.id!r} ({Path(raw.source).name} "
                             f"line {g.line}): {name} = {value:g}{must}"))
    bus = raw.buses.get(g.bus)
    if bus is None or bus.problem or not (math.isfinite(bus.vm_pu) and bus.vm_pu > 0):
        problems.append(("bus", f"bus {g.bus} of the generator: no usable voltage VM in "
                         f"{Path(raw.source).name}"))
    warnings = machine_warnings(records["machine"]) if "machine" in records else []
    return _Static(models, records, unsupported, problems, um, warnings)


# --- the runs ---------------------------------------------------------------------------------------

class _Run(eqx.Module):
    """How the runs are integrated (static: one compiled function per setting)."""

    solver: str = eqx.field(static=True, default="tsit5")
    substeps: int = eqx.field(static=True, default=4)
    frame_hz: float = eqx.field(static=True, default=30.0)
    end_s: float = eqx.field(static=True, default=21.0)
    step_at_s: float = eqx.field(static=True, default=1.0)


class _Lane(NamedTuple):
    """One run of one unit: the power flow at its terminal and the voltage step (0: held)."""

    v_re: jax.Array
    v_im: jax.Array
    i_re: jax.Array
    i_im: jax.Array
    step: jax.Array


class _Result(NamedTuple):
    dy0: jax.Array
    y0: jax.Array
    efd_ref: jax.Array
    tm_ref: jax.Array
    vref: jax.Array
    efd_t0: jax.Array
    tm_t0: jax.Array
    ifd_t0: jax.Array
    p: jax.Array
    q: jax.Array
    omega: jax.Array
    delta: jax.Array
    dy_end: jax.Array
    jac_t0: jax.Array
    """d(vector field)/d(state) at the initial state, held input (the modes: on the host)."""
    jac_end: jax.Array
    """... at the end of the run."""
    ok: jax.Array


def _one(unit: DyrUnit, lane: _Lane, run: _Run) -> _Result:
    zero = jnp.zeros_like(lane.v_re)
    u0 = UnitInputs(lane.v_re, lane.v_im, zero, zero)
    y0, refs = unit.initial_state(u0, lane.i_re, lane.i_im)
    dy0 = unit.vector_field(y0, u0, refs)
    jac0 = jax.jacfwd(lambda y: unit.vector_field(y, u0, refs))(y0)
    out0, efd_t0, tm_t0, _ = unit.signals(y0, u0, refs)
    v0 = jnp.hypot(lane.v_re, lane.v_im)

    def at(t):  # the step just after step_at_s (left-continuous at the step boundary)
        on = t > run.step_at_s
        k = 1.0 + jnp.where(on, lane.step, 0.0)
        return (UnitInputs(lane.v_re * k, lane.v_im * k, zero, zero),
                refs._replace(vref_pu=refs.vref_pu + jnp.where(on, lane.step * v0, 0.0)))

    def rhs(t, y, args):
        return unit.vector_field(y, *at(t))

    n = int(round(run.end_s * run.frame_hz)) + 1
    ts = np.arange(n) / run.frame_hz
    ys, solved = _integrate(rhs, y0, run, n)

    def outputs(t, y):
        out, _, _, _ = unit.signals(y, *at(t))
        return out.p_pu, out.q_pu

    p, q = jax.vmap(outputs)(jnp.asarray(ts), ys)
    m = unit.machine.n_states
    ok = solved & jnp.all(jnp.isfinite(ys))
    y_end = jnp.where(ok, ys[-1], y0)
    dy_end = rhs(run.end_s, y_end, None)
    jac_end = jax.jacfwd(lambda y: rhs(run.end_s, y, None))(y_end)
    return _Result(dy0, y0, refs.efd0_pu, refs.tm0_pu, refs.vref_pu, efd_t0, tm_t0, out0.ifd_pu,
                   p, q, ys[:, m - 1], ys[:, m - 2], dy_end, jac0, jac_end, ok)


def _integrate(rhs, y0, run: _Run, n: int):
    """(states at the ``n`` frames, solved): Tsit5 at ``substeps`` fixed steps per frame as a
    plain scan of the solver's steps (diffeqsolve's SaveAt(ts=...) brings a runtime check, a
    host callback that keeps the executable out of JAX's persistent compilation cache), or
    Kvaerno5 with an adaptive step through diffeqsolve (its Newton solves without LAPACK:
    :func:`~jaxdse._dyr.stiff.kvaerno5`)."""
    term = diffrax.ODETerm(rhs)
    if run.solver == "tsit5":
        solver = diffrax.Tsit5()
        h = 1.0 / (run.frame_hz * run.substeps)

        def frame(carry, k):
            def sub(c, j):
                y, st = c
                t = (k * run.substeps + j) * h
                y, _, _, st, _ = solver.step(term, t, t + h, y, None, st, made_jump=False)
                return (y, st), None

            carry, _ = jax.lax.scan(sub, carry, jnp.arange(run.substeps))
            return carry, carry[0]

        _, ys = jax.lax.scan(frame, (y0, solver.init(term, 0.0, h, y0, None)), jnp.arange(n - 1))
        return jnp.concatenate([y0[None], ys]), jnp.asarray(True)
    sol = diffrax.diffeqsolve(term, kvaerno5(), 0.0, run.end_s, 1.0 / run.frame_hz, y0,
                              saveat=diffrax.SaveAt(ts=np.arange(n) / run.frame_hz),
                              stepsize_controller=diffrax.PIDController(rtol=1e-7, atol=1e-9,
                                                                        jump_ts=[run.step_at_s]),
                              max_steps=64 * n, throw=False, adjoint=diffrax.ForwardMode())
    return sol.ys, sol.result == diffrax.RESULTS.successful


def _batch_fn():
    from .._many.runner import COMPILER_OPTIONS

    vm = eqx.filter_vmap(_one, in_axes=(0, 0, None))
    if jax.default_backend() == "cpu" and not jax.config.read("jax_disable_most_optimizations"):
        return eqx.filter_jit(vm, compiler_options=COMPILER_OPTIONS)
    return eqx.filter_jit(vm)


_BATCH: list = []


def _batch_jit():
    """The jitted vmapped :func:`_one` (made once)."""
    if not _BATCH:
        _BATCH.append(_batch_fn())
    return _BATCH[0]


def _mapped(units, lanes, run: _Run) -> _Result:
    """:func:`_one` over the leading axis, one unit after another (``lax.map``): for Kvaerno5,
    whose nested Newton loops cost twice the tracing when batched, and whose adaptive steps are
    each unit's own."""
    dyn, static = eqx.partition((units, lanes), eqx.is_array)
    return jax.lax.map(lambda d: _one(*eqx.combine(d, static), run), dyn)


_MAPPED = eqx.filter_jit(_mapped)


def _stack(trees):
    return jax.tree.map(lambda *x: jnp.stack(x), *trees)


def _lane(raw: RawCase, g: RawGenerator, step: float) -> _Lane:
    b = raw.buses[g.bus]
    v = b.vm_pu * complex(math.cos(math.radians(b.va_deg)), math.sin(math.radians(b.va_deg)))
    i = ((g.pg_mw + 1j * g.qg_mvar) / g.mbase_mva / v).conjugate()
    return _Lane(*(jnp.asarray(float(x)) for x in (v.real, v.imag, i.real, i.imag, step)))


# --- judging one unit -------------------------------------------------------------------------------

def _g(x: float) -> str:
    return f"{x:.4g}"


def _state_name(unit: DyrUnit, models: dict, k: int) -> str:
    """'GENROU speed', 'ESST4B state 3', ... for index ``k`` of the flat state."""
    start = 0
    for kind, n in zip(KINDS, unit.sizes):
        if k < start + n:
            j = k - start
            if kind == "machine" and j == n - 1:
                return f"{models[kind]} speed"
            if kind == "machine" and j == n - 2:
                return f"{models[kind]} rotor angle"
            return f"{models[kind]} state {j + 1} of {n}"
        start += n
    return f"state {k}"


def _at(r: _Result, j: int) -> dict:
    """Lane ``j`` of ``r`` (host arrays), with its modes computed from the Jacobians (host NumPy,
    :func:`~jaxdse._dyr.stiff.modes`): ``growth_end``, ``fastest_end`` (at the end of the run)
    and ``fastest_t0`` (at the initial state)."""
    out = {f: np.asarray(getattr(r, f)[j]) for f in r._fields}
    out["growth_end"], out["fastest_end"] = modes(out["jac_end"])
    out["fastest_t0"] = modes(out["jac_t0"])[1]
    return out


def _limit(rec: DyrRecord, c) -> dict:
    """A limit crossed at the initial state, for check.json."""
    return {"record": rec.model, "line": rec.line, "signal": c.signal, "value": c.value, "con": c.con,
            "bound": c.bound, "side": c.side, "context": c.context,
            "fix": None if c.fix is None else c.fix._asdict()}


def _stiff(r: dict, spec: CheckSpec, solver: tuple[str, float]) -> str:
    """A hint when the unit's fastest mode is too fast for the explicit fixed step."""
    fastest = float(r["fastest_end"])
    name, h = solver
    if name == "tsit5" and math.isfinite(fastest) and -fastest * h > EXPLICIT_LIMIT:
        return (f": its fastest mode ({fastest:.4g} 1/s at the initial state) needs a step below "
                f"{EXPLICIT_LIMIT / -fastest:.3g} s and the fixed step is {h:.3g} s (more substeps, or "
                'solver = "kvaerno5", in [playback])')
    return ""


def _judge(st: _Static, g: RawGenerator, raw: RawCase, held: dict, step: dict, spec: CheckSpec,
           solver: tuple[str, float] = ("tsit5", 1.0 / 120.0)) -> tuple[str, list[str], dict, list]:
    """(outcome, reasons, numbers, limits crossed) of a unit that was simulated; ``solver``:
    (name, fixed step)."""
    unit = st.model.unit
    models, recs = st.models, st.records
    start = Start(efd0=float(held["efd_ref"]), tm0=float(held["tm_ref"]),
                  vt=raw.buses[g.bus].vm_pu, ifd=float(held["ifd_t0"]), vref=float(held["vref"]))
    y_m, y_e, _, _ = unit.split(held["y0"])
    where = (f"PG = {g.pg_mw:g} MW, QG = {g.qg_mvar:g} Mvar on MBASE = {g.mbase_mva:g} MVA, "
             f"VT = {start.vt:.4g} pu")
    data, limits = [], []
    for c in rating_crossings(g.pg_mw, g.qg_mvar, g.mbase_mva):
        data.append(f"generator on bus {g.bus} id {g.id.strip()!r} ({Path(raw.source).name} line {g.line}): "
                    f"{describe(c)}: the power flow lies outside the capability of MBASE, the rating its "
                    "dynamic records are per unit of")
        limits.append({"record": "generator", "file": Path(raw.source).name, "line": g.line,
                       "signal": c.signal, "value": c.value, "con": c.con, "bound": c.bound,
                       "side": c.side, "context": c.context, "fix": c.fix._asdict()})
    if unit.exciter is not None:
        for c in exciter_crossings(models["exciter"], unit.exciter, y_e, start):
            data.append(f"{record_label(recs['exciter'])}: {describe(c)}: the initial field voltage "
                        f"EFD0 = {_g(start.efd0)} pu ({where}) needs a signal outside the record's limit")
            limits.append(_limit(recs["exciter"], c))
    if unit.governor is not None:
        for c in governor_crossings(models["governor"], unit.governor, start):
            data.append(f"{record_label(recs['governor'])}: {describe(c)}: the initial mechanical "
                        f"torque TM0 = PG/MBASE = {_g(start.tm0)} pu ({where}) needs a signal outside "
                        "the record's limit")
            limits.append(_limit(recs["governor"], c))
    t = np.arange(len(step["p"])) / spec.frame_hz
    dy0 = np.abs(held["dy0"])
    k0 = int(np.argmax(dy0)) if dy0.size else 0
    p0, q0 = g.pg_mw / g.mbase_mva, g.qg_mvar / g.mbase_mva
    kh = int(round(spec.held_s * spec.frame_hz))
    numbers = {"max_dxdt_t0": float(np.max(dy0)) if dy0.size else 0.0,
               "max_dxdt_t0_state": _state_name(unit, models, k0),
               "efd0_pu": start.efd0, "tm0_pu": start.tm0, "vref_pu": start.vref,
               "efd_error_t0_pu": float(held["efd_t0"] - held["efd_ref"]),
               "tm_error_t0_pu": float(held["tm_t0"] - held["tm_ref"]),
               "p_error_held_pu": float(held["p"][kh] - p0), "q_error_held_pu": float(held["q"][kh] - q0)}
    fails = []
    if not (numbers["max_dxdt_t0"] < spec.max_derivative):
        fails.append(f"not steady at t = 0: |d(state)/dt| = {numbers['max_dxdt_t0']:.3g} "
                     f"({numbers['max_dxdt_t0_state']}) above {spec.max_derivative:g}")
    if unit.exciter is not None and not abs(numbers["efd_error_t0_pu"]) < spec.max_derivative:
        fails.append(f"{record_label(recs['exciter'])}: gives EFD = {_g(float(held['efd_t0']))} at the "
                     f"initial state, not EFD0 = {_g(start.efd0)} pu: a limit binds")
    if unit.governor is not None and not abs(numbers["tm_error_t0_pu"]) < spec.max_derivative:
        fails.append(f"{record_label(recs['governor'])}: gives TM = {_g(float(held['tm_t0']))} at the "
                     f"initial state, not TM0 = {_g(start.tm0)} pu: a limit binds")
    if not bool(held["ok"]):
        fails.append("held run: the solver did not reach the end (or states became non-finite)"
                     + _stiff(held, spec, solver))
    elif not (abs(numbers["p_error_held_pu"]) < spec.max_pq_error and
              abs(numbers["q_error_held_pu"]) < spec.max_pq_error):
        fails.append(f"held run: P, Q at {spec.held_s:g} s differ from the power flow by "
                     f"{numbers['p_error_held_pu']:.3g}, {numbers['q_error_held_pu']:.3g} pu "
                     f"(limit {spec.max_pq_error:g})")
    if data:
        return "data problem", data + [f"hence: {f}" for f in fails], numbers, limits
    if fails:
        return "fail", fails, numbers, []
    # the step
    p, q, w, d = (np.asarray(step[k], float) for k in ("p", "q", "omega", "delta"))
    after = t > spec.step_at_s
    swing = float(np.max(np.abs(d - d[0]))) if np.all(np.isfinite(d)) else math.inf
    speed = float(np.max(np.abs(w - 1.0))) if np.all(np.isfinite(w)) else math.inf
    numbers.update(step_max_speed_dev_pu=speed, step_max_angle_swing_rad=swing)
    if not bool(step["ok"]):
        return "fail", [f"the {100 * spec.step:g} % step: the solver did not reach the end (or "
                        "states became non-finite)" + _stiff(held, spec, solver)], numbers, []
    if speed > spec.max_speed_dev or swing > spec.max_angle_swing_rad:
        return "fail", [f"the {100 * spec.step:g} % step: not bounded: speed deviation up to "
                        f"{speed:.3g} pu (limit {spec.max_speed_dev:g}), rotor angle moved up to "
                        f"{swing:.3g} rad (limit {spec.max_angle_swing_rad:.3g}: a pole slipped)"], \
            numbers, []
    win = t >= t[-1] - spec.settle_window_s - 1e-9
    why = []
    for name, x in (("P", p), ("Q", q)):
        seen = np.concatenate([x[:1], x[after]])
        span = float(np.max(seen) - np.min(seen))
        band = max(spec.settle_fraction * span, spec.settle_floor_pu)
        spread = float(np.max(np.abs(x[win] - x[-1])))
        numbers[f"step_{name.lower()}_range_pu"] = span
        numbers[f"step_{name.lower()}_final_spread_pu"] = spread
        numbers[f"step_{name.lower()}_change_pu"] = float(x[-1] - x[0])
        if spread > band:
            why.append(f"{name} moves by {spread:.3g} pu over the last {spec.settle_window_s:g} s "
                       f"(band {band:.3g} pu: {100 * spec.settle_fraction:g} % of the range "
                       f"{span:.3g} pu it spans after the step, at least {spec.settle_floor_pu:g})")
    growth = float(step["growth_end"])
    numbers["step_growth_rate_end_per_s"] = growth if math.isfinite(growth) else None
    held_growth = float(held["growth_end"])
    numbers["held_growth_rate_per_s"] = held_growth if math.isfinite(held_growth) else None
    w_end = float(np.max(np.abs(w[win] - 1.0)))
    dy_end = np.abs(step["dy_end"])
    numbers["step_final_speed_dev_pu"] = w_end
    numbers["step_max_dxdt_end"] = float(np.max(dy_end)) if dy_end.size else 0.0
    if w_end > spec.settle_speed_pu:
        why.append(f"speed deviation {w_end:.3g} pu over the last {spec.settle_window_s:g} s "
                   f"(limit {spec.settle_speed_pu:g})")
    if numbers["step_max_dxdt_end"] > spec.settle_derivative:
        k = int(np.argmax(dy_end))
        why.append(f"|d(state)/dt| = {numbers['step_max_dxdt_end']:.3g} at {t[-1]:g} s "
                   f"({_state_name(unit, models, k)}; limit {spec.settle_derivative:g})")
    if why:
        slow = (f" (linearised at {t[-1]:g} s, its slowest mode decays with a time constant of "
                f"{-1.0 / growth:.3g} s)" if math.isfinite(growth) and growth < 0 else
                f" (linearised at {t[-1]:g} s, it has a mode growing at {growth:.3g} 1/s)"
                if math.isfinite(growth) and growth > 0 else "")
        if math.isfinite(held_growth) and held_growth > 0:
            slow += (f"; with its terminal voltage imposed its initial state is itself unstable (a mode "
                     f"grows at {held_growth:.3g} 1/s at rest; the held run stays put only because "
                     "nothing disturbs it)")
        return "fail", [f"the {100 * spec.step:g} % step: not settled {t[-1] - spec.step_at_s:g} s "
                        "after it: " + "; ".join(why) + slow], numbers, []
    return "pass", [], numbers, []


# --- the whole case -----------------------------------------------------------------------------

def _unit_name(g: RawGenerator) -> str:
    return f"{g.bus}_{g.id.strip()}"


def check_case(case: CaseFile, *, out_of_service: bool = False, spec: CheckSpec = SPEC,
               progress: Callable[[str], None] | bool = True, workers: int | None = None,
               only: Collection[str] | None = None) -> dict:
    """The check of every unit of ``case``: the check.json document (``units``, ``summary``,
    the runs' definition, timings); ``only``: just the units of these names ("BUS_ID", as
    check.json names them; ``--repair`` checks again the units whose MBASE it changed)."""
    t_start = time.perf_counter()
    raw, dyr = case.raw, case.dyr
    inv = inventory(raw, dyr)
    accounts = inv.units(out_of_service=out_of_service)
    if only is not None:
        accounts = [a for a in accounts if _unit_name(a.generator) in set(only)]
    gens = [a.generator for a in accounts]
    off = inv.summary()["out_of_service_with_machine_record"]
    if not any(a.has_machine or a.category in ("machine model unknown", "inverter-based") for a in accounts):
        counts = ", ".join(f"{n} {k}" for k, n in inv.counts().items() if n)
        raise InputError(case.path, "no unit to check: no in-service generator of "
                         f"{Path(raw.source).name} has a machine or inverter-based plant record in the "
                         f".dyr (its {len(raw.generators)} generator record(s): {counts})")
    statics = [check_ibr.ibr_static(raw, dyr, g, spec.end_s) if a.category == "inverter-based"
               else _static(raw, dyr, g, case.playback.ke_zero) for g, a in zip(gens, accounts)]
    entries = []
    groups: dict = {}
    for g, st, acc in zip(gens, statics, accounts):
        e = {"name": _unit_name(g), "bus": g.bus, "id": g.id.strip(), "line": g.line, "models": st.models,
             "mbase_mva": g.mbase_mva, "pg_mw": g.pg_mw, "qg_mvar": g.qg_mvar, "in_service": g.stat == 1,
             "category": acc.category if acc.category != "out of service" else "synchronous",
             "outcome": None, "reasons": [], "notes": [*st.model.notes, *st.warnings], "numbers": {}}
        entries.append(e)
        if st.unsupported:
            e["outcome"] = "not supported"
            e["reasons"] = [line for _, line in st.unsupported] + [f"also: {line}" for _, line in st.problems]
            e["not_simulated"] = [m for m, _ in st.unsupported]
        elif st.problems or st.model.unit is None:
            e["outcome"] = "data problem"
            e["reasons"] = [line for _, line in st.problems] or ["the unit's model could not be built"]
            e["records_at_fault"] = [m for m, _ in st.problems]
        else:
            groups.setdefault(jax.tree_util.tree_structure(st.model.unit), []).append(len(entries) - 1)
    run = _Run(solver=case.playback.solver, substeps=case.playback.substeps, frame_hz=spec.frame_hz,
               end_s=spec.end_s, step_at_s=spec.step_at_s)
    h = 1.0 / (run.frame_hz * run.substeps)
    bar = Progress(len(groups)) if progress is True else None
    report = progress if callable(progress) else (bar.step if bar is not None else (lambda _: None))
    order = sorted(groups.values(), key=len, reverse=True)
    n_workers = workers or threads(len(order))
    in_threads = _same_context_in_threads()
    done: dict = {}
    """unit index -> (held lane, step lane, the _Run it was integrated with)"""
    times: list = []

    def one_group(members: list[int], how: _Run) -> tuple[list, float]:
        """Per member: (held run, step run(s)) as host dicts; and the wall time."""
        t0 = time.perf_counter()
        units = [statics[k].model.unit for k in members]
        n = len(members)
        if isinstance(units[0], INVERTER_UNITS):   # held, voltage step, frequency step
            per = [check_ibr.lanes(raw, gens[k], spec.step) for k in members]
            lanes = [p[j] for j in range(3) for p in per]
            fn, split = check_ibr.batch_jit(), (lambda r, j: (check_ibr.at(r, j), (
                check_ibr.at(r, n + j), check_ibr.at(r, 2 * n + j))))
        else:
            lanes = [_lane(raw, gens[k], x) for x in (0.0, spec.step) for k in members]
            fn = _MAPPED if how.solver == "kvaerno5" else _batch_jit()
            split = lambda r, j: (_at(r, j), _at(r, n + j))  # noqa: E731
        args = (_stack(units * (len(lanes) // n)), _stack(lanes), how)
        compiled = fn.lower(*args).compile()
        executing()   # the group's run limit counts from here
        res = jax.device_get(compiled(*args))
        return [split(res, j) for j in range(n)], time.perf_counter() - t0

    def execute(batches: list[tuple[list[int], _Run]]) -> None:
        # one compiled call per model structure and solver, side by side on the cores; every
        # wait bounded (a limit from the group's work), an expired group's units marked
        tasks = [Task(f"group {_chain(entries[m[0]])} ({len(m)} unit(s), {how.solver})",
                      wait_limit_s(len(m) * (3 if isinstance(statics[m[0]].model.unit, INVERTER_UNITS) else 2) // 2,
                                   spec, how.solver, how.substeps),
                      lambda m=m, how=how: one_group(m, how), COMPILE_LIMIT_S) for m, how in batches]
        for i, value in bounded(tasks, n_workers, threads=in_threads):
            members, how = batches[i]
            if isinstance(value, Expired):
                for k in members:
                    entries[k].update(outcome="fail", reasons=[value.reason + " (the compiled run did "
                                                               "not return; nothing was judged)"])
                    done.pop(k, None)
                report(f"{tasks[i].label}: {value.reason}")
                continue
            runs, dt = value
            times.append(dt)
            for k, (held, step) in zip(members, runs):
                done[k] = (held, step, how)
            report(f"{_chain(entries[members[0]])}: {len(members)} unit(s), {how.solver}, {dt:.1f} s")

    execute([(m, run) for m in order])
    # units whose fastest mode at the initial state the explicit fixed step cannot follow: again,
    # with Kvaerno5 (implicit), and said so
    stiff: dict = {}
    if run.solver == "tsit5":
        for k, (held, _, _) in done.items():
            if too_stiff(float(held["fastest_t0"]), h):
                stiff.setdefault(jax.tree_util.tree_structure(statics[k].model.unit), []).append(k)
    if stiff:
        implicit = _Run(solver="kvaerno5", substeps=run.substeps, frame_hz=spec.frame_hz,
                        end_s=spec.end_s, step_at_s=spec.step_at_s)
        if bar is not None:
            bar.total += len(stiff)
        for members in stiff.values():
            for k in members:
                entries[k]["notes"].append(stiff_note(float(done.pop(k)[0]["fastest_t0"]), h, "Tsit5"))
                entries[k]["solver"] = "kvaerno5"
        execute([(m, implicit) for m in sorted(stiff.values(), key=len, reverse=True)])
    for k, (held, step, how) in done.items():
        if isinstance(statics[k].model.unit, INVERTER_UNITS):
            outcome, reasons, numbers, notes = check_ibr.judge(statics[k], gens[k], held, step, spec)
            entries[k].update(outcome=outcome, reasons=reasons, numbers=numbers)
            entries[k]["notes"] += notes
            continue
        outcome, reasons, numbers, limits = _judge(
            statics[k], gens[k], raw, held, step, spec, (how.solver, 1.0 / (how.frame_hz * how.substeps)))
        if outcome == "fail" and statics[k].warnings:
            outcome, reasons = "data problem", statics[k].warnings + [f"hence: {r}" for r in reasons]
            entries[k]["records_at_fault"] = [statics[k].models["machine"]]
        entries[k].update(outcome=outcome, reasons=reasons, numbers=numbers)
        if limits:
            entries[k]["limits"] = limits
            entries[k]["records_at_fault"] = [lim["record"] for lim in limits]
    checked = {id(a) for a in accounts}
    doc = {
        "jaxdse_version": __version__,
        "source": str(case.path),
        "case": {"raw": str(raw.source), "raw_revision": raw.revision, "dyr": str(dyr.source)},
        "check": {**dataclasses.asdict(spec), "solver": case.playback.solver,
                  "step_s": 1.0 / (spec.frame_hz * case.playback.substeps),
                  "ke_zero": case.playback.ke_zero},
        "summary": {**_summary(entries, off if not out_of_service else 0, len(order) + len(stiff)),
                    "accounting": accounting(inv, entries) if only is None else None},
        "units": entries,
        "not_checked": [a.as_dict() for a in inv.generators if id(a) not in checked],
        "dyr_records_not_used": [r.as_dict() for r in inv.records],
        "dyr_records_unreadable": list(inv.unreadable),
        "wall_time_s": time.perf_counter() - t_start,
        "group_times_s": times,
    }
    _finite(doc)
    attach_carried(doc, dyr, raw)
    return doc


NOT_CHECKED = {"out of service": "out of service, not checked",
               "no dynamic records": "in service without dynamic records (no .dyr record on their bus "
                                     "and ID)",
               "not a generator": "not generators: static var compensators or STATCOMs in the generator data",
               "duplicate": "second generator records for the same bus and ID (the first is used)"}
"""The categories of generator records that are not units of the check, in words."""


def accounting(inv: Inventory, entries: list[dict]) -> dict:
    """Every generator record of the .raw: ``checked`` (the units, by category) and each
    category not checked; they add up to ``generator_records``. And the .dyr records of no
    generator (orphaned, bus level, unreadable)."""
    counts = inv.counts()
    checked_off = sum(not e["in_service"] for e in entries)
    by_category = Counter(e["category"] for e in entries)
    out = {"generator_records": len(inv.generators), "checked": len(entries),
           "checked_by_category": {k: by_category.get(k, 0) for k in GENERATOR_CATEGORIES
                                   if by_category.get(k)},
           **{k: counts[k] - (checked_off if k == "out of service" else 0) for k in NOT_CHECKED}}
    if out["checked"] + sum(out[k] for k in NOT_CHECKED) != out["generator_records"]:  # a bug, not data
        raise AssertionError(f"generator records not accounted for: {out}")
    s = inv.summary()
    out.update({"dyr_records_orphaned": s["dyr_records_orphaned"],
                "dyr_records_bus_level": s["dyr_records_bus_level"],
                "dyr_records_unreadable": s["dyr_records_unreadable"]})
    return out


def _accounting_lines(doc: dict, most: int = 5) -> list[str]:
    """The console's account of every generator record and of the .dyr records of no generator."""
    a = doc["summary"]["accounting"]
    by = ", ".join(f"{n} {k}" for k, n in a["checked_by_category"].items())
    lines = [f"  {a['checked']:5d} checked ({by})"]
    for k, words in NOT_CHECKED.items():
        rows = [r for r in doc["not_checked"] if r["category"] == k]
        if not a[k]:
            continue
        extra = ""
        if k == "out of service":
            m = doc["summary"]["out_of_service_not_checked"]
            extra = f" ({m} with a machine record; --out-of-service checks them)" if m else ""
        elif rows:
            names = ", ".join(f"{r['bus']} {r['id']!r}" + (f" {'/'.join(dict.fromkeys(r['models']))}"
                                                            if r["models"] and k != "duplicate" else "")
                              for r in rows[:most])
            extra = f": {names}" + (f" (+{len(rows) - most} more)" if len(rows) > most else "")
        lines.append(f"  {a[k]:5d} {words}{extra}")
    recs = doc["dyr_records_not_used"]
    for cat, words in (("orphaned", "orphaned .dyr records (no generator of theirs in the .raw)"),
                       ("bus level", ".dyr records of a bus or plant, not of one machine (not used)")):
        rows = [r for r in recs if r["category"] == cat]
        if rows:
            lines.append(f"  {len(rows):5d} {words}:")
            lines += [f"          {r['why']}" for r in rows[:2 * most]]
            if len(rows) > 2 * most:
                lines.append(f"          (+{len(rows) - 2 * most} more in check.json)")
    for line in doc["dyr_records_unreadable"]:
        lines.append(f"        unreadable .dyr record, not used: {line}")
    return lines


WAIT_BASE_S = 60.0
"""The wait on one group's compiled run: this much [s] ..."""
WAIT_PER_LANE_STEP_S = 2e-4
"""... plus this much per integration step of each of its runs [s] (2 runs per unit; Kvaerno5
counted at 8 steps per frame). On ACTIVSg2000 with both cores loaded 7-fold, 205 units of
GENROU ESST4B IEEEST GGOV1 took 64 s, compile included (3 us per lane-step): the limit (266 s)
is 4 times that."""


def wait_limit_s(units: int, spec: CheckSpec, solver: str, substeps: int) -> float:
    """How long the check waits for a group of ``units`` units' compiled call [s] before it
    marks them timed out (:data:`WAIT_BASE_S`, :data:`WAIT_PER_LANE_STEP_S`)."""
    frames = int(round(spec.end_s * spec.frame_hz))
    steps = frames * (substeps if solver == "tsit5" else 8)
    return WAIT_BASE_S + WAIT_PER_LANE_STEP_S * 2 * units * steps


def _chain(e: dict) -> str:
    if e.get("category") == "inverter-based":   # a wind turbine's mechanics after the three
        wind = [e["models"][k] for k in check_ibr.WIND_KINDS if e["models"].get(k)]
        return " ".join([e["models"].get(k) or "-" for k in check_ibr.IBR_KINDS] + wind)
    return " ".join(e["models"].get(k) or "-" for k in KINDS)


def _summary(entries: list[dict], off: int, programs: int) -> dict:
    counts = Counter(e["outcome"] for e in entries)
    chains: dict = {}
    for e in entries:
        c = chains.setdefault(_chain(e), dict.fromkeys(OUTCOMES, 0))
        c[e["outcome"]] += 1
    unsupported = Counter(m for e in entries for m in dict.fromkeys(e.get("not_simulated", [])))
    problems = Counter()
    for e in entries:
        if e["outcome"] != "data problem":
            continue
        keys = ([f"{lim['record']} {lim['con']} ({lim['signal'].split(' = ')[0]} {lim['side']})"
                 for lim in e.get("limits", [])]
                or [m if m == "no machine record" else f"{m or 'case'}: values refused by the model's checks"
                    for m in e.get("records_at_fault", [])])
        for key in dict.fromkeys(keys):
            problems[key] += 1
    return {"units": len(entries), **{o: counts.get(o, 0) for o in OUTCOMES},
            "pass_percent": 100.0 * counts.get("pass", 0) / max(len(entries), 1),
            "out_of_service_not_checked": off,
            "model_chains": dict(sorted(chains.items(), key=lambda kv: -sum(kv[1].values()))),
            "compiled_programs": programs,
            "not_supported_models": dict(unsupported.most_common()),
            "data_problems": dict(problems.most_common())}


# --- output -------------------------------------------------------------------------------------

def console_table(doc: dict) -> str:
    """The console report: the units by model chain, every unit that does not pass with its
    first reason, and the counts."""
    s, lines = doc["summary"], []
    lines.append(f"jaxdse check: {Path(doc['case']['raw']).name} + {Path(doc['case']['dyr']).name}: "
                 f"{s['accounting']['generator_records']} generator record(s), {s['units']} unit(s) checked")
    lines += _accounting_lines(doc)
    lines.append("")
    w = max([len(c) for c in s["model_chains"]] + [11])
    lines.append(f"  {'model chain':<{w}}  units   pass  data problem  not supported  fail")
    for c, n in s["model_chains"].items():
        lines.append(f"  {c:<{w}}  {sum(n.values()):5d}  {n['pass']:5d}  {n['data problem']:12d}  "
                     f"{n['not supported']:13d}  {n['fail']:4d}")
    bad = [e for e in doc["units"] if e["outcome"] != "pass"]
    if bad:
        nw = max(len(e["name"]) for e in bad)
        lines.append("")
        lines.append(f"  {'unit':<{nw}}  {'outcome':<13}  reason")
        for e in sorted(bad, key=lambda e: (OUTCOMES.index(e["outcome"]), e["bus"], e["id"])):
            more = f" (+{len(e['reasons']) - 1} more)" if len(e["reasons"]) > 1 else ""
            lines.append(f"  {e['name']:<{nw}}  {e['outcome']:<13}  {e['reasons'][0]}{more}")
    lines.extend(repair_console(doc))
    lines.append("")
    lines.append(f"{s['pass']} pass ({s['pass_percent']:.1f} %), {s['data problem']} data problem, "
                 f"{s['not supported']} not supported, {s['fail']} fail, of {s['units']} "
                 f"({doc['wall_time_s']:.0f} s)")
    return "\n".join(lines)


def _badge(outcome: str) -> str:
    return f'<span class="v" style="background:{OUTCOME_COLOURS[outcome]}">{html.escape(outcome)}</span>'


def check_page(doc: dict) -> str:
    """check.html: the counts, the reasons, the sortable table of every unit."""
    from .fleet_report import _page

    s, c = doc["summary"], doc["check"]
    rows = []
    for e in doc["units"]:
        m = e["models"]
        reasons = "<br>".join(html.escape(r) for r in e["reasons"]) or "–"
        rows.append(f"<tr><td>{html.escape(e['name'])}</td><td>{e['bus']}</td><td>{html.escape(e['id'])}</td>"
                    f"<td>{e['mbase_mva']:.0f}</td><td>{e['pg_mw']:.1f}</td>"
                    + "".join(f"<td>{html.escape(m.get(k) or '–')}</td>"
                              for k in (check_ibr.IBR_KINDS + ("",) if e.get("category") == "inverter-based"
                                        else KINDS))
                    + f"<td data-sort=\"{OUTCOMES.index(e['outcome'])}\">{_badge(e['outcome'])}</td>"
                    f"<td style=\"text-align:left\" class=\"small\">{reasons}</td></tr>")
    chains = "".join(
        f"<tr><td>{html.escape(ch)}</td><td>{sum(n.values())}</td>"
        + "".join(f"<td>{n[o]}</td>" for o in OUTCOMES) + "</tr>" for ch, n in s["model_chains"].items())
    reasons = "".join(f"<li>{html.escape(k)}: {n} unit(s)</li>" for k, n in s["data_problems"].items()) \
        or "<li>none</li>"
    unsupported = "".join(f"<li>{html.escape(k)}: {n} unit(s)</li>"
                          for k, n in s["not_supported_models"].items()) or "<li>none</li>"
    counts = ", ".join(f"{_badge(o)} {s[o]}" for o in OUTCOMES)
    body = f"""
<h1>Case check: every unit at rest and after a voltage step (and a frequency step for
inverter-based plants)</h1>
<p class="small">{html.escape(doc['source'])} · jaxdse {html.escape(doc['jaxdse_version'])} ·
case {html.escape(Path(doc['case']['raw']).name)} (rev {doc['case']['raw_revision']}) and
{html.escape(Path(doc['case']['dyr']).name)} · {doc['wall_time_s']:.0f} s</p>
<p><b>{s['units']}</b> units checked: {counts} · <b>{s['pass_percent']:.1f} %</b> pass.</p>
{_accounting_html(doc)}
<h2>What is checked</h2>
<p class="small">Each unit's own records (machine, exciter, stabiliser, governor) are built into one
model, initialised from the power flow at its terminal (the .raw PG, QG on MBASE and the bus
voltage VM, VA) and simulated with the terminal voltage imposed (the .dyr playback's convention),
fixed step {c['step_s']:.4g} s ({html.escape(c['solver'])}). <b>Held</b>: every state derivative at
t = 0 below {c['max_derivative']:g}, P and Q at {c['held_s']:g} s within {c['max_pq_error']:g} pu of
the power flow. <b>Step</b>: the voltage stepped by {100 * c['step']:g} % at {c['step_at_s']:g} s and
Vref moved with it (with the voltage imposed, a regulator with integral action would otherwise
wind up to its limit); bounded (speed within ±{c['max_speed_dev']:g} pu, rotor angle within
{c['max_angle_swing_rad']:.3g} rad of its start: no pole slipped) and settled at {c['end_s']:g} s:
over the last {c['settle_window_s']:g} s, P and Q within {100 * c['settle_fraction']:g} % of the
range they span after the step (at least {c['settle_floor_pu']:g} pu) of their final value,
speed within {c['settle_speed_pu']:g} pu, every state derivative below {c['settle_derivative']:g}.
<b>data problem</b>: a record whose values cannot be simulated (named by the model's checks) or
whose initial operating point needs a signal outside the record's limits (the signal and the CON
with their values); <b>not supported</b>: a model jaxdse does not simulate; <b>fail</b>: all
simulated and no value at fault found, but not steady or not settled.</p>
<h2>Reasons</h2>
<p>Data problems (the record and the limit its initial operating point crosses, or the values
its model's checks refuse):</p><ul>{reasons}</ul>
<p>Models not simulated:</p><ul>{unsupported}</ul>
{repair_html(doc)}
<h2>Model chains</h2>
<table class="sortable"><thead><tr><th>machine exciter stabiliser governor, or converter,
electrical controls, plant controller</th><th>units</th>
{''.join(f'<th>{o}</th>' for o in OUTCOMES)}</tr></thead><tbody>{chains}</tbody></table>
<h2>All units</h2>
<p class="small">Click a column heading to sort.</p>
<table class="sortable"><thead><tr><th>unit</th><th>bus</th><th>id</th><th>MBASE [MVA]</th>
<th>PG [MW]</th><th>machine / converter</th><th>exciter / electrical controls</th>
<th>stabiliser / plant controller</th><th>governor</th><th>outcome</th>
<th>reasons</th></tr></thead><tbody>
{''.join(rows)}
</tbody></table>
<p class="small">Also: <a href="check.json">check.json</a> (every number).</p>
"""
    return _page("Case check", body, script=True)


def _accounting_html(doc: dict) -> str:
    """Every generator record of the .raw (the counts add up), every one not checked with its
    reason, and the .dyr records of no generator."""
    from .fleet_report import record_tables

    a = doc["summary"]["accounting"]
    by = ", ".join(f"{n} {html.escape(k)}" for k, n in a["checked_by_category"].items())
    items = [f"<li><b>{a['checked']}</b> checked ({by}; a machine model jaxdse does not know is "
             "<i>not supported</i>, exciter, stabiliser or governor records without a machine record "
             "are a <i>data problem</i>)</li>"]
    off = doc["summary"]["out_of_service_not_checked"]
    for k, words in NOT_CHECKED.items():
        if a[k]:
            more = f" ({off} with a machine record)" if k == "out of service" and off else ""
            items.append(f"<li><b>{a[k]}</b> {html.escape(words)}{more}</li>")
    return (f"<p>Every generator record of {html.escape(Path(doc['case']['raw']).name)}: "
            f"<b>{a['generator_records']}</b>, of which</p><ul>{''.join(items)}</ul>"
            + record_tables(doc["not_checked"], "not checked", doc["dyr_records_not_used"],
                            f" ({a['dyr_records_orphaned']} orphaned, {a['dyr_records_bus_level']} of a bus "
                            "or plant)", doc["dyr_records_unreadable"]))


def write_check(out_dir: Path, doc: dict) -> None:
    """``out_dir``/check.json and check.html."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "check.json").write_text(json.dumps(doc, indent=2, allow_nan=False, default=_jsonable) + "\n")
    (out_dir / "check.html").write_text(check_page(doc))


def _jsonable(x):
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")


def run_check(path, out: Path | None = None, *, out_of_service: bool = False, repair: bool = False) -> dict:
    """``jaxdse check``: load, check, print the table, write ``out`` when given; with ``repair``,
    write repaired.dyr, repairs.csv and repaired.toml (into ``out``, else beside the case file)
    and the change table into the outputs (:mod:`jaxdse._app.repair`)."""
    case = load_case(path)
    doc = check_case(case, out_of_service=out_of_service)
    if repair:
        def recheck(again: CaseFile, names) -> dict:
            # the units of their model chains: the groups of the first run, so its compiled programs
            chains = {_chain(e) for e in doc["units"] if e["name"] in set(names)}
            return check_case(again, out_of_service=out_of_service,
                              only=[e["name"] for e in doc["units"] if _chain(e) in chains])

        doc["repair"] = write_repair(case, doc, Path(out) if out is not None else Path(path).parent,
                                     recheck=recheck)
    print(console_table(doc))
    if out is not None:
        write_check(out, doc)
        print(f"wrote {Path(out) / 'check.json'} and {Path(out) / 'check.html'}")
    if repair:
        files = doc["repair"]["files"]
        print(f"wrote {files['dyr']}, " + (f"{files['raw']}, " if "raw" in files else "")
              + f"{files['csv']} and {files['case']}; check the repaired case: "
              f"jaxdse check {files['case']}")
    return doc


def _finite(doc: dict) -> None:
    """Replace non-finite numbers by None (JSON has no NaN)."""
    for e in doc["units"]:
        for k, v in e["numbers"].items():
            if isinstance(v, float) and not math.isfinite(v):
                e["numbers"][k] = None


__all__ = ["OUTCOMES", "SPEC", "CaseFile", "CheckSpec", "check_case", "check_page",
           "console_table", "load_case", "run_check", "synchronous_units", "write_check"]
