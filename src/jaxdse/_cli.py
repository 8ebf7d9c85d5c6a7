"""Command-line interface: ``jaxdse demo`` (more commands arrive with the file readers)."""

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


def _demo(args) -> int:
    import jax

    jax.config.update("jax_enable_x64", True)
    from ._demo import run_demo

    run_demo(Path(args.out), duration_s=args.duration, seed=args.seed)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="jaxdse", description=DESCRIPTION,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
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
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
