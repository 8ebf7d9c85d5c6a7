"""Independent-simulator test bench for jaxdse: PMU-like recordings simulated with ANDES.

What it makes, for each case c in {ieee14, npcc, wecc}, under ``data/<c>/``:

* ``line_trip.csv.gz``, ``load_step.csv.gz``, ``gen_trip.csv.gz`` (70 s, event at t = 10 s, 60 frames/s)
  and ``ambient.csv.gz`` (600 s, Ornstein-Uhlenbeck load fluctuations, 30 frames/s): noise-free
  terminal measurements of the recorded GENROU machines, columns ``time_s`` then, per machine tag
  ``B<bus>_G<id>``, ``<tag>/F`` [Hz], ``<tag>/VM`` [pu of bus kV], ``<tag>/VA`` [deg, wrapped to
  (-180, 180]], ``<tag>/IM`` [pu on the system base at the bus kV base], ``<tag>/IA`` [deg, wrapped];
  the current is the machine's own output current (generator convention, out of the machine).
* ``<event>_truth.csv.gz``: rotor angle, speed, mechanical and electrical torque of the recorded
  machines at the same frames.
* ``truth.json``: machine data (H, D, GENROU, governor, exciter, PSS), events, load model,
  statistics and the self-checks.
* ``<c>.raw`` (PSS/E v33) and ``<c>.dyr``: the simulated system, written from the ANDES data.

The script also re-reads its own .raw/.dyr with ANDES and checks that they reproduce the power flow,
the dynamic data and a short line-trip simulation.

ANDES is GPL-3. This script is the only file of the project that imports it; the project never
imports ANDES, and no ANDES code or case file is stored here, only the outputs of this script.
ANDES: H. Cui, F. Li, K. Tomsovic, "Hybrid Symbolic-Numeric Framework for Power System Modeling
and Analysis," IEEE Transactions on Power Systems, vol. 36, no. 2, pp. 1373-1384, 2021.

Install ANDES in its own virtual environment (never in the project's) and run from the repo root::

    python3 -m venv /work/andes-venv && /work/andes-venv/bin/pip install andes==2.0.0
    /work/andes-venv/bin/python experiments/andes_bench/generate.py                # all cases
    /work/andes-venv/bin/python experiments/andes_bench/generate.py --case ieee14  # one case

Derived cases (a function each, under "derived cases" below, stating its parameter choices):
``npcc_exdc2`` (npcc with its exciters swapped to EXDC2) and ``npcc_xd2_below_xl`` (npcc with
X''d below Xl on every GENROU), simulated for the three events only::

    A=/work/andes-venv/bin/python
    $A experiments/andes_bench/generate.py --case npcc_exdc2 --scenario line_trip load_step gen_trip
    $A experiments/andes_bench/generate.py --case npcc_xd2_below_xl --scenario line_trip load_step gen_trip

``ieee14_lib``, ``npcc_lib``, ``wecc_lib`` (the recorded units' exciters swapped to the PSS/E
library models of issue 33 that ANDES 2.0 has, every second governor to IEESGO; see "derived cases
with the PSS/E library models" below), simulated for the line trip and the load step (70 s), and
for the large events (40 s, T_RUN): a generator trip and ``fault``, a bolted three-phase bus fault
cleared after 0.1 s (FAULT_*; deep enough that exciter limits are reached: ANDES's limiter flags of
every recorded unit's exciter and governor are recorded at each step into truth.json,
``andes_limits_reached``, and the exciters' EFD into ``<event>_controls.csv.gz``), without the
round trip (ANDES's .dyr reader takes ESAC1A and ESST1A constants in another order than the PSS/E
order written); ``new_models.py`` plays them back::

    $A experiments/andes_bench/generate.py --case ieee14_lib npcc_lib wecc_lib \
        --scenario line_trip load_step --no-verify
    $A experiments/andes_bench/generate.py --case ieee14_lib npcc_lib --scenario fault gen_trip --no-verify

Options: ``--scenario`` (any of line_trip, load_step, gen_trip, fault, ambient; none: only rewrite and
verify the .raw/.dyr), ``--no-verify`` (skip the .raw/.dyr round trip), ``--step-check`` (rerun at
half the step and record the largest differences). Several runs of one case (e.g. one per scenario,
in parallel) merge their results into truth.json. Output is deterministic (seeded noise, gzip
without timestamps).

Runtime: ANDES takes about 2.7 ms (ieee14), 4 ms (npcc) and 5 ms (wecc) per integration step on an
idle core; a case is 3 x 16,800 event steps + 72,000 ambient steps + the round trip, i.e. about
6 min (ieee14), 9 min (npcc) and 11 min (wecc) on an idle machine, several times that on a busy one.
"""

from __future__ import annotations

import argparse
import gzip
import io
import json
import logging
import time
from pathlib import Path

import andes
import numpy as np

HERE = Path(__file__).resolve().parent
DATA = HERE / "data"

STEP_RATE = 240  # integration steps per second: h = 1/240 s, 4 steps per 60 fps event frame
AMBIENT_STEP_RATE = 120  # ambient: h = 1/120 s, 4 steps per 30 fps frame (the OU path lives on 1/240 s)
TDS_TOL = 1e-6  # Newton tolerance of the ANDES implicit trapezoid
T_EVENT = 10.0
T_EVENT_RUN = 70.0
T_RUN = {"gen_trip": 40.0, "fault": 40.0}  # the large events of the *_lib cases: 30 s after the event
T_AMBIENT = 600.0
FPS = {"line_trip": 60, "load_step": 60, "gen_trip": 60, "fault": 60, "ambient": 30}
SCENARIOS = tuple(FPS)
LOAD_STEP_FRACTION = 0.05  # load step: 5 % of the total system load
LOAD_STEP_MAX_RISE = 0.25  # ... spread over the nearest loads so that none rises by more than 25 %
GEN_TRIP_FRACTION = 0.03  # generator trip: the unrecorded unit whose output is nearest 3 % of load
FAULT_DURATION_S = 0.1  # fault: a bolted three-phase bus fault, cleared after 6 cycles (no
FAULT_XF_PU = 1e-4  # ... branch lost), at the bus with the most recorded units within 2 hops
FAULT_HOPS = 2
OU_TAU_S = 5.0  # ambient: time constant of every load's Ornstein-Uhlenbeck process
# ou_sigma: relative std of each load; wecc at 0.05 lost synchronism within the 600 s, hence 0.02

CASES = {
    "ieee14": {"files": ("ieee14/ieee14_full.xlsx",), "n_record": None, "ou_sigma": 0.03, "seed": 14},
    "npcc": {"files": ("npcc/npcc.raw", "npcc/npcc_full.dyr"), "n_record": 10, "ou_sigma": 0.03,
             "seed": 140},
    "wecc": {"files": ("wecc/wecc.raw", "wecc/wecc_full.dyr"), "n_record": 10, "ou_sigma": 0.02,
             "seed": 179, "load_step_max_rise": 0.10},  # 25 %: 3 GW at buses 77-79, loss of synchronism
}
# Derived cases (a function each, below: npcc_exdc2, npcc_xd2_below_xl): the shipped case changed by
# CASES[case]["dyr"] (its .dyr text) or CASES[case]["modify"] (before set-up); run with
# --scenario line_trip load_step gen_trip.

# Standard models with typical data, added only to GENROU units that the case leaves without one.
ADDED_EXCITER = ("SEXS", {"TATB": 0.1, "TB": 10.0, "K": 100.0, "TE": 0.05, "EMIN": 0.0, "EMAX": 5.0})
ADDED_GOVERNOR = ("TGOV1", {"R": 0.05, "T1": 0.5, "VMAX": 1.05, "VMIN": 0.0, "T2": 1.0, "T3": 2.1,
                            "Dt": 0.0})

# PSS/E .dyr record layouts: ICONs (written first) and CONs in PSS/E order, as ANDES parameter names.
# Values are on the machine base, as ANDES takes them from a .dyr ("vin").
DYR = {
    "GENROU": ((), ("Td10", "Td20", "Tq10", "Tq20", "H", "D", "xd", "xq", "xd1", "xq1", "xd2", "xl",
                    "S10", "S12")),
    "GENCLS": ((), ("H", "D")),
    "TGOV1": ((), ("R", "T1", "VMAX", "VMIN", "T2", "T3", "Dt")),
    "IEEEG1": (("syn2_bus", "syn2_id"), ("K", "T1", "T2", "T3", "UO", "UC", "PMAX", "PMIN", "T4", "K1",
                                         "K2", "T5", "K3", "K4", "T6", "K5", "K6", "T7", "K7", "K8")),
    "IEEEX1": ((), ("TR", "KA", "TA", "TB", "TC", "VRMAX", "VRMIN", "KE", "TE", "KF1", "TF1", "Switch",
                    "E1", "SE1", "E2", "SE2")),
    "ESDC2A": ((), ("TR", "KA", "TA", "TB", "TC", "VRMAX", "VRMIN", "KE", "TE", "KF", "TF1", "Switch",
                    "E1", "SE1", "E2", "SE2")),
    "EXDC2": ((), ("TR", "KA", "TA", "TB", "TC", "VRMAX", "VRMIN", "KE", "TE", "KF1", "TF1", "Switch",
                   "E1", "SE1", "E2", "SE2")),
    "EXST1": ((), ("TR", "VIMAX", "VIMIN", "TC", "TB", "KA", "TA", "VRMAX", "VRMIN", "KC", "KF", "TF")),
    "ESST3A": ((), ("TR", "VIMAX", "VIMIN", "KM", "TC", "TB", "KA", "TA", "VRMAX", "VRMIN", "KG", "KP",
                    "KI", "VBMAX", "KC", "XL", "VGMAX", "THETAP", "TM", "VMMAX", "VMMIN")),
    "SEXS": ((), ("TATB", "TB", "K", "TE", "EMIN", "EMAX")),
    "IEEEST": (("MODE", "busr"), ("A1", "A2", "A3", "A4", "A5", "A6", "T1", "T2", "T3", "T4", "T5", "T6",
                                  "KS", "LSMAX", "LSMIN", "VCU", "VCL")),
    "ST2CUT": (("MODE", "busr", "MODE2", "busr2"), ("K1", "K2", "T1", "T2", "T3", "T4", "T5", "T6", "T7",
                                                    "T8", "T9", "T10", "LSMAX", "LSMIN", "VCU", "VCL")),
}
GENROU_PARAMS = ("ra", "xl", "xd", "xq", "xd1", "xq1", "xd2", "xq2", "Td10", "Tq10", "Td20", "Tq20",
                 "S10", "S12")
MEANING = {
    "TGOV1": "R droop [pu speed/pu power], T1 valve [s], VMAX/VMIN valve limits [pu], T2/T3 lead/lag [s], "
             "Dt turbine damping [pu]",
    "IEEEG1": "PSS/E IEEEG1 (K=1/R, T1..T7 [s], UO/UC valve rates [pu/s], PMAX/PMIN [pu], K1..K8 fractions); "
              "UO/UC as ANDES 2.0 simulates them: its data value times Sb/Tn",
    "IEEEX1": "PSS/E IEEEX1 (IEEE DC1A-like), limits and gains in pu",
    "ESDC2A": "PSS/E ESDC2A (IEEE DC2A)",
    "EXDC2": "PSS/E EXDC2 (1981 IEEE DC2), parameters chosen as npcc_exdc2 states",
    "EXST1": "PSS/E EXST1 (IEEE ST1)",
    "ESST3A": "PSS/E ESST3A (IEEE ST3A)",
    "SEXS": "PSS/E SEXS simplified excitation system",
    "IEEEST": "PSS/E IEEEST stabilizer (ICONs: input MODE, remote bus)",
    "ST2CUT": "PSS/E ST2CUT stabilizer (ICONs: MODE, bus, MODE2, bus2)",
}

log = logging.getLogger("andes_bench")


# ----------------------------------------------------------------------------------------------------
# case set-up
# ----------------------------------------------------------------------------------------------------

def _group_links(ss, group, key):
    """{controlled device idx: (model name, own idx)} for the in-service devices of a group."""
    out = {}
    for name, mdl in ss.groups[group].models.items():
        for idx, dev, u in zip(mdl.idx.v, getattr(mdl, key).v, mdl.u.v):
            if u:
                out[dev] = (name, idx)
    return out


