"""Playback of a unit's .dyr model against a recording: the PSS/E PLBVFU1 convention.

The recorded terminal voltage (magnitude and angle, frame rotating at nominal frequency) is
imposed at the machine terminal; the unit starts in the steady state of the first frames'
power flow; diffrax integrates the composed model and the simulated P, Q, speed and rotor
angle are returned at the recording's frames. Derivatives are taken in forward mode
(``diffrax.ForwardMode``): sensitivities and Levenberg-Marquardt need Jacobian columns for a
handful of parameters, never a gradient of a scalar.
"""

from __future__ import annotations

from typing import Literal, NamedTuple

import diffrax
import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._core.lti import zero_phase_lowpass
from .._core.signals import jumps
from .._models.ibr import GfmReferences
from .gfm_unit import GfmUnit
from .ibr_unit import IbrReferences, IbrUnit
from .stiff import kvaerno5
from .unit import DyrUnit, UnitInputs, UnitReferences


class PlaybackSettings(eqx.Module):
    """How the playback is integrated (static: one compiled function per setting)."""

    solver: Literal["tsit5", "kvaerno5"] = eqx.field(static=True, default="tsit5")
    """"tsit5": explicit 5th-order Runge-Kutta with an adaptive step, one solve per frame
    interval (a ``lax.scan`` over the frames: under vmap each interval waits only for its own
    slowest unit), about 2 steps per frame on a smooth stretch and as many as a fault's fast
    transient needs; "kvaerno5": implicit (L-stable), adaptive over the whole recording, for
    units whose blocks are too fast for an explicit step (its Newton solves without LAPACK:
    :func:`~jaxdse._dyr.stiff.kvaerno5`)."""
    substeps: int = eqx.field(static=True, default=4)
    """The first step of each frame interval is 1/``substeps`` of it."""
    max_steps_per_frame: int = eqx.field(static=True, default=256)
    """Steps allowed per frame interval ("tsit5"); more: the interval is played again at the
    fixed step (``fixed_substeps``)."""
    fixed_substeps: int = eqx.field(static=True, default=64)
    """"tsit5": a frame interval whose adaptive solve does not reach its end is played again with
    this many fixed Tsit5 steps (0: not; the playback is then not ``ok``). The case: a PI whose
    output sits on its non-windup limit while its proportional part moves (REECA1's voltage PI
    during a fault): the exact solution slides along the limit, the integrator switching between
    blocked and free at every trial step, and the step control cannot pass (4,204 accepted and
    15,796 rejected steps in one interval of a Texas 7k REGCA1/REECA1/REPCA1 plant). A fixed step
    switches at most once per step, as PSS/E's fixed step does, and converges to the sliding
    solution (that interval's end at 64 steps against 4,096: 0.03 pu in the PI's state, which the
    limit's clip keeps from the output, 1e-5 pu in the others). Under vmap the fallback's loop
    runs only in the intervals where some unit of the batch needs it, and then for the whole
    batch."""
    init_s: float = eqx.field(static=True, default=0.5)
    """The initial steady state is the power flow averaged over the quiet stretch before the
    first event (:func:`quiet_frames`), at least this long [s]."""
    init_max_s: float = eqx.field(static=True, default=60.0)
    """... and at most this long [s]. A long average matters: with the voltage imposed, a
    regulator with integral action runs open loop and integrates any offset between its reference
    (the initial |V|) and the recording's mean |V|; an average over 0.5 s of noisy frames leaves
    an offset that drifts Q by several % of MBASE within a minute."""
    init_sigmas: float = eqx.field(static=True, default=6.0)
    """The quiet stretch ends where a 0.1 s moving mean of |V|, P or Q leaves the first
    ``init_s``'s mean by this many standard errors of the noise (or at the first voltage step)."""
    settle_s: float = eqx.field(static=True, default=1.0)
    """A voltage step within this first stretch [s] is a start-up artefact of the recording
    (a flat start, a re-initialised PMU): the frames before it are replaced by the first
    frame after it, so that the unit starts where the recording is steady."""
    rtol: float = eqx.field(static=True, default=1e-7)
    """Relative tolerance of the step control. A fixed step of 1/4 frame was not enough: an
    ESST4B with IEEEST under a 3-cycle fault at 30 frames/s ended its playback with Efd 0.2 pu
    and Q 8 % of MBASE off the converged solution (the stabiliser reaches its limit within a
    frame while the regulator's PI sits on its non-windup limit, and that PI's integrator runs
    open loop under the imposed voltage, so the error stays); adaptive at 1e-7: 0.0001 %."""
    atol: float = eqx.field(static=True, default=1e-9)
    """Absolute tolerance of the step control [pu]."""
    step_ratio: float = eqx.field(static=True, default=4.0)
    """A jump of the voltage phasor between two frames this many times larger than the smooth
    curvature around it (and ``step_factor`` times the median second difference) is a switching
    step: the post-event trajectory is extended back to it, not ramped over the interval
    (:func:`voltage_steps`)."""
    step_factor: float = eqx.field(static=True, default=10.0)
    """See ``step_ratio`` and :func:`voltage_steps`."""
    input_filter_hz: float = eqx.field(static=True, default=0.0)
    """Low-pass the imposed |V| and angle at this cut-off [Hz] (zero-phase 2nd-order
    Butterworth, the switching steps kept sharp); 0: off. Measurement noise on V drives the
    model (an exciter answers every jitter of the recorded voltage) and biases a calibration
    towards parameters that damp the response to it; 5 Hz keeps the electromechanical band."""


