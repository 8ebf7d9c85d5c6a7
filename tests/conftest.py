"""Shared set-up of the suite (tests mirror src/jaxdse/: core/, io/, many/, app/).

* float64, and broadcasting that must be explicit (as diffrax's conftest sets it: rank
  promotion raises). Strict dtype promotion does not fit: the phasor arithmetic mixes float64
  arrays with Python complex scalars throughout.
* JAX's persistent compilation cache only when ``JAX_COMPILATION_CACHE_DIR`` is set (then
  subprocesses share it). Off by default: a fresh clone has nothing to read, and a cache
  write once crashed the interpreter (SIGSEGV in ``put_executable_and_time``, CI, jax 0.10).
* XLA's CPU executables each hold a few memory mappings, and a suite run compiles thousands
  (every eagerly run operation of a new shape is one). Past the kernel's ``vm.max_map_count``
  (65530 by default) the next compile segfaults: measured, 40 000 mappings at 60 % of the
  suite, a crash at 95 %. So after any test that leaves more than ``MAX_MAPPINGS``, the
  compilation caches are cleared (the shared shapes then compile once more). A clear costs
  5-13 s and the recompiles after it; each of the two workers ends near 30 000 mappings
  (measured 2026-11-27), so the bar sits at 45 000, 20 000 below the limit: a serial run
  clears once.
* Recordings of a few fixed lengths and the compiled estimator, built once per session:
  compiling the whole pipeline costs seconds, so tests reuse these shapes (20 s, 60 s and
  120 s at 50 frames/s; 60 s and its first 50 s at 25 frames/s for the file-based tests and
  the runner). A suite run compiles each pipeline shape once: the shapes below, and those of
  ``jaxdse run`` on the 60 s recording (padded to 1536 samples) and on two parts of 1250
  samples (1280 each), are shared across modules.
* The suite compiles far more than it runs, so XLA's slow optimisation passes are off
  (``jax_disable_most_optimizations``; ``JAXDSE_TEST_OPTIMIZE=1`` keeps them): measured on 2
  cores, the serial suite reached the same test in 12.9 min against 15.5 min. So are XLA's
  MLIR fusion emitters, which took half of each compile at that level: the suite on 2 cores
  took 8.0 min instead of 12.5 min. The session run
  that computes more than it compiles, ``jaxdse run`` on the ISO-NE recording, runs with them
  on (:func:`optimised`), as a user's does: its set-up took 21 s against 26 s without, alone
  on 2 cores (``jaxdse demo``: 18 s either way, so it stays without; 2026-11-25).
* Python's cyclic garbage collector runs less often (``gc.set_threshold`` below).
* pytest-xdist, one worker per core (``-n auto --dist loadscope`` in pyproject.toml): each
  module, and the modules that share compiled shapes or session runs (``SHARED``,
  ``xdist_scope``), stay on one worker, and the longest of them are handed out first
  (``LONGEST_FIRST``), so that no worker is left with a long module at the end.
"""

import contextlib
import gc
import os
from pathlib import Path

import jax

ROOT = Path(__file__).resolve().parents[1]
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
if not os.environ.get("JAXDSE_TEST_OPTIMIZE"):
    jax.config.update("jax_disable_most_optimizations", True)
    # XLA's MLIR fusion emitters cost half of a compile at optimisation level 0 (read at the
    # backend's start, so set before the first computation; subprocesses inherit it).
    os.environ["XLA_FLAGS"] = " ".join((os.environ.get("XLA_FLAGS", ""),
                                        "--xla_cpu_use_fusion_emitters=false")).strip()
if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)
# `jaxdse` commands run in-process or in subprocesses use the same cache, or none: never the
# user's own (~/.cache/jaxdse).
os.environ.setdefault("JAXDSE_CACHE_DIR", os.environ.get("JAX_COMPILATION_CACHE_DIR", "off"))

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxdse as jd  # noqa: E402

# The suite traces far more than it runs, and tracing allocates millions of short-lived
# objects: with Python's default thresholds the cyclic collector walks the young ones every
# 700 allocations. Less often (the objects die by reference counting all the same): the
# tune and estimate modules, serially, 73-78 s -> 67-68 s.
gc.set_threshold(100_000, 50, 100)

