"""Regenerate the example recordings in examples/data/ from the built-in plant simulator.

    python examples/make_example_data.py

Each file holds the same kind of simulated substation PMU recording (the paper's plant, ambient
fluctuations and one event; truth: H = 6.18 s, a2 = 25.42) in a different layout and in
different units, as exported by real tools. Values are written with 9 significant digits.
"""

from datetime import UTC, datetime
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

from jaxdse import (  # noqa: E402  # noqa: E402
    Event,
    MeasurementSpec,
    Plant,
    Scenario,
    phasor_columns,
    simulate,
    write_comtrade,
    write_csv,
)

HERE = Path(__file__).parent / "data"
DURATION_S, RATE = 300.0, 25.0


def main():
    HERE.mkdir(exist_ok=True)
    plant = Plant()
    high = simulate(plant, Scenario(duration_s=DURATION_S, frame_rate_hz=RATE, p_pu=0.818, q_pu=0.15,
                                    seed=101, events=(Event(150.0, "load_step", 0.05),)))
    low = simulate(plant, Scenario(duration_s=DURATION_S, frame_rate_hz=RATE, p_pu=0.409, q_pu=0.05,
                                   seed=102, events=(Event(150.0, "line_trip", 1.5),)))

    # 1. Positive sequence, seconds, kV phase-to-phase, A, degrees, current out of the plant.
    spec = MeasurementSpec(file=(), columns={"time": "Time_s", "frequency": "Freq_Hz",
                                             "v_mag": "V1_kV", "v_ang": "V1_deg",
                                             "i_mag": "I1_A", "i_ang": "I1_deg"},
                           voltage_unit="kV_LL", current_unit="A", v_base_kv=400.0)
    write_csv(HERE / "pmu_positive_sequence.csv", phasor_columns(high.recording, spec), digits=9)

    # 2. Three-phase, ISO timestamps (openPDC/PhasorPoint-style names), kV phase-to-ground, kA,
    #    radians, current measured into the plant, no frequency channel; the low-power run.
    names = {"time": "Timestamp"}
    for q, quantity in (("v", "V"), ("i", "I")):
        for p in "abc":
            names[f"{q}_{p}_mag"] = f"SUB1_{quantity}{p.upper()}:Magnitude"
            names[f"{q}_{p}_ang"] = f"SUB1_{quantity}{p.upper()}:Angle"
    spec3 = MeasurementSpec(file=(), columns=names, voltage_unit="kV_LN", current_unit="kA",
                            angle_unit="rad", time_unit="iso", v_base_kv=400.0,
                            current_direction="into_plant")
    cols = phasor_columns(low.recording, spec3, low.v_abc, low.i_abc)
    write_csv(HERE / "pmu_three_phase.csv.gz", cols, time_column="Timestamp",
              start=datetime(2024, 3, 1, 12, 0, tzinfo=UTC), digits=9)

    # 3. COMTRADE 2013 BINARY32, positive sequence in kV (phase-to-ground) and A, degrees.
    specc = MeasurementSpec(file=(), columns={"time": "time", "frequency": "F",
                                              "v_mag": "V1 MAG", "v_ang": "V1 ANG",
                                              "i_mag": "I1 MAG", "i_ang": "I1 ANG"},
                            voltage_unit="kV_LN", current_unit="A", v_base_kv=400.0)
    cols = phasor_columns(high.recording, specc)
    t = cols.pop("time")
    write_comtrade(HERE / "pmu_comtrade.cfg", t, cols,
                   {"F": "Hz", "V1 MAG": "kV", "V1 ANG": "deg", "I1 MAG": "A", "I1 ANG": "deg"},
                   data_format="BINARY32", frequency_hz=50.0, station="SUB1")
    print(f"wrote {sorted(p.name for p in HERE.iterdir())}; truth a2 = {float(high.truth.a2):.4f}, "
          f"a1 = {float(high.truth.a1):.4f}")


if __name__ == "__main__":
    main()