class TerminalSeries(NamedTuple):
    """Imposed terminal voltage and measured current, machine base, per frame."""

    t_s: Float[Array, " T"]
    v_mag_pu: Float[Array, " T"]
    v_ang_rad: Float[Array, " T"]
    """Unwrapped voltage angle in the frame rotating at nominal frequency [rad]."""
    i_re_pu: Float[Array, " T"]
    """Measured current (out of the machine), real part, same frame [pu]."""
    i_im_pu: Float[Array, " T"]
    f_dev_pu: Float[Array, " T"] | None = None
    """Recorded frequency deviation [pu of nominal] (the PMU's frequency channel; NaN where it
    has none). An inverter-based plant's frequency input follows it, as PSS/E's PLBVFU1 plays
    back a recorded frequency, and the voltage angle's slope where it is NaN or None. A
    machine's playback always takes the slope."""


class PlaybackResult(eqx.Module):
    """The simulated unit at the recording's frames (machine base)."""

    t_s: Array
    p_pu: Array
    """Active power out of the terminal [pu]."""
    q_pu: Array
    """Reactive power out of the terminal [pu]."""
    omega_pu: Array
    """Rotor speed [pu] (a grid-forming converter's virtual rotor; NaN for a grid-following
    inverter-based plant: not applicable)."""
    delta_rad: Array
    """Rotor angle (q axis) in the nominal frame [rad] (a grid-forming converter's: its virtual
    d axis; NaN for a grid-following inverter-based plant)."""
    efd_pu: Array
    """Field voltage [pu] (NaN for an inverter-based plant)."""
    tm_pu: Array
    """Mechanical torque [pu] (NaN for an inverter-based plant)."""
    references: UnitReferences | IbrReferences | GfmReferences
    ok: Array
    """True when the solver reached the end with finite states."""
    fixed_step_intervals: Array
    """Frame intervals played at the fixed step because the adaptive step could not pass them
    (``PlaybackSettings.fixed_substeps``; 0 with "kvaerno5")."""


def quiet_frames(series: TerminalSeries, settings: PlaybackSettings):
    """Frames before the first event, between ``init_s`` and ``init_max_s`` (traced: one program
    for every recording). The event is the first voltage step (:func:`voltage_steps`) or the first
    0.1 s moving mean of |V|, P or Q that leaves the mean of the first ``init_s`` by
    ``init_sigmas`` standard errors; the noise is taken from the median second difference, which a
    smooth event leaves alone. The moving mean's own frames are left out of the stretch."""
    n = series.t_s.shape[0]
    dt = series.t_s[1] - series.t_s[0]
    n0 = jnp.clip(jnp.round(settings.init_s / dt), 1.0, n)
    m = jnp.maximum(1.0, jnp.round(0.1 / dt))
    j = jnp.arange(n)
    rel = series.v_ang_rad - series.v_ang_rad[0]
    c, s = jnp.cos(rel), jnp.sin(rel)
    ip = series.i_re_pu * c + series.i_im_pu * s
    iq = series.i_im_pu * c - series.i_re_pu * s
    first = n

    for x in (series.v_mag_pu, series.v_mag_pu * ip, series.v_mag_pu * iq):
        base = jnp.sum(jnp.where(j < n0, x, 0.0)) / n0
        sigma = 1.4826 * jnp.median(jnp.abs(jnp.diff(x, 2))) / jnp.sqrt(6.0)
        cum = jnp.concatenate([jnp.zeros(1, x.dtype), jnp.cumsum(x - base)])
        lag = jnp.maximum(j + 1 - m, 0).astype(int)
        mean = (cum[j + 1] - cum[lag]) / (j + 1 - lag)  # trailing, up to m frames
        tol = settings.init_sigmas * sigma * jnp.sqrt(1.0 / m + 1.0 / n0) \
            + 1e-9 * (1.0 + jnp.abs(base))
        off = (jnp.abs(mean) > tol) & (j >= n0)
        first = jnp.minimum(first, jnp.min(jnp.where(off, j - m + 1, n)))
    steps = voltage_steps(series, settings)
    first = jnp.minimum(first, jnp.min(jnp.where(steps, jnp.arange(n - 1) + 1, n)))
    return jnp.clip(first, n0, jnp.maximum(n0, jnp.round(settings.init_max_s / dt)))


