"""Compile once: a 10-generator config compiles the whole per-unit pipeline a few times.

`jaxdse run` pads every recording to one of a few length buckets and batches the generators
of a bucket into one call (``_many/runner.py``), so 10 generators on recordings of two lengths
compile the vmapped ``assess`` (online estimate, identification, replay, verdict) at most 3
times. Counted from JAX's compile log (``jax.log_compiles``) of a `jaxdse run` in this
process: JAX logs "Compiling <name>" for every lowering, before it looks in the persistent
compilation cache, so the count does not depend on that cache. No other test compiles these
two shapes (5 units of 1536 and of 1280 samples per call), so the process's in-memory cache
does not hide them either.
"""

import contextlib
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

MAX_COMPILES = 3
COMPILING = re.compile(r"Compiling jit\((\w+)\)")
"""Names of the jitted online estimator: jaxdse._many.batch jits ``one`` (vmapped estimate)."""


@pytest.fixture(scope="module")
def ten_generators(pmu25, tmp_path_factory):
    """10 generators: 5 recordings of 60 s and 5 of 50 s (two length buckets), each with its own
    current scale and a2 reference."""
    root = tmp_path_factory.mktemp("ten")
    spec = jd.MeasurementSpec(file=(), columns=COLS, v_base_kv=400.0)
    cols = jd.phasor_columns(pmu25.recording, spec)
    text = run_toml("unused.csv")
    for k in range(10):
        n = 1501 if k < 5 else 1251
        part = {name: x[:n] for name, x in cols.items()}
        part["IM"] = part["IM"] * (0.9 + 0.02 * k)
        jd.write_csv(root / f"g{k}.csv", part)
        text += generator_toml(f"g{k}", f"g{k}.csv", 25.4 + 0.1 * k)
    (root / "ten.toml").write_text(text)
    return root


class CompileLog(logging.Handler):
    """The names of the functions JAX logs "Compiling <name>" for."""

    def __init__(self):
        super().__init__(logging.DEBUG)
        self.names = []

    def emit(self, record):
        self.names += COMPILING.findall(record.getMessage())


def test_ten_generators_compile_the_pipeline_at_most_three_times(ten_generators):
    log, logger = CompileLog(), logging.getLogger("jax")
    logger.addHandler(log)
    err, out = io.StringIO(), io.StringIO()
    try:
        with jax.log_compiles(True), contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            rc = main(["run", str(ten_generators / "ten.toml"), "--out", str(ten_generators / "out")])
    finally:
        logger.removeHandler(log)
    assert rc == 0, err.getvalue()[-3000:]
    summary = json.loads((ten_generators / "out" / "summary.json").read_text())
    assert len(summary["recordings"]) == 10
    assert all(np.isfinite(e["H_s"]) for e in summary["recordings"])
    names = log.names
    assess = [n for n in names if "assess" in n]
    print(f"compiles: assess {len(assess)}, all {len(names)}")
    assert 1 <= len(assess) <= MAX_COMPILES, names