def load_case(case, events=()):
    """Load a shipped ANDES case, add the missing standard controls and the given events; solve the PF."""
    files = [andes.get_case(f) for f in CASES[case]["files"]]
    if "dyr" in CASES[case]:  # a derived case whose .dyr records are rewritten (npcc_exdc2)
        files[1] = _derived_dyr(case, files[1])
    ss = andes.load(files[0], addfile=files[1] if len(files) > 1 else None, setup=False,
                    no_output=True, default_config=True)
    gov = _group_links(ss, "TurbineGov", "syn")
    exc = _group_links(ss, "Exciter", "syn")
    added = []
    for gidx, u in zip(ss.GENROU.idx.v, ss.GENROU.u.v):
        if not u:
            continue
        if gidx not in gov:
            ss.add(ADDED_GOVERNOR[0], {"syn": gidx, "idx": f"added_{ADDED_GOVERNOR[0]}_{gidx}",
                                       **ADDED_GOVERNOR[1]})
            added.append((gidx, ADDED_GOVERNOR[0]))
        if gidx not in exc:
            ss.add(ADDED_EXCITER[0], {"syn": gidx, "idx": f"added_{ADDED_EXCITER[0]}_{gidx}",
                                      **ADDED_EXCITER[1]})
            added.append((gidx, ADDED_EXCITER[0]))
    if "modify" in CASES[case]:  # a derived case (npcc_exdc2, npcc_xd2_below_xl)
        CASES[case]["modify"](ss)
    for model, params in events:
        ss.add(model, params)
    ss.setup()
    if not ss.PFlow.run():
        raise RuntimeError(f"{case}: power flow did not converge")
    ss.bench_added = added
    return ss


def _norm_id(sub):
    """PSS/E machine ID as text: the .raw ID where the case has one (1.0 -> '1'), else '1'."""
    if sub is None or str(sub).strip() in ("", "None"):
        return "1"
    try:
        f = float(sub)
    except ValueError:
        return str(sub).strip()
    if np.isnan(f):
        return "1"
    return str(int(f)) if f == int(f) else str(sub).strip()


def machine_id(ss, uid):
    return _norm_id(ss.GENROU.subidx.v[uid])


def gen_ids(ss):
    """PSS/E machine ID of every static generator."""
    out = {}
    for mdl in (ss.PV, ss.Slack):
        for idx, sub in zip(mdl.idx.v, mdl.subidx.v):
            out[idx] = _norm_id(sub)
    return out


def select_machines(ss, case):
    """Recorded machines: all GENROU of ieee14; else the n largest MBASE among GENROU units that the
    shipped case equips with both a governor and an exciter (ties: lower bus number first)."""
    gov = _group_links(ss, "TurbineGov", "syn")
    exc = _group_links(ss, "Exciter", "syn")
    added = {g for g, _ in ss.bench_added}
    cand = [i for i in range(ss.GENROU.n) if ss.GENROU.u.v[i] and ss.GENROU.idx.v[i] in gov
            and ss.GENROU.idx.v[i] in exc and ss.GENROU.idx.v[i] not in added]
    cand.sort(key=lambda i: (-ss.GENROU.Sn.v[i], int(ss.GENROU.bus.v[i]), machine_id(ss, i)))
    n = CASES[case]["n_record"]
    return cand if n is None else cand[:n]


def _branch_kind(ss):
    line = ss.Line
    return (np.asarray(line.trans.v) != 0) | (np.asarray(line.tap.v) != 1) | (np.asarray(line.phi.v) != 0)


def _connected(ss, skip):
    """True if the in-service branches other than index ``skip`` connect all buses."""
    buses = list(ss.Bus.idx.v)
    parent = {b: b for b in buses}

    def find(b):
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        return b

    for i, (b1, b2, u) in enumerate(zip(ss.Line.bus1.v, ss.Line.bus2.v, ss.Line.u.v)):
        if u and i != skip:
            parent[find(b1)] = find(b2)
    return len({find(b) for b in buses}) == 1


def _bus_phasors(ss):
    v = np.asarray(ss.Bus.v.v) * np.exp(1j * np.asarray(ss.Bus.a.v))
    return dict(zip(ss.Bus.idx.v, v))


def choose_events(ss, case, machines):
    """The three events, chosen by fixed rules on the base-case power flow."""
    sb = ss.config.mva
    vb = _bus_phasors(ss)
    total_load = float(np.sum(np.asarray(ss.PQ.p0.v)[np.asarray(ss.PQ.u.v) > 0]))
    # line trip: the in-service non-transformer line between buses of equal base kV with the
    # largest active-power flow whose loss leaves the network connected
    is_tf = _branch_kind(ss)
    best = None
    for i in range(ss.Line.n):
        if not ss.Line.u.v[i] or is_tf[i] or ss.Line.Vn1.v[i] != ss.Line.Vn2.v[i]:
            continue
        v1, v2 = vb[ss.Line.bus1.v[i]], vb[ss.Line.bus2.v[i]]
        y = 1 / complex(ss.Line.r.v[i], ss.Line.x.v[i])
        ysh = complex(ss.Line.g1.v[i] + ss.Line.g.v[i] / 2, ss.Line.b1.v[i] + ss.Line.b.v[i] / 2)
        p = (v1 * np.conj((v1 - v2) * y + v1 * ysh)).real
        if (best is None or abs(p) > best[1]) and _connected(ss, i):
            best = (i, abs(p))
    li = best[0]
    line = {"andes_idx": ss.Line.idx.v[li], "from_bus": int(ss.Line.bus1.v[li]),
            "to_bus": int(ss.Line.bus2.v[li]), "kv": float(ss.Line.Vn1.v[li]),
            "pre_event_flow_mw": round(best[1] * sb, 3)}

    # load step near the largest recorded machine: loads ordered by hop distance from its bus
    # (then by size), taken until they carry 1/LOAD_STEP_MAX_RISE times the step; all scaled alike
    ref = machines[0]
    adj = {b: set() for b in ss.Bus.idx.v}
    for b1, b2, u in zip(ss.Line.bus1.v, ss.Line.bus2.v, ss.Line.u.v):
        if u:
            adj[b1].add(b2)
            adj[b2].add(b1)
    hops, frontier = {ref["bus"]: 0}, [ref["bus"]]
    while frontier:
        nxt = []
        for b in frontier:
            for c in sorted(adj[b]):
                if c not in hops:
                    hops[c] = hops[b] + 1
                    nxt.append(c)
        frontier = nxt
    loads = [i for i in range(ss.PQ.n) if ss.PQ.u.v[i] and ss.PQ.p0.v[i] > 0]
    loads.sort(key=lambda i: (hops[ss.PQ.bus.v[i]], -ss.PQ.p0.v[i], str(ss.PQ.idx.v[i])))
    step = LOAD_STEP_FRACTION * total_load
    chosen, acc = [], 0.0
    for i in loads:
        chosen.append(i)
        acc += ss.PQ.p0.v[i]
        if acc * CASES[case].get("load_step_max_rise", LOAD_STEP_MAX_RISE) >= step:
            break
    factor = 1 + step / acc
    load = {"near_machine": ref["tag"], "factor": factor, "step_mw_at_pf_voltage": step * sb,
            "rule": "loads by hop distance from the machine bus (then size) until no load rises by more "
                    f"than {CASES[case].get('load_step_max_rise', LOAD_STEP_MAX_RISE):.0%}; all scaled alike",
            "total_system_load_mw": total_load * sb,
            "loads": [{"andes_idx": ss.PQ.idx.v[i], "bus": int(ss.PQ.bus.v[i]),
                       "hops_from_machine_bus": hops[ss.PQ.bus.v[i]], "p_mw": ss.PQ.p0.v[i] * sb,
                       "q_mvar": ss.PQ.q0.v[i] * sb} for i in chosen]}

    # generator trip: the unrecorded in-service GENROU whose output is nearest 3 % of the load;
    # ieee14 records every GENROU, so there the smallest unit is tripped and left out of that file
    recorded = {m["uid"] for m in machines}
    pgen = _genrou_p0(ss)
    pool = [i for i in range(ss.GENROU.n) if ss.GENROU.u.v[i] and i not in recorded]
    if pool:
        gi = min(pool, key=lambda i: abs(pgen[i] - GEN_TRIP_FRACTION * total_load))
    else:
        gi = min(range(ss.GENROU.n), key=lambda i: pgen[i])
    gen = {"andes_idx": ss.GENROU.idx.v[gi], "bus": int(ss.GENROU.bus.v[gi]), "id": machine_id(ss, gi),
           "mbase_mva": float(ss.GENROU.Sn.v[gi]), "p_mw": float(pgen[gi] * sb),
           "q_mvar": float(_genrou_q0(ss)[gi] * sb), "recorded_elsewhere": gi in recorded}
    # fault: the bus (not a recorded unit's terminal) with the most recorded units' terminal buses
    # within FAULT_HOPS hops (then the most within 1 hop, then the lower bus number)
    terminals = {m["bus"] for m in machines}

    def hops_from(b0):
        seen, front = {b0: 0}, [b0]
        while front:
            nxt = []
            for b in front:
                for c in adj[b]:
                    if c not in seen and seen[b] < FAULT_HOPS:
                        seen[c] = seen[b] + 1
                        nxt.append(c)
            front = nxt
        return seen

    def score(b):
        h = hops_from(b)
        return (sum(t in h for t in terminals), sum(h.get(t, 9) <= 1 for t in terminals), -int(b))

    fbus = max((b for b in ss.Bus.idx.v if b not in terminals), key=score)
    near = hops_from(fbus)
    fault = {"bus": int(fbus), "kv": float(ss.Bus.Vn.v[ss.Bus.idx2uid(fbus)]),
             "xf_pu_system_base": FAULT_XF_PU, "rf_pu_system_base": 0.0,
             "clear_after_s": FAULT_DURATION_S,
             "recorded_within_hops": {m["tag"]: near[m["bus"]] for m in machines if m["bus"] in near},
             "rule": f"bolted three-phase fault (xf = {FAULT_XF_PU:g} pu) at the bus, other than a "
                     f"recorded unit's terminal, with the most recorded terminals within {FAULT_HOPS} "
                     f"hops; cleared after {FAULT_DURATION_S:g} s with no branch lost"}
    return {"line_trip": line, "load_step": load, "gen_trip": gen, "fault": fault}


def _genrou_p0(ss):
    """PF output of each GENROU's static generator [pu system base]."""
    return np.array([_static_pq(ss, g)[0] for g in ss.GENROU.gen.v])


def _genrou_q0(ss):
    return np.array([_static_pq(ss, g)[1] for g in ss.GENROU.gen.v])


def _static_pq(ss, gen_idx):
    for mdl in (ss.PV, ss.Slack):
        if gen_idx in mdl.idx.v:
            k = mdl.idx2uid(gen_idx)
            return float(mdl.p.v[k]), float(mdl.q.v[k])
    raise KeyError(gen_idx)


def event_models(scenario, ev):
    """ANDES timed-event devices for a scenario (none for ambient)."""
    if scenario == "line_trip":
        return [("Toggle", {"model": "Line", "dev": ev["line_trip"]["andes_idx"], "t": T_EVENT})]
    if scenario == "gen_trip":
        return [("Toggle", {"model": "GENROU", "dev": ev["gen_trip"]["andes_idx"], "t": T_EVENT})]
    if scenario == "fault":
        f = ev["fault"]
        return [("Fault", {"bus": f["bus"], "tf": T_EVENT, "tc": T_EVENT + f["clear_after_s"],
                           "xf": f["xf_pu_system_base"], "rf": f["rf_pu_system_base"]})]
    if scenario == "load_step":
        out = []
        for ld in ev["load_step"]["loads"]:
            for src in ("Req", "Xeq"):  # constant-impedance load: scale both, P and Q rise alike
                out.append(("Alter", {"model": "PQ", "dev": ld["andes_idx"], "src": src, "attr": "v",
                                      "method": "*", "amount": ev["load_step"]["factor"], "t": T_EVENT}))
        return out
    return []


# ----------------------------------------------------------------------------------------------------
# simulation
# ----------------------------------------------------------------------------------------------------

