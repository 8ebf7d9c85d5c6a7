"""Every ANDES integration step of the EXAC1 units around the bolted fault (for ``exac1_ve.py``).

    /work/andes-venv/bin/python experiments/andes_bench/exac1_steps.py   # ANDES venv, from the repo root

``generate.py`` keeps the exciters' EFD at the 60 frames/s of the recordings; the trace of EXAC1's
difference after the fault (``exac1_ve.py``) needs ANDES's own exciter variables at each of its
integration steps (h = 1/240 s): this script re-runs the ``fault`` event of the ``*_lib`` cases
exactly as ``generate.py`` does (same case set-up, event rule, fixed-step trapezoid and Newton
tolerance, ``generate.simulate``) up to ``T_EVENT + 1 s`` and writes, for every EXAC1 unit, the
steps from ``T_EVENT - 0.1 s`` to ``T_EVENT + 1 s`` to ``data/<case>/fault_exac1_steps.csv.gz``
(column ``time_s``, then ``<tag>/<variable>``; 10-20 kB a case), and rewrites data/MANIFEST.md:

- ``v``: terminal voltage VT [pu]; ``XadIfd``: the machine's field current LadIfd [pu], the exciter's input;
- ``LA_y``: VR, the regulator's output (ANDES's LagAntiWindup KA/(1 + s TA), limits VRMIN/VRMAX);
- ``INT_y``: VE, the exciter alternator's voltage (TE dVE/dt = VR - VFE); ``VFE``; ``vout``: EFD;
- ``WF_y``: the rate feedback; ``vi``: the regulator's input, vref - v - WF_y plus the stabiliser's
  output VOTHSG where the unit has one (ANDES adds it there); ``vref``;
- ``LA_zu``, ``LA_zl``: ANDES's anti-windup flags of the regulator (1: pegged).

ANDES is GPL-3: like generate.py, this script only writes outputs; the project never imports it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import generate as g  # noqa: E402  (imports ANDES)

VARS = ("v", "XadIfd", "LA_y", "INT_y", "VFE", "vout", "WF_y", "vi", "vref")
WINDOW_S = (g.T_EVENT - 0.1, g.T_EVENT + 1.0)


def one_case(case):
    base = g.load_case(case)
    machines = []
    for i in g.select_machines(base, case):
        bus, gid = int(base.GENROU.bus.v[i]), g.machine_id(base, i)
        machines.append({"uid": i, "andes_idx": base.GENROU.idx.v[i], "bus": bus, "id": gid,
                         "tag": f"B{bus}_G{gid}", "mbase": float(base.GENROU.Sn.vin[i])})
    events = g.choose_events(base, case, machines)
    ss = g.load_case(case, g.event_models("fault", events))
    mach = [dict(m, uid=ss.GENROU.idx2uid(m["andes_idx"])) for m in machines]
    units, extra, watch = [], [], []
    for m in mach:
        _, exc, _ = g.controls_of(ss, m["andes_idx"])
        if exc is None or exc[0] != "EXAC1":
            continue
        mdl, j = ss.models["EXAC1"], exc[1]
        units.append(m)
        extra += [(f"{m['tag']}/{v}", getattr(mdl, v), j) for v in VARS]
        watch.append((m["tag"], "exciter", "EXAC1", j, "LA_lim", mdl.LA_lim))
    if not units:
        print(f"{case}: no EXAC1 unit")
        return
    sim = g.simulate(ss, units, WINDOW_S[1], watch=watch, extra=extra)
    n = sim["extra"].shape[0]
    k = np.arange(int(round(WINDOW_S[0] * g.STEP_RATE)), int(round(WINDOW_S[1] * g.STEP_RATE)) + 1)
    k = k[k < n]
    header = ["time_s"] + [c for c, *_ in extra]
    cols = [k / g.STEP_RATE] + [sim["extra"][k, c] for c in range(len(extra))]
    fmts = ["%.6f"] + ["%.10g"] * len(extra)
    for w, (tag, *_) in enumerate(watch):
        header += [f"{tag}/LA_zu", f"{tag}/LA_zl"]
        cols += [sim["limit_flags"][k, w, 0].astype(int), sim["limit_flags"][k, w, 1].astype(int)]
        fmts += ["%d", "%d"]
    path = g.DATA / case / "fault_exac1_steps.csv.gz"
    g.write_csv_gz(path, header, cols, fmts)
    print(f"{case}: {[m['tag'] for m in units]} -> {path} ({path.stat().st_size} bytes)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", nargs="+", default=["ieee14_lib", "npcc_lib", "wecc_lib"],
                    choices=("ieee14_lib", "npcc_lib", "wecc_lib"))
    args = ap.parse_args()
    g.setup_logging()
    for case in args.case:
        one_case(case)
    g.write_manifest()  # data/MANIFEST.md lists the new files and sizes


if __name__ == "__main__":
    main()