def initial_operating_point(series: TerminalSeries, settings: PlaybackSettings):
    """(UnitInputs at t0, I_re, I_im): |V| averaged over the quiet stretch before the first event
    (:func:`quiet_frames`) at the first frame's angle, and the current averaged over it relative
    to the voltage angle (a noise-robust power flow, and the reference an integrating regulator
    holds)."""
    k = jnp.arange(series.t_s.shape[0]) < quiet_frames(series, settings)
    w = k / jnp.sum(k)
    th0 = series.v_ang_rad[0]
    rel = series.v_ang_rad - th0
    c, s = jnp.cos(rel), jnp.sin(rel)
    i_re = jnp.sum(w * (series.i_re_pu * c + series.i_im_pu * s))
    i_im = jnp.sum(w * (series.i_im_pu * c - series.i_re_pu * s))
    v = jnp.sum(w * series.v_mag_pu)
    cr, sr = jnp.cos(th0), jnp.sin(th0)
    u0 = UnitInputs(v * cr, v * sr, jnp.zeros_like(v), jnp.zeros_like(v))
    return u0, i_re, i_im


def voltage_steps(series: TerminalSeries, settings: PlaybackSettings):
    """Per frame interval: True where the voltage phasor jumps (a switching event between two
    frames; :func:`~jaxdse._core.signals.jumps` with ``step_ratio`` and ``step_factor``)."""
    return jumps(series.v_mag_pu * jnp.exp(1j * series.v_ang_rad), settings.step_ratio,
                 settings.step_factor)


def _filtered(x, step, dt, cutoff_hz):
    """``x`` low-passed at zero phase with its steps (at ``step`` intervals) taken out first and
    put back after, so that a switching event stays a step."""
    jumps = jnp.concatenate([jnp.zeros(1, x.dtype), jnp.cumsum(jnp.where(step, jnp.diff(x), 0.0))])
    return zero_phase_lowpass(x - jumps, dt, cutoff_hz) + jumps