class OULoads:
    """Independent OU processes xi_i on every load, applied as Req, Xeq = (1 + xi_i) * initial value
    (P and Q of a load move together). Exact discretisation on the 1/STEP_RATE grid, seeded; a run
    with a coarser step uses the same path at its own step instants."""

    def __init__(self, ss, sigma, tau, n_steps, seed):
        rng = np.random.default_rng(seed)
        n = ss.PQ.n
        a = np.exp(-1 / (STEP_RATE * tau))
        xi = np.empty((n_steps + 1, n))
        xi[0] = 0.0  # start from the power-flow loads; the variance builds up over ~tau
        noise = sigma * np.sqrt(1 - a * a) * rng.standard_normal((n_steps, n))
        for k in range(n_steps):
            xi[k + 1] = a * xi[k] + noise[k]
        self.xi = xi
        self.ss = ss
        self.req0 = None

    def start(self):
        self.req0 = np.array(self.ss.PQ.Req.v, dtype=float)
        self.xeq0 = np.array(self.ss.PQ.Xeq.v, dtype=float)
        self.apply(0)

    def apply(self, k):
        self.ss.PQ.Req.v[:] = self.req0 * (1 + self.xi[k])
        self.ss.PQ.Xeq.v[:] = self.xeq0 * (1 + self.xi[k])

    def pert(self, t, system):  # ANDES calls this before solving the step that ends at time t
        k = float(t) * STEP_RATE
        if abs(k - round(k)) > 1e-6:
            raise RuntimeError(f"load update off the OU grid at t={float(t)!r}")
        self.apply(int(round(k)))


REC = ("a", "v", "Pe", "Qe", "delta", "omega", "tm", "te", "Id", "Iq")


def limiters_of(ss, machines):
    """Every ANDES limiter (HardLimiter, AntiWindup, the limits inside its blocks: flags zu, zl) of
    the recorded units' exciters and governors: [(tag, kind, model, device uid, limiter name, limiter)]."""
    from andes.core.discrete import Limiter
    out = []
    for m in machines:
        gov, exc, _ = controls_of(ss, m["andes_idx"])
        for kind, c in (("exciter", exc), ("governor", gov)):
            if c is None:
                continue
            name, j = c
            for lname, d in ss.models[name].discrete.items():
                n = ss.models[name].n  # a limiter that ANDES leaves unevaluated keeps 1 flag
                if isinstance(d, Limiter) and np.size(getattr(d, "zu", ())) == n == np.size(d.zl):
                    out.append((m["tag"], kind, name, j, lname, d))
    return out


def limits_reached(watch, flags, step_rate):
    """{tag: {"<kind> <ANDES model>.<limiter>": {upper/lower: seconds at the limit after the
    event, first time, at the limit at t = 0}}}: ANDES's own limiter flags, each integration step."""
    k_ev = int(round(T_EVENT * step_rate))
    out = {}
    for w, (tag, kind, name, _, lname, _) in enumerate(watch):
        for side, col in (("upper", 0), ("lower", 1)):
            on = flags[:, w, col]
            after = on[k_ev + 1:]
            if not after.any():
                continue
            first = (k_ev + 1 + int(np.argmax(after))) / step_rate
            out.setdefault(tag, {})[f"{kind} {name}.{lname} {side}"] = {
                "seconds_after_event": round(float(after.sum()) / step_rate, 4),
                "first_s": round(first, 4), "at_t0": bool(on[0])}
    return out


CONTROL_VARS = {"ESST4B": ("PI1_xi", "PI1_ys", "PI1_y", "PI2_y")}
"""Exciter variables recorded beside the output EFD (``vout``) in ``<event>_controls.csv.gz``."""


def controls_of_recorded(ss, machines):
    """[(column, ANDES variable, device uid)]: each recorded unit's exciter output EFD and
    CONTROL_VARS (addresses are read once the simulation is initialised)."""
    out = []
    for m in machines:
        _, exc, _ = controls_of(ss, m["andes_idx"])
        if exc is None:
            continue
        name, j = exc
        mdl = ss.models[name]
        for var in ("vout",) + CONTROL_VARS.get(name, ()):
            out.append((f"{m['tag']}/{name}.{var}", getattr(mdl, var), j))
    return out


def simulate(ss, machines, t_end, step_rate=STEP_RATE, ou=None, watch=(), extra=()):
    """Fixed-step trapezoidal run on the exact grid k/step_rate; returns every step of REC per machine
    (and, under "limit_flags", the zu, zl flags of the limiters in ``watch``, see limiters_of)."""
    tds = ss.TDS
    cfg = tds.config
    cfg.tf = t_end + 2.0 / step_rate
    cfg.tstep = 1.0 / step_rate
    cfg.fixt, cfg.shrinkt, cfg.tol = 1, 0, TDS_TOL
    cfg.no_tqdm, cfg.criteria, cfg.save_every = 1, 0, 0
    tds.init()
    if not tds.initialized:
        raise RuntimeError("TDS initialisation failed")
    # ANDES adds helper breakpoints 1e-4 s before and after each event time; keep only on-grid times
    keep = [t for t in ss.switch_times if abs(t * step_rate - round(t * step_rate)) < 1e-9]
    ss.switch_dict = {t: ss.switch_dict[t] for t in keep}
    ss.switch_times = np.array(keep)
    ss.n_switches = len(keep)

    gu = np.array([m["uid"] for m in machines], dtype=int)
    bu = np.array(ss.Bus.idx2uid([m["bus"] for m in machines]), dtype=int)
    addr = [("y", ss.Bus.a.a[bu]), ("y", ss.Bus.v.a[bu])]
    addr += [("y", getattr(ss.GENROU, n).a[gu]) for n in ("Pe", "Qe")]
    addr += [("x", getattr(ss.GENROU, n).a[gu]) for n in ("delta", "omega")]
    addr += [("y", getattr(ss.GENROU, n).a[gu]) for n in ("tm", "te", "Id", "Iq")]
    n_steps = int(round(cfg.tf * step_rate))
    buf = np.full((n_steps + 1, len(REC), len(machines)), np.nan)
    flags = np.zeros((n_steps + 1, len(watch), 2), dtype=bool)
    ext = np.full((n_steps + 1, len(extra)), np.nan)
    extra = [(c, "x" if v.v_code == "x" else "y", v.a[j]) for c, v, j in extra]

    def grab(k):
        for j, (kind, a) in enumerate(addr):
            buf[k, j] = (ss.dae.x if kind == "x" else ss.dae.y)[a]
        for c, (_, kind, a) in enumerate(extra):
            ext[k, c] = (ss.dae.x if kind == "x" else ss.dae.y)[a]
        for w, (*_, j, _, lim) in enumerate(watch):
            flags[k, w] = lim.zu[j] > 0.5, lim.zl[j] > 0.5

    grab(0)
    if ou is not None:
        ou.start()
        tds.callpert = ou.pert

    def on_step():  # called by ANDES after every converged step, before the event switches
        k = int(round(float(ss.dae.t) * step_rate))
        if abs(float(ss.dae.t) * step_rate - k) > 1e-6:
            raise RuntimeError(f"step left the fixed grid at t={float(ss.dae.t)!r}")
        ss.dae.t[...] = k / step_rate  # hold the clock exactly on the grid
        tds.deltatmin = 1.0 / step_rate  # ANDES trims h by 5 % after a step with >= 7 Newton iterations
        grab(k)

    tds.streaming_step = on_step
    ok = tds.run(no_summary=True)
    if not ok or np.isnan(buf).any():
        raise RuntimeError("time-domain simulation failed or left steps unrecorded")
    return {**{name: buf[:, j, :] for j, name in enumerate(REC)}, "limit_flags": flags, "extra": ext}


def wrap180(deg):
    """Wrap degrees to (-180, 180]."""
    return 180.0 - np.mod(180.0 - deg, 360.0)


def frames(sim, f0, sb, machines, fps, t_end, step_rate=STEP_RATE):
    """PMU frames from the fine-step record: F by the central difference of the bus angle over
    +-1 step (one-sided at t = 0), phasors and the machine current at the frame instants."""
    stride = step_rate // fps
    k = np.arange(0, int(round(t_end * step_rate)) + 1, stride)
    a = sim["a"]
    dadt = np.empty_like(a[k])
    dadt[1:] = (a[k[1:] + 1] - a[k[1:] - 1]) * step_rate / 2
    dadt[0] = (a[1] - a[0]) * step_rate
    freq = f0 + dadt / (2 * np.pi)
    v = sim["v"][k] * np.exp(1j * a[k])
    s = sim["Pe"][k] + 1j * sim["Qe"][k]
    cur = np.conj(s / v)
    mbase = np.array([m["mbase"] for m in machines])
    # independent check: the machine's own d-q current in the network frame
    cur_dq = (sim["Id"][k] + 1j * sim["Iq"][k]) * np.exp(1j * (sim["delta"][k] - np.pi / 2))
    return {"t": k / step_rate, "F": freq, "VM": sim["v"][k], "VA": wrap180(np.degrees(a[k])),
            "IM": np.abs(cur), "IA": wrap180(np.degrees(np.angle(cur))), "V": v, "I": cur,
            "Pe": sim["Pe"][k], "I_dq": cur_dq, "delta": sim["delta"][k], "omega": sim["omega"][k],
            "pm": sim["tm"][k] * sb / mbase, "pe": sim["te"][k] * sb / mbase}


# ----------------------------------------------------------------------------------------------------
# writers
# ----------------------------------------------------------------------------------------------------

PMU_FMT = {"F": "%.6f", "VM": "%.7f", "VA": "%.5f", "IM": "%.8g", "IA": "%.5f"}
TRUTH_COLS = (("delta", "delta_rad", "%.7f"), ("omega", "omega_pu", "%.10f"),
              ("pm", "pm_pu_mbase", "%.8f"), ("pe", "pe_pu_mbase", "%.8f"))


def write_csv_gz(path, header, columns, fmts):
    text = io.StringIO()
    np.savetxt(text, np.column_stack(columns), fmt=fmts, delimiter=",", header=",".join(header),
               comments="")
    with open(path, "wb") as fh, gzip.GzipFile(filename="", mode="wb", fileobj=fh, mtime=0,
                                               compresslevel=9) as gz:
        gz.write(text.getvalue().encode())


def write_pmu(path, fr, machines, keep):
    header, cols, fmts = ["time_s"], [fr["t"]], ["%.9f"]
    for j, m in enumerate(machines):
        if not keep[j]:
            continue
        for q in ("F", "VM", "VA", "IM", "IA"):
            header.append(f"{m['tag']}/{q}")
            cols.append(fr[q][:, j])
            fmts.append(PMU_FMT[q])
    write_csv_gz(path, header, cols, fmts)


def write_truth_csv(path, fr, machines, keep):
    header, cols, fmts = ["time_s"], [fr["t"]], ["%.9f"]
    for j, m in enumerate(machines):
        if not keep[j]:
            continue
        for key, name, fmt in TRUTH_COLS:
            header.append(f"{m['tag']}/{name}")
            cols.append(fr[key][:, j])
            fmts.append(fmt)
    write_csv_gz(path, header, cols, fmts)


def _g(x):
    return f"{float(x):.10g}"


