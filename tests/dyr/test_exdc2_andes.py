"""EXDC2 against an independent simulator (issue 32, item 5).

The npcc recordings of the ANDES bench were simulated with ANDES's IEEEX1, which is the PSS/E
EXDC2 block diagram (regulator limits times the terminal voltage, EFD without a speed factor;
ANDES's own EXDC2 adds a speed factor, see experiments/andes_bench/records_as_given.md). Read
as EXDC2 records (the same 16 constants), a unit with KE = 1 and KA = 400 plays back ANDES's P
and Q with its terminal voltage imposed.
"""

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pandas as pd

import jaxdse as jd

DATA = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench" / "data" / "npcc"
KEEP_S = 20.0
TAG, BUS, MBASE = "B22_G1", 22, 700.0


def test_exdc2_plays_back_andes_ieeex1_recording(tmp_path):
    dyr_file = tmp_path / "npcc_exdc2.dyr"
    dyr_file.write_text((DATA / "npcc.dyr").read_text().replace("'IEEEX1'", "'EXDC2'"))
    um = jd.unit_model(jd.read_dyr(dyr_file), jd.read_raw(DATA / "npcc.raw"), BUS, "1", ke_zero="literal")
    assert um.unit is not None and um.models["exciter"] == "EXDC2", um.missing
    df = pd.read_csv(DATA / "line_trip.csv.gz")
    df = df[df["time_s"] <= KEEP_S]
    i = (df[f"{TAG}/IM"].to_numpy() * (100.0 / MBASE)
         * np.exp(1j * np.deg2rad(df[f"{TAG}/IA"].to_numpy())))
    series = jd.TerminalSeries(*(jnp.asarray(a) for a in (
        df["time_s"].to_numpy(), df[f"{TAG}/VM"].to_numpy(),
        np.unwrap(np.deg2rad(df[f"{TAG}/VA"].to_numpy())), i.real, i.imag)))
    r = jd.play_back(um.unit, series, jd.PlaybackSettings(substeps=4))
    assert bool(r.ok)
    p, q = (np.asarray(a) for a in jd.measured_pq(series))
    assert np.ptp(q) > 0.01                              # the exciter is at work: Q moves
    rms = [float(np.sqrt(np.mean((np.asarray(s) - m) ** 2))) for s, m in ((r.p_pu, p), (r.q_pu, q))]
    assert max(rms) < 1e-4, rms                           # 0.01 % of MBASE
