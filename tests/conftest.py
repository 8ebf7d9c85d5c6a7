"""Shared set-up of the suite (tests mirror src/jaxdse/: core/, io/, many/, app/).

* float64, and broadcasting that must be explicit (as diffrax's conftest sets it: rank
  promotion raises). Strict dtype promotion does not fit: the phasor arithmetic mixes float64
  arrays with Python complex scalars throughout.
* A persistent compilation cache in ``.jax_cache/``; subprocesses get it through the
  environment (``JAX_COMPILATION_CACHE_DIR``).
* Recordings of a few fixed lengths and the compiled estimator, built once per session:
  compiling the whole pipeline costs seconds, so tests reuse these shapes (20 s, 60 s and
  120 s at 50 frames/s; 60 s at 25 frames/s for the file-based tests).
"""

import os
from pathlib import Path

import jax

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / ".jax_cache"
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", str(CACHE))
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_compilation_cache_dir", str(CACHE))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.5)

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxdse as jd  # noqa: E402

SHARED_DATA = ROOT.parent / "shared" / "data"


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
    import contextlib
    import io
    import json

    from jaxdse._app.cli import main

    out = tmp_path_factory.mktemp("demo")
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        rc = main(["demo", "--out", str(out)])
    return rc, out, printed.getvalue(), json.loads((out / "summary.json").read_text())