def write_raw(ss, path, title):
    """PSS/E v33 RAW of the simulated network (PF solution as bus voltages, generator PG/QG)."""
    sb, f0 = ss.config.mva, ss.config.freq
    ids = gen_ids(ss)
    mbase_of = {g: (float(ss.GENROU.Sn.vin[i]), float(ss.GENROU.ra.vin[i]), float(ss.GENROU.xd2.vin[i]))
                for i, g in enumerate(ss.GENROU.gen.v)}
    if hasattr(ss, "GENCLS"):
        for i, g in enumerate(ss.GENCLS.gen.v):
            mbase_of[g] = (float(ss.GENCLS.Sn.vin[i]), float(ss.GENCLS.ra.vin[i]),
                           float(ss.GENCLS.xd1.vin[i]))
    slack_buses = set(ss.Slack.bus.v)
    pv_buses = set(ss.PV.bus.v)
    out = [f"0, {sb:.2f}, 33, 0, 1, {f0:.2f}     / PSS(R)E 33 RAW, jaxdse andes_bench generate.py",
           title[:60], "loads: constant power here, constant impedance in ANDES TDS"]
    for i, b in enumerate(ss.Bus.idx.v):
        ide = 3 if b in slack_buses else 2 if b in pv_buses else 1
        out.append(f"{b}, '{str(ss.Bus.name.v[i])[:12]}', {_g(ss.Bus.Vn.v[i])}, {ide}, "
                   f"{int(ss.Bus.area.v[i] or 1)}, {int(ss.Bus.zone.v[i] or 1)}, 1, "
                   f"{_g(ss.Bus.v.v[i])}, {_g(np.degrees(ss.Bus.a.v[i]))}, 1.1, 0.9, 1.1, 0.9")
    out.append("0 / End of Bus data, Begin Load data")
    count = {}
    for i in range(ss.PQ.n):
        b = ss.PQ.bus.v[i]
        count[b] = count.get(b, 0) + 1
        out.append(f"{b}, '{count[b]}', {int(ss.PQ.u.v[i])}, 1, 1, {_g(ss.PQ.p0.v[i] * sb)}, "
                   f"{_g(ss.PQ.q0.v[i] * sb)}, 0, 0, 0, 0, 1, 1, 0")
    out.append("0 / End of Load data, Begin Fixed shunt data")
    count = {}
    if hasattr(ss, "Shunt"):
        for i in range(ss.Shunt.n):
            b = ss.Shunt.bus.v[i]
            count[b] = count.get(b, 0) + 1
            out.append(f"{b}, '{count[b]}', {int(ss.Shunt.u.v[i])}, {_g(ss.Shunt.g.v[i] * sb)}, "
                       f"{_g(ss.Shunt.b.v[i] * sb)}")
    out.append("0 / End of Fixed shunt data, Begin Generator data")
    gens = []
    for mdl in (ss.PV, ss.Slack):
        for i, g in enumerate(mdl.idx.v):
            gens.append((int(mdl.bus.v[i]), ids[g], mdl, i, g))
    for b, gid, mdl, i, g in sorted(gens, key=lambda r: (r[0], r[1])):
        mbase, zr, zx = mbase_of.get(g, (float(mdl.Sn.v[i]), float(mdl.ra.v[i]), float(mdl.xs.v[i])))
        out.append(f"{b}, '{gid}', {_g(mdl.p.v[i] * sb)}, {_g(mdl.q.v[i] * sb)}, "
                   f"{_g(mdl.qmax.v[i] * sb)}, {_g(mdl.qmin.v[i] * sb)}, {_g(mdl.v0.v[i])}, 0, "
                   f"{_g(mbase)}, {_g(zr)}, {_g(zx)}, 0, 0, 1, {int(mdl.u.v[i])}, 100, "
                   f"{_g(mdl.pmax.v[i] * sb)}, {_g(mdl.pmin.v[i] * sb)}, 1, 1, 0, 1, 0, 1, 0, 1, 0, 1")
    out.append("0 / End of Generator data, Begin Branch data")
    is_tf = _branch_kind(ss)
    ckt = {}

    def circuit(b1, b2):
        key = (min(b1, b2), max(b1, b2))
        ckt[key] = ckt.get(key, 0) + 1
        return ckt[key]

    L = ss.Line
    for i in range(L.n):
        if is_tf[i]:
            continue
        if L.g.v[i] != 0:
            raise ValueError("line series-shunt conductance g is not representable; none expected")
        c = circuit(L.bus1.v[i], L.bus2.v[i])
        out.append(f"{L.bus1.v[i]}, {L.bus2.v[i]}, '{c}', {_g(L.r.v[i])}, {_g(L.x.v[i])}, {_g(L.b.v[i])}, "
                   f"0, 0, 0, {_g(L.g1.v[i])}, {_g(L.b1.v[i])}, {_g(L.g2.v[i])}, {_g(L.b2.v[i])}, "
                   f"{int(L.u.v[i])}, 1, 0, 1, 1, 0, 1, 0, 1, 0, 1")
    out.append("0 / End of Branch data, Begin Transformer data")
    for i in range(L.n):
        if not is_tf[i]:
            continue
        if any(getattr(L, n).v[i] != 0 for n in ("b", "g", "b1", "g1", "b2", "g2")):
            raise ValueError("transformer with shunt admittance; not expected in these cases")
        c = circuit(L.bus1.v[i], L.bus2.v[i])
        out.append(f"{L.bus1.v[i]}, {L.bus2.v[i]}, 0, '{c}', 1, 1, 1, 0, 0, 2, '            ', "
                   f"{int(L.u.v[i])}, 1, 1, 0, 1, 0, 1, 0, 1, '            '")
        out.append(f"{_g(L.r.v[i])}, {_g(L.x.v[i])}, {_g(sb)}")
        out.append(f"{_g(L.tap.v[i])}, 0, {_g(np.degrees(L.phi.v[i]))}, 0, 0, 0, 0, 0, 1.1, 0.9, 1.1, 0.9, "
                   f"33, 0, 0, 0, 0")
        out.append("1, 0")
    for name in ("Area interchange", "Two-terminal dc line", "VSC dc line", "Impedance correction table",
                 "Multi-terminal dc line", "Multi-section line", "Zone", "Inter-area transfer", "Owner",
                 "FACTS device", "Switched shunt", "GNE device", "Induction machine"):
        out.append(f"0 / End of {name} data")
    out.append("Q")
    path.write_text("\n".join(out) + "\n")


def dyn_params(mdl, i, names):
    vals = {}
    for n in names:
        if n == "H":
            vals[n] = float(mdl.M.vin[i]) / 2
        elif not hasattr(mdl, n):  # PSS/E CON that ANDES does not model (IEEEX1 Switch): unused, 0
            vals[n] = 0.0
        else:
            vals[n] = float(getattr(mdl, n).vin[i])
        if mdl.class_name == "IEEEG1" and n in ("UO", "UC"):
            # ANDES 2.0 applies the valve rate limits on the system base: the rate it simulates,
            # in pu of the turbine rating per second, is UO * Sb / Tn. Matched to its tm output
            # (rms 1e-7 pu over the wecc events); the files record the rates as simulated.
            vals[n] *= float(mdl.system.config.mva) / float(mdl.Sn.v[i])
        if mdl.class_name == "ESST4B" and n in ("KI", "XL"):
            # ANDES 2.0 applies KI and XL to the machine current on the system base: the
            # machine-base value it simulates is its value times MBASE/Sb (see _lib_convert)
            vals[n] *= float(mdl.Sn.v[i]) / float(mdl.system.config.mva)
        if mdl.class_name == "IEESGO" and n == "K1":
            # ANDES 2.0 applies K1 on the system base: machine base K1 = its value times Sb/MBASE
            vals[n] *= float(mdl.system.config.mva) / float(mdl.Sn.v[i])
    return vals


def _icons(ss, mdl, i, icon_names):
    out = []
    for n in icon_names:
        if n == "syn2_bus":
            s2 = mdl.syn2.v[i]
            out.append(0 if s2 in (None, "None") else int(ss.GENROU.bus.v[ss.GENROU.idx2uid(s2)]))
        elif n == "syn2_id":
            s2 = mdl.syn2.v[i]
            out.append(0 if s2 in (None, "None") else int(machine_id(ss, ss.GENROU.idx2uid(s2))))
        elif n.startswith("busr"):
            b = getattr(mdl, n).v[i]
            out.append(0 if b in (None, "None") else int(b))
        else:
            out.append(int(getattr(mdl, n).v[i]))
    return out


def controls_of(ss, syn_idx):
    """(governor, exciter, pss) as (model name, uid) or None for one synchronous machine."""
    gov = _group_links(ss, "TurbineGov", "syn").get(syn_idx)
    exc = _group_links(ss, "Exciter", "syn").get(syn_idx)
    pss = _group_links(ss, "PSS", "avr").get(exc[1]) if exc else None
    return [None if c is None else (c[0], ss.models[c[0]].idx2uid(c[1])) for c in (gov, exc, pss)]


def write_dyr(ss, path):
    """GENROU/GENCLS, governor, exciter and stabilizer records of every in-service machine."""
    lines = []
    machines = []
    for model in ("GENROU", "GENCLS"):
        mdl = ss.models.get(model)
        if mdl is None:
            continue
        for i in range(mdl.n):
            if mdl.u.v[i]:
                gid = gen_ids(ss)[mdl.gen.v[i]]
                machines.append((int(mdl.bus.v[i]), gid, model, i))
    for bus, gid, model, i in sorted(machines, key=lambda r: (r[0], r[1])):
        mdl = ss.models[model]
        recs = [(model, i)] + [c for c in controls_of(ss, mdl.idx.v[i]) if c is not None]
        for name, j in recs:
            icon_names, con_names = DYR[name]
            m = ss.models[name]
            if name in ("TGOV1", "IEEEG1") and float(m.Tn.vin[j]) not in (0.0, float(mdl.Sn.vin[i])):
                raise ValueError("governor rating differs from MBASE; not expected")
            vals = [str(v) for v in _icons(ss, m, j, icon_names)]
            cons = dyn_params(m, j, con_names)
            vals += [_g(cons[n]) for n in con_names]
            body = [" ".join(vals[k:k + 6]) for k in range(0, len(vals), 6)]
            lines.append(f"{bus} '{DYR_AS.get(m.idx.v[j], name)}' {gid} " + ("\n    ".join(body)) + " /")
    path.write_text("\n".join(lines) + "\n")


# ----------------------------------------------------------------------------------------------------
# truth, checks, verification
# ----------------------------------------------------------------------------------------------------

def machine_truth(ss, m):
    i = m["uid"]
    f0 = float(ss.GENROU.fn.v[i])
    h = float(ss.GENROU.M.vin[i]) / 2
    d = float(ss.GENROU.D.vin[i])
    gov, exc, pss = controls_of(ss, ss.GENROU.idx.v[i])
    out = {"tag": m["tag"], "andes_idx": ss.GENROU.idx.v[i], "bus": m["bus"], "id": m["id"],
           "bus_kv": float(ss.Bus.Vn.v[ss.Bus.idx2uid(m["bus"])]), "mbase_mva": m["mbase"],
           "H_s_mbase": h, "M_2H_s_mbase": 2 * h,
           "D_andes_pu_torque_per_pu_speed_mbase": d,
           "D_pu_torque_per_rad_s_electrical": d / (2 * np.pi * f0),
           "genrou_mbase": {n: float(getattr(ss.GENROU, n).vin[i]) for n in GENROU_PARAMS}}
    for key, c in (("governor", gov), ("exciter", exc), ("pss", pss)):
        if c is None:
            out[key] = None
            continue
        name, j = c
        mdl = ss.models[name]
        icon_names, con_names = DYR[name]
        psse = DYR_AS.get(mdl.idx.v[j], name)  # the PSS/E model written (DYR_AS), else ANDES's
        out[key] = {"model": psse, **({"andes_model": name} if psse != name else {}),
                    "andes_idx": mdl.idx.v[j], "meaning": MEANING.get(psse, ""),
                    "icons": dict(zip(icon_names, _icons(ss, mdl, j, icon_names))),
                    "params_mbase_psse_order": dyn_params(mdl, j, con_names),
                    "added_by_bench": str(mdl.idx.v[j]).startswith("added_")}
    return out


def read_csv_gz(path):
    with gzip.open(path, "rt") as fh:
        header = fh.readline().strip().split(",")
        arr = np.loadtxt(fh, delimiter=",")
    return header, arr


def check_consistency(path, fr, machines, keep):
    """Re(V I*) from the written file vs ANDES Pe; |I_file - I_dq| (the machine's own d-q current)."""
    header, arr = read_csv_gz(path)
    col = {h: k for k, h in enumerate(header)}
    worst_p, worst_i = 0.0, 0.0
    for j, m in enumerate(machines):
        if not keep[j]:
            continue
        t = m["tag"]
        v = arr[:, col[f"{t}/VM"]] * np.exp(1j * np.radians(arr[:, col[f"{t}/VA"]]))
        cur = arr[:, col[f"{t}/IM"]] * np.exp(1j * np.radians(arr[:, col[f"{t}/IA"]]))
        worst_p = max(worst_p, float(np.max(np.abs((v * np.conj(cur)).real - fr["Pe"][:, j]))))
        worst_i = max(worst_i, float(np.max(np.abs(fr["I"][:, j] - fr["I_dq"][:, j]))))
    return {"max_abs_ReVIconj_minus_andes_Pe_pu_sys": worst_p,
            "max_abs_I_from_PQ_minus_I_from_dq_pu_sys": worst_i}


