"""Where the test suite's time goes: per test file, the wall and CPU time and how much of it JAX
spent turning programs into code.

    python benchmarks/suite_profile.py            # the whole suite, as README runs it (~17 min)
    python benchmarks/suite_profile.py tests/app  # a part

Runs ``python -m pytest -q`` with this file as a plugin (``-p suite_profile``): each worker
listens to JAX's compile events (``jax.monitoring``: the jaxpr trace, the lowering to MLIR and
XLA's backend compile, each with its duration) and writes one line per test (its wall and CPU
time, and the seconds and count of each event during it). The lines of both workers are summed
per file and overall.

Writes ``benchmarks/suite_profile.json`` (``totals`` and ``files``, the longest first) and prints
the totals and the 15 longest files.
"""

from __future__ import annotations

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
           **{k: _sums[k] - before[k] for k in _sums}}
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


def main(argv: list[str]) -> int:
    paths = argv or ["tests"]
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, "SUITE_PROFILE_DIR": folder,
               "PYTHONPATH": os.pathsep.join(filter(None, [str(HERE), os.environ.get("PYTHONPATH")]))}
        t0 = time.perf_counter()
        rc = subprocess.call([sys.executable, "-m", "pytest", "-q", "-p", "suite_profile", *paths],
                             cwd=HERE.parent, env=env)
        elapsed = time.perf_counter() - t0
        rows = [json.loads(line) for p in sorted(Path(folder).glob("*.jsonl")) for line in p.open()]
    out = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "paths": paths, "pytest_exit": rc,
           "elapsed_s": elapsed, **summarise(rows)}
    (HERE / "suite_profile.json").write_text(json.dumps(out, indent=1) + "\n")
    t = out["totals"]
    print(f"{t['tests']} tests, {elapsed:.0f} s elapsed, {t['cpu_s']:.0f} s CPU in the tests: backend "
          f"compile {t['compile_s']:.0f} s, trace {t['trace_s']:.0f} s, lowering {t['lower_s']:.0f} s "
          f"({t['compiles']} compilations)")
    for f in out["files"][:15]:
        compiling = f["compile_s"] + f["trace_s"] + f["lower_s"]
        print(f"  {f['file']:50s} {f['wall_s']:7.1f} s wall, {compiling:6.1f} s compiling, "
              f"{f['compiles']} compilations, {f['tests']} tests")
    return rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
