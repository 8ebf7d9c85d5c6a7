"""Outputs at the edge: summary.json entries, estimates CSVs, printed tables and figures."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np

from .._core.assess import Assessment
from .._core.estimate import Replay
from .._core.identify import Identified, condition_number
from .._core.result import Estimate
from .._core.verdict import (
    D_MEANING,
    D_VERDICTS,
    FINDINGS,
    NOTES,
    REASONS,
    VERDICTS,
    describe,
    online_verdict,
)


def _playback(est: Estimate, rep: Replay | None):
    """The playback shown to the user: with the identified parameters when there are some."""
    return rep.playback if rep is not None else est.trajectories.playback


CSV_COLUMNS = {
    "time_s": lambda e, r: e.time_s, "delta_rad": lambda e, r: e.trajectories.delta_rad,
    "x2_hat_rad_s": lambda e, r: e.trajectories.x2_hat_rad_s,
    "x2_meas_rad_s": lambda e, r: e.trajectories.x2_meas_rad_s,
    "e_q_prime_pu": lambda e, r: e.trajectories.e_q1_pu, "a1_hat": lambda e, r: e.a1_hat,
    "a2_hat": lambda e, r: e.a2_hat, "t_e_pu": lambda e, r: e.trajectories.t_e_pu,
    "t_m_pu": lambda e, r: e.trajectories.t_m_pu, "e_f_pu": lambda e, r: e.trajectories.e_f_pu,
    "i_t_pu": lambda e, r: e.trajectories.i_t_pu, "p_t_pu": lambda e, r: e.trajectories.p_t_pu,
    "q_t_pu": lambda e, r: e.trajectories.q_t_pu,
    "x2_sim_rad_s": lambda e, r: _playback(e, r).x2_rad_s,
    "i_t_sim_pu": lambda e, r: _playback(e, r).i_t_pu,
    "p_t_sim_pu": lambda e, r: _playback(e, r).p_t_pu,
    "q_t_sim_pu": lambda e, r: _playback(e, r).q_t_pu,
}
"""CSV column -> how to read it from an (Estimate, Replay) pair (the contract of the estimates
CSV). The ``*_sim`` columns are the playback with the identified parameters (the online ones
when identification is off)."""


def _num(x):
    x = float(x)
    return None if not math.isfinite(x) else x


def _pair(x):
    return [_num(x[0]), _num(x[1])]


def summary_entry(name: str, assessment: Assessment | Estimate, a2_reference=None,
                  h_reference_s=None) -> dict:
    """One entry of ``summary.json["recordings"]``: a serialiser of one unit's :class:`Assessment`
    (an :class:`Estimate` alone counts as an assessment without identification).

    The headline values (``H_s``, ``H_ci95``, ``D``, ``verdict``) are the batch
    identification's when it ran; ``online`` holds the paper's DREM/I&I estimate beside them.
    """
    if isinstance(assessment, Estimate):
        assessment = Assessment(assessment, None, None, None)
    est, ident, rep, verdict = assessment.estimate, assessment.identified, assessment.replay, \
        assessment.verdict
    tr = est.trajectories
    x2_std = float(np.std(np.asarray(tr.x2_meas_rad_s)))
    after = np.asarray(est.time_s) >= (float(est.convergence_time_s) if bool(est.converged) else 0.0)
    err = np.asarray(tr.x2_hat_rad_s - tr.x2_meas_rad_s)[after]
    finite = bool(all(np.all(np.isfinite(np.asarray(get(est, rep)))) for get in CSV_COLUMNS.values())
                  and np.isfinite(float(est.a1)) and np.isfinite(float(est.a2)))
    online = {
        "a1": _num(est.a1), "a2": _num(est.a2), "H_s": _num(est.h_s), "D": _num(est.d_pu_s),
        "convergence_time_s": _num(est.convergence_time_s),
        "converged": bool(est.converged) and finite and float(est.a2) > 0,
        "flags": {"excited": bool(est.excited), "online": bool(est.online),
                  "solver_ok": bool(est.solver_ok), "torque_balanced": bool(est.torque_balanced),
                  "finite": finite, "a2_positive": bool(float(est.a2) > 0),
                  "log_contraction_a2": _num(est.log_contraction_end[1])},
        "x2_observer_smape_percent": _num(est.smape.x2_observer),
        "x2_observer_nrmse_percent": _num(100 * np.sqrt(np.mean(err**2)) / x2_std)
        if x2_std > 0 and err.size else None,
        "playback_smape_percent": {"x2": _num(est.smape.x2_playback), "I_t": _num(est.smape.i_t),
                                   "P_t": _num(est.smape.p_t), "Q_t": _num(est.smape.q_t)},
    }
    if not online["converged"]:
        reasons = [k for k in ("excited", "online", "solver_ok", "torque_balanced", "finite", "a2_positive")
                   if not online["flags"][k]]
        online["not_converged_reason"] = ", ".join(f"not {r}" for r in reasons) or \
            "a2_hat did not settle within the band"
    final = ident if ident is not None else est
    scores = rep.smape if rep is not None else est.smape
    entry = {
        "name": name,
        "method": "batch identification" if ident is not None else "online DREM/I&I (identification off)",
        "a1": _num(final.a1), "a2": _num(final.a2), "H_s": _num(final.h_s), "D": _num(final.d_pu_s),
        "H_ci95": _pair(ident.h_ci95) if ident is not None else None,
        "D_ci95": _pair(ident.d_ci95) if ident is not None else None,
        # the same identified D per pu speed [pu torque per pu speed]: D w_s = 2 H a1 (the unit of
        # a machine record's D, not its meaning: D_MEANING)
        "D_pu_speed": _num(2.0 * final.h_s * final.a1),
        "a2_reference": _num(a2_reference) if a2_reference is not None else None,
        "H_reference_s": _num(h_reference_s) if h_reference_s is not None else None,
        "a2_error_percent": (_num(100 * (final.a2 - a2_reference) / abs(a2_reference))
                             if a2_reference is not None else None),
        "smape_percent": {"x2_observer": _num(est.smape.x2_observer),
                          "x2_playback": _num(scores.x2_playback), "I_t": _num(scores.i_t),
                          "P_t": _num(scores.p_t), "Q_t": _num(scores.q_t)},
        "online": online,
        "t_ref_pu": _num(est.t_ref_pu),
        "n_samples": int(np.shape(est.time_s)[0]),
        "duration_s": _num(est.time_s[-1] - est.time_s[0]),
    }
    if ident is not None:
        entry["identification"] = {
            "se_a1": _num(ident.se_a1), "se_a2": _num(ident.se_a2),
            "relative_ci_percent": _num(100 * ident.relative_ci),
            "condition": _num(condition_number(ident.information)),
            "h_variance_inflation": _num(ident.h_variance_inflation),
            "H_without_damping_s": _num(ident.h_without_damping_s),
            "H_without_governor_correction_s": _num(ident.h_without_governor_correction_s),
            "t_m_offset_pu": _num(ident.t_m_offset_pu), "output_error": bool(ident.output_error),
            "governor_gain_error": _num(ident.governor_gain_error), "samples": int(ident.samples)}
    if verdict is None:  # an Estimate alone: the online estimate's verdict, built in JAX
        verdict = online_verdict(est)
    word, keys = describe(verdict)
    entry["verdict"] = word
    entry["reasons"] = {k: _reason_text(k, ident, online) for k in keys}
    entry["parameters"] = parameter_verdicts(verdict, keys, ident)
    return entry


def _reason_text(key: str, ident, online: dict) -> str:
    """A reason in words, with the unit's numbers where they say more than the rule."""
    if key == "governor_model_off" and ident is not None:
        g = float(ident.governor_gain_error)
        return (f"the data ask for a governor response {abs(100 * g):.0f} % "
                f"{'below' if g < 0 else 'above'} the model's")
    if key == "power_above_droop" and ident is not None:
        k = 1.0 + float(ident.governor_gain_error)
        cause = ("a current logged as peak instead of RMS (x1.414)?" if abs(k - 2**0.5) < 0.12
                 else "a CT ratio or a base?")
        return (f"the measured power answers the frequency {k:.2f}x as strongly as the governor's "
                f"droop allows (governor correction {100 * (k - 1):+.0f} %): if the governor data are "
                f"right, the power and H are {k:.2f}x too large: {cause}")
    if key == "negative_damping" and ident is not None:
        lo, hi = (float(x) for x in ident.d_ci95)
        return (f"D = {float(ident.d_pu_s):.3g} pu torque per rad/s ({2.0 * float(ident.h_s * ident.a1):.3g} "
                f"per pu speed) < 0 with 95 % confidence (interval {lo:.4g} to {hi:.4g}): the swing "
                "equation needs negative damping to follow the recording; its D lumps the excitation "
                "and stabiliser damping (an exciter's negative damping outweighing the damper "
                "windings'), not the machine record's D")
    if key in ("h_rests_on_damping", "h_rests_on_governor") and ident is not None:
        alt = (ident.h_without_damping_s if key == "h_rests_on_damping"
               else ident.h_without_governor_correction_s)
        lo, hi = (float(x) for x in ident.h_ci95)
        return f"{REASONS[key]} (H = {float(alt):.3g} s against the interval {lo:.3g}-{hi:.3g} s)"
    if key == "drem_not_converged" and online.get("not_converged_reason"):
        return f"{REASONS[key]}: {online['not_converged_reason']}"
    return REASONS[key]


