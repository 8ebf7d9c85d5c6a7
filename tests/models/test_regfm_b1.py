"""REGFM_B1 (virtual-synchronous-machine grid-forming inverter) against a plain SciPy integration
of its block diagram written here from the REGFM_B1 specification (NREL/TP-5D00-90260; scalar
Python, not the module), with the terminal voltage phasor imposed: a voltage step with a frequency
ramp, and a deep voltage dip (the transient current limit ImaxF, the moving E limit and the
angle limit dITmax reached); a flat run stays flat; every flag combination starts at rest; the
record reads in PSS/E order (REGFMB1U) with its coupling impedance from ZSORCE.

One compiled program, shared by the three runs (one shape). The largest differences are printed
(``pytest -s``) and asserted below 1e-5 pu.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from gfm_drive import ANG, P0, Q0, TS, V0, W0, away, nw, simulate, solve_pieces, theta_of, v_of
from gfm_drive import runs as drive_runs

import jaxdse as jd
from jaxdse._dyr.gfm_unit import GfmUnit
from jaxdse._models.ibr import REGFM_B1, GfmInputs, ibr_from_dyr

RUNS = drive_runs()
# wFlag VdrpFlag QVFlag PQFlag FFlag ESFlag, then the 25 CONs in PSS/E order
C = dict(
    wflag=0,
    vdrpflag=0,
    qvflag=0,
    pqflag=1,
    fflag=1,
    esflag=1,
    mq=0.05,
    kpv=0.1,
    kiv=5.0,
    mp=0.02,
    dwmax=0.05,
    dwmin=-0.05,
    kppll=0.265,
    kipll=2.65,
    dwpllmax=0.2,
    dwpllmin=-0.2,
    tp=0.02,
    h=1.5,
    d1=1.0,
    d2=100.0,
    wd=50.0,
    imaxss=1.0,
    kf=0.9,
    ki=2.0,
    imaxf=1.3,
    tpf=0.02,
    tqf=0.02,
    tvf=0.02,
    tif=0.02,
    ke=0.5,
    vpllfrz=0.05,
    re=0.0,
    xl=0.15,
)
RECORD = [
    C[k]
    for k in (
        "wflag",
        "vdrpflag",
        "qvflag",
        "pqflag",
        "fflag",
        "esflag",
        "mq",
        "kpv",
        "kiv",
        "mp",
        "dwmax",
        "dwmin",
        "kppll",
        "kipll",
        "dwpllmax",
        "dwpllmin",
        "tp",
        "h",
        "d1",
        "d2",
        "wd",
        "imaxss",
        "kf",
        "ki",
        "imaxf",
        "tpf",
        "tqf",
        "tvf",
        "tif",
        "ke",
        "vpllfrz",
    )
]


def _module():
    m = ibr_from_dyr("REGFMB1U", RECORD)
    return eqx.tree_at(lambda c: (c.re_pu, c.xe_pu), m, (jnp.asarray(C["re"]), jnp.asarray(C["xl"])))


# --- the block diagram, written out (REGFM_B1) -------------------------------------------------

RESET = 1e-3  # a state beyond a limit that moved past it is brought to it (the module's choice)


def _to_limit(x, d, lo, hi):
    """Non-windup within limits that move: beyond one, back to it fast."""
    if x > hi:
        return (hi - x) / RESET
    if x < lo:
        return (lo - x) / RESET
    return nw(x, d, lo, hi)


def _reference(steps, ramps):
    """P, Q out of the terminal at TS, by solve_ivp, and which limits were reached."""
    c = C
    z = complex(c["re"], c["xl"])
    v0 = V0 * np.exp(1j * ANG)
    i0 = np.conj((P0 + 1j * Q0) / v0)
    e0 = v0 + z * i0
    ipll0 = i0 * np.exp(-1j * ANG)
    pref, qref, vref = P0, Q0, V0  # QVFlag = 0
    dmax = math.asin(c["xl"] * c["imaxss"])
    reached = set()

    def limits(x):
        vinv, idinv = x[2], x[3]
        idmax = c["kf"] * c["imaxss"]  # PQFlag = 1
        iqmax = math.sqrt(max(c["imaxss"] ** 2 - idinv**2, 0.0))
        emax = math.hypot(vinv + iqmax * c["xl"], idinv * c["xl"])
        emin = math.hypot(vinv - iqmax * c["xl"], idinv * c["xl"])
        return idmax, emin, emax

    def source(x, t):
        _, emin, emax = limits(x)
        vcmd = vref + c["mq"] * (qref - x[1])
        e_raw = c["kpv"] * (vcmd - x[2]) + x[13]
        e = min(max(e_raw, emin), emax)
        if e_raw > emax:
            reached.add("Emax")
        delta = x[6] + min(max(x[10], x[12]), x[11])  # ESFlag = 1
        v = v_of(t, steps) * np.exp(1j * theta_of(t, ramps))
        cur = (e * np.exp(1j * delta) - v) / z
        if abs(cur) > c["imaxf"]:
            cur *= c["imaxf"] / abs(cur)
            reached.add("ImaxF")
        if x[11] < dmax - 1e-6:
            reached.add("dITmax")
        return v, cur, vcmd

    def rhs(t, x):
        v, cur, vcmd = source(x, t)
        s = v * np.conj(cur)
        vt, theta = abs(v), np.angle(v)
        vq = vt * math.sin(theta - x[6])
        dwpll = min(max(c["kppll"] * vq + x[5], c["dwpllmin"]), c["dwpllmax"])
        ipll = cur * np.exp(-1j * x[6])
        idmax, emin, emax = limits(x)
        frozen = vt < c["vpllfrz"]
        droop = -x[7] / c["mp"]  # FFlag = 1
        d_dwm = (pref + droop - x[0] - c["d1"] * x[9] - c["d2"] * (x[9] - x[8])) / (2 * c["h"])
        return [
            (s.real - x[0]) / c["tpf"],
            (s.imag - x[1]) / c["tqf"],
            (vt - x[2]) / c["tvf"],
            (ipll.real - x[3]) / c["tif"],
            (-ipll.imag - x[4]) / c["tif"],
            0.0 if frozen else c["kipll"] * vq,
            0.0 if frozen else W0 * dwpll,
            (x[9] - x[7]) / c["tp"],  # wFlag = 0
            c["wd"] * (x[9] - x[8]),
            nw(x[9], d_dwm, c["dwmin"], c["dwmax"]),
            _to_limit(x[10], W0 * (x[9] - dwpll), x[12], x[11]),
            _to_limit(x[11], c["ki"] * (idmax - x[3]), 0.0, dmax),
            _to_limit(x[12], c["ki"] * (-c["ke"] * idmax - x[3]), -dmax, 0.0),
            _to_limit(x[13], c["kiv"] * (vcmd - x[2]), emin, emax),
        ]

    x = np.array(
        [
            P0,
            Q0,
            V0,
            ipll0.real,
            -ipll0.imag,
            0.0,
            ANG,
            0.0,
            0.0,
            0.0,
            np.angle(e0) - ANG,
            dmax,
            -dmax,
            abs(e0),
        ]
    )
    ys = solve_pieces(rhs, x, steps, ramps)
    s = np.array([(lambda v, cur, _: v * np.conj(cur))(*source(y, t)) for t, y in zip(TS, ys)])
    return s.real, s.imag, reached, ys


@pytest.fixture(scope="module")
def runs():
    m = _module()
    out = {}
    for name, (steps, ramps) in RUNS.items():
        ys, sig, y0 = simulate(m, jnp.asarray(TS), jnp.asarray(steps), jnp.asarray(ramps))
        ref = _reference(steps, ramps) if name != "flat" else None
        out[name] = (np.asarray(ys), sig, np.asarray(y0), ref)
    return m, out


@pytest.mark.parametrize("name, limits", [("step_ramp", set()), ("dip", {"ImaxF", "Emax", "dITmax"})])
def test_matches_the_scipy_block_diagram(runs, name, limits):
    _, out = runs
    ys, sig, _, (p_ref, q_ref, reached, ys_ref) = out[name]
    far = away(*RUNS[name])
    dp = np.max(np.abs(np.asarray(sig.p_pu) - p_ref)[far])
    dq = np.max(np.abs(np.asarray(sig.q_pu) - q_ref)[far])
    dw = np.max(np.abs(ys[:, 9] - ys_ref[:, 9])[far])
    print(
        f"\nREGFM_B1 {name}: largest difference from SciPy {max(dp, dq):.2e} pu (P {dp:.2e}, Q {dq:.2e}; "
        f"virtual speed {dw:.2e} pu); limits reached: {sorted(reached)}"
    )
    assert max(dp, dq) < 1e-5 and dw < 1e-6
    assert limits <= reached
    assert np.ptp(p_ref) > 0.05 and np.ptp(q_ref) > 0.02


def test_a_flat_run_stays_flat(runs):
    m, out = runs
    ys, sig, y0, _ = out["flat"]
    assert np.max(np.abs(np.asarray(sig.p_pu) - P0)) < 1e-9
    assert np.max(np.abs(np.asarray(sig.q_pu) - Q0)) < 1e-9
    assert np.max(np.abs(ys - y0)) < 1e-9
    assert float(m.h_s) == C["h"]


def test_the_swing_sets_the_frequency_response(runs):
    """After the +0.1 Hz ramp the virtual speed follows the grid (dwm -> df) and P falls by
    (1/mp + D1) df: the droop and the steady-state damping (within 5 % after 0.49 s: the PLL and the
    swing still settle)."""
    _, out = runs
    ys, sig, _, _ = out["step_ramp"]
    k = np.searchsorted(TS, 1.49)
    df = 0.1 / 60.0
    print(
        f"\nREGFM_B1 0.49 s after the ramp: dwm {ys[k, 9]:.6g} pu (df {df:.6g}), P change "
        f"{float(np.asarray(sig.p_pu)[k]) - P0:.4g} pu "
        f"(-(1/mp + D1) df = {-(1 / C['mp'] + C['d1']) * df:.4g})"
    )
    assert ys[k, 9] == pytest.approx(df, rel=5e-2)
    assert float(np.asarray(sig.p_pu)[k]) - P0 == pytest.approx(-(1 / C["mp"] + C["d1"]) * df, rel=5e-2)


@pytest.mark.parametrize(
    "flags", [(0, 0, 1, 1, 1, 1), (0, 0, 0, 1, 1, 0), (1, 1, 1, 0, 1, 1), (0, 1, 1, 1, 0, 0)]
)
def test_every_flag_combination_starts_at_rest(flags):
    m = _module()
    m = eqx.tree_at(
        lambda c: (c.wflag, c.vdrpflag, c.qvflag, c.pqflag, c.fflag, c.esflag),
        m,
        tuple(jnp.asarray(f) for f in flags),
    )
    v = V0 * np.exp(1j * ANG)
    i = np.conj((P0 + 1j * Q0) / v)
    u = GfmInputs(jnp.asarray(v.real), jnp.asarray(v.imag))
    y0, refs = m.initial_state(u, jnp.asarray(i.real), jnp.asarray(i.imag))
    assert np.max(np.abs(np.asarray(m.vector_field(y0, u, refs)))) < 1e-12
    s = m.signals(y0, u, refs)
    assert float(s.p_pu) == pytest.approx(P0, abs=1e-12) and float(s.q_pu) == pytest.approx(Q0, abs=1e-12)


def test_record_reads_in_psse_order_and_names_its_constants():
    m = ibr_from_dyr("REGFMB1U", RECORD)
    assert float(m.h_s) == C["h"] and float(m.mp) == C["mp"] and float(m.i_max_f_pu) == C["imaxf"]
    assert int(m.esflag) == 1 and float(m.v_pll_frz_pu) == C["vpllfrz"]
    with pytest.raises(ValueError, match="REGFMB1U: H must be > 0"):
        ibr_from_dyr("REGFMB1U", RECORD[:17] + [0.0] + RECORD[18:])
    with pytest.raises(ValueError, match="expected 31 values"):
        ibr_from_dyr("REGFMB1U", RECORD[:-1])
    with pytest.raises(ValueError, match="wFlag"):
        ibr_from_dyr("REGFMB1U", [3] + RECORD[1:])
    assert isinstance(GfmUnit(m).converter, REGFM_B1) and jd.REGFM_B1 is REGFM_B1
