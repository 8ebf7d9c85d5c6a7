"""EXAC1 during the field forcing of a deep voltage dip: ANDES's alternator voltage VE against the
PSS/E block diagram, step by step.

    python experiments/andes_bench/exac1_ve.py   # after exac1_steps.py; before new_models.py, which reports it

PSS/E EXAC1 (the 1981 IEEE type AC1; IEEE Std 421.5 AC1A without VA limits): the regulator
VR = KA/(1 + s TA) u has non-windup limits [VRMIN, VRMAX], and the exciter alternator integrates
TE dVE/dt = VR - VFE with VFE = KD LadIfd + KE VE + SE(VE) VE; EFD = VE FEX(KC LadIfd / VE).
While VR sits on VRMAX the alternator's input is VRMAX - VFE, never more.

ANDES 2.0 builds the same blocks (LagAntiWindup, Integrator) and integrates them by the implicit
trapezoid, VE(n+1) = VE(n) + h/2 (f(n) + f(n+1)), f = (VR - VFE)/TE. Its anti-windup limiter pegs
the regulator state at VRMAX inside the Newton iterations; ``data/<case>/fault_exac1_steps.csv.gz``
(``exac1_steps.py``: ANDES's own VR, VE, VFE of every step) shows that at some of the steps on the
limit, VE grows by twice what the trapezoid gives with the recorded VR and VFE, as if VR at the
start of the step were 16-17 pu against VRMAX = 7.3 (part 1: each step's VE increment against
the trapezoid of the recorded values, and the VR that the increment implies).

Part 2 isolates the consequence: the PSS/E block diagram of EXAC1, driven by ANDES's own terminal
voltage VT, field current LadIfd and stabiliser output VOTHSG (where the unit has one; taken from
ANDES's regulator input ``vi``) of each step (linear between steps), integrated by SciPy
(``solve_ivp``, Radau) from ANDES's steady state (a) as the block diagram has it, and (b) with
ANDES's excess VE increments of part 1 added at the steps where they occur; and (c) jaxdse's own
EXAC1 (``jd.EXAC1`` from the unit's constants: its initial_state, vector_field and efd) driven
the same way. EFD of each against ANDES's (largest error over the steps after the event), and
jaxdse's against the block diagram's. The exciter runs open loop here (VT and LadIfd imposed), as
the terminal voltage is in the playback.

Writes exac1_ve.json here (read by new_models.py). No ANDES import: only its recordings are read.
"""

import argparse
import json
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

jax.config.update("jax_enable_x64", True)
import jaxdse as jd  # noqa: E402

HERE = Path(__file__).parent
DATA = HERE / "data"
T_EVENT_S = 10.0
EXCESS_TOL_PU = 1e-5  # a step whose VE increment leaves the trapezoid of the recorded values by more


def sat_product(ve, e1, se1, e2, se2):
    """SE(VE) VE of the PSS/E quadratic saturation through (E1, SE1), (E2, SE2): B (VE - A)^2 above A."""
    a = np.sqrt(se1 * e1 / (se2 * e2))
    big_a = (a * e2 - e1) / (a - 1.0)
    big_b = se2 * e2 / (e2 - big_a) ** 2
    return big_b * (ve - big_a) ** 2 if ve > big_a else 0.0


def fex(i_n):
    """FEX(IN) of IEEE Std 421.5 Annex D."""
    if i_n <= 0:
        return 1.0
    if i_n <= 0.433:
        return 1.0 - 0.577 * i_n
    if i_n <= 0.75:
        return np.sqrt(0.75 - i_n * i_n)
    if i_n <= 1.0:
        return 1.732 * (1.0 - i_n)
    return 0.0


def trapezoid_check(t, vr, ve, vfe, te):
    """Each step's VE increment against h/2 (f(n) + f(n+1)), f = (VR - VFE)/TE of the recorded
    values: the excess [pu] per step and the VR at the step's start that the increment implies."""
    h = np.diff(t)
    f = (vr - vfe) / te
    excess = np.diff(ve) - h / 2 * (f[:-1] + f[1:])
    implied_vr_n = (2 * np.diff(ve) / h - f[1:]) * te + vfe[:-1]
    return excess, implied_vr_n