def parameter_verdicts(verdict, keys: list[str], ident) -> dict:
    """The verdict of each parameter (H, D, the governor correction) with its reasons' keys."""
    def word(code):
        return VERDICTS[int(code)]

    h_keys = [k for k in keys if k not in NOTES]
    out = {"H": {"verdict": word(verdict.code), "reasons": h_keys}}
    if ident is not None:
        out["D"] = {"verdict": D_VERDICTS[int(verdict.d_code)],
                    "reasons": [k for k in keys if k in ("negative_damping", "d_interval_wide")],
                    "meaning": D_MEANING}
        out["governor_correction"] = {"verdict": word(verdict.governor_code),
                                      "value_percent": _num(100 * ident.governor_gain_error),
                                      "reasons": [k for k in keys if k == "governor_model_off"]}
    return out


def write_summary(path: Path, entries: list[dict], extra: dict | None = None) -> None:
    data = {"recordings": entries, **(extra or {})}
    Path(path).write_text(json.dumps(data, indent=2) + "\n")


def write_estimates_csv(path: Path, est: Estimate, rep: Replay | None = None) -> None:
    cols = [np.asarray(get(est, rep)) for get in CSV_COLUMNS.values()]
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(CSV_COLUMNS.keys())
        for row in zip(*cols):
            w.writerow([f"{v:.10g}" for v in row])


