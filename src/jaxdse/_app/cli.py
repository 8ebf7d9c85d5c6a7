"""Command-line interface: ``jaxdse run CONFIG.toml``, ``sweep``, ``tune``, ``fleet FLEET.toml``,
``validate CONFIG.toml``, ``check CASE.toml``, ``pmu-sim RECORDING.toml``
and ``demo``.

User mistakes end in a one-line error on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

DESCRIPTION = """\
jaxdse estimates the rotor angle, speed deviation and E'q of a synchronous generator and its
inertia H and damping D (a2 = ws/2H, a1 = ws D/2H) from PMU recordings, following
Lorenz-Meyer, Suchantke & Schiffer (arXiv:2203.14623): mapping substation phasors to the
machine terminal, an algebraic observer, a DREM parameter estimator, an I&I speed observer
and event playback.

a planner's path through a PSS/E case (.raw revisions {RAW_REVISIONS}, .dyr):
  jaxdse check CASE.toml --out DIR      1. does every unit start at rest and settle? no recordings
  jaxdse fleet FLEET.toml --out DIR     2. H and D of every plant from PMU recordings; model validation
  jaxdse validate FLEET.toml --out DIR  3. validate and calibrate the units' own .dyr records (MOD-026-2)
  jaxdse monitor MONITOR.toml           4. H and D of every unit each second from live PMU streams
  (`jaxdse pmu-sim` serves a recording as a live C37.118 stream to try the monitor on.)

examples:
  jaxdse demo --out jaxdse_demo                       built-in simulated data, truth known
  jaxdse run examples/csv_positive_sequence.toml      your own recording (CSV/COMTRADE/MAT)
  jaxdse run --help                                   what goes in and what comes out
  jaxdse sweep examples/sweep_tune.toml               many observer configurations at once
  jaxdse tune examples/sweep_tune.toml                tune lambda, c, K, gamma, k by gradient

compilation cache: the first run of a recording length and plant structure compiles the
estimator (tens of seconds); the compiled code is kept in JAX's persistent cache, so later
runs skip that. The cache lives in $JAXDSE_CACHE_DIR, else $XDG_CACHE_HOME/jaxdse/xla, else
~/.cache/jaxdse/xla; JAXDSE_CACHE_DIR=off turns it off.
"""
CACHE_ENV = "JAXDSE_CACHE_DIR"

DEMO_HELP = """\
Simulate the paper's plant (machine, exciter, governor, auxiliary load, tap-changing
transformer, HV line, ambient grid fluctuations and one event) at 90 % and 45 % of rating,
run the estimator on both with the same configuration (auto- and cross-validation) and write:

  DIR/summary.json             final a1, a2, H, D, a2 reference, convergence time, sMAPE
  DIR/estimates_<name>.csv     trajectories (time_s, delta_rad, x2_hat_rad_s, ...)
  DIR/convergence_<name>.png   a1_hat and a2_hat against their references
  DIR/x2_<name>.png            x2 observed vs measured
  DIR/playback_<name>.png      measured vs playback x2, I_t, P_t, Q_t

example:
  jaxdse demo --out demo_out
"""


RUN_HELP = """\
Read the PMU recording(s) named in CONFIG.toml and, for every [[generator]]: screen the data
(spikes, invalid frames, unit and set-up mistakes), map the phasors to the machine terminal,
run the algebraic observer, the governor model and the paper's online DREM/I&I estimator,
then identify H and D from the whole recording at once (with 95 % intervals), play the
event back with them, and give a verdict per parameter. The unit's headline is H's:

  identified          H within +-10 % at 95 % confidence, D not negative, and H stays inside
                      that interval with D fixed at 0 and without the governor correction
  weakly identified   interval wider than +-10 %, D < 0 with confidence, or H rests on the
                      fitted D or on correcting the governor model (the reason says which)
  not identified      the data do not tell H apart (interval too wide or unbounded)
  failed              offline, a solver failure, H <= 0 or a diverging playback

