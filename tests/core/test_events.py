"""Event recordings of an independent simulator (the ANDES bench, stored CSV): the fixed-step
path and tuning stay finite through a line trip at gamma = 850, 60 frames/s, and agree with
the adaptive integrator."""

import gzip
import json
from pathlib import Path

import numpy as np
import pytest

import jaxdse as jd

BENCH = Path(__file__).resolve().parents[2] / "experiments" / "andes_bench" / "data" / "ieee14"
TAG = "B3_G1"
GAMMA = 850.0
N_SAMPLES = 2400


@pytest.fixture(scope="module")
def line_trip():
    """The ieee14 line trip at one machine's terminal (the first 40 s at 60 frames/s, the trip at
    10 s) and its plant."""
    with gzip.open(BENCH / "line_trip.csv.gz", "rt") as fh:
        header = fh.readline().strip().split(",")
        body = np.loadtxt(fh, delimiter=",")
    col = {name: body[:N_SAMPLES, k] for k, name in enumerate(header)}
    m = next(x for x in json.loads((BENCH / "truth.json").read_text())["machines"] if x["tag"] == TAG)
    g, p = m["genrou_mbase"], m["governor"]["params_mbase_psse_order"]
    assert m["governor"]["model"] == "TGOV1"
    plant = jd.Plant(
        machine=jd.Machine(xd_pu=g["xd"], xq_pu=g["xq"], xd1_pu=g["xd1"], rs_pu=g["ra"], td01_s=g["Td10"],
                           s_rated_mva=m["mbase_mva"], v_rated_kv=m["bus_kv"], f_nominal_hz=60.0),
        governor=jd.TGOV1(r_pu=p["R"], t1_s=p["T1"], v_max_pu=p["VMAX"], v_min_pu=p["VMIN"], t2_s=p["T2"],
                          t3_s=p["T3"], dt_pu=p["Dt"]))
    rec = jd.Recording(t_s=col["time_s"], v_mag_pu=col[f"{TAG}/VM"], v_ang_rad=np.deg2rad(col[f"{TAG}/VA"]),
                       i_mag_pu=col[f"{TAG}/IM"], i_ang_rad=np.deg2rad(col[f"{TAG}/IA"]),
                       f_hz=col[f"{TAG}/F"], location="terminal")
    return jd.Recording(**{k: np.unwrap(getattr(rec, k)) if k.endswith("ang_rad") else getattr(rec, k)
                           for k in ("t_s", "v_mag_pu", "v_ang_rad", "i_mag_pu", "i_ang_rad", "f_hz")},
                        location="terminal"), plant, m["H_s_mbase"]


@pytest.mark.slow
def test_fixed_step_path_through_a_line_trip_matches_adaptive(line_trip):
    rec, plant, _ = line_trip
    cfg = jd.ObserverConfig(gamma1=GAMMA, gamma2=GAMMA)
    fast = jd.estimate(rec, plant, cfg, jd.Settings.fast())
    adaptive = jd.estimate(rec, plant, cfg, jd.Settings(playback=False, keep="final"))
    assert bool(fast.solver_ok) and bool(adaptive.solver_ok)
    assert np.all(np.isfinite(np.asarray(fast.a2_hat))) and np.isfinite(float(fast.a2))
    assert abs(float(fast.a2) / float(adaptive.a2) - 1.0) < 0.02


@pytest.mark.slow
def test_tuning_on_a_line_trip_stays_finite(line_trip):
    rec, plant, _ = line_trip
    res = jd.tune([rec], plant, jd.ObserverConfig(gamma1=GAMMA, gamma2=GAMMA), max_steps=2)
    assert np.isfinite(float(res.loss_start)) and np.isfinite(float(res.loss_tuned))
    tuned = jd.estimate(rec, plant, res.config, jd.Settings(playback=False, keep="final"))
    assert np.isfinite(float(tuned.a2)) and float(tuned.a2) > 0
