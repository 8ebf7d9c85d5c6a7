"""Outputs at the edge: summary.json entries, estimates CSVs, printed tables and figures."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from .._core.result import Estimate

CSV_COLUMNS = {
    "time_s": lambda e: e.time_s, "delta_rad": lambda e: e.trajectories.delta_rad,
    "x2_hat_rad_s": lambda e: e.trajectories.x2_hat_rad_s,
    "x2_meas_rad_s": lambda e: e.trajectories.x2_meas_rad_s,
    "e_q_prime_pu": lambda e: e.trajectories.e_q1_pu, "a1_hat": lambda e: e.a1_hat,
    "a2_hat": lambda e: e.a2_hat, "t_e_pu": lambda e: e.trajectories.t_e_pu,
    "t_m_pu": lambda e: e.trajectories.t_m_pu, "e_f_pu": lambda e: e.trajectories.e_f_pu,
    "x2_sim_rad_s": lambda e: e.trajectories.playback.x2_rad_s,
    "i_t_sim_pu": lambda e: e.trajectories.playback.i_t_pu,
    "p_t_sim_pu": lambda e: e.trajectories.playback.p_t_pu,
    "q_t_sim_pu": lambda e: e.trajectories.playback.q_t_pu,
}
"""CSV column -> how to read it from an Estimate (the contract of the estimates CSV)."""


def _num(x):
    x = float(x)
    return None if not math.isfinite(x) else x


def summary_entry(name: str, est: Estimate, a2_reference=None, h_reference_s=None) -> dict:
    """One entry of ``summary.json["recordings"]``."""
    tr = est.trajectories
    x2_std = float(np.std(np.asarray(tr.x2_meas_rad_s)))
    after = np.asarray(est.time_s) >= (float(est.convergence_time_s)
                                       if bool(est.converged) else 0.0)
    err = np.asarray(tr.x2_hat_rad_s - tr.x2_meas_rad_s)[after]
    finite = bool(all(np.all(np.isfinite(np.asarray(get(est)))) for get in CSV_COLUMNS.values())
                  and np.isfinite(float(est.a1)) and np.isfinite(float(est.a2)))
    entry = {
        "name": name,
        "a1": _num(est.a1),
        "a2": _num(est.a2),
        "H_s": _num(est.h_s),
        "D": _num(est.d_pu_s),
        "a2_reference": _num(a2_reference) if a2_reference is not None else None,
        "H_reference_s": _num(h_reference_s) if h_reference_s is not None else None,
        "a2_error_percent": (_num(100 * (est.a2 - a2_reference) / abs(a2_reference))
                             if a2_reference is not None else None),
        "convergence_time_s": _num(est.convergence_time_s),
        "converged": bool(est.converged) and finite and float(est.a2) > 0,
        "flags": {"excited": bool(est.excited), "online": bool(est.online),
                  "solver_ok": bool(est.solver_ok), "torque_balanced": bool(est.torque_balanced),
                  "finite": finite,
                  "a2_positive": bool(float(est.a2) > 0),
                  "log_contraction_a2": _num(est.log_contraction_end[1])},
        "smape_percent": {"x2_observer": _num(est.smape.x2_observer),
                          "x2_playback": _num(est.smape.x2_playback), "I_t": _num(est.smape.i_t),
                          "P_t": _num(est.smape.p_t), "Q_t": _num(est.smape.q_t)},
        "x2_observer_nrmse_percent": _num(100 * np.sqrt(np.mean(err**2)) / x2_std)
        if x2_std > 0 and err.size else None,
        "t_ref_pu": _num(est.t_ref_pu),
        "n_samples": int(np.shape(est.time_s)[0]),
        "duration_s": _num(est.time_s[-1] - est.time_s[0]),
    }
    if not entry["converged"]:
        reasons = [k for k in ("excited", "online", "solver_ok", "torque_balanced", "finite",
                               "a2_positive")
                   if not entry["flags"][k]]
        entry["not_converged_reason"] = ", ".join(f"not {r}" for r in reasons) or \
            "a2_hat did not settle within the band"
    return entry


def write_summary(path: Path, entries: list[dict], extra: dict | None = None) -> None:
    data = {"recordings": entries, **(extra or {})}
    Path(path).write_text(json.dumps(data, indent=2) + "\n")


def write_estimates_csv(path: Path, est: Estimate) -> None:
    cols = [np.asarray(get(est)) for get in CSV_COLUMNS.values()]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS.keys())
        for row in zip(*cols):
            w.writerow([f"{v:.10g}" for v in row])


def format_table(entries: list[dict]) -> str:
    """A text table in the style of the paper's Tables II and III."""
    w = max([10] + [len(e["name"]) for e in entries])
    head = (f"{'recording':<{w}} {'a2 ref':>8} {'a2 est':>8} {'err %':>7} {'H s':>6} "
            f"{'conv s':>7} {'x2 obs':>7} {'x2 sim':>7} {'I_t':>6} {'P_t':>6} {'Q_t':>6}")
    lines = [head, "-" * len(head)]

    def f(x, fmt):
        return format(x, fmt) if x is not None else "n/a"

    for e in entries:
        s = e["smape_percent"]
        lines.append(
            f"{e['name']:<{w}} {f(e['a2_reference'], '8.2f'):>8} {f(e['a2'], '8.2f'):>8} "
            f"{f(e['a2_error_percent'], '7.2f'):>7} {f(e['H_s'], '6.2f'):>6} "
            f"{f(e['convergence_time_s'], '7.1f'):>7} {f(s['x2_observer'], '7.2f'):>7} "
            f"{f(s['x2_playback'], '7.2f'):>7} {f(s['I_t'], '6.2f'):>6} {f(s['P_t'], '6.2f'):>6} "
            f"{f(s['Q_t'], '6.2f'):>6}")
    lines.append("a2 in rad/s^2 per pu; x2 obs/sim, I_t, P_t, Q_t: sMAPE in % (paper Eq. 23).")
    return "\n".join(lines)