def block_diagram(t, vt, ifd, vs, p, x0, ve0, vref, kicks):
    """EXAC1 (TR = TB = TC = 0) from the block diagram, segment by segment between ANDES's steps,
    VT and LadIfd linear in between; ``kicks[n]`` is added to VE at the end of segment n.
    States: regulator lag x (non-windup [VRMIN, VRMAX]), VE (>= 0), rate-feedback lag s."""
    def vfe_of(ve, i):
        return p["KD"] * i + p["KE"] * ve + sat_product(ve, p["E1"], p["SE1"], p["E2"], p["SE2"])

    z = np.array([x0, ve0, vfe_of(ve0, ifd[0])])
    efd = np.empty_like(t)
    efd[0] = ve0 * fex(p["KC"] * ifd[0] / ve0)
    for n in range(len(t) - 1):
        ta, tb = t[n], t[n + 1]

        def f(tt, zz, n=n, ta=ta, tb=tb):
            w = (tt - ta) / (tb - ta)
            v = (1 - w) * vt[n] + w * vt[n + 1]
            i = (1 - w) * ifd[n] + w * ifd[n + 1]
            vso = (1 - w) * vs[n] + w * vs[n + 1]
            x, ve, s = zz
            ve = max(ve, 0.0)
            vfe = vfe_of(ve, i)
            u = vref + vso - v - p["KF"] * (vfe - s) / p["TF"]
            dx = (p["KA"] * u - x) / p["TA"]
            if (x >= p["VRMAX"] and dx > 0) or (x <= p["VRMIN"] and dx < 0):
                dx = 0.0
            vr = min(max(x, p["VRMIN"]), p["VRMAX"])
            dve = (vr - vfe) / p["TE"]
            if zz[1] <= 0 and dve < 0:
                dve = 0.0
            return [dx, dve, (vfe - s) / p["TF"]]

        sol = solve_ivp(f, (ta, tb), z, method="Radau", rtol=1e-9, atol=1e-11)
        z = sol.y[:, -1].copy()
        z[0] = min(max(z[0], p["VRMIN"]), p["VRMAX"])
        z[1] += kicks[n]
        ve = max(z[1], 0.0)
        efd[n + 1] = ve * fex(p["KC"] * ifd[n + 1] / ve) if ve > 0 else 0.0
    return efd


class _Inputs(NamedTuple):  # the fields of what a jaxdse exciter reads at one instant
    vt_pu: float
    v_re_pu: float
    v_im_pu: float
    i_re_pu: float
    i_im_pu: float
    ifd_pu: float
    vs_pu: float


def jaxdse_exac1(t, vt, ifd, vs, p, efd0):
    """jaxdse's own EXAC1 (``jd.EXAC1``: its initial_state, vector_field and efd) from the unit's
    constants, driven by the same VT and LadIfd, segment by segment as :func:`block_diagram`."""
    ex = jd.EXAC1(t_r_s=p["TR"], t_b_s=p["TB"], t_c_s=p["TC"], ka=p["KA"], t_a_s=p["TA"],
                  vr_max_pu=p["VRMAX"], vr_min_pu=p["VRMIN"], t_e_s=p["TE"], kf=p["KF"], t_f_s=p["TF"],
                  kc=p["KC"], kd=p["KD"], ke=p["KE"], e1_pu=p["E1"], se1=p["SE1"], e2_pu=p["E2"],
                  se2=p["SE2"])

    def inputs(v, i, s):
        return _Inputs(v, v, 0.0, 0.0, 0.0, i, s)

    z, vref = ex.initial_state(efd0, inputs(vt[0], ifd[0], vs[0]))
    vf = jax.jit(lambda z, v, i, s: ex.vector_field(z, inputs(v, i, s), vref))
    out = jax.jit(lambda z, v, i, s: ex.efd(z, inputs(v, i, s), vref))
    z = np.asarray(z, float)
    efd = np.empty_like(t)
    efd[0] = float(out(z, vt[0], ifd[0], vs[0]))
    for n in range(len(t) - 1):
        ta, tb = t[n], t[n + 1]

        def f(tt, zz, n=n, ta=ta, tb=tb):
            w = (tt - ta) / (tb - ta)
            return np.asarray(vf(zz, (1 - w) * vt[n] + w * vt[n + 1], (1 - w) * ifd[n] + w * ifd[n + 1],
                                 (1 - w) * vs[n] + w * vs[n + 1]))

        z = solve_ivp(f, (ta, tb), z, method="Radau", rtol=1e-9, atol=1e-11).y[:, -1]
        efd[n + 1] = float(out(z, vt[n + 1], ifd[n + 1], vs[n + 1]))
    return efd


