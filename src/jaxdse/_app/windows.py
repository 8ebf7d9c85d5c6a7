"""Window-by-window judgement of a model playback against a measured disturbance response.

The setting is NERC MOD-026-2 model validation: the playback (the model driven by the
recorded terminal voltage and frequency) must reproduce the recorded active and reactive
power response to a disturbance; the acceptance criteria are the Transmission Planner's.
A whole-record average (sMAPE on P around 0.8 pu, say) hides exactly what a planner looks
at, so the recording is cut into windows as in IEC 61400-27-2 validation (pre-event, event,
post-event) and, per window and channel, this module measures:

* the peak deviation from the pre-event value (measured and simulated),
* the RMS error in % of MBASE (never sMAPE: P, Q and speed deviations cross zero),
* the RMS error after the best integer-sample time shift (a time-stamp offset shows here),
* in the event window, the measurement's dominant electromechanical mode and the replay's
  mode nearest to it in frequency (matrix pencil method).

A replay that swings wider (peak deviation) or rings longer (lower damping ratio, larger
post-event oscillation) than the recording fails, whatever its average error. Host-side
NumPy only: ``event_start``, ``windows``, ``oscillatory_modes`` (``dominant_mode``,
``nearest_mode``), ``window_scores`` and the thresholds in ``WindowCriteria``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Collection, Mapping, Sequence
from typing import NamedTuple

import numpy as np
from threadpoolctl import ThreadpoolController

WINDOW_NAMES = ("pre", "event", "post")
"""Window names, in time order."""
PEAK_SMOOTH_S = 0.1
"""Peak deviations are taken of a centred moving average this long [s]: the peak of raw
samples is biased up by about 3 noise standard deviations; the average cuts that by the
square root of its length and lowers a 1.2 Hz swing by about 2 % (both signals alike)."""


# --------------------------------------------------------------------------------------------
# Criteria
# --------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class WindowCriteria:
    """Pass/fail thresholds of ``window_scores`` (plain float fields: a TOML table fills them).

    The defaults are engineering choices, not NERC numbers (MOD-026-2 leaves the acceptance
    criteria to the Transmission Planner); "% of MBASE" is a channel's value in per unit of
    the machine rating times 100 (see ``mbase_scale`` in ``window_scores``).
    """

    pre_s: float = 5.0
    """Pre-event window length before the onset [s]."""
    event_s: float = 10.0
    """Event window length from the onset [s]: the first swings of electromechanical modes
    (0.1-2 Hz) and the first governor response."""
    post_s: float = 10.0
    """Post-event window length after the event window [s]; ``inf`` = rest of the record."""
    onset_threshold: float = 6.0
    """Onset: departure from the pre-event level in robust standard deviations [-]."""
    max_shift_s: float = 0.5
    """Time shifts searched for the time-aligned error, +- [s] (PMU/SCADA stamps may differ
    by a few frames; larger shifts would start to trade one swing for the next)."""
    max_peak_ratio: float = 1.25
    """Simulated / measured peak deviation in the event window, upper limit [-]: a replay
    that swings 25 % wider than recorded overstates the unit's response."""
    min_peak_ratio: float = 0.5
    """... and lower limit [-]: a replay that moves less than half as much as the unit."""
    min_damping_ratio_fraction: float = 0.75
    """Simulated damping ratio of the dominant mode at least this fraction of the measured
    one [-]: a ring-down fit resolves the damping ratio to about +-10-20 %, so 0.75 leaves
    room for that and still fails a replay that rings a third longer or more."""
    max_damping_ratio_fraction: float = 2.0
    """... and at most this multiple [-]: an over-damped model is optimistic; the looser
    bound because peak and RMS tests also catch a replay that hardly moves."""
    max_mode_frequency_error: float = 0.2
    """|f_sim - f_meas| / f_meas of the dominant mode, upper limit [-]."""
    max_rms_percent_mbase_p: float = 2.0
    """RMS error of active power (channels named P...) per window [% of MBASE]."""
    max_rms_percent_mbase_q: float = 2.0
    """RMS error of reactive power (channels named Q...) per window [% of MBASE]."""
    max_rms_percent_other: float = math.inf
    """RMS error of other channels (speed, voltage) per window [% of their scale]; inf: not
    judged (the voltage is usually the playback's input)."""
    max_post_oscillation_ratio: float = 1.5
    """Simulated / measured oscillation RMS (about a straight line) in the post-event
    window, upper limit [-]: the replay must not keep ringing after the recording settled."""
    min_deviation_percent_mbase: float = 1.0
    """Absolute tolerance that every ratio test also needs exceeded [% of MBASE]: below it a
    difference is within the recording's noise (and a measured mode is not compared)."""
    mode_delay_s: float = 0.2
    """The ring-down fit starts this long after the onset, past the switching transient [s]."""
    mode_match_fraction: float = 0.1
    """Modes are compared only where the replay differs from the recording: an event-window
    RMS error (time-aligned) within this fraction of the measured oscillation RMS means the two
    swing alike, and the ring-down fits' differences are the fits' own (a damping ratio off by
    the 25 % that ``min_damping_ratio_fraction`` allows shows as some 30 % of the oscillation)
    [-]."""
    mode_noise_sigmas: float = 3.0
    """... nor where that error is within this many times the replay's pre-event RMS error,
    the error that noise alone makes where nothing happens (the recorded voltage's noise
    drives the model: through X''d, 0.05 % TVE puts 0.16-0.36 % of MBASE into a playback's Q
    on ACTIVSg2000, ten times the recording's own noise): a difference within 3 sigma of the
    noise is no evidence of another mode, and fits of a sub-1 % oscillation through it disagree
    (one finds a mode, the other none) [-]."""