def format_table(entries: list[dict]) -> str:
    """A text table: H with its 95 % interval and the verdict, the online estimate, the playback."""
    w = max([10] + [len(e["name"]) for e in entries])

    def f(x, fmt):
        return format(x, fmt) if x is not None else "n/a"

    head = (f"{'recording':<{w}} {'H s':>7} {'95 % interval':>16} {'D':>7} {'verdict':<17} "
            f"{'H online':>8} {'I_t %':>6} {'P_t %':>6} {'H ref':>6}  reasons")
    lines = [head, "-" * len(head)]
    for e in entries:
        ci = e.get("H_ci95")
        ci_txt = "n/a" if not ci or ci[0] is None else \
            f"{ci[0]:.2f}-{'inf' if ci[1] is None else format(ci[1], '.2f')}"
        s = e["smape_percent"]
        keys = list(e.get("reasons", {}))
        # H's reasons set the verdict; the findings about D and the governor are said apart
        reasons = ", ".join(k.replace("_", " ") for k in keys if k not in NOTES)
        found = [k.replace("_", " ") for k in keys if k in FINDINGS]
        if found:
            reasons += ("; " if reasons else "") + "findings: " + ", ".join(found)
        lines.append(
            f"{e['name']:<{w}} {f(e['H_s'], '7.2f'):>7} {ci_txt:>16} {f(e['D'], '7.3f'):>7} "
            f"{e['verdict']:<17} {f(e['online']['H_s'], '8.2f'):>8} {f(s['I_t'], '6.2f'):>6} "
            f"{f(s['P_t'], '6.2f'):>6} {f(e['H_reference_s'], '6.2f'):>6}  {reasons}")
    lines.append("H in s (machine base), 95 % interval from the batch identification; H online: the "
                 "paper's DREM/I&I; I_t, P_t: playback sMAPE (paper Eq. 23).")
    return "\n".join(lines)