def swing_fit(path, machines, keep, f0, exclude=(T_EVENT - 0.1, T_EVENT + 0.5)):
    """Least squares of d omega/dt (central difference) on (pm - pe), (omega - 1) and a constant."""
    header, arr = read_csv_gz(path)
    col = {h: k for k, h in enumerate(header)}
    t = arr[:, 0]
    dt = t[1] - t[0]
    out = {}
    for j, m in enumerate(machines):
        if not keep[j]:
            continue
        tag = m["tag"]
        w = arr[:, col[f"{tag}/omega_pu"]]
        acc = arr[:, col[f"{tag}/pm_pu_mbase"]] - arr[:, col[f"{tag}/pe_pu_mbase"]]
        dw = (w[2:] - w[:-2]) / (2 * dt)
        tt = t[1:-1]
        sel = (tt < exclude[0]) | (tt > exclude[1])
        a = np.column_stack([acc[1:-1], w[1:-1] - 1, np.ones_like(tt)])[sel]
        coef, *_ = np.linalg.lstsq(a, dw[sel], rcond=None)
        m_fit = 1 / coef[0]
        out[tag] = {"M_fit_s": m_fit, "M_true_s": 2 * m["H"], "rel_err": m_fit / (2 * m["H"]) - 1,
                    "D_fit_pu": -coef[1] * m_fit, "D_true_pu": m["D"]}
    return out


def stats(fr, machines, keep, f0):
    out = {}
    for j, m in enumerate(machines):
        if not keep[j]:
            continue
        dev = (fr["omega"][:, j] - 1) * f0 * 1e3
        fdev = (fr["F"][:, j] - f0) * 1e3
        out[m["tag"]] = {"speed_dev_std_mHz": float(np.std(dev)), "speed_dev_min_mHz": float(dev.min()),
                         "speed_dev_max_mHz": float(dev.max()), "bus_freq_dev_std_mHz": float(np.std(fdev)),
                         "bus_freq_dev_min_mHz": float(fdev.min()), "bus_freq_dev_max_mHz": float(fdev.max())}
    return out


def verify_psse(case, ss, machines, raw, dyr, line_ev):
    """Reload the written .raw/.dyr with ANDES: PF, dynamic data and a 15 s line-trip run must match."""
    new = andes.load(str(raw), addfile=str(dyr), setup=False, no_output=True, default_config=True)
    new.add("Toggle", {"model": "Line", "dev": _line_idx_by_buses(new, line_ev), "t": T_EVENT})
    new.setup()
    new.PFlow.run()
    d_v = float(np.max(np.abs(np.asarray(new.Bus.v.v) - np.asarray(ss.Bus.v.v))))
    d_a = float(np.max(np.abs(np.asarray(new.Bus.a.v) - np.asarray(ss.Bus.a.v))))
    worst_par = 0.0
    for model in ("GENROU", "GENCLS", "TGOV1", "IEEEG1", "IEEEX1", "ESDC2A", "EXDC2", "EXST1", "ESST3A",
                  "SEXS", "IEEEST", "ST2CUT"):
        a, b = ss.models.get(model), new.models.get(model)
        if a is None or a.n == 0:
            continue
        if b.n != a.n:
            raise AssertionError(f"{model}: {a.n} devices simulated, {b.n} read back")
        syn = "syn" if hasattr(a, "syn") else "avr" if hasattr(a, "avr") else None
        key_a = _device_keys(ss, a, syn)
        key_b = _device_keys(new, b, syn)
        order = [key_b.index(k) for k in key_a]
        for n, p in a.params.items():
            if type(p).__name__ != "NumParam" or n in ("u", "Tn", "coi", "coi2"):
                continue
            va = np.asarray(p.vin, dtype=float)
            vb = np.asarray(b.params[n].vin, dtype=float)[order]
            worst_par = max(worst_par, float(np.max(np.abs(va - vb) / np.maximum(1, np.abs(va)))))
    # short line trip on both
    t_end = 15.0
    ref = load_case(case, event_models("line_trip", {"line_trip": line_ev}))
    mach_ref = [dict(m, uid=ref.GENROU.idx2uid(m["andes_idx"])) for m in machines]
    s_ref = simulate(ref, mach_ref, t_end)
    mach_new = []
    for m in machines:
        k = next(i for i in range(new.GENROU.n) if int(new.GENROU.bus.v[i]) == m["bus"]
                 and machine_id(new, i) == m["id"])
        mach_new.append(dict(m, uid=k))
    s_new = simulate(new, mach_new, t_end)
    d_w = float(np.max(np.abs(s_ref["omega"] - s_new["omega"])))
    d_p = float(np.max(np.abs(s_ref["Pe"] - s_new["Pe"])))
    return {"pf_max_abs_dV_pu": d_v, "pf_max_abs_dangle_rad": d_a, "dyn_param_max_rel_diff": worst_par,
            "line_trip_15s_max_abs_domega_pu": d_w, "line_trip_15s_max_abs_dPe_pu_sys": d_p}


def _line_idx_by_buses(ss, ev):
    for i in range(ss.Line.n):
        if {int(ss.Line.bus1.v[i]), int(ss.Line.bus2.v[i])} == {ev["from_bus"], ev["to_bus"]}:
            return ss.Line.idx.v[i]
    raise KeyError(ev)


def _device_keys(ss, mdl, link):
    """(bus, machine id) of the machine behind each device, to pair devices across two loads."""
    keys = []
    for i in range(mdl.n):
        if link is None:
            keys.append((int(mdl.bus.v[i]), machine_id_any(ss, mdl.gen.v[i])))
            continue
        dev = getattr(mdl, link).v[i]
        if link == "avr":
            grp = ss.models[_model_of(ss, "Exciter", dev)]
            dev = grp.syn.v[grp.idx2uid(dev)]
        syn_model = ss.models[_model_of(ss, "SynGen", dev)]
        k = syn_model.idx2uid(dev)
        keys.append((int(syn_model.bus.v[k]), machine_id_any(ss, syn_model.gen.v[k])))
    return keys


def _model_of(ss, group, idx):
    for name, mdl in ss.groups[group].models.items():
        if idx in mdl.idx.v:
            return name
    raise KeyError(idx)


def machine_id_any(ss, gen_idx):
    return gen_ids(ss)[gen_idx]


# ----------------------------------------------------------------------------------------------------
# derived cases: the shipped npcc case changed (CASES[case]["dyr"] or ["modify"])
# ----------------------------------------------------------------------------------------------------

EXDC2_VR_LIMIT = 50.0  # npcc_exdc2: VRMAX = -VRMIN, never reached in these events (see npcc_exdc2)


def _derived_dyr(case, path):
    """The shipped .dyr rewritten by CASES[case]["dyr"], in a temporary file (the same text every run)."""
    import tempfile
    out = Path(tempfile.mkdtemp(prefix=f"andes_bench_{case}_")) / Path(path).name
    out.write_text(CASES[case]["dyr"](Path(path).read_text()))
    return str(out)


def _derived_entry(case):
    """truth.json's "derived_case": the function that derives the case and its docstring."""
    fs = [CASES[case][k] for k in ("dyr", "modify") if k in CASES[case]]
    if not fs:
        return {}
    constants = {n: globals()[n] for n in ("EXDC2_VR_LIMIT", "XD2_OVER_XL", "VSG_REGCV1")
                 if any(n in f.__doc__ for f in fs)}
    return {"derived_case": {"function": " + ".join(f.__name__ for f in fs),
                             "description": " ".join(" ".join(f.__doc__.split()) for f in fs),
                             "constants": constants}}


def npcc_exdc2(text):
    """npcc with every IEEEX1 exciter record swapped to EXDC2 (the exciters the bench adds stay SEXS).

    Parameter choices, so that ANDES 2.0's EXDC2 and the PSS/E EXDC2 (1981 IEEE DC2) are the same
    system: TR, KA, TA, TB, TC, TE, KF, TF1 and the saturation points E1, SE(E1), E2, SE(E2) are the
    IEEEX1 record's; KE as in the record where nonzero, else 1.0 (ANDES reads KE = 0 literally, PSS/E
    computes it at initialisation; npcc has no KE = 0); VRMAX = -VRMIN = EXDC2_VR_LIMIT, wide enough
    that no regulator limit is reached (PSS/E scales the EXDC2 limits by the terminal voltage, ANDES
    2.0 does not). One difference no parameter removes: ANDES 2.0's EXDC2 outputs EFD = omega times
    the exciter voltage, a speed factor that neither the PSS/E EXDC2 nor IEEE DC2 has (ANDES's own
    IEEEX1 is the same model without it, and with the limits scaled by the terminal voltage). At
    the speed deviations of these events (up to 2.6e-3 pu, load step) EFD differs by up to 0.26 %;
    it is left in, and records_as_given.py shows what it costs in Q. The records are rewritten in
    the .dyr text (ANDES cannot take a device out of a case before set-up)."""
    out = []
    for rec in text.split("/"):
        tok = rec.split()
        if len(tok) >= 3 and tok[1].strip("'\"").upper() == "IEEEX1":
            bus, mid = tok[0], tok[2]
            c = dict(zip(("TR", "KA", "TA", "TB", "TC", "VRMAX", "VRMIN", "KE", "TE", "KF1", "TF1",
                          "Switch", "E1", "SE1", "E2", "SE2"), (float(v) for v in tok[3:19])))
            c["KE"] = c["KE"] if c["KE"] != 0 else 1.0
            c["VRMAX"], c["VRMIN"] = EXDC2_VR_LIMIT, -EXDC2_VR_LIMIT
            vals = [_g(v) for v in c.values()]
            rec = (f"\n{bus} 'EXDC2' {mid} " + " ".join(vals[:6]) + "\n    " + " ".join(vals[6:12])
                   + "\n    " + " ".join(vals[12:]) + " ")
        out.append(rec)
    return "/".join(out)


XD2_OVER_XL = 0.5  # npcc_xd2_below_xl: X''d = X''q = XD2_OVER_XL * Xl on every GENROU


def npcc_xd2_below_xl(ss):
    """npcc with X''d (= X''q) below Xl on every GENROU: X''d = XD2_OVER_XL * Xl, all else as shipped.

    Such records are common in shipped cases (ANDES's IEEE 39-bus case has 9 of its 10 GENROU so);
    PSS/E warns about them and simulates them, and so does ANDES (its GENROU equations need only
    X'd != Xl and X'q != Xl). The .raw ZSORCE X follows (it is X''d)."""
    g = ss.GENROU
    for i in range(g.n):
        g.xd2.v[i] = XD2_OVER_XL * g.xl.v[i]
        g.xq2.v[i] = XD2_OVER_XL * g.xl.v[i]


CASES["npcc_exdc2"] = dict(CASES["npcc"], dyr=npcc_exdc2)
CASES["npcc_xd2_below_xl"] = dict(CASES["npcc"], modify=npcc_xd2_below_xl)


# ----------------------------------------------------------------------------------------------------
# derived cases with inverter-based plants beside the machines (issue 44, "machines beside inverters")
# ----------------------------------------------------------------------------------------------------
# ieee14's synchronous unit at bus 8 (GENROU + TGOV1 + ESST3A, P = 0.35 pu) replaced by an
# inverter-based plant on the same static generator, so that the power flow is unchanged; the four
# other GENROU machines (buses 1, 2, 3, 6) are recorded. Only the machines are scored
# (``beside_ibr.py``): the plants' models need not follow the WECC specification here, and are
# ANDES's own cases' as shipped:
# * ieee14_solar: ANDES's ``ieee14_solar.xlsx`` (REGCA1 + REECA1 + REPCA1 at bus 8);
# * ieee14_wt3: ANDES's ``ieee14_wt3.xlsx`` (a type-3 wind plant: REGCA1 + REECA1 + REPCA1 +
#   WTDTA1 + WTARA1 + WTPTA1 + WTTQA1 at bus 8);
# * ieee14_vsg: this bench's ieee14 .raw/.dyr without the bus-8 records, and a virtual synchronous
#   generator (REGCV1, the constants of experiments/andes_gfm/generate.py: M = 8 s, D = 2) there.
# Run with --scenario line_trip load_step gen_trip --no-verify.

VSG_REGCV1 = dict(Sn=100.0, fn=60.0, Tc=0.01, kw=0.0, kv=0.0, M=8.0, D=2.0, ra=0.0, xs=0.2,
                  Kpvd=0.5, Kivd=0.02, Kpvq=0.5, Kivq=0.02, KpId=0.2, KiId=0.01, KpIq=0.2, KiIq=0.01)
"""REGCV1 at bus 8 of ieee14_vsg (ANDES's names and units; H = M/2 = 4 s on Sn)."""


def ieee14_without_bus8(text):
    """ieee14 (this bench's .dyr) without the records of bus 8 (GENROU, TGOV1, ESST3A): the static
    generator there is taken by the REGCV1 that ``ieee14_add_vsg`` adds."""
    records = [r for r in text.split("/") if r.strip()]
    return "/".join(r for r in records if int(r.split()[0]) != 8) + "/\n"