D and the governor correction get their own verdicts, with findings in words (D < 0: the
3rd-order model lumps excitation and stabiliser damping into D; the data ask for a governor
response N % below the model's). The online DREM/I&I estimate is reported beside H, as a note.

Writes:
  DIR/summary.json             per recording: H [s] with its 95 % interval, D, the verdict
                               and its reasons, the online (DREM) estimate beside it, the
                               playback sMAPE of x2, I_t, P_t, Q_t, a "data_quality" section
                               (what was read, screened, bridged, split); and for the run:
                               the jaxdse version, the sha256 of the config and every input
                               file, the full plant, observer and settings used
  DIR/estimates_<name>.csv     trajectories: time_s, delta_rad, x2_hat_rad_s, a1_hat, a2_hat,
                               E'q, Te, Tm, Ef, measured and playback x2/I_t/P_t/Q_t
  DIR/convergence_<name>.png   online a1_hat, a2_hat with the identified value and interval
  DIR/x2_<name>.png            x2 estimated vs measured
  DIR/playback_<name>.png      measured vs playback x2, I_t, P_t, Q_t; the title says the verdict

The config describes the measurement (file, format csv|comtrade|mat, layout, column names,
units, bases, current direction, PMU location), the plant (line, transformer, aux, machine,
governor: required as the location needs them, or plant_defaults = "paper") and the
observer (paper Table I by default). See examples/*.toml.

Exit status: 0 on success; 2 on bad input (missing file or column, unknown key, wrong unit,
implausible data, missing plant data) with a one-line message naming the file, column/key
and row; 3 with --strict when any unit is not identified. Units that are not identified
get a one-line warning on stderr either way.

example:
  jaxdse run examples/csv_positive_sequence.toml --out out/
  jaxdse run examples/isone_mat.toml --strict   # exit 3 unless every unit is identified; needs ../shared/data
"""


SWEEP_HELP = """\
Run the estimator for many observer configurations at once (one compiled, vmapped call per
chunk of configurations, sharded over all devices) on the recording of every [[generator]]
in CONFIG.toml, and write

  DIR/sweep.csv    one row per configuration and generator: the swept values, final a1,
                   a2, H, D, convergence time, flags and sMAPE (x2 observer and playback)

The [sweep] section of the config says what to vary:

  [sweep]
  mode = "grid"                      # every combination; or "random": log-uniform draws
  draws = 64                         # random mode only
  chunk = 256                        # configurations per compiled call (memory, progress)
  parameters = { gamma = [425, 850, 1700, 3400], lambda1 = [4.0, 8.0] }
  # random mode: parameters = { gamma = [200, 5000], k_obs = [2, 20] }   (low, high)

"gamma" sets gamma1 = gamma2; any ObserverConfig field may be swept. Only final values are
kept (Settings keep = "final"), so memory does not grow with the recording length;
convergence times are resolved to one block (50 samples). Add `integrator = "fast"` under
[settings] for Heun steps (about 10x the throughput, a2 within ~0.4 % of adaptive steps).

example:
  jaxdse sweep examples/sweep_tune.toml --out sweep_out/
"""

TUNE_HELP = """\
Tune the observer by gradient descent through the whole pipeline (optimistix BFGS on the
logarithms of the parameters, bounded to max_factor of the start). Generators with
role = "auto" are the training recordings, role = "cross" ones are held out and scored
before and after. The loss adds, per recording:

  x2         mean squared error of x2_hat vs the measured x2 after burn_in_s, / variance
  playback   the same for the playback P_t and x2
  parameter  (where a2_reference is given, e.g. synthetic data) time averages of
             ((a2_hat - a2)/a2)^2 and of a smooth count of the time outside +-band,
             plus a soft last exit time from the band (the 8-norm of t/T times outside)

The gradient is taken in forward mode (one pass carrying one tangent per parameter) or
reverse mode (back through the checkpointed time loop): autodiff = "auto" uses forward
mode up to 8 training recordings, where it is the cheaper one.

  [tune]
  parameters = ["lambda1", "lambda2", "lambda3", "c1", "c2", "k_ext", "gamma1", "gamma2", "k_obs"]
  max_steps = 30
  max_factor = 10.0
  autodiff = "auto"        # or "fwd", "bwd"
  weights = { x2 = 1.0, playback = 1.0, parameter = 1.0, burn_in_s = 10.0, band = 0.01 }

Generators may have different plants (each keeps its own). Writes DIR/tune.json (losses,
history, start, tuned and recommended values) and DIR/tuned_observer.toml (an [observer]
section to paste into a config). The tuned values are recommended only if the held-out loss
(the training loss when no role = "cross" generator is given) got better; otherwise
tuned_observer.toml keeps the start values and the command says so. A non-finite loss is an
error (exit 1). A progress bar shows the loss per step.

example:
  jaxdse tune examples/sweep_tune.toml --out tune_out/
"""


FLEET_HELP = """\
Estimate H and D of every plant of a PSS/E case from PMU recordings, in one batched call, and
write a model-validation report a planner can file. Plant data come from the case: the
in-service units with a machine record on a bus form one plant on their summed MBASE; its
reference H is the MBASE-weighted H of those records; its governor is the MBASE-weighted sum
of the units' own governor records (units without one hold their torque). Models the .dyr has
beyond these are listed, not fatal. A bus whose units have inverter-based records (REGCA1 or
REGCB1 + REECA1, REECB1 or REECCU1, optionally REPCA1) and no machine
record is an inverter-based plant: no rotor, so no H
or D ("not applicable"); with model = "dyr" its records are played back and P against
frequency, Q against voltage judged by the same windows (MOD-026-2). A grid-forming converter
(an ANDES REGCV1 or REGCV2 record: `bus 'REGCV1' id Tc kw kv M D ra xs Kpvd Kivd Kpvq Kivq KpId
KiId KpIq KiIq /`; a WECC REGFM_A1 or REGFM_B1 in PSS/E's order, `bus 'REGFMA1' id VFlag QVFlag
TPf TQf TVf Imax Emax Emin Pmax Pmin Qmax Qmin mp mq kppmax kipmax kpqmax kiqmax kpv kiv /` or
`bus 'REGFMB1U' id wFlag VdrpFlag QVFlag PQFlag FFlag ESFlag mq kpv kiv mp Dwmax Dwmin kpPLL kiPLL
DwPLLmax DwPLLmin Tp H D1 D2 wD ImaxSS kf kI ImaxF TPf TQf TVf TIf Ke VPLLfrz /`, the coupling
impedance the generator's ZSORCE) has a virtual rotor: with model = "dyr" its H and D (REGCV1:
M/2 and D; REGFM_A1: TPf/(2 mp) and 1/mp; REGFM_B1: H and 1/mp + D1) are fitted to the
recording by its playback, with an interval and a verdict.

{FLEET_MODELS}

FLEET.toml (paths relative to it):
  [case]         raw = "case.raw" (PSS/E rev {RAW_REVISIONS}), dyr = "case.dyr"; q_axis_circuits = false
                 leaves every GENROU/GENTPJ's q-axis circuits out of the estimator, for comparison
                 (records are used as given where their equations can be evaluated; odd values
                 are listed as data warnings on the unit's page)
  [measurement]  as in `jaxdse run`: file (one file, or a list of files sharing one time
                 axis: columns are then "<file stem>/<column>"), format, units, s_base_mva,
                 location = "terminal" | "hv" (HV side of the step-up transformer in the .raw)
  [channels]     how each plant's columns are found, by pattern (* = any text):
                   layout = "per_machine"     one plant per machine; {bus}, {id} fill names:
                     time = "time_s", v_mag = "B{bus}_G{id}/VM", ... i_ang, frequency (optional)
                   layout = "step_up_branch"  one plant per generator bus; the bus columns
                     ({bus}) and the one branch that leaves the bus ({branch}):
                     v_mag = "BusVolMag/{bus}|*", i_mag = "LinCurMag/{branch}", ...,
                     branch = "{from}|*|{to}|*" (how a branch name shows its end buses; the
                     end at the plant sets the current direction)
                   name = "B{bus}_G{id}" (optional)
  [[unit]]       or an explicit list instead of [channels]: name, bus, ids = ["1", ...]
                 (default: every in-service unit of the bus), columns = {time, v_mag, v_ang,
                 i_mag, i_ang, frequency}, current_direction
  [criteria]     the model validation's pass/fail limits (the Transmission Planner's,
                 NERC MOD-026-2), the playback by window (pre-event, event,
                 post-event): max_peak_ratio (1.25),
                 min_damping_ratio_fraction (0.75), max_rms_percent_mbase_p (2),
                 max_rms_percent_mbase_q (2), event_s (10), ... (see fleet.json)
  [observer] [settings] [identify]   as in `jaxdse run`;  [output] figures = true
  [playback]     model = "dyr" (default: each unit's own PSS/E records, machine, exciter,
                 stabiliser and governor, listed below; the recorded terminal voltage
                 imposed as PSS/E PLBVFU1 does; a unit with another model plays back the
                 surrogate and its page says which record) | "surrogate" (3rd-order,
                 identified H and D; validates P/frequency only); solver = "tsit5" | "kvaerno5";
                 substeps (first step 1/substeps of a frame; adaptive Tsit5, rtol 1e-7);
                 ke_zero = "psse" | "literal" (a DC exciter's KE = 0)
  [inertia]      the system inertia per area (an empty section: every default): areas =
                 "area" | "zone" | {NAME = [buses]}, status = "raw" | "states.csv" (time_s,
                 unit "BUS_ID", online), model_uncertainty (0.15), measured_errors = "shared" |
                 "independent", largest_loss_mw, f0_hz, stale_s, floor_MWs, online_current_pu,
                 grid_forming = {"BUS_ID" = virtual H}; writes DIR/inertia.csv, inertia.png and
                 fleet.json "inertia" (one value per recording; README "System inertia")

{SIMULATED}

DIR gets:
  DIR/report.html            fleet page: two results per unit, never merged: H's verdict and
                             the model validation; units to look at first, overview figure of
                             H with 95 % intervals against the .dyr H, sortable table
  DIR/units/<name>.html      one page per unit: H's verdict and its reasons in words, H, D and
                             their intervals; the model validation (pass/fail/not judged, the
                             model played back) with measured vs simulated x2, I_t, P_t, Q_t
                             and their residuals, errors and paired modes over the pre-event,
                             event and post-event windows; the plant, data quality, provenance
  DIR/overview.png, DIR/units/<name>.png   the figures of these pages
  DIR/fleet.json             "units": name, H_s, H_ci95, H_reference_s, H_error_percent,
                             verdict, reasons (H's), D, interval parts, validation {result,
                             model, scope, reasons, windows}, governor models, data quality,
                             ...; "skipped": plants not estimated, why
  DIR/fleet.csv, DIR/report.md   the table

Exit status: 0 on success; 2 on bad input (missing .raw/.dyr or recording, unknown key, no
plant found) with a one-line message; 3 with --strict when any unit is not identified (an
inverter-based plant, which has no H, is not counted).

example:
  jaxdse fleet experiments/naspi_osl_case1/fleet.toml --out osl_fleet/   # needs ../shared/data
  jaxdse fleet experiments/andes_bench/fleet_ieee14.toml --out ieee14/ --strict
"""


VALIDATE_HELP = """\
Validate and calibrate the planner's own model (NERC MOD-026-2): each one-unit plant's PSS/E
records are played back against the recordings (the recorded terminal voltage imposed, PSS/E
PLBVFU1 convention), their parameters ranked by how well these events identify them
(normalised sensitivities of P and Q by forward-mode autodiff; Fisher information:
Cramer-Rao half-widths, variance inflation), and the identifiable ones calibrated on all
events jointly by bounded Levenberg-Marquardt (the same integrator as the playback), with
95 % intervals. Parameters the events cannot identify stay at their .dyr value, and the page
says so. A calibration never makes the model worse: a parameter changes in calibrated.dyr only
where the events reject its .dyr value (outside its 95 % interval) and the joint error falls by
more than the noise; one that would make any event worse beyond the noise is refused, and the
page and console say why; otherwise the record is "consistent with the .dyr".

CONFIG.toml is a fleet file (see `jaxdse fleet --help`) with, optionally:
  [calibrate]    events = ["line_trip.csv", ...]   more recordings of the same plants (same
                   columns as [measurement]); all events are fitted jointly
                 parameters = ["H", "KA", "R"]     default: H, D, the exciter's main gain and
                   time constant, the governor's droop (IEEEG1: K) and main time constant
                 bounds = {H = [2.0, 8.0], KA = [10, 400]}   default [x/4, 4x]; D [0, 20]
                 max_relative_ci (0.05) calibrate only what the events fix within +-5 %
                 noise_floor_pu (0.001), bound_factor (4)
                 model_error (0.01)  the .dyr playback's own relative error, added to every
                   parameter's interval (noise alone covers H in 78 % on the bench)
                 input_filter_hz (0: off)  low-pass the imposed voltage inside the fit (PMU
                   noise on V biases H; a voltage-angle jump the step detector misses smears)
  [playback]     substeps, solver, ke_zero (model = "dyr" is implied)

DIR gets:
  DIR/report.html, DIR/units/<name>.html   per unit: P/f and Q/V overlays of the measurement,
                 the .dyr model (before) and the calibrated model (after), per event, with
                 residual panels; the error before and after by event; the sensitivity
                 ranking; fitted values with 95 % intervals, and what was filed and why
  DIR/calibrated.dyr    only the changed records, PSS/E syntax (read back by jaxdse)
  DIR/validate.json     everything above as numbers

Exit status: 0 on success; 2 on bad input, with a one-line message.

example:
  jaxdse validate experiments/andes_bench/validate_npcc.toml --out npcc_validate/
"""


PMU_SIM_HELP = """\
Serve a recording as a live IEEE C37.118.2-2011 PMU stream, to test a monitor or a PDC on
this machine. Every [[generator]] of a run configuration, or every plant of a fleet file (its
[case], [measurement] and [channels]), is one PMU station of one concentrator stream, read and
conditioned as `jaxdse run` and `jaxdse fleet` read it (units, gaps, screening). Each station
sends V1 and I1 (positive-sequence voltage, and current out of the plant: V phase to neutral
and A where the measurement gives v_base_kv, else per unit), FREQ (measured, or derived from
the voltage angle) and DFREQ; the header frame says which.

Time stamps lie on the recording's reporting grid (its frame rate and sub-second phase): from
the next whole second (--start now), at the recording's own time (--start recording: its
timestamps, or its time column read as seconds since 1970), or from a given time (ISO 8601 or
seconds since 1970). Frames leave as their time comes; --speed X sends X times faster, the time
stamps unchanged. The recording starts when the first client turns data on (--free-run: at
once) and its end ends the stream (--loop repeats it, the grid going on). Parts of the
recording between long gaps keep their gap.

A client uses the standard's command frames (TCP; --udp for UDP both ways): send CFG-2 (or
CFG-1, CFG-3, the header), turn data on, turn data off; frames it does not understand, or for
another IDCODE, are ignored. The simulator listens on 127.0.0.1 only unless --host says
otherwise, serves at most 16 clients, and drops (and counts) the frames of a client that does
not keep up.

Faults (--fault, repeatable): KIND[=VALUE]@START[+DURATION][:STATION], START and DURATION in
seconds of stream time from the first frame; without +DURATION, the one frame at START;
without :STATION, every station.
  error, pmu-error, test, absent      STAT data error 11, 01, 10 (absent: also NaN or 0x8000)
  sync, sorting, trigger[=REASON]     STAT bit 13, 12, 11 (and its trigger reason, 0-15)
  config-bit, modified                STAT bit 10, 9
  time-quality[=0-7], unlocked[=0-3]  STAT bits 8-6, 5-4 (default 7 and 3)
  clock[=0-15]                        message time quality in FRACSEC (default 15, clock failure)
  drop                                frames not sent
  late=SECONDS                        frames sent SECONDS late (out of order)
  stale                               the frame before START repeated (a PDC holding the last
                                      value), timestamps and STAT running on
  crc                                 frames with a wrong CRC
  config-change[=LEAD]                STAT bit 10 for LEAD s (default 60), then a new
                                      configuration (phasors float <-> integer, CFGCNT + 1)
  disconnect                          every client's connection closed

On start it prints "pmu-sim listening on tcp HOST:PORT (...)" (with --port 0, the port the
system chose). Exit status: 0 at the recording's end, after --duration or on Ctrl-C; 2 on bad
input (the recording, a fault, the format) with a one-line message.

examples:
  jaxdse pmu-sim experiments/naspi_osl_case1/fleet.toml --port 4712   # needs ../shared/data
  jaxdse pmu-sim examples/csv_positive_sequence.toml --port 0 --speed 10 --loop --duration 60 \\
      --format int,rect --fault drop@30+2 --fault error@40+5 --fault config-change=5@60
"""


MONITOR_HELP = """\
Live inertia monitoring: each unit's H and D, with their 95 % intervals, every update_s from
the PMU streams an operator's PDC already receives (IEEE C37.118.2-2011, TCP or UDP; or STTP,
IEEE 2664, with the optional extra: pip install jaxdse[sttp]).

MONITOR.toml:
  fleet = "fleet.toml"     # a fleet file or a run configuration: the plants, their bases and
                           # the estimator's settings ([observer], [settings], [identify])
  update_s = 1.0           # a new estimate per unit every update_s seconds
  window_s = 120.0         # ... fitted on the last window_s seconds (first one after window_s)
  record = true            # write the stream as used, for replay (false: archived elsewhere;
                           # its CSV text costs a core at 5,000 units and 30 frames/s)
  [[stream]]               # one per PMU or PDC (or a single [stream] table)
  host = "127.0.0.1"
  port = 4712              # (STTP: 7165 by default)
  protocol = "c37.118"     # or "sttp": subscribe to an STTP publisher (TCP)
  idcode = 1
  transport = "tcp"        # or "udp" (C37.118 only)
  reorder_s = 0.2          # frames held this long for late ones
  timeout_s = 5.0          # a silent connection is made again (back-off 0.5 s to 10 s)
  current_direction = "out_of_plant"
  frequency = "stream"     # the stations' FREQ; "angle": derived from the voltage angle
  frame_rate_hz = 0        # STTP: the reporting rate (0: the devices' FramesPerSecond)
  units = ["G1", "G2"]     # the units this stream carries (default: all, with one stream)
  [stream.stations]        # unit -> station name, where the name is not the unit's own
  G1 = "PMU_PLANT_A"
  [alarm]
  h_below_s = 2.0          # an alarm when an identified H falls below this
  hysteresis = 0.05        # ... cleared when it rises 5 % above it
  [publish]                # the results as a C37.118 stream (a "virtual PMU") for a PDC
  port = 4713              # or a historian: per unit the analogs H, H_LO, H_HI, D, AGE;
  idcode = 7734            # STAT 01 not excited, 11 failed, trigger bit: H alarm
  protocol = "c37.118"     # or "sttp": an STTP publisher (port 7166 by default) of the point
                           # tags UNIT:H, UNIT:H_LO, UNIT:H_HI, UNIT:D, UNIT:AGE, UNIT:STATE
                           # (0 identified, 1 weakly, 2 not excited, 3 failed), UNIT:ALARM
  [view]                   # a live web page: H with its interval over time per unit
  port = 8050
  [inertia]                # the system inertia per area every update_s (else the fleet
  largest_loss_mw = 1000.0 # file's [inertia]; keys as in `jaxdse fleet --help`): lines
  update_s = 1.0           # {"t", "area", "E_MWs", "E_ci95", "measured_share",
                           # "E_commitment_MWs", "rocof_hz_per_s", "units_online",
                           # "units_measured"} in updates.jsonl, one per area and "system"
  (tile = K repeats the units K times, named as `jaxdse pmu-sim --tile K` names them:
   capacity tests.)

STTP input: per station (the unit's name or its [stream.stations] name) the point tags
STATION:V1_MAG, STATION:V1_ANG, STATION:I1_MAG, STATION:I1_ANG (angles in degrees, magnitudes in
the units `jaxdse pmu-sim` serves: V and A where the fleet gives v_base_kv, else pu), and
optionally STATION:FREQ [Hz] and STATION:STAT (the C37.118 STAT word); points are grouped into
frames by timestamp on the reporting grid (within 1 ms), and STTP's bad-quality flags make a
sample unusable.

Per unit, the online identification runs chunk by chunk on the stream (the regression of
`jaxdse run`'s [identify], its sums kept per update_s: the cost per frame does not grow with
the window). Frames are placed by their timestamps on the reporting grid, never by arrival; a
sample with a STAT data error, lost sync, NaN or an implausible value is not used; gaps up to
the measurement's max_gap_s are bridged, longer ones restart the unit's estimator; a new
configuration re-maps the stations and restarts their estimators. A window that does not
excite H (ambient data) says "not excited" and gives no number; the last identified H stays
in the line with its age.

--out DIR gets updates.jsonl (one line per unit and update: t [s since 1970, the window's last
frame], unit, H_s, H_ci95, D, D_ci95, verdict, reasons, age_s, last_H_s, alarm, delay_s,
wall_delay_s), the stream as the monitor used it (recording_*.csv) with replay.toml (unless
record = false), and monitor.json: per stream its counters (data frames, frames used, grid
slots without a frame, late, repeated and off-grid frames, disconnects, the decoder's counts;
"counters" says what each counts) and its pace (stream seconds per wall second), and the delay
from a frame's timestamp to its estimate, measured on the stream's own clock in seconds of
stream time (the same at any pmu-sim --speed) and in wall seconds. While a unit's window
fills, a line every 5 s says how far along it is and what it waits for. `jaxdse run
DIR/replay.toml` replays the recording through the file readers: the same estimates.

Listens only for [publish] and [view], on 127.0.0.1 unless their host says otherwise. Exit
status 0 after --duration or on Ctrl-C; 2 on bad input with a one-line message.

examples:
  jaxdse pmu-sim examples/csv_positive_sequence.toml --port 4712 --speed 5 &
  jaxdse monitor examples/monitor.toml --out live --duration 70     # then http://127.0.0.1:8050/
  jaxdse run live/replay.toml --out replayed
  jaxdse pmu-sim experiments/naspi_osl_case1/fleet.toml --port 4712 &      # needs ../shared/data
  jaxdse monitor experiments/monitor/osl_monitor.toml --out osl --duration 95
"""


CHECK_HELP = """\
The first thing to run on a PSS/E dynamic case: does every unit (synchronous machines and
inverter-based plants) start at rest and settle after a small disturbance, with the records as
they are? No recordings needed.

Every in-service generator with a machine record in the .dyr (a synchronous unit) gets its own
model from its records (machine, exciter, stabiliser, governor: the models listed below),
initialised from the power flow at its terminal (the .raw PG, QG on MBASE and the
bus voltage VM, VA), and two runs with the terminal voltage imposed, as `jaxdse fleet` plays a
recording back (PSS/E PLBVFU1):

  held   the voltage held: every state derivative at t = 0 below 1e-6 (pu/s), P and Q at
         20 s within 1e-5 pu of the power flow
  step   the voltage stepped by 2 % at 1 s, Vref moved with it (the imposed voltage leaves the
         regulator's loop open: a regulator with integral action would otherwise wind up to
         its limit and slip poles); bounded (speed within 5 %, rotor angle within pi: no pole
         slipped) and settled at 21 s: over the last 5 s P and Q within 10 % of the range they
         span after the step (at least 0.001 pu) of their final value, speed within 1e-4 pu,
         every state derivative below 1e-2

Outcome per unit:
  pass            both runs as above, every record simulated
  data problem    a record whose values cannot be simulated (an inverted limit, a negative time
                  constant: the model's own checks name the CON and its value), or whose initial
                  operating point needs a signal outside the record's limits, e.g.
                  "IEEEG1 on bus 2057 id '1' (case.dyr line 124): GV0 = TM0/(K1 + K3 + K5 + K7)
                  = 1.949 above PMAX = 0.5207 (K1 + K3 + K5 + K7 = 0.3407)": the record's own
                  values show that the unit cannot hold its power flow
  not supported   a record of a model jaxdse does not simulate (named)
  fail            every record simulated and no value at fault, yet not steady or not settled
                  (the reasons give the numbers)
Units of one model structure run in one compiled, vmapped call.

Inverter-based plants (REGCA1 or REGCB1 + REECA1, REECB1 or REECCU1, optional REPCA1, optional
type-3 wind mechanics WTTQA1, WTPTA1, WTARA1, WTDTA1) get the held run, the 2 % voltage step
(REECx Vref0/Vref1 and REPCA1 Vref moved with it) and a 0.1 Hz frequency step (the plant
controller's droop); data problem where the power flow crosses PMAX/PMIN, QMAX/QMIN, IMAX/Imax,
VMAX/VMIN (VFLAG = 0) or REECCU1's SOC limits, at the start or within the runs (REECCU1's state
of charge integrates P and is left out of the at-rest test).
A step still settling at 21 s with every mode decaying is a note (its time constant), and so is
the voltage step of QFLAG = 1 with VFLAG = 1 (its voltage loop closes only through the
network: open with the voltage imposed). ANDES's virtual synchronous generators (REGCV1, REGCV2)
get the held run judged and their steps run unjudged (with the voltage imposed their virtual
rotor has no synchronising power); the WECC grid-forming REGFM_A1 (REGFMA1) and REGFM_B1
(REGFMB1U), sources behind ZSORCE that synchronise against the imposed voltage, have all three
judged, the frequency step turning the imposed phasor, and a data problem where the power flow
crosses REGFM_A1's Pmax/Pmin, Qmax/Qmin, Imax or Emax/Emin, or REGFM_B1's ImaxSS, kf ImaxSS or
angle limit asin(XL ImaxSS) (P0 < 0 without ESFlag). Other converter models (WT4G1, PVGU1,
REECDU1, ...) are units, not supported, named.

Every generator record of the .raw is accounted for (the counts add up to the .raw's): the
units checked (machines and inverter-based plants; an unknown machine model, e.g. a renamed GENSAL, is a unit, not supported,
named; exciter or governor records without a machine record, a data problem); out of service;
in service without dynamic records; not generators
(SVC, STATCOM: CSVGN1, CSTATT, SVSMO1, ...); second records of one generator. .dyr records of
no generator are listed: orphaned (bus or ID not in the .raw: record, line) or of a bus (USRBUS).

CASE.toml: a fleet file's [case] is enough (paths relative to the file); a whole fleet file
serves as it is (its other sections are not read):
  [case]       raw = "case.raw" (PSS/E rev {RAW_REVISIONS}), dyr = "case.dyr" (or a list of .dyr files,
               later records replacing earlier ones of the same machine and model)
  [playback]   optional: solver = "tsit5" (the check's held run and step: fixed step,
               1/(30 x substeps) s) | "kvaerno5", substeps (4: PSS/E's half-cycle step),
               ke_zero = "psse" | "literal"

{SIMULATED}

Prints a table (units by model chain, every unit that does not pass with its first reason,
the counts). With --out DIR:
  DIR/check.json   "units": name, bus, id, models {machine, exciter, stabiliser, governor:
                   PSS/E names or null}, outcome, reasons (lines), notes, numbers (derivatives
                   at t = 0, P/Q errors, the step's ranges and spreads); "summary": the count of
                   each outcome, by model chain, the models not supported; "check": the runs'
                   definition
  DIR/check.html   the same as a page: counts, reasons, sortable table

With --repair, every data problem that is a crossed limit is repaired: the constant that sets
the limit (e.g. HYGOV GMAX, IEEEG1 PMAX, GGOV1 Vmax) is moved so that the signal lies 5 % of its
value (at least 0.01 pu) inside it, rounded outward to 4 significant figures; nothing else
changes (a DC exciter whose VRMAX = 0 stated computed limits gets both written out). Written
into DIR (or beside CASE.toml):
  repaired.dyr     the case's .dyr, each changed constant replaced in place, a PSS/E comment
                   line "/ jaxdse repair: CON of MODEL bus N id 'ID': OLD -> NEW (FILE line L):
                   WHY" before its record (jaxdse reads them back: every page of a repaired
                   unit, in check, fleet and validate, lists its changes)
  repairs.csv      one row per change: unit, bus, id, record, file, line, con, con_number, old,
                   new, signal, value, limit, bound, side, why
  repaired.toml    the case with the repaired .dyr: jaxdse check DIR/repaired.toml
and the change table on the console, in check.json ("repair") and check.html. Data problems
that are not a crossed limit (values the model's checks refuse) are listed as not repaired.

Exit status: 0 whatever the outcomes; 2 on unreadable input (a missing or malformed file, no
synchronous unit) with a one-line message.

examples:
  jaxdse check experiments/activsg2000/case.toml --out activsg2000_check/   # needs ../shared/data
  jaxdse check experiments/andes_bench/fleet_npcc.toml
  jaxdse check experiments/activsg2000/case.toml --repair --out activsg2000_repaired/
"""


STRICT_HELP = "exit with status 3 when any unit's verdict is not 'identified'"
DEMO_SECONDS = (10.0, 3600.0)
"""The demo's recording length: the event at its middle, at least 5 s either side; at most an
hour (90 001 frames a recording)."""


def _in_range(command: str, option: str, value, low, high, what: str, low_open: bool = False) -> None:
    """A numeric option outside [low, high] (``low_open``: above low), or not finite: one line."""
    from .._io.errors import InputError

    if value is None:
        return
    ok = math.isfinite(value) and (low is None or (value > low if low_open else value >= low)) \
        and (high is None or value <= high)
    if not ok:
        raise InputError(command, f"{option} {value:g}: out of range; give {what}")


def _strict(args, units: list[dict]) -> int:
    """Exit status 3 under --strict when any unit's verdict is not "identified" (an
    inverter-based plant's "not applicable": it has no H), else 0."""
    shaky = [e["name"] for e in units if e["verdict"] not in ("identified", "not applicable")]
    if args.strict and shaky:
        print(f"jaxdse: --strict: {len(shaky)} unit(s) not identified: {', '.join(shaky)}", file=sys.stderr)
        return 3
    return 0


def _fleet(args) -> int:
    from .fleet import run_fleet
    from .fleet_file import load_fleet

    return _strict(args, run_fleet(load_fleet(args.fleet), Path(args.out))["units"])


def _check(args) -> int:
    from .check import run_check

    run_check(args.case, Path(args.out) if args.out else None, out_of_service=args.out_of_service,
              repair=args.repair)
    return 0


def _validate(args) -> int:
    from .validate import validate

    validate(args.config, Path(args.out))
    return 0


def _sweep(args) -> int:
    from .._io.config import load_config
    from .run import run_sweep

    run_sweep(load_config(args.config), Path(args.out) if args.out else None)
    return 0


def _tune(args) -> int:
    from .._io.config import load_config
    from .run import run_tune

    run_tune(load_config(args.config), Path(args.out) if args.out else None)
    return 0


def _run(args) -> int:
    from .._io.config import load_config
    from .._io.schema import read_toml
    from .run import run_config

    if "replay" in read_toml(Path(args.config)):
        from .sources import replay_recording

        out = Path(args.out) if args.out else Path(args.config).parent / "replayed"
        lines = replay_recording(args.config, out)
        print(f"jaxdse run: {len(lines)} windowed update(s) replayed to {out / 'updates.jsonl'}", file=sys.stderr)
        return 0

    summary = run_config(load_config(args.config), Path(args.out) if args.out else None)
    return _strict(args, summary["recordings"])


def _pmu_sim(args) -> int:
    from .._stream.pmu_sim import main as pmu_sim
    from .sources import source_units

    return pmu_sim(args, source_units)


def _monitor(args) -> int:
    from .._io.errors import InputError
    from .._stream.monitor import Monitor
    from .sources import load_monitor

    _in_range("monitor", "--duration", args.duration, 0.0, None, "seconds > 0", low_open=True)
    summary = Monitor(load_monitor(args.config), Path(args.out) if args.out else None).run(args.duration)
    print(f"jaxdse monitor: {summary['updates']} update(s) in {summary['wall_s']:.0f} s"
          + delay_words(summary), file=sys.stderr)
    return 0


def delay_words(summary: dict) -> str:
    """The monitor's delay from a frame to its estimate, in stream time (and in wall time where
    the streams do not run in real time), for the closing line."""
    d, w = summary.get("delay_s"), summary.get("wall_delay_s")
    if not d:
        return ""
    text = f"; delay from frame to estimate: median {d['median']:.3f} s, 99 % {d['p99']:.3f} s of stream time"
    paces = [s["pace"] for s in summary["streams"] if s.get("pace")]
    if w and paces and any(abs(p - 1.0) > 0.01 for p in paces):
        text += (f" (the stream at {', '.join(f'{p:.2f}' for p in paces)}x real time: median {w['median']:.3f} s, "
                 f"99 % {w['p99']:.3f} s of wall time)")
    return text


def _demo(args) -> int:
    from .demo import run_demo

    _in_range("demo", "--duration", args.duration, DEMO_SECONDS[0], DEMO_SECONDS[1],
              f"{DEMO_SECONDS[0]:g}-{DEMO_SECONDS[1]:g} s")
    _in_range("demo", "--seed", args.seed, 0, None, "a whole number >= 0")
    run_demo(Path(args.out), duration_s=args.duration, seed=args.seed)
    return 0


def model_lists() -> dict[str, str]:
    """The help texts' lists, from the registries: .raw revisions, and the models jaxdse
    simulates by family (what README lists)."""
    import textwrap

    from .._io.psse import MACHINE_FIELDS, SUPPORTED_RAW_REVISIONS
    from .._models.exciters import EXCITERS
    from .._models.governors import GOVERNORS
    from .._models.machines import MACHINES
    from .._models.stabilisers import STABILISERS

    revs = sorted(SUPPORTED_RAW_REVISIONS)
    contiguous = revs == list(range(revs[0], revs[-1] + 1))

    def block(title, families):
        lines = [title]
        for name, models in families:
            lines += textwrap.wrap(", ".join(models), width=92, initial_indent=f"  {name:<12}",
                                   subsequent_indent=" " * 14)
        return "\n".join(lines)

    return {
        "RAW_REVISIONS": f"{revs[0]}-{revs[-1]}" if contiguous else ", ".join(map(str, revs)),
        "SIMULATED": block("Models jaxdse simulates (a record of any other model is named, not guessed):",
                           [("machines", MACHINES), ("exciters", EXCITERS), ("stabilisers", STABILISERS),
                            ("governors", GOVERNORS)]),
        "FLEET_MODELS": block("Records the estimator's plant is built from:",
                              [("machines", MACHINE_FIELDS), ("governors", GOVERNORS)]),
    }


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose help fills in the registries' lists ({RAW_REVISIONS}, {SIMULATED},
    {FLEET_MODELS}) when it is printed: a command line that does not ask for help imports none."""

    def format_help(self) -> str:
        text = super().format_help()
        if "{" in text:
            for key, value in model_lists().items():
                text = text.replace("{" + key + "}", value)
        return text


def build_parser() -> argparse.ArgumentParser:
    from .._version import __version__

    parser = _Parser(prog="jaxdse", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"jaxdse {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    run = sub.add_parser("run", help="estimate states, H and D from the recordings in a TOML config",
                         description=RUN_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("config", metavar="CONFIG.toml", help="run configuration (see examples/)")
    run.add_argument("--out", metavar="DIR", default=None,
                     help="output folder (default: [output] dir of the config, else jaxdse_out "
                          "beside it)")
    run.add_argument("--strict", action="store_true", help=STRICT_HELP)
    run.set_defaults(func=_run)
    for name, helptext, desc, func in (
            ("sweep", "run many observer configurations at once ([sweep] of the config)", SWEEP_HELP,
             _sweep),
            ("tune", "tune the observer by gradient on role 'auto' recordings", TUNE_HELP, _tune)):
        p = sub.add_parser(name, help=helptext, description=desc,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        p.add_argument("config", metavar="CONFIG.toml", help="run configuration (see examples/)")
        p.add_argument("--out", metavar="DIR", default=None,
                       help="output folder (default: [output] dir of the config)")
        p.set_defaults(func=func)
    fl = sub.add_parser("fleet", help="every plant of a PSS/E case from PMU recordings, with a report",
                        description=FLEET_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    fl.add_argument("fleet", metavar="FLEET.toml", help="fleet file (see `jaxdse fleet --help`)")
    fl.add_argument("--out", metavar="DIR", required=True, help="output folder")
    fl.add_argument("--strict", action="store_true", help=STRICT_HELP)
    fl.set_defaults(func=_fleet)
    va = sub.add_parser("validate", help="validate and calibrate the units' own PSS/E models against "
                        "recordings", description=VALIDATE_HELP,
                        formatter_class=argparse.RawDescriptionHelpFormatter)
    va.add_argument("config", metavar="CONFIG.toml", help="fleet file with [calibrate]")
    va.add_argument("--out", metavar="DIR", required=True, help="output folder")
    va.set_defaults(func=_validate)
    ch = sub.add_parser("check", help="no-disturbance check of every unit of a PSS/E case",
                        description=CHECK_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    ch.add_argument("case", metavar="CASE.toml", help="a file with [case] raw, dyr (a fleet file serves)")
    ch.add_argument("--out", metavar="DIR", default=None, help="write DIR/check.json and DIR/check.html")
    ch.add_argument("--out-of-service", action="store_true",
                    help="also check the units switched off in the .raw (STAT = 0), at their PG, QG")
    ch.add_argument("--repair", action="store_true",
                    help="write repaired.dyr (each crossed limit moved, a comment per change), "
                         "repairs.csv and repaired.toml into DIR (or beside CASE.toml)")
    ch.set_defaults(func=_check)
    ps = sub.add_parser("pmu-sim", help="serve a recording as a live C37.118 PMU stream (loopback)",
                        description=PMU_SIM_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    ps.add_argument("recording", metavar="RECORDING-or-FLEET.toml",
                    help="a run configuration (see examples/) or a fleet file")
    ps.add_argument("--port", type=int, default=4712, help="port (default: %(default)s; 0: any free)")
    ps.add_argument("--host", default="127.0.0.1", help="address to listen on (default: %(default)s)")
    ps.add_argument("--udp", action="store_true", help="UDP instead of TCP (commands and data)")
    ps.add_argument("--idcode", type=int, default=1, help="the stream's IDCODE (default: %(default)s)")
    ps.add_argument("--format", default="float", metavar="WORDS",
                    help="FORMAT: float (default), int, or words such as rect,phasor=int,freq=int")
    ps.add_argument("--speed", type=float, default=1.0, metavar="X",
                    help="X times faster than real time (default: %(default)s)")
    ps.add_argument("--loop", action="store_true", help="repeat the recording")
    ps.add_argument("--duration", type=float, default=None, metavar="S", help="stop after S seconds")
    ps.add_argument("--start", default="now", metavar="WHEN",
                    help="now (default), recording, or a time (ISO 8601 or seconds since 1970)")
    ps.add_argument("--free-run", action="store_true",
                    help="start the recording at once, not at the first client's 'data on'")
    ps.add_argument("--tile", type=int, default=1, metavar="K",
                    help="serve every station K times (capacity tests; default: %(default)s)")
    ps.add_argument("--time-base", type=int, default=1_000_000, metavar="N",
                    help="TIME_BASE, FRACSEC counts per second (default: %(default)s)")
    ps.add_argument("--fault", action="append", metavar="SPEC",
                    help="inject a fault, KIND[=VALUE]@START[+DURATION][:STATION] (see above)")
    ps.set_defaults(func=_pmu_sim)
    mo = sub.add_parser("monitor", help="per-unit H and D every second from live PMU streams (C37.118, STTP)",
                        description=MONITOR_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    mo.add_argument("config", metavar="MONITOR.toml", help="the monitor file (see above)")
    mo.add_argument("--out", metavar="DIR", default=None,
                    help="folder for updates.jsonl, the recording and monitor.json (default: none)")
    mo.add_argument("--duration", type=float, default=None, metavar="S",
                    help="stop cleanly after S seconds, not counting the compilation of the estimators at a "
                         "stream's configuration (default: run until Ctrl-C)")
    mo.set_defaults(func=_monitor)
    demo = sub.add_parser("demo", help="run the estimator on two built-in simulated recordings",
                          description=DEMO_HELP,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    demo.add_argument("--out", default="jaxdse_demo", metavar="DIR",
                      help="output folder (default: %(default)s)")
    demo.add_argument("--duration", type=float, default=600.0, metavar="S",
                      help=f"length of each recording in seconds, {DEMO_SECONDS[0]:g}-{DEMO_SECONDS[1]:g} "
                           "(default: %(default)s)")
    demo.add_argument("--seed", type=int, default=0, help="random seed >= 0 (default: %(default)s)")
    demo.set_defaults(func=_demo)
    return parser


def compilation_cache() -> str | None:
    """Point JAX's persistent compilation cache at jaxdse's cache folder (see ``DESCRIPTION``),
    unless the caller already chose one or ``JAXDSE_CACHE_DIR=off``. Returns the folder used."""
    import jax

    if jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    where = os.environ.get(CACHE_ENV)
    if where is None:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
        where = os.path.join(base, "jaxdse", "xla")
    if where.strip().lower() in ("", "0", "off", "none", "false"):
        return None
    try:
        os.makedirs(where, exist_ok=True)
    except OSError as err:
        print(f"jaxdse: note: no compilation cache ({where}: {err.strerror}); every run compiles anew",
              file=sys.stderr)
        return None
    jax.config.update("jax_compilation_cache_dir", where)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)  # the estimator, not small ops
    return where


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    import jax

    jax.config.update("jax_enable_x64", True)  # every command computes in float64
    compilation_cache()
    from .._io.errors import InputError

    try:
        return args.func(args)
    except InputError as err:
        print(f"jaxdse: error: {err}", file=sys.stderr)
        return 2
    except TimeoutError as err:  # a compiled run that did not return within its limit
        print(f"jaxdse: error: {err}", file=sys.stderr)
        return 1
    except OSError as err:
        print(f"jaxdse: error: {err.filename or ''}: {err.strerror or err}", file=sys.stderr)
        return 2
    except FloatingPointError as err:  # a numerical failure, not bad input
        print(f"jaxdse: error: {err}", file=sys.stderr)
        return 1


def entry() -> None:
    """The ``jaxdse`` console script: :func:`main`, then exit without the interpreter's
    teardown of the XLA client and its compiled code (~0.7 s after a fleet run), once the
    outputs are written and the streams flushed."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(int(code or 0))


if __name__ == "__main__":
    entry()
