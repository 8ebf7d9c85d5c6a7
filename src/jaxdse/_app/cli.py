"""Command-line interface: ``jaxdse run CONFIG.toml`` and ``jaxdse demo``.

User mistakes end in a one-line error on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

DESCRIPTION = """\
jaxdse estimates the rotor angle, speed deviation and E'q of a synchronous generator and its
inertia H and damping D (a2 = ws/2H, a1 = ws D/2H) from PMU recordings, following
Lorenz-Meyer, Suchantke & Schiffer (arXiv:2203.14623): mapping substation phasors to the
machine terminal, an algebraic observer, a DREM parameter estimator, an I&I speed observer
and event playback.

examples:
  jaxdse demo --out jaxdse_demo                       built-in simulated data, truth known
  jaxdse run examples/csv_positive_sequence.toml      your own recording (CSV/COMTRADE/MAT)
  jaxdse run --help                                   what goes in and what comes out
  jaxdse sweep examples/sweep_tune.toml               many observer configurations at once
  jaxdse tune examples/sweep_tune.toml                tune lambda, c, K, gamma, k by gradient
"""

DEMO_HELP = """\
Simulate the paper's plant (machine, exciter, governor, auxiliary load, tap-changing
transformer, HV line, ambient grid fluctuations and one event) at 90 % and 45 % of rating,
run the estimator on both with the same configuration (auto- and cross-validation) and write:

  DIR/summary.json             final a1, a2, H, D, a2 reference, convergence time, sMAPE
  DIR/estimates_<name>.csv     trajectories (time_s, delta_rad, x2_hat_rad_s, ...)
  DIR/convergence_<name>.png   a1_hat and a2_hat against their references
  DIR/x2_<name>.png            x2 observed vs measured
  DIR/playback_<name>.png      playback errors of x2, I_t, P_t, Q_t

example:
  jaxdse demo --out demo_out
"""


RUN_HELP = """\
Read the PMU recording(s) named in CONFIG.toml, map them to the machine terminal, run the
algebraic observer, the governor model, the DREM parameter estimator, the I&I speed observer
and the event playback for every [[generator]], and write:

  DIR/summary.json             per recording: a1, a2, H [s], D, convergence time, flags
                               (excited, online, solver_ok, finite), playback sMAPE of
                               x2, I_t, P_t, Q_t, and a "data_quality" section (rows read,
                               duplicates, reordering, NaN, bridged gaps, splits, units)
  DIR/estimates_<name>.csv     trajectories: time_s, delta_rad, x2_hat_rad_s, a1_hat, a2_hat,
                               E'q, Te, Tm, Ef, playback x2/I_t/P_t/Q_t
  DIR/convergence_<name>.png   a1_hat, a2_hat (and the reference where known)
  DIR/x2_<name>.png            x2 estimated vs measured
  DIR/playback_<name>.png      playback errors of x2, I_t, P_t, Q_t

The config describes the measurement (file, format csv|comtrade|mat, column names, units,
bases, current direction, PMU location), the plant (line, transformer, aux, machine,
governor) and the observer (paper Table I by default). See examples/*.toml.

Exit status: 0 on success, 2 on bad input (missing file or column, unknown key, wrong unit,
impossible value, gap too long) with a one-line message naming the file, column/key and row.

example:
  jaxdse run examples/csv_positive_sequence.toml --out out/
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

Writes DIR/tune.json (losses, history, start and tuned values) and DIR/tuned_observer.toml
(an [observer] section to paste into a config). A progress bar shows the loss per step.

example:
  jaxdse tune examples/sweep_tune.toml --out tune_out/
"""


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
    from .run import run_config

    run_config(load_config(args.config), Path(args.out) if args.out else None)
    return 0


def _demo(args) -> int:
    from .demo import run_demo

    run_demo(Path(args.out), duration_s=args.duration, seed=args.seed)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="jaxdse", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    run = sub.add_parser("run", help="estimate states, H and D from the recordings in a TOML config",
                         description=RUN_HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    run.add_argument("config", metavar="CONFIG.toml", help="run configuration (see examples/)")
    run.add_argument("--out", metavar="DIR", default=None,
                     help="output folder (default: [output] dir of the config, else jaxdse_out "
                          "beside it)")
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
    demo = sub.add_parser("demo", help="run the estimator on two built-in simulated recordings",
                          description=DEMO_HELP,
                          formatter_class=argparse.RawDescriptionHelpFormatter)
    demo.add_argument("--out", default="jaxdse_demo", metavar="DIR",
                      help="output folder (default: %(default)s)")
    demo.add_argument("--duration", type=float, default=600.0, metavar="S",
                      help="length of each recording in seconds (default: %(default)s)")
    demo.add_argument("--seed", type=int, default=0, help="random seed (default: %(default)s)")
    demo.set_defaults(func=_demo)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    import jax

    jax.config.update("jax_enable_x64", True)  # every command computes in float64
    from .._io.errors import InputError

    try:
        return args.func(args)
    except InputError as err:
        print(f"jaxdse: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"jaxdse: error: {err.filename or ''}: {err.strerror or err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