def ieee14_add_vsg(ss):
    """A REGCV1 (VSG_REGCV1) on the static generator of bus 8."""
    gen = [g for g, b in zip(ss.PV.idx.v, ss.PV.bus.v) if int(b) == 8][0]
    ss.add("REGCV1", dict(idx="VSG_8", bus=8, gen=gen, **VSG_REGCV1))


_IEEE14_BENCH = (str(DATA / "ieee14" / "ieee14.raw"), str(DATA / "ieee14" / "ieee14.dyr"))
CASES["ieee14_solar"] = dict(CASES["ieee14"], files=("ieee14/ieee14_solar.xlsx",))
CASES["ieee14_wt3"] = dict(CASES["ieee14"], files=("ieee14/ieee14_wt3.xlsx",))
CASES["ieee14_vsg"] = dict(CASES["ieee14"], files=_IEEE14_BENCH, dyr=ieee14_without_bus8,
                           modify=ieee14_add_vsg)


# ----------------------------------------------------------------------------------------------------
# derived cases with the PSS/E library models that ANDES 2.0 also has (issue 33): ieee14_lib,
# npcc_lib, wecc_lib -- the recorded units' exciters swapped, and every second one's governor
# ----------------------------------------------------------------------------------------------------
#
# Each recorded unit gets one of ESST4B, IEEET1, ESAC1A, EXAC1, EXAC2, ESST1A, ESDC1A (the case
# function lists which), and every second recorded unit (1st, 3rd, ...) an IEESGO governor; the
# other units keep the shipped data. The shipped .dyr records of a swapped unit's exciter and
# governor are replaced in the .dyr text (ANDES 2.0 cannot take a device out before set-up, and
# an out-of-service exciter or governor breaks its initialisation), written in the order that
# ANDES's reader takes (its psse-dyr.yaml: ESAC1A and ESST1A differ from the PSS/E library);
# stabilisers follow the unit's exciter. The .dyr that jaxdse reads is written from the ANDES
# data in PSS/E CON order (DYR below). Simulated for the line trip and the load step
# (--scenario line_trip load_step --no-verify: ANDES's reader cannot read the PSS/E order of
# ESAC1A and ESST1A back).
#
# Typical data (IEEE Std 421.5 sample data, the ACTIVSg2000 records and the PSS/E sample records),
# with these choices so that ANDES 2.0 and the PSS/E library are the same system:
# * ESST4B: ANDES applies KI and XL to the machine current on the system base: it gets
#   KI, XL times Sb/MBASE (the .dyr gets the machine-base values, dyn_params converts back).
#   KI = 0.1, XL = 0.05 (a compound source) so that the conversion matters. TA > 0 (ANDES's lag),
#   limits wide enough not to be reached in the line trip and load step (ANDES's PI blocks track
#   their limit, PSS/E's do not wind up: the bolted fault reaches them, esst4b_pi.py shows the
#   difference); KG = 0 (ANDES's VG limit VGMAX is not in the PSS/E model).
# * IEEET1: KE = 1 (nonzero: ANDES reads KE = 0 literally, PSS/E computes it); VRMAX nonzero
#   (ANDES turns VRMAX = 0 into 999).
# * ESAC1A: KF = 0 (ANDES computes the rate feedback but does not feed it back), transient gain
#   reduction by TC/TB instead; VRMAX = VAMAX, VRMIN = VAMIN (ANDES leaves the VR limits out;
#   with the VA limits inside them they cannot act).
# * EXAC1: TR = 0 (ANDES skips the sensor lag).
# * EXAC2: TR = 0; KL = KH (ANDES initialises VA with KL where KH belongs); VLR above the
#   initial VFE (1 + 1/(KB KL)) (ANDES then keeps VLR, and the LV gate starts on VA - KH VFE).
# * ESST1A: TA > 0 (ANDES's anti-windup lag); ILR above the initial field current.
# * ESDC1A: ANDES 2.0's ESDC1A cannot be used: it replaces ESDC2A's VR limits (VT VRMAX,
#   VT VRMIN) by constants but its regulator keeps the removed ones (value 0), so VR is held at
#   0 (set-up fails where VR0 > 0). The unit is simulated with ANDES's ESDC2A, which is the
#   PSS/E ESDC1A block diagram with the VR limits scaled by VT: VRMAX, VRMIN wide enough not to
#   be reached, TR = 0 (ANDES's ESDC2A skips the sensor lag), KE = 1; its .dyr record and
#   truth.json say ESDC1A (DYR_AS), and truth.json names the ANDES model.
# * IEESGO: ANDES applies K1 on the system base: it gets K1 times MBASE/Sb (the .dyr gets K1).
#   T1 > 0 (ANDES's lag), PMAX = 1 pu MBASE.
# * wecc's units run at 2.8-4.8 pu field voltage (ANDES's data), about twice the others:
#   there the saturation points E1, E2, the regulator ceilings and ILR, VLR are doubled
#   (LIB_SCALED; LIB_WECC_SCALE).

DYR_AS: dict = {}
"""ANDES device idx -> the PSS/E model that its .dyr record and truth.json name (a derived case
that simulates a PSS/E model with an equivalent ANDES one: ESDC1A by ANDES's ESDC2A)."""

DYR.update({
    "ESST4B": ((), ("TR", "KPR", "KIR", "VRMAX", "VRMIN", "TA", "KPM", "KIM", "VMMAX", "VMMIN", "KG",
                    "KP", "KI", "VBMAX", "KC", "XL", "THETAP")),
    "IEEET1": ((), ("TR", "KA", "TA", "VRMAX", "VRMIN", "KE", "TE", "KF", "TF", "Switch", "E1", "SE1",
                    "E2", "SE2")),
    "ESAC1A": ((), ("TR", "TB", "TC", "KA", "TA", "VAMAX", "VAMIN", "TE", "KF", "TF", "KC", "KD", "KE",
                    "E1", "SE1", "E2", "SE2", "VRMAX", "VRMIN")),
    "EXAC1": ((), ("TR", "TB", "TC", "KA", "TA", "VRMAX", "VRMIN", "TE", "KF", "TF", "KC", "KD", "KE",
                   "E1", "SE1", "E2", "SE2")),
    "EXAC2": ((), ("TR", "TB", "TC", "KA", "TA", "VAMAX", "VAMIN", "KB", "VRMAX", "VRMIN", "TE", "KL",
                   "KH", "KF", "TF", "KC", "KD", "KE", "VLR", "E1", "SE1", "E2", "SE2")),
    "ESST1A": (("UELc", "VOSc"), ("TR", "VIMAX", "VIMIN", "TC", "TB", "TC1", "TB1", "KA", "TA", "VAMAX",
                                  "VAMIN", "VRMAX", "VRMIN", "KC", "KF", "TF", "KLR", "ILR")),
    "IEESGO": ((), ("T1", "T2", "T3", "T4", "T5", "T6", "K1", "K2", "K3", "PMAX", "PMIN")),
})  # PSS/E CON order (Siemens PTI PSS/E Model Library), as ANDES parameter names (ESDC1A: ESDC2A's)
MEANING.update({
    "ESST4B": "PSS/E ESST4B (IEEE ST4B); KI, XL on the machine base (ANDES got them times Sb/MBASE)",
    "IEEET1": "PSS/E IEEET1 (1968 IEEE type 1)",
    "ESAC1A": "PSS/E ESAC1A (IEEE AC1A), KF = 0, VR limits = VA limits",
    "EXAC1": "PSS/E EXAC1 (1981 IEEE AC1), TR = 0",
    "EXAC2": "PSS/E EXAC2 (1981 IEEE AC2), TR = 0, KL = KH",
    "ESST1A": "PSS/E ESST1A (IEEE ST1A) (ICONs: UEL, VOS)",
    "ESDC1A": "PSS/E ESDC1A (IEEE DC1A), simulated by ANDES's ESDC2A with VR limits never reached",
    "IEESGO": "PSS/E IEESGO (IEEE 1973 steam); K1 on the machine base (ANDES got K1 times MBASE/Sb)",
})

LIB_PARAMS = {  # machine base, PSS/E meaning; ANDES parameter names
    "ESST4B": {"TR": 0.02, "KPR": 3.15, "KIR": 3.15, "VRMAX": 1.0, "VRMIN": -0.87, "TA": 0.02,
               "KPM": 1.0, "KIM": 0.0, "VMMAX": 1.0, "VMMIN": -0.87, "KG": 0.0, "KP": 6.89, "KI": 0.1,
               "VBMAX": 11.63, "KC": 0.08, "XL": 0.05, "THETAP": 0.0},
    "IEEET1": {"TR": 0.02, "KA": 50.0, "TA": 0.06, "VRMAX": 5.0, "VRMIN": -5.0, "KE": 1.0, "TE": 0.5,
               "KF": 0.06, "TF": 1.0, "Switch": 0.0, "E1": 2.8, "SE1": 0.04, "E2": 3.73, "SE2": 0.33},
    "ESAC1A": {"TR": 0.02, "TB": 10.0, "TC": 1.0, "KA": 400.0, "TA": 0.02, "VAMAX": 14.5,
               "VAMIN": -14.5, "TE": 0.8, "KF": 0.0, "TF": 1.0, "KC": 0.2, "KD": 0.38, "KE": 1.0,
               "E1": 4.18, "SE1": 0.1, "E2": 3.14, "SE2": 0.03, "VRMAX": 14.5, "VRMIN": -14.5},
    "EXAC1": {"TR": 0.0, "TB": 0.0, "TC": 0.0, "KA": 400.0, "TA": 0.05, "VRMAX": 7.3, "VRMIN": -7.3,
              "TE": 1.1, "KF": 0.035, "TF": 1.0, "KC": 0.247, "KD": 0.5, "KE": 1.0, "E1": 2.71,
              "SE1": 0.0366, "E2": 3.61, "SE2": 0.183},
    "EXAC2": {"TR": 0.0, "TB": 0.0, "TC": 0.0, "KA": 400.0, "TA": 0.02, "VAMAX": 8.0, "VAMIN": -8.0,
              "KB": 25.0, "VRMAX": 105.0, "VRMIN": -95.0, "TE": 0.6, "KL": 1.0, "KH": 1.0, "KF": 0.03,
              "TF": 1.0, "KC": 0.28, "KD": 0.35, "KE": 1.0, "VLR": 4.4, "E1": 4.4, "SE1": 0.037,
              "E2": 3.3, "SE2": 0.012},
    "ESST1A": {"UELc": 1, "VOSc": 1, "TR": 0.02, "VIMAX": 999.0, "VIMIN": -999.0, "TC": 1.0,
               "TB": 10.0, "TC1": 0.0, "TB1": 0.0, "KA": 210.0, "TA": 0.02, "VAMAX": 999.0,
               "VAMIN": -999.0, "VRMAX": 6.43, "VRMIN": -6.0, "KC": 0.038, "KF": 0.0, "TF": 1.0,
               "KLR": 4.54, "ILR": 4.4},
    "ESDC1A": {"TR": 0.0, "KA": 40.0, "TA": 0.05, "TB": 0.0, "TC": 0.0, "VRMAX": 10.0, "VRMIN": -10.0,
               "KE": 1.0, "TE": 0.9, "KF": 0.0378, "TF1": 1.0, "Switch": 0.0, "E1": 2.36, "SE1": 0.127,
               "E2": 3.15, "SE2": 0.381},
    "IEESGO": {"T1": 0.1, "T2": 0.0, "T3": 0.2, "T4": 0.3, "T5": 7.0, "T6": 0.6, "K1": 20.0, "K2": 0.7,
               "K3": 0.43, "PMAX": 1.0, "PMIN": 0.0},
}
LIB_SCALED = {"ESST4B": (), "IEEET1": ("VRMAX", "VRMIN", "E1", "E2"), "ESAC1A": ("E1", "E2"),
              "EXAC1": ("VRMAX", "VRMIN", "E1", "E2"),
              "EXAC2": ("VAMAX", "VAMIN", "VLR", "E1", "E2"), "ESST1A": ("ILR",),
              "ESDC1A": ("VRMAX", "VRMIN", "E1", "E2"), "IEESGO": ()}
LIB_WECC_SCALE = 2.0  # wecc_lib: LIB_SCALED parameters times this (field voltages twice the others')
LIB_ANDES_MODEL = {"ESDC1A": "ESDC2A"}  # simulated by this ANDES model (see ESDC1A above)


