"""jaxdse's XLA compile options for the per-unit pipeline against XLA's defaults.

    python benchmarks/compile_options.py

For each variant (``jaxdse``: ``compiler_options=None``, the runner's own options, LLVM at
level 1 and XLA's classic emitters, what ``jaxdse run``, ``fleet`` and ``demo`` use on CPU;
``xla_defaults``: ``compiler_options={}``) and each size
(units x samples of simulated recordings at 25 frames/s), a fresh process times the first
call of ``jd.assess_units`` (compile and run) and a second call (run only), and keeps the
identified H of every unit (the variants must agree to round-off).

Writes ``benchmarks/compile_options.json`` (and prints it).
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).parent
SIZES = ((2, 15000), (8, 15000))
"""(units, samples): two 600 s recordings (as the demo's, at 25 frames/s) and four times as many."""
VARIANTS = {"jaxdse": "null", "xla_defaults": "{}"}
"""The ``compiler_options`` argument of each variant, as JSON."""

CHILD = """
import json, sys, time
import jax
jax.config.update("jax_enable_x64", True)
import jaxdse as jd
options, units, samples = json.loads(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
plant = jd.Plant()
work = [jd.Unit(f"u{k}", jd.simulate(plant, jd.Scenario(duration_s=(samples - 1) / 25.0, frame_rate_hz=25.0,
        seed=k)).recording, plant) for k in range(units)]
t0 = time.perf_counter()
jd.assess_units(work, compiler_options=options)
t1 = time.perf_counter()
b = jd.assess_units(work, compiler_options=options)
t2 = time.perf_counter()
print(json.dumps({"first_s": t1 - t0, "run_s": t2 - t1, "h_s": [float(x.identified.h_s) for x in b]}))
"""


def measure(options: str, units: int, samples: int) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "JAX_DISABLE_MOST_OPTIMIZATIONS")}
    out = subprocess.run([sys.executable, "-c", CHILD, options, str(units), str(samples)],
                         capture_output=True, text=True, check=True, env=env)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    r["compile_s"] = r["first_s"] - r["run_s"]
    return r


def main() -> None:
    res: dict = {"machine": f"{platform.machine()}, {os.cpu_count()} cores", "sizes": {}}
    for units, samples in SIZES:
        row = {name: measure(options, units, samples) for name, options in VARIANTS.items()}
        row["h_max_abs_difference_s"] = max(abs(a - b) for a, b in zip(*(row[v]["h_s"] for v in VARIANTS)))
        res["sizes"][f"{units}x{samples}"] = row
        print(f"{units} x {samples}:", {v: (round(row[v]["compile_s"], 1), round(row[v]["run_s"], 2))
                                        for v in VARIANTS}, flush=True)
    (HERE / "compile_options.json").write_text(json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