# --------------------------------------------------------------------------------------------
# Onset and windows
# --------------------------------------------------------------------------------------------

def _as_channels(x, n: int) -> np.ndarray:
    """One or more channels -> (n, k) float array (dict or sequence of 1-D, or (n,)/(n, k)/(k, n))."""
    if isinstance(x, Mapping):
        x = list(x.values())
    if isinstance(x, (list, tuple)):
        x = np.column_stack([np.asarray(c, dtype=float) for c in x])
    x = np.asarray(x, dtype=float)
    if x.ndim == 1:
        x = x[:, None]
    if x.ndim != 2:
        raise ValueError(f"channels must be 1-D or 2-D, got shape {x.shape}")
    if x.shape[0] != n and x.shape[1] == n:
        x = x.T
    if x.shape[0] != n:
        raise ValueError(f"channels have {x.shape[0]} samples, time has {n}")
    return x


def _mad_sigma(a: np.ndarray, axis=None) -> np.ndarray:
    """Robust standard deviation: 1.4826 x median absolute deviation."""
    med = np.median(a, axis=axis, keepdims=True)
    return 1.4826 * np.median(np.abs(a - med), axis=axis)


def event_start(t, x, threshold: float = 6.0, ref_s: float = 1.0, min_samples: int = 3):
    """Time of the event onset in a recording [s], or None when there is none (ambient data).

    Rule (per channel, earliest channel wins): sample i is the onset when the ``min_samples``
    samples from i on all lie more than ``threshold`` robust standard deviations from the
    level of the ``ref_s`` seconds just before i. Level = median of that reference window;
    standard deviation = 1.4826 x its median absolute deviation, floored by the white-noise
    scale of the whole channel (1.4826 MAD of the first differences / sqrt 2) so that a flat
    stretch does not make every flicker an event. Medians ignore a spike; the reference
    window's own spread absorbs the slow wander of ambient data; ``min_samples`` consecutive
    departures reject a single bad sample. An event in the first ``ref_s`` seconds is not
    found.

    t: time [s], increasing, uniformly sampled. x: one channel (n,), several as (n, k) or a
    dict/sequence of 1-D arrays (e.g. P_t and Q_t [pu], or speed). threshold [-], ref_s [s].
    """
    t = np.asarray(t, dtype=float)
    xs = _as_channels(x, t.size)
    if not np.all(np.isfinite(xs)):
        raise ValueError("event_start: channels contain NaN or inf")
    n = t.size
    dt = float(np.median(np.diff(t))) if n > 1 else 1.0
    w = max(10, int(round(ref_s / dt)))
    m = max(1, int(min_samples))
    if n < w + m:
        return None
    best = None
    for c in range(xs.shape[1]):
        y = xs[:, c]
        floor = max(_mad_sigma(np.diff(y)) / math.sqrt(2.0), 1e-12 * max(1.0, float(np.median(np.abs(y)))))
        ref = np.lib.stride_tricks.sliding_window_view(y[:-m], w)   # ref[j] = y[j:j+w], candidate i = j+w
        level = np.median(ref, axis=1)
        sigma = np.maximum(_mad_sigma(ref, axis=1), floor)
        ahead = np.lib.stride_tricks.sliding_window_view(y[w:], m)[: ref.shape[0]]  # y[i:i+m]
        depart = np.all(np.abs(ahead - level[:, None]) > threshold * sigma[:, None], axis=1)
        hits = np.flatnonzero(depart)
        if hits.size:
            i = int(hits[0]) + w
            best = i if best is None else min(best, i)
    return None if best is None else float(t[best])