SHARED_DATA = ROOT.parent / "shared" / "data"
MAPS = Path("/proc/self/maps")
MAX_MAPPINGS = 45000
"""Memory mappings of this process above which the JAX caches are cleared (Linux only)."""


@pytest.fixture(autouse=True)
def bounded_executables():
    """Clear JAX's compilation caches when the process holds many mappings (see above)."""
    yield
    if MAPS.exists():
        with MAPS.open("rb") as fh:
            if sum(1 for _ in fh) > MAX_MAPPINGS:
                jax.clear_caches()
                gc.collect()


@contextlib.contextmanager
def optimised():
    """XLA's optimisation passes on within the block (the suite turns them off)."""
    before = jax.config.read("jax_disable_most_optimizations")
    jax.config.update("jax_disable_most_optimizations", False)
    try:
        yield
    finally:
        jax.config.update("jax_disable_most_optimizations", before)


def cut(rec: jd.Recording, n: int) -> jd.Recording:
    """The first ``n`` samples of a recording."""
    return jax.tree_util.tree_map(lambda x: x[:n], rec)


@pytest.fixture(scope="session")
def plant():
    return jd.Plant()


@pytest.fixture(scope="session")
def ambient(plant):
    """120 s of ambient excitation at 90 % of rating: noisy recording, clean twin and truth."""
    return jd.simulate(plant, jd.Scenario(duration_s=120.0, seed=3))


@pytest.fixture(scope="session")
def short(ambient):
    """The first 20 s (1001 samples) of the ambient recording: gradient and vmap tests."""
    return cut(ambient.recording, 1001)


@pytest.fixture(scope="session")
def pmu25(plant):
    """60 s at 25 frames/s (1501 samples): the recording the file-based tests write and read."""
    return jd.simulate(plant, jd.Scenario(duration_s=60.0, frame_rate_hz=25.0, seed=8))


@pytest.fixture(scope="session")
def cut25(pmu25):
    """The first 1251 samples (50 s) of ``pmu25``: the unit-alone shape of ``assess_jit``
    (padded to 1280 samples in a batch, as the two parts of `jaxdse run`'s split-recording
    test are)."""
    return cut(pmu25.recording, 1251)


@pytest.fixture(scope="session")
def assess_jit():
    """``jd.assess`` of one unit with the test settings (``jaxdse run``'s: trajectories kept,
    4 bootstrap draws), compiled once: the runner test's and the verdict tests'
    unit-alone runs share it (on ``cut25``'s shape)."""
    from builders import TEST_BOOTSTRAP_DRAWS

    return jax.jit(lambda r, p: jd.assess(r, p, jd.ObserverConfig(), jd.Settings(),
                                          jd.IdentifySettings(bootstrap_draws=TEST_BOOTSTRAP_DRAWS)))


@pytest.fixture(scope="session")
def isone_run(tmp_path_factory):
    """``jaxdse run examples/isone_mat.toml`` on the REAL ISO-NE recording, once, in-process
    (figures off): (exit status, stderr, summary.json). The CLI test and the results-regression
    tests read it."""
    import io
    import json

    from jaxdse._app.cli import main

    if not (SHARED_DATA / "isone_oscillation" / "case3row.mat").exists():
        pytest.skip("the shared ISO-NE recording is not beside the checkout")
    out = tmp_path_factory.mktemp("isone")
    # The shipped config as it is, with its figures off (no test reads them; ~8 s): the data
    # path made absolute, as the copy sits in a temporary folder.
    text = (ROOT / "examples" / "isone_mat.toml").read_text()
    text = text.replace('file = "../../shared/', f'file = "{ROOT.parent / "shared"}/')
    config = out / "isone_mat.toml"
    config.write_text(text.replace('[output]\ndir = "isone_out"',
                                   '[output]\ndir = "isone_out"\nfigures = false'))
    assert "figures = false" in config.read_text() and str(SHARED_DATA) in config.read_text()
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()), optimised():
        rc = main(["run", str(config), "--out", str(out)])
    summary = json.loads((out / "summary.json").read_text()) if rc == 0 else None
    return rc, err.getvalue(), summary


@pytest.fixture(scope="session")
def estimate_jit():
    return jax.jit(jd.estimate)


