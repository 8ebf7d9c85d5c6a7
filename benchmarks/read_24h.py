"""Read a 24 h, 50 frames/s positive-sequence CSV (4.32 million rows) through the public API.

    python benchmarks/read_24h.py            # writes benchmarks/read_24h.json

Writes the file (time, |V|, angle V, |I|, angle I, f) to a temporary folder, then reads it with
``jd.read_measurement`` in a fresh subprocess (reader, unit handling, plausibility, screening,
resampling), which reports the wall time and its peak resident memory (``ru_maxrss``, the
imports included), with the CPU time of the read and the machine's load (wall times on a
shared machine depend on it). Targets: under 10 s and under 2 GiB.
"""

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
RATE_HZ, HOURS = 50.0, 24.0
COLUMNS = {"time": "Time_s", "v_mag": "V1_kV", "v_ang": "V1_deg", "i_mag": "I1_A", "i_ang": "I1_deg",
           "frequency": "Freq_Hz"}
CHILD = """
import json, resource, sys, time
t0 = time.perf_counter()
import jaxdse as jd
imported, cpu0 = time.perf_counter(), time.process_time()
rss_imports = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
spec = jd.MeasurementSpec(file=(sys.argv[1],), columns=json.loads(sys.argv[2]), v_base_kv=400.0)
segments, quality = jd.read_measurement(spec, jd.Machine())
done = time.perf_counter()
print(json.dumps({"read_s": done - imported, "read_cpu_s": time.process_time() - cpu0,
                  "import_s": imported - t0,
                  "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "rss_after_imports_mib": rss_imports, "rows": quality["rows_read"],
                  "samples": int(segments[0][1].t_s.shape[0]),
                  "masked_samples": quality["screening"]["masked_samples"]}))
"""


def write_recording(path: Path, seed: int = 0) -> int:
    """A plausible 24 h substation recording: ambient frequency and load, 9 significant digits."""
    import pandas as pd
    from scipy.signal import lfilter

    rng = np.random.default_rng(seed)
    n = int(HOURS * 3600 * RATE_HZ) + 1
    t = np.arange(n) / RATE_HZ
    # Ornstein-Uhlenbeck frequency deviation (0.02 Hz, 30 s), integrated into the angle.
    a = np.exp(-1 / (30 * RATE_HZ))
    df = lfilter([1.0], [1.0, -a], rng.normal(0, 0.02 * np.sqrt(1 - a * a), n))
    v_ang = np.degrees(np.cumsum(2 * np.pi * df / RATE_HZ))
    load = 0.8 + 0.1 * np.sin(2 * np.pi * t / 86400) + rng.normal(0, 0.002, n)
    frame = pd.DataFrame({
        COLUMNS["time"]: t,
        COLUMNS["v_mag"]: 400.0 * (0.98 + rng.normal(0, 0.001, n)),
        COLUMNS["v_ang"]: (v_ang + 180.0) % 360.0 - 180.0,
        COLUMNS["i_mag"]: load * 1300.0,
        COLUMNS["i_ang"]: (v_ang - 10.0 + 180.0) % 360.0 - 180.0,
        COLUMNS["frequency"]: 50.0 + df + rng.normal(0, 5e-4, n),
    })
    frame.to_csv(path, index=False, float_format="%.9g")
    return n


def main():
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "pmu_24h.csv"
        t0 = time.perf_counter()
        rows = write_recording(path)
        size_mib = path.stat().st_size / 2**20
        print(f"wrote {rows} rows, {size_mib:.0f} MiB in {time.perf_counter() - t0:.1f} s", file=sys.stderr)
        out = subprocess.run([sys.executable, "-c", CHILD, str(path), json.dumps(COLUMNS)],
                             capture_output=True, text=True, check=True)
    result = json.loads(out.stdout.strip().splitlines()[-1])
    result = {"read_s": round(result["read_s"], 2), "read_cpu_s": round(result["read_cpu_s"], 2),
              "load_average_1min": round(os.getloadavg()[0], 2), "cpus": os.cpu_count(),
              "peak_rss_mib": round(result["peak_rss_mib"], 1),
              "rss_after_imports_mib": round(result["rss_after_imports_mib"], 1),
              "import_s": round(result["import_s"], 2), "rows": result["rows"],
              "samples": result["samples"], "masked_samples": result["masked_samples"],
              "file_mib": round(size_mib, 1), "frame_rate_hz": RATE_HZ, "hours": HOURS,
              "targets": {"read_s": 10.0, "peak_rss_mib": 2048.0}}
    (HERE / "read_24h.json").write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