class Windows(NamedTuple):
    """Index slices into the recording: pre-event, event and post-event window."""

    pre: slice
    event: slice
    post: slice


def windows(t, onset: float, pre_s: float = 5.0, event_s: float = 10.0,
            post_s: float | None = None) -> Windows:
    """Index slices of the pre-event window [onset - pre_s, onset), the event window
    [onset, onset + event_s) and the post-event window [onset + event_s, + post_s) (to the end
    of the record when post_s is None or inf). t: time [s], increasing; onset, *_s: [s].
    Windows are clipped to the record (and may be empty)."""
    t = np.asarray(t, dtype=float)
    i0, i1, i2 = np.searchsorted(t, [onset - pre_s, onset, onset + event_s], side="left")
    to_end = post_s is None or not math.isfinite(post_s)
    i3 = t.size if to_end else int(np.searchsorted(t, onset + event_s + post_s))
    return Windows(slice(int(i0), int(i1)), slice(int(i1), int(i2)), slice(int(i2), int(i3)))


# --------------------------------------------------------------------------------------------
# Dominant mode (matrix pencil)
# --------------------------------------------------------------------------------------------

class Mode(NamedTuple):
    """An oscillatory mode: frequency [Hz], damping ratio [-] (negative: growing) and
    amplitude at the start of the window (units of the signal; zero-to-peak)."""

    frequency_hz: float
    damping_ratio: float
    amplitude: float


NO_MODE = Mode(math.nan, math.nan, math.nan)


ELECTROMECHANICAL_BAND_HZ = (0.1, 3.0)
"""Frequencies of electromechanical modes [Hz]: inter-area (0.1-0.8) and local (0.8-3)."""
MAX_OSCILLATION_DAMPING = 0.3
"""A pole pair damped above this ratio [-] is a decay, not an oscillation: it overshoots by under
37 % and has decayed by e within half a period (e.g. the slow recovery after a step)."""