def _input_function(series: TerminalSeries, settings: PlaybackSettings, omega_s,
                    recorded_f: bool = False):
    """(k, s) -> UnitInputs on frame interval ``k`` (from frame k to k + 1) at the fraction
    ``s`` in [0, 1] of it: |V| and its angle linear between frames, except across a voltage
    step: a switching event happens just after the frame before it, so over that interval the
    parabola through the three frames after it is extended back to the switching instant (the
    post-event trajectory, not a hold of the frame after the step, nor a ramp; a line through
    two frames missed the fast swing after a switching: 1.2 % of the response in the round-trip
    test, the parabola 0.5 %). Each interval is its own curve, closed at both ends, so that a solve over one interval never sees the next one's step
    (and the frames' outputs, at ``s`` = 1 of the interval before, see the recorded frame).
    ``recorded_f``: the frequency is ``series.f_dev_pu`` (linear between frames) where it is
    finite, else the angle's slope."""
    ts, vm, th = series.t_s, series.v_mag_pu, series.v_ang_rad
    fr = series.f_dev_pu if recorded_f else None
    dt = ts[1] - ts[0]
    step = voltage_steps(series, settings)
    n = ts.shape[0]
    if settings.input_filter_hz > 0:
        vm, th = (_filtered(x, step, dt, settings.input_filter_hz) for x in (vm, th))

    def inputs(k, s):
        # Indices from k alone (the same for every unit under vmap: slices, not gathers); across
        # a step, the next interval's line (held, at the last interval).
        k = jnp.clip(k, 0, n - 2)
        k2, k3 = jnp.minimum(k + 2, n - 1), jnp.minimum(k + 3, n - 1)

        def line(x):
            # across a step: the parabola through the three frames after it, extended back
            u = s - 1.0
            first, second = x[k2] - x[k + 1], x[k3] - 2 * x[k2] + x[k + 1]
            back = x[k + 1] + u * first + 0.5 * u * (u - 1) * second
            return jnp.where(step[k], back, x[k] + s * (x[k + 1] - x[k])), \
                jnp.where(step[k], first + (u - 0.5) * second, x[k + 1] - x[k])

        (m, dvm), (a, dth) = line(vm), line(th)
        f = dth / dt / omega_s
        if fr is not None:   # the recorded channel, linear between frames
            f_rec = fr[k] + s * (fr[k + 1] - fr[k])
            f = jnp.where(jnp.isfinite(f_rec), f_rec, f)
        return UnitInputs(m * jnp.cos(a), m * jnp.sin(a), f, dvm / dt)

    return inputs


def _fixed_steps(rhs, y, n, m):
    """``n`` (0 or ``m``, traced) Tsit5 steps of 1/``m`` over s in [0, 1] from ``y``: a
    ``while_loop``, so that under vmap the steps are taken only while some unit needs them."""
    solver, term = diffrax.Tsit5(scan_kind="lax"), diffrax.ODETerm(rhs)   # forward-mode: no
    h = 1.0 / m                                                            # checkpointed stages

    def body(c):
        i, y, st = c
        y1, _, _, st, _ = solver.step(term, i * h, (i + 1) * h, y, None, st, False)
        return i + 1, y1, st

    st = solver.init(term, 0.0, h, y, None)
    return jax.lax.while_loop(lambda c: c[0] < n, body, (jnp.zeros((), int), y, st))[1]


def _frame_of(s):
    """(interval, fraction) of the time ``s`` in frames: left-continuous at the frames (frame k
    is the end of interval k - 1; frame 0 the start of interval 0)."""
    k = jnp.maximum(jnp.ceil(s - 1e-9) - 1, 0)
    return k.astype(int), s - k


def steady_start(series: TerminalSeries, settings: PlaybackSettings) -> TerminalSeries:
    """``series`` with the frames before the last voltage step of its first ``settle_s``
    replaced by the frame after that step (unchanged when there is none)."""
    n = series.t_s.shape[0]
    k = jnp.arange(n - 1)
    early = voltage_steps(series, settings) & (series.t_s[1:] - series.t_s[0] <= settings.settle_s)
    start = jnp.max(jnp.where(early, k + 1, 0))
    keep = jnp.arange(n) >= start
    return TerminalSeries(series.t_s, *(None if a is None else jnp.where(keep, a, a[start])
                                        for a in series[1:]))