def plot_estimates(est: Estimate, name: str, out_dir: Path, omega_s: float, a1_reference=None,
                   a2_reference=None, ident: Identified | None = None, rep: Replay | None = None,
                   status: str | None = None, onset_s: float | None = None) -> list[Path]:
    """Figures like the paper's Figs. 5-8: H and D over time, x2, playback (the whole record,
    and 30 s around the event where there is one). Returns the paths.

    ``omega_s``: synchronous speed [rad/s] (H = omega_s / (2 a2), D = a1 / a2). ``status`` (the
    verdict and its main reason) goes into every title, so that a figure of a failed or
    unidentified unit says so. ``onset_s``: the event's time where it is known (a simulation);
    else it is looked for in P and Q as the fleet's validation does.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .fleet_report import PlaybackFigure
    from .windows import WindowCriteria, event_start

    t = np.asarray(est.time_s)
    tag = f" — {status}" if status else ""
    paths = []

    a1_hat, a2_hat = np.asarray(est.a1_hat), np.asarray(est.a2_hat)
    ok = a2_hat > 0
    h_online = np.where(ok, omega_s / (2.0 * np.where(ok, a2_hat, 1.0)), np.nan)
    d_online = np.where(ok, a1_hat / np.where(ok, a2_hat, 1.0), np.nan)
    h_ref = None if a2_reference is None else omega_s / (2.0 * float(a2_reference))
    d_ref = None if a1_reference is None or a2_reference is None else float(a1_reference) / float(a2_reference)
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5.5))
    for ax, online, ref, label, k in ((axes[0], h_online, h_ref, "inertia H [s]", "h"),
                                      (axes[1], d_online, d_ref, "damping D [pu torque / (rad/s)]", "d")):
        ax.plot(t, online, label="online estimate (DREM/I&I)")
        scale = [abs(x) for x in (ref,) if x is not None]
        if ident is not None:
            value = float(ident.h_s if k == "h" else ident.d_pu_s)
            lo, hi = (float(x) for x in (ident.h_ci95 if k == "h" else ident.d_ci95))
            ax.axhline(value, color="tab:red", lw=1.2, label=f"batch identification ({value:.3g})")
            if np.isfinite(lo) and np.isfinite(hi):
                ax.axhspan(lo, hi, color="tab:red", alpha=0.15, label="its 95 % interval")
            scale += [abs(x) for x in (value, lo, hi) if np.isfinite(x)]
        if ref is not None:
            ax.axhline(ref, color="k", ls="--", label=f"reference ({ref:.3g})")
        if scale and k == "h":                 # the online transient would hide the answer
            ax.set_ylim(0.0, 2.0 * max(scale))
        elif scale:
            top = 2.0 * max(scale) + 1e-3
            ax.set_ylim(-top, top)
        ax.set_ylabel(label, fontsize=9)
        ax.legend(loc="best", fontsize=7)
        ax.grid(alpha=0.3)
    if bool(est.converged):
        axes[0].axvline(float(est.convergence_time_s), color="g", ls=":", label="converged")
    axes[1].set_xlabel("time [s]")
    fig.suptitle(f"Inertia and damping: online estimate and batch identification — {name}{tag}",
                 fontsize=10)
    paths.append(_save(fig, out_dir / f"convergence_{name}.png"))

    tr = est.trajectories
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(8, 5))
    axes[0].plot(t, np.asarray(tr.x2_hat_rad_s), label="I&I observer", lw=1.6, color="tab:red", alpha=0.6)
    axes[0].plot(t, np.asarray(tr.x2_meas_rad_s), label="measured", lw=0.8, color="k")
    axes[0].set_ylabel("x2 [rad/s]")
    axes[0].legend(loc="best", fontsize=8)
    axes[1].plot(t, np.asarray(tr.x2_hat_rad_s - tr.x2_meas_rad_s), lw=0.8)
    axes[1].set_ylabel("x2 error [rad/s]")
    axes[1].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle(f"Speed deviation x2, observer vs measurement — {name}{tag}", fontsize=10)
    paths.append(_save(fig, out_dir / f"x2_{name}.png"))

    traces = playback_traces(est, rep)
    p_meas, q_meas = traces["P_t"][0], traces["Q_t"][0]
    criteria = WindowCriteria()
    onset = onset_s if onset_s is not None else event_start(
        traces["time_s"], [p_meas, q_meas], threshold=criteria.onset_threshold)
    label = f"simulated (3rd-order model, {'identified' if rep is not None else 'online'} H and D)"
    figure = PlaybackFigure()
    try:
        paths.append(out_dir / f"playback_{name}.png")
        figure.draw(traces, paths[-1], f"{name}{tag}", label, onset, criteria.event_s)
        if onset is not None:
            paths.append(out_dir / f"playback_{name}_event.png")
            figure.draw(traces, paths[-1], f"{name}{tag}, 30 s around the event", label, onset,
                        criteria.event_s, xlim=(onset - 5.0, onset + 25.0))
    finally:
        figure.close()
    return paths


def playback_traces(est: Estimate, rep: Replay | None = None) -> dict:
    """Measured and played-back x2, I_t, P_t, Q_t (host arrays): {"time_s": t, channel:
    (measured, simulated)}, the replay with the identified H and D where ``rep`` has one."""
    tr = est.trajectories
    pb = _playback(est, rep)
    out = {"time_s": np.asarray(est.time_s)}
    for k, meas, sim in (("x2", tr.x2_meas_rad_s, pb.x2_rad_s), ("I_t", tr.i_t_pu, pb.i_t_pu),
                         ("P_t", tr.p_t_pu, pb.p_t_pu), ("Q_t", tr.q_t_pu, pb.q_t_pu)):
        out[k] = (np.asarray(meas), np.asarray(sim))
    return out


def _limit_to_measurement(ax, meas, sim):
    """Keep the measurement readable when the playback runs away (the title says it diverged)."""
    fin = meas[np.isfinite(meas)]
    if not fin.size:
        return
    lo, hi = float(fin.min()), float(fin.max())
    pad = 0.5 * max(hi - lo, 1e-6 * max(abs(hi), 1.0))
    sim_f = sim[np.isfinite(sim)]
    if sim_f.size and (sim_f.min() < lo - 4 * pad or sim_f.max() > hi + 4 * pad):
        ax.set_ylim(lo - 4 * pad, hi + 4 * pad)


def _save(fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
