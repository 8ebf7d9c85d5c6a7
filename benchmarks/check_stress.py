"""`jaxdse check` back to back on real cases while another job loads every core (issue 43).

    python benchmarks/check_stress.py                       # ACTIVSg2000 and Texas 7k, 10 runs each
    python benchmarks/check_stress.py --runs 2 --cases activsg2000 --no-write

Each run is the console script in a fresh process (``jaxdse check CASE.toml --out DIR``), with
its own empty compilation cache (``JAXDSE_CACHE_DIR``) for the first run of a case and the cache
that run filled for the others (the warm cache made the hang likeliest). Meanwhile ``--load``
processes (default: one per core) spin in pure Python at normal priority. A run that has not
ended after ``--limit-s`` seconds is a hang: it is killed and counted. Per run: the wall time,
the exit status and the outcome counts of its check.json (which must equal the first run's).

Writes ``check_stress`` into ``benchmarks/results.json`` (other keys kept), after every run (a
run cut short keeps what it measured). ``--from-log LOG``: the results of the runs a log of this
script holds (its per-run lines), written the same way, without running anything.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import platform
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
CASES = {"activsg2000": HERE.parent / "experiments" / "activsg2000" / "case.toml",
         "texas7k": HERE.parent / "experiments" / "texas7k" / "case.toml"}


def spin(stop) -> None:
    """Load one core until ``stop`` is set."""
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x = (x * 1103515245 + 12345) & 0xFFFFFFFF


def one_run(case: Path, out: Path, cache: Path, limit_s: float) -> dict:
    env = dict(os.environ, JAXDSE_CACHE_DIR=str(cache))
    t0 = time.perf_counter()
    with open(out.with_suffix(".log"), "w") as log:
        proc = subprocess.Popen([shutil.which("jaxdse") or "jaxdse", "check", str(case), "--out", str(out)],
                                stdout=log, stderr=subprocess.STDOUT, env=env)
        try:
            rc = proc.wait(timeout=limit_s)
            hung = False
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            rc, hung = None, True
    wall = time.perf_counter() - t0
    counts = None
    if (out / "check.json").exists():
        s = json.loads((out / "check.json").read_text())["summary"]
        counts = {k: s[k] for k in ("units", "pass", "data problem", "not supported", "fail")}
    return {"wall_s": round(wall, 1), "exit": rc, "hung": hung, "outcomes": counts,
            "load_average": [round(x, 2) for x in os.getloadavg()]}


def summarise(runs_by_case: dict, result: dict) -> dict:
    """``result`` with, per case, its runs and their counts (hangs, exits, outcomes, wall times)."""
    for name, runs in runs_by_case.items():
        first = runs[0]["outcomes"]
        result["cases"][name] = {
            "runs": runs, "runs_done": len(runs), "hangs": sum(r["hung"] for r in runs),
            "nonzero_exits": sum(r["exit"] != 0 for r in runs if not r["hung"]),
            "outcomes_equal_to_first": all(r["outcomes"] == first for r in runs),
            "outcomes": first,
            "wall_s": {"min": min(r["wall_s"] for r in runs), "max": max(r["wall_s"] for r in runs),
                       "warm_median": float(sorted(r["wall_s"] for r in runs[1:])[len(runs[1:]) // 2])
                       if len(runs) > 1 else None}}
    return result


def write(result: dict) -> None:
    path = HERE / "results.json"
    doc = json.loads(path.read_text()) if path.exists() else {}
    doc["check_stress"] = result
    path.write_text(json.dumps(doc, indent=2) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--runs", type=int, default=10, help="runs per case (default 10)")
    ap.add_argument("--load", type=int, default=os.cpu_count(), help="busy processes (default: one per core)")
    ap.add_argument("--limit-s", type=float, default=1800.0, help="a run longer than this is a hang (s)")
    ap.add_argument("--no-write", action="store_true", help="leave benchmarks/results.json alone")
    ap.add_argument("--from-log", type=Path, default=None, help="record the runs of this script's log")
    args = ap.parse_args()
    base = {"runs_per_case": args.runs, "load_processes": args.load, "limit_s": args.limit_s,
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores", "cases": {}}
    if args.from_log is not None:
        runs_by_case: dict = {}
        for line in args.from_log.read_text().splitlines():
            parts = line.split(" ", 2)
            if len(parts) == 3 and parts[0] in CASES and parts[1].isdigit():
                runs_by_case.setdefault(parts[0], []).append(json.loads(parts[2]))
        result = summarise(runs_by_case, {**base, "from_log": args.from_log.name})
        print(json.dumps({k: {kk: vv for kk, vv in v.items() if kk != "runs"}
                          for k, v in result["cases"].items()}, indent=1))
        if not args.no_write:
            write(result)
        return
    stop = mp.Event()
    load = [mp.Process(target=spin, args=(stop,), daemon=True) for _ in range(args.load)]
    for p in load:
        p.start()
    result = base
    runs_by_case = {}
    try:
        with tempfile.TemporaryDirectory(prefix="check_stress_") as tmp:
            for name in args.cases:
                cache = Path(tmp) / f"cache_{name}"
                runs = runs_by_case.setdefault(name, [])
                for k in range(args.runs):
                    r = one_run(CASES[name], Path(tmp) / f"{name}_{k}", cache, args.limit_s)
                    r["cache"] = "cold" if k == 0 else "warm"
                    runs.append(r)
                    print(name, k + 1, json.dumps(r), flush=True)
                    summarise(runs_by_case, result)
                    if not args.no_write:
                        write(result)
    finally:
        stop.set()
        for p in load:
            p.join(5)
    print(json.dumps({k: {kk: vv for kk, vv in v.items() if kk != "runs"} for k, v in result["cases"].items()},
                     indent=1))


if __name__ == "__main__":
    main()