def _lib_dyr_order(model):
    """The CON names in the order ANDES 2.0's .dyr reader takes them (its psse-dyr.yaml), as ANDES
    parameter names."""
    import yaml
    spec = yaml.safe_load((Path(andes.__file__).parent / "io" / "psse-dyr.yaml").read_text())[model]
    name_of = {v: k for k, v in spec["outputs"].items()}
    return [name_of[n] for n in spec["inputs"][2:]]  # after BUS, ID


def _lib_rewrite(text, plan, scale, drop):
    """The shipped .dyr with the exciter (and governor) records of the units in ``plan`` ((bus,
    exciter, governor or None), ...) replaced, each written in ANDES's reader order, and the
    records of the models in ``drop`` left out."""
    import yaml
    spec = yaml.safe_load((Path(andes.__file__).parent / "io" / "psse-dyr.yaml").read_text())
    groups = dict(andes.models.file_classes)
    kind = {name: k for k in ("exciter", "governor") for name, s in spec.items()
            if s["destination"] in groups[k]}
    new = {}
    for bus, exc, gov in plan:
        new[(str(bus), "exciter")] = exc
        if gov is not None:
            new[(str(bus), "governor")] = gov
    out, done = [], set()
    for rec in text.split("/"):
        tok = rec.split()
        if len(tok) >= 3 and tok[1].strip("'\"").upper() in drop:
            continue
        key = (tok[0], kind.get(tok[1].strip("'\"").upper())) if len(tok) >= 3 else None
        if key in new and tok[2].strip("'\"") == "1":
            model = new[key]
            p = dict(LIB_PARAMS[model])
            for n in LIB_SCALED[model]:
                p[n] *= scale
            andes_model = LIB_ANDES_MODEL.get(model, model)
            vals = [_g(p[n]) for n in _lib_dyr_order(andes_model)]
            rec = f"\n{tok[0]} '{andes_model}' 1 " + "\n    ".join(
                " ".join(vals[k:k + 6]) for k in range(0, len(vals), 6)) + " "
            done.add(key)
        out.append(rec)
    if done != set(new):
        raise ValueError(f"records not found: {sorted(set(new) - done)}")
    return "/".join(out)


def _lib_convert(ss, plan):
    """Before set-up: ESST4B's KI, XL times Sb/MBASE and IEESGO's K1 times MBASE/Sb (ANDES applies
    them on the system base); DYR_AS for the units that ANDES simulates with another model; and a
    check that every unit of ``plan`` carries the planned models."""
    sb = float(ss.config.mva)
    exc_of = _group_links(ss, "Exciter", "syn")
    gov_of = _group_links(ss, "TurbineGov", "syn")
    for bus, exc, gov in plan:
        (gi,) = [i for i in range(ss.GENROU.n) if ss.GENROU.u.v[i] and int(ss.GENROU.bus.v[i]) == bus]
        syn, sn = ss.GENROU.idx.v[gi], float(ss.GENROU.Sn.v[gi])
        for model, (name, idx) in ((exc, exc_of[syn]), (gov, gov_of[syn])):
            if model is None:
                continue
            if name != LIB_ANDES_MODEL.get(model, model):
                raise ValueError(f"bus {bus}: {name} where {model} was planned")
            mdl, k = ss.models[name], ss.models[name].idx.v.index(idx)
            if name == "ESST4B":
                mdl.KI.v[k] *= sb / sn
                mdl.XL.v[k] *= sb / sn
            if name == "IEESGO":
                mdl.K1.v[k] *= sn / sb
            if model != name:
                DYR_AS[idx] = model


def _lib_case(plan_of):
    """CASES hooks of a derived case whose plan is ``plan_of()`` -> (plan, scale, drop): the .dyr
    text rewritten (_lib_rewrite), then the ANDES inputs converted (_lib_convert)."""
    def dyr(text):
        return _lib_rewrite(text, *plan_of())

    def modify(ss):
        _lib_convert(ss, plan_of()[0])

    for f in (dyr, modify):
        f.__name__, f.__doc__ = plan_of.__name__, plan_of.__doc__
    return {"dyr": dyr, "modify": modify}


def ieee14_lib():
    """ieee14 from ANDES's PSS/E files of it (ieee14/ieee14.raw, ieee14/ieee14.dyr; its governors
    there are TGOV1 and IEEEG1) without their stabilisers (ANDES's IEEEST at bus 3 does not start
    flat: its filter state moves by 500 in the first 2 s) and without the two Toggle records (a
    trip and reclosure of Line_1 at 1.0 and 1.1 s), with the PSS/E library models of issue
    33 that ANDES 2.0 has (all units 100 MVA = the system base): exciters B1 ESST4B, B2 IEEET1,
    B3 ESAC1A, B6 EXAC1, B8 EXAC2; IEESGO governors on B1, B3, B8.
    Parameters and the choices that make ANDES 2.0 and the PSS/E library agree: LIB_PARAMS and
    the notes above it in generate.py."""
    return ((1, "ESST4B", "IEESGO"), (2, "IEEET1", None), (3, "ESAC1A", "IEESGO"),
            (6, "EXAC1", None), (8, "EXAC2", "IEESGO")), 1.0, ("IEEEST", "ST2CUT", "TOGGLE")


def npcc_lib():
    """npcc with the PSS/E library models of issue 33 that ANDES 2.0 has, on the 10 recorded units:
    exciters B55 ESST1A, B79 ESDC1A, B26 ESST4B, B24 IEEET1, B80 ESAC1A, B21 EXAC1, B22 EXAC2,
    B50 ESST1A, B25 ESDC1A, B36 ESST4B; IEESGO governors on B55, B26, B80, B22, B25 (MBASE
    650-1200 MVA: ESST4B's KI, XL and IEESGO's K1 converted for ANDES). Parameters and choices:
    LIB_PARAMS and the notes above it in generate.py."""
    return ((55, "ESST1A", "IEESGO"), (79, "ESDC1A", None), (26, "ESST4B", "IEESGO"),
            (24, "IEEET1", None), (80, "ESAC1A", "IEESGO"), (21, "EXAC1", None),
            (22, "EXAC2", "IEESGO"), (50, "ESST1A", None), (25, "ESDC1A", "IEESGO"),
            (36, "ESST4B", None)), 1.0, ()


def wecc_lib():
    """wecc with the PSS/E library models of issue 33 that ANDES 2.0 has, on the 10 recorded units
    (their stabilisers kept: ANDES links them to the unit's exciter): exciters B78 IEEET1,
    B76 ESAC1A, B34 EXAC1, B29 EXAC2, B117 ESST1A, B139 ESDC1A, B64 ESST4B, B14 IEEET1,
    B148 ESAC1A, B8 EXAC1; IEESGO governors on B78, B34, B117, B64, B148 (replacing IEEEG1).
    Field voltages of 2.8-4.8 pu: saturation points, ceilings, ILR and VLR times LIB_WECC_SCALE.
    Parameters and choices: LIB_PARAMS and the notes above it in generate.py."""
    return ((78, "IEEET1", "IEESGO"), (76, "ESAC1A", None), (34, "EXAC1", "IEESGO"),
            (29, "EXAC2", None), (117, "ESST1A", "IEESGO"), (139, "ESDC1A", None),
            (64, "ESST4B", "IEESGO"), (14, "IEEET1", None), (148, "ESAC1A", "IEESGO"),
            (8, "EXAC1", None)), LIB_WECC_SCALE, ()


CASES["ieee14_lib"] = dict(CASES["ieee14"], files=("ieee14/ieee14.raw", "ieee14/ieee14.dyr"),
                          **_lib_case(ieee14_lib))
CASES["npcc_lib"] = dict(CASES["npcc"], **_lib_case(npcc_lib))
CASES["wecc_lib"] = dict(CASES["wecc"], **_lib_case(wecc_lib))


# ----------------------------------------------------------------------------------------------------
# driver
# ----------------------------------------------------------------------------------------------------

def save_truth(path, top, scenario_entries):
    """Merge into truth.json (several runs of one case, e.g. events and ambient, may write it)."""
    cur = json.loads(path.read_text()) if path.exists() else {}
    for key, val in top.items():  # psse_files: a run without the round trip keeps the last one
        cur[key] = {**cur[key], **val} if key == "psse_files" and key in cur else val
    cur.setdefault("scenarios", {}).update(scenario_entries)
    cur["scenarios"] = {k: cur["scenarios"][k] for k in SCENARIOS if k in cur["scenarios"]}
    path.write_text(json.dumps(cur, indent=1, default=float) + "\n")


