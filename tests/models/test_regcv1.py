"""The grid-forming converter REGCV1 (and REGCV2): its steady state, its playback against ANDES
2.0.0 (the independent trace of STYLE 20); its inertia from a recording: tests/app/test_gfm_fleet.py.

The recordings (``experiments/andes_gfm/*.csv.gz``, made by ``experiments/andes_gfm/generate.py``
with ANDES in its own venv) hold the converter's terminal V and I phasors in the IEEE 14-bus
case with REGCV1 at bus 8 (M = 8 s, D = 2 pu), and ANDES's virtual rotor speed. To keep the
tests cheap they use 5 s of the line trip (1 s before the event, 4 s after it), and every
playback goes through one jitted function of one length (one compilation).
"""

import gzip
import json
from pathlib import Path

import jax.numpy as jnp
import equinox as eqx
import numpy as np
import pytest

import jaxdse as jd
from jaxdse._dyr.gfm_unit import GfmUnit
from jaxdse._dyr.playback import TerminalSeries, play_back
from jaxdse._models.ibr import REGCV1, GfmInputs, gfm_from_andes

DATA = Path(__file__).resolve().parents[2] / "experiments" / "andes_gfm"
T0_S, T1_S = 9.0, 14.0
N_FRAMES = 301
_play = eqx.filter_jit(play_back)


def _read(name, folder=DATA):
    with gzip.open(folder / name, "rt") as fh:
        header = fh.readline().strip().split(",")
        body = np.loadtxt(fh, delimiter=",")
    return {k: body[:, j] for j, k in enumerate(header)}


def _line_trip(folder):
    meta = json.loads((folder / "truth.json").read_text())
    rec, truth = _read("line_trip.csv.gz", folder), _read("line_trip_truth.csv.gz", folder)
    keep = (rec["time_s"] >= T0_S - 1e-9) & (rec["time_s"] <= T1_S + 1e-9)
    tag = meta["tag"]
    v = rec[f"{tag}/VM"] * np.exp(1j * np.deg2rad(rec[f"{tag}/VA"]))
    i = rec[f"{tag}/IM"] * np.exp(1j * np.deg2rad(rec[f"{tag}/IA"]))
    v, i = v[keep], i[keep]
    series = TerminalSeries(jnp.asarray(rec["time_s"][keep]), jnp.abs(v), jnp.unwrap(jnp.angle(v)),
                            jnp.real(i), jnp.imag(i))
    assert series.t_s.shape == (N_FRAMES,)
    return meta, series, truth["omega_pu"][keep], v * np.conj(i)


@pytest.fixture(scope="module")
def line_trip():
    return _line_trip(DATA)


@pytest.mark.parametrize("inner", ["pi", "lag"])
def test_flat_start_stays_flat(inner):
    """At the initial state the vector field is zero, and a playback under a constant voltage
    stays there (REGCV1: inner PI; REGCV2: current lags)."""
    m = REGCV1(inner=inner, m_s=8.0, d_pu=2.0, ra_pu=0.01, kv_pu=0.05, kw_pu=10.0)
    v, i = 1.03 * np.exp(0.3j), (0.35 - 0.08j) * np.exp(0.3j)
    u = GfmInputs(jnp.asarray(v.real), jnp.asarray(v.imag))
    y0, refs = m.initial_state(u, jnp.asarray(i.real), jnp.asarray(i.imag))
    assert np.max(np.abs(np.asarray(m.vector_field(y0, u, refs)))) < 1e-12
    s = m.signals(y0, u, refs)
    assert float(s.p_pu) == pytest.approx(0.35 * 1.03, abs=1e-12)
    assert float(s.q_pu) == pytest.approx(0.08 * 1.03, abs=1e-12)
    assert float(s.vq_pu) == pytest.approx(0.0, abs=1e-12)
    if inner == "lag":  # (one playback compiled: the REGCV1 structure of the ANDES comparison)
        return
    n = N_FRAMES
    series = TerminalSeries(jnp.linspace(0.0, 5.0, n), jnp.full(n, 1.03), jnp.full(n, 0.3),
                            jnp.full(n, i.real), jnp.full(n, i.imag))
    r = _play(GfmUnit(m), series)
    assert bool(r.ok)
    assert np.max(np.abs(np.asarray(r.p_pu) - 0.35 * 1.03)) < 1e-9
    assert np.max(np.abs(np.asarray(r.omega_pu) - 1.0)) < 1e-12