def plot_estimates(est: Estimate, name: str, out_dir: Path, a1_reference=None,
                   a2_reference=None) -> list[Path]:
    """Figures like the paper's Figs. 5-8: convergence, x2, playback errors. Returns the paths."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.asarray(est.time_s)
    paths = []

    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    for ax, traj, ref, label in ((axes[0], est.a1_hat, a1_reference, "a1 [1/s]"),
                                 (axes[1], est.a2_hat, a2_reference, "a2 [rad/s² per pu]")):
        ax.plot(t, np.asarray(traj), label="estimate")
        if ref is not None:
            ax.axhline(float(ref), color="k", ls="--", label="reference")
        ax.set_ylabel(label)
        ax.legend(loc="best")
        ax.grid(alpha=0.3)
    if bool(est.converged):
        axes[1].axvline(float(est.convergence_time_s), color="g", ls=":", label="converged")
    axes[1].set_xlabel("time [s]")
    fig.suptitle(f"DREM parameter estimates — {name}")
    paths.append(_save(fig, out_dir / f"convergence_{name}.png"))

    tr = est.trajectories
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    axes[0].plot(t, np.asarray(tr.x2_meas_rad_s), label="measured", lw=0.8)
    axes[0].plot(t, np.asarray(tr.x2_hat_rad_s), label="I&I observer", lw=0.8)
    axes[0].set_ylabel("x2 [rad/s]")
    axes[0].legend(loc="best")
    axes[1].plot(t, np.asarray(tr.x2_hat_rad_s - tr.x2_meas_rad_s), lw=0.8)
    axes[1].set_ylabel("x2 error [rad/s]")
    axes[1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(f"Speed deviation x2, observer vs measurement — {name}")
    paths.append(_save(fig, out_dir / f"x2_{name}.png"))

    fig, axes = plt.subplots(4, 1, sharex=True, figsize=(8, 8))
    pb = tr.playback
    errs = ((pb.x2_rad_s - tr.x2_meas_rad_s, "x2 error [rad/s]"),
            (pb.i_t_pu - tr.i_t_pu, "I_t error [pu]"),
            (pb.p_t_pu - tr.p_t_pu, "P_t error [pu]"),
            (pb.q_t_pu - tr.q_t_pu, "Q_t error [pu]"))
    for ax, (e, label) in zip(axes, errs):
        ax.plot(t, np.asarray(e), lw=0.8)
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(f"Event playback minus measurement — {name}")
    paths.append(_save(fig, out_dir / f"playback_{name}.png"))
    return paths


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