def _play_back(unit: DyrUnit | IbrUnit | GfmUnit, series: TerminalSeries,
               settings: PlaybackSettings = PlaybackSettings()) -> PlaybackResult:
    """Simulate ``unit`` (a machine's :class:`DyrUnit`, an inverter-based plant's
    :class:`IbrUnit` or a grid-forming converter's :class:`GfmUnit`) with the
    recorded terminal voltage imposed (PLBVFU1 convention); the frequency deviation an
    inverter-based plant sees is the recorded angle's slope. A grid-forming converter's
    ``omega_pu`` and ``delta_rad`` are its virtual rotor's."""
    series = steady_start(series, settings)
    ts = series.t_s
    ibr = isinstance(unit, IbrUnit)
    gfm = isinstance(unit, GfmUnit)
    omega_s = unit.omega_s_rad_s if (ibr or gfm) else unit.machine.omega_s_rad_s
    u0, i_re0, i_im0 = initial_operating_point(series, settings)
    y0, refs = unit.initial_state(u0, i_re0, i_im0)
    inputs = _input_function(series, settings, omega_s, recorded_f=ibr)
    dt = (ts[1] - ts[0])
    controller = diffrax.PIDController(rtol=settings.rtol, atol=settings.atol)

    if settings.solver == "tsit5":
        def frame(y, k):  # one frame interval, time in frames from its start: dy/ds = dt dy/dt
            def rhs(s, y, args):
                return jax.tree_util.tree_map(lambda d: dt * d,
                                              unit.vector_field(y, inputs(k, s), refs))

            # t0, t1 and dt0 constants: diffeqsolve's runtime check of their signs (an error_if,
            # a host callback) folds away and the executable can be cached
            sol = diffrax.diffeqsolve(diffrax.ODETerm(rhs), diffrax.Tsit5(), 0.0, 1.0,
                                      1.0 / settings.substeps, y, saveat=diffrax.SaveAt(t1=True),
                                      stepsize_controller=controller,
                                      max_steps=settings.max_steps_per_frame, throw=False,
                                      adjoint=diffrax.ForwardMode())
            adaptive = sol.result == diffrax.RESULTS.successful
            y1 = sol.ys[-1]
            if settings.fixed_substeps > 0:
                y1 = jnp.where(adaptive, y1, _fixed_steps(rhs, y, jnp.where(
                    adaptive, 0, settings.fixed_substeps), settings.fixed_substeps))
            return y1, (y1, adaptive | (settings.fixed_substeps > 0), ~adaptive)

        _, (ys, solved, fixed) = jax.lax.scan(frame, y0, jnp.arange(ts.shape[0] - 1))
        ys = jnp.concatenate([y0[None], ys])
        solved, n_fixed = jnp.all(solved), jnp.sum(fixed)
    else:
        def rhs(s, y, args):  # in frames: dy/ds = dt dy/dt
            return jax.tree_util.tree_map(lambda d: dt * d,
                                          unit.vector_field(y, inputs(*_frame_of(s)), refs))

        sol = diffrax.diffeqsolve(diffrax.ODETerm(rhs), kvaerno5(), 0.0,
                                  float(ts.shape[0] - 1), 1.0 / settings.substeps, y0,
                                  saveat=diffrax.SaveAt(ts=np.arange(ts.shape[0], dtype=float)),
                                  stepsize_controller=controller, max_steps=64 * ts.shape[0],
                                  throw=False, adjoint=diffrax.ForwardMode())
        ys, solved = sol.ys, sol.result == diffrax.RESULTS.successful
        n_fixed = jnp.zeros((), int)

    def outputs(s, y):
        if gfm:
            sig = unit.signals(y, inputs(*_frame_of(s)), refs)
            return sig.p_pu, sig.q_pu, sig.omega_pu, sig.delta_rad
        if ibr:
            sig = unit.signals(y, inputs(*_frame_of(s)), refs)
            return sig.p_pu, sig.q_pu, jnp.nan * sig.p_pu, jnp.nan * sig.p_pu
        out, efd, tm, _ = unit.signals(y, inputs(*_frame_of(s)), refs)
        return out.p_pu, out.q_pu, efd, tm

    p, q, efd, tm = jax.vmap(outputs)(jnp.arange(ts.shape[0], dtype=ts.dtype), ys)
    ok = solved & jnp.all(jnp.isfinite(ys))
    if gfm:  # (efd, tm are omega, delta here; the field voltage and torque do not apply)
        nan = jnp.nan * p
        return PlaybackResult(t_s=ts, p_pu=p, q_pu=q, omega_pu=efd, delta_rad=tm, efd_pu=nan,
                              tm_pu=nan, references=refs, ok=ok,
                              fixed_step_intervals=n_fixed)
    if ibr:
        return PlaybackResult(t_s=ts, p_pu=p, q_pu=q, omega_pu=efd, delta_rad=efd, efd_pu=efd,
                              tm_pu=tm, references=refs, ok=ok,
                              fixed_step_intervals=n_fixed)
    m = unit.machine.n_states
    return PlaybackResult(t_s=ts, p_pu=p, q_pu=q, omega_pu=ys[:, m - 1], delta_rad=ys[:, m - 2],
                          efd_pu=efd, tm_pu=tm, references=refs, ok=ok,
                          fixed_step_intervals=n_fixed)


play_back = eqx.filter_jit(_play_back)
"""Jitted: called inside another program (each of a calibration's programs calls it), it is
traced once for them all."""


__all__ = ["PlaybackResult", "PlaybackSettings", "TerminalSeries", "initial_operating_point",
           "play_back", "quiet_frames", "steady_start", "voltage_steps"]