def one_unit(df, tag, p):
    if p["TR"] or p["TB"] or p["TC"]:
        raise ValueError(f"{tag}: block_diagram() takes TR = TB = TC = 0 (generate.py's EXAC1 choice)")
    c = lambda v: df[f"{tag}/{v}"].to_numpy()  # noqa: E731
    t, vt, ifd, vr, ve, vfe, efd_andes = (df["time_s"].to_numpy(), c("v"), c("XadIfd"), c("LA_y"),
                                          c("INT_y"), c("VFE"), c("vout"))
    vs = c("vi") - (c("vref") - vt - c("WF_y"))  # the stabiliser's output VOTHSG (0 without one)
    pegged = (c("LA_zu") > 0) | (c("LA_zl") > 0)
    excess, implied = trapezoid_check(t, vr, ve, vfe, p["TE"])
    big = np.abs(excess) > EXCESS_TOL_PU
    on_limit = pegged[:-1] | pegged[1:]
    k0 = int(np.argmin(np.abs(t - T_EVENT_S)))  # the pre-event step (steady state)
    vref = vt[k0] - vs[k0] + vr[k0] / p["KA"]
    after = t > T_EVENT_S
    res = {"steps": int(len(t) - 1), "steps_with_vr_pegged": int(on_limit.sum()),
           "steps_with_excess": int(big.sum()),
           "steps_with_excess_and_vr_pegged": int((big & on_limit).sum()),
           "excess_ve_total_pu": float(excess[big].sum()),
           "excess_steps_at_s": [round(float(t[n + 1]), 4) for n in np.where(big)[0]],
           "implied_vr_at_step_start_pu": [round(float(implied[n]), 3) for n in np.where(big)[0]],
           "vr_max_pu": p["VRMAX"], "max_recorded_vr_pu": float(vr.max()),
           "max_abs_stabiliser_output_pu": float(np.max(np.abs(vs))),
           "max_abs_excess_off_limit_pu": float(np.max(np.abs(excess[~on_limit]), initial=0.0))}
    sl = slice(k0, None)
    for name, kicks in (("block_diagram", np.zeros(len(t) - 1)),
                        ("with_andes_excess", np.where(big, excess, 0.0))):
        e = np.full_like(t, np.nan)
        e[sl] = block_diagram(t[sl], vt[sl], ifd[sl], vs[sl], p, vr[k0], ve[k0], vref, kicks[k0:])
        err = (e - efd_andes)[after]
        res[name] = {"rms_efd_err_pu": float(np.sqrt(np.mean(err ** 2))),
                     "max_abs_efd_err_pu": float(np.max(np.abs(err))),
                     "efd_err_at_s": float(t[after][np.argmax(np.abs(err))])}
    e = np.full_like(t, np.nan)
    e[sl] = jaxdse_exac1(t[sl], vt[sl], ifd[sl], vs[sl], p, efd_andes[k0])
    bd = block_diagram(t[sl], vt[sl], ifd[sl], vs[sl], p, vr[k0], ve[k0], vref, np.zeros(len(t) - 1 - k0))
    res["jaxdse_vs_block_diagram_max_abs_efd_pu"] = float(np.max(np.abs(e[sl] - bd)))
    res["jaxdse"] = {"max_abs_efd_err_pu": float(np.max(np.abs((e - efd_andes)[after])))}
    res["andes_peak_efd_pu"] = float(efd_andes[after].max())
    return res


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", nargs="+", default=["ieee14_lib", "npcc_lib", "wecc_lib"],
                    help="cases whose fault_exac1_steps.csv.gz exists (others are named and skipped)")
    args = ap.parse_args()
    out = {"event": "fault", "excess_tol_pu": EXCESS_TOL_PU, "skipped": [], "units": {}}
    for case in args.case:
        d = DATA / case
        path = d / "fault_exac1_steps.csv.gz"
        if not path.exists():
            out["skipped"].append(f"{case}: no fault_exac1_steps.csv.gz (exac1_steps.py)")
            continue
        truth = json.loads((d / "truth.json").read_text())
        df = pd.read_csv(path)
        for m in truth["machines"]:
            if m["exciter"]["model"] == "EXAC1" and f"{m['tag']}/v" in df:
                out["units"][f"{case} {m['tag']}"] = one_unit(df, m["tag"],
                                                              m["exciter"]["params_mbase_psse_order"])
    (HERE / "exac1_ve.json").write_text(json.dumps(out, indent=1) + "\n")
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