def run_case(case, scenarios, verify, step_check):
    t_start = time.time()
    out_dir = DATA / case
    out_dir.mkdir(parents=True, exist_ok=True)
    base = load_case(case)
    sb, f0 = float(base.config.mva), float(base.config.freq)
    machines = []
    for i in select_machines(base, case):
        bus, gid = int(base.GENROU.bus.v[i]), machine_id(base, i)
        machines.append({"uid": i, "andes_idx": base.GENROU.idx.v[i], "bus": bus, "id": gid,
                         "tag": f"B{bus}_G{gid}", "mbase": float(base.GENROU.Sn.vin[i]),
                         "H": float(base.GENROU.M.vin[i]) / 2, "D": float(base.GENROU.D.vin[i])})
    events = choose_events(base, case, machines)
    log.info("%s: recording %s", case, [m["tag"] for m in machines])
    truth_path = out_dir / "truth.json"
    truth = {}
    truth.update({
        "generator": "experiments/andes_bench/generate.py",
        "andes_version": andes.__version__,
        "case": case, "andes_case_files": list(CASES[case]["files"]),
        **_derived_entry(case),
        "system_base_mva": sb, "f0_hz": f0,
        "integration": {"method": "ANDES implicit trapezoid, fixed step", "step_s_events": 1 / STEP_RATE,
                        "step_s_ambient": 1 / AMBIENT_STEP_RATE, "newton_tol": TDS_TOL},
        "load_model_in_dynamics": "ANDES default: every PQ load becomes a constant impedance at t=0 "
                                  "(p2z = q2z = 1); the .raw holds them as constant-power PL/QL",
        "added_to_case": [{"machine": g, "model": mname,
                           "params": (ADDED_EXCITER if mname == ADDED_EXCITER[0] else ADDED_GOVERNOR)[1]}
                          for g, mname in base.bench_added],
        "selection_rule": "all in-service GENROU" if CASES[case]["n_record"] is None else
        f"the {CASES[case]['n_record']} largest MBASE among in-service GENROU that the shipped case "
        "equips with a governor and an exciter (ties: lower bus number)",
        "conventions": {
            "F": "bus frequency [Hz] = f0 + (d theta/dt)/(2 pi), theta = ANDES bus angle in the frame "
                 "rotating at f0, central difference over +-1 integration step around the frame "
                 "(forward difference at t=0)",
            "VM": "terminal bus voltage magnitude [pu of bus base kV]",
            "VA": "terminal bus voltage angle [deg] wrapped to (-180, 180], same frame as F",
            "IM_IA": "machine output current I = conj((Pe + jQe)/V) [pu on the system base at the bus "
                     "base kV; deg wrapped]; direction out of the machine into the network",
            "delta_rad": "ANDES rotor angle: q axis angle in the same frame as VA (unwrapped), "
                         "V e^{j theta} = (vd + j vq) e^{j(delta - pi/2)}",
            "omega_pu": "rotor speed [pu of f0]",
            "pm_pu_mbase": "ANDES mechanical torque tm on the machine base",
            "pe_pu_mbase": "ANDES air-gap torque te on the machine base (= Pe + ra |I|^2; ra = 0 here)",
            "swing_equation": "2H d(omega)/dt = tm - te - D (omega - 1), torques and D on the machine "
                              "base, omega in pu, t in s (ANDES GENROU; no 1/omega factor)",
            "event_frame": "the frame at t = 10 s holds the pre-event state; the event acts from the "
                           "next integration step on",
        },
        "machines": [machine_truth(base, m) for m in machines],
    })
    timing = {}
    for sc in scenarios:
        t0 = time.time()
        fps = FPS[sc]
        if sc == "ambient":
            ss = load_case(case)
            n_steps = int(round((T_AMBIENT + 2.0 / AMBIENT_STEP_RATE) * STEP_RATE))
            ou = OULoads(ss, CASES[case]["ou_sigma"], OU_TAU_S, n_steps, CASES[case]["seed"])
            t_end, desc = T_AMBIENT, {
                "description": "no event; every load's P and Q follow (1 + xi_i(t)) times the initial "
                               "value, xi_i independent Ornstein-Uhlenbeck processes",
                "ou_std": CASES[case]["ou_sigma"], "ou_time_constant_s": OU_TAU_S,
                "ou_update": "exact discretisation at every integration step", "seed": CASES[case]["seed"],
                "n_loads": int(ss.PQ.n)}
        else:
            ss = load_case(case, event_models(sc, events))
            ou, t_end = None, T_RUN.get(sc, T_EVENT_RUN) if case.endswith("_lib") else T_EVENT_RUN
            desc = {"event_time_s": T_EVENT, **events[sc]}
        mach = [dict(m, uid=ss.GENROU.idx2uid(m["andes_idx"])) for m in machines]
        rate = AMBIENT_STEP_RATE if sc == "ambient" else STEP_RATE
        watch = limiters_of(ss, mach) if sc != "ambient" else []
        extra = controls_of_recorded(ss, mach) if case.endswith("_lib") and sc in T_RUN else []
        sim = simulate(ss, mach, t_end, step_rate=rate, ou=ou, watch=watch, extra=extra)
        fr = frames(sim, f0, sb, mach, fps, t_end, step_rate=rate)
        keep = [not (sc == "gen_trip" and m["andes_idx"] == events["gen_trip"]["andes_idx"])
                for m in machines]
        pmu_path = out_dir / f"{sc}.csv.gz"
        write_pmu(pmu_path, fr, mach, keep)
        if extra:  # the exciters' EFD and CONTROL_VARS at the frames
            kf = np.arange(0, int(round(t_end * rate)) + 1, rate // fps)
            write_csv_gz(out_dir / f"{sc}_controls.csv.gz", ["time_s"] + [c[0] for c in extra],
                         [kf / rate] + [sim["extra"][kf, c] for c in range(len(extra))],
                         ["%.9f"] + ["%.8g"] * len(extra))
        entry = dict(desc, fps=fps, duration_s=t_end, file=pmu_path.name, integration_step_s=1 / rate,
                     recorded=[m["tag"] for m, k in zip(machines, keep) if k],
                     initial_pq_pu_mbase={m["tag"]: [float(fr["Pe"][0, j] * sb / m["mbase"]),
                                                     float(np.imag(fr["V"][0, j] * np.conj(fr["I"][0, j]))
                                                           * sb / m["mbase"])]
                                          for j, m in enumerate(machines) if keep[j]},
                     stats=stats(fr, mach, keep, f0),
                     **({"andes_limits_reached": limits_reached(watch, sim["limit_flags"], rate)}
                        if watch else {}),
                     checks=check_consistency(pmu_path, fr, mach, keep))
        if sc == "ambient" and step_check:  # first 60 s again at h = 1/240 s on the same OU path
            ss2 = load_case(case)
            ou2 = OULoads(ss2, CASES[case]["ou_sigma"], OU_TAU_S, n_steps, CASES[case]["seed"])
            mach2 = [dict(m, uid=ss2.GENROU.idx2uid(m["andes_idx"])) for m in machines]
            sim2 = simulate(ss2, mach2, 60.0, step_rate=STEP_RATE, ou=ou2)
            fr2 = frames(sim2, f0, sb, mach2, fps, 60.0, step_rate=STEP_RATE)
            n = len(fr2["t"])
            entry["checks"]["half_step_first_60s"] = {
                "max_abs_domega_pu": float(np.max(np.abs(fr2["omega"] - fr["omega"][:n]))),
                "max_abs_dF_Hz": float(np.max(np.abs(fr2["F"] - fr["F"][:n]))),
                "max_abs_dVM_pu": float(np.max(np.abs(fr2["VM"] - fr["VM"][:n]))),
                "max_abs_dI_pu_sys": float(np.max(np.abs(fr2["I"] - fr["I"][:n])))}
        if sc != "ambient":
            tpath = out_dir / f"{sc}_truth.csv.gz"
            write_truth_csv(tpath, fr, mach, keep)
            entry["truth_file"] = tpath.name
            entry["checks"]["swing_fit"] = swing_fit(tpath, mach, keep, f0)
            if step_check:
                ss2 = load_case(case, event_models(sc, events))
                mach2 = [dict(m, uid=ss2.GENROU.idx2uid(m["andes_idx"])) for m in machines]
                sim2 = simulate(ss2, mach2, t_end, step_rate=2 * STEP_RATE)
                fr2 = frames(sim2, f0, sb, mach2, fps, t_end, step_rate=2 * STEP_RATE)
                entry["checks"]["half_step"] = {
                    "max_abs_domega_pu": float(np.max(np.abs(fr2["omega"] - fr["omega"]))),
                    "max_abs_dF_Hz_excluding_event_frame": float(np.max(np.abs(
                        (fr2["F"] - fr["F"])[np.abs(fr["t"] - T_EVENT) > 1e-9]))),
                    "max_abs_dVM_pu": float(np.max(np.abs(fr2["VM"] - fr["VM"]))),
                    "max_abs_dI_pu_sys": float(np.max(np.abs(fr2["I"] - fr["I"])))}
        timing[sc] = time.time() - t0
        entry["runtime_s"] = round(timing[sc], 1)
        log.info("%s %s done in %.0f s", case, sc, timing[sc])
        save_truth(truth_path, truth, {sc: entry})

    raw, dyr = out_dir / f"{case}.raw", out_dir / f"{case}.dyr"
    write_raw(base, raw, f"ANDES {andes.__version__} {CASES[case]['files'][0]} as simulated")
    write_dyr(base, dyr)
    truth["psse_files"] = {"raw": raw.name, "dyr": dyr.name,
                           "transformer_codes": "CW=1 (WINDV1 = ANDES tap in pu of bus kV, WINDV2 = 1), "
                                                "CZ=1 (R, X on system base), CM=1 (MAG1 = MAG2 = 0)",
                           "zsorce": "ZR = ra, ZX = X''d (GENROU) or X'd (GENCLS), machine base"}
    if verify:
        truth["psse_files"]["roundtrip"] = verify_psse(case, base, machines, raw, dyr, events["line_trip"])
    save_truth(truth_path, truth, {})
    log.info("%s finished in %.0f s", case, time.time() - t_start)


def _event_text(sc, e):
    if sc == "line_trip":
        return (f"trip line {e['from_bus']}-{e['to_bus']} ({e['kv']:g} kV, {e['pre_event_flow_mw']:.0f} MW "
                f"before) at {e['event_time_s']:g} s")
    if sc == "load_step":
        buses = ", ".join(str(ld["bus"]) for ld in e["loads"])
        return (f"loads at bus {buses} x{e['factor']:.4f} (+{e['step_mw_at_pf_voltage']:.1f} MW = 5 % of "
                f"{e['total_system_load_mw']:.0f} MW) at {e['event_time_s']:g} s, near {e['near_machine']}")
    if sc == "fault":
        return (f"bolted fault at bus {e['bus']} ({e['kv']:g} kV, xf {e['xf_pu_system_base']:g} pu) at "
                f"{e['event_time_s']:g} s, cleared after {e['clear_after_s']:g} s")
    if sc == "gen_trip":
        note = " (recorded in the other files; left out of this one)" if e["recorded_elsewhere"] else ""
        return (f"trip GENROU at bus {e['bus']} id {e['id']} ({e['mbase_mva']:g} MVA, {e['p_mw']:.0f} MW)"
                f"{note} at {e['event_time_s']:g} s")
    return (f"no event; OU load noise std {e['ou_std']:g} (relative), tau {e['ou_time_constant_s']:g} s, "
            f"seed {e['seed']}")


def write_manifest():
    """data/MANIFEST.md from the truth.json files and the sizes on disk."""
    rows = ["# ANDES bench data", "",
            "Written by `experiments/andes_bench/generate.py` (ANDES, GPL-3, run in its own venv; only "
            "that script imports it). All recordings are noise-free.", "",
            "Conventions: `time_s` from 0; per machine tag `B<bus>_G<id>`: `F` bus frequency [Hz] "
            "(central difference of the bus-voltage angle over +-1 integration step), `VM` [pu of bus "
            "kV], `VA` [deg, (-180, 180]], `IM` [pu on the 100 MVA system base at the bus kV], `IA` "
            "[deg]; current = conj((Pe + jQe)/V) of the machine itself, flowing out of the machine "
            "(generator convention). Events at 60 frames/s, 70 s, event at t = 10 s (the t = 10 s frame is "
            "pre-event, its F straddles the switching); ambient at 30 frames/s, 600 s. Truth files: "
            "`delta_rad` (ANDES rotor angle, same frame as VA, unwrapped), `omega_pu`, `pm_pu_mbase` "
            "(mechanical torque), `pe_pu_mbase` (air-gap torque; ra = 0 so = terminal P), machine base. "
            "Swing equation: 2H d(omega)/dt = pm - pe - D (omega - 1). Integration: implicit trapezoid, "
            "h = 1/240 s (events), 1/120 s (ambient). Loads are constant impedances in the dynamics. "
            "H, D, machine, governor, "
            "exciter and PSS data: `truth.json`; the simulated network: `<case>.raw` (PSS/E v33) and "
            "`<case>.dyr`.", ""]
    total = 0
    for case in CASES:
        tp = DATA / case / "truth.json"
        if not tp.exists():
            continue
        t = json.loads(tp.read_text())
        rows += [f"## {case}", "", f"Case files: {', '.join(t['andes_case_files'])} (ANDES "
                 f"{t['andes_version']}); recorded: {t['selection_rule']}.", ""]
        if "derived_case" in t:
            d = t["derived_case"]
            consts = ", ".join(f"{k} = {v:g}" if isinstance(v, int | float) else f"{k} = {json.dumps(v)}"
                           for k, v in d.get("constants", {}).items())
            rows += [f"Derived by `{d['function']}` in generate.py: {d['description']}"
                     + (f" ({consts})" if consts else ""), ""]
        if t["added_to_case"]:
            added = ", ".join(f"{a['model']} on {a['machine']}" for a in t["added_to_case"])
            rows += [f"Added to the case: {added} (data in truth.json).", ""]
        rows += ["| tag | MBASE [MVA] | H [s] | D [pu] | governor | exciter | PSS |",
                 "|---|---|---|---|---|---|---|"]
        for m in t["machines"]:
            ctl = [m[k]["model"] if m[k] else "-" for k in ("governor", "exciter", "pss")]
            rows.append(f"| {m['tag']} | {m['mbase_mva']:g} | {m['H_s_mbase']:g} | "
                        f"{m['D_andes_pu_torque_per_pu_speed_mbase']:g} | {' | '.join(ctl)} |")
        rows += ["", "| file | frames/s | s | scenario | size [kB] |", "|---|---|---|---|---|"]
        for f in sorted((DATA / case).iterdir()):
            size = f.stat().st_size
            total += size
            sc = f.name.split(".")[0].replace("_truth", "")
            e = t["scenarios"].get(sc)
            what = ("truth: " if "_truth" in f.name else "") + (_event_text(sc, e) if e else "")
            fps = e["fps"] if e else ""
            dur = f"{e['duration_s']:g}" if e else ""
            rows.append(f"| {case}/{f.name} | {fps} | {dur} | {what} | {size / 1e3:.0f} |")
        rows.append("")
    rows += [f"Total of data/: {total / 1e6:.2f} MB (plus this file and generate.py).", ""]
    (DATA / "MANIFEST.md").write_text("\n".join(rows))


def setup_logging():
    andes.config_logger(stream_level=logging.ERROR)
    handler = logging.StreamHandler()
    handler.setFormatter(logging.Formatter("%(asctime)s %(message)s"))
    log.addHandler(handler)
    log.setLevel(logging.INFO)
    log.propagate = False


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--case", nargs="+", choices=tuple(CASES), default=list(CASES))
    ap.add_argument("--scenario", nargs="*", choices=SCENARIOS, default=list(SCENARIOS),
                    help="scenarios to simulate; give none to rewrite only the .raw/.dyr (and verify)")
    ap.add_argument("--no-verify", action="store_true", help="skip the .raw/.dyr round trip")
    ap.add_argument("--step-check", action="store_true", help="rerun events at half the step")
    args = ap.parse_args()
    setup_logging()
    for case in args.case:
        run_case(case, args.scenario, not args.no_verify, args.step_check)
    write_manifest()


if __name__ == "__main__":
    main()
