"""Accuracy with default PMU noise and governor Tm, default configuration: the demo's two
600 s recordings (auto at 90 %, cross at 45 % of rating), as ``jaxdse demo`` estimates them."""

import numpy as np
import pytest


@pytest.mark.slow
@pytest.mark.parametrize("name,limit", [("auto", 3.0), ("cross", 5.0)])
def test_a2_error_with_noise(demo_run, name, limit):
    rc, _, _, summary = demo_run
    assert rc == 0
    e = next(r for r in summary["recordings"] if r["name"] == name)
    assert e["n_samples"] == 30001  # the full 600 s at 50 frames/s
    assert abs(e["a2_error_percent"]) < limit, e["a2_error_percent"]
    assert e["converged"] and np.isfinite(e["convergence_time_s"])