@pytest.fixture(scope="session")
def rng():
    return np.random.default_rng(1234)


@pytest.fixture(scope="session")
def demo_run(tmp_path_factory):
    """``jaxdse demo`` (the main job on built-in data, 600 s recordings), run once in-process:
    its files, its printed table and its summary. The CLI contract test and the accuracy
    test both read it."""
    import io
    import json

    from jaxdse._app.cli import main

    out = tmp_path_factory.mktemp("demo")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        rc = main(["demo", "--out", str(out)])
    return rc, out, printed.getvalue(), json.loads((out / "summary.json").read_text())


SHARED = {
    "pipeline": ("app/test_bad_input.py", "app/test_run.py", "io/test_fuzz.py", "many/test_runner.py",
                 "core/test_identify.py"),
    "isone": ("app/test_isone.py",),
    "demo": ("app/test_cli.py", "core/test_accuracy.py"),
    "check": ("app/test_check.py", "app/test_repair.py"),
}
"""xdist work units of modules that share compiled pipeline shapes or session runs: `jaxdse run`
on the 60 s recording (1536 samples) and on two split parts (2 x 1280), and ``assess_jit`` on
``cut25`` (pipeline); the ISO-NE run (isone, with test_run's CLI test of it); ``demo_run``
(demo); the check's program of the ieee14 case with three bad records (check)."""


LONGEST_FIRST = ("pipeline", "tests/many/test_tune.py", "tests/app/test_dyr_playback.py",
                 "tests/app/test_regfm_fleet.py",  # (added 2026-11-30: 151 s in the suite, two fits)
                 "tests/models/test_regcv1.py",  # (added 2026-11-29: 56 s alone, 31 s CPU)
                 "tests/stream/test_monitor.py", "demo", "tests/models/test_machines_new.py",
                 "tests/core/test_estimate.py", "tests/stream/test_windowed.py",
                 "tests/models/test_ibr_pv.py", "tests/app/test_check_pv.py",  # (added 2026-11-29)
                 "tests/app/test_ibr_validate.py",  # (added 2026-11-29: 48 s CPU alone, 3 IBR fit programs)
                 "tests/models/test_governors.py", "tests/app/test_fleet.py", "tests/core/test_events.py",
                 "tests/models/test_stabilisers_pss2.py", "tests/many/test_stream.py",
                 "tests/many/test_batch.py", "isone", "tests/models/test_exciters.py",
                 "tests/app/test_compiles.py", "tests/core/test_drem.py",
                 "tests/models/test_exciters_dc_st.py", "tests/app/test_window_replay.py",
                 "tests/stream/test_sttp.py", "tests/dyr/test_playback.py",
                 "tests/models/test_governors_new.py", "tests/models/test_exciters_ac.py",
                 "tests/stream/test_pmu_sim.py", "tests/stream/test_c37118.py",
                 "tests/models/test_stabilisers.py", "tests/core/test_lti.py")
"""Work units that took longest (``--durations=0`` summed per unit, 2 cores, 2026-11-27), in
that order: run first."""


def pytest_collection_modifyitems(items):
    """The longest work units first (a stable sort: the rest keep their order)."""
    rank = {scope: k for k, scope in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(xdist_scope(item.nodeid), len(LONGEST_FIRST)))


def xdist_scope(nodeid: str) -> str:
    """The xdist work unit of a test: its module, or the module's ``SHARED`` group; the CLI
    test of the ISO-NE config joins the isone group."""
    path, _, name = nodeid.partition("::")
    rel = path.removeprefix("tests/")
    if "isone" in name:
        return "isone"
    return next((group for group, paths in SHARED.items() if rel in paths), path)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadscope`` with ``xdist_scope`` as the scope (xdist's own ``loadgroup`` reads
    marks through ``item._nodeid``, which pytest 9 no longer uses for the node id)."""
    if config.getvalue("dist") != "loadscope":
        return None
    from xdist.scheduler import LoadScopeScheduling

    # xdist (>= 3.6) would sort the units by their number of tests, not by LONGEST_FIRST.
    config.option.loadscopereorder = False

    class SharedScopeScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return xdist_scope(nodeid)

    return SharedScopeScheduling(config, log)