def test_swing_equation_is_andes():
    """The speed's derivative is (Pref - kw dw - Pe - D dw)/M, and the angle's omega_s dw."""
    m = REGCV1(m_s=6.0, d_pu=3.0, kw_pu=20.0)
    u = GfmInputs(jnp.asarray(1.0), jnp.asarray(0.0))
    y0, refs = m.initial_state(u, jnp.asarray(0.5), jnp.asarray(0.0))
    y = y0.at[0].set(1e-3)
    f = np.asarray(m.vector_field(y, u, refs))
    pe = float(m.signals(y, u, refs).p_pu)
    assert f[0] == pytest.approx((0.5 - 20.0 * 1e-3 - pe - 3.0 * 1e-3) / 6.0, rel=1e-12)
    assert f[1] == pytest.approx(2 * np.pi * 60 * 1e-3, rel=1e-12)


def test_andes_names_and_refusals():
    m = gfm_from_andes("REGCV1", {"M": 8.0, "D": 2.0, "xs": 0.2, "Sn": 100.0, "fn": 50.0})
    assert float(m.h_s) == 4.0 and m.inner == "pi"
    assert float(m.omega_s_rad_s) == pytest.approx(2 * np.pi * 50)
    assert gfm_from_andes("regcv2", {"Tid": 0.02}).inner == "lag"
    with pytest.raises(ValueError, match="unknown parameter 'H'"):
        gfm_from_andes("REGCV1", {"H": 4.0})
    with pytest.raises(ValueError, match="not a supported grid-forming model"):
        gfm_from_andes("REGCA1", {})
    with pytest.raises(ValueError, match="m_s"):
        REGCV1(m_s=0.0)


@pytest.mark.parametrize("model", ["REGCV1", "REGCV2"])
def test_playback_matches_andes(model, line_trip):
    """With ANDES's recorded terminal voltage imposed, the module's virtual rotor speed follows
    ANDES's within 2 % of its swing, and P and Q within 0.2 % of Sn (RMS, frames after the
    switching instant's interval). REGCV2: its own ANDES line trip (``regcv2/``)."""
    meta, series, omega, s = line_trip if model == "REGCV1" else _line_trip(DATA / "regcv2")
    assert meta["model"] == model
    r = _play(GfmUnit(gfm_from_andes(model, meta["constants"])), series)
    assert bool(r.ok)
    after = np.asarray(series.t_s) > 10.0 + 1.5 / 60
    swing = np.ptp(omega)
    assert np.max(np.abs(np.asarray(r.omega_pu) - omega)) < 0.02 * swing
    assert np.sqrt(np.mean((np.asarray(r.p_pu) - s.real)[after] ** 2)) < 2e-3
    assert np.sqrt(np.mean((np.asarray(r.q_pu) - s.imag)[after] ** 2)) < 2e-3


def test_classical_plant_of_a_converter():
    """The estimator's plant of a converter: xd = xq = x'd = xs (or the reactance asked for),
    the governor's droop 1/kw (or the no-droop value when kw = 0)."""
    from jaxdse._dyr.gfm_unit import NO_DROOP_R_PU, classical_plant

    p = classical_plant(REGCV1(xs_pu=0.25, kw_pu=20.0, ra_pu=0.01), 50.0, 13.8)
    m = p.machine
    assert float(m.xd_pu) == float(m.xq_pu) == float(m.xd1_pu) == 0.25
    assert float(m.rs_pu) == 0.01 and float(m.s_rated_mva) == 50.0
    assert float(p.governor.r_pu) == pytest.approx(0.05)
    p0 = classical_plant(REGCV1(), 100.0, 1.0, x_internal_pu=0.5)
    assert float(p0.machine.xd1_pu) == 0.5 and float(p0.governor.r_pu) == NO_DROOP_R_PU
