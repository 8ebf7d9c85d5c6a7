"""Where the test suite's time goes: per test file, the wall and CPU time and how much of it JAX
spent turning programs into code, for the quick run (README's test command: the tests not marked
``slow``) and for the whole suite (``-m ''``).

    python benchmarks/suite_profile.py                 # both: the quick run, then the whole suite (~20 min)
    python benchmarks/suite_profile.py --tier quick    # README's test command only (~5 min)
    python benchmarks/suite_profile.py --tier all tests/app   # a part of the whole suite

Runs ``python -m pytest -q`` with this file as a plugin (``-p suite_profile``): each worker
listens to JAX's compile events (``jax.monitoring``: the jaxpr trace, the lowering to MLIR and
XLA's backend compile, each with its duration) and writes one line per test (its wall and CPU
time, the seconds and count of each event during it, and whether it is marked ``slow``). The
lines of both workers are summed per file and overall.

Writes ``benchmarks/suite_profile.json`` (per tier: ``totals``, ``files`` the longest first, and,
for the whole suite, ``unmarked_over_s``: the tests not marked ``slow`` that took ``SLOW_S`` or
more, which the quick run should not hold) and prints the totals and the 15 longest files.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
EVENTS = {"/jax/core/compile/backend_compile_duration": "compile_s",
          "/jax/core/compile/jaxpr_trace_duration": "trace_s",
          "/jax/core/compile/jaxpr_to_mlir_module_duration": "lower_s"}
"""JAX's monitoring events counted, and their names in the results."""
FIELDS = ("wall_s", "cpu_s", "compile_s", "trace_s", "lower_s", "compiles")
SLOW_S = 5.0
"""A test's wall time [s] from which it is marked ``slow`` (pyproject.toml's marker): measured in
the whole suite, where a module's shared set-up counts to its first test."""
TIERS = {"quick": [], "all": ["-m", ""]}
"""pytest's selection per tier: README's (pyproject.toml's ``-m 'not slow'``), and every test."""

# --- the plugin (imported by each pytest process through ``-p suite_profile``) ----------------

_sums = {"compile_s": 0.0, "trace_s": 0.0, "lower_s": 0.0, "compiles": 0}
_out = None


def _listener(event, duration, **_):
    name = EVENTS.get(event)
    if name is not None:
        _sums[name] += duration
        _sums["compiles"] += name == "compile_s"


def pytest_configure(config):
    if os.environ.get("SUITE_PROFILE_DIR"):
        from jax import monitoring

        monitoring.register_event_duration_secs_listener(_listener)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item, nextitem):
    """One line per test in this worker's file."""
    global _out
    folder = os.environ.get("SUITE_PROFILE_DIR")
    if not folder:
        return (yield)
    if _out is None:
        _out = open(Path(folder) / f"{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.jsonl", "a")
    before = dict(_sums)
    t0, c0 = time.perf_counter(), time.process_time()
    result = yield
    row = {"test": item.nodeid, "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
           "slow": item.get_closest_marker("slow") is not None, **{k: _sums[k] - before[k] for k in _sums}}
    _out.write(json.dumps(row) + "\n")
    _out.flush()
    return result


# --- the script -------------------------------------------------------------------------------

def summarise(rows: list[dict]) -> dict:
    """Per-file and overall sums of the per-test lines, the files longest (wall) first."""
    files = defaultdict(lambda: dict.fromkeys(("tests",) + FIELDS, 0))
    total = dict.fromkeys(("tests",) + FIELDS, 0)
    for r in rows:
        f = files[r["test"].split("::")[0]]
        for acc in (f, total):
            acc["tests"] += 1
            for k in FIELDS:
                acc[k] += r[k]
    share = {f"{k[:-2]}_share": total[k] / total["cpu_s"] for k in ("compile_s", "trace_s", "lower_s")
             if total["cpu_s"]}
    ordered = sorted(files.items(), key=lambda kv: -kv[1]["wall_s"])
    return {"totals": {**total, **share}, "files": [{"file": name, **v} for name, v in ordered]}


def run(tier: str, paths: list[str]) -> dict:
    """One pytest run of ``tier`` over ``paths``, profiled."""
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, "SUITE_PROFILE_DIR": folder,
               "PYTHONPATH": os.pathsep.join(filter(None, [str(HERE), os.environ.get("PYTHONPATH")]))}
        t0 = time.perf_counter()
        cmd = [sys.executable, "-m", "pytest", "-q", "-p", "suite_profile", *TIERS[tier], *paths]
        rc = subprocess.call(cmd, cwd=HERE.parent, env=env)
        elapsed = time.perf_counter() - t0
        rows = [json.loads(line) for p in sorted(Path(folder).glob("*.jsonl")) for line in p.open()]
    out = {"paths": paths, "pytest_exit": rc, "elapsed_s": elapsed, **summarise(rows)}
    if tier == "all":
        over = [{"test": r["test"], "wall_s": round(r["wall_s"], 1)} for r in rows
                if r["wall_s"] >= SLOW_S and not r["slow"]]
        out["unmarked_over_s"] = sorted(over, key=lambda r: -r["wall_s"])
    t = out["totals"]
    print(f"{tier}: {t['tests']} tests, {elapsed:.0f} s elapsed, {t['cpu_s']:.0f} s CPU in the tests: "
          f"backend compile {t['compile_s']:.0f} s, trace {t['trace_s']:.0f} s, "
          f"lowering {t['lower_s']:.0f} s ({t['compiles']} compilations)")
    for f in out["files"][:15]:
        compiling = f["compile_s"] + f["trace_s"] + f["lower_s"]
        print(f"  {f['file']:50s} {f['wall_s']:7.1f} s wall, {compiling:6.1f} s compiling, "
              f"{f['compiles']} compilations, {f['tests']} tests")
    return out


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(description="Where the test suite's time goes, per test file and tier.")
    ap.add_argument("--tier", choices=[*TIERS, "both"], default="both",
                    help="quick: README's test command; all: every test (-m ''); both (default)")
    ap.add_argument("paths", nargs="*", default=["tests"], help="test folders or files (default: tests)")
    args = ap.parse_args(argv)
    tiers, paths = (list(TIERS) if args.tier == "both" else [args.tier]), args.paths
    results = HERE / "suite_profile.json"
    old = json.loads(results.read_text()) if results.exists() else {}
    out = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "slow_s": SLOW_S,
           "tiers": {**old.get("tiers", {}), **{tier: run(tier, paths) for tier in tiers}}}
    results.write_text(json.dumps(out, indent=1) + "\n")
    return max(out["tiers"][tier]["pytest_exit"] for tier in tiers)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
