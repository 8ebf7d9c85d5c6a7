"""Compile once, and no deadlock: 16 generators with different plants, one compiled pipeline.

`jaxdse run` pads every recording to one of a few length buckets and batches the generators
of a bucket into one call (``_many/runner.py``). So 16 generators on recordings of two lengths
in one bucket (1501 and 1440 samples, padded to 1536), each with its own machine and governor
droop, compile the vmapped ``assess`` (online estimate, identification, replay, verdict) once,
and run it as ``jit(vmap(assess))`` over 16 different plants. The bucketing of two lengths
into two buckets is ``tests/many/test_runner.py``'s.

* The count comes from JAX's compile log (``jax.log_compiles``) of a `jaxdse run` in this
  process: JAX logs "Compiling <name>" for every lowering, before it looks in the persistent
  compilation cache, so the count does not depend on that cache. No other test compiles this
  shape (16 units of 1536 samples per call), so the process's in-memory cache does not hide it.
* XLA's CPU runtime once deadlocked (every thread idle) on a vmapped identification whose graph
  held LAPACK calls; the per-unit graph now holds none. The run is under a watchdog
  (``faulthandler``): a deadlock ends the test process with the threads' tracebacks after
  ``DEADLOCK_TIMEOUT_S``, so that it fails the suite instead of hanging it.
"""

import contextlib
import faulthandler
import io
import json
import logging
import re

import jax
import numpy as np
import pytest
from builders import COLS, generator_toml, run_toml

import jaxdse as jd
from jaxdse._app.cli import main

pytestmark = pytest.mark.slow

UNITS = 16
DEADLOCK_TIMEOUT_S = 420
"""The watchdog's limit [s]: the run takes about a minute on 2 busy cores, compiling included."""
COMPILING = re.compile(r"Compiling jit\((\w+)\)")


def _plant_toml(k: int) -> str:
    """Generator ``k``'s own machine reactances and governor droop."""
    return (f"[generator.machine]\nxd_pu = {1.6 + 0.02 * k}\nxq_pu = {1.5 + 0.01 * k}\n"
            f"xd1_pu = {0.3 + 0.005 * k}\n"
            f"[generator.governor]\nmodel = \"TGOV1\"\nr_pu = {0.04 + 0.002 * k}\n")


@pytest.fixture(scope="module")
def sixteen_generators(pmu25, tmp_path_factory):
    """16 generators: 8 recordings of 60 s and 8 of 57.6 s (one length bucket), each with its
    own current scale, a2 reference and plant."""
    root = tmp_path_factory.mktemp("sixteen")
    spec = jd.MeasurementSpec(file=(), columns=COLS, v_base_kv=400.0)
    cols = jd.phasor_columns(pmu25.recording, spec)
    text = run_toml("unused.csv")
    for k in range(UNITS):
        n = 1501 if k < UNITS // 2 else 1440
        part = {name: x[:n] for name, x in cols.items()}
        part["IM"] = part["IM"] * (0.9 + 0.01 * k)
        jd.write_csv(root / f"g{k}.csv", part)
        text += generator_toml(f"g{k}", f"g{k}.csv", 25.4 + 0.1 * k) + _plant_toml(k)
    (root / "sixteen.toml").write_text(text)
    return root


class CompileLog(logging.Handler):
    """The names of the functions JAX logs "Compiling <name>" for."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.names = []

    def emit(self, record):
        self.names += COMPILING.findall(record.getMessage())


def test_sixteen_plants_compile_the_pipeline_once_without_deadlock(sixteen_generators):
    cfg = jd.load_config(sixteen_generators / "sixteen.toml")
    assert len({str(g.plant.machine.xq_pu) for g in cfg.generators}) == UNITS  # 16 plants
    assert len({str(g.plant.governor.r_pu) for g in cfg.generators}) == UNITS
    log, logger = CompileLog(), logging.getLogger("jax")
    logger.addHandler(log)
    err, out = io.StringIO(), io.StringIO()
    faulthandler.dump_traceback_later(DEADLOCK_TIMEOUT_S, exit=True)
    try:
        with jax.log_compiles(True), contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            rc = main(["run", str(sixteen_generators / "sixteen.toml"), "--out",
                       str(sixteen_generators / "out")])
    finally:
        faulthandler.cancel_dump_traceback_later()
        logger.removeHandler(log)
    assert rc == 0, err.getvalue()[-3000:]
    summary = json.loads((sixteen_generators / "out" / "summary.json").read_text())
    assert len(summary["recordings"]) == UNITS
    h = np.array([e["H_s"] for e in summary["recordings"]])
    ci = np.array([e["H_ci95"] for e in summary["recordings"]])
    assert np.all(np.isfinite(h)) and np.all(np.isfinite(ci))
    assert len(set(np.round(h, 9))) == UNITS, "different plants must give different H"
    assess = [n for n in log.names if "assess" in n]
    print(f"compiles: assess {len(assess)}, all {len(log.names)}")
    assert len(assess) == 1, log.names