def oscillatory_modes(t, y, detrend: str = "final", max_order: int = 20, max_samples: int = 600,
                      min_energy_fraction: float = 0.05, fmin_hz: float = 0.05) -> list[Mode]:
    """The oscillatory modes of a response, by the matrix pencil method, most energetic first.

    Method: Y. Hua and T. K. Sarkar, "Matrix pencil method for estimating parameters of
    exponentially damped/undamped sinusoids in noise", IEEE Trans. ASSP 38(5), 1990, in the
    SVD ("total least squares") form of T. K. Sarkar and O. Pereira, IEEE Antennas Propag.
    Mag. 37(1), 1995:

    1. detrend by the window's final value (mean of its last 10 %; ``detrend="mean"``: its
       mean); a window longer than ``max_samples`` is block-averaged (a linear filter: the
       poles of a sum of exponentials keep their frequency and damping, the amplitudes are
       corrected);
    2. Hankel matrix Y (N-L) x (L+1) of the samples, pencil parameter L = N/3; SVD;
    3. model order M = number of singular values above max(1e-8 s_1, tau), tau the optimal
       hard threshold for a noisy low-rank matrix (Gavish & Donoho 2014: omega(beta) x median
       singular value), at most ``max_order``;
    4. poles z = eig(V2^H pinv(V1^H)) of the M leading right singular vectors (V1: last row
       dropped, V2: first row dropped); s = ln(z)/dt; residues by least squares;
    5. a mode is an oscillatory pole (f >= max(fmin_hz, 1 / window length), below 0.45 of the
       sampling rate) whose conjugate pair carries at least ``min_energy_fraction`` of the
       detrended signal's energy in the window.

    t: time [s], uniform; y: response. Returns [Mode(frequency [Hz], damping ratio -Re s/|s|
    [-], amplitude [units of y])], empty without an oscillatory mode (monotone response, pure
    noise, fewer than 12 samples).
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if y.size < 12 or t.size != y.size or not np.all(np.isfinite(y)):
        return []
    dt = float(np.median(np.diff(t)))
    tail = y[-max(1, y.size // 10):]
    y = y - (np.mean(tail) if detrend == "final" else np.mean(y))
    duration = dt * y.size
    k = max(1, math.ceil(y.size / max_samples))        # block-average to at most max_samples
    if k > 1:
        y = y[: (y.size // k) * k].reshape(-1, k).mean(axis=1)
    h = dt * k
    n = y.size
    if n < 12:
        return []
    # One BLAS thread: the matrices are small (about 200 x 100 for a 10 s window at 30 frames/s)
    # and OpenBLAS's threads cost more than they give; on 2 busy cores one SVD took 20-70 ms
    # threaded against 2 ms (0.87 s per unit of jaxdse fleet's window criteria, 0.04 s now).
    with _blas().limit(limits=1, user_api="blas"):
        return _pencil_modes(y, n, dt, k, h, duration, max_order, min_energy_fraction, fmin_hz)


@functools.cache
def _blas() -> ThreadpoolController:
    """The process's thread pools, found once: a ``threadpool_limits`` looks for them in the
    loaded libraries on every call (3 ms, a third of a unit's window criteria)."""
    return ThreadpoolController()


def _pencil_modes(y, n, dt, k, h, duration, max_order, min_energy_fraction, fmin_hz) -> list[Mode]:
    """Steps 2-5 of :func:`oscillatory_modes` on the detrended, block-averaged samples ``y``."""
    L = n // 3
    Y = np.lib.stride_tricks.sliding_window_view(y, L + 1)          # (n-L) x (L+1) Hankel
    _, sv, Vh = np.linalg.svd(Y, full_matrices=False)
    if sv[0] <= 0:
        return []
    beta = min(Y.shape) / max(Y.shape)
    omega = 0.56 * beta**3 - 0.95 * beta**2 + 1.82 * beta + 1.43
    order = int(np.sum(sv > max(1e-8 * sv[0], omega * np.median(sv))))
    order = min(order, max_order, L - 1)
    if order < 2:                                                  # a sinusoid needs two poles
        return []
    V = Vh[:order]                                                 # M x (L+1)
    z = np.linalg.eigvals(V[:, 1:] @ np.linalg.pinv(V[:, :-1]))
    z = z[(np.abs(z) > 1e-12) & (n * np.log(np.abs(z) + 1e-300) < 700)].astype(complex)  # no overflow
    Z = z[None, :] ** np.arange(n)[:, None]                        # Vandermonde n x M
    R = np.linalg.lstsq(Z, y.astype(complex), rcond=None)[0]
    s = np.log(z) / h
    f = s.imag / (2 * np.pi)
    energy = 2.0 * np.abs(R) ** 2 * np.sum(np.abs(Z) ** 2, axis=0)   # of the conjugate pair [y^2 x samples]
    keep = (f >= max(fmin_hz, 1.0 / duration)) & (f < 0.45 / h) & (
        energy >= min_energy_fraction * float(np.sum(y * y)))
    out = []
    for i in sorted(np.flatnonzero(keep), key=lambda i: -energy[i]):
        gain = np.mean(np.exp(s[i] * dt * np.arange(k)))           # block-average gain (1 if k = 1)
        out.append(Mode(float(f[i]), float(-s[i].real / abs(s[i])), float(2.0 * abs(R[i]) / abs(gain))))
    return out


def dominant_mode(t, y, band_hz: tuple[float, float] = ELECTROMECHANICAL_BAND_HZ,
                  max_damping_ratio: float = MAX_OSCILLATION_DAMPING, **options) -> Mode:
    """The dominant electromechanical mode of a response: of its :func:`oscillatory_modes` in
    ``band_hz`` and damped at most ``max_damping_ratio``, the most energetic; ``NO_MODE`` if none.

    A step response's slow recovery shows up as a heavily damped low-frequency pole pair that
    may carry more energy than the swing itself; it is not the oscillation a planner compares.
    """
    for m in oscillatory_modes(t, y, **options):
        if band_hz[0] <= m.frequency_hz <= band_hz[1] and m.damping_ratio <= max_damping_ratio:
            return m
    return NO_MODE


def nearest_mode(t, y, frequency_hz: float, min_energy_fraction: float = 0.01, **options) -> Mode:
    """Of the :func:`oscillatory_modes` of ``y`` (down to ``min_energy_fraction``: the
    counterpart need not dominate the replay), the one nearest in frequency to
    ``frequency_hz`` (the replay's counterpart of a measured mode); ``NO_MODE`` if none."""
    modes = oscillatory_modes(t, y, min_energy_fraction=min_energy_fraction, **options)
    if not modes or not math.isfinite(frequency_hz):
        return NO_MODE
    return min(modes, key=lambda m: abs(m.frequency_hz - frequency_hz))


# --------------------------------------------------------------------------------------------
# Scores
# --------------------------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class ChannelScore:
    """One channel in one window. Deviations and errors in % of MBASE (the channel times
    its ``mbase_scale``); ``shift_s`` > 0: the replay lags the recording."""

    channel: str
    window: str
    samples: int
    peak_deviation_measured: float
    """max |measured - measured pre-event value| in the window, of the ``PEAK_SMOOTH_S``
    moving average [% of MBASE]."""
    peak_deviation_simulated: float
    """The same for simulated (its own pre-event value) [% of MBASE]."""
    rms_error: float
    """RMS(simulated - measured) [% of MBASE]."""
    aligned_rms_error: float
    """RMS error at the best shift within +- max_shift_s [% of MBASE]."""
    shift_s: float
    """That shift [s]: simulated(t + shift) is compared with measured(t)."""
    oscillation_measured: float
    """RMS of measured about its least-squares straight line in the window [% of MBASE]."""
    oscillation_simulated: float
    """The same for simulated [% of MBASE]."""
    mode_measured: Mode = NO_MODE
    """Dominant mode of measured (event window only; amplitude in % of MBASE)."""
    mode_simulated: Mode = NO_MODE
    """Dominant mode of simulated (event window only; amplitude in % of MBASE)."""


@dataclasses.dataclass(frozen=True)
class WindowScores:
    """Result of ``window_scores``: the onset, the windows, the scores and the verdict."""

    onset_s: float | None
    windows: Windows | None
    scores: tuple[ChannelScore, ...]
    passed: bool
    reasons: tuple[str, ...]
    """Why it failed, one sentence per failed test (empty when passed)."""

    def score(self, window: str, channel: str) -> ChannelScore:
        """The score of one channel in one window ("pre", "event" or "post")."""
        for s in self.scores:
            if s.window == window and s.channel == channel:
                return s
        raise KeyError((window, channel))

    def as_dict(self) -> dict:
        """JSON-ready form (NaN -> None)."""
        def num(v):
            return None if isinstance(v, float) and not math.isfinite(v) else v
        rows = []
        for s in self.scores:
            d = dataclasses.asdict(s)
            for key in ("mode_measured", "mode_simulated"):
                d[key] = {k: num(float(v)) for k, v in zip(Mode._fields, getattr(s, key))}
            rows.append({k: num(v) for k, v in d.items()})
        w = None if self.windows is None else {k: [v.start, v.stop]
                                               for k, v in self.windows._asdict().items()}
        return {"onset_s": self.onset_s, "windows": w, "passed": self.passed,
                "reasons": list(self.reasons), "scores": rows}


def _rms(a: np.ndarray) -> float:
    return float(np.sqrt(np.mean(a * a))) if a.size else math.nan


def _aligned(meas: np.ndarray, sim: np.ndarray, sl: slice, max_shift: int) -> tuple[float, int]:
    """Smallest RMS(sim[i + s] - meas[i]) over i in the window, |s| <= max_shift; and s."""
    idx = np.arange(sl.start, sl.stop)
    best = (math.inf, 0)
    for s in range(-max_shift, max_shift + 1):
        j = idx + s
        ok = (j >= 0) & (j < sim.size)
        if np.count_nonzero(ok) < max(2, idx.size // 2):
            continue
        e = _rms(sim[j[ok]] - meas[idx[ok]])
        if e < best[0] - 1e-15 or (abs(e - best[0]) <= 1e-15 and abs(s) < abs(best[1])):
            best = (e, s)
    return best


def _smooth(y: np.ndarray, width: int) -> np.ndarray:
    """Centred moving average over ``width`` samples (shorter at the ends)."""
    if width <= 1:
        return y
    kernel = np.ones(width)
    return np.convolve(y, kernel, mode="same") / np.convolve(np.ones(y.size), kernel, mode="same")


def _oscillation(t: np.ndarray, y: np.ndarray) -> float:
    """RMS about the least-squares straight line (what is left is swing and noise)."""
    if y.size < 3:
        return math.nan
    coef = np.polyfit(t - t[0], y, 1)
    return _rms(y - np.polyval(coef, t - t[0]))


def _rms_limit(channel: str, c: WindowCriteria) -> float:
    name = channel.upper()
    if name.startswith("P"):
        return c.max_rms_percent_mbase_p
    if name.startswith("Q"):
        return c.max_rms_percent_mbase_q
    return c.max_rms_percent_other


def window_scores(t, measured: Mapping[str, Sequence[float]], simulated: Mapping[str, Sequence[float]],
                  mbase_scale: Mapping[str, float], criteria: WindowCriteria = WindowCriteria(),
                  onset: float | None = None, judged: Collection[str] | None = None) -> WindowScores:
    """Judge a playback window by window (pre-event, event, post-event) and channel.

    t: time [s], uniform. measured, simulated: channel name -> samples in per unit (e.g.
    "P_t", "Q_t", and optionally "x2" speed, "V"); the channels present in both are judged.
    mbase_scale: channel -> factor from the channel's unit to % of MBASE (100 for pu on the
    machine base; 100 x S_base / MBASE for pu on a system base S_base; missing: 100).
    onset: event onset [s]; None: ``event_start`` on the measured channels.
    judged: the channels whose tests count (None: all); the others are scored and reported only.

    Per window and channel (``ChannelScore``): peak deviation from the pre-event value
    (median of the pre-event window, each signal its own), RMS error, time-aligned RMS error
    and shift, oscillation RMS about a straight line; in the event window, from ``mode_delay_s``
    after the onset, the measurement's dominant electromechanical mode (``dominant_mode``) and
    the replay's mode nearest to it in frequency (``nearest_mode``), so that the criteria
    compare one mode (without a measured mode: the replay's dominant one). Fails (reasons in words):

    * event window: peak-deviation ratio sim/meas above ``max_peak_ratio`` or below
      ``min_peak_ratio`` (and the difference above ``min_deviation_percent_mbase``);
    * event window: the replay's mode damps below ``min_damping_ratio_fraction`` (rings
      longer) or above ``max_damping_ratio_fraction`` of the measured damping ratio, its
      frequency is off by more than ``max_mode_frequency_error``, or one of the two has a mode
      of more than ``min_deviation_percent_mbase`` amplitude and the other none (the modes
      compared only where the time-aligned error exceeds ``mode_match_fraction`` of the
      oscillation and ``mode_noise_sigmas`` times the pre-event RMS error);
    * post-event window: oscillation RMS ratio above ``max_post_oscillation_ratio`` (and
      the difference above ``min_deviation_percent_mbase``);
    * any window: RMS error above ``max_rms_percent_mbase_p`` / ``_q`` / ``_other``.

    No event in the measured channels: not judged (passed False, with that reason).
    """
    c = criteria
    t = np.asarray(t, dtype=float)
    names = [k for k in measured if k in simulated]
    if not names:
        raise ValueError("window_scores: no channel is both measured and simulated")
    meas = {k: np.asarray(measured[k], dtype=float) for k in names}
    sim = {k: np.asarray(simulated[k], dtype=float) for k in names}
    for k in names:
        if meas[k].shape != t.shape or sim[k].shape != t.shape:
            raise ValueError(f"window_scores: {k} does not have the shape of t {t.shape}")
        if not (np.all(np.isfinite(meas[k])) and np.all(np.isfinite(sim[k]))):
            raise ValueError(f"window_scores: {k} contains NaN or inf")
    if t.size < 2 or np.any(np.diff(t) <= 0):
        raise ValueError("window_scores: t must be increasing with at least two samples")
    if onset is None:
        onset = event_start(t, [meas[k] for k in names], threshold=c.onset_threshold)
    if onset is None:
        return WindowScores(None, None, (), False,
                            ("no disturbance found in the measured channels: a window test needs an event",))
    dt = float(np.median(np.diff(t)))
    win = windows(t, onset, c.pre_s, c.event_s, c.post_s)
    max_shift = int(round(c.max_shift_s / dt))
    width = int(round(PEAK_SMOOTH_S / dt))
    tol = c.min_deviation_percent_mbase
    scores: list[ChannelScore] = []
    reasons: list[str] = []
    for k in names:
        scale = float(mbase_scale.get(k, 100.0))
        m, s = meas[k] * scale, sim[k] * scale                       # % of MBASE
        m_avg, s_avg = _smooth(m, width), _smooth(s, width)           # for the peaks
        first = win.event.start if win.event.start < t.size else t.size - 1
        m0 = float(np.median(m[win.pre])) if win.pre.stop > win.pre.start else float(m[first])
        s0 = float(np.median(s[win.pre])) if win.pre.stop > win.pre.start else float(s[first])
        noise = 0.0    # the replay's RMS error before the event (noise alone)
        for name, sl in zip(WINDOW_NAMES, win):
            ms, ss, ts = m[sl], s[sl], t[sl]
            if ms.size == 0:
                continue
            aligned, shift = _aligned(m, s, sl, max_shift)
            mode_m = mode_s = NO_MODE
            if name == "event":
                fit = ts >= onset + c.mode_delay_s
                mode_m = dominant_mode(ts[fit], ms[fit])
                mode_s = (nearest_mode(ts[fit], ss[fit], mode_m.frequency_hz)
                          if math.isfinite(mode_m.frequency_hz) else dominant_mode(ts[fit], ss[fit]))
            sc = ChannelScore(k, name, int(ms.size), float(np.max(np.abs(m_avg[sl] - m0))),
                              float(np.max(np.abs(s_avg[sl] - s0))), _rms(ss - ms), aligned, shift * dt,
                              _oscillation(ts, ms), _oscillation(ts, ss), mode_m, mode_s)
            scores.append(sc)
            if name == "pre":
                noise = sc.rms_error
            if judged is None or k in judged:
                reasons += _judge(sc, c, _rms_limit(k, c), tol, noise if name == "event" else 0.0)
    return WindowScores(float(onset), win, tuple(scores), not reasons, tuple(reasons))


def _judge(sc: ChannelScore, c: WindowCriteria, rms_limit: float, tol: float,
           noise: float = 0.0) -> list[str]:
    """The failed tests of one channel in one window, in words."""
    out = []
    k, w = sc.channel, sc.window
    where = {"pre": "pre-event", "event": "event", "post": "post-event"}[w]
    if w == "event":
        pm, ps = sc.peak_deviation_measured, sc.peak_deviation_simulated
        ratio = ps / pm if pm > 0 else math.inf
        if ratio > c.max_peak_ratio and ps - pm > tol:
            out.append(f"{k}: the replay's peak deviation in the event window is {ratio:.1f}x the measured "
                       f"one ({ps:.2f} against {pm:.2f} % of MBASE; limit {c.max_peak_ratio:g}x)")
        elif ratio < c.min_peak_ratio and pm - ps > tol:
            out.append(f"{k}: the replay's peak deviation in the event window is {ratio:.2f}x the measured "
                       f"one ({ps:.2f} against {pm:.2f} % of MBASE; limit {c.min_peak_ratio:g}x)")
        out += _judge_modes(sc, c, tol, noise)
    if w == "post":
        om, os_ = sc.oscillation_measured, sc.oscillation_simulated
        ratio = os_ / om if om > 0 else math.inf
        if ratio > c.max_post_oscillation_ratio and os_ - om > tol:
            out.append(f"{k}: the replay still oscillates after the event, {ratio:.1f}x the measured "
                       f"post-event oscillation ({os_:.2f} against {om:.2f} % of MBASE RMS; "
                       f"limit {c.max_post_oscillation_ratio:g}x)")
    if sc.rms_error > rms_limit:
        msg = f"{k}: RMS error {sc.rms_error:.1f} % of MBASE in the {where} window (limit {rms_limit:g} %)"
        if sc.shift_s != 0 and sc.aligned_rms_error <= rms_limit:
            msg += (f"; shifted by {sc.shift_s:+.3g} s it is {sc.aligned_rms_error:.1f} %: "
                    "check the time stamps")
        out.append(msg)
    return out


def _judge_modes(sc: ChannelScore, c: WindowCriteria, tol: float, noise: float = 0.0) -> list[str]:
    """Dominant-mode tests of the event window (damping ratio, frequency, presence); none where
    the replay swings as the recording does (``mode_match_fraction``), or differs from it no
    more than noise does (``mode_noise_sigmas`` x ``noise``, the pre-event RMS error)."""
    if sc.aligned_rms_error <= max(c.mode_match_fraction * sc.oscillation_measured,
                                   c.mode_noise_sigmas * noise):
        return []
    k = sc.channel
    fm, zm, am = sc.mode_measured
    fs, zs, as_ = sc.mode_simulated
    has_m, has_s = math.isfinite(fm), math.isfinite(fs)
    if has_m and has_s:
        if am <= tol and as_ <= tol:                                  # both within noise
            return []
        out = []
        low = zm * c.min_damping_ratio_fraction if zm > 0 else zm
        high = zm * c.max_damping_ratio_fraction if zm > 0 else math.inf
        if zs < low:
            out.append(f"{k}: the replay's mode damps at {100 * zs:.1f} % against {100 * zm:.1f} % measured, "
                       f"so it oscillates longer (limit: at least {100 * c.min_damping_ratio_fraction:.0f} % "
                       "of the measured damping ratio)")
        elif zs > high:
            out.append(f"{k}: the replay's mode damps at {100 * zs:.1f} % against {100 * zm:.1f} % measured "
                       f"(limit: at most {c.max_damping_ratio_fraction:g}x the measured damping ratio)")
        if abs(fs - fm) > c.max_mode_frequency_error * fm:
            out.append(f"{k}: the replay's mode is at {fs:.2f} Hz against {fm:.2f} Hz measured "
                       f"(limit: within {100 * c.max_mode_frequency_error:.0f} %)")
        return out
    if has_m and am > tol:
        return [f"{k}: the recording oscillates at {fm:.2f} Hz (damping {100 * zm:.1f} %, "
                f"{am:.2f} % of MBASE) and the replay shows no oscillatory mode"]
    if has_s and as_ > tol:
        return [f"{k}: the replay oscillates at {fs:.2f} Hz (damping {100 * zs:.1f} %, {as_:.2f} % of MBASE) "
                "and the recording shows no oscillatory mode"]
    return []
